//! Scene files (TOML): CSG solids written as expressions (see [`hytrace_csg::expr`]) and
//! their placements in the world.
//!
//! ```toml
//! [solids.vessel]
//! shape = "tube(0, 1000, -500, 500) - sphere(300).translate(0, 0, 200)"
//!
//! [[place]]
//! solid = "vessel"
//! translate = [0, 0, 100]          # mm, optional
//! rotate = [0, 0, 1, 90]           # axis xyz and degrees, optional
//! copy = 3                         # copy number, optional (default: placement index)
//! ```
//!
//! Placements apply the rotation first, then the translation. A solid without placements is
//! placed once at the origin. Solids are listed (and indexed) in name order.

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{bail, Context};
use hytrace_csg::{parse_shape, to_tree};
use hytrace_foundry::{Foundry, Transform64, UNSET};
use serde::Deserialize;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SceneFile {
    solids: BTreeMap<String, SolidEntry>,
    #[serde(default)]
    place: Vec<Placement>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SolidEntry {
    shape: String,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Placement {
    solid: String,
    #[serde(default)]
    translate: Option<[f64; 3]>,
    #[serde(default)]
    rotate: Option<[f64; 4]>,
    #[serde(default)]
    copy: Option<i32>,
}

fn placement_transform(p: &Placement) -> anyhow::Result<Transform64> {
    let mut t = Transform64::IDENTITY;
    if let Some([x, y, z, deg]) = p.rotate {
        if [x, y, z] == [0.0; 3] || ![x, y, z, deg].iter().all(|v| v.is_finite()) {
            bail!(
                "rotate needs a finite non-zero axis and angle, got {:?}",
                p.rotate
            );
        }
        t = Transform64::rotation([x, y, z], deg.to_radians());
    }
    if let Some(v) = p.translate {
        if !v.iter().all(|c| c.is_finite()) {
            bail!("translate must be finite, got {v:?}");
        }
        t = Transform64::translation(v).compose(&t);
    }
    Ok(t)
}

/// Builds a Foundry from the text of a scene file; `source` names it in errors.
pub fn scene_from_toml(text: &str, source: &str) -> anyhow::Result<Foundry> {
    let file: SceneFile =
        toml::from_str(text).with_context(|| format!("{source}: not a valid scene file"))?;
    if file.solids.is_empty() {
        bail!("{source}: no [solids.NAME] entries");
    }
    let mut f = Foundry::new();
    let mut index = BTreeMap::new();
    for (i, (name, entry)) in file.solids.iter().enumerate() {
        let shape = parse_shape(&entry.shape)
            .with_context(|| format!("{source}: solid `{name}`: shape `{}`", entry.shape))?;
        let tree = to_tree(&shape).with_context(|| format!("{source}: solid `{name}`"))?;
        let mut s = f.begin_solid(name);
        s.add_csg(tree, i as u32, UNSET)?;
        let solid = s.finish(i as u32)?;
        index.insert(name.clone(), solid);
    }
    let mut placed = vec![false; index.len()];
    for (k, p) in file.place.iter().enumerate() {
        let &solid = index
            .get(&p.solid)
            .with_context(|| format!("{source}: place {k}: unknown solid `{}`", p.solid))?;
        let t = placement_transform(p).with_context(|| format!("{source}: place {k}"))?;
        f.add_instance(solid, t, k as u32, p.copy.unwrap_or(k as i32))?;
        placed[solid as usize] = true;
    }
    for (solid, was_placed) in placed.iter().enumerate() {
        if !was_placed {
            f.add_instance(solid as u32, Transform64::IDENTITY, UNSET, 0)?;
        }
    }
    f.validate()
        .with_context(|| format!("{source}: built an invalid Foundry"))?;
    Ok(f)
}

/// Reads a scene file.
pub fn load_toml_scene(path: &Path) -> anyhow::Result<Foundry> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    scene_from_toml(&text, &path.display().to_string())
}
