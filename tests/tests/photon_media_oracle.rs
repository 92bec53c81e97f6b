//! Photons in a thick scattering medium against an independent Monte Carlo
//! (`tests/oracle/medium_sphere_mc.py`, NumPy alone): from the centre of a sphere of fog
//! of extinction 0.2 per mm, radius 30 mm (optical depth 6 to its surface), albedo 0.9 and
//! Henyey-Greenstein g 0.5, the fraction of photons absorbed in it (after about ten
//! collisions each) agrees within 3 sigma of the two runs' binomial errors together. The
//! photons that leave the fog are detected by a ball around it, so the absorbed ones are
//! the photons without a hit.

use std::path::Path;
use std::process::Command;

use hytrace_foundry::gdml::GdmlOptions;
use hytrace_tests::oracle_python;
use hytrace_trace::photons::sources::{Source, Wavelength};
use hytrace_trace::photons::{load_photon_scene, propagate, Origin, PhotonScene, RunOptions};
use serde::Deserialize;

/// A vacuum world 400 mm wide with a vacuum ball of radius 100 mm at its centre whose skin
/// surface detects every photon crossing it.
const BALL_GDML: &str = r#"<?xml version="1.0" encoding="UTF-8"?>
<gdml>
  <define>
    <matrix name="RINDEX_VACUUM" coldim="2" values="2.0*eV 1.0 3.6*eV 1.0"/>
    <matrix name="REFLECTIVITY_SENSOR" coldim="2" values="2.0*eV 0 3.6*eV 0"/>
    <matrix name="EFFICIENCY_SENSOR" coldim="2" values="2.0*eV 1 3.6*eV 1"/>
  </define>
  <materials>
    <material name="Vacuum" Z="1">
      <D value="1e-25" unit="g/cm3"/>
      <atom value="1.008"/>
      <property name="RINDEX" ref="RINDEX_VACUUM"/>
    </material>
  </materials>
  <solids>
    <box name="WorldBox" x="400" y="400" z="400" lunit="mm"/>
    <orb name="BallSolid" r="100" lunit="mm"/>
    <opticalsurface name="SensorSurface" model="glisur" finish="polished" type="dielectric_metal" value="1">
      <property name="REFLECTIVITY" ref="REFLECTIVITY_SENSOR"/>
      <property name="EFFICIENCY" ref="EFFICIENCY_SENSOR"/>
    </opticalsurface>
  </solids>
  <structure>
    <volume name="Ball">
      <materialref ref="Vacuum"/>
      <solidref ref="BallSolid"/>
    </volume>
    <volume name="World">
      <materialref ref="Vacuum"/>
      <solidref ref="WorldBox"/>
      <physvol name="ball_pv"><volumeref ref="Ball"/></physvol>
    </volume>
    <skinsurface name="BallSkin" surfaceproperty="SensorSurface"><volumeref ref="Ball"/></skinsurface>
  </structure>
  <setup name="Default" version="1.0"><world ref="World"/></setup>
</gdml>
"#;

#[derive(Deserialize)]
struct Oracle {
    photons: u64,
    absorbed: u64,
}

#[test]
fn absorption_in_a_thick_sphere_of_albedo_a_agrees_with_an_independent_monte_carlo() {
    let Some(python) = oracle_python(&["numpy"]) else {
        return;
    };
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = tempfile::tempdir().unwrap();
    let (sigma, albedo, g) = (0.2, 0.9, 0.5);
    // Radius 60 voxels of 0.5 mm, the density blended to 0 over the outer voxel: the
    // optical depth to the surface is that of a uniform sphere of radius 29.75 mm.
    // A vacuum world holding a vacuum ball of radius 100 mm whose skin detects every photon
    // leaving it (so that photons end absorbed or detected, whatever the length of their
    // history, of which 16 labels are kept), and the fog inside the ball.
    let ball = BALL_GDML.to_string();
    std::fs::write(dir.path().join("ball.gdml"), ball).unwrap();
    let scene = format!(
        "[gdml.ball]\nfile = \"ball.gdml\"\n\n[volumes.fog]\nsource = \"sphere:30,0.5,1\"\n\
         density_scale = {sigma}\nalbedo = {albedo}\ng = {g}\n"
    );
    let path = dir.path().join("sphere.toml");
    std::fs::write(&path, scene).unwrap();
    let (f, surfaces) = load_photon_scene(&path, &GdmlOptions::default()).unwrap();
    let scene = PhotonScene::new(&f, surfaces).unwrap();
    let n = 20_000;
    let run = RunOptions {
        origin: Origin::Torch {
            source: Source::parse("point:0,0,0").unwrap(),
            wavelength: Wavelength::Fixed(420.0),
        },
        photons: n,
        first: 0,
        seed: 4,
        max_steps: 10_000,
        keep_histories: true,
        records: 0,
    };
    let ours = propagate(&scene, &run).unwrap();
    // Every photon is absorbed in the fog or detected leaving the ball.
    let absorbed = (n - ours.hits.len() as u64) as f64;
    let out = Command::new(python)
        .arg(root.join("oracle/medium_sphere_mc.py"))
        .args([
            "29.75",
            &sigma.to_string(),
            &albedo.to_string(),
            &g.to_string(),
        ])
        .args(["20000", "11"])
        .output()
        .expect("the NumPy Monte Carlo runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let oracle: Oracle = serde_json::from_slice(&out.stdout).unwrap();
    let (a, b) = (
        absorbed / n as f64,
        oracle.absorbed as f64 / oracle.photons as f64,
    );
    let p = (a + b) / 2.0;
    let sigma_ab = (p * (1.0 - p) * (1.0 / n as f64 + 1.0 / oracle.photons as f64)).sqrt();
    assert!(
        (a - b).abs() < 3.0 * sigma_ab,
        "absorbed fraction {a} (hytrace) against {b} (NumPy), sigma {sigma_ab}"
    );
    // The test can fail: a medium that never scattered would absorb every photon, one of
    // half the albedo far fewer.
    assert!(a > 0.3 && a < 0.95, "{a}");
    eprintln!("absorbed: hytrace {a}, NumPy {b} (sigma {sigma_ab})");
}
