//! The GPU transmittance kernel against its CPU twin (`transmittance_batch` in f64 on the
//! same bricked grid), ray by ray, on lavapipe in CI: every texel format x filter x
//! estimator x majorant, over ray families with named hard cases; bad input; and the
//! `volume transmittance --backend gpu|auto` command line.
//!
//! Agreement (all printed, with every disagreement):
//! - `exact` (any filter) is continuous in the ray's positions: every ray within
//!   [`DETERMINISTIC_TOL`] (measured on lavapipe: at most 2.2e-6).
//! - the others decide by comparisons: the march's step count `ceil(length / step)` (a
//!   face-aligned ray whose length is an exact multiple of the step gets n or n + 1 steps by
//!   rounding), a nearest lookup at a point within f32 rounding of a half-integer, a free
//!   flight ending within rounding of a segment's end, a stochastic or collision test at its
//!   threshold. The hard-case families put points exactly on such
//!   ties (midpoints on voxel faces, rays through block edges and corners, where f64 keeps a
//!   sliver segment that f32 rounds away, so the tracker's restart draws one number more and
//!   the streams shift). There at least [`SAME_FRACTION`] of the rays agree within
//!   [`DETERMINISTIC_TOL`] (march) or [`SAME_TOL`] (trackers: the same samples, as the same
//!   seed streams give), and the trackers' means over all rays agree within four standard
//!   errors.

mod common;

use std::path::Path;

use common::{gpu_stats, hytrace, nanovdb_fixture, read_f64, unit, Random, Rng};
use hytrace_foundry::layout::Scalar;
use hytrace_foundry::npy::write_array;
use hytrace_trace::gpu::{transmittance_source, GpuContext, GpuVolume, TexelStore};
use hytrace_volume::{
    fog_sphere, transmittance_batch, BrickedGrid, DenseGrid, Estimate, Estimator, Filter, GridMap,
    Majorant, NanoGrid, NanoGridType, RangeMips, Ray, TexelFormat, TransmittanceParams, VoxelGrid,
};

/// Estimates of `a` whose transmittance is not bit for bit that of `b`'s.
fn bits_differ(a: &[Estimate], b: &[Estimate]) -> usize {
    assert_eq!(a.len(), b.len());
    let differ = a.iter().zip(b);
    differ
        .filter(|(x, y)| x.transmittance.to_bits() != y.transmittance.to_bits())
        .count()
}

/// Largest |GPU - CPU| of a deterministic estimate.
const DETERMINISTIC_TOL: f64 = 1e-5;
/// A tracked estimate counts as the same samples within this.
const SAME_TOL: f64 = 1e-4;
/// Least fraction of rays agreeing where comparisons decide.
const SAME_FRACTION: f64 = 0.97;

/// A named set of world rays.
struct Family {
    name: &'static str,
    rays: Vec<Ray>,
}

/// A grid with noise, constant bricks (no texels), an empty hole and `background`, spanning
/// negative and positive coordinates, placed at `map`.
fn noisy_grid(map: GridMap, background: f32) -> DenseGrid {
    let mut g = DenseGrid::new([-37, -21, -20], [70, 45, 52], background)
        .unwrap()
        .with_map(map);
    let mut rng = Rng(7);
    for z in -20..32i64 {
        for y in -21..24i64 {
            for x in -37..33i64 {
                let v = if (0..8).contains(&x) && (0..8).contains(&y) {
                    // A constant brick column.
                    0.75
                } else if x > 16 && y > 8 {
                    // Empty space (the background).
                    continue;
                } else {
                    (rng.uniform() * 2.0) as f32
                };
                g.set([x, y, z], v);
            }
        }
    }
    g
}

/// Ray families in the index space of a grid whose box spans about `lo..hi`, mapped to
/// world space by `map`.
fn families(map: &GridMap, lo: [f64; 3], hi: [f64; 3], random: usize) -> Vec<Family> {
    let mut rng = Rng(0xbeef);
    let inside = |rng: &mut Rng| -> [f64; 3] {
        std::array::from_fn(|k| lo[k] - 6.0 + (hi[k] - lo[k] + 12.0) * rng.uniform())
    };
    let world = |o: [f64; 3], d: [f64; 3], tmin: f64, tmax: f64| {
        // Index direction d, scaled so that t is world length along it.
        let wd = map.index_to_world(d);
        let w0 = map.index_to_world([0.0; 3]);
        let wd: [f64; 3] = std::array::from_fn(|k| wd[k] - w0[k]);
        let n = (wd[0] * wd[0] + wd[1] * wd[1] + wd[2] * wd[2]).sqrt();
        Ray::new(map.index_to_world(o), wd.map(|v| v / n), tmin * n, tmax * n)
    };
    let mut out = Vec::new();
    let mut random_rays = Vec::new();
    for i in 0..random {
        let o = inside(&mut rng);
        let d = unit(std::array::from_fn(|_| 2.0 * rng.uniform() - 1.0));
        let tmax = if i % 3 == 0 {
            20.0 * rng.uniform()
        } else {
            f64::INFINITY
        };
        random_rays.push(world(o, d, 0.0, tmax));
    }
    out.push(Family {
        name: "random",
        rays: random_rays,
    });
    let mut zero = Vec::new();
    for i in 0..random / 2 {
        let o = inside(&mut rng);
        let mut d: [f64; 3] = std::array::from_fn(|_| 2.0 * rng.uniform() - 1.0);
        d[i % 3] = 0.0;
        if i % 2 == 0 {
            d[(i + 1) % 3] = 0.0;
        }
        if d.iter().all(|v| *v == 0.0) {
            continue;
        }
        zero.push(world(o, unit(d), -3.0, f64::INFINITY));
    }
    out.push(Family {
        name: "zero direction components",
        rays: zero,
    });
    // Along brick and block faces (x = 8j - 0.5), voxel planes (integers) and cell centres.
    let mut faces = Vec::new();
    for (j, plane) in [-24.5, -0.5, 7.5, 15.5, 0.0, 8.0, 3.25]
        .into_iter()
        .enumerate()
    {
        for d in [
            [0.0, 1.0, 0.0],
            [0.0, 0.6, 0.8],
            [0.0, -0.28, 0.96],
            [0.0, 0.0, -1.0],
        ] {
            let y = lo[1] + (j as f64 * 5.3) % (hi[1] - lo[1]);
            let o = [plane, y - 40.0 * d[1], 3.0 - 40.0 * d[2]];
            faces.push(world(o, d, 0.0, f64::INFINITY));
            // The same along an edge (x and z on faces).
            faces.push(world(
                [plane, lo[1] - 10.0, 7.5],
                [0.0, 1.0, 0.0],
                0.0,
                200.0,
            ));
        }
    }
    out.push(Family {
        name: "along brick faces",
        rays: faces,
    });
    // Starting exactly on faces, leaving, entering, along them; and through block corners.
    let mut starts = Vec::new();
    for o in [
        [7.5, 3.0, 3.0],
        [-0.5, -0.5, -0.5],
        [15.5, 7.5, 2.0],
        [0.0, 8.0, 7.5],
    ] {
        for d in [
            [1.0, 0.0, 0.0],
            [-1.0, 0.0, 0.0],
            [0.6, 0.8, 0.0],
            [-0.48, 0.6, 0.64],
            [0.0, 0.0, 1.0],
        ] {
            starts.push(world(o, d, 0.0, 60.0));
        }
    }
    starts.push(world(
        [-40.5, -24.5, -24.5],
        unit([1.0, 1.0, 1.0]),
        0.0,
        f64::INFINITY,
    ));
    out.push(Family {
        name: "starting on a boundary",
        rays: starts,
    });
    // Origins far away (1e6 voxels), aimed through the box.
    let mut far = Vec::new();
    for _ in 0..random / 4 {
        let target = inside(&mut rng);
        let d = unit(std::array::from_fn(|_| 2.0 * rng.uniform() - 1.0));
        let o = std::array::from_fn(|k| target[k] - 1e6 * d[k]);
        far.push(world(o, d, 0.0, f64::INFINITY));
    }
    far.push(world([-1e6, 3.0, 2.5], [1.0, 0.0, 0.0], 0.0, f64::INFINITY));
    out.push(Family {
        name: "far origins",
        rays: far,
    });
    let mut empty = Vec::new();
    for (tmin, tmax) in [(5.0, 5.0), (10.0, 2.0), (0.0, 0.0), (30.0, -30.0)] {
        empty.push(world([0.0, 1.0, 2.0], unit([1.0, 0.5, 0.25]), tmin, tmax));
    }
    out.push(Family {
        name: "empty and reversed",
        rays: empty,
    });
    let mut miss = Vec::new();
    for k in 0..3 {
        let mut o = [0.0; 3];
        o[k] = hi[k] + 80.0;
        let mut d = [0.0; 3];
        d[(k + 1) % 3] = 1.0;
        miss.push(world(o, d, -100.0, 100.0));
        miss.push(world(o, unit([0.3, 0.4, 0.5]), 0.0, f64::INFINITY));
    }
    out.push(Family {
        name: "missing the box",
        rays: miss,
    });
    out
}

/// What one comparison found.
#[derive(Default)]
struct Tally {
    rays: usize,
    /// Largest |GPU - CPU| over the agreeing rays.
    max_same_diff: f64,
    same: usize,
    disagreements: usize,
}

/// Whether the estimate is continuous in the positions along the ray (no comparison
/// decides it), so every ray must agree.
fn continuous(params: &TransmittanceParams) -> bool {
    params.estimator == Estimator::Exact
}

/// The GPU's and CPU's estimates for `rays` under `params`, and a line of their agreement;
/// prints every disagreement beyond `tol`.
fn compare(
    label: &str,
    gpu: &GpuVolume,
    ctx: &GpuContext,
    twin: &Twin,
    families: &[Family],
    params: &TransmittanceParams,
) -> (Tally, f64, f64, f64) {
    let rays: Vec<Ray> = families.iter().flat_map(|f| f.rays.clone()).collect();
    let want = transmittance_batch(twin.grid, twin.mips, &rays, params).unwrap();
    let (got, times) = gpu.transmittance(ctx, &rays, params).unwrap();
    assert_eq!(want.len(), got.len());
    // Every answer is the kernel's (none past the driver's loop budget, redone on the CPU).
    assert_eq!(times.redone_on_cpu, 0, "{label}");
    let tol = match params.estimator {
        Estimator::Exact | Estimator::March { .. } => DETERMINISTIC_TOL,
        _ => SAME_TOL,
    };
    let mut tally = Tally::default();
    let (mut sum_w, mut sum_g, mut var) = (0.0, 0.0, 0.0);
    let mut i = 0;
    for fam in families {
        for ray in &fam.rays {
            let (w, g): (&Estimate, &Estimate) = (&want[i], &got[i]);
            let diff = (w.transmittance - g.transmittance).abs();
            tally.rays += 1;
            if diff <= tol {
                tally.same += 1;
                tally.max_same_diff = tally.max_same_diff.max(diff);
            } else {
                tally.disagreements += 1;
                println!(
                    "{label}: {} ray {i} {ray:?}: cpu {} gpu {} (|diff| {diff:.3e})",
                    fam.name, w.transmittance, g.transmittance
                );
            }
            sum_w += w.transmittance;
            sum_g += g.transmittance;
            var += (w.variance + g.variance) / f64::from(params.spp);
            i += 1;
        }
    }
    let n = tally.rays as f64;
    (tally, sum_w / n, sum_g / n, var.sqrt() / n)
}

fn params(
    estimator: Estimator,
    filter: Filter,
    majorant: Majorant,
    scale: f64,
) -> TransmittanceParams {
    TransmittanceParams {
        estimator,
        density_scale: scale,
        spp: 4,
        seed: 17,
        filter,
        majorant,
    }
}

const ESTIMATORS: [Estimator; 5] = [
    Estimator::Exact,
    Estimator::March { step: 0.7 },
    Estimator::Delta,
    Estimator::Ratio,
    Estimator::Residual,
];
const FILTERS: [Filter; 3] = [Filter::Nearest, Filter::Trilinear, Filter::Stochastic];
const MAJORANTS: [Majorant; 3] = [
    Majorant::Local { level: 0 },
    Majorant::Local { level: 2 },
    Majorant::Global,
];

/// The CPU twin of a [`GpuVolume`]: the grid as the CPU reads it and the range mips its
/// walks use.
struct Twin<'a> {
    grid: &'a dyn VoxelGrid,
    mips: &'a RangeMips,
}

/// Every estimator x filter x majorant on bricked `grid` over `families`, asserted as the
/// module documentation says.
fn check_grid(name: &str, ctx: &GpuContext, grid: &BrickedGrid, families: &[Family], scale: f64) {
    let gpu = GpuVolume::new(ctx, grid).unwrap();
    let twin = Twin {
        grid,
        mips: grid.ranges(),
    };
    check_volume(name, ctx, &gpu, &twin, families, scale, &ESTIMATORS);
}

/// Every estimator of `estimators` x filter x majorant of `gpu` against its CPU `twin` over
/// `families`.
fn check_volume(
    name: &str,
    ctx: &GpuContext,
    gpu: &GpuVolume,
    twin: &Twin,
    families: &[Family],
    scale: f64,
    estimators: &[Estimator],
) {
    for &estimator in estimators {
        let (mut max_diff, mut least, mut disagreements) = (0.0f64, 1.0f64, 0);
        for filter in FILTERS {
            for majorant in MAJORANTS {
                let p = params(estimator, filter, majorant, scale);
                let label = format!("{name} {estimator:?} {filter:?} {majorant:?}");
                let (t, mean_w, mean_g, se) = compare(&label, gpu, ctx, twin, families, &p);
                let fraction = t.same as f64 / t.rays as f64;
                println!(
                    "{label}: {} rays, same {:.4}, max |diff| of those {:.3e}, means cpu {mean_w:.6} gpu {mean_g:.6}",
                    t.rays, fraction, t.max_same_diff
                );
                (max_diff, least) = (max_diff.max(t.max_same_diff), least.min(fraction));
                disagreements += t.disagreements;
                if continuous(&p) {
                    assert_eq!(t.disagreements, 0, "{label}: see the lines above");
                    continue;
                }
                assert!(fraction >= SAME_FRACTION, "{label}: same {fraction}");
                if !matches!(estimator, Estimator::March { .. }) {
                    assert!(
                        (mean_w - mean_g).abs() <= 4.0 * se + 1e-6,
                        "{label}: means {mean_w} {mean_g} (standard error {se})"
                    );
                }
            }
        }
        println!(
            "SUMMARY {name} {estimator:?}: over filters and majorants max |diff| {max_diff:.3e} \
             on agreeing rays, least fraction agreeing {least:.4}, {disagreements} disagreements"
        );
    }
}

fn bounds(grid: &BrickedGrid) -> ([f64; 3], [f64; 3]) {
    let (lo, dims) = grid.indirection_box();
    (
        lo.map(|c| f64::from(c) * 8.0),
        std::array::from_fn(|k| f64::from(lo[k] + dims[k] as i32) * 8.0),
    )
}

#[test]
fn every_format_filter_estimator_and_majorant_matches_the_cpu() {
    let Some(ctx) = GpuContext::for_tests() else {
        return;
    };
    let source = noisy_grid(GridMap::IDENTITY, 0.0);
    for format in TexelFormat::ALL {
        let grid = BrickedGrid::convert(&source, format).unwrap();
        let (lo, hi) = bounds(&grid);
        let fams = families(grid.map(), lo, hi, 160);
        check_grid(&format!("noisy {format}"), &ctx, &grid, &fams, 0.02);
    }
}

/// Texels read from a 3D texture of each format's texture format (R8Unorm, R16Unorm,
/// R16Float, R32Float, BC4 sliced 3D) instead of the atlas buffer. The unorm and float
/// formats give the same voxel values, so every estimator x filter x majorant matches the
/// CPU as above, and `exact` is bit for bit the storage kernel's. BC4 is decoded by the
/// device, whose palette may round differently (lavapipe: to whole code units): `exact`
/// stays within the bound that one code unit per voxel allows,
/// `density_scale * largest brick scale * longest chord`.
#[test]
fn texels_from_3d_textures_match_the_cpu() {
    let Some(ctx) = GpuContext::for_tests() else {
        return;
    };
    let source = noisy_grid(GridMap::IDENTITY, 0.0);
    let scale = 0.02;
    for format in TexelFormat::ALL {
        let grid = BrickedGrid::convert(&source, format).unwrap();
        let (lo, hi) = bounds(&grid);
        let fams = families(grid.map(), lo, hi, 120);
        let textured = GpuVolume::with_texels(&ctx, &grid, TexelStore::Texture).unwrap();
        assert!(textured.features().contains(&"atlas_texture"), "{format}");
        let twin = Twin {
            grid: &grid,
            mips: grid.ranges(),
        };
        let name = format!("noisy {format} in a 3D texture");
        let rays: Vec<Ray> = fams.iter().flat_map(|f| f.rays.clone()).collect();
        let exact = params(Estimator::Exact, Filter::Trilinear, MAJORANTS[0], scale);
        let from_texture = textured.transmittance(&ctx, &rays, &exact).unwrap().0;
        if format != TexelFormat::Bc4 {
            check_volume(&name, &ctx, &textured, &twin, &fams, scale, &ESTIMATORS);
            let storage = GpuVolume::new(&ctx, &grid).unwrap();
            let from_storage = storage.transmittance(&ctx, &rays, &exact).unwrap().0;
            let differ = bits_differ(&from_texture, &from_storage);
            assert_eq!(
                differ, 0,
                "{name}: texture and storage differ on {differ} rays"
            );
            continue;
        }
        let cpu = transmittance_batch(&grid, grid.ranges(), &rays, &exact).unwrap();
        let largest_scale = grid.bricks().iter().map(|b| b.scale).fold(0.0f32, f32::max);
        let chord = (0..3).map(|k| (hi[k] - lo[k]).powi(2)).sum::<f64>().sqrt();
        let bound = scale * f64::from(largest_scale) * chord + DETERMINISTIC_TOL;
        let worst = cpu
            .iter()
            .zip(&from_texture)
            .map(|(c, g)| (c.transmittance - g.transmittance).abs())
            .fold(0.0, f64::max);
        println!("{name}: exact, largest |GPU - CPU| {worst:.3e} (bound {bound:.3e})");
        assert!(worst <= bound, "{name}: {worst} above {bound}");
    }
}

/// A fog sphere with half-voxel world units placed 1e5 world units out, and the noisy grid
/// with a background of 0.01 moved 2^20 voxels out in index space: the host's translations
/// keep the kernel's f32 numbers grid-sized.
#[test]
fn far_placements_match_the_cpu() {
    let Some(ctx) = GpuContext::for_tests() else {
        return;
    };
    let map = GridMap::uniform(0.5, [1e5, -3.0, 2.0]).unwrap();
    let sphere = fog_sphere(14.0, 3.0).unwrap().with_map(map);
    let grid = BrickedGrid::convert(&sphere, TexelFormat::F16).unwrap();
    let (lo, hi) = bounds(&grid);
    let fams = families(grid.map(), lo, hi, 120);
    check_grid("sphere at 1e5", &ctx, &grid, &fams, 0.3);

    let mut moved = noisy_grid(GridMap::IDENTITY, 0.01);
    moved.origin = [1 << 20, -(1 << 20), 3 << 18];
    let grid = BrickedGrid::convert(&moved, TexelFormat::Unorm16).unwrap();
    let (lo, hi) = bounds(&grid);
    let fams = families(grid.map(), lo, hi, 120);
    check_grid("noisy at 2^20", &ctx, &grid, &fams, 0.02);
}

/// Raw NanoVDB grids traced by the kernel (no conversion: it walks the grid's own buffer)
/// against the CPU estimators on the same grid and range mips: float, the quantized types
/// (Fp4, Fp8, Fp16, FpN) on a rotated anisotropic map, and grids of tiles. On the exact
/// estimator the kernel also gives, bit for bit, what it gives on the grid converted to f32
/// bricks (the same voxel values and mips, read another way).
#[test]
fn raw_nanovdb_grids_match_the_cpu() {
    // Only kernels for NanoVDB grids carry the NanoVDB lookup, only split atlases more
    // than one atlas binding.
    let split = "var<storage, read> atlas_1";
    let nanovdb = transmittance_source(&["nanovdb"]).unwrap();
    assert!(nanovdb.contains("fn nanovdb_voxel(") && !nanovdb.contains(split));
    let bricked = transmittance_source(&[]).unwrap();
    assert!(!bricked.contains("fn nanovdb_") && !bricked.contains(split));
    assert!(transmittance_source(&["chunked_atlas"])
        .unwrap()
        .contains("var<storage, read> atlas_3"));
    let Some(ctx) = GpuContext::for_tests() else {
        return;
    };
    let files = [
        "density_zip.nvdb",
        "density_fp4.nvdb",
        "density_fp8.nvdb",
        "density_fp16.nvdb",
        "density_fpn.nvdb",
        "tiles_zip.nvdb",
        "tiles_fp8.nvdb",
    ];
    for file in files {
        for grid in &nanovdb_fixture(file).grids {
            let name = format!("{file}:{} ({})", grid.name(), grid.grid_type());
            let gpu = GpuVolume::nanovdb(&ctx, grid).unwrap();
            let mips = RangeMips::build(grid).unwrap();
            let twin = Twin { grid, mips: &mips };
            let [lo, hi] = grid.index_bbox().unwrap().map(|c| c.map(f64::from));
            let fams = families(grid.map(), lo, hi, 120);
            // Optical depths up to about 30 across the box (the fixtures are sparse).
            let range = hytrace_volume::global_range(&mips);
            let diagonal = (0..3).map(|k| (hi[k] - lo[k]).powi(2)).sum::<f64>().sqrt();
            let scale = 30.0 / (f64::from(range.max.abs().max(1e-3)) * diagonal);
            let rays: Vec<Ray> = fams.iter().flat_map(|f| f.rays.clone()).collect();
            if range.min >= 0.0 {
                check_volume(&name, &ctx, &gpu, &twin, &fams, scale, &ESTIMATORS);
            } else {
                // Negative tiles: the trackers are refused on the GPU as on the CPU.
                check_volume(&name, &ctx, &gpu, &twin, &fams, scale, &ESTIMATORS[..2]);
                let p = params(Estimator::Delta, Filter::Trilinear, MAJORANTS[0], scale);
                let err = gpu.transmittance(&ctx, &rays, &p).unwrap_err().to_string();
                assert!(err.contains("need a density >= 0"), "{name}: {err}");
            }

            let bricks = BrickedGrid::convert(grid, TexelFormat::F32).unwrap();
            assert_eq!(bricks.ranges(), &mips, "{name}: the same range mips");
            let converted = GpuVolume::new(&ctx, &bricks).unwrap();
            let p = params(Estimator::Exact, Filter::Trilinear, MAJORANTS[0], scale);
            let raw = gpu.transmittance(&ctx, &rays, &p).unwrap().0;
            let via_bricks = converted.transmittance(&ctx, &rays, &p).unwrap().0;
            let differ = bits_differ(&raw, &via_bricks);
            assert_eq!(differ, 0, "{name}: raw and bricked differ on {differ} rays");
        }
    }
    // Refused before anything is uploaded, naming the grid: a vector grid, and a grid
    // with more 8^3 blocks of data than range mips may list.
    let refusal = |grid: &NanoGrid| match GpuVolume::nanovdb(&ctx, grid) {
        Ok(_) => panic!("grid '{}' was accepted", grid.name()),
        Err(e) => e.to_string(),
    };
    let multi = nanovdb_fixture("multi_zip.nvdb");
    let vector = multi
        .grids
        .iter()
        .find(|g| g.grid_type() == NanoGridType::Vec3f);
    let err = refusal(vector.unwrap());
    assert!(err.contains("values of type Vec3f"), "{err}");
    let err = refusal(&nanovdb_fixture("roottile_zip.nvdb").grids[0]);
    assert!(
        err.contains("'roottile' cannot be read on the GPU") && err.contains("blocks"),
        "{err}"
    );
}

/// An atlas above the device's binding limit is split over up to four buffers: with the
/// limit lowered, bricks (756 KB of f32 texels) and a raw NanoVDB grid (614 KB) are read
/// from three chunks of 256 KiB and every estimate is bit for bit the one-buffer kernel's,
/// as with the range mips, indirection and brick table split in chunks; an atlas beyond four
/// chunks is refused, naming it.
#[test]
fn atlases_above_the_binding_limit_are_split() {
    let Some(mut ctx) = GpuContext::for_tests() else {
        return;
    };
    let bricks =
        BrickedGrid::convert(&noisy_grid(GridMap::IDENTITY, 0.0), TexelFormat::F32).unwrap();
    let tiles = nanovdb_fixture("tiles_zip.nvdb");
    let (lo, hi) = bounds(&bricks);
    let brick_rays: Vec<Ray> = families(bricks.map(), lo, hi, 200)
        .into_iter()
        .flat_map(|f| f.rays)
        .collect();
    let [lo, hi] = tiles.grids[0]
        .index_bbox()
        .unwrap()
        .map(|c| c.map(f64::from));
    let tile_rays: Vec<Ray> = families(tiles.grids[0].map(), lo, hi, 200)
        .into_iter()
        .flat_map(|f| f.rays)
        .collect();
    let estimators = [
        params(Estimator::Exact, Filter::Trilinear, MAJORANTS[0], 0.02),
        params(
            Estimator::March { step: 0.7 },
            Filter::Nearest,
            MAJORANTS[1],
            0.02,
        ),
    ];
    let trackers = [
        params(Estimator::Ratio, Filter::Trilinear, MAJORANTS[0], 0.02),
        params(Estimator::Delta, Filter::Stochastic, MAJORANTS[2], 0.02),
    ];
    let run = |ctx: &GpuContext, nanovdb: bool| {
        let volume = if nanovdb {
            GpuVolume::nanovdb(ctx, &tiles.grids[0]).unwrap()
        } else {
            GpuVolume::new(ctx, &bricks).unwrap()
        };
        let (rays, sets) = if nanovdb {
            // Negative tiles: the deterministic estimators only.
            (&tile_rays, &estimators[..])
        } else {
            (&brick_rays, &[estimators, trackers].concat()[..])
        };
        let values: Vec<u64> = sets
            .iter()
            .flat_map(|p| volume.transmittance(ctx, rays, p).unwrap().0)
            .map(|e| e.transmittance.to_bits())
            .collect();
        let chunked: Vec<&str> = (volume.features().iter())
            .filter(|f| f.starts_with("chunked_"))
            .copied()
            .collect();
        (chunked, values)
    };
    let compare = |what: &str, w: &[u64], s: &[u64]| {
        assert_eq!(w.len(), s.len());
        let differ = w.iter().zip(s).filter(|(a, b)| a != b).count();
        println!("{what}: {} estimates, {differ} differ", w.len());
        assert_eq!(differ, 0, "{what}: split and whole arrays differ");
    };
    let whole = [run(&ctx, false), run(&ctx, true)];
    let limit = ctx.limits.max_storage_buffer_binding_size;
    ctx.limits.max_storage_buffer_binding_size = 256 << 10;
    let split = [run(&ctx, false), run(&ctx, true)];
    for (what, (w, s)) in ["bricks", "nanovdb"].iter().zip(whole.iter().zip(&split)) {
        assert!(w.0.is_empty(), "{what}: {:?}", w.0);
        assert_eq!(
            s.0,
            ["chunked_atlas"],
            "{what}: split under the lowered limit"
        );
        compare(what, &w.1, &s.1);
    }
    // The range mips and brick tables are read through chunks the same way (split on
    // demand: no grid here is big enough).
    ctx.limits.max_storage_buffer_binding_size = limit;
    let tables = ["ranges", "indirection", "bricks"];
    ctx.split_arrays = tables.map(String::from).to_vec();
    let split = [run(&ctx, false), run(&ctx, true)];
    for (what, (w, s)) in ["bricks", "nanovdb"].iter().zip(whole.iter().zip(&split)) {
        let expected = tables.map(|t| format!("chunked_{t}"));
        assert_eq!(s.0, expected, "{what}");
        compare(&format!("{what}, split tables"), &w.1, &s.1);
    }
    ctx.split_arrays.clear();
    // Four chunks of 64 KiB hold neither.
    ctx.limits.max_storage_buffer_binding_size = 64 << 10;
    let err = GpuVolume::new(&ctx, &bricks).err().unwrap().to_string();
    assert!(
        err.contains("array `atlas` has") && err.contains("4 storage buffers"),
        "{err}"
    );
    let err = GpuVolume::nanovdb(&ctx, &tiles.grids[0])
        .err()
        .unwrap()
        .to_string();
    assert!(err.contains("the device can bind"), "{err}");
}

/// Drivers inline every call: the kernel's costly functions each have one call site.
#[test]
fn costly_functions_are_called_once() {
    let source = hytrace_trace::gpu::compose::compose("kernels/transmittance").unwrap();
    for f in [
        "walk_start",
        "walk_next",
        "cells_start",
        "cells_next",
        "grid_fetch",
        "grid_voxel",
        "atlas_texel",
        "bc4_texel",
        "trilinear_lerp",
        "trilinear_sum",
        "nanovdb_voxel",
        "nanovdb_root",
        "nanovdb_internal",
        "nanovdb_leaf",
    ] {
        let calls = source.matches(&format!("{f}(")).count();
        let definitions = source.matches(&format!("fn {f}(")).count();
        assert_eq!((definitions, calls - definitions), (1, 1), "{f}");
    }
}

#[test]
fn bad_input_is_refused_clearly() {
    let Some(ctx) = GpuContext::for_tests() else {
        return;
    };
    let grid = BrickedGrid::convert(&fog_sphere(6.0, 2.0).unwrap(), TexelFormat::F32).unwrap();
    let gpu = GpuVolume::new(&ctx, &grid).unwrap();
    let good = Ray::new([-20.0, 0.0, 0.0], [1.0, 0.0, 0.0], 0.0, f64::INFINITY);
    let nan = Ray::new([f64::NAN, 0.0, 0.0], [1.0, 0.0, 0.0], 0.0, 1.0);
    let zero = Ray::new([0.0; 3], [0.0; 3], 0.0, 1.0);
    let p = params(
        Estimator::Ratio,
        Filter::Trilinear,
        Majorant::Local { level: 0 },
        1.0,
    );
    for (bad, why) in [(nan, "origin must be finite"), (zero, "non-zero")] {
        let err = gpu
            .transmittance(&ctx, &[good, bad], &p)
            .unwrap_err()
            .to_string();
        assert!(err.contains("ray 1") && err.contains(why), "{err}");
    }
    let zero_spp = TransmittanceParams { spp: 0, ..p };
    let err = gpu
        .transmittance(&ctx, &[good], &zero_spp)
        .unwrap_err()
        .to_string();
    assert!(err.contains("spp must be at least 1"), "{err}");
    // Negative densities: refused by the trackers, as on the CPU.
    let mut negative = DenseGrid::new([0; 3], [4, 4, 4], 0.0).unwrap();
    negative.set([1, 1, 1], -1.0);
    let grid = BrickedGrid::convert(&negative, TexelFormat::F32).unwrap();
    let gpu = GpuVolume::new(&ctx, &grid).unwrap();
    let through = Ray::new([-5.0, 1.0, 1.0], [1.0, 0.0, 0.0], 0.0, f64::INFINITY);
    assert!(transmittance_batch(&grid, grid.ranges(), &[through], &p).is_err());
    let err = gpu
        .transmittance(&ctx, &[through], &p)
        .unwrap_err()
        .to_string();
    assert!(err.contains("density >= 0"), "{err}");
    let exact = TransmittanceParams {
        estimator: Estimator::Exact,
        ..p
    };
    let (t, _) = gpu.transmittance(&ctx, &[through], &exact).unwrap();
    assert!(t[0].transmittance > 1.0, "{}", t[0].transmittance);
    assert!(grid.background() == 0.0);
}

/// `volume transmittance --backend gpu` writes what the CPU writes (within f32), on a
/// bricked representation (texels in a buffer or in a 3D texture), on `--repr nanovdb` of
/// a NanoVDB file (its raw buffer traced, as `--stats` says) and of a procedural grid
/// (converted to f32 bricks); a raw buffer asked for in a texture is refused; without an
/// adapter `gpu` fails and writes nothing, `auto` falls back to the CPU.
#[test]
fn transmittance_cli_on_the_gpu() {
    if GpuContext::for_tests().is_none() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let p = |n: &str| dir.path().join(n).display().to_string();
    // Rays along x through the sphere's centre region, and through the NanoVDB fixture's
    // world box (x -12.6..0.4, y -22.1..-9.1, z -6.5..3).
    for (file, centre) in [
        ("rays.npy", [0.0, 0.0]),
        ("fixture_rays.npy", [-15.5, -1.75]),
    ] {
        let mut rows: Vec<f64> = Vec::new();
        for i in 0..40 {
            let a = f64::from(i) * 0.157;
            let (y, z) = (centre[0] + a.sin() * 5.0, centre[1] + a.cos() * 3.0);
            rows.extend([-30.0, y, z, 0.0, 1.0, 0.0, 0.0]);
            rows.push(if i % 2 == 0 { f64::INFINITY } else { 35.0 });
        }
        write_array(
            Path::new(&p(file)),
            Scalar::F64,
            &[40, 8],
            bytemuck::cast_slice(&rows),
        )
        .unwrap();
    }
    let fixture = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../tests/data/nanovdb/density_fp8.nvdb")
        .display()
        .to_string();
    // `texels`: where the GPU reads a bricked grid's texels from.
    let run = |spec: &str,
               rays: &str,
               backend: &str,
               (repr, texels): (&str, &str),
               out: &str,
               env: &[(&str, &str)]| {
        let args = [
            "volume",
            "transmittance",
            spec,
            "--rays",
            &p(rays),
            "--out",
            out,
            "--repr",
            repr,
            "--density-scale",
            "0.05",
            "--stats",
            "--backend",
            backend,
            "--gpu-texels",
            texels,
        ];
        hytrace(&args, env)
    };
    for (spec, rays, (repr, texels), want_repr) in [
        ("sphere:12,0.5", "rays.npy", ("unorm8", "storage"), "unorm8"),
        (
            "sphere:12,0.5",
            "rays.npy",
            ("unorm8", "texture"),
            "unorm8, texels in a 3D texture",
        ),
        (
            "sphere:12,0.5",
            "rays.npy",
            ("nanovdb", "storage"),
            "f32 (converted from procedural)",
        ),
        (
            fixture.as_str(),
            "fixture_rays.npy",
            ("nanovdb", "storage"),
            "nanovdb (the raw grid buffer)",
        ),
    ] {
        let cpu = run(spec, rays, "cpu", (repr, texels), &p("cpu.npy"), &[]);
        assert!(
            cpu.status.success(),
            "{}",
            String::from_utf8_lossy(&cpu.stderr)
        );
        let gpu = run(spec, rays, "gpu", (repr, texels), &p("gpu.npy"), &[]);
        let stats = gpu_stats(&gpu);
        // The kernel's own time from timestamp queries, which lavapipe has.
        let stamps = &stats["gpu_kernel_timestamps_s"];
        if stats["adapter"]
            .as_str()
            .is_some_and(|a| a.contains("llvmpipe"))
        {
            assert!(stamps.as_f64().is_some_and(|s| s >= 0.0), "{stamps}");
        }
        assert_eq!(stats["gpu_repr"], want_repr);
        let (want, got) = (
            read_f64(Path::new(&p("cpu.npy"))),
            read_f64(Path::new(&p("gpu.npy"))),
        );
        assert_eq!(want.len(), 40);
        assert!(want.iter().any(|t| *t < 0.9), "{spec}: {want:?}");
        for (i, (w, g)) in want.iter().zip(&got).enumerate() {
            assert!(
                (w - g).abs() <= DETERMINISTIC_TOL,
                "{spec} ray {i}: cpu {w} gpu {g}"
            );
        }
    }
    // A raw NanoVDB buffer has no texels to put in a texture: refused, nothing written.
    let both = run(
        &fixture,
        "fixture_rays.npy",
        "gpu",
        ("nanovdb", "texture"),
        &p("both.npy"),
        &[],
    );
    let err = String::from_utf8_lossy(&both.stderr);
    assert!(
        !both.status.success() && err.contains("--gpu-texels texture reads bricked grids"),
        "{err}"
    );
    assert!(!Path::new(&p("both.npy")).exists());
    // No adapter: WGPU_BACKEND names one this build does not have.
    let none = [("WGPU_BACKEND", "metal")];
    let no_gpu = run(
        "sphere:12,0.5",
        "rays.npy",
        "gpu",
        ("f32", "storage"),
        &p("none.npy"),
        &none,
    );
    let err = String::from_utf8_lossy(&no_gpu.stderr);
    assert!(
        !no_gpu.status.success() && err.contains("no GPU adapter found"),
        "{err}"
    );
    assert!(!Path::new(&p("none.npy")).exists());
    let auto = run(
        "sphere:12,0.5",
        "rays.npy",
        "auto",
        ("f32", "storage"),
        &p("auto.npy"),
        &none,
    );
    assert!(
        auto.status.success(),
        "{}",
        String::from_utf8_lossy(&auto.stderr)
    );
    assert!(String::from_utf8_lossy(&auto.stderr).contains("--backend auto traces on the CPU"));
    let stats: serde_json::Value = serde_json::from_slice(&auto.stdout).unwrap();
    assert_eq!(stats["backend"], "cpu");
}

#[test]
fn rays_past_the_driver_loop_budget_are_computed_again_on_the_cpu() {
    // A march of 1/10000 voxel: some 120 000 steps through a fog sphere, past the 65535
    // loop iterations lavapipe gives 8 invocations together. The first 32 rays cross the
    // sphere, the last 32 pass far from it: on lavapipe the kernel's probe marks exactly
    // the first 32, which the CPU twin computes again, on their own streams; the answers
    // equal the CPU's. A GPU without such a budget redoes none.
    let Some(ctx) = GpuContext::for_tests() else {
        return;
    };
    let grid = BrickedGrid::convert(&fog_sphere(6.0, 2.0).unwrap(), TexelFormat::F32).unwrap();
    let gpu = GpuVolume::new(&ctx, &grid).unwrap();
    let rays: Vec<Ray> = (0..64)
        .map(|k| {
            let y = if k < 32 {
                0.05 * k as f64
            } else {
                100.0 + k as f64
            };
            Ray::new([-20.0, y, 0.3], [1.0, 0.0, 0.0], 0.0, 40.0)
        })
        .collect();
    let mut p = params(
        Estimator::March { step: 1e-4 },
        Filter::Trilinear,
        Majorant::Global,
        1.0,
    );
    p.spp = 1;
    let want = transmittance_batch(&grid, grid.ranges(), &rays, &p).unwrap();
    let (got, times) = gpu.transmittance(&ctx, &rays, &p).unwrap();
    let llvmpipe = ctx.describe().contains("llvmpipe");
    assert_eq!(times.redone_on_cpu, if llvmpipe { 32 } else { 0 });
    for (k, (w, g)) in want.iter().zip(&got).enumerate() {
        // Redone rays are the CPU's own answers; the others (1: no fog) equal too. A real
        // GPU's f32 march of 120 000 steps rounds more.
        let tol = if llvmpipe { 0.0 } else { 1e-3 };
        assert!(
            (w.transmittance - g.transmittance).abs() <= tol,
            "ray {k}: cpu {} gpu {}",
            w.transmittance,
            g.transmittance
        );
        assert!(k >= 32 || w.transmittance < 0.99, "ray {k} misses the fog");
    }
}
