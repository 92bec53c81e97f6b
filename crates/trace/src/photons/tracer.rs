//! The geometry under the photon propagator: the CPU tracer in f64 (the default), or in
//! f32, the precision of the GPU kernel's scene traversal, so that the CPU propagator is
//! the GPU photon kernel's twin (`shaders/kernels/photons.wgsl`; compared photon by photon
//! in `crates/trace/tests/gpu_photons.rs`): rays and points are rounded to f32 first, as
//! the kernel holds them. The physics stays f64 in both.

use hytrace_csg::{Ray, V3};

use crate::cpu::{CpuScene, Hit};
use hytrace_foundry::Foundry;

/// The precision of the geometry a photon run navigates with.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Precision {
    /// The CPU tracer in f64 (the default).
    #[default]
    F64,
    /// The CPU tracer in f32: the GPU kernel's geometry.
    F32,
}

/// The CPU tracer of a photon scene in either precision.
pub enum PhotonTracer {
    /// f64.
    F64(CpuScene<f64>),
    /// f32.
    F32(CpuScene<f32>),
}

/// A hit of the f32 tracer in f64.
fn widened(h: Hit<f32>) -> Hit<f64> {
    Hit {
        t: f64::from(h.t),
        normal: V3::from_f64(h.normal.to_f64()),
        instance: h.instance,
        prim: h.prim,
    }
}

/// `v` rounded to f32, as the GPU kernel holds a photon (no low part).
fn rounded(v: V3<f64>) -> V3<f64> {
    V3::from_f64(v.to_f64().map(|c| f64::from(c as f32)))
}

impl PhotonTracer {
    /// Prepares the scene's tracer in `precision`.
    pub fn new(f: &Foundry, precision: Precision) -> crate::Result<Self> {
        Ok(match precision {
            Precision::F64 => PhotonTracer::F64(CpuScene::new(f)?),
            Precision::F32 => PhotonTracer::F32(CpuScene::new(f)?),
        })
    }

    /// The navigator's step from inside instance `current` ([`CpuScene::trace_in`]), past
    /// `tmin`.
    pub fn trace_in(&self, ray: &Ray<f64>, current: u32, tmin: f64) -> Option<Hit<f64>> {
        match self {
            PhotonTracer::F64(s) => s.trace_in(ray, Some(current), tmin, f64::INFINITY),
            PhotonTracer::F32(s) => s
                .trace_in(
                    &Ray {
                        origin: rounded(ray.origin),
                        direction: rounded(ray.direction),
                    },
                    Some(current),
                    tmin as f32,
                    f32::INFINITY,
                )
                .map(widened),
        }
    }

    /// The instance containing `x` ([`CpuScene::locate_point`]).
    pub fn locate_point(&self, x: [f64; 3]) -> Option<u32> {
        match self {
            PhotonTracer::F64(s) => s.locate_point(x),
            PhotonTracer::F32(s) => s.locate_point(rounded(V3::from_f64(x)).to_f64()),
        }
    }

    /// The f32 scene (what the GPU uploads), `None` in f64.
    pub fn f32_scene(&self) -> Option<&CpuScene<f32>> {
        match self {
            PhotonTracer::F32(s) => Some(s),
            PhotonTracer::F64(_) => None,
        }
    }

    /// The precision.
    pub fn precision(&self) -> Precision {
        match self {
            PhotonTracer::F64(_) => Precision::F64,
            PhotonTracer::F32(_) => Precision::F32,
        }
    }
}
