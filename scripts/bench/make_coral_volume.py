"""Writes a synthetic coral-like CT volume as a raw file, slab by slab in bounded memory.

The field imitates the coral scans of the seed talk: thin branching walls (the zero set of
a sum of sines, thickened) inside a cylindrical specimen, surrounded by empty space, with
16-bit densities and a little noise. Voxels are x fastest, then y, then z.

    python scripts/bench/make_coral_volume.py OUT.raw --dims 2048,2048,2048 [--dtype u16|f32]

Only NumPy is needed; memory stays about 16 bytes a voxel of one slab of 16 z-planes.
"""

import argparse
import sys

import numpy as np


def slab(dims, z0, planes, rng):
    nx, ny, nz = dims
    x = np.linspace(-1.0, 1.0, nx, dtype=np.float32)[None, None, :]
    y = np.linspace(-1.0, 1.0, ny, dtype=np.float32)[None, :, None]
    z = (np.arange(z0, z0 + planes, dtype=np.float32)[:, None, None] / max(nz - 1, 1)) * 2 - 1
    # A gyroid-like sheet: walls where the sum is near zero.
    f = 9.0
    g = (np.sin(f * x) * np.cos(f * y) + np.sin(f * y) * np.cos(f * z) + np.sin(f * z) * np.cos(f * x))
    wall = np.clip(1.0 - np.abs(g) / 0.35, 0.0, 1.0)
    # Inside a cylinder of radius 0.8 around z, tapering towards the top.
    r = np.sqrt(x * x + y * y)
    inside = (r < 0.8 * (1.0 - 0.3 * (z + 1) / 2)).astype(np.float32)
    density = wall * inside
    noise = rng.random(density.shape, dtype=np.float32) * 0.02
    return np.where(density > 0, density * 0.9 + noise, 0.0).astype(np.float32)


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("out")
    p.add_argument("--dims", default="512,512,512", help="X,Y,Z voxels")
    p.add_argument("--dtype", choices=["u16", "f32"], default="u16")
    p.add_argument("--seed", type=int, default=1)
    a = p.parse_args()
    dims = [int(v) for v in a.dims.split(",")]
    if len(dims) != 3 or min(dims) < 1:
        sys.exit(f"--dims {a.dims}: three positive integers X,Y,Z")
    rng = np.random.default_rng(a.seed)
    nx, ny, nz = dims
    with open(a.out, "wb") as out:
        for z0 in range(0, nz, 16):
            planes = min(16, nz - z0)
            d = slab(dims, z0, planes, rng)
            if a.dtype == "u16":
                out.write((d * 65535).astype("<u2").tobytes())
            else:
                out.write(d.astype("<f4").tobytes())
    size = nx * ny * nz * (2 if a.dtype == "u16" else 4)
    print(f"wrote {a.out}: {nx}x{ny}x{nz} {a.dtype}, {size} bytes")


if __name__ == "__main__":
    main()
