//! Procedural grids named on the command line, in place of a file:
//! `sphere:RADIUS[,VOXEL[,BLEND]]` and `box:WIDTH,HEIGHT,DEPTH[,VOXEL[,BLEND]]`, with the
//! arguments of Falcor's createSphere/createBox: sizes in world units, cubic voxels of side
//! VOXEL (default 1) centred on the world origin, and a density blend over the outer BLEND
//! voxels (default 3).

use crate::dense::{DenseGrid, VolumeError};
use crate::grid::GridMap;
use crate::procedural::{fog_box, fog_sphere};

const DEFAULT_VOXEL: f64 = 1.0;
const DEFAULT_BLEND: f64 = 3.0;

/// Whether `spec` names a procedural grid rather than a file.
pub fn is_procedural(spec: &str) -> bool {
    spec.starts_with("sphere:") || spec.starts_with("box:")
}

/// The fog grid `spec` names (see the module documentation).
pub fn procedural_grid(spec: &str) -> Result<DenseGrid, VolumeError> {
    let bad = |why: String| VolumeError(format!("procedural grid `{spec}`: {why}"));
    let (shape, args) = spec
        .split_once(':')
        .ok_or_else(|| bad("expected sphere:... or box:...".into()))?;
    let numbers = args
        .split(',')
        .map(|a| {
            a.trim()
                .parse::<f64>()
                .map_err(|_| bad(format!("`{a}` is not a number")))
        })
        .collect::<Result<Vec<f64>, VolumeError>>()?;
    let sizes = match shape {
        "sphere" => 1,
        "box" => 3,
        _ => return Err(bad(format!("unknown shape `{shape}`"))),
    };
    if numbers.len() < sizes || numbers.len() > sizes + 2 {
        return Err(bad(format!(
            "{shape} takes {sizes} size(s), then optionally the voxel size and the blend in voxels"
        )));
    }
    let voxel = numbers.get(sizes).copied().unwrap_or(DEFAULT_VOXEL);
    let blend = numbers.get(sizes + 1).copied().unwrap_or(DEFAULT_BLEND);
    let map = GridMap::uniform(voxel, [0.0; 3])
        .map_err(|_| bad(format!("voxel size {voxel} must be finite and > 0")))?;
    let grid = match shape {
        "sphere" => fog_sphere(numbers[0] / voxel, blend),
        _ => fog_box(std::array::from_fn(|k| numbers[k] / voxel / 2.0), blend),
    }
    .map_err(|e| bad(e.0))?;
    Ok(grid.with_map(map))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::{sample_nearest, VoxelGrid};

    #[test]
    fn specs_build_falcor_shapes_in_world_units() {
        let s = procedural_grid("sphere:2.0,0.1,4").unwrap();
        assert_eq!(s.origin, [-20; 3]);
        // World point (1.9, 0, 0) is index 19: one voxel inside a 4-voxel blend.
        let p = s.map().world_to_index([1.9, 0.0, 0.0]);
        assert_eq!(sample_nearest(&s, p), 0.25);
        let b = procedural_grid("box:4,2,2").unwrap();
        assert_eq!(b.dims, [5, 3, 3]);
        assert!(is_procedural("box:1,1,1") && !is_procedural("fog.nvdb"));
        for bad in [
            "sphere:",
            "sphere:x",
            "sphere:1,0",
            "box:1,2",
            "cone:1",
            "sphere:1,1,1,1",
            "sphere:-1",
        ] {
            let e = procedural_grid(bad).unwrap_err();
            assert!(e.0.contains(bad), "{e}");
        }
    }
}
