//! Ray sweeps around a scene in the style of Opticks' ScanTest: `axis`, `rect` and
//! `circle` fans generated from the scene's bounds.

use hytrace_csg::{transform_bounds, EMPTY_AABB};
use hytrace_foundry::Foundry;

use crate::scan::RayRow;

/// A family of generated rays.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Sweep {
    /// `count` origins along the x axis through the scene centre, each shooting along +-y
    /// and +-z (many start inside solids and find exits).
    Axis,
    /// A `count` x `count` grid of parallel rays along +z, from below the scene.
    Rect,
    /// `count` origins on a circle around the scene (xz plane), aimed at the centre.
    Circle,
}

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

/// Generates a sweep of about `count` (per side for `rect`) rays around `bounds`.
pub fn generate(sweep: Sweep, bounds: &[f64; 6], count: usize) -> Vec<RayRow> {
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
        Sweep::Axis => (0..n)
            .flat_map(|i| {
                let x = centre[0] + 1.2 * half[0] * (2.0 * frac(i) - 1.0);
                let o = [x, centre[1], centre[2]];
                [
                    [0.0, 1.0, 0.0],
                    [0.0, -1.0, 0.0],
                    [0.0, 0.0, 1.0],
                    [0.0, 0.0, -1.0],
                ]
                .map(|d| ray(o, d))
            })
            .collect(),
        Sweep::Rect => (0..n * n)
            .map(|k| {
                let (i, j) = (k % n, k / n);
                let x = centre[0] + 1.2 * half[0] * (2.0 * frac(i) - 1.0);
                let y = centre[1] + 1.2 * half[1] * (2.0 * frac(j) - 1.0);
                ray([x, y, bounds[2] - 0.2 * extent - 1.0], [0.0, 0.0, 1.0])
            })
            .collect(),
        Sweep::Circle => (0..n)
            .map(|i| {
                let a = 2.0 * std::f64::consts::PI * i as f64 / n as f64;
                let (s, c) = a.sin_cos();
                let r = 2.0 * extent;
                ray(
                    [centre[0] + r * c, centre[1], centre[2] + r * s],
                    [-c, 0.0, -s],
                )
            })
            .collect(),
    }
}
