//! The f32 CPU kernel's form of a mesh BVH: nodes of 8 children and triangles in blocks of
//! 4, each tested all at once with SIMD (`wide`'s `f32x8` and `f32x4`: SSE on x86-64, NEON
//! on AArch64, plain arrays elsewhere).
//!
//! It is built from the mesh's binary BVH (the one the GPU traverses) by collapsing: each
//! wide node takes a binary node's two children and keeps opening its largest inner child
//! (by surface area) until it has 8 or only leaves are left. Leaves keep their triangles,
//! in blocks of 4 stored lane by lane; a leaf's last block repeats its first triangle in
//! the unused lanes, a duplicate that can never win (same distance, same number).
//!
//! The answers are bit for bit those of the binary walk (`MeshPrim::nearest_binary`): the
//! box tests are conservative the same way (same padded boxes, reciprocal slabs, the
//! dividing test when a direction component is zero), each lane of the triangle test
//! performs the scalar watertight test's operations in the same order (no fused
//! multiply-add), lanes with an edge function of exactly 0 are redone by the scalar test
//! (its f64 fallback), and ties between equal distances go to the lowest triangle number,
//! so the order leaves are visited in does not matter.
//!
//! Why this shape, measured on the 1M-triangle heightfield of `cargo bench -p
//! hytrace-tests --bench mesh` (2-core VM, 2026-11-22, BENCHMARKS.md): the binary walk
//! reached 2.2-2.7 (coherent) and 0.9-1.1 (incoherent) Mrays/s; 4-wide nodes with these
//! blocks 4.4-5.7 and 2.0-2.3; 8-wide nodes 5.3-7.4 and 2.2-2.9. Incoherent rays wait on
//! memory: a profile puts half of the kernel's time on the first load of a node and of a
//! block, so fewer levels (wider nodes) is what pays. The tree's quality matters less:
//! obvhs' medium and slow presets were within the VM's noise of the fast one.

use std::mem::MaybeUninit;

use wide::{f32x4, f32x8};

use super::{MeshNode, MeshPrim, Shear, MAX_BVH_DEPTH};
use crate::real::{Ray, Real, V3};

/// Children per node.
const WIDTH: usize = 8;

/// Triangles per block.
const LANES: usize = 4;

/// Entries the traversal stack may need: a node visit pushes at most `WIDTH - 1` siblings,
/// and the wide tree is no deeper than the binary one.
const STACK: usize = (WIDTH - 1) * MAX_BVH_DEPTH + 1;

/// Eight child boxes and what they hold, lane by lane (256 bytes, four cache lines).
#[derive(Clone, Debug, PartialEq)]
#[repr(C, align(64))]
struct WideNode {
    /// Padded child boxes: min x, min y, min z, max x, max y, max z, one lane per child.
    /// Unused lanes hold empty boxes (min +inf, max -inf), which no ray enters.
    planes: [[f32; WIDTH]; 6],
    /// An inner child's node index (`count == 0`), or a leaf's first triangle block.
    child: [u32; WIDTH],
    /// A leaf's number of triangle blocks; 0 for an inner child.
    count: [u32; WIDTH],
}

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
    /// Node 0 is the root.
    nodes: Vec<WideNode>,
    blocks: Vec<TriangleBlock>,
}

/// Surface area of a box (the collapse opens the largest inner child first).
fn area(b: &[V3<f32>; 2]) -> f32 {
    let e = b[1] - b[0];
    e.x * e.y + e.y * e.z + e.z * e.x
}

impl WideBvh {
    /// The wide form of a mesh's binary BVH (`nodes`, root first, children of an inner node
    /// at `first, first + 1`) over its reordered triangles.
    pub(crate) fn new(nodes: &[MeshNode<f32>], triangles: &[[V3<f32>; 3]]) -> Self {
        let mut wide = WideBvh {
            nodes: Vec::with_capacity(nodes.len() / 2 + 1),
            blocks: Vec::with_capacity(triangles.len() / 2 + 1),
        };
        if !nodes.is_empty() {
            wide.collapse(nodes, triangles, 0);
        }
        wide
    }

    /// Adds the wide node that stands for binary node `index` and, below it, its subtree;
    /// returns its index.
    fn collapse(
        &mut self,
        nodes: &[MeshNode<f32>],
        triangles: &[[V3<f32>; 3]],
        index: usize,
    ) -> u32 {
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
                (self.collapse(nodes, triangles, c), 0)
            } else {
                let range = node.first as usize..(node.first + node.count) as usize;
                self.push_leaf(triangles, range)
            };
            let w = &mut self.nodes[slot];
            for k in 0..3 {
                w.planes[k][lane] = node.bounds[0].get(k);
                w.planes[k + 3][lane] = node.bounds[1].get(k);
            }
            w.child[lane] = child;
            w.count[lane] = count;
        }
        slot as u32
    }

    /// Adds the triangle blocks of one leaf; returns its first block and block count.
    fn push_leaf(
        &mut self,
        triangles: &[[V3<f32>; 3]],
        range: std::ops::Range<usize>,
    ) -> (u32, u32) {
        let first = self.blocks.len() as u32;
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
            self.blocks.push(block);
        }
        (first, self.blocks.len() as u32 - first)
    }

    /// Bytes of the nodes and triangle blocks.
    pub(crate) fn bytes(&self) -> usize {
        std::mem::size_of_val(self.nodes.as_slice()) + std::mem::size_of_val(self.blocks.as_slice())
    }

    /// The nearest crossing after `after` and strictly before `limit` of a (recentred) ray:
    /// its distance, triangle number and geometric normal `(v1 - v0) x (v2 - v0)`.
    /// `MeshPrim::nearest_binary`'s search, 8 boxes and 4 triangles at a time.
    pub(crate) fn nearest(
        &self,
        ray: &Ray<f32>,
        after: f32,
        limit: f32,
    ) -> Option<(f32, usize, V3<f32>)> {
        if self.nodes.is_empty() {
            return None;
        }
        let slabs = WideSlabs::new(ray);
        let triangles = WideRay::new(ray);
        let mut best = Best {
            t: limit,
            number: 0,
            block: 0,
            lane: 0,
            found: false,
        };
        // Postponed children, the nearest on top; only `stack[..top]` is ever read.
        let mut stack = [MaybeUninit::<Postponed>::uninit(); STACK];
        let mut top = 0;
        let (mut child, mut count) = (0u32, 0u32);
        loop {
            if count == 0 {
                let node = &self.nodes[child as usize];
                let (hit, entries) = slabs.entries(node, after, best.t);
                match hit.count_ones() {
                    0 => {}
                    1 => {
                        let lane = hit.trailing_zeros() as usize;
                        (child, count) = (node.child[lane], node.count[lane]);
                        continue;
                    }
                    _ => {
                        // Sort the entered children farthest first, push all but the
                        // nearest, and go on with it.
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
                            stack[top].write(*e);
                            top += 1;
                        }
                        (child, count) = (entered[n - 1].child, entered[n - 1].count);
                        continue;
                    }
                }
            } else {
                for b in child..child + count {
                    triangles.test(&self.blocks[b as usize], b, ray, after, &mut best);
                }
            }
            // The nearest postponed child still entered within the best distance (boxes
            // entered exactly there may hold a tied crossing).
            loop {
                if top == 0 {
                    return best.found.then(|| {
                        let v = &self.blocks[best.block as usize].vertex;
                        let [v0, v1, v2] = [0, 1, 2].map(|j| {
                            V3::new(v[j][0][best.lane], v[j][1][best.lane], v[j][2][best.lane])
                        });
                        (best.t, best.number as usize, (v1 - v0).cross(v2 - v0))
                    });
                }
                top -= 1;
                // SAFETY: entries below `top` were written by the pushes above (each
                // push writes `stack[top]` before raising `top`), and `top` never exceeds
                // `STACK` (see its doc).
                let e = unsafe { stack[top].assume_init() };
                if e.entry <= best.t {
                    (child, count) = (e.child, e.count);
                    break;
                }
            }
        }
    }
}

/// A child postponed by the traversal, with its box entry.
#[derive(Clone, Copy, Default)]
struct Postponed {
    child: u32,
    count: u32,
    entry: f32,
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
}

impl Best {
    /// Takes a crossing at `t` of triangle `number` if it is nearer, or as near with a
    /// lower number; before any is found, only one strictly before the limit (an
    /// overflowed, infinite distance is no crossing).
    #[inline(always)]
    fn offer(&mut self, t: f32, number: u32, block: u32, lane: usize) {
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
            };
        }
    }
}

/// The per-ray part of the node-wide slab test.
struct WideSlabs {
    origin: [f32x8; 3],
    /// Reciprocal direction, or, when a component is zero (or its reciprocal overflows),
    /// the direction itself for the dividing test.
    scale: [f32x8; 3],
    /// Which of `planes` is each axis' entry plane (min for a positive component).
    near: [usize; 3],
    /// Whether the dividing test runs (some reciprocal is not finite).
    exact: bool,
    /// Per axis in the dividing test: whether the direction component is zero.
    zero: [bool; 3],
}

impl WideSlabs {
    fn new(ray: &Ray<f32>) -> Self {
        let d = [ray.direction.x, ray.direction.y, ray.direction.z];
        let inv = d.map(|c| 1.0 / c);
        let exact = !inv.iter().all(|c| c.is_finite());
        WideSlabs {
            origin: [ray.origin.x, ray.origin.y, ray.origin.z].map(f32x8::splat),
            scale: if exact { d } else { inv }.map(f32x8::splat),
            near: [0, 1, 2].map(|k| if d[k] >= 0.0 { k } else { k + 3 }),
            exact,
            zero: d.map(|c| c == 0.0),
        }
    }

    /// Which children's boxes the ray enters within `[after, limit]` (bit per lane) and
    /// where (the padding of the boxes exceeds the reciprocal's error, as for the binary
    /// walk's [`crate::SlabRay::entry`]).
    #[inline(always)]
    fn entries(&self, node: &WideNode, after: f32, limit: f32) -> (u32, [f32; WIDTH]) {
        let mut entry = f32x8::splat(after);
        let mut exit = f32x8::splat(limit);
        let mut inside = f32x8::splat(f32::from_bits(u32::MAX));
        for k in 0..3 {
            let near = f32x8::from(node.planes[self.near[k]]);
            let far = f32x8::from(node.planes[(self.near[k] + 3) % 6]);
            let o = self.origin[k];
            let (t0, t1) = if !self.exact {
                ((near - o) * self.scale[k], (far - o) * self.scale[k])
            } else if self.zero[k] {
                // Parallel to the slab: inside it or not, at every distance.
                let lo = f32x8::from(node.planes[k]);
                let hi = f32x8::from(node.planes[k + 3]);
                inside = inside & lo.simd_le(o) & o.simd_le(hi);
                continue;
            } else {
                ((near - o) / self.scale[k], (far - o) / self.scale[k])
            };
            entry = entry.fast_max(t0);
            exit = exit.fast_min(t1);
        }
        let hit = (entry.simd_le(exit) & inside).to_bitmask();
        (hit, entry.to_array())
    }
}

/// The per-ray part of the 4-lane watertight triangle test (see `MeshPrim::crossing`).
struct WideRay {
    shear: Shear<f32>,
    origin: [f32x4; 3],
    shear_x: f32x4,
    shear_y: f32x4,
    shear_z: f32x4,
}

impl WideRay {
    fn new(ray: &Ray<f32>) -> Self {
        let shear = Shear::new(ray.direction);
        let origin = shear.axes.map(|k| f32x4::splat(ray.origin.get(k)));
        WideRay {
            shear_x: f32x4::splat(shear.x),
            shear_y: f32x4::splat(shear.y),
            shear_z: f32x4::splat(shear.z),
            origin,
            shear,
        }
    }

    /// Offers `best` the crossings after `after` of the triangles of block `index`.
    #[inline(always)]
    fn test(&self, block: &TriangleBlock, index: u32, ray: &Ray<f32>, after: f32, best: &mut Best) {
        let [kx, ky, kz] = self.shear.axes;
        let zero = f32x4::splat(0.0);
        // Vertex j relative to the origin, sheared: (x, y) and the unsheared height.
        let vertex = |j: usize| {
            let v = &block.vertex[j];
            let px = f32x4::from(v[kx]) - self.origin[0];
            let py = f32x4::from(v[ky]) - self.origin[1];
            let pz = f32x4::from(v[kz]) - self.origin[2];
            (px - self.shear_x * pz, py - self.shear_y * pz, pz)
        };
        let (ax, ay, az) = vertex(0);
        let (bx, by, bz) = vertex(1);
        let (cx, cy, cz) = vertex(2);
        let u = cx * by - cy * bx;
        let v = ax * cy - ay * cx;
        let w = bx * ay - by * ax;
        let det = u + v + w;
        let negative = u.simd_lt(zero) | v.simd_lt(zero) | w.simd_lt(zero);
        let positive = u.simd_gt(zero) | v.simd_gt(zero) | w.simd_gt(zero);
        let t = (u * (self.shear_z * az) + v * (self.shear_z * bz) + w * (self.shear_z * cz)) / det;
        let crossed = !(negative & positive) & det.simd_ne(zero);
        let candidate = crossed & t.simd_gt(f32x4::splat(after)) & t.simd_le(f32x4::splat(best.t));
        let on_edge = (u.simd_eq(zero) | v.simd_eq(zero) | w.simd_eq(zero)).to_bitmask();
        let mut lanes = (candidate.to_bitmask() & !on_edge) | on_edge;
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
            best.offer(t, number, index, lane);
        }
    }
}

/// A point or direction in f32 (exact when `T` is f32, the only precision that builds a
/// wide BVH).
pub(crate) fn point_f32<T: Real>(p: V3<T>) -> V3<f32> {
    V3::new(
        p.x.to_f64() as f32,
        p.y.to_f64() as f32,
        p.z.to_f64() as f32,
    )
}

/// A mesh's binary BVH and triangles in f32 (exact when `T` is f32).
pub(crate) fn to_f32<T: Real>(
    nodes: &[MeshNode<T>],
    triangles: &[[V3<T>; 3]],
) -> (Vec<MeshNode<f32>>, Vec<[V3<f32>; 3]>) {
    (
        nodes
            .iter()
            .map(|n| MeshNode {
                bounds: n.bounds.map(point_f32),
                first: n.first,
                count: n.count,
            })
            .collect(),
        triangles.iter().map(|t| t.map(point_f32)).collect(),
    )
}

#[cfg(test)]
#[path = "../../tests/common/mod.rs"]
mod test_common;

#[cfg(test)]
mod tests {
    use super::*;

    use super::test_common::{grid, Rng};

    /// A grid with integer heights, shifted by `offset`: every vertex, edge and box face is
    /// exact in f32, so rays aimed at them meet edge functions of exactly 0.
    fn shifted_grid(n: usize, offset: f64) -> Vec<[[f64; 3]; 3]> {
        let tris = grid(n, |x, y| ((x as usize * y as usize) % 3) as f64);
        tris.iter()
            .map(|t| t.map(|v| v.map(|c| c + offset)))
            .collect()
    }

    /// Runs both searches on a ray and its recentred form; returns whether it hit.
    fn both_agree(mesh: &MeshPrim<f32>, origin: [f64; 3], direction: [f64; 3]) -> bool {
        let wide = mesh.wide.as_ref().expect("f32 meshes have a wide BVH");
        let ray = Ray {
            origin: V3::from_f64(origin),
            direction: V3::from_f64(direction),
        };
        let (moved, shift) = mesh.recentred(&ray);
        let mut hit = false;
        for (r, after) in [(ray, 0.0f32), (moved, -shift)] {
            let got = wide.nearest(&r, after, f32::INFINITY);
            let want = mesh.nearest_binary(&r, after);
            if let Some((_, i, normal)) = got {
                let [v0, v1, v2] = mesh.triangles[i];
                assert_eq!(normal, (v1 - v0).cross(v2 - v0), "normal of triangle {i}");
            }
            assert_eq!(
                got.map(|(t, i, _)| (t.to_bits(), i)),
                want.map(|(t, i)| (t.to_bits(), i)),
                "ray {origin:?} + t {direction:?} after {after}: wide {got:?}, binary {want:?}"
            );
            hit |= got.is_some();
        }
        hit
    }

    #[test]
    fn wide_search_equals_the_binary_one_bit_for_bit_on_random_rays() {
        let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
        let mut soup = Vec::new();
        for _ in 0..3000 {
            let c = [0; 3].map(|_| rng.range(-10.0, 10.0));
            let size = rng.range(0.01, 2.0);
            soup.push([0; 3].map(|_| {
                let e = rng.unit();
                [0, 1, 2].map(|k| c[k] + size * e[k])
            }));
        }
        let mesh = MeshPrim::<f32>::new(&soup).unwrap();
        let mut hits = 0;
        for _ in 0..20_000 {
            let o = [0; 3].map(|_| rng.range(-15.0, 15.0));
            hits += both_agree(&mesh, o, rng.unit()) as usize;
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
                both_agree(&mesh, o, rng.unit());
            }
        }
    }
}
