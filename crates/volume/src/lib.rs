//! Sparse volumes for hytrace.
//!
//! Index-space convention (as OpenVDB and NanoVDB): voxel centres sit at integer coordinates;
//! a nearest lookup reads the voxel at `floor(p + 0.5)`, a trilinear lookup blends the eight
//! voxels around `p`; voxels outside the grid read as the background.
//!
//! [`DenseGrid`] holds voxels in a box of index space; [`fog_sphere`] makes one procedurally;
//! [`bricks`] cuts a grid into 8^3 Foundry bricks whose value ranges include a one-voxel halo,
//! so a brick's `value_max` bounds every trilinear lookup inside its bounds (a true majorant).

mod bricks;
mod dense;
mod procedural;

pub use bricks::{bricks, BRICK_SIZE};
pub use dense::{DenseGrid, VolumeError};
pub use procedural::fog_sphere;
