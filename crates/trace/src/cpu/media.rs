//! Transmittance along rays through a scene's media up to the first surface: surfaces are
//! opaque, media attenuate (`trace_transmittance`); and the first real collision with the
//! media along a ray (`collision`, delta tracking: the free paths of the renderer's paths
//! and of photons).
//!
//! Each medium's grid is opened again from its source and bricked in the texel format its
//! Foundry bricks were made from, so the lookups are those of the bricked grid a GPU
//! would sample. The instances holding media are found through their BVH, then the
//! clusters of their bricks through the solid's BVH; the part of the ray inside a
//! placement's clusters (widened for rounding: beyond the bricks the density is zero) is
//! handed to the volume crate's estimators in the grid's index space, in f64. Media that
//! overlap add their densities, so the transmittances multiply; every placement draws its
//! own random streams, which keeps the product of the stochastic estimates unbiased.
//!
//! The grids are kept with an identity map (index space is their world space; the
//! placement lives in the scene's transforms), so a GPU volume handed a segment's
//! [`MediumSegment::ray`] as its world ray estimates the very index ray the CPU does
//! (`crate::scan::scan_transmittance_on`).

use std::collections::BTreeMap;
use std::str::FromStr;

use crate::error::Context;
use hytrace_csg::{Ray, Real};
use hytrace_foundry::{Foundry, PrimKind, Transform64};
use hytrace_volume::{
    CacheStats, GridMap, IndexRay, IndexTransmittance, Rng, TexelFormat, TransmittanceParams,
    VolumeError, DEFAULT_STORE_BUDGET,
};

use rayon::prelude::*;

use super::bvh::RaySlabs;
use super::{CpuScene, Hit};
use crate::scan::RayRow;
use crate::scene::{open_medium, MediumGrid, MediumSpec, STORED_FORMAT};

/// A medium's grid and what its transmittance needs.
struct OpenMedium {
    grid: MediumGrid,
    /// The caller's parameters with this medium's density scale folded in.
    params: TransmittanceParams,
}

/// One ray's answer: its first surface crossing and the transmittance of the media before
/// it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Transmitted<T> {
    /// The first surface crossing, if any.
    pub hit: Option<Hit<T>>,
    /// Transmittance of the media over `[tmin, hit t]` (`[tmin, tmax]` without a hit).
    pub transmittance: f64,
    /// Density lookups spent.
    pub lookups: u64,
}

/// One placed medium's part of a ray: the medium, the part in its index space and the
/// random streams it draws.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MediumSegment {
    /// The medium (index into the Foundry's `optics.media`).
    pub medium: u32,
    /// Position of the placement among the ray's segments (instance order); its random
    /// streams are those of [`SceneMedia::params`] for it.
    pub placement: u32,
    /// The part of the ray inside the placement, in the medium's index space, with the
    /// world ray's `t`.
    pub ray: IndexRay,
}

/// A scene's media opened: their grids and where each placement's index space lies. It
/// answers queries on the [`CpuScene`] it was opened for, through [`OpenMedia::on`] (so
/// that a holder of both, such as the photon propagator's scene, need not borrow one from
/// the other).
pub struct OpenMedia {
    grids: Vec<OpenMedium>,
    /// Index space of the medium of each volume prim, from world space, per instance:
    /// `(instance, medium) -> world-to-index`.
    to_index: BTreeMap<(u32, u32), Transform64>,
}

/// The media of a [`SceneMedia`]: its own, or borrowed from an [`OpenMedia`] kept apart.
enum Held<'a> {
    Own(OpenMedia),
    Borrowed(&'a OpenMedia),
}

impl std::ops::Deref for Held<'_> {
    type Target = OpenMedia;

    fn deref(&self) -> &OpenMedia {
        match self {
            Held::Own(m) => m,
            Held::Borrowed(m) => m,
        }
    }
}

/// A scene's surfaces and its media opened for transmittance queries.
pub struct SceneMedia<'a, T> {
    scene: &'a CpuScene<T>,
    open: Held<'a>,
}

/// The first real collision of a ray with a scene's media ([`SceneMedia::collision`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MediumCollision {
    /// The medium (index into the Foundry's `optics.media`).
    pub medium: u32,
    /// Where along the ray.
    pub t: f64,
    /// The extinction there: the density with the medium's density scale and the
    /// caller's folded in.
    pub density: f64,
}

impl OpenMedia {
    /// The media of `scene` opened once, for queries on it through [`OpenMedia::on`]; see
    /// [`SceneMedia::with_memory`].
    pub fn open<T: Real>(
        scene: &CpuScene<T>,
        f: &Foundry,
        params: &TransmittanceParams,
        memory: u64,
    ) -> crate::Result<OpenMedia> {
        let mut grids = Vec::with_capacity(f.optics.media.len());
        for (i, m) in f.optics.media.iter().enumerate() {
            let format = match m.format.as_str() {
                STORED_FORMAT => None,
                name => Some(
                    TexelFormat::from_str(name)
                        .with_context(|| format!("medium {i}: texel format"))?,
                ),
            };
            let spec = MediumSpec {
                source: m.source.clone(),
                grid: m.grid.clone(),
                density_scale: m.density_scale,
                format,
                placement: Transform64::IDENTITY,
            };
            let grid = open_medium(&spec, memory)
                .with_context(|| format!("medium {i} ({})", m.source))?
                .with_map(GridMap::IDENTITY);
            let mut params = *params;
            params.density_scale *= m.density_scale;
            params
                .validate(&grid, grid.ranges())
                .with_context(|| format!("medium {i} ({})", m.source))?;
            grids.push(OpenMedium { grid, params });
        }
        let mut to_index = BTreeMap::new();
        for &instance in &scene.media.members {
            let inst = &f.inst[instance as usize];
            let world = f.inst_tran[instance as usize].to_transform();
            let s = &f.solid[inst.solid as usize];
            for p in s.prim_offset..s.prim_offset + s.num_prim {
                let prim = &f.prim[p as usize];
                if prim.kind != PrimKind::Volume as u32 {
                    continue;
                }
                let medium = f
                    .optics
                    .media
                    .iter()
                    .position(|m| m.prim == p)
                    .with_context(|| format!("volume prim {p} has no medium"))?;
                let index_to_solid = match prim.transform {
                    0 => Transform64::IDENTITY,
                    k => f.tran[k as usize - 1],
                };
                let inverse = world
                    .compose(&index_to_solid)
                    .inverse()
                    .with_context(|| format!("instance {instance}: singular medium transform"))?;
                to_index.insert((instance, medium as u32), inverse);
            }
        }
        Ok(OpenMedia { grids, to_index })
    }

    /// The media answering queries on `scene`, which must be the scene they were opened
    /// for.
    pub fn on<'a, T: Real>(&'a self, scene: &'a CpuScene<T>) -> SceneMedia<'a, T> {
        SceneMedia {
            scene,
            open: Held::Borrowed(self),
        }
    }

    /// Number of media (the Foundry's `optics.media`).
    pub fn medium_count(&self) -> usize {
        self.grids.len()
    }

    /// The grid of `medium`, bricked in its Foundry texel format or read as stored, with an
    /// identity map: its world space is its index space.
    pub fn grid(&self, medium: u32) -> &MediumGrid {
        &self.grids[medium as usize].grid
    }
}

/// Seed of the random streams of the `k`-th placed medium on a ray (a Weyl step keeps the
/// streams of different placements apart).
fn placement_seed(seed: u32, k: u32) -> u32 {
    seed.wrapping_add(k.wrapping_mul(0x9E37_79B9))
}

impl<'a, T: Real> SceneMedia<'a, T> {
    /// Opens every medium of `f` (the Foundry `scene` was prepared from); `params` apply to
    /// all, their density scale multiplying each medium's own. Media read as stored in a
    /// brick store hold at most [`DEFAULT_STORE_BUDGET`] bytes each.
    pub fn new(
        scene: &'a CpuScene<T>,
        f: &Foundry,
        params: &TransmittanceParams,
    ) -> crate::Result<Self> {
        Self::with_memory(scene, f, params, DEFAULT_STORE_BUDGET)
    }

    /// [`SceneMedia::new`] with each medium read as stored in a brick store holding at most
    /// `memory` bytes resident (its tables and a cache of bricks read on demand).
    pub fn with_memory(
        scene: &'a CpuScene<T>,
        f: &Foundry,
        params: &TransmittanceParams,
        memory: u64,
    ) -> crate::Result<Self> {
        Ok(SceneMedia {
            scene,
            open: Held::Own(OpenMedia::open(scene, f, params, memory)?),
        })
    }

    /// The first surface crossing of the ray `origin + t direction` (unit direction, world
    /// space) with `tmin < t < tmax`, and the transmittance of the media before it;
    /// `ray_index` selects the random streams of the stochastic estimators.
    pub fn trace_transmittance(
        &self,
        origin: [f64; 3],
        direction: [f64; 3],
        tmin: f64,
        tmax: f64,
        ray_index: u32,
    ) -> crate::Result<Transmitted<T>> {
        let ray = Ray::from_f64(origin, direction);
        let hit = self.scene.trace(&ray, T::from_f64(tmin), T::from_f64(tmax));
        let end = hit.map_or(tmax, |h| h.t.to_f64());
        let (transmittance, lookups) =
            self.transmittance_to(origin, direction, tmin, end, ray_index)?;
        Ok(Transmitted {
            hit,
            transmittance,
            lookups,
        })
    }

    /// The transmittance of the media along the ray over `[tmin, end]`, `end` being its
    /// first surface crossing already found (or its `tmax`), and the density lookups it
    /// took.
    pub fn transmittance_to(
        &self,
        origin: [f64; 3],
        direction: [f64; 3],
        tmin: f64,
        end: f64,
        ray_index: u32,
    ) -> crate::Result<(f64, u64)> {
        let spans = self.spans(&Ray::from_f64(origin, direction), tmin, end);
        self.transmittance_over(origin, direction, spans, ray_index)
    }

    /// [`Self::transmittance_to`] with the brick clusters the ray meets found by another
    /// backend (the Embree one): `visits` lists `(instance, medium, t0, t1)` for every
    /// cluster of a placed medium whose box the ray crosses over `[t0, t1]` within
    /// `[tmin, end]`, in any order, as [`CpuScene`]'s own search finds them.
    pub fn transmittance_with(
        &self,
        origin: [f64; 3],
        direction: [f64; 3],
        tmin: f64,
        end: f64,
        visits: impl IntoIterator<Item = (u32, u32, f64, f64)>,
        ray_index: u32,
    ) -> crate::Result<(f64, u64)> {
        let ray: Ray<T> = Ray::from_f64(origin, direction);
        let mut spans = ClusterSpans::default();
        for (instance, medium, t0, t1) in visits {
            spans.add(instance, medium, t0, t1);
        }
        let spans = spans.finish(&ray, tmin, end);
        self.transmittance_over(origin, direction, spans, ray_index)
    }

    /// The product of the media's transmittances over their spans on the ray, and the
    /// lookups spent.
    fn transmittance_over(
        &self,
        origin: [f64; 3],
        direction: [f64; 3],
        spans: Vec<((u32, u32), (f64, f64))>,
        ray_index: u32,
    ) -> crate::Result<(f64, u64)> {
        let mut transmittance = 1.0;
        let mut lookups = 0;
        for s in self.segments_of(origin, direction, spans)? {
            let e = self.tracked(&s, |t| t.estimate(&s.ray, ray_index))?;
            transmittance *= e.transmittance;
            lookups += e.lookups;
        }
        Ok((transmittance, lookups))
    }

    /// `estimate` given the tracker of segment `s`'s medium, with its parameters.
    fn tracked<R>(
        &self,
        s: &MediumSegment,
        estimate: impl FnOnce(IndexTransmittance<MediumGrid>) -> Result<R, VolumeError>,
    ) -> crate::Result<R> {
        let params = self.params(s.medium, s.placement);
        let grid = self.grid(s.medium);
        let tracker = IndexTransmittance::new(grid, grid.ranges(), &params)?;
        Ok(estimate(tracker)?)
    }

    /// The first real collision with any medium over `[t0, t1]` of the ray `origin + t
    /// direction` (unit direction, world space), by delta tracking each placed medium
    /// under its local majorants ([`IndexTransmittance::collision`]) with draws from `rng`:
    /// the earliest of the media's independent collisions is the collision of the media
    /// together. `None` when the ray passes `[t0, t1]` without one.
    pub fn collision(
        &self,
        origin: [f64; 3],
        direction: [f64; 3],
        t0: f64,
        t1: f64,
        rng: &mut Rng,
    ) -> crate::Result<Option<MediumCollision>> {
        let mut best: Option<MediumCollision> = None;
        for s in self.segments(origin, direction, t0, t1)? {
            if let Some(c) = self.tracked(&s, |t| t.collision(&s.ray, rng))? {
                if best.is_none_or(|b| c.t < b.t) {
                    best = Some(MediumCollision {
                        medium: s.medium,
                        t: c.t,
                        density: c.density,
                    });
                }
            }
        }
        Ok(best)
    }

    /// [`Self::trace_transmittance`] of every ray in parallel, ray `i` with the random
    /// streams of index `i`; an error names the first ray that fails.
    pub fn trace_all(&self, rays: &[RayRow]) -> crate::Result<Vec<Transmitted<T>>> {
        crate::error::ensure!(
            u32::try_from(rays.len()).is_ok(),
            "{} rays, at most {} in one batch",
            rays.len(),
            u32::MAX
        );
        rays.par_iter()
            .enumerate()
            .map(|(i, r)| {
                self.trace_transmittance(r.origin, r.direction, r.tmin, r.tmax, i as u32)
                    .with_context(|| format!("ray {i}"))
            })
            .collect()
    }

    /// The transmittance along every ray up to its end (`ends[i]`: its first surface
    /// crossing from a scan, or its `tmax`), ray `i` drawing the streams of index
    /// `first_ray + i` (so a batch split in parts, each given the index of its first ray,
    /// estimates what the whole batch does).
    pub fn transmittances_to(
        &self,
        rays: &[RayRow],
        ends: &[f64],
        first_ray: u32,
    ) -> crate::Result<Vec<f64>> {
        self.each_ray(rays, ends, first_ray, |r, end, i| {
            self.transmittance_to(r.origin, r.direction, r.tmin, end, i)
        })
    }

    /// [`Self::transmittances_to`] with the clusters each ray meets over `[tmin, end]` found
    /// by another backend (see [`Self::transmittance_with`]).
    pub fn transmittances_with(
        &self,
        rays: &[RayRow],
        ends: &[f64],
        first_ray: u32,
        visits: impl Fn(&RayRow, f64) -> crate::Result<Vec<(u32, u32, f64, f64)>> + Sync,
    ) -> crate::Result<Vec<f64>> {
        self.each_ray(rays, ends, first_ray, |r, end, i| {
            let found = visits(r, end)?;
            self.transmittance_with(r.origin, r.direction, r.tmin, end, found, i)
        })
    }

    /// `estimate(ray, end, first_ray + ray index)` of every ray in parallel (the
    /// transmittances); an error names the first ray that fails.
    fn each_ray(
        &self,
        rays: &[RayRow],
        ends: &[f64],
        first_ray: u32,
        estimate: impl Fn(&RayRow, f64, u32) -> crate::Result<(f64, u64)> + Sync,
    ) -> crate::Result<Vec<f64>> {
        crate::error::ensure!(
            rays.len() == ends.len()
                && u64::from(first_ray) + rays.len() as u64 <= u64::from(u32::MAX) + 1,
            "{} rays from index {first_ray} and {} ends: need as many, at most {} indices",
            rays.len(),
            ends.len(),
            u64::from(u32::MAX) + 1
        );
        rays.par_iter()
            .zip(ends)
            .enumerate()
            .map(|(i, (r, &end))| {
                estimate(r, end, first_ray + i as u32)
                    .map(|(t, _)| t)
                    .with_context(|| format!("ray {i}"))
            })
            .collect()
    }

    /// The placed media: `(instance, medium)` with the transform from world space to the
    /// medium's index space, in instance order.
    pub fn placements(&self) -> impl Iterator<Item = ((u32, u32), &Transform64)> {
        self.open.to_index.iter().map(|(k, t)| (*k, t))
    }

    /// Number of media ([`OpenMedia::medium_count`]).
    pub fn medium_count(&self) -> usize {
        self.open.medium_count()
    }

    /// The grid of `medium` ([`OpenMedia::grid`]).
    pub fn grid(&self, medium: u32) -> &MediumGrid {
        self.open.grid(medium)
    }

    /// What the caches of the media read as stored did, summed over them (`None` when no
    /// medium is read as stored).
    pub fn store_stats(&self) -> Option<CacheStats> {
        let stores = self.open.grids.iter().filter_map(|m| match &m.grid {
            MediumGrid::Store(s, _) => Some(s.stats()),
            MediumGrid::Bricked(_) => None,
        });
        stores.reduce(|a, b| CacheStats {
            bricks_read: a.bricks_read + b.bricks_read,
            capacity_bricks: a.capacity_bricks + b.capacity_bricks,
            table_bytes: a.table_bytes + b.table_bytes,
        })
    }

    /// An error when a medium read as stored could not read a brick it needed since it was
    /// opened (those lookups read the background): results computed meanwhile are wrong.
    pub fn check_reads(&self) -> crate::Result<()> {
        for (i, m) in self.open.grids.iter().enumerate() {
            m.grid
                .check_reads()
                .with_context(|| format!("medium {i}"))?;
        }
        Ok(())
    }

    /// The parameters of `medium` on the `placement`-th segment of a ray: the caller's, with
    /// the medium's density scale folded in and the placement's seed.
    pub fn params(&self, medium: u32, placement: u32) -> TransmittanceParams {
        let mut params = self.open.grids[medium as usize].params;
        params.seed = placement_seed(params.seed, placement);
        params
    }

    /// The segments of the ray `origin + t direction` (unit direction, world space) over
    /// `[tmin, end]` (`end` being its first surface crossing or its `tmax`) inside each
    /// placed medium, in instance order; errors on a ray the estimators refuse.
    pub fn segments(
        &self,
        origin: [f64; 3],
        direction: [f64; 3],
        tmin: f64,
        end: f64,
    ) -> crate::Result<Vec<MediumSegment>> {
        let spans = self.spans(&Ray::from_f64(origin, direction), tmin, end);
        self.segments_of(origin, direction, spans)
    }

    /// The segments of the ray over the spans of [`Self::spans`] (or [`ClusterSpans`]).
    fn segments_of(
        &self,
        origin: [f64; 3],
        direction: [f64; 3],
        spans: Vec<((u32, u32), (f64, f64))>,
    ) -> crate::Result<Vec<MediumSegment>> {
        spans
            .into_iter()
            .enumerate()
            .map(|(k, ((instance, medium), (t0, t1)))| {
                // A visit from another backend may name a placement this scene lacks.
                let w = self
                    .open
                    .to_index
                    .get(&(instance, medium))
                    .with_context(|| {
                        format!("instance {instance} does not hold medium {medium}")
                    })?;
                let ray = IndexRay::new(w.apply_point(origin), w.apply_vector(direction), t0, t1)?;
                Ok(MediumSegment {
                    medium,
                    placement: k as u32,
                    ray,
                })
            })
            .collect()
    }

    /// The part of `[tmin, end]` inside the brick clusters of each placed medium the ray
    /// meets (see [`ClusterSpans`]), the clusters found through the scene's BVHs.
    fn spans(&self, ray: &Ray<T>, tmin: f64, end: f64) -> Vec<((u32, u32), (f64, f64))> {
        let scene = self.scene;
        let mut spans = ClusterSpans::default();
        let (lo, hi) = (T::from_f64(tmin), T::from_f64(end));
        let mut visit_instance = |i: u32| {
            let p = &scene.placements[i as usize];
            let local = p.frame.ray_to_local(ray);
            scene.solids[p.solid].visit_clusters(&local, lo, hi, |c, t0, t1| {
                spans.add(i, c.medium, t0.to_f64(), t1.to_f64());
            });
        };
        let group = &scene.media;
        match &group.bvh {
            None => group.members.iter().for_each(|&i| visit_instance(i)),
            Some(bvh) => bvh.visit_ray(ray, &RaySlabs::new(ray), lo, hi, |i| {
                visit_instance(i);
                hi
            }),
        }
        spans.finish(ray, tmin, end)
    }
}

/// The brick clusters one ray meets, merged per placed medium as they are found (by
/// [`CpuScene`]'s BVHs or by another backend, in any order): `((instance, medium),
/// (t0, t1))`, the union of the placement's cluster spans. A ray meets few placed media,
/// so a list it is.
#[derive(Default)]
struct ClusterSpans(Vec<((u32, u32), (f64, f64))>);

impl ClusterSpans {
    /// Adds the part `[t0, t1]` of the ray inside one cluster of `medium` in `instance`.
    fn add(&mut self, instance: u32, medium: u32, t0: f64, t1: f64) {
        match self
            .0
            .iter_mut()
            .find(|(key, _)| *key == (instance, medium))
        {
            Some((_, span)) => *span = (span.0.min(t0), span.1.max(t1)),
            None => self.0.push(((instance, medium), (t0, t1))),
        }
    }

    /// The spans in instance order, widened for the rounding of the precision `T` tests
    /// and clamped to `[tmin, end]`.
    fn finish<T: Real>(self, ray: &Ray<T>, tmin: f64, end: f64) -> Vec<((u32, u32), (f64, f64))> {
        let o = ray.origin.to_f64();
        let reach = 1.0 + o.iter().fold(0.0f64, |a, c| a.max(c.abs()));
        let mut spans = self.0;
        // Instance order, whatever order the clusters were found in: it picks the seeds.
        spans.sort_unstable_by_key(|(key, _)| *key);
        spans
            .into_iter()
            .map(|(key, (t0, t1))| {
                // Precision-T slab tests are off by a few ulps of the larger of t and the
                // coordinates; the density is zero just outside the clusters, so widening
                // costs nothing but a few empty steps.
                let slack = 64.0 * T::EPSILON.to_f64() * (t0.abs().max(t1.abs()) + reach);
                (key, ((t0 - slack).max(tmin), (t1 + slack).min(end)))
            })
            .collect()
    }
}
