//! Tracers, rendering and the `hytrace` command-line tool.
//!
//! This crate owns the GPU layer ([`gpu`]: wgpu device, WGSL composition, the Foundry's
//! upload as eight storage buffers and the kernels with their CPU twins) and the scenes the
//! command line reads ([`scene`]).

pub mod accuracy;
pub mod choice;
pub mod cpu;
#[cfg(feature = "embree")]
pub mod embree;
pub mod error;
pub mod gpu;
pub mod memory;
pub mod number_list;
pub mod outputs;
pub mod photons;
pub mod progress;
pub mod render;
pub mod report;
pub mod scan;
pub mod scene;
pub mod sweep;
pub mod volume;

pub use error::{Error, Result};
