"""Scale-out of scans, transmittance and photon runs on Dask (``dask.distributed`` or any
Dask scheduler).

Rays go in as a dask array of shape (N, 8) and results come out as dask arrays chunked as
the rays are; photon runs are split into ranges of photon indices, one task each. Every
task loads its scene through a per-process cache keyed by path (:func:`scene`), so a
worker reads each scene once. Results are identical bit for bit for any number of
workers and any chunking: rays are traced independently of each other, the stochastic
transmittance estimators draw ray i's random numbers from the stream of its global index
(each chunk passes the index of its first ray), and photon i draws the stream
``(seed, i)`` whichever range it falls in.

>>> from dask.distributed import Client, LocalCluster
>>> import dask.array as da, hytrace.dask
>>> client = Client(LocalCluster(n_workers=2, threads_per_worker=1))
>>> rays = da.from_array(numpy_rays, chunks=(100_000, 8))
>>> hits, ids = hytrace.dask.scan("scene.gdml", rays)
>>> hits.compute()
"""

from __future__ import annotations

import os
import threading
from typing import Any, Dict, Tuple, Union

import dask
import dask.array as da
import numpy as np

from . import _hytrace

__all__ = ["scene", "scan", "transmittance", "photons", "photon_ranges"]

PathLike = Union[str, "os.PathLike[str]"]

_scenes: Dict[Tuple[str, bool], _hytrace.Scene] = {}
_scenes_lock = threading.Lock()


def scene(path: PathLike = "default", *, lenient: bool = False) -> _hytrace.Scene:
    """The scene at ``path`` loaded once per process (a cache keyed by the path as given
    and ``lenient``): what every task of this module traces."""
    key = (os.fspath(path), lenient)
    with _scenes_lock:
        loaded = _scenes.get(key)
        if loaded is None:
            loaded = _hytrace.load(key[0], lenient=lenient)
            _scenes[key] = loaded
        return loaded


def _rays_array(rays: Any) -> da.Array:
    """``rays`` as a dask array of (N, 8) rows, one chunk across the columns."""
    rays = da.asarray(rays)
    if rays.ndim != 2 or rays.shape[1] != 8:
        raise _hytrace_value_error(
            f"rays need shape (N, 8) (ox oy oz tmin dx dy dz tmax), got {list(rays.shape)}"
        )
    return rays.rechunk({1: 8})


def _hytrace_value_error(message: str) -> Exception:
    from ._errors import HytraceValueError

    return HytraceValueError(message)


def _scan_block(block: np.ndarray, path: str, lenient: bool, precision: str, backend: str):
    return scene(path, lenient=lenient).scan(block, precision=precision, backend=backend)


def scan(
    path: PathLike,
    rays: Any,
    *,
    precision: str = "f32",
    backend: str = "cpu",
    lenient: bool = False,
) -> Tuple[da.Array, da.Array]:
    """:meth:`hytrace.Scene.scan` of the scene at ``path`` over a dask array of rays
    (N, 8), chunk by chunk: ``(hits, ids)``, dask arrays (N, 4) and (N, 3) chunked along
    N as the rays are. Nothing runs until they are computed."""
    rays = _rays_array(rays)
    dtype = np.float32 if precision == "f32" else np.float64
    path = os.fspath(path)
    hits, ids = [], []
    for block, n in zip(rays.to_delayed().ravel(), rays.chunks[0]):
        pair = dask.delayed(_scan_block, nout=2, pure=True)(
            block, path, lenient, precision, backend
        )
        hits.append(da.from_delayed(pair[0], shape=(n, 4), dtype=dtype))
        ids.append(da.from_delayed(pair[1], shape=(n, 3), dtype=np.int32))
    return da.concatenate(hits), da.concatenate(ids)


def _transmittance_block(
    block: np.ndarray, path: str, lenient: bool, first: int, options: Dict[str, Any]
) -> np.ndarray:
    return scene(path, lenient=lenient).transmittance(block, first=first, **options)


def transmittance(
    path: PathLike, rays: Any, *, lenient: bool = False, **options: Any
) -> da.Array:
    """:meth:`hytrace.Scene.transmittance` of the scene at ``path`` over a dask array of
    rays (N, 8), chunk by chunk: a dask array (N,) float64. ``options`` are the method's
    (``estimator``, ``spp``, ``seed`` ...); ray i draws the streams of its global index
    i, so chunking does not change the estimates (the GPU backend numbers rays from 0 and
    takes a single chunk only)."""
    if "first" in options:
        raise _hytrace_value_error("first is set per chunk by hytrace.dask.transmittance")
    rays = _rays_array(rays)
    path = os.fspath(path)
    parts = []
    start = 0
    for block, n in zip(rays.to_delayed().ravel(), rays.chunks[0]):
        values = dask.delayed(_transmittance_block, pure=True)(
            block, path, lenient, start, options
        )
        parts.append(da.from_delayed(values, shape=(n,), dtype=np.float64))
        start += n
    return da.concatenate(parts)


def photon_ranges(photons: int, chunk: int) -> list:
    """``photons`` split into ``(first, count)`` ranges of at most ``chunk`` photons."""
    if photons < 1 or chunk < 1:
        raise _hytrace_value_error(
            f"photons ({photons}) and chunk ({chunk}) must be at least 1"
        )
    return [(first, min(chunk, photons - first)) for first in range(0, photons, chunk)]


def _photon_block(
    path: str, lenient: bool, source: str, first: int, count: int, options: Dict[str, Any]
):
    return scene(path, lenient=lenient).photons(source, count, first=first, **options)


def photons(
    path: PathLike,
    source: str,
    photons: int,
    *,
    chunk: int = 1_000_000,
    histories: bool = False,
    lenient: bool = False,
    **options: Any,
) -> Union[da.Array, Tuple[da.Array, da.Array]]:
    """:meth:`hytrace.Scene.photons` of the scene at ``path``, photons ``0 .. photons``
    split into tasks of ``chunk`` photons (each a range of photon indices, so the seeds of
    a task are its ``seed`` and its first index): the detected photons, a dask array
    (H, 16) float64 in photon order whose chunk lengths are known once computed; with
    ``histories=True`` also every photon's packed history, (photons,) uint64. ``options``
    are the method's (``wavelength``, ``seed``, ``max_steps``, ``memory``: each task's
    budget for the media read as stored)."""
    path = os.fspath(path)
    hits, codes = [], []
    for first, count in photon_ranges(photons, chunk):
        task = dask.delayed(_photon_block, pure=True, nout=2 if histories else None)(
            path, lenient, source, first, count, dict(options, histories=histories)
        )
        if histories:
            hits.append(da.from_delayed(task[0], shape=(np.nan, 16), dtype=np.float64))
            codes.append(da.from_delayed(task[1], shape=(count,), dtype=np.uint64))
        else:
            hits.append(da.from_delayed(task, shape=(np.nan, 16), dtype=np.float64))
    if histories:
        return da.concatenate(hits), da.concatenate(codes)
    return da.concatenate(hits)

