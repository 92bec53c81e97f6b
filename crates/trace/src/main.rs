//! The `hytrace` command-line tool.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context;
use clap::{Parser, Subcommand};
use hytrace_foundry::gdml::GdmlOptions;
use hytrace_trace::gpu::GpuContext;
use hytrace_trace::scan::{self, Precision};
use hytrace_trace::sweep::{self, Sweep};
use hytrace_trace::{report, scene};

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
    },
    /// Describe the GPU adapter wgpu finds (lavapipe on machines without a GPU).
    GpuInfo,
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
        } => {
            let t0 = std::time::Instant::now();
            let f = scene::load_scene(scene.as_deref(), &options)?;
            let ray_rows = match (sweep_kind, &rays) {
                (Some(kind), _) => {
                    let bounds =
                        sweep::scene_bounds(&f).context("the scene has no solids to sweep")?;
                    let generated = sweep::generate(kind, &bounds, count);
                    if let Some(p) = &rays {
                        scan::write_rays(p, &generated)
                            .with_context(|| format!("writing {}", p.display()))?;
                    }
                    generated
                }
                (None, Some(p)) => scan::read_rays(p)?,
                (None, None) => anyhow::bail!("give --rays RAYS.npy or --sweep KIND"),
            };
            let load_s = t0.elapsed().as_secs_f64();
            let (result, times) = scan::scan(&f, &ray_rows, precision)?;
            scan::write_hits(&result, precision, &out, ids.as_deref())
                .with_context(|| format!("writing {}", out.display()))?;
            let hits = result.ids.iter().filter(|i| i[0] >= 0).count();
            if stats {
                println!("{}", scan::stats_json(ray_rows.len(), load_s, &times, hits));
            } else {
                eprintln!(
                    "{} rays, {hits} hits, {:.3} s tracing; wrote {}",
                    ray_rows.len(),
                    times.trace_s,
                    out.display()
                );
            }
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
    match run(Cli::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("hytrace: error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
