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

use std::time::Duration;

use obvhs::aabb::Aabb;
use obvhs::bvh2::builder::{build_bvh2, build_bvh2_from_tris};
use obvhs::bvh2::node::Bvh2Node;
use obvhs::bvh2::Bvh2;
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
/// triangles where `params` asks for them; the median split bounds whole triangles).
pub fn shallow_bvh2_from_tris(triangles: &[Triangle], params: BvhBuildParams) -> Bvh2 {
    let boxes: Vec<Aabb> = triangles.iter().map(Boundable::aabb).collect();
    if fan_beyond(triangles, MAX_FAN) {
        return median_split_bvh2(&boxes, params.max_prims_per_leaf.max(1) as usize);
    }
    shallow(&boxes, params, || {
        build_bvh2_from_tris(triangles, params, &mut Duration::default())
    })
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
        let bvh = shallow_bvh2_from_tris(&triangles, BvhBuildParams::fast_build());
        assert!(bvh2_depth(&bvh.nodes) <= MAX_BVH_DEPTH);
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
