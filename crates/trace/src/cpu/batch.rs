//! Tracing rays in batches, so that the mesh searches of several rays run interleaved on
//! one thread ([`MeshPrim::first_crossings`]): incoherent rays through a large mesh spend
//! most of their time waiting on memory, and the interleaved searches wait together;
//! coherent rays (consecutive queries of one mesh running close together) are searched
//! as packets, sharing each node's fetch and test.
//!
//! A trace asks for its prims' first crossings through [`Crossings`]. [`Direct`] computes
//! each at once (the per-ray [`CpuScene::trace`]). A batch trace runs each ray's ordinary
//! trace through a [`Replay`] instead: it answers CSG prims and small meshes at once
//! ([`INTERLEAVE_MIN_BYTES`]), and other mesh prims from the ray's log of earlier answers,
//! in the order the trace asks for them; the first mesh query past the end of the log
//! abandons the trace. The batch then answers the abandoned rays' queries together,
//! interleaved, appends each answer to its ray's log, and replays those rays. A replay
//! makes the same decisions as the trace before it up to the new answer (same limits, same
//! order), so it asks the same queries, and the last replay returns exactly what
//! [`CpuScene::trace`] returns, bit for bit. After [`REPLAYS`] rounds a ray is finished
//! with direct answers, so rays that meet many meshes do not pay for their walks over and
//! over.
//!
//! The replays cost: tracing each ray twice (abandoned, then replayed) took a fifth to a
//! quarter of a batch's time on the 1M-triangle heightfield, measured against the bare
//! interleaved searches. A scene that is one axis-aligned placement of one mesh (an OBJ or
//! glTF mesh scanned alone, [`CpuScene::lone_mesh`]) needs none: its trace asks that mesh
//! one query, as its last act, so the batch makes each ray's query and finishes its answer
//! with the trace's own steps (`Placement::local_ray`, `SolidAccel::lone_crossing`,
//! `CpuScene::in_world`), and traces nothing.

use hytrace_csg::kernel::Step;
use hytrace_csg::{CrossingScratch, MeshPrim, MeshQuery, PreparedPrim, Ray, Real, SlabRay};

use super::{CpuScene, Hit, WorldRay};

/// Rounds of interleaved mesh searches a ray of a batch takes part in; past them its trace
/// answers its remaining mesh queries directly.
pub(super) const REPLAYS: usize = 4;

/// Meshes whose search structures ([`MeshPrim::bvh_bytes`]) are smaller than this are
/// searched at once, not interleaved: their searches run from the caches, where stepping
/// several in turn only adds work. A core's L2 cache here holds 1 MiB. Measured with
/// `cargo bench -p hytrace-tests --bench mixed` and `--bench mesh` (BENCHMARKS.md): the
/// mixed scene's 1280-triangle mesh (about 0.2 MB) traced 5-25% slower interleaved, the
/// 1M-triangle heightfield (tens of MB) 30-60% faster on incoherent rays.
pub const INTERLEAVE_MIN_BYTES: usize = 1 << 20;

/// Where a trace gets its prims' first crossings (in the solid's frame) and the location
/// of its origin.
pub(super) trait Crossings<'a, T: Real> {
    /// `prim.first_crossing(ray, tmin)`, or `None` to abandon the trace (computed at once
    /// unless the implementation says otherwise).
    #[inline(always)]
    fn first_crossing(
        &mut self,
        prim: &'a PreparedPrim<T>,
        ray: &Ray<T>,
        tmin: T,
    ) -> Option<Step<T>> {
        Some(prim.first_crossing(ray, tmin))
    }

    /// Whether the trace was abandoned: its answer means nothing and it should stop
    /// (never, unless the implementation says otherwise).
    #[inline(always)]
    fn abandoned(&self) -> bool {
        false
    }

    /// The deepest instance containing the ray's origin, which `locate` finds.
    fn located(&mut self, locate: impl FnOnce() -> Option<u32>) -> Option<u32>;

    /// A prim asked for its first crossing skipped a short span as a touch, or a mesh
    /// decided a triangle within rounding, before the search's limit ([`Step::dropped`]),
    /// at world parameter `at`: an answer not beyond it is within rounding of a decision.
    fn note_dropped(&mut self, at: T);
}

/// Every crossing computed when asked: the per-ray trace.
pub(super) struct Direct;

impl<T: Real> Crossings<'_, T> for Direct {
    #[inline(always)]
    fn located(&mut self, locate: impl FnOnce() -> Option<u32>) -> Option<u32> {
        locate()
    }

    #[inline(always)]
    fn note_dropped(&mut self, _at: T) {}
}

/// Every crossing computed when asked, noting what the f32 fallback asks of the trace
/// ([`CpuScene::trace_flagged`]): where the origin was located and where a decision was
/// within rounding.
pub(super) struct Noting<T> {
    /// Where the origin was located, once it was.
    pub located: Option<Option<u32>>,
    /// The least world parameter of a decision within rounding ([`Crossings::note_dropped`]);
    /// `+inf` when there was none.
    pub dropped: T,
}

impl<T: Real> Default for Noting<T> {
    fn default() -> Self {
        Noting {
            located: None,
            dropped: T::INFINITY,
        }
    }
}

impl<T: Real> Crossings<'_, T> for Noting<T> {
    fn located(&mut self, locate: impl FnOnce() -> Option<u32>) -> Option<u32> {
        *self.located.get_or_insert_with(locate)
    }

    fn note_dropped(&mut self, at: T) {
        self.dropped = self.dropped.min(at);
    }
}

/// What a batch keeps of one ray between its replays.
#[derive(Clone, Debug)]
struct RayLog<T> {
    /// Answers to the ray's mesh queries, in the order its trace asks them.
    answers: Vec<Step<T>>,
    /// Where its origin was located, once it was.
    located: Option<Option<u32>>,
    /// The least world parameter of a decision within rounding, as [`Noting::dropped`] (a
    /// replay repeats the decisions of the one before, so the last one's notes are all of
    /// them).
    dropped: T,
}

impl<T: Real> Default for RayLog<T> {
    fn default() -> Self {
        RayLog {
            answers: Vec::new(),
            located: None,
            dropped: T::INFINITY,
        }
    }
}

/// One replay of a ray's trace.
struct Replay<'a, 'l, T> {
    log: &'l mut RayLog<T>,
    /// Mesh queries asked so far, the first ones answered from the log.
    asked: usize,
    /// Past the log, compute answers instead of abandoning.
    direct: bool,
    /// The query past the log that abandoned the trace.
    pending: Option<MeshQuery<'a, T>>,
    /// Meshes with smaller search structures are answered at once.
    min_bytes: usize,
}

impl<'a, T: Real> Crossings<'a, T> for Replay<'a, '_, T> {
    fn first_crossing(
        &mut self,
        prim: &'a PreparedPrim<T>,
        ray: &Ray<T>,
        tmin: T,
    ) -> Option<Step<T>> {
        let mesh = match prim {
            PreparedPrim::Mesh(mesh) if mesh.bvh_bytes() >= self.min_bytes => mesh,
            _ => return Some(prim.first_crossing(ray, tmin)),
        };
        let logged = self.log.answers.get(self.asked).copied();
        self.asked += 1;
        if logged.is_some() {
            return logged;
        }
        if self.direct {
            return Some(mesh.first_crossing(ray, tmin));
        }
        self.pending = Some(MeshQuery {
            mesh,
            ray: *ray,
            tmin,
        });
        None
    }

    fn abandoned(&self) -> bool {
        self.pending.is_some()
    }

    fn located(&mut self, locate: impl FnOnce() -> Option<u32>) -> Option<u32> {
        *self.log.located.get_or_insert_with(locate)
    }

    fn note_dropped(&mut self, at: T) {
        self.log.dropped = self.log.dropped.min(at);
    }
}

/// Working space of [`CpuScene::trace_batch`], kept by each thread from batch to batch
/// (the interleaved searches' stacks are large).
pub struct TraceScratch<T> {
    /// Meshes whose searches are interleaved: those of at least this many bytes.
    min_bytes: usize,
    /// One per ray of the batch.
    logs: Vec<RayLog<T>>,
    /// The rays still open, in order; after a round, those that asked its queries.
    askers: Vec<usize>,
    steps: Vec<Step<T>>,
    searches: CrossingScratch,
}

impl<T> Default for TraceScratch<T> {
    fn default() -> Self {
        Self::interleaving_from(INTERLEAVE_MIN_BYTES)
    }
}

impl<T> TraceScratch<T> {
    /// Scratch space for batches that interleave the searches of meshes whose search
    /// structures take at least `min_bytes` (the default: [`INTERLEAVE_MIN_BYTES`]); 0
    /// interleaves every mesh's, as tests do.
    pub fn interleaving_from(min_bytes: usize) -> Self {
        TraceScratch {
            min_bytes,
            logs: Vec::new(),
            askers: Vec::new(),
            steps: Vec::new(),
            searches: CrossingScratch::default(),
        }
    }
}

impl<T: Real> CpuScene<T> {
    /// [`Self::trace`] of every `(ray, tmin, tmax)` of `rays`, into `out` (cleared first):
    /// the same answers, bit for bit, with the mesh searches of the rays interleaved (see
    /// the module doc): hand it a few hundred rays at a time. In f64, where meshes are
    /// searched one box at a time, and in scenes without large meshes, each ray is traced
    /// on its own.
    pub fn trace_batch(
        &self,
        rays: &[(Ray<f64>, T, T)],
        scratch: &mut TraceScratch<T>,
        out: &mut Vec<Option<Hit<T>>>,
    ) {
        self.trace_batch_noting(rays, scratch, out, None);
    }

    /// [`Self::trace_batch`] that also reports, in `flags` (cleared first), what each ray's
    /// trace could not decide, as [`Self::trace_flagged`] does: the same hits and flags.
    pub fn trace_batch_flagged(
        &self,
        rays: &[(Ray<f64>, T, T)],
        scratch: &mut TraceScratch<T>,
        out: &mut Vec<Option<Hit<T>>>,
        flags: &mut Vec<u32>,
    ) {
        self.trace_batch_noting(rays, scratch, out, Some(flags));
    }

    /// [`Self::trace_batch`], with the flags of [`Self::trace_flagged`] when `flags` is
    /// given.
    fn trace_batch_noting(
        &self,
        rays: &[(Ray<f64>, T, T)],
        scratch: &mut TraceScratch<T>,
        out: &mut Vec<Option<Hit<T>>>,
        flags: Option<&mut Vec<u32>>,
    ) {
        out.clear();
        if T::NAME != "f32" || self.largest_mesh_bytes < scratch.min_bytes {
            match flags {
                None => out.extend(
                    rays.iter()
                        .map(|(r, tmin, tmax)| self.trace(r, *tmin, *tmax)),
                ),
                Some(flags) => {
                    flags.clear();
                    for (r, tmin, tmax) in rays {
                        let traced = self.trace_flagged(r, *tmin, *tmax);
                        out.push(traced.hit);
                        flags.push(traced.flags);
                    }
                }
            }
            return;
        }
        out.resize(rays.len(), None);
        if let Some((index, mesh)) = self.lone_mesh() {
            if mesh.bvh_bytes() >= scratch.min_bytes {
                let mut dropped = vec![T::INFINITY; rays.len()];
                self.trace_lone_mesh(index, mesh, rays, scratch, out, &mut dropped);
                if let Some(flags) = flags {
                    flags.clear();
                    flags.extend(rays.iter().zip(out.iter()).zip(&dropped).map(
                        |(((r, tmin, _), hit), &dropped)| {
                            let world = WorldRay::new(r);
                            self.flags_of(&world, *tmin, None, dropped, hit.as_ref())
                        },
                    ));
                }
                return;
            }
        }
        let TraceScratch {
            min_bytes,
            logs,
            askers,
            steps,
            searches,
        } = scratch;
        if logs.len() < rays.len() {
            logs.resize_with(rays.len(), RayLog::default);
        }
        for log in &mut logs[..rays.len()] {
            log.answers.clear();
            log.located = None;
            log.dropped = T::INFINITY;
        }
        // The rays still open: all at first, then those whose last replay was abandoned.
        askers.clear();
        askers.extend(0..rays.len());
        let mut queries = Vec::with_capacity(rays.len());
        for round in 0..=REPLAYS {
            queries.clear();
            askers.retain(|&i| {
                let (ray, tmin, tmax) = &rays[i];
                let mut replay = Replay {
                    log: &mut logs[i],
                    asked: 0,
                    direct: round == REPLAYS,
                    pending: None,
                    min_bytes: *min_bytes,
                };
                let hit = self.trace_with(&WorldRay::new(ray), *tmin, *tmax, &mut replay);
                match replay.pending {
                    Some(query) => queries.push(query),
                    None => out[i] = hit,
                }
                replay.pending.is_some()
            });
            if queries.is_empty() {
                break;
            }
            MeshPrim::first_crossings(&queries, searches, steps);
            for (&i, step) in askers.iter().zip(steps.iter()) {
                logs[i].answers.push(*step);
            }
        }
        if let Some(flags) = flags {
            flags.clear();
            flags.extend(rays.iter().zip(logs.iter()).zip(out.iter()).map(
                |(((r, tmin, _), log), hit)| {
                    let world = WorldRay::new(r);
                    self.flags_of(&world, *tmin, log.located, log.dropped, hit.as_ref())
                },
            ));
        }
    }
}

impl<T: Real> CpuScene<T> {
    /// [`Self::trace_batch`] of a scene that is one placed mesh, instance `index`
    /// ([`CpuScene::lone_mesh`]): each ray's trace asks that mesh one query, its last act,
    /// so the queries are made and their answers finished here as the trace does, and no
    /// trace is replayed. `dropped` gets, per ray, the world parameter of a decision within
    /// rounding before the search's limit, as [`Crossings::note_dropped`] notes it (`+inf`
    /// when none).
    fn trace_lone_mesh(
        &self,
        index: usize,
        mesh: &MeshPrim<T>,
        rays: &[(Ray<f64>, T, T)],
        scratch: &mut TraceScratch<T>,
        out: &mut [Option<Hit<T>>],
        dropped: &mut [T],
    ) {
        let TraceScratch {
            askers,
            steps,
            searches,
            ..
        } = scratch;
        let placement = &self.placements[index];
        askers.clear();
        let mut queries = Vec::with_capacity(rays.len());
        let mut locals = Vec::with_capacity(rays.len());
        for (i, (ray, tmin, tmax)) in rays.iter().enumerate() {
            // `trace`'s walk of a one-member group: the member's box, then its frame.
            let world = WorldRay::new(ray);
            let slabs = SlabRay::new(&world.rounded);
            if let Some(local) = placement.local_ray(&world, Some(&slabs), *tmin, *tmax) {
                queries.push(MeshQuery {
                    mesh,
                    ray: local.ray,
                    tmin: local.local_t(*tmin),
                });
                locals.push(local);
                askers.push(i);
            }
        }
        MeshPrim::first_crossings(&queries, searches, steps);
        let solid = &self.solids[placement.solid];
        for ((&i, step), local) in askers.iter().zip(steps.iter()).zip(&locals) {
            let (_, tmin, tmax) = rays[i];
            // `SolidAccel::cross`'s note for a lone prim.
            if step.dropped < local.past_local(tmax) {
                dropped[i] = local.shift + step.dropped;
            }
            out[i] = solid
                .lone_crossing(step, local.local_t(tmin), local.past_local(tmax))
                .and_then(|c| local.world_hit(c, index as u32, tmax))
                .map(|hit| self.in_world(hit));
        }
    }
}

#[cfg(test)]
impl<T: Real> CpuScene<T> {
    /// How many mesh queries the trace of `ray` asks (tests: which rays replay how often,
    /// every mesh interleaved).
    pub(super) fn mesh_queries(&self, ray: &Ray<f64>, tmin: T, tmax: T) -> usize {
        let mut log = RayLog::default();
        let mut replay = Replay {
            log: &mut log,
            asked: 0,
            direct: true,
            pending: None,
            min_bytes: 0,
        };
        self.trace_with(&WorldRay::new(ray), tmin, tmax, &mut replay);
        replay.asked
    }
}
