# Incoherent rays for the f32-fallback bench: origins uniform in a box, isotropic directions.
import sys, numpy as np
out, n, lo, hi, seed = sys.argv[1], int(sys.argv[2]), float(sys.argv[3]), float(sys.argv[4]), int(sys.argv[5])
rng = np.random.default_rng(seed)
o = rng.uniform(lo, hi, (n, 3))
z = rng.uniform(-1, 1, n); phi = rng.uniform(0, 2 * np.pi, n); r = np.sqrt(1 - z * z)
d = np.stack([r * np.cos(phi), r * np.sin(phi), z], 1)
rays = np.concatenate([o, np.zeros((n, 1)), d, np.full((n, 1), np.inf)], 1)
np.save(out, rays)
