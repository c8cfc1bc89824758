#!/usr/bin/env python3
"""octrace's Python module beside Open3D's RaycastingScene and trimesh, from Python, on
the same rays: opening a scene, nearest hits, occlusion, every hit, counts, and (for a
closed mesh) inside/outside of points; one thread and all.

Every figure is the median of --runs interleaved rounds (each round times every peer
once, so that a noisy spell weighs on all of them alike). The rays are the mesh's
standard sets (bench/RAYS.md), written by `octrace rays`; octrace's "Rust" rows are
`octrace trace`'s own tracing time on the same rays (the Rust batch call, no Python),
so that the module's overhead reads off beside them. Answers are compared as they are
timed: octrace's nearest hits against Open3D's (distances within 1e-4 relative where
both hit; the rays where one hits and not the other are counted).

Usage:

    cargo build --release -p octrace && pip install ./python
    octrace bake bunny.obj -o bunny.oct
    python3 bench/python.py bunny.obj bunny.oct --octrace target/release/octrace

Optional dependencies (PyPI): open3d-cpu, trimesh, embreex. Peers that are not
installed are left out. A table prints; --json writes the figures as JSON too.
"""

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

import octrace


def timed(f):
    t = time.perf_counter()
    out = f()
    return time.perf_counter() - t, out


def standard_rays(cli, scene_path, name, work):
    path = os.path.join(work, f"{name}.rays")
    subprocess.run([cli, "rays", scene_path, "--set", name, "-o", path], check=True, capture_output=True)
    raw = np.fromfile(path, dtype="<f4").reshape(-1, 8)
    return path, np.ascontiguousarray(raw[:, [0, 1, 2, 4, 5, 6]])


def rust_seconds(cli, scene_path, ray_path, threads, work, mode=()):
    """`octrace trace`'s tracing time (the Rust batch call alone)."""
    out = os.path.join(work, "hits.bin")
    res = subprocess.run([cli, "trace", scene_path, "--rays", ray_path, "-o", out, "--json",
                          "--threads", str(threads), *mode], check=True, capture_output=True, text=True)
    return json.loads(res.stdout)["seconds"]


def load_mesh(path):
    import trimesh

    mesh = trimesh.load(path, force="mesh", process=False)
    return np.asarray(mesh.vertices, np.float32), np.asarray(mesh.faces, np.uint32)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("mesh", help="the mesh the peers load (OBJ)")
    ap.add_argument("scene", help="the same mesh baked by octrace")
    ap.add_argument("--octrace", default="octrace", help="the octrace command line")
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--threads", default="1,0", help="thread counts to time (0: all cores)")
    ap.add_argument("--json", help="write the figures to this file")
    args = ap.parse_args()
    threads = [int(t) for t in args.threads.split(",")]
    work = tempfile.mkdtemp(prefix="octrace-bench-")
    rows = {}

    def record(name, seconds, count):
        rows.setdefault(name, []).append((seconds, count))

    vertices, faces = load_mesh(args.mesh)
    try:
        import open3d as o3d
    except ImportError:
        o3d = None
    try:
        import trimesh
        import trimesh.ray.ray_pyembree  # noqa: F401 (embreex)

        has_trimesh = True
    except ImportError:
        has_trimesh = False

    scene = octrace.Scene(args.scene)
    sets = {name: standard_rays(args.octrace, args.scene, name, work) for name in ("primary", "incoherent")}
    closed = scene.is_closed
    points = None
    if closed:
        lo, hi = map(np.array, scene.bounds)
        points = np.random.default_rng(1).uniform(lo, hi, (1_000_000, 3)).astype(np.float32)

    o3d_scene = None
    for run in range(args.runs):
        # Opening: octrace validated (read into memory, every checksum and rule), mapped
        # and validated, trusted (header only); Open3D's build (add_triangles, then the
        # first query builds the BVH); trimesh's (embreex) build.
        record("open: octrace Scene(path)", *[timed(lambda: octrace.Scene(args.scene))[0], 1])
        record("open: octrace Scene(path, mmap=True)", timed(lambda: octrace.Scene(args.scene, mmap=True))[0], 1)
        record("open: octrace Scene(path, trusted=True)", timed(lambda: octrace.Scene(args.scene, trusted=True))[0], 1)
        one = np.zeros((1, 6), np.float32)
        one[0, 5] = 1
        if o3d is not None:
            def build():
                s = o3d.t.geometry.RaycastingScene()
                s.add_triangles(o3d.core.Tensor(vertices), o3d.core.Tensor(faces))
                s.cast_rays(o3d.core.Tensor(one))
                return s

            seconds, o3d_scene = timed(build)
            record("open: Open3D build", seconds, 1)
        if has_trimesh:
            def tri_build():
                m = trimesh.Trimesh(vertices, faces, process=False)
                m.ray.intersects_first(one[:, :3], one[:, 3:])
                return m

            seconds, tri_mesh = timed(tri_build)
            record("open: trimesh (embreex) build", seconds, 1)

        for name, (ray_path, rays) in sets.items():
            n = len(rays)
            for t in threads:
                tag = f"{name}, {'all cores' if t == 0 else f'{t} thread'}"
                record(f"nearest {tag}: octrace Rust batch", rust_seconds(args.octrace, args.scene, ray_path,
                                                                         t if t else os.cpu_count(), work), n)
                seconds, ours = timed(lambda: scene.cast_rays(rays, nthreads=t))
                record(f"nearest {tag}: octrace cast_rays", seconds, n)
                if o3d_scene is not None:
                    tensor = o3d.core.Tensor(rays)
                    seconds, theirs = timed(lambda: o3d_scene.cast_rays(tensor, nthreads=t))
                    record(f"nearest {tag}: Open3D cast_rays", seconds, n)
                    if run == 0:
                        a, b = ours["t_hit"], theirs["t_hit"].numpy()
                        both = np.isfinite(a) & np.isfinite(b)
                        differ = int((np.isfinite(a) != np.isfinite(b)).sum())
                        far = int((np.abs(a[both] - b[both]) > 1e-4 * np.abs(b[both])).sum())
                        rows.setdefault(f"agreement {name}", [(differ, far)])
                if has_trimesh and t == 0:
                    seconds, _ = timed(lambda: tri_mesh.ray.intersects_first(rays[:, :3], rays[:, 3:]))
                    record(f"nearest {tag}: trimesh intersects_first", seconds, n)
                seconds, _ = timed(lambda: scene.test_occlusions(rays, nthreads=t))
                record(f"occluded {tag}: octrace test_occlusions", seconds, n)
                if o3d_scene is not None:
                    seconds, _ = timed(lambda: o3d_scene.test_occlusions(tensor, nthreads=t))
                    record(f"occluded {tag}: Open3D test_occlusions", seconds, n)
                if name == "incoherent":
                    record(f"all hits {tag}: octrace Rust batch",
                           rust_seconds(args.octrace, args.scene, ray_path, t if t else os.cpu_count(), work,
                                        ("--all-hits",)), n)
                    seconds, _ = timed(lambda: scene.list_intersections(rays, nthreads=t))
                    record(f"all hits {tag}: octrace list_intersections", seconds, n)
                    seconds, _ = timed(lambda: scene.count_intersections(rays, nthreads=t))
                    record(f"counts {tag}: octrace count_intersections", seconds, n)
                    if o3d_scene is not None:
                        seconds, _ = timed(lambda: o3d_scene.list_intersections(tensor, nthreads=t))
                        record(f"all hits {tag}: Open3D list_intersections", seconds, n)
                        seconds, _ = timed(lambda: o3d_scene.count_intersections(tensor, nthreads=t))
                        record(f"counts {tag}: Open3D count_intersections", seconds, n)
                    if has_trimesh and t == 0:
                        seconds, _ = timed(lambda: tri_mesh.ray.intersects_location(rays[:, :3], rays[:, 3:],
                                                                                    multiple_hits=True))
                        record(f"all hits {tag}: trimesh intersects_location", seconds, n)
        if points is not None:
            for t in threads:
                tag = f"{'all cores' if t == 0 else f'{t} thread'}"
                seconds, _ = timed(lambda: scene.compute_occupancy(points, nthreads=t))
                record(f"inside {tag}: octrace compute_occupancy", seconds, len(points))
                if o3d_scene is not None:
                    tensor = o3d.core.Tensor(points)
                    seconds, _ = timed(lambda: o3d_scene.compute_occupancy(tensor, nthreads=t))
                    record(f"inside {tag}: Open3D compute_occupancy", seconds, len(points))
        print(f"round {run + 1} of {args.runs}", file=sys.stderr)

    table = {}
    print(f"{'query: who':<60} {'median':>12} {'M/s':>8}")
    for name, samples in rows.items():
        if name.startswith("agreement"):
            differ, far = samples[0]
            print(f"{name}: octrace and Open3D disagree on hit or miss for {differ} rays, "
                  f"on the distance (1e-4) for {far}")
            table[name] = {"hit_or_miss": differ, "distance": far}
            continue
        seconds = statistics.median(s for s, _ in samples)
        count = samples[0][1]
        rate = count / seconds / 1e6 if count > 1 else None
        shown = f"{seconds * 1e3:10.3f} ms" if count == 1 else f"{seconds:10.3f} s "
        print(f"{name:<60} {shown:>12} {'' if rate is None else f'{rate:8.2f}'}")
        table[name] = {"median_s": seconds, "count": count, "m_per_s": rate}
    if args.json:
        with open(args.json, "w") as f:
            json.dump(table, f, indent=1)


if __name__ == "__main__":
    main()
