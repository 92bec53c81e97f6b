//! The mixed scene of the mixed benchmarks (`scenes/mixed.toml` with 400 sensors) and its
//! two ray sets, shared by `benches/mixed.rs` (CPU and Embree) and `benches/gpu.rs`.

use std::path::Path;

use hytrace_trace::scan::RayRow;
use hytrace_volume::Rng;

/// The mixed scene's text: `scenes/mixed.toml` with a grid of sensors added.
pub fn scene_text() -> String {
    let mut text = std::fs::read_to_string(scenes_dir().join("mixed.toml")).unwrap();
    for i in 0..20 {
        for j in 0..20 {
            let (x, y) = (-570.0 + 60.0 * i as f64, -570.0 + 60.0 * j as f64);
            text += &format!(
                "\n[[place]]\nsolid = \"sensor\"\ntranslate = [{x}, {y}, 700]\nrotate = [1, 0, 0, 180]\n"
            );
        }
    }
    text
}

/// The repository's `scenes` directory.
pub fn scenes_dir() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes")
}

/// `n` parallel rays straight down from just below the tank's open top, on a square
/// grid in 8x8 tiles.
pub fn coherent_rays(n: usize) -> Vec<RayRow> {
    let side = (n as f64).sqrt().ceil() as usize;
    let tiles = side.div_ceil(8);
    let mut rows = Vec::with_capacity(side * side);
    for tile in 0..tiles * tiles {
        let (ti, tj) = (tile % tiles, tile / tiles);
        for k in 0..64 {
            let (i, j) = (ti * 8 + k % 8, tj * 8 + k / 8);
            if i >= side || j >= side {
                continue;
            }
            let u = |c: usize| -580.0 + 1160.0 * (c as f64 + 0.5) / side as f64;
            rows.push(RayRow {
                origin: [u(i), u(j), 390.0],
                direction: [0.0, 0.0, -1.0],
                tmin: 0.0,
                tmax: f64::INFINITY,
            });
        }
    }
    rows.truncate(n);
    rows
}

/// `n` rays from origins uniform in the tank, directions uniform over the sphere.
pub fn incoherent_rays(n: usize) -> Vec<RayRow> {
    (0..n)
        .map(|i| {
            let mut rng = Rng::new(11, i as u32, 0);
            let mut u = || rng.next_f64();
            let origin = [
                -580.0 + 1160.0 * u(),
                -580.0 + 1160.0 * u(),
                -380.0 + 760.0 * u(),
            ];
            let z = 2.0 * u() - 1.0;
            let phi = std::f64::consts::TAU * u();
            let r = (1.0 - z * z).sqrt();
            RayRow {
                origin,
                direction: [r * phi.cos(), r * phi.sin(), z],
                tmin: 0.0,
                tmax: f64::INFINITY,
            }
        })
        .collect()
}
