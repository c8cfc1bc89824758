//! Materials, lights and the effects renderer: the effect set decided at bake, ray
//! counters that are zero exactly for absent effects, analytic checks, and the glTF
//! and MTL materials that feed them.

use glam::{DVec3, Vec3};
use octrace_bake::{bake, procedural, BuildParams, Mesh};
use octrace_format::{AlphaMode, Effect, Light, LightKind, Material, StoredIndex};
use octrace_runtime::raysets::Camera;
use octrace_runtime::render::effects::{render_effects, EffectSet, Radiance, RayCounts, RayKind, RenderOptions};
use octrace_runtime::{Ray, Scene};

pub(crate) fn diffuse(name: &str, grey: f32) -> Material {
    Material {
        name: name.into(),
        base_color: [grey, grey, grey, 1.0],
        metallic: 0.0,
        roughness: 1.0,
        ..Material::default()
    }
}

/// Appends `part`'s triangles to `mesh` with material `material` (added to the list).
pub(crate) fn add(mesh: &mut Mesh, part: Mesh, material: Material) {
    let id = mesh.materials.len() as u32;
    mesh.materials.push(material);
    for t in part.triangles {
        mesh.push(t, None, None);
        mesh.material_ids.push(id);
    }
}

/// A square in the plane `y = height`, facing up, over `[-half, half]` in x and z.
pub(crate) fn floor(half: f32, height: f32) -> Mesh {
    let p = |x: f32, z: f32| [x, height, z];
    Mesh::from_triangles(vec![
        [p(-half, -half), p(-half, half), p(half, half)],
        [p(-half, -half), p(half, half), p(half, -half)],
    ])
}

/// A square in the plane `z = depth`, facing `+z`, over `[-half, half]` in x and y (plus
/// `lift` in y).
pub(crate) fn wall(half: f32, depth: f32, lift: f32) -> Mesh {
    let p = |x: f32, y: f32| [x, y + lift, depth];
    Mesh::from_triangles(vec![
        [p(-half, -half), p(half, -half), p(half, half)],
        [p(-half, -half), p(half, half), p(-half, half)],
    ])
}

pub(crate) fn point_light(position: [f32; 3], intensity: f32) -> Light {
    Light {
        name: "bulb".into(),
        kind: LightKind::Point,
        color: [1.0; 3],
        intensity,
        position,
        direction: [0.0, -1.0, 0.0],
        range: f32::INFINITY,
        inner_cone: 0.0,
        outer_cone: 0.0,
    }
}

pub(crate) fn scene_of(mesh: &Mesh) -> Scene {
    Scene::from_baked(bake(mesh, &BuildParams::auto()).expect("bakes")).expect("valid")
}

pub(crate) fn camera(eye: [f64; 3], target: [f64; 3], size: u32) -> Camera {
    Camera::look_at(DVec3::from(eye), DVec3::from(target), 50.0, size, size)
}

pub(crate) fn render(scene: &Scene, cam: &Camera, effects: EffectSet) -> (Radiance, RayCounts) {
    let options = RenderOptions { effects, ..RenderOptions::for_scene(scene.shading()) };
    render_effects(scene, cam, &options, &|_| {})
}

/// A sphere on a floor, with materials, and what else `extra` adds.
pub(crate) fn base_scene(extra: impl FnOnce(&mut Mesh)) -> Mesh {
    let mut m = Mesh::default();
    add(&mut m, floor(4.0, 0.0), diffuse("floor", 0.7));
    add(&mut m, procedural::sphere([0.0, 0.8, 0.0], 0.8, 16, 24), diffuse("ball", 0.5));
    extra(&mut m);
    m
}

/// The scene for each effect alone (with the lights some need), and the effects its
/// bake must decide.
fn one_effect_scenes() -> Vec<(&'static str, Mesh, Vec<Effect>)> {
    let glass = Material { transmission: 1.0, ior: 1.5, roughness: 0.0, ..diffuse("glass", 1.0) };
    let mirror = Material { metallic: 1.0, roughness: 0.0, ..diffuse("mirror", 0.9) };
    let pane = Material { alpha_mode: AlphaMode::Blend, base_color: [0.2, 0.8, 0.2, 0.4], ..diffuse("pane", 1.0) };
    let lamp = Material { emissive: [5.0; 3], ..diffuse("lamp", 0.0) };
    vec![
        ("none", base_scene(|_| {}), vec![]),
        ("point light", base_scene(|m| m.lights.push(point_light([2.0, 4.0, 3.0], 30.0))), vec![Effect::Shadows]),
        (
            "area light",
            base_scene(|m| add(m, floor(0.5, 3.0), lamp.clone())),
            vec![Effect::Shadows, Effect::SoftShadows],
        ),
        ("mirror", base_scene(|m| add(m, wall(3.0, -2.0, 1.0), mirror.clone())), vec![Effect::Reflection]),
        (
            "glass",
            base_scene(|m| add(m, procedural::sphere([1.5, 0.6, 1.5], 0.6, 12, 16), glass.clone())),
            vec![Effect::Reflection, Effect::Refraction],
        ),
        ("pane", base_scene(|m| add(m, wall(1.0, 2.0, 1.0), pane.clone())), vec![Effect::Alpha]),
    ]
}

/// The counters of the rays an effect traces (shadows: any shadow ray; soft shadows:
/// those towards sampled points of area lights).
fn kinds_of(effect: Effect) -> &'static [RayKind] {
    match effect {
        Effect::Shadows => &[RayKind::Shadow, RayKind::SoftShadow],
        Effect::SoftShadows => &[RayKind::SoftShadow],
        Effect::Reflection => &[RayKind::Reflection],
        Effect::Refraction => &[RayKind::Refraction],
        Effect::Alpha => &[RayKind::Alpha],
    }
}

#[test]
fn bake_decides_the_effects_and_counters_are_zero_exactly_for_absent_ones() {
    let cam = camera([0.5, 3.0, 6.0], [0.0, 0.8, 0.0], 48);
    for (name, mesh, expected) in one_effect_scenes() {
        let scene = scene_of(&mesh);
        let decided: Vec<Effect> = scene.shading().effects.iter().map(|e| e.effect).collect();
        assert_eq!(decided, expected, "{name}: {:?}", scene.shading().effects);
        let (_, counts) = render(&scene, &cam, EffectSet::of(scene.shading()));
        assert_eq!(counts.get(RayKind::Primary), 48 * 48, "{name}");
        for effect in Effect::ALL {
            let rays: u64 = kinds_of(effect).iter().map(|&k| counts.get(k)).sum();
            if expected.contains(&effect) {
                assert!(rays > 0, "{name}: {effect:?} present, no rays of its kinds");
            } else {
                assert_eq!(rays, 0, "{name}: {effect:?} absent, {counts:?}");
            }
        }
        // Each present effect turned off: its rays stop, the others' go on.
        for &off in &expected {
            let (_, c) = render(&scene, &cam, EffectSet::of(scene.shading()).without(off));
            for &kind in kinds_of(off) {
                assert_eq!(c.get(kind), 0, "{name}: {off:?} off, {} rays traced", kind.name());
            }
        }
    }
}

#[test]
fn every_effect_is_decided_with_its_reason() {
    let baked = bake(&procedural::effects_scene(), &BuildParams::auto()).unwrap();
    let reasons: Vec<String> =
        baked.shading.effects.iter().map(|e| format!("{}: {}", e.effect.name(), e.reason)).collect();
    assert_eq!(
        reasons,
        [
            "shadows: light 'key' (point) (and 1 more)",
            "soft-shadows: area light: material 'lamp' emits (14.00, 13.00, 11.50) on 2 triangles",
            "reflection: material 'mirror', metallic 1.00, roughness 0.00 (and 2 more)",
            "refraction: material 'glass', transmission 1.00, ior 1.50",
            "alpha: material 'tinted pane', alphaMode BLEND, alpha 0.35",
        ]
    );
}

/// A diffuse plane under a point light: radiance `albedo / pi * I * cos(theta) / r^2`.
#[test]
fn a_diffuse_plane_under_a_point_light_follows_cos_over_r_squared() {
    let mut mesh = Mesh::default();
    add(&mut mesh, floor(5.0, 0.0), diffuse("plane", 0.5));
    let light = [0.7f32, 2.0, -0.4];
    mesh.lights.push(point_light(light, 10.0));
    let scene = scene_of(&mesh);
    let cam = camera([0.0, 6.0, 0.01], [0.0, 0.0, 0.0], 64);
    let (radiance, counts) = render(&scene, &cam, EffectSet::of(scene.shading()));
    assert!(counts.get(RayKind::Shadow) > 0);
    let mut checked = 0;
    for y in (0..64).step_by(7) {
        for x in (0..64).step_by(5) {
            let ray = cam.ray(x, y);
            let Some(hit) = scene.intersect(&ray) else { continue };
            let p = ray.origin + ray.dir * hit.t;
            let to = Vec3::from(light) - p;
            let r2 = to.length_squared();
            let cos = to.y / r2.sqrt();
            let expected = 0.5 / std::f32::consts::PI * 10.0 * cos / r2;
            let got = radiance.at(x, y);
            assert!((got.x - expected).abs() <= 1e-4 * expected, "({x}, {y}): {got} vs {expected}");
            assert_eq!(got.x, got.z);
            checked += 1;
        }
    }
    assert!(checked > 80, "{checked}");
}

/// An object seen in a perfect mirror looks exactly like the object mirrored through
/// the mirror's plane, seen directly.
#[test]
fn a_mirror_shows_the_mirrored_object() {
    let object = |mirrored: bool| {
        let mut t = procedural::torus([0.3, 0.2, 1.2], 0.6, 0.25, 24, 12);
        if mirrored {
            for v in t.triangles.iter_mut().flatten() {
                v[2] = -v[2];
            }
        }
        t
    };
    let mirror = Material { metallic: 1.0, roughness: 0.0, ..diffuse("mirror", 1.0) };
    let mut with_mirror = Mesh::default();
    add(&mut with_mirror, wall(50.0, 0.0, 0.0), mirror);
    add(&mut with_mirror, object(false), diffuse("clay", 0.8));
    // Without the mirror, the object and its mirror image: what the camera sees
    // directly is the same, and rays that would meet the mirror go on to the image.
    let mut unfolded = Mesh::default();
    add(&mut unfolded, object(false), diffuse("clay", 0.8));
    add(&mut unfolded, object(true), diffuse("clay", 0.8));
    // The headlight lights both scenes (no lights).
    let cam = camera([0.0, 0.5, 4.0], [0.3, 0.2, 0.0], 64);
    let (a, counts) = render(&scene_of(&with_mirror), &cam, EffectSet::NONE.with(Effect::Reflection));
    assert!(counts.get(RayKind::Reflection) > 64 * 48);
    let (b, _) = render(&scene_of(&unfolded), &cam, EffectSet::NONE);
    let (a, b) = (a.to_image(), b.to_image());
    let differing = a.rgb.iter().zip(&b.rgb).filter(|(x, y)| x.abs_diff(**y) > 2).count();
    assert!(differing * 200 <= a.rgb.len(), "{differing} of {} channels differ", a.rgb.len());
    assert!(a.mean_abs_diff(&b).unwrap() < 0.5);
    // The torus is in the picture.
    assert!(b.rgb.iter().filter(|&&c| c > 60).count() > 500);
}

/// A pane that lets everything through — alpha 0, or full transmission with the index
/// of air — leaves the image as it was without it, shadows included.
#[test]
fn a_fully_transparent_pane_changes_nothing_behind_it() {
    let lit = |pane: Option<Material>| {
        let mut m = base_scene(|m| m.lights.push(point_light([0.5, 3.0, 4.0], 40.0)));
        if let Some(p) = pane {
            // Between the camera and the ball, and across the light's shadow rays.
            add(&mut m, wall(1.5, 1.5, 1.2), p);
        }
        scene_of(&m)
    };
    let cam = camera([0.0, 1.5, 5.0], [0.0, 0.8, 0.0], 64);
    let (plain, _) = render(&lit(None), &cam, EffectSet::NONE.with(Effect::Shadows));
    let invisible = Material { alpha_mode: AlphaMode::Blend, base_color: [0.3, 0.9, 0.2, 0.0], ..diffuse("pane", 1.0) };
    let air = Material { transmission: 1.0, ior: 1.0, ..diffuse("air", 1.0) };
    for (pane, effect) in [(invisible, Effect::Alpha), (air, Effect::Refraction)] {
        let scene = lit(Some(pane.clone()));
        assert!(scene.shading().has(effect), "{}", pane.name);
        let (through, counts) = render(&scene, &cam, EffectSet::of(scene.shading()));
        assert!(counts.get(kinds_of(effect)[0]) > 0);
        for (i, (p, q)) in plain.pixels.iter().zip(&through.pixels).enumerate() {
            assert!(
                (*p - *q).abs().max_element() <= 1e-4 * (1.0 + p.max_element()),
                "{}: pixel {i}: {p} vs {q}",
                pane.name
            );
        }
    }
}

#[test]
fn a_scene_without_lights_gets_a_headlight_and_no_shadow_rays() {
    let scene = scene_of(&base_scene(|_| {}));
    let (image, counts) = render(&scene, &camera([0.0, 2.0, 5.0], [0.0, 0.8, 0.0], 32), EffectSet::of(scene.shading()));
    assert_eq!(counts.total(), counts.get(RayKind::Primary));
    // The sphere's centre faces the camera: ambient 0.1 + 0.85, times the albedo 0.5.
    let centre = image.at(16, 16);
    assert!((centre.x - 0.5 * 0.95).abs() < 0.02, "{centre}");
}

#[test]
fn renders_do_not_depend_on_the_thread_count() {
    let scene = scene_of(&procedural::effects_scene());
    let cam = camera([0.2, 2.1, 6.4], [0.0, 0.6, 0.0], 40);
    let options = RenderOptions::for_scene(scene.shading());
    let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
    let a = one.install(|| render_effects(&scene, &cam, &options, &|_| {}));
    let b = render_effects(&scene, &cam, &options, &|_| {});
    assert_eq!(a, b);
}

#[test]
fn shading_data_survives_the_file() {
    let baked = bake(&procedural::effects_scene(), &BuildParams::auto()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("effects.oct");
    baked.write(&path, 0).unwrap();
    let scene = Scene::open(&path).unwrap();
    assert_eq!(scene.shading(), &baked.shading);
    let view = scene.view();
    assert_eq!(view.material_ids, baked.material_ids.as_slice());
    assert_eq!(view.normals, baked.normals.as_slice());
    // Every stored triangle's material is the one its input triangle had.
    let mesh = procedural::effects_scene();
    for (stored, &input) in view.triangle_ids.iter().enumerate() {
        assert_eq!(view.material_ids[stored], mesh.material_ids[input as usize]);
        assert_eq!(view.corner_normals(StoredIndex(stored as u32)), Some(mesh.normals[input as usize]));
    }
}

#[test]
fn a_file_with_a_material_id_out_of_range_is_refused() {
    let mut baked = bake(&procedural::effects_scene(), &BuildParams::auto()).unwrap();
    baked.material_ids[7] = baked.shading.materials.len() as u32;
    let err = baked.view().validate().unwrap_err().to_string();
    assert!(err.contains("material id 6 out of range (6 materials)"), "{err}");
    let mut baked = bake(&procedural::effects_scene(), &BuildParams::auto()).unwrap();
    baked.normals.pop();
    let err = baked.view().validate().unwrap_err().to_string();
    assert!(err.contains("normal array holds"), "{err}");
    let mut baked = bake(&procedural::effects_scene(), &BuildParams::auto()).unwrap();
    baked.shading.lights[0].intensity = f32::NAN;
    assert!(baked.view().validate().is_err());
}

/// A ray spawned by the renderer from the floor of the effects scene: the shadow ray
/// to the key light must get through (regression: exact hit points spawned rays on
/// their own plane, and every floor shadow ray was blocked).
#[test]
fn shadow_rays_leave_an_exact_plane() {
    let scene = scene_of(&base_scene(|_| {}));
    let hit = scene.intersect(&Ray::new(Vec3::new(2.5, 2.0, 2.5), Vec3::new(0.0, -1.0, 0.0))).unwrap();
    let tri = scene.view().triangle(hit.prim);
    let ray = octrace_runtime::spawn::spawn(&tri, &hit, Vec3::new(0.5, 3.0, 0.5), 1.0);
    assert!(!scene.occluded(&ray));
}
