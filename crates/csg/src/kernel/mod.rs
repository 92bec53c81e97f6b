//! Primitive kernels, generic over f32 and f64: the spans of a ray inside each primitive,
//! signed distances, and the first surface crossing of a (possibly complemented,
//! transformed) leaf after a given ray parameter.

mod cuts;
mod planar;
mod quadric;
pub mod spans;
pub mod torus;
mod torus_prim;
mod twisted;

use hytrace_foundry::{Transform64, TypeCode};
pub use twisted::twisted_spans_in;

use crate::real::{Ray, Real, V3};
use spans::Spans;

/// An affine frame: maps points of a parent frame into a node's own frame as
/// `inverse * (p - origin)`. Subtracting the origin first keeps f32 exact for solids placed
/// far from the world origin when rays start near them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frame<T> {
    /// Rows of the inverse of the linear part.
    inverse: [V3<T>; 3],
    /// Where the frame's origin lies in the parent frame.
    origin: V3<T>,
}

impl<T: Real> Frame<T> {
    /// The frame of a local-to-parent transform, inverted in f64; `None` if singular.
    pub fn from_transform(t: &Transform64) -> Option<Self> {
        let inv = t.inverse()?;
        let row = |k: usize| V3::from_f64([inv.rows[k][0], inv.rows[k][1], inv.rows[k][2]]);
        Some(Frame {
            inverse: [row(0), row(1), row(2)],
            origin: V3::from_f64([t.rows[0][3], t.rows[1][3], t.rows[2][3]]),
        })
    }

    /// The frame packed as the GPU reads it: row `k` is `(inverse[k], origin[k])`.
    pub fn rows(&self) -> [[T; 4]; 3] {
        std::array::from_fn(|k| {
            let r = self.inverse[k];
            [r.x, r.y, r.z, self.origin.get(k)]
        })
    }

    /// Whether the frame's axes are the parent's up to order, sign and scale, within 1e-6
    /// (each row of the inverse has one entry above 1e-6 of its largest: rotations by right
    /// angles built from sines and cosines leave entries of about 1e-16): a box placed by
    /// it has a parent-frame box as tight as itself.
    pub fn is_axis_aligned(&self) -> bool {
        self.inverse.iter().all(|r| {
            let c = [r.x, r.y, r.z].map(|c| c.abs());
            let largest = c[0].max(c[1]).max(c[2]);
            c.iter()
                .filter(|&&c| c > T::from_f64(1e-6) * largest)
                .count()
                == 1
        })
    }

    /// Whether the frame keeps distances (a rotation or reflection, rows of its inverse
    /// orthonormal within 1e-6): signed distances in it are distances in the parent.
    pub fn is_rigid(&self) -> bool {
        let tol = T::from_f64(1e-6);
        let r = &self.inverse;
        (0..3).all(|i| {
            (0..3).all(|j| {
                let want = if i == j { T::ONE } else { T::ZERO };
                (r[i].dot(r[j]) - want).abs() <= tol
            })
        })
    }

    /// Where the frame's origin lies in the parent frame.
    pub fn origin(&self) -> V3<T> {
        self.origin
    }

    /// A parent-frame offset (a vector: no origin subtracted) in this frame.
    pub fn linear(&self, v: V3<T>) -> V3<T> {
        V3::new(
            self.inverse[0].dot(v),
            self.inverse[1].dot(v),
            self.inverse[2].dot(v),
        )
    }

    /// A parent-frame point in this frame.
    pub fn point_to_local(&self, p: V3<T>) -> V3<T> {
        self.linear(p - self.origin)
    }

    /// A parent-frame ray in this frame (same parameter `t` along both).
    pub fn ray_to_local(&self, ray: &Ray<T>) -> Ray<T> {
        Ray {
            origin: self.point_to_local(ray.origin),
            direction: self.linear(ray.direction),
        }
    }

    /// A normal of this frame in the parent frame (inverse transpose; not normalized).
    pub fn normal_to_parent(&self, n: V3<T>) -> V3<T> {
        self.inverse[0] * n.x + self.inverse[1] * n.y + self.inverse[2] * n.z
    }
}

/// A primitive node ready to be intersected: typecode, parameters, planes, frame and
/// complement flag.
#[derive(Clone, Debug, PartialEq)]
pub struct Leaf<T> {
    /// Which primitive.
    pub code: TypeCode,
    /// Parameters (`param` then `param_ext`, see [`TypeCode`]).
    pub params: [T; 6],
    /// Convex polyhedra: the range of the tree's plane list.
    pub planes: std::ops::Range<usize>,
    /// The node's frame, if it has a transform.
    pub frame: Option<Frame<T>>,
    /// Whether the leaf is complemented (inside-out).
    pub complement: bool,
}

/// Whether a primitive encloses a bounded region (cuts and half-spaces do not).
pub fn is_bounded(code: TypeCode) -> bool {
    !matches!(
        code,
        TypeCode::HalfSpace
            | TypeCode::Slab
            | TypeCode::PhiCut
            | TypeCode::ThetaCut
            | TypeCode::Saddle
            | TypeCode::TwistedHalfSpace
    )
}

/// How far along itself a ray from `o` along `d` (in the primitive's frame) is moved
/// before the primitive's spans are solved: to its closest approach to the primitive's
/// [`centre`], so that its quadric has coefficients of the primitive's size however far
/// away the ray starts (0 where that is not finite: a zero direction). The walls of
/// cylinders and tubes do not depend on z: a ray starting beside the wall (within the z
/// range, within twice the radius of the axis) is not moved, and others are moved to their
/// closest approach to the axis when that is no farther along the ray than the start is
/// from the centre. A move toward the centre would carry a start beside a long thin tube
/// far across its axis (a ray from inside a 1 m optical fibre of radius 0.18 mm was solved
/// with coordinates of hundreds of mm).
pub fn origin_shift<T: Real>(code: TypeCode, p: &[T; 6], o: V3<T>, d: V3<T>) -> T {
    if matches!(code, TypeCode::Cylinder | TypeCode::Disc) {
        let (x, y) = (o.x - p[0], o.y - p[1]);
        let beside = x * x + y * y <= T::from_f64(4.0) * p[3] * p[3];
        if beside && o.z >= p[4] && o.z <= p[5] {
            return T::ZERO;
        }
        // Elsewhere to the closest approach to the axis, when that is no farther along the
        // ray than the origin is from the centre.
        let (across, d2) = (x * d.x + y * d.y, d.x * d.x + d.y * d.y);
        let shift = -across / d2;
        let c = o - centre(code, p);
        if shift * shift * d.length_squared() <= c.length_squared() {
            return shift;
        }
    }
    let shift = -(o - centre(code, p)).dot(d) / d.length_squared();
    if shift.is_finite() {
        shift
    } else {
        T::ZERO
    }
}

/// Whether a primitive's surfaces are planes (box, convex polyhedron, half-space, slab, phi
/// cut): its spans' ends are as exact as the planes, with no near-double roots.
pub fn is_planar(code: TypeCode) -> bool {
    matches!(
        code,
        TypeCode::Box3
            | TypeCode::ConvexPolyhedron
            | TypeCode::HalfSpace
            | TypeCode::Slab
            | TypeCode::PhiCut
    )
}

/// The point a leaf's rays are moved toward before its quadric is solved: the middle of the
/// axis of a cone frustum, cylinder or tube (a polycone's segments lie far along z from
/// their frame's origin, where the cone's radius, extrapolated, would cancel badly), the
/// frame's origin for the others.
pub fn centre<T: Real>(code: TypeCode, p: &[T; 6]) -> V3<T> {
    match code {
        TypeCode::Cone => V3::new(T::ZERO, T::ZERO, (p[1] + p[3]) * T::HALF),
        TypeCode::Cylinder | TypeCode::Disc => V3::new(p[0], p[1], (p[4] + p[5]) * T::HALF),
        _ => V3::zero(),
    }
}

/// The spans of the ray `o + t d` (in the primitive's own frame) inside a primitive, solved
/// from `o + shift d` (see [`origin_shift`]) and given as parameters from there. The z caps
/// of capped quadrics are met from `o` itself, so that leaves sharing a cap plane meet it
/// at the same parameter whatever their moves.
pub fn primitive_spans<T: Real>(
    code: TypeCode,
    p: &[T; 6],
    planes: &[[T; 4]],
    o: V3<T>,
    d: V3<T>,
    shift: T,
) -> Spans<T> {
    match code {
        TypeCode::ZSphere => quadric::zsphere_spans(p, o, d, shift),
        TypeCode::Cylinder => quadric::cylinder_spans(p, o, d, shift),
        TypeCode::Disc => quadric::tube_spans(p, o, d, shift),
        TypeCode::Cone => quadric::cone_spans(p, o, d, shift),
        TypeCode::Hyperboloid => quadric::hyperboloid_spans(p, o, d, shift),
        TypeCode::Paraboloid => quadric::paraboloid_spans(p, o, d, shift),
        TypeCode::TwistedHalfSpace => twisted::twisted_spans(p, o, d, shift),
        _ => moved_spans(code, p, planes, o.at(d, shift), d),
    }
}

/// The spans of primitives without z caps, from the moved origin.
fn moved_spans<T: Real>(
    code: TypeCode,
    p: &[T; 6],
    planes: &[[T; 4]],
    o: V3<T>,
    d: V3<T>,
) -> Spans<T> {
    match code {
        TypeCode::Sphere => quadric::sphere_spans(p, o, d),
        TypeCode::Torus => torus_prim::torus_spans(p, o, d),
        TypeCode::Box3 => planar::box_spans(p, o, d),
        TypeCode::ConvexPolyhedron => planar::polyhedron_spans(planes, o, d),
        TypeCode::HalfSpace => planar::halfspace_spans(p, o, d),
        TypeCode::Slab => planar::slab_spans(p, o, d),
        TypeCode::PhiCut => cuts::phicut_spans(p, o, d),
        TypeCode::ThetaCut => cuts::thetacut_spans(p, o, d),
        TypeCode::Saddle => quadric::saddle_spans(p, o, d),
        _ => Spans::empty(),
    }
}

/// Signed distance from a point (in the primitive's own frame) to a primitive: negative
/// inside. Exact for sphere, cylinder, tube, torus, box, half-space and slab; a bound with
/// the exact sign for the others.
pub fn primitive_sdf<T: Real>(code: TypeCode, p: &[T; 6], planes: &[[T; 4]], x: V3<T>) -> T {
    match code {
        TypeCode::Sphere => quadric::sphere_sdf(p, x),
        TypeCode::ZSphere => quadric::zsphere_sdf(p, x),
        TypeCode::Cylinder => quadric::cylinder_sdf(p, x),
        TypeCode::Disc => quadric::tube_sdf(p, x),
        TypeCode::Cone => quadric::cone_sdf(p, x),
        TypeCode::Hyperboloid => quadric::hyperboloid_sdf(p, x),
        TypeCode::Paraboloid => quadric::paraboloid_sdf(p, x),
        TypeCode::Torus => torus_prim::torus_prim_sdf(p, x),
        TypeCode::Box3 => planar::box_sdf(p, x),
        TypeCode::ConvexPolyhedron => planar::polyhedron_sdf(planes, x),
        TypeCode::HalfSpace => planar::halfspace_sdf(p, x),
        TypeCode::Slab => planar::slab_sdf(p, x),
        TypeCode::PhiCut => cuts::phicut_sdf(p, x),
        TypeCode::ThetaCut => cuts::thetacut_sdf(p, x),
        TypeCode::Saddle => quadric::saddle_sdf(p, x),
        TypeCode::TwistedHalfSpace => twisted::twisted_sdf(p, x),
        _ => T::INFINITY,
    }
}

/// The first surface crossing of a node after a ray parameter, or a miss.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Step<T> {
    /// Ray parameter of the crossing (`+inf`: no crossing).
    pub t: T,
    /// Outward normal of the node's region at the crossing (not normalized).
    pub normal: V3<T>,
    /// Whether the ray is inside the node's region just before `t` (for a miss: all along).
    pub inside_before: bool,
    /// The smallest start of a span that the evaluation skipped as a touch (no longer
    /// than the tolerance) although it ended past the start of the search; `+inf` when
    /// none was. Such a span is a decision within rounding: a chord through an edge or a
    /// near-tangent that an exact evaluation may keep (scans trace such rays again in f64).
    /// A mesh in f32 reports here the least distance, not beyond its answer, of a triangle
    /// whose hit or miss is within the rounding of its edge functions (a crossing beside
    /// an edge or vertex, or a near miss of one).
    pub dropped: T,
}

impl<T: Real> Step<T> {
    /// No crossing; the ray is inside (or outside) all along.
    pub fn miss(inside: bool) -> Self {
        Step {
            t: T::INFINITY,
            normal: V3::zero(),
            inside_before: inside,
            dropped: T::INFINITY,
        }
    }

    /// Whether there is a crossing.
    pub fn is_hit(&self) -> bool {
        self.t < T::INFINITY
    }

    /// Whether the ray is inside just after `t` (for a miss: all along).
    pub fn inside_after(&self) -> bool {
        self.inside_before != self.is_hit()
    }

    /// The same crossing as a boundary of the complement.
    pub fn complemented(self) -> Self {
        Step {
            t: self.t,
            normal: -self.normal,
            inside_before: !self.inside_before,
            dropped: self.dropped,
        }
    }
}

/// Which spans of a ray `o + t d` (in the primitive's own frame, `o` shifted as the spans
/// were solved) only run along the primitive's surface: a bit per span whose points at a
/// quarter, half and three quarters of its length are all within `tol` of the surface
/// (signed distance within `tol` of 0: a span that a degenerate root put outside is no
/// contact). Such a span is a *contact*: the ray lies in a face, along a
/// wall's generator or on a tangent, and never enters the interior. Geant4 takes the surface
/// for outside the solid (`Inside()` is `kSurface` all along) and answers no boundary
/// there; callers skip contact spans where the tree agrees ([`contacts_outside`]). An
/// infinite end (of a cut or half-space, whose faces are planes or cones through the
/// origin) is replaced by one as far from the other end as that is from the closest
/// approach to the centre (at least a unit: a plane crossed at a grazing angle far away is
/// no contact), or by the unit around that approach if both ends are infinite (the ray
/// parallel to every face it might run along). Three points, not one:
/// a ray tangent to a tube's inner wall has its middle on the surface but runs deep through
/// the wall on both sides. The points are only asked for rays with a zero direction
/// component (a ray parallel to a face or wall of the primitive's frame): others are not
/// contacts but for the rounding of a tangent, which the touch length already decides.
/// Saddles and twisted half-spaces have none: their distance bounds shrink along a ruling
/// away from the axis (their gradients grow there), so a ray parallel to a ruling inside
/// the solid, whose span reaches far along it, would pass the three points for one; a ray
/// exactly in such a face is inside or outside by the rounding of its function.
pub fn contact_spans<T: Real>(
    code: TypeCode,
    p: &[T; 6],
    planes: &[[T; 4]],
    spans: &Spans<T>,
    o: V3<T>,
    d: V3<T>,
    tol: T,
) -> u32 {
    let oblique = d.x != T::ZERO && d.y != T::ZERO && d.z != T::ZERO;
    let ruled = matches!(code, TypeCode::Saddle | TypeCode::TwistedHalfSpace);
    if oblique || ruled || on_phi_axis(code, o, d) {
        return 0;
    }
    let mut contacts = 0;
    for (i, s) in spans.as_slice().iter().enumerate() {
        let (t0, t1) = match (s.t0.is_finite(), s.t1.is_finite()) {
            (true, true) => (s.t0, s.t1),
            (true, false) => (s.t0, s.t0 + s.t0.abs().max(T::ONE)),
            (false, true) => (s.t1 - s.t1.abs().max(T::ONE), s.t1),
            (false, false) => (-T::HALF, T::HALF),
        };
        let length = t1 - t0;
        let on_surface = [0.25, 0.5, 0.75].iter().all(|&f| {
            let x = o.at(d, t0 + length * T::from_f64(f));
            primitive_sdf(code, p, planes, x).abs() <= tol
        });
        contacts |= (on_surface as u32) << i;
    }
    contacts
}

/// Whether a ray runs along the axis of a phi cut, the edge where its half-planes meet.
/// Geant4's solids disagree there: G4Sphere does not check phi on the axis (inside),
/// G4Tubs, G4Polycone and G4Polyhedra take it for surface; the closed rule is kept.
fn on_phi_axis<T: Real>(code: TypeCode, o: V3<T>, d: V3<T>) -> bool {
    code == TypeCode::PhiCut && o.x == T::ZERO && o.y == T::ZERO && d.x == T::ZERO && d.y == T::ZERO
}

/// Whether a ray running along the surface of the leaf at `position` of a complete binary
/// tree (whose operator at position `k` is `operator(k)`, `None` for other slots) is
/// outside the tree there, as Geant4's booleans decide: the surface of a solid is not its
/// interior, an intersection is inside where both operands are, and a difference `A - B`
/// where `A` is inside and `B` neither inside nor on its surface (the leaf's contacts count
/// as inside it when it is subtracted an odd number of times, `complement` included). A
/// union's faces may be shared by its operands, inside the union (G4UnionSolid: both on
/// their surfaces with opposite normals): under a union, contacts keep the closed rule.
pub fn contacts_outside(
    position: usize,
    complement: bool,
    operator: impl Fn(usize) -> Option<TypeCode>,
) -> bool {
    let (mut p, mut subtracted) = (position, complement);
    while p > 1 {
        match operator(p / 2) {
            Some(TypeCode::Union) => return false,
            Some(TypeCode::Difference) if p % 2 == 1 => subtracted = !subtracted,
            _ => {}
        }
        p /= 2;
    }
    !subtracted
}

/// Picks the first span end after `tmin + tol` among `spans` shifted by `shift`, skipping
/// spans no longer than `touch` (tangent touches, not crossings) and the spans whose bit is
/// set in `contacts` (see [`contact_spans`]); the least start of those skipped that end
/// after `tmin + tol` is reported as [`Step::dropped`]. Normals are oriented outward from
/// the span's role (entries face against the ray, exits along it).
pub fn first_crossing<T: Real>(
    spans: &Spans<T>,
    shift: T,
    d: V3<T>,
    tmin: T,
    tol: T,
    touch: T,
    contacts: u32,
) -> Step<T> {
    let after = tmin + tol;
    let mut dropped = T::INFINITY;
    for (i, s) in spans.as_slice().iter().enumerate() {
        if s.t1 - s.t0 <= touch || contacts & (1 << i) != 0 {
            if s.t1 + shift > after && s.t0 < T::INFINITY {
                dropped = dropped.min(s.t0 + shift);
            }
            continue;
        }
        let (t0, t1) = (s.t0 + shift, s.t1 + shift);
        if t0 > after {
            let n = if s.n0.dot(d) > T::ZERO { -s.n0 } else { s.n0 };
            return Step {
                t: t0,
                normal: n,
                inside_before: false,
                dropped,
            };
        }
        if t1 > after {
            let n = if s.n1.dot(d) < T::ZERO { -s.n1 } else { s.n1 };
            return Step {
                t: t1,
                normal: n,
                inside_before: true,
                dropped,
            };
        }
    }
    Step {
        dropped,
        ..Step::miss(false)
    }
}

impl<T: Real> Leaf<T> {
    /// The first crossing of the leaf's surface by `ray` (in the tree's frame) after
    /// `tmin + tol`; normals in the tree's frame. `alone`: the leaf is the whole prim (no
    /// other leaf shares its faces). `contacts_outside`: a ray running along the leaf's
    /// surface is outside the tree there (see [`contacts_outside`]), so contact spans are
    /// skipped.
    pub fn step(
        &self,
        planes: &[[T; 4]],
        ray: &Ray<T>,
        tmin: T,
        tol: T,
        alone: bool,
        contacts_outside: bool,
    ) -> Step<T> {
        let local = match &self.frame {
            Some(f) => f.ray_to_local(ray),
            None => *ray,
        };
        // The quadrics are solved from the ray's closest approach to the primitive's centre,
        // with coefficients of the primitive's size however far away the ray starts; a ray
        // starting beside the wall of a cylinder or tube is solved where it starts
        // ([`origin_shift`]). Z caps are met from the unmoved origin ([`primitive_spans`]).
        let d = local.direction;
        let shift = origin_shift(self.code, &self.params, local.origin, d);
        let leaf_planes = &planes[self.planes.clone()];
        let spans = primitive_spans(self.code, &self.params, leaf_planes, local.origin, d, shift);
        // The spans' parameter starts at the moved origin.
        let o = local.origin.at(d, shift);
        // A curved surface's near-double roots (a tangent ray) are uncertain by more than
        // their distance: such short spans are touches, and so are the slivers that the
        // rounded planes of faces that leaves share leave along a ray near those faces.
        // A planar leaf alone meets a ray in roots exact to a few ulps of the solid's size:
        // only spans within that of empty are touches, a longer short span is a thin part
        // of it (a ray past the edge of a long bar).
        let touch = if alone && is_planar(self.code) {
            tol / T::from_f64(4.0)
        } else {
            tol
        };
        let contacts = if contacts_outside {
            contact_spans(self.code, &self.params, leaf_planes, &spans, o, d, tol)
        } else {
            0
        };
        let mut step = first_crossing(&spans, shift, d, tmin, tol, touch, contacts);
        if let Some(f) = &self.frame {
            step.normal = f.normal_to_parent(step.normal);
        }
        if self.complement {
            step.complemented()
        } else {
            step
        }
    }

    /// Signed distance bound of the leaf at a point of the tree's frame (negative inside;
    /// see [`primitive_sdf`]).
    pub fn sdf(&self, planes: &[[T; 4]], x: V3<T>) -> T {
        let local = match &self.frame {
            Some(f) => f.point_to_local(x),
            None => x,
        };
        let s = primitive_sdf(self.code, &self.params, &planes[self.planes.clone()], local);
        if self.complement {
            -s
        } else {
            s
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rotations_and_reflections_are_rigid_and_scalings_are_not() {
        let frame = |t: &Transform64| Frame::<f32>::from_transform(t).unwrap();
        for t in [
            Transform64::IDENTITY,
            Transform64::translation([3.0, -1e6, 2.0]),
            Transform64::rotation([1.0, 1.0, 1.0], 0.7),
            Transform64::rotation([0.0, 1.0, 0.0], 3.0),
        ] {
            assert!(frame(&t).is_rigid(), "{t:?}");
        }
        let mut scaled = Transform64::rotation([1.0, 0.0, 0.0], 0.3);
        scaled.rows[0][0] *= 1.5;
        assert!(!frame(&scaled).is_rigid());
        let mut mirrored = Transform64::IDENTITY;
        mirrored.rows[2][2] = -1.0;
        assert!(frame(&mirrored).is_rigid());
    }

    #[test]
    fn right_angle_placements_are_axis_aligned_and_others_are_not() {
        let frame = |t: &Transform64| Frame::<f32>::from_transform(t).unwrap();
        let aligned = [
            Transform64::IDENTITY,
            Transform64::translation([3.0, -1e6, 2.0]),
            Transform64::rotation([1.0, 0.0, 0.0], std::f64::consts::PI),
            Transform64::rotation([0.0, 0.0, 1.0], std::f64::consts::FRAC_PI_2),
        ];
        for t in &aligned {
            assert!(frame(t).is_axis_aligned(), "{t:?}");
        }
        for angle in [0.5f64, 1.0, 3.0] {
            let t = Transform64::rotation([0.0, 1.0, 0.0], angle);
            assert!(!frame(&t).is_axis_aligned(), "{t:?}");
            let t = Transform64::rotation([1.0, 1.0, 1.0], angle);
            assert!(!frame(&t).is_axis_aligned(), "{t:?}");
        }
    }
}
