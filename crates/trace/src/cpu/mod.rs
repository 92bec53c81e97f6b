//! The CPU tracer: the next boundary along a ray among the placed CSG and mesh solids of a
//! Foundry, in f32 or f64.
//!
//! A flat scene (no instance has a mother) answers the first surface crossing of any
//! instance. A hierarchical scene (GDML: every physical volume an instance with its
//! mother) answers as Geant4's navigator does: the ray's origin is located in the deepest
//! instance containing it (daughters tried last-placed first), and the answer is the
//! nearer of leaving that instance and entering one of its daughters. The two agree on
//! well-formed geometry; where a daughter protrudes from its mother, only the navigator
//! form reproduces Geant4.
//!
//! Every instance is tested by its world bounds, then its solid's CSG and mesh prims by
//! their bounds in the solid's frame, then the prims themselves (see
//! [`hytrace_csg::PreparedPrim`]). Groups of more than [`BVH_MIN_MEMBERS`] instances searched
//! together (a flat scene's instances, a hierarchy's roots, one mother's daughters) sit in a
//! bounding volume hierarchy ([`bvh`]); it returns exactly what the linear loop over the
//! group did, ties included. So do a solid's leaves when they are many: its surface prims
//! and the clusters of its volume bricks ([`solid`]), two levels in all (instances, then
//! each solid's leaves), so repeated solids cost one structure.
//!
//! [`CpuScene::trace_batch`] answers many rays as [`CpuScene::trace`] does, bit for bit, with
//! the searches of large meshes interleaved across the rays ([`batch`]); `hytrace scan`
//! traces through it.
//!
//! Volume prims are media, not surfaces: [`CpuScene::trace`] and [`CpuScene::occluded`] go
//! through them, and [`media::SceneMedia`] adds the transmittance of the media along a ray
//! up to its first surface crossing, finding them through a BVH over the instances that hold
//! media and each solid's brick clusters.

use anyhow::Context;
use hytrace_csg::kernel::Frame;
use hytrace_csg::{transform_bounds, Bounds, PreparedPrim, Ray, Real, SlabRay, V3};
use hytrace_foundry::{Foundry, UNSET};

mod batch;
mod bvh;
pub mod gpu_export;
pub mod media;
#[cfg(feature = "embree")]
mod parts;
pub(crate) mod solid;
#[cfg(test)]
mod tests;

use batch::{Crossings, Direct};
pub use batch::{TraceScratch, INTERLEAVE_MIN_BYTES};
use bvh::{holds, BoxBvh, RaySlabs};

/// Deepest box BVH (instances, a solid's leaves) a scene may have: the traversal stacks'
/// size, on the CPU and in the GPU kernels.
pub const BOX_BVH_MAX_DEPTH: usize = bvh::MAX_DEPTH;
use solid::SolidAccel;

/// Rays `hytrace scan` hands [`CpuScene::trace_batch`] at a time: enough to keep its
/// interleaved searches (8 at a time) busy, few enough that rayon's threads share the
/// work evenly.
pub const BATCH: usize = 256;

/// Groups of more instances than this are searched through a BVH.
pub const BVH_MIN_MEMBERS: usize = 8;

/// One placement of a solid.
#[derive(Clone, Debug)]
struct Placement<T> {
    frame: Frame<T>,
    /// Whether `frame` is axis-aligned ([`Frame::is_axis_aligned`]): `bounds` are then as
    /// tight as the solid's own box.
    aligned: bool,
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
    /// Index of the Foundry prim crossed (the solid's and boundary are the instance's).
    pub prim: u32,
}

/// Instances searched together, in placement order (which is also increasing instance
/// index), with a BVH over them when they are many.
#[derive(Clone, Debug)]
struct Group<T> {
    members: Vec<u32>,
    bvh: Option<Box<BoxBvh<T>>>,
}

impl<T: Real> Placement<T> {
    /// `ray` in the placed solid's frame; `None` when `cull` (the ray's slab-test form) is
    /// given and the ray misses the placement's world box within `[tmin, limit]`.
    #[inline]
    fn local_ray(
        &self,
        ray: &Ray<T>,
        cull: Option<&SlabRay<T>>,
        tmin: T,
        limit: T,
    ) -> Option<Ray<T>> {
        if let Some(slabs) = cull {
            // A superset of the exact test's boxes: culling only, the solid decides.
            slabs.entry_conservative(ray, &self.bounds, tmin, limit)?;
        }
        Some(self.frame.ray_to_local(ray))
    }
}

impl<T: Real> Group<T> {
    fn new(members: Vec<u32>, placements: &[Placement<T>]) -> anyhow::Result<Self> {
        let bvh = if members.len() > BVH_MIN_MEMBERS {
            let boxed: Vec<_> = members
                .iter()
                .map(|&i| (i, placements[i as usize].bounds))
                .collect();
            Some(Box::new(BoxBvh::new(&boxed).map_err(anyhow::Error::msg)?))
        } else {
            None
        };
        Ok(Group { members, bvh })
    }
}

/// The placement tree of a hierarchical scene.
#[derive(Clone, Debug)]
struct Hierarchy<T> {
    /// Instances without a mother (the world).
    roots: Group<T>,
    /// Daughters of each instance.
    daughters: Vec<Group<T>>,
}

/// How the instances are searched.
#[derive(Clone, Debug)]
enum Layout<T> {
    /// All instances at once, for the first crossing.
    Flat(Group<T>),
    /// As Geant4's navigator.
    Tree(Hierarchy<T>),
}

/// A Foundry's content prepared for tracing in precision `T`.
#[derive(Clone, Debug)]
pub struct CpuScene<T> {
    placements: Vec<Placement<T>>,
    solids: Vec<SolidAccel<T>>,
    layout: Layout<T>,
    /// The instances whose solids hold media.
    media: Group<T>,
    /// Bytes of the search structures of the largest mesh prim ([`batch`]: whether a
    /// batch may interleave any mesh searches).
    largest_mesh_bytes: usize,
}

fn world_bounds<T: Real>(aabb: &[f32; 6], t: &hytrace_foundry::Transform64) -> Bounds<T> {
    widened_bounds(&transform_bounds(&aabb.map(f64::from), t))
}

/// `b` in precision `T`, widened by a relative hair so rounding never clips a surface.
fn widened_bounds<T: Real>(b: &hytrace_csg::Aabb) -> Bounds<T> {
    let pad = 1e-6 * b.iter().fold(1.0f64, |a, v| a.max(v.abs()));
    [
        V3::from_f64([b[0] - pad, b[1] - pad, b[2] - pad]),
        V3::from_f64([b[3] + pad, b[4] + pad, b[5] + pad]),
    ]
}

impl<T: Real> CpuScene<T> {
    /// Prepares every instance of a validated Foundry.
    pub fn new(f: &Foundry) -> anyhow::Result<Self> {
        let solids = (0..f.solid.len())
            .map(|i| {
                SolidAccel::new(f, i).with_context(|| {
                    format!("solid {i} `{}`", f.solid_names.get(i).map_or("", |n| n))
                })
            })
            .collect::<anyhow::Result<Vec<_>>>()?;
        let mut placements = Vec::with_capacity(f.inst.len());
        for (i, (inst, tran)) in f.inst.iter().zip(&f.inst_tran).enumerate() {
            let tran = &tran.to_transform();
            let frame = Frame::from_transform(tran)
                .with_context(|| format!("instance {i}: singular transform"))?;
            let aabb = &f.solid[inst.solid as usize].aabb;
            placements.push(Placement {
                aligned: frame.is_axis_aligned(),
                frame,
                solid: inst.solid as usize,
                bounds: world_bounds(aabb, tran),
            });
        }
        let layout = if f.inst_mother.iter().any(|m| m.index != UNSET) {
            let mut roots = Vec::new();
            let mut daughters = vec![Vec::new(); f.inst.len()];
            for (i, m) in f.inst_mother.iter().enumerate() {
                match m.index {
                    UNSET => roots.push(i as u32),
                    mother => daughters[mother as usize].push(i as u32),
                }
            }
            Layout::Tree(Hierarchy {
                roots: Group::new(roots, &placements)?,
                daughters: daughters
                    .into_iter()
                    .map(|d| Group::new(d, &placements))
                    .collect::<anyhow::Result<_>>()?,
            })
        } else {
            // Instances of solids without surface prims (media only) have nothing to cross.
            let surfaced = (0..placements.len() as u32)
                .filter(|&i| !solids[placements[i as usize].solid].prims.is_empty())
                .collect();
            Layout::Flat(Group::new(surfaced, &placements)?)
        };
        let holding_media = (0..placements.len() as u32)
            .filter(|&i| !solids[placements[i as usize].solid].clusters.is_empty())
            .collect();
        let media = Group::new(holding_media, &placements)?;
        let largest_mesh_bytes = solids
            .iter()
            .flat_map(|s| &s.prims)
            .map(|p| match p {
                PreparedPrim::Mesh(m) => m.bvh_bytes(),
                PreparedPrim::Csg(_) => 0,
            })
            .max()
            .unwrap_or(0);
        Ok(CpuScene {
            placements,
            solids,
            layout,
            media,
            largest_mesh_bytes,
        })
    }

    /// The first crossing of instance `index`'s surface in `(tmin, limit)`. `cull`: the
    /// ray's slab-test form, to skip the instance when the ray misses its box; `None` when
    /// the caller's BVH walk found the ray meeting that box.
    /// Prims' first crossings come from `crossings` (see [`SolidAccel::cross`]).
    #[inline]
    fn cross_instance<'a>(
        &'a self,
        index: usize,
        ray: &Ray<T>,
        cull: Option<&SlabRay<T>>,
        tmin: T,
        limit: T,
        crossings: &mut impl Crossings<'a, T>,
    ) -> Option<Hit<T>> {
        let p = &self.placements[index];
        let local = p.local_ray(ray, cull, tmin, limit)?;
        self.solids[p.solid]
            .cross(&local, tmin, limit, p.aligned, crossings)
            .map(|c| c.hit(index as u32))
    }

    /// `hit`, found in its instance's frame, with its normal turned into the world frame
    /// and normalized.
    fn in_world(&self, mut hit: Hit<T>) -> Hit<T> {
        let p = &self.placements[hit.instance as usize];
        hit.normal = p.frame.normal_to_parent(hit.normal).normalized();
        hit
    }

    /// The instance and its mesh when the scene is one axis-aligned placement of a solid
    /// whose only surface prim is a mesh (an OBJ or glTF mesh traced alone): a trace then
    /// asks that mesh one query at most, and answers from it alone.
    fn lone_mesh(&self) -> Option<(usize, &hytrace_csg::MeshPrim<T>)> {
        let Layout::Flat(group) = &self.layout else {
            return None;
        };
        let [index] = group.members[..] else {
            return None;
        };
        let p = &self.placements[index as usize];
        match &self.solids[p.solid].prims[..] {
            [PreparedPrim::Mesh(mesh)] if p.aligned => Some((index as usize, mesh)),
            _ => None,
        }
    }

    /// The nearer of `seed` and the first crossing of a member of `group`: what folding
    /// [`Self::cross_instance`] over the members in placement order gives, that is the
    /// nearest crossing, ties going to `seed`, then to the lowest instance index. Stops
    /// early, its answer meaningless, when `crossings` abandons the trace.
    // Inlined into the trace, as `trace_with` is into its callers: the nearest hit then
    // reaches the caller without a round trip through memory.
    #[inline(always)]
    fn enter<'a>(
        &'a self,
        group: &Group<T>,
        ray: &Ray<T>,
        tmin: T,
        tmax: T,
        seed: Option<Hit<T>>,
        crossings: &mut impl Crossings<'a, T>,
    ) -> Option<Hit<T>> {
        let Some(bvh) = &group.bvh else {
            let slabs = SlabRay::new(ray);
            let mut best = seed;
            for &i in &group.members {
                let limit = best.map_or(tmax, |b| b.t);
                best = self
                    .cross_instance(i as usize, ray, Some(&slabs), tmin, limit, crossings)
                    .or(best);
                if crossings.abandoned() {
                    break;
                }
            }
            return best;
        };
        let slabs = RaySlabs::new(ray);
        let mut best = seed;
        let mut seeded = seed.is_some();
        bvh.visit_ray(ray, &slabs, tmin, best.map_or(tmax, |b| b.t), |i| {
            let limit = match best {
                None => tmax,
                // Visited out of order: an earlier member wins a tie with a later one.
                Some(b) if !seeded && i < b.instance => b.t.next_up(),
                Some(b) => b.t,
            };
            if let Some(h) = self.cross_instance(i as usize, ray, None, tmin, limit, crossings) {
                best = Some(h);
                seeded = false;
            }
            if crossings.abandoned() {
                return -T::INFINITY;
            }
            best.map_or(tmax, |b| b.t)
        });
        best
    }

    /// The last-placed member of `group` containing `x` (`scratch` is working space).
    fn locate(&self, group: &Group<T>, x: V3<T>, scratch: &mut Vec<u32>) -> Option<u32> {
        let Some(bvh) = &group.bvh else {
            return group
                .members
                .iter()
                .rev()
                .copied()
                .find(|&c| self.contains(c, x));
        };
        scratch.clear();
        bvh.candidates_at(x, scratch);
        scratch.sort_unstable_by(|a, b| b.cmp(a));
        scratch.iter().copied().find(|&c| self.contains(c, x))
    }

    /// Whether instance `index`'s solid contains the world point `x`.
    fn contains(&self, index: u32, x: V3<T>) -> bool {
        let p = &self.placements[index as usize];
        if !holds(&p.bounds, x) {
            return false;
        }
        self.solids[p.solid].contains(p.frame.point_to_local(x))
    }

    /// Geant4's navigator step: locate the origin, then the nearer of leaving the located
    /// instance and entering one of its daughters.
    fn navigate<'a>(
        &'a self,
        h: &Hierarchy<T>,
        ray: &Ray<T>,
        tmin: T,
        tmax: T,
        crossings: &mut impl Crossings<'a, T>,
    ) -> Option<Hit<T>> {
        let current = crossings.located(|| self.locate_deepest(h, ray.origin));
        let group = current.map_or(&h.roots, |c| &h.daughters[c as usize]);
        let exit = current.and_then(|c| self.exit(c as usize, ray, tmin, tmax, crossings));
        if crossings.abandoned() {
            return None;
        }
        self.enter(group, ray, tmin, tmax, exit, crossings)
    }

    /// The deepest instance containing `x` as the navigator locates it (daughters tried
    /// last-placed first); `None` outside every root.
    fn locate_deepest(&self, h: &Hierarchy<T>, x: V3<T>) -> Option<u32> {
        let (mut current, mut group, mut scratch) = (None, &h.roots, Vec::new());
        while let Some(c) = self.locate(group, x, &mut scratch) {
            current = Some(c);
            group = &h.daughters[c as usize];
        }
        current
    }

    /// Where the ray leaves the instance its origin was located in. An origin within the
    /// surface tolerance of that instance's surface, moving out, has its exit suppressed as
    /// the surface it starts on; the navigator's answer is then that surface, found again
    /// with the start moved back by the tolerance band.
    fn exit<'a>(
        &'a self,
        index: usize,
        ray: &Ray<T>,
        tmin: T,
        tmax: T,
        crossings: &mut impl Crossings<'a, T>,
    ) -> Option<Hit<T>> {
        let slabs = SlabRay::new(ray);
        self.cross_instance(index, ray, Some(&slabs), tmin, tmax, crossings)
            .or_else(|| {
                if crossings.abandoned() {
                    return None;
                }
                let [lo, hi] = &self.placements[index].bounds;
                let size = (hi.x - lo.x).max(hi.y - lo.y).max(hi.z - lo.z);
                let o = ray.origin;
                let scale = size + o.x.abs().max(o.y.abs()).max(o.z.abs());
                let band = T::from_f64(4.0) * T::SURFACE_TOLERANCE * scale;
                self.cross_instance(index, ray, Some(&slabs), tmin - band, tmax, crossings)
                    .map(|h| Hit {
                        t: h.t.max(tmin),
                        ..h
                    })
            })
    }

    /// The first surface crossing with `tmin < t < tmax` of a ray with a unit direction,
    /// wherever it starts (inside or outside any solid).
    pub fn trace(&self, ray: &Ray<T>, tmin: T, tmax: T) -> Option<Hit<T>> {
        self.trace_with(ray, tmin, tmax, &mut Direct)
    }

    /// [`Self::trace`], prims' first crossings coming from `crossings`; meaningless when
    /// `crossings` abandons the trace.
    // Inlined so that the hit is built where the caller keeps it: returned through memory,
    // the caller's copy read it back in wider pieces than it had been written in, a
    // store-forwarding stall on every ray (measured: 2-3% of a batch's time).
    #[inline(always)]
    fn trace_with<'a>(
        &'a self,
        ray: &Ray<T>,
        tmin: T,
        tmax: T,
        crossings: &mut impl Crossings<'a, T>,
    ) -> Option<Hit<T>> {
        let best = match &self.layout {
            Layout::Tree(h) => self.navigate(h, ray, tmin, tmax, crossings),
            Layout::Flat(all) => self.enter(all, ray, tmin, tmax, None, crossings),
        };
        best.map(|h| self.in_world(h))
    }

    /// Whether any surface crosses the ray with `tmin < t < tmax` (shadow rays): the
    /// search stops at the first crossing found. In a hierarchical scene every surface
    /// counts, the located volume's and its daughters' alike, so this is whether
    /// [`Self::trace`] finds a crossing.
    pub fn occluded(&self, ray: &Ray<T>, tmin: T, tmax: T) -> bool {
        let all = match &self.layout {
            Layout::Tree(_) => return self.trace(ray, tmin, tmax).is_some(),
            Layout::Flat(all) => all,
        };
        let Some(bvh) = &all.bvh else {
            let slabs = SlabRay::new(ray);
            return all.members.iter().any(|&i| {
                self.cross_instance(i as usize, ray, Some(&slabs), tmin, tmax, &mut Direct)
                    .is_some()
            });
        };
        let slabs = RaySlabs::new(ray);
        let mut found = false;
        bvh.visit_ray(ray, &slabs, tmin, tmax, |i| {
            found = self
                .cross_instance(i as usize, ray, None, tmin, tmax, &mut Direct)
                .is_some();
            if found {
                -T::INFINITY
            } else {
                tmax
            }
        });
        found
    }

    /// Number of placed solids.
    pub fn instances(&self) -> usize {
        self.placements.len()
    }

    /// World bounds (min, max) of the placed solids, `None` without any.
    pub fn world_bounds(&self) -> Option<[[f64; 3]; 2]> {
        self.bounds_of(|_| true)
    }

    /// World bounds (min, max) of the instances `keep` accepts, `None` without any.
    pub fn bounds_of(&self, keep: impl Fn(usize) -> bool) -> Option<[[f64; 3]; 2]> {
        let kept = self.placements.iter().enumerate().filter(|(i, _)| keep(*i));
        kept.fold(None, |acc, (_, p)| {
            let [lo, hi] = [p.bounds[0].to_f64(), p.bounds[1].to_f64()];
            Some(match acc {
                None => [lo, hi],
                Some([a, b]) => [
                    std::array::from_fn(|k| a[k].min(lo[k])),
                    std::array::from_fn(|k| b[k].max(hi[k])),
                ],
            })
        })
    }
}
