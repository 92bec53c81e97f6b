//! The f32 scan's fallback to f64, decided inside the trace (`CpuScene::trace_flagged`),
//! against the check it replaced, on every file of the shared public GDML corpus with the
//! rays of `gpu_gdml.rs` (sweeps and random rays, moved to start at their `tmin`): the old
//! check located every ray's origin again after the trace and asked whether the start lies
//! within the tolerance band of a surface (`CpuScene::starts_near_surface`, kept for the
//! rays the trace sends it). Every ray that check sent to f64 must be flagged, and the
//! scan's answers must be the old rule's (start near a surface, grazing incidence, torus
//! crossings off the f64 surface: the f64 answer; else the f32 one) on every ray but those
//! the trace alone flags, which may only move toward the f64 answer.

mod common;

use common::{f32_ray, rays_for};
use hytrace_csg::{Ray, Real};
use hytrace_foundry::gdml::GdmlOptions;
use hytrace_testkit::files::{shared_gdml_dir, shared_gdml_files};
use hytrace_trace::cpu::{CpuScene, STATUS_DROPPED_SPAN, STATUS_START_BAND, STATUS_START_NEAR};
use hytrace_trace::scan::{scan, Precision, RayRow, ScanResult};
use hytrace_trace::scene::load_scene;
use rayon::prelude::*;

/// `gpu_gdml.rs`'s rays per file: sweeps of this many rays a side ...
const SWEEP: usize = 40;
/// ... and this many random rays.
const RANDOM: usize = 3000;

/// The rays as they start at `tmin` (origin moved there, `tmin` 0), as a scan of a
/// hierarchical scene traces them.
fn started(rays: &[RayRow]) -> Vec<RayRow> {
    rays.iter()
        .map(|r| RayRow {
            origin: std::array::from_fn(|k| r.origin[k] + r.tmin * r.direction[k]),
            direction: r.direction,
            tmin: 0.0,
            tmax: r.tmax - r.tmin,
        })
        .collect()
}

/// Row `i` of a scan: `nx ny nz t` and the instance.
fn answer(s: &ScanResult, i: usize) -> ([u64; 4], i32) {
    (s.hits[i].map(f64::to_bits), s.ids[i][0])
}

/// What the check before the fold sent to f64: starts near a surface (the same f32 scene,
/// the origin located again), crossings at a cosine below 1/8, torus crossings whose point
/// lies off the f64 surface by more than an eighth of the f32 band.
fn old_rule(
    cpu: &CpuScene<f32>,
    exact: &CpuScene<f64>,
    r: &RayRow,
    f32_answer: &[f64; 4],
    instance: i32,
) -> (bool, bool) {
    let (_, tmin, _) = f32_ray(r);
    let near =
        cpu.starts_near_surface(&Ray::from_f64(r.origin, r.direction), tmin, &mut Vec::new());
    let t = f32_answer[3];
    if !t.is_finite() {
        return (near, near);
    }
    let cosine = (0..3)
        .map(|k| f32_answer[k] * r.direction[k])
        .sum::<f64>()
        .abs();
    let torus = usize::try_from(instance).is_ok_and(|i| cpu.has_torus(i as u32)) && {
        let x: [f64; 3] = std::array::from_fn(|k| r.origin[k] + t * r.direction[k]);
        let reach = r.origin.iter().map(|c| c * c).sum::<f64>().sqrt() + t;
        let allowed = f64::from(<f32 as Real>::SURFACE_TOLERANCE) * reach / 8.0;
        exact.surface_distance(instance as u32, x) > allowed
    };
    (near, near || cosine < 0.125 || torus)
}

#[test]
fn the_trace_flags_every_ray_the_old_fallback_check_redid() {
    let dir = shared_gdml_dir();
    let (mut rays_all, mut near_all, mut flagged_all, mut changed_all) = (0, 0, 0, 0);
    let mut problems = Vec::new();
    for path in shared_gdml_files() {
        let name = path.strip_prefix(&dir).unwrap().display().to_string();
        let f = load_scene(Some(&path), &GdmlOptions::default())
            .unwrap_or_else(|e| panic!("{name}: {e:#}"));
        let rays = started(&rays_for(&f, SWEEP, RANDOM));
        let cpu = CpuScene::<f32>::new(&f).unwrap();
        let exact = CpuScene::<f64>::new(&f).unwrap();
        let flags: Vec<u32> = rays
            .par_iter()
            .map(|r| {
                let (_, tmin, tmax) = f32_ray(r);
                cpu.trace_flagged(&Ray::from_f64(r.origin, r.direction), tmin, tmax)
                    .flags
            })
            .collect();
        let (scanned, _) = scan(&f, &rays, Precision::F32).unwrap();
        let (in_f64, _) = scan(&f, &rays, Precision::F64).unwrap();
        // The plain f32 answers: the trace's own, before any ray is traced again.
        let plain: Vec<_> = rays
            .par_iter()
            .map(|r| {
                let (_, tmin, tmax) = f32_ray(r);
                cpu.trace(&Ray::from_f64(r.origin, r.direction), tmin, tmax)
            })
            .collect();
        let results: Vec<(bool, bool, bool, Option<String>)> = (0..rays.len())
            .into_par_iter()
            .map(|i| {
                let r = &rays[i];
                let (f32_answer, instance) = match plain[i] {
                    Some(h) => {
                        let n = h.normal.to_f64();
                        ([n[0], n[1], n[2], f64::from(h.t)], h.instance as i32)
                    }
                    None => ([0.0, 0.0, 0.0, f64::INFINITY], -1),
                };
                let (near, redone) = old_rule(&cpu, &exact, r, &f32_answer, instance);
                let flag = flags[i];
                let flagged =
                    flag & (STATUS_START_NEAR | STATUS_START_BAND | STATUS_DROPPED_SPAN) != 0;
                let mut problem = None;
                if near && flag & (STATUS_START_NEAR | STATUS_START_BAND) == 0 {
                    problem = Some(format!(
                        "{name}: ray {i} {r:?}: near a surface, not flagged"
                    ));
                }
                let old = match redone {
                    true => answer(&in_f64, i),
                    false => (f32_answer.map(f64::to_bits), instance),
                };
                let new = answer(&scanned, i);
                let changed = new != old;
                // Only rays the trace alone flags may answer otherwise, and then as f64 does.
                if changed && (redone || !flagged || new != answer(&in_f64, i)) {
                    problem = Some(format!(
                        "{name}: ray {i} {r:?} (flags {flag}): scan {:?}, old rule {:?}",
                        scanned.hits[i], old
                    ));
                }
                (near, flagged, changed, problem)
            })
            .collect();
        let near = results.iter().filter(|r| r.0).count();
        let flagged = results.iter().filter(|r| r.1).count();
        let changed = results.iter().filter(|r| r.2).count();
        let dropped = flags
            .iter()
            .filter(|&&f| f & STATUS_DROPPED_SPAN != 0)
            .count();
        eprintln!(
            "{name:<60} {:>6} rays: {near:>5} near a surface (old check), {flagged:>5} flagged ({dropped} dropped spans), {changed} answers changed",
            rays.len()
        );
        problems.extend(results.into_iter().filter_map(|r| r.3));
        rays_all += rays.len();
        near_all += near;
        flagged_all += flagged;
        changed_all += changed;
    }
    eprintln!(
        "all: {rays_all} rays, {near_all} near a surface by the old check, {flagged_all} flagged, {changed_all} answers changed"
    );
    assert!(
        problems.is_empty(),
        "{} problems, e.g.\n{}",
        problems.len(),
        problems[..problems.len().min(10)].join("\n")
    );
    assert!(near_all > 0, "no ray started near a surface");
}
