"""Regenerates the OpenVDB fixtures of crates/volume/tests/openvdb_reader.rs.

Run from this folder with Debian's python3-openvdb (pyopenvdb 10.0.1), libopenvdb-tools
(vdb_tool), libopenvdb-dev and g++ (for make_double.cpp):  /usr/bin/python3 generate.py
See README.md for what each file holds.
"""

import json
import math
import os
import subprocess
import tempfile

import numpy as np
import pyopenvdb as vdb


def rotation(axis, angle):
    """Rodrigues' rotation matrix about `axis` by `angle` radians (column vectors)."""
    n = np.asarray(axis, dtype=np.float64)
    n /= np.linalg.norm(n)
    k = np.array([[0, -n[2], n[1]], [n[2], 0, -n[0]], [-n[1], n[0], 0]])
    return np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * (k @ k)


def openvdb_matrix(linear, translation):
    """OpenVDB's 4x4 (row vectors: world = [i j k 1] * M) for world = linear @ ijk + t."""
    m = np.zeros((4, 4))
    m[:3, :3] = np.asarray(linear).T
    m[3, :3] = translation
    m[3, 3] = 1.0
    return m.tolist()


def world_points(grid, points):
    return {
        "index": points,
        "world": [list(grid.transform.indexToWorld(tuple(p))) for p in points],
    }


def density_source():
    """Sparse values over a box with a negative origin: background 0.25 almost everywhere,
    random voxels, a smooth blob, two constant 8^3-aligned blocks (they become tiles)."""
    rng = np.random.default_rng(7)
    origin = (-140, -45, -50)
    a = np.full((37, 29, 26), 0.25, dtype=np.float32)
    pick = rng.random(a.shape) < 0.03
    a[pick] = rng.uniform(-2.0, 5.0, pick.sum()).astype(np.float32)
    x, y, z = np.meshgrid(*[np.arange(n) for n in a.shape], indexing="ij")
    r2 = (x - 26.0) ** 2 + (y - 20.0) ** 2 + (z - 8.0) ** 2
    blob = r2 < 36.0
    a[blob] = np.exp(-r2[blob] / 9.0).astype(np.float32)
    # Index blocks [-136, -128) x [-40, -32) x [-48, -40) and [-120, -112) x [-32, -24) x [-40, -32).
    def block(lo, value):
        s = tuple(slice(lo[k] - origin[k], lo[k] - origin[k] + 8) for k in range(3))
        a[s] = value
    block((-136, -40, -48), 3.0)
    block((-120, -32, -40), -1.0)
    return origin, a


def inactive_values(grid, source, origin):
    """Gives a few background voxels of mixed leaves inactive values other than the
    background, so the file holds each way OpenVDB stores inactive leaf values: both signs
    of the background (a selection mask), one other value (value + mask) and more than two
    distinct values (every value stored). They must still read as the background."""
    acc = grid.getAccessor()
    leaves = {}
    for p in zip(*np.nonzero(source == grid.background)):
        ijk = tuple(int(p[k]) + origin[k] for k in range(3))
        leaves.setdefault(tuple(c & ~7 for c in ijk), []).append(ijk)
    mixed = [k for k in sorted(leaves) if 3 <= len(leaves[k]) < 500]
    plan = [(mixed[0], [-grid.background]), (mixed[1], [7.0]), (mixed[2], [7.0, 8.0, 9.0])]
    out = []
    for leaf, values in plan:
        for ijk, value in zip(leaves[leaf], values):
            acc.setValueOff(ijk, value)
            out.append({"ijk": list(ijk), "value": value})
    return out


def main():
    here = os.path.dirname(os.path.abspath(__file__))
    os.chdir(here)
    meta = {}

    # --- grids.vdb: four grids, OpenVDB's default codec (blosc + active mask).
    origin, dens = density_source()
    np.save("density.npy", dens)
    density = vdb.FloatGrid(0.25)
    density.name = "density"
    density.copyFromArray(dens, ijk=origin, tolerance=0)
    inactive = inactive_values(density, dens, origin)
    fill = {"min": [-256, -256, -256], "max": [-129, -129, -129], "value": 1.75}
    density.fill(tuple(fill["min"]), tuple(fill["max"]), fill["value"], True)
    linear = rotation((1.0, 2.0, 3.0), 0.7) @ np.diag([0.5, 0.75, 1.25])
    translation = [10.0, -4.0, 2.5]
    density.transform = vdb.createLinearTransform(openvdb_matrix(linear, translation))
    probe = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [-21.5, 7.25, 100.0]]
    meta["density"] = {
        "source": "density.npy",
        "origin": list(origin),
        "background": 0.25,
        "fill": fill,
        "inactive": inactive,
        "linear": linear.tolist(),
        "translation": translation,
        "points": world_points(density, probe),
    }

    rng = np.random.default_rng(11)
    temp = rng.uniform(0.5, 9.0, (10, 9, 12)).astype(np.float32)
    temp[rng.random(temp.shape) < 0.4] = 0.0
    np.save("temperature.npy", temp)
    temperature = vdb.FloatGrid(0.0)
    temperature.name = "temperature"
    temperature.copyFromArray(temp, ijk=(3, -40, 7), tolerance=0)
    temperature.transform = vdb.createLinearTransform(voxelSize=0.1)
    temperature.transform.translate((1.5, -2.0, 0.25))
    meta["temperature"] = {
        "source": "temperature.npy",
        "origin": [3, -40, 7],
        "background": 0.0,
        "points": world_points(temperature, probe),
    }

    # A shallow copy shares density's tree: OpenVDB writes it as an instance.
    instance = density.copy()
    instance.name = "density_instance"
    instance.transform = vdb.createLinearTransform(
        [[0.5, 0, 0, 0], [0, 0.25, 0, 0], [0, 0, 2.0, 0], [1.0, 2.0, 3.0, 1.0]]
    )
    meta["density_instance"] = {"points": world_points(instance, probe)}

    velocity = vdb.Vec3SGrid()
    velocity.name = "velocity"
    acc = velocity.getAccessor()
    acc.setValueOn((1, 2, 3), (1.0, 0.0, -1.0))
    acc.setValueOn((9, 0, 4), (0.5, 0.5, 0.5))

    vdb.write(
        "grids.vdb",
        grids=[density, temperature, instance, velocity],
        metadata={"creator": "hytrace tests/data/openvdb/generate.py"},
    )

    # --- the same density grid with the other codecs; saved as half floats.
    with tempfile.TemporaryDirectory() as tmp:
        only = os.path.join(tmp, "density.vdb")
        vdb.write(only, grids=[density])
        for codec, out in [("zip", "density_zip.vdb"), ("active", "density_active.vdb")]:
            subprocess.run(
                ["vdb_tool", "-read", only, "-write", f"codec={codec}", out],
                check=True, capture_output=True,
            )
    half = density.deepCopy()
    half.saveFloatAsHalf = True
    vdb.write("density_half.vdb", grids=[half])

    # --- a DoubleGrid (pyopenvdb 10 has none: make_double.cpp writes it).
    rng = np.random.default_rng(5)
    dbl = np.full((12, 17, 9), -1.5)
    pick = rng.random(dbl.shape) < 0.2
    dbl[pick] = rng.uniform(-1e3, 1e3, pick.sum())
    dbl[0:8, 8:16, 0:8] = 1.0 / 3.0  # voxels [-24, -16) x [-32, -24) x [-16, -8): one 8^3 tile
    np.save("double.npy", dbl)
    with tempfile.TemporaryDirectory() as tmp:
        exe = os.path.join(tmp, "make_double")
        subprocess.run(
            ["g++", "-std=c++17", "-O1", "make_double.cpp", "-o", exe, "-lopenvdb", "-ltbb", "-lImath-3_1"],
            check=True,
        )
        subprocess.run([exe, "double.npy", "double.vdb", "-24", "-40", "-16", "-1.5", "0.3"], check=True)
    meta["double_density"] = {
        "source": "double.npy",
        "origin": [-24, -40, -16],
        "background": -1.5,
        "voxel_size": 0.3,
    }

    # --- root-level tiles (4096^3 voxels each): one fits the block cap, two do not.
    one = vdb.FloatGrid(0.0)
    one.name = "one_root_tile"
    one.fill((-4096, 0, 4096), (-1, 4095, 8191), 0.5, True)
    two = vdb.FloatGrid(0.0)
    two.name = "two_root_tiles"
    two.fill((0, 0, 0), (4095, 4095, 4095), 2.0, True)
    two.fill((4096, 0, 0), (8191, 4095, 4095), 3.0, True)
    vdb.write("root_tiles.vdb", grids=[one, two])
    meta["one_root_tile"] = {"min": [-4096, 0, 4096], "max": [-1, 4095, 8191], "value": 0.5}

    # --- a frustum transform, which the reader refuses.
    frustum = vdb.FloatGrid(0.0)
    frustum.name = "frustum"
    frustum.getAccessor().setValueOn((1, 1, 1), 1.0)
    frustum.transform = vdb.createFrustumTransform((0, 0, 0), (10, 10, 10), 0.5, 2.0, 1.0)
    vdb.write("frustum.vdb", grids=[frustum])

    with open("fixtures.json", "w") as f:
        json.dump(meta, f, indent=1)
        f.write("\n")


if __name__ == "__main__":
    main()
