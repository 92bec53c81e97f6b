//! The NanoVDB reader against files written by the reference tools (NanoVDB 32.4.2, see
//! tests/data/nanovdb/README.md), files derived from them in the layouts of newer
//! versions, and corrupted, truncated and fuzzed copies.

use std::collections::HashSet;
use std::io::Read;
use std::path::{Path, PathBuf};

use hytrace_testkit::{Random, SplitMix64};
use hytrace_volume::{
    parse_nanovdb, read_nanovdb, Coord, NanoCodec, NanoFile, NanoGrid, NanoGridClass, NanoGridType,
    NanoVersion, RangeMips, VoxelGrid,
};

fn data_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/data/nanovdb")
}

/// The bytes of a fixture; `.gz` fixtures are gunzipped.
fn fixture(name: &str) -> Vec<u8> {
    let bytes = std::fs::read(data_dir().join(name)).unwrap();
    if !name.ends_with(".gz") {
        return bytes;
    }
    let mut out = Vec::new();
    flate2::read::GzDecoder::new(&bytes[..])
        .read_to_end(&mut out)
        .unwrap();
    out
}

fn parse(name: &str) -> NanoFile {
    parse_nanovdb(&fixture(name), name).unwrap_or_else(|e| panic!("{e}"))
}

/// A dense source array saved by make_fixtures.py: C order, index [a][b][c] = voxel
/// origin + (a, b, c).
struct Source<T> {
    origin: Coord,
    dims: [usize; 3],
    values: Vec<T>,
}

impl<T: Copy> Source<T> {
    fn get(&self, ijk: Coord) -> Option<T> {
        let local: [i64; 3] = std::array::from_fn(|a| ijk[a] as i64 - self.origin[a] as i64);
        if (0..3).any(|a| local[a] < 0 || local[a] >= self.dims[a] as i64) {
            return None;
        }
        let [a, b, c] = local.map(|v| v as usize);
        Some(self.values[(a * self.dims[1] + b) * self.dims[2] + c])
    }

    /// Every voxel of the source box grown by `margin` on each side.
    fn voxels(&self, margin: i32) -> Vec<Coord> {
        let mut out = Vec::new();
        for a in -margin..self.dims[0] as i32 + margin {
            for b in -margin..self.dims[1] as i32 + margin {
                for c in -margin..self.dims[2] as i32 + margin {
                    out.push([self.origin[0] + a, self.origin[1] + b, self.origin[2] + c]);
                }
            }
        }
        out
    }
}

fn npy<T: npyz::Deserialize>(name: &str, origin: Coord) -> Source<T> {
    let bytes = std::fs::read(data_dir().join(name)).unwrap();
    let file = npyz::NpyFile::new(&bytes[..]).unwrap();
    let shape = file.shape().to_vec();
    assert_eq!(shape.len(), 3, "{name}");
    Source {
        origin,
        dims: std::array::from_fn(|a| shape[a] as usize),
        values: file.into_vec().unwrap(),
    }
}

const DENSITY_ORIGIN: Coord = [-37, -26, -20];

fn density() -> Source<f32> {
    npy("density.npy", DENSITY_ORIGIN)
}

fn temperature() -> Source<f64> {
    npy("temperature.npy", [5, 6, 7])
}

fn block_of(ijk: Coord) -> Coord {
    ijk.map(|c| c.div_euclid(8) * 8)
}

/// Checks the facts of a density grid against its source (any value type).
fn check_density_facts(g: &NanoGrid, src: &Source<f32>) {
    let active: Vec<Coord> = src
        .voxels(0)
        .into_iter()
        .filter(|c| src.get(*c) != Some(0.0))
        .collect();
    assert_eq!(g.name(), "density");
    assert_eq!(g.grid_class(), NanoGridClass::FogVolume);
    assert_eq!(
        g.version(),
        NanoVersion {
            major: 32,
            minor: 4,
            patch: 2
        }
    );
    assert_eq!(g.active_voxel_count(), active.len() as u64);
    let lo = std::array::from_fn(|a| active.iter().map(|c| c[a]).min().unwrap());
    let hi = std::array::from_fn(|a| active.iter().map(|c| c[a]).max().unwrap());
    assert_eq!(g.index_bbox(), Some([lo, hi]));
    let blocks: HashSet<Coord> = active.iter().map(|c| block_of(*c)).collect();
    let counts = g.node_counts();
    assert_eq!(
        (counts.leaves as usize, counts.lower, counts.upper),
        (blocks.len(), 1, 1)
    );
    let listed: HashSet<Coord> = g.block_origins().unwrap().into_iter().collect();
    assert_eq!(listed, blocks);
    assert!(g.is_sampleable() && g.check_sampleable().is_ok());

    // world = 0.5 * Rz(30 deg) * ijk + (1.5, -2.25, 3).
    let (s, c) = 30f64.to_radians().sin_cos();
    let expect = [
        [0.5 * c, -0.5 * s, 0.0],
        [0.5 * s, 0.5 * c, 0.0],
        [0.0, 0.0, 0.5],
    ];
    let map = g.map();
    let close = map
        .matrix
        .iter()
        .flatten()
        .zip(expect.iter().flatten())
        .all(|(m, e)| (m - e).abs() < 1e-12);
    assert!(close, "{:?}", map.matrix);
    assert!((0..3).all(|a| (map.translation[a] - [1.5, -2.25, 3.0][a]).abs() < 1e-12));
    assert!(g.voxel_size().iter().all(|v| (v - 0.5).abs() < 1e-12));
    // The world box holds every active voxel centre.
    let [wlo, whi] = g.world_bbox().unwrap();
    for ijk in &active {
        let w = map.index_to_world(ijk.map(f64::from));
        assert!((0..3).all(|a| w[a] >= wlo[a] - 1e-9 && w[a] <= whi[a] + 1e-9));
    }
}

#[test]
fn float_grids_match_their_source_exactly_with_every_codec() {
    let src = density();
    let mut buffers = Vec::new();
    for (name, codec) in [
        ("density_none.nvdb.gz", NanoCodec::None),
        ("density_zip.nvdb", NanoCodec::Zip),
        ("density_blosc.nvdb", NanoCodec::Blosc),
    ] {
        let file = parse(name);
        assert_eq!(file.grids.len(), 1);
        let g = &file.grids[0];
        assert_eq!(
            (g.grid_type(), g.codec()),
            (NanoGridType::Float, codec),
            "{name}"
        );
        check_density_facts(g, &src);
        assert_eq!(g.background(), 0.0);
        for ijk in src.voxels(9) {
            let expect = src.get(ijk).unwrap_or(0.0);
            assert_eq!(g.voxel(ijk), expect, "{name} {ijk:?}");
            assert_eq!(g.voxel_f64(ijk), f64::from(expect), "{name} {ijk:?}");
        }
        buffers.push(g.buffer().to_vec());
    }
    // The three codecs carry the same grid buffer.
    assert_eq!(buffers[0], buffers[1]);
    assert_eq!(buffers[0], buffers[2]);
    assert_eq!(
        buffers[0].len() as u64,
        parse("density_zip.nvdb").grids[0].buffer_bytes()
    );
}

#[test]
fn quantized_grids_stay_within_their_quantum() {
    let src = density();
    // Per leaf, NanoVDB 32.4 quantizes all 512 values (inactive ones hold the background)
    // between their min and max, rounding to the nearest code: error <= quantum / 2.
    let leaf_range = |ijk: Coord| {
        let o = block_of(ijk);
        let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
        for a in 0..8 {
            for b in 0..8 {
                for c in 0..8 {
                    let v = src.get([o[0] + a, o[1] + b, o[2] + c]).unwrap_or(0.0);
                    lo = lo.min(v);
                    hi = hi.max(v);
                }
            }
        }
        hi - lo
    };
    for (name, grid_type, bits) in [
        ("density_fp4.nvdb", NanoGridType::Fp4, 4),
        ("density_fp8.nvdb", NanoGridType::Fp8, 8),
        ("density_fp16.nvdb", NanoGridType::Fp16, 16),
    ] {
        let file = parse(name);
        let g = &file.grids[0];
        assert_eq!(g.grid_type(), grid_type);
        check_density_facts(g, &src);
        let mut worst = 0f32;
        for ijk in src.voxels(9) {
            let v = g.voxel(ijk);
            match src.get(ijk) {
                Some(e) if e != 0.0 => {
                    let quantum = leaf_range(ijk) / ((1u32 << bits) - 1) as f32;
                    let err = (v - e).abs();
                    assert!(
                        err <= 0.5 * quantum * 1.0001 + 1e-6,
                        "{name} {ijk:?}: {v} vs {e}"
                    );
                    worst = worst.max(err / quantum);
                }
                _ => assert_eq!(v, 0.0, "{name} {ijk:?}"),
            }
        }
        // The bound is tight: rounding uses about half a quantum somewhere.
        assert!(worst > 0.3, "{name}: worst error {worst} quanta");
    }
    let file = parse("density_fpn.nvdb");
    let g = &file.grids[0];
    assert_eq!(g.grid_type(), NanoGridType::FpN);
    check_density_facts(g, &src);
    for ijk in src.voxels(9) {
        let v = g.voxel(ijk);
        match src.get(ijk) {
            // make_fixtures.py converted with an absolute tolerance of 0.002.
            Some(e) if e != 0.0 => assert!((v - e).abs() <= 0.002 + 1e-6, "{ijk:?}: {v} vs {e}"),
            _ => assert_eq!(v, 0.0, "{ijk:?}"),
        }
    }
}

#[test]
fn double_grids_keep_their_f64_values() {
    let src = temperature();
    let file = parse("temperature_zip.nvdb");
    let g = &file.grids[0];
    assert_eq!(
        (g.name(), g.grid_type()),
        ("temperature", NanoGridType::Double)
    );
    let bg = 293.15;
    assert_eq!(g.background(), bg as f32);
    let active = src
        .voxels(0)
        .into_iter()
        .filter(|c| src.get(*c) != Some(bg))
        .count();
    assert_eq!(g.active_voxel_count(), active as u64);
    let mut inexact = 0;
    for ijk in src.voxels(5) {
        let expect = src.get(ijk).unwrap_or(bg);
        assert_eq!(g.voxel_f64(ijk), expect, "{ijk:?}");
        assert_eq!(g.voxel(ijk), expect as f32, "{ijk:?}");
        inexact += (f64::from(expect as f32) != expect) as usize;
    }
    assert!(inexact > 100, "the source must need f64");
    let map = g.map();
    assert_eq!(
        map.matrix,
        [[0.25, 0.0, 0.0], [0.0, 0.25, 0.0], [0.0, 0.0, 0.25]]
    );
    assert_eq!(map.translation, [-1.0, -2.0, -3.0]);
}

#[test]
fn a_file_lists_all_its_grids_and_refuses_to_sample_vectors() {
    let file = read_nanovdb(&data_dir().join("multi_zip.nvdb")).unwrap();
    let names: Vec<&str> = file.grids.iter().map(|g| g.name()).collect();
    assert_eq!(names, ["density", "empty", "velocity"]);
    check_density_facts(file.grid("density").unwrap(), &density());

    let empty = file.grid("empty").unwrap();
    assert_eq!(empty.grid_type(), NanoGridType::Float);
    assert_eq!((empty.index_bbox(), empty.world_bbox()), (None, None));
    assert_eq!(empty.active_voxel_count(), 0);
    assert!(empty.block_origins().unwrap().is_empty());
    assert_eq!(empty.voxel([0, 0, 0]), 0.0);

    let velocity = file.grid("velocity").unwrap();
    assert_eq!(velocity.grid_type(), NanoGridType::Vec3f);
    assert_eq!(velocity.grid_type().to_string(), "Vec3f");
    assert_eq!(velocity.index_bbox(), Some([[2, 3, 4], [5, 6, 7]]));
    assert_eq!(velocity.active_voxel_count(), 64);
    assert_eq!(velocity.node_counts().leaves, 1);
    assert!(!velocity.is_sampleable());
    let err = velocity.check_sampleable().unwrap_err().to_string();
    assert!(
        err.contains("multi_zip.nvdb") && err.contains("'velocity'") && err.contains("Vec3f"),
        "{err}"
    );
    assert_eq!(velocity.voxel([3, 4, 5]), 0.0);
    assert!(velocity.block_origins().unwrap().is_empty());
    assert!(file.grid("missing").is_none());
}

#[test]
fn tiles_read_their_values_and_list_their_blocks() {
    for (name, tolerance) in [
        ("tiles_zip.nvdb", 0.0),
        ("tiles_fp8.nvdb", 4.5 / 255.0 * 0.5001),
    ] {
        let file = parse(name);
        let g = &file.grids[0];
        assert_eq!(g.background(), 0.5);
        let tiles = g.tile_counts();
        assert_eq!((tiles.lower, tiles.upper, tiles.root), (1, 1, 0), "{name}");
        // Active upper tile of 128^3 (2.0), active lower tile of 8^3 (3.0), inactive lower
        // tile holding 7.0 (reads the background), two voxels, background elsewhere.
        for (ijk, expect) in [
            ([0, 0, 0], 2.0),
            ([127, 127, 127], 2.0),
            ([64, 5, 99], 2.0),
            ([128, 0, 0], 3.0),
            ([135, 7, 7], 3.0),
            ([136, 0, 0], 0.5),
            ([143, 7, 7], 0.5),
            ([128, 8, 0], 0.5),
            ([-1, 0, 0], 0.5),
            ([-5, 3, 2], 1.25),
            ([-5, 3, 3], 0.5),
            ([200, 1, 1], -4.0),
            ([4096, 1, 1], 0.5),
        ] {
            let v = g.voxel(ijk);
            assert!(
                (v - expect).abs() <= tolerance,
                "{name} {ijk:?}: {v} vs {expect}"
            );
        }
        let origins = g.block_origins().unwrap();
        let distinct: HashSet<Coord> = origins.iter().copied().collect();
        assert_eq!(origins.len(), 4096 + 1 + 2, "{name}");
        assert_eq!(distinct.len(), origins.len());
        for o in [
            [0, 0, 0],
            [120, 120, 120],
            [128, 0, 0],
            [-8, 0, 0],
            [200, 0, 0],
        ] {
            assert!(distinct.contains(&o), "{name} {o:?}");
        }
        assert!(!distinct.contains(&[136, 0, 0]));
        check_read_box(g, [120, -3, -2], [30, 14, 12]);
        check_read_box(g, [-9, 0, 0], [20, 9, 9]);
    }
}

#[test]
fn root_tiles_read_but_refuse_to_list_their_blocks() {
    let file = parse("roottile_zip.nvdb");
    let g = &file.grids[0];
    assert_eq!(g.tile_counts().root, 1);
    assert_eq!(g.voxel([5000, 10, 4095]), 9.0);
    assert_eq!(g.voxel([4095, 10, 10]), 0.0);
    assert_eq!(g.voxel([1, 2, 3]), 1.0);
    assert_eq!(g.active_voxel_count(), (1 << 36) + 1);
    let err = g.block_origins().unwrap_err().to_string();
    assert!(
        err.contains("roottile_zip.nvdb") && err.contains("blocks"),
        "{err}"
    );
    // Consumers of the block list fail with that error instead of allocating gigabytes.
    let err = RangeMips::build(g).unwrap_err().to_string();
    assert!(err.contains("roottile_zip.nvdb"), "{err}");
}

/// `read_box` equals one `voxel` call per voxel.
fn check_read_box(g: &NanoGrid, origin: Coord, dims: [u32; 3]) {
    let n = dims.iter().product::<u32>() as usize;
    let mut out = vec![f32::NAN; n];
    g.read_box(origin, dims, &mut out);
    let mut i = 0;
    for z in 0..dims[2] as i64 {
        for y in 0..dims[1] as i64 {
            for x in 0..dims[0] as i64 {
                let c = [
                    origin[0] as i64 + x,
                    origin[1] as i64 + y,
                    origin[2] as i64 + z,
                ];
                let expect = if c.iter().all(|v| *v <= i32::MAX as i64) {
                    g.voxel(c.map(|v| v as i32))
                } else {
                    g.background()
                };
                assert_eq!(out[i].to_bits(), expect.to_bits(), "{} at {c:?}", g.name());
                i += 1;
            }
        }
    }
}

#[test]
fn read_box_matches_voxel_lookups() {
    let mut rng = SplitMix64(3);
    for name in [
        "density_zip.nvdb",
        "density_fp4.nvdb",
        "density_fpn.nvdb",
        "temperature_zip.nvdb",
    ] {
        let file = parse(name);
        let g = &file.grids[0];
        let [lo, hi] = g.index_bbox().unwrap();
        for _ in 0..40 {
            let origin = std::array::from_fn(|a| {
                lo[a] - 10 + rng.below((hi[a] - lo[a] + 12) as usize) as i32
            });
            let dims = std::array::from_fn(|_| 1 + rng.below(13) as u32);
            check_read_box(g, origin, dims);
        }
    }
    let file = parse("density_zip.nvdb");
    check_read_box(&file.grids[0], [i32::MAX - 3, -20, -20], [9, 2, 2]);
    check_read_box(&file.grids[0], [i32::MIN, -20, -20], [3, 2, 2]);
}

/// Where the first grid's metadata starts (after the 16-byte segment header).
const META: usize = 16;

/// Where the first grid's payload starts in a tool-written file.
fn payload_start(bytes: &[u8]) -> usize {
    let name_size = u32::from_le_bytes(bytes[META + 136..META + 140].try_into().unwrap());
    META + 176 + name_size as usize
}

fn put_u32(bytes: &mut [u8], at: usize, v: u32) {
    bytes[at..at + 4].copy_from_slice(&v.to_le_bytes());
}

fn put_u64(bytes: &mut [u8], at: usize, v: u64) {
    bytes[at..at + 8].copy_from_slice(&v.to_le_bytes());
}

fn packed(major: u32, minor: u32, patch: u32) -> u32 {
    major << 21 | minor << 10 | patch
}

#[test]
fn newer_layouts_raw_buffers_and_several_segments_read() {
    let src = density();
    let none = fixture("density_none.nvdb.gz");
    let start = payload_start(&none);
    let same_values = |file: &NanoFile, version: NanoVersion| {
        let g = &file.grids[0];
        assert_eq!(g.version(), version);
        for ijk in src.voxels(2) {
            assert_eq!(g.voxel(ijk), src.get(ijk).unwrap_or(0.0));
        }
    };

    // NanoVDB 32.7+: "NanoVDB2" segment magic, "NanoVDB1" grid magic.
    let mut v327 = none.clone();
    v327[..8].copy_from_slice(b"NanoVDB2");
    put_u32(&mut v327, 8, packed(32, 7, 0));
    v327[start..start + 8].copy_from_slice(b"NanoVDB1");
    put_u32(&mut v327, start + 16, packed(32, 7, 0));
    same_values(
        &parse_nanovdb(&v327, "v327").unwrap(),
        NanoVersion {
            major: 32,
            minor: 7,
            patch: 0,
        },
    );

    // 32.6: "NanoVDB0" everywhere, "NanoVDB1" in the grid header's last word.
    let mut v326 = none.clone();
    put_u32(&mut v326, 8, packed(32, 6, 0));
    put_u32(&mut v326, start + 16, packed(32, 6, 0));
    v326[start + 664..start + 672].copy_from_slice(b"NanoVDB1");
    same_values(
        &parse_nanovdb(&v326, "v326").unwrap(),
        NanoVersion {
            major: 32,
            minor: 6,
            patch: 0,
        },
    );

    // Raw grid buffers (a file that is just grids): as 32.4 kept them in memory, as 32.6
    // and as 32.7 write them; several back to back.
    let temperature = parse("temperature_zip.nvdb");
    let grid_bytes = none[start..].to_vec();
    for (label, raw) in [
        ("raw 32.4", grid_bytes.clone()),
        ("raw 32.6", v326[start..].to_vec()),
        ("raw 32.7", v327[start..].to_vec()),
        (
            "raw pair",
            [&grid_bytes[..], temperature.grids[0].buffer()].concat(),
        ),
    ] {
        let file = parse_nanovdb(&raw, label).unwrap_or_else(|e| panic!("{e}"));
        let g = &file.grids[0];
        assert_eq!(
            (g.name(), g.codec()),
            ("density", NanoCodec::None),
            "{label}"
        );
        assert_eq!(g.voxel([-27, -16, -10]), src.get([-27, -16, -10]).unwrap());
        if label == "raw pair" {
            assert_eq!(file.grids[1].name(), "temperature");
            assert_eq!(
                file.grids[1].voxel_f64([6, 7, 8]),
                temperature.grids[0].voxel_f64([6, 7, 8])
            );
        }
    }

    // Several segments, as NanoVDB 32.6+ writes several grids (and as files concatenate).
    let joined = [
        fixture("density_zip.nvdb"),
        fixture("temperature_zip.nvdb"),
        fixture("density_blosc.nvdb"),
    ]
    .concat();
    let file = parse_nanovdb(&joined, "joined").unwrap();
    let names: Vec<&str> = file.grids.iter().map(|g| g.name()).collect();
    assert_eq!(names, ["density", "temperature", "density"]);
    assert_eq!(file.grids[2].codec(), NanoCodec::Blosc);
    assert_eq!(file.grids[1].number(), 1);
}

fn error_of(bytes: &[u8]) -> String {
    match parse_nanovdb(bytes, "bad.nvdb") {
        Ok(f) => panic!("expected an error, read {} grids", f.grids.len()),
        Err(e) => {
            let text = e.to_string();
            assert!(text.starts_with("bad.nvdb: "), "{text}");
            assert_eq!(e.file(), "bad.nvdb");
            text
        }
    }
}

#[test]
fn unsupported_versions_and_foreign_files_are_refused() {
    let zip = fixture("density_zip.nvdb");
    let mut newer = zip.clone();
    put_u32(&mut newer, 8, packed(33, 0, 0));
    assert!(error_of(&newer).contains("version 33.0.0 is not supported"));
    let mut older = zip.clone();
    put_u32(&mut older, 8, packed(32, 2, 1));
    assert!(error_of(&older).contains("version 32.2.1 is not supported"));
    // A grid whose own header carries an unsupported version.
    let none = fixture("density_none.nvdb.gz");
    let mut grid_version = none.clone();
    put_u32(
        &mut grid_version,
        payload_start(&none) + 16,
        packed(31, 0, 0),
    );
    let e = error_of(&grid_version);
    assert!(
        e.contains("grid 0 'density'") && e.contains("31.0.0"),
        "{e}"
    );

    let mut magic = zip.clone();
    magic[..8].copy_from_slice(b"NotNano!");
    assert!(error_of(&magic).contains("not a NanoVDB file"));
    let mut openvdb = zip.clone();
    openvdb[..8].copy_from_slice(&[0x20, 0x42, 0x44, 0x56, 0, 0, 0, 0]);
    assert!(error_of(&openvdb).contains("OpenVDB"));
    let mut swapped = zip.clone();
    swapped[..8].reverse();
    assert!(error_of(&swapped).contains("big-endian"));
    let mut codec = zip.clone();
    codec[14] = 7;
    assert!(error_of(&codec).contains("unknown codec 7"));
    assert!(error_of(&[]).contains("too few"));
    let missing = read_nanovdb(&data_dir().join("missing.nvdb")).unwrap_err();
    assert!(missing.to_string().contains("missing.nvdb"));
}

/// The first lower node of a Float grid buffer and the slot of its first leaf.
fn first_lower_node(buf: &[u8]) -> (usize, usize) {
    let u64_at = |at: usize| u64::from_le_bytes(buf[at..at + 8].try_into().unwrap());
    let first_child = |node: usize, child_mask: usize, words: usize| {
        let w = (0..words)
            .find(|w| u64_at(node + child_mask + 8 * w) != 0)
            .unwrap();
        w * 64 + u64_at(node + child_mask + 8 * w).trailing_zeros() as usize
    };
    let root = 672 + u64_at(672 + 24) as usize;
    let tile = root + 64; // a Float root is 64 bytes, then come the tiles
    let upper = (root as i64 + u64_at(tile + 8) as i64) as usize;
    let n = first_child(upper, 32 + 4096, 512);
    let lower = (upper as i64 + u64_at(upper + 8256 + 8 * n) as i64) as usize;
    (lower, first_child(lower, 32 + 512, 64))
}

#[test]
fn wrong_counts_sizes_and_offsets_are_errors() {
    let none = fixture("density_none.nvdb.gz");
    let start = payload_start(&none);
    let patched = |at: usize, v: u64, width: usize| {
        let mut b = none.clone();
        b[at..at + width].copy_from_slice(&v.to_le_bytes()[..width]);
        b
    };
    let cases: Vec<(Vec<u8>, &str)> = vec![
        (patched(12, 1000, 2), "beyond the file"),
        (patched(12, 0, 2), "holds no grids"),
        (patched(META, 1 << 40, 8), "exceeds"),
        (patched(META, 1 << 20, 8), "uncompressed grid"),
        (patched(META + 8, u64::MAX, 8), "beyond the file"),
        (patched(META + 136, 1 << 31, 4), "name of"),
        (patched(start + 32, 1 << 20, 8), "grid header states"),
        (patched(start + 672 + 24, 1 << 40, 8), "root offset"),
        (patched(start + 672 + 24, 40, 8), "not 32-byte aligned"),
        (
            patched(start + 672 + 32, 23, 4),
            "states 23 leaf nodes, the tree holds 22",
        ),
        (patched(start + 672 + 40, 2, 4), "states 2 upper nodes"),
        (patched(start + 672 + 56, 3024, 8), "3024 active voxels"),
        (patched(start + 672 + 64 + 24, 1 << 30, 4), "root table"),
    ];
    for (bytes, expect) in cases {
        let e = error_of(&bytes);
        assert!(e.contains(expect), "expected {expect:?} in {e}");
    }
    let (lower, slot) = first_lower_node(&none[start..]);
    let (lower, entry) = (start + lower, start + lower + 1088 + 8 * slot);
    let e = error_of(&patched(entry, 123_456_789, 8));
    assert!(
        e.contains("grid 0 'density': lower node 0 child") && e.contains("beyond the grid buffer"),
        "{e}"
    );
    let e = error_of(&patched(entry, 8, 8));
    assert!(e.contains("not 32-byte aligned"), "{e}");
    let e = error_of(&patched(entry, (-1i64 << 40) as u64, 8));
    assert!(e.contains("before the grid buffer"), "{e}");
    // Two children pointing at one leaf: make the next slot a child with the same offset.
    let mut twice = none.clone();
    let next = slot + 1;
    let word_at = lower + 32 + 512 + 8 * (next / 64);
    let mut word = u64::from_le_bytes(twice[word_at..word_at + 8].try_into().unwrap());
    word |= 1 << (next % 64);
    twice[word_at..word_at + 8].copy_from_slice(&word.to_le_bytes());
    let delta = none[entry..entry + 8].to_vec();
    twice[entry + 8..entry + 16].copy_from_slice(&delta);
    let e = error_of(&twice);
    assert!(e.contains("a second time"), "{e}");
    // A payload claiming a giant grid is refused without allocating it.
    let mut zip = fixture("density_zip.nvdb");
    put_u64(&mut zip, META, 1 << 35);
    assert!(error_of(&zip).contains("cannot hold"));
}

/// Where each segment of a tool-written file ends (one grid per segment).
fn segment_ends(bytes: &[u8]) -> Vec<usize> {
    let mut ends = Vec::new();
    let mut pos = 0;
    while pos < bytes.len() {
        assert_eq!(u16::from_le_bytes([bytes[pos + 12], bytes[pos + 13]]), 1);
        let meta = pos + 16;
        let file_size = u64::from_le_bytes(bytes[meta + 8..meta + 16].try_into().unwrap());
        let name_size = u32::from_le_bytes(bytes[meta + 136..meta + 140].try_into().unwrap());
        pos = meta + 176 + name_size as usize + file_size as usize;
        ends.push(pos);
    }
    ends
}

/// Exercises every lookup of a parsed (possibly corrupt) file: none may panic.
fn exercise(file: &NanoFile) {
    for g in &file.grids {
        let _ = (
            g.name(),
            g.index_bbox(),
            g.world_bbox(),
            g.check_sampleable(),
        );
        for ijk in [
            [-27, -16, -10],
            [0, 0, 0],
            [6, 7, 8],
            [200, 1, 1],
            [-1, -1, -1],
        ] {
            let _ = g.voxel(ijk);
            let _ = g.voxel_f64(ijk);
        }
        if g.block_origins().is_ok_and(|o| o.len() < 20_000) {
            let mut out = vec![0.0; 9 * 9 * 9];
            for o in g.block_origins().unwrap().into_iter().take(3) {
                g.read_box(o.map(|c| c - 1), [9, 9, 9], &mut out);
            }
        }
    }
}

#[test]
fn every_truncation_is_an_error_not_a_panic() {
    for name in ["density_zip.nvdb", "multi_zip.nvdb", "tiles_fp8.nvdb"] {
        let bytes = fixture(name);
        let ends = segment_ends(&bytes);
        assert_eq!(ends.len(), parse(name).grids.len());
        // Every cut in the headers, around segment ends and near the end, a stride elsewhere.
        let mut cuts: Vec<usize> = (0..400).chain((400..bytes.len()).step_by(11)).collect();
        cuts.extend(bytes.len() - 64..bytes.len());
        for end in &ends {
            cuts.extend(end - 300..end + 300);
        }
        cuts.retain(|c| *c < bytes.len());
        // nanovdb_convert 32.4 writes one segment per grid: a cut between two segments
        // leaves a valid file of fewer grids, every other cut is an error.
        for len in cuts {
            match parse_nanovdb(&bytes[..len], name) {
                Ok(file) => assert!(
                    ends.iter().position(|e| *e == len) == Some(file.grids.len() - 1),
                    "{name} cut at {len}"
                ),
                Err(e) => assert!(e.to_string().starts_with(name)),
            }
        }
    }
    // The uncompressed file: every section boundary and a stride through the rest.
    let none = fixture("density_none.nvdb.gz");
    let start = payload_start(&none);
    let mut cuts: Vec<usize> = (0..start + 1024).collect();
    cuts.extend((start..none.len()).step_by(997));
    cuts.extend([none.len() - 1, none.len() - 2048]);
    for len in cuts {
        assert!(parse_nanovdb(&none[..len], "none").is_err(), "cut at {len}");
    }
    let blosc = fixture("density_blosc.nvdb");
    for len in (0..blosc.len()).step_by(7) {
        assert!(
            parse_nanovdb(&blosc[..len], "blosc").is_err(),
            "cut at {len}"
        );
    }
}

#[test]
fn flipped_bytes_never_panic() {
    let none = fixture("density_none.nvdb.gz");
    let start = payload_start(&none);
    // Every byte of the headers, the root and the start of the first nodes, then a stride.
    let positions = (0..start + 1024).chain((start + 1024..none.len()).step_by(331));
    let mut rejected = 0;
    for pos in positions {
        for flip in [0x01u8, 0x80] {
            let mut bad = none.clone();
            bad[pos] ^= flip;
            match parse_nanovdb(&bad, "flipped") {
                Ok(file) => exercise(&file),
                Err(_) => rejected += 1,
            }
        }
    }
    assert!(rejected > 500, "{rejected}");
    for name in [
        "density_zip.nvdb",
        "density_blosc.nvdb",
        "density_fpn.nvdb",
        "tiles_zip.nvdb",
    ] {
        let bytes = fixture(name);
        for pos in (0..bytes.len()).step_by(29) {
            let mut bad = bytes.clone();
            bad[pos] ^= 0x24;
            if let Ok(file) = parse_nanovdb(&bad, name) {
                exercise(&file);
            }
        }
    }
}

#[test]
fn fuzzed_files_never_panic() {
    let none = fixture("density_none.nvdb.gz");
    let start = payload_start(&none);
    let grid = none[start..].to_vec();
    let sources = [
        none,
        grid,
        fixture("tiles_fp8.nvdb"),
        fixture("density_fpn.nvdb"),
        fixture("multi_zip.nvdb"),
        fixture("density_blosc.nvdb"),
    ];
    let mut rng = SplitMix64(0x5eed);
    let mut outcomes = [0usize; 2];
    let cases = hytrace_testkit::fuzz_cases(3000);
    for _ in 0..cases {
        let src = &sources[rng.below(sources.len())];
        let mut bytes = src.clone();
        for _ in 0..1 + rng.below(8) {
            // Mostly the first few KiB (headers, root, node masks), sometimes anywhere.
            let span = if rng.below(4) == 0 {
                bytes.len()
            } else {
                bytes.len().min(12_000)
            };
            let pos = rng.below(span);
            match rng.below(4) {
                0 => bytes[pos] = rng.next_u64() as u8,
                1 => bytes[pos] ^= 1 << rng.below(8),
                2 => {
                    // An 8-byte word set to a boundary value.
                    let v = [0u64, 1, u64::MAX, 1 << 31, 1 << 40, i64::MIN as u64][rng.below(6)];
                    let end = (pos + 8).min(bytes.len());
                    bytes[pos..end].copy_from_slice(&v.to_le_bytes()[..end - pos]);
                }
                _ => bytes.truncate(pos),
            }
            if bytes.is_empty() {
                break;
            }
        }
        match parse_nanovdb(&bytes, "fuzz") {
            Ok(file) => {
                exercise(&file);
                outcomes[0] += 1;
            }
            Err(e) => {
                assert!(e.to_string().starts_with("fuzz: "));
                outcomes[1] += 1;
            }
        }
    }
    assert!(
        outcomes[0] > cases / 60 && outcomes[1] > cases / 60,
        "{outcomes:?}"
    );
}
