//! `hytrace scan` end to end: TOML scenes, rays in, hits and ids out (checked against
//! analytic answers), sweeps, stats, and bad input that must fail cleanly without output.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use hytrace_foundry::layout::Scalar;
use hytrace_foundry::npy::{read_array, write_array};

mod common;
use common::stderr;

fn hytrace(args: &[&str]) -> Output {
    common::hytrace(args, &[])
}

/// A sphere of radius 100 placed 20 m out and a box at the origin.
const SCENE: &str = r#"
[solids.ball]
shape = "sphere(100)"

[solids.crate]
shape = "box(50, 50, 50) - sphere(20)"

[[place]]
solid = "ball"
translate = [20000, 0, 0]

[[place]]
solid = "crate"
rotate = [0, 0, 1, 45]
"#;

fn write_f32_rays(path: &Path, rows: &[[f32; 8]]) {
    let flat: Vec<f32> = rows.iter().flatten().copied().collect();
    write_array(
        path,
        Scalar::F32,
        &[rows.len() as u64, 8],
        bytemuck::cast_slice(&flat),
    )
    .unwrap();
}

fn read_f64(path: &Path) -> (Vec<u64>, Vec<f64>) {
    let a = read_array(path).unwrap();
    let v = match a.scalar {
        Scalar::F32 => bytemuck::pod_collect_to_vec::<u8, f32>(&a.bytes)
            .into_iter()
            .map(f64::from)
            .collect(),
        Scalar::F64 => bytemuck::pod_collect_to_vec(&a.bytes),
        s => panic!("unexpected {s:?}"),
    };
    (a.shape, v)
}

fn setup() -> (tempfile::TempDir, PathBuf) {
    let tmp = tempfile::tempdir().unwrap();
    let scene = tmp.path().join("scene.toml");
    std::fs::write(&scene, SCENE).unwrap();
    (tmp, scene)
}

#[test]
fn scan_answers_match_the_analytic_sphere_and_name_the_instance() {
    let (tmp, scene) = setup();
    let rays = tmp.path().join("rays.npy");
    // Rays from 1 m left of the far sphere towards points of its disc; one starting inside;
    // one whose tmax stops short; one missing everything.
    let mut rows = Vec::new();
    for k in 0..50 {
        let y = -90.0 + 3.6 * k as f32;
        rows.push([19000.0, y, 0.0, 0.0, 1.0, 0.0, 0.0, f32::INFINITY]);
    }
    rows.push([20000.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, f32::INFINITY]);
    rows.push([19000.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 800.0]);
    rows.push([19000.0, 500.0, 0.0, 0.0, 1.0, 0.0, 0.0, f32::INFINITY]);
    write_f32_rays(&rays, &rows);
    for precision in ["f32", "f64"] {
        let hits = tmp.path().join(format!("hits-{precision}.npy"));
        let ids = tmp.path().join(format!("ids-{precision}.npy"));
        let o = hytrace(&[
            "scan",
            scene.to_str().unwrap(),
            "--rays",
            rays.to_str().unwrap(),
            "--out",
            hits.to_str().unwrap(),
            "--ids",
            ids.to_str().unwrap(),
            "--precision",
            precision,
            "--stats",
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        let stats: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        for key in ["rays", "load_s", "build_s", "trace_s", "rays_per_s"] {
            assert!(stats.get(key).is_some(), "stats lack {key}: {stats}");
        }
        assert_eq!(stats["rays"], rows.len());
        let (shape, h) = read_f64(&hits);
        assert_eq!(shape, vec![rows.len() as u64, 4]);
        assert_eq!(
            read_array(&hits).unwrap().scalar,
            if precision == "f32" {
                Scalar::F32
            } else {
                Scalar::F64
            }
        );
        let ids = read_array(&ids).unwrap();
        assert_eq!(ids.scalar, Scalar::I32);
        assert_eq!(
            ids.shape,
            vec![rows.len() as u64, 3],
            "instance boundary copy"
        );
        let rows3: Vec<[i32; 3]> = bytemuck::pod_collect_to_vec(&ids.bytes);
        // A TOML scene has no boundaries; copy numbers default to the placement index.
        for r in &rows3 {
            assert!(r[0] == -1 || (r[1] == -1 && r[2] == r[0]), "{r:?}");
        }
        let ids: Vec<i32> = rows3.iter().map(|r| r[0]).collect();
        let tol = if precision == "f32" { 1e-3 } else { 1e-6 };
        for (k, r) in rows[..50].iter().enumerate() {
            let y = r[1] as f64;
            let want = 1000.0 - (100.0f64 * 100.0 - y * y).sqrt();
            let hit = &h[4 * k..4 * k + 4];
            assert!(
                (hit[3] - want).abs() <= tol,
                "{precision} ray {k}: t {} want {want}",
                hit[3]
            );
            // Outward unit normal of the sphere at the hit point.
            let n = [(-1000.0 + hit[3]) / 100.0, y / 100.0, 0.0];
            for c in 0..3 {
                assert!(
                    (hit[c] - n[c]).abs() < 1e-3,
                    "{precision} ray {k}: normal {hit:?} want {n:?}"
                );
            }
            assert_eq!(ids[k], 0, "the far sphere is the first placement");
        }
        // From the centre of the ball upwards: the exit at 100 with normal +z.
        let inside = &h[4 * 50..4 * 51];
        assert!(
            (inside[3] - 100.0).abs() <= tol && inside[2] > 0.999,
            "{inside:?}"
        );
        // tmax 800 stops before the sphere at 900; the last ray misses.
        assert!(h[4 * 51 + 3].is_infinite() && ids[51] == -1);
        assert!(h[4 * 52 + 3].is_infinite() && ids[52] == -1);
    }
}

#[test]
fn sweeps_generate_rays_and_the_default_scene_scans() {
    let tmp = tempfile::tempdir().unwrap();
    let rays = tmp.path().join("rays.npy");
    // Output directories that do not exist yet are created (the README's main command
    // writes into `out/` on a fresh clone).
    let hits = tmp.path().join("not/yet/there/hits.npy");
    let o = hytrace(&[
        "scan",
        "default",
        "--sweep",
        "rect",
        "--count",
        "20",
        "--rays",
        rays.to_str().unwrap(),
        "--out",
        hits.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(read_array(&rays).unwrap().shape, vec![400, 8]);
    let (_, h) = read_f64(&hits);
    assert!(h.chunks(4).any(|c| c[3].is_finite()));
    // The same rays read back give the same hits.
    let again = tmp.path().join("again.npy");
    let o = hytrace(&[
        "scan",
        "--rays",
        rays.to_str().unwrap(),
        "--out",
        again.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(read_f64(&again).1, h);
    for sweep in ["axis", "circle"] {
        let out = tmp.path().join(format!("{sweep}.npy"));
        let o = hytrace(&[
            "scan",
            "--sweep",
            sweep,
            "--count",
            "50",
            "--out",
            out.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        let (_, h) = read_f64(&out);
        assert!(
            h.chunks(4).filter(|c| c[3].is_finite()).count() > 10,
            "{sweep}"
        );
    }
}

#[test]
fn bad_rays_and_scenes_fail_clearly_without_output() {
    let (tmp, scene) = setup();
    let out = tmp.path().join("hits.npy");
    let scan = |scene: &Path, rays: &Path| {
        hytrace(&[
            "scan",
            scene.to_str().unwrap(),
            "--rays",
            rays.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ])
    };
    let good = [0.0f32, 0.0, -500.0, 0.0, 0.0, 0.0, 1.0, f32::INFINITY];
    let mut cases: Vec<(String, PathBuf, &str)> = Vec::new();
    let mut rays_case = |name: &str, rows: Vec<[f32; 8]>, needle: &'static str| {
        let p = tmp.path().join(format!("{name}.npy"));
        write_f32_rays(&p, &rows);
        cases.push((name.to_string(), p, needle));
    };
    let mut nan = good;
    nan[5] = f32::NAN;
    rays_case("nan-direction", vec![good, nan], "ray 1: direction");
    let mut zero = good;
    zero[4..7].copy_from_slice(&[0.0, 0.0, 0.0]);
    rays_case("zero-direction", vec![zero], "zero length");
    let mut reversed = good;
    reversed[3] = 10.0;
    reversed[7] = 5.0;
    rays_case(
        "reversed-range",
        vec![good, good, reversed],
        "ray 2: needs finite tmin < tmax",
    );
    let mut inf_origin = good;
    inf_origin[0] = f32::INFINITY;
    rays_case("infinite-origin", vec![inf_origin], "origin");
    // Wrong shape, wrong dtype, truncated, not npy.
    let p = tmp.path().join("shape.npy");
    write_array(&p, Scalar::F32, &[2, 7], &[0u8; 56]).unwrap();
    cases.push(("shape".into(), p, "shape (N, 8)"));
    let p = tmp.path().join("dtype.npy");
    write_array(&p, Scalar::I32, &[1, 8], &[0u8; 32]).unwrap();
    cases.push(("dtype".into(), p, "float32 or float64"));
    let p = tmp.path().join("truncated.npy");
    write_f32_rays(&p, &[good, good]);
    let bytes = std::fs::read(&p).unwrap();
    std::fs::write(&p, &bytes[..bytes.len() - 10]).unwrap();
    cases.push(("truncated".into(), p, "truncated.npy"));
    let p = tmp.path().join("text.npy");
    std::fs::write(&p, "not numpy").unwrap();
    cases.push(("text".into(), p, "text.npy"));
    for (name, path, needle) in &cases {
        let o = scan(&scene, path);
        assert!(!o.status.success(), "{name} must fail");
        let e = stderr(&o);
        assert!(e.contains(needle), "{name}: {e}");
        assert!(
            e.contains(path.file_name().unwrap().to_str().unwrap()),
            "{name} names the file: {e}"
        );
        assert!(!out.exists(), "{name} left an output file");
    }
    // Scene files: unknown primitive, bad syntax, unknown solid, impossible parameter.
    let good_rays = tmp.path().join("good.npy");
    write_f32_rays(&good_rays, &[good]);
    let scenes = [
        (
            "[solids.a]\nshape = \"blob(3)\"\n",
            "unknown primitive `blob`",
        ),
        (
            "[solids.a]\nshape = \"sphere(3\"\n",
            "at column 9: expected `,`",
        ),
        (
            "[solids.a]\nshape = \"sphere(3)\"\n[[place]]\nsolid = \"b\"\n",
            "unknown solid `b`",
        ),
        ("[solids.a]\nshape = \"torus(0, 5, 2)\"\n", "swept radius"),
        ("[solids.a\nshape = 1\n", "not a valid scene file"),
        (
            "[solids.a]\nshape = \"sphere(1) * sphere(1).translate(5, 0, 0)\"\n",
            "empty",
        ),
    ];
    for (k, (text, needle)) in scenes.iter().enumerate() {
        let p = tmp.path().join(format!("bad{k}.toml"));
        std::fs::write(&p, text).unwrap();
        let o = scan(&p, &good_rays);
        assert!(!o.status.success(), "{text}");
        let e = stderr(&o);
        assert!(
            e.contains(needle) && e.contains(&format!("bad{k}.toml")),
            "{text}: {e}"
        );
        assert!(!out.exists());
    }
    // A tree that regrouping cannot make shallow enough is rejected, naming the solid.
    let mut deep = "sphere(100)".to_string();
    for i in 0..12 {
        let op = if i % 2 == 0 { "*" } else { "+" };
        deep = format!("({deep} {op} sphere(50).translate({i}, 0, 0))");
    }
    let p = tmp.path().join("deep.toml");
    std::fs::write(&p, format!("[solids.tower]\nshape = \"{deep}\"\n")).unwrap();
    let o = scan(&p, &good_rays);
    let e = stderr(&o);
    assert!(!o.status.success());
    assert!(
        e.contains("solid `tower`") && e.contains("exceeds the evaluator's limit"),
        "{e}"
    );
    assert!(!out.exists());
}

#[test]
fn failed_scans_leave_no_output_and_sizes_are_checked_first() {
    let (tmp, scene) = setup();
    let path = |name: &str| tmp.path().join(name);
    let listing = || {
        let mut names: Vec<String> = std::fs::read_dir(tmp.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().into_string().unwrap())
            .collect();
        names.sort();
        names
    };
    let before = listing();
    std::fs::create_dir(path("taken")).unwrap();
    let run = |args: &[&str]| {
        let mut all = vec![
            "scan",
            scene.to_str().unwrap(),
            "--sweep",
            "rect",
            "--count",
            "8",
        ];
        all.extend(args);
        hytrace(&all)
    };
    let hits = path("out/hits.npy");
    let (hits, taken, rays) = (hits.to_str().unwrap(), path("taken"), path("rays.npy"));
    let taken = taken.to_str().unwrap();
    // An output that is a directory, whichever option names it: refused before the scan,
    // nothing written (the hits' directory is not even created).
    for (args, option) in [
        (vec!["--out", hits, "--ids", taken], "--ids"),
        (
            vec!["--out", taken, "--rays", rays.to_str().unwrap()],
            "--out",
        ),
        (
            vec!["--out", hits, "--transmittance", taken],
            "--transmittance",
        ),
        (
            vec!["--out", hits, "--ids", hits],
            "--ids and --out both name",
        ),
    ] {
        let o = run(&args);
        assert!(!o.status.success(), "{args:?}");
        assert!(stderr(&o).contains(option), "{args:?}: {}", stderr(&o));
        let mut now = listing();
        now.retain(|n| n != "taken");
        assert_eq!(now, before, "{args:?} left files");
    }
    // Sweeps too large for the machine are refused by option before any allocation.
    for count in ["1000000000", "1000000000000"] {
        let o = hytrace(&[
            "scan", "default", "--sweep", "axis", "--count", count, "--out", hits,
        ]);
        let e = stderr(&o);
        assert!(!o.status.success());
        assert!(e.contains(&format!("--count {count}:")), "{e}");
        assert!(e.contains("memory"), "{e}");
        assert!(!e.contains("panicked"), "{e}");
    }
}

#[test]
fn every_scene_file_in_scenes_loads_and_scans() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes");
    let tmp = tempfile::tempdir().unwrap();
    let mut seen = 0;
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_none_or(|e| e != "toml") {
            continue;
        }
        seen += 1;
        let out = tmp.path().join("hits.npy");
        let o = hytrace(&[
            "scan",
            path.to_str().unwrap(),
            "--sweep",
            "circle",
            "--count",
            "360",
            "--out",
            out.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}: {}", path.display(), stderr(&o));
        let (_, h) = read_f64(&out);
        assert!(
            h.chunks(4).any(|c| c[3].is_finite()),
            "{}: no hits",
            path.display()
        );
    }
    assert!(seen > 0);
}

#[test]
fn an_interrupted_scan_exits_130_and_leaves_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("hits.npy");
    // 1.6x10^7 rays, about 4 s of work here, interrupted half a second in.
    let mut child = Command::new(env!("CARGO_BIN_EXE_hytrace"))
        .args([
            "scan", "default", "--sweep", "rect", "--count", "3200", "--out",
        ])
        .arg(&out)
        .spawn()
        .unwrap();
    std::thread::sleep(std::time::Duration::from_millis(500));
    let killed = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(killed.success());
    let status = child.wait().unwrap();
    assert_eq!(status.code(), Some(130), "{status:?}");
    let left: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
    assert!(left.is_empty(), "{left:?}");
}

/// The scan's progress counts every ray once (batches answered in any order add up to the
/// ray count) and the answers are the plain scan's.
#[test]
fn scan_progress_counts_every_ray_and_changes_nothing() {
    use hytrace_trace::scan::{rays_from_rows, scan_reporting, scan_with, Backend, Precision};
    let f = hytrace_trace::scene::load_scene(None, &Default::default()).unwrap();
    let rows: Vec<[f64; 8]> = (0..20_000)
        .map(|k| {
            let a = k as f64 * 0.618;
            let d = [
                a.cos() * (0.37 * a).sin(),
                a.sin() * (0.37 * a).sin(),
                (0.37 * a).cos(),
            ];
            [0.0, 0.0, 50.0, 0.0, d[0], d[1], d[2], f64::INFINITY]
        })
        .collect();
    let rays = rays_from_rows(&rows, "rays").unwrap();
    for precision in [Precision::F32, Precision::F64] {
        let most = std::sync::atomic::AtomicU64::new(0);
        let calls = std::sync::atomic::AtomicU64::new(0);
        let progress = |done: u64| {
            assert!(done <= rays.len() as u64);
            most.fetch_max(done, std::sync::atomic::Ordering::Relaxed);
            calls.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        };
        let (reported, _) = scan_reporting(&f, &rays, precision, Backend::Cpu, &progress).unwrap();
        assert_eq!(most.into_inner(), rays.len() as u64);
        assert!(calls.into_inner() > 1);
        let (plain, _) = scan_with(&f, &rays, precision, Backend::Cpu).unwrap();
        assert_eq!(reported.hits, plain.hits);
        assert_eq!(reported.ids, plain.ids);
    }
}

/// Every SIMD path this CPU runs (`HYTRACE_SIMD`) scans a mesh to the same bytes and
/// reports itself in `--stats`; a name that is no path, or a path this CPU lacks, fails
/// before any output, naming the variable.
#[test]
fn every_simd_path_scans_a_mesh_to_the_same_bytes_and_bad_paths_fail() {
    use hytrace_csg::simd::SimdPath;
    let mesh = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/meshes/rock.obj");
    let tmp = tempfile::tempdir().unwrap();
    let scan = |simd: &str, out: &Path| {
        common::hytrace(
            &[
                "scan",
                mesh.to_str().unwrap(),
                "--sweep",
                "circle",
                "--count",
                "3000",
                "--stats",
                "--out",
                out.to_str().unwrap(),
            ],
            &[("HYTRACE_SIMD", simd)],
        )
    };
    let mut first: Option<Vec<u8>> = None;
    for path in SimdPath::available() {
        let out = tmp.path().join(format!("{path}.npy"));
        let o = scan(&path.to_string(), &out);
        assert!(o.status.success(), "{path}: {}", stderr(&o));
        let stats: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        assert_eq!(stats["simd"], path.to_string(), "{stats}");
        assert!(stats["hits"].as_u64().unwrap() > 500, "{stats}");
        let bytes = std::fs::read(&out).unwrap();
        match &first {
            None => first = Some(bytes),
            Some(want) => assert!(bytes == *want, "{path} scans to other bytes"),
        }
    }
    let missing = [SimdPath::Avx2, SimdPath::Avx512]
        .into_iter()
        .filter(|p| !p.supported())
        .map(|p| (p.to_string(), "does not support"));
    for (name, problem) in [("sse9".to_string(), "unknown SIMD path")]
        .into_iter()
        .chain(missing)
    {
        let out = tmp.path().join("refused.npy");
        let o = scan(&name, &out);
        let err = stderr(&o);
        assert!(!o.status.success(), "{name} was accepted");
        assert!(
            err.contains("HYTRACE_SIMD") && err.contains(problem),
            "{name}: {err}"
        );
        assert!(!out.exists(), "{name} left {}", out.display());
    }
}
