//! Mesh scenes (OBJ and GLB written by trimesh) against Embree's first hits (embreex, robust
//! mode): an icosphere, a block of touching unit boxes (one mesh placed by many glTF
//! nodes), a mesh 1e5 away from the origin and an open random heightfield. Rays agree when
//! both hit or both miss, distances within `max(1e-4, 4e-7 * scale)` (`scale` the size of
//! the coordinates involved). Embree traces in float32 and still misses a few head-on rays
//! at vertices (and reports a few crossings no triangle has), so where it disagrees with
//! hytrace, a float64 brute-force reference computed by NumPy referees: a ray counts as
//! agreeing when hytrace matches that reference and Embree does not. At least 99.99% of
//! the rays of each file must agree after refereeing; every disagreement is printed, and
//! the raw agreement with Embree too.
//!
//! `meshes_in_f32_are_as_accurate_as_embree` holds hytrace's f32 scan (the default) and
//! f64 scan to the float64 reference on the accuracy cases of `mesh_oracle.py` (a lumpy
//! sphere, a torus, boxes 5000 from the origin, the icosphere and the far sphere again) and
//! on every case above: rays from outside and inside, through vertices and edges from any
//! direction, grazing triangles at 1 to 6 degrees. A distance is right when it is within
//! `4e-7 * scale` of the reference (hit against miss is wrong). Rays that moving by that
//! tolerance makes jump (a hit to a miss, or to another surface: rays within rounding of a
//! silhouette edge or vertex, `ill_conditioned` in the script) are counted apart: an f32
//! answer there is right or wrong by the luck of its rounding, Embree's as hytrace's.
//! hytrace's f32 scan may be wrong no more often than Embree's on any file, and its f64
//! scan must be right on every well-conditioned ray. The stricter criterion (no
//! ray where Embree is right and hytrace's f32 wrong, ill-conditioned rays included) is
//! `meshes_in_f32_are_never_wrong_where_embree_is_right`: the f32 triangle test reports
//! the triangles it hit or missed within its rounding, and the scan traces those rays
//! again in f64.
//! `gpu_mesh_scans_give_the_cpu_f32_answers` holds the GPU scan to the CPU's f32 bits on the
//! accuracy cases.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use hytrace_foundry::gdml::GdmlOptions;
use hytrace_tests::{f64_array, oracle_python};
use hytrace_trace::gpu::GpuContext;
use hytrace_trace::scan::{rays_from_rows, scan, scan_with, Backend, Precision};
use hytrace_trace::scene::load_scene;

const CASES: [&str; 4] = ["icosphere", "boxes", "far", "heightfield"];

/// The accuracy cases (`ACCURACY` in `mesh_oracle.py`): meshes and rays that stress the
/// f32 triangle test.
const ACCURACY_CASES: [&str; 5] = ["lumpy", "torus", "boxes5m", "icosphere_acc", "far_acc"];

/// One ray on which hytrace and Embree disagree.
struct Disagreement {
    ray: usize,
    ours: f64,
    embree: f64,
    exact: f64,
    tol: f64,
    /// Whether the float64 reference sides with hytrace (and not with Embree).
    overruled: bool,
}

/// Whether two first-hit distances agree within `tol`.
fn same(a: f64, b: f64, tol: f64) -> bool {
    match (a.is_finite(), b.is_finite()) {
        (true, true) => (a - b).abs() <= tol,
        (false, false) => true,
        _ => false,
    }
}

/// One case's scene file loaded, its rays and the oracle's answers.
struct Loaded {
    foundry: hytrace_foundry::Foundry,
    rays: Vec<hytrace_trace::scan::RayRow>,
    /// Embree's first-hit distances (inf on a miss).
    embree: Vec<f64>,
    /// The float64 reference's.
    exact: Vec<f64>,
    /// Whether each ray is ill-conditioned at the tolerance (`ill_conditioned` in
    /// `mesh_oracle.py`).
    ill: Vec<bool>,
}

/// Loads `CASE.EXT` and the case's rays and answers from the oracle's directory.
fn load(dir: &Path, case: &str, ext: &str) -> Loaded {
    let file = dir.join(format!("{case}.{ext}"));
    let foundry = load_scene(Some(&file), &GdmlOptions::default())
        .unwrap_or_else(|e| panic!("{}: {e:#}", file.display()));
    let (shape, flat) = f64_array(&dir.join(format!("{case}_rays.npy")));
    assert_eq!(shape[1], 8);
    let rows: Vec<[f64; 8]> = flat
        .chunks_exact(8)
        .map(|c| std::array::from_fn(|k| c[k]))
        .collect();
    let rays = rays_from_rows(&rows, case).unwrap();
    let (_, embree) = f64_array(&dir.join(format!("{case}_t.npy")));
    let (_, exact) = f64_array(&dir.join(format!("{case}_t_exact.npy")));
    let (_, ill) = f64_array(&dir.join(format!("{case}_ill.npy")));
    Loaded {
        foundry,
        rays,
        embree,
        exact,
        ill: ill.iter().map(|&x| x != 0.0).collect(),
    }
}

/// The size of the coordinates a ray's answer involves: its origin's largest coordinate
/// plus the distance (`t`, capped).
fn scale(origin: [f64; 3], t: f64) -> f64 {
    origin.iter().fold(0.0f64, |a, c| a.max(c.abs())) + t.min(1e9)
}

/// The rays of one scene file and the disagreements with Embree.
fn compare(dir: &Path, case: &str, ext: &str) -> (usize, Vec<Disagreement>) {
    let Loaded {
        foundry,
        rays,
        embree,
        exact,
        ..
    } = load(dir, case, ext);
    let (result, _) = scan(&foundry, &rays, Precision::F64).unwrap();
    let mut bad = Vec::new();
    for (i, (hit, &want)) in result.hits.iter().zip(&embree).enumerate() {
        let got = hit[3];
        let tol = (4e-7 * scale(rays[i].origin, want.min(got))).max(1e-4);
        if !same(got, want, tol) {
            bad.push(Disagreement {
                ray: i,
                ours: got,
                embree: want,
                exact: exact[i],
                tol,
                overruled: same(got, exact[i], tol) && !same(want, exact[i], tol),
            });
        }
    }
    (rays.len(), bad)
}

/// The directory `mesh_oracle.py` wrote its cases to (run once per test binary), or
/// `None` when the oracle environment is missing and not required.
fn oracle_dir() -> Option<&'static Path> {
    static DIR: OnceLock<Option<(tempfile::TempDir, PathBuf)>> = OnceLock::new();
    DIR.get_or_init(|| {
        let python = oracle_python(&["numpy", "trimesh", "embreex"])?;
        let dir = tempfile::tempdir().unwrap();
        let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("oracle/mesh_oracle.py");
        let out = std::process::Command::new(&python)
            .arg(&script)
            .arg(dir.path())
            .output()
            .expect("python runs");
        assert!(
            out.status.success(),
            "mesh_oracle.py failed:\n{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let path = dir.path().to_path_buf();
        Some((dir, path))
    })
    .as_ref()
    .map(|(_, path)| path.as_path())
}

#[test]
fn mesh_scenes_agree_with_embree() {
    let Some(dir) = oracle_dir() else {
        return;
    };
    let mut failed = Vec::new();
    for case in CASES {
        for ext in ["obj", "glb"] {
            let (n, bad) = compare(dir, case, ext);
            let wrong = bad.iter().filter(|d| !d.overruled).count();
            let agreement = 1.0 - wrong as f64 / n as f64;
            eprintln!(
                "{case}.{ext}: {n} rays, {} differ from Embree ({:.4}% agree), {} of them \
                 refereed for hytrace: agreement {:.4}%",
                bad.len(),
                100.0 * (1.0 - bad.len() as f64 / n as f64),
                bad.len() - wrong,
                100.0 * agreement
            );
            for d in &bad {
                eprintln!(
                    "    ray {}: hytrace {} embree {} float64 {} (tolerance {:.1e}){}",
                    d.ray,
                    d.ours,
                    d.embree,
                    d.exact,
                    d.tol,
                    if d.overruled {
                        ""
                    } else if same(d.ours, d.exact, d.tol) {
                        "  unresolved: float64 is within tolerance of both"
                    } else {
                        "  HYTRACE WRONG"
                    }
                );
            }
            if agreement < 0.9999 {
                failed.push(format!("{case}.{ext}"));
            }
        }
    }
    assert!(failed.is_empty(), "below 99.99% agreement: {failed:?}");
}

/// One ray's answers against the float64 reference.
struct Judged {
    ray: usize,
    exact: f64,
    embree: f64,
    f32: f64,
    f64: f64,
    tol: f64,
    ill: bool,
}

impl Judged {
    /// Whether `t` is within the tolerance of the reference.
    fn right(&self, t: f64) -> bool {
        same(t, self.exact, self.tol)
    }

    /// How far `t` is from the reference, in tolerances (infinite for hit against miss).
    fn error(&self, t: f64) -> f64 {
        match (t.is_finite(), self.exact.is_finite()) {
            (true, true) => (t - self.exact).abs() / self.tol,
            (false, false) => 0.0,
            _ => f64::INFINITY,
        }
    }
}

/// Every ray of `CASE.EXT` scanned in f32 and f64 and judged against the reference.
fn judge(dir: &Path, case: &str, ext: &str) -> (Loaded, Vec<Judged>) {
    let l = load(dir, case, ext);
    let (f32_scan, _) = scan(&l.foundry, &l.rays, Precision::F32).unwrap();
    let (f64_scan, _) = scan(&l.foundry, &l.rays, Precision::F64).unwrap();
    let judged = (0..l.rays.len())
        .map(|i| {
            let exact = l.exact[i];
            let (f32, f64) = (f32_scan.hits[i][3], f64_scan.hits[i][3]);
            // The reference's distance, or on a miss the nearest answer's.
            let t = [exact, f64, f32, l.embree[i]]
                .into_iter()
                .find(|t| t.is_finite())
                .unwrap_or(0.0);
            Judged {
                ray: i,
                exact,
                embree: l.embree[i],
                f32,
                f64,
                tol: 4e-7 * scale(l.rays[i].origin, t),
                ill: l.ill[i],
            }
        })
        .collect();
    (l, judged)
}

/// Counts of one file's rays off the float64 reference, and the rays a test fails on.
struct Accuracy {
    /// Rays Embree's f32 answer is wrong on.
    embree_wrong: usize,
    /// Rays hytrace's f32 scan is wrong on.
    f32_wrong: usize,
    /// Well-conditioned rays hytrace's f64 scan is wrong on.
    f64_wrong: usize,
    /// Well-conditioned rays hytrace's f32 scan is wrong on and Embree right.
    worse: usize,
    /// Ill-conditioned rays hytrace's f32 scan is wrong on and Embree right.
    worse_ill: usize,
}

/// Scans every accuracy case and every older case in f32 and f64 and prints, per file,
/// how many rays Embree and hytrace get wrong (ill-conditioned ones apart) and the worst
/// rays and failing ones.
fn accuracy(dir: &Path) -> Vec<(String, Accuracy)> {
    let mut out = Vec::new();
    for case in ACCURACY_CASES.iter().chain(&CASES) {
        for ext in ["obj", "glb"] {
            let (l, judged) = judge(dir, case, ext);
            let count = |f: &dyn Fn(&Judged) -> bool| judged.iter().filter(|j| f(j)).count();
            let worse = |j: &Judged| j.right(j.embree) && !j.right(j.f32);
            let a = Accuracy {
                embree_wrong: count(&|j| !j.right(j.embree)),
                f32_wrong: count(&|j| !j.right(j.f32)),
                f64_wrong: count(&|j| !j.ill && !j.right(j.f64)),
                worse: count(&|j| !j.ill && worse(j)),
                worse_ill: count(&|j| j.ill && worse(j)),
            };
            eprintln!(
                "{case}.{ext}: {} rays ({} ill-conditioned); off the float64 reference by more \
                 than 4e-7 relative: Embree f32 {} ({} ill-conditioned), hytrace f32 {} ({} \
                 ill-conditioned), hytrace f64 {} (+{} ill-conditioned); hytrace f32 wrong \
                 where Embree is right: {} (+{} ill-conditioned)",
                judged.len(),
                count(&|j| j.ill),
                a.embree_wrong,
                count(&|j| j.ill && !j.right(j.embree)),
                a.f32_wrong,
                count(&|j| j.ill && !j.right(j.f32)),
                a.f64_wrong,
                count(&|j| j.ill && !j.right(j.f64)),
                a.worse,
                a.worse_ill,
            );
            let mut worst: Vec<&Judged> = judged.iter().filter(|j| !j.right(j.f32)).collect();
            worst.sort_by(|a, b| b.error(b.f32).total_cmp(&a.error(a.f32)));
            let failing = judged
                .iter()
                .filter(|j| worse(j) || (!j.ill && !j.right(j.f64)));
            for j in worst.iter().copied().take(3).chain(failing) {
                let r = &l.rays[j.ray];
                eprintln!(
                    "    ray {}{} (o {:?} d {:?}): float64 {} embree {} f32 {} \
                     ({:.1} tolerances) f64 {} (tolerance {:.1e})",
                    j.ray,
                    if j.ill { " (ill-conditioned)" } else { "" },
                    r.origin,
                    r.direction,
                    j.exact,
                    j.embree,
                    j.f32,
                    j.error(j.f32),
                    j.f64,
                    j.tol
                );
            }
            out.push((format!("{case}.{ext}"), a));
        }
    }
    out
}

/// hytrace's f32 scan is wrong no more often than Embree's on any file, and its f64 scan
/// is right on every well-conditioned ray.
#[test]
fn meshes_in_f32_are_as_accurate_as_embree() {
    let Some(dir) = oracle_dir() else {
        return;
    };
    let failed: Vec<String> = accuracy(dir)
        .into_iter()
        .filter(|(_, a)| a.f32_wrong > a.embree_wrong || a.f64_wrong > 0)
        .map(|(file, _)| file)
        .collect();
    assert!(
        failed.is_empty(),
        "hytrace f32 wrong more often than Embree, or f64 wrong: {failed:?}"
    );
}

/// Issue 30's acceptance for meshes: no ray on which Embree's f32 answer is within
/// `4e-7 * scale` of the float64 reference and hytrace's f32 answer is not, ill-conditioned
/// rays (within rounding of a silhouette) included. Before the f32 triangle test reported
/// its doubtful decisions (`edge_doubt` in `crates/csg/src/mesh/wide.rs`), this failed on
/// one well-conditioned ray (icosphere_acc ray 4070, 1.8 tolerances off where Embree is 0.5
/// off: a crossing at cosine 0.14 beside a vertex) and about 30 ill-conditioned ones.
#[test]
fn meshes_in_f32_are_never_wrong_where_embree_is_right() {
    let Some(dir) = oracle_dir() else {
        return;
    };
    let failed: Vec<String> = accuracy(dir)
        .into_iter()
        .filter(|(_, a)| a.worse + a.worse_ill > 0)
        .map(|(file, _)| file)
        .collect();
    assert!(
        failed.is_empty(),
        "hytrace f32 wrong where Embree is right: {failed:?}"
    );
}

/// The GPU scan (the WGSL twin of the f32 tracer, and the same f64 redo on the host) gives
/// the CPU's f32 scan bit for bit on the accuracy cases: distances, normals and ids.
#[test]
fn gpu_mesh_scans_give_the_cpu_f32_answers() {
    let Some(dir) = oracle_dir() else {
        return;
    };
    if GpuContext::for_tests().is_none() {
        return;
    }
    for case in ACCURACY_CASES {
        for ext in ["obj", "glb"] {
            let l = load(dir, case, ext);
            let (cpu, _) = scan(&l.foundry, &l.rays, Precision::F32).unwrap();
            let (gpu, _) = scan_with(&l.foundry, &l.rays, Precision::F32, Backend::Gpu).unwrap();
            let differ: Vec<usize> = (0..l.rays.len())
                .filter(|&i| {
                    cpu.ids[i] != gpu.ids[i]
                        || (0..4).any(|k| cpu.hits[i][k].to_bits() != gpu.hits[i][k].to_bits())
                })
                .collect();
            eprintln!(
                "{case}.{ext}: {} rays, {} differ between the GPU and the CPU's f32 scan",
                l.rays.len(),
                differ.len()
            );
            for &i in differ.iter().take(10) {
                eprintln!(
                    "    ray {i}: cpu {:?} {:?} gpu {:?} {:?}",
                    cpu.hits[i], cpu.ids[i], gpu.hits[i], gpu.ids[i]
                );
            }
            assert!(differ.is_empty(), "{case}.{ext}: GPU differs from the CPU");
        }
    }
}
