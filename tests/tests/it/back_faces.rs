//! glTF's `doubleSided` (issue 45, item 3: `doubleSided: false` was ignored, and
//! NegativeScaleTest and TextureSettingsTest showed the red "X" of their back-face
//! markers): the backs of single-sided surfaces are not seen by camera rays and cast
//! no shadow, a mirroring node's triangles keep glTF's front; and glTF camera numbers
//! (item 5: `--camera N` counted placements, so VC.gltf's camera 13 was octrace's 0).

use octrace_bake::Mesh;
use octrace_format::Material;
use octrace_runtime::render::effects::{render_effects, Environment, RenderOptions};
use octrace_tests::gltf::GltfBuffer;

use crate::effects::{add, camera, diffuse, floor, point_light, scene_of};

/// A unit quad in the plane z = 0 facing +z (counter-clockwise seen from +z).
fn quad(z: f32) -> Mesh {
    let p = |x: f32, y: f32| [x, y, z];
    Mesh::from_triangles(vec![[p(-0.5, -0.5), p(0.5, -0.5), p(0.5, 0.5)], [p(-0.5, -0.5), p(0.5, 0.5), p(-0.5, 0.5)]])
}

/// The glTF loader reads `doubleSided` (false by default, glTF's default material
/// included), and a node that mirrors keeps glTF's front: a closed cube under a
/// negative scale still faces out.
#[test]
fn gltf_sides_and_mirrored_nodes_load_as_the_spec_says() {
    let mut b = GltfBuffer::default();
    let cube = octrace_bake::procedural::cube([0.0; 3], [1.0; 3], 1);
    let positions: Vec<[f32; 3]> = cube.triangles.iter().flatten().copied().collect();
    let p = b.positions(&positions);
    let prim = |material: &str| format!(r#"{{"attributes":{{"POSITION":{p}}}{material}}}"#);
    let json = format!(
        r#"{{"asset":{{"version":"2.0"}},"scenes":[{{"nodes":[0,1,2,3]}}],
        "nodes":[{{"mesh":0}},{{"mesh":1}},{{"mesh":2,"scale":[-1,1,1],"translation":[5,0,0]}},
                 {{"mesh":3,"matrix":[1,0,0,0, 0,-2,0,0, 0,0,1,0, 0,0,9,1]}}],
        "meshes":[{{"primitives":[{}]}},{{"primitives":[{}]}},{{"primitives":[{}]}},{{"primitives":[{}]}}],
        "materials":[{{"name":"two","doubleSided":true}},{{"name":"one"}}],{}}}"#,
        prim(r#","material":0"#),
        prim(r#","material":1"#),
        prim(""),
        prim(r#","material":0"#),
        b.members()
    );
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("sides.gltf");
    std::fs::write(&path, json).unwrap();
    let mesh = Mesh::load(&path).unwrap();
    let sides: Vec<(&str, bool)> = mesh.materials.iter().map(|m| (m.name.as_str(), m.double_sided)).collect();
    assert_eq!(sides, [("two", true), ("one", false), ("default", false)]);
    let n = cube.triangles.len();
    for (k, what) in ["plain", "single-sided", "mirrored by a scale", "mirrored by a matrix"].iter().enumerate() {
        let volume = octrace_bake::topology::signed_volume(&mesh.triangles[k * n..(k + 1) * n]);
        let expected = if k == 3 { 2.0 } else { 1.0 };
        assert!((volume - expected).abs() < 1e-9, "{what}: signed volume {volume}");
    }
}

fn render(mesh: &Mesh, eye: [f64; 3], target: [f64; 3]) -> octrace_runtime::render::effects::Radiance {
    let scene = scene_of(mesh);
    let options = RenderOptions { environment: Environment::Off, ..RenderOptions::for_scene(scene.shading()) };
    render_effects(&scene, &camera(eye, target, 16), &options, &|_| {}).0
}

/// A single-sided quad is seen from the front only; a double-sided one from both
/// sides. From behind, the camera sees what lies beyond it (here a wall).
#[test]
fn camera_rays_pass_the_backs_of_single_sided_surfaces() {
    for double_sided in [true, false] {
        let mut mesh = Mesh::default();
        add(&mut mesh, quad(0.0), Material { double_sided, ..diffuse("quad", 0.8) });
        // A wall farther along -z, facing +z: behind the camera that looks at the
        // quad's back, which sees the quad or the background.
        add(&mut mesh, quad(-2.0), diffuse("wall", 0.3));
        let front = render(&mesh, [0.0, 0.0, 3.0], [0.0, 0.0, 0.0]);
        let back = render(&mesh, [0.0, 0.0, -1.0], [0.0, 0.0, 1.0]);
        // The headlight: 0.8 (0.1 + 0.85) straight on.
        assert!((front.at(8, 8).x - 0.8 * 0.95).abs() < 0.01, "{double_sided}: {}", front.at(8, 8));
        let seen = back.at(8, 8).x;
        if double_sided {
            assert!((seen - 0.8 * 0.95).abs() < 0.01, "double-sided from behind: {seen}");
        } else {
            assert!(seen < 0.1, "single-sided from behind: {seen}");
        }
    }
    // Through a single-sided quad's back to a wall beyond it.
    let mut mesh = Mesh::default();
    add(&mut mesh, quad(0.0), Material { double_sided: false, ..diffuse("quad", 0.8) });
    let mut wall = quad(2.0);
    for t in &mut wall.triangles {
        t.swap(1, 2); // facing -z, towards the camera below
    }
    add(&mut mesh, wall, diffuse("wall", 0.3));
    let seen = render(&mesh, [0.0, 0.0, -1.0], [0.0, 0.0, 1.0]).at(8, 8).x;
    assert!((seen - 0.3 * 0.95).abs() < 0.01, "the wall behind the quad's back: {seen}");
}

/// A single-sided surface casts a shadow where the light sees its front, none where
/// the light sees its back; a double-sided one casts it either way.
#[test]
fn single_sided_surfaces_cast_shadows_from_their_front_only() {
    let shadowed = |double_sided: bool, facing_light: bool| {
        let mut mesh = Mesh::default();
        add(&mut mesh, floor(3.0, 0.0), diffuse("floor", 0.7));
        let mut blocker = floor(0.5, 1.0);
        if !facing_light {
            for t in &mut blocker.triangles {
                t.swap(1, 2);
            }
        }
        add(&mut mesh, blocker, Material { double_sided, ..diffuse("blocker", 0.5) });
        mesh.lights.push(point_light([0.0, 4.0, 0.0], 20.0));
        // Looking past the blocker's edge at the floor in its shadow, (0.3, 0, 0).
        let image = render(&mesh, [2.5, 3.0, 0.0], [0.3, 0.0, 0.0]);
        let lit = render(&Mesh { lights: mesh.lights.clone(), ..floor_only() }, [2.5, 3.0, 0.0], [0.3, 0.0, 0.0]);
        // The floor just under the blocker's edge is in its shadow, or lit as without it.
        let (got, open) = (image.at(8, 8).x, lit.at(8, 8).x);
        assert!(open > 0.05, "the open floor is lit: {open}");
        got < 0.5 * open
    };
    assert!(shadowed(true, true) && shadowed(true, false), "double-sided: a shadow either way");
    assert!(shadowed(false, true), "single-sided, front towards the light: a shadow");
    assert!(!shadowed(false, false), "single-sided, back towards the light: no shadow");
}

fn floor_only() -> Mesh {
    let mut mesh = Mesh::default();
    add(&mut mesh, floor(3.0, 0.0), diffuse("floor", 0.7));
    mesh
}

/// `render --camera N` and `inspect` number a glTF's cameras by their index in the
/// file, whatever order its nodes place them in.
#[test]
fn cameras_keep_their_gltf_numbers() {
    let mut b = GltfBuffer::default();
    let p = b.positions(&[[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);
    let json = format!(
        r#"{{"asset":{{"version":"2.0"}},"scenes":[{{"nodes":[0,1,2]}}],
        "nodes":[{{"mesh":0}},{{"camera":2,"translation":[0,0,5]}},{{"camera":0,"translation":[0,0,9]}}],
        "cameras":[{{"name":"far","type":"perspective","perspective":{{"yfov":0.5,"znear":0.1}}}},
                   {{"name":"unplaced","type":"perspective","perspective":{{"yfov":0.5,"znear":0.1}}}},
                   {{"name":"near","type":"perspective","perspective":{{"yfov":0.5,"znear":0.1}}}}],
        "meshes":[{{"primitives":[{{"attributes":{{"POSITION":{p}}}}}]}}],{}}}"#,
        b.members()
    );
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("cams.gltf");
    std::fs::write(&path, json).unwrap();
    let mesh = Mesh::load(&path).unwrap();
    let numbered: Vec<(u32, &str, f32)> =
        mesh.cameras.iter().enumerate().map(|(i, c)| (c.number(i), c.name.as_str(), c.position[2])).collect();
    assert_eq!(numbered, [(2, "near", 5.0), (0, "far", 9.0)]);
}

/// In a world, a mirroring placement keeps its scene's front (as glTF's mirrored nodes
/// do): a single-sided quad placed by `x -> -x` (its corners then run the other way
/// round) is still seen from its front and passed from its back, as placed plainly.
#[test]
fn a_mirrored_instance_keeps_its_front_in_a_world() {
    use octrace_runtime::render::effects::render_effects_world;
    use octrace_runtime::world::{Transform, World};
    let mut mesh = Mesh::default();
    add(&mut mesh, quad(0.0), Material { double_sided: false, ..diffuse("quad", 0.8) });
    let scene = std::sync::Arc::new(scene_of(&mesh));
    let options = RenderOptions { environment: Environment::Off, ..RenderOptions::for_scene(scene.shading()) };
    for placement in [Transform::IDENTITY, Transform::scaling([-1.0, 1.0, 1.0])] {
        let mut world = World::new();
        world.add(&scene, placement).unwrap();
        world.commit();
        let seen = |eye: [f64; 3], target: [f64; 3]| {
            render_effects_world(&world, &camera(eye, target, 16), &options, &|_| {}).expect("renders").0.at(8, 8).x
        };
        let mirrored = placement != Transform::IDENTITY;
        let front = seen([0.0, 0.0, 3.0], [0.0, 0.0, 0.0]);
        assert!((front - 0.8 * 0.95).abs() < 0.01, "mirrored {mirrored}: the front {front}");
        let back = seen([0.0, 0.0, -1.0], [0.0, 0.0, 1.0]);
        assert!(back < 0.1, "mirrored {mirrored}: the back {back}");
    }
}
