//! The GPU scan kernel against its CPU twin (`CpuScene::<f32>::trace`), ray by ray, on
//! lavapipe in CI: CSG scenes, meshes, a mixed scene, hierarchical GDML scenes and the
//! shared GDML files; plus the kernel's composition (only what a scene uses), and the
//! `scan --backend gpu|auto` command line.

mod common;

use std::path::{Path, PathBuf};

use common::{check, mesh_obj, mesh_scene_rays, rays_for};
use hytrace_csg::V3;
use hytrace_foundry::gdml::GdmlOptions;
use hytrace_foundry::Foundry;
use hytrace_trace::cpu::{CpuScene, Hit};
use hytrace_trace::gpu::{GpuContext, GpuTracer, GPU_INF};
use hytrace_trace::scan::{ray_record, RayRow};
use hytrace_trace::scene::{default_scene, load_scene, obj_to_foundry};

fn repo(path: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../..")
        .join(path)
}

/// The GPU's answer for every ray (`None` when no adapter and GPUs are not required).
fn gpu_answers(f: &Foundry, rays: &[RayRow]) -> Option<Vec<Option<Hit<f32>>>> {
    let ctx = GpuContext::for_tests()?;
    let cpu = CpuScene::<f32>::new(f).unwrap();
    let t0 = std::time::Instant::now();
    let tracer = GpuTracer::new(&ctx, &cpu).unwrap();
    let t1 = std::time::Instant::now();
    let records: Vec<_> = rays.iter().map(ray_record).collect();
    let (hits, _) = tracer.trace(&ctx, &records).unwrap();
    eprintln!(
        "GPU scan of {} rays: kernel built in {:.1} s, traced in {:.1} s ({:?})",
        rays.len(),
        (t1 - t0).as_secs_f64(),
        t1.elapsed().as_secs_f64(),
        tracer.features()
    );
    assert!(hits.iter().all(|h| h.status == 0), "a ray was cut short");
    Some(
        hits.iter()
            .map(|h| {
                (h.t < GPU_INF).then(|| Hit {
                    t: h.t,
                    normal: V3::new(h.normal[0], h.normal[1], h.normal[2]),
                    instance: h.instance,
                    prim: h.prim,
                })
            })
            .collect(),
    )
}

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
