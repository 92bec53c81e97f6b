//! The Foundry probe kernels (`shaders/kernels/foundry_probe.wgsl`) and their CPU twins.
//!
//! `apply_itra` maps points through the GPU's inverse transforms; `locate` counts, for world
//! points, the instances, prims and CSG leaves whose bounds contain them. Together they read
//! every field the tracers rely on to find their way through the uploaded arrays.

use hytrace_foundry::{Foundry, PrimKind, TypeCode, UNSET};
use wgpu::util::DeviceExt;

use super::compose::compose;
use super::context::{compute_pipeline, whole_buffer_entries, GpuContext, GpuError};
use super::scene::GpuScene;

const KERNEL: &str = "kernels/foundry_probe";
const WORKGROUP: u32 = 64;

/// Workgroup counts (x, y) covering `n` invocations of 64 within the per-dimension limit.
pub fn dispatch_size(n: u32, max_per_dimension: u32) -> (u32, u32) {
    let groups = n.div_ceil(WORKGROUP).max(1);
    let x = groups.min(max_per_dimension);
    (x, groups.div_ceil(x))
}

fn rows_apply(r: &[[f32; 4]], p: [f32; 3]) -> [f32; 3] {
    std::array::from_fn(|i| r[i][0] * p[0] + r[i][1] * p[1] + r[i][2] * p[2] + r[i][3])
}

fn contains(b: &[f32; 6], p: [f32; 3], margin: f32) -> bool {
    (0..3).all(|k| p[k] >= b[k] - margin && p[k] <= b[k + 3] + margin)
}

/// CPU twin of `apply_itra`: point `i` mapped by `itra[transforms[i] - 1]` (0: unchanged).
pub fn apply_itra_cpu(f: &Foundry, points: &[[f32; 3]], transforms: &[u32]) -> Vec<[f32; 3]> {
    points
        .iter()
        .zip(transforms)
        .map(|(&p, &t)| match t {
            0 => p,
            t => rows_apply(&f.itra[t as usize - 1].rows, p),
        })
        .collect()
}

/// CPU twin of `locate`, with every box grown by `margin` (shrunk when negative): per point,
/// the number of instances, prims and CSG leaves whose bounds contain it, and the first such
/// instance (`UNSET` if none).
pub fn locate_cpu(f: &Foundry, points: &[[f32; 3]], margin: f32) -> Vec<[u32; 4]> {
    points
        .iter()
        .map(|&p| {
            let mut counts = [0, 0, 0, UNSET];
            for (k, instance) in f.inst.iter().enumerate() {
                let s = &f.solid[instance.solid as usize];
                let local = rows_apply(&instance.itra, p);
                if !contains(&s.aabb, local, margin) {
                    continue;
                }
                counts[0] += 1;
                if counts[3] == UNSET {
                    counts[3] = k as u32;
                }
                for pr in &f.prim[s.prim_offset as usize..][..s.num_prim as usize] {
                    if !contains(&pr.aabb, local, margin) {
                        continue;
                    }
                    counts[1] += 1;
                    if pr.kind != PrimKind::Csg as u32 {
                        continue;
                    }
                    counts[2] += f.node[pr.node_offset as usize..][..pr.num_node as usize]
                        .iter()
                        .filter(|n| {
                            n.typecode >= TypeCode::Sphere as u32
                                && contains(&n.aabb, local, margin)
                        })
                        .count() as u32;
                }
            }
            counts
        })
        .collect()
}

/// The compiled probe kernels.
pub struct ProbeKernels {
    io_layout: wgpu::BindGroupLayout,
    apply_itra: wgpu::ComputePipeline,
    locate: wgpu::ComputePipeline,
}

impl ProbeKernels {
    /// Composes and compiles the kernels for scenes uploaded as `scene`.
    pub fn new(ctx: &GpuContext, scene: &GpuScene) -> Result<ProbeKernels, GpuError> {
        let source = compose(KERNEL).map_err(|problem| GpuError::Shader {
            name: KERNEL.to_string(),
            problem: problem.to_string(),
        })?;
        ctx.checked("compiling the probe kernels", || {
            let module = ctx.wgsl_module(KERNEL, &source);
            let io_layout = ctx.storage_layout("probe io", 4, &[2, 3]);
            let layout = ctx
                .device
                .create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                    label: Some("probe"),
                    bind_group_layouts: &[Some(&scene.layout), Some(&io_layout)],
                    immediate_size: 0,
                });
            let pipeline = |entry: &str| compute_pipeline(ctx, &layout, &module, entry, &[]);
            ProbeKernels {
                apply_itra: pipeline("apply_itra"),
                locate: pipeline("locate"),
                io_layout,
            }
        })
    }

    /// Runs `pipeline` over `points` and reads back binding 2 or 3 (`read_locate`).
    fn run(
        &self,
        ctx: &GpuContext,
        scene: &GpuScene,
        pipeline: &wgpu::ComputePipeline,
        points: &[[f32; 3]],
        transforms: &[u32],
        read_locate: bool,
    ) -> Result<Vec<u8>, GpuError> {
        let n = points.len();
        if n == 0 {
            return Ok(Vec::new());
        }
        let padded: Vec<[f32; 4]> = points.iter().map(|p| [p[0], p[1], p[2], 1.0]).collect();
        let out_size = (n.max(1) * 16) as u64;
        let (buffers, bind_group) = ctx.checked("probe dispatch", || {
            let input = |label, bytes: &[u8]| {
                ctx.device
                    .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                        label: Some(label),
                        contents: bytes,
                        usage: wgpu::BufferUsages::STORAGE,
                    })
            };
            let output = |label| {
                ctx.device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some(label),
                    size: out_size,
                    usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
                    mapped_at_creation: false,
                })
            };
            let buffers = [
                input("points", bytemuck::cast_slice(&padded)),
                input("point_transform", bytemuck::cast_slice(transforms)),
                output("out_points"),
                output("out_locate"),
            ];
            let entries = whole_buffer_entries(&buffers);
            let bind_group = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("probe io"),
                layout: &self.io_layout,
                entries: &entries,
            });
            let (x, y) = dispatch_size(n as u32, ctx.limits.max_compute_workgroups_per_dimension);
            let mut encoder = ctx.device.create_command_encoder(&Default::default());
            {
                let mut pass = encoder.begin_compute_pass(&Default::default());
                pass.set_pipeline(pipeline);
                pass.set_bind_group(0, &scene.bind_group, &[]);
                pass.set_bind_group(1, &bind_group, &[]);
                pass.dispatch_workgroups(x, y, 1);
            }
            ctx.queue.submit([encoder.finish()]);
            (buffers, bind_group)
        })?;
        drop(bind_group);
        let mut bytes = ctx.read_buffer(&buffers[if read_locate { 3 } else { 2 }], out_size)?;
        bytes.truncate(n * 16);
        Ok(bytes)
    }

    /// GPU `apply_itra`; see [`apply_itra_cpu`].
    pub fn apply_itra(
        &self,
        ctx: &GpuContext,
        scene: &GpuScene,
        points: &[[f32; 3]],
        transforms: &[u32],
    ) -> Result<Vec<[f32; 3]>, GpuError> {
        if points.len() != transforms.len() {
            return Err(GpuError::Operation {
                what: "apply_itra".to_string(),
                problem: format!(
                    "{} points but {} transform indices",
                    points.len(),
                    transforms.len()
                ),
            });
        }
        let bytes = self.run(ctx, scene, &self.apply_itra, points, transforms, false)?;
        let out: Vec<[f32; 4]> = bytemuck::pod_collect_to_vec(&bytes);
        Ok(out.into_iter().map(|q| [q[0], q[1], q[2]]).collect())
    }

    /// GPU `locate`; see [`locate_cpu`] (with margin 0).
    pub fn locate(
        &self,
        ctx: &GpuContext,
        scene: &GpuScene,
        points: &[[f32; 3]],
    ) -> Result<Vec<[u32; 4]>, GpuError> {
        let zeros = vec![0u32; points.len()];
        let bytes = self.run(ctx, scene, &self.locate, points, &zeros, true)?;
        Ok(bytemuck::pod_collect_to_vec(&bytes))
    }
}
