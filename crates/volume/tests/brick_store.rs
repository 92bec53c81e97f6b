//! The out-of-core brick store against the in-core path: raw volumes generated here are
//! converted, opened with budgets far smaller than the volume, and every voxel, the range
//! mips, the Foundry bricks and the transmittance of every estimator must equal those of a dense in-memory
//! grid holding the values the store promises (each raw value quantized to 16 bits, bricks
//! within the threshold of the background dropped), computed here independently.
//! Bad input: raw files of the wrong size, non-finite voxels, budgets below one
//! superchunk, truncated and corrupted stores, an existing output.

use std::path::{Path, PathBuf};

use hytrace_volume::{
    convert_grid, convert_raw, fog_sphere, open_volume_with, planned_memory, select_grid,
    transmittance_batch, BrickStore, BrickedGrid, ConvertOptions, DenseGrid, Endian, Estimator,
    Filter, GridMap, Majorant, RangeMips, RawSpec, RawType, Ray, Rng, TexelFormat,
    TransmittanceParams, VoxelGrid, SUPERCHUNK_BRICKS,
};

/// A coral-like field: thin shells around a few random centres, mostly empty space, with
/// values in [0, 3); x fastest.
fn coral_field(dims: [u32; 3], seed: u32, shells: usize) -> Vec<f32> {
    let mut rng = Rng::new(seed, 0, 0);
    let centres: Vec<([f64; 3], f64)> = (0..shells)
        .map(|_| {
            let c = std::array::from_fn(|k| rng.next_f64() * dims[k] as f64);
            (c, 4.0 + rng.next_f64() * dims[0] as f64 * 0.3)
        })
        .collect();
    let [nx, ny, nz] = dims.map(|d| d as usize);
    let mut out = vec![0f32; nx * ny * nz];
    for z in 0..nz {
        for y in 0..ny {
            for x in 0..nx {
                let p = [x as f64, y as f64, z as f64];
                let mut v = 0.0f64;
                for (c, r) in &centres {
                    if (0..3).any(|k| (p[k] - c[k]).abs() > r + 3.0) {
                        continue;
                    }
                    let d = (0..3).map(|k| (p[k] - c[k]).powi(2)).sum::<f64>().sqrt();
                    let shell = 1.0 - (d - r).abs() / 2.5;
                    if shell > 0.0 {
                        v += shell * (1.0 + 0.5 * (0.3 * p[0] + 0.2 * p[1]).sin());
                    }
                }
                out[(z * ny + y) * nx + x] = v.min(2.999) as f32;
            }
        }
    }
    out
}

fn write_raw(path: &Path, values: &[f32], dtype: RawType, endian: Endian) {
    let bytes: Vec<u8> = values
        .iter()
        .flat_map(|&v| match (dtype, endian) {
            (RawType::F32, Endian::Little) => v.to_le_bytes().to_vec(),
            (RawType::F32, Endian::Big) => v.to_be_bytes().to_vec(),
            (RawType::U16, Endian::Little) => ((v * 1000.0) as u16).to_le_bytes().to_vec(),
            (RawType::U16, Endian::Big) => ((v * 1000.0) as u16).to_be_bytes().to_vec(),
            (RawType::U8, _) => vec![(v * 80.0) as u8],
        })
        .collect();
    std::fs::write(path, bytes).unwrap();
}

/// The voxel values as the file holds them (what the converter reads).
fn file_values(values: &[f32], dtype: RawType) -> Vec<f32> {
    values
        .iter()
        .map(|&v| match dtype {
            RawType::F32 => v,
            RawType::U16 => f32::from((v * 1000.0) as u16),
            RawType::U8 => f32::from((v * 80.0) as u8),
        })
        .collect()
}

fn spec(dims: [u32; 3], dtype: RawType, endian: Endian) -> RawSpec {
    RawSpec {
        dims,
        dtype,
        endian,
        spacing: [0.5, 0.5, 0.75],
        origin: [-3.0, 1.0, 2.0],
    }
}

fn options(background: f32, threshold: f32) -> ConvertOptions {
    ConvertOptions {
        background,
        threshold,
        range: None,
        memory: 1 << 32,
    }
}

/// The store's promise, computed without the converter: each voxel quantized with the
/// store's codes (nearest code of `(v - lo) / step`, decoded `lo + code * step` in f32),
/// bricks whose decoded voxels all lie within the threshold of the background dropped;
/// `values` (x fastest) start at index `origin`, placed by `map`.
fn expected_grid(
    values: &[f32],
    origin: [i32; 3],
    dims: [u32; 3],
    map: GridMap,
    store: &BrickStore,
) -> (DenseGrid, u64) {
    let meta = store.meta();
    let q = meta.quantization;
    let code = |v: f32| -> f32 {
        let c = if q.step == 0.0 {
            0.0
        } else {
            ((f64::from(v) - f64::from(q.lo)) / f64::from(q.step))
                .round()
                .clamp(0.0, 65535.0)
        };
        q.lo + (c as u16) as f32 * q.step
    };
    let mut g = DenseGrid::new(origin, dims, meta.background).unwrap();
    let [nx, ny, nz] = dims.map(|d| d as usize);
    let mut kept = 0;
    for bz in 0..nz.div_ceil(8) {
        for by in 0..ny.div_ceil(8) {
            for bx in 0..nx.div_ceil(8) {
                let voxels: Vec<(usize, f32)> = (bz * 8..(bz * 8 + 8).min(nz))
                    .flat_map(|z| (by * 8..(by * 8 + 8).min(ny)).map(move |y| (z, y)))
                    .flat_map(|(z, y)| (bx * 8..(bx * 8 + 8).min(nx)).map(move |x| (z, y, x)))
                    .map(|(z, y, x)| {
                        let i = (z * ny + y) * nx + x;
                        (i, code(values[i]))
                    })
                    .collect();
                let keep = voxels
                    .iter()
                    .any(|(_, v)| (v - meta.background).abs() > meta.threshold);
                if keep {
                    kept += 1;
                    for (i, v) in voxels {
                        g.values[i] = v;
                    }
                }
            }
        }
    }
    (g.with_map(map), kept)
}

/// The map of the raw volumes' [`spec`].
fn raw_map() -> GridMap {
    GridMap::new(
        [[0.5, 0.0, 0.0], [0.0, 0.5, 0.0], [0.0, 0.0, 0.75]],
        [-3.0, 1.0, 2.0],
    )
    .unwrap()
}

/// Rays through the volume's world box from all sides, some starting inside.
fn rays(dims: [u32; 3], count: usize) -> Vec<Ray> {
    let mut rng = Rng::new(7, 1, 0);
    let size = [
        dims[0] as f64 * 0.5,
        dims[1] as f64 * 0.5,
        dims[2] as f64 * 0.75,
    ];
    let lo = [-3.0, 1.0, 2.0];
    (0..count)
        .map(|_| {
            let o: [f64; 3] =
                std::array::from_fn(|k| lo[k] - 0.2 * size[k] + rng.next_f64() * 1.4 * size[k]);
            let target: [f64; 3] = std::array::from_fn(|k| lo[k] + rng.next_f64() * size[k]);
            let d: [f64; 3] = std::array::from_fn(|k| target[k] - o[k]);
            let n = d.iter().map(|v| v * v).sum::<f64>().sqrt();
            Ray::new(o, d.map(|v| v / n), 0.0, 1e9)
        })
        .collect()
}

fn every_estimator() -> Vec<TransmittanceParams> {
    let mut out = Vec::new();
    for estimator in [
        Estimator::Exact,
        Estimator::March { step: 0.3 },
        Estimator::Delta,
        Estimator::Ratio,
        Estimator::Residual,
    ] {
        for filter in [Filter::Trilinear, Filter::Nearest, Filter::Stochastic] {
            let mut p = TransmittanceParams::new(estimator);
            p.filter = filter;
            p.spp = 4;
            p.seed = 11;
            p.density_scale = 0.7;
            out.push(p);
        }
    }
    let mut global = TransmittanceParams::new(Estimator::Ratio);
    global.majorant = Majorant::Global;
    out.push(global);
    out
}

fn convert(
    dir: &Path,
    name: &str,
    values: &[f32],
    spec: &RawSpec,
    options: &ConvertOptions,
) -> PathBuf {
    let raw = dir.join(format!("{name}.raw"));
    write_raw(&raw, values, spec.dtype, spec.endian);
    let out = dir.join(format!("{name}.bricks"));
    convert_raw(&raw, spec, options, &out, &|_, _| ()).unwrap();
    out
}

#[test]
fn a_store_read_through_a_small_cache_equals_the_in_core_grid_voxel_by_voxel() {
    let dir = tempfile::tempdir().unwrap();
    // Dimensions that are not multiples of 8 or 16: partial bricks and superchunks.
    let dims = [75, 41, 139];
    let values = coral_field(dims, 3, 6);
    for (dtype, endian, background, threshold) in [
        (RawType::F32, Endian::Little, 0.0, 0.0),
        (RawType::F32, Endian::Big, 0.0, 0.05),
        (RawType::U16, Endian::Big, 0.0, 0.0),
        (RawType::U8, Endian::Little, 0.5, 10.0),
    ] {
        let spec = spec(dims, dtype, endian);
        let name = format!("{dtype:?}-{endian:?}-{threshold}");
        let path = convert(
            dir.path(),
            &name,
            &values,
            &spec,
            &options(background, threshold),
        );
        let store = BrickStore::open(&path, 6 << 20).unwrap();
        let held = file_values(&values, dtype);
        let (expected, kept) = expected_grid(&held, [0; 3], dims, raw_map(), &store);
        assert_eq!(store.meta().kept_bricks, kept, "{name}");
        assert!(
            store.meta().dropped_bricks > 0,
            "{name}: the field is mostly empty"
        );
        // Quantization error at most half a code where bricks are kept.
        let step = store.meta().quantization.step;
        for (i, (&raw, &got)) in held.iter().zip(&expected.values).enumerate() {
            if got != background {
                assert!(
                    (raw - got).abs() <= step * 0.5 + raw.abs() * 1e-6,
                    "{name}: voxel {i}: {raw} -> {got}"
                );
            }
        }
        for z in -2..dims[2] as i32 + 2 {
            for y in -2..dims[1] as i32 + 2 {
                for x in -2..dims[0] as i32 + 2 {
                    assert_eq!(
                        store.voxel([x, y, z]).to_bits(),
                        expected.voxel([x, y, z]).to_bits(),
                        "{name}: voxel {:?}",
                        [x, y, z]
                    );
                }
            }
        }
        // The stored ranges are the in-core grid's range mips, exactly.
        assert_eq!(
            store.mips(),
            &RangeMips::build(&expected).unwrap(),
            "{name}"
        );
        // So are its Foundry bricks (bounds and majorants), read without a brick.
        let bricked = BrickedGrid::convert(&expected, TexelFormat::F32).unwrap();
        let key = |b: &hytrace_foundry::Brick| {
            let bits = [b.value_min, b.value_max].map(f32::to_bits);
            (b.origin, b.aabb.map(f32::to_bits), bits)
        };
        let keys = |bricks: Vec<hytrace_foundry::Brick>| bricks.iter().map(key).collect::<Vec<_>>();
        let reads = store.stats().bricks_read;
        assert_eq!(
            keys(store.foundry_bricks()),
            keys(bricked.foundry_bricks()),
            "{name}"
        );
        // The mips of its data alone are those built by reading its kept bricks.
        let data_mips = store.data_mips().unwrap();
        assert_eq!(store.stats().bricks_read, reads, "{name}");
        assert_eq!(data_mips, RangeMips::build(&store).unwrap(), "{name}");
        store.check().unwrap();
    }
}

#[test]
fn transmittance_through_a_budget_far_below_the_volume_equals_the_in_core_answer_bit_for_bit() {
    let dir = tempfile::tempdir().unwrap();
    // 256 x 256 x 384 f32: 96 MiB of raw data, 24 M voxels; the cache gets a few MiB.
    let dims = [256, 256, 384];
    let values = coral_field(dims, 5, 30);
    let spec = spec(dims, RawType::F32, Endian::Little);
    let path = convert(dir.path(), "coral", &values, &spec, &options(0.0, 0.0));
    let raw_bytes = values.len() as u64 * 4;
    // The least budget the store accepts: its tables and one superchunk's bricks.
    let budget = 6 << 20;
    let store = BrickStore::open(&path, budget).unwrap();
    assert!(budget < raw_bytes / 4);
    let (expected, _) = expected_grid(&values, [0; 3], dims, raw_map(), &store);
    let in_core_mips = RangeMips::build(&expected).unwrap();
    assert_eq!(store.mips(), &in_core_mips);
    let rays = rays(dims, 1000);
    for params in every_estimator() {
        let streamed = transmittance_batch(&store, store.mips(), &rays, &params).unwrap();
        let in_core = transmittance_batch(&expected, &in_core_mips, &rays, &params).unwrap();
        assert_eq!(streamed, in_core, "{params:?}");
        assert!(
            in_core.iter().any(|e| e.transmittance < 0.9),
            "{params:?}: rays see the field"
        );
    }
    store.check().unwrap();
    let stats = store.stats();
    assert!(
        stats.bricks_read > stats.capacity_bricks,
        "the cache evicted and read bricks again: {stats:?}"
    );
    assert!(
        stats.bricks_evicted > 0 && stats.bricks_evicted < stats.bricks_read,
        "evictions counted: {stats:?}"
    );
}

#[test]
fn a_grid_converted_from_memory_keeps_its_index_space_and_map() {
    let dir = tempfile::tempdir().unwrap();
    // A fog sphere: a dense grid centred on index (0, 0, 0), so its blocks start at negative
    // multiples of 8, with a non-trivial map.
    let sphere = fog_sphere(13.0, 3.0).unwrap().with_map(
        GridMap::new(
            [[0.2, 0.1, 0.0], [0.0, 0.3, 0.0], [0.05, 0.0, 0.25]],
            [4.0, -2.0, 7.0],
        )
        .unwrap(),
    );
    let out = dir.path().join("sphere.bricks");
    let seen = std::cell::Cell::new((0, 0));
    let report = convert_grid(
        &sphere,
        "sphere:13",
        &options(0.0, 0.0),
        &out,
        &|done, total| {
            assert!(done > seen.get().0 && done <= total);
            seen.set((done, total));
        },
    )
    .unwrap();
    // Both passes read every voxel once.
    let voxels = report.meta.dims.iter().map(|&d| d as u64).product::<u64>();
    assert_eq!(seen.get(), (2 * voxels, 2 * voxels));
    let store = BrickStore::open(&out, 16 << 20).unwrap();
    let meta = store.meta();
    assert_eq!(meta, &report.meta);
    assert!(
        meta.index_origin.iter().all(|c| c % 8 == 0 && *c < 0),
        "{:?}",
        meta.index_origin
    );
    // Every voxel of the store's box, read from the source.
    let o = meta.index_origin;
    let d = meta.dims;
    let mut values = Vec::new();
    for z in 0..d[2] as i32 {
        for y in 0..d[1] as i32 {
            for x in 0..d[0] as i32 {
                values.push(sphere.voxel([o[0] + x, o[1] + y, o[2] + z]));
            }
        }
    }
    let (expected, kept) = expected_grid(&values, o, d, sphere.map, &store);
    assert_eq!(meta.kept_bricks, kept);
    for z in o[2] - 9..o[2] + d[2] as i32 + 9 {
        for y in o[1] - 9..o[1] + d[1] as i32 + 9 {
            for x in o[0] - 9..o[0] + d[0] as i32 + 9 {
                assert_eq!(
                    store.voxel([x, y, z]).to_bits(),
                    expected.voxel([x, y, z]).to_bits()
                );
            }
        }
    }
    assert_eq!(store.mips(), &RangeMips::build(&expected).unwrap());
    // Opened by name as every volume command opens volumes.
    let spec = out.to_str().unwrap();
    let (summary, volume) =
        select_grid(spec, open_volume_with(spec, 16 << 20).unwrap(), None).unwrap();
    assert_eq!(summary.source_kind, "brick-store");
    assert_eq!(summary.brick_store.as_ref(), Some(meta));
    assert_eq!(summary.index_bbox.unwrap()[0], meta.index_origin);
    assert!(
        matches!(volume.range_mips().unwrap(), std::borrow::Cow::Borrowed(m) if m == store.mips())
    );
    assert_eq!(volume.voxel([0, 0, 0]), expected.voxel([0, 0, 0]));
    // World-space rays through the sheared map.
    let rays: Vec<Ray> = (0..200)
        .map(|k| {
            let a = k as f64 * 0.37;
            let d = [
                a.cos() * (0.7 * a).sin(),
                a.sin() * (0.7 * a).sin(),
                (0.7 * a).cos(),
            ];
            Ray::new(
                [4.0 - 20.0 * d[0], -2.0 - 20.0 * d[1], 7.0 - 20.0 * d[2]],
                d,
                0.0,
                40.0,
            )
        })
        .collect();
    for params in every_estimator() {
        let streamed = transmittance_batch(&store, store.mips(), &rays, &params).unwrap();
        let in_core = transmittance_batch(&expected, store.mips(), &rays, &params).unwrap();
        assert_eq!(streamed, in_core, "{params:?}");
        assert!(in_core.iter().any(|e| e.transmittance < 0.5), "{params:?}");
    }
}

#[test]
fn converting_plans_bounded_memory_for_volumes_far_larger_than_it() {
    // The coral scans of the seed (2144 x 2176 x 2176 f32, 37 GiB) and a 2048^3 16-bit volume.
    let coral = planned_memory([2144, 2176, 2176], RawType::F32);
    assert!(coral < 2 << 30, "{coral}");
    let cube = planned_memory([2048, 2048, 2048], RawType::U16);
    assert!(cube < 2 << 30, "{cube}");
    // Far below the volume: three layers of planes, the tables and (at most) every
    // brick's levels of detail.
    assert!(cube < 2048u64.pow(3) * 2 / 8, "{cube}");
}

#[test]
fn bad_raw_files_and_options_are_refused_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let dims = [20, 20, 20];
    let values = coral_field(dims, 1, 6);
    let raw = dir.path().join("v.raw");
    write_raw(&raw, &values, RawType::F32, Endian::Little);
    let out = dir.path().join("v.bricks");
    let refuse = |spec: &RawSpec, options: &ConvertOptions, want: &str| {
        let e = convert_raw(&raw, spec, options, &out, &|_, _| ())
            .unwrap_err()
            .to_string();
        assert!(e.contains("v.raw") && e.contains(want), "{e}");
        assert!(!out.exists());
    };
    let good = spec(dims, RawType::F32, Endian::Little);
    refuse(
        &spec([20, 20, 21], RawType::F32, Endian::Little),
        &options(0.0, 0.0),
        "need 33600",
    );
    refuse(
        &spec(dims, RawType::U16, Endian::Little),
        &options(0.0, 0.0),
        "has 32000 bytes",
    );
    refuse(
        &spec([0, 20, 20], RawType::F32, Endian::Little),
        &options(0.0, 0.0),
        "at least 1",
    );
    let mut bad_spacing = good.clone();
    bad_spacing.spacing[1] = 0.0;
    refuse(&bad_spacing, &options(0.0, 0.0), "--spacing");
    refuse(&good, &options(f32::NAN, 0.0), "background");
    refuse(&good, &options(0.0, -1.0), "threshold");
    let mut small = options(0.0, 0.0);
    small.memory = 1000;
    refuse(&good, &small, "--memory 1000");
    let mut range = options(0.0, 0.0);
    range.range = Some([2.0, 1.0]);
    refuse(&good, &range, "--range");
    // A NaN voxel late in the file: refused by position, nothing left behind.
    let mut nan = values.clone();
    nan[19 + 20 * (5 + 20 * 17)] = f32::NAN;
    write_raw(&raw, &nan, RawType::F32, Endian::Little);
    refuse(&good, &options(0.0, 0.0), "voxel [19, 5, 17] is NaN");
    let mut given_range = options(0.0, 0.0);
    given_range.range = Some([0.0, 3.0]);
    refuse(&good, &given_range, "voxel [19, 5, 17] is NaN");
    let leftovers: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .filter(|n| n != "v.raw")
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
    // An existing output is not overwritten.
    write_raw(&raw, &values, RawType::F32, Endian::Little);
    std::fs::create_dir(&out).unwrap();
    let e = convert_raw(&raw, &good, &options(0.0, 0.0), &out, &|_, _| ()).unwrap_err();
    assert!(e.to_string().contains("already exists"), "{e}");
}

/// A raw volume streamed through a pipe (read once, as a reconstruction streamed while it
/// is made, or a file decompressed on the fly) converts with its range given to the same
/// store, file for file, as the file itself; without the range, and with a stream shorter
/// or longer than the volume, it is refused naming the pipe, nothing left behind.
#[cfg(unix)]
#[test]
fn a_raw_volume_streamed_through_a_pipe_converts_in_one_pass_with_its_range() {
    let dir = tempfile::tempdir().unwrap();
    let dims = [20, 20, 20];
    let values = coral_field(dims, 1, 6);
    let spec = spec(dims, RawType::F32, Endian::Little);
    let mut opts = options(0.0, 0.0);
    let lo = values.iter().copied().fold(f32::INFINITY, f32::min);
    let hi = values.iter().copied().fold(f32::NEG_INFINITY, f32::max);
    opts.range = Some([lo, hi]);
    let from_file = convert(dir.path(), "file", &values, &spec, &opts);
    let bytes = std::fs::read(dir.path().join("file.raw")).unwrap();
    let pipe = dir.path().join("pipe.raw");
    let made = std::process::Command::new("mkfifo")
        .arg(&pipe)
        .status()
        .unwrap();
    assert!(made.success());
    // Writes `bytes` into the pipe once a reader opens it (a reader that stops early
    // breaks the pipe: the writer's error is expected then).
    let feed = |bytes: Vec<u8>| {
        let pipe = pipe.clone();
        std::thread::spawn(move || {
            let mut f = std::fs::OpenOptions::new().write(true).open(pipe).unwrap();
            let _ = std::io::Write::write_all(&mut f, &bytes);
        })
    };
    let out = dir.path().join("pipe.bricks");
    let writer = feed(bytes.clone());
    convert_raw(&pipe, &spec, &opts, &out, &|_, _| ()).unwrap();
    writer.join().unwrap();
    for entry in std::fs::read_dir(&from_file).unwrap() {
        let name = entry.unwrap().file_name();
        let a = std::fs::read(from_file.join(&name)).unwrap();
        let b = std::fs::read(out.join(&name)).unwrap();
        if name == "store.json" {
            // The metadata names its source file.
            let a = String::from_utf8(a)
                .unwrap()
                .replace("file.raw", "pipe.raw");
            assert_eq!(a, String::from_utf8(b).unwrap());
        } else {
            assert!(a == b, "{name:?} differs");
        }
    }
    std::fs::remove_dir_all(&out).unwrap();
    let refused = |opts: &ConvertOptions, want: &str| {
        let e = convert_raw(&pipe, &spec, opts, &out, &|_, _| ())
            .unwrap_err()
            .to_string();
        assert!(e.contains("pipe.raw") && e.contains(want), "{e}");
        assert!(!out.exists());
    };
    // Refused before the pipe is opened: no writer.
    refused(&options(0.0, 0.0), "--range");
    let writer = feed(bytes[..bytes.len() - 7].to_vec());
    refused(&opts, "failed to fill whole buffer");
    writer.join().unwrap();
    let writer = feed([&bytes[..], &[0u8; 16]].concat());
    refused(&opts, "holds more than the 32000 bytes");
    writer.join().unwrap();
    let leftovers: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .filter(|n| n != "file.raw" && n != "file.bricks" && n != "pipe.raw")
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
}

#[test]
fn truncated_corrupted_and_underbudgeted_stores_are_refused_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let dims = [40, 40, 40];
    let values = coral_field(dims, 2, 6);
    let spec = spec(dims, RawType::F32, Endian::Little);
    let path = convert(dir.path(), "s", &values, &spec, &options(0.0, 0.0));
    // A budget below one superchunk's bricks.
    let e = BrickStore::open(&path, SUPERCHUNK_BRICKS as u64 * 1024)
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("s.bricks") && e.contains("too small"), "{e}");
    let open_error = |file: &str, bytes: Vec<u8>| -> String {
        let target = path.join(file);
        let original = std::fs::read(&target).unwrap();
        std::fs::write(&target, bytes).unwrap();
        let e = BrickStore::open(&path, 64 << 20)
            .err()
            .map(|e| e.to_string());
        std::fs::write(&target, original).unwrap();
        e.unwrap_or_else(|| panic!("{file}: the damaged store opened"))
    };
    for file in [
        "store.json",
        "superchunks.npy",
        "brick_lod.npy",
        "ranges.npy",
        "bricks.bin",
    ] {
        let bytes = std::fs::read(path.join(file)).unwrap();
        // Every truncation (sampled) is refused with the file named.
        for len in (0..bytes.len()).step_by(bytes.len() / 97 + 1) {
            let e = open_error(file, bytes[..len].to_vec());
            assert!(e.contains(file), "{file} cut to {len}: {e}");
        }
        let mut longer = bytes.clone();
        longer.push(0);
        let e = open_error(file, longer);
        assert!(e.contains(file), "{file} + 1 byte: {e}");
    }
    // A table entry pointing past the kept bricks.
    let table = std::fs::read(path.join("superchunks.npy")).unwrap();
    let mut bad = table.clone();
    let n = bad.len();
    bad[n - 4..].copy_from_slice(&7_000_000u32.to_le_bytes());
    let e = open_error("superchunks.npy", bad);
    assert!(e.contains("past the"), "{e}");
    // Unordered ranges.
    let ranges = std::fs::read(path.join("ranges.npy")).unwrap();
    let mut bad = ranges.clone();
    let n = bad.len();
    bad[n - 8..n - 4].copy_from_slice(&5.0f32.to_le_bytes());
    bad[n - 4..].copy_from_slice(&1.0f32.to_le_bytes());
    let e = open_error("ranges.npy", bad);
    assert!(e.contains("ordered pair"), "{e}");
    // Another format version.
    let json = std::fs::read_to_string(path.join("store.json")).unwrap();
    let e = open_error(
        "store.json",
        json.replace("\"version\": 1", "\"version\": 9")
            .into_bytes(),
    );
    assert!(e.contains("version 9"), "{e}");
    assert!(BrickStore::open(&path, 64 << 20).is_ok());
    // A store truncated after it was opened: lookups read the background and `check` says
    // which file failed.
    let store = BrickStore::open(&path, 64 << 20).unwrap();
    let bin = path.join("bricks.bin");
    std::fs::OpenOptions::new()
        .write(true)
        .open(&bin)
        .unwrap()
        .set_len(0)
        .unwrap();
    let inside: Vec<[i32; 3]> = (0..40).map(|k| [k, k, k]).collect();
    for p in inside {
        let _ = store.voxel(p);
    }
    let e = store.check().unwrap_err().to_string();
    assert!(e.contains("bricks.bin"), "{e}");
}
