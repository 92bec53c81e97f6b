//! `hytrace volume`: info, sample, transmittance and convert on NanoVDB, OpenVDB,
//! procedural grids and brick stores.

use std::path::PathBuf;

use clap::Subcommand;
use hytrace_trace::gpu::TexelStore;
use hytrace_trace::scan;
use hytrace_trace::volume::{self, FilterArg, Repr, Space};
use hytrace_volume::TexelFormat;

use super::choice::choice;
use super::options::{EstimatorArgs, StoreArgs};

/// The subcommands of `hytrace volume`.
#[derive(Subcommand)]
pub enum VolumeCommand {
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
        #[arg(long, value_parser = choice::<Space>(), default_value_t = Space::World)]
        space: Space,
        /// Lookup filter.
        #[arg(long, value_parser = choice::<FilterArg>(), default_value_t = FilterArg::Trilinear)]
        filter: FilterArg,
        /// Representation looked up [default: the file's own, read with no conversion:
        /// nanovdb for a .nvdb file, source for a .vdb file, a procedural grid or a brick
        /// store].
        #[arg(long, value_parser = choice::<Repr>())]
        repr: Option<Repr>,
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
        /// A .nvdb or .vdb file, a brick store directory, or a procedural grid.
        file: String,
        /// Rays, (N, 8) float32 or float64.
        #[arg(long)]
        rays: PathBuf,
        /// Transmittances, (N,) float64.
        #[arg(long)]
        out: PathBuf,
        /// Representation traced [default: the file's own, read with no conversion:
        /// nanovdb for a .nvdb file, source for a .vdb file, a procedural grid or a brick
        /// store].
        #[arg(long, value_parser = choice::<Repr>())]
        repr: Option<Repr>,
        #[command(flatten)]
        estimate: EstimatorArgs,
        /// Grid name (default: the first grid).
        #[arg(long)]
        grid: Option<String>,
        /// Where to trace: the CPU (f64), the GPU (f32: bricked grids, or with `--repr
        /// nanovdb` a NanoVDB file's raw buffer; other grids are converted to f32 bricks; a
        /// brick store streams through a brick pool of --memory bytes) or the GPU when one
        /// opens, else the CPU.
        #[arg(long, value_parser = choice::<volume::VolumeBackend>(), default_value_t = volume::VolumeBackend::Cpu)]
        backend: volume::VolumeBackend,
        /// Where the GPU reads a bricked grid's texels from: a storage buffer, decoded as on
        /// the CPU, or a 3D texture (BC4 then decoded by the device).
        #[arg(long, value_parser = choice::<TexelStore>(), default_value_t = TexelStore::Storage)]
        gpu_texels: TexelStore,
        /// Print one JSON line of counts and timings.
        #[arg(long)]
        stats: bool,
        /// Memory a brick store may hold resident (its tables and brick cache), e.g. 4G; on
        /// the GPU also the device memory of its brick pool, page table and request buffer.
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
        store_options: StoreArgs,
    },
}

/// Runs `hytrace volume COMMAND`.
pub fn run(command: VolumeCommand) -> anyhow::Result<()> {
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
            let run = volume::transmittances_on(
                &g,
                &rays,
                &volume::EstimatorOptions::from(estimate).args(),
                backend,
                gpu_texels,
                memory,
            )?;
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
                let r = volume::convert_store(&file, grid.as_deref(), &out, &store_options.into())?;
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
