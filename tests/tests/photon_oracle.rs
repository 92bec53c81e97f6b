//! `hytrace photons` against Geant4's optical physics (`tests/oracle/optical_oracle.py`:
//! G4OpticalPhysics with absorption, Rayleigh and the boundary process, the same GDML file
//! read by Geant4, the same source): the frequencies of the photons' step histories
//! compared by Opticks' chi2 (histories seen at least 30 times in the two runs together),
//! the detected counts within 3 sigma and the mean hit times within 4 standard errors.
//! Files: the raindrop and 8x8 SiPM files of ../shared/gdml/eic-opticks and our scene with
//! every process of the propagator (tests/data/photons/every_process.gdml).
//! The two programs draw different random numbers, so the comparison is statistical; the
//! seeds are fixed, so the test is deterministic. Where a GPU adapter opens, the GPU
//! photon kernel's run of the same photons is held to the same criteria.

use std::collections::HashMap;
use std::path::Path;
use std::process::Command;

use hytrace_foundry::gdml::GdmlOptions;
use hytrace_tests::gdml::gdml_dir;
use hytrace_tests::{geant4_data_dir, oracle_python};
use hytrace_trace::gpu::{GpuContext, GpuPhotons};
use hytrace_trace::photons::output::compare_histories;
use hytrace_trace::photons::sources::{Source, Wavelength};
use hytrace_trace::photons::tracer::Precision;
use hytrace_trace::photons::{
    load_photon_scene, propagate, Origin, PhotonRun, PhotonScene, RunOptions,
};
use serde::Deserialize;

/// Photons per run of each program.
const PHOTONS: u64 = 4000;
/// Wavelength of the runs with a fixed one, as `--wavelength` takes it (nm).
const WAVELENGTH: &str = "420";
/// Opticks' cut: histories counted at least this often in the two runs together.
const MIN_COUNT: u64 = 30;
/// Smallest acceptable p-value of the history chi2.
const MIN_P_VALUE: f64 = 1e-3;

#[derive(Deserialize)]
struct Geant4Run {
    geant4: String,
    photons: u64,
    detected: u64,
    histories: HashMap<String, u64>,
    hit_times: Vec<f64>,
    hit_positions: Vec<[f64; 3]>,
    hit_wavelengths: Vec<f64>,
}

/// Hit wavelengths as counts per 5 nm bin, named for [`compare_histories`].
fn wavelength_bins(wavelengths: impl Iterator<Item = f64>) -> Vec<(String, u64)> {
    let mut counts: HashMap<String, u64> = HashMap::new();
    for w in wavelengths {
        *counts
            .entry(format!("{} nm", (w / 5.0).floor() * 5.0))
            .or_default() += 1;
    }
    counts.into_iter().collect()
}

/// Where hits landed, as counts per direction bin seen from the origin: 10 bins of the
/// polar angle's cosine by 8 of the azimuth, named for [`compare_histories`].
fn position_bins(positions: impl Iterator<Item = [f64; 3]>) -> Vec<(String, u64)> {
    let mut counts: HashMap<String, u64> = HashMap::new();
    for [x, y, z] in positions {
        let r = (x * x + y * y + z * z).sqrt();
        let c = ((z / r + 1.0) * 5.0).floor().clamp(0.0, 9.0);
        let phi = y.atan2(x) + std::f64::consts::PI;
        let p = (phi / std::f64::consts::TAU * 8.0).floor().clamp(0.0, 7.0);
        *counts
            .entry(format!("cos bin {c}, azimuth bin {p}"))
            .or_default() += 1;
    }
    counts.into_iter().collect()
}

fn geant4(python: &Path, gdml: &Path, source: &str, wavelength: &str) -> Geant4Run {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("oracle/optical_oracle.py");
    let out = Command::new(python)
        .arg(&script)
        .arg(gdml)
        .args(["--source", source, "--wavelength", wavelength])
        .args(["-n", &PHOTONS.to_string(), "--seed", "5"])
        .env("GEANT4_DATA_DIR", geant4_data_dir())
        .output()
        .expect("the optical oracle runs");
    assert!(
        out.status.success(),
        "optical oracle failed on {}:\n{}",
        gdml.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("the oracle's JSON")
}

fn mean_and_error(x: &[f64]) -> (f64, f64) {
    let n = x.len() as f64;
    let mean = x.iter().sum::<f64>() / n;
    let var = x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0);
    (mean, (var / n).sqrt())
}

/// Runs both programs on one file and source at a wavelength given as `--wavelength` takes
/// it (nm or MATERIAL:PROPERTY); returns a failure description, if any.
fn compare_at(python: &Path, file: &str, source: &str, wavelength: &str) -> Option<String> {
    let gdml = match file.strip_prefix("data/") {
        Some(own) => Path::new(env!("CARGO_MANIFEST_DIR")).join("data").join(own),
        None => gdml_dir().join(file),
    };
    let g4 = geant4(python, &gdml, source, wavelength);
    assert!(g4.photons >= PHOTONS, "{} histories", g4.photons);
    let (f, surfaces) = load_photon_scene(&gdml, &GdmlOptions::default()).unwrap();
    let options = RunOptions {
        origin: Origin::Torch {
            source: Source::parse(source).unwrap(),
            wavelength: Wavelength::parse(wavelength).unwrap(),
        },
        photons: PHOTONS,
        first: 0,
        seed: 1,
        max_steps: 100_000,
        keep_histories: false,
        records: 0,
    };
    let scene = PhotonScene::new(&f, surfaces.clone()).unwrap();
    let cpu = propagate(&scene, &options).unwrap();
    let what = format!("{file} {source} {wavelength}");
    let mut problems = judge(&format!("{what} ({})", g4.geant4), &cpu, &g4);
    // The GPU kernel against Geant4 too, where an adapter opens.
    if let Some(ctx) = GpuContext::for_tests() {
        let s32 = PhotonScene::with_precision(&f, surfaces, Precision::F32).unwrap();
        let kernel = GpuPhotons::new(&ctx, &s32, &options).unwrap();
        let gpu = kernel.propagate(&ctx, &s32, &options, &|_| ()).unwrap();
        let found = judge(&format!("{what} (GPU kernel)"), &gpu.run, &g4);
        problems.extend(found.into_iter().map(|p| format!("GPU kernel: {p}")));
    }
    (!problems.is_empty()).then(|| format!("{what}: {}", problems.join("; ")))
}

/// A run against Geant4's: the history frequencies, the detected count, the mean hit time,
/// and where the hits land and at which wavelengths; what disagrees, in words.
fn judge(what: &str, run: &PhotonRun, g4: &Geant4Run) -> Vec<String> {
    let theirs: Vec<(String, u64)> = g4.histories.clone().into_iter().collect();
    let c = compare_histories(&run.counts, &theirs, MIN_COUNT);
    let (a, b) = (run.hits.len() as f64, g4.detected as f64);
    let sigma = (a + b).sqrt();
    let times: Vec<f64> = run.hits.iter().map(|h| h.0[3]).collect();
    let ((ta, ea), (tb, eb)) = (mean_and_error(&times), mean_and_error(&g4.hit_times));
    let time_sigmas = (ta - tb).abs() / (ea * ea + eb * eb).sqrt();
    let ours_at = position_bins(run.hits.iter().map(|h| [h.0[0], h.0[1], h.0[2]]));
    let theirs_at = position_bins(g4.hit_positions.iter().copied());
    let at = compare_histories(&ours_at, &theirs_at, MIN_COUNT);
    let ours_nm = wavelength_bins(run.hits.iter().map(|h| h.0[7]));
    let nm = compare_histories(
        &ours_nm,
        &wavelength_bins(g4.hit_wavelengths.iter().copied()),
        MIN_COUNT,
    );
    eprintln!(
        "{what}: chi2/ndf {:.2}/{} = {:.3}, p {:.3}; detected {} vs Geant4 {} ({:.2} sigma); mean hit time {ta:.5} vs {tb:.5} ns ({time_sigmas:.2} standard errors); hit directions chi2/ndf {:.2}/{}, p {:.3}; hit wavelengths chi2/ndf {:.2}/{}, p {:.3}",
        c.chi2,
        c.ndf,
        c.chi2 / c.ndf.max(1) as f64,
        c.p_value,
        a,
        b,
        (a - b).abs() / sigma,
        at.chi2,
        at.ndf,
        at.p_value,
        nm.chi2,
        nm.ndf,
        nm.p_value
    );
    for (h, x, y) in c.rows.iter().take(5) {
        eprintln!("    {x:>6} {y:>6}  {h}");
    }
    let mut problems = Vec::new();
    if c.ndf < 2 {
        problems.push(format!("only {} histories to compare", c.ndf));
    }
    if c.p_value < MIN_P_VALUE {
        problems.push(format!("history chi2 p-value {:.2e}", c.p_value));
    }
    if (a - b).abs() > 3.0 * sigma {
        problems.push(format!("detected {a} vs {b}"));
    }
    if at.ndf > 0 && at.p_value < MIN_P_VALUE {
        problems.push(format!("hit direction chi2 p-value {:.2e}", at.p_value));
    }
    if nm.ndf > 1 && nm.p_value < MIN_P_VALUE {
        problems.push(format!("hit wavelength chi2 p-value {:.2e}", nm.p_value));
    }
    if time_sigmas > 4.0 {
        problems.push(format!("mean hit time {ta} vs {tb} ns"));
    }
    problems
}

fn all_agree(cases: &[(&str, &str, &str)]) {
    let Some(python) = oracle_python(&["geant4_pybind", "numpy"]) else {
        return;
    };
    let failures: Vec<String> = cases
        .iter()
        .filter_map(|(file, source, wavelength)| compare_at(&python, file, source, wavelength))
        .collect();
    assert!(failures.is_empty(), "{failures:#?}");
}

#[test]
fn photon_histories_and_detections_agree_with_geant4() {
    let cases = [
        // From the air around the drop: Fresnel and total internal reflection at the air
        // (n 1.1) and lead (n from 1.0 to 1.1 across the table) boundaries, the vacuum
        // world left behind, the drop's border surface (dielectric_metal, REFLECTIVITY 0,
        // EFFICIENCY 1) detecting what leaves the water.
        ("eic-opticks/opticks_raindrop.gdml", "point:0,0,70"),
        // A beam into the drop at an angle: refraction into water, then detection.
        (
            "eic-opticks/opticks_raindrop.gdml",
            "beam:-90,0,60:1,0,-0.4:30",
        ),
        // Inside one CsI pixel: total internal reflection, the pixels' skin surface
        // (dielectric_dielectric, REFLECTIVITY 0.98: 2% absorbed per hit), absorption
        // (400 mm), grease and window, SiPMs detecting (skin, REFLECTIVITY 0, EFFICIENCY
        // 1) and dead areas absorbing 70%.
        (
            "eic-opticks/8x8SiPM_w_CSI_optial_grease.gdml",
            "point:0.1,0.1,4",
        ),
        // Our scene with every process (tests/data/photons): absorption and Rayleigh
        // scattering with tables varying in energy, a glass ball, a sensor
        // (dielectric_metal skin, REFLECTIVITY 0.3, EFFICIENCY 0.8), a mirror border
        // surface (dielectric_metal, REFLECTIVITY 0.9) and a block without RINDEX.
        ("data/photons/every_process.gdml", "point:0,0,0"),
        ("data/photons/every_process.gdml", "beam:-90,0,5:1,0,0:20"),
        // The other sources: a beam diverging 20 degrees into the drop, a sphere in the
        // tank shining inward.
        (
            "eic-opticks/opticks_raindrop.gdml",
            "beam:-90,0,60:1,0,-0.4:30:20",
        ),
        ("data/photons/every_process.gdml", "sphere:0,0,0:90:in"),
    ];
    all_agree(&cases.map(|(file, source)| (file, source, WAVELENGTH)));
}

/// Rough and painted surfaces (Geant4's glisur and unified models, every plain finish):
/// one beam per slab of tests/data/photons/rough_surfaces.gdml, 5 mm wide, from 20-50 mm
/// above at 27 or 60 degrees; a shell around them detects every photon that leaves, so
/// the hit-direction comparison weighs the angular distributions the surfaces send out.
#[test]
fn rough_and_painted_surfaces_agree_with_geant4() {
    let file = "data/photons/rough_surfaces.gdml";
    let cases = [
        // unified, ground glass: spike 0.2, lobe 0.4, backscatter 0.1, Lambertian 0.3
        // (sigma_alpha 0.2), inside and out.
        "beam:-265,0,50:0.5,0,-1:5",
        "beam:-266,0,20:1.732,0,-1:5",
        // unified, ground metal (REFLECTIVITY 0.8, sigma_alpha 0.3).
        "beam:-185,0,50:0.5,0,-1:5",
        // glisur, ground glass (polish 0.7).
        "beam:-105,0,50:0.5,0,-1:5",
        "beam:-167,0,50:1.732,0,-1:5",
        // unified, ground front-painted glass (REFLECTIVITY 0.8: Lambertian paint).
        "beam:-25,0,50:0.5,0,-1:5",
        // unified, polished back-painted glass (gap RINDEX 1.2, REFLECTIVITY 0.9,
        // sigma_alpha 0.1 with spike 0.5 and lobe 0.3 on the gap's boundary).
        "beam:55,0,50:0.5,0,-1:5",
        // unified, ground back-painted glass (gap RINDEX 1.3, REFLECTIVITY 0.85).
        "beam:135,0,50:0.5,0,-1:5",
        // glisur, ground metal (polish 0.5, REFLECTIVITY 0.9).
        "beam:215,0,50:0.5,0,-1:5",
    ];
    all_agree(&cases.map(|source| (file, source, WAVELENGTH)));
}

/// Wavelength shifting (Geant4's OpWLS): a beam into each plate of
/// tests/data/photons/wavelength_shifter.gdml, one re-emitted photon per absorption in the
/// first, a Poisson number (mean 2) in the second; the hit wavelengths compare the
/// re-emission spectrum, the hit times its delay.
#[test]
fn wavelength_shifting_agrees_with_geant4() {
    let file = "data/photons/wavelength_shifter.gdml";
    all_agree(&[
        (file, "beam:-80,0,50:0.2,0,-1:10", WAVELENGTH),
        (file, "beam:80,0,50:0.2,0,-1:10", WAVELENGTH),
    ]);
}

/// Wavelengths drawn from a material's emission spectrum (the liquid's
/// SCINTILLATIONCOMPONENT1 in tests/data/photons/every_process.gdml), through absorption
/// and Rayleigh lengths and a RINDEX that vary with energy: the hit wavelengths weigh the
/// spectrum as the liquid filters it.
#[test]
fn wavelengths_drawn_from_a_spectrum_agree_with_geant4() {
    let (file, spectrum) = (
        "data/photons/every_process.gdml",
        "Liquid:SCINTILLATIONCOMPONENT1",
    );
    all_agree(&[
        (file, "beam:0,0,50:0,0,-1:20", spectrum),
        (file, "point:0,0,0", spectrum),
    ]);
}
