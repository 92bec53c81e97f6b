//! CSG prims and volume-brick clusters as Embree user geometry: per solid, one user
//! geometry with a user primitive per CSG prim, intersected by
//! [`PreparedPrim::first_crossing`] as the CPU tracer does, and one with a user primitive
//! per brick cluster, whose callback lists the clusters a ray crosses (the media's part of
//! a transmittance query).
//!
//! Embree hands the intersect callback the ray already moved into the instance's frame in
//! f32 by its own inverse. The callback instead re-derives the local ray from the world ray
//! with the instance's [`Frame`](hytrace_csg::kernel::Frame) (origin subtracted first),
//! exactly as the CPU tracer does, so CSG answers match it bit for bit and keep f32
//! precision far from the world origin. The world ray travels in [`TraceContext`], which
//! starts with the `RTCIntersectContext` Embree passes back to callbacks.
//!
//! The backend only calls `rtcIntersect1` and `rtcOccluded1`, so every callback sees
//! `N == 1`: one ray in the structure-of-arrays `RTCRayHitN` (or `RTCRayN`), whose layout
//! for `N == 1` is [`ffi::RTCRayHit`]'s (or [`ffi::RTCRay`]'s) fields in order (checked by
//! the layout test). Callbacks never unwind into Embree: a
//! panic is caught and flagged in the context, and the trace reports it as an error.

use std::cell::{Cell, RefCell};
use std::ffi::c_void;
use std::panic::{catch_unwind, AssertUnwindSafe};

use crate::error::bail;
use hytrace_csg::{ray_bounds_span, PreparedPrim, Ray, V3};
use hytrace_foundry::{Foundry, PrimKind};

use super::ffi;
use super::handle::{Device, Geometry};
use crate::cpu::solid::Cluster;
use crate::cpu::CpuScene;

/// The CSG prims of one solid, with their Foundry indices: the user data of its user
/// geometry.
pub(crate) struct CsgPrims<'a> {
    prims: Vec<(u32, &'a PreparedPrim<f32>)>,
}

impl<'a> CsgPrims<'a> {
    /// The CSG prims among solid `solid`'s surface prims `prims` (in Foundry order, as
    /// [`CpuScene`] holds them); meshes go to Embree as triangles.
    pub(crate) fn new(
        foundry: &Foundry,
        solid: usize,
        prims: &'a [PreparedPrim<f32>],
    ) -> crate::Result<Self> {
        let s = &foundry.solid[solid];
        let surfaces: Vec<u32> = (s.prim_offset..s.prim_offset + s.num_prim)
            .filter(|&p| {
                let kind = foundry.prim[p as usize].kind;
                kind == PrimKind::Csg as u32 || kind == PrimKind::Mesh as u32
            })
            .collect();
        if surfaces.len() != prims.len() {
            bail!(
                "the Foundry has {} surface prims, the CPU scene {}",
                surfaces.len(),
                prims.len()
            );
        }
        Ok(CsgPrims {
            prims: surfaces
                .into_iter()
                .zip(prims)
                .filter(|(_, p)| matches!(p, PreparedPrim::Csg(_)))
                .collect(),
        })
    }

    /// Whether the solid has no CSG prim.
    pub(crate) fn is_empty(&self) -> bool {
        self.prims.is_empty()
    }

    /// A user geometry over these prims. `self` must outlive the geometry and stay at its
    /// address (the caller keeps it, unmoved, as long as the Embree scenes).
    pub(crate) fn geometry(&self, device: &Device) -> crate::Result<Geometry> {
        let g = Geometry::new(device, ffi::RTC_GEOMETRY_TYPE_USER)?;
        let user = self as *const CsgPrims as *mut c_void;
        // SAFETY: `g` is a new user geometry; `user` stays valid for as long as the
        // geometry (see above) and is only read, through `&CsgPrims`, by the callbacks.
        unsafe {
            ffi::rtcSetGeometryUserPrimitiveCount(g.raw(), self.prims.len() as u32);
            ffi::rtcSetGeometryUserData(g.raw(), user);
            ffi::rtcSetGeometryBoundsFunction(g.raw(), Some(bounds), user);
            ffi::rtcSetGeometryIntersectFunction(g.raw(), Some(intersect));
            ffi::rtcSetGeometryOccludedFunction(g.raw(), Some(occluded));
        }
        device.check(|| "setting up a CSG user geometry".into())?;
        Ok(g)
    }
}

/// What `rtcIntersect1` is given as its context: Embree's context first, then what the
/// callbacks need. Callbacks get a pointer to `base` back and cast it to this struct.
#[repr(C)]
pub(crate) struct TraceContext<'s> {
    /// Embree's part; must stay the first field.
    pub(crate) base: ffi::RTCIntersectContext,
    /// The ray in world coordinates.
    pub(crate) ray: Ray<f32>,
    /// Instance index of each geometry id of the top-level scene traced.
    pub(crate) members: &'s [u32],
    /// Frames of the instances.
    pub(crate) cpu: &'s CpuScene<f32>,
    /// Set when a callback panicked (the answer is then not to be trusted).
    pub(crate) panicked: Cell<bool>,
    /// The least parameter, before the segment's end, at which a CSG prim decided within
    /// rounding ([`hytrace_csg::kernel::Step::dropped`]; `+inf`: nowhere).
    pub(crate) dropped: Cell<f32>,
}

/// `RTCBoundsFunction`: a CSG prim's bounds in the solid's frame.
unsafe extern "C" fn bounds(args: *const ffi::RTCBoundsFunctionArguments) {
    // SAFETY: Embree passes valid arguments whose user pointer is the `CsgPrims` set in
    // `CsgPrims::geometry`, alive while the geometry is.
    let args = unsafe { &*args };
    let prims = unsafe { &*(args.geometry_user_ptr as *const CsgPrims) };
    // Indexing with `get` and plain arithmetic: nothing here can panic.
    let b = prims
        .prims
        .get(args.prim_id as usize)
        .map(|(_, p)| *p.bounds());
    // SAFETY: `args` are a bounds callback's arguments.
    unsafe { write_bounds(args, b) };
}

/// Writes a bounds callback's answer (an empty point box for a primitive that is not
/// there).
///
/// # Safety
/// `args` must be the arguments Embree passes to a bounds callback.
unsafe fn write_bounds(args: &ffi::RTCBoundsFunctionArguments, b: Option<[V3<f32>; 2]>) {
    let [lo, hi] = b.unwrap_or([V3::new(0.0, 0.0, 0.0); 2]);
    let out = ffi::RTCBounds {
        lower_x: lo.x,
        lower_y: lo.y,
        lower_z: lo.z,
        align0: 0.0,
        upper_x: hi.x,
        upper_y: hi.y,
        upper_z: hi.z,
        align1: 0.0,
    };
    // SAFETY: `bounds_o` points at one writable `RTCBounds`.
    unsafe { args.bounds_o.write(out) };
}

/// Word offsets (in units of `N`) of the `RTCRayHitN` fields the callback uses.
const TNEAR: usize = 3;
const TFAR: usize = 8;
const HIT: usize = 12;
const NG_X: usize = HIT;
const PRIM_ID: usize = HIT + 5;
const GEOM_ID: usize = HIT + 6;
const INST_ID: usize = HIT + 7;

/// The ray's segment `(tnear, tfar)` in a callback call with one ray (`N == 1`, the only
/// calls the backend makes) whose lane is valid; `None` for any other call.
///
/// # Safety
/// `args` must be the arguments Embree passes to an intersect or occluded callback.
unsafe fn segment(args: &ffi::RTCIntersectFunctionNArguments) -> Option<(f32, f32)> {
    // SAFETY: `valid` has `N` entries.
    if args.n != 1 || unsafe { *args.valid } == 0 {
        return None;
    }
    let floats = args.rayhit as *const f32;
    // SAFETY: with `N == 1` the structure of arrays has one word per field, the ray's
    // first (12 words, `tnear` and `tfar` among them).
    Some(unsafe { (*floats.add(TNEAR), *floats.add(TFAR)) })
}

/// The first crossing of the callback's CSG prim in the ray's open segment `(tnear, tfar)`
/// (read from the ray's words), with the prim's Foundry index and the instance; `None`
/// also when the call is not one the backend makes. A panic is flagged in the context.
///
/// # Safety
/// `args` must be the arguments Embree passes to an intersect or occluded callback of a
/// geometry set up by [`CsgPrims::geometry`], during `rtcIntersect1` or `rtcOccluded1`
/// with a [`TraceContext`].
unsafe fn crossing(
    args: &ffi::RTCIntersectFunctionNArguments,
) -> Option<(u32, hytrace_csg::kernel::Step<f32>, u32)> {
    // SAFETY: per the function's contract, the user pointer is the `CsgPrims` set in
    // `CsgPrims::geometry` and the context a `TraceContext`, both alive during the call.
    let prims = unsafe { &*(args.geometry_user_ptr as *const CsgPrims) };
    let ctx = unsafe { &*(args.context as *const TraceContext) };
    // SAFETY: per the function's contract.
    let (tnear, tfar) = unsafe { segment(args) }?;
    let instance = ctx.base.inst_id[0];
    let found = catch_unwind(AssertUnwindSafe(|| {
        let (id, prim) = prims.prims.get(args.prim_id as usize)?;
        let index = *ctx.members.get(instance as usize)?;
        let local = ctx.cpu.instance_frame(index).ray_to_local(&ctx.ray);
        let step = prim.first_crossing(&local, tnear);
        // The frame keeps the world ray's parameter: `dropped` is a world parameter.
        if step.dropped < tfar {
            ctx.dropped.set(ctx.dropped.get().min(step.dropped));
        }
        (step.t > tnear && step.t < tfar).then_some((*id, step, instance))
    }));
    found.unwrap_or_else(|_| {
        ctx.panicked.set(true);
        None
    })
}

/// `RTCIntersectFunctionN`: the first crossing of a CSG prim, accepted when it lies in the
/// ray's open segment `(tnear, tfar)`. The hit's `primID` is the prim's Foundry index.
unsafe extern "C" fn intersect(args: *const ffi::RTCIntersectFunctionNArguments) {
    // SAFETY: Embree passes valid arguments of a geometry set up by `CsgPrims::geometry`,
    // during the backend's `rtcIntersect1` with a `TraceContext`.
    let args = unsafe { &*args };
    let Some((id, step, instance)) = (unsafe { crossing(args) }) else {
        return;
    };
    let words = args.rayhit as *mut u32;
    let floats = args.rayhit as *mut f32;
    // SAFETY: with `N == 1` the `RTCRayHitN` is 20 words; the callback owns lane 0 of the
    // hit for this call.
    unsafe {
        *floats.add(TFAR) = step.t;
        *floats.add(NG_X) = step.normal.x;
        *floats.add(NG_X + 1) = step.normal.y;
        *floats.add(NG_X + 2) = step.normal.z;
        *words.add(PRIM_ID) = id;
        *words.add(GEOM_ID) = args.geom_id;
        *words.add(INST_ID) = instance;
    }
}

/// `RTCOccludedFunctionN`: marks the ray occluded (`tfar = -inf`) when the CSG prim is
/// crossed in its open segment `(tnear, tfar)`.
unsafe extern "C" fn occluded(args: *const ffi::RTCIntersectFunctionNArguments) {
    // SAFETY: as for `intersect`, during the backend's `rtcOccluded1`; the arguments have
    // the intersect arguments' layout with an `RTCRayN` in place of the `RTCRayHitN`.
    let args = unsafe { &*args };
    if unsafe { crossing(args) }.is_some() {
        // SAFETY: with `N == 1` the `RTCRayN` is 12 words; the callback owns lane 0.
        unsafe { *(args.rayhit as *mut f32).add(TFAR) = f32::NEG_INFINITY };
    }
}

/// The volume-brick clusters of one solid: the user data of its cluster user geometry, one
/// user primitive per cluster.
pub(crate) struct ClusterBoxes<'a> {
    clusters: &'a [Cluster<f32>],
}

impl<'a> ClusterBoxes<'a> {
    /// The clusters of a solid, as [`CpuScene`] holds them.
    pub(crate) fn new(clusters: &'a [Cluster<f32>]) -> Self {
        ClusterBoxes { clusters }
    }

    /// Whether the solid has no cluster.
    pub(crate) fn is_empty(&self) -> bool {
        self.clusters.is_empty()
    }

    /// A user geometry over these clusters; `self` must outlive it and stay at its address
    /// (as for [`CsgPrims::geometry`]). Its intersect callback records every cluster the
    /// ray crosses in the [`MediaContext`] and accepts no hit, so one `rtcIntersect1`
    /// visits them all.
    pub(crate) fn geometry(&self, device: &Device) -> crate::Result<Geometry> {
        let g = Geometry::new(device, ffi::RTC_GEOMETRY_TYPE_USER)?;
        let user = self as *const ClusterBoxes as *mut c_void;
        // SAFETY: as in `CsgPrims::geometry`, for `ClusterBoxes`.
        unsafe {
            ffi::rtcSetGeometryUserPrimitiveCount(g.raw(), self.clusters.len() as u32);
            ffi::rtcSetGeometryUserData(g.raw(), user);
            ffi::rtcSetGeometryBoundsFunction(g.raw(), Some(cluster_bounds), user);
            ffi::rtcSetGeometryIntersectFunction(g.raw(), Some(cluster_visit));
        }
        device.check(|| "setting up a brick-cluster user geometry".into())?;
        Ok(g)
    }
}

/// What `rtcIntersect1` is given as its context when it looks for brick clusters: Embree's
/// context first, then the world ray and where the visits go.
#[repr(C)]
pub(crate) struct MediaContext<'s> {
    /// Embree's part; must stay the first field.
    pub(crate) base: ffi::RTCIntersectContext,
    /// The ray in world coordinates.
    pub(crate) ray: Ray<f32>,
    /// Instance index of each geometry id of the media's top-level scene.
    pub(crate) members: &'s [u32],
    /// Frames of the instances.
    pub(crate) cpu: &'s CpuScene<f32>,
    /// The clusters crossed: `(instance, medium, t0, t1)`.
    pub(crate) visits: RefCell<Vec<(u32, u32, f64, f64)>>,
    /// Set when a callback panicked.
    pub(crate) panicked: Cell<bool>,
}

/// `RTCBoundsFunction`: a cluster's box in the solid's frame.
unsafe extern "C" fn cluster_bounds(args: *const ffi::RTCBoundsFunctionArguments) {
    // SAFETY: Embree passes valid arguments whose user pointer is the `ClusterBoxes` set in
    // `ClusterBoxes::geometry`, alive while the geometry is.
    let args = unsafe { &*args };
    let boxes = unsafe { &*(args.geometry_user_ptr as *const ClusterBoxes) };
    let b = boxes.clusters.get(args.prim_id as usize).map(|c| c.bounds);
    // SAFETY: `args` are a bounds callback's arguments.
    unsafe { write_bounds(args, b) };
}

/// `RTCIntersectFunctionN`: records the part `[t0, t1]` of `[tnear, tfar]` inside a
/// cluster's box, the box tested in the instance's frame as [`CpuScene`] tests it (ray
/// re-derived from the world ray with the instance's frame, exact slab test); accepts no
/// hit.
unsafe extern "C" fn cluster_visit(args: *const ffi::RTCIntersectFunctionNArguments) {
    // SAFETY: Embree passes valid arguments; the user pointer is the `ClusterBoxes` set in
    // `ClusterBoxes::geometry` and the context the `MediaContext` the backend gives
    // `rtcIntersect1` for the media's scene, both alive during the call.
    let args = unsafe { &*args };
    let boxes = unsafe { &*(args.geometry_user_ptr as *const ClusterBoxes) };
    let ctx = unsafe { &*(args.context as *const MediaContext) };
    // SAFETY: as above.
    let Some((tnear, tfar)) = (unsafe { segment(args) }) else {
        return;
    };
    let instance = ctx.base.inst_id[0];
    let visited = catch_unwind(AssertUnwindSafe(|| {
        let cluster = boxes.clusters.get(args.prim_id as usize)?;
        let index = *ctx.members.get(instance as usize)?;
        let local = ctx.cpu.instance_frame(index).ray_to_local(&ctx.ray);
        let (t0, t1) = ray_bounds_span(&local, &cluster.bounds, tnear, tfar)?;
        ctx.visits
            .borrow_mut()
            .push((index, cluster.medium, f64::from(t0), f64::from(t1)));
        Some(())
    }));
    if visited.is_err() {
        ctx.panicked.set(true);
    }
}
