//! The CPU tracer: the first surface crossing of a ray among all placed CSG solids of a
//! Foundry, in f32 or f64.
//!
//! Every instance is tested by its world bounds, then its solid's CSG and mesh prims by
//! their bounds in the solid's frame, then the prims themselves (see
//! [`hytrace_csg::PreparedPrim`]). Volume prims are media, not surfaces. A bounding volume hierarchy over the
//! instances replaces the linear loop in the BVH issue; the answers do not change.

use anyhow::Context;
use hytrace_csg::kernel::Frame;
use hytrace_csg::{ray_meets_bounds, transform_bounds, Bounds, PreparedPrim, Ray, Real, V3};
use hytrace_foundry::Foundry;

/// One placement of a solid.
#[derive(Clone, Debug)]
struct Placement<T> {
    frame: Frame<T>,
    solid: usize,
    bounds: Bounds<T>,
}

/// A surface crossing found by the tracer.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit<T> {
    /// Distance along the ray.
    pub t: T,
    /// Unit outward normal (world frame) of the solid whose surface is crossed.
    pub normal: V3<T>,
    /// Index of the instance crossed.
    pub instance: u32,
}

/// A Foundry's CSG content prepared for tracing in precision `T`.
#[derive(Clone, Debug)]
pub struct CpuScene<T> {
    placements: Vec<Placement<T>>,
    solids: Vec<Vec<PreparedPrim<T>>>,
}

fn world_bounds<T: Real>(aabb: &[f32; 6], t: &hytrace_foundry::Transform64) -> Bounds<T> {
    let b = transform_bounds(&aabb.map(f64::from), t);
    // Widen by a relative hair so rounding to T never clips a surface.
    let pad = 1e-6 * b.iter().fold(1.0f64, |a, v| a.max(v.abs()));
    [
        V3::from_f64([b[0] - pad, b[1] - pad, b[2] - pad]),
        V3::from_f64([b[3] + pad, b[4] + pad, b[5] + pad]),
    ]
}

impl<T: Real> CpuScene<T> {
    /// Prepares every instance of a validated Foundry.
    pub fn new(f: &Foundry) -> anyhow::Result<Self> {
        let mut solids = Vec::with_capacity(f.solid.len());
        for (i, s) in f.solid.iter().enumerate() {
            let mut trees = Vec::new();
            for p in s.prim_offset as usize..(s.prim_offset + s.num_prim) as usize {
                let prepared = PreparedPrim::from_foundry(f, p).with_context(|| {
                    format!("solid {i} `{}`", f.solid_names.get(i).map_or("", |n| n))
                })?;
                trees.extend(prepared);
            }
            solids.push(trees);
        }
        let mut placements = Vec::with_capacity(f.inst.len());
        for (i, (inst, tran)) in f.inst.iter().zip(&f.inst_tran).enumerate() {
            let frame = Frame::from_transform(tran)
                .with_context(|| format!("instance {i}: singular transform"))?;
            let aabb = &f.solid[inst.solid as usize].aabb;
            placements.push(Placement {
                frame,
                solid: inst.solid as usize,
                bounds: world_bounds(aabb, tran),
            });
        }
        Ok(CpuScene { placements, solids })
    }

    /// The first surface crossing with `tmin < t < tmax` of a ray with a unit direction,
    /// wherever it starts (inside or outside any solid).
    pub fn trace(&self, ray: &Ray<T>, tmin: T, tmax: T) -> Option<Hit<T>> {
        let mut best: Option<Hit<T>> = None;
        for (index, p) in self.placements.iter().enumerate() {
            let limit = best.map_or(tmax, |b| b.t);
            if !ray_meets_bounds(ray, &p.bounds, tmin, limit) {
                continue;
            }
            let local = p.frame.ray_to_local(ray);
            for tree in &self.solids[p.solid] {
                let limit = best.map_or(tmax, |b| b.t);
                if !ray_meets_bounds(&local, tree.bounds(), tmin, limit) {
                    continue;
                }
                let step = tree.first_crossing(&local, tmin);
                if step.t < limit && step.t > tmin {
                    best = Some(Hit {
                        t: step.t,
                        normal: step.normal,
                        instance: index as u32,
                    });
                }
            }
        }
        best.map(|mut h| {
            let p = &self.placements[h.instance as usize];
            h.normal = p.frame.normal_to_parent(h.normal).normalized();
            h
        })
    }

    /// Number of placed solids.
    pub fn instances(&self) -> usize {
        self.placements.len()
    }
}
