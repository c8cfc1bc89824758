"""Fixtures: the command-line tool to compare with, and the bunny this repository carries."""

import json
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

import octrace

ROOT = Path(__file__).resolve().parents[2]
BUNNY = ROOT / "assets" / "bunny.obj.zst"


def find_cli():
    """`octrace`, the command line: $OCTRACE_CLI, else the workspace's build of it."""
    named = os.environ.get("OCTRACE_CLI")
    if named:
        return Path(named)
    for profile in ("release", "debug"):
        path = ROOT / "target" / profile / "octrace"
        if path.exists():
            return path
    found = shutil.which("octrace")
    if found:
        return Path(found)
    pytest.fail("the octrace command line is needed to compare with: cargo build --release -p octrace "
                "(or set OCTRACE_CLI)")


@pytest.fixture(scope="session")
def cli():
    path = find_cli()

    def run(*args, json_out=False):
        out = subprocess.run([str(path), *map(str, args)], check=True, capture_output=True, text=True)
        return json.loads(out.stdout) if json_out else out.stdout

    return run


@pytest.fixture(scope="session")
def work(tmp_path_factory):
    return tmp_path_factory.mktemp("octrace")


@pytest.fixture(scope="session")
def bunny_oct(work):
    """The bunny baked by the module."""
    path = work / "bunny.oct"
    octrace.bake(BUNNY, path)
    return path


@pytest.fixture(scope="session")
def bunny(bunny_oct):
    return octrace.Scene(bunny_oct)


def read_rays(path):
    """A ray file of the command line (32 bytes a ray: ox oy oz tmin dx dy dz tmax) as
    Open3D-style (n, 6) rays; the standard sets cover [0, inf)."""
    raw = np.fromfile(path, dtype="<f4").reshape(-1, 8)
    assert (raw[:, 3] == 0).all() and np.isposinf(raw[:, 7]).all()
    return np.ascontiguousarray(raw[:, [0, 1, 2, 4, 5, 6]])


@pytest.fixture(scope="session", params=["primary", "incoherent"])
def standard_set(request, cli, bunny_oct, work):
    """The bunny's standard ray sets (bench/RAYS.md), written by `octrace rays`."""
    path = work / f"{request.param}.rays"
    if not path.exists():
        cli("rays", bunny_oct, "--set", request.param, "-o", path)
    return request.param, path, read_rays(path)


def cube_arrays(lo=0.0, hi=1.0):
    """A closed axis-aligned cube, wound outward: 8 vertices, 12 triangles."""
    v = np.array([[x, y, z] for x in (lo, hi) for y in (lo, hi) for z in (lo, hi)], np.float32)
    # Vertex i has x = i >> 2, y = (i >> 1) & 1, z = i & 1.
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    t = [[a, b, c] for a, b, c, d in quads] + [[a, c, d] for a, b, c, d in quads]
    return v, np.array(t, np.int64)


class Tensor:
    """What Open3D's (and PyTorch's) CPU tensors offer numpy: a `numpy()` method, and
    no element-by-element sequence protocol numpy could read."""

    def __init__(self, array):
        self._array = np.asarray(array)

    def numpy(self):
        return self._array
