//! The OpenVDB reader against files written by OpenVDB 10.0.1 (pyopenvdb, vdb_tool and a
//! C++ program; tests/data/openvdb/README.md says how) and their dense NumPy sources.

use std::collections::HashSet;
use std::path::{Path, PathBuf};

use hytrace_testkit::{Random, XorShift64};
use hytrace_volume::{read_vdb, Coord, VdbFile, VdbGrid, VoxelGrid, BLOCK_SIDE};
use serde_json::Value;

fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../tests/data/openvdb")
        .join(name)
}

fn fixtures() -> Value {
    let text = std::fs::read_to_string(data("fixtures.json")).unwrap();
    serde_json::from_str(&text).unwrap()
}

fn coord(v: &Value) -> Coord {
    std::array::from_fn(|k| v[k].as_i64().unwrap() as i32)
}

fn vec3(v: &Value) -> [f64; 3] {
    std::array::from_fn(|k| v[k].as_f64().unwrap())
}

/// A dense source array (axis 0 is x) as f64 values with its shape.
fn npy(name: &str) -> (Vec<f64>, [usize; 3]) {
    let bytes = std::fs::read(data(name)).unwrap();
    let file = npyz::NpyFile::new(&bytes[..]).unwrap();
    let shape: Vec<usize> = file.shape().iter().map(|&n| n as usize).collect();
    let values = match file.dtype().descr().as_str() {
        "'<f4'" => file
            .into_vec::<f32>()
            .unwrap()
            .into_iter()
            .map(f64::from)
            .collect(),
        "'<f8'" => file.into_vec::<f64>().unwrap(),
        other => panic!("unexpected dtype {other}"),
    };
    (values, [shape[0], shape[1], shape[2]])
}

fn load(file: &str, name: &str) -> VdbGrid {
    let f = VdbFile::open(&data(file)).unwrap();
    let i = f.grids.iter().position(|g| g.name == name).unwrap();
    f.load(i).unwrap()
}

/// Checks every voxel of a box `margin` voxels wider than the source: inside, the source
/// value converted by `expect`; outside, the background.
fn check_against_source(g: &VdbGrid, source: &str, origin: Coord, expect: impl Fn(f64) -> f32) {
    let (values, shape) = npy(source);
    let bg = g.background();
    let margin = 3i32;
    for x in -margin..shape[0] as i32 + margin {
        for y in -margin..shape[1] as i32 + margin {
            for z in -margin..shape[2] as i32 + margin {
                let local = [x, y, z];
                let inside = (0..3).all(|k| local[k] >= 0 && (local[k] as usize) < shape[k]);
                let want = if inside {
                    let [x, y, z] = local.map(|c| c as usize);
                    expect(values[(x * shape[1] + y) * shape[2] + z])
                } else {
                    bg
                };
                let ijk = std::array::from_fn(|k| origin[k] + local[k]);
                assert_eq!(g.voxel(ijk), want, "{} voxel {ijk:?}", g.info.name);
            }
        }
    }
}

fn check_density(g: &VdbGrid, expect: impl Fn(f64) -> f32) {
    let fx = &fixtures()["density"];
    assert_eq!(g.background(), 0.25);
    check_against_source(g, "density.npy", coord(&fx["origin"]), expect);
    // Voxels given inactive values other than the background read as the background.
    for v in fx["inactive"].as_array().unwrap() {
        assert_eq!(g.voxel(coord(&v["ijk"])), 0.25);
    }
    // The filled 128^3 region is one tile of a 32^3 node.
    let (lo, hi) = (coord(&fx["fill"]["min"]), coord(&fx["fill"]["max"]));
    let value = fx["fill"]["value"].as_f64().unwrap() as f32;
    for p in [lo, hi, [lo[0] + 70, hi[1] - 3, lo[2] + 9]] {
        assert_eq!(g.voxel(p), value, "{p:?}");
    }
    assert_eq!(g.voxel([lo[0] - 1, lo[1], lo[2]]), 0.25);
    assert_eq!(g.voxel([hi[0], hi[1] + 1, hi[2]]), 0.25);
}

#[test]
fn blosc_zip_and_raw_files_match_the_numpy_source_exactly() {
    for file in ["grids.vdb", "density_zip.vdb", "density_active.vdb"] {
        let g = load(file, "density");
        check_density(&g, |v| v as f32);
    }
    let fx = &fixtures()["temperature"];
    let t = load("grids.vdb", "temperature");
    assert_eq!(t.background(), 0.0);
    check_against_source(&t, "temperature.npy", coord(&fx["origin"]), |v| v as f32);
}

#[test]
fn half_float_files_match_the_source_rounded_to_half() {
    let g = load("density_half.vdb", "density");
    assert!(g.info.saved_as_half);
    check_density(&g, |v| half::f16::from_f64(v).to_f32());
}

#[test]
fn double_grids_match_the_source_rounded_to_f32() {
    let fx = &fixtures()["double_density"];
    let g = load("double.vdb", "double_density");
    assert_eq!(g.info.value_type, "double");
    assert_eq!(g.background(), -1.5);
    check_against_source(&g, "double.npy", coord(&fx["origin"]), |v| v as f32);
    let s = fx["voxel_size"].as_f64().unwrap();
    let w = g.map().index_to_world([1.0, -2.0, 3.0]);
    assert_eq!(w, [s, -2.0 * s, 3.0 * s]);
}

#[test]
fn transforms_match_the_matrices_used_in_python() {
    let fx = fixtures();
    for name in ["density", "temperature", "density_instance"] {
        let g = load("grids.vdb", name);
        let points = &fx[name]["points"];
        let index = points["index"].as_array().unwrap();
        let world = points["world"].as_array().unwrap();
        for (i, w) in index.iter().zip(world) {
            let got = g.map().index_to_world(vec3(i));
            let want = vec3(w);
            for k in 0..3 {
                assert!(
                    (got[k] - want[k]).abs() < 1e-12 * (1.0 + want[k].abs()),
                    "{name}: {got:?} vs {want:?}"
                );
            }
            let back = g.map().world_to_index(got);
            for k in 0..3 {
                assert!((back[k] - vec3(i)[k]).abs() < 1e-9, "{name}: {back:?}");
            }
        }
    }
    let d = load("grids.vdb", "density");
    let linear = &fx["density"]["linear"];
    for r in 0..3 {
        for c in 0..3 {
            assert!((d.map().matrix[r][c] - linear[r][c].as_f64().unwrap()).abs() < 1e-15);
        }
    }
    assert_eq!(d.map().translation, vec3(&fx["density"]["translation"]));
}

#[test]
fn grids_are_listed_with_type_transform_bbox_and_count() {
    let f = VdbFile::open(&data("grids.vdb")).unwrap();
    let names: Vec<&str> = f.grids.iter().map(|g| g.name.as_str()).collect();
    assert_eq!(
        names,
        ["density", "temperature", "density_instance", "velocity"]
    );
    let types: Vec<&str> = f.grids.iter().map(|g| g.value_type.as_str()).collect();
    assert_eq!(types, ["float", "float", "float", "vec3s"]);
    let maps: Vec<&str> = f.grids.iter().map(|g| g.transform.as_str()).collect();
    assert_eq!(
        maps,
        [
            "AffineMap",
            "UniformScaleTranslateMap",
            "ScaleTranslateMap",
            "UniformScaleMap"
        ]
    );
    let density = &f.grids[0];
    assert_eq!(density.tree_type, "Tree_float_5_4_3");
    assert_eq!(density.compression, "blosc + active mask");
    assert!(!density.saved_as_half);
    assert_eq!(density.bbox, Some([[-256, -256, -256], [-104, -17, -25]]));
    let (values, _) = npy("density.npy");
    let fill = 128u64.pow(3);
    let sparse = values.iter().filter(|v| **v != 0.25).count() as u64;
    assert_eq!(density.active_voxel_count, Some(sparse + fill));
    assert_eq!(density.instance_of, None);
    assert_eq!(f.grids[2].instance_of.as_deref(), Some("density"));
    let (temp, _) = npy("temperature.npy");
    let temperature = &f.grids[1];
    assert_eq!(temperature.bbox, Some([[3, -40, 7], [12, -32, 18]]));
    let nonzero = temp.iter().filter(|v| **v != 0.0).count() as u64;
    assert_eq!(temperature.active_voxel_count, Some(nonzero));
    assert_eq!(
        VdbFile::open(&data("density_zip.vdb")).unwrap().grids[0].compression,
        "zip + active mask"
    );
    assert_eq!(
        VdbFile::open(&data("density_active.vdb")).unwrap().grids[0].compression,
        "none + active mask"
    );
}

#[test]
fn instances_share_the_tree_under_their_own_transform() {
    let d = load("grids.vdb", "density");
    let i = load("grids.vdb", "density_instance");
    assert_ne!(d.map(), i.map());
    let (origin, dims) = ([-260, -60, -60], [170u32, 50, 40]);
    let n = dims.iter().product::<u32>() as usize;
    let (mut a, mut b) = (vec![0.0; n], vec![0.0; n]);
    d.read_box(origin, dims, &mut a);
    i.read_box(origin, dims, &mut b);
    assert_eq!(a, b);
}

#[test]
fn read_vdb_loads_the_scalar_grids_and_skips_the_others() {
    let grids = read_vdb(&data("grids.vdb")).unwrap();
    let names: Vec<&str> = grids.iter().map(|g| g.info.name.as_str()).collect();
    assert_eq!(names, ["density", "temperature", "density_instance"]);
    let f = VdbFile::open(&data("grids.vdb")).unwrap();
    let err = f.load(3).err().unwrap().to_string();
    assert!(
        err.contains("grids.vdb") && err.contains("'velocity'") && err.contains("vec3s"),
        "{err}"
    );
    assert!(f.load(4).is_err());
}

#[test]
fn block_origins_cover_every_value_other_than_the_background_once() {
    let g = load("grids.vdb", "density");
    let origins = g.block_origins().unwrap();
    let set: HashSet<Coord> = origins.iter().copied().collect();
    assert_eq!(set.len(), origins.len(), "duplicates");
    let bg = g.background();
    let mut block = vec![0.0; 512];
    for o in &origins {
        assert!(o.iter().all(|c| c % BLOCK_SIDE == 0), "{o:?}");
        g.read_box(*o, [8, 8, 8], &mut block);
        assert!(
            block.iter().any(|v| *v != bg),
            "block {o:?} is all background"
        );
    }
    // 16^3 blocks of the 128^3 tile, the two 8^3 tiles, and the leaves.
    assert!(origins.len() > 4096 + 2);
    let fx = &fixtures()["density"];
    let (values, shape) = npy("density.npy");
    let origin = coord(&fx["origin"]);
    for x in 0..shape[0] {
        for y in 0..shape[1] {
            for z in 0..shape[2] {
                if values[(x * shape[1] + y) * shape[2] + z] != 0.25 {
                    let ijk = [x, y, z].map(|c| c as i32);
                    let b = std::array::from_fn(|k| (origin[k] + ijk[k]) & !(BLOCK_SIDE - 1));
                    assert!(set.contains(&b), "{b:?}");
                }
            }
        }
    }
    let lo = coord(&fx["fill"]["min"]);
    assert!(set.contains(&lo) && set.contains(&[lo[0] + 120, lo[1] + 64, lo[2] + 8]));
}

#[test]
fn read_box_matches_voxel_lookups() {
    let g = load("grids.vdb", "density");
    let mut rng = XorShift64(0x2545_f491_4f6c_dd1d);
    let mut next = |n: u64| rng.next_u64() % n;
    let mut boxes: Vec<(Coord, [u32; 3])> = (0..200)
        .map(|_| {
            let o = [0; 3].map(|_| next(300) as i32 - 270);
            let d = [0; 3].map(|_| 1 + next(40) as u32);
            (o, d)
        })
        .collect();
    boxes.push(([i32::MAX - 3, -5, 0], [9, 2, 3]));
    boxes.push(([i32::MIN, -5, 0], [9, 2, 0]));
    for (o, d) in boxes {
        let n = d.iter().map(|&v| v as usize).product();
        let mut out = vec![f32::NAN; n];
        g.read_box(o, d, &mut out);
        let mut i = 0;
        for z in 0..d[2] as i64 {
            for y in 0..d[1] as i64 {
                for x in 0..d[0] as i64 {
                    let p = [x, y, z];
                    let c: [i64; 3] = std::array::from_fn(|k| o[k] as i64 + p[k]);
                    let want = match c.map(i32::try_from) {
                        [Ok(a), Ok(b), Ok(c)] => g.voxel([a, b, c]),
                        _ => g.background(),
                    };
                    assert_eq!(out[i], want, "box {o:?} {d:?} at {c:?}");
                    i += 1;
                }
            }
        }
    }
}

#[test]
fn root_tiles_read_as_their_value_and_too_many_blocks_are_refused() {
    let f = VdbFile::open(&data("root_tiles.vdb")).unwrap();
    let g = f.load(0).unwrap();
    let fx = &fixtures()["one_root_tile"];
    let (lo, hi) = (coord(&fx["min"]), coord(&fx["max"]));
    for p in [lo, hi, [lo[0] + 100, lo[1] + 4000, hi[2] - 2]] {
        assert_eq!(g.voxel(p), 0.5, "{p:?}");
    }
    assert_eq!(g.voxel([hi[0] + 1, lo[1], lo[2]]), 0.0);
    assert_eq!(g.voxel([lo[0], lo[1] - 1, lo[2]]), 0.0);
    let mut out = vec![0.0; 8];
    g.read_box(hi, [2, 2, 2], &mut out);
    assert_eq!(out, [0.5, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
    let err = f.load(1).err().unwrap().to_string();
    assert!(
        err.contains("'two_root_tiles'") && err.contains("blocks"),
        "{err}"
    );
}

#[test]
fn frustum_transforms_are_listed_but_refused() {
    let f = VdbFile::open(&data("frustum.vdb")).unwrap();
    assert_eq!(f.grids[0].transform, "NonlinearFrustumMap");
    let err = f.load(0).err().unwrap().to_string();
    assert!(
        err.contains("frustum.vdb") && err.contains("frustum"),
        "{err}"
    );
    assert!(read_vdb(&data("frustum.vdb")).is_err());
}

#[test]
fn missing_and_foreign_files_give_errors_naming_them() {
    let missing = data("no_such_file.vdb");
    let err = VdbFile::open(&missing).err().unwrap().to_string();
    assert!(err.contains("no_such_file.vdb"), "{err}");
    let err = VdbFile::open(&data("density.npy"))
        .err()
        .unwrap()
        .to_string();
    assert!(
        err.contains("density.npy") && err.contains("not an OpenVDB file"),
        "{err}"
    );
    let err = VdbFile::from_bytes(Path::new("empty.vdb"), Vec::new())
        .err()
        .unwrap();
    assert!(err.to_string().contains("empty.vdb"), "{err}");
}

/// Opens `bytes` and loads and samples every grid; a panic fails the test.
fn exercise(name: &str, bytes: Vec<u8>) -> Result<(), String> {
    let f = VdbFile::from_bytes(Path::new(name), bytes).map_err(|e| e.to_string())?;
    for i in 0..f.grids.len() {
        if let Ok(g) = f.load(i) {
            let mut out = vec![0.0; 64];
            g.read_box([-140, -45, -50], [4, 4, 4], &mut out);
            g.voxel([-130, -20, -30]);
        }
    }
    Ok(())
}

#[test]
fn truncated_files_error_at_every_length() {
    for file in [
        "grids.vdb",
        "density_zip.vdb",
        "density_half.vdb",
        "double.vdb",
    ] {
        let bytes = std::fs::read(data(file)).unwrap();
        let lengths = (0..bytes.len().min(3000)).chain((3000..bytes.len()).step_by(61));
        for len in lengths {
            let err = exercise(file, bytes[..len].to_vec()).err();
            let err = err.unwrap_or_else(|| panic!("{file} cut to {len} bytes opened"));
            assert!(err.contains(file), "{err}");
        }
    }
}

#[test]
fn corrupt_bytes_never_panic() {
    let mut state = 0x9e37_79b9_7f4a_7c15_u64;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state
    };
    for file in [
        "grids.vdb",
        "density_zip.vdb",
        "density_half.vdb",
        "double.vdb",
    ] {
        let bytes = std::fs::read(data(file)).unwrap();
        for _ in 0..hytrace_testkit::fuzz_cases(1600) / 4 {
            let mut b = bytes.clone();
            for _ in 0..1 + next() % 4 {
                let at = (next() % b.len() as u64) as usize;
                b[at] ^= 1 + (next() % 255) as u8;
            }
            if let Err(e) = exercise(file, b) {
                assert!(e.contains(file), "{e}");
            }
        }
    }
}

#[test]
fn absurd_counts_and_sizes_give_errors() {
    let bytes = std::fs::read(data("double.vdb")).unwrap();
    // Every aligned 4- and 8-byte field set to huge values, one at a time.
    for at in (0..bytes.len().min(4096)).step_by(4) {
        for huge in [u32::MAX as u64, i64::MAX as u64, 1 << 40] {
            let mut b = bytes.clone();
            let n = if huge > u32::MAX as u64 { 8 } else { 4 };
            let end = (at + n).min(b.len());
            b[at..end].copy_from_slice(&huge.to_le_bytes()[..end - at]);
            if let Err(e) = exercise("double.vdb", b) {
                assert!(e.contains("double.vdb"), "{e}");
            }
        }
    }
}
