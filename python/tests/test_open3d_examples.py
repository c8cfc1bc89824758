"""Open3D's RaycastingScene examples, from its documentation (the class's page, the
ray casting tutorial, occupancy on an open mesh with nsamples), with ``octrace`` in
Open3D's place: the same code runs and gives Open3D's answers. Open3D's meshes and
tensors are stood in for by the attributes the code reads from them."""

from types import SimpleNamespace

import numpy as np
import pytest

import octrace
from conftest import Tensor, cube_arrays


def tensor_mesh(vertices, triangles):
    """An ``open3d.t.geometry.TriangleMesh``: ``vertex.positions``, ``triangle.indices``."""
    return SimpleNamespace(vertex=SimpleNamespace(positions=Tensor(np.asarray(vertices, np.float32))),
                           triangle=SimpleNamespace(indices=Tensor(np.asarray(triangles, np.int64))))


def legacy_mesh(vertices, triangles):
    """An ``open3d.geometry.TriangleMesh``: ``vertices``, ``triangles`` (vectors)."""
    return SimpleNamespace(vertices=[list(map(float, v)) for v in vertices],
                           triangles=[list(map(int, t)) for t in triangles])


def box_hits(rays, lo=0.0, hi=1.0):
    """The exact (f64) entry distance of each ray into the box, inf where it misses."""
    o, d = rays[..., :3].astype(np.float64), rays[..., 3:].astype(np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        t0, t1 = (lo - o) / d, (hi - o) / d
    near = np.nanmax(np.minimum(t0, t1), axis=-1)
    far = np.nanmin(np.maximum(t0, t1), axis=-1)
    return np.where((near <= far) & (far >= 0), np.maximum(near, 0), np.inf)


def test_the_class_pages_example():
    # open3d.t.geometry.RaycastingScene's page: a box, a pinhole camera, the depth.
    cube = tensor_mesh(*cube_arrays())
    scene = octrace.RaycastingScene()
    scene.add_triangles(cube)
    rays = scene.create_rays_pinhole(fov_deg=60, center=[0.5, 0.5, 0.5], eye=[-1, -1, -1], up=[0, 0, 1],
                                     width_px=320, height_px=240)
    ans = scene.cast_rays(rays)
    depth = ans["t_hit"].numpy()
    assert type(depth) is np.ndarray and depth.shape == (240, 320) and depth.dtype == np.float32
    want = box_hits(rays.numpy())
    hit = np.isfinite(want)
    assert 0.2 < hit.mean() < 0.9
    np.testing.assert_array_equal(np.isfinite(depth), hit)
    np.testing.assert_allclose(depth[hit], want[hit], rtol=1e-6)


def test_the_ray_casting_tutorial():
    # Open3D's "Ray Casting" tutorial: the box's id, two rays, the answers it prints.
    cube = legacy_mesh(*cube_arrays())
    scene = octrace.RaycastingScene()
    cube_id = scene.add_triangles(cube)
    assert cube_id == 0
    rays = np.array([[0.5, 0.5, 10, 0, 0, -1], [-1, -1, -1, 0, 0, -1]], np.float32)
    ans = scene.cast_rays(rays)
    assert sorted(ans) == ["geometry_ids", "primitive_ids", "primitive_normals", "primitive_uvs", "t_hit"]
    np.testing.assert_array_equal(ans["t_hit"].numpy(), [9, np.inf])
    np.testing.assert_array_equal(ans["geometry_ids"].numpy(), [0, scene.INVALID_ID])
    np.testing.assert_array_equal(ans["primitive_normals"].numpy()[0], [0, 0, 1])
    assert ans["primitive_ids"].numpy()[0] < 12
    # More geometries: ids in the order added, triangles counted within each.
    far_cube = scene.add_triangles(*[Tensor(a) for a in cube_arrays(5.0, 6.0)])
    assert far_cube == 1
    rays = np.array([[0.5, 0.5, 10, 0, 0, -1], [5.5, 5.5, 10, 0, 0, -1]], np.float32)
    ans = scene.cast_rays(rays)
    np.testing.assert_array_equal(ans["geometry_ids"].numpy(), [0, 1])
    np.testing.assert_array_equal(ans["t_hit"].numpy(), [9, 4])
    assert (ans["primitive_ids"].numpy() < 12).all()
    np.testing.assert_array_equal(ans["primitive_ids"].numpy()[0], ans["primitive_ids"].numpy()[1])
    np.testing.assert_array_equal(scene.test_occlusions(rays).numpy(), [True, True])
    np.testing.assert_array_equal(scene.count_intersections(rays).numpy(), [2, 2])
    lists = scene.list_intersections(rays)
    np.testing.assert_array_equal(lists["ray_splits"].numpy(), [0, 2, 4])
    np.testing.assert_array_equal(lists["geometry_ids"].numpy(), [0, 0, 1, 1])
    np.testing.assert_array_equal(lists["t_hit"].numpy(), [9, 10, 4, 5])


def sphere(n=24, m=48):
    """A closed UV sphere of radius 1, wound outward."""
    theta = np.linspace(0, np.pi, n + 1)[1:-1]
    phi = np.linspace(0, 2 * np.pi, m, endpoint=False)
    ring = np.stack([np.outer(np.sin(theta), np.cos(phi)), np.outer(np.sin(theta), np.sin(phi)),
                     np.outer(np.cos(theta), np.ones(m))], -1).reshape(-1, 3)
    v = np.vstack([[0, 0, 1], ring, [0, 0, -1]]).astype(np.float32)
    at = lambda i, j: 1 + i * m + j % m  # noqa: E731
    t = [[0, at(0, j), at(0, j + 1)] for j in range(m)]
    for i in range(n - 2):
        for j in range(m):
            t += [[at(i, j), at(i + 1, j), at(i + 1, j + 1)], [at(i, j), at(i + 1, j + 1), at(i, j + 1)]]
    t += [[len(v) - 1, at(n - 2, j + 1), at(n - 2, j)] for j in range(m)]
    return v, np.array(t)


def test_occupancy_on_an_open_mesh_with_nsamples():
    # Open3D's occupancy (its distance queries tutorial) on a mesh that is not closed:
    # a sphere with a cap of triangles missing. Open3D votes with nsamples rays; so
    # does octrace, and agrees with the closed sphere's exact answer away from the
    # hole, as Open3D's vote does (within its documented approximation: a ray that
    # leaves through the hole counts wrong).
    v, t = sphere()
    closed = octrace.RaycastingScene()
    closed.add_triangles(v, t)
    scene = octrace.RaycastingScene()
    scene.add_triangles(v, t[48:])   # the cap round the north pole left out
    rng = np.random.default_rng(3)
    query_points = rng.uniform(-1.3, 1.3, (4000, 3)).astype(np.float32)
    exact = closed.compute_occupancy(query_points).numpy()
    with pytest.raises(octrace.NotClosedError):
        octrace.Scene.from_arrays(v, t[48:]).compute_occupancy(query_points)
    occupancy = scene.compute_occupancy(query_points, nsamples=3).numpy()
    assert occupancy.dtype == np.float32 and occupancy.shape == (4000,)
    assert 0.2 < exact.mean() < 0.4
    assert (occupancy != exact).mean() < 0.02
    np.testing.assert_array_equal(
        scene.compute_occupancy(query_points, nsamples=3), octrace.Scene.from_arrays(v, t[48:]).contains_by_vote(
            query_points, nsamples=3).astype(np.float32))


def test_bad_meshes_are_named():
    scene = octrace.RaycastingScene()
    with pytest.raises(TypeError, match="add_triangles: str is not a triangle mesh"):
        scene.add_triangles("cube.obj")
    with pytest.raises(ValueError, match=r"indices from 0 to 8, outside the 8 vertices"):
        scene.add_triangles(cube_arrays()[0], [[0, 1, 8]])
    with pytest.raises(ValueError, match="the scene is empty: add_triangles first"):
        scene.cast_rays(np.zeros((1, 6), np.float32))


def test_the_class_reads_as_octraces():
    assert repr(octrace.RaycastingScene) == "<class 'octrace.RaycastingScene'>"
    assert octrace.RaycastingScene.INVALID_ID == octrace.INVALID_ID
    scene = octrace.RaycastingScene()
    scene.add_triangles(*cube_arrays())
    ans = scene.cast_rays(np.array([[0.5, 0.5, 10, 0, 0, -1]], np.float32))
    assert isinstance(ans["t_hit"], octrace.Tensor) and isinstance(ans["t_hit"], np.ndarray)
