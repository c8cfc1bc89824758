"""The module's answers against the command line's, bit for bit, on the bunny's
standard ray sets; one thread against all."""

import numpy as np
import pytest

import octrace

MISS = 0xFFFFFFFF


def test_bake_writes_the_command_lines_file(cli, work, bunny_oct):
    from conftest import BUNNY

    path = work / "bunny-cli.oct"
    cli("bake", BUNNY, "-o", path)
    assert path.read_bytes() == bunny_oct.read_bytes()


def test_cast_rays_equals_trace(cli, bunny, bunny_oct, standard_set, work):
    name, ray_file, rays = standard_set
    hits_file = work / f"{name}.hits"
    cli("trace", bunny_oct, "--rays", ray_file, "-o", hits_file)
    hits = np.fromfile(hits_file, dtype=[("t", "<f4"), ("id", "<u4")])
    ans = bunny.cast_rays(rays)
    assert ans["t_hit"].dtype == np.float32 and ans["primitive_ids"].dtype == np.uint32
    # Bit for bit: a miss is inf in both (the sets' tmax).
    np.testing.assert_array_equal(ans["t_hit"].view(np.uint32), hits["t"].view(np.uint32))
    np.testing.assert_array_equal(ans["primitive_ids"], hits["id"])
    hit = hits["id"] != MISS
    assert hit.sum() > 100_000
    assert (ans["geometry_ids"][hit] == 0).all() and (ans["geometry_ids"][~hit] == octrace.INVALID_ID).all()
    uv = ans["primitive_uvs"][hit]
    assert (uv >= 0).all() and (uv.sum(axis=1) <= 1 + 1e-6).all()
    # Unit normals, facing against the ray on the bunny's outside... or not: but unit.
    n = ans["primitive_normals"][hit]
    assert np.allclose(np.linalg.norm(n, axis=1), 1, atol=1e-5)
    # The hit point from the normal's triangle plane: origin + t dir lies on it.
    if name == "primary":
        assert np.isfinite(ans["t_hit"][hit]).all()


def test_test_occlusions_equals_trace(cli, bunny, bunny_oct, standard_set, work):
    name, ray_file, rays = standard_set
    hits_file = work / f"{name}.occluded"
    cli("trace", bunny_oct, "--rays", ray_file, "-o", hits_file, "--occluded")
    ids = np.fromfile(hits_file, dtype=[("t", "<f4"), ("id", "<u4")])["id"]
    occluded = bunny.test_occlusions(rays)
    assert occluded.dtype == np.bool_
    np.testing.assert_array_equal(occluded, ids != MISS)


def test_list_and_count_intersections_equal_trace(cli, bunny, bunny_oct, standard_set, work):
    name, ray_file, rays = standard_set
    all_file = work / f"{name}.all"
    cli("trace", bunny_oct, "--rays", ray_file, "-o", all_file, "--all-hits")
    raw = all_file.read_bytes()
    n = len(rays)
    offsets = np.frombuffer(raw, "<u8", n + 1)
    records = np.frombuffer(raw, [("t", "<f4"), ("triangle", "<u4"), ("u", "<f4"), ("v", "<f4"),
                                  ("enters", "<u4")], offset=8 * (n + 1))
    ans = bunny.list_intersections(rays)
    np.testing.assert_array_equal(ans["ray_splits"], offsets)
    np.testing.assert_array_equal(ans["ray_ids"], np.repeat(np.arange(n, dtype=np.uint32), np.diff(offsets).astype(np.int64)))
    np.testing.assert_array_equal(ans["t_hit"].view(np.uint32), records["t"].view(np.uint32))
    np.testing.assert_array_equal(ans["primitive_ids"], records["triangle"])
    np.testing.assert_array_equal(ans["primitive_uvs"][:, 0].view(np.uint32), records["u"].view(np.uint32))
    np.testing.assert_array_equal(ans["primitive_uvs"][:, 1].view(np.uint32), records["v"].view(np.uint32))
    np.testing.assert_array_equal(ans["enters"], records["enters"] == 1)
    assert (ans["geometry_ids"] == 0).all()
    counts_file = work / f"{name}.counts"
    cli("trace", bunny_oct, "--rays", ray_file, "-o", counts_file, "--counts")
    counts = np.fromfile(counts_file, dtype=[("total", "<u4"), ("entries", "<u4")])
    got = bunny.count_intersections(rays)
    assert got.dtype == np.int32
    np.testing.assert_array_equal(got, counts["total"])
    np.testing.assert_array_equal(got, np.diff(offsets))
    # Each ray's nearest crossing is its nearest hit.
    first = bunny.cast_rays(rays)
    some = np.diff(offsets) > 0
    np.testing.assert_array_equal(ans["t_hit"][offsets[:-1][some]], first["t_hit"][some])


def test_one_thread_answers_as_all(bunny, standard_set):
    _, _, rays = standard_set
    rays = rays[:100_000]
    one, every = bunny.cast_rays(rays, nthreads=1), bunny.cast_rays(rays)
    for key in one:
        np.testing.assert_array_equal(one[key], every[key])
    np.testing.assert_array_equal(bunny.count_intersections(rays, nthreads=1), bunny.count_intersections(rays))
    one, every = bunny.list_intersections(rays, nthreads=1), bunny.list_intersections(rays, nthreads=2)
    for key in one:
        np.testing.assert_array_equal(one[key], every[key])


def test_leading_shapes_are_kept(bunny, standard_set):
    _, _, rays = standard_set
    grid = rays[:12].reshape(3, 4, 6)
    ans = bunny.cast_rays(grid)
    assert ans["t_hit"].shape == (3, 4)
    assert ans["primitive_uvs"].shape == (3, 4, 2) and ans["primitive_normals"].shape == (3, 4, 3)
    flat = bunny.cast_rays(rays[:12])
    np.testing.assert_array_equal(ans["t_hit"].ravel(), flat["t_hit"])
    assert bunny.test_occlusions(grid).shape == (3, 4)
    assert bunny.count_intersections(grid).shape == (3, 4)
    one = bunny.cast_rays(rays[0])
    assert one["t_hit"].shape == () and one["primitive_normals"].shape == (3,)
    empty = bunny.cast_rays(np.zeros((0, 6), np.float32))
    assert empty["t_hit"].shape == (0,) and empty["primitive_uvs"].shape == (0, 2)
    assert len(bunny.list_intersections(np.zeros((0, 6), np.float32))["ray_splits"]) == 1


def test_strided_and_list_input_give_the_same_answers(bunny, standard_set):
    _, _, rays = standard_set
    wide = np.zeros((1000, 8), np.float32)
    wide[:, :6] = rays[:1000]
    strided = wide[:, :6]
    assert not strided.flags["C_CONTIGUOUS"]
    np.testing.assert_array_equal(bunny.cast_rays(strided)["t_hit"], bunny.cast_rays(rays[:1000])["t_hit"])
    as_list = rays[:5].tolist()
    np.testing.assert_array_equal(bunny.cast_rays(as_list)["t_hit"], bunny.cast_rays(rays[:5])["t_hit"])


def test_inspect_is_the_command_lines_json(cli, bunny, bunny_oct):
    assert bunny.inspect() == cli("inspect", "--json", bunny_oct, json_out=True)
    d = bunny.inspect()
    assert d["triangles"] == bunny.triangle_count == 69451
    assert not bunny.is_closed and d["surface"]["boundary_edges"] > 0
    assert [(p["name"], p["object"], p["first_triangle"], p["triangles"]) for p in bunny.parts] == [
        (d["scene_data"]["parts"][0]["name"], 0, 0, 69451)]
    assert d["scene_data"]["parts"][0]["object"] == 0


def test_geometry_ids_name_gltf_nodes_meshes_and_primitives(tmp_path):
    """SimpleMeshes (Khronos sample): one triangle mesh placed by two nodes, the second
    moved one unit along x."""
    from conftest import ROOT

    octrace.bake(ROOT / "fuzz" / "seeds" / "load_gltf" / "SimpleMeshes.gltf", tmp_path / "simple.oct")
    scene = octrace.Scene(tmp_path / "simple.oct")
    assert [(p["node"], p["mesh"], p["primitive"]) for p in scene.parts] == [(0, 0, 0), (1, 0, 0)]
    rays = np.array([[0.25, 0.25, 1, 0, 0, -1], [1.25, 0.25, 1, 0, 0, -1], [3, 3, 1, 0, 0, -1]], np.float32)
    ans = scene.cast_rays(rays)
    np.testing.assert_array_equal(ans["geometry_ids"], [0, 1, octrace.INVALID_ID])
    every = scene.list_intersections(rays)
    np.testing.assert_array_equal(every["geometry_ids"], [0, 1])


def test_occlusion_interval(bunny):
    lo, hi = map(np.array, bunny.bounds)
    centre = (lo + hi) / 2
    ray = np.array([[*(centre - [0, 0, 2]), 0, 0, 1]], np.float32)
    t = bunny.cast_rays(ray)["t_hit"][0]
    assert np.isfinite(t)
    assert bunny.test_occlusions(ray)[0]
    assert not bunny.test_occlusions(ray, tfar=t * 0.999)[0]
    assert bunny.test_occlusions(ray, tnear=0.0, tfar=t)[0]
