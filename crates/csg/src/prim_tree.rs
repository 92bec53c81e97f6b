//! A Foundry CSG prim prepared for intersection in one precision, and its evaluators.
//!
//! The first crossing of a tree walks the complete binary tree by index arithmetic
//! (children of position `p` are `2p` and `2p + 1`), recursively here and from a stack of
//! frames in the GPU kernels (`shaders/csg/tree.wgsl`), asking the same queries in the same
//! order (a recursion as deep as the tree sets up no stack of the largest height on every
//! call: one-thread closest hits on the mixed bench scene ran 15-25% faster without it).
//! Each operator node combines the first crossings of its children with the state table of
//! its boolean operation (Kensler's single-hit algorithm, written with inside states so that
//! coincident crossings of both children and complements that miss are handled exactly): a
//! child crossing that changes the operator's inside state is the operator's crossing; one
//! that does not is skipped by querying that child again after it.
//!
//! Signed distances (and so inside tests) walk the tree in postorder with the same index
//! arithmetic and a value stack. Points where the distance is about 0 on faces that members
//! of a union share (inside the union, though on its members' surfaces) are told from
//! points of the surface by rays from them (see [`PrimTree::contains`]).

use std::ops::Range;

use hytrace_foundry::{Foundry, PrimKind, TypeCode, COMPLEMENT_BIT, MAX_TREE_HEIGHT};

use crate::kernel::{contacts_outside, is_bounded, Frame, Leaf, Step};
use crate::real::{Ray, Real, V3};
use crate::shape::CsgError;

/// Bounds `[min, max]` in the prim's frame.
pub type Bounds<T> = [V3<T>; 2];

/// One slot of the complete binary tree.
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum Slot<T> {
    /// Below a leaf.
    Empty,
    /// Union, intersection or difference of the two children.
    Operator(TypeCode),
    /// N-ary union or intersection of primitive members.
    List {
        code: TypeCode,
        members: Range<usize>,
        bounds: Bounds<T>,
    },
    /// A primitive.
    Leaf(Leaf<T>),
}

/// A CSG prim ready for intersection and inside tests in precision `T`.
#[derive(Clone, Debug, PartialEq)]
pub struct PrimTree<T> {
    pub(crate) slots: Vec<Slot<T>>,
    pub(crate) members: Vec<(Leaf<T>, Bounds<T>)>,
    pub(crate) planes: Vec<[T; 4]>,
    pub(crate) height: u32,
    pub(crate) bounds: Bounds<T>,
    pub(crate) scale: T,
    /// The surface tolerance at the farthest point of `bounds`: the most it is at a point
    /// near the surface.
    pub(crate) near_max: T,
    /// Per slot: whether a ray along the surface of the leaf there is outside the tree
    /// ([`crate::kernel::contacts_outside`]; false for other slots).
    pub(crate) contacts_outside: Vec<bool>,
}

/// Tolerance for crossings near ray parameter `t` in a tree of size `scale`: crossings of
/// the same surface are at least this far apart, coincident faces within it.
pub(crate) fn tolerance<T: Real>(scale: T, t: T) -> T {
    T::SURFACE_TOLERANCE * (scale + t.abs())
}

fn bounds_of<T: Real>(aabb: &[f32; 6]) -> Bounds<T> {
    [
        V3::new(
            T::from_f32(aabb[0]),
            T::from_f32(aabb[1]),
            T::from_f32(aabb[2]),
        ),
        V3::new(
            T::from_f32(aabb[3]),
            T::from_f32(aabb[4]),
            T::from_f32(aabb[5]),
        ),
    ]
}

/// Whether `ray` meets `bounds` at some parameter in `[tmin, tmax]` (slab test, exact for
/// zero direction components).
pub fn ray_meets_bounds<T: Real>(ray: &Ray<T>, bounds: &Bounds<T>, tmin: T, tmax: T) -> bool {
    ray_bounds_entry(ray, bounds, tmin, tmax).is_some()
}

/// The first parameter in `[tmin, tmax]` at which `ray` is inside `bounds`, if any (the
/// slab test of [`ray_meets_bounds`]: nearest-first traversals order boxes by it).
pub fn ray_bounds_entry<T: Real>(ray: &Ray<T>, bounds: &Bounds<T>, tmin: T, tmax: T) -> Option<T> {
    ray_bounds_span(ray, bounds, tmin, tmax).map(|(t0, _)| t0)
}

/// The part `[t0, t1]` of `[tmin, tmax]` in which `ray` is inside `bounds`, if any (slab
/// test, exact for zero direction components).
pub fn ray_bounds_span<T: Real>(
    ray: &Ray<T>,
    bounds: &Bounds<T>,
    tmin: T,
    tmax: T,
) -> Option<(T, T)> {
    let (mut lo, mut hi) = (tmin, tmax);
    for k in 0..3 {
        let (o, d) = (ray.origin.get(k), ray.direction.get(k));
        let (a, b) = (bounds[0].get(k), bounds[1].get(k));
        if d == T::ZERO {
            if o < a || o > b {
                return None;
            }
            continue;
        }
        let (ta, tb) = ((a - o) / d, (b - o) / d);
        lo = lo.max(ta.min(tb));
        hi = hi.min(ta.max(tb));
    }
    (lo <= hi).then_some((lo, hi))
}

/// The per-ray part of slab tests against many boxes (BVH traversals).
///
/// Rays whose direction has a reciprocal in every component (no zero or subnormal
/// component) multiply by the reciprocal instead of dividing: at most three roundings
/// instead of two per plane, a relative error under 2e-7 (f32) of the distance to the
/// plane. Other rays take the exact dividing test [`ray_bounds_entry`], which handles zero
/// components without NaNs.
pub struct SlabRay<T> {
    origin: V3<T>,
    inv: V3<T>,
    exact: bool,
}

impl<T: Real> SlabRay<T> {
    /// The slab-test form of `ray`.
    pub fn new(ray: &Ray<T>) -> Self {
        let d = ray.direction;
        let inv = V3::new(T::ONE / d.x, T::ONE / d.y, T::ONE / d.z);
        SlabRay {
            origin: ray.origin,
            inv,
            exact: !(inv.x.is_finite() && inv.y.is_finite() && inv.z.is_finite()),
        }
    }

    /// The slab intervals' bounds `(max of entries, min of exits)` by the reciprocal.
    #[inline(always)]
    fn slabs(&self, b: &Bounds<T>) -> (T, T) {
        // Plain comparisons (no NaN can occur with finite reciprocals): minss/maxss.
        let min = |a: T, b: T| if a < b { a } else { b };
        let max = |a: T, b: T| if a > b { a } else { b };
        let (o, inv) = (self.origin, self.inv);
        let (x0, x1) = ((b[0].x - o.x) * inv.x, (b[1].x - o.x) * inv.x);
        let (y0, y1) = ((b[0].y - o.y) * inv.y, (b[1].y - o.y) * inv.y);
        let (z0, z1) = ((b[0].z - o.z) * inv.z, (b[1].z - o.z) * inv.z);
        (
            max(min(x0, x1), max(min(y0, y1), min(z0, z1))),
            min(max(x0, x1), min(max(y0, y1), max(z0, z1))),
        )
    }

    /// The ray's entry into `b` within `[after, limit]`, if it meets it there, by the
    /// reciprocal: callers pad their boxes by more than its error (see the type's doc).
    #[inline(always)]
    pub fn entry(&self, ray: &Ray<T>, b: &Bounds<T>, after: T, limit: T) -> Option<T> {
        if self.exact {
            return ray_bounds_entry(ray, b, after, limit);
        }
        let (lo, hi) = self.slabs(b);
        let lo = if after > lo { after } else { lo };
        let hi = if limit < hi { limit } else { hi };
        (lo <= hi).then_some(lo)
    }

    /// Like [`Self::entry`], for unpadded boxes: the slab bounds are widened by four
    /// machine epsilons of their size, more than the reciprocal's error, so every box the
    /// exact test [`ray_bounds_entry`] accepts is accepted (with an entry at most that far
    /// before the exact one).
    #[inline(always)]
    pub fn entry_conservative(&self, ray: &Ray<T>, b: &Bounds<T>, after: T, limit: T) -> Option<T> {
        if self.exact {
            return ray_bounds_entry(ray, b, after, limit);
        }
        let (lo, hi) = self.slabs(b);
        let widen = T::from_f64(4.0) * T::EPSILON;
        let (lo, hi) = (lo - widen * lo.abs(), hi + widen * hi.abs());
        let lo = if after > lo { after } else { lo };
        let hi = if limit < hi { limit } else { hi };
        (lo <= hi).then_some(lo)
    }
}

/// A ray set up for slab tests against boxes widened by `pad` on every side: its origin
/// moved by `+pad` and `-pad` (testing the lower and upper faces a widened box moves by
/// `-pad` and `+pad`), so that each test costs what an exact one does.
struct Widened<T> {
    up: V3<T>,
    down: V3<T>,
    direction: V3<T>,
}

impl<T: Real> Widened<T> {
    fn new(ray: &Ray<T>, pad: T) -> Self {
        let pad = V3::new(pad, pad, pad);
        Widened {
            up: ray.origin + pad,
            down: ray.origin - pad,
            direction: ray.direction,
        }
    }
}

/// Whether `ray` meets `bounds` widened by its pad at some parameter in `[tmin, tmax]`.
fn meets_widened<T: Real>(ray: &Widened<T>, bounds: &Bounds<T>, tmin: T, tmax: T) -> bool {
    let (mut lo, mut hi) = (tmin, tmax);
    for k in 0..3 {
        let d = ray.direction.get(k);
        let (a, b) = (bounds[0].get(k), bounds[1].get(k));
        let (up, down) = (ray.up.get(k), ray.down.get(k));
        if d == T::ZERO {
            if up < a || down > b {
                return false;
            }
            continue;
        }
        let (ta, tb) = ((a - up) / d, (b - down) / d);
        lo = lo.max(ta.min(tb));
        hi = hi.min(ta.max(tb));
    }
    lo <= hi
}

fn operator_inside(code: TypeCode, a: bool, b: bool) -> bool {
    match code {
        TypeCode::Union | TypeCode::ListContiguous | TypeCode::ListDiscontiguous => a || b,
        TypeCode::Intersection | TypeCode::ListOverlap => a && b,
        _ => a && !b,
    }
}

/// What an operator node does with its children's first crossings.
enum Decision<T> {
    /// The operator's first crossing (or miss).
    Done(Step<T>),
    /// Query again the children that cross first (left, right) after their crossings; the
    /// third field is [`Step::dropped`] of the crossings merged (`+inf`: none dropped).
    Advance(bool, bool, T),
}

/// Whether two surfaces crossed at one point, with normals `a` and `b` (not normalized),
/// meet there at an angle: the sine of the angle between them over 1e-3. Faces that
/// operands share, placed by transforms rounded in their own frames, are parallel to a few
/// ulps.
fn meet_at_an_angle<T: Real>(a: V3<T>, b: V3<T>) -> bool {
    let sine2 = T::from_f64(1e-6);
    a.cross(b).length_squared() > sine2 * a.length_squared() * b.length_squared()
}

/// The state table of a binary operator: combines the children's next crossings.
fn decide<T: Real>(code: TypeCode, a: &Step<T>, b: &Step<T>, scale: T) -> Decision<T> {
    let t = a.t.min(b.t);
    if !t.is_finite() {
        return Decision::Done(Step::miss(operator_inside(
            code,
            a.inside_before,
            b.inside_before,
        )));
    }
    let tol = tolerance(scale, t);
    let (cross_a, cross_b) = (a.t <= t + tol, b.t <= t + tol);
    let before = operator_inside(code, a.inside_before, b.inside_before);
    let a_after = a.inside_before != cross_a;
    let b_after = b.inside_before != cross_b;
    if operator_inside(code, a_after, b_after) == before {
        // Both children crossing within the tolerance, the result between their crossings
        // other than before and after: a chord through an edge where they meet (or a gap
        // between them) is dropped. Where their surfaces meet at an angle, the chord may be
        // shorter than the rounding of `t`, its ends at one parameter or in either order:
        // either may lie between. Faces both share (parallel normals) are ordered by `t`.
        let a_first = operator_inside(code, a_after, b.inside_before) != before;
        let b_first = operator_inside(code, a.inside_before, b_after) != before;
        let sliver = cross_a && cross_b && {
            if meet_at_an_angle(a.normal, b.normal) {
                a_first || b_first
            } else if a.t < b.t {
                a_first
            } else {
                a.t > b.t && b_first
            }
        };
        let dropped = if sliver { t } else { T::INFINITY };
        return Decision::Advance(cross_a, cross_b, dropped);
    }
    // The crossing child that changes the result on its own gives the surface.
    let use_a = cross_a && (!cross_b || operator_inside(code, a_after, b.inside_before) != before);
    let crossing = if use_a {
        Step {
            inside_before: before,
            ..*a
        }
    } else {
        let normal = if code == TypeCode::Difference {
            -b.normal
        } else {
            b.normal
        };
        Step {
            t: b.t,
            normal,
            inside_before: before,
            dropped: b.dropped,
        }
    };
    Decision::Done(crossing)
}

impl<T: Real> PrimTree<T> {
    /// Prepares CSG prim `prim` of a validated Foundry.
    pub fn from_foundry(foundry: &Foundry, prim: usize) -> Result<Self, CsgError> {
        let err = |problem: String| CsgError {
            primitive: "prim",
            problem: format!("prim {prim}: {problem}"),
        };
        let p = foundry
            .prim
            .get(prim)
            .ok_or_else(|| err("no such prim".into()))?;
        if p.kind != PrimKind::Csg as u32 {
            return Err(err("not a CSG prim".into()));
        }
        let nodes = foundry
            .node
            .get(p.node_offset as usize..(p.node_offset + p.num_node) as usize)
            .ok_or_else(|| err("node range out of bounds".into()))?;
        let height = (p.num_node + 1).trailing_zeros().saturating_sub(1);
        if !(p.num_node + 1).is_power_of_two() || height > MAX_TREE_HEIGHT {
            return Err(err(format!(
                "{} nodes is not a complete binary tree of height <= {MAX_TREE_HEIGHT}",
                p.num_node
            )));
        }
        let mut planes = Vec::new();
        let mut members = Vec::new();
        let mut slots = Vec::with_capacity(nodes.len());
        for (k, n) in nodes.iter().enumerate() {
            let index = p.node_offset as usize + k;
            let code = TypeCode::from_u32(n.typecode)
                .ok_or_else(|| err(format!("unknown typecode {}", n.typecode)))?;
            slots.push(match code {
                TypeCode::Zero => Slot::Empty,
                c if c.is_operator() => Slot::Operator(c),
                c if c.is_list() => {
                    let (first, count) = (n.param[0].to_bits() as usize, n.param[1].to_bits());
                    if foundry.node.get(first..first + count as usize).is_none() {
                        return Err(err("list members out of bounds".into()));
                    }
                    let start = members.len();
                    for index in first..first + count as usize {
                        let m = &foundry.node[index];
                        let leaf = make_leaf(foundry, index, &mut planes, &err)?;
                        if leaf.complement || !is_bounded(leaf.code) {
                            return Err(err(
                                "list members must be bounded, uncomplemented primitives".into(),
                            ));
                        }
                        members.push((leaf, bounds_of(&m.aabb)));
                    }
                    Slot::List {
                        code: c,
                        members: start..members.len(),
                        bounds: bounds_of(&n.aabb),
                    }
                }
                _ => Slot::Leaf(make_leaf(foundry, index, &mut planes, &err)?),
            });
        }
        let [lo, hi] = bounds_of(&p.aabb);
        let scale = T::HALF * (hi - lo).max_abs();
        let scale = if scale.is_finite() { scale } else { T::ONE };
        // Widened like list members' boxes (see `list_step`): culling the prim by them must
        // never drop a crossing of a ray grazing a face its box shares.
        let pad = tolerance(scale, lo.max_abs().max(hi.max_abs()));
        let pad = if pad.is_finite() { pad } else { T::ZERO };
        let pad = V3::new(pad, pad, pad);
        let bounds = [lo - pad, hi + pad];
        let operator = |position: usize| match slots.get(position - 1) {
            Some(Slot::Operator(code)) => Some(*code),
            _ => None,
        };
        let contacts_outside = slots
            .iter()
            .enumerate()
            .map(|(k, slot)| match slot {
                Slot::Leaf(leaf) => contacts_outside(k + 1, leaf.complement, operator),
                _ => false,
            })
            .collect();
        Ok(PrimTree {
            contacts_outside,
            slots,
            members,
            planes,
            height,
            near_max: tolerance(scale, bounds[0].max_abs().max(bounds[1].max_abs())),
            bounds,
            scale,
        })
    }

    /// Prepares a shape directly (one prim of a throwaway Foundry), for users of the builder
    /// API and for tests.
    pub fn from_shape(shape: &crate::Shape) -> Result<Self, CsgError> {
        Self::from_shape_with(shape, crate::TreeOptions::default())
    }

    /// [`PrimTree::from_shape`] with a choice of regrouping (see [`crate::to_tree_with`]).
    pub fn from_shape_with(
        shape: &crate::Shape,
        options: crate::TreeOptions,
    ) -> Result<Self, CsgError> {
        let tree = crate::to_tree_with(shape, options)?;
        let mut f = Foundry::new();
        let mut solid = f.begin_solid("shape");
        let built = solid
            .add_csg(tree, 0, hytrace_foundry::UNSET)
            .and_then(|_| solid.finish(0));
        built.map_err(|e| CsgError {
            primitive: "tree",
            problem: e.to_string(),
        })?;
        Self::from_foundry(&f, 0)
    }

    /// Bounds of the prim in its solid's frame, widened by the surface tolerance (so that a
    /// ray the prim's surfaces hold is never culled by them).
    pub fn bounds(&self) -> &Bounds<T> {
        &self.bounds
    }

    /// Whether the signed distance ([`Self::sdf`]) bounds true distances: every leaf's frame
    /// (if any) keeps distances. A scaled leaf (an elliptical tube, a scaled solid) has its
    /// distance in its own units.
    pub fn sdf_is_distance(&self) -> bool {
        let rigid = |leaf: &Leaf<T>| leaf.frame.as_ref().is_none_or(|f| f.is_rigid());
        self.members.iter().all(|(leaf, _)| rigid(leaf))
            && self.slots.iter().all(|s| match s {
                Slot::Leaf(leaf) => rigid(leaf),
                _ => true,
            })
    }

    /// Whether some leaf of the tree (or member of a list) is the primitive `code`.
    pub fn has_primitive(&self, code: TypeCode) -> bool {
        self.members.iter().any(|(leaf, _)| leaf.code == code)
            || self
                .slots
                .iter()
                .any(|s| matches!(s, Slot::Leaf(leaf) if leaf.code == code))
    }

    /// Height of the tree (0 for a single primitive).
    pub fn height(&self) -> u32 {
        self.height
    }

    /// The first crossing of the prim's surface by `ray` after `tmin` (see the module docs),
    /// with the outward normal in the solid's frame and whether the ray is inside before.
    pub fn first_crossing(&self, ray: &Ray<T>, tmin: T) -> Step<T> {
        self.node_step(1, ray, tmin)
    }

    /// The first crossing after `tmin` of the node at `position`. An operator asks its
    /// children for their first crossings and, while [`decide`] says so, asks the children
    /// that crossed first again after their crossings. The recursion is as deep as the tree
    /// ([`MAX_TREE_HEIGHT`] at most); the GPU kernels make the same queries in the same order
    /// from a stack of frames.
    fn node_step(&self, position: usize, ray: &Ray<T>, tmin: T) -> Step<T> {
        let code = match &self.slots[position - 1] {
            Slot::Operator(code) => *code,
            Slot::Empty => return Step::miss(false),
            Slot::Leaf(leaf) => {
                let outside = self.contacts_outside[position - 1];
                return leaf.step(
                    &self.planes,
                    ray,
                    tmin,
                    self.tol(tmin),
                    position == 1,
                    outside,
                );
            }
            Slot::List {
                code,
                members,
                bounds,
            } => return self.list_step(*code, members.clone(), bounds, ray, tmin),
        };
        let (l, r) = (2 * position, 2 * position + 1);
        let mut left = self.node_step(l, ray, tmin);
        let mut right = self.node_step(r, ray, tmin);
        // Spans dropped by any of the children's steps, the ones advanced past included.
        let mut dropped = left.dropped.min(right.dropped);
        loop {
            match decide(code, &left, &right, self.scale) {
                Decision::Done(step) => return Step { dropped, ..step },
                Decision::Advance(again_left, again_right, sliver) => {
                    dropped = dropped.min(sliver);
                    if again_left {
                        left = self.node_step(l, ray, left.t);
                        dropped = dropped.min(left.dropped);
                    }
                    if again_right {
                        right = self.node_step(r, ray, right.t);
                        dropped = dropped.min(right.dropped);
                    }
                }
            }
        }
    }

    fn tol(&self, t: T) -> T {
        tolerance(self.scale, t)
    }

    /// First crossing of an n-ary union or intersection: walks the members' crossings in
    /// order, counting how many members the ray is inside, until the count crosses the
    /// operator's threshold (more than zero for unions, all for intersections). Members
    /// whose bounds the ray misses by more than the tolerance are skipped unintersected.
    fn list_step(
        &self,
        code: TypeCode,
        members: Range<usize>,
        bounds: &Bounds<T>,
        ray: &Ray<T>,
        tmin: T,
    ) -> Step<T> {
        let all = members.len();
        let inside = |count: usize| match code {
            TypeCode::ListOverlap => count == all,
            _ => count > 0,
        };
        // The bounds are exact (rounded outward) boxes of the true members, but a member's
        // own surfaces, evaluated in `T`, may hold a ray that grazes one of its faces a
        // rounding error outside its box (a ray along a face two members share, say): the
        // boxes are widened by the tolerance of crossings as far out as the list's box, so
        // that culling never changes the answer.
        let reach = (ray.origin - bounds[0])
            .max_abs()
            .max((ray.origin - bounds[1]).max_abs());
        let widened = Widened::new(ray, self.tol(tmin.abs() + reach));
        if !meets_widened(&widened, bounds, tmin, T::INFINITY) {
            return Step::miss(false);
        }
        let mut tau = tmin;
        let mut dropped = T::INFINITY;
        loop {
            let (mut best, mut count) = (T::INFINITY, 0usize);
            // The last of the crossings merged with the first (`best`).
            let mut last = T::INFINITY;
            let (mut entries, mut exits) = (0usize, 0usize);
            let (mut entry_normal, mut exit_normal) = (V3::zero(), V3::zero());
            for (leaf, b) in &self.members[members.clone()] {
                if !meets_widened(&widened, b, tau, T::INFINITY) {
                    continue;
                }
                let s = leaf.step(&self.planes, ray, tau, self.tol(tau), false, false);
                dropped = dropped.min(s.dropped);
                count += s.inside_before as usize;
                if !s.is_hit() {
                    continue;
                }
                let tol = self.tol(s.t);
                if s.t < best - tol {
                    (best, last, entries, exits) = (s.t, s.t, 0, 0);
                } else if s.t > best + tol {
                    continue;
                }
                best = best.min(s.t);
                last = last.max(s.t);
                if s.inside_before {
                    exits += 1;
                    exit_normal = s.normal;
                } else {
                    entries += 1;
                    entry_normal = s.normal;
                }
            }
            if best == T::INFINITY {
                return Step {
                    dropped,
                    ..Step::miss(inside(count))
                };
            }
            let after = count + entries - exits;
            // Entries and exits merged with the result unchanged: a chord or a gap between
            // members may lie between them (decide's sliver), at one parameter where the
            // surfaces meet at an angle.
            let apart = last != best || meet_at_an_angle(entry_normal, exit_normal);
            if entries > 0 && exits > 0 && apart && inside(count) == inside(after) {
                dropped = dropped.min(best);
            }
            if inside(count) != inside(after) {
                return Step {
                    t: best,
                    normal: if inside(after) {
                        entry_normal
                    } else {
                        exit_normal
                    },
                    inside_before: inside(count),
                    dropped,
                };
            }
            tau = best;
        }
    }

    /// Signed distance bound of the prim at a point of the solid's frame: negative inside,
    /// with the exact sign (unions take the minimum, intersections the maximum, differences
    /// the maximum of the left and the negated right).
    pub fn sdf(&self, x: V3<T>) -> T {
        let mut values = [T::ZERO; MAX_TREE_HEIGHT as usize + 2];
        let mut top = 0;
        // Postorder over the perfect tree of this height: start at the leftmost deepest
        // position; a left child is followed by the leftmost deepest descendant of its
        // sibling, a right child by its parent.
        let deepest = self.height;
        let mut position = 1usize << deepest;
        loop {
            match &self.slots[position - 1] {
                Slot::Empty => {}
                Slot::Leaf(leaf) => {
                    values[top] = leaf.sdf(&self.planes, x);
                    top += 1;
                }
                Slot::List { code, members, .. } => {
                    let mut v = if *code == TypeCode::ListOverlap {
                        -T::INFINITY
                    } else {
                        T::INFINITY
                    };
                    for (leaf, _) in &self.members[members.clone()] {
                        let s = leaf.sdf(&self.planes, x);
                        v = if *code == TypeCode::ListOverlap {
                            v.max(s)
                        } else {
                            v.min(s)
                        };
                    }
                    values[top] = v;
                    top += 1;
                }
                Slot::Operator(code) => {
                    let (a, b) = (values[top - 2], values[top - 1]);
                    top -= 1;
                    values[top - 1] = match code {
                        TypeCode::Union => a.min(b),
                        TypeCode::Intersection => a.max(b),
                        _ => a.max(-b),
                    };
                }
            }
            if position == 1 {
                return values[0];
            }
            position = if position & 1 == 1 {
                position >> 1
            } else {
                let sibling = position + 1;
                let level = usize::BITS - 1 - sibling.leading_zeros();
                sibling << (deepest - level)
            };
        }
    }

    /// The signed distance of the subtree at `position`, and whether one of its unions
    /// (binary or list) has `x` within `near` of, but not inside, two or more of its
    /// children: on a face they share, say, where the union's value is 0 although the point
    /// may lie inside the union. For the rare points near a surface only (recursive).
    fn seam(&self, position: usize, x: V3<T>, near: T) -> (T, bool) {
        match &self.slots[position - 1] {
            Slot::Empty => (T::INFINITY, false),
            Slot::Leaf(leaf) => (leaf.sdf(&self.planes, x), false),
            Slot::List { code, members, .. } => {
                let sdfs = self.members[members.clone()]
                    .iter()
                    .map(|(leaf, _)| leaf.sdf(&self.planes, x));
                if *code == TypeCode::ListOverlap {
                    return (sdfs.fold(-T::INFINITY, T::max), false);
                }
                let (v, close) = sdfs.fold((T::INFINITY, 0usize), |(v, close), s| {
                    (v.min(s), close + (s <= near) as usize)
                });
                (v, close > 1 && v >= T::ZERO)
            }
            Slot::Operator(code) => {
                let (a, seam_a) = self.seam(2 * position, x, near);
                let (b, seam_b) = self.seam(2 * position + 1, x, near);
                let (v, seam) = match code {
                    TypeCode::Union => (a.min(b), a.max(b) <= near && a.min(b) >= T::ZERO),
                    TypeCode::Intersection => (a.max(b), false),
                    _ => (a.max(-b), false),
                };
                (v, seam || seam_a || seam_b)
            }
        }
    }

    /// Whether a point of the solid's frame is inside the prim: in its interior, so that
    /// points of its surface are outside, but points of faces its members share inside.
    ///
    /// The signed distance decides, except where it is within the surface tolerance of 0,
    /// not negative, and some union has the point that near two or more of its children (a
    /// rare case: the point must lie on two surfaces at once). The point is then inside if
    /// rays from it in 32 directions spread over the sphere start inside by
    /// [`Self::first_crossing`] (which hides the faces members share): on a face or edge
    /// the members share they do; on the solid's surface the rays leaving it do not (at a
    /// reflex edge, if the outside wedge is wider than about 55 degrees). Rays that cross
    /// a surface close to the point, where rounding may decide, are left out.
    pub fn contains(&self, x: V3<T>) -> bool {
        let v = self.sdf(x);
        v < T::ZERO || (v <= self.near_max && self.inside_on_seam(x, v))
    }

    /// [`Self::contains`] for a point with signed distance `v`, not negative but possibly
    /// within the surface tolerance.
    #[cold]
    #[inline(never)]
    fn inside_on_seam(&self, x: V3<T>, v: T) -> bool {
        let near = self.tol(x.max_abs());
        v <= near && self.seam(1, x, near).1 && self.inside_by_probes(x, near)
    }

    /// Whether rays from `x` in [`SEAM_PROBES`] directions all start inside by
    /// [`Self::first_crossing`]. A crossing within `2 near` is the surface the ray starts
    /// on (its state is the one after that crossing), and a ray that crosses a surface
    /// (another one) within `1000 near` is left out. On a shared face, a ray nearly along
    /// it from a point rounded into the sliver between the members' rounded planes may
    /// start outside both, or leave one, and enter the other about the sliver's width over
    /// its angle to the face further on; on the solid's surface, a ray leaving it crosses
    /// the surface it starts on a rounding error away (or not at all) and, if at all, the
    /// solid again much farther away.
    fn inside_by_probes(&self, x: V3<T>, near: T) -> bool {
        let (start, far) = (T::TWO * near, T::from_f64(1000.0) * near);
        let mut inside = false;
        for k in 0..SEAM_PROBES {
            let ray = Ray {
                origin: x,
                direction: V3::from_f64(probe_direction(k)),
            };
            let mut step = self.first_crossing(&ray, T::ZERO);
            if step.t <= start {
                step = self.first_crossing(&ray, step.t);
            }
            if step.t > far {
                if !step.inside_before {
                    return false;
                }
                inside = true;
            }
        }
        inside
    }
}

/// How many rays decide [`PrimTree::contains`] on faces that members share.
pub(crate) const SEAM_PROBES: usize = 32;

/// Unit direction `k` of [`SEAM_PROBES`] spread evenly over the sphere (a spherical
/// Fibonacci set, turned so that none lies along an axis or a diagonal).
pub(crate) fn probe_direction(k: usize) -> [f64; 3] {
    let z = 1.0 - (2 * k + 1) as f64 / SEAM_PROBES as f64;
    let r = (1.0 - z * z).sqrt();
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    let phi = 1.68 + golden * k as f64;
    [r * phi.cos(), r * phi.sin(), z]
}

/// The leaf of node `index`, its parameters and planes from the double-precision copies
/// (rounded to `T`: exactly the f32 values for f32); errors are made by `err`.
fn make_leaf<T: Real>(
    foundry: &Foundry,
    index: usize,
    planes: &mut Vec<[T; 4]>,
    err: &impl Fn(String) -> CsgError,
) -> Result<Leaf<T>, CsgError> {
    let n = &foundry.node[index];
    let code = TypeCode::from_u32(n.typecode)
        .filter(|c| c.is_primitive())
        .ok_or_else(|| err(format!("typecode {} is not a primitive", n.typecode)))?;
    let tran = (n.transform & !COMPLEMENT_BIT) as usize;
    let frame = match tran {
        0 => None,
        k => {
            let t = foundry
                .tran
                .get(k - 1)
                .ok_or_else(|| err(format!("transform {k} out of range")))?;
            Some(
                Frame::from_transform(t)
                    .ok_or_else(|| err(format!("transform {k} is singular")))?,
            )
        }
    };
    let mut leaf_planes = 0..0;
    if code == TypeCode::ConvexPolyhedron {
        let (first, count) = (n.param[0].to_bits() as usize, n.param[1].to_bits() as usize);
        let src = foundry
            .plan64
            .get(first..first + count)
            .ok_or_else(|| err("planes out of range".to_string()))?;
        let start = planes.len();
        planes.extend(src.iter().map(|p| p.plane.map(T::from_f64)));
        leaf_planes = start..planes.len();
    }
    let params = foundry
        .node64
        .get(index)
        .ok_or_else(|| err(format!("node {index} has no double-precision parameters")))?
        .param
        .map(T::from_f64);
    Ok(Leaf {
        code,
        params,
        planes: leaf_planes,
        frame,
        complement: n.transform & COMPLEMENT_BIT != 0,
    })
}
