//! Sparse volumes for hytrace.
//!
//! Index-space convention (as OpenVDB and NanoVDB): voxel centres sit at integer coordinates;
//! a nearest lookup reads the voxel at `floor(p + 0.5)`, a trilinear lookup blends the eight
//! voxels around `p`; inactive voxels and voxels outside the grid read as the background.
//!
//! Every voxel source ([`DenseGrid`], procedural grids such as [`fog_sphere`]) implements
//! [`VoxelGrid`]; the lookups ([`sample`]) and the halo-inclusive range mips ([`RangeMips`])
//! work on any of them. [`BrickedGrid`] stores a grid as quantized 8^3 bricks for the GPU;
//! its [`BrickedGrid::foundry_bricks`] are Foundry bricks whose value ranges include a
//! one-voxel halo, so a brick's `value_max` bounds every lookup inside its bounds.

mod brick_store;
mod bricked;
mod bricks;
mod codec;
mod dda;
mod decode_error;
mod dense;
mod grid;
mod nanovdb;
mod openvdb;
mod procedural;
mod procedural_spec;
mod ranges;
mod rng;
mod source;
mod transmittance;

pub use brick_store::{
    convert_grid, convert_raw, is_brick_store, planned_memory, BrickStore, CacheStats,
    ConvertOptions, ConvertReport, Endian, Quantization, RawSpec, RawType, StoreError, StoreMeta,
    BRICK_BYTES, LOD_VALUES, STORE_FORMAT, STORE_VERSION, SUPERCHUNK_BRICKS,
};
pub use bricked::{BrickEntry, BrickedGrid, MemoryBreakdown, TexelFormat, NO_BRICK, NO_SLOT};
pub use dda::{
    global_range, CellPiece, CellWalk, IndexRay, Ray, Segment, SegmentWalk, LEVEL_GLOBAL,
    LEVEL_OUTSIDE,
};
pub use dense::{DenseGrid, VolumeError};
pub use grid::{
    sample, sample_nearest, sample_stochastic, sample_trilinear, Coord, Filter, GridMap, VoxelGrid,
    BLOCK_SIDE,
};
pub use nanovdb::{
    parse_nanovdb, read_nanovdb, NanoCodec, NanoError, NanoFile, NanoGrid, NanoGridClass,
    NanoGridType, NanoVersion, NodeCounts, TileCounts,
};
pub use openvdb::{read_vdb, VdbFile, VdbGrid, VdbGridInfo};
pub use procedural::{fog_box, fog_sphere};
pub use procedural_spec::{is_procedural, procedural_grid};
pub use ranges::{RangeLevel, RangeMips, ValueRange, MAX_RANGE_BLOCKS, RANGE_LEVELS};
pub use rng::{pcg4d, Rng};
pub use source::{
    open_volume, open_volume_with, select_grid, world_bbox, GridSummary, NamedVolume, Unsampleable,
    Volume, DEFAULT_STORE_BUDGET,
};
pub use transmittance::{
    transmittance, transmittance_batch, Collision, Estimate, Estimator, IndexTransmittance,
    Majorant, TransmittanceParams, MAX_TRACKED_LOOKUPS,
};
