"""Embree side of the triangle-mesh benchmark (tests/benches/mesh.rs), run in the .venv
oracle environment.

Usage: mesh_bench.py DIR

Reads DIR/vertices.npy (V, 3) float32, DIR/faces.npy (F, 3) int32 and, for SET in
coherent and incoherent, DIR/SET_origins.npy and DIR/SET_dirs.npy (N, 3) float32. For each
Embree configuration it builds the scene (geometry upload and BVH build, timed: embreex
commits the scene on the first query, so a one-ray query is part of the build), traces
every set with `EmbreeScene.run(origins, dirs, output=1)` (best of three, only that call
timed), writes DIR/TAG_SET_t.npy (N,) float32 (inf on a miss) and prints one line
`label|build_s|coherent_s|incoherent_s|TAG`.

embreex's `run` calls `rtcIntersect1` ray by ray on the calling thread (Embree's own
threads only build the BVH), so the first configurations use one thread; the
`2 threads` ones split each set in two halves traced by two Python threads at once, which
runs in parallel only as far as `run` releases the GIL; the printed ratio of process CPU
time to wall time says how many cores were busy.
"""

import os
import sys
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from embreex import rtcore_scene as rtcs
from embreex.mesh_construction import TriangleMesh

SETS = ["coherent", "incoherent"]
RUNS = 3


def build(vertices, faces, robust):
    start = time.perf_counter()
    scene = rtcs.EmbreeScene(robust=robust)
    TriangleMesh(scene, vertices, faces)
    scene.run(np.zeros((1, 3), np.float32), np.ones((1, 3), np.float32), output=1)
    return scene, time.perf_counter() - start


def trace(scene, origins, dirs, threads):
    """First-hit distances of all rays, and the best wall time and CPU/wall ratio."""
    best, ratio, t = np.inf, 0.0, None
    chunks = np.array_split(np.arange(len(origins)), threads)
    for _ in range(RUNS):
        wall, cpu = time.perf_counter(), time.process_time()
        if threads == 1:
            results = [scene.run(origins, dirs, output=1)]
        else:
            with ThreadPoolExecutor(threads) as pool:
                results = list(
                    pool.map(lambda c: scene.run(origins[c], dirs[c], output=1), chunks)
                )
        wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
        if wall < best:
            best, ratio = wall, cpu / wall
        t = np.concatenate([r["tfar"] for r in results]).astype(np.float32)
        geom = np.concatenate([r["geomID"] for r in results])
        t[geom == -1] = np.inf
    return t, best, ratio


def main(out):
    vertices = np.load(os.path.join(out, "vertices.npy")).astype(np.float32)
    faces = np.load(os.path.join(out, "faces.npy")).astype(np.int32)
    rays = {
        s: (
            np.ascontiguousarray(np.load(os.path.join(out, f"{s}_origins.npy")), np.float32),
            np.ascontiguousarray(np.load(os.path.join(out, f"{s}_dirs.npy")), np.float32),
        )
        for s in SETS
    }
    for robust in [False, True]:
        scene, build_s = build(vertices, faces, robust)
        mode = "robust" if robust else "default"
        for threads in [1, 2]:
            tag = f"embree_{mode}_{threads}"
            seconds, ratios = [], []
            for s in SETS:
                t, wall, ratio = trace(scene, *rays[s], threads)
                np.save(os.path.join(out, f"{tag}_{s}_t.npy"), t)
                seconds.append(wall)
                ratios.append(ratio)
            busy = max(ratios)
            label = (
                f"Embree 4 (embreex, {mode} mode, {threads} Python thread"
                f"{'s' if threads > 1 else ''}, {busy:.1f} cores busy)"
            )
            print(f"{label}|{build_s:.4f}|{seconds[0]:.6f}|{seconds[1]:.6f}|{tag}", flush=True)


if __name__ == "__main__":
    main(sys.argv[1])
