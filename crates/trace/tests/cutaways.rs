//! Cutaways and sections (`render::cutaway`, `--cut`, `--cut-mode`): a sphere cut by one to
//! three planes, in union and intersection modes, shows in every pixel the surface the
//! analytic geometry says (the sphere's own surface where the first kept point of the ray
//! inside the sphere is on it, else the section on the plane the ray entered through),
//! on the CPU and on the GPU.

mod common;

use std::path::Path;

use glam::DVec3;
use hytrace_foundry::gdml::GdmlOptions;
use hytrace_foundry::Foundry;
use hytrace_trace::cpu::CpuScene;
use hytrace_trace::render::camera::CameraSpec;
use hytrace_trace::render::cutaway::{CutMode, CutPlane, Cutaway};
use hytrace_trace::render::spec::{RenderSpec, View};
use hytrace_trace::render::{Image, Renderer};
use hytrace_trace::scene::load_render_scene;

const RADIUS: f64 = 50.0;
const SIZE: [u32; 2] = [64, 48];

/// A lead sphere of radius 50 mm at the centre of an air world.
const SPHERE_GDML: &str = r#"<?xml version="1.0"?>
<gdml>
  <materials>
    <material name="Air" Z="7"><D value="0.0012"/><atom value="14"/></material>
    <material name="Lead" Z="82"><D value="11.3"/><atom value="207"/></material>
  </materials>
  <solids>
    <box name="WorldBox" x="400" y="400" z="400" lunit="mm"/>
    <sphere name="Ball" rmax="50" deltaphi="360" deltatheta="180" aunit="deg" lunit="mm"/>
  </solids>
  <structure>
    <volume name="BallLV"><materialref ref="Lead"/><solidref ref="Ball"/></volume>
    <volume name="World"><materialref ref="Air"/><solidref ref="WorldBox"/>
      <physvol name="Ball_pv"><volumeref ref="BallLV"/></physvol>
    </volume>
  </structure>
  <setup name="Default" version="1.0"><world ref="World"/></setup>
</gdml>
"#;

fn load(dir: &Path) -> (Foundry, RenderSpec) {
    let path = dir.join("sphere.gdml");
    std::fs::write(&path, SPHERE_GDML).unwrap();
    let (f, mut spec) = load_render_scene(Some(&path), &GdmlOptions::default()).unwrap();
    spec.settings.size = SIZE;
    spec.settings.spp = 1;
    spec.settings.view = View::Normal;
    spec.camera = Some(CameraSpec {
        eye: [120.0, -160.0, 90.0],
        target: [0.0, 0.0, 0.0],
        up: [0.0, 0.0, 1.0],
        fov: Some(40.0),
        orthographic: None,
    });
    (f, spec)
}

/// Whether the planes keep `p`, combined as `mode` says (written here from the definition:
/// each plane keeps `n . p <= offset`).
fn kept(planes: &[CutPlane], mode: CutMode, p: DVec3) -> bool {
    let mut each = planes
        .iter()
        .map(|c| DVec3::from(c.normal).dot(p) <= c.offset);
    match mode {
        CutMode::Union => each.any(|k| k),
        CutMode::Intersection => each.all(|k| k),
    }
}

/// What the ray `o + t d` shows, from the analytic geometry in f64: `Some(None)` the
/// sphere's surface (with its normal), `Some(Some(k))` the section on plane `k`, `None`
/// nothing; and the normal seen.
fn analytic(
    planes: &[CutPlane],
    mode: CutMode,
    o: DVec3,
    d: DVec3,
) -> Option<(Option<usize>, DVec3)> {
    let (b, c) = (o.dot(d), o.dot(o) - RADIUS * RADIUS);
    let disc = b * b - c;
    if disc <= 0.0 {
        return None;
    }
    let (t0, t1) = (-b - disc.sqrt(), -b + disc.sqrt());
    let at = |t: f64| o + t * d;
    if kept(planes, mode, at(t0)) {
        return Some((None, at(t0) / RADIUS));
    }
    // The first point inside the sphere where the ray passes from removed to kept.
    let eps = 1e-7;
    planes
        .iter()
        .enumerate()
        .filter_map(|(k, p)| {
            let n = DVec3::from(p.normal);
            let t = (p.offset - n.dot(o)) / n.dot(d);
            (t > t0
                && t < t1
                && kept(planes, mode, at(t + eps))
                && !kept(planes, mode, at(t - eps)))
            .then_some((t, k, n))
        })
        .min_by(|a, b| a.0.total_cmp(&b.0))
        .map(|(_, k, n)| (Some(k), n))
}

fn render_cpu(f: &Foundry, spec: &RenderSpec) -> (Image, Vec<[(DVec3, DVec3); 5]>) {
    let scene = CpuScene::<f32>::new(f).unwrap();
    let r = Renderer::new(&scene, f, spec).unwrap();
    // Each pixel's centre ray and rays half a pixel away on each side.
    let offsets = [[0.5, 0.5], [0.0, 0.5], [1.0, 0.5], [0.5, 0.0], [0.5, 1.0]];
    let rays = (0..SIZE[0] * SIZE[1])
        .map(|k| offsets.map(|off| r.camera().ray(k % SIZE[0], k / SIZE[0], off)))
        .collect();
    (r.render(&|_| {}).unwrap(), rays)
}

fn cases() -> Vec<(Vec<&'static str>, CutMode)> {
    let mut out = vec![
        (vec!["x=0"], CutMode::Union),
        (vec!["x=20"], CutMode::Union),
        (vec!["1,-1,0.5:5"], CutMode::Union),
    ];
    for mode in [CutMode::Union, CutMode::Intersection] {
        out.push((vec!["x=10", "-y=-5"], mode));
        out.push((vec!["x=0", "-y=0", "z=20"], mode));
    }
    out
}

#[test]
fn a_cut_sphere_shows_its_surface_and_sections_where_the_planes_say_on_cpu_and_gpu() {
    let dir = tempfile::tempdir().unwrap();
    let (f, base) = load(dir.path());
    for (texts, mode) in cases() {
        let planes: Vec<CutPlane> = texts.iter().map(|t| t.parse().unwrap()).collect();
        let mut spec = base.clone();
        spec.cutaway = Cutaway {
            planes: planes.clone(),
            mode,
        };
        let (image, rays) = render_cpu(&f, &spec);
        let (mut checked, mut sections) = (0, 0);
        for (k, (px, around)) in image.pixels.iter().zip(&rays).enumerate() {
            let what: Vec<_> = around
                .iter()
                .map(|&(o, d)| analytic(&planes, mode, o, d))
                .collect();
            // Pixels with an edge within half a pixel (silhouettes, section rims) are skipped.
            if what.iter().any(|w| w.map(|x| x.0) != what[0].map(|x| x.0)) {
                continue;
            }
            checked += 1;
            let expected = match what[0] {
                None => DVec3::ZERO,
                Some((kind, n)) => {
                    sections += kind.is_some() as usize;
                    0.5 * (n + 1.0)
                }
            };
            let got = DVec3::from(px.map(f64::from));
            assert!(
                (got - expected).abs().max_element() < 2e-3,
                "{texts:?} {mode:?}: pixel ({}, {}) shows {got}, the geometry says {expected} ({:?})",
                k as u32 % SIZE[0],
                k as u32 / SIZE[0],
                what[0].map(|w| w.0)
            );
        }
        let n = image.pixels.len();
        assert!(
            checked * 10 >= n * 8,
            "{texts:?}: only {checked} of {n} pixels away from edges"
        );
        assert!(
            sections >= 40,
            "{texts:?} {mode:?}: {sections} section pixels"
        );
        if let Some(gpu) = common::render_on_gpu(&f, &spec) {
            let agree = gpu
                .pixels
                .iter()
                .zip(&image.pixels)
                .filter(|(g, c)| (0..3).all(|k| (g[k] - c[k]).abs() <= 1e-4))
                .count();
            assert!(
                agree * 1000 >= n * 995,
                "{texts:?} {mode:?}: GPU and CPU agree on {agree} of {n} pixels"
            );
        }
    }
}

#[test]
fn cuts_change_the_picture_only_where_they_remove_geometry_in_the_shaded_view_too() {
    let dir = tempfile::tempdir().unwrap();
    let (f, mut spec) = load(dir.path());
    spec.settings.view = View::Shaded;
    let whole = render_cpu(&f, &spec).0;
    spec.cutaway.planes = vec!["x=0".parse().unwrap()];
    let (cut, rays) = render_cpu(&f, &spec);
    // Pixels whose ray meets the sphere only at x < 0 (away from edges) are unchanged.
    let mut same = 0;
    for ((a, b), around) in whole.pixels.iter().zip(&cut.pixels).zip(&rays) {
        let untouched = around.iter().all(|&(o, d)| {
            let (b2, c) = (o.dot(d), o.dot(o) - RADIUS * RADIUS);
            let disc = b2 * b2 - c;
            disc <= 0.0 || (o + (-b2 - disc.sqrt()) * d).x < -1.0
        });
        if untouched {
            // The same point lit by the same light (traced from where the kept stretch
            // starts, so equal to f32 rounding).
            assert!(
                (0..3).all(|k| (a[k] - b[k]).abs() <= 1e-5 * (1.0 + a[k])),
                "{a:?} {b:?}"
            );
            same += 1;
        }
    }
    assert!(same > 0);
    assert_ne!(whole.pixels, cut.pixels);
}

#[test]
fn more_than_three_planes_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let (f, mut spec) = load(dir.path());
    spec.cutaway.planes = ["x=0", "y=0", "z=0", "x=1"]
        .iter()
        .map(|t| t.parse().unwrap())
        .collect();
    let scene = CpuScene::<f32>::new(&f).unwrap();
    let err = Renderer::new(&scene, &f, &spec).err().expect("refused");
    assert!(format!("{err:#}").contains("at most 3"), "{err:#}");
}
