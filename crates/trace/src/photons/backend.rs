//! Where a photon run goes (`hytrace photons --backend`): the CPU propagator (f64
//! geometry), the GPU kernel (f32, [`crate::gpu::GpuPhotons`]) or, with `auto`, the GPU
//! when an adapter opens and the kernel models the scene's physics, else the CPU.

use std::path::Path;
use std::time::Instant;

use hytrace_foundry::Foundry;

use super::run::{prepare, propagate_in};
use super::tracer::Precision;
use super::{PhotonRun, PhotonScene, RunOptions};
use crate::error::Context;
use crate::gpu::{gpu_or_cpu, GpuContext, GpuPhotons, GpuTimes};
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
    (PhotonBackend::Gpu, "gpu", [], "The WGSL photon kernel through wgpu (f32): torch sources, fixed wavelengths, absorption, Rayleigh scattering, Fresnel boundaries, polished surfaces"),
    (PhotonBackend::Auto, "auto", [], "The GPU when an adapter opens and the kernel models the scene's physics, else the CPU"),
});

/// What the GPU side of a photon run reports.
pub struct GpuPhotonInfo {
    /// The adapter (name, type, backend, driver).
    pub adapter: String,
    /// The composition features of the kernel.
    pub features: Vec<&'static str>,
    /// Upload, kernel and readback seconds, and the photons the CPU propagated again.
    pub times: GpuTimes,
}

/// A photon run on a backend.
pub struct BackendRun {
    /// The results.
    pub run: PhotonRun,
    /// Seconds preparing the scene (and on the GPU, building the kernel).
    pub build_s: f64,
    /// The GPU's report; `None` when the CPU ran.
    pub gpu: Option<GpuPhotonInfo>,
}

/// Prepares the scene `f` read from `path` and propagates `run` on `backend`; errors
/// name the file. `auto` tells on stderr why it fell back to the CPU.
pub fn propagate_on(
    f: &Foundry,
    surfaces: Option<VolumeSurfaces>,
    path: &Path,
    run: &RunOptions,
    backend: PhotonBackend,
    progress: &dyn Fn(u64),
) -> crate::Result<BackendRun> {
    let cpu = |surfaces| {
        let t = Instant::now();
        let scene = prepare(f, surfaces, path)?;
        let build_s = t.elapsed().as_secs_f64();
        Ok(BackendRun {
            run: propagate_in(&scene, path, run, progress)?,
            build_s,
            gpu: None,
        })
    };
    let gpu = |ctx: GpuContext, surfaces| {
        let t = Instant::now();
        let scene = PhotonScene::with_precision(f, surfaces, Precision::F32)
            .with_context(|| format!("{}: preparing for photons", path.display()))?;
        let kernel = GpuPhotons::new(&ctx, &scene, &run.wavelength)
            .with_context(|| format!("{}: the GPU photon kernel", path.display()))?;
        let build_s = t.elapsed().as_secs_f64();
        let done = kernel
            .propagate(&ctx, &scene, run, progress)
            .with_context(|| format!("{}: propagating photons on the GPU", path.display()))?;
        Ok(BackendRun {
            run: done.run,
            build_s,
            gpu: Some(GpuPhotonInfo {
                adapter: ctx.describe(),
                features: kernel.features().to_vec(),
                times: done.times,
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
