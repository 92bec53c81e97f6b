"""The Python package's overhead against the `hytrace` command, and hytrace.dask's
throughput on LocalClusters of 1 and 2 workers, measured side by side in one run.

    python scripts/bench_python.py [--rays 1000000] [--repeats 5] [--bin target/release/hytrace]

Needs the package installed (release build: `pip install ./crates/python[dask]`) and the
command built in release (`cargo build --release --bin hytrace`). Prints a Markdown table
(BENCHMARKS.md, "Python and Dask"): the minimum (the least disturbed run on a shared
machine) and the median of each.
"""

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import hytrace


def rays_around_the_default_scene(n: int) -> np.ndarray:
    """The rays of the benchmark: origins spread over the default scene (normal, 600 mm),
    random directions, a fifth with a finite tmax (as the tests' rays)."""
    rng = np.random.default_rng(2026)
    origins = rng.normal(scale=600.0, size=(n, 3))
    directions = rng.normal(size=(n, 3))
    tmax = np.where(rng.random(n) < 0.2, rng.uniform(1, 2400, n), np.inf)
    return np.column_stack([origins, np.zeros(n), directions, tmax])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rays", type=int, default=1_000_000)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--bin", default="target/release/hytrace")
    parser.add_argument("--chunk", type=int, default=125_000)
    args = parser.parse_args()

    rays = rays_around_the_default_scene(args.rays)
    tmp = Path(tempfile.mkdtemp())
    np.save(tmp / "rays.npy", rays)
    command = [args.bin, "scan", "default", "--rays", str(tmp / "rays.npy"),
               "--out", str(tmp / "hits.npy"), "--ids", str(tmp / "ids.npy"), "--stats"]

    scene = hytrace.load("default")
    scene.scan(rays[:1000])  # first call: pages in the library
    cli_wall, cli_scan, py_call, py_whole = [], [], [], []
    for _ in range(args.repeats):
        # Interleaved, so that the machine's load falls on both alike.
        t0 = time.perf_counter()
        p = subprocess.run(command, capture_output=True, text=True, check=True)
        cli_wall.append(time.perf_counter() - t0)
        stats = json.loads(p.stdout)
        cli_scan.append(stats["build_s"] + stats["trace_s"])
        t0 = time.perf_counter()
        hits, ids = scene.scan(rays)
        py_call.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        hits, ids = hytrace.load("default").scan(rays)
        py_whole.append(time.perf_counter() - t0)
    assert np.array_equal(hits, np.load(tmp / "hits.npy"))
    assert np.array_equal(ids, np.load(tmp / "ids.npy"))

    from dask.distributed import Client, LocalCluster
    import dask.array as da
    import hytrace.dask as hd

    dask_rows = []
    for workers in (1, 2):
        with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                          dashboard_address=None, memory_limit=0) as cluster, \
                Client(cluster) as client:
            client.wait_for_workers(workers)
            # Rays scattered to the workers first: what is timed is the tracing.
            blocks = da.from_array(rays, chunks=(args.chunk, 8)).persist()
            warm, _ = hd.scan("default", blocks[: args.chunk * workers])
            client.compute(warm, sync=True)  # every worker loads the scene
            times = []
            for _ in range(args.repeats):
                h, i = hd.scan("default", blocks)
                t0 = time.perf_counter()
                h, i = client.compute([h, i], sync=True)
                times.append(time.perf_counter() - t0)
            assert np.array_equal(h, hits) and np.array_equal(i, ids)
            dask_rows.append((workers, times))

    n = args.rays
    print(f"{n} rays, default scene, f32, CPU backend; {args.repeats} runs each, interleaved; "
          f"Python {sys.version.split()[0]}\n")
    print("| what | min s | median s | rays/s (min) | min against the library's scan |")
    print("|---|---|---|---|---|")
    base = min(cli_scan)

    def row(what, times):
        t = min(times)
        print(f"| {what} | {t:.3f} | {statistics.median(times):.3f} | {n / t:.3e} "
              f"| {t / base:.3f} |")

    row("`hytrace scan --stats`: build_s + trace_s (the library's scan)", cli_scan)
    row("`hytrace scan` process wall time (start, read .npy, scan, write .npy)", cli_wall)
    row("`scene.scan(rays)` (scene loaded)", py_call)
    row("`hytrace.load('default').scan(rays)`", py_whole)
    for workers, times in dask_rows:
        row(f"`hytrace.dask.scan`, LocalCluster of {workers} worker process"
            f"{'es' if workers > 1 else ''} x 1 thread, chunks of {args.chunk}", times)

if __name__ == "__main__":
    main()
