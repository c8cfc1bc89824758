//! Per-triangle attribute arrays whatever order a glTF's primitives with and without
//! an attribute come in (issue 45, item 1: a normal-mapped primitive followed by one
//! without a normal map, or a material reading a second texture-coordinate set followed
//! by one that does not, made valid files unbakeable).

use octrace_bake::{bake, BuildParams, Mesh};
use octrace_tests::gltf::{png_data_uri, GltfBuffer};

/// What a primitive may carry that fills a per-triangle array of the mesh.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Attribute {
    /// `NORMAL` (the mesh's `normals`).
    Normals,
    /// `TEXCOORD_0` (the mesh's `uvs`).
    TexCoords,
    /// `COLOR_0` (the mesh's `colors`).
    Colors,
    /// A material with a normal texture (the mesh's `tangents`).
    NormalMap,
    /// A material whose emissive texture reads `TEXCOORD_1` (a second channel).
    SecondSet,
}

const ATTRIBUTES: [Attribute; 5] =
    [Attribute::Normals, Attribute::TexCoords, Attribute::Colors, Attribute::NormalMap, Attribute::SecondSet];

/// A normal that is not the quads' face normal (+z), so a padded entry shows.
const TILTED: [f32; 3] = [0.6, 0.0, 0.8];

/// A glTF of one mesh whose primitives are unit quads facing +z, one a step along x,
/// primitive `k` carrying `attribute` where `with[k]`. Materials: 0 plain, 1 with a
/// normal texture, 2 with base colour and emissive textures reading sets 0 and 1.
fn document(attribute: Attribute, with: &[bool]) -> String {
    let mut b = GltfBuffer::default();
    let mut primitives = Vec::new();
    for (k, &has) in with.iter().enumerate() {
        let x = k as f32 * 2.0;
        let p = b.positions(&[[x, 0.0, 0.0], [x + 1.0, 0.0, 0.0], [x + 1.0, 1.0, 0.0], [x, 1.0, 0.0]]);
        let i = b.indices(&[0, 1, 2, 0, 2, 3]);
        let uv = [[0.0, 1.0], [1.0, 1.0], [1.0, 0.0], [0.0, 0.0]];
        let mut attributes = vec![format!(r#""POSITION":{p}"#)];
        let mut material = 0;
        if has {
            match attribute {
                Attribute::Normals => attributes.push(format!(r#""NORMAL":{}"#, b.vec3(&[TILTED; 4]))),
                Attribute::TexCoords => attributes.push(format!(r#""TEXCOORD_0":{}"#, b.vec2(&uv))),
                Attribute::Colors => attributes.push(format!(r#""COLOR_0":{}"#, b.vec4(&[[1.0, 0.0, 0.0, 1.0]; 4]))),
                Attribute::NormalMap => {
                    attributes.push(format!(r#""NORMAL":{}"#, b.vec3(&[[0.0, 0.0, 1.0]; 4])));
                    attributes.push(format!(r#""TEXCOORD_0":{}"#, b.vec2(&uv)));
                    material = 1;
                }
                Attribute::SecondSet => {
                    attributes.push(format!(r#""TEXCOORD_0":{}"#, b.vec2(&uv)));
                    attributes.push(format!(r#""TEXCOORD_1":{}"#, b.vec2(&uv.map(|[u, v]| [v, u]))));
                    material = 2;
                }
            }
        }
        primitives
            .push(format!(r#"{{"attributes":{{{}}},"indices":{i},"material":{material}}}"#, attributes.join(",")));
    }
    let flat_normal = png_data_uri(1, 1, &[128, 128, 255, 255]);
    let white = png_data_uri(1, 1, &[255, 255, 255, 255]);
    format!(
        r#"{{"asset":{{"version":"2.0"}},"scene":0,"scenes":[{{"nodes":[0]}}],"nodes":[{{"mesh":0}}],
        "meshes":[{{"primitives":[{}]}}],
        "materials":[{{"name":"plain"}},{{"name":"bumpy","normalTexture":{{"index":0}}}},
            {{"name":"two sets","pbrMetallicRoughness":{{"baseColorTexture":{{"index":1}}}},
              "emissiveFactor":[1,1,1],"emissiveTexture":{{"index":1,"texCoord":1}}}}],
        "textures":[{{"source":0}},{{"source":1}}],"images":[{{"uri":"{flat_normal}"}},{{"uri":"{white}"}}],
        {}}}"#,
        primitives.join(","),
        b.members()
    )
}

/// Every per-triangle array of a mesh is empty or one entry a triangle: the loader's
/// rule, and the bake's.
fn assert_whole(mesh: &Mesh, case: &str) {
    let n = mesh.triangles.len();
    let lengths = [
        ("material ids", mesh.material_ids.len()),
        ("normals", mesh.normals.len()),
        ("uvs", mesh.uvs.len()),
        ("colors", mesh.colors.len()),
        ("tangents", mesh.tangents.len()),
    ]
    .into_iter()
    .chain(mesh.more_uvs.iter().map(|c| ("more uvs", c.len())));
    for (what, len) in lengths {
        assert!(len == 0 || len == n, "{case}: {what} has {len} entries for {n} triangles");
    }
}

/// For every attribute and every order of three primitives that have it and lack it,
/// the file loads and bakes, every array is whole, the triangles of the primitives
/// that have the attribute carry it, and the others carry what a triangle without it
/// gets (the face normal, zero coordinates, white, no tangent).
#[test]
fn every_order_of_primitives_with_and_without_an_attribute_bakes() {
    let dir = tempfile::tempdir().unwrap();
    for attribute in ATTRIBUTES {
        for pattern in 0..8u32 {
            let with: Vec<bool> = (0..3).map(|k| pattern >> k & 1 == 1).collect();
            let case = format!("{attribute:?} on primitives {with:?}");
            let path = dir.path().join("t.gltf");
            std::fs::write(&path, document(attribute, &with)).unwrap();
            let mesh = Mesh::load(&path).unwrap_or_else(|e| panic!("{case}: {e}"));
            assert_eq!(mesh.triangles.len(), 6, "{case}");
            assert_whole(&mesh, &case);
            for (t, &has) in with.iter().flat_map(|h| [h, h]).enumerate() {
                match attribute {
                    Attribute::Normals if has => assert_eq!(mesh.normals[t], [TILTED; 3], "{case}: triangle {t}"),
                    Attribute::Normals if !mesh.normals.is_empty() => {
                        assert_eq!(mesh.normals[t], [[0.0, 0.0, 1.0]; 3], "{case}: triangle {t}")
                    }
                    Attribute::TexCoords if has => assert_ne!(mesh.uvs[t], [[0.0; 2]; 3], "{case}: triangle {t}"),
                    Attribute::TexCoords if !mesh.uvs.is_empty() => {
                        assert_eq!(mesh.uvs[t], [[0.0; 2]; 3], "{case}: triangle {t}")
                    }
                    Attribute::Colors if has => assert_eq!(mesh.colors[t][0], [u16::MAX, 0, 0, u16::MAX], "{case}"),
                    Attribute::Colors if !mesh.colors.is_empty() => {
                        assert_eq!(mesh.colors[t], [[u16::MAX; 4]; 3], "{case}: triangle {t}")
                    }
                    Attribute::NormalMap if has => {
                        assert!(mesh.tangents[t].iter().all(|c| c[0] > 0.99 && c[3] == 1.0), "{case}: triangle {t}")
                    }
                    Attribute::NormalMap if !mesh.tangents.is_empty() => {
                        assert_eq!(mesh.tangents[t], [[0.0; 4]; 3], "{case}: triangle {t}")
                    }
                    Attribute::SecondSet if has => {
                        let expected = match t % 2 {
                            0 => [[1.0, 0.0], [1.0, 1.0], [0.0, 1.0]],
                            _ => [[1.0, 0.0], [0.0, 1.0], [0.0, 0.0]],
                        };
                        assert_eq!(mesh.corner_uvs(t, 1), Some(expected), "{case}: triangle {t}")
                    }
                    Attribute::SecondSet if !mesh.more_uvs.is_empty() => {
                        assert_eq!(mesh.corner_uvs(t, 1), Some([[0.0; 2]; 3]), "{case}: triangle {t}")
                    }
                    _ => {}
                }
            }
            let baked = bake(&mesh, &BuildParams::default()).unwrap_or_else(|e| panic!("{case}: bake: {e}"));
            octrace_runtime::Scene::from_baked(baked).unwrap_or_else(|e| panic!("{case}: open: {e}"));
        }
    }
}

/// A mesh made in code keeps its arrays whole whichever of `push`, `push_colored` and
/// the per-channel pushes come last, and `pad_attributes` is the one rule.
#[test]
fn pushes_in_any_order_keep_the_arrays_whole() {
    let tri = |x: f32| [[x, 0.0, 0.0], [x + 1.0, 0.0, 0.0], [x, 1.0, 0.0]];
    let mut mesh = Mesh::default();
    mesh.push(tri(0.0), None, None);
    mesh.push_colored(tri(1.0), Some([TILTED; 3]), None, Some([[7; 4]; 3]));
    mesh.push(tri(2.0), None, Some([[0.5; 2]; 3]));
    mesh.push(tri(3.0), None, None);
    assert_whole(&mesh, "pushes");
    assert_eq!(mesh.normals.len(), 4);
    assert_eq!(mesh.normals[0], [[0.0, 0.0, 1.0]; 3]);
    assert_eq!(mesh.normals[1], [TILTED; 3]);
    assert_eq!(mesh.colors[3], [[u16::MAX; 4]; 3]);
    assert_eq!(mesh.uvs[1], [[0.0; 2]; 3]);
    assert_eq!(mesh.uvs[2], [[0.5; 2]; 3]);
}
