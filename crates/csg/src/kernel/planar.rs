//! Primitives bounded by planes: box, convex polyhedron, half-space and slab.

use super::spans::{slab_span, Span, Spans};
use crate::real::{Real, V3};

/// The span of the ray on the inner side (`dot(n, x) <= dist`) of one plane.
fn plane_span<T: Real>(o: V3<T>, d: V3<T>, n: V3<T>, dist: T) -> Option<Span<T>> {
    let (on, dn) = (n.dot(o), n.dot(d));
    if dn == T::ZERO {
        return (on <= dist).then(Span::everywhere);
    }
    let t = (dist - on) / dn;
    Some(if dn > T::ZERO {
        Span {
            t0: -T::INFINITY,
            n0: V3::zero(),
            t1: t,
            n1: n,
        }
    } else {
        Span {
            t0: t,
            n0: n,
            t1: T::INFINITY,
            n1: V3::zero(),
        }
    })
}

/// Box `[sx, sy, sz]` (full side lengths) centred on the origin.
pub fn box_spans<T: Real>(p: &[T; 6], o: V3<T>, d: V3<T>) -> Spans<T> {
    let mut span = Span::everywhere();
    for (k, &size) in p[..3].iter().enumerate() {
        let h = T::HALF * size;
        let mut axis = V3::zero();
        match k {
            0 => axis.x = T::ONE,
            1 => axis.y = T::ONE,
            _ => axis.z = T::ONE,
        }
        match slab_span(o.get(k), d.get(k), -h, h, axis).and_then(|s| span.clip(&s)) {
            Some(s) => span = s,
            None => return Spans::empty(),
        }
    }
    Spans::one(span)
}

/// Signed distance to a box (exact).
pub fn box_sdf<T: Real>(p: &[T; 6], x: V3<T>) -> T {
    let q = V3::new(
        x.x.abs() - T::HALF * p[0],
        x.y.abs() - T::HALF * p[1],
        x.z.abs() - T::HALF * p[2],
    );
    let outside = V3::new(q.x.max(T::ZERO), q.y.max(T::ZERO), q.z.max(T::ZERO)).length();
    q.x.max(q.y).max(q.z).min(T::ZERO) + outside
}

/// Convex polyhedron: the intersection of the inner sides of `planes` (`[nx, ny, nz, d]`).
pub fn polyhedron_spans<T: Real>(planes: &[[T; 4]], o: V3<T>, d: V3<T>) -> Spans<T> {
    let mut span = Span::everywhere();
    for pl in planes {
        let n = V3::new(pl[0], pl[1], pl[2]);
        match plane_span(o, d, n, pl[3]).and_then(|s| span.clip(&s)) {
            Some(s) => span = s,
            None => return Spans::empty(),
        }
    }
    Spans::one(span)
}

/// Signed distance bound of a convex polyhedron (the largest plane distance; exact sign).
pub fn polyhedron_sdf<T: Real>(planes: &[[T; 4]], x: V3<T>) -> T {
    planes
        .iter()
        .map(|pl| V3::new(pl[0], pl[1], pl[2]).dot(x) - pl[3])
        .fold(-T::INFINITY, T::max)
}

/// Half-space `[nx, ny, nz, d]`: `dot(n, x) <= d`.
pub fn halfspace_spans<T: Real>(p: &[T; 6], o: V3<T>, d: V3<T>) -> Spans<T> {
    let n = V3::new(p[0], p[1], p[2]);
    plane_span(o, d, n, p[3]).map_or(Spans::empty(), Spans::one)
}

/// Signed distance to a half-space (exact).
pub fn halfspace_sdf<T: Real>(p: &[T; 6], x: V3<T>) -> T {
    V3::new(p[0], p[1], p[2]).dot(x) - p[3]
}

/// Slab `[nx, ny, nz, -]`, `[a, b]`: `a <= dot(n, x) <= b`.
pub fn slab_spans<T: Real>(p: &[T; 6], o: V3<T>, d: V3<T>) -> Spans<T> {
    let n = V3::new(p[0], p[1], p[2]);
    slab_span(n.dot(o), n.dot(d), p[4], p[5], n).map_or(Spans::empty(), Spans::one)
}

/// Signed distance to a slab (exact).
pub fn slab_sdf<T: Real>(p: &[T; 6], x: V3<T>) -> T {
    let s = V3::new(p[0], p[1], p[2]).dot(x);
    (p[4] - s).max(s - p[5])
}
