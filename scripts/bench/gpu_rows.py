"""The GPU rows of BENCHMARKS.md, each measured beside the CPU on the same machine.

Usage: python3 scripts/bench/gpu_rows.py HYTRACE GDML_DIR OUT_DIR [SCALE]

HYTRACE is a release build of the command, GDML_DIR the shared corpus (../shared/gdml),
SCALE shrinks every size (1: 4e6 rays per scan, 1280x720 renders, 1e6 transmittance rays
and photons; 0.01 runs in a minute on lavapipe). BENCH_PARTS picks the parts
(scans,transmittance,renders,photons,streaming). Each measurement is one JSON line in
OUT_DIR/rows.jsonl (and on stdout): the command's --stats, its wall time, and for every
pair of GPU and CPU outputs the rows that agree bit for bit and the largest difference.
Needs NumPy. On a machine lent through the device tool, see docs/gpu.md.
"""

import json
import os
import subprocess
import sys
import time

import numpy as np

H, GDML, OUT = sys.argv[1], sys.argv[2], sys.argv[3]
SCALE = float(sys.argv[4]) if len(sys.argv) > 4 else 1.0
TMP = os.environ.get("BENCH_TMP", "/dev/shm/hyb")
os.makedirs(TMP, exist_ok=True)
ROWS = open(os.path.join(OUT, "rows.jsonl"), "a")


def run(label, args, timeout=120):
    t0 = time.time()
    try:
        p = subprocess.run([H] + args, capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        row = {"label": label, "error": "timeout", "args": args}
        print(json.dumps(row), flush=True)
        ROWS.write(json.dumps(row) + "\n")
        return None
    wall = time.time() - t0
    stats = None
    for line in p.stdout.splitlines() + p.stderr.splitlines():
        line = line.strip()
        if line.startswith("{"):
            try:
                stats = json.loads(line)
            except ValueError:
                pass
    row = {"label": label, "wall_s": wall, "rc": p.returncode, "stats": stats, "args": args}
    if p.returncode != 0:
        row["stderr"] = p.stderr[-2000:]
    print(json.dumps(row), flush=True)
    ROWS.write(json.dumps(row) + "\n")
    ROWS.flush()
    return stats


def record(row):
    print(json.dumps(row), flush=True)
    ROWS.write(json.dumps(row) + "\n")
    ROWS.flush()


def world_bounds(scene):
    p = subprocess.run([H, "info", scene], capture_output=True, text=True)
    for line in p.stdout.splitlines():
        s = line.split()
        if len(s) > 4 and s[0] == "0" and "[" in line:
            nums = line[line.index("[") + 1 : line.index("]")].split(",")
            return np.array([float(x) for x in nums])
    raise SystemExit(f"no bounds for {scene}: {p.stdout[:500]} {p.stderr[:500]}")


def random_rays(scene, n, seed=1):
    """Incoherent rays: origins uniform in the inner half of the world box, isotropic."""
    b = world_bounds(scene)
    lo, hi = b[:3], b[3:]
    c, h = (lo + hi) / 2, (hi - lo) / 4
    rng = np.random.default_rng(seed)
    o = c + h * rng.uniform(-1, 1, (n, 3))
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    r = np.zeros((n, 8), np.float32)
    r[:, :3], r[:, 4:7], r[:, 7] = o, d, np.inf
    return r


def compare(label, a_path, b_path):
    a, b = np.load(a_path), np.load(b_path)
    same = np.all((a == b) | (np.isnan(a) & np.isnan(b)), axis=1)
    ta, tb = a[:, 3].astype(np.float64), b[:, 3].astype(np.float64)
    fin = np.isfinite(ta) & np.isfinite(tb)
    miss_mismatch = int(np.sum(np.isfinite(ta) != np.isfinite(tb)))
    d = np.abs(ta[fin] - tb[fin])
    record(
        {
            "label": label,
            "rows": int(len(a)),
            "bit_identical_rows": int(same.sum()),
            "hit_miss_disagree": miss_mismatch,
            "max_abs_t_diff": float(d.max()) if d.size else 0.0,
            "rows_t_diff_gt_1e-3": int(np.sum(d > 1e-3)),
        }
    )


def split(label, stats):
    """Where a GPU scan's trace time went: the kernel's pass (uploads, kernel, readback),
    host work per ray (ray records, answers), the f64 fallback, and the rest."""
    if not stats or "gpu_kernel_s" not in stats:
        return
    parts = {
        "upload_s": stats["gpu_upload_s"],
        "kernel_s": stats["gpu_kernel_s"],
        "readback_s": stats["gpu_readback_s"],
        "host_s": stats.get("gpu_host_s", 0.0),
        "fallback_s": stats.get("fallback_s", 0.0),
    }
    parts["rest_s"] = stats["trace_s"] - sum(parts.values())
    rays = max(stats["rays"], 1)
    record(
        {
            "label": label + " split",
            **parts,
            "kernel_timestamps_s": stats.get("gpu_kernel_timestamps_s"),
            "trace_s": stats["trace_s"],
            "flagged_fraction": stats.get("flagged", 0) / rays,
            "redone_fraction": stats["redone_in_f64"] / rays,
        }
    )


def scans():
    files = [
        "default",
        f"{GDML}/dune/protodune_v7_refactored_nowires.gdml",
        f"{GDML}/eic-opticks/pfrich_min_FINAL.gdml",
        f"{GDML}/celeritas/testem3.gdml",
        f"{GDML}/celeritas/cmse.gdml",
        f"{GDML}/eic-opticks/8x8SiPM_w_CSI_optial_grease.gdml",
    ]
    n = int(4_000_000 * SCALE)
    for f in files:
        name = os.path.basename(f).split(".")[0]
        rays = f"{TMP}/{name}.rays.npy"
        if f == "default":
            # the default scene is not a file: rect sweep rays via the command itself
            run("rays " + name, ["scan", f, "--sweep", "rect", "--count", "10", "--out", f"{TMP}/x.npy"])
            np.save(rays, random_rays_default(n))
        else:
            np.save(rays, random_rays(f, n))
        outs = {}
        for be in ["cpu", "gpu"]:
            out = f"{TMP}/{name}.{be}.npy"
            label = f"scan {name} incoherent {be}"
            split(label, run(label, ["scan", f, "--rays", rays, "--out", out, "--stats", "--backend", be]))
            outs[be] = out
        compare(f"scan {name} gpu vs cpu", outs["cpu"], outs["gpu"])
        count = str(int(2000 * SCALE**0.5))
        for be in ["cpu", "gpu"]:
            label = f"scan {name} rect {be}"
            split(label, run(label, ["scan", f, "--sweep", "rect", "--count", count, "--out", f"{TMP}/r.{be}.npy", "--stats", "--backend", be]))
        compare(f"scan {name} rect gpu vs cpu", f"{TMP}/r.cpu.npy", f"{TMP}/r.gpu.npy")


def random_rays_default(n, seed=1):
    rng = np.random.default_rng(seed)
    o = rng.uniform(-2, 2, (n, 3))
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    r = np.zeros((n, 8), np.float32)
    r[:, :3], r[:, 4:7], r[:, 7] = o, d, np.inf
    return r


def renders():
    size = "1280x720" if SCALE >= 1 else "160x90"
    scenes = ["default", "scenes/render/fog-single.toml", "scenes/render/gdml.toml", "scenes/render/glass.toml"]
    for s in scenes:
        for be, spp in [("gpu", 64), ("cpu", 16), ("gpu", 16)]:
            name = os.path.basename(s)
            run(f"render {name} {be} spp{spp}", ["render", s, "--size", size, "--spp", str(spp), "--backend", be, "--stats", "-o", f"{TMP}/{name}.{be}.{spp}.png"], timeout=90)


def transmittance():
    n = int(1_000_000 * SCALE)
    grid = "sphere:100,0.5,5"
    rng = np.random.default_rng(2)
    a = rng.normal(size=(n, 3))
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    b = rng.normal(size=(n, 3))
    b /= np.linalg.norm(b, axis=1, keepdims=True)
    o = 130 * a
    e = 130 * b
    d = e - o
    ln = np.linalg.norm(d, axis=1, keepdims=True)
    r = np.zeros((n, 8), np.float32)
    r[:, :3], r[:, 4:7], r[:, 7] = o, d / ln, ln[:, 0]
    rays = f"{TMP}/tr.rays.npy"
    np.save(rays, r)
    for est in ["exact", "ratio"]:
        for repr_ in ["nanovdb", "unorm16"]:
            outs = {}
            for be in ["cpu", "gpu"]:
                out = f"{TMP}/tr.{est}.{repr_}.{be}.npy"
                run(f"transmittance {est} {repr_} {be}", ["volume", "transmittance", grid, "--rays", rays, "--out", out, "--estimator", est, "--repr", repr_, "--backend", be, "--stats"], timeout=90)
                outs[be] = out
            try:
                x, y = np.load(outs["cpu"]), np.load(outs["gpu"])
                record({"label": f"transmittance {est} {repr_} gpu vs cpu", "rows": int(len(x)), "identical": int(np.sum(x == y)), "max_abs_diff": float(np.max(np.abs(x - y)))})
            except Exception as e:  # noqa: BLE001 - a failed run is reported above
                record({"label": f"transmittance {est} {repr_} compare", "error": str(e)})


PHOTON_PHASES = ["gpu_upload_s", "gpu_kernel_s", "gpu_readback_s", "gpu_host_s", "tally_s", "write_s"]


def photon_split(label, stats):
    """Where a GPU photon run's time went: each phase of --stats, what is left of
    propagate_s, the kernel's own rate (timestamps where the device has them) and the GPU
    memory the batch held."""
    if not stats or stats.get("backend") != "gpu":
        return
    row = {"label": f"{label} split", "propagate_s": stats["propagate_s"]}
    for k in PHOTON_PHASES:
        row[k] = stats.get(k)
    row["rest_s"] = stats["propagate_s"] - sum(stats.get(k) or 0.0 for k in PHOTON_PHASES)
    kernel = stats.get("gpu_kernel_timestamps_s") or stats.get("gpu_kernel_s")
    row["kernel_photons_per_s"] = stats["photons"] / kernel if kernel else None
    row["end_to_end_photons_per_s"] = stats["photons_per_s"]
    if "gpu_batch" in stats:
        row["gpu_batch_bytes"] = stats["gpu_batch"] * stats["gpu_bytes_per_photon"]
    record(row)


def photons():
    """Photons/s of the GPU kernel beside the CPU propagator on the same photons, the
    fraction of photons whose histories agree (the kernel is f32, the CPU f64), and where
    each GPU run's time went."""
    n = str(int(1_000_000 * SCALE))
    for name, f, src in [
        ("sipm", f"{GDML}/eic-opticks/8x8SiPM_w_CSI_optial_grease.gdml", "point:0.1,0.1,4"),
        ("raindrop", f"{GDML}/eic-opticks/opticks_raindrop.gdml", "point:0,0,70"),
        ("every_process", "tests/data/photons/every_process.gdml", "point:0,0,0"),
        # Rough surfaces (the kernel's rough_surfaces feature): unified ground glass.
        ("rough_surfaces", "tests/data/photons/rough_surfaces.gdml", "beam:-265,0,50:0.5,0,-1:5"),
    ]:
        histories = {}
        for be in ["cpu", "gpu"]:
            h = f"{TMP}/ph.{name}.{be}.history.npy"
            args = ["photons", f, "--source", src, "-n", n, "-o", f"{TMP}/ph.{be}.npy", f"--history={h}", "--top", "0", "--backend", be, "--stats"]
            stats = run(f"photons {name} {be}", args, timeout=300)
            if stats is not None:
                histories[be] = h
                photon_split(f"photons {name} {be}", stats)
        if len(histories) == 2:
            a, b = np.load(histories["cpu"]), np.load(histories["gpu"])
            record({"label": f"photons {name} gpu vs cpu", "photons": int(len(a)), "same_history": int(np.sum(a == b))})
        if SCALE >= 1:
            # Ten times as many on the GPU alone: the rate once the device is full.
            big = str(int(10_000_000 * SCALE))
            stats = run(f"photons {name} gpu 1e7", ["photons", f, "--source", src, "-n", big, "-o", f"{TMP}/ph.big.npy", "--backend", "gpu", "--stats"], timeout=120)
            photon_split(f"photons {name} gpu 1e7", stats)


CORAL_SCENE = """[volumes.coral]
source = "{store}"
density_scale = {density}
emission = [2e-5, 1.3e-5, 0.6e-5]

[camera]
eye = [42, -30, 34]
target = [10.24, 10.24, 9]
fov = 32

[[lights]]
kind = "environment"
radiance = [0.02, 0.02, 0.03]

[render]
volumes = "emission-absorption"
spp = 1
"""


def streaming():
    """A coral-like brick store (BENCH_CORAL_SIDE^3 voxels, 1024 by default at SCALE 1) rendered on the GPU streamed through a
    64 MiB brick pool and with a pool holding it whole, and on the CPU through a 64 MiB
    cache: times, bricks uploaded and deferred pixels; the two GPU images bit for bit."""
    side = int(os.environ.get("BENCH_CORAL_SIDE", "1024" if SCALE >= 1 else "128"))
    raw, store = f"{TMP}/coral{side}.raw", f"{TMP}/coral{side}.bricks"
    if not os.path.exists(store):
        here = os.path.dirname(os.path.abspath(__file__))
        subprocess.run([sys.executable, os.path.join(here, "make_coral_volume.py"), raw,
                        "--dims", f"{side},{side},{side}"], check=True)
        spacing = 20.48 / side
        run(f"convert coral{side}", ["volume", "convert", raw, "--store", "--dims", f"{side},{side},{side}",
                                     "--dtype", "u16", "--spacing", f"{spacing},{spacing},{spacing}",
                                     "--memory", "2G", "-o", store], timeout=600)
        os.remove(raw)
    scene = f"{TMP}/coral{side}.toml"
    with open(scene, "w") as f:
        f.write(CORAL_SCENE.format(store=store, density=3e-5 * side / 1024))
    size = "1280x720" if SCALE >= 1 else "160x90"
    outs = {}
    for be, memory in [("gpu", "64M"), ("gpu", "4G"), ("cpu", "64M")]:
        out = f"{TMP}/coral.{be}.{memory}.npy"
        run(f"render coral{side} {be} --memory {memory}", ["render", scene, "--size", size, "--step", "1",
            "--memory", memory, "--backend", be, "--stats", "-o", out], timeout=300)
        outs[(be, memory)] = out
    for a, b in [(("gpu", "64M"), ("gpu", "4G")), (("gpu", "64M"), ("cpu", "64M"))]:
        try:
            x, y = np.load(outs[a]), np.load(outs[b])
            record({"label": f"coral render {a} vs {b}", "values": int(x.size),
                    "identical": int(np.sum(x == y)), "max_abs_diff": float(np.max(np.abs(x - y)))})
        except Exception as e:  # noqa: BLE001 - a failed run is reported above
            record({"label": f"coral render {a} vs {b}", "error": str(e)})


if __name__ == "__main__":
    which = os.environ.get("BENCH_PARTS", "scans,transmittance,renders,photons,streaming").split(",")
    for part in which:
        t0 = time.time()
        globals()[part]()
        record({"label": f"part {part} done", "wall_s": time.time() - t0})
