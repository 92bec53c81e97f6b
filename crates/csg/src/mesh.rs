//! Triangle-mesh prims: closed meshes (tessellated solids, or solids with no analytic form
//! here) and open ones (mesh-file scenes), traced in f32 or f64 with the same crossing
//! semantics as CSG trees.
//!
//! Triangles sit in a binary BVH built by obvhs (from their f32 copies); the traversal runs
//! in the kernel's precision over node boxes padded for the f32 rounding, so it never culls
//! a triangle the ray meets. Triangles are counter-clockwise seen from outside, so the
//! geometric normal `(v1 - v0) x (v2 - v0)` points out and classifies each crossing as an
//! entry or an exit. Rays meet triangles by the watertight test of Woop, Benthin and Wald,
//! so a ray through an edge or vertex shared by triangles never slips between them.
//!
//! The traversal visits the nearer child first (by box entry), skips subtrees entered
//! beyond the best crossing so far, and tests boxes with the ray's reciprocal direction
//! (rays with a zero direction component keep the exact dividing test); sibling nodes
//! share a cache line, in depth-first order. Equal-distance ties go to the lowest triangle
//! number, so the answers (distances, normals, sides) are bit for bit those of the
//! unordered traversal this replaced. On the 1M-triangle heightfield of
//! `cargo bench -p hytrace-tests --bench mesh` (2-core VM, 2026-11-22, old and new
//! binaries run alternately) `MeshPrim::<f32>::first_crossing` went from 0.99-1.15 to
//! 2.30-2.74 Mrays/s on coherent rays and from 0.47-0.49 to 1.00-1.04 on incoherent ones
//! with 2 threads, about 2.2x (see BENCHMARKS.md).
//!
//! The f32 kernel's nearest-crossing search on the CPU does not walk this binary tree: it
//! walks its wide form (module `wide`: 8 children per node and 4 triangles per SIMD test),
//! built from it and giving the same answers bit for bit, with the instruction set chosen at
//! run time ([`crate::simd`]: AVX2 where the CPU has it, SSE2 otherwise; the same bits).
//! The binary tree stays what the GPU kernels, the f64 kernel and the parity count of
//! [`MeshPrim::contains`] traverse.
//!
//! obvhs' own compressed 8-wide BVH (`build_cwbvh_from_tris`) was measured first and not
//! adopted: with our triangle test it was only 3-13% (coherent) and 12-29% (incoherent)
//! faster than the binary walk, its node test clamps the entry to a fixed 1e-4 where our
//! recentred rays need a signed start, and its 8-bit child boxes, rounded outward but not
//! to the last bit, left one of 743 600 decoded boxes 3e-8 smaller than its triangles.

use std::ops::Range;

use glam::Vec3A;
use hytrace_foundry::{Foundry, PrimKind, Transform64};
use obvhs::bvh2::Bvh2;
use obvhs::triangle::Triangle as BvhTriangle;
use obvhs::BvhBuildParams;

use crate::bvh_build::{shallow_bvh2_from_tris, LeafPlan};
use crate::kernel::Step;
use crate::prim_tree::{ray_meets_bounds, tolerance, Bounds, SlabRay};
use crate::real::{Ray, Real, V3};
use crate::shape::CsgError;
use crate::simd::{self, run_on, Isa, Kernel, SimdPath};
use crate::wide_bvh::{ray_f32, PacketSlabs, PACKET};

mod wide;

use wide::{Found, Search, WideBvh};

/// How many mesh searches [`MeshPrim::first_crossings`] interleaves on one thread. Measured
/// on the 1M-triangle heightfield of `cargo bench -p hytrace-tests --bench mesh` (2-core VM,
/// incoherent rays, BENCHMARKS.md): 5, 8 and 16 gave the same speed within the noise, and
/// 8 beat 4 and 16 when finished searches were not replaced until all of them were done.
pub const INTERLEAVED: usize = 8;

/// How far apart, relative to a mesh's half size, the (recentred) origins of a packet's
/// rays may lie on each axis ([`MeshPrim::first_crossings`]).
pub const PACKET_SPREAD: f32 = 1.0 / 32.0;

/// How far apart, in radians, the directions of a packet's rays may point.
pub const PACKET_ANGLE: f32 = 0.05;

/// A first-crossing query of a mesh ([`MeshPrim::first_crossings`]).
#[derive(Clone, Copy, Debug)]
pub struct MeshQuery<'a, T> {
    /// The mesh.
    pub mesh: &'a MeshPrim<T>,
    /// The ray, in the mesh's frame.
    pub ray: Ray<T>,
    /// Crossings count after this parameter (and its surface tolerance).
    pub tmin: T,
}

/// Working space of [`MeshPrim::first_crossings`], kept from call to call (it is large).
#[derive(Default)]
pub struct CrossingScratch {
    searches: Vec<Search>,
    /// The queries left to the interleaved searches.
    rest: Vec<usize>,
}

/// The packet form of `rays` (recentred, of a mesh of half size `scale`) when they run
/// close enough together for a packet search to pay: origins within [`PACKET_SPREAD`] of
/// `scale` of each other on every axis, directions within [`PACKET_ANGLE`] radians of the
/// first one's, and of one sign on each axis ([`PacketSlabs::new`]).
fn coherent(rays: &[Ray<f32>], scale: f32) -> Option<PacketSlabs> {
    let first = rays.first()?;
    let spread = PACKET_SPREAD * scale;
    let cos = PACKET_ANGLE.cos();
    let d0 = first.direction;
    let close = rays.iter().all(|r| {
        let d = r.direction;
        (0..3).all(|k| (r.origin.get(k) - first.origin.get(k)).abs() <= spread)
            && d.dot(d0) >= cos * (d.length_squared() * d0.length_squared()).sqrt()
    });
    if close {
        PacketSlabs::new(rays)
    } else {
        None
    }
}

/// The nearest crossing (distance and normal) and the least doubtful one's distance
/// (`+inf`: none) of a search, in precision `T`.
type Nearest<T> = (Option<(T, V3<T>)>, T);

/// What the f32 wide search found, in precision `T` (exact: `T` is f32 there).
fn from_wide<T: Real>(found: Found) -> Nearest<T> {
    let from_f32 = |v: V3<f32>| V3::new(T::from_f32(v.x), T::from_f32(v.y), T::from_f32(v.z));
    let crossing = found
        .crossing
        .map(|(t, _, normal)| (T::from_f32(t), from_f32(normal)));
    (crossing, T::from_f32(found.doubt))
}

/// A triangle mesh ready for intersection in precision `T`, closed or open.
///
/// [`Self::first_crossing`] assumes nothing about closure: it is the nearest triangle
/// crossing, with that triangle's geometric normal `(v1 - v0) x (v2 - v0)`, and the ray
/// counts as inside before it when it comes from behind the triangle. On a closed,
/// outward-wound mesh these are entries and exits of its region. An open mesh (a
/// heightfield, a sheet) bounds no region: its first crossings are plain first hits, and
/// "inside" only names the side behind the triangle. [`Self::contains`] counts crossings
/// and so means something only for closed meshes; tracers ask it only in hierarchical
/// (GDML) scenes, whose meshes are closed solids.
#[derive(Clone, Debug, PartialEq)]
pub struct MeshPrim<T> {
    pub(crate) triangles: Vec<[V3<T>; 3]>,
    pub(crate) bounds: Bounds<T>,
    pub(crate) scale: T,
    pub(crate) nodes: Vec<MeshNode<T>>,
    /// The 4-wide form of the BVH the f32 kernel traverses on the CPU (`None` in f64).
    wide: Option<WideBvh>,
}

/// A BVH node: padded bounds, then either children `first, first + 1` (`count == 0`) or
/// triangles `first..first + count` of the reordered triangle list. Aligned so that a pair
/// of f32 siblings, stored at an even index, fills one 64-byte cache line.
#[derive(Clone, Debug, PartialEq)]
#[repr(C, align(32))]
pub(crate) struct MeshNode<T> {
    pub(crate) bounds: Bounds<T>,
    pub(crate) first: u32,
    pub(crate) count: u32,
}

/// Deepest mesh BVH the traversal's fixed stack accepts (PLOC trees over a million
/// triangles stay far below it).
pub(crate) const MAX_BVH_DEPTH: usize = crate::wide_bvh::MAX_DEPTH;

/// The nodes and triangles of a mesh BVH as the traversals read them, from obvhs' tree and
/// the leaves `plan` gives it. Nodes: sibling pairs in depth-first order (a subtree's nodes
/// close together) and at even indices (slot 1, never visited, repeats the root), boxes
/// padded by `pad` outward. Triangles: in leaf order, leaves met in a depth-first walk that
/// visits second children first (the traversal breaks ties between equal distances by this
/// numbering, see `nearest`, which keeps the answers of the unordered traversal earlier
/// versions had), a merged leaf's triangles in its subtree's order
/// ([`LeafPlan::prims_of`]).
fn lay_out<T: Real>(
    bvh: &Bvh2,
    plan: &LeafPlan,
    triangles: &[[[f64; 3]; 3]],
    pad: f64,
) -> (Vec<MeshNode<T>>, Vec<[V3<T>; 3]>) {
    let padded = |v: Vec3A, sign: f64| V3::from_f64([v.x, v.y, v.z].map(|c| c as f64 + sign * pad));
    let node = |i: usize, first: u32, count: u32| {
        let aabb = &bvh.nodes[i].aabb;
        MeshNode {
            bounds: [padded(aabb.min, -1.0), padded(aabb.max, 1.0)],
            first,
            count,
        }
    };
    let total = plan.prims.first().copied().unwrap_or(0) as usize;
    let mut ordered = vec![triangles[0].map(V3::from_f64); total];
    let mut nodes = vec![node(0, 0, 0), node(0, 0, 0)];
    // (position in `plan`, slot in `nodes`, the number of its subtree's first triangle)
    let mut stack = vec![(0usize, 0usize, 0u32)];
    while let Some((pos, slot, start)) = stack.pop() {
        let i = plan.node[pos] as usize;
        if plan.leaf[pos] {
            nodes[slot] = node(i, start, plan.prims[pos]);
            let slots = &mut ordered[start as usize..][..plan.prims[pos] as usize];
            for (slot, &p) in slots.iter_mut().zip(plan.prims_of(pos)) {
                *slot = triangles[p as usize].map(V3::from_f64);
            }
            continue;
        }
        let (a, b) = (pos + 1, plan.second[pos] as usize);
        let base = nodes.len();
        nodes[slot] = node(i, base as u32, 0);
        nodes.extend([node(0, 0, 0), node(0, 0, 0)]);
        // The second child's triangles are numbered first.
        stack.push((b, base + 1, start));
        stack.push((a, base, start + plan.prims[b]));
    }
    nodes[1] = nodes[0].clone();
    (nodes, ordered)
}

/// The per-ray part of the watertight test: axes permuted so `z` is the direction's
/// largest component, and the shear mapping the direction to +z.
struct Shear<T> {
    /// `kx, ky, kz`: `kz` the dominant axis, `kx, ky` swapped when the direction's `kz`
    /// component is negative, so triangles keep their winding in the sheared frame.
    axes: [usize; 3],
    /// `d[kx] / d[kz]`.
    x: T,
    /// `d[ky] / d[kz]`.
    y: T,
    /// `1 / d[kz]`.
    z: T,
}

impl<T: Real> Shear<T> {
    fn new(d: V3<T>) -> Self {
        let (ax, ay, az) = (d.x.abs(), d.y.abs(), d.z.abs());
        let kz = if ax >= ay && ax >= az {
            0
        } else if ay >= az {
            1
        } else {
            2
        };
        let (mut kx, mut ky) = ((kz + 1) % 3, (kz + 2) % 3);
        if d.get(kz) < T::ZERO {
            std::mem::swap(&mut kx, &mut ky);
        }
        let dz = d.get(kz);
        Shear {
            axes: [kx, ky, kz],
            x: d.get(kx) / dz,
            y: d.get(ky) / dz,
            z: T::ONE / dz,
        }
    }
}

/// Crossings [`MeshPrim::contains`] collects in one walk before it falls back to one
/// nearest-crossing query per crossing.
pub(crate) const PARITY_BUFFER: usize = 32;

/// Direction of the parity rays of [`MeshPrim::contains`]: no simple ratios between its
/// components, so it does not run along the edges of ordinary meshes.
pub(crate) const PARITY_DIRECTION: [f64; 3] = [0.577_215_664_9, 0.618_033_988_7, 0.533_751_168_8];

impl<T: Real> MeshPrim<T> {
    /// A mesh from triangles (f64 vertices in the solid's frame), its BVH built with
    /// obvhs's `fast_build` preset.
    pub fn new(triangles: &[[[f64; 3]; 3]]) -> Result<Self, CsgError> {
        Self::with_bvh_build(triangles, BvhBuildParams::fast_build())
    }

    /// [`MeshPrim::new`] with another obvhs BVH build preset: slower builds give BVHs
    /// that are faster to trace; the answers are the same.
    pub fn with_bvh_build(
        triangles: &[[[f64; 3]; 3]],
        build: BvhBuildParams,
    ) -> Result<Self, CsgError> {
        if triangles.is_empty() {
            return Err(CsgError {
                primitive: "mesh",
                problem: "a mesh needs at least one triangle".into(),
            });
        }
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for v in triangles.iter().flatten() {
            if !v.iter().all(|c| c.is_finite()) {
                return Err(CsgError {
                    primitive: "mesh",
                    problem: format!("vertex {v:?} is not finite"),
                });
            }
            for k in 0..3 {
                lo[k] = lo[k].min(v[k]);
                hi[k] = hi[k].max(v[k]);
            }
        }
        let size = (0..3).fold(0.0f64, |a, k| a.max(hi[k] - lo[k]));
        // Rounding vertices to T must not clip them out of the bounds.
        let pad = 1e-6 * (size + (0..3).fold(0.0f64, |a, k| a.max(lo[k].abs()).max(hi[k].abs())));
        let bvh_input: Vec<BvhTriangle> = triangles
            .iter()
            .map(|t| {
                let [v0, v1, v2] = t.map(|v| Vec3A::new(v[0] as f32, v[1] as f32, v[2] as f32));
                BvhTriangle { v0, v1, v2 }
            })
            .collect();
        let (bvh, plan) = shallow_bvh2_from_tris(&bvh_input, build);
        // Node boxes come from f32 vertices: pad them like the mesh bounds.
        let (nodes, ordered) = lay_out(&bvh, &plan, triangles, pad);
        let wide = (T::NAME == "f32")
            .then(|| {
                let (nodes, triangles) = wide::to_f32(&nodes, &ordered);
                wide::WideBvh::new(&nodes, &triangles)
            })
            .transpose()
            .map_err(|e| CsgError {
                primitive: "mesh",
                problem: e.to_string(),
            })?;
        Ok(MeshPrim {
            triangles: ordered,
            nodes,
            wide,
            bounds: [
                V3::from_f64(lo.map(|v| v - pad)),
                V3::from_f64(hi.map(|v| v + pad)),
            ],
            scale: T::from_f64(0.5 * size.max(f64::MIN_POSITIVE)),
        })
    }

    /// Mesh prim `prim` of a validated Foundry, its triangles mapped into the solid's frame.
    pub fn from_foundry(foundry: &Foundry, prim: usize) -> Result<Self, CsgError> {
        let err = |problem: String| CsgError {
            primitive: "mesh",
            problem: format!("prim {prim}: {problem}"),
        };
        let p = foundry
            .prim
            .get(prim)
            .ok_or_else(|| err("no such prim".into()))?;
        if p.kind != PrimKind::Mesh as u32 {
            return Err(err("not a mesh prim".into()));
        }
        let tris = foundry
            .tri
            .get(p.item_offset as usize..(p.item_offset + p.item_count) as usize)
            .ok_or_else(|| err("triangle range out of bounds".into()))?;
        let transform = match p.transform {
            0 => Transform64::IDENTITY,
            k => *foundry
                .tran
                .get(k as usize - 1)
                .ok_or_else(|| err(format!("transform {k} out of range")))?,
        };
        let triangles: Vec<[[f64; 3]; 3]> = tris
            .iter()
            .map(|t| {
                t.v.map(|v| transform.apply_point([v[0], v[1], v[2]].map(f64::from)))
            })
            .collect();
        Self::new(&triangles)
    }

    /// Bounds of the mesh in its solid's frame.
    pub fn bounds(&self) -> &Bounds<T> {
        &self.bounds
    }

    /// The ray moved to its closest approach to the mesh's centre, and the parameter of
    /// that point: working from there keeps f32 precise for rays starting far away. A ray
    /// starting within twice the mesh's size of its centre (any coordinate) stays where it
    /// is: its origin is exact there, and moving it would round it by the mesh's size times
    /// epsilon, where the triangle test's own rounding is the distance to the crossing
    /// times epsilon (a ray from 2 mm inside a 20 mm sphere was off by 10 ulps).
    fn recentred(&self, ray: &Ray<T>) -> (Ray<T>, T) {
        let d = ray.direction;
        let centre = (self.bounds[0] + self.bounds[1]) * T::HALF;
        let offset = ray.origin - centre;
        let far = offset.max_abs();
        let shift = if far > T::from_f64(4.0) * self.scale {
            -offset.dot(d) / d.length_squared()
        } else {
            T::ZERO
        };
        let shift = if shift.is_finite() { shift } else { T::ZERO };
        let moved = Ray {
            origin: ray.origin.at(d, shift),
            direction: d,
        };
        (moved, shift)
    }

    /// Visits the leaves whose boxes the (recentred) ray meets within `[after, limit]`,
    /// nearest box entry first: `leaf` gets each leaf's triangle range and the current
    /// limit and returns the new one. Subtrees are skipped once their box entry is beyond
    /// the limit, so a closest-hit query that lowers it to its best crossing prunes
    /// everything behind that crossing (boxes entered exactly at the limit are still
    /// visited: they may hold a tied crossing).
    fn walk(
        &self,
        ray: &Ray<T>,
        after: T,
        mut limit: T,
        mut leaf: impl FnMut(Range<usize>, T) -> T,
    ) {
        // Node boxes are padded by 1e-6 of the mesh's size plus its largest coordinate (at
        // least 1.5e-6 of its size) and the ray starts within twice that size of the
        // mesh's centre (any coordinate), or was moved to its closest approach to it (its
        // origin then within the mesh's bounding sphere whenever it can hit): a box face
        // lies at most 2.5 sizes from the origin, and the reciprocal slab test's position
        // error (three roundings of that: under 9e-7 of the size) stays inside the
        // padding, so [`SlabRay::entry`] culls no box that holds a crossing.
        let boxes = SlabRay::new(ray);
        let Some(root) = self.nodes.first() else {
            return;
        };
        if boxes.entry(ray, &root.bounds, after, limit).is_none() {
            return;
        }
        // A fixed stack (no allocation per ray) of the farther children and their box
        // entries: one push per level of descent, and the depth was bounded at build.
        let mut stack = [(0u32, T::ZERO); MAX_BVH_DEPTH + 1];
        let mut top = 0;
        let mut node = root;
        loop {
            if node.count == 0 {
                let (a, b) = (node.first as usize, node.first as usize + 1);
                let ea = boxes.entry(ray, &self.nodes[a].bounds, after, limit);
                let eb = boxes.entry(ray, &self.nodes[b].bounds, after, limit);
                match (ea, eb) {
                    (Some(ta), Some(tb)) => {
                        let (near, far, far_entry) = if tb < ta { (b, a, ta) } else { (a, b, tb) };
                        stack[top] = (far as u32, far_entry);
                        top += 1;
                        node = &self.nodes[near];
                        continue;
                    }
                    (Some(_), None) => {
                        node = &self.nodes[a];
                        continue;
                    }
                    (None, Some(_)) => {
                        node = &self.nodes[b];
                        continue;
                    }
                    (None, None) => {}
                }
            } else {
                limit = leaf(
                    node.first as usize..(node.first + node.count) as usize,
                    limit,
                );
            }
            // The nearest postponed subtree still entered within the limit.
            loop {
                if top == 0 {
                    return;
                }
                top -= 1;
                let (index, entry) = stack[top];
                if entry <= limit {
                    node = &self.nodes[index as usize];
                    break;
                }
            }
        }
    }

    /// The nearest crossing after `after` of a (recentred) ray, with the triangle's
    /// geometric, not normalized, normal. Crossings at equal distances go to the lowest
    /// triangle index, so the answer does not depend on the order leaves are visited in
    /// (triangles are numbered in the order a depth-first walk visiting second children
    /// first meets them, the order earlier versions searched them in). With it, in f32, the
    /// least distance of a crossing within rounding not beyond it (`Found::doubt`; `+inf`
    /// in f64, which has nothing to fall back to).
    fn nearest(&self, ray: &Ray<T>, after: T) -> Nearest<T> {
        match &self.wide {
            Some(wide) => from_wide(wide.nearest(
                simd::selected(),
                &ray_f32(ray),
                after.to_f64() as f32,
                f32::INFINITY,
            )),
            None => {
                let found = self.nearest_binary(ray, after).map(|(t, i)| {
                    let [v0, v1, v2] = self.triangles[i];
                    (t, (v1 - v0).cross(v2 - v0))
                });
                (found, T::INFINITY)
            }
        }
    }

    /// [`Self::nearest`] by the binary BVH, one box and one triangle at a time: the f64
    /// kernel's search, and the f32 one's on the GPU. Returns the distance and triangle.
    fn nearest_binary(&self, ray: &Ray<T>, after: T) -> Option<(T, usize)> {
        let shear = Shear::new(ray.direction);
        let mut best: Option<(T, usize)> = None;
        self.walk(ray, after, T::INFINITY, |leaf, limit| {
            let start = leaf.start;
            for (i, tri) in self.triangles[leaf].iter().enumerate() {
                let Some(t) = Self::crossing(tri, ray, &shear) else {
                    continue;
                };
                let index = start + i;
                // Strictly below the limit when nothing is found yet: an overflowed
                // (infinite) distance is no crossing.
                let better = match best {
                    None => t < limit,
                    Some((b, j)) => t < b || (t == b && index < j),
                };
                if t > after && better {
                    best = Some((t, index));
                }
            }
            best.map_or(limit, |(b, _)| b)
        });
        best
    }

    /// Bytes of the BVH nodes, in both forms (the f32 kernel's wide form adds its copy of
    /// the triangles, in blocks).
    pub fn bvh_bytes(&self) -> usize {
        std::mem::size_of_val(self.nodes.as_slice()) + self.wide.as_ref().map_or(0, |w| w.bytes())
    }

    /// The ray parameter where `ray` meets triangle `tri` (either side), by the
    /// watertight test of [`MeshPrim::first_crossing`]; `None` when it misses.
    pub fn triangle_crossing(tri: &[V3<T>; 3], ray: &Ray<T>) -> Option<T> {
        Self::crossing(tri, ray, &Shear::new(ray.direction))
    }

    /// Where a ray meets one triangle, by the watertight test of Woop, Benthin and Wald
    /// (2013): vertices are taken relative to the origin and sheared so the ray runs along
    /// +z, leaving a 2D point-in-triangle test at (0, 0) by the signs of three edge
    /// functions. Adjacent triangles evaluate a shared edge's function from the same two
    /// sheared vertices, with opposite signs, so no ray passes between them; zeros count as
    /// inside (a ray through an edge hits both sides).
    #[inline(always)]
    fn crossing(tri: &[V3<T>; 3], ray: &Ray<T>, shear: &Shear<T>) -> Option<T> {
        let [kx, ky, kz] = shear.axes;
        let [v0, v1, v2] = *tri;
        let (a, b, c) = (v0 - ray.origin, v1 - ray.origin, v2 - ray.origin);
        let sheared = |p: V3<T>| {
            (
                p.get(kx) - shear.x * p.get(kz),
                p.get(ky) - shear.y * p.get(kz),
            )
        };
        let ((ax, ay), (bx, by), (cx, cy)) = (sheared(a), sheared(b), sheared(c));
        let mut u = cx * by - cy * bx;
        let mut v = ax * cy - ay * cx;
        let mut w = bx * ay - by * ax;
        // In f32 an edge function of exactly 0 may be a rounding artefact of the
        // products: recompute all three from the same sheared values in f64 (the f64
        // kernel has no wider type to fall back to).
        if T::NAME == "f32" && (u == T::ZERO || v == T::ZERO || w == T::ZERO) {
            let edge = |px: T, py: T, qx: T, qy: T| {
                T::from_f64(px.to_f64() * qy.to_f64() - py.to_f64() * qx.to_f64())
            };
            u = edge(cx, cy, bx, by);
            v = edge(ax, ay, cx, cy);
            w = edge(bx, by, ax, ay);
        }
        let negative = u < T::ZERO || v < T::ZERO || w < T::ZERO;
        let positive = u > T::ZERO || v > T::ZERO || w > T::ZERO;
        let det = u + v + w;
        if (negative && positive) || det == T::ZERO {
            return None;
        }
        // Barycentric-weighted heights along the ray, then one division.
        let (az, bz, cz) = (
            shear.z * a.get(kz),
            shear.z * b.get(kz),
            shear.z * c.get(kz),
        );
        Some((u * az + v * bz + w * cz) / det)
    }

    /// The first crossing of the mesh's surface after `tmin` (crossings within the surface
    /// tolerance of `tmin` are the surface the ray starts on), with the triangle's
    /// geometric normal (outward on a closed mesh) and whether the ray comes from behind
    /// that triangle (from inside, on a closed mesh).
    pub fn first_crossing(&self, ray: &Ray<T>, tmin: T) -> Step<T> {
        match self.search_start(ray, tmin) {
            Some((moved, shift, after)) => Self::step_at(self.nearest(&moved, after), shift, ray),
            None => Step::miss(false),
        }
    }

    /// Where [`Self::first_crossing`]'s search starts: the recentred ray, the shift of its
    /// parameter and the recentred parameter after which crossings count; `None` when the
    /// ray misses the mesh's box.
    fn search_start(&self, ray: &Ray<T>, tmin: T) -> Option<(Ray<T>, T, T)> {
        if !ray_meets_bounds(ray, &self.bounds, tmin, T::INFINITY) {
            return None;
        }
        let after = tmin + tolerance(self.scale, tmin);
        let (moved, shift) = self.recentred(ray);
        Some((moved, shift, after - shift))
    }

    /// [`Self::first_crossing`]'s answer from what the search recentred by `shift` found.
    /// A doubtful crossing is reported as [`Step::dropped`]: a decision within rounding,
    /// which scans trace again in f64.
    fn step_at((found, doubt): Nearest<T>, shift: T, ray: &Ray<T>) -> Step<T> {
        let dropped = doubt + shift;
        match found {
            Some((t, normal)) => Step {
                t: t + shift,
                normal,
                inside_before: normal.dot(ray.direction) > T::ZERO,
                dropped,
            },
            None => Step {
                dropped,
                ..Step::miss(false)
            },
        }
    }

    /// [`Self::first_crossing`] of every query, in `out` (cleared first), bit for bit. In
    /// f32, consecutive queries of one mesh whose rays run close together (camera rays,
    /// fine sweeps: origins within [`PACKET_SPREAD`] of the mesh's half size, directions
    /// within [`PACKET_ANGLE`]) are searched [`PACKET`] at a time as a packet, each node
    /// fetched and tested once for all of them (`WideTree::walk_packet`); the other
    /// searches run [`INTERLEAVED`] at a time on this thread, one step of each in turn,
    /// each step asking for the memory its next one reads: a search of a large mesh mostly
    /// waits on memory, and so waits for several at once. A finished search's place goes
    /// to the next query at once, so the searches stay that many until the queries run
    /// out. Meshes in f64 are searched one query after another. The searches run on the
    /// SIMD path [`simd::selected`] names.
    pub fn first_crossings(
        queries: &[MeshQuery<'_, T>],
        scratch: &mut CrossingScratch,
        out: &mut Vec<Step<T>>,
    ) {
        Self::first_crossings_on(simd::selected(), queries, scratch, out);
    }

    /// [`Self::first_crossings`] on SIMD path `path`, whatever [`simd::selected`] says (the
    /// same answers on every path; tests and benchmarks compare them). A path this CPU
    /// does not run ([`SimdPath::supported`]) runs the portable one.
    pub fn first_crossings_on(
        path: SimdPath,
        queries: &[MeshQuery<'_, T>],
        scratch: &mut CrossingScratch,
        out: &mut Vec<Step<T>>,
    ) {
        /// The searches as a [`Kernel`].
        struct Crossings<'q, 'm, 's, T>(
            &'q [MeshQuery<'m, T>],
            &'s mut CrossingScratch,
            &'s mut Vec<Step<T>>,
        );
        impl<T: Real> Kernel for Crossings<'_, '_, '_, T> {
            type Output = ();
            #[inline(always)]
            fn run<S: Isa>(self) {
                let Crossings(queries, scratch, out) = self;
                MeshPrim::first_crossings_with::<S>(queries, scratch, out);
            }
        }
        run_on(path, Crossings(queries, scratch, out));
    }

    /// [`Self::first_crossings`] with the vectors of `S`.
    #[inline(always)]
    fn first_crossings_with<S: Isa>(
        queries: &[MeshQuery<'_, T>],
        scratch: &mut CrossingScratch,
        out: &mut Vec<Step<T>>,
    ) {
        out.clear();
        out.resize(queries.len(), Step::miss(false));
        let CrossingScratch { searches, rest } = scratch;
        // Packets first; what they leave goes to the interleaved searches.
        rest.clear();
        let mut start = 0;
        while start < queries.len() {
            let mesh = queries[start].mesh;
            let stop = queries.len().min(start + PACKET);
            let end = (start + 1..stop)
                .find(|&j| !std::ptr::eq(queries[j].mesh, mesh))
                .unwrap_or(stop);
            if !mesh.search_packet::<S>(&queries[start..end], &mut out[start..end]) {
                rest.extend(start..end);
            }
            start = end;
        }
        if searches.len() < INTERLEAVED {
            searches.resize_with(INTERLEAVED, Search::new);
        }
        // Per place: the query its search answers, the mesh's wide BVH, the search's shift.
        let mut running: [Option<(usize, &WideBvh, T)>; INTERLEAVED] = [None; INTERLEAVED];
        let mut waiting = rest.iter().copied();
        loop {
            let mut busy = false;
            for (place, search) in running.iter_mut().zip(searches.iter_mut()) {
                if let Some((i, wide, shift)) = *place {
                    if !wide.advance::<S, true>(search) {
                        let found = from_wide(wide.answer(search));
                        out[i] = Self::step_at(found, shift, &queries[i].ray);
                        *place = None;
                    }
                }
                // An empty place takes the next query needing a search.
                while place.is_none() {
                    let Some(next) = waiting.next() else { break };
                    let q = &queries[next];
                    match (&q.mesh.wide, q.mesh.search_start(&q.ray, q.tmin)) {
                        (Some(wide), Some((moved, shift, after))) => {
                            let after = after.to_f64() as f32;
                            search.start(&ray_f32(&moved), after, f32::INFINITY);
                            *place = Some((next, wide, shift));
                        }
                        (None, _) => out[next] = q.mesh.first_crossing(&q.ray, q.tmin),
                        (Some(_), None) => {}
                    }
                }
                busy |= place.is_some();
            }
            if !busy {
                return;
            }
        }
    }

    /// [`Self::first_crossing`] of `queries` (of this mesh, at most [`PACKET`]) searched as
    /// one packet, into `out`, when the mesh has a wide BVH and at least two of the rays
    /// meet its box and run close together ([`coherent`]); false, `out` holding nothing of
    /// use, when not.
    #[inline(always)]
    fn search_packet<S: Isa>(&self, queries: &[MeshQuery<'_, T>], out: &mut [Step<T>]) -> bool {
        let Some(wide) = &self.wide else {
            return false;
        };
        if queries.len() < 2 {
            return false;
        }
        let unused = Ray {
            origin: V3::new(0.0, 0.0, 0.0),
            direction: V3::new(0.0, 0.0, 1.0),
        };
        let mut rays = [unused; PACKET];
        let mut after = [0.0f32; PACKET];
        // Per ray of the packet: its query and the shift of its parameter.
        let mut asked = [(0, T::ZERO); PACKET];
        let mut n = 0;
        for (i, q) in queries.iter().enumerate() {
            if let Some((moved, shift, from)) = self.search_start(&q.ray, q.tmin) {
                rays[n] = ray_f32(&moved);
                after[n] = from.to_f64() as f32;
                asked[n] = (i, shift);
                n += 1;
            }
        }
        let packet = match coherent(&rays[..n], self.scale.to_f64() as f32) {
            Some(packet) if n >= 2 => packet,
            _ => return false,
        };
        let none = Found {
            crossing: None,
            doubt: f32::INFINITY,
        };
        let mut found = [none; PACKET];
        wide.nearest_packet::<S>(&packet, &rays[..n], &after[..n], &mut found[..n]);
        for (&(i, shift), found) in asked[..n].iter().zip(found) {
            out[i] = Self::step_at(from_wide(found), shift, &queries[i].ray);
        }
        true
    }

    /// Whether a point of the solid's frame is inside the mesh (parity of the crossings of
    /// a ray from it); meaningful for closed meshes only.
    pub fn contains(&self, x: V3<T>) -> bool {
        let ray = Ray {
            origin: x,
            direction: V3::from_f64(PARITY_DIRECTION),
        };
        if !ray_meets_bounds(&ray, &self.bounds, T::ZERO, T::INFINITY) {
            return false;
        }
        // Crossings in the recentred parameter, counted once per distinct distance (a ray
        // through a shared edge crosses the surface once): one walk collecting them, or,
        // past the buffer's capacity, one nearest-crossing query after another.
        let (moved, shift) = self.recentred(&ray);
        let shear = Shear::new(moved.direction);
        let mut found = [T::ZERO; PARITY_BUFFER];
        let mut count = 0;
        self.walk(&moved, -shift, T::INFINITY, |leaf, limit| {
            for tri in &self.triangles[leaf] {
                match Self::crossing(tri, &moved, &shear) {
                    Some(t) if t > -shift && t < T::INFINITY => {
                        if let Some(slot) = found.get_mut(count) {
                            *slot = t;
                        }
                        count += 1;
                    }
                    _ => {}
                }
            }
            limit
        });
        if count > PARITY_BUFFER {
            let mut inside = false;
            let mut after = -shift;
            while let (Some((t, _)), _) = self.nearest(&moved, after) {
                inside = !inside;
                after = t;
            }
            return inside;
        }
        let found = &mut found[..count];
        found.sort_unstable_by(|a, b| a.partial_cmp(b).unwrap_or(std::cmp::Ordering::Equal));
        let distinct = found
            .iter()
            .enumerate()
            .filter(|&(i, t)| i == 0 || found[i - 1] < *t)
            .count();
        distinct % 2 == 1
    }
}
