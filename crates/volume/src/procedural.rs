//! Procedural grids, so tests and demos need no files.

use crate::dense::{DenseGrid, VolumeError};

/// A fog sphere of `radius` voxels centred on the index-space origin: density 1 inside
/// `radius - blend`, falling linearly to 0 at `radius` (Falcor's createSphere shape).
pub fn fog_sphere(radius: f64, blend: f64) -> Result<DenseGrid, VolumeError> {
    if !(radius.is_finite() && radius > 0.0 && blend.is_finite() && blend > 0.0 && blend <= radius)
    {
        return Err(VolumeError(format!(
            "fog sphere needs 0 < blend <= radius, got radius {radius}, blend {blend}"
        )));
    }
    let r = radius.ceil() as i32;
    let side = (2 * r + 1) as u32;
    let mut g = DenseGrid::new([-r; 3], [side; 3], 0.0)?;
    for z in -r..=r {
        for y in -r..=r {
            for x in -r..=r {
                let d = ((x * x + y * y + z * z) as f64).sqrt();
                let v = ((radius - d) / blend).clamp(0.0, 1.0) as f32;
                g.set([x, y, z].map(i64::from), v);
            }
        }
    }
    Ok(g)
}
