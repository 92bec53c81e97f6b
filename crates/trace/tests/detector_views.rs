//! Detector views of GDML files (`render::detector`): what the default view, `--depth`,
//! `--show`, `--hide` and the file's colours draw, checked against the placement tree;
//! every file of the shared corpus showing its volumes; and coincident faces (a daughter
//! sharing faces with its mother, abutting daughters) rendered as their twin with the faces
//! 1e-3 mm apart is, with no black pixel, on the CPU and on the GPU; the PNG legend's
//! swatches are the JSON legend's colours, which the drawn volumes show; the automatic
//! camera frames what is drawn in every corpus file.

mod common;

use std::path::Path;

use common::{hytrace, read_png, stderr};
use hytrace_foundry::gdml::GdmlOptions;
use hytrace_foundry::Foundry;
use hytrace_testkit::files::{shared_gdml_dir, shared_gdml_files};
use hytrace_trace::cpu::CpuScene;
use hytrace_trace::render::detector::{ColorBy, DetectorError, DetectorStyle};
use hytrace_trace::render::id_colour;
use hytrace_trace::render::run::RenderSettings;
use hytrace_trace::render::spec::{Light, Material, RenderSpec, View};
use hytrace_trace::render::{Image, Renderer};
use hytrace_trace::scene::load_render_scene;

/// A world holding an envelope (a 100 mm box) holding box A, which shares its +x and +z
/// faces with the envelope, and box B, which shares the envelope's +z face and abuts A at
/// x = 10 (B is red by the file's colour). `gap` shrinks A and B by that much on every
/// side: 0 for coincident faces, 1e-3 for the separated twin.
fn nested_boxes(gap: f64) -> String {
    let (ax, bx) = (20.0 - gap, 10.0 - gap);
    let az = 20.0 - gap;
    format!(
        r#"<?xml version="1.0"?>
<gdml>
  <materials>
    <material name="Air" Z="7"><D value="0.0012"/><atom value="14"/></material>
    <material name="Lead" Z="82"><D value="11.3"/><atom value="207"/></material>
    <material name="Steel" Z="26"><D value="7.9"/><atom value="56"/></material>
  </materials>
  <solids>
    <box name="WorldBox" x="400" y="400" z="400" lunit="mm"/>
    <box name="EnvelopeBox" x="100" y="100" z="100" lunit="mm"/>
    <box name="ABox" x="{}" y="40" z="{}" lunit="mm"/>
    <box name="BBox" x="{}" y="40" z="{}" lunit="mm"/>
  </solids>
  <structure>
    <volume name="BoxA"><materialref ref="Lead"/><solidref ref="ABox"/></volume>
    <volume name="BoxB"><materialref ref="Steel"/><solidref ref="BBox"/>
      <auxiliary auxtype="Color" auxvalue="1 0 0 1"/></volume>
    <volume name="Envelope"><materialref ref="Air"/><solidref ref="EnvelopeBox"/>
      <physvol name="A_pv"><volumeref ref="BoxA"/><position name="pa" x="30" y="0" z="30" unit="mm"/></physvol>
      <physvol name="B_pv"><volumeref ref="BoxB"/><position name="pb" x="0" y="0" z="30" unit="mm"/></physvol>
    </volume>
    <volume name="World"><materialref ref="Air"/><solidref ref="WorldBox"/>
      <physvol name="Envelope_pv"><volumeref ref="Envelope"/></physvol>
    </volume>
  </structure>
  <setup name="Default" version="1.0"><world ref="World"/></setup>
</gdml>
"#,
        2.0 * ax,
        2.0 * az,
        2.0 * bx,
        2.0 * az
    )
}

/// Writes `text` as a GDML file in `dir` and loads it for rendering.
fn load_text(dir: &Path, name: &str, text: &str) -> (Foundry, RenderSpec) {
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    load_render_scene(Some(&path), &GdmlOptions::default()).unwrap()
}

/// Instances in placement order: World, Envelope, A, B.
const WORLD: usize = 0;
const ENVELOPE: usize = 1;
const A: usize = 2;
const B: usize = 3;

fn kinds(materials: &[Material]) -> Vec<&'static str> {
    materials
        .iter()
        .map(|m| match m {
            Material::Transparent => "hidden",
            Material::Shell { .. } => "shell",
            Material::Diffuse { .. } => "solid",
            _ => "other",
        })
        .collect()
}

#[test]
fn depth_show_hide_and_file_colours_follow_the_placement_tree() {
    let dir = tempfile::tempdir().unwrap();
    let (f, spec) = load_text(dir.path(), "boxes.gdml", &nested_boxes(0.0));
    let labels = &spec.volumes;
    assert_eq!(labels.len(), 4);
    assert_eq!([A, B].map(|i| labels[i].logical.as_str()), ["BoxA", "BoxB"]);
    assert_eq!(labels[A].material, "Lead");
    let style = |s: DetectorStyle| kinds(&s.apply(&f, labels).unwrap().materials);
    // The default: the world invisible, the envelope a shell, its contents solid.
    assert_eq!(
        style(DetectorStyle::default()),
        ["hidden", "shell", "solid", "solid"]
    );
    assert_eq!(
        kinds(&spec.instance_materials),
        style(DetectorStyle::default())
    );
    // Depth 1: the envelope, drawn solid since nothing inside it is drawn.
    let depth1 = DetectorStyle {
        depth: Some(1),
        ..Default::default()
    };
    assert_eq!(style(depth1), ["hidden", "solid", "hidden", "hidden"]);
    // --show by physical or logical name, case-insensitive globs.
    for pattern in ["a_PV", "boxa", "*A"] {
        let show = DetectorStyle {
            show: vec![pattern.into()],
            ..Default::default()
        };
        assert_eq!(
            style(show),
            ["hidden", "hidden", "solid", "hidden"],
            "{pattern}"
        );
    }
    let show_envelope = DetectorStyle {
        show: vec!["envelope".into()],
        depth: Some(0),
        ..Default::default()
    };
    assert_eq!(
        style(show_envelope),
        ["hidden", "solid", "hidden", "hidden"]
    );
    // --hide leaves the daughters drawn: a hidden envelope no longer holds a shell.
    let hide = DetectorStyle {
        hide: vec!["ENV*".into()],
        ..Default::default()
    };
    assert_eq!(style(hide), ["hidden", "hidden", "solid", "solid"]);
    // A pattern matching nothing names the nearest volumes.
    let typo = DetectorStyle {
        show: vec!["Envelop".into()],
        ..Default::default()
    };
    match typo.apply(&f, labels) {
        Err(DetectorError::NoMatch { suggestions, .. }) => {
            assert!(
                suggestions.iter().any(|s| s == "Envelope"),
                "{suggestions:?}"
            )
        }
        other => panic!("{other:?}"),
    }
    // The file's colour (sRGB 1 0 0 is linear 1 0 0) unless a colouring is asked for.
    let view = DetectorStyle::default().apply(&f, labels).unwrap();
    assert_eq!(
        view.materials[B],
        Material::Diffuse {
            colour: [1.0, 0.0, 0.0]
        }
    );
    let by_volume = DetectorStyle {
        color_by: Some(ColorBy::Volume),
        ..Default::default()
    };
    let view = by_volume.apply(&f, labels).unwrap();
    let names: Vec<&str> = view
        .legend
        .entries
        .iter()
        .map(|e| e.name.as_str())
        .collect();
    assert_eq!(names, ["BoxA", "BoxB", "Envelope"]);
    assert_ne!(view.materials[A], view.materials[B]);
    assert_eq!(view.materials[WORLD], Material::Transparent);
    let Material::Shell { colour, .. } = view.materials[ENVELOPE] else {
        panic!("{:?}", view.materials[ENVELOPE]);
    };
    assert_eq!(colour, view.legend.entries[2].colour);
}

#[test]
fn bad_auxiliary_colours_are_refused_naming_the_volume() {
    let dir = tempfile::tempdir().unwrap();
    let text = nested_boxes(0.0).replace("auxvalue=\"1 0 0 1\"", "auxvalue=\"red-ish\"");
    let path = dir.path().join("bad.gdml");
    std::fs::write(&path, text).unwrap();
    let err = load_render_scene(Some(&path), &GdmlOptions::default()).unwrap_err();
    let msg = format!("{err:#}");
    assert!(msg.contains("BoxB") && msg.contains("red-ish"), "{msg}");
}

/// Renders `spec` of `f` on the CPU.
fn render_cpu(f: &Foundry, spec: &RenderSpec) -> Image {
    let scene = CpuScene::<f32>::new(f).unwrap();
    Renderer::new(&scene, f, spec)
        .unwrap()
        .render(&|_| {})
        .unwrap()
}

fn black(p: &[f32; 3]) -> bool {
    p.iter().all(|&c| c <= 1e-4)
}

#[test]
fn coincident_faces_render_as_their_separated_twin_without_black_pixels() {
    let dir = tempfile::tempdir().unwrap();
    let (f, mut touching) = load_text(dir.path(), "touching.gdml", &nested_boxes(0.0));
    let (g, mut apart) = load_text(dir.path(), "apart.gdml", &nested_boxes(1e-3));
    for view in [View::Shaded, View::Instance] {
        for spec in [&mut touching, &mut apart] {
            spec.settings.size = [64, 48];
            spec.settings.spp = 1;
            spec.settings.view = view;
        }
        let (a, b) = (render_cpu(&f, &touching), render_cpu(&g, &apart));
        let mut gpu = vec![("cpu", a.clone())];
        gpu.extend(common::render_on_gpu(&f, &touching).map(|i| ("gpu", i)));
        for (side, image) in &gpu {
            let mut differ = 0;
            for (k, (p, q)) in image.pixels.iter().zip(&b.pixels).enumerate() {
                let (i, j) = (k % 64, k / 64);
                assert!(
                    !black(p) || black(q),
                    "{view:?} {side}: pixel ({i}, {j}) black, {q:?} with the faces apart"
                );
                if (0..3).any(|c| (p[c] - q[c]).abs() > 0.02) {
                    differ += 1;
                }
            }
            // The same picture but where a silhouette moved by 1e-3 mm.
            assert!(
                differ * 100 <= image.pixels.len(),
                "{view:?} {side}: {differ} pixels differ from the twin"
            );
        }
        // Both solid boxes show, through the envelope's coincident faces.
        if view == View::Instance {
            for i in [A as u32, B as u32] {
                let c = id_colour(i).as_vec3().to_array();
                assert!(a.pixels.contains(&c), "instance {i} not visible");
            }
        }
    }
}

/// The legend's colours by name in a detector view of the nested boxes coloured by volume,
/// the envelope hidden (so no shell tints what is behind it).
fn by_volume() -> RenderSettings {
    RenderSettings {
        detector: DetectorStyle {
            color_by: Some(ColorBy::Volume),
            hide: vec!["Envelope".into()],
            ..Default::default()
        },
        ..Default::default()
    }
}

#[test]
fn the_png_legend_shows_the_json_legend_colours_in_order() {
    let dir = tempfile::tempdir().unwrap();
    let gdml = dir.path().join("boxes.gdml");
    std::fs::write(&gdml, nested_boxes(0.0)).unwrap();
    let out = dir.path().join("boxes.npy");
    let run = hytrace(
        &[
            "render",
            gdml.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
            "--size",
            "16x12",
            "--spp",
            "1",
            "--color-by",
            "volume",
            "--hide",
            "Envelope",
        ],
        &[],
    );
    assert!(run.status.success(), "{}", stderr(&run));
    let json: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.path().join("boxes.legend.json")).unwrap(),
    )
    .unwrap();
    let expected: Vec<[u8; 3]> = json["entries"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| serde_json::from_value(e["srgb8"].clone()).unwrap())
        .collect();
    assert_eq!(expected.len(), 2, "{json}");
    // Swatches: runs of 16 equal pixels down the column at x = 16 (their middle) other
    // than the paper's colour of the top left corner; each row has text to its right.
    let (w, h, rgb) = read_png(&dir.path().join("boxes.legend.png"));
    let at = |x: u32, y: u32| -> [u8; 3] {
        let k = 3 * (y * w + x) as usize;
        [rgb[k], rgb[k + 1], rgb[k + 2]]
    };
    let paper = at(0, 0);
    let mut swatches = Vec::new();
    let mut y = 0;
    while y < h {
        let c = at(16, y);
        let run = (y..h).take_while(|&v| at(16, v) == c).count() as u32;
        if c != paper && run == 16 {
            swatches.push(c);
            let ink = (y..y + 16).any(|v| (32..w).any(|x| at(x, v) == [255; 3]));
            assert!(ink, "no name beside the swatch at row {y}");
        }
        y += run;
    }
    assert_eq!(swatches, expected);
}

#[test]
fn drawn_volumes_show_their_legend_colours() {
    let dir = tempfile::tempdir().unwrap();
    let (f, mut spec) = load_text(dir.path(), "boxes.gdml", &nested_boxes(0.0));
    let legend = by_volume().apply(&f, &mut spec).unwrap().unwrap();
    // White light from one direction (no sky; diffuse surfaces take direct light only): a
    // lit pixel is its surface's colour times one grey level.
    spec.lights = vec![Light::Directional {
        direction: [-0.3, 0.4, -1.0],
        irradiance: [3.0; 3],
    }];
    spec.settings.size = [64, 48];
    spec.settings.spp = 1;
    let shaded = render_cpu(&f, &spec);
    spec.settings.view = View::Instance;
    let ids = render_cpu(&f, &spec);
    let mut checked = [0; 2];
    for (k, volume) in [A, B].into_iter().enumerate() {
        let name = &spec.volumes[volume].logical;
        let entry = legend.entries.iter().find(|e| &e.name == name).unwrap();
        let id = id_colour(volume as u32).as_vec3().to_array();
        for (p, q) in shaded.pixels.iter().zip(&ids.pixels) {
            if *q != id || p.iter().all(|&c| c < 1e-3) {
                continue;
            }
            let grey = p[0] as f64 / entry.colour[0];
            for c in 0..3 {
                let expected = grey * entry.colour[c];
                assert!(
                    (p[c] as f64 - expected).abs() <= 1e-4 + 1e-3 * expected,
                    "{name}: pixel {p:?} is not a grey level times {:?}",
                    entry.colour
                );
            }
            checked[k] += 1;
        }
    }
    assert!(checked.iter().all(|&n| n > 20), "{checked:?} lit pixels");
}

/// How the default camera frames what is drawn, from the pixels that show a volume.
#[derive(Clone, Copy, Debug)]
struct Framing {
    /// The larger of the fractions of the width and the height their bounding rectangle
    /// spans (small: framed from too far).
    span: f64,
    /// The fraction of the image's border pixels among them (large: framed too close).
    border: f64,
}

impl Framing {
    /// The framing of the pixels `shown` accepts (by index) of `image`.
    fn of(image: &Image, shown: impl Fn(usize) -> bool) -> Framing {
        let (w, h) = (image.width as usize, image.height as usize);
        let shown = |i: usize, j: usize| shown(j * w + i);
        let (mut lo, mut hi) = ([w, h], [0, 0]);
        let mut border = 0;
        for j in 0..h {
            for i in 0..w {
                if shown(i, j) {
                    lo = [lo[0].min(i), lo[1].min(j)];
                    hi = [hi[0].max(i + 1), hi[1].max(j + 1)];
                    border += usize::from(i == 0 || j == 0 || i == w - 1 || j == h - 1);
                }
            }
        }
        let span = |k: usize, n: usize| hi[k].saturating_sub(lo[k]) as f64 / n as f64;
        Framing {
            span: span(0, w).max(span(1, h)),
            border: border as f64 / (2 * (w + h) - 4) as f64,
        }
    }
}

/// Framing limits of every corpus file's default view: what is drawn spans at least this
/// much of the width or height (the least: cmse.gdml's detector, 19%, framed without the
/// 900 m beam line around it; most files above 45%)...
const MIN_SPAN: f64 = 0.15;
/// ... and what is drawn solid touches at most this fraction of the border (a shell may
/// surround the camera: an envelope far larger than its contents).
const MAX_BORDER: f64 = 0.1;

#[test]
fn every_corpus_file_shows_more_than_one_volume_when_it_places_several() {
    let dir = shared_gdml_dir();
    let files = shared_gdml_files();
    let (mut failed, mut framed_badly) = (Vec::new(), Vec::new());
    for path in &files {
        let name = path.strip_prefix(&dir).unwrap().display().to_string();
        let (f, mut spec) = load_render_scene(Some(path), &GdmlOptions::default())
            .unwrap_or_else(|e| panic!("{name}: {e:#}"));
        spec.settings.size = [128, 96];
        spec.settings.spp = 1;
        spec.settings.view = View::Instance;
        let image = render_cpu(&f, &spec);
        // The instance view colours each placement by its index: map colours back. At
        // 128x96, the smallest size at which cmse.gdml's detector (20 m along a 900 m beam
        // line) shows its parts.
        let colours: std::collections::HashMap<[u32; 3], u32> = (0..f.inst.len() as u32)
            .map(|i| (id_colour(i).as_vec3().to_array().map(f32::to_bits), i))
            .collect();
        let instance_at: Vec<Option<usize>> = image
            .pixels
            .iter()
            .map(|p| colours.get(&p.map(f32::to_bits)).map(|&i| i as usize))
            .collect();
        let drawn = Framing::of(&image, |k| instance_at[k].is_some());
        let solid = Framing::of(&image, |k| {
            instance_at[k].is_some_and(|i| !spec.instance_materials[i].is_see_through())
        });
        let mut seen: Vec<usize> = instance_at.iter().flatten().copied().collect();
        seen.sort_unstable();
        seen.dedup();
        let placed = f.inst.len() - 1;
        eprintln!(
            "{name:<60} {placed:>6} placed volumes, {:>4} visible, spanning {:>3.0}% of the image, solid on {:>3.0}% of its border",
            seen.len(),
            100.0 * drawn.span,
            100.0 * solid.border
        );
        if placed > 1 && seen.len() < 2 {
            failed.push(name.clone());
        }
        if drawn.span < MIN_SPAN || solid.border > MAX_BORDER {
            framed_badly.push(format!("{name}: {drawn:?} {solid:?}"));
        }
        // simple-cms.gdml nests its envelopes around one thin solid, the beam pipe: the
        // camera frames them all, so none is cut off by the image's border.
        if name.ends_with("simple-cms.gdml") && drawn.border > 0.0 {
            framed_badly.push(format!("{name}: envelopes cut off, {drawn:?}"));
        }
    }
    assert!(failed.is_empty(), "show one volume or none: {failed:?}");
    assert!(
        framed_badly.is_empty(),
        "drawn volumes cover too little: {framed_badly:?}"
    );
}
