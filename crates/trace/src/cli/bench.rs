//! `hytrace bench`: measurements that write reports.

use std::path::PathBuf;

use clap::Subcommand;
use hytrace_trace::accuracy;

/// The subcommands of `hytrace bench`.
#[derive(Subcommand)]
pub enum BenchCommand {
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

/// Runs `hytrace bench COMMAND`.
pub fn run(command: BenchCommand) -> anyhow::Result<()> {
    match command {
        BenchCommand::Accuracy { out, quick } => {
            let settings = accuracy::Settings { quick };
            eprintln!("measuring on {}", accuracy::machine_line(settings));
            let rows = accuracy::run(settings, &out)?;
            eprintln!(
                "{} rows; wrote {}/accuracy.csv, accuracy.md and the plots",
                rows.len(),
                out.display()
            );
        }
    }
    Ok(())
}
