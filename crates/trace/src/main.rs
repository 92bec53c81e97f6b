//! The `hytrace` command-line tool.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::Context;
use clap::{Parser, Subcommand};
use hytrace_foundry::gdml::GdmlOptions;
use hytrace_trace::gpu::{GpuContext, TexelStore};
use hytrace_trace::scan::{self, Backend, Precision};
use hytrace_trace::sweep::{self, Sweep};
use hytrace_trace::volume::{self, FilterArg, Repr, Space};
use hytrace_trace::{accuracy, outputs, report, scene};
use hytrace_volume::TexelFormat;

/// Hybrid ray tracing of analytic CSG solids, triangle meshes and sparse volumes.
#[derive(Parser)]
#[command(name = "hytrace", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
    /// Skip GDML elements this build does not support (with a warning) instead of failing.
    #[arg(long, global = true)]
    lenient: bool,
}

#[derive(Subcommand)]
enum Command {
    /// Print a summary of a scene (the embedded default scene when SCENE is omitted).
    Info {
        /// `default`, a Foundry directory, a .toml scene file or a .gdml file.
        scene: Option<PathBuf>,
        /// Print JSON instead of text.
        #[arg(long)]
        json: bool,
    },
    /// Write a scene's Foundry store as one .npy file per array (plus meta.json) into DIR.
    Foundry {
        /// `default`, a Foundry directory, a .toml scene file or a .gdml file.
        scene: Option<PathBuf>,
        /// Output directory (created or replaced as a whole).
        #[arg(short, long)]
        out: PathBuf,
    },
    /// Trace rays against the scene's CSG solids on the CPU: the first boundary crossing of
    /// each ray (Geant4's distance to the next boundary), written as NumPy arrays.
    Scan {
        /// `default`, a Foundry directory, a .toml scene file or a .gdml file.
        scene: Option<PathBuf>,
        /// Rays, (N, 8) float32/float64: ox oy oz tmin dx dy dz tmax. With --sweep, the
        /// generated rays are written here instead (optional).
        #[arg(long)]
        rays: Option<PathBuf>,
        /// Generate a sweep around the scene instead of reading rays.
        #[arg(long, value_enum)]
        sweep: Option<Sweep>,
        /// Rays in the sweep (origins for `axis` and `circle`, per side for `rect`).
        #[arg(long, default_value_t = 1000)]
        count: usize,
        /// Hits, (N, 4): nx ny nz t (t = inf on a miss).
        #[arg(long)]
        out: PathBuf,
        /// Identity of each crossing, int32 (N, 3): instance, boundary (index into the
        /// boundary table of `hytrace info`), copy number; -1 on a miss.
        #[arg(long)]
        ids: Option<PathBuf>,
        /// Arithmetic precision (and dtype of the hits).
        #[arg(long, value_enum, default_value_t = Precision::F32)]
        precision: Precision,
        /// Print one JSON line of counts and timings.
        #[arg(long)]
        stats: bool,
        /// Tracer: our CPU tracer; Embree (f32; needs a build with `--features embree`); our
        /// GPU tracer through wgpu (f32); or `auto`: the GPU when one opens, else the CPU.
        #[arg(long, value_enum, default_value_t = Backend::Cpu)]
        backend: Backend,
        /// Also write the transmittance of the scene's media along each ray up to its first
        /// surface crossing (to tmax on a miss), (N,) float64 (not with Embree).
        #[arg(long)]
        transmittance: Option<PathBuf>,
        #[command(flatten)]
        estimate: volume::EstimatorOptions,
    },
    /// Render a scene (the embedded default scene when SCENE is omitted) to a PNG or NumPy
    /// image, simulating only the effects the scene calls for.
    Render(hytrace_trace::render::run::RenderArgs),
    /// Propagate optical photons from a source through a scene with Geant4's optical
    /// physics (Fresnel, total internal reflection, absorption, Rayleigh scattering,
    /// polished dielectric_metal and dielectric_dielectric surfaces) on the CPU; write the
    /// detected photons.
    Photons(hytrace_trace::photons::run::PhotonsArgs),
    /// Describe the GPU adapter wgpu finds (lavapipe on machines without a GPU).
    GpuInfo,
    /// Sparse volumes: NanoVDB (.nvdb), OpenVDB (.vdb) or procedural grids
    /// (`sphere:RADIUS[,VOXEL[,BLEND]]`, `box:W,H,D[,VOXEL[,BLEND]]`).
    #[command(subcommand)]
    Volume(VolumeCommand),
    /// Benchmarks.
    #[command(subcommand)]
    Bench(BenchCommand),
}

#[derive(Subcommand)]
enum BenchCommand {
    /// Error against a high-precision reference and time per operation of every accuracy
    /// knob (CSG, triangles, volumes), written as DIR/accuracy.csv, DIR/accuracy.md and one
    /// error-versus-time plot per knob (DIR/accuracy-*.svg) with the Pareto front marked.
    Accuracy {
        /// Output directory (created if missing).
        #[arg(short, long, default_value = "accuracy")]
        out: PathBuf,
        /// Small inputs and few repeats (well under a minute), for CI.
        #[arg(long)]
        quick: bool,
    },
}

#[derive(Subcommand)]
enum VolumeCommand {
    /// Grids, value types, bounding boxes, voxel counts and memory per representation.
    Info {
        /// A .nvdb or .vdb file, or a procedural grid.
        file: String,
        /// Print JSON instead of text.
        #[arg(long)]
        json: bool,
    },
    /// Look up the grid at points: (N, 3) float32/float64 in, (N,) float32 out.
    Sample {
        /// A .nvdb or .vdb file, or a procedural grid.
        file: String,
        /// Points, (N, 3) float32 or float64.
        #[arg(long)]
        points: PathBuf,
        /// Values, (N,) float32.
        #[arg(long)]
        out: PathBuf,
        /// Coordinates of the points.
        #[arg(long, value_enum, default_value_t = Space::World)]
        space: Space,
        /// Lookup filter.
        #[arg(long, value_enum, default_value_t = FilterArg::Trilinear)]
        filter: FilterArg,
        /// Representation looked up.
        #[arg(long, value_enum, default_value_t = Repr::Nanovdb)]
        repr: Repr,
        /// Grid name (default: the first grid).
        #[arg(long)]
        grid: Option<String>,
        /// Seed of the stochastic filter's random numbers.
        #[arg(long, default_value_t = 0)]
        seed: u32,
        /// Write the local majorant at this mip level (0: 8^3 blocks .. 3: 64^3) of the block
        /// holding each point instead of the value: the largest value any lookup there reads.
        #[arg(long)]
        majorant: Option<usize>,
        /// Memory a brick store may hold resident (its tables and brick cache), e.g. 4G.
        #[arg(long, value_parser = hytrace_trace::memory::parse_bytes, default_value = "1G")]
        memory: u64,
    },
    /// Transmittance along rays: (N, 8) rays (ox oy oz tmin dx dy dz tmax, world space) in,
    /// (N,) float64 out; density = value x scale, per unit of world length.
    Transmittance {
        /// A .nvdb or .vdb file, or a procedural grid.
        file: String,
        /// Rays, (N, 8) float32 or float64.
        #[arg(long)]
        rays: PathBuf,
        /// Transmittances, (N,) float64.
        #[arg(long)]
        out: PathBuf,
        /// Representation traced.
        #[arg(long, value_enum, default_value_t = Repr::Nanovdb)]
        repr: Repr,
        #[command(flatten)]
        estimate: volume::EstimatorOptions,
        /// Grid name (default: the first grid).
        #[arg(long)]
        grid: Option<String>,
        /// Where to trace: the CPU (f64), the GPU (f32: bricked grids, or with `--repr
        /// nanovdb` a NanoVDB file's raw buffer; other grids are converted to f32 bricks) or
        /// the GPU when one opens, else the CPU.
        #[arg(long, value_enum, default_value_t = volume::VolumeBackend::Cpu)]
        backend: volume::VolumeBackend,
        /// Where the GPU reads a bricked grid's texels from: a storage buffer, decoded as on
        /// the CPU, or a 3D texture (BC4 then decoded by the device).
        #[arg(long, value_enum, default_value_t = TexelStore::Storage)]
        gpu_texels: TexelStore,
        /// Print one JSON line of counts and timings.
        #[arg(long)]
        stats: bool,
        /// Memory a brick store may hold resident (its tables and brick cache), e.g. 4G.
        #[arg(long, value_parser = hytrace_trace::memory::parse_bytes, default_value = "1G")]
        memory: u64,
    },
    /// Write the bricked grid (atlas, indirection, brick table, range mips) as .npy files,
    /// or with --store an out-of-core brick store (also from raw files larger than memory).
    Convert {
        /// A .nvdb or .vdb file, a procedural grid, or with --store a raw file (`.raw`,
        /// with --dims and --dtype).
        file: String,
        /// Texel format of the bricked grid.
        #[arg(long, required_unless_present = "store", conflicts_with = "store")]
        format: Option<TexelFormat>,
        /// Write a brick store instead: superchunks of 16^3 bricks of 16-bit 8^3 bricks,
        /// empty bricks dropped, range mips and levels of detail, converted in bounded
        /// memory (--memory); every volume command then reads it through a brick cache.
        #[arg(long)]
        store: bool,
        /// Output directory (a brick store's must not exist).
        #[arg(short, long)]
        out: PathBuf,
        /// Grid name (default: the first grid).
        #[arg(long)]
        grid: Option<String>,
        #[command(flatten)]
        store_options: volume::StoreOptions,
    },
}

fn run_volume(command: VolumeCommand) -> anyhow::Result<()> {
    match command {
        VolumeCommand::Info { file, json } => {
            let info = volume::info(&file)?;
            if json {
                println!("{info}");
            } else {
                print!("{}", volume::info_text(&info));
            }
        }
        VolumeCommand::Sample {
            file,
            points,
            out,
            space,
            filter,
            repr,
            grid,
            seed,
            majorant,
            memory,
        } => {
            let (_, g) = volume::open_within(&file, grid.as_deref(), memory)?;
            let points = volume::read_points(&points)?;
            let g = volume::represent(g, repr)?;
            let values = match majorant {
                Some(level) => volume::majorants(&g, &points, space, level)?,
                None => volume::sample_points(g.grid(), &points, space, filter.into(), seed),
            };
            g.check_reads()?;
            volume::write_f32(&out, &values)?;
            eprintln!("{} lookups; wrote {}", values.len(), out.display());
        }
        VolumeCommand::Transmittance {
            file,
            rays,
            out,
            repr,
            estimate,
            grid,
            backend,
            gpu_texels,
            stats,
            memory,
        } => {
            let t0 = std::time::Instant::now();
            let (_, g) = volume::open_within(&file, grid.as_deref(), memory)?;
            let rays = scan::read_rays(&rays)?;
            let g = volume::represent(g, repr)?;
            let load_s = t0.elapsed().as_secs_f64();
            let run = volume::transmittances_on(&g, &rays, &estimate.args(), backend, gpu_texels)?;
            g.check_reads()?;
            let values: Vec<f64> = run.estimates.iter().map(|e| e.transmittance).collect();
            volume::write_f64(&out, &values)?;
            if stats {
                println!("{}", volume::transmittance_stats(&run, load_s));
            } else {
                eprintln!(
                    "{} rays, {:.3} s; wrote {}",
                    rays.len(),
                    run.trace_s,
                    out.display()
                );
            }
        }
        VolumeCommand::Convert {
            file,
            format,
            store,
            out,
            grid,
            store_options,
        } => {
            if store {
                let r = volume::convert_store(&file, grid.as_deref(), &out, &store_options)?;
                eprintln!(
                    "{}x{}x{} voxels: {} bricks kept, {} dropped; {} bytes written in {:.1} s (range {:.1} s); wrote {}",
                    r.meta.dims[0],
                    r.meta.dims[1],
                    r.meta.dims[2],
                    r.meta.kept_bricks,
                    r.meta.dropped_bricks,
                    r.bytes_written,
                    r.range_s + r.brick_s,
                    r.range_s,
                    out.display()
                );
                return Ok(());
            }
            let Some(format) = format else {
                anyhow::bail!("volume convert needs --format (or --store)");
            };
            let (_, g) = volume::open(&file, grid.as_deref())?;
            let b = hytrace_volume::BrickedGrid::convert(&g, format)?;
            b.write_npy_dir(&out)?;
            let m = b.memory_bytes();
            eprintln!(
                "{} bricks ({} with texels), {} bytes, max voxel error {:.3e}; wrote {}",
                b.bricks().len(),
                b.atlas_slots(),
                m.total(),
                b.error_bound(),
                out.display()
            );
        }
    }
    Ok(())
}

fn run(cli: Cli) -> anyhow::Result<()> {
    let options = GdmlOptions {
        lenient: cli.lenient,
    };
    match cli.command {
        Command::Info { scene, json } => {
            let f = scene::load_scene(scene.as_deref(), &options)?;
            if json {
                println!("{}", report::summary(&f));
            } else {
                print!("{}", report::summary_text(&f));
            }
        }
        Command::Foundry { scene, out } => {
            let f = scene::load_scene(scene.as_deref(), &options)?;
            f.save(&out)
                .with_context(|| format!("writing {}", out.display()))?;
            print!("{}", report::summary_text(&f));
            println!(
                "wrote {} files to {}",
                hytrace_foundry::file_names().len(),
                out.display()
            );
        }
        Command::Scan {
            scene,
            rays,
            sweep: sweep_kind,
            count,
            out,
            ids,
            precision,
            stats,
            backend,
            transmittance,
            estimate,
        } => {
            // Every output is checked before the work and written together after it.
            let generated_rays = rays.as_deref().filter(|_| sweep_kind.is_some());
            let destinations: Vec<(&str, &Path)> = [
                ("--out", Some(out.as_path())),
                ("--ids", ids.as_deref()),
                ("--transmittance", transmittance.as_deref()),
                ("--rays", generated_rays),
            ]
            .into_iter()
            .filter_map(|(option, path)| Some((option, path?)))
            .collect();
            outputs::check_destinations(&destinations)?;
            let t0 = std::time::Instant::now();
            let f = scene::load_scene(scene.as_deref(), &options)?;
            let ray_rows = match (sweep_kind, &rays) {
                (Some(kind), _) => {
                    let bounds =
                        sweep::scene_bounds(&f).context("the scene has no solids to sweep")?;
                    sweep::generate(kind, &bounds, count)
                        .with_context(|| format!("--count {count}"))?
                }
                (None, Some(p)) => scan::read_rays(p)?,
                (None, None) => anyhow::bail!("give --rays RAYS.npy or --sweep KIND"),
            };
            let load_s = t0.elapsed().as_secs_f64();
            let bar = hytrace_trace::progress::bar(ray_rows.len() as u64, "tracing", "rays");
            let progress = |done| bar.set_position(done);
            let (result, times) =
                scan::scan_reporting(&f, &ray_rows, precision, backend, &progress)?;
            bar.finish_and_clear();
            // The media where the surfaces ran (`auto` on the GPU may still fall back).
            let media_backend = match times.gpu {
                Some(_) => backend,
                None => Backend::Cpu,
            };
            let media = match &transmittance {
                Some(_) => Some(scan::media_transmittance(
                    &f,
                    &ray_rows,
                    &scan::ray_ends(&result, &ray_rows),
                    precision,
                    &estimate.args().params(),
                    media_backend,
                    0,
                )?),
                None => None,
            };
            let mut written = outputs::OutputSet::new();
            written.stage(&out, |p| scan::write_hits(&result, precision, p))?;
            if let Some(path) = &ids {
                written.stage(path, |p| scan::write_ids(&result, p))?;
            }
            if let (Some(path), Some(run)) = (&transmittance, &media) {
                written.stage(path, |p| volume::write_f64(p, &run.values))?;
            }
            if let Some(path) = generated_rays {
                written.stage(path, |p| scan::write_rays(p, &ray_rows))?;
            }
            written.commit()?;
            let hits = result.ids.iter().filter(|i| i[0] >= 0).count();
            if stats {
                let mut line = scan::stats_json(backend, ray_rows.len(), load_s, &times, hits);
                if let Some(run) = &media {
                    run.add_stats(&mut line);
                }
                println!("{line}");
            } else {
                eprintln!(
                    "{} rays, {hits} hits, {:.3} s tracing; wrote {}",
                    ray_rows.len(),
                    times.trace_s,
                    out.display()
                );
            }
        }
        Command::Volume(command) => run_volume(command)?,
        Command::Render(args) => hytrace_trace::render::run::run(args, &options)?,
        Command::Photons(args) => hytrace_trace::photons::run::run(args, &options)?,
        Command::Bench(BenchCommand::Accuracy { out, quick }) => {
            let settings = accuracy::Settings { quick };
            eprintln!("measuring on {}", accuracy::machine_line(settings));
            let rows = accuracy::run(settings, &out).map_err(anyhow::Error::msg)?;
            eprintln!(
                "{} rows; wrote {}/accuracy.csv, accuracy.md and the plots",
                rows.len(),
                out.display()
            );
        }
        Command::GpuInfo => {
            let ctx = GpuContext::new()?;
            println!("{}", ctx.describe());
            println!(
                "max storage binding: {} bytes",
                ctx.limits.max_storage_buffer_binding_size
            );
        }
    }
    Ok(())
}

fn main() -> ExitCode {
    // An interrupted command leaves no partial output: the temporary files it was writing
    // are removed before it exits (with 130, as shells report an interrupt).
    if let Err(e) = ctrlc::set_handler(|| {
        hytrace_foundry::npy::remove_temporaries();
        std::process::exit(130);
    }) {
        eprintln!(
            "hytrace: warning: no interrupt handler ({e}): an interrupt may leave temporary files"
        );
    }
    match run(Cli::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("hytrace: error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
