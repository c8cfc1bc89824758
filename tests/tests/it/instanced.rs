//! Instanced files (issue 51): a glTF that places a mesh many times bakes the mesh
//! once and its placements as instances, opens as a world, and answers as the same
//! file baked flat (each placement's triangles transformed in `f64`, then rounded).

use std::path::Path;

use octrace_bake::procedural::SplitMix;
use octrace_bake::{bake, BuildParams, InstancedMesh, LoadOptions, Loaded, Mesh};
use octrace_format::instanced::{InstanceRecord, InstancedFile};
use octrace_runtime::glam::Vec3;
use octrace_runtime::world::{Transform, World};
use octrace_runtime::{Ray, Scene};

/// Loads `path` with its repeated meshes kept once.
fn instanced(path: &Path) -> InstancedMesh {
    match Mesh::load_instanced(path, &LoadOptions::default()).expect("loads") {
        Loaded::Instanced(i) => i,
        Loaded::One(_) => panic!("{}: loaded as one mesh", path.display()),
    }
}

/// Bakes each mesh of `i` and writes them with their placements to `path`.
fn write_instanced(i: &InstancedMesh, path: &Path) {
    let files: Vec<Vec<u8>> = i
        .meshes
        .iter()
        .map(|m| bake(m, &BuildParams::auto()).expect("bakes").to_file_bytes(0).expect("serializes"))
        .collect();
    let instances: Vec<InstanceRecord> =
        i.placements.iter().map(|p| InstanceRecord { scene: p.mesh, rows: p.rows, map: p.map }).collect();
    let table = InstancedFile { scenes: Vec::new(), maps: i.maps.clone(), instances };
    table.write(path, &files).expect("writes");
}

/// A MetalRoughSpheresNoTextures-like GLB (98 meshes sharing one sphere's accessors,
/// each its own material; one placement mirrored, one turned and scaled; a floor and
/// a light placed once) bakes to one scene of the sphere and one of the floor, within
/// 20 times the GLB (the flat bake: 459 times for the Khronos file), and each
/// placement draws its own material.
#[test]
fn a_mesh_placed_many_times_bakes_once_within_twenty_times_its_glb() {
    let dir = tempfile::tempdir().unwrap();
    let glb = dir.path().join("spheres.glb");
    let bytes = octrace_tests::gltf::placed_spheres(98, true);
    std::fs::write(&glb, &bytes).unwrap();
    let i = instanced(&glb);
    // The floor (with the light), the sphere, and the sphere mirrored for the
    // placement that mirrors (so that glTF's front stays the stored winding's).
    assert_eq!(i.meshes.len(), 3);
    assert_eq!((i.meshes[0].triangles.len(), i.meshes[0].lights.len(), i.meshes[0].cameras.len()), (2, 1, 1));
    assert_eq!((i.meshes[1].triangles.len(), i.meshes[2].triangles.len()), (10_600, 10_600));
    assert_eq!(i.placements.len(), 99);
    assert_eq!((i.stored_triangles(), i.placed_triangles()), (21_202, 98 * 10_600 + 2));
    // The floor as it is; sphere k draws material k of the sphere's scene, which
    // holds every material its placements draw (named as in the file) and no other,
    // the first placement's first; the mirrored copy's scene, its one placement's
    // material alone. Each map is stored once (the first placements draw their own).
    assert_eq!((i.placements[0].mesh, i.placements[0].map), (0, None));
    assert_eq!((i.meshes[1].materials.len(), i.meshes[2].materials.len()), (97, 1));
    assert_eq!(i.maps.len(), 96);
    for (k, p) in i.placements[1..].iter().enumerate() {
        assert_eq!(p.mesh, if k == 1 { 2 } else { 1 }, "placement {k}");
        let sphere = &i.meshes[p.mesh as usize];
        let own = sphere.material_ids[0] as usize;
        assert_eq!(own, 0);
        let map = p.map.map_or(&[][..], |m| i.maps[m as usize].as_slice());
        let drawn = map.get(own).map_or(own, |&m| m as usize);
        assert_eq!(sphere.materials[drawn].name, format!("sphere {k}"), "placement {k}");
    }
    let oct = dir.path().join("spheres.oct");
    write_instanced(&i, &oct);
    let size = std::fs::metadata(&oct).unwrap().len();
    assert!(size <= 20 * bytes.len() as u64, "{size} bytes for a GLB of {}", bytes.len());
    // An ordinary scene's reader refuses it, saying what to do.
    let err = Scene::open(&oct).unwrap_err().to_string();
    assert!(err.contains("an instanced file") && err.contains("World::open"), "{err}");
    let world = World::open(&oct).expect("opens");
    assert_eq!((world.len(), world.scenes().len()), (99, 3));
}

/// The instanced file answers as the flat bake of the same GLB: nearest hits (the
/// same material, the distance within the rounding of the carried ray), occlusion,
/// crossing counts, and each hit's material; renders alike.
#[test]
fn an_instanced_file_answers_as_its_flat_bake() {
    let dir = tempfile::tempdir().unwrap();
    let glb = dir.path().join("spheres.glb");
    std::fs::write(&glb, octrace_tests::gltf::placed_spheres(40, true)).unwrap();
    let oct = dir.path().join("spheres.oct");
    write_instanced(&instanced(&glb), &oct);
    let world = World::open(&oct).expect("opens");
    let flat = Scene::from_baked(bake(&Mesh::load(&glb).unwrap(), &BuildParams::auto()).unwrap()).unwrap();
    let (lo, hi) = world.bounds().expect("placed");
    let (lo, hi) = (Vec3::from(lo), Vec3::from(hi));
    let mut rng = SplitMix(51);
    let (mut hits, mut crossings) = (0, 0);
    for n in 0..20_000 {
        let mut u = || rng.unit();
        let pick = |u: &mut dyn FnMut() -> f32| lo + (hi - lo) * Vec3::new(u(), u(), u());
        let origin = (pick(&mut u) - (lo + hi) / 2.0) * 1.4 + (lo + hi) / 2.0;
        let ray = Ray::new(origin, pick(&mut u) - origin);
        let (w, f) = (world.intersect(&ray), flat.intersect(&ray));
        assert_eq!(w.is_some(), f.is_some(), "ray {n} {ray:?}: {w:?} against {f:?}");
        assert_eq!(world.occluded(&ray), flat.occluded(&ray), "ray {n}");
        let (wc, fc) = (world.count_crossings(&ray), flat.count_crossings_batch(&[ray])[0]);
        assert_eq!((wc.total, wc.entries), (fc.total, fc.entries), "ray {n}");
        crossings += fc.total;
        let (Some(w), Some(f)) = (w, f) else { continue };
        hits += 1;
        // A few f32 ulps of the coordinates reached (up to about 40 here), over the
        // direction's length: the carried ray's rounding and the flat bake's.
        let reach = f64::from(origin.abs().max_element() + (ray.dir * f.t).abs().max_element());
        let bound = 16.0 * f64::from(f32::EPSILON) * reach / f64::from(ray.dir.length());
        assert!(f64::from((w.hit.t - f.t).abs()) <= bound, "ray {n}: t {} against {} (bound {bound})", w.hit.t, f.t);
        let name = |m: Option<u32>, s: &Scene| m.map(|m| s.shading().materials[m as usize].name.clone());
        let placed = world.surface(&w).expect("live");
        let scene: &Scene = world.instance(w.instance).expect("live").0;
        assert_eq!(name(placed.material, scene), name(flat.surface(&f).material, &flat), "ray {n}");
    }
    assert!(hits > 2_000 && crossings > 4_000, "{hits} hits, {crossings} crossings");
    // The renders: each sphere its own material (a map ignored would draw sphere 0's
    // everywhere: rough, not metallic).
    use octrace_runtime::raysets::Camera;
    use octrace_runtime::render::effects::{render_effects, render_effects_world, RenderOptions};
    let options = RenderOptions::for_scene(flat.shading());
    let v = |p: [f64; 3]| octrace_runtime::glam::DVec3::from_array(p);
    let camera = Camera::look_at(v([8.0, 2.5, 10.0]), v([8.0, 2.5, 0.0]), 50.0, 128, 64);
    let (one, _) = render_effects(&flat, &camera, &options, &|_| {});
    let (placed, _) = render_effects_world(&world, &camera, &options, &|_| {}).expect("renders");
    let diff = placed.to_image().mean_abs_diff(&one.to_image()).expect("same size");
    assert!(diff < 0.5, "mean difference {diff}");
    let mut plain = World::new();
    for id in 0..world.len() as u32 {
        let (scene, t) = world.instance(id).expect("live");
        plain.add(scene, t).expect("placed");
    }
    plain.commit();
    let (unmapped, _) = render_effects_world(&plain, &camera, &options, &|_| {}).expect("renders");
    let diff = unmapped.to_image().mean_abs_diff(&one.to_image()).expect("same size");
    assert!(diff > 1.5, "without the maps, a difference of {diff} only");
}

/// Where a mesh is placed a few times with few triangles, or where nothing repeats,
/// the scene loads as one mesh; with lights and no mesh placed once, too (with the
/// reason in its warning).
#[test]
fn small_repeats_and_lights_without_a_mesh_placed_once_load_as_one_mesh() {
    let dir = tempfile::tempdir().unwrap();
    let load = |bytes: Vec<u8>| {
        let path = dir.path().join("x.glb");
        std::fs::write(&path, bytes).unwrap();
        Mesh::load_instanced(&path, &LoadOptions::default()).expect("loads")
    };
    // Twice a 10,600-triangle sphere, no floor: instanced (the copy adds 10,600).
    assert!(matches!(load(octrace_tests::gltf::placed_spheres(2, false)), Loaded::Instanced(_)));
    // Once: one mesh, no warning.
    match load(octrace_tests::gltf::placed_spheres(1, false)) {
        Loaded::One(m) => assert!(m.warnings.is_empty(), "{:?}", m.warnings),
        Loaded::Instanced(_) => panic!("one placement"),
    }
    // SimpleMeshes places a one-triangle mesh twice: one mesh.
    let simple = octrace_tests::data("gltf").join("SimpleMeshes.gltf");
    match Mesh::load_instanced(&simple, &LoadOptions::default()).unwrap() {
        Loaded::One(m) => assert_eq!(m.triangles.len(), 2),
        Loaded::Instanced(_) => panic!("a triangle placed twice is not worth an instance"),
    }
}

/// Hostile instanced files are refused with what is wrong, never a panic: cut
/// short, a table byte changed, an instance naming a scene that is not there, a
/// material map naming a material its scene lacks, a singular transform, scenes out
/// of the file.
#[test]
fn broken_instanced_files_are_refused_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("w.oct");
    let scene = octrace_format::testing::single_leaf_scene().to_file_bytes(0).unwrap();
    let identity = Transform::IDENTITY.rows;
    let record = |scene: u32, rows, map: Option<u32>| InstanceRecord { scene, rows, map };
    let table =
        |maps: Vec<Vec<u32>>, instances: Vec<InstanceRecord>| InstancedFile { scenes: Vec::new(), maps, instances };
    table(vec![], vec![record(0, identity, None)]).write(&path, std::slice::from_ref(&scene)).unwrap();
    let good = std::fs::read(&path).unwrap();
    assert_eq!(World::open(&path).expect("opens").len(), 1);
    let refused = |bytes: &[u8], says: &str| {
        std::fs::write(&path, bytes).unwrap();
        let err = World::open(&path).expect_err("refused").to_string();
        assert!(err.contains(says), "{err} (expected '{says}')");
        // SAFETY: the file is not changed while the world is alive.
        let mapped = unsafe { World::map(&path) }.expect_err("refused").to_string();
        assert!(mapped.contains(says), "{mapped}");
    };
    refused(&good[..good.len() - 1], "truncated");
    refused(&good[..40], "truncated");
    let mut flipped = good.clone();
    flipped[64 + 20] ^= 1;
    refused(&flipped, "checksum mismatch in instance table");
    let mut version = good.clone();
    version[8] = 9;
    refused(&version, "unsupported format version 9");
    // Instances the writer refuses: a scene or a map that is not there.
    let one = std::slice::from_ref(&scene);
    assert!(table(vec![], vec![record(1, identity, None)]).write(&path, one).is_err());
    assert!(table(vec![], vec![record(0, identity, Some(0))]).write(&path, one).is_err());
    let write = |t: InstancedFile| {
        t.write(&path, one).unwrap();
        std::fs::read(&path).unwrap()
    };
    refused(
        &write(table(vec![vec![3]], vec![record(0, identity, Some(0))])),
        "material map entry 0 names material 3; the scene has 0",
    );
    let flat = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0]];
    refused(&write(table(vec![], vec![record(0, flat, None)])), "singular");
    // The scene's offset moved past the file's end (checksum recomputed).
    let mut out = good.clone();
    let table_len = u64::from_le_bytes(out[32..40].try_into().unwrap()) as usize;
    out[64..72].copy_from_slice(&(1u64 << 40).to_le_bytes());
    let sum = xxhash_rust::xxh3::xxh3_64(&out[64..64 + table_len]);
    out[40..48].copy_from_slice(&sum.to_le_bytes());
    refused(&out, "past the file's");
    // A scene byte changed: the scene's own checksum names it.
    let mut scene_byte = good.clone();
    let at = scene_byte.len() - 8;
    scene_byte[at] ^= 0x40;
    refused(&scene_byte, "checksum mismatch");
    // An ordinary scene is not an instanced file.
    refused(&scene, "one baked scene, not an instanced file");
    refused(b"not a file of ours at all", "bad magic");
    // Random damage: an error or a world, never a panic.
    let mut rng = SplitMix(7);
    for _ in 0..300 {
        let mut bytes = good.clone();
        for _ in 0..1 + rng.next_u64() % 3 {
            let at = (rng.next_u64() % bytes.len() as u64) as usize;
            bytes[at] = rng.next_u64() as u8;
        }
        std::fs::write(&path, &bytes).unwrap();
        let _ = World::open(&path).map(|w| w.len());
    }
}

/// `EXT_mesh_gpu_instancing`'s instances of a mesh worth keeping once are instances
/// of one scene: each its translation, rotation and scale, the node's transform after
/// them, as the flat load places them (a mirroring one through the mirrored copy).
#[test]
fn gpu_instancing_bakes_each_instance_as_an_instance() {
    let mut b = octrace_tests::gltf::GltfBuffer::default();
    // A strip of 3,000 triangles.
    let n = 1_500;
    let positions: Vec<[f32; 3]> =
        (0..=n).flat_map(|k| [[k as f32 * 0.01, 0.0, 0.0], [k as f32 * 0.01, 1.0, 0.3]]).collect();
    let indices: Vec<u16> =
        (0..n as u16).flat_map(|k| [2 * k, 2 * k + 2, 2 * k + 1, 2 * k + 1, 2 * k + 2, 2 * k + 3]).collect();
    let p = b.positions(&positions);
    let i = b.indices(&indices);
    let t = b.vec3(&[[0.0; 3], [20.0, 0.0, 0.0], [0.0, 20.0, 0.0]]);
    let h = std::f32::consts::FRAC_1_SQRT_2;
    let r = b.vec4(&[[0.0, 0.0, 0.0, 1.0], [0.0, 0.0, h, h], [0.0, 0.0, 0.0, 1.0]]);
    let s = b.vec3(&[[1.0; 3], [1.0; 3], [-2.0, 2.0, 2.0]]);
    let json = format!(
        r#"{{"asset":{{"version":"2.0"}},"extensionsUsed":["EXT_mesh_gpu_instancing"],
        "scenes":[{{"nodes":[0]}}],
        "nodes":[{{"mesh":0,"translation":[0,0,5],
            "extensions":{{"EXT_mesh_gpu_instancing":{{"attributes":{{"TRANSLATION":{t},"ROTATION":{r},"SCALE":{s}}}}}}}}}],
        "meshes":[{{"primitives":[{{"attributes":{{"POSITION":{p}}},"indices":{i}}}]}}],{}}}"#,
        b.members_glb()
    );
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("strips.glb");
    std::fs::write(&path, b.glb(&json)).unwrap();
    let i = instanced(&path);
    assert_eq!((i.meshes.len(), i.placements.len()), (2, 3), "the strip, and its mirrored copy");
    assert!(i.maps.is_empty() && i.placements.iter().all(|p| p.map.is_none()), "one material drawn");
    // Each placed triangle where the flat load puts it (within the rounding of f32).
    let flat = Mesh::load(&path).unwrap();
    let mut k = 0;
    for p in &i.placements {
        let t = Transform::from_rows(p.rows);
        for tri in &i.meshes[p.mesh as usize].triangles {
            let placed = tri.map(|v| t.point(v.map(f64::from)));
            let want = flat.triangles[k];
            k += 1;
            for (a, b) in placed.iter().zip(&want) {
                assert!(
                    (0..3).all(|c| (a[c] - f64::from(b[c])).abs() < 1e-5),
                    "triangle {k}: {placed:?} against {want:?}"
                );
            }
        }
    }
    assert_eq!(k, flat.triangles.len());
}
