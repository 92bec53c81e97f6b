//! Running the project's Geant4 oracle (`tests/oracle/geant4_oracle.py`) and comparing
//! hytrace's CSG answers with it, ray by ray.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

use hytrace_csg::geant4::{G4Mapping, G4Solid};
use hytrace_csg::{add_geometry, to_tree, PreparedPrim, Ray, Real};
use hytrace_foundry::layout::Scalar;
use hytrace_foundry::npy::read_array;
use hytrace_foundry::{Foundry, Transform64, UNSET};
use hytrace_trace::cpu::CpuScene;
use hytrace_trace::scan::{rays_from_rows, scan, Precision};
use serde::Deserialize;

use crate::f64_array;

/// One oracle run: the solids, rays and Geant4's answers.
pub struct OracleData {
    /// Kind name of each solid.
    pub kinds: Vec<String>,
    /// Geant4 parameters of each solid.
    pub solids: Vec<G4Solid>,
    /// Rays `ox oy oz tmin dx dy dz tmax`.
    pub rays: Vec<[f64; 8]>,
    /// Solid of each ray.
    pub ray_solid: Vec<i32>,
    /// Ray family (0 random, 1 aimed, 2 axis, 3 inside).
    pub ray_family: Vec<i32>,
    /// Non-zero where Geant4 contradicts itself on the ray (its `Inside` along the ray
    /// disagrees with its distance) or warned: no reference there.
    pub ray_flags: Vec<i32>,
    /// Geant4's distance to the next boundary (inf: none) and inside code (0 out, 1 surface,
    /// 2 in).
    pub expected: Vec<[f64; 2]>,
    /// For solids with a tessellated approximation: the origin's distance to the true
    /// surface (an upper bound); NaN otherwise.
    pub origin_distance: Vec<f64>,
    /// The oracle's timing summary.
    pub timing: serde_json::Value,
}

#[derive(Deserialize)]
struct SolidsFile {
    solids: Vec<SolidEntry>,
}

#[derive(Deserialize)]
struct SolidEntry {
    kind: String,
    spec: G4Solid,
}

/// The oracle script's path.
pub fn oracle_script() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("oracle/geant4_oracle.py")
}

fn i32_array(path: &Path) -> Vec<i32> {
    let a = read_array(path).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(a.scalar, Scalar::I32, "{}", path.display());
    bytemuck::pod_collect_to_vec(&a.bytes)
}

/// Runs the oracle with `python` into `dir` and reads what it wrote.
pub fn run_oracle(python: &Path, dir: &Path, args: &[&str]) -> OracleData {
    let out = Command::new(python)
        .arg(oracle_script())
        .arg("--out")
        .arg(dir)
        .args(args)
        .env("GEANT4_DATA_DIR", crate::geant4_data_dir())
        .output()
        .expect("python runs");
    assert!(
        out.status.success(),
        "geant4 oracle failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = std::fs::read_to_string(dir.join("solids.json")).unwrap();
    let file: SolidsFile =
        serde_json::from_str(&text).unwrap_or_else(|e| panic!("solids.json: {e}"));
    let (shape, rays) = f64_array(&dir.join("rays.npy"));
    assert_eq!(shape[1], 8);
    let (_, expected) = f64_array(&dir.join("expected.npy"));
    let timing =
        serde_json::from_str(&std::fs::read_to_string(dir.join("timing.json")).unwrap()).unwrap();
    OracleData {
        kinds: file.solids.iter().map(|s| s.kind.clone()).collect(),
        solids: file.solids.into_iter().map(|s| s.spec).collect(),
        rays: rays
            .chunks_exact(8)
            .map(|c| std::array::from_fn(|k| c[k]))
            .collect(),
        ray_solid: i32_array(&dir.join("ray_solid.npy")),
        ray_family: i32_array(&dir.join("ray_family.npy")),
        ray_flags: i32_array(&dir.join("ray_flags.npy")),
        origin_distance: f64_array(&dir.join("origin_distance.npy")).1,
        expected: expected.chunks_exact(2).map(|c| [c[0], c[1]]).collect(),
        timing,
    }
}

/// Distance within which meshes of solids with no analytic form follow the true surface.
/// Planar triangles approach a twisted face slowly (the deviation falls only as the inverse
/// of the triangle count), so 0.01 mm keeps the oracle's 100-300 mm generic traps with
/// twisted faces at 10^3-10^4 triangles.
pub const TESSELLATION_TOLERANCE: f64 = 1e-2;

/// Kinds whose mesh approximates a curved (twisted) surface: distances agree within the
/// tessellation tolerance over the cosine of incidence rather than the analytic tolerance.
/// (The twisted solids are exact: saddles, hyperboloids and twisted half-spaces.)
pub const APPROXIMATED_KINDS: [&str; 1] = ["genericTrap"];

/// Builds one Foundry solid per Geant4 solid (CSG, or a mesh within
/// [`TESSELLATION_TOLERANCE`]) and prepares each for tracing in `T`.
pub fn prepare<T: Real>(solids: &[G4Solid]) -> Vec<PreparedPrim<T>> {
    let mut f = Foundry::new();
    for (i, s) in solids.iter().enumerate() {
        let geometry = s
            .to_geometry(TESSELLATION_TOLERANCE)
            .unwrap_or_else(|e| panic!("solid {i} {s:?}: {e}"));
        add_geometry(&mut f, &format!("oracle{i}"), &geometry, i as u32)
            .unwrap_or_else(|e| panic!("solid {i}: {e}"));
    }
    f.validate().unwrap();
    (0..solids.len())
        .map(|i| {
            PreparedPrim::from_foundry(&f, i)
                .unwrap()
                .expect("a surface prim")
        })
        .collect()
}

/// hytrace's answer for one oracle ray: the first crossing distance (inf: none), the
/// cosine between the ray and the surface normal there, and whether the ray starts inside
/// by the prim's inside test.
pub fn answer<T: Real>(prim: &PreparedPrim<T>, r: &[f64; 8]) -> (f64, f64, bool) {
    let ray = Ray::from_f64([r[0], r[1], r[2]], [r[4], r[5], r[6]]);
    let step = prim.first_crossing(&ray, T::from_f64(r[3]));
    let cos = step
        .normal
        .normalized()
        .dot(ray.direction.normalized())
        .abs();
    (step.t.to_f64(), cos.to_f64(), prim.contains(ray.origin))
}

/// The agreement tolerance of the CSG issue: `max(1e-4 mm, 2e-6 (|origin| + t))`.
pub fn tolerance(r: &[f64; 8], t: f64) -> f64 {
    let o = (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt();
    (2e-6 * (o + t)).max(1e-4)
}

/// Disagreements described per kind by the random-solid comparisons.
const MAX_EXAMPLES: usize = 5;

/// Agreement counts of one kind of solid.
#[derive(Clone, Debug, Default)]
pub struct KindStats {
    /// Rays compared (origins on a surface excluded).
    pub rays: usize,
    /// Rays without a reference: Geant4 contradicted itself there.
    pub flagged: usize,
    /// Rays of approximated kinds whose origin lies within the tessellation band of the
    /// true surface (where inside and outside legitimately differ).
    pub in_band: usize,
    /// Rays whose distance agrees within [`tolerance`].
    pub distance_ok: usize,
    /// Rays whose inside test agrees with Geant4's `Inside`.
    pub inside_ok: usize,
    /// Disagreements, described (up to a number the comparison sets).
    pub examples: Vec<String>,
    /// The indices of every ray whose distance disagrees.
    pub disagreeing: Vec<usize>,
}

/// Compares hytrace in precision `T` with the oracle's answers, per kind.
pub fn compare<T: Real>(data: &OracleData) -> BTreeMap<String, KindStats> {
    let trees = prepare::<T>(&data.solids);
    compare_rays(
        data,
        &|_, solid, r| {
            let (t, cos, inside) = answer(&trees[solid], r);
            Some((t, cos, Some(inside)))
        },
        &tolerance,
        "",
        MAX_EXAMPLES,
    )
}

/// Like [`compare`], with every solid placed alone in a scene at `offset` (a translation)
/// and traced by the CPU tracer in precision `T` from the oracle's origins moved by
/// `offset` (added in f64, within 1e-10 mm of the exact sum), against Geant4's answers
/// (a translation changes no distance), within `allowed` mm.
pub fn compare_placed<T: Real>(
    data: &OracleData,
    offset: [f64; 3],
    allowed: f64,
) -> BTreeMap<String, KindStats> {
    let scenes: Vec<CpuScene<T>> = data
        .solids
        .iter()
        .enumerate()
        .map(|(i, s)| {
            let geometry = s
                .to_geometry(TESSELLATION_TOLERANCE)
                .unwrap_or_else(|e| panic!("solid {i} {s:?}: {e}"));
            let mut f = Foundry::new();
            let solid = add_geometry(&mut f, "placed", &geometry, 0)
                .unwrap_or_else(|e| panic!("solid {i}: {e}"));
            f.add_instance(solid, Transform64::translation(offset), 0, 0)
                .unwrap();
            f.validate().unwrap();
            CpuScene::new(&f).unwrap_or_else(|e| panic!("solid {i}: {e:#}"))
        })
        .collect();
    let trace = |_: usize, solid: usize, r: &[f64; 8]| {
        let origin = [0, 1, 2].map(|k| r[k] + offset[k]);
        let ray = Ray::from_f64(origin, [r[4], r[5], r[6]]);
        let hit = scenes[solid].trace(&ray, T::from_f64(r[3]), T::INFINITY);
        let t = hit.map_or(f64::INFINITY, |h| h.t.to_f64());
        let cos = hit.map_or(1.0, |h| {
            let n = h.normal.to_f64();
            (n[0] * r[4] + n[1] * r[5] + n[2] * r[6]).abs()
        });
        let inside = scenes[solid].locate_point(origin).is_some();
        Some((t, cos, Some(inside)))
    };
    compare_rays(data, &trace, &|_, _| allowed, "", MAX_EXAMPLES)
}

/// Like [`compare`] for the solids of `kinds` only, each built from its exact CSG
/// expression ([`G4Mapping::to_shape`]) even where [`G4Mapping::to_geometry`] meshes it
/// (G4ExtrudedSolid); the kinds are reported as `KIND (csg)`.
pub fn compare_csg<T: Real>(data: &OracleData, kinds: &[&str]) -> BTreeMap<String, KindStats> {
    let mut f = Foundry::new();
    let mut index = vec![None; data.solids.len()];
    for (i, s) in data.solids.iter().enumerate() {
        if !kinds.contains(&data.kinds[i].as_str()) {
            continue;
        }
        let shape = s
            .to_shape()
            .unwrap_or_else(|e| panic!("solid {i} {s:?}: {e}"));
        let tree = to_tree(&shape).unwrap_or_else(|e| panic!("solid {i}: {e}"));
        let k = f.prim.len() as u32;
        let mut b = f.begin_solid(&format!("oracle{i}"));
        b.add_csg(tree, k, UNSET).unwrap();
        b.finish(k).unwrap();
        index[i] = Some(k as usize);
    }
    f.validate().unwrap();
    let trees: Vec<Option<PreparedPrim<T>>> = index
        .iter()
        .map(|k| {
            k.map(|k| {
                PreparedPrim::from_foundry(&f, k)
                    .unwrap()
                    .expect("a CSG prim")
            })
        })
        .collect();
    let answer = |_: usize, solid: usize, r: &[f64; 8]| {
        trees[solid].as_ref().map(|p| {
            let (t, cos, inside) = answer(p, r);
            (t, cos, Some(inside))
        })
    };
    compare_rays(data, &answer, &tolerance, " (csg)", MAX_EXAMPLES)
}

/// hytrace's answer for one oracle ray: the first crossing distance (inf: none), the cosine
/// of incidence there, and whether the origin is inside (`None`: not compared).
type Answer = (f64, f64, Option<bool>);

/// hytrace's answer for ray `i` (of solid `solid`), or `None` to skip it.
type AnswerFn<'a> = dyn Fn(usize, usize, &[f64; 8]) -> Option<Answer> + 'a;

/// Compares the rays of the solids that `answer(ray index, solid, ray)` answers (`None`:
/// skipped; else distance, cosine of incidence and whether the origin is inside), per kind
/// (the kind's name followed by `suffix`), within `tolerance(ray, geant4's distance)` for
/// exact solids, describing up to `max_examples` disagreements per kind.
fn compare_rays(
    data: &OracleData,
    answer: &AnswerFn,
    tolerance: &dyn Fn(&[f64; 8], f64) -> f64,
    suffix: &str,
    max_examples: usize,
) -> BTreeMap<String, KindStats> {
    let mut stats: BTreeMap<String, KindStats> = BTreeMap::new();
    for (i, r) in data.rays.iter().enumerate() {
        let [want, code] = data.expected[i];
        if code == 1.0 || want.is_nan() {
            continue;
        }
        let solid = data.ray_solid[i] as usize;
        let Some((got, cos, inside)) = answer(i, solid, r) else {
            continue;
        };
        let s = stats
            .entry(format!("{}{suffix}", data.kinds[solid]))
            .or_default();
        if data.ray_flags[i] != 0 {
            s.flagged += 1;
            continue;
        }
        let approximated = APPROXIMATED_KINDS.contains(&data.solids[solid].kind());
        if approximated && data.origin_distance[i] <= 4.0 * TESSELLATION_TOLERANCE {
            s.in_band += 1;
            continue;
        }
        s.rays += 1;
        let ok = if want.is_infinite() {
            got.is_infinite()
        } else {
            let allowed = if approximated {
                tolerance(r, want).max(2.0 * TESSELLATION_TOLERANCE / cos.max(0.05))
            } else {
                tolerance(r, want)
            };
            (got - want).abs() <= allowed
        };
        s.distance_ok += ok as usize;
        s.inside_ok += inside.is_none_or(|inside| inside == (code == 2.0)) as usize;
        if !ok {
            s.disagreeing.push(i);
        }
        if !ok && s.examples.len() < max_examples {
            s.examples.push(format!(
                "ray {i} (family {}) solid {solid}: geant4 {want} ({}), hytrace {got} \
                 (cosine of incidence {cos:.2e}); ray {r:?}",
                data.ray_family[i],
                if code == 2.0 { "inside" } else { "outside" },
            ));
        }
    }
    stats
}

/// The case file of Geant4's own solid unit tests (see its `about`).
pub fn unit_cases_path() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("data/geant4_unit_cases.json")
}

#[derive(Deserialize)]
struct UnitCaseFile {
    families: Vec<UnitFamily>,
}

/// One family of the unit-test case file: the solids and rays of one Geant4 test source.
#[derive(Deserialize)]
pub struct UnitFamily {
    /// The Geant4 test it came from (`testG4Tubs`).
    pub family: String,
    /// Its path and commit in Geant4's repository.
    pub source: String,
    /// The solids, in the oracle's JSON form.
    pub solids: Vec<G4Solid>,
    /// `[solid, ox, oy, oz, dx, dy, dz]`.
    pub rays: Vec<[f64; 7]>,
}

/// Why the navigator's step is not the reference of a unit-test ray.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Contradiction {
    /// The step contradicts Geant4's own `Inside()` along the ray; the reference is the
    /// boundary `Inside()` shows.
    Inside,
    /// Geant4's `Inside()` calls the origin surface, but an exact computation puts it
    /// outside a phi plane by more than 1e-9 mm (within Geant4's angular tolerance), and
    /// the ray enters there; the reference is that entry.
    PhiTolerance,
}

/// Geant4's answers for the unit-test cases.
pub struct UnitOracle {
    /// The cases as oracle data: one kind per family, ray flags 0, and as expected the
    /// navigator's step, or where Geant4 contradicts itself the second judge's.
    pub data: OracleData,
    /// The rays where the navigator's step is not the reference: `(ray, navigator's step,
    /// the reference, why)`.
    pub contradicted: Vec<(usize, f64, f64, Contradiction)>,
    /// The families in file order with their ray ranges.
    pub families: Vec<(String, std::ops::Range<usize>)>,
}

/// The oracle's flag where the navigator's step contradicts `Inside()`.
const FLAG_INCONSISTENT: i32 = 2;
/// The oracle's flag where the origin is within Geant4's angular tolerance of a phi plane.
const FLAG_TOLERANCE: i32 = 16;

/// Runs the oracle's `--cases` mode on the unit-test case file into `dir`: Geant4's
/// navigator (a fresh locate at the origin with the ray's direction, so that a surface
/// origin is in the solid when the ray enters it; after a zero step, the relocation across
/// the boundary G4Transportation makes and the next step), checked against the solid's
/// `Inside()` along the ray; where they contradict each other, the boundary `Inside()`
/// finds (bisected) is the reference, and where the origin is within Geant4's angular
/// tolerance of a phi plane but outside it exactly, the exact entry is.
pub fn run_unit_oracle(python: &Path, dir: &Path) -> UnitOracle {
    let cases = unit_cases_path();
    let out = Command::new(python)
        .arg(oracle_script())
        .arg("--out")
        .arg(dir)
        .arg("--cases")
        .arg(&cases)
        .env("GEANT4_DATA_DIR", crate::geant4_data_dir())
        .output()
        .expect("python runs");
    assert!(
        out.status.success(),
        "geant4 oracle --cases failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let file: UnitCaseFile = serde_json::from_str(&std::fs::read_to_string(&cases).unwrap())
        .unwrap_or_else(|e| panic!("{}: {e}", cases.display()));
    let (shape, expected) = f64_array(&dir.join("unit_expected.npy"));
    assert_eq!(shape[1], 4);
    let flags = i32_array(&dir.join("unit_flags.npy"));
    let mut data = OracleData {
        kinds: Vec::new(),
        solids: Vec::new(),
        rays: Vec::new(),
        ray_solid: Vec::new(),
        ray_family: Vec::new(),
        ray_flags: Vec::new(),
        expected: Vec::new(),
        origin_distance: Vec::new(),
        timing: serde_json::Value::Null,
    };
    let (mut contradicted, mut families) = (Vec::new(), Vec::new());
    for fam in file.families {
        let first_solid = data.solids.len();
        let first_ray = data.rays.len();
        for s in fam.solids {
            data.kinds.push(fam.family.clone());
            data.solids.push(s);
        }
        for r in &fam.rays {
            let i = data.rays.len();
            let [step, code, _inside, judge] = std::array::from_fn(|k| expected[4 * i + k]);
            let why = match flags[i] {
                0 => None,
                FLAG_INCONSISTENT => Some(Contradiction::Inside),
                FLAG_TOLERANCE => Some(Contradiction::PhiTolerance),
                f => panic!("ray {i}: unknown oracle flag {f}"),
            };
            let want = match why {
                Some(why) => {
                    contradicted.push((i, step, judge, why));
                    judge
                }
                None => step,
            };
            data.rays
                .push([r[1], r[2], r[3], 0.0, r[4], r[5], r[6], f64::INFINITY]);
            data.ray_solid.push((first_solid + r[0] as usize) as i32);
            data.ray_family.push(0);
            data.ray_flags.push(0);
            data.expected.push([want, code]);
            data.origin_distance.push(f64::NAN);
        }
        families.push((fam.family, first_ray..data.rays.len()));
    }
    assert_eq!(data.rays.len(), shape[0] as usize, "rays against answers");
    UnitOracle {
        data,
        contradicted,
        families,
    }
}

/// Compares hytrace's scans (each solid alone at the origin of its own scene, `scan` in
/// `precision`: in f32 with its f64 fallback, as `hytrace scan` runs) with the oracle's
/// distances, per kind, within [`tolerance`] (meshes of approximated kinds as
/// [`compare`]); the origin's side is not compared (the oracle's code is the navigator's
/// side for the ray, which for a surface origin depends on the direction).
pub fn compare_scanned(data: &OracleData, precision: Precision) -> BTreeMap<String, KindStats> {
    let mut answers: Vec<Option<Answer>> = vec![None; data.rays.len()];
    for (i, s) in data.solids.iter().enumerate() {
        let geometry = s
            .to_geometry(TESSELLATION_TOLERANCE)
            .unwrap_or_else(|e| panic!("solid {i} {s:?}: {e}"));
        let mut f = Foundry::new();
        let solid =
            add_geometry(&mut f, "unit", &geometry, 0).unwrap_or_else(|e| panic!("solid {i}: {e}"));
        f.add_instance(solid, Transform64::IDENTITY, 0, 0).unwrap();
        f.validate().unwrap();
        let rays: Vec<usize> = (0..data.rays.len())
            .filter(|&k| data.ray_solid[k] as usize == i)
            .collect();
        let rows: Vec<[f64; 8]> = rays.iter().map(|&k| data.rays[k]).collect();
        let rows = rays_from_rows(&rows, "unit cases").unwrap();
        let (result, _) = scan(&f, &rows, precision).unwrap_or_else(|e| panic!("{e:#}"));
        for (j, &k) in rays.iter().enumerate() {
            let [nx, ny, nz, t] = result.hits[j];
            let r = &data.rays[k];
            let cos = if t.is_finite() {
                (nx * r[4] + ny * r[5] + nz * r[6]).abs()
            } else {
                1.0
            };
            answers[k] = Some((t, cos, None));
        }
    }
    compare_rays(data, &|i, _, _| answers[i], &tolerance, "", usize::MAX)
}
