//! Procedural fog grids (Falcor's createSphere and createBox shapes), so tests and demos
//! need no files.
//!
//! Density is 1 deeper than `blend` voxels inside the shape and falls linearly to 0 at its
//! surface, as NanoVDB's fog volumes made from a level set with a narrow band of `blend`
//! voxels: value = clamp(inside distance / blend, 0, 1).

use crate::dense::{DenseGrid, VolumeError};

fn check_blend(what: &str, size: f64, blend: f64) -> Result<(), VolumeError> {
    if size.is_finite() && size > 0.0 && blend.is_finite() && blend > 0.0 {
        Ok(())
    } else {
        Err(VolumeError(format!(
            "fog {what} needs a finite size > 0 and a finite blend > 0, got size {size}, blend {blend}"
        )))
    }
}

/// Fills the voxels of `[-r, r]` per axis with `density(x, y, z)`.
fn fill(r: [i32; 3], density: impl Fn([f64; 3]) -> f64) -> Result<DenseGrid, VolumeError> {
    let dims = r.map(|v| (2 * v + 1) as u32);
    let mut g = DenseGrid::new(r.map(|v| -v), dims, 0.0)?;
    for z in -r[2]..=r[2] {
        for y in -r[1]..=r[1] {
            for x in -r[0]..=r[0] {
                let v = density([x, y, z].map(f64::from)).clamp(0.0, 1.0) as f32;
                g.set([x, y, z].map(i64::from), v);
            }
        }
    }
    Ok(g)
}

/// Most voxels per side of a procedural grid.
const MAX_SIDE: f64 = 4096.0;

fn half_side(what: &str, size: f64) -> Result<i32, VolumeError> {
    if size > MAX_SIDE / 2.0 {
        return Err(VolumeError(format!(
            "fog {what} of {size} voxels is larger than {} voxels per side",
            MAX_SIDE / 2.0
        )));
    }
    Ok(size.ceil() as i32)
}

/// A fog sphere of `radius` voxels centred on the index-space origin, with a linear blend
/// over the outer `blend` voxels.
pub fn fog_sphere(radius: f64, blend: f64) -> Result<DenseGrid, VolumeError> {
    check_blend("sphere", radius, blend)?;
    let r = half_side("sphere", radius)?;
    fill([r; 3], |p| {
        let d = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
        (radius - d) / blend
    })
}

/// A fog box of half extents `half` voxels centred on the index-space origin, with a linear
/// blend over the outer `blend` voxels (inside distance = the smallest distance to a face).
pub fn fog_box(half: [f64; 3], blend: f64) -> Result<DenseGrid, VolumeError> {
    for h in half {
        check_blend("box", h, blend)?;
    }
    let r = [
        half_side("box", half[0])?,
        half_side("box", half[1])?,
        half_side("box", half[2])?,
    ];
    fill(r, |p| {
        let inside = (0..3)
            .map(|k| half[k] - p[k].abs())
            .fold(f64::INFINITY, f64::min);
        inside / blend
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fog_shapes_have_the_requested_profile() {
        let g = fog_sphere(20.0, 4.0).unwrap();
        assert_eq!(g.get([0, 0, 0]), 1.0);
        assert_eq!(g.get([16, 0, 0]), 1.0);
        assert_eq!(g.get([18, 0, 0]), 0.5);
        assert_eq!(g.get([0, -19, 0]), 0.25);
        assert_eq!(g.get([20, 0, 0]), 0.0);
        let b = fog_box([10.0, 6.0, 4.0], 2.0).unwrap();
        assert_eq!(b.dims, [21, 13, 9]);
        assert_eq!(b.get([0, 0, 0]), 1.0);
        assert_eq!(b.get([9, 0, 0]), 0.5);
        assert_eq!(b.get([0, -5, 0]), 0.5);
        assert_eq!(b.get([9, 5, 3]), 0.5);
        assert_eq!(b.get([0, 0, 4]), 0.0);
        assert!(fog_sphere(1.0, 0.0).is_err());
        // A blend wider than the shape: the density peaks below 1.
        assert_eq!(fog_sphere(1.0, 2.0).unwrap().get([0, 0, 0]), 0.5);
        assert!(fog_sphere(f64::NAN, 1.0).is_err());
        assert!(fog_box([3.0, -1.0, 2.0], 1.0).is_err());
        assert!(fog_sphere(1e9, 3.0).is_err());
    }
}
