#!/usr/bin/env python3
"""Closest points, distances and signed distances: octrace beside Open3D, FCPW,
libigl and point-cloud-utils, on the same points, one core (run it under `taskset -c 0`: FCPW and libigl
use every core they see), medians of three runs in one process.

Points: uniform in 1.1x the mesh's box, and within 1 % of the box's diagonal from the
surface (random points of random triangles, moved in a random direction). Wrong
answers are counted against octrace's exact ones (checked in its tests against exact
arithmetic and the brute force): a distance off by more than 1e-5 of the box's
diagonal (Open3D and FCPW work in float), a sign that differs from the exact
inside/outside (closed meshes).

    taskset -c 0 python3 bench/distances.py ../shared/meshes/dragon.obj --points 20000

Needs numpy, octrace (`pip install ./python`) and open3d-cpu; FCPW (`fcpw`), libigl
(`libigl`) and point-cloud-utils (`point-cloud-utils`) are timed where installed.
"""

import argparse
import os
import tempfile
import time

import numpy as np

import octrace


def median_rate(n, f, runs=3):
    rates = []
    out = None
    for _ in range(runs):
        t = time.perf_counter()
        out = f()
        rates.append(n / (time.perf_counter() - t) / 1e6)
    return float(np.median(rates)), out


def point_sets(v, t, n, seed=1):
    rng = np.random.default_rng(seed)
    lo, hi = v.min(axis=0), v.max(axis=0)
    size = hi - lo
    uniform = lo - 0.05 * size + 1.1 * size * rng.random((n, 3))
    tri = v[t[rng.integers(0, len(t), n)]]
    a, b = rng.random((2, n, 1))
    flip = (a + b) > 1
    a, b = np.where(flip, 1 - a, a), np.where(flip, 1 - b, b)
    on = tri[:, 0] + a * (tri[:, 1] - tri[:, 0]) + b * (tri[:, 2] - tri[:, 0])
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    near = on + d * (0.01 * np.linalg.norm(size) * rng.random((n, 1)))
    return {"uniform 1.1x box": uniform.astype(np.float32), "within 1% of the surface": near.astype(np.float32)}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("mesh", help="an OBJ (or any mesh Open3D reads)")
    ap.add_argument("--points", type=int, default=20000, help="points of each kind")
    ap.add_argument("--queries", default="closest,distance,signed,winding",
                    help="which to time, comma-separated (default: all)")
    args = ap.parse_args()
    queries = set(args.queries.split(","))

    import open3d as o3d
    legacy = o3d.io.read_triangle_mesh(args.mesh)
    v = np.asarray(legacy.vertices, np.float32)
    t = np.asarray(legacy.triangles, np.int64)
    diag = float(np.linalg.norm(v.max(axis=0) - v.min(axis=0)))
    print(f"{args.mesh}: {len(t):,} triangles; {args.points:,} points of each kind; "
          f"{os.cpu_count()} CPUs visible (pin with taskset -c 0)")

    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "mesh.oct")
        octrace.bake_arrays(v, t, path)
        ours = octrace.Scene(path)
        closed = ours.is_closed
        t0 = time.perf_counter()
        ours.compute_distance(v[:1], nthreads=1)  # the search's bounds, made once a scene
        bounds_s = time.perf_counter() - t0
        o3d_scene = o3d.t.geometry.RaycastingScene()
        o3d_scene.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(legacy))
        peers = {}
        try:
            import fcpw
            f = fcpw.scene_3D()
            f.set_object_count(1)
            f.set_object_vertices(np.asfortranarray(v), 0)
            f.set_object_triangles(np.asfortranarray(t.astype(np.int32)), 0)
            f.build(fcpw.aggregate_type.bvh_surface_area, True)
            peers["fcpw"] = f
        except ImportError:
            pass
        try:
            import igl
            peers["igl"] = igl
        except ImportError:
            pass
        try:
            import point_cloud_utils as pcu
            peers["pcu"] = pcu
        except ImportError:
            pass
        print(f"octrace: closed {closed}; the search's bounds {bounds_s * 1e3:.0f} ms once")

        rows = []
        for kind, p in point_sets(v, t, args.points).items():
            n = len(p)
            # The exact answers the peers' are checked against (not needed for winding
            # numbers, checked against libigl's brute force).
            exact_d = ours.compute_distance(p, nthreads=1) if queries - {"winding"} else None
            exact_in = ours.contains(p, nthreads=1) if closed else None
            tensor = o3d.core.Tensor(p)

            def wrong_d(d):
                return int((np.abs(np.asarray(d, np.float64) - exact_d) > 1e-5 * diag).sum())

            def wrong_sign(s):
                if exact_in is None:
                    return ""
                return int(((np.asarray(s) < 0) != exact_in)[exact_d > 0].sum())

            if "closest" in queries:
                closest_rows(rows, kind, p, ours, o3d_scene, peers, v, t, wrong_d)
            if "distance" in queries:
                r, _ = median_rate(n, lambda: ours.compute_distance(p, nthreads=1))
                rows.append((kind, "distance", "octrace", r, 0))
                r, d = median_rate(n, lambda: o3d_scene.compute_distance(tensor, nthreads=1))
                rows.append((kind, "distance", "Open3D", r, wrong_d(d.numpy())))
            if closed and "signed" in queries:
                signed_rows(rows, kind, p, ours, o3d_scene, peers, v, t, wrong_d, wrong_sign)
            if "winding" in queries:
                winding_rows(rows, kind, p, ours, peers, v, t, closed)
        print("\n| points | query | who | M points/s | wrong (winding: largest error) |\n| --- | --- | --- | ---: | ---: |")
        for kind, query, who, r, wrong in rows:
            print(f"| {kind} | {query} | {who} | {r:.4f} | {wrong} |")


def closest_rows(rows, kind, p, ours, o3d_scene, peers, v, t, wrong_d):
    import open3d as o3d
    n = len(p)
    r, _ = median_rate(n, lambda: ours.compute_closest_points(p, nthreads=1))
    rows.append((kind, "closest points", "octrace", r, 0))
    r, d = median_rate(n, lambda: o3d_scene.compute_closest_points(o3d.core.Tensor(p), nthreads=1))
    dd = np.linalg.norm(d["points"].numpy() - p, axis=1)
    rows.append((kind, "closest points", "Open3D", r, wrong_d(dd)))
    if "fcpw" in peers:
        import fcpw
        f = peers["fcpw"]
        inter = fcpw.interaction_3D_list()
        radii = np.full(n, np.inf, np.float32)
        pf = np.asfortranarray(p)
        r, _ = median_rate(n, lambda: f.find_closest_points(pf, radii, inter))
        fd = np.array([i.d for i in inter])
        rows.append((kind, "closest points", "FCPW", r, wrong_d(fd)))
    if "pcu" in peers:
        # Its tree is built in each call, as users call it: timed apart first.
        pcu, vd = peers["pcu"], v.astype(np.float64)
        pd = p.astype(np.float64)
        t0 = time.perf_counter()
        pcu.closest_points_on_mesh(pd[:1], vd, t)
        pre = time.perf_counter() - t0
        r, res = median_rate(n, lambda: pcu.closest_points_on_mesh(pd, vd, t))
        rows.append((kind, f"closest points (its tree, {pre * 1e3:.0f} ms, built in the call)",
                     "point-cloud-utils", r, wrong_d(res[0])))


def signed_rows(rows, kind, p, ours, o3d_scene, peers, v, t, wrong_d, wrong_sign):
    import open3d as o3d
    n = len(p)
    r, s = median_rate(n, lambda: ours.compute_signed_distance(p, nthreads=1))
    rows.append((kind, "signed distance", "octrace", r, wrong_sign(s)))
    r, s = median_rate(n, lambda: o3d_scene.compute_signed_distance(o3d.core.Tensor(p), nthreads=1))
    rows.append((kind, "signed distance (1 vote)", "Open3D", r,
                 f"{wrong_d(np.abs(s.numpy()))} d, {wrong_sign(s.numpy())} signs"))
    if "pcu" in peers:
        pcu, vd, pd = peers["pcu"], v.astype(np.float64), p.astype(np.float64)
        r, res = median_rate(n, lambda: pcu.signed_distance_to_mesh(pd, vd, t))
        rows.append((kind, "signed distance", "point-cloud-utils", r,
                     f"{wrong_d(np.abs(res[0]))} d, {wrong_sign(res[0])} signs"))
    if "igl" in peers:
        igl = peers["igl"]
        vd, pd = v.astype(np.float64), p.astype(np.float64)
        r, res = median_rate(n, lambda: igl.signed_distance(
            pd, vd, t, sign_type=igl.SIGNED_DISTANCE_TYPE_FAST_WINDING_NUMBER), runs=1)
        rows.append((kind, "signed distance (fast winding)", "libigl", r,
                     f"{wrong_d(np.abs(res[0]))} d, {wrong_sign(res[0])} signs"))


def winding_rows(rows, kind, p, ours, peers, v, t, closed):
    """Winding numbers: the largest error against the brute-force sum over every
    triangle (libigl's `winding_number`, independent of octrace) on the first 200
    points. libigl's `fast_winding_number` builds its tree in every call, as users
    call it; the row below it takes that set-up (timed on one point) away."""
    n = len(p)
    m = min(n, 200)
    ours.winding_number(v[:1], nthreads=1)  # the clusters, made once a scene
    igl = peers.get("igl")
    exact_w = None if igl is None else igl.winding_number(v.astype(np.float64), t, p[:m].astype(np.float64))

    def err(w):
        return "" if exact_w is None else f"{np.abs(np.asarray(w)[:m] - exact_w).max():.1e}"

    name = "winding number (exact)" if closed else "winding number (beta 2)"
    r, w = median_rate(n, lambda: ours.winding_number(p, nthreads=1))
    rows.append((kind, name, "octrace", r, err(w)))
    # The guaranteed sums run at some 1,000 points a second: on 20,000 points at most.
    few = p[:20000]
    for tol in (1e-2, 1e-4):
        if not closed:
            r, w = median_rate(len(few), lambda: ours.winding_number(few, nthreads=1, tolerance=tol), runs=1)
            rows.append((kind, f"winding number (within {tol:g}, guaranteed; {len(few):,} points)", "octrace", r,
                         err(w)))
    if igl is not None:
        vd, pd = v.astype(np.float64), p.astype(np.float64)
        pres = []
        for _ in range(3):
            t0 = time.perf_counter()
            igl.fast_winding_number(vd, t, pd[:1])
            pres.append(time.perf_counter() - t0)
        pre = float(np.median(pres))
        r, w = median_rate(n, lambda: igl.fast_winding_number(vd, t, pd))
        rows.append((kind, f"fast_winding_number (beta 2; its tree, {pre * 1e3:.0f} ms, built in the call)",
                     "libigl", r, err(w)))
        rows.append((kind, "fast_winding_number, its tree's set-up taken away", "libigl",
                     n / max(n / r / 1e6 - pre, 1e-9) / 1e6, err(w)))


if __name__ == "__main__":
    main()
