//! `hytrace photons --records K` and streamed outputs, on the every-process scene
//! (`tests/data/photons/every_process.gdml`): the files streamed batch by batch (tiny
//! batches) equal the library's in-memory run; the step points lie where the CPU tracer puts
//! the scene's boundaries, and a detected photon's last point is its hit.

use std::path::{Path, PathBuf};
use std::process::Command;

use hytrace_csg::V3;
use hytrace_foundry::gdml::GdmlOptions;
use hytrace_foundry::layout::Scalar;
use hytrace_foundry::npy::read_array;
use hytrace_trace::cpu::CpuScene;
use hytrace_trace::photons::output::RECORD_COLUMNS;
use hytrace_trace::photons::sources::{Source, Wavelength};
use hytrace_trace::photons::{load_photon_scene, propagate, Origin, PhotonScene, RunOptions};

const K: u32 = 6;
const SOURCE: &str = "point:0,0,-20";

fn scene_path() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/data/photons/every_process.gdml")
}

fn options(photons: u64) -> RunOptions {
    RunOptions {
        origin: Origin::Torch {
            source: Source::parse(SOURCE).unwrap(),
            wavelength: Wavelength::Fixed(420.0),
        },
        photons,
        first: 0,
        seed: 3,
        max_steps: 10_000,
        keep_histories: true,
        records: K,
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
    let (f, surfaces) = load_photon_scene(&scene_path(), &GdmlOptions::default()).unwrap();
    let scene = PhotonScene::new(&f, surfaces).unwrap();
    let run = propagate(&scene, &options(n)).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let (hits, hist, rec) = (
        dir.path().join("hits.npy"),
        dir.path().join("hist.npy"),
        dir.path().join("rec.npy"),
    );
    let scene_arg = scene_path();
    let out = Command::new(env!("CARGO_BIN_EXE_hytrace"))
        .args(["photons", scene_arg.to_str().unwrap(), "--source", SOURCE])
        .args(["-n", &n.to_string(), "--seed", "3", "--batch", "7"])
        .args(["--records", &K.to_string(), "--records-out"])
        .arg(&rec)
        .arg("-o")
        .arg(&hits)
        .arg(format!("--history={}", hist.display()))
        .output()
        .unwrap();
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
    let run = propagate(&scene, &options(n)).unwrap();
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
            let want: Vec<f32> = [0, 1, 2, 3, 4, 5, 6, 8, 9, 10, 7]
                .iter()
                .map(|&c| hit.0[c] as f32)
                .collect();
            assert_eq!(&last[..11], want.as_slice(), "photon {i}");
        }
    }
}
