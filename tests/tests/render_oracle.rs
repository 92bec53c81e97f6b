//! Rendering against independent references.
//!
//! - Emission-absorption: a render of the NanoVDB fog fixture (`density_zip.nvdb`) equals,
//!   pixel by pixel within 1e-3, NumPy's quadrature of the same camera rays (rebuilt from
//!   the documented camera convention) over the dense array the fixture was made from
//!   (tests/oracle/render_ea.py).

use std::path::Path;

use hytrace_foundry::gdml::GdmlOptions;
use hytrace_trace::cpu::CpuScene;
use hytrace_trace::render::Renderer;
use hytrace_trace::scene::load_render_scene;

fn data() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("data/nanovdb")
}

/// World position of index point `ijk` under the fixture's map (its README):
/// `0.5 * Rz(30 deg) * ijk + (1.5, -2.25, 3)`.
fn fixture_world(ijk: [f64; 3]) -> [f64; 3] {
    let (s, c) = 30f64.to_radians().sin_cos();
    [
        0.5 * (c * ijk[0] - s * ijk[1]) + 1.5,
        0.5 * (s * ijk[0] + c * ijk[1]) - 2.25,
        0.5 * ijk[2] + 3.0,
    ]
}

/// Renders the fixture in emission-absorption with each march step of `steps` (voxels;
/// `None`: the default) and returns our images and NumPy's, as flat RGB values.
fn ea_images(python: &Path, size: [u32; 2], steps: &[Option<f64>]) -> (Vec<Vec<f32>>, Vec<f64>) {
    let dir = tempfile::tempdir().unwrap();
    // The array covers voxels (-37, -26, -20) + [0, 20)^3: look at its centre.
    let target = fixture_world([-27.5, -16.5, -10.5]);
    let eye = [target[0] + 4.0, target[1] - 26.0, target[2] + 9.0];
    let (scale, fov) = (1.2, 32.0);
    let emission = [1.0, 0.6, 0.3];
    let background = [0.05, 0.1, 0.2];
    let scene = format!(
        r#"
[volumes.fog]
source = "{}"
density_scale = {scale}
emission = {emission:?}

[camera]
eye = {eye:?}
target = {target:?}
fov = {fov}

[[lights]]
kind = "environment"
radiance = {background:?}

[render]
volumes = "emission-absorption"
size = {size:?}
spp = 1
"#,
        data().join("density_zip.nvdb").display()
    );
    let path = dir.path().join("ea.toml");
    std::fs::write(&path, scene).unwrap();
    let (f, mut spec) = load_render_scene(Some(&path), &GdmlOptions::default()).unwrap();
    let cpu = CpuScene::<f32>::new(&f).unwrap();
    let default_step = spec.settings.step;
    let ours = steps
        .iter()
        .map(|step| {
            spec.settings.step = step.unwrap_or(default_step);
            let image = Renderer::new(&cpu, &f, &spec)
                .unwrap()
                .render(&|_| {})
                .unwrap();
            image.pixels.iter().flatten().copied().collect()
        })
        .collect();

    let reference = dir.path().join("reference.npy");
    let params = serde_json::json!({
        "width": size[0], "height": size[1], "eye": eye, "target": target,
        "up": [0.0, 0.0, 1.0], "fov": fov, "scale": scale, "emission": emission,
        "background": background, "step": 0.002,
    });
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("oracle/render_ea.py");
    let out = std::process::Command::new(python)
        .arg(&script)
        .arg(data().join("density.npy"))
        .arg(&reference)
        .arg(params.to_string())
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "render_ea.py failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let (shape, theirs) = hytrace_tests::f64_array(&reference);
    assert_eq!(shape, [size[1] as u64, size[0] as u64, 3]);
    (ours, theirs)
}

/// The largest difference and where.
fn worst(ours: &[f32], theirs: &[f64]) -> (f64, usize) {
    ours.iter()
        .zip(theirs)
        .map(|(a, b)| (*a as f64 - b).abs())
        .enumerate()
        .fold((0.0, 0), |w, (k, e)| if e > w.0 { (e, k) } else { w })
}

#[test]
fn emission_absorption_render_of_a_nanovdb_fog_matches_numpy_quadrature() {
    let Some(python) = hytrace_tests::oracle_python(&["numpy"]) else {
        return;
    };
    let steps = [None, Some(0.5), Some(0.25), Some(0.125), Some(0.0625)];
    let (ours, theirs) = ea_images(&python, [40, 30], &steps);
    // Pixels whose light is mostly the fog's own.
    let lit = theirs.iter().filter(|v| **v > 0.3).count();
    assert!(lit > 100, "the fog should fill much of the image: {lit}");
    let errors: Vec<f64> = ours.iter().map(|o| worst(o, &theirs).0).collect();
    let rms: Vec<f64> = ours
        .iter()
        .map(|o| {
            let sum: f64 = o
                .iter()
                .zip(&theirs)
                .map(|(a, b)| (*a as f64 - b).powi(2))
                .sum();
            (sum / theirs.len() as f64).sqrt()
        })
        .collect();
    let show = |v: &[f64]| v.iter().map(|e| format!("{e:.3e}")).collect::<Vec<_>>();
    eprintln!(
        "march step (voxels): default, 0.5, 0.25, 0.125, 0.0625\nworst pixel error: {:?}\nrms error: {:?}",
        show(&errors),
        show(&rms)
    );
    let (e, k) = worst(&ours[0], &theirs);
    assert!(
        e < 1e-3,
        "default step: pixel channel {k} differs by {e:.3e} (ours {}, NumPy {})",
        ours[0][k],
        theirs[k]
    );
    // Midpoint compositing is second order: from 0.5 to 0.0625 voxels (three halvings) the
    // rms error over pixels falls by about 2^6 (one halving alone moves with where steps
    // fall on cell faces).
    let order = (rms[1] / rms[4]).log2() / 3.0;
    assert!(
        (1.6..2.4).contains(&order),
        "observed order {order:.2} of the march: rms {:?}",
        show(&rms)
    );
}

/// OpenEXR output read back by the OpenEXR Python bindings equals the .npy output of the
/// same image: exactly in float, and as NumPy rounds it to float16 in half; for a render of
/// the default scene and for an image of high dynamic range (1e-6 to 6e4).
#[test]
fn exr_images_read_back_by_openexr_equal_the_npy_output() {
    use hytrace_trace::render::{write_image, ExrPrecision, Image};
    let Some(python) = hytrace_tests::oracle_python(&["OpenEXR", "numpy"]) else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let (f, mut spec) = load_render_scene(None, &GdmlOptions::default()).unwrap();
    spec.settings.size = [24, 16];
    spec.settings.spp = 1;
    let scene = CpuScene::<f32>::new(&f).unwrap();
    let rendered = Renderer::new(&scene, &f, &spec)
        .unwrap()
        .render(&|_| {})
        .unwrap();
    let ramp = Image {
        width: 7,
        height: 3,
        pixels: (0..21)
            .map(|k| {
                let v = 1e-6 * 10f32.powf(k as f32 * 10.7 / 20.0);
                [v, 0.5 * v, 1.0 / (1.0 + v)]
            })
            .collect(),
    };
    let script = r#"
import sys, numpy as np, OpenEXR
npy, flt, hlf = sys.argv[1:4]
ref = np.load(npy)
a = OpenEXR.File(flt).channels()["RGB"].pixels
b = OpenEXR.File(hlf).channels()["RGB"].pixels
assert a.dtype == np.float32 and a.shape == ref.shape, (a.dtype, a.shape, ref.shape)
assert b.dtype == np.float16 and b.shape == ref.shape, (b.dtype, b.shape)
assert np.array_equal(a, ref), np.abs(a - ref).max()
assert np.array_equal(b, ref.astype(np.float16)), np.abs(b.astype(np.float32) - ref).max()
print(ref.shape, float(ref.max()))
"#;
    for (name, image) in [("render", &rendered), ("ramp", &ramp)] {
        let path = |ext: &str| dir.path().join(format!("{name}.{ext}"));
        write_image(image, &path("npy"), ExrPrecision::Float).unwrap();
        write_image(image, &path("exr"), ExrPrecision::Float).unwrap();
        write_image(image, &path("half.exr"), ExrPrecision::Half).unwrap();
        let paths = ["npy", "exr", "half.exr"].map(|e| path(e).to_string_lossy().into_owned());
        let out = hytrace_tests::run_python(&python, script, &paths.each_ref().map(String::as_str));
        eprintln!("{name}: {out}");
    }
}
