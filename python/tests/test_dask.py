"""Scenes across processes: a scene pickled and unpickled in another process answers
as in this one, and the README's Dask example (two worker processes) runs as written."""

import multiprocessing
import pickle
import re
import subprocess
import sys

import numpy as np
import pytest

import octrace
from conftest import BUNNY, ROOT


def distances_elsewhere(scene, points):
    return scene.compute_signed_distance(points, nthreads=1, nsamples=5), scene.compute_closest_points(points)


def test_a_pickled_scene_answers_identically_in_another_process(tmp_path):
    path = tmp_path / "bunny.oct"
    octrace.bake(str(BUNNY), str(path))
    points = np.random.default_rng(3).uniform(-0.1, 0.2, (2000, 3)).astype(np.float32)
    for options in ({}, {"mmap": True}, {"trusted": True}):
        scene = octrace.Scene(path, **options)
        with multiprocessing.get_context("spawn").Pool(1) as pool:
            sdf, near = pool.apply(distances_elsewhere, (scene, points))
        np.testing.assert_array_equal(sdf, scene.compute_signed_distance(points, nsamples=5))
        here = scene.compute_closest_points(points)
        for key in here:
            np.testing.assert_array_equal(near[key], here[key])


def test_a_relative_path_pickles_as_the_absolute_one(tmp_path, monkeypatch):
    octrace.bake(str(BUNNY), str(tmp_path / "bunny.oct"))
    monkeypatch.chdir(tmp_path)
    pickled = pickle.dumps(octrace.Scene("bunny.oct", mmap=True))
    monkeypatch.chdir(ROOT)
    points = np.random.default_rng(4).uniform(-0.1, 0.2, (500, 3)).astype(np.float32)
    np.testing.assert_array_equal(pickle.loads(pickled).compute_distance(points),
                                  octrace.Scene(tmp_path / "bunny.oct").compute_distance(points))


def test_a_raycasting_scene_pickles_its_meshes():
    from conftest import cube_arrays
    scene = octrace.RaycastingScene()
    scene.add_triangles(*cube_arrays())
    points = np.array([[0.5, 0.5, 2.0], [0.5, 0.5, 0.6]], np.float32)
    before = scene.compute_signed_distance(points).numpy()
    np.testing.assert_array_equal(pickle.loads(pickle.dumps(scene)).compute_signed_distance(points).numpy(), before)
    np.testing.assert_allclose(before, [1.0, -0.4], rtol=1e-6)


def test_a_scene_in_memory_refuses_to_pickle_and_says_why():
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)
    with pytest.raises(TypeError, match="bake_arrays"):
        pickle.dumps(octrace.Scene.from_arrays(v, np.array([[0, 1, 2]])))


def test_the_readmes_dask_example_runs(tmp_path):
    pytest.importorskip("distributed", reason="needs dask.distributed (pip install 'dask[distributed]')")
    text = (ROOT / "README.md").read_text()
    block = next(b for b in re.findall(r"```python\n(.*?)```", text, re.S) if "LocalCluster" in b)
    (tmp_path / "sample.py").write_text(block)
    out = subprocess.run([sys.executable, "sample.py"], cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-4000:]
    assert "3 meshes, 60,000 signed distances" in out.stdout
