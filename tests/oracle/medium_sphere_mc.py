"""Independent Monte Carlo of photons in a uniform sphere of absorbing and scattering
medium, for tests/tests/photon_media_oracle.rs: photons start at the centre, isotropic,
fly exponential free paths of extinction SIGMA, are absorbed at a collision with
probability 1 - ALBEDO, else scattered by the Henyey-Greenstein law of asymmetry G,
until absorbed or out of the sphere of radius R. Prints JSON: photons, absorbed.

Written for hytrace's tests with NumPy alone (no code shared with hytrace).

usage: medium_sphere_mc.py R SIGMA ALBEDO G N SEED
"""

import json
import sys

import numpy as np


def hg_cosines(rng, g, n):
    """Cosines of Henyey-Greenstein scattering angles (inverse CDF)."""
    u = rng.random(n)
    if abs(g) < 1e-9:
        return 1.0 - 2.0 * u
    s = (1.0 - g * g) / (1.0 + g - 2.0 * g * u)
    return np.clip((1.0 + g * g - s * s) / (2.0 * g), -1.0, 1.0)


def turn(d, cos_t, phi):
    """Directions at angle acos(cos_t) from the unit rows of d, azimuth phi."""
    # Any unit vector perpendicular to d, then the third axis.
    helper = np.where(np.abs(d[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    a = np.cross(d, helper)
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    b = np.cross(d, a)
    sin_t = np.sqrt(np.maximum(0.0, 1.0 - cos_t * cos_t))
    out = (d * cos_t[:, None] + a * (sin_t * np.cos(phi))[:, None]
           + b * (sin_t * np.sin(phi))[:, None])
    return out / np.linalg.norm(out, axis=1, keepdims=True)


def main():
    radius, sigma, albedo, g = (float(v) for v in sys.argv[1:5])
    n, seed = int(sys.argv[5]), int(sys.argv[6])
    rng = np.random.default_rng(seed)
    pos = np.zeros((n, 3))
    z = 1.0 - 2.0 * rng.random(n)
    phi = 2.0 * np.pi * rng.random(n)
    r = np.sqrt(1.0 - z * z)
    d = np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)
    absorbed = 0
    while len(pos):
        free = -np.log(1.0 - rng.random(len(pos))) / sigma
        # Distance to the sphere along d from inside: t^2 + 2 b t + c = 0, c < 0.
        b = np.einsum("ij,ij->i", pos, d)
        c = np.einsum("ij,ij->i", pos, pos) - radius * radius
        out = -b + np.sqrt(np.maximum(0.0, b * b - c))
        inside = free < out
        pos, d, free = pos[inside], d[inside], free[inside]
        pos = pos + d * free[:, None]
        scatters = rng.random(len(pos)) < albedo
        absorbed += int(np.count_nonzero(~scatters))
        pos, d = pos[scatters], d[scatters]
        d = turn(d, hg_cosines(rng, g, len(d)), 2.0 * np.pi * rng.random(len(d)))
    print(json.dumps({"photons": n, "absorbed": absorbed}))


if __name__ == "__main__":
    main()
