//! Shared by the backend comparison tests (Embree, GPU): ray sets around a scene, a mesh
//! scene, a hard CSG case (chords through a boolean edge), the GPU scan's answers, and the
//! ray-by-ray comparison with the CPU's f32 tracer.

// Each test crate uses only some of these helpers.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use hytrace_csg::{box3, to_tree};
use hytrace_csg::{Ray, V3};
use hytrace_foundry::layout::Scalar;
use hytrace_foundry::npy::read_array;
use hytrace_foundry::{Foundry, Transform64, UNSET};
use hytrace_trace::cpu::{CpuScene, Hit};
use hytrace_trace::gpu::records::{STATUS_CUT_SHORT, STATUS_FLAGS};
use hytrace_trace::gpu::{GpuContext, GpuError, GpuTracer, GPU_INF};
use hytrace_trace::photons::sources::{Source, Wavelength};
use hytrace_trace::photons::{Origin, RunOptions};
use hytrace_trace::scan::{ray_record, RayRow};
use hytrace_trace::sweep::{generate, scene_bounds, Sweep};
use hytrace_volume::{convert_grid, parse_nanovdb, ConvertOptions, DenseGrid, NanoFile};

/// The tests' deterministic generator (SplitMix64).
#[allow(unused_imports)] // not every test file draws
pub use hytrace_testkit::{Random, SplitMix64 as Rng};

/// The volume crate's PCG stream (what the kernels draw from) as a [`Random`] source, for
/// the GPU twin tests: uniform draws are its `next_f64`, other bits its `next_u32`.
pub struct PcgDraws(pub hytrace_volume::Rng);

impl PcgDraws {
    /// Stream 0, sample 0 of `seed`.
    pub fn new(seed: u32) -> Self {
        PcgDraws(hytrace_volume::Rng::new(seed, 0, 0))
    }
}

impl Random for PcgDraws {
    fn next_u64(&mut self) -> u64 {
        u64::from(self.0.next_u32())
    }

    fn uniform(&mut self) -> f64 {
        self.0.next_f64()
    }
}

/// A concrete block 2 x 2 x 1 m with a pit 0.4 x 0.4 m cut into its top face (a box minus a
/// box that rises above it).
pub fn block_with_pit() -> Foundry {
    let pit = box3(400.0, 400.0, 400.0)
        .unwrap()
        .translate(0.0, 0.0, 500.0);
    let mut f = Foundry::new();
    let mut s = f.begin_solid("block");
    s.add_csg(
        to_tree(&(box3(2000.0, 2000.0, 1000.0).unwrap() - pit)).unwrap(),
        0,
        UNSET,
    )
    .unwrap();
    let solid = s.finish(0).unwrap();
    f.add_instance(solid, Transform64::IDENTITY, 0, 0).unwrap();
    f
}

/// `count` rays from inside the pit of [`block_with_pit`] crossing its wall `10^e` mm below
/// the top face (`e` uniform in `exponents`) at about 30 degrees of elevation, half of them
/// at an angle across the wall, each cutting the edge where the wall meets the top in a
/// chord of about twice that. Exact (f64, and Geant4 with its 1e-9 mm) answer: the entry
/// through the wall, 200 mm on.
pub fn rays_across_the_pit_edge(seed: u64, count: usize, exponents: [f64; 2]) -> Vec<RayRow> {
    let mut rng = Rng(seed);
    let elevation = 30f64.to_radians();
    (0..count)
        .map(|i| {
            let below = 10f64.powf(exponents[0] + (exponents[1] - exponents[0]) * rng.uniform());
            let across = if i % 2 == 0 {
                0.0
            } else {
                0.3 * (2.0 * rng.uniform() - 1.0)
            };
            let d = unit([elevation.cos(), across, elevation.sin()]);
            // Where the ray meets the wall x = 200, `below` under the top face z = 500.
            let wall = [200.0, 100.0 * (2.0 * rng.uniform() - 1.0), 500.0 - below];
            RayRow {
                origin: [0, 1, 2].map(|k| wall[k] - 200.0 * d[k]),
                direction: d,
                tmin: 0.0,
                tmax: f64::INFINITY,
            }
        })
        .collect()
}

/// The NanoVDB fixture `name` of `tests/data/nanovdb`, parsed.
pub fn nanovdb_fixture(name: &str) -> NanoFile {
    let path = repo("tests/data/nanovdb").join(name);
    let bytes = std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    parse_nanovdb(&bytes, name).unwrap_or_else(|e| panic!("{e}"))
}

/// A path in the repository.
pub fn repo(path: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../..")
        .join(path)
}

/// `v` scaled to unit length.
#[allow(unused_imports)] // not every test file uses it
pub use hytrace_testkit::vec3::normalized as unit;

/// Runs the `hytrace` binary with `args` and extra environment variables.
pub fn hytrace(args: &[&str], env: &[(&str, &str)]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_hytrace"))
        .args(args)
        .envs(env.iter().copied())
        .output()
        .unwrap()
}

/// The standard error of a command, as text.
pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// The `--stats` line of a GPU run, after checking that the command succeeded (its stderr
/// shown otherwise) and reported what every GPU command reports: backend `gpu`, the
/// adapter, host kernel seconds and the timestamp field (null where a device has no
/// timestamp queries).
pub fn gpu_stats(out: &Output) -> serde_json::Value {
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let stats: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(stats["backend"], "gpu");
    assert!(stats["adapter"].as_str().is_some_and(|a| !a.is_empty()));
    assert!(stats["gpu_kernel_s"].as_f64().is_some());
    assert!(stats.get("gpu_kernel_timestamps_s").is_some());
    stats
}

/// Runs `hytrace ARGS --backend B --out DIR/B.npy --stats` on the GPU and then on the CPU:
/// the values each wrote, the GPU run's stats ([`gpu_stats`]) and its stderr.
pub fn gpu_and_cpu_values(
    args: &[&str],
    dir: &Path,
) -> (Vec<f64>, Vec<f64>, serde_json::Value, String) {
    let run = |backend: &str| {
        let out = dir.join(format!("{backend}.npy"));
        let mut all = args.to_vec();
        let path = out.to_str().unwrap();
        all.extend(["--backend", backend, "--out", path, "--stats"]);
        (hytrace(&all, &[]), out)
    };
    let (gpu, gpu_out) = run("gpu");
    let stats = gpu_stats(&gpu);
    let (cpu, cpu_out) = run("cpu");
    assert!(
        cpu.status.success(),
        "{}",
        String::from_utf8_lossy(&cpu.stderr)
    );
    (
        read_values(&gpu_out),
        read_values(&cpu_out),
        stats,
        String::from_utf8_lossy(&gpu.stderr).into_owned(),
    )
}

/// Width, height and RGB bytes of a PNG file.
pub fn read_png(path: &Path) -> (u32, u32, Vec<u8>) {
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!(info.color_type, png::ColorType::Rgb);
    buf.truncate(info.buffer_size());
    (info.width, info.height, buf)
}

/// The values of a float32, float64 or int32 `.npy` file, as f64.
pub fn read_values(path: &Path) -> Vec<f64> {
    let a = read_array(path).unwrap();
    match a.scalar {
        Scalar::F32 => bytemuck::pod_collect_to_vec::<u8, f32>(&a.bytes)
            .into_iter()
            .map(f64::from)
            .collect(),
        Scalar::F64 => bytemuck::pod_collect_to_vec(&a.bytes),
        Scalar::I32 => bytemuck::pod_collect_to_vec::<u8, i32>(&a.bytes)
            .into_iter()
            .map(f64::from)
            .collect(),
        s => panic!("{}: unexpected {s:?}", path.display()),
    }
}

/// The values of a `.npy` file that must be float64.
pub fn read_f64(path: &Path) -> Vec<f64> {
    let a = read_array(path).unwrap();
    assert_eq!(a.scalar, Scalar::F64, "{}", path.display());
    bytemuck::pod_collect_to_vec(&a.bytes)
}

/// Sweeps (`axis`, `rect`, `circle`) around the scene plus `random` rays from points in
/// its (enlarged) bounds, a quarter of them with one or two direction components zero
/// and a fifth on a finite segment `(tmin, tmax)`.
pub fn rays_for(f: &Foundry, count: usize, random: usize) -> Vec<RayRow> {
    let b = scene_bounds(f).expect("scene has solids");
    let mut rays: Vec<RayRow> = [Sweep::Axis, Sweep::Rect, Sweep::Circle]
        .into_iter()
        .flat_map(|s| generate(s, &b, count).unwrap())
        .collect();
    let mut rng = Rng(0x5eed_0000 + f.inst.len() as u64);
    for i in 0..random {
        let origin: [f64; 3] = std::array::from_fn(|k| {
            let (lo, hi) = (b[k], b[k + 3]);
            lo + (hi - lo) * (1.2 * rng.uniform() - 0.1)
        });
        let mut d: [f64; 3] = std::array::from_fn(|_| 2.0 * rng.uniform() - 1.0);
        match i % 8 {
            0 => d[(i / 8) % 3] = 0.0,
            1 => {
                d[(i / 8) % 3] = 0.0;
                d[(i / 8 + 1) % 3] = 0.0;
            }
            _ => {}
        }
        let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        if len < 1e-3 {
            continue;
        }
        // A fifth of them on a finite segment.
        let (tmin, tmax) = if i % 5 == 2 {
            let size = (0..3).fold(0.0f64, |a, k| a.max(b[k + 3] - b[k]));
            let tmin = 0.3 * size * rng.uniform();
            (tmin, tmin + size * rng.uniform())
        } else {
            (0.0, f64::INFINITY)
        };
        rays.push(RayRow {
            origin,
            direction: d.map(|v| v / len),
            tmin,
            tmax,
        });
    }
    rays
}

/// A GPU scan of a set of rays: its answers and the seconds it took.
pub struct GpuRun {
    /// The answer for every ray, as the CPU tracer gives it.
    pub hits: Vec<Option<Hit<f32>>>,
    /// Rays whose search was cut short (`STATUS_CUT_SHORT` bits).
    pub cut_short: usize,
    /// The trace's flags for every ray (`STATUS_FLAGS` bits, `CpuScene::trace_flagged`).
    pub flags: Vec<u32>,
    /// Uploading the scene and compiling its scan kernel.
    pub build_s: f64,
    /// Tracing all the rays (uploads and readbacks included).
    pub trace_s: f64,
    /// The composition features the kernel was built with.
    pub features: Vec<&'static str>,
}

/// Traces `rays` through the scene with the GPU scan kernel.
pub fn gpu_run(ctx: &GpuContext, f: &Foundry, rays: &[RayRow]) -> Result<GpuRun, GpuError> {
    let cpu = CpuScene::<f32>::new(f).unwrap();
    let t0 = std::time::Instant::now();
    let tracer = GpuTracer::new(ctx, &cpu)?;
    let t1 = std::time::Instant::now();
    let records: Vec<_> = rays.iter().map(ray_record).collect();
    let (hits, _) = tracer.trace(ctx, &records)?;
    Ok(GpuRun {
        cut_short: hits
            .iter()
            .filter(|h| h.status & STATUS_CUT_SHORT != 0)
            .count(),
        flags: hits.iter().map(|h| h.status & STATUS_FLAGS).collect(),
        hits: hits
            .iter()
            .map(|h| {
                (h.t < GPU_INF).then(|| Hit {
                    t: h.t,
                    normal: V3::new(h.normal[0], h.normal[1], h.normal[2]),
                    instance: h.instance,
                    prim: h.prim,
                })
            })
            .collect(),
        build_s: (t1 - t0).as_secs_f64(),
        trace_s: t1.elapsed().as_secs_f64(),
        features: tracer.features().to_vec(),
    })
}

/// The GPU's answer for every ray (`None` when no adapter and GPUs are not required).
pub fn gpu_answers(f: &Foundry, rays: &[RayRow]) -> Option<Vec<Option<Hit<f32>>>> {
    let ctx = GpuContext::for_tests()?;
    let run = gpu_run(&ctx, f, rays).unwrap();
    eprintln!(
        "GPU scan of {} rays: kernel built in {:.1} s, traced in {:.1} s ({:?})",
        rays.len(),
        run.build_s,
        run.trace_s,
        run.features
    );
    assert_eq!(run.cut_short, 0, "a ray was cut short");
    Some(run.hits)
}

/// How the two backends compare on a set of rays.
#[derive(Debug, Default)]
pub struct Agreement {
    pub rays: usize,
    pub hits: usize,
    pub agree: usize,
    /// Answers equal to the last bit (t, normal, instance, prim) or both misses.
    pub identical: usize,
    /// Same `t` (within tolerance) on different instances: ties broken differently.
    pub ties: usize,
    /// Agreeing hits on the same instance whose normals differ.
    pub normals: usize,
}

impl Agreement {
    pub fn percent(&self) -> f64 {
        100.0 * self.agree as f64 / self.rays.max(1) as f64
    }
}

/// Compares another backend's answers `got` (one per ray) with the CPU's f32 tracer: the
/// same hit or miss, and `t` within `max(1e-4, 4e-7 * scale)` where `scale` is the size of
/// the coordinates involved (scene extent, origin and distance). Prints the disagreements.
pub fn compare(name: &str, f: &Foundry, rays: &[RayRow], got: &[Option<Hit<f32>>]) -> Agreement {
    assert_eq!(rays.len(), got.len(), "{name}: one answer per ray");
    let cpu = CpuScene::<f32>::new(f).unwrap();
    let b = scene_bounds(f).unwrap();
    let extent = b.iter().fold(0.0f64, |a, v| a.max(v.abs()));
    let mut a = Agreement {
        rays: rays.len(),
        ..Default::default()
    };
    let mut shown = 0;
    for (i, (r, &got)) in rays.iter().zip(got).enumerate() {
        let (_, tmin, tmax) = f32_ray(r);
        let want = cpu.trace(&Ray::from_f64(r.origin, r.direction), tmin, tmax);
        a.hits += usize::from(want.is_some());
        let ok = match (want, got) {
            (None, None) => true,
            (Some(w), Some(g)) => {
                let o = r.origin.iter().fold(0.0f64, |m, v| m.max(v.abs()));
                let scale = extent.max(o + f64::from(w.t.abs()));
                let close = f64::from((w.t - g.t).abs()) <= (4e-7 * scale).max(1e-4);
                if close && w.instance != g.instance {
                    a.ties += 1;
                } else if close && w.normal.dot(g.normal) < 0.999 {
                    a.normals += 1;
                }
                a.identical += usize::from(w == g);
                close
            }
            _ => false,
        };
        a.identical += usize::from(want.is_none() && got.is_none());
        if ok {
            a.agree += 1;
        } else if shown < 10 {
            shown += 1;
            eprintln!("{name}: ray {i} {r:?}: cpu {want:?}, other {got:?}");
        }
    }
    eprintln!(
        "{name}: {} rays, {} hits, {:.3}% agree, {:.3}% bit-identical ({} ties on different instances, {} normals differ)",
        a.rays,
        a.hits,
        a.percent(),
        100.0 * a.identical as f64 / a.rays.max(1) as f64,
        a.ties,
        a.normals
    );
    a
}

/// A ray as the f32 tracers take it: rounded, infinite `tmax` kept infinite.
pub fn f32_ray(r: &RayRow) -> (Ray<f32>, f32, f32) {
    let ray = Ray::from_f64(r.origin, r.direction);
    let tmax = if r.tmax.is_finite() {
        r.tmax as f32
    } else {
        f32::INFINITY
    };
    (ray, r.tmin as f32, tmax)
}

/// Requires at least 99.9% agreement, normals agreeing on 99.9% of the hits, and some hits.
pub fn check(name: &str, f: &Foundry, rays: &[RayRow], got: &[Option<Hit<f32>>]) {
    let a = compare(name, f, rays, got);
    assert!(a.hits > a.rays / 10, "{name}: too few hits: {a:?}");
    assert!(a.percent() >= 99.9, "{name}: {a:?}");
    assert!(a.normals * 1000 <= a.hits, "{name}: {a:?}");
}

/// OBJ text: an icosphere of radius 50 (three subdivisions), a 40 x 40 heightfield beside
/// it, and a cube 10^5 mm out (far from the origin). Rays along a shared edge may take
/// either triangle's normal: the sphere is turned and the grid jittered off the sweeps.
pub fn mesh_obj() -> String {
    let mut out = String::new();
    let mut base = 1;
    let mut object = |name: &str, verts: &[[f64; 3]], faces: &[[usize; 3]], out: &mut String| {
        out.push_str(&format!("o {name}\n"));
        for v in verts {
            out.push_str(&format!("v {} {} {}\n", v[0], v[1], v[2]));
        }
        for t in faces {
            out.push_str(&format!(
                "f {} {} {}\n",
                t[0] + base,
                t[1] + base,
                t[2] + base
            ));
        }
        base += verts.len();
    };
    let (verts, faces) = hytrace_csg::tessellate::icosphere(3);
    // Turned off the axes, so the axis-aligned sweeps do not run along its edges
    // (where either triangle's normal is right).
    let (c, s) = (0.3f64.cos(), 0.3f64.sin());
    let sphere: Vec<[f64; 3]> = verts
        .iter()
        .map(|v| {
            [
                c * v[0] - s * v[1],
                s * c * v[0] + c * c * v[1] - s * v[2],
                s * s * v[0] + s * c * v[1] + c * v[2],
            ]
            .map(|x| 50.0 * x)
        })
        .collect();
    object("sphere", &sphere, &faces, &mut out);
    let n = 40;
    let mut grid = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            // Jittered, so no sweep runs along a row of edges.
            let (i, j) = (i as f64, j as f64);
            let (x, y) = (
                5.0 * i + (1.7 * i).sin() + 80.0,
                5.0 * j + (2.3 * j).sin() - 100.0,
            );
            grid.push([x, y, 10.0 * (x * 0.05).sin() * (y * 0.07).cos()]);
        }
    }
    let mut quads = Vec::new();
    for j in 0..n {
        for i in 0..n {
            let v = j * (n + 1) + i;
            quads.push([v, v + 1, v + n + 2]);
            quads.push([v, v + n + 2, v + n + 1]);
        }
    }
    object("heightfield", &grid, &quads, &mut out);
    let c = |x: f64, y: f64, z: f64| [1e5 + 30.0 * x, 30.0 * y, 30.0 * z];
    let cube = [
        c(0., 0., 0.),
        c(1., 0., 0.),
        c(1., 1., 0.),
        c(0., 1., 0.),
        c(0., 0., 1.),
        c(1., 0., 1.),
        c(1., 1., 1.),
        c(0., 1., 1.),
    ];
    let cube_faces = [
        [0, 3, 2],
        [0, 2, 1],
        [4, 5, 6],
        [4, 6, 7],
        [0, 1, 5],
        [0, 5, 4],
        [1, 2, 6],
        [1, 6, 5],
        [2, 3, 7],
        [2, 7, 6],
        [3, 0, 4],
        [3, 4, 7],
    ];
    object("far_cube", &cube, &cube_faces, &mut out);
    out
}

/// Rays for the scene of [`mesh_obj`]: sweeps around the near objects and the far cube,
/// and random rays from inside the near objects' bounds.
pub fn mesh_scene_rays(f: &Foundry) -> Vec<RayRow> {
    let near = {
        let mut g = f.clone();
        g.inst.truncate(2);
        g.inst_tran.truncate(2);
        scene_bounds(&g).unwrap()
    };
    let mut rays: Vec<RayRow> = [Sweep::Axis, Sweep::Rect, Sweep::Circle]
        .into_iter()
        .flat_map(|s| generate(s, &near, 100).unwrap())
        .collect();
    let far = [1e5, 0.0, 0.0, 1e5 + 30.0, 30.0, 30.0];
    rays.extend(generate(Sweep::Rect, &far, 60).unwrap());
    rays.extend(generate(Sweep::Circle, &far, 2000).unwrap());
    let mut rng = Rng(7);
    for _ in 0..20_000 {
        let origin: [f64; 3] =
            std::array::from_fn(|k| near[k] + (near[k + 3] - near[k]) * rng.uniform());
        let d: [f64; 3] = std::array::from_fn(|_| 2.0 * rng.uniform() - 1.0);
        let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        rays.push(RayRow {
            origin,
            direction: d.map(|v| v / len),
            tmin: 0.0,
            tmax: f64::INFINITY,
        });
    }
    rays
}

/// Renders `spec` of `f` on the GPU (pixels past lavapipe's loop budget fail the test);
/// `None` without a GPU (a panic when `HYTRACE_REQUIRE_GPU=1`).
pub fn render_on_gpu(
    f: &Foundry,
    spec: &hytrace_trace::render::spec::RenderSpec,
) -> Option<hytrace_trace::render::Image> {
    let ctx = GpuContext::for_tests()?;
    let scene = CpuScene::<f32>::new(f).unwrap();
    let renderer = hytrace_trace::render::Renderer::new(&scene, f, spec).unwrap();
    let gpu = hytrace_trace::gpu::GpuRenderer::new(&ctx, &renderer).unwrap();
    let mut run = gpu.render(&ctx, &renderer, &|_| {}).unwrap();
    assert!(run.cut_short.is_empty(), "pixels past the loop budget");
    run.redo_cut_short(&renderer).unwrap();
    Some(run.image)
}

/// A photon run of `photons` photons from the torch `source` at 420 nm, from photon 0 with
/// seed `seed`, keeping every history, no step points.
pub fn torch_run(source: &str, photons: u64, seed: u32) -> RunOptions {
    RunOptions {
        origin: Origin::Torch {
            source: Source::parse(source).unwrap(),
            wavelength: Wavelength::Fixed(420.0),
        },
        photons,
        first: 0,
        seed,
        max_steps: 10_000,
        keep_histories: true,
        records: 0,
    }
}

/// A scene whose medium is a brick store read as stored (16^3 voxels of density 1, an
/// extinction of 0.05 per mm) in the tank of `media_tank.gdml`, written into `dir`.
pub fn stored_medium(dir: &Path) -> PathBuf {
    stored_slab(dir, [16; 3], 1.0, 0.05)
}

/// A scene whose medium is a brick store read as stored: `dims` voxels of density 1 and
/// side `voxel` mm centred on the origin, an extinction of `density_scale` per mm and an
/// albedo of 0.8, in the tank of `media_tank.gdml` (a vacuum world of 400 mm with a sensor
/// plate at z = 150), written into `dir` (`stored.toml`, `fog.bricks`).
pub fn stored_slab(dir: &Path, dims: [u32; 3], voxel: f64, density_scale: f64) -> PathBuf {
    stored_slab_in(
        dir,
        &repo("tests/data/photons/media_tank.gdml"),
        dims,
        voxel,
        density_scale,
    )
}

/// [`stored_slab`] in the GDML scene `gdml` instead of the tank.
pub fn stored_slab_in(
    dir: &Path,
    gdml: &Path,
    dims: [u32; 3],
    voxel: f64,
    density_scale: f64,
) -> PathBuf {
    let map = hytrace_volume::GridMap::uniform(voxel, [0.0; 3]).unwrap();
    let mut grid = DenseGrid::new([0; 3], dims, 0.0).unwrap().with_map(map);
    grid.values.fill(1.0);
    let options = ConvertOptions {
        background: 0.0,
        threshold: 0.0,
        range: None,
        memory: 1 << 28,
    };
    convert_grid(
        &grid,
        "density",
        &options,
        &dir.join("fog.bricks"),
        &|_, _| (),
    )
    .unwrap();
    let path = dir.join("stored.toml");
    let [x, y, z] = dims.map(|d| -f64::from(d) * voxel / 2.0);
    std::fs::write(
        &path,
        format!(
            "[gdml.tank]\nfile = \"{}\"\n\n[volumes.fog]\nsource = \"fog.bricks\"\n\
             density_scale = {density_scale}\nalbedo = 0.8\n\n[[place]]\nsolid = \"fog\"\n\
             translate = [{x}, {y}, {z}]\n",
            gdml.display()
        ),
    )
    .unwrap();
    path
}

/// Cuts the bricks file of the store [`stored_slab`] wrote into `dir` short, to its first
/// four bricks (a store damaged while a run reads it).
pub fn cut_store_short(dir: &Path) {
    std::fs::OpenOptions::new()
        .write(true)
        .open(dir.join("fog.bricks/bricks.bin"))
        .unwrap()
        .set_len(4096)
        .unwrap();
}
