//! The reports of `hytrace bench accuracy`: `accuracy.csv`, `accuracy.md` and one
//! error-versus-time plot per component (`accuracy-<component>.svg`) with the Pareto front
//! marked. Every file is written atomically (temporary file, then rename).

use std::fmt::Write as _;
use std::path::Path;

use hytrace_foundry::npy::write_atomically;
use plotters::prelude::*;

use super::{Row, Settings};

/// Rows of one component, in measurement order, with whether each is Pareto-optimal.
struct Group<'a> {
    component: &'static str,
    rows: Vec<&'a Row>,
    pareto: Vec<bool>,
}

/// Whether each row is on the Pareto front: no other row is at least as good in both error
/// and time and strictly better in one.
fn pareto_front(rows: &[&Row]) -> Vec<bool> {
    rows.iter()
        .map(|r| {
            !rows.iter().any(|o| {
                o.error <= r.error
                    && o.ns_per_op <= r.ns_per_op
                    && (o.error < r.error || o.ns_per_op < r.ns_per_op)
            })
        })
        .collect()
}

fn groups(rows: &[Row]) -> Vec<Group<'_>> {
    let mut out: Vec<Group> = Vec::new();
    for row in rows {
        match out.iter_mut().find(|g| g.component == row.component) {
            Some(g) => g.rows.push(row),
            None => out.push(Group {
                component: row.component,
                rows: vec![row],
                pareto: Vec::new(),
            }),
        }
    }
    for g in &mut out {
        g.pareto = pareto_front(&g.rows);
    }
    out
}

/// The file-name form of a component: lower case, words joined by '-'.
pub fn slug(component: &str) -> String {
    component
        .split(|c: char| !c.is_ascii_alphanumeric())
        .filter(|w| !w.is_empty())
        .map(str::to_ascii_lowercase)
        .collect::<Vec<_>>()
        .join("-")
}

/// A CSV field, quoted when it holds a comma or a quote.
fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

fn memory_text(row: &Row) -> String {
    row.memory_bytes.map_or("n/a".into(), |b| b.to_string())
}

fn csv(groups: &[Group]) -> String {
    let mut s =
        String::from("component,variant,metric,reference,error,ns_per_op,memory_bytes,pareto\n");
    for g in groups {
        for (row, &front) in g.rows.iter().zip(&g.pareto) {
            let fields = [
                csv_field(row.component),
                csv_field(&row.variant),
                csv_field(row.metric),
                csv_field(row.reference),
                format!("{:e}", row.error),
                format!("{:.3}", row.ns_per_op),
                memory_text(row),
                front.to_string(),
            ];
            s.push_str(&fields.join(","));
            s.push('\n');
        }
    }
    s
}

/// The machine, build and run the numbers were measured on.
pub fn machine_line(settings: Settings) -> String {
    let cpu = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("model name"))
                .and_then(|l| l.split(':').nth(1))
                .map(|m| m.trim().to_string())
        })
        .unwrap_or_else(|| std::env::consts::ARCH.to_string());
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let profile = if cfg!(debug_assertions) {
        "debug"
    } else {
        "release"
    };
    let run = if settings.quick { "--quick" } else { "full" };
    format!(
        "{cpu}, {cores} logical cores; timed on 1 thread; {profile} build; {run} run; {}",
        utc_date()
    )
}

/// Today's date (UTC), `YYYY-MM-DD`, from the system clock.
pub fn utc_date() -> String {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    // Days since 1970-01-01 to a civil date (the proleptic Gregorian calendar, counted in
    // 400-year eras that start on 1 March).
    let z = (secs / 86_400) as i64 + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    format!("{year:04}-{month:02}-{day:02}")
}

fn markdown(groups: &[Group], settings: Settings) -> String {
    let mut s = String::from("# What accuracy costs in time\n\n");
    let _ = writeln!(
        s,
        "Measured by `hytrace bench accuracy` on: {}.\n",
        machine_line(settings)
    );
    s.push_str(
        "Each table is one knob: error against the stated reference and median time per \
         operation; * marks the Pareto front (no other variant is both as accurate and as \
         fast). Numbers match the plot of the same name.\n",
    );
    for g in groups {
        let first = g.rows[0];
        let _ = write!(
            s,
            "\n## {}\n\nError: {}. Reference: {}. Plot: `accuracy-{}.svg`.\n\n\
             | # | variant | error | ns/op | memory (bytes) | Pareto |\n|---|---|---|---|---|---|\n",
            g.component,
            first.metric,
            first.reference,
            slug(g.component)
        );
        for (i, (row, &front)) in g.rows.iter().zip(&g.pareto).enumerate() {
            let _ = writeln!(
                s,
                "| {} | {} | {:.3e} | {:.1} | {} | {} |",
                i + 1,
                row.variant,
                row.error,
                row.ns_per_op,
                memory_text(row),
                if front { "*" } else { "" }
            );
        }
    }
    s
}

/// One component's plot: error against time per operation, both logarithmic, points
/// numbered as in the Markdown table, the Pareto front joined by a line. Errors of 0 sit
/// on the bottom edge.
fn plot(g: &Group) -> crate::Result<String> {
    let positive = g.rows.iter().map(|r| r.error).filter(|e| *e > 0.0);
    let lo_err = positive.clone().fold(f64::INFINITY, f64::min);
    let hi_err = positive.fold(0.0, f64::max);
    let (lo_err, hi_err) = if lo_err.is_finite() {
        (lo_err / 10.0, hi_err * 10.0)
    } else {
        (1e-12, 1.0)
    };
    let floor = |e: f64| e.max(lo_err);
    let lo_ns = g
        .rows
        .iter()
        .map(|r| r.ns_per_op)
        .fold(f64::INFINITY, f64::min);
    let hi_ns = g.rows.iter().map(|r| r.ns_per_op).fold(0.0, f64::max);
    let (lo_ns, hi_ns) = (lo_ns.max(1e-3) / 2.0, hi_ns.max(1e-3) * 2.0);
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (900, 600)).into_drawing_area();
        let draw = |e: &dyn std::fmt::Display| {
            crate::Error::invalid(format!("plot of {}: {e}", g.component))
        };
        root.fill(&WHITE).map_err(|e| draw(&e))?;
        let mut chart = ChartBuilder::on(&root)
            .caption(
                format!("{} (error vs time, Pareto front in red)", g.component),
                ("sans-serif", 20),
            )
            .margin(15)
            .x_label_area_size(45)
            .y_label_area_size(70)
            .build_cartesian_2d((lo_ns..hi_ns).log_scale(), (lo_err..hi_err).log_scale())
            .map_err(|e| draw(&e))?;
        chart
            .configure_mesh()
            .x_desc("ns per operation")
            .y_desc(g.rows[0].metric)
            .x_label_formatter(&|v| format!("{v:.0}"))
            .y_label_formatter(&|v| format!("{v:.0e}"))
            .draw()
            .map_err(|e| draw(&e))?;
        let mut front: Vec<(f64, f64)> = g
            .rows
            .iter()
            .zip(&g.pareto)
            .filter(|(_, f)| **f)
            .map(|(r, _)| (r.ns_per_op, floor(r.error)))
            .collect();
        front.sort_by(|a, b| a.0.total_cmp(&b.0));
        chart
            .draw_series(LineSeries::new(front, RED.stroke_width(2)))
            .map_err(|e| draw(&e))?;
        for (i, (row, &on_front)) in g.rows.iter().zip(&g.pareto).enumerate() {
            let colour = if on_front { RED } else { BLUE };
            let at = (row.ns_per_op, floor(row.error));
            chart
                .draw_series(std::iter::once(Circle::new(at, 5, colour.filled())))
                .map_err(|e| draw(&e))?;
            chart
                .draw_series(std::iter::once(Text::new(
                    format!("{}", i + 1),
                    at,
                    ("sans-serif", 14).into_font(),
                )))
                .map_err(|e| draw(&e))?;
        }
        root.present().map_err(|e| draw(&e))?;
    }
    Ok(svg)
}

/// Errors when `dir` exists and is not a directory (checked before measuring, so a run
/// that could not write its reports fails at once).
pub fn check_output_dir(dir: &Path) -> crate::Result<()> {
    if dir.exists() && !dir.is_dir() {
        return Err(crate::Error::Invalid(format!(
            "{}: exists and is not a directory",
            dir.display()
        )));
    }
    Ok(())
}

/// Writes `accuracy.csv`, `accuracy.md` and the plots into `dir` (created if missing).
pub fn write_reports(rows: &[Row], settings: Settings, dir: &Path) -> crate::Result<()> {
    check_output_dir(dir)?;
    let groups = groups(rows);
    let write = |name: String, text: String| {
        write_atomically(&dir.join(name), |w| w.write_all(text.as_bytes()))
            .map_err(crate::Error::from)
    };
    for g in &groups {
        write(format!("accuracy-{}.svg", slug(g.component)), plot(g)?)?;
    }
    write("accuracy.md".into(), markdown(&groups, settings))?;
    // The CSV last: its presence means the run completed.
    write("accuracy.csv".into(), csv(&groups))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(error: f64, ns: f64) -> Row {
        Row {
            component: "knob",
            variant: format!("{error} {ns}"),
            metric: "m",
            reference: "r",
            error,
            ns_per_op: ns,
            memory_bytes: None,
        }
    }

    #[test]
    fn pareto_front_keeps_only_undominated_rows() {
        let rows = [
            row(1.0, 10.0),
            row(0.1, 20.0),
            row(1.0, 30.0),
            row(0.1, 20.0),
        ];
        let refs: Vec<&Row> = rows.iter().collect();
        assert_eq!(pareto_front(&refs), [true, true, false, true]);
    }

    #[test]
    fn csv_quotes_commas_and_dates_are_civil() {
        assert_eq!(csv_field("a, b"), "\"a, b\"");
        assert_eq!(csv_field("a,\"b\""), "\"a,\"\"b\"\"\"");
        let d = utc_date();
        assert_eq!(d.len(), 10, "{d}");
        assert_eq!(slug("csg tree form (x)"), "csg-tree-form-x");
    }
}
