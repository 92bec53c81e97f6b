//! The GPU scan kernel against its CPU twin (`CpuScene::<f32>::trace`), ray by ray, on every
//! file of the shared public GDML corpus (`HYTRACE_GDML_DIR`, default `../shared/gdml`
//! beside the repository): at least 99.99% of all rays and 99.9% of each file's agree.
//!
//! On lavapipe (a CPU adapter) one file is left out, with the reason printed: llvmpipe
//! stops any loop after 65 535 iterations per SIMD group of 8 invocations
//! (`LP_MAX_TGSI_LOOP_ITERATIONS` in Mesa), silently, and the group's other rays go wrong
//! with it. In `celeritas/solids.gdml` the ray from (-2769.23, 0, 0) along -y (it ends on
//! a finely tessellated solid) gives the world's wall at 3000 mm instead of 850 mm even
//! alone in its dispatch, and the ray along +y, right alone, goes wrong when dispatched
//! beside it: no correct kernel makes one invocation's answer depend on another's. Run on
//! lavapipe with all 50 files, 239 988 rays, 99.980% agreed, every disagreement in that
//! file (48 rays).

mod common;

use std::path::{Path, PathBuf};
use std::time::Instant;

use common::{compare, gpu_run, rays_for};
use hytrace_foundry::gdml::GdmlOptions;
use hytrace_trace::gpu::GpuContext;
use hytrace_trace::scene::load_scene;

/// Rays per file: sweeps of this many rays a side (three sweeps) ...
const SWEEP: usize = 40;
/// ... and this many random rays.
const RANDOM: usize = 3000;

/// Files whose searches exceed llvmpipe's loop cap (see the module docs).
const BEYOND_LAVAPIPE_LOOP_CAP: &[&str] = &["celeritas/solids.gdml"];

/// Every `.gdml` file under `dir`, sorted.
fn gdml_files(dir: &Path) -> Vec<PathBuf> {
    fn walk(dir: &Path, out: &mut Vec<PathBuf>) {
        for e in std::fs::read_dir(dir).unwrap().flatten() {
            let p = e.path();
            if p.is_dir() {
                walk(&p, out);
            } else if p.extension().is_some_and(|x| x == "gdml") {
                out.push(p);
            }
        }
    }
    let mut files = Vec::new();
    walk(dir, &mut files);
    files.sort();
    files
}

#[test]
fn gpu_matches_cpu_on_every_shared_gdml_file() {
    let Some(ctx) = GpuContext::for_tests() else {
        return;
    };
    let dir = std::env::var_os("HYTRACE_GDML_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/gdml"));
    assert!(dir.is_dir(), "{}: shared GDML files missing", dir.display());
    let files = gdml_files(&dir);
    assert!(!files.is_empty(), "{}: no GDML files", dir.display());
    let start = Instant::now();
    let (mut rays_all, mut agree_all) = (0, 0);
    let mut failed = Vec::new();
    let mut lines = Vec::new();
    let software = ctx.adapter_info.device_type == wgpu::DeviceType::Cpu;
    for path in &files {
        let name = path.strip_prefix(&dir).unwrap().display().to_string();
        if software && BEYOND_LAVAPIPE_LOOP_CAP.contains(&name.as_str()) {
            eprintln!("{name}: left out on a software adapter (llvmpipe's loop cap)");
            continue;
        }
        // The Geant4 oracle loads every shared file this way: none is skipped.
        let f = load_scene(Some(path), &GdmlOptions::default())
            .unwrap_or_else(|e| panic!("{name}: {e:#}"));
        let rays = rays_for(&f, SWEEP, RANDOM);
        let run = gpu_run(&ctx, &f, &rays).unwrap_or_else(|e| panic!("{name}: {e}"));
        let t = Instant::now();
        let a = compare(&name, &f, &rays, &run.hits);
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
    assert!(failed.is_empty(), "below 99.9% or cut short: {failed:?}");
    assert!(overall >= 99.99, "{overall:.4}% of {rays_all} rays agree");
}
