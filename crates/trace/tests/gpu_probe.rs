//! The probe kernels on the GPU (lavapipe in CI) agree with their CPU twins point by point.
//! With HYTRACE_REQUIRE_GPU=1 a missing adapter fails these tests.

use hytrace_foundry::Transform64;
use hytrace_testkit::{Random, SplitMix64};
use hytrace_trace::gpu::probe::{apply_itra_cpu, locate_cpu, ProbeKernels};
use hytrace_trace::gpu::{GpuContext, GpuScene};
use hytrace_trace::scene::default_scene;

/// A point uniform in the cube of half side `half`, in f32.
fn point(rng: &mut SplitMix64, half: f64) -> [f32; 3] {
    [0; 3].map(|_| ((rng.uniform() * 2.0 - 1.0) * half) as f32)
}

#[test]
fn gpu_apply_itra_matches_cpu_and_f64() {
    let Some(ctx) = GpuContext::for_tests() else {
        return;
    };
    let mut f = default_scene().unwrap();
    // Add transforms far from the origin and with rotation + scale.
    let far = Transform64::translation([2.0e4, -3.0e4, 1.0e4]);
    let skew = Transform64 {
        rows: [
            [0.0, -2.0, 0.0, 5.0],
            [1.0, 0.0, 0.0, -7.0],
            [0.0, 0.0, 0.5, 3.0],
            [0.0, 0.0, 0.0, 1.0],
        ],
    };
    f.add_transform(far).unwrap();
    f.add_transform(skew).unwrap();
    let scene = GpuScene::upload(&ctx, &f).unwrap();
    let kernels = ProbeKernels::new(&ctx, &scene).unwrap();
    let mut rng = SplitMix64(7);
    let n = 10_000;
    let points: Vec<[f32; 3]> = (0..n).map(|_| point(&mut rng, 3.0e4)).collect();
    let transforms: Vec<u32> = (0..n).map(|i| (i % (f.tran.len() + 1)) as u32).collect();
    let gpu = kernels
        .apply_itra(&ctx, &scene, &points, &transforms)
        .unwrap();
    let cpu = apply_itra_cpu(&f, &points, &transforms);
    for i in 0..n {
        let t = transforms[i] as usize;
        let exact = if t == 0 {
            points[i].map(f64::from)
        } else {
            f.tran[t - 1]
                .inverse()
                .unwrap()
                .apply_point(points[i].map(f64::from))
        };
        let scale = exact
            .iter()
            .chain(&points[i].map(f64::from))
            .fold(1.0f64, |a, v| a.max(v.abs()));
        for k in 0..3 {
            // Twins differ at most by FMA contraction; both stay within f32 rounding of f64.
            let (g, c) = (gpu[i][k] as f64, cpu[i][k] as f64);
            assert!(
                (g - c).abs() <= 4.0 * f32::EPSILON as f64 * scale,
                "point {i}: gpu {g} cpu {c}"
            );
            assert!(
                (g - exact[k]).abs() <= 8.0 * f32::EPSILON as f64 * scale,
                "point {i}: gpu {g} f64 {}",
                exact[k]
            );
        }
    }
    assert!(kernels
        .apply_itra(&ctx, &scene, &points[..3], &transforms[..2])
        .is_err());
    assert!(kernels
        .apply_itra(&ctx, &scene, &[], &[])
        .unwrap()
        .is_empty());
}

#[test]
fn gpu_locate_matches_cpu_twin() {
    let Some(ctx) = GpuContext::for_tests() else {
        return;
    };
    let f = default_scene().unwrap();
    let scene = GpuScene::upload(&ctx, &f).unwrap();
    let kernels = ProbeKernels::new(&ctx, &scene).unwrap();
    let mut rng = SplitMix64(11);
    // Uniform points in the detector plus points near PMT windows, where boxes nest.
    let mut points: Vec<[f32; 3]> = (0..20_000).map(|_| point(&mut rng, 1600.0)).collect();
    for k in 0..f.inst.len() {
        let at = f.inst_tran[k].apply_point([0.0, 0.0, 0.0]);
        for _ in 0..100 {
            let d = point(&mut rng, 150.0);
            points.push([0, 1, 2].map(|c| at[c] as f32 + d[c]));
        }
    }
    let gpu = kernels.locate(&ctx, &scene, &points).unwrap();
    let exact = locate_cpu(&f, &points, 0.0);
    // Where a point lies within 1e-3 mm of a box face, FMA contraction may flip the test;
    // the GPU count must then lie between the shrunk-box and grown-box counts.
    let inner = locate_cpu(&f, &points, -1e-3);
    let outer = locate_cpu(&f, &points, 1e-3);
    let mut identical = 0;
    let mut hits = 0;
    for i in 0..points.len() {
        if gpu[i] == exact[i] {
            identical += 1;
        } else {
            for c in 0..3 {
                assert!(
                    inner[i][c] <= gpu[i][c] && gpu[i][c] <= outer[i][c],
                    "point {i} {:?}: gpu {:?} cpu {:?}",
                    points[i],
                    gpu[i],
                    exact[i]
                );
            }
        }
        hits += (exact[i][0] > 0) as usize;
    }
    assert!(
        identical as f64 >= 0.9999 * points.len() as f64,
        "{identical} of {} identical",
        points.len()
    );
    assert!(
        hits > points.len() / 4,
        "the sample must exercise the instances ({hits} hits)"
    );
    assert!(kernels.locate(&ctx, &scene, &[]).unwrap().is_empty());
}
