//! Read access to the pieces of a [`CpuScene`] that other tracers build on (the Embree
//! backend): prims and brick clusters per solid, placements, the search groups, and the
//! navigator's locate and exit steps. Each accessor only forwards to the scene's own fields and methods.

use hytrace_csg::kernel::Frame;
use hytrace_csg::{PreparedPrim, Ray, Real, V3};

use super::batch::Noting;
#[cfg(feature = "embree")]
use super::solid::Cluster;
use super::{CpuScene, Hit, Layout, WorldPoint, WorldRay};

impl<T: Real> CpuScene<T> {
    /// The surface prims (CSG trees and meshes) of solid `solid`, in the solid's frame.
    pub(crate) fn solid_prims(&self, solid: usize) -> &[PreparedPrim<T>] {
        &self.solids[solid].prims
    }

    /// The volume-brick clusters of solid `solid`, in the solid's frame.
    #[cfg(feature = "embree")]
    pub(crate) fn solid_clusters(&self, solid: usize) -> &[Cluster<T>] {
        &self.solids[solid].clusters
    }

    /// The instances whose solids hold media.
    #[cfg(feature = "embree")]
    pub(crate) fn media_members(&self) -> &[u32] {
        &self.media.members
    }

    /// The solid instance `instance` places.
    pub(crate) fn instance_solid(&self, instance: u32) -> usize {
        self.placements[instance as usize].solid
    }

    /// The frame of instance `instance` (world to the solid's frame).
    pub(crate) fn instance_frame(&self, instance: u32) -> &Frame<T> {
        &self.placements[instance as usize].frame
    }

    /// The instances a ray located outside every instance may enter: all of a flat scene,
    /// the roots of a hierarchical one.
    pub(crate) fn top_members(&self) -> &[u32] {
        match &self.layout {
            Layout::Flat(all) => &all.members,
            Layout::Tree(h) => &h.roots.members,
        }
    }

    /// The daughters of instance `instance` (none in a flat scene).
    pub(crate) fn daughter_members(&self, instance: u32) -> &[u32] {
        match &self.layout {
            Layout::Flat(_) => &[],
            Layout::Tree(h) => &h.daughters[instance as usize].members,
        }
    }

    /// The deepest instance containing `x` as the navigator locates it; `None` outside every
    /// root and in flat scenes (which [`CpuScene::trace`] does not navigate).
    pub(crate) fn locate_origin(&self, x: V3<f64>) -> Option<u32> {
        let Layout::Tree(h) = &self.layout else {
            return None;
        };
        self.locate_deepest(h, &WorldPoint::new(x))
    }

    /// Where the ray leaves instance `instance`, the navigator's exit (normal in the
    /// instance's frame, not normalized), and the least world parameter at which its
    /// search decided within rounding (`+inf`: nowhere; see [`CpuScene::trace_flagged`]).
    pub(crate) fn exit_from(
        &self,
        instance: u32,
        ray: &Ray<f64>,
        tmin: T,
        tmax: T,
    ) -> (Option<Hit<T>>, T) {
        let mut noting = Noting::default();
        let exit = self.exit(
            instance as usize,
            &WorldRay::new(ray),
            tmin,
            tmax,
            &mut noting,
        );
        (exit, noting.dropped)
    }

    /// The flags [`CpuScene::trace_flagged`] gives a trace of `ray` from `tmin` whose origin
    /// was located in `located` (as [`Self::locate_origin`] finds it), which decided within
    /// rounding at world parameters down to `dropped`, and answered `hit`.
    pub(crate) fn flags_for(
        &self,
        ray: &Ray<f64>,
        tmin: T,
        located: Option<u32>,
        dropped: T,
        hit: Option<&Hit<T>>,
    ) -> u32 {
        self.flags_of(&WorldRay::new(ray), tmin, Some(located), dropped, hit)
    }
}
