//! Primitives bounded by quadrics of revolution around z, capped by z planes: sphere, z-cut
//! sphere, cylinder, tube (annular cylinder), cone frustum, hyperboloid, paraboloid; and the
//! uncapped half-space below a hyperbolic paraboloid (the saddle).
//!
//! Each primitive gives the spans of a ray inside it (see [`super::spans`]) and a signed
//! distance. Quadrics are written `a t^2 + 2 b t + c` in the ray parameter. The capped
//! ones take the ray's origin in their frame and the move along the ray that
//! [`super::origin_shift`] chose: their walls are solved from the moved origin, their z
//! caps from the origin itself (see `z_slab`), both as parameters from the moved origin.

use super::spans::{quadric_spans, slab_span, Span, Spans};
use crate::real::{Real, V3};

fn z_axis<T: Real>() -> V3<T> {
    V3::new(T::ZERO, T::ZERO, T::ONE)
}

/// The span between the planes `z = lo` and `z = hi` of the ray `o + t d`, in parameters
/// from `o + shift d`. The caps are met from the unmoved origin: every leaf of a tree in one
/// frame then meets a z plane they share at the same parameter to the last bit (from a
/// moved origin, the move's rounding, a few ulps of the frame's coordinates over the
/// cosine, split a polycone's internal faces into gaps longer than the tolerance).
fn z_slab<T: Real>(o: V3<T>, d: V3<T>, shift: T, lo: T, hi: T) -> Option<Span<T>> {
    slab_span(o.z, d.z, lo, hi, z_axis()).map(|s| Span {
        t0: s.t0 - shift,
        t1: s.t1 - shift,
        ..s
    })
}

/// Signed distance of a capped solid of revolution from its radial distance `dr` (negative
/// inside the side wall) and the z range: exact when `dr` is an exact distance.
fn capped<T: Real>(dr: T, z: T, z1: T, z2: T) -> T {
    let dz = (z1 - z).max(z - z2);
    let outside = V3::new(dr.max(T::ZERO), dz.max(T::ZERO), T::ZERO).length();
    dr.max(dz).min(T::ZERO) + outside
}

/// Spans of an infinite cylinder of `radius` around the z axis through `(cx, cy)`.
fn cylinder_wall<T: Real>(o: V3<T>, d: V3<T>, cx: T, cy: T, radius: T) -> Spans<T> {
    let (ox, oy) = (o.x - cx, o.y - cy);
    let a = d.x * d.x + d.y * d.y;
    let b = ox * d.x + oy * d.y;
    let c = ox * ox + oy * oy - radius * radius;
    quadric_spans(a, b, c, |t| V3::new(ox + d.x * t, oy + d.y * t, T::ZERO))
}

/// Sphere `[cx, cy, cz, r]`.
pub fn sphere_spans<T: Real>(p: &[T; 6], o: V3<T>, d: V3<T>) -> Spans<T> {
    let oc = o - V3::new(p[0], p[1], p[2]);
    let c = oc.length_squared() - p[3] * p[3];
    quadric_spans(d.length_squared(), oc.dot(d), c, |t| oc.at(d, t))
}

/// Signed distance to a sphere (exact).
pub fn sphere_sdf<T: Real>(p: &[T; 6], x: V3<T>) -> T {
    (x - V3::new(p[0], p[1], p[2])).length() - p[3]
}

/// Z-cut sphere `[cx, cy, cz, r]`, `[z1, z2]` relative to the centre.
pub fn zsphere_spans<T: Real>(p: &[T; 6], o: V3<T>, d: V3<T>, shift: T) -> Spans<T> {
    let (start, o) = (o, o.at(d, shift));
    let slab = z_slab(start, d, shift, p[2] + p[4], p[2] + p[5]);
    sphere_spans(p, o, d).clip_opt(slab)
}

/// Signed distance bound of a z-cut sphere (exact sign).
pub fn zsphere_sdf<T: Real>(p: &[T; 6], x: V3<T>) -> T {
    let z = x.z - p[2];
    sphere_sdf(p, x).max(p[4] - z).max(z - p[5])
}

/// Cylinder `[cx, cy, -, r]`, `[z1, z2]`.
pub fn cylinder_spans<T: Real>(p: &[T; 6], o: V3<T>, d: V3<T>, shift: T) -> Spans<T> {
    let (start, o) = (o, o.at(d, shift));
    cylinder_wall(o, d, p[0], p[1], p[3]).clip_opt(z_slab(start, d, shift, p[4], p[5]))
}

/// Signed distance to a cylinder (exact).
pub fn cylinder_sdf<T: Real>(p: &[T; 6], x: V3<T>) -> T {
    let rho = V3::new(x.x - p[0], x.y - p[1], T::ZERO).length();
    capped(rho - p[3], x.z, p[4], p[5])
}

/// Tube (annular cylinder) `[cx, cy, rin, r]`, `[z1, z2]`; `rin = 0` is a cylinder.
pub fn tube_spans<T: Real>(p: &[T; 6], o: V3<T>, d: V3<T>, shift: T) -> Spans<T> {
    let (start, o) = (o, o.at(d, shift));
    let outer = cylinder_wall(o, d, p[0], p[1], p[3]);
    let walls = if p[2] > T::ZERO {
        outer.subtract(&cylinder_wall(o, d, p[0], p[1], p[2]))
    } else {
        outer
    };
    walls.clip_opt(z_slab(start, d, shift, p[4], p[5]))
}

/// Signed distance to a tube (exact).
pub fn tube_sdf<T: Real>(p: &[T; 6], x: V3<T>) -> T {
    let rho = V3::new(x.x - p[0], x.y - p[1], T::ZERO).length();
    capped((rho - p[3]).max(p[2] - rho), x.z, p[4], p[5])
}

/// Cone frustum `[r1, z1, r2, z2]`: radius `r1` at `z1`, `r2` at `z2`.
pub fn cone_spans<T: Real>(p: &[T; 6], o: V3<T>, d: V3<T>, shift: T) -> Spans<T> {
    let (start, o) = (o, o.at(d, shift));
    let [r1, z1, r2, z2] = [p[0], p[1], p[2], p[3]];
    let k = (r2 - r1) / (z2 - z1);
    let r_at = |z: T| r1 + k * (z - z1);
    let ro = r_at(o.z);
    let a = d.x * d.x + d.y * d.y - k * k * d.z * d.z;
    let b = o.x * d.x + o.y * d.y - k * d.z * ro;
    let c = o.x * o.x + o.y * o.y - ro * ro;
    // Gradient of x^2 + y^2 - r(z)^2 (halved).
    let wall = quadric_spans(a, b, c, |t| {
        let q = o.at(d, t);
        V3::new(q.x, q.y, -k * r_at(q.z))
    });
    wall.clip_opt(z_slab(start, d, shift, z1, z2))
}

/// Signed distance bound of a cone frustum: the distance to the side line in the meridian
/// plane and to the caps (exact sign).
pub fn cone_sdf<T: Real>(p: &[T; 6], x: V3<T>) -> T {
    let [r1, z1, r2, z2] = [p[0], p[1], p[2], p[3]];
    let rho = V3::new(x.x, x.y, T::ZERO).length();
    let (ez, er) = (z2 - z1, r2 - r1);
    let side = ((rho - r1) * ez - (x.z - z1) * er) / (ez * ez + er * er).sqrt();
    side.max(z1 - x.z).max(x.z - z2)
}

/// One-sheet hyperboloid `[r0, tan(stereo), z1, z2]`: `x^2 + y^2 = r0^2 + tan^2 z^2`.
pub fn hyperboloid_spans<T: Real>(p: &[T; 6], o: V3<T>, d: V3<T>, shift: T) -> Spans<T> {
    let (start, o) = (o, o.at(d, shift));
    let (r0, s2) = (p[0], p[1] * p[1]);
    let a = d.x * d.x + d.y * d.y - s2 * d.z * d.z;
    let b = o.x * d.x + o.y * d.y - s2 * o.z * d.z;
    let c = o.x * o.x + o.y * o.y - r0 * r0 - s2 * o.z * o.z;
    let wall = quadric_spans(a, b, c, |t| {
        let q = o.at(d, t);
        V3::new(q.x, q.y, -s2 * q.z)
    });
    wall.clip_opt(z_slab(start, d, shift, p[2], p[3]))
}

/// Signed distance bound of a hyperboloid (first-order estimate; exact sign).
pub fn hyperboloid_sdf<T: Real>(p: &[T; 6], x: V3<T>) -> T {
    let (r0, s2) = (p[0], p[1] * p[1]);
    let rho2 = x.x * x.x + x.y * x.y;
    let f = rho2 - r0 * r0 - s2 * x.z * x.z;
    let grad = T::TWO * (rho2 + s2 * s2 * x.z * x.z).sqrt();
    let wall = if grad > T::ZERO { f / grad } else { -r0 };
    wall.max(p[2] - x.z).max(x.z - p[3])
}

/// Paraboloid `[rlo, rhi, dz]`: `x^2 + y^2 = k1 z + k2` through radius `rlo` at `z = -dz`
/// and `rhi` at `z = +dz`, capped there.
pub fn paraboloid_spans<T: Real>(p: &[T; 6], o: V3<T>, d: V3<T>, shift: T) -> Spans<T> {
    let (start, o) = (o, o.at(d, shift));
    let (k1, k2) = paraboloid_coefficients(p);
    let a = d.x * d.x + d.y * d.y;
    let b = o.x * d.x + o.y * d.y - T::HALF * k1 * d.z;
    let c = o.x * o.x + o.y * o.y - k1 * o.z - k2;
    let wall = quadric_spans(a, b, c, |t| {
        let q = o.at(d, t);
        V3::new(q.x, q.y, -T::HALF * k1)
    });
    wall.clip_opt(z_slab(start, d, shift, -p[2], p[2]))
}

fn paraboloid_coefficients<T: Real>(p: &[T; 6]) -> (T, T) {
    let (lo2, hi2) = (p[0] * p[0], p[1] * p[1]);
    ((hi2 - lo2) / (T::TWO * p[2]), T::HALF * (hi2 + lo2))
}

/// Signed distance bound of a paraboloid (first-order estimate; exact sign).
pub fn paraboloid_sdf<T: Real>(p: &[T; 6], x: V3<T>) -> T {
    let (k1, k2) = paraboloid_coefficients(p);
    let rho2 = x.x * x.x + x.y * x.y;
    let f = rho2 - k1 * x.z - k2;
    let grad = (T::TWO * T::TWO * rho2 + k1 * k1).sqrt();
    let wall = if grad > T::ZERO { f / grad } else { f };
    wall.max(-p[2] - x.z).max(x.z - p[2])
}

/// Saddle `[kappa]`: the half-space `y - kappa x z <= 0`. Along the ray the function is the
/// quadratic `-kappa dx dz t^2 + (dy - kappa (ox dz + oz dx)) t + oy - kappa ox oz`, whose
/// leading coefficient vanishes for rays in a plane `x = c` or `z = c` (one crossing then).
pub fn saddle_spans<T: Real>(p: &[T; 6], o: V3<T>, d: V3<T>) -> Spans<T> {
    let k = p[0];
    let a = -k * d.x * d.z;
    let b = T::HALF * (d.y - k * (o.x * d.z + o.z * d.x));
    let c = o.y - k * o.x * o.z;
    quadric_spans(a, b, c, |t| saddle_gradient(k, o.at(d, t)))
}

/// The gradient of `y - kappa x z` at `x` (never zero: its y component is 1).
fn saddle_gradient<T: Real>(k: T, x: V3<T>) -> V3<T> {
    V3::new(-k * x.z, T::ONE, -k * x.x)
}

/// Signed distance bound of a saddle (first-order estimate; exact sign).
pub fn saddle_sdf<T: Real>(p: &[T; 6], x: V3<T>) -> T {
    let k = p[0];
    (x.y - k * x.x * x.z) / saddle_gradient(k, x).length()
}
