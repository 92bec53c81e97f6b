//! Binary BVH builds that stay within the traversal stacks on any input: obvhs' PLOC build
//! where it works, a top-down median-split build where it does not.
//!
//! PLOC merges mutual nearest neighbours in Morton order. Where many boxes coincide (a
//! volume placed many times at one position) or nest around one point (the fan of
//! triangles an OBJ polygon becomes), few pairs are mutual, so each pass merges one pair:
//! the tree becomes a chain as deep as the input is long, and the build takes quadratic
//! time. The median-split build halves every range on the longest axis of its box
//! centres (equal centres ordered by index), so it is `ceil(log2(n / leaf))` levels deep
//! whatever the boxes, in `O(n log n)` time. Inputs known to chain (many coincident boxes,
//! a vertex shared by very many triangles) skip PLOC; other inputs fall back to the median
//! split only when the PLOC tree comes out too deep.
//!
//! What a mesh build costs (the 1M-triangle heightfield of `cargo bench -p hytrace-tests
//! --bench mesh`, one thread, 2026-11-28): obvhs' PLOC passes and reinsertion are most
//! of it; its last step, the SAH leaf collapse, copied and reordered the whole tree, which
//! the mesh then copied and reordered again for its own layout, so the collapse is only
//! decided here ([`LeafPlan`], the same decisions) and the mesh applies it while it lays
//! the tree out. The checks for chaining inputs count by hash bucket before they sort.

use std::time::Duration;

use obvhs::aabb::Aabb;
use obvhs::bvh2::builder::{build_bvh2, build_bvh2_from_tris};
use obvhs::bvh2::node::Bvh2Node;
use obvhs::bvh2::reinsertion::ReinsertionOptimizer;
use obvhs::bvh2::Bvh2;
use obvhs::ploc::PlocBuilder;
use obvhs::triangle::Triangle;
use obvhs::{Boundable, BvhBuildParams};

use crate::wide_bvh::MAX_DEPTH as MAX_BVH_DEPTH;

/// Boxes that coincide exactly beyond this many make PLOC chain them; such inputs go
/// straight to the median split.
const MAX_COINCIDENT: usize = 16;

/// Levels below the root of an obvhs BVH2 (0 for a single leaf or an empty tree): the
/// traversal stack a tree needs.
pub fn bvh2_depth(nodes: &[Bvh2Node]) -> usize {
    binary_tree_depth(|i| {
        let n = nodes.get(i)?;
        Some((n.prim_count == 0).then_some(n.first_index as usize))
    })
}

/// Levels below the root of a binary tree in an array whose inner nodes have their children
/// at `first, first + 1`: `node(i)` is `None` where there is no node `i`, `Some(None)` for
/// a leaf and `Some(Some(first))` for an inner node.
pub(crate) fn binary_tree_depth(node: impl Fn(usize) -> Option<Option<usize>>) -> usize {
    let mut deepest = 0;
    let mut stack = vec![(0usize, 0usize)];
    while let Some((index, depth)) = stack.pop() {
        let Some(children) = node(index) else {
            continue;
        };
        deepest = deepest.max(depth);
        if let Some(first) = children {
            stack.push((first, depth + 1));
            stack.push((first + 1, depth + 1));
        }
    }
    deepest
}

/// A BVH over `boxes` at most [`crate::wide_bvh::MAX_DEPTH`] deep (what the traversals'
/// fixed stacks, CPU and GPU, accept): obvhs' build with `params`, or the
/// median split where many boxes coincide or the PLOC tree is too deep.
pub fn shallow_bvh2(boxes: &[Aabb], params: BvhBuildParams) -> Bvh2 {
    shallow(boxes, params, || {
        build_bvh2(boxes, params, &mut Duration::default())
    })
}

/// [`shallow_bvh2`] over triangles (obvhs' triangle build, with its splits of large
/// triangles where `params` asks for them; the median split bounds whole triangles), with
/// the leaves it is to have ([`LeafPlan`]). Where obvhs' SAH leaf collapse would be its
/// build's last step (no reinsertion after it, no splits), the tree comes uncollapsed and
/// the plan holds the collapse's decisions, for the caller to apply while it lays the tree
/// out: obvhs applies it by copying and reordering the whole tree, which took as long as the
/// PLOC build itself on a 1M-triangle mesh.
pub fn shallow_bvh2_from_tris(triangles: &[Triangle], params: BvhBuildParams) -> (Bvh2, LeafPlan) {
    let boxes: Vec<Aabb> = triangles.iter().map(Boundable::aabb).collect();
    let leaf = params.max_prims_per_leaf.max(1) as usize;
    let median = |boxes: &[Aabb]| {
        let bvh = median_split_bvh2(boxes, leaf);
        let plan = LeafPlan::new(&bvh, None);
        (bvh, plan)
    };
    if fan_beyond(triangles, MAX_FAN) || coincident_beyond(&boxes, MAX_COINCIDENT) {
        return median(&boxes);
    }
    let collapses_last = !params.pre_split
        && params.reinsertion_batch_ratio * params.post_collapse_reinsertion_batch_ratio_multiplier
            <= 0.0;
    let (bvh, plan) = if collapses_last {
        // `build_bvh2_from_tris` up to its leaf collapse.
        let mut bvh = PlocBuilder::with_capacity(triangles.len()).build(
            params.ploc_search_distance,
            triangles,
            (0..triangles.len() as u32).collect(),
            params.sort_precision,
            params.search_depth_threshold,
        );
        ReinsertionOptimizer::default().run(&mut bvh, params.reinsertion_batch_ratio, None);
        let collapse = (
            params.max_prims_per_leaf.clamp(1, 255),
            params.collapse_traversal_cost,
        );
        let plan = LeafPlan::new(&bvh, Some(collapse));
        (bvh, plan)
    } else {
        let bvh = build_bvh2_from_tris(triangles, params, &mut Duration::default());
        let plan = LeafPlan::new(&bvh, None);
        (bvh, plan)
    };
    if plan.depth > MAX_BVH_DEPTH {
        return median(&boxes);
    }
    (bvh, plan)
}

/// The leaves a binary BVH is to have: its own, or those of obvhs' SAH leaf collapse
/// (`obvhs::bvh2::leaf_collapser::collapse`), decided as it decides them, on the same
/// numbers, so the tree is the one obvhs would return. Nodes are listed by position: the
/// BVH's nodes in depth-first order, first children first (a node's first child is at the
/// next position), so that the walks over it read arrays in order; nodes the root does not
/// reach are left out.
#[derive(Clone, Debug)]
pub struct LeafPlan {
    /// The BVH node at each position.
    pub node: Vec<u32>,
    /// The position of each inner node's second child (0 for a leaf of the BVH).
    pub second: Vec<u32>,
    /// Primitives (entries of the BVH's `primitive_indices`) below each position.
    pub prims: Vec<u32>,
    /// Whether each position is a leaf of the planned tree (a leaf, or an inner node whose
    /// subtree becomes one leaf); positions below such a one are not part of the tree.
    pub leaf: Vec<bool>,
    /// Where each position's primitives start in [`Self::sequence`].
    pub start: Vec<u32>,
    /// The primitives of the BVH's leaves, leaves in depth-first order, first children
    /// first: the order obvhs' collapse gives a merged leaf.
    pub sequence: Vec<u32>,
    /// Levels below the root of the planned tree.
    pub depth: usize,
}

/// What the collapse asks of a finished subtree.
struct Subtree {
    prims: u32,
    leaf: bool,
    height: u32,
    half_area: f32,
    first_index: u32,
}

/// A step of [`LeafPlan::new`]'s walk.
enum Step {
    /// Visit a node; `second_of`: the position of the parent whose second child it is.
    Enter { node: u32, second_of: Option<u32> },
    /// Both children of the inner node at `pos` are done.
    Leave {
        pos: u32,
        half_area: f32,
        first_index: u32,
    },
}

impl LeafPlan {
    /// The plan for `bvh`: its own leaves, or with `collapse = Some((max_prims,
    /// traversal_cost))` obvhs' collapse with those parameters.
    pub fn new(bvh: &Bvh2, collapse: Option<(u32, f32)>) -> Self {
        let nodes = &bvh.nodes;
        let n = nodes.len();
        // obvhs' collapse leaves small trees as they are.
        let collapse = collapse.filter(|&(max_prims, _)| {
            max_prims > 1
                && n > 2 * max_prims as usize + 1
                && (bvh.primitive_indices.is_empty()
                    || bvh.primitive_indices.len() > max_prims as usize)
                && nodes[0].prim_count == 0
        });
        let mut plan = LeafPlan {
            node: Vec::with_capacity(n),
            second: Vec::with_capacity(n),
            prims: Vec::with_capacity(n),
            leaf: Vec::with_capacity(n),
            start: Vec::with_capacity(n),
            sequence: Vec::with_capacity(bvh.primitive_indices.len()),
            depth: 0,
        };
        let mut steps = Vec::new();
        if n > 0 {
            steps.push(Step::Enter {
                node: 0,
                second_of: None,
            });
        }
        // Finished subtrees whose parents are not: a first child's below its sibling's.
        let mut done: Vec<Subtree> = Vec::new();
        while let Some(step) = steps.pop() {
            match step {
                Step::Enter { node, second_of } => {
                    let pos = plan.node.len() as u32;
                    if let Some(parent) = second_of {
                        plan.second[parent as usize] = pos;
                    }
                    let bvh_node = &nodes[node as usize];
                    let first = bvh_node.first_index;
                    plan.node.push(node);
                    plan.second.push(0);
                    plan.start.push(plan.sequence.len() as u32);
                    plan.prims.push(bvh_node.prim_count);
                    plan.leaf.push(bvh_node.prim_count != 0);
                    if bvh_node.prim_count != 0 {
                        let range = first as usize..(first + bvh_node.prim_count) as usize;
                        plan.sequence
                            .extend_from_slice(&bvh.primitive_indices[range]);
                        done.push(Subtree {
                            prims: bvh_node.prim_count,
                            leaf: true,
                            height: 0,
                            half_area: bvh_node.aabb().half_area(),
                            first_index: first,
                        });
                    } else {
                        steps.push(Step::Leave {
                            pos,
                            half_area: bvh_node.aabb().half_area(),
                            first_index: first,
                        });
                        steps.push(Step::Enter {
                            node: first + 1,
                            second_of: Some(pos),
                        });
                        steps.push(Step::Enter {
                            node: first,
                            second_of: None,
                        });
                    }
                }
                Step::Leave {
                    pos,
                    half_area,
                    first_index,
                } => {
                    let (Some(r), Some(l)) = (done.pop(), done.pop()) else {
                        unreachable!("an inner node is left after both its children");
                    };
                    let total = l.prims + r.prims;
                    let mut leaf = false;
                    if let Some((max_prims, traversal_cost)) = collapse {
                        // obvhs merges two children that are leaves (after its own merges
                        // below) when one leaf of both costs no more by the SAH, or when
                        // both hold the same primitive (its spatial splits).
                        if l.leaf && r.leaf && total <= max_prims {
                            let merged = half_area * (total as f32 - traversal_cost);
                            let apart = l.half_area * l.prims as f32 + r.half_area * r.prims as f32;
                            let same_prim = l.first_index == r.first_index && total == 2;
                            leaf = merged <= apart || same_prim;
                        }
                    }
                    plan.prims[pos as usize] = total;
                    plan.leaf[pos as usize] = leaf;
                    done.push(Subtree {
                        prims: total,
                        leaf,
                        height: if leaf { 0 } else { 1 + l.height.max(r.height) },
                        half_area,
                        first_index,
                    });
                }
            }
        }
        plan.depth = done.first().map_or(0, |root| root.height as usize);
        plan
    }

    /// The primitives below position `pos`, in the order of [`Self::sequence`].
    pub fn prims_of(&self, pos: usize) -> &[u32] {
        let start = self.start[pos] as usize;
        &self.sequence[start..start + self.prims[pos] as usize]
    }
}

/// Triangles sharing one vertex beyond this many make a fan PLOC builds in quadratic time
/// (a fan of 10^5 triangles took 15 s): such meshes go straight to the median split.
const MAX_FAN: usize = 1024;

/// Whether more than `limit` triangles share one vertex (by exact position).
fn fan_beyond(triangles: &[Triangle], limit: usize) -> bool {
    let corners = || {
        triangles
            .iter()
            .flat_map(|t| [t.v0, t.v1, t.v2].map(|v| v.to_array().map(f32::to_bits)))
    };
    occurs_more_than(corners, triangles.len() * 3, limit)
}

/// Whether some value of `values()` (`count` of them) occurs more than `limit` times. A
/// first pass counts the values by a hash into buckets: a bucket's count is at least that
/// of any value in it, so when no bucket passes `limit` no value does, the usual answer,
/// found in linear time. Otherwise the values are sorted and counted exactly. Buckets
/// expect `limit / 16` values each: few enough that distinct values rarely crowd one past
/// the limit, and for a large limit few enough buckets to stay in cache.
fn occurs_more_than<const N: usize, I>(values: impl Fn() -> I, count: usize, limit: usize) -> bool
where
    I: Iterator<Item = [u32; N]>,
{
    let buckets = count.saturating_mul(16) / limit.max(1);
    let bits = buckets.max(2).next_power_of_two().trailing_zeros();
    let mut buckets = vec![0u16; 1 << bits];
    let mut crowded = false;
    for v in values() {
        // A multiplicative hash; its top bits pick the bucket.
        let h = v.iter().fold(0u64, |h, &w| {
            (h ^ u64::from(w)).wrapping_mul(0x9e37_79b9_7f4a_7c15)
        });
        let b = &mut buckets[(h >> (64 - bits)) as usize];
        *b = b.saturating_add(1);
        crowded |= usize::from(*b) > limit;
    }
    if !crowded {
        return false;
    }
    let mut sorted: Vec<[u32; N]> = values().collect();
    sorted.sort_unstable();
    sorted.chunk_by(|a, b| a == b).any(|run| run.len() > limit)
}

fn shallow(boxes: &[Aabb], params: BvhBuildParams, ploc: impl FnOnce() -> Bvh2) -> Bvh2 {
    let leaf = params.max_prims_per_leaf.max(1) as usize;
    if coincident_beyond(boxes, MAX_COINCIDENT) {
        return median_split_bvh2(boxes, leaf);
    }
    let bvh = ploc();
    if bvh2_depth(&bvh.nodes) > MAX_BVH_DEPTH {
        return median_split_bvh2(boxes, leaf);
    }
    bvh
}

/// Whether more than `limit` boxes have exactly the same corners.
fn coincident_beyond(boxes: &[Aabb], limit: usize) -> bool {
    let corners = || {
        boxes.iter().map(|b| {
            let (lo, hi) = (b.min.to_array(), b.max.to_array());
            [lo[0], lo[1], lo[2], hi[0], hi[1], hi[2]].map(f32::to_bits)
        })
    };
    occurs_more_than(corners, boxes.len(), limit)
}

/// A BVH whose every inner node splits its boxes in two halves by their centres along the
/// longest axis of the centres' box (ties by index), with leaves of at most `leaf` boxes.
pub fn median_split_bvh2(boxes: &[Aabb], leaf: usize) -> Bvh2 {
    let leaf = leaf.max(1);
    let mut order: Vec<u32> = (0..boxes.len() as u32).collect();
    let centre = |i: u32| boxes[i as usize].center();
    let mut nodes = vec![Bvh2Node::new(Aabb::empty(), 0, 0)];
    // (node, range of `order`) still to be filled in.
    let mut pending = vec![(0usize, 0usize, boxes.len())];
    let mut deepest = 0;
    let mut depth_of = vec![0usize];
    while let Some((node, lo, hi)) = pending.pop() {
        let range = &mut order[lo..hi];
        let bounds = range
            .iter()
            .fold(Aabb::empty(), |b, &i| b.union(&boxes[i as usize]));
        deepest = deepest.max(depth_of[node]);
        if range.len() <= leaf {
            nodes[node] = Bvh2Node::new(bounds, range.len() as u32, lo as u32);
            continue;
        }
        let centres = range
            .iter()
            .fold(Aabb::empty(), |b, &i| b.union(&Aabb::from_point(centre(i))));
        let axis = centres.largest_axis();
        let half = range.len() / 2;
        range.select_nth_unstable_by(half, |&a, &b| {
            centre(a)[axis].total_cmp(&centre(b)[axis]).then(a.cmp(&b))
        });
        let first = nodes.len();
        nodes[node] = Bvh2Node::new(bounds, 0, first as u32);
        nodes.extend([Bvh2Node::new(Aabb::empty(), 0, 0); 2]);
        depth_of.extend([depth_of[node] + 1; 2]);
        pending.push((first + 1, lo + half, hi));
        pending.push((first, lo, lo + half));
    }
    Bvh2 {
        nodes,
        primitive_indices: order,
        children_are_ordered_after_parents: true,
        max_depth: deepest.max(obvhs::bvh2::DEFAULT_MAX_STACK_DEPTH),
        ..Bvh2::default()
    }
}

#[cfg(test)]
mod tests {
    use glam::Vec3A;

    use super::*;

    fn unit_box(at: [f32; 3]) -> Aabb {
        let p = Vec3A::from_array(at);
        Aabb::new(p, p + Vec3A::ONE)
    }

    /// Every box sits in exactly one leaf, under nodes whose boxes hold it.
    fn check_tree(bvh: &Bvh2, boxes: &[Aabb]) {
        let mut seen = vec![0usize; boxes.len()];
        let mut stack = vec![(0usize, Vec::<Aabb>::new())];
        while let Some((i, above)) = stack.pop() {
            let n = &bvh.nodes[i];
            let mut above = above;
            above.push(n.aabb);
            if n.prim_count == 0 {
                let f = n.first_index as usize;
                stack.push((f, above.clone()));
                stack.push((f + 1, above));
                continue;
            }
            let f = n.first_index as usize;
            for &p in &bvh.primitive_indices[f..f + n.prim_count as usize] {
                seen[p as usize] += 1;
                let b = boxes[p as usize];
                for a in &above {
                    assert!(a.min.cmple(b.min).all() && a.max.cmpge(b.max).all());
                }
            }
        }
        assert!(seen.iter().all(|&s| s == 1), "{seen:?}");
    }

    #[test]
    fn coincident_boxes_build_a_balanced_tree() {
        // PLOC chains these: 70 boxes went 69 levels deep.
        for n in [2, 70, 5000] {
            let boxes = vec![unit_box([5.0, -3.0, 2.0]); n];
            let bvh = shallow_bvh2(&boxes, BvhBuildParams::medium_build());
            let depth = bvh2_depth(&bvh.nodes);
            assert!(depth <= (n as f64).log2().ceil() as usize, "{n}: {depth}");
            check_tree(&bvh, &boxes);
        }
    }

    #[test]
    fn a_triangle_fan_builds_within_the_stack() {
        // One OBJ polygon of 20 000 vertices becomes a fan around its first vertex: PLOC
        // went 5090 levels deep on it.
        let n = 20_000;
        let rim = |i: usize| {
            let a = std::f32::consts::TAU * i as f32 / n as f32;
            Vec3A::new(a.cos(), a.sin(), 0.0)
        };
        let triangles: Vec<Triangle> = (1..n - 1)
            .map(|i| Triangle {
                v0: rim(0),
                v1: rim(i),
                v2: rim(i + 1),
            })
            .collect();
        let (bvh, plan) = shallow_bvh2_from_tris(&triangles, BvhBuildParams::fast_build());
        assert!(bvh2_depth(&bvh.nodes) <= MAX_BVH_DEPTH);
        assert!(plan.depth <= MAX_BVH_DEPTH);
        let boxes: Vec<Aabb> = triangles.iter().map(Boundable::aabb).collect();
        check_tree(&bvh, &boxes);
    }

    /// Values drawn from `0..range` (a small range repeats some), by a fixed LCG.
    fn draws(n: usize, range: u32, seed: u64) -> Vec<[u32; 2]> {
        let mut x = seed;
        (0..n)
            .map(|_| {
                x = x.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1);
                [((x >> 33) as u32) % range, 7]
            })
            .collect()
    }

    #[test]
    fn repeat_counts_agree_with_a_plain_count() {
        // Limits below, at and above the true largest count, for values that repeat a
        // little (the filter's answer) and a lot (the exact count's).
        for (n, range) in [(20_000, 1 << 30), (20_000, 5000), (3000, 40), (1, 1)] {
            let values = draws(n, range, n as u64 + u64::from(range));
            let mut count = std::collections::HashMap::new();
            for v in &values {
                *count.entry(*v).or_insert(0usize) += 1;
            }
            let most = count.values().copied().max().unwrap();
            for limit in [1, most.saturating_sub(1).max(1), most, most + 1, 1024] {
                assert_eq!(
                    occurs_more_than(|| values.iter().copied(), values.len(), limit),
                    most > limit,
                    "{n} values in 0..{range}, most {most}, limit {limit}"
                );
            }
        }
    }

    /// The leaves of a collapsed obvhs tree, each as its primitives, in depth-first order
    /// (first children first), and the tree's depth.
    fn obvhs_leaves(bvh: &Bvh2) -> (Vec<Vec<u32>>, usize) {
        let mut leaves = Vec::new();
        let mut stack = vec![0usize];
        while let Some(i) = stack.pop() {
            let n = &bvh.nodes[i];
            let first = n.first_index as usize;
            if n.prim_count == 0 {
                stack.extend([first + 1, first]);
            } else {
                leaves.push(bvh.primitive_indices[first..first + n.prim_count as usize].to_vec());
            }
        }
        (leaves, bvh2_depth(&bvh.nodes))
    }

    #[test]
    fn the_leaf_plan_is_obvhs_collapse() {
        // Random triangles of mixed sizes (leaves of 1 to 8 merge or not by the SAH), and
        // the plan's leaves against those of obvhs' own collapse of the same tree.
        let mut x = 17u64;
        let mut next = || {
            x = x.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1);
            (x >> 40) as f32 / (1u64 << 24) as f32
        };
        for (count, params) in [
            (5000, BvhBuildParams::fast_build()),
            (3000, BvhBuildParams::very_fast_build()),
            (7, BvhBuildParams::fast_build()),
            (40, BvhBuildParams::fast_build()),
        ] {
            let triangles: Vec<Triangle> = (0..count)
                .map(|_| {
                    let c = Vec3A::new(next(), next(), next()) * 100.0;
                    let size = 0.05 + 5.0 * next() * next();
                    let mut corner = || c + Vec3A::new(next(), next(), next()) * size;
                    Triangle {
                        v0: corner(),
                        v1: corner(),
                        v2: corner(),
                    }
                })
                .collect();
            let mut bvh = PlocBuilder::with_capacity(count).build(
                params.ploc_search_distance,
                &triangles,
                (0..count as u32).collect(),
                params.sort_precision,
                params.search_depth_threshold,
            );
            ReinsertionOptimizer::default().run(&mut bvh, params.reinsertion_batch_ratio, None);
            let max_prims = params.max_prims_per_leaf;
            let plan = LeafPlan::new(&bvh, Some((max_prims, params.collapse_traversal_cost)));
            let mut collapsed = bvh.clone();
            obvhs::bvh2::leaf_collapser::collapse(
                &mut collapsed,
                max_prims,
                params.collapse_traversal_cost,
            );
            // The plan's leaves, walked as its positions give them.
            let mut leaves = Vec::new();
            let mut stack = vec![0usize];
            while let Some(pos) = stack.pop() {
                if plan.leaf[pos] {
                    leaves.push(plan.prims_of(pos).to_vec());
                } else {
                    stack.extend([plan.second[pos] as usize, pos + 1]);
                }
            }
            let (expected, depth) = obvhs_leaves(&collapsed);
            assert_eq!(leaves, expected, "{count} triangles");
            assert_eq!(plan.depth, depth, "{count} triangles");
            assert!(leaves.iter().any(|l| l.len() > 1) || count < 20);
            // Without a collapse, the plan's leaves are the tree's own.
            let own = LeafPlan::new(&collapsed, None);
            assert_eq!(own.depth, depth);
            assert_eq!(own.prims[0] as usize, count);
        }
    }

    #[test]
    fn ordinary_boxes_keep_the_ploc_tree() {
        let boxes: Vec<Aabb> = (0..1000)
            .map(|i| {
                unit_box([
                    (i % 10) as f32 * 2.0,
                    (i / 10 % 10) as f32 * 2.0,
                    (i / 100) as f32 * 2.0,
                ])
            })
            .collect();
        let params = BvhBuildParams::medium_build();
        let ploc = build_bvh2(&boxes, params, &mut Duration::default());
        let ours = shallow_bvh2(&boxes, params);
        assert_eq!(ours.primitive_indices, ploc.primitive_indices);
        assert_eq!(ours.nodes.len(), ploc.nodes.len());
        check_tree(&ours, &boxes);
    }
}
