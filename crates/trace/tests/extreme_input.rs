//! Inputs far outside ordinary scenes end in a correct result or a clear error, in bounded
//! time and memory:
//! - scenes whose boxes a PLOC build chains into trees deeper than the traversal stacks
//!   (obvhs went one level per box): many placements of one solid at one position, and the
//!   triangle fan one large OBJ polygon becomes. They used to be refused ("the BVH over 70
//!   boxes is 69 levels deep"); they now build and trace, in f32 and f64, with the answers
//!   the geometry gives, and the GPU's walk of the same trees gives the CPU's f32 answers;
//! - CSG expressions in scene files nested thousands of levels deep (they used to overflow
//!   the stack): chains of one operator become shallow trees, other nesting is refused by
//!   name;
//! - convex polyhedra of thousands of planes: bounded in quadratic time (the meets of every
//!   three planes took quartic time), more than the limit refused by name;
//! - media so dense that tracking estimators would look the density up astronomically often
//!   per sample: refused by name (the run did not end), while the exact estimator answers;
//! - 10^5 mutated scene files: each builds or is refused with an error naming the file;
//! - ray rows of every special value (NaN, infinities, zero, subnormal, huge): accepted
//!   exactly when every component is usable, normalized, or refused naming the row;
//! - a GDML hierarchy tens of thousands of volumes deep (reading it used to take quadratic
//!   time: every volume's line number was found by scanning the file from its start).

mod common;

use std::path::Path;

use hytrace_foundry::Foundry;

use hytrace_foundry::gdml::GdmlOptions;
use hytrace_testkit::{Random, SplitMix64, XorShift64};
use hytrace_trace::scan::{rays_from_rows, scan, scan_transmittance, Precision, RayRow};
use hytrace_trace::scene::{load_scene, obj_to_foundry, scene_from_toml};
use hytrace_volume::{Estimator, TransmittanceParams};

/// In f32 the GPU scan kernel (where an adapter opens) answers every ray as the CPU's
/// f32 scan did.
fn gpu_agrees(f: &Foundry, rays: &[RayRow], cpu: &[[f64; 4]]) {
    let Some(gpu) = common::gpu_answers(f, rays) else {
        return;
    };
    for ((r, g), c) in rays.iter().zip(&gpu).zip(cpu) {
        let t = g.map_or(f64::INFINITY, |h| f64::from(h.t));
        assert_eq!(t, c[3], "GPU against CPU, ray {r:?}");
    }
}

/// Rays along +z from below, on a grid over `[-half, half]^2`.
fn rays_up(count: usize, half: f64) -> Vec<RayRow> {
    (0..count * count)
        .map(|i| {
            let (a, b) = ((i % count) as f64, (i / count) as f64);
            let at = |u: f64| -half + 2.0 * half * (u + 0.5) / count as f64;
            RayRow {
                origin: [at(a), at(b), -100.0],
                direction: [0.0, 0.0, 1.0],
                tmin: 0.0,
                tmax: f64::INFINITY,
            }
        })
        .collect()
}

#[test]
fn coincident_placements_build_and_trace_in_f32_and_f64() {
    let mut text = String::from("[solids.b]\nshape = \"box(10, 10, 10)\"\n");
    for _ in 0..300 {
        text.push_str("\n[[place]]\nsolid = \"b\"\n");
    }
    let f = scene_from_toml(&text, "coincident.toml", Path::new(".")).unwrap();
    let rays = rays_up(12, 8.0);
    for precision in [Precision::F32, Precision::F64] {
        let (result, _) = scan(&f, &rays, precision).unwrap();
        for (r, h) in rays.iter().zip(&result.hits) {
            let inside = r.origin[0].abs() < 5.0 && r.origin[1].abs() < 5.0;
            let want = if inside { 95.0 } else { f64::INFINITY };
            assert_eq!(h[3], want, "{precision:?} ray from {:?}", r.origin);
        }
        if precision == Precision::F32 {
            gpu_agrees(&f, &rays, &result.hits);
        }
    }
}

#[test]
fn a_large_polygon_fan_builds_and_traces_in_f32_and_f64() {
    // One face of 1000 vertices on the unit circle at z = 1: a fan of 998 triangles
    // (PLOC chained such fans hundreds of levels deep).
    let n = 1000;
    let mut obj = String::new();
    for i in 0..n {
        let a = std::f64::consts::TAU * i as f64 / n as f64;
        obj.push_str(&format!("v {} {} 1\n", a.cos(), a.sin()));
    }
    obj.push('f');
    for i in 1..=n {
        obj.push_str(&format!(" {i}"));
    }
    obj.push('\n');
    let f = obj_to_foundry(obj.as_bytes()).unwrap();
    let rays = rays_up(40, 1.2);
    // The polygon's inscribed radius: every chord stays outside it.
    let inner = (std::f64::consts::PI / n as f64).cos();
    for precision in [Precision::F32, Precision::F64] {
        let (result, _) = scan(&f, &rays, precision).unwrap();
        for (r, h) in rays.iter().zip(&result.hits) {
            let radius = r.origin[0].hypot(r.origin[1]);
            if radius < inner - 1e-6 {
                assert!((h[3] - 101.0).abs() < 1e-9, "{precision:?} {r:?}: {}", h[3]);
            } else if radius > 1.0 + 1e-6 {
                assert_eq!(h[3], f64::INFINITY, "{precision:?} {r:?}");
            }
        }
        if precision == Precision::F32 {
            gpu_agrees(&f, &rays, &result.hits);
        }
    }
}

#[test]
fn deep_expressions_in_scene_files_build_or_fail_clearly() {
    let scene =
        |shape: &str| format!("[solids.s]\nshape = \"{shape}\"\n\n[[place]]\nsolid = \"s\"\n");
    // 2000 unions nested to the right: one list of spheres along x.
    let parts = 2000;
    let mut shape = format!("sphere(1).translate({}, 0, 0)", 3 * (parts - 1));
    for i in (0..parts - 1).rev() {
        shape = format!("sphere(1).translate({}, 0, 0) + ({shape})", 3 * i);
    }
    let f = scene_from_toml(&scene(&shape), "right.toml", Path::new(".")).unwrap();
    let rays: Vec<RayRow> = (0..parts)
        .map(|i| RayRow {
            origin: [3.0 * i as f64, 0.0, -10.0],
            direction: [0.0, 0.0, 1.0],
            tmin: 0.0,
            tmax: f64::INFINITY,
        })
        .collect();
    let (result, _) = scan(&f, &rays, Precision::F64).unwrap();
    assert!(result.hits.iter().all(|h| h[3] == 9.0));
    // Differences nested to the right 5000 deep: an error naming the file, the solid and
    // the depth, with the shape abridged.
    let mut shape = String::from("sphere(1)");
    for _ in 0..5000 {
        shape = format!("sphere(2) - ({shape})");
    }
    let e = format!(
        "{:#}",
        scene_from_toml(&scene(&shape), "diff.toml", Path::new(".")).unwrap_err()
    );
    assert!(
        e.contains("diff.toml: solid `s`") && e.contains("more than 1000 levels"),
        "{e}"
    );
    assert!(e.len() < 600, "{} bytes", e.len());
}

/// GDML text of `depth` boxes each placed in the next larger (sides `2 (depth - i) + 2`).
fn nested_boxes_gdml(depth: usize) -> String {
    let mut out = String::from(
        "<?xml version=\"1.0\"?>\n<gdml>\n<define/>\n<materials><material name=\"M\" Z=\"1\">\
         <D value=\"1\"/><atom value=\"1\"/></material></materials>\n<solids>\n",
    );
    for i in 0..depth {
        let side = 2 * (depth - i) + 2;
        out.push_str(&format!(
            "<box name=\"b{i}\" x=\"{side}\" y=\"{side}\" z=\"{side}\" lunit=\"mm\"/>\n"
        ));
    }
    out.push_str("</solids>\n<structure>\n");
    for i in (0..depth).rev() {
        out.push_str(&format!(
            "<volume name=\"v{i}\"><materialref ref=\"M\"/><solidref ref=\"b{i}\"/>"
        ));
        if i + 1 < depth {
            out.push_str(&format!(
                "<physvol><volumeref ref=\"v{}\"/></physvol>",
                i + 1
            ));
        }
        out.push_str("</volume>\n");
    }
    out.push_str("</structure>\n<setup name=\"Default\" version=\"1.0\"><world ref=\"v0\"/></setup>\n</gdml>\n");
    out
}

#[test]
fn a_gdml_hierarchy_thousands_of_volumes_deep_reads_and_traces() {
    let depth = 20_000;
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("deep.gdml");
    std::fs::write(&file, nested_boxes_gdml(depth)).unwrap();
    let f = load_scene(Some(&file), &GdmlOptions::default()).unwrap();
    assert_eq!(f.inst.len(), depth);
    // From the centre along +x: the innermost box's face at x = 2 (sides 4).
    let ray = RayRow {
        origin: [0.0; 3],
        direction: [1.0, 0.0, 0.0],
        tmin: 0.0,
        tmax: f64::INFINITY,
    };
    for precision in [Precision::F32, Precision::F64] {
        let (result, _) = scan(&f, &[ray], precision).unwrap();
        assert_eq!(result.hits[0][3], 2.0, "{precision:?}");
    }
}

/// A polyhedron of `n` planes tangent to a sphere of radius 10 (Fibonacci normals), as
/// the text of a scene file.
fn tangent_polyhedron_scene(n: usize) -> String {
    let planes: Vec<String> = (0..n)
        .map(|i| {
            let z = 1.0 - (2 * i + 1) as f64 / n as f64;
            let phi = i as f64 * std::f64::consts::PI * (3.0 - 5f64.sqrt());
            let r = (1.0 - z * z).sqrt();
            format!("{}, {}, {z}, 10", r * phi.cos(), r * phi.sin())
        })
        .collect();
    format!(
        "[solids.p]\nshape = \"polyhedron({})\"\n\n[[place]]\nsolid = \"p\"\n",
        planes.join(", ")
    )
}

#[test]
fn polyhedra_of_thousands_of_planes_build_or_fail_clearly() {
    // 2000 planes tangent to a ball of radius 10.
    let f = scene_from_toml(&tangent_polyhedron_scene(2000), "p.toml", Path::new(".")).unwrap();
    let rays = rays_up(6, 5.0);
    let (result, _) = scan(&f, &rays, Precision::F64).unwrap();
    for (r, h) in rays.iter().zip(&result.hits) {
        let sphere = 100.0 - (100.0 - r.origin[0].hypot(r.origin[1]).powi(2)).sqrt();
        // The polyhedron holds the ball and lies within 1% of its radius of it.
        assert!(
            h[3] <= sphere + 1e-9 && h[3] > sphere - 0.1,
            "{r:?}: {}",
            h[3]
        );
    }
    let e = format!(
        "{:#}",
        scene_from_toml(&tangent_polyhedron_scene(5000), "many.toml", Path::new(".")).unwrap_err()
    );
    assert!(
        e.contains("many.toml") && e.contains("5000 planes, more than 4096"),
        "{}",
        &e[e.len().saturating_sub(300)..]
    );
}

#[test]
fn tracking_through_an_astronomically_dense_medium_is_refused_by_name() {
    let text = "[volumes.fog]\nsource = \"box:50,50,50,10,2\"\ndensity_scale = 1e300\n\n\
                [[place]]\nsolid = \"fog\"\n";
    let f = scene_from_toml(text, "fog.toml", Path::new(".")).unwrap();
    let rays = rays_up(3, 20.0);
    for estimator in [Estimator::Delta, Estimator::Ratio, Estimator::Residual] {
        let e = format!(
            "{:#}",
            scan_transmittance(
                &f,
                &rays,
                Precision::F64,
                &TransmittanceParams::new(estimator)
            )
            .unwrap_err()
        );
        assert!(
            e.contains("optical depth") && e.contains("exact estimator"),
            "{e}"
        );
    }
    // The exact estimator integrates it: nothing gets through the fog's core.
    let run = scan_transmittance(
        &f,
        &rays,
        Precision::F64,
        &TransmittanceParams::new(Estimator::Exact),
    )
    .unwrap();
    assert_eq!(run.values[4], 0.0, "{:?}", run.values);
}

#[test]
fn mutated_scene_files_give_errors_never_panics() {
    let seed = "[solids.a]\nshape = \"(tube(1, 5, -3, 3) - sphere(2).translate(0, 0, 3)) * !box(2, 2, 9)\"\n\n\
                [solids.b]\nshape = \"polyhedron(1,0,0,1, -1,0,0,1, 0,1,0,1, 0,-1,0,1, 0,0,1,1, 0,0,-1,1)\"\n\n\
                [[place]]\nsolid = \"a\"\ntranslate = [0, 0, 10]\nrotate = [0, 1, 0, 30]\n\n\
                [[place]]\nsolid = \"b\"\ntranslate = [5, 0, 0]\n";
    scene_from_toml(seed, "seed.toml", Path::new(".")).unwrap();
    let alphabet = b"()[]{}=\"+-*!.,0123456789e \nabpstx#";
    let mut rng = XorShift64(0x2545_f491_4f6c_dd1d);
    let mut next = move || rng.next_u64();
    let (mut built, mut refused) = (0, 0);
    // 10^5 mutations: each builds or is refused with an error naming the file.
    for _ in 0..100_000 {
        let mut bytes = seed.as_bytes().to_vec();
        for _ in 0..1 + next() % 4 {
            let at = (next() % bytes.len() as u64) as usize;
            bytes[at] = alphabet[(next() % alphabet.len() as u64) as usize];
        }
        let text = String::from_utf8(bytes).unwrap();
        match scene_from_toml(&text, "fuzz.toml", Path::new(".")) {
            Ok(_) => built += 1,
            Err(e) => {
                assert!(format!("{e:#}").contains("fuzz.toml"), "{e:#}");
                refused += 1;
            }
        }
    }
    assert!(
        built > 1000 && refused > 1000,
        "{built} built, {refused} refused"
    );
}

#[test]
fn ray_rows_of_special_values_are_accepted_exactly_when_usable() {
    let specials = [
        0.0,
        -0.0,
        1.0,
        -2.5,
        f64::MIN_POSITIVE,
        5e-324,
        1e-300,
        1e300,
        f64::MAX,
        -f64::MAX,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::NAN,
    ];
    let mut rng = SplitMix64(0x0005_eed0_f0a5);
    let cases = hytrace_testkit::fuzz_cases(100_000);
    let (mut accepted, mut refused) = (0, 0);
    for case in 0..cases {
        // One to three rows; the last one is the mutated one.
        let rows: Vec<[f64; 8]> = (0..1 + rng.next_u64() % 3)
            .map(|_| {
                std::array::from_fn(|c| match rng.next_u64() % 4 {
                    0 => specials[(rng.next_u64() % specials.len() as u64) as usize],
                    _ if c == 7 => 1e3 + rng.uniform(),
                    _ => rng.uniform() * 2.0 - 1.0,
                })
            })
            .collect();
        // The reference: what a ray needs, written out independently of the reader.
        let usable = |r: &[f64; 8]| {
            let d = [r[4], r[5], r[6]];
            r[..3].iter().all(|v| v.is_finite())
                && d.iter().all(|v| v.is_finite())
                && d.iter().any(|&v| v != 0.0)
                && r[3].is_finite()
                && !r[7].is_nan()
                && r[3] < r[7]
        };
        let first_bad = rows.iter().position(|r| !usable(r));
        match (rays_from_rows(&rows, "case.npy"), first_bad) {
            (Ok(rays), None) => {
                for (ray, row) in rays.iter().zip(&rows) {
                    let n = ray.direction.iter().map(|v| v * v).sum::<f64>();
                    assert!((n - 1.0).abs() < 1e-12, "case {case}: {row:?}");
                    assert_eq!(ray.origin, [row[0], row[1], row[2]]);
                    assert_eq!((ray.tmin, ray.tmax), (row[3], row[7]));
                }
                accepted += 1;
            }
            (Err(e), Some(i)) => {
                let msg = e.to_string();
                assert!(
                    msg.starts_with(&format!("case.npy: ray {i}:")),
                    "case {case}: {msg}"
                );
                refused += 1;
            }
            (got, want) => {
                panic!("case {case}: {rows:?}: got {got:?}, the first unusable row is {want:?}")
            }
        }
    }
    assert!(
        accepted > cases / 20 && refused > cases / 4,
        "{accepted} accepted, {refused} refused"
    );
}
