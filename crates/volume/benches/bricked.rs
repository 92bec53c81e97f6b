//! Conversion throughput of the bricked grid: source voxels per second for each texel format,
//! on all threads, for a dense fog sphere and a grid of random values.
//!
//! `cargo bench -p hytrace-volume --bench bricked`

use std::time::Instant;

use hytrace_volume::{fog_sphere, BrickedGrid, DenseGrid, TexelFormat};

/// Seconds per conversion, the best of three.
fn seconds(g: &DenseGrid, format: TexelFormat) -> (f64, BrickedGrid) {
    let mut best = f64::INFINITY;
    let mut out = None;
    for _ in 0..3 {
        let start = Instant::now();
        let b = BrickedGrid::convert(g, format).expect("the bench grids convert");
        best = best.min(start.elapsed().as_secs_f64());
        out = Some(b);
    }
    (best, out.expect("three runs"))
}

fn main() {
    let sphere = fog_sphere(96.0, 24.0).expect("valid sphere");
    let mut noise = DenseGrid::new([-64; 3], [128; 3], 0.0).expect("valid grid");
    let mut state = 1u64;
    for v in noise.values.iter_mut() {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        *v = (state >> 40) as f32 / (1u32 << 24) as f32;
    }
    println!(
        "threads {}; rates in source voxels (dense box) per second",
        rayon::current_num_threads()
    );
    for (name, g) in [("fog sphere 193^3", &sphere), ("noise 128^3", &noise)] {
        let voxels = g.values.len() as f64;
        for format in TexelFormat::ALL {
            let (s, b) = seconds(g, format);
            println!(
                "{name:18} {format:8} {:8.1} ms  {:7.1} Mvoxel/s  bricks {:6}  slots {:6}  \
                 error {:.3e} (analytic {:.3e})  {:.1} MiB",
                s * 1e3,
                voxels / s / 1e6,
                b.bricks().len(),
                b.atlas_slots(),
                b.error_bound(),
                b.analytic_error_bound(),
                b.memory_bytes().total() as f64 / (1 << 20) as f64
            );
        }
    }
}
