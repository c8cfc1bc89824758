"""Closest points, distances and signed distances (Open3D's compute_closest_points,
compute_distance, compute_signed_distance): against the analytic answers of a box,
computed here in float64, and their limits, shapes and errors."""

import numpy as np
import pytest

import octrace
from conftest import cube_arrays

LO, HI = np.array([-1.0, 0.0, 0.5]), np.array([1.0, 2.0, 1.5])


@pytest.fixture(scope="module")
def box():
    v, t = cube_arrays()
    return octrace.Scene.from_arrays(LO + v * (HI - LO), t)


def box_distance(p):
    """The float64 distance from each point to the box's surface, negative inside."""
    outside = np.linalg.norm(np.maximum(np.maximum(LO - p, p - HI), 0.0), axis=-1)
    inside = np.minimum(p - LO, HI - p).min(axis=-1)
    return np.where(outside > 0, outside, -np.maximum(inside, 0.0))


@pytest.fixture(scope="module")
def points():
    rng = np.random.default_rng(5)
    uniform = rng.uniform(LO - 1.0, HI + 1.0, (4000, 3))
    # On faces, edges and corners, and a hair off them.
    corners = np.array([[x, y, z] for x in (LO[0], HI[0]) for y in (LO[1], HI[1]) for z in (LO[2], HI[2])])
    hair = corners + rng.normal(0.0, 1e-5, corners.shape)
    return np.concatenate([uniform, corners, hair]).astype(np.float32)


def test_distances_are_the_exact_distances_rounded(box, points):
    d = box.compute_distance(points)
    assert d.dtype == np.float32 and d.shape == (len(points),)
    exact = np.abs(box_distance(points.astype(np.float64)))
    # One float32 rounding of the float64 value (which is itself within 1e-16 of exact).
    np.testing.assert_array_equal(d, exact.astype(np.float32))


def test_signed_distances_are_negative_inside(box, points):
    s = box.compute_signed_distance(points)
    np.testing.assert_array_equal(s, box_distance(points.astype(np.float64)).astype(np.float32))
    assert (s < 0).any() and (s > 0).any()
    np.testing.assert_array_equal(np.sign(s[s != 0]) < 0, box.contains(points)[s != 0])


def test_closest_points_lie_on_the_box_at_the_distance(box, points):
    ans = box.compute_closest_points(points)
    assert set(ans) == {"points", "geometry_ids", "primitive_ids", "primitive_uvs", "primitive_normals"}
    q = ans["points"].astype(np.float64)
    outside = box_distance(points.astype(np.float64)) > 0
    # Outside a box the nearest point is the point clamped to it.
    np.testing.assert_allclose(q[outside], np.clip(points[outside], LO, HI), atol=1e-6)
    np.testing.assert_allclose(np.linalg.norm(q - points, axis=-1), box.compute_distance(points), atol=1e-6)
    assert (ans["geometry_ids"] == 0).all()
    assert (ans["primitive_ids"] < 12).all()
    # The normal is the face's: an axis, and the point lies on that face's plane.
    n = ans["primitive_normals"]
    np.testing.assert_array_equal(np.abs(n).sum(axis=-1), 1.0)
    axis = np.abs(n).argmax(axis=-1)
    plane = np.where(n[np.arange(len(n)), axis] > 0, HI[axis], LO[axis])
    np.testing.assert_allclose(q[np.arange(len(q)), axis], plane, atol=1e-6)
    uv = ans["primitive_uvs"]
    assert ((uv >= 0) & (uv.sum(axis=-1, keepdims=True) <= 1 + 1e-6)).all()


def test_max_distance_bounds_the_answers(box):
    p = np.array([[0, 1, 1], [0, 1, 3], [0, 1, 30], [5, 5, 5]], np.float32)
    d = box.compute_distance(p, max_distance=2.0)
    np.testing.assert_array_equal(d, [0.5, 1.5, np.inf, np.inf])
    np.testing.assert_array_equal(box.compute_signed_distance(p, max_distance=2.0), [-0.5, 1.5, np.inf, np.inf])
    ans = box.compute_closest_points(p, max_distance=2.0)
    assert np.isnan(ans["points"][2:]).all()
    np.testing.assert_array_equal(ans["primitive_ids"][2:], octrace.INVALID_ID)
    np.testing.assert_array_equal(ans["geometry_ids"][2:], octrace.INVALID_ID)
    for bad in (-1.0, np.nan):
        with pytest.raises(ValueError, match="max_distance"):
            box.compute_distance(p, max_distance=bad)


def test_shapes_threads_and_bad_points(box, points):
    grid = points[:60].reshape(3, 4, 5, 3)
    assert box.compute_distance(grid).shape == (3, 4, 5)
    assert box.compute_signed_distance(grid).shape == (3, 4, 5)
    ans = box.compute_closest_points(grid)
    assert ans["points"].shape == (3, 4, 5, 3) and ans["primitive_uvs"].shape == (3, 4, 5, 2)
    np.testing.assert_array_equal(box.compute_distance(points, nthreads=1), box.compute_distance(points))
    with pytest.raises(ValueError, match="NaN"):
        box.compute_distance(np.array([[0, np.nan, 0]], np.float32))
    with pytest.raises(ValueError):
        box.compute_distance(np.zeros((4, 2), np.float32))


def test_an_open_mesh_signs_by_its_winding_number_or_a_vote():
    v, t = cube_arrays()
    opened = octrace.Scene.from_arrays(v, t[1:])  # one triangle gone
    p = np.array([[0.5, 0.5, 0.5], [0.5, 0.5, 3.0]], np.float32)
    np.testing.assert_array_equal(opened.compute_distance(p), [0.5, 2.0])
    np.testing.assert_array_equal(opened.compute_signed_distance(p), [-0.5, 2.0])
    np.testing.assert_array_equal(opened.compute_signed_distance(p, nsamples=5), [-0.5, 2.0])
    # Half a triangle of the cube's twelve gone: 1 - 1/12 of the sphere at the centre.
    w = opened.winding_number(p[:1], tolerance=1e-9)
    assert abs(w[0] - (1 - 1 / 12)) <= 1e-9


def test_winding_numbers_exact_on_closed_meshes_and_bounded_on_open_ones():
    v, t = cube_arrays()
    box = octrace.Scene.from_arrays(v, t)
    grid = np.array([[[0.5, 0.5, 0.5], [2.0, 0.5, 0.5]], [[0.1, 0.9, 0.2], [-1.0, -1.0, -1.0]]], np.float32)
    w = box.winding_number(grid)
    assert w.shape == (2, 2) and w.dtype == np.float64
    np.testing.assert_array_equal(w, [[1.0, 0.0], [1.0, 0.0]])
    # Open: a square seen from above its centre, 4 asin(s^2 / (s^2 + 4 h^2)) / 4 pi.
    sq = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], np.float32)
    sheet = octrace.Scene.from_arrays(sq, np.array([[0, 1, 2], [0, 2, 3]], np.uint32))
    h = float(np.float32(0.3))  # as the query holds it
    want = -4 * np.arcsin(1 / (1 + 4 * h * h)) / (4 * np.pi)
    got = sheet.winding_number(np.array([[0.5, 0.5, h]], np.float32), tolerance=1e-12)
    assert abs(got[0] - want) <= 1e-12
    assert abs(sheet.winding_number(np.array([[0.5, 0.5, h]], np.float32))[0] - want) < 1e-2
    with pytest.raises(ValueError, match="tolerance"):
        sheet.winding_number(grid, tolerance=-1.0)
    rc = octrace.RaycastingScene()
    rc.add_triangles(v, t)
    np.testing.assert_array_equal(rc.winding_number(grid).numpy(), w)


def test_raycasting_scene_answers_by_geometry():
    scene = octrace.RaycastingScene()
    v, t = cube_arrays()
    scene.add_triangles(v, t)
    scene.add_triangles(v + np.float32(3.0), t)
    p = np.array([[0.5, 0.5, 1.25], [3.5, 3.5, 4.5], [2.0, 2.0, 2.0]], np.float32)
    ans = scene.compute_closest_points(p)
    np.testing.assert_array_equal(ans["geometry_ids"].numpy(), [0, 1, 0])
    assert (ans["primitive_ids"].numpy() < 12).all()
    np.testing.assert_allclose(scene.compute_distance(p).numpy(), [0.25, 0.5, np.sqrt(3.0)], rtol=1e-7)
    np.testing.assert_allclose(scene.compute_signed_distance(p).numpy(), [0.25, 0.5, np.sqrt(3.0)], rtol=1e-7)
    inside = np.array([[0.5, 0.5, 0.6]], np.float32)
    np.testing.assert_allclose(scene.compute_signed_distance(inside).numpy(), [-0.4], rtol=1e-6)


def test_a_file_baked_with_its_distance_tree_answers_the_same(tmp_path, points):
    v, t = cube_arrays()
    v = LO + v * (HI - LO)
    summaries = {}
    for name, distance in (("plain", False), ("near", True)):
        octrace.bake_arrays(v, t, tmp_path / f"{name}.oct", distance=distance)
        summaries[name] = octrace.Scene(tmp_path / f"{name}.oct")
    plain, near = summaries["plain"], summaries["near"]
    assert plain.inspect()["distance"] is None
    assert near.inspect()["distance"]["triangles"] == len(t)
    a, b = plain.compute_closest_points(points), near.compute_closest_points(points)
    for key in ("points", "primitive_ids", "primitive_uvs", "primitive_normals"):
        np.testing.assert_array_equal(np.asarray(a[key]), np.asarray(b[key]), err_msg=key)
    np.testing.assert_array_equal(plain.compute_signed_distance(points), near.compute_signed_distance(points))
