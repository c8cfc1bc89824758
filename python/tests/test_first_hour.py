"""What a user meets in the first hour, coming from Open3D (issue 50): occupancy on an
open mesh by Open3D's vote, tensors passed as Open3D passes them, messages that name
what to do, signatures that read, one part for a mesh without parts, and what a hit
is on (normals, texture coordinates, materials)."""

import inspect
import math

import numpy as np
import pytest

import octrace
from conftest import BUNNY, Tensor, cube_arrays


def points_in_box(lo, hi, n, seed=5):
    rng = np.random.default_rng(seed)
    lo, hi = np.asarray(lo, np.float32), np.asarray(hi, np.float32)
    centre, half = (lo + hi) / 2, (hi - lo) / 2
    return (centre + rng.uniform(-1.2, 1.2, (n, 3)) * half).astype(np.float32)


def test_occupancy_of_an_open_mesh_is_open3ds_vote_when_nsamples_is_given(bunny):
    assert not bunny.is_closed
    points = points_in_box(*bunny.bounds, 2000)
    with pytest.raises(octrace.NotClosedError, match=r"when given nsamples \(an odd number of rays a point"):
        bunny.compute_occupancy(points)
    for k in (1, 3, 5):
        votes = bunny.contains_by_vote(points, nsamples=k)
        occupancy = bunny.compute_occupancy(points, nsamples=k)
        assert occupancy.dtype == np.float32 and occupancy.shape == (2000,)
        np.testing.assert_array_equal(occupancy, votes.astype(np.float32))
    # A point far outside the box is outside by every vote.
    far = np.array([[100, 100, 100]], np.float32)
    assert not bunny.contains_by_vote(far, nsamples=7)[0]
    # Most of the bunny is closed: most points inside its body vote inside.
    inside = bunny.compute_occupancy(points, nsamples=5)
    assert 0.05 < inside.mean() < 0.6
    for bad in (0, 2, 256):
        with pytest.raises(ValueError, match=f"nsamples: {bad}, expected an odd number of rays from 1 to 255"):
            bunny.compute_occupancy(points, nsamples=bad)


def test_occupancy_of_a_closed_mesh_stays_exact_whatever_nsamples():
    cube = octrace.Scene.from_arrays(*cube_arrays())
    points = points_in_box([0, 0, 0], [1, 1, 1], 500)
    exact = cube.contains(points).astype(np.float32)
    for k in (None, 1, 3):
        np.testing.assert_array_equal(cube.compute_occupancy(points, nsamples=k), exact)
    np.testing.assert_array_equal(cube.contains_by_vote(points, nsamples=3), exact.astype(bool))


def test_tensors_with_a_numpy_method_are_read_as_open3d_passes_them(bunny):
    lo, hi = map(np.array, bunny.bounds)
    centre = (lo + hi) / 2
    rays = bunny.create_rays_pinhole(fov_deg=40, center=centre, eye=centre + [0, 0, 0.4], up=[0, 1, 0],
                                     width_px=32, height_px=24)
    want = bunny.cast_rays(rays)
    got = bunny.cast_rays(Tensor(rays))
    for key in want:
        np.testing.assert_array_equal(got[key], want[key])
    np.testing.assert_array_equal(bunny.count_intersections(Tensor(rays)), bunny.count_intersections(rays))
    v, t = cube_arrays()
    cube = octrace.Scene.from_arrays(Tensor(v), Tensor(t))
    np.testing.assert_array_equal(cube.contains(Tensor(np.array([[0.5, 0.5, 0.5]], np.float32))), [True])
    camera = Tensor(np.array(centre + [0, 0, 0.4]))
    np.testing.assert_array_equal(
        bunny.create_rays_pinhole(fov_deg=40, center=centre, eye=camera, up=[0, 1, 0], width_px=32, height_px=24),
        rays)

    class Broken:
        def numpy(self):
            raise RuntimeError("on the GPU")

    with pytest.raises(ValueError, match=r"rays: its numpy\(\) failed \(RuntimeError: on the GPU\); pass a numpy array"):
        bunny.cast_rays(Broken())


def test_a_mesh_given_as_a_scene_says_bake_it_first(tmp_path):
    mesh = tmp_path / "cow.obj"
    mesh.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    with pytest.raises(octrace.FormatError, match=r"cow.obj is a mesh \(OBJ\), not a baked scene: bake it first "
                                                  r"\(octrace.bake\('.*cow.obj', 'scene.oct'\)\)"):
        octrace.Scene(mesh)
    glb = tmp_path / "thing.glb"
    glb.write_bytes(b"glTF" + bytes(20))
    with pytest.raises(octrace.FormatError, match=r"a mesh \(glTF\), not a baked scene"):
        octrace.Scene(glb)


def test_every_signature_reads_and_shows_its_defaults():
    calls = [octrace.bake, octrace.bake_arrays, octrace.Scene.from_arrays]
    calls += [getattr(octrace.Scene, name) for name in dir(octrace.Scene)
              if not name.startswith("_") and callable(getattr(octrace.Scene, name))
              and name != "create_rays_pinhole"]
    for call in calls:
        signature = inspect.signature(call)  # raises where the text signature does not parse
        for p in signature.parameters.values():
            assert p.default is not Ellipsis, f"{call.__name__}: {p.name}"
    assert inspect.signature(octrace.Scene.length_inside).parameters["tmax"].default == math.inf
    assert inspect.signature(octrace.Scene.test_occlusions).parameters["tfar"].default == math.inf
    bake = inspect.signature(octrace.bake).parameters
    assert (bake["leaf_size"].default, bake["margin"].default) == (16, 2**-20)
    assert (bake["max_instances"].default, bake["max_triangles"].default) == (2**20, 2**27)
    assert "Ellipsis" not in inspect.getdoc(octrace.Scene.length_inside) + str(
        inspect.signature(octrace.Scene.length_inside))


def test_a_mesh_without_parts_has_one_that_geometry_ids_name():
    cube = octrace.Scene.from_arrays(*cube_arrays())
    assert cube.parts == [{"name": "whole mesh", "first_triangle": 0, "triangles": 12}]
    ans = cube.cast_rays(np.array([[0.5, 0.5, -1, 0, 0, 1]], np.float32))
    assert cube.parts[ans["geometry_ids"][0]]["triangles"] == 12


def test_cast_rays_says_what_each_hit_is_on(tmp_path):
    # A quad with vertex normals, texture coordinates and a material: an OBJ with an MTL.
    (tmp_path / "quad.mtl").write_text("newmtl red\nKd 0.8 0.1 0.1\n")
    (tmp_path / "quad.obj").write_text(
        "mtllib quad.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n"
        "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
        "vn 0 0 1\nvn 0 0 1\nvn 0.6 0 0.8\nvn 0.6 0 0.8\n"
        "usemtl red\nf 1/1/1 2/2/2 3/3/3\nf 1/1/1 3/3/3 4/4/4\n")
    octrace.bake(tmp_path / "quad.obj", tmp_path / "quad.oct")
    quad = octrace.Scene(tmp_path / "quad.oct")
    rays = np.array([[0.25, 0.75, 1, 0, 0, -1], [0.75, 0.25, 1, 0, 0, -1], [5, 5, 1, 0, 0, -1]], np.float32)
    plain = quad.cast_rays(rays)
    assert "points" not in plain
    ans = quad.cast_rays(rays, surface=True)
    for key in plain:
        np.testing.assert_array_equal(ans[key], plain[key])
    np.testing.assert_allclose(ans["points"][:2], [[0.25, 0.75, 0], [0.75, 0.25, 0]], atol=1e-6)
    assert np.isnan(ans["points"][2]).all() and np.isnan(ans["texture_uvs"][2]).all()
    np.testing.assert_allclose(ans["texture_uvs"][:2], [[0.25, 0.75], [0.75, 0.25]], atol=1e-6)
    # The normals interpolated: their x is 0.6 at y = 1 and 0 at y = 0, between them here.
    n = ans["shading_normals"][:2]
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1, atol=1e-6)
    assert 0 < n[1, 0] < n[0, 0] < 0.6 and (n[:, 2] > 0).all()
    np.testing.assert_array_equal(ans["primitive_normals"][:2], [[0, 0, 1], [0, 0, 1]])
    assert list(ans["material_ids"]) == [0, 0, octrace.INVALID_ID]
    assert quad.materials[0]["name"] == "red"
    np.testing.assert_allclose(quad.materials[0]["base_color"][:3], [0.8, 0.1, 0.1], atol=1e-6)
    # A mesh without any of it: the geometric normal, no texture coordinates, no material.
    cube = octrace.Scene.from_arrays(*cube_arrays())
    ans = cube.cast_rays(np.array([[0.5, 0.5, -1, 0, 0, 1]], np.float32), surface=True)
    np.testing.assert_array_equal(ans["shading_normals"], ans["primitive_normals"])
    assert np.isnan(ans["texture_uvs"]).all() and ans["material_ids"][0] == octrace.INVALID_ID
    assert cube.materials == []


def read_png(path):
    """An 8-bit RGB PNG (as `octrace render` writes them) as a (height, width, 3) array."""
    import struct
    import zlib
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    at, idat = 8, b""
    while at < len(data):
        n, kind = struct.unpack(">I4s", data[at:at + 8])
        body = data[at + 8:at + 8 + n]
        if kind == b"IHDR":
            width, height, depth, colour = struct.unpack(">IIBB", body[:10])
            assert (depth, colour) == (8, 2), "8-bit RGB"
        elif kind == b"IDAT":
            idat += body
        at += 12 + n
    raw = zlib.decompress(idat)
    stride = 3 * width
    out = np.zeros((height, stride), np.int32)
    for y in range(height):
        kind, line = raw[y * (stride + 1)], np.frombuffer(raw, np.uint8, stride, y * (stride + 1) + 1).astype(np.int32)
        up = out[y - 1] if y else np.zeros(stride, np.int32)
        row = out[y]
        for x in range(stride):
            left = row[x - 3] if x >= 3 else 0
            corner = up[x - 3] if x >= 3 else 0
            if kind == 0:
                pred = 0
            elif kind == 1:
                pred = left
            elif kind == 2:
                pred = up[x]
            elif kind == 3:
                pred = (left + up[x]) // 2
            else:
                p = left + up[x] - corner
                pa, pb, pc = abs(p - left), abs(p - up[x]), abs(p - corner)
                pred = left if pa <= pb and pa <= pc else (up[x] if pb <= pc else corner)
            row[x] = (line[x] + pred) & 255
    return out.reshape(height, width, 3).astype(np.uint8)


def test_open3ds_camera_renders_from_the_command_line_turned_half_a_turn(bunny, bunny_oct, cli, tmp_path):
    lo, hi = map(np.array, bunny.bounds)
    centre = (lo + hi) / 2
    eye, up, fov, (w, h) = centre + [0.05, 0.03, 0.3], [0.1, 1, 0], 35.0, (48, 32)
    rays = bunny.create_rays_pinhole(fov_deg=fov, center=centre, eye=eye, up=up, width_px=w, height_px=h)
    hit = np.isfinite(bunny.cast_rays(rays)["t_hit"])
    vec = lambda v: ",".join(repr(float(x)) for x in v)  # noqa: E731
    cli("render", bunny_oct, "-o", tmp_path / "n.png", "--mode", "normals", "--width", w, "--height", h,
        "--hfov", fov, "--eye", vec(eye), "--target", vec(centre), "--up", vec(up))
    image = read_png(tmp_path / "n.png")
    rendered = (image != [20, 20, 26]).any(axis=2)  # the background of a miss
    assert 0.1 < hit.mean() < 0.9
    # Half a turn: Open3D's row 0 is the image's bottom, its column 0 the right edge.
    # Pixels on the silhouette may differ (the render's directions are normalised).
    assert (rendered[::-1, ::-1] != hit).mean() < 0.01
    assert (rendered != hit).mean() > 0.1
