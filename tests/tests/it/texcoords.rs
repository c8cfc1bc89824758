//! Every texture slot reads its own texture coordinates (issue 34): its `TEXCOORD_n`
//! set through its own `KHR_texture_transform` (occlusion and normal textures
//! included, whose transform the gltf crate gives only as JSON), each distinct pair a
//! channel of the baked scene.

use glam::Vec3;
use octrace_bake::{bake, BuildParams, Mesh};
use octrace_runtime::{Ray, Scene};

/// A `w x 1` RGB PNG of `pixels`.
fn png(pixels: &[[u8; 3]]) -> String {
    let mut out = Vec::new();
    let mut encoder = png::Encoder::new(&mut out, pixels.len() as u32, 1);
    encoder.set_color(png::ColorType::Rgb);
    encoder.write_header().unwrap().write_image_data(pixels.as_flattened()).unwrap();
    format!("data:image/png;base64,{}", octrace_tests::base64(&out))
}

/// A unit quad facing +z whose `TEXCOORD_0` runs with x (`u = x`, `v = 1 - y`) and
/// `TEXCOORD_1` against it (`u = 1 - x`); a material whose base colour (red | green)
/// reads set 0, emissive (black | white) set 1, occlusion (black | white) set 0
/// offset by half a texture, normal set 0 turned by 0.3 radians; nearest texels.
pub(crate) fn two_set_quad() -> String {
    let positions: [[f32; 3]; 4] = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]];
    let set0: [[f32; 2]; 4] = [[0.0, 1.0], [1.0, 1.0], [1.0, 0.0], [0.0, 0.0]];
    let set1: [[f32; 2]; 4] = [[1.0, 1.0], [0.0, 1.0], [0.0, 0.0], [1.0, 0.0]];
    let mut buf: Vec<u8> = Vec::new();
    for f in positions.as_flattened().iter().chain(set0.as_flattened()).chain(set1.as_flattened()) {
        buf.extend(f.to_le_bytes());
    }
    buf.extend([0u16, 1, 2, 0, 2, 3].iter().flat_map(|i| i.to_le_bytes()));
    let (red_green, black_white) = (png(&[[255, 0, 0], [0, 255, 0]]), png(&[[0, 0, 0], [255, 255, 255]]));
    format!(
        r#"{{"asset":{{"version":"2.0"}},"extensionsUsed":["KHR_texture_transform"],"scene":0,"scenes":[{{"nodes":[0]}}],
        "nodes":[{{"mesh":0}}],
        "meshes":[{{"primitives":[{{"attributes":{{"POSITION":0,"TEXCOORD_0":1,"TEXCOORD_1":2}},"indices":3,"material":0}}]}}],
        "materials":[{{"name":"two sets","emissiveFactor":[1,1,1],
            "pbrMetallicRoughness":{{"baseColorTexture":{{"index":0}},"metallicFactor":0}},
            "emissiveTexture":{{"index":1,"texCoord":1}},
            "occlusionTexture":{{"index":1,"extensions":{{"KHR_texture_transform":{{"offset":[0.5,0]}}}}}},
            "normalTexture":{{"index":1,"texCoord":1,"extensions":{{"KHR_texture_transform":{{"rotation":0.3,"texCoord":0}}}}}}}}],
        "samplers":[{{"magFilter":9728,"minFilter":9728}}],
        "textures":[{{"source":0,"sampler":0}},{{"source":1,"sampler":0}}],
        "images":[{{"uri":"{red_green}"}},{{"uri":"{black_white}"}}],
        "buffers":[{{"byteLength":{len},"uri":"data:application/octet-stream;base64,{b64}"}}],
        "bufferViews":[{{"buffer":0,"byteLength":48}},{{"buffer":0,"byteOffset":48,"byteLength":32}},
            {{"buffer":0,"byteOffset":80,"byteLength":32}},{{"buffer":0,"byteOffset":112,"byteLength":12}}],
        "accessors":[{{"bufferView":0,"componentType":5126,"count":4,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}},
            {{"bufferView":1,"componentType":5126,"count":4,"type":"VEC2"}},
            {{"bufferView":2,"componentType":5126,"count":4,"type":"VEC2"}},
            {{"bufferView":3,"componentType":5123,"count":6,"type":"SCALAR"}}]}}"#,
        len = buf.len(),
        b64 = octrace_tests::base64(&buf),
    )
}

/// [`two_set_quad`], loaded.
pub(crate) fn two_set_mesh() -> Mesh {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("two-sets.gltf");
    std::fs::write(&path, two_set_quad()).unwrap();
    Mesh::load(&path).unwrap()
}

/// Each slot samples at its own coordinates: at a quarter of the quad's width the
/// base colour is red (set 0), the emission white (set 1, mirrored), the occlusion
/// none (set 0 moved half a texture onto the white texel); at three quarters green,
/// no emission, full occlusion. The normal texture's channel holds set 0 turned as
/// its transform says. Four channels, no warning. Before, every slot sampled the base
/// colour's coordinates, with a warning.
#[test]
fn each_texture_slot_reads_its_own_set_and_transform() {
    let mesh = two_set_mesh();
    assert!(mesh.warnings.is_empty(), "{:?}", mesh.warnings);
    let m = &mesh.materials[0];
    assert_eq!(m.uv_channels, [0, 1, 0, 2, 3]);
    let scene = Scene::from_baked(bake(&mesh, &BuildParams::auto()).unwrap()).unwrap();
    let view = scene.view();
    assert_eq!(view.uv_channel_count(), 4);
    let m = &view.shading.materials[0];
    for (x, base, emission, occlusion) in [(0.25, [1.0, 0.0], 1.0, 1.0), (0.75, [0.0, 1.0], 0.0, 0.0)] {
        let hit = scene.intersect(&Ray::new(Vec3::new(x, 0.5, 1.0), -Vec3::Z)).expect("the quad");
        let colour = view.base_color_at(m, hit.prim, hit.u, hit.v);
        assert_eq!([colour[0], colour[1]], base, "base colour at x = {x}");
        assert_eq!(view.emissive_at(m, hit.prim, hit.u, hit.v), [emission; 3], "emission at x = {x}");
        assert_eq!(view.occlusion_at(m, hit.prim, hit.u, hit.v), occlusion, "occlusion at x = {x}");
        // The normal texture's coordinates: set 0 turned by 0.3 (u' = c u + s v,
        // v' = -s u + c v), at each corner.
        let (c, s) = (0.3f64.cos(), 0.3f64.sin());
        let set0 = view.corner_uvs_in(hit.prim, 0).unwrap();
        let turned = view.corner_uvs_in(hit.prim, 3).unwrap();
        for (a, b) in set0.iter().zip(turned) {
            let (u, v) = (a[0] as f64, a[1] as f64);
            assert_eq!(b, [(c * u + s * v) as f32, (-s * u + c * v) as f32]);
        }
    }
}
