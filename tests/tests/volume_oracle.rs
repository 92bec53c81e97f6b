//! Volumes against OpenVDB, NanoVDB and NumPy: grids built from NumPy arrays by pyopenvdb,
//! converted by `nanovdb_convert` to every codec and quantization, read back by hytrace and
//! compared with the arrays (tests/oracle/vdb_oracle.py).
//!
//! - Voxel values at every voxel centre (and a margin of background around the array):
//!   float files exact, Fp4/Fp8/Fp16 within half a quantum of their leaf's range, FpN
//!   within the tolerance given to the tool, bricked formats within their stated bound.
//! - Trilinear lookups at random world points: NumPy's float64 trilinear of the array.
//! - Exact transmittance along world rays: NumPy's quadrature of the trilinear field;
//!   delta, ratio and residual ratio tracking within four standard errors of it.

use std::path::Path;

use hytrace_tests::vdb::{case, oracle_cases, run_oracle, CaseMeta, CASES};
use hytrace_trace::scan::{rays_from_rows, RayRow};
use hytrace_trace::volume::{
    open, represent, sample_points, transmittances, EstimatorArg, Repr, Space, TransmittanceArgs,
};
use hytrace_volume::{Filter, Rng, TexelFormat, VoxelGrid};

/// The next uniform number in [0, 1) of `state` (the crate's counter-based generator).
fn rng(state: &mut Rng) -> f64 {
    state.next_f64()
}

/// The dense source: its value at voxel `ijk` (background outside), axes x y z, C order.
struct Source {
    meta: CaseMeta,
    shape: [i64; 3],
    values: Vec<f32>,
}

impl Source {
    fn load(dir: &Path, name: &str) -> Source {
        let (meta, shape, values) = case(dir, name);
        Source {
            meta,
            shape: [shape[0] as i64, shape[1] as i64, shape[2] as i64],
            values,
        }
    }

    fn get(&self, ijk: [i64; 3]) -> f32 {
        let l: [i64; 3] = std::array::from_fn(|k| ijk[k] - self.meta.origin[k] as i64);
        if (0..3).any(|k| l[k] < 0 || l[k] >= self.shape[k]) {
            return self.meta.background;
        }
        self.values[((l[0] * self.shape[1] + l[1]) * self.shape[2] + l[2]) as usize]
    }

    /// Every voxel of the array grown by `margin` voxels.
    fn voxels(&self, margin: i64) -> Vec<[i64; 3]> {
        let o = self.meta.origin.map(i64::from);
        let mut out = Vec::new();
        for x in o[0] - margin..o[0] + self.shape[0] + margin {
            for y in o[1] - margin..o[1] + self.shape[1] + margin {
                for z in o[2] - margin..o[2] + self.shape[2] + margin {
                    out.push([x, y, z]);
                }
            }
        }
        out
    }

    /// Smallest and largest value of the 8^3 block (leaf, brick) holding `ijk`.
    fn block_range(&self, ijk: [i64; 3]) -> (f32, f32) {
        let o = ijk.map(|c| c.div_euclid(8) * 8);
        let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
        for x in 0..8 {
            for y in 0..8 {
                for z in 0..8 {
                    let v = self.get([o[0] + x, o[1] + y, o[2] + z]);
                    lo = lo.min(v);
                    hi = hi.max(v);
                }
            }
        }
        (lo, hi)
    }

    fn world(&self, p: [f64; 3]) -> [f64; 3] {
        let m = &self.meta.matrix;
        std::array::from_fn(|r| {
            m[r][0] * p[0] + m[r][1] * p[1] + m[r][2] * p[2] + self.meta.translation[r]
        })
    }
}

/// How far a representation's voxel may be from the source's.
fn voxel_tolerance(src: &Source, file_kind: &str, ijk: [i64; 3]) -> f64 {
    let (lo, hi) = src.block_range(ijk);
    let range = (hi - lo) as f64;
    let ulp = 4.0 * f32::EPSILON as f64 * (lo.abs().max(hi.abs()) as f64);
    match file_kind {
        // NanoVDB's Fp quantization: codes of `bits` bits spanning the leaf's active range,
        // rounded to nearest.
        "nanovdb_fp4" => range / 15.0 / 2.0 + ulp,
        "nanovdb_fp8" => range / 255.0 / 2.0 + ulp,
        "nanovdb_fp16" => range / 65535.0 / 2.0 + ulp,
        // The absolute tolerance given to nanovdb_convert (-a 0.01).
        "nanovdb_fpn" => 0.01 + ulp,
        // Float files hold the source values.
        _ => 0.0,
    }
}

#[test]
fn nanovdb_and_openvdb_voxels_equal_the_numpy_source() {
    let Some((_, dir)) = oracle_cases() else {
        return;
    };
    let mut checked = 0usize;
    for name in CASES {
        let src = Source::load(dir, name);
        let voxels = src.voxels(2);
        let points: Vec<[f64; 3]> = voxels.iter().map(|v| v.map(|c| c as f64)).collect();
        for (kind, file) in &src.meta.files {
            let file = file
                .as_ref()
                .unwrap_or_else(|| panic!("{name}: the oracle could not write {kind}"));
            let path = dir.join(file);
            let (summary, grid) = open(path.to_str().unwrap(), None).unwrap();
            if !kind.contains("fp") {
                assert_eq!(
                    summary.active_voxels, src.meta.active_voxels,
                    "{file}: active voxels"
                );
            }
            let values = sample_points(&grid, &points, Space::Index, Filter::Nearest, 0);
            for (ijk, v) in voxels.iter().zip(&values) {
                let want = src.get(*ijk);
                let tol = voxel_tolerance(&src, kind, *ijk);
                assert!(
                    ((*v - want) as f64).abs() <= tol,
                    "{file}: voxel {ijk:?}: {v} != source {want} (tolerance {tol:e})"
                );
                checked += 1;
            }
        }
    }
    eprintln!("{checked} voxels compared");
}

#[test]
fn bricked_formats_stay_within_their_stated_bounds() {
    let Some((_, dir)) = oracle_cases() else {
        return;
    };
    for name in CASES {
        let src = Source::load(dir, name);
        let path = dir.join(format!("{name}.nvdb"));
        let voxels = src.voxels(1);
        let points: Vec<[f64; 3]> = voxels.iter().map(|v| v.map(|c| c as f64)).collect();
        for (repr, format) in [
            (Repr::Bc4, TexelFormat::Bc4),
            (Repr::Unorm8, TexelFormat::Unorm8),
            (Repr::Unorm16, TexelFormat::Unorm16),
            (Repr::F16, TexelFormat::F16),
            (Repr::F32, TexelFormat::F32),
        ] {
            let (_, grid) = open(path.to_str().unwrap(), None).unwrap();
            let bricked = represent(grid, Some(repr)).unwrap();
            let hytrace_trace::volume::Represented::Bricked(b) = &bricked else {
                panic!("{format}: not bricked");
            };
            let bound = b.error_bound();
            let values = sample_points(bricked.grid(), &points, Space::Index, Filter::Nearest, 0);
            for (ijk, v) in voxels.iter().zip(&values) {
                let want = src.get(*ijk);
                let (lo, hi) = src.block_range(*ijk);
                let range = (hi - lo) as f64;
                let ulp = 4.0 * f32::EPSILON as f64 * lo.abs().max(hi.abs()) as f64;
                // The bound the format promises from its bits alone, over the brick's range.
                let analytic = match format {
                    TexelFormat::Bc4 => range / 14.0 + range / 255.0 + ulp,
                    TexelFormat::Unorm8 => range / 255.0 / 2.0 + ulp,
                    TexelFormat::Unorm16 => range / 65535.0 / 2.0 + ulp,
                    TexelFormat::F16 => want.abs() as f64 / 2048.0 + ulp,
                    TexelFormat::F32 => 0.0,
                };
                let err = ((*v - want) as f64).abs();
                assert!(
                    err <= bound && err <= analytic,
                    "{name} {format}: voxel {ijk:?}: {v} vs source {want}: error {err:e}, \
                     stated bound {bound:e}, analytic {analytic:e}"
                );
            }
        }
    }
}

#[test]
fn trilinear_world_lookups_equal_numpy() {
    let Some((python, dir)) = oracle_cases() else {
        return;
    };
    let mut state = Rng::new(7, 0, 0);
    for name in CASES {
        let src = Source::load(dir, name);
        // Points over the array grown by two voxels, in world space.
        let points: Vec<[f64; 3]> = (0..3000)
            .map(|_| {
                let p = std::array::from_fn(|k| {
                    src.meta.origin[k] as f64 - 2.0 + rng(&mut state) * (src.shape[k] as f64 + 3.0)
                });
                src.world(p)
            })
            .collect();
        let pts_path = dir.join(format!("{name}_points.npy"));
        let flat: Vec<f64> = points.iter().flatten().copied().collect();
        hytrace_foundry::npy::write_array(
            &pts_path,
            hytrace_foundry::layout::Scalar::F64,
            &[points.len() as u64, 3],
            bytemuck::cast_slice(&flat),
        )
        .unwrap();
        let ref_path = dir.join(format!("{name}_trilinear.npy"));
        run_oracle(
            python,
            &[
                "trilinear",
                dir.to_str().unwrap(),
                name,
                pts_path.to_str().unwrap(),
                ref_path.to_str().unwrap(),
            ],
        );
        let (_, want) = hytrace_tests::f64_array(&ref_path);
        for kind in ["vdb", "nanovdb", "nanovdb_zip", "nanovdb_blosc"] {
            let file = dir.join(src.meta.files[kind].as_ref().unwrap());
            let (_, grid) = open(file.to_str().unwrap(), None).unwrap();
            let got = sample_points(&grid, &points, Space::World, Filter::Trilinear, 0);
            for (i, (g, w)) in got.iter().zip(&want).enumerate() {
                assert!(
                    ((*g as f64) - w).abs() <= 1e-5 * (1.0 + w.abs()),
                    "{name} {kind}: point {i} {:?}: {g} != NumPy {w}",
                    points[i]
                );
            }
        }
    }
}

/// Rays through case `src`: random chords of the array's world box, axis-aligned rays
/// through voxel centres and faces, and rays with an infinite end.
fn oracle_rays(src: &Source, state: &mut Rng) -> Vec<RayRow> {
    let mut rows = Vec::new();
    let inside = |state: &mut Rng| -> [f64; 3] {
        std::array::from_fn(|k| {
            src.meta.origin[k] as f64 - 1.0 + rng(state) * (src.shape[k] as f64 + 1.0)
        })
    };
    for i in 0..60 {
        let a = src.world(inside(state));
        let b = src.world(inside(state));
        let d: [f64; 3] = std::array::from_fn(|k| b[k] - a[k]);
        let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        let dir = d.map(|v| v / len);
        let tmax = if i % 5 == 0 { f64::INFINITY } else { len * 1.5 };
        rows.push([a[0], a[1], a[2], -len, dir[0], dir[1], dir[2], tmax]);
    }
    // Along index axes through voxel centres (.0) and between voxels (.5).
    for (axis, offset) in [(0usize, 0.0), (1, 0.5), (2, 0.0), (0, 0.5)] {
        let mut p = inside(state).map(|v| v.floor() + offset);
        p[axis] = src.meta.origin[axis] as f64 - 3.0;
        let mut q = p;
        q[axis] += 1.0;
        let (a, b) = (src.world(p), src.world(q));
        let d: [f64; 3] = std::array::from_fn(|k| b[k] - a[k]);
        let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        let dir = d.map(|v| v / len);
        rows.push([a[0], a[1], a[2], 0.0, dir[0], dir[1], dir[2], f64::INFINITY]);
    }
    if src.meta.background != 0.0 {
        // A non-zero background makes infinite rays opaque; keep them finite.
        for r in rows.iter_mut() {
            if r[7].is_infinite() {
                r[7] = 1e3;
            }
        }
    }
    rays_from_rows(&rows, "oracle rays").unwrap()
}

fn save_rays(path: &Path, rays: &[RayRow]) {
    hytrace_trace::scan::write_rays(path, rays).unwrap();
}

#[test]
fn transmittance_equals_numpy_quadrature() {
    let Some((python, dir)) = oracle_cases() else {
        return;
    };
    let mut state = Rng::new(99, 0, 0);
    for name in CASES {
        let src = Source::load(dir, name);
        let rays = oracle_rays(&src, &mut state);
        let rays_path = dir.join(format!("{name}_rays.npy"));
        save_rays(&rays_path, &rays);
        let depth_path = dir.join(format!("{name}_depth.npy"));
        run_oracle(
            python,
            &[
                "optical-depth",
                dir.to_str().unwrap(),
                name,
                rays_path.to_str().unwrap(),
                depth_path.to_str().unwrap(),
            ],
        );
        let (_, depth) = hytrace_tests::f64_array(&depth_path);
        let file = dir.join(format!("{name}.nvdb"));
        let (_, grid) = open(file.to_str().unwrap(), None).unwrap();
        let grid = represent(grid, Some(Repr::Nanovdb)).unwrap();
        let exact = TransmittanceArgs {
            estimator: EstimatorArg::Exact,
            step: 1.0,
            spp: 1,
            seed: 1,
            density_scale: 1.0,
            filter: Filter::Trilinear,
            level: Some(0),
        };
        let (got, _, _) = transmittances(&grid, &rays, &exact).unwrap();
        for (i, (g, d)) in got.iter().zip(&depth).enumerate() {
            let want = (-d).exp();
            assert!(
                (g.transmittance - want).abs() <= 1e-9 + 1e-6 * want,
                "{name}: ray {i}: exact T {} != NumPy exp(-{d}) = {want}",
                g.transmittance
            );
        }
        // The unbiased trackers: every estimate lies in [0, 1], so its variance is at most
        // T (1 - T); the mean of `spp` samples is within 4 standard errors of T.
        let spp = 2000;
        for estimator in [
            EstimatorArg::Delta,
            EstimatorArg::Ratio,
            EstimatorArg::Residual,
        ] {
            for level in [Some(0), Some(2), None] {
                let args = TransmittanceArgs {
                    estimator,
                    spp,
                    level,
                    ..exact
                };
                let (est, _, _) = transmittances(&grid, &rays[..12], &args).unwrap();
                for (i, e) in est.iter().enumerate() {
                    let want = (-depth[i]).exp();
                    let sigma = (want * (1.0 - want) / spp as f64).sqrt();
                    assert!(
                        (e.transmittance - want).abs() <= 4.0 * sigma + 1e-9,
                        "{name} {estimator:?} level {level:?}: ray {i}: {} vs exact {want} \
                         (4 sigma = {})",
                        e.transmittance,
                        4.0 * sigma
                    );
                }
            }
        }
    }
}

#[test]
fn grid_maps_equal_openvdb_transforms() {
    let Some((_, dir)) = oracle_cases() else {
        return;
    };
    for name in CASES {
        let src = Source::load(dir, name);
        for kind in ["vdb", "nanovdb"] {
            let file = dir.join(src.meta.files[kind].as_ref().unwrap());
            let (_, grid) = open(file.to_str().unwrap(), None).unwrap();
            for (p, want) in &src.meta.map_samples {
                let got = grid.map().index_to_world(*p);
                let scale = want.iter().chain(p).fold(1.0f64, |a, v| a.max(v.abs()));
                for k in 0..3 {
                    assert!(
                        (got[k] - want[k]).abs() <= 1e-12 * scale,
                        "{name} {kind}: index {p:?} -> {got:?}, OpenVDB {want:?}"
                    );
                }
            }
        }
    }
}
