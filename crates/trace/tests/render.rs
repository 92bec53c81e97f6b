//! Rendering checked against what physics says the image must be.
//!
//! - Furnace tests: in a uniform white environment, a closed white diffuse sphere, a clear
//!   glass sphere and a white (albedo 1) scattering fog must each return exactly the light
//!   they receive: every pixel equals the environment. Absorbing versions must come out
//!   darker, never brighter: energy is never created.
//! - Single scattering from a slab of constant density lit along the view direction equals
//!   the closed form `albedo E / (8 pi) (1 - exp(-2 sigma D))`.
//! - Geometry views of spheres match their analytic normals and identities.

use std::f64::consts::PI;

use hytrace_foundry::gdml::GdmlOptions;
use hytrace_trace::cpu::CpuScene;
use hytrace_trace::render::{Image, Renderer};
use hytrace_trace::scene::load_render_scene;

/// Renders a scene file's text.
fn render(text: &str) -> Image {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("scene.toml");
    std::fs::write(&path, text).unwrap();
    let (f, spec) = load_render_scene(Some(&path), &GdmlOptions::default()).unwrap();
    let cpu = CpuScene::<f32>::new(&f).unwrap();
    Renderer::new(&cpu, &f, &spec)
        .unwrap()
        .render(&|_| {})
        .unwrap()
}

/// A unit-radiance white environment, a camera at 500 mm looking at the origin, and
/// `extra` (solids, materials, volumes, render settings).
fn furnace(extra: &str, render_table: &str) -> Image {
    render(&format!(
        r#"
[camera]
eye = [0, -500, 0]
target = [0, 0, 0]
fov = 30

[[lights]]
kind = "environment"
radiance = [1, 1, 1]

{extra}

[render]
size = [24, 24]
{render_table}
"#
    ))
}

/// Smallest and largest channel over the image.
fn range(image: &Image) -> (f32, f32) {
    image
        .pixels
        .iter()
        .flatten()
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &v| {
            (a.min(v), b.max(v))
        })
}

/// Every channel of every pixel is 1 (to f32 rounding): the furnace's environment.
fn assert_all_one(image: &Image) {
    let (lo, hi) = range(image);
    assert!(
        (1.0 - lo) < 1e-6 && (hi - 1.0) < 1e-6,
        "pixels in [{lo}, {hi}], expected exactly 1"
    );
}

/// The centre pixel's channels.
fn centre(image: &Image) -> [f32; 3] {
    image.pixels[(image.height / 2 * image.width + image.width / 2) as usize]
}

#[test]
fn furnace_white_diffuse_sphere_returns_exactly_the_environment() {
    let scene = r#"
[solids.ball]
shape = "sphere(100)"
material = "white"

[materials.white]
kind = "diffuse"
colour = [1, 1, 1]
"#;
    // Every shadow ray from a convex surface escapes: a leak (self-shadowing) darkens.
    assert_all_one(&furnace(scene, "spp = 4"));
    let grey = furnace(
        &scene.replace("[1, 1, 1]\n", "[0.5, 0.5, 0.5]\n"),
        "spp = 4",
    );
    let c = centre(&grey);
    assert!(c.iter().all(|v| (v - 0.5).abs() < 1e-6), "{c:?}");
}

#[test]
fn furnace_clear_glass_sphere_neither_creates_nor_loses_light() {
    let clear = r#"
[solids.ball]
shape = "sphere(100)"
material = "glass"

[materials.glass]
kind = "dielectric"
ior = 1.5
"#;
    let image = furnace(clear, "spp = 8\nmax_bounces = 256");
    assert_all_one(&image);
    // Absorbing glass: the centre ray crosses 200 mm of it.
    let tinted = furnace(
        &format!("{clear}absorption_length = 400\n"),
        "spp = 64\nmax_bounces = 256",
    );
    let (_, hi) = range(&tinted);
    let c = centre(&tinted)[0] as f64;
    assert!(hi <= 1.0 + 1e-6, "absorbing glass brightened a pixel: {hi}");
    // Mostly transmitted straight through: about exp(-200 / 400) of the light, plus the
    // few percent reflected at the front face.
    assert!(c > 0.55 && c < 0.7, "centre {c}, expected near 0.6");
}

#[test]
fn furnace_white_fog_returns_exactly_the_environment_and_grey_fog_less() {
    let fog = |albedo: f64| {
        format!(
            r#"
[volumes.fog]
source = "sphere:120,6,3"
density_scale = 0.05
albedo = {albedo}
g = 0.4
"#
        )
    };
    // Optical depth about 12 across: many scatterings before a path escapes.
    let white = furnace(&fog(1.0), "spp = 4\nmax_bounces = 4096");
    assert_all_one(&white);
    let grey = furnace(&fog(0.8), "spp = 16\nmax_bounces = 4096");
    let (_, hi) = range(&grey);
    assert!(hi <= 1.0 + 1e-6, "a grey fog brightened a pixel: {hi}");
    let c = centre(&grey)[0];
    assert!(
        c < 0.7,
        "the centre of a thick grey fog should be dark: {c}"
    );
}

#[test]
fn single_scattering_of_a_lit_slab_matches_the_closed_form() {
    // A slab 100 mm thick (2 mm voxels, blended over one voxel) of extinction 0.01 / mm,
    // seen from above through its middle, lit from above along the view direction.
    let (albedo, sigma, depth): (f64, f64, f64) = (0.8, 0.01, 100.0);
    let image = render(&format!(
        r#"
[volumes.slab]
source = "box:400,400,{depth},2,1"
density_scale = {sigma}
albedo = {albedo}

[camera]
eye = [0, 0, 200]
target = [0, 0, 0]
up = [0, 1, 0]
orthographic = 60

[[lights]]
kind = "directional"
direction = [0, 0, -1]
irradiance = [1, 1, 1]

[render]
size = [32, 32]
spp = 64
volumes = "single-scattering"
"#
    ));
    let n = image.pixels.len() as f64;
    let mean = image.pixels.iter().map(|p| p[0] as f64).sum::<f64>() / n;
    // L = integral over depth of sigma_s T(t)^2 E / (4 pi) = albedo E / (8 pi) (1 - e^(-2 tau)).
    let expect = albedo / (8.0 * PI) * (1.0 - (-2.0 * sigma * depth).exp());
    eprintln!("single scattering: mean {mean:.5}, closed form {expect:.5}");
    assert!(
        (mean / expect - 1.0).abs() < 0.02,
        "mean radiance {mean:.5}, closed form {expect:.5}"
    );
}

#[test]
fn normal_and_instance_views_match_analytic_spheres() {
    // Two spheres of radius 40 at x = -50 and x = +50, seen orthographically from -y.
    let scene = r#"
[solids.ball]
shape = "sphere(40)"

[[place]]
solid = "ball"
translate = [-50, 0, 0]

[[place]]
solid = "ball"
translate = [50, 0, 0]

[camera]
eye = [0, -300, 0]
target = [0, 0, 0]
orthographic = 100

[render]
view = "normal"
size = [64, 32]
spp = 1
"#;
    let image = render(scene);
    let instances = render(&scene.replace("\"normal\"", "\"instance\""));
    // Colour of each sphere in the instance view.
    let mut colours: [Option<[f32; 3]>; 2] = [None, None];
    let (w, h) = (image.width as f64, image.height as f64);
    let mut hits = 0;
    for j in 0..image.height {
        for i in 0..image.width {
            // Pixel centre on the view plane (x right, z up; height 100 mm).
            let x = (2.0 * (i as f64 + 0.5) / w - 1.0) * (w / h) * 50.0;
            let z = (1.0 - 2.0 * (j as f64 + 0.5) / h) * 50.0;
            let centre_x = if x < 0.0 { -50.0 } else { 50.0 };
            let r2 = (x - centre_x).powi(2) + z * z;
            let got = image.pixels[(j * image.width + i) as usize];
            if r2 > 40.0f64.powi(2) - 1e-3 {
                if r2 > 40.0f64.powi(2) + 1e-3 {
                    assert_eq!(got, [0.0; 3], "pixel ({i}, {j}) misses");
                }
                continue;
            }
            hits += 1;
            let colour = instances.pixels[(j * image.width + i) as usize];
            let slot = &mut colours[usize::from(x > 0.0)];
            assert_eq!(*slot.get_or_insert(colour), colour, "pixel ({i}, {j})");
            let n = [(x - centre_x) / 40.0, -(1.0 - r2 / 1600.0).sqrt(), z / 40.0];
            for k in 0..3 {
                let expect = 0.5 * (n[k] + 1.0);
                assert!(
                    (got[k] as f64 - expect).abs() < 2e-5,
                    "pixel ({i}, {j}) channel {k}: {} vs {expect}",
                    got[k]
                );
            }
        }
    }
    assert!(hits > 600, "{hits} pixels on the spheres");
    assert_ne!(colours[0], colours[1], "the two instances share a colour");
}
