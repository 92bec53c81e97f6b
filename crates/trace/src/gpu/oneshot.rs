//! One dispatch of a composed kernel over buffers given as bytes: what the twin tests of
//! individual WGSL modules (primitives, trees, meshes) need, without a pipeline of their own.

use wgpu::util::DeviceExt;

use super::compose::compose_with;
use super::context::{compute_pipeline, whole_buffer_entries, GpuContext, GpuError};
use super::probe::dispatch_size;

/// A storage buffer of a one-shot dispatch.
pub enum Buffer<'a> {
    /// Read-only input bytes (an empty input is bound as 16 zero bytes).
    Input(&'a [u8]),
    /// A read-write output of this many bytes, zero-filled, read back after the dispatch.
    Output(u64),
}

/// Runs entry point `entry` of the composed module `module` with `invocations` invocations
/// (64-wide workgroups in a 2D grid: the kernel's flat index is
/// `gid.y * num_workgroups.x * 64 + gid.x`). `groups[g][b]` is bound at `@group(g)
/// @binding(b)`. Returns the outputs' bytes, in the order they appear in `groups`.
pub fn run(
    ctx: &GpuContext,
    module: &str,
    entry: &str,
    invocations: u32,
    groups: &[Vec<Buffer>],
) -> Result<Vec<Vec<u8>>, GpuError> {
    // Every feature but the chunked arrays' (probes bind each array whole).
    let source = compose_with(module, &|f| !f.starts_with("chunked_")).map_err(|problem| {
        GpuError::Shader {
            name: module.to_string(),
            problem: problem.to_string(),
        }
    })?;
    let (buffers, outputs) = ctx.checked(module, || {
        let shader = ctx.wgsl_module(module, &source);
        let mut layouts = Vec::new();
        let mut bind_groups = Vec::new();
        let mut outputs = Vec::new();
        let mut all = Vec::new();
        for group in groups {
            let writable: Vec<u32> = (0..group.len() as u32)
                .filter(|&b| matches!(group[b as usize], Buffer::Output(_)))
                .collect();
            let layout = ctx.storage_layout(module, group.len() as u32, &writable);
            let buffers: Vec<wgpu::Buffer> = group
                .iter()
                .map(|buf| match buf {
                    Buffer::Input(bytes) => {
                        let zeros = [0u8; 16];
                        let contents = if bytes.is_empty() { &zeros[..] } else { bytes };
                        ctx.device
                            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                                label: Some("oneshot input"),
                                contents,
                                usage: wgpu::BufferUsages::STORAGE,
                            })
                    }
                    Buffer::Output(size) => ctx.device.create_buffer(&wgpu::BufferDescriptor {
                        label: Some("oneshot output"),
                        size: (*size).max(16),
                        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
                        mapped_at_creation: false,
                    }),
                })
                .collect();
            for (buf, spec) in buffers.iter().zip(group) {
                if let Buffer::Output(size) = spec {
                    outputs.push((buf.clone(), *size));
                }
            }
            let bind_entries = whole_buffer_entries(&buffers);
            bind_groups.push(ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some(module),
                layout: &layout,
                entries: &bind_entries,
            }));
            layouts.push(layout);
            all.extend(buffers);
        }
        let layout_refs: Vec<_> = layouts.iter().map(Some).collect();
        let pipeline_layout = ctx
            .device
            .create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some(module),
                bind_group_layouts: &layout_refs,
                immediate_size: 0,
            });
        let pipeline = compute_pipeline(ctx, &pipeline_layout, &shader, entry, &[]);
        let (x, y) = dispatch_size(invocations, ctx.limits.max_compute_workgroups_per_dimension);
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        {
            let mut pass = encoder.begin_compute_pass(&Default::default());
            pass.set_pipeline(&pipeline);
            for (g, bg) in bind_groups.iter().enumerate() {
                pass.set_bind_group(g as u32, bg, &[]);
            }
            pass.dispatch_workgroups(x, y, 1);
        }
        ctx.queue.submit([encoder.finish()]);
        (all, outputs)
    })?;
    let result = outputs
        .iter()
        .map(|(buf, size)| {
            let mut bytes = ctx.read_buffer(buf, (*size).max(16))?;
            bytes.truncate(*size as usize);
            Ok(bytes)
        })
        .collect();
    drop(buffers);
    result
}
