//! Sparse volumes for hytrace.
//!
//! Index-space convention (as OpenVDB and NanoVDB): voxel centres sit at integer coordinates;
//! a nearest lookup reads the voxel at `floor(p + 0.5)`, a trilinear lookup blends the eight
//! voxels around `p`; inactive voxels and voxels outside the grid read as the background.
//!
//! Every voxel source ([`DenseGrid`], procedural grids such as [`fog_sphere`]) implements
//! [`VoxelGrid`]; the lookups ([`sample`]) and the halo-inclusive range mips ([`RangeMips`])
//! work on any of them. [`bricks`] cuts a grid into 8^3 Foundry bricks whose value ranges
//! include a one-voxel halo, so a brick's `value_max` bounds every lookup inside its bounds.

mod bricks;
mod dense;
mod grid;
mod procedural;
mod procedural_spec;
mod ranges;
mod source;

pub use bricks::{bricks, BRICK_SIZE};
pub use dense::{DenseGrid, VolumeError};
pub use grid::{
    sample, sample_nearest, sample_stochastic, sample_trilinear, Coord, Filter, GridMap, VoxelGrid,
    BLOCK_SIDE,
};
pub use procedural::{fog_box, fog_sphere};
pub use procedural_spec::{is_procedural, procedural_grid};
pub use ranges::{RangeLevel, RangeMips, ValueRange, MAX_RANGE_BLOCKS, RANGE_LEVELS};
pub use source::{open_volume, select_grid, world_bbox, GridSummary, NamedVolume, Volume};
