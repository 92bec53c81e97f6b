//! Participating media in scenes: a voxel grid (NanoVDB, OpenVDB or procedural) placed in a
//! solid's frame as a volume prim of 8^3 bricks, with its [`Medium`] record.

use crate::error::{ensure, Context};
use hytrace_foundry::optics::Medium;
use hytrace_foundry::{Foundry, Transform64};
use hytrace_volume::{BrickedGrid, GridMap, TexelFormat, VoxelGrid};

/// A medium to add to a scene.
#[derive(Clone, Debug)]
pub struct MediumSpec {
    /// A .nvdb or .vdb path, or a procedural grid (`sphere:...`, `box:...`).
    pub source: String,
    /// Grid name inside the source (`None`: the first grid).
    pub grid: Option<String>,
    /// Extinction per unit length per unit of grid value.
    pub density_scale: f64,
    /// Texel format of the bricked grid.
    pub format: TexelFormat,
    /// Placement of the grid's world frame in the solid's frame.
    pub placement: Transform64,
}

/// The index-to-world map of a grid as a Foundry transform.
pub fn grid_map_transform(map: &GridMap) -> Transform64 {
    let (m, t) = (&map.matrix, &map.translation);
    Transform64 {
        rows: [
            [m[0][0], m[0][1], m[0][2], t[0]],
            [m[1][0], m[1][1], m[1][2], t[1]],
            [m[2][0], m[2][1], m[2][2], t[2]],
            [0.0, 0.0, 0.0, 1.0],
        ],
    }
}

/// Opens the grid of `spec` as a bricked grid in its texel format; errors name the source.
pub fn open_medium(spec: &MediumSpec) -> crate::Result<BrickedGrid> {
    let (_, volume) = crate::volume::open(&spec.source, spec.grid.as_deref())?;
    // Outside its bricks a medium is the background everywhere: only 0 keeps it finite.
    ensure!(
        volume.background() == 0.0,
        "{}: a scene medium needs a zero background, the grid's is {}",
        spec.source,
        volume.background()
    );
    BrickedGrid::convert(&volume, spec.format)
        .with_context(|| format!("{}: bricking the grid", spec.source))
}

/// Appends a solid made of one volume prim holding the grid of `spec`, and its medium;
/// returns the solid. `identity` is stored in the prim and the solid.
pub fn add_medium_solid(
    f: &mut Foundry,
    name: &str,
    spec: &MediumSpec,
    identity: u32,
) -> crate::Result<u32> {
    ensure!(
        spec.density_scale.is_finite() && spec.density_scale >= 0.0,
        "medium `{name}`: the density scale must be finite and >= 0, got {}",
        spec.density_scale
    );
    let grid = open_medium(spec).with_context(|| format!("medium `{name}`"))?;
    let bricks = grid.foundry_bricks();
    ensure!(
        !bricks.is_empty(),
        "medium `{name}`: {} has no voxel other than the background",
        spec.source
    );
    let index_to_solid = spec.placement.compose(&grid_map_transform(grid.map()));
    let mut s = f.begin_solid(name);
    let prim = s.add_volume(&bricks, Some(index_to_solid), identity)?;
    let solid = s.finish(identity)?;
    f.optics.media.push(Medium {
        prim: prim as u32,
        source: spec.source.clone(),
        grid: spec.grid.clone(),
        density_scale: spec.density_scale,
        format: spec.format.to_string(),
    });
    Ok(solid)
}
