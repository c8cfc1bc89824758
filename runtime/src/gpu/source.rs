//! The tracing kernel's WGSL: trace.wgsl with the scene's bindings, the `word` accessor
//! over them, and the helpers generated for the adapter's precision (exact `f64` paths
//! where it has 64-bit floats).

use super::device::Budget;

/// The kernel's source: trace.wgsl with the scene's bindings, the `word` accessor over
/// them, and the precision-dependent helpers.
///
/// `subnormals`: whether the kernels keep `f32` subnormals (else the exact test's
/// error bounds allow for flushed ones).
pub(super) fn shader_source(
    chunks: usize,
    chunk_words: u64,
    f64_edges: bool,
    subnormals: bool,
    budget: Budget,
) -> String {
    let mut g =
        format!("const WORKGROUP_SIZE: u32 = {}u;\nconst LOOP_BUDGET: u32 = {}u;\n", budget.workgroup, budget.loops);
    for k in 0..chunks {
        g += &format!("@group(0) @binding({}) var<storage, read> scene_{k}: array<u32>;\n", 3 + k);
    }
    if chunks == 1 {
        g += "fn word(i: u32) -> u32 {\n    return scene_0[i];\n}\n";
    } else {
        let shift = chunk_words.ilog2();
        g +=
            &format!("fn word(i: u32) -> u32 {{\n    let j = i & {}u;\n    switch i >> {shift}u {{\n", chunk_words - 1);
        for k in 0..chunks {
            g += &format!("        case {k}u: {{ return scene_{k}[j]; }}\n");
        }
        g += "        default: { return 0u; }\n    }\n}\n";
    }
    if f64_edges {
        // Products of f32s are exact in f64, and so is the sign of their difference:
        // the edge function of a shared edge is the exact negation in both triangles,
        // whatever the compiler fuses.
        g += "fn edge(px: f32, py: f32, qx: f32, qy: f32) -> f32 {\n    \
              return f32(f64(px) * f64(qy) - f64(py) * f64(qx));\n}\n";
        // The product of two f32s is exact in f64: rounded to f32 it is the f32
        // product, bit for bit, and no longer a multiply a compiler may fuse.
        g += "fn product(a: f32, b: f32) -> f32 {\n    return f32(f64(a) * f64(b));\n}\n";
        // The products round as the CPU's (trace.wgsl, `fan_pick`).
        g += "const PRODUCTS_EXACT: bool = true;\n";
        // SceneView::uv_at: exact products, one f64 sum, rounded once.
        g += "fn uv_mix(a: f32, b: f32, c: f32, w: f32, u: f32, v: f32) -> f32 {\n    \
              return f32(f64(a) * f64(w) + f64(b) * f64(u) + f64(c) * f64(v));\n}\n";
        g += "fn grid_coord(p: f32, lo: f32) -> u32 {\n    \
              let last = f64((1u << params.max_depth) - 1u);\n    \
              let x = (f64(p) - f64(lo)) * f64(params.root_hi.w);\n    \
              return u32(f32(clamp(x, 0.0lf, last)));\n}\n";
        g += &triangle_source("f64");
        g += &plane_distance_source("f64");
        g += &front_source("f64");
        // tables::exact_exit and exact_side: exact products, the difference's sign exact.
        g += "fn exits_before(oi: f32, di: f32, oj: f32, dj: f32) -> bool {\n    \
              let p = f64(oi) * f64(dj) - f64(oj) * f64(di);\n    \
              return select(p > 0.0lf, p < 0.0lf, is_negative(di) == is_negative(dj));\n}\n";
        g += "fn exact_distance(off: f32, d: f32) -> f32 {\n    return f32(f64(off) / f64(d));\n}\n";
        // The f32 quotient and square root correctly rounded, as the CPU's: in f64
        // (rounding twice is exact for these: 53 >= 2 x 24 + 2 bits), where a driver's
        // f32 division may be 2.5 ulps off (NVIDIA's is) and its square root worse.
        g += "fn div(a: f32, b: f32) -> f32 {\n    return f32(f64(a) / f64(b));\n}\n";
        g += "fn root(x: f32) -> f32 {\n    return f32(sqrt(f64(x)));\n}\n";
        g += FAR_F64;
        g += HIT_F64;
        g += "fn exact_side(off_a: f32, d_a: f32, m: f32, dk: f32, negative_a: bool) -> u32 {\n    \
              let p = f64(off_a) * f64(dk) - f64(m) * f64(d_a);\n    \
              return select(0u, 1u, (p > 0.0lf) != negative_a);\n}\n";
        // The exact test's filter (trace.wgsl, EXACT): the f32 bound's floor for
        // underflow, 2^-147 where subnormals are kept, 2^-120 where they may be flushed.
        g += &format!(
            "const EXACT_FLOOR: f64 = {};\n",
            if subnormals { "5.605193857299268e-45lf" } else { "7.52316384526264e-37lf" }
        );
        g += FILTER_F64;
    } else {
        // Without f64 the exact test is refused (`GpuTracer::with_options`); were it
        // run, every triangle would be in doubt and every ray handed back.
        g += "fn f64_above(x: f32, bound: f32) -> bool {\n    return false;\n}\n";
        g += "fn edge_bound(r: vec3<f32>, sa: f32, sb: f32, sc: f32) -> f32 {\n    return 0.0;\n}\n";
        g += "fn rounded_distance(o: vec3<f32>, d: vec3<f32>, at: u32) -> vec2<f32> {\n    return vec2<f32>(0.0);\n}\n";
        g += "fn edge(px: f32, py: f32, qx: f32, qy: f32) -> f32 {\n    return px * qy - py * qx;\n}\n";
        g += "fn product(a: f32, b: f32) -> f32 {\n    return a * b;\n}\n";
        g += "const PRODUCTS_EXACT: bool = false;\n";
        g += "fn uv_mix(a: f32, b: f32, c: f32, w: f32, u: f32, v: f32) -> f32 {\n    \
              return a * w + b * u + c * v;\n}\n";
        g += "fn grid_coord(p: f32, lo: f32) -> u32 {\n    \
              let last = f32((1u << params.max_depth) - 1u);\n    \
              return u32(clamp((p - lo) * params.root_hi.w, 0.0, last));\n}\n";
        g += &triangle_source("f32");
        g += &plane_distance_source("f32");
        g += &front_source("f32");
        // Without f64 the exact rule compares rounded f32 distances (no underflowing
        // products, but the adapter's division).
        g += "fn exits_before(oi: f32, di: f32, oj: f32, dj: f32) -> bool {\n    return oi / di < oj / dj;\n}\n";
        g += "fn exact_distance(off: f32, d: f32) -> f32 {\n    return off / d;\n}\n";
        // Without f64, the adapter's quotient and square root.
        g += "fn div(a: f32, b: f32) -> f32 {\n    return a / b;\n}\n";
        g += "fn root(x: f32) -> f32 {\n    return sqrt(x);\n}\n";
        g += FAR_F32;
        // Without f64 the exact rule's rays take the f32 test.
        g += "fn hit_triangle_exact(wk: ptr<function, Walk>, at: u32, tmin: f32, tmax: f32, owned: bool) -> vec4<f32> {\n    \
              return hit_triangle(wk, at, tmin, tmax, owned);\n}\n";
        g += "fn exact_side(off_a: f32, d_a: f32, m: f32, dk: f32, negative_a: bool) -> u32 {\n    \
              let x = (off_a / d_a) * dk - m;\n    \
              let p_positive = select(x > 0.0, x < 0.0, is_negative(d_a));\n    \
              return select(0u, 1u, p_positive != negative_a);\n}\n";
    }
    include_str!("trace.wgsl").replace("//GENERATED//\n", &g)
}

/// Moving a far origin to the root (`cpu::walk`'s `begin_far`), in `f64`: the entry
/// into the root cube, `max(tmin)`, split into two `f32` whose sum is exact; the moved
/// origin; distances shifted back and `tmin` forward, each rounded once (`tmax`
/// forward by `moved_tmax`, trace.wgsl).
/// `far_shift` answers `(hi, lo, 1)`, or `z = 0` for a ray that misses the root.
const FAR_F64: &str = "fn far_shift(o: vec3<f32>, d: vec3<f32>, tmin: f32) -> vec3<f32> {
    var t_enter = -1.0e300lf;
    var t_leave = 1.0e300lf;
    for (var k = 0u; k < 3u; k++) {
        let lo = f64(component(params.root_lo.xyz, k));
        let hi = f64(component(params.root_hi.xyz, k));
        let ok = f64(component(o, k));
        let dk = f64(component(d, k));
        if dk == 0.0lf {
            if ok < lo || ok > hi {
                return vec3<f32>(0.0);
            }
            continue;
        }
        let ta = (lo - ok) / dk;
        let tb = (hi - ok) / dk;
        t_enter = max(t_enter, min(ta, tb));
        t_leave = min(t_leave, max(ta, tb));
    }
    let entry = max(t_enter, f64(tmin));
    if entry > t_leave || !(entry < 3.4028234663852886e38lf) {
        return vec3<f32>(0.0);
    }
    let hi = f32(entry);
    return vec3<f32>(hi, f32(entry - f64(hi)), 1.0);
}
fn moved_origin(o: vec3<f32>, d: vec3<f32>, s: vec2<f32>) -> vec3<f32> {
    let shift = f64(s.x) + f64(s.y);
    return vec3<f32>(f32(f64(o.x) + shift * f64(d.x)), f32(f64(o.y) + shift * f64(d.y)), f32(f64(o.z) + shift * f64(d.z)));
}
fn shifted(t: f32, s: vec2<f32>) -> f32 {
    return f32(f64(s.x) + f64(s.y) + f64(t));
}
fn unshifted(t: f32, s: vec2<f32>) -> f32 {
    return f32(f64(t) - (f64(s.x) + f64(s.y)));
}
";

/// `cpu::watertight::Shear::intersect_f64`: the watertight test in `f64` throughout,
/// for the rays under the exact exit rule (the same operations in the same order).
const HIT_F64: &str = "fn c64(v: vec3<f64>, i: u32) -> f64 {
    return select(select(v.z, v.y, i == 1u), v.x, i == 0u);
}
fn owns64(positive: bool, fx: f64, fy: f64, tx: f64, ty: f64) -> bool {
    let up = select((ty < fy), (ty > fy), positive);
    let right = select((tx < fx), (tx > fx), positive);
    return up || (ty == fy && right);
}
fn hit_triangle_exact(wk: ptr<function, Walk>, at: u32, tmin: f32, tmax: f32, owned: bool) -> vec4<f32> {
    let k = (*wk).k;
    let d = vec3<f64>(f64((*wk).d.x), f64((*wk).d.y), f64((*wk).d.z));
    let sx = c64(d, k.x) / c64(d, k.z);
    let sy = c64(d, k.y) / c64(d, k.z);
    let o = vec3<f64>(f64((*wk).o.x), f64((*wk).o.y), f64((*wk).o.z));
    let a = corner(at) - o;
    let b = corner(at + 3u) - o;
    let c = corner(at + 6u) - o;
    let ax = c64(a, k.x) - sx * c64(a, k.z);
    let ay = c64(a, k.y) - sy * c64(a, k.z);
    let bx = c64(b, k.x) - sx * c64(b, k.z);
    let by = c64(b, k.y) - sy * c64(b, k.z);
    let cx = c64(c, k.x) - sx * c64(c, k.z);
    let cy = c64(c, k.y) - sy * c64(c, k.z);
    let u = cx * by - cy * bx;
    let v = ax * cy - ay * cx;
    let w = bx * ay - by * ax;
    if (u < 0.0lf || v < 0.0lf || w < 0.0lf) && (u > 0.0lf || v > 0.0lf || w > 0.0lf) {
        return vec4<f32>(0.0);
    }
    let det = u + v + w;
    if det == 0.0lf {
        return vec4<f32>(0.0);
    }
    if owned && (u == 0.0lf || v == 0.0lf || w == 0.0lf) {
        let p = det > 0.0lf;
        if (u == 0.0lf && !owns64(p, bx, by, cx, cy)) || (v == 0.0lf && !owns64(p, cx, cy, ax, ay))
            || (w == 0.0lf && !owns64(p, ax, ay, bx, by)) {
            return vec4<f32>(0.0);
        }
    }
    let plane = plane_distance((*wk).o, (*wk).d, at);
    let dist = plane.x;
    if plane.y != 0.0 && dist >= tmin && dist <= tmax {
        return vec4<f32>(dist, f32(v / det), f32(w / det), 1.0);
    }
    return vec4<f32>(0.0);
}
";

/// The exact test's filter in `f64` (trace.wgsl, EXACT; `cpu::watertight`'s
/// `edge_error_bound` and `plane_distance_rounded`, with wider margins: a sign or a
/// distance they certify is exact arithmetic's, whatever the adapter's last bits).
///
/// `edge_bound(r, sa, sb, sc)`: the bound on each `f32` edge function's error, with
/// `r` the largest magnitudes of the vertices relative to the origin and `sa, sb, sc`
/// the sheared vertices' `|x| + |y|`. `rounded_distance`: the distance correctly
/// rounded to `f32`, `(t, 1)`, where the `f64` quotient's bound leaves one `f32`,
/// else `(0, 0)` (in doubt: the ray is handed back).
const FILTER_F64: &str = "fn f64_above(x: f32, bound: f64) -> bool {
    return f64(x) > bound;
}
fn edge_bound(r: vec3<f32>, sa: f32, sb: f32, sc: f32) -> f64 {
    let m = f64(max(max(r.x, r.y), r.z));
    let e = m * 4.76837158203125e-7lf + EXACT_FLOOR;
    let t = f64(max(max(sa, sb), sc)) * 1.0001lf + e;
    return t * (2.0lf * e + t * 2.384185791015625e-7lf) * 1.0001lf + EXACT_FLOOR;
}
fn rounded_distance(o: vec3<f32>, d: vec3<f32>, at: u32) -> vec2<f32> {
    let a = corner(at);
    let e1 = corner(at + 3u) - a;
    let e2 = corner(at + 6u) - a;
    let t0 = vec3<f64>(e1.y * e2.z, e1.z * e2.x, e1.x * e2.y);
    let t1 = vec3<f64>(e1.z * e2.y, e1.x * e2.z, e1.y * e2.x);
    let n = t0 - t1;
    let big = abs(t0) + abs(t1);
    let ao = a - vec3<f64>(f64(o.x), f64(o.y), f64(o.z));
    let dd = vec3<f64>(f64(d.x), f64(d.y), f64(d.z));
    let num = ao.x * n.x + ao.y * n.y + ao.z * n.z;
    let den = dd.x * n.x + dd.y * n.y + dd.z * n.z;
    let g = 7.105427357601002e-15lf;
    let err_num = g * (abs(ao.x) * big.x + abs(ao.y) * big.y + abs(ao.z) * big.z);
    let err_den = g * (abs(dd.x) * big.x + abs(dd.y) * big.y + abs(dd.z) * big.z);
    if !(err_den < 0.25lf * abs(den)) {
        return vec2<f32>(0.0);
    }
    let q = num / den;
    let err = (err_num + 2.0lf * abs(q) * err_den) / abs(den) * 1.001lf + abs(q) * 3.552713678800501e-15lf;
    if !(abs(q) + err < 3.0e38lf) {
        return vec2<f32>(0.0);
    }
    let lo = f32(q - err);
    if lo != f32(q + err) || lo == 0.0 {
        return vec2<f32>(0.0);
    }
    return vec2<f32>(lo, 1.0);
}
";

/// [`FAR_F64`] without `f64`: the entry from the kernel's `f32` clip, pulled back by
/// eight ulps so that the moved origin stays before the root, and the origin moved by a
/// fused multiply-add (on the ray's line within a rounding of the moved point).
const FAR_F32: &str = "fn far_shift(o: vec3<f32>, d: vec3<f32>, tmin: f32) -> vec3<f32> {
    let root = clip(o, d, params.root_lo.xyz, params.root_hi.xyz);
    let entry = max(root.x, tmin);
    if root.w == 0.0 || entry > root.y || !is_finite(entry) {
        return vec3<f32>(0.0);
    }
    return vec3<f32>(entry * (1.0 - 9.5367431640625e-7), 0.0, 1.0);
}
fn moved_origin(o: vec3<f32>, d: vec3<f32>, s: vec2<f32>) -> vec3<f32> {
    return fma(vec3<f32>(s.x), d, o);
}
fn shifted(t: f32, s: vec2<f32>) -> f32 {
    return s.x + t;
}
fn unshifted(t: f32, s: vec2<f32>) -> f32 {
    return t - s.x;
}
";

/// The stored triangle's corners and plane normal in `float` (`f64` where the adapter
/// has it), shared by the generated functions below: `corner(at)`, the three floats
/// from word `at`; `plane_normal(at)`, `(v1 - v0) x (v2 - v0)` of the triangle at word
/// `at`, the same operations in the same order as the CPU's.
fn triangle_source(float: &str) -> String {
    format!(
        "fn corner(at: u32) -> vec3<{float}> {{
    return vec3<{float}>({float}(wordf(at)), {float}(wordf(at + 1u)), {float}(wordf(at + 2u)));
}}
fn plane_normal(at: u32) -> vec3<{float}> {{
    let a = corner(at);
    let e1 = corner(at + 3u) - a;
    let e2 = corner(at + 6u) - a;
    return vec3<{float}>(e1.y * e2.z - e1.z * e2.y, e1.z * e2.x - e1.x * e2.z, e1.x * e2.y - e1.y * e2.x);
}}
"
    )
}

/// `plane_distance(o, d, at)`: where the ray meets the plane of the triangle at word
/// `at`, as `cpu::watertight::plane_distance` computes it (the same operations in the
/// same order), in `float` (`f64` where the adapter has it; else `f32`, whose error
/// grows on long thin triangles): `(t, 1)`, or `(0, 0)` for a ray parallel to the
/// plane or a distance beyond `f32`'s range.
fn plane_distance_source(float: &str) -> String {
    format!(
        "fn plane_distance(o: vec3<f32>, d: vec3<f32>, at: u32) -> vec2<f32> {{
    let n = plane_normal(at);
    let ao = corner(at) - vec3<{float}>({float}(o.x), {float}(o.y), {float}(o.z));
    let num = ao.x * n.x + ao.y * n.y + ao.z * n.z;
    let den = {float}(d.x) * n.x + {float}(d.y) * n.y + {float}(d.z) * n.z;
    if den == {float}(0.0) {{
        return vec2<f32>(0.0);
    }}
    let t = f32(num / den);
    if !is_finite(t) {{
        return vec2<f32>(0.0);
    }}
    return vec2<f32>(t, 1.0);
}}
"
    )
}

/// `arrives_on_front(d, at)`: whether a ray of direction `d` arrives on the front of
/// the triangle at word `at` (`cpu::crossings::arrives_on_front`: `d . n < 0`, the same
/// operations in the same order), in `float`.
fn front_source(float: &str) -> String {
    format!(
        "fn arrives_on_front(d: vec3<f32>, at: u32) -> bool {{
    let n = plane_normal(at);
    return {float}(d.x) * n.x + {float}(d.y) * n.y + {float}(d.z) * n.z < {float}(0.0);
}}
"
    )
}
