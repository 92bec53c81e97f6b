//! The mixed scene benchmark: CSG solids, a triangle mesh and a fog volume in one world,
//! traced by hytrace's CPU backend and by its Embree backend on the same rays.
//!
//! `cargo bench -p hytrace-tests --bench mixed --features embree` (without the feature the
//! Embree rows are left out: closest hit, any hit, and transmittance with Embree finding
//! the surfaces and brick clusters). `HYTRACE_BENCH_RAYS=N` sets the rays per set (default 10^6).
//!
//! The scene: the open tank, rock mesh (1280 triangles) and fog box of
//! `scenes/mixed.toml`, with a 20 x 20 grid of PMT-like sensors above the tank (400 CSG
//! instances). Rays: "coherent", parallel rays from just below the tank's open top straight
//! down through the fog and past the rock, on a square grid in 8x8 tiles; "incoherent",
//! origins uniform in the tank with uniform random directions.

#[path = "common/batched.rs"]
mod batched;
#[path = "common/mixed_scene.rs"]
mod mixed_scene;
#[path = "common/pairs.rs"]
mod pairs;

use std::time::Instant;

use batched::trace_batches;
use hytrace_csg::Ray;
use hytrace_trace::cpu::media::SceneMedia;
use hytrace_trace::cpu::CpuScene;
use hytrace_trace::scan::RayRow;
use hytrace_trace::scene::scene_from_toml;
use hytrace_volume::{Estimator, TransmittanceParams};
use mixed_scene::{coherent_rays, incoherent_rays, scene_text, scenes_dir};
#[cfg(feature = "embree")]
use pairs::{paired_speed_ratio, PAIRS};
use pairs::{simd_line, simd_over_portable};
use rayon::prelude::*;

#[cfg(feature = "embree")]
fn ray32(r: &RayRow) -> Ray<f32> {
    Ray::from_f64(r.origin, r.direction)
}

/// The ray as hytrace's CPU tracer takes it (f64, as `hytrace scan` reads it).
fn ray64(r: &RayRow) -> Ray<f64> {
    Ray::from_f64(r.origin, r.direction)
}

/// Seconds of the best of three runs of `f`, and its last result.
fn best<T>(mut f: impl FnMut() -> T) -> (f64, T) {
    let mut out = None;
    let mut best = f64::INFINITY;
    for _ in 0..3 {
        let t = Instant::now();
        out = Some(f());
        best = best.min(t.elapsed().as_secs_f64());
    }
    (best, out.unwrap())
}

fn main() {
    let n: usize = std::env::var("HYTRACE_BENCH_RAYS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(1_000_000);
    let t = Instant::now();
    let f = scene_from_toml(&scene_text(), "mixed bench scene", &scenes_dir()).unwrap();
    let load_s = t.elapsed().as_secs_f64();
    let (build_s, cpu) = best(|| CpuScene::<f32>::new(&f).unwrap());
    println!(
        "mixed scene: {} instances, {} triangles, {} bricks; load {load_s:.3} s; {} threads; {n} rays per set",
        f.inst.len(),
        f.tri.len(),
        f.brick.len(),
        rayon::current_num_threads()
    );
    println!("{}", simd_line());
    println!("| rays | query | backend | build s | Mrays/s | hits |");
    println!("|---|---|---|---|---|---|");
    #[cfg(feature = "embree")]
    let (embree_build_s, embree) =
        best(|| hytrace_trace::embree::EmbreeScene::new(&f, &cpu).unwrap());
    for (name, rays) in [
        ("coherent", coherent_rays(n)),
        ("incoherent", incoherent_rays(n)),
    ] {
        let row = |query: &str, backend: &str, build: f64, secs: f64, hits: usize| {
            println!(
                "| {name} | {query} | {backend} | {build:.3} | {:.2} | {hits} |",
                rays.len() as f64 / secs / 1e6
            );
        };
        let (secs, cpu_hits) = best(|| {
            rays.par_iter()
                .map(|r| {
                    cpu.trace(&ray64(r), 0.0, f32::INFINITY)
                        .map(|h| (h.t, h.instance))
                })
                .collect::<Vec<_>>()
        });
        row(
            "closest hit",
            "hytrace cpu",
            build_s,
            secs,
            cpu_hits.iter().flatten().count(),
        );
        #[cfg(feature = "embree")]
        let rays32: Vec<Ray<f32>> = rays.iter().map(ray32).collect();
        let rays64: Vec<Ray<f64>> = rays.iter().map(ray64).collect();
        let (secs, batch_hits) =
            best(|| trace_batches(&cpu, &rays64, |h| h.map(|h| (h.t, h.instance))));
        assert!(batch_hits == cpu_hits, "trace_batch and trace differ");
        row(
            "closest hit, batches (as `hytrace scan`)",
            "hytrace cpu",
            build_s,
            secs,
            batch_hits.iter().flatten().count(),
        );
        let (secs, occluded) = best(|| {
            rays.par_iter()
                .filter(|r| cpu.occluded(&ray64(r), 0.0, f32::INFINITY))
                .count()
        });
        row("any hit", "hytrace cpu", build_s, secs, occluded);
        if let Some(line) = simd_over_portable(&cpu, &rays64) {
            println!("|  | {line} | | | | |");
        }
        #[cfg(feature = "embree")]
        {
            let (secs, embree_hits) = best(|| {
                rays.par_iter()
                    .map(|r| {
                        embree
                            .trace(&ray32(r), 0.0, f32::INFINITY)
                            .unwrap()
                            .map(|h| (h.t, h.instance))
                    })
                    .collect::<Vec<_>>()
            });
            row(
                "closest hit",
                "Embree 3 (hytrace backend)",
                embree_build_s,
                secs,
                embree_hits.iter().flatten().count(),
            );
            let agree = cpu_hits
                .iter()
                .zip(&embree_hits)
                .filter(|(a, b)| match (a, b) {
                    (Some(a), Some(b)) => (a.0 - b.0).abs() <= 1e-4f32.max(4e-7 * a.0.abs()),
                    (None, None) => true,
                    _ => false,
                })
                .count();
            println!(
                "|  | agreement cpu vs Embree | {:.4}% | | | |",
                100.0 * agree as f64 / rays.len() as f64
            );
            let (secs, embree_occluded) = best(|| {
                rays.par_iter()
                    .filter(|r| embree.occluded(&ray32(r), 0.0, f32::INFINITY).unwrap())
                    .count()
            });
            row(
                "any hit",
                "Embree 3 (hytrace backend)",
                embree_build_s,
                secs,
                embree_occluded,
            );
            // The rows above come from different moments; these pairs are side by side.
            let [median, low, high] = paired_speed_ratio(
                || {
                    trace_batches(&cpu, &rays64, |h| h.map(|h| h.t));
                },
                || {
                    rays32.par_iter().for_each(|r| {
                        embree.trace(r, 0.0, f32::INFINITY).unwrap();
                    })
                },
            );
            println!(
                "|  | closest hit, batches over Embree 3: {PAIRS} alternating pairs, median {median:.2}x, range {low:.2}-{high:.2}x | | | | |"
            );
            let [median, low, high] = paired_speed_ratio(
                || {
                    rays64.par_iter().for_each(|r| {
                        cpu.occluded(r, 0.0, f32::INFINITY);
                    })
                },
                || {
                    rays32.par_iter().for_each(|r| {
                        embree.occluded(r, 0.0, f32::INFINITY).unwrap();
                    })
                },
            );
            println!(
                "|  | any hit over Embree 3: {PAIRS} alternating pairs, median {median:.2}x, range {low:.2}-{high:.2}x | | | | |"
            );
        }
        for (label, estimator) in [
            ("transmittance exact", Estimator::Exact),
            ("transmittance ratio 1 spp", Estimator::Ratio),
        ] {
            let params = TransmittanceParams::new(estimator);
            let (open_s, media) = best(|| SceneMedia::new(&cpu, &f, &params).unwrap());
            let (secs, out) = best(|| media.trace_all(&rays).unwrap());
            let lookups: u64 = out.iter().map(|r| r.lookups).sum();
            row(
                label,
                "hytrace cpu",
                open_s,
                secs,
                out.iter().filter(|r| r.hit.is_some()).count(),
            );
            println!(
                "|  | {label}: mean T {:.4}, {:.1} lookups/ray | | | | |",
                out.iter().map(|r| r.transmittance).sum::<f64>() / out.len() as f64,
                lookups as f64 / out.len() as f64
            );
            // Embree finding the surfaces and the brick clusters, the same estimators.
            #[cfg(feature = "embree")]
            {
                let (secs, through_embree) = best(|| {
                    rays.par_iter()
                        .enumerate()
                        .map(|(i, r)| {
                            embree
                                .trace_transmittance(
                                    &media,
                                    r.origin,
                                    r.direction,
                                    r.tmin,
                                    r.tmax,
                                    i as u32,
                                )
                                .unwrap()
                        })
                        .collect::<Vec<_>>()
                });
                row(
                    label,
                    "Embree 3 (hytrace backend)",
                    embree_build_s,
                    secs,
                    through_embree.iter().filter(|r| r.hit.is_some()).count(),
                );
                // Embree's own triangle test puts the rock's hits a few ulps off ours, so
                // the media end there a few ulps apart too.
                let pairs = out.iter().zip(&through_embree);
                let same = pairs
                    .clone()
                    .filter(|(a, b)| a.transmittance == b.transmittance)
                    .count();
                let largest = pairs.fold(0.0f64, |m, (a, b)| {
                    m.max((a.transmittance - b.transmittance).abs())
                });
                println!(
                    "|  | {label}: cpu vs Embree: {:.4}% identical, largest difference {largest:.1e} | | | | |",
                    100.0 * same as f64 / out.len() as f64
                );
            }
        }
    }
}
