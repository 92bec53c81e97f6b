//! The GPU scan: the prepared f32 scene uploaded as it is ([`SceneArrays`]) and the scan
//! kernel (`shaders/kernels/scan.wgsl`), composed with only the code the scene uses. Its
//! CPU twin is [`CpuScene::<f32>::trace`]; `tests/gpu_scan.rs` compares them ray by ray.

use std::time::Instant;

use hytrace_foundry::{PrimKind, TypeCode, COMPLEMENT_BIT};

use super::chunks::{named_array, ChunkedUpload};
use super::compose::{compose_with, declared_constants};
use super::context::{compute_pipeline, whole_buffer_entries, GpuContext, GpuError};
use super::records::{HitRecord, RayRecord, ScanParams};
use super::timing::{finish_batch, GpuTimes, PassTimer};
use crate::cpu::gpu_export::SceneArrays;
use crate::cpu::CpuScene;

const KERNEL: &str = "kernels/scan";

/// The distance the kernels use for infinity (WGSL may assume no infinities).
pub const GPU_INF: f32 = 1.0e38;

/// Storage buffers of the ray group (group 2).
const RAY_BINDINGS: u32 = 4;

/// The `#if` feature of a primitive typecode's code in `shaders/csg/primitive.wgsl`.
pub fn primitive_feature(code: TypeCode) -> Option<&'static str> {
    Some(match code {
        TypeCode::Sphere => "sphere",
        TypeCode::ZSphere => "zsphere",
        TypeCode::Cylinder => "cylinder",
        TypeCode::Disc => "tube",
        TypeCode::Cone => "cone",
        TypeCode::Hyperboloid => "hyperboloid",
        TypeCode::Torus => "torus",
        TypeCode::Box3 => "box",
        TypeCode::ConvexPolyhedron => "polyhedron",
        TypeCode::Paraboloid => "paraboloid",
        TypeCode::HalfSpace => "halfspace",
        TypeCode::Slab => "slab",
        TypeCode::PhiCut => "phicut",
        TypeCode::ThetaCut => "thetacut",
        TypeCode::Saddle => "saddle",
        TypeCode::TwistedHalfSpace => "twisted",
        _ => return None,
    })
}

/// The composition features a scene needs: `csg` and `mesh` by the prims it has, and one
/// per primitive type its trees use.
pub fn scene_features(arrays: &SceneArrays) -> Vec<&'static str> {
    let mut features = Vec::new();
    let has = |kind: PrimKind| arrays.surface_prims.iter().any(|p| p.kind == kind as u32);
    if has(PrimKind::Csg) {
        features.push("csg");
    }
    if has(PrimKind::Mesh) {
        features.push("mesh");
    }
    for node in &arrays.csg.nodes {
        let code = TypeCode::from_u32(node.code & !COMPLEMENT_BIT);
        if let Some(f) = code.and_then(primitive_feature) {
            if !features.contains(&f) {
                features.push(f);
            }
        }
    }
    features
}

/// The bytes of an array for a storage binding: an empty array becomes one zeroed record
/// (bindings cannot be empty, nor smaller than one element), never read.
pub(super) fn binding_bytes<T: bytemuck::Pod>(items: &[T]) -> Vec<u8> {
    let mut bytes = bytemuck::cast_slice(items).to_vec();
    if bytes.len() < size_of::<T>().max(16) {
        bytes.resize(size_of::<T>().max(16), 0);
    }
    bytes
}

/// A prepared f32 scene uploaded as the scene group (group 1) of a kernel, with the
/// composition features it needs.
pub(super) struct SceneUpload {
    /// Layout of group 1.
    pub layout: wgpu::BindGroupLayout,
    /// Group 1.
    pub group: wgpu::BindGroup,
    /// `csg`, `mesh` and the primitive types the scene uses, and `chunked_ARRAY` for each
    /// array split over several buffers.
    pub features: Vec<&'static str>,
    /// The pipeline constants of the arrays split in chunks.
    pub constants: Vec<(String, f64)>,
    /// Whether the scene is hierarchical (the navigator's answers).
    pub hierarchical: bool,
}

impl SceneUpload {
    /// Uploads `scene` for a kernel that binds `kernel_bindings` more storage buffers.
    pub fn new(
        ctx: &GpuContext,
        scene: &CpuScene<f32>,
        kernel: &str,
        kernel_bindings: u32,
    ) -> Result<SceneUpload, GpuError> {
        let arrays = scene
            .gpu_arrays()
            .map_err(|e| GpuError::SceneTooBig(e.to_string()))?;
        let m = &arrays.meshes;
        let c = &arrays.csg;
        let upload = ChunkedUpload::new(
            ctx,
            vec![
                named_array!("csg_planes", &c.planes),
                named_array!("csg_nodes", &c.nodes),
                named_array!("csg_frames", &c.frames),
                named_array!("csg_trees", &c.trees),
                named_array!("mesh_nodes", &m.nodes),
                named_array!("mesh_triangles", &m.triangles),
                named_array!("meshes", &m.meshes),
                named_array!("box_nodes", &arrays.box_nodes),
                named_array!("box_items", &arrays.box_items),
                named_array!("placements", &arrays.placements),
                named_array!("groups", &arrays.groups),
                named_array!("group_members", &arrays.group_members),
                named_array!("solids", &arrays.solids),
                named_array!("surface_prims", &arrays.surface_prims),
            ],
        )?;
        let per_stage = ctx.limits.max_storage_buffers_per_shader_stage;
        let count = upload.buffers.len() as u32 + kernel_bindings;
        if per_stage < count {
            return Err(GpuError::SceneTooBig(format!(
                "the {kernel} kernel binds {count} storage buffers, the device allows {per_stage}"
            )));
        }
        let mut features = scene_features(&arrays);
        features.extend(&upload.features);
        ctx.checked("uploading the scene", || {
            let layout = ctx.read_only_layout("scene", &upload.bindings);
            let group = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("scene"),
                layout: &layout,
                entries: &upload.entries(),
            });
            SceneUpload {
                layout,
                group,
                features,
                constants: upload.constants.clone(),
                hierarchical: arrays.hierarchical,
            }
        })
    }
}

/// The composed source of `kernel` with `features` on, or a [`GpuError::Shader`].
pub(super) fn kernel_source(kernel: &str, features: &[&str]) -> Result<String, GpuError> {
    compose_with(kernel, &|f| features.contains(&f)).map_err(|problem| GpuError::Shader {
        name: kernel.to_string(),
        problem: problem.to_string(),
    })
}

/// A scene on the GPU with its scan pipeline.
pub struct GpuTracer {
    pipeline: wgpu::ComputePipeline,
    /// The first pass over the rays: the navigator's locate (hierarchical scenes) and the
    /// flags of starts near a surface.
    locate: wgpu::ComputePipeline,
    ray_layout: wgpu::BindGroupLayout,
    scene_group: wgpu::BindGroup,
    hierarchical: bool,
    features: Vec<&'static str>,
    source: String,
}

impl GpuTracer {
    /// Uploads `scene` and compiles its scan kernel. Arrays beyond the device's binding
    /// limit, or a device with too few storage bindings, are a [`GpuError::SceneTooBig`].
    pub fn new(ctx: &GpuContext, scene: &CpuScene<f32>) -> Result<GpuTracer, GpuError> {
        let upload = SceneUpload::new(ctx, scene, "scan", RAY_BINDINGS)?;
        let source = kernel_source(KERNEL, &upload.features)?;
        let constants = declared_constants(&source, &upload.constants);
        ctx.checked("building the scan kernel", || {
            let module = ctx.wgsl_module(KERNEL, &source);
            let ray_layout = ctx.storage_layout("scan rays", RAY_BINDINGS, &[2, 3]);
            // Group 0 (the Foundry's own arrays) is not used by the scan.
            let pipeline_layout =
                ctx.pipeline_layout("scan", &[None, Some(&upload.layout), Some(&ray_layout)]);
            let entry =
                |name: &str| compute_pipeline(ctx, &pipeline_layout, &module, name, &constants);
            GpuTracer {
                pipeline: entry("scan"),
                locate: entry("locate_rays"),
                ray_layout,
                scene_group: upload.group.clone(),
                hierarchical: upload.hierarchical,
                features: upload.features.clone(),
                source: source.clone(),
            }
        })
    }

    /// The composition features the scene's kernel was built with.
    pub fn features(&self) -> &[&'static str] {
        &self.features
    }

    /// The composed WGSL of the scene's scan kernel.
    pub fn source(&self) -> &str {
        &self.source
    }

    /// The first crossing of every ray, in batches that fit the device's binding limit.
    pub fn trace(
        &self,
        ctx: &GpuContext,
        rays: &[RayRecord],
    ) -> Result<(Vec<HitRecord>, GpuTimes), GpuError> {
        let limit = ctx.limits.max_storage_buffer_binding_size;
        let record = size_of::<HitRecord>().max(size_of::<RayRecord>()) as u64;
        // Batches also bounded to keep one dispatch short (drivers may kill long ones).
        let batch = (limit / record).clamp(1, 1 << 20) as usize;
        let mut hits = Vec::with_capacity(rays.len());
        let mut times = GpuTimes::default();
        for chunk in rays.chunks(batch) {
            hits.extend(self.trace_batch(ctx, chunk, &mut times)?);
        }
        Ok((hits, times))
    }

    fn trace_batch(
        &self,
        ctx: &GpuContext,
        rays: &[RayRecord],
        times: &mut GpuTimes,
    ) -> Result<Vec<HitRecord>, GpuError> {
        let n = rays.len();
        let out_size = (n.max(1) * size_of::<HitRecord>()) as u64;
        let t0 = Instant::now();
        let timer = PassTimer::new(ctx, "scan timestamps");
        let (hits, _keep) = ctx.checked("scan dispatch", || {
            let params = ScanParams {
                ray_count: n as u32,
                hierarchical: self.hierarchical as u32,
                probe_trips: 2,
                pad: 0,
            };
            let located = ctx.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("located"),
                // Flat scenes locate nothing: a minimal binding, never read.
                size: if self.hierarchical {
                    (n.max(4) * 4) as u64
                } else {
                    16
                },
                usage: wgpu::BufferUsages::STORAGE,
                mapped_at_creation: false,
            });
            let buffers = [
                ctx.input_buffer("scan params", &binding_bytes(&[params])),
                ctx.input_buffer("rays", &binding_bytes(rays)),
                ctx.output_buffer("hits", out_size),
                located,
            ];
            let group = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("scan rays"),
                layout: &self.ray_layout,
                entries: &whole_buffer_entries(&buffers),
            });
            // Every origin is located (and its start flagged) before the scan runs.
            let pipelines = [&self.locate, &self.pipeline];
            ctx.submit_pass(
                "scan",
                &pipelines,
                &[(1, &self.scene_group), (2, &group)],
                n as u32,
                timer.as_ref(),
            );
            let hits = buffers[2].clone();
            (hits, (buffers, group))
        })?;
        let bytes = finish_batch(
            ctx,
            "scan kernel",
            t0,
            &hits,
            out_size,
            timer.as_ref(),
            times,
        )?;
        let mut out: Vec<HitRecord> = bytemuck::pod_collect_to_vec(&bytes);
        out.truncate(n);
        Ok(out)
    }
}
