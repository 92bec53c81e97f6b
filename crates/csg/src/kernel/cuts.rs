//! Unbounded cutting primitives used to carve angular segments: the phi wedge around z and
//! the theta cone shell around z with its apex at the origin.

use super::spans::{quadratic_roots, Spans};
use crate::real::{Real, V3};

/// Angle from `phi0` (unit `(c0, s0)`) to the direction `(x, y)`, in `[0, 2 pi)`.
fn angle_from<T: Real>(c0: T, s0: T, x: T, y: T) -> T {
    let a = (c0 * y - s0 * x).atan2(c0 * x + s0 * y);
    if a < T::ZERO {
        a + T::TWO * T::PI
    } else {
        a
    }
}

/// Opening angle of the wedge `[cos phi0, sin phi0, cos phi1, sin phi1]`, in `(0, 2 pi]`.
fn wedge_width<T: Real>(p: &[T; 6]) -> T {
    let w = angle_from(p[0], p[1], p[2], p[3]);
    if w > T::ZERO {
        w
    } else {
        T::TWO * T::PI
    }
}

fn in_wedge<T: Real>(p: &[T; 6], x: T, y: T) -> bool {
    angle_from(p[0], p[1], x, y) <= wedge_width(p)
}

/// Angle within which a direction runs along a cut's surface: the rounding of its angles
/// (an f32 wedge of 90 degrees is wider by 4e-8 rad).
fn angle_tolerance<T: Real>() -> T {
    T::from_f64(4.0) * T::EPSILON
}

/// Whether the direction `(x, y)` points strictly between the wedge's half-planes (not
/// along one, within [`angle_tolerance`]).
fn strictly_in_wedge<T: Real>(p: &[T; 6], x: T, y: T) -> bool {
    let a = angle_from(p[0], p[1], x, y);
    a > angle_tolerance() && a < wedge_width(p) - angle_tolerance()
}

/// Whether the line through `o` along `d` passes through the origin (of the plane when
/// `z` is zero) within rounding: `|o x d|^2 <= (8 eps)^2 |o|^2 |d|^2`.
fn through_origin<T: Real>(o: V3<T>, d: V3<T>) -> bool {
    let c = o.cross(d);
    let eps = T::from_f64(8.0) * T::EPSILON;
    c.length_squared() <= eps * eps * o.length_squared() * d.length_squared()
}

/// Spans of a ray whose line passes through the edge of a cut (the wedge's axis, the
/// cone's apex) at `t`: the ray goes from the side `before` to the side `after` there,
/// one crossing (with `normal`, oriented by the caller) or none.
fn through_edge<T: Real>(before: bool, after: bool, t: T, normal: V3<T>) -> Spans<T> {
    if before == after {
        return if before {
            Spans::one(super::spans::Span::everywhere())
        } else {
            Spans::empty()
        };
    }
    Spans::from_toggles(before, &[(t, normal)])
}

/// Outward normals of the two bounding half-planes of a wedge.
fn wedge_normals<T: Real>(p: &[T; 6]) -> [V3<T>; 2] {
    [V3::new(p[1], -p[0], T::ZERO), V3::new(-p[3], p[2], T::ZERO)]
}

/// Phi wedge `[cos phi0, sin phi0, cos phi1, sin phi1]`: points whose azimuth lies from
/// `phi0` counter-clockwise to `phi1`.
pub fn phicut_spans<T: Real>(p: &[T; 6], o: V3<T>, d: V3<T>) -> Spans<T> {
    if d.x == T::ZERO && d.y == T::ZERO {
        return if in_wedge(p, o.x, o.y) {
            Spans::one(super::spans::Span::everywhere())
        } else {
            Spans::empty()
        };
    }
    // A ray whose line passes through the axis meets both half-planes there: it goes from
    // the azimuth of -d to that of d, where a direction along a half-plane runs on the
    // surface, outside (as Geant4 has it). Two crossings at one point would toggle twice.
    let flat = |v: V3<T>| V3::new(v.x, v.y, T::ZERO);
    if through_origin(flat(o), flat(d)) {
        let t = -(o.x * d.x + o.y * d.y) / (d.x * d.x + d.y * d.y);
        return through_edge(
            strictly_in_wedge(p, -d.x, -d.y),
            strictly_in_wedge(p, d.x, d.y),
            t,
            -d,
        );
    }
    let mut crossings = [(T::ZERO, V3::zero()); 2];
    let mut count = 0;
    for (k, n) in wedge_normals(p).into_iter().enumerate() {
        let dn = n.dot(d);
        if dn == T::ZERO {
            continue;
        }
        let t = -n.dot(o) / dn;
        let q = o.at(d, t);
        // Only the half-plane on the phi side of the axis bounds the wedge.
        let (c, s) = (p[2 * k], p[2 * k + 1]);
        if c * q.x + s * q.y >= T::ZERO {
            crossings[count] = (t, n);
            count += 1;
        }
    }
    if count == 2 && crossings[1].0 < crossings[0].0 {
        crossings.swap(0, 1);
    }
    // The state before the first crossing follows from that crossing's own normal (the ray
    // leaves through an outward normal it moves along). Deciding it from the direction
    // instead can contradict the crossing when the ray runs along a cut plane.
    let inside_before = match count {
        0 => in_wedge(p, o.x, o.y),
        _ => crossings[0].1.dot(d) > T::ZERO,
    };
    Spans::from_toggles(inside_before, &crossings[..count])
}

/// Signed distance bound of a phi wedge (exact sign).
pub fn phicut_sdf<T: Real>(p: &[T; 6], x: V3<T>) -> T {
    let [n0, n1] = wedge_normals(p);
    let (a, b) = (n0.dot(x), n1.dot(x));
    if wedge_width(p) <= T::PI {
        a.max(b)
    } else {
        a.min(b)
    }
}

/// Polar angle of a direction, in `[0, pi]`.
fn polar<T: Real>(v: V3<T>) -> T {
    V3::new(v.x, v.y, T::ZERO).length().atan2(v.z)
}

/// Theta cone shell `[theta0, theta1]`: points whose polar angle from +z lies between
/// `theta0` and `theta1` (`theta0 = 0` or `theta1 = pi` leave that side open).
pub fn thetacut_spans<T: Real>(p: &[T; 6], o: V3<T>, d: V3<T>) -> Spans<T> {
    // A ray through the apex meets the cones there: it goes from the polar angle of -d to
    // that of d, where a direction along a cone runs on the surface, outside.
    if through_origin(o, d) {
        let strictly_in = |v: V3<T>| {
            let (theta, tol) = (polar(v), angle_tolerance());
            (p[0] <= T::ZERO || theta > p[0] + tol) && (p[1] >= T::PI || theta < p[1] - tol)
        };
        let t = -o.dot(d) / d.length_squared();
        return through_edge(strictly_in(-d), strictly_in(d), t, -d);
    }
    let mut crossings = [(T::ZERO, V3::zero()); 4];
    let mut count = 0;
    let mut add = |t: T| {
        let q = o.at(d, t);
        // Direction of increasing theta (times rho |q|); the caller orients normals.
        let rho2 = q.x * q.x + q.y * q.y;
        crossings[count] = (t, V3::new(q.x * q.z, q.y * q.z, -rho2));
        if rho2 == T::ZERO {
            crossings[count].1 = V3::new(T::ZERO, T::ZERO, -T::ONE);
        }
        count += 1;
    };
    for (k, theta) in [p[0], p[1]].into_iter().enumerate() {
        let open = if k == 0 {
            theta <= T::ZERO
        } else {
            theta >= T::PI
        };
        if open {
            continue;
        }
        let (c, s) = (theta.cos(), theta.sin());
        if c.abs() < T::SURFACE_TOLERANCE {
            // theta = pi/2: the plane z = 0.
            if d.z != T::ZERO {
                add(-o.z / d.z);
            }
            continue;
        }
        // c^2 rho^2 - s^2 z^2 = 0 on the nappe where z has the sign of cos(theta).
        let (c2, s2) = (c * c, s * s);
        let a = c2 * (d.x * d.x + d.y * d.y) - s2 * d.z * d.z;
        let b = c2 * (o.x * d.x + o.y * d.y) - s2 * o.z * d.z;
        let cc = c2 * (o.x * o.x + o.y * o.y) - s2 * o.z * o.z;
        if let Some((r1, r2)) = quadratic_roots(a, b, cc) {
            for t in [r1, r2] {
                if (o.z + d.z * t) * c >= T::ZERO {
                    add(t);
                }
            }
        }
    }
    let crossings = &mut crossings[..count];
    crossings.sort_by(|a, b| a.0.partial_cmp(&b.0).unwrap_or(std::cmp::Ordering::Equal));
    let far = polar(-d);
    Spans::from_toggles(p[0] <= far && far <= p[1], crossings)
}

/// Signed distance bound of a theta cone shell (exact sign).
pub fn thetacut_sdf<T: Real>(p: &[T; 6], x: V3<T>) -> T {
    let r = x.length();
    let theta = polar(x);
    let half_pi = T::HALF * T::PI;
    let mut sdf = -T::INFINITY;
    if p[0] > T::ZERO {
        sdf = sdf.max(r * (p[0] - theta).max(-half_pi).min(half_pi).sin());
    }
    if p[1] < T::PI {
        sdf = sdf.max(r * (theta - p[1]).max(-half_pi).min(half_pi).sin());
    }
    sdf
}
