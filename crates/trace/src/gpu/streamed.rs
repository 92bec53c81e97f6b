//! GPU transmittance through a brick store larger than the device's memory budget, read
//! through a brick pool ([`super::streamed_store`]).
//!
//! Rays run in passes. A ray that read an absent brick is marked missing: its answer is
//! discarded and it runs again in a later pass, after the host has read the requested
//! bricks from the store and uploaded them, so every answer is computed with all its bricks
//! resident and equals, bit for bit, the answer of the same kernel with the whole store
//! resident. When a pass finishes no ray and places no brick (the pending rays need more
//! bricks together than the pool holds), the next pass runs half as many rays, down to one;
//! a ray that alone needs more bricks than the pool holds is an error.
//!
//! The CPU twin is [`hytrace_volume::transmittance_batch`] on the [`BrickStore`] itself
//! (read through its cache): `tests/gpu_stream.rs` compares them ray by ray.

use hytrace_volume::{BrickStore, Estimate, RangeMips, Ray, TransmittanceParams, VoxelGrid};

use super::context::{GpuContext, GpuError};
use super::records::{RayRecord, TransmittanceRecord, VolumeParams, VOLUME_STATUS_MISSING};
use super::streamed_store::{PassSize, StorePool, StreamError, StreamStats};
use super::timing::GpuTimes;
use super::transmittance::{
    kernel_params, kernel_rays, ray_batch, record_estimate, transmittance_source,
    TransmittanceKernel,
};

const KERNEL: &str = "kernels/transmittance";

/// A brick store on the GPU through a brick pool, with the streamed transmittance kernel.
pub struct GpuStreamedVolume<'a> {
    pool: StorePool<'a>,
    /// The range mips walks take (the store's own, or those of its data).
    mips: &'a RangeMips,
    /// Group 0: the parameters and the pool's arrays and state; group 1: rays, results,
    /// the rays' stream indices.
    kernel: TransmittanceKernel,
}

impl<'a> GpuStreamedVolume<'a> {
    /// Sets up the pool of `store` in at most `budget` device bytes (the range mips, page
    /// table, request buffer and the pool's slots) and compiles the kernel. A budget that
    /// cannot hold one superchunk's bricks (or every kept brick of a smaller store) is a
    /// [`StreamError::Budget`].
    pub fn new(
        ctx: &GpuContext,
        store: &'a BrickStore,
        budget: u64,
    ) -> Result<GpuStreamedVolume<'a>, StreamError> {
        Self::with_mips(ctx, store, store.mips(), budget)
    }

    /// [`GpuStreamedVolume::new`] with walks bounded by `mips` (e.g.
    /// [`BrickStore::data_mips`], which scene media take, so that the GPU walks take the
    /// CPU twin's steps).
    pub fn with_mips(
        ctx: &GpuContext,
        store: &'a BrickStore,
        mips: &'a RangeMips,
        budget: u64,
    ) -> Result<GpuStreamedVolume<'a>, StreamError> {
        let pool = StorePool::new(ctx, store, mips, budget)?;
        let per_stage = ctx.limits.max_storage_buffers_per_shader_stage;
        if per_stage < 10 {
            return Err(GpuError::SceneTooBig(format!(
                "the streamed transmittance kernel binds 10 storage buffers, the device allows {per_stage}"
            ))
            .into());
        }
        let source = transmittance_source(&["streamed", "stream_lods"]).map_err(|problem| {
            GpuError::Shader {
                name: KERNEL.to_string(),
                problem: problem.to_string(),
            }
        })?;
        let mut layout = vec![super::context::storage_layout_entry(0, true)];
        layout.extend(StorePool::layout_entries(true));
        let kernel =
            TransmittanceKernel::new(ctx, "streamed transmittance", &source, &layout, 3, &[])?;
        Ok(GpuStreamedVolume { pool, mips, kernel })
    }

    /// What the streaming did so far.
    pub fn stats(&self) -> StreamStats {
        self.pool.stats()
    }

    /// The bricks in the pool (page-table indices: x fastest over the store's bricks).
    pub fn resident_bricks(&self) -> Vec<u32> {
        self.pool.resident_bricks()
    }

    /// Seconds spent setting up (host wall clock).
    pub fn upload_s(&self) -> f64 {
        self.pool.upload_s()
    }

    /// Uploads every kept brick before any pass (the store held whole on the device: the
    /// in-core reference of a streamed run); the budget must hold them all.
    pub fn make_resident(&mut self, ctx: &GpuContext) -> Result<(), StreamError> {
        self.pool.make_resident(ctx)
    }

    /// The transmittance of every world ray (ray `i` uses the random streams of index `i`),
    /// in passes until every ray ran with its bricks resident, with the GPU's times. Errors
    /// as [`super::GpuVolume::transmittance`], and [`StreamError::PoolTooSmall`] for a ray
    /// that needs more bricks at once than the pool holds.
    pub fn transmittance(
        &mut self,
        ctx: &GpuContext,
        rays: &[Ray],
        params: &TransmittanceParams,
    ) -> crate::Result<(Vec<Estimate>, GpuTimes)> {
        let store: &dyn VoxelGrid = self.pool.store();
        let mips = self.mips;
        let grid = self.pool.grid();
        let records = kernel_rays(store, mips, grid, rays, params)?;
        let base = kernel_params(&grid.base, params);
        let batch = ray_batch(ctx);
        let mut out: Vec<Option<Estimate>> = vec![None; rays.len()];
        let mut pending: Vec<u32> = (0..rays.len() as u32).collect();
        let mut size = PassSize::new(pending.len());
        let mut times = GpuTimes::default();
        while !pending.is_empty() {
            let pass = self.pool.begin_pass(ctx)?;
            let run = &pending[..size.of(pending.len())];
            let mut missing = Vec::new();
            for chunk in run.chunks(batch) {
                let mut p = base;
                p.ray_count = chunk.len() as u32;
                let chunk_rays: Vec<RayRecord> =
                    chunk.iter().map(|&i| records[i as usize]).collect();
                let results = self.dispatch(ctx, &p, &chunk_rays, chunk, &mut times)?;
                for (&i, r) in chunk.iter().zip(&results) {
                    let i = i as usize;
                    if r.status & VOLUME_STATUS_MISSING != 0 {
                        missing.push(i as u32);
                        continue;
                    }
                    let twin = (store, mips);
                    out[i] = Some(record_estimate(r, i, &rays[i], twin, params, &mut times)?);
                }
            }
            let finished = run.len() - missing.len();
            self.pool.defer(missing.len());
            let placed = self.pool.end_pass(ctx, pass)?;
            // The rays not run this pass stay after the deferred ones.
            let rest = pending[run.len()..].to_vec();
            pending = missing;
            pending.extend(rest);
            if size.stuck_after(finished, placed) {
                return Err(StreamError::PoolTooSmall {
                    item: format!("ray {}", pending[0]),
                    slots: self.pool.slots(),
                }
                .into());
            }
        }
        let out = out
            .into_iter()
            .map(|e| e.expect("every ray finished"))
            .collect();
        Ok((out, times))
    }

    /// One batch: upload, dispatch, wait, read back; `streams` are the rays' indices.
    fn dispatch(
        &self,
        ctx: &GpuContext,
        params: &VolumeParams,
        rays: &[RayRecord],
        streams: &[u32],
        times: &mut GpuTimes,
    ) -> Result<Vec<TransmittanceRecord>, GpuError> {
        let arrays = self.pool.entries(true);
        let streams = [bytemuck::cast_slice(streams)];
        let label = "streamed transmittance";
        (self.kernel).dispatch(ctx, label, params, rays, &streams, &arrays, times)
    }
}
