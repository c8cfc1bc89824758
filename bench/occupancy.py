#!/usr/bin/env python3
"""Inside/outside of points: octrace's exact `contains` beside Open3D's one-vote
`compute_occupancy`, on the same points, one thread, medians of five runs in one
process (interleaved: octrace, Open3D, octrace, ...).

Points: uniform in 1.1x the mesh's box (the issue's measure), and within 1 % of the
box's diagonal from the surface (random points of random triangles, moved in a
random direction). "Wrong" counts Open3D's answers that differ from octrace's exact
ones (checked in its tests against exact arithmetic and an independent oracle).

    taskset -c 0 python3 bench/occupancy.py ../shared/meshes/dragon.obj --points 1000000

Needs numpy, octrace (`pip install ./python`) and open3d-cpu. The mesh must be closed.
"""

import argparse
import os
import tempfile
import time

import numpy as np

import octrace
from distances import point_sets  # the same points as the distance benchmark (this folder)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("mesh", help="a closed OBJ (or any mesh Open3D reads)")
    ap.add_argument("--points", type=int, default=1_000_000, help="points of each kind")
    ap.add_argument("--runs", type=int, default=5, help="timed runs of each, interleaved")
    args = ap.parse_args()

    import open3d as o3d
    legacy = o3d.io.read_triangle_mesh(args.mesh)
    v = np.asarray(legacy.vertices, np.float32)
    t = np.asarray(legacy.triangles, np.int64)
    print(f"{args.mesh}: {len(t):,} triangles; {args.points:,} points of each kind; "
          f"{os.cpu_count()} CPUs visible (pin with taskset -c 0)")
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "mesh.oct")
        octrace.bake_arrays(v, t, path)
        ours = octrace.Scene(path)
        if not ours.is_closed:
            raise SystemExit("the mesh is not closed: contains has no answer")
        t0 = time.perf_counter()
        ours.contains(v[:1], nthreads=1)  # the labels, made once a scene
        labels_s = time.perf_counter() - t0
        scene = o3d.t.geometry.RaycastingScene()
        scene.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(legacy))
        print(f"octrace: the labels {labels_s * 1e3:.0f} ms once")
        print("| points | octrace contains (M/s) | Open3D compute_occupancy, 1 vote (M/s) | ratio | Open3D wrong |")
        print("| --- | ---: | ---: | ---: | ---: |")
        for kind, p in point_sets(v, t, args.points).items():
            tensor = o3d.core.Tensor(p)
            ours_r, theirs_r = [], []
            exact = theirs = None
            for _ in range(args.runs):
                t0 = time.perf_counter()
                exact = ours.contains(p, nthreads=1)
                ours_r.append(len(p) / (time.perf_counter() - t0) / 1e6)
                t0 = time.perf_counter()
                theirs = scene.compute_occupancy(tensor, nthreads=1).numpy()
                theirs_r.append(len(p) / (time.perf_counter() - t0) / 1e6)
            a, b = float(np.median(ours_r)), float(np.median(theirs_r))
            wrong = int(((theirs > 0.5) != exact).sum())
            print(f"| {kind} | {a:.2f} | {b:.2f} | {a / b:.1f}x | {wrong} |")


if __name__ == "__main__":
    main()
