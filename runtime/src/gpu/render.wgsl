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
// A uniform environment of radiance rp.environment (effects.rs, `Environment`).
override ENVIRONMENT: bool = false;
// Some material is single-sided: camera and shadow rays pass the backs of its
// surfaces (effects.rs, `culls`).
override CULLING: bool = false;

struct RenderParams {
    // xyz: the eye (unused: the primary rays come in `pixel_io`).
    eye: vec4<f32>,
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
    // The emitters' total power (Emitters::total).
    emitter_power: f32,
    // Texture coordinates (absent when has_uvs is 0), texture records (8 words each:
    // width, height, first texel, wrap u, wrap v, filter) and texels.
    o_uvs: u32,
    has_uvs: u32,
    o_textures: u32,
    o_texels: u32,
    // Vertex colours (absent when has_colors is 0): six words a triangle.
    o_colors: u32,
    has_colors: u32,
    // octrace_format::linear16: the 16-bit linear value of each 8-bit sRGB value.
    o_srgb: u32,
    // Tangents (absent when has_tangents is 0): six words a triangle, two a corner
    // (octrace_format::layout::decode_tangent).
    o_tangents: u32,
    has_tangents: u32,
    // Words a texture-coordinate channel takes (six a triangle), channel after channel.
    uv_channel_words: u32,
    // The environment's sky (effects.rs, `Sky`), read when ENVIRONMENT: its radiance
    // at the horizon and its gradient.
    environment: f32,
    environment_gradient: f32,
    // lighting::grid_side(soft_samples).
    soft_grid: u32,
    pad1: u32,
    pad2: u32,
}

@group(1) @binding(0) var<uniform> rp: RenderParams;
// Materials (52 words each, see `material_record` in render.rs), lights (16 words),
// emitters (4 words: radiance rgb, running power), emitter triangles (1 word), material
// ids and normals (the file's sections, as they are).
@group(1) @binding(1) var<storage, read> shade: array<u32>;
// Eight words a pixel. In: the direction of its primary ray (words 0-2, f32 bits) and
// its origin (words 3-5), the CPU camera's (raysets::Camera::ray), so the GPU traces
// exactly the CPU's rays. Out:
// its light sum (`light_sum`, words 0-5) and in word 6 whether it ran out of loop
// budget.
@group(1) @binding(2) var<storage, read_write> pixel_io: array<u32>;
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
    // What a texture changes is derived again per hit from these (`tinted`).
    factor: vec4<f32>,
    texture: u32,
    unlit: bool,
    metallic: f32,
    gloss: f32,
    keep_metal: f32,
    keep_transmission: f32,
    dielectric: f32,
    highlight_a: f32,
    keep_shadow: f32,
    alpha_mode: u32,
    alpha_cutoff: f32,
    // The emissive texture's index plus one, 0 for none.
    emissive_texture: u32,
    // The metallic-roughness texture's index plus one, the roughness factor and the
    // dielectric's F0, from which a hit's metal, gloss and highlight are derived again.
    mr_texture: u32,
    roughness: f32,
    f0: f32,
    // The occlusion texture's index plus one, its strength, and its value at the hit
    // (1 without one): what reaches the ambient term.
    occlusion_texture: u32,
    occlusion_strength: f32,
    occlusion: f32,
    // The normal texture's index plus one, and its scale.
    normal_texture: u32,
    normal_scale: f32,
    // The texture-coordinate channel of each slot (base colour, emissive,
    // metallic-roughness, occlusion, normal), three bits each.
    uv_channels: u32,
}

// A hit prepared for spawning rays (runtime/src/spawn.rs, SpawnPoint).
struct SpawnPoint {
    point: vec3<f32>,
    normal: vec3<f32>,
    offset: f32,
}

var<private> stack: array<Task, STACK_SIZE>;
var<private> counts: array<u32, 6>;
// The pixel's light (effects.rs's `LightSum`): per channel a 64-bit sum of 32.32 fixed
// point terms, low word first. Integer sums do not depend on the order of the terms,
// which this kernel adds ray tree by ray tree and the CPU wave by wave.
var<private> light_sum: array<u32, 6>;
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

// glam's `dot`: the products summed left to right (WGSL's `dot` is the adapter's, which
// may fuse them).
fn dot3(a: vec3<f32>, b: vec3<f32>) -> f32 {
    return a.x * b.x + a.y * b.y + a.z * b.z;
}

// glam's `length`: the square root of `dot3`, correctly rounded (generated `root`).
fn length3(v: vec3<f32>) -> f32 {
    return root(dot3(v, v));
}

// A vector over a scalar, each component's quotient correctly rounded (generated `div`).
fn div3(a: vec3<f32>, b: f32) -> vec3<f32> {
    return vec3<f32>(div(a.x, b), div(a.y, b), div(a.z, b));
}

// glam's `normalize`: `v` times the reciprocal of its length (WGSL's `normalize` is
// the adapter's; lavapipe's differs from this in the last bit of a quarter of vectors).
fn unit(v: vec3<f32>) -> vec3<f32> {
    return v * div(1.0, length3(v));
}

// glam's `normalize_or_zero`.
fn normalize_or_zero(v: vec3<f32>) -> vec3<f32> {
    let r = div(1.0, length3(v));
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

// The word of a material record that holds its emissive texture (`material_record`).
const EMISSIVE_TEXTURE_WORD: u32 = 43u;
// The word of a material record that packs its slots' texture-coordinate channels.
const UV_CHANNELS_WORD: u32 = 51u;
// The word of a material record that is 1 for a single-sided material.
const SINGLE_SIDED_WORD: u32 = 19u;
// Context's MAX_CULLED_LAYERS.
const MAX_CULLED_LAYERS: u32 = 16u;

// The record of `prim`'s material (the plain one for a triangle without).
fn material_at(prim: u32) -> u32 {
    var id = rp.plain_material;
    if rp.has_material_ids != 0u {
        id = min(shade[rp.o_material_ids + prim], rp.plain_material);
    }
    return rp.o_materials + 52u * id;
}

// Context::culled: whether `hit` is on the back of a single-sided surface, seen
// along `d`.
fn culled(hit: HitOut, d: vec3<f32>) -> bool {
    return CULLING && shade[material_at(hit.prim) + SINGLE_SIDED_WORD] != 0u
        && dot3(face_normal(vertex(hit.prim, 0u), vertex(hit.prim, 1u), vertex(hit.prim, 2u)), d) > 0.0;
}

fn material(prim: u32) -> Material {
    let at = material_at(prim);
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
    m.factor = vec4<f32>(sv3(at + 28u), sf(at + 31u));
    m.texture = shade[at + 32u];
    m.unlit = shade[at + 33u] != 0u;
    m.metallic = sf(at + 34u);
    m.gloss = sf(at + 35u);
    m.keep_metal = sf(at + 36u);
    m.keep_transmission = sf(at + 37u);
    m.dielectric = sf(at + 38u);
    m.highlight_a = sf(at + 39u);
    m.keep_shadow = sf(at + 40u);
    m.alpha_mode = shade[at + 41u];
    m.alpha_cutoff = sf(at + 42u);
    m.emissive_texture = shade[at + EMISSIVE_TEXTURE_WORD];
    m.mr_texture = shade[at + 44u];
    m.roughness = sf(at + 45u);
    m.f0 = sf(at + 46u);
    m.occlusion_texture = shade[at + 47u];
    m.occlusion_strength = sf(at + 48u);
    m.occlusion = 1.0;
    m.normal_texture = shade[at + 49u];
    m.normal_scale = sf(at + 50u);
    m.uv_channels = shade[at + UV_CHANNELS_WORD];
    return m;
}

// The texture-coordinate channel of texture slot `slot` (Material::TEXTURE_SLOTS' order).
fn channel_of(m: Material, slot: u32) -> u32 {
    return (m.uv_channels >> (3u * slot)) & 7u;
}

// SceneView::uv_at_in: the texture coordinates at the hit in `channel` (`uv_mix` is
// generated: exact products in f64 where the adapter has it).
fn uv_at(prim: u32, channel: u32, u: f32, v: f32) -> vec2<f32> {
    if rp.has_uvs == 0u {
        return vec2<f32>(0.0);
    }
    let at = rp.o_uvs + channel * rp.uv_channel_words + 6u * prim;
    let w = 1.0 - u - v;
    return vec2<f32>(uv_mix(sf(at), sf(at + 2u), sf(at + 4u), w, u, v), uv_mix(sf(at + 1u), sf(at + 3u), sf(at + 5u), w, u, v));
}

// One corner's vertex colour, its 16-bit channels scaled.
fn corner_color(at: u32) -> vec4<f32> {
    let a = shade[at];
    let b = shade[at + 1u];
    return vec4<f32>(vec4<u32>(a & 0xffffu, a >> 16u, b & 0xffffu, b >> 16u)) * COLOR_SCALE;
}

// SceneView::color_at: the corners mixed as `uv_at` mixes (no loop: loops count
// against a driver's loop cap).
fn color_at(prim: u32, u: f32, v: f32) -> vec4<f32> {
    let at = rp.o_colors + 6u * prim;
    let c = array<vec4<f32>, 3>(corner_color(at), corner_color(at + 2u), corner_color(at + 4u));
    let w = 1.0 - u - v;
    return vec4<f32>(
        uv_mix(c[0].x, c[1].x, c[2].x, w, u, v),
        uv_mix(c[0].y, c[1].y, c[2].y, w, u, v),
        uv_mix(c[0].z, c[1].z, c[2].z, w, u, v),
        uv_mix(c[0].w, c[1].w, c[2].w, w, u, v),
    );
}

// Texture::reduce.
fn reduce(wrap: u32, c: f32) -> f32 {
    if c - c != 0.0 {
        return 0.0; // not finite
    }
    switch wrap {
        case 0u: { return c - floor(c); }
        case 1u: { return c - 2.0 * floor(c * 0.5); }
        default: { return clamp(c, 0.0, 1.0); }
    }
}

// Texture::wrap_index.
fn wrap_index(wrap: u32, i: i32, n: i32) -> i32 {
    switch wrap {
        case 0u: { return ((i % n) + n) % n; }
        case 1u: {
            let k = ((i % (2 * n)) + 2 * n) % (2 * n);
            return select(k, 2 * n - 1 - k, k >= n);
        }
        default: { return clamp(i, 0, n - 1); }
    }
}

// One texel's four channels decoded to 16 bits (Texture::decode): stored 8 bits a
// channel, colour through the sRGB table or times 257, alpha times 257.
fn texel(first: u32, srgb: bool, w: i32, x: i32, y: i32) -> vec4<u32> {
    let word = shade[rp.o_texels + first + u32(y * w + x)];
    let c = vec4<u32>(word & 0xffu, (word >> 8u) & 0xffu, (word >> 16u) & 0xffu, word >> 24u);
    if srgb {
        return vec4<u32>(shade[rp.o_srgb + c.x], shade[rp.o_srgb + c.y], shade[rp.o_srgb + c.z], c.w * 257u);
    }
    return c * 257u;
}

// Texture::sample: integers up to the final scale, so the CPU's values exactly.
fn sample(t: u32, uv: vec2<f32>) -> vec4<f32> {
    let at = rp.o_textures + 8u * t;
    let w = i32(shade[at]);
    let h = i32(shade[at + 1u]);
    let first = shade[at + 2u];
    let wrap_u = shade[at + 3u];
    let wrap_v = shade[at + 4u];
    let srgb = shade[at + 6u] != 0u;
    let cu = reduce(wrap_u, uv.x);
    let cv = reduce(wrap_v, uv.y);
    var sum = vec4<u32>(0u);
    if shade[at + 5u] == 0u {
        let x = wrap_index(wrap_u, i32(floor(cu * f32(w))), w);
        let y = wrap_index(wrap_v, i32(floor(cv * f32(h))), h);
        sum = texel(first, srgb, w, x, y) << vec4<u32>(16u);
    } else {
        let fx = i32(floor(cu * f32(w * 256))) - 128;
        let fy = i32(floor(cv * f32(h * 256))) - 128;
        let x0 = fx >> 8u;
        let y0 = fy >> 8u;
        let ax = u32(fx & 255);
        let ay = u32(fy & 255);
        // Unrolled: loops count against a driver's loop cap (gpu::loop_cap).
        let xa = wrap_index(wrap_u, x0, w);
        let xb = wrap_index(wrap_u, x0 + 1, w);
        let ya = wrap_index(wrap_v, y0, h);
        let yb = wrap_index(wrap_v, y0 + 1, h);
        sum = texel(first, srgb, w, xa, ya) * ((256u - ax) * (256u - ay)) + texel(first, srgb, w, xb, ya) * (ax * (256u - ay))
            + texel(first, srgb, w, xa, yb) * ((256u - ax) * ay) + texel(first, srgb, w, xb, yb) * (ax * ay);
    }
    return vec4<f32>(sum >> vec4<u32>(8u)) * SAMPLE_SCALE;
}

// The coordinates slot `slot` of `m` reads at the hit: `first`, the first channel's,
// or its own channel's.
fn slot_uv(m: Material, slot: u32, first: vec2<f32>, hit: HitOut) -> vec2<f32> {
    let channel = channel_of(m, slot);
    if channel == 0u {
        return first;
    }
    return uv_at(hit.prim, channel, hit.u, hit.v);
}

// Context::surface: the material at a hit, its base colour times its texture and its
// vertex colour there, and what shading derives from the base colour computed again
// from it, in the CPU's operations (lighting.rs; `product` keeps a multiply from being fused).
fn surface(hit: HitOut) -> Material {
    var m = material(hit.prim);
    let textured = (m.texture | m.emissive_texture | m.occlusion_texture | m.mr_texture) != 0u;
    if !textured && rp.has_colors == 0u {
        return m;
    }
    // The hit's texture coordinates, once for every texture of the first channel;
    // the others' where a slot reads another.
    var uv = vec2<f32>(0.0);
    if textured {
        uv = uv_at(hit.prim, 0u, hit.u, hit.v);
    }
    if m.emissive_texture != 0u {
        m.emissive = m.emissive * sample(m.emissive_texture - 1u, slot_uv(m, 1u, uv, hit)).xyz;
    }
    if m.occlusion_texture != 0u {
        let r = sample(m.occlusion_texture - 1u, slot_uv(m, 3u, uv, hit)).x;
        m.occlusion = 1.0 + m.occlusion_strength * (r - 1.0);
    }
    if m.texture == 0u && rp.has_colors == 0u && m.mr_texture == 0u {
        return m;
    }
    if m.mr_texture != 0u {
        // SceneView::metallic_roughness_at, then what lighting.rs and Material derive
        // from them (gloss, metal, the dielectric mirror, the highlight's F0 and
        // exponent), in their operations.
        let mr = sample(m.mr_texture - 1u, slot_uv(m, 2u, uv, hit));
        m.metallic = m.metallic * mr.z;
        let r = clamp(m.roughness * mr.y, 0.0, 1.0);
        let rough = 1.0 - r;
        m.gloss = rough * rough;
        m.keep_metal = 1.0 - m.metallic * m.gloss;
        m.dielectric = (1.0 - m.metallic) * m.keep_transmission * m.f0;
        m.highlight_a = m.f0 * (1.0 - m.metallic);
        let alpha = max(r * r, 1e-2);
        m.exponent = clamp(div(2.0, alpha * alpha) - 2.0, 1.0, 1e4);
    }
    var bc = m.factor;
    if m.texture != 0u {
        bc = bc * sample(m.texture - 1u, slot_uv(m, 0u, uv, hit));
    }
    if rp.has_colors != 0u {
        bc = bc * color_at(hit.prim, hit.u, hit.v);
    }
    let base = clamp(bc.xyz, vec3<f32>(0.0), vec3<f32>(1.0));
    m.base = base;
    m.albedo = base * m.keep_metal;
    m.albedo_transmits = base * m.keep_metal * m.keep_transmission;
    let mp = vec3<f32>(product(m.metallic, base.x), product(m.metallic, base.y), product(m.metallic, base.z));
    let mirror = (vec3<f32>(m.dielectric) + mp) * m.gloss;
    m.mirror = select(vec3<f32>(0.0), mirror, max3(mirror) >= VISIBLE_WEIGHT);
    m.ks = (vec3<f32>(m.highlight_a) + mp) * m.gloss;
    m.shadow_pass = base * m.transmission * m.keep_shadow;
    let alpha = clamp(bc.w, 0.0, 1.0);
    switch m.alpha_mode {
        case 0u: { m.coverage = 1.0; }
        case 1u: { m.coverage = select(0.0, 1.0, alpha >= m.alpha_cutoff); }
        default: { m.coverage = alpha; }
    }
    return m;
}

fn vertex(prim: u32, corner: u32) -> vec3<f32> {
    let at = params.o_tris + 9u * prim + 3u * corner;
    return vec3<f32>(wordf(at), wordf(at + 1u), wordf(at + 2u));
}

// glam's `cross`, in its order (WGSL's `cross` is the adapter's: lavapipe's differs
// from this in the last bit of a third of cases).
fn cross3(a: vec3<f32>, b: vec3<f32>) -> vec3<f32> {
    return vec3<f32>(a.y * b.z - b.y * a.z, a.z * b.x - b.z * a.x, a.x * b.y - b.x * a.y);
}

fn face_normal(a: vec3<f32>, b: vec3<f32>, c: vec3<f32>) -> vec3<f32> {
    return normalize_or_zero(cross3(b - a, c - a));
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
    sp.offset = max(dot3(err, abs(sp.normal)), GAMMA_7 * scale);
    return sp;
}

// The origin of a ray leaving `sp` towards `d`: offset to the side it leaves by, then
// one float further out per axis.
fn spawn_origin(sp: SpawnPoint, d: vec3<f32>) -> vec3<f32> {
    let n = select(sp.normal, -sp.normal, dot3(sp.normal, d) < 0.0);
    let offset = n * sp.offset;
    var o = sp.point + offset;
    if offset.x > 0.0 { o.x = next_up(o.x); } else if offset.x < 0.0 { o.x = next_down(o.x); }
    if offset.y > 0.0 { o.y = next_up(o.y); } else if offset.y < 0.0 { o.y = next_down(o.y); }
    if offset.z > 0.0 { o.z = next_up(o.z); } else if offset.z < 0.0 { o.z = next_down(o.z); }
    return o;
}

// runtime/src/render/lighting.rs, hash32: Wellons' lowbias32.
fn hash32(x0: u32) -> u32 {
    var x = x0;
    x ^= x >> 16u;
    x *= 0x7feb352du;
    x ^= x >> 15u;
    x *= 0x846ca68bu;
    return x ^ (x >> 16u);
}

// lighting::stratified2: point k of n, one in each cell of a side x side grid (or
// each of n slices of the first number when side is 0), jittered by the hash.
fn stratified2(pixel: u32, depth: u32, k: u32, n: u32, side: u32) -> vec2<f32> {
    let a = hash32(k + hash32(depth + hash32(pixel)));
    let b = hash32(a);
    let ja = f32(a >> 8u) * (1.0 / 16777216.0);
    let jb = f32(b >> 8u) * (1.0 / 16777216.0);
    if side > 0u {
        return vec2<f32>(div(f32(k % side) + ja, f32(side)), div(f32(k / side) + jb, f32(side)));
    }
    return vec2<f32>(div(f32(k) + ja, f32(max(n, 1u))), jb);
}

// lighting::power: x^e for the highlight, with lighting.rs's operations in its order
// (not WGSL's `pow`, the adapter's own approximation), so the lobe, and whether a
// shadow ray is traced for it, is the CPU's.
fn power(x: f32, e: f32) -> f32 {
    if !(x >= F32_MIN_POSITIVE) {
        return 0.0;
    }
    let bits = bitcast<u32>(x);
    var k = i32(bits >> 23u) - 127;
    var m = bitcast<f32>((bits & 0x007fffffu) | 0x3f800000u);
    if m > SQRT_2 {
        m *= 0.5;
        k += 1;
    }
    let f = div(m - 1.0, m + 1.0);
    let s = f * f;
    let l = POWER_LN;
    let ln_m = 2.0 * f * (1.0 + s * (l[0] + s * (l[1] + s * (l[2] + s * l[3]))));
    let y = e * (f32(k) + ln_m * LOG2_E);
    let n = floor(y + 0.5);
    if !(n >= -126.0) {
        return 0.0;
    }
    if n > 127.0 {
        return inf();
    }
    let r = (y - n) * LN_2;
    let c = POWER_EXP;
    let two_r = 1.0 + r * (c[0] + r * (c[1] + r * (c[2] + r * (c[3] + r * (c[4] + r * (c[5] + r * c[6]))))));
    return two_r * bitcast<f32>(u32(i32(n) + 127) << 23u);
}

// LightSum::add: `x` rounded down to a multiple of 2^-32 (nothing for x <= 0 or NaN,
// all ones from 2^32 up) and added to channel `c`, saturating.
fn add_channel(c: u32, x: f32) {
    if !(x > 0.0) {
        return;
    }
    var hi = 0xffffffffu;
    var lo = 0xffffffffu;
    if x < 4294967296.0 {
        let whole = floor(x);
        hi = u32(whole);
        lo = u32((x - whole) * 4294967296.0);
    }
    let lo0 = light_sum[2u * c];
    let hi0 = light_sum[2u * c + 1u];
    let lo1 = lo0 + lo;
    let hi1 = hi0 + hi;
    let hi2 = hi1 + select(0u, 1u, lo1 < lo0);
    if hi1 < hi0 || hi2 < hi1 {
        light_sum[2u * c] = 0xffffffffu;
        light_sum[2u * c + 1u] = 0xffffffffu;
    } else {
        light_sum[2u * c] = lo1;
        light_sum[2u * c + 1u] = hi2;
    }
}

// One term of the pixel's light.
fn add_light(v: vec3<f32>) {
    add_channel(0u, v.x);
    add_channel(1u, v.y);
    add_channel(2u, v.z);
}

// lighting::reflectance: Lambert plus a normalised Blinn-Phong highlight.
fn reflectance(m: Material, transmits: bool, n: vec3<f32>, v: vec3<f32>, l: vec3<f32>) -> vec3<f32> {
    let kd = select(m.albedo, m.albedo_transmits, transmits);
    let h = normalize_or_zero(v + l);
    var spec = vec3<f32>(0.0);
    if any(m.ks != vec3<f32>(0.0)) {
        let lobe = power(max(dot3(n, h), 0.0), m.exponent);
        spec = div3(m.ks * (m.exponent + 8.0), 8.0 * PI) * select(0.0, lobe, lobe >= F32_MIN_POSITIVE);
    }
    return div3(kd, PI) + spec;
}

// What of `value0` reaches a shadow ray's end: all of it when nothing blocks it, none
// when something does, and with alpha or refraction what the surfaces it crosses let
// through, dimmed surface by surface as Context::trace_shadows does.
fn shadowed(o0: vec3<f32>, d: vec3<f32>, tmax0: f32, kind: u32, value0: vec3<f32>) -> vec3<f32> {
    if !(ALPHA || REFRACTION || CULLING) {
        counts[kind] += 1u;
        let blocked = trace(o0, d, 0.0, tmax0, true).triangle != MISS;
        return select(value0, vec3<f32>(0.0), blocked);
    }
    var o = o0;
    var tmax = tmax0;
    var value = value0;
    for (var layers = 0u; layers <= MAX_SHADOW_LAYERS && tick(); layers++) {
        counts[kind] += 1u;
        let hit = trace(o, d, 0.0, tmax, false);
        if hit.triangle == MISS {
            return value;
        }
        // A single-sided surface whose back the light sees casts no shadow (seen
        // from the light, the ray runs the other way).
        var passes = vec3<f32>(1.0);
        if !culled(hit, -d) {
            let m = surface(hit);
            var coverage = 1.0;
            if ALPHA {
                coverage = m.coverage;
            }
            var transmitted = vec3<f32>(0.0);
            if REFRACTION {
                transmitted = m.shadow_pass;
            }
            passes = vec3<f32>(1.0 - coverage) + coverage * transmitted;
        }
        if !(max3(passes) > 0.0) || layers >= MAX_SHADOW_LAYERS {
            return vec3<f32>(0.0);
        }
        o = spawn_origin(spawn_point(hit.prim, hit), d);
        tmax = tmax - hit.t;
        value = value * passes;
    }
    return vec3<f32>(0.0);
}

// The interpolated shading normal on the side of `ng`, or `ng`.
// Context::shading_normal: the interpolated normal, then the material's normal map.
fn shading_normal(hit: HitOut, ng: vec3<f32>, m: Material) -> vec3<f32> {
    let n = interpolated_normal(hit, ng);
    if m.normal_texture == 0u || rp.has_uvs == 0u {
        return n;
    }
    return mapped_normal(hit, n, ng, m.normal_texture - 1u, m.normal_scale, channel_of(m, 4u));
}

// Context::mapped_normal, in its operations.
// A corner's stored tangent (two words, octrace_format::layout::decode_tangent): x y z
// as i16 times 1 / 32767, and w's sign.
fn tangent_at(at: u32) -> vec4<f32> {
    let a = shade[at];
    let b = shade[at + 1u];
    let s = bitcast<f32>(0x38000100u);
    let x = f32(bitcast<i32>(a << 16u) >> 16u) * s;
    let y = f32(bitcast<i32>(a) >> 16u) * s;
    let z = f32(bitcast<i32>(b << 16u) >> 16u) * s;
    return vec4<f32>(x, y, z, sign(f32(bitcast<i32>(b) >> 16u)));
}

fn mapped_normal(hit: HitOut, n: vec3<f32>, ng: vec3<f32>, texture: u32, scale: f32, channel: u32) -> vec3<f32> {
    let p0 = vertex(hit.prim, 0u);
    let e1 = vertex(hit.prim, 1u) - p0;
    let e2 = vertex(hit.prim, 2u) - p0;
    let back = dot3(n, cross3(e1, e2)) < 0.0;
    let front = select(n, -n, back);
    var t0: vec3<f32>;
    var sign = 1.0;
    // The corners' tangents where the scene has them and they are not all zero here.
    let tt = rp.o_tangents + 6u * hit.prim;
    var c0 = vec4<f32>(0.0);
    var c1 = vec4<f32>(0.0);
    var c2 = vec4<f32>(0.0);
    if rp.has_tangents != 0u {
        c0 = tangent_at(tt);
        c1 = tangent_at(tt + 2u);
        c2 = tangent_at(tt + 4u);
    }
    if c0.w != 0.0 || c1.w != 0.0 || c2.w != 0.0 {
        t0 = c0.xyz * (1.0 - hit.u - hit.v) + c1.xyz * hit.u + c2.xyz * hit.v;
        let w = c0.w * (1.0 - hit.u - hit.v) + c1.w * hit.u + c2.w * hit.v;
        sign = select(1.0, -1.0, w < 0.0);
    } else {
        let at = rp.o_uvs + channel * rp.uv_channel_words + 6u * hit.prim;
        let du1 = sf(at + 2u) - sf(at);
        let dv1 = sf(at + 3u) - sf(at + 1u);
        let du2 = sf(at + 4u) - sf(at);
        let dv2 = sf(at + 5u) - sf(at + 1u);
        let det = du1 * dv2 - du2 * dv1;
        if det == 0.0 || !is_finite(det) {
            return n;
        }
        t0 = (e1 * dv2 - e2 * dv1) * select(-1.0, 1.0, det > 0.0);
    }
    let t = normalize_or_zero(t0 - front * dot3(front, t0));
    if all(t == vec3<f32>(0.0)) || !(is_finite(t.x) && is_finite(t.y) && is_finite(t.z)) {
        return n;
    }
    let b = cross3(front, t) * sign;
    let texel = sample(texture, uv_at(hit.prim, channel, hit.u, hit.v));
    let x = (texel.x * 2.0 - 1.0) * scale;
    let y = (texel.y * 2.0 - 1.0) * scale;
    let z = texel.z * 2.0 - 1.0;
    var mapped = normalize_or_zero(t * x + b * y + front * z);
    mapped = select(mapped, -mapped, back);
    if all(mapped == vec3<f32>(0.0)) || !(is_finite(mapped.x) && is_finite(mapped.y) && is_finite(mapped.z)) || dot3(mapped, ng) <= 0.0 {
        return n;
    }
    return mapped;
}

fn interpolated_normal(hit: HitOut, ng: vec3<f32>) -> vec3<f32> {
    if rp.has_normals == 0u {
        return ng;
    }
    let at = rp.o_normals + 9u * hit.prim;
    let n = normalize_or_zero(sv3(at) * (1.0 - hit.u - hit.v) + sv3(at + 3u) * hit.u + sv3(at + 6u) * hit.v);
    if !(is_finite(n.x) && is_finite(n.y) && is_finite(n.z)) || all(n == vec3<f32>(0.0)) {
        return ng;
    }
    return select(n, -n, dot3(n, ng) < 0.0);
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

fn light(s: Surface, to: vec3<f32>, tmax: f32, incident: vec3<f32>, kind: u32) {
    let l = normalize_or_zero(to);
    let cos = dot3(s.n, l);
    if cos <= 0.0 || dot3(s.ng, l) <= 0.0 {
        return;
    }
    let value = s.weight * reflectance(s.m, s.transmits, s.n, s.v, l) * incident * cos;
    // Below f32's normal range is nothing (GPUs flush it to zero; so does the CPU here).
    if !(max3(value) >= F32_MIN_POSITIVE) {
        return;
    }
    if SHADOWS {
        add_light(shadowed(spawn_origin(s.sp, to), to, tmax, kind, value));
    } else {
        add_light(value);
    }
}

// lighting::punctual for light `i`, seen from `p`.
fn punctual(s: Surface, i: u32, p: vec3<f32>) {
    let at = rp.o_lights + 16u * i;
    let kind = shade[at];
    let colour = sv3(at + 4u);
    let direction = sv3(at + 12u);
    if kind == 2u {
        light(s, -direction, inf(), colour, SHADOW);
        return;
    }
    let to_light = sv3(at + 8u) - p;
    let d2 = dot3(to_light, to_light);
    if d2 == 0.0 || !is_finite(d2) {
        return;
    }
    let d = root(d2);
    let range = sf(at + 1u);
    var window = 1.0;
    if is_finite(range) {
        let x = div(d, range);
        let x2 = x * x;
        let w = clamp(1.0 - x2 * x2, 0.0, 1.0);
        window = w * w;
    }
    var falloff = div(window, d2);
    if kind == 1u {
        let cos = dot3(direction, div3(-to_light, d));
        let cos_outer = sf(at + 2u);
        let cos_inner = sf(at + 3u);
        let x = clamp(div(cos - cos_outer, max(cos_inner - cos_outer, 1e-4)), 0.0, 1.0);
        falloff *= x * x;
    }
    if !(falloff > 0.0) {
        return;
    }
    light(s, to_light, 1.0, colour * falloff, SHADOW);
}

// Emitters::pick: the emitter whose running power passes target_area (u * total).
fn pick_emitter(target_area: f32) -> u32 {
    var lo = 0u;
    var hi = rp.emitter_count;
    while lo < hi && tick() {
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
fn area_lights(s: Surface, pixel: u32, depth: u32, p: vec3<f32>) {
    var samples = 1u;
    var grid = 1u;
    if SOFT_SHADOWS {
        samples = max(rp.soft_samples, 1u);
        grid = rp.soft_grid;
    }
    let scale = div(rp.emitter_power, f32(samples));
    for (var k = 0u; k < samples && tick(); k++) {
        let point = stratified2(pixel, depth, k, samples, grid);
        let target_area = point.x * rp.emitter_power;
        let e = pick_emitter(target_area);
        // Where the point falls along the emitter (Emitters::pick's `within`).
        var lo_area = 0.0;
        if e > 0u {
            lo_area = sf(rp.o_emitters + 4u * (e - 1u) + 3u);
        }
        let hi_area = sf(rp.o_emitters + 4u * e + 3u);
        var within = 0.5;
        if hi_area > lo_area {
            within = clamp(div(target_area - lo_area, hi_area - lo_area), 0.0, 1.0);
        }
        var emitted = sv3(rp.o_emitters + 4u * e);
        // The sample's weight (lighting::strength: the factor's largest channel).
        let weight = div(scale, max(max(emitted.x, emitted.y), emitted.z));
        let prim = shade[rp.o_emitters + 4u * rp.emitter_count + e];
        let a = vertex(prim, 0u);
        let b = vertex(prim, 1u);
        let c = vertex(prim, 2u);
        var y: vec3<f32>;
        // The point's barycentrics (weights of b and c), lighting::point_on's.
        var wb = 1.0 / 3.0;
        var wc = 1.0 / 3.0;
        if SOFT_SHADOWS {
            // (within, across), folded into the triangle past its diagonal.
            wb = within;
            wc = point.y;
            if wb + wc > 1.0 {
                wb = 1.0 - within;
                wc = 1.0 - point.y;
            }
            y = a * (1.0 - wb - wc) + b * wb + c * wc;
        } else {
            y = div3(a + b + c, 3.0);
        }
        // The emission where the point is, through the material's emissive texture.
        let record = material_at(prim);
        let emissive_texture = shade[record + EMISSIVE_TEXTURE_WORD];
        if emissive_texture != 0u {
            // The emissive slot's channel (`channel_of` for slot 1).
            let channel = (shade[record + UV_CHANNELS_WORD] >> 3u) & 7u;
            emitted = emitted * sample(emissive_texture - 1u, uv_at(prim, channel, wb, wc)).xyz;
        }
        let to = y - p;
        let d2 = dot3(to, to);
        let cos_y = div(abs(dot3(face_normal(a, b, c), to)), root(d2));
        if d2 > 0.0 && cos_y > 0.0 {
            let kind = select(SHADOW, SOFT_SHADOW, SOFT_SHADOWS);
            light(s, to, AREA_SHADOW_END, emitted * div(cos_y * weight, d2), kind);
        }
    }
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
fn shade_hit(task: Task, hit: HitOut, pixel: u32, sp: ptr<function, u32>) {
    var s: Surface;
    s.sp = spawn_point(hit.prim, hit);
    s.m = surface(hit);
    let dir = unit(task.d);
    var ng = s.sp.normal;
    let entering = dot3(ng, dir) < 0.0;
    if !entering {
        ng = -ng;
    }
    s.ng = ng;
    s.n = shading_normal(hit, ng, s.m);
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
        return;
    }
    s.weight = task.weight * coverage;
    if s.m.unlit {
        // KHR_materials_unlit: the base colour as it is, no light, no further ray.
        add_light(s.weight * s.m.base);
        return;
    }
    s.v = -dir;
    s.transmits = REFRACTION && s.m.transmission > 0.0;
    add_light(s.weight * s.m.emissive);
    let p = s.sp.point;
    if ENVIRONMENT {
        // Sky::received for the shading normal.
        let kd = select(s.m.albedo, s.m.albedo_transmits, s.transmits);
        let received = rp.environment * (1.0 + rp.environment_gradient * (2.0 / 3.0) * s.n.y);
        add_light(s.weight * kd * (received * s.m.occlusion));
    }
    if HEADLIGHT {
        let kd = select(s.m.albedo, s.m.albedo_transmits, s.transmits);
        add_light(s.weight * kd * (HEADLIGHT_AMBIENT * s.m.occlusion + HEADLIGHT_DIRECT * abs(dot3(s.n, s.v))));
    } else {
        for (var i = 0u; i < rp.light_count && tick(); i++) {
            punctual(s, i, p);
        }
        if rp.emitter_count > 0u {
            area_lights(s, pixel, task.depth, p);
        }
    }
    if !can_continue {
        return;
    }
    // Context::secondary.
    let n = s.n;
    var reflected = vec3<f32>(0.0);
    if REFRACTION && s.m.transmission > 0.0 {
        let t = s.m.transmission;
        let eta = select(s.m.ior, div(1.0, s.m.ior), entering);
        let cos_i = -dot3(dir, n);
        let k = 1.0 - eta * eta * (1.0 - cos_i * cos_i);
        if k < 0.0 {
            reflected += s.weight * t;
        } else {
            let cos_t = root(k);
            let rs = div(eta * cos_i - cos_t, eta * cos_i + cos_t);
            let rpar = div(cos_i - eta * cos_t, cos_i + eta * cos_t);
            let fresnel = clamp(0.5 * (rs * rs + rpar * rpar), 0.0, 1.0);
            let refracted = eta * dir + (eta * cos_i - cos_t) * n;
            if dot3(refracted, ng) < 0.0 {
                let w = s.weight * t * (1.0 - fresnel) * s.m.base;
                push(sp, spawn_origin(s.sp, refracted), refracted, w, task.depth + 1u, REFRACTION_RAY);
            }
            reflected += s.weight * t * fresnel;
        }
    }
    if REFLECTION {
        // A direction on the wrong side of the surface is mirrored about ng instead.
        var r = dir - 2.0 * dot3(dir, n) * n;
        if !(dot3(r, ng) > 0.0) {
            r = dir - 2.0 * dot3(dir, ng) * ng;
        }
        let w = reflected + s.weight * s.m.mirror;
        push(sp, spawn_origin(s.sp, r), r, w, task.depth + 1u, REFLECTION_RAY);
    }
}

// The light of pixel `pixel`, whose primary ray leaves `o` along `d`, into
// `light_sum`.
fn render_pixel(pixel: u32, o: vec3<f32>, d: vec3<f32>) {
    var sp = 1u;
    stack[0] = Task(o, 0u, d, PRIMARY, vec3<f32>(1.0));
    // Every push is one level deeper and depths are bounded: the loop ends.
    while sp > 0u && tick() {
        sp -= 1u;
        let task = stack[sp];
        counts[task.kind] += 1u;
        var hit = trace(task.o, task.d, 0.0, inf(), false);
        // Context::pass_back_faces: camera rays (and the alpha rays continuing them)
        // go on past the backs of single-sided surfaces, the same ray.
        if CULLING && (task.kind == PRIMARY || task.kind == ALPHA_RAY) {
            var layers = 0u;
            while hit.triangle != MISS && culled(hit, task.d) && tick() {
                if layers == MAX_CULLED_LAYERS {
                    hit.triangle = MISS;
                    break;
                }
                layers += 1u;
                hit = trace(spawn_origin(spawn_point(hit.prim, hit), task.d), task.d, 0.0, inf(), false);
            }
        }
        if hit.triangle == MISS {
            // Context::background: the environment, else the background.
            var background = BACKGROUND;
            if ENVIRONMENT {
                background = vec3<f32>(rp.environment * (1.0 + rp.environment_gradient * unit(task.d).y));
            }
            add_light(task.weight * background);
        } else {
            shade_hit(task, hit, pixel, &sp);
        }
    }
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn render(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = gid.x;
    if i < rp.pixel_count {
        let at = 8u * i;
        let d = vec3<f32>(bitcast<f32>(pixel_io[at]), bitcast<f32>(pixel_io[at + 1u]), bitcast<f32>(pixel_io[at + 2u]));
        let o = vec3<f32>(bitcast<f32>(pixel_io[at + 3u]), bitcast<f32>(pixel_io[at + 4u]), bitcast<f32>(pixel_io[at + 5u]));
        render_pixel(rp.first_pixel + i, o, d);
        for (var k = 0u; k < 6u; k++) {
            pixel_io[at + k] = light_sum[k];
        }
        // A pixel that ran out of loop budget (trace.wgsl, `tick`) is rendered again
        // on the CPU: word 6 says so, and its rays are not counted here.
        pixel_io[at + 6u] = select(0u, 1u, over_budget);
    }
    for (var k = 0u; k < 6u; k++) {
        if counts[k] != 0u && !over_budget {
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
