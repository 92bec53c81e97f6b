"""Two builds of hytrace in alternating pairs on f32 scans of mesh scenes (issue 30's mesh
fallback: its cost in time and the share of rays it traces again in f64).

Usage: python3 scripts/bench/mesh_scan_pairs.py BASE NEW MESH_DIR OUT_DIR [PAIRS]

BASE and NEW are release builds of the command. MESH_DIR holds the meshes of
`tests/oracle/mesh_oracle.py` (run it with the .venv's Python: lumpy.glb, torus.glb,
icosphere.glb); a 1M-triangle heightfield OBJ (the mesh bench's size, 2 x 708^2 triangles,
smooth random heights) is written to OUT_DIR. Rays (2x10^5 per scene, seeded): incoherent
ones from a sphere around each mesh's bounds, aimed at random points of the bounds; for the
heightfield, random origins above it with uniform downward directions. For each scene:
`hytrace scan FILE --rays R --out O --stats` (CPU, f32: the default), BASE then NEW, PAIRS
times (default 5); one JSON line per scene with both builds' `trace_s`, the median of the
per-pair ratios NEW / BASE and NEW's `--stats` (flagged, redone in f64, the fallback's
seconds). Needs NumPy and trimesh (the .venv).
"""
import json, os, subprocess, statistics as st, sys
import numpy as np
import trimesh

BASE, NEW, MESHES, OUT = sys.argv[1:5]
PAIRS = int(sys.argv[5]) if len(sys.argv) > 5 else 5
N = 200_000
os.makedirs(OUT, exist_ok=True)
rng = np.random.default_rng(20261128)


def unit(v):
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def heightfield(path, side=708):
    x, y = np.meshgrid(np.linspace(0, 100, side + 1), np.linspace(0, 100, side + 1))
    z = 3 * np.sin(x / 7) * np.cos(y / 5) + rng.normal(scale=0.2, size=x.shape)
    v = np.stack([x, y, z], axis=-1).reshape(-1, 3)
    i = np.arange(side)[:, None] * (side + 1) + np.arange(side)[None, :]
    a, b, c, d = i, i + 1, i + side + 1, i + side + 2
    faces = np.concatenate([np.stack([a, b, d], -1).reshape(-1, 3), np.stack([a, d, c], -1).reshape(-1, 3)])
    trimesh.Trimesh(v, faces, process=False).export(path)
    o = np.column_stack([rng.uniform(0, 100, N), rng.uniform(0, 100, N), np.full(N, 20.0)])
    d = unit(rng.normal(size=(N, 3)))
    d[:, 2] = -np.abs(d[:, 2])
    return o, d


def around(path):
    lo, hi = trimesh.load(path, force="mesh").bounds
    c, r = (lo + hi) / 2, np.linalg.norm(hi - lo)
    o = c + r * unit(rng.normal(size=(N, 3)))
    target = lo + (hi - lo) * rng.uniform(size=(N, 3))
    return o, unit(target - o)


def rays_file(name, o, d):
    rows = np.column_stack([o, np.zeros(N), d, np.full(N, np.inf)])
    path = os.path.join(OUT, f"{name}.rays.npy")
    np.save(path, rows)
    return path


scenes = {}
for name in ("lumpy", "torus", "icosphere"):
    f = os.path.join(MESHES, f"{name}.glb")
    scenes[name] = (f, rays_file(name, *around(f)))
hf = os.path.join(OUT, "heightfield1m.obj")
scenes["heightfield1m"] = (hf, rays_file("heightfield1m", *heightfield(hf)))


def run(binary, scene, rays):
    out = os.path.join(OUT, "pairs.out.npy")
    p = subprocess.run([binary, "scan", scene, "--rays", rays, "--out", out, "--stats"],
                       capture_output=True, text=True, check=True)
    return json.loads([l for l in p.stdout.splitlines() if l.startswith("{")][0])


for name, (scene, rays) in scenes.items():
    t = {"base": [], "new": []}
    for _ in range(PAIRS):
        for b, binary in (("base", BASE), ("new", NEW)):
            s = run(binary, scene, rays)
            t[b].append(s["trace_s"])
            last = s
    ratios = [n / b for n, b in zip(t["new"], t["base"])]
    print(json.dumps({"scene": name, "rays": N, "base_trace_s": t["base"], "new_trace_s": t["new"],
                      "ratio_median": st.median(ratios), "flagged": last.get("flagged"),
                      "redone_in_f64": last.get("redone_in_f64"), "fallback_s": last.get("fallback_s")}),
          flush=True)
