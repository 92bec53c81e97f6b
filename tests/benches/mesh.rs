//! Triangle-mesh benchmark (issue 6): a 1M-triangle heightfield traced on the CPU by
//! hytrace and by Embree 4 (the `embreex` wheel), on the same rays.
//!
//! `cargo bench -p hytrace-tests --bench mesh` (needs the oracle environment of
//! `scripts/test.sh`: `HYTRACE_PYTHON=$PWD/.venv/bin/python` with numpy and embreex; without it
//! the Embree rows are skipped with a note). `HYTRACE_BENCH_GRID=N` sets the grid side
//! (default 708: 2 x 708^2 = 1 002 528 triangles), `HYTRACE_BENCH_RAYS=N` the rays per set
//! (default 1 000 000).
//!
//! The heightfield is written as an OBJ to a temporary directory and loaded through
//! [`load_scene`], so the scene path users get is measured. Ray sets: coherent (a pinhole
//! camera's primary rays over the field, in 8x8 pixel tiles) and incoherent (random origins
//! above the field, uniform directions over the downward hemisphere). hytrace traces each
//! set with rayon over all threads through [`CpuScene::trace`] (f32), and through the bare
//! [`MeshPrim::first_crossing`] of a mesh prim built directly from the triangles. Embree
//! gets the same float32 mesh and rays from `tests/oracle/mesh_bench.py`, which times only
//! the intersection calls; the hit/miss and distance agreement of the two is printed.

#[path = "common/batched.rs"]
mod batched;
#[path = "common/heightfield.rs"]
mod heightfield;
#[path = "common/pairs.rs"]
mod pairs;

use std::path::Path;
use std::process::Command;
use std::time::Instant;

use batched::trace_batches;
use heightfield::{coherent, heightfield, incoherent, write_obj};
use hytrace_csg::{CrossingScratch, MeshPrim, MeshQuery};
use hytrace_foundry::gdml::GdmlOptions;
use hytrace_foundry::layout::Scalar;
use hytrace_foundry::npy::{read_array, write_array};
use hytrace_tests::oracle_python;
use hytrace_trace::cpu::{CpuScene, Hit, BATCH};
use hytrace_trace::scene::load_scene;
#[cfg(feature = "embree")]
use pairs::{paired_speed_ratio, PAIRS};
use pairs::{simd_line, simd_over_portable};
use rayon::prelude::*;

/// Timed runs per measurement (the best is reported).
const RUNS: usize = 3;

/// A hit's distance, `inf` for a miss.
/// The same rays in f64, as hytrace's CPU tracer takes them (exact conversions).
fn exactly_f64(rays: &[hytrace_csg::Ray<f32>]) -> Vec<hytrace_csg::Ray<f64>> {
    rays.iter()
        .map(|r| hytrace_csg::Ray::from_f64(r.origin.to_f64(), r.direction.to_f64()))
        .collect()
}

fn distance(hit: &Option<Hit<f32>>) -> f32 {
    hit.map_or(f32::INFINITY, |h| h.t)
}

fn env_usize(name: &str, default: usize) -> usize {
    std::env::var(name)
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(default)
}

/// Best time of `RUNS` calls of `f`, in seconds, and the last result.
fn best<T>(mut f: impl FnMut() -> T) -> (f64, T) {
    let mut best = f64::INFINITY;
    let mut last = None;
    for _ in 0..RUNS {
        let t = Instant::now();
        let r = f();
        best = best.min(t.elapsed().as_secs_f64());
        last = Some(r);
    }
    (best, last.unwrap())
}

fn save_f32(path: &Path, rows: &[[f32; 3]]) {
    write_array(
        path,
        Scalar::F32,
        &[rows.len() as u64, 3],
        bytemuck::cast_slice(rows),
    )
    .unwrap();
}

/// Hits agreeing with Embree's: both miss, or both hit within 1e-4 relative distance.
fn agreement(ours: &[f32], embree: &[f32]) -> (f64, usize) {
    let same = ours
        .iter()
        .zip(embree)
        .filter(|(&a, &b)| match (a.is_finite(), b.is_finite()) {
            (true, true) => (a - b).abs() <= 1e-4 * a.abs().max(b.abs()).max(1.0),
            (false, false) => true,
            _ => false,
        })
        .count();
    (same as f64 / ours.len() as f64, ours.len() - same)
}

fn mrays(count: usize, seconds: f64) -> f64 {
    count as f64 / seconds / 1e6
}

fn main() {
    let n = env_usize("HYTRACE_BENCH_GRID", 708);
    let count = env_usize("HYTRACE_BENCH_RAYS", 1_000_000);
    let dir = tempfile::tempdir().unwrap();
    let (vertices, faces) = heightfield(n);
    let zmax = vertices.iter().fold(f64::NEG_INFINITY, |a, v| a.max(v[2]));
    let obj = dir.path().join("heightfield.obj");
    write_obj(&obj, &vertices, &faces);
    println!(
        "machine: {} threads (rayon), build profile bench; heightfield {n} x {n} quads, {} triangles, {} rays per set",
        rayon::current_num_threads(),
        faces.len(),
        count
    );
    println!("{}", simd_line());

    let t0 = Instant::now();
    let foundry = load_scene(Some(&obj), &GdmlOptions::default()).unwrap();
    let load_s = t0.elapsed().as_secs_f64();
    let t0 = Instant::now();
    let scene = CpuScene::<f32>::new(&foundry).unwrap();
    let build_s = t0.elapsed().as_secs_f64();
    let triangles: Vec<[[f64; 3]; 3]> = faces
        .iter()
        .map(|f| f.map(|i| vertices[i as usize]))
        .collect();
    let t0 = Instant::now();
    let prim = MeshPrim::<f32>::new(&triangles).unwrap();
    let prim_build_s = t0.elapsed().as_secs_f64();
    println!(
        "OBJ load (load_scene): {load_s:.2} s; CpuScene::<f32>::new: {build_s:.2} s; MeshPrim::<f32>::new: {prim_build_s:.2} s"
    );

    let sets = [coherent(n, zmax, count), incoherent(n, zmax, count)];
    let mut rows = Vec::new();
    let mut ours_t = Vec::new();
    let mut scene_rates = Vec::new();
    let mut batch_rates = Vec::new();
    let mut many_rates = Vec::new();
    let mut prim_rates = Vec::new();
    for set in &sets {
        let rays = set.rays();
        let rays64 = exactly_f64(&rays);
        let (scene_s, hits) = best(|| {
            rays64
                .par_iter()
                .map(|r| distance(&scene.trace(r, 0.0, f32::INFINITY)))
                .collect::<Vec<f32>>()
        });
        let (batch_s, batch_hits) = best(|| trace_batches(&scene, &rays64, distance));
        let (prim_s, prim_hits) = best(|| {
            rays.par_iter()
                .map(|r| prim.first_crossing(r, 0.0).t)
                .collect::<Vec<f32>>()
        });
        let (many_s, many_hits) = best(|| {
            rays.par_chunks(BATCH)
                .map_init(
                    || (CrossingScratch::default(), Vec::new()),
                    |(scratch, out), chunk| {
                        let queries: Vec<MeshQuery<f32>> = chunk
                            .iter()
                            .map(|r| MeshQuery {
                                mesh: &prim,
                                ray: *r,
                                tmin: 0.0,
                            })
                            .collect();
                        MeshPrim::first_crossings(&queries, scratch, out);
                        out.iter().map(|s| s.t).collect::<Vec<f32>>()
                    },
                )
                .flatten_iter()
                .collect::<Vec<f32>>()
        });
        assert!(
            many_hits
                .iter()
                .zip(&prim_hits)
                .all(|(a, b)| a.to_bits() == b.to_bits()),
            "first_crossings and first_crossing differ"
        );
        many_rates.push(mrays(rays.len(), many_s));
        let hit_fraction = hits.iter().filter(|t| t.is_finite()).count() as f64 / rays.len() as f64;
        let (same, _) = agreement(&hits, &prim_hits);
        println!(
            "{}: {} rays, {:.1}% hit; CpuScene::trace and MeshPrim::first_crossing agree on {:.4}%",
            set.name,
            rays.len(),
            100.0 * hit_fraction,
            100.0 * same
        );
        let identical = batch_hits
            .iter()
            .zip(&hits)
            .filter(|(a, b)| a.to_bits() == b.to_bits())
            .count();
        println!(
            "{}: CpuScene::trace_batch and CpuScene::trace give the same bits on {identical} of {} rays",
            set.name,
            rays.len()
        );
        scene_rates.push(mrays(rays.len(), scene_s));
        batch_rates.push(mrays(rays.len(), batch_s));
        prim_rates.push(mrays(rays.len(), prim_s));
        ours_t.push(hits);
        if let Some(line) = simd_over_portable(&scene, &rays64) {
            println!("{}: {line}", set.name);
        }
    }
    rows.push(format!(
        "| hytrace CpuScene::<f32>::trace ({} threads) | {build_s:.2} | {:.2} | {:.2} |",
        rayon::current_num_threads(),
        scene_rates[0],
        scene_rates[1]
    ));
    rows.push(format!(
        "| hytrace CpuScene::<f32>::trace_batch, as `hytrace scan` ({} threads) | {build_s:.2} | {:.2} | {:.2} |",
        rayon::current_num_threads(),
        batch_rates[0],
        batch_rates[1]
    ));
    rows.push(format!(
        "| hytrace MeshPrim::<f32>::first_crossing ({} threads) | {prim_build_s:.2} | {:.2} | {:.2} |",
        rayon::current_num_threads(),
        prim_rates[0],
        prim_rates[1]
    ));
    rows.push(format!(
        "| hytrace MeshPrim::<f32>::first_crossings, interleaved ({} threads) | {prim_build_s:.2} | {:.2} | {:.2} |",
        rayon::current_num_threads(),
        many_rates[0],
        many_rates[1]
    ));

    match oracle_python(&["numpy", "embreex"]) {
        None => println!("(no oracle Python with numpy and embreex: Embree rows skipped)"),
        Some(python) => {
            let d = dir.path();
            save_f32(
                &d.join("vertices.npy"),
                &vertices
                    .iter()
                    .map(|v| v.map(|c| c as f32))
                    .collect::<Vec<_>>(),
            );
            write_array(
                &d.join("faces.npy"),
                Scalar::I32,
                &[faces.len() as u64, 3],
                bytemuck::cast_slice(&faces),
            )
            .unwrap();
            for set in &sets {
                save_f32(&d.join(format!("{}_origins.npy", set.name)), &set.origins);
                save_f32(&d.join(format!("{}_dirs.npy", set.name)), &set.dirs);
            }
            let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("oracle/mesh_bench.py");
            let out = Command::new(&python)
                .arg(&script)
                .arg(d)
                .output()
                .expect("python runs");
            assert!(
                out.status.success(),
                "mesh_bench.py failed:\n{}",
                String::from_utf8_lossy(&out.stderr)
            );
            // One line per Embree configuration: `label|build_s|coherent_s|incoherent_s|tag`
            // where `tag` names the distance files it wrote.
            for line in String::from_utf8_lossy(&out.stdout).lines() {
                let fields: Vec<&str> = line.split('|').collect();
                if fields.len() != 5 {
                    println!("{line}");
                    continue;
                }
                let seconds: Vec<f64> = fields[1..4].iter().map(|s| s.parse().unwrap()).collect();
                let mut agree = Vec::new();
                for (set, ours) in sets.iter().zip(&ours_t) {
                    let a =
                        read_array(&d.join(format!("{}_{}_t.npy", fields[4], set.name))).unwrap();
                    let embree: Vec<f32> = bytemuck::pod_collect_to_vec(&a.bytes);
                    let (same, differ) = agreement(ours, &embree);
                    agree.push(format!(
                        "{} {:.4}% ({differ} differ)",
                        set.name,
                        100.0 * same
                    ));
                }
                rows.push(format!(
                    "| {} | {:.2} | {:.2} | {:.2} |",
                    fields[0],
                    seconds[0],
                    mrays(sets[0].origins.len(), seconds[1]),
                    mrays(sets[1].origins.len(), seconds[2])
                ));
                println!(
                    "agreement of hytrace with {}: {}",
                    fields[0],
                    agree.join(", ")
                );
            }
        }
    }
    #[cfg(feature = "embree")]
    rows.push(embree_backend_row(&foundry, &scene, &sets, &ours_t));

    println!("\n| backend | build s | coherent Mrays/s | incoherent Mrays/s |");
    println!("|---|---:|---:|---:|");
    for row in rows {
        println!("{row}");
    }
}

/// The row of Embree 3 through hytrace's own backend (`--features embree`): build (Embree's
/// structures over the prepared scene) and both ray sets, checked against hytrace's hits.
#[cfg(feature = "embree")]
fn embree_backend_row(
    foundry: &hytrace_foundry::Foundry,
    scene: &CpuScene<f32>,
    sets: &[heightfield::RaySet],
    ours: &[Vec<f32>],
) -> String {
    let t0 = Instant::now();
    let embree = hytrace_trace::embree::EmbreeScene::new(foundry, scene).unwrap();
    let build_s = t0.elapsed().as_secs_f64();
    // Builds alternate too: Embree's (2 TBB threads here) against the CPU scene's, each
    // from the same Foundry.
    let [median, low, high] = paired_speed_ratio(
        || drop(CpuScene::<f32>::new(foundry).unwrap()),
        || drop(hytrace_trace::embree::EmbreeScene::new(foundry, scene).unwrap()),
    );
    println!(
        "build: CpuScene::<f32>::new over Embree 3's (hytrace backend), {PAIRS} alternating pairs: median {median:.2}x, range {low:.2}-{high:.2}x"
    );
    let mut rates = Vec::new();
    for (set, ours) in sets.iter().zip(ours) {
        let rays = set.rays();
        let (secs, hits) = best(|| {
            rays.par_iter()
                .map(|r| distance(&embree.trace(r, 0.0, f32::INFINITY).unwrap()))
                .collect::<Vec<f32>>()
        });
        let (same, differ) = agreement(ours, &hits);
        println!(
            "agreement of hytrace with Embree 3 (hytrace backend), {}: {:.4}% ({differ} differ)",
            set.name,
            100.0 * same
        );
        rates.push(mrays(rays.len(), secs));
    }
    for set in sets {
        let rays = set.rays();
        let rays64 = exactly_f64(&rays);
        let [median, low, high] = paired_speed_ratio(
            || {
                trace_batches(scene, &rays64, distance);
            },
            || {
                rays.par_iter().for_each(|r| {
                    embree.trace(r, 0.0, f32::INFINITY).unwrap();
                })
            },
        );
        println!(
            "{}: CpuScene::trace_batch over Embree 3 (hytrace backend), {PAIRS} alternating pairs: median {median:.2}x, range {low:.2}-{high:.2}x",
            set.name
        );
    }
    format!(
        "| Embree 3 through hytrace's backend ({} threads) | {build_s:.2} | {:.2} | {:.2} |",
        rayon::current_num_threads(),
        rates[0],
        rates[1]
    )
}
