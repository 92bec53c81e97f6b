//! A torus around the z axis, centred on the origin: the points at distance `r` (tube radius)
//! from the core circle `x^2 + y^2 = rtor^2, z = 0` (`rtor` is the swept, major radius).
//!
//! [`torus_crossings`] finds where a ray crosses the tube surface, [`torus_normal`] gives the
//! outward normal there and [`torus_sdf`] the exact signed distance.
//!
//! # Why no quartic
//!
//! Squaring the tube equation gives the classic quartic in the ray parameter, but solving a
//! quartic in f32 is fragile exactly where a CSG tracer needs it most: near a tangency the
//! two roots of a short chord are a near-double root, whose real or complex nature is decided
//! by coefficient rounding, so a quartic solver loses or invents chords (and with them the
//! inside/outside parity of everything after them along the ray). Instead we work with the
//! unsquared function along the ray,
//!
//! ```text
//! g(s) = (rho(s) - rtor)^2 + z(s)^2 - r^2,      rho = sqrt(x^2 + y^2),
//! ```
//!
//! the squared distance to the core circle minus `r^2`, evaluated directly from the point.
//! Its rounding error is a few ulps of `r * (rtor + r)` everywhere, so the sign of `g` (inside
//! or outside the tube) is reliable down to depths of a few ulps of the torus size.
//!
//! # Algorithm
//!
//! * With `s` the arc length from the line's closest approach `c` to the centre and `u` the
//!   unit direction, `g(s) = s^2 + |c|^2 + rtor^2 - r^2 - 2 rtor rho(s)`, and `rho(s)` is
//!   the square root of a quadratic. Hence `g'' = 2 - 2 rtor m^2 / rho^3` with the constant
//!   `m = c_x u_y - c_y u_x` (the line's moment about the z axis).
//! * `g''` grows with `rho`, and `rho` has a single minimum along the line, so `g` is convex,
//!   then concave where `rho^3 < rtor m^2` (an interval around the point nearest the z axis,
//!   often empty), then convex again. The interval's ends are found in closed form.
//! * On a piece where `sigma * g` is convex (`sigma = +-1`), every tangent lies below the
//!   curve. Newton's method started at an end where `sigma * g > 0` therefore approaches the
//!   nearest crossing monotonically and never passes it, and once an iterate's slope stops
//!   pointing down, or its tangent stays positive up to the far end, there is provably no
//!   crossing in the piece. So per piece: ends on opposite sides of the surface give exactly
//!   one crossing (Newton from the end where `sigma * g > 0`); `sigma * g > 0` at both ends
//!   gives none or two (the first by Newton from one end, the last from the other, skipped
//!   outright when the two end tangents meet clearly above zero); `sigma * g < 0` at both ends
//!   gives none. Convergence is quadratic except next to a tangency; a bracketed,
//!   bisection-safeguarded Newton step takes over where rounding makes an iterate overshoot.
//!
//! The search runs along the chord of a sphere slightly larger than the torus's bounding
//! sphere, on whose boundary `g > 0`. Each piece contributes crossings according to the
//! signs of `g` at its ends, so the number of crossings is always even (at most four) and
//! they alternate enter/exit: a tangency is either dropped or reported as two (nearly)
//! equal crossings, never as one. Short chords are not lost: a chord is found whenever `g` at
//! the bottom of the dip is negative in floating point, i.e. whenever the ray dips into the
//! tube by more than a few ulps of the torus size (the same holds for short gaps when the ray
//! touches the surface from inside). Within that rounding noise of a tangency, or of a
//! higher-order contact (a ray along an asymptotic direction of the saddle-shaped inner
//! half), a crossing can come out as three nearby crossings, still alternating.
//!
//! # Conditioning
//!
//! Before anything else the origin is moved to the point `c` of closest approach to the torus
//! centre (computed with a compensated product and sum, so that it lies on the given line to
//! a few ulps of `|c|`, not of `|origin|`) and the direction is normalised; then everything
//! is scaled by `1 / (rtor + r)`. All quantities the search sees are O(1) whatever the
//! distance of the ray origin or the length of the direction, and the returned `t` is mapped
//! back as `t = t_c + s (rtor + r) / |d|`, which loses no more than rounding `t` itself.
//!
//! Everything is allocation-free and non-recursive with fixed iteration caps, so the same
//! algorithm ports directly to a shader. A ray aimed at the torus costs about a dozen
//! evaluations of `g` and `g'` (one square root and one division each) on average.

use crate::real::{two_product, two_sum, Real, V3};

/// The search runs over the chord of a sphere `1 + SPHERE_MARGIN` times the torus's bounding
/// sphere, on whose surface `g >= 2 r (rtor + r) SPHERE_MARGIN`, comfortably outside.
const SPHERE_MARGIN: f64 = 1.0 / 64.0;

/// Iteration cap of every Newton search: never reached in practice (a search converges
/// quadratically, or linearly with ratio 1/2 next to a tangency, or halves its bracket at
/// least every second step).
const MAX_ITERATIONS: usize = 64;

/// `o + d * t` with the product and the sum compensated: correctly rounded up to a few ulps
/// of the result, whatever the cancellation between `o` and `d * t`.
fn exact_at<T: Real>(o: V3<T>, d: V3<T>, t: T) -> V3<T> {
    let one = |o: T, d: T| {
        let (p, pe) = two_product(d, t);
        let (s, se) = two_sum(o, p);
        s + (se + pe)
    };
    V3::new(one(o.x, d.x), one(o.y, d.y), one(o.z, d.z))
}

/// All ray parameters `t` at which `origin + t * direction` crosses the surface of the torus
/// around z with tube radius `r` and swept radius `rtor`, sorted ascending; returns how many
/// (0, 2 or 4) were written to `out`.
///
/// Crossings behind the origin (`t < 0`) are included. `direction` need not be unit length;
/// `t` is always the parameter along the given vector. The count is always even and the
/// crossings alternate enter/exit, so toggling inside/outside from "outside" at `t = -inf`
/// is consistent: an exact tangency is either dropped or reported as two equal crossings,
/// depending on the rounding of the tube function at the touching point (see the module
/// documentation for the algorithm and why it is robust for grazing rays).
///
/// Meant for `rtor >= r > 0`. For `rtor < r` the result is the boundary of the set of points
/// within `r` of the core circle (the outer surface of the spindle torus). Returns 0 for a
/// zero or non-finite direction, `r <= 0`, `rtor < 0`, or non-finite input.
pub fn torus_crossings<T: Real>(
    origin: V3<T>,
    direction: V3<T>,
    r: T,
    rtor: T,
    out: &mut [T; 4],
) -> usize {
    let big = direction.max_abs();
    let scale = rtor + r;
    if !(big > T::ZERO && big.is_finite() && r > T::ZERO && rtor >= T::ZERO && scale.is_finite()) {
        return 0;
    }
    // |direction| and the unit direction, without squaring tiny or huge components.
    let dn = V3::new(direction.x / big, direction.y / big, direction.z / big);
    let ln = dn.length();
    let u = dn * (T::ONE / ln);
    let len = big * ln;
    // The point of closest approach to the centre, `c = origin + t_c * direction`. The
    // product and sum are compensated, so `c` lies on the given line to a few ulps of |c|
    // rather than of |origin|: a grazing crossing moves by the ray's sideways error divided
    // by the sine of the grazing angle, which would otherwise cost f32 a factor
    // |origin| / size in accuracy. An error in `t_c` itself only slides `c` along the
    // line; one projection removes it (to rounding of |c|) and is accounted for in `t_c`.
    let mut t_c = -origin.dot(u) / len;
    let mut c = exact_at(origin, direction, t_c);
    let along = c.dot(u);
    c = c - u * along;
    t_c = t_c - along / len;
    let inv_scale = T::ONE / scale;
    let c = c * inv_scale;
    let c2 = c.length_squared();
    // The tube lies inside the unit sphere (in scaled units); a ray that does not enter it
    // at most touches the outer equator.
    if !(c2 < T::ONE && t_c.is_finite()) {
        return 0;
    }
    let outer = T::ONE + T::from_f64(SPHERE_MARGIN);
    let reach = (outer * outer - c2).sqrt();
    let line = Line::new(c, u, rtor * inv_scale, r * inv_scale);
    let mut s = [T::ZERO; 4];
    let count = line.crossings(-reach, reach, &mut s);
    let per_s = scale / len;
    for (o, &si) in out.iter_mut().zip(&s[..count]) {
        *o = t_c + si * per_s;
    }
    count
}

/// Outward normal (not normalised) of the tube surface at `p`: `p` minus the nearest point
/// of the core circle of radius `rtor`, so its length is the distance to the core circle
/// (`r` on the surface). On the z axis, where every core point is equally near, the core
/// point `(rtor, 0, 0)` is used.
pub fn torus_normal<T: Real>(p: V3<T>, rtor: T) -> V3<T> {
    let rho = (p.x * p.x + p.y * p.y).sqrt();
    if rho > T::ZERO {
        // p - rtor * (x, y, 0) / rho, written to keep (rho - rtor) exact near the surface.
        let k = (rho - rtor) / rho;
        V3::new(p.x * k, p.y * k, p.z)
    } else {
        V3::new(-rtor, T::ZERO, p.z)
    }
}

/// Exact signed distance from `p` to the tube surface (negative inside):
/// `|(rho - rtor, z)| - r` with `rho = sqrt(x^2 + y^2)`.
pub fn torus_sdf<T: Real>(p: V3<T>, r: T, rtor: T) -> T {
    let rho = (p.x * p.x + p.y * p.y).sqrt();
    let q = rho - rtor;
    (q * q + p.z * p.z).sqrt() - r
}

/// `g` and `g'` at `s`.
#[derive(Clone, Copy)]
struct Sample<T> {
    s: T,
    g: T,
    d: T,
}

/// The tube function along one line, in units of `rtor + r`: the line is `c + s u` with unit
/// `u` and `c` orthogonal to `u`.
struct Line<T> {
    c: V3<T>,
    u: V3<T>,
    /// Swept radius.
    big: T,
    /// Tube radius squared.
    small2: T,
    /// Squared moment of the line about the z axis, `(c_x u_y - c_y u_x)^2`.
    m2: T,
    /// Convergence tolerance on `s`.
    tol: T,
    eps: T,
}

impl<T: Real> Line<T> {
    fn new(c: V3<T>, u: V3<T>, big: T, small: T) -> Self {
        let m = c.x * u.y - c.y * u.x;
        let eps = T::EPSILON;
        Line {
            c,
            u,
            big,
            small2: small * small,
            m2: m * m,
            tol: T::from_f64(4.0) * eps,
            eps,
        }
    }

    /// `g` and `g'` at `s`, from the point itself.
    fn sample(&self, s: T) -> Sample<T> {
        let p = self.c.at(self.u, s);
        let rho = (p.x * p.x + p.y * p.y).sqrt();
        let q = rho - self.big;
        let g = q * q + p.z * p.z - self.small2;
        // On the axis rho is not differentiable; any finite slope keeps the searches safe.
        let drho = if rho > T::ZERO {
            (p.x * self.u.x + p.y * self.u.y) / rho
        } else {
            T::ZERO
        };
        let d = T::TWO * (q * drho + p.z * self.u.z);
        Sample { s, g, d }
    }

    /// The interval `[i1, i2]` (clamped to `[lo, hi]`) outside of which `g` is convex: where
    /// `rho^3 < rtor m^2`. `None` when `g` is convex on all of `[lo, hi]`.
    fn concave_part(&self, lo: T, hi: T) -> Option<(T, T)> {
        let u = self.u;
        let a = u.x * u.x + u.y * u.y;
        // A line (nearly) parallel to the axis: rho is (nearly) constant and g convex, up to
        // a region within rtor * eps of the axis where g is far from zero anyway.
        if a > self.eps {
            // rho at the inflection points. The floor widens the concave part around the
            // kink of rho where a line crosses the axis (zero-width there) to where rho is
            // resolved; the extra width is convex, but there rho <= floor, so
            // g >= (rtor - floor)^2 - r^2 > 0 and no crossing can hide in it.
            let floor = self.eps.sqrt();
            let rho_i = (self.big * self.m2).cbrt().max(floor);
            // rho(s)^2 = a s^2 + 2 b s + cc reaches rho_i^2 where (a s + b)^2 = a rho_i^2 - m^2.
            let w = a * rho_i * rho_i - self.m2;
            if w >= T::ZERO {
                let b = self.c.x * u.x + self.c.y * u.y;
                let mid = -b / a;
                let half = w.sqrt() / a;
                let (i1, i2) = ((mid - half).max(lo), (mid + half).min(hi));
                if i1 < i2 {
                    return Some((i1, i2));
                }
            }
        }
        None
    }

    /// Newton's method on `g` from `start` towards `end`, where `sigma * g` (`sigma` = +-1)
    /// is convex and `sigma * g(start) > 0`. The tangent at each iterate bounds `sigma * g`
    /// from below, so the iterates approach the nearest crossing monotonically without
    /// passing it, and once the slope no longer points down towards zero or the tangent
    /// stays positive up to `end`, there is no crossing before `end`: returns `None`.
    fn newton_from(&self, start: Sample<T>, end: T, sigma: T) -> Option<T> {
        let dir = if end > start.s { T::ONE } else { -T::ONE };
        let mut x = start;
        for _ in 0..MAX_ITERATIONS {
            if x.g == T::ZERO {
                return Some(x.s);
            }
            // sigma * g must decrease along dir.
            if sigma * x.d * dir >= T::ZERO || !x.d.is_finite() {
                return None;
            }
            let next = x.s - x.g / x.d;
            if (next - end) * dir > T::ZERO {
                return None;
            }
            if (next - x.s).abs() <= self.tol {
                return Some(next);
            }
            let y = self.sample(next);
            if (y.g < T::ZERO) != (x.g < T::ZERO) {
                // Overshot by rounding (or by the rounding of the piece ends): the crossing
                // is bracketed, usually within a few ulps.
                return Some(if dir > T::ZERO {
                    self.bracketed(x, y)
                } else {
                    self.bracketed(y, x)
                });
            }
            x = y;
        }
        Some(x.s)
    }

    /// The crossing in `[a.s, b.s]`, where `g` changes sign: Newton's method safeguarded by
    /// bisection (a fallback that only rounding ever needs).
    fn bracketed(&self, a: Sample<T>, b: Sample<T>) -> T {
        let a_inside = a.g < T::ZERO;
        let (mut lo, mut hi) = (a.s, b.s);
        let mut x = if a.g != b.g {
            a.s + (b.s - a.s) * (a.g / (a.g - b.g))
        } else {
            T::HALF * (lo + hi)
        };
        let mut prev = hi - lo;
        for _ in 0..MAX_ITERATIONS {
            if !(x > lo && x < hi) {
                x = T::HALF * (lo + hi);
            }
            let y = self.sample(x);
            if y.g == T::ZERO {
                return x;
            }
            if (y.g < T::ZERO) == a_inside {
                lo = x;
            } else {
                hi = x;
            }
            let mut next = x - y.g / y.d;
            if !(next > lo && next < hi) || T::TWO * (next - x).abs() > prev {
                next = T::HALF * (lo + hi);
            }
            prev = (next - x).abs();
            x = next;
            if prev <= self.tol || hi - lo <= self.tol {
                break;
            }
        }
        x
    }

    /// Whether `sigma * g`, convex on `[a.s, b.s]` and positive at both ends, might dip to
    /// zero in between: false when the two end tangents (lower bounds) meet clearly above
    /// zero, which spares the Newton searches for most rays that pass near the tube.
    fn may_dip(&self, a: Sample<T>, b: Sample<T>, sigma: T) -> bool {
        let (ga, da, gb, db) = (sigma * a.g, sigma * a.d, sigma * b.g, sigma * b.d);
        if !(da < T::ZERO && db > T::ZERO) {
            // One tangent never descends; `newton_from` settles it without evaluations.
            return true;
        }
        let w = b.s - a.s;
        // The tangents meet at a.s + y, at height ga + da * y.
        let y = (gb - ga - db * w) / (da - db);
        let low = ga + da * y;
        let noise = T::from_f64(16.0) * self.eps * (ga + gb + (db - da) * w);
        low <= noise
    }

    /// The crossings in the piece `[a.s, b.s]` where `g` is convex (or concave), appended
    /// to `out`.
    fn piece(&self, a: Sample<T>, b: Sample<T>, convex: bool, out: &mut [T; 4], n: &mut usize) {
        if b.s <= a.s {
            return;
        }
        let sigma = if convex { T::ONE } else { -T::ONE };
        // Ends where g has the sign of g'' (outside for a convex piece, inside for a concave
        // one); Newton from there is monotone.
        let start_a = (a.g >= T::ZERO) == convex;
        let start_b = (b.g >= T::ZERO) == convex;
        let mut push = |t: T| {
            if *n < out.len() {
                out[*n] = t;
                *n += 1;
            }
        };
        match (start_a, start_b) {
            // sigma * g < 0 at both ends: one-signed throughout.
            (false, false) => {}
            // Exactly one crossing.
            (true, false) => push(
                self.newton_from(a, b.s, sigma)
                    .unwrap_or_else(|| self.bracketed(a, b)),
            ),
            (false, true) => push(
                self.newton_from(b, a.s, sigma)
                    .unwrap_or_else(|| self.bracketed(a, b)),
            ),
            // None or two: the first from a, the last from b.
            (true, true) => {
                if self.may_dip(a, b, sigma) {
                    if let Some(first) = self.newton_from(a, b.s, sigma) {
                        let last = self.newton_from(b, a.s, sigma).unwrap_or(first);
                        push(first);
                        push(last.max(first));
                    }
                }
            }
        }
    }

    /// The crossings in `[lo, hi]` (where `g > 0` at both ends), ascending, into `out`.
    fn crossings(&self, lo: T, hi: T, out: &mut [T; 4]) -> usize {
        // Both ends lie outside the torus by construction; pinning them keeps the count even
        // whatever the rounding.
        let outside = |mut x: Sample<T>| {
            x.g = x.g.max(T::ZERO);
            x
        };
        let first = outside(self.sample(lo));
        let last = outside(self.sample(hi));
        let mut n = 0;
        match self.concave_part(lo, hi) {
            Some((i1, i2)) => {
                let s1 = if i1 > lo { self.sample(i1) } else { first };
                let s2 = if i2 < hi { self.sample(i2) } else { last };
                self.piece(first, s1, true, out, &mut n);
                self.piece(s1, s2, false, out, &mut n);
                self.piece(s2, last, true, out, &mut n);
            }
            None => self.piece(first, last, true, out, &mut n),
        }
        n
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    type P = [f64; 3];

    fn add(a: P, b: P) -> P {
        [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
    }
    fn sub(a: P, b: P) -> P {
        [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
    }
    fn mul(a: P, k: f64) -> P {
        [a[0] * k, a[1] * k, a[2] * k]
    }
    fn dot(a: P, b: P) -> f64 {
        a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
    }
    fn cross(a: P, b: P) -> P {
        [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ]
    }
    fn norm(a: P) -> f64 {
        dot(a, a).sqrt()
    }
    fn unit(a: P) -> P {
        mul(a, 1.0 / norm(a))
    }

    /// SplitMix64: a seeded, dependency-free generator.
    struct Rng(u64);

    impl Rng {
        fn next(&mut self) -> u64 {
            self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            z ^ (z >> 31)
        }
        /// Uniform in [0, 1).
        fn unit(&mut self) -> f64 {
            (self.next() >> 11) as f64 / (1u64 << 53) as f64
        }
        fn range(&mut self, a: f64, b: f64) -> f64 {
            a + (b - a) * self.unit()
        }
        fn below(&mut self, n: u64) -> u64 {
            self.next() % n
        }
        /// Uniform on the unit sphere.
        fn direction(&mut self) -> P {
            loop {
                let v = [
                    self.range(-1.0, 1.0),
                    self.range(-1.0, 1.0),
                    self.range(-1.0, 1.0),
                ];
                let l2 = dot(v, v);
                if l2 > 1e-4 && l2 <= 1.0 {
                    return mul(v, 1.0 / l2.sqrt());
                }
            }
        }
        /// A torus of random size (1e-2 to 1e2) and tube ratio (0.01 to 0.95): `(r, rtor)`.
        fn torus(&mut self) -> (f64, f64) {
            let rtor = 10f64.powf(self.range(-2.0, 2.0));
            let ratio = if self.unit() < 0.3 {
                10f64.powf(self.range(-2.0, -1.0))
            } else {
                self.range(0.1, 0.95)
            };
            (rtor * ratio, rtor)
        }
        /// A point in the torus's bounding box scaled by `k`.
        fn near(&mut self, r: f64, rtor: f64, k: f64) -> P {
            let s = k * (rtor + r);
            [
                self.range(-s, s),
                self.range(-s, s),
                self.range(-k * r, k * r),
            ]
        }
    }

    /// The point of the core circle at azimuth `phi` plus `rad` along the tube direction
    /// `(theta, phi)`, and that unit direction.
    fn tube_point(rtor: f64, phi: f64, theta: f64, rad: f64) -> (P, P) {
        let n = [
            theta.cos() * phi.cos(),
            theta.cos() * phi.sin(),
            theta.sin(),
        ];
        (
            add([rtor * phi.cos(), rtor * phi.sin(), 0.0], mul(n, rad)),
            n,
        )
    }

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
                let o = rng.near(r, rtor, 3.0);
                let d = if rng.unit() < 0.7 {
                    unit(sub(rng.near(r, rtor, 1.0), o))
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
                let (o, _) = tube_point(rtor, phi, theta, 0.999 * r * rng.unit().sqrt());
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
                let rho = 0.95 * (rtor - r) * rng.unit().sqrt();
                let h = [rho * phi.cos(), rho * phi.sin(), rng.range(-r, r)];
                let mut d = rng.direction();
                if rng.unit() < 0.5 {
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
                let mut o = rng.near(r, rtor, 2.0);
                let k = rng.below(3) as usize;
                let sign = if rng.unit() < 0.5 { -1.0 } else { 1.0 };
                let mut d = [0.0; 3];
                match i % 5 {
                    // Along a coordinate axis.
                    0 => d[k] = sign,
                    // One zero component.
                    1 => {
                        d = rng.direction();
                        d[k] = 0.0;
                    }
                    // Zero components in both origin and direction.
                    2 => {
                        d = rng.direction();
                        d[k] = 0.0;
                        o[(k + 1) % 3] = 0.0;
                    }
                    // Parallel to the z axis, on it or through the tube.
                    3 => {
                        d[2] = sign;
                        let rho = if rng.unit() < 0.2 {
                            0.0
                        } else {
                            rng.range(0.0, 1.2 * (rtor + r))
                        };
                        o[0] = rho;
                        o[1] = 0.0;
                    }
                    // In the equatorial plane through the axis.
                    _ => {
                        d[k.min(1)] = sign;
                        o = [0.0; 3];
                        o[k.min(1)] = -sign * rng.range(0.0, 3.0) * (rtor + r);
                    }
                }
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
                let target = rng.near(r, rtor, 1.0);
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
                let o = rng.near(r, rtor, 3.0);
                let d = unit(sub(rng.near(r, rtor, 1.0), o));
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
                let o = rng.near(rtor, rtor, 3.0);
                let d = if rng.unit() < 0.5 {
                    unit(sub(rng.near(rtor, rtor, 1e-3), o))
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
                let o = rng.near(r, rtor, 3.0);
                let target = if i % 2 == 0 {
                    rng.near(r, rtor, 0.5)
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
            let p = rng.near(r, rtor, 2.0);
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
}
