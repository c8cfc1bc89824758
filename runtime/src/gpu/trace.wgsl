// The octree walk of runtime/src/cpu/walk.rs, one ray per invocation.
//
// The scene is one array of 32-bit words (the file's sections octree, tri_refs,
// triangles, triangle_ids, boxes, cube_map, nodes, back to back, at the word offsets in
// `params`), split across several bindings when it is larger than one binding may be:
// `word(i)` hides the split. The host generates `word` and the bindings above it, and the
// two helpers whose precision depends on the adapter (`grid_coord`, `edge`).
//
// Every step is the CPU's scalar step, in the same order and with the same
// conventions (faces 2 * axis + side, exit-face table, quadrant order, cell-derived
// boxes); see the CPU code for the reasoning behind each line.

// Any hit (shadow rays) rather than the nearest.
override ANY_HIT: bool = false;
// Whether the scene has fans (`fan_pick`); without, their code is left out.
override FANS: bool = false;
// 0: the nearest hit (or with ANY_HIT any hit) a ray; 1: crossing counts (`hits[i]`:
// `triangle` the crossings, `leaf` those arriving on a front); 2: every crossing, as
// records of their own (`cross`), at offsets the host puts after the rays.
override MODE: u32 = 0u;
// How MODE 0 writes a ray's answer (gpu::HitRecord): 0 the whole record (`HitOut`, 8
// words); 1 distance and triangle (2 words); 2 distance (1 word); in 1 and 2 a miss is
// distance +inf and triangle 0xFFFFFFFF, a walk out of loop budget distance
// OVER_BUDGET_T (a NaN). 3: occlusion, one bit a ray, 32 rays a word, then as many words
// of over-budget bits (needs WORKGROUP_SIZE a multiple of 32).
override RECORD: u32 = 0u;
// Rays made here from a pinhole camera (`camera_ray`) rather than read from `rays`.
override CAMERA: bool = false;
// The exact test (cpu TriangleTest::Exact), on adapters with f64: each triangle's f32
// edge functions with an error bound and its distance with its own
// (the EXACT branch of `hit_triangle`); a ray any of whose decisions the bounds leave in doubt
// is handed back to the host (`give_back`), which traces it with the CPU's exact test.
override EXACT: bool = false;

struct Params {
    ray_count: u32,
    max_depth: u32,
    max_steps: u32,
    cube_level: u32,
    root_node: u32,
    o_octree: u32,
    o_refs: u32,
    o_tris: u32,
    o_ids: u32,
    o_boxes: u32,
    o_cube: u32,
    o_nodes: u32,
    // The fans' words (cpu::FanIndex::gpu_words), and whether there are any.
    o_fans: u32,
    fans: u32,
    // MODE 3: the leaf labels' count (a byte each, four a word, before the points).
    labels: u32,
    pad1: u32,
    // xyz: the root cube's low corner; w: its edge.
    root_lo: vec4<f32>,
    // xyz: the root cube's high corner; w: 2^max_depth / edge.
    root_hi: vec4<f32>,
    // The mesh box, enlarged (runtime/src/cpu/tracer.rs, box_slack); w: the exit
    // rule's scale (runtime/src/cpu/tables.rs, RuleScale): box_lo.w the root edge's
    // exponent, box_hi.w that of the root's largest corner coordinate.
    box_lo: vec4<f32>,
    box_hi: vec4<f32>,
}

// Relative slack on the distance where a ray leaves the mesh box (BOX_T_SLACK).
const BOX_T_SLACK: f32 = 1.52587890625e-5;
// Root edges an origin may lie outside the root and be walked from where it is
// (tracer.rs, FAR_ROOTS).
const FAR_ROOTS: f32 = 4.0;

// 32 bytes a hit; `triangle` is 0xFFFFFFFF on a miss.
struct HitOut {
    t: f32,
    triangle: u32,
    u: f32,
    v: f32,
    leaf: u32,
    prim: u32,
    steps: u32,
    // Bit 0: the walk was stopped by the step bound; bits 1..32: triangle tests run.
    flags: u32,
}

@group(0) @binding(0) var<uniform> params: Params;
// Two vec4s a ray: (ox, oy, oz, tmin), (dx, dy, dz, tmax): the 32-byte RAYS.bin record.
// With CAMERA, the camera's four vec4s (`camera_ray`).
@group(0) @binding(1) var<storage, read> rays: array<vec4<f32>>;
// The answers, as RECORD says (MODE 1 and 2: `HitOut`s, `put_hit`).
@group(0) @binding(2) var<storage, read_write> hits: array<u32>;

// A HitOut's eight words at record `i`.
fn put_hit(i: u32, h: HitOut) {
    let b = 8u * i;
    hits[b] = bitcast<u32>(h.t);
    hits[b + 1u] = h.triangle;
    hits[b + 2u] = bitcast<u32>(h.u);
    hits[b + 3u] = bitcast<u32>(h.v);
    hits[b + 4u] = h.leaf;
    hits[b + 5u] = h.prim;
    hits[b + 6u] = h.steps;
    hits[b + 7u] = h.flags;
}

// The HitOut at record `i`.
fn get_hit(i: u32) -> HitOut {
    let b = 8u * i;
    var h: HitOut;
    h.t = bitcast<f32>(hits[b]);
    h.triangle = hits[b + 1u];
    h.u = bitcast<f32>(hits[b + 2u]);
    h.v = bitcast<f32>(hits[b + 3u]);
    h.leaf = hits[b + 4u];
    h.prim = hits[b + 5u];
    h.steps = hits[b + 6u];
    h.flags = hits[b + 7u];
    return h;
}

// Ray `i`'s two vec4s: read, or with CAMERA made from the camera in rays[0..4]:
// (origin, tmin), (d0, tmax), (dx, width), (dy, first pixel), the last two words' bits
// integers. Pixel p = first + i is column p % width, row p / width; its direction is
// (dx (column + 1/2) + dy (row + 1/2)) + d0, each operation rounded to f32 (no fused
// multiply-adds: the host's gpu::GpuCamera::ray is the same arithmetic).
fn ray_at(i: u32) -> array<vec4<f32>, 2> {
    if CAMERA {
        let c1 = rays[1];
        let c2 = rays[2];
        let c3 = rays[3];
        let p = bitcast<u32>(c3.w) + i;
        let width = bitcast<u32>(c2.w);
        let x = f32(p % width) + 0.5;
        let y = f32(p / width) + 0.5;
        let d = c2.xyz * x + c3.xyz * y + c1.xyz;
        return array<vec4<f32>, 2>(rays[0], vec4<f32>(d, c1.w));
    }
    return array<vec4<f32>, 2>(rays[2u * i], rays[2u * i + 1u]);
}

// Record 1 and 2's distance for a walk that ran out of loop budget (a NaN).
const OVER_BUDGET_T: u32 = 0x7FC0B0D6u;

// MODE 0's answer for ray `i`, as RECORD says.
fn put_record(i: u32, h: HitOut) {
    if RECORD == 0u {
        put_hit(i, h);
        return;
    }
    var t = bitcast<u32>(h.t);
    if h.triangle == 0xFFFFFFFFu {
        t = 0x7F800000u;
    }
    if h.steps == OVER_BUDGET {
        t = OVER_BUDGET_T;
    }
    if RECORD == 1u {
        hits[2u * i] = t;
        hits[2u * i + 1u] = h.triangle;
    } else {
        hits[i] = t;
    }
}

// RECORD 3's lanes: bit 0 occluded, bit 1 over budget.
var<workgroup> lane_bits: array<u32, WORKGROUP_SIZE>;

// RECORD 3: whether ray `i` is occluded, one bit a ray; the workgroup's first lanes
// pack 32 lanes' bits a word (a workgroup's rays start at a multiple of 32).
fn occlusion_bits(i: u32, lane: u32) {
    var b = 0u;
    if i < params.ray_count {
        let r = ray_at(i);
        let out = trace(r[0].xyz, r[1].xyz, r[0].w, r[1].w, true);
        b = select(0u, 1u, out.triangle != 0xFFFFFFFFu) | select(0u, 2u, over_budget);
    }
    lane_bits[lane] = b;
    workgroupBarrier();
    if lane < WORKGROUP_SIZE / 32u {
        var hit = 0u;
        var over = 0u;
        for (var k = 0u; k < 32u; k++) {
            let v = lane_bits[32u * lane + k];
            hit |= (v & 1u) << k;
            over |= (v >> 1u) << k;
        }
        let words = (params.ray_count + 31u) / 32u;
        let word = (i - lane) / 32u + lane;
        if word < words {
            hits[word] = hit;
            hits[words + word] = over;
        }
    }
}

//GENERATED//

// Loops run under a budget of iterations an invocation (LOOP_BUDGET, generated). Mesa's
// llvmpipe (lavapipe, the Vulkan driver CI runs) caps the loop iterations of a shader
// invocation at 65,535, counted over all its loops together, and then silently leaves
// every loop: walks ended early and pixels lost the rest of their ray tree
// (tests/tests/it/gpu.rs, `lavapipe_caps_loop_iterations`, is the reproduction). On
// such an adapter the host gives each invocation its own workgroup and a budget under
// the cap; an invocation that spends it stops and says so (`over_budget`), and the host
// traces or renders that ray or pixel on the CPU. Elsewhere the budget is unbounded.
var<private> loops_left: u32 = LOOP_BUDGET;
var<private> over_budget: bool = false;

// Ends the walk and hands the ray back to the host as a walk out of budget is
// (EXACT: a decision the filter leaves in doubt): every loop stops at its next tick.
fn give_back() {
    over_budget = true;
    loops_left = 0u;
}

// Spends one loop iteration of the budget; false (and `over_budget`) when none is left.
fn tick() -> bool {
    if loops_left == 0u {
        over_budget = true;
        return false;
    }
    loops_left -= 1u;
    return true;
}

const LEAF_HEADER_WORDS: u32 = 4u;
const INTERNAL_BIT: u32 = 0x80000000u;
const COARSER_SHIFT: u32 = 24u;
const MISS: u32 = 0xFFFFFFFFu;

fn wordf(i: u32) -> f32 {
    return bitcast<f32>(word(i));
}

fn inf() -> f32 {
    return bitcast<f32>(0x7F800000u);
}

fn is_finite(x: f32) -> bool {
    return (bitcast<u32>(x) & 0x7F800000u) != 0x7F800000u;
}

fn is_nan(x: f32) -> bool {
    return (bitcast<u32>(x) & 0x7FFFFFFFu) > 0x7F800000u;
}

fn is_negative(x: f32) -> bool {
    // The sign bit: -0.0 counts as negative, as on the CPU.
    return (bitcast<u32>(x) & 0x80000000u) != 0u;
}

// +0.0 or -0.0, read from the bits (a driver that flushes subnormals may compare one
// equal to zero; the exit rule must see it as the CPU does).
fn is_zero(x: f32) -> bool {
    return (bitcast<u32>(x) & 0x7FFFFFFFu) == 0u;
}

// tables::exponent: the unbiased exponent read from the bits (-127 for zeros and
// subnormals).
fn exponent(x: f32) -> i32 {
    return i32((bitcast<u32>(x) >> 23u) & 0xFFu) - 127;
}

// tables::ExitRule.
const RULE_TABLE: u32 = 0u;
const RULE_FLAT: u32 = 1u;
const RULE_EXACT: u32 = 2u;

// tables::exit_rule, from the same integer exponents: the table, the slab rule among
// the moving axes (zero components), or exact decisions for the directions whose f32
// products could underflow or overflow.
fn exit_rule(o: vec3<f32>, d: vec3<f32>) -> u32 {
    let zx = is_zero(d.x);
    let zy = is_zero(d.y);
    let zz = is_zero(d.z);
    let e_min = min(min(select(exponent(d.x), 200, zx), select(exponent(d.y), 200, zy)), select(exponent(d.z), 200, zz));
    let e_max = max(max(exponent(d.x), exponent(d.y)), exponent(d.z));
    let e_origin = max(max(exponent(o.x), exponent(o.y)), exponent(o.z));
    let reach = max(e_origin, i32(params.box_hi.w));
    let served = e_min >= -100 && 2 * e_min + i32(params.box_lo.w) >= e_max - 119 && e_max + reach <= 100;
    if !served {
        return RULE_EXACT;
    }
    if zx || zy || zz {
        return RULE_FLAT;
    }
    return RULE_TABLE;
}

// EXIT_FACE[octant] (runtime/src/cpu/tables.rs), three bits a code.
fn exit_row(octant: u32) -> u32 {
    switch octant {
        case 0u: { return pack_row(1u, 3u, 5u, 5u, 1u, 3u, 1u, 1u); }
        case 1u: { return pack_row(3u, 0u, 0u, 0u, 3u, 0u, 5u, 5u); }
        case 2u: { return pack_row(5u, 5u, 2u, 1u, 1u, 1u, 2u, 1u); }
        case 3u: { return pack_row(0u, 0u, 0u, 2u, 5u, 5u, 0u, 2u); }
        case 4u: { return pack_row(1u, 1u, 1u, 3u, 4u, 4u, 1u, 3u); }
        case 5u: { return pack_row(4u, 4u, 3u, 0u, 0u, 0u, 3u, 0u); }
        case 6u: { return pack_row(2u, 1u, 1u, 1u, 2u, 1u, 4u, 4u); }
        default: { return pack_row(0u, 2u, 4u, 4u, 0u, 2u, 0u, 0u); }
    }
}

fn pack_row(a: u32, b: u32, c: u32, d: u32, e: u32, f: u32, g: u32, h: u32) -> u32 {
    return a | (b << 3u) | (c << 6u) | (d << 9u) | (e << 12u) | (f << 15u) | (g << 18u) | (h << 21u);
}

fn links_before(ncount: u32, face: u32) -> u32 {
    let below = ncount & ((1u << (4u * face)) - 1u);
    let pairs = (below & 0x0F0F0Fu) + ((below >> 4u) & 0x0F0F0Fu);
    return ((pairs * 0x010101u) >> 16u) & 0xFFu;
}

// The leaf holding finest-grid cell q, descending from `start` (a node at `level`):
// (address, level) in .xy; its cell is q >> (max_depth - level).
fn descend(start: u32, start_level: u32, q: vec3<u32>) -> vec2<u32> {
    var node = start;
    var level = start_level;
    // A valid tree is at most max_depth deep; the bound keeps any file finite.
    for (var guard = 0u; guard <= 32u && tick(); guard++) {
        if (node & INTERNAL_BIT) == 0u {
            return vec2<u32>(node, level);
        }
        let shift = params.max_depth - level - 1u;
        let child = ((q.x >> shift) & 1u) | (((q.y >> shift) & 1u) << 1u) | (((q.z >> shift) & 1u) << 2u);
        node = word(params.o_nodes + 8u * (node & ~INTERNAL_BIT) + child);
        level += 1u;
    }
    return vec2<u32>(0u, 0u);
}

fn grid_coords(p: vec3<f32>) -> vec3<u32> {
    let lo = params.root_lo.xyz;
    return vec3<u32>(grid_coord(p.x, lo.x), grid_coord(p.y, lo.y), grid_coord(p.z, lo.z));
}

struct Walk {
    o: vec3<f32>,
    d: vec3<f32>,
    inv: vec3<f32>,
    high: vec3<u32>,
    row: u32,
    // RULE_TABLE, RULE_FLAT or RULE_EXACT.
    rule: u32,
    // For an origin far outside the root (walk.rs, begin_far): the distance it was
    // moved along the ray, as the sum of two f32; zero otherwise.
    shift: vec2<f32>,
    tmin: f32,
    tmax: f32,
    address: u32,
    level: u32,
    cell: vec3<u32>,
    // Watertight shear: axes (kx, ky, kz) and (d[kx]/d[kz], d[ky]/d[kz], 1/d[kz]).
    k: vec3<u32>,
    s: vec3<f32>,
    best: HitOut,
    t_best: f32,
    steps: u32,
    tests: u32,
    done: bool,
}

fn component(v: vec3<f32>, i: u32) -> f32 {
    return select(select(v.z, v.y, i == 1u), v.x, i == 0u);
}

fn ucomponent(v: vec3<u32>, i: u32) -> u32 {
    return select(select(v.z, v.y, i == 1u), v.x, i == 0u);
}

// `v` with component `i` replaced by `x`.
fn with_component(v: vec3<u32>, i: u32, x: u32) -> vec3<u32> {
    return select(v, vec3<u32>(x), vec3<u32>(0u, 1u, 2u) == vec3<u32>(i));
}

// Woop, Benthin & Wald's watertight test (runtime/src/cpu/watertight.rs) against the
// triangle at word `at`; a hit in [tmin, tmax] comes back as (t, u, v, 1). With
// `owned`, an exact zero edge function counts only on the edge's owner
// (Shear::intersect_owned: the top-left rule, `owns`).
fn hit_triangle(wk: ptr<function, Walk>, at: u32, tmin: f32, tmax: f32, owned: bool) -> vec4<f32> {
    let o = (*wk).o;
    let a = vec3<f32>(wordf(at), wordf(at + 1u), wordf(at + 2u)) - o;
    let b = vec3<f32>(wordf(at + 3u), wordf(at + 4u), wordf(at + 5u)) - o;
    let c = vec3<f32>(wordf(at + 6u), wordf(at + 7u), wordf(at + 8u)) - o;
    let k = (*wk).k;
    let s = (*wk).s;
    let az = component(a, k.z);
    let bz = component(b, k.z);
    let cz = component(c, k.z);
    // Every product rounded on its own, as on the CPU (generated `product`: exact in
    // f64 and then rounded where the adapter has f64, so no compiler fusing a multiply
    // into the subtraction changes a bit).
    let ax = component(a, k.x) - product(s.x, az);
    let ay = component(a, k.y) - product(s.y, az);
    let bx = component(b, k.x) - product(s.x, bz);
    let by = component(b, k.y) - product(s.y, bz);
    let cx = component(c, k.x) - product(s.x, cz);
    let cy = component(c, k.y) - product(s.y, cz);
    var u = product(cx, by) - product(cy, bx);
    var v = product(ax, cy) - product(ay, cx);
    var w = product(bx, ay) - product(by, ax);
    if EXACT {
        // The exact test's first stage: what it leaves in doubt goes to the host.
        let bound = edge_bound(max(max(abs(a), abs(b)), abs(c)), abs(ax) + abs(ay), abs(bx) + abs(by), abs(cx) + abs(cy));
        let pos = f64_above(u, bound) || f64_above(v, bound) || f64_above(w, bound);
        let neg = f64_above(-u, bound) || f64_above(-v, bound) || f64_above(-w, bound);
        if pos && neg {
            return vec4<f32>(0.0); // two edges decided, on opposite sides
        }
        if !(f64_above(abs(u), bound) && f64_above(abs(v), bound) && f64_above(abs(w), bound)) {
            give_back();
            return vec4<f32>(0.0);
        }
        // All three decided and agreeing: inside, off every edge (no edge rule), the
        // plane not parallel to the ray; the distance correctly rounded or handed back.
        let det = u + v + w;
        let t = rounded_distance(o, (*wk).d, at);
        if t.y == 0.0 {
            give_back();
            return vec4<f32>(0.0);
        }
        if t.x >= tmin && t.x <= tmax {
            return vec4<f32>(t.x, div(v, det), div(w, det), 1.0);
        }
        return vec4<f32>(0.0);
    }
    if u == 0.0 || v == 0.0 || w == 0.0 {
        // Exact zeros are decided again (generated `edge`: exactly in f64 where the
        // adapter has it), as cpu::watertight does.
        u = edge(cx, cy, bx, by);
        v = edge(ax, ay, cx, cy);
        w = edge(bx, by, ax, ay);
    }
    if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
        return vec4<f32>(0.0);
    }
    let det = u + v + w;
    if det == 0.0 {
        return vec4<f32>(0.0);
    }
    if owned && (u == 0.0 || v == 0.0 || w == 0.0) {
        // U, V, W are the functions of edges B->C, C->A, A->B.
        let p = det > 0.0;
        if (u == 0.0 && !owns(p, bx, by, cx, cy)) || (v == 0.0 && !owns(p, cx, cy, ax, ay))
            || (w == 0.0 && !owns(p, ax, ay, bx, by)) {
            return vec4<f32>(0.0);
        }
    }
    // The distance: where the ray meets the triangle's plane (generated:
    // cpu::watertight::plane_distance, in f64 where the adapter has it).
    let plane = plane_distance(o, (*wk).d, at);
    let dist = plane.x;
    if plane.y != 0.0 && dist >= tmin && dist <= tmax {
        return vec4<f32>(dist, div(v, det), div(w, det), 1.0);
    }
    return vec4<f32>(0.0);
}

// Whether a triangle whose projected area is positive (or not) owns its edge from
// (fx, fy) to (tx, ty) in sheared coordinates (cpu::watertight::owns64): by
// comparisons, exact whatever the adapter does with subnormal differences.
fn owns(positive: bool, fx: f32, fy: f32, tx: f32, ty: f32) -> bool {
    let up = select((ty < fy), (ty > fy), positive);
    let right = select((tx < fx), (tx > fx), positive);
    return up || (ty == fy && right);
}

// Fans (runtime/src/cpu/fans.rs): a crowded leaf whose triangles share a vertex
// lists, through the hierarchy of their wedges at it, the few the ray's plane may
// cross. Fills `picked` with their positions in the leaf, ascending, and returns how
// many, or NO_FAN to test the whole leaf (no fan, the exact rule, a ray through the
// vertex, more than FAN_PICKS, the loop budget). The same filter as the CPU's (with,
// on adapters without f64, an absolute slack for the sheared vertex besides): the
// answers are those of testing them all.
const NO_FAN: u32 = 0xFFFFFFFFu;
const FAN_MIN_REFERENCES: u32 = 256u;
const FAN_PICKS: u32 = 64u;
const FAN_STACK: u32 = 32u;
// Beyond any finite f32 product here: a NaN or an infinity fails `< FAN_HUGE`.
const FAN_HUGE: f32 = 3.0e38;
// What `fan_pick` picks, for the leaf being tested: one array an invocation (a
// function-scope array is zeroed at every leaf of every walk, 64 stores a leaf even in
// scenes without fans). Only the entries `fan_pick` fills are read.
var<private> picked: array<u32, FAN_PICKS>;

fn with_fcomponent(v: vec3<f32>, i: u32, x: f32) -> vec3<f32> {
    return vec3<f32>(select(v.x, x, i == 0u), select(v.y, x, i == 1u), select(v.z, x, i == 2u));
}

fn fan_pick(wk: ptr<function, Walk>, box_index: u32, offset: u32, count: u32) -> u32 {
    let leaves = (params.o_cube - params.o_boxes) / 6u;
    if !FANS || EXACT || count < FAN_MIN_REFERENCES || (*wk).rule == RULE_EXACT || box_index >= leaves {
        return NO_FAN;
    }
    let at = word(params.o_fans + box_index);
    if at == NO_FAN {
        return NO_FAN;
    }
    let f = params.o_fans + at;
    if word(f) != offset || word(f + 1u) != count {
        return NO_FAN;
    }
    let v = vec3<f32>(wordf(f + 2u), wordf(f + 3u), wordf(f + 4u));
    let reach = wordf(f + 5u);
    let fan_slack = wordf(f + 6u);
    let n_rest = word(f + 7u);
    let o_rest = params.o_fans + word(f + 8u);
    let o_arcs = params.o_fans + word(f + 9u);
    let o_pairs = params.o_fans + word(f + 10u);
    // The sheared vertex, as hit_triangle computes it.
    let r = v - (*wk).o;
    let k = (*wk).k;
    let s = (*wk).s;
    let rz = component(r, k.z);
    let vx = component(r, k.x) - product(s.x, rz);
    let vy = component(r, k.y) - product(s.y, rz);
    var n = with_fcomponent(vec3<f32>(0.0), k.x, -vy);
    n = with_fcomponent(n, k.y, vx);
    n = with_fcomponent(n, k.z, product(s.x, vy) - product(s.y, vx));
    let l1 = abs(r.x) + abs(r.y) + abs(r.z);
    // Where the adapter has no f64, a product may be fused into the subtraction in one
    // place and not the other: the sheared vertex may then differ from the test's by a
    // few ulps of |r|, which the slack allows for.
    let loose = select(4.7683716e-7 * l1, 0.0, PRODUCTS_EXACT);
    let slack = ((abs(vx) + abs(vy)) * (l1 + reach) * fan_slack + loose) * 1.001;
    let fine = abs(n.x) < FAN_HUGE && abs(n.y) < FAN_HUGE && abs(n.z) < FAN_HUGE;
    if !(slack > 0.0 && slack < FAN_HUGE) || !fine {
        return NO_FAN;
    }
    let limit = min(FAN_PICKS, count / 2u);
    if n_rest >= limit {
        return NO_FAN;
    }
    var found = 0u;
    for (var i = 0u; i < n_rest; i++) {
        picked[found] = word(o_rest + i);
        found += 1u;
    }
    var stack: array<u32, FAN_STACK>;
    stack[0] = 0u;
    var top = 1u;
    loop {
        if top == 0u {
            break;
        }
        if !tick() {
            return NO_FAN;
        }
        top -= 1u;
        let pair = o_pairs + 16u * stack[top];
        for (var h = 0u; h < 2u; h++) {
            let node = pair + 8u * h;
            let node_count = word(node + 7u);
            if node_count == NO_FAN {
                continue;
            }
            let a = n * vec3<f32>(wordf(node), wordf(node + 1u), wordf(node + 2u));
            let b = n * vec3<f32>(wordf(node + 3u), wordf(node + 4u), wordf(node + 5u));
            let lo = min(a, b);
            let hi = max(a, b);
            if lo.x + lo.y + lo.z > slack || hi.x + hi.y + hi.z < -slack {
                continue;
            }
            let first = word(node + 6u);
            if node_count > 0u {
                if found + node_count > limit {
                    return NO_FAN;
                }
                for (var i = 0u; i < node_count; i++) {
                    picked[found] = word(o_arcs + first + i);
                    found += 1u;
                }
            } else {
                if top == FAN_STACK {
                    return NO_FAN;
                }
                stack[top] = first;
                top += 1u;
            }
        }
    }
    // In the leaf's order (insertion sort: a few dozen at most).
    for (var i = 1u; i < found; i++) {
        let key = picked[i];
        var j = i;
        loop {
            if j == 0u || picked[j - 1u] <= key {
                break;
            }
            picked[j] = picked[j - 1u];
            j -= 1u;
        }
        picked[j] = key;
    }
    return found;
}

// Visits the current leaf: its triangles, then the neighbour to go on to. Sets
// `done` when the walk is over; with `any`, at the first hit.
fn step(wk: ptr<function, Walk>, any: bool) {
    (*wk).steps += 1u;
    if (*wk).steps > params.max_steps {
        (*wk).best.flags |= 1u;
        (*wk).done = true;
        return;
    }
    let address = (*wk).address;
    let rec = params.o_octree + address;
    let count = word(rec);
    let offset = word(rec + 1u);
    let box_index = word(rec + 2u);
    let ncount = word(rec + 3u);
    // 1. The leaf's triangles: keep the nearest in [tmin, t_best] (in a fan's leaf,
    // those its hierarchy picks).
    let fan = fan_pick(wk, box_index, offset, count);
    let tested = select(count, fan, fan != NO_FAN);
    (*wk).tests += tested;
    for (var j = 0u; j < tested && tick(); j++) {
        let tri = word(params.o_refs + offset + select(j, picked[min(j, FAN_PICKS - 1u)], fan != NO_FAN));
        var h: vec4<f32>;
        if (*wk).rule == RULE_EXACT && !EXACT {
            // In f64 throughout (generated: cpu::watertight::Shear::intersect_f64).
            h = hit_triangle_exact(wk, params.o_tris + 9u * tri, (*wk).tmin, (*wk).t_best, false);
        } else {
            h = hit_triangle(wk, params.o_tris + 9u * tri, (*wk).tmin, (*wk).t_best, false);
        }
        // The exact test orders equal rounded distances exactly (walk.rs, `replaces`):
        // that comparison is the host's.
        if EXACT && h.w != 0.0 && h.x == (*wk).t_best && (*wk).best.triangle != MISS && (*wk).best.prim != tri {
            give_back();
            return;
        }
        // Of equal hits the last tested, which is the lowest input id (walk.rs, `keep`).
        if h.w != 0.0 {
            (*wk).t_best = h.x;
            (*wk).best.t = h.x;
            (*wk).best.triangle = word(params.o_ids + tri);
            (*wk).best.u = h.y;
            (*wk).best.v = h.z;
            (*wk).best.leaf = box_index;
            (*wk).best.prim = tri;
            if any {
                (*wk).done = true;
                return;
            }
        }
    }
    // 2. The exit face and distance (`leave`); a candidate inside this leaf is the
    // nearest, and past tmax nothing more counts.
    let l = leave(wk);
    if ((*wk).best.triangle != MISS && (*wk).best.t <= l.t) || l.t >= (*wk).tmax {
        (*wk).done = true;
        return;
    }
    // 3. The neighbour across the face.
    if !follow(wk, l, ncount) {
        (*wk).done = true;
    }
}

// Where a walk leaves its leaf (walk.rs, exit_of): the face, the distance, and the
// exit axis's corner offset and direction component.
struct Leave {
    face: u32,
    t: f32,
    off_a: f32,
    d_a: f32,
}

// The exit corner from the cell, then the exit face from three Plücker signs.
fn leave(wk: ptr<function, Walk>) -> Leave {
    let cell = (*wk).cell;
    let level = (*wk).level;
    let size = ldexp(params.root_lo.w, -i32(level & 31u));
    let lo = params.root_lo.xyz;
    let o = (*wk).o;
    let d = (*wk).d;
    let off = (lo + vec3<f32>(cell + (*wk).high) * size) - o;
    let p_xy = off.x * d.y - off.y * d.x;
    let p_yz = off.y * d.z - off.z * d.y;
    let p_zx = off.z * d.x - off.x * d.z;
    let code = select(0u, 1u, p_xy > 0.0) | select(0u, 2u, p_yz > 0.0) | select(0u, 4u, p_zx > 0.0);
    var face = ((*wk).row >> (3u * code)) & 7u;
    // A zero direction component: the slab rule, never the table (exit_along_moving_axes
    // in walk.rs says why); a direction the f32 products cannot serve: exact decisions
    // (tables::exit_rule).
    let exact = (*wk).rule == RULE_EXACT;
    var t_exact = 0.0;
    if exact {
        let e = exact_exit(off, d);
        face = e.face;
        t_exact = e.t;
    } else if (*wk).rule == RULE_FLAT {
        face = exit_along_moving_axes(off, d, (*wk).inv);
    }
    let axis = face >> 1u;
    let off_a = component(off, axis);
    var t_exit = off_a * component((*wk).inv, axis);
    if exact {
        t_exit = t_exact;
    }
    return Leave(face, t_exit, off_a, component(d, axis));
}

// Moves the walk across face `l.face` of its leaf (record word `ncount`) to the
// neighbour there (walk.rs, follow): one, or one of four by the median lines; false
// where there is none.
fn follow(wk: ptr<function, Walk>, l: Leave, ncount: u32) -> bool {
    let face = l.face;
    let n = (ncount >> (4u * face)) & 0xFu;
    if n == 0u {
        return false;
    }
    let cell = (*wk).cell;
    let level = (*wk).level;
    let size = ldexp(params.root_lo.w, -i32(level & 31u));
    let lo = params.root_lo.xyz;
    let o = (*wk).o;
    let d = (*wk).d;
    let axis = face >> 1u;
    let off_a = l.off_a;
    let d_a = l.d_a;
    let half = 0.5 * size;
    let negative_a = (face & 1u) == 0u;
    let mid = lo + vec3<f32>(2u * cell + 1u) * half;
    let m = mid - o;
    let p = off_a * d - m * d_a;
    var sides = vec3<u32>(select(vec3<u32>(0u), vec3<u32>(1u), p > vec3<f32>(0.0))) ^ vec3<u32>(select(0u, 1u, negative_a));
    if (*wk).rule == RULE_EXACT {
        sides = vec3<u32>(
            exact_side(off_a, d_a, m.x, d.x, negative_a),
            exact_side(off_a, d_a, m.y, d.y, negative_a),
            exact_side(off_a, d_a, m.z, d.z, negative_a),
        );
    }
    let side_bits = sides.x | (sides.y << 1u) | (sides.z << 2u);
    let quadrant = (side_bits & ((1u << axis) - 1u)) | ((side_bits >> (axis + 1u)) << axis);
    let address = (*wk).address;
    let link = address + LEAF_HEADER_WORDS + links_before(ncount, face) + (n >> 2u) * quadrant;
    (*wk).address = word(params.o_octree + link);
    // The neighbour's cell: ((across << 1) | child bit) >> (1 + coarser - finer).
    let coarser = (ncount >> (COARSER_SHIFT + face)) & 1u;
    let finer = n >> 2u;
    let shift = 1u + coarser - finer;
    let up = (face & 1u) * 2u;
    let across = ((ucomponent(cell, axis) + up - 1u) << 1u) | select(0u, 1u, negative_a);
    let next = with_component((cell << vec3<u32>(1u)) | sides, axis, across);
    (*wk).cell = next >> vec3<u32>(shift);
    (*wk).level = level + finer - coarser;
    return true;
}

struct Exit {
    face: u32,
    t: f32,
}

// tables::exact_exit: the moving axis whose exit plane the ray meets first, decided
// exactly (generated `exits_before`), ties to the lowest axis; its distance rounded once.
fn exact_exit(off: vec3<f32>, d: vec3<f32>) -> Exit {
    var axis = 3u;
    if !is_zero(d.x) {
        axis = 0u;
    }
    if !is_zero(d.y) && (axis == 3u || exits_before(off.y, d.y, component(off, axis), component(d, axis))) {
        axis = 1u;
    }
    if !is_zero(d.z) && (axis == 3u || exits_before(off.z, d.z, component(off, axis), component(d, axis))) {
        axis = 2u;
    }
    axis = axis % 3u;
    let da = component(d, axis);
    return Exit(2u * axis + select(1u, 0u, is_negative(da)), exact_distance(component(off, axis), da));
}

// The exit face of a ray with a zero direction component: the nearest exit among the
// axes it moves along (ties to the lowest axis).
fn exit_along_moving_axes(off: vec3<f32>, d: vec3<f32>, inv: vec3<f32>) -> u32 {
    var best_t = inf();
    var best_axis = 0u;
    var found = false;
    for (var a = 0u; a < 3u && tick(); a++) {
        if component(d, a) != 0.0 {
            let t = component(off, a) * component(inv, a);
            if t < best_t || !found {
                best_t = t;
                best_axis = a;
                found = true;
            }
        }
    }
    return 2u * best_axis + select(1u, 0u, is_negative(component(d, best_axis)));
}

// The ray's interval in the box lo..hi: (t0, t1, entry axis, 1) or w = 0 on a miss.
// Zero components explicitly: 0 * inf never happens.
fn clip(o: vec3<f32>, d: vec3<f32>, lo: vec3<f32>, hi: vec3<f32>) -> vec4<f32> {
    var t0 = -inf();
    var t1 = inf();
    var entry_axis = 0u;
    for (var a = 0u; a < 3u && tick(); a++) {
        let da = component(d, a);
        let oa = component(o, a);
        let la = component(lo, a);
        let ha = component(hi, a);
        if da == 0.0 {
            if oa < la || oa > ha {
                return vec4<f32>(0.0);
            }
            continue;
        }
        let ta = div(la - oa, da);
        let tb = div(ha - oa, da);
        let near = min(ta, tb);
        let far = max(ta, tb);
        if near > t0 {
            t0 = near;
            entry_axis = a;
        }
        t1 = min(t1, far);
    }
    if !(t0 <= t1) {
        return vec4<f32>(0.0);
    }
    return vec4<f32>(t0, t1, f32(entry_axis), 1.0);
}

// Starts a walk: clips to the root, finds the first leaf. `done` when it cannot hit.
fn begin(o0: vec3<f32>, d: vec3<f32>, tmin0: f32, tmax0: f32) -> Walk {
    var wk: Walk;
    wk.done = true;
    wk.best.t = tmax0;
    wk.best.triangle = MISS;
    wk.best.flags = 0u;
    wk.steps = 0u;
    wk.tests = 0u;
    wk.shift = vec2<f32>(0.0);
    let finite = is_finite(o0.x) && is_finite(o0.y) && is_finite(o0.z) && is_finite(d.x) && is_finite(d.y) && is_finite(d.z);
    if !finite || all(d == vec3<f32>(0.0)) || is_nan(tmin0) || is_nan(tmax0) || !(tmin0 <= tmax0) {
        return wk;
    }
    // An origin far outside the root (more than FAR_ROOTS root edges, tracer.rs) is
    // moved to where the ray enters the root (walk.rs, begin_far; generated
    // `far_shift`, in f64 where the adapter has it).
    var o = o0;
    var tmin = tmin0;
    var tmax = tmax0;
    let reach = FAR_ROOTS * params.root_lo.w;
    if any(o0 < params.root_lo.xyz - reach) || any(o0 > params.root_hi.xyz + reach) {
        let far = far_shift(o0, d, tmin0);
        if far.z == 0.0 {
            return wk;
        }
        // The exact test decides on the ray as given, which the moved one is not (its
        // origin rounded): the host's walk does so (walk.rs, `Far`).
        if EXACT {
            give_back();
            return wk;
        }
        wk.shift = far.xy;
        o = moved_origin(o0, d, far.xy);
        tmin = unshifted(tmin0, far.xy);
        tmax = moved_tmax(tmax0, far.xy);
        wk.best.t = tmax;
    }
    // Clip to the root cube, then to the mesh box: beyond it there is nothing to hit.
    let mesh = clip(o, d, params.box_lo.xyz, params.box_hi.xyz);
    if mesh.w == 0.0 {
        return wk;
    }
    // A ray that grazes the root's edge where the mesh box reaches the root's faces,
    // which the root clip's rounding calls a miss, starts where it enters the
    // enlarged box (walk.rs, begin_near).
    var root = clip(o, d, params.root_lo.xyz, params.root_hi.xyz);
    let grazes = root.w == 0.0;
    if grazes {
        root = vec4<f32>(mesh.x, mesh.y, 0.0, 1.0);
    }
    let t0 = root.x;
    let entry_axis = u32(root.z);
    let t_start = max(t0, tmin);
    let box_stop = mesh.y + abs(mesh.y) * BOX_T_SLACK;
    let t_stop = min(tmax, box_stop);
    // Not against tmax (walk.rs, begin_near, says why).
    if t_start > root.y || max(t_start, mesh.x) > box_stop {
        return wk;
    }
    // Reached past f32's range (a tiny direction from far away): no representable hit.
    if max(t_start, mesh.x) == inf() {
        return wk;
    }
    // The first leaf: through the cube map from outside, by point location inside.
    var leaf: vec2<u32>;
    var q: vec3<u32>;
    if grazes {
        q = grid_coords(o + t_start * d);
        leaf = descend(params.root_node, 0u, q);
    } else if mesh.x > t_start {
        q = grid_coords(o + mesh.x * d);
        leaf = descend(params.root_node, 0u, q);
    } else if t0 > tmin {
        q = grid_coords(o + t0 * d);
        let high = component(d, entry_axis) < 0.0;
        let last = (1u << params.max_depth) - 1u;
        q = with_component(q, entry_axis, select(0u, last, high));
        let face = 2u * entry_axis + select(0u, 1u, high);
        let level = params.cube_level;
        let res = 1u << level;
        let shift = params.max_depth - level;
        var iu: u32;
        var iv: u32;
        if entry_axis == 0u {
            iu = q.y;
            iv = q.z;
        } else if entry_axis == 1u {
            iu = q.x;
            iv = q.z;
        } else {
            iu = q.x;
            iv = q.y;
        }
        let texel = (face * res + (iv >> shift)) * res + (iu >> shift);
        let node = word(params.o_cube + texel);
        if (node & INTERNAL_BIT) != 0u {
            leaf = descend(node, level, q);
        } else {
            // The texel's leaf may be coarser than the texel: its level from its box's
            // edge, a power-of-two fraction of the root's.
            let b = params.o_boxes + 6u * word(params.o_octree + node + 2u);
            let edge = wordf(b + 3u) - wordf(b);
            let ratio = div(params.root_lo.w, edge) * 1.4142135;
            let exponent = i32((bitcast<u32>(ratio) >> 23u) & 0xFFu) - 127;
            leaf = vec2<u32>(node, u32(clamp(exponent, 0, i32(level))));
        }
    } else {
        q = grid_coords(o + t_start * d);
        leaf = descend(params.root_node, 0u, q);
    }
    wk.o = o;
    wk.d = d;
    wk.inv = vec3<f32>(div(1.0, d.x), div(1.0, d.y), div(1.0, d.z));
    wk.high = vec3<u32>(select(1u, 0u, is_negative(d.x)), select(1u, 0u, is_negative(d.y)), select(1u, 0u, is_negative(d.z)));
    let octant = select(0u, 1u, is_negative(d.x)) | select(0u, 2u, is_negative(d.y)) | select(0u, 4u, is_negative(d.z));
    wk.row = exit_row(octant);
    wk.rule = exit_rule(o, d);
    wk.tmin = tmin;
    wk.tmax = t_stop;
    wk.address = leaf.x;
    wk.level = leaf.y;
    wk.cell = q >> vec3<u32>(params.max_depth - leaf.y);
    set_shear(&wk, d);
    wk.t_best = tmax;
    wk.done = false;
    return wk;
}

// The watertight shear of direction d (cpu::watertight::Shear::new): kz the largest
// component, winding kept.
fn set_shear(wk: ptr<function, Walk>, d: vec3<f32>) {
    let ad = abs(d);
    var kz = 2u;
    if ad.x >= ad.y && ad.x >= ad.z {
        kz = 0u;
    } else if ad.y >= ad.z {
        kz = 1u;
    }
    var kx = (kz + 1u) % 3u;
    var ky = (kz + 2u) % 3u;
    if component(d, kz) < 0.0 {
        let t = kx;
        kx = ky;
        ky = t;
    }
    let dz = component(d, kz);
    (*wk).k = vec3<u32>(kx, ky, kz);
    (*wk).s = vec3<f32>(div(component(d, kx), dz), div(component(d, ky), dz), div(1.0, dz));
}

// The nearest hit of a ray in [tmin, tmax] (with `any`, any hit), with the walk's
// counts in `steps` and `flags`.
fn trace(o: vec3<f32>, d: vec3<f32>, tmin: f32, tmax: f32, any: bool) -> HitOut {
    var wk = begin(o, d, tmin, tmax);
    // Bounded by max_steps (step() stops the walk there), and by the loop budget.
    loop {
        if wk.done || !tick() {
            break;
        }
        step(&wk, any);
    }
    var out = wk.best;
    // A moved origin's distances back from the ray's own (walk.rs, RayWalk::unshift).
    if wk.shift.x != 0.0 || wk.shift.y != 0.0 {
        out.t = select(tmax, clamp(shifted(out.t, wk.shift), tmin, tmax), out.triangle != MISS);
    }
    out.steps = wk.steps;
    out.flags = (out.flags & 1u) | (min(wk.tests, 0x7FFFFFFFu) << 1u);
    return out;
}

// Every crossing of a ray in [tmin, tmax] in order, each once (cpu::crossings,
// crossings_entering): each leaf tests its triangles with edges owned and keeps the
// crossings in its piece of the ray, (the previous leaf's exit, its own exit] (the
// first leaf's from tmin, closed; the last's to tmax). Counts them and those arriving
// on a front (generated `arrives_on_front`); with MODE 2 writes the first `capacity`
// to `hits[base..]`, each leaf's sorted by (walk distance, input id), distances moved
// back for a moved origin. (total, entries, steps).
fn cross(o: vec3<f32>, d: vec3<f32>, tmin0: f32, tmax0: f32, base: u32, capacity: u32) -> vec3<u32> {
    var wk = begin(o, d, tmin0, tmax0);
    var total = 0u;
    var entries = 0u;
    var lo = 0.0;
    var first = true;
    let exact = wk.rule == RULE_EXACT;
    let moved = wk.shift.x != 0.0 || wk.shift.y != 0.0;
    loop {
        if wk.done || !tick() {
            break;
        }
        wk.steps += 1u;
        if wk.steps > params.max_steps {
            break;
        }
        let rec = params.o_octree + wk.address;
        let count = word(rec);
        let offset = word(rec + 1u);
        let ncount = word(rec + 3u);
        let l = leave(&wk);
        let n = (ncount >> (4u * l.face)) & 0xFu;
        let last = l.t >= wk.tmax || n == 0u;
        var hi = wk.t_best;
        if !last {
            hi = max(l.t, select(lo, wk.tmin, first));
        }
        let leaf_start = total;
        let fan = fan_pick(&wk, word(rec + 2u), offset, count);
        let tested = select(count, fan, fan != NO_FAN);
        for (var j = 0u; j < tested && tick(); j++) {
            let tri = word(params.o_refs + offset + select(j, picked[min(j, FAN_PICKS - 1u)], fan != NO_FAN));
            let at = params.o_tris + 9u * tri;
            var h: vec4<f32>;
            if exact && !EXACT {
                h = hit_triangle_exact(&wk, at, wk.tmin, hi, true);
            } else {
                h = hit_triangle(&wk, at, wk.tmin, hi, true);
            }
            if h.w == 0.0 || (!first && h.x <= lo) {
                continue;
            }
            let front = arrives_on_front(wk.d, at);
            if MODE == 2u && leaf_start < capacity {
                var c: HitOut;
                c.t = h.x;
                if moved {
                    c.t = clamp(shifted(h.x, wk.shift), tmin0, tmax0);
                }
                c.triangle = word(params.o_ids + tri);
                c.u = h.y;
                c.v = h.z;
                c.leaf = select(0u, 1u, front);
                c.prim = tri;
                // The walk's distance, the sort key (a moved origin's distances may
                // round together), as f32::total_cmp orders it.
                c.steps = order_key(h.x);
                c.flags = 0u;
                // Insertion into the leaf's sorted run, [leaf_start, min(total,
                // capacity)): in a full list (a ray cut at its first `capacity`) a
                // crossing after the last kept is dropped, one before it pushes the
                // last out.
                var k = min(total, capacity);
                let key = c.steps;
                loop {
                    if k == leaf_start || !tick() {
                        break;
                    }
                    let prev = get_hit(base + k - 1u);
                    // Equal rounded distances: the exact test's order is the host's.
                    if EXACT && prev.steps == key {
                        give_back();
                        break;
                    }
                    if prev.steps < key || (prev.steps == key && prev.triangle < c.triangle) {
                        break;
                    }
                    if k < capacity {
                        put_hit(base + k, prev);
                    }
                    k -= 1u;
                }
                if k < capacity {
                    put_hit(base + k, c);
                }
            }
            total += 1u;
            entries += select(0u, 1u, front);
        }
        lo = hi;
        first = false;
        // A list full after a leaf is done: the next leaves' crossings lie beyond.
        if last || (MODE == 2u && total >= capacity) || !follow(&wk, l, ncount) {
            break;
        }
    }
    return vec3<u32>(total, entries, wk.steps);
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(local_invocation_index) lane: u32) {
    let i = gid.x;
    if MODE == 0u && RECORD == 3u {
        occlusion_bits(i, lane);
        return;
    }
    if i >= params.ray_count {
        return;
    }
    if MODE == 3u {
        var side = side_of(point_at(i));
        if over_budget {
            side = UNDECIDED;
        }
        hits[i] = side;
        return;
    }
    let r = ray_at(i);
    let r0 = r[0];
    let r1 = r[1];
    if MODE == 0u {
        var out = trace(r0.xyz, r1.xyz, r0.w, r1.w, ANY_HIT);
        // A walk that ran out of loop budget: the host traces it again on the CPU.
        if over_budget {
            out.steps = OVER_BUDGET;
        }
        put_record(i, out);
        return;
    }
    if MODE == 1u {
        let c = cross(r0.xyz, r1.xyz, r0.w, r1.w, 0u, 0u);
        var out: HitOut;
        out.triangle = c.x;
        out.leaf = c.y;
        out.steps = select(c.z, OVER_BUDGET, over_budget);
        put_hit(i, out);
        return;
    }
    // MODE 2: ray i's records start at offsets[i] (u32s after the rays, four a vec4).
    let n = params.ray_count;
    let base = ray_offset(n, i);
    let capacity = ray_offset(n, i + 1u) - base;
    cross(r0.xyz, r1.xyz, r0.w, r1.w, base, capacity);
    if over_budget && capacity > 0u {
        hits[8u * base + 7u] = OVER_BUDGET;
    }
}

// The walk's tmax for a moved origin: the largest distance from it that `shifted`
// takes back to tmax or below (walk.rs, moved_tmax), by a binary search over the
// f32 in order.
fn moved_tmax(tmax: f32, s: vec2<f32>) -> f32 {
    if !is_finite(tmax) {
        return tmax;
    }
    var lo = order_key(bitcast<f32>(0xFF800000u));
    var hi = order_key(bitcast<f32>(0x7F800000u));
    for (var i = 0u; i < 34u && hi - lo > 1u; i++) {
        let mid = lo + (hi - lo) / 2u;
        if shifted(from_order_key(mid), s) <= tmax {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    return from_order_key(lo);
}

// `order_key`'s inverse.
fn from_order_key(k: u32) -> f32 {
    return bitcast<f32>(select(~k, k & 0x7FFFFFFFu, (k >> 31u) == 1u));
}

// The bits of `t` as an unsigned key in f32::total_cmp's order.
fn order_key(t: f32) -> u32 {
    let b = bitcast<u32>(t);
    return select(b | 0x80000000u, ~b, (b >> 31u) == 1u);
}

// Offset `i` of the list kernel's, after the `n` rays (their bits: no float
// operation touches them).
fn ray_offset(n: u32, i: u32) -> u32 {
    let v = bitcast<vec4<u32>>(rays[2u * n + i / 4u]);
    return v[i % 4u];
}

// `HitOut::steps` of a walk that ran out of loop budget.
const OVER_BUDGET: u32 = 0xFFFFFFFFu;

// MODE 3, inside/outside of points (cpu::inside): 0 outside, 1 inside, UNDECIDED for
// the host. A point outside the mesh box is outside; a point in an empty leaf takes
// the leaf's label, which holds for its whole closed box (no triangle comes within the
// bake's margin of it); a point in a leaf with a reference point counts the crossings
// of the segment to it (`side_by_reference`). The point is checked to lie in the
// leaf's box, so a location rounded into a neighbour decides nothing. The rest (leaves
// with triangles and no reference point, decisions in doubt) are the host's.
const UNDECIDED: u32 = 2u;

// Point i of MODE 3: three floats a point in the rays binding, 12 bytes as given,
// after the leaf labels (a byte a leaf, to a whole vec4).
fn point_at(i: u32) -> vec3<f32> {
    let w = 4u * ((params.labels + 15u) / 16u) + 3u * i;
    return vec3<f32>(rays[w / 4u][w % 4u], rays[(w + 1u) / 4u][(w + 1u) % 4u], rays[(w + 2u) / 4u][(w + 2u) % 4u]);
}
// Leaf labels (cpu::inside): from REFERENCED on, REFERENCED + 2 * candidate + inside.
const REFERENCED: u32 = 3u;

fn side_of(p: vec3<f32>) -> u32 {
    if !(all(p >= params.box_lo.xyz) && all(p <= params.box_hi.xyz)) {
        // Outside the (enlarged) mesh box, or NaN: outside, as on the CPU.
        return 0u;
    }
    if any(p < params.root_lo.xyz) || any(p > params.root_hi.xyz) {
        return UNDECIDED;
    }
    let leaf = descend(params.root_node, 0u, grid_coords(p));
    let b = word(params.o_octree + leaf.x + 2u);
    if b >= params.labels {
        return UNDECIDED;
    }
    // The labels' words come first, four labels a word.
    let at = b / 4u;
    let label = (bitcast<u32>(rays[at / 4u][at % 4u]) >> (8u * (b % 4u))) & 0xFFu;
    let o = params.o_boxes + 6u * b;
    let lo = vec3<f32>(wordf(o), wordf(o + 1u), wordf(o + 2u));
    let hi = vec3<f32>(wordf(o + 3u), wordf(o + 4u), wordf(o + 5u));
    if !(all(p >= lo) && all(p <= hi)) {
        return UNDECIDED;
    }
    if label <= 1u {
        return label;
    }
    if label >= REFERENCED && EXACT {
        return side_by_reference(p, leaf.x, lo, hi, label);
    }
    return UNDECIDED;
}

// A point in a leaf with a reference point (cpu::inside, contains_by_reference): the
// reference point's side, flipped by the parity of the crossings of the segment from
// the point to it over the leaf's triangles (the segment stays in the leaf's box,
// whose triangles the leaf lists all), under the exact test's filter, which hands
// back what it leaves in doubt. A crossing at a distance of zero (the point on the
// surface, answered by the host's rule) is the host's too; any other crossing's
// rounded distance has its exact sign. The reference point is clear of every plane of
// the leaf's triangles, so no crossing lies near the segment's end.
fn side_by_reference(p: vec3<f32>, address: u32, lo: vec3<f32>, hi: vec3<f32>, label: u32) -> u32 {
    let i = (label - REFERENCED) / 2u;
    let inside = (label - REFERENCED) % 2u;
    // Candidate i of the box (cpu::inside, candidate): exact, the box's edge a power of two.
    let f = vec3<f32>(candidate_at(i % 3u), candidate_at((i / 3u) % 3u), candidate_at(i / 9u));
    let c = lo + (hi - lo) * f;
    let d = c - p;
    if all(d == vec3<f32>(0.0)) {
        return inside;
    }
    var wk: Walk;
    wk.o = p;
    wk.d = d;
    set_shear(&wk, d);
    let count = word(params.o_octree + address);
    let offset = word(params.o_octree + address + 1u);
    var odd = 0u;
    for (var j = 0u; j < count && tick(); j++) {
        let tri = word(params.o_refs + offset + j);
        let h = hit_triangle(&wk, params.o_tris + 9u * tri, -inf(), 1.0, true);
        if over_budget || (h.w != 0.0 && h.x == 0.0) {
            return UNDECIDED;
        }
        if h.w != 0.0 && h.x > 0.0 {
            odd ^= 1u;
        }
    }
    if over_budget {
        return UNDECIDED;
    }
    return inside ^ odd;
}

// The fractions of a box's edge its reference candidates lie at: 1/2, 1/4, 3/4.
fn candidate_at(k: u32) -> f32 {
    return select(select(0.75, 0.25, k == 1u), 0.5, k == 0u);
}
