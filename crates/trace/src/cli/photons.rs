//! `hytrace photons`: options, outputs and the history table.

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

use anyhow::{bail, Context};
use clap::Args;
use hytrace_foundry::gdml::GdmlOptions;
use hytrace_trace::gpu::{add_gpu_stats, warn_redone, BYTES_PER_PHOTON};
use hytrace_trace::outputs::{check_destinations, OutputSet};
use hytrace_trace::photons::backend::{propagate_on, BackendRun, PhotonBackend};
use hytrace_trace::photons::explain::explain;
use hytrace_trace::photons::gensteps::GenstepFile;
use hytrace_trace::photons::output::{history_table, RunFiles};
use hytrace_trace::photons::sources::{Source, Wavelength};
use hytrace_trace::photons::{load_photon_scene, Origin, PhotonScene, RunOptions};
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
    #[arg(
        long,
        required_unless_present = "gensteps",
        conflicts_with = "gensteps"
    )]
    pub source: Option<String>,
    /// Photons from gensteps instead of a source: a float64 .npy of shape (G, 14), one row
    /// a Cherenkov (kind 1) or scintillation (kind 2) step of a charged particle, emitted as
    /// Geant4's G4Cerenkov and G4Scintillation emit them (layout in docs/photons.md).
    #[arg(long, value_name = "G.npy")]
    pub gensteps: Option<PathBuf>,
    /// Wavelength of every photon, nm (photon energy h c / lambda, h c = 1239.84198 eV nm),
    /// or MATERIAL:PROPERTY: drawn for each photon from that intensity table (per photon
    /// energy) of a material of the scene, e.g. LAr:SCINTILLATIONCOMPONENT1 (torch sources
    /// only).
    #[arg(long, default_value = "420", conflicts_with = "gensteps")]
    pub wavelength: String,
    /// Number of photons (with --gensteps: by default all from --first on).
    #[arg(short = 'n', long, required_unless_present_any = ["gensteps", "explain"])]
    pub photons: Option<u64>,
    /// Detected photons, float64 (H, 16): x y z (mm) t (ns) dx dy dz wavelength (nm)
    /// px py pz (polarization) instance (whose surface detected it) copy (its copy number)
    /// photon (index) mask (history flags, Opticks' bits) steps; written atomically.
    #[arg(short = 'o', long, required_unless_present = "explain")]
    pub out: Option<PathBuf>,
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
    /// Record the first K step points of every photon (its own lineage, through
    /// re-emissions) into --records-out: float32 (N, K, 12), x y z t dx dy dz wavelength
    /// px py pz label (direction and polarization as it leaves the point, label code as in
    /// the history; zeros past the photon's end).
    #[arg(long, value_name = "K", requires = "records_out")]
    pub records: Option<u32>,
    /// Where --records writes the step points.
    #[arg(long, value_name = "PATH", requires = "records")]
    pub records_out: Option<PathBuf>,
    /// Photons propagated per batch (default: 65536 on the CPU; on the GPU as many as fill
    /// it, up to 1048576): each batch's hits, histories and records are written out as it
    /// finishes, so memory is bounded by the batch; results do not depend on it.
    #[arg(long)]
    pub batch: Option<u64>,
    /// Rows of the history table.
    #[arg(long, default_value_t = 20)]
    pub top: usize,
    /// Steps after which a photon is stopped (history label TR).
    #[arg(long, default_value_t = 10_000)]
    pub max_steps: u32,
    /// Where photons are propagated: cpu (f64 geometry), gpu (the WGSL kernel, f32, with
    /// the same physics and outputs; a photon whose wavelength-shifting absorption emits
    /// several photons is propagated on the CPU with them; --explain lists what the run
    /// needs) or auto (the GPU when an adapter opens, else the CPU).
    #[arg(long, value_parser = choice::<PhotonBackend>(), default_value_t = PhotonBackend::Cpu)]
    pub backend: PhotonBackend,
    /// Device memory a medium read as stored in a brick store may take on the GPU (its
    /// brick pool, page table and request buffer), e.g. 256M; the run streams the store
    /// through it in passes. A budget too small for one superchunk's bricks, or for the
    /// bricks one photon reads, is refused.
    #[arg(long, value_parser = hytrace_trace::memory::parse_bytes, default_value = "1G")]
    pub memory: u64,
    /// Print the processes the run calls for (source, bulk processes with their materials,
    /// optical surfaces, outputs), where each runs (cpu, gpu), and what the GPU kernel would
    /// be composed of; propagate nothing.
    #[arg(long)]
    pub explain: bool,
    /// Print one JSON line of counts and timings (photons, hits, load_s, build_s,
    /// propagate_s and of it tally_s and write_s, photons_per_s, threads, backend; on the
    /// GPU also the adapter, its times, the host's work on the results and the batch, and
    /// `stream` for a medium read as stored: passes, photons_deferred, bricks uploaded and
    /// evicted, the pool's slots and device bytes).
    #[arg(long)]
    pub stats: bool,
}

/// Runs `hytrace photons`.
pub fn run(args: PhotonsArgs, options: &GdmlOptions) -> anyhow::Result<()> {
    let origin = match (&args.gensteps, &args.source) {
        (Some(path), _) => Origin::Gensteps(Arc::new(GenstepFile::read(path)?)),
        (None, Some(source)) => Origin::Torch {
            source: Source::parse(source)?,
            wavelength: Wavelength::parse(&args.wavelength)?,
        },
        (None, None) => bail!("give --source or --gensteps"),
    };
    if args.explain {
        let (f, surfaces) = load_photon_scene(&args.scene, options)?;
        let scene = PhotonScene::new(&f, surfaces)
            .with_context(|| format!("{}: preparing for photons", args.scene.display()))?;
        let run = RunOptions {
            origin,
            photons: args.photons.unwrap_or(1),
            first: args.first,
            seed: args.seed,
            max_steps: args.max_steps,
            keep_histories: false,
            records: args.records.unwrap_or(0),
        };
        for line in explain(&scene, &run) {
            println!("{line}");
        }
        return Ok(());
    }
    let Some(out) = &args.out else {
        bail!("give -o HITS.npy");
    };
    // The outputs are checked before the work, streamed to temporary files during it and
    // moved into place together after it.
    let history_path = args.history.as_ref().and_then(|h| h.as_deref());
    let mut destinations = vec![("--out", out.as_path())];
    destinations.extend(history_path.map(|p| ("--history", p)));
    destinations.extend(args.records_out.as_deref().map(|p| ("--records-out", p)));
    check_destinations(&destinations)?;
    if args.records == Some(0) {
        bail!("--records 0: record at least one step point");
    }
    let t0 = Instant::now();
    let (f, surfaces) = load_photon_scene(&args.scene, options)?;
    let load_s = t0.elapsed().as_secs_f64();
    let photons = match (args.photons, &origin) {
        (Some(n), _) => n,
        (None, Origin::Gensteps(file)) => {
            let total = file.photons(&f.optics.materials)?;
            if total <= args.first {
                bail!(
                    "{}: the gensteps emit {total} photons, none from --first {}",
                    file.source,
                    args.first
                );
            }
            total - args.first
        }
        (None, Origin::Torch { .. }) => bail!("-n is needed with --source"),
    };
    let mut written = OutputSet::new();
    let hits_tmp = written.reserve(out)?;
    let history_tmp = history_path.map(|p| written.reserve(p)).transpose()?;
    let records_tmp = match (&args.records_out, args.records) {
        (Some(p), Some(k)) => Some((written.reserve(p)?, k)),
        _ => None,
    };
    let mut files = RunFiles::create(
        &hits_tmp,
        history_tmp.as_deref(),
        records_tmp.as_ref().map(|(p, k)| (p.as_path(), *k)),
    )?;
    let bar = hytrace_trace::progress::bar(photons, "propagating", "photons");
    let BackendRun { run, build_s, gpu } = propagate_on(
        &f,
        surfaces,
        &args.scene,
        &RunOptions {
            origin,
            photons,
            first: args.first,
            seed: args.seed,
            max_steps: args.max_steps,
            keep_histories: history_tmp.is_some(),
            records: args.records.unwrap_or(0),
        },
        args.backend,
        args.batch,
        args.memory,
        &mut |batch| files.append(&batch),
        &|done| bar.set_position(done),
    )?;
    bar.finish_and_clear();
    if let Some(g) = &gpu {
        warn_redone(&g.adapter, &g.times, photons as usize, "photons");
    }
    files.finish()?;
    written.commit()?;
    if args.history.is_some() {
        print!("{}", history_table(&run.counts, args.top));
    }
    if args.stats {
        let mut line = json!({
            "backend": if gpu.is_some() { "gpu" } else { "cpu" },
            "photons": photons,
            "hits": run.hits,
            "load_s": load_s,
            "build_s": build_s,
            "propagate_s": run.propagate_s,
            "tally_s": run.tally_s,
            "write_s": run.write_s,
            "photons_per_s": if run.propagate_s > 0.0 { photons as f64 / run.propagate_s } else { 0.0 },
            "threads": rayon::current_num_threads(),
        });
        if let Some(g) = &gpu {
            add_gpu_stats(&mut line, &g.adapter, &g.features, &g.times);
            line["gpu_host_s"] = g.host.host_s.into();
            line["gpu_batch"] = g.host.batch.into();
            line["gpu_bytes_per_photon"] = BYTES_PER_PHOTON.into();
            if let Some(st) = &g.host.stream {
                line["stream"] = st.json("photons_deferred");
            }
        }
        println!("{line}");
    } else {
        eprintln!(
            "{} photons, {} detected, written to {}",
            photons,
            run.hits,
            out.display()
        );
    }
    Ok(())
}
