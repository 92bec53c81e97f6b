"""hytrace: hybrid ray tracing of Geant4 CSG solids, triangle meshes and sparse volumes,
with NumPy arrays in and out.

>>> import numpy as np, hytrace
>>> scene = hytrace.load("default")
>>> rays = np.array([[0, 0, -500, 0, 0, 0, 1, np.inf]], dtype=np.float64)
>>> hits, ids = scene.scan(rays)

Every function computes what the matching ``hytrace`` command computes, bit for bit;
``hytrace.dask`` maps scans, transmittance and photon runs over a Dask cluster. See
docs/python.md.
"""

from ._errors import (
    HytraceError,
    HytraceFileNotFoundError,
    HytraceTypeError,
    HytraceValueError,
)
from ._hytrace import Scene, Volume, __version__, load

__all__ = [
    "HytraceError",
    "HytraceFileNotFoundError",
    "HytraceTypeError",
    "HytraceValueError",
    "Scene",
    "Volume",
    "__version__",
    "load",
]
