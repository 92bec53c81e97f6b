//! GDML import time and Foundry size: a synthetic detector of 50 000 placements of one
//! PMT-like volume (alone, and holding an inner volume: 100 001 instances), and the
//! largest shared file (DUNE's protodune, 2864 volumes).
//!
//! `cargo bench -p hytrace-tests --bench gdml` (reads ../shared/gdml for protodune). With
//! `HYTRACE_BENCH_OUT=DIR` the synthetic files are kept in DIR (to measure the peak memory
//! of `hytrace info` on them, say).

use std::path::Path;
use std::time::Instant;

use hytrace_foundry::gdml::{read_gdml, GdmlOptions};
use hytrace_tests::gdml::{gdml_dir, synthetic_pmt_array};
use hytrace_trace::scene::gdml_to_foundry;

/// Best of `runs` timings of reading and building, with the Foundry's sizes.
fn measure(name: &str, path: &Path, runs: usize) {
    let bytes = std::fs::metadata(path).unwrap().len();
    let (mut best_read, mut best_build) = (f64::INFINITY, f64::INFINITY);
    let mut last = None;
    for _ in 0..runs {
        let t0 = Instant::now();
        let g = read_gdml(path, &GdmlOptions::default()).unwrap();
        let t1 = Instant::now();
        let f = gdml_to_foundry(&g).unwrap();
        let t2 = Instant::now();
        best_read = best_read.min((t1 - t0).as_secs_f64());
        best_build = best_build.min((t2 - t1).as_secs_f64());
        last = Some(f);
    }
    let f = last.unwrap();
    let gpu: usize = f.gpu_array_bytes().iter().map(|b| b.len()).sum();
    let cpu = f.cpu_only_bytes();
    println!(
        "{name:<28} file {:>6.2} MB  instances {:>6}  solids {:>4}  read {:>7.3} s  build {:>7.3} s  \
         total {:>7.3} s  Foundry {:>6.2} MB (GPU {:.2} MB + CPU-only {:.2} MB)",
        bytes as f64 / 1e6,
        f.inst.len(),
        f.solid.len(),
        best_read,
        best_build,
        best_read + best_build,
        (gpu + cpu) as f64 / 1e6,
        gpu as f64 / 1e6,
        cpu as f64 / 1e6,
    );
}

fn main() {
    let scratch = tempfile::tempdir().unwrap();
    let out = std::env::var_os("HYTRACE_BENCH_OUT").map(std::path::PathBuf::from);
    let dir = out.as_deref().unwrap_or(scratch.path());
    std::fs::create_dir_all(dir).unwrap();
    let pmts = dir.join("pmt50k.gdml");
    std::fs::write(&pmts, synthetic_pmt_array(50_000, false)).unwrap();
    let nested = dir.join("pmt50k_nested.gdml");
    std::fs::write(&nested, synthetic_pmt_array(50_000, true)).unwrap();
    println!(
        "threads: {} (import is single-threaded)",
        rayon::current_num_threads()
    );
    measure("50 000 PMTs", &pmts, 5);
    measure("50 000 PMTs + inner volume", &nested, 5);
    measure(
        "protodune_v7 (2864 volumes)",
        &gdml_dir().join("dune/protodune_v7_refactored_nowires.gdml"),
        5,
    );
}
