//! The GPU scan kernel against its CPU twin (`CpuScene::<f32>::trace`), ray by ray, on
//! lavapipe in CI: CSG scenes, meshes, a mixed scene, hierarchical GDML scenes and the
//! shared GDML files; plus the kernel's composition (only what a scene uses), and the
//! `scan --backend gpu|auto` command line.

mod common;

use std::path::Path;

use common::{
    check, gpu_answers, gpu_run, gpu_stats, hytrace, mesh_obj, mesh_scene_rays, rays_for,
    read_values, repo,
};
use hytrace_foundry::gdml::GdmlOptions;
use hytrace_foundry::Foundry;
use hytrace_trace::cpu::{CpuScene, Hit};
use hytrace_trace::gpu::{GpuContext, GpuTracer};
use hytrace_trace::scan::RayRow;
use hytrace_trace::scene::{default_scene, load_scene, obj_to_foundry};

fn check_gpu(name: &str, f: &Foundry, rays: &[RayRow]) {
    if let Some(got) = gpu_answers(f, rays) {
        check(name, f, rays, &got);
    }
}

fn scene_file(path: &str) -> Foundry {
    load_scene(Some(&repo(path)), &GdmlOptions::default()).unwrap()
}

#[test]
fn gpu_matches_cpu_on_the_default_scene() {
    let f = default_scene().unwrap();
    check_gpu("default", &f, &rays_for(&f, 60, 8000));
}

#[test]
fn gpu_matches_cpu_on_the_csg_showcase() {
    let f = scene_file("scenes/csg-showcase.toml");
    check_gpu("csg-showcase", &f, &rays_for(&f, 60, 8000));
}

#[test]
fn gpu_matches_cpu_on_the_mixed_scene() {
    let f = scene_file("scenes/mixed.toml");
    check_gpu("mixed", &f, &rays_for(&f, 60, 8000));
}

/// The CSG showcase moved 10^6 mm from the origin, along a direction off the axes, with
/// rays about it: the GPU gives its CPU twin's answers there too, and both agree with the
/// CPU's f64 tracer (which the Geant4 oracle checks) within 1e-2 mm on 99.99% of the rays,
/// with no crossing found or lost at grazing incidence beyond that share.
#[test]
fn gpu_matches_cpu_and_f64_far_from_the_origin() {
    let offset = [0.6, -0.48, 0.64].map(|c| c * 1e6);
    let text = std::fs::read_to_string(repo("scenes/csg-showcase.toml")).unwrap();
    let (solids, places) = text.split_at(text.find("[[place]]").unwrap());
    let mut far = solids.to_string();
    for place in places.split("[[place]]").skip(1) {
        let mut translate = [0.0f64; 3];
        let mut kept = String::new();
        for line in place.lines() {
            match line.strip_prefix("translate = ") {
                Some(v) => {
                    let v: Vec<f64> = v
                        .trim_matches(['[', ']'])
                        .split(',')
                        .map(|c| c.trim().parse().unwrap())
                        .collect();
                    translate = [v[0], v[1], v[2]];
                }
                None => kept.push_str(&format!("{line}\n")),
            }
        }
        let t = [0, 1, 2].map(|k| translate[k] + offset[k]);
        far.push_str(&format!(
            "[[place]]\ntranslate = [{}, {}, {}]{kept}",
            t[0], t[1], t[2]
        ));
    }
    let f = hytrace_trace::scene::scene_from_toml(&far, "far showcase", &repo("scenes")).unwrap();
    let rays = rays_for(&f, 60, 8000);
    let Some(gpu) = gpu_answers(&f, &rays) else {
        return;
    };
    check("far showcase", &f, &rays, &gpu);
    let exact = CpuScene::<f64>::new(&f).unwrap();
    let (mut hits, mut off) = (0, Vec::new());
    for (i, (r, g)) in rays.iter().zip(&gpu).enumerate() {
        let ray = hytrace_csg::Ray::from_f64(r.origin, r.direction);
        let tmax = if r.tmax.is_finite() {
            r.tmax
        } else {
            f64::INFINITY
        };
        let want = exact.trace(&ray, r.tmin, tmax);
        hits += usize::from(want.is_some());
        let ok = match (want, g) {
            (None, None) => true,
            (Some(w), Some(g)) => (w.t - f64::from(g.t)).abs() <= 1e-2,
            _ => false,
        };
        if !ok {
            off.push(format!("ray {i} {r:?}: f64 {want:?}, gpu {g:?}"));
        }
    }
    eprintln!(
        "far showcase: {} rays, {hits} hits, {} beyond 1e-2 mm of f64",
        rays.len(),
        off.len()
    );
    assert!(hits > rays.len() / 10, "too few hits: {hits}");
    assert!(off.len() * 10_000 <= rays.len(), "{}", off.join("\n"));
}

/// An icosphere, a heightfield and a cube 10^5 mm from the origin.
#[test]
fn gpu_matches_cpu_on_a_mesh_scene() {
    let f = obj_to_foundry(mesh_obj().as_bytes()).unwrap();
    check_gpu("mesh", &f, &mesh_scene_rays(&f));
}

#[test]
fn gpu_matches_cpu_on_a_hierarchical_gdml_scene() {
    let f = scene_file("tests/data/gdml/coverage.gdml");
    check_gpu("coverage.gdml", &f, &rays_for(&f, 60, 8000));
}

/// The kernel carries only what a scene uses: no mesh code for CSG scenes, no CSG code for
/// mesh scenes, no torus crossing search without a torus, and only the primitives the trees use.
#[test]
fn scan_kernels_compose_only_what_the_scene_uses() {
    let Some(ctx) = GpuContext::for_tests() else {
        return;
    };
    let source_of = |f: &Foundry| {
        let cpu = CpuScene::<f32>::new(f).unwrap();
        let tracer = GpuTracer::new(&ctx, &cpu).unwrap();
        (tracer.features().to_vec(), tracer.source().to_string())
    };
    let defines = |src: &str, function: &str| src.contains(&format!("fn {function}("));

    let (features, csg) = source_of(&default_scene().unwrap());
    assert!(
        features.contains(&"torus") && !features.contains(&"mesh"),
        "{features:?}"
    );
    assert!(defines(&csg, "csg_tree_first_crossing") && defines(&csg, "torus_spans"));
    assert!(!defines(&csg, "mesh_first_crossing") && !csg.contains("module mesh/mesh"));
    // Primitives the trees do not use are not dispatched (so never compiled).
    assert!(csg.contains("code == CSG_TORUS") && csg.contains("code == CSG_BOX3"));
    for absent in ["CSG_PARABOLOID", "CSG_THETACUT", "CSG_HYPERBOLOID"] {
        assert!(
            !csg.contains(&format!("code == {absent}")),
            "{absent} dispatched"
        );
    }

    let (features, mesh) = source_of(&obj_to_foundry(mesh_obj().as_bytes()).unwrap());
    assert_eq!(features, ["mesh"]);
    assert!(defines(&mesh, "mesh_first_crossing"));
    assert!(!defines(&mesh, "csg_tree_first_crossing") && !defines(&mesh, "torus_spans"));

    let (features, no_torus) = source_of(&scene_file("scenes/mixed.toml"));
    assert!(!features.contains(&"torus"), "{features:?}");
    assert!(!defines(&no_torus, "torus_spans") && !no_torus.contains("module csg/torus"));
    // Every composed kernel is valid WGSL.
    for src in [&csg, &mesh, &no_torus] {
        let module = naga::front::wgsl::parse_str(src).expect("composed kernel parses");
        naga::valid::Validator::new(
            naga::valid::ValidationFlags::all(),
            naga::valid::Capabilities::all(),
        )
        .validate(&module)
        .expect("composed kernel validates");
    }
}

/// `scan --backend gpu` writes what `--backend cpu` writes (f32, same rays), reports its
/// adapter and GPU timings with `--stats`; f64 is refused, and without an adapter `gpu`
/// fails naming the problem while `auto` falls back to the CPU.
#[test]
fn scan_cli_on_the_gpu() {
    if GpuContext::for_tests().is_none() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let p = |n: &str| dir.path().join(n).display().to_string();
    let scan = |backend: &str, hits: &str, ids: &str, env: &[(&str, &str)]| {
        let args = [
            "scan",
            "default",
            "--sweep",
            "rect",
            "--count",
            "30",
            "--out",
            hits,
            "--ids",
            ids,
            "--stats",
            "--backend",
            backend,
        ];
        hytrace(&args, env)
    };
    let cpu = scan("cpu", &p("cpu.npy"), &p("cpu_ids.npy"), &[]);
    assert!(
        cpu.status.success(),
        "{}",
        String::from_utf8_lossy(&cpu.stderr)
    );
    let gpu = scan("gpu", &p("gpu.npy"), &p("gpu_ids.npy"), &[]);
    let stats = gpu_stats(&gpu);
    assert_eq!(stats["kernel_features"][0], "csg");
    let (want, got) = (
        read_values(Path::new(&p("cpu.npy"))),
        read_values(Path::new(&p("gpu.npy"))),
    );
    assert_eq!(want.len(), got.len());
    assert!(want.len() >= 4 * 100, "{} values", want.len());
    assert!(
        want.iter().skip(3).step_by(4).any(|t| t.is_finite()),
        "no hits"
    );
    for (i, (w, g)) in want.iter().zip(&got).enumerate() {
        assert!(
            w == g || (w - g).abs() <= 1e-4 * w.abs().max(1.0),
            "value {i}: cpu {w} gpu {g}"
        );
    }
    assert_eq!(
        read_values(Path::new(&p("cpu_ids.npy"))),
        read_values(Path::new(&p("gpu_ids.npy")))
    );

    let f64_run = hytrace(
        &[
            "scan",
            "default",
            "--sweep",
            "axis",
            "--count",
            "4",
            "--out",
            &p("f64.npy"),
            "--backend",
            "gpu",
            "--precision",
            "f64",
        ],
        &[],
    );
    assert!(!f64_run.status.success());
    assert!(String::from_utf8_lossy(&f64_run.stderr).contains("GPU backend traces in f32"));
    assert!(!Path::new(&p("f64.npy")).exists());

    // No adapter: WGPU_BACKEND names one this build does not have.
    let none = [("WGPU_BACKEND", "metal")];
    let no_gpu = scan("gpu", &p("none.npy"), &p("none_ids.npy"), &none);
    let err = String::from_utf8_lossy(&no_gpu.stderr);
    assert!(
        !no_gpu.status.success() && err.contains("no GPU adapter found"),
        "{err}"
    );
    assert!(!Path::new(&p("none.npy")).exists());
    let auto = scan("auto", &p("auto.npy"), &p("auto_ids.npy"), &none);
    assert!(
        auto.status.success(),
        "{}",
        String::from_utf8_lossy(&auto.stderr)
    );
    assert!(String::from_utf8_lossy(&auto.stderr).contains("--backend auto scans on the CPU"));
    let stats: serde_json::Value = serde_json::from_slice(&auto.stdout).unwrap();
    assert_eq!(stats["backend"], "cpu");
    assert_eq!(read_values(Path::new(&p("auto.npy"))), want);
}

#[test]
fn rays_past_the_driver_loop_budget_are_traced_again_on_the_cpu() {
    // A stack of 40 000 overlapping triangles in the plane z = 0 and a wall beyond it.
    // Rays in the plane meet every triangle's box and test every triangle (none is hit:
    // the ray lies in its plane), past the 65535 loop iterations lavapipe gives 8
    // invocations together; rays above the plane skip the stack. Both kinds hit the wall.
    // On lavapipe the kernel's probe marks exactly the 8 rays in the plane, the CPU twin
    // traces them again, and every answer equals the f32 CPU scan's; a GPU without such a
    // budget redoes none.
    let Some(ctx) = GpuContext::for_tests() else {
        return;
    };
    let llvmpipe = ctx.describe().contains("llvmpipe");
    let dir = tempfile::tempdir().unwrap();
    let p = |n: &str| dir.path().join(n).display().to_string();
    let mut obj = String::new();
    let n = 40_000;
    for k in 0..n {
        let s = k as f64 * 1e-3;
        obj += &format!(
            "v {} -100 0\nv {} -100 0\nv {s} 100 0\n",
            s - 100.0,
            s + 100.0
        );
    }
    for k in 0..n {
        obj += &format!("f {} {} {}\n", 3 * k + 1, 3 * k + 2, 3 * k + 3);
    }
    std::fs::write(p("stack.obj"), obj).unwrap();
    let scene = "[meshes.stack]\nfile = \"stack.obj\"\n\n[solids.wall]\nshape = \"box(5, 200, 200)\"\n\n\
                 [[place]]\nsolid = \"stack\"\n\n[[place]]\nsolid = \"wall\"\ntranslate = [300, 0, 0]\n";
    std::fs::write(p("stack.toml"), scene).unwrap();
    let rows: Vec<f64> = (0..16)
        .flat_map(|k| {
            let z = if k < 8 { 0.0 } else { 5.0 };
            [-150.0, -40.25 + 0.5 * k as f64, z, 0.0, 1.0, 0.0, 0.0, 1e9]
        })
        .collect();
    hytrace_foundry::npy::write_array(
        Path::new(&p("rays.npy")),
        hytrace_foundry::layout::Scalar::F64,
        &[16, 8],
        bytemuck::cast_slice(&rows),
    )
    .unwrap();
    let args = ["scan", &p("stack.toml"), "--rays", &p("rays.npy")];
    let (gpu, cpu, stats, err) = common::gpu_and_cpu_values(&args, dir.path());
    let redone = stats["gpu_redone_on_cpu"].as_u64().unwrap();
    if llvmpipe {
        assert_eq!(redone, 8, "{stats}");
        assert!(err.contains("loop budget"), "{err}");
    } else {
        assert_eq!(redone, 0, "{stats}");
    }
    // nx ny nz t per ray: every ray hits the wall's face at x = 297.5.
    for k in 0..16 {
        assert!(
            (cpu[4 * k + 3] - 447.5).abs() < 1e-3,
            "ray {k}: t {}",
            cpu[4 * k + 3]
        );
    }
    assert_eq!(gpu, cpu);
}

/// Mesh nodes and triangles above the device's binding limit are split over four buffers
/// each: with the limit lowered under both arrays of the mesh scene (an icosphere, a
/// heightfield and a far cube), the scan gives, ray by ray and bit for bit, what the
/// one-buffer kernel gives; an array beyond four buffers is refused, naming it.
#[test]
fn mesh_arrays_above_the_binding_limit_are_split() {
    let Some(mut ctx) = GpuContext::for_tests() else {
        return;
    };
    let f = obj_to_foundry(mesh_obj().as_bytes()).unwrap();
    let rays = mesh_scene_rays(&f);
    let whole = gpu_run(&ctx, &f, &rays).unwrap();
    let arrays = CpuScene::<f32>::new(&f).unwrap().gpu_arrays().unwrap();
    let nodes = std::mem::size_of_val(arrays.meshes.nodes.as_slice());
    let triangles = std::mem::size_of_val(arrays.meshes.triangles.as_slice());
    // Under both arrays, and above a quarter of the larger: four chunks hold each.
    let limit = nodes.min(triangles) - 64;
    assert!(
        4 * (limit - 48) >= nodes.max(triangles),
        "{nodes} {triangles}"
    );
    ctx.limits.max_storage_buffer_binding_size = limit as u64;
    let split = gpu_run(&ctx, &f, &rays).unwrap();
    for feature in ["chunked_mesh_nodes", "chunked_mesh_triangles"] {
        assert!(!whole.features.contains(&feature), "{:?}", whole.features);
        assert!(split.features.contains(&feature), "{:?}", split.features);
    }
    let (hits, differ) = compare_bits(&whole.hits, &split.hits);
    println!(
        "{} rays ({hits} hits) at a limit of {limit} bytes: {differ} differ",
        rays.len()
    );
    assert!(hits > rays.len() / 10);
    assert_eq!(differ, 0, "split and whole mesh arrays differ");
    // Four chunks of an eighth of the triangles' bytes hold less than they need.
    ctx.limits.max_storage_buffer_binding_size = (triangles / 8) as u64;
    let err = gpu_run(&ctx, &f, &rays).err().unwrap().to_string();
    assert!(err.contains("array `mesh_"), "{err}");
}

/// Hits of `whole`, and answers of `split` not bit for bit those of `whole`.
fn compare_bits(whole: &[Option<Hit<f32>>], split: &[Option<Hit<f32>>]) -> (usize, usize) {
    let bits = |h: &Option<Hit<f32>>| {
        h.as_ref().map(|h| {
            let n = [h.normal.x, h.normal.y, h.normal.z].map(f32::to_bits);
            (h.t.to_bits(), n, h.instance, h.prim)
        })
    };
    let differ = whole.iter().zip(split).filter(|(a, b)| bits(a) != bits(b));
    (whole.iter().flatten().count(), differ.count())
}

/// Every array of a scene is read through its chunks when split: with each array split in
/// four (`split_arrays`, at most four at a time: lavapipe binds at most 32 storage buffers),
/// a hierarchical GDML scene of CSG solids and a mesh scene give, ray by ray and bit for
/// bit, what the one-buffer kernels give.
#[test]
fn every_scene_array_split_in_chunks_gives_the_same_hits() {
    let Some(mut ctx) = GpuContext::for_tests() else {
        return;
    };
    let gdml = scene_file("tests/data/gdml/coverage.gdml");
    let mesh = obj_to_foundry(mesh_obj().as_bytes()).unwrap();
    // Scene, its rays, and the arrays split together in each run.
    type SplitRuns<'a> = &'a [&'a [&'a str]];
    let runs: [(&str, &Foundry, Vec<RayRow>, SplitRuns); 2] = [
        (
            "coverage.gdml",
            &gdml,
            rays_for(&gdml, 60, 3000),
            &[
                &["csg_planes", "csg_nodes", "csg_frames", "csg_trees"],
                &["box_items", "placements", "groups", "group_members"],
                &["box_nodes", "solids", "surface_prims"],
            ],
        ),
        (
            "mesh",
            &mesh,
            mesh_scene_rays(&mesh),
            &[&["mesh_nodes", "mesh_triangles", "meshes", "box_nodes"]],
        ),
    ];
    for (name, f, rays, splits) in runs {
        ctx.split_arrays.clear();
        let whole = gpu_run(&ctx, f, &rays).unwrap();
        assert!(!whole.features.iter().any(|f| f.starts_with("chunked_")));
        for &some in splits {
            ctx.split_arrays = some.iter().map(|a| a.to_string()).collect();
            let split = gpu_run(&ctx, f, &rays).unwrap();
            let features: Vec<String> = (split.features.iter())
                .filter(|f| f.starts_with("chunked_"))
                .map(|f| f.to_string())
                .collect();
            let expected: Vec<_> = some.iter().map(|a| format!("chunked_{a}")).collect();
            assert_eq!(features, expected, "{name}");
            let (hits, differ) = compare_bits(&whole.hits, &split.hits);
            println!(
                "{name}, {some:?} split: {} rays ({hits} hits), {differ} differ",
                rays.len()
            );
            assert!(hits > rays.len() / 10, "{name}");
            assert_eq!(differ, 0, "{name}: split and whole arrays differ");
            assert_eq!(split.cut_short, 0, "{name}");
        }
    }
}
