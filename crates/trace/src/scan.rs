//! `hytrace scan`: rays in, first boundary crossings out, as NumPy arrays.
//!
//! Rays are `(N, 8)` float32 or float64 rows `ox oy oz tmin dx dy dz tmax`. Directions are
//! normalized, so `t` is a distance. Hits are `(N, 4)` rows `nx ny nz t`: the unit outward
//! normal of the surface crossed and `t`, `+inf` on a miss, in float32 (`f32` precision)
//! or float64 (`f64`). Ids are `(N, 3)` int32 rows `instance boundary copy`: the instance
//! crossed, its boundary (index into the Foundry's `optics.json` boundary table: outer
//! material, outer surface, inner surface, inner material; -1 when unset) and its copy
//! number (Geant4's copyNo, the sensor identity); `-1 -1 -1` on a miss. Whether the ray
//! enters or leaves the instance follows from the sign of the direction against the normal.

use std::path::Path;
use std::time::Instant;

use crate::error::{bail, Context};
use hytrace_csg::{Ray, Real};
use hytrace_foundry::layout::Scalar;
use hytrace_foundry::npy::{read_array, write_array};
use hytrace_foundry::Foundry;
use rayon::prelude::*;
use serde_json::json;

use hytrace_volume::{TransmittanceParams, DEFAULT_STORE_BUDGET};

use crate::cpu::media::{MediumSegment, SceneMedia};
use crate::cpu::{
    CpuScene, Hit, TraceScratch, BATCH, STATUS_DROPPED_SPAN, STATUS_START_BAND, STATUS_START_NEAR,
};
use crate::gpu::records::{
    split_f64, RayRecord, STATUS_DEPTH_LIMIT, STATUS_FLAGS, STATUS_LOOPS_CUT,
};
use crate::gpu::{
    gpu_or_cpu, warn_redone, GpuContext, GpuStreamedVolume, GpuTimes, GpuTracer, GpuVolume, GPU_INF,
};
use crate::scene::MediumGrid;

/// Which tracer answers a scan.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Backend {
    /// Our CPU tracer, in f32 or f64.
    #[default]
    Cpu,
    /// Embree 3 (f32; builds with the `embree` feature only).
    Embree,
    /// Our GPU tracer through wgpu (f32): the scan kernel, twin of the CPU's f32 tracer.
    Gpu,
    /// The GPU when one can be opened, else the CPU (with a note on stderr).
    Auto,
}

crate::choice::named!(Backend {
    (Backend::Cpu, "cpu", [], "Our CPU tracer (CSG, meshes, media), in f32 or f64"),
    (Backend::Embree, "embree", [], "Embree 3 (f32): meshes as Embree triangles, CSG solids as its user geometry; builds with the `embree` feature only"),
    (Backend::Gpu, "gpu", [], "Our GPU tracer through wgpu (f32; Vulkan, Metal, DX12): the scan kernel, twin of the CPU's f32 tracer, meshes included"),
    (Backend::Auto, "auto", [], "The GPU when one can be opened, else the CPU (with a note on stderr)"),
});

/// Arithmetic precision of the intersection kernels.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Precision {
    /// Single precision (what the GPU runs).
    F32,
    /// Double precision.
    F64,
}

crate::choice::named!(Precision {
    (Precision::F32, "f32", [], "Single precision (what the GPU runs)"),
    (Precision::F64, "f64", [], "Double precision"),
});

/// One validated ray in f64: origin, unit direction, parameter range.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RayRow {
    /// Origin.
    pub origin: [f64; 3],
    /// Unit direction.
    pub direction: [f64; 3],
    /// Smallest accepted distance (exclusive).
    pub tmin: f64,
    /// Largest accepted distance (exclusive; may be +inf).
    pub tmax: f64,
}

/// Validates raw `(N, 8)` rows (in parallel), naming `source` and the first bad row in
/// errors.
pub fn rays_from_rows(rows: &[[f64; 8]], source: &str) -> crate::Result<Vec<RayRow>> {
    // Checked first, so that the rays are collected straight into place (an indexed
    // collect) and the error names the first bad row.
    if let Some(i) = rows.par_iter().position_first(|r| ray_of_row(r).is_err()) {
        let problem = ray_of_row(&rows[i]).expect_err("row i failed");
        bail!("{source}: ray {i}: {problem}");
    }
    Ok(rows
        .par_iter()
        .map(|r| ray_of_row(r).expect("every row passed"))
        .collect())
}

/// What is wrong with a ray row.
#[derive(Debug, thiserror::Error)]
enum RowError {
    #[error("origin {0:?} is not finite")]
    Origin([f64; 3]),
    #[error("direction {0:?} is not finite")]
    Direction([f64; 3]),
    #[error("direction {0:?} has zero length")]
    ZeroDirection([f64; 3]),
    #[error("needs finite tmin < tmax, got {0} {1}")]
    Interval(f64, f64),
}

/// One validated ray, or what is wrong with the row.
fn ray_of_row(r: &[f64; 8]) -> Result<RayRow, RowError> {
    let o = [r[0], r[1], r[2]];
    let d = [r[4], r[5], r[6]];
    let (tmin, tmax) = (r[3], r[7]);
    if !o.iter().all(|v| v.is_finite()) {
        return Err(RowError::Origin(o));
    }
    if !d.iter().all(|v| v.is_finite()) {
        return Err(RowError::Direction(d));
    }
    let largest = d.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    if largest == 0.0 {
        return Err(RowError::ZeroDirection(d));
    }
    let mut len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    // Squares of components like 1e200 or 1e-200 overflow or vanish: scaled by the largest
    // component first, any finite non-zero direction normalizes.
    let d = if len == 0.0 || !len.is_finite() {
        let d = d.map(|v| v / largest);
        len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        d
    } else {
        d
    };
    if !tmin.is_finite() || tmax.is_nan() || tmin >= tmax {
        return Err(RowError::Interval(tmin, tmax));
    }
    Ok(RayRow {
        origin: o,
        direction: d.map(|v| v / len),
        tmin,
        tmax,
    })
}

/// Reads an `(N, W)` float32 or float64 array as rows of f64; `what` names the rows in
/// errors ("rays need shape (N, 8) ...", with `columns` describing the columns).
pub fn read_float_rows<const W: usize>(
    path: &Path,
    what: &str,
    columns: &str,
) -> crate::Result<Vec<[f64; W]>> {
    let a = read_array(path)?;
    let source = path.display().to_string();
    check_row_shape::<W>(&a.shape, &source, what, columns)?;
    let values: Vec<f64> = match a.scalar {
        Scalar::F32 => bytemuck::pod_collect_to_vec::<u8, f32>(&a.bytes)
            .into_iter()
            .map(f64::from)
            .collect(),
        Scalar::F64 => bytemuck::pod_collect_to_vec::<u8, f64>(&a.bytes),
        other => return Err(not_float_rows(&source, what, &format!("{other:?}"))),
    };
    Ok(values
        .chunks_exact(W)
        .map(|c| std::array::from_fn(|k| c[k]))
        .collect())
}

/// Errors unless `shape` is `(N, W)`: "{source}: {what} need shape (N, W){columns}, got
/// [..]" (the message of [`read_float_rows`], for arrays from elsewhere too).
pub fn check_row_shape<const W: usize>(
    shape: &[u64],
    source: &str,
    what: &str,
    columns: &str,
) -> crate::Result<()> {
    if shape.len() != 2 || shape[1] != W as u64 {
        bail!("{source}: {what} need shape (N, {W}){columns}, got {shape:?}");
    }
    Ok(())
}

/// The error of rows whose element type `got` is not float32 or float64 (the message of
/// [`read_float_rows`], for arrays from elsewhere too).
pub fn not_float_rows(source: &str, what: &str, got: &str) -> crate::Error {
    crate::Error::Invalid(format!(
        "{source}: {what} must be float32 or float64, got {got}"
    ))
}

/// The columns of a rays array, as errors describe them.
pub const RAY_COLUMNS: &str = " (ox oy oz tmin dx dy dz tmax)";

/// Reads and validates a rays file.
pub fn read_rays(path: &Path) -> crate::Result<Vec<RayRow>> {
    let rows = read_float_rows::<8>(path, "rays", RAY_COLUMNS)?;
    rays_from_rows(&rows, &path.display().to_string())
}

/// Writes rays as an `(N, 8)` float64 array.
pub fn write_rays(path: &Path, rays: &[RayRow]) -> crate::Result<()> {
    let flat: Vec<f64> = rays
        .iter()
        .flat_map(|r| {
            let (o, d) = (r.origin, r.direction);
            [o[0], o[1], o[2], r.tmin, d[0], d[1], d[2], r.tmax]
        })
        .collect();
    write_array(
        path,
        Scalar::F64,
        &[rays.len() as u64, 8],
        bytemuck::cast_slice(&flat),
    )?;
    Ok(())
}

/// The answers of a scan in f64: `nx ny nz t` per ray and the identity of the crossing.
#[derive(Clone, Debug, Default)]
pub struct ScanResult {
    /// `(N, 4)` rows.
    pub hits: Vec<[f64; 4]>,
    /// `instance boundary copy` per ray, -1 where there is none.
    pub ids: Vec<[i32; 3]>,
}

impl ScanResult {
    /// The hits rounded to f32, row after row (what an `f32` scan writes).
    pub fn hits_f32(&self) -> Vec<f32> {
        let mut out = vec![0.0; self.hits.len() * 4];
        out.par_chunks_mut(4)
            .zip(&self.hits)
            .for_each(|(o, h)| o.copy_from_slice(&h.map(|v| v as f32)));
        out
    }
}

/// Number of columns of the ids array.
pub const ID_COLUMNS: usize = 3;

/// Every ray's answer from the CPU tracer and its trace's flags
/// ([`CpuScene::trace_batch_flagged`]: what the f32 fallback needs).
pub(crate) fn cpu_answers_flagged<T: Real>(
    scene: &CpuScene<T>,
    rays: &[RayRow],
) -> (Vec<Answer>, Vec<u32>) {
    let mut flags = vec![0; rays.len()];
    let answers = cpu_answers_reporting(scene, rays, &|_| (), Some(&mut flags));
    (answers, flags)
}

/// Every ray's answer from the CPU tracer, handed rays in batches
/// ([`CpuScene::trace_batch`]: the same answers as its `trace`, sooner).
pub(crate) fn cpu_answers<T: Real>(scene: &CpuScene<T>, rays: &[RayRow]) -> Vec<Answer> {
    cpu_answers_reporting(scene, rays, &|_| (), None)
}

/// [`cpu_answers`], calling `progress` with the number of rays answered after each batch;
/// with `flags`, each ray's flags written there too ([`cpu_answers_flagged`]).
fn cpu_answers_reporting<T: Real>(
    scene: &CpuScene<T>,
    rays: &[RayRow],
    progress: &(dyn Fn(u64) + Sync),
    flags: Option<&mut [u32]>,
) -> Vec<Answer> {
    let done = std::sync::atomic::AtomicU64::new(0);
    let mut answers = vec![answer_of::<T>(None); rays.len()];
    let flagged = flags.is_some();
    // Unflagged scans write no flags: an empty chunk per batch keeps the chunks paired.
    let mut unused = vec![0; if flagged { 0 } else { rays.len() }];
    let flags = flags.unwrap_or(&mut unused);
    answers
        .par_chunks_mut(BATCH)
        .zip(rays.par_chunks(BATCH))
        .zip(flags.par_chunks_mut(BATCH))
        .for_each_init(
            || (TraceScratch::default(), Vec::new(), Vec::new(), Vec::new()),
            |(scratch, queries, hits, chunk_flags), ((answers, chunk), flags)| {
                queries.clear();
                queries.extend(chunk.iter().map(query_of));
                if flagged {
                    scene.trace_batch_flagged(queries, scratch, hits, chunk_flags);
                    flags.copy_from_slice(chunk_flags);
                } else {
                    scene.trace_batch(queries, scratch, hits);
                }
                for (a, h) in answers.iter_mut().zip(hits.iter()) {
                    *a = answer_of(*h);
                }
                let n = chunk.len() as u64;
                progress(done.fetch_add(n, std::sync::atomic::Ordering::Relaxed) + n);
            },
        );
    answers
}

/// A ray row as the tracers are handed it: ray (in f64), tmin, tmax (`+inf` for an
/// infinite one).
fn query_of<T: Real>(r: &RayRow) -> (Ray<f64>, T, T) {
    let tmax = if r.tmax.is_finite() {
        T::from_f64(r.tmax)
    } else {
        T::INFINITY
    };
    (
        Ray::from_f64(r.origin, r.direction),
        T::from_f64(r.tmin),
        tmax,
    )
}

/// A tracer's answer as a scan row: `(nx ny nz t, instance)`, instance -1 on a miss.
fn answer_of<T: Real>(hit: Option<Hit<T>>) -> Answer {
    match hit {
        Some(h) => {
            let n = h.normal.to_f64();
            ([n[0], n[1], n[2], h.t.to_f64()], h.instance as i32)
        }
        None => ([0.0, 0.0, 0.0, f64::INFINITY], -1),
    }
}

/// A scan's result from `(nx ny nz t, instance)` per ray (instance -1 on a miss).
fn result_from(f: &Foundry, answers: &[([f64; 4], i32)]) -> ScanResult {
    let identity = |instance: i32| -> [i32; 3] {
        match f.inst.get(instance as usize) {
            Some(inst) if instance >= 0 => [instance, inst.boundary as i32, inst.copy_number],
            _ => [-1; 3],
        }
    };
    ScanResult {
        hits: answers.iter().map(|a| a.0).collect(),
        ids: answers.iter().map(|a| identity(a.1)).collect(),
    }
}

/// Timings of one scan.
#[derive(Clone, Debug, Default)]
pub struct ScanTimes {
    /// Seconds preparing the scene for the tracer.
    pub build_s: f64,
    /// Seconds tracing.
    pub trace_s: f64,
    /// Set when the scan ran on the GPU.
    pub gpu: Option<GpuScanInfo>,
    /// Rays of an f32 scan traced again in f64 because f32 could not tell their answers
    /// (starts within the f32 tolerance of a surface, grazing crossings, torus crossings
    /// off the f64 surface; see `docs/f32-precision.md`).
    pub redone_in_f64: usize,
    /// Seconds of `trace_s` spent on the f64 fallback: choosing the rays from the flags and
    /// answers, building the f64 scene and tracing them again.
    pub fallback_s: f64,
    /// Rays of an f32 scan its trace flagged as within rounding of a decision
    /// ([`crate::cpu::Traced::flags`]), before the fallback's own checks.
    pub flagged: usize,
}

/// What a GPU scan ran on and where its time went.
#[derive(Clone, Debug, Default)]
pub struct GpuScanInfo {
    /// The adapter (name, type, backend, driver).
    pub adapter: String,
    /// The composition features of the scene's kernel.
    pub features: Vec<&'static str>,
    /// Upload, kernel and readback seconds (host wall clock).
    pub times: GpuTimes,
    /// Seconds of host work per ray in a scan: building the ray records, converting the
    /// answers (0 for the transmittance kernels).
    pub host_s: f64,
}

/// Traces every ray against the scene's CSG and mesh solids in the given precision, on the
/// default (CPU) backend.
pub fn scan(
    foundry: &Foundry,
    rays: &[RayRow],
    precision: Precision,
) -> crate::Result<(ScanResult, ScanTimes)> {
    scan_with(foundry, rays, precision, Backend::Cpu)
}

/// Traces every ray on the given backend. Embree and the GPU trace in f32 only; Embree
/// needs a build with the `embree` feature.
pub fn scan_with(
    foundry: &Foundry,
    rays: &[RayRow],
    precision: Precision,
    backend: Backend,
) -> crate::Result<(ScanResult, ScanTimes)> {
    scan_reporting(foundry, rays, precision, backend, &|_| ())
}

/// [`scan_with`], calling `progress` with the number of rays the CPU tracer has answered
/// after each batch (the GPU and Embree report nothing until they are done).
pub fn scan_reporting(
    foundry: &Foundry,
    rays: &[RayRow],
    precision: Precision,
    backend: Backend,
    progress: &(dyn Fn(u64) + Sync),
) -> crate::Result<(ScanResult, ScanTimes)> {
    let Some(moved) = started_at_tmin(foundry, rays) else {
        return scan_from_origins(foundry, rays, precision, backend, progress);
    };
    let (mut result, times) = scan_from_origins(foundry, &moved, precision, backend, progress)?;
    for (hit, r) in result.hits.iter_mut().zip(rays) {
        if r.tmin > 0.0 && hit[3].is_finite() {
            hit[3] += r.tmin;
        }
    }
    Ok((result, times))
}

/// A hierarchical scene's navigator locates a ray's origin and answers the boundaries of
/// the volume it is in, so a ray whose `tmin` is past a boundary would be answered from a
/// volume it has left (and miss the next one). Where a scene is hierarchical and some ray
/// has `tmin > 0`, the rays as they start at `tmin`: origin moved there (in f64), `tmin`
/// 0 and `tmax` shortened by it; their distances count from there. `None` otherwise.
fn started_at_tmin(f: &Foundry, rays: &[RayRow]) -> Option<Vec<RayRow>> {
    if !f.is_hierarchical() || !rays.iter().any(|r| r.tmin > 0.0) {
        return None;
    }
    let moved = |r: &RayRow| match r.tmin > 0.0 {
        true => RayRow {
            origin: std::array::from_fn(|k| r.origin[k] + r.tmin * r.direction[k]),
            direction: r.direction,
            tmin: 0.0,
            tmax: r.tmax - r.tmin,
        },
        false => *r,
    };
    Some(rays.iter().map(moved).collect())
}

/// [`scan_reporting`] of rays whose `tmin` needs no move ([`started_at_tmin`]).
fn scan_from_origins(
    foundry: &Foundry,
    rays: &[RayRow],
    precision: Precision,
    backend: Backend,
    progress: &(dyn Fn(u64) + Sync),
) -> crate::Result<(ScanResult, ScanTimes)> {
    /// A CPU scan; `finish` (the f32 fallback, given the traces' flags when `flagged`)
    /// returns how many rays it traced again.
    fn cpu<T: Real>(
        f: &Foundry,
        rays: &[RayRow],
        progress: &(dyn Fn(u64) + Sync),
        flagged: bool,
        finish: impl FnOnce(&CpuScene<T>, &mut [Answer], &[u32]) -> crate::Result<usize>,
    ) -> crate::Result<(ScanResult, ScanTimes)> {
        let t0 = Instant::now();
        let scene = CpuScene::<T>::new(f)?;
        let build_s = t0.elapsed().as_secs_f64();
        let t1 = Instant::now();
        let mut flags = vec![0; if flagged { rays.len() } else { 0 }];
        let flags_out = flagged.then_some(&mut flags[..]);
        let mut answers = cpu_answers_reporting(&scene, rays, progress, flags_out);
        let t2 = Instant::now();
        let flagged = flags.par_iter().filter(|&&f| f != 0).count();
        let redone_in_f64 = finish(&scene, &mut answers, &flags)?;
        let fallback_s = t2.elapsed().as_secs_f64();
        let result = result_from(f, &answers);
        let trace_s = t1.elapsed().as_secs_f64();
        let times = ScanTimes {
            build_s,
            trace_s,
            redone_in_f64,
            fallback_s,
            flagged,
            ..Default::default()
        };
        Ok((result, times))
    }
    let f32_cpu = || {
        cpu::<f32>(foundry, rays, progress, true, |scene, answers, flags| {
            redo_flagged_in_f64(foundry, scene, rays, answers, flags)
        })
    };
    match (backend, precision) {
        (Backend::Cpu, Precision::F32) => f32_cpu(),
        (Backend::Cpu, Precision::F64) => {
            cpu::<f64>(foundry, rays, progress, false, |_, _, _| Ok(0))
        }
        (Backend::Embree, Precision::F64) => {
            bail!("the Embree backend traces in f32: use --precision f32 (the default)")
        }
        (Backend::Embree, Precision::F32) => embree_scan(foundry, rays),
        (Backend::Gpu | Backend::Auto, Precision::F64) => {
            bail!("the GPU backend traces in f32: use --precision f32 (the default)")
        }
        (Backend::Gpu, Precision::F32) => gpu_scan(foundry, rays, GpuContext::new()?),
        (Backend::Auto, Precision::F32) => {
            gpu_or_cpu("scans", |ctx| gpu_scan(foundry, rays, ctx), f32_cpu)
        }
    }
}

/// Below this cosine of incidence an f32 crossing is traced again in f64: a crossing's
/// error in `t` is its surface's rounding over the cosine (on a quadric near a tangent,
/// the solid's size times epsilon over the cosine), and at 1/8 that stays within the f32
/// surface tolerance (17 epsilons of the solid's size). About 1.6% of the crossings of
/// isotropic rays come in that shallow.
const GRAZING_COSINE: f64 = 0.125;

/// Whether an f32 answer crosses its surface at grazing incidence ([`GRAZING_COSINE`]).
fn grazes(ray: &RayRow, answer: &Answer) -> bool {
    let (n, d) = (&answer.0, &ray.direction);
    answer.0[3].is_finite() && (n[0] * d[0] + n[1] * d[1] + n[2] * d[2]).abs() < GRAZING_COSINE
}

/// Traces again in f64 the rays of an f32 scan whose answers the f32 tolerance or f32
/// rounding may have decided, as Geant4 (in f64) would not. The trace reports what it could
/// not decide (`flags`, [`CpuScene::trace_flagged`] or the GPU kernel's status bits): rays
/// that start within the tolerance band of a CSG surface ([`STATUS_START_NEAR`]: which side
/// the start lies on, and whether a crossing there is the surface it starts on, are within
/// rounding), rays along which a prim dropped a span shorter than the tolerance as a touch
/// ([`STATUS_DROPPED_SPAN`]), and rays starting in the band of a solid whose signed
/// distance does not decide ([`STATUS_START_BAND`]), which are searched here
/// ([`CpuScene::starts_near_surface`]). From the answers: rays that cross at grazing
/// incidence ([`GRAZING_COSINE`]), and crossings of solids with a torus whose point lies
/// off the f64 surface by more than an eighth of the f32 band (so off by the band at most
/// at the incidences the grazing test lets through: the f32 roots of the quartic can stray
/// further than its tolerance). Every other ray keeps its f32 answer; no origin is located
/// again but those of [`STATUS_START_BAND`] rays. `scene` is the scan's f32 scene; the f64
/// scene is built only when some ray needs it. Returns how many rays were traced again.
pub(crate) fn redo_flagged_in_f64(
    f: &Foundry,
    scene: &CpuScene<f32>,
    rays: &[RayRow],
    answers: &mut [Answer],
    flags: &[u32],
) -> crate::Result<usize> {
    crate::error::ensure!(
        flags.len() == rays.len() && answers.len() == rays.len(),
        "{} rays, {} answers and {} flags",
        rays.len(),
        answers.len(),
        flags.len()
    );
    let torus: Vec<bool> = (0..scene.instances() as u32)
        .map(|i| scene.has_torus(i))
        .collect();
    let on_torus = |a: &Answer| usize::try_from(a.1).is_ok_and(|i| torus[i]);
    let (mut again, checked): (Vec<usize>, Vec<usize>) = rays
        .par_iter()
        .zip(answers.par_iter())
        .zip(flags.par_iter())
        .enumerate()
        .map_init(Vec::new, |candidates, (i, ((r, a), &flag))| {
            let uncertain = flag & (STATUS_START_NEAR | STATUS_DROPPED_SPAN) != 0
                || grazes(r, a)
                || (flag & STATUS_START_BAND != 0 && {
                    let (ray, tmin, _) = query_of::<f32>(r);
                    scene.starts_near_surface(&ray, tmin, candidates)
                });
            if uncertain {
                Some((i, true))
            } else {
                on_torus(a).then_some((i, false))
            }
        })
        .flatten()
        .partition_map(|(i, uncertain)| match uncertain {
            true => rayon::iter::Either::Left(i),
            false => rayon::iter::Either::Right(i),
        });
    if again.is_empty() && checked.is_empty() {
        return Ok(0);
    }
    let exact = CpuScene::<f64>::new(f)?;
    again.par_extend(checked.into_par_iter().filter(|&i| {
        let (r, t) = (&rays[i], answers[i].0[3]);
        let x: [f64; 3] = std::array::from_fn(|k| r.origin[k] + t * r.direction[k]);
        let reach = r.origin.iter().map(|c| c * c).sum::<f64>().sqrt() + t;
        let allowed = f64::from(<f32 as Real>::SURFACE_TOLERANCE) * reach / 8.0;
        exact.surface_distance(answers[i].1 as u32, x) > allowed
    }));
    let rows: Vec<RayRow> = again.iter().map(|&i| rays[i]).collect();
    for (&i, answer) in again.iter().zip(cpu_answers(&exact, &rows)) {
        answers[i] = answer;
    }
    Ok(again.len())
}

/// A ray in the form the GPU kernels read: the origin in two f32 parts as the CPU's f32
/// tracer carries it, the rest rounded to f32, infinite `tmax` as the kernels' [`GPU_INF`].
pub fn ray_record(r: &RayRow) -> RayRecord {
    let (origin, origin_lo) = split_f64(r.origin);
    RayRecord {
        origin,
        tmin: r.tmin as f32,
        direction: r.direction.map(|c| c as f32),
        tmax: (r.tmax as f32).min(GPU_INF),
        origin_lo,
        pad: 0,
    }
}

/// The GPU backend's scan: build time includes preparing the f32 CPU scene it uploads,
/// uploading it and compiling the kernel; trace time is the rays' upload, the kernel and
/// the readback.
fn gpu_scan(
    f: &Foundry,
    rays: &[RayRow],
    ctx: GpuContext,
) -> crate::Result<(ScanResult, ScanTimes)> {
    let t0 = Instant::now();
    let cpu = CpuScene::<f32>::new(f)?;
    let tracer = GpuTracer::new(&ctx, &cpu)?;
    let build_s = t0.elapsed().as_secs_f64();
    let t1 = Instant::now();
    let traced = gpu_trace(&ctx, &tracer, &cpu, rays)?;
    let (mut answers, flags) = (traced.answers, traced.flags);
    let t2 = Instant::now();
    let flagged = flags.par_iter().filter(|&&f| f != 0).count();
    let redone_in_f64 = redo_flagged_in_f64(f, &cpu, rays, &mut answers, &flags)?;
    let fallback_s = t2.elapsed().as_secs_f64();
    let trace_s = t1.elapsed().as_secs_f64();
    let gpu = GpuScanInfo {
        adapter: ctx.describe(),
        features: tracer.features().to_vec(),
        times: traced.times,
        host_s: traced.host_s,
    };
    let times = ScanTimes {
        build_s,
        trace_s,
        gpu: Some(gpu),
        redone_in_f64,
        fallback_s,
        flagged,
    };
    Ok((result_from(f, &answers), times))
}

/// A ray's answer: `nx ny nz t` and the instance crossed (-1 on a miss).
pub(crate) type Answer = ([f64; 4], i32);

/// What the GPU scan kernel answered for every ray, as the host uses it.
pub(crate) struct GpuTraced {
    /// `(nx ny nz t, instance)` per ray (`t = inf`, instance -1 on a miss).
    pub answers: Vec<Answer>,
    /// The trace's flags per ray ([`crate::cpu::Traced::flags`]).
    pub flags: Vec<u32>,
    /// The kernel's times.
    pub times: GpuTimes,
    /// Seconds of host work per ray: ray records before, answers and flags after.
    pub host_s: f64,
}

/// Every ray through the GPU scan kernel. A placement tree deeper than the kernel's bound
/// is an error; rays whose loops the driver's budget cut short (llvmpipe) are traced again
/// by the kernel's twin `cpu`, flags included. Ray records and answers are made in
/// parallel, each straight into its place.
pub(crate) fn gpu_trace(
    ctx: &GpuContext,
    tracer: &GpuTracer,
    cpu: &CpuScene<f32>,
    rays: &[RayRow],
) -> crate::Result<GpuTraced> {
    let t0 = Instant::now();
    let records: Vec<RayRecord> = rays.par_iter().map(ray_record).collect();
    let records_s = t0.elapsed().as_secs_f64();
    let (hits, mut times) = tracer.trace(ctx, &records)?;
    drop(records);
    let t1 = Instant::now();
    if let Some(i) = hits
        .par_iter()
        .position_first(|h| h.status & STATUS_DEPTH_LIMIT != 0)
    {
        bail!(
            "GPU scan: ray {i} was cut short: the placement tree is deeper than the kernel's \
             bound"
        );
    }
    let (mut answers, mut flags): (Vec<Answer>, Vec<u32>) = hits
        .par_iter()
        .map(|h| {
            let answer = match h.t < GPU_INF {
                true => {
                    let n = h.normal.map(f64::from);
                    ([n[0], n[1], n[2], f64::from(h.t)], h.instance as i32)
                }
                false => ([0.0, 0.0, 0.0, f64::INFINITY], -1),
            };
            (answer, h.status & STATUS_FLAGS)
        })
        .unzip();
    let cut: Vec<usize> = (0..hits.len())
        .into_par_iter()
        .filter(|&i| hits[i].status & STATUS_LOOPS_CUT != 0)
        .collect();
    let host_s = records_s + t1.elapsed().as_secs_f64();
    let cut_rows: Vec<RayRow> = cut.iter().map(|&i| rays[i]).collect();
    let (again, again_flags) = cpu_answers_flagged(cpu, &cut_rows);
    times.redone_on_cpu = cut.len() as u64;
    warn_redone(&ctx.describe(), &times, rays.len(), "rays");
    for ((&i, answer), flag) in cut.iter().zip(again).zip(again_flags) {
        answers[i] = answer;
        flags[i] = flag;
    }
    Ok(GpuTraced {
        answers,
        flags,
        times,
        host_s,
    })
}

/// The transmittances of `scan --transmittance` and where their time went.
#[derive(Clone, Debug, Default)]
pub struct TransmittanceRun {
    /// Transmittance of the media along each ray up to its first surface crossing.
    pub values: Vec<f64>,
    /// Seconds preparing the surfaces and opening the media (on the GPU also uploading the
    /// scene and the grids and building the kernels).
    pub open_s: f64,
    /// Seconds tracing the surfaces and estimating the media.
    pub transmittance_s: f64,
    /// Set when it ran on the GPU: the adapter, the scan kernel's features and the seconds
    /// of the scan and transmittance kernels together.
    pub gpu: Option<GpuScanInfo>,
}

impl TransmittanceRun {
    /// Adds this run's timings to a `--stats` line: `media_open_s` and `transmittance_s`,
    /// and after a GPU run `transmittance_gpu_upload_s`, `_kernel_s`, `_readback_s` and
    /// `_kernel_timestamps_s` (null without timestamp queries).
    pub fn add_stats(&self, line: &mut serde_json::Value) {
        line["media_open_s"] = self.open_s.into();
        line["transmittance_s"] = self.transmittance_s.into();
        if let Some(g) = &self.gpu {
            line["transmittance_gpu_upload_s"] = g.times.upload_s.into();
            line["transmittance_gpu_kernel_s"] = g.times.kernel_s.into();
            line["transmittance_gpu_readback_s"] = g.times.readback_s.into();
            line["transmittance_gpu_kernel_timestamps_s"] = g.times.kernel_gpu_s.into();
        }
    }
}

/// Transmittance of the scene's media along every ray up to its first surface crossing
/// (see [`crate::cpu::media::SceneMedia`]), the surfaces traced on the CPU in `precision`.
pub fn scan_transmittance(
    foundry: &Foundry,
    rays: &[RayRow],
    precision: Precision,
    params: &TransmittanceParams,
) -> crate::Result<TransmittanceRun> {
    scan_transmittance_on(foundry, rays, precision, params, Backend::Cpu, 0)
}

/// [`scan_transmittance`] on `backend`: the surfaces scanned there ([`scan_with`]), then
/// the media estimated where the scan ran ([`media_transmittance`]), ray `i` drawing the
/// random streams of index `first_ray + i`.
pub fn scan_transmittance_on(
    foundry: &Foundry,
    rays: &[RayRow],
    precision: Precision,
    params: &TransmittanceParams,
    backend: Backend,
    first_ray: u32,
) -> crate::Result<TransmittanceRun> {
    let (result, times) = scan_with(foundry, rays, precision, backend)?;
    let ends = ray_ends(&result, rays);
    let ran_on = match backend {
        Backend::Embree => Backend::Embree,
        _ if times.gpu.is_some() => Backend::Gpu,
        _ => Backend::Cpu,
    };
    let run = MediaRun {
        backend: ran_on,
        first_ray,
        memory: DEFAULT_STORE_BUDGET,
    };
    media_transmittance(foundry, rays, &ends, precision, params, run)
}

/// Where and how a scan's media transmittance runs.
#[derive(Clone, Copy, Debug)]
pub struct MediaRun {
    /// The backend (the one the surfaces ran on).
    pub backend: Backend,
    /// The random stream index of the first ray.
    pub first_ray: u32,
    /// Bytes each medium read as stored in a brick store may hold resident (its tables
    /// and a cache of bricks read on demand).
    pub memory: u64,
}

/// Where each ray's media end: its first surface crossing in `result`, or its `tmax` on a
/// miss.
pub fn ray_ends(result: &ScanResult, rays: &[RayRow]) -> Vec<f64> {
    result
        .hits
        .iter()
        .zip(rays)
        .map(|(h, r)| if h[3].is_finite() { h[3] } else { r.tmax })
        .collect()
}

/// Transmittance of the scene's media along every ray over `[tmin, ends[i]]` (the ends a
/// scan found, [`ray_ends`]), on `run.backend`, media read as stored in a brick store
/// through caches of `run.memory` bytes. On the GPU (f32 only) the transmittance kernel
/// estimates every medium on the very index-space segments and random streams the CPU
/// would; `auto` falls back to the CPU with a line on stderr when the GPU fails. With
/// Embree (f32 only) the brick clusters each ray meets are found by Embree, the estimates
/// are the CPU's. Ray `i` draws the random streams of index `run.first_ray + i`; the
/// GPU's kernel numbers its rays from 0 and takes `first_ray = 0` only.
pub fn media_transmittance(
    foundry: &Foundry,
    rays: &[RayRow],
    ends: &[f64],
    precision: Precision,
    params: &TransmittanceParams,
    run: MediaRun,
) -> crate::Result<TransmittanceRun> {
    let MediaRun {
        backend,
        first_ray,
        memory,
    } = run;
    fn cpu<T: Real>(
        f: &Foundry,
        rays: &[RayRow],
        ends: &[f64],
        params: &TransmittanceParams,
        (first_ray, memory): (u32, u64),
    ) -> crate::Result<TransmittanceRun> {
        timed_transmittance(|opened| {
            let scene = CpuScene::<T>::new(f)?;
            let media = SceneMedia::with_memory(&scene, f, params, memory)?;
            *opened = Instant::now();
            media.transmittances_to(rays, ends, first_ray)
        })
    }
    if first_ray != 0 && matches!(backend, Backend::Gpu | Backend::Auto) {
        bail!(
            "the GPU transmittance kernel numbers its rays from 0: a first ray index of \
             {first_ray} needs the CPU or Embree backend"
        );
    }
    match (backend, precision) {
        (Backend::Cpu, Precision::F32) => {
            cpu::<f32>(foundry, rays, ends, params, (first_ray, memory))
        }
        (Backend::Cpu, Precision::F64) => {
            cpu::<f64>(foundry, rays, ends, params, (first_ray, memory))
        }
        (Backend::Embree, Precision::F64) => {
            bail!("the Embree backend traces in f32: use --precision f32 (the default)")
        }
        (Backend::Embree, Precision::F32) => {
            embree_transmittance(foundry, rays, ends, params, (first_ray, memory))
        }
        (Backend::Gpu | Backend::Auto, Precision::F64) => {
            bail!("the GPU backend traces in f32: use --precision f32 (the default)")
        }
        (Backend::Gpu, Precision::F32) => {
            gpu_transmittance(foundry, rays, ends, params, memory, GpuContext::new()?)
        }
        (Backend::Auto, Precision::F32) => gpu_or_cpu(
            "computes transmittance",
            |ctx| gpu_transmittance(foundry, rays, ends, params, memory, ctx),
            || cpu::<f32>(foundry, rays, ends, params, (0, memory)),
        ),
    }
}

/// A scene medium's transmittance kernel on the GPU.
enum MediumKernel<'a> {
    /// Bricked in memory, uploaded whole.
    InCore(GpuVolume<'a>),
    /// Read as stored in a brick store, streamed through a brick pool.
    Streamed(GpuStreamedVolume<'a>),
}

/// The GPU's transmittance over each ray's `[tmin, end]`: the CPU's f32 scene clips the
/// ray to each placed medium's bricks (as [`SceneMedia::segments`]); then one
/// transmittance batch per
/// segment position and medium, each of all `N` rays so that ray `i` draws the random
/// streams of index `i` (rays without such a segment go as empty rays, their estimates
/// unused), with that placement's seed. The estimates multiply per ray in segment order,
/// as on the CPU. Each medium's grid is uploaded once; a medium read as stored in a brick
/// store streams through a GPU brick pool of `memory` bytes ([`GpuStreamedVolume`]).
fn gpu_transmittance(
    f: &Foundry,
    rays: &[RayRow],
    ends: &[f64],
    params: &TransmittanceParams,
    memory: u64,
    ctx: GpuContext,
) -> crate::Result<TransmittanceRun> {
    crate::error::ensure!(
        rays.len() == ends.len(),
        "{} rays and {} ends",
        rays.len(),
        ends.len()
    );
    let t0 = Instant::now();
    let cpu = CpuScene::<f32>::new(f)?;
    let media = SceneMedia::new(&cpu, f, params)?;
    let mut volumes = (0..media.medium_count() as u32)
        .map(|m| {
            let kernel: crate::Result<MediumKernel> = match media.grid(m) {
                MediumGrid::Bricked(grid) => GpuVolume::new(&ctx, grid)
                    .map(MediumKernel::InCore)
                    .map_err(Into::into),
                MediumGrid::Store(store, mips) => {
                    GpuStreamedVolume::with_mips(&ctx, store, mips, memory)
                        .map(MediumKernel::Streamed)
                        .map_err(Into::into)
                }
            };
            kernel.with_context(|| format!("medium {m}"))
        })
        .collect::<crate::Result<Vec<_>>>()?;
    let open_s = t0.elapsed().as_secs_f64();
    let t1 = Instant::now();
    let mut times = GpuTimes::default();
    let segments: Vec<Vec<MediumSegment>> = rays
        .par_iter()
        .zip(ends)
        .enumerate()
        .map(|(i, (r, &end))| {
            media
                .segments(r.origin, r.direction, r.tmin, end)
                .with_context(|| format!("ray {i}"))
        })
        .collect::<crate::Result<_>>()?;
    // (placement, medium) in order: per ray, the segments' order on the CPU.
    let batches: std::collections::BTreeSet<(u32, u32)> = segments
        .iter()
        .flatten()
        .map(|s| (s.placement, s.medium))
        .collect();
    let mut values = vec![1.0; rays.len()];
    let pieces = batches.len() * rays.len();
    for (placement, medium) in batches {
        let find = |ray: &[MediumSegment]| {
            ray.iter()
                .find(|s| (s.placement, s.medium) == (placement, medium))
                .copied()
        };
        let batch: Vec<hytrace_volume::Ray> = segments
            .iter()
            .map(|ray| match find(ray) {
                Some(s) => {
                    hytrace_volume::Ray::new(s.ray.origin, s.ray.dir, s.ray.tmin, s.ray.tmax)
                }
                None => hytrace_volume::Ray::new([0.0; 3], [1.0, 0.0, 0.0], 0.0, 0.0),
            })
            .collect();
        let params = media.params(medium, placement);
        let (estimates, t) = match &mut volumes[medium as usize] {
            MediumKernel::InCore(v) => v.transmittance(&ctx, &batch, &params),
            MediumKernel::Streamed(v) => v.transmittance(&ctx, &batch, &params),
        }
        .with_context(|| format!("medium {medium}"))?;
        add_times(&mut times, &t);
        for ((v, ray), e) in values.iter_mut().zip(&segments).zip(&estimates) {
            if find(ray).is_some() {
                *v *= e.transmittance;
            }
        }
    }
    warn_redone(&ctx.describe(), &times, pieces, "ray pieces");
    Ok(TransmittanceRun {
        values,
        open_s,
        transmittance_s: t1.elapsed().as_secs_f64(),
        gpu: Some(GpuScanInfo {
            adapter: ctx.describe(),
            features: vec!["transmittance"],
            times,
            host_s: 0.0,
        }),
    })
}

/// Adds the seconds of `more` to `total` (kernel timestamps only where both have them).
fn add_times(total: &mut GpuTimes, more: &GpuTimes) {
    total.upload_s += more.upload_s;
    total.kernel_s += more.kernel_s;
    total.readback_s += more.readback_s;
    total.kernel_gpu_s = total
        .kernel_gpu_s
        .zip(more.kernel_gpu_s)
        .map(|(a, b)| a + b);
    total.redone_on_cpu += more.redone_on_cpu;
}

/// The Embree backend's scan: build times include preparing the CPU scene it borrows. As
/// the default scan, the rays whose f32 answers its trace flags
/// ([`crate::embree::EmbreeScene::trace_flagged`]) or the answers show doubtful are traced
/// again in f64 ([`redo_flagged_in_f64`]).
#[cfg(feature = "embree")]
fn embree_scan(f: &Foundry, rays: &[RayRow]) -> crate::Result<(ScanResult, ScanTimes)> {
    let t0 = Instant::now();
    let cpu = CpuScene::<f32>::new(f)?;
    let scene = crate::embree::EmbreeScene::new(f, &cpu)?;
    let build_s = t0.elapsed().as_secs_f64();
    let t1 = Instant::now();
    // Embree takes rays in f32.
    let traced = rays
        .par_iter()
        .map(|r| {
            let (ray, tmin, tmax) = query_of::<f32>(r);
            let ray = Ray::from_f64(ray.origin.to_f64(), ray.direction.to_f64());
            let t = scene.trace_flagged(&ray, tmin, tmax)?;
            Ok((answer_of(t.hit), t.flags))
        })
        .collect::<crate::Result<Vec<_>>>()?;
    let (mut answers, flags): (Vec<Answer>, Vec<u32>) = traced.into_iter().unzip();
    let t2 = Instant::now();
    let flagged = flags.par_iter().filter(|&&f| f != 0).count();
    let redone_in_f64 = redo_flagged_in_f64(f, &cpu, rays, &mut answers, &flags)?;
    let fallback_s = t2.elapsed().as_secs_f64();
    let times = ScanTimes {
        build_s,
        trace_s: t1.elapsed().as_secs_f64(),
        redone_in_f64,
        fallback_s,
        flagged,
        ..Default::default()
    };
    Ok((result_from(f, &answers), times))
}

#[cfg(not(feature = "embree"))]
fn embree_scan(_: &Foundry, _: &[RayRow]) -> crate::Result<(ScanResult, ScanTimes)> {
    bail!("{NO_EMBREE}")
}

/// Why a build without the `embree` feature refuses `--backend embree`.
#[cfg(not(feature = "embree"))]
const NO_EMBREE: &str = "this hytrace was built without Embree; rebuild with \
     `cargo build --release --features embree` (needs Debian's libembree-dev)";

/// The media's transmittance over each ray's `[tmin, end]` with Embree finding the brick
/// clusters (see [`crate::embree::EmbreeScene::trace_transmittance`]).
#[cfg(feature = "embree")]
fn embree_transmittance(
    f: &Foundry,
    rays: &[RayRow],
    ends: &[f64],
    params: &TransmittanceParams,
    (first_ray, memory): (u32, u64),
) -> crate::Result<TransmittanceRun> {
    timed_transmittance(|opened| {
        let cpu = CpuScene::<f32>::new(f)?;
        let media = SceneMedia::with_memory(&cpu, f, params, memory)?;
        let scene = crate::embree::EmbreeScene::new(f, &cpu)?;
        *opened = Instant::now();
        media.transmittances_with(rays, ends, first_ray, |r, end| {
            let ray = Ray::from_f64(r.origin, r.direction);
            scene.cluster_visits(&ray, r.tmin, end)
        })
    })
}

/// A transmittance run on the CPU side: `run` opens the scene and its media, sets
/// `opened` to when it is done, and estimates; the two parts are timed apart.
fn timed_transmittance(
    run: impl FnOnce(&mut Instant) -> crate::Result<Vec<f64>>,
) -> crate::Result<TransmittanceRun> {
    let t0 = Instant::now();
    let mut opened = t0;
    let values = run(&mut opened)?;
    Ok(TransmittanceRun {
        values,
        open_s: (opened - t0).as_secs_f64(),
        transmittance_s: opened.elapsed().as_secs_f64(),
        gpu: None,
    })
}

#[cfg(not(feature = "embree"))]
fn embree_transmittance(
    _: &Foundry,
    _: &[RayRow],
    _: &[f64],
    _: &TransmittanceParams,
    _: (u32, u64),
) -> crate::Result<TransmittanceRun> {
    bail!("{NO_EMBREE}")
}

/// Writes the hits, `(N, 4)` float32 or float64 per the precision, atomically.
pub fn write_hits(result: &ScanResult, precision: Precision, path: &Path) -> crate::Result<()> {
    let shape = [result.hits.len() as u64, 4];
    match precision {
        Precision::F32 => {
            let flat = result.hits_f32();
            write_array(path, Scalar::F32, &shape, bytemuck::cast_slice(&flat))?;
        }
        Precision::F64 => {
            let flat: Vec<f64> = result.hits.iter().flatten().copied().collect();
            write_array(path, Scalar::F64, &shape, bytemuck::cast_slice(&flat))?;
        }
    }
    Ok(())
}

/// Writes the identities of the crossings, `(N, 3)` int32, atomically.
pub fn write_ids(result: &ScanResult, path: &Path) -> crate::Result<()> {
    write_array(
        path,
        Scalar::I32,
        &[result.ids.len() as u64, ID_COLUMNS as u64],
        bytemuck::cast_slice(&result.ids),
    )?;
    Ok(())
}

/// The stats line of `--stats`.
pub fn stats_json(
    backend: Backend,
    rays: usize,
    load_s: f64,
    times: &ScanTimes,
    hits: usize,
) -> serde_json::Value {
    // `auto` reports the backend it fell to.
    let ran_on = match (backend, &times.gpu) {
        (Backend::Auto, Some(_)) => Backend::Gpu,
        (Backend::Auto, None) => Backend::Cpu,
        (b, _) => b,
    };
    let mut line = json!({
        "backend": format!("{ran_on:?}").to_lowercase(),
        "rays": rays,
        "hits": hits,
        "load_s": load_s,
        "build_s": times.build_s,
        "trace_s": times.trace_s,
        "rays_per_s": if times.trace_s > 0.0 { rays as f64 / times.trace_s } else { 0.0 },
        "threads": rayon::current_num_threads(),
        "simd": hytrace_csg::simd::selected().to_string(),
        "redone_in_f64": times.redone_in_f64,
        "fallback_s": times.fallback_s,
        "flagged": times.flagged,
    });
    if let Some(g) = &times.gpu {
        crate::gpu::add_gpu_stats(&mut line, &g.adapter, &g.features, &g.times);
        line["gpu_host_s"] = g.host_s.into();
    }
    line
}
