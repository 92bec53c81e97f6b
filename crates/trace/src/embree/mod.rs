//! The Embree backend: the CPU tracer's answers ([`CpuScene::trace`]) with Embree 3's
//! acceleration structures, in f32.
//!
//! Each solid is one Embree scene (a bottom-level structure): the triangles of its mesh
//! prims as an Embree triangle geometry, its CSG prims as a user geometry calling our
//! intersectors ([`user_geometry`]). Instances are Embree instances of those scenes, with
//! the instance's local-to-world transform, in one top-level scene per group of instances
//! searched together: all instances of a flat scene; the roots, and each instance's
//! daughters, of a hierarchical one.
//!
//! A flat scene's answer is Embree's closest hit over its one group. A hierarchical scene
//! is traced as Geant4's navigator, as the CPU tracer does and with its code: the origin is
//! located in the deepest instance containing it and the exit from that instance found by
//! [`CpuScene`]; Embree answers only "entering one of this group's members", and the nearer
//! of the two wins (the exit on a tie, as on the CPU). Ties between instances at the same
//! `t` may go to a different instance than on the CPU (which takes the lowest index).
//!
//! [`EmbreeScene::trace_flagged`] adds the flags of [`CpuScene::trace_flagged`] where the
//! information exists: starts near a surface (the CPU's check, from the instance the origin
//! was located in) and spans the CSG prims dropped (noted by the navigator's exit and by
//! the user geometry's callbacks), so that an f32 scan on Embree traces the same doubtful
//! rays again in f64 as the default scan. Embree's triangle tests report no doubt.
//!
//! Any-hit queries ([`EmbreeScene::occluded`]) go through `rtcOccluded1`, which stops at the
//! first crossing it finds.
//!
//! Every Embree object is released on drop. Requires the `embree` cargo feature and
//! Embree 3 (Debian: `libembree-dev`).

pub mod ffi;
mod handle;
mod user_geometry;

use std::cell::{Cell, RefCell};
use std::ffi::c_void;

use crate::error::{bail, Context};
use hytrace_csg::{Ray, V3};
use hytrace_foundry::{Foundry, PrimKind, Transform64};

use crate::cpu::media::{SceneMedia, Transmitted};
use crate::cpu::{CpuScene, Hit, Traced};
use handle::{Device, Geometry, Scene};
use user_geometry::{ClusterBoxes, CsgPrims, MediaContext, TraceContext};

/// A top-level scene over a group of instances, with the instance index of each of its
/// geometry ids.
struct GroupScene {
    scene: Scene,
    members: Vec<u32>,
}

/// A solid's bottom-level scene, with the Foundry prim of each of its triangle geometries.
struct SolidScene {
    scene: Scene,
    /// Per geometry id: the Foundry mesh prim, or [`CSG_GEOMETRY`] for the user geometry
    /// (whose hits carry the Foundry prim as `primID`).
    geometry_prims: Vec<u32>,
}

/// Marks the CSG user geometry in [`SolidScene::geometry_prims`].
const CSG_GEOMETRY: u32 = u32::MAX;

/// A scene prepared for Embree; borrows the [`CpuScene`] whose prims (CSG intersectors)
/// and navigation it uses.
pub struct EmbreeScene<'a> {
    cpu: &'a CpuScene<f32>,
    /// Top-level scene of a flat scene's instances or a hierarchy's roots.
    top: Option<GroupScene>,
    /// Per instance: the top-level scene of its daughters (hierarchies only).
    daughters: Vec<Option<GroupScene>>,
    /// The instances holding media, each an Embree instance of its solid's clusters.
    media: Option<GroupScene>,
    /// Per solid: its bottom-level scene, `None` for a solid without surfaces. Declared
    /// after the top-level scenes, which reference them, so they drop later.
    solids: Vec<Option<SolidScene>>,
    /// Per solid: the scene of its brick clusters, `None` for a solid without media.
    _cluster_scenes: Vec<Option<Scene>>,
    /// User data of the CSG user geometries (which point into it).
    _csg: Vec<CsgPrims<'a>>,
    /// User data of the cluster user geometries (which point into it).
    _clusters: Vec<ClusterBoxes<'a>>,
    _device: Device,
}

// SAFETY: after construction nothing is mutated; Embree's `rtcIntersect1` may be called
// from many threads at once on committed scenes, and the callbacks only read the shared
// `CsgPrims` and `CpuScene` (each call's mutable state lives in its own `TraceContext`).
unsafe impl Sync for EmbreeScene<'_> {}

impl<'a> EmbreeScene<'a> {
    /// Builds Embree's structures for the scene `cpu` was prepared from (`foundry`, for the
    /// mesh triangles and the instance transforms).
    pub fn new(foundry: &Foundry, cpu: &'a CpuScene<f32>) -> crate::Result<Self> {
        if foundry.inst.len() != cpu.instances() {
            bail!(
                "Embree: the Foundry has {} instances, the CPU scene {}",
                foundry.inst.len(),
                cpu.instances()
            );
        }
        let device = Device::new()?;
        // Built in full before any scene points into it, and never grown: the user
        // geometries' pointers to its elements stay valid while `self` lives.
        let csg = (0..foundry.solid.len())
            .map(|s| {
                CsgPrims::new(foundry, s, cpu.solid_prims(s))
                    .with_context(|| format!("Embree: solid {s}"))
            })
            .collect::<crate::Result<Vec<_>>>()?;
        let solids = csg
            .iter()
            .enumerate()
            .map(|(s, prims)| {
                solid_scene(&device, foundry, s, prims)
                    .with_context(|| format!("Embree: solid {s}"))
            })
            .collect::<crate::Result<Vec<_>>>()?;
        let clusters: Vec<ClusterBoxes> = (0..foundry.solid.len())
            .map(|s| ClusterBoxes::new(cpu.solid_clusters(s)))
            .collect();
        let cluster_scenes = clusters
            .iter()
            .map(|boxes| cluster_scene(&device, boxes))
            .collect::<crate::Result<Vec<_>>>()
            .context("Embree: brick clusters")?;
        let surfaces = |s: usize| solids[s].as_ref().map(|solid| &solid.scene);
        let group = |members: &[u32]| group_scene(&device, foundry, cpu, &surfaces, members);
        let top = group(cpu.top_members()).context("Embree: top-level scene")?;
        let daughters = (0..cpu.instances() as u32)
            .map(|i| {
                group(cpu.daughter_members(i))
                    .with_context(|| format!("Embree: daughters of instance {i}"))
            })
            .collect::<crate::Result<_>>()?;
        let media_of = |s: usize| cluster_scenes[s].as_ref();
        let media = group_scene(&device, foundry, cpu, &media_of, cpu.media_members())
            .context("Embree: media scene")?;
        Ok(EmbreeScene {
            cpu,
            top,
            daughters,
            media,
            solids,
            _cluster_scenes: cluster_scenes,
            _csg: csg,
            _clusters: clusters,
            _device: device,
        })
    }

    /// The first surface crossing with `tmin < t < tmax` of a ray with a unit direction,
    /// as [`CpuScene::trace`] answers it (up to ties and rounding). Fails only if one of
    /// our intersection callbacks panicked.
    pub fn trace(&self, ray: &Ray<f32>, tmin: f32, tmax: f32) -> crate::Result<Option<Hit<f32>>> {
        Ok(self.trace_noting(ray, tmin, tmax)?.0)
    }

    /// [`Self::trace`] and what it could not decide within its rounding, as
    /// [`CpuScene::trace_flagged`] flags it: starts near a surface, from the instance the
    /// origin was located in, and spans that CSG prims dropped, in the navigator's exit
    /// and in the user geometry's callbacks, not beyond the answer. Embree's own triangle
    /// tests report no doubt: a mesh hit is Embree's.
    pub fn trace_flagged(
        &self,
        ray: &Ray<f32>,
        tmin: f32,
        tmax: f32,
    ) -> crate::Result<Traced<f32>> {
        let (hit, located, dropped) = self.trace_noting(ray, tmin, tmax)?;
        let exact = Ray::<f64>::from_f64(ray.origin.to_f64(), ray.direction.to_f64());
        Ok(Traced {
            hit,
            flags: self
                .cpu
                .flags_for(&exact, tmin, located, dropped, hit.as_ref()),
        })
    }

    /// [`Self::trace`], where the origin was located, and the least world parameter at
    /// which a CSG prim decided within rounding (`+inf`: nowhere).
    fn trace_noting(
        &self,
        ray: &Ray<f32>,
        tmin: f32,
        tmax: f32,
    ) -> crate::Result<(Option<Hit<f32>>, Option<u32>, f32)> {
        let exact = Ray::<f64>::from_f64(ray.origin.to_f64(), ray.direction.to_f64());
        let located = self.cpu.locate_origin(exact.origin);
        let (exit, exit_dropped) = located.map_or((None, f32::INFINITY), |c| {
            self.cpu.exit_from(c, &exact, tmin, tmax)
        });
        let group = match located {
            Some(c) => self.daughters[c as usize].as_ref(),
            None => self.top.as_ref(),
        };
        let limit = exit.map_or(tmax, |h| h.t);
        let (entry, entry_dropped) = match group {
            Some(g) => self.enter(g, ray, tmin, limit)?,
            None => (None, f32::INFINITY),
        };
        let hit = entry.filter(|h| h.t < limit).or(exit).map(|mut h| {
            let frame = self.cpu.instance_frame(h.instance);
            h.normal = frame.normal_to_parent(h.normal).normalized();
            h
        });
        Ok((hit, located, exit_dropped.min(entry_dropped)))
    }

    /// Whether any surface crosses the ray with `tmin < t < tmax`, as
    /// [`CpuScene::occluded`] answers it: Embree's any-hit query (`rtcOccluded1`, which
    /// stops at the first crossing found) over the top-level instances, or, from inside an
    /// instance of a hierarchy, whether [`Self::trace`] finds a crossing. Fails only if one
    /// of our intersection callbacks panicked.
    pub fn occluded(&self, ray: &Ray<f32>, tmin: f32, tmax: f32) -> crate::Result<bool> {
        if self
            .cpu
            .locate_origin(V3::from_f64(ray.origin.to_f64()))
            .is_some()
        {
            return Ok(self.trace(ray, tmin, tmax)?.is_some());
        }
        // From outside every root, a crossing of a daughter comes after one of its mother,
        // so the top-level instances decide.
        let Some(group) = self.top.as_ref() else {
            return Ok(false);
        };
        // Embree's triangles accept `tnear <= t <= tfar`: the neighbouring floats make the
        // segment open, as the CPU's (an empty segment, `tnear > tfar`, meets nothing).
        let mut embree_ray = embree_ray(ray, tmin.next_up(), tmax.next_down());
        let mut ctx = self.context(group, ray);
        // SAFETY: the scene is committed and alive; `ctx` starts with the
        // `RTCIntersectContext` (repr(C)) and outlives the call, as does `embree_ray`.
        unsafe {
            ffi::rtcOccluded1(
                group.scene.raw(),
                &mut ctx as *mut TraceContext as *mut ffi::RTCIntersectContext,
                &mut embree_ray,
            )
        };
        if ctx.panicked.get() {
            bail!("Embree: an intersection callback panicked");
        }
        Ok(embree_ray.tfar == f32::NEG_INFINITY)
    }

    /// The first surface crossing with `tmin < t < tmax` of the ray `origin + t direction`
    /// (unit direction, world space) and the transmittance of `media` before it, as
    /// [`SceneMedia::trace_transmittance`] answers it, with Embree finding the surface
    /// crossing and the brick clusters the ray meets (a user geometry of clusters); the
    /// estimators and their random streams (`ray_index`) are the CPU's. `media` must have
    /// been opened on this scene's [`CpuScene`].
    pub fn trace_transmittance(
        &self,
        media: &SceneMedia<f32>,
        origin: [f64; 3],
        direction: [f64; 3],
        tmin: f64,
        tmax: f64,
        ray_index: u32,
    ) -> crate::Result<Transmitted<f32>> {
        let ray = Ray::from_f64(origin, direction);
        let hit = self.trace(&ray, tmin as f32, tmax as f32)?;
        let end = hit.map_or(tmax, |h| f64::from(h.t));
        let visits = self.cluster_visits(&ray, tmin, end)?;
        let (transmittance, lookups) =
            media.transmittance_with(origin, direction, tmin, end, visits, ray_index)?;
        Ok(Transmitted {
            hit,
            transmittance,
            lookups,
        })
    }

    /// Every brick cluster of a placed medium whose box the ray crosses within
    /// `[tmin, end]`: `(instance, medium, t0, t1)`, in Embree's order.
    pub fn cluster_visits(
        &self,
        ray: &Ray<f32>,
        tmin: f64,
        end: f64,
    ) -> crate::Result<Vec<(u32, u32, f64, f64)>> {
        let Some(group) = self.media.as_ref() else {
            return Ok(Vec::new());
        };
        let mut rayhit = ray_hit(ray, tmin as f32, end as f32);
        let mut ctx = MediaContext {
            base: ffi::RTCIntersectContext::default(),
            ray: *ray,
            members: &group.members,
            cpu: self.cpu,
            visits: RefCell::new(Vec::new()),
            panicked: Cell::new(false),
        };
        // SAFETY: the scene is committed and alive; `ctx` starts with the
        // `RTCIntersectContext` (repr(C)) and outlives the call, as does `rayhit`.
        unsafe {
            ffi::rtcIntersect1(
                group.scene.raw(),
                &mut ctx as *mut MediaContext as *mut ffi::RTCIntersectContext,
                &mut rayhit,
            )
        };
        if ctx.panicked.get() {
            bail!("Embree: a brick-cluster callback panicked");
        }
        Ok(ctx.visits.into_inner())
    }

    /// The context of one query on `group`'s scene.
    fn context<'s>(&'s self, group: &'s GroupScene, ray: &Ray<f32>) -> TraceContext<'s> {
        TraceContext {
            base: ffi::RTCIntersectContext::default(),
            ray: *ray,
            members: &group.members,
            cpu: self.cpu,
            panicked: Cell::new(false),
            dropped: Cell::new(f32::INFINITY),
        }
    }

    /// Embree's closest hit in `(tmin, tmax)` among a group's instances (normal in the
    /// instance's frame), and the least parameter at which a CSG prim it asked decided
    /// within rounding (`+inf`: nowhere).
    fn enter(
        &self,
        group: &GroupScene,
        ray: &Ray<f32>,
        tmin: f32,
        tmax: f32,
    ) -> crate::Result<(Option<Hit<f32>>, f32)> {
        let mut rayhit = ray_hit(ray, tmin, tmax);
        let mut ctx = self.context(group, ray);
        // SAFETY: the scene is committed and alive; `ctx` starts with the
        // `RTCIntersectContext` (repr(C)) and outlives the call, as does `rayhit`.
        unsafe {
            ffi::rtcIntersect1(
                group.scene.raw(),
                &mut ctx as *mut TraceContext as *mut ffi::RTCIntersectContext,
                &mut rayhit,
            )
        };
        if ctx.panicked.get() {
            bail!("Embree: an intersection callback panicked");
        }
        let dropped = ctx.dropped.get();
        let (r, h) = (&rayhit.ray, &rayhit.hit);
        if h.geom_id == ffi::RTC_INVALID_GEOMETRY_ID || !(r.tfar > tmin && r.tfar < tmax) {
            return Ok((None, dropped));
        }
        let solid = group
            .members
            .get(h.inst_id[0] as usize)
            .and_then(|&i| Some((i, self.solids[self.cpu.instance_solid(i)].as_ref()?)));
        let Some((instance, solid)) = solid else {
            bail!("Embree: hit an unknown instance id {}", h.inst_id[0]);
        };
        let prim = match solid.geometry_prims.get(h.geom_id as usize) {
            Some(&CSG_GEOMETRY) => h.prim_id,
            Some(&mesh) => mesh,
            None => bail!("Embree: hit an unknown geometry id {}", h.geom_id),
        };
        let hit = Hit {
            t: r.tfar,
            normal: V3::new(h.ng_x, h.ng_y, h.ng_z),
            instance,
            prim,
        };
        Ok((Some(hit), dropped))
    }
}

/// Embree's form of a ray over `[tnear, tfar]`.
fn embree_ray(ray: &Ray<f32>, tnear: f32, tfar: f32) -> ffi::RTCRay {
    let (o, d) = (ray.origin, ray.direction);
    ffi::RTCRay {
        org_x: o.x,
        org_y: o.y,
        org_z: o.z,
        tnear,
        dir_x: d.x,
        dir_y: d.y,
        dir_z: d.z,
        time: 0.0,
        tfar,
        mask: u32::MAX,
        id: 0,
        flags: 0,
    }
}

/// A ray over `[tnear, tfar]` with no hit yet, for `rtcIntersect1`.
fn ray_hit(ray: &Ray<f32>, tnear: f32, tfar: f32) -> ffi::RTCRayHit {
    ffi::RTCRayHit {
        ray: embree_ray(ray, tnear, tfar),
        hit: ffi::RTCHit {
            geom_id: ffi::RTC_INVALID_GEOMETRY_ID,
            inst_id: [ffi::RTC_INVALID_GEOMETRY_ID; ffi::RTC_MAX_INSTANCE_LEVEL_COUNT],
            ..Default::default()
        },
    }
}

/// The scene of a solid's brick clusters (one user geometry); `None` without clusters.
fn cluster_scene(device: &Device, boxes: &ClusterBoxes) -> crate::Result<Option<Scene>> {
    if boxes.is_empty() {
        return Ok(None);
    }
    let mut scene = Scene::new(device)?;
    scene.attach(boxes.geometry(device)?)?;
    scene.commit();
    device.check(|| "building a solid's cluster scene".into())?;
    Ok(Some(scene))
}

/// The bottom-level scene of solid `solid`: one triangle geometry per mesh prim and one user
/// geometry for its CSG prims; `None` when it has neither (volume-only solids).
fn solid_scene(
    device: &Device,
    foundry: &Foundry,
    solid: usize,
    csg: &CsgPrims,
) -> crate::Result<Option<SolidScene>> {
    let s = &foundry.solid[solid];
    let meshes: Vec<u32> = (s.prim_offset..s.prim_offset + s.num_prim)
        .filter(|&p| foundry.prim[p as usize].kind == PrimKind::Mesh as u32)
        .collect();
    if meshes.is_empty() && csg.is_empty() {
        return Ok(None);
    }
    let mut scene = Scene::new(device)?;
    let mut geometry_prims = Vec::new();
    for &p in &meshes {
        let triangles =
            mesh_triangles(foundry, p as usize).with_context(|| format!("mesh prim {p}"))?;
        scene.attach(triangle_geometry(device, &triangles)?)?;
        geometry_prims.push(p);
    }
    if !csg.is_empty() {
        scene.attach(csg.geometry(device)?)?;
        geometry_prims.push(CSG_GEOMETRY);
    }
    scene.commit();
    device.check(|| "building a solid's scene".into())?;
    Ok(Some(SolidScene {
        scene,
        geometry_prims,
    }))
}

/// The triangles of mesh prim `prim` in its solid's frame (the prim's own transform applied
/// in f64, as [`hytrace_csg::MeshPrim::from_foundry`] does), in f32.
fn mesh_triangles(foundry: &Foundry, prim: usize) -> crate::Result<Vec<[[f32; 3]; 3]>> {
    let p = &foundry.prim[prim];
    let transform = match p.transform {
        0 => Transform64::IDENTITY,
        k => *foundry
            .tran
            .get(k as usize - 1)
            .with_context(|| format!("transform {k} out of range"))?,
    };
    let range = p.item_offset as usize..(p.item_offset + p.item_count) as usize;
    let tris = foundry
        .tri
        .get(range)
        .context("triangle range out of bounds")?;
    Ok(tris
        .iter()
        .map(|t| {
            t.v.map(|v| {
                transform
                    .apply_point([v[0], v[1], v[2]].map(f64::from))
                    .map(|c| c as f32)
            })
        })
        .collect())
}

/// An Embree triangle geometry (unshared vertices; Embree's geometric normal is
/// `(v1 - v0) x (v2 - v0)`, as ours).
fn triangle_geometry(device: &Device, triangles: &[[[f32; 3]; 3]]) -> crate::Result<Geometry> {
    let g = Geometry::new(device, ffi::RTC_GEOMETRY_TYPE_TRIANGLE)?;
    let n = triangles.len();
    if n > (u32::MAX / 3) as usize {
        bail!("{n} triangles are more than Embree's 32-bit indices address");
    }
    // SAFETY: `g` is a new triangle geometry; Embree allocates the buffers (vertex buffers
    // padded past the last vertex as it requires) and returns them, or null on failure.
    let (vertices, indices) = unsafe {
        let v = ffi::rtcSetNewGeometryBuffer(
            g.raw(),
            ffi::RTC_BUFFER_TYPE_VERTEX,
            0,
            ffi::RTC_FORMAT_FLOAT3,
            12,
            3 * n,
        );
        let i = ffi::rtcSetNewGeometryBuffer(
            g.raw(),
            ffi::RTC_BUFFER_TYPE_INDEX,
            0,
            ffi::RTC_FORMAT_UINT3,
            12,
            n,
        );
        (v as *mut [f32; 3], i as *mut [u32; 3])
    };
    device.check(|| format!("allocating buffers for {n} triangles"))?;
    if vertices.is_null() || indices.is_null() {
        bail!("Embree: allocating buffers for {n} triangles failed");
    }
    // SAFETY: the buffers hold `3 n` float triples and `n` index triples, 4-byte aligned
    // (Embree aligns them to 16), and nothing else writes them until the commit.
    let (vertices, indices) = unsafe {
        (
            std::slice::from_raw_parts_mut(vertices, 3 * n),
            std::slice::from_raw_parts_mut(indices, n),
        )
    };
    for (k, t) in triangles.iter().enumerate() {
        vertices[3 * k..3 * k + 3].copy_from_slice(t);
        let first = 3 * k as u32;
        indices[k] = [first, first + 1, first + 2];
    }
    Ok(g)
}

/// The top-level scene over `members`, each an Embree instance of its solid's scene
/// (`scene_of(solid)`: its surfaces, or its brick clusters); `None` if no member's solid
/// has one.
fn group_scene<'s>(
    device: &Device,
    foundry: &Foundry,
    cpu: &CpuScene<f32>,
    scene_of: &dyn Fn(usize) -> Option<&'s Scene>,
    members: &[u32],
) -> crate::Result<Option<GroupScene>> {
    if members.is_empty() {
        return Ok(None);
    }
    let mut scene = Scene::new(device)?;
    let mut ids = Vec::with_capacity(members.len());
    for &i in members {
        let Some(solid_scene) = scene_of(cpu.instance_solid(i)) else {
            continue;
        };
        let rows = foundry.inst_tran[i as usize].to_transform().rows;
        let xfm: [f32; 12] = std::array::from_fn(|k| rows[k / 4][k % 4] as f32);
        let g = Geometry::new(device, ffi::RTC_GEOMETRY_TYPE_INSTANCE)?;
        // SAFETY: both handles are alive (the instance takes a reference to the solid's
        // scene); `xfm` is twelve floats, three rows of four, read during the call.
        unsafe {
            ffi::rtcSetGeometryInstancedScene(g.raw(), solid_scene.raw());
            ffi::rtcSetGeometryTransform(
                g.raw(),
                0,
                ffi::RTC_FORMAT_FLOAT3X4_ROW_MAJOR,
                xfm.as_ptr() as *const c_void,
            );
        }
        device.check(|| format!("placing instance {i}"))?;
        scene.attach(g)?;
        ids.push(i);
    }
    if ids.is_empty() {
        return Ok(None);
    }
    scene.commit();
    device.check(|| "building a top-level scene".into())?;
    Ok(Some(GroupScene {
        scene,
        members: ids,
    }))
}
