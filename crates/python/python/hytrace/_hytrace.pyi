"""Type stubs of the extension module (re-exported by ``hytrace``)."""

import os
from typing import Any, Literal, Optional, Sequence, Tuple, Union, overload

import numpy as np
import numpy.typing as npt

__version__: str

Precision = Literal["f32", "f64"]
Backend = Literal["cpu", "embree", "gpu", "auto"]
Estimator = Literal["exact", "march", "delta", "ratio", "residual"]
Filter = Literal["nearest", "trilinear", "stochastic"]

def load(path: Union[str, "os.PathLike[str]"] = "default", *, lenient: bool = False) -> Scene:
    """Loads a scene: ``"default"``, a Foundry directory, a .toml scene file, a .gdml file
    or an .obj, .gltf or .glb mesh, as ``hytrace info`` reads it."""

class Scene:
    """A scene loaded once and traced many times (``hytrace.load``)."""

    @property
    def path(self) -> "os.PathLike[str]":
        """What the scene was loaded from."""
    def info(self) -> dict[str, Any]:
        """The scene's summary, as ``hytrace info --json`` prints it."""
    def scan(
        self,
        rays: npt.ArrayLike,
        *,
        precision: Precision = "f32",
        backend: Backend = "cpu",
    ) -> Tuple[npt.NDArray[np.floating[Any]], npt.NDArray[np.int32]]:
        """First boundary crossing of each (N, 8) ray ``ox oy oz tmin dx dy dz tmax``:
        ``(hits (N, 4) nx ny nz t, ids (N, 3) int32 instance boundary copy)``, as
        ``hytrace scan``; hits are float32 for ``precision="f32"``, float64 for "f64"."""
    def transmittance(
        self,
        rays: npt.ArrayLike,
        *,
        estimator: Estimator = "exact",
        step: float = 0.5,
        spp: int = 1,
        seed: int = 0,
        density_scale: float = 1.0,
        filter: Filter = "trilinear",
        level: int = 0,
        global_majorant: bool = False,
        precision: Precision = "f32",
        backend: Backend = "cpu",
        first: int = 0,
    ) -> npt.NDArray[np.float64]:
        """Transmittance of the scene's media along each ray up to its first surface
        crossing, (N,) float64, as ``hytrace scan --transmittance``; ray i draws the
        random streams of index ``first + i``."""
    def render(
        self,
        *,
        size: Optional[Union[Tuple[int, int], str]] = None,
        spp: Optional[int] = None,
        view: Optional[str] = None,
        volumes: Optional[str] = None,
        max_bounces: Optional[int] = None,
        step: Optional[float] = None,
        seed: Optional[int] = None,
        transparent: Sequence[str] = (),
        backend: Literal["cpu", "gpu", "auto"] = "cpu",
        gpu_texels: Literal["storage", "texture"] = "storage",
        memory: Optional[int] = None,
    ) -> npt.NDArray[np.float32]:
        """Renders the scene as ``hytrace render``: (H, W, 3) float32 linear radiance."""
    @overload
    def photons(
        self,
        source: Optional[str] = None,
        photons: Optional[int] = None,
        *,
        gensteps: Optional[npt.ArrayLike] = None,
        wavelength: float | str = 420.0,
        seed: int = 0,
        max_steps: int = 10000,
        first: int = 0,
        histories: Literal[False] = False,
        memory: int = 1 << 30,
    ) -> npt.NDArray[np.float64]: ...
    @overload
    def photons(
        self,
        source: Optional[str] = None,
        photons: Optional[int] = None,
        *,
        gensteps: Optional[npt.ArrayLike] = None,
        wavelength: float | str = 420.0,
        seed: int = 0,
        max_steps: int = 10000,
        first: int = 0,
        histories: Literal[True],
        memory: int = 1 << 30,
    ) -> Tuple[npt.NDArray[np.float64], npt.NDArray[np.uint64]]: ...

class Volume:
    """One grid of a .nvdb or .vdb file or a procedural grid, in a representation."""

    def __init__(
        self,
        path: Union[str, "os.PathLike[str]"],
        *,
        grid: Optional[str] = None,
        repr: Literal["nanovdb", "source", "bc4", "unorm8", "unorm16", "f16", "f32"] = "nanovdb",
    ) -> None: ...
    def info(self) -> dict[str, Any]:
        """The file's grids, as ``hytrace volume info --json``."""
    def sample(
        self,
        points: npt.ArrayLike,
        *,
        filter: Filter = "trilinear",
        space: Literal["index", "world"] = "world",
        seed: int = 0,
        majorant: Optional[int] = None,
    ) -> npt.NDArray[np.float32]:
        """Lookups at (N, 3) points, (N,) float32, as ``hytrace volume sample``."""
