//! Properties of the bricked grid against its source: decode errors within the stated
//! bounds, ranges that bound every lookup, layout edge cases, the `.npy` output and
//! determinism.

use std::path::Path;

use hytrace_foundry::layout::Scalar;
use hytrace_foundry::npy::{read_array, read_records};
use hytrace_volume::{
    sample_nearest, sample_stochastic, sample_trilinear, BrickEntry, BrickedGrid, DenseGrid, Rng,
    TexelFormat, VoxelGrid, NO_BRICK, NO_SLOT, RANGE_LEVELS,
};

/// The next uniform number in [0, 1) of `state` (the crate's counter-based generator).
fn rng(state: &mut Rng) -> f64 {
    state.next_f64()
}

/// Negative origin, sides that are not multiples of 8; random values, an empty region, a
/// constant aligned brick, a smooth ramp and a lone voxel whose neighbour brick is empty.
fn structured_grid() -> DenseGrid {
    let mut state = Rng::new(7, 0, 0);
    let mut g = DenseGrid::new([-19, -6, -27], [37, 22, 29], 0.0).unwrap();
    for z in -27..2 {
        for y in -6..16 {
            for x in -19..18 {
                let v = if x < -3 && y < 8 {
                    // Random values, some of them background.
                    if rng(&mut state) < 0.3 {
                        0.0
                    } else {
                        (rng(&mut state) * 7.0 - 2.0) as f32
                    }
                } else if x >= 8 {
                    // A smooth ramp.
                    0.25 + 0.01 * (x + 2 * y + 3 * z) as f32
                } else {
                    0.0
                };
                g.set([x, y, z], v);
            }
        }
    }
    // An aligned constant brick: voxels [-16, -8) x [0, 8) x [-24, -16).
    for z in -24..-16 {
        for y in 0..8 {
            for x in -16..-8 {
                g.set([x, y, z], 3.0);
            }
        }
    }
    // A lone voxel next to the empty brick [0, 8) x [8, 16) x [-8, 0).
    g.set([7, 7, -1], 2.5);
    g
}

/// A grid with values `base + spread * noise` filling the bricks of `[-8, 16)^3`.
fn offset_grid(base: f32, spread: f32, seed: u32) -> DenseGrid {
    let mut state = Rng::new(seed, 0, 0);
    let mut g = DenseGrid::new([-8; 3], [24; 3], 0.0).unwrap();
    for v in g.values.iter_mut() {
        *v = base + spread * (rng(&mut state) * 2.0 - 1.0) as f32;
    }
    g
}

/// Every voxel of the source box grown by `margin`.
fn voxels(g: &DenseGrid, margin: i32) -> impl Iterator<Item = [i32; 3]> + '_ {
    let [x0, y0, z0] = g.origin.map(|c| c - margin);
    let [nx, ny, nz] = g.dims.map(|d| d as i32 + 2 * margin);
    (0..nz).flat_map(move |z| {
        (0..ny).flat_map(move |y| (0..nx).map(move |x| [x0 + x, y0 + y, z0 + z]))
    })
}

/// Checks every voxel against the stated bound and the bound against the analytic one.
fn assert_within_bound(g: &DenseGrid, b: &BrickedGrid) {
    let bound = b.error_bound();
    assert!(
        bound <= b.analytic_error_bound(),
        "{}: measured {bound} above analytic {}",
        b.format(),
        b.analytic_error_bound()
    );
    let mut largest = 0.0f64;
    for ijk in voxels(g, 2) {
        let (d, s) = (b.voxel(ijk), g.voxel(ijk));
        let e = (d as f64 - s as f64).abs();
        assert!(
            e <= bound,
            "{}: voxel {ijk:?} {d} vs {s}, bound {bound}",
            b.format()
        );
        largest = largest.max(e);
    }
    // The stated bound is the measured maximum: attained, not merely an upper bound.
    assert_eq!(largest, bound, "{}", b.format());
}

/// `(max - min, max |v|)` over all voxels of `g`.
fn span(g: &DenseGrid) -> (f64, f64) {
    let lo = g.values.iter().fold(g.background, |a, v| a.min(*v)) as f64;
    let hi = g.values.iter().fold(g.background, |a, v| a.max(*v)) as f64;
    (hi - lo, lo.abs().max(hi.abs()))
}

#[test]
fn every_format_decodes_within_its_bound() {
    let grids = [
        structured_grid(),
        offset_grid(1e4, 0.01, 1),
        offset_grid(1e6, 0.5, 2),
        offset_grid(0.0, 1e-30, 3),
    ];
    for g in &grids {
        let (range, magnitude) = span(g);
        for format in TexelFormat::ALL {
            let b = BrickedGrid::convert(g, format).unwrap();
            assert_within_bound(g, &b);
            // The analytic bound itself is the documented formula at the grid's spread.
            let u = 2f64.powi(-24);
            let rounding = 4.0 * u * range + 2.0 * u * magnitude + 1e-40;
            let outer = match format {
                TexelFormat::Unorm8 => range / 510.0 * 1.001 + rounding,
                TexelFormat::Unorm16 => range / 131070.0 * 1.001 + rounding,
                TexelFormat::Bc4 => range / 14.0 * 1.001 + rounding,
                TexelFormat::F16 => magnitude * 2f64.powi(-11) + 1e-7,
                TexelFormat::F32 => 0.0,
            };
            assert!(
                b.analytic_error_bound() <= outer,
                "{format}: analytic {} above {outer}",
                b.analytic_error_bound()
            );
        }
    }
}

#[test]
fn f32_is_exact_and_quantized_formats_use_the_brick_range() {
    let g = structured_grid();
    let b = BrickedGrid::convert(&g, TexelFormat::F32).unwrap();
    assert_eq!(b.error_bound(), 0.0);
    assert!(voxels(&g, 1).all(|ijk| b.voxel(ijk) == g.voxel(ijk)));
    // 1e6 + 0.5 noise: relative to the brick minimum, unorm16 is far finer than f32's
    // spacing (1/16) at 1e6, so every voxel is within one f32 rounding.
    let g = offset_grid(1e6, 0.5, 4);
    let b = BrickedGrid::convert(&g, TexelFormat::Unorm16).unwrap();
    assert!(b.error_bound() <= 0.0625, "{}", b.error_bound());
    // 1e4 + 0.01 noise in f16: relative to the minimum the error is ~1e-5, raw it would be 4.
    let g = offset_grid(1e4, 0.01, 5);
    let b = BrickedGrid::convert(&g, TexelFormat::F16).unwrap();
    assert!(b.error_bound() < 1e-3, "{}", b.error_bound());
    // 1e6 + 0.01 noise rounds to 1e6 in f32: every brick is constant and exact.
    let g = offset_grid(1e6, 0.01, 6);
    let b = BrickedGrid::convert(&g, TexelFormat::Bc4).unwrap();
    assert_eq!((b.error_bound(), b.atlas_slots()), (0.0, 0));
}

#[test]
fn ranges_near_the_f32_limit() {
    let mut state = Rng::new(9, 0, 0);
    let mut g = DenseGrid::new([0; 3], [8, 8, 16], 0.0).unwrap();
    for v in g.values.iter_mut() {
        *v = (1e37 + rng(&mut state) * 2.9e38) as f32;
    }
    for format in [TexelFormat::Bc4, TexelFormat::Unorm8, TexelFormat::Unorm16] {
        let b = BrickedGrid::convert(&g, format).unwrap();
        assert_within_bound(&g, &b);
        assert!(b.ranges().levels.iter().all(|l| l
            .ranges
            .iter()
            .all(|r| r.min.is_finite() && r.max.is_finite())));
    }
    let err = BrickedGrid::convert(&g, TexelFormat::F16)
        .unwrap_err()
        .to_string();
    assert!(err.contains("f16") && err.contains("[0, 0, 0]"), "{err}");
    // A brick spanning [-3e38, 3e38]: its range overflows f32, only f32 storage holds it.
    g.set([1, 2, 3], -3e38);
    g.set([2, 2, 3], 3e38);
    for format in [TexelFormat::Bc4, TexelFormat::Unorm8, TexelFormat::Unorm16] {
        let err = BrickedGrid::convert(&g, format).unwrap_err().to_string();
        assert!(err.contains("wider than the largest f32"), "{err}");
    }
    let b = BrickedGrid::convert(&g, TexelFormat::F32).unwrap();
    assert_within_bound(&g, &b);
}

#[test]
fn non_finite_voxels_and_f16_overflow_are_errors() {
    for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
        let mut g = DenseGrid::new([-10, 0, 0], [20, 4, 4], 0.0).unwrap();
        g.set([-3, 1, 2], bad);
        for format in TexelFormat::ALL {
            let err = BrickedGrid::convert(&g, format).unwrap_err().to_string();
            assert!(
                err.contains("[-3, 1, 2]") && err.contains("[-8, 0, 0]"),
                "{format}: {err}"
            );
        }
    }
    // |v| beyond 65504 both raw and relative to the brick minimum.
    let mut g = DenseGrid::new([0; 3], [8, 8, 8], 0.0).unwrap();
    g.set([1, 1, 1], 1e5);
    let err = BrickedGrid::convert(&g, TexelFormat::F16)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("f16 range") && err.contains("[0, 0, 0]"),
        "{err}"
    );
    // Large values with a small spread are stored relative to the brick minimum.
    g.values.fill(1e5);
    g.set([1, 1, 1], 1e5 + 3.0);
    let b = BrickedGrid::convert(&g, TexelFormat::F16).unwrap();
    assert_within_bound(&g, &b);
    assert!(b.error_bound() < 1e-2);
}

/// Random lookups of every filter on `b` lie within every level's range at their point.
fn assert_ranges_bound_lookups(b: &BrickedGrid, points: &[[f64; 3]], state: &mut Rng) {
    for p in points {
        let u: [f64; 3] = std::array::from_fn(|_| rng(state));
        let lookups = [
            sample_trilinear(b, *p),
            sample_nearest(b, *p) as f64,
            sample_stochastic(b, *p, u) as f64,
        ];
        let mut previous = None;
        for level in 0..RANGE_LEVELS {
            let r = b.range_at(level, *p);
            for v in lookups {
                let slack = 1e-6 * v.abs().max(1.0);
                assert!(
                    r.min as f64 - slack <= v && v <= r.max as f64 + slack,
                    "{}: level {level} range {r:?} misses {v} at {p:?}",
                    b.format()
                );
            }
            // Coarser levels contain the finer ones.
            if let Some(f) = previous {
                let f: hytrace_volume::ValueRange = f;
                assert!(r.min <= f.min && r.max >= f.max, "{p:?}: {r:?} vs {f:?}");
            }
            previous = Some(r);
            assert_eq!(b.majorant(level, *p), r.max);
        }
    }
}

#[test]
fn ranges_bound_every_lookup() {
    let g = structured_grid();
    let mut state = Rng::new(13, 0, 0);
    let mut points: Vec<[f64; 3]> = (0..6000)
        .map(|_| {
            std::array::from_fn(|k| {
                g.origin[k] as f64 - 20.0 + rng(&mut state) * (g.dims[k] as f64 + 40.0)
            })
        })
        .collect();
    // Points in the constant brick, in the empty brick next to the lone voxel, and on
    // brick faces.
    for _ in 0..500 {
        let r: [f64; 3] = std::array::from_fn(|_| rng(&mut state) * 8.0 - 0.5);
        points.push([r[0] - 16.0, r[1], r[2] - 24.0]);
        points.push([r[0], r[1] + 8.0, r[2] - 8.0]);
        points.push([7.5, r[1] + 8.0, r[2] - 8.0]);
    }
    for format in [TexelFormat::Bc4, TexelFormat::Unorm8, TexelFormat::F16] {
        let b = BrickedGrid::convert(&g, format).unwrap();
        assert_ranges_bound_lookups(&b, &points, &mut state);
        // The source's lookups lie in the same ranges widened by the stated error.
        for p in &points {
            let v = sample_trilinear(&g, *p);
            let r = b.range_at(0, *p);
            let e = b.error_bound() + 1e-6;
            assert!(r.min as f64 - e <= v && v <= r.max as f64 + e, "{p:?}");
        }
    }
    assert!(
        sample_trilinear(
            &BrickedGrid::convert(&g, TexelFormat::F32).unwrap(),
            [1e30, 0.0, 0.0]
        ) == 0.0
    );
}

#[test]
fn constant_and_background_bricks_store_no_texels() {
    let g = structured_grid();
    for format in TexelFormat::ALL {
        let b = BrickedGrid::convert(&g, format).unwrap();
        let constant = b
            .bricks()
            .iter()
            .find(|e| e.origin == [-16, 0, -24])
            .unwrap();
        assert_eq!((constant.atlas_slot, constant.offset), (NO_SLOT, 3.0));
        assert_eq!(b.voxel([-12, 3, -20]), 3.0);
        // The empty brick [0, 8) x [8, 16) x [-8, 0) is not stored, yet its range reaches the
        // lone voxel at (7, 7, -1) through the halo, and a lookup there is not background.
        let (lo, dims) = b.indirection_box();
        let local = [0 - lo[0], 1 - lo[1], -1 - lo[2]].map(|c| c as usize);
        let slot = local[0] + dims[0] as usize * (local[1] + dims[1] as usize * local[2]);
        assert_eq!(b.indirection()[slot], NO_BRICK);
        assert!(b.bricks().iter().all(|e| e.origin != [0, 8, -8]));
        let p = [7.0, 7.75, -1.0];
        let v = sample_trilinear(&b, p);
        assert!(v > 0.0 && v <= b.majorant(0, p) as f64, "{format}: {v}");
        assert_eq!(b.range_at(0, [3.0, 8.0, -4.0]).max, b.voxel([7, 7, -1]));
    }
}

#[test]
fn no_voxel_lost_at_brick_boundaries() {
    // Extents ending on multiples of 8, from both sides of zero.
    for origin in [[0, 0, 0], [-16, -16, -16], [-8, 0, 8]] {
        let mut g = DenseGrid::new(origin, [16, 16, 16], 0.0).unwrap();
        for (i, v) in g.values.iter_mut().enumerate() {
            *v = (i % 11) as f32 * 0.5;
        }
        for format in [TexelFormat::F32, TexelFormat::Unorm8] {
            let b = BrickedGrid::convert(&g, format).unwrap();
            assert_within_bound(&g, &b);
            // The last voxel's brick is stored (the box ends on its far face).
            let last = origin.map(|c| c + 15);
            let brick = last.map(|c| c.div_euclid(8) * 8);
            assert!(b.bricks().iter().any(|e| e.origin == brick), "{brick:?}");
            assert_eq!(b.bricks().len(), 8);
        }
    }
}

#[test]
fn long_lines_need_no_atlas_coordinate_limit() {
    // 1 x 1 x 2100 voxels: 263 bricks along z, beyond Falcor's 8-bit atlas coordinates.
    let mut g = DenseGrid::new([3, -4, -1000], [1, 1, 2100], 0.0).unwrap();
    for (i, v) in g.values.iter_mut().enumerate() {
        *v = 1.0 + (i % 7) as f32;
    }
    for format in [TexelFormat::F32, TexelFormat::Unorm8, TexelFormat::Bc4] {
        let b = BrickedGrid::convert(&g, format).unwrap();
        let (lo, dims) = b.indirection_box();
        assert_eq!((lo, dims), ([0, -1, -125], [1, 1, 263]));
        assert_eq!(b.bricks().len(), 263);
        assert_within_bound(&g, &b);
    }
}

#[test]
fn box_reads_match_voxel_reads() {
    let g = structured_grid();
    let mut state = Rng::new(17, 0, 0);
    for format in [TexelFormat::Bc4, TexelFormat::Unorm16] {
        let b = BrickedGrid::convert(&g, format).unwrap();
        for _ in 0..50 {
            let origin: [i32; 3] =
                std::array::from_fn(|k| g.origin[k] - 12 + (rng(&mut state) * 40.0) as i32);
            let dims: [u32; 3] = std::array::from_fn(|_| 1 + (rng(&mut state) * 19.0) as u32);
            let mut out = vec![f32::NAN; dims.iter().product::<u32>() as usize];
            b.read_box(origin, dims, &mut out);
            let mut i = 0;
            for z in 0..dims[2] as i32 {
                for y in 0..dims[1] as i32 {
                    for x in 0..dims[0] as i32 {
                        let ijk = [origin[0] + x, origin[1] + y, origin[2] + z];
                        assert_eq!(out[i], b.voxel(ijk), "{format} {ijk:?}");
                        i += 1;
                    }
                }
            }
        }
        // Non-finite points read the background, and their majorant is the background's.
        let p = [f64::NAN, 0.0, 0.0];
        assert_eq!((sample_trilinear(&b, p), b.majorant(2, p)), (0.0, 0.0));
    }
}

/// A sparse source: one constant-valued 8^3 block per origin.
struct Blocks {
    origins: Vec<[i32; 3]>,
    map: hytrace_volume::GridMap,
}

impl VoxelGrid for Blocks {
    fn background(&self) -> f32 {
        0.0
    }

    fn voxel(&self, ijk: [i32; 3]) -> f32 {
        let block = ijk.map(|c| c.div_euclid(8) * 8);
        self.origins.contains(&block) as u8 as f32
    }

    fn block_origins(&self) -> Result<Vec<[i32; 3]>, hytrace_volume::VolumeError> {
        Ok(self.origins.clone())
    }

    fn map(&self) -> &hytrace_volume::GridMap {
        &self.map
    }
}

#[test]
fn sparse_sources_convert_within_the_box_limit() {
    let map = hytrace_volume::GridMap::IDENTITY;
    let near = Blocks {
        origins: vec![[-8, 0, 0], [800, -8, 16], [-8, 0, 0]],
        map,
    };
    let b = BrickedGrid::convert(&near, TexelFormat::Bc4).unwrap();
    // Duplicate origins are stored once; both blocks are constant.
    assert_eq!((b.bricks().len(), b.atlas_slots()), (2, 0));
    assert_eq!(b.indirection_box(), ([-1, -1, 0], [102, 2, 3]));
    assert_eq!((b.voxel([805, -1, 23]), b.voxel([805, -1, 24])), (1.0, 0.0));
    // Two bricks 600 bricks apart on every axis: the dense indirection box is too large.
    let far = Blocks {
        origins: vec![[0; 3], [4800; 3]],
        map,
    };
    let err = BrickedGrid::convert(&far, TexelFormat::F32)
        .unwrap_err()
        .to_string();
    assert!(err.contains("[601, 601, 601]"), "{err}");
    let odd = Blocks {
        origins: vec![[4, 0, 0]],
        map,
    };
    assert!(BrickedGrid::convert(&odd, TexelFormat::F32)
        .unwrap_err()
        .to_string()
        .contains("[4, 0, 0]"));
}

#[test]
fn grids_of_background_only_convert_to_nothing() {
    let g = DenseGrid::new([-3, 0, 5], [9, 9, 9], 0.5).unwrap();
    let b = BrickedGrid::convert(&g, TexelFormat::Bc4).unwrap();
    assert!(b.bricks().is_empty() && b.atlas().is_empty() && b.foundry_bricks().is_empty());
    assert_eq!(b.voxel([0, 2, 7]), 0.5);
    assert_eq!(b.majorant(3, [0.0, 2.0, 7.0]), 0.5);
    let dir = tempfile::tempdir().unwrap();
    b.write_npy_dir(&dir.path().join("empty")).unwrap();
    let ind = read_array(&dir.path().join("empty/indirection.npy")).unwrap();
    assert_eq!(ind.shape, vec![0, 0, 0]);
}

#[test]
fn memory_breakdown_adds_up() {
    let g = structured_grid();
    let bc4 = BrickedGrid::convert(&g, TexelFormat::Bc4).unwrap();
    let u8 = BrickedGrid::convert(&g, TexelFormat::Unorm8).unwrap();
    let (mb, m8) = (bc4.memory_bytes(), u8.memory_bytes());
    assert_eq!(mb.atlas, bc4.atlas_slots() * 256);
    assert_eq!(2 * mb.atlas, m8.atlas);
    assert_eq!(mb.indirection, bc4.indirection().len() * 4);
    assert_eq!(mb.brick_table, 32 * bc4.bricks().len());
    assert_eq!(mb.ranges, bc4.ranges().memory_bytes());
    assert_eq!(
        mb.total(),
        mb.atlas + mb.indirection + mb.brick_table + mb.ranges
    );
}

/// The NumPy type string, shape and data bytes of an `.npy` file.
fn npy_header_and_data(path: &Path) -> (String, Vec<u64>, Vec<u8>) {
    let bytes = std::fs::read(path).unwrap();
    let npy = npyz::NpyFile::new(&bytes[..]).unwrap();
    let descr = npy.dtype().descr();
    let shape = npy.shape().to_vec();
    let item = npy.dtype().num_bytes().unwrap() as u64;
    let len = (shape.iter().product::<u64>() * item) as usize;
    (descr, shape, bytes[bytes.len() - len..].to_vec())
}

#[test]
fn npy_directory_has_the_documented_shapes() {
    let g = structured_grid();
    let dir = tempfile::tempdir().unwrap();
    for (format, descr, per_slot) in [
        (TexelFormat::Bc4, "'<u8'", vec![8, 4]),
        (TexelFormat::Unorm8, "'|u1'", vec![8, 8, 8]),
        (TexelFormat::Unorm16, "'<u2'", vec![8, 8, 8]),
        (TexelFormat::F16, "'<f2'", vec![8, 8, 8]),
        (TexelFormat::F32, "'<f4'", vec![8, 8, 8]),
    ] {
        let b = BrickedGrid::convert(&g, format).unwrap();
        let out = dir.path().join(format.name());
        b.write_npy_dir(&out).unwrap();
        // Writing again replaces the files in place.
        b.write_npy_dir(&out).unwrap();

        let (d, shape, data) = npy_header_and_data(&out.join("atlas.npy"));
        let mut expected = vec![b.atlas_slots() as u64];
        expected.extend(per_slot);
        assert_eq!((d.as_str(), shape), (descr, expected));
        assert_eq!(data, b.atlas());

        let (lo, dims) = b.indirection_box();
        let zyx = [dims[2], dims[1], dims[0]].map(u64::from);
        let ind = read_array(&out.join("indirection.npy")).unwrap();
        assert_eq!((ind.scalar, &ind.shape[..]), (Scalar::U32, &zyx[..]));
        assert_eq!(ind.bytes, bytemuck::cast_slice::<u32, u8>(b.indirection()));

        let table: Vec<BrickEntry> = read_records(&out.join("bricks.npy")).unwrap();
        assert_eq!(table, b.bricks());

        for (l, level) in b.ranges().levels.iter().enumerate() {
            let r = read_array(&out.join(format!("ranges_l{l}.npy"))).unwrap();
            let d = level.dims;
            assert_eq!(r.shape, vec![d[2] as u64, d[1] as u64, d[0] as u64, 2]);
            let pairs: Vec<f32> = bytemuck::pod_collect_to_vec(&r.bytes);
            let want: Vec<f32> = level.ranges.iter().flat_map(|r| [r.min, r.max]).collect();
            assert_eq!(pairs, want);
        }

        let meta: serde_json::Value =
            serde_json::from_slice(&std::fs::read(out.join("meta.json")).unwrap()).unwrap();
        assert_eq!(meta["format"], format.name());
        assert_eq!(meta["lo"], serde_json::json!(lo));
        assert_eq!(meta["dims"], serde_json::json!(dims));
        let stated = meta["error_bound"].as_f64().unwrap();
        assert!((stated - b.error_bound()).abs() <= 1e-15 * b.error_bound());
        assert_eq!(meta["background"], 0.0);
        // Nothing but the documented files (no temporaries left behind).
        let mut names: Vec<String> = std::fs::read_dir(&out)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        assert_eq!(
            names,
            [
                "atlas.npy",
                "bricks.npy",
                "indirection.npy",
                "meta.json",
                "ranges_l0.npy",
                "ranges_l1.npy",
                "ranges_l2.npy",
                "ranges_l3.npy"
            ]
        );
    }
    // A file in the way is an error, not a clobbered file.
    let file = dir.path().join("file");
    std::fs::write(&file, b"x").unwrap();
    let b = BrickedGrid::convert(&g, TexelFormat::Bc4).unwrap();
    assert!(b.write_npy_dir(&file).is_err());
    assert_eq!(std::fs::read(&file).unwrap(), b"x");
}

#[test]
fn conversion_is_deterministic_across_thread_counts() {
    let mut g = offset_grid(2.0, 1.5, 21);
    g.set([0, 0, 0], 0.0);
    let convert = |threads| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| BrickedGrid::convert(&g, TexelFormat::Bc4).unwrap())
    };
    let (one, four) = (convert(1), convert(4));
    assert_eq!(one.atlas(), four.atlas());
    assert_eq!(one, four);
    assert_eq!(one, BrickedGrid::convert(&g, TexelFormat::Bc4).unwrap());
}
