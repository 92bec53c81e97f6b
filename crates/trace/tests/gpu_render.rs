//! The GPU render kernel against its CPU twin (`Renderer::render`), pixel by pixel on
//! lavapipe in CI: geometry views (deterministic: within 1e-4), and surface light transport
//! (direct light, shadows, mirrors, dielectrics: the same random streams, so the same
//! paths but where f32 and f64 round a decision apart). Camera rays are made in f32 on the
//! GPU and in f64 on the CPU, so a pixel whose ray grazes a silhouette may see another
//! surface: at least 99.5% of pixels must agree, and every disagreement is printed.
//! Media: emission-absorption pixel by pixel; scattering media (delta tracking, ratio
//! tracking, phase functions) on the same streams, compared pixel by pixel and in the mean
//! and spread of the image. Also: the composed kernel holds only the effects the scene
//! calls for (and validates), more placed media than the kernel takes are refused, pixels
//! past the driver's loop budget are found and rendered again on the CPU, and
//! `render --backend gpu|auto` from the command line; GPU renders report their progress
//! after each sample pass.

mod common;

use common::{hytrace, repo};
use hytrace_foundry::gdml::GdmlOptions;
use hytrace_trace::cpu::CpuScene;
use hytrace_trace::gpu::{compose_render_kernel, GpuContext, GpuError, GpuRenderer, TexelStore};
use hytrace_trace::render::run::{render, RenderBackend};
use hytrace_trace::render::spec::{RenderSpec, View, VolumeMode};
use hytrace_trace::render::{Image, Renderer};
use hytrace_trace::scene::{load_render_scene, render_scene_from_toml};

fn load(scene: &str) -> (hytrace_foundry::Foundry, RenderSpec) {
    let arg = if scene == "default" {
        None
    } else {
        Some(repo(scene))
    };
    load_render_scene(arg.as_deref(), &GdmlOptions::default()).unwrap()
}

/// A change of a render's settings.
type Tweak<'a> = dyn Fn(&mut RenderSpec) + 'a;

/// Renders `scene` on both sides in each of `tweaks`, with one kernel built for the first
/// (the tweaks change views and settings, not the effects); `None` without a GPU.
fn both(scene: &str, tweaks: &[&Tweak]) -> Option<Vec<(Image, Image, Vec<&'static str>)>> {
    let ctx = GpuContext::for_tests()?;
    let (f, spec) = load(scene);
    let cpu_scene = CpuScene::<f32>::new(&f).unwrap();
    let mut kernel: Option<GpuRenderer> = None;
    let mut out = Vec::new();
    for tweak in tweaks {
        let mut spec = spec.clone();
        tweak(&mut spec);
        let renderer = Renderer::new(&cpu_scene, &f, &spec).unwrap();
        let cpu = renderer.render(&|_| {}).unwrap();
        let gpu = kernel.get_or_insert_with(|| GpuRenderer::new(&ctx, &renderer).unwrap());
        let mut run = gpu.render(&ctx, &renderer, &|_| {}).unwrap();
        // Pixels past lavapipe's loop budget are the CPU's, as in `render --backend gpu`:
        // at most 5% of them (only the default scene's longest paths come near it).
        let cut = run.cut_short.len();
        eprintln!("{scene}: {cut} pixels past the loop budget");
        assert!(
            cut * 20 <= run.image.pixels.len(),
            "{scene}: {cut} pixels past the loop budget"
        );
        run.redo_cut_short(&renderer).unwrap();
        out.push((cpu, run.image, gpu.features().to_vec()));
    }
    Some(out)
}

/// Pixels of `a` and `b` that differ by more than `tolerance` in a channel; prints them.
fn compare(name: &str, a: &Image, b: &Image, tolerance: f32) -> f64 {
    assert_eq!((a.width, a.height), (b.width, b.height));
    let mut bad = 0;
    for (k, (p, q)) in a.pixels.iter().zip(&b.pixels).enumerate() {
        if (0..3).any(|c| (p[c] - q[c]).abs() > tolerance || !q[c].is_finite()) {
            bad += 1;
            let (i, j) = (k as u32 % a.width, k as u32 / a.width);
            eprintln!("{name}: pixel ({i}, {j}) CPU {p:?} GPU {q:?}");
        }
    }
    let agree = 1.0 - bad as f64 / a.pixels.len() as f64;
    eprintln!(
        "{name}: {:.3}% of {} pixels agree",
        100.0 * agree,
        a.pixels.len()
    );
    agree
}

fn small(spec: &mut RenderSpec, view: View, spp: u32) {
    spec.settings.size = [48, 32];
    spec.settings.spp = spp;
    spec.settings.view = view;
}

#[test]
fn geometry_views_match_the_cpu_pixel_by_pixel() {
    let views = [
        View::Depth,
        View::Normal,
        View::Solid,
        View::Prim,
        View::Instance,
        View::Boundary,
    ];
    let closures: Vec<_> = views
        .iter()
        .map(|&v| move |s: &mut RenderSpec| small(s, v, 1))
        .collect();
    let tweaks: Vec<&Tweak> = closures.iter().map(|t| t as &Tweak).collect();
    for scene in ["scenes/render/views.toml", "default"] {
        let Some(images) = both(scene, &tweaks) else {
            return;
        };
        for ((cpu, gpu, _), view) in images.iter().zip(views) {
            let agree = compare(&format!("{scene} {view:?}"), cpu, gpu, 1e-4);
            assert!(
                agree >= 0.995,
                "{scene} {view:?}: {:.3}% agree",
                100.0 * agree
            );
        }
    }
}

#[test]
fn gdml_boundary_view_sees_through_the_world_as_the_cpu_does() {
    let scene = "tests/data/gdml/coverage.gdml";
    let Some(images) = both(scene, &[&|s| small(s, View::Boundary, 1)]) else {
        return;
    };
    let (cpu, gpu, _) = &images[0];
    let agree = compare("gdml boundary", cpu, gpu, 1e-4);
    assert!(agree >= 0.995);
    assert!(
        cpu.pixels.iter().any(|p| *p != [0.0; 3]),
        "the detector shows"
    );
}

#[test]
fn shaded_surfaces_match_the_cpu_sample_for_sample() {
    // The default scene with its fog turned off: acrylic vessel, mirror ring, shadows.
    // A scene file placing a GDML detector twice (its world transparent, a gold mirror).
    for (scene, spp) in [
        ("scenes/render/shading.toml", 2),
        ("scenes/render/glass.toml", 2),
        ("scenes/render/gdml.toml", 1),
        ("default", 1),
    ] {
        let tweak = |s: &mut RenderSpec| {
            small(s, View::Shaded, spp);
            s.settings.volumes = Some(VolumeMode::Off);
        };
        let Some(images) = both(scene, &[&tweak]) else {
            return;
        };
        let (cpu, gpu, features) = &images[0];
        assert!(features.contains(&"shading"), "{features:?}");
        assert!(!features.contains(&"media"), "{features:?}");
        let agree = compare(scene, cpu, gpu, 1e-4);
        assert!(agree >= 0.995, "{scene}: {:.3}% agree", 100.0 * agree);
    }
}

#[test]
fn the_kernel_holds_only_the_effects_the_scene_calls_for() {
    let kernel = |scene: &str, view: View| {
        let (f, mut spec) = load(scene);
        small(&mut spec, view, 1);
        let cpu_scene = CpuScene::<f32>::new(&f).unwrap();
        let renderer = Renderer::new(&cpu_scene, &f, &spec).unwrap();
        compose_render_kernel(&renderer)
    };
    let mut sources = Vec::new();
    let (features, source) = kernel("scenes/render/views.toml", View::Solid).unwrap();
    sources.push(source.clone());
    assert!(!features.contains(&"shading") && !features.contains(&"specular"));
    assert!(!source.contains("fn next_shadow") && !source.contains("refraction(d, facing"));
    let (features, source) = kernel("scenes/render/shading.toml", View::Shaded).unwrap();
    sources.push(source.clone());
    assert!(features.contains(&"shading") && !features.contains(&"specular"));
    assert!(source.contains("fn next_shadow") && !source.contains("refraction(d, facing"));
    let (features, source) = kernel("scenes/render/glass.toml", View::Shaded).unwrap();
    assert!(features.contains(&"specular"), "{features:?}");
    assert!(source.contains("refraction(d, facing"));
    sources.push(source);
    // Every composition is valid WGSL.
    for src in &sources {
        let module = naga::front::wgsl::parse_str(src).expect("the render kernel parses");
        naga::valid::Validator::new(Default::default(), naga::valid::Capabilities::all())
            .validate(&module)
            .expect("the render kernel validates");
    }
    let (features, source) = kernel("scenes/render/fog-emission.toml", View::Shaded).unwrap();
    assert!(features.contains(&"absorption") && source.contains("fn emission_absorption"));
    assert!(!source.contains("fn estimate_sample") && !source.contains("fn scatter_step"));
    let (features, scattering) = kernel("scenes/render/fog-single.toml", View::Shaded).unwrap();
    assert!(features.contains(&"scattering") && features.contains(&"lights"));
    assert!(!features.contains(&"absorption") && !scattering.contains("fn emission_absorption"));
    assert!(scattering.contains("fn estimate_sample") && scattering.contains("fn scatter_step"));
    assert!(!sources.iter().any(|s| s.contains("fn walk_start")));
    // The media's code validates too.
    for src in [&source, &scattering] {
        let module = naga::front::wgsl::parse_str(src).expect("the render kernel parses");
        naga::valid::Validator::new(Default::default(), naga::valid::Capabilities::all())
            .validate(&module)
            .expect("the render kernel validates");
    }
    // More placed media than the kernel takes: refused as such, so `auto` can fall back.
    let (f, spec) = render_scene_from_toml(&many_fogs(17), "fogs.toml", &repo(".")).unwrap();
    let cpu_scene = CpuScene::<f32>::new(&f).unwrap();
    let renderer = Renderer::new(&cpu_scene, &f, &spec).unwrap();
    assert!(matches!(
        compose_render_kernel(&renderer),
        Err(GpuError::Unsupported(why)) if why.contains("at most 16")
    ));
}

/// `n` placements of one scattering fog in a row: more than 16 the GPU renderer refuses.
fn many_fogs(n: usize) -> String {
    let mut scene =
        "[volumes.fog]\nsource = \"sphere:100,10\"\ndensity_scale = 0.01\nalbedo = 0.5\n"
            .to_string();
    for k in 0..n {
        scene += &format!(
            "[[place]]\nsolid = \"fog\"\ntranslate = [{}, 0, 0]\n",
            250 * k
        );
    }
    scene
}

/// Several media: one grid placed twice (once turned), a second grid overlapping both, a
/// floor (whose edges stay out of view) and a light; `ALBEDO` and `EMISSION` are filled in.
const MEDIA_SCENE: &str = r#"
[volumes.fog]
source = "sphere:100,10,4"
density_scale = 0.012
albedo = ALBEDO
g = 0.4
emission = EMISSION

[volumes.haze]
source = "box:260,120,120,12,6"
density_scale = 0.004
albedo = ALBEDO
g = -0.2
emission = EMISSION

[solids.floor]
shape = "box(4000, 4000, 20)"

[[place]]
solid = "fog"
translate = [-110, 0, 120]

[[place]]
solid = "fog"
translate = [110, 0, 120]
rotate = [0, 1, 0, 35]

[[place]]
solid = "haze"
translate = [0, 20, 140]

[[place]]
solid = "floor"
translate = [0, 0, -10]

[[lights]]
kind = "point"
position = [-300, -400, 700]
intensity = [3e5, 3e5, 2.8e5]

[[lights]]
kind = "environment"
radiance = [0.05, 0.06, 0.08]

[camera]
eye = [0, -700, 700]
target = [0, 0, 110]
fov = 45
"#;

/// The several-media scene as a file in `dir`.
fn media_scene(dir: &std::path::Path, albedo: &str, emission: &str) -> String {
    let path = dir.join(format!("media-{albedo}.toml"));
    let text = MEDIA_SCENE
        .replace("ALBEDO", albedo)
        .replace("EMISSION", emission);
    std::fs::write(&path, text).unwrap();
    path.to_str().unwrap().to_string()
}

#[test]
fn render_backend_gpu_and_auto_from_the_command_line() {
    if GpuContext::for_tests().is_none() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("gpu.npy");
    let o = out.to_str().unwrap();
    let views = repo("scenes/render/views.toml");
    let v = views.to_str().unwrap();
    let run = |args: &[&str]| {
        let r = hytrace(args, &[]);
        assert!(
            r.status.success(),
            "{args:?}: {}",
            String::from_utf8_lossy(&r.stderr)
        );
        serde_json::from_slice::<serde_json::Value>(&r.stdout).unwrap()
    };
    let stats = run(&[
        "render",
        v,
        "--backend",
        "gpu",
        "--size",
        "24x16",
        "--spp",
        "1",
        "-o",
        o,
        "--stats",
    ]);
    assert_eq!(stats["backend"], "gpu");
    assert!(stats["adapter"].as_str().is_some_and(|a| !a.is_empty()));
    assert!(stats.get("gpu_kernel_timestamps_s").is_some());
    let gpu = common::read_values(&out);
    let cpu_out = dir.path().join("cpu.npy");
    run(&[
        "render",
        v,
        "--size",
        "24x16",
        "--spp",
        "1",
        "-o",
        cpu_out.to_str().unwrap(),
        "--stats",
    ]);
    let cpu = common::read_values(&cpu_out);
    let close = gpu
        .iter()
        .zip(&cpu)
        .filter(|(a, b)| (*a - *b).abs() <= 1e-4)
        .count();
    assert!(
        close as f64 >= 0.995 * cpu.len() as f64,
        "{close} of {} values",
        cpu.len()
    );
    // `--gpu-texels texture` reads a medium's texels from a 3D texture.
    let fog = repo("scenes/render/fog-emission.toml");
    let stats = run(&[
        "render",
        fog.to_str().unwrap(),
        "--backend",
        "gpu",
        "--gpu-texels",
        "texture",
        "--size",
        "16x12",
        "-o",
        o,
        "--stats",
    ]);
    let features = stats["kernel_features"].as_array().unwrap();
    assert!(
        features.iter().any(|f| f == "atlas_texture"),
        "{features:?}"
    );
    // A scene with too many media: `gpu` refuses clearly, `auto` falls back to the CPU.
    let fog = dir.path().join("fogs.toml");
    std::fs::write(&fog, many_fogs(17)).unwrap();
    let f = fog.to_str().unwrap();
    let refused = hytrace(
        &["render", f, "--backend", "gpu", "--size", "8x8", "-o", o],
        &[],
    );
    assert!(!refused.status.success());
    let err = String::from_utf8_lossy(&refused.stderr);
    assert!(err.contains("at most 16"), "{err}");
    let stats = run(&[
        "render",
        f,
        "--backend",
        "auto",
        "--size",
        "8x8",
        "--spp",
        "1",
        "-o",
        o,
        "--stats",
    ]);
    assert_eq!(stats["backend"], "cpu");
}

#[test]
fn emission_absorption_media_match_the_cpu_pixel_by_pixel() {
    // The NanoVDB fog alone, the mixed scene (diffuse surfaces, shadow rays through an
    // absorbing fog box), and several overlapping emitting media over a lit floor (at a
    // half-voxel step: the default eighth marches the shadow rays past lavapipe's loop
    // budget, which `both` allows on 5% of pixels only).
    let dir = tempfile::tempdir().unwrap();
    let several = media_scene(dir.path(), "0.0", "[0.8, 0.5, 0.3]");
    for (scene, step) in [
        ("scenes/render/fog-emission.toml", None),
        ("scenes/mixed.toml", None),
        (several.as_str(), Some(0.5)),
    ] {
        let tweak = |s: &mut RenderSpec| {
            small(s, View::Shaded, 1);
            s.settings.step = step.unwrap_or(s.settings.step);
        };
        let Some(images) = both(scene, &[&tweak]) else {
            return;
        };
        let (cpu, gpu, features) = &images[0];
        assert!(features.contains(&"media"), "{features:?}");
        let agree = compare(scene, cpu, gpu, 1e-4);
        assert!(agree >= 0.995, "{scene}: {:.3}% agree", 100.0 * agree);
    }
}

/// Mean, sample variance and count of `values`.
fn moments(values: impl Iterator<Item = f64>) -> (f64, f64, f64) {
    let values: Vec<f64> = values.collect();
    let n = values.len() as f64;
    let mean = values.iter().sum::<f64>() / n;
    let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0);
    (mean, var, n)
}

/// Each pixel's channel sum (one value per path: its channels are not independent).
fn channels(image: &Image) -> impl Iterator<Item = f64> + '_ {
    image
        .pixels
        .iter()
        .map(|p| p.iter().map(|&c| f64::from(c)).sum())
}

#[test]
fn scattering_media_match_the_cpu_in_mean_and_variance() {
    // Single scattering toward a point light and the sky, multiple scattering under the
    // sun, the default scene (a scattering fog inside the acrylic vessel) and several
    // overlapping media over a lit floor, at 1 spp so the images are noisy.
    //
    // On the same streams, f32 and f64 take a different branch of a random decision now
    // and then and the path diverges from there: most pixels agree exactly (with several
    // media fewer, 96.9%: the CPU keys each medium's shadow stream by its place among the
    // media the ray meets, the GPU by its place among all). On
    // independent streams (another seed on the GPU) the images agree in distribution: the
    // mean of the pixel differences is within four standard errors of 0, and the spread
    // of the pixel values (the scene's structure plus the noise) is the same within 10%.
    // The images are 128 x 96: at 64 x 48 the default scene's pixel variance moved by 8%
    // between two seeds of the CPU alone, most of the 10% bound.
    let dir = tempfile::tempdir().unwrap();
    let several = media_scene(dir.path(), "0.9", "[0, 0, 0]");
    for (scene, exact) in [
        ("scenes/render/fog-single.toml", 0.95),
        ("scenes/render/fog-multiple.toml", 0.95),
        ("default", 0.95),
        (several.as_str(), 0.9),
    ] {
        let tweak = |seed: u32| {
            move |s: &mut RenderSpec| {
                small(s, View::Shaded, 1);
                s.settings.size = [128, 96];
                s.settings.seed = seed;
            }
        };
        let (same, other) = (tweak(0), tweak(1000));
        let Some(images) = both(scene, &[&same, &other]) else {
            return;
        };
        let (cpu, gpu, features) = &images[0];
        assert!(features.contains(&"scattering"), "{features:?}");
        let agree = compare(scene, cpu, gpu, 1e-4);
        assert!(agree >= exact, "{scene}: {:.3}% agree", 100.0 * agree);
        let independent = &images[1].1;
        let (m_cpu, v_cpu, _) = moments(channels(cpu));
        let (m_gpu, v_gpu, _) = moments(channels(independent));
        let (m_diff, v_diff, n) =
            moments(channels(cpu).zip(channels(independent)).map(|(a, b)| a - b));
        let se = (v_diff / n).sqrt();
        eprintln!(
            "{scene}: mean CPU {m_cpu} GPU {m_gpu}, difference {m_diff} (se {se}); variance CPU {v_cpu} GPU {v_gpu}"
        );
        assert!(
            m_cpu > 0.0 && v_diff > 0.0,
            "{scene}: the medium shows, and is noisy"
        );
        assert!(m_diff.abs() <= 4.0 * se, "{scene}: means differ");
        assert!(
            (v_gpu / v_cpu - 1.0).abs() <= 0.1,
            "{scene}: variances {v_cpu} and {v_gpu}"
        );
    }
}

#[test]
fn long_paths_over_many_samples_match_the_cpu() {
    // Multiple scattering in a dense cloud (paths of tens of bounces) at 16 spp: every
    // sample of every pixel, with the running sums, as on the CPU. (One dispatch per
    // sample keeps each invocation within lavapipe's loop budget.)
    let tweak = |s: &mut RenderSpec| {
        small(s, View::Shaded, 16);
        s.settings.size = [24, 16];
    };
    let Some(images) = both("scenes/render/fog-multiple.toml", &[&tweak]) else {
        return;
    };
    let (cpu, gpu, _) = &images[0];
    let agree = compare("fog-multiple at 16 spp", cpu, gpu, 1e-4);
    assert!(agree >= 0.99, "{:.3}% agree", 100.0 * agree);
}

#[test]
fn pixels_past_the_driver_loop_budget_are_rendered_again_on_the_cpu() {
    // A march of 1/2000 voxel: tens of thousands of lookups per ray, past the 65535 loop
    // iterations lavapipe gives 8 invocations together. The kernel's probe finds the
    // pixels whose loops were cut short, the CPU renders them again, and the image equals
    // the CPU's; on a GPU without such a budget, no pixel is redone.
    let Some(ctx) = GpuContext::for_tests() else {
        return;
    };
    let llvmpipe = ctx.describe().contains("llvmpipe");
    let dir = tempfile::tempdir().unwrap();
    // The fog seen from afar: the rays of the image's edges miss its box and loop little,
    // so some pixels are redone and some are the kernel's.
    let scene = dir.path().join("far-fog.toml");
    let fixture = repo("tests/data/nanovdb/density_zip.nvdb");
    std::fs::write(
        &scene,
        format!(
            "[volumes.fog]\nsource = {:?}\ndensity_scale = 1.2\nemission = [1.0, 0.6, 0.3]\n\
             [camera]\neye = [9.72, -120.27, 33.75]\ntarget = [-6.28, -16.27, -2.25]\nfov = 60\n\
             [render]\nvolumes = \"emission-absorption\"\n",
            fixture.to_str().unwrap()
        ),
    )
    .unwrap();
    let args = [
        "render",
        scene.to_str().unwrap(),
        "--size",
        "16x12",
        "--step",
        "0.0005",
    ];
    let (gpu, cpu, stats, err) = common::gpu_and_cpu_values(&args, dir.path());
    let redone = stats["gpu_redone_on_cpu"].as_u64().unwrap();
    if llvmpipe {
        assert!(
            redone > 0 && redone < 16 * 12,
            "{redone} of 192 pixels found past the budget: {stats}"
        );
        assert!(err.contains("loop budget"), "{err}");
    } else {
        assert_eq!(redone, 0, "{stats}");
    }
    assert_eq!(gpu.len(), cpu.len());
    for (k, (g, c)) in gpu.iter().zip(&cpu).enumerate() {
        assert!((g - c).abs() <= 1e-4, "value {k}: GPU {g}, CPU {c}");
    }
}

/// A media atlas above the device's binding limit is split over several buffers: the
/// several-media scene rendered with the limit lowered so that its atlas takes three
/// buffers is, pixel for pixel and bit for bit, what the one-buffer kernel renders; so it
/// is with its range mips, brick tables and scene arrays split.
#[test]
fn media_atlases_above_the_binding_limit_are_split() {
    let Some(mut ctx) = GpuContext::for_tests() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let (f, mut spec) = load(&media_scene(dir.path(), "0.0", "[0.8, 0.5, 0.3]"));
    small(&mut spec, View::Shaded, 1);
    spec.settings.step = 0.5;
    let cpu_scene = CpuScene::<f32>::new(&f).unwrap();
    let renderer = Renderer::new(&cpu_scene, &f, &spec).unwrap();
    let render = |ctx: &GpuContext| {
        let gpu = GpuRenderer::new(ctx, &renderer).unwrap();
        let run = gpu.render(ctx, &renderer, &|_| {}).unwrap();
        let bits: Vec<[u32; 3]> = run
            .image
            .pixels
            .iter()
            .map(|p| p.map(f32::to_bits))
            .collect();
        (
            gpu.features().contains(&"chunked_atlas"),
            bits,
            run.cut_short,
        )
    };
    let whole = render(&ctx);
    let full = ctx.limits.max_storage_buffer_binding_size;
    // Its atlas holds 96 KiB: three chunks of 32 KiB.
    ctx.limits.max_storage_buffer_binding_size = 32 << 10;
    let split = render(&ctx);
    assert!(!whole.0 && split.0, "split only under the lowered limit");
    assert_eq!(whole.2, split.2, "the same pixels past the loop budget");
    let differ = whole.1.iter().zip(&split.1).filter(|(a, b)| a != b).count();
    assert_eq!(differ, 0, "{differ} pixels differ");
    // The media's range mips and brick tables, and the scene's arrays, are read through
    // chunks the same way (split on demand: lavapipe binds 32 storage buffers, two arrays
    // at a time).
    ctx.limits.max_storage_buffer_binding_size = full;
    for arrays in [["ranges", "bricks"], ["indirection", "placements"]] {
        ctx.split_arrays = arrays.map(String::from).to_vec();
        let split = render(&ctx);
        assert_eq!(whole.2, split.2, "{arrays:?}");
        let differ = whole.1.iter().zip(&split.1).filter(|(a, b)| a != b).count();
        assert_eq!(differ, 0, "{arrays:?} split: {differ} pixels differ");
    }
    ctx.split_arrays.clear();
    // Four chunks of 16 KiB do not hold it.
    ctx.limits.max_storage_buffer_binding_size = 16 << 10;
    let err = GpuRenderer::new(&ctx, &renderer).err().unwrap().to_string();
    assert!(err.contains("array `atlas` has"), "{err}");
}

/// The media's texels read from one 3D texture render, pixel for pixel and bit for bit,
/// what the kernel reading them from the atlas buffer renders, for f32 and unorm8 media
/// (read back exactly); media of two texel formats are refused for a texture, naming both.
#[test]
fn media_texels_from_a_3d_texture_match_the_buffer_kernel() {
    let Some(ctx) = GpuContext::for_tests() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let scene = media_scene(dir.path(), "0.0", "[0.8, 0.5, 0.3]");
    let text = std::fs::read_to_string(&scene).unwrap();
    for (name, fog, haze) in [
        ("f32", "f32", "f32"),
        ("unorm8", "unorm8", "unorm8"),
        ("mixed", "f32", "bc4"),
    ] {
        let with_formats = text
            .replacen(
                "density_scale",
                &format!("format = \"{fog}\"\ndensity_scale"),
                1,
            )
            .replace("g = -0.2", &format!("g = -0.2\nformat = \"{haze}\""));
        let path = dir.path().join(format!("{name}.toml"));
        std::fs::write(&path, with_formats).unwrap();
        let (f, mut spec) = load(path.to_str().unwrap());
        small(&mut spec, View::Shaded, 1);
        spec.settings.step = 0.5;
        let cpu_scene = CpuScene::<f32>::new(&f).unwrap();
        let renderer = Renderer::new(&cpu_scene, &f, &spec).unwrap();
        if fog != haze {
            let err = GpuRenderer::with_texels(&ctx, &renderer, TexelStore::Texture)
                .err()
                .unwrap()
                .to_string();
            assert!(
                err.contains("one texel format") && err.contains("bc4"),
                "{err}"
            );
            continue;
        }
        let render = |store| {
            let gpu = GpuRenderer::with_texels(&ctx, &renderer, store).unwrap();
            let run = gpu.render(&ctx, &renderer, &|_| {}).unwrap();
            let bits: Vec<[u32; 3]> = (run.image.pixels.iter())
                .map(|p| p.map(f32::to_bits))
                .collect();
            (
                gpu.features().contains(&"atlas_texture"),
                bits,
                run.cut_short,
            )
        };
        let buffer = render(TexelStore::Storage);
        let texture = render(TexelStore::Texture);
        assert!(!buffer.0 && texture.0, "{name}");
        assert_eq!(
            buffer.2, texture.2,
            "{name}: the same pixels past the loop budget"
        );
        let lit = buffer
            .1
            .iter()
            .filter(|p| p.iter().any(|&c| c != 0))
            .count();
        assert!(lit > buffer.1.len() / 2, "{name}: {lit} lit pixels");
        let differ = (buffer.1.iter().zip(&texture.1))
            .filter(|(a, b)| a != b)
            .count();
        println!("{name}: {} pixels, {differ} differ", buffer.1.len());
        assert_eq!(differ, 0, "{name}: {differ} pixels differ");
    }
}

/// The progress a render reports, in calls: the row samples done so far.
fn progress_calls(backend: RenderBackend, spp: u32) -> Vec<u64> {
    let (f, mut spec) = load("default");
    small(&mut spec, View::Shaded, spp);
    let calls = std::sync::Mutex::new(Vec::new());
    let record = |done: u64| calls.lock().unwrap().push(done);
    render(&f, &spec, backend, TexelStore::Storage, &record).unwrap();
    calls.into_inner().unwrap()
}

#[test]
fn gpu_renders_report_progress_after_every_sample_pass() {
    if GpuContext::for_tests().is_none() {
        return;
    }
    let (_, mut spec) = load("default");
    small(&mut spec, View::Shaded, 5);
    let [_, height] = spec.settings.size;
    let total = u64::from(height) * 5;
    // The small image is one batch of rows: a call after each of its five passes.
    let gpu = progress_calls(RenderBackend::Gpu, 5);
    assert!(gpu.len() >= 5, "{gpu:?}");
    assert!(gpu.windows(2).all(|w| w[0] <= w[1]), "{gpu:?}");
    assert_eq!(gpu.last(), Some(&total), "{gpu:?}");
    let distinct: std::collections::BTreeSet<u64> = gpu.iter().copied().collect();
    assert!(distinct.len() >= 5, "{gpu:?}");
    // The CPU counts in the same units.
    let cpu = progress_calls(RenderBackend::Cpu, 5);
    assert_eq!(cpu.iter().max(), Some(&total), "{cpu:?}");
}
