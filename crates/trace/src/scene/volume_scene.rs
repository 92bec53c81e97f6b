//! A voxel grid rendered on its own (`hytrace render VOLUME`): the grid placed where its
//! file puts it, seen from an automatic camera through an automatic transfer function.
//!
//! The rule (also in `docs/rendering.md`):
//! - camera: the automatic 3/4 view ([`auto_camera`]) of the grid's active bounding box;
//! - extinction `density_scale * value`, with `density_scale` chosen so that the median
//!   ray through the box has an optical depth of [`TARGET_DEPTH`]: rays along the view
//!   direction through a [`CALIBRATION_RAYS`]² lattice spanning the box as the camera sees
//!   it, the median taken over those of positive optical depth;
//! - emission-absorption, the medium glowing [`EMISSION`] times `value / max` (its source
//!   over its extinction: the densest voxels glow at the full colour) in front of the
//!   environment [`BACKGROUND`]. The glow has no blue, so a pixel's blue channel is the
//!   background's seen through the medium: `T * BACKGROUND[2]`.

use std::path::Path;

use crate::error::{ensure, Context};
use glam::DVec3;
use hytrace_foundry::{Foundry, Transform64, UNSET};
use hytrace_volume::{
    global_range, is_brick_store, is_procedural, transmittance_batch, Estimator, Ray,
    TransmittanceParams,
};

use super::media::{add_medium_solid, MediumSpec};
use crate::render::auto_camera;
use crate::render::spec::{Light, MediumOptics, RenderSpec, VolumeMode};

/// Optical depth of the median ray through the box under the automatic transfer function.
pub const TARGET_DEPTH: f64 = 1.5;
/// Rays per side of the lattice the density scale is calibrated on.
pub const CALIBRATION_RAYS: usize = 32;
/// Colour the densest voxels glow at (no blue: see the module documentation).
pub const EMISSION: [f64; 3] = [1.0, 0.45, 0.0];
/// Radiance of the environment behind the grid: a dark blue.
pub const BACKGROUND: [f64; 3] = [0.02, 0.03, 0.09];

/// Whether `arg` names a volume rendered on its own: a .nvdb or .vdb file, a brick store
/// directory or a procedural grid (`sphere:...`, `box:...`).
pub fn is_volume_source(arg: &Path) -> bool {
    let volume_file = !arg.is_dir()
        && arg
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("nvdb") || e.eq_ignore_ascii_case("vdb"));
    volume_file || is_brick_store(arg) || arg.to_str().is_some_and(is_procedural)
}

/// The scene of grid `source` rendered on its own: one medium placed once, the automatic
/// camera and transfer function. Errors name the source (an unreadable or truncated
/// file, a grid with no value above zero).
pub fn load_volume_render_scene(source: &Path) -> crate::Result<(Foundry, RenderSpec)> {
    let name = source.display().to_string();
    let (summary, volume) = crate::volume::open(&name, None)?;
    let mips = volume.range_mips().with_context(|| name.clone())?;
    let max = global_range(&mips).max as f64;
    ensure!(
        max > 0.0,
        "{name}: no value above zero: nothing to render as a fog"
    );
    let bbox = summary
        .world_bbox
        .with_context(|| format!("{name}: the grid has no active voxel"))?;
    let camera = auto_camera(Some(bbox));
    let w = (DVec3::from(camera.target) - DVec3::from(camera.eye)).normalize();
    let rays = calibration_rays(bbox, w);
    // Optical depths at a scale that keeps every one below 1 (no transmittance underflows),
    // then brought to scale 1.
    let [lo, hi] = bbox.map(DVec3::from);
    let probe = 1.0 / (max * (hi - lo).length().max(f64::MIN_POSITIVE));
    let mut params = TransmittanceParams::new(Estimator::Exact);
    params.density_scale = probe;
    let mut depths: Vec<f64> = transmittance_batch(&volume, &mips, &rays, &params)
        .with_context(|| format!("{name}: calibrating the density scale"))?
        .iter()
        .map(|e| -e.transmittance.ln() / probe)
        .filter(|&tau| tau > 0.0)
        .collect();
    volume.check_reads()?;
    ensure!(
        !depths.is_empty(),
        "{name}: no ray through the grid's bounding box meets a value above zero"
    );
    depths.sort_by(f64::total_cmp);
    let density_scale = TARGET_DEPTH / depths[depths.len() / 2];

    let spec = MediumSpec::of_source(name.clone(), None, density_scale);
    let mut f = Foundry::new();
    let solid = add_medium_solid(&mut f, "volume", &spec, 0)?;
    f.add_instance(solid, Transform64::IDENTITY, UNSET, 0)?;
    let mut render = RenderSpec {
        camera: Some(camera),
        lights: vec![Light::Environment {
            radiance: BACKGROUND,
        }],
        ..RenderSpec::default()
    };
    render.settings.volumes = Some(VolumeMode::EmissionAbsorption);
    render.media.insert(
        "volume".to_string(),
        MediumOptics {
            emission: EMISSION.map(|c| c / max),
            ..MediumOptics::default()
        },
    );
    Ok((f, render))
}

/// Rays along `w` through a [`CALIBRATION_RAYS`]² lattice of cell centres spanning the
/// projection of `bbox` on the plane across `w`, each over the whole box.
fn calibration_rays(bbox: [[f64; 3]; 2], w: DVec3) -> Vec<Ray> {
    let [lo, hi] = bbox.map(DVec3::from);
    let centre = 0.5 * (lo + hi);
    let radius = 0.5 * (hi - lo).length() * (1.0 + 1e-9) + f64::MIN_POSITIVE;
    // The camera's right and up (see `render::camera`).
    let u = w.cross(DVec3::Z).try_normalize().unwrap_or(DVec3::X);
    let v = u.cross(w);
    let (mut a, mut b) = (
        [f64::INFINITY, f64::NEG_INFINITY],
        [f64::INFINITY, f64::NEG_INFINITY],
    );
    for corner in 0..8 {
        let p = DVec3::select(
            glam::BVec3::new(corner & 1 != 0, corner & 2 != 0, corner & 4 != 0),
            hi,
            lo,
        ) - centre;
        a = [a[0].min(p.dot(u)), a[1].max(p.dot(u))];
        b = [b[0].min(p.dot(v)), b[1].max(p.dot(v))];
    }
    let n = CALIBRATION_RAYS;
    let at =
        |range: [f64; 2], k: usize| range[0] + (k as f64 + 0.5) / n as f64 * (range[1] - range[0]);
    (0..n * n)
        .map(|k| {
            let origin = centre + at(a, k % n) * u + at(b, k / n) * v - radius * w;
            Ray::new(origin.into(), w.into(), 0.0, 2.0 * radius)
        })
        .collect()
}
