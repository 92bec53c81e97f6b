//! GPU scan benchmark: hytrace's wgpu scan kernel ([`GpuTracer`]) on the 1M-triangle
//! heightfield, the mixed scene and the shared GDML corpus, on whatever adapter wgpu opens.
//!
//! `cargo bench -p hytrace-tests --bench gpu`. `HYTRACE_BENCH_RAYS=N` sets the rays per set
//! (default 1 000 000; 50 000 when the adapter is a CPU, such as Mesa's lavapipe, whose
//! numbers are then functional ones of a software rasterizer, not GPU performance),
//! `HYTRACE_BENCH_GRID=N` the heightfield's side (default 708: 1 002 528 triangles),
//! `HYTRACE_GDML_DIR` the corpus (default `../shared/gdml` beside the repository).
//!
//! Workloads: the heightfield of `benches/mesh.rs` with its coherent (a pinhole camera's
//! primary rays) and incoherent (from above the field, downward hemisphere) sets and a
//! diffuse set (bounce rays: from random points on the surface, cosine-distributed about
//! the normal); the mixed scene of `benches/mixed.rs` with its coherent and incoherent
//! sets; every file of the GDML corpus with an `axis` sweep of about N rays (origins along
//! the x axis through the scene's centre, inside the world volume, shooting along +-y and
//! +-z: the kernel locates each origin in the placement tree and finds its next boundary),
//! files the loader rejects skipped with a note. Build is [`CpuScene::new`] (f32) plus
//! [`GpuTracer::new`] (upload and kernel compilation), timed once; both parts are shown. Each ray set is traced once to warm up,
//! then [`RUNS`] times; the medians are reported of the kernel time (GPU timestamp queries
//! where the device has them, else the host's submission to completion) and of the end to
//! end time (ray upload + kernel + hit readback; converting rays to records is not timed).

#[path = "common/heightfield.rs"]
mod heightfield;
#[path = "common/mixed_scene.rs"]
mod mixed_scene;

use std::time::Instant;

use heightfield::{coherent, heightfield, incoherent, unit, write_obj, RaySet};
use hytrace_foundry::gdml::GdmlOptions;
use hytrace_foundry::Foundry;
use hytrace_tests::gdml::{gdml_dir, gdml_files};
use hytrace_trace::accuracy::utc_date;
use hytrace_trace::cpu::CpuScene;
use hytrace_trace::gpu::records::STATUS_CUT_SHORT;
use hytrace_trace::gpu::{GpuContext, GpuTracer, GPU_INF};
use hytrace_trace::scan::{ray_record, RayRow};
use hytrace_trace::scene::{load_scene, scene_from_toml};
use hytrace_trace::sweep::{generate, scene_bounds, Sweep};
use hytrace_volume::Rng;
use mixed_scene::{coherent_rays, incoherent_rays, scene_text, scenes_dir};

/// Timed runs per ray set, after one warm-up run (the median is reported).
const RUNS: usize = 3;

/// Rays per set on a CPU adapter (a software rasterizer), unless `HYTRACE_BENCH_RAYS` says.
const SOFTWARE_RAYS: usize = 50_000;

/// A scene on the GPU and the seconds it took to build.
struct Built {
    tracer: GpuTracer,
    /// [`CpuScene::new`] seconds.
    prep_s: f64,
    /// [`GpuTracer::new`] seconds (upload and kernel compilation).
    gpu_s: f64,
}

impl Built {
    /// The build cell: total seconds, then its two parts.
    fn cell(&self) -> String {
        build_cell(self.prep_s, self.gpu_s)
    }
}

/// `total (CpuScene + GpuTracer)` seconds.
fn build_cell(prep_s: f64, gpu_s: f64) -> String {
    format!("{:.2} ({prep_s:.2} + {gpu_s:.2})", prep_s + gpu_s)
}

/// Prepares `foundry`'s f32 CPU scene, uploads it and compiles its kernel.
fn build(ctx: &GpuContext, foundry: &Foundry) -> Result<Built, String> {
    let t0 = Instant::now();
    let cpu = CpuScene::<f32>::new(foundry).map_err(|e| format!("{e:#}"))?;
    let t1 = Instant::now();
    let tracer = GpuTracer::new(ctx, &cpu).map_err(|e| e.to_string())?;
    Ok(Built {
        tracer,
        prep_s: (t1 - t0).as_secs_f64(),
        gpu_s: t1.elapsed().as_secs_f64(),
    })
}

/// The numbers of one traced ray set.
#[derive(Clone, Copy, Default)]
struct Measured {
    rays: usize,
    hits: usize,
    /// Rays whose search the kernel cut short (a placement tree deeper than its bound).
    cut_short: usize,
    /// Median kernel seconds.
    kernel_s: f64,
    /// Median upload + kernel + readback seconds.
    end_to_end_s: f64,
}

impl Measured {
    /// Sums of the counts and seconds of `self` and `other`.
    fn add(self, other: Measured) -> Measured {
        Measured {
            rays: self.rays + other.rays,
            hits: self.hits + other.hits,
            cut_short: self.cut_short + other.cut_short,
            kernel_s: self.kernel_s + other.kernel_s,
            end_to_end_s: self.end_to_end_s + other.end_to_end_s,
        }
    }

    /// Table cells: rays, kernel and end-to-end Mrays/s, hit percentage (and rays cut short).
    fn cells(&self) -> String {
        let mrays = |s: f64| self.rays as f64 / s / 1e6;
        let cut = match self.cut_short {
            0 => String::new(),
            n => format!(" ({n} cut short)"),
        };
        format!(
            "{} | {:.3} | {:.3} | {:.1}{cut}",
            self.rays,
            mrays(self.kernel_s),
            mrays(self.end_to_end_s),
            100.0 * self.hits as f64 / self.rays.max(1) as f64
        )
    }
}

/// The middle value of `v`.
fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Traces `rows` once to warm up, then [`RUNS`] times. Also whether every timed run had
/// GPU timestamps.
fn measure(ctx: &GpuContext, tracer: &GpuTracer, rows: &[RayRow]) -> (Measured, bool) {
    let records: Vec<_> = rows.iter().map(ray_record).collect();
    let trace = || tracer.trace(ctx, &records).expect("GPU trace");
    let (hits, _) = trace();
    let (mut kernel, mut end_to_end, mut timestamps) = (Vec::new(), Vec::new(), true);
    for _ in 0..RUNS {
        let (_, t) = trace();
        timestamps &= t.kernel_gpu_s.is_some();
        kernel.push(t.kernel_gpu_s.unwrap_or(t.kernel_s));
        end_to_end.push(t.upload_s + t.kernel_s + t.readback_s);
    }
    let measured = Measured {
        rays: rows.len(),
        hits: hits.iter().filter(|h| h.t < GPU_INF).count(),
        cut_short: hits
            .iter()
            .filter(|h| h.status & STATUS_CUT_SHORT != 0)
            .count(),
        kernel_s: median(kernel),
        end_to_end_s: median(end_to_end),
    };
    (measured, timestamps)
}

/// The rays of a [`RaySet`] as scan rows.
fn rows(set: &RaySet) -> Vec<RayRow> {
    set.rays()
        .iter()
        .map(|r| RayRow {
            origin: r.origin.to_f64(),
            direction: r.direction.to_f64(),
            tmin: 0.0,
            tmax: f64::INFINITY,
        })
        .collect()
}

/// `a x b`.
fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// Diffuse bounce rays off the heightfield: origins at uniform points of random triangles,
/// lifted 1e-3 along the triangle's (upward) normal, directions cosine-distributed about it
/// (the normal plus a uniform unit vector).
fn diffuse(vertices: &[[f64; 3]], faces: &[[u32; 3]], count: usize) -> RaySet {
    let mut rng = Rng::new(666, 0, 0);
    RaySet::new(
        "diffuse",
        (0..count).map(move |_| {
            let face = faces[(rng.next_f64() * faces.len() as f64) as usize];
            let [a, b, c] = face.map(|i| vertices[i as usize]);
            let (r1, r2) = (rng.next_f64().sqrt(), rng.next_f64());
            let normal = unit(cross(
                std::array::from_fn(|k| b[k] - a[k]),
                std::array::from_fn(|k| c[k] - a[k]),
            ));
            let origin = std::array::from_fn(|k| {
                (1.0 - r1) * a[k] + r1 * (1.0 - r2) * b[k] + r1 * r2 * c[k] + 1e-3 * normal[k]
            });
            let z = 2.0 * rng.next_f64() - 1.0;
            let (s, c) = (std::f64::consts::TAU * rng.next_f64()).sin_cos();
            let r = (1.0 - z * z).sqrt();
            let sphere = [r * c, r * s, z];
            (origin, std::array::from_fn(|k| normal[k] + sphere[k]))
        }),
    )
}

/// An environment variable parsed as a count.
fn env_usize(name: &str) -> Option<usize> {
    std::env::var(name).ok().and_then(|s| s.parse().ok())
}

/// The table's rows and notes, filled workload by workload.
#[derive(Default)]
struct Report {
    rows: Vec<String>,
    notes: Vec<String>,
    /// Whether every kernel time came from GPU timestamps.
    timestamps: bool,
}

impl Report {
    /// Traces each named ray set on `built` and adds its row.
    fn sets(
        &mut self,
        ctx: &GpuContext,
        workload: &str,
        built: &Built,
        sets: &[(&str, Vec<RayRow>)],
    ) {
        for (name, rows) in sets {
            let (m, timestamps) = measure(ctx, &built.tracer, rows);
            self.timestamps &= timestamps;
            self.rows.push(format!(
                "| {workload} | {name} | {} | {} |",
                built.cell(),
                m.cells()
            ));
        }
    }
}

fn main() {
    let start = Instant::now();
    let ctx = match GpuContext::new() {
        Ok(ctx) => ctx,
        Err(e) => {
            println!("no GPU benchmark: {e}");
            return;
        }
    };
    let software = ctx.adapter_info.device_type == wgpu::DeviceType::Cpu;
    let count =
        env_usize("HYTRACE_BENCH_RAYS").unwrap_or(if software { SOFTWARE_RAYS } else { 1_000_000 });
    let n = env_usize("HYTRACE_BENCH_GRID").unwrap_or(708);
    let mut report = Report {
        timestamps: true,
        ..Report::default()
    };

    // The heightfield, loaded from an OBJ as users load it.
    let dir = tempfile::tempdir().unwrap();
    let (vertices, faces) = heightfield(n);
    let zmax = vertices.iter().fold(f64::NEG_INFINITY, |a, v| a.max(v[2]));
    let obj = dir.path().join("heightfield.obj");
    write_obj(&obj, &vertices, &faces);
    let foundry = load_scene(Some(&obj), &GdmlOptions::default()).unwrap();
    let built = build(&ctx, &foundry).expect("heightfield on the GPU");
    let sets = [
        coherent(n, zmax, count),
        incoherent(n, zmax, count),
        diffuse(&vertices, &faces, count),
    ];
    let sets: Vec<_> = sets.iter().map(|s| (s.name, rows(s))).collect();
    let workload = format!("heightfield, {} triangles", faces.len());
    report.sets(&ctx, &workload, &built, &sets);
    drop((built, foundry, sets));

    // The mixed scene.
    let foundry = scene_from_toml(&scene_text(), "mixed bench scene", &scenes_dir()).unwrap();
    let built = build(&ctx, &foundry).expect("mixed scene on the GPU");
    let workload = format!(
        "mixed scene, {} instances, {} triangles, fog box",
        foundry.inst.len(),
        foundry.tri.len()
    );
    let sets = [
        ("coherent", coherent_rays(count)),
        ("incoherent", incoherent_rays(count)),
    ];
    report.sets(&ctx, &workload, &built, &sets);
    drop((built, foundry, sets));

    // The GDML corpus, an axis sweep per file.
    let corpus = gdml_dir();
    let origins = count.div_ceil(4);
    let (mut total, mut prep_s, mut gpu_s, mut files) = (Measured::default(), 0.0, 0.0, 0);
    let mut per_file = Vec::new();
    for path in gdml_files().iter().filter(|p| p.starts_with(&corpus)) {
        let name = path.strip_prefix(&corpus).unwrap().display().to_string();
        let scene = load_scene(Some(path), &GdmlOptions::default())
            .map_err(|e| format!("loader rejects it: {e:#}"))
            .and_then(|f| {
                let bounds = scene_bounds(&f).ok_or("no placed solid")?;
                Ok((build(&ctx, &f)?, bounds))
            });
        let (built, bounds) = match scene {
            Ok(scene) => scene,
            Err(why) => {
                report.notes.push(format!("skipped `{name}`: {why}"));
                continue;
            }
        };
        let (m, timestamps) = measure(
            &ctx,
            &built.tracer,
            &generate(Sweep::Axis, &bounds, origins).unwrap(),
        );
        report.timestamps &= timestamps;
        per_file.push(format!("| {name} | {} | {} |", built.cell(), m.cells()));
        total = total.add(m);
        prep_s += built.prep_s;
        gpu_s += built.gpu_s;
        files += 1;
    }
    report.rows.push(format!(
        "| GDML corpus, {files} files | axis sweep per file | {} | {} |",
        build_cell(prep_s, gpu_s),
        total.cells()
    ));

    let mut command = String::new();
    for var in [
        "HYTRACE_BENCH_RAYS",
        "HYTRACE_BENCH_GRID",
        "HYTRACE_GDML_DIR",
    ] {
        if let Ok(value) = std::env::var(var) {
            command += &format!("{var}={value} ");
        }
    }
    command += "cargo bench -p hytrace-tests --bench gpu";
    println!("\n## GPU scan benchmark\n");
    println!("- Date: {} (UTC)", utc_date());
    println!("- Adapter: {}", ctx.describe());
    println!("- Command: `{command}`");
    println!(
        "- Host: {} threads; {count} rays per set; median of {RUNS} runs after a warm-up; \
         kernel time from {}",
        std::thread::available_parallelism().map_or(1, |n| n.get()),
        if report.timestamps {
            "GPU timestamp queries"
        } else {
            "the host (submission to completion: no timestamp queries)"
        }
    );
    if software {
        println!(
            "- **The adapter is a CPU (a software rasterizer): these are functional numbers, \
             not GPU performance.**"
        );
    }
    println!(
        "\n| workload | rays | build s (CpuScene + GpuTracer) | rays traced | kernel Mrays/s | end-to-end Mrays/s | hit % |"
    );
    println!("|---|---|---:|---:|---:|---:|---:|");
    for row in &report.rows {
        println!("{row}");
    }
    println!(
        "\nGDML corpus per file (axis sweep: {origins} origins on the x axis, each shooting \
         along +-y and +-z):\n"
    );
    println!("| file | build s (CpuScene + GpuTracer) | rays | kernel Mrays/s | end-to-end Mrays/s | hit % |");
    println!("|---|---:|---:|---:|---:|---:|");
    for row in &per_file {
        println!("{row}");
    }
    for note in &report.notes {
        println!("\n- {note}");
    }
    println!(
        "\nTotal benchmark time: {:.0} s",
        start.elapsed().as_secs_f64()
    );
}
