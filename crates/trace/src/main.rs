//! The `hytrace` command-line tool: parses the command line ([`cli`]), runs it and reports
//! errors.

mod cli;

use std::process::ExitCode;

use clap::Parser;

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
    match cli::run(cli::Cli::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!(
                "hytrace: error: {}",
                hytrace_trace::error::report(e.as_ref())
            );
            ExitCode::FAILURE
        }
    }
}
