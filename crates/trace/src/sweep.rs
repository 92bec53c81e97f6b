//! Ray sweeps around a scene in the style of Opticks' ScanTest: `axis`, `rect` and
//! `circle` fans generated from the scene's bounds.

use hytrace_csg::{transform_bounds, EMPTY_AABB};
use hytrace_foundry::Foundry;

use crate::scan::RayRow;

/// A family of generated rays.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Sweep {
    /// `count` origins along the x axis through the scene centre, each shooting along +-y
    /// and +-z (many start inside solids and find exits).
    Axis,
    /// A `count` x `count` grid of parallel rays along +z, from below the scene.
    Rect,
    /// `count` origins on a circle around the scene (xz plane), aimed at the centre.
    Circle,
}

crate::choice::named!(Sweep {
    (Sweep::Axis, "axis", [], "`count` origins along the x axis through the scene centre, each shooting along +-y and +-z (many start inside solids and find exits)"),
    (Sweep::Rect, "rect", [], "A `count` x `count` grid of parallel rays along +z, from below the scene"),
    (Sweep::Circle, "circle", [], "`count` origins on a circle around the scene (xz plane), aimed at the centre"),
});

/// World bounds of every placed solid, `[min xyz, max xyz]` (`None` for an empty scene).
pub fn scene_bounds(f: &Foundry) -> Option<[f64; 6]> {
    let mut b = EMPTY_AABB;
    for (inst, tran) in f.inst.iter().zip(&f.inst_tran) {
        let a = f.solid[inst.solid as usize].aabb.map(f64::from);
        let w = transform_bounds(&a, &tran.to_transform());
        for k in 0..3 {
            b[k] = b[k].min(w[k]);
            b[k + 3] = b[k + 3].max(w[k + 3]);
        }
    }
    (b[0] <= b[3]).then_some(b)
}

/// A sweep too large to generate.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum SweepError {
    /// The number of rays does not fit in memory's address space.
    #[error("{sweep} sweep of count {count} has more rays than memory can index")]
    TooManyRays {
        /// The sweep.
        sweep: Sweep,
        /// The count asked for.
        count: usize,
    },
    /// The rays, with what a scan keeps per ray, do not fit in the available memory.
    #[error("{0}")]
    OutOfMemory(String),
}

/// Bytes a scan holds per ray at its peak: the ray (64), the tracer's answer (40), the
/// result's hit and identity (44) and the output array (up to 32), rounded up.
pub const SCAN_BYTES_PER_RAY: u64 = 200;

/// How many rays a sweep of `count` makes (`None` when that overflows).
pub fn ray_count(sweep: Sweep, count: usize) -> Option<usize> {
    let n = count.max(1);
    match sweep {
        Sweep::Axis => n.checked_mul(4),
        Sweep::Rect => n.checked_mul(n),
        Sweep::Circle => Some(n),
    }
}

/// Generates a sweep of about `count` (per side for `rect`) rays around `bounds`; an error,
/// before anything is allocated, when the rays a scan of them would hold
/// ([`SCAN_BYTES_PER_RAY`] each) exceed the available memory.
pub fn generate(sweep: Sweep, bounds: &[f64; 6], count: usize) -> Result<Vec<RayRow>, SweepError> {
    let total = ray_count(sweep, count).ok_or(SweepError::TooManyRays { sweep, count })?;
    let bytes = (total as u64).saturating_mul(SCAN_BYTES_PER_RAY);
    crate::memory::check_fits(&format!("{sweep} sweep of {total} rays"), bytes)
        .map_err(|e| SweepError::OutOfMemory(e.to_string()))?;
    let mut rays = Vec::new();
    rays.try_reserve_exact(total)
        .map_err(|e| SweepError::OutOfMemory(format!("{total} rays: {e}")))?;
    push_rays(sweep, bounds, count, &mut rays);
    Ok(rays)
}

/// Appends the rays of a sweep to `rays`, in order.
fn push_rays(sweep: Sweep, bounds: &[f64; 6], count: usize, rays: &mut Vec<RayRow>) {
    let centre: [f64; 3] = std::array::from_fn(|k| 0.5 * (bounds[k] + bounds[k + 3]));
    let half: [f64; 3] = std::array::from_fn(|k| 0.5 * (bounds[k + 3] - bounds[k]));
    let extent = half.iter().fold(0.0f64, |a, &h| a.max(h)).max(1e-6);
    let n = count.max(1);
    let frac = |i: usize| {
        if n == 1 {
            0.5
        } else {
            i as f64 / (n - 1) as f64
        }
    };
    let ray = |origin: [f64; 3], direction: [f64; 3]| RayRow {
        origin,
        direction,
        tmin: 0.0,
        tmax: f64::INFINITY,
    };
    match sweep {
        Sweep::Axis => rays.extend((0..n).flat_map(|i| {
            let x = centre[0] + 1.2 * half[0] * (2.0 * frac(i) - 1.0);
            let o = [x, centre[1], centre[2]];
            [
                [0.0, 1.0, 0.0],
                [0.0, -1.0, 0.0],
                [0.0, 0.0, 1.0],
                [0.0, 0.0, -1.0],
            ]
            .map(|d| ray(o, d))
        })),
        Sweep::Rect => rays.extend((0..n * n).map(|k| {
            let (i, j) = (k % n, k / n);
            let x = centre[0] + 1.2 * half[0] * (2.0 * frac(i) - 1.0);
            let y = centre[1] + 1.2 * half[1] * (2.0 * frac(j) - 1.0);
            ray([x, y, bounds[2] - 0.2 * extent - 1.0], [0.0, 0.0, 1.0])
        })),
        Sweep::Circle => rays.extend((0..n).map(|i| {
            let a = 2.0 * std::f64::consts::PI * i as f64 / n as f64;
            let (s, c) = a.sin_cos();
            let r = 2.0 * extent;
            ray(
                [centre[0] + r * c, centre[1], centre[2] + r * s],
                [-c, 0.0, -s],
            )
        })),
    }
}
