//! GPU transmittance through a bricked grid or a raw NanoVDB grid buffer: the grid, its
//! range mips and the estimator's parameters uploaded once, rays dispatched in batches under
//! the device's binding limit (`shaders/kernels/transmittance.wgsl`). The CPU twin is
//! [`hytrace_volume::transmittance_batch`] on the same grid and range mips;
//! `tests/gpu_volume.rs` compares them ray by ray.
//!
//! The kernel computes in f32, so the host hands it numbers of the grid's size: the index
//! space is translated by a multiple of 64 voxels (the coarsest blocks stay aligned) to put
//! the range mips' box near 0, and a ray whose origin lies far away is moved along itself
//! (in f64) to its point nearest the box, its `t` counted from there. Transmittance depends
//! only on lengths of `t`, which this keeps.

use std::borrow::Cow;
use std::time::Instant;

use bytemuck::Zeroable;
use hytrace_volume::{
    global_range, transmittance, BrickEntry, BrickedGrid, Estimate, Estimator, Filter, GridMap,
    IndexRay, Majorant, NanoGrid, RangeMips, Ray, TexelFormat, TransmittanceParams, VolumeError,
    VoxelGrid, BLOCK_SIDE, NO_BRICK, RANGE_LEVELS,
};

use super::chunks::{chunked_capacity, ChunkedUpload, NamedArray};
use super::compose::{compose_with, ComposeError};
use super::context::{compute_pipeline, whole_buffer_entries, GpuContext, GpuError};
use super::nanovdb::{nanovdb_gpu_bytes, NanoGpuError};
use super::records::{
    split_f64, RayRecord, TransmittanceRecord, VolumeParams, VOLUME_ESTIMATOR_DELTA,
    VOLUME_ESTIMATOR_EXACT, VOLUME_ESTIMATOR_MARCH, VOLUME_ESTIMATOR_RATIO,
    VOLUME_ESTIMATOR_RESIDUAL, VOLUME_FILTER_NEAREST, VOLUME_FILTER_STOCHASTIC,
    VOLUME_FILTER_TRILINEAR, VOLUME_FORMAT_BC4, VOLUME_FORMAT_F16, VOLUME_FORMAT_F32,
    VOLUME_FORMAT_NANOVDB, VOLUME_FORMAT_UNORM16, VOLUME_FORMAT_UNORM8, VOLUME_STATUS_LOOPS_CUT,
    VOLUME_STATUS_MARCH_STEPS, VOLUME_STATUS_NEGATIVE,
};
use super::texels::{atlas_texture, texture_layout_entry, TexelStore, ATLAS_TEXTURE_BINDING};
use super::timing::{finish_batch, GpuTimes, PassTimer};
use super::tracer::GPU_INF;

const KERNEL: &str = "kernels/transmittance";

/// Side in voxels of the coarsest range blocks: the index space moves by multiples of it.
const TOP_SIDE: i64 = 64;

/// Rays whose origin (after the translation) lies within this many voxels of 0 are sent as
/// they are; farther ones are moved to their point nearest the box.
const NEAR: f64 = 65_536.0;

/// The transmittance kernel's source with composition `features`: `nanovdb` (the raw
/// NanoVDB lookup, for such grids), `chunked_atlas` (an atlas split over several buffers)
/// and `atlas_texture` (texels in a 3D texture); without them it reads bricks from one
/// buffer.
pub fn transmittance_source(features: &[&str]) -> Result<String, ComposeError> {
    compose_with(KERNEL, &|feature| features.contains(&feature))
}

/// A storage binding's bytes: at least one element of its largest type, a 32-byte brick
/// entry (bindings cannot be empty, and an array's binding holds one element or more; a
/// NanoVDB grid leaves the brick table empty).
/// Pads in place: the atlas, which grows with the grid, is never copied here.
fn storage_bytes(mut bytes: Vec<u8>) -> Vec<u8> {
    bytes.resize(bytes.len().max(size_of::<BrickEntry>()), 0);
    bytes
}

/// A grid on the GPU (bricked, or a raw NanoVDB buffer) with its transmittance pipeline.
pub struct GpuVolume<'a> {
    /// The grid as the CPU twin reads it.
    grid: &'a dyn VoxelGrid,
    /// The range mips the kernel walks (the CPU twin's too).
    mips: Cow<'a, RangeMips>,
    /// Group 0: the parameters, then the grid's arrays; group 1: rays, results.
    kernel: TransmittanceKernel,
    upload: VolumeUpload,
    /// The texels' 3D texture (`atlas_texture` kernels).
    texture: Option<wgpu::TextureView>,
    features: Vec<&'static str>,
    /// The grid's parameters and translation.
    grid_upload: UploadedGrid,
    upload_s: f64,
}

/// Bricked grids on the GPU: the arrays of `shaders/volume/bindings.wgsl` but the
/// parameters, every grid's concatenated (the renderer uploads all its media; the
/// transmittance kernel one grid), and each grid's parameters and index-space translation.
pub(super) struct VolumeUpload {
    /// Ranges, indirection, bricks and the atlas (bindings 1 to 4, and those of their
    /// chunks when split).
    arrays: ChunkedUpload,
    /// Each grid's place in them, in the order given.
    pub grids: Vec<UploadedGrid>,
}

/// One grid of a [`VolumeUpload`].
#[derive(Clone, Copy)]
pub(super) struct UploadedGrid {
    /// Everything of the parameters but the estimator's and the batch's (with the grid's
    /// first entries in the shared arrays).
    pub base: VolumeParams,
    /// The translation of index space (voxels, a multiple of [`TOP_SIDE`]): the kernels'
    /// index space is the grid's minus `shift`.
    pub shift: [f64; 3],
    /// Centre of the range mips' box after the translation.
    pub centre: [f64; 3],
}

/// `n` as a u32 index into the shared arrays, or a [`GpuError::SceneTooBig`] naming `what`.
fn count_u32(n: usize, what: &str) -> Result<u32, GpuError> {
    u32::try_from(n).map_err(|_| GpuError::SceneTooBig(format!("more than 2^32 {what}")))
}

/// A grid as the volume kernels read it, with the range mips its walks use.
#[derive(Clone, Copy)]
pub(super) enum KernelGrid<'a> {
    /// A bricked grid (its own range mips), texels in the atlas.
    Bricked(&'a BrickedGrid),
    /// A bricked grid whose texels the kernel reads from a 3D texture (`super::texels`):
    /// its brick table only.
    TexturedBricks(&'a BrickedGrid),
    /// A brick store read through a GPU brick pool (`super::streamed`): its range mips and
    /// its bricks' box; the page table, brick table and texels are the pool's own buffers.
    Store {
        /// The store's range mips.
        mips: &'a RangeMips,
        /// Brick coordinate of its first brick.
        brick_lo: [i32; 3],
        /// Bricks along x, y, z.
        brick_dims: [u32; 3],
        /// Its background.
        background: f32,
    },
    /// A raw NanoVDB grid buffer (checked by [`nanovdb_gpu_bytes`]) and the range mips
    /// built from the grid.
    Nanovdb {
        /// The grid's buffer.
        bytes: &'a [u8],
        /// Its background.
        background: f32,
        /// Range mips of its values.
        mips: &'a RangeMips,
    },
}

impl KernelGrid<'_> {
    fn mips(&self) -> &RangeMips {
        match self {
            KernelGrid::Bricked(grid) | KernelGrid::TexturedBricks(grid) => grid.ranges(),
            KernelGrid::Nanovdb { mips, .. } | KernelGrid::Store { mips, .. } => mips,
        }
    }
}

/// The shared arrays being filled: ranges, indirection, brick table, atlas words, and the
/// count of brick slots of the grids whose texels are in a 3D texture.
#[derive(Default)]
struct VolumeArrays {
    ranges: Vec<[f32; 2]>,
    indirection: Vec<u32>,
    bricks: Vec<u8>,
    brick_count: u32,
    atlas: Vec<u8>,
    texture_slots: u32,
}

impl VolumeArrays {
    /// Appends `grid`: its parameters with its first entries in the arrays.
    fn push(&mut self, grid: KernelGrid) -> Result<UploadedGrid, GpuError> {
        let too_big = |why: String| Err(GpuError::SceneTooBig(why));
        let mips = grid.mips();
        if mips.levels.len() != RANGE_LEVELS {
            return too_big(format!(
                "the kernel walks {RANGE_LEVELS} range levels, the grid has {}",
                mips.levels.len()
            ));
        }
        let top = &mips.levels[RANGE_LEVELS - 1];
        let shift_blocks = top.lo.map(i64::from);
        // Block coordinates `lo` of blocks of `side` voxels in the translated index space.
        let shifted = |lo: [i32; 3], side: u32| -> Result<[i32; 3], GpuError> {
            let per_top = TOP_SIDE / i64::from(side);
            let mut out = [0; 3];
            for (o, (l, s)) in out.iter_mut().zip(lo.iter().zip(&shift_blocks)) {
                *o = i32::try_from(i64::from(*l) - s * per_top).map_err(|_| {
                    GpuError::SceneTooBig(format!("blocks of {side} voxels span too far"))
                })?;
            }
            Ok(out)
        };
        let mut base = VolumeParams::zeroed();
        base.probe_trips = 2;
        for (l, level) in mips.levels.iter().enumerate() {
            let lo = shifted(level.lo, level.side)?;
            base.level_lo[l] = [lo[0], lo[1], lo[2], level.side as i32];
            let d = level.dims;
            base.level_dims[l] = [d[0], d[1], d[2], count_u32(self.ranges.len(), "ranges")?];
            self.ranges
                .extend(level.ranges.iter().map(|r| [r.min, r.max]));
        }
        let global = global_range(mips);
        base.global_min = global.min;
        base.global_max = global.max;
        // Voxel coordinates are i32: so is the corner of the coarsest blocks holding them.
        for (s, b) in base.index_shift.iter_mut().zip(&shift_blocks) {
            *s = i32::try_from(b * TOP_SIDE)
                .map_err(|_| GpuError::SceneTooBig("index space beyond i32".to_string()))?;
        }
        base.atlas_base = count_u32(self.atlas.len() / 4, "atlas words")?;
        match grid {
            KernelGrid::Bricked(grid) => self.push_bricks(grid, true, &mut base, shifted)?,
            KernelGrid::TexturedBricks(grid) => {
                self.push_bricks(grid, false, &mut base, shifted)?
            }
            KernelGrid::Store {
                brick_lo,
                brick_dims,
                background,
                ..
            } => {
                // Pool texels are the store's 16-bit codes (each brick-table entry decodes
                // them with the store's quantization).
                base.brick_lo = shifted(brick_lo, BLOCK_SIDE as u32)?;
                base.brick_dims = brick_dims;
                base.format = VOLUME_FORMAT_UNORM16;
                base.background = background;
            }
            KernelGrid::Nanovdb {
                bytes, background, ..
            } => {
                base.format = VOLUME_FORMAT_NANOVDB;
                base.background = background;
                base.nanovdb_words = count_u32(bytes.len() / 4, "NanoVDB words")?;
                self.atlas.extend_from_slice(bytes);
            }
        }
        self.atlas.resize(self.atlas.len().next_multiple_of(4), 0);
        let side = TOP_SIDE as f64;
        Ok(UploadedGrid {
            base,
            shift: shift_blocks.map(|b| b as f64 * side),
            centre: std::array::from_fn(|k| f64::from(top.dims[k]) * side * 0.5 - 0.5),
        })
    }

    /// Appends the bricks of `grid` (indirection, brick table, and with `texels` the atlas,
    /// else slots of the 3D texture) and sets their part of its parameters `base`; `shifted`
    /// translates brick coordinates.
    fn push_bricks(
        &mut self,
        grid: &BrickedGrid,
        texels: bool,
        base: &mut VolumeParams,
        shifted: impl Fn([i32; 3], u32) -> Result<[i32; 3], GpuError>,
    ) -> Result<(), GpuError> {
        let (brick_lo, brick_dims) = grid.indirection_box();
        base.brick_lo = shifted(brick_lo, BLOCK_SIDE as u32)?;
        base.brick_dims = brick_dims;
        base.format = match grid.format() {
            TexelFormat::Bc4 => VOLUME_FORMAT_BC4,
            TexelFormat::Unorm8 => VOLUME_FORMAT_UNORM8,
            TexelFormat::Unorm16 => VOLUME_FORMAT_UNORM16,
            TexelFormat::F16 => VOLUME_FORMAT_F16,
            TexelFormat::F32 => VOLUME_FORMAT_F32,
        };
        base.background = grid.background();
        // Brick indices move past the bricks of the grids before.
        base.indirection_base = count_u32(self.indirection.len(), "indirection entries")?;
        let first_brick = self.brick_count;
        self.indirection.extend(grid.indirection().iter().map(|&e| {
            if e == NO_BRICK {
                e
            } else {
                e + first_brick
            }
        }));
        let bricks: &[u8] = bytemuck::cast_slice(grid.bricks());
        self.bricks.extend_from_slice(bricks);
        self.brick_count = count_u32(self.brick_count as usize + grid.bricks().len(), "bricks")?;
        if texels {
            self.atlas.extend_from_slice(grid.atlas());
        } else {
            // Its slots in the 3D texture follow those of the textured grids before.
            base.atlas_base = self.texture_slots;
            self.texture_slots = count_u32(
                self.texture_slots as usize + grid.atlas_slots(),
                "texture slots",
            )?;
        }
        Ok(())
    }
}

impl VolumeUpload {
    /// Uploads `grids` and their range mips into shared arrays, each split into up to four
    /// buffers when it exceeds the device's binding limit; one still too big is a
    /// [`GpuError::SceneTooBig`].
    pub fn new(ctx: &GpuContext, grids: &[KernelGrid]) -> Result<VolumeUpload, GpuError> {
        let mut arrays = VolumeArrays::default();
        let grids = grids
            .iter()
            .map(|g| arrays.push(*g))
            .collect::<Result<Vec<_>, _>>()?;
        let named = |name, feature, element, bytes| NamedArray {
            name,
            feature,
            element,
            bytes: storage_bytes(bytes),
        };
        let arrays = ChunkedUpload::new(
            ctx,
            vec![
                named(
                    "ranges",
                    "chunked_ranges",
                    8,
                    bytemuck::cast_slice(&arrays.ranges).to_vec(),
                ),
                named(
                    "indirection",
                    "chunked_indirection",
                    4,
                    bytemuck::cast_slice(&arrays.indirection).to_vec(),
                ),
                named(
                    "bricks",
                    "chunked_bricks",
                    size_of::<BrickEntry>(),
                    arrays.bricks,
                ),
                named("atlas", "chunked_atlas", 4, arrays.atlas),
            ],
        )?;
        Ok(VolumeUpload { arrays, grids })
    }

    /// The composition features and pipeline constants the kernels reading these arrays
    /// need: `chunked_ARRAY` for each array split over several buffers.
    pub fn kernel_options(&self) -> (Vec<&'static str>, Vec<(String, f64)>) {
        (self.arrays.features.clone(), self.arrays.constants.clone())
    }

    /// The read-only storage layout entries of the parameters (binding 0) and the arrays.
    pub fn layout_entries(&self, ctx: &GpuContext) -> Vec<wgpu::BindGroupLayoutEntry> {
        let mut bindings = vec![0];
        bindings.extend(&self.arrays.bindings);
        ctx.read_only_entries(&bindings)
    }

    /// The bind group entries of `params` (binding 0) and the arrays.
    pub fn entries<'b>(&'b self, params: &'b wgpu::Buffer) -> Vec<wgpu::BindGroupEntry<'b>> {
        let mut entries = vec![wgpu::BindGroupEntry {
            binding: 0,
            resource: params.as_entire_binding(),
        }];
        entries.extend(self.arrays.entries());
        entries
    }

    /// Storage buffers bound: the parameters and the arrays' buffers.
    pub fn binding_count(&self) -> u32 {
        1 + self.arrays.buffers.len() as u32
    }
}

/// Bytes the volume atlas may hold on a device with binding limit `limit`.
pub fn atlas_capacity(limit: u64) -> u64 {
    chunked_capacity(4, limit)
}

/// The parameters of a [`KernelGrid::Store`] and its range mips' ranges, level after level
/// (the arrays of a brick pool's kernel but its own page table, brick table and texels).
pub(super) fn store_grid(grid: KernelGrid) -> Result<(UploadedGrid, Vec<[f32; 2]>), GpuError> {
    let mut arrays = VolumeArrays::default();
    let uploaded = arrays.push(grid)?;
    Ok((uploaded, arrays.ranges))
}

/// The kernel's form of world ray `ray` through a grid mapped by `map` and uploaded as
/// `grid`: in the translated index space, moved near the box when its origin is far; errors
/// as [`IndexRay::from_world`].
pub(super) fn kernel_ray(
    map: &GridMap,
    grid: &UploadedGrid,
    ray: &Ray,
) -> Result<RayRecord, VolumeError> {
    let r = IndexRay::from_world(ray, map)?;
    let origin: [f64; 3] = std::array::from_fn(|k| r.origin[k] - grid.shift[k]);
    let near = origin.iter().all(|c| c.abs() <= NEAR) && r.tmin.abs() <= NEAR;
    let base = if near {
        0.0
    } else {
        // The point nearest the box's centre, within [tmin, tmax].
        let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
        let to_centre = std::array::from_fn(|k| grid.centre[k] - origin[k]);
        (dot(to_centre, r.dir) / dot(r.dir, r.dir))
            .min(r.tmax)
            .max(r.tmin)
    };
    let gpu_f32 = f64::from(GPU_INF);
    let local = |t: f64| (t - base).clamp(-gpu_f32, gpu_f32) as f32;
    let (origin, origin_lo) = split_f64(std::array::from_fn(|k| origin[k] + base * r.dir[k]));
    Ok(RayRecord {
        origin,
        tmin: local(r.tmin),
        direction: r.dir.map(|v| v as f32),
        tmax: local(r.tmax),
        origin_lo,
        pad: 0,
    })
}

/// The kernel records of `rays` (errors name the ray) after checking `params` against the
/// grid and the batch's size.
pub(super) fn kernel_rays(
    grid: &dyn VoxelGrid,
    mips: &RangeMips,
    uploaded: &UploadedGrid,
    rays: &[Ray],
    params: &TransmittanceParams,
) -> crate::Result<Vec<RayRecord>> {
    params.validate(grid, mips)?;
    if u32::try_from(rays.len()).is_err() {
        crate::error::bail!(
            "transmittance: {} rays in one batch, at most {}",
            rays.len(),
            u32::MAX
        );
    }
    Ok(rays
        .iter()
        .enumerate()
        .map(|(i, r)| {
            kernel_ray(grid.map(), uploaded, r)
                .map_err(|e| VolumeError(format!("transmittance: ray {i}: {}", e.0)))
        })
        .collect::<Result<Vec<_>, _>>()?)
}

/// The kernel's parameters of an estimate with `params` through the grid of `base`.
pub(super) fn kernel_params(base: &VolumeParams, params: &TransmittanceParams) -> VolumeParams {
    let mut p = *base;
    (p.estimator, p.march_step) = match params.estimator {
        Estimator::Exact => (VOLUME_ESTIMATOR_EXACT, 0.0),
        Estimator::March { step } => (VOLUME_ESTIMATOR_MARCH, step as f32),
        Estimator::Delta => (VOLUME_ESTIMATOR_DELTA, 0.0),
        Estimator::Ratio => (VOLUME_ESTIMATOR_RATIO, 0.0),
        Estimator::Residual => (VOLUME_ESTIMATOR_RESIDUAL, 0.0),
    };
    p.lookup_filter = match params.filter {
        Filter::Nearest => VOLUME_FILTER_NEAREST,
        Filter::Trilinear => VOLUME_FILTER_TRILINEAR,
        Filter::Stochastic => VOLUME_FILTER_STOCHASTIC,
    };
    (p.global, p.finest) = match params.majorant {
        Majorant::Global => (1, 0),
        Majorant::Local { level } => (0, level as u32),
    };
    p.spp = params.spp;
    p.seed = params.seed;
    p.density_scale = params.density_scale as f32;
    p
}

/// Rays of one batch under the device's binding limit (and at most 2^20, to keep one
/// dispatch short: drivers may kill long ones).
pub(super) fn ray_batch(ctx: &GpuContext) -> usize {
    let limit = ctx.limits.max_storage_buffer_binding_size;
    (limit / size_of::<TransmittanceRecord>() as u64).clamp(1, 1 << 20) as usize
}

/// The estimate of ray `i` (world ray `ray`) from the kernel's record `r`: errors for the
/// statuses the CPU refuses, and for rays whose loops the driver's loop budget cut short,
/// the CPU twin's answer on `grid` and `mips` (counted in `times`).
pub(super) fn record_estimate(
    r: &TransmittanceRecord,
    i: usize,
    ray: &Ray,
    (grid, mips): (&dyn VoxelGrid, &RangeMips),
    params: &TransmittanceParams,
    times: &mut GpuTimes,
) -> crate::Result<Estimate> {
    if r.status & VOLUME_STATUS_NEGATIVE != 0 {
        crate::error::bail!(
            "transmittance: ray {i} meets values below 0; delta, ratio and residual \
             tracking need a density >= 0"
        );
    }
    if r.status & VOLUME_STATUS_MARCH_STEPS != 0 {
        let step = match params.estimator {
            Estimator::March { step } => step,
            _ => 0.0,
        };
        crate::error::bail!(
            "transmittance: ray {i}: a march step of {step} needs more than {} steps",
            u32::MAX
        );
    }
    if r.status & VOLUME_STATUS_LOOPS_CUT != 0 {
        // The CPU twin, on the ray's own streams.
        times.redone_on_cpu += 1;
        return Ok(transmittance(grid, mips, ray, i as u32, params)?);
    }
    Ok(Estimate {
        transmittance: f64::from(r.transmittance),
        variance: f64::from(r.variance),
        lookups: u64::from(r.lookups),
        null_collisions: u64::from(r.null_collisions),
    })
}

/// The transmittance kernel compiled: its pipeline and bind group layouts (group 0: the
/// parameters and the grid's arrays; group 1: rays, results, then any further ray inputs).
pub(super) struct TransmittanceKernel {
    pipeline: wgpu::ComputePipeline,
    volume_layout: wgpu::BindGroupLayout,
    ray_layout: wgpu::BindGroupLayout,
}

impl TransmittanceKernel {
    /// Compiles `source` with override `constants`: group 0 laid out as `volume_entries`,
    /// group 1 as `ray_bindings` storage buffers of which binding 1 (the results) is
    /// written; `label` names it in errors.
    pub(super) fn new(
        ctx: &GpuContext,
        label: &str,
        source: &str,
        volume_entries: &[wgpu::BindGroupLayoutEntry],
        ray_bindings: u32,
        constants: &[(String, f64)],
    ) -> Result<TransmittanceKernel, GpuError> {
        ctx.checked(&format!("building the {label} kernel"), || {
            let module = ctx.wgsl_module(KERNEL, source);
            let volume_layout =
                ctx.device
                    .create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                        label: Some(&format!("{label} volume")),
                        entries: volume_entries,
                    });
            let ray_layout = ctx.storage_layout(&format!("{label} rays"), ray_bindings, &[1]);
            let pipeline_layout =
                ctx.device
                    .create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                        label: Some(label),
                        bind_group_layouts: &[Some(&volume_layout), Some(&ray_layout)],
                        immediate_size: 0,
                    });
            let pipeline =
                compute_pipeline(ctx, &pipeline_layout, &module, "transmittance", constants);
            TransmittanceKernel {
                pipeline,
                volume_layout,
                ray_layout,
            }
        })
    }

    /// One batch of `rays` with `params`: uploads them, the parameters and `ray_inputs`
    /// (group 1's buffers after the results), binds group 0 as the parameters (binding 0)
    /// and `arrays`, dispatches, waits and reads back one record per ray.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn dispatch(
        &self,
        ctx: &GpuContext,
        label: &str,
        params: &VolumeParams,
        rays: &[RayRecord],
        ray_inputs: &[&[u8]],
        arrays: &[wgpu::BindGroupEntry],
        times: &mut GpuTimes,
    ) -> Result<Vec<TransmittanceRecord>, GpuError> {
        let n = rays.len();
        let out_size = (n.max(1) * size_of::<TransmittanceRecord>()) as u64;
        let t0 = Instant::now();
        let timer = PassTimer::new(ctx, &format!("{label} timestamps"));
        let results = ctx.checked(&format!("{label} dispatch"), || {
            let input =
                |label, bytes: &[u8]| ctx.input_buffer(label, &storage_bytes(bytes.to_vec()));
            let results = ctx.output_buffer("transmittances", out_size);
            let params = input("volume params", bytemuck::bytes_of(params));
            let mut ray_buffers = vec![
                input("volume rays", bytemuck::cast_slice(rays)),
                results.clone(),
            ];
            ray_buffers.extend(ray_inputs.iter().map(|bytes| input("ray inputs", bytes)));
            let mut entries = vec![wgpu::BindGroupEntry {
                binding: 0,
                resource: params.as_entire_binding(),
            }];
            entries.extend_from_slice(arrays);
            let volume_group = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some(&format!("{label} volume")),
                layout: &self.volume_layout,
                entries: &entries,
            });
            let ray_group = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some(&format!("{label} rays")),
                layout: &self.ray_layout,
                entries: &whole_buffer_entries(&ray_buffers),
            });
            ctx.submit_pass(
                label,
                &[&self.pipeline],
                &[(0, &volume_group), (1, &ray_group)],
                n as u32,
                timer.as_ref(),
            );
            results
        })?;
        let bytes = finish_batch(
            ctx,
            &format!("{label} kernel"),
            t0,
            &results,
            out_size,
            timer.as_ref(),
            times,
        )?;
        let mut out: Vec<TransmittanceRecord> = bytemuck::pod_collect_to_vec(&bytes);
        out.truncate(n);
        Ok(out)
    }
}

impl<'a> GpuVolume<'a> {
    /// Uploads `grid` and its range mips and compiles the kernel. Arrays beyond the device's
    /// binding limit, or too few storage bindings, are a [`GpuError::SceneTooBig`].
    pub fn new(ctx: &GpuContext, grid: &'a BrickedGrid) -> Result<GpuVolume<'a>, GpuError> {
        Self::with_texels(ctx, grid, TexelStore::Storage)
    }

    /// [`GpuVolume::new`] with the texels read from `store`: the atlas' storage buffer, or
    /// a 3D texture ([`TexelStore::Texture`]; a device without the format's texture
    /// features is a [`GpuError::SceneTooBig`]).
    pub fn with_texels(
        ctx: &GpuContext,
        grid: &'a BrickedGrid,
        store: TexelStore,
    ) -> Result<GpuVolume<'a>, GpuError> {
        let t0 = Instant::now();
        let (kernel_grid, texture) = match store {
            TexelStore::Storage => (KernelGrid::Bricked(grid), None),
            TexelStore::Texture => (
                KernelGrid::TexturedBricks(grid),
                Some(atlas_texture(ctx, &[grid])?),
            ),
        };
        Self::upload(
            ctx,
            grid,
            Cow::Borrowed(grid.ranges()),
            kernel_grid,
            texture,
            t0,
        )
    }

    /// Uploads the raw buffer of NanoVDB `grid` (no conversion: the kernel walks its tree)
    /// with range mips built from it, and compiles the kernel with the NanoVDB lookup.
    /// Grids the lookup cannot read, or above what the device can bind for the atlas, are
    /// refused before anything is uploaded ([`nanovdb_gpu_bytes`]).
    pub fn nanovdb(ctx: &GpuContext, grid: &'a NanoGrid) -> Result<GpuVolume<'a>, NanoGpuError> {
        let t0 = Instant::now();
        let capacity = atlas_capacity(ctx.limits.max_storage_buffer_binding_size);
        let bytes = nanovdb_gpu_bytes(grid, capacity)?;
        let mips = RangeMips::build(grid).map_err(|e| NanoGpuError::Refused {
            number: grid.number(),
            name: grid.name().to_string(),
            reason: e.0,
        })?;
        let kernel_grid = KernelGrid::Nanovdb {
            bytes,
            background: grid.background(),
            mips: &mips,
        };
        Ok(Self::upload(
            ctx,
            grid,
            Cow::Owned(mips.clone()),
            kernel_grid,
            None,
            t0,
        )?)
    }

    /// Uploads `kernel_grid` (the kernel's form of `grid`, whose walks use `mips`, and its
    /// texels' 3D `texture` if it has one) and compiles the kernel with what it needs; `t0`
    /// is when the setup began.
    fn upload(
        ctx: &GpuContext,
        grid: &'a dyn VoxelGrid,
        mips: Cow<'a, RangeMips>,
        kernel_grid: KernelGrid,
        texture: Option<wgpu::TextureView>,
        t0: Instant,
    ) -> Result<GpuVolume<'a>, GpuError> {
        let upload = VolumeUpload::new(ctx, &[kernel_grid])?;
        // Group 0: the parameters and the grid's arrays; group 1: rays and results.
        let volume_bindings = upload.binding_count();
        let per_stage = ctx.limits.max_storage_buffers_per_shader_stage;
        if per_stage < volume_bindings + 2 {
            return Err(GpuError::SceneTooBig(format!(
                "the transmittance kernel binds {} storage buffers, the device allows {per_stage}",
                volume_bindings + 2
            )));
        }
        let grid_upload = upload.grids[0];
        let (mut features, constants) = upload.kernel_options();
        if matches!(kernel_grid, KernelGrid::Nanovdb { .. }) {
            features.push("nanovdb");
        }
        if texture.is_some() {
            features.push("atlas_texture");
        }
        let source = transmittance_source(&features).map_err(|problem| GpuError::Shader {
            name: KERNEL.to_string(),
            problem: problem.to_string(),
        })?;
        let mut entries = upload.layout_entries(ctx);
        if texture.is_some() {
            entries.push(texture_layout_entry(ATLAS_TEXTURE_BINDING));
        }
        let kernel =
            TransmittanceKernel::new(ctx, "transmittance", &source, &entries, 2, &constants)?;
        Ok(GpuVolume {
            grid,
            mips,
            kernel,
            upload,
            texture,
            grid_upload,
            features,
            upload_s: t0.elapsed().as_secs_f64(),
        })
    }

    /// The composition features of the kernel: `nanovdb` for a raw NanoVDB grid,
    /// `chunked_atlas` for an atlas split over several buffers, `atlas_texture` for texels
    /// in a 3D texture.
    pub fn features(&self) -> &[&'static str] {
        &self.features
    }

    /// Seconds spent uploading the grid and building the kernel (host wall clock).
    pub fn upload_s(&self) -> f64 {
        self.upload_s
    }

    /// The transmittance of every world ray (ray `i` uses the random streams of index `i`),
    /// with the upload, kernel and readback seconds of the batches. Errors as the CPU's
    /// [`hytrace_volume::transmittance_batch`] on bad parameters or rays (NaN, zero
    /// direction), a march of more than `u32::MAX` steps, or a tracker meeting a negative
    /// density. Rays whose loops the driver's loop budget cut short (llvmpipe) are
    /// computed again by that CPU twin ([`GpuTimes::redone_on_cpu`]).
    pub fn transmittance(
        &self,
        ctx: &GpuContext,
        rays: &[Ray],
        params: &TransmittanceParams,
    ) -> crate::Result<(Vec<Estimate>, GpuTimes)> {
        let records = kernel_rays(self.grid, &self.mips, &self.grid_upload, rays, params)?;
        let mut p = kernel_params(&self.grid_upload.base, params);
        let batch = ray_batch(ctx);
        let mut out = Vec::with_capacity(rays.len());
        let mut times = GpuTimes::default();
        for (b, chunk) in records.chunks(batch).enumerate() {
            p.ray_count = chunk.len() as u32;
            p.ray_offset = (b * batch) as u32;
            let results = self.dispatch(ctx, &p, chunk, &mut times)?;
            for (j, r) in results.iter().enumerate() {
                let i = b * batch + j;
                let twin = (self.grid, self.mips.as_ref());
                out.push(record_estimate(r, i, &rays[i], twin, params, &mut times)?);
            }
        }
        Ok((out, times))
    }

    /// One batch: upload, dispatch, wait, read back.
    fn dispatch(
        &self,
        ctx: &GpuContext,
        params: &VolumeParams,
        rays: &[RayRecord],
        times: &mut GpuTimes,
    ) -> Result<Vec<TransmittanceRecord>, GpuError> {
        let mut arrays = self.upload.arrays.entries();
        if let Some(view) = &self.texture {
            arrays.push(wgpu::BindGroupEntry {
                binding: ATLAS_TEXTURE_BINDING,
                resource: wgpu::BindingResource::TextureView(view),
            });
        }
        (self.kernel).dispatch(ctx, "transmittance", params, rays, &[], &arrays, times)
    }
}
