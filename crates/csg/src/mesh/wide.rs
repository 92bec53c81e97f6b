//! The f32 CPU kernel's form of a mesh BVH: the mesh's binary BVH (the one the GPU
//! traverses) collapsed into eight-wide nodes ([`crate::wide_bvh`]), with leaves holding
//! triangles in blocks of 4 stored lane by lane, tested all at once with 4-lane SIMD (of
//! the instruction set the search runs with, [`crate::simd`]).
//! A leaf's last block repeats its first triangle in the unused lanes, a duplicate that can
//! never win (same distance, same number).
//!
//! The answers are bit for bit those of the binary walk (`MeshPrim::nearest_binary`): the
//! node test accepts every box the binary walk's does, each lane of the triangle test
//! performs the scalar watertight test's operations in the same order (no fused
//! multiply-add), lanes with an edge function of exactly 0 are redone by the scalar test
//! (its f64 fallback), and ties between equal distances go to the lowest triangle number,
//! so the order leaves are visited in does not matter.
//!
//! Each search also reports where the f32 test's hit or miss of a triangle is within its
//! rounding ([`edge_doubt`], [`Found::doubt`]): scans trace such rays again in f64. Only
//! doubtful triangles not beyond the answer count, and every walk enters every box the ray
//! meets before its answer, so that too does not depend on the order leaves are visited
//! in, but for a doubtful triangle in a box that the ray grazes within the box test's own
//! rounding (a triangle at most the doubt's bound from the ray, outside the box's
//! padding). The GPU's binary walk reports the same (`mesh_doubt` in
//! `shaders/mesh/mesh.wgsl`).

use wide::f32x4;

use super::{MeshNode, MeshPrim, Shear};
use crate::real::{Ray, Real, V3};
use crate::simd::{run_on, Isa, Kernel, Lanes, SimdPath};
use crate::wide_bvh::{
    point_f32, prefetch_lines, BinaryNode, PacketSlabs, Walker, WideBvhError, WideSlabs, WideTree,
    PACKET,
};

/// Triangles per block.
const LANES: usize = 4;

/// Four triangles, lane by lane.
#[derive(Clone, Debug, PartialEq)]
#[repr(C, align(16))]
struct TriangleBlock {
    /// `vertex[j][k][lane]`: coordinate `k` of vertex `j`.
    vertex: [[[f32; LANES]; 3]; 3],
    /// Each lane's triangle number in the mesh's reordered list (the tie-break order).
    number: [u32; LANES],
}

/// A mesh BVH in the f32 CPU kernel's wide form.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct WideBvh {
    /// Leaves: `(first block, block count)`.
    tree: WideTree,
    blocks: Vec<TriangleBlock>,
}

impl WideBvh {
    /// The wide form of a mesh's binary BVH (`nodes`, root first, children of an inner node
    /// at `first, first + 1`) over its reordered triangles; an error when the binary tree
    /// is deeper than [`crate::wide_bvh::MAX_DEPTH`].
    pub(crate) fn new(
        nodes: &[BinaryNode],
        triangles: &[[V3<f32>; 3]],
    ) -> Result<Self, WideBvhError> {
        let mut blocks = Vec::with_capacity(triangles.len() / 2 + 1);
        let tree = WideTree::new(nodes, |first, count| {
            Self::push_leaf(
                &mut blocks,
                triangles,
                first as usize..(first + count) as usize,
            )
        })?;
        Ok(WideBvh { tree, blocks })
    }

    /// Adds the triangle blocks of one leaf; returns its first block and block count.
    fn push_leaf(
        blocks: &mut Vec<TriangleBlock>,
        triangles: &[[V3<f32>; 3]],
        range: std::ops::Range<usize>,
    ) -> (u32, u32) {
        let first = blocks.len() as u32;
        let start = range.start;
        for chunk in range.clone().step_by(LANES) {
            let mut block = TriangleBlock {
                vertex: [[[0.0; LANES]; 3]; 3],
                number: [0; LANES],
            };
            for lane in 0..LANES {
                // Unused lanes repeat the leaf's first triangle.
                let i = if chunk + lane < range.end {
                    chunk + lane
                } else {
                    start
                };
                for (j, v) in triangles[i].iter().enumerate() {
                    for k in 0..3 {
                        block.vertex[j][k][lane] = v.get(k);
                    }
                }
                block.number[lane] = i as u32;
            }
            blocks.push(block);
        }
        (first, blocks.len() as u32 - first)
    }

    /// Bytes of the nodes and triangle blocks.
    pub(crate) fn bytes(&self) -> usize {
        self.tree.bytes() + std::mem::size_of_val(self.blocks.as_slice())
    }

    /// The nearest crossing after `after` and strictly before `limit` of a (recentred) ray:
    /// its distance, triangle number and geometric normal `(v1 - v0) x (v2 - v0)`, and where
    /// a crossing is doubtful ([`Found`]). `MeshPrim::nearest_binary`'s search, 8 boxes and 4 triangles at a time, on SIMD
    /// path `path` (the same answers on every path).
    pub(crate) fn nearest(&self, path: SimdPath, ray: &Ray<f32>, after: f32, limit: f32) -> Found {
        /// The search as a [`Kernel`].
        struct Nearest<'a>(&'a WideBvh, &'a Ray<f32>, f32, f32);
        impl Kernel for Nearest<'_> {
            type Output = Found;
            #[inline(always)]
            fn run<S: Isa>(self) -> Self::Output {
                let Nearest(wide, ray, after, limit) = self;
                wide.nearest_with::<S>(ray, after, limit)
            }
        }
        run_on(path, Nearest(self, ray, after, limit))
    }

    /// [`Self::nearest`] with the vectors of `S`.
    #[inline(always)]
    fn nearest_with<S: Isa>(&self, ray: &Ray<f32>, after: f32, limit: f32) -> Found {
        let triangles = WideRay::new(ray);
        let mut best = Best::none(limit);
        self.tree
            .walk_with::<S>(&WideSlabs::new(ray), after, limit, |first, count| {
                for b in first..first + count {
                    triangles.test::<S>(&self.blocks[b as usize], b, ray, after, &mut best);
                }
                best.t
            });
        self.found(&best, triangles.reach(after))
    }

    /// [`Self::nearest`] of each ray of a packet (`rays`, at most [`PACKET`], each with its
    /// `after` and no limit; `packet` is their [`PacketSlabs`]), walked together
    /// (`WideTree::walk_packet`): the same answers, bit for bit, in `out`.
    #[inline(always)]
    pub(crate) fn nearest_packet<S: Isa>(
        &self,
        packet: &PacketSlabs,
        rays: &[Ray<f32>],
        after: &[f32],
        out: &mut [Found],
    ) {
        let n = rays.len();
        let triangles: [WideRay; PACKET] =
            std::array::from_fn(|i| WideRay::new(&rays[i.min(n - 1)]));
        let mut best: [Best; PACKET] = std::array::from_fn(|_| Best::none(f32::INFINITY));
        let lanes = std::array::from_fn(|i| after[i.min(n - 1)]);
        let mut limits = std::array::from_fn(|i| {
            if i < n {
                f32::INFINITY
            } else {
                f32::NEG_INFINITY
            }
        });
        self.tree.walk_packet::<S>(
            packet,
            &lanes,
            &mut limits,
            |r, first, count| {
                for b in first..first + count {
                    triangles[r].test::<S>(
                        &self.blocks[b as usize],
                        b,
                        &rays[r],
                        after[r],
                        &mut best[r],
                    );
                }
                best[r].t
            },
            |first, count| {
                for block in &self.blocks[first as usize..(first + count) as usize] {
                    prefetch_lines(block);
                }
            },
        );
        for (r, (slot, best)) in out.iter_mut().zip(&best[..n]).enumerate() {
            *slot = self.found(best, triangles[r].reach(after[r]));
        }
    }

    /// Advances `search` by one node visit or one leaf (see [`Walker::step`] for `AHEAD`);
    /// false once it is over.
    #[inline(always)]
    pub(crate) fn advance<S: Isa, const AHEAD: bool>(&self, search: &mut Search) -> bool {
        let Search {
            ray,
            triangles,
            slabs,
            after,
            best,
            walker,
        } = search;
        let after = *after;
        walker.step::<S, AHEAD>(
            &self.tree,
            slabs,
            after,
            &mut |first, count| {
                for b in first..first + count {
                    triangles.test::<S>(&self.blocks[b as usize], b, ray, after, best);
                }
                best.t
            },
            |first, count| {
                for block in &self.blocks[first as usize..(first + count) as usize] {
                    prefetch_lines(block);
                }
            },
        )
    }

    /// What a finished `search` found: as [`Self::nearest`].
    pub(crate) fn answer(&self, search: &Search) -> Found {
        self.found(&search.best, search.triangles.reach(search.after))
    }

    /// The crossing `best` holds, with its triangle number and geometric normal, and where a
    /// doubtful crossing lies ([`Found::doubt`]) for a ray of [`WideRay::reach`] `reach`.
    fn found(&self, best: &Best, reach: f32) -> Found {
        let crossing = best.found.then(|| {
            let v = &self.blocks[best.block as usize].vertex;
            let [v0, v1, v2] = [0, 1, 2]
                .map(|j| V3::new(v[j][0][best.lane], v[j][1][best.lane], v[j][2][best.lane]));
            (best.t, best.number as usize, (v1 - v0).cross(v2 - v0))
        });
        // Doubtful triangles met beyond the answer were seen only because the walk had not
        // yet found it (which depends on the order leaves are visited in), and those met
        // within the rounding of its distance (a coincident face, a neighbour across an
        // edge) change nothing that matters: neither counts. The answer's own triangle does
        // when it is doubtful (an exact test may miss it).
        let earlier = if best.found {
            let margin = 2.0 * f32::EPSILON * (reach + best.t.abs());
            best.doubt < best.t - margin
        } else {
            best.doubt <= best.t
        };
        let earlier = if earlier { best.doubt } else { f32::INFINITY };
        let doubt = if best.found && best.doubtful {
            earlier.min(best.t)
        } else {
            earlier
        };
        Found { crossing, doubt }
    }
}

/// What a search of a [`WideBvh`] found.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Found {
    /// The nearest crossing: its distance, triangle number and geometric normal.
    pub crossing: Option<(f32, usize, V3<f32>)>,
    /// The least distance at which the ray may meet the plane of a triangle whose hit or
    /// miss is within f32 rounding ([`edge_doubt`]; the latest such distance,
    /// [`latest_crossing`], or the crossing's own), counting only the nearest crossing's
    /// own triangle and those met surely before it by more than the rounding of its
    /// distance (all of them, up to the search's limit, when there is none); `+inf` when
    /// there is none. An exact search may answer otherwise.
    pub doubt: f32,
}

/// One ray's search of a [`WideBvh`] for its nearest crossing, advanced a step at a time
/// ([`WideBvh::advance`]) so that one thread can interleave the searches of several rays.
/// Large (its walker's stack): reused from ray to ray, not rebuilt.
pub(crate) struct Search {
    ray: Ray<f32>,
    triangles: WideRay,
    slabs: WideSlabs,
    after: f32,
    best: Best,
    walker: Walker,
}

impl Search {
    /// A search to be [`Search::start`]ed.
    pub(crate) fn new() -> Self {
        let ray = Ray {
            origin: V3::new(0.0, 0.0, 0.0),
            direction: V3::new(0.0, 0.0, 1.0),
        };
        Search {
            triangles: WideRay::new(&ray),
            slabs: WideSlabs::new(&ray),
            ray,
            after: 0.0,
            best: Best::none(f32::NEG_INFINITY),
            walker: Walker::new(),
        }
    }

    /// Starts the search for the nearest crossing of `ray` after `after` and strictly
    /// before `limit`.
    #[inline]
    pub(crate) fn start(&mut self, ray: &Ray<f32>, after: f32, limit: f32) {
        self.ray = *ray;
        self.triangles = WideRay::new(ray);
        self.slabs = WideSlabs::new(ray);
        self.after = after;
        self.best = Best::none(limit);
        self.walker.restart(limit);
    }
}

/// The best crossing so far: its distance (the search limit until one is found) and
/// triangle number.
struct Best {
    t: f32,
    number: u32,
    /// Where the triangle is: its block and lane.
    block: u32,
    lane: usize,
    found: bool,
    /// The least distance of a doubtful crossing seen ([`Found::doubt`], before the
    /// answer is known).
    doubt: f32,
    /// Whether the crossing held is doubtful.
    doubtful: bool,
}

impl Best {
    /// Nothing found yet, searching strictly before `limit`.
    fn none(limit: f32) -> Self {
        Best {
            t: limit,
            number: 0,
            block: 0,
            lane: 0,
            found: false,
            doubt: f32::INFINITY,
            doubtful: false,
        }
    }

    /// Notes a doubtful triangle whose plane the ray crosses at `latest` at the latest
    /// ([`latest_crossing`]), if that is after `after` and not beyond the crossing held (or
    /// the limit).
    #[inline(always)]
    fn doubt_at(&mut self, latest: f32, after: f32) {
        if latest > after && latest <= self.t && latest < self.doubt {
            self.doubt = latest;
        }
    }

    /// Takes a crossing at `t` of triangle `number` (`doubtful` or not) if it is nearer, or
    /// as near with a lower number; before any is found, only one strictly before the
    /// limit (an overflowed, infinite distance is no crossing).
    #[inline(always)]
    fn offer(&mut self, t: f32, number: u32, block: u32, lane: usize, doubtful: bool) {
        let better = if self.found {
            t < self.t || (t == self.t && number < self.number)
        } else {
            t < self.t
        };
        if better {
            *self = Best {
                t,
                number,
                block,
                lane,
                found: true,
                doubt: self.doubt,
                doubtful,
            };
        }
    }
}

/// The per-ray part of the 4-lane watertight triangle test (see `MeshPrim::crossing`).
struct WideRay {
    shear: Shear<f32>,
    /// The origin's coordinates in the sheared frame's axis order.
    origin: [f32; 3],
    /// The origin's largest coordinate (its rounding is part of [`edge_doubt`]'s bound).
    origin_max: f32,
}

impl WideRay {
    /// The `reach` of [`edge_doubt`] for a search after `after`.
    #[inline(always)]
    fn reach(&self, after: f32) -> f32 {
        self.origin_max + after.abs()
    }

    fn new(ray: &Ray<f32>) -> Self {
        let shear = Shear::new(ray.direction);
        let origin = shear.axes.map(|k| ray.origin.get(k));
        WideRay {
            origin,
            origin_max: ray.origin.max_abs(),
            shear,
        }
    }

    /// Offers `best` the crossings after `after` of the triangles of block `index`.
    #[inline(always)]
    fn test<S: Isa>(
        &self,
        block: &TriangleBlock,
        index: u32,
        ray: &Ray<f32>,
        after: f32,
        best: &mut Best,
    ) {
        let [kx, ky, kz] = self.shear.axes;
        let zero = S::F4::splat(0.0);
        let origin = self.origin.map(S::F4::splat);
        let [shear_x, shear_y, shear_z] =
            [self.shear.x, self.shear.y, self.shear.z].map(S::F4::splat);
        // Vertex j relative to the origin, sheared: (x, y) and the unsheared height.
        let vertex = |j: usize| {
            let v = &block.vertex[j];
            let px = S::F4::load(&v[kx]) - origin[0];
            let py = S::F4::load(&v[ky]) - origin[1];
            let pz = S::F4::load(&v[kz]) - origin[2];
            (px - shear_x * pz, py - shear_y * pz, pz)
        };
        let (ax, ay, az) = vertex(0);
        let (bx, by, bz) = vertex(1);
        let (cx, cy, cz) = vertex(2);
        let u = cx * by - cy * bx;
        let v = ax * cy - ay * cx;
        let w = bx * ay - by * ax;
        let det = u + v + w;
        let negative = u.lt(zero) | v.lt(zero) | w.lt(zero);
        let positive = u.gt(zero) | v.gt(zero) | w.gt(zero);
        let t = (u * (shear_z * az) + v * (shear_z * bz) + w * (shear_z * cz)) / det;
        let crossed = !(negative & positive) & det.ne(zero);
        let candidate = crossed & t.gt(S::F4::splat(after)) & t.le(S::F4::splat(best.t));
        // The doubt, in `wide`'s f32x4 (what every path's 4 lanes are).
        let four = |x: S::F4| f32x4::from(x.to_array());
        let reach = f32x4::splat(self.reach(after));
        let sheared =
            [(ax, ay, az), (bx, by, bz), (cx, cy, cz)].map(|(x, y, z)| (four(x), four(y), four(z)));
        let (doubt, bound) = edge_doubt(sheared, [four(u), four(v), four(w)], reach);
        let doubtful = doubt.to_bitmask();
        if doubtful != 0 {
            // Rare: the latest each doubtful triangle's plane may be crossed.
            let heights = [az, bz, cz].map(|z| (shear_z * z).to_array());
            let (t, det, bound) = (t.to_array(), det.to_array(), bound.to_array());
            let mut lanes = doubtful;
            while lanes != 0 {
                let lane = lanes.trailing_zeros() as usize;
                lanes &= lanes - 1;
                let z = heights.map(|h| h[lane]);
                best.doubt_at(latest_crossing(t[lane], z, det[lane], bound[lane]), after);
            }
        }
        let on_edge = (u.eq(zero) | v.eq(zero) | w.eq(zero)).bitmask();
        let mut lanes = (candidate.bitmask() & !on_edge) | on_edge;
        if lanes == 0 {
            return;
        }
        let t = t.to_array();
        while lanes != 0 {
            let lane = lanes.trailing_zeros() as usize;
            lanes &= lanes - 1;
            let number = block.number[lane];
            let t = if on_edge & (1 << lane) != 0 {
                // An edge function of exactly 0: the scalar test and its f64 fallback.
                let tri = [0, 1, 2].map(|j| {
                    let v = &block.vertex[j];
                    V3::new(v[0][lane], v[1][lane], v[2][lane])
                });
                match MeshPrim::<f32>::crossing(&tri, ray, &self.shear) {
                    Some(t) if t > after => t,
                    _ => continue,
                }
            } else {
                t[lane]
            };
            best.offer(t, number, index, lane, doubtful & (1 << lane) != 0);
        }
    }
}

/// Which lanes' hit or miss is within f32 rounding: the ray passes within the rounding of
/// the test's values of the triangle's boundary (a near-edge or near-vertex crossing, or a
/// near miss), so an exact test may decide otherwise. From the test's own values: each
/// vertex's sheared coordinates relative to the origin and its unsheared height
/// (`vertex[j] = (x, y, z)`), the edge functions `edge` and `reach`, the largest coordinate
/// of the ray's origin plus how far its parameter was moved (the rounding of the recentred
/// origin). The WGSL twin is `mesh_doubt` in `shaders/mesh/mesh.wgsl`, operation by
/// operation.
///
/// The bound: each sheared coordinate is off by at most `u (2 |x| + 4 |z| + 2 reach)`
/// (`u` the unit roundoff 2^-24: the origin's rounding, the difference, the shear's ratio
/// and product), so an edge function `px qy - py qx` is off by that times the four
/// coordinates it multiplies, plus the rounding of its products and difference: with
/// `S` the sum of all six |sheared coordinates| and `Z` of the three |heights|, at most
/// `2u S (1.5 S + 2 Z + reach)`. Twice that, `2 eps S (2 S + 2 Z + reach)` (eps = 2u),
/// is `bound`. A lane is doubtful when some edge function is within `bound` of 0 and
/// moving each by at most `bound` can make all three agree in sign (a hit).
/// Returns the mask and `bound`.
#[inline(always)]
fn edge_doubt(
    vertex: [(f32x4, f32x4, f32x4); 3],
    edge: [f32x4; 3],
    reach: f32x4,
) -> (f32x4, f32x4) {
    let [(ax, ay, az), (bx, by, bz), (cx, cy, cz)] = vertex;
    let sheared = ax.abs() + ay.abs() + (bx.abs() + by.abs()) + (cx.abs() + cy.abs());
    let heights = az.abs() + bz.abs() + cz.abs();
    let bound = f32x4::splat(2.0 * f32::EPSILON)
        * sheared
        * ((sheared + heights) * f32x4::splat(2.0) + reach);
    let [u, v, w] = edge;
    let low = -bound;
    let near = u.abs().simd_le(bound) | v.abs().simd_le(bound) | w.abs().simd_le(bound);
    let may_hit_from_front = u.simd_ge(low) & v.simd_ge(low) & w.simd_ge(low);
    let may_hit_from_behind = u.simd_le(bound) & v.simd_le(bound) & w.simd_le(bound);
    (near & (may_hit_from_front | may_hit_from_behind), bound)
}

/// The latest distance at which the ray may cross a doubtful triangle: `t`, the test's
/// `sum(e_j z_j) / det` (`z` the vertices' distances along the ray, their heights times the
/// shear's `z`; `det` the sum of the edge functions `e_j`), plus its change when each
/// `e_j` moves by `bound` ([`edge_doubt`]), `bound sum |z_j - t| / |det|`, but no later
/// than its farthest vertex (a crossing lies within the triangle). Nearly edge-on
/// triangles have garbage plane distances; this keeps a doubtful one from counting as met
/// before the answer when it may not be. The WGSL twin is `mesh_latest_crossing`,
/// operation by operation (comparisons, not `min`/`max`, which differ on NaN).
#[inline(always)]
fn latest_crossing(t: f32, z: [f32; 3], det: f32, bound: f32) -> f32 {
    let spread = (z[0] - t).abs() + (z[1] - t).abs() + (z[2] - t).abs();
    let late = t + bound * spread / det.abs();
    let far = if z[0] > z[1] { z[0] } else { z[1] };
    let far = if z[2] > far { z[2] } else { far };
    if late < far {
        late
    } else {
        far
    }
}

/// A mesh's binary BVH and triangles in f32 (exact when `T` is f32).
pub(crate) fn to_f32<T: Real>(
    nodes: &[MeshNode<T>],
    triangles: &[[V3<T>; 3]],
) -> (Vec<BinaryNode>, Vec<[V3<f32>; 3]>) {
    (
        nodes
            .iter()
            .map(|n| BinaryNode {
                bounds: n.bounds.map(point_f32),
                first: n.first,
                count: n.count,
            })
            .collect(),
        triangles.iter().map(|t| t.map(point_f32)).collect(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::test_common::{grid, Random, Rng};

    /// A grid with integer heights, shifted by `offset`: every vertex, edge and box face is
    /// exact in f32, so rays aimed at them meet edge functions of exactly 0.
    fn shifted_grid(n: usize, offset: f64) -> Vec<[[f64; 3]; 3]> {
        let tris = grid(n, |x, y| ((x as usize * y as usize) % 3) as f64);
        tris.iter()
            .map(|t| t.map(|v| v.map(|c| c + offset)))
            .collect()
    }

    /// 3000 random triangles of sizes 0.01 to 2 in a 20-wide cube about the origin.
    fn random_soup(rng: &mut Rng) -> MeshPrim<f32> {
        let soup: Vec<_> = (0..3000)
            .map(|_| {
                let c = [0; 3].map(|_| rng.range(-10.0, 10.0));
                let size = rng.range(0.01, 2.0);
                [0; 3].map(|_| {
                    let e = rng.direction();
                    [0, 1, 2].map(|k| c[k] + size * e[k])
                })
            })
            .collect();
        MeshPrim::<f32>::new(&soup).unwrap()
    }

    /// Runs the binary search and the wide one on every SIMD path this CPU has, on a ray
    /// and its recentred form; returns whether it hit.
    fn both_agree(mesh: &MeshPrim<f32>, origin: [f64; 3], direction: [f64; 3]) -> bool {
        let wide = mesh.wide.as_ref().expect("f32 meshes have a wide BVH");
        let ray = Ray::from_f64(origin, direction);
        let (moved, shift) = mesh.recentred(&ray);
        let mut hit = false;
        let paths = SimdPath::available();
        for (r, after, path) in [(ray, 0.0f32), (moved, -shift)]
            .into_iter()
            .flat_map(|(r, after)| paths.iter().map(move |&p| (r, after, p)))
        {
            let got = wide.nearest(path, &r, after, f32::INFINITY).crossing;
            let want = mesh.nearest_binary(&r, after);
            if let Some((_, i, normal)) = got {
                let [v0, v1, v2] = mesh.triangles[i];
                assert_eq!(normal, (v1 - v0).cross(v2 - v0), "normal of triangle {i}");
            }
            assert_eq!(
                got.map(|(t, i, _)| (t.to_bits(), i)),
                want.map(|(t, i)| (t.to_bits(), i)),
                "ray {origin:?} + t {direction:?} after {after}: wide ({path}) {got:?}, binary {want:?}"
            );
            hit |= got.is_some();
        }
        hit
    }

    #[test]
    fn wide_search_equals_the_binary_one_bit_for_bit_on_random_rays() {
        let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
        let mesh = random_soup(&mut rng);
        let mut hits = 0;
        for _ in 0..20_000 {
            let o = [0; 3].map(|_| rng.range(-15.0, 15.0));
            hits += both_agree(&mesh, o, rng.direction()) as usize;
        }
        assert!(hits > 5_000, "only {hits} of 20000 rays hit the soup");
    }

    #[test]
    fn wide_search_equals_the_binary_one_on_edges_vertices_and_box_faces() {
        for offset in [0.0, 1.0e5] {
            let mesh = MeshPrim::<f32>::new(&shifted_grid(24, offset)).unwrap();
            let mut hits = 0;
            // Rays straight down (two zero components) and tilted in one axis plane (one
            // zero component) onto every vertex, edge midpoint and quad centre.
            for i in 0..49 {
                for j in 0..49 {
                    let (x, y) = (i as f64 * 0.5 + offset, j as f64 * 0.5 + offset);
                    for d in [[0.0, 0.0, -1.0], [0.0, 0.6, -0.8], [0.6, 0.0, -0.8]] {
                        let o = [x - 10.0 * d[0], y - 10.0 * d[1], offset + 10.0];
                        hits += both_agree(&mesh, o, d) as usize;
                    }
                }
            }
            assert!(
                hits > 49 * 49 * 2,
                "only {hits} rays hit the grid at {offset}"
            );
            // Grazing rays in the planes of the grid lines, and random ones.
            let mut rng = Rng(7);
            for k in 0..2000 {
                let o = [
                    offset + rng.range(-2.0, 26.0),
                    offset + (k % 25) as f64,
                    offset + rng.range(-1.0, 3.0),
                ];
                let d = [rng.range(-1.0, 1.0), 0.0, rng.range(-0.2, 0.2)];
                both_agree(&mesh, o, d);
                both_agree(&mesh, o, rng.direction());
            }
        }
    }

    /// Checks [`WideBvh::nearest_packet`] of `rays` (origin, direction) against
    /// [`WideBvh::nearest`] ray by ray, bit for bit, on every SIMD path this CPU has (the
    /// single searches on the portable one), each ray recentred as the mesh's searches
    /// recentre it; returns how many hit, or `None` when the rays have no packet form. With
    /// `coherent`, also checks that the mesh's searches would take them as a packet.
    fn packet_agrees(
        mesh: &MeshPrim<f32>,
        rays: &[([f64; 3], [f64; 3])],
        coherent: bool,
    ) -> Option<usize> {
        let wide = mesh.wide.as_ref().expect("f32 meshes have a wide BVH");
        let (moved, after): (Vec<Ray<f32>>, Vec<f32>) = rays
            .iter()
            .map(|(o, d)| {
                let (moved, shift) = mesh.recentred(&Ray::from_f64(*o, *d));
                (moved, -shift)
            })
            .unzip();
        if coherent {
            assert!(
                super::super::coherent(&moved, mesh.scale).is_some(),
                "rays {rays:?} not taken as a packet"
            );
        }
        let packet = PacketSlabs::new(&moved)?;
        let none = Found {
            crossing: None,
            doubt: f32::INFINITY,
        };
        /// The packet search as a [`Kernel`].
        struct Packet<'a>(
            &'a WideBvh,
            &'a PacketSlabs,
            &'a [Ray<f32>],
            &'a [f32],
            Found,
        );
        impl Kernel for Packet<'_> {
            type Output = Vec<Found>;
            fn run<S: Isa>(self) -> Self::Output {
                let Packet(wide, packet, rays, after, none) = self;
                let mut got = vec![none; rays.len()];
                wide.nearest_packet::<S>(packet, rays, after, &mut got);
                got
            }
        }
        let mut hits = 0;
        for path in SimdPath::available() {
            let got = run_on(path, Packet(wide, &packet, &moved, &after, none));
            for ((ray, after), got) in moved.iter().zip(&after).zip(&got) {
                let want = wide.nearest(SimdPath::Portable, ray, *after, f32::INFINITY);
                assert_eq!(
                    (
                        got.crossing.map(|(t, i, n)| (t.to_bits(), i, n)),
                        got.doubt.to_bits()
                    ),
                    (
                        want.crossing.map(|(t, i, n)| (t.to_bits(), i, n)),
                        want.doubt.to_bits()
                    ),
                    "ray {ray:?} after {after} in the packet {rays:?} ({path})"
                );
            }
            hits = got.iter().filter(|g| g.crossing.is_some()).count();
        }
        Some(hits)
    }

    #[test]
    fn packet_search_equals_single_searches_on_camera_rays_and_sweeps() {
        for offset in [0.0, 1.0e5] {
            let mesh = MeshPrim::<f32>::new(&shifted_grid(24, offset)).unwrap();
            let mut hits = 0;
            // A camera's rows of 8 pixels (of 256 across), from above the grid's corner.
            let eye = [offset - 6.0, offset - 6.0, offset + 20.0];
            for row in 0..240 {
                for col in (0..256).step_by(8) {
                    let packet: Vec<_> = (col..col + 8)
                        .map(|x| {
                            let (u, v) = (f64::from(x) / 256.0, f64::from(row) / 240.0);
                            (eye, [0.3 + 0.9 * u, 0.3 + 0.9 * v, -0.8])
                        })
                        .collect();
                    hits += packet_agrees(&mesh, &packet, true).unwrap();
                }
            }
            // Sweeps: rows of parallel rays 1/32 apart (every vertex and edge among their
            // targets), straight down (two zero components) and tilted (one).
            for d in [[0.0, 0.0, -1.0], [0.0, 0.6, -0.8], [0.6, 0.0, -0.8]] {
                for j in 0..49 {
                    for i0 in (0..24 * 32).step_by(8) {
                        let packet: Vec<_> = (i0..i0 + 8)
                            .map(|i| {
                                let (x, y) = (i as f64 / 32.0 + offset, j as f64 * 0.5 + offset);
                                ([x - 10.0 * d[0], y - 10.0 * d[1], offset + 10.0], d)
                            })
                            .collect();
                        hits += packet_agrees(&mesh, &packet, true).unwrap();
                    }
                }
            }
            assert!(hits > 100_000, "only {hits} rays hit the grid at {offset}");
        }
    }

    #[test]
    fn packet_search_equals_single_searches_on_divergent_packets() {
        let mut rng = Rng(0x5851_f42d_4c95_7f2d);
        let mesh = random_soup(&mut rng);
        let (mut hits, mut packets) = (0, 0);
        for k in 0..4000 {
            // Rays of one octant from anywhere (the packet test accepts them, loosely),
            // packets of 1 to 8; some rays start far away and are recentred.
            let sign = [0; 3].map(|_| {
                if rng.range(-1.0, 1.0) < 0.0 {
                    -1.0
                } else {
                    1.0
                }
            });
            let packet: Vec<_> = (0..1 + k % 8)
                .map(|_| {
                    let far = if rng.range(0.0, 1.0) < 0.2 {
                        100.0
                    } else {
                        1.0
                    };
                    let o = [0; 3].map(|_| far * rng.range(-15.0, 15.0));
                    let d = rng.direction();
                    (o, [0, 1, 2].map(|c| sign[c] * d[c].abs()))
                })
                .collect();
            hits += packet_agrees(&mesh, &packet, false).expect("one octant");
            packets += 1;
        }
        assert_eq!(packets, 4000);
        assert!(hits > 2000, "only {hits} rays hit the soup");
        // Rays of different octants have no packet form.
        let mixed = [([0.0; 3], [1.0, 0.0, 0.0]), ([0.0; 3], [-1.0, 0.0, 0.0])];
        assert!(packet_agrees(&mesh, &mixed, false).is_none());
    }
}
