//! The GPU photon kernel (`shaders/kernels/photons.wgsl`) against its CPU twin (the
//! propagator with the f32 tracer) photon by photon, and against the default CPU run (f64
//! geometry) by the fraction of identical histories and a chi2 on history frequencies,
//! on every process: the repository's every-process, rough-surface, scintillator and
//! wavelength-shifter scenes (spectra, re-emission, gensteps, wavelength shifting, step
//! points), media (a fog slab and a dense fog), the raindrop and the 8x8 SiPM files of the
//! shared corpus.

mod common;

use std::path::{Path, PathBuf};
use std::sync::Arc;

use common::{gpu_stats, hytrace, repo, stderr};
use hytrace_foundry::gdml::GdmlOptions;
use hytrace_foundry::layout::Scalar;
use hytrace_foundry::npy::read_array;
use hytrace_trace::gpu::{GpuContext, GpuPhotons, StreamError};
use hytrace_trace::photons::gensteps::GenstepFile;
use hytrace_trace::photons::output::{compare_histories, history_string, HitRow};
use hytrace_trace::photons::sources::{Source, Wavelength};
use hytrace_trace::photons::tracer::Precision;
use hytrace_trace::photons::{
    load_photon_scene, propagate, Batch, Origin, PhotonRun, PhotonScene, RunOptions,
};

fn options(source: &str, photons: u64) -> RunOptions {
    RunOptions {
        origin: Origin::Torch {
            source: Source::parse(source).unwrap(),
            wavelength: Wavelength::Fixed(420.0),
        },
        photons,
        first: 7,
        seed: 11,
        max_steps: 10_000,
        keep_histories: true,
        records: 0,
    }
}

fn scene(path: &Path, precision: Precision) -> PhotonScene {
    let (f, surfaces) = load_photon_scene(path, &GdmlOptions::default()).unwrap();
    PhotonScene::with_precision(&f, surfaces, precision).unwrap()
}

/// The hit rows of the photons whose histories are equal in both runs, paired.
fn paired_hits<'a>(a: &'a PhotonRun, b: &'a PhotonRun) -> Vec<(&'a HitRow, &'a HitRow)> {
    let first = 7.0;
    let same = |h: &HitRow| {
        let i = (h.0[13] - first) as usize;
        a.histories[i] == b.histories[i]
    };
    let (x, y): (Vec<_>, Vec<_>) = (
        a.hits.iter().filter(|h| same(h)).collect(),
        b.hits.iter().filter(|h| same(h)).collect(),
    );
    assert_eq!(x.len(), y.len());
    x.into_iter().zip(y).collect()
}

/// The fraction of photons with identical histories.
fn same_histories(a: &PhotonRun, b: &PhotonRun) -> f64 {
    let same = a
        .histories
        .iter()
        .zip(&b.histories)
        .filter(|(x, y)| x == y)
        .count();
    same as f64 / a.histories.len() as f64
}

/// GPU against the f32 twin photon by photon (histories, then hit rows within f32
/// rounding of the physics: the kernel computes it in f32, the twin in f64 over the same
/// f32 geometry), and against the f64 CPU by the histories' frequencies.
fn twin(name: &str, path: PathBuf, source: &str, photons: u64, min_detected: usize) {
    twin_run(name, path, options(source, photons), min_detected);
}

/// The share of photons that may run out of lavapipe's loop budget (propagated again by
/// the twin): none, but in the wavelength shifter, whose photons take many steps and
/// draw up to 100 spectrum energies at each shifting absorption.
const SHIFTER_REDONE: f64 = 0.3;

/// [`twin`] for any torch run (photons from index 7); the GPU's run, or `None` without an
/// adapter (tests do not require one).
fn twin_run(name: &str, path: PathBuf, run: RunOptions, min_detected: usize) -> Option<PhotonRun> {
    twin_within(name, path, run, min_detected, 0.0).map(|(g, _)| g)
}

/// [`twin_run`], with at most `redone` of the photons run out of the driver's loop budget;
/// the GPU's run and the fraction of its histories equal to the twin's.
fn twin_within(
    name: &str,
    path: PathBuf,
    run: RunOptions,
    min_detected: usize,
    redone: f64,
) -> Option<(PhotonRun, f64)> {
    let ctx = GpuContext::for_tests()?;
    let photons = run.photons;
    let s32 = scene(&path, Precision::F32);
    let kernel = GpuPhotons::new(&ctx, &s32, &run).unwrap();
    let gpu = kernel.propagate(&ctx, &s32, &run, &|_| ()).unwrap();
    let cpu32 = propagate(&s32, &run).unwrap();
    let cpu64 = propagate(&scene(&path, Precision::F64), &run).unwrap();
    let g = &gpu.run;
    assert_eq!(g.histories.len(), photons as usize);
    assert!(
        g.hits.len() >= min_detected,
        "{name}: {} hits",
        g.hits.len()
    );
    let twin_same = same_histories(g, &cpu32);
    let f64_same = same_histories(g, &cpu64);
    let chi2 = compare_histories(&g.counts, &cpu64.counts, 30);
    eprintln!(
        "{name}: {photons} photons, {} hits; histories equal to the f32 twin {:.4}, to the f64 CPU {:.4}; \
         chi2/ndf vs f64 {:.2}/{} (p {:.3}); redone on the CPU {}, split on the CPU {}",
        g.hits.len(),
        twin_same,
        f64_same,
        chi2.chi2,
        chi2.ndf,
        chi2.p_value,
        gpu.times.redone_on_cpu,
        gpu.times.split_on_cpu
    );
    // Photons that ran out of lavapipe's loop budget are the twin's by construction.
    assert!(
        gpu.times.redone_on_cpu as f64 <= redone * photons as f64,
        "{name}: {} photons redone on the CPU",
        gpu.times.redone_on_cpu
    );
    // f32 rounding of the physics takes a random decision apart for a few photons.
    assert!(twin_same >= 0.99, "{name}: {twin_same}");
    assert!(f64_same >= 0.98, "{name}: {f64_same}");
    assert!(chi2.p_value > 1e-3, "{name}: {chi2:?}");
    let pairs = paired_hits(g, &cpu32);
    assert!(pairs.len() as f64 >= 0.95 * g.hits.len() as f64);
    // Position, time, direction, wavelength, polarization: f32 physics over the same steps
    // (an f32 sine of a scattering angle near 0 or pi, or a long path after it, spreads
    // the rounding); instance, copy number, index, mask and steps exactly.
    let within = |a: &HitRow, b: &HitRow, r: f64| {
        (0..11).all(|k| (a.0[k] - b.0[k]).abs() <= r * (1.0 + b.0[k].abs()))
    };
    let close = pairs.iter().filter(|(a, b)| within(a, b, 1e-4)).count();
    eprintln!(
        "{name}: {close} of {} hits with equal histories within 1e-4 relative",
        pairs.len()
    );
    assert!(close as f64 >= 0.95 * pairs.len() as f64, "{name}");
    for (a, b) in pairs {
        assert!(within(a, b, 2e-2), "{name}: {:?} vs {:?}", a.0, b.0);
        assert_eq!(a.0[11..], b.0[11..], "{name}");
    }
    if run.records > 0 {
        same_step_points(name, g, &cpu32, run.records as usize);
    }
    Some((gpu.run, twin_same))
}

/// The step points of the photons with equal histories: labels (and zero points past the
/// end) exactly, the columns within f32 rounding of the physics as hit rows are.
fn same_step_points(name: &str, g: &PhotonRun, cpu: &PhotonRun, k: usize) {
    assert_eq!(g.records.len(), g.histories.len() * k, "{name}");
    assert_eq!(cpu.records.len(), g.records.len(), "{name}");
    let (mut points, mut close) = (0, 0);
    for (i, (a, b)) in g.histories.iter().zip(&cpu.histories).enumerate() {
        if a != b {
            continue;
        }
        for p in i * k..(i + 1) * k {
            let (x, y) = (&g.records[p], &cpu.records[p]);
            assert_eq!(x[11], y[11], "{name}: photon {i}, point {}", p - i * k);
            let near = |r: f32| (0..11).all(|c| (x[c] - y[c]).abs() <= r * (1.0 + y[c].abs()));
            assert!(near(2e-2), "{name}: photon {i}: {x:?} vs {y:?}");
            points += usize::from(y[11] != 0.0);
            close += usize::from(y[11] != 0.0 && near(1e-4));
        }
    }
    eprintln!("{name}: {close} of {points} step points within 1e-4 relative");
    assert!(points > 0 && close as f64 >= 0.95 * points as f64, "{name}");
}

/// Photons from gensteps in the scintillator cube: a scintillation step shared by the two
/// components (with a charged particle, and a neutral one emitting at the step's end), one
/// of the second component only, and a Cherenkov step of a slowing particle; the GPU emits
/// them as the CPU does (the same draws), so the twin agrees photon by photon, and the hit
/// times reach past the slow component's decay.
#[test]
fn gensteps_match_the_cpu_twin_photon_by_photon() {
    #[rustfmt::skip]
    let rows: [[f64; 14]; 4] = [
        // kind, photons, material, t0, start, end, beta0, beta1, charge, component
        [2.0, 1200.0, 1.0, 10.0, -20.0, 0.0, 0.0, 20.0, 0.0, 0.0, 0.5, 0.5, -1.0, 0.0],
        [2.0, 300.0, 1.0, 5.0, 0.0, 30.0, 10.0, 0.0, 30.0, 40.0, 0.4, 0.3, 0.0, 2.0],
        [2.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.5, 0.5, -1.0, 0.0],
        [1.0, 1500.0, 1.0, 50.0, 0.0, 0.0, 60.0, 0.0, 0.0, 20.0, 0.99, 0.9, -1.0, 0.0],
    ];
    let file = GenstepFile::from_values("twin.npy".into(), &[4, 14], rows.as_flattened()).unwrap();
    let run = RunOptions {
        origin: Origin::Gensteps(Arc::new(file)),
        photons: 2990,
        ..options("point:0,0,0", 1)
    };
    let path = repo("tests/data/photons/scintillator.gdml");
    let Some(gpu) = twin_run("gensteps", path, run, 300) else {
        return;
    };
    // The second step's photons (from index 1200, the run's from 7) start at its end, 40 mm
    // above the floor, at least 5 ns plus the flight time.
    let late = gpu.hits.iter().filter(|h| h.0[3] > 60.0).count();
    assert!(late > 10, "{late} hits after 60 ns");
}

/// Wavelength shifting: one photon per absorption (the first plate), a Poisson number
/// (mean 2; the absorptions emitting several are the CPU twin's by construction).
#[test]
fn wavelength_shifting_matches_the_cpu_twin_photon_by_photon() {
    let path = repo("tests/data/photons/wavelength_shifter.gdml");
    for (name, source) in [
        ("shifter one", "beam:-80,0,50:0.2,0,-1:10"),
        ("shifter poisson", "beam:80,0,50:0.2,0,-1:10"),
    ] {
        let run = options(source, 1500);
        twin_within(name, path.clone(), run, 100, SHIFTER_REDONE);
    }
}

/// Step points (`--records`) from the GPU: the first K points of every photon, through
/// boundaries, rough surfaces and re-emission, against the twin's.
#[test]
fn step_points_match_the_cpu_twin_point_by_point() {
    for (name, file, source, k, wavelength) in [
        (
            "every_process records",
            "tests/data/photons/every_process.gdml",
            "point:0,0,0",
            8,
            Wavelength::Fixed(420.0),
        ),
        (
            "rough surfaces records",
            "tests/data/photons/rough_surfaces.gdml",
            "beam:-265,0,50:0.5,0,-1:5",
            5,
            Wavelength::Fixed(420.0),
        ),
        (
            "scintillator records",
            "tests/data/photons/scintillator.gdml",
            "point:0,0,50",
            20,
            Wavelength::Fixed(400.0),
        ),
    ] {
        let run = RunOptions {
            records: k,
            ..with_wavelength(options(source, 1000), wavelength)
        };
        if twin_run(name, repo(file), run, 10).is_none() {
            return;
        }
    }
}

/// [`options`] with photon energies drawn from `material`'s spectrum `property`, or at
/// `nm`.
fn with_wavelength(run: RunOptions, wavelength: Wavelength) -> RunOptions {
    let Origin::Torch { source, .. } = run.origin else {
        unreachable!("a torch run")
    };
    RunOptions {
        origin: Origin::Torch { source, wavelength },
        ..run
    }
}

fn spectrum(material: &str, property: &str) -> Wavelength {
    Wavelength::Spectrum {
        material: material.into(),
        property: property.into(),
    }
}

/// Photon energies drawn from a material's spectrum (the every-process scene's liquid,
/// as the Geant4 oracle test draws them): the hits' wavelengths spread over the spectrum.
#[test]
fn spectra_match_the_cpu_twin_photon_by_photon() {
    let path = repo("tests/data/photons/every_process.gdml");
    let wavelength = spectrum("Liquid", "SCINTILLATIONCOMPONENT1");
    for (name, source, min_detected) in [
        ("every_process spectrum point", "point:0,0,0", 50),
        ("every_process spectrum beam", "beam:0,0,50:0,0,-1:20", 300),
    ] {
        let run = with_wavelength(options(source, 2000), wavelength.clone());
        let Some(gpu) = twin_run(name, path.clone(), run, min_detected) else {
            return;
        };
        let nm: Vec<f64> = gpu.hits.iter().map(|h| h.0[7]).collect();
        let (lo, hi) = nm
            .iter()
            .fold((f64::MAX, 0f64), |(a, b), &x| (a.min(x), b.max(x)));
        assert!(hi - lo > 20.0, "{name}: hit wavelengths {lo} .. {hi} nm");
    }
}

/// Re-emission (REEMISSIONPROB 0.5 above 3 eV in the scintillator cube, two components):
/// photons at 400 nm, and photons drawn from the fast component's spectrum (partly above
/// 3 eV, where it re-emits), from inside the cube; re-emitted photons are among them.
#[test]
fn re_emission_matches_the_cpu_twin_photon_by_photon() {
    let path = repo("tests/data/photons/scintillator.gdml");
    for (name, wavelength, least) in [
        ("scintillator 400 nm", Wavelength::Fixed(400.0), 100),
        (
            "scintillator spectrum",
            spectrum("LS", "SCINTILLATIONCOMPONENT1"),
            20,
        ),
    ] {
        let run = with_wavelength(options("point:0,0,50", 3000), wavelength);
        let Some(gpu) = twin_run(name, path.clone(), run, 300) else {
            return;
        };
        let re = (gpu.histories.iter())
            .filter(|&&h| history_string(h).contains("RE"))
            .count();
        eprintln!("{name}: {re} photons re-emitted");
        assert!(re >= least, "{name}: {re} photons re-emitted");
    }
}

#[test]
fn every_process_scene_matches_the_cpu_twin_photon_by_photon() {
    let path = repo("tests/data/photons/every_process.gdml");
    twin("every_process point", path.clone(), "point:0,0,0", 3000, 50);
    twin(
        "every_process beam",
        path,
        "beam:-90,0,5:1,0,0:20:10",
        2000,
        20,
    );
}

#[test]
fn raindrop_matches_the_cpu_twin_photon_by_photon() {
    let path = repo("../shared/gdml/eic-opticks/opticks_raindrop.gdml");
    twin("raindrop point", path.clone(), "point:0,0,70", 3000, 500);
    twin("raindrop sphere", path, "sphere:0,0,0:40:in", 2000, 500);
}

#[test]
fn sipm_matches_the_cpu_twin_photon_by_photon() {
    let path = repo("../shared/gdml/eic-opticks/8x8SiPM_w_CSI_optial_grease.gdml");
    twin("sipm point", path, "point:0.1,0.1,4", 1500, 200);
}

/// Rough and painted surfaces (glisur and unified, every plain finish, on
/// dielectric_dielectric and dielectric_metal): one beam per slab of
/// `rough_surfaces.gdml`, as the Geant4 oracle test shines them; the shell around the slabs
/// detects every photon that leaves.
#[test]
fn rough_and_painted_surfaces_match_the_cpu_twin_photon_by_photon() {
    let path = repo("tests/data/photons/rough_surfaces.gdml");
    for (name, source) in [
        ("unified ground glass", "beam:-265,0,50:0.5,0,-1:5"),
        (
            "unified ground glass at 60 degrees",
            "beam:-266,0,20:1.732,0,-1:5",
        ),
        ("unified ground metal", "beam:-185,0,50:0.5,0,-1:5"),
        ("glisur ground glass", "beam:-105,0,50:0.5,0,-1:5"),
        (
            "glisur ground glass at 60 degrees",
            "beam:-167,0,50:1.732,0,-1:5",
        ),
        ("ground front-painted glass", "beam:-25,0,50:0.5,0,-1:5"),
        ("polished back-painted glass", "beam:55,0,50:0.5,0,-1:5"),
        ("ground back-painted glass", "beam:135,0,50:0.5,0,-1:5"),
        ("glisur ground metal", "beam:215,0,50:0.5,0,-1:5"),
    ] {
        twin(name, path.clone(), source, 1000, 500);
    }
}

/// Runs `hytrace photons SCENE --source SOURCE -n N` on `backend` with `--history`,
/// `--stats` and `extra` into `dir`: the command's output and the paths of its hits and
/// histories.
fn photons_command(
    dir: &Path,
    scene: &Path,
    source: &str,
    n: u64,
    backend: &str,
    extra: &[&str],
) -> (std::process::Output, PathBuf, PathBuf) {
    let out = dir.join(format!("{backend}.npy"));
    let history = dir.join(format!("{backend}-history.npy"));
    let (n, history_arg) = (n.to_string(), format!("--history={}", history.display()));
    let mut args = vec![
        "photons",
        scene.to_str().unwrap(),
        "--source",
        source,
        "-n",
        &n,
        "-o",
        out.to_str().unwrap(),
        &history_arg,
        "--top",
        "0",
        "--backend",
        backend,
        "--stats",
    ];
    args.extend(extra);
    let o = hytrace(&args, &[]);
    (o, out, history)
}

/// The packed histories of a `--history` file (uint64).
fn packed_histories(p: &Path) -> Vec<u64> {
    let h = std::fs::read(p).unwrap();
    assert!(String::from_utf8_lossy(&h[..128]).contains("<u8"));
    h[128..]
        .chunks_exact(8)
        .map(|b| u64::from_le_bytes(b.try_into().unwrap()))
        .collect()
}

/// The `--stats` line that ends a command's stdout.
fn stats_line(o: &std::process::Output) -> serde_json::Value {
    let stdout = String::from_utf8_lossy(&o.stdout).into_owned();
    let line = stdout.lines().last().unwrap_or_default().to_string();
    gpu_stats(&std::process::Output {
        stdout: line.into_bytes(),
        ..o.clone()
    })
}

/// Batches overlap on the GPU (the next one runs while the host handles the last) and the
/// kernel appends its hits in the order photons finish: whatever the batch, a run gives
/// the one-batch run's histories, hit rows and step points exactly, hits in photon order
/// (the points past a photon's end zero, not those of a photon of the batch before).
#[test]
fn gpu_batches_give_the_one_batch_run_with_hits_in_photon_order() {
    let Some(ctx) = GpuContext::for_tests() else {
        return;
    };
    let path = repo("tests/data/photons/every_process.gdml");
    let run = RunOptions {
        records: 3,
        ..options("point:0,0,0", 1000)
    };
    let s32 = scene(&path, Precision::F32);
    let kernel = GpuPhotons::new(&ctx, &s32, &run).unwrap();
    let whole = kernel.propagate(&ctx, &s32, &run, &|_| ()).unwrap().run;
    // Photons ending before their third point: a batch before must not leave its points.
    let short = whole.records.chunks(3).filter(|p| p[2][11] == 0.0).count();
    assert!(short > 10, "{short} photons with fewer than 3 points");
    let photon_order = |hits: &[HitRow]| hits.windows(2).all(|w| w[0].0[13] < w[1].0[13]);
    assert!(whole.hits.len() >= 10, "{} hits", whole.hits.len());
    assert!(photon_order(&whole.hits));
    for batch in [1, 97, 256] {
        let mut all = hytrace_trace::photons::Batch::default();
        let mut sizes = Vec::new();
        let (summary, _, host) = kernel
            .propagate_into(
                &ctx,
                &s32,
                &run,
                Some(batch),
                &mut |b| {
                    sizes.push(b.histories.len());
                    all.gather(b)
                },
                &|_| (),
            )
            .unwrap();
        assert_eq!(host.batch, batch);
        assert_eq!(
            sizes.len() as u64,
            1000_u64.div_ceil(batch),
            "batch {batch}"
        );
        assert_eq!(all.histories, whole.histories, "batch {batch}");
        assert_eq!(all.hits, whole.hits, "batch {batch}");
        assert_eq!(all.records, whole.records, "batch {batch}");
        assert_eq!(summary.counts, whole.counts, "batch {batch}");
        assert_eq!(summary.hits as usize, whole.hits.len());
    }
}

#[test]
fn the_command_runs_photons_on_the_gpu_and_writes_what_the_cpu_writes() {
    if GpuContext::for_tests().is_none() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let scene = repo("tests/data/photons/every_process.gdml");
    let run = |backend| {
        let batch = ["--batch", "128"];
        photons_command(dir.path(), &scene, "point:0,0,0", 500, backend, &batch)
    };
    let (gpu, gpu_hits, gpu_history) = run("gpu");
    let stats = stats_line(&gpu);
    assert_eq!(stats["photons"], 500);
    // Four batches of 128 photons in flight, 88 bytes each on the GPU; the phases of the
    // run are timed apart, so they add up to at most the whole.
    assert_eq!(stats["gpu_batch"], 128);
    assert_eq!(stats["gpu_bytes_per_photon"], 88);
    let phases: f64 = [
        "gpu_upload_s",
        "gpu_kernel_s",
        "gpu_readback_s",
        "gpu_host_s",
        "tally_s",
        "write_s",
    ]
    .iter()
    .map(|k| stats[*k].as_f64().unwrap_or_else(|| panic!("{k}: {stats}")))
    .sum();
    assert!(phases <= stats["propagate_s"].as_f64().unwrap(), "{stats}");
    let (cpu, cpu_hits, cpu_history) = run("cpu");
    assert!(cpu.status.success(), "{}", stderr(&cpu));
    // The same layouts: float64 (H, 16) hits, uint64 (500,) histories, nearly all equal.
    let (g, c) = (
        read_array(&gpu_hits).unwrap(),
        read_array(&cpu_hits).unwrap(),
    );
    assert_eq!((g.scalar, c.scalar), (Scalar::F64, Scalar::F64));
    assert_eq!(g.shape, vec![stats["hits"].as_u64().unwrap(), 16]);
    assert!(
        g.shape[0].abs_diff(c.shape[0]) <= 2,
        "{:?} {:?}",
        g.shape,
        c.shape
    );
    let (hg, hc) = (
        packed_histories(&gpu_history),
        packed_histories(&cpu_history),
    );
    assert_eq!((hg.len(), hc.len()), (500, 500));
    let same = hg.iter().zip(&hc).filter(|(a, b)| a == b).count();
    assert!(same >= 495, "{same} of 500 histories equal");
}

/// Wavelength shifting from the command line (the two plates of
/// `wavelength_shifter.gdml`, as the Geant4 oracle test shines them): one photon per
/// absorption stays on the GPU; an absorption emitting a Poisson number (mean 2) leaves
/// the photon, with all it emitted, to the CPU twin, as `gpu_split_on_cpu` counts; both
/// give the CPU run's histories.
#[test]
fn wavelength_shifting_runs_on_the_gpu_and_gives_the_cpu_histories() {
    if GpuContext::for_tests().is_none() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let scene = repo("tests/data/photons/wavelength_shifter.gdml");
    for (source, split) in [
        ("beam:-80,0,50:0.2,0,-1:10", false),
        ("beam:80,0,50:0.2,0,-1:10", true),
    ] {
        let (gpu, _, gpu_history) = photons_command(dir.path(), &scene, source, 1000, "gpu", &[]);
        let stats = stats_line(&gpu);
        let (cpu, _, cpu_history) = photons_command(dir.path(), &scene, source, 1000, "cpu", &[]);
        assert!(cpu.status.success(), "{source}: {}", stderr(&cpu));
        let (g, c) = (
            packed_histories(&gpu_history),
            packed_histories(&cpu_history),
        );
        assert!(stats["kernel_features"]
            .as_array()
            .unwrap()
            .contains(&"wls".into()));
        let on_cpu = stats["gpu_split_on_cpu"].as_u64().unwrap();
        assert_eq!(
            on_cpu > 0,
            split,
            "{source}: {on_cpu} photons split on the CPU"
        );
        let re = g
            .iter()
            .filter(|&&h| history_string(h).contains("RE"))
            .count();
        let same = g.iter().zip(&c).filter(|(a, b)| a == b).count();
        eprintln!(
            "{source}: {re} re-emitted, {on_cpu} split on the CPU, {same} of 1000 histories equal"
        );
        assert!(re > 100, "{source}: {re} re-emitted");
        assert!(same >= 980, "{source}: {same} of 1000 histories equal");
    }
}

/// A scene of the tank of `media_tank.gdml` with the fog `volume` (its TOML lines) at the
/// origin, written as `name` into `dir`.
fn fog_scene(dir: &Path, name: &str, volume: &str) -> PathBuf {
    let tank = repo("tests/data/photons/media_tank.gdml");
    let path = dir.join(name);
    let text = format!(
        "[gdml.tank]\nfile = {:?}\n\n[volumes.fog]\n{volume}\n\n[[place]]\nsolid = \"fog\"\n",
        tank.display().to_string()
    );
    std::fs::write(&path, text).unwrap();
    path
}

/// Media: the beam through `media_slab.toml`'s scattering fog (one scattering or none for
/// most photons), through a dense, forward-scattering slab (optical depth 8: many
/// scatterings a photon) and through a fog ball (radius 30 mm in 0.5 mm voxels, optical
/// depth 6 to its surface: brick clusters and range-mips blocks only partly filled, so the
/// walk crosses empty and partial blocks) on the GPU, against
/// the f32 twin photon by photon: the kernel tracks the media with the volume module's
/// delta tracking on the photon's own stream, so at least 99.9% of the histories are
/// equal (the rest: an f32 free flight or density against the twin's f64 lands a
/// decision the other way), and their hits agree within 1e-4 relative.
#[test]
fn media_match_the_cpu_twin_photon_by_photon() {
    let dir = tempfile::tempdir().unwrap();
    for (name, path, photons, min_detected) in [
        (
            "media slab",
            repo("tests/data/photons/media_slab.toml"),
            10_000,
            5_000,
        ),
        (
            "dense fog",
            fog_scene(
                dir.path(),
                "dense.toml",
                "source = \"box:200,200,20,1,1\"\ndensity_scale = 0.4\nalbedo = 0.95\ng = 0.85",
            ),
            3_000,
            300,
        ),
        (
            "fog ball",
            fog_scene(
                dir.path(),
                "ball.toml",
                "source = \"sphere:30,0.5,1\"\ndensity_scale = 0.2\nalbedo = 0.9\ng = 0.5",
            ),
            3_000,
            20,
        ),
    ] {
        let run = options("beam:0,0,-150:0,0,1:0", photons);
        let Some((g, twin_same)) = twin_within(name, path, run, min_detected, 0.0) else {
            return;
        };
        assert!(twin_same >= 0.999, "{name}: {twin_same}");
        let scattered = g
            .histories
            .iter()
            .filter(|h| history_string(**h).contains("SC"))
            .count();
        assert!(
            scattered > photons as usize / 20,
            "{name}: {scattered} scattered"
        );
    }
}

/// `--backend gpu` runs a scene with media and `--backend auto` picks the GPU for it: the
/// two give the same histories and hits, which agree with the CPU's f64 run by the
/// fraction of equal histories.
#[test]
fn the_command_runs_media_on_the_gpu_and_auto_picks_it() {
    if GpuContext::for_tests().is_none() {
        return;
    }
    let path = repo("tests/data/photons/media_slab.toml");
    let dir = tempfile::tempdir().unwrap();
    let source = "beam:0,0,-150:0,0,1:0";
    let (gpu, gpu_hits, gpu_history) = photons_command(dir.path(), &path, source, 1000, "gpu", &[]);
    assert!(gpu.status.success(), "{}", stderr(&gpu));
    assert_eq!(stats_line(&gpu)["backend"], "gpu");
    let (auto, auto_hits, auto_history) =
        photons_command(dir.path(), &path, source, 1000, "auto", &[]);
    assert!(auto.status.success(), "{}", stderr(&auto));
    assert!(!stderr(&auto).contains("on the CPU"), "{}", stderr(&auto));
    assert_eq!(
        packed_histories(&auto_history),
        packed_histories(&gpu_history)
    );
    assert_eq!(
        std::fs::read(auto_hits).unwrap(),
        std::fs::read(&gpu_hits).unwrap()
    );
    let (cpu, _, cpu_history) = photons_command(dir.path(), &path, source, 1000, "cpu", &[]);
    assert!(cpu.status.success(), "{}", stderr(&cpu));
    let (a, b) = (
        packed_histories(&gpu_history),
        packed_histories(&cpu_history),
    );
    let same = a.iter().zip(&b).filter(|(x, y)| x == y).count();
    assert!(
        same as f64 >= 0.98 * a.len() as f64,
        "{same} of {}",
        a.len()
    );
}

/// A stored slab larger than the smallest brick pool: 64 x 64 x 2 bricks of density 1 in
/// 0.5 mm voxels (256 x 256 x 8 mm, optical depth 4 across), 8192 bricks kept, more than
/// one superchunk (4096, the pool's least) holds; the beam covers most of it.
const SLAB_SOURCE: &str = "beam:0,0,-150:0,0,1:128";

/// A medium read as stored streams through the kernel's brick pool. With the least budget
/// the pool accepts (one superchunk's bricks) and batches of 1500 photons sharing the pool,
/// the photons touch more bricks than it holds: the run takes several passes, evicts bricks
/// and defers photons, and still gives the
/// histories, hit rows and step points of the run with the whole store resident bit for bit (a deferred
/// photon runs again from its start on its own stream); that run matches the f32 CPU twin
/// photon by photon as the in-core media do ([`twin_within`], through the default 1 GiB
/// pool), and the streamed runs give the same results whatever the budget.
#[test]
fn stored_media_stream_through_a_brick_pool_and_match_the_resident_run() {
    let Some(ctx) = GpuContext::for_tests() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let path = common::stored_slab(dir.path(), [512, 512, 16], 0.5, 0.5);
    let run = RunOptions {
        records: 4,
        ..options(SLAB_SOURCE, 4000)
    };
    let (roomy, twin_same) =
        twin_within("stored slab", path.clone(), run.clone(), 100, 0.0).unwrap();
    assert!(twin_same >= 0.999, "{twin_same}");
    let s32 = scene(&path, Precision::F32);
    let kernel = || GpuPhotons::new(&ctx, &s32, &run).unwrap();
    let least = match kernel().with_memory(1).propagate(&ctx, &s32, &run, &|_| ()) {
        Err(hytrace_trace::Error::Stream(StreamError::Budget { least, .. })) => least,
        other => panic!("a 1-byte budget: {:?}", other.err()),
    };
    let resident = kernel()
        .with_store_resident()
        .propagate(&ctx, &s32, &run, &|_| ())
        .unwrap()
        .run;
    let mut tight = Batch::default();
    let (_, _, host) = kernel()
        .with_memory(least)
        .propagate_into(
            &ctx,
            &s32,
            &run,
            Some(1500),
            &mut |b| tight.gather(b),
            &|_| (),
        )
        .unwrap();
    let stream = host.stream.expect("the run streamed the store");
    eprintln!("stored slab, pool of {least} bytes: {stream:?}");
    assert!(stream.passes >= 3, "{stream:?}");
    assert!(
        stream.bricks_evicted > 0 && stream.deferred > 0,
        "{stream:?}"
    );
    assert!(u64::from(stream.max_slots) < 8192, "{stream:?}");
    let scattered = resident
        .histories
        .iter()
        .filter(|&&h| history_string(h).contains("SC"))
        .count();
    assert!(scattered > 1000, "{scattered} scattered");
    for (name, got) in [
        ("tight pool", &tight.histories),
        ("1 GiB pool", &roomy.histories),
    ] {
        assert!(got == &resident.histories, "{name}: histories differ");
    }
    let bits = |hits: &[HitRow]| -> Vec<[u64; 16]> {
        hits.iter().map(|h| h.0.map(f64::to_bits)).collect()
    };
    assert!(!resident.hits.is_empty());
    assert_eq!(bits(&tight.hits), bits(&resident.hits));
    assert_eq!(bits(&roomy.hits), bits(&resident.hits));
    let points = |r: &[hytrace_trace::photons::output::RecordPoint]| -> Vec<[u32; 12]> {
        r.iter().map(|p| p.map(f32::to_bits)).collect()
    };
    assert_eq!(resident.records.len(), 4 * 4000);
    assert_eq!(points(&tight.records), points(&resident.records));
    assert_eq!(points(&roomy.records), points(&resident.records));
}

/// A streamed run with step points and gensteps: the kernel binds the scene's 14 arrays,
/// the photon group's 12 storage buffers (tables, outputs, step points, gensteps, placed
/// media; its parameters are a uniform buffer) and the brick pool's 6, 32 in all, which a
/// device allowing 32 a stage (lavapipe) runs. A fog of 64^3 voxels of 1 mm read as stored
/// in the scintillator cube, photons from a scintillation and a Cherenkov step crossing
/// it: the GPU matches the f32 CPU twin photon by photon, step points included.
#[test]
fn streamed_runs_with_step_points_and_gensteps_match_the_cpu_twin() {
    let Some(ctx) = GpuContext::for_tests() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let cube = repo("tests/data/photons/scintillator.gdml");
    let path = common::stored_slab_in(dir.path(), &cube, [64; 3], 1.0, 0.03);
    #[rustfmt::skip]
    let rows: [[f64; 14]; 2] = [
        // kind, photons, material, t0, start, end, beta0, beta1, charge, component
        [2.0, 500.0, 1.0, 10.0, -20.0, 0.0, 0.0, 20.0, 0.0, 0.0, 0.5, 0.5, -1.0, 0.0],
        [1.0, 500.0, 1.0, 50.0, 0.0, 0.0, 30.0, 0.0, 0.0, 10.0, 0.99, 0.9, -1.0, 0.0],
    ];
    let file = GenstepFile::from_values("fog.npy".into(), &[2, 14], rows.as_flattened()).unwrap();
    let run = RunOptions {
        origin: Origin::Gensteps(Arc::new(file)),
        photons: 993,
        records: 4,
        ..options("point:0,0,0", 1)
    };
    let s32 = scene(&path, Precision::F32);
    let kernel = GpuPhotons::new(&ctx, &s32, &run).unwrap();
    for feature in ["streamed", "records", "gensteps"] {
        assert!(
            kernel.features().contains(&feature),
            "{:?}",
            kernel.features()
        );
    }
    let (gpu, twin_same) = twin_within("streamed gensteps", path, run, 50, 0.0).unwrap();
    assert!(twin_same >= 0.99, "{twin_same}");
    let scattered = (gpu.histories.iter())
        .filter(|&&h| history_string(h).contains("SC"))
        .count();
    assert!(scattered > 50, "{scattered} scattered in the fog");
}

/// The command streams a medium read as stored on the GPU: `--backend gpu` reports the
/// streaming under `stream` in `--stats`, `--backend auto` picks the GPU (nothing on
/// stderr about the CPU) and writes the same files, `--explain` says where it runs; a
/// `--memory` too small for the pool fails naming the file and the least budget, and a
/// store cut short while the run reads it fails naming its bricks file; neither leaves an
/// output file.
#[test]
fn the_command_streams_stored_media_on_the_gpu_and_auto_picks_it() {
    if GpuContext::for_tests().is_none() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let path = common::stored_medium(dir.path());
    let source = "beam:0,0,-150:0,0,1:0";
    let (gpu, gpu_hits, gpu_history) =
        photons_command(dir.path(), &path, source, 500, "gpu", &["--memory", "64M"]);
    assert!(gpu.status.success(), "{}", stderr(&gpu));
    let stats = stats_line(&gpu);
    assert_eq!(stats["backend"], "gpu");
    assert!(stats["stream"]["passes"].as_u64().unwrap() >= 2, "{stats}");
    assert_eq!(stats["stream"]["bricks_uploaded"], 8, "{stats}");
    let (auto, auto_hits, auto_history) =
        photons_command(dir.path(), &path, source, 500, "auto", &[]);
    assert!(auto.status.success(), "{}", stderr(&auto));
    assert!(!stderr(&auto).contains("on the CPU"), "{}", stderr(&auto));
    assert_eq!(stats_line(&auto)["backend"], "gpu");
    let histories = packed_histories(&gpu_history);
    assert_eq!(packed_histories(&auto_history), histories);
    let absorbed_or_scattered = histories
        .iter()
        .filter(|&&h| history_string(h) != "TO SD")
        .count();
    assert!(absorbed_or_scattered > 50, "{absorbed_or_scattered}");
    assert_eq!(
        std::fs::read(auto_hits).unwrap(),
        std::fs::read(&gpu_hits).unwrap()
    );
    let explain = hytrace(
        &[
            "photons",
            path.to_str().unwrap(),
            "--source",
            source,
            "--explain",
        ],
        &[],
    );
    assert!(
        String::from_utf8_lossy(&explain.stdout).contains("streamed through the GPU's brick pool"),
        "{}",
        String::from_utf8_lossy(&explain.stdout)
    );
    let failed = dir.path().join("failed");
    std::fs::create_dir(&failed).unwrap();
    let (small, hits, _) = photons_command(&failed, &path, source, 500, "gpu", &["--memory", "1K"]);
    assert!(!small.status.success());
    let err = stderr(&small);
    assert!(
        err.contains("stored.toml") && err.contains("give at least") && !err.contains("panicked"),
        "{err}"
    );
    assert!(!hits.exists());
    common::cut_store_short(dir.path());
    let (cut, hits, history) = photons_command(&failed, &path, source, 500, "gpu", &[]);
    assert!(!cut.status.success());
    let err = stderr(&cut);
    assert!(
        err.contains("bricks.bin") && !err.contains("panicked"),
        "{err}"
    );
    assert!(!hits.exists() && !history.exists());
}
