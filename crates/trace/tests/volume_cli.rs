//! `hytrace volume` end to end: info, sample, transmittance and convert on procedural grids
//! and committed files, checked against analytic values, and bad input that must fail
//! cleanly, naming what is wrong, without leaving an output file.

use std::path::{Path, PathBuf};
use std::process::Output;

use hytrace_foundry::layout::Scalar;
use hytrace_foundry::npy::{read_array, write_array};

mod common;
use common::stderr;

fn hytrace(args: &[&str]) -> Output {
    common::hytrace(args, &[])
}

fn data(path: &str) -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../tests/data")
        .join(path)
        .to_str()
        .unwrap()
        .to_string()
}

fn write_f64(path: &Path, shape: &[u64], values: &[f64]) {
    write_array(path, Scalar::F64, shape, bytemuck::cast_slice(values)).unwrap();
}

fn read_values<T: bytemuck::Pod>(path: &Path, scalar: Scalar) -> Vec<T> {
    let a = read_array(path).unwrap();
    assert_eq!(a.scalar, scalar, "{}", path.display());
    assert_eq!(a.shape.len(), 1, "{}: shape {:?}", path.display(), a.shape);
    bytemuck::pod_collect_to_vec(&a.bytes)
}

struct Dir(tempfile::TempDir);

impl Dir {
    fn new() -> Dir {
        Dir(tempfile::tempdir().unwrap())
    }

    fn path(&self, name: &str) -> PathBuf {
        self.0.path().join(name)
    }

    fn arg(&self, name: &str) -> String {
        self.path(name).to_str().unwrap().to_string()
    }
}

/// `hytrace volume sample FOG_BOX` of the points in `p.npy` with `options`, read back from
/// `v.npy`.
fn sample_fog_box(d: &Dir, options: &[&str]) -> Vec<f32> {
    let (points, out) = (d.arg("p.npy"), d.arg("v.npy"));
    let mut args = vec![
        "volume", "sample", FOG_BOX, "--points", &points, "--out", &out,
    ];
    args.extend(options);
    let run = hytrace(&args);
    assert!(run.status.success(), "{args:?}: {}", stderr(&run));
    read_values(&d.path("v.npy"), Scalar::F32)
}

/// The fog box `box:20,20,20,1,4`: half extents 10 voxels, a 4-voxel blend. Along the x axis
/// through the centre the voxel values are clamp((10 - |i|) / 4, 0, 1), linearly
/// interpolated between voxel centres: the optical depth across is the trapezoid sum
/// 13 * 1 + 2 * (0.75 + 0.5 + 0.25) = 16.
const FOG_BOX: &str = "box:20,20,20,1,4";

#[test]
fn transmittance_across_a_fog_box_is_the_analytic_one() {
    let d = Dir::new();
    let scale = 0.05;
    // Along x through the centre, along x through voxel faces (y = 0.5: the same profile,
    // both neighbours equal), with a zero direction component, and an infinite end.
    let rays = [
        [-30.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, f64::INFINITY],
        [30.0, 0.5, 0.0, 0.0, -1.0, 0.0, 0.0, 100.0],
        [0.0, -40.0, 0.5, 0.0, 0.0, 1.0, 0.0, f64::INFINITY],
    ];
    write_f64(&d.path("rays.npy"), &[3, 8], rays.as_flattened());
    let want = (-16.0f64 * scale).exp();
    for estimator in ["exact", "march", "delta", "ratio", "residual"] {
        let spp = if matches!(estimator, "exact" | "march") {
            "1"
        } else {
            "20000"
        };
        let out = hytrace(&[
            "volume",
            "transmittance",
            FOG_BOX,
            "--rays",
            &d.arg("rays.npy"),
            "--out",
            &d.arg("t.npy"),
            "--estimator",
            estimator,
            "--spp",
            spp,
            "--step",
            "0.25",
            "--density-scale",
            &scale.to_string(),
        ]);
        assert!(out.status.success(), "{estimator}: {}", stderr(&out));
        let t: Vec<f64> = read_values(&d.path("t.npy"), Scalar::F64);
        // The unbiased trackers' samples lie in [0, 1]: standard error <= sqrt(T(1-T)/spp).
        let tol = match estimator {
            "exact" => 1e-12,
            // Midpoint steps that straddle the profile's kinks: O(step^2) per kink.
            "march" => 1e-3,
            _ => 4.0 * (want * (1.0 - want) / 20000.0).sqrt(),
        };
        for (i, v) in t.iter().enumerate() {
            assert!(
                (v - want).abs() <= tol,
                "{estimator}: ray {i}: T {v} != exp(-16 * {scale}) = {want}"
            );
        }
    }
}

#[test]
fn samples_follow_the_voxel_convention_in_every_representation() {
    let d = Dir::new();
    // World = index for voxel size 1. Voxel 8 of the box's x axis holds 0.5, voxel 9 0.25.
    let points = [
        [8.0, 0.0, 0.0],
        [8.5, 0.0, 0.0],
        [8.49, 0.0, 0.0],
        [50.0, 0.0, 0.0],
    ];
    write_f64(&d.path("p.npy"), &[4, 3], points.as_flattened());
    for (filter, want) in [
        ("nearest", [0.5, 0.25, 0.5, 0.0]),
        ("trilinear", [0.5, 0.375, 0.3775, 0.0]),
    ] {
        for repr in ["nanovdb", "f32", "f16", "unorm16", "unorm8", "bc4"] {
            let v = sample_fog_box(&d, &["--filter", filter, "--repr", repr]);
            // Quantized formats: within their share of the brick's range [0, 1].
            let tol = match repr {
                "bc4" => 1.0 / 14.0 + 1e-6,
                "unorm8" => 0.5 / 255.0 + 1e-6,
                "unorm16" | "f16" => 1e-3,
                _ => 1e-6,
            };
            for (i, (g, w)) in v.iter().zip(want).enumerate() {
                assert!(
                    (*g as f64 - w).abs() <= tol,
                    "{filter} {repr}: point {i}: {g} != {w}"
                );
            }
        }
    }
}

#[test]
fn majorants_bound_the_block_and_its_halo() {
    let d = Dir::new();
    let points = [[8.0, 0.0, 0.0], [50.0, 0.0, 0.0], [-7.6, 0.0, 0.0]];
    write_f64(&d.path("p.npy"), &[3, 3], points.as_flattened());
    // Level 0: point 8 lies in the block of voxels 8..15, whose halo reaches voxel 7 (0.75);
    // the block of voxels 48..55 and its halo are empty; -7.6 rounds to voxel -8, in the
    // block of voxels -8..-1 whose halo reaches voxel 0 (1.0). Level 3: one 64^3 block
    // around the origin holds the whole box (max 1).
    for (level, want) in [("0", [0.75, 0.0, 1.0]), ("3", [1.0, 1.0, 1.0])] {
        for repr in ["nanovdb", "unorm8"] {
            let m = sample_fog_box(&d, &["--majorant", level, "--repr", repr]);
            assert_eq!(m, want.map(|v| v as f32), "level {level} {repr}");
        }
    }
    let bad = hytrace(&[
        "volume",
        "sample",
        FOG_BOX,
        "--points",
        &d.arg("p.npy"),
        "--out",
        &d.arg("x.npy"),
        "--majorant",
        "4",
    ]);
    assert!(!bad.status.success() && stderr(&bad).contains("majorant level 4"));
    assert!(!d.path("x.npy").exists());
}

#[test]
fn info_lists_grids_and_memory_per_representation() {
    let out = hytrace(&["volume", "info", &data("openvdb/grids.vdb"), "--json"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let info: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let grids = info["grids"].as_array().unwrap();
    let names: Vec<&str> = grids.iter().map(|g| g["name"].as_str().unwrap()).collect();
    assert!(
        names.contains(&"density") && names.contains(&"velocity"),
        "{names:?}"
    );
    let density = grids.iter().find(|g| g["name"] == "density").unwrap();
    let memory: Vec<&str> = density["memory"]
        .as_array()
        .unwrap()
        .iter()
        .map(|m| m["representation"].as_str().unwrap())
        .collect();
    assert_eq!(
        memory,
        ["openvdb", "bc4", "unorm8", "unorm16", "f16", "f32"]
    );
    let velocity = grids.iter().find(|g| g["name"] == "velocity").unwrap();
    assert!(velocity["note"].as_str().unwrap().contains("vec3s"));
    // A grid whose 4096^3 root tile is too big to brick is still described, with why.
    let tile = hytrace(&[
        "volume",
        "info",
        &data("nanovdb/roottile_zip.nvdb"),
        "--json",
    ]);
    assert!(tile.status.success(), "{}", stderr(&tile));
    let info: serde_json::Value = serde_json::from_slice(&tile.stdout).unwrap();
    let note = info["grids"][0]["note"].as_str().unwrap();
    assert!(
        note.contains("not bricked") && note.contains("blocks"),
        "{note}"
    );
    let text = hytrace(&["volume", "info", "sphere:5,0.5"]);
    assert!(text.status.success(), "{}", stderr(&text));
    assert!(String::from_utf8_lossy(&text.stdout).contains("procedural"));
}

#[test]
fn convert_writes_a_complete_directory() {
    let d = Dir::new();
    let out = hytrace(&[
        "volume",
        "convert",
        "sphere:6,0.5,3",
        "--format",
        "unorm8",
        "-o",
        &d.arg("bricks"),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    for f in ["atlas.npy", "indirection.npy", "bricks.npy", "meta.json"] {
        assert!(d.path("bricks").join(f).exists(), "{f} missing");
    }
    let meta: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.path("bricks/meta.json")).unwrap())
            .unwrap();
    assert_eq!(meta["format"], "unorm8");
    let bad = hytrace(&[
        "volume",
        "convert",
        "sphere:6",
        "--format",
        "bc7",
        "-o",
        &d.arg("other"),
    ]);
    assert!(!bad.status.success());
    assert!(stderr(&bad).contains("bc7"), "{}", stderr(&bad));
    assert!(!d.path("other").exists());
}

#[test]
fn bad_input_fails_cleanly_without_output() {
    let d = Dir::new();
    write_f64(&d.path("p2.npy"), &[2, 2], &[0.0; 4]);
    write_f64(
        &d.path("nan.npy"),
        &[2, 3],
        &[0.0, 0.0, 0.0, f64::NAN, 1.0, 2.0],
    );
    write_f64(&d.path("p.npy"), &[1, 3], &[0.0; 3]);
    write_f64(
        &d.path("badray.npy"),
        &[1, 8],
        &[0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0],
    );
    write_f64(
        &d.path("ray.npy"),
        &[1, 8],
        &[0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0],
    );
    let truncated = d.path("cut.vdb");
    let whole = std::fs::read(data("openvdb/density_zip.vdb")).unwrap();
    std::fs::write(&truncated, &whole[..whole.len() / 2]).unwrap();
    let out_arg = d.arg("out.npy");
    let cases: Vec<(Vec<String>, &str)> = vec![
        (
            vec!["sample", FOG_BOX, "--points", &d.arg("p2.npy")].map_owned(),
            "(N, 3)",
        ),
        (
            vec!["sample", FOG_BOX, "--points", &d.arg("nan.npy")].map_owned(),
            "point 1",
        ),
        (
            vec!["sample", "sphere:1,0", "--points", &d.arg("p.npy")].map_owned(),
            "voxel size",
        ),
        (
            vec![
                "sample",
                &d.arg("missing.nvdb"),
                "--points",
                &d.arg("p.npy"),
            ]
            .map_owned(),
            "missing.nvdb",
        ),
        (
            vec![
                "sample",
                truncated.to_str().unwrap(),
                "--points",
                &d.arg("p.npy"),
            ]
            .map_owned(),
            "cut.vdb",
        ),
        (
            vec![
                "sample",
                &data("openvdb/grids.vdb"),
                "--points",
                &d.arg("p.npy"),
                "--grid",
                "nope",
            ]
            .map_owned(),
            "nope",
        ),
        (
            vec![
                "sample",
                &data("openvdb/grids.vdb"),
                "--points",
                &d.arg("p.npy"),
                "--grid",
                "velocity",
            ]
            .map_owned(),
            "vec3s",
        ),
        (
            vec!["transmittance", FOG_BOX, "--rays", &d.arg("badray.npy")].map_owned(),
            "zero length",
        ),
        (
            vec!["transmittance", FOG_BOX, "--rays", &d.arg("p.npy")].map_owned(),
            "(N, 8)",
        ),
        (
            vec![
                "transmittance",
                FOG_BOX,
                "--rays",
                &d.arg("ray.npy"),
                "--spp",
                "0",
            ]
            .map_owned(),
            "spp",
        ),
        (
            vec!["sample", "data.xyz", "--points", &d.arg("p.npy")].map_owned(),
            "unknown volume format",
        ),
    ];
    for (args, expect) in cases {
        let mut full = vec!["volume".to_string()];
        full.extend(args);
        full.extend(["--out".to_string(), out_arg.clone()]);
        let refs: Vec<&str> = full.iter().map(String::as_str).collect();
        let out = hytrace(&refs);
        assert!(!out.status.success(), "{full:?} succeeded");
        let err = stderr(&out);
        assert!(err.contains(expect), "{full:?}: `{expect}` not in: {err}");
        assert!(!err.contains("panicked"), "{full:?}: {err}");
        assert!(!d.path("out.npy").exists(), "{full:?} left an output file");
    }
}

/// `vec![&str]` to owned strings.
trait MapOwned {
    fn map_owned(self) -> Vec<String>;
}

impl MapOwned for Vec<&str> {
    fn map_owned(self) -> Vec<String> {
        self.into_iter().map(str::to_string).collect()
    }
}

/// A raw f32 volume whose values are a function of the voxel: a ball of radius 10 voxels
/// with a ramp inside, zero outside, 40 x 32 x 24 voxels.
fn write_ball_raw(path: &Path) -> Vec<f32> {
    let dims = [40usize, 32, 24];
    let mut values = Vec::new();
    for z in 0..dims[2] {
        for y in 0..dims[1] {
            for x in 0..dims[0] {
                let r = ((x as f32 - 20.0).powi(2)
                    + (y as f32 - 16.0).powi(2)
                    + (z as f32 - 12.0).powi(2))
                .sqrt();
                values.push(if r < 10.0 { 2.0 - r / 10.0 } else { 0.0 });
            }
        }
    }
    let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
    std::fs::write(path, bytes).unwrap();
    values
}

#[test]
fn a_raw_volume_converts_to_a_brick_store_that_every_budget_reads_alike() {
    let d = Dir::new();
    write_ball_raw(&d.path("ball.raw"));
    let convert = hytrace(&[
        "volume",
        "convert",
        &d.arg("ball.raw"),
        "--store",
        "--dims",
        "40,32,24",
        "--dtype",
        "f32",
        "--spacing",
        "0.5,0.5,0.5",
        "--origin",
        "-10,-8,-6",
        "-o",
        &d.arg("ball.bricks"),
    ]);
    assert!(convert.status.success(), "{}", stderr(&convert));
    assert!(
        stderr(&convert).contains("bricks kept"),
        "{}",
        stderr(&convert)
    );
    let info = hytrace(&["volume", "info", &d.arg("ball.bricks"), "--json"]);
    assert!(info.status.success(), "{}", stderr(&info));
    let json: serde_json::Value = serde_json::from_slice(&info.stdout).unwrap();
    let store = &json["grids"][0]["brick_store"];
    assert_eq!(store["dims"], serde_json::json!([40, 32, 24]));
    // The ball (radius 10 voxels) touches bricks of 8^3 around the centre; the corners drop.
    let (kept, dropped) = (
        store["kept_bricks"].as_u64().unwrap(),
        store["dropped_bricks"].as_u64().unwrap(),
    );
    assert_eq!(kept + dropped, 5 * 4 * 3);
    assert!(kept > 10 && dropped > 4, "{kept} kept, {dropped} dropped");
    // Rays through the ball's centre (world (0, 0, 0)) along x: the exact optical depth is
    // the integral of the ramp, 2 * integral_0^5 (2 - r/5) dr = 15 world units, up to
    // quantization and the voxel grid.
    let rays: Vec<f64> = (0..5)
        .flat_map(|k| {
            let y = -0.5 + 0.25 * k as f64;
            [-20.0, y, 0.0, 0.0, 1.0, 0.0, 0.0, 40.0]
        })
        .collect();
    write_f64(&d.path("rays.npy"), &[5, 8], &rays);
    let mut answers = Vec::new();
    for (memory, estimator) in [
        ("6M", "exact"),
        ("1G", "exact"),
        ("6M", "ratio"),
        ("1G", "ratio"),
    ] {
        let out = d.arg(&format!("t_{memory}_{estimator}.npy"));
        let o = hytrace(&[
            "volume",
            "transmittance",
            &d.arg("ball.bricks"),
            "--rays",
            &d.arg("rays.npy"),
            "--out",
            &out,
            "--memory",
            memory,
            "--estimator",
            estimator,
            "--spp",
            "16",
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        answers.push(read_values::<f64>(Path::new(&out), Scalar::F64));
    }
    assert_eq!(
        answers[0], answers[1],
        "exact: every budget reads the same voxels"
    );
    assert_eq!(answers[2], answers[3], "ratio: the same random streams");
    let tau = -answers[0][2].ln();
    assert!((tau - 15.0).abs() < 0.6, "optical depth {tau}");
}

#[test]
fn brick_store_misuse_fails_cleanly_without_output() {
    let d = Dir::new();
    write_ball_raw(&d.path("ball.raw"));
    let fails = |args: &[&str], want: &str| {
        let o = hytrace(args);
        assert!(!o.status.success(), "{args:?} succeeded");
        assert!(stderr(&o).contains(want), "{args:?}: {}", stderr(&o));
    };
    let out = d.arg("out.bricks");
    let raw = d.arg("ball.raw");
    fails(
        &[
            "volume", "convert", &raw, "--store", "--dims", "40,32,25", "--dtype", "f32", "-o",
            &out,
        ],
        "need 128000",
    );
    fails(
        &["volume", "convert", &raw, "--store", "-o", &out],
        "needs --dims X,Y,Z and --dtype",
    );
    fails(
        &[
            "volume", "convert", &raw, "--store", "--dims", "40,32", "--dtype", "f32", "-o", &out,
        ],
        "--dims `40,32`",
    );
    fails(
        &[
            "volume",
            "convert",
            "sphere:10",
            "--store",
            "--dims",
            "1,1,1",
            "-o",
            &out,
        ],
        "raw files (.raw) and pipes only",
    );
    fails(
        &[
            "volume", "convert", &raw, "--store", "--dims", "40,32,24", "--dtype", "f32",
            "--memory", "1K", "-o", &out,
        ],
        "--memory 1024",
    );
    fails(
        &[
            "volume", "convert", &raw, "--store", "--dims", "40,32,24", "--dtype", "f32",
            "--memory", "lots", "-o", &out,
        ],
        "not a byte count",
    );
    fails(&["volume", "convert", "sphere:10", "-o", &out], "--format");
    assert!(!d.path("out.bricks").exists());
    let o = hytrace(&[
        "volume", "convert", &raw, "--store", "--dims", "40,32,24", "--dtype", "f32", "-o", &out,
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    fails(
        &[
            "volume", "convert", &raw, "--store", "--dims", "40,32,24", "--dtype", "f32", "-o",
            &out,
        ],
        "already exists",
    );
    write_f64(
        &d.path("rays.npy"),
        &[1, 8],
        &[-20.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 40.0],
    );
    let t = d.arg("t.npy");
    let rays = d.arg("rays.npy");
    fails(
        &[
            "volume",
            "transmittance",
            &out,
            "--rays",
            &rays,
            "--out",
            &t,
            "--memory",
            "1M",
        ],
        "too small",
    );
    fails(
        &[
            "volume",
            "transmittance",
            &out,
            "--rays",
            &rays,
            "--out",
            &t,
            "--repr",
            "bc4",
        ],
        "read it whole",
    );
    fails(
        &[
            "volume",
            "transmittance",
            &out,
            "--rays",
            &rays,
            "--out",
            &t,
            "--backend",
            "gpu",
            "--memory",
            "1M",
        ],
        "give at least",
    );
    std::fs::remove_file(d.path("out.bricks").join("ranges.npy")).unwrap();
    fails(
        &[
            "volume",
            "transmittance",
            &out,
            "--rays",
            &rays,
            "--out",
            &t,
        ],
        "ranges.npy",
    );
    assert!(!d.path("t.npy").exists());
}

#[test]
fn repr_defaults_to_the_files_own_representation() {
    use hytrace_trace::volume::{open, Repr};
    let fitting = |spec: &str| Repr::fitting(&open(spec, None).unwrap().1);
    assert_eq!(fitting(&data("nanovdb/density_zip.nvdb")), Repr::Nanovdb);
    assert_eq!(fitting(&data("openvdb/density_zip.vdb")), Repr::Source);
    assert_eq!(fitting(FOG_BOX), Repr::Source);
    // The help says so for both commands that take --repr.
    for command in ["sample", "transmittance"] {
        let help = String::from_utf8(hytrace(&["volume", command, "--help"]).stdout).unwrap();
        let help = help.split_whitespace().collect::<Vec<_>>().join(" ");
        assert!(
            help.contains("nanovdb for a .nvdb file, source for a .vdb file, a procedural grid or a brick store"),
            "{command}: {help}"
        );
    }
    // With no --repr a .nvdb file is looked up in its NanoVDB buffer: the values equal
    // those of --repr nanovdb and of the grid as its NumPy source holds them (density.npy,
    // [a, b, c] is voxel (-37 + a, -26 + b, -20 + c)).
    let d = Dir::new();
    let index_points = [
        [-30.0, -20.0, -10.0],
        [-25.0, -15.0, -5.0],
        [-36.0, -25.0, -19.0],
    ];
    write_f64(&d.path("p.npy"), &[3, 3], index_points.as_flattened());
    let nvdb = data("nanovdb/density_zip.nvdb");
    let sample = |extra: &[&str]| {
        let (p, v) = (d.arg("p.npy"), d.arg("v.npy"));
        let mut args = vec!["volume", "sample", &nvdb, "--points", &p, "--out", &v];
        args.extend_from_slice(&["--space", "index", "--filter", "nearest"]);
        args.extend_from_slice(extra);
        let out = hytrace(&args);
        assert!(out.status.success(), "{}", stderr(&out));
        read_values::<f32>(&d.path("v.npy"), Scalar::F32)
    };
    let by_default = sample(&[]);
    assert_eq!(by_default, sample(&["--repr", "nanovdb"]));
    let source = read_array(Path::new(&data("nanovdb/density.npy"))).unwrap();
    let voxels: Vec<f32> = bytemuck::pod_collect_to_vec(&source.bytes);
    for (p, got) in index_points.iter().zip(&by_default) {
        let [a, b, c] = [p[0] + 37.0, p[1] + 26.0, p[2] + 20.0].map(|v| v as usize);
        assert_eq!(*got, voxels[(a * 20 + b) * 20 + c], "{p:?}");
    }
}

/// `volume convert` of raw voxels arriving on standard input (a pipe, read once): with
/// `--range` the store equals, file for file, the store of the same bytes from a `.raw`
/// file; without it the command refuses, naming the option, and writes nothing.
#[cfg(unix)]
#[test]
fn raw_voxels_from_a_pipe_convert_in_one_pass_as_the_file_does() {
    use std::io::Write;
    use std::process::{Command, Stdio};
    let d = Dir::new();
    write_ball_raw(&d.path("ball.raw"));
    let common = [
        "--store", "--dims", "40,32,24", "--dtype", "f32", "--range", "0,2",
    ];
    let from_file = hytrace(
        &[
            &["volume", "convert", &d.arg("ball.raw")][..],
            &common,
            &["-o", &d.arg("file.bricks")],
        ]
        .concat(),
    );
    assert!(from_file.status.success(), "{}", stderr(&from_file));
    let piped = |extra: &[&str], out: &str| {
        let mut child = Command::new(env!("CARGO_BIN_EXE_hytrace"))
            .args(
                [
                    &["volume", "convert", "/dev/stdin"][..],
                    extra,
                    &["-o", &d.arg(out)],
                ]
                .concat(),
            )
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let bytes = std::fs::read(d.path("ball.raw")).unwrap();
        // A refusal before reading closes the pipe: the write's error is expected then.
        let _ = child.stdin.take().unwrap().write_all(&bytes);
        child.wait_with_output().unwrap()
    };
    let o = piped(&common, "pipe.bricks");
    assert!(o.status.success(), "{}", stderr(&o));
    for entry in std::fs::read_dir(d.path("file.bricks")).unwrap() {
        let name = entry.unwrap().file_name();
        if name == "store.json" {
            continue;
        }
        let a = std::fs::read(d.path("file.bricks").join(&name)).unwrap();
        let b = std::fs::read(d.path("pipe.bricks").join(&name)).unwrap();
        assert!(a == b, "{name:?} differs");
    }
    let o = piped(&common[..5], "refused.bricks");
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("/dev/stdin") && stderr(&o).contains("--range"),
        "{}",
        stderr(&o)
    );
    assert!(!d.path("refused.bricks").exists());
}
