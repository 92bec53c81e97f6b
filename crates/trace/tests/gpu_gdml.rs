//! The GPU scan kernel against its CPU twin (`CpuScene::<f32>::trace`), ray by ray, on every
//! file of the shared public GDML corpus (`HYTRACE_GDML_DIR`, default `../shared/gdml`
//! beside the repository): at least 99.99% of all rays and 99.9% of each file's agree, and
//! the kernel's flags for the f64 fallback (`CpuScene::trace_flagged`) are the CPU's on
//! every ray whose answer is the CPU's bit for bit.
//!
//! Every file runs on lavapipe too. llvmpipe stops any loop after 65 535 iterations per
//! SIMD group of 8 invocations (`LP_MAX_TGSI_LOOP_ITERATIONS` in Mesa), silently;
//! `celeritas/solids.gdml` used to reach that cap while its twisted arb8s were tessellated
//! into face-high slivers, and now, with well-shaped triangles, agrees bit for bit.

mod common;

use std::time::Instant;

use common::{compare, f32_ray, gpu_run, rays_for};
use hytrace_csg::Ray;
use hytrace_foundry::gdml::GdmlOptions;
use hytrace_foundry::Foundry;
use hytrace_testkit::files::{shared_gdml_dir, shared_gdml_files};
use hytrace_trace::cpu::{CpuScene, Hit};
use hytrace_trace::gpu::GpuContext;
use hytrace_trace::scan::RayRow;
use hytrace_trace::scene::load_scene;

/// Rays per file: sweeps of this many rays a side (three sweeps) ...
const SWEEP: usize = 40;
/// ... and this many random rays.
const RANDOM: usize = 3000;

#[test]
fn gpu_matches_cpu_on_every_shared_gdml_file() {
    let Some(ctx) = GpuContext::for_tests() else {
        return;
    };
    let dir = shared_gdml_dir();
    let files = shared_gdml_files();
    let start = Instant::now();
    let (mut rays_all, mut agree_all) = (0, 0);
    let mut failed = Vec::new();
    let mut lines = Vec::new();
    for path in &files {
        let name = path.strip_prefix(&dir).unwrap().display().to_string();
        // The Geant4 oracle loads every shared file this way: none is skipped.
        let f = load_scene(Some(path), &GdmlOptions::default())
            .unwrap_or_else(|e| panic!("{name}: {e:#}"));
        let rays = rays_for(&f, SWEEP, RANDOM);
        let run = gpu_run(&ctx, &f, &rays).unwrap_or_else(|e| panic!("{name}: {e}"));
        let t = Instant::now();
        let a = compare(&name, &f, &rays, &run.hits);
        let flags = flag_mismatches(&f, &rays, &run.hits, &run.flags);
        if flags > 0 {
            failed.push(format!("{name}: {flags} rays flagged otherwise"));
        }
        let line = format!(
            "{name:<60} {:>6} rays {:>6} hits {:>8.3}% agree {:>8.3}% identical  build {:>5.1} s  trace {:>5.1} s  cpu {:>5.1} s{}",
            a.rays,
            a.hits,
            a.percent(),
            100.0 * a.identical as f64 / a.rays.max(1) as f64,
            run.build_s,
            run.trace_s,
            t.elapsed().as_secs_f64(),
            if run.cut_short > 0 {
                format!("  {} CUT SHORT", run.cut_short)
            } else {
                String::new()
            }
        );
        eprintln!("{line}");
        lines.push(line);
        rays_all += a.rays;
        agree_all += a.agree;
        if a.percent() < 99.9 || run.cut_short > 0 {
            failed.push(name);
        }
    }
    eprintln!("\n{} files:", files.len());
    for line in &lines {
        eprintln!("{line}");
    }
    let overall = 100.0 * agree_all as f64 / rays_all.max(1) as f64;
    eprintln!(
        "all: {rays_all} rays, {overall:.4}% agree, {:.1} s",
        start.elapsed().as_secs_f64()
    );
    assert!(
        failed.is_empty(),
        "below 99.9%, cut short or flagged otherwise: {failed:?}"
    );
    assert!(overall >= 99.99, "{overall:.4}% of {rays_all} rays agree");
}

/// Rays whose answer on the GPU is the CPU's f32 trace's bit for bit but whose flags are
/// not (printing the first few).
fn flag_mismatches(
    f: &Foundry,
    rays: &[RayRow],
    hits: &[Option<Hit<f32>>],
    flags: &[u32],
) -> usize {
    let cpu = CpuScene::<f32>::new(f).unwrap();
    let mut wrong = 0;
    for (i, r) in rays.iter().enumerate() {
        let (_, tmin, tmax) = f32_ray(r);
        let c = cpu.trace_flagged(&Ray::from_f64(r.origin, r.direction), tmin, tmax);
        if c.hit == hits[i] && c.flags != flags[i] {
            if wrong < 5 {
                eprintln!(
                    "ray {i} {r:?}: flags {} on the CPU, {} on the GPU",
                    c.flags, flags[i]
                );
            }
            wrong += 1;
        }
    }
    wrong
}
