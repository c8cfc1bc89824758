#!/usr/bin/env python3
"""Measures a render's noise: the root mean square difference, in 8-bit levels, between
renders at a few soft-shadow sample counts and a reference of many samples.

    scripts/render-noise.py SCENE [--octrace BIN ...] [--samples 4,16,64]
                            [--reference 1024] [--width 256] [--reference-octrace BIN]
                            [-- RENDER OPTIONS]

SCENE is a baked .oct, or a mesh each build bakes itself (so builds of different
format versions can be compared). Each --octrace (repeatable) renders it at each
sample count; all are compared with
one reference rendered by --reference-octrace (default: the first --octrace), so two
builds' samplers can be measured against the same image (an unbiased sampler converges
to it). Options after `--` go to every render; a build given as "BIN OPTIONS" adds its
own (e.g. --octrace "target/release/octrace --environment none" beside an older
build that has no --environment).

Only the Python standard library is used.
"""

import argparse
import importlib.util
import math
import os
import subprocess
import sys
import tempfile


def load_png_module():
    here = os.path.dirname(os.path.abspath(__file__))
    spec = importlib.util.spec_from_file_location("gltf_sweep", os.path.join(here, "gltf-sweep.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def baked(octrace, scene, work):
    """SCENE itself when it is a baked file, else SCENE baked by this build (builds of
    other format versions each read their own)."""
    if scene.endswith(".oct"):
        return scene
    out = os.path.join(work, "%x.oct" % abs(hash(octrace)))
    if not os.path.exists(out):
        subprocess.run([octrace, "bake", scene, "-o", out], check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return out


def render(build, scene, samples, width, extra, out):
    # A build is a binary, optionally followed by options of its own for `render`.
    octrace, *own = build.split()
    scene = baked(octrace, scene, os.path.dirname(out))
    cmd = [octrace, "render", scene, "-o", out, "--width", str(width), "--soft-samples", str(samples)] + own + extra
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


def rmse(png, a, b):
    pa, pb = png.png_pixels(a), png.png_pixels(b)
    return math.sqrt(sum((x - y) ** 2 for x, y in zip(pa, pb)) / max(len(pa), 1))


def main():
    args_in = sys.argv[1:]
    extra = []
    if "--" in args_in:
        i = args_in.index("--")
        args_in, extra = args_in[:i], args_in[i + 1 :]
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("scene")
    parser.add_argument("--octrace", action="append", default=None)
    parser.add_argument("--reference-octrace", default=None)
    parser.add_argument("--samples", default="4,16,64")
    parser.add_argument("--reference", type=int, default=1024)
    parser.add_argument("--width", type=int, default=256)
    args = parser.parse_args(args_in)
    builds = args.octrace or ["target/release/octrace"]
    png = load_png_module()
    work = tempfile.mkdtemp(prefix="render-noise-")
    reference = os.path.join(work, "reference.png")
    render(args.reference_octrace or builds[0], args.scene, args.reference, args.width, extra, reference)
    print("| build | " + " | ".join("%s samples" % s for s in args.samples.split(",")) + " |")
    print("| --- |" + " ---: |" * len(args.samples.split(",")))
    for build in builds:
        row = []
        for s in args.samples.split(","):
            out = os.path.join(work, "%d.png" % int(s))
            render(build, args.scene, int(s), args.width, extra, out)
            row.append("%.2f" % rmse(png, out, reference))
        print("| %s | %s |" % (build, " | ".join(row)))


if __name__ == "__main__":
    main()
