//! Packets of coherent rays walking a [`WideTree`] together: each inner node is fetched and
//! tested once for the whole packet, by one slab test of the packet's bounds (the interval
//! of its origins and of its reciprocal directions, per axis), and only the nodes that hold
//! leaves are tested ray by ray, to hand each ray exactly the leaves its own test accepts.
//!
//! The packet's test accepts every box any of its rays' tests ([`WideSlabs::entries`])
//! accepts, and its entry is never beyond theirs: rounding is monotonic, so bounding each
//! operand of the per-ray test by the packet's interval bounds each rounded result. Each
//! ray thus reaches every leaf its own walk would (and maybe more), and a caller whose
//! answers do not depend on the order leaves are visited in (the nearest crossing, ties by
//! a fixed numbering) gets, ray by ray, the answers of [`WideTree::walk`].

use std::mem::MaybeUninit;

use super::{enter, prefetch_lines, resume, Postponed, SlabSpan, WideNode, WideTree, STACK, WIDTH};
use crate::real::Ray;
use crate::simd::{Isa, Lanes};

/// Most rays a packet holds: one per lane of the 8-lane vectors.
pub const PACKET: usize = 8;

/// An array of `f(lane)` for every lane of a packet.
fn lanes(f: impl Fn(usize) -> f32) -> [f32; PACKET] {
    std::array::from_fn(f)
}

/// The per-packet part of the node-wide slab test: per axis, bounds of the rays' origins
/// and reciprocal direction components, the rays all of one sign on each axis.
pub struct PacketSlabs {
    /// Per axis, the origin bound that gives the lowest entry: the highest origin for a
    /// positive direction, the lowest for a negative one; for a zero component, the
    /// highest origin.
    entry_origin: [f32; 3],
    /// Per axis, the origin bound that gives the highest exit (the other one).
    exit_origin: [f32; 3],
    /// Per axis, the lowest and highest reciprocal direction component.
    scale: [[f32; 2]; 3],
    /// Which of the node's planes is each axis' entry plane (min for a positive component).
    near: [usize; 3],
    /// Per axis: whether the rays' components are all zero.
    parallel: [bool; 3],
    /// The rays lane by lane (lanes past the last ray repeat it): per axis, the origin and
    /// the reciprocal direction component, as [`WideSlabs`] holds them for one ray.
    origin: [[f32; PACKET]; 3],
    inverse: [[f32; PACKET]; 3],
    /// The rays, in lanes from the first.
    rays: usize,
}

impl PacketSlabs {
    /// The packet form of `rays` (at most [`PACKET`], at least one), or `None` when it has
    /// none: on some axis the rays' direction components differ in sign, some are zero and
    /// some not, or one has no finite reciprocal.
    pub fn new(rays: &[Ray<f32>]) -> Option<Self> {
        if rays.is_empty() || rays.len() > PACKET {
            return None;
        }
        // Lanes past the last ray repeat it, so bounds over all lanes are the rays' bounds.
        let lane = |i: usize| &rays[i.min(rays.len() - 1)];
        let mut packet = PacketSlabs {
            entry_origin: [0.0; 3],
            exit_origin: [0.0; 3],
            scale: [[0.0; 2]; 3],
            near: [0; 3],
            parallel: [false; 3],
            origin: [[0.0; PACKET]; 3],
            inverse: [[0.0; PACKET]; 3],
            rays: rays.len(),
        };
        for k in 0..3 {
            let d = lanes(|i| lane(i).direction.get(k));
            let o = lanes(|i| lane(i).origin.get(k));
            let inv = d.map(|d| 1.0 / d);
            let (positive, parallel) = (d[0] >= 0.0, d[0] == 0.0);
            let alike = (0..PACKET).all(|i| {
                (d[i] >= 0.0) == positive
                    && (d[i] == 0.0) == parallel
                    && (parallel || inv[i].is_finite())
            });
            if !alike {
                return None;
            }
            let low = |v: &[f32; PACKET]| v.iter().copied().fold(f32::INFINITY, f32::min);
            let high = |v: &[f32; PACKET]| v.iter().copied().fold(f32::NEG_INFINITY, f32::max);
            // The entry (near plane - origin) * inverse is lowest for the highest origin
            // when the inverse is positive (a zero component counts as positive here).
            let (entry_o, exit_o) = if positive {
                (high(&o), low(&o))
            } else {
                (low(&o), high(&o))
            };
            packet.entry_origin[k] = entry_o;
            packet.exit_origin[k] = exit_o;
            packet.scale[k] = [low(&inv), high(&inv)];
            packet.near[k] = if positive { k } else { k + 3 };
            packet.parallel[k] = parallel;
            packet.origin[k] = o;
            packet.inverse[k] = inv;
        }
        Some(packet)
    }

    /// Which children's boxes some ray of the packet may enter within `[after, limit]` (bit
    /// per lane), and a lower bound of each one's entry for every ray: `after` is the
    /// lowest of the rays' and `limit` the highest.
    #[inline(always)]
    fn entries<S: Isa>(&self, node: &WideNode, after: f32, limit: f32) -> (u32, [f32; WIDTH]) {
        let mut span = SlabSpan::<S::F8>::new();
        for k in 0..3 {
            let (near, far) = SlabSpan::<S::F8>::planes(node, self.near[k]);
            let entry_origin = S::F8::splat(self.entry_origin[k]);
            let exit_origin = S::F8::splat(self.exit_origin[k]);
            if self.parallel[k] {
                // Some origin inside the slab, at every distance.
                span.inside = span.inside & near.le(entry_origin);
                span.inside = span.inside & exit_origin.le(far);
                continue;
            }
            // Each ray's (near - o) * inv is at least the lowest product of the bounding
            // difference with either end of the reciprocals' interval (the product is
            // monotonic in each factor, and so is its rounding); likewise for the exit.
            let [lo, hi] = self.scale[k].map(S::F8::splat);
            let x0 = near - entry_origin;
            let x1 = far - exit_origin;
            span.entry = span.entry.max((x0 * lo).min(x0 * hi));
            span.exit = span.exit.min((x1 * lo).max(x1 * hi));
        }
        // The per-ray test's widening, monotonic in the entry and in the exit.
        span.hits(S::F8::splat(after), S::F8::splat(limit))
    }
}

impl PacketSlabs {
    /// Which rays of the packet (bit per ray) enter the box of lane `lane` of `node` within
    /// `[after, limit]` (each ray's, lane by lane), and where: for each ray, what
    /// [`WideSlabs::entries`] answers for that box, by the same operations.
    #[inline(always)]
    fn rays_entering<S: Isa>(
        &self,
        node: &WideNode,
        lane: usize,
        after: S::F8,
        limit: S::F8,
    ) -> (u32, [f32; PACKET]) {
        let mut span = SlabSpan::<S::F8>::new();
        for k in 0..3 {
            let near = S::F8::splat(node.planes[self.near[k]][lane]);
            let far = S::F8::splat(node.planes[(self.near[k] + 3) % 6][lane]);
            let o = S::F8::load(&self.origin[k]);
            if self.parallel[k] {
                span.inside = span.inside & (near.le(o) & o.le(far));
                continue;
            }
            let inverse = S::F8::load(&self.inverse[k]);
            span.entry = span.entry.max((near - o) * inverse);
            span.exit = span.exit.min((far - o) * inverse);
        }
        let (hit, entries) = span.hits(after, limit);
        (hit & ((1 << self.rays) - 1), entries)
    }
}

/// The lanes of `node` that hold leaves (bit per lane).
#[inline(always)]
fn leaf_lanes<S: Isa>(node: &WideNode) -> u32 {
    S::nonzero(&node.count)
}

impl WideTree {
    /// [`WideTree::walk`] of a packet of rays (`packet`; each ray's `after` and `limits` in
    /// its lane, lanes past the last ray holding a limit of -inf): calls
    /// `leaf(ray, child, count)` for every leaf whose boxes ray `ray` meets within
    /// `[after[ray], limits[ray]]`, and sets the ray's limit to what it returns (the
    /// nearest crossing so far; never below its `after`). Inner nodes are visited once for
    /// the packet, nearer boxes first by the packet's entries; so are the leaves under a
    /// node, each tested against every ray at once (by the operations of
    /// [`WideTree::walk`]'s test, lane by lane). Each
    /// visit asks for the memory of every child the packet enters (a node, or through
    /// `prefetch_leaf(child, count)` a leaf's items): a coherent packet visits most of
    /// them, and their misses then overlap.
    #[inline(always)]
    pub(crate) fn walk_packet<S: Isa>(
        &self,
        packet: &PacketSlabs,
        after: &[f32; PACKET],
        limits: &mut [f32; PACKET],
        mut leaf: impl FnMut(usize, u32, u32) -> f32,
        prefetch_leaf: impl Fn(u32, u32),
    ) {
        if self.nodes.is_empty() {
            return;
        }
        let lowest_after = after.iter().copied().fold(f32::INFINITY, f32::min);
        let after_lanes = S::F8::load(after);
        let highest = |limits: &[f32]| limits.iter().copied().fold(f32::NEG_INFINITY, f32::max);
        let mut limit = highest(limits);
        let mut stack = [MaybeUninit::<Postponed>::uninit(); STACK];
        let mut top = 0;
        let mut child = 0u32;
        loop {
            let node = &self.nodes[child as usize];
            let (hit, entries) = packet.entries::<S>(node, lowest_after, limit);
            let leaves = hit & leaf_lanes::<S>(node);
            let mut lanes = hit;
            while lanes != 0 {
                let lane = lanes.trailing_zeros() as usize;
                lanes &= lanes - 1;
                if node.count[lane] == 0 {
                    prefetch_lines(&self.nodes[node.child[lane] as usize]);
                } else {
                    prefetch_leaf(node.child[lane], node.count[lane]);
                }
            }
            let mut lanes = leaves;
            while lanes != 0 {
                // The leaf the packet enters first among those left.
                let mut lane = lanes.trailing_zeros() as usize;
                let mut rest = lanes & (lanes - 1);
                while rest != 0 {
                    let other = rest.trailing_zeros() as usize;
                    rest &= rest - 1;
                    if entries[other] < entries[lane] {
                        lane = other;
                    }
                }
                lanes &= !(1 << lane);
                let (mut rays, _) =
                    packet.rays_entering::<S>(node, lane, after_lanes, S::F8::load(limits));
                while rays != 0 {
                    let ray = rays.trailing_zeros() as usize;
                    rays &= rays - 1;
                    limits[ray] = leaf(ray, node.child[lane], node.count[lane]);
                }
            }
            if leaves != 0 {
                limit = highest(limits);
            }
            let inner = hit & !leaves;
            let next = if inner != 0 {
                Some(enter(node, inner, &entries, &mut stack, &mut top))
            } else {
                resume(&stack, &mut top, limit)
            };
            match next {
                Some((next, _)) => child = next,
                None => return,
            }
        }
    }
}
