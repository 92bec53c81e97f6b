//! Renders of a scene medium read lazily from a brick store (`hytrace render --memory`):
//! with a brick cache smaller than the store, so that bricks are evicted and read again,
//! the image equals bit for bit (fixed seed) the render of the same store bricked in memory
//! (`format = "f32"`, which holds the store's decoded values exactly), by emission-absorption
//! and by multiple scattering; a budget below one superchunk is refused naming the least
//! one, and the GPU renderer streams such a medium through its brick pool (the same bits as
//! with the whole store resident; the CPU's image pixel by pixel).

mod common;

use std::path::{Path, PathBuf};

use common::{hytrace, read_values};
use hytrace_foundry::gdml::GdmlOptions;
use hytrace_trace::cpu::CpuScene;
use hytrace_trace::gpu::{GpuContext, GpuRenderer, GpuStreamedVolume, StreamError};
use hytrace_trace::render::spec::VolumeMode;
use hytrace_trace::render::{Image, Renderer};
use hytrace_trace::scene::load_render_scene;
use hytrace_volume::{convert_grid, BrickStore, ConvertOptions, DenseGrid, Rng};

/// Voxels along each side of the test volume: 32^3 bricks, about 6800 of them kept (7 MiB
/// of 16-bit bricks), more than the cache of the least budget (one superchunk, 4096 bricks)
/// holds.
const SIDE: i32 = 256;

/// A cloud: noise inside a ball that leaves the volume's sides empty (so the store's own
/// range mips span more than its data), every fifth brick (in a diagonal pattern) empty.
fn cloud() -> DenseGrid {
    let mut g = DenseGrid::new([0; 3], [SIDE as u32; 3], 0.0).unwrap();
    let mut rng = Rng::new(11, 0, 0);
    let c = f64::from(SIDE) / 2.0;
    for z in 0..SIDE {
        for y in 0..SIDE {
            for x in 0..SIDE {
                let r = [x, y, z].map(|v| f64::from(v) + 0.5 - c);
                let r = (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt();
                if r > 0.75 * c || (x / 8 + y / 8 + z / 8) % 5 == 0 {
                    continue;
                }
                let wave = 0.4 * ((0.19 * f64::from(x)).sin() + (0.13 * f64::from(y + z)).cos());
                let value = (1.0 - r / c) * (1.2 + wave + 0.4 * rng.next_f64()) * 1.5;
                g.set([x, y, z].map(i64::from), value as f32);
            }
        }
    }
    g
}

/// Converts the cloud into a brick store `cloud.bricks` in `dir` and writes two scenes
/// placing it: `stored.toml` reads the store as stored, `in_core.toml` bricks it in memory.
fn scenes(dir: &Path) -> (PathBuf, PathBuf) {
    let options = ConvertOptions {
        background: 0.0,
        threshold: 0.0,
        range: None,
        memory: 1 << 30,
    };
    convert_grid(
        &cloud(),
        "density",
        &options,
        &dir.join("cloud.bricks"),
        &|_, _| (),
    )
    .unwrap();
    let scene = |name: &str, format: &str| {
        let text = format!(
            r#"
[volumes.cloud]
source = "cloud.bricks"
density_scale = 0.02
albedo = 0.9
g = 0.4
emission = [0.6, 0.3, 0.1]
{format}

[solids.floor]
shape = "box(600, 600, 4)"

[[place]]
solid = "cloud"
translate = [-128, -128, -32]

[[place]]
solid = "floor"
translate = [0, 0, -4]

[[lights]]
kind = "directional"
direction = [-0.5, 0.4, -0.75]
irradiance = [2.5, 2.4, 2.2]

[[lights]]
kind = "environment"
radiance = [0.2, 0.25, 0.35]

[camera]
eye = [380, -420, 260]
target = [0, 0, 90]
fov = 40
"#
        );
        let path = dir.join(name);
        std::fs::write(&path, text).unwrap();
        path
    };
    (
        scene("stored.toml", ""),
        scene("in_core.toml", "format = \"f32\""),
    )
}

/// `hytrace render` of `scene` into `out` with `args` after the common ones.
fn render(scene: &Path, out: &Path, args: &[&str]) -> std::process::Output {
    let common = [
        "render",
        scene.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--size",
        "48x32",
        "--seed",
        "7",
        "--step",
        "0.5",
    ];
    hytrace(&[&common[..], args].concat(), &[])
}

fn stderr(o: &std::process::Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// The error of a render of `scene` into `out` with `args` that must fail and write nothing.
fn refused(scene: &Path, out: &Path, args: &[&str]) -> String {
    let o = render(scene, out, args);
    assert!(!o.status.success());
    assert!(!out.exists());
    stderr(&o)
}

/// The least `--memory` the store accepts, from the error refusing a budget of one byte
/// (which must name it and write nothing).
fn least_memory(scene: &Path, dir: &Path) -> u64 {
    let text = refused(scene, &dir.join("refused.npy"), &["--memory", "1"]);
    assert!(
        text.contains("cloud.bricks") && text.contains("too small"),
        "{text}"
    );
    let least = text
        .split("give at least ")
        .nth(1)
        .unwrap_or_else(|| panic!("{text}"));
    least
        .trim()
        .trim_end_matches(|c: char| !c.is_ascii_digit())
        .parse()
        .unwrap_or_else(|e| panic!("{e}: {text}"))
}

#[test]
fn a_store_rendered_through_a_small_cache_equals_the_in_core_render_bit_for_bit() {
    let tmp = tempfile::tempdir().unwrap();
    let (stored, in_core) = scenes(tmp.path());
    let least = least_memory(&stored, tmp.path());
    let memory = least.to_string();
    for (mode, spp) in [("emission-absorption", "2"), ("multiple-scattering", "32")] {
        let image = |scene: &Path, name: &str, extra: &[&str]| {
            let out = tmp.path().join(format!("{mode}-{name}.npy"));
            let args = [&["--volumes", mode, "--spp", spp, "--stats"][..], extra].concat();
            let o = render(scene, &out, &args);
            assert!(o.status.success(), "{name}: {}", stderr(&o));
            let stats: serde_json::Value =
                serde_json::from_slice(o.stdout.split(|&b| b == b'\n').next().unwrap()).unwrap();
            (read_values(&out), stats)
        };
        let (lazy, stats) = image(&stored, "stored", &["--memory", &memory]);
        let store = &stats["store"];
        eprintln!("{mode}: {store}");
        let (read, cache) = (
            store["bricks_read"].as_u64(),
            store["cache_bricks"].as_u64(),
        );
        // The cache holds fewer bricks than the render read: bricks were evicted.
        assert!(read.unwrap() > cache.unwrap(), "{stats}");
        let (whole, stats) = image(&in_core, "in-core", &[]);
        assert!(stats.get("store").is_none(), "{stats}");
        assert!(lazy.iter().any(|&v| v > 0.0));
        let differ = (lazy.iter().zip(&whole))
            .filter(|(a, b)| a.to_bits() != b.to_bits())
            .count();
        assert_eq!(
            differ,
            0,
            "{mode}: {differ} of {} values differ",
            lazy.len()
        );
    }
}

/// The GPU renderer streams a store read as stored through a brick pool of the least
/// budget, which holds fewer bricks than the store keeps: passes defer pixels, the pool
/// doubles and evicts, and the image equals bit for bit the same kernel's render with the
/// whole store resident, and the CPU's render of the store pixel by pixel (within 1e-4, on
/// 99.5% of pixels, as `gpu_render.rs` compares media). From the command line,
/// `--backend gpu` with that budget writes the image and reports the streaming.
#[test]
fn a_store_read_as_stored_streams_through_the_gpu_brick_pool() {
    let Some(ctx) = GpuContext::for_tests() else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let (stored, _) = scenes(tmp.path());
    // The least budget both the CPU's cache and the GPU's pool accept.
    let store = BrickStore::open(&tmp.path().join("cloud.bricks"), 1 << 30).unwrap();
    let gpu_least = match GpuStreamedVolume::new(&ctx, &store, 1) {
        Err(StreamError::Budget { least, .. }) => least,
        other => panic!("a 1-byte budget: {:?}", other.err()),
    };
    let least = least_memory(&stored, tmp.path()).max(gpu_least);
    let (f, mut spec) = load_render_scene(Some(&stored), &GdmlOptions::default()).unwrap();
    spec.settings.size = [48, 32];
    spec.settings.seed = 7;
    spec.settings.step = 0.5;
    spec.settings.spp = 2;
    spec.settings.volumes = Some(VolumeMode::EmissionAbsorption);
    spec.settings.memory = least;
    let scene = CpuScene::<f32>::new(&f).unwrap();
    let renderer = Renderer::new(&scene, &f, &spec).unwrap();
    let cpu = renderer.render(&|_| {}).unwrap();
    let kernel = GpuRenderer::new(&ctx, &renderer).unwrap();
    assert!(
        kernel.features().contains(&"streamed"),
        "{:?}",
        kernel.features()
    );
    let mut streamed = kernel.render(&ctx, &renderer, &|_| {}).unwrap();
    let st = streamed.stream.unwrap();
    eprintln!("{st:?}");
    assert!(st.passes >= 2 && st.deferred > 0, "{st:?}");
    assert!(st.pool_doublings > 0 && st.bricks_evicted > 0, "{st:?}");
    let mut whole_spec = spec.clone();
    whole_spec.settings.memory = 1 << 30;
    let whole_renderer = Renderer::new(&scene, &f, &whole_spec).unwrap();
    let whole_kernel = GpuRenderer::new(&ctx, &whole_renderer)
        .unwrap()
        .with_store_resident();
    let mut whole = whole_kernel.render(&ctx, &whole_renderer, &|_| {}).unwrap();
    assert_eq!(whole.stream.unwrap().deferred, 0);
    assert_eq!(whole.preview.as_ref().unwrap().pixels, whole.image.pixels);
    assert_eq!(streamed.cut_short, whole.cut_short);
    streamed.redo_cut_short(&renderer).unwrap();
    whole.redo_cut_short(&whole_renderer).unwrap();
    let bits = |i: &Image| -> Vec<u32> { i.pixels.iter().flatten().map(|v| v.to_bits()).collect() };
    assert_eq!(bits(&streamed.image), bits(&whole.image));
    let lit = streamed.image.pixels.iter().filter(|p| p[0] > 0.0).count();
    assert!(lit * 4 > streamed.image.pixels.len(), "{lit} pixels lit");
    // The first pass, every pixel: those it finished are the image's; those that lacked a
    // brick show its coarser level of detail (octant means), near the image but not it,
    // and not the background the absent bricks would read without it.
    let preview = streamed.preview.as_ref().unwrap();
    let (mut deferred, mut dark, mut error, mut total) = (0, 0, 0.0f64, 0.0f64);
    for (p, q) in preview.pixels.iter().zip(&streamed.image.pixels) {
        if p == q {
            continue;
        }
        deferred += 1;
        if q[0] > 1e-3 && p[0] == 0.0 {
            dark += 1;
        }
        error += (0..3).map(|c| f64::from((p[c] - q[c]).abs())).sum::<f64>();
        total += (0..3).map(|c| f64::from(q[c])).sum::<f64>();
    }
    eprintln!(
        "preview: {deferred} pixels differ, relative L1 {:.3}",
        error / total
    );
    assert!(deferred > 0);
    assert_eq!(dark, 0, "lit pixels black in the preview");
    assert!(
        error < 0.25 * total,
        "the preview is far from the image: {error} of {total}"
    );
    let bad = (cpu.pixels.iter().zip(&streamed.image.pixels))
        .filter(|(p, q)| (0..3).any(|c| (p[c] - q[c]).abs() > 1e-4))
        .count();
    assert!(
        bad * 200 <= cpu.pixels.len(),
        "{bad} pixels differ from the CPU's"
    );

    let out = tmp.path().join("gpu.npy");
    let memory = least.to_string();
    let first = tmp.path().join("first.npy");
    let first_arg = first.to_str().unwrap();
    let args = [
        "--backend",
        "gpu",
        "--spp",
        "1",
        "--memory",
        &memory,
        "--stats",
        "--preview",
        first_arg,
    ];
    let o = render(&stored, &out, &args);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(read_values(&first).len(), read_values(&out).len());
    let cpu_out = tmp.path().join("cpu.npy");
    let text = refused(&stored, &cpu_out, &["--preview", first_arg]);
    assert!(text.contains("--backend gpu"), "{text}");
    let stats: serde_json::Value =
        serde_json::from_slice(o.stdout.split(|&b| b == b'\n').next().unwrap()).unwrap();
    assert_eq!(stats["backend"], "gpu", "{stats}");
    assert!(
        stats["stream"]["pixels_deferred"].as_u64().unwrap() > 0,
        "{stats}"
    );
    assert!(read_values(&out).iter().any(|&v| v > 0.0));
}

/// A pool too small for what one pixel reads, and two stores read as stored, are clear
/// errors that write no image.
#[test]
fn gpu_renders_of_stores_refuse_what_they_cannot_stream() {
    if GpuContext::for_tests().is_none() {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let (stored, _) = scenes(tmp.path());
    let text = std::fs::read_to_string(&stored).unwrap();
    let second = text.replace(
        "[volumes.cloud]",
        "[volumes.cloud2]\nsource = \"cloud.bricks\"\ndensity_scale = 0.02\n\n[volumes.cloud]",
    ) + "\n[[place]]\nsolid = \"cloud2\"\ntranslate = [0, 0, 200]\n";
    let two = tmp.path().join("two.toml");
    std::fs::write(&two, second).unwrap();
    let out = tmp.path().join("two.npy");
    let err = refused(&two, &out, &["--backend", "gpu", "--spp", "1"]);
    assert!(
        err.contains("one medium read as stored") && err.contains("--backend cpu"),
        "{err}"
    );
}

/// `scan --transmittance` reads a medium stored in a brick store through a cache of
/// `--memory` bytes: with the least budget (bricks evicted and read again) the
/// transmittance equals, bit for bit, that of the same store bricked in memory; a budget
/// below it is refused naming the store, writing nothing.
#[test]
fn scan_transmittance_reads_a_store_through_a_memory_budget() {
    use hytrace_trace::scan::{write_rays, RayRow};
    let tmp = tempfile::tempdir().unwrap();
    let (stored, in_core) = scenes(tmp.path());
    let least = least_memory(&stored, tmp.path()).to_string();
    let mut rng = Rng::new(5, 0, 0);
    let rays: Vec<RayRow> = (0..4000)
        .map(|_| {
            // From a sphere around the cloud towards a random point of it.
            let o = [0.0; 3].map(|_: f64| rng.next_f64() * 2.0 - 1.0);
            let n = (o[0] * o[0] + o[1] * o[1] + o[2] * o[2]).sqrt().max(1e-3);
            let origin = o.map(|c| 400.0 * c / n);
            let target = [0.0; 3].map(|_: f64| (rng.next_f64() * 2.0 - 1.0) * 90.0);
            let d: [f64; 3] = std::array::from_fn(|k| target[k] - origin[k]);
            let l = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            RayRow {
                origin,
                direction: d.map(|c| c / l),
                tmin: 0.0,
                tmax: f64::INFINITY,
            }
        })
        .collect();
    let rays_path = tmp.path().join("rays.npy");
    write_rays(&rays_path, &rays).unwrap();
    // `scan --transmittance` of `scene` through a cache of `memory` bytes, `extra`
    // options after: its output and the transmittance file's path.
    let scan = |scene: &Path, name: &str, memory: &str, extra: &[&str]| {
        let hits = tmp.path().join(format!("{name}-hits.npy"));
        let t = tmp.path().join(format!("{name}-t.npy"));
        let args = [
            "scan",
            scene.to_str().unwrap(),
            "--rays",
            rays_path.to_str().unwrap(),
            "--out",
            hits.to_str().unwrap(),
            "--transmittance",
            t.to_str().unwrap(),
            "--memory",
            memory,
        ];
        (hytrace(&[&args[..], extra].concat(), &[]), t)
    };
    let (o, lazy) = scan(&stored, "stored", &least, &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    let (o, whole) = scan(&in_core, "in-core", "1G", &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    let (lazy, whole) = (read_values(&lazy), read_values(&whole));
    assert!(lazy.iter().any(|&v| v < 0.5), "no ray crosses the cloud");
    assert_eq!(
        lazy.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
        whole.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
    );
    let (o, t) = scan(&stored, "refused", "1", &[]);
    assert!(!o.status.success() && !t.exists());
    assert!(
        stderr(&o).contains("cloud.bricks") && stderr(&o).contains("too small"),
        "{}",
        stderr(&o)
    );
    // On the GPU the store streams through a brick pool of that budget (at least what the
    // pool needs): the exact estimator's answers agree with the CPU's ray by ray.
    let Some(ctx) = GpuContext::for_tests() else {
        return;
    };
    let store = BrickStore::open(&tmp.path().join("cloud.bricks"), 1 << 30).unwrap();
    let gpu_least = match GpuStreamedVolume::new(&ctx, &store, 1) {
        Err(StreamError::Budget { least, .. }) => least,
        other => panic!("a 1-byte budget: {:?}", other.err()),
    };
    let budget = least.parse::<u64>().unwrap().max(gpu_least).to_string();
    let exact = |backend: &str| {
        let extra = ["--estimator", "exact", "--backend", backend];
        let (o, t) = scan(&stored, &format!("{backend}-exact"), &budget, &extra);
        assert!(o.status.success(), "{}", stderr(&o));
        read_values(&t)
    };
    let (cpu, gpu) = (exact("cpu"), exact("gpu"));
    let worst = (cpu.iter().zip(&gpu))
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(worst < 1e-4, "GPU and CPU differ by up to {worst}");
}
