//! The on-disk layout of a brick store: a directory of
//! - `store.json` ([`StoreMeta`]): dimensions, voxel size, background, quantization, counts;
//! - `superchunks.npy`, uint32 `(Sz, Sy, Sx, 4096)`: for each superchunk of 16^3 bricks,
//!   the record number of each of its bricks (local index `(z * 16 + y) * 16 + x`, 12 bits,
//!   as BrickMap), or [`NO_RECORD`] for a dropped brick (it reads as the background);
//! - `bricks.bin`: the kept bricks' 8^3 voxels as little-endian 16-bit codes, x fastest,
//!   1024 bytes a record, in record order;
//! - `brick_lod.npy`, float32 `(K, 9)`: each kept brick's coarser levels of detail, its
//!   mean (1^3) then the means of its eight 4^3 octants (2^3, x fastest);
//! - `ranges.npy`, float32 `(Bz + 2, By + 2, Bx + 2, 2)`: min and max of the decoded values
//!   every lookup in each 8^3 block reads (the block's voxels and a one-voxel halo), over
//!   the bricks grown by one block on each side; the finest level of the range mips.
//!
//! Store voxel `v` is index-space voxel `index_origin + v` of the source (a multiple of 8,
//! so bricks are the source's 8^3 blocks). A voxel's value is the background outside the
//! dimensions and in dropped bricks, and `lo + code * step` (in f32) in kept ones.

use serde::{Deserialize, Serialize};

/// Voxels along a brick's side.
pub const BRICK_SIDE: usize = 8;
/// Voxels in a brick.
pub const BRICK_VOXELS: usize = BRICK_SIDE * BRICK_SIDE * BRICK_SIDE;
/// Bytes of one brick record in `bricks.bin`.
pub const BRICK_BYTES: usize = BRICK_VOXELS * 2;
/// Bricks along a superchunk's side.
pub const SUPERCHUNK_SIDE: usize = 16;
/// Bricks in a superchunk (a 12-bit local index).
pub const SUPERCHUNK_BRICKS: usize = SUPERCHUNK_SIDE * SUPERCHUNK_SIDE * SUPERCHUNK_SIDE;
/// The superchunk table's entry of a dropped brick.
pub const NO_RECORD: u32 = u32::MAX;
/// `store.json`'s format name.
pub const STORE_FORMAT: &str = "hytrace-brick-store";
/// `store.json`'s format version.
pub const STORE_VERSION: u32 = 1;
/// Values of the coarser levels of detail per brick: the mean, then eight octant means.
pub const LOD_VALUES: usize = 9;

/// How voxel values become 16-bit codes: `value = lo + code * step`, in f32.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Quantization {
    /// The value of code 0 (the data's minimum).
    pub lo: f32,
    /// The value between consecutive codes (`(max - min) / 65535`, 0 for constant data).
    pub step: f32,
}

impl Quantization {
    /// The codes spanning `[min, max]`.
    pub fn spanning(min: f32, max: f32) -> Quantization {
        Quantization {
            lo: min,
            step: ((f64::from(max) - f64::from(min)) / 65535.0) as f32,
        }
    }

    /// The code nearest to `v` (clamped to the codes).
    pub fn encode(&self, v: f32) -> u16 {
        if self.step == 0.0 {
            return 0;
        }
        let q = ((f64::from(v) - f64::from(self.lo)) / f64::from(self.step)).round();
        q.clamp(0.0, 65535.0) as u16
    }

    /// The value of `code`.
    #[inline]
    pub fn decode(&self, code: u16) -> f32 {
        self.lo + f32::from(code) * self.step
    }
}

/// `store.json`: what a brick store holds.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StoreMeta {
    /// [`STORE_FORMAT`].
    pub format: String,
    /// [`STORE_VERSION`].
    pub version: u32,
    /// Voxels along x, y, z.
    pub dims: [u32; 3],
    /// Index-space coordinate of the store's first voxel; multiples of 8.
    pub index_origin: [i32; 3],
    /// Index-to-world map, linear part (row-major): `world = matrix * ijk + translation`.
    pub matrix: [[f64; 3]; 3],
    /// Index-to-world map, translation (the world position of index `(0, 0, 0)`).
    pub translation: [f64; 3],
    /// Value outside the dimensions and in dropped bricks.
    pub background: f32,
    /// Bricks whose decoded values all lie within this of the background were dropped.
    pub threshold: f32,
    /// The codes' values.
    pub quantization: Quantization,
    /// Kept bricks (records).
    pub kept_bricks: u64,
    /// Dropped bricks.
    pub dropped_bricks: u64,
    /// What the store was converted from (file name, type).
    pub source: String,
}

impl StoreMeta {
    /// Bricks along x, y, z.
    pub fn bricks(&self) -> [usize; 3] {
        self.dims.map(|d| (d as usize).div_ceil(BRICK_SIDE))
    }

    /// Superchunks along x, y, z.
    pub fn superchunks(&self) -> [usize; 3] {
        self.bricks().map(|b| b.div_ceil(SUPERCHUNK_SIDE))
    }

    /// The superchunk table's slot of brick `b` (brick coordinates inside the bricks).
    #[inline]
    pub fn table_slot(&self, b: [usize; 3]) -> usize {
        let s = self.superchunks();
        let c = b.map(|v| v / SUPERCHUNK_SIDE);
        let l = b.map(|v| v % SUPERCHUNK_SIDE);
        let chunk = (c[2] * s[1] + c[1]) * s[0] + c[0];
        chunk * SUPERCHUNK_BRICKS + (l[2] * SUPERCHUNK_SIDE + l[1]) * SUPERCHUNK_SIDE + l[0]
    }

    /// Entries of the superchunk table.
    pub fn table_len(&self) -> usize {
        self.superchunks().iter().product::<usize>() * SUPERCHUNK_BRICKS
    }

    /// Blocks of the `ranges.npy` box along x, y, z (the bricks grown by one on each side).
    pub fn range_dims(&self) -> [usize; 3] {
        self.bricks().map(|b| b + 2)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codes_round_trip_within_half_a_step_and_clamp() {
        let q = Quantization::spanning(-3.0, 5.0);
        for k in 0..=1000 {
            let v = -3.0 + 8.0 * k as f32 / 1000.0;
            let back = q.decode(q.encode(v));
            assert!((back - v).abs() <= q.step * 0.5 + 1e-6, "{v} -> {back}");
        }
        assert_eq!(q.encode(-100.0), 0);
        assert_eq!(q.encode(100.0), 65535);
        assert_eq!(q.decode(0), -3.0);
        let flat = Quantization::spanning(2.0, 2.0);
        assert_eq!((flat.encode(7.0), flat.decode(123)), (0, 2.0));
    }

    #[test]
    fn table_slots_are_a_bijection() {
        let meta = StoreMeta::for_dims([300, 9, 140]);
        let b = meta.bricks();
        let mut seen = vec![false; meta.table_len()];
        for z in 0..b[2] {
            for y in 0..b[1] {
                for x in 0..b[0] {
                    let s = meta.table_slot([x, y, z]);
                    assert!(!seen[s]);
                    seen[s] = true;
                }
            }
        }
    }
}
