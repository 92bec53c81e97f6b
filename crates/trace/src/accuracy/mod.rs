//! `hytrace bench accuracy`: error against an independent high-precision reference and time
//! per operation for every accuracy knob of the toolkit (CSG, triangles, volumes, GPU), written as CSV, a Markdown table
//! and error-versus-time plots with the Pareto front marked.
//!
//! Each component module measures its own rows; this module times, collects and reports.

mod csg;
mod dd;
mod far_scan;
mod gpu;
mod report;
mod timing;
mod triangles;
mod volume;

use std::path::Path;

pub use report::{check_output_dir, machine_line, slug, utc_date, write_reports};
pub use timing::Timer;

/// One measured variant of one knob.
#[derive(Clone, Debug, PartialEq)]
pub struct Row {
    /// The knob measured; rows of one component share an error metric and one plot.
    pub component: &'static str,
    /// The setting measured, e.g. `f32, 1 km offset, origin subtracted`.
    pub variant: String,
    /// What `error` measures, e.g. `max |t - t_ref| (mm)`.
    pub metric: &'static str,
    /// The reference the error is measured against, computed independently of the variant.
    pub reference: &'static str,
    /// The error, in the metric's unit; finite and `>= 0`.
    pub error: f64,
    /// Median time per operation (what an operation is: see `metric`'s component notes).
    pub ns_per_op: f64,
    /// Memory the variant needs, where it differs between variants.
    pub memory_bytes: Option<u64>,
}

/// How much work each measurement does.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Settings {
    /// Small inputs and few repeats, for CI (the whole run in well under a minute).
    pub quick: bool,
}

impl Settings {
    /// `full` work items normally, `quick` ones with `--quick`.
    pub fn size(&self, full: usize, quick: usize) -> usize {
        if self.quick {
            quick
        } else {
            full
        }
    }
}

/// Measures every component's rows, in a fixed order.
pub fn measure(settings: Settings) -> crate::Result<Vec<Row>> {
    type Measure = fn(Settings) -> crate::Result<Vec<Row>>;
    let components: [(&str, Measure); 5] = [
        ("CSG", csg::rows),
        ("CSG scans far from the origin", far_scan::rows),
        ("triangles", triangles::rows),
        ("volumes", volume::rows),
        ("GPU", gpu::rows),
    ];
    let mut rows = Vec::new();
    for (name, measure) in components {
        eprintln!("measuring {name}...");
        rows.extend(measure(settings)?);
    }
    for row in &rows {
        if !(row.error.is_finite() && row.error >= 0.0 && row.ns_per_op.is_finite()) {
            return Err(crate::Error::Invalid(format!(
                "{} / {}: error {} and time {} ns must be finite",
                row.component, row.variant, row.error, row.ns_per_op
            )));
        }
    }
    Ok(rows)
}

/// Measures every row and writes the reports into `dir` (see [`write_reports`]).
pub fn run(settings: Settings, dir: &Path) -> crate::Result<Vec<Row>> {
    check_output_dir(dir)?;
    let rows = measure(settings)?;
    write_reports(&rows, settings, dir)?;
    Ok(rows)
}
