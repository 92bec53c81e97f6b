//! Scene files (TOML): CSG solids written as expressions (see [`hytrace_csg::expr`]), triangle
//! meshes from files, participating media from voxel grids, GDML detectors, and their
//! placements.
//!
//! ```toml
//! [solids.vessel]
//! shape = "tube(0, 1000, -500, 500) - sphere(300).translate(0, 0, 200)"
//!
//! [meshes.bunny]
//! file = "bunny.obj"               # .obj, .gltf or .glb, relative to the scene file
//!
//! [volumes.fog]
//! source = "sphere:400,10"         # .nvdb, .vdb, a brick store (relative to the scene
//!                                  # file) or procedural
//! grid = "density"                 # optional: grid name (default: the first)
//! density_scale = 0.002            # extinction per mm at grid value 1
//! format = "f32"                   # optional: bricked texel format (f32, f16, unorm16,
//!                                  # unorm8, bc4); a brick store without one is read
//!                                  # lazily, as stored
//!
//! [gdml.detector]
//! file = "detector.gdml"           # relative to the scene file; its solids are named
//!                                  # `detector/SOLID`
//! material = "steel"               # optional: render material of all its solids
//! materials = { PMT = "glass" }    # optional: by GDML solid or logical volume name
//!
//! [[place]]
//! solid = "vessel"                 # any solid, mesh, volume or gdml name
//! translate = [0, 0, 100]          # mm, optional
//! rotate = [0, 0, 1, 90]           # axis xyz and degrees, optional
//! copy = 3                         # copy number, optional (default: placement index;
//!                                  # not for gdml, whose volumes keep their own)
//! ```
//!
//! Rendering adds `[camera]`, `[materials.NAME]`, `[[lights]]` and `[render]` tables, a
//! `material` on solids, meshes and gdml entries and `albedo`, `g` and `emission` on volumes
//! (see [`crate::render::spec`]); scans ignore them.
//!
//! Names are shared by solids, meshes, volumes and gdml entries. Placements apply the
//! rotation first, then the translation. Anything without placements is placed once at the
//! origin. The Foundry lists CSG solids, then meshes, then volumes, then the solids of each
//! GDML file, each in name order; its instances are the placements in file order, then the
//! unplaced solids, then one copy of each GDML file's whole hierarchy per placement (see
//! [`Foundry::append`]), with the file's boundaries, materials, surfaces and copy numbers.
//! Media need a grid with a zero background; their bricks are made in the given texel
//! format, which the tracers sample.
//!
//! A GDML world is rendered transparent, as for a GDML scene on its own. Its copies are
//! traced as Geant4's navigator traces the file alone: a ray starting inside a copy's world
//! meets only that world's daughters and boundary, so other entries placed inside a GDML
//! world's volume are seen from outside it only. A `materials` key naming a logical volume
//! stands for its solid; logical volumes sharing a solid share its material.

use std::collections::BTreeMap;
use std::path::Path;
use std::str::FromStr;

use crate::error::{bail, Context};
use hytrace_csg::{parse_shape, to_tree};
use hytrace_foundry::gdml::{read_gdml, GdmlOptions};
use hytrace_foundry::{pack_label, Foundry, Transform64, UNSET};
use hytrace_volume::{is_procedural, TexelFormat};
use serde::Deserialize;

use super::gdml_scene::{gdml_to_foundry, world_solids};
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
    gdml: BTreeMap<String, GdmlEntry>,
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
struct GdmlEntry {
    file: String,
    #[serde(default)]
    material: Option<String>,
    #[serde(default)]
    materials: BTreeMap<String, String>,
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

fn placement_transform(p: &Placement) -> crate::Result<Transform64> {
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

/// `text` cut to its first and last 30 characters when longer than 80, for messages.
fn abridged(text: &str) -> String {
    let chars: Vec<char> = text.chars().collect();
    if chars.len() <= 80 {
        return text.to_string();
    }
    let head: String = chars[..30].iter().collect();
    let tail: String = chars[chars.len() - 30..].iter().collect();
    format!("{head} ... {tail}")
}

/// Builds a Foundry from the text of a scene file; `source` names it in errors and `dir` is
/// where relative mesh and grid paths start.
pub fn scene_from_toml(text: &str, source: &str, dir: &Path) -> crate::Result<Foundry> {
    render_scene_from_toml(text, source, dir).map(|(f, _)| f)
}

/// The render description of a parsed scene file, checked.
fn render_spec(file: &SceneFile, source: &str) -> crate::Result<RenderSpec> {
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
        ..RenderSpec::default()
    };
    spec.validate().with_context(|| source.to_string())?;
    Ok(spec)
}

/// What a scene name stands for.
#[derive(Clone, Copy)]
enum Entry {
    /// A solid, mesh or volume: its solid and the centre its vertices are relative to.
    Solid(u32, [f64; 3]),
    /// A GDML entry: its index in name order.
    Gdml(usize),
}

/// A scene file's Foundry and its render description (camera, materials, lights, media
/// optics, settings).
pub fn render_scene_from_toml(
    text: &str,
    source: &str,
    dir: &Path,
) -> crate::Result<(Foundry, RenderSpec)> {
    let file: SceneFile =
        toml::from_str(text).with_context(|| format!("{source}: not a valid scene file"))?;
    let mut spec = render_spec(&file, source)?;
    if file.solids.is_empty()
        && file.meshes.is_empty()
        && file.volumes.is_empty()
        && file.gdml.is_empty()
    {
        bail!("{source}: no [solids.NAME], [meshes.NAME], [volumes.NAME] or [gdml.NAME] entries");
    }
    let mut f = Foundry::new();
    let mut index: BTreeMap<String, Entry> = BTreeMap::new();
    let mut claim = |name: &String, entry: Entry| {
        if index.insert(name.clone(), entry).is_some() {
            bail!(
                "{source}: `{name}` names two entries (solids, meshes, volumes and gdml share names)"
            );
        }
        Ok(())
    };
    for (name, entry) in &file.solids {
        let identity = f.solid.len() as u32;
        let shape = parse_shape(&entry.shape).with_context(|| {
            format!(
                "{source}: solid `{name}`: shape `{}`",
                abridged(&entry.shape)
            )
        })?;
        let tree = to_tree(&shape).with_context(|| format!("{source}: solid `{name}`"))?;
        let mut s = f.begin_solid(name);
        s.add_csg(tree, identity, UNSET)?;
        claim(name, Entry::Solid(s.finish(identity)?, [0.0; 3]))?;
    }
    for (name, entry) in &file.meshes {
        let (solid, centre) = add_mesh_file_solid(&mut f, name, &dir.join(&entry.file))
            .with_context(|| format!("{source}: mesh `{name}`"))?;
        claim(name, Entry::Solid(solid, centre))?;
    }
    for (name, entry) in &file.volumes {
        let spec = volume_spec(entry, dir).with_context(|| format!("{source}: volume `{name}`"))?;
        let identity = f.solid.len() as u32;
        let solid = add_medium_solid(&mut f, name, &spec, identity)
            .with_context(|| format!("{source}: volume `{name}`"))?;
        // What photons meet there (renders take it from the render description).
        if let Some(m) = f.optics.media.last_mut() {
            (m.albedo, m.g) = (entry.albedo, entry.g);
        }
        claim(name, Entry::Solid(solid, [0.0; 3]))?;
    }
    let mut gdml = Vec::with_capacity(file.gdml.len());
    for (k, (name, entry)) in file.gdml.iter().enumerate() {
        claim(name, Entry::Gdml(k))?;
        let part = gdml_part(name, entry, &file.materials, dir)
            .with_context(|| format!("{source}: gdml `{name}`"))?;
        gdml.push(part);
    }
    check_solid_names(&f, &gdml).with_context(|| source.to_string())?;

    let mut placed = vec![false; f.solid.len()];
    let mut centres = vec![[0.0; 3]; f.solid.len()];
    for entry in index.values() {
        if let &Entry::Solid(solid, centre) = entry {
            centres[solid as usize] = centre;
        }
    }
    for (k, p) in file.place.iter().enumerate() {
        let entry = index
            .get(&p.solid)
            .with_context(|| format!("{source}: place {k}: unknown solid `{}`", p.solid))?;
        let t = placement_transform(p).with_context(|| format!("{source}: place {k}"))?;
        match *entry {
            Entry::Solid(solid, centre) => {
                let t = t.compose(&Transform64::translation(centre));
                f.add_instance(solid, t, k as u32, p.copy.unwrap_or(k as i32))?;
                placed[solid as usize] = true;
            }
            Entry::Gdml(g) if p.copy.is_some() => bail!(
                "{source}: place {k}: gdml `{}` keeps its own copy numbers, `copy` does not apply",
                gdml[g].name
            ),
            Entry::Gdml(g) => gdml[g].placements.push(t),
        }
    }
    for (solid, was_placed) in placed.iter().enumerate() {
        if !was_placed {
            let t = Transform64::translation(centres[solid]);
            f.add_instance(solid as u32, t, UNSET, 0)?;
        }
    }
    // Each GDML hierarchy is appended once, with every placement a copy of it.
    for mut part in gdml {
        if part.placements.is_empty() {
            part.placements.push(Transform64::IDENTITY);
        }
        f.append(&part.foundry, &part.placements)
            .with_context(|| format!("{source}: gdml `{}`", part.name))?;
        spec.solid_materials.extend(part.solid_materials);
        spec.transparent_solids.extend(part.transparent_solids);
    }
    f.validate()
        .with_context(|| format!("{source}: built an invalid Foundry"))?;
    Ok((f, spec))
}

/// A GDML entry read: its Foundry with solids named `NAME/solid`, the render materials of
/// those solids, and its world's solid, rendered transparent.
struct GdmlPart {
    name: String,
    foundry: Foundry,
    placements: Vec<Transform64>,
    solid_materials: BTreeMap<String, String>,
    transparent_solids: Vec<String>,
}

/// Reads the GDML file of entry `name` (relative to `dir`) and assigns the render
/// materials it names (which `materials` must define).
fn gdml_part(
    name: &str,
    entry: &GdmlEntry,
    materials: &BTreeMap<String, Material>,
    dir: &Path,
) -> crate::Result<GdmlPart> {
    for m in entry.material.iter().chain(entry.materials.values()) {
        if !materials.contains_key(m) {
            bail!("unknown material `{m}`");
        }
    }
    let path = dir.join(&entry.file);
    let g = read_gdml(&path, &GdmlOptions::default())?;
    let mut foundry =
        gdml_to_foundry(&g).with_context(|| format!("{}: building the scene", path.display()))?;
    // Render material of each GDML solid name: a key names a solid, or a logical volume
    // standing for its solid.
    let mut by_solid: BTreeMap<&str, (&str, &str)> = BTreeMap::new();
    for (key, material) in &entry.materials {
        let solids: Vec<&str> = g
            .solids
            .iter()
            .filter(|s| s.name == *key)
            .map(|s| s.name.as_str())
            .chain(
                g.volumes
                    .iter()
                    .filter(|v| v.name == *key)
                    .map(|v| g.solids[v.solid].name.as_str()),
            )
            .collect();
        if solids.is_empty() {
            bail!(
                "materials: `{key}` is neither a solid nor a logical volume of {}",
                path.display()
            );
        }
        for solid in solids {
            match by_solid.insert(solid, (key, material)) {
                Some((other, m)) if m != material => bail!(
                    "materials: `{other}` and `{key}` give solid `{solid}` two materials \
                     (`{m}` and `{material}`)"
                ),
                _ => {}
            }
        }
    }
    let mut solid_materials = BTreeMap::new();
    for (s, old) in foundry.solid.iter_mut().zip(&mut foundry.solid_names) {
        let material = by_solid
            .get(old.as_str())
            .map(|&(_, m)| m)
            .or(entry.material.as_deref());
        let renamed = format!("{name}/{old}");
        s.label = pack_label(&renamed);
        if let Some(m) = material {
            solid_materials.insert(renamed.clone(), m.to_string());
        }
        *old = renamed;
    }
    // As for a GDML scene on its own: the world (no mother) is transparent.
    let transparent_solids = world_solids(&foundry);
    Ok(GdmlPart {
        name: name.to_string(),
        foundry,
        placements: Vec::new(),
        solid_materials,
        transparent_solids,
    })
}

/// Fails when a GDML entry's solid, once prefixed, has the name of another entry's solid
/// (materials and transparency are assigned by solid name).
fn check_solid_names(f: &Foundry, gdml: &[GdmlPart]) -> crate::Result<()> {
    // Solid name -> entry name; a solid, mesh or volume entry names its one solid.
    let mut owner: BTreeMap<&str, &str> = f
        .solid_names
        .iter()
        .map(|n| (n.as_str(), n.as_str()))
        .collect();
    for part in gdml {
        for solid in &part.foundry.solid_names {
            match owner.insert(solid, &part.name) {
                Some(other) if other != part.name => bail!(
                    "gdml `{}`: its solid `{solid}` has the name of a solid of entry `{other}`",
                    part.name
                ),
                _ => {}
            }
        }
    }
    Ok(())
}

/// A volume entry as a medium: file sources resolved against `dir`.
fn volume_spec(entry: &VolumeEntry, dir: &Path) -> crate::Result<MediumSpec> {
    let source = if is_procedural(&entry.source) {
        entry.source.clone()
    } else {
        dir.join(&entry.source).display().to_string()
    };
    // A brick store is read as stored unless a format asks to brick it in memory.
    let mut spec = MediumSpec::of_source(source, entry.grid.clone(), entry.density_scale);
    if let Some(name) = &entry.format {
        spec.format = Some(TexelFormat::from_str(name)?);
    }
    Ok(spec)
}

/// Reads a scene file.
pub fn load_toml_scene(path: &Path) -> crate::Result<Foundry> {
    load_toml_render_scene(path).map(|(f, _)| f)
}

/// Reads a scene file with its render description.
pub fn load_toml_render_scene(path: &Path) -> crate::Result<(Foundry, RenderSpec)> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let dir = path.parent().unwrap_or(Path::new("."));
    render_scene_from_toml(&text, &path.display().to_string(), dir)
}
