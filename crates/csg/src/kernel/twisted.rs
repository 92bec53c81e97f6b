//! The twisted half-space `[nx, ny, nz, d, w, h]`: the points of the slab `|z| <= h` that,
//! turned back about the z axis by the angle `w z`, lie in the half-space `n . q <= d`
//! (unit `n`). With `m(z) = R(w z) (nx, ny)` (the in-plane normal turned with the height),
//!
//! ```text
//! f(x, y, z) = m(z) . (x, y) + nz z - d <= 0.
//! ```
//!
//! Its surface is the plane `n . q = d` twisted about z at the rate `w`: a lateral face of
//! G4TwistedBox, G4TwistedTrd and G4TwistedTrap, whose untwisted faces Geant4 requires to be
//! planar.
//!
//! # Crossings
//!
//! Along a ray `p(t) = o + t u` the angle `w z(t)` is linear in `t` with rate
//! `omega = w u_z`, so `f(t) = m(t) . q(t) + nz z(t) - d` mixes a sine and a cosine of `t`
//! with linear coefficients. Within the slab interval of the ray the kernel bounds
//! `|f''| <= |n_xy| (omega^2 max|q| + 2 |omega| |u_xy|) = M` (`|q|` is largest at an end of
//! the interval, being convex), and isolates the crossings by bisecting the interval:
//!
//! * a piece whose ends have the same sign and `min(|f_a|, |f_b|) > M L^2 / 8` has no
//!   crossing (the function stays within `M L^2 / 8` of its chord);
//! * a piece where `|f'(mid)| > M L / 2` is monotonic: one crossing if the ends' signs
//!   differ (found by Newton's method kept inside the bracket, bisecting when a step leaves
//!   it), none otherwise;
//! * other pieces are halved, down to 2^-40 of the interval or until the midpoint rounds
//!   onto an end (a tangency within rounding: a crossing if the ends' signs differ).
//!
//! Crossings are found in increasing order and alternate, so the spans follow from the sign
//! at the start of the interval. A ray in a plane `z = c` sees a fixed angle: `f` is linear
//! in `t`, one crossing solved directly. The rays are moved to their closest approach to
//! the frame's origin first and the caps met from the unmoved origin, as for the capped
//! quadrics.
//!
//! The CPU solves in f64 for either precision (the answers rounded to it): in f32 the
//! cancellation of `m . q` against `d` near the face leaves an ulp of the solid's size,
//! which a crossing at a grazing angle turns into more than the oracle's tolerance. The
//! WGSL twin, `shaders/csg/twisted.wgsl`, takes the same steps in f32 with a fixed-size
//! stack; its CPU twin is [`twisted_spans_in`] in f32.

use super::spans::{slab_span, Span, Spans, MAX_SPANS};
use crate::real::{Real, V3};

/// Deepest bisection of the slab interval (pieces of 2^-40 of it: below f32's and at
/// f64's rounding of `t` for intervals of the solid's size).
const MAX_DEPTH: usize = 40;

/// Newton steps per crossing (quadratic convergence; bisection when a step leaves the
/// bracket): never reached in practice.
const MAX_NEWTON: usize = 60;

/// Pieces examined per ray: a bound the bisection stays far below (a handful of crossings,
/// each isolated within a few levels).
const MAX_PIECES: usize = 256;

/// The function, its in-plane normal and its derivative along the ray at `t`.
#[derive(Clone, Copy)]
struct Face<T> {
    /// In-plane normal `(nx, ny)`.
    n: [T; 2],
    nz: T,
    d: T,
    w: T,
    o: V3<T>,
    u: V3<T>,
}

impl<T: Real> Face<T> {
    fn new(p: &[T; 6], o: V3<T>, u: V3<T>) -> Self {
        Face {
            n: [p[0], p[1]],
            nz: p[2],
            d: p[3],
            w: p[4],
            o,
            u,
        }
    }

    /// `m(z) = R(w z) (nx, ny)`.
    fn turned(&self, z: T) -> [T; 2] {
        let a = self.w * z;
        let (c, s) = (a.cos(), a.sin());
        [c * self.n[0] - s * self.n[1], s * self.n[0] + c * self.n[1]]
    }

    /// `f(t)`.
    fn value(&self, t: T) -> T {
        let q = self.o.at(self.u, t);
        let m = self.turned(q.z);
        m[0] * q.x + m[1] * q.y + self.nz * q.z - self.d
    }

    /// `f'(t) = omega m_perp . q + m . u_xy + nz u_z`, `m_perp = (-m_y, m_x)`.
    fn slope(&self, t: T) -> T {
        let q = self.o.at(self.u, t);
        let m = self.turned(q.z);
        let omega = self.w * self.u.z;
        omega * (m[0] * q.y - m[1] * q.x) + m[0] * self.u.x + m[1] * self.u.y + self.nz * self.u.z
    }

    /// The gradient of `f` at `t`: `(m, nz + w m_perp . q)`.
    fn gradient(&self, t: T) -> V3<T> {
        let q = self.o.at(self.u, t);
        let m = self.turned(q.z);
        V3::new(m[0], m[1], self.nz + self.w * (m[0] * q.y - m[1] * q.x))
    }

    /// The crossing in `[a, b]`, where `f` is monotonic and `f(a)`, `f(b)` have opposite
    /// signs (`fa` is `f(a)`).
    fn crossing(&self, mut a: T, mut b: T, fa: T) -> T {
        let inside_a = fa <= T::ZERO;
        let mut t = (a + b) * T::HALF;
        for _ in 0..MAX_NEWTON {
            let f = self.value(t);
            if f == T::ZERO {
                return t;
            }
            if (f <= T::ZERO) == inside_a {
                a = t;
            } else {
                b = t;
            }
            let step = t - f / self.slope(t);
            let next = if step > a && step < b {
                step
            } else {
                (a + b) * T::HALF
            };
            if next == t || b <= a {
                break;
            }
            t = next;
        }
        t
    }
}

/// A piece of the slab interval with the function's values at its ends.
#[derive(Clone, Copy)]
struct Piece<T> {
    a: T,
    fa: T,
    b: T,
    fb: T,
    depth: usize,
}

/// The crossings of `f` in `[a, b]`, ascending, into `out`; returns how many.
fn crossings<T: Real>(face: &Face<T>, a: T, b: T, out: &mut [T; MAX_SPANS]) -> usize {
    let (qa, qb) = (face.o.at(face.u, a), face.o.at(face.u, b));
    let q_max = (qa.x * qa.x + qa.y * qa.y)
        .max(qb.x * qb.x + qb.y * qb.y)
        .sqrt();
    let omega = (face.w * face.u.z).abs();
    let n_xy = (face.n[0] * face.n[0] + face.n[1] * face.n[1]).sqrt();
    let u_xy = (face.u.x * face.u.x + face.u.y * face.u.y).sqrt();
    let bound = n_xy * (omega * omega * q_max + T::TWO * omega * u_xy);
    let mut stack = [Piece {
        a,
        fa: T::ZERO,
        b,
        fb: T::ZERO,
        depth: 0,
    }; MAX_DEPTH + 1];
    stack[0].fa = face.value(a);
    stack[0].fb = face.value(b);
    let (mut len, mut count) = (1usize, 0usize);
    let mut pieces = 0;
    while len > 0 && pieces < MAX_PIECES && count < MAX_SPANS {
        len -= 1;
        pieces += 1;
        let s = stack[len];
        let length = s.b - s.a;
        let differ = (s.fa <= T::ZERO) != (s.fb <= T::ZERO);
        let eighth = bound * length * length * T::HALF * T::HALF * T::HALF;
        if !differ && s.fa.abs().min(s.fb.abs()) > eighth {
            continue;
        }
        let mid = (s.a + s.b) * T::HALF;
        let monotonic = face.slope(mid).abs() > bound * length * T::HALF;
        if monotonic || s.depth >= MAX_DEPTH || mid <= s.a || mid >= s.b {
            if differ {
                out[count] = if monotonic {
                    face.crossing(s.a, s.b, s.fa)
                } else {
                    mid
                };
                count += 1;
            }
            continue;
        }
        let fm = face.value(mid);
        // The right half below the left one: the left is examined first.
        stack[len] = Piece {
            a: mid,
            fa: fm,
            b: s.b,
            fb: s.fb,
            depth: s.depth + 1,
        };
        stack[len + 1] = Piece {
            a: s.a,
            fa: s.fa,
            b: mid,
            fb: fm,
            depth: s.depth + 1,
        };
        len += 2;
    }
    count
}

/// Twisted half-space `[nx, ny, nz, d, w, h]` (see the module's description), the ray
/// given by its unmoved origin `start`, and the move `shift` along it (see
/// [`super::origin_shift`]); parameters from the moved origin. Solved in f64 whatever `T`
/// (twisted solids are rare, and the turned normal's rounding in f32 moves a grazing
/// crossing by more than the tolerance); the answers are rounded to `T`.
pub fn twisted_spans<T: Real>(p: &[T; 6], start: V3<T>, u: V3<T>, shift: T) -> Spans<T> {
    let v3 = |v: V3<T>| V3::<f64>::from_f64(v.to_f64());
    let spans = twisted_spans_in::<f64>(&p.map(T::to_f64), v3(start), v3(u), shift.to_f64());
    let back = |v: V3<f64>| V3::<T>::from_f64(v.to_f64());
    let mut out = Spans::empty();
    for s in spans.as_slice() {
        out.push(Span {
            t0: T::from_f64(s.t0),
            n0: back(s.n0),
            t1: T::from_f64(s.t1),
            n1: back(s.n1),
        });
    }
    out
}

/// The spans of a twisted half-space (see the module's description) solved in `T`
/// throughout: the steps the WGSL twin takes in f32 (the GPU parity test compares them item
/// by item), and the CPU's solver in f64 for either precision
/// ([`super::primitive_spans`] rounds its answers).
pub fn twisted_spans_in<T: Real>(p: &[T; 6], start: V3<T>, u: V3<T>, shift: T) -> Spans<T> {
    let z_axis = V3::new(T::ZERO, T::ZERO, T::ONE);
    let Some(slab) = slab_span(start.z, u.z, -p[5], p[5], z_axis) else {
        return Spans::empty();
    };
    let slab = Span {
        t0: slab.t0 - shift,
        t1: slab.t1 - shift,
        ..slab
    };
    let face = Face::new(p, start.at(u, shift), u);
    if u.z == T::ZERO {
        // A fixed angle: f(t) = f(0) + f'(0) t.
        let (c, slope) = (face.value(T::ZERO), face.slope(T::ZERO));
        let walls = super::spans::quadric_spans(T::ZERO, slope * T::HALF, c, |t| face.gradient(t));
        return walls.clip(&slab);
    }
    let mut roots = [T::ZERO; MAX_SPANS];
    let count = crossings(&face, slab.t0, slab.t1, &mut roots);
    let mut toggles = [(T::ZERO, V3::zero()); MAX_SPANS];
    for (c, &t) in toggles.iter_mut().zip(&roots[..count]) {
        *c = (t, face.gradient(t));
    }
    let inside = face.value(slab.t0) <= T::ZERO;
    Spans::from_toggles(inside, &toggles[..count]).clip(&slab)
}

/// Signed distance bound of a twisted half-space (first-order estimate of the face; exact
/// sign).
pub fn twisted_sdf<T: Real>(p: &[T; 6], x: V3<T>) -> T {
    let face = Face::new(p, x, V3::zero());
    let g = face.gradient(T::ZERO).length();
    (face.value(T::ZERO) / g).max(x.z.abs() - p[5])
}
