"""Hostile sizes raise, never abort the interpreter (issue 46).

Each case runs in a child interpreter under an address-space limit (RLIMIT_AS, as
`prlimit --as` sets): it must exit by itself, never by a signal, print the exception it
caught, and stay within the memory its budget states (its peak resident set, from
getrusage).
"""

import json
import subprocess
import sys
import textwrap

import pytest

GB = 1 << 30
MB = 1 << 20


def capped(code, cap):
    """Runs `code` in a child interpreter with at most `cap` bytes of address space.

    The code sets `answer` (anything JSON takes); the child prints it with its peak
    resident memory. Returns (the answer, the peak in bytes)."""
    script = textwrap.dedent(
        f"""
        import json, resource
        resource.setrlimit(resource.RLIMIT_AS, ({cap}, {cap}))
        import numpy as np, octrace
        def caught(call):
            try:
                call()
            except Exception as e:
                return [type(e).__name__, str(e)]
            return None
        answer = None
        """
    ) + textwrap.dedent(code) + textwrap.dedent(
        """
        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
        print(json.dumps({"answer": answer, "peak": peak}))
        """
    )
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, f"exit {out.returncode} (negative: a signal): {out.stderr[-2000:]}"
    result = json.loads(out.stdout.strip().splitlines()[-1])
    return result["answer"], result["peak"]


def test_the_bake_budget_stops_a_small_mesh_in_time():
    # Before: the tree's tally reached the budget only when a subtree handed to another
    # thread was done, which a 4-triangle mesh never does: 7.5 GB, an abort.
    answer, peak = capped(
        """
        v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], np.float32)
        t = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
        answer = caught(lambda: octrace.Scene.from_arrays(v, t, max_depth=20, leaf_size=1, max_memory=1 << 28))
        """,
        2 * GB,
    )
    assert answer[0] == "BakeError" and "past the bake's memory budget of 268,435,456" in answer[1], answer
    assert peak < 600 * MB, peak


STACK = """
quads = 2000
z = np.repeat(np.arange(quads, dtype=np.float32) / quads, 4)
corners = np.tile(np.array([[0, 0], [1, 0], [1, 1], [0, 1]], np.float32), (quads, 1))
v = np.column_stack([corners, z])
base = 4 * np.arange(quads)[:, None]
t = np.concatenate([base + [0, 1, 2], base + [0, 2, 3]])
scene = octrace.Scene.from_arrays(v, t)
i = np.arange(10000)
rays = np.zeros((10000, 6), np.float32)
rays[:, 0] = 0.05 + 0.9 * (i % 100) / 100
rays[:, 1] = 0.05 + 0.9 * (i // 100) / 100
rays[:, 2] = -1
rays[:, 5] = 1
"""


def test_every_hit_lists_stop_at_their_budget():
    # 2,000 stacked quads, 10,000 rays through all: 20 million crossings, 400 MB of lists
    # (before: grown without bound; the audit's 20,000 quads aborted the interpreter).
    answer, peak = capped(
        STACK
        + textwrap.dedent(
            """
        answer = [caught(lambda: scene.list_intersections(rays)),
                  caught(lambda: scene.list_intersections(rays, max_memory=64 << 20))]
        four = scene.list_intersections(rays, max_hits=4, max_memory=1 << 20)
        answer.append([int(four["ray_splits"][-1]), sorted(int(p) % quads for p in four["primitive_ids"][:4])])
        """
        ),
        GB,
    )
    default, given, four = answer
    # The default: a quarter of the memory the process may use, 256 MB under the cap.
    assert default[0] == "MemoryError" and "past the budget of 268435456 bytes" in default[1], default
    assert given[0] == "MemoryError" and "past the budget of 67108864 bytes" in given[1], given
    assert four == [40000, [0, 1, 2, 3]]
    assert peak < 700 * MB, peak


def test_allocations_past_memory_raise_memory_error():
    answer, peak = capped(
        """
        answer = [
            # 103 GB of rays, inside the documented sizes.
            caught(lambda: octrace.Scene.create_rays_pinhole(fov_deg=60, center=[0, 0, 1], eye=[0, 0, 0],
                                                             up=[0, 1, 0], width_px=65536, height_px=65536)),
            # 10^8 triangles: 3.6 GB of corners.
            caught(lambda: octrace.Scene.from_arrays(np.zeros((3, 3), np.float32),
                                                     np.zeros((10**8, 3), np.int64))),
        ]
        """,
        3 * GB,
    )
    pinhole, triangles = answer
    assert pinhole[0] == "MemoryError" and "rays need 103079215104 bytes" in pinhole[1], pinhole
    assert triangles[0] == "MemoryError" and "triangles need 3600000000 bytes" in triangles[1], triangles


def test_thread_pools_are_not_kept_for_every_count():
    # Before: a pool kept for each distinct nthreads, 822 threads after 1..40.
    answer, _ = capped(
        """
        import os, time
        v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)
        scene = octrace.Scene.from_arrays(v, np.array([[0, 1, 2]]))
        rays = np.array([[0.2, 0.2, 1, 0, 0, -1]], np.float32)
        for n in range(1, 41):
            assert scene.cast_rays(rays, nthreads=n)["t_hit"][0] == 1
        # Dropped pools' threads end once their calls are done.
        for _ in range(100):
            threads = len(os.listdir("/proc/self/task"))
            if threads <= 200:
                break
            time.sleep(0.05)
        answer = threads
        """,
        8 * GB,
    )
    # The four pools kept (37 to 40 threads) and the interpreter's own.
    assert answer <= 200, answer
