//! The GPU photon kernel (`shaders/kernels/photons.wgsl`): the photon scene's f32 tracer
//! uploaded as the scan uploads it, its physics flattened
//! ([`crate::photons::gpu_tables`]), one invocation per photon. Its CPU twin is the
//! propagator with the f32 tracer ([`crate::photons::tracer::Precision::F32`]);
//! `tests/gpu_photons.rs` compares them photon by photon. Photons whose loops ran out of
//! the driver's loop budget (llvmpipe only) are propagated again by that twin. A scene's
//! media are bound as the renderer binds them: their grids in the volume group (group 0,
//! [`super::render::media_group`]) and their placements as [`RenderMedium`] records. A
//! scene whose one medium is a brick store read as stored streams it through a brick pool
//! ([`super::streamed_store`]), in passes as the streamed render does: a photon that read an
//! absent brick runs again from its start once the brick is resident, so the results equal
//! bit for bit those of the store held whole.

use std::ops::Range;
use std::time::Instant;

use rayon::prelude::*;

use super::compose::declared_constants;
use super::context::{
    compute_pipeline, storage_layout_entry, uniform_layout_entry, GpuContext, GpuError,
};
use super::photon_records::{
    PhotonParams, PhotonRecord, PHOTON_DEPTH_LIMIT, PHOTON_DETECTED, PHOTON_LOOPS_CUT,
    PHOTON_MISSING_BRICK, PHOTON_SEVERAL_EMITTED, PHOTON_SOURCE_BEAM, PHOTON_SOURCE_GENSTEPS,
    PHOTON_SOURCE_POINT, PHOTON_SOURCE_SPHERE,
};
use super::records::RenderMedium;
use super::render::{media_group, placed_rows, tracking_params};
use super::streamed_store::{store_kernel_grid, PassSize, StorePool, StreamError, StreamStats};
use super::timing::{finish_pass, GpuTimes, PassTimer};
use super::tracer::{binding_bytes, kernel_source, SceneUpload};
use super::transmittance::{store_grid, KernelGrid, VolumeUpload};
use crate::photons::gpu_tables::{kernel_features, GpuTables};
use crate::photons::output::{HitRow, RecordPoint, RECORD_COLUMNS};
use crate::photons::propagate::{drive_batches, BatchEnds, Emission, Emitting, PhotonEnd};
use crate::photons::sources::Source;
use crate::photons::{Batch, Origin, PhotonError, PhotonRun, PhotonScene, RunOptions, RunSummary};
use hytrace_foundry::UNSET;
use hytrace_volume::{BrickStore, RangeMips, DEFAULT_STORE_BUDGET};

const KERNEL: &str = "kernels/photons";
/// Photons per dispatch at most.
const BATCH: u64 = 1 << 20;
/// Buffers of the photon group (group 2) every kernel binds: the parameters (a uniform
/// buffer, [`PARAMS_BINDING`]), the tables (1-6) and the outputs (7-9).
const PHOTON_BINDINGS: u32 = 10;
/// The binding of the parameters, the photon group's one uniform buffer.
const PARAMS_BINDING: u32 = 0;
/// The photon group's bindings a kernel binds when composed with a feature: the step
/// points, the gensteps, the placed media.
const FEATURE_BINDINGS: [(&str, u32); 3] = [("records", 10), ("gensteps", 11), ("media", 12)];
/// The photon group's bindings the kernel writes.
const WRITTEN: [u32; 4] = [7, 8, 9, 10];
/// Bytes of one step point (`--records`).
const POINT_BYTES: u64 = (RECORD_COLUMNS * size_of::<f32>()) as u64;
/// GPU memory a photon in flight takes (bytes): its packed history and room for its
/// record (every photon of a batch may be detected); `--records K` adds `K` step points.
pub const BYTES_PER_PHOTON: u64 = (size_of::<PhotonRecord>() + size_of::<[u32; 2]>()) as u64;

/// A photon scene on the GPU with its kernel.
pub struct GpuPhotons {
    pipeline: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
    /// The photon group's bindings the kernel declares.
    bindings: Vec<u32>,
    scene_group: wgpu::BindGroup,
    /// The tables, materials, surfaces, instances and borders (bindings 1-6).
    tables: Vec<wgpu::Buffer>,
    hierarchical: bool,
    features: Vec<&'static str>,
    /// The table of the run's torch spectrum (`UNSET`: a fixed wavelength).
    spectrum: u32,
    /// The run's gensteps (binding 11).
    gensteps: wgpu::Buffer,
    /// The placed media (binding 12; one zeroed record without).
    placed: wgpu::Buffer,
    /// The media's grids (group 0), when the scene has placed media.
    media_group: Option<MediaGroup>,
    /// Device bytes a streamed brick store's pool may take ([`GpuPhotons::with_memory`]).
    memory: u64,
    /// Upload a streamed store whole before a run ([`GpuPhotons::with_store_resident`]).
    resident_store: bool,
}

/// Where the photon kernel reads a scene's media grids (group 0).
enum MediaGrids {
    /// Every grid bricked in memory, in the volume group's shared arrays.
    InCore(VolumeUpload),
    /// The scene's one medium, a brick store read as stored, streamed through a brick pool
    /// each run sets up ([`StorePool`]).
    Streamed,
}

/// A scene's media as the photon kernel reads them: the grids with the trackers'
/// parameters, and every placement (in the CPU's instance order).
struct MediaUpload {
    grids: MediaGrids,
    params: wgpu::Buffer,
    placed: Vec<RenderMedium>,
}

impl MediaUpload {
    /// The media of `scene` uploaded (`None` without media). A medium read as stored in a
    /// brick store is streamed when it is the scene's only medium; beside others it is a
    /// [`GpuError::Unsupported`].
    fn new(ctx: &GpuContext, scene: &PhotonScene) -> Result<Option<MediaUpload>, GpuError> {
        let (Some(media), Some(f32_scene)) = (&scene.media, scene.tracer.f32_scene()) else {
            return Ok(None);
        };
        // `PhotonMedia::new` kept only placed media.
        let on = media.open().on(f32_scene);
        let count = on.medium_count() as u32;
        let stores = (0..count).filter(|&m| on.grid(m).store().is_some()).count();
        let (grids, uploaded) = match streamed_store(scene) {
            Some((store, mips)) => {
                let (grid, _) = store_grid(store_kernel_grid(store, mips))?;
                (MediaGrids::Streamed, vec![grid])
            }
            None if stores > 0 => {
                return Err(GpuError::Unsupported(format!(
                    "photons: the kernel streams one medium read as stored in a brick store, \
                     alone; this scene has {count} media, {stores} of them brick stores read as \
                     stored (--backend cpu propagates it, or give the stores a texel format)"
                )))
            }
            None => {
                let grids: Vec<KernelGrid> = (0..count)
                    .filter_map(|m| on.grid(m).bricked().map(KernelGrid::Bricked))
                    .collect();
                let volume = VolumeUpload::new(ctx, &grids)?;
                let uploaded = volume.grids.clone();
                (MediaGrids::InCore(volume), uploaded)
            }
        };
        let params: Vec<_> = (uploaded.iter().enumerate())
            .map(|(m, g)| tracking_params(g, Some(on.params(m as u32, 0).density_scale)))
            .collect();
        let scattering = media.scattering();
        let placed = on
            .placements()
            .map(|((_, medium), to_index)| {
                let s = scattering[medium as usize];
                RenderMedium {
                    rows: placed_rows(to_index, uploaded[medium as usize].shift),
                    emission: [0.0; 3],
                    volume: medium,
                    albedo: s.albedo as f32,
                    g: s.g as f32,
                    // The photon's own stream tracks every placement, as on the CPU.
                    seed: 0,
                    pad: 0,
                }
            })
            .collect();
        let params = ctx.checked("photon media", || {
            ctx.input_buffer("photon medium params", &binding_bytes(&params))
        })?;
        Ok(Some(MediaUpload {
            grids,
            params,
            placed,
        }))
    }

    /// Bindings of group 0 (a streamed store's levels of detail with `lods`).
    fn binding_count(&self, lods: bool) -> u32 {
        match &self.grids {
            MediaGrids::InCore(volume) => volume.binding_count(),
            MediaGrids::Streamed => 1 + StorePool::layout_entries(lods).len() as u32,
        }
    }
}

/// The brick store a photon run streams (the scene's one medium, read as stored) and the
/// range mips walks over it take (the CPU twin's).
fn streamed_store(scene: &PhotonScene) -> Option<(&BrickStore, &RangeMips)> {
    let open = scene.media.as_ref()?.open();
    (open.medium_count() == 1)
        .then(|| open.grid(0).store())
        .flatten()
}

/// The media's group 0 of a built kernel.
enum MediaGroup {
    /// Grids bricked in memory: their bind group.
    InCore(wgpu::BindGroup),
    /// A brick store streamed: the group's layout and the medium's parameters, bound
    /// beside the pool's buffers each pass, and whether the kernel reads the store's
    /// levels of detail (feature `stream_lods`).
    Streamed(wgpu::BindGroupLayout, wgpu::Buffer, bool),
}

/// What a GPU photon run gives back.
pub struct GpuPhotonRun {
    /// The run's results, as the CPU gives them.
    pub run: PhotonRun,
    /// Where the time went; `redone_on_cpu` counts the photons the CPU twin propagated
    /// again.
    pub times: GpuTimes,
}

/// Where a GPU photon run's time went beyond the GPU's phases, its batches and the
/// streaming of a medium read as stored.
#[derive(Clone, Copy, Debug, Default)]
pub struct PhotonHostWork {
    /// Seconds the host spent on the batches' results: the records put in photon order
    /// and turned into hit rows, the photons cut short propagated again on the CPU.
    pub host_s: f64,
    /// Photons a batch (each in flight at once on the GPU).
    pub batch: u64,
    /// What streaming a brick store through the brick pool did (its `deferred`: photon
    /// runs discarded for a missing brick), for a run that streamed one.
    pub stream: Option<StreamStats>,
}

/// The buffers every batch of a run writes (made once a run): the records appended, the
/// histories and the number of records.
struct Outputs {
    records: wgpu::Buffer,
    histories: wgpu::Buffer,
    count: wgpu::Buffer,
    /// The step points of `--records`, `K` a photon (one point without).
    steps: wgpu::Buffer,
}

/// A batch submitted to the GPU and not yet read back, with what it binds.
struct InFlight {
    range: Range<u64>,
    /// Photons the dispatch propagates (those of `range`, or those a streamed pass lists).
    count: u64,
    /// Step points a photon.
    records: u32,
    timer: Option<PassTimer>,
    _bound: (Vec<wgpu::Buffer>, wgpu::BindGroup),
}

/// A run's brick pool, with the kernel's group 0 layout and medium parameters its passes
/// bind beside it.
struct Streaming<'a> {
    pool: StorePool<'a>,
    layout: &'a wgpu::BindGroupLayout,
    params: &'a wgpu::Buffer,
    /// The kernel reads the store's levels of detail.
    lods: bool,
}

/// What a batch's kernel gives back: every photon's packed history, and the records of
/// the photons detected or cut short, in the order they finished.
struct Readback {
    histories: Vec<u64>,
    records: Vec<PhotonRecord>,
    /// Every photon's step points, when asked for.
    points: Vec<RecordPoint>,
}

impl GpuPhotons {
    /// Uploads `scene` (prepared with the f32 tracer) and compiles its photon kernel for
    /// runs like `run`. Physics or options the kernel does not model, in the scene or in
    /// `run`, are a [`GpuError::Unsupported`] naming them.
    pub fn new(
        ctx: &GpuContext,
        scene: &PhotonScene,
        run: &RunOptions,
    ) -> Result<GpuPhotons, GpuError> {
        let Some(f32_scene) = scene.tracer.f32_scene() else {
            return Err(GpuError::Unsupported(
                "photons: the scene was prepared with the f64 tracer (the kernel's twin is f32)"
                    .into(),
            ));
        };
        let media = MediaUpload::new(ctx, scene)?;
        let physics = kernel_features(&scene.tables, media.is_some(), run);
        // Only the bindings the kernel declares: a device may allow as few as 32 storage
        // buffers a stage (lavapipe), which a streamed medium's pool comes close to.
        let mut bindings: Vec<u32> = (0..PHOTON_BINDINGS).collect();
        bindings.extend(
            (FEATURE_BINDINGS.iter())
                .filter(|(feature, _)| physics.contains(feature))
                .map(|&(_, binding)| binding),
        );
        // Storage buffers: the photon group's but the parameters, and the media's.
        let kernel_bindings =
            |lods| bindings.len() as u32 - 1 + media.as_ref().map_or(0, |m| m.binding_count(lods));
        // A streamed store's coarser levels of detail stand in for its absent bricks where
        // the device has a binding to spare (a pass's paths then stay close to those through
        // the bricks they lack, which they request); else the background does.
        let streamed = matches!(media.as_ref().map(|m| &m.grids), Some(MediaGrids::Streamed));
        let mut lods = streamed;
        let upload = match SceneUpload::new(ctx, f32_scene, "photons", kernel_bindings(lods)) {
            Err(GpuError::SceneTooBig(_)) if lods => {
                lods = false;
                SceneUpload::new(ctx, f32_scene, "photons", kernel_bindings(false))?
            }
            upload => upload?,
        };
        let mut flat = GpuTables::new(scene);
        // A torch spectrum that does not resolve is left to the run, which names it.
        let spectrum = match &run.origin {
            Origin::Torch { wavelength, .. } => match scene.emission(wavelength) {
                Ok(Emission::Spectrum(s)) => flat.push_spectrum(&s),
                _ => UNSET,
            },
            Origin::Gensteps(_) => UNSET,
        };
        // Gensteps that do not resolve are likewise left to the run.
        let gensteps = match scene.emitting(&run.origin) {
            Ok(Emitting::Gensteps(g)) => g
                .gpu_records(&mut flat)
                .map_err(|why| GpuError::Unsupported(format!("photons: gensteps: {why}")))?,
            _ => Vec::new(),
        };
        let mut features = upload.features.clone();
        features.extend(physics);
        let mut constants = upload.constants.clone();
        match media.as_ref().map(|m| &m.grids) {
            Some(MediaGrids::InCore(volume)) => {
                let (chunked, volume_constants) = volume.kernel_options();
                features.extend(chunked);
                constants.extend(volume_constants);
            }
            Some(MediaGrids::Streamed) => {
                features.push("streamed");
                if lods {
                    features.push("stream_lods");
                }
            }
            None => {}
        }
        let source = kernel_source(KERNEL, &features)?;
        let constants = declared_constants(&source, &constants);
        ctx.checked("building the photon kernel", || {
            let module = ctx.wgsl_module(KERNEL, &source);
            let entries: Vec<_> = (bindings.iter())
                .map(|&b| match b {
                    PARAMS_BINDING => uniform_layout_entry(b),
                    _ => storage_layout_entry(b, !WRITTEN.contains(&b)),
                })
                .collect();
            let layout = ctx
                .device
                .create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                    label: Some("photons"),
                    entries: &entries,
                });
            // Group 0 holds the media's grids (the Foundry's own arrays are not used).
            let media_group = media.as_ref().map(|m| match &m.grids {
                MediaGrids::InCore(volume) => {
                    let (layout, group) = media_group(ctx, volume, &m.params, None);
                    (layout, MediaGroup::InCore(group))
                }
                MediaGrids::Streamed => {
                    let layout = StorePool::group_layout(ctx, "streamed photon medium", lods);
                    (
                        layout.clone(),
                        MediaGroup::Streamed(layout, m.params.clone(), lods),
                    )
                }
            });
            let pipeline_layout = ctx.pipeline_layout(
                "photons",
                &[
                    media_group.as_ref().map(|(layout, _)| layout),
                    Some(&upload.layout),
                    Some(&layout),
                ],
            );
            let tables = vec![
                ctx.input_buffer("photon tables", &binding_bytes(&flat.tables)),
                ctx.input_buffer("photon rows", &binding_bytes(&flat.rows)),
                ctx.input_buffer("photon materials", &binding_bytes(&flat.materials)),
                ctx.input_buffer("photon surfaces", &binding_bytes(&flat.surfaces)),
                ctx.input_buffer("photon instances", &binding_bytes(&flat.lookup.instances)),
                // An empty list is uploaded as one zeroed record, which the kernel
                // searches: it names a crossing from instance 0 into itself, which never
                // happens.
                ctx.input_buffer("photon borders", &binding_bytes(&flat.lookup.borders)),
            ];
            // Likewise an empty list of gensteps (a torch run) and of placed media.
            let gensteps = ctx.input_buffer("photon gensteps", &binding_bytes(&gensteps));
            let placed = media.as_ref().map_or(&[][..], |m| &m.placed[..]);
            let placed = ctx.input_buffer("photon media", &binding_bytes(placed));
            GpuPhotons {
                pipeline: compute_pipeline(
                    ctx,
                    &pipeline_layout,
                    &module,
                    "propagate_photons",
                    &constants,
                ),
                layout,
                bindings: bindings.clone(),
                scene_group: upload.group.clone(),
                tables,
                hierarchical: upload.hierarchical,
                features,
                spectrum,
                gensteps,
                placed,
                media_group: media_group.map(|(_, group)| group),
                memory: DEFAULT_STORE_BUDGET,
                resident_store: false,
            }
        })
    }

    /// This kernel streaming a medium read as stored through a brick pool of at most
    /// `bytes` of device memory (its range mips, page table, request buffer and slots;
    /// [`DEFAULT_STORE_BUDGET`] by default). A budget that cannot hold one superchunk's
    /// bricks fails the run with [`StreamError::Budget`].
    pub fn with_memory(mut self, bytes: u64) -> Self {
        self.memory = bytes;
        self
    }

    /// This kernel uploading a streamed brick store whole before a run: the in-core
    /// reference of a streamed run (the memory budget must hold every kept brick).
    pub fn with_store_resident(mut self) -> Self {
        self.resident_store = true;
        self
    }

    /// The composition features of the kernel.
    pub fn features(&self) -> &[&'static str] {
        &self.features
    }

    /// Photons a batch for runs asking for at most `batch` a dispatch and `records` step
    /// points a photon: by default as many as fill the GPU, up to 2^20, within the
    /// device's binding limit for the records and the step points.
    pub fn batch_size(ctx: &GpuContext, batch: Option<u64>, records: u32) -> u64 {
        let record = (size_of::<PhotonRecord>() as u64).max(u64::from(records) * POINT_BYTES);
        let most = (ctx.limits.max_storage_buffer_binding_size / record).clamp(1, BATCH);
        batch.map_or(most, |b| b.min(most))
    }

    /// Propagates `run`'s photons through `scene` (the one the kernel was built for), in
    /// batches, gathering their results; `progress` hears the photons done after each.
    pub fn propagate(
        &self,
        ctx: &GpuContext,
        scene: &PhotonScene,
        run: &RunOptions,
        progress: &dyn Fn(u64),
    ) -> crate::Result<GpuPhotonRun> {
        let mut all = Batch::default();
        let (summary, times, _) =
            self.propagate_into(ctx, scene, run, None, &mut |b| all.gather(b), progress)?;
        Ok(GpuPhotonRun {
            run: PhotonRun::of(all, summary),
            times,
        })
    }

    /// Propagates `run`'s photons through `scene` (the one the kernel was built for)
    /// [`GpuPhotons::batch_size`] a dispatch, handing each batch's results to `sink` as it
    /// finishes ([`crate::photons::propagate_batches`] on the GPU); `progress` hears the
    /// photons done after each. The next batch runs on the GPU while the host works
    /// through the results of the one before and the sink writes them. A medium read as
    /// stored is streamed through a brick pool of [`GpuPhotons::with_memory`] bytes, each
    /// batch in passes: a photon that read an absent brick runs again from its start once
    /// the brick is resident.
    pub fn propagate_into(
        &self,
        ctx: &GpuContext,
        scene: &PhotonScene,
        run: &RunOptions,
        batch: Option<u64>,
        sink: &mut dyn FnMut(Batch) -> Result<(), PhotonError>,
        progress: &dyn Fn(u64),
    ) -> crate::Result<(RunSummary, GpuTimes, PhotonHostWork)> {
        let mut times = GpuTimes::default();
        let mut host = PhotonHostWork {
            batch: Self::batch_size(ctx, batch, run.records),
            ..Default::default()
        };
        // Room for the run's largest batch (wgpu clears a buffer before its first use); a
        // batch of 0 is refused by the batches' loop, before any buffer is bound.
        let outputs = self.outputs(ctx, host.batch.min(run.photons).max(1), run.records)?;
        let mut streaming = self.streaming(ctx, scene)?;
        let mut flight: Option<InFlight> = None;
        let mut on_gpu = |range: Range<u64>, next: Option<Range<u64>>, emitting: &Emitting| {
            let back = match &mut streaming {
                Some(streaming) => {
                    self.passes(ctx, run, emitting, &outputs, &range, streaming, &mut times)?
                }
                None => {
                    if flight.as_ref().map(|f| &f.range) != Some(&range) {
                        flight = Some(self.submit(
                            ctx,
                            run,
                            emitting,
                            &outputs,
                            range.clone(),
                            None,
                            &mut times,
                        )?);
                    }
                    let done = flight.take().expect("the batch was submitted above");
                    let back = self.finish(ctx, done, &outputs, &mut times)?;
                    if let Some(next) = next {
                        flight = Some(
                            self.submit(ctx, run, emitting, &outputs, next, None, &mut times)?,
                        );
                    }
                    back
                }
            };
            let t = Instant::now();
            let ends = ends(scene, run, emitting, range.start, back, &mut times);
            // The CPU twin read a stored medium for the photons it propagated again.
            if let Some(media) = &scene.media {
                media.check_reads(&scene.tracer)?;
            }
            host.host_s += t.elapsed().as_secs_f64();
            Ok::<_, crate::Error>(ends)
        };
        let summary = drive_batches(scene, run, host.batch, &mut on_gpu, sink, progress)?;
        host.stream = streaming.map(|s| s.pool.stats());
        Ok((summary, times, host))
    }

    /// The brick pool a run streams its medium read as stored through, when the kernel
    /// was built to stream one: set up in the kernel's memory budget, and filled with the
    /// whole store for [`GpuPhotons::with_store_resident`].
    fn streaming<'a>(
        &'a self,
        ctx: &GpuContext,
        scene: &'a PhotonScene,
    ) -> crate::Result<Option<Streaming<'a>>> {
        let Some(MediaGroup::Streamed(layout, params, lods)) = &self.media_group else {
            return Ok(None);
        };
        let (store, mips) = streamed_store(scene).ok_or_else(|| GpuError::Operation {
            what: "photons".into(),
            problem: "the kernel was built to stream a brick store this scene lacks".into(),
        })?;
        let mut pool = StorePool::new(ctx, store, mips, self.memory)?;
        if self.resident_store {
            pool.make_resident(ctx)?;
        }
        Ok(Some(Streaming {
            pool,
            layout,
            params,
            lods: *lods,
        }))
    }

    /// The photons `range` of `run` through a brick store streamed by `streaming`, in
    /// passes: a pass runs the pending photons (all of them at first); a photon that read
    /// a brick the pool lacked is discarded and runs again from its start in a later pass
    /// (photon `i` draws the stream `(seed, i)`, so it takes the same path), after the
    /// host uploaded the bricks the pass requested. The results come back in photon order
    /// as one dispatch with the whole store resident gives them, bit for bit. Pass sizes
    /// halve while a pass finishes no photon and places no brick; a photon that alone
    /// needs more bricks than the pool holds is a [`StreamError::PoolTooSmall`].
    #[allow(clippy::too_many_arguments)]
    fn passes(
        &self,
        ctx: &GpuContext,
        run: &RunOptions,
        emitting: &Emitting,
        outputs: &Outputs,
        range: &Range<u64>,
        streaming: &mut Streaming,
        times: &mut GpuTimes,
    ) -> crate::Result<Readback> {
        let n = (range.end - range.start) as usize;
        let k = run.records as usize;
        let mut back = Readback {
            histories: vec![0; n],
            records: Vec::new(),
            points: vec![[0.0; RECORD_COLUMNS]; n * k],
        };
        let mut pending: Vec<u32> = (0..n as u32).collect();
        let mut size = PassSize::new(n);
        let Streaming {
            pool,
            layout,
            params,
            lods,
        } = streaming;
        while !pending.is_empty() {
            let pass = pool.begin_pass(ctx)?;
            let listed = &pending[..size.of(pending.len())];
            let group = pool.group(ctx, layout, "streamed photon medium", params, *lods);
            let done = self.submit(
                ctx,
                run,
                emitting,
                outputs,
                range.clone(),
                Some((listed, &group)),
                times,
            )?;
            let got = self.finish(ctx, done, outputs, times)?;
            // The kernel's slots are the listed photons' places in `listed`.
            let mut missing = vec![false; listed.len()];
            for r in got.records.iter() {
                if r.status & PHOTON_MISSING_BRICK != 0 {
                    missing[r.photon as usize] = true;
                }
            }
            for (j, &p) in listed.iter().enumerate().filter(|(j, _)| !missing[*j]) {
                let p = p as usize;
                back.histories[p] = got.histories[j];
                back.points[p * k..(p + 1) * k].copy_from_slice(&got.points[j * k..(j + 1) * k]);
            }
            let finished = got
                .records
                .into_iter()
                .filter(|r| !missing[r.photon as usize]);
            back.records.extend(finished.map(|mut r| {
                r.photon = listed[r.photon as usize];
                r
            }));
            let deferred: Vec<u32> = (listed.iter().zip(&missing))
                .filter(|(_, &m)| m)
                .map(|(&p, _)| p)
                .collect();
            let finished = listed.len() - deferred.len();
            let rest = pending[listed.len()..].to_vec();
            pool.defer(deferred.len());
            let placed = pool.end_pass(ctx, pass)?;
            // The photons not run this pass stay after the deferred ones.
            pending = deferred;
            pending.extend(rest);
            if size.stuck_after(finished, placed) {
                return Err(StreamError::PoolTooSmall {
                    item: format!("photon {}", range.start + u64::from(pending[0])),
                    slots: pool.slots(),
                }
                .into());
            }
        }
        Ok(back)
    }

    /// The output buffers of batches of `batch` photons with `k` step points each.
    fn outputs(&self, ctx: &GpuContext, batch: u64, k: u32) -> Result<Outputs, GpuError> {
        // Outputs the host also writes: the record count (reset each batch), the histories
        // (a streamed pass's photons) and the step points (cleared each batch).
        let written = |label: &str, size: u64| {
            ctx.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size,
                usage: wgpu::BufferUsages::STORAGE
                    | wgpu::BufferUsages::COPY_SRC
                    | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        };
        ctx.checked("photon output buffers", || Outputs {
            steps: written(
                "photon step points",
                (batch * u64::from(k)).max(1) * POINT_BYTES,
            ),
            records: ctx.output_buffer("photon records", batch * size_of::<PhotonRecord>() as u64),
            histories: written("photon histories", batch * size_of::<[u32; 2]>() as u64),
            count: written("photon record count", 4),
        })
    }

    /// Submits the kernel on the photons `range` of `run`, writing into `outputs`; in a
    /// streamed pass on the photons `listed` (offsets from the range's start) alone, with
    /// the pass's group 0.
    #[allow(clippy::too_many_arguments)]
    fn submit(
        &self,
        ctx: &GpuContext,
        run: &RunOptions,
        emitting: &Emitting,
        outputs: &Outputs,
        range: Range<u64>,
        pass: Option<(&[u32], &wgpu::BindGroup)>,
        times: &mut GpuTimes,
    ) -> crate::Result<InFlight> {
        let t0 = Instant::now();
        let mut params = params(run, &range, self.hierarchical);
        if let Some((listed, _)) = pass {
            params.photon_count = listed.len() as u32;
        }
        let group0 = match (pass, &self.media_group) {
            (Some((_, group)), _) => Some(group),
            (None, Some(MediaGroup::InCore(group))) => Some(group),
            (None, _) => None,
        };
        match emitting {
            Emitting::Torch { source, emission } => {
                torch(&mut params, *source);
                if let Emission::Fixed { energy, nm } = *emission {
                    params.energy = energy as f32;
                    params.wavelength_nm = nm as f32;
                }
                params.spectrum = self.spectrum;
            }
            Emitting::Gensteps(_) => params.source_kind = PHOTON_SOURCE_GENSTEPS,
        }
        let timer = PassTimer::new(ctx, "photon timestamps");
        let bound = ctx.checked("photon dispatch", || {
            let mut buffers =
                vec![ctx.uniform_buffer("photon params", bytemuck::bytes_of(&params))];
            buffers.extend(self.tables.iter().cloned());
            buffers.extend(
                [
                    &outputs.records,
                    &outputs.histories,
                    &outputs.count,
                    &outputs.steps,
                    &self.gensteps,
                    &self.placed,
                ]
                .map(Clone::clone),
            );
            let entries: Vec<_> = (self.bindings.iter())
                .map(|&b| wgpu::BindGroupEntry {
                    binding: b,
                    resource: buffers[b as usize].as_entire_binding(),
                })
                .collect();
            let group = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("photons"),
                layout: &self.layout,
                entries: &entries,
            });
            if let Some((listed, _)) = pass {
                // A pass's photons go in through their history slots, which the kernel
                // reads before it writes them.
                let slots: Vec<[u32; 2]> = listed.iter().map(|&p| [p, 0]).collect();
                (ctx.queue).write_buffer(&outputs.histories, 0, bytemuck::cast_slice(&slots));
            }
            ctx.queue
                .write_buffer(&outputs.count, 0, &0u32.to_le_bytes());
            // The kernel writes a photon's step points up to its end: the rest of its K
            // must read zero, not a point of the batch or pass before.
            let points = u64::from(params.photon_count) * u64::from(run.records) * POINT_BYTES;
            if points > 0 {
                let mut encoder = ctx.device.create_command_encoder(&Default::default());
                encoder.clear_buffer(&outputs.steps, 0, Some(points));
                ctx.queue.submit([encoder.finish()]);
            }
            ctx.submit_pass(
                "photons",
                &[&self.pipeline],
                &group0
                    .iter()
                    .map(|g| (0, *g))
                    .chain([(1, &self.scene_group), (2, &group)])
                    .collect::<Vec<_>>(),
                params.photon_count,
                timer.as_ref(),
            );
            (buffers, group)
        })?;
        times.upload_s += t0.elapsed().as_secs_f64();
        Ok(InFlight {
            range,
            count: u64::from(params.photon_count),
            records: run.records,
            timer,
            _bound: bound,
        })
    }

    /// Waits for the batch `done` and reads back its histories and records.
    fn finish(
        &self,
        ctx: &GpuContext,
        done: InFlight,
        outputs: &Outputs,
        times: &mut GpuTimes,
    ) -> Result<Readback, GpuError> {
        // Timed from now: the kernel's time the host's work did not hide.
        finish_pass(
            ctx,
            "photon kernel",
            Instant::now(),
            done.timer.as_ref(),
            times,
        )?;
        let t = Instant::now();
        let n = done.count;
        let count: u32 = bytemuck::pod_read_unaligned(&ctx.read_buffer(&outputs.count, 4)?);
        let words: Vec<[u32; 2]> = bytemuck::pod_collect_to_vec(
            &ctx.read_buffer(&outputs.histories, n * size_of::<[u32; 2]>() as u64)?,
        );
        let records = match u64::from(count) * size_of::<PhotonRecord>() as u64 {
            0 => Vec::new(),
            bytes => bytemuck::pod_collect_to_vec(&ctx.read_buffer(&outputs.records, bytes)?),
        };
        let k = u64::from(done.records);
        let points = match n * k * POINT_BYTES {
            0 => Vec::new(),
            bytes => bytemuck::pod_collect_to_vec(&ctx.read_buffer(&outputs.steps, bytes)?),
        };
        times.readback_s += t.elapsed().as_secs_f64();
        Ok(Readback {
            points,
            histories: words
                .into_iter()
                .map(|[lo, hi]| u64::from(lo) | (u64::from(hi) << 32))
                .collect(),
            records,
        })
    }
}

/// The ends of a batch's photons (the first `first`) from what its kernel gave back: the
/// records put in photon order, those detected turned into hit rows, those cut short or
/// whose wavelength-shifting absorption emitted several photons propagated again by the
/// CPU twin (in parallel), their step points in place of the kernel's.
fn ends(
    scene: &PhotonScene,
    run: &RunOptions,
    emitting: &Emitting,
    first: u64,
    back: Readback,
    times: &mut GpuTimes,
) -> BatchEnds {
    let Readback {
        mut histories,
        mut records,
        points,
    } = back;
    records.sort_unstable_by_key(|r| r.photon);
    let again_on_cpu = PHOTON_LOOPS_CUT | PHOTON_DEPTH_LIMIT | PHOTON_SEVERAL_EMITTED;
    let cut = |r: &PhotonRecord| r.status & again_on_cpu != 0;
    // Threads only where some photon is to be propagated again.
    let again: Vec<Option<PhotonEnd>> = if records.iter().any(cut) {
        records
            .par_iter()
            .map(|r| cut(r).then(|| scene.photon(first + u64::from(r.photon), run, emitting)))
            .collect()
    } else {
        Vec::new()
    };
    let mut again = again.into_iter();
    let k = run.records as usize;
    let mut out = BatchEnds {
        records: points,
        ..BatchEnds::default()
    };
    for r in &records {
        match again.next().flatten() {
            Some(mut end) => {
                if r.status & PHOTON_SEVERAL_EMITTED != 0 {
                    times.split_on_cpu += 1;
                } else {
                    times.redone_on_cpu += 1;
                }
                let p = r.photon as usize;
                let points = std::mem::take(&mut end.record);
                if k > 0 {
                    out.records[p * k..(p + 1) * k].copy_from_slice(&points);
                }
                histories[p] = out.add_lineages(end);
            }
            None if r.status & PHOTON_DETECTED != 0 => {
                out.hits
                    .push(hit_row(r, first + u64::from(r.photon), &scene.copy));
            }
            None => {}
        }
    }
    out.histories = histories;
    out
}

/// The kernel's parameters for the photons `range` of `run` (the source's are added by
/// [`torch`]).
fn params(run: &RunOptions, range: &Range<u64>, hierarchical: bool) -> PhotonParams {
    PhotonParams {
        first_lo: range.start as u32,
        first_hi: (range.start >> 32) as u32,
        photon_count: (range.end - range.start) as u32,
        seed: run.seed,
        max_steps: run.max_steps,
        hierarchical: u32::from(hierarchical),
        probe_trips: 2,
        records: run.records,
        cos_divergence: 1.0,
        spectrum: UNSET,
        ..Default::default()
    }
}

/// Sets the torch `source` in the parameters `p`.
fn torch(p: &mut PhotonParams, source: Source) {
    let f = |v: crate::photons::V| {
        let [x, y, z] = v.to_f64();
        [x as f32, y as f32, z as f32, 0.0]
    };
    match source {
        Source::Point { position } => {
            p.source_kind = PHOTON_SOURCE_POINT;
            p.source_at = f(position);
        }
        Source::Beam {
            centre,
            direction,
            radius,
            cos_divergence,
        } => {
            p.source_kind = PHOTON_SOURCE_BEAM;
            p.source_at = f(centre);
            p.source_direction = f(direction);
            p.source_radius = radius as f32;
            p.cos_divergence = cos_divergence as f32;
        }
        Source::Sphere {
            centre,
            radius,
            inward,
        } => {
            p.source_kind = PHOTON_SOURCE_SPHERE;
            p.source_at = f(centre);
            p.source_radius = radius as f32;
            p.inward = u32::from(inward);
        }
    }
}

/// The hit row of a detected photon's record.
fn hit_row(r: &PhotonRecord, index: u64, copy: &[i32]) -> HitRow {
    let [x, y, z] = r.position.map(f64::from);
    let [dx, dy, dz] = r.direction.map(f64::from);
    let [px, py, pz] = r.polarization.map(f64::from);
    HitRow([
        x,
        y,
        z,
        f64::from(r.time),
        dx,
        dy,
        dz,
        f64::from(r.wavelength),
        px,
        py,
        pz,
        f64::from(r.instance),
        f64::from(copy[r.instance as usize]),
        index as f64,
        f64::from(r.mask),
        f64::from(r.steps),
    ])
}
