//! The renderer's environment (issue 45, item 2): scenes lit only by emissive surfaces
//! rendered black wherever a surface faced away from the emitters (EmissiveStrengthTest:
//! 18.6 % of its pixels pure black), where glTF viewers light them with a neutral
//! environment.

use octrace_bake::Mesh;
use octrace_runtime::render::effects::{render_effects, Environment, Radiance, RayKind, RenderOptions, Sky};
use octrace_runtime::Scene;

use crate::effects::{add, base_scene, camera, diffuse, floor, point_light, scene_of};

/// A grey floor (albedo 0.7) with an untextured emissive panel under it, facing down:
/// the only light, which no point of the floor's top sees.
pub(crate) fn lit_from_below() -> Mesh {
    let mut mesh = Mesh::default();
    add(&mut mesh, floor(1.0, 0.0), diffuse("floor", 0.7));
    let panel = octrace_format::Material { emissive: [3.0; 3], ..diffuse("lamp", 0.2) };
    add(&mut mesh, floor(0.5, -1.0), panel);
    mesh
}

/// A ball on a floor under an untextured emissive panel: soft shadows, and the
/// environment where the panel does not reach.
pub(crate) fn lit_from_above() -> Mesh {
    let mut mesh = base_scene(|_| {});
    let panel = octrace_format::Material { emissive: [4.0, 3.5, 3.0], ..diffuse("lamp", 0.2) };
    add(&mut mesh, floor(0.6, 2.5), panel);
    mesh
}

fn render(scene: &Scene, environment: Environment) -> (Radiance, octrace_runtime::render::effects::RayCounts) {
    let options = RenderOptions { environment, ..RenderOptions::for_scene(scene.shading()) };
    // Straight down at the floor's middle, the corners of the view past its edges.
    let cam = camera([0.0, 3.0, 0.001], [0.0, 0.0, 0.0], 32);
    render_effects(scene, &cam, &options, &|_| {})
}

/// By default a scene lit only by emitters gets the neutral sky: a surface the emitters
/// do not light shows its albedo times what the sky gives it (not black), and a ray
/// that leaves the scene sees the sky. `Environment::Off` gives the
/// strict direct light of before (black there, the dark background).
#[test]
fn a_scene_lit_only_by_emitters_gets_a_neutral_environment() {
    let scene = scene_of(&lit_from_below());
    let (auto, counts) = render(&scene, Environment::Auto);
    let (off, _) = render(&scene, Environment::Off);
    assert!(counts.get(RayKind::SoftShadow) == 0 && counts.get(RayKind::Shadow) == 0, "{counts:?}");
    // The floor faces up: it receives the sky's radiance times 1 + 2/3 of its gradient.
    let Sky { radiance, gradient } = Sky::NEUTRAL;
    let floor = 0.7 * radiance * (1.0 + gradient * 2.0 / 3.0);
    let (centre, corner) = ((16, 16), (0, 0));
    let close = |a: glam::Vec3, b: f32| (a - glam::Vec3::splat(b)).abs().max_element() < 1e-6;
    assert!(close(auto.at(centre.0, centre.1), floor), "{}", auto.at(16, 16));
    // A ray that leaves the scene looking down sees the sky below the horizon.
    let below = auto.at(corner.0, corner.1).x;
    assert!(below > radiance * (1.0 - gradient) && below < radiance, "{below}");
    assert_eq!(off.at(centre.0, centre.1), glam::Vec3::ZERO);
    assert!(off.at(corner.0, corner.1).max_element() < 0.11, "{}", off.at(0, 0));
    let black = |r: &Radiance| r.pixels.iter().filter(|p| p.max_element() == 0.0).count();
    assert_eq!(black(&auto), 0);
    assert!(black(&off) > 32 * 32 / 4, "{}", black(&off));
}

/// Scenes with punctual lights keep their lights only, and scenes without any light
/// the headlight, unless an environment is asked for: then it replaces the headlight.
#[test]
fn lit_scenes_and_headlight_scenes_keep_their_light_unless_asked() {
    let lit = scene_of(&base_scene(|m| m.lights.push(point_light([0.0, 4.0, 2.0], 30.0))));
    assert_eq!(render(&lit, Environment::Auto).0, render(&lit, Environment::Off).0);
    let headlit = scene_of(&base_scene(|_| {}));
    let (auto, _) = render(&headlit, Environment::Auto);
    assert_eq!(auto, render(&headlit, Environment::Off).0);
    // The floor beside the sphere: the environment times the albedo, no headlight.
    let (uniform, counts) = render(&headlit, Environment::Sky(Sky::uniform(0.8)));
    assert_eq!(counts.total(), counts.get(RayKind::Primary));
    assert!((uniform.at(2, 16).x - 0.7 * 0.8).abs() < 1e-6, "{}", uniform.at(2, 16));
}
