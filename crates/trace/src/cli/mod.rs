//! The `hytrace` command line: options and reports, one module per subcommand; the work is
//! the library's (`hytrace_trace`).

mod bench;
mod choice;
mod options;
mod photons;
mod render;
mod scan;
mod volume;

use std::path::PathBuf;

use anyhow::Context;
use clap::{Parser, Subcommand};
use hytrace_foundry::gdml::GdmlOptions;
use hytrace_trace::gpu::GpuContext;
use hytrace_trace::{report, scene};

/// Hybrid ray tracing of analytic CSG solids (every Geant4 solid, GDML detectors), triangle
/// meshes and sparse volumes (NanoVDB, OpenVDB), on the CPU and on GPUs.
///
/// hytrace traces rays through detector geometry as Geant4's navigator sees it: `scan`
/// finds the first boundary crossing of each ray (and the media's transmittance),
/// `render` draws images of scenes and GDML detectors, `photons` propagates optical
/// photons, `volume` converts and queries sparse volumes. A scene is `default` (an
/// embedded example), a .toml scene file, a .gdml file, a mesh or a Foundry directory.
#[derive(Parser)]
#[command(name = "hytrace", version)]
pub struct Cli {
    #[command(subcommand)]
    command: Command,
    /// Skip GDML elements this build does not support (with a warning) instead of failing.
    #[arg(long, global = true)]
    lenient: bool,
}

/// The subcommands of `hytrace`.
#[derive(Subcommand)]
pub enum Command {
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
    /// Trace rays through a scene (CSG solids, GDML volumes and triangle meshes) on our CPU
    /// tracer, Embree or the GPU: the first boundary crossing of each ray (Geant4's
    /// distance to the next boundary), written as NumPy arrays.
    Scan(scan::ScanArgs),
    /// Render a scene (the embedded default scene when SCENE is omitted) on the CPU or the
    /// GPU to a PNG, NumPy or OpenEXR image, simulating only the effects the scene calls
    /// for; a GDML file as a detector view (cutaways, colours, legend).
    Render(render::RenderArgs),
    /// Propagate optical photons from a source through a scene with Geant4's optical
    /// physics (Fresnel, total internal reflection, absorption, Rayleigh scattering,
    /// wavelength shifting, dielectric_metal and dielectric_dielectric surfaces of the
    /// glisur and unified models: polished, ground and painted) on the CPU; write the
    /// detected photons.
    Photons(photons::PhotonsArgs),
    /// Describe the GPU adapter wgpu finds (lavapipe on machines without a GPU).
    GpuInfo,
    /// Sparse volumes: NanoVDB (.nvdb), OpenVDB (.vdb) or procedural grids
    /// (`sphere:RADIUS[,VOXEL[,BLEND]]`, `box:W,H,D[,VOXEL[,BLEND]]`).
    #[command(subcommand)]
    Volume(volume::VolumeCommand),
    /// Benchmarks.
    #[command(subcommand)]
    Bench(bench::BenchCommand),
}

/// Runs the command `cli` names.
pub fn run(cli: Cli) -> anyhow::Result<()> {
    // A HYTRACE_SIMD that names no path, or one this CPU lacks, is refused before any work.
    if let Some(path) = hytrace_csg::simd::SimdPath::from_env()? {
        hytrace_csg::simd::select(path)?;
    }
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
        Command::Scan(args) => scan::run(args, &options)?,
        Command::Volume(command) => volume::run(command)?,
        Command::Render(args) => render::run(args, &options)?,
        Command::Photons(args) => photons::run(args, &options)?,
        Command::Bench(command) => bench::run(command)?,
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
