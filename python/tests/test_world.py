"""octrace.World: scenes placed by transforms against the same triangles placed in
double precision and baked into one scene."""

import numpy as np
import pytest

import octrace
from conftest import cube_arrays


def rotation(axis, angle):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


def placements(n, seed=5):
    rng = np.random.default_rng(seed)
    out = []
    for i in range(n):
        m = np.eye(4)
        scale = rng.uniform(0.5, 1.5, 3) * (-1 if i % 4 == 3 else 1)  # some mirrored
        m[:3, :3] = rotation(rng.normal(size=3), rng.uniform(0, 6.3)) @ np.diag(scale)
        m[:3, 3] = [3.0 * (i % 4), 3.0 * (i // 4), 0.0]  # each in its own cell
        out.append(m)
    return out


def placed(v, t, transforms):
    """The triangles of every placement, in double precision, then rounded."""
    vs, ts = [], []
    for k, m in enumerate(transforms):
        vs.append((v.astype(np.float64) @ m[:3, :3].T + m[:3, 3]).astype(np.float32))
        ts.append(t + k * len(v))
    return np.vstack(vs), np.vstack(ts)


def rays(n, seed=6):
    rng = np.random.default_rng(seed)
    o = rng.uniform([-3, -3, -6], [12, 9, -5], (n, 3))
    target = rng.uniform([-1, -1, -1], [10, 7, 1], (n, 3))
    return np.hstack([o, target - o]).astype(np.float32)


def test_a_world_answers_as_its_triangles_baked_into_one_scene():
    v, t = cube_arrays(-1.0, 1.0)
    cube = octrace.Scene.from_arrays(v, t)
    transforms = placements(12)
    world = octrace.World()
    ids = [world.add(cube, m) for m in transforms]
    assert len(world) == 0  # not committed yet
    world.commit()
    assert len(world) == 12 and ids == list(range(12))
    np.testing.assert_allclose(world.transform(ids[5]), transforms[5])
    one = octrace.Scene.from_arrays(*placed(v, t, transforms))
    r = rays(4000)
    ours, theirs = world.cast_rays(r), one.cast_rays(r)
    hit = np.isfinite(theirs["t_hit"])
    assert hit.sum() > 1000
    same = ours["geometry_ids"] * len(t) + ours["primitive_ids"] == theirs["primitive_ids"]
    # The same triangle but for rays within rounding of an edge.
    assert (same | ~hit).mean() > 0.995
    assert (np.isfinite(ours["t_hit"]) == hit).mean() > 0.995
    both = same & hit
    np.testing.assert_allclose(ours["t_hit"][both], theirs["t_hit"][both], rtol=1e-5)
    np.testing.assert_allclose(ours["primitive_normals"][both], theirs["primitive_normals"][both], atol=1e-5)
    assert (ours["geometry_ids"][~np.isfinite(ours["t_hit"])] == octrace.INVALID_ID).all()
    agree = world.test_occlusions(r) == one.test_occlusions(r)
    assert agree.mean() > 0.995
    assert (world.count_intersections(r) == one.count_intersections(r)).mean() > 0.995
    lists, theirs_lists = world.list_intersections(r), one.list_intersections(r)
    np.testing.assert_array_equal(np.diff(lists["ray_splits"]), world.count_intersections(r))
    ids = lists["geometry_ids"].astype(np.int64) * len(t) + lists["primitive_ids"]
    agree = 0
    for i in range(len(r)):
        a, b = lists["ray_splits"][i:i + 2]
        c, d = theirs_lists["ray_splits"][i:i + 2]
        agree += sorted(ids[a:b]) == sorted(theirs_lists["primitive_ids"][c:d])
        assert (np.diff(lists["t_hit"][a:b]) >= 0).all()
    assert agree >= 0.995 * len(r)
    first = world.list_intersections(r, max_hits=1)
    np.testing.assert_array_equal(np.diff(first["ray_splits"]), np.minimum(np.diff(lists["ray_splits"]), 1))
    with pytest.raises(MemoryError, match="max_memory"):
        world.list_intersections(r, max_memory=1000)
    points = np.random.default_rng(7).uniform([-2, -2, -2], [11, 8, 2], (5000, 3)).astype(np.float32)
    inside = world.compute_occupancy(points)
    assert inside.sum() > 200
    assert (inside == one.compute_occupancy(points)).mean() > 0.999


def test_moves_and_removals_are_seen_after_commit():
    v, t = cube_arrays(-1.0, 1.0)
    cube = octrace.Scene.from_arrays(v, t)
    world = octrace.World()
    a = world.add(cube)  # the identity
    b = world.add(cube, np.hstack([np.eye(3), [[5.0], [0.0], [0.0]]]))  # 3x4
    world.commit()
    ray = np.array([[5, 0, -5, 0, 0, 1]], np.float32)
    assert world.cast_rays(ray)["geometry_ids"][0] == b
    assert world.cast_rays(ray)["t_hit"][0] == 4.0
    world.remove(b)
    assert world.cast_rays(ray)["geometry_ids"][0] == b  # staged, not seen yet
    world.commit()
    assert world.cast_rays(ray)["geometry_ids"][0] == octrace.INVALID_ID
    moved = np.eye(4)
    moved[0, 3] = 5.0
    world.set_transform(a, moved)
    world.commit()
    assert world.cast_rays(ray)["geometry_ids"][0] == a
    with pytest.raises(KeyError):
        world.remove(b)
    with pytest.raises(ValueError, match="singular"):
        world.add(cube, np.diag([1.0, 0.0, 1.0, 1.0]))
    with pytest.raises(ValueError, match="0 0 0 1"):
        world.add(cube, np.ones((4, 4)))
    with pytest.raises(ValueError, match="shape"):
        world.add(cube, np.eye(3))


def test_files_and_arrays_are_added_as_scenes_are(tmp_path):
    v, t = cube_arrays(-1.0, 1.0)
    path = tmp_path / "cube.oct"
    octrace.bake_arrays(v, t, str(path))
    transforms = placements(6)
    by_scene, by_file, by_arrays = octrace.World(), octrace.World(), octrace.World()
    cube = octrace.Scene(str(path))
    for i, m in enumerate(transforms):
        by_scene.add(cube, m)
        # A path as str or pathlib.Path: the file read once, shared by its instances.
        by_file.add(path if i % 2 else str(path), m)
        by_arrays.add_triangles(v, t, m)
    r = rays(3000)
    answers = []
    for world in (by_scene, by_file, by_arrays):
        world.commit()
        assert len(world) == 6
        answers.append(world.cast_rays(r))
    assert np.isfinite(answers[0]["t_hit"]).sum() > 500
    for other in answers[1:]:
        for key in ("t_hit", "geometry_ids", "primitive_ids", "primitive_uvs", "primitive_normals"):
            np.testing.assert_array_equal(other[key], answers[0][key], err_msg=key)
    # The file was read once: rewriting it now changes no instance of it.
    octrace.bake_arrays(v * 2, t, str(path))
    by_file.add(path, transforms[0])
    by_file.commit()
    again = by_file.cast_rays(r)
    # Placed where instance 0 is, the same cube: every hit as before (ties go to the
    # lower id); the doubled cube would have been hit first by many rays.
    np.testing.assert_array_equal(again["t_hit"], answers[1]["t_hit"])
    np.testing.assert_array_equal(again["geometry_ids"], answers[1]["geometry_ids"])


def test_what_is_not_a_scene_is_refused_by_name(tmp_path):
    world = octrace.World()
    with pytest.raises(TypeError, match="expected an octrace.Scene or the path of a .oct file, got int"):
        world.add(3)
    with pytest.raises(OSError):
        world.add(str(tmp_path / "missing.oct"))
    (tmp_path / "junk.oct").write_bytes(b"not a scene")
    with pytest.raises(octrace.FormatError):
        world.add(tmp_path / "junk.oct")
    v, t = cube_arrays(-1.0, 1.0)
    with pytest.raises(ValueError):
        world.add_triangles(v, t, np.eye(3))
    assert len(world) == 0
    world.commit()
    assert len(world) == 0


def even_placements(n, seed=7):
    """Rotations, one scale each (some mirrored), translations: distances kept in ratio."""
    rng = np.random.default_rng(seed)
    out = []
    for i in range(n):
        m = np.eye(4)
        s = rng.uniform(0.5, 1.5)
        m[:3, :3] = rotation(rng.normal(size=3), rng.uniform(0, 6.3)) * s
        if i % 4 == 3:
            m[:3, 0] = -m[:3, 0]  # mirrored
        m[:3, 3] = [3.0 * (i % 4), 3.0 * (i // 4), 0.0]
        out.append(m)
    return out


def test_closest_points_and_distances_through_a_world_are_the_baked_scenes():
    v, t = cube_arrays(-1.0, 1.0)
    cube = octrace.Scene.from_arrays(v, t)
    transforms = even_placements(8)
    world = octrace.World()
    for m in transforms:
        world.add(cube, m)
    world.commit()
    one = octrace.Scene.from_arrays(*placed(v, t, transforms))
    rng = np.random.default_rng(8)
    points = rng.uniform([-3, -3, -2], [12, 6, 2], (3000, 3)).astype(np.float32)
    ours, theirs = world.compute_closest_points(points), one.compute_closest_points(points)
    distance = np.linalg.norm(theirs["points"] - points, axis=1)
    np.testing.assert_allclose(np.linalg.norm(ours["points"] - points, axis=1), distance, rtol=1e-5, atol=1e-5)
    same = ours["geometry_ids"] * len(t) + ours["primitive_ids"] == theirs["primitive_ids"]
    assert same.mean() > 0.97  # the rest: equally near triangles within the rounding
    np.testing.assert_allclose(ours["points"][same], theirs["points"][same], atol=1e-5)
    np.testing.assert_allclose(ours["primitive_normals"][same], theirs["primitive_normals"][same], atol=1e-5)
    d = world.compute_distance(points)
    np.testing.assert_allclose(d, one.compute_distance(points), rtol=1e-5, atol=1e-5)
    signed = world.compute_signed_distance(points)
    np.testing.assert_array_equal(signed < 0, world.compute_occupancy(points) == 1.0)
    np.testing.assert_allclose(signed, one.compute_signed_distance(points), rtol=1e-5, atol=1e-5)
    assert (signed < 0).sum() > 100
    # A band: points farther than 0.1 answer inf and INVALID_ID.
    band = world.compute_closest_points(points, max_distance=0.1)
    far = d > 0.1
    assert far.sum() > 100 and (~far).sum() > 10
    assert (band["geometry_ids"][far] == octrace.INVALID_ID).all() and np.isnan(band["points"][far]).all()
    assert np.isinf(world.compute_distance(points, max_distance=0.1)[far]).all()


def test_distances_through_a_stretched_placement_are_the_placed_triangles():
    v, t = cube_arrays(-1.0, 1.0)
    world = octrace.World()
    first = world.add_triangles(v, t)
    m = np.diag([1.0, 2.0, 1.0, 1.0])
    m[:3, :3] = rotation([1, 2, 3], 0.4) @ m[:3, :3]  # stretched, then turned
    m[0, 3] = 5.0
    stretched = world.add_triangles(v, t, m)
    world.commit()
    assert world.compute_distance(np.zeros((1, 3), np.float32))[0] == 1.0
    baked = octrace.Scene.from_arrays(*placed(v, t, [np.eye(4), m]))
    rng = np.random.default_rng(8)
    points = rng.uniform([-3, -4, -3], [8, 4, 3], (2000, 3)).astype(np.float32)
    got, want = world.compute_closest_points(points), baked.compute_closest_points(points)
    np.testing.assert_allclose(got["points"], want["points"], rtol=0, atol=1e-5)
    np.testing.assert_allclose(world.compute_distance(points), baked.compute_distance(points), rtol=1e-6)
    ids = np.where(want["primitive_ids"] < len(t), first, stretched)
    assert (got["geometry_ids"] == ids).mean() > 0.99


def spheres_glb(path, count=30):
    """A glTF-Binary file like Khronos' MetalRoughSpheresNoTextures: `count` meshes
    sharing one sphere's accessors (2,400 triangles), each its own material, placed on a
    grid (node 1 mirrored)."""
    import json
    import struct

    segments, rings = 40, 31
    verts = []
    for r in range(rings + 1):
        th = np.pi * r / rings
        for s in range(segments + 1):
            ph = 2 * np.pi * s / segments
            verts.append((np.sin(th) * np.cos(ph), np.cos(th), np.sin(th) * np.sin(ph)))
    idx = []
    for r in range(rings):
        for s in range(segments):
            a = r * (segments + 1) + s
            b = a + segments + 1
            if r > 0:
                idx += [a, a + 1, b]
            if r < rings - 1:
                idx += [a + 1, b + 1, b]
    positions = np.asarray(verts, np.float32).tobytes()
    indices = np.asarray(idx, np.uint16).tobytes()
    indices += b"\0" * (-len(indices) % 4)
    blob = positions + indices
    nodes = [{"mesh": k, "translation": [2.5 * (k % 6), 2.5 * (k // 6), 0]} for k in range(count)]
    nodes[1]["scale"] = [-1, 1, 1]
    doc = {
        "asset": {"version": "2.0"},
        "scenes": [{"nodes": list(range(count))}],
        "nodes": nodes,
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1, "material": k}]}
                   for k in range(count)],
        "materials": [{"name": f"sphere {k}", "pbrMetallicRoughness": {"metallicFactor": (k % 6) / 5}}
                      for k in range(count)],
        "buffers": [{"byteLength": len(blob)}],
        "bufferViews": [{"buffer": 0, "byteLength": len(positions)},
                        {"buffer": 0, "byteOffset": len(positions), "byteLength": 2 * len(idx)}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": len(verts), "type": "VEC3",
                       "min": [-1, -1, -1], "max": [1, 1, 1]},
                      {"bufferView": 1, "componentType": 5123, "count": len(idx), "type": "SCALAR"}],
    }
    text = json.dumps(doc).encode()
    text += b" " * (-len(text) % 4)
    total = 12 + 8 + len(text) + 8 + len(blob)
    path.write_bytes(struct.pack("<5I", 0x46546C67, 2, total, len(text), 0x4E4F534A) + text
                     + struct.pack("<2I", len(blob), 0x004E4942) + blob)


def test_an_instanced_bake_opens_as_a_world_answering_as_its_flat_bake(tmp_path, cli):
    """A glTF placing one mesh many times bakes to an instanced file (issue 51), which
    `World.open` opens: its hits, counts and occupancy are the flat bake's, and each
    instance names the material it draws."""
    spheres_glb(tmp_path / "spheres.glb")
    cli("bake", tmp_path / "spheres.glb", "-o", tmp_path / "spheres.oct")
    cli("bake", tmp_path / "spheres.glb", "-o", tmp_path / "flat.oct", "--flatten")
    with pytest.raises(octrace.FormatError, match="instanced file"):
        octrace.Scene(tmp_path / "spheres.oct")
    world = octrace.World.open(tmp_path / "spheres.oct")
    assert len(world) == 30
    flat = octrace.Scene(tmp_path / "flat.oct")
    rng = np.random.default_rng(51)
    origins = rng.uniform([-3, -3, -6], [15, 13, 6], (5000, 3))
    targets = rng.uniform([-1, -1, -1], [13.5, 11, 1], (5000, 3))
    r = np.hstack([origins, targets - origins]).astype(np.float32)
    w, f = world.cast_rays(r), flat.cast_rays(r)
    hit = np.isfinite(f["t_hit"])
    assert hit.sum() > 1000
    np.testing.assert_array_equal(np.isfinite(w["t_hit"]), hit)
    np.testing.assert_allclose(w["t_hit"][hit], f["t_hit"][hit], rtol=1e-5, atol=1e-5)
    np.testing.assert_array_equal(world.count_intersections(r), flat.count_intersections(r))
    with pytest.raises(ValueError):
        octrace.World.open(tmp_path / "spheres.oct", device="tpu")
    with pytest.raises(octrace.FormatError, match="not an instanced file"):
        octrace.World.open(tmp_path / "flat.oct")
