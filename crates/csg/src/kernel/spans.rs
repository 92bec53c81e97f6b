//! Where a ray is inside a primitive: up to four sorted, disjoint parameter intervals, each
//! end with the surface normal there.
//!
//! Every primitive describes its intersection with a ray as such spans. Classifying
//! crossings from spans (a span's start is an entry, its end an exit) is exact even for
//! grazing rays, where the sign of `dot(normal, direction)` is not.

use crate::real::{Real, V3};

/// Most spans a primitive produces (a hollow torus: two tube passes minus two).
pub const MAX_SPANS: usize = 4;

/// One interval `[t0, t1]` of the ray inside a primitive; infinite ends have zero normals.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Span<T> {
    /// Entry parameter (may be -inf).
    pub t0: T,
    /// Surface normal at the entry (any orientation; oriented by the caller).
    pub n0: V3<T>,
    /// Exit parameter (may be +inf).
    pub t1: T,
    /// Surface normal at the exit.
    pub n1: V3<T>,
}

impl<T: Real> Span<T> {
    /// The whole line.
    pub fn everywhere() -> Self {
        Span {
            t0: -T::INFINITY,
            n0: V3::zero(),
            t1: T::INFINITY,
            n1: V3::zero(),
        }
    }

    /// `self` restricted to `other` (the later entry, the earlier exit), if not empty.
    pub fn clip(self, other: &Span<T>) -> Option<Span<T>> {
        let (t0, n0) = if other.t0 > self.t0 {
            (other.t0, other.n0)
        } else {
            (self.t0, self.n0)
        };
        let (t1, n1) = if other.t1 < self.t1 {
            (other.t1, other.n1)
        } else {
            (self.t1, self.n1)
        };
        (t0 <= t1).then_some(Span { t0, n0, t1, n1 })
    }
}

/// A sorted set of disjoint spans.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Spans<T> {
    len: usize,
    items: [Span<T>; MAX_SPANS],
}

impl<T: Real> Default for Spans<T> {
    fn default() -> Self {
        Spans {
            len: 0,
            items: [Span::everywhere(); MAX_SPANS],
        }
    }
}

impl<T: Real> Spans<T> {
    /// No spans: the ray is outside everywhere.
    pub fn empty() -> Self {
        Self::default()
    }

    /// A single span.
    pub fn one(span: Span<T>) -> Self {
        let mut s = Self::default();
        s.push(span);
        s
    }

    /// Appends a span that starts after the last one ends (capacity is [`MAX_SPANS`]).
    pub fn push(&mut self, span: Span<T>) {
        debug_assert!(self.len < MAX_SPANS);
        if self.len < MAX_SPANS {
            self.items[self.len] = span;
            self.len += 1;
        }
    }

    /// The spans in order.
    pub fn as_slice(&self) -> &[Span<T>] {
        &self.items[..self.len]
    }

    /// Every span restricted to `window`.
    pub fn clip(&self, window: &Span<T>) -> Self {
        let mut out = Self::default();
        for s in self.as_slice() {
            if let Some(c) = s.clip(window) {
                out.push(c);
            }
        }
        out
    }

    /// Every span restricted to `window`, or nothing when there is no window.
    pub fn clip_opt(&self, window: Option<Span<T>>) -> Self {
        match window {
            Some(w) => self.clip(&w),
            None => Self::empty(),
        }
    }

    /// The parts of `self` outside every span of `hole` (the hole's surfaces face the other
    /// way as boundaries of the result; orientation is left to the caller). A hole span of
    /// zero length (a ray tangent to the hole's surface) removes nothing: it would split a
    /// span into two that meet, whose shared end a tree would take for an exit (a ray
    /// touching the inner wall of a tube where it stops at the faces of a union).
    pub fn subtract(&self, hole: &Spans<T>) -> Self {
        let mut out = Self::default();
        for s in self.as_slice() {
            let mut rest = Some(*s);
            for h in hole.as_slice() {
                let Some(r) = rest else { break };
                if h.t1 <= h.t0 || h.t1 <= r.t0 || h.t0 >= r.t1 {
                    continue;
                }
                if h.t0 > r.t0 {
                    out.push(Span {
                        t0: r.t0,
                        n0: r.n0,
                        t1: h.t0,
                        n1: h.n0,
                    });
                }
                rest = (h.t1 < r.t1).then_some(Span {
                    t0: h.t1,
                    n0: h.n1,
                    t1: r.t1,
                    n1: r.n1,
                });
            }
            if let Some(r) = rest {
                out.push(r);
            }
        }
        out
    }

    /// Spans from sorted surface crossings of a region, given whether the ray is inside the
    /// region as `t -> -inf`: the inside state toggles at every crossing.
    pub fn from_toggles(mut inside: bool, crossings: &[(T, V3<T>)]) -> Self {
        let mut out = Self::default();
        let mut start = (-T::INFINITY, V3::zero());
        for &(t, n) in crossings {
            if inside {
                out.push(Span {
                    t0: start.0,
                    n0: start.1,
                    t1: t,
                    n1: n,
                });
            } else {
                start = (t, n);
            }
            inside = !inside;
        }
        if inside {
            out.push(Span {
                t0: start.0,
                n0: start.1,
                t1: T::INFINITY,
                n1: V3::zero(),
            });
        }
        out
    }
}

/// Real roots of `a t^2 + 2 b t + c`, ascending, computed without cancellation.
pub fn quadratic_roots<T: Real>(a: T, b: T, c: T) -> Option<(T, T)> {
    let disc = b * b - a * c;
    if disc < T::ZERO || !disc.is_finite() {
        return None;
    }
    let q = -(b + disc.sqrt().copysign(b));
    if q == T::ZERO {
        // b = 0 and a c = 0: a double root at 0 (c = 0) or no roots.
        return (c == T::ZERO).then_some((T::ZERO, T::ZERO));
    }
    let (r1, r2) = (q / a, c / q);
    if !r1.is_finite() {
        // a = 0: one root of the linear equation.
        return Some((r2, r2));
    }
    Some(if r1 <= r2 { (r1, r2) } else { (r2, r1) })
}

/// Spans where `a t^2 + 2 b t + c <= 0`, with `normal(t)` at finite ends.
pub fn quadric_spans<T: Real>(a: T, b: T, c: T, normal: impl Fn(T) -> V3<T>) -> Spans<T> {
    let bounded = |t0: T, t1: T| Span {
        t0,
        n0: if t0.is_finite() {
            normal(t0)
        } else {
            V3::zero()
        },
        t1,
        n1: if t1.is_finite() {
            normal(t1)
        } else {
            V3::zero()
        },
    };
    if a == T::ZERO {
        // Linear: 2 b t + c <= 0.
        if b == T::ZERO {
            return if c <= T::ZERO {
                Spans::one(Span::everywhere())
            } else {
                Spans::empty()
            };
        }
        let t = -c / (T::TWO * b);
        return Spans::one(if b > T::ZERO {
            bounded(-T::INFINITY, t)
        } else {
            bounded(t, T::INFINITY)
        });
    }
    match quadratic_roots(a, b, c) {
        None if a > T::ZERO => Spans::empty(),
        None => Spans::one(Span::everywhere()),
        Some((r1, r2)) if a > T::ZERO => Spans::one(bounded(r1, r2)),
        Some((r1, r2)) => {
            let mut s = Spans::one(bounded(-T::INFINITY, r1));
            s.push(bounded(r2, T::INFINITY));
            s
        }
    }
}

/// The span where `lo <= o + t d <= hi` along one axis (normals `-axis` at `lo`, `+axis` at
/// `hi`), the whole line when `d = 0` and `o` is between, or `None`.
pub fn slab_span<T: Real>(o: T, d: T, lo: T, hi: T, axis: V3<T>) -> Option<Span<T>> {
    if d == T::ZERO {
        return (lo <= o && o <= hi).then(Span::everywhere);
    }
    let (ta, tb) = ((lo - o) / d, (hi - o) / d);
    Some(if d > T::ZERO {
        Span {
            t0: ta,
            n0: -axis,
            t1: tb,
            n1: axis,
        }
    } else {
        Span {
            t0: tb,
            n0: axis,
            t1: ta,
            n1: -axis,
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn z() -> V3<f64> {
        V3::zero()
    }

    #[test]
    fn quadratic_roots_match_float64_expansion() {
        // (t - 1e-8)(t - 1e8): the textbook formula loses the small root entirely.
        let (r1, r2) = quadratic_roots(1.0, -0.5 * (1e8 + 1e-8), 1.0).unwrap();
        assert!((r1 - 1e-8).abs() < 1e-22, "{r1}");
        assert!((r2 - 1e8).abs() < 1e-6);
        assert_eq!(quadratic_roots(1.0, 0.0, 1.0), None);
        assert_eq!(quadratic_roots(0.0, 1.0, -4.0), Some((2.0, 2.0)));
    }

    #[test]
    fn subtract_splits_and_trims() {
        let s = Spans::one(Span {
            t0: 0.0,
            n0: z(),
            t1: 10.0,
            n1: z(),
        });
        let mut hole = Spans::one(Span {
            t0: 2.0,
            n0: z(),
            t1: 3.0,
            n1: z(),
        });
        hole.push(Span {
            t0: 9.0,
            n0: z(),
            t1: 12.0,
            n1: z(),
        });
        let r = s.subtract(&hole);
        let ends: Vec<_> = r.as_slice().iter().map(|s| (s.t0, s.t1)).collect();
        assert_eq!(ends, vec![(0.0, 2.0), (3.0, 9.0)]);
    }

    #[test]
    fn toggles_start_inside_or_outside() {
        let c = [(1.0, z()), (2.0, z())];
        let a: Vec<_> = Spans::from_toggles(false, &c)
            .as_slice()
            .iter()
            .map(|s| (s.t0, s.t1))
            .collect();
        assert_eq!(a, vec![(1.0, 2.0)]);
        let b: Vec<_> = Spans::from_toggles(true, &c)
            .as_slice()
            .iter()
            .map(|s| (s.t0, s.t1))
            .collect();
        assert_eq!(b, vec![(f64::NEG_INFINITY, 1.0), (2.0, f64::INFINITY)]);
    }
}
