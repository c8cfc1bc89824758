//! Tangents for normal maps (issue 34): a glTF's `TANGENT` is read, MikkTSpace's are
//! made where a normal-mapped primitive has none, and the renderer turns the normal
//! map's texels in the frame they give.

use glam::{DVec3, Vec3};
use octrace_bake::Mesh;
use octrace_runtime::render::effects::EffectSet;

use crate::effects::{camera, render, scene_of};
use crate::materials::bump_scene;

/// A 1 x 1 PNG (a flat normal), for the normal texture of the glTF below.
fn flat_normal_png() -> Vec<u8> {
    let mut out = Vec::new();
    let mut encoder = png::Encoder::new(&mut out, 1, 1);
    encoder.set_color(png::ColorType::Rgb);
    encoder.write_header().unwrap().write_image_data(&[128, 128, 255]).unwrap();
    out
}

/// An embedded glTF of one normal-mapped primitive: `positions`, `normals`, `uvs`,
/// optional `tangents`, triangles `indices`, under a node of `matrix` (column-major).
fn normal_mapped_gltf(
    positions: &[[f32; 3]],
    normals: &[[f32; 3]],
    uvs: &[[f32; 2]],
    tangents: Option<&[[f32; 4]]>,
    indices: &[u16],
    matrix: [f32; 16],
) -> String {
    let mut buf = Vec::new();
    let mut views = Vec::new();
    let mut push = |bytes: Vec<u8>| {
        views.push(format!(r#"{{"buffer":0,"byteOffset":{},"byteLength":{}}}"#, buf.len(), bytes.len()));
        buf.extend(bytes);
        while buf.len() % 4 != 0 {
            buf.push(0);
        }
    };
    let floats = |v: &[f32]| v.iter().flat_map(|c| c.to_le_bytes()).collect::<Vec<u8>>();
    push(floats(positions.as_flattened()));
    push(floats(normals.as_flattened()));
    push(floats(uvs.as_flattened()));
    push(indices.iter().flat_map(|i| i.to_le_bytes()).collect());
    let n = positions.len();
    let mut accessors = vec![
        format!(r#"{{"bufferView":0,"componentType":5126,"count":{n},"type":"VEC3","min":[-9,-9,-9],"max":[9,9,9]}}"#),
        format!(r#"{{"bufferView":1,"componentType":5126,"count":{n},"type":"VEC3"}}"#),
        format!(r#"{{"bufferView":2,"componentType":5126,"count":{n},"type":"VEC2"}}"#),
        format!(r#"{{"bufferView":3,"componentType":5123,"count":{},"type":"SCALAR"}}"#, indices.len()),
    ];
    let mut attributes = r#""POSITION":0,"NORMAL":1,"TEXCOORD_0":2"#.to_string();
    if let Some(t) = tangents {
        push(floats(t.as_flattened()));
        accessors.push(format!(r#"{{"bufferView":4,"componentType":5126,"count":{n},"type":"VEC4"}}"#));
        attributes.push_str(r#","TANGENT":4"#);
    }
    let png = octrace_tests::base64(&flat_normal_png());
    let matrix = matrix.map(|c| c.to_string()).join(",");
    format!(
        r#"{{"asset":{{"version":"2.0"}},"scene":0,"scenes":[{{"nodes":[0]}}],"nodes":[{{"mesh":0,"matrix":[{matrix}]}}],
        "meshes":[{{"primitives":[{{"attributes":{{{attributes}}},"indices":3,"material":0}}]}}],
        "materials":[{{"name":"bumpy","normalTexture":{{"index":0}}}}],
        "textures":[{{"source":0}}],"images":[{{"uri":"data:image/png;base64,{png}"}}],
        "buffers":[{{"byteLength":{len},"uri":"data:application/octet-stream;base64,{b64}"}}],
        "bufferViews":[{views}],"accessors":[{accessors}]}}"#,
        len = buf.len(),
        b64 = octrace_tests::base64(&buf),
        views = views.join(","),
        accessors = accessors.join(","),
    )
}

fn load(gltf: &str) -> Mesh {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("t.gltf");
    std::fs::write(&path, gltf).unwrap();
    let mesh = Mesh::load(&path).unwrap();
    assert!(mesh.warnings.is_empty(), "{:?}", mesh.warnings);
    mesh
}

const IDENTITY: [f32; 16] = [1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0];

/// A primitive's positions, normals, texture coordinates and indices.
type Primitive = (Vec<[f32; 3]>, Vec<[f32; 3]>, Vec<[f32; 2]>, Vec<u16>);

/// A quad facing +z, `u` growing with x and `v` down the image (with -y), as glTF
/// lays out an image on it.
fn quad() -> Primitive {
    let p = vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]];
    let uv = vec![[0.0, 1.0], [1.0, 1.0], [1.0, 0.0], [0.0, 0.0]];
    (p, vec![[0.0, 0.0, 1.0]; 4], uv, vec![0, 1, 2, 0, 2, 3])
}

/// Without `TANGENT`, a normal-mapped primitive gets MikkTSpace's tangents: on a flat
/// quad, +x (where `u` grows) with the bitangent `w (n x t)` = +y, up the image (glTF's
/// green); on a bent strip whose coordinates bend too, one tangent a vertex (every
/// corner of a vertex the same, bit for bit: no seam between its triangles, where each
/// triangle's own tangent differs), each orthogonal to the normal. A file's `TANGENT`
/// is read as it is, through the node's transform, its sign reversed by a mirroring
/// node. A primitive without a normal texture gets none.
#[test]
fn tangents_come_from_the_file_else_from_mikktspace() {
    let (p, n, uv, idx) = quad();
    let mesh = load(&normal_mapped_gltf(&p, &n, &uv, None, &idx, IDENTITY));
    assert_eq!(mesh.tangents.len(), 2);
    for corner in mesh.tangents.iter().flatten() {
        assert!((Vec3::from_slice(corner) - Vec3::X).length() < 1e-6 && corner[3] == 1.0, "{corner:?}");
    }

    // A strip bent around the y axis (radial normals), v bent along it (each
    // triangle's own direction of growing u tips another way).
    let (columns, mut p, mut n, mut uv, mut idx) = (8u16, vec![], vec![], vec![], vec![]);
    for row in 0..2u16 {
        for c in 0..=columns {
            let a = f32::from(c) * 0.2;
            p.push([a.sin(), f32::from(row), a.cos()]);
            n.push([a.sin(), 0.0, a.cos()]);
            uv.push([f32::from(c) / 8.0, 1.0 - f32::from(row) + 0.02 * f32::from(c * c)]);
        }
    }
    for c in 0..columns {
        let (a, b, d, e) = (c, c + 1, c + columns + 1, c + columns + 2);
        idx.extend([a, b, e, a, e, d]);
    }
    let mesh = load(&normal_mapped_gltf(&p, &n, &uv, None, &idx, IDENTITY));
    let mut seen: std::collections::HashMap<[u32; 3], [f32; 4]> = Default::default();
    let (mut shared, mut face_differs) = (0, 0);
    for (k, tri) in mesh.triangles.iter().enumerate() {
        let [a, b, c] = tri.map(Vec3::from);
        for (i, t) in mesh.tangents[k].iter().enumerate() {
            let normal = Vec3::from(mesh.normals[k][i]);
            assert!(t[3] == 1.0 && Vec3::from_slice(t).dot(normal).abs() < 1e-5, "{t:?} against {normal}");
            if let Some(before) = seen.insert(tri[i].map(f32::to_bits), *t) {
                assert_eq!(before.map(f32::to_bits), t.map(f32::to_bits), "one tangent a vertex");
                shared += 1;
            }
        }
        // The triangle's own tangent (increasing u, made orthogonal to the normal at
        // its first corner), as the renderer takes without tangents.
        let [t0, t1, t2] = mesh.uvs[k];
        let (e1, e2) = (b - a, c - a);
        let (du1, dv1, du2, dv2) = (t1[0] - t0[0], t1[1] - t0[1], t2[0] - t0[0], t2[1] - t0[1]);
        let own = (e1 * dv2 - e2 * dv1) * (du1 * dv2 - du2 * dv1).signum();
        let normal = Vec3::from(mesh.normals[k][0]);
        let own = (own - normal * normal.dot(own)).normalize();
        if (own - Vec3::from_slice(&mesh.tangents[k][0])).length() > 1e-3 {
            face_differs += 1;
        }
    }
    assert!(shared > 20 && face_differs > 4, "{shared} shared corners, {face_differs} triangles' own tangents differ");

    // The file's tangents: +y with sign -1, under a node that mirrors x and turns y
    // into z (a rotation about x by 90 degrees, then x negated).
    let (p, n, uv, idx) = quad();
    let tangents = [[0.0, 1.0, 0.0, -1.0]; 4];
    let mirror = [-1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0];
    let mesh = load(&normal_mapped_gltf(&p, &n, &uv, Some(&tangents), &idx, mirror));
    for corner in mesh.tangents.iter().flatten() {
        assert!((Vec3::from_slice(corner) - Vec3::Z).length() < 1e-6 && corner[3] == 1.0, "{corner:?}");
    }
    let plain = load(&normal_mapped_gltf(&p, &n, &uv, Some(&tangents), &idx, IDENTITY));
    assert!(plain.tangents.iter().flatten().all(|c| c == &[0.0, 1.0, 0.0, -1.0]));

    // No normal texture: no tangents kept.
    let gltf =
        normal_mapped_gltf(&p, &n, &uv, Some(&tangents), &idx, IDENTITY).replace(r#","normalTexture":{"index":0}"#, "");
    assert!(load(&gltf).tangents.is_empty());
}

/// The renderer turns a normal map's texels in the tangent frame the scene gives: the
/// floor of `bump_scene` (a texel tipping the normal towards the tangent on its left
/// half) with tangents +z, -x (towards and away from nothing, then against the light)
/// and signs 1 and -1: each pixel is Lambert's with the normal
/// `normalize(t (2r - 1) + w (n x t) (2g - 1) + n (2b - 1))` in f64, to 1e-5. Before,
/// the tangents were ignored (the light-ward +x of the triangle's coordinates).
#[test]
fn a_scenes_tangents_turn_the_normal_map_as_they_say() {
    let l = DVec3::new(0.6, 0.8, 0.0);
    let mut lefts = vec![];
    for (tangent, w) in [(DVec3::Z, 1.0), (DVec3::NEG_X, 1.0), (DVec3::X, -1.0)] {
        let mut mesh = bump_scene(1.0);
        // Left half tips by texel (218, 128, 218); here the green is tilted too.
        mesh.texels[0] = u32::from_le_bytes([218, 200, 218, 255]);
        let t = [tangent.x as f32, tangent.y as f32, tangent.z as f32, w as f32];
        mesh.tangents = vec![[t; 3]; mesh.triangles.len()];
        let scene = scene_of(&mesh);
        let cam = camera([0.0, 5.0, 3.0], [0.0, 0.0, 0.0], 96);
        let (image, _) = render(&scene, &cam, EffectSet::of(scene.shading()));
        let expected = |texel: [u8; 3]| {
            let c = texel.map(|c| f64::from(c) / 255.0 * 2.0 - 1.0);
            let b = DVec3::Y.cross(tangent) * w;
            let n = (tangent * c[0] + b * c[1] + DVec3::Y * c[2]).normalize();
            0.7 / std::f64::consts::PI * 2.0 * n.dot(l).max(0.0)
        };
        let left = expected([218, 200, 218]);
        let mut seen = 0;
        for y in 0..image.height {
            for x in 0..image.width {
                let ray = cam.ray(x, y);
                let Some(hit) = scene.intersect(&ray) else { continue };
                if (ray.origin + hit.t * ray.dir).x > -0.05 {
                    continue;
                }
                let got = image.at(x, y).x as f64;
                assert!((got - left).abs() < 1e-5 * left.max(1.0), "{tangent} {w}: ({x}, {y}) {got} against {left}");
                seen += 1;
            }
        }
        assert!(seen > 500, "{seen}");
        lefts.push(left);
    }
    // The three frames light the left half differently.
    assert!((lefts[0] - lefts[1]).abs() > 0.05 && (lefts[1] - lefts[2]).abs() > 0.05, "{lefts:?}");
}
