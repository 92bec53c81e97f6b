//! `hytrace photons` end to end on a scene with every process of the propagator
//! (`tests/data/photons/every_process.gdml`): results independent of the number of
//! threads, Beer-Lambert attenuation on the way to a material without RINDEX (which kills
//! photons at its boundary, as Geant4 does), detections only on the sensor, the output
//! files, and bad input failing cleanly without output; the outputs streamed batch by batch
//! (tiny batches) equal to the in-memory run, and `--records` step points lying where the
//! CPU tracer puts the scene's surfaces and ending at the hits.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use hytrace_csg::V3;
use hytrace_foundry::gdml::GdmlOptions;
use hytrace_foundry::layout::Scalar;
use hytrace_foundry::npy::read_array;
use hytrace_trace::cpu::CpuScene;
use hytrace_trace::photons::output::RECORD_COLUMNS;
use hytrace_trace::photons::properties::energy_of_wavelength;
use hytrace_trace::photons::{
    load_photon_scene, propagate, propagate_reporting, PhotonRun, PhotonScene, RunOptions,
};

fn scene_path() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/data/photons/every_process.gdml")
}

fn scene() -> PhotonScene {
    let (f, surfaces) = load_photon_scene(&scene_path(), &GdmlOptions::default()).unwrap();
    PhotonScene::new(&f, surfaces).unwrap()
}

fn options(source: &str, photons: u64) -> RunOptions {
    common::torch_run(source, photons, 3)
}

fn run_on_threads(scene: &PhotonScene, run: &RunOptions, threads: usize) -> PhotonRun {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap()
        .install(|| propagate(scene, run).unwrap())
}

#[test]
fn results_do_not_depend_on_the_number_of_threads() {
    let scene = scene();
    let run = options("point:0,0,0", 3000);
    let one = run_on_threads(&scene, &run, 1);
    let three = run_on_threads(&scene, &run, 3);
    assert_eq!(one.histories, three.histories);
    assert_eq!(one.hits, three.hits);
    assert!(!one.hits.is_empty());
}

#[test]
fn progress_counts_every_photon_once_in_order_and_changes_nothing() {
    let scene = scene();
    // Past the first photon, in more than one batch of the propagator.
    let mut run = options("point:0,0,0", 70_000);
    run.first = 5;
    run.keep_histories = false;
    let seen = std::sync::Mutex::new(Vec::new());
    let reported =
        propagate_reporting(&scene, &run, &|done| seen.lock().unwrap().push(done)).unwrap();
    let seen = seen.into_inner().unwrap();
    assert!(seen.len() > 1, "{seen:?}");
    assert!(seen.windows(2).all(|w| w[0] < w[1]), "{seen:?}");
    assert_eq!(seen.last(), Some(&70_000));
    assert_eq!(reported.hits, propagate(&scene, &run).unwrap().hits);
}

#[test]
fn a_run_split_into_ranges_gives_the_whole_run() {
    let scene = scene();
    let whole = propagate(&scene, &options("point:0,0,0", 2500)).unwrap();
    let (mut hits, mut histories) = (Vec::new(), Vec::new());
    for (first, photons) in [(0, 700), (700, 1), (701, 1799)] {
        let part = propagate(
            &scene,
            &RunOptions {
                first,
                ..options("point:0,0,0", photons)
            },
        )
        .unwrap();
        assert!(part
            .hits
            .iter()
            .all(|h| (first..first + photons).contains(&(h.0[13] as u64))));
        hits.extend(part.hits);
        histories.extend(part.histories);
    }
    assert_eq!(hits, whole.hits);
    assert_eq!(histories, whole.histories);
    assert!(!whole.hits.is_empty());
    // A range past the last index is refused.
    let past = RunOptions {
        first: u64::MAX,
        ..options("point:0,0,0", 2)
    };
    assert!(propagate(&scene, &past).is_err());
}

/// The property tables at 420 nm, linear in photon energy (eV): the scene's ABSLENGTH
/// and RAYLEIGH of the liquid.
fn liquid_lengths() -> (f64, f64) {
    let e = energy_of_wavelength(420.0) * 1e6;
    let lerp = |a: f64, b: f64| a + (b - a) * (e - 2.0) / 1.5;
    (lerp(400.0, 250.0), lerp(300.0, 120.0))
}

#[test]
fn photons_reach_a_material_without_rindex_as_beer_lambert_says_and_die_there() {
    // A pencil-thin beam along +z from z = 40 in the liquid to the block at z = 65.
    let scene = scene();
    let run = propagate(&scene, &options("beam:0,0,40:0,0,1:5", 40_000)).unwrap();
    let (abs, ray) = liquid_lengths();
    let expected = (-25.0 / abs - 25.0 / ray).exp();
    let count = |h: &str| {
        run.counts
            .iter()
            .find(|(x, _)| x == h)
            .map_or(0, |(_, n)| *n)
    };
    let n = 40_000.0;
    let got = count("TO SA") as f64 / n;
    let sigma = (expected * (1.0 - expected) / n).sqrt();
    assert!((got - expected).abs() < 4.0 * sigma, "{got} vs {expected}");
    // None enters the block: nothing crosses it.
    assert!(
        run.counts.iter().all(|(h, _)| !h.starts_with("TO BT")),
        "{:?}",
        &run.counts[..5]
    );
    assert_eq!(
        count("TO AB") + count("TO SC") + count("TO SA"),
        run.counts
            .iter()
            .filter(|(h, _)| h.split(' ').count() == 2)
            .map(|(_, n)| n)
            .sum::<u64>()
    );
}

#[test]
fn only_the_sensor_detects() {
    let scene = scene();
    let run = propagate(&scene, &options("point:0,0,-20", 20_000)).unwrap();
    assert!(run.hits.len() > 100, "{}", run.hits.len());
    for h in &run.hits {
        let [x, y, z] = [h.0[0], h.0[1], h.0[2]];
        // Copy number 7: the sensor's; the hit lies on its surface.
        assert_eq!(h.0[12], 7.0);
        assert!(x.abs() <= 30.0 + 1e-6 && y.abs() <= 30.0 + 1e-6);
        assert!((-75.0 - 1e-6..=-65.0 + 1e-6).contains(&z), "{z}");
        let on_face = [
            30.0 - x.abs(),
            30.0 - y.abs(),
            (z + 65.0).abs(),
            (z + 75.0).abs(),
        ]
        .iter()
        .any(|d| d.abs() < 1e-6);
        assert!(on_face, "{x} {y} {z}");
        assert_eq!(h.0[7], 420.0);
        let dir = [h.0[4], h.0[5], h.0[6]];
        let pol = [h.0[8], h.0[9], h.0[10]];
        let dot: f64 = dir.iter().zip(&pol).map(|(a, b)| a * b).sum();
        assert!(dot.abs() < 1e-9);
    }
}

/// Geant4's lookup: the border surface of the ordered pair of physical volumes, else the
/// skin of the volume entered (when it is a daughter of the one left) or left, then the
/// other's.
#[test]
fn surfaces_are_found_as_geant4_finds_them() {
    let (f, surfaces) = load_photon_scene(&scene_path(), &GdmlOptions::default()).unwrap();
    let v = surfaces.unwrap();
    let instance = |name: &str| {
        f.inst
            .iter()
            .position(|i| f.optics.volumes[i.identity as usize] == name)
            .unwrap_or_else(|| panic!("no {name}")) as u32
    };
    let surface = |name: &str| {
        f.optics
            .surfaces
            .iter()
            .position(|s| s.name == name)
            .unwrap() as u32
    };
    let (tank, shell, sensor, ball) = (
        instance("tank_pv"),
        instance("shell_pv"),
        instance("sensor_pv"),
        instance("ball_pv"),
    );
    let (mirror, skin) = (surface("MirrorSurface"), surface("SensorSurface"));
    // The border surface is ordered: tank to shell only.
    assert_eq!(v.between(tank, shell), mirror);
    assert_eq!(v.between(shell, tank), hytrace_foundry::UNSET);
    // The sensor's skin both ways; nothing between the tank and the ball.
    assert_eq!(v.between(tank, sensor), skin);
    assert_eq!(v.between(sensor, tank), skin);
    assert_eq!(v.between(tank, ball), hytrace_foundry::UNSET);
    assert_eq!(v.between(ball, tank), hytrace_foundry::UNSET);
    // Between siblings: the skin of the one left, else of the one entered.
    assert_eq!(v.between(ball, sensor), skin);
    assert_eq!(v.between(sensor, ball), skin);
}

fn hytrace(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_hytrace"))
        .args(args)
        .output()
        .unwrap()
}

#[test]
fn the_command_writes_hits_histories_and_stats() {
    let dir = tempfile::tempdir().unwrap();
    let hits = dir.path().join("hits.npy");
    let hist = dir.path().join("history.npy");
    let scene = scene_path();
    let out = hytrace(&[
        "photons",
        scene.to_str().unwrap(),
        "--source",
        "point:0,0,-20",
        "-n",
        "2000",
        "-o",
        hits.to_str().unwrap(),
        &format!("--history={}", hist.display()),
        "--stats",
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        stdout.contains("history") && stdout.contains("TO AB"),
        "{stdout}"
    );
    let stats: serde_json::Value = serde_json::from_str(stdout.lines().last().unwrap()).unwrap();
    let a = read_array(&hits).unwrap();
    assert_eq!(a.scalar, Scalar::F64);
    assert_eq!(a.shape, vec![stats["hits"].as_u64().unwrap(), 16]);
    assert_eq!(stats["photons"], 2000);
    let h = std::fs::read(&hist).unwrap();
    // A uint64 array of 2000 entries after the npy header.
    assert!(String::from_utf8_lossy(&h[..128]).contains("<u8"));
    assert_eq!((h.len() - 128) / 8, 2000);
}

/// `--explain` lists the processes and where they run, propagates nothing and writes
/// nothing; it needs neither `-n` nor `-o`.
#[test]
fn explain_lists_the_processes_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let hits = dir.path().join("hits.npy");
    let scene = scene_path();
    for with_out in [false, true] {
        let mut args = vec![
            "photons",
            scene.to_str().unwrap(),
            "--source",
            "point:0,0,0",
        ];
        if with_out {
            args.extend(["-n", "10", "-o", hits.to_str().unwrap()]);
        }
        args.push("--explain");
        let out = hytrace(&args);
        let stdout = String::from_utf8_lossy(&out.stdout);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        for needle in [
            "torch source: point at (0, 0, 0) mm [cpu, gpu]",
            "Rayleigh scattering (RAYLEIGH): materials",
            "gpu kernel: composed with the physics features []",
        ] {
            assert!(stdout.contains(needle), "{needle}: {stdout}");
        }
        assert!(!hits.exists());
    }
}

#[test]
fn bad_input_fails_naming_the_problem_without_output() {
    let dir = tempfile::tempdir().unwrap();
    let hits = dir.path().join("hits.npy");
    let hits_arg = hits.to_str().unwrap();
    let scene = scene_path();
    let scene_arg = scene.to_str().unwrap();
    let text = std::fs::read_to_string(&scene).unwrap();
    let unsorted = dir.path().join("unsorted.gdml");
    std::fs::write(
        &unsorted,
        text.replace(
            r#"values="2.0*eV 1.30 2.8*eV 1.33 3.5*eV 1.36""#,
            r#"values="2.0*eV 1.30 3.5*eV 1.33 2.8*eV 1.36""#,
        ),
    )
    .unwrap();
    let negative = dir.path().join("negative.gdml");
    std::fs::write(
        &negative,
        text.replace(
            r#"values="2.0*eV 400 3.5*eV 250""#,
            r#"values="2.0*eV 400 3.5*eV -250""#,
        ),
    )
    .unwrap();
    for (args, needles) in [
        (
            vec!["--source", "point:0,0,0", "-n", "0"],
            vec!["-n", "at least 1"],
        ),
        (
            vec!["--source", "laser:0,0,0", "-n", "10"],
            vec!["laser:0,0,0", "unknown source"],
        ),
        (
            vec!["--source", "point:0,0,900", "-n", "10"],
            vec!["outside the world"],
        ),
        (
            vec!["--source", "point:0,0,0", "-n", "10", "--wavelength", "0"],
            vec!["wavelength"],
        ),
        (
            vec![
                "--source",
                "point:0,0,0",
                "-n",
                "10",
                "--wavelength",
                "Lava:RINDEX",
            ],
            vec!["no material `Lava`", "Liquid"],
        ),
        (
            vec![
                "--source",
                "point:0,0,0",
                "-n",
                "10",
                "--wavelength",
                "Liquid:GLOW",
            ],
            vec!["no property `GLOW`", "SCINTILLATIONCOMPONENT1"],
        ),
        (
            vec![
                "--source",
                "point:0,0,0",
                "-n",
                "10",
                "--wavelength",
                "blue",
            ],
            vec!["`blue`", "nanometres"],
        ),
        (
            vec!["--source", "point:0,0,0", "-n", "10", "--batch", "0"],
            vec!["batch size must be at least 1"],
        ),
        (
            vec![
                "--source",
                "point:0,0,0",
                "-n",
                "10",
                "--records",
                "0",
                "--records-out",
                "r.npy",
            ],
            vec!["--records 0"],
        ),
        (
            vec!["--source", "point:0,0,0", "-n", "10", "--records", "4"],
            vec!["--records-out"],
        ),
    ] {
        let mut all = vec!["photons", scene_arg];
        all.extend(&args);
        all.extend(["-o", hits_arg]);
        let out = hytrace(&all);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{args:?}");
        for n in needles {
            assert!(err.contains(n), "{args:?}: {err}");
        }
        assert!(!hits.exists(), "{args:?} left {}", hits.display());
    }
    for (file, needles) in [
        (&unsorted, ["material `Liquid`: property RINDEX", "row 2"]),
        (
            &negative,
            ["material `Liquid`: property ABSLENGTH", "row 1"],
        ),
    ] {
        let out = hytrace(&[
            "photons",
            file.to_str().unwrap(),
            "--source",
            "point:0,0,0",
            "-n",
            "10",
            "-o",
            hits_arg,
        ]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success());
        assert!(err.contains(file.to_str().unwrap()), "{err}");
        for n in needles {
            assert!(err.contains(n), "{err}");
        }
        assert!(!hits.exists());
    }
}

/// Steps recorded by the `--records` tests, and their source.
const K: u32 = 6;
const SOURCE: &str = "point:0,0,-20";

/// A run from [`SOURCE`] recording `K` step points a photon.
fn recording(photons: u64) -> RunOptions {
    RunOptions {
        records: K,
        ..options(SOURCE, photons)
    }
}

/// An array's values, as `T`.
fn values<T: bytemuck::Pod>(path: &Path, scalar: Scalar, shape: &[u64]) -> Vec<T> {
    let a = read_array(path).unwrap();
    assert_eq!((a.scalar, a.shape.as_slice()), (scalar, shape));
    bytemuck::pod_collect_to_vec(&a.bytes)
}

#[test]
fn streamed_outputs_equal_the_in_memory_run_whatever_the_batch() {
    let n = 1500;
    let run = propagate(&scene(), &recording(n)).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let (hits, hist, rec) = (
        dir.path().join("hits.npy"),
        dir.path().join("hist.npy"),
        dir.path().join("rec.npy"),
    );
    let scene_arg = scene_path();
    let out = hytrace(&[
        "photons",
        scene_arg.to_str().unwrap(),
        "--source",
        SOURCE,
        "-n",
        &n.to_string(),
        "--seed",
        "3",
        "--batch",
        "7",
        "--records",
        &K.to_string(),
        "--records-out",
        rec.to_str().unwrap(),
        "-o",
        hits.to_str().unwrap(),
        &format!("--history={}", hist.display()),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let h = run.hits.len() as u64;
    assert!(h > 50, "{h} hits");
    let streamed: Vec<f64> = values(&hits, Scalar::F64, &[h, 16]);
    let memory: Vec<f64> = run.hits.iter().flat_map(|r| r.0).collect();
    assert_eq!(streamed, memory);
    let a = std::fs::read(&hist).unwrap();
    assert_eq!(
        bytemuck::pod_collect_to_vec::<u8, u64>(&a[128..]),
        run.histories
    );
    let points: Vec<f32> = values(&rec, Scalar::F32, &[n, u64::from(K), 12]);
    let memory: Vec<f32> = run.records.iter().flatten().copied().collect();
    assert_eq!(points, memory);
}

#[test]
fn step_points_lie_on_the_boundaries_and_end_at_the_hits() {
    let n = 3000;
    let (f, surfaces) = load_photon_scene(&scene_path(), &GdmlOptions::default()).unwrap();
    let scene = PhotonScene::new(&f, surfaces).unwrap();
    let tracer = CpuScene::<f64>::new(&f).unwrap();
    let run = propagate(&scene, &recording(n)).unwrap();
    assert_eq!(run.records.len(), (n * u64::from(K)) as usize);
    let label = |p: &[f32; RECORD_COLUMNS]| p[11] as u64;
    let (mut on_boundaries, mut in_bulk) = (0, 0);
    for (i, points) in run.records.chunks_exact(K as usize).enumerate() {
        // The labels are the history's first K, then zero points.
        let code = run.histories[i];
        for (k, p) in points.iter().enumerate() {
            assert_eq!(label(p), (code >> (4 * k)) & 0xf, "photon {i} point {k}");
            if label(p) == 0 {
                assert_eq!(*p, [0.0; RECORD_COLUMNS]);
            }
        }
        // The source's point first.
        assert_eq!(&points[0][..4], &[0.0, 0.0, -20.0, 0.0]);
        for w in points.windows(2) {
            let (a, b) = (&w[0], &w[1]);
            if label(b) == 0 {
                break;
            }
            let v = |p: &[f32; RECORD_COLUMNS], c: usize| {
                V3::new(f64::from(p[c]), f64::from(p[c + 1]), f64::from(p[c + 2]))
            };
            let (pa, pb, da) = (v(a, 0), v(b, 0), v(a, 4).normalized());
            // Straight along the direction the photon left the previous point, later.
            let seg = pb - pa;
            assert!(
                seg.cross(da).length() < 1e-3 && seg.dot(da) > -1e-3,
                "photon {i}"
            );
            assert!(b[3] >= a[3], "photon {i}");
            // Boundaries (BT, BR, SR, DR, SD, SA): on a solid's surface (the least distance
            // to the surfaces of the scene's solids, which are boxes and a sphere: exact).
            let nearest = (0..tracer.instances() as u32)
                .map(|inst| tracer.surface_distance(inst, [pb.x, pb.y, pb.z]))
                .fold(f64::INFINITY, f64::min);
            match label(b) {
                7..=12 => {
                    assert!(nearest < 1e-3, "photon {i}: {nearest} mm from a surface");
                    on_boundaries += 1;
                }
                4 | 6 => in_bulk += 1,
                _ => {}
            }
        }
    }
    assert!(
        on_boundaries > 1000 && in_bulk > 300,
        "{on_boundaries} {in_bulk}"
    );
    // A detected photon's last point is its hit row (rounded to float32).
    for hit in &run.hits {
        let i = hit.0[13] as usize;
        let points = &run.records[i * K as usize..(i + 1) * K as usize];
        let Some(last) = points.iter().rev().find(|p| label(p) != 0) else {
            panic!("photon {i} has no points")
        };
        if (hit.0[15] as usize) < K as usize {
            assert_eq!(label(last), 7, "photon {i}");
            let want: Vec<f32> = hit.0[..11].iter().map(|&c| c as f32).collect();
            assert_eq!(&last[..11], want.as_slice(), "photon {i}");
        }
    }
}
