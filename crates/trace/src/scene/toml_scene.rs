//! Scene files (TOML): CSG solids written as expressions (see [`hytrace_csg::expr`]), triangle
//! meshes from files, participating media from voxel grids, and their placements.
//!
//! ```toml
//! [solids.vessel]
//! shape = "tube(0, 1000, -500, 500) - sphere(300).translate(0, 0, 200)"
//!
//! [meshes.bunny]
//! file = "bunny.obj"               # .obj, .gltf or .glb, relative to the scene file
//!
//! [volumes.fog]
//! source = "sphere:400,10"         # .nvdb, .vdb (relative to the scene file) or procedural
//! grid = "density"                 # optional: grid name (default: the first)
//! density_scale = 0.002            # extinction per mm at grid value 1
//! format = "f32"                   # optional: bricked texel format (f32, f16, unorm16,
//!                                  # unorm8, bc4)
//!
//! [[place]]
//! solid = "vessel"                 # any solid, mesh or volume name
//! translate = [0, 0, 100]          # mm, optional
//! rotate = [0, 0, 1, 90]           # axis xyz and degrees, optional
//! copy = 3                         # copy number, optional (default: placement index)
//! ```
//!
//! Rendering adds `[camera]`, `[materials.NAME]`, `[[lights]]` and `[render]` tables, a
//! `material` on solids and meshes and `albedo`, `g` and `emission` on volumes (see
//! [`crate::render::spec`]); scans ignore them.
//!
//! Names are shared by solids, meshes and volumes. Placements apply the rotation first, then
//! the translation. Anything without placements is placed once at the origin. The Foundry
//! lists CSG solids, then meshes, then volumes, each in name order. Media need a grid with a
//! zero background; their bricks are made in the given texel format, which the tracers
//! sample.

use std::collections::BTreeMap;
use std::path::Path;
use std::str::FromStr;

use anyhow::{bail, Context};
use hytrace_csg::{parse_shape, to_tree};
use hytrace_foundry::{Foundry, Transform64, UNSET};
use hytrace_volume::{is_procedural, TexelFormat};
use serde::Deserialize;

use super::media::{add_medium_solid, MediumSpec};
use super::mesh_scene::add_mesh_file_solid;
use crate::render::camera::CameraSpec;
use crate::render::spec::{Light, Material, MediumOptics, RenderSettings, RenderSpec};

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SceneFile {
    #[serde(default)]
    solids: BTreeMap<String, SolidEntry>,
    #[serde(default)]
    meshes: BTreeMap<String, MeshEntry>,
    #[serde(default)]
    volumes: BTreeMap<String, VolumeEntry>,
    #[serde(default)]
    place: Vec<Placement>,
    #[serde(default)]
    camera: Option<CameraSpec>,
    #[serde(default)]
    materials: BTreeMap<String, Material>,
    #[serde(default)]
    lights: Vec<Light>,
    #[serde(default)]
    render: Option<RenderSettings>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SolidEntry {
    shape: String,
    #[serde(default)]
    material: Option<String>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct MeshEntry {
    file: String,
    #[serde(default)]
    material: Option<String>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct VolumeEntry {
    source: String,
    #[serde(default)]
    grid: Option<String>,
    density_scale: f64,
    #[serde(default)]
    format: Option<String>,
    #[serde(default)]
    albedo: f64,
    #[serde(default)]
    g: f64,
    #[serde(default)]
    emission: [f64; 3],
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

/// Builds a Foundry from the text of a scene file; `source` names it in errors and `dir` is
/// where relative mesh and grid paths start.
pub fn scene_from_toml(text: &str, source: &str, dir: &Path) -> anyhow::Result<Foundry> {
    render_scene_from_toml(text, source, dir).map(|(f, _)| f)
}

/// The render description of a parsed scene file, checked.
fn render_spec(file: &SceneFile, source: &str) -> anyhow::Result<RenderSpec> {
    let mut solid_materials = BTreeMap::new();
    let named = file
        .solids
        .iter()
        .map(|(n, e)| (n, &e.material))
        .chain(file.meshes.iter().map(|(n, e)| (n, &e.material)));
    for (name, material) in named {
        if let Some(m) = material {
            solid_materials.insert(name.clone(), m.clone());
        }
    }
    let media = file
        .volumes
        .iter()
        .map(|(name, v)| {
            let optics = MediumOptics {
                albedo: v.albedo,
                g: v.g,
                emission: v.emission,
            };
            (name.clone(), optics)
        })
        .collect();
    let spec = RenderSpec {
        camera: file.camera.clone(),
        materials: file.materials.clone(),
        solid_materials,
        lights: file.lights.clone(),
        media,
        settings: file.render.clone().unwrap_or_default(),
        transparent_solids: Vec::new(),
    };
    spec.validate().with_context(|| source.to_string())?;
    Ok(spec)
}

/// A scene file's Foundry and its render description (camera, materials, lights, media
/// optics, settings).
pub fn render_scene_from_toml(
    text: &str,
    source: &str,
    dir: &Path,
) -> anyhow::Result<(Foundry, RenderSpec)> {
    let file: SceneFile =
        toml::from_str(text).with_context(|| format!("{source}: not a valid scene file"))?;
    let spec = render_spec(&file, source)?;
    if file.solids.is_empty() && file.meshes.is_empty() && file.volumes.is_empty() {
        bail!("{source}: no [solids.NAME], [meshes.NAME] or [volumes.NAME] entries");
    }
    let mut f = Foundry::new();
    // Name -> (solid, centre its vertices are relative to).
    let mut index: BTreeMap<String, (u32, [f64; 3])> = BTreeMap::new();
    let mut claim = |name: &String, entry: (u32, [f64; 3])| {
        if index.insert(name.clone(), entry).is_some() {
            bail!("{source}: `{name}` names two entries (solids, meshes and volumes share names)");
        }
        Ok(())
    };
    for (name, entry) in &file.solids {
        let identity = f.solid.len() as u32;
        let shape = parse_shape(&entry.shape)
            .with_context(|| format!("{source}: solid `{name}`: shape `{}`", entry.shape))?;
        let tree = to_tree(&shape).with_context(|| format!("{source}: solid `{name}`"))?;
        let mut s = f.begin_solid(name);
        s.add_csg(tree, identity, UNSET)?;
        claim(name, (s.finish(identity)?, [0.0; 3]))?;
    }
    for (name, entry) in &file.meshes {
        let solid = add_mesh_file_solid(&mut f, name, &dir.join(&entry.file))
            .with_context(|| format!("{source}: mesh `{name}`"))?;
        claim(name, solid)?;
    }
    for (name, entry) in &file.volumes {
        let spec = volume_spec(entry, dir).with_context(|| format!("{source}: volume `{name}`"))?;
        let identity = f.solid.len() as u32;
        let solid = add_medium_solid(&mut f, name, &spec, identity)
            .with_context(|| format!("{source}: volume `{name}`"))?;
        claim(name, (solid, [0.0; 3]))?;
    }
    let mut placed = vec![false; f.solid.len()];
    let mut centres = vec![[0.0; 3]; f.solid.len()];
    for &(solid, centre) in index.values() {
        centres[solid as usize] = centre;
    }
    for (k, p) in file.place.iter().enumerate() {
        let &(solid, centre) = index
            .get(&p.solid)
            .with_context(|| format!("{source}: place {k}: unknown solid `{}`", p.solid))?;
        let t = placement_transform(p).with_context(|| format!("{source}: place {k}"))?;
        let t = t.compose(&Transform64::translation(centre));
        f.add_instance(solid, t, k as u32, p.copy.unwrap_or(k as i32))?;
        placed[solid as usize] = true;
    }
    for (solid, was_placed) in placed.iter().enumerate() {
        if !was_placed {
            let t = Transform64::translation(centres[solid]);
            f.add_instance(solid as u32, t, UNSET, 0)?;
        }
    }
    f.validate()
        .with_context(|| format!("{source}: built an invalid Foundry"))?;
    Ok((f, spec))
}

/// A volume entry as a medium: file sources resolved against `dir`.
fn volume_spec(entry: &VolumeEntry, dir: &Path) -> anyhow::Result<MediumSpec> {
    let source = if is_procedural(&entry.source) {
        entry.source.clone()
    } else {
        dir.join(&entry.source).display().to_string()
    };
    let format = match &entry.format {
        Some(name) => TexelFormat::from_str(name)?,
        None => TexelFormat::F32,
    };
    Ok(MediumSpec {
        source,
        grid: entry.grid.clone(),
        density_scale: entry.density_scale,
        format,
        placement: Transform64::IDENTITY,
    })
}

/// Reads a scene file.
pub fn load_toml_scene(path: &Path) -> anyhow::Result<Foundry> {
    load_toml_render_scene(path).map(|(f, _)| f)
}

/// Reads a scene file with its render description.
pub fn load_toml_render_scene(path: &Path) -> anyhow::Result<(Foundry, RenderSpec)> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let dir = path.parent().unwrap_or(Path::new("."));
    render_scene_from_toml(&text, &path.display().to_string(), dir)
}
