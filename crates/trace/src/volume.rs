//! The operations behind `hytrace volume`: open a grid, choose its representation, sample
//! points, estimate transmittance along rays, convert to a bricked grid, summarize.

use std::borrow::Cow;
use std::path::Path;
use std::time::Instant;

use crate::error::bail;
use hytrace_foundry::layout::Scalar;
use hytrace_foundry::npy::write_array;
use hytrace_volume::{
    convert_grid, convert_raw, open_volume, open_volume_with, sample, select_grid, BrickStore,
    BrickedGrid, ConvertOptions, ConvertReport, Endian, Estimate, Estimator, Filter, GridSummary,
    Majorant, RangeMips, RawSpec, RawType, Ray, Rng, TexelFormat, TransmittanceParams,
    Unsampleable, Volume, VoxelGrid, DEFAULT_STORE_BUDGET,
};
use rayon::prelude::*;
use serde_json::json;

use crate::gpu::nanovdb::nanovdb_gpu_bytes;
use crate::gpu::{
    gpu_or_cpu, warn_redone, GpuContext, GpuStreamedVolume, GpuTimes, GpuVolume, StreamStats,
    TexelStore,
};
use crate::number_list::parse_numbers;
use crate::scan::{read_float_rows, RayRow};

/// Coordinates of sample points.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Space {
    /// Index space: voxel centres at integer coordinates.
    Index,
    /// World space, through the grid's index-to-world map.
    World,
}

crate::choice::named!(Space {
    (Space::Index, "index", [], "Index space: voxel centres at integer coordinates"),
    (Space::World, "world", [], "World space, through the grid's index-to-world map"),
});

/// Lookup filter (see `hytrace_volume::Filter`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FilterArg {
    /// The voxel at floor(p + 0.5).
    Nearest,
    /// OpenVDB's box sampler: the trilinear blend of the eight voxels around p.
    Trilinear,
    /// One of those eight voxels, with probability equal to its trilinear weight.
    Stochastic,
}

crate::choice::named!(FilterArg {
    (FilterArg::Nearest, "nearest", [], "The voxel at floor(p + 0.5)"),
    (FilterArg::Trilinear, "trilinear", [], "OpenVDB's box sampler: the trilinear blend of the eight voxels around p"),
    (FilterArg::Stochastic, "stochastic", [], "One of those eight voxels, with probability equal to its trilinear weight"),
});

impl From<FilterArg> for Filter {
    fn from(f: FilterArg) -> Filter {
        match f {
            FilterArg::Nearest => Filter::Nearest,
            FilterArg::Trilinear => Filter::Trilinear,
            FilterArg::Stochastic => Filter::Stochastic,
        }
    }
}

/// Representation sampled: the grid as read, or a bricked grid of one texel format.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Repr {
    /// The grid as the file stores it (a NanoVDB buffer; OpenVDB or procedural grids as
    /// read).
    Nanovdb,
    /// Bricked grid, BC4 texels.
    Bc4,
    /// Bricked grid, 8-bit normalized texels.
    Unorm8,
    /// Bricked grid, 16-bit normalized texels.
    Unorm16,
    /// Bricked grid, half-precision texels.
    F16,
    /// Bricked grid, single-precision texels.
    F32,
}

crate::choice::named!(Repr {
    (Repr::Nanovdb, "nanovdb", ["source"], "The grid as the file stores it (a NanoVDB buffer; OpenVDB or procedural grids as read)"),
    (Repr::Bc4, "bc4", [], "Bricked grid, BC4 texels"),
    (Repr::Unorm8, "unorm8", [], "Bricked grid, 8-bit normalized texels"),
    (Repr::Unorm16, "unorm16", [], "Bricked grid, 16-bit normalized texels"),
    (Repr::F16, "f16", [], "Bricked grid, half-precision texels"),
    (Repr::F32, "f32", [], "Bricked grid, single-precision texels"),
});

impl Repr {
    fn texel_format(self) -> Option<TexelFormat> {
        match self {
            Repr::Nanovdb => None,
            Repr::Bc4 => Some(TexelFormat::Bc4),
            Repr::Unorm8 => Some(TexelFormat::Unorm8),
            Repr::Unorm16 => Some(TexelFormat::Unorm16),
            Repr::F16 => Some(TexelFormat::F16),
            Repr::F32 => Some(TexelFormat::F32),
        }
    }
}

/// Transmittance estimator on the command line.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EstimatorArg {
    /// The optical depth integrated exactly (per voxel cell, in f64).
    Exact,
    /// Fixed-step midpoint ray marching (--step).
    March,
    /// Delta tracking with local majorants.
    Delta,
    /// Ratio tracking with local majorants.
    Ratio,
    /// Residual ratio tracking (control density = local minorant).
    Residual,
}

crate::choice::named!(EstimatorArg {
    (EstimatorArg::Exact, "exact", [], "The optical depth integrated exactly (per voxel cell, in f64)"),
    (EstimatorArg::March, "march", [], "Fixed-step midpoint ray marching (--step)"),
    (EstimatorArg::Delta, "delta", [], "Delta tracking with local majorants"),
    (EstimatorArg::Ratio, "ratio", [], "Ratio tracking with local majorants"),
    (EstimatorArg::Residual, "residual", [], "Residual ratio tracking (control density = local minorant)"),
});

/// A grid in the representation asked for.
pub enum Represented {
    /// The grid as read.
    Source(Volume),
    /// Converted to a bricked grid.
    Bricked(Box<BrickedGrid>),
}

impl Represented {
    /// The grid, for lookups.
    pub fn grid(&self) -> &dyn VoxelGrid {
        match self {
            Represented::Source(v) => v,
            Represented::Bricked(b) => b.as_ref(),
        }
    }

    /// The range mips of what lookups on this representation read: the bricked grid's or
    /// brick store's own, or built from the grid as read.
    pub fn range_mips(&self) -> crate::Result<Cow<'_, RangeMips>> {
        Ok(match self {
            Represented::Bricked(b) => Cow::Borrowed(b.ranges()),
            Represented::Source(v) => v.range_mips()?,
        })
    }

    /// An error when lookups could not read what they needed (see
    /// [`Volume::check_reads`]); results computed meanwhile must not be written.
    pub fn check_reads(&self) -> crate::Result<()> {
        match self {
            Represented::Source(v) => Ok(v.check_reads()?),
            Represented::Bricked(_) => Ok(()),
        }
    }

    /// Whether this is a brick store, read through its cache.
    pub fn is_brick_store(&self) -> bool {
        matches!(self, Represented::Source(Volume::Store(_)))
    }
}

/// Opens grid `name` (or the first) of `spec`: a .nvdb or .vdb file, a brick store (with
/// [`DEFAULT_STORE_BUDGET`]) or a procedural grid.
pub fn open(spec: &str, name: Option<&str>) -> crate::Result<(GridSummary, Volume)> {
    open_within(spec, name, DEFAULT_STORE_BUDGET)
}

/// Opens grid `name` of `spec` as [`open`] does, a brick store holding at most `memory`
/// bytes resident.
pub fn open_within(
    spec: &str,
    name: Option<&str>,
    memory: u64,
) -> crate::Result<(GridSummary, Volume)> {
    Ok(select_grid(spec, open_volume_with(spec, memory)?, name)?)
}

/// The grid in representation `repr`.
pub fn represent(volume: Volume, repr: Repr) -> crate::Result<Represented> {
    Ok(match repr.texel_format() {
        None => Represented::Source(volume),
        Some(_) if matches!(volume, Volume::Store(_)) => bail!(
            "a brick store is read as stored (--repr nanovdb, the default): converting it to a bricked grid would read it whole"
        ),
        Some(format) => Represented::Bricked(Box::new(BrickedGrid::convert(&volume, format)?)),
    })
}

/// Reads `(N, 3)` float32 or float64 points; errors name the file and the first bad row.
pub fn read_points(path: &Path) -> crate::Result<Vec<[f64; 3]>> {
    let rows = read_float_rows::<3>(path, "points", "")?;
    check_points(&rows, &path.display().to_string())?;
    Ok(rows)
}

/// Errors on the first point that is not finite, naming `source`.
pub fn check_points(points: &[[f64; 3]], source: &str) -> crate::Result<()> {
    if let Some(i) = points.iter().position(|p| !p.iter().all(|v| v.is_finite())) {
        bail!("{source}: point {i}: {:?} is not finite", points[i]);
    }
    Ok(())
}

/// Lookups of `grid` at `points`; point `i` of a stochastic lookup uses the random stream
/// `(seed, i)`.
pub fn sample_points(
    grid: &dyn VoxelGrid,
    points: &[[f64; 3]],
    space: Space,
    filter: Filter,
    seed: u32,
) -> Vec<f32> {
    points
        .par_iter()
        .enumerate()
        .map(|(i, p)| {
            let index = match space {
                Space::Index => *p,
                Space::World => grid.map().world_to_index(*p),
            };
            let mut rng = Rng::new(seed, i as u32, 0);
            let u = [rng.next_f64(), rng.next_f64(), rng.next_f64()];
            sample(grid, index, filter, u)
        })
        .collect()
}

/// The local majorant at mip `level` (0: 8^3 blocks .. 3: 64^3) of the block holding each
/// point: the largest value any lookup there can read on this representation.
pub fn majorants(
    grid: &Represented,
    points: &[[f64; 3]],
    space: Space,
    level: usize,
) -> crate::Result<Vec<f32>> {
    let mips = grid.range_mips()?;
    if level >= mips.levels.len() {
        bail!(
            "majorant level {level}: the range mips have levels 0 to {}",
            mips.levels.len() - 1
        );
    }
    let map = grid.grid().map();
    Ok(points
        .par_iter()
        .map(|p| {
            let index = match space {
                Space::Index => *p,
                Space::World => map.world_to_index(*p),
            };
            mips.range_at(level, index).max
        })
        .collect())
}

/// Writes `(N,)` values atomically.
pub fn write_f32(path: &Path, values: &[f32]) -> crate::Result<()> {
    write_array(
        path,
        Scalar::F32,
        &[values.len() as u64],
        bytemuck::cast_slice(values),
    )?;
    Ok(())
}

/// Writes `(N,)` values atomically.
pub fn write_f64(path: &Path, values: &[f64]) -> crate::Result<()> {
    write_array(
        path,
        Scalar::F64,
        &[values.len() as u64],
        bytemuck::cast_slice(values),
    )?;
    Ok(())
}

/// The estimator options of `hytrace volume transmittance` and `hytrace scan
/// --transmittance`.
#[derive(Clone, Copy, Debug)]
pub struct EstimatorOptions {
    /// Estimator.
    pub estimator: EstimatorArg,
    /// Step of `march`, world units.
    pub step: f64,
    /// Samples per ray of the trackers (delta, ratio, residual).
    pub spp: u32,
    /// Seed of the random streams (ray i uses stream i).
    pub seed: u32,
    /// Density per unit of grid value (for scene media: a factor on each medium's own).
    pub density_scale: f64,
    /// Lookup filter.
    pub filter: FilterArg,
    /// Finest mip level of the local majorants (0: 8^3 bricks ... 3: 64^3).
    pub level: usize,
    /// One majorant for the whole grid instead of local ones.
    pub global_majorant: bool,
}

impl EstimatorOptions {
    /// The options as transmittance arguments.
    pub fn args(&self) -> TransmittanceArgs {
        TransmittanceArgs {
            estimator: self.estimator,
            step: self.step,
            spp: self.spp,
            seed: self.seed,
            density_scale: self.density_scale,
            filter: self.filter.into(),
            level: (!self.global_majorant).then_some(self.level),
        }
    }
}

/// Parameters of `hytrace volume transmittance`.
#[derive(Clone, Copy, Debug)]
pub struct TransmittanceArgs {
    /// Estimator.
    pub estimator: EstimatorArg,
    /// March step (world units).
    pub step: f64,
    /// Samples per ray of the trackers.
    pub spp: u32,
    /// Seed of the random streams.
    pub seed: u32,
    /// Density per unit of grid value.
    pub density_scale: f64,
    /// Lookup filter.
    pub filter: Filter,
    /// Finest mip level of the local majorants, or `None` for one global majorant.
    pub level: Option<usize>,
}

impl TransmittanceArgs {
    /// The library's parameters.
    pub fn params(&self) -> TransmittanceParams {
        TransmittanceParams {
            estimator: match self.estimator {
                EstimatorArg::Exact => Estimator::Exact,
                EstimatorArg::March => Estimator::March { step: self.step },
                EstimatorArg::Delta => Estimator::Delta,
                EstimatorArg::Ratio => Estimator::Ratio,
                EstimatorArg::Residual => Estimator::Residual,
            },
            density_scale: self.density_scale,
            spp: self.spp,
            seed: self.seed,
            filter: self.filter,
            majorant: match self.level {
                Some(level) => Majorant::Local { level },
                None => Majorant::Global,
            },
        }
    }
}

/// The rows as world rays.
fn world_rays(rays: &[RayRow]) -> Vec<Ray> {
    rays.iter()
        .map(|r| Ray::new(r.origin, r.direction, r.tmin, r.tmax))
        .collect()
}

/// Transmittance estimates along `rays` through `grid` (range mips built from the grid,
/// or the bricked grid's own), with the time spent building mips and estimating.
pub fn transmittances(
    grid: &Represented,
    rays: &[RayRow],
    args: &TransmittanceArgs,
) -> crate::Result<(Vec<Estimate>, f64, f64)> {
    let t0 = Instant::now();
    let mips = grid.range_mips()?;
    let t1 = Instant::now();
    let rays = world_rays(rays);
    let estimates = hytrace_volume::transmittance_batch(grid.grid(), &mips, &rays, &args.params())?;
    let t2 = Instant::now();
    Ok((estimates, (t1 - t0).as_secs_f64(), (t2 - t1).as_secs_f64()))
}

/// Where `hytrace volume transmittance` runs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum VolumeBackend {
    /// The CPU estimators in f64, on any representation.
    #[default]
    Cpu,
    /// The GPU kernel in f32: on the bricked grid, or with `--repr nanovdb` on the raw
    /// NanoVDB buffer (other grids as read, and NanoVDB types the GPU does not read, are
    /// converted to f32 bricks).
    Gpu,
    /// The GPU when an adapter opens, else the CPU (with a note on stderr).
    Auto,
}

crate::choice::named!(VolumeBackend {
    (VolumeBackend::Cpu, "cpu", [], "The CPU estimators in f64, on any representation"),
    (VolumeBackend::Gpu, "gpu", [], "The GPU kernel in f32: on the bricked grid, or with `--repr nanovdb` on the raw NanoVDB buffer (other grids as read, and NanoVDB types the GPU does not read, are converted to f32 bricks)"),
    (VolumeBackend::Auto, "auto", [], "The GPU when an adapter opens, else the CPU (with a note on stderr)"),
});

/// Where a GPU transmittance ran and where its time went.
#[derive(Clone, Debug)]
pub struct GpuVolumeInfo {
    /// The adapter (name, type, backend, driver).
    pub adapter: String,
    /// The representation traced: the bricked format, the raw NanoVDB buffer, or f32 bricks
    /// converted from the grid as read (`--repr nanovdb`).
    pub repr: String,
    /// Seconds converting (a grid as read that is not a NanoVDB buffer the GPU reads),
    /// uploading the grid and building the kernel.
    pub setup_s: f64,
    /// Upload, kernel and readback seconds of the rays' batches (host wall clock).
    pub times: GpuTimes,
    /// A brick store's streaming: passes, bricks uploaded, pool size.
    pub stream: Option<StreamStats>,
}

/// A transmittance run: the estimates, the seconds building mips (CPU) and tracing, and
/// the GPU's details when it ran there.
pub struct TransmittanceRun {
    /// One estimate per ray.
    pub estimates: Vec<Estimate>,
    /// Seconds building range mips (CPU backend).
    pub mips_s: f64,
    /// Seconds tracing (GPU: upload, kernel and readback of the rays).
    pub trace_s: f64,
    /// Set when the run was on the GPU.
    pub gpu: Option<GpuVolumeInfo>,
}

/// [`transmittances`] on `backend`: the GPU traces, in f32, the bricked grid or the raw
/// NanoVDB buffer of a grid as read (other grids as read are converted to f32 bricks, exact
/// for float grids; a brick store streams through a brick pool of at most `gpu_memory`
/// bytes: [`GpuStreamedVolume`]). `gpu` without an adapter is an
/// error; `auto` falls back to the CPU with a line on stderr when the GPU fails.
pub fn transmittances_on(
    grid: &Represented,
    rays: &[RayRow],
    args: &TransmittanceArgs,
    backend: VolumeBackend,
    texels: TexelStore,
    gpu_memory: u64,
) -> crate::Result<TransmittanceRun> {
    let cpu = || {
        let (estimates, mips_s, trace_s) = transmittances(grid, rays, args)?;
        Ok(TransmittanceRun {
            estimates,
            mips_s,
            trace_s,
            gpu: None,
        })
    };
    let gpu = |ctx| match grid {
        Represented::Source(Volume::Store(store)) => {
            if texels == TexelStore::Texture {
                bail!("--gpu-texels texture reads bricked grids; a brick store streams its bricks through a storage buffer");
            }
            gpu_store_transmittances(ctx, store, rays, args, gpu_memory)
        }
        _ => gpu_transmittances(ctx, grid, rays, args, texels),
    };
    match backend {
        VolumeBackend::Cpu => cpu(),
        VolumeBackend::Gpu => gpu(GpuContext::new()?),
        VolumeBackend::Auto => gpu_or_cpu("traces", gpu, cpu),
    }
}

/// The GPU side of [`transmittances_on`] for a brick store: streamed through a brick pool of
/// at most `memory` device bytes.
fn gpu_store_transmittances(
    ctx: GpuContext,
    store: &BrickStore,
    rays: &[RayRow],
    args: &TransmittanceArgs,
    memory: u64,
) -> crate::Result<TransmittanceRun> {
    let t0 = Instant::now();
    let mut volume = GpuStreamedVolume::new(&ctx, store, memory)?;
    let repr = "brick store (16-bit codes streamed through a brick pool)".to_string();
    let mut run = gpu_run(&ctx, t0, repr, rays, |rays| {
        volume.transmittance(&ctx, rays, &args.params())
    })?;
    if let Some(info) = &mut run.gpu {
        info.stream = Some(volume.stats());
    }
    Ok(run)
}

/// The run of a GPU volume set up since `t0` (`repr` names what it traces): `trace` on the
/// world form of `rays`, timed, with a line on stderr for rays redone on the CPU.
fn gpu_run(
    ctx: &GpuContext,
    t0: Instant,
    repr: String,
    rays: &[RayRow],
    trace: impl FnOnce(&[Ray]) -> crate::Result<(Vec<Estimate>, GpuTimes)>,
) -> crate::Result<TransmittanceRun> {
    let setup_s = t0.elapsed().as_secs_f64();
    let rays = world_rays(rays);
    let t1 = Instant::now();
    let (estimates, times) = trace(&rays)?;
    warn_redone(&ctx.describe(), &times, rays.len(), "rays");
    Ok(TransmittanceRun {
        estimates,
        mips_s: 0.0,
        trace_s: t1.elapsed().as_secs_f64(),
        gpu: Some(GpuVolumeInfo {
            adapter: ctx.describe(),
            repr,
            setup_s,
            times,
            stream: None,
        }),
    })
}

/// The GPU side of [`transmittances_on`], reading bricked grids' texels from `texels`.
fn gpu_transmittances(
    ctx: GpuContext,
    grid: &Represented,
    rays: &[RayRow],
    args: &TransmittanceArgs,
    texels: TexelStore,
) -> crate::Result<TransmittanceRun> {
    let t0 = Instant::now();
    let in_texture = |repr: String| match texels {
        TexelStore::Storage => repr,
        TexelStore::Texture => format!("{repr}, texels in a 3D texture"),
    };
    let converted;
    let (volume, repr) = match grid {
        Represented::Bricked(b) => (
            GpuVolume::with_texels(&ctx, b, texels)?,
            in_texture(b.format().name().to_string()),
        ),
        Represented::Source(Volume::Nano(g)) if nanovdb_gpu_bytes(g, u64::MAX).is_ok() => {
            if texels == TexelStore::Texture {
                bail!(
                    "--gpu-texels texture reads bricked grids; --repr nanovdb traces this \
                     NanoVDB grid's own buffer (choose a bricked --repr for a texture)"
                );
            }
            (
                GpuVolume::nanovdb(&ctx, g)?,
                "nanovdb (the raw grid buffer)".to_string(),
            )
        }
        Represented::Source(v) => {
            converted = BrickedGrid::convert(v, TexelFormat::F32)?;
            (
                GpuVolume::with_texels(&ctx, &converted, texels)?,
                in_texture(format!("f32 (converted from {})", v.kind())),
            )
        }
    };
    gpu_run(&ctx, t0, repr, rays, |rays| {
        volume.transmittance(&ctx, rays, &args.params())
    })
}

/// The `--stats` line of `volume transmittance`: counts and timings, and on the GPU the
/// adapter, the representation traced and the GPU's seconds.
pub fn transmittance_stats(run: &TransmittanceRun, load_s: f64) -> serde_json::Value {
    let lookups: u64 = run.estimates.iter().map(|e| e.lookups).sum();
    let nulls: u64 = run.estimates.iter().map(|e| e.null_collisions).sum();
    let mut line = json!({
        "backend": if run.gpu.is_some() { "gpu" } else { "cpu" },
        "rays": run.estimates.len(), "load_s": load_s, "mips_s": run.mips_s,
        "trace_s": run.trace_s, "lookups": lookups, "null_collisions": nulls,
    });
    if let Some(g) = &run.gpu {
        line["adapter"] = g.adapter.clone().into();
        line["gpu_repr"] = g.repr.clone().into();
        line["gpu_setup_s"] = g.setup_s.into();
        line["gpu_upload_s"] = g.times.upload_s.into();
        line["gpu_kernel_s"] = g.times.kernel_s.into();
        line["gpu_readback_s"] = g.times.readback_s.into();
        line["gpu_kernel_timestamps_s"] = g.times.kernel_gpu_s.into();
        if let Some(st) = &g.stream {
            line["stream"] = st.json("rays_deferred");
        }
    }
    line
}

/// Memory of one representation, for `volume info`.
fn memory_row(name: &str, bytes: usize, bound: Option<f64>) -> serde_json::Value {
    json!({"representation": name, "bytes": bytes, "error_bound": bound})
}

/// The memory rows of a grid as read and as each bricked representation (measured by
/// converting it), and why a representation is missing.
fn representations(
    s: &GridSummary,
    grid: &Result<Volume, Unsampleable>,
) -> (Vec<serde_json::Value>, Option<String>) {
    let mut memory = vec![memory_row(
        s.source_kind,
        s.source_bytes as usize,
        Some(0.0),
    )];
    let mut note = None;
    match grid {
        Ok(volume) => {
            // A grid that cannot be bricked (tiles spanning too many blocks, values a
            // format cannot hold) is still described; the reason replaces its rows.
            for format in TexelFormat::ALL {
                match BrickedGrid::convert(volume, format) {
                    Ok(b) => memory.push(memory_row(
                        format.name(),
                        b.memory_bytes().total(),
                        Some(b.error_bound()),
                    )),
                    Err(e) => {
                        note = Some(format!("not bricked as {format}: {}", e.0));
                        break;
                    }
                }
            }
        }
        Err(why) => note = Some(why.to_string()),
    }
    (memory, note)
}

/// The summary `hytrace volume info` prints: every grid of `spec` with its bounding boxes,
/// voxel counts and the memory of each representation (bricked ones measured by
/// converting the scalar grids).
pub fn info(spec: &str) -> crate::Result<serde_json::Value> {
    let mut grids = Vec::new();
    for named in open_volume(spec)? {
        let s = &named.summary;
        let (memory, note) = match &s.brick_store {
            // A store is described by its metadata; converting it would read it whole.
            Some(store) => (
                vec![memory_row(s.source_kind, s.source_bytes as usize, None)],
                Some(format!(
                    "brick store of {}x{}x{} voxels: {} bricks kept, {} dropped, {} bytes on disk; 16-bit codes (value = {} + code x {}); levels of detail 8^3, 2^3, 1^3 per brick; range mips of 8 to 64 voxels",
                    store.dims[0], store.dims[1], store.dims[2], store.kept_bricks, store.dropped_bricks,
                    s.source_bytes, store.quantization.lo, store.quantization.step
                )),
            ),
            None => representations(s, &named.grid),
        };
        grids.push(json!({
            "name": s.name,
            "value_type": s.value_type,
            "index_bbox": s.index_bbox,
            "world_bbox": s.world_bbox,
            "active_voxels": s.active_voxels,
            "memory": memory,
            "brick_store": s.brick_store,
            "note": note,
        }));
    }
    Ok(json!({"source": spec, "grids": grids}))
}

/// The text form of [`info`].
pub fn info_text(info: &serde_json::Value) -> String {
    let mut out = format!("{}\n", info["source"].as_str().unwrap_or(""));
    for g in info["grids"].as_array().into_iter().flatten() {
        out += &format!(
            "grid `{}` ({}): {} active voxels, index bbox {}, world bbox {}\n",
            g["name"].as_str().unwrap_or(""),
            g["value_type"].as_str().unwrap_or(""),
            g["active_voxels"],
            g["index_bbox"],
            g["world_bbox"],
        );
        if let Some(note) = g["note"].as_str() {
            out += &format!("  note: {note}\n");
        }
        for m in g["memory"].as_array().into_iter().flatten() {
            let bound = m["error_bound"]
                .as_f64()
                .map_or(String::new(), |b| format!(", max voxel error {b:.3e}"));
            out += &format!(
                "  {:<8} {:>12} bytes{bound}\n",
                m["representation"].as_str().unwrap_or(""),
                m["bytes"],
            );
        }
    }
    out
}

/// Element type of a raw volume file on the command line.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RawTypeArg {
    /// Unsigned 8-bit.
    U8,
    /// Unsigned 16-bit.
    U16,
    /// 32-bit float.
    F32,
}

crate::choice::named!(RawTypeArg {
    (RawTypeArg::U8, "u8", [], "Unsigned 8-bit"),
    (RawTypeArg::U16, "u16", [], "Unsigned 16-bit"),
    (RawTypeArg::F32, "f32", [], "32-bit float"),
});

/// Byte order of a raw volume file on the command line.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EndianArg {
    /// Least significant byte first.
    Little,
    /// Most significant byte first.
    Big,
}

crate::choice::named!(EndianArg {
    (EndianArg::Little, "little", [], "Least significant byte first"),
    (EndianArg::Big, "big", [], "Most significant byte first"),
});

/// The options of `hytrace volume convert --store`.
#[derive(Clone, Debug)]
pub struct StoreOptions {
    /// Voxels of a raw file along x, y, z (`X,Y,Z`; x fastest in the file, no header).
    pub dims: Option<String>,
    /// Element type of a raw file.
    pub dtype: Option<RawTypeArg>,
    /// Byte order of a raw file.
    pub endian: EndianArg,
    /// World size of a raw file's voxel along x, y, z (`SX,SY,SZ`).
    pub spacing: String,
    /// World position of a raw file's first voxel (`X,Y,Z`).
    pub origin: String,
    /// Value outside the volume and of dropped bricks.
    pub background: f32,
    /// Bricks whose values all lie within this of the background are dropped.
    pub threshold: f32,
    /// The range the 16-bit codes span (`MIN,MAX`); the data's own range by default (a
    /// first pass over the file finds it).
    pub range: Option<String>,
    /// Memory the converter may hold resident (e.g. 2G): its window of brick layers and
    /// its tables; refused when that does not fit.
    pub memory: u64,
}

/// `N` comma-separated finite numbers of option `what`.
fn numbers<const N: usize>(text: &str, what: &str) -> crate::Result<[f64; N]> {
    parse_numbers(text).map_err(|_| {
        crate::Error::invalid(format!(
            "{what} `{text}`: expected {N} comma-separated finite numbers"
        ))
    })
}

/// `hytrace volume convert --store`: a raw file (`.raw`) or any volume `spec` (grid `name`)
/// into a brick store at `out`, with a progress bar; returns the conversion's report.
pub fn convert_store(
    spec: &str,
    name: Option<&str>,
    out: &Path,
    options: &StoreOptions,
) -> crate::Result<ConvertReport> {
    let convert = ConvertOptions {
        background: options.background,
        threshold: options.threshold,
        range: match &options.range {
            Some(r) => Some(numbers::<2>(r, "--range")?.map(|v| v as f32)),
            None => None,
        },
        memory: options.memory,
    };
    let bar = crate::progress::bar(100, "converting", "percent");
    let progress = |done: u64, total: u64| bar.set_position(done * 100 / total.max(1));
    // Raw voxels: a `.raw` file, or a stream (a pipe: nothing else reads one).
    let path = Path::new(spec);
    let raw = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("raw"))
        || std::fs::metadata(path).is_ok_and(|m| !m.is_file() && !m.is_dir());
    let report = match (raw, &options.dims, options.dtype) {
        (true, Some(dims), Some(dtype)) => {
            let d = numbers::<3>(dims, "--dims")?;
            if !d
                .iter()
                .all(|v| *v >= 1.0 && *v <= u32::MAX as f64 && v.fract() == 0.0)
            {
                bail!("--dims `{dims}`: expected three whole numbers of voxels, at least 1");
            }
            let spec_raw = RawSpec {
                dims: d.map(|v| v as u32),
                dtype: match dtype {
                    RawTypeArg::U8 => RawType::U8,
                    RawTypeArg::U16 => RawType::U16,
                    RawTypeArg::F32 => RawType::F32,
                },
                endian: match options.endian {
                    EndianArg::Little => Endian::Little,
                    EndianArg::Big => Endian::Big,
                },
                spacing: numbers::<3>(&options.spacing, "--spacing")?,
                origin: numbers::<3>(&options.origin, "--origin")?,
            };
            convert_raw(Path::new(spec), &spec_raw, &convert, out, &progress)?
        }
        (true, _, _) => bail!("{spec}: a raw file needs --dims X,Y,Z and --dtype u8|u16|f32"),
        (false, None, None) => {
            let (_, volume) = open(spec, name)?;
            convert_grid(&volume, spec, &convert, out, &progress)?
        }
        (false, _, _) => {
            bail!("{spec}: --dims and --dtype describe raw files (.raw) and pipes only")
        }
    };
    bar.finish_and_clear();
    Ok(report)
}
