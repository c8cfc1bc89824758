#!/usr/bin/env python3
"""Mutated scene files and hostile Python inputs, run as a user would: counts of exits,
errors, signals and hangs (issue 46's acceptance: 0 signals, 0 hangs).

    scripts/hostile-sweep.py [--octrace BIN] [--mutations N] [--seed S] [--timeout S]
                             [--memory MIB] [--python] [--json FILE]

Scenes: a cube (OBJ), the repository's textured leaf (glTF with PNG textures) and
extensions sample, and an instanced file (a GLB placing one sphere three times), baked
by `octrace bake`. Each gets N mutations (a byte set to a
random value, a run of bytes zeroed or set to 0xFF, a 32-bit word set to a size-like
value, the file cut short or grown), each run through `inspect`, `inspect --json`,
`trace` (the standard incoherent set's first 256 rays, nearest and every hit),
`contains` (256 points), `render` (32 x 32) and `verify --rays 16`, and, with --python,
opened by the Python module (validated, and trusted: `Scene(path, mmap=True,
trusted=True)`) and
asked `cast_rays`, `list_intersections` and `contains`. Every command runs alone under
--timeout seconds (default 20) and --memory MiB of address space (default 4096).

The mesh files are mutated too (the cube's OBJ, the same with relative face indices,
the leaf's glTF), N each, and baked.

With --python, the module's array handling is fuzzed too: random dtypes, shapes,
strides, NaN and infinity, empty and huge-but-empty arrays, into every query.

A command counts as: ok (exit 0), refused (exit 1 with a message), signal (ended by a
signal: a crash or an abort), timeout (ran past --timeout), other (any other code).
Exit status: 1 when any signal or timeout was seen.

Only the Python standard library (and numpy with the module, for --python) is used.
"""

import argparse
import json
import math
import os
import random
import resource
import struct
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def limited(memory_mib):
    def apply():
        cap = memory_mib << 20
        resource.setrlimit(resource.RLIMIT_AS, (cap, cap))

    return apply


def run(cmd, timeout, memory_mib, cwd):
    """(outcome, exit code, the last line of stderr, or of stdout where stderr is empty)."""
    try:
        out = subprocess.run(cmd, cwd=cwd, capture_output=True, timeout=timeout, preexec_fn=limited(memory_mib))
    except subprocess.TimeoutExpired:
        return "timeout", None, ""
    err = (out.stderr or out.stdout).decode("utf-8", "replace").strip().splitlines()
    last = err[-1] if err else ""
    if out.returncode < 0:
        return "signal", out.returncode, last
    if out.returncode == 0:
        return "ok", 0, last
    if out.returncode == 1 and last:
        return "refused", 1, last
    return "other", out.returncode, last


def mutate(data, rng):
    data = bytearray(data)
    kind = rng.randrange(6)
    at = rng.randrange(len(data))
    if kind == 0:
        data[at] = rng.randrange(256)
    elif kind == 1:
        n = rng.randrange(1, 64)
        data[at : at + n] = bytes(len(data[at : at + n]))
    elif kind == 2:
        n = rng.randrange(1, 64)
        data[at : at + n] = b"\xff" * len(data[at : at + n])
    elif kind == 3:
        word = rng.choice([0, 1, 0x7FFFFFFF, 0x80000000, 0xFFFFFFFF, 1 << 20, 1 << 28, len(data)])
        at -= at % 4
        data[at : at + 4] = word.to_bytes(4, "little")[: len(data[at : at + 4])]
    elif kind == 4:
        del data[at:]
    else:
        data += bytes(rng.randrange(1, 4096))
    return bytes(data)


PY_SCENE = """
import sys, numpy as np, octrace
path, trusted = sys.argv[1], sys.argv[2] == "1"
scene = octrace.Scene(path, mmap=trusted, trusted=trusted)
rays = np.random.default_rng(1).normal(size=(256, 6)).astype(np.float32)
scene.cast_rays(rays)
scene.list_intersections(rays, max_hits=16)
try:
    scene.contains(rays[:, :3].copy())
except octrace.NotClosedError:
    pass
"""

PY_ARRAYS = """
import sys, numpy as np, octrace
rng = np.random.default_rng(int(sys.argv[2]))
scene = octrace.Scene(sys.argv[1])
dtypes = [np.float32, np.float64, np.int32, np.int64, np.uint8, np.bool_, np.complex64, object]
def array():
    shape = tuple(int(rng.choice([0, 1, 2, 3, 5, 6, 7, 64])) for _ in range(int(rng.integers(0, 4))))
    if rng.random() < 0.6:  # mostly rays (..., 6) and points (..., 3), of any leading shape
        shape = shape[:-1] + (int(rng.choice([3, 6])),)
    dtype_bias = rng.random() < 0.5
    dtype = np.float32 if dtype_bias else dtypes[int(rng.integers(len(dtypes)))]
    a = np.asarray(rng.normal(size=shape) * float(rng.choice([1, 1e30, 1e-40])))
    a = a.astype(dtype) if dtype is not object else a.astype(object)
    if a.size and dtype in (np.float32, np.float64) and rng.random() < 0.3:
        a.flat[int(rng.integers(a.size))] = float(rng.choice([np.nan, np.inf, -np.inf]))
    if a.ndim >= 2 and rng.random() < 0.3:
        a = a[:, ::-1]
    if rng.random() < 0.1:
        a = np.broadcast_to(np.zeros(6, np.float32), (1 << 40, 6))
    return a
calls = [
    lambda a: scene.cast_rays(a), lambda a: scene.test_occlusions(a), lambda a: scene.count_intersections(a),
    lambda a: scene.list_intersections(a), lambda a: scene.compute_occupancy(a), lambda a: scene.contains(a),
    lambda a: octrace.Scene.from_arrays(a, np.array([[0, 1, 2]])),
    lambda a: octrace.Scene.from_arrays(np.zeros((3, 3), np.float32), a),
]
failures = {}
for _ in range(200):
    a = array()
    call = calls[int(rng.integers(len(calls)))]
    try:
        call(a)
        failures["ok"] = failures.get("ok", 0) + 1
    except BaseException as e:  # a Rust panic is pyo3's PanicException, a BaseException
        failures[type(e).__name__] = failures.get(type(e).__name__, 0) + 1
print(failures)
# Exit 3 (counted as "other") on an exception no caller should see: a panic.
sys.exit(3 if "PanicException" in failures or "SystemError" in failures else 0)
"""


def repeated_glb(path):
    """A GLB whose one mesh (a 2,400-triangle sphere) three nodes place (one mirrored):
    `octrace bake` writes it as an instanced file."""
    segments, rings = 40, 31
    verts = [(math.sin(math.pi * r / rings) * math.cos(2 * math.pi * s / segments), math.cos(math.pi * r / rings),
              math.sin(math.pi * r / rings) * math.sin(2 * math.pi * s / segments))
             for r in range(rings + 1) for s in range(segments + 1)]
    idx = []
    for r in range(rings):
        for s in range(segments):
            a = r * (segments + 1) + s
            b = a + segments + 1
            idx += ([a, a + 1, b] if r > 0 else []) + ([a + 1, b + 1, b] if r < rings - 1 else [])
    positions = b"".join(struct.pack("<3f", *v) for v in verts)
    indices = struct.pack(f"<{len(idx)}H", *idx)
    indices += b"\0" * (-len(indices) % 4)
    blob = positions + indices
    doc = {
        "asset": {"version": "2.0"}, "scenes": [{"nodes": [0, 1, 2]}],
        "nodes": [{"mesh": 0}, {"mesh": 0, "translation": [3, 0, 0]},
                  {"mesh": 0, "translation": [6, 0, 0], "scale": [-1, 1, 1]}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
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


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--octrace", default=str(ROOT / "target" / "release" / "octrace"))
    p.add_argument("--mutations", type=int, default=100)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--timeout", type=float, default=20)
    p.add_argument("--memory", type=int, default=4096)
    p.add_argument("--python", action="store_true")
    p.add_argument("--json")
    args = p.parse_args()
    rng = random.Random(args.seed)
    bin_ = args.octrace
    counts = {}
    bad = []

    def count(what, outcome, code, last):
        counts.setdefault(what, {}).setdefault(outcome, 0)
        counts[what][outcome] += 1
        if outcome in ("signal", "timeout", "other"):
            bad.append({"command": what, "outcome": outcome, "code": code, "stderr": last})

    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        (d / "cube.obj").write_text(
            "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1\n"
            "f 1 3 2\nf 1 4 3\nf 5 6 7\nf 5 7 8\nf 1 2 6\nf 1 6 5\nf 4 7 3\nf 4 8 7\nf 1 5 8\nf 1 8 4\nf 2 3 7\nf 2 7 6\n"
        )
        repeated_glb(d / "repeated.glb")
        inputs = {
            "cube": d / "cube.obj",
            "instanced": d / "repeated.glb",
            "leaf": ROOT / "tests" / "data" / "textured" / "leaf.gltf",
            "extensions": ROOT / "tests" / "data" / "extensions.gltf",
        }
        scenes = {}
        for name, mesh in inputs.items():
            out = d / f"{name}.oct"
            subprocess.run([bin_, "bake", str(mesh), "-o", str(out)], check=True, capture_output=True)
            scenes[name] = out.read_bytes()
        subprocess.run([bin_, "rays", str(d / "cube.oct"), "-o", str(d / "all.bin"), "--set", "incoherent"],
                       check=True, capture_output=True)
        (d / "rays.bin").write_bytes((d / "all.bin").read_bytes()[: 32 * 256])
        subprocess.run([bin_, "points", str(d / "cube.oct"), "--count", "256", "-o", str(d / "points.bin")],
                       check=True, capture_output=True)
        runs = 0
        for name, data in scenes.items():
            for k in range(args.mutations):
                m = d / "m.oct"
                m.write_bytes(mutate(data, rng))
                commands = {
                    "inspect": ["inspect", "m.oct"],
                    "inspect --json": ["inspect", "m.oct", "--json"],
                    "trace": ["trace", "m.oct", "--rays", "rays.bin", "-o", "hits.bin"],
                    "trace --all-hits": ["trace", "m.oct", "--rays", "rays.bin", "-o", "all.bin", "--all-hits"],
                    "contains": ["contains", "m.oct", "--points", "points.bin", "-o", "in.bin"],
                    "render": ["render", "m.oct", "-o", "m.png", "--width", "32", "--height", "32"],
                    "verify": ["verify", "m.oct", "--rays", "16"],
                }
                for what, cmd in commands.items():
                    count(what, *run([bin_, *cmd], args.timeout, args.memory, d))
                    runs += 1
                if args.python:
                    for trusted in ("0", "1"):
                        what = "python " + ("trusted" if trusted == "1" else "validated")
                        count(what, *run([sys.executable, "-c", PY_SCENE, "m.oct", trusted], args.timeout,
                                         args.memory, d))
                        runs += 1
        # The mesh files themselves, mutated, baked (the OBJ read in blocks, the glTF
        # loader): the cube's OBJ, its faces written relative, and the leaf's glTF.
        relative = "".join(
            line if not line.startswith("f ") else
            "f " + " ".join(str(int(i) - 9) for i in line.split()[1:]) + "\n"
            for line in (d / "cube.obj").read_text().splitlines(keepends=True)
        )
        meshes = {
            "cube.obj": (d / "cube.obj").read_bytes(),
            "relative.obj": relative.encode(),
            "leaf.gltf": inputs["leaf"].read_bytes(),
        }
        for png in ("leaf.png",):
            (d / png).write_bytes((inputs["leaf"].parent / png).read_bytes())
        for name, data in meshes.items():
            for k in range(args.mutations):
                m = d / ("m" + Path(name).suffix)
                m.write_bytes(mutate(data, rng))
                count("bake " + Path(name).suffix, *run([bin_, "bake", m.name, "-o", "mesh.oct"], args.timeout,
                                                        args.memory, d))
                runs += 1
        if args.python:
            for seed in range(args.mutations // 10 + 1):
                count("python arrays", *run([sys.executable, "-c", PY_ARRAYS, "cube.oct", str(seed)],
                                             args.timeout * 3, args.memory, d))
                runs += 1
    signals = sum(c.get("signal", 0) for c in counts.values())
    timeouts = sum(c.get("timeout", 0) for c in counts.values())
    print(f"{runs} runs: {signals} signals, {timeouts} timeouts")
    for what, c in counts.items():
        print(f"  {what:22} " + ", ".join(f"{k} {v}" for k, v in sorted(c.items())))
    for b in bad[:20]:
        print(f"  {b['outcome']}: {b['command']} (code {b['code']}): {b['stderr']}")
    if args.json:
        Path(args.json).write_text(json.dumps({"runs": runs, "counts": counts, "bad": bad}, indent=1))
    return 1 if signals or timeouts else 0


if __name__ == "__main__":
    sys.exit(main())
