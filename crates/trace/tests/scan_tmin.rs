//! `tmin` in a hierarchical (GDML) scene: a ray's distances count from its origin, but the
//! volume it is answered from is the one it is in at `tmin`. A ray starting 1e-4 mm inside
//! a ball of radius 30 mm centred 40 mm along x in a 200 mm tank (`every_process.gdml`),
//! going +x with `tmin` 1e-3 mm, has left the ball before `tmin`: its next boundary is the
//! tank's wall at x = 100 mm, 30.0001 mm on (analytic). Before the fix it was answered
//! from the ball and missed. In f32 and f64 on the CPU, and on the GPU.

mod common;

use common::repo;
use hytrace_foundry::gdml::GdmlOptions;
use hytrace_trace::gpu::GpuContext;
use hytrace_trace::scan::{scan, scan_with, Backend, Precision, RayRow, ScanResult};
use hytrace_trace::scene::load_scene;

fn ray(x: f64, tmin: f64) -> RayRow {
    RayRow {
        origin: [x, 0.0, 0.0],
        direction: [1.0, 0.0, 0.0],
        tmin,
        tmax: f64::INFINITY,
    }
}

/// The rays and the distances they must answer (analytic), within 1e-3 mm.
fn cases() -> (Vec<RayRow>, Vec<f64>) {
    let inside = 69.9999;
    let rays = vec![
        // From inside the ball: its surface 1e-4 mm on.
        ray(inside, 0.0),
        // `tmin` within the ball: still its surface.
        ray(inside, 1e-5),
        // `tmin` past the ball's surface: the tank's wall.
        ray(inside, 1e-3),
        // From the ball's centre, `tmin` past its surface: the tank's wall 60 mm on.
        ray(40.0, 35.0),
        // A `tmin` past the tank too: the world's shell (300 mm box) at x = 150.
        ray(inside, 40.0),
    ];
    (rays, vec![1e-4, 1e-4, 30.0001, 60.0, 80.0001])
}

fn check(label: &str, result: &ScanResult, want: &[f64]) {
    for (i, (hit, w)) in result.hits.iter().zip(want).enumerate() {
        assert!(
            (hit[3] - w).abs() < 1e-3,
            "{label}: ray {i} answers {} where the geometry says {w}",
            hit[3]
        );
    }
}

#[test]
fn a_ray_is_answered_from_the_volume_it_is_in_at_tmin() {
    let f = load_scene(
        Some(&repo("tests/data/photons/every_process.gdml")),
        &GdmlOptions::default(),
    )
    .unwrap();
    assert!(f.is_hierarchical());
    let (rays, want) = cases();
    for precision in [Precision::F32, Precision::F64] {
        let (result, _) = scan(&f, &rays, precision).unwrap();
        check(&format!("{precision}"), &result, &want);
    }
    if GpuContext::for_tests().is_some() {
        let (gpu, _) = scan_with(&f, &rays, Precision::F32, Backend::Gpu).unwrap();
        check("gpu", &gpu, &want);
    }
}
