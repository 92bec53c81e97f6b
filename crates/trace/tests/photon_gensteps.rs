//! Photons in a scintillator cube with a sensor plate
//! (`tests/data/photons/scintillator.gdml`): `hytrace photons --gensteps` from Cherenkov
//! and scintillation steps, end to end, and bad genstep files; re-emission (REEMISSIONPROB)
//! at the rate and with the spectrum the material gives.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use hytrace_foundry::gdml::GdmlOptions;
use hytrace_foundry::layout::Scalar;
use hytrace_foundry::npy::{read_array, write_array};
use hytrace_trace::photons::output::chi2_survival;
use hytrace_trace::photons::properties::HC_EV_NM;
use hytrace_trace::photons::sources::{Source, Wavelength};
use hytrace_trace::photons::{load_photon_scene, propagate, Origin, PhotonScene, RunOptions};

fn scene_path() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/data/photons/scintillator.gdml")
}

fn hytrace(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_hytrace"))
        .args(args)
        .output()
        .unwrap()
}

/// Writes float64 rows of 14 columns as a genstep file.
fn write_gensteps(path: &Path, rows: &[[f64; 14]]) {
    let flat: Vec<f64> = rows.concat();
    write_array(
        path,
        Scalar::F64,
        &[rows.len() as u64, 14],
        bytemuck::cast_slice(&flat),
    )
    .unwrap();
}

/// A scintillation step (material 1, the scintillator) along x at z = 0 from t = 10 ns,
/// and a Cherenkov step of a fast electron down the z axis from t = 50 ns.
const STEPS: [[f64; 14]; 2] = [
    [
        2.0, 3000.0, 1.0, 10.0, -20.0, 0.0, 0.0, 20.0, 0.0, 0.0, 0.5, 0.5, -1.0, 0.0,
    ],
    [
        1.0, 2000.0, 1.0, 50.0, 0.0, 0.0, 60.0, 0.0, 0.0, 20.0, 0.99, 0.98, -1.0, 0.0,
    ],
];

fn hits_of(args: &[&str]) -> (Vec<[f64; 16]>, serde_json::Value) {
    let out = hytrace(args);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stats = serde_json::from_str(stdout.lines().last().unwrap()).unwrap();
    let hits_path = args[args.iter().position(|a| *a == "-o").unwrap() + 1];
    let a = read_array(Path::new(hits_path)).unwrap();
    assert_eq!(a.scalar, Scalar::F64);
    let values: Vec<f64> = bytemuck::pod_collect_to_vec(&a.bytes);
    (
        values
            .chunks_exact(16)
            .map(|r| r.try_into().unwrap())
            .collect(),
        stats,
    )
}

#[test]
fn gensteps_emit_photons_that_reach_the_sensor_after_their_step() {
    let dir = tempfile::tempdir().unwrap();
    let g = dir.path().join("g.npy");
    write_gensteps(&g, &STEPS);
    let hits = dir.path().join("hits.npy");
    let scene = scene_path();
    let (s, h) = (scene.to_str().unwrap(), hits.to_str().unwrap());
    let gs = g.to_str().unwrap();
    let (rows, stats) = hits_of(&["photons", s, "--gensteps", gs, "-o", h, "--stats"]);
    // Every photon of the file, numbered through it.
    assert_eq!(stats["photons"], 5000);
    assert!(rows.len() > 500, "{} hits", rows.len());
    let mut scint_late = 0;
    for r in &rows {
        // On the sensor plate's top face, z = -98, after its step began.
        assert!((r[2] + 98.0).abs() < 1e-6, "{r:?}");
        let photon = r[13] as u64;
        let t0 = if photon < 3000 { 10.0 } else { 50.0 };
        // No earlier than light from the nearest point of the step at c / n_min.
        let nearest = if photon < 3000 { 98.0 } else { 118.0 };
        assert!(r[3] >= t0 + nearest / (299.792458 / 1.48) - 1e-9, "{r:?}");
        // Wavelengths inside the tables (2.0 to 3.6 eV).
        assert!((344.0..620.0).contains(&r[7]), "{r:?}");
        scint_late += usize::from(photon < 3000 && r[3] > 10.0 + 30.0);
    }
    // The 30 ns component shows as a late tail.
    assert!(scint_late > 0);
    // A range of the photons gives exactly those photons' hits of the whole run.
    let part = dir.path().join("part.npy");
    let p = part.to_str().unwrap();
    let (some, stats) = hits_of(&[
        "photons",
        s,
        "--gensteps",
        gs,
        "--first",
        "2500",
        "-n",
        "1000",
        "-o",
        p,
        "--stats",
    ]);
    assert_eq!(stats["photons"], 1000);
    let want: Vec<[f64; 16]> = rows
        .iter()
        .filter(|r| (2500.0..3500.0).contains(&r[13]))
        .copied()
        .collect();
    assert_eq!(some, want);
}

#[test]
fn bad_genstep_files_fail_naming_the_file_and_row_without_output() {
    let dir = tempfile::tempdir().unwrap();
    let hits = dir.path().join("hits.npy");
    let scene = scene_path();
    let (s, h) = (scene.to_str().unwrap(), hits.to_str().unwrap());
    let g = dir.path().join("g.npy");
    let gs = g.to_str().unwrap();
    let mut unknown = STEPS;
    unknown[1][0] = 7.0;
    let mut negative = STEPS;
    negative[0][1] = -5.0;
    let mut material = STEPS;
    material[1][2] = 9.0;
    let mut no_scint = STEPS;
    no_scint[0][2] = 0.0;
    for (rows, needles) in [
        (unknown, vec!["g.npy: row 1", "unknown kind 7"]),
        (negative, vec!["g.npy: row 0", "column 1) is -5"]),
        (material, vec!["g.npy: row 1", "material index 9", "1 LS"]),
        (
            no_scint,
            vec!["g.npy: row 0", "`Vacuum` has no SCINTILLATIONCOMPONENT1"],
        ),
    ] {
        write_gensteps(&g, &rows);
        let out = hytrace(&["photons", s, "--gensteps", gs, "-o", h]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success());
        for n in needles {
            assert!(err.contains(n), "{n}: {err}");
        }
        assert!(!hits.exists());
    }
    // Wrong dtype and shape.
    write_array(&g, Scalar::F32, &[1, 14], &[0u8; 56]).unwrap();
    let flat = [0.0f64; 13];
    let shape13 = dir.path().join("g13.npy");
    write_array(&shape13, Scalar::F64, &[1, 13], bytemuck::cast_slice(&flat)).unwrap();
    for (file, needle) in [
        (gs, "gensteps must be float64, found <f4"),
        (
            shape13.to_str().unwrap(),
            "must have shape (G, 14), found [1, 13]",
        ),
    ] {
        let out = hytrace(&["photons", s, "--gensteps", file, "-o", h]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success() && err.contains(needle), "{err}");
        assert!(!hits.exists());
    }
    // --gensteps with --source, or past its photons.
    write_gensteps(&g, &STEPS);
    for (args, needle) in [
        (vec!["--source", "point:0,0,0"], "cannot be used with"),
        (
            vec!["--first", "6000"],
            "emit 5000 photons, none from --first 6000",
        ),
        (
            vec!["--first", "4000", "-n", "2000"],
            "the gensteps emit 5000 photons",
        ),
    ] {
        let mut all = vec!["photons", s, "--gensteps", gs, "-o", h];
        all.extend(args);
        let out = hytrace(&all);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success() && err.contains(needle), "{err}");
        assert!(!hits.exists());
    }
}

/// The probability that Geant4's draw from an emission table `(eV, intensity)` rows (the
/// trapezoid integral inverted linearly between rows) falls below `e` eV.
fn emission_cdf(rows: &[(f64, f64)], e: f64) -> f64 {
    let mut cumulative = vec![0.0];
    for w in rows.windows(2) {
        let last = cumulative[cumulative.len() - 1];
        cumulative.push(last + 0.5 * (w[1].0 - w[0].0) * (w[0].1 + w[1].1));
    }
    let total = cumulative[cumulative.len() - 1];
    let i = rows.partition_point(|r| r.0 <= e).clamp(1, rows.len() - 1);
    let (e0, e1) = (rows[i - 1].0, rows[i].0);
    let c = cumulative[i - 1]
        + (cumulative[i] - cumulative[i - 1]) * ((e - e0) / (e1 - e0)).clamp(0.0, 1.0);
    c / total
}

#[test]
fn absorbed_photons_are_re_emitted_at_the_rate_and_with_the_spectrum_of_the_scintillator() {
    let (f, surfaces) = load_photon_scene(&scene_path(), &GdmlOptions::default()).unwrap();
    let scene = PhotonScene::new(&f, surfaces).unwrap();
    let run = propagate(
        &scene,
        &RunOptions {
            // 400 nm = 3.1 eV: REEMISSIONPROB 0.5.
            origin: Origin::Torch {
                source: Source::parse("point:0,0,0").unwrap(),
                wavelength: Wavelength::Fixed(400.0),
            },
            photons: 40_000,
            first: 0,
            seed: 9,
            max_steps: 10_000,
            keep_histories: false,
            records: 2,
        },
    )
    .unwrap();
    // The photons whose first step ended in the bulk: absorbed (AB) or re-emitted (RE).
    let (mut absorbed, mut energies) = (0u64, Vec::new());
    for p in run.records.chunks_exact(2) {
        let (a, b) = (&p[0], &p[1]);
        match b[11] as u8 {
            4 => absorbed += 1,
            5 => {
                energies.push(HC_EV_NM / f64::from(b[7]));
                let seg =
                    ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2) + (b[2] - a[2]).powi(2)).sqrt();
                // Delayed: no earlier than the absorbed photon's arrival at c.
                assert!(b[3] >= seg / 299.8 - 1e-6, "{b:?}");
            }
            _ => {}
        }
    }
    let re = energies.len() as f64;
    let n = re + absorbed as f64;
    assert!(n > 4000.0, "{n} absorptions");
    assert!(
        (re / n - 0.5).abs() < 3.0 * (0.25 / n).sqrt(),
        "{re} of {n}"
    );
    // The spectrum: SCINTILLATIONCOMPONENT1 and 2 (yields 0.8, 0.2) between their rows.
    let fast = [(2.0, 0.0), (2.6, 0.3), (2.9, 1.0), (3.2, 0.5), (3.6, 0.0)];
    let slow = [(2.0, 0.0), (2.4, 1.0), (2.8, 0.2), (3.6, 0.0)];
    let edges = [2.0, 2.4, 2.6, 2.8, 2.9, 3.2, 3.6];
    let mix = |e: f64| 0.8 * emission_cdf(&fast, e) + 0.2 * emission_cdf(&slow, e);
    let mut chi2 = 0.0;
    for w in edges.windows(2) {
        let seen = energies.iter().filter(|&&e| e >= w[0] && e < w[1]).count() as f64;
        let want = re * (mix(w[1]) - mix(w[0]));
        chi2 += (seen - want).powi(2) / want;
    }
    let p = chi2_survival(chi2, (edges.len() - 2) as f64);
    assert!(p > 1e-3, "chi2 {chi2}, p {p}");
    // The fast component alone is rejected.
    let mut alone = 0.0;
    for w in edges.windows(2) {
        let seen = energies.iter().filter(|&&e| e >= w[0] && e < w[1]).count() as f64;
        let want = re * (emission_cdf(&fast, w[1]) - emission_cdf(&fast, w[0]));
        alone += (seen - want).powi(2) / want;
    }
    assert!(chi2_survival(alone, (edges.len() - 2) as f64) < 1e-6);
}
