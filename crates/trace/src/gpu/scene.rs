//! The Foundry on the GPU: eight storage buffers in one bind group (group 0 of every kernel).

use hytrace_foundry::{gpu_arrays, Foundry};
use wgpu::util::DeviceExt;

use super::context::{whole_buffer_entries, GpuContext, GpuError};

/// A Foundry uploaded to the GPU.
pub struct GpuScene {
    /// Layout of group 0, shared by every kernel's pipeline layout.
    pub layout: wgpu::BindGroupLayout,
    /// The bind group of the eight arrays.
    pub bind_group: wgpu::BindGroup,
    /// The buffers, in binding order of [`gpu_arrays`].
    pub buffers: Vec<wgpu::Buffer>,
}

impl GpuScene {
    /// Uploads the eight GPU arrays of `foundry` (eight buffer writes, whatever the scene's
    /// size). An array larger than the device's storage-binding limit is an error.
    pub fn upload(ctx: &GpuContext, foundry: &Foundry) -> Result<GpuScene, GpuError> {
        let limit = ctx.limits.max_storage_buffer_binding_size;
        let names = gpu_arrays();
        let arrays = foundry.gpu_array_bytes();
        for ((name, _), bytes) in names.iter().zip(&arrays) {
            if bytes.len() as u64 > limit {
                return Err(GpuError::SceneTooBig(format!(
                    "array `{name}` has {} bytes, the device binds at most {limit}",
                    bytes.len()
                )));
            }
        }
        ctx.checked("scene upload", || {
            let buffers: Vec<wgpu::Buffer> = names
                .iter()
                .zip(&arrays)
                .map(|((name, _), bytes)| {
                    // A binding cannot be empty: an empty array gets one zeroed record.
                    let padded;
                    let contents = if bytes.is_empty() {
                        padded = vec![0u8; 64];
                        &padded[..]
                    } else {
                        bytes
                    };
                    ctx.device
                        .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                            label: Some(name),
                            contents,
                            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
                        })
                })
                .collect();
            let layout = ctx.storage_layout("foundry", buffers.len() as u32, &[]);
            let bind_entries = whole_buffer_entries(&buffers);
            let bind_group = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("foundry"),
                layout: &layout,
                entries: &bind_entries,
            });
            GpuScene {
                layout,
                bind_group,
                buffers,
            }
        })
    }
}
