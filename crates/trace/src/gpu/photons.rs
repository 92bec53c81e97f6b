//! The GPU photon kernel (`shaders/kernels/photons.wgsl`): the photon scene's f32 tracer
//! uploaded as the scan uploads it, its physics flattened
//! ([`crate::photons::gpu_tables`]), one invocation per photon. Its CPU twin is the
//! propagator with the f32 tracer ([`crate::photons::tracer::Precision::F32`]);
//! `tests/gpu_photons.rs` compares them photon by photon. Photons whose loops ran out of
//! the driver's loop budget (llvmpipe only) are propagated again by that twin.

use std::ops::Range;
use std::time::Instant;

use super::compose::declared_constants;
use super::context::{compute_pipeline, whole_buffer_entries, GpuContext, GpuError};
use super::photon_records::{
    PhotonParams, PhotonRecord, PHOTON_DEPTH_LIMIT, PHOTON_DETECTED, PHOTON_LOOPS_CUT,
    PHOTON_SEVERAL_EMITTED, PHOTON_SOURCE_BEAM, PHOTON_SOURCE_GENSTEPS, PHOTON_SOURCE_POINT,
    PHOTON_SOURCE_SPHERE,
};
use super::timing::{finish_batch, GpuTimes, PassTimer};
use super::tracer::{binding_bytes, kernel_source, SceneUpload};
use crate::photons::gpu_tables::{kernel_features, GpuTables};
use crate::photons::output::{History, HitRow, RecordPoint, RECORD_COLUMNS};
use crate::photons::propagate::{drive_batches, Emission, Emitting, PhotonEnd};
use crate::photons::sources::Source;
use crate::photons::{Batch, Origin, PhotonError, PhotonRun, PhotonScene, RunOptions, RunSummary};
use hytrace_foundry::UNSET;

const KERNEL: &str = "kernels/photons";
/// Photons per dispatch at most (records of 80 bytes: 84 MB).
const BATCH: u64 = 1 << 20;
/// Storage buffers of the photon group (group 2).
const PHOTON_BINDINGS: u32 = 10;
/// Bytes of one step point (`--records`).
const POINT_BYTES: u64 = (RECORD_COLUMNS * size_of::<f32>()) as u64;

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
    /// The run's gensteps (binding 9).
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
            let layout = ctx.storage_layout("photons", PHOTON_BINDINGS, &[7, 8]);
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
        let (summary, times) =
            self.propagate_into(ctx, scene, run, None, &mut |b| all.gather(b), progress)?;
        Ok(GpuPhotonRun {
            run: PhotonRun::of(all, summary),
            times,
        })
    }

    /// Propagates `run`'s photons through `scene` (the one the kernel was built for) at
    /// most `batch` a dispatch (by default as many as fill the GPU, up to 2^20), handing
    /// each batch's results to `sink` as it finishes
    /// ([`crate::photons::propagate_batches`] on the GPU); `progress` hears the photons
    /// done after each.
    pub fn propagate_into(
        &self,
        ctx: &GpuContext,
        scene: &PhotonScene,
        run: &RunOptions,
        batch: Option<u64>,
        sink: &mut dyn FnMut(Batch) -> Result<(), PhotonError>,
        progress: &dyn Fn(u64),
    ) -> crate::Result<(RunSummary, GpuTimes)> {
        let mut times = GpuTimes::default();
        // Batches fill a large GPU, within the binding limit of the records and step points.
        let record = (size_of::<PhotonRecord>() as u64).max(u64::from(run.records) * POINT_BYTES);
        let most = (ctx.limits.max_storage_buffer_binding_size / record).clamp(1, BATCH);
        let mut on_gpu =
            |range, emitting: &Emitting| self.batch(ctx, scene, run, range, emitting, &mut times);
        let size = batch.map_or(most, |b| b.min(most));
        let summary = drive_batches(scene, run, size, &mut on_gpu, sink, progress)?;
        Ok((summary, times))
    }

    /// One batch: the kernel's records turned into the photons' ends, those cut short
    /// propagated again on the CPU.
    fn batch(
        &self,
        ctx: &GpuContext,
        scene: &PhotonScene,
        run: &RunOptions,
        range: Range<u64>,
        emitting: &Emitting,
        times: &mut GpuTimes,
    ) -> crate::Result<Vec<PhotonEnd>> {
        let n = (range.end - range.start) as usize;
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
        let out_size = (n.max(1) * size_of::<PhotonRecord>()) as u64;
        let k = run.records as usize;
        let steps_size = (n * k).max(1) as u64 * POINT_BYTES;
        let t0 = Instant::now();
        let timer = PassTimer::new(ctx, "photon timestamps");
        let (out, _keep) = ctx.checked("photon dispatch", || {
            let mut buffers = vec![ctx.input_buffer("photon params", &binding_bytes(&[params]))];
            buffers.extend(self.tables.iter().cloned());
            buffers.push(ctx.output_buffer("photon records", out_size));
            buffers.push(ctx.output_buffer("photon step points", steps_size));
            buffers.push(self.gensteps.clone());
            let group = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("photons"),
                layout: &self.layout,
                entries: &whole_buffer_entries(&buffers),
            });
            ctx.submit_pass(
                "photons",
                &[&self.pipeline],
                &[(1, &self.scene_group), (2, &group)],
                n as u32,
                timer.as_ref(),
            );
            (buffers[7..9].to_vec(), (buffers, group))
        })?;
        let bytes = finish_batch(
            ctx,
            "photon kernel",
            t0,
            &out[0],
            out_size,
            timer.as_ref(),
            times,
        )?;
        let records: Vec<PhotonRecord> =
            bytemuck::pod_collect_to_vec(&bytes[..n * size_of::<PhotonRecord>()]);
        let points: Vec<RecordPoint> = if k > 0 {
            let t = Instant::now();
            let bytes = ctx.read_buffer(&out[1], steps_size)?;
            times.readback_s += t.elapsed().as_secs_f64();
            bytemuck::pod_collect_to_vec(&bytes)
        } else {
            Vec::new()
        };
        Ok(range
            .zip(records)
            .enumerate()
            .map(|(j, (index, r))| {
                if r.status & (PHOTON_LOOPS_CUT | PHOTON_DEPTH_LIMIT) != 0 {
                    times.redone_on_cpu += 1;
                    return scene.photon(index, run, emitting);
                }
                if r.status & PHOTON_SEVERAL_EMITTED != 0 {
                    times.split_on_cpu += 1;
                    return scene.photon(index, run, emitting);
                }
                PhotonEnd {
                    own: end_of(&r, index, &scene.copy),
                    further: Vec::new(),
                    record: points.get(j * k..(j + 1) * k).unwrap_or_default().to_vec(),
                }
            })
            .collect())
    }
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

/// A photon's history and hit row from its record.
fn end_of(r: &PhotonRecord, index: u64, copy: &[i32]) -> (History, Option<HitRow>) {
    let history = History {
        code: u64::from(r.history[0]) | (u64::from(r.history[1]) << 32),
        len: r.labels,
        mask: r.mask,
    };
    let hit = (r.status & PHOTON_DETECTED != 0).then(|| {
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
    });
    (history, hit)
}
