//! GPU compute through wgpu: device setup, WGSL composition, scene upload and kernels.

mod brick_pool;
mod chunks;
pub mod compose;
mod context;
pub mod nanovdb;
pub mod oneshot;
pub mod photon_records;
mod photons;
pub mod probe;
pub mod records;
mod render;
mod scene;
mod streamed;
mod streamed_store;
mod texels;
mod timing;
mod tracer;
mod transmittance;

pub use context::{gpu_or_cpu, GpuContext, GpuError};
pub use photons::{GpuPhotonRun, GpuPhotons, PhotonHostWork, BYTES_PER_PHOTON};
pub use render::{compose_render_kernel, GpuImage, GpuRenderer};
pub use scene::GpuScene;
pub use streamed::GpuStreamedVolume;
pub use streamed_store::{StreamError, StreamStats};
pub use texels::TexelStore;
pub use timing::{add_gpu_stats, warn_redone, GpuTimes};
pub use tracer::{primitive_feature, scene_features, GpuTracer, GPU_INF};
pub use transmittance::{transmittance_source, GpuVolume};
