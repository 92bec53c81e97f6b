//! Where a photon run goes (`hytrace photons --backend`): the CPU propagator (f64
//! geometry), the GPU kernel (f32, [`crate::gpu::GpuPhotons`]) or, with `auto`, the GPU
//! when an adapter opens and the kernel models the scene's physics, else the CPU.

use std::path::Path;
use std::time::Instant;

use hytrace_foundry::Foundry;

use super::run::{prepare, propagate_batches_in};
use super::tracer::Precision;
use super::{Batch, PhotonError, PhotonScene, RunOptions, RunSummary};
use crate::error::Context;
use crate::gpu::{gpu_or_cpu, GpuContext, GpuPhotons, GpuTimes, PhotonHostWork};
use crate::scene::VolumeSurfaces;

/// Where photons are propagated.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum PhotonBackend {
    /// The CPU propagator (rayon over photons, f64 geometry).
    #[default]
    Cpu,
    /// The WGSL photon kernel through wgpu (f32).
    Gpu,
    /// The GPU when an adapter opens and the kernel models the scene, else the CPU.
    Auto,
}

crate::choice::named!(PhotonBackend {
    (PhotonBackend::Cpu, "cpu", [], "The CPU propagator (rayon over photons, f64 geometry)"),
    (PhotonBackend::Gpu, "gpu", [], "The WGSL photon kernel through wgpu (f32): the CPU's physics, sources, gensteps and outputs"),
    (PhotonBackend::Auto, "auto", [], "The GPU when an adapter opens, else the CPU"),
});

/// What the GPU side of a photon run reports.
pub struct GpuPhotonInfo {
    /// The adapter (name, type, backend, driver).
    pub adapter: String,
    /// The composition features of the kernel.
    pub features: Vec<&'static str>,
    /// Upload, kernel and readback seconds, and the photons the CPU propagated again.
    pub times: GpuTimes,
    /// The host's work on the batches' results, the photons a batch and what streaming a
    /// medium read as stored did.
    pub host: PhotonHostWork,
}

/// A photon run on a backend.
pub struct BackendRun {
    /// What the run's batches added up to.
    pub run: RunSummary,
    /// Seconds preparing the scene (and on the GPU, building the kernel).
    pub build_s: f64,
    /// The GPU's report; `None` when the CPU ran.
    pub gpu: Option<GpuPhotonInfo>,
}

/// Prepares the scene `f` read from `path` and propagates `run` on `backend`, `batch`
/// photons at a time (by default the CPU's [`super::propagate::BATCH`], on the GPU as many
/// as fill it), handing each batch's results to `sink` as it finishes; errors name the
/// file. On the GPU a medium read as stored streams through a brick pool of at most
/// `memory` device bytes ([`GpuPhotons::with_memory`]). `auto` tells on stderr why it fell
/// back to the CPU.
#[allow(clippy::too_many_arguments)]
pub fn propagate_on(
    f: &Foundry,
    surfaces: Option<VolumeSurfaces>,
    path: &Path,
    run: &RunOptions,
    backend: PhotonBackend,
    batch: Option<u64>,
    memory: u64,
    sink: &mut dyn FnMut(Batch) -> Result<(), PhotonError>,
    progress: &dyn Fn(u64),
) -> crate::Result<BackendRun> {
    // `auto` falls back to the CPU when the GPU fails before any batch reached the sink
    // (the kernel is built first); after, the output is part written and the run fails.
    let sink = std::cell::RefCell::new(sink);
    let started = std::cell::Cell::new(false);
    let cpu = |surfaces| {
        if started.get() {
            crate::error::bail!(
                "{}: the GPU failed part way through the run; run it again with --backend cpu",
                path.display()
            );
        }
        let t = Instant::now();
        let scene = prepare(f, surfaces, path)?;
        let build_s = t.elapsed().as_secs_f64();
        let mut sink = sink.borrow_mut();
        Ok(BackendRun {
            run: propagate_batches_in(
                &scene,
                path,
                run,
                batch.unwrap_or(super::propagate::BATCH),
                &mut **sink,
                progress,
            )?,
            build_s,
            gpu: None,
        })
    };
    let gpu = |ctx: GpuContext, surfaces| {
        let t = Instant::now();
        let scene = PhotonScene::with_precision(f, surfaces, Precision::F32)
            .with_context(|| format!("{}: preparing for photons", path.display()))?;
        let kernel = GpuPhotons::new(&ctx, &scene, run)
            .with_context(|| format!("{}: the GPU photon kernel", path.display()))?
            .with_memory(memory);
        let build_s = t.elapsed().as_secs_f64();
        let mut sink = sink.borrow_mut();
        let mut noted = |b: Batch| {
            started.set(true);
            sink(b)
        };
        let (summary, times, host) = kernel
            .propagate_into(&ctx, &scene, run, batch, &mut noted, progress)
            .with_context(|| format!("{}: propagating photons on the GPU", path.display()))?;
        Ok(BackendRun {
            run: summary,
            build_s,
            gpu: Some(GpuPhotonInfo {
                adapter: ctx.describe(),
                features: kernel.features().to_vec(),
                times,
                host,
            }),
        })
    };
    match backend {
        PhotonBackend::Cpu => cpu(surfaces),
        PhotonBackend::Gpu => gpu(GpuContext::new()?, surfaces),
        PhotonBackend::Auto => {
            let again = surfaces.clone();
            gpu_or_cpu(
                "propagates photons",
                |ctx| gpu(ctx, surfaces),
                || cpu(again),
            )
        }
    }
}
