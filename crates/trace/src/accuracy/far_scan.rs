//! Accuracy rows of whole CPU scans of solids placed far from the world origin: what the
//! f32 path's two-part ray origins and its f64 fallback buy, and what they cost, against
//! f32 with origins rounded at world scale (as before the rebasing) and f64.
//!
//! The scene is a sphere, a torus and a box, placed 1 m, 20 m, 100 m and 1 km (1e6 mm)
//! from the origin at translations no f32 holds. Rays start in f64 beside the solids: near
//! them in every direction, just off their surfaces, and grazing the sphere (see
//! [`rays`]). The reference is the first crossing of the exact
//! surfaces in double-double arithmetic ([`super::dd`]), independent of the tracer.

use hytrace_csg::{box3, sphere, to_tree, torus, Shape};
use hytrace_foundry::{Foundry, Transform64, UNSET};
use hytrace_volume::Rng;

use super::csg::{in_ball, sphere_reference, torus_reference, Case, RADIUS, TUBE};
use super::dd::Dd;
use super::{Row, Settings, Timer};
use crate::cpu::CpuScene;
use crate::error::Context;
use crate::scan::{cpu_answers, cpu_answers_flagged, redo_flagged_in_f64, Answer, RayRow};

/// How far the solids are from the world origin (mm).
const DISTANCES: [f64; 4] = [1e3, 2e4, 1e5, 1e6];
/// Components, one per distance (the distances are different workloads).
const COMPONENTS: [&str; 4] = [
    "csg scan, solids 1 m out",
    "csg scan, solids 20 m out",
    "csg scan, solids 100 m out",
    "csg scan, solids 1 km out",
];
/// An answer counts as wrong when its distance is off by more than this (mm).
const TOLERANCE: f64 = 1e-3;
const METRIC: &str = "share of rays off by more than 1e-3 mm (a wrong hit or miss included)";
const REFERENCE: &str = "double-double first crossing of the exact surfaces";
/// Half sides of the box (mm).
const BOX: [f64; 3] = [100.0, 60.0, 40.0];

/// Where each solid sits relative to the group's centre (mm): sphere, torus, box.
const OFFSETS: [[f64; 3]; 3] = [[0.0; 3], [400.0, 0.0, 0.0], [0.0, 400.0, 0.0]];

/// The group's centre `distance` out, with digits no f32 keeps.
fn group_centre(distance: f64) -> [f64; 3] {
    [0.48, 0.6, 0.64].map(|c| c * distance + 0.123_456_789)
}

/// The scene: the three solids placed around `centre`.
fn scene(centre: [f64; 3]) -> crate::Result<Foundry> {
    let shapes: [Shape; 3] = [
        sphere(RADIUS).context("far-scan scene")?,
        torus(0.0, TUBE, RADIUS).context("far-scan scene")?,
        box3(2.0 * BOX[0], 2.0 * BOX[1], 2.0 * BOX[2]).context("far-scan scene")?,
    ];
    let mut f = Foundry::new();
    for (k, shape) in shapes.iter().enumerate() {
        let mut s = f.begin_solid(&format!("solid{k}"));
        let tree = to_tree(shape).context("far-scan scene")?;
        s.add_csg(tree, 0, UNSET).context("far-scan scene")?;
        let solid = s.finish(0).context("far-scan scene")?;
        let at = std::array::from_fn(|i| centre[i] + OFFSETS[k][i]);
        f.add_instance(solid, Transform64::translation(at), 0, 0)
            .context("far-scan scene")?;
    }
    Ok(f)
}

/// The first crossing after 0 of the box centred on `centre`, in double-double (slabs).
fn box_reference(case: &Case, centre: [f64; 3]) -> Option<f64> {
    let (mut near, mut far) = (f64::NEG_INFINITY, f64::INFINITY);
    for k in 0..3 {
        let o = Dd::new(case.origin[k]) - Dd::new(centre[k]);
        let d = case.dir[k];
        if d == 0.0 {
            if o.to_f64().abs() > BOX[k] {
                return None;
            }
            continue;
        }
        let at = |side: f64| (Dd::new(side) - o).div(Dd::new(d)).to_f64();
        let (a, b) = (at(-BOX[k]), at(BOX[k]));
        near = near.max(a.min(b));
        far = far.min(a.max(b));
    }
    if near > far {
        return None;
    }
    [near, far].into_iter().find(|t| *t > 0.0)
}

/// The reference first crossing after 0 of every solid of the scene around `centre`.
fn reference(case: &Case, centre: [f64; 3]) -> Option<f64> {
    let at = |k: usize| std::array::from_fn(|i| centre[i] + OFFSETS[k][i]);
    [
        sphere_reference(case, at(0), RADIUS),
        torus_reference(case, at(1)),
        box_reference(case, at(2)),
    ]
    .into_iter()
    .flatten()
    .reduce(f64::min)
}

/// A unit direction, uniform on the sphere.
fn direction(rng: &mut Rng) -> [f64; 3] {
    let z = 2.0 * rng.next_f64() - 1.0;
    let phi = std::f64::consts::TAU * rng.next_f64();
    let r = (1.0 - z * z).sqrt();
    [r * phi.cos(), r * phi.sin(), z]
}

/// A unit vector perpendicular to the unit vector `n`.
fn perpendicular(rng: &mut Rng, n: [f64; 3]) -> [f64; 3] {
    loop {
        let a = direction(rng);
        let dot = a[0] * n[0] + a[1] * n[1] + a[2] * n[2];
        let u: [f64; 3] = std::array::from_fn(|k| a[k] - dot * n[k]);
        let l = (u[0] * u[0] + u[1] * u[1] + u[2] * u[2]).sqrt();
        if l > 0.1 {
            return u.map(|c| c / l);
        }
    }
}

/// `10^x` for `x` uniform in `[lo, hi]`, with a random sign.
fn signed_log_uniform(rng: &mut Rng, lo: f64, hi: f64) -> f64 {
    let m = 10f64.powf(lo + (hi - lo) * rng.next_f64());
    if rng.next_f64() < 0.5 {
        -m
    } else {
        m
    }
}

/// The bench's rays, in three families of the cases a detector scan meets:
/// - half start within 2.5 radii of a solid's centre (inside and outside it) in every
///   direction;
/// - a quarter start 1e-6 to 1e-3 mm off the sphere's surface or a box face, on either
///   side, in every direction (a ray starting on the boundary it was handed over at);
/// - a quarter pass the sphere 1e-3 to 1e-1 mm outside or inside its surface, tangent to
///   it (grazing).
fn rays(rng: &mut Rng, centre: [f64; 3], count: usize) -> Vec<RayRow> {
    let at = |k: usize| std::array::from_fn::<f64, 3, _>(|i| centre[i] + OFFSETS[k][i]);
    let row = |origin: [f64; 3], direction: [f64; 3]| RayRow {
        origin,
        direction,
        tmin: 0.0,
        tmax: f64::INFINITY,
    };
    (0..count)
        .map(|i| match i % 4 {
            0 | 1 => {
                let near = at(i % 3);
                let p = in_ball(rng, 2.5 * RADIUS);
                row(std::array::from_fn(|k| near[k] + p[k]), direction(rng))
            }
            2 if rng.next_f64() < 0.5 => {
                let (c, n) = (at(0), direction(rng));
                let r = RADIUS + signed_log_uniform(rng, -6.0, -3.0);
                row(std::array::from_fn(|k| c[k] + r * n[k]), direction(rng))
            }
            2 => {
                // A point on a random face of the box, moved off it along the face's normal.
                let (c, axis) = (at(2), rng.next_u32() as usize % 3);
                let mut p: [f64; 3] =
                    std::array::from_fn(|k| BOX[k] * (2.0 * rng.next_f64() - 1.0));
                let side = if rng.next_f64() < 0.5 { -1.0 } else { 1.0 };
                p[axis] = side * (BOX[axis] + signed_log_uniform(rng, -6.0, -3.0));
                row(std::array::from_fn(|k| c[k] + p[k]), direction(rng))
            }
            _ => {
                let (c, n) = (at(0), direction(rng));
                let u = perpendicular(rng, n);
                let r = RADIUS + signed_log_uniform(rng, -3.0, -1.0);
                let origin = std::array::from_fn(|k| c[k] + r * n[k] - 3.0 * RADIUS * u[k]);
                row(origin, u)
            }
        })
        .collect()
}

/// The share of `got` off `want` by more than [`TOLERANCE`].
fn share_wrong(got: &[Answer], want: &[Option<f64>]) -> f64 {
    let wrong = got
        .iter()
        .zip(want)
        .filter(|(g, w)| {
            let t = g.0[3];
            match (t.is_finite(), w) {
                (true, Some(w)) => (t - w).abs() > TOLERANCE,
                (false, None) => false,
                _ => true,
            }
        })
        .count();
    wrong as f64 / want.len().max(1) as f64
}

/// The rows of one distance: f32 with world-rounded origins, f32 with two-part origins
/// (the trace alone), the default f32 scan (two-part origins and the f64 fallback), f64.
fn distance_rows(
    settings: Settings,
    component: &'static str,
    distance: f64,
    seed: u32,
) -> crate::Result<Vec<Row>> {
    let centre = group_centre(distance);
    let f = scene(centre)?;
    let mut rng = Rng::new(13, seed, 0);
    let rays = rays(&mut rng, centre, settings.size(20_000, 600));
    let want: Vec<Option<f64>> = rays
        .iter()
        .map(|r| {
            let case = Case {
                origin: r.origin,
                dir: r.direction,
            };
            reference(&case, centre)
        })
        .collect();
    // Origins rounded to f32 in the world frame: what the tracer saw before it carried
    // the rest of each coordinate down to the instance's frame.
    let rounded: Vec<RayRow> = rays
        .iter()
        .map(|r| RayRow {
            origin: r.origin.map(|c| c as f32 as f64),
            ..*r
        })
        .collect();
    let f32_scene = CpuScene::<f32>::new(&f).context(component)?;
    let f64_scene = CpuScene::<f64>::new(&f).context(component)?;
    let with_fallback = || -> crate::Result<Vec<Answer>> {
        let (mut answers, flags) = cpu_answers_flagged(&f32_scene, &rays);
        redo_flagged_in_f64(&f, &f32_scene, &rays, &mut answers, &flags).context(component)?;
        Ok(answers)
    };
    let timer = Timer::new(settings);
    let row = |variant: &str, got: &[Answer], ns: f64| Row {
        component,
        variant: variant.into(),
        metric: METRIC,
        reference: REFERENCE,
        error: share_wrong(got, &want),
        ns_per_op: ns,
        memory_bytes: None,
    };
    Ok(vec![
        row(
            "f32, origins rounded in the world frame",
            &cpu_answers(&f32_scene, &rounded),
            timer.ns_per_op(rays.len(), || cpu_answers(&f32_scene, &rounded)),
        ),
        row(
            "f32, two-part origins rebased per instance",
            &cpu_answers(&f32_scene, &rays),
            timer.ns_per_op(rays.len(), || cpu_answers(&f32_scene, &rays)),
        ),
        row(
            "f32, rebased, f64 fallback (the default scan)",
            &with_fallback()?,
            timer.ns_per_op(rays.len(), with_fallback),
        ),
        row(
            "f64",
            &cpu_answers(&f64_scene, &rays),
            timer.ns_per_op(rays.len(), || cpu_answers(&f64_scene, &rays)),
        ),
    ])
}

/// Every far-scan row, timed on one thread (the scan's rayon loops run in a one-thread
/// pool, as every other row of the benchmark is timed).
pub(super) fn rows(settings: Settings) -> crate::Result<Vec<Row>> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .map_err(|e| crate::Error::Invalid(format!("far-scan rows: {e}")))?;
    pool.install(|| {
        let mut rows = Vec::new();
        for (k, (&distance, component)) in DISTANCES.iter().zip(COMPONENTS).enumerate() {
            rows.extend(distance_rows(settings, component, distance, k as u32)?);
        }
        Ok(rows)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn box_reference_finds_entries_and_exits() {
        let centre = [1e6, 0.0, 0.0];
        // From outside along x: the face at x = -100.
        let case = Case {
            origin: [1e6 - 1000.0, 0.0, 0.0],
            dir: [1.0, 0.0, 0.0],
        };
        assert_eq!(box_reference(&case, centre), Some(900.0));
        // From the centre along y: the face at y = 60.
        let case = Case {
            origin: centre,
            dir: [0.0, 1.0, 0.0],
        };
        assert_eq!(box_reference(&case, centre), Some(60.0));
        // Passing beside it along x at y = 61: nothing.
        let case = Case {
            origin: [1e6 - 1000.0, 61.0, 0.0],
            dir: [1.0, 0.0, 0.0],
        };
        assert_eq!(box_reference(&case, centre), None);
        // Away from it: nothing.
        let case = Case {
            origin: [1e6 - 1000.0, 0.0, 0.0],
            dir: [-1.0, 0.0, 0.0],
        };
        assert_eq!(box_reference(&case, centre), None);
    }

    #[test]
    fn torus_reference_finds_the_exit_from_inside_the_tube() {
        // From the tube's centre line straight up: the exit at z = TUBE.
        let case = Case {
            origin: [RADIUS, 0.0, 0.0],
            dir: [0.0, 0.0, 1.0],
        };
        let t = torus_reference(&case, [0.0; 3]).unwrap();
        assert!((t - TUBE).abs() < 1e-9, "{t}");
    }

    #[test]
    fn the_f64_scan_meets_the_reference_far_out() {
        let rows = distance_rows(Settings { quick: true }, "test", 1e6, 0).unwrap();
        let f64_row = rows.iter().find(|r| r.variant == "f64").unwrap();
        assert_eq!(f64_row.error, 0.0, "{rows:?}");
    }
}
