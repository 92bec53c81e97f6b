//! The GPU photon kernel (`shaders/kernels/photons.wgsl`): the photon scene's f32 tracer
//! uploaded as the scan uploads it, its physics flattened
//! ([`crate::photons::gpu_tables`]), one invocation per photon. Its CPU twin is the
//! propagator with the f32 tracer ([`crate::photons::tracer::Precision::F32`]);
//! `tests/gpu_photons.rs` compares them photon by photon. Photons whose loops ran out of
//! the driver's loop budget (llvmpipe only) are propagated again by that twin.

use std::ops::Range;
use std::time::Instant;

use rayon::prelude::*;

use super::compose::declared_constants;
use super::context::{compute_pipeline, whole_buffer_entries, GpuContext, GpuError};
use super::photon_records::{
    PhotonParams, PhotonRecord, PHOTON_DEPTH_LIMIT, PHOTON_DETECTED, PHOTON_LOOPS_CUT,
    PHOTON_SEVERAL_EMITTED, PHOTON_SOURCE_BEAM, PHOTON_SOURCE_GENSTEPS, PHOTON_SOURCE_POINT,
    PHOTON_SOURCE_SPHERE,
};
use super::timing::{finish_pass, GpuTimes, PassTimer};
use super::tracer::{binding_bytes, kernel_source, SceneUpload};
use crate::photons::gpu_tables::{kernel_features, GpuTables};
use crate::photons::output::{HitRow, RecordPoint, RECORD_COLUMNS};
use crate::photons::propagate::{drive_batches, BatchEnds, Emission, Emitting, PhotonEnd};
use crate::photons::sources::Source;
use crate::photons::{Batch, Origin, PhotonError, PhotonRun, PhotonScene, RunOptions, RunSummary};
use hytrace_foundry::UNSET;

const KERNEL: &str = "kernels/photons";
/// Photons per dispatch at most.
const BATCH: u64 = 1 << 20;
/// Storage buffers of the photon group (group 2).
const PHOTON_BINDINGS: u32 = 12;
/// Bytes of one step point (`--records`).
const POINT_BYTES: u64 = (RECORD_COLUMNS * size_of::<f32>()) as u64;
/// GPU memory a photon in flight takes (bytes): its packed history and room for its
/// record (every photon of a batch may be detected); `--records K` adds `K` step points.
pub const BYTES_PER_PHOTON: u64 = (size_of::<PhotonRecord>() + size_of::<[u32; 2]>()) as u64;

/// A photon scene on the GPU with its kernel.
pub struct GpuPhotons {
    pipeline: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
    scene_group: wgpu::BindGroup,
    /// The tables, materials, surfaces, instances and borders (bindings 1-6).
    tables: Vec<wgpu::Buffer>,
    hierarchical: bool,
    features: Vec<&'static str>,
    /// The table of the run's torch spectrum (`UNSET`: a fixed wavelength).
    spectrum: u32,
    /// The run's gensteps (binding 11).
    gensteps: wgpu::Buffer,
}

/// What a GPU photon run gives back.
pub struct GpuPhotonRun {
    /// The run's results, as the CPU gives them.
    pub run: PhotonRun,
    /// Where the time went; `redone_on_cpu` counts the photons the CPU twin propagated
    /// again.
    pub times: GpuTimes,
}

/// Where a GPU photon run's time went beyond the GPU's phases, and its batches.
#[derive(Clone, Copy, Debug, Default)]
pub struct PhotonHostWork {
    /// Seconds the host spent on the batches' results: the records put in photon order
    /// and turned into hit rows, the photons cut short propagated again on the CPU.
    pub host_s: f64,
    /// Photons a batch (each in flight at once on the GPU).
    pub batch: u64,
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
    /// Step points a photon.
    records: u32,
    timer: Option<PassTimer>,
    _bound: (wgpu::Buffer, wgpu::BindGroup),
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
        if scene.media.is_some() {
            return Err(GpuError::Unsupported(
                "photons: media (the scene's volumes) are not modelled by the photon kernel; \
                 --backend cpu propagates them"
                    .into(),
            ));
        }
        let upload = SceneUpload::new(ctx, f32_scene, "photons", PHOTON_BINDINGS)?;
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
        features.extend(kernel_features(&scene.tables, run));
        let source = kernel_source(KERNEL, &features)?;
        let constants = declared_constants(&source, &upload.constants);
        ctx.checked("building the photon kernel", || {
            let module = ctx.wgsl_module(KERNEL, &source);
            let layout = ctx.storage_layout("photons", PHOTON_BINDINGS, &[7, 8, 9, 10]);
            // Group 0 (the Foundry's own arrays) is not used.
            let pipeline_layout =
                ctx.pipeline_layout("photons", &[None, Some(&upload.layout), Some(&layout)]);
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
            // Likewise an empty list of gensteps (a torch run) as one zeroed record.
            let gensteps = ctx.input_buffer("photon gensteps", &binding_bytes(&gensteps));
            GpuPhotons {
                pipeline: compute_pipeline(
                    ctx,
                    &pipeline_layout,
                    &module,
                    "propagate_photons",
                    &constants,
                ),
                layout,
                scene_group: upload.group.clone(),
                tables,
                hierarchical: upload.hierarchical,
                features,
                spectrum,
                gensteps,
            }
        })
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
    /// through the results of the one before and the sink writes them.
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
        let mut flight: Option<InFlight> = None;
        let mut on_gpu = |range: Range<u64>, next: Option<Range<u64>>, emitting: &Emitting| {
            if flight.as_ref().map(|f| &f.range) != Some(&range) {
                flight =
                    Some(self.submit(ctx, run, emitting, &outputs, range.clone(), &mut times)?);
            }
            let done = flight.take().expect("the batch was submitted above");
            let back = self.finish(ctx, done, &outputs, &mut times)?;
            if let Some(next) = next {
                flight = Some(self.submit(ctx, run, emitting, &outputs, next, &mut times)?);
            }
            let t = Instant::now();
            let ends = ends(scene, run, emitting, range.start, back, &mut times);
            host.host_s += t.elapsed().as_secs_f64();
            Ok::<_, crate::Error>(ends)
        };
        let summary = drive_batches(scene, run, host.batch, &mut on_gpu, sink, progress)?;
        Ok((summary, times, host))
    }

    /// The output buffers of batches of `batch` photons with `k` step points each.
    fn outputs(&self, ctx: &GpuContext, batch: u64, k: u32) -> Result<Outputs, GpuError> {
        ctx.checked("photon output buffers", || Outputs {
            steps: ctx.output_buffer(
                "photon step points",
                (batch * u64::from(k)).max(1) * POINT_BYTES,
            ),
            records: ctx.output_buffer("photon records", batch * size_of::<PhotonRecord>() as u64),
            histories: ctx.output_buffer("photon histories", batch * size_of::<[u32; 2]>() as u64),
            count: ctx.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("photon record count"),
                size: 4,
                usage: wgpu::BufferUsages::STORAGE
                    | wgpu::BufferUsages::COPY_SRC
                    | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }),
        })
    }

    /// Submits the kernel on the photons `range` of `run`, writing into `outputs`.
    fn submit(
        &self,
        ctx: &GpuContext,
        run: &RunOptions,
        emitting: &Emitting,
        outputs: &Outputs,
        range: Range<u64>,
        times: &mut GpuTimes,
    ) -> crate::Result<InFlight> {
        let t0 = Instant::now();
        let mut params = params(run, &range, self.hierarchical);
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
            let mut buffers = vec![ctx.input_buffer("photon params", &binding_bytes(&[params]))];
            buffers.extend(self.tables.iter().cloned());
            buffers.extend(
                [
                    &outputs.records,
                    &outputs.histories,
                    &outputs.count,
                    &outputs.steps,
                    &self.gensteps,
                ]
                .map(Clone::clone),
            );
            let group = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("photons"),
                layout: &self.layout,
                entries: &whole_buffer_entries(&buffers),
            });
            ctx.queue
                .write_buffer(&outputs.count, 0, &0u32.to_le_bytes());
            ctx.submit_pass(
                "photons",
                &[&self.pipeline],
                &[(1, &self.scene_group), (2, &group)],
                (range.end - range.start) as u32,
                timer.as_ref(),
            );
            (buffers.swap_remove(0), group)
        })?;
        times.upload_s += t0.elapsed().as_secs_f64();
        Ok(InFlight {
            range,
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
        let n = done.range.end - done.range.start;
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
    let f = |v: crate::photons::V| v.to_f64().map(|c| c as f32);
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
