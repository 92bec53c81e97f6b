//! Transmittance through scene media up to the first surface, against analytic optical
//! depths: fog boxes placed (translated, rotated, far from the origin) in TOML scenes with
//! CSG walls and meshes, every estimator.
//!
//! The fog box `box:200,200,200,10,4` has half extents of 10 voxels of 10 mm and a 4-voxel
//! blend: along a line through its centre parallel to an edge the voxel values are
//! clamp((10 - |i|) / 4, 0, 1), linearly interpolated, so the optical depth across is the
//! trapezoid sum 16 voxels = 160 mm times the density, and up to the centre 80 mm.

use std::path::Path;
use std::process::Command;

use hytrace_foundry::layout::Scalar;
use hytrace_foundry::npy::{read_array, write_array};

use hytrace_trace::cpu::media::SceneMedia;
use hytrace_trace::cpu::CpuScene;
use hytrace_trace::scene::scene_from_toml;
use hytrace_volume::{Estimator, Majorant, TransmittanceParams};

const DENSITY: f64 = 0.005;
/// Optical depth across one fog box through its centre.
const TAU_ACROSS: f64 = 160.0 * DENSITY;

/// A scene of fog boxes at `fogs`, a CSG wall (a thin box, 1000 x 1000 mm, facing x) at
/// `wall`, all rotated by `rotate` degrees about z and then translated by `centre`.
fn scene(centre: [f64; 3], fogs: &[[f64; 3]], wall: [f64; 3], rotate: f64) -> String {
    let mut text = format!(
        "[solids.wall]\nshape = \"box(2, 1000, 1000)\"\n\n\
         [volumes.fog]\nsource = \"box:200,200,200,10,4\"\ndensity_scale = {DENSITY}\n\n\
         [[place]]\nsolid = \"wall\"\ntranslate = {:?}\nrotate = [0, 0, 1, {rotate}]\n",
        place(centre, wall, rotate)
    );
    for fog in fogs {
        text += &format!(
            "\n[[place]]\nsolid = \"fog\"\ntranslate = {:?}\nrotate = [0, 0, 1, {rotate}]\n",
            place(centre, *fog, rotate)
        );
    }
    text
}

/// `p` rotated by `degrees` about z, then moved by `centre`.
fn place(centre: [f64; 3], p: [f64; 3], degrees: f64) -> [f64; 3] {
    let (s, c) = degrees.to_radians().sin_cos();
    [
        centre[0] + c * p[0] - s * p[1],
        centre[1] + s * p[0] + c * p[1],
        centre[2] + p[2],
    ]
}

/// The first crossing and transmittance of the rays from `from` along the scene's rotated
/// x axis with indices `0..count`, in precision `T`.
fn trace_many<T: hytrace_csg::Real>(
    text: &str,
    centre: [f64; 3],
    from: [f64; 3],
    rotate: f64,
    params: &TransmittanceParams,
    count: u32,
) -> Vec<(Option<f64>, f64)> {
    let f = scene_from_toml(text, "test scene", Path::new(".")).unwrap();
    let scene = CpuScene::<T>::new(&f).unwrap();
    let media = SceneMedia::new(&scene, &f, params).unwrap();
    let (s, c) = rotate.to_radians().sin_cos();
    (0..count)
        .map(|i| {
            let r = media
                .trace_transmittance(
                    place(centre, from, rotate),
                    [c, s, 0.0],
                    0.0,
                    f64::INFINITY,
                    i,
                )
                .unwrap();
            (r.hit.map(|h| h.t.to_f64()), r.transmittance)
        })
        .collect()
}

/// [`trace_many`] for one ray.
fn trace<T: hytrace_csg::Real>(
    text: &str,
    centre: [f64; 3],
    from: [f64; 3],
    rotate: f64,
    params: &TransmittanceParams,
) -> (Option<f64>, f64) {
    trace_many::<T>(text, centre, from, rotate, params, 1)[0]
}

#[test]
fn exact_transmittance_through_placed_fog_boxes_is_analytic() {
    let exact = TransmittanceParams::new(Estimator::Exact);
    for (centre, rotate) in [
        ([0.0; 3], 0.0),
        ([3e3, -2e3, 5e2], 90.0),
        ([1e3, 2e3, 0.0], 33.0),
    ] {
        // Two fog boxes, then the wall: both boxes count.
        let text = scene(
            centre,
            &[[0.0; 3], [400.0, 0.0, 0.0]],
            [800.0, 0.0, 0.0],
            rotate,
        );
        let (hit, tr) = trace::<f64>(&text, centre, [-500.0, 0.0, 0.0], rotate, &exact);
        assert!((hit.unwrap() - 1299.0).abs() < 1e-6, "hit {hit:?}");
        let want = (-2.0 * TAU_ACROSS).exp();
        assert!(
            (tr - want).abs() < 1e-9,
            "centre {centre:?}: {tr} vs {want}"
        );
        // The wall through the first box's centre: half of it, and not the second box.
        let text = scene(
            centre,
            &[[0.0; 3], [400.0, 0.0, 0.0]],
            [1.0, 0.0, 0.0],
            rotate,
        );
        let (hit, tr) = trace::<f64>(&text, centre, [-500.0, 0.0, 0.0], rotate, &exact);
        assert!((hit.unwrap() - 500.0).abs() < 1e-6, "hit {hit:?}");
        let want = (-0.5 * TAU_ACROSS).exp();
        assert!(
            (tr - want).abs() < 1e-9,
            "centre {centre:?}: {tr} vs {want}"
        );
    }
}

#[test]
fn ray_missing_the_media_or_starting_past_them_has_transmittance_one() {
    let exact = TransmittanceParams::new(Estimator::Exact);
    let text = scene([0.0; 3], &[[0.0; 3]], [800.0, 0.0, 0.0], 0.0);
    // Past the box, towards the wall.
    let (hit, tr) = trace::<f64>(&text, [0.0; 3], [300.0, 0.0, 0.0], 0.0, &exact);
    assert!(
        (hit.unwrap() - 499.0).abs() < 1e-6 && tr == 1.0,
        "{hit:?} {tr}"
    );
    // Beside the box (300 mm off its axis).
    let (_, tr) = trace::<f64>(&text, [0.0; 3], [-500.0, 300.0, 0.0], 0.0, &exact);
    assert_eq!(tr, 1.0);
}

#[test]
fn far_from_the_origin_f32_surfaces_keep_media_exact() {
    // 1e6 mm away: the surfaces are traced in f32, the media in f64 over widened spans.
    let centre = [1e6, -1e6, 5e5];
    let exact = TransmittanceParams::new(Estimator::Exact);
    let text = scene(centre, &[[0.0; 3]], [800.0, 0.0, 0.0], 30.0);
    let (hit, tr) = trace::<f32>(&text, centre, [-500.0, 0.0, 0.0], 30.0, &exact);
    assert!((hit.unwrap() - 1299.0).abs() < 0.5, "hit {hit:?}");
    let want = (-TAU_ACROSS).exp();
    assert!((tr - want).abs() < 1e-9, "{tr} vs {want}");
}

#[test]
fn trackers_through_two_placements_are_unbiased() {
    let centre = [0.0; 3];
    let text = scene(
        centre,
        &[[0.0; 3], [400.0, 0.0, 0.0]],
        [800.0, 0.0, 0.0],
        0.0,
    );
    let want = (-2.0 * TAU_ACROSS).exp();
    for estimator in [Estimator::Delta, Estimator::Ratio, Estimator::Residual] {
        for majorant in [Majorant::Local { level: 0 }, Majorant::Global] {
            let mut params = TransmittanceParams::new(estimator);
            params.majorant = majorant;
            params.spp = 1;
            // Independent rays (indices) of one sample each: mean and standard error.
            let n = 4000;
            let samples: Vec<f64> =
                trace_many::<f64>(&text, centre, [-500.0, 0.0, 0.0], 0.0, &params, n)
                    .iter()
                    .map(|r| r.1)
                    .collect();
            let mean = samples.iter().sum::<f64>() / n as f64;
            let var = samples.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
            let error = (var / n as f64).sqrt();
            assert!(
                (mean - want).abs() < 4.0 * error + 1e-12,
                "{estimator:?} {majorant:?}: {mean} +- {error} vs {want}"
            );
        }
    }
}

#[test]
fn scene_media_errors_name_the_problem() {
    let bad = |text: &str, needle: &str| {
        let e = scene_from_toml(text, "bad.toml", Path::new("."))
            .err()
            .unwrap_or_else(|| panic!("accepted: {text}"));
        let message = format!("{e:#}");
        assert!(message.contains(needle), "`{message}` lacks `{needle}`");
    };
    bad(
        "[volumes.fog]\nsource = \"box:200,200,200,10,4\"\ndensity_scale = -1\n",
        "density scale must be finite and >= 0",
    );
    bad(
        "[volumes.fog]\nsource = \"nowhere.nvdb\"\ndensity_scale = 1\n",
        "nowhere.nvdb",
    );
    bad(
        "[volumes.fog]\nsource = \"sphere:x\"\ndensity_scale = 1\n",
        "not a number",
    );
    bad(
        "[volumes.fog]\nsource = \"box:200,200,200,10,4\"\ndensity_scale = 1\nformat = \"f8\"\n",
        "f8",
    );
    bad(
        "[volumes.fog]\nsource = \"box:200,200,200,10,4\"\ndensity_scale = 1\n\
         [solids.fog]\nshape = \"sphere(1)\"\n",
        "names two entries",
    );
    bad("[meshes.m]\nfile = \"missing.obj\"\n", "missing.obj");
}

/// `hytrace scan --transmittance` end to end: the analytic values for rays through two fog
/// boxes to a wall, through half a box, beside the boxes, and clean failures.
#[test]
fn scan_writes_transmittance_up_to_the_first_surface() {
    let dir = tempfile::tempdir().unwrap();
    let scene_file = dir.path().join("fog.toml");
    std::fs::write(
        &scene_file,
        scene(
            [0.0; 3],
            &[[0.0; 3], [400.0, 0.0, 0.0]],
            [800.0, 0.0, 0.0],
            0.0,
        ),
    )
    .unwrap();
    let rays = dir.path().join("rays.npy");
    let inf = f64::INFINITY;
    #[rustfmt::skip]
    let rows: [f64; 32] = [
        -500.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, inf,    // both boxes, then the wall
        -500.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 500.0,  // stops at the first box's centre
        -500.0, 300.0, 0.0, 0.0, 1.0, 0.0, 0.0, inf,  // beside the boxes
        1000.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, inf,   // from behind the wall: stopped by it
    ];
    write_array(&rays, Scalar::F64, &[4, 8], bytemuck::cast_slice(&rows)).unwrap();
    let (hits, trans) = (dir.path().join("h.npy"), dir.path().join("t.npy"));
    let run = |extra: &[&str]| {
        let mut args = vec![
            "scan".to_string(),
            scene_file.display().to_string(),
            "--rays".into(),
            rays.display().to_string(),
            "--out".into(),
            hits.display().to_string(),
            "--transmittance".into(),
            trans.display().to_string(),
        ];
        args.extend(extra.iter().map(|a| a.to_string()));
        Command::new(env!("CARGO_BIN_EXE_hytrace"))
            .args(&args)
            .output()
            .unwrap()
    };
    let ok = run(&["--estimator", "exact", "--precision", "f64"]);
    assert!(
        ok.status.success(),
        "{}",
        String::from_utf8_lossy(&ok.stderr)
    );
    let a = read_array(&trans).unwrap();
    assert_eq!((a.scalar, a.shape.clone()), (Scalar::F64, vec![4]));
    let t: Vec<f64> = bytemuck::pod_collect_to_vec(&a.bytes);
    let want = [
        (-2.0 * TAU_ACROSS).exp(),
        (-0.5 * TAU_ACROSS).exp(),
        1.0,
        1.0,
    ];
    for (got, want) in t.iter().zip(want) {
        assert!((got - want).abs() < 1e-9, "{t:?} vs {want}");
    }
    // Embree finding the surfaces and the brick clusters, in f32; a build without Embree
    // says so and writes nothing.
    let embree = run(&["--estimator", "exact", "--backend", "embree"]);
    let message = String::from_utf8_lossy(&embree.stderr);
    if cfg!(feature = "embree") {
        assert!(embree.status.success(), "{message}");
        let t: Vec<f64> = bytemuck::pod_collect_to_vec(&read_array(&trans).unwrap().bytes);
        for (got, want) in t.iter().zip(want) {
            assert!((got - want).abs() < 1e-5, "embree: {t:?} vs {want}");
        }
    } else {
        assert!(
            !embree.status.success() && message.contains("built without Embree"),
            "{message}"
        );
    }
    // The density scale multiplies each medium's own.
    let ok = run(&["--density-scale", "2"]);
    assert!(
        ok.status.success(),
        "{}",
        String::from_utf8_lossy(&ok.stderr)
    );
    let t: Vec<f64> = bytemuck::pod_collect_to_vec(&read_array(&trans).unwrap().bytes);
    assert!((t[0] - (-4.0 * TAU_ACROSS).exp()).abs() < 1e-9, "{t:?}");
    // Bad input fails naming the problem and writes nothing.
    std::fs::remove_file(&trans).unwrap();
    std::fs::remove_file(&hits).unwrap();
    for (extra, needle) in [
        (&["--spp", "0"][..], "spp must be at least 1"),
        (&["--estimator", "march", "--step=-1"][..], "march step"),
        (&["--level", "9"][..], "mip level 9"),
    ] {
        let bad = run(extra);
        let message = String::from_utf8_lossy(&bad.stderr);
        assert!(
            !bad.status.success() && message.contains(needle),
            "{extra:?}: {message}"
        );
        assert!(
            !trans.exists() && !hits.exists(),
            "{extra:?} left an output"
        );
    }
}
