//! CSG intersection throughput: rays per second on all threads (2 on the project's
//! machines) per Geant4 solid kind and for boolean trees of height 1-6, in f32 and f64,
//! next to Geant4 answering the same queries through geant4-pybind.
//!
//! `cargo bench -p hytrace-tests --bench csg` (needs the oracle environment: run
//! `scripts/test.sh` once, or set HYTRACE_PYTHON to a Python with numpy and geant4_pybind).

use std::time::Instant;

use hytrace_csg::{box3, sphere, PrimTree, Ray, Real, Shape};
use hytrace_foundry::TypeCode;
use hytrace_tests::geant4::{prepare, run_oracle, OracleData};
use hytrace_tests::oracle_python;
use rayon::prelude::*;

/// Rays per second of `trees` answering `rays` (tree index, ray), repeated for >= 0.3 s.
fn rate<T: Real, P: Sync + Fn(usize, &Ray<T>) -> bool>(
    first_hit: P,
    rays: &[(usize, [f64; 8])],
) -> f64 {
    let prepared: Vec<(usize, Ray<T>)> = rays
        .iter()
        .map(|(i, r)| (*i, Ray::from_f64([r[0], r[1], r[2]], [r[4], r[5], r[6]])))
        .collect();
    let mut done = 0usize;
    let start = Instant::now();
    while start.elapsed().as_secs_f64() < 0.3 {
        let hits: usize = prepared
            .par_iter()
            .map(|(i, ray)| first_hit(*i, ray) as usize)
            .sum();
        std::hint::black_box(hits);
        done += prepared.len();
    }
    done as f64 / start.elapsed().as_secs_f64()
}

/// A complete tree of `height` with operators cycling union, intersection, difference by
/// level over spheres and boxes near the origin (so no level collapses into a list).
fn tree_of_height(height: u32, seed: &mut u64) -> Shape {
    let mut next = || {
        *seed ^= *seed << 13;
        *seed ^= *seed >> 7;
        *seed ^= *seed << 17;
        (*seed >> 11) as f64 / (1u64 << 53) as f64
    };
    fn build(level: u32, height: u32, next: &mut dyn FnMut() -> f64) -> Shape {
        if level == height {
            let (x, y, z) = (
                20.0 * next() - 10.0,
                20.0 * next() - 10.0,
                20.0 * next() - 10.0,
            );
            let leaf = if next() < 0.5 {
                sphere(60.0 + 20.0 * next()).unwrap()
            } else {
                box3(100.0, 90.0 + 20.0 * next(), 110.0).unwrap()
            };
            return leaf.translate(x, y, z);
        }
        let a = build(level + 1, height, next);
        let b = build(level + 1, height, next);
        match [
            TypeCode::Union,
            TypeCode::Intersection,
            TypeCode::Difference,
        ][(level % 3) as usize]
        {
            TypeCode::Union => a + b,
            TypeCode::Intersection => a * b,
            _ => a - b.scale(0.5, 0.5, 0.5),
        }
    }
    build(0, height, &mut next)
}

fn main() {
    let Some(python) = oracle_python(&["numpy", "geant4_pybind"]) else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let data: OracleData = run_oracle(
        &python,
        dir.path(),
        &[
            "--seed",
            "5",
            "--solids-per-kind",
            "20",
            "--rays-per-solid",
            "2000",
            "--bench",
        ],
    );
    let trees32 = prepare::<f32>(&data.solids);
    let trees64 = prepare::<f64>(&data.solids);
    println!(
        "threads: {}; Geant4 binding overhead per call: {:.3} us",
        rayon::current_num_threads(),
        data.timing["overhead_per_call_s"]
            .as_f64()
            .unwrap_or(f64::NAN)
            * 1e6
    );
    println!("| solid kind | rays | hytrace f32 (rays/s) | hytrace f64 (rays/s) | Geant4 via geant4-pybind, 1 thread (rays/s) |");
    println!("|---|---:|---:|---:|---:|");
    let mut kinds: Vec<&String> = data.kinds.iter().collect();
    kinds.sort();
    kinds.dedup();
    for kind in kinds {
        let rays: Vec<(usize, [f64; 8])> = data
            .rays
            .iter()
            .zip(&data.ray_solid)
            .filter(|(_, s)| &data.kinds[**s as usize] == kind)
            .map(|(r, s)| (*s as usize, *r))
            .collect();
        let g4 = &data.timing["per_kind"][kind.as_str()];
        let g4_rate =
            g4["queries"].as_f64().unwrap_or(f64::NAN) / g4["seconds"].as_f64().unwrap_or(f64::NAN);
        println!(
            "| {kind} | {} | {:.3e} | {:.3e} | {:.3e} |",
            rays.len(),
            rate(
                |i, r: &Ray<f32>| trees32[i].first_crossing(r, 0.0).is_hit(),
                &rays
            ),
            rate(
                |i, r: &Ray<f64>| trees64[i].first_crossing(r, 0.0).is_hit(),
                &rays
            ),
            g4_rate
        );
    }
    println!();
    println!("| tree height | nodes | hytrace f32 (rays/s) | hytrace f64 (rays/s) |");
    println!("|---:|---:|---:|---:|");
    let mut seed = 0x1234_5678_9abc_def1u64;
    for height in 1..=6 {
        let shapes: Vec<Shape> = (0..8).map(|_| tree_of_height(height, &mut seed)).collect();
        let t32: Vec<PrimTree<f32>> = shapes
            .iter()
            .map(|s| PrimTree::from_shape(s).unwrap())
            .collect();
        let t64: Vec<PrimTree<f64>> = shapes
            .iter()
            .map(|s| PrimTree::from_shape(s).unwrap())
            .collect();
        let nodes = (1u32 << (t32[0].height() + 1)) - 1;
        let mut rays = Vec::new();
        let mut s = 0x9e37_79b9u64;
        for i in 0..20000 {
            let mut u = || {
                s ^= s << 13;
                s ^= s >> 7;
                s ^= s << 17;
                (s >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
            };
            let o = [300.0 * u(), 300.0 * u(), 300.0 * u()];
            let target = [50.0 * u(), 50.0 * u(), 50.0 * u()];
            let d = [target[0] - o[0], target[1] - o[1], target[2] - o[2]];
            let l = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            rays.push((
                i % shapes.len(),
                [
                    o[0],
                    o[1],
                    o[2],
                    0.0,
                    d[0] / l,
                    d[1] / l,
                    d[2] / l,
                    f64::INFINITY,
                ],
            ));
        }
        println!(
            "| {height} | {nodes} | {:.3e} | {:.3e} |",
            rate(
                |i, r: &Ray<f32>| t32[i].first_crossing(r, 0.0).is_hit(),
                &rays
            ),
            rate(
                |i, r: &Ray<f64>| t64[i].first_crossing(r, 0.0).is_hit(),
                &rays
            )
        );
    }
}
