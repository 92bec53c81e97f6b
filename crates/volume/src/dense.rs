//! Dense voxel grids in index space.

use crate::grid::{Coord, GridMap, VoxelGrid, BLOCK_SIDE};

/// A grid that cannot be built.
#[derive(Debug, thiserror::Error, PartialEq)]
#[error("volume: {0}")]
pub struct VolumeError(pub String);

/// Voxels of a box of index space, x fastest.
#[derive(Clone, Debug, PartialEq)]
pub struct DenseGrid {
    /// Index coordinate of the first voxel.
    pub origin: [i32; 3],
    /// Number of voxels along x, y, z.
    pub dims: [u32; 3],
    /// Values, `dims[0] * dims[1] * dims[2]` of them, x fastest.
    pub values: Vec<f32>,
    /// Value of every voxel outside the box (and of inactive voxels).
    pub background: f32,
    /// Index-to-world map.
    pub map: GridMap,
}

impl DenseGrid {
    /// A grid of `dims` voxels starting at `origin`, filled with `background`.
    pub fn new(
        origin: [i32; 3],
        dims: [u32; 3],
        background: f32,
    ) -> Result<DenseGrid, VolumeError> {
        let count = dims
            .iter()
            .try_fold(1usize, |a, &d| a.checked_mul(d as usize));
        let fits = (0..3).all(|k| origin[k] as i64 + dims[k] as i64 <= i32::MAX as i64);
        match count {
            Some(n) if fits && background.is_finite() => Ok(DenseGrid {
                origin,
                dims,
                values: vec![background; n],
                background,
                map: GridMap::IDENTITY,
            }),
            _ => Err(VolumeError(format!(
                "impossible grid: origin {origin:?}, dims {dims:?}, background {background}"
            ))),
        }
    }

    /// The same grid placed in world space by `map`.
    pub fn with_map(mut self, map: GridMap) -> DenseGrid {
        self.map = map;
        self
    }

    fn slot(&self, ijk: [i64; 3]) -> Option<usize> {
        let mut index = 0usize;
        for k in (0..3).rev() {
            let local = ijk[k] - self.origin[k] as i64;
            if local < 0 || local >= self.dims[k] as i64 {
                return None;
            }
            index = index * self.dims[k] as usize + local as usize;
        }
        Some(index)
    }

    /// The value of voxel `ijk` (background outside the box).
    pub fn get(&self, ijk: [i64; 3]) -> f32 {
        self.slot(ijk).map_or(self.background, |s| self.values[s])
    }

    /// Sets voxel `ijk`; returns false (and changes nothing) outside the box.
    pub fn set(&mut self, ijk: [i64; 3], value: f32) -> bool {
        match self.slot(ijk) {
            Some(s) => {
                self.values[s] = value;
                true
            }
            None => false,
        }
    }
}

impl VoxelGrid for DenseGrid {
    fn background(&self) -> f32 {
        self.background
    }

    fn voxel(&self, ijk: Coord) -> f32 {
        self.get(ijk.map(i64::from))
    }

    fn block_origins(&self) -> Result<Vec<Coord>, VolumeError> {
        let b = BLOCK_SIDE as i64;
        let lo: [i64; 3] = std::array::from_fn(|k| (self.origin[k] as i64).div_euclid(b));
        let hi: [i64; 3] = std::array::from_fn(|k| {
            (self.origin[k] as i64 + self.dims[k] as i64 - 1).div_euclid(b)
        });
        let mut out = Vec::new();
        for z in lo[2]..=hi[2] {
            for y in lo[1]..=hi[1] {
                for x in lo[0]..=hi[0] {
                    out.push([x, y, z].map(|c| (c * b) as i32));
                }
            }
        }
        Ok(out)
    }

    fn map(&self) -> &GridMap {
        &self.map
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{sample_nearest, sample_trilinear};

    #[test]
    fn lookups_follow_the_voxel_centre_convention() {
        let mut g = DenseGrid::new([-2, 0, 5], [4, 1, 1], 0.0).unwrap();
        for (i, x) in (-2..2).enumerate() {
            g.set([x, 0, 5], i as f32);
        }
        assert_eq!(g.get([-3, 0, 5]), 0.0);
        assert_eq!(sample_nearest(&g, [-0.51, 0.2, 5.4]), 1.0);
        assert_eq!(sample_nearest(&g, [-0.5, 0.2, 5.4]), 2.0);
        // Halfway between voxel -1 (value 1) and voxel 0 (value 2), on the voxel row.
        assert!((sample_trilinear(&g, [-0.5, 0.0, 5.0]) - 1.5).abs() < 1e-12);
        // A quarter voxel above the row blends with background 0 along y.
        assert!((sample_trilinear(&g, [-0.5, 0.25, 5.0]) - 1.125).abs() < 1e-12);
        assert!(DenseGrid::new([i32::MAX, 0, 0], [2, 1, 1], 0.0).is_err());
        assert!(DenseGrid::new([0; 3], [1, 1, 1], f32::NAN).is_err());
    }
}
