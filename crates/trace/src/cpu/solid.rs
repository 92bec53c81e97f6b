//! One solid prepared for tracing: its surface prims (CSG trees, triangle meshes) and its
//! volume bricks grouped into clusters, with one BVH over all of them when they are many.
//!
//! Bricks are grouped by the 64^3-voxel region (the coarsest range-mip block) holding them:
//! a cluster's box is the union of its bricks' boxes, so the clusters cover every place a
//! medium can have a non-zero density (outside its bricks a medium is its zero
//! background). Rays asking for surfaces skip cluster leaves; rays asking for media skip
//! surface leaves.

use std::collections::BTreeMap;

use crate::error::Context;
use hytrace_csg::kernel::Step;
use hytrace_csg::{
    ray_bounds_span, transform_bounds, Bounds, PreparedPrim, Ray, Real, SlabRay, EMPTY_AABB, V3,
};
use hytrace_foundry::{Foundry, PrimKind, Transform64};

use super::batch::Crossings;
use super::bvh::{BoxBvh, RaySlabs};
use super::{widened_bounds, Hit, BVH_MIN_MEMBERS};

/// Side, in voxels, of the regions whose bricks form one cluster.
pub const CLUSTER_SIDE: i32 = 64;

/// Bricks of one medium in one 64^3-voxel region.
#[derive(Clone, Debug)]
pub(crate) struct Cluster<T> {
    /// Index of the medium (into the Foundry's `optics.media`).
    pub medium: u32,
    /// Box in the solid's frame.
    pub bounds: Bounds<T>,
}

/// A crossing of one of a solid's surface prims, in the solid's frame.
#[derive(Clone, Copy, Debug)]
pub(super) struct PrimCrossing<T> {
    pub t: T,
    /// Outward normal, not normalized.
    pub normal: V3<T>,
    /// The Foundry prim crossed.
    pub prim: u32,
}

impl<T> PrimCrossing<T> {
    /// The crossing as a hit of instance `instance` (the normal still in the solid's frame).
    pub fn hit(self, instance: u32) -> Hit<T> {
        Hit {
            t: self.t,
            normal: self.normal,
            instance,
            prim: self.prim,
        }
    }
}

/// A solid's prims and clusters.
#[derive(Clone, Debug)]
pub(super) struct SolidAccel<T> {
    /// Surface prims.
    pub prims: Vec<PreparedPrim<T>>,
    /// Foundry index of each surface prim.
    pub prim_ids: Vec<u32>,
    /// Volume-brick clusters.
    pub clusters: Vec<Cluster<T>>,
    /// Over surface prims (ids `0..prims.len()`) then clusters (the ids after), when there
    /// are more than [`BVH_MIN_MEMBERS`] of them.
    pub bvh: Option<BoxBvh<T>>,
    /// Whether every surface prim is a CSG tree whose signed distance bounds true
    /// distances ([`hytrace_csg::PrimTree::sdf_is_distance`]): [`Self::near_surface`]
    /// then decides alone whether a point is near the surface.
    pub sdf_decides: bool,
}

/// The prim transform of `prim` (identity for none).
fn prim_transform(f: &Foundry, prim: usize) -> Transform64 {
    match f.prim[prim].transform {
        0 => Transform64::IDENTITY,
        k => f.tran[k as usize - 1],
    }
}

/// Clusters of volume prim `prim`, boxes in the solid's frame.
fn clusters_of<T: Real>(f: &Foundry, prim: usize) -> crate::Result<Vec<Cluster<T>>> {
    let medium = f
        .optics
        .media
        .iter()
        .position(|m| m.prim as usize == prim)
        .with_context(|| format!("volume prim {prim} has no medium"))?;
    let p = &f.prim[prim];
    let to_solid = prim_transform(f, prim);
    let mut regions: BTreeMap<[i32; 3], [f64; 6]> = BTreeMap::new();
    for b in &f.brick[p.item_offset as usize..(p.item_offset + p.item_count) as usize] {
        let key = b.origin.map(|c| c.div_euclid(CLUSTER_SIDE));
        let r = regions.entry(key).or_insert(EMPTY_AABB);
        for k in 0..3 {
            r[k] = r[k].min(f64::from(b.aabb[k]));
            r[k + 3] = r[k + 3].max(f64::from(b.aabb[k + 3]));
        }
    }
    Ok(regions
        .values()
        .map(|r| Cluster {
            medium: medium as u32,
            bounds: widened_bounds(&transform_bounds(r, &to_solid)),
        })
        .collect())
}

impl<T: Real> SolidAccel<T> {
    /// Prepares solid `solid` of a validated Foundry.
    pub fn new(f: &Foundry, solid: usize) -> crate::Result<Self> {
        let s = &f.solid[solid];
        let (mut prims, mut prim_ids, mut clusters) = (Vec::new(), Vec::new(), Vec::new());
        for p in s.prim_offset as usize..(s.prim_offset + s.num_prim) as usize {
            if f.prim[p].kind == PrimKind::Volume as u32 {
                clusters.extend(clusters_of(f, p)?);
            } else if let Some(prepared) = PreparedPrim::from_foundry(f, p)? {
                prims.push(prepared);
                prim_ids.push(p as u32);
            }
        }
        let leaves = prims.len() + clusters.len();
        let bvh = if leaves > BVH_MIN_MEMBERS {
            let boxes: Vec<(u32, Bounds<T>)> = prims
                .iter()
                .map(|p| *p.bounds())
                .chain(clusters.iter().map(|c| c.bounds))
                .enumerate()
                .map(|(i, b)| (i as u32, b))
                .collect();
            Some(BoxBvh::new(&boxes)?)
        } else {
            None
        };
        let sdf_decides = prims
            .iter()
            .all(|p| matches!(p, PreparedPrim::Csg(tree) if tree.sdf_is_distance()));
        Ok(SolidAccel {
            prims,
            prim_ids,
            clusters,
            bvh,
            sdf_decides,
        })
    }

    /// The first surface crossing in `(tmin, limit)` of a ray in the solid's frame; of
    /// crossings at the same `t`, the lowest prim's. `boxed`: the caller found the ray
    /// meeting a box as tight as the solid's (an axis-aligned placement's world box), so a
    /// lone prim's own box test would cull nothing more.
    /// The prims' first crossings come from `crossings`; when it abandons the trace, the
    /// search stops and its answer means nothing. Decisions within rounding are noted there
    /// ([`Crossings::note_dropped`]) at world parameters: `shift` (the world parameter of
    /// the local ray's origin) plus the local one.
    pub fn cross<'a>(
        &'a self,
        ray: &Ray<T>,
        tmin: T,
        limit: T,
        shift: T,
        boxed: bool,
        crossings: &mut impl Crossings<'a, T>,
    ) -> Option<PrimCrossing<T>> {
        if boxed && self.prims.len() == 1 {
            let step = crossings.first_crossing(&self.prims[0], ray, tmin)?;
            if step.dropped < limit {
                crossings.note_dropped(shift + step.dropped);
            }
            return self.lone_crossing(&step, tmin, limit);
        }
        // (local prim index, t, normal)
        let mut best: Option<(usize, T, V3<T>)> = None;
        if self.prims.is_empty() {
            return None;
        }
        // `cull`: the ray's slab form to skip a prim whose box it misses; `None` when a BVH
        // walk found it meeting the box.
        // False when `crossings` abandons the trace.
        let mut try_prim =
            |i: usize, cull: Option<&SlabRay<T>>, best: &mut Option<(usize, T, V3<T>)>| {
                let within = best.map_or(limit, |b| b.1);
                let prim = &self.prims[i];
                // A superset of the exact test's boxes: culling only, the prim decides.
                if cull.is_some_and(|s| {
                    s.entry_conservative(ray, prim.bounds(), tmin, within)
                        .is_none()
                }) {
                    return true;
                }
                let Some(step) = crossings.first_crossing(prim, ray, tmin) else {
                    return false;
                };
                // A span skipped as a touch, or a mesh triangle decided within rounding,
                // before the limit: the fallback.
                if step.dropped < within {
                    crossings.note_dropped(shift + step.dropped);
                }
                let tie_won = step.t == within && best.is_some_and(|b| i < b.0);
                if step.t > tmin && (step.t < within || tie_won) {
                    *best = Some((i, step.t, step.normal));
                }
                true
            };
        match &self.bvh {
            None => {
                let slabs = SlabRay::new(ray);
                for i in 0..self.prims.len() {
                    if !try_prim(i, Some(&slabs), &mut best) {
                        return None;
                    }
                }
            }
            Some(bvh) => {
                let mut abandoned = false;
                bvh.visit_ray(ray, &RaySlabs::new(ray), tmin, limit, |id| {
                    if (id as usize) < self.prims.len() && !try_prim(id as usize, None, &mut best) {
                        abandoned = true;
                        return -T::INFINITY;
                    }
                    best.map_or(limit, |b| b.1)
                });
                if abandoned {
                    return None;
                }
            }
        }
        best.map(|(i, t, normal)| PrimCrossing {
            t,
            normal,
            prim: self.prim_ids[i],
        })
    }

    /// The crossing in `(tmin, limit)` of a solid of one surface prim, from that prim's
    /// first crossing `step`.
    #[inline]
    pub fn lone_crossing(&self, step: &Step<T>, tmin: T, limit: T) -> Option<PrimCrossing<T>> {
        (step.t > tmin && step.t < limit).then(|| PrimCrossing {
            t: step.t,
            normal: step.normal,
            prim: self.prim_ids[0],
        })
    }

    /// Whether a point of the solid's frame is inside one of its surface prims.
    pub fn contains(&self, x: V3<T>) -> bool {
        self.prims.iter().any(|p| p.contains(x))
    }

    /// Whether the point `x` of the solid's frame lies within `band` of a CSG prim's
    /// surface, by the prim's signed distance bound (meshes have none: never near).
    pub fn near_surface(&self, x: V3<T>, band: T) -> bool {
        self.prims
            .iter()
            .any(|p| matches!(p, PreparedPrim::Csg(tree) if tree.sdf(x).abs() <= band))
    }

    /// Calls `visit(cluster, t0, t1)` for every cluster whose box the ray (solid frame)
    /// meets within `[tmin, tmax]`, `[t0, t1]` the part inside the box.
    pub fn visit_clusters(
        &self,
        ray: &Ray<T>,
        tmin: T,
        tmax: T,
        mut visit: impl FnMut(&Cluster<T>, T, T),
    ) {
        let mut one = |c: &Cluster<T>| {
            if let Some((t0, t1)) = ray_bounds_span(ray, &c.bounds, tmin, tmax) {
                visit(c, t0, t1);
            }
        };
        match &self.bvh {
            None => self.clusters.iter().for_each(&mut one),
            Some(bvh) => bvh.visit_ray(ray, &RaySlabs::new(ray), tmin, tmax, |id| {
                if let Some(c) = (id as usize)
                    .checked_sub(self.prims.len())
                    .and_then(|k| self.clusters.get(k))
                {
                    one(c);
                }
                tmax
            }),
        }
    }
}
