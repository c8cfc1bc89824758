//! glTF materials as glTF defines them: base colour textures (sampling, wrap modes,
//! filters, `KHR_texture_transform`, alpha cut-outs), `KHR_materials_unlit`, Fresnel
//! from the index of refraction, orthographic cameras.

use glam::{DVec3, Vec3};
use octrace_bake::{bake, procedural, BuildParams, Mesh};
use octrace_format::{AlphaMode, Effect, Filter, Material, StoredIndex, Texture, Wrap, TEXEL_WORDS};
use octrace_runtime::raysets::Camera;
use octrace_runtime::render::effects::{render_effects, EffectSet, RayKind, RenderOptions};
use octrace_runtime::Scene;
use octrace_tests::data;
use proptest::prelude::*;

use crate::effects::{add, base_scene, camera, diffuse, point_light, render, scene_of, wall};

/// A linear texture of `w x h` texels whose channel `c` of texel `i` is `value(i, c)`
/// (8 bits).
fn texture(w: u32, h: u32, wrap: [Wrap; 2], filter: Filter, value: impl Fn(usize, usize) -> u8) -> (Texture, Vec<u32>) {
    let texels = (0..(w * h) as usize).map(|i| u32::from_le_bytes([0, 1, 2, 3].map(|c| value(i, c)))).collect();
    (
        Texture {
            name: "t".into(),
            width: w,
            height: h,
            first: 0,
            wrap,
            filter,
            min_alpha: 0.0,
            srgb: false,
            encoded: None,
        },
        texels,
    )
}

/// The sample glTF describes in words: wrap the coordinate into one period, then the
/// nearest texel, or the bilinear blend of the four around it with exact weights
/// (`f64`), texel centres at half-integers.
fn reference_sample(t: &Texture, texels: &[u32], uv: [f32; 2]) -> [f64; 4] {
    // sRGB colour decoded by the transfer function (to 16 bits, as glTF viewers keep
    // more than 8), the rest c / 255.
    let channel = |x: i64, y: i64, c: usize| {
        let v = texels[(y * t.width as i64 + x) as usize].to_le_bytes()[c];
        if t.srgb && c < 3 {
            f64::from(octrace_format::srgb_to_linear16(v)) / 65535.0
        } else {
            f64::from(v) / 255.0
        }
    };
    let wrap = |mode: Wrap, i: i64, n: i64| match mode {
        Wrap::Repeat => i.rem_euclid(n),
        Wrap::MirroredRepeat => {
            let k = i.rem_euclid(2 * n);
            if k < n {
                k
            } else {
                2 * n - 1 - k
            }
        }
        Wrap::ClampToEdge => i.clamp(0, n - 1),
    };
    let (w, h) = (t.width as i64, t.height as i64);
    let period = |mode: Wrap, c: f32| match mode {
        Wrap::Repeat => c.rem_euclid(1.0) as f64,
        Wrap::MirroredRepeat => c.rem_euclid(2.0) as f64,
        Wrap::ClampToEdge => c.clamp(0.0, 1.0) as f64,
    };
    let (cu, cv) = (period(t.wrap[0], uv[0]), period(t.wrap[1], uv[1]));
    match t.filter {
        Filter::Nearest => {
            // The product in f32, as documented: its rounding picks the texel at an edge.
            let (x, y) = ((cu as f32 * w as f32).floor() as i64, (cv as f32 * h as f32).floor() as i64);
            [0, 1, 2, 3].map(|c| channel(wrap(t.wrap[0], x, w), wrap(t.wrap[1], y, h), c))
        }
        Filter::Linear => {
            let (x, y) = (cu * w as f64 - 0.5, cv * h as f64 - 0.5);
            let (x0, y0) = (x.floor() as i64, y.floor() as i64);
            let (fx, fy) = (x - x0 as f64, y - y0 as f64);
            [0, 1, 2, 3].map(|c| {
                let at = |dx: i64, dy: i64| channel(wrap(t.wrap[0], x0 + dx, w), wrap(t.wrap[1], y0 + dy, h), c);
                (at(0, 0) * (1.0 - fx) + at(1, 0) * fx) * (1.0 - fy) + (at(0, 1) * (1.0 - fx) + at(1, 1) * fx) * fy
            })
        }
    }
}

fn wraps() -> impl Strategy<Value = Wrap> {
    prop_oneof![Just(Wrap::Repeat), Just(Wrap::MirroredRepeat), Just(Wrap::ClampToEdge)]
}

/// Coordinates anywhere, on texel edges and centres, at 0 and 1 exactly, negative.
fn coordinates() -> impl Strategy<Value = f32> {
    prop_oneof![
        -3.0f32..3.0,
        (-24i32..24, 1u32..9).prop_map(|(k, n)| k as f32 / n as f32),
        (-48i32..48, 1u32..9).prop_map(|(k, n)| (k as f32 + 0.5) / n as f32),
        Just(0.0f32),
        Just(-0.0f32),
        Just(1.0f32),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(4000))]

    /// Every wrap mode on each axis, both filters, textures from 1 x 1 up: the sample is
    /// the exact bilinear blend within the 8-bit weights' step (a 256th of the
    /// neighbours' difference) and the 16-bit rounding, and the nearest texel exactly.
    #[test]
    fn texture_samples_are_the_exact_filter_within_the_weights_step(
        w in 1u32..6, h in 1u32..6, wrap in (wraps(), wraps()), linear in any::<bool>(),
        u in coordinates(), v in coordinates(), seed in any::<u64>(), srgb in any::<bool>(),
    ) {
        let filter = if linear { Filter::Linear } else { Filter::Nearest };
        let value = |i: usize, c: usize| (seed.wrapping_mul(i as u64 * 4 + c as u64 + 1).rotate_left(17) >> 56) as u8;
        let (t, texels) = texture(w, h, [wrap.0, wrap.1], filter, value);
        let t = Texture { srgb, ..t };
        let got = t.sample(&texels, [u, v]);
        let want = reference_sample(&t, &texels, [u, v]);
        // Two weight steps (one per axis) of the full range, plus rounding.
        let tolerance = if linear { 2.0 / 256.0 + 1e-6 } else { 1e-7 };
        for c in 0..4 {
            prop_assert!((got[c] as f64 - want[c]).abs() <= tolerance, "channel {c}: {} vs {}", got[c], want[c]);
            prop_assert!((0.0..=1.0).contains(&got[c]));
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(1500))]

    /// `LitTexels::any_lit` never calls a triangle dark where a sample inside it reads
    /// colour: small textures with a few lit texels, every wrap mode and filter, corners
    /// anywhere (across periods, on texel edges), the samples at a grid of barycentrics
    /// read through `Texture::sample` as the renderer reads them. Corners spread around
    /// one point (zero to three texture widths) so that most triangles are called dark
    /// (counted once: 1,353 of 3,000 cases).
    #[test]
    fn a_triangle_called_dark_samples_only_black_texels(
        w in 1u32..7, h in 1u32..7, wrap in (wraps(), wraps()), linear in any::<bool>(),
        at in (coordinates(), coordinates()), spread in prop_oneof![Just(0.0f32), 0.0f32..0.4, 0.0f32..3.0],
        deltas in proptest::array::uniform3((-1.0f32..1.0, -1.0f32..1.0)), seed in any::<u64>(),
    ) {
        let filter = if linear { Filter::Linear } else { Filter::Nearest };
        let lit = |i: usize| seed.wrapping_mul(i as u64 + 7).rotate_left(29) % 6 == 0;
        let (t, texels) = texture(w, h, [wrap.0, wrap.1], filter, |i, c| if c == 3 || lit(i) { 160 } else { 0 });
        let corners = deltas.map(|(du, dv)| [at.0 + spread * du, at.1 + spread * dv]);
        if !octrace_format::LitTexels::new(&t, &texels).any_lit(corners) {
            let mix = |a: f32, b: f32, c: f32, x: f32, y: f32| a * (1.0 - x - y) + b * x + c * y;
            for i in 0..=16 {
                for j in 0..=16 - i {
                    let (x, y) = (i as f32 / 16.0, j as f32 / 16.0);
                    let uv = [0, 1].map(|k| mix(corners[0][k], corners[1][k], corners[2][k], x, y));
                    let sample = t.sample(&texels, uv);
                    prop_assert!(sample[..3].iter().all(|&c| c == 0.0), "lit at {uv:?}: {sample:?}");
                }
            }
        }
    }
}

/// A texture of one value samples to exactly that value everywhere: the weights sum to
/// one in integers, so a flat texture has no seams at any coordinate or wrap mode.
#[test]
fn a_flat_texture_samples_to_its_value_everywhere() {
    for wrap in [Wrap::Repeat, Wrap::MirroredRepeat, Wrap::ClampToEdge] {
        for filter in [Filter::Nearest, Filter::Linear] {
            let (t, texels) = texture(3, 2, [wrap; 2], filter, |_, c| [255, 128, 1, 0][c]);
            let centre = t.sample(&texels, [0.5 / 3.0, 0.25]);
            assert_eq!(centre[0], 1.0);
            assert!((centre[1] - 128.0 / 255.0).abs() < 1e-7 && (centre[2] - 1.0 / 255.0).abs() < 1e-9);
            assert_eq!(centre[3], 0.0);
            for k in -40..40 {
                let c = k as f32 * 0.137;
                assert_eq!(t.sample(&texels, [c, -c]), centre, "{wrap:?} {filter:?} {c}");
            }
        }
    }
}

fn leaf() -> Mesh {
    Mesh::load(data("textured/leaf.gltf")).expect("the textured sample loads")
}

/// The textured sample: an external PNG with alpha (a MASK cut-out), an embedded one
/// repeated four times by `KHR_texture_transform` with nearest filtering, and its
/// cameras, perspective and orthographic.
#[test]
fn the_textured_sample_loads_its_textures_samplers_and_transforms() {
    let mesh = leaf();
    assert!(mesh.warnings.is_empty(), "{:?}", mesh.warnings);
    let [checker, leaf] = &mesh.textures[..] else { panic!("{:?}", mesh.textures) };
    assert_eq!(
        (checker.width, checker.height, checker.filter, checker.wrap),
        (8, 8, Filter::Nearest, [Wrap::Repeat; 2])
    );
    assert_eq!((leaf.width, leaf.height, leaf.filter, leaf.wrap), (64, 64, Filter::Linear, [Wrap::ClampToEdge; 2]));
    assert_eq!((checker.min_alpha, leaf.min_alpha), (1.0, 0.0));
    assert_eq!(mesh.texels.len(), (64 + 64 * 64) * TEXEL_WORDS);
    assert!(checker.srgb && leaf.srgb);
    assert!(mesh.sources.iter().any(|s| s.ends_with("leaf.png")), "the external image is a source: {:?}", mesh.sources);
    assert_eq!(mesh.materials[0].base_color_texture, Some(0));
    assert_eq!((mesh.materials[1].base_color_texture, mesh.materials[1].alpha_mode), (Some(1), AlphaMode::Mask));
    // The floor's corner (1, 1) scaled by 4; the leaf's untouched.
    assert_eq!(mesh.uvs[0][1], [4.0, 4.0]);
    assert_eq!(mesh.uvs[2][1], [1.0, 1.0]);
    // sRGB decoded: the checker's blue texel (40, 80, 200) in linear light.
    let blue = checker.sample(&mesh.texels, [0.01, 0.01]);
    assert!((blue[2] as f64 - (200.0f64 / 255.0 + 0.055).powf(2.4) / 1.055f64.powf(2.4)).abs() < 1e-4, "{blue:?}");
    let [view, plan] = &mesh.cameras[..] else { panic!("{:?}", mesh.cameras) };
    assert_eq!((view.name.as_str(), view.orthographic), ("view", None));
    assert_eq!(plan.name, "plan");
    assert!((plan.orthographic.unwrap() - 1.8).abs() < 1e-6 && (plan.aspect.unwrap() - 2.4 / 1.8).abs() < 1e-6);
    let baked = bake(&mesh, &BuildParams::auto()).unwrap();
    let alpha = baked.shading.effects.iter().find(|e| e.effect == Effect::Alpha).expect("alpha from the texture");
    assert_eq!(
        alpha.reason,
        "material 'leaf', alphaMode MASK, alpha down to 0.00 (texture image 1 'leaf.png') < cutoff 0.50"
    );
}

/// Through the leaf's hole and its transparent corners the camera sees what lies
/// behind; its opaque part shows the texture's green; shadow rays pass the hole too.
#[test]
fn the_leaf_is_cut_out_where_its_texture_is_transparent() {
    let scene = Scene::from_baked(bake(&leaf(), &BuildParams::auto()).unwrap()).unwrap();
    // Square on to the leaf (x in [-1, 1], y in [0.2, 2.2] at z = 0), level with its
    // centre: the image spans x in [-1.25, 1.25].
    let cam = Camera::look_at(DVec3::new(0.0, 1.2, 5.0), DVec3::new(0.0, 1.2, 0.0), 28.07, 101, 101);
    let options = RenderOptions::for_scene(scene.shading());
    let (image, counts) = render_effects(&scene, &cam, &options, &|_| {});
    let background = Vec3::new(0.08, 0.08, 0.1);
    // The hole at the centre (uv 0.5, 0.5) and a transparent corner: the background.
    for (x, y) in [(50, 50), (14, 14), (86, 14)] {
        assert_eq!(image.at(x, y), background, "pixel ({x}, {y})");
    }
    // Opaque leaf (along its long axis, off the hole): the texture's green (or its
    // yellow vein), nothing of the background's blue.
    for (x, y) in [(35, 35), (65, 65), (40, 45)] {
        let p = image.at(x, y);
        assert!(p.y > 0.2 && p.y > 5.0 * p.z, "pixel ({x}, {y}): {p}");
    }
    assert!(counts.get(RayKind::Alpha) > 0);
    // Without the alpha effect the quad is opaque: its corners hide the background.
    let opaque = RenderOptions { effects: options.effects.without(Effect::Alpha), ..options };
    let (solid, _) = render_effects(&scene, &cam, &opaque, &|_| {});
    assert_ne!(solid.at(14, 14), background);
}

/// `KHR_materials_unlit`: the surface shows its base colour whatever the light, and an
/// all-unlit scene with a light casts no shadow ray.
#[test]
fn unlit_surfaces_show_their_colour_and_cast_no_shadow_rays() {
    let flat = |m: Material| Material { unlit: true, ..m };
    let mut mesh = Mesh::default();
    add(&mut mesh, wall(2.0, 0.0, 0.0), flat(Material { base_color: [0.9, 0.2, 0.1, 1.0], ..diffuse("red", 1.0) }));
    add(&mut mesh, procedural::sphere([0.0, 0.0, 1.0], 0.5, 12, 16), flat(diffuse("grey", 0.5)));
    mesh.lights.push(point_light([1.0, 2.0, 4.0], 50.0));
    let scene = scene_of(&mesh);
    assert!(scene.shading().effects.is_empty(), "{:?}", scene.shading().effects);
    let cam = camera([0.0, 0.0, 5.0], [0.0, 0.0, 0.0], 48);
    let (image, counts) = render(&scene, &cam, EffectSet::of(scene.shading()));
    assert_eq!(counts.total(), counts.get(RayKind::Primary), "{counts:?}");
    assert_eq!(image.at(24, 24), Vec3::splat(0.5), "the sphere, unlit");
    assert_eq!(image.at(8, 24), Vec3::new(0.9, 0.2, 0.1), "the wall, unlit");
    // One lit surface brings the shadows back, for it alone.
    add(&mut mesh, wall(0.3, 1.6, 0.0), diffuse("lit", 0.8));
    let scene = scene_of(&mesh);
    assert!(scene.shading().has(Effect::Shadows));
    let (_, counts) = render(&scene, &cam, EffectSet::of(scene.shading()));
    let lit_pixels = counts.get(RayKind::Shadow);
    assert!(lit_pixels > 0 && lit_pixels < 48 * 48 / 4, "{lit_pixels} shadow rays");
}

/// Glass with the index of air is no interface: no reflection is decided or traced,
/// and what lies behind it shows unchanged.
#[test]
fn a_sphere_with_the_index_of_air_is_invisible() {
    let air = Material { transmission: 1.0, ior: 1.0, roughness: 0.0, ..diffuse("air", 1.0) };
    let without = scene_of(&base_scene(|m| m.lights.push(point_light([0.5, 3.0, 4.0], 40.0))));
    let with = scene_of(&base_scene(|m| {
        m.lights.push(point_light([0.5, 3.0, 4.0], 40.0));
        add(m, procedural::sphere([0.4, 1.2, 2.0], 0.7, 16, 24), air.clone());
    }));
    let decided: Vec<Effect> = with.shading().effects.iter().map(|e| e.effect).collect();
    assert_eq!(decided, [Effect::Shadows, Effect::Refraction]);
    let cam = camera([0.0, 1.5, 5.0], [0.0, 0.8, 0.0], 64);
    let (a, _) = render(&without, &cam, EffectSet::of(without.shading()));
    let (b, counts) = render(&with, &cam, EffectSet::of(with.shading()).with(Effect::Reflection));
    assert_eq!(counts.get(RayKind::Reflection), 0, "{counts:?}");
    assert!(counts.get(RayKind::Refraction) > 200, "{counts:?}");
    for (i, (p, q)) in a.pixels.iter().zip(&b.pixels).enumerate() {
        assert!((*p - *q).abs().max_element() <= 1e-4 * (1.0 + p.max_element()), "pixel {i}: {p} vs {q}");
    }
}

/// Energy: glass in empty space, no light (so no local highlight): every ray that
/// leaves sees the background, so a pixel on the glass sees the background times its
/// reflectance plus its transmittance. Fresnel from the index, counted once, sums to 1
/// (less what the depth limit cuts); the second mirror term glass used to get on top
/// of its Fresnel reflection pushed it above 1. The sphere is faceted and wound
/// outward, so light enters it as glass and leaves it as air: near its rim a facet can
/// tilt the way out past the critical angle, and rays trapped by total internal
/// reflection run into the depth limit (as they would in cut glass). So: no pixel above
/// the background anywhere, and at most 3 % lost where no facet traps (rays passing
/// the centre within half the radius).
#[test]
fn glass_reflects_and_transmits_no_more_than_it_receives() {
    let background = Vec3::new(0.08, 0.08, 0.1);
    for ior in [1.2f32, 1.5, 2.4] {
        let mut mesh = Mesh::default();
        let glass = Material { transmission: 1.0, ior, roughness: 0.0, metallic: 0.0, ..diffuse("glass", 1.0) };
        add(&mut mesh, procedural::sphere([0.0; 3], 1.0, 24, 32), glass);
        let scene = scene_of(&mesh);
        let options = RenderOptions { max_depth: 12, ..RenderOptions::for_scene(scene.shading()) };
        let cam = camera([0.0, 0.0, 3.0], [0.0; 3], 40);
        let (image, counts) = render_effects(&scene, &cam, &options, &|_| {});
        assert!(counts.get(RayKind::Reflection) > 0 && counts.get(RayKind::Refraction) > 0);
        let rays = cam.rays();
        let (mut inner, mut inner_sum) = (0, 0.0);
        for (p, r) in image.pixels.iter().zip(&rays) {
            let ratio = *p / background;
            assert!(ratio.max_element() <= 1.0 + 1e-5, "ior {ior}: a pixel sees {ratio} of the background");
            // Rays passing the centre within half the radius: no facet traps them.
            if r.origin.cross(r.dir.normalize()).length() < 0.5 {
                assert!(ratio.min_element() >= 0.97, "ior {ior}: {r:?} sees only {ratio} of the background");
                (inner, inner_sum) = (inner + 1, inner_sum + ratio.min_element());
            }
        }
        assert!(inner > 100 && inner_sum / inner as f32 >= 0.98, "ior {ior}: {inner} central pixels");
        let on_glass = rays.iter().filter(|r| scene.intersect(r).is_some()).count();
        assert!(on_glass > 400, "ior {ior}: {on_glass} pixels on the glass");
    }
}

/// An orthographic camera's rays are parallel, one through each pixel of its view
/// rectangle, and it renders (the sample's second camera, `render --camera 1`).
#[test]
fn orthographic_cameras_cast_parallel_rays_over_their_height() {
    let scene = Scene::from_baked(bake(&leaf(), &BuildParams::auto()).unwrap()).unwrap();
    let c = &scene.shading().cameras[1];
    let cam = Camera::from_scene(c, 45.0, 40, 30);
    let (first, last) = (cam.ray(0, 0), cam.ray(39, 29));
    assert_eq!(first.dir, last.dir);
    assert_eq!(first.dir, Vec3::from(c.forward));
    // Opposite pixel centres lie (1 - 1/30) of the height apart, vertically in view.
    let span = (last.origin - first.origin).dot(Vec3::from(c.up)).abs();
    assert!((span - 2.0 * 1.8 * (1.0 - 1.0 / 30.0)).abs() < 1e-4, "{span}");
    let (image, counts) = render_effects(&scene, &cam, &RenderOptions::for_scene(scene.shading()), &|_| {});
    assert_eq!(counts.get(RayKind::Primary), 40 * 30);
    assert!(image.pixels.iter().any(|p| p.y > 2.0 * p.x), "the leaf is in view");
}

/// `COLOR_0` multiplies the base colour: the Khronos sample's corners show their
/// colours exactly, and a face's middle their mix.
#[test]
fn vertex_colours_multiply_the_base_colour() {
    let mesh = Mesh::load(data("gltf/BoxVertexColors.gltf")).unwrap();
    assert_eq!(mesh.colors.len(), 12);
    let scene = Scene::from_baked(bake(&mesh, &BuildParams::auto()).unwrap()).unwrap();
    let view = scene.view();
    let material = view.material(StoredIndex(0)).unwrap();
    let stored = |i: u32| mesh.colors[view.triangle_ids[i as usize] as usize];
    for prim in 0..view.triangle_count() as u32 {
        let corners = stored(prim).map(|c| c.map(|x| x as f32 / 65535.0));
        for (k, (u, v)) in [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0)].into_iter().enumerate() {
            let got = view.base_color_at(material, StoredIndex(prim), u, v);
            let want: [f32; 4] = [0, 1, 2, 3].map(|c| material.base_color[c] * corners[k][c]);
            for c in 0..4 {
                assert!((got[c] - want[c]).abs() <= 1e-6, "triangle {prim} corner {k}: {got:?} vs {want:?}");
            }
        }
        let middle = view.color_at(StoredIndex(prim), 1.0 / 3.0, 1.0 / 3.0).unwrap();
        for c in 0..4 {
            let mean = (corners[0][c] + corners[1][c] + corners[2][c]) / 3.0;
            assert!((middle[c] - mean).abs() <= 1e-6, "triangle {prim}: {middle:?}");
        }
    }
}

/// KHR_texture_transform's rotation as the spec writes it (issue 34), on Khronos'
/// TextureTransformTest: the arrow drawn in `Arrow.png` runs from near the texture's
/// origin to its tip at about (0.63, 0.63); mapped back onto the "Rotation" and "All"
/// quads through the uvs the bake stored, it points at the quad's "Correct" marker
/// (within 6 degrees), not at the "Error" one (with the transposed matrix the bake
/// used before: the other way round, 45 degrees off).
#[test]
#[cfg_attr(not(octrace_shared), ignore = "needs ../shared beside the clone (README: Set up)")]
fn texture_rotation_points_the_arrow_at_the_correct_marker() {
    let test = "texture_rotation_points_the_arrow_at_the_correct_marker";
    let Some(path) = octrace_tests::shared_file("gltf/TextureTransformTest/TextureTransformTest.gltf", test) else {
        return;
    };
    let mesh = octrace_bake::Mesh::load(&path).unwrap();
    // (quad node's name, its translation, the markers' translations within it).
    let quads = [
        (
            "'Rotation'",
            [-1.1f64, -0.55],
            [-0.07904822439840126, -0.5162674857624154],
            Some([0.5162674857624154, 0.07904822439840126]),
        ),
        ("'All'", [1.1, -0.55], [-0.07, -0.25], None),
    ];
    for (quad, at, correct, error) in quads {
        let part = mesh.parts.iter().find(|p| p.name.starts_with("node") && p.name.contains(quad)).unwrap();
        // The quad's uv map is affine in position: invert it on its first triangle.
        let t = part.first as usize;
        let (p, uv) =
            (mesh.triangles[t].map(|c| [c[0] as f64, c[1] as f64]), mesh.uvs[t].map(|c| [c[0] as f64, c[1] as f64]));
        let (du1, du2) = ([uv[1][0] - uv[0][0], uv[1][1] - uv[0][1]], [uv[2][0] - uv[0][0], uv[2][1] - uv[0][1]]);
        let det = du1[0] * du2[1] - du2[0] * du1[1];
        let position = |u: f64, v: f64| {
            let (du, dv) = (u - uv[0][0], v - uv[0][1]);
            let (a, b) = ((du * du2[1] - du2[0] * dv) / det, (du1[0] * dv - du * du1[1]) / det);
            [0, 1].map(|k| p[0][k] + a * (p[1][k] - p[0][k]) + b * (p[2][k] - p[0][k]))
        };
        let (origin, tip) = (position(0.0, 0.0), position(0.63, 0.63));
        let angle_to = |m: [f64; 2]| {
            let (d, e) =
                ([tip[0] - origin[0], tip[1] - origin[1]], [at[0] + m[0] - origin[0], at[1] + m[1] - origin[1]]);
            (d[0] * e[1] - d[1] * e[0]).atan2(d[0] * e[0] + d[1] * e[1]).abs().to_degrees()
        };
        assert!(
            angle_to(correct) < 6.0,
            "{quad}: the arrow is {:.1} degrees off its correct marker",
            angle_to(correct)
        );
        if let Some(error) = error {
            assert!(angle_to(error) > 30.0, "{quad}: the arrow points at the error marker");
        }
    }
}

/// `Scene::surface` (issue 35): on the textured leaf sample and the glTF extensions
/// sample, the point, normals, texture coordinates, part and material of each hit
/// agree with the input mesh read independently, looked up by the hit's input
/// triangle index (the stored order differs from the input's).
#[test]
fn a_hit_surface_agrees_with_the_input_mesh() {
    use glam::Vec3;
    for file in ["textured/leaf.gltf", "extensions.gltf"] {
        let mesh = octrace_bake::Mesh::load(octrace_tests::data(file)).unwrap();
        let scene =
            octrace_runtime::Scene::from_baked(octrace_bake::bake(&mesh, &Default::default()).unwrap()).unwrap();
        let (lo, hi) =
            mesh.triangles.iter().flatten().fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), &p| {
                (lo.min(Vec3::from(p)), hi.max(Vec3::from(p)))
            });
        let mut rng = octrace_bake::procedural::SplitMix(35);
        let (mut hits, mut reordered) = (0, 0);
        for _ in 0..4000 {
            let target = lo + (hi - lo) * Vec3::new(rng.unit(), rng.unit(), rng.unit());
            let origin = target + (Vec3::new(rng.unit(), rng.unit(), rng.unit()) - 0.5) * 20.0;
            let ray = octrace_runtime::Ray::new(origin, target - origin);
            let Some(hit) = scene.intersect(&ray) else { continue };
            hits += 1;
            reordered += (hit.prim.0 != hit.triangle) as usize;
            let s = scene.surface(&hit);
            let t = hit.triangle as usize;
            let [a, b, c] = mesh.triangles[t].map(Vec3::from);
            let expected_point = a * (1.0 - hit.u - hit.v) + b * hit.u + c * hit.v;
            assert!((s.point - expected_point).abs().max_element() <= 1e-5, "{file}: {s:?}");
            assert!((s.point - (origin + hit.t * ray.dir)).length() <= 1e-3 * (1.0 + origin.length()), "{file}");
            assert!((s.geometric_normal - (b - a).cross(c - a).normalize()).length() < 1e-5, "{file}");
            assert!(s.shading_normal.dot(s.geometric_normal) >= 0.0 && (s.shading_normal.length() - 1.0).abs() < 1e-5);
            if let Some(uvs) = mesh.uvs.get(t) {
                let uv = s.uv.expect("the mesh has uvs");
                for k in 0..2 {
                    let want = uvs[0][k] * (1.0 - hit.u - hit.v) + uvs[1][k] * hit.u + uvs[2][k] * hit.v;
                    assert!((uv[k] - want).abs() <= 1e-5, "{file}: uv {uv:?}, want {want}");
                }
            }
            let part = mesh.parts.iter().position(|p| (p.first..p.first + p.count).contains(&hit.triangle));
            assert_eq!(s.part.map(|p| p as usize), part, "{file}");
            assert_eq!(s.part_name.as_deref(), part.map(|p| mesh.parts[p].name.as_str()));
            // The part's numbers say what its name says.
            let Some(octrace_format::PartSource::Gltf { node, mesh: m, primitive }) = s.part_source else {
                panic!("{file}: a glTF part without its numbers: {:?}", s.part_source)
            };
            let name = s.part_name.as_deref().unwrap_or_default();
            assert!(name.starts_with(&format!("node {node}")), "{file}: {name} is not node {node}");
            assert!(name.contains(&format!("mesh {m}")) && name.ends_with(&format!("primitive {primitive}")), "{name}");
            assert_eq!(s.material, mesh.material_ids.get(t).copied(), "{file}");
        }
        assert!(hits > 200, "{file}: {hits} hits");
        eprintln!("{file}: {hits} hits, {reordered} on triangles stored out of input order");
    }
}

/// A floor and a sign of two panels whose material emits through a texture (issue 34):
/// 8 x 2 texels, clamped, the five left columns black and the three right ones orange;
/// the left panel reads only black texels (u in [0, 0.25]), the right one only orange
/// ones (u in [0.75, 1]). With `light`, a point light above.
pub(crate) fn glow_scene(light: bool) -> Mesh {
    let mut mesh = Mesh::default();
    add(&mut mesh, crate::effects::floor(4.0, 0.0), diffuse("floor", 0.7));
    let (texture, texels) = texture(2 * 4, 2, [Wrap::ClampToEdge; 2], Filter::Nearest, |i, c| {
        let orange = [255, 120, 0, 255];
        if i % 8 >= 5 {
            orange[c]
        } else if c == 3 {
            255
        } else {
            0
        }
    });
    mesh.textures.push(Texture { min_alpha: 1.0, ..texture });
    mesh.texels = texels;
    let sign = mesh.materials.len() as u32;
    mesh.materials.push(Material { emissive: [4.0; 3], emissive_texture: Some(0), ..diffuse("sign", 0.2) });
    for (x0, u0) in [(-1.2f32, 0.0f32), (0.2, 0.75)] {
        let (x1, u1, z) = (x0 + 1.0, u0 + 0.25, -1.5);
        let p = |x: f32, y: f32| [x, y, z];
        mesh.push([p(x0, 0.3), p(x1, 0.3), p(x1, 1.3)], None, Some([[u0, 1.0], [u1, 1.0], [u1, 0.0]]));
        mesh.push([p(x0, 0.3), p(x1, 1.3), p(x0, 1.3)], None, Some([[u0, 1.0], [u1, 0.0], [u0, 0.0]]));
        mesh.material_ids.extend([sign; 2]);
    }
    if light {
        mesh.lights.push(point_light([0.0, 4.0, 3.0], 40.0));
    }
    mesh
}

/// The glow scene's camera, and the mean red radiance of the pixels whose primary ray
/// meets what `region` accepts (its hit point and whether it hit the sign).
fn mean_red(
    scene: &Scene,
    image: &octrace_runtime::render::effects::Radiance,
    cam: &Camera,
    region: impl Fn(Vec3, bool) -> bool,
) -> f32 {
    let view = scene.view();
    let (mut sum, mut n) = (0.0, 0);
    for y in 0..image.height {
        for x in 0..image.width {
            let ray = cam.ray(x, y);
            let Some(hit) = scene.intersect(&ray) else { continue };
            let point = ray.origin + hit.t * ray.dir;
            let on_sign = view.material(hit.prim).is_some_and(|m| m.name == "sign");
            if region(point, on_sign) {
                sum += image.at(x, y).x;
                n += 1;
            }
        }
    }
    assert!(n > 20, "too few pixels in the region: {n}");
    sum / n as f32
}

/// Emission through an emissive texture (issue 34): the bake counts as area lights only
/// the triangles whose texels are not all black (2 of the sign's 4) and names the
/// texture; the render shows emission on the orange panel and not on the black one, and
/// the floor before the orange panel gets its light while the floor before the black
/// one does not (the light above is centred between them). Before, the texture was
/// ignored and the whole sign glowed and lit the floor alike on both sides.
#[test]
fn emission_through_a_texture_glows_and_lights_only_where_the_texture_is_bright() {
    let mesh = glow_scene(true);
    let used: Vec<u32> = (0..mesh.triangles.len() as u32).collect();
    let effects = octrace_bake::effects::decide(&mesh, &used);
    let soft = effects.iter().find(|e| e.effect == Effect::SoftShadows).expect("soft shadows: the orange panel");
    assert!(soft.reason.contains("texture t on 2 of 4 triangles"), "{}", soft.reason);
    let scene = scene_of(&mesh);
    let cam = camera([0.0, 1.6, 4.0], [0.0, 0.6, -1.5], 160);
    let (image, counts) = render(&scene, &cam, EffectSet::NONE.with(Effect::Shadows).with(Effect::SoftShadows));
    assert!(counts.get(RayKind::SoftShadow) > 0, "{counts:?}");
    let left = mean_red(&scene, &image, &cam, |p, sign| sign && p.x < 0.0);
    let right = mean_red(&scene, &image, &cam, |p, sign| sign && p.x > 0.0);
    eprintln!("panels: black {left}, orange {right}");
    assert!(right > 3.5 && left < 0.5, "panels: black {left}, orange {right}");
    let floor = |side: f32| {
        move |p: Vec3, sign: bool| !sign && p.x * side > 0.3 && p.x * side < 1.1 && p.z > -1.4 && p.z < -0.9
    };
    let (floor_left, floor_right) =
        (mean_red(&scene, &image, &cam, floor(-1.0)), mean_red(&scene, &image, &cam, floor(1.0)));
    eprintln!("floor before the black panel {floor_left}, before the orange {floor_right}");
    assert!(
        floor_right > 1.2 * floor_left,
        "floor before the black panel {floor_left}, before the orange {floor_right}"
    );
}

/// A scene whose only emission comes through textures keeps the headlight (issue 34):
/// what glows is seen, and the floor is lit as a glTF viewer lights it; the bake
/// decides no shadows, and the render traces none. Before, the sign was the scene's
/// only light and the floor far from it came out black.
#[test]
fn a_scene_lit_only_through_emissive_textures_keeps_its_headlight() {
    let mesh = glow_scene(false);
    let used: Vec<u32> = (0..mesh.triangles.len() as u32).collect();
    assert!(octrace_bake::effects::decide(&mesh, &used).is_empty());
    let scene = scene_of(&mesh);
    let cam = camera([0.0, 1.6, 4.0], [0.0, 0.6, -1.5], 160);
    let (image, counts) = render(&scene, &cam, EffectSet::NONE.with(Effect::Shadows).with(Effect::SoftShadows));
    assert_eq!(counts.get(RayKind::Shadow) + counts.get(RayKind::SoftShadow), 0, "{counts:?}");
    let near_floor = mean_red(&scene, &image, &cam, |p, sign| !sign && p.z > 1.0);
    eprintln!("the floor near the camera: {near_floor}");
    assert!(near_floor > 0.2, "the floor near the camera: {near_floor}");
    let orange = mean_red(&scene, &image, &cam, |p, sign| sign && p.x > 0.0);
    assert!(orange > 3.5, "the orange panel: {orange}");
}

/// DamagedHelmet (Khronos sample, `../shared/gltf`): its emissive factor is (1, 1, 1)
/// and its emissive texture black almost everywhere. Rendered with its emission and
/// without it, the images differ only where the texture is bright: a few per cent of
/// the helmet's pixels (lamps, visor displays), not the whole helmet (the white
/// silhouette of before); and `inspect`'s effects name no whole-surface area light.
#[test]
#[cfg_attr(not(octrace_shared), ignore = "needs ../shared beside the clone (README: Set up)")]
fn damaged_helmet_glows_only_where_its_emissive_texture_is_bright() {
    let test = "damaged_helmet_glows_only_where_its_emissive_texture_is_bright";
    let Some(path) = octrace_tests::shared_file("gltf/DamagedHelmet.glb", test) else { return };
    let mesh = Mesh::load(&path).unwrap();
    let m = &mesh.materials[0];
    assert_eq!((m.emissive, m.emissive_texture.is_some()), ([1.0; 3], true));
    let used: Vec<u32> = (0..mesh.triangles.len() as u32).collect();
    let effects = octrace_bake::effects::decide(&mesh, &used);
    assert!(effects.iter().all(|e| !e.reason.contains("area light")), "{effects:?}");
    let lit = scene_of(&mesh);
    let mut dark = mesh.clone();
    dark.materials[0].emissive = [0.0; 3];
    let dark = scene_of(&dark);
    let frame = octrace_runtime::raysets::Frame::from_triangles(&mesh.triangles);
    let cam = Camera::standard_sized(&frame, 192, 192);
    let (a, _) = render(&lit, &cam, EffectSet::NONE);
    let (b, _) = render(&dark, &cam, EffectSet::NONE);
    let rays = cam.rays();
    let helmet: Vec<usize> = (0..rays.len()).filter(|&i| lit.intersect(&rays[i]).is_some()).collect();
    let glowing = helmet.iter().filter(|&&i| (a.pixels[i] - b.pixels[i]).max_element() > 0.02).count();
    let white = helmet.iter().filter(|&&i| a.pixels[i].min_element() >= 0.98).count();
    let share = |n: usize| n as f64 / helmet.len() as f64;
    eprintln!("{} helmet pixels, {glowing} glow, {white} white", helmet.len());
    assert!(helmet.len() > 5000, "{} helmet pixels", helmet.len());
    assert!(share(glowing) > 0.005 && share(glowing) < 0.15, "{glowing} of {} pixels glow", helmet.len());
    assert!(share(white) < 0.02, "{white} of {} pixels are white", helmet.len());
}

/// A lit panel in two halves before a ball on a floor (issue 34): with `textured`, one
/// material (metallic 1, roughness 1) whose metallic-roughness texture makes the left
/// half a rough dielectric (green 255, blue 0) and the right a polished metal (green 0,
/// blue 255); without, two materials with those values as factors. With `occlusion`,
/// the floor's occlusion texture (red 0 on its left half, 255 on its right, strength
/// 1) and no light: the headlight's ambient term is what occlusion darkens.
pub(crate) fn metal_scene(textured: bool, occlusion: bool) -> Mesh {
    let mut mesh = Mesh::default();
    // Texture 0: metallic-roughness, 2 x 1; texture 1: occlusion, 2 x 1.
    let (mr, mut texels) =
        texture(2, 1, [Wrap::ClampToEdge; 2], Filter::Nearest, |i, c| [[0, 255, 0, 255], [0, 0, 255, 255]][i][c]);
    let (occ, occ_texels) =
        texture(2, 1, [Wrap::ClampToEdge; 2], Filter::Nearest, |i, c| [[0, 0, 0, 255], [255, 0, 0, 255]][i][c]);
    mesh.textures = vec![mr, Texture { first: texels.len() as u32, ..occ }];
    texels.extend(occ_texels);
    mesh.texels = texels;
    let floor = mesh.materials.len() as u32;
    let occlusion_texture = occlusion.then_some(1);
    mesh.materials.push(Material { occlusion_texture, ..diffuse("floor", 0.7) });
    let quad = |mesh: &mut Mesh, p: [[f32; 3]; 4], uv: [[f32; 2]; 4], material: u32| {
        mesh.push([p[0], p[1], p[2]], None, Some([uv[0], uv[1], uv[2]]));
        mesh.push([p[0], p[2], p[3]], None, Some([uv[0], uv[2], uv[3]]));
        mesh.material_ids.extend([material; 2]);
    };
    for (x0, u0) in [(-4.0f32, 0.1f32), (0.0, 0.6)] {
        let p = [[x0, 0.0, 4.0], [x0 + 4.0, 0.0, 4.0], [x0 + 4.0, 0.0, -4.0], [x0, 0.0, -4.0]];
        quad(&mut mesh, p, [[u0, 0.5], [u0 + 0.3, 0.5], [u0 + 0.3, 0.5], [u0, 0.5]], floor);
    }
    let panel = |metallic: f32, roughness: f32| Material { metallic, roughness, ..diffuse("panel", 0.8) };
    let first = mesh.materials.len() as u32;
    if textured {
        mesh.materials.push(Material { metallic_roughness_texture: Some(0), ..panel(1.0, 1.0) });
    } else {
        mesh.materials.extend([panel(0.0, 1.0), panel(1.0, 0.0)]);
    }
    for (k, (x0, u0)) in [(-1.6f32, 0.1f32), (0.0, 0.6)].into_iter().enumerate() {
        let p = [[x0, 0.1, -1.5], [x0 + 1.6, 0.1, -1.5], [x0 + 1.6, 1.7, -1.5], [x0, 1.7, -1.5]];
        let material = if textured { first } else { first + k as u32 };
        quad(&mut mesh, p, [[u0, 0.5], [u0 + 0.3, 0.5], [u0 + 0.3, 0.5], [u0, 0.5]], material);
    }
    add(&mut mesh, procedural::sphere([0.0, 0.5, 0.2], 0.5, 12, 16), diffuse("ball", 0.5));
    if !occlusion {
        mesh.lights.push(point_light([0.5, 3.0, 2.5], 30.0));
    }
    mesh
}

/// A metallic-roughness texture (issue 34) shades each point as its texel says: the
/// panel whose texture makes one half a rough dielectric and the other a polished metal
/// renders to exactly the image (and the rays of each kind) of the panel made of two
/// materials with those values, and the bake decides the reflection its polished half
/// calls for, naming the texture. Before, the texture was ignored: the whole panel was
/// a rough metal, and nothing reflected.
#[test]
fn a_metallic_roughness_texture_shades_as_its_values_would() {
    let (textured, plain) = (metal_scene(true, false), metal_scene(false, false));
    let used: Vec<u32> = (0..textured.triangles.len() as u32).collect();
    let effects = octrace_bake::effects::decide(&textured, &used);
    let reflection = effects.iter().find(|e| e.effect == Effect::Reflection).expect("reflection: the metal half");
    assert!(reflection.reason.contains("roughness down to 0.00 (texture t)"), "{}", reflection.reason);
    assert_eq!(
        effects.iter().map(|e| e.effect).collect::<Vec<_>>(),
        octrace_bake::effects::decide(&plain, &used).iter().map(|e| e.effect).collect::<Vec<_>>()
    );
    let cam = camera([0.0, 1.4, 4.0], [0.0, 0.7, -1.5], 128);
    let (a, ca) = render(&scene_of(&textured), &cam, EffectSet::NONE.with(Effect::Shadows).with(Effect::Reflection));
    let (b, cb) = render(&scene_of(&plain), &cam, EffectSet::NONE.with(Effect::Shadows).with(Effect::Reflection));
    assert!(ca.get(RayKind::Reflection) > 1000, "{ca:?}");
    assert_eq!(format!("{ca:?}"), format!("{cb:?}"));
    let differ = a.pixels.iter().zip(&b.pixels).filter(|(x, y)| x != y).count();
    assert_eq!(differ, 0, "{differ} pixels differ");
}

/// An occlusion texture (issue 34) darkens the light from all around, and nothing
/// else: under the headlight, the floor's half whose texels say "occluded" loses its
/// ambient part (0.1 of the albedo, here 0.07), the other half and everything else
/// render exactly as without the texture.
#[test]
fn an_occlusion_texture_darkens_only_the_ambient_light_where_it_says() {
    let (occluded, open) = (metal_scene(false, true), metal_scene(false, false));
    let mut open_under_headlight = open.clone();
    open_under_headlight.lights.clear();
    let scene = scene_of(&occluded);
    let cam = camera([0.0, 1.4, 4.0], [0.0, 0.7, -1.5], 128);
    let (a, _) = render(&scene, &cam, EffectSet::NONE);
    let (b, _) = render(&scene_of(&open_under_headlight), &cam, EffectSet::NONE);
    let (mut darker, mut same) = (0, 0);
    for y in 0..a.height {
        for x in 0..a.width {
            let ray = cam.ray(x, y);
            let (pa, pb) = (a.at(x, y), b.at(x, y));
            let on_left_floor = scene.intersect(&ray).is_some_and(|hit| {
                let p = ray.origin + hit.t * ray.dir;
                scene.view().material(hit.prim).is_some_and(|m| m.name == "floor") && p.x < 0.0
            });
            if on_left_floor {
                let lost = pb - pa;
                assert!((lost - Vec3::splat(0.07)).abs().max_element() < 1e-6, "({x}, {y}): {pa} against {pb}");
                darker += 1;
            } else {
                assert_eq!(pa, pb, "({x}, {y})");
                same += 1;
            }
        }
    }
    assert!(darker > 1000 && same > 1000, "{darker} darker, {same} the same");
}

/// A floor in two halves under a directional light (issue 34), one material with a
/// normal texture of two texels: the left half's tips the normal 45 degrees towards
/// +x (towards the light), the right half's is flat.
pub(crate) fn bump_scene(scale: f32) -> Mesh {
    let mut mesh = Mesh::default();
    let (t, texels) = texture(2, 1, [Wrap::ClampToEdge; 2], Filter::Nearest, |i, c| {
        [[218, 128, 218, 255], [128, 128, 255, 255]][i][c]
    });
    mesh.textures.push(t);
    mesh.texels = texels;
    mesh.materials.push(Material { normal_texture: Some(0), normal_scale: scale, ..diffuse("floor", 0.7) });
    for (x0, u0) in [(-4.0f32, 0.1f32), (0.0, 0.6)] {
        let p = [[x0, 0.0, 4.0], [x0 + 4.0, 0.0, 4.0], [x0 + 4.0, 0.0, -4.0], [x0, 0.0, -4.0]];
        let uv = [[u0, 1.0], [u0 + 0.3, 1.0], [u0 + 0.3, 0.0], [u0, 0.0]];
        mesh.push([p[0], p[1], p[2]], None, Some([uv[0], uv[1], uv[2]]));
        mesh.push([p[0], p[2], p[3]], None, Some([uv[0], uv[2], uv[3]]));
        mesh.material_ids.extend([0; 2]);
    }
    let sun = octrace_format::Light {
        name: "sun".into(),
        kind: octrace_format::LightKind::Directional,
        direction: [-0.6, -0.8, 0.0],
        intensity: 2.0,
        ..point_light([0.0; 3], 1.0)
    };
    mesh.lights.push(sun);
    mesh
}

/// A normal texture (issue 34) turns the shading normal as its texels say: on a flat
/// floor whose tangent is +x (u grows with x) and bitangent the normal crossed with it
/// (-z), each pixel's radiance is Lambert's with the normal the texel gives
/// (`normalize(t (2r - 1) scale + b (2g - 1) scale + n (2b - 1))`, computed here in f64),
/// to 1e-5: the tipped half brighter (towards the light), the flat half as without a
/// map; with a scale of 0 the map only shortens the normal, and both halves light as
/// the plain floor. Before, the map was ignored.
#[test]
fn a_normal_texture_turns_the_shading_normal_as_its_texels_say() {
    for scale in [1.0f32, 0.0] {
        let mesh = bump_scene(scale);
        let scene = scene_of(&mesh);
        let cam = camera([0.0, 5.0, 3.0], [0.0, 0.0, 0.0], 96);
        let (image, _) = render(&scene, &cam, EffectSet::of(scene.shading()));
        let l = DVec3::new(0.6, 0.8, 0.0);
        let expected = |texel: [u8; 3]| {
            let c = texel.map(|c| f64::from(c) / 255.0 * 2.0 - 1.0);
            let n = (DVec3::X * c[0] * scale as f64 + DVec3::NEG_Z * c[1] * scale as f64 + DVec3::Y * c[2]).normalize();
            0.7 / std::f64::consts::PI * 2.0 * n.dot(l).max(0.0)
        };
        let (left, right) = (expected([218, 128, 218]), expected([128, 128, 255]));
        let mut seen = [0; 2];
        for y in 0..image.height {
            for x in 0..image.width {
                let ray = cam.ray(x, y);
                let Some(hit) = scene.intersect(&ray) else { continue };
                let p = ray.origin + hit.t * ray.dir;
                let (want, side) = if p.x < -0.05 {
                    (left, 0)
                } else if p.x > 0.05 {
                    (right, 1)
                } else {
                    continue;
                };
                let got = image.at(x, y);
                assert!(
                    ((got.x as f64) - want).abs() < 1e-5 * want.max(1.0),
                    "scale {scale}, ({x}, {y}): {got} against {want}"
                );
                seen[side] += 1;
            }
        }
        assert!(seen[0] > 500 && seen[1] > 500, "{seen:?}");
        if scale == 1.0 {
            assert!(left > 1.2 * right, "{left} {right}");
        }
    }
}
