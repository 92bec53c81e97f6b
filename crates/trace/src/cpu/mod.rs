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
//! bounding volume hierarchy (module `bvh`); it returns exactly what the linear loop over the
//! group did, ties included. So do a solid's leaves when they are many: its surface prims
//! and the clusters of its volume bricks (module `solid`), two levels in all (instances, then
//! each solid's leaves), so repeated solids cost one structure.
//!
//! Rays come in f64 and stay exact until they are taken into an instance's frame: in f32
//! each origin is carried as two f32s (its rounding and the rest), placements' translations
//! likewise, and their difference is formed part by part (large parts cancel exactly when
//! the ray starts near the solid); a ray starting beyond the solid's reach is then moved
//! along itself to its closest approach to the centre of the solid's box
//! (`Placement::rebase`). The solid is solved in coordinates of its own size, so an f32
//! answer's error is set by the solid's scale, not by how far the solid or the ray's origin
//! lies from the world origin. The arithmetic is plain f32, operation by operation that of
//! the GPU kernel (`shaders/trace/scene.wgsl`), which makes the same steps. The searches
//! over instance boxes use the rounded origin; those boxes are padded (`widened_bounds`).
//!
//! [`CpuScene::trace_batch`] answers many rays as [`CpuScene::trace`] does, bit for bit, with
//! the searches of large meshes interleaved across the rays (module `batch`); `hytrace scan`
//! traces through it.
//!
//! Volume prims are media, not surfaces: [`CpuScene::trace`] and [`CpuScene::occluded`] go
//! through them, and [`media::SceneMedia`] adds the transmittance of the media along a ray
//! up to its first surface crossing, finding them through a BVH over the instances that hold
//! media and each solid's brick clusters.

use crate::error::Context;
use hytrace_csg::kernel::Frame;
use hytrace_csg::{transform_bounds, Bounds, PreparedPrim, Ray, Real, SlabRay, V3};
use hytrace_foundry::{Foundry, TypeCode, UNSET};

mod batch;
mod bvh;
pub mod gpu_export;
pub mod media;
#[cfg(feature = "embree")]
mod parts;
pub(crate) mod solid;
#[cfg(test)]
mod tests;

pub use crate::gpu::records::{STATUS_DROPPED_SPAN, STATUS_START_BAND, STATUS_START_NEAR};
use batch::{Crossings, Direct, Noting};
pub use batch::{TraceScratch, INTERLEAVE_MIN_BYTES};
use bvh::{holds, holds_within, BoxBvh, RaySlabs};

/// Deepest box BVH (instances, a solid's leaves) a scene may have: the traversal stacks'
/// size, on the CPU and in the GPU kernels.
pub const BOX_BVH_MAX_DEPTH: usize = bvh::MAX_DEPTH;
use solid::{PrimCrossing, SolidAccel};

/// Rays `hytrace scan` hands [`CpuScene::trace_batch`] at a time: enough to keep its
/// interleaved searches (8 at a time) busy, few enough that rayon's threads share the
/// work evenly.
pub const BATCH: usize = 256;

/// Groups of more instances than this are searched through a BVH.
pub const BVH_MIN_MEMBERS: usize = 8;

thread_local! {
    /// Working space of the searches that locate points (the candidates of a group's BVH),
    /// kept by each thread across calls: a photon locates a point at most crossings, and
    /// a fresh list allocated and freed each time (measured: 6% of a photon run among
    /// many daughters).
    static LOCATE_SCRATCH: std::cell::RefCell<Vec<u32>> = const { std::cell::RefCell::new(Vec::new()) };
}

/// One placement of a solid.
#[derive(Clone, Debug)]
struct Placement<T> {
    frame: Frame<T>,
    /// The rest of the frame's origin (its translation) after rounding to `T`.
    origin_lo: V3<T>,
    /// The centre of the solid's box in its own frame, where local rays are rebased to.
    centre: V3<T>,
    /// Twice the largest coordinate of the solid's box in its own frame: rays starting
    /// farther out are rebased.
    reach: T,
    /// Whether `frame` is axis-aligned ([`Frame::is_axis_aligned`]): `bounds` are then as
    /// tight as the solid's own box.
    aligned: bool,
    /// Whether `frame` keeps distances ([`Frame::is_rigid`]).
    rigid: bool,
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

/// A ray's answer and what its trace could not decide ([`CpuScene::trace_flagged`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Traced<T> {
    /// The first crossing, as [`CpuScene::trace`] answers it.
    pub hit: Option<Hit<T>>,
    /// [`STATUS_START_NEAR`], [`STATUS_START_BAND`] and [`STATUS_DROPPED_SPAN`] bits (the
    /// GPU scan kernel reports the same bits in its hit records).
    pub flags: u32,
}

/// Instances searched together, in placement order (which is also increasing instance
/// index), with a BVH over them when they are many.
#[derive(Clone, Debug)]
struct Group<T> {
    members: Vec<u32>,
    bvh: Option<Box<BoxBvh<T>>>,
    /// The largest extent of a member's world bounds (0 for no members): the scale of the
    /// widest tolerance band around the members.
    largest: T,
}

/// A world point carried in precision `T` as two parts: `hi`, the point rounded, and
/// `lo`, the rest rounded (zero in f64, where `hi` is exact). Their sum holds 48 bits of
/// an f64 coordinate in f32.
#[derive(Clone, Copy, Debug)]
struct WorldPoint<T> {
    hi: V3<T>,
    lo: V3<T>,
}

impl<T: Real> WorldPoint<T> {
    fn new(x: V3<f64>) -> Self {
        let hi = V3::<T>::from_f64(x.to_f64());
        let rest = x - V3::from_f64(hi.to_f64());
        WorldPoint {
            hi,
            lo: V3::from_f64(rest.to_f64()),
        }
    }
}

/// A world-frame ray as the tracer takes it: its origin in two parts, for the rebasing into
/// each instance's frame, and `rounded` (the origin's `hi` part and the direction) for the
/// searches over instance boxes.
#[derive(Clone, Copy, Debug)]
struct WorldRay<T> {
    origin: WorldPoint<T>,
    rounded: Ray<T>,
}

impl<T: Real> WorldRay<T> {
    fn new(ray: &Ray<f64>) -> Self {
        let origin = WorldPoint::new(ray.origin);
        WorldRay {
            origin,
            rounded: Ray {
                origin: origin.hi,
                direction: V3::from_f64(ray.direction.to_f64()),
            },
        }
    }
}

/// A world ray in an instance's frame, rebased: its origin is its point of closest
/// approach to the centre of the solid's box, so the solid is solved with coordinates of
/// its own size.
#[derive(Clone, Copy, Debug)]
struct LocalRay<T> {
    ray: Ray<T>,
    /// The world ray's parameter at the local ray's origin: `t_world = shift + t_local`.
    shift: T,
}

impl<T: Real> LocalRay<T> {
    /// A world parameter as a parameter of the local ray.
    #[inline]
    fn local_t(&self, t: T) -> T {
        t - self.shift
    }

    /// A local parameter at or past every local one whose world parameter is below `limit`
    /// (four epsilons past its rounded difference): the solid is searched up to it, and
    /// [`Self::world_hit`] decides on the world parameter.
    #[inline]
    fn past_local(&self, limit: T) -> T {
        let past = limit - self.shift;
        past + T::from_f64(4.0) * T::EPSILON * past.abs()
    }

    /// Crossing `c` of instance `index`, found on this ray up to `past_local(limit)`, as a
    /// hit at its world parameter; `None` unless that is below `limit`, so ties between
    /// instances are decided on world parameters, as the searches' tie rules expect.
    #[inline]
    fn world_hit(&self, c: PrimCrossing<T>, index: u32, limit: T) -> Option<Hit<T>> {
        let mut hit = c.hit(index);
        hit.t = self.shift + hit.t;
        (hit.t < limit).then_some(hit)
    }
}

impl<T: Real> Placement<T> {
    /// `ray` in the placed solid's frame, rebased ([`Self::rebase`]); `None` when `cull`
    /// (the rounded ray's slab-test form) is given and the ray misses the placement's world
    /// box within `[tmin, limit]`.
    #[inline]
    fn local_ray(
        &self,
        ray: &WorldRay<T>,
        cull: Option<&SlabRay<T>>,
        tmin: T,
        limit: T,
    ) -> Option<LocalRay<T>> {
        if let Some(slabs) = cull {
            // A superset of the exact test's boxes: culling only, the solid decides.
            slabs.entry_conservative(&ray.rounded, &self.bounds, tmin, limit)?;
        }
        Some(self.rebase(ray))
    }

    /// The world ray `ray` in the solid's frame. The origin's offset from the placement's
    /// translation is formed part by part ([`Self::offset_of`]): when the ray starts near
    /// the solid the large parts cancel exactly, and the offset errs by the solid's size
    /// times `T`'s epsilon however far both lie from the world origin. A ray starting
    /// beyond the solid's reach is moved along itself to its closest approach to the
    /// solid's centre, so the solid is solved with coordinates of its own size; `shift`
    /// carries parameters between the two rays. Nearer rays are not moved: the move's own
    /// roundings would cost them more than it saves (measured: 12% on the median error of
    /// the mixed scene's rays).
    #[inline]
    fn rebase(&self, ray: &WorldRay<T>) -> LocalRay<T> {
        let offset = self.offset_of(&ray.origin);
        let d = self.frame.linear(ray.rounded.direction);
        let beyond = offset.x.abs().max(offset.y.abs()).max(offset.z.abs()) > self.reach;
        let shift = if beyond {
            (self.centre - offset).dot(d) / d.length_squared()
        } else {
            T::ZERO
        };
        let shift = if shift.is_finite() { shift } else { T::ZERO };
        LocalRay {
            ray: Ray {
                origin: offset.at(d, shift),
                direction: d,
            },
            shift,
        }
    }

    /// The world point `x` in the solid's frame: `(hi - origin) + (lo - origin_lo)`, then
    /// the frame's linear part.
    #[inline]
    fn offset_of(&self, x: &WorldPoint<T>) -> V3<T> {
        let hi = x.hi - self.frame.origin();
        let lo = x.lo - self.origin_lo;
        self.frame.linear(hi + lo)
    }
}

impl<T: Real> Group<T> {
    fn new(members: Vec<u32>, placements: &[Placement<T>]) -> crate::Result<Self> {
        let bvh = if members.len() > BVH_MIN_MEMBERS {
            let boxed: Vec<_> = members
                .iter()
                .map(|&i| (i, placements[i as usize].bounds))
                .collect();
            Some(Box::new(BoxBvh::new(&boxed)?))
        } else {
            None
        };
        let largest = members
            .iter()
            .map(|&i| extent(&placements[i as usize].bounds))
            .fold(T::ZERO, T::max);
        Ok(Group {
            members,
            bvh,
            largest,
        })
    }

    /// Calls `visit` with every member whose bounds, widened by `margin`, may hold `x`.
    fn visit_near(
        &self,
        placements: &[Placement<T>],
        x: V3<T>,
        margin: T,
        mut visit: impl FnMut(u32),
    ) {
        match &self.bvh {
            Some(bvh) => bvh.visit_near(x, margin, visit),
            None => self
                .members
                .iter()
                .filter(|&&i| holds_within(&placements[i as usize].bounds, x, margin))
                .for_each(|&i| visit(i)),
        }
    }
}

/// The largest side of a box.
fn extent<T: Real>(b: &Bounds<T>) -> T {
    (b[1].x - b[0].x).max(b[1].y - b[0].y).max(b[1].z - b[0].z)
}

/// A band about a query's start `tmin` in which the tracer's surface tolerance decides, for
/// solids of size up to `size` (their largest world extent): four times the tolerance of
/// crossings there (the solids' own scale is at most this size, their frames' at most
/// twice it), so a crossing the tolerance skipped at the start lies inside.
fn band<T: Real>(size: T, tmin: T) -> T {
    T::from_f64(8.0) * T::SURFACE_TOLERANCE * (size + tmin.abs())
}

/// The instance a ray's origin is located in (none in a flat scene, or outside a
/// hierarchy's roots) and the group searched from there.
type StartGroup<'a, T> = (Option<u32>, &'a Group<T>);

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
    pub fn new(f: &Foundry) -> crate::Result<Self> {
        let solids = (0..f.solid.len())
            .map(|i| {
                SolidAccel::new(f, i).with_context(|| {
                    format!("solid {i} `{}`", f.solid_names.get(i).map_or("", |n| n))
                })
            })
            .collect::<crate::Result<Vec<_>>>()?;
        let mut placements = Vec::with_capacity(f.inst.len());
        for (i, (inst, tran)) in f.inst.iter().zip(&f.inst_tran).enumerate() {
            let tran = &tran.to_transform();
            let frame: Frame<T> = Frame::from_transform(tran)
                .with_context(|| format!("instance {i}: singular transform"))?;
            let translation = [0, 1, 2].map(|k| tran.rows[k][3]);
            let origin_lo: [f64; 3] =
                std::array::from_fn(|k| translation[k] - frame.origin().get(k).to_f64());
            let aabb = &f.solid[inst.solid as usize].aabb;
            let centre: [f64; 3] =
                std::array::from_fn(|k| 0.5 * (f64::from(aabb[k]) + f64::from(aabb[k + 3])));
            let reach = 2.0 * aabb.iter().fold(0.0f64, |m, &c| m.max(f64::from(c).abs()));
            placements.push(Placement {
                aligned: frame.is_axis_aligned(),
                rigid: frame.is_rigid(),
                frame,
                origin_lo: V3::from_f64(origin_lo),
                centre: V3::from_f64(centre),
                reach: T::from_f64(reach),
                solid: inst.solid as usize,
                bounds: world_bounds(aabb, tran),
            });
        }
        let layout = if f.is_hierarchical() {
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
                    .collect::<crate::Result<_>>()?,
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
        ray: &WorldRay<T>,
        cull: Option<&SlabRay<T>>,
        tmin: T,
        limit: T,
        crossings: &mut impl Crossings<'a, T>,
    ) -> Option<Hit<T>> {
        let p = &self.placements[index];
        let local = p.local_ray(ray, cull, tmin, limit)?;
        let (tmin_local, limit_local) = (local.local_t(tmin), local.past_local(limit));
        self.solids[p.solid]
            .cross(
                &local.ray,
                tmin_local,
                limit_local,
                local.shift,
                p.aligned,
                crossings,
            )
            .and_then(|c| local.world_hit(c, index as u32, limit))
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
        ray: &WorldRay<T>,
        tmin: T,
        tmax: T,
        seed: Option<Hit<T>>,
        crossings: &mut impl Crossings<'a, T>,
    ) -> Option<Hit<T>> {
        let Some(bvh) = &group.bvh else {
            let slabs = SlabRay::new(&ray.rounded);
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
        let slabs = RaySlabs::new(&ray.rounded);
        let mut best = seed;
        let mut seeded = seed.is_some();
        bvh.visit_ray(
            &ray.rounded,
            &slabs,
            tmin,
            best.map_or(tmax, |b| b.t),
            |i| {
                let limit = match best {
                    None => tmax,
                    // Visited out of order: an earlier member wins a tie with a later one.
                    Some(b) if !seeded && i < b.instance => b.t.next_up(),
                    Some(b) => b.t,
                };
                if let Some(h) = self.cross_instance(i as usize, ray, None, tmin, limit, crossings)
                {
                    best = Some(h);
                    seeded = false;
                }
                if crossings.abandoned() {
                    return -T::INFINITY;
                }
                best.map_or(tmax, |b| b.t)
            },
        );
        best
    }

    /// The last-placed member of `group` containing the world point `x` (`scratch` is
    /// working space).
    fn locate(&self, group: &Group<T>, x: &WorldPoint<T>, scratch: &mut Vec<u32>) -> Option<u32> {
        let Some(bvh) = &group.bvh else {
            return group
                .members
                .iter()
                .rev()
                .copied()
                .find(|&c| self.contains(c, x));
        };
        scratch.clear();
        // The boxes are padded by more than the rounding of a point inside them.
        bvh.candidates_near(x.hi, T::ZERO, scratch);
        scratch.sort_unstable_by(|a, b| b.cmp(a));
        scratch.iter().copied().find(|&c| self.contains(c, x))
    }

    /// Whether instance `index`'s solid contains the world point `x` (taken into the
    /// solid's frame as ray origins are, [`Placement::offset_of`]).
    fn contains(&self, index: u32, x: &WorldPoint<T>) -> bool {
        let p = &self.placements[index as usize];
        if !holds(&p.bounds, x.hi) {
            return false;
        }
        self.solids[p.solid].contains(p.offset_of(x))
    }

    /// Geant4's navigator step: locate the origin, then the nearer of leaving the located
    /// instance and entering one of its daughters.
    fn navigate<'a>(
        &'a self,
        h: &Hierarchy<T>,
        ray: &WorldRay<T>,
        tmin: T,
        tmax: T,
        crossings: &mut impl Crossings<'a, T>,
    ) -> Option<Hit<T>> {
        let current = crossings.located(|| self.locate_deepest(h, &ray.origin));
        self.step_from(h, current, ray, tmin, tmax, crossings)
    }

    /// The navigator's step from instance `current` (`None`: outside the world): the nearer
    /// of leaving it and entering one of its daughters.
    fn step_from<'a>(
        &'a self,
        h: &Hierarchy<T>,
        current: Option<u32>,
        ray: &WorldRay<T>,
        tmin: T,
        tmax: T,
        crossings: &mut impl Crossings<'a, T>,
    ) -> Option<Hit<T>> {
        let group = current.map_or(&h.roots, |c| &h.daughters[c as usize]);
        let exit = current.and_then(|c| self.exit(c as usize, ray, tmin, tmax, crossings));
        if crossings.abandoned() {
            return None;
        }
        self.enter(group, ray, tmin, tmax, exit, crossings)
    }

    /// The deepest instance containing `x` as the navigator locates it (daughters tried
    /// last-placed first); `None` outside every root.
    fn locate_deepest(&self, h: &Hierarchy<T>, x: &WorldPoint<T>) -> Option<u32> {
        LOCATE_SCRATCH.with_borrow_mut(|scratch| {
            let (mut current, mut group) = (None, &h.roots);
            while let Some(c) = self.locate(group, x, scratch) {
                current = Some(c);
                group = &h.daughters[c as usize];
            }
            current
        })
    }

    /// Where the ray leaves the instance its origin was located in. An origin within the
    /// surface tolerance of that instance's surface, moving out, has its exit suppressed as
    /// the surface it starts on; the navigator's answer is then that surface, found again
    /// with the start moved back by the tolerance band.
    fn exit<'a>(
        &'a self,
        index: usize,
        ray: &WorldRay<T>,
        tmin: T,
        tmax: T,
        crossings: &mut impl Crossings<'a, T>,
    ) -> Option<Hit<T>> {
        let slabs = SlabRay::new(&ray.rounded);
        self.cross_instance(index, ray, Some(&slabs), tmin, tmax, crossings)
            .or_else(|| {
                if crossings.abandoned() {
                    return None;
                }
                // The solid's tolerance where the ray starts: its size plus the start's
                // distance from the rebased origin, which its distance from the box's
                // centre bounds (the GPU kernel's `PHASE_EXIT_BAND`, operation by operation).
                let [lo, hi] = &self.placements[index].bounds;
                let size = (hi.x - lo.x).max(hi.y - lo.y).max(hi.z - lo.z);
                let o = ray.rounded.origin;
                let half = T::HALF;
                let far = (o.x - half * (lo.x + hi.x)).abs().max(
                    (o.y - half * (lo.y + hi.y))
                        .abs()
                        .max((o.z - half * (lo.z + hi.z)).abs()),
                );
                let band = T::from_f64(4.0) * T::SURFACE_TOLERANCE * (size + far);
                self.cross_instance(index, ray, Some(&slabs), tmin - band, tmax, crossings)
                    .map(|h| Hit {
                        t: h.t.max(tmin),
                        ..h
                    })
            })
    }

    /// The first surface crossing with `tmin < t < tmax` of a ray with a unit direction,
    /// wherever it starts (inside or outside any solid). The ray is given in f64 in either
    /// precision: it is rounded to `T` only in each instance's frame, after rebasing (see
    /// the module doc).
    pub fn trace(&self, ray: &Ray<f64>, tmin: T, tmax: T) -> Option<Hit<T>> {
        self.trace_with(&WorldRay::new(ray), tmin, tmax, &mut Direct)
    }

    /// [`Self::trace`], and what the trace could not decide within its rounding: the
    /// checks of the f32 scan's fallback to f64, made from the trace's own location of the
    /// origin (see [`Traced::flags`]). The GPU scan kernel reports the same flags.
    pub fn trace_flagged(&self, ray: &Ray<f64>, tmin: T, tmax: T) -> Traced<T> {
        let world = WorldRay::new(ray);
        let mut noting = Noting::default();
        let hit = self.trace_with(&world, tmin, tmax, &mut noting);
        Traced {
            hit,
            flags: self.flags_of(&world, tmin, noting.located, noting.dropped, hit.as_ref()),
        }
    }

    /// The flags of a trace of `ray` from `tmin` that answered `hit`: [`STATUS_DROPPED_SPAN`]
    /// when a decision within rounding was noted at a world parameter `dropped` not beyond
    /// the answer (a prim skipped a short span, or a mesh decided a triangle within
    /// rounding: see [`Crossings::note_dropped`]; one beyond the answer changes nothing,
    /// and whether it was seen depends on the order instances were searched in), and the
    /// start's flags ([`Self::start_flags`]) from the instance the trace located the origin
    /// in (`located`; a hierarchical scene's trace always locates it, a flat one's never).
    fn flags_of(
        &self,
        ray: &WorldRay<T>,
        tmin: T,
        located: Option<Option<u32>>,
        dropped: T,
        hit: Option<&Hit<T>>,
    ) -> u32 {
        let group = match &self.layout {
            Layout::Tree(h) => {
                let current = located.unwrap_or_else(|| self.locate_deepest(h, &ray.origin));
                (
                    current,
                    current.map_or(&h.roots, |c| &h.daughters[c as usize]),
                )
            }
            Layout::Flat(all) => (None, all),
        };
        let answer = hit.map_or(T::INFINITY, |h| h.t);
        let dropped = if dropped < T::INFINITY && dropped <= answer {
            STATUS_DROPPED_SPAN
        } else {
            0
        };
        dropped | self.start_flags(ray, tmin, group)
    }

    /// Whether the ray starts (at `tmin`) within the tracer's tolerance band of a surface
    /// among the instances the trace asks about there (`current`, the instance the origin
    /// is located in, and the members of `group`, its daughters or a flat scene's
    /// instances): [`STATUS_START_NEAR`] when the start lies within the band of a CSG
    /// surface by the signed distance, [`STATUS_START_BAND`] when it lies within the band
    /// of the box of a solid whose signed distance does not decide (meshes, frames that
    /// scale distances), whose band only a search decides
    /// ([`Self::starts_near_surface`]). The start is computed in `T` from the rounded
    /// origin, and the boxes are widened by its rounding, so that every instance
    /// [`Self::starts_near_surface`] asks about is asked about here.
    fn start_flags(&self, ray: &WorldRay<T>, tmin: T, (current, group): StartGroup<'_, T>) -> u32 {
        let start = ray.rounded.origin.at(ray.rounded.direction, tmin);
        let pad = T::from_f64(4.0) * T::EPSILON * (start.max_abs() + tmin.abs());
        let mut flags = current.map_or(0, |c| self.start_flag(c, ray, start, tmin, pad));
        let margin = band(group.largest, tmin) + pad;
        group.visit_near(&self.placements, start, margin, |i| {
            flags |= self.start_flag(i, ray, start, tmin, pad);
        });
        flags
    }

    /// Instance `index`'s part of [`Self::start_flags`]: none unless its box, widened by
    /// the band and `pad`, holds `start`; then [`STATUS_START_NEAR`] when the ray's start
    /// (at `tmin`, in the solid's frame as the trace takes it) lies within the band of a
    /// CSG surface by the signed distance, else [`STATUS_START_BAND`] when that distance
    /// does not decide.
    fn start_flag(&self, index: u32, ray: &WorldRay<T>, start: V3<T>, tmin: T, pad: T) -> u32 {
        let p = &self.placements[index as usize];
        let b = band(extent(&p.bounds), tmin);
        if !holds_within(&p.bounds, start, b + pad) {
            return 0;
        }
        let local = p.rebase(ray);
        let x = local
            .ray
            .origin
            .at(local.ray.direction, local.local_t(tmin));
        let solid = &self.solids[p.solid];
        if solid.near_surface(x, b) {
            STATUS_START_NEAR
        } else if solid.sdf_decides && p.rigid {
            0
        } else {
            STATUS_START_BAND
        }
    }

    /// Geant4's navigator step from a volume the caller already knows, as a tracking
    /// navigator keeps it between steps: in a hierarchical scene, the nearer of leaving
    /// instance `current` (the roots' surfaces when `None`: outside the world) and entering
    /// one of its daughters, the origin not located again (so a photon on a surface it has
    /// just crossed stays on the side it was put). In a flat scene, [`Self::trace`].
    pub fn trace_in(
        &self,
        ray: &Ray<f64>,
        current: Option<u32>,
        tmin: T,
        tmax: T,
    ) -> Option<Hit<T>> {
        let world = WorldRay::new(ray);
        let best = match &self.layout {
            Layout::Tree(h) => self.step_from(h, current, &world, tmin, tmax, &mut Direct),
            Layout::Flat(all) => self.enter(all, &world, tmin, tmax, None, &mut Direct),
        };
        best.map(|h| self.in_world(h))
    }

    /// [`Self::trace`], prims' first crossings coming from `crossings`; meaningless when
    /// `crossings` abandons the trace.
    // Inlined so that the hit is built where the caller keeps it: returned through memory,
    // the caller's copy read it back in wider pieces than it had been written in, a
    // store-forwarding stall on every ray (measured: 2-3% of a batch's time).
    #[inline(always)]
    fn trace_with<'a>(
        &'a self,
        ray: &WorldRay<T>,
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
    pub fn occluded(&self, ray: &Ray<f64>, tmin: T, tmax: T) -> bool {
        let all = match &self.layout {
            Layout::Tree(_) => return self.trace(ray, tmin, tmax).is_some(),
            Layout::Flat(all) => all,
        };
        let world = WorldRay::new(ray);
        let Some(bvh) = &all.bvh else {
            let slabs = SlabRay::new(&world.rounded);
            return all.members.iter().any(|&i| {
                self.cross_instance(i as usize, &world, Some(&slabs), tmin, tmax, &mut Direct)
                    .is_some()
            });
        };
        let slabs = RaySlabs::new(&world.rounded);
        let mut found = false;
        bvh.visit_ray(&world.rounded, &slabs, tmin, tmax, |i| {
            found = self
                .cross_instance(i as usize, &world, None, tmin, tmax, &mut Direct)
                .is_some();
            if found {
                -T::INFINITY
            } else {
                tmax
            }
        });
        found
    }

    /// Whether the ray starts (at `tmin`) so near a surface that the tracer's surface
    /// tolerance decides about it: a crossing there may have been taken for the surface the
    /// ray starts on, and which side of it the start lies on is within rounding (in f32,
    /// scans trace such rays again in f64). The instances the trace asks about where the
    /// ray starts (in a hierarchical scene the one its origin is located in and that one's
    /// daughters, in a flat scene all) whose boxes hold the start are asked whether the
    /// start lies within a band of eight tolerances (of their size and `tmin`) of a CSG
    /// surface by the signed distance (which catches rays along a surface they start on);
    /// solids with meshes, or in frames that scale distances, are also searched, as the
    /// trace searches them, for a crossing within that band about `tmin`. `candidates` is
    /// working space, kept by the caller across rays.
    pub fn starts_near_surface(&self, ray: &Ray<f64>, tmin: T, candidates: &mut Vec<u32>) -> bool {
        let world = WorldRay::new(ray);
        let start = WorldPoint::<T>::new(ray.origin.at(ray.direction, tmin.to_f64())).hi;
        candidates.clear();
        let group = match &self.layout {
            Layout::Tree(h) => {
                let current = self.locate_deepest(h, &world.origin);
                candidates.extend(current);
                current.map_or(&h.roots, |c| &h.daughters[c as usize])
            }
            Layout::Flat(all) => all,
        };
        group.visit_near(&self.placements, start, band(group.largest, tmin), |i| {
            candidates.push(i)
        });
        candidates.iter().any(
            |&i| match self.start_flag(i, &world, start, tmin, T::ZERO) {
                STATUS_START_NEAR => true,
                // The signed distance says "not near" for certain only when it measures
                // true distances, in a placement that keeps them: otherwise the band is
                // searched.
                STATUS_START_BAND => {
                    let b = band(extent(&self.placements[i as usize].bounds), tmin);
                    self.cross_instance(i as usize, &world, None, tmin - b, tmin + b, &mut Direct)
                        .is_some()
                }
                _ => false,
            },
        )
    }

    /// Whether instance `instance`'s solid has a torus among its CSG primitives (whose f32
    /// roots, of a quartic, are the least certain; see `scan`).
    pub fn has_torus(&self, instance: u32) -> bool {
        let p = &self.placements[instance as usize];
        self.solids[p.solid].prims.iter().any(
            |prim| matches!(prim, PreparedPrim::Csg(tree) if tree.has_primitive(TypeCode::Torus)),
        )
    }

    /// How far the world point `x` lies from the surface of instance `instance`'s CSG
    /// prims: the least magnitude of their signed distance bounds there (a lower bound of
    /// the distance; infinite for a solid without CSG prims).
    pub fn surface_distance(&self, instance: u32, x: [f64; 3]) -> T {
        let p = &self.placements[instance as usize];
        let local = p.offset_of(&WorldPoint::new(V3::from_f64(x)));
        self.solids[p.solid]
            .prims
            .iter()
            .filter_map(|prim| match prim {
                PreparedPrim::Csg(tree) => Some(tree.sdf(local).abs()),
                PreparedPrim::Mesh(_) => None,
            })
            .fold(T::INFINITY, T::min)
    }

    /// The instance whose solid contains the world point `x` (taken into each solid's frame
    /// as ray origins are): in a hierarchical scene the deepest, as the navigator locates it
    /// (daughters tried last-placed first); in a flat scene the last placed. `None` outside
    /// every instance.
    pub fn locate_point(&self, x: [f64; 3]) -> Option<u32> {
        let x = WorldPoint::new(V3::from_f64(x));
        match &self.layout {
            Layout::Tree(h) => self.locate_deepest(h, &x),
            Layout::Flat(all) => {
                LOCATE_SCRATCH.with_borrow_mut(|scratch| self.locate(all, &x, scratch))
            }
        }
    }

    /// Number of placed solids.
    pub fn instances(&self) -> usize {
        self.placements.len()
    }

    /// World bounds (min, max) of the placed solids, `None` without any.
    pub fn world_bounds(&self) -> Option<[[f64; 3]; 2]> {
        self.bounds_of(|_| true)
    }

    /// World bounds (min, max) of instance `instance`.
    pub fn instance_bounds(&self, instance: usize) -> [[f64; 3]; 2] {
        let b = &self.placements[instance].bounds;
        [b[0].to_f64(), b[1].to_f64()]
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
