//! Scenes: the embedded default scene and loading a scene argument.

mod default;
mod gdml_scene;
mod media;
mod mesh_scene;
mod toml_scene;
mod volume_scene;

use std::path::Path;

use crate::error::{bail, Context};
use hytrace_foundry::gdml::GdmlOptions;
use hytrace_foundry::Foundry;

use crate::render::detector::{foundry_labels, DetectorStyle};
use crate::render::spec::RenderSpec;

pub use default::{default_render_spec, default_scene};
pub use gdml_scene::{
    gdml_to_foundry, gdml_to_foundry_with_surfaces, load_gdml_scene, load_gdml_scene_with_surfaces,
    VolumeSurfaces, GDML_MESH_TOLERANCE,
};
pub use media::{
    add_medium_solid, grid_map_transform, open_medium, MediumGrid, MediumSpec, STORED_FORMAT,
};
pub use mesh_scene::{add_mesh_file_solid, gltf_to_foundry, load_mesh_scene, obj_to_foundry};
pub use toml_scene::{
    load_toml_render_scene, load_toml_scene, render_scene_from_toml, scene_from_toml,
};
pub use volume_scene::{
    is_volume_source, load_volume_render_scene, BACKGROUND, CALIBRATION_RAYS, EMISSION,
    TARGET_DEPTH,
};

/// Loads the scene named on the command line: none or `default` gives the embedded default
/// scene; a directory is read as a Foundry written by `hytrace foundry`; a `.toml` file is a
/// scene file of CSG expressions (see [`scene_from_toml`]); a `.gdml` file is read with
/// Geant4's semantics (see [`load_gdml_scene`]); an `.obj`, `.gltf` or `.glb` file is a
/// triangle-mesh scene (see [`load_mesh_scene`]).
pub fn load_scene(arg: Option<&Path>, options: &GdmlOptions) -> crate::Result<Foundry> {
    match arg {
        None => default_scene(),
        Some(p) if p.as_os_str() == "default" => default_scene(),
        Some(p) if p.is_dir() => Foundry::load(p).with_context(|| format!("loading Foundry directory {}", p.display())),
        Some(p) if p.extension().is_some_and(|e| e == "toml") => load_toml_scene(p),
        Some(p) if p.extension().is_some_and(|e| e.eq_ignore_ascii_case("gdml")) => {
            load_gdml_scene(p, options)
        }
        Some(p)
            if p.extension().is_some_and(|e| {
                ["obj", "gltf", "glb"]
                    .iter()
                    .any(|m| e.eq_ignore_ascii_case(m))
            }) =>
        {
            load_mesh_scene(p)
        }
        Some(p) if !p.exists() => Err(std::io::Error::new(
            std::io::ErrorKind::NotFound,
            format!("{}: no such file or directory", p.display()),
        )
        .into()),
        Some(p) => bail!(
            "{}: not a scene this build reads (expected `default`, a Foundry directory with meta.json, a .toml scene file, a .gdml file or an .obj, .gltf or .glb mesh)",
            p.display()
        ),
    }
}

/// Loads a scene as [`load_scene`] does, with its render description: a scene file's own
/// (camera, materials, lights, media, settings), the default scene's, or for other scenes
/// the defaults (an automatic camera, grey diffuse solids, default lights). A hierarchical
/// scene (GDML) gets the default detector view ([`DetectorStyle`]): the world invisible,
/// envelopes as faint shells, their contents solid, coloured by material. A volume (a .nvdb
/// or .vdb file, a brick store, a procedural grid) is rendered on its own, with an
/// automatic camera and transfer function ([`load_volume_render_scene`]).
pub fn load_render_scene(
    arg: Option<&Path>,
    options: &GdmlOptions,
) -> crate::Result<(Foundry, RenderSpec)> {
    let is_default = arg.is_none_or(|p| p.as_os_str() == "default");
    if is_default {
        return Ok((default_scene()?, default_render_spec()));
    }
    if let Some(p) = arg.filter(|p| is_volume_source(p)) {
        return load_volume_render_scene(p);
    }
    if let Some(p) = arg.filter(|p| p.extension().is_some_and(|e| e == "toml") && !p.is_dir()) {
        return load_toml_render_scene(p);
    }
    let is_gdml = arg.is_some_and(|p| {
        !p.is_dir()
            && p.extension()
                .is_some_and(|e| e.eq_ignore_ascii_case("gdml"))
    });
    let (f, volumes) = match arg {
        Some(p) if is_gdml => gdml_scene::load_gdml_render_scene(p, options)?,
        _ => {
            let f = load_scene(arg, options)?;
            let labels = foundry_labels(&f);
            (f, labels)
        }
    };
    let mut spec = RenderSpec {
        transparent_solids: gdml_scene::world_solids(&f),
        ..RenderSpec::default()
    };
    if !volumes.is_empty() {
        spec.instance_materials = DetectorStyle::default().apply(&f, &volumes)?.materials;
        spec.volumes = volumes;
    }
    Ok((f, spec))
}
