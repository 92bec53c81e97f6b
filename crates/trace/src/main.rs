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
            eprintln!("hytrace: error: {}", message(&e));
            ExitCode::FAILURE
        }
    }
}

/// The message of an error followed by its causes, each cause left out when the message so
/// far already ends with it (the library's errors spell out their causes).
fn message(e: &anyhow::Error) -> String {
    let mut text = String::new();
    for cause in e.chain().map(ToString::to_string) {
        if text.is_empty() {
            text = cause;
        } else if !text.ends_with(&cause) {
            text = format!("{text}: {cause}");
        }
    }
    text
}
