//! Volume benchmarks: bricked-grid conversion throughput per texel format against the
//! machine's memcpy bandwidth and `nanovdb_convert`, memory per representation, lookup rate
//! per representation and filter, and transmittance accuracy against time per estimator.
//!
//! `cargo bench -p hytrace-tests --bench volume` (needs /usr/bin/python3 with pyopenvdb and
//! nanovdb_convert, as scripts/test.sh installs). `HYTRACE_BENCH_SIDE=N` sets the fog
//! sphere's box side (default 512).

use std::process::Command;
use std::time::Instant;

use hytrace_tests::vdb::{run_oracle, vdb_python};
use hytrace_trace::scan::{rays_from_rows, RayRow};
use hytrace_trace::volume::{
    open, sample_points, transmittances, EstimatorArg, Represented, Space, TransmittanceArgs,
};
use hytrace_volume::{BrickedGrid, Filter, Rng, TexelFormat, Volume, VoxelGrid};

/// The next uniform number in [0, 1) of `state` (the crate's counter-based generator).
fn rng(state: &mut Rng) -> f64 {
    state.next_f64()
}

/// Best time of `runs` calls of `f`, in seconds, and the last result.
fn best<T>(runs: usize, mut f: impl FnMut() -> T) -> (f64, T) {
    let mut best = f64::INFINITY;
    let mut last = None;
    for _ in 0..runs {
        let t = Instant::now();
        let r = f();
        best = best.min(t.elapsed().as_secs_f64());
        last = Some(r);
    }
    (best, last.unwrap())
}

/// memcpy bandwidth (read + write bytes per second) on a 1 GiB buffer.
fn memcpy_bandwidth() -> f64 {
    let n = 1usize << 30;
    let src = vec![1u8; n];
    let mut dst = vec![0u8; n];
    let (t, _) = best(3, || {
        std::hint::black_box(&mut dst).copy_from_slice(std::hint::black_box(&src));
        std::hint::black_box(dst[n / 2])
    });
    2.0 * n as f64 / t
}

fn main() {
    let side: usize = std::env::var("HYTRACE_BENCH_SIDE")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(512);
    let python = vdb_python().expect("the volume benchmark needs pyopenvdb and nanovdb_convert");
    let dir = tempfile::tempdir().unwrap();
    let vdb = dir.path().join("sphere.vdb");
    let nvdb = dir.path().join("sphere.nvdb");
    run_oracle(
        &python,
        &["fog-sphere", vdb.to_str().unwrap(), &side.to_string()],
    );
    let (tool_s, _) = best(3, || {
        let out = Command::new("nanovdb_convert")
            .args(["-f", vdb.to_str().unwrap(), nvdb.to_str().unwrap()])
            .output()
            .unwrap();
        assert!(out.status.success());
    });
    println!(
        "machine: {} threads (rayon), build profile bench; fog sphere in a {side}^3 box",
        rayon::current_num_threads()
    );
    let (summary, grid) = open(nvdb.to_str().unwrap(), None).unwrap();
    let leaves = grid.block_origins().unwrap().len();
    // Voxel data converted: every 8^3 block the source reports, 4 bytes per voxel.
    let voxel_bytes = leaves as f64 * 512.0 * 4.0;
    let memcpy = memcpy_bandwidth();
    println!(
        "source: {} active voxels, {} 8^3 blocks ({:.1} MB of f32 voxel data), NanoVDB buffer {:.1} MB",
        summary.active_voxels,
        leaves,
        voxel_bytes / 1e6,
        summary.source_bytes as f64 / 1e6
    );
    println!("memcpy: {:.2} GB/s (read + write)", memcpy / 1e9);
    println!(
        "nanovdb_convert .vdb -> .nvdb: {tool_s:.3} s ({:.2} GB/s of voxel data)",
        voxel_bytes / tool_s / 1e9
    );
    println!(
        "\n| format | convert s | GB/s voxel data | vs memcpy | memory MB | max voxel error |"
    );
    println!("|---|---|---|---|---|---|");
    let mut bricked = Vec::new();
    for format in TexelFormat::ALL {
        let (t, b) = best(3, || BrickedGrid::convert(&grid, format).unwrap());
        println!(
            "| {format} | {t:.3} | {:.2} | {:.3} | {:.1} | {:.2e} |",
            voxel_bytes / t / 1e9,
            voxel_bytes / t / memcpy,
            b.memory_bytes().total() as f64 / 1e6,
            b.error_bound()
        );
        bricked.push((format, b));
    }
    println!(
        "| NanoVDB float (as read) | - | - | - | {:.1} | 0 |",
        summary.source_bytes as f64 / 1e6
    );

    // Lookups at random points of the sphere's box.
    let mut state = Rng::new(1, 0, 0);
    let points: Vec<[f64; 3]> = (0..2_000_000)
        .map(|_| std::array::from_fn(|_| rng(&mut state) * side as f64))
        .collect();
    println!(
        "\n| representation | nearest Msamples/s | trilinear Msamples/s | stochastic Msamples/s |"
    );
    println!("|---|---|---|---|");
    let rate = |g: &dyn VoxelGrid, filter: Filter| {
        let (t, _) = best(5, || sample_points(g, &points, Space::Index, filter, 1));
        points.len() as f64 / t / 1e6
    };
    let row = |name: &str, g: &dyn VoxelGrid| {
        println!(
            "| {name} | {:.1} | {:.1} | {:.1} |",
            rate(g, Filter::Nearest),
            rate(g, Filter::Trilinear),
            rate(g, Filter::Stochastic)
        );
    };
    row("NanoVDB float", &grid);
    for (format, b) in &bricked {
        row(format.name(), b);
    }

    transmittance_table(grid, side);
}

/// Accuracy against time of the transmittance estimators on chords of the sphere.
fn transmittance_table(grid: Volume, side: usize) {
    let mut state = Rng::new(5, 0, 0);
    let c = side as f64 / 2.0;
    let rows: Vec<[f64; 8]> = (0..20_000)
        .map(|_| {
            let d = loop {
                let v: [f64; 3] = std::array::from_fn(|_| rng(&mut state) * 2.0 - 1.0);
                let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
                if l > 0.1 && l < 1.0 {
                    break v.map(|x| x / l);
                }
            };
            let o: [f64; 3] =
                std::array::from_fn(|k| c + (rng(&mut state) - 0.5) * c - d[k] * c * 2.0);
            [o[0], o[1], o[2], 0.0, d[0], d[1], d[2], f64::INFINITY]
        })
        .collect();
    let rays: Vec<RayRow> = rays_from_rows(&rows, "bench rays").unwrap();
    let grid = Represented::Source(grid);
    // A density scale giving an optical depth of about 2 across the sphere.
    let scale = 2.0 / side as f64;
    let base = TransmittanceArgs {
        estimator: EstimatorArg::Exact,
        step: 1.0,
        spp: 1,
        seed: 3,
        density_scale: scale,
        filter: Filter::Trilinear,
        level: Some(0),
    };
    // Times exclude building the range mips (once per grid, reported apart).
    let timed = |args: &TransmittanceArgs| {
        // Best of three runs of the estimates alone.
        let mut best_run = (Vec::new(), 0.0, f64::INFINITY);
        for _ in 0..3 {
            let (est, mips_s, t) = transmittances(&grid, &rays, args).unwrap();
            if t < best_run.2 {
                best_run = (est, mips_s, t);
            }
        }
        best_run
    };
    let (exact, mips_s, exact_t) = timed(&base);
    println!(
        "\ntransmittance, {} rays through the sphere, optical depth up to 2; range mips built in {mips_s:.3} s",
        rays.len()
    );
    println!("\n| estimator | settings | RMS error | mean bias | lookups/ray | CPU us/ray |");
    println!("|---|---|---|---|---|---|");
    println!(
        "| exact | trilinear, per voxel cell | 0 (reference) | 0 | {:.0} | {:.2} |",
        exact.iter().map(|e| e.lookups).sum::<u64>() as f64 / rays.len() as f64,
        exact_t * 1e6 * rayon::current_num_threads() as f64 / rays.len() as f64
    );
    let mut cases: Vec<(&str, String, TransmittanceArgs)> = Vec::new();
    for step in [4.0, 1.0, 0.25] {
        cases.push((
            "march",
            format!("step {step} voxels"),
            TransmittanceArgs {
                estimator: EstimatorArg::March,
                step,
                ..base
            },
        ));
    }
    for (name, estimator) in [
        ("delta", EstimatorArg::Delta),
        ("ratio", EstimatorArg::Ratio),
        ("residual", EstimatorArg::Residual),
    ] {
        for (majorant, level) in [
            ("local 8^3", Some(0)),
            ("local 64^3", Some(3)),
            ("global", None),
        ] {
            for spp in [1, 16] {
                cases.push((
                    name,
                    format!("{majorant} majorant, {spp} spp"),
                    TransmittanceArgs {
                        estimator,
                        spp,
                        level,
                        ..base
                    },
                ));
            }
        }
    }
    for (label, settings, args) in cases {
        let (est, _, t) = timed(&args);
        let n = rays.len() as f64;
        let (mut sq, mut bias) = (0.0, 0.0);
        for (e, x) in est.iter().zip(&exact) {
            let d = e.transmittance - x.transmittance;
            sq += d * d;
            bias += d;
        }
        println!(
            "| {label} | {settings} | {:.2e} | {:.1e} | {:.1} | {:.2} |",
            (sq / n).sqrt(),
            bias / n,
            est.iter().map(|e| e.lookups).sum::<u64>() as f64 / n,
            t * 1e6 * rayon::current_num_threads() as f64 / n
        );
    }
}
