//! `hytrace photons --gensteps`: photons from Cherenkov and scintillation steps through a
//! scintillator cube with a sensor plate, end to end; bad genstep files.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use hytrace_foundry::layout::Scalar;
use hytrace_foundry::npy::{read_array, write_array};

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
