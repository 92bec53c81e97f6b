//! What every voxel source shares: the index-to-world map, voxel access and the lookups.
//!
//! Index-space convention (as OpenVDB and NanoVDB): voxel centres sit at integer coordinates;
//! a nearest lookup reads the voxel at `floor(p + 0.5)`, a trilinear lookup blends the eight
//! voxels around `p` (OpenVDB's box sampler), a stochastic lookup reads one of those eight
//! voxels with probability equal to its trilinear weight, so its mean is the trilinear value.
//! Inactive voxels and voxels outside the grid read as the background.

use crate::dense::VolumeError;

/// A voxel coordinate in index space.
pub type Coord = [i32; 3];

/// Voxels per side of the blocks sources report and bricks hold (NanoVDB's leaf size).
pub const BLOCK_SIDE: i32 = 8;

/// Affine map between index space and world space: `world = matrix * ijk + translation`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GridMap {
    /// Linear part, row-major.
    pub matrix: [[f64; 3]; 3],
    /// Inverse of `matrix`.
    pub inverse: [[f64; 3]; 3],
    /// World position of index-space point (0, 0, 0).
    pub translation: [f64; 3],
}

fn mat_vec(m: &[[f64; 3]; 3], v: [f64; 3]) -> [f64; 3] {
    std::array::from_fn(|r| m[r][0] * v[0] + m[r][1] * v[1] + m[r][2] * v[2])
}

impl GridMap {
    /// Index space is world space.
    pub const IDENTITY: GridMap = GridMap {
        matrix: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        inverse: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        translation: [0.0; 3],
    };

    /// A map from its linear part and translation; errors when `matrix` is singular or not finite.
    pub fn new(matrix: [[f64; 3]; 3], translation: [f64; 3]) -> Result<GridMap, VolumeError> {
        let m = &matrix;
        let cof = |r: usize, c: usize| {
            let (r1, r2) = ((r + 1) % 3, (r + 2) % 3);
            let (c1, c2) = ((c + 1) % 3, (c + 2) % 3);
            m[r1][c1] * m[r2][c2] - m[r1][c2] * m[r2][c1]
        };
        let det = m[0][0] * cof(0, 0) + m[0][1] * cof(0, 1) + m[0][2] * cof(0, 2);
        let scale = m.iter().flatten().fold(0.0f64, |a, v| a.max(v.abs()));
        let finite = m
            .iter()
            .flatten()
            .chain(&translation)
            .all(|v| v.is_finite());
        if !finite || det.abs() <= 1e-12 * scale.powi(3) {
            return Err(VolumeError(format!(
                "index-to-world map is singular or not finite: {matrix:?} + {translation:?}"
            )));
        }
        // The inverse is the transposed cofactor matrix over the determinant.
        let inverse = std::array::from_fn(|r| std::array::from_fn(|c| cof(c, r) / det));
        Ok(GridMap {
            matrix,
            inverse,
            translation,
        })
    }

    /// Cubic voxels of side `voxel_size` with index (0, 0, 0) at `origin`.
    pub fn uniform(voxel_size: f64, origin: [f64; 3]) -> Result<GridMap, VolumeError> {
        let s = voxel_size;
        GridMap::new([[s, 0.0, 0.0], [0.0, s, 0.0], [0.0, 0.0, s]], origin)
    }

    /// World position of index-space point `p`.
    pub fn index_to_world(&self, p: [f64; 3]) -> [f64; 3] {
        let v = mat_vec(&self.matrix, p);
        std::array::from_fn(|k| v[k] + self.translation[k])
    }

    /// Index-space position of world point `p`.
    pub fn world_to_index(&self, p: [f64; 3]) -> [f64; 3] {
        mat_vec(
            &self.inverse,
            std::array::from_fn(|k| p[k] - self.translation[k]),
        )
    }

    /// Index-space image of world direction `d` (not normalized: a ray's parameter `t`
    /// stays the same in both spaces).
    pub fn world_dir_to_index(&self, d: [f64; 3]) -> [f64; 3] {
        mat_vec(&self.inverse, d)
    }

    /// Volume of one voxel in world units (|det matrix|).
    pub fn voxel_volume(&self) -> f64 {
        let m = &self.matrix;
        (m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
            - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]))
            .abs()
    }
}

/// A scalar field stored on voxels, read one voxel at a time.
pub trait VoxelGrid: Sync {
    /// Value of every inactive voxel and of every voxel outside the grid.
    fn background(&self) -> f32;

    /// Value of voxel `ijk` (the background when it is inactive or outside).
    fn voxel(&self, ijk: Coord) -> f32;

    /// Origins (multiples of [`BLOCK_SIDE`]) of the 8^3 blocks that may hold a value other
    /// than the background, each once, in no particular order; an error when they are too
    /// many to list (more than [`crate::MAX_RANGE_BLOCKS`], e.g. a 4096^3 tile).
    fn block_origins(&self) -> Result<Vec<Coord>, VolumeError>;

    /// The index-to-world map.
    fn map(&self) -> &GridMap;

    /// Reads voxels `origin .. origin + dims` into `out`, x fastest. Sources with a faster
    /// path than one [`VoxelGrid::voxel`] call per voxel override it.
    fn read_box(&self, origin: Coord, dims: [u32; 3], out: &mut [f32]) {
        let mut i = 0;
        for z in 0..dims[2] as i32 {
            for y in 0..dims[1] as i32 {
                for x in 0..dims[0] as i32 {
                    out[i] = self.voxel([origin[0] + x, origin[1] + y, origin[2] + z]);
                    i += 1;
                }
            }
        }
    }
}

/// How a lookup between voxel centres is filtered.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Filter {
    /// The voxel at `floor(p + 0.5)`.
    Nearest,
    /// The trilinear blend of the eight voxels around `p`.
    Trilinear,
    /// One of those eight voxels, chosen with probability equal to its trilinear weight.
    Stochastic,
}

/// The voxel coordinate `c`, or `None` when it lies outside the i32 index range (such
/// voxels read as the background).
fn to_coord(c: [f64; 3]) -> Option<Coord> {
    let ok = c
        .iter()
        .all(|v| *v >= i32::MIN as f64 && *v <= i32::MAX as f64);
    ok.then(|| c.map(|v| v as i32))
}

fn voxel_or_background<G: VoxelGrid + ?Sized>(g: &G, c: [f64; 3]) -> f32 {
    to_coord(c).map_or(g.background(), |ijk| g.voxel(ijk))
}

/// Nearest lookup at index-space point `p`.
pub fn sample_nearest<G: VoxelGrid + ?Sized>(g: &G, p: [f64; 3]) -> f32 {
    if p.iter().any(|v| !v.is_finite()) {
        return g.background();
    }
    voxel_or_background(g, p.map(|v| (v + 0.5).floor()))
}

/// Trilinear lookup at index-space point `p`, blended in f64.
pub fn sample_trilinear<G: VoxelGrid + ?Sized>(g: &G, p: [f64; 3]) -> f64 {
    if p.iter().any(|v| !v.is_finite()) {
        return g.background() as f64;
    }
    let base = p.map(f64::floor);
    let frac: [f64; 3] = std::array::from_fn(|k| p[k] - base[k]);
    // The eight voxels in one box read (sources resolve their block once), unless the box
    // leaves the i32 index range, where voxels read one by one (the outside ones as the
    // background).
    let mut corners = [0f32; 8];
    if base
        .iter()
        .all(|c| *c >= i32::MIN as f64 && *c < i32::MAX as f64)
    {
        g.read_box(base.map(|c| c as i32), [2, 2, 2], &mut corners);
    } else {
        for (corner, value) in corners.iter_mut().enumerate() {
            let c = std::array::from_fn(|k| base[k] + (corner >> k & 1) as f64);
            *value = voxel_or_background(g, c);
        }
    }
    let mut sum = 0.0;
    // Corner bits: x is bit 0, as read_box orders voxels x fastest.
    for (corner, value) in corners.iter().enumerate() {
        let weight: f64 = (0..3)
            .map(|k| {
                if corner >> k & 1 == 1 {
                    frac[k]
                } else {
                    1.0 - frac[k]
                }
            })
            .product();
        if weight != 0.0 {
            sum += weight * *value as f64;
        }
    }
    sum
}

/// Stochastic lookup at `p` with uniform numbers `u` in [0, 1): per axis the upper
/// neighbour is taken when `u < frac`, so each of the eight voxels is read with its
/// trilinear weight and the mean over `u` is the trilinear value (one fetch per lookup).
pub fn sample_stochastic<G: VoxelGrid + ?Sized>(g: &G, p: [f64; 3], u: [f64; 3]) -> f32 {
    if p.iter().any(|v| !v.is_finite()) {
        return g.background();
    }
    let base = p.map(f64::floor);
    let c = std::array::from_fn(|k| base[k] + ((u[k] < p[k] - base[k]) as u8) as f64);
    voxel_or_background(g, c)
}

/// A lookup with `filter`; `u` feeds the stochastic filter and is ignored by the others.
pub fn sample<G: VoxelGrid + ?Sized>(g: &G, p: [f64; 3], filter: Filter, u: [f64; 3]) -> f32 {
    match filter {
        Filter::Nearest => sample_nearest(g, p),
        Filter::Trilinear => sample_trilinear(g, p) as f32,
        Filter::Stochastic => sample_stochastic(g, p, u),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::DenseGrid;

    #[test]
    fn map_inverse_round_trips_and_singular_maps_fail() {
        let m = GridMap::new(
            [[0.5, 0.1, 0.0], [0.0, 0.25, -0.3], [0.2, 0.0, 2.0]],
            [10.0, -3.0, 1e6],
        )
        .unwrap();
        let p = [3.5, -7.25, 100.0];
        let back = m.world_to_index(m.index_to_world(p));
        for k in 0..3 {
            assert!((back[k] - p[k]).abs() < 1e-9, "{back:?}");
        }
        assert!(GridMap::new(
            [[1.0, 2.0, 3.0], [2.0, 4.0, 6.0], [0.0, 0.0, 1.0]],
            [0.0; 3]
        )
        .is_err());
        assert!(GridMap::uniform(f64::NAN, [0.0; 3]).is_err());
        assert!(GridMap::uniform(0.0, [0.0; 3]).is_err());
        assert!((GridMap::uniform(0.5, [0.0; 3]).unwrap().voxel_volume() - 0.125).abs() < 1e-15);
    }

    #[test]
    fn stochastic_lookups_average_to_trilinear() {
        let mut g = DenseGrid::new([0, 0, 0], [2, 2, 2], 0.0).unwrap();
        for (i, v) in g.values.iter_mut().enumerate() {
            *v = (i * i) as f32 + 1.0;
        }
        // Fractions on the strata grid, so the stratified mean is exact.
        let p = [19.0 / 64.0, 38.0 / 64.0, 54.0 / 64.0];
        let n = 64;
        let mut sum = 0.0;
        // A stratified grid of u: the mean is exact up to the stratification.
        for a in 0..n {
            for b in 0..n {
                for c in 0..n {
                    let u = [a, b, c].map(|x| (x as f64 + 0.5) / n as f64);
                    sum += sample_stochastic(&g, p, u) as f64;
                }
            }
        }
        let mean = sum / (n * n * n) as f64;
        assert!((mean - sample_trilinear(&g, p)).abs() < 1e-9, "{mean}");
    }

    #[test]
    fn far_and_non_finite_points_read_the_background() {
        let g = DenseGrid::new([0, 0, 0], [1, 1, 1], 0.25).unwrap();
        assert_eq!(sample_nearest(&g, [1e30, 0.0, 0.0]), 0.25);
        assert_eq!(sample_trilinear(&g, [f64::NAN, 0.0, 0.0]), 0.25);
        assert_eq!(
            sample_stochastic(&g, [0.0, f64::INFINITY, 0.0], [0.5; 3]),
            0.25
        );
        assert_eq!(sample_trilinear(&g, [2.147483647e9, 0.0, 0.0]), 0.25);
    }
}
