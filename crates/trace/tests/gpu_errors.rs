//! GPU failures give clear errors, never answers: a lost device (destroyed here, as a driver
//! reset loses it) fails the scan and the volume transmittance with a device-lost error.

use hytrace_trace::cpu::CpuScene;
use hytrace_trace::gpu::{gpu_or_cpu, GpuContext, GpuError, GpuTracer, GpuVolume};
use hytrace_trace::scan::ray_record;
use hytrace_trace::scene::default_scene;
use hytrace_trace::sweep::{generate, scene_bounds, Sweep};
use hytrace_volume::{fog_sphere, BrickedGrid, Estimator, Ray, TexelFormat, TransmittanceParams};

fn assert_lost<T>(what: &str, result: Result<T, impl Into<anyhow::Error>>) {
    let err: anyhow::Error = match result {
        Ok(_) => panic!("{what} answered on a lost device"),
        Err(e) => e.into(),
    };
    match err.chain().find_map(|c| c.downcast_ref::<GpuError>()) {
        Some(GpuError::DeviceLost(reason)) => {
            assert!(reason.contains("Destroyed"), "{what}: {reason}");
            assert!(err.to_string().contains("device was lost"), "{err}");
        }
        _ => panic!("{what}: expected a device-lost error, got {err:#}"),
    }
}

#[test]
fn a_lost_device_fails_scans_and_transmittances_clearly() {
    let Some(ctx) = GpuContext::for_tests() else {
        return;
    };
    let f = default_scene().unwrap();
    let scene = CpuScene::<f32>::new(&f).unwrap();
    let tracer = GpuTracer::new(&ctx, &scene).unwrap();
    let rays = generate(Sweep::Circle, &scene_bounds(&f).unwrap(), 16).unwrap();
    let records: Vec<_> = rays.iter().map(ray_record).collect();
    assert!(tracer.trace(&ctx, &records).is_ok());
    let grid = BrickedGrid::convert(&fog_sphere(6.0, 2.0).unwrap(), TexelFormat::F32).unwrap();
    let volume = GpuVolume::new(&ctx, &grid).unwrap();
    let through = [Ray::new([-20.0, 0.0, 0.0], [1.0, 0.0, 0.0], 0.0, 40.0)];
    let exact = TransmittanceParams::new(Estimator::Exact);
    assert!(volume.transmittance(&ctx, &through, &exact).is_ok());

    ctx.device.destroy();
    let _ = ctx.device.poll(wgpu::PollType::wait_indefinitely());
    assert!(ctx.check_not_lost().is_err());
    assert_lost("scan", tracer.trace(&ctx, &records));
    assert_lost(
        "transmittance",
        volume.transmittance(&ctx, &through, &exact),
    );
}

/// `--backend auto` falls back to the CPU on the GPU's failures (a lost device here), not on
/// the input's.
#[test]
fn auto_falls_back_on_gpu_failures_only() {
    let lost = gpu_or_cpu(
        "scans",
        |_| -> hytrace_trace::Result<u32> {
            Err(GpuError::DeviceLost("Unknown: reset".into()).into())
        },
        || Ok(7),
    );
    assert_eq!(lost.unwrap(), 7);
    let bad_input = gpu_or_cpu(
        "scans",
        |_| -> hytrace_trace::Result<u32> {
            Err(hytrace_trace::Error::invalid("rays.npy: wrong shape"))
        },
        || Ok(7),
    );
    // Without an adapter the GPU closure never runs and the CPU answers.
    if GpuContext::new().is_ok() {
        assert!(bad_input.unwrap_err().to_string().contains("wrong shape"));
    }
}
