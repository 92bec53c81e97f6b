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
///
/// The slab test axis by axis, keeping the face of the latest entry and of the earliest
/// exit (the first axis's on ties): the same comparisons, in the same order, as clipping
/// the whole line by each axis' [`slab_span`], with the two normals built once at the end.
pub fn box_spans<T: Real>(p: &[T; 6], o: V3<T>, d: V3<T>) -> Spans<T> {
    let mut ends = BoxEnds {
        t0: -T::INFINITY,
        t1: T::INFINITY,
        entry_face: NO_FACE,
        exit_face: NO_FACE,
    };
    let inside = ends.clip(0, p[0], o.x, d.x)
        && ends.clip(1, p[1], o.y, d.y)
        && ends.clip(2, p[2], o.z, d.z);
    if !inside {
        return Spans::empty();
    }
    Spans::one(Span {
        t0: ends.t0,
        n0: face_normal(ends.entry_face),
        t1: ends.t1,
        n1: face_normal(ends.exit_face),
    })
}

/// The part of the line inside the slabs clipped so far, and the faces of its ends.
struct BoxEnds<T> {
    t0: T,
    t1: T,
    entry_face: u32,
    exit_face: u32,
}

impl<T: Real> BoxEnds<T> {
    /// Clips by the slab of axis `k` (full width `size`; `o`, `d` the ray's components);
    /// false once nothing is left.
    #[inline(always)]
    fn clip(&mut self, k: u32, size: T, o: T, d: T) -> bool {
        let h = T::HALF * size;
        if d == T::ZERO {
            // Inside the slab everywhere or nowhere.
            return -h <= o && o <= h;
        }
        let (ta, tb) = ((-h - o) / d, (h - o) / d);
        // Rising along the axis, the ray enters through the -axis face and leaves through
        // the +axis face; falling, the other way round.
        let rising = d > T::ZERO;
        let (enter, leave) = if rising { (ta, tb) } else { (tb, ta) };
        let (enter_face, leave_face) = (2 * k + rising as u32, 2 * k + !rising as u32);
        if enter > self.t0 {
            (self.t0, self.entry_face) = (enter, enter_face);
        }
        if leave < self.t1 {
            (self.t1, self.exit_face) = (leave, leave_face);
        }
        self.t0 <= self.t1
    }
}

/// [`box_spans`]' face of an infinite end of the line.
const NO_FACE: u32 = 6;

/// The outward normal of box face `face` (`2 k`: the +axis `k` face, `2 k + 1`: the -axis
/// face), as [`slab_span`] writes it (the -axis face's zero components are -0); zero for
/// [`NO_FACE`]. Selects, not branches: which face ends a span is data, not a pattern.
#[inline(always)]
fn face_normal<T: Real>(face: u32) -> V3<T> {
    let negative = face % 2 == 1 && face < NO_FACE;
    let (one, zero) = if negative {
        (-T::ONE, -T::ZERO)
    } else {
        (T::ONE, T::ZERO)
    };
    let component = |k: u32| if face / 2 == k { one } else { zero };
    V3::new(component(0), component(1), component(2))
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_common::{Random, Rng};

    /// The box as its definition: the whole line clipped by each axis' slab in turn.
    fn clipped_by_slabs<T: Real>(p: &[T; 6], o: V3<T>, d: V3<T>) -> Spans<T> {
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

    /// The spans' ends and normals as bits (so that -0.0 and 0.0 differ).
    fn bits<T: Real>(s: &Spans<T>) -> Vec<[u64; 8]> {
        let b = |v: T| v.to_f64().to_bits();
        s.as_slice()
            .iter()
            .map(|s| {
                let [n0, n1] = [s.n0, s.n1].map(|n| [b(n.x), b(n.y), b(n.z)]);
                [b(s.t0), n0[0], n0[1], n0[2], b(s.t1), n1[0], n1[1], n1[2]]
            })
            .collect()
    }

    fn check<T: Real>(p: [f64; 3], o: [f64; 3], d: [f64; 3]) -> bool {
        let p = [p[0], p[1], p[2], 0.0, 0.0, 0.0].map(T::from_f64);
        let (o, d) = (V3::from_f64(o), V3::from_f64(d));
        let (fast, reference) = (box_spans(&p, o, d), clipped_by_slabs(&p, o, d));
        assert_eq!(bits(&fast), bits(&reference), "box {p:?} o {o:?} d {d:?}");
        !fast.as_slice().is_empty()
    }

    #[test]
    fn box_spans_equal_the_line_clipped_by_each_slab_bit_for_bit() {
        let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
        let mut met = 0;
        for i in 0..20_000 {
            let size = [0; 3].map(|_| rng.range(0.1, 20.0));
            // Near the box, far from the origin (the box's frame is then far too).
            let reach = if i % 4 == 0 { 1.0e6 } else { 15.0 };
            let mut o = [0; 3].map(|_| rng.range(-reach, reach));
            let mut d = rng.direction();
            match i % 5 {
                // Zero direction components: rays parallel to one or two face pairs.
                1 => d[i % 3] = 0.0,
                2 => {
                    d[i % 3] = 0.0;
                    d[(i + 1) % 3] = 0.0;
                }
                // Origins on a face plane, moving along it (grazing).
                3 => {
                    o[i % 3] = 0.5 * size[i % 3];
                    d[i % 3] = 0.0;
                }
                // Aimed at a corner, where entry or exit ties between axes.
                4 => {
                    let corner = [0, 1, 2].map(|k| 0.5 * size[k]);
                    let far = rng.range(5.0, 50.0);
                    o = [0, 1, 2].map(|k| corner[k] - far * d[k]);
                }
                _ => {}
            }
            met += check::<f32>(size, o, d) as usize;
            met += check::<f64>(size, o, d) as usize;
        }
        assert!(met > 5_000, "only {met} rays met their box");
        // Equal sides and a diagonal ray: entry and exit tie on all three axes.
        assert!(check::<f32>([2.0; 3], [-3.0; 3], [1.0; 3]));
        assert!(check::<f64>([2.0; 3], [3.0; 3], [-1.0; 3]));
        // A subnormal component (f32): the slab's parameters overflow to infinities.
        check::<f32>([2.0; 3], [0.5, 0.0, -3.0], [1.0e-40, 0.0, 1.0]);
        check::<f32>([2.0; 3], [5.0, 0.0, -3.0], [-1.0e-40, 0.0, 1.0]);
    }
}
