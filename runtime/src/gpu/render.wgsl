// The effects renderer of runtime/src/render/effects.rs, one pixel per invocation,
// shading included. Appended to trace.wgsl (its `trace` walks the octree).
//
// The CPU renders in waves; here each invocation runs its pixel's ray tree depth
// first with a private stack: a hit pushes the rays its shading asks for (alpha
// continuation, refraction, reflection) and traces its shadow rays on the spot. The
// light each ray brings is the CPU's, term for term (the same reflectance model, the
// same random numbers, materials' derived values computed once on the host); only the
// order of the sums differs.
//
// Which effects run is fixed when the pipeline is made, with override constants: an
// effect turned off is a constant `false` and the compiler drops its code. The host
// generates STACK_SIZE (2 max_depth + 1: the deepest a depth-first ray tree of up to
// three children a hit gets) and GAMMA_7 above this file.

override SHADOWS: bool = true;
override SOFT_SHADOWS: bool = true;
override REFLECTION: bool = true;
override REFRACTION: bool = true;
override ALPHA: bool = true;
// No light and no emitter: a headlight at the camera, no shadow rays.
override HEADLIGHT: bool = false;

struct RenderParams {
    // xyz: the eye; w: tan(fov / 2).
    eye: vec4<f32>,
    // xyz: right; w: width / height.
    right: vec4<f32>,
    // xyz: up.
    up: vec4<f32>,
    // xyz: backwards (from the target to the eye).
    back: vec4<f32>,
    width: u32,
    height: u32,
    first_pixel: u32,
    pixel_count: u32,
    max_depth: u32,
    soft_samples: u32,
    light_count: u32,
    emitter_count: u32,
    // Word offsets in `shade`; material_ids and normals are absent when their count is 0.
    o_materials: u32,
    o_lights: u32,
    o_emitters: u32,
    o_material_ids: u32,
    o_normals: u32,
    has_material_ids: u32,
    has_normals: u32,
    // The material of triangles without one (the last record).
    plain_material: u32,
    emitter_area: f32,
    pad0: u32,
    pad1: u32,
    pad2: u32,
}

@group(1) @binding(0) var<uniform> rp: RenderParams;
// Materials (28 words each, see `MaterialRecord` in render.rs), lights (16 words),
// emitters (4 words: radiance rgb, running area), emitter triangles (1 word), material
// ids and normals (the file's sections, as they are).
@group(1) @binding(1) var<storage, read> shade: array<u32>;
@group(1) @binding(2) var<storage, read_write> radiance_out: array<vec4<f32>>;
// Rays traced per kind (RayKind order), summed over the dispatch: 64 bits each, low
// word first.
@group(1) @binding(3) var<storage, read_write> ray_counts: array<atomic<u32>, 12>;

const PRIMARY: u32 = 0u;
const SHADOW: u32 = 1u;
const SOFT_SHADOW: u32 = 2u;
const REFLECTION_RAY: u32 = 3u;
const REFRACTION_RAY: u32 = 4u;
const ALPHA_RAY: u32 = 5u;

const PI: f32 = 3.14159265358979;
const BACKGROUND: vec3<f32> = vec3<f32>(0.08, 0.08, 0.1);
const HEADLIGHT_AMBIENT: f32 = 0.1;
const HEADLIGHT_DIRECT: f32 = 0.85;
const AREA_SHADOW_END: f32 = 0.999;
const MAX_SHADOW_LAYERS: u32 = 16u;
const VISIBLE_WEIGHT: f32 = 0.001953125;
const F32_MIN_POSITIVE: f32 = 1.17549435e-38;

struct Task {
    o: vec3<f32>,
    depth: u32,
    d: vec3<f32>,
    kind: u32,
    weight: vec3<f32>,
}

struct Material {
    emissive: vec3<f32>,
    coverage: f32,
    albedo: vec3<f32>,
    transmission: f32,
    albedo_transmits: vec3<f32>,
    ior: f32,
    ks: vec3<f32>,
    exponent: f32,
    base: vec3<f32>,
    mirror: vec3<f32>,
    shadow_pass: vec3<f32>,
}

// A hit prepared for spawning rays (runtime/src/spawn.rs, SpawnPoint).
struct SpawnPoint {
    point: vec3<f32>,
    normal: vec3<f32>,
    offset: f32,
}

var<private> stack: array<Task, STACK_SIZE>;
var<private> counts: array<u32, 6>;
var<workgroup> group_counts: array<atomic<u32>, 6>;

fn sf(i: u32) -> f32 {
    return bitcast<f32>(shade[i]);
}

fn sv3(i: u32) -> vec3<f32> {
    return vec3<f32>(sf(i), sf(i + 1u), sf(i + 2u));
}

fn max3(v: vec3<f32>) -> f32 {
    return max(max(v.x, v.y), v.z);
}

fn normalize_or_zero(v: vec3<f32>) -> vec3<f32> {
    let r = 1.0 / length(v);
    if is_finite(r) && r > 0.0 {
        return v * r;
    }
    return vec3<f32>(0.0);
}

fn next_up(x: f32) -> f32 {
    if is_nan(x) || x == inf() {
        return x;
    }
    if x == 0.0 {
        return bitcast<f32>(1u);
    }
    let bits = bitcast<u32>(x);
    return bitcast<f32>(select(bits - 1u, bits + 1u, x > 0.0));
}

fn next_down(x: f32) -> f32 {
    return -next_up(-x);
}

fn material(prim: u32) -> Material {
    var id = rp.plain_material;
    if rp.has_material_ids != 0u {
        id = min(shade[rp.o_material_ids + prim], rp.plain_material);
    }
    let at = rp.o_materials + 28u * id;
    var m: Material;
    m.emissive = sv3(at);
    m.coverage = sf(at + 3u);
    m.albedo = sv3(at + 4u);
    m.transmission = sf(at + 7u);
    m.albedo_transmits = sv3(at + 8u);
    m.ior = sf(at + 11u);
    m.ks = sv3(at + 12u);
    m.exponent = sf(at + 15u);
    m.base = sv3(at + 16u);
    m.mirror = sv3(at + 20u);
    m.shadow_pass = sv3(at + 24u);
    return m;
}

fn vertex(prim: u32, corner: u32) -> vec3<f32> {
    let at = params.o_tris + 9u * prim + 3u * corner;
    return vec3<f32>(wordf(at), wordf(at + 1u), wordf(at + 2u));
}

fn face_normal(a: vec3<f32>, b: vec3<f32>, c: vec3<f32>) -> vec3<f32> {
    return normalize_or_zero(cross(b - a, c - a));
}

fn spawn_point(prim: u32, hit: HitOut) -> SpawnPoint {
    let v0 = vertex(prim, 0u);
    let v1 = vertex(prim, 1u);
    let v2 = vertex(prim, 2u);
    let b0 = 1.0 - hit.u - hit.v;
    var sp: SpawnPoint;
    sp.point = b0 * v0 + hit.u * v1 + hit.v * v2;
    let err = GAMMA_7 * (abs(b0 * v0) + abs(hit.u * v1) + abs(hit.v * v2));
    sp.normal = face_normal(v0, v1, v2);
    let scale = max(max3(abs(v0)), max(max3(abs(v1)), max3(abs(v2))));
    sp.offset = max(dot(err, abs(sp.normal)), GAMMA_7 * scale);
    return sp;
}

// The origin of a ray leaving `sp` towards `d`: offset to the side it leaves by, then
// one float further out per axis.
fn spawn_origin(sp: SpawnPoint, d: vec3<f32>) -> vec3<f32> {
    let n = select(sp.normal, -sp.normal, dot(sp.normal, d) < 0.0);
    let offset = n * sp.offset;
    var o = sp.point + offset;
    if offset.x > 0.0 { o.x = next_up(o.x); } else if offset.x < 0.0 { o.x = next_down(o.x); }
    if offset.y > 0.0 { o.y = next_up(o.y); } else if offset.y < 0.0 { o.y = next_down(o.y); }
    if offset.z > 0.0 { o.z = next_up(o.z); } else if offset.z < 0.0 { o.z = next_down(o.z); }
    return o;
}

// runtime/src/render/lighting.rs, uniform2: Wellons' lowbias32.
fn hash32(x0: u32) -> u32 {
    var x = x0;
    x ^= x >> 16u;
    x *= 0x7feb352du;
    x ^= x >> 15u;
    x *= 0x846ca68bu;
    return x ^ (x >> 16u);
}

fn uniform2(pixel: u32, depth: u32, sample: u32) -> vec2<f32> {
    let a = hash32(sample + hash32(depth + hash32(pixel)));
    let b = hash32(a);
    return vec2<f32>(f32(a >> 8u), f32(b >> 8u)) * (1.0 / 16777216.0);
}

// lighting::reflectance: Lambert plus a normalised Blinn-Phong highlight.
fn reflectance(m: Material, transmits: bool, n: vec3<f32>, v: vec3<f32>, l: vec3<f32>) -> vec3<f32> {
    let kd = select(m.albedo, m.albedo_transmits, transmits);
    let h = normalize_or_zero(v + l);
    var spec = vec3<f32>(0.0);
    if any(m.ks != vec3<f32>(0.0)) {
        let lobe = pow(max(dot(n, h), 0.0), m.exponent);
        spec = m.ks * (m.exponent + 8.0) / (8.0 * PI) * select(0.0, lobe, lobe >= F32_MIN_POSITIVE);
    }
    return kd / PI + spec;
}

// What reaches a shadow ray's end: 1 when nothing blocks it, 0 when something does, and
// with alpha or refraction what the surfaces it crosses let through.
fn shadow(o0: vec3<f32>, d: vec3<f32>, tmax0: f32, kind: u32) -> vec3<f32> {
    if !(ALPHA || REFRACTION) {
        counts[kind] += 1u;
        let blocked = trace(o0, d, 0.0, tmax0, true).triangle != MISS;
        return select(vec3<f32>(1.0), vec3<f32>(0.0), blocked);
    }
    var o = o0;
    var tmax = tmax0;
    var through = vec3<f32>(1.0);
    for (var layers = 0u; layers <= MAX_SHADOW_LAYERS; layers++) {
        counts[kind] += 1u;
        let hit = trace(o, d, 0.0, tmax, false);
        if hit.triangle == MISS {
            return through;
        }
        let m = material(hit.prim);
        var coverage = 1.0;
        if ALPHA {
            coverage = m.coverage;
        }
        var transmitted = vec3<f32>(0.0);
        if REFRACTION {
            transmitted = m.shadow_pass;
        }
        let passes = vec3<f32>(1.0 - coverage) + coverage * transmitted;
        if !(max3(passes) > 0.0) || layers >= MAX_SHADOW_LAYERS {
            return vec3<f32>(0.0);
        }
        o = spawn_origin(spawn_point(hit.prim, hit), d);
        tmax = tmax - hit.t;
        through *= passes;
    }
    return vec3<f32>(0.0);
}

// The interpolated shading normal on the side of `ng`, or `ng`.
fn shading_normal(hit: HitOut, ng: vec3<f32>) -> vec3<f32> {
    if rp.has_normals == 0u {
        return ng;
    }
    let at = rp.o_normals + 9u * hit.prim;
    let n = normalize_or_zero(sv3(at) * (1.0 - hit.u - hit.v) + sv3(at + 3u) * hit.u + sv3(at + 6u) * hit.v);
    if !(is_finite(n.x) && is_finite(n.y) && is_finite(n.z)) || all(n == vec3<f32>(0.0)) {
        return ng;
    }
    return select(n, -n, dot(n, ng) < 0.0);
}

// What a surface point receives from one light direction (lighting's `light` closure):
// `to` towards the light, `tmax` the shadow ray's end, `incident` the radiance.
struct Surface {
    sp: SpawnPoint,
    m: Material,
    transmits: bool,
    n: vec3<f32>,
    ng: vec3<f32>,
    v: vec3<f32>,
    weight: vec3<f32>,
}

fn light(s: Surface, to: vec3<f32>, tmax: f32, incident: vec3<f32>, kind: u32) -> vec3<f32> {
    let l = normalize_or_zero(to);
    let cos = dot(s.n, l);
    if cos <= 0.0 || dot(s.ng, l) <= 0.0 {
        return vec3<f32>(0.0);
    }
    let value = s.weight * reflectance(s.m, s.transmits, s.n, s.v, l) * incident * cos;
    // Below f32's normal range is nothing (GPUs flush it to zero; so does the CPU here).
    if !(max3(value) >= F32_MIN_POSITIVE) {
        return vec3<f32>(0.0);
    }
    if SHADOWS {
        return value * shadow(spawn_origin(s.sp, to), to, tmax, kind);
    }
    return value;
}

// lighting::punctual for light `i`, seen from `p`.
fn punctual(s: Surface, i: u32, p: vec3<f32>) -> vec3<f32> {
    let at = rp.o_lights + 16u * i;
    let kind = shade[at];
    let colour = sv3(at + 4u);
    let direction = sv3(at + 12u);
    if kind == 2u {
        return light(s, -direction, inf(), colour, SHADOW);
    }
    let to_light = sv3(at + 8u) - p;
    let d2 = dot(to_light, to_light);
    if d2 == 0.0 || !is_finite(d2) {
        return vec3<f32>(0.0);
    }
    let d = sqrt(d2);
    let range = sf(at + 1u);
    var window = 1.0;
    if is_finite(range) {
        let x = d / range;
        let w = clamp(1.0 - x * x * x * x, 0.0, 1.0);
        window = w * w;
    }
    var falloff = window / d2;
    if kind == 1u {
        let cos = dot(direction, -to_light / d);
        let cos_outer = sf(at + 2u);
        let cos_inner = sf(at + 3u);
        let x = clamp((cos - cos_outer) / max(cos_inner - cos_outer, 1e-4), 0.0, 1.0);
        falloff *= x * x;
    }
    if !(falloff > 0.0) {
        return vec3<f32>(0.0);
    }
    return light(s, to_light, 1.0, colour * falloff, SHADOW);
}

// Emitters::pick: the emitter whose running area passes u * total.
fn pick_emitter(u: f32) -> u32 {
    let target_area = u * rp.emitter_area;
    var lo = 0u;
    var hi = rp.emitter_count;
    while lo < hi {
        let mid = (lo + hi) / 2u;
        if sf(rp.o_emitters + 4u * mid + 3u) <= target_area {
            lo = mid + 1u;
        } else {
            hi = mid;
        }
    }
    return min(lo, rp.emitter_count - 1u);
}

// Context::sample_area_lights.
fn area_lights(s: Surface, pixel: u32, depth: u32, p: vec3<f32>) -> vec3<f32> {
    var samples = 1u;
    if SOFT_SHADOWS {
        samples = max(rp.soft_samples, 1u);
    }
    let scale = rp.emitter_area / f32(samples);
    var sum = vec3<f32>(0.0);
    for (var k = 0u; k < samples; k++) {
        let e = pick_emitter(uniform2(pixel, depth, 2u * k).x);
        let emitted = sv3(rp.o_emitters + 4u * e);
        let prim = shade[rp.o_emitters + 4u * rp.emitter_count + e];
        let a = vertex(prim, 0u);
        let b = vertex(prim, 1u);
        let c = vertex(prim, 2u);
        var y: vec3<f32>;
        if SOFT_SHADOWS {
            let uv = uniform2(pixel, depth, 2u * k + 1u);
            let r = sqrt(uv.x);
            y = a * (1.0 - r) + b * (r * (1.0 - uv.y)) + c * (r * uv.y);
        } else {
            y = (a + b + c) / 3.0;
        }
        let to = y - p;
        let d2 = dot(to, to);
        let cos_y = abs(dot(face_normal(a, b, c), to)) / sqrt(d2);
        if d2 > 0.0 && cos_y > 0.0 {
            let kind = select(SHADOW, SOFT_SHADOW, SOFT_SHADOWS);
            sum += light(s, to, AREA_SHADOW_END, emitted * (cos_y * scale / d2), kind);
        }
    }
    return sum;
}

// A ray pushed for later, when it carries enough to see.
fn push(sp: ptr<function, u32>, o: vec3<f32>, d: vec3<f32>, weight: vec3<f32>, depth: u32, kind: u32) {
    if max3(weight) >= VISIBLE_WEIGHT && *sp < STACK_SIZE {
        stack[*sp] = Task(o, depth, d, kind, weight);
        *sp += 1u;
    }
}

// Context::shade: the light of `task`'s hit that needs no further ray (shadow rays are
// traced here), the other rays pushed.
fn shade_hit(task: Task, hit: HitOut, pixel: u32, sp: ptr<function, u32>) -> vec3<f32> {
    var s: Surface;
    s.sp = spawn_point(hit.prim, hit);
    s.m = material(hit.prim);
    let dir = normalize(task.d);
    var ng = s.sp.normal;
    let entering = dot(ng, dir) < 0.0;
    if !entering {
        ng = -ng;
    }
    s.ng = ng;
    s.n = shading_normal(hit, ng);
    let can_continue = task.depth < rp.max_depth;
    var coverage = 1.0;
    if ALPHA {
        coverage = s.m.coverage;
    }
    if coverage < 1.0 && can_continue {
        let w = task.weight * (1.0 - coverage);
        if *sp < STACK_SIZE {
            stack[*sp] = Task(spawn_origin(s.sp, task.d), task.depth + 1u, task.d, ALPHA_RAY, w);
            *sp += 1u;
        }
    }
    if coverage <= 0.0 {
        return vec3<f32>(0.0);
    }
    s.weight = task.weight * coverage;
    s.v = -dir;
    s.transmits = REFRACTION && s.m.transmission > 0.0;
    var radiance = s.weight * s.m.emissive;
    let p = s.sp.point;
    if HEADLIGHT {
        let kd = select(s.m.albedo, s.m.albedo_transmits, s.transmits);
        radiance += s.weight * kd * (HEADLIGHT_AMBIENT + HEADLIGHT_DIRECT * abs(dot(s.n, s.v)));
    } else {
        for (var i = 0u; i < rp.light_count; i++) {
            radiance += punctual(s, i, p);
        }
        if rp.emitter_count > 0u {
            radiance += area_lights(s, pixel, task.depth, p);
        }
    }
    if !can_continue {
        return radiance;
    }
    // Context::secondary.
    let n = s.n;
    var reflected = vec3<f32>(0.0);
    if REFRACTION && s.m.transmission > 0.0 {
        let t = s.m.transmission;
        let eta = select(s.m.ior, 1.0 / s.m.ior, entering);
        let cos_i = -dot(dir, n);
        let k = 1.0 - eta * eta * (1.0 - cos_i * cos_i);
        if k < 0.0 {
            reflected += s.weight * t;
        } else {
            let cos_t = sqrt(k);
            let rs = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
            let rpar = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
            let fresnel = clamp(0.5 * (rs * rs + rpar * rpar), 0.0, 1.0);
            let refracted = eta * dir + (eta * cos_i - cos_t) * n;
            if dot(refracted, ng) < 0.0 {
                let w = s.weight * t * (1.0 - fresnel) * s.m.base;
                push(sp, spawn_origin(s.sp, refracted), refracted, w, task.depth + 1u, REFRACTION_RAY);
            }
            reflected += s.weight * t * fresnel;
        }
    }
    if REFLECTION {
        // A direction on the wrong side of the surface is mirrored about ng instead.
        var r = dir - 2.0 * dot(dir, n) * n;
        if !(dot(r, ng) > 0.0) {
            r = dir - 2.0 * dot(dir, ng) * ng;
        }
        let w = reflected + s.weight * s.m.mirror;
        push(sp, spawn_origin(s.sp, r), r, w, task.depth + 1u, REFLECTION_RAY);
    }
    return radiance;
}

fn render_pixel(pixel: u32) -> vec3<f32> {
    let x = pixel % rp.width;
    let y = pixel / rp.width;
    let tan_half = rp.eye.w;
    let px = (2.0 * (f32(x) + 0.5) / f32(rp.width) - 1.0) * tan_half * rp.right.w;
    let py = (1.0 - 2.0 * (f32(y) + 0.5) / f32(rp.height)) * tan_half;
    let d = normalize(px * rp.right.xyz + py * rp.up.xyz - rp.back.xyz);
    var sp = 1u;
    stack[0] = Task(rp.eye.xyz, 0u, d, PRIMARY, vec3<f32>(1.0));
    var radiance = vec3<f32>(0.0);
    // Every push is one level deeper and depths are bounded: the loop ends.
    while sp > 0u {
        sp -= 1u;
        let task = stack[sp];
        counts[task.kind] += 1u;
        let hit = trace(task.o, task.d, 0.0, inf(), false);
        if hit.triangle == MISS {
            radiance += task.weight * BACKGROUND;
        } else {
            radiance += shade_hit(task, hit, pixel, &sp);
        }
    }
    return radiance;
}

@compute @workgroup_size(64)
fn render(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = gid.x;
    if i < rp.pixel_count {
        radiance_out[i] = vec4<f32>(render_pixel(rp.first_pixel + i), 1.0);
    }
    for (var k = 0u; k < 6u; k++) {
        if counts[k] != 0u {
            atomicAdd(&group_counts[k], counts[k]);
        }
    }
    workgroupBarrier();
    if lid == 0u {
        for (var k = 0u; k < 6u; k++) {
            let add = atomicLoad(&group_counts[k]);
            let old = atomicAdd(&ray_counts[2u * k], add);
            if old + add < old {
                atomicAdd(&ray_counts[2u * k + 1u], 1u);
            }
        }
    }
}
