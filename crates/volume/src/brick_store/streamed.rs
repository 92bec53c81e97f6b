//! Reading a brick store through a cache of bricks with a byte budget: bricks are read on
//! demand with positioned reads and the least recently used are evicted.

use std::fs::File;
use std::num::NonZeroUsize;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

use hytrace_foundry::layout::Scalar;
use hytrace_foundry::npy::read_array;
use lru::LruCache;

use super::format::{
    StoreMeta, BRICK_BYTES, BRICK_SIDE, BRICK_VOXELS, LOD_VALUES, NO_RECORD, STORE_FORMAT,
    STORE_VERSION, SUPERCHUNK_BRICKS,
};
use super::StoreError;
use crate::dense::VolumeError;
use crate::grid::{Coord, GridMap, VoxelGrid};
use crate::ranges::{RangeLevel, RangeMips, ValueRange};

/// Independent parts of the cache (a brick's record number picks its part), so threads
/// rarely wait on one another.
const SHARDS: usize = 64;

/// Bytes a cached brick costs: its codes and the cache's bookkeeping.
const CACHED_BRICK_BYTES: u64 = BRICK_BYTES as u64 + 64;

type Brick = Arc<[u16; BRICK_VOXELS]>;

/// Stores opened so far: each gets its own number, which the per-thread memo is keyed by.
static STORES_OPENED: AtomicU64 = AtomicU64::new(0);

thread_local! {
    /// The brick this thread read last (store number, record, codes): consecutive lookups
    /// mostly fall in one brick (a trilinear lookup reads eight neighbours), and the memo
    /// spares them the cache's lock. It holds one brick per thread beyond the budget.
    static LAST_BRICK: std::cell::RefCell<Option<(u64, u32, Brick)>> =
        const { std::cell::RefCell::new(None) };
}

/// What the cache did so far.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct CacheStats {
    /// Bricks read from disk (a brick evicted and needed again is read again).
    pub bricks_read: u64,
    /// Bricks the cache dropped, least recently used first, to make room for others.
    pub bricks_evicted: u64,
    /// Bricks the cache may hold.
    pub capacity_bricks: u64,
    /// Bytes of the index, ranges and levels of detail, resident while the store is open.
    pub table_bytes: u64,
}

impl std::ops::Add for CacheStats {
    type Output = CacheStats;

    /// The counts of two caches together (a scene's media read as stored, summed).
    fn add(self, o: CacheStats) -> CacheStats {
        CacheStats {
            bricks_read: self.bricks_read + o.bricks_read,
            bricks_evicted: self.bricks_evicted + o.bricks_evicted,
            capacity_bricks: self.capacity_bricks + o.capacity_bricks,
            table_bytes: self.table_bytes + o.table_bytes,
        }
    }
}

impl CacheStats {
    /// The counts as the commands' `--stats` report them under `store`: `bricks_read`,
    /// `bricks_evicted`, `cache_bricks` (the capacity) and `table_bytes`.
    pub fn json(&self) -> serde_json::Value {
        serde_json::json!({
            "bricks_read": self.bricks_read,
            "bricks_evicted": self.bricks_evicted,
            "cache_bricks": self.capacity_bricks,
            "table_bytes": self.table_bytes,
        })
    }
}

/// An opened brick store: its tables resident, its bricks read through the cache.
pub struct BrickStore {
    dir: PathBuf,
    meta: StoreMeta,
    table: Vec<u32>,
    lods: Vec<f32>,
    mips: RangeMips,
    map: GridMap,
    bricks: File,
    shards: Vec<Mutex<LruCache<u32, Brick>>>,
    bricks_read: AtomicU64,
    bricks_evicted: AtomicU64,
    capacity_bricks: u64,
    /// This store's number (for the per-thread memo).
    id: u64,
    /// The first failed read: the brick reads as the background and callers learn of it
    /// from [`BrickStore::check`].
    failure: Mutex<Option<String>>,
}

/// Whether `path` is a brick store directory (it holds `store.json`).
pub fn is_brick_store(path: &Path) -> bool {
    path.join("store.json").is_file()
}

fn file_error(path: &Path, problem: impl Into<String>) -> StoreError {
    StoreError::new(path, problem.into())
}

/// Reads `name` of `dir` as a `scalar` array of shape `shape`.
fn read_table(
    dir: &Path,
    name: &str,
    scalar: Scalar,
    shape: &[u64],
) -> Result<Vec<u8>, StoreError> {
    let path = dir.join(name);
    let a = read_array(&path).map_err(|e| file_error(&path, e.to_string()))?;
    if a.scalar != scalar || a.shape != shape {
        return Err(file_error(
            &path,
            format!(
                "expected {scalar:?} of shape {shape:?}, found {:?} of shape {:?}",
                a.scalar, a.shape
            ),
        ));
    }
    Ok(a.bytes)
}

impl BrickStore {
    /// Opens the store in `dir`, holding at most `budget` bytes resident: its tables, and
    /// bricks in the cache up to the rest, which must fit one superchunk's bricks.
    pub fn open(dir: &Path, budget: u64) -> Result<BrickStore, StoreError> {
        let meta = read_meta(dir)?;
        let s = meta.superchunks().map(|v| v as u64);
        let kept = meta.kept_bricks;
        let table: Vec<u32> = bytemuck::pod_collect_to_vec(&read_table(
            dir,
            "superchunks.npy",
            Scalar::U32,
            &[s[2], s[1], s[0], SUPERCHUNK_BRICKS as u64],
        )?);
        if let Some(bad) = table
            .iter()
            .find(|&&r| r != NO_RECORD && u64::from(r) >= kept)
        {
            return Err(file_error(
                &dir.join("superchunks.npy"),
                format!("brick record {bad} is past the {kept} kept bricks"),
            ));
        }
        let lods: Vec<f32> = bytemuck::pod_collect_to_vec(&read_table(
            dir,
            "brick_lod.npy",
            Scalar::F32,
            &[kept, LOD_VALUES as u64],
        )?);
        let mips = read_mips(dir, &meta)?;
        let bin = dir.join("bricks.bin");
        let bricks = File::open(&bin).map_err(|e| file_error(&bin, e.to_string()))?;
        let len = bricks
            .metadata()
            .map_err(|e| file_error(&bin, e.to_string()))?
            .len();
        if len != kept * BRICK_BYTES as u64 {
            return Err(file_error(
                &bin,
                format!(
                    "has {len} bytes; {kept} bricks of {BRICK_BYTES} bytes need {}",
                    kept * BRICK_BYTES as u64
                ),
            ));
        }
        let table_bytes = (table.len() * 4 + lods.len() * 4 + mips.memory_bytes()) as u64;
        let least = table_bytes + SUPERCHUNK_BRICKS as u64 * CACHED_BRICK_BYTES;
        if budget < least {
            return Err(file_error(
                dir,
                format!(
                    "a memory budget (--memory) of {budget} bytes is too small: the store's tables take {table_bytes} bytes and its cache needs one superchunk's {SUPERCHUNK_BRICKS} bricks ({} bytes); give at least {least}",
                    SUPERCHUNK_BRICKS as u64 * CACHED_BRICK_BYTES
                ),
            ));
        }
        let capacity_bricks = (budget - table_bytes) / CACHED_BRICK_BYTES;
        let per_shard = NonZeroUsize::new((capacity_bricks as usize / SHARDS).max(1))
            .expect("at least one brick a shard");
        let map = GridMap::new(meta.matrix, meta.translation)
            .map_err(|e| file_error(&dir.join("store.json"), e.0))?;
        Ok(BrickStore {
            dir: dir.to_path_buf(),
            meta,
            table,
            lods,
            mips,
            map,
            bricks,
            shards: (0..SHARDS)
                .map(|_| Mutex::new(LruCache::new(per_shard)))
                .collect(),
            bricks_read: AtomicU64::new(0),
            bricks_evicted: AtomicU64::new(0),
            capacity_bricks: per_shard.get() as u64 * SHARDS as u64,
            id: STORES_OPENED.fetch_add(1, Ordering::Relaxed),
            failure: Mutex::new(None),
        })
    }

    /// The store's metadata.
    pub fn meta(&self) -> &StoreMeta {
        &self.meta
    }

    /// The range mips of the store's decoded values (read from `ranges.npy`).
    pub fn mips(&self) -> &RangeMips {
        &self.mips
    }

    /// The coarser levels of detail of kept brick `record`: its mean, then its eight
    /// octants' means (x fastest).
    pub fn lod(&self, record: u32) -> &[f32] {
        let at = record as usize * LOD_VALUES;
        &self.lods[at..at + LOD_VALUES]
    }

    /// The range mips of the store's data alone, computed without reading a brick: its
    /// range mips cropped to the box of the kept bricks grown by one block, which is what
    /// [`RangeMips::build`] makes from the store's voxels (and so the ranges of a bricked
    /// grid converted from it: walks over both take the same steps). The store's own mips
    /// span the whole volume.
    pub fn data_mips(&self) -> Result<RangeMips, VolumeError> {
        let side = BRICK_SIDE as i32;
        let blocks: Vec<Coord> = (self.block_origins()?.iter())
            .map(|o| o.map(|c| c.div_euclid(side)))
            .collect();
        let (mut lo, mut hi) = ([i32::MAX; 3], [i32::MIN; 3]);
        for b in &blocks {
            for k in 0..3 {
                lo[k] = lo[k].min(b[k] - 1);
                hi[k] = hi[k].max(b[k] + 1);
            }
        }
        if blocks.is_empty() {
            (lo, hi) = ([0; 3], [-1; 3]);
        }
        let dims: [u32; 3] = std::array::from_fn(|k| (hi[k] - lo[k] + 1) as u32);
        let mut ranges = Vec::with_capacity(dims.iter().map(|&d| d as usize).product());
        for z in lo[2]..=hi[2] {
            for y in lo[1]..=hi[1] {
                ranges.extend((lo[0]..=hi[0]).map(|x| self.mips.range(0, [x, y, z])));
            }
        }
        let level0 = RangeLevel {
            side: BRICK_SIDE as u32,
            lo,
            dims,
            ranges,
        };
        RangeMips::from_finest(self.meta.background, level0)
    }

    /// The store with its index-to-world map replaced by `map` (a scene places its media
    /// with their own transforms).
    pub fn with_map(mut self, map: GridMap) -> BrickStore {
        self.map = map;
        self
    }

    /// The record of the brick holding store voxel `v` (index voxel `index_origin + v`), or
    /// `None` outside the volume and for a dropped brick.
    pub fn record_of(&self, v: [i64; 3]) -> Option<u32> {
        let inside = (0..3).all(|k| v[k] >= 0 && v[k] < i64::from(self.meta.dims[k]));
        if !inside {
            return None;
        }
        let b = v.map(|c| c as usize / BRICK_SIDE);
        let r = self.table[self.meta.table_slot(b)];
        (r != NO_RECORD).then_some(r)
    }

    /// What the cache did so far.
    pub fn stats(&self) -> CacheStats {
        CacheStats {
            bricks_read: self.bricks_read.load(Ordering::Relaxed),
            bricks_evicted: self.bricks_evicted.load(Ordering::Relaxed),
            capacity_bricks: self.capacity_bricks,
            table_bytes: (self.table.len() * 4 + self.lods.len() * 4 + self.mips.memory_bytes())
                as u64,
        }
    }

    /// An error when a brick could not be read since the store was opened (such bricks
    /// read as the background, so results computed meanwhile are wrong).
    pub fn check(&self) -> Result<(), StoreError> {
        let failure = self.failure.lock().unwrap_or_else(|e| e.into_inner());
        match failure.as_ref() {
            Some(why) => Err(file_error(&self.dir.join("bricks.bin"), why.clone())),
            None => Ok(()),
        }
    }

    /// The record of every brick, x fastest over [`StoreMeta::bricks`], or `None` for a
    /// dropped brick: the page table a GPU brick pool starts from.
    pub fn brick_records(&self) -> Vec<Option<u32>> {
        let b = self.meta.bricks();
        let mut out = Vec::with_capacity(b.iter().product());
        for z in 0..b[2] {
            for y in 0..b[1] {
                for x in 0..b[0] {
                    let r = self.table[self.meta.table_slot([x, y, z])];
                    out.push((r != NO_RECORD).then_some(r));
                }
            }
        }
        out
    }

    /// The 16-bit codes of kept brick `record` (x fastest), read from disk past the cache
    /// (a GPU brick pool keeps its own copies); counted in [`CacheStats::bricks_read`].
    pub fn read_brick(&self, record: u32) -> Result<[u16; BRICK_VOXELS], StoreError> {
        let bin = self.dir.join("bricks.bin");
        if u64::from(record) >= self.meta.kept_bricks {
            return Err(file_error(
                &bin,
                format!(
                    "brick {record} is past the {} kept bricks",
                    self.meta.kept_bricks
                ),
            ));
        }
        let mut bytes = vec![0u8; BRICK_BYTES];
        read_at(&self.bricks, &mut bytes, record as u64 * BRICK_BYTES as u64)
            .map_err(|e| file_error(&bin, format!("reading brick {record}: {e}")))?;
        self.bricks_read.fetch_add(1, Ordering::Relaxed);
        let mut codes = [0u16; BRICK_VOXELS];
        for (c, b) in codes.iter_mut().zip(bytes.chunks_exact(2)) {
            *c = u16::from_le_bytes([b[0], b[1]]);
        }
        Ok(codes)
    }

    /// Kept brick `record`, from the cache or read from disk.
    fn brick(&self, record: u32) -> Option<Brick> {
        let shard = &self.shards[record as usize % SHARDS];
        if let Some(b) = shard.lock().unwrap_or_else(|e| e.into_inner()).get(&record) {
            return Some(b.clone());
        }
        // Read outside the lock; two threads missing the same brick both read it.
        let codes = match self.read_brick(record) {
            Ok(codes) => codes,
            Err(e) => {
                let mut failure = self.failure.lock().unwrap_or_else(|e| e.into_inner());
                failure.get_or_insert_with(|| e.problem);
                return None;
            }
        };
        let brick: Brick = Arc::new(codes);
        // `push` hands back the entry it displaced: another brick when the shard was full,
        // or this one when another thread read it meanwhile.
        let displaced = shard
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .push(record, brick.clone());
        if displaced.is_some_and(|(r, _)| r != record) {
            self.bricks_evicted.fetch_add(1, Ordering::Relaxed);
        }
        Some(brick)
    }
}

#[cfg(unix)]
fn read_at(file: &File, buf: &mut [u8], offset: u64) -> std::io::Result<()> {
    std::os::unix::fs::FileExt::read_exact_at(file, buf, offset)
}

#[cfg(windows)]
fn read_at(file: &File, mut buf: &mut [u8], mut offset: u64) -> std::io::Result<()> {
    while !buf.is_empty() {
        match std::os::windows::fs::FileExt::seek_read(file, buf, offset)? {
            0 => return Err(std::io::ErrorKind::UnexpectedEof.into()),
            n => {
                buf = &mut buf[n..];
                offset += n as u64;
            }
        }
    }
    Ok(())
}

fn read_meta(dir: &Path) -> Result<StoreMeta, StoreError> {
    let path = dir.join("store.json");
    let text = std::fs::read(&path).map_err(|e| file_error(&path, e.to_string()))?;
    let meta: StoreMeta =
        serde_json::from_slice(&text).map_err(|e| file_error(&path, e.to_string()))?;
    if meta.format != STORE_FORMAT || meta.version != STORE_VERSION {
        return Err(file_error(
            &path,
            format!(
                "format {} version {}; this build reads {STORE_FORMAT} version {STORE_VERSION}",
                meta.format, meta.version
            ),
        ));
    }
    let q = meta.quantization;
    let sane = !meta.dims.contains(&0)
        && meta.index_origin.iter().all(|c| c % BRICK_SIDE as i32 == 0)
        && (0..3).all(|k| meta.index_origin[k] as i64 + meta.dims[k] as i64 <= i32::MAX as i64)
        && meta.background.is_finite()
        && q.lo.is_finite()
        && q.step.is_finite()
        && (q.lo + 65535.0 * q.step).is_finite();
    let total = meta.bricks().iter().map(|&b| b as u64).product::<u64>();
    if !sane || meta.kept_bricks + meta.dropped_bricks != total {
        return Err(file_error(
            &path,
            "impossible dimensions, index origin, quantization or brick counts",
        ));
    }
    Ok(meta)
}

fn read_mips(dir: &Path, meta: &StoreMeta) -> Result<RangeMips, StoreError> {
    let d = meta.range_dims();
    let path = dir.join("ranges.npy");
    let values: Vec<f32> = bytemuck::pod_collect_to_vec(&read_table(
        dir,
        "ranges.npy",
        Scalar::F32,
        &[d[2] as u64, d[1] as u64, d[0] as u64, 2],
    )?);
    let ranges: Vec<ValueRange> = values
        .chunks_exact(2)
        .map(|r| ValueRange {
            min: r[0],
            max: r[1],
        })
        .collect();
    if let Some(i) = ranges
        .iter()
        .position(|r| r.min.is_nan() || !r.max.is_finite() || r.min > r.max)
    {
        return Err(file_error(
            &path,
            format!("range {i} is not an ordered pair of finite values"),
        ));
    }
    let level0 = RangeLevel {
        side: BRICK_SIDE as u32,
        lo: meta.index_origin.map(|c| c / BRICK_SIDE as i32 - 1),
        dims: d.map(|v| v as u32),
        ranges,
    };
    RangeMips::from_finest(meta.background, level0).map_err(|e| file_error(&path, e.0))
}

impl VoxelGrid for BrickStore {
    fn background(&self) -> f32 {
        self.meta.background
    }

    fn voxel(&self, ijk: Coord) -> f32 {
        let v: [i64; 3] =
            std::array::from_fn(|k| i64::from(ijk[k]) - i64::from(self.meta.index_origin[k]));
        let Some(record) = self.record_of(v) else {
            return self.meta.background;
        };
        let l = v.map(|c| c as usize % BRICK_SIDE);
        let at = (l[2] * BRICK_SIDE + l[1]) * BRICK_SIDE + l[0];
        let memo = LAST_BRICK.with_borrow(|last| match last {
            Some((id, r, brick)) if *id == self.id && *r == record => Some(brick[at]),
            _ => None,
        });
        let code = match memo {
            Some(code) => code,
            None => {
                let Some(brick) = self.brick(record) else {
                    return self.meta.background;
                };
                let code = brick[at];
                LAST_BRICK.set(Some((self.id, record, brick)));
                code
            }
        };
        self.meta.quantization.decode(code)
    }

    fn block_origins(&self) -> Result<Vec<Coord>, VolumeError> {
        let b = self.meta.bricks();
        let mut out = Vec::new();
        for z in 0..b[2] {
            for y in 0..b[1] {
                for x in 0..b[0] {
                    if self.table[self.meta.table_slot([x, y, z])] != NO_RECORD {
                        let b = [x, y, z];
                        let o = self.meta.index_origin;
                        out.push(std::array::from_fn(|k| (b[k] * BRICK_SIDE) as i32 + o[k]));
                    }
                }
            }
        }
        Ok(out)
    }

    fn map(&self) -> &GridMap {
        &self.map
    }
}
