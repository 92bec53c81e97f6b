//! `[gdml.NAME]` entries of scene files: a GDML file placed any number of times traces, copy
//! by copy, as the file alone does (distances, instances, copy numbers, boundaries), gets
//! its render materials and a transparent world, and bad entries are refused with an error
//! naming the scene file and the entry.

mod common;

use std::path::Path;

use common::{repo, unit, Random, Rng};
use hytrace_csg::Ray;
use hytrace_foundry::gdml::GdmlOptions;
use hytrace_foundry::{pack_label, Foundry, Transform64, UNSET};
use hytrace_trace::cpu::{CpuScene, Hit};
use hytrace_trace::scene::{load_gdml_scene, load_toml_render_scene, render_scene_from_toml};

/// The two repository GDML files: Geant4's harder features, and the render example (with
/// an optical surface).
const FILES: [&str; 2] = [
    "tests/data/gdml/coverage.gdml",
    "scenes/render/detector.gdml",
];

/// The boundary of instance `i` as names: outer material, outer and inner surfaces, inner
/// material.
fn boundary_names(f: &Foundry, i: u32) -> Option<[Option<String>; 4]> {
    let b = f
        .optics
        .boundaries
        .get(f.inst[i as usize].boundary as usize)?;
    let material = |m: u32| f.optics.materials.get(m as usize).map(|m| m.name.clone());
    let surface = |s: u32| f.optics.surfaces.get(s as usize).map(|s| s.name.clone());
    Some([
        material(b.outer_material),
        surface(b.outer_surface),
        surface(b.inner_surface),
        material(b.inner_material),
    ])
}

fn trace(scene: &CpuScene<f64>, origin: [f64; 3], direction: [f64; 3]) -> Option<Hit<f64>> {
    let ray = Ray::from_f64(origin, direction);
    scene.trace(&ray, 0.0, f64::INFINITY)
}

fn gdml_file(path: &str) -> (std::path::PathBuf, Foundry) {
    let path = repo(path);
    let f = load_gdml_scene(&path, &GdmlOptions::default()).unwrap();
    (path, f)
}

#[test]
fn placed_copies_trace_as_the_file_alone_moved() {
    for file in FILES {
        let (path, alone) = gdml_file(file);
        let placements = [
            Transform64::translation([20000.0, 0.0, 0.0]),
            Transform64::translation([-20000.0, 5000.0, 300.0])
                .compose(&Transform64::rotation([0.0, 0.0, 1.0], 90f64.to_radians())),
        ];
        // A CSG solid first, so the GDML's solids, instances and boundaries all move.
        let text = format!(
            r#"
[solids.ball]
shape = "sphere(100)"

[gdml.det]
file = "{}"

[[place]]
solid = "ball"
translate = [0, 30000, 0]

[[place]]
solid = "det"
translate = [20000, 0, 0]

[[place]]
solid = "det"
translate = [-20000, 5000, 300]
rotate = [0, 0, 1, 90]
"#,
            path.file_name().unwrap().to_str().unwrap()
        );
        let (f, _) = render_scene_from_toml(&text, "scene.toml", path.parent().unwrap()).unwrap();
        let n = alone.inst.len() as u32;
        assert_eq!(f.inst.len() as u32, 1 + 2 * n, "{file}");
        assert_eq!(f.solid.len(), 1 + alone.solid.len(), "{file}");
        let merged = CpuScene::<f64>::new(&f).unwrap();
        let single = CpuScene::<f64>::new(&alone).unwrap();

        // Rays from inside the world (in every volume of it) and from outside towards it.
        let bounds = alone.solid[alone.inst[0].solid as usize]
            .aabb
            .map(f64::from);
        let mut rng = Rng(0x5eed ^ file.len() as u64);
        let (mut hits, mut rays) = (0, 0);
        for k in 0..2000 {
            let mut origin: [f64; 3] =
                std::array::from_fn(|a| bounds[a] + rng.uniform() * (bounds[a + 3] - bounds[a]));
            let direction = unit([
                rng.uniform() - 0.5,
                rng.uniform() - 0.5,
                rng.uniform() - 0.5,
            ]);
            if k % 4 == 0 {
                // From outside, aimed at a point of the world.
                let back = 2.0 * (bounds[3] - bounds[0]).max(bounds[5] - bounds[2]);
                origin = std::array::from_fn(|a| origin[a] - back * direction[a]);
            }
            let want = trace(&single, origin, direction);
            for (copy, p) in placements.iter().enumerate() {
                let moved = p.apply_point(origin);
                let turned = p.apply_vector(direction);
                let got = trace(&merged, moved, turned);
                rays += 1;
                let (Some(w), Some(g)) = (want, got) else {
                    assert_eq!(
                        want.is_some(),
                        got.is_some(),
                        "{file}: ray {k}, copy {copy}"
                    );
                    continue;
                };
                hits += 1;
                let at = format!("{file}: ray {k} copy {copy}: {w:?} vs {g:?}");
                assert!((w.t - g.t).abs() <= 1e-6 * (1.0 + w.t), "{at}");
                let base = 1 + copy as u32 * n;
                assert_eq!(g.instance, base + w.instance, "{at}");
                let normal = p.apply_vector(w.normal.to_f64());
                let gn = g.normal.to_f64();
                assert!((0..3).all(|a| (normal[a] - gn[a]).abs() < 1e-9), "{at}");
                let (wi, gi) = (
                    &alone.inst[w.instance as usize],
                    &f.inst[g.instance as usize],
                );
                assert_eq!(wi.copy_number, gi.copy_number, "{at}");
                assert_eq!(
                    boundary_names(&alone, w.instance),
                    boundary_names(&f, g.instance),
                    "{at}"
                );
            }
        }
        assert!(hits > rays / 2, "{file}: {hits} of {rays} rays hit");
    }
}

#[test]
fn an_unplaced_entry_is_the_file_alone_with_prefixed_solid_names() {
    for file in FILES {
        let (path, mut alone) = gdml_file(file);
        let text = format!("[gdml.det]\nfile = {:?}\n", path.display().to_string());
        let (f, _) = render_scene_from_toml(&text, "scene.toml", Path::new("/")).unwrap();
        for (s, name) in alone.solid.iter_mut().zip(&mut alone.solid_names) {
            *name = format!("det/{name}");
            s.label = pack_label(name);
        }
        assert_eq!(f, alone, "{file}");
    }
}

#[test]
fn render_materials_follow_solid_and_logical_volume_names_and_the_world_is_transparent() {
    let (f, spec) = load_toml_render_scene(&repo("scenes/render/gdml.toml")).unwrap();
    assert_eq!(
        spec.transparent_solids,
        vec!["detector/WorldBox".to_string()]
    );
    let material = |solid: &str| spec.solid_materials.get(solid).map(String::as_str);
    // `PMT`, `Water` and `Source` are logical volumes, standing for their solids.
    assert_eq!(material("detector/PMTBulb"), Some("cathode"));
    assert_eq!(material("detector/WaterTube"), Some("water"));
    assert_eq!(material("detector/SourceBall"), Some("gold"));
    // The entry's `material` for the others.
    assert_eq!(material("detector/TankWall"), Some("steel"));
    assert_eq!(material("detector/Rod"), Some("steel"));
    assert_eq!(material("floor"), Some("grey"));
    // Two copies of the hierarchy, their worlds without a mother.
    let worlds: Vec<_> = (0..f.inst.len())
        .filter(|&i| f.inst_mother[i].index == UNSET)
        .map(|i| f.solid_names[f.inst[i].solid as usize].as_str())
        .collect();
    assert_eq!(worlds, ["floor", "detector/WorldBox", "detector/WorldBox"]);

    // A solid name works as a key too; without `material`, the renderer's default.
    let dir = repo("scenes/render");
    let text = r#"
[gdml.d]
file = "detector.gdml"
materials = { Rod = "red" }
[materials.red]
kind = "diffuse"
colour = [0.8, 0.1, 0.1]
"#;
    let (_, spec) = render_scene_from_toml(text, "scene.toml", &dir).unwrap();
    let assigned: Vec<_> = spec.solid_materials.iter().collect();
    assert_eq!(assigned, [(&"d/Rod".to_string(), &"red".to_string())]);
}

#[test]
fn bad_gdml_entries_are_refused_naming_the_scene_file_and_the_entry() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::copy(
        repo("scenes/render/detector.gdml"),
        dir.path().join("detector.gdml"),
    )
    .unwrap();
    std::fs::write(
        dir.path().join("broken.gdml"),
        "<gdml><solids><box name=\"b\" x=\"1\"",
    )
    .unwrap();
    let materials = "[materials.steel]\nkind = \"diffuse\"\ncolour = [0.5, 0.5, 0.5]\n";
    let cases = [
        ("file = \"missing.gdml\"", "missing.gdml"),
        ("file = \"broken.gdml\"", "broken.gdml"),
        (
            "file = \"detector.gdml\"\nmaterial = \"gold\"",
            "unknown material `gold`",
        ),
        (
            "file = \"detector.gdml\"\nmaterials = { PMT = \"glass\" }",
            "unknown material `glass`",
        ),
        (
            "file = \"detector.gdml\"\nmaterials = { Nothing = \"steel\" }",
            "`Nothing` is neither a solid nor a logical volume",
        ),
        (
            "file = \"detector.gdml\"\nmaterials = { PMT = \"steel\", PMTBulb = \"other\" }\n\
             [materials.other]\nkind = \"diffuse\"\ncolour = [0.1, 0.1, 0.1]",
            "two materials",
        ),
    ];
    for (entry, why) in cases {
        let scene = dir.path().join("scene.toml");
        std::fs::write(&scene, format!("[gdml.det]\n{entry}\n{materials}")).unwrap();
        let e = format!("{:#}", load_toml_render_scene(&scene).unwrap_err());
        assert!(e.contains(why), "{entry}: expected `{why}` in: {e}");
        assert!(
            e.contains("scene.toml") && e.contains("gdml `det`"),
            "{entry}: the error names the file and the entry: {e}"
        );
    }

    let collisions = [
        (
            "[gdml.det]\nfile = \"detector.gdml\"\n[solids.det]\nshape = \"sphere(1)\"",
            "`det` names two entries",
        ),
        (
            "[gdml.det]\nfile = \"detector.gdml\"\n[solids.\"det/Rod\"]\nshape = \"sphere(1)\"",
            "gdml `det`: its solid `det/Rod` has the name of a solid of entry `det/Rod`",
        ),
        (
            "[gdml.det]\nfile = \"detector.gdml\"\n[[place]]\nsolid = \"det\"\ncopy = 4",
            "gdml `det` keeps its own copy numbers",
        ),
    ];
    for (text, why) in collisions {
        let e = format!(
            "{:#}",
            render_scene_from_toml(text, "scene.toml", dir.path()).unwrap_err()
        );
        assert!(e.contains(why) && e.contains("scene.toml"), "{text}: {e}");
    }
}
