"""`Scene(..., device="gpu")` against the CPU's answers, bit for bit: every ray query
on the bunny's standard sets and on rays through a cube's vertices and edges (the
ties the exact test decides), with the occlusion interval, hit limits, surface data
and pickling; inside/outside of points on a closed torus.

CI builds the module with the GPU (`MATURIN_PEP517_ARGS="--features gpu"`) and runs
these on Mesa's software Vulkan (lavapipe) with OCTRACE_REQUIRE_GPU=1: there a module
without the GPU, or a machine without an adapter, fails them rather than skips."""

import os
import pickle

import numpy as np
import pytest

import octrace
from conftest import cube_arrays

REQUIRED = os.environ.get("OCTRACE_REQUIRE_GPU") == "1"


def on_gpu(open_scene):
    """`open_scene()` on the GPU, or the test skipped (failed where the GPU is required)
    when the module or the machine has none."""
    why = None
    if not octrace.HAS_GPU:
        why = 'the module was built without the GPU (MATURIN_PEP517_ARGS="--features gpu")'
    else:
        try:
            return open_scene()
        except octrace.GpuError as e:
            why = f"no GPU to run on: {e}"
    if REQUIRED:
        pytest.fail(f"{why}; OCTRACE_REQUIRE_GPU=1")
    pytest.skip(why)


@pytest.fixture(scope="module")
def gpu_bunny(bunny_oct):
    return on_gpu(lambda: octrace.Scene(bunny_oct, device="gpu"))


def same_bits(a, b, what):
    """Equal arrays, floats compared by their bits (-0.0 and 0.0 differ, NaN equals NaN)."""
    a, b = np.asarray(a), np.asarray(b)
    assert a.dtype == b.dtype and a.shape == b.shape, f"{what}: {a.dtype}{a.shape} vs {b.dtype}{b.shape}"
    if a.dtype.kind == "f":
        a, b = a.view(np.uint32 if a.itemsize == 4 else np.uint64), b.view(np.uint32 if b.itemsize == 4 else np.uint64)
    differ = np.flatnonzero((a != b).reshape(a.shape[0], -1).any(axis=1)) if a.ndim else []
    assert len(differ) == 0, f"{what}: {len(differ)} rays differ, the first {differ[:5]}"


def same_dicts(gpu, cpu, what):
    assert gpu.keys() == cpu.keys(), what
    for key in cpu:
        same_bits(gpu[key], cpu[key], f"{what}: {key}")


def some(rays, n):
    """`n` rays spread over the set (lavapipe runs the kernel on the CPU's cores)."""
    return np.ascontiguousarray(rays[:: max(1, len(rays) // n)][:n])


def test_the_gpu_scene_says_where_it_runs(gpu_bunny, bunny):
    assert gpu_bunny.device == "gpu" and bunny.device == "cpu"
    assert bunny.adapter == "cpu" and gpu_bunny.adapter != "cpu"
    assert "on the gpu" in repr(gpu_bunny)


def test_cast_rays_on_the_gpu_equals_the_cpu(gpu_bunny, bunny, standard_set):
    name, _, rays = standard_set
    rays = some(rays, 1 << 16)
    same_dicts(gpu_bunny.cast_rays(rays), bunny.cast_rays(rays), f"{name}: cast_rays")
    same_dicts(
        gpu_bunny.cast_rays(rays, surface=True), bunny.cast_rays(rays, surface=True), f"{name}: surface=True"
    )
    # One host thread answers as all.
    same_dicts(gpu_bunny.cast_rays(rays[:4096], nthreads=1), bunny.cast_rays(rays[:4096]), f"{name}: one thread")


def test_occlusions_on_the_gpu_equal_the_cpu(gpu_bunny, bunny, standard_set):
    name, _, rays = standard_set
    rays = some(rays, 1 << 16)
    t = bunny.cast_rays(rays)["t_hit"]
    same_bits(gpu_bunny.test_occlusions(rays), bunny.test_occlusions(rays), f"{name}: occlusions")
    # The interval: up to just short of each hit (nothing), and from just past it.
    finite = np.isfinite(t)
    near = np.float32(0.5) * t[finite].min()
    for tnear, tfar in [(0.0, near), (near, np.inf), (0.0, float(np.median(t[finite])))]:
        same_bits(
            gpu_bunny.test_occlusions(rays, tnear=tnear, tfar=tfar),
            bunny.test_occlusions(rays, tnear=tnear, tfar=tfar),
            f"{name}: occlusions in [{tnear}, {tfar}]",
        )


def test_counts_and_lists_on_the_gpu_equal_the_cpu(gpu_bunny, bunny, standard_set):
    name, _, rays = standard_set
    rays = some(rays, 1 << 14)
    same_bits(gpu_bunny.count_intersections(rays), bunny.count_intersections(rays), f"{name}: counts")
    same_dicts(gpu_bunny.list_intersections(rays), bunny.list_intersections(rays), f"{name}: lists")
    same_dicts(
        gpu_bunny.list_intersections(rays, max_hits=1),
        bunny.list_intersections(rays, max_hits=1),
        f"{name}: first crossings",
    )
    with pytest.raises(MemoryError, match="max_memory|budget|bytes"):
        gpu_bunny.list_intersections(rays, max_memory=64)


def torus_arrays(n=96, m=48, big=1.0, small=0.4):
    """A closed torus about the z axis: n x m quads, two triangles each."""
    a, b = np.meshgrid(np.arange(n) * 2 * np.pi / n, np.arange(m) * 2 * np.pi / m, indexing="ij")
    ring = big + small * np.cos(b)
    v = np.stack([ring * np.cos(a), ring * np.sin(a), small * np.sin(b)], axis=-1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(n), np.arange(m), indexing="ij")
    p, q, r, s = i * m + j, ((i + 1) % n) * m + j, ((i + 1) % n) * m + (j + 1) % m, i * m + (j + 1) % m
    t = np.concatenate([np.stack([p, q, r], -1).reshape(-1, 3), np.stack([p, r, s], -1).reshape(-1, 3)])
    return v.astype(np.float32), t


def test_lengths_inside_on_the_gpu_equal_the_cpu(gpu_bunny):
    # The bunny is open: no inside, on either device.
    with pytest.raises(octrace.NotClosedError):
        gpu_bunny.length_inside(np.array([[0, 0, 0, 1, 0, 0]], np.float32))
    v, t = torus_arrays()
    cpu = octrace.Scene.from_arrays(v, t)
    gpu = on_gpu(lambda: octrace.Scene.from_arrays(v, t, device="gpu"))
    assert cpu.is_closed
    rng = np.random.default_rng(11)
    rays = np.concatenate([rng.uniform(-1.6, 1.6, (1 << 14, 3)), rng.normal(size=(1 << 14, 3))], 1).astype(np.float32)
    for tmax in (np.inf, 0.5):
        lengths = cpu.length_inside(rays, tmax)
        assert (lengths > 0).mean() > 0.05
        same_bits(gpu.length_inside(rays, tmax), lengths, f"torus: lengths to {tmax}")


def test_ties_on_a_cubes_vertices_and_edges_are_the_cpus(bunny_oct):
    v, t = cube_arrays(-1.0, 1.0)
    cpu = octrace.Scene.from_arrays(v, t)
    gpu = on_gpu(lambda: octrace.Scene.from_arrays(v, t, device="gpu"))
    # Rays from many directions at the cube's vertices, edge midpoints and face
    # centres, and across its diagonals: every one meets triangles at a shared edge
    # or vertex, where the lowest triangle index must win on both.
    rng = np.random.default_rng(7)
    g = np.array([-1, 0, 1], np.float32)
    targets = np.array([[x, y, z] for x in g for y in g for z in g if (x, y, z) != (0, 0, 0)], np.float32)
    dirs = rng.normal(size=(256, 3)).astype(np.float32)
    origins = (targets[:, None, :] - 3 * dirs[None, :, :]).reshape(-1, 3)
    rays = np.concatenate([origins, np.tile(dirs, (len(targets), 1))], axis=1).astype(np.float32)
    same_dicts(gpu.cast_rays(rays), cpu.cast_rays(rays), "cube: cast_rays")
    same_bits(gpu.count_intersections(rays), cpu.count_intersections(rays), "cube: counts")
    same_dicts(gpu.list_intersections(rays), cpu.list_intersections(rays), "cube: lists")
    same_bits(gpu.length_inside(rays), cpu.length_inside(rays), "cube: lengths")


def test_a_pickled_gpu_scene_opens_on_the_gpu(gpu_bunny, bunny, standard_set):
    again = pickle.loads(pickle.dumps(gpu_bunny))
    assert again.device == "gpu"
    rays = some(standard_set[2], 4096)
    same_dicts(again.cast_rays(rays), bunny.cast_rays(rays), "unpickled")


def test_inside_and_outside_on_the_gpu_are_the_cpus():
    v, t = torus_arrays()
    cpu = octrace.Scene.from_arrays(v, t)
    gpu = on_gpu(lambda: octrace.Scene.from_arrays(v, t, device="gpu"))
    rng = np.random.default_rng(5)
    points = rng.uniform(-1.6, 1.6, (1 << 15, 3)).astype(np.float32)
    # Beside the surface, on it (the vertices) and on the triangles' edges.
    points = np.concatenate([points, v, (v[t[:, 0]] + v[t[:, 1]]) / 2, v + 1e-6]).astype(np.float32)
    inside = cpu.contains(points)
    assert 0.1 < inside.mean() < 0.9
    same_bits(gpu.contains(points), inside, "torus: contains")
    same_bits(gpu.compute_occupancy(points), cpu.compute_occupancy(points), "torus: occupancy")


def test_point_queries_on_a_gpu_scene_are_the_cpus(gpu_bunny, bunny):
    rng = np.random.default_rng(3)
    lo, hi = map(np.array, bunny.bounds)
    points = (lo + (hi - lo) * rng.random((2000, 3))).astype(np.float32)
    same_bits(gpu_bunny.compute_distance(points), bunny.compute_distance(points), "distances")
    same_bits(gpu_bunny.compute_signed_distance(points), bunny.compute_signed_distance(points), "signed")
    same_bits(gpu_bunny.compute_occupancy(points, nsamples=3), bunny.compute_occupancy(points, nsamples=3), "votes")


def test_a_device_not_known_is_refused(bunny_oct):
    with pytest.raises(ValueError, match="device"):
        octrace.Scene(bunny_oct, device="cuda")


def test_without_the_gpu_the_error_says_how_to_build_it(bunny_oct):
    if octrace.HAS_GPU:
        pytest.skip("the module has the GPU")
    with pytest.raises(octrace.GpuError, match="features gpu"):
        octrace.Scene(bunny_oct, device="gpu")


def test_raycasting_scene_takes_open3ds_devices(bunny):
    v, t = torus_arrays()
    rays = np.concatenate([np.full((64, 3), 3.0), -np.ones((64, 3))], 1).astype(np.float32)
    rays[:, :3] += np.linspace(-1, 1, 64, dtype=np.float32)[:, None] * [1, -1, 0]
    want = octrace.RaycastingScene()
    want.add_triangles(v, t)
    assert np.isfinite(want.cast_rays(rays)["t_hit"].numpy()).sum() > 20
    for device in ("gpu", "CUDA:0", "SYCL:0"):
        scene = octrace.RaycastingScene(device=device)
        scene.add_triangles(v, t)
        got = on_gpu(lambda: scene.cast_rays(rays))
        same_dicts({k: np.asarray(a) for k, a in got.items()},
                   {k: np.asarray(a) for k, a in want.cast_rays(rays).items()}, f"RaycastingScene({device!r})")
    with pytest.raises(ValueError, match="device"):
        octrace.RaycastingScene(device="TPU:0")


def fan_arrays(n=600):
    """A closed double cone whose 2n triangles meet at its two apexes: the leaves there
    list hundreds of triangles around one vertex (fans, which the CPU walks with the
    watertight test)."""
    a = np.arange(n) * 2 * np.pi / n
    ring = np.stack([np.cos(a), np.sin(a), np.zeros(n)], 1)
    v = np.concatenate([ring, [[0, 0, 1], [0, 0, -1]]]).astype(np.float32)
    i, j = np.arange(n), (np.arange(n) + 1) % n
    t = np.concatenate([np.stack([i, j, np.full(n, n)], 1), np.stack([j, i, np.full(n, n + 1)], 1)])
    return v, t


def test_a_scene_with_fans_answers_as_the_cpu_module():
    v, t = fan_arrays()
    cpu = octrace.Scene.from_arrays(v, t)
    gpu = on_gpu(lambda: octrace.Scene.from_arrays(v, t, device="gpu"))
    assert sum(cpu.inspect()["fans"].values()) > 0
    # Rays at the apexes and beside them, from all around.
    rng = np.random.default_rng(9)
    targets = np.concatenate([np.tile([[0, 0, 1], [0, 0, -1]], (512, 1)), rng.normal(0, 1e-3, (1024, 3))])
    targets[1024:, 2] += np.where(np.arange(1024) % 2 == 0, 1, -1)
    dirs = rng.normal(size=(2048, 3))
    rays = np.concatenate([targets - 3 * dirs, dirs], 1).astype(np.float32)
    same_dicts(gpu.cast_rays(rays), cpu.cast_rays(rays), "fans: cast_rays")
    same_dicts(gpu.list_intersections(rays), cpu.list_intersections(rays), "fans: lists")


def test_a_world_on_the_gpu_answers_as_on_the_cpu(bunny_oct):
    """`World(device="gpu")`: the instances' walks on the GPU, the CPU's answers bit for
    bit (hits, occlusion, crossings counted and listed), through moves and a scene added
    after the first query."""
    gpu = on_gpu(lambda: octrace.World(device="gpu"))
    cpu = octrace.World()
    assert gpu.device == "gpu" and "on the gpu" in repr(gpu)
    rng = np.random.default_rng(11)
    bunny = octrace.Scene(bunny_oct)
    ids = []
    for k in range(24):
        m = np.eye(4)
        m[:3, 3] = [0.25 * (k % 6), 0.2 * (k // 6), 0.0]
        ids.append(gpu.add(bunny, m))
        cpu.add(bunny, m)
    gpu.commit()
    cpu.commit()
    o = rng.uniform([-0.3, -0.2, 1.0], [1.5, 0.9, 1.2], (4096, 3))
    target = rng.uniform([-0.2, 0.0, -0.1], [1.4, 0.8, 0.1], (4096, 3))
    rays = np.hstack([o, target - o]).astype(np.float32)

    def same(what):
        same_dicts(gpu.cast_rays(rays), cpu.cast_rays(rays), what)
        same_bits(gpu.test_occlusions(rays, tfar=0.9), cpu.test_occlusions(rays, tfar=0.9), what)

    same("24 bunnies")
    assert np.isfinite(gpu.cast_rays(rays)["t_hit"]).sum() > 1000
    for w in (gpu, cpu):
        for k in ids[::3]:
            m = w.transform(k)
            m[2, 3] -= 0.3
            w.set_transform(k, m)
        w.add_triangles(*cube_arrays(0.3, 0.5))
        w.commit()
    same("moved, and a cube")
    # From farther, through the crowd: crossings counted and listed.
    rays[:, :3] = rays[:, :3] * 4.0 - np.float32([0, 0, 3])
    same_bits(gpu.count_intersections(rays), cpu.count_intersections(rays), "counts")
    assert gpu.count_intersections(rays).max() >= 4
    same_dicts(gpu.list_intersections(rays, max_hits=5), cpu.list_intersections(rays, max_hits=5), "lists")
    with pytest.raises(ValueError, match="device"):
        octrace.World(device="TPU:0")
