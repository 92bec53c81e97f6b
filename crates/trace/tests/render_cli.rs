//! `hytrace render` from the command line: the README's main command on the embedded
//! default scene, every example scene, `--explain`, and bad input refused with an error
//! that names the file and what is wrong, leaving no image behind.

mod common;

use std::path::Path;

use common::{hytrace, read_png, repo};

fn run_ok(args: &[&str]) -> std::process::Output {
    let out = hytrace(args, &[]);
    assert!(
        out.status.success(),
        "hytrace {args:?} failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

fn run_err(args: &[&str]) -> String {
    let out = hytrace(args, &[]);
    assert!(!out.status.success(), "hytrace {args:?} should fail");
    String::from_utf8_lossy(&out.stderr).into_owned()
}

#[test]
fn default_scene_renders_to_png_and_npy_with_stats() {
    let dir = tempfile::tempdir().unwrap();
    let png_path = dir.path().join("sub/default.png");
    let p = png_path.to_str().unwrap();
    let out = run_ok(&[
        "render", "--size", "48x27", "--spp", "2", "-o", p, "--stats",
    ]);
    let stats: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(stats["backend"], "cpu");
    assert_eq!(stats["volumes"], "multiple-scattering");
    assert_eq!(stats["specular"], true);
    assert!(stats["samples_per_s"].as_f64().unwrap() > 0.0);
    let (w, h, rgb) = read_png(&png_path);
    assert_eq!((w, h), (48, 27));
    // Not a blank image: the scene is lit and has detail.
    let distinct: std::collections::BTreeSet<_> = rgb.chunks(3).collect();
    assert!(distinct.len() > 100, "{} distinct colours", distinct.len());

    let npy = dir.path().join("default.npy");
    run_ok(&[
        "render",
        "default",
        "--size",
        "16x9",
        "--spp",
        "1",
        "-o",
        npy.to_str().unwrap(),
    ]);
    let values = common::read_values(&npy);
    assert_eq!(values.len(), 16 * 9 * 3);
    assert!(values.iter().all(|v| v.is_finite() && *v >= 0.0));
}

#[test]
fn every_example_scene_renders() {
    let dir = tempfile::tempdir().unwrap();
    let mut scenes: Vec<_> = std::fs::read_dir(repo("scenes/render"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    scenes.push(repo("scenes/mixed.toml"));
    scenes.push(repo("scenes/csg-showcase.toml"));
    scenes.sort();
    assert!(scenes.len() >= 6, "{scenes:?}");
    for scene in &scenes {
        let out = dir.path().join("x.png");
        let args = [
            "render",
            scene.to_str().unwrap(),
            "--size",
            "24x16",
            "--spp",
            "1",
            "-o",
            out.to_str().unwrap(),
        ];
        run_ok(&args);
        assert_eq!(read_png(&out).0, 24, "{}", scene.display());
    }
}

#[test]
fn explain_names_only_the_effects_a_scene_calls_for() {
    let text = |out: std::process::Output| String::from_utf8(out.stdout).unwrap();
    let geometry_only = text(run_ok(&[
        "render",
        repo("scenes/csg-showcase.toml").to_str().unwrap(),
        "--explain",
    ]));
    assert!(
        geometry_only.contains("media: no (not compiled in)"),
        "{geometry_only}"
    );
    let default = text(run_ok(&["render", "--explain"]));
    assert!(default.contains("media: multiple scattering"), "{default}");
    assert!(
        default.contains("dielectric surfaces (Fresnel): yes"),
        "{default}"
    );
    let off = text(run_ok(&["render", "--explain", "--volumes", "off"]));
    assert!(off.contains("media: no (not compiled in)"), "{off}");
    let view = text(run_ok(&["render", "--explain", "--view", "boundary"]));
    assert!(view.contains("view boundary: first hits only"), "{view}");
}

#[test]
fn bad_input_is_refused_with_a_clear_error_and_no_image() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("never.png");
    let o = out.to_str().unwrap();
    let write = |name: &str, text: &str| {
        let p = dir.path().join(name);
        std::fs::write(&p, text).unwrap();
        p.to_str().unwrap().to_string()
    };
    let cases = [
        (
            write("unknown.toml", "[solids.a]\nshape = \"sphere(1)\"\nmaterial = \"gold\"\n"),
            "unknown material `gold`",
        ),
        (
            write(
                "albedo.toml",
                "[volumes.f]\nsource = \"sphere:10,1,1\"\ndensity_scale = 1\nalbedo = 2\n",
            ),
            "albedo must be in [0, 1]",
        ),
        (
            write(
                "bright.toml",
                "[solids.a]\nshape = \"sphere(1)\"\nmaterial = \"m\"\n[materials.m]\nkind = \"diffuse\"\ncolour = [1.5, 0, 0]\n",
            ),
            "energy is never created",
        ),
        (
            write(
                "camera.toml",
                "[solids.a]\nshape = \"sphere(1)\"\n[camera]\neye = [0, 0, 5]\ntarget = [0, 0, 0]\n",
            ),
            "parallel to the view direction",
        ),
        (
            write("kind.toml", "[solids.a]\nshape = \"sphere(1)\"\n[[lights]]\nkind = \"laser\"\n"),
            "laser",
        ),
        (write("broken.toml", "[solids.a\nshape = "), "not a valid scene file"),
    ];
    for (scene, why) in &cases {
        let err = run_err(&["render", scene, "--size", "8x8", "-o", o]);
        assert!(err.contains(why), "{scene}: expected `{why}` in:\n{err}");
        let name = Path::new(scene).file_name().unwrap().to_str().unwrap();
        assert!(
            err.contains(name),
            "the error names the file {name}:\n{err}"
        );
        assert!(!out.exists(), "{scene} left an image");
    }
    for (args, why) in [
        (vec!["--size", "0x8"], "WIDTHxHEIGHT"),
        (vec!["--spp", "0"], "spp must be"),
        (vec!["--step=-1"], "step must be"),
        (vec!["--cut", "w=0"], "unknown axis `w`"),
        (vec!["--cut", "0,0,0:1"], "the normal is zero"),
        (
            vec![
                "--cut", "x=0", "--cut", "y=0", "--cut", "z=0", "--cut", "x=1",
            ],
            "at most 3 planes",
        ),
    ] {
        let mut all = vec!["render", "-o", o];
        all.extend(args);
        let err = run_err(&all);
        assert!(err.contains(why), "{all:?}: expected `{why}` in:\n{err}");
        assert!(!out.exists());
    }
    let err = run_err(&["render", "--transparent", "no_such_solid", "-o", o]);
    assert!(
        err.contains("no_such_solid") && err.contains("no solid of that name"),
        "{err}"
    );
    assert!(!out.exists());
    let err = run_err(&["render", "-o", dir.path().join("x.jpg").to_str().unwrap()]);
    assert!(
        err.contains("x.jpg") && err.contains(".npy or .exr"),
        "{err}"
    );
}

/// The help texts: the top level says what the tool does, `scan --help` covers meshes,
/// Embree and the GPU, and `render --help` shows the defaults the library uses for
/// `--size`, `--spp` and `--view`.
#[test]
fn help_texts_say_what_the_tool_does_and_show_the_defaults() {
    let text = |args: &[&str]| String::from_utf8(run_ok(args).stdout).unwrap();
    let top = text(&["--help"]);
    for words in [
        "CSG solids",
        "GDML",
        "meshes",
        "sparse volumes",
        "GPU",
        "render",
        "scan",
    ] {
        assert!(
            top.contains(words),
            "top-level help lacks `{words}`:\n{top}"
        );
    }
    let scan = text(&["scan", "--help"]);
    for words in ["meshes", "Embree", "GPU", "wgpu"] {
        assert!(scan.contains(words), "scan --help lacks `{words}`:\n{scan}");
    }
    let render = text(&["render", "--help"]);
    let d = hytrace_trace::render::spec::RenderSettings::default();
    for default in [
        format!("[default: {}x{}", d.size[0], d.size[1]),
        format!("[default: {},", d.spp),
        format!("[default: {},", d.view),
    ] {
        assert!(
            render.contains(&default),
            "render --help lacks `{default}`:\n{render}"
        );
    }
    assert!(render.contains("--cut <PLANE>") && render.contains("--exr <TYPE>"));
}
