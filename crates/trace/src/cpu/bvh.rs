//! Bounding volume hierarchies over boxes with ids, replacing the tracer's linear loops: over
//! groups of instances (all of a flat scene's, one mother's daughters, those holding media)
//! and over the leaves of one solid (its surface prims and its volume-brick clusters).
//!
//! obvhs builds the tree from f32 copies of the boxes, each rounded outward, so every node
//! box (a union of such boxes, exact in f32) contains the exact box of every item below
//! it. Leaves hold one item each, so a leaf's box is its item's and callers need no box
//! test of their own. The traversal runs over those boxes with a reciprocal slab test
//! widened to accept every box the exact test ([`hytrace_csg::ray_meets_bounds`]) accepts:
//! in f32 eight boxes at a time over the tree collapsed into eight-wide nodes
//! ([`hytrace_csg::wide_bvh`], the mesh kernel's node form), in f64 one at a time over the
//! binary tree ([`SlabRay::entry_conservative`]); the GPU walks the binary tree. The exact
//! test is monotone in the box, so whenever an item's own exact bounds test passes, so does
//! every node above it, and no item the ray meets is culled. Items with non-finite bounds
//! stay out of the tree and are visited every time.
//!
//! Measured on the mixed scene of `cargo bench -p hytrace-tests --bench mixed` (406
//! instances; BENCHMARKS.md), the wide walk with one-item leaves and no repeated box tests
//! took the closest-hit query from 0.80x (coherent) and 0.94x (incoherent) of Embree's
//! speed to 1.01x and 1.06-1.18x.

use glam::Vec3A;
use hytrace_csg::bvh_build::shallow_bvh2;
use hytrace_csg::wide_bvh::{ray_f32, WideBvhError, WideSlabs, WideTree};
use hytrace_csg::{Bounds, Ray, Real, SlabRay, V3};
use obvhs::aabb::Aabb;
use obvhs::BvhBuildParams;

use crate::gpu::records::BoxNode;

/// A node: its box, then either children `first, first + 1` (`count == 0`) or the items
/// `first..first + count` of the leaf-ordered item list.
#[derive(Clone, Debug)]
struct Node<T> {
    bounds: Bounds<T>,
    first: u32,
    count: u32,
}

/// A BVH over boxes with `u32` ids, queried by ray (nearest nodes first) or by point.
#[derive(Clone, Debug)]
pub(super) struct BoxBvh<T> {
    nodes: Vec<Node<T>>,
    /// Item ids in leaf order.
    items: Vec<u32>,
    /// Items whose bounds are not finite: not in the tree, visited by every query.
    unbounded: Vec<u32>,
    /// The tree with eight-wide nodes (leaves: ranges of `items`) the f32 ray walk takes;
    /// `None` in f64.
    wide: Option<WideTree>,
}

/// A ray's slab-test form for [`BoxBvh::visit_ray`], made once per ray: eight boxes at a
/// time in f32 (the wide tree's walk), one at a time in f64 (the binary tree's).
// A value on the stack for one ray's walk, never stored: boxing the wide form would cost
// an allocation per ray.
#[allow(clippy::large_enum_variant)]
pub(crate) enum RaySlabs<T> {
    Binary(SlabRay<T>),
    Wide(WideSlabs),
}

impl<T: Real> RaySlabs<T> {
    pub(crate) fn new(ray: &Ray<T>) -> Self {
        if T::NAME == "f32" {
            RaySlabs::Wide(WideSlabs::new(&ray_f32(ray)))
        } else {
            RaySlabs::Binary(SlabRay::new(ray))
        }
    }
}

/// Deepest BVH the traversals' fixed stacks accept ([`shallow_bvh2`] never builds a
/// deeper one).
pub(crate) const MAX_DEPTH: usize = hytrace_csg::wide_bvh::MAX_DEPTH;

/// The largest f32 not above `v`.
pub(super) fn f32_down(v: f64) -> f32 {
    let r = v as f32;
    if f64::from(r) > v {
        r.next_down()
    } else {
        r
    }
}

/// The smallest f32 not below `v`.
pub(super) fn f32_up(v: f64) -> f32 {
    let r = v as f32;
    if f64::from(r) < v {
        r.next_up()
    } else {
        r
    }
}

/// A traversal stack on the call stack: a depth-first walk of a tree at most [`MAX_DEPTH`]
/// levels deep holds at most one pending sibling per level plus the node being expanded,
/// so no query allocates.
struct Stack<E> {
    items: [E; MAX_DEPTH + 2],
    len: usize,
}

impl<E: Copy> Stack<E> {
    fn new(fill: E) -> Self {
        Stack {
            items: [fill; MAX_DEPTH + 2],
            len: 0,
        }
    }

    fn push(&mut self, e: E) {
        self.items[self.len] = e;
        self.len += 1;
    }

    fn pop(&mut self) -> Option<E> {
        self.len = self.len.checked_sub(1)?;
        Some(self.items[self.len])
    }
}

/// Whether `bounds` contain `x` (faces included).
pub(super) fn holds<T: Real>(bounds: &Bounds<T>, x: V3<T>) -> bool {
    holds_within(bounds, x, T::ZERO)
}

/// Whether `bounds` widened by `margin` contain `x` (faces included).
pub(super) fn holds_within<T: Real>(bounds: &Bounds<T>, x: V3<T>, margin: T) -> bool {
    (0..3).all(|k| x.get(k) >= bounds[0].get(k) - margin && x.get(k) <= bounds[1].get(k) + margin)
}

impl<T: Real> BoxBvh<T> {
    /// A BVH over items given as `(id, bounds)`, within the traversal stacks however the
    /// boxes lie ([`shallow_bvh2`]); an error only where the f32 wide tree cannot be formed
    /// from it.
    pub(super) fn new(members: &[(u32, Bounds<T>)]) -> Result<Self, WideBvhError> {
        let finite =
            |b: &Bounds<T>| (0..3).all(|k| b[0].get(k).is_finite() && b[1].get(k).is_finite());
        let (bounded, unbounded): (Vec<_>, Vec<_>) = members.iter().partition(|(_, b)| finite(b));
        let boxes: Vec<Aabb> = bounded
            .iter()
            .map(|(_, b)| {
                let [lo, hi] = [b[0].to_f64(), b[1].to_f64()];
                Aabb::new(
                    Vec3A::from_array(lo.map(f32_down)),
                    Vec3A::from_array(hi.map(f32_up)),
                )
            })
            .collect();
        let unbounded = unbounded.iter().map(|(i, _)| *i).collect();
        if boxes.is_empty() {
            return Ok(BoxBvh {
                nodes: Vec::new(),
                items: Vec::new(),
                unbounded,
                wide: None,
            });
        }
        let bvh = shallow_bvh2(
            &boxes,
            BvhBuildParams {
                max_prims_per_leaf: 1,
                ..BvhBuildParams::medium_build()
            },
        );
        let corner = |v: Vec3A| V3::from_f64([v.x, v.y, v.z].map(f64::from));
        let wide = (T::NAME == "f32")
            .then(|| WideTree::from_bvh2(&bvh))
            .transpose()?;
        Ok(BoxBvh {
            nodes: bvh
                .nodes
                .iter()
                .map(|n| Node {
                    bounds: [corner(n.aabb.min), corner(n.aabb.max)],
                    first: n.first_index,
                    count: n.prim_count,
                })
                .collect(),
            items: bvh
                .primitive_indices
                .iter()
                .map(|&i| bounded[i as usize].0)
                .collect(),
            unbounded,
            wide,
        })
    }

    /// Calls `visit` on every item whose box the ray (`slabs`: its slab-test form) meets
    /// within `[tmin, limit]` by a test accepting every box the exact one does (leaves hold
    /// one item, so the leaf's box is the item's, rounded outward to f32), and on the
    /// unbounded items; nearer boxes first. `visit` tests the item and returns the limit
    /// from then on (the nearest crossing found so far; below `tmin` to stop). Boxes met
    /// exactly at the limit are still visited, so crossings tied with the best one are
    /// seen.
    pub(super) fn visit_ray(
        &self,
        ray: &Ray<T>,
        slabs: &RaySlabs<T>,
        tmin: T,
        mut limit: T,
        mut visit: impl FnMut(u32) -> T,
    ) {
        for &i in &self.unbounded {
            limit = visit(i);
            if limit < tmin {
                return;
            }
        }
        if self.nodes.is_empty() {
            return;
        }
        let (wide, wide_slabs) = match (&self.wide, slabs) {
            (Some(wide), RaySlabs::Wide(wide_slabs)) => (wide, wide_slabs),
            (_, RaySlabs::Binary(slabs)) => {
                return self.visit_binary(ray, slabs, tmin, limit, visit)
            }
            // f32 trees always have a wide form; a binary walk would answer the same.
            (None, RaySlabs::Wide(_)) => {
                return self.visit_binary(ray, &SlabRay::new(ray), tmin, limit, visit)
            }
        };
        // `T` is f32: the conversions are exact.
        let f32_of = |t: T| t.to_f64() as f32;
        let (tmin, mut limit) = (f32_of(tmin), f32_of(limit));
        wide.walk(wide_slabs, tmin, limit, |first, count| {
            for &i in &self.items[first as usize..(first + count) as usize] {
                limit = f32_of(visit(i));
                if limit < tmin {
                    break;
                }
            }
            limit
        });
    }

    /// [`Self::visit_ray`]'s walk of the binary tree, one box at a time.
    fn visit_binary(
        &self,
        ray: &Ray<T>,
        slabs: &SlabRay<T>,
        tmin: T,
        mut limit: T,
        mut visit: impl FnMut(u32) -> T,
    ) {
        // (node, entry parameter); children are pushed farther first. Node tests are
        // conservative (a superset of the exact slab test), so monotonicity holds.
        let entry = |b: &Bounds<T>, limit: T| slabs.entry_conservative(ray, b, tmin, limit);
        let mut stack = Stack::new((0u32, T::ZERO));
        if let Some(t) = entry(&self.nodes[0].bounds, limit) {
            stack.push((0, t));
        }
        while let Some((index, t)) = stack.pop() {
            if t > limit {
                continue;
            }
            let node = &self.nodes[index as usize];
            if node.count > 0 {
                for &i in &self.items[node.first as usize..(node.first + node.count) as usize] {
                    limit = visit(i);
                    if limit < tmin {
                        return;
                    }
                }
                continue;
            }
            let (a, b) = (node.first, node.first + 1);
            let ta = entry(&self.nodes[a as usize].bounds, limit);
            let tb = entry(&self.nodes[b as usize].bounds, limit);
            match (ta, tb) {
                (Some(ta), Some(tb)) if ta <= tb => {
                    stack.push((b, tb));
                    stack.push((a, ta));
                }
                (Some(ta), Some(tb)) => {
                    stack.push((a, ta));
                    stack.push((b, tb));
                }
                (Some(ta), None) => stack.push((a, ta)),
                (None, Some(tb)) => stack.push((b, tb)),
                (None, None) => {}
            }
        }
    }

    /// Appends the tree to the GPU's node and item arrays (indices made absolute); returns
    /// the root node (`u32::MAX` for an empty tree) and the range of the unbounded items.
    pub(super) fn export(
        &self,
        nodes: &mut Vec<BoxNode>,
        items: &mut Vec<u32>,
    ) -> (u32, std::ops::Range<u32>) {
        let unbounded = items.len() as u32..(items.len() + self.unbounded.len()) as u32;
        items.extend_from_slice(&self.unbounded);
        if self.nodes.is_empty() {
            return (u32::MAX, unbounded);
        }
        let (node_base, item_base) = (nodes.len() as u32, items.len() as u32);
        items.extend_from_slice(&self.items);
        nodes.extend(self.nodes.iter().map(|n| {
            let [lo, hi] = n.bounds.map(|c| c.to_f64().map(|v| v as f32));
            BoxNode {
                lo,
                first: n.first + if n.count > 0 { item_base } else { node_base },
                hi,
                count: n.count,
            }
        }));
        (node_base, unbounded)
    }

    /// Appends to `out` every item whose node boxes, widened by `margin`, contain `x` (a
    /// superset of those whose own bounds do), in no particular order.
    pub(super) fn candidates_near(&self, x: V3<T>, margin: T, out: &mut Vec<u32>) {
        self.visit_near(x, margin, |i| out.push(i));
    }

    /// Calls `visit` with what [`Self::candidates_near`] returns, in the same order.
    pub(super) fn visit_near(&self, x: V3<T>, margin: T, mut visit: impl FnMut(u32)) {
        self.unbounded.iter().for_each(|&i| visit(i));
        if self.nodes.is_empty() {
            return;
        }
        let mut stack = Stack::new(0u32);
        stack.push(0);
        while let Some(index) = stack.pop() {
            let node = &self.nodes[index as usize];
            if !holds_within(&node.bounds, x, margin) {
                continue;
            }
            if node.count > 0 {
                self.items[node.first as usize..(node.first + node.count) as usize]
                    .iter()
                    .for_each(|&i| visit(i));
            } else {
                stack.push(node.first);
                stack.push(node.first + 1);
            }
        }
    }
}
