//! Human-readable and JSON summaries of a Foundry (`hytrace info`).

use hytrace_foundry::{file_names, Foundry, PrimKind};
use serde_json::json;

/// Sizes of the arrays and a line per solid.
pub fn summary(f: &Foundry) -> serde_json::Value {
    let count = |k: PrimKind| f.prim.iter().filter(|p| p.kind == k as u32).count();
    let gpu_bytes: usize = f.gpu_array_bytes().iter().map(|b| b.len()).sum();
    let cpu_only_bytes = f.cpu_only_bytes();
    let solids: Vec<_> = f
        .solid
        .iter()
        .zip(&f.solid_names)
        .enumerate()
        .map(|(i, (s, name))| {
            json!({
                "index": i,
                "name": name,
                "prims": s.num_prim,
                "max_tree_height": s.max_height,
                "instances": f.inst.iter().filter(|x| x.solid as usize == i).count(),
                "aabb": s.aabb,
            })
        })
        .collect();
    json!({
        "solids": f.solid.len(),
        "prims": { "csg": count(PrimKind::Csg), "mesh": count(PrimKind::Mesh), "volume": count(PrimKind::Volume) },
        "nodes": f.node.len(),
        "planes": f.plan.len(),
        "transforms": f.tran.len(),
        "instances": f.inst.len(),
        "triangles": f.tri.len(),
        "bricks": f.brick.len(),
        "gpu_bytes": gpu_bytes,
        "cpu_only_bytes": cpu_only_bytes,
        "materials": f.optics.materials.len(),
        "optical_surfaces": f.optics.surfaces.len(),
        "boundaries": f.optics.boundaries.len(),
        "media": f.optics.media,
        "files": file_names(),
        "solid_list": solids,
        "placements": placements(f),
    })
}

/// Every placement in instance order: the numbering of `hytrace scan --ids`.
fn placements(f: &Foundry) -> Vec<serde_json::Value> {
    f.inst
        .iter()
        .zip(&f.inst_tran)
        .enumerate()
        .map(|(i, (inst, t))| {
            json!({
                "instance": i,
                "solid": inst.solid,
                "solid_name": f.solid_names.get(inst.solid as usize),
                "copy_number": inst.copy_number,
                "position": [t.rows[0][3], t.rows[1][3], t.rows[2][3]],
            })
        })
        .collect()
}

/// A JSON array of numbers as comma-separated text with one decimal.
fn one_decimal(values: &serde_json::Value) -> String {
    let parts: Vec<String> = values
        .as_array()
        .into_iter()
        .flatten()
        .map(|v| format!("{:.1}", v.as_f64().unwrap_or(f64::NAN)))
        .collect();
    parts.join(", ")
}

/// Placements listed in text before the rest are summarized.
const LISTED_PLACEMENTS: usize = 20;

/// The summary as aligned text.
pub fn summary_text(f: &Foundry) -> String {
    let s = summary(f);
    let mut out =
        format!(
        "solids {}  prims {} (csg {}, mesh {}, volume {})  nodes {}  planes {}  transforms {}\n\
         instances {}  triangles {}  bricks {}  GPU bytes {}  CPU-only bytes {}\n\
         materials {}  optical surfaces {}  boundaries {}\n",
        s["solids"], f.prim.len(), s["prims"]["csg"], s["prims"]["mesh"], s["prims"]["volume"],
        s["nodes"], s["planes"], s["transforms"], s["instances"], s["triangles"], s["bricks"],
        s["gpu_bytes"], s["cpu_only_bytes"], s["materials"], s["optical_surfaces"],
        s["boundaries"],
    );
    out.push_str(&format!(
        "{:>5}  {:<20} {:>5} {:>6} {:>9}  bounds (solid frame, mm)\n",
        "index", "solid", "prims", "height", "instances"
    ));
    for row in s["solid_list"].as_array().into_iter().flatten() {
        let b = one_decimal(&row["aabb"]);
        out.push_str(&format!(
            "{:>5}  {:<20} {:>5} {:>6} {:>9}  [{}]\n",
            row["index"].to_string(),
            row["name"].as_str().unwrap_or(""),
            row["prims"].to_string(),
            row["max_tree_height"].to_string(),
            row["instances"].to_string(),
            b
        ));
    }
    out.push_str(&format!(
        "{:>8}  {:<20} {:>6}  position (mm)   [instance numbers are scan --ids values]\n",
        "instance", "solid", "copy"
    ));
    let rows = s["placements"].as_array().cloned().unwrap_or_default();
    for row in rows.iter().take(LISTED_PLACEMENTS) {
        let p = one_decimal(&row["position"]);
        out.push_str(&format!(
            "{:>8}  {:<20} {:>6}  ({})\n",
            row["instance"].to_string(),
            row["solid_name"].as_str().unwrap_or(""),
            row["copy_number"].to_string(),
            p
        ));
    }
    if rows.len() > LISTED_PLACEMENTS {
        out.push_str(&format!(
            "{:>8}  ... {} more (all in `info --json`)\n",
            "",
            rows.len() - LISTED_PLACEMENTS
        ));
    }
    for m in &f.optics.media {
        let grid = m
            .grid
            .as_deref()
            .map_or(String::new(), |g| format!(" grid {g}"));
        out.push_str(&format!(
            "medium of prim {}: {}{grid}, {} bricks, density scale {} per unit length\n",
            m.prim, m.source, m.format, m.density_scale
        ));
    }
    out
}
