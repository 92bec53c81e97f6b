//! Halo-inclusive value ranges of 8^3 blocks and their 2x2x2 mips (min/max "range mips").
//!
//! Block `b` of level `l` has side `s = 8 * 2^l` voxels and covers voxels `s*b .. s*b + s - 1`;
//! its lookup region is `[s*b - 0.5, s*b + s - 0.5)` on each axis (the points whose nearest
//! voxel lies in the block). A trilinear or stochastic lookup there reads voxels
//! `s*b - 1 ..= s*b + s`, so every range spans that halo-inclusive set: `max` bounds every
//! lookup in the block (a true majorant), `min` is a true minorant, for constant and
//! background-only blocks as well.

use rayon::prelude::*;

use crate::dense::VolumeError;
use crate::grid::{Coord, VoxelGrid, BLOCK_SIDE};

/// Number of mip levels: blocks of 8, 16, 32 and 64 voxels per side.
pub const RANGE_LEVELS: usize = 4;

/// Most blocks a level may hold (dense over the bounding box of the data).
pub const MAX_RANGE_BLOCKS: u64 = 1 << 27;

/// Smallest and largest value of a set of lookups.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ValueRange {
    /// Smallest value.
    pub min: f32,
    /// Largest value.
    pub max: f32,
}

impl ValueRange {
    /// The range of no values (the identity of [`ValueRange::union`]).
    pub const EMPTY: ValueRange = ValueRange {
        min: f32::INFINITY,
        max: f32::NEG_INFINITY,
    };

    /// The range of the single value `v`.
    pub fn constant(v: f32) -> ValueRange {
        ValueRange { min: v, max: v }
    }

    /// The smallest range holding both.
    pub fn union(self, other: ValueRange) -> ValueRange {
        ValueRange {
            min: self.min.min(other.min),
            max: self.max.max(other.max),
        }
    }

    /// The smallest range holding `self` and `v`.
    pub fn with(self, v: f32) -> ValueRange {
        self.union(ValueRange::constant(v))
    }

    /// Whether every value in the range is `v`.
    pub fn is_constant(&self, v: f32) -> bool {
        self.min == v && self.max == v
    }
}

/// One level of the range mips: a dense box of blocks.
#[derive(Clone, Debug, PartialEq)]
pub struct RangeLevel {
    /// Voxels per block side.
    pub side: u32,
    /// Block coordinate of the box's first block.
    pub lo: Coord,
    /// Blocks along x, y, z.
    pub dims: [u32; 3],
    /// Ranges, x fastest.
    pub ranges: Vec<ValueRange>,
}

impl RangeLevel {
    fn slot(&self, block: Coord) -> Option<usize> {
        let mut index = 0usize;
        for k in (0..3).rev() {
            let local = block[k] as i64 - self.lo[k] as i64;
            if local < 0 || local >= self.dims[k] as i64 {
                return None;
            }
            index = index * self.dims[k] as usize + local as usize;
        }
        Some(index)
    }

    fn block_of_slot(&self, slot: usize) -> Coord {
        let x = slot % self.dims[0] as usize;
        let y = slot / self.dims[0] as usize % self.dims[1] as usize;
        let z = slot / (self.dims[0] as usize * self.dims[1] as usize);
        let local = [x, y, z];
        std::array::from_fn(|k| self.lo[k] + local[k] as i32)
    }
}

/// Halo-inclusive ranges of every block at [`RANGE_LEVELS`] levels.
#[derive(Clone, Debug, PartialEq)]
pub struct RangeMips {
    /// The grid's background (the range of every block outside the levels' boxes).
    pub background: f32,
    /// Levels, finest (8^3 blocks) first.
    pub levels: Vec<RangeLevel>,
}

fn level_box(lo: [i64; 3], hi: [i64; 3], side: u32) -> Result<RangeLevel, VolumeError> {
    let dims: [u64; 3] = std::array::from_fn(|k| (hi[k] - lo[k] + 1).max(0) as u64);
    let count = dims[0] * dims[1] * dims[2];
    if count > MAX_RANGE_BLOCKS {
        return Err(VolumeError(format!(
            "the grid's data spans {dims:?} blocks of {side}^3 voxels, more than {MAX_RANGE_BLOCKS}"
        )));
    }
    Ok(RangeLevel {
        side,
        lo: lo.map(|v| v as i32),
        dims: dims.map(|v| v as u32),
        ranges: Vec::new(),
    })
}

impl RangeMips {
    /// The ranges of the lookups `grid` answers. Blocks are read in parallel.
    pub fn build<G: VoxelGrid + ?Sized>(grid: &G) -> Result<RangeMips, VolumeError> {
        let background = grid.background();
        let origins = grid.block_origins()?;
        let b = BLOCK_SIDE as i64;
        let blocks: Vec<[i64; 3]> = origins
            .iter()
            .map(|o| o.map(|c| (c as i64).div_euclid(b)))
            .collect();
        // The level-0 box holds every block whose halo touches a data block: the data
        // blocks' bounding box grown by one block.
        // An empty source gets empty boxes (hi = lo - 1): every block reads the background.
        let (mut lo, mut hi) = if blocks.is_empty() {
            ([0; 3], [-1; 3])
        } else {
            ([i64::MAX; 3], [i64::MIN; 3])
        };
        for blk in &blocks {
            for k in 0..3 {
                lo[k] = lo[k].min(blk[k] - 1);
                hi[k] = hi[k].max(blk[k] + 1);
            }
        }
        let mut level0 = level_box(lo, hi, BLOCK_SIDE as u32)?;
        let count = level0.dims.iter().map(|d| *d as usize).product::<usize>();
        // Mark the data blocks and their 26 neighbours; every other block is background.
        let mut marked = vec![false; count];
        for blk in &blocks {
            for dz in -1..=1 {
                for dy in -1..=1 {
                    for dx in -1..=1 {
                        let c = [blk[0] + dx, blk[1] + dy, blk[2] + dz].map(|v| v as i32);
                        if let Some(s) = level0.slot(c) {
                            marked[s] = true;
                        }
                    }
                }
            }
        }
        let halo = BLOCK_SIDE as u32 + 2;
        level0.ranges = (0..count)
            .into_par_iter()
            .map_init(
                || vec![0f32; (halo * halo * halo) as usize],
                |buffer, slot| {
                    if !marked[slot] {
                        return ValueRange::constant(background);
                    }
                    let blk = level0.block_of_slot(slot);
                    let origin = blk.map(|c| c * BLOCK_SIDE - 1);
                    grid.read_box(origin, [halo; 3], buffer);
                    buffer.iter().fold(ValueRange::EMPTY, |r, v| r.with(*v))
                },
            )
            .collect();
        RangeMips::from_finest(background, level0)
    }

    /// The mips over a finest level of halo-inclusive 8^3 block ranges computed elsewhere
    /// (e.g. by a brick store's converter); the coarser levels are their unions.
    pub fn from_finest(background: f32, level0: RangeLevel) -> Result<RangeMips, VolumeError> {
        let count = level0.dims.iter().map(|d| *d as usize).product::<usize>();
        if level0.side != BLOCK_SIDE as u32 || level0.ranges.len() != count {
            return Err(VolumeError(format!(
                "range mips: the finest level needs {count} ranges of {BLOCK_SIDE}^3 blocks, got {} of {}^3",
                level0.ranges.len(),
                level0.side
            )));
        }
        let mut levels = vec![level0];
        for l in 1..RANGE_LEVELS {
            let fine = &levels[l - 1];
            let lo = fine.lo.map(|c| (c as i64).div_euclid(2));
            let hi: [i64; 3] = std::array::from_fn(|k| {
                (fine.lo[k] as i64 + fine.dims[k] as i64 - 1).div_euclid(2)
            });
            let mut coarse = level_box(lo, hi, fine.side * 2)?;
            let n = coarse.dims.iter().map(|d| *d as usize).product::<usize>();
            coarse.ranges = (0..n)
                .into_par_iter()
                .map(|slot| {
                    let c = coarse.block_of_slot(slot);
                    let mut r = ValueRange::EMPTY;
                    for child in 0..8 {
                        let f = std::array::from_fn(|k| c[k] * 2 + (child >> k & 1));
                        r = r.union(fine.range_or(f, background));
                    }
                    r
                })
                .collect();
            levels.push(coarse);
        }
        Ok(RangeMips { background, levels })
    }

    /// The range of block `block` at `level` (the background's outside the level's box).
    pub fn range(&self, level: usize, block: Coord) -> ValueRange {
        self.levels[level].range_or(block, self.background)
    }

    /// The range at `level` (panics beyond the levels) of the block holding index-space
    /// point `p` (the background's range for non-finite points, which read the background).
    pub fn range_at(&self, level: usize, p: [f64; 3]) -> ValueRange {
        if p.iter().any(|c| !c.is_finite()) {
            return ValueRange::constant(self.background);
        }
        let side = f64::from(self.levels[level].side);
        // The block whose voxels are nearest to p (lookup regions are [s b - 0.5, s b + s - 0.5));
        // the float-to-int cast saturates far outside, where every block is the background's.
        let block = p.map(|c| ((c + 0.5) / side).floor() as i32);
        self.range(level, block)
    }

    /// Bytes the ranges occupy.
    pub fn memory_bytes(&self) -> usize {
        self.levels
            .iter()
            .map(|l| l.ranges.len() * size_of::<ValueRange>())
            .sum()
    }
}

impl RangeLevel {
    fn range_or(&self, block: Coord, background: f32) -> ValueRange {
        self.slot(block)
            .map_or(ValueRange::constant(background), |s| self.ranges[s])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{sample_nearest, sample_trilinear, DenseGrid, Rng};

    /// The next uniform number in [0, 1) of `state` (the crate's counter-based generator).
    fn rng(state: &mut Rng) -> f64 {
        state.next_f64()
    }

    #[test]
    fn every_level_bounds_every_lookup_in_its_blocks() {
        let mut state = Rng::new(11, 0, 0);
        let mut g = DenseGrid::new([-37, 5, -70], [45, 29, 80], 0.5).unwrap();
        for v in g.values.iter_mut() {
            if rng(&mut state) < 0.4 {
                *v = (rng(&mut state) * 10.0 - 3.0) as f32;
            }
        }
        let mips = RangeMips::build(&g).unwrap();
        for _ in 0..40_000 {
            let p: [f64; 3] = std::array::from_fn(|k| {
                g.origin[k] as f64 - 20.0 + rng(&mut state) * (g.dims[k] as f64 + 40.0)
            });
            let v = sample_trilinear(&g, p) as f32;
            let n = sample_nearest(&g, p);
            for (l, level) in mips.levels.iter().enumerate() {
                let side = level.side as f64;
                let block = p.map(|c| ((c + 0.5) / side).floor() as i32);
                let r = mips.range(l, block);
                for x in [v, n] {
                    assert!(
                        r.min <= x + 1e-5 && x <= r.max + 1e-5,
                        "level {l} block {block:?} range {r:?} misses {x} at {p:?}"
                    );
                }
            }
        }
        // The coarsest levels are unions of their children.
        assert_eq!(mips.levels.len(), RANGE_LEVELS);
        assert_eq!(mips.levels[3].side, 64);
        assert!(mips.memory_bytes() > 0);
    }

    #[test]
    fn blocks_of_background_next_to_data_carry_the_halo() {
        let mut g = DenseGrid::new([0, 0, 0], [8, 8, 8], 0.0).unwrap();
        g.set([7, 7, 7], 2.0);
        let mips = RangeMips::build(&g).unwrap();
        // Block (1,1,1) holds only background voxels, yet a lookup at 7.75 reads voxel 7.
        let r = mips.range(0, [1, 1, 1]);
        assert_eq!((r.min, r.max), (0.0, 2.0));
        assert_eq!(mips.range(0, [2, 2, 2]), ValueRange::constant(0.0));
        assert_eq!(mips.range(0, [-5, 900, 3]), ValueRange::constant(0.0));
    }

    #[test]
    fn a_grid_of_background_only_has_empty_levels() {
        let g = DenseGrid::new([0, 0, 0], [0, 0, 0], 0.5).unwrap();
        let mips = RangeMips::build(&g).unwrap();
        assert_eq!(mips.levels.len(), RANGE_LEVELS);
        assert!(mips.levels.iter().all(|l| l.ranges.is_empty()));
        assert_eq!(mips.range(2, [0, 0, 0]), ValueRange::constant(0.5));
    }
}
