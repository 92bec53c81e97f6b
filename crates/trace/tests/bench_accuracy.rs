//! `hytrace bench accuracy --quick` end to end: every row filled, the reports written, and
//! the harness itself judged: deliberately worse variants must measure worse than their
//! better twins.

use std::collections::HashMap;
use std::path::Path;
use std::process::Command;

use hytrace_trace::accuracy::slug;

/// One CSV record, honouring double-quoted fields.
fn split_csv(line: &str) -> Vec<String> {
    let (mut fields, mut field, mut quoted) = (Vec::new(), String::new(), false);
    let mut chars = line.chars().peekable();
    while let Some(c) = chars.next() {
        match (c, quoted) {
            ('"', true) if chars.peek() == Some(&'"') => {
                field.push('"');
                chars.next();
            }
            ('"', _) => quoted = !quoted,
            (',', false) => fields.push(std::mem::take(&mut field)),
            _ => field.push(c),
        }
    }
    fields.push(field);
    fields
}

struct Measured {
    error: f64,
    ns: f64,
}

fn run_quick(dir: &Path) -> HashMap<(String, String), Measured> {
    let out = Command::new(env!("CARGO_BIN_EXE_hytrace"))
        .args(["bench", "accuracy", "--quick", "-o"])
        .arg(dir)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "bench accuracy failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let csv = std::fs::read_to_string(dir.join("accuracy.csv")).unwrap();
    let mut lines = csv.lines();
    let header = split_csv(lines.next().unwrap());
    assert_eq!(
        header,
        [
            "component",
            "variant",
            "metric",
            "reference",
            "error",
            "ns_per_op",
            "memory_bytes",
            "pareto"
        ]
    );
    let mut rows = HashMap::new();
    for line in lines {
        let f = split_csv(line);
        assert_eq!(f.len(), header.len(), "row `{line}`");
        assert!(f.iter().all(|x| !x.is_empty()), "empty field in `{line}`");
        let error: f64 = f[4].parse().unwrap();
        let ns: f64 = f[5].parse().unwrap();
        assert!(error.is_finite() && error >= 0.0, "error of `{line}`");
        assert!(ns.is_finite() && ns > 0.0, "time of `{line}`");
        assert!(
            f[6] == "n/a" || f[6].parse::<u64>().is_ok(),
            "memory of `{line}`"
        );
        assert!(f[7] == "true" || f[7] == "false", "pareto of `{line}`");
        rows.insert((f[0].clone(), f[1].clone()), Measured { error, ns });
    }
    rows
}

fn get<'a>(rows: &'a HashMap<(String, String), Measured>, c: &str, v: &str) -> &'a Measured {
    rows.iter()
        .find(|((rc, rv), _)| rc == c && rv.starts_with(v))
        .map(|(_, m)| m)
        .unwrap_or_else(|| panic!("no row `{c}` / `{v}*`"))
}

#[test]
fn quick_run_fills_every_row_and_ranks_worse_variants_worse() {
    let dir = tempfile::tempdir().unwrap();
    let rows = run_quick(dir.path());
    let err = |c: &str, v: &str| get(&rows, c, v).error;
    // Far from the origin, f32 without the closest-approach shift is far worse than with
    // it, and f32 is worse than f64.
    let km = "csg sphere, rays from 1 km";
    assert!(err(km, "f32, strategy off") > 100.0 * err(km, "f32, strategy on"));
    assert!(err(km, "f32, strategy on") > err(km, "f64, strategy on"));
    assert!(err("csg sphere, rays from 20 m", "f32, strategy on") < 0.01);
    // Whole scans beside solids far out: world-rounded origins are wrong on more rays
    // the farther out; two-part origins are not, but f32 still misjudges starts on a
    // surface and grazing rays; the f64 fallback gives the exact answers, as f64 does.
    for far in ["20 m", "100 m", "1 km"] {
        let c = format!("csg scan, solids {far} out");
        let rounded = err(&c, "f32, origins rounded");
        let rebased = err(&c, "f32, two-part origins");
        assert!(rounded > rebased, "{c}: {rounded} vs {rebased}");
        assert!(
            rebased > 0.01,
            "{c}: the hard rays are no longer hard ({rebased})"
        );
        assert_eq!(err(&c, "f32, rebased, f64 fallback"), 0.0, "{c}");
        assert_eq!(err(&c, "f64"), 0.0, "{c}");
    }
    // Lists and binary trees have the same surfaces.
    let tree = "csg tree form";
    assert_eq!(
        err(tree, "f64, union of 24 spheres as a list node"),
        err(tree, "f64, union of 24 spheres as a binary tree")
    );
    assert!(err(tree, "f64, union") < 1e-9);
    // The watertight test never lets a ray through an edge or vertex.
    assert!(err("triangle test", "watertight, f32") < 1e-3);
    assert!(err("triangle test", "watertight, f64") < 1e-9);
    // Coarser texels, coarser steps and nearest lookups are less accurate.
    let texel = "volume texel format";
    assert!(err(texel, "bricked unorm8") > err(texel, "bricked unorm16"));
    assert!(err(texel, "nanovdb fp4") > err(texel, "nanovdb fp16"));
    let est = "transmittance estimator";
    assert!(err(est, "march, step 2 voxel") > err(est, "march, step 0.25 voxel"));
    assert!(err(est, "exact") < 1e-9);
    assert!(err("volume filter", "nearest") > err("volume filter", "trilinear"));
    // Global majorants cost more density lookups than local ones.
    assert!(err("majorant", "global") > err("majorant", "local, 8^3"));
    // The GPU row exists wherever GPU tests are required (lavapipe in CI), and agrees with
    // the CPU's f32 tracer to f32 rounding.
    if std::env::var("HYTRACE_REQUIRE_GPU").as_deref() == Ok("1") {
        let gpu = get(&rows, "gpu vs cpu scan", "GPU f32 on");
        assert!(gpu.error < 1e-5, "GPU error {}", gpu.error);
        assert!(gpu.ns > 0.0);
        // The GPU's exact transmittance is the CPU's to f32 rounding, and its ratio
        // tracking draws the same samples, so both errors match the CPU's.
        let t = "gpu vs cpu transmittance";
        assert!(err(t, "exact, GPU f32") < 1e-5);
        let (cpu, gpu) = (err(t, "ratio, 4 spp, CPU"), err(t, "ratio, 4 spp, GPU"));
        assert!(
            (cpu - gpu).abs() < 1e-3 * cpu,
            "ratio: CPU {cpu}, GPU {gpu}"
        );
    }
    // One plot per component, and the Markdown table.
    let components: std::collections::HashSet<&String> = rows.keys().map(|k| &k.0).collect();
    for c in components {
        let name = format!("accuracy-{}.svg", slug(c));
        let svg = std::fs::read_to_string(dir.path().join(name))
            .unwrap_or_else(|e| panic!("plot of `{c}`: {e}"));
        assert!(
            svg.starts_with("<svg") && svg.contains("</svg>"),
            "plot of `{c}`"
        );
    }
    let md = std::fs::read_to_string(dir.path().join("accuracy.md")).unwrap();
    assert!(md.contains("timed on 1 thread") && md.contains("## csg tree form"));
}

#[test]
fn an_output_path_that_is_a_file_is_an_error_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("taken");
    std::fs::write(&file, "x").unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_hytrace"))
        .args(["bench", "accuracy", "--quick", "-o"])
        .arg(&file)
        .output()
        .unwrap();
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("taken") && stderr.contains("not a directory"),
        "{stderr}"
    );
    assert_eq!(std::fs::read_to_string(&file).unwrap(), "x");
}
