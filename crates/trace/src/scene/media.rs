//! Participating media in scenes: a voxel grid (NanoVDB, OpenVDB, procedural or a brick
//! store) placed in a solid's frame as a volume prim of 8^3 bricks, with its [`Medium`]
//! record.
//!
//! A medium is bricked in memory in its texel format, or, when its source is a brick store
//! and no format is given, read as stored: lazily, through the store's brick cache.

use std::path::Path;

use crate::error::{bail, ensure, Context};
use hytrace_foundry::optics::Medium;
use hytrace_foundry::{Brick, Foundry, Transform64};
use hytrace_volume::{
    is_brick_store, BrickStore, BrickedGrid, Coord, GridMap, RangeMips, TexelFormat, Volume,
    VolumeError, VoxelGrid, DEFAULT_STORE_BUDGET,
};

/// The format name of a medium read as stored in its brick store (in [`Medium::format`]).
pub const STORED_FORMAT: &str = "stored";

/// A medium to add to a scene.
#[derive(Clone, Debug)]
pub struct MediumSpec {
    /// A .nvdb or .vdb path, or a procedural grid (`sphere:...`, `box:...`).
    pub source: String,
    /// Grid name inside the source (`None`: the first grid).
    pub grid: Option<String>,
    /// Extinction per unit length per unit of grid value.
    pub density_scale: f64,
    /// Texel format of the bricked grid; `None` reads a brick store as stored (lazily).
    pub format: Option<TexelFormat>,
    /// Placement of the grid's world frame in the solid's frame.
    pub placement: Transform64,
}

impl MediumSpec {
    /// The grid `grid` (`None`: the first) of `source`, unplaced: a brick store read as
    /// stored, any other grid bricked in single-precision texels.
    pub fn of_source(source: String, grid: Option<String>, density_scale: f64) -> MediumSpec {
        let format = (!is_brick_store(Path::new(&source))).then_some(TexelFormat::F32);
        MediumSpec {
            source,
            grid,
            density_scale,
            format,
            placement: Transform64::IDENTITY,
        }
    }
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

/// A medium's voxels as the tracers read them.
pub enum MediumGrid {
    /// Bricked in memory.
    Bricked(Box<BrickedGrid>),
    /// A brick store read through its cache of bricks, with the range mips of its data
    /// ([`BrickStore::data_mips`]: those of the store bricked in memory).
    Store(Box<BrickStore>, Box<RangeMips>),
}

impl MediumGrid {
    /// The range mips lookups on this grid are bounded by.
    pub fn ranges(&self) -> &RangeMips {
        match self {
            MediumGrid::Bricked(g) => g.ranges(),
            MediumGrid::Store(_, mips) => mips,
        }
    }

    /// The bricked grid, `None` for a brick store.
    pub fn bricked(&self) -> Option<&BrickedGrid> {
        match self {
            MediumGrid::Bricked(g) => Some(g),
            MediumGrid::Store(..) => None,
        }
    }

    /// The brick store read as stored and the range mips walks over it take (those of its
    /// data), `None` for a grid bricked in memory.
    pub fn store(&self) -> Option<(&BrickStore, &RangeMips)> {
        match self {
            MediumGrid::Bricked(_) => None,
            MediumGrid::Store(s, mips) => Some((s, mips)),
        }
    }

    /// The grid with its index-to-world map replaced by `map`.
    pub fn with_map(self, map: GridMap) -> MediumGrid {
        match self {
            MediumGrid::Bricked(g) => MediumGrid::Bricked(Box::new(g.with_map(map))),
            MediumGrid::Store(s, mips) => MediumGrid::Store(Box::new(s.with_map(map)), mips),
        }
    }

    /// Its Foundry bricks (bounds and majorants).
    pub fn foundry_bricks(&self) -> Vec<Brick> {
        match self {
            MediumGrid::Bricked(g) => g.foundry_bricks(),
            MediumGrid::Store(s, _) => s.foundry_bricks(),
        }
    }

    /// An error when a brick store's reads failed since it was opened (its lookups then
    /// read the background, so results computed meanwhile are wrong).
    pub fn check_reads(&self) -> Result<(), VolumeError> {
        match self {
            MediumGrid::Bricked(_) => Ok(()),
            MediumGrid::Store(s, _) => s.check().map_err(|e| VolumeError(e.to_string())),
        }
    }

    fn grid(&self) -> &dyn VoxelGrid {
        match self {
            MediumGrid::Bricked(g) => g.as_ref(),
            MediumGrid::Store(s, _) => s.as_ref(),
        }
    }
}

impl VoxelGrid for MediumGrid {
    fn background(&self) -> f32 {
        self.grid().background()
    }

    fn voxel(&self, ijk: Coord) -> f32 {
        // The lookups' hot path: each grid's own, without a virtual call.
        match self {
            MediumGrid::Bricked(g) => g.voxel(ijk),
            MediumGrid::Store(s, _) => s.voxel(ijk),
        }
    }

    fn block_origins(&self) -> Result<Vec<Coord>, VolumeError> {
        self.grid().block_origins()
    }

    fn map(&self) -> &GridMap {
        self.grid().map()
    }

    fn read_box(&self, origin: Coord, dims: [u32; 3], out: &mut [f32]) {
        self.grid().read_box(origin, dims, out)
    }
}

/// Opens the grid of `spec`: bricked in its texel format, or a brick store read as stored
/// holding at most `memory` bytes resident; errors name the source.
pub fn open_medium(spec: &MediumSpec, memory: u64) -> crate::Result<MediumGrid> {
    let (_, volume) = crate::volume::open_within(&spec.source, spec.grid.as_deref(), memory)?;
    // Outside its bricks a medium is the background everywhere: only 0 keeps it finite.
    ensure!(
        volume.background() == 0.0,
        "{}: a scene medium needs a zero background, the grid's is {}",
        spec.source,
        volume.background()
    );
    match (spec.format, volume) {
        (None, Volume::Store(store)) => {
            let mips = store.data_mips().with_context(|| spec.source.clone())?;
            Ok(MediumGrid::Store(store, Box::new(mips)))
        }
        (None, _) => bail!(
            "{}: only a brick store is read as stored (format `{STORED_FORMAT}`); give a \
             texel format",
            spec.source
        ),
        (Some(format), volume) => Ok(MediumGrid::Bricked(Box::new(
            BrickedGrid::convert(&volume, format)
                .with_context(|| format!("{}: bricking the grid", spec.source))?,
        ))),
    }
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
    // Only the tables of a brick store are read here.
    let grid =
        open_medium(spec, DEFAULT_STORE_BUDGET).with_context(|| format!("medium `{name}`"))?;
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
        format: spec
            .format
            .map_or(STORED_FORMAT.to_string(), |f| f.to_string()),
        ..Medium::default()
    });
    Ok(solid)
}
