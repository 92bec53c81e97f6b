//! The 1M-triangle heightfield of the mesh benchmarks and its two ray sets, shared by
//! `benches/mesh.rs` (CPU and Embree) and `benches/gpu.rs`.

use std::io::Write;
use std::path::Path;

use hytrace_csg::{Ray, V3};
use hytrace_volume::Rng;

/// Vertices (row-major, `(n + 1)^2`) and counter-clockwise (seen from above) triangles of
/// an `n x n` grid of unit quads with smooth pseudo-random heights: six octaves of plane
/// waves, amplitudes halving as frequencies double.
pub fn heightfield(n: usize) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
    let mut rng = Rng::new(6, 0, 0);
    let waves: Vec<[f64; 4]> = (0..6)
        .map(|k| {
            let angle = rng.next_f64() * std::f64::consts::TAU;
            let freq = std::f64::consts::TAU * f64::from(1u32 << k) / n as f64 * 1.5;
            let amp = 0.06 * n as f64 / f64::from(1u32 << k);
            [
                freq * angle.cos(),
                freq * angle.sin(),
                rng.next_f64() * std::f64::consts::TAU,
                amp,
            ]
        })
        .collect();
    let mut vertices = Vec::with_capacity((n + 1) * (n + 1));
    for i in 0..=n {
        for j in 0..=n {
            let (x, y) = (i as f64, j as f64);
            let z: f64 = waves
                .iter()
                .map(|w| w[3] * (w[0] * x + w[1] * y + w[2]).sin())
                .sum();
            // Float32 vertices, what Embree and the Foundry hold.
            vertices.push([x, y, z].map(|c| c as f32 as f64));
        }
    }
    let idx = |i: usize, j: usize| (i * (n + 1) + j) as u32;
    let mut faces = Vec::with_capacity(2 * n * n);
    for i in 0..n {
        for j in 0..n {
            let (a, b, c, d) = (idx(i, j), idx(i + 1, j), idx(i + 1, j + 1), idx(i, j + 1));
            faces.push([a, b, c]);
            faces.push([a, c, d]);
        }
    }
    (vertices, faces)
}

/// Writes the mesh as a Wavefront OBJ (one object, f32 coordinates).
pub fn write_obj(path: &Path, vertices: &[[f64; 3]], faces: &[[u32; 3]]) {
    let mut w = std::io::BufWriter::new(std::fs::File::create(path).unwrap());
    writeln!(w, "o heightfield").unwrap();
    for v in vertices {
        writeln!(w, "v {} {} {}", v[0] as f32, v[1] as f32, v[2] as f32).unwrap();
    }
    for f in faces {
        writeln!(w, "f {} {} {}", f[0] + 1, f[1] + 1, f[2] + 1).unwrap();
    }
    w.flush().unwrap();
}

/// `v` scaled to unit length.
pub fn unit(v: [f64; 3]) -> [f64; 3] {
    let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    v.map(|c| c / l)
}

/// A set of float32 rays (origins and directions, the directions unit length in f64 before
/// rounding).
pub struct RaySet {
    /// The set's name in tables.
    pub name: &'static str,
    /// Origins.
    pub origins: Vec<[f32; 3]>,
    /// Unit directions.
    pub dirs: Vec<[f32; 3]>,
}

impl RaySet {
    /// Rounds `rays` (origin, direction) to f32, the directions normalized first.
    pub fn new(name: &'static str, rays: impl Iterator<Item = ([f64; 3], [f64; 3])>) -> Self {
        let (origins, dirs) = rays
            .map(|(o, d)| (o.map(|c| c as f32), unit(d).map(|c| c as f32)))
            .unzip();
        RaySet {
            name,
            origins,
            dirs,
        }
    }

    /// The rays for the tracers.
    pub fn rays(&self) -> Vec<Ray<f32>> {
        self.origins
            .iter()
            .zip(&self.dirs)
            .map(|(o, d)| Ray {
                origin: V3::new(o[0], o[1], o[2]),
                direction: V3::new(d[0], d[1], d[2]),
            })
            .collect()
    }
}

/// Primary rays of a pinhole camera looking over the field, pixels in 8x8 tiles, about
/// `count` of them (a square image whose side is a multiple of 8).
pub fn coherent(n: usize, zmax: f64, count: usize) -> RaySet {
    let side = (((count as f64).sqrt() as usize) / 8).max(1) * 8;
    let s = n as f64;
    let eye = [0.5 * s, -0.15 * s, zmax + 0.45 * s];
    let forward = unit([0.0, 0.65 * s, -(zmax + 0.45 * s)]);
    let right = unit([forward[1], -forward[0], 0.0]);
    let up = [
        right[1] * forward[2] - right[2] * forward[1],
        right[2] * forward[0] - right[0] * forward[2],
        right[0] * forward[1] - right[1] * forward[0],
    ];
    let half = (30f64.to_radians()).tan();
    let tiles = side / 8;
    let pixels = (0..tiles * tiles).flat_map(move |tile| {
        let (ty, tx) = (tile / tiles, tile % tiles);
        (0..64).map(move |p| (tx * 8 + p % 8, ty * 8 + p / 8))
    });
    RaySet::new(
        "coherent",
        pixels.map(|(x, y)| {
            let u = ((x as f64 + 0.5) / side as f64 * 2.0 - 1.0) * half;
            let v = (1.0 - (y as f64 + 0.5) / side as f64 * 2.0) * half;
            let d = std::array::from_fn(|k| forward[k] + u * right[k] + v * up[k]);
            (eye, d)
        }),
    )
}

/// Random origins above the field, uniform directions over the downward hemisphere.
pub fn incoherent(n: usize, zmax: f64, count: usize) -> RaySet {
    let mut rng = Rng::new(66, 0, 0);
    let s = n as f64;
    RaySet::new(
        "incoherent",
        (0..count).map(move |_| {
            let o = [
                rng.next_f64() * s,
                rng.next_f64() * s,
                zmax + 1.0 + rng.next_f64() * 0.05 * s,
            ];
            let d = loop {
                let v: [f64; 3] = std::array::from_fn(|_| rng.next_f64() * 2.0 - 1.0);
                let l2 = v[0] * v[0] + v[1] * v[1] + v[2] * v[2];
                if l2 > 1e-4 && l2 <= 1.0 {
                    break [v[0], v[1], -v[2].abs()];
                }
            };
            (o, d)
        }),
    )
}
