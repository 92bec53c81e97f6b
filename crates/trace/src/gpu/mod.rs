//! GPU compute through wgpu: device setup, WGSL composition, scene upload and kernels.

pub mod compose;
mod context;
pub mod probe;
mod scene;

pub use context::{GpuContext, GpuError};
pub use scene::GpuScene;
