//! Tests of `torus.rs`.

use super::*;
use hytrace_testkit::torus::{tube_point, TorusRays};
use hytrace_testkit::vec3::{
    add, cross, dot, length as norm, normalized as unit, scale as mul, sub,
};
use hytrace_testkit::{Random, SplitMix64 as Rng};

type P = [f64; 3];

/// The torus tests' draws, on the shared generator.
trait TorusDraws: Random {
    /// A torus of random size (1e-2 to 1e2) and tube ratio (0.01 to 0.95): `(r, rtor)`.
    fn torus(&mut self) -> (f64, f64) {
        let rtor = 10f64.powf(self.range(-2.0, 2.0));
        let ratio = if self.uniform() < 0.3 {
            10f64.powf(self.range(-2.0, -1.0))
        } else {
            self.range(0.1, 0.95)
        };
        (rtor * ratio, rtor)
    }
}

impl TorusDraws for Rng {}

/// A ray and torus, rounded to f32 so that one f64 reference serves both precisions.
#[derive(Clone, Copy, Debug)]
struct Case {
    o: P,
    d: P,
    r: f64,
    rtor: f64,
}

fn round(p: P) -> P {
    p.map(|x| x as f32 as f64)
}

impl Case {
    fn new(o: P, d: P, r: f64, rtor: f64) -> Self {
        Case {
            o: round(o),
            d: round(d),
            r: r as f32 as f64,
            rtor: rtor as f32 as f64,
        }
    }
    fn size(&self) -> f64 {
        self.rtor + self.r
    }
    fn point(&self, t: f64) -> P {
        add(self.o, mul(self.d, t))
    }
    /// The tube function, straight from its definition.
    fn g(&self, t: f64) -> f64 {
        let p = self.point(t);
        let q = p[0].hypot(p[1]) - self.rtor;
        q * q + p[2] * p[2] - self.r * self.r
    }
    fn sdf(&self, t: f64) -> f64 {
        let p = self.point(t);
        (p[0].hypot(p[1]) - self.rtor).hypot(p[2]) - self.r
    }
    fn solve<T: Real>(&self) -> Vec<f64> {
        let mut out = [T::ZERO; 4];
        let n = torus_crossings(
            V3::<T>::from_f64(self.o),
            V3::from_f64(self.d),
            T::from_f64(self.r),
            T::from_f64(self.rtor),
            &mut out,
        );
        out[..n].iter().map(|t| t.to_f64()).collect()
    }
}

/// Bisection of a sign change of `g` on `[a, b]` down to adjacent doubles.
fn bisect(c: &Case, mut a: f64, mut b: f64) -> f64 {
    let a_inside = c.g(a) < 0.0;
    for _ in 0..200 {
        let m = 0.5 * (a + b);
        if m <= a || m >= b {
            break;
        }
        if (c.g(m) < 0.0) == a_inside {
            a = m;
        } else {
            b = m;
        }
    }
    0.5 * (a + b)
}

/// Golden-section search for the minimum of `f` on `[a, b]`: `(x, f(x))`.
fn golden_min(f: impl Fn(f64) -> f64, mut a: f64, mut b: f64) -> (f64, f64) {
    let k = 0.5 * (5f64.sqrt() - 1.0);
    let mut x1 = b - k * (b - a);
    let mut x2 = a + k * (b - a);
    let (mut f1, mut f2) = (f(x1), f(x2));
    for _ in 0..200 {
        if b - a <= 1e-15 * (1.0 + a.abs().max(b.abs())) {
            break;
        }
        if f1 < f2 {
            b = x2;
            x2 = x1;
            f2 = f1;
            x1 = b - k * (b - a);
            f1 = f(x1);
        } else {
            a = x1;
            x1 = x2;
            f1 = f2;
            x2 = a + k * (b - a);
            f2 = f(x2);
        }
    }
    if f1 < f2 {
        (x1, f1)
    } else {
        (x2, f2)
    }
}

/// Independent reference: every crossing of the ray with the tube, from 20000 samples of
/// `g` over the chord of (1.01 x) the bounding sphere, bisection of every sign change, and
/// a golden-section probe of every sampled local extremum that might hide a tiny chord.
fn reference(c: &Case) -> Vec<f64> {
    let dd = dot(c.d, c.d);
    let big = 1.01 * c.size();
    let perp2 = dot(cross(c.o, c.d), cross(c.o, c.d)) / dd;
    if perp2 >= big * big {
        return Vec::new();
    }
    let tc = -dot(c.o, c.d) / dd;
    let half = (big * big - perp2).sqrt() / dd.sqrt();
    let n = 20000;
    let ts: Vec<f64> = (0..=n)
        .map(|i| tc - half + 2.0 * half * i as f64 / n as f64)
        .collect();
    let gs: Vec<f64> = ts.iter().map(|&t| c.g(t)).collect();
    let mut roots = Vec::new();
    for i in 0..n {
        if (gs[i] < 0.0) != (gs[i + 1] < 0.0) {
            roots.push(bisect(c, ts[i], ts[i + 1]));
        }
    }
    for i in 1..n {
        let (l, m, r) = (gs[i - 1], gs[i], gs[i + 1]);
        let sign = if m > 0.0 && m <= l && m <= r {
            1.0
        } else if m < 0.0 && m >= l && m >= r {
            -1.0
        } else {
            continue;
        };
        if sign * l <= 0.0 || sign * r <= 0.0 {
            continue;
        }
        let (tm, gm) = golden_min(|t| sign * c.g(t), ts[i - 1], ts[i + 1]);
        if gm < 0.0 {
            roots.push(bisect(c, ts[i - 1], tm));
            roots.push(bisect(c, tm, ts[i + 1]));
        }
    }
    roots.sort_by(f64::total_cmp);
    roots
}

/// How far the ray gets from the surface between two parameters: max |sdf|.
fn excursion(c: &Case, a: f64, b: f64) -> f64 {
    let k = 64;
    let (mut best, mut at) = (-1.0, 0);
    for i in 0..=k {
        let v = c.sdf(a + (b - a) * i as f64 / k as f64).abs();
        if v > best {
            best = v;
            at = i;
        }
    }
    let step = (b - a) / k as f64;
    let lo = (a + step * at as f64 - step).max(a.min(b));
    let hi = (a + step * at as f64 + step).min(a.max(b));
    let (_, m) = golden_min(|t| -c.sdf(t).abs(), lo, hi);
    best.max(-m)
}

/// How far the ray stays within `delta` of the surface on either side of the reference
/// crossing `tr`: the parameter interval that a surface perturbed by `delta` (a few
/// ulps of the size, the rounding of the kernel's own tube function) could move the
/// crossing across. About `delta / sin(grazing angle)` for a simple crossing, far more
/// near a higher-order contact.
fn ambiguity(c: &Case, tr: f64, delta: f64) -> (f64, f64) {
    let side = |dir: f64| {
        let (mut lo, mut hi) = (0.0, delta / norm(c.d));
        for _ in 0..200 {
            if c.sdf(tr + dir * hi).abs() > delta {
                break;
            }
            lo = hi;
            hi *= 2.0;
        }
        for _ in 0..60 {
            let m = 0.5 * (lo + hi);
            if c.sdf(tr + dir * m).abs() > delta {
                hi = m;
            } else {
                lo = m;
            }
        }
        hi
    };
    (side(-1.0), side(1.0))
}

/// Worst errors of one family in one precision.
#[derive(Default, Debug)]
struct Tally {
    rays: usize,
    /// Crossings checked against the accuracy target.
    roots: usize,
    /// Max distance error along the ray over the torus size.
    max_err: f64,
    /// Max distance error over (torus size + distance of the crossing from the origin).
    max_rel: f64,
    /// Of those, crossings so ill-conditioned that rounding the surface by `delta` moves
    /// them by more than the target; they are held to that wider window instead.
    ill: usize,
    /// Max distance error over the size among the ill-conditioned crossings.
    ill_max_err: f64,
    /// Crossings of tiny chords or gaps (allowed to be missing) that were missing.
    tiny_missed: usize,
    /// Tiny-chord crossings reported but absent from the reference.
    tiny_extra: usize,
}

/// Compares `torus_crossings::<T>` with the reference on one case. A reference crossing
/// must be found within `tol(t)` (a distance along the ray), widened by its
/// [`ambiguity`] for `delta`, unless one of the chords or gaps next to it stays within
/// `tiny * r` of the surface; a reported crossing must be in the reference, or next to a
/// reported one with such a tiny chord or gap between them.
fn check<T: Real>(
    c: &Case,
    reference: &[f64],
    tol: &dyn Fn(f64) -> f64,
    (delta, tiny): (f64, f64),
    tally: &mut Tally,
) -> Result<(), String> {
    let got = c.solve::<T>();
    let len = norm(c.d);
    let size = c.size();
    let fail = |what: &str| {
        Err(format!(
            "{} {what}: case {c:?}\n  reference {reference:?}\n  got {got:?}",
            T::NAME
        ))
    };
    if got.len() & 1 == 1 {
        return fail("odd count");
    }
    if got.iter().any(|t| !t.is_finite()) || got.windows(2).any(|w| w[0] > w[1]) {
        return fail("not finite and sorted");
    }
    let thin = tiny * c.r;
    // The window around each reference crossing that a reported one may fall in.
    let windows: Vec<(f64, f64, bool)> = reference
        .iter()
        .map(|&tr| {
            let (wl, wr) = ambiguity(c, tr, delta * size);
            let w = tol(tr) / len;
            (tr - wl.max(w), tr + wr.max(w), wl.max(wr) > w)
        })
        .collect();
    let mut required = 0;
    tally.rays += 1;
    for (i, &tr) in reference.iter().enumerate() {
        let left = i > 0 && excursion(c, reference[i - 1], tr) < thin;
        let right = i + 1 < reference.len() && excursion(c, tr, reference[i + 1]) < thin;
        let (lo, hi, ill) = windows[i];
        let found = got.iter().any(|&t| lo <= t && t <= hi);
        if left || right {
            if !found {
                tally.tiny_missed += 1;
            }
            continue;
        }
        required += 1;
        let err = got
            .iter()
            .map(|&t| (t - tr).abs() * len)
            .fold(f64::INFINITY, f64::min);
        if !found {
            return fail(&format!("missed or inaccurate root {tr} (error {err:e})"));
        }
        tally.roots += 1;
        if ill {
            tally.ill += 1;
            tally.ill_max_err = tally.ill_max_err.max(err / size);
        } else {
            tally.max_err = tally.max_err.max(err / size);
            tally.max_rel = tally.max_rel.max(err / (size + tr.abs() * len));
        }
    }
    if got.len() < required {
        return fail("too few roots");
    }
    for (j, &tg) in got.iter().enumerate() {
        if windows.iter().any(|&(lo, hi, _)| lo <= tg && tg <= hi) {
            continue;
        }
        let tiny_pair = (j > 0 && excursion(c, got[j - 1], tg) < thin)
            || (j + 1 < got.len() && excursion(c, tg, got[j + 1]) < thin);
        if !tiny_pair {
            return fail(&format!("spurious root {tg}"));
        }
        tally.tiny_extra += 1;
    }
    Ok(())
}

/// Accuracy targets: f64 within 1e-9 (size + distance); f32 within 2e-5 size, or
/// relative to the distance too (`f32_far`) for far origins. Both widened by the
/// crossing's ambiguity for a surface error of 8 ulps of the size; chords and gaps that
/// stay within 1e-9 r (f64) or 0.9e-3 r (f32) of the surface may be missing.
fn run_family(name: &str, cases: &[Case], f32_far: bool) {
    let (mut t64, mut t32) = (Tally::default(), Tally::default());
    let mut failures = Vec::new();
    for c in cases {
        let reference = reference(c);
        let size = c.size();
        let tol64 = |t: f64| 1e-9 * (size + t.abs() * norm(c.d));
        let tol32 = |t: f64| {
            if f32_far {
                2e-5 * (size + t.abs() * norm(c.d))
            } else {
                2e-5 * size
            }
        };
        let limits64 = (8.0 * f64::EPSILON, 1e-9);
        if let Err(e) = check::<f64>(c, &reference, &tol64, limits64, &mut t64) {
            failures.push(e);
        }
        let limits32 = (8.0 * f32::EPSILON as f64, 0.9e-3);
        if let Err(e) = check::<f32>(c, &reference, &tol32, limits32, &mut t32) {
            failures.push(e);
        }
    }
    println!("{name} f64: {t64:?}");
    println!("{name} f32: {t32:?}");
    assert!(
        failures.is_empty(),
        "{name}: {} failures, first:\n{}",
        failures.len(),
        failures[0]
    );
}

const RAYS: usize = 2000;

#[test]
fn random_rays_near_torus() {
    let mut rng = Rng(1);
    let cases: Vec<Case> = (0..RAYS)
        .map(|_| {
            let (r, rtor) = rng.torus();
            let o = rng.torus_near(r, rtor, 3.0);
            let d = if rng.uniform() < 0.7 {
                unit(sub(rng.torus_near(r, rtor, 1.0), o))
            } else {
                rng.direction()
            };
            Case::new(o, d, r, rtor)
        })
        .collect();
    run_family("near", &cases, false);
}

#[test]
fn origin_inside_tube() {
    let mut rng = Rng(2);
    let cases: Vec<Case> = (0..RAYS)
        .map(|_| {
            let (r, rtor) = rng.torus();
            let phi = rng.range(0.0, 2.0 * std::f64::consts::PI);
            let theta = rng.range(0.0, 2.0 * std::f64::consts::PI);
            let (o, _) = tube_point(rtor, phi, theta, 0.999 * r * rng.uniform().sqrt());
            Case::new(o, rng.direction(), r, rtor)
        })
        .collect();
    run_family("inside_tube", &cases, false);
}

#[test]
fn rays_through_hole() {
    let mut rng = Rng(3);
    let cases: Vec<Case> = (0..RAYS)
        .map(|_| {
            let (r, rtor) = rng.torus();
            let phi = rng.range(0.0, 2.0 * std::f64::consts::PI);
            let rho = 0.95 * (rtor - r) * rng.uniform().sqrt();
            let h = [rho * phi.cos(), rho * phi.sin(), rng.range(-r, r)];
            let mut d = rng.direction();
            if rng.uniform() < 0.5 {
                // Nearly in the equatorial plane: through both sides of the tube.
                d[2] *= 0.05;
                d = unit(d);
            }
            let o = sub(h, mul(d, rng.range(0.5, 3.0) * (rtor + r)));
            Case::new(o, d, r, rtor)
        })
        .collect();
    run_family("through_hole", &cases, false);
}

#[test]
fn axis_aligned_and_zero_components() {
    let mut rng = Rng(4);
    let cases: Vec<Case> = (0..RAYS)
        .map(|i| {
            let (r, rtor) = rng.torus();
            let (o, d) = rng.torus_axis_ray(r, rtor, i);
            Case::new(o, d, r, rtor)
        })
        .collect();
    run_family("axis_aligned", &cases, false);
}

#[test]
fn far_origin() {
    let mut rng = Rng(5);
    let cases: Vec<Case> = (0..RAYS)
        .map(|_| {
            let (r, rtor) = rng.torus();
            let target = rng.torus_near(r, rtor, 1.0);
            let d = rng.direction();
            let o = sub(target, mul(d, rng.range(1e4, 2e4) * (rtor + r)));
            Case::new(o, d, r, rtor)
        })
        .collect();
    run_family("far_origin", &cases, true);
}

#[test]
fn non_unit_directions() {
    let mut rng = Rng(6);
    let cases: Vec<Case> = (0..RAYS)
        .map(|i| {
            let (r, rtor) = rng.torus();
            let o = rng.torus_near(r, rtor, 3.0);
            let d = unit(sub(rng.torus_near(r, rtor, 1.0), o));
            let k = if i % 2 == 0 { 0.01 } else { 100.0 };
            Case::new(o, mul(d, k), r, rtor)
        })
        .collect();
    run_family("non_unit", &cases, false);
}

/// Rays tangent to the tube at a random point, shifted along the normal by -1e-3 r
/// (a short chord that must be found), +1e-3 r (a near miss) or 0 (exact tangency).
/// Besides the comparison with the reference, the crossings must put the shifted
/// tangent point (1e-3 r from the surface) on the right side: inside for -1e-3 r (the
/// chord is found, in f32 too), outside for +1e-3 r (no chord invented).
#[test]
fn grazing_tube_tangent() {
    let mut rng = Rng(7);
    let (cases, at): (Vec<Case>, Vec<f64>) = (0..RAYS)
        .map(|i| {
            let (r, rtor) = rng.torus();
            let phi = rng.range(0.0, 2.0 * std::f64::consts::PI);
            let theta = rng.range(0.0, 2.0 * std::f64::consts::PI);
            let (p, n) = tube_point(rtor, phi, theta, r);
            let t = rng.direction();
            let d = unit(sub(t, mul(n, dot(t, n))));
            let offset = [-1e-3, 1e-3, 0.0][i % 3] * r;
            let back = rng.range(1.0, 3.0) * (rtor + r);
            let o = sub(add(p, mul(n, offset)), mul(d, back));
            (Case::new(o, d, r, rtor), back)
        })
        .unzip();
    run_family("grazing", &cases, false);
    let mut chords = 0;
    for (c, &t0) in cases.iter().zip(&at) {
        let depth = c.sdf(t0);
        if depth.abs() < 0.5e-3 * c.r {
            continue;
        }
        let inside = depth < 0.0;
        chords += inside as usize;
        for got in [c.solve::<f32>(), c.solve::<f64>()] {
            let before = got.iter().filter(|&&t| t < t0).count();
            assert_eq!(before % 2 == 1, inside, "{c:?} t0 {t0} got {got:?}");
        }
    }
    assert!(chords > RAYS / 4, "{chords}");
}

/// Horn tori (`rtor == r`): the hole closes to a point at the origin; half the rays pass
/// within 1e-3 of the size of that point.
#[test]
fn horn_torus_rtor_equals_r() {
    let mut rng = Rng(8);
    let cases: Vec<Case> = (0..RAYS)
        .map(|_| {
            let (_, rtor) = rng.torus();
            let o = rng.torus_near(rtor, rtor, 3.0);
            let d = if rng.uniform() < 0.5 {
                unit(sub(rng.torus_near(rtor, rtor, 1e-3), o))
            } else {
                rng.direction()
            };
            Case::new(o, d, rtor, rtor)
        })
        .collect();
    run_family("horn", &cases, false);
}

/// Spindle tori (`rtor < r`): the crossings of the outer ("apple") surface, the boundary
/// of the points within `r` of the core circle, including rays near its dimples on the
/// axis.
#[test]
fn spindle_torus_outer_surface() {
    let mut rng = Rng(12);
    let cases: Vec<Case> = (0..RAYS)
        .map(|i| {
            let (_, rtor) = rng.torus();
            let r = rtor * rng.range(1.0, 2.0);
            let o = rng.torus_near(r, rtor, 3.0);
            let target = if i % 2 == 0 {
                rng.torus_near(r, rtor, 0.5)
            } else {
                let (z, e) = ((r * r - rtor * rtor).sqrt(), 1e-3 * r);
                [rng.range(-e, e), rng.range(-e, e), z + rng.range(-e, e)]
            };
            Case::new(o, unit(sub(target, o)), r, rtor)
        })
        .collect();
    run_family("spindle", &cases, false);
}

#[test]
fn known_crossings() {
    fn solve<T: Real>(o: P, d: P, r: f64, rtor: f64) -> Vec<f64> {
        Case { o, d, r, rtor }.solve::<T>()
    }
    fn close(got: &[f64], want: &[f64], tol: f64) {
        assert_eq!(got.len(), want.len(), "{got:?} vs {want:?}");
        for (g, w) in got.iter().zip(want) {
            assert!(
                (g - w).abs() <= tol * w.abs().max(1.0),
                "{got:?} vs {want:?}"
            );
        }
    }
    for tol in [1e-13, 2e-6] {
        let s: fn(P, P, f64, f64) -> Vec<f64> = if tol < 1e-9 {
            solve::<f64>
        } else {
            solve::<f32>
        };
        // Along a diameter in the equatorial plane: through both sides of the tube.
        close(
            &s([-10.0, 0.0, 0.0], [1.0, 0.0, 0.0], 1.0, 3.0),
            &[6.0, 8.0, 12.0, 14.0],
            tol,
        );
        // Parallel to the axis through the tube's core, with a direction of length 2.
        close(
            &s([3.0, 0.0, -10.0], [0.0, 0.0, 2.0], 1.0, 3.0),
            &[4.5, 5.5],
            tol,
        );
        // Along the axis, through the hole.
        close(&s([0.0, 0.0, -10.0], [0.0, 0.0, 1.0], 1.0, 3.0), &[], tol);
        // Starting inside the tube, crossings behind the origin included.
        close(
            &s([3.5, 0.0, 0.0], [-1.0, 0.0, 0.0], 1.0, 3.0),
            &[-0.5, 1.5, 5.5, 7.5],
            tol,
        );
        // Tiny and huge direction lengths: t scales inversely.
        let h = 0.75f64.sqrt();
        for k in [1e-20, 1e20] {
            let want = [
                10.0 - 3.0 - h,
                10.0 - 3.0 + h,
                10.0 + 3.0 - h,
                10.0 + 3.0 + h,
            ];
            let got: Vec<f64> = s([-10.0, 0.0, 0.5], [k, 0.0, 0.0], 1.0, 3.0)
                .iter()
                .map(|t| t * k)
                .collect();
            close(&got, &want, tol);
        }
        // Tangent to the inner equator: dropped, or two equal crossings.
        let got = s([2.0, 0.0, -10.0], [0.0, 0.0, 1.0], 1.0, 3.0);
        assert!(got.is_empty() || (got.len() == 2 && (got[0] - 10.0).abs() < 1e-2));
    }
}

#[test]
fn degenerate_inputs_give_no_crossings() {
    let o = [-10.0, 0.0, 0.0];
    let x = [1.0, 0.0, 0.0];
    let none = |o: P, d: P, r: f64, rtor: f64| {
        let c = Case { o, d, r, rtor };
        assert!(
            c.solve::<f32>().is_empty() && c.solve::<f64>().is_empty(),
            "{c:?}"
        );
    };
    none(o, [0.0; 3], 1.0, 3.0);
    none(o, [f64::NAN, 0.0, 0.0], 1.0, 3.0);
    none(o, [f64::INFINITY, 0.0, 0.0], 1.0, 3.0);
    none([f64::NAN, 0.0, 0.0], x, 1.0, 3.0);
    none([f64::INFINITY, 0.0, 0.0], x, 1.0, 3.0);
    none(o, x, 0.0, 3.0);
    none(o, x, -1.0, 3.0);
    none(o, x, 1.0, -3.0);
    none(o, x, f64::NAN, 3.0);
    // Misses the bounding sphere.
    none([-10.0, 0.0, 4.5], x, 1.0, 3.0);
}

/// Points built at a known distance from the surface along the tube's normal, and on the
/// axis.
#[test]
fn sdf_at_known_distances() {
    let mut rng = Rng(10);
    for _ in 0..RAYS {
        let (r, rtor) = rng.torus();
        let phi = rng.range(0.0, 2.0 * std::f64::consts::PI);
        let theta = rng.range(0.0, 2.0 * std::f64::consts::PI);
        // Nearest core point stays (rtor cos phi, rtor sin phi, 0) up to the axis.
        let dist = rng.range(-r, rtor - r);
        let (p, _) = tube_point(rtor, phi, theta, r + dist);
        let size = rtor + r;
        let d64 = torus_sdf(V3::from_f64(p), r, rtor);
        assert!((d64 - dist).abs() <= 1e-13 * size, "{d64} vs {dist}");
        let d32 = torus_sdf(V3::<f32>::from_f64(p), r as f32, rtor as f32) as f64;
        assert!((d32 - dist).abs() <= 1e-6 * size, "{d32} vs {dist}");
        assert_eq!(d64 < 0.0, dist < 0.0);
        let z = rng.range(-2.0, 2.0) * size;
        let axis = torus_sdf(V3::new(0.0, 0.0, z), r, rtor);
        assert!((axis - (rtor.hypot(z) - r)).abs() <= 1e-13 * size);
    }
}

/// The normal is the sdf's gradient (finite differences) scaled by the distance to the
/// core circle.
#[test]
fn normal_matches_sdf_gradient() {
    let mut rng = Rng(11);
    for _ in 0..RAYS {
        let (r, rtor) = rng.torus();
        let size = rtor + r;
        let p = rng.torus_near(r, rtor, 2.0);
        let (rho, core) = (p[0].hypot(p[1]), (p[0].hypot(p[1]) - rtor).hypot(p[2]));
        if rho < 1e-3 * size || core < 1e-3 * size {
            continue;
        }
        let h = 1e-6 * size;
        let mut grad = [0.0; 3];
        for (k, g) in grad.iter_mut().enumerate() {
            let (mut a, mut b) = (p, p);
            a[k] += h;
            b[k] -= h;
            let f = |q: P| torus_sdf(V3::from_f64(q), r, rtor);
            *g = (f(a) - f(b)) / (2.0 * h);
        }
        let n = torus_normal(V3::from_f64(p), rtor).to_f64();
        assert!((norm(n) - core).abs() <= 1e-12 * size);
        let err = norm(sub(unit(n), grad));
        assert!(err < 1e-6, "normal {n:?} gradient {grad:?}");
        let n32 = torus_normal(V3::<f32>::from_f64(p), rtor as f32).to_f64();
        assert!(norm(sub(n32, n)) <= 1e-6 * size, "{n32:?} vs {n:?}");
    }
    // On the axis: the documented choice of core point.
    let n = torus_normal(V3::new(0.0, 0.0, 2.0), 3.0);
    assert_eq!(n, V3::new(-3.0, 0.0, 2.0));
}
