"""Which of the GPU's and the CPU's f32 scans is nearer the f64 scan of the same rays.

Usage: python3 scripts/bench/scan_precisions.py HYTRACE GDML_DIR OUT_DIR

For the default scene and three corpus files: 10^6 rays as gpu_rows.py draws them, scanned
in f64 on the CPU, in f32 on the CPU and on the GPU; one JSON line per comparison in
OUT_DIR/rows.jsonl (rows bit for bit equal, largest difference in t, rows differing by more
than 1e-3 mm). Needs NumPy and a GPU.
"""
import os, sys
H, GDML, OUT = sys.argv[1], sys.argv[2], sys.argv[3]
sys.argv = [sys.argv[0], H, GDML, OUT, "1"]
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import numpy as np
import gpu_rows as g

for f in ["default", f"{GDML}/celeritas/cmse.gdml", f"{GDML}/dune/protodune_v7_refactored_nowires.gdml", f"{GDML}/celeritas/testem3.gdml"]:
    name = os.path.basename(f).split(".")[0]
    rays = f"{g.TMP}/d.{name}.rays.npy"
    np.save(rays, g.random_rays_default(1_000_000) if f == "default" else g.random_rays(f, 1_000_000))
    outs = {}
    for label, extra in [("f64", ["--precision", "f64"]), ("cpu", []), ("gpu", ["--backend", "gpu"])]:
        out = f"{g.TMP}/d.{name}.{label}.npy"
        g.run(f"diag {name} {label}", ["scan", f, "--rays", rays, "--out", out, "--stats"] + extra, timeout=120)
        outs[label] = out
    g.compare(f"diag {name} cpu f32 vs f64", outs["f64"], outs["cpu"])
    g.compare(f"diag {name} gpu vs f64", outs["f64"], outs["gpu"])
    g.compare(f"diag {name} gpu vs cpu f32", outs["cpu"], outs["gpu"])
