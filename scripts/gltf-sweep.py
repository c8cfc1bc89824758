#!/usr/bin/env python3
"""Bakes, inspects and renders every glTF/GLB file under a folder, as a new user would,
and writes a table of what happened to each: exit codes, warnings, seconds, peak memory,
sizes, and the share of the render that is pure black or pure white.

    scripts/gltf-sweep.py FOLDER [--octrace BIN] [--out DIR] [--timeout S]
                          [--memory MIB] [--width PX] [--markdown FILE] [--json FILE]

Each command runs alone, bounded: --timeout seconds (default 60) of wall time and
--memory MiB (default 4096) of address space; a command past either is a failure
(timeout, or killed), never a hang. The default octrace is target/release/octrace.

A file counts as:
  ok        baked, inspected and rendered (exit 0 each);
  refused   bake exited 1 with a message: a required extension octrace cannot honour
            (named), or something else (a valid file refused: a defect to fix);
  incomplete copy
            bake exited 1 because a buffer the file names is not in the folder (a
            partial copy of the samples), counted apart;
  crashed   any command ended by a signal or an exit code other than 0 and 1;
  timeout   a command ran past --timeout.
The summary's first line says how many valid files were refused and how many crashed:
the sweep's acceptance is 0 and 0. Exit status: 1 when either is not 0, else 0.

Only the Python standard library is used (the PNG is decoded here).
"""

import argparse
import json
import os
import re
import resource
import struct
import subprocess
import sys
import time
import zlib


def run_measured(cmd, timeout, memory_mib):
    """Runs cmd bounded in time and address space: (status, seconds, peak MiB, stderr),
    the peak being the child's own resident set (wait4's, not all children's)."""

    def limit():
        cap = memory_mib * 1024 * 1024
        resource.setrlimit(resource.RLIMIT_AS, (cap, cap))

    start = time.monotonic()
    err_path = "/tmp/gltf-sweep-%d.err" % os.getpid()
    with open(err_path, "wb") as err_file:
        proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=err_file, preexec_fn=limit)
        status = None
        while True:
            pid, code, usage = os.wait4(proc.pid, os.WNOHANG)
            if pid == proc.pid:
                break
            if time.monotonic() - start > timeout:
                proc.kill()
                pid, code, usage = os.wait4(proc.pid, 0)
                status = "timeout"
                break
            time.sleep(0.01)
    proc.returncode = 0  # reaped here; keep subprocess from waiting again
    seconds = time.monotonic() - start
    with open(err_path, "rb") as f:
        err = f.read().decode("utf-8", "replace")
    os.remove(err_path)
    if status is None:
        if os.WIFSIGNALED(code):
            status = "signal %d" % os.WTERMSIG(code)
        else:
            status = "exit %d" % os.WEXITSTATUS(code)
    return status, seconds, usage.ru_maxrss / 1024.0, err


def png_pixels(path):
    """The RGB bytes of an 8-bit RGB or RGBA PNG (alpha dropped), row by row, or None
    for another kind of PNG."""
    data = open(path, "rb").read()
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        return None
    pos, idat, width, height, channels = 8, b"", 0, 0, 3
    while pos < len(data):
        (length,) = struct.unpack(">I", data[pos : pos + 4])
        kind = data[pos + 4 : pos + 8]
        body = data[pos + 8 : pos + 8 + length]
        if kind == b"IHDR":
            width, height, depth, colour = struct.unpack(">IIBB", body[:10])
            if depth != 8 or colour not in (2, 6):
                return None
            channels = 3 if colour == 2 else 4
        elif kind == b"IDAT":
            idat += body
        pos += 12 + length
    raw = zlib.decompress(idat)
    stride = width * channels
    prev = bytearray(stride)
    out = bytearray()
    for y in range(height):
        row = raw[y * (stride + 1) : (y + 1) * (stride + 1)]
        kind, line = row[0], bytearray(row[1:])
        for i in range(stride):
            a = line[i - channels] if i >= channels else 0
            b = prev[i]
            c = prev[i - channels] if i >= channels else 0
            if kind == 1:
                line[i] = (line[i] + a) & 255
            elif kind == 2:
                line[i] = (line[i] + b) & 255
            elif kind == 3:
                line[i] = (line[i] + (a + b) // 2) & 255
            elif kind == 4:
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                pred = a if pa <= pb and pa <= pc else (b if pb <= pc else c)
                line[i] = (line[i] + pred) & 255
        for x in range(width):
            out += line[x * channels : x * channels + 3]
        prev = line
    return bytes(out)


def png_shares(path):
    """Shares of pure black and pure white pixels of an 8-bit RGB or RGBA PNG."""
    rgb = png_pixels(path)
    if rgb is None:
        return None
    total = max(len(rgb) // 3, 1)
    black = sum(1 for i in range(0, len(rgb), 3) if rgb[i : i + 3] == b"\x00\x00\x00")
    white = sum(1 for i in range(0, len(rgb), 3) if rgb[i : i + 3] == b"\xff\xff\xff")
    return black / total, white / total


REQUIRED = re.compile(r"requires extension '([^']+)'")
# A buffer or image the file names is not in the folder (a partial copy of a sample
# repository: one that leaves out large files): not a defect of octrace's.
MISSING = re.compile(r"not read: No such file or directory")


def input_bytes(path):
    """The input's size: a GLB's file; a .gltf's folder (its buffers and images beside it,
    as the samples lay them out: one variant a folder)."""
    if path.lower().endswith(".glb"):
        return os.path.getsize(path)
    folder = os.path.dirname(path)
    return sum(os.path.getsize(os.path.join(folder, n)) for n in os.listdir(folder) if os.path.isfile(os.path.join(folder, n)))


def sweep_file(path, args, out_dir, index):
    """Bake, inspect and render one file: a row of the table."""
    base = os.path.join(out_dir, "%03d" % index)
    baked, image = base + ".oct", base + ".png"
    row = {"file": os.path.relpath(path, args.folder), "input_bytes": input_bytes(path)}
    status, seconds, peak, err = run_measured([args.octrace, "bake", path, "-o", baked], args.timeout, args.memory)
    row.update(bake=status, bake_s=round(seconds, 3), bake_mib=round(peak, 1))
    row["warnings"] = [l[len("warning: ") :] for l in err.splitlines() if l.startswith("warning: ")]
    errors = [l for l in err.splitlines() if l.startswith("error")]
    row["error"] = errors[0] if errors else (err.strip().splitlines() or [""])[-1] if status != "exit 0" else ""
    if status != "exit 0":
        required = REQUIRED.search(err)
        if status == "timeout":
            row["class"] = "timeout"
        elif status != "exit 1":
            row["class"] = "crashed"
        elif required:
            row["class"] = "refused: requires " + required.group(1)
        elif MISSING.search(err):
            row["class"] = "incomplete copy"
        else:
            row["class"] = "refused"
        return row
    row["oct_bytes"] = os.path.getsize(baked)
    status, seconds, peak, err = run_measured([args.octrace, "inspect", baked, "--json"], args.timeout, args.memory)
    row.update(inspect=status, inspect_s=round(seconds, 3), inspect_mib=round(peak, 1))
    cmd = [args.octrace, "render", baked, "-o", image, "--width", str(args.width)]
    status, seconds, peak, err = run_measured(cmd, args.timeout, args.memory)
    row.update(render=status, render_s=round(seconds, 3), render_mib=round(peak, 1))
    if status == "exit 0" and os.path.exists(image):
        shares = png_shares(image)
        if shares:
            row["black"], row["white"] = round(shares[0], 4), round(shares[1], 4)
    bad = [s for s in (row["inspect"], row["render"]) if s != "exit 0"]
    if any(s == "timeout" for s in bad):
        row["class"] = "timeout"
    elif any(s not in ("exit 0", "exit 1") for s in bad):
        row["class"] = "crashed"
    elif bad:
        row["class"] = "failed after bake"
        row["error"] = (err.strip().splitlines() or [""])[-1]
    else:
        row["class"] = "ok"
    for p in (baked, image):
        if os.path.exists(p) and not args.keep:
            os.remove(p)
    return row


def markdown(rows, summary):
    out = ["# glTF sweep", "", summary, ""]
    out.append("| file | result | bake s | bake MiB | render s | render MiB | .oct / input | black | white | warnings |")
    out.append("| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
    for r in rows:
        ratio = "%.2f" % (r["oct_bytes"] / r["input_bytes"]) if "oct_bytes" in r else ""
        result = r["class"] + (" (%s)" % r["error"][:80] if r["class"] not in ("ok",) and r.get("error") else "")
        out.append(
            "| %s | %s | %s | %s | %s | %s | %s | %s | %s | %d |"
            % (
                r["file"],
                result.replace("|", "/"),
                r.get("bake_s", ""),
                r.get("bake_mib", ""),
                r.get("render_s", ""),
                r.get("render_mib", ""),
                ratio,
                "%.1f %%" % (100 * r["black"]) if "black" in r else "",
                "%.1f %%" % (100 * r["white"]) if "white" in r else "",
                len(r["warnings"]),
            )
        )
    return "\n".join(out) + "\n"


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("folder")
    parser.add_argument("--octrace", default="target/release/octrace")
    parser.add_argument("--out", default=None, help="where baked files and renders go (default: a temporary folder)")
    parser.add_argument("--keep", action="store_true", help="keep each .oct and .png in --out")
    parser.add_argument("--timeout", type=float, default=60.0)
    parser.add_argument("--memory", type=int, default=4096, help="address-space cap per command, MiB")
    parser.add_argument("--width", type=int, default=256)
    parser.add_argument("--markdown", default=None)
    parser.add_argument("--json", default=None)
    args = parser.parse_args()
    import tempfile

    out_dir = args.out or tempfile.mkdtemp(prefix="gltf-sweep-")
    os.makedirs(out_dir, exist_ok=True)
    files = []
    for root, _, names in os.walk(args.folder):
        files += [os.path.join(root, n) for n in names if n.lower().endswith((".gltf", ".glb"))]
    files.sort()
    rows = []
    for i, path in enumerate(files):
        row = sweep_file(path, args, out_dir, i)
        rows.append(row)
        print("%-70s %s" % (row["file"][:70], row["class"]), file=sys.stderr)
    count = lambda c: sum(1 for r in rows if r["class"] == c)
    refused = [r for r in rows if r["class"] in ("refused", "failed after bake")]
    crashed = [r for r in rows if r["class"] in ("crashed", "timeout")]
    required = sorted({r["class"][len("refused: requires ") :] for r in rows if r["class"].startswith("refused: requires")})
    peak = max([r.get(k, 0) or 0 for r in rows for k in ("bake_mib", "inspect_mib", "render_mib")] or [0])
    slowest = max([r.get(k, 0) or 0 for r in rows for k in ("bake_s", "inspect_s", "render_s")] or [0])
    summary = (
        "%d files: %d ok, %d valid files refused, %d crashed or timed out, %d incomplete in this copy (a buffer "
        "missing), %d refused for a required extension octrace cannot honour (%s); slowest command %.2f s, "
        "largest peak %.0f MiB; %d files with warnings"
        % (
            len(rows),
            count("ok"),
            len(refused),
            len(crashed),
            count("incomplete copy"),
            sum(1 for r in rows if r["class"].startswith("refused: requires")),
            ", ".join(required) or "none",
            slowest,
            peak,
            sum(1 for r in rows if r["warnings"]),
        )
    )
    print(summary)
    if args.markdown:
        open(args.markdown, "w").write(markdown(rows, summary))
    if args.json:
        json.dump({"summary": summary, "files": rows}, open(args.json, "w"), indent=1)
    return 1 if refused or crashed else 0


if __name__ == "__main__":
    sys.exit(main())
