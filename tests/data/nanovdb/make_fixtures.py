#!/usr/bin/python3
"""Regenerates the NanoVDB fixtures of this folder (see README.md).

Run with Debian's /usr/bin/python3 (python3-openvdb 10.0.1, NumPy); it builds
make_double_vdb.cpp with g++, writes the .npy sources, the .vdb files in a scratch folder
and converts them with nanovdb_convert (NanoVDB 32.4.2).
"""

import gzip
import math
import os
import shutil
import subprocess
import tempfile

import numpy as np
import pyopenvdb as vdb

HERE = os.path.dirname(os.path.abspath(__file__))

# The density grid: 20^3 voxels starting at a negative corner (all coordinates stay negative,
# so the grid has one upper and one lower internal node), background 0.
DENSITY_ORIGIN = (-37, -26, -20)
DENSITY_DIMS = (20, 20, 20)
# Index-to-world map, column convention world = A * ijk + t: uniform scale 0.5 and a
# rotation of 30 degrees about z.
ANGLE = math.radians(30.0)
SCALE = 0.5
TRANSLATION = (1.5, -2.25, 3.0)
# The double grid.
TEMPERATURE_ORIGIN = (5, 6, 7)
TEMPERATURE_BACKGROUND = 293.15
# The Vec3f grid of the multi-grid file.
VELOCITY_ORIGIN = (2, 3, 4)


def splitmix(state):
    """One SplitMix64 step: (new state, uniform float in [0, 1))."""
    state = (state + 0x9E3779B97F4A7C15) & 0xFFFFFFFFFFFFFFFF
    z = state
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & 0xFFFFFFFFFFFFFFFF
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & 0xFFFFFFFFFFFFFFFF
    return state, ((z ^ (z >> 31)) >> 11) / float(1 << 53)


def density_values():
    """A blob with ripples; voxels below 0.05 become background (inactive); one corner
    region holds noise so that FpN leaves need different bit widths."""
    values = np.zeros(DENSITY_DIMS, dtype=np.float32)
    state = 7
    for a in range(DENSITY_DIMS[0]):
        for b in range(DENSITY_DIMS[1]):
            for c in range(DENSITY_DIMS[2]):
                r = math.sqrt((a - 9.5) ** 2 + (b - 9.5) ** 2 + (c - 9.5) ** 2) / 9.0
                v = max(0.0, 1.0 - r) * (1.0 + 0.3 * math.sin(0.7 * a) * math.cos(0.5 * b))
                state, u = splitmix(state)
                if a >= 12 and b >= 12 and c >= 12:
                    v = 0.2 + 0.8 * u
                if v < 0.05:
                    v = 0.0
                values[a, b, c] = v
    return values


def temperature_values():
    """float64 values that float32 cannot hold exactly; every 7th voxel is background."""
    dims = (12, 10, 9)
    values = np.zeros(dims, dtype=np.float64)
    for a in range(dims[0]):
        for b in range(dims[1]):
            for c in range(dims[2]):
                if (a + b + c) % 7 == 0:
                    values[a, b, c] = TEMPERATURE_BACKGROUND
                else:
                    values[a, b, c] = 300.0 + 1e-3 * (a + 0.1 * b) + 1e-9 * (c + 1)
    return values


def density_grid(values):
    grid = vdb.FloatGrid(0.0)
    grid.name = "density"
    grid.gridClass = vdb.GridClass.FOG_VOLUME
    grid.copyFromArray(values, ijk=DENSITY_ORIGIN, tolerance=0.0)
    # OpenVDB's linear transform matrix is in row-vector convention: world = [ijk 1] * M.
    c, s = math.cos(ANGLE), math.sin(ANGLE)
    m = [
        [SCALE * c, SCALE * s, 0.0, 0.0],
        [-SCALE * s, SCALE * c, 0.0, 0.0],
        [0.0, 0.0, SCALE, 0.0],
        [TRANSLATION[0], TRANSLATION[1], TRANSLATION[2], 1.0],
    ]
    grid.transform = vdb.createLinearTransform(m)
    return grid


def velocity_grid():
    values = np.zeros((4, 4, 4, 3), dtype=np.float32)
    for a in range(4):
        for b in range(4):
            for c in range(4):
                values[a, b, c] = (a + 1.0, b - 2.0, c * 0.5)
    grid = vdb.Vec3SGrid((0.0, 0.0, 0.0))
    grid.name = "velocity"
    grid.copyFromArray(values, ijk=VELOCITY_ORIGIN, tolerance=(0.0, 0.0, 0.0))
    return grid


def tiles_grid():
    """Background 0.5; an active upper-node tile (128^3 of 2.0), an active lower-node tile
    (8^3 of 3.0), an inactive lower-node tile holding 7.0 and two active voxels."""
    grid = vdb.FloatGrid(0.5)
    grid.name = "tiles"
    grid.fill((0, 0, 0), (127, 127, 127), 2.0, True)
    grid.fill((128, 0, 0), (135, 7, 7), 3.0, True)
    grid.fill((136, 0, 0), (143, 7, 7), 7.0, False)
    acc = grid.getAccessor()
    acc.setValueOn((-5, 3, 2), 1.25)
    acc.setValueOn((200, 1, 1), -4.0)
    return grid


def root_tile_grid():
    """An active root tile (4096^3 voxels of 9.0 at x = 4096..8191) and one voxel."""
    grid = vdb.FloatGrid(0.0)
    grid.name = "roottile"
    grid.fill((4096, 0, 0), (8191, 4095, 4095), 9.0, True)
    grid.getAccessor().setValueOn((1, 2, 3), 1.0)
    return grid


def convert(args, src, dst):
    subprocess.run(["nanovdb_convert", "-f", *args, src, os.path.join(HERE, dst)], check=True)


def main():
    density = density_values()
    np.save(os.path.join(HERE, "density.npy"), density)
    temperature = temperature_values()
    np.save(os.path.join(HERE, "temperature.npy"), temperature)

    scratch = tempfile.mkdtemp()
    try:
        path = lambda name: os.path.join(scratch, name)
        subprocess.run(
            [
                "g++",
                "-std=c++17",
                "-O1",
                "-o",
                path("make_double_vdb"),
                os.path.join(HERE, "make_double_vdb.cpp"),
                "-lopenvdb",
                "-ltbb",
                "-lImath-3_1",
            ],
            check=True,
        )
        vdb.write(path("density.vdb"), grids=[density_grid(density)])
        empty = vdb.FloatGrid(0.0)
        empty.name = "empty"
        vdb.write(path("multi.vdb"), grids=[density_grid(density), velocity_grid(), empty])
        vdb.write(path("tiles.vdb"), grids=[tiles_grid()])
        vdb.write(path("roottile.vdb"), grids=[root_tile_grid()])
        subprocess.run(
            [
                path("make_double_vdb"),
                os.path.join(HERE, "temperature.npy"),
                "temperature",
                repr(TEMPERATURE_BACKGROUND),
                *[str(v) for v in TEMPERATURE_ORIGIN],
                "0.25",
                "-1",
                "-2",
                "-3",
                path("temperature.vdb"),
            ],
            check=True,
        )

        convert([], path("density.vdb"), "density_none.nvdb")
        with open(os.path.join(HERE, "density_none.nvdb"), "rb") as f:
            raw = f.read()
        # Stored gzipped (mtime 0) to keep the repository small; tests gunzip it.
        with gzip.GzipFile(os.path.join(HERE, "density_none.nvdb.gz"), "wb", 9, mtime=0) as f:
            f.write(raw)
        os.remove(os.path.join(HERE, "density_none.nvdb"))
        convert(["-z"], path("density.vdb"), "density_zip.nvdb")
        convert(["-b"], path("density.vdb"), "density_blosc.nvdb")
        convert(["-z", "--fp4"], path("density.vdb"), "density_fp4.nvdb")
        convert(["-z", "--fp8"], path("density.vdb"), "density_fp8.nvdb")
        convert(["-z", "--fp16"], path("density.vdb"), "density_fp16.nvdb")
        convert(["-z", "--fpN", "-a", "0.002"], path("density.vdb"), "density_fpn.nvdb")
        convert(["-z"], path("temperature.vdb"), "temperature_zip.nvdb")
        convert(["-z"], path("multi.vdb"), "multi_zip.nvdb")
        convert(["-z"], path("tiles.vdb"), "tiles_zip.nvdb")
        convert(["-z", "--fp8"], path("tiles.vdb"), "tiles_fp8.nvdb")
        convert(["-z"], path("roottile.vdb"), "roottile_zip.nvdb")
    finally:
        shutil.rmtree(scratch)


if __name__ == "__main__":
    main()
