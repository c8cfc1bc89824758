"""Bad input raises a clear exception; a hostile file never crashes the interpreter."""

import subprocess
import sys

import numpy as np
import pytest

import octrace
from conftest import BUNNY, cube_arrays


def test_rays_of_the_wrong_dtype_shape_or_with_nans_are_refused(bunny):
    with pytest.raises(ValueError, match="dtype float64, expected float32"):
        bunny.cast_rays(np.zeros((3, 6)))
    with pytest.raises(ValueError, match=r"shape \(3, 5\), expected \(\.\.\., 6\)"):
        bunny.cast_rays(np.zeros((3, 5), np.float32))
    with pytest.raises(ValueError, match=r"shape \(\), expected"):
        bunny.test_occlusions(np.float32(1))
    rays = np.zeros((4, 6), np.float32)
    rays[:, 5] = 1
    rays[2, 4] = np.nan
    for query in (bunny.cast_rays, bunny.test_occlusions, bunny.count_intersections, bunny.list_intersections):
        with pytest.raises(ValueError, match="ray 2 has a NaN"):
            query(rays)
    with pytest.raises(ValueError, match="point 0 has a NaN"):
        octrace.Scene.from_arrays(*cube_arrays()).contains(np.full((1, 3), np.nan, np.float32))
    with pytest.raises(ValueError, match="not an array of numbers"):
        bunny.cast_rays([["a"] * 6])
    with pytest.raises(ValueError, match="nthreads"):
        bunny.cast_rays(rays[:1], nthreads=100_000)
    with pytest.raises(ValueError, match=r"nthreads: -1, expected 0 \(all cores\) to 1024"):
        bunny.cast_rays(rays[:1], nthreads=-1)


def test_rays_that_cannot_hit_are_misses(bunny):
    rays = np.array([[0, 0, 0, 0, 0, 0], [np.inf, 0, 0, 1, 0, 0], [0, 0, 0, 1e-45, 0, 0]], np.float32)
    ans = bunny.cast_rays(rays)
    assert np.isinf(ans["t_hit"][:2]).all()
    assert (ans["primitive_ids"][:2] == octrace.INVALID_ID).all()


def test_bad_meshes_and_options(tmp_path):
    with pytest.raises(FileNotFoundError):
        octrace.bake(tmp_path / "missing.obj", tmp_path / "x.oct")
    bad = tmp_path / "bad.obj"
    bad.write_text("v 0 0 0\nv 1 0 0\nf 1 2 7\n")
    with pytest.raises(octrace.BakeError, match="bad.obj"):
        octrace.bake(bad, tmp_path / "x.oct")
    assert not (tmp_path / "x.oct").exists()
    with pytest.raises(ValueError, match="leaf size 0 .*the leaf target must be at least 1"):
        octrace.bake(BUNNY, tmp_path / "x.oct", leaf_size=0)
    with pytest.raises(ValueError, match="one of the bake's inputs"):
        octrace.bake(bad, bad)
    (tmp_path / "linked.oct").hardlink_to(bad)  # the same file by another name
    with pytest.raises(ValueError, match="one of the bake's inputs"):
        octrace.bake(bad, tmp_path / "linked.oct")
    v, t = cube_arrays()
    with pytest.raises(ValueError, match=r"triangles\[1\]: vertex index 8 out of range"):
        octrace.Scene.from_arrays(v, np.array([[0, 1, 2], [1, 2, 8]]))
    with pytest.raises(ValueError, match="expected integer indices"):
        octrace.Scene.from_arrays(v, t.astype(np.float32))
    with pytest.raises(octrace.BakeError):
        octrace.Scene.from_arrays(np.full((3, 3), np.nan), np.array([[0, 1, 2]]))
    with pytest.raises(octrace.BakeError, match="budget"):
        octrace.bake(BUNNY, tmp_path / "x.oct", max_triangles=1000)


def test_files_that_are_not_scenes(tmp_path, bunny_oct):
    with pytest.raises(FileNotFoundError, match="nowhere.oct"):
        octrace.Scene(tmp_path / "nowhere.oct")
    text = tmp_path / "text.oct"
    text.write_text("hello\n")
    with pytest.raises(octrace.FormatError, match="text.oct"):
        octrace.Scene(text)
    data = bytearray(bunny_oct.read_bytes())
    cut = tmp_path / "cut.oct"
    cut.write_bytes(data[: len(data) // 2])
    with pytest.raises(octrace.FormatError):
        octrace.Scene(cut)
    flipped = tmp_path / "flipped.oct"
    data[len(data) // 3] ^= 0x40
    flipped.write_bytes(data)
    with pytest.raises(octrace.FormatError, match="checksum"):
        octrace.Scene(flipped)


HOSTILE = r"""
import sys, numpy as np, octrace
rng = np.random.default_rng(int(sys.argv[2]))
data = open(sys.argv[1], 'rb').read()
rays = rng.normal(size=(2000, 6)).astype(np.float32)
opened = 0
for i in range(60):
    b = bytearray(data)
    for _ in range(rng.integers(1, 8)):
        at = int(rng.integers(0, len(b)))
        b[at] = int(rng.integers(0, 256))
    path = sys.argv[1] + '.mutant'
    open(path, 'wb').write(bytes(b))
    for trusted in (False, True):
        try:
            scene = octrace.Scene(path, trusted=trusted)
        except (octrace.FormatError, OSError):
            continue
        opened += 1
        scene.cast_rays(rays); scene.count_intersections(rays); scene.list_intersections(rays)
        try:
            scene.contains(rays[:, :3].copy())
        except octrace.NotClosedError:
            pass
        del scene
print(opened)
"""


def test_hostile_files_raise_and_never_crash_the_interpreter(tmp_path):
    v, t = cube_arrays()
    path = tmp_path / "cube.oct"
    octrace.bake_arrays(v, t, path)
    out = subprocess.run([sys.executable, "-c", HOSTILE, str(path), "3"], capture_output=True, text=True,
                         timeout=300)
    assert out.returncode == 0, out.stderr
    assert int(out.stdout) > 0  # some damaged files open (trusted: header checks only) and answer
