"""Two builds of hytrace in alternating pairs on the scans of gpu_rows.py.

Usage: python3 scripts/bench/scan_fallback_pairs.py BASE NEW GDML_DIR RAYS_DIR

BASE and NEW are release builds of the command; RAYS_DIR holds the incoherent rays
`gpu_rows.py` drew (`BENCH_PARTS=scans`, SCALE 0.05: 2x10^5 rays a file, `BENCH_TMP`).
For each scene: `hytrace scan FILE --rays R --stats` on the CPU (f32, every ray) and on the
GPU (`--backend gpu`, the first 5x10^4 rays), BASE then NEW, three times; one JSON line per
scene and backend with both builds' `trace_s`, the ratio of their medians and NEW's
`--stats` (flagged, redone in f64, the fallback's and the GPU's split). Needs NumPy.
"""
import json, os, subprocess, statistics as st, sys
import numpy as np
BASE, NEW, G, RAYS = sys.argv[1], sys.argv[2], sys.argv[3] + "/", sys.argv[4]
BIN = {"base": BASE, "new": NEW}
files = {"default": "default", "protodune": G + "dune/protodune_v7_refactored_nowires.gdml",
         "pfrich": G + "eic-opticks/pfrich_min_FINAL.gdml", "testem3": G + "celeritas/testem3.gdml",
         "cmse": G + "celeritas/cmse.gdml", "8x8SiPM": G + "eic-opticks/8x8SiPM_w_CSI_optial_grease.gdml"}
raysf = {"default": "default", "protodune": "protodune_v7_refactored_nowires", "pfrich": "pfrich_min_FINAL",
         "testem3": "testem3", "cmse": "cmse", "8x8SiPM": "8x8SiPM_w_CSI_optial_grease"}
REPS = 3
def run(b, f, rays, be):
    out = os.path.join(RAYS, "pairs.out.npy")
    p = subprocess.run([BIN[b], "scan", f, "--rays", rays, "--out", out, "--stats", "--backend", be], capture_output=True, text=True)
    return json.loads([l for l in p.stdout.splitlines() if l.startswith("{")][0])
for name, f in files.items():
    full = os.path.join(RAYS, f"{raysf[name]}.rays.npy")
    small = os.path.join(RAYS, f"{raysf[name]}.rays50k.npy")
    np.save(small, np.load(full)[:50000])
    for be, rays in (("cpu", full), ("gpu", small)):
        t = {"base": [], "new": []}; last = {}
        for _ in range(REPS):
            for b in ("base", "new"):
                s = run(b, f, rays, be); t[b].append(s["trace_s"]); last[b] = s
        n = last["new"]
        row = {"scene": name, "backend": be, "rays": n["rays"], "base_trace_s": t["base"], "new_trace_s": t["new"],
               "ratio": st.median(t["new"]) / st.median(t["base"]), "flagged": n.get("flagged"), "redone_in_f64": n["redone_in_f64"],
               "fallback_s": n.get("fallback_s"), "base_redone": last["base"]["redone_in_f64"]}
        for k in ("gpu_upload_s", "gpu_kernel_s", "gpu_readback_s", "gpu_host_s"):
            if k in n: row[k] = n[k]
        print(json.dumps(row), flush=True)
