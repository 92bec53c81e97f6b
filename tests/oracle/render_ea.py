"""Independent emission-absorption reference for `hytrace render` (NumPy only).

Rebuilds the camera rays from the documented convention (docs/rendering.md, "Camera convention") and
integrates, per pixel centre, the emission-absorption model

    L = integral of T(t) * sigma(t) * v(t) * e dt + T(inf) * background,
    sigma = scale * v,  v = trilinear value of the dense grid,  T(t) = exp(-integral sigma)

by midpoint compositing in float64 with a step far below a voxel, over the NanoVDB
fixture's source array (tests/data/nanovdb/density.npy) and the index-to-world map its
README states. Nothing here reads hytrace's files except the arguments.

Usage: render_ea.py DENSITY.npy OUT.npy JSON where JSON holds width, height, eye, target,
up, fov (degrees), scale, emission, background, step (world units).
"""

import json
import sys

import numpy as np

density_path, out_path, params = sys.argv[1], sys.argv[2], json.loads(sys.argv[3])
grid = np.load(density_path).astype(np.float64)
origin = np.array([-37, -26, -20], dtype=np.float64)  # voxel of grid[0, 0, 0]
# world = 0.5 * Rz(30 deg) * ijk + (1.5, -2.25, 3)
c, s = np.cos(np.radians(30.0)), np.sin(np.radians(30.0))
rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
voxel, shift = 0.5, np.array([1.5, -2.25, 3.0])

w, h = params["width"], params["height"]
eye, target, up = (np.array(params[k], dtype=np.float64) for k in ("eye", "target", "up"))
fwd = (target - eye) / np.linalg.norm(target - eye)
right = np.cross(fwd, up)
right /= np.linalg.norm(right)
true_up = np.cross(right, fwd)
tan_half = np.tan(np.radians(params["fov"]) / 2)
ii, jj = np.meshgrid(np.arange(w), np.arange(h))
x = (2 * (ii + 0.5) / w - 1) * (w / h)
y = 1 - 2 * (jj + 0.5) / h
dirs = fwd + tan_half * (x[..., None] * right + y[..., None] * true_up)
dirs /= np.linalg.norm(dirs, axis=-1, keepdims=True)
dirs = dirs.reshape(-1, 3)

# Rays in index space: ijk = R^T (world - shift) / voxel.
o_idx = rot.T @ (eye - shift) / voxel
d_idx = dirs @ rot / voxel  # row vectors: (R^T d)^T = d^T R

# Where trilinear lookups can be non-zero: [origin - 1, origin + shape] per axis.
lo, hi = origin - 1.0, origin + np.array(grid.shape, dtype=np.float64)
with np.errstate(divide="ignore", invalid="ignore"):
    ta = (lo - o_idx) / d_idx
    tb = (hi - o_idx) / d_idx
t0 = np.nanmax(np.minimum(ta, tb), axis=1).clip(min=0.0)
t1 = np.nanmin(np.maximum(ta, tb), axis=1)


def trilinear(p):
    q = p - origin
    base = np.floor(q).astype(np.int64)
    f = q - base
    out = np.zeros(len(p))
    for corner in range(8):
        off = np.array([corner & 1, corner >> 1 & 1, corner >> 2 & 1])
        idx = base + off
        inside = np.all((idx >= 0) & (idx < np.array(grid.shape)), axis=1)
        wgt = np.prod(np.where(off == 1, f, 1 - f), axis=1)
        vals = np.zeros(len(p))
        vals[inside] = grid[idx[inside, 0], idx[inside, 1], idx[inside, 2]]
        out += wgt * vals
    return out


scale, step = params["scale"], params["step"]
emission, background = np.array(params["emission"]), np.array(params["background"])
n_rays = len(dirs)
radiance = np.zeros((n_rays, 3))
trans = np.ones(n_rays)
live = t1 > t0
length = np.where(live, t1 - t0, 0.0)
n_steps = int(np.ceil(length.max() / step)) if live.any() else 0
for k in range(n_steps):
    t = t0 + (k + 0.5) * step
    active = live & (t < t1)
    if not active.any():
        break
    # The last step of each ray is clipped to t1 (midpoint of the clipped piece).
    h_k = np.minimum(step, t1 - (t0 + k * step))
    t = t0 + k * step + 0.5 * h_k
    p = o_idx + t[:, None] * d_idx
    v = np.where(active, trilinear(p), 0.0)
    sigma = scale * v
    a = 1.0 - np.exp(-sigma * np.where(active, h_k, 0.0))
    radiance += (trans * a * v)[:, None] * emission
    trans *= 1.0 - a
radiance += trans[:, None] * background
np.save(out_path, radiance.reshape(h, w, 3))
