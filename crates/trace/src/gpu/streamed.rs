//! GPU transmittance through a brick store larger than the device's memory budget: a brick
//! pool (the store's 16-bit bricks in a storage buffer of slots) behind a page table (the
//! kernel's indirection: each brick's pool slot, [`VOLUME_ABSENT_BRICK`] or none), and a
//! request buffer the kernel fills with the bricks it needs and lacks
//! (`shaders/volume/stream.wgsl`).
//!
//! Rays run in passes. A ray that read an absent brick is marked missing: its answer is
//! discarded and it runs again in a later pass, after the host has read the requested
//! bricks from the store and uploaded them, so every answer is computed with all its bricks
//! resident and equals, bit for bit, the answer of the same kernel with the whole store
//! resident. The pool starts small, doubles up to the budget, then evicts the bricks least
//! recently used (never one used in the pass just run: [`BrickPool`]). When a pass finishes
//! no ray and places no brick (the pending rays need more bricks together than the pool
//! holds), the next pass runs half as many rays, down to one; a ray that alone needs more
//! bricks than the pool holds is an error.
//!
//! The CPU twin is [`hytrace_volume::transmittance_batch`] on the [`BrickStore`] itself
//! (read through its cache): `tests/gpu_stream.rs` compares them ray by ray.

use std::time::Instant;

use hytrace_volume::{
    BrickEntry, BrickStore, Estimate, Ray, StoreError, TransmittanceParams, VoxelGrid, BRICK_BYTES,
    NO_BRICK, SUPERCHUNK_BRICKS,
};
use rayon::prelude::*;

use super::brick_pool::{Admission, BrickPool};
use super::context::{storage_layout_entry, GpuContext, GpuError};
use super::records::{
    RayRecord, TransmittanceRecord, VolumeParams, STREAM_CAPACITY, STREAM_FLAGS,
    STREAM_HEADER_WORDS, STREAM_PASS, STREAM_REQUESTED, STREAM_STAMPS, VOLUME_ABSENT_BRICK,
    VOLUME_STATUS_MISSING,
};
use super::timing::GpuTimes;
use super::transmittance::{
    kernel_params, kernel_rays, ray_batch, record_estimate, store_grid, transmittance_source,
    KernelGrid, TransmittanceKernel, UploadedGrid,
};

const KERNEL: &str = "kernels/transmittance";

/// Slots a pool starts with (it doubles from there).
const INITIAL_SLOTS: u32 = 512;

/// Device bytes a pool slot costs: its texels, its brick-table entry and its use stamp.
const SLOT_BYTES: u64 = BRICK_BYTES as u64 + size_of::<BrickEntry>() as u64 + 4;

/// The state buffer's binding in group 0 (`shaders/volume/stream.wgsl`).
const STATE_BINDING: u32 = 20;

/// Why a streamed volume could not be set up or finish.
#[derive(Debug, thiserror::Error)]
pub enum StreamError {
    /// The budget does not hold the fixed arrays and one superchunk's bricks.
    #[error(
        "a GPU memory budget of {budget} bytes is too small for this brick store: its range \
         mips, page table and request buffer take {fixed} bytes and the brick pool needs room \
         for {least_bricks} bricks ({SLOT_BYTES} bytes each); give at least {least} bytes"
    )]
    Budget {
        /// The budget given.
        budget: u64,
        /// Bytes of the arrays that do not grow.
        fixed: u64,
        /// Bricks the pool must hold at least (one superchunk's, or all the store keeps).
        least_bricks: u64,
        /// The least budget.
        least: u64,
    },
    /// A ray needs more bricks at once than the pool holds.
    #[error(
        "ray {ray} needs more bricks at once than the GPU brick pool's {slots} slots hold; \
         give a larger --memory"
    )]
    PoolTooSmall {
        /// The ray.
        ray: usize,
        /// The pool's slots.
        slots: u32,
    },
    /// Reading a brick from the store failed.
    #[error(transparent)]
    Store(#[from] StoreError),
    /// The device failed.
    #[error(transparent)]
    Gpu(#[from] GpuError),
}

/// What the streaming did so far.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct StreamStats {
    /// Passes run.
    pub passes: u64,
    /// Ray runs whose answer was discarded because a brick was missing.
    pub rays_deferred: u64,
    /// Bricks read from the store and uploaded.
    pub bricks_uploaded: u64,
    /// Bricks evicted from the pool to make room.
    pub bricks_evicted: u64,
    /// Bricks in the pool now.
    pub resident_bricks: u64,
    /// Slots the pool holds now.
    pub pool_slots: u32,
    /// Slots the budget allows.
    pub max_slots: u32,
    /// Times the pool doubled.
    pub pool_doublings: u32,
    /// Device bytes of the pool and the fixed arrays now.
    pub device_bytes: u64,
}

/// A brick store on the GPU through a brick pool, with the streamed transmittance kernel.
pub struct GpuStreamedVolume<'a> {
    store: &'a BrickStore,
    /// The store's record of every page (x-fastest brick order), `None` when dropped.
    records: Vec<Option<u32>>,
    /// The page table as uploaded.
    pages: Vec<u32>,
    grid: UploadedGrid,
    /// Group 0: the parameters, ranges, page table, brick table, pool, state; group 1:
    /// rays, results, the rays' stream indices.
    kernel: TransmittanceKernel,
    ranges: wgpu::Buffer,
    page_table: wgpu::Buffer,
    brick_table: wgpu::Buffer,
    atlas: wgpu::Buffer,
    state: wgpu::Buffer,
    /// Words of the state buffer: header, requests, flags, stamps.
    state_words: u64,
    request_capacity: u32,
    flag_words: u32,
    pool: BrickPool,
    fixed_bytes: u64,
    stats: StreamStats,
    upload_s: f64,
}

/// A device buffer of `size` bytes the host writes and the kernel reads (and writes when
/// `copy_src`, read back).
fn pool_buffer(ctx: &GpuContext, label: &str, size: u64, copy_src: bool) -> wgpu::Buffer {
    let mut usage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST;
    if copy_src {
        usage |= wgpu::BufferUsages::COPY_SRC;
    }
    ctx.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: size.max(32),
        usage,
        mapped_at_creation: false,
    })
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
        let t0 = Instant::now();
        let meta = store.meta();
        let bricks = meta.bricks();
        let brick_lo = meta.index_origin.map(|c| c.div_euclid(8));
        let kernel_grid = KernelGrid::Store {
            mips: store.mips(),
            brick_lo,
            brick_dims: bricks.map(|b| b as u32),
            background: meta.background,
        };
        let (grid, ranges) = store_grid(kernel_grid)?;
        let records = store.brick_records();
        let page_count = records.len() as u64;
        let flag_words = page_count.div_ceil(32);
        let kept = meta.kept_bricks;
        let least_bricks = kept.min(SUPERCHUNK_BRICKS as u64).max(1);
        // Requests a pass may record: as many as the pool may place, and a few superchunks.
        let per_slot_requests = 4;
        let fixed = (ranges.len() * 8) as u64
            + page_count * 4
            + (u64::from(STREAM_HEADER_WORDS) + flag_words) * 4
            + size_of::<VolumeParams>() as u64;
        let least = fixed + least_bricks * (SLOT_BYTES + per_slot_requests);
        if budget < least {
            return Err(StreamError::Budget {
                budget,
                fixed,
                least_bricks,
                least,
            });
        }
        let limit = ctx.limits.max_storage_buffer_binding_size;
        let max_slots = ((budget - fixed) / (SLOT_BYTES + per_slot_requests))
            .min(kept.max(1))
            .min(limit / BRICK_BYTES as u64)
            .min(u64::from(VOLUME_ABSENT_BRICK - 1)) as u32;
        let request_capacity = max_slots;
        let pool = BrickPool::new(INITIAL_SLOTS, max_slots);
        let state_words = u64::from(STREAM_HEADER_WORDS)
            + u64::from(request_capacity)
            + flag_words
            + u64::from(max_slots);
        let per_stage = ctx.limits.max_storage_buffers_per_shader_stage;
        if per_stage < 9 {
            return Err(GpuError::SceneTooBig(format!(
                "the streamed transmittance kernel binds 9 storage buffers, the device allows {per_stage}"
            ))
            .into());
        }
        let source = transmittance_source(&["streamed"]).map_err(|problem| GpuError::Shader {
            name: KERNEL.to_string(),
            problem: problem.to_string(),
        })?;
        let pages: Vec<u32> = (records.iter())
            .map(|r| r.map_or(NO_BRICK, |_| VOLUME_ABSENT_BRICK))
            .collect();
        let q = meta.quantization;
        // Slot `k`'s entry decodes slot `k`'s texels with the store's quantization.
        let entries: Vec<BrickEntry> = (0..max_slots)
            .map(|k| BrickEntry {
                origin: [0; 3],
                atlas_slot: k,
                offset: q.lo,
                scale: q.step,
                active_voxels: 0,
                max_error: 0.0,
            })
            .collect();
        let mut layout: Vec<_> = (0..5).map(|b| storage_layout_entry(b, true)).collect();
        layout.push(storage_layout_entry(STATE_BINDING, false));
        let kernel =
            TransmittanceKernel::new(ctx, "streamed transmittance", &source, &layout, 3, &[])?;
        let buffers = ctx.checked("allocating the brick pool", || {
            let ranges_buffer = pool_buffer(ctx, "stream ranges", (ranges.len() * 8) as u64, false);
            ctx.queue
                .write_buffer(&ranges_buffer, 0, bytemuck::cast_slice(&ranges));
            let page_table = pool_buffer(ctx, "page table", page_count * 4, false);
            ctx.queue
                .write_buffer(&page_table, 0, bytemuck::cast_slice(&pages));
            let brick_table = pool_buffer(
                ctx,
                "pool brick table",
                (entries.len() * size_of::<BrickEntry>()) as u64,
                false,
            );
            ctx.queue
                .write_buffer(&brick_table, 0, bytemuck::cast_slice(&entries));
            let atlas = pool_buffer(
                ctx,
                "brick pool",
                u64::from(pool.slots()) * BRICK_BYTES as u64,
                true,
            );
            let state = pool_buffer(ctx, "stream state", state_words * 4, true);
            (ranges_buffer, page_table, brick_table, atlas, state)
        })?;
        let (ranges, page_table, brick_table, atlas, state) = buffers;
        let mut volume = GpuStreamedVolume {
            store,
            records,
            pages,
            grid,
            kernel,
            ranges,
            page_table,
            brick_table,
            atlas,
            state,
            state_words,
            request_capacity,
            flag_words: flag_words as u32,
            pool,
            fixed_bytes: fixed,
            stats: StreamStats::default(),
            upload_s: 0.0,
        };
        volume.update_stats();
        volume.upload_s = t0.elapsed().as_secs_f64();
        Ok(volume)
    }

    /// What the streaming did so far.
    pub fn stats(&self) -> StreamStats {
        self.stats
    }

    /// The bricks in the pool (page-table indices: x fastest over the store's bricks).
    pub fn resident_bricks(&self) -> Vec<u32> {
        (self.pages.iter().enumerate())
            .filter(|(_, &e)| e != NO_BRICK && e != VOLUME_ABSENT_BRICK)
            .map(|(p, _)| p as u32)
            .collect()
    }

    /// Seconds spent setting up (host wall clock).
    pub fn upload_s(&self) -> f64 {
        self.upload_s
    }

    fn update_stats(&mut self) {
        self.stats.resident_bricks = self.pool.resident() as u64;
        self.stats.pool_slots = self.pool.slots();
        self.stats.max_slots = self.pool.max_slots();
        self.stats.device_bytes = self.fixed_bytes
            + u64::from(self.pool.slots()) * BRICK_BYTES as u64
            + u64::from(self.pool.max_slots()) * (SLOT_BYTES - BRICK_BYTES as u64)
            + u64::from(self.request_capacity) * 4;
    }

    /// Uploads every kept brick before any pass (the store held whole on the device: the
    /// in-core reference of a streamed run); the budget must hold them all.
    pub fn make_resident(&mut self, ctx: &GpuContext) -> Result<(), StreamError> {
        let all: Vec<u32> = (self.records.iter().enumerate())
            .filter(|(_, r)| r.is_some())
            .map(|(p, _)| p as u32)
            .collect();
        if all.len() > self.pool.max_slots() as usize {
            return Err(StreamError::PoolTooSmall {
                ray: 0,
                slots: self.pool.max_slots(),
            });
        }
        let admission = self.pool.admit(&all, 0);
        self.place(ctx, &admission)
    }

    /// Grows the pool's texel buffer to the admission's slots and uploads its bricks.
    fn place(&mut self, ctx: &GpuContext, admission: &Admission) -> Result<(), StreamError> {
        let slot_bytes = BRICK_BYTES as u64;
        let have = self.atlas.size() / slot_bytes;
        if u64::from(admission.slots) > have {
            let grown = ctx.checked("growing the brick pool", || {
                let grown = pool_buffer(
                    ctx,
                    "brick pool",
                    u64::from(admission.slots) * slot_bytes,
                    true,
                );
                let mut encoder = ctx.device.create_command_encoder(&Default::default());
                encoder.copy_buffer_to_buffer(&self.atlas, 0, &grown, 0, self.atlas.size());
                ctx.queue.submit([encoder.finish()]);
                grown
            })?;
            self.atlas = grown;
            let mut slots = have.max(1);
            while slots < u64::from(admission.slots) {
                slots *= 2;
                self.stats.pool_doublings += 1;
            }
        }
        let records = &self.records;
        let codes: Vec<Vec<u8>> = (admission.placed.par_iter())
            .map(|p| {
                let record = records[p.brick as usize].expect("only kept bricks are requested");
                let codes = self.store.read_brick(record)?;
                Ok(bytemuck::cast_slice(&codes).to_vec())
            })
            .collect::<Result<_, StoreError>>()?;
        for (p, bytes) in admission.placed.iter().zip(&codes) {
            ctx.queue
                .write_buffer(&self.atlas, u64::from(p.slot) * slot_bytes, bytes);
            self.pages[p.brick as usize] = p.slot;
            if let Some(old) = p.evicted {
                self.pages[old as usize] = VOLUME_ABSENT_BRICK;
                self.stats.bricks_evicted += 1;
            }
        }
        if !admission.placed.is_empty() {
            ctx.queue
                .write_buffer(&self.page_table, 0, bytemuck::cast_slice(&self.pages));
        }
        self.stats.bricks_uploaded += admission.placed.len() as u64;
        self.update_stats();
        ctx.check_not_lost()?;
        Ok(())
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
        let store: &dyn VoxelGrid = self.store;
        let mips = self.store.mips();
        let records = kernel_rays(store, mips, &self.grid, rays, params)?;
        let base = kernel_params(&self.grid.base, params);
        let batch = ray_batch(ctx);
        let mut out: Vec<Option<Estimate>> = vec![None; rays.len()];
        let mut pending: Vec<u32> = (0..rays.len() as u32).collect();
        let mut active = pending.len();
        let mut times = GpuTimes::default();
        while !pending.is_empty() {
            let pass = self.stats.passes as u32 + 1;
            self.stats.passes += 1;
            self.begin_pass(ctx, pass)?;
            let run = &pending[..active.min(pending.len())];
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
            self.stats.rays_deferred += missing.len() as u64;
            let (requests, stamps) = self.read_state(ctx)?;
            self.pool.record_use(&stamps, pass);
            let admission = self.pool.admit(&requests, pass);
            let placed = admission.placed.len();
            self.place(ctx, &admission)?;
            // The rays not run this pass stay after the deferred ones.
            let rest = pending[run.len()..].to_vec();
            pending = missing;
            pending.extend(rest);
            if finished == 0 && placed == 0 {
                if active == 1 {
                    return Err(StreamError::PoolTooSmall {
                        ray: pending[0] as usize,
                        slots: self.pool.slots(),
                    }
                    .into());
                }
                active = active.div_ceil(2);
            } else if finished > 0 {
                active = active.saturating_mul(2);
            }
        }
        let out = out
            .into_iter()
            .map(|e| e.expect("every ray finished"))
            .collect();
        Ok((out, times))
    }

    /// Resets the request list and flags and sets the pass number.
    fn begin_pass(&self, ctx: &GpuContext, pass: u32) -> Result<(), GpuError> {
        let mut header = [0u32; STREAM_HEADER_WORDS as usize];
        header[STREAM_REQUESTED as usize] = 0;
        header[STREAM_CAPACITY as usize] = self.request_capacity;
        let flags = STREAM_HEADER_WORDS + self.request_capacity;
        header[STREAM_FLAGS as usize] = flags;
        header[STREAM_STAMPS as usize] = flags + self.flag_words;
        header[STREAM_PASS as usize] = pass;
        ctx.checked("starting a streamed pass", || {
            ctx.queue
                .write_buffer(&self.state, 0, bytemuck::cast_slice(&header));
            let mut encoder = ctx.device.create_command_encoder(&Default::default());
            let start = u64::from(flags) * 4;
            encoder.clear_buffer(&self.state, start, Some(u64::from(self.flag_words) * 4));
            ctx.queue.submit([encoder.finish()]);
        })
    }

    /// The bricks requested in the pass (as many as the list held) and the slots' stamps.
    fn read_state(&self, ctx: &GpuContext) -> Result<(Vec<u32>, Vec<u32>), GpuError> {
        let words: Vec<u32> =
            bytemuck::pod_collect_to_vec(&ctx.read_buffer(&self.state, self.state_words * 4)?);
        let h = STREAM_HEADER_WORDS as usize;
        let n = (words[STREAM_REQUESTED as usize] as usize).min(self.request_capacity as usize);
        let requests = words[h..h + n].to_vec();
        let stamps_at = words[STREAM_STAMPS as usize] as usize;
        let stamps = words[stamps_at..stamps_at + self.pool.slots() as usize].to_vec();
        Ok((requests, stamps))
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
        let arrays = [
            (1, &self.ranges),
            (2, &self.page_table),
            (3, &self.brick_table),
            (4, &self.atlas),
            (STATE_BINDING, &self.state),
        ]
        .map(|(binding, b)| wgpu::BindGroupEntry {
            binding,
            resource: b.as_entire_binding(),
        });
        let streams = [bytemuck::cast_slice(streams)];
        let label = "streamed transmittance";
        (self.kernel).dispatch(ctx, label, params, rays, &streams, &arrays, times)
    }
}
