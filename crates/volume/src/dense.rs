//! Dense voxel grids in index space and their reference lookups.

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
            }),
            _ => Err(VolumeError(format!(
                "impossible grid: origin {origin:?}, dims {dims:?}, background {background}"
            ))),
        }
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

    /// Nearest lookup at index-space point `p`: the voxel at `floor(p + 0.5)`.
    pub fn sample_nearest(&self, p: [f64; 3]) -> f32 {
        self.get(p.map(|c| (c + 0.5).floor() as i64))
    }

    /// Trilinear lookup at index-space point `p` (OpenVDB's box sampler), in f64.
    pub fn sample_trilinear(&self, p: [f64; 3]) -> f64 {
        let base = p.map(|c| c.floor());
        let frac: [f64; 3] = std::array::from_fn(|k| p[k] - base[k]);
        let mut sum = 0.0;
        for corner in 0..8 {
            let offset = [0, 1, 2].map(|k| (corner >> k & 1) as i64);
            let weight: f64 = (0..3)
                .map(|k| {
                    if offset[k] == 1 {
                        frac[k]
                    } else {
                        1.0 - frac[k]
                    }
                })
                .product();
            let ijk: [i64; 3] = std::array::from_fn(|k| base[k] as i64 + offset[k]);
            sum += weight * self.get(ijk) as f64;
        }
        sum
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lookups_follow_the_voxel_centre_convention() {
        let mut g = DenseGrid::new([-2, 0, 5], [4, 1, 1], 0.0).unwrap();
        for (i, x) in (-2..2).enumerate() {
            g.set([x, 0, 5], i as f32);
        }
        assert_eq!(g.get([-3, 0, 5]), 0.0);
        assert_eq!(g.sample_nearest([-0.51, 0.2, 5.4]), 1.0);
        assert_eq!(g.sample_nearest([-0.5, 0.2, 5.4]), 2.0);
        // Halfway between voxel -1 (value 1) and voxel 0 (value 2), on the voxel row.
        assert!((g.sample_trilinear([-0.5, 0.0, 5.0]) - 1.5).abs() < 1e-12);
        // A quarter voxel above the row blends with background 0 along y.
        assert!((g.sample_trilinear([-0.5, 0.25, 5.0]) - 1.125).abs() < 1e-12);
        assert!(DenseGrid::new([i32::MAX, 0, 0], [2, 1, 1], 0.0).is_err());
        assert!(DenseGrid::new([0; 3], [1, 1, 1], f32::NAN).is_err());
    }
}
