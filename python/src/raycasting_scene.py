"""``octrace.RaycastingScene``: Open3D's ``open3d.t.geometry.RaycastingScene`` on octrace,
so that code written for Open3D runs with ``octrace`` in its place.

Meshes are added (``add_triangles``) and baked into one scene in memory at the first
query after an addition; each addition is a geometry, whose id the answers'
``geometry_ids`` give, and ``primitive_ids`` count triangles within their geometry, as
Open3D's do. Answers are numpy arrays that also have Open3D's ``.numpy()``. The
queries are ``octrace.Scene``'s: exact where Open3D's are approximate (nearest hits,
crossing counts and lists; ``compute_occupancy`` on a closed mesh), and on an open mesh
``compute_occupancy`` votes with ``nsamples`` rays as Open3D does.

This file is compiled into the extension module (``lib.rs``), which hands ``make`` its
``Scene`` type.
"""

import numpy as np


class Tensor(np.ndarray):
    """A numpy array that also answers ``.numpy()`` (the array itself, as a plain
    ``numpy.ndarray``), as the Open3D tensors that Open3D's answers are."""

    def numpy(self):
        return self.view(np.ndarray)


Tensor.__module__ = "octrace"


def _numpy(x):
    """``x`` as a numpy array: through its ``numpy()`` where it has one (an Open3D
    tensor), else ``numpy.asarray``."""
    if not isinstance(x, np.ndarray) and hasattr(x, "numpy"):
        x = x.numpy()
    return np.asarray(x)


def _tensors(answers):
    return {key: np.asarray(value).view(Tensor) for key, value in answers.items()}


def _mesh_arrays(mesh):
    """The vertex positions and triangle indices of an Open3D mesh: a tensor mesh
    (``open3d.t.geometry.TriangleMesh``: ``vertex.positions``, ``triangle.indices``) or
    a legacy one (``open3d.geometry.TriangleMesh``: ``vertices``, ``triangles``, as
    trimesh's meshes also have)."""
    if hasattr(mesh, "vertex") and hasattr(mesh, "triangle"):
        return mesh.vertex.positions, mesh.triangle.indices
    if hasattr(mesh, "vertices") and hasattr(mesh, "triangles"):
        return mesh.vertices, mesh.triangles
    raise TypeError(
        f"add_triangles: {type(mesh).__name__} is not a triangle mesh (expected vertex.positions and "
        "triangle.indices, or vertices and triangles); or pass vertex_positions and triangle_indices")


def _device(device):
    """``"cpu"`` or ``"gpu"`` from a name or an Open3D device (``CPU:0``, ``CUDA:0``)."""
    if device is None:
        return "cpu"
    name = str(device).split(":")[0].strip().lower()
    if name in ("cpu", "gpu"):
        return name
    if name in ("cuda", "sycl"):
        return "gpu"
    raise ValueError(f"device: {device!r}, expected 'cpu' or 'gpu' (or Open3D's CPU:0, CUDA:0, SYCL:0)")


def make(Scene, invalid_id):
    """The ``RaycastingScene`` class over the extension's ``Scene``."""

    class RaycastingScene:
        """Open3D's ``RaycastingScene`` on octrace: add meshes, then ask the same
        queries under the same names, with the same shapes, dtypes and ids.

        Example::

            scene = octrace.RaycastingScene()
            cube_id = scene.add_triangles(vertices, triangles)   # or an Open3D mesh
            rays = np.array([[0.5, 0.5, 10, 0, 0, -1]], np.float32)
            ans = scene.cast_rays(rays)
            ans["t_hit"].numpy()    # [9.] for the unit cube
        """

        INVALID_ID = invalid_id

        def __init__(self, nthreads=0, device=None):
            """``device``: where the ray queries run, ``"cpu"`` (the default) or
            ``"gpu"`` (``octrace.Scene``'s ``device``); Open3D's devices are taken too,
            ``CPU:0`` for the CPU and ``CUDA:0``/``SYCL:0`` for the GPU."""
            self._nthreads = nthreads
            self._device = _device(device)
            self._vertices = []
            self._triangles = []
            self._scene = None
            self._first = np.zeros(1, np.int64)

        def add_triangles(self, vertex_positions, triangle_indices=None):
            """Adds a mesh, given as ``vertex_positions`` ``(n, 3)`` and
            ``triangle_indices`` ``(m, 3)``, or as an Open3D (or trimesh) mesh; returns
            its geometry id (0 for the first, then 1, ...)."""
            if triangle_indices is None:
                vertex_positions, triangle_indices = _mesh_arrays(vertex_positions)
            vertices = _numpy(vertex_positions)
            triangles = _numpy(triangle_indices)
            if vertices.ndim != 2 or vertices.shape[1] != 3:
                raise ValueError(f"vertex_positions: shape {vertices.shape}, expected (n, 3)")
            if triangles.ndim != 2 or triangles.shape[1] != 3 or triangles.dtype.kind not in "iu":
                raise ValueError(
                    f"triangle_indices: shape {triangles.shape}, dtype {triangles.dtype}; expected (m, 3) integers")
            if triangles.size and (triangles.min() < 0 or triangles.max() >= len(vertices)):
                raise ValueError(
                    f"triangle_indices: indices from {triangles.min()} to {triangles.max()}, "
                    f"outside the {len(vertices)} vertices")
            self._vertices.append(vertices.astype(np.float32))
            self._triangles.append(triangles.astype(np.int64))
            self._scene = None
            return len(self._triangles) - 1

        def __getstate__(self):
            # The meshes pickle; the scene baked from them is baked again where needed.
            state = self.__dict__.copy()
            state["_scene"] = None
            return state

        def _built(self):
            if self._scene is None:
                if not self._triangles:
                    raise ValueError("the scene is empty: add_triangles first")
                offsets = np.cumsum([0] + [len(v) for v in self._vertices])
                triangles = np.concatenate([t + o for t, o in zip(self._triangles, offsets)])
                self._scene = Scene.from_arrays(np.concatenate(self._vertices), triangles, threads=self._nthreads,
                                                 device=getattr(self, "_device", "cpu"))
                self._first = np.cumsum([0] + [len(t) for t in self._triangles])
            return self._scene

        def _ids(self, answers):
            """Rewrites the scene's triangle ids into (geometry, triangle within it)."""
            ids = answers["primitive_ids"]
            hit = ids != invalid_id
            geometry = np.full_like(ids, invalid_id)
            geometry[hit] = np.searchsorted(self._first, ids[hit], side="right") - 1
            local = ids.copy()
            local[hit] -= self._first[geometry[hit]].astype(ids.dtype)
            answers["geometry_ids"] = geometry
            answers["primitive_ids"] = local
            return _tensors(answers)

        def cast_rays(self, rays, nthreads=0):
            """The nearest hit of each ray: ``octrace.Scene.cast_rays``, with the
            geometry's id and the triangle's index within it."""
            return self._ids(self._built().cast_rays(rays, nthreads))

        def test_occlusions(self, rays, tnear=0.0, tfar=float("inf"), nthreads=0):
            """Whether anything lies on each ray in ``[tnear, tfar]``."""
            return self._built().test_occlusions(rays, tnear, tfar, nthreads).view(Tensor)

        def count_intersections(self, rays, nthreads=0):
            """How many times each ray crosses the scene (each crossing once)."""
            return self._built().count_intersections(rays, nthreads).view(Tensor)

        def list_intersections(self, rays, nthreads=0):
            """Every crossing of each ray, in order along it."""
            return self._ids(self._built().list_intersections(rays, nthreads))

        def compute_occupancy(self, query_points, nthreads=0, nsamples=1):
            """1.0 inside, 0.0 outside: exact on a closed mesh; on an open one the vote
            of ``nsamples`` rays (odd), as Open3D answers."""
            return self._built().compute_occupancy(query_points, nthreads, nsamples).view(Tensor)

        def compute_closest_points(self, query_points, nthreads=0):
            """The nearest point of the scene to each point, exact: ``points``,
            ``geometry_ids``, ``primitive_ids`` (within the geometry),
            ``primitive_uvs``, ``primitive_normals``."""
            return self._ids(self._built().compute_closest_points(query_points, nthreads))

        def compute_distance(self, query_points, nthreads=0):
            """The distance from each point to the scene, exact (correctly rounded)."""
            return self._built().compute_distance(query_points, nthreads).view(Tensor)

        def compute_signed_distance(self, query_points, nthreads=0, nsamples=1):
            """The distance, negative inside: the sign exact on a closed mesh; on an
            open one the vote of ``nsamples`` rays (odd), as Open3D signs."""
            return self._built().compute_signed_distance(query_points, nthreads, nsamples).view(Tensor)

        def winding_number(self, query_points, nthreads=0, tolerance=None):
            """The generalized winding number of each point (not in Open3D):
            ``octrace.Scene.winding_number``."""
            return self._built().winding_number(query_points, nthreads, tolerance=tolerance).view(Tensor)

        @staticmethod
        def create_rays_pinhole(*args, **kwargs):
            """Rays of a pinhole camera: ``octrace.Scene.create_rays_pinhole``, Open3D's
            two forms and conventions."""
            return Scene.create_rays_pinhole(*args, **kwargs).view(Tensor)

    RaycastingScene.__module__ = "octrace"
    RaycastingScene.__qualname__ = "RaycastingScene"
    return RaycastingScene
