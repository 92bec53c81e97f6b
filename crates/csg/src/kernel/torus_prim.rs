//! The torus primitive `[rmin, rmax, rtor]`: a tube of radius `rmax` (hollow inside `rmin`)
//! swept around z at radius `rtor`. Its spans and signed distance are built on the tube
//! crossings of [`super::torus`] (a convexity-split Newton search on the squared distance
//! to the core circle: no quartic is solved, see there why).

use super::spans::Spans;
use super::torus::{torus_crossings, torus_normal, torus_sdf};
use crate::real::{Real, V3};

/// Spans of the ray inside the tube of radius `r`.
fn tube_spans<T: Real>(o: V3<T>, d: V3<T>, r: T, rtor: T) -> Spans<T> {
    let mut roots = [T::ZERO; 4];
    let count = torus_crossings(o, d, r, rtor, &mut roots);
    let mut crossings = [(T::ZERO, V3::zero()); 4];
    for (c, &t) in crossings.iter_mut().zip(&roots[..count]) {
        *c = (t, torus_normal(o.at(d, t), rtor));
    }
    Spans::from_toggles(false, &crossings[..count])
}

/// Spans of a ray inside a torus `[rmin, rmax, rtor]`.
pub fn torus_spans<T: Real>(p: &[T; 6], o: V3<T>, d: V3<T>) -> Spans<T> {
    let outer = tube_spans(o, d, p[1], p[2]);
    if p[0] > T::ZERO {
        outer.subtract(&tube_spans(o, d, p[0], p[2]))
    } else {
        outer
    }
}

/// Signed distance to a torus (exact).
pub fn torus_prim_sdf<T: Real>(p: &[T; 6], x: V3<T>) -> T {
    let outer = torus_sdf(x, p[1], p[2]);
    if p[0] > T::ZERO {
        outer.max(-torus_sdf(x, p[0], p[2]))
    } else {
        outer
    }
}
