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
mod tests;
