//! Accuracy rows of the GPU tracer against the CPU's: the embedded default scene (CSG
//! booleans, a torus, instanced solids) scanned in f32 on both, judged against the CPU's
//! f64 tracer. On lavapipe the GPU's time means nothing for real GPUs: the row is
//! functional there, and says so.

use hytrace_csg::{Ray, V3};

use crate::cpu::CpuScene;
use crate::gpu::{GpuContext, GpuTracer, GPU_INF};
use crate::scan::{ray_record, RayRow};
use crate::scene::default_scene;
use crate::sweep::{generate, scene_bounds, Sweep};

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
            let ray = Ray {
                origin: V3::from_f64(r.origin),
                direction: V3::from_f64(r.direction),
            };
            scene
                .trace(&ray, T::from_f64(r.tmin), T::INFINITY)
                .map(|h| (h.t.to_f64(), h.instance))
        })
        .collect()
}

/// The CPU f32 row and, when an adapter opens, the GPU row; without an adapter the GPU row
/// is left out with a note on stderr.
pub(super) fn rows(settings: Settings) -> Result<Vec<Row>, String> {
    let err = |e: &dyn std::fmt::Display| format!("{COMPONENT}: {e}");
    let foundry = default_scene().map_err(|e| err(&e))?;
    let bounds = scene_bounds(&foundry).ok_or_else(|| err(&"the default scene is empty"))?;
    let rays = generate(Sweep::Circle, &bounds, settings.size(20_000, 1000));
    let f64_scene = CpuScene::<f64>::new(&foundry).map_err(|e| err(&e))?;
    let f32_scene = CpuScene::<f32>::new(&foundry).map_err(|e| err(&e))?;
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
    let ctx = match GpuContext::new() {
        Ok(ctx) => ctx,
        Err(e) => {
            eprintln!("hytrace: no GPU adapter ({e}); the GPU row is left out");
            return Ok(rows);
        }
    };
    let tracer = GpuTracer::new(&ctx, &f32_scene).map_err(|e| err(&e))?;
    let records: Vec<_> = rays.iter().map(ray_record).collect();
    let (hits, _) = tracer.trace(&ctx, &records).map_err(|e| err(&e))?;
    let got: Vec<Answer> = hits
        .iter()
        .map(|h| (h.t < GPU_INF).then(|| (f64::from(h.t), h.instance)))
        .collect();
    // Host time of the whole trace (upload, kernels, readback): the pipeline is built once.
    let ns = timer.ns_per_op(rays.len(), || {
        tracer.trace(&ctx, &records).map(|r| r.0.len())
    });
    let info = &ctx.adapter_info;
    let functional = if info.device_type == wgpu::DeviceType::Cpu {
        ", a CPU adapter: functional only"
    } else {
        ""
    };
    rows.push(Row {
        component: COMPONENT,
        variant: format!("GPU f32 on {} ({:?}{functional})", info.name, info.backend),
        metric: METRIC,
        reference: REFERENCE,
        error: max_error(&got, &want),
        ns_per_op: ns,
        memory_bytes: None,
    });
    Ok(rows)
}
