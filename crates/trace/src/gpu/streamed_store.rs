//! A brick store on the GPU through a brick pool: the device side of streaming, shared by
//! every kernel that reads a store larger than the device's memory budget (the streamed
//! transmittance of [`super::streamed`] and the streamed render of [`super::render`]).
//!
//! The pool holds the store's 16-bit bricks in a storage buffer of slots behind a page
//! table (the kernel's indirection: each brick's pool slot, [`VOLUME_ABSENT_BRICK`] with
//! its record, whose coarser level of detail the kernel reads meanwhile, or none), and a request buffer the kernel fills with the bricks it needs and lacks
//! (`shaders/volume/stream.wgsl`). Kernels run in passes: before one, [`StorePool::begin_pass`]
//! clears the requests; after it, [`StorePool::end_pass`] reads them, places the bricks in
//! the pool ([`BrickPool`]: doubling up to the budget, then evicting the least recently
//! used) and uploads them. An item (a ray, a pixel) that read an absent brick is marked
//! missing by the kernel; its driver runs it again in a later pass.

use std::time::Instant;

use hytrace_volume::{
    BrickEntry, BrickStore, RangeMips, StoreError, BRICK_BYTES, NO_BRICK, SUPERCHUNK_BRICKS,
};
use rayon::prelude::*;

use super::brick_pool::{Admission, BrickPool};
use super::context::{storage_layout_entry, GpuContext, GpuError};
use super::records::{
    VolumeParams, STREAM_CAPACITY, STREAM_FLAGS, STREAM_HEADER_WORDS, STREAM_PASS,
    STREAM_REQUESTED, STREAM_STAMPS, VOLUME_ABSENT_BRICK,
};
use super::transmittance::{store_grid, KernelGrid, UploadedGrid};

/// Slots a pool starts with (it doubles from there).
const INITIAL_SLOTS: u32 = 512;

/// Device bytes a pool slot costs: its texels, its brick-table entry and its use stamp.
const SLOT_BYTES: u64 = BRICK_BYTES as u64 + size_of::<BrickEntry>() as u64 + 4;

/// The state buffer's binding in group 0 (`shaders/volume/stream.wgsl`).
const STATE_BINDING: u32 = 20;

/// The levels of detail's binding in group 0 (`shaders/volume/stream.wgsl`).
const LODS_BINDING: u32 = 21;

/// Why a streamed volume could not be set up or finish.
#[derive(Debug, thiserror::Error)]
pub enum StreamError {
    /// The budget does not hold the fixed arrays and one superchunk's bricks.
    #[error(
        "a GPU memory budget of {budget} bytes is too small for this brick store: its range \
         mips, page table, levels of detail and request buffer take {fixed} bytes and the brick pool needs room \
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
    /// An item (a ray, a pixel) needs more bricks at once than the pool holds.
    #[error(
        "{item} needs more bricks at once than the GPU brick pool's {slots} slots hold; \
         give a larger --memory"
    )]
    PoolTooSmall {
        /// The item: `ray N` or `pixel (I, J)`.
        item: String,
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
    /// Item runs (rays, pixels) whose answer was discarded because a brick was missing.
    pub deferred: u64,
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

impl StreamStats {
    /// These stats as the commands' `--stats` print them, the deferred runs under
    /// `deferred` (`rays_deferred`, `pixels_deferred`).
    pub fn json(&self, deferred: &str) -> serde_json::Value {
        let mut line = serde_json::json!({
            "passes": self.passes,
            "bricks_uploaded": self.bricks_uploaded, "bricks_evicted": self.bricks_evicted,
            "resident_bricks": self.resident_bricks, "pool_slots": self.pool_slots,
            "max_slots": self.max_slots, "pool_doublings": self.pool_doublings,
            "device_bytes": self.device_bytes,
        });
        line[deferred] = self.deferred.into();
        line
    }
}

/// `store` as the streamed kernels read it, walks bounded by `mips`.
pub(super) fn store_kernel_grid<'m>(store: &BrickStore, mips: &'m RangeMips) -> KernelGrid<'m> {
    let meta = store.meta();
    KernelGrid::Store {
        mips,
        brick_lo: meta.index_origin.map(|c| c.div_euclid(8)),
        brick_dims: meta.bricks().map(|b| b as u32),
        background: meta.background,
    }
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

/// A brick store's pool on the device: its range mips, page table, brick table, texel
/// slots and request state (group 0, bindings 1 to 4 and [`STATE_BINDING`], beside the
/// kernel's parameters at binding 0), and the host's bookkeeping of them.
pub(super) struct StorePool<'a> {
    store: &'a BrickStore,
    /// The store's record of every page (x-fastest brick order), `None` when dropped.
    records: Vec<Option<u32>>,
    /// The page table as uploaded.
    pages: Vec<u32>,
    grid: UploadedGrid,
    ranges: wgpu::Buffer,
    page_table: wgpu::Buffer,
    brick_table: wgpu::Buffer,
    atlas: wgpu::Buffer,
    state: wgpu::Buffer,
    /// Every kept brick's coarser levels of detail (by record).
    lods: wgpu::Buffer,
    /// Words of the state buffer: header, requests, flags, stamps.
    state_words: u64,
    request_capacity: u32,
    flag_words: u32,
    pool: BrickPool,
    fixed_bytes: u64,
    stats: StreamStats,
    upload_s: f64,
}

impl<'a> StorePool<'a> {
    /// Sets up the pool of `store` in at most `budget` device bytes (the range mips, page
    /// table, request buffer and the pool's slots); walks over it are bounded by `mips`
    /// (the store's own, or [`BrickStore::data_mips`] to take the steps of the store
    /// bricked in memory). A budget that cannot hold one superchunk's bricks (or every
    /// kept brick of a smaller store) is a [`StreamError::Budget`].
    pub fn new(
        ctx: &GpuContext,
        store: &'a BrickStore,
        mips: &RangeMips,
        budget: u64,
    ) -> Result<StorePool<'a>, StreamError> {
        let t0 = Instant::now();
        let meta = store.meta();
        let (grid, ranges) = store_grid(store_kernel_grid(store, mips))?;
        let records = store.brick_records();
        let page_count = records.len() as u64;
        let flag_words = page_count.div_ceil(32);
        let kept = meta.kept_bricks;
        let least_bricks = kept.min(SUPERCHUNK_BRICKS as u64).max(1);
        // Requests a pass may record: as many as the pool may place, and a few superchunks.
        let per_slot_requests = 4;
        let lods: Vec<f32> = (0..kept as u32)
            .flat_map(|r| store.lod(r).iter().copied())
            .collect();
        let fixed = (ranges.len() * 8) as u64
            + (lods.len() * 4) as u64
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
        // An absent page holds its record beside the flag bit.
        if kept >= u64::from(VOLUME_ABSENT_BRICK - 1) {
            return Err(GpuError::SceneTooBig(format!(
                "the store keeps {kept} bricks; the GPU's page table holds fewer than 2^31"
            ))
            .into());
        }
        let request_capacity = max_slots;
        let pool = BrickPool::new(INITIAL_SLOTS, max_slots);
        let state_words = u64::from(STREAM_HEADER_WORDS)
            + u64::from(request_capacity)
            + flag_words
            + u64::from(max_slots);
        let pages: Vec<u32> = (records.iter())
            .map(|r| r.map_or(NO_BRICK, |record| VOLUME_ABSENT_BRICK | record))
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
            let lods_buffer = pool_buffer(ctx, "levels of detail", (lods.len() * 4) as u64, false);
            ctx.queue
                .write_buffer(&lods_buffer, 0, bytemuck::cast_slice(&lods));
            (
                ranges_buffer,
                page_table,
                brick_table,
                atlas,
                state,
                lods_buffer,
            )
        })?;
        let (ranges, page_table, brick_table, atlas, state, lods) = buffers;
        let mut pool = StorePool {
            store,
            records,
            pages,
            grid,
            ranges,
            page_table,
            brick_table,
            atlas,
            state,
            lods,
            state_words,
            request_capacity,
            flag_words: flag_words as u32,
            pool,
            fixed_bytes: fixed,
            stats: StreamStats::default(),
            upload_s: 0.0,
        };
        pool.update_stats();
        pool.upload_s = t0.elapsed().as_secs_f64();
        Ok(pool)
    }

    /// The store.
    pub fn store(&self) -> &'a BrickStore {
        self.store
    }

    /// The grid's kernel parameters and translation of index space.
    pub fn grid(&self) -> &UploadedGrid {
        &self.grid
    }

    /// The layout entries of group 0 but the parameters: the arrays (read-only), the state
    /// (read-write) and, for a kernel composed with `stream_lods` (`lods`), the levels of
    /// detail (read-only).
    pub fn layout_entries(lods: bool) -> Vec<wgpu::BindGroupLayoutEntry> {
        let mut layout: Vec<_> = (1..5).map(|b| storage_layout_entry(b, true)).collect();
        layout.push(storage_layout_entry(STATE_BINDING, false));
        if lods {
            layout.push(storage_layout_entry(LODS_BINDING, true));
        }
        layout
    }

    /// The layout of group 0 of a kernel that streams a store: its parameters (binding 0)
    /// beside the pool's arrays, state and levels of detail when `lods`
    /// ([`StorePool::layout_entries`]).
    pub fn group_layout(ctx: &GpuContext, label: &str, lods: bool) -> wgpu::BindGroupLayout {
        let mut entries = vec![storage_layout_entry(0, true)];
        entries.extend(Self::layout_entries(lods));
        ctx.device
            .create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some(label),
                entries: &entries,
            })
    }

    /// Group 0 of a pass in `layout` ([`StorePool::group_layout`] of `lods`): `params`
    /// beside the pool's buffers (made again each pass: the pool's buffer changes as it
    /// grows).
    pub fn group(
        &self,
        ctx: &GpuContext,
        layout: &wgpu::BindGroupLayout,
        label: &str,
        params: &wgpu::Buffer,
        lods: bool,
    ) -> wgpu::BindGroup {
        let mut entries = vec![wgpu::BindGroupEntry {
            binding: 0,
            resource: params.as_entire_binding(),
        }];
        entries.extend(self.entries(lods));
        ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some(label),
            layout,
            entries: &entries,
        })
    }

    /// The bind group entries of the arrays, the state and, when `lods`, the levels of
    /// detail (the pool's buffer changes as it grows: bind them again each pass).
    pub fn entries(&self, lods: bool) -> Vec<wgpu::BindGroupEntry<'_>> {
        let mut buffers = vec![
            (1, &self.ranges),
            (2, &self.page_table),
            (3, &self.brick_table),
            (4, &self.atlas),
            (STATE_BINDING, &self.state),
        ];
        if lods {
            buffers.push((LODS_BINDING, &self.lods));
        }
        (buffers.into_iter())
            .map(|(binding, b)| wgpu::BindGroupEntry {
                binding,
                resource: b.as_entire_binding(),
            })
            .collect()
    }

    /// What the streaming did so far.
    pub fn stats(&self) -> StreamStats {
        self.stats
    }

    /// Counts `n` item runs discarded for a missing brick.
    pub fn defer(&mut self, n: usize) {
        self.stats.deferred += n as u64;
    }

    /// The bricks in the pool (page-table indices: x fastest over the store's bricks).
    pub fn resident_bricks(&self) -> Vec<u32> {
        (self.pages.iter().enumerate())
            .filter(|(_, &e)| e != NO_BRICK && e & VOLUME_ABSENT_BRICK == 0)
            .map(|(p, _)| p as u32)
            .collect()
    }

    /// Slots the pool holds now.
    pub fn slots(&self) -> u32 {
        self.pool.slots()
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
                item: "the whole store".into(),
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
                let record = records[old as usize].expect("only kept bricks are resident");
                self.pages[old as usize] = VOLUME_ABSENT_BRICK | record;
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

    /// Starts a pass: counts it, resets the request list and flags and sets the pass
    /// number; returns the pass number.
    pub fn begin_pass(&mut self, ctx: &GpuContext) -> Result<u32, GpuError> {
        self.stats.passes += 1;
        let pass = self.stats.passes as u32;
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
        })?;
        Ok(pass)
    }

    /// Ends pass `pass`: reads the bricks its kernels requested and the slots they used,
    /// places the requested bricks and uploads them; returns how many were placed.
    pub fn end_pass(&mut self, ctx: &GpuContext, pass: u32) -> Result<usize, StreamError> {
        let (requests, stamps) = self.read_state(ctx)?;
        self.pool.record_use(&stamps, pass);
        let admission = self.pool.admit(&requests, pass);
        self.place(ctx, &admission)?;
        Ok(admission.placed.len())
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
}

/// The pass sizing of a streamed run: how many pending items the next pass runs. It
/// starts with all of them, halves when a pass finished no item and placed no brick (the
/// items together need more bricks than the pool holds), down to one, and doubles again
/// after a pass that finished some.
pub(super) struct PassSize {
    active: usize,
}

impl PassSize {
    /// All `items` at first.
    pub fn new(items: usize) -> PassSize {
        PassSize { active: items }
    }

    /// Items the next pass runs, of `pending`.
    pub fn of(&self, pending: usize) -> usize {
        self.active.min(pending)
    }

    /// After a pass that finished `finished` items and placed `placed` bricks; `true` when
    /// one item alone ran and could not finish (it needs more bricks than the pool holds).
    pub fn stuck_after(&mut self, finished: usize, placed: usize) -> bool {
        if finished == 0 && placed == 0 {
            if self.active == 1 {
                return true;
            }
            self.active = self.active.div_ceil(2);
        } else if finished > 0 {
            self.active = self.active.saturating_mul(2);
        }
        false
    }
}
