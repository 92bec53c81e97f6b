//! Accuracy rows of the GPU kernels against the CPU's: the embedded default scene (CSG
//! booleans, a torus, instanced solids) scanned in f32 on both, judged against the CPU's
//! f64 tracer; and the volume transmittance (exact and ratio tracking) on the transmittance
//! rows' fog, judged against their quadrature reference. On a CPU adapter (lavapipe) the
//! GPU's time means nothing for real GPUs: those rows are functional there, and say so.

use hytrace_csg::Ray;

use hytrace_volume::{BrickedGrid, Estimator, Majorant, TexelFormat};

use crate::cpu::CpuScene;
use crate::error::Context;
use crate::gpu::{GpuContext, GpuTracer, GpuVolume, GPU_INF};
use crate::scan::{ray_record, RayRow};
use crate::scene::default_scene;
use crate::sweep::{generate, scene_bounds, Sweep};

use super::volume::{fog_params, Fog};
use super::{Row, Settings, Timer};

const COMPONENT: &str = "gpu vs cpu scan";
const METRIC: &str = "max |t - t_ref| / t_ref; a wrong hit, miss or instance counts 1";
const REFERENCE: &str = "hytrace CPU tracer in f64";

/// `(t, instance)` of a hit, `None` on a miss.
type Answer = Option<(f64, u32)>;

/// The worst relative disagreement of `got` with `want` (see [`METRIC`]).
fn max_error(got: &[Answer], want: &[Answer]) -> f64 {
    got.iter()
        .zip(want)
        .map(|(g, w)| match (g, w) {
            (Some((g, gi)), Some((w, wi))) if gi == wi => (g - w).abs() / w.abs().max(1.0),
            (None, None) => 0.0,
            _ => 1.0,
        })
        .fold(0.0, f64::max)
}

fn cpu_answers<T: hytrace_csg::Real>(scene: &CpuScene<T>, rays: &[RayRow]) -> Vec<Answer> {
    rays.iter()
        .map(|r| {
            let ray = Ray::from_f64(r.origin, r.direction);
            scene
                .trace(&ray, T::from_f64(r.tmin), T::INFINITY)
                .map(|h| (h.t.to_f64(), h.instance))
        })
        .collect()
}

/// What a GPU row's variant adds on a CPU adapter.
fn functional(ctx: &GpuContext) -> &'static str {
    if ctx.adapter_info.device_type == wgpu::DeviceType::Cpu {
        ", a CPU adapter: functional only"
    } else {
        ""
    }
}

/// The scan rows and the transmittance rows; without an adapter the GPU rows are left out
/// with a note on stderr.
pub(super) fn rows(settings: Settings) -> crate::Result<Vec<Row>> {
    let ctx = match GpuContext::new() {
        Ok(ctx) => Some(ctx),
        Err(e) => {
            eprintln!("hytrace: no GPU adapter ({e}); the GPU rows are left out");
            None
        }
    };
    let mut rows = scan_rows(settings, ctx.as_ref())?;
    rows.extend(transmittance_rows(settings, ctx.as_ref())?);
    Ok(rows)
}

/// The CPU f32 scan row and, with `ctx`, the GPU's.
fn scan_rows(settings: Settings, ctx: Option<&GpuContext>) -> crate::Result<Vec<Row>> {
    let foundry = default_scene().context(COMPONENT)?;
    let bounds =
        scene_bounds(&foundry).context(format!("{COMPONENT}: the default scene is empty"))?;
    let rays = generate(Sweep::Circle, &bounds, settings.size(20_000, 1000)).context(COMPONENT)?;
    let f64_scene = CpuScene::<f64>::new(&foundry).context(COMPONENT)?;
    let f32_scene = CpuScene::<f32>::new(&foundry).context(COMPONENT)?;
    let want = cpu_answers(&f64_scene, &rays);
    let timer = Timer::new(settings);
    let mut rows = vec![Row {
        component: COMPONENT,
        variant: "CPU f32, 1 thread".into(),
        metric: METRIC,
        reference: REFERENCE,
        error: max_error(&cpu_answers(&f32_scene, &rays), &want),
        ns_per_op: timer.ns_per_op(rays.len(), || cpu_answers(&f32_scene, &rays)),
        memory_bytes: None,
    }];
    let Some(ctx) = ctx else {
        return Ok(rows);
    };
    let tracer = GpuTracer::new(ctx, &f32_scene).context(COMPONENT)?;
    let records: Vec<_> = rays.iter().map(ray_record).collect();
    let (hits, _) = tracer.trace(ctx, &records).context(COMPONENT)?;
    let got: Vec<Answer> = hits
        .iter()
        .map(|h| (h.t < GPU_INF).then(|| (f64::from(h.t), h.instance)))
        .collect();
    // Host time of the whole trace (upload, kernels, readback): the pipeline is built once.
    let ns = timer.ns_per_op(rays.len(), || {
        tracer.trace(ctx, &records).map(|r| r.0.len())
    });
    let info = &ctx.adapter_info;
    rows.push(Row {
        component: COMPONENT,
        variant: format!(
            "GPU f32 on {} ({:?}{})",
            info.name,
            info.backend,
            functional(ctx)
        ),
        metric: METRIC,
        reference: REFERENCE,
        error: max_error(&got, &want),
        ns_per_op: ns,
        memory_bytes: None,
    });
    Ok(rows)
}

/// Exact and ratio-tracking transmittance on the CPU (f64, one thread) and, with `ctx`, on
/// the GPU (f32, the grid as f32 bricks, which hold its values exactly).
fn transmittance_rows(settings: Settings, ctx: Option<&GpuContext>) -> crate::Result<Vec<Row>> {
    const CONTEXT: &str = "gpu vs cpu transmittance";
    let fog = Fog::new(settings)?;
    let timer = Timer::new(settings);
    let bricks = BrickedGrid::convert(&fog.grid, TexelFormat::F32).context(CONTEXT)?;
    let gpu = match ctx {
        Some(ctx) => Some((ctx, GpuVolume::new(ctx, &bricks).context(CONTEXT)?)),
        None => None,
    };
    // The fog's grid has the identity map: its index rays are its world rays.
    let rays: Vec<hytrace_volume::Ray> = fog
        .rays
        .iter()
        .map(|r| hytrace_volume::Ray::new(r.origin, r.dir, r.tmin, r.tmax))
        .collect();
    let rms = |t: &mut dyn Iterator<Item = f64>| {
        let squares: f64 = t.zip(&fog.reference).map(|(t, r)| (t - r) * (t - r)).sum();
        (squares / fog.reference.len() as f64).sqrt()
    };
    let row = |variant: String, error: f64, ns_per_op: f64| Row {
        component: "gpu vs cpu transmittance",
        variant,
        metric: "RMS |T - T_ref| over rays",
        reference: "the transmittance rows' quadrature of the trilinear interpolant (f64)",
        error,
        ns_per_op,
        memory_bytes: None,
    };
    let mut rows = Vec::new();
    let local = Majorant::Local { level: 0 };
    for (estimator, spp, name) in [
        (Estimator::Exact, 1, "exact"),
        (Estimator::Ratio, 4, "ratio, 4 spp"),
    ] {
        let params = fog_params(estimator, spp, local);
        let (cpu, ns) = fog.trace(&params, timer)?;
        let error = rms(&mut cpu.iter().map(|e| e.transmittance));
        rows.push(row(format!("{name}, CPU f64, 1 thread"), error, ns));
        if let Some((ctx, volume)) = &gpu {
            let run = || volume.transmittance(ctx, &rays, &params);
            let (estimates, _) = run().context(CONTEXT)?;
            let error = rms(&mut estimates.iter().map(|e| e.transmittance));
            let ns = timer.ns_per_op(rays.len(), run);
            let variant = format!(
                "{name}, GPU f32 on {}{}",
                ctx.adapter_info.name,
                functional(ctx)
            );
            rows.push(row(variant, error, ns));
        }
    }
    Ok(rows)
}
