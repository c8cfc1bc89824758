#!/usr/bin/env python3
"""Open3D and trimesh on the ordered queries, beside octrace, on the same rays and points.

Times Open3D's RaycastingScene (Embree 4 inside) `list_intersections`,
`count_intersections` and `compute_occupancy` (one vote and three), trimesh's
`intersects_location(multiple_hits=True)` (embreex when installed) and `contains`, and
octrace's `trace --all-hits`, `trace --counts` and `contains` (through its CLI, tracing
time as it reports it), on one thread unless --threads says otherwise; and counts wrong
answers against references that do not depend on any of them:

- points: `octrace contains --reference`, the exact oracle (crossings along the axes,
  every sign by Shewchuk's predicates); points on the surface or undecided are left out;
- rays (a closed mesh): a ray from a point to infinity crosses a closed surface an odd
  number of times exactly when the point is inside, so a count or list whose parity
  disagrees with the exact oracle at the ray's origin is wrong; a list that names a
  triangle twice, or is out of order, is wrong too.

Usage (a closed mesh; the skull of BENCHMARKS.md, say):

    octrace bake skull.obj -o skull.oct
    python3 bench/peers.py skull.obj skull.oct --octrace target/release/octrace

Optional dependencies (PyPI): numpy, open3d-cpu, trimesh, embreex. Peers that are not
installed are left out. Results print as a table, and as JSON with --json.
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

RAY_DTYPE = np.dtype("<f4")
HIT_DTYPE = np.dtype([("t", "<f4"), ("triangle", "<u4"), ("u", "<f4"), ("v", "<f4"), ("enters", "<u4")])


def octrace(binary, *args):
    """Runs octrace; returns its summary (JSON where asked)."""
    out = subprocess.run([binary, *args], check=True, capture_output=True, text=True)
    return out.stdout


def median_rate(n, f, runs):
    """Median items/s (millions) of `runs` calls of f, and the last result."""
    rates, result = [], None
    for _ in range(runs):
        t = time.perf_counter()
        result = f()
        rates.append(n / (time.perf_counter() - t) / 1e6)
    return float(np.median(rates)), result


def read_mesh(path):
    """Vertices and faces as the file lists them (no merging, no repair)."""
    import trimesh

    mesh = trimesh.load(path, force="mesh", process=False)
    return np.asarray(mesh.vertices, dtype=np.float32), np.asarray(mesh.faces, dtype=np.int64)


def list_wrong(offsets, triangles, ts, truth_parity):
    """Rays whose list is wrong (parity unlike the truth where known, or a triangle
    twice), and rays whose list is out of order (not wrong for a peer that does not
    promise order, reported apart)."""
    wrong = unordered = 0
    for i in range(len(offsets) - 1):
        a, b = offsets[i], offsets[i + 1]
        tri, t = triangles[a:b], ts[a:b]
        bad = len(np.unique(tri)) != len(tri)
        if truth_parity[i] >= 0 and (b - a) % 2 != truth_parity[i]:
            bad = True
        wrong += bool(bad)
        unordered += bool(np.any(np.diff(t) < 0))
    return wrong, unordered


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("mesh", help="the mesh file (OBJ, PLY, ...) the scene was baked from")
    p.add_argument("scene", help="its .oct")
    p.add_argument("--octrace", default="octrace", help="the octrace binary")
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--runs", type=int, default=3)
    p.add_argument("--rays", type=int, default=1_000_000, help="the first N incoherent rays")
    p.add_argument("--points", type=int, default=1_000_000, help="N standard points")
    p.add_argument("--json", action="store_true")
    a = p.parse_args()

    work = tempfile.mkdtemp(prefix="octrace-peers-")
    path = lambda name: os.path.join(work, name)
    octrace(a.octrace, "rays", a.scene, "--set", "incoherent", "-o", path("rays.bin"))
    rays = np.fromfile(path("rays.bin"), RAY_DTYPE).reshape(-1, 8)[: a.rays]
    rays.tofile(path("rays.bin"))
    octrace(a.octrace, "points", a.scene, "--count", str(a.points), "-o", path("points.bin"))
    points = np.fromfile(path("points.bin"), RAY_DTYPE).reshape(-1, 3)
    # The exact oracle at the points, and at the rays' origins.
    octrace(a.octrace, "contains", a.scene, "--points", path("points.bin"), "--out", path("truth.bin"), "--reference")
    truth = np.fromfile(path("truth.bin"), np.uint8)
    np.ascontiguousarray(rays[:, 0:3]).tofile(path("origins.bin"))
    octrace(a.octrace, "contains", a.scene, "--points", path("origins.bin"), "--out", path("origin_truth.bin"), "--reference")
    origin_truth = np.fromfile(path("origin_truth.bin"), np.uint8)
    parity = np.where(origin_truth <= 1, origin_truth, 255).astype(np.int64)
    parity[parity == 255] = -1
    decided = truth <= 1
    closed = json.loads(octrace(a.octrace, "inspect", a.scene, "--json"))["surface"]["closed"]
    if not closed:
        # An open mesh has no inside: no truth for parities or points (the lists are
        # still checked for triangles named twice).
        print("the mesh is not closed: parities and points are not checked", file=sys.stderr)
        parity[:] = -1
        decided[:] = False

    rows = []

    def add(who, query, rate, wrong, note=""):
        rows.append({"peer": who, "query": query, "mitems_per_s": rate, "wrong": wrong, "note": note})

    threads = ["--threads", str(a.threads)]
    # octrace, through its CLI (the rate it reports: tracing alone).
    for query, flag in [("all hits", "--all-hits"), ("counts", "--counts")]:
        rates = []
        for _ in range(a.runs):
            s = json.loads(octrace(a.octrace, "trace", a.scene, "--rays", path("rays.bin"), "--out", path("o.bin"), flag, "--json", *threads))
            rates.append(s["mrays_per_s"])
        data = open(path("o.bin"), "rb").read()
        n = len(rays)
        if flag == "--all-hits":
            offsets = np.frombuffer(data, "<u8", n + 1)
            hits = np.frombuffer(data, HIT_DTYPE, offset=8 * (n + 1))
            wrong, unordered = list_wrong(offsets, hits["triangle"], hits["t"], parity)
            add("octrace", query, float(np.median(rates)), wrong, f"{unordered:,} lists out of order")
            continue
        else:
            counts = np.frombuffer(data, "<u4").reshape(-1, 2)[:, 0].astype(np.int64)
            wrong = int(np.sum((parity >= 0) & (counts % 2 != parity)))
        add("octrace", query, float(np.median(rates)), wrong)
    rates = []
    vote = [] if closed else ["--vote", "1"]  # an open mesh is refused without a vote
    for _ in range(a.runs):
        s = json.loads(octrace(a.octrace, "contains", a.scene, "--points", path("points.bin"), "--out", path("o.bin"), "--json", *vote, *threads))
        rates.append(s["mpoints_per_s"])
    ours = np.fromfile(path("o.bin"), np.uint8)
    add("octrace", "inside", float(np.median(rates)), int(np.sum(decided & (ours != truth))), "" if closed else "--vote 1")

    vertices, faces = read_mesh(a.mesh)
    try:
        import open3d as o3d

        mesh = o3d.t.geometry.TriangleMesh()
        mesh.vertex.positions = o3d.core.Tensor(vertices)
        mesh.triangle.indices = o3d.core.Tensor(faces.astype(np.int32))
        scene = o3d.t.geometry.RaycastingScene(nthreads=a.threads)
        scene.add_triangles(mesh)
        R = o3d.core.Tensor(np.ascontiguousarray(np.concatenate([rays[:, 0:3], rays[:, 4:7]], axis=1)))
        rate, out = median_rate(len(rays), lambda: scene.list_intersections(R, nthreads=a.threads), a.runs)
        offsets = out["ray_splits"].numpy()
        wrong, unordered = list_wrong(offsets, out["primitive_ids"].numpy(), out["t_hit"].numpy(), parity)
        add("Open3D", "all hits", rate, wrong, f"list_intersections ({unordered:,} lists out of order)")
        rate, out = median_rate(len(rays), lambda: scene.count_intersections(R, nthreads=a.threads), a.runs)
        counts = out.numpy().astype(np.int64)
        add("Open3D", "counts", rate, int(np.sum((parity >= 0) & (counts % 2 != parity))), "count_intersections")
        P = o3d.core.Tensor(points)
        for votes in (1, 3):
            rate, out = median_rate(len(points), lambda: scene.compute_occupancy(P, nthreads=a.threads, nsamples=votes), a.runs)
            occ = out.numpy().astype(np.uint8)
            add("Open3D", "inside", rate, int(np.sum(decided & (occ != truth))), f"compute_occupancy, {votes} vote{'s' if votes > 1 else ''}")
    except ImportError:
        print("open3d not installed: left out", file=sys.stderr)

    try:
        import trimesh

        tm = trimesh.Trimesh(vertices=vertices, faces=faces, process=False)
        intersector = tm.ray
        origins, directions = np.ascontiguousarray(rays[:, 0:3], np.float64), np.ascontiguousarray(rays[:, 4:7], np.float64)
        rate, out = median_rate(len(rays), lambda: intersector.intersects_location(origins, directions, multiple_hits=True), 1)
        _, index_ray, index_tri = out
        order = np.argsort(index_ray, kind="stable")
        index_ray, index_tri = index_ray[order], index_tri[order]
        offsets = np.searchsorted(index_ray, np.arange(len(rays) + 1))
        # trimesh returns locations, not distances: order is not checked, duplicates and parity are.
        wrong, _ = list_wrong(offsets, index_tri, np.zeros(len(index_tri)), parity)
        add("trimesh", "all hits", rate, wrong, f"intersects_location(multiple_hits=True), {type(intersector).__module__}")
        rate, out = median_rate(len(points), lambda: tm.contains(points.astype(np.float64)), 1)
        add("trimesh", "inside", rate, int(np.sum(decided & (out.astype(np.uint8) != truth))), "contains")
    except ImportError:
        print("trimesh not installed: left out", file=sys.stderr)

    summary = {
        "mesh": a.mesh, "threads": a.threads, "runs": a.runs, "rays": len(rays), "points": len(points),
        "rays_with_known_parity": int(np.sum(parity >= 0)), "points_decided": int(np.sum(decided)), "rows": rows,
    }
    if a.json:
        print(json.dumps(summary, indent=2))
        return
    print(f"{a.mesh}: {len(rays):,} incoherent rays, {len(points):,} points, {a.threads} thread(s), median of {a.runs}")
    print(f"{'query':<10} {'peer':<8} {'M items/s':>10} {'wrong':>8}  call")
    for r in rows:
        print(f"{r['query']:<10} {r['peer']:<8} {r['mitems_per_s']:>10.2f} {r['wrong']:>8,}  {r['note']}")


if __name__ == "__main__":
    main()
