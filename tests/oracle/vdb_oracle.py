"""OpenVDB/NanoVDB oracle of the volume tests (run with Debian's /usr/bin/python3).

Subcommands:
  make DIR            build the test grids from NumPy arrays with pyopenvdb (python3-openvdb),
                      write them as .vdb and convert each with nanovdb_convert
                      (libnanovdb-tools) to plain, ZIP, BLOSC, Fp4, Fp8, Fp16 and FpN .nvdb
                      files; beside each case its dense source (CASE.npy, float32, axes x y z)
                      and CASE.json (index origin, background, index-to-world matrix,
                      translation, files written).
  trilinear DIR CASE POINTS OUT
                      trilinear lookups (OpenVDB's box sampler convention: voxel centres at
                      integer index coordinates) of the dense source at world points
                      POINTS (N, 3) float64, computed in float64 -> OUT (N,) float64.
  fog-sphere PATH N   a fog sphere filling an N^3 box (radius N/2 voxels, density 1 inside
                      a 3-voxel linear blend, as Falcor's createSphere) as a .vdb file, for
                      the conversion benchmark.
  optical-depth DIR CASE RAYS OUT
                      optical depth of the trilinear field along world rays RAYS (N, 8):
                      ox oy oz tmin dx dy dz tmax, by composite Simpson quadrature with
                      nodes on every unit-cell crossing (the field is a cubic polynomial
                      between crossings, so the quadrature is exact up to rounding).

The references are NumPy's, computed from the arrays the grids were built from, independent
of hytrace's readers and samplers.
"""

import json
import os
import subprocess
import sys

import numpy as np
import pyopenvdb as vdb


def affine(rotation_deg, scale, translation):
    """Index-to-world matrix (column-vector convention) and translation."""
    a = np.radians(rotation_deg)
    rz = np.array([[np.cos(a[2]), -np.sin(a[2]), 0], [np.sin(a[2]), np.cos(a[2]), 0], [0, 0, 1]])
    ry = np.array([[np.cos(a[1]), 0, np.sin(a[1])], [0, 1, 0], [-np.sin(a[1]), 0, np.cos(a[1])]])
    rx = np.array([[1, 0, 0], [0, np.cos(a[0]), -np.sin(a[0])], [0, np.sin(a[0]), np.cos(a[0])]])
    return rz @ ry @ rx @ np.diag(scale), np.array(translation, dtype=float)


def cases(rng):
    """(name, dense float32 array indexed [x, y, z], index origin, background, matrix, translation)."""
    out = []
    # Random sparse values, negative origin, rotated anisotropic voxels.
    a = rng.uniform(0.0, 3.0, size=(40, 33, 27)).astype(np.float32)
    a[rng.random(a.shape) < 0.35] = 0.0
    a[5:21, 8:24, 3:19] = 1.25  # constant leaves (OpenVDB may keep them as tiles)
    m, t = affine([20.0, -35.0, 50.0], [0.5, 0.25, 0.75], [10.0, -20.0, 3.5])
    out.append(("sparse", a, (-61, -7, -130), 0.0, m, t))
    # A smooth fog blob at very large index coordinates with small voxels far from the origin.
    n = 36
    x = np.arange(n) - (n - 1) / 2
    d = np.sqrt(x[:, None, None] ** 2 + x[None, :, None] ** 2 + x[None, None, :] ** 2)
    blob = np.clip((15.0 - d) / 5.0, 0.0, 1.0).astype(np.float32) * 2.0
    m, t = affine([0.0, 0.0, 0.0], [0.01, 0.01, 0.01], [-10000.0, 20000.0, 5.0])
    out.append(("far", blob, (1_000_000, -2_000_008, 5_000_000), 0.0, m, t))
    # A non-zero background with holes of other values.
    b = np.full((17, 16, 9), 0.25, np.float32)
    b[rng.random(b.shape) < 0.2] = 4.0
    b[3:6, 3:6, 3:6] = 0.0
    m, t = affine([0.0, 90.0, 0.0], [1.0, 2.0, 1.0], [0.0, 0.0, 0.0])
    out.append(("background", b, (-8, -8, -4), 0.25, m, t))
    return out


def to_vdb_matrix(m, t):
    """OpenVDB's row-vector 4x4 matrix for world = m @ ijk + t."""
    mat = np.eye(4)
    mat[:3, :3] = m.T
    mat[3, :3] = t
    return mat.tolist()


NANO_VARIANTS = {
    "": [],
    "_zip": ["-z"],
    "_blosc": ["-b"],
    "_fp4": ["--fp4"],
    "_fp8": ["--fp8"],
    "_fp16": ["--fp16"],
    "_fpn": ["--fpN", "-a", "0.01"],
}


def make(directory):
    os.makedirs(directory, exist_ok=True)
    rng = np.random.default_rng(20261122)
    for name, array, origin, background, m, t in cases(rng):
        grid = vdb.FloatGrid(background)
        grid.name = name
        grid.copyFromArray(array, ijk=origin, tolerance=0.0)
        grid.transform = vdb.createLinearTransform(to_vdb_matrix(m, t))
        grid.prune()
        vdb_path = os.path.join(directory, name + ".vdb")
        vdb.write(vdb_path, grids=[grid])
        files = {"vdb": name + ".vdb"}
        for suffix, flags in NANO_VARIANTS.items():
            nano = os.path.join(directory, name + suffix + ".nvdb")
            r = subprocess.run(["nanovdb_convert", "-f", *flags, vdb_path, nano], capture_output=True, text=True)
            if r.returncode == 0 and os.path.exists(nano):
                files["nanovdb" + suffix] = name + suffix + ".nvdb"
            else:
                files["nanovdb" + suffix] = None
                sys.stderr.write(f"nanovdb_convert {flags} failed for {name}: {r.stderr.strip()}\n")
        np.save(os.path.join(directory, name + ".npy"), array)
        samples = [(0, 0, 0), (1, -2, 3), (1_000_000, 2_000_000, -5_000_000)]
        meta = {
            "origin": list(origin),
            "map_samples": [[list(p), list(grid.transform.indexToWorld(p))] for p in samples],
            "background": background,
            "matrix": m.tolist(),
            "translation": t.tolist(),
            "active_voxels": int(grid.activeVoxelCount()),
            "files": files,
        }
        with open(os.path.join(directory, name + ".json"), "w") as f:
            json.dump(meta, f, indent=1)


def load(directory, name):
    with open(os.path.join(directory, name + ".json")) as f:
        meta = json.load(f)
    return np.load(os.path.join(directory, name + ".npy")).astype(np.float64), meta


def voxel_values(array, origin, background, ijk):
    """Values of integer voxels ijk (M, 3), background outside the array."""
    local = ijk - np.asarray(origin)
    inside = np.all((local >= 0) & (local < np.asarray(array.shape)), axis=1)
    out = np.full(len(ijk), background, dtype=np.float64)
    li = local[inside]
    out[inside] = array[li[:, 0], li[:, 1], li[:, 2]]
    return out


def trilinear_index(array, meta, p):
    base = np.floor(p)
    frac = p - base
    base = base.astype(np.int64)
    total = np.zeros(len(p))
    for corner in range(8):
        offset = np.array([(corner >> k) & 1 for k in range(3)])
        w = np.prod(np.where(offset == 1, frac, 1.0 - frac), axis=1)
        total += w * voxel_values(array, meta["origin"], meta["background"], base + offset)
    return total


def transform(directory, name):
    """The case's transform as OpenVDB stores and applies it, which may differ from the
    matrix it was built from by rounding: OpenVDB's is the reference."""
    return vdb.read(os.path.join(directory, name + ".vdb"), name).transform


def world_to_index(xform, world):
    return np.array([xform.worldToIndex(tuple(p)) for p in world])


def trilinear(directory, name, points_path, out_path):
    array, meta = load(directory, name)
    points = np.load(points_path).astype(np.float64).reshape(-1, 3)
    xform = transform(directory, name)
    np.save(out_path, trilinear_index(array, meta, world_to_index(xform, points)))


def optical_depth(directory, name, rays_path, out_path):
    array, meta = load(directory, name)
    rays = np.load(rays_path).astype(np.float64).reshape(-1, 8)
    xform = transform(directory, name)
    lo = np.asarray(meta["origin"]) - 1.0
    hi = lo + np.asarray(array.shape) + 1.0
    depths = []
    for ray in rays:
        # The index-space ray: t is the same in both spaces (the map is affine).
        o = np.array(xform.worldToIndex(tuple(ray[0:3])))
        d = np.array(xform.worldToIndex(tuple(ray[0:3] + ray[4:7]))) - o
        t0, t1 = ray[3], ray[7]
        # Outside [lo, hi] (one voxel beyond the data) the field is the background.
        with np.errstate(divide="ignore", invalid="ignore"):
            ta = (lo - o) / d
            tb = (hi - o) / d
        near = np.where(d != 0, np.minimum(ta, tb), -np.inf)
        far = np.where(d != 0, np.maximum(ta, tb), np.inf)
        inside_slab = np.all((d != 0) | ((o >= lo) & (o <= hi)))
        a, b = max(t0, near.max()), min(t1, far.min())
        background_length = t1 - t0
        depth = 0.0
        if inside_slab and a < b:
            background_length -= b - a
            # Breakpoints: every crossing of an integer plane (unit-cell faces of the
            # trilinear interpolation) between a and b.
            cuts = [a, b]
            for k in range(3):
                if d[k] != 0:
                    pa, pb = o[k] + a * d[k], o[k] + b * d[k]
                    planes = np.arange(np.ceil(min(pa, pb)), np.floor(max(pa, pb)) + 1)
                    cuts.extend(((planes - o[k]) / d[k]).tolist())
            cuts = np.unique(np.clip(np.asarray(cuts), a, b))
            left, right = cuts[:-1], cuts[1:]
            mid = 0.5 * (left + right)
            f = lambda ts: trilinear_index(array, meta, o[None, :] + ts[:, None] * d[None, :])
            depth = np.sum((right - left) / 6.0 * (f(left) + 4.0 * f(mid) + f(right)))
        if background_length > 0 and meta["background"] != 0.0:
            depth += meta["background"] * background_length
        depths.append(depth)
    np.save(out_path, np.asarray(depths))


def fog_sphere(path, n):
    n = int(n)
    c = (n - 1) / 2.0
    x = (np.arange(n, dtype=np.float32) - c) ** 2
    grid = vdb.FloatGrid(0.0)
    grid.name = "density"
    # Slab by slab, to keep NumPy's temporaries small.
    for i in range(n):
        d = np.sqrt(x[i] + x[:, None] + x[None, :])
        slab = np.clip((n / 2.0 - d) / 3.0, 0.0, 1.0).astype(np.float32)[None, :, :]
        grid.copyFromArray(slab, ijk=(i, 0, 0), tolerance=0.0)
    grid.prune()
    vdb.write(path, grids=[grid])


def main():
    command, args = sys.argv[1], sys.argv[2:]
    if command == "make":
        make(*args)
    elif command == "trilinear":
        trilinear(*args)
    elif command == "fog-sphere":
        fog_sphere(*args)
    elif command == "optical-depth":
        optical_depth(*args)
    else:
        raise SystemExit(f"unknown command {command}")


if __name__ == "__main__":
    main()
