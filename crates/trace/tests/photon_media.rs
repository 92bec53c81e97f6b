//! Photons in a scene's sparse volumes (`docs/photons.md#media`), against analytic
//! results: Beer-Lambert through a uniform pure absorber and through a graded one (the
//! exponential of the optical depth integral), the first scattering angles of a thin
//! scattering slab against the Henyey-Greenstein formula, every photon accounted for;
//! results independent of threads and batches; `--explain`; bad media refused by name
//! with no output written. The Beer-Lambert checks run on the GPU kernel too where an
//! adapter opens.
//!
//! The scenes are `tests/data/photons/media_tank.gdml` (a vacuum world with a sensor plate
//! at z = 150 that detects everything reaching it) with procedural volumes placed at the
//! origin, written as scene files into a temporary directory.

mod common;

use std::path::{Path, PathBuf};

use common::{hytrace, stderr, torch_run};

use hytrace_foundry::gdml::GdmlOptions;
use hytrace_trace::gpu::{GpuContext, GpuPhotons};
use hytrace_trace::photons::output::{chi2_survival, history_string};
use hytrace_trace::photons::tracer::Precision;
use hytrace_trace::photons::{
    load_photon_scene, propagate, propagate_batches, Batch, PhotonRun, PhotonScene, RunOptions,
};

fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../tests/data/photons")
        .join(name)
}

/// A fresh directory for one test's files.
fn scratch(test: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!(
        "hytrace-photon-media-{}-{test}",
        std::process::id()
    ));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A scene file in `dir`: the tank with the volume entry `volume` (its TOML lines) named
/// `fog`, placed at `z`.
fn scene_file(dir: &Path, volume: &str, z: f64) -> PathBuf {
    let text = format!(
        "[gdml.tank]\nfile = {:?}\n\n[volumes.fog]\n{volume}\n\n[[place]]\nsolid = \"fog\"\ntranslate = [0, 0, {z}]\n",
        data("media_tank.gdml").display().to_string()
    );
    let path = dir.join("scene.toml");
    std::fs::write(&path, text).unwrap();
    path
}

fn scene(path: &Path) -> PhotonScene {
    let (f, surfaces) = load_photon_scene(path, &GdmlOptions::default()).unwrap();
    PhotonScene::new(&f, surfaces).unwrap()
}

/// `run` through the scene at `path` on the CPU, then on the GPU kernel (its scene prepared
/// with the kernel's f32 tracer) where an adapter opens: each backend's name and run.
fn on_each_backend(path: &Path, run: &RunOptions) -> Vec<(&'static str, PhotonRun)> {
    let mut runs = vec![("cpu", propagate(&scene(path), run).unwrap())];
    if let Some(ctx) = GpuContext::for_tests() {
        let (f, surfaces) = load_photon_scene(path, &GdmlOptions::default()).unwrap();
        let s32 = PhotonScene::with_precision(&f, surfaces, Precision::F32).unwrap();
        let kernel = GpuPhotons::new(&ctx, &s32, run).unwrap();
        let gpu = kernel.propagate(&ctx, &s32, run, &|_| ()).unwrap();
        runs.push(("gpu", gpu.run));
    }
    runs
}

fn options(source: &str, photons: u64, records: u32) -> RunOptions {
    RunOptions {
        records,
        ..torch_run(source, photons, 9)
    }
}

/// The last label of every photon's history.
fn last_labels(run: &PhotonRun) -> Vec<String> {
    run.histories
        .iter()
        .map(|&h| {
            history_string(h)
                .split(' ')
                .next_back()
                .unwrap()
                .to_string()
        })
        .collect()
}

/// `got` successes of `n` within 3 binomial sigma of probability `p`.
fn assert_binomial(what: &str, got: usize, n: u64, p: f64) {
    let sigma = (p * (1.0 - p) / n as f64).sqrt();
    let f = got as f64 / n as f64;
    assert!(
        (f - p).abs() < 3.0 * sigma,
        "{what}: {got} of {n} = {f}, expected {p} +- {sigma}"
    );
}

/// A slab 20 mm thick of unit density (blended to 0 over its outer voxel: the trilinear
/// field falls linearly over the last 1 mm on each side, so the optical depth across it is
/// `scale * (20 - 1)` mm), pure absorber: a pencil beam through it reaches the sensor with
/// probability `exp(-tau)`, and every other photon is absorbed in it.
#[test]
fn a_pure_absorber_transmits_exp_minus_its_optical_depth() {
    let dir = scratch("absorber");
    let tau: f64 = 1.0;
    let volume = format!(
        "source = \"box:200,200,20,1,1\"\ndensity_scale = {}\nalbedo = 0",
        tau / 19.0
    );
    let path = scene_file(&dir, &volume, 0.0);
    let n = 20_000;
    for (backend, run) in on_each_backend(&path, &options("beam:0,0,-150:0,0,1:0", n, 0)) {
        let labels = last_labels(&run);
        let detected = labels.iter().filter(|l| *l == "SD").count();
        let absorbed = labels.iter().filter(|l| *l == "AB").count();
        assert_eq!(
            detected + absorbed,
            n as usize,
            "{backend}: {:?}",
            run.counts
        );
        assert_eq!(run.hits.len(), detected, "{backend}");
        assert_binomial(backend, detected, n, (-tau).exp());
        // Detected on the sensor plate (its face at z = 149).
        assert!(run.hits.iter().all(|h| (h.0[2] - 149.0).abs() < 1e-4));
    }
}

/// A graded medium: a fog box 40 mm deep whose density rises linearly from 0 at its faces
/// to 1 at its centre (blend 20 voxels of 1 mm), the beam starting inside it 10 mm before
/// the centre: the optical depth ahead is `scale * (7.5 + 10)` mm (the integral of the
/// ramp), and a tracker that took the density for its majorant, or started at the box's
/// face, would see 30 or 20 mm.
#[test]
fn a_graded_medium_transmits_the_exponential_of_its_optical_depth_integral() {
    let dir = scratch("graded");
    let scale = 1.0 / 17.5;
    let volume = format!("source = \"box:200,200,40,1,20\"\ndensity_scale = {scale}");
    let path = scene_file(&dir, &volume, 0.0);
    let n = 20_000;
    for (backend, run) in on_each_backend(&path, &options("beam:0,0,-10:0,0,1:0", n, 0)) {
        let labels = last_labels(&run);
        let detected = labels.iter().filter(|l| *l == "SD").count();
        let absorbed = labels.iter().filter(|l| *l == "AB").count();
        assert_eq!(detected + absorbed, n as usize, "{backend}");
        assert_binomial(backend, detected, n, (-1.0f64).exp());
    }
}

/// An optically thin scattering slab (optical depth 0.1 across, albedo 0.8, g 0.6): the
/// direction after each photon's first scattering against the Henyey-Greenstein CDF by a
/// chi2 over 12 bins of its cosine (and an isotropic law rejected), the fraction that
/// collides at all against `1 - exp(-tau)`, and every photon ending detected, absorbed or
/// leaving the world.
#[test]
fn first_scatterings_follow_henyey_greenstein_and_every_photon_is_counted() {
    let dir = scratch("thin");
    let g: f64 = 0.6;
    let volume = "source = \"box:300,300,21,1,1\"\ndensity_scale = 0.005\nalbedo = 0.8\ng = 0.6";
    let scene = scene(&scene_file(&dir, volume, 0.0));
    let n = 40_000;
    let k = 3;
    let run = propagate(&scene, &options("beam:0,0,-150:0,0,1:0", n, k)).unwrap();
    let labels = last_labels(&run);
    for end in ["SD", "AB", "MI"] {
        assert!(
            labels.iter().any(|l| l == end),
            "no photon ends {end}: {:?}",
            run.counts
        );
    }
    let ended = |l: &&String| ["SD", "AB", "MI"].contains(&l.as_str());
    assert_eq!(
        labels.iter().filter(ended).count(),
        n as usize,
        "{:?}",
        run.counts
    );
    let total: u64 = run.counts.iter().map(|(_, c)| c).sum();
    assert_eq!(total, n);
    // Step points: TO, then the first interaction; its direction column after it.
    let point = |i: usize, j: usize| &run.records[i * k as usize + j];
    let sc = hytrace_trace::photons::output::Label::Sc as u8 as f32;
    let ab = hytrace_trace::photons::output::Label::Ab as u8 as f32;
    let mut cosines = Vec::new();
    let mut collided = 0;
    for i in 0..n as usize {
        let first = point(i, 1);
        if first[11] == sc {
            cosines.push(f64::from(first[6]));
        }
        if first[11] == sc || first[11] == ab {
            collided += 1;
            assert!(
                first[2].abs() < 11.0,
                "a collision outside the slab: z {}",
                first[2]
            );
        }
    }
    assert_binomial("collided", collided, n, 1.0 - (-0.1f64).exp());
    let bins = 12;
    let mut counts = vec![0u64; bins];
    for c in &cosines {
        counts[(((c + 1.0) / 2.0 * bins as f64) as usize).min(bins - 1)] += 1;
    }
    let cdf = |c: f64| {
        (1.0 - g * g) / (2.0 * g) * (1.0 / (1.0 + g * g - 2.0 * g * c).sqrt() - 1.0 / (1.0 + g))
    };
    let p_value = |expected: &dyn Fn(f64, f64) -> f64| {
        let m = cosines.len() as f64;
        let chi2: f64 = (0..bins)
            .map(|b| {
                let lo = -1.0 + 2.0 * b as f64 / bins as f64;
                let e = m * expected(lo, lo + 2.0 / bins as f64);
                (counts[b] as f64 - e).powi(2) / e
            })
            .sum();
        chi2_survival(chi2, (bins - 1) as f64)
    };
    let p = p_value(&|a, b| cdf(b) - cdf(a));
    assert!(
        p > 1e-3,
        "HG p-value {p} over {} first scatterings: {counts:?}",
        cosines.len()
    );
    assert!(
        p_value(&|a, b| (b - a) / 2.0) < 1e-6,
        "isotropic not rejected"
    );
}

fn run_on(scene: &PhotonScene, run: &RunOptions, threads: usize, batch: u64) -> Batch {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    let mut all = Batch::default();
    pool.install(|| propagate_batches(scene, run, batch, &mut |b| all.gather(b), &|_| ()))
        .unwrap();
    all
}

/// The same seed gives the same bits on 1 or 3 threads, in one batch or batches of 37.
#[test]
fn media_runs_do_not_depend_on_threads_or_batches() {
    let scene = scene(&data("media_slab.toml"));
    let run = options("point:0,0,-5", 3000, 4);
    let a = run_on(&scene, &run, 1, 3000);
    let b = run_on(&scene, &run, 3, 37);
    assert_eq!(a.histories, b.histories);
    assert_eq!(a.records, b.records);
    let bits =
        |x: &Batch| -> Vec<u64> { x.hits.iter().flat_map(|h| h.0.map(f64::to_bits)).collect() };
    assert_eq!(bits(&a), bits(&b));
    assert!(!a.hits.is_empty());
    assert!(a
        .histories
        .iter()
        .any(|&h| history_string(h).contains("SC")));
}

/// `--explain` lists the medium with where it runs (both backends) and the kernel composed
/// with `media`.
#[test]
fn explain_lists_the_media() {
    let scene = data("media_slab.toml");
    let out = hytrace(
        &[
            "photons",
            scene.to_str().unwrap(),
            "--source",
            "point:0,0,0",
            "--explain",
        ],
        &[],
    );
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(
        text.contains("medium: delta-tracked absorption (AB) and Henyey-Greenstein scattering (SC): `box:200,200,20,1,1` x 0.05 /mm, albedo 0.8, g 0.6 [cpu, gpu;"),
        "{text}"
    );
    assert!(text.contains("physics features [media]"), "{text}");
}

/// Bad media: each refused naming the scene file and the volume entry, with no output.
#[test]
fn bad_media_fail_naming_the_file_and_entry_without_output() {
    let dir = scratch("bad");
    let nvdb = data("../nanovdb/density_zip.nvdb");
    let missing_grid = format!(
        "source = {:?}\ngrid = \"smoke\"\ndensity_scale = 0.1",
        nvdb.display().to_string()
    );
    let cases = [
        (
            "source = \"box:20,20,20\"\ndensity_scale = -0.1",
            "density scale",
        ),
        (
            "source = \"box:20,20,20\"\ndensity_scale = 0.1\ng = 1.5",
            "g must be in (-1, 1)",
        ),
        (
            "source = \"box:20,20,20\"\ndensity_scale = 0.1\nalbedo = 1.2",
            "albedo must be in [0, 1]",
        ),
        (
            "source = \"missing.nvdb\"\ndensity_scale = 0.1",
            "missing.nvdb",
        ),
        (missing_grid.as_str(), "smoke"),
        (
            "source = \"box:20,20,20\"\ndensity_scale = 1e9",
            "optical depth",
        ),
    ];
    for (volume, why) in cases {
        let scene = scene_file(&dir, volume, 0.0);
        let hits = dir.join("hits.npy");
        let out = hytrace(
            &[
                "photons",
                scene.to_str().unwrap(),
                "--source",
                "point:0,0,-100",
                "-n",
                "10",
                "-o",
                hits.to_str().unwrap(),
            ],
            &[],
        );
        let err = stderr(&out);
        assert!(!out.status.success(), "{volume}: succeeded");
        assert!(
            err.contains("scene.toml") && err.contains(why),
            "{volume}: {err}"
        );
        assert!(
            err.contains("fog") || err.contains("medium 0"),
            "{volume}: {err}"
        );
        assert!(!err.contains("panicked"), "{err}");
        assert!(!hits.exists(), "{volume}: wrote {}", hits.display());
    }
}

/// A medium read as stored from a brick store whose bricks file is cut short while the
/// run is under way: the failed lookups read the background, so the run fails naming the
/// file instead of handing over photons propagated through a wrong medium.
#[test]
fn a_stored_medium_cut_short_while_open_fails_naming_its_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = common::stored_medium(dir.path());
    let scene = scene(&path);
    let run = options("beam:0,0,-150:0,0,1:0", 500, 0);
    common::cut_store_short(dir.path());
    let mut handed = 0;
    let err = propagate_batches(
        &scene,
        &run,
        100,
        &mut |_| {
            handed += 1;
            Ok(())
        },
        &|_| (),
    )
    .expect_err("a store cut short must fail the run");
    let text = err.to_string();
    assert!(text.contains("bricks.bin"), "{text}");
    assert_eq!(
        handed, 0,
        "a batch through the wrong medium was handed over"
    );
}
