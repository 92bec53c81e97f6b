//! `hytrace photons`: options, outputs and the history table.

use std::path::PathBuf;
use std::time::Instant;

use clap::Args;
use hytrace_foundry::gdml::GdmlOptions;
use hytrace_trace::gpu::{add_gpu_stats, warn_redone};
use hytrace_trace::outputs::{check_destinations, OutputSet};
use hytrace_trace::photons::backend::{propagate_on, BackendRun, PhotonBackend};
use hytrace_trace::photons::output::{history_table, write_histories, write_hits};
use hytrace_trace::photons::sources::{Source, Wavelength};
use hytrace_trace::photons::{load_photon_scene, RunOptions};
use serde_json::json;

use super::choice::choice;

/// Options of `hytrace photons`.
#[derive(Args, Debug)]
pub struct PhotonsArgs {
    /// A .gdml file (optical surfaces found as Geant4 finds them), a Foundry directory or a
    /// .toml scene file (surfaces from the boundary table).
    pub scene: PathBuf,
    /// Photon source: `point:X,Y,Z` (isotropic from a point), `beam:X,Y,Z:DX,DY,DZ:R[:A]`
    /// (along D over the disk of radius R centred on X,Y,Z, perpendicular to D; parallel,
    /// or spread uniformly within a cone of half-angle A degrees) or `sphere:X,Y,Z:R:in`
    /// / `...:out` (from the sphere's surface along its inward or outward normal); mm.
    /// Photons start at time 0 with a random linear polarization perpendicular to their
    /// direction.
    #[arg(long)]
    pub source: String,
    /// Wavelength of every photon, nm (photon energy h c / lambda, h c = 1239.84198 eV nm),
    /// or MATERIAL:PROPERTY: drawn for each photon from that intensity table (per photon
    /// energy) of a material of the scene, e.g. LAr:SCINTILLATIONCOMPONENT1.
    #[arg(long, default_value = "420")]
    pub wavelength: String,
    /// Number of photons.
    #[arg(short = 'n', long)]
    pub photons: u64,
    /// Detected photons, float64 (H, 16): x y z (mm) t (ns) dx dy dz wavelength (nm)
    /// px py pz (polarization) instance (whose surface detected it) copy (its copy number)
    /// photon (index) mask (history flags, Opticks' bits) steps; written atomically.
    #[arg(short = 'o', long)]
    pub out: PathBuf,
    /// Index of the first photon: photons FIRST .. FIRST + N are propagated, each with its
    /// own stream, so a run split into ranges gives exactly the whole run's photons.
    #[arg(long, default_value_t = 0)]
    pub first: u64,
    /// Seed of the random streams: photon i draws stream (seed, i), so results do not
    /// depend on the number of threads.
    #[arg(long, default_value_t = 0)]
    pub seed: u32,
    /// Print the table of the most frequent step histories (Opticks labels: TO BT BR SR
    /// SC AB SD SA MI TR), and with `--history=PATH` also write every photon's packed
    /// history there, uint64 (N,), 4 bits a label, first label lowest.
    #[arg(long, num_args = 0..=1, require_equals = true, value_name = "PATH")]
    pub history: Option<Option<PathBuf>>,
    /// Rows of the history table.
    #[arg(long, default_value_t = 20)]
    pub top: usize,
    /// Steps after which a photon is stopped (history label TR).
    #[arg(long, default_value_t = 10_000)]
    pub max_steps: u32,
    /// Where photons are propagated: cpu (f64 geometry), gpu (the WGSL kernel, f32: torch
    /// sources at a fixed wavelength, absorption, Rayleigh scattering, Fresnel boundaries,
    /// polished surfaces; other physics is refused, naming it) or auto (the GPU when an
    /// adapter opens and the kernel models the scene, else the CPU).
    #[arg(long, value_parser = choice::<PhotonBackend>(), default_value_t = PhotonBackend::Cpu)]
    pub backend: PhotonBackend,
    /// Print one JSON line of counts and timings (photons, hits, load_s, build_s,
    /// propagate_s, photons_per_s, threads, backend; on the GPU also the adapter and its
    /// times).
    #[arg(long)]
    pub stats: bool,
}

/// Runs `hytrace photons`.
pub fn run(args: PhotonsArgs, options: &GdmlOptions) -> anyhow::Result<()> {
    let source = Source::parse(&args.source)?;
    // Both outputs are checked before the work and written together after it.
    let history_path = args.history.as_ref().and_then(|h| h.as_deref());
    let mut destinations = vec![("--out", args.out.as_path())];
    destinations.extend(history_path.map(|p| ("--history", p)));
    check_destinations(&destinations)?;
    let t0 = Instant::now();
    let (f, surfaces) = load_photon_scene(&args.scene, options)?;
    let load_s = t0.elapsed().as_secs_f64();
    let bar = hytrace_trace::progress::bar(args.photons, "propagating", "photons");
    let BackendRun { run, build_s, gpu } = propagate_on(
        &f,
        surfaces,
        &args.scene,
        &RunOptions {
            source,
            wavelength: Wavelength::parse(&args.wavelength)?,
            photons: args.photons,
            first: args.first,
            seed: args.seed,
            max_steps: args.max_steps,
            keep_histories: matches!(args.history, Some(Some(_))),
        },
        args.backend,
        &|done| bar.set_position(done),
    )?;
    bar.finish_and_clear();
    if let Some(g) = &gpu {
        warn_redone(&g.adapter, &g.times, args.photons as usize, "photons");
    }
    let mut written = OutputSet::new();
    written.stage(&args.out, |p| Ok(write_hits(p, &run.hits)?))?;
    if let Some(path) = history_path {
        written.stage(path, |p| Ok(write_histories(p, &run.histories)?))?;
    }
    written.commit()?;
    if args.history.is_some() {
        print!("{}", history_table(&run.counts, args.top));
    }
    if args.stats {
        let mut line = json!({
            "backend": if gpu.is_some() { "gpu" } else { "cpu" },
            "photons": args.photons,
            "hits": run.hits.len(),
            "load_s": load_s,
            "build_s": build_s,
            "propagate_s": run.propagate_s,
            "photons_per_s": if run.propagate_s > 0.0 { args.photons as f64 / run.propagate_s } else { 0.0 },
            "threads": rayon::current_num_threads(),
        });
        if let Some(g) = &gpu {
            add_gpu_stats(&mut line, &g.adapter, &g.features, &g.times);
        }
        println!("{line}");
    } else {
        eprintln!(
            "{} photons, {} detected, written to {}",
            args.photons,
            run.hits.len(),
            args.out.display()
        );
    }
    Ok(())
}
