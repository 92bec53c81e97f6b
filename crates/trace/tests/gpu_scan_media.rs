//! `scan --transmittance` on the GPU (the scan kernel for the surfaces, the transmittance
//! kernel for every placed medium) against the CPU with f32 surfaces, ray by ray: the
//! default scene (a fog sphere inside a vessel), the mixed scene (a fog box in an open
//! tank, a mesh, CSG sensors) and a scene of two overlapping, rotated placements of one fog
//! box far from the origin (a ray's second placement draws other streams); sweeps and
//! random rays plus named hard cases (rays missing everything, starting inside the medium,
//! along the axes, with zero direction components, grazing it, on finite segments ending
//! inside it); and the `scan --transmittance --backend gpu|auto` command line.
//!
//! Agreement (every disagreement printed):
//! - `exact`: every ray within [`EXACT_TOL`] (the GPU estimates in f32; the CPU in f64 on
//!   the same index-space segments).
//! - `ratio` (4 samples): at least [`SAME_FRACTION`] of the rays give the same samples
//!   (within [`SAME_TOL`]; the same seed streams), the rest are rays on f32/f64 ties (see
//!   `gpu_volume.rs`), and the means over all rays agree within four standard errors.

mod common;

use std::path::Path;

use common::{hytrace, rays_for, read_f64, repo, unit, Random, Rng};
use hytrace_foundry::gdml::GdmlOptions;
use hytrace_foundry::Foundry;
use hytrace_trace::cpu::media::SceneMedia;
use hytrace_trace::cpu::CpuScene;
use hytrace_trace::gpu::GpuContext;
use hytrace_trace::scan::{
    scan_transmittance, scan_transmittance_on, write_rays, Backend, Precision, RayRow,
};
use hytrace_trace::scene::{default_scene, load_scene, scene_from_toml};
use hytrace_volume::{Estimator, TransmittanceParams};

/// Largest |GPU - CPU| of an exact transmittance.
const EXACT_TOL: f64 = 1e-5;
/// A ratio-tracking estimate counts as the same samples within this.
const SAME_TOL: f64 = 1e-4;
/// Least fraction of rays with the same ratio-tracking samples.
const SAME_FRACTION: f64 = 0.99;

/// Two overlapping placements of one fog box (20 mm voxels), rotated, 1e4 mm out, and a
/// CSG wall behind them.
const TWO_FOGS: &str = r#"
[solids.wall]
shape = "box(20, 1500, 1500)"

[volumes.fog]
source = "box:600,500,400,20,4"
density_scale = 0.002

[[place]]
solid = "wall"
translate = [10700, 5000, 0]

[[place]]
solid = "fog"
translate = [10000, 5000, 0]
rotate = [0, 0, 1, 30]

[[place]]
solid = "fog"
translate = [10250, 5100, 60]
rotate = [1, 1, 0, 45]
"#;

fn ray(origin: [f64; 3], direction: [f64; 3], tmin: f64, tmax: f64) -> RayRow {
    RayRow {
        origin,
        direction: unit(direction),
        tmin,
        tmax,
    }
}

/// Named hard cases around a medium centred at `c` of radius about `r`, in a scene of
/// size about `size`.
fn hard_rays(c: [f64; 3], r: f64, size: f64) -> Vec<(&'static str, RayRow)> {
    let at = |d: [f64; 3]| std::array::from_fn(|k| c[k] + d[k]);
    let inf = f64::INFINITY;
    let mut rays = Vec::new();
    let axes = [
        [1.0, 0.0, 0.0],
        [-1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, -1.0, 0.0],
        [0.0, 0.0, 1.0],
        [0.0, 0.0, -1.0],
    ];
    for d in axes {
        // Far outside, pointing away: misses everything.
        let o = at(d.map(|v| 10.0 * size * v + 0.37 * size));
        rays.push(("misses everything", ray(o, d, 0.0, inf)));
        // From the medium's centre and off it, along the axes.
        rays.push(("inside, along an axis", ray(c, d, 0.0, inf)));
        rays.push((
            "inside off centre, along an axis",
            ray(at([0.13 * r, -0.21 * r, 0.07 * r]), d, 0.0, inf),
        ));
        // Through the medium along an axis, from well outside it.
        let o = at(d.map(|v| -1.5 * r * v));
        rays.push(("through along an axis", ray(o, d, 0.0, inf)));
        // On voxel faces of 20 and 30 mm voxels (multiples of 60 mm off the centre).
        let o = at([60.0 * d[1], 60.0 * d[2], 60.0 * d[0]]);
        rays.push(("inside on voxel faces, along an axis", ray(o, d, 0.0, inf)));
        // Grazing the medium's edge.
        let o = at([-1.5 * r * d[0], r * d[0] + r * d[1], r * d[2]]);
        rays.push(("grazing", ray(o, [d[0] + d[2], d[1], 0.0], 0.0, inf)));
    }
    for d in [
        [1.0, 1.0, 0.0],
        [0.0, -1.0, 1.0],
        [1.0, 0.0, -1.0],
        [0.6, 0.8, 0.0],
        [0.0, 0.6, -0.8],
        [1.0, 1.0, 1.0],
        [-1.0, 2.0, -3.0],
    ] {
        let o = at([-0.3 * r, 0.1 * r, 0.2 * r]);
        rays.push(("inside, zero direction components", ray(o, d, 0.0, inf)));
        rays.push(("inside, ends inside", ray(o, d, 0.0, 0.4 * r)));
        rays.push(("inside, starts later", ray(o, d, 0.25 * r, inf)));
        let o = at(d.map(|v| -2.0 * r * v));
        rays.push(("from outside, finite", ray(o, d, 0.5 * r, 3.0 * r)));
        rays.push(("pointing away", ray(o, d.map(|v| -v), 0.0, inf)));
    }
    rays
}

/// The sweeps and random rays of [`rays_for`], `inside` random rays from points in the
/// medium's box (every other one with a zero direction component) and the hard cases; the
/// name of every ray.
fn scene_rays(f: &Foundry, centre: [f64; 3], radius: f64) -> (Vec<RayRow>, Vec<String>) {
    let mut rays = rays_for(f, 40, 3000);
    let mut names = vec![String::from("sweep or random"); rays.len()];
    let mut rng = Rng(0x3ed1a);
    for i in 0..1000 {
        let o = centre.map(|c| c + radius * (2.0 * rng.uniform() - 1.0));
        let mut d: [f64; 3] = std::array::from_fn(|_| 2.0 * rng.uniform() - 1.0);
        if i % 2 == 0 {
            d[(i / 2) % 3] = 0.0;
        }
        rays.push(ray(o, d, 0.0, f64::INFINITY));
        names.push("random from inside".to_string());
    }
    let b = hytrace_trace::sweep::scene_bounds(f).unwrap();
    let size = (0..3).fold(0.0f64, |a, k| a.max(b[k + 3] - b[k]));
    for (name, r) in hard_rays(centre, radius, size) {
        names.push(name.to_string());
        rays.push(r);
    }
    (rays, names)
}

/// One run's agreement.
#[derive(Debug, Default)]
struct Tally {
    rays: usize,
    same: usize,
    max_diff: f64,
    /// Rays the media attenuate (CPU transmittance below 0.99).
    attenuated: usize,
}

/// The CPU's (f32 surfaces) and the GPU's transmittance of every ray, compared within
/// `tol`; prints every disagreement. Also returns the means and the standard error of the
/// mean of the CPU's values.
fn compare(
    label: &str,
    f: &Foundry,
    rays: &[RayRow],
    names: &[String],
    params: &TransmittanceParams,
    tol: f64,
) -> (Tally, f64, f64, f64) {
    let want = scan_transmittance(f, rays, Precision::F32, params).unwrap();
    let got = scan_transmittance_on(f, rays, Precision::F32, params, Backend::Gpu, 0).unwrap();
    let g = got.gpu.as_ref().expect("ran on the GPU");
    eprintln!(
        "{label}: {} rays, cpu {:.2} s, gpu {:.2} s (kernels {:.3} s) on {}",
        rays.len(),
        want.transmittance_s,
        got.transmittance_s,
        g.times.kernel_s,
        g.adapter
    );
    assert_eq!(want.values.len(), rays.len());
    assert_eq!(got.values.len(), rays.len());
    let mut t = Tally {
        rays: rays.len(),
        ..Default::default()
    };
    for (i, ((w, g), r)) in want.values.iter().zip(&got.values).zip(rays).enumerate() {
        let diff = (w - g).abs();
        if diff <= tol {
            t.same += 1;
            t.max_diff = t.max_diff.max(diff);
        } else {
            println!(
                "{label}: {} ray {i} {r:?}: cpu {w} gpu {g} (|diff| {diff:.3e})",
                names[i]
            );
        }
        t.attenuated += usize::from(*w < 0.99);
        if names[i] == "misses everything" {
            assert!(*w == 1.0 && *g == 1.0, "{label}: ray {i} {r:?}: {w} {g}");
        }
    }
    let n = rays.len() as f64;
    let mean = |v: &[f64]| v.iter().sum::<f64>() / n;
    let (mean_w, mean_g) = (mean(&want.values), mean(&got.values));
    let var = want
        .values
        .iter()
        .map(|w| (w - mean_w).powi(2))
        .sum::<f64>()
        / (n - 1.0);
    eprintln!(
        "{label}: {} of {} rays within {tol:.0e} (max |diff| {:.3e}), {} attenuated, means cpu {mean_w:.6} gpu {mean_g:.6}",
        t.same, t.rays, t.max_diff, t.attenuated
    );
    (t, mean_w, mean_g, (var / n).sqrt())
}

/// Exact: every ray within [`EXACT_TOL`]; ratio tracking: the same samples on at least
/// [`SAME_FRACTION`] of the rays and the means within four standard errors.
fn check_scene(name: &str, f: &Foundry, centre: [f64; 3], radius: f64) {
    if GpuContext::for_tests().is_none() {
        return;
    }
    let (rays, names) = scene_rays(f, centre, radius);
    let exact = TransmittanceParams::new(Estimator::Exact);
    let (t, ..) = compare(
        &format!("{name} exact"),
        f,
        &rays,
        &names,
        &exact,
        EXACT_TOL,
    );
    assert_eq!(t.same, t.rays, "{name} exact: {t:?}");
    assert!(
        t.attenuated * 10 >= t.rays,
        "{name}: too few attenuated rays: {t:?}"
    );
    let ratio = TransmittanceParams {
        spp: 4,
        seed: 11,
        ..TransmittanceParams::new(Estimator::Ratio)
    };
    let label = format!("{name} ratio");
    let (t, mean_w, mean_g, se) = compare(&label, f, &rays, &names, &ratio, SAME_TOL);
    assert!(
        t.same as f64 >= SAME_FRACTION * t.rays as f64,
        "{label}: {t:?}"
    );
    assert!(
        (mean_w - mean_g).abs() <= 4.0 * se + 1e-6,
        "{label}: means {mean_w} {mean_g} (standard error {se})"
    );
}

#[test]
fn gpu_transmittance_matches_cpu_on_the_default_scene() {
    check_scene("default", &default_scene().unwrap(), [0.0; 3], 720.0);
}

#[test]
fn gpu_transmittance_matches_cpu_on_the_mixed_scene() {
    let f = load_scene(Some(&repo("scenes/mixed.toml")), &GdmlOptions::default()).unwrap();
    check_scene("mixed", &f, [0.0, 0.0, 10.0], 350.0);
}

#[test]
fn gpu_transmittance_matches_cpu_on_overlapping_placements_far_out() {
    let f = scene_from_toml(TWO_FOGS, "two fogs", Path::new(".")).unwrap();
    let (centre, radius) = ([10100.0, 5050.0, 30.0], 200.0);
    // Many rays cross both placements (before their tmax): second segments are tested.
    let cpu = CpuScene::<f32>::new(&f).unwrap();
    let media = SceneMedia::new(&cpu, &f, &TransmittanceParams::new(Estimator::Exact)).unwrap();
    let (rays, _) = scene_rays(&f, centre, radius);
    let both = rays
        .iter()
        .filter(|r| {
            let s = media.segments(r.origin, r.direction, r.tmin, r.tmax);
            s.unwrap().len() == 2
        })
        .count();
    eprintln!(
        "two fogs: {both} of {} rays cross both placements",
        rays.len()
    );
    assert!(both >= 500, "{both} rays cross both placements");
    check_scene("two fogs", &f, centre, radius);
}

/// `scan default --sweep circle --transmittance T.npy --backend gpu` writes the hits and
/// transmittances, the latter within [`EXACT_TOL`] of `--backend cpu`'s, with the GPU's
/// seconds in `--stats`, and so do rays from inside the fog (`--rays`); `auto` without an
/// adapter falls back to the CPU's values exactly, `gpu` fails; Embree is refused.
#[test]
fn scan_transmittance_cli_on_the_gpu() {
    if GpuContext::for_tests().is_none() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let p = |n: &str| dir.path().join(n).display().to_string();
    let inside = p("inside.npy");
    let f = default_scene().unwrap();
    let (rays, _) = scene_rays(&f, [0.0; 3], 720.0);
    write_rays(Path::new(&inside), &rays[rays.len() - 1200..]).unwrap();
    let sweep = ["--sweep", "circle", "--count", "50"];
    let scan = |backend: &str, name: &str, source: &[&str], env: &[(&str, &str)]| {
        let (hits, t) = (p(&format!("{name}-hits.npy")), p(&format!("{name}-t.npy")));
        let mut args = vec!["scan", "default"];
        args.extend_from_slice(source);
        args.extend([
            "--out",
            &hits,
            "--transmittance",
            &t,
            "--stats",
            "--backend",
            backend,
        ]);
        let out = hytrace(&args, env);
        (out, hits, t)
    };
    let mut cpu_sweep = Vec::new();
    for (source, name, attenuated) in [
        (&sweep[..], "sweep", false),
        (&["--rays", &inside][..], "inside", true),
    ] {
        let (cpu, cpu_hits, cpu_t) = scan("cpu", &format!("{name}-cpu"), source, &[]);
        assert!(
            cpu.status.success(),
            "{}",
            String::from_utf8_lossy(&cpu.stderr)
        );
        let (gpu, gpu_hits, gpu_t) = scan("gpu", &format!("{name}-gpu"), source, &[]);
        assert!(
            gpu.status.success(),
            "{}",
            String::from_utf8_lossy(&gpu.stderr)
        );
        assert!(Path::new(&gpu_hits).exists() && Path::new(&cpu_hits).exists());
        let stats: serde_json::Value = serde_json::from_slice(&gpu.stdout).unwrap();
        assert_eq!(stats["backend"], "gpu");
        assert!(stats["transmittance_s"].as_f64().is_some());
        assert!(stats["transmittance_gpu_kernel_s"].as_f64().is_some());
        let (want, got) = (read_f64(Path::new(&cpu_t)), read_f64(Path::new(&gpu_t)));
        assert!(!want.is_empty());
        assert_eq!(want.len(), got.len());
        assert_eq!(want.iter().any(|&t| t < 0.99), attenuated, "{name}");
        for (i, (w, g)) in want.iter().zip(&got).enumerate() {
            assert!(
                (w - g).abs() <= EXACT_TOL,
                "{name} ray {i}: cpu {w} gpu {g}"
            );
        }
        if cpu_sweep.is_empty() {
            cpu_sweep = want;
        }
    }

    // No adapter (a backend this build lacks): `auto` scans and attenuates on the CPU.
    let none = [("WGPU_BACKEND", "metal")];
    let (auto, _, auto_t) = scan("auto", "auto", &sweep, &none);
    let err = String::from_utf8_lossy(&auto.stderr);
    assert!(auto.status.success(), "{err}");
    assert!(err.contains("--backend auto scans on the CPU"), "{err}");
    assert_eq!(read_f64(Path::new(&auto_t)), cpu_sweep);
    let (no_gpu, _, no_t) = scan("gpu", "none", &sweep, &none);
    assert!(!no_gpu.status.success());
    assert!(!Path::new(&no_t).exists());

    // Embree finds the surfaces and the brick clusters, the CPU estimates: the CPU's
    // transmittances (a build without Embree says so and writes nothing).
    let (embree, _, embree_t) = scan("embree", "embree", &sweep, &[]);
    let err = String::from_utf8_lossy(&embree.stderr);
    if cfg!(feature = "embree") {
        assert!(embree.status.success(), "{err}");
        assert_eq!(read_f64(Path::new(&embree_t)), cpu_sweep);
    } else {
        assert!(
            !embree.status.success() && err.contains("built without Embree"),
            "{err}"
        );
        assert!(!Path::new(&embree_t).exists());
    }
}
