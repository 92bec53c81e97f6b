//! Where a batch's time goes: host wall clock of upload, kernels and readback, and the
//! kernels' own time from GPU timestamp queries where the device has them. Shared by every
//! kernel that runs rays in batches (the scan and the volume transmittance).

use std::time::Instant;

use super::context::{GpuContext, GpuError};

/// Seconds spent in each phase of a GPU run: wall clock on the host, and the kernels'
/// own time from GPU timestamps where the device has timestamp queries.
#[derive(Clone, Copy, Debug, Default)]
pub struct GpuTimes {
    /// Uploading rays (host).
    pub upload_s: f64,
    /// Running the kernels, submission to completion (host).
    pub kernel_s: f64,
    /// Reading results back (host).
    pub readback_s: f64,
    /// The kernels' pass on the GPU, from timestamp queries (`None` without them).
    pub kernel_gpu_s: Option<f64>,
    /// Items (rays, pixels) the CPU computed again because the driver's loop budget cut
    /// their loops short (llvmpipe only: `shaders/loop_budget.wgsl`).
    pub redone_on_cpu: u64,
    /// Photons whose wavelength-shifting absorption emitted several photons, propagated
    /// with them by the CPU twin (the photon kernel carries one photon).
    pub split_on_cpu: u64,
}

/// Timestamp queries written at the beginning and end of one compute pass.
pub struct PassTimer {
    set: wgpu::QuerySet,
    resolved: wgpu::Buffer,
}

impl PassTimer {
    /// The queries of one pass; `None` on devices without timestamp queries.
    pub fn new(ctx: &GpuContext, label: &str) -> Option<PassTimer> {
        let features = ctx.device.features();
        features.contains(wgpu::Features::TIMESTAMP_QUERY).then(|| {
            let set = ctx.device.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some(label),
                ty: wgpu::QueryType::Timestamp,
                count: 2,
            });
            let resolved = ctx.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: 16,
                usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            });
            PassTimer { set, resolved }
        })
    }

    /// What the pass descriptor needs to write the two timestamps.
    pub fn writes(&self) -> wgpu::ComputePassTimestampWrites<'_> {
        wgpu::ComputePassTimestampWrites {
            query_set: &self.set,
            beginning_of_pass_write_index: Some(0),
            end_of_pass_write_index: Some(1),
        }
    }

    /// Copies the timestamps where [`finish_batch`] reads them (after the pass, before
    /// the encoder is finished).
    pub fn resolve(&self, encoder: &mut wgpu::CommandEncoder) {
        encoder.resolve_query_set(&self.set, 0..2, &self.resolved, 0);
    }

    /// Seconds between the two timestamps.
    fn seconds(&self, ctx: &GpuContext) -> Result<f64, GpuError> {
        let ticks: Vec<u64> = bytemuck::pod_collect_to_vec(&ctx.read_buffer(&self.resolved, 16)?);
        let period_ns = f64::from(ctx.queue.get_timestamp_period());
        Ok(ticks[1].saturating_sub(ticks[0]) as f64 * period_ns * 1e-9)
    }
}

/// Waits for the batch `what`, just submitted (its upload began at `started`), reads the
/// first `size` bytes of `out` back and adds the batch's times to `times`.
pub fn finish_batch(
    ctx: &GpuContext,
    what: &str,
    started: Instant,
    out: &wgpu::Buffer,
    size: u64,
    timer: Option<&PassTimer>,
    times: &mut GpuTimes,
) -> Result<Vec<u8>, GpuError> {
    let submitted = Instant::now();
    wait(ctx, what)?;
    let done = Instant::now();
    let bytes = ctx.read_buffer(out, size)?;
    times.upload_s += (submitted - started).as_secs_f64();
    times.kernel_s += (done - submitted).as_secs_f64();
    times.readback_s += done.elapsed().as_secs_f64();
    add_gpu_seconds(ctx, timer, times)?;
    Ok(bytes)
}

/// Adds what every GPU command's `--stats` line reports: the adapter, the kernel's
/// composition features and the times (`gpu_upload_s`, `gpu_kernel_s`, `gpu_readback_s`,
/// `gpu_kernel_timestamps_s`: null where the device has no timestamp queries).
/// Warns on stderr when the CPU computed some of `total` `items` again
/// ([`GpuTimes::redone_on_cpu`]): the adapter's loop budget was too small for them.
pub fn warn_redone(adapter: &str, times: &GpuTimes, total: usize, items: &str) {
    if times.redone_on_cpu > 0 {
        eprintln!(
            "warning: on {adapter}, {} of {total} {items} ran out of the driver's loop budget \
             (65535 loop iterations per 8 invocations); the CPU computed them again",
            times.redone_on_cpu
        );
    }
}

pub fn add_gpu_stats(
    line: &mut serde_json::Value,
    adapter: &str,
    features: &[&str],
    times: &GpuTimes,
) {
    line["adapter"] = adapter.into();
    line["kernel_features"] = features.into();
    line["gpu_upload_s"] = times.upload_s.into();
    line["gpu_kernel_s"] = times.kernel_s.into();
    line["gpu_readback_s"] = times.readback_s.into();
    line["gpu_kernel_timestamps_s"] = times.kernel_gpu_s.into();
    line["gpu_redone_on_cpu"] = times.redone_on_cpu.into();
    line["gpu_split_on_cpu"] = times.split_on_cpu.into();
}

/// Waits until the GPU has finished the work submitted so far (`what` names it in errors).
fn wait(ctx: &GpuContext, what: &str) -> Result<(), GpuError> {
    ctx.device
        .poll(wgpu::PollType::wait_indefinitely())
        .map_err(|e| {
            ctx.check_not_lost().err().unwrap_or(GpuError::Operation {
                what: what.to_string(),
                problem: e.to_string(),
            })
        })?;
    Ok(())
}

/// Waits for the pass `what`, one of several of a batch, submitted at `submitted` (timed by
/// `timer`), and adds its kernel time to `times`; the batch's last pass goes through
/// [`finish_batch`] instead.
pub fn finish_pass(
    ctx: &GpuContext,
    what: &str,
    submitted: Instant,
    timer: Option<&PassTimer>,
    times: &mut GpuTimes,
) -> Result<(), GpuError> {
    wait(ctx, what)?;
    times.kernel_s += submitted.elapsed().as_secs_f64();
    add_gpu_seconds(ctx, timer, times)?;
    Ok(())
}

/// Adds the seconds `timer` measured to the kernels' GPU time.
fn add_gpu_seconds(
    ctx: &GpuContext,
    timer: Option<&PassTimer>,
    times: &mut GpuTimes,
) -> Result<(), GpuError> {
    if let Some(timer) = timer {
        times.kernel_gpu_s = Some(times.kernel_gpu_s.unwrap_or(0.0) + timer.seconds(ctx)?);
    }
    Ok(())
}
