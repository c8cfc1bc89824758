#!/usr/bin/env bash
# Qualifies a GPU for octrace in one run: the GPU tests, `bench --gpu` on the bunny and the
# dragon, and the CPU's answers against the GPU's on the standard ray sets, a world of
# 100 bunnies, the dragon's inside/outside of a million points (uniform and near the
# surface) and renders.
#
#   scripts/gpu-check.sh pack [--bundle DIR]
#       Here, with the Rust toolchain: builds the CLI (release) and the integration test
#       binary, strips them, and puts them in the bundle (default .gpu-check/, ignored by
#       git) with the dragon (gzip), DamagedHelmet and the Debian packages of the Vulkan
#       loader and glvnd, for a GPU machine that has a driver but no toolchain, no
#       network, maybe no loader (NVIDIA's Vulkan driver also needs glvnd's
#       libGLdispatch).
#   scripts/gpu-check.sh run [--bundle DIR] [--json FILE] [--quick] [--no-tests]
#                            [--no-bench] [--octrace BIN]
#       On the GPU machine, from the repository's root (the tests read tests/data and
#       assets/). Unpacks the loader if the machine has none (as root), then runs every
#       step, prints one table and writes it as JSON (default: $OUT/gpu-check.json when
#       OUT is set, else BUNDLE/gpu-check.json). Exits 1 if a test fails or an answer
#       differs. Without a GPU it runs against Mesa's lavapipe: the rehearsal.
#       --quick: the bunny, two ray sets and small renders (the script's own test);
#       --large: the dragon's primary set also as one 16M-ray batch (transfers of large
#       batches) and the kernel at workgroups of 32, 128 and 256 (occupancy);
#       --octrace: the CLI to run (default BUNDLE/bin/octrace, else target/release);
#       --timeout S: seconds a step may take before it counts as failed (default 300;
#       the tests get four times that): a hung kernel fails the check, never hangs it.
#
# Equal means: nearest hits bit for bit (`trace` files compared byte for byte);
# occlusion the same ray for ray (the occluder may be any); crossing counts and lists
# byte for byte; renders the same rays of each kind and the same 8-bit image (the tests'
# bound off lavapipe: channels at most one level apart, at most one in 10,000).
set -euo pipefail
cd "$(dirname "$0")/.."

mode="${1:-}"
shift || true
bundle=.gpu-check
json=""
step_timeout=300
quick=0
large=0
tests=1
bench=1
octrace=""
while [ $# -gt 0 ]; do
    case "$1" in
        --bundle) bundle="$2"; shift 2 ;;
        --json) json="$2"; shift 2 ;;
        --quick) quick=1; shift ;;
        --large) large=1; shift ;;
        --no-tests) tests=0; shift ;;
        --no-bench) bench=0; shift ;;
        --octrace) octrace="$2"; shift 2 ;;
        --timeout) step_timeout="$2"; shift 2 ;;
        *) echo "gpu-check: unknown option $1 (see the head of $0)" >&2; exit 2 ;;
    esac
done

pack() {
    echo "== building the CLI (release) and the test binary"
    cargo build --release --locked -p octrace
    local it
    it=$(cargo test --locked -p octrace-tests --test it --no-run --message-format=json \
        | python3 -c 'import json, sys
for line in sys.stdin:
    m = json.loads(line)
    if m.get("reason") == "compiler-artifact" and m["target"]["name"] == "it" and m.get("executable"):
        print(m["executable"])')
    mkdir -p "$bundle/bin" "$bundle/shared/meshes" "$bundle/vulkan"
    cp target/release/octrace "$bundle/bin/octrace"
    cp "$it" "$bundle/bin/it"
    strip "$bundle/bin/octrace" "$bundle/bin/it"
    if [ -e ../shared/meshes/dragon.obj ]; then
        [ -e "$bundle/shared/meshes/dragon.obj.gz" ] || gzip -9 -c ../shared/meshes/dragon.obj >"$bundle/shared/meshes/dragon.obj.gz"
    else
        echo "no ../shared/meshes/dragon.obj: the bundle checks the bunny only" >&2
    fi
    # The GPU tests' real asset (emissive textures).
    if [ -e ../shared/gltf/DamagedHelmet.glb ]; then
        mkdir -p "$bundle/shared/gltf"
        cp ../shared/gltf/DamagedHelmet.glb "$bundle/shared/gltf/"
    fi
    if ! ls "$bundle"/vulkan/libvulkan1_*.deb "$bundle"/vulkan/libglvnd0_*.deb >/dev/null 2>&1; then
        # The Vulkan loader, and glvnd, which NVIDIA's Vulkan driver (libGLX_nvidia) loads.
        echo "== the Vulkan loader and glvnd (Debian packages, amd64)"
        local apt
        apt=$(mktemp -d)
        mkdir -p "$apt/lists/partial" "$apt/cache"
        local o=(-oAPT::Architecture=amd64 -oAPT::Architectures=amd64 "-oDir::State::Lists=$apt/lists"
            "-oDir::Cache=$apt/cache")
        apt-get "${o[@]}" update -qq
        (cd "$bundle/vulkan" && apt-get "${o[@]}" download libvulkan1 libglvnd0 libegl1 libgl1 libglx0 libopengl0 libgles2)
        rm -rf "$apt"
    fi
    du -sh "$bundle"
    echo "bundle ready: carry it to the GPU machine with the repository, then: scripts/gpu-check.sh run --bundle $bundle"
}

# One line of the summary: step, result (ok, same, differs, failed, or a figure), detail.
record() {
    printf '%s\t%s\t%s\n' "$1" "$2" "$3" >>"$work/records.tsv"
}

run() {
    work=$(mktemp -d /tmp/gpu-check.XXXXXX)
    trap 'rm -rf "$work"' EXIT
    : >"$work/records.tsv"
    [ -n "$octrace" ] || octrace="$bundle/bin/octrace"
    [ -x "$octrace" ] || octrace=target/release/octrace
    [ -x "$octrace" ] || { echo "gpu-check: no CLI at $bundle/bin/octrace or target/release/octrace: run pack first" >&2; exit 2; }
    octrace=$(realpath "$octrace")
    if [ -z "$json" ]; then
        if [ -n "${OUT:-}" ]; then json="$OUT/gpu-check.json"; else json="$bundle/gpu-check.json"; fi
    fi
    mkdir -p "$(dirname "$json")"
    export XDG_RUNTIME_DIR="${XDG_RUNTIME_DIR:-$work}"

    # The Vulkan loader, and the glvnd dispatch library NVIDIA's Vulkan driver loads
    # (without it the loader finds the driver and gets no vkCreateInstance from it): a
    # GPU machine may have the driver and not these. Wanted only where a driver asks.
    local missing=""
    ldconfig -p 2>/dev/null | grep -q 'libvulkan.so.1 ' || missing="libvulkan.so.1"
    if ls /usr/share/vulkan/icd.d/nvidia* /usr/local/nvidia/share/vulkan/icd.d/nvidia* >/dev/null 2>&1; then
        ldconfig -p 2>/dev/null | grep -q 'libGLdispatch.so.0 ' || missing="$missing libGLdispatch.so.0"
    fi
    if [ -n "$missing" ]; then
        if ls "$bundle"/vulkan/*.deb >/dev/null 2>&1 && [ "$(id -u)" -eq 0 ]; then
            echo "== missing $missing: unpacking the bundle's packages"
            for f in "$bundle"/vulkan/*.deb; do dpkg -x "$f" /; done
            ldconfig
        else
            echo "gpu-check: missing $missing, and no bundle packages to unpack as root" >&2
        fi
    fi
    # NVIDIA's driver may keep its Vulkan manifest where the loader does not look.
    local nv=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
    if [ -z "${VK_DRIVER_FILES:-}" ] && [ -e "$nv" ] && ! ls /usr/share/vulkan/icd.d/nvidia* /etc/vulkan/icd.d/nvidia* >/dev/null 2>&1; then
        export VK_DRIVER_FILES="$nv"
    fi
    command -v nvidia-smi >/dev/null && nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader || true

    local scenes=(bunny)
    bake assets/bunny.obj.zst bunny
    if [ "$quick" -eq 0 ]; then
        local dragon_gz="$bundle/shared/meshes/dragon.obj.gz"
        mkdir -p "$work/shared/meshes"
        if [ -e "$dragon_gz" ]; then
            gunzip -c "$dragon_gz" >"$work/shared/meshes/dragon.obj"
        elif [ -e ../shared/meshes/dragon.obj ]; then
            ln -s "$(realpath ../shared/meshes/dragon.obj)" "$work/shared/meshes/dragon.obj"
        fi
        local helmet="$bundle/shared/gltf/DamagedHelmet.glb"
        [ -e "$helmet" ] || helmet=../shared/gltf/DamagedHelmet.glb
        if [ -e "$helmet" ]; then
            mkdir -p "$work/shared/gltf"
            ln -s "$(realpath "$helmet")" "$work/shared/gltf/DamagedHelmet.glb"
        fi
        if [ -e "$work/shared/meshes/dragon.obj" ]; then
            bake "$work/shared/meshes/dragon.obj" dragon
            scenes+=(dragon)
        else
            record "dragon" "missing" "no dragon in the bundle or ../shared: the bunny only"
        fi
    fi

    if [ "$tests" -eq 1 ]; then
        echo "== the GPU tests"
        local it="$bundle/bin/it" start rc=0
        if [ ! -x "$it" ]; then
            record "GPU tests" "failed" "no test binary at $it: run pack first"
        else
            start=$(date +%s.%N)
            # The log goes beside the JSON as it is written (a step that times out
            # leaves it, naming the tests still running).
            local log="${json%.json}-tests.log"
            OCTRACE_REPO="$PWD" OCTRACE_SHARED="$work/shared" OCTRACE_REQUIRE_GPU=1 OCTRACE_REQUIRE_SHARED=1 \
                timeout $((4 * step_timeout)) "$it" gpu >"$log" 2>&1 || rc=$?
            local secs summary
            secs=$(python3 -c "import time; print(f'{time.time() - $start:.1f}')")
            summary=$(grep -E '^test result:' "$log" | tail -n 1 || true)
            tail -n 30 "$log"
            if [ "$rc" -eq 0 ]; then
                record "GPU tests" "ok" "${summary#test result: ok. } in $secs s"
            elif [ "$rc" -eq 124 ]; then
                record "GPU tests" "failed" "timed out after $secs s: $(grep -E 'running for over' "$log" | tr '\n' ' ')"
            else
                record "GPU tests" "failed" "exit $rc: $(grep -E '^(test .* FAILED|failures:)|panicked' "$log" | head -n 5 | tr '\n' ' ')"
            fi
        fi
    fi

    for s in "${scenes[@]}"; do
        if [ "$bench" -eq 1 ]; then
            echo "== bench --gpu: $s"
            if timeout "$step_timeout" "$octrace" bench "$work/$s.oct" --gpu --no-peer --no-queries --json --runs 5 >"$work/bench-$s.json" 2>"$work/bench-$s.err"; then
                record "bench $s" "ok" "$work/bench-$s.json"
            else
                record "bench $s" "failed" "$(tail -n 3 "$work/bench-$s.err" | tr '\n' ' ')"
            fi
        fi
        echo "== CPU = GPU: $s"
        local sets=(primary incoherent shadow)
        if [ "$quick" -eq 1 ]; then sets=(primary shadow); fi
        for set in "${sets[@]}"; do
            "$octrace" rays "$work/$s.oct" --set "$set" -o "$work/$s-$set.rays" >/dev/null
            local flag=() what=nearest
            if [ "$set" = shadow ]; then flag=(--occluded); what=occluded; fi
            compare_trace "$s" "$set" "$what" "${flag[@]}"
        done
        local crossing_set=incoherent
        if [ "$quick" -eq 1 ]; then crossing_set=primary; fi
        compare_trace "$s" "$crossing_set" counts --counts
        compare_trace "$s" "$crossing_set" "every hit" --all-hits
    done

    echo "== a world of 100 bunnies: CPU = GPU"
    compare_world

    if [ -e "$work/dragon.oct" ]; then
        echo "== inside/outside: CPU = GPU"
        compare_contains dragon uniform
        compare_contains dragon near
    fi

    if [ "$large" -eq 1 ] && [ -e "$work/dragon.oct" ]; then
        echo "== bench --gpu: the dragon's primary set as a 16M-ray batch"
        if timeout "$step_timeout" "$octrace" bench "$work/dragon.oct" --set primary --gpu --gpu-repeat 16 --no-peer --no-queries --json --runs 5 >"$work/bench-dragon16.json" 2>"$work/bench-dragon16.err"; then
            record "bench dragon16" "ok" "$work/bench-dragon16.json"
        else
            record "bench dragon16" "failed" "$(tail -n 3 "$work/bench-dragon16.err" | tr '\n' ' ')"
        fi
        for wg in 32 128 256; do
            echo "== bench --gpu: the dragon's primary set, workgroups of $wg"
            if OCTRACE_GPU_WORKGROUP=$wg timeout "$step_timeout" "$octrace" bench "$work/dragon.oct" --set primary --gpu --no-peer --no-queries --json --runs 5 >"$work/bench-dragonwg$wg.json" 2>"$work/bench-dragonwg$wg.err"; then
                record "bench dragonwg$wg" "ok" "$work/bench-dragonwg$wg.json"
            else
                record "bench dragonwg$wg" "failed" "$(tail -n 3 "$work/bench-dragonwg$wg.err" | tr '\n' ' ')"
            fi
        done
    fi

    echo "== renders: CPU = GPU"
    local effects_width=256 textured_width=512
    if [ "$quick" -eq 1 ]; then effects_width=32; textured_width=32; fi
    "$octrace" demo --scene effects --save-scene "$work/fx.oct" -o "$work/demo.png" >/dev/null
    "$octrace" bake tests/data/textured/leaf.gltf -o "$work/leaf.oct" >/dev/null
    compare_render effects "$work/fx.oct" "$effects_width"
    compare_render textured "$work/leaf.oct" "$textured_width"

    summarize
}

# Bakes a mesh into $work/NAME.oct, timed.
bake() {
    local start
    start=$(date +%s.%N)
    "$octrace" bake "$1" -o "$work/$2.oct" >"$work/bake-$2.log" 2>&1 || { cat "$work/bake-$2.log" >&2; exit 1; }
    record "bake $2" "ok" "$(python3 -c "import time; print(f'{time.time() - $start:.2f} s')"), $(du -h "$work/$2.oct" | cut -f1)"
}

# Traces one ray set on the CPU and on the GPU and compares the answers.
# A world of 100 bunnies (a scene description: a lattice, each turned about y) traced
# on the CPU and with the instances' walks on the GPU (`GpuWorld`): nearest hits,
# occlusion and crossing counts byte for byte on the bunny's primary set; with the
# bench, the world's Mrays/s both ways and where the GPU batch's time goes.
compare_world() {
    python3 - "$work/world.json" <<'EOF'
import json, math, sys
instances = []
for k in range(100):
    a = 2.399 * k
    c, s = math.cos(a), math.sin(a)
    x, y, z = k % 5, k // 5 % 5, k // 25
    instances.append({"scene": "bunny", "transform": [[c, 0, s, 0.2 * x], [0, 1, 0, 0.2 * y], [-s, 0, c, 0.2 * z]]})
json.dump({"scenes": {"bunny": "bunny.oct"}, "instances": instances}, open(sys.argv[1], "w"))
EOF
    local rays="$work/bunny-primary.rays"
    [ -e "$rays" ] || "$octrace" rays "$work/bunny.oct" --set primary -o "$rays" >/dev/null
    local what flag
    for what in nearest occluded counts; do
        flag=()
        [ "$what" = occluded ] && flag=(--occluded)
        [ "$what" = counts ] && flag=(--counts)
        if ! timeout "$step_timeout" "$octrace" trace "$work/world.json" --rays "$rays" -o "$work/world-$what.cpu" "${flag[@]}" >"$work/world-$what.cpu.txt" 2>"$work/world.err" ||
            ! timeout "$step_timeout" "$octrace" trace "$work/world.json" --rays "$rays" -o "$work/world-$what.gpu" --gpu "${flag[@]}" >"$work/world-$what.gpu.txt" 2>>"$work/world.err"; then
            record "world $what" "failed" "$(tail -n 3 "$work/world.err" | tr '\n' ' ')"
        elif cmp -s "$work/world-$what.cpu" "$work/world-$what.gpu"; then
            record "world $what" "same" "CPU: $(tr '\n' ' ' <"$work/world-$what.cpu.txt")/ GPU: $(tr '\n' ' ' <"$work/world-$what.gpu.txt")"
        else
            record "world $what" "differs" "the files differ: $(cmp "$work/world-$what.cpu" "$work/world-$what.gpu" 2>&1 | head -n 1)"
        fi
    done
    if [ "$bench" -eq 1 ]; then
        if timeout "$step_timeout" "$octrace" bench "$work/bunny.oct" --instances 100 --gpu --no-peer --runs 5 >"$work/world-bench.txt" 2>"$work/world.err"; then
            local verdict=same
            grep -q "the CPU's answers: yes" "$work/world-bench.txt" || verdict=differs
            record "world bench" "$verdict" "$(grep -E "GPU|batch" "$work/world-bench.txt" | tr -s ' ' | tr '\n' ';')"
        else
            record "world bench" "failed" "$(tail -n 3 "$work/world.err" | tr '\n' ' ')"
        fi
    fi
}

compare_trace() {
    local scene=$1 set=$2 what=$3
    shift 3
    local rays="$work/$scene-$set.rays" tag="$scene-$set-${what// /-}"
    local name="trace $scene $set $what"
    if ! timeout "$step_timeout" "$octrace" trace "$work/$scene.oct" --rays "$rays" -o "$work/$tag.cpu" --json "$@" >"$work/$tag.cpu.json" 2>"$work/$tag.err" ||
        ! timeout "$step_timeout" "$octrace" trace "$work/$scene.oct" --rays "$rays" -o "$work/$tag.gpu" --json --gpu "$@" >"$work/$tag.gpu.json" 2>>"$work/$tag.err"; then
        record "$name" "failed" "$(tail -n 3 "$work/$tag.err" | tr '\n' ' ')"
        return
    fi
    local verdict
    verdict=$(python3 - "$work/$tag.cpu" "$work/$tag.gpu" "$work/$tag.cpu.json" "$work/$tag.gpu.json" "$what" <<'EOF'
import json, struct, sys
cpu, gpu = open(sys.argv[1], "rb").read(), open(sys.argv[2], "rb").read()
c, g = json.load(open(sys.argv[3])), json.load(open(sys.argv[4]))
what = sys.argv[5]
rate = lambda j: f"{j['mrays_per_s']:.1f}" if "mrays_per_s" in j else "-"
on = g.get("on", "")
clock = "whole call" if "whole call" in on else "kernel, GPU clock" if "timestamps" in on else "kernel, host clock"
figures = f"CPU {rate(c)} Mrays/s, GPU {rate(g)} Mrays/s ({clock})"
if what == "occluded":
    # 8 bytes a ray, the id second: any occluder counts.
    ids = lambda b: [i != 0xFFFFFFFF for (i,) in struct.iter_unpack("<4xI", b)]
    a, b = ids(cpu), ids(gpu)
    differ = sum(x != y for x, y in zip(a, b)) + abs(len(a) - len(b))
    print(("same" if differ == 0 else "differs") + f"\t{len(a):,} rays, {differ} occlusions differ; {figures}")
else:
    if cpu == gpu:
        print(f"same\t{len(cpu):,} bytes identical; {figures}")
    else:
        first = next((i for i, (x, y) in enumerate(zip(cpu, gpu)) if x != y), min(len(cpu), len(gpu)))
        print(f"differs\t{len(cpu):,} and {len(gpu):,} bytes, first difference at byte {first:,}; {figures}")
EOF
)
    record "$name" "${verdict%%$'\t'*}" "${verdict#*$'\t'}"
}

# Inside/outside of a million points of a standard set (`octrace points`) of a closed
# scene on the CPU and on the GPU (the kernel, the CPU finishing what it leaves): the
# same bytes.
compare_contains() {
    local scene=$1 set=$2 name="contains $1 $2"
    local points="$work/$scene-$set.points" tag="$work/$scene-$set-inside"
    if ! "$octrace" points "$work/$scene.oct" --set "$set" --count 1000000 -o "$points" >/dev/null 2>"$tag.err" ||
        ! timeout "$step_timeout" "$octrace" contains "$work/$scene.oct" --points "$points" -o "$tag.cpu" --json >"$tag.cpu.json" 2>>"$tag.err" ||
        ! timeout "$step_timeout" "$octrace" contains "$work/$scene.oct" --points "$points" -o "$tag.gpu" --json --gpu >"$tag.gpu.json" 2>>"$tag.err"; then
        record "$name" "failed" "$(tail -n 3 "$tag.err" | tr '\n' ' ')"
        return
    fi
    local verdict
    verdict=$(python3 - "$tag.cpu" "$tag.gpu" "$tag.cpu.json" "$tag.gpu.json" <<'EOF'
import json, sys
cpu, gpu = open(sys.argv[1], "rb").read(), open(sys.argv[2], "rb").read()
c, g = json.load(open(sys.argv[3])), json.load(open(sys.argv[4]))
figures = f"CPU {c['mpoints_per_s']:.1f} M points/s, GPU {g['mpoints_per_s']:.1f} ({g['answer']})"
print(("same" if cpu == gpu else "differs") + f"\t{len(cpu):,} points; {figures}")
EOF
)
    record "$name" "${verdict%%$'\t'*}" "${verdict#*$'\t'}"
}

# Renders a scene on the CPU and on the GPU at a width and compares rays and images.
compare_render() {
    local scene=$1 file=$2 width=$3 name="render $1 $3 px"
    if ! timeout "$step_timeout" "$octrace" render "$file" -o "$work/$scene-cpu.png" --width "$width" --json >"$work/$scene-cpu.json" 2>"$work/$scene.err" ||
        ! timeout "$step_timeout" "$octrace" render "$file" -o "$work/$scene-gpu.png" --width "$width" --json --gpu >"$work/$scene-gpu.json" 2>>"$work/$scene.err"; then
        record "$name" "failed" "$(tail -n 3 "$work/$scene.err" | tr '\n' ' ')"
        return
    fi
    local verdict
    verdict=$(python3 - "$work/$scene-cpu.png" "$work/$scene-gpu.png" "$work/$scene-cpu.json" "$work/$scene-gpu.json" <<'EOF'
import json, struct, sys, zlib

def pixels(path):
    """The 8-bit samples of a non-interlaced PNG (octrace writes RGB or RGBA)."""
    data = open(path, "rb").read()
    at, idat, header = 8, b"", None
    while at < len(data):
        n, kind = struct.unpack(">I4s", data[at:at + 8])
        body = data[at + 8:at + 8 + n]
        if kind == b"IHDR":
            header = struct.unpack(">IIBBBBB", body)
        elif kind == b"IDAT":
            idat += body
        at += 12 + n
    width, height, depth, colour = header[:4]
    channels = {2: 3, 6: 4, 0: 1, 4: 2}[colour]
    stride, bpp = width * channels, channels
    raw, out, prev = zlib.decompress(idat), bytearray(), bytearray(width * channels)
    for y in range(height):
        f, row = raw[y * (stride + 1)], bytearray(raw[y * (stride + 1) + 1:(y + 1) * (stride + 1)])
        for i in range(stride):
            a = row[i - bpp] if i >= bpp else 0
            b, c = prev[i], (prev[i - bpp] if i >= bpp else 0)
            if f == 1: row[i] = (row[i] + a) & 255
            elif f == 2: row[i] = (row[i] + b) & 255
            elif f == 3: row[i] = (row[i] + (a + b) // 2) & 255
            elif f == 4:
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                row[i] = (row[i] + (a if pa <= pb and pa <= pc else b if pb <= pc else c)) & 255
        out += row
        prev = row
    return out

c, g = json.load(open(sys.argv[3])), json.load(open(sys.argv[4]))
setup = g.get("gpu_setup_seconds")
figures = f"CPU {c['seconds']:.2f} s, GPU {g['seconds']:.2f} s" + (f" (+ {setup:.2f} s making the kernel)" if setup else "")
rays = "same rays of each kind" if c["rays"] == g["rays"] else f"rays differ: CPU {c['rays']}, GPU {g['rays']}"
ok = c["rays"] == g["rays"]
if open(sys.argv[1], "rb").read() == open(sys.argv[2], "rb").read():
    image = "identical images"
else:
    a, b = pixels(sys.argv[1]), pixels(sys.argv[2])
    diffs = [abs(x - y) for x, y in zip(a, b) if x != y]
    worst = max(diffs, default=0)
    image = f"{len(diffs)} of {len(a):,} 8-bit channels differ (by up to {worst})"
    ok = ok and len(a) == len(b) and worst <= 1 and len(diffs) * 10_000 <= len(a)
print(("same" if ok else "differs") + f"\t{rays}; {image}; {figures}; {c['rays'].get('total', 0):,} rays")
EOF
)
    record "$name" "${verdict%%$'\t'*}" "${verdict#*$'\t'}"
}

# Prints the table (the bench's figures in it) and writes the JSON; exit 1 on a failure.
summarize() {
    python3 - "$work" "$json" <<'EOF'
import json, os, sys
work, out = sys.argv[1], sys.argv[2]
records = [line.rstrip("\n").split("\t", 2) for line in open(os.path.join(work, "records.tsv"))]
checks, bench, adapter = [], {}, None
rows = []
for name, result, detail in records:
    if name.startswith("bench ") and result == "ok":
        scene = name.split()[1]
        b = json.load(open(detail))
        bench[scene] = b
        g = b.get("gpu") or {}
        adapter = adapter or g.get("adapter")
        cpu = {s["set"]: s for s in b.get("sets", [])}
        for s in g.get("sets", []):
            med = lambda v: f"{v['median']:.1f}" if v else "-"
            c = cpu.get(s["set"], {})
            cpu_rate = f"{med(c.get('mrays_all_threads'))} Mrays/s ({b.get('threads')} threads)"
            rows.append((f"bench {scene} {s['set']}", f"{med(s.get('mrays_kernel_device'))}",
                         f"kernel Mrays/s on the GPU's clock; with transfers {med(s['mrays_end_to_end'])} (full records), "
                         f"{med(s.get('mrays_compact'))} (compact); transfers alone {med(s.get('transfers_ms'))} ms, "
                         f"memcpy of the same bytes {med(s.get('memcpy_ms'))} ms; up {med(s.get('upload_ms'))} + down "
                         f"{med(s.get('download_ms'))} ms; {s['rays']:,} rays; first call {s['first_call_s'] * 1e3:.0f} ms; "
                         f"CPU {cpu_rate}; {s['differ_from_cpu']} rays differ"))
            checks.append({"name": f"bench {scene} {s['set']}", "ok": s["differ_from_cpu"] == 0, **s})
        cam = g.get("camera")
        if cam:
            med = lambda v: f"{v['median']:.1f}" if v else "-"
            rows.append((f"bench {scene} camera", med(cam.get("mrays_kernel_device")),
                         f"camera rays made on the GPU, kernel Mrays/s on the GPU's clock; whole calls "
                         f"{med(cam['mrays_nearest'])} (distance and triangle back), {med(cam['mrays_distance'])} "
                         f"(distance); {cam['rays']:,} rays; {cam['differ_from_cpu']} pixels differ"))
            checks.append({"name": f"bench {scene} camera", "ok": cam["differ_from_cpu"] == 0, **cam})
        continue
    rows.append((name, result, detail))
    checks.append({"name": name, "ok": result in ("ok", "same", "missing"), "result": result, "detail": detail})
ok = all(c["ok"] for c in checks)
width = max(len(r[0]) for r in rows)
print()
print(f"octrace GPU check on {adapter or 'the first Vulkan adapter'}: {'PASSED' if ok else 'FAILED'}")
for name, result, detail in rows:
    print(f"{name:<{width}}  {result:<8} {detail}")
json.dump({"adapter": adapter, "ok": ok, "checks": checks, "bench": bench}, open(out, "w"), indent=1)
print(f"(written to {out})")
sys.exit(0 if ok else 1)
EOF
}

case "$mode" in
    pack) pack ;;
    run) run ;;
    *) echo "usage: scripts/gpu-check.sh pack|run [options] (see the head of $0)" >&2; exit 2 ;;
esac
