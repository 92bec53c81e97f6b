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

use std::time::Duration;

use glam::Vec3A;
use hytrace_foundry::{Foundry, PrimKind, Transform64};
use obvhs::bvh2::builder::build_bvh2_from_tris;
use obvhs::triangle::Triangle as BvhTriangle;
use obvhs::BvhBuildParams;

use crate::kernel::Step;
use crate::prim_tree::{ray_meets_bounds, tolerance, Bounds};
use crate::real::{Ray, Real, V3};
use crate::shape::CsgError;

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
    triangles: Vec<[V3<T>; 3]>,
    bounds: Bounds<T>,
    scale: T,
    nodes: Vec<MeshNode<T>>,
}

/// A BVH node: padded bounds, then either children `first, first + 1` (`count == 0`) or
/// triangles `first..first + count` of the reordered triangle list.
#[derive(Clone, Debug, PartialEq)]
struct MeshNode<T> {
    bounds: Bounds<T>,
    first: u32,
    count: u32,
}

/// Deepest mesh BVH the traversal's fixed stack accepts (PLOC trees over a million
/// triangles stay far below it).
const MAX_BVH_DEPTH: usize = 64;

/// Levels below the root of an obvhs BVH2 (0 for a single leaf or an empty tree): the
/// traversal stack a tree needs.
pub fn bvh2_depth(nodes: &[obvhs::bvh2::node::Bvh2Node]) -> usize {
    let mut deepest = 0;
    let mut stack = vec![(0usize, 0usize)];
    while let Some((index, depth)) = stack.pop() {
        let Some(n) = nodes.get(index) else { continue };
        deepest = deepest.max(depth);
        if n.prim_count == 0 {
            let first = n.first_index as usize;
            stack.push((first, depth + 1));
            stack.push((first + 1, depth + 1));
        }
    }
    deepest
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

/// Direction of the parity rays of [`MeshPrim::contains`]: no simple ratios between its
/// components, so it does not run along the edges of ordinary meshes.
const PARITY_DIRECTION: [f64; 3] = [0.577_215_664_9, 0.618_033_988_7, 0.533_751_168_8];

impl<T: Real> MeshPrim<T> {
    /// A mesh from triangles (f64 vertices in the solid's frame).
    pub fn new(triangles: &[[[f64; 3]; 3]]) -> Result<Self, CsgError> {
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
        let bvh = build_bvh2_from_tris(
            &bvh_input,
            BvhBuildParams::fast_build(),
            &mut Duration::default(),
        );
        // Triangles in the BVH's leaf order, so leaves index them directly.
        let ordered: Vec<[V3<T>; 3]> = bvh
            .primitive_indices
            .iter()
            .map(|&i| triangles[i as usize].map(V3::from_f64))
            .collect();
        // Node boxes come from f32 vertices: pad them like the mesh bounds.
        let padded =
            |v: Vec3A, sign: f64| V3::from_f64([v.x, v.y, v.z].map(|c| c as f64 + sign * pad));
        let depth = bvh2_depth(&bvh.nodes);
        if depth > MAX_BVH_DEPTH {
            return Err(CsgError {
                primitive: "mesh",
                problem: format!(
                    "BVH over {} triangles is {depth} levels deep, more than {MAX_BVH_DEPTH}",
                    triangles.len()
                ),
            });
        }
        let nodes = bvh
            .nodes
            .iter()
            .map(|n| MeshNode {
                bounds: [padded(n.aabb.min, -1.0), padded(n.aabb.max, 1.0)],
                first: n.first_index,
                count: n.prim_count,
            })
            .collect();
        Ok(MeshPrim {
            triangles: ordered,
            bounds: [
                V3::from_f64(lo.map(|v| v - pad)),
                V3::from_f64(hi.map(|v| v + pad)),
            ],
            scale: T::from_f64(0.5 * size.max(f64::MIN_POSITIVE)),
            nodes,
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
    /// that point: working from there keeps f32 precise for rays starting far away.
    fn recentred(&self, ray: &Ray<T>) -> (Ray<T>, T) {
        let d = ray.direction;
        let centre = (self.bounds[0] + self.bounds[1]) * T::HALF;
        let shift = -(ray.origin - centre).dot(d) / d.length_squared();
        let shift = if shift.is_finite() { shift } else { T::ZERO };
        let moved = Ray {
            origin: ray.origin.at(d, shift),
            direction: d,
        };
        (moved, shift)
    }

    /// The nearest crossing after `after` of a (recentred) ray, with the triangle's
    /// geometric, not normalized, normal.
    fn nearest(&self, ray: &Ray<T>, after: T) -> Option<(T, V3<T>)> {
        let shear = Shear::new(ray.direction);
        let mut best: Option<(T, V3<T>)> = None;
        // A fixed stack (no allocation per ray): depth was bounded when the mesh was built,
        // and visiting pushes two children for each node popped.
        let mut stack = [0u32; MAX_BVH_DEPTH + 1];
        let mut top = usize::from(!self.nodes.is_empty());
        while top > 0 {
            top -= 1;
            let node = &self.nodes[stack[top] as usize];
            let limit = best.map_or(T::INFINITY, |(b, _)| b);
            if !ray_meets_bounds(ray, &node.bounds, after, limit) {
                continue;
            }
            if node.count == 0 {
                stack[top] = node.first;
                stack[top + 1] = node.first + 1;
                top += 2;
                continue;
            }
            let leaf = node.first as usize..(node.first + node.count) as usize;
            if let Some(hit) = Self::nearest_in(&self.triangles[leaf], ray, &shear, after, limit) {
                best = Some(hit);
            }
        }
        best
    }

    /// The nearest crossing in `(after, limit)` among `triangles`, by the watertight test
    /// of Woop, Benthin and Wald (2013): vertices are taken relative to the origin and
    /// sheared so the ray runs along +z, leaving a 2D point-in-triangle test at (0, 0) by
    /// the signs of three edge functions. Adjacent triangles evaluate a shared edge's
    /// function from the same two sheared vertices, with opposite signs, so no ray passes
    /// between them; zeros count as inside (a ray through an edge hits both sides).
    fn nearest_in(
        triangles: &[[V3<T>; 3]],
        ray: &Ray<T>,
        shear: &Shear<T>,
        after: T,
        limit: T,
    ) -> Option<(T, V3<T>)> {
        let mut best: Option<(T, V3<T>)> = None;
        let [kx, ky, kz] = shear.axes;
        for [v0, v1, v2] in triangles {
            let (a, b, c) = (*v0 - ray.origin, *v1 - ray.origin, *v2 - ray.origin);
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
                continue;
            }
            // Barycentric-weighted heights along the ray, then one division.
            let (az, bz, cz) = (
                shear.z * a.get(kz),
                shear.z * b.get(kz),
                shear.z * c.get(kz),
            );
            let t = (u * az + v * bz + w * cz) / det;
            if t > after && t < limit && best.is_none_or(|(b, _)| t < b) {
                best = Some((t, (*v1 - *v0).cross(*v2 - *v0)));
            }
        }
        best
    }

    /// The first crossing of the mesh's surface after `tmin` (crossings within the surface
    /// tolerance of `tmin` are the surface the ray starts on), with the triangle's
    /// geometric normal (outward on a closed mesh) and whether the ray comes from behind
    /// that triangle (from inside, on a closed mesh).
    pub fn first_crossing(&self, ray: &Ray<T>, tmin: T) -> Step<T> {
        if !ray_meets_bounds(ray, &self.bounds, tmin, T::INFINITY) {
            return Step::miss(false);
        }
        let after = tmin + tolerance(self.scale, tmin);
        let (moved, shift) = self.recentred(ray);
        match self.nearest(&moved, after - shift) {
            Some((t, normal)) => Step {
                t: t + shift,
                normal,
                inside_before: normal.dot(ray.direction) > T::ZERO,
            },
            None => Step::miss(false),
        }
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
        // Count crossings in the recentred parameter; each query starts strictly after the
        // last crossing, so the walk ends.
        let (moved, shift) = self.recentred(&ray);
        let mut inside = false;
        let mut after = -shift;
        while let Some((t, _)) = self.nearest(&moved, after) {
            inside = !inside;
            after = t;
        }
        inside
    }
}
