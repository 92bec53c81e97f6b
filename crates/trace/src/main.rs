//! The `hytrace` command-line tool.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context;
use clap::{Parser, Subcommand};
use hytrace_trace::gpu::GpuContext;
use hytrace_trace::{report, scene};

/// Hybrid ray tracing of analytic CSG solids, triangle meshes and sparse volumes.
#[derive(Parser)]
#[command(name = "hytrace", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Print a summary of a scene (the embedded default scene when SCENE is omitted).
    Info {
        /// `default` or a Foundry directory.
        scene: Option<PathBuf>,
        /// Print JSON instead of text.
        #[arg(long)]
        json: bool,
    },
    /// Write a scene's Foundry store as one .npy file per array (plus meta.json) into DIR.
    Foundry {
        /// `default` or a Foundry directory.
        scene: Option<PathBuf>,
        /// Output directory (created or replaced as a whole).
        #[arg(short, long)]
        out: PathBuf,
    },
    /// Describe the GPU adapter wgpu finds (lavapipe on machines without a GPU).
    GpuInfo,
}

fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Info { scene, json } => {
            let f = scene::load_scene(scene.as_deref())?;
            if json {
                println!("{}", report::summary(&f));
            } else {
                print!("{}", report::summary_text(&f));
            }
        }
        Command::Foundry { scene, out } => {
            let f = scene::load_scene(scene.as_deref())?;
            f.save(&out)
                .with_context(|| format!("writing {}", out.display()))?;
            print!("{}", report::summary_text(&f));
            println!(
                "wrote {} files to {}",
                hytrace_foundry::file_names().len(),
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
    match run(Cli::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("hytrace: error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
