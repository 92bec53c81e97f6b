//! Progress bars of long commands, drawn on stderr when it is a terminal (indicatif hides
//! them otherwise, so piped and CI output stays clean).

use indicatif::{ProgressBar, ProgressStyle};

/// A bar of `len` steps counted in `unit` (rows, rays, photons, percent), labelled
/// `message`.
pub fn bar(len: u64, message: &'static str, unit: &str) -> ProgressBar {
    let template = format!("{{msg}} [{{bar:40}}] {{pos}}/{{len}} {unit}, {{eta}} left");
    let style = ProgressStyle::with_template(&template)
        .unwrap_or_else(|_| ProgressStyle::default_bar())
        .progress_chars("=> ");
    let bar = ProgressBar::new(len).with_style(style);
    bar.set_message(message);
    bar
}
