//! The Geant4 navigation oracle for GDML files (`tests/oracle/gdml_navigator.py`): rays
//! from points spread over every volume, with `G4Navigator::ComputeStep` as the reference.

use std::path::{Path, PathBuf};
use std::process::Command;

use hytrace_testkit::files::{files_with_extension, shared_gdml_files};
use serde::Deserialize;

use crate::f64_array;

/// The shared public GDML files (`HYTRACE_GDML_DIR`, default `../shared/gdml` beside the
/// repository). Panics when missing: the oracle tests must not pass by finding nothing.
pub use hytrace_testkit::files::shared_gdml_dir as gdml_dir;

/// Every `.gdml` file under [`gdml_dir`], sorted, then the project's own files of
/// `tests/data/gdml` (features the public files do not use).
pub fn gdml_files() -> Vec<PathBuf> {
    let mut files = shared_gdml_files();
    files.extend(files_with_extension(
        &Path::new(env!("CARGO_MANIFEST_DIR")).join("data/gdml"),
        "gdml",
    ));
    files
}

/// The oracle script.
pub fn navigator_script() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("oracle/gdml_navigator.py")
}

#[derive(Deserialize)]
struct Located {
    touchables: Vec<Touchable>,
    ray_touchable: Vec<usize>,
}

/// A volume instance Geant4 located a ray origin in.
#[derive(Clone, Debug, Deserialize)]
pub struct Touchable {
    /// Physical volume name.
    pub name: String,
    /// Geant4 solid name.
    pub solid: String,
    /// Geant4 solid class (`G4Box`, ...).
    pub solid_type: String,
}

/// What Geant4 answered for one file.
pub struct NavigatorSample {
    /// Rays `ox oy oz 0 dx dy dz inf`.
    pub rays: Vec<[f64; 8]>,
    /// `ComputeStep` of each ray.
    pub steps: Vec<f64>,
    /// The volume each origin lies in.
    pub located: Vec<Touchable>,
    /// Solids Geant4 reported defective while reading (its answers near them are not a
    /// reference).
    pub defective_solids: Vec<String>,
}

/// Runs `sample` on `gdml` into `dir`.
pub fn sample(python: &Path, gdml: &Path, rays: usize, seed: u64, dir: &Path) -> NavigatorSample {
    let out = Command::new(python)
        .arg(navigator_script())
        .arg("sample")
        .arg(gdml)
        .args(["--rays", &rays.to_string(), "--seed", &seed.to_string()])
        .arg("--out")
        .arg(dir)
        .env("GEANT4_DATA_DIR", crate::geant4_data_dir())
        .output()
        .expect("python runs");
    assert!(
        out.status.success(),
        "gdml navigator oracle failed on {}:\n{}",
        gdml.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    let (shape, flat) = f64_array(&dir.join("rays.npy"));
    assert_eq!(shape[1], 8);
    let (_, steps) = f64_array(&dir.join("steps.npy"));
    let located: Located =
        serde_json::from_str(&std::fs::read_to_string(dir.join("located.json")).unwrap()).unwrap();
    let log = std::fs::read_to_string(dir.join("geant4.log")).unwrap_or_default();
    let defective_solids = log
        .lines()
        .filter_map(|l| l.strip_prefix("Defects in solid: "))
        .filter_map(|l| l.split(" - ").next())
        .map(|s| s.trim().to_string())
        .collect();
    NavigatorSample {
        rays: flat
            .chunks_exact(8)
            .map(|c| std::array::from_fn(|k| c[k]))
            .collect(),
        steps,
        located: located
            .ray_touchable
            .iter()
            .map(|&i| located.touchables[i].clone())
            .collect(),
        defective_solids,
    }
}

/// A placement as Geant4 reports it.
#[derive(Clone, Debug, Deserialize)]
pub struct G4Placement {
    /// Physical volume name.
    pub name: String,
    /// Copy number (absent for replicated kinds).
    pub copy: Option<i64>,
    /// `world`, `placement`, `replica`, `division` or `parameterised`.
    pub kind: String,
    /// Logical volume name.
    pub logical: String,
    /// Global rotation, row-major (absent for replicated kinds).
    pub rotation: Option<[f64; 9]>,
    /// Global translation.
    pub translation: Option<[f64; 3]>,
    /// Present for reflected placements.
    pub reflection: Option<serde_json::Value>,
    /// Materials and optical surfaces at this placement's surface (absent for the world).
    pub optics: Option<PlacementOptics>,
}

/// What Geant4 holds for the surface of a placement: its material, its mother's, and the
/// optical surface properties of the border surfaces (out: daughter to mother, in: mother
/// to daughter) and of the skin surfaces of both logical volumes.
#[derive(Clone, Debug, Deserialize)]
pub struct PlacementOptics {
    /// Material of the placed logical volume.
    pub material: Option<String>,
    /// Material of the mother.
    pub mother_material: Option<String>,
    /// Border surface (daughter, mother).
    pub border_out: Option<String>,
    /// Border surface (mother, daughter).
    pub border_in: Option<String>,
    /// Skin surface of the daughter's logical volume.
    pub skin: Option<String>,
    /// Skin surface of the mother's logical volume.
    pub mother_skin: Option<String>,
}

#[derive(Deserialize)]
struct Placements {
    placements: Vec<G4Placement>,
}

/// Runs `placements` on `gdml`.
pub fn placements(python: &Path, gdml: &Path) -> Vec<G4Placement> {
    let out = Command::new(python)
        .arg(navigator_script())
        .arg("placements")
        .arg(gdml)
        .env("GEANT4_DATA_DIR", crate::geant4_data_dir())
        .output()
        .expect("python runs");
    assert!(
        out.status.success(),
        "placements failed on {}:\n{}",
        gdml.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    let p: Placements = serde_json::from_slice(&out.stdout).unwrap();
    p.placements
}

/// Geant4's point location across a distance along a ray.
#[derive(Clone, Copy, Debug, Deserialize)]
pub struct Verdict {
    /// The located volume changes across hytrace's distance.
    pub boundary_at_hytrace: bool,
    /// The located volume changes across Geant4's step.
    pub boundary_at_geant4: bool,
}

impl Verdict {
    /// Whether Geant4's `ComputeStep` contradicts its own point location in hytrace's
    /// favour: it stepped over the boundary hytrace found (which location sees), or
    /// stopped where location sees none before hytrace's.
    pub fn geant4_contradicts_itself(&self, hytrace: f64, geant4: f64) -> bool {
        self.boundary_at_hytrace && (hytrace < geant4 || !self.boundary_at_geant4)
    }
}

#[derive(Deserialize)]
struct Verdicts {
    rays: Vec<Verdict>,
}

/// Runs `adjudicate` on the given rays, hytrace distances and Geant4 steps.
pub fn adjudicate(
    python: &Path,
    gdml: &Path,
    rays: &[[f64; 8]],
    hytrace: &[f64],
    geant4: &[f64],
    dir: &Path,
) -> Vec<Verdict> {
    use hytrace_foundry::layout::Scalar;
    use hytrace_foundry::npy::write_array;
    let write = |name: &str, shape: &[u64], values: &[f64]| {
        let p = dir.join(name);
        write_array(&p, Scalar::F64, shape, bytemuck::cast_slice(values)).unwrap();
        p
    };
    let flat: Vec<f64> = rays.iter().flatten().copied().collect();
    let r = write("adjudicate_rays.npy", &[rays.len() as u64, 8], &flat);
    let a = write("adjudicate_hytrace.npy", &[hytrace.len() as u64], hytrace);
    let s = write("adjudicate_geant4.npy", &[geant4.len() as u64], geant4);
    let out = Command::new(python)
        .arg(navigator_script())
        .arg("adjudicate")
        .arg(gdml)
        .arg("--rays")
        .arg(&r)
        .arg("--answers")
        .arg(&a)
        .arg("--steps")
        .arg(&s)
        .env("GEANT4_DATA_DIR", crate::geant4_data_dir())
        .output()
        .expect("python runs");
    assert!(
        out.status.success(),
        "adjudicate failed on {}:\n{}",
        gdml.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    let v: Verdicts = serde_json::from_slice(&out.stdout).unwrap();
    v.rays
}

/// The direction from the centre to sensor `i` of [`synthetic_pmt_array`]`(n, _)`.
pub fn synthetic_pmt_direction(i: usize, n: usize) -> [f64; 3] {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
    let r = (1.0 - z * z).sqrt();
    let phi = golden * i as f64;
    [r * phi.cos(), r * phi.sin(), z]
}

/// A synthetic detector: `n` placements of one PMT-like volume (a glass bulb: a half
/// sphere on a polycone neck, holding a vacuum volume when `with_inner`) 20 m from the
/// centre on a Fibonacci sphere, each with its own rotation and copy number `i`, written
/// out as explicit `<physvol>` elements.
pub fn synthetic_pmt_array(n: usize, with_inner: bool) -> String {
    let mut physvols = String::with_capacity(n * 260);
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    for i in 0..n {
        let [x, y, z] = synthetic_pmt_direction(i, n);
        let phi = golden * i as f64;
        let theta = z.acos().to_degrees();
        physvols.push_str(&format!(
            "    <physvol name=\"pmt_pv\" copynumber=\"{i}\"><volumeref ref=\"pmt\"/>\
             <position name=\"p{i}\" unit=\"mm\" x=\"{:.6}\" y=\"{:.6}\" z=\"{:.6}\"/>\
             <rotation name=\"r{i}\" unit=\"deg\" x=\"0\" y=\"{theta:.6}\" z=\"{:.6}\"/></physvol>\n",
            20000.0 * x,
            20000.0 * y,
            20000.0 * z,
            phi.to_degrees().rem_euclid(360.0)
        ));
    }
    format!(
        r#"<?xml version="1.0" encoding="UTF-8"?>
<gdml>
  <define/>
  <materials>
    <material name="Water" Z="1"><D value="1.0"/><atom value="1.01"/></material>
    <material name="Glass" Z="14"><D value="2.2"/><atom value="28.09"/></material>
    <material name="Vacuum" Z="1"><D value="1e-25"/><atom value="1.01"/></material>
  </materials>
  <solids>
    <box name="world_box" x="50" y="50" z="50" lunit="m"/>
    <sphere name="bulb" rmax="101.6" starttheta="0" deltatheta="90" deltaphi="360" aunit="deg"/>
    <polycone name="neck" startphi="0" deltaphi="360" aunit="deg">
      <zplane z="-120" rmin="0" rmax="42"/><zplane z="-40" rmin="0" rmax="42"/><zplane z="0" rmin="0" rmax="101.6"/>
    </polycone>
    <union name="pmt_solid"><first ref="bulb"/><second ref="neck"/></union>
    <sphere name="inner" rmax="98" starttheta="0" deltatheta="90" deltaphi="360" aunit="deg"/>
  </solids>
  <structure>
    <volume name="vacuum"><materialref ref="Vacuum"/><solidref ref="inner"/></volume>
    <volume name="pmt"><materialref ref="Glass"/><solidref ref="pmt_solid"/>
      {inner}
    </volume>
    <volume name="world"><materialref ref="Water"/><solidref ref="world_box"/>
{physvols}    </volume>
  </structure>
  <setup name="Default" version="1.0"><world ref="world"/></setup>
</gdml>
"#,
        inner = if with_inner {
            r#"<physvol name="vacuum_pv"><volumeref ref="vacuum"/></physvol>"#
        } else {
            ""
        }
    )
}
