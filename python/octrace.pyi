"""Type stubs of octrace's Python module (the docstrings are in the module itself:
``help(octrace.Scene)``)."""

from os import PathLike
from typing import Any, Optional, Sequence, Union, overload

import numpy as np
import numpy.typing as npt

__version__: str
INVALID_ID: int
"""The id of "no triangle" and "no part" in the returned arrays (0xFFFFFFFF)."""
HAS_GPU: bool
"""Whether the module was built with the GPU (``Scene(..., device="gpu")``)."""

_Path = Union[str, PathLike]
_Rays = Union[npt.NDArray[np.float32], Sequence[Sequence[float]]]
_Points = Union[npt.NDArray[np.float32], Sequence[Sequence[float]]]

class FormatError(ValueError):
    """A file that is not a valid octrace scene."""

class BakeError(ValueError):
    """A mesh that cannot be baked; the message names the file and where."""

class NotClosedError(ValueError):
    """A query that needs an inside, on a scene that is not closed."""

class GpuError(RuntimeError):
    """The GPU cannot serve a scene opened with ``device="gpu"`` (the message says why)."""

def bake(
    mesh: _Path,
    output: _Path,
    *,
    max_depth: Optional[int] = None,
    leaf_size: int = 16,
    margin: float = 2**-20,
    threads: int = 0,
    allow_outside_references: bool = False,
    max_memory: Optional[int] = None,
    max_instances: int = 2**20,
    max_triangles: int = 2**27,
    distance: bool = False,
    compress: bool = False,
    level: int = 3,
    record_time: bool = False,
) -> dict[str, Any]: ...
def bake_arrays(
    vertices: npt.ArrayLike,
    triangles: npt.ArrayLike,
    output: _Path,
    *,
    max_depth: Optional[int] = None,
    leaf_size: int = 16,
    margin: float = 2**-20,
    threads: int = 0,
    max_memory: Optional[int] = None,
    distance: bool = False,
    compress: bool = False,
    level: int = 3,
) -> dict[str, Any]: ...

class Scene:
    def __init__(
        self, path: _Path, *, mmap: bool = False, trusted: bool = False, device: str = "cpu"
    ) -> None: ...
    @staticmethod
    def from_arrays(
        vertices: npt.ArrayLike,
        triangles: npt.ArrayLike,
        *,
        max_depth: Optional[int] = None,
        leaf_size: int = 16,
        margin: float = 2**-20,
        threads: int = 0,
        max_memory: Optional[int] = None,
        device: str = "cpu",
    ) -> "Scene": ...
    @property
    def device(self) -> str: ...
    @property
    def adapter(self) -> str: ...
    @property
    def triangle_count(self) -> int: ...
    @property
    def parts(self) -> list[dict[str, Any]]: ...
    @property
    def bounds(self) -> tuple[list[float], list[float]]: ...
    @property
    def materials(self) -> list[dict[str, Any]]: ...
    @property
    def is_closed(self) -> bool: ...
    def inspect(self) -> dict[str, Any]: ...
    def cast_rays(self, rays: _Rays, nthreads: int = 0, *, surface: bool = False) -> dict[str, np.ndarray]: ...
    def test_occlusions(
        self, rays: _Rays, tnear: float = 0.0, tfar: float = float("inf"), nthreads: int = 0
    ) -> npt.NDArray[np.bool_]: ...
    def count_intersections(self, rays: _Rays, nthreads: int = 0) -> npt.NDArray[np.int32]: ...
    def list_intersections(
        self, rays: _Rays, nthreads: int = 0, *, max_hits: Optional[int] = None, max_memory: Optional[int] = None
    ) -> dict[str, np.ndarray]: ...
    def compute_occupancy(
        self, query_points: _Points, nthreads: int = 0, nsamples: Optional[int] = None
    ) -> npt.NDArray[np.float32]: ...
    def compute_closest_points(
        self, query_points: _Points, nthreads: int = 0, *, max_distance: float = float("inf")
    ) -> dict[str, np.ndarray]: ...
    def compute_distance(
        self, query_points: _Points, nthreads: int = 0, *, max_distance: float = float("inf")
    ) -> npt.NDArray[np.float32]: ...
    def compute_signed_distance(
        self,
        query_points: _Points,
        nthreads: int = 0,
        nsamples: Optional[int] = None,
        *,
        max_distance: float = float("inf"),
    ) -> npt.NDArray[np.float32]: ...
    def winding_number(
        self, query_points: _Points, nthreads: int = 0, *, tolerance: Optional[float] = None
    ) -> npt.NDArray[np.float64]: ...
    def contains(self, query_points: _Points, nthreads: int = 0) -> npt.NDArray[np.bool_]: ...
    def contains_by_vote(
        self, query_points: _Points, nsamples: int = 3, nthreads: int = 0
    ) -> npt.NDArray[np.bool_]: ...
    def length_inside(self, rays: _Rays, tmax: float = float("inf"), nthreads: int = 0) -> npt.NDArray[np.float32]: ...
    @overload
    @staticmethod
    def create_rays_pinhole(
        fov_deg: float,
        center: npt.ArrayLike,
        eye: npt.ArrayLike,
        up: npt.ArrayLike,
        width_px: int,
        height_px: int,
    ) -> npt.NDArray[np.float32]: ...
    @overload
    @staticmethod
    def create_rays_pinhole(
        intrinsic_matrix: npt.ArrayLike,
        extrinsic_matrix: npt.ArrayLike,
        width_px: int,
        height_px: int,
    ) -> npt.NDArray[np.float32]: ...

class World:
    """Scenes placed by transforms (4x4 or 3x4, local to world) and traced as one;
    edits are seen after ``commit()``. ``geometry_ids`` are the instances' ids.
    ``device="gpu"``: the ray queries with the instances' walks on the GPU."""
    def __init__(self, *, device: str = "cpu") -> None: ...
    @staticmethod
    def open(path: _Path, *, device: str = "cpu") -> World:
        """The world an instanced file places (a glTF's meshes placed many times,
        baked once each by ``octrace bake``)."""
        ...
    @property
    def device(self) -> str: ...
    def add(self, scene: Union[Scene, _Path], transform: Optional[npt.ArrayLike] = None) -> int: ...
    def add_triangles(
        self,
        vertex_positions: npt.ArrayLike,
        triangle_indices: npt.ArrayLike,
        transform: Optional[npt.ArrayLike] = None,
    ) -> int: ...
    def set_transform(self, id: int, transform: npt.ArrayLike) -> None: ...
    def remove(self, id: int) -> None: ...
    def commit(self) -> None: ...
    def transform(self, id: int) -> npt.NDArray[np.float64]: ...
    def __len__(self) -> int: ...
    def cast_rays(self, rays: _Rays, nthreads: int = 0) -> dict[str, np.ndarray]: ...
    def test_occlusions(
        self, rays: _Rays, tnear: float = 0.0, tfar: float = float("inf"), nthreads: int = 0
    ) -> npt.NDArray[np.bool_]: ...
    def count_intersections(self, rays: _Rays, nthreads: int = 0) -> npt.NDArray[np.int32]: ...
    def list_intersections(
        self, rays: _Rays, nthreads: int = 0, max_hits: Optional[int] = None, max_memory: Optional[int] = None
    ) -> dict[str, np.ndarray]: ...
    def compute_occupancy(self, query_points: _Points, nthreads: int = 0) -> npt.NDArray[np.float32]: ...
    def compute_closest_points(
        self, query_points: _Points, nthreads: int = 0, *, max_distance: float = float("inf")
    ) -> dict[str, np.ndarray]: ...
    def compute_distance(
        self, query_points: _Points, nthreads: int = 0, *, max_distance: float = float("inf")
    ) -> npt.NDArray[np.float32]: ...
    def compute_signed_distance(
        self, query_points: _Points, nthreads: int = 0, *, max_distance: float = float("inf")
    ) -> npt.NDArray[np.float32]: ...

class Tensor(np.ndarray):
    """What RaycastingScene answers: numpy arrays that also have Open3D's ``numpy()``."""
    def numpy(self) -> np.ndarray: ...

class RaycastingScene:
    """Open3D's ``open3d.t.geometry.RaycastingScene`` on octrace: meshes added, baked
    in memory at the first query after an addition; ``geometry_ids`` name the
    additions, ``primitive_ids`` triangles within each."""

    INVALID_ID: int
    def __init__(self, nthreads: int = 0) -> None: ...
    @overload
    def add_triangles(self, vertex_positions: npt.ArrayLike, triangle_indices: npt.ArrayLike) -> int: ...
    @overload
    def add_triangles(self, mesh: Any) -> int: ...
    def cast_rays(self, rays: _Rays, nthreads: int = 0) -> dict[str, Tensor]: ...
    def test_occlusions(
        self, rays: _Rays, tnear: float = 0.0, tfar: float = float("inf"), nthreads: int = 0
    ) -> Tensor: ...
    def count_intersections(self, rays: _Rays, nthreads: int = 0) -> Tensor: ...
    def list_intersections(self, rays: _Rays, nthreads: int = 0) -> dict[str, Tensor]: ...
    def compute_occupancy(self, query_points: _Points, nthreads: int = 0, nsamples: int = 1) -> Tensor: ...
    def compute_closest_points(self, query_points: _Points, nthreads: int = 0) -> dict[str, Tensor]: ...
    def compute_distance(self, query_points: _Points, nthreads: int = 0) -> Tensor: ...
    def winding_number(self, query_points: _Points, nthreads: int = 0, tolerance: Optional[float] = None) -> Tensor: ...
    def compute_signed_distance(self, query_points: _Points, nthreads: int = 0, nsamples: int = 1) -> Tensor: ...
    @staticmethod
    def create_rays_pinhole(*args: Any, **kwargs: Any) -> Tensor: ...
