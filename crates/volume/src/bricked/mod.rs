//! The bricked grid: a sparse grid stored as 8^3 bricks in a linear atlas, for GPU lookups
//! (Falcor's BrickedGrid, with its weaknesses fixed).
//!
//! Layout:
//! - indirection: a dense u32 array over the bounding box of the stored bricks (brick units,
//!   x fastest), holding the brick's index in the brick table or [`NO_BRICK`] for a brick
//!   whose 512 voxels are all the background. Indices are u32, so there is no limit of 256
//!   bricks per axis (Falcor packs 8-bit atlas coordinates).
//! - brick table: one [`BrickEntry`] per stored brick, in z, y, x order of their origins:
//!   atlas slot ([`NO_SLOT`] for a constant brick, which stores no texels), decode offset and
//!   scale.
//! - atlas: slot `s` holds its brick's texels at bytes `s * format.bytes_per_brick()`, 512
//!   texels x fastest for unorm8/unorm16/f16/f32; for BC4 each z-slice is four 4x4 blocks of
//!   8 bytes, by block row then block column (32 blocks, 256 bytes).
//! - ranges: [`RangeMips`] of the *decoded* values, halo included, so a range bounds every
//!   lookup this representation answers.
//!
//! Decode, on the CPU here and on the GPU later: `value = offset + t * scale` in f32, `t`
//! being the texel in code units (see `quantize.rs` for each format; BC4's palette in
//! `bc4.rs`); a constant brick reads `offset`.

mod bc4;
mod convert;
mod format;
mod npy_dir;
mod quantize;

use hytrace_foundry::record;

use crate::dense::VolumeError;
use crate::grid::{Coord, GridMap, VoxelGrid, BLOCK_SIDE};
use crate::ranges::{RangeMips, ValueRange};

pub use format::TexelFormat;

/// Indirection value of a brick that is not stored (all its voxels are the background).
pub const NO_BRICK: u32 = u32::MAX;

/// Atlas slot of a constant brick (its value is the entry's `offset`).
pub const NO_SLOT: u32 = u32::MAX;

record! {
    /// One stored brick of a [`BrickedGrid`] (`bricks.npy`).
    pub struct BrickEntry {
        /// Index coordinate of the brick's first voxel (a multiple of 8).
        pub origin: [i32; 3],
        /// Atlas slot of the brick's texels; [`NO_SLOT`] for a constant brick.
        pub atlas_slot: u32,
        /// Decode offset: `value = offset + t * scale` (the value of a constant brick).
        pub offset: f32,
        /// Decode scale (0 for a constant brick).
        pub scale: f32,
        /// Voxels of the source brick whose value is not the background.
        pub active_voxels: u32,
        /// Largest |decoded - source| over the brick's voxels, rounded up to f32.
        pub max_error: f32,
    }
}

/// Bytes a bricked grid occupies, by array.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct MemoryBreakdown {
    /// The texel atlas.
    pub atlas: usize,
    /// The dense indirection array.
    pub indirection: usize,
    /// The brick table.
    pub brick_table: usize,
    /// The range mips (all levels).
    pub ranges: usize,
}

impl MemoryBreakdown {
    /// Sum of all arrays.
    pub fn total(&self) -> usize {
        self.atlas + self.indirection + self.brick_table + self.ranges
    }
}

/// A grid of 8^3 bricks with quantized texels in an atlas; see the module docs for the
/// layout and [`BrickedGrid::convert`] for its construction.
#[derive(Clone, Debug, PartialEq)]
pub struct BrickedGrid {
    format: TexelFormat,
    background: f32,
    map: GridMap,
    /// Brick coordinate of the indirection box's first brick.
    lo: Coord,
    /// Bricks of the indirection box along x, y, z.
    dims: [u32; 3],
    indirection: Vec<u32>,
    table: Vec<BrickEntry>,
    atlas: Vec<u8>,
    ranges: RangeMips,
    max_error: f64,
    analytic_bound: f64,
}

impl BrickedGrid {
    /// The same grid placed in world space by `map` (bricks, atlas and ranges live in index
    /// space and stay as they are).
    pub fn with_map(mut self, map: GridMap) -> BrickedGrid {
        self.map = map;
        self
    }

    /// The texel format.
    pub fn format(&self) -> TexelFormat {
        self.format
    }

    /// Brick coordinate of the indirection box's first brick and the box's size in bricks.
    pub fn indirection_box(&self) -> (Coord, [u32; 3]) {
        (self.lo, self.dims)
    }

    /// The indirection array, x fastest: brick-table indices or [`NO_BRICK`].
    pub fn indirection(&self) -> &[u32] {
        &self.indirection
    }

    /// The brick table.
    pub fn bricks(&self) -> &[BrickEntry] {
        &self.table
    }

    /// The atlas bytes (slot after slot).
    pub fn atlas(&self) -> &[u8] {
        &self.atlas
    }

    /// Number of atlas slots (stored bricks that are not constant).
    pub fn atlas_slots(&self) -> usize {
        self.atlas.len() / self.format.bytes_per_brick()
    }

    /// The halo-inclusive ranges of the decoded values.
    pub fn ranges(&self) -> &RangeMips {
        &self.ranges
    }

    /// Largest |decoded - source| over all voxels, measured during conversion with the
    /// decoder the lookups use (0 for the f32 format; voxels outside the stored bricks are
    /// the background in both). Never larger than [`BrickedGrid::analytic_error_bound`].
    pub fn error_bound(&self) -> f64 {
        self.max_error
    }

    /// The a priori bound on |decoded - source| given only each brick's `[min, max]`
    /// (`R = max - min`, `M = max(|min|, |max|)`, `u = 2^-24`), the largest over the bricks:
    /// - unorm with `N = 2^n - 1` codes: `R / (2N)` (half a quantum) + `4uR + 2uM` (f32 decode);
    /// - bc4: `R / 14` (half the spacing of an 8-level palette over all 255 codes) + `4uR + 2uM`;
    /// - f16: half an f16 ulp at `M` (raw), or at `R` plus `4uR + 2uM` (relative to the min);
    /// - f32: 0.
    ///
    /// Each term carries a relative slack of 2^-20 for the f64 encoder, plus subnormal steps.
    pub fn analytic_error_bound(&self) -> f64 {
        self.analytic_bound
    }

    /// Bytes by array.
    pub fn memory_bytes(&self) -> MemoryBreakdown {
        MemoryBreakdown {
            atlas: self.atlas.len(),
            indirection: self.indirection.len() * size_of::<u32>(),
            brick_table: self.table.len() * size_of::<BrickEntry>(),
            ranges: self.ranges.memory_bytes(),
        }
    }

    /// The range, at mip `level` (0..[`crate::RANGE_LEVELS`], panics beyond), of the block
    /// holding index-space point `p`: its `max` bounds every nearest, trilinear or stochastic
    /// lookup on this grid within that block (the background's range for non-finite points,
    /// which read the background).
    pub fn range_at(&self, level: usize, p: [f64; 3]) -> ValueRange {
        self.ranges.range_at(level, p)
    }

    /// The local majorant at mip `level` around index-space point `p` (see
    /// [`BrickedGrid::range_at`]).
    pub fn majorant(&self, level: usize, p: [f64; 3]) -> f32 {
        self.range_at(level, p).max
    }

    /// The table entry of brick `brick` (brick units), if stored.
    pub(crate) fn entry(&self, brick: Coord) -> Option<&BrickEntry> {
        let mut index = 0usize;
        for k in (0..3).rev() {
            let local = i64::from(brick[k]) - i64::from(self.lo[k]);
            if local < 0 || local >= i64::from(self.dims[k]) {
                return None;
            }
            index = index * self.dims[k] as usize + local as usize;
        }
        match self.indirection[index] {
            NO_BRICK => None,
            i => Some(&self.table[i as usize]),
        }
    }

    /// Voxel `i` (`x + 8 y + 64 z`) of a stored brick.
    fn decoded(&self, e: &BrickEntry, i: usize) -> f32 {
        if e.atlas_slot == NO_SLOT {
            return e.offset;
        }
        let size = self.format.bytes_per_brick();
        let start = e.atlas_slot as usize * size;
        let t = quantize::texel(self.format, &self.atlas[start..start + size], i);
        quantize::decode(e.offset, e.scale, t)
    }
}

impl VoxelGrid for BrickedGrid {
    fn background(&self) -> f32 {
        self.background
    }

    fn voxel(&self, ijk: Coord) -> f32 {
        match self.entry(ijk.map(|c| c >> 3)) {
            None => self.background,
            Some(e) => self.decoded(
                e,
                (ijk[0] & 7 | (ijk[1] & 7) << 3 | (ijk[2] & 7) << 6) as usize,
            ),
        }
    }

    fn block_origins(&self) -> Result<Vec<Coord>, VolumeError> {
        Ok(self.table.iter().map(|e| e.origin).collect())
    }

    fn map(&self) -> &GridMap {
        &self.map
    }

    fn read_box(&self, origin: Coord, dims: [u32; 3], out: &mut [f32]) {
        let side = i64::from(BLOCK_SIDE);
        let mut i = 0;
        for z in 0..i64::from(dims[2]) {
            for y in 0..i64::from(dims[1]) {
                let (wy, wz) = (i64::from(origin[1]) + y, i64::from(origin[2]) + z);
                let mut x = i64::from(origin[0]);
                let end = x + i64::from(dims[0]);
                // One run of voxels per brick crossed by the row.
                while x < end {
                    let run_end = end.min((x.div_euclid(side) + 1) * side);
                    let n = (run_end - x) as usize;
                    let fits = [x, wy, wz]
                        .iter()
                        .all(|c| *c >= i64::from(i32::MIN) && *c <= i64::from(i32::MAX));
                    let entry = if fits {
                        self.entry([x, wy, wz].map(|c| (c >> 3) as i32))
                    } else {
                        None
                    };
                    let row = &mut out[i..i + n];
                    match entry {
                        None => row.fill(self.background),
                        Some(e) => {
                            let base = ((wy & 7) << 3 | (wz & 7) << 6) as usize;
                            let lx = (x & 7) as usize;
                            for (k, v) in row.iter_mut().enumerate() {
                                *v = self.decoded(e, base + lx + k);
                            }
                        }
                    }
                    i += n;
                    x = run_end;
                }
            }
        }
    }
}
