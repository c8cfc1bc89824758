"""Scenes from numpy arrays, inside and outside, lengths inside: exact against the
analytic answers of a cube."""

import numpy as np
import pytest

import octrace
from conftest import cube_arrays


@pytest.fixture(scope="module")
def cube():
    v, t = cube_arrays()
    return octrace.Scene.from_arrays(v, t)


def test_from_arrays_hits_the_triangle_it_names():
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 2], [1, 0, 2], [0, 1, 2]], np.float64)
    scene = octrace.Scene.from_arrays(v, np.array([[3, 4, 5], [0, 1, 2]], np.int32))
    ans = scene.cast_rays(np.array([[0.25, 0.25, -1, 0, 0, 1], [0.25, 0.25, 5, 0, 0, -1],
                                    [2, 2, -1, 0, 0, 1]], np.float32))
    np.testing.assert_array_equal(ans["t_hit"], [1, 3, np.inf])
    np.testing.assert_array_equal(ans["primitive_ids"], [1, 0, octrace.INVALID_ID])
    np.testing.assert_allclose(ans["primitive_uvs"][:2], [[0.25, 0.25], [0.25, 0.25]])
    np.testing.assert_array_equal(ans["primitive_normals"][:2], [[0, 0, 1], [0, 0, 1]])
    every = scene.list_intersections(np.array([[0.25, 0.25, -1, 0, 0, 1]], np.float32))
    np.testing.assert_array_equal(every["t_hit"], [1, 3])
    np.testing.assert_array_equal(every["primitive_ids"], [1, 0])
    np.testing.assert_array_equal(every["enters"], [False, False])  # arrives on the backs (normals +z)


def test_bake_arrays_writes_the_scene_from_arrays(tmp_path):
    v, t = cube_arrays()
    summary = octrace.bake_arrays(v, t, tmp_path / "cube.oct")
    assert summary["triangles"] == 12 and summary["bytes"] == (tmp_path / "cube.oct").stat().st_size
    scene = octrace.Scene(tmp_path / "cube.oct")
    assert scene.is_closed and scene.inspect() == octrace.Scene.from_arrays(v, t).inspect() | {
        "bytes_on_disk": summary["bytes"]}


def test_occupancy_is_exact(cube):
    rng = np.random.default_rng(7)
    points = rng.uniform(-0.5, 1.5, (20_000, 3)).astype(np.float32)
    # Points a few ulps either side of the faces.
    near = rng.uniform(0.1, 0.9, (2_000, 3)).astype(np.float32)
    near[:1000, 0] = np.nextafter(np.float32(1), np.float32(2))
    near[1000:, 0] = np.nextafter(np.float32(1), np.float32(0))
    points = np.concatenate([points, near])
    truth = ((points > 0) & (points < 1)).all(axis=1)
    occupancy = cube.compute_occupancy(points)
    assert occupancy.dtype == np.float32
    np.testing.assert_array_equal(occupancy, truth.astype(np.float32))
    np.testing.assert_array_equal(cube.contains(points), truth)
    np.testing.assert_array_equal(cube.contains(points, nthreads=1), truth)
    assert cube.contains(points.reshape(-1, 2, 3)).shape == (len(points) // 2, 2)


def test_length_inside(cube):
    rays = np.array([[0.5, 0.5, -1, 0, 0, 1], [0.5, 0.5, -1, 0, 0, 2], [0.5, 0.5, 0.5, 1, 0, 0],
                     [2, 2, 2, 1, 0, 0]], np.float32)
    np.testing.assert_array_equal(cube.length_inside(rays), [1, 0.5, 0.5, 0])
    np.testing.assert_array_equal(cube.length_inside(rays, tmax=1.5), [0.5, 0.5, 0.5, 0])
    counts = cube.count_intersections(rays)
    np.testing.assert_array_equal(counts, [2, 2, 1, 0])


def test_open_meshes_have_no_inside(bunny):
    with pytest.raises(octrace.NotClosedError, match="not closed"):
        bunny.compute_occupancy(np.zeros((1, 3), np.float32))
    with pytest.raises(ValueError):
        bunny.length_inside(np.zeros((1, 6), np.float32))


def test_pinhole_rays_are_open3ds():
    # Open3D 0.20's create_rays_pinhole, recorded for these arguments.
    rays = octrace.Scene.create_rays_pinhole(fov_deg=90, center=[1, 0, 0], eye=[0, 0, 0], up=[0, 0, 1],
                                             width_px=2, height_px=2)
    assert rays.shape == (2, 2, 6) and rays.dtype == np.float32
    np.testing.assert_array_equal(rays[..., 3:].reshape(-1, 3),
                                  [[1, -0.5, -0.5], [1, 0.5, -0.5], [1, -0.5, 0.5], [1, 0.5, 0.5]])
    rays = octrace.Scene.create_rays_pinhole(60, [0.5, 0.5, 0.5], [-1, -1, -1], [0, 0, 1], 4, 3)
    np.testing.assert_allclose(rays[0, 0], [-1, -1, -1, 1.0013876, 0.38901517, 0.341648], rtol=1e-6)
    np.testing.assert_allclose(rays[2, 3], [-1, -1, -1, 0.15331292, 0.7656853, 0.81305254], rtol=1e-6)
    k = np.array([[100, 0, 50], [0, 100, 40], [0, 0, 1.0]])
    e = np.eye(4)
    e[:3, 3] = [1, 2, 3]
    rays = octrace.Scene.create_rays_pinhole(intrinsic_matrix=k, extrinsic_matrix=e, width_px=100, height_px=80)
    assert rays.shape == (80, 100, 6)
    np.testing.assert_allclose(rays[0, 0], [-1, -2, -3, -0.495, -0.395, 1], rtol=1e-6)
    np.testing.assert_allclose(rays[79, 99], [-1, -2, -3, 0.495, 0.395, 1], rtol=1e-6)
    with pytest.raises(ValueError, match="missing"):
        octrace.Scene.create_rays_pinhole(fov_deg=60, center=[0, 0, 0], eye=[0, 0, 1], up=[0, 1, 0], width_px=4)
    with pytest.raises(ValueError, match="parallel"):
        octrace.Scene.create_rays_pinhole(60, [0, 0, 0], [0, 0, 1], [0, 0, 1], 4, 4)
