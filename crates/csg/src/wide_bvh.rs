//! Eight-wide BVH nodes for the f32 CPU traversals: a binary BVH collapsed so that each node
//! holds up to 8 child boxes, tested against a ray all at once with SIMD (8 lanes of the
//! instruction set [`crate::simd`] chose: one AVX register, two SSE halves, NEON, or plain
//! arrays; the walks are generic over it). The triangle meshes' kernel
//! (`mesh::wide`, leaves of triangle blocks) and the tracer's box BVHs over instances and a
//! solid's prims (leaves of item ranges) share it.
//!
//! Collapsing: each wide node takes a binary node's two children and keeps opening its
//! largest inner child (by surface area) until it has 8 or only leaves are left. A wide
//! tree is no deeper than the binary one.
//!
//! The box test accepts every box the exact dividing slab test
//! ([`crate::ray_bounds_entry`]) accepts: it multiplies by the reciprocal direction and
//! widens the slab bounds by four machine epsilons of their size, as
//! [`crate::SlabRay::entry_conservative`] does; per axis, it divides where a non-zero
//! direction component has no finite reciprocal, and tests the origin against the slab
//! where the component is zero. The walk is a culling: callers whose answers do not depend
//! on the order leaves are visited in (nearest wins, ties by a fixed numbering) get the
//! answers an exhaustive search gives.
//!
//! A walk is either run to its end in one loop ([`WideTree::walk`]) or advanced one node
//! visit or leaf at a time (`Walker`), so that one thread can interleave the walks of
//! several rays, each prefetching what it reads next while the others work: the mesh
//! kernel's `MeshPrim::first_crossings`. Both share the node visit and the stack. Coherent
//! rays walk it as packets of 8 instead (`WideTree::walk_packet`, module `packet`).
//!
//! Why this shape, measured on the 1M-triangle heightfield of `cargo bench -p
//! hytrace-tests --bench mesh` (2-core VM, 2026-11-22, BENCHMARKS.md): the binary walk
//! reached 2.2-2.7 (coherent) and 0.9-1.1 (incoherent) Mrays/s; 4-wide nodes 4.4-5.7 and
//! 2.0-2.3; 8-wide nodes 5.3-7.4 and 2.2-2.9. Incoherent rays wait on memory: a profile puts
//! half of the mesh kernel's time on the first load of a node and of a triangle block, so
//! fewer levels (wider nodes) is what pays.

use std::mem::MaybeUninit;

use obvhs::bvh2::Bvh2;

use crate::real::{Ray, Real, V3};
use crate::simd::{Isa, Lanes, Portable};

mod packet;

pub use packet::{PacketSlabs, PACKET};

/// Children per node.
pub const WIDTH: usize = 8;

/// Deepest binary tree a wide tree is collapsed from (the traversal stack's size follows).
pub const MAX_DEPTH: usize = 64;

/// Entries the traversal stack may need: a node visit pushes at most `WIDTH - 1` siblings,
/// and the wide tree is at most [`MAX_DEPTH`] levels deep.
const STACK: usize = (WIDTH - 1) * MAX_DEPTH + 1;

/// A binary BVH that cannot be collapsed into a wide tree.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum WideBvhError {
    /// An inner node names children past the end of the node list.
    #[error("BVH node {node} names children {first} and {second} of {nodes} nodes")]
    MissingChild {
        /// The inner node.
        node: usize,
        /// Its first child.
        first: u32,
        /// Its second child.
        second: u64,
        /// Nodes in the tree.
        nodes: usize,
    },
    /// The tree is deeper than [`MAX_DEPTH`] (a cycle included).
    #[error("a BVH over {nodes} nodes is deeper than {MAX_DEPTH} levels")]
    TooDeep {
        /// Nodes in the tree.
        nodes: usize,
    },
    /// The leaf callback stored a leaf with no items.
    #[error("leaf node {node} was stored with no items")]
    EmptyLeaf {
        /// The leaf.
        node: usize,
    },
}

/// A node of the binary BVH a wide tree is collapsed from: its box, then either children
/// `first, first + 1` (`count == 0`) or a leaf's `count` items from `first`.
#[derive(Clone, Copy, Debug)]
pub struct BinaryNode {
    /// Box (min, max) in f32, containing everything below.
    pub bounds: [V3<f32>; 2],
    /// First child, or a leaf's first item.
    pub first: u32,
    /// A leaf's item count; 0 for an inner node.
    pub count: u32,
}

/// Eight child boxes and what they hold, lane by lane (256 bytes, four cache lines).
#[derive(Clone, Debug, PartialEq)]
#[repr(C, align(64))]
struct WideNode {
    /// Child boxes: min x, min y, min z, max x, max y, max z, one lane per child. Unused
    /// lanes hold empty boxes (min +inf, max -inf), which no ray enters.
    planes: [[f32; WIDTH]; 6],
    /// An inner child's node index (`count == 0`), or what the leaf callback made of a
    /// leaf's first item.
    child: [u32; WIDTH],
    /// What the leaf callback made of a leaf's item count (never 0); 0 for an inner child.
    count: [u32; WIDTH],
}

/// A BVH of eight-wide nodes; node 0 is the root.
#[derive(Clone, Debug, PartialEq)]
pub struct WideTree {
    nodes: Vec<WideNode>,
}

/// Surface area of a box (the collapse opens the largest inner child first).
fn area(b: &[V3<f32>; 2]) -> f32 {
    let e = b[1] - b[0];
    e.x * e.y + e.y * e.z + e.z * e.x
}

/// A child postponed by the walk, with its box entry.
#[derive(Clone, Copy, Default)]
struct Postponed {
    child: u32,
    count: u32,
    entry: f32,
}

impl WideTree {
    /// The wide form of a binary BVH (`nodes`, root first; empty for an empty tree).
    /// `leaf(first, count)` turns each binary leaf's item range into what the wide node
    /// stores for it, `(child, count)` with `count > 0`, for instance after copying the
    /// items into blocks of its own. An error when the binary tree is deeper than
    /// [`MAX_DEPTH`] (a cycle included), names a child it lacks, or a leaf is stored with no
    /// items.
    pub fn new(
        nodes: &[BinaryNode],
        mut leaf: impl FnMut(u32, u32) -> (u32, u32),
    ) -> Result<Self, WideBvhError> {
        if let Some(i) = nodes
            .iter()
            .position(|n| n.count == 0 && n.first as usize + 1 >= nodes.len())
        {
            return Err(WideBvhError::MissingChild {
                node: i,
                first: nodes[i].first,
                second: nodes[i].first as u64 + 1,
                nodes: nodes.len(),
            });
        }
        let mut tree = WideTree {
            nodes: Vec::with_capacity(nodes.len() / 4 + 1),
        };
        if !nodes.is_empty() {
            tree.collapse(nodes, 0, 1, &mut leaf)?;
        }
        Ok(tree)
    }

    /// The wide form of an obvhs binary BVH whose leaves keep their ranges of the BVH's
    /// `primitive_indices`; an error when it is deeper than [`MAX_DEPTH`].
    pub fn from_bvh2(bvh: &Bvh2) -> Result<Self, WideBvhError> {
        let binary: Vec<BinaryNode> = bvh
            .nodes
            .iter()
            .map(|n| BinaryNode {
                bounds: [n.aabb.min, n.aabb.max].map(|v| V3::new(v.x, v.y, v.z)),
                first: n.first_index,
                count: n.prim_count,
            })
            .collect();
        Self::new(&binary, |first, count| (first, count))
    }

    /// Adds the wide node that stands for binary node `index` (at wide depth `depth`) and,
    /// below it, its subtree; returns its index.
    fn collapse(
        &mut self,
        nodes: &[BinaryNode],
        index: usize,
        depth: usize,
        leaf: &mut impl FnMut(u32, u32) -> (u32, u32),
    ) -> Result<u32, WideBvhError> {
        if depth > MAX_DEPTH {
            return Err(WideBvhError::TooDeep { nodes: nodes.len() });
        }
        let n = &nodes[index];
        let mut children = if n.count == 0 {
            vec![n.first as usize, n.first as usize + 1]
        } else {
            vec![index]
        };
        while children.len() < WIDTH {
            let largest_inner = (0..children.len())
                .filter(|&i| nodes[children[i]].count == 0)
                .max_by(|&a, &b| {
                    area(&nodes[children[a]].bounds).total_cmp(&area(&nodes[children[b]].bounds))
                });
            let Some(i) = largest_inner else { break };
            let first = nodes[children[i]].first as usize;
            children[i] = first;
            children.push(first + 1);
        }
        let slot = self.nodes.len();
        self.nodes.push(WideNode {
            planes: [
                [f32::INFINITY; WIDTH],
                [f32::INFINITY; WIDTH],
                [f32::INFINITY; WIDTH],
                [f32::NEG_INFINITY; WIDTH],
                [f32::NEG_INFINITY; WIDTH],
                [f32::NEG_INFINITY; WIDTH],
            ],
            child: [0; WIDTH],
            count: [0; WIDTH],
        });
        for (lane, &c) in children.iter().enumerate() {
            let node = &nodes[c];
            let (child, count) = if node.count == 0 {
                (self.collapse(nodes, c, depth + 1, leaf)?, 0)
            } else {
                match leaf(node.first, node.count) {
                    (_, 0) => return Err(WideBvhError::EmptyLeaf { node: c }),
                    stored => stored,
                }
            };
            let w = &mut self.nodes[slot];
            for k in 0..3 {
                w.planes[k][lane] = node.bounds[0].get(k);
                w.planes[k + 3][lane] = node.bounds[1].get(k);
            }
            w.child[lane] = child;
            w.count[lane] = count;
        }
        Ok(slot as u32)
    }

    /// Bytes of the nodes.
    pub fn bytes(&self) -> usize {
        std::mem::size_of_val(self.nodes.as_slice())
    }

    /// Calls `leaf(child, count)` for every leaf whose boxes the ray (`slabs`) meets within
    /// `[after, limit]`, nearer boxes first; `leaf` tests what it holds and returns the limit
    /// from then on (the nearest crossing so far; below `after` to stop). Boxes met exactly
    /// at the limit are still visited, so crossings tied with the best one are seen. Runs
    /// on the portable SIMD path.
    #[inline(always)]
    pub fn walk(
        &self,
        slabs: &WideSlabs,
        after: f32,
        limit: f32,
        leaf: impl FnMut(u32, u32) -> f32,
    ) {
        self.walk_with::<Portable>(slabs, after, limit, leaf);
    }

    /// [`Self::walk`] with the vectors of `S`.
    #[inline(always)]
    pub(crate) fn walk_with<S: Isa>(
        &self,
        slabs: &WideSlabs,
        after: f32,
        mut limit: f32,
        mut leaf: impl FnMut(u32, u32) -> f32,
    ) {
        // [`Walker::step`]'s walk in one loop, its state in registers: measured 10-20% faster
        // on coherent mesh rays than stepping a walker to the end.
        if self.nodes.is_empty() {
            return;
        }
        let mut stack = [MaybeUninit::<Postponed>::uninit(); STACK];
        let mut top = 0;
        let (mut child, mut count) = (0u32, 0u32);
        loop {
            if count == 0 {
                let node = &self.nodes[child as usize];
                let (hit, entries) = slabs.entries::<S>(node, after, limit);
                if hit != 0 {
                    (child, count) = enter(node, hit, &entries, &mut stack, &mut top);
                    continue;
                }
            } else {
                limit = leaf(child, count);
                if limit < after {
                    return;
                }
            }
            match resume(&stack, &mut top, limit) {
                Some(next) => (child, count) = next,
                None => return,
            }
        }
    }
}

/// The child of `node` to visit next among the entered ones `hit` (their `entries`): the
/// only one, or the nearest, the others postponed on `stack[..top]`, farthest deepest.
#[inline(always)]
fn enter(
    node: &WideNode,
    hit: u32,
    entries: &[f32; WIDTH],
    stack: &mut [MaybeUninit<Postponed>; STACK],
    top: &mut usize,
) -> (u32, u32) {
    // (`count_ones` would be a bit-trick sequence without POPCNT, which the baseline
    // x86-64 target lacks.)
    if hit & (hit - 1) == 0 {
        let lane = hit.trailing_zeros() as usize;
        return (node.child[lane], node.count[lane]);
    }
    // Insertion sort, farthest first.
    let mut entered = [Postponed::default(); WIDTH];
    let mut n = 0;
    let mut bits = hit;
    while bits != 0 {
        let lane = bits.trailing_zeros() as usize;
        bits &= bits - 1;
        let e = Postponed {
            child: node.child[lane],
            count: node.count[lane],
            entry: entries[lane],
        };
        let mut at = n;
        while at > 0 && entered[at - 1].entry < e.entry {
            entered[at] = entered[at - 1];
            at -= 1;
        }
        entered[at] = e;
        n += 1;
    }
    for e in &entered[..n - 1] {
        stack[*top].write(*e);
        *top += 1;
    }
    (entered[n - 1].child, entered[n - 1].count)
}

/// The nearest postponed child on `stack[..top]` still entered within `limit` (boxes
/// entered exactly there may hold a tied crossing), popping those that are not; `None`
/// when none is left.
#[inline(always)]
fn resume(
    stack: &[MaybeUninit<Postponed>; STACK],
    top: &mut usize,
    limit: f32,
) -> Option<(u32, u32)> {
    while *top > 0 {
        *top -= 1;
        // SAFETY: entries below `top` were written by `enter` (each push writes
        // `stack[top]` before raising `top`), and `top` never exceeds `STACK`: each level of
        // the at most `MAX_DEPTH` deep tree pushes at most `WIDTH - 1` siblings.
        let e = unsafe { stack[*top].assume_init() };
        if e.entry <= limit {
            return Some((e.child, e.count));
        }
    }
    None
}

/// A walk of a [`WideTree`] that advances one node visit or one leaf at a time, so one
/// thread can keep the walks of several rays going, each waiting on memory while the others
/// work ([`Walker::step`]). [`WideTree::walk`] runs the same walk in one loop.
pub(crate) struct Walker {
    /// Postponed children, the nearest on top; only `stack[..top]` is ever read.
    stack: [MaybeUninit<Postponed>; STACK],
    top: usize,
    /// What the walk visits next: an inner node (`count == 0`) or a leaf.
    child: u32,
    count: u32,
    /// The nearest crossing so far, or the caller's limit.
    limit: f32,
}

impl Walker {
    /// A walker, to be [`Walker::restart`]ed before use (its stack stays uninitialized:
    /// a walker is reused, not rebuilt, since it is large).
    pub(crate) fn new() -> Self {
        Walker {
            stack: [MaybeUninit::uninit(); STACK],
            top: 0,
            child: 0,
            count: 0,
            limit: f32::NEG_INFINITY,
        }
    }

    /// Starts a walk from the root, within `limit`.
    #[inline(always)]
    pub(crate) fn restart(&mut self, limit: f32) {
        self.top = 0;
        self.child = 0;
        self.count = 0;
        self.limit = limit;
    }

    /// Visits the next node or leaf of `tree` the ray (`slabs`) meets within
    /// `[after, limit]` (see [`WideTree::walk`] for `leaf`); false once the walk is over.
    /// With `AHEAD`, the memory the following step reads (a node, or through
    /// `prefetch_leaf(child, count)` a leaf's items) is asked for before returning: it
    /// arrives while the caller steps other walks.
    #[inline(always)]
    pub(crate) fn step<S: Isa, const AHEAD: bool>(
        &mut self,
        tree: &WideTree,
        slabs: &WideSlabs,
        after: f32,
        leaf: &mut impl FnMut(u32, u32) -> f32,
        prefetch_leaf: impl Fn(u32, u32),
    ) -> bool {
        if tree.nodes.is_empty() {
            return false;
        }
        let next = if self.count == 0 {
            let node = &tree.nodes[self.child as usize];
            let (hit, entries) = slabs.entries::<S>(node, after, self.limit);
            if hit != 0 {
                Some(enter(node, hit, &entries, &mut self.stack, &mut self.top))
            } else {
                resume(&self.stack, &mut self.top, self.limit)
            }
        } else {
            self.limit = leaf(self.child, self.count);
            if self.limit < after {
                return false;
            }
            resume(&self.stack, &mut self.top, self.limit)
        };
        let Some((child, count)) = next else {
            return false;
        };
        (self.child, self.count) = (child, count);
        if AHEAD {
            if count == 0 {
                prefetch_lines(&tree.nodes[child as usize]);
            } else {
                prefetch_leaf(child, count);
            }
        }
        true
    }
}

/// Asks the caches for the lines of `item` ahead of its use; only a hint (a no-op off
/// x86-64).
#[inline(always)]
pub(crate) fn prefetch_lines<T>(item: &T) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
        let p = (item as *const T).cast::<i8>();
        for line in 0..size_of::<T>().div_ceil(64) {
            // SAFETY: a prefetch reads nothing and never faults; the addresses lie within
            // `item` anyway.
            unsafe { _mm_prefetch::<_MM_HINT_T0>(p.wrapping_add(64 * line)) };
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = item;
}

/// How one axis of the slab test is computed for a ray.
#[derive(Clone, Copy, PartialEq)]
enum Axis {
    /// By the reciprocal direction component.
    Multiply,
    /// By dividing, for a non-zero component without a finite reciprocal (subnormal).
    Divide,
    /// The component is zero: the ray is inside the slab at every distance or never.
    Parallel,
}

/// The per-ray part of the node-wide slab test.
pub struct WideSlabs {
    origin: [f32; 3],
    /// Per axis: the reciprocal direction component, or (`Axis::Divide`) the component.
    scale: [f32; 3],
    /// Which of `planes` is each axis' entry plane (min for a positive component).
    near: [usize; 3],
    axis: [Axis; 3],
}

impl WideSlabs {
    /// The slab-test form of `ray`.
    #[inline]
    pub fn new(ray: &Ray<f32>) -> Self {
        // Per axis: how it is tested, and the reciprocal (or, to divide by, the component).
        // Written out axis by axis: maps of closures over `[0, 1, 2]` were left as calls, a
        // fifth of the instructions of a walk over one or two nodes.
        let axis = |d: f32| -> (Axis, f32) {
            let inv = 1.0 / d;
            if d == 0.0 {
                (Axis::Parallel, inv)
            } else if inv.is_finite() {
                (Axis::Multiply, inv)
            } else {
                (Axis::Divide, d)
            }
        };
        let ((ax, sx), (ay, sy), (az, sz)) = (
            axis(ray.direction.x),
            axis(ray.direction.y),
            axis(ray.direction.z),
        );
        let near = |d: f32, k: usize| if d >= 0.0 { k } else { k + 3 };
        let near = [
            near(ray.direction.x, 0),
            near(ray.direction.y, 1),
            near(ray.direction.z, 2),
        ];
        WideSlabs {
            origin: [ray.origin.x, ray.origin.y, ray.origin.z],
            scale: [sx, sy, sz],
            near,
            axis: [ax, ay, az],
        }
    }

    /// Which children's boxes the ray enters within `[after, limit]` (bit per lane) and
    /// where (see the module doc for why no box the exact test accepts is missed).
    #[inline(always)]
    fn entries<S: Isa>(&self, node: &WideNode, after: f32, limit: f32) -> (u32, [f32; WIDTH]) {
        let mut span = SlabSpan::<S::F8>::new();
        for k in 0..3 {
            let (near, far) = SlabSpan::<S::F8>::planes(node, self.near[k]);
            let o = S::F8::splat(self.origin[k]);
            let scale = S::F8::splat(self.scale[k]);
            let (t0, t1) = match self.axis[k] {
                Axis::Multiply => ((near - o) * scale, (far - o) * scale),
                Axis::Divide => ((near - o) / scale, (far - o) / scale),
                Axis::Parallel => {
                    // Inside the slab or not, at every distance.
                    span.inside = span.inside & near.le(o) & o.le(far);
                    continue;
                }
            };
            span.entry = span.entry.max(t0);
            span.exit = span.exit.min(t1);
        }
        span.hits(S::F8::splat(after), S::F8::splat(limit))
    }
}

/// A node's slab test in progress, lane by lane: the latest entry and earliest exit over
/// the axes so far, and whether every axis without a direction component holds the origin
/// (all ones).
struct SlabSpan<L> {
    entry: L,
    exit: L,
    inside: L,
}

impl<L: Lanes<Array = [f32; WIDTH]>> SlabSpan<L> {
    /// No axis yet: entered at -inf, left at +inf, inside.
    #[inline(always)]
    fn new() -> Self {
        SlabSpan {
            entry: L::splat(f32::NEG_INFINITY),
            exit: L::splat(f32::INFINITY),
            inside: L::splat(f32::from_bits(u32::MAX)),
        }
    }

    /// The planes of every child of `node` on one axis: plane `near_of` (where a ray
    /// enters that axis' slab) and the opposite one.
    #[inline(always)]
    fn planes(node: &WideNode, near_of: usize) -> (L, L) {
        (
            L::load(&node.planes[near_of]),
            L::load(&node.planes[(near_of + 3) % 6]),
        )
    }

    /// The lanes (bit per lane) whose span, widened, overlaps `[after, limit]` while
    /// inside, and the widened entries clipped to `after`. Widened by four machine
    /// epsilons of their size, more than the reciprocal's error; by multiplying, which
    /// keeps the empty lanes' infinities (no inf - inf). The widening is a monotonic
    /// function of the entry and of the exit (packet tests rely on it).
    #[inline(always)]
    fn hits(self, after: L, limit: L) -> (u32, [f32; WIDTH]) {
        let (less, more) = (
            L::splat(1.0 - 4.0 * f32::EPSILON),
            L::splat(1.0 + 4.0 * f32::EPSILON),
        );
        let negative = |t: L| t.lt(L::splat(0.0));
        let SlabSpan {
            entry,
            exit,
            inside,
        } = self;
        let entry = (entry * negative(entry).select(more, less)).max(after);
        let exit = (exit * negative(exit).select(less, more)).min(limit);
        let hit = (entry.le(exit) & inside).bitmask();
        (hit, entry.to_array())
    }
}

/// A point or direction in f32 (exact when `T` is f32, the precision wide trees serve).
pub fn point_f32<T: Real>(p: V3<T>) -> V3<f32> {
    V3::new(
        p.x.to_f64() as f32,
        p.y.to_f64() as f32,
        p.z.to_f64() as f32,
    )
}

/// A ray in f32 (exact when `T` is f32).
pub fn ray_f32<T: Real>(ray: &Ray<T>) -> Ray<f32> {
    Ray {
        origin: point_f32(ray.origin),
        direction: point_f32(ray.direction),
    }
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use glam::Vec3A;
    use obvhs::aabb::Aabb;
    use obvhs::bvh2::builder::build_bvh2;
    use obvhs::BvhBuildParams;

    use super::*;
    use crate::prim_tree::ray_bounds_entry;
    use crate::simd::{run_on, Kernel, SimdPath};
    use crate::test_common::{Random, Rng};

    /// Random boxes, a wide tree over them (leaves of up to 4 boxes) and the box numbers in
    /// leaf order.
    struct Forest {
        boxes: Vec<[V3<f32>; 2]>,
        tree: WideTree,
        order: Vec<u32>,
    }

    impl Forest {
        /// Boxes around `centre` (f32 corners), some flat in one axis.
        fn new(rng: &mut Rng, n: usize, centre: f64, size: f64) -> Self {
            let boxes: Vec<[V3<f32>; 2]> = (0..n)
                .map(|_| {
                    let c = [0; 3].map(|_| centre + rng.range(-size, size));
                    // Some boxes flat in one axis (a face's box), most not.
                    let e = [0; 3].map(|_| {
                        if rng.range(0.0, 1.0) < 0.1 {
                            0.0
                        } else {
                            rng.range(0.0, 0.1 * size)
                        }
                    });
                    [
                        V3::from_f64([0, 1, 2].map(|k| c[k] - e[k])),
                        V3::from_f64([0, 1, 2].map(|k| c[k] + e[k])),
                    ]
                })
                .collect();
            let aabbs: Vec<Aabb> = boxes
                .iter()
                .map(|b| {
                    Aabb::new(
                        Vec3A::new(b[0].x, b[0].y, b[0].z),
                        Vec3A::new(b[1].x, b[1].y, b[1].z),
                    )
                })
                .collect();
            let params = BvhBuildParams {
                max_prims_per_leaf: 4,
                ..BvhBuildParams::fast_build()
            };
            let bvh = build_bvh2(&aabbs, params, &mut Duration::default());
            let tree = WideTree::from_bvh2(&bvh).unwrap();
            Forest {
                boxes,
                tree,
                order: bvh.primitive_indices,
            }
        }

        /// Checks that walking the tree (the limit never lowered) reaches every box the
        /// exact dividing test finds the ray meeting within `[after, limit]`; returns how many.
        fn window(&self, origin: [f64; 3], direction: [f64; 3], after: f32, limit: f32) -> usize {
            let ray = &Ray::<f32>::from_f64(origin, direction);
            /// The boxes a walk reaches, as a [`Kernel`].
            struct Reach<'a>(&'a Forest, &'a WideSlabs, f32, f32);
            impl Kernel for Reach<'_> {
                type Output = Vec<bool>;
                fn run<S: Isa>(self) -> Vec<bool> {
                    let Reach(forest, slabs, after, limit) = self;
                    let mut reached = vec![false; forest.boxes.len()];
                    forest
                        .tree
                        .walk_with::<S>(slabs, after, limit, |first, count| {
                            for &i in &forest.order[first as usize..(first + count) as usize] {
                                reached[i as usize] = true;
                            }
                            limit
                        });
                    reached
                }
            }
            let slabs = WideSlabs::new(ray);
            let reached = run_on(SimdPath::Portable, Reach(self, &slabs, after, limit));
            // Every path reaches the same boxes (its node test gives the same bits).
            for path in SimdPath::available() {
                assert!(
                    run_on(path, Reach(self, &slabs, after, limit)) == reached,
                    "{path} reaches other boxes than the portable path for {ray:?}"
                );
            }
            let mut met = 0;
            for (i, b) in self.boxes.iter().enumerate() {
                if ray_bounds_entry(ray, b, after, limit).is_some() {
                    met += 1;
                    assert!(
                        reached[i],
                        "box {i} {b:?} met by {ray:?} in [{after}, {limit}] not reached"
                    );
                }
            }
            met
        }

        /// [`Self::window`] over the whole ray.
        fn whole(&self, origin: [f64; 3], direction: [f64; 3]) -> usize {
            self.window(origin, direction, 0.0, f32::INFINITY)
        }
    }

    #[test]
    fn wide_walk_reaches_every_box_the_exact_test_meets_near_and_far_from_the_origin() {
        let mut rng = Rng(0x2545_f491_4f6c_dd1d);
        for centre in [0.0, 1.0e6, -3.0e7] {
            let forest = Forest::new(&mut rng, 3000, centre, 100.0);
            let mut met = 0;
            for _ in 0..3000 {
                let o = [0; 3].map(|_| centre + rng.range(-150.0, 150.0));
                met += forest.whole(o, rng.direction());
                // A window of the ray, as a closest-hit search's shrinking limit makes.
                let (a, b) = (rng.range(-50.0, 100.0) as f32, rng.range(0.0, 300.0) as f32);
                met += forest.window(o, rng.direction(), a, a + b);
            }
            assert!(met > 10_000, "only {met} boxes met around {centre}");
        }
    }

    #[test]
    fn wide_walk_reaches_boxes_for_zero_and_subnormal_direction_components() {
        let mut rng = Rng(99);
        let forest = Forest::new(&mut rng, 2000, 0.0, 50.0);
        let mut met = 0;
        for _ in 0..2000 {
            let o = [0; 3].map(|_| rng.range(-60.0, 60.0));
            let u = rng.direction();
            for zeroed in [
                [true, false, false],
                [false, true, true],
                [true, true, false],
            ] {
                let d = [0, 1, 2].map(|k| if zeroed[k] { 0.0 } else { u[k] });
                if d.iter().all(|c| *c == 0.0) {
                    continue;
                }
                met += forest.whole(o, d);
            }
            // A subnormal component: its reciprocal overflows, that axis divides.
            let d = [u[0], 1.0e-40, u[2]];
            met += forest.whole(o, d);
        }
        assert!(met > 5_000, "only {met} boxes met");
    }

    #[test]
    fn wide_walk_reaches_boxes_grazed_along_faces_and_touched_at_corners() {
        let mut rng = Rng(5);
        let forest = Forest::new(&mut rng, 1000, 10.0, 20.0);
        let mut met = 0;
        for (i, b) in forest.boxes.iter().enumerate() {
            // Along a face plane of box `i` (origin on the plane, direction in it), and
            // touching its edge.
            let k = i % 3;
            let mut o = [0, 1, 2].map(|j| f64::from(b[0].get(j)) - 5.0);
            o[k] = f64::from(b[1].get(k));
            let mut d = [1.0, 1.0, 1.0];
            d[k] = 0.0;
            met += forest.whole(o, d);
            let mut d = rng.direction();
            d[k] = 0.0;
            met += forest.whole(o, d);
            // Aimed from afar at a corner, where the slabs' entry and exit meet: rounding
            // decides whether the ray touches the box, and the walk must not disagree.
            for corner in 0..8 {
                let c = [0, 1, 2].map(|j| f64::from(b[(corner >> j) & 1].get(j)));
                let d = rng.direction();
                let o = [0, 1, 2].map(|j| c[j] - 1.0e3 * d[j]);
                met += forest.whole(o, d);
            }
        }
        assert!(met > 1_000, "only {met} boxes met");
    }

    #[test]
    fn malformed_trees_are_errors_not_panics() {
        let unit = [V3::new(0.0, 0.0, 0.0), V3::new(1.0, 1.0, 1.0)];
        let node = |first, count| BinaryNode {
            bounds: unit,
            first,
            count,
        };
        let keep = |first, count| (first, count);
        // A child index past the end.
        let err = WideTree::new(&[node(1, 0), node(0, 1)], keep).unwrap_err();
        assert!(
            err.to_string()
                .contains("names children 1 and 2 of 2 nodes"),
            "{err}"
        );
        // A cycle: node 1's children are the root and node 1 again.
        let err = WideTree::new(&[node(1, 0), node(0, 0), node(0, 1)], keep).unwrap_err();
        assert!(err.to_string().contains("deeper than"), "{err}");
        // A leaf stored with no items.
        let err = WideTree::new(&[node(1, 0), node(0, 1), node(1, 1)], |first, _| (first, 0))
            .unwrap_err();
        assert!(err.to_string().contains("no items"), "{err}");
        assert!(WideTree::new(&[node(1, 0), node(0, 1), node(1, 1)], keep).is_ok());
    }
}
