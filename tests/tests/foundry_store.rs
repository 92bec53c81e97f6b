//! Foundry persistence: round trips through Rust and NumPy, and corrupt stores that must give
//! a clear error naming the file, the record and the field (never a panic).

use std::path::{Path, PathBuf};

use hytrace_foundry::layout::Record;
use hytrace_foundry::{file_names, Foundry, Node, Prim, Transform64};
use hytrace_testkit::{Random, SplitMix64};
use hytrace_tests::{oracle_python, run_python};
use hytrace_trace::scene::default_scene;

fn saved_default() -> (tempfile::TempDir, PathBuf, Foundry) {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("store");
    let f = default_scene().unwrap();
    f.save(&dir).unwrap();
    (tmp, dir, f)
}

/// Overwrites the 4-byte field `field` of record `index` in `dir/<file>` (data at the end).
fn patch_u32<R: Record>(
    dir: &Path,
    file: &str,
    count: usize,
    index: usize,
    field: &str,
    value: u32,
) {
    let path = dir.join(file);
    let mut bytes = std::fs::read(&path).unwrap();
    let data_start = bytes.len() - count * size_of::<R>();
    let offset = R::fields().iter().find(|f| f.name == field).unwrap().offset;
    let at = data_start + index * size_of::<R>() + offset;
    bytes[at..at + 4].copy_from_slice(&value.to_le_bytes());
    std::fs::write(&path, bytes).unwrap();
}

/// The data section of an .npy file, located from the header length field of the format
/// specification (version 1: u16 at byte 8; versions 2 and 3: u32 at byte 8).
fn npy_data(bytes: &[u8]) -> &[u8] {
    assert_eq!(&bytes[..6], b"\x93NUMPY");
    let start = match bytes[6] {
        1 => 10 + u16::from_le_bytes([bytes[8], bytes[9]]) as usize,
        _ => 12 + u32::from_le_bytes(bytes[8..12].try_into().unwrap()) as usize,
    };
    &bytes[start..]
}

fn load_error(dir: &Path) -> String {
    Foundry::load(dir)
        .expect_err("corrupt store must not load")
        .to_string()
}

#[test]
fn save_load_round_trip_is_exact() {
    let (_tmp, dir, f) = saved_default();
    let back = Foundry::load(&dir).unwrap();
    assert_eq!(back, f);
    let names: Vec<String> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    for name in file_names() {
        assert!(names.contains(&name), "{name} missing");
    }
    assert_eq!(
        names.len(),
        file_names().len(),
        "no temporary files left behind: {names:?}"
    );
    // Saving over an existing store replaces it whole.
    let dir2 = dir.clone();
    back.save(&dir2).unwrap();
    assert_eq!(Foundry::load(&dir2).unwrap(), f);
}

#[test]
fn numpy_reads_and_rewrites_identical_bytes() {
    let Some(python) = oracle_python(&["numpy"]) else {
        return;
    };
    let (tmp, dir, f) = saved_default();
    let copy = tmp.path().join("numpy_copy");
    let script = r#"
import json, sys, pathlib, shutil
import numpy as np
src, dst = pathlib.Path(sys.argv[1]), pathlib.Path(sys.argv[2])
dst.mkdir()
shutil.copy(src / "meta.json", dst / "meta.json")
shutil.copy(src / "optics.json", dst / "optics.json")
out = {}
for p in sorted(src.glob("*.npy")):
    a = np.load(p, allow_pickle=False)
    np.save(dst / p.name, a)
    out[p.stem] = {"shape": list(a.shape), "fields": list(a.dtype.names or [])}
node = np.load(src / "node.npy")
prim = np.load(src / "prim.npy")
inst = np.load(src / "inst.npy")
tran = np.load(src / "tran.npy")
itra = np.load(src / "itra.npy")
out["typecodes"] = node["typecode"].tolist()
out["root_aabb"] = [node["aabb"][p["node_offset"]].tolist() for p in prim]
out["pmt_copies"] = sorted(int(c) for c in inst["copy_number"][inst["solid"] == 3])
# itra is the inverse of tran: an independent check in float64.
out["inverse_error"] = float(np.abs(np.einsum("nij,njk->nik", tran, itra.astype(np.float64)) - np.eye(4)).max()) if len(tran) else 0.0
print(json.dumps(out))
"#;
    let text = run_python(
        &python,
        script,
        &[dir.to_str().unwrap(), copy.to_str().unwrap()],
    );
    // Each array's shape and structured fields as NumPy sees them.
    let field_names = |fields: &[hytrace_foundry::layout::Field]| {
        fields
            .iter()
            .map(|f| format!("\"{}\"", f.name))
            .collect::<Vec<_>>()
            .join(", ")
    };
    assert!(
        text.contains(&format!(
            "\"node\": {{\"shape\": [{}], \"fields\": [{}]}}",
            f.node.len(),
            field_names(Node::fields())
        )),
        "{text}"
    );
    assert!(
        text.contains(&format!(
            "\"prim\": {{\"shape\": [{}], \"fields\": [{}]}}",
            f.prim.len(),
            field_names(Prim::fields())
        )),
        "{text}"
    );
    assert!(
        text.contains(&format!(
            "\"tran\": {{\"shape\": [{}, 4, 4], \"fields\": []}}",
            f.tran.len()
        )),
        "{text}"
    );
    let typecodes: Vec<String> = f.node.iter().map(|n| n.typecode.to_string()).collect();
    assert!(
        text.contains(&format!("\"typecodes\": [{}]", typecodes.join(", "))),
        "{text}"
    );
    let copies: Vec<String> = (0..48).map(|i| i.to_string()).collect();
    assert!(
        text.contains(&format!("\"pmt_copies\": [{}]", copies.join(", "))),
        "{text}"
    );
    let err: f64 = text
        .split("\"inverse_error\": ")
        .nth(1)
        .unwrap()
        .trim_end_matches(['}', '\n'])
        .parse()
        .unwrap();
    assert!(err < 1e-5, "itra is not the inverse of tran: {err}");
    // NumPy's rewrite loads back in Rust with identical records.
    let back = Foundry::load(&copy).unwrap();
    assert_eq!(back, f);
    for name in file_names().iter().filter(|n| n.ends_with(".npy")) {
        let (a, b) = (
            std::fs::read(dir.join(name)).unwrap(),
            std::fs::read(copy.join(name)).unwrap(),
        );
        // Headers may differ in padding; the data sections must be identical.
        assert_eq!(npy_data(&a), npy_data(&b), "{name}: data bytes differ");
    }
}

#[test]
fn truncated_file_is_named() {
    let (_tmp, dir, _) = saved_default();
    let path = dir.join("node.npy");
    let bytes = std::fs::read(&path).unwrap();
    std::fs::write(&path, &bytes[..bytes.len() - 10]).unwrap();
    let e = load_error(&dir);
    assert!(e.contains("node.npy") && e.contains("truncated"), "{e}");
    std::fs::write(&path, &bytes[..40]).unwrap();
    let e = load_error(&dir);
    assert!(e.contains("node.npy"), "{e}");
}

#[test]
fn bad_offset_names_record_and_field() {
    let (_tmp, dir, f) = saved_default();
    patch_u32::<Prim>(&dir, "prim.npy", f.prim.len(), 2, "node_offset", 1_000_000);
    let e = load_error(&dir);
    assert!(
        e.contains("prim.npy") && e.contains("record 2") && e.contains("node_offset"),
        "{e}"
    );
}

#[test]
fn bad_typecode_names_record_and_field() {
    let (_tmp, dir, f) = saved_default();
    patch_u32::<Node>(&dir, "node.npy", f.node.len(), 3, "typecode", 999);
    let e = load_error(&dir);
    assert!(
        e.contains("node.npy")
            && e.contains("record 3")
            && e.contains("typecode")
            && e.contains("999"),
        "{e}"
    );
}

#[test]
fn bad_transform_index_and_broken_tree_are_caught() {
    let (_tmp, dir, f) = saved_default();
    patch_u32::<Node>(&dir, "node.npy", f.node.len(), 0, "transform", 77);
    let e = load_error(&dir);
    assert!(
        e.contains("node.npy") && e.contains("record 0") && e.contains("transform"),
        "{e}"
    );
    let (_tmp, dir, f) = saved_default();
    // Turn the vessel's root union into a leaf: its children are now orphans.
    patch_u32::<Node>(
        &dir,
        "node.npy",
        f.node.len(),
        0,
        "typecode",
        hytrace_foundry::TypeCode::Sphere as u32,
    );
    let e = load_error(&dir);
    assert!(
        e.contains("prim.npy") && e.contains("non-empty children"),
        "{e}"
    );
}

#[test]
fn wrong_dtype_and_shape_are_named() {
    let (_tmp, dir, f) = saved_default();
    // tran.npy written as float32 instead of float64.
    let as_f32: Vec<f32> = f
        .tran
        .iter()
        .flat_map(|t| t.rows.iter().flatten().map(|v| *v as f32))
        .collect();
    let shape = [f.tran.len() as u64, 4, 4];
    hytrace_foundry::npy::write_array(
        &dir.join("tran.npy"),
        hytrace_foundry::layout::Scalar::F32,
        &shape,
        bytemuck::cast_slice(&as_f32),
    )
    .unwrap();
    let e = load_error(&dir);
    assert!(e.contains("tran.npy") && e.contains("wrong dtype"), "{e}");
    // tran.npy as (N, 16) float64: right dtype, wrong shape.
    let flat: Vec<f64> = f
        .tran
        .iter()
        .flat_map(|t| t.rows.into_iter().flatten())
        .collect();
    hytrace_foundry::npy::write_array(
        &dir.join("tran.npy"),
        hytrace_foundry::layout::Scalar::F64,
        &[f.tran.len() as u64, 16],
        bytemuck::cast_slice(&flat),
    )
    .unwrap();
    let e = load_error(&dir);
    assert!(e.contains("tran.npy") && e.contains("wrong shape"), "{e}");
}

#[test]
fn inconsistent_inverse_and_meta_are_caught() {
    let (_tmp, dir, f) = saved_default();
    let mut tran = f.tran.clone();
    tran[0] = Transform64::translation([1.0, 2.0, 3.0]);
    hytrace_foundry::npy::write_records(&dir.join("tran.npy"), &tran).unwrap();
    let e = load_error(&dir);
    assert!(
        e.contains("itra.npy") && e.contains("record 0") && e.contains("inverse"),
        "{e}"
    );

    let (_tmp, dir, _) = saved_default();
    std::fs::write(dir.join("meta.json"), "{\"format\": \"something-else\"").unwrap();
    let e = load_error(&dir);
    assert!(e.contains("meta.json"), "{e}");
    std::fs::remove_file(dir.join("brick.npy")).unwrap();
    assert!(load_error(&dir).contains("meta.json"));
    let (_tmp, dir, _) = saved_default();
    std::fs::remove_file(dir.join("brick.npy")).unwrap();
    assert!(load_error(&dir).contains("brick.npy"));
}

#[test]
fn double_precision_copies_must_round_to_the_gpu_values() {
    let (_tmp, dir, f) = saved_default();
    let mut node64 = f.node64.clone();
    // The vessel's outer sphere radius, moved by far more than an f32 ulp.
    let k = f
        .node
        .iter()
        .position(|n| n.typecode == hytrace_foundry::TypeCode::Sphere as u32)
        .unwrap();
    node64[k].param[3] += 0.5;
    hytrace_foundry::npy::write_records(&dir.join("node64.npy"), &node64).unwrap();
    let e = load_error(&dir);
    assert!(
        e.contains("node64.npy")
            && e.contains(&format!("record {k}"))
            && e.contains("does not round"),
        "{e}"
    );
    let (_tmp, dir, f) = saved_default();
    let mut node64 = f.node64.clone();
    node64.pop();
    hytrace_foundry::npy::write_records(&dir.join("node64.npy"), &node64).unwrap();
    let e = load_error(&dir);
    assert!(
        e.contains("node64.npy") && e.contains("records for the"),
        "{e}"
    );
}

#[test]
fn random_corruption_never_panics() {
    let (_tmp, dir, f) = saved_default();
    let files: Vec<String> = file_names();
    let originals: Vec<Vec<u8>> = files
        .iter()
        .map(|n| std::fs::read(dir.join(n)).unwrap())
        .collect();
    let mut rng = SplitMix64(42);
    let (mut rejected, mut accepted) = (0, 0);
    let cases = hytrace_testkit::fuzz_cases(600);
    for _ in 0..cases {
        let k = (rng.next_u64() % files.len() as u64) as usize;
        let mut bytes = originals[k].clone();
        match rng.next_u64() % 3 {
            0 => bytes.truncate((rng.next_u64() % (bytes.len() as u64 + 1)) as usize),
            1 => {
                for _ in 0..1 + rng.next_u64() % 4 {
                    let at = (rng.next_u64() % bytes.len().max(1) as u64) as usize;
                    if let Some(b) = bytes.get_mut(at) {
                        *b ^= 1 << (rng.next_u64() % 8);
                    }
                }
            }
            _ => {
                let at = (rng.next_u64() % (bytes.len() as u64 + 1)) as usize;
                bytes.insert(at, rng.next_u64() as u8);
            }
        }
        std::fs::write(dir.join(&files[k]), &bytes).unwrap();
        match Foundry::load(&dir) {
            Ok(loaded) => {
                // A flip in a float's low bits can leave a valid store; it must still validate.
                loaded.validate().unwrap();
                accepted += 1;
            }
            Err(e) => {
                // The message names the corrupted file, or its partner in a consistency pair
                // (tran/itra, inst/inst_tran) by its array name.
                let msg = e.to_string();
                let stem = files[k].trim_end_matches(".npy").trim_end_matches(".json");
                assert!(
                    msg.contains(stem),
                    "error does not name {}: {msg}",
                    files[k]
                );
                rejected += 1;
            }
        }
        std::fs::write(dir.join(&files[k]), &originals[k]).unwrap();
    }
    assert!(
        rejected > cases / 2,
        "only {rejected} of {cases} corruptions rejected ({accepted} accepted)"
    );
    assert_eq!(Foundry::load(&dir).unwrap(), f);
}

#[test]
fn media_must_match_the_volume_prims() {
    let (_tmp, dir, f) = saved_default();
    let fog = f.optics.media[0].prim;
    let edit = |change: &dyn Fn(&mut serde_json::Value)| {
        let path = dir.join("optics.json");
        let original = std::fs::read_to_string(&path).unwrap();
        let mut json: serde_json::Value = serde_json::from_str(&original).unwrap();
        change(&mut json);
        std::fs::write(&path, json.to_string()).unwrap();
        let message = load_error(&dir);
        std::fs::write(&path, original).unwrap();
        message
    };
    let message = edit(&|j| j["media"] = serde_json::json!([]));
    assert!(
        message.contains(&format!("volume prim {fog} has no medium")),
        "{message}"
    );
    let message = edit(&|j| j["media"][0]["prim"] = 0.into());
    assert!(message.contains("prim 0 is not a volume prim"), "{message}");
    let message = edit(&|j| {
        let m = j["media"][0].clone();
        j["media"].as_array_mut().unwrap().push(m);
    });
    assert!(
        message.contains(&format!("both describe prim {fog}")),
        "{message}"
    );
    let message = edit(&|j| j["media"][0]["density_scale"] = (-1.0).into());
    assert!(message.contains("density scale -1"), "{message}");
    // A boundary naming a material the table lacks: the file, the boundary, the field and
    // the table's size.
    let message = edit(&|j| {
        let none = u32::MAX;
        j["boundaries"]
            .as_array_mut()
            .unwrap()
            .push(serde_json::json!({
                "outer_material": 99, "outer_surface": none,
                "inner_surface": none, "inner_material": none,
            }));
    });
    assert!(
        message.contains("optics.json")
            && message.contains("boundary 0: outer_material is 99, but the table has"),
        "{message}"
    );
    // Unchanged, the store loads and keeps its medium.
    assert_eq!(Foundry::load(&dir).unwrap().optics.media, f.optics.media);
}
