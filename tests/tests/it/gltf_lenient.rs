//! glTF files that bend the spec load as viewers load them, with a warning naming the
//! element; what octrace cannot honour is refused by name; errors say where.

use std::path::Path;

use octrace_bake::{Error, Mesh, MeshFormat};
use octrace_format::{Filter, TEXEL_WORDS};
use octrace_tests::data;

/// `tests/data/extensions.gltf` with `edit` applied to its text, loaded from a folder
/// of its own (with `files` beside it).
fn load_edited(edit: impl Fn(String) -> String, files: &[(&str, &[u8])]) -> Result<Mesh, Error> {
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(data("extensions.gltf")).unwrap();
    let edited = edit(text.clone());
    assert_ne!(edited, text, "the edit changed nothing");
    std::fs::write(dir.path().join("scene.gltf"), edited).unwrap();
    for (name, bytes) in files {
        std::fs::write(dir.path().join(name), bytes).unwrap();
    }
    Mesh::load(dir.path().join("scene.gltf"))
}

fn warned(mesh: &Mesh, needle: &str) -> bool {
    mesh.warnings.iter().any(|w| w.contains(needle))
}

#[test]
fn a_camera_without_type_loads_with_a_warning_naming_it() {
    let mesh = load_edited(|t| t.replace(r#""type":"perspective","#, ""), &[]).unwrap();
    assert!(
        warned(&mesh, r#"camera 0 'cam' has no "type"; taken as perspective, from its "perspective" object"#),
        "{:?}",
        mesh.warnings
    );
    assert_eq!(mesh.cameras.len(), 1);
    assert_eq!(mesh.cameras[0].yfov, 0.8);
}

#[test]
fn a_byte_stride_of_zero_is_taken_as_tightly_packed() {
    let mesh = load_edited(|t| t.replacen(r#""byteLength""#, r#""byteStride":0,"byteLength""#, 2), &[]);
    let mesh = mesh.unwrap();
    assert!(warned(&mesh, "buffer view 0 has byteStride 0; taken as tightly packed"), "{:?}", mesh.warnings);
    assert_eq!(mesh.triangles.len(), 5);
}

#[test]
fn required_extensions_load_only_when_honoured_and_ignored_ones_are_warned_about_once() {
    let required = |list: &'static str| {
        move |t: String| {
            t.replacen(r#""extensionsUsed""#, &format!(r#""extensionsRequired":{list},"extensionsUsed""#), 1)
        }
    };
    let mesh = load_edited(required(r#"["KHR_materials_transmission","KHR_lights_punctual"]"#), &[]).unwrap();
    assert_eq!(mesh.materials[1].transmission, 0.9);
    let err = load_edited(required(r#"["KHR_materials_transmission","KHR_draco_mesh_compression"]"#), &[]).unwrap_err();
    let msg = err.to_string();
    assert!(matches!(err, Error::Parse { ref element, .. } if element == "extensionsRequired"), "{msg}");
    assert!(msg.contains("requires extension 'KHR_draco_mesh_compression', which octrace cannot honour"), "{msg}");
    let used = |t: String| t.replacen(r#""extensionsUsed":["#, r#""extensionsUsed":["KHR_materials_clearcoat","#, 1);
    let mesh = load_edited(used, &[]).unwrap();
    let notes: Vec<_> = mesh.warnings.iter().filter(|w| w.contains("KHR_materials_clearcoat")).collect();
    assert_eq!(notes.len(), 1, "{:?}", mesh.warnings);
    assert!(notes[0].ends_with("extension 'KHR_materials_clearcoat' is used by the file but ignored by octrace"));
}

#[test]
fn errors_name_the_json_path_or_the_line() {
    let err = load_edited(|t| t.replace(r#""yfov":0.8"#, r#""yfov":"wide""#), &[]).unwrap_err();
    let msg = err.to_string();
    assert!(matches!(err, Error::Parse { ref element, .. } if element == "cameras[0].perspective.yfov"), "{msg}");
    let err = load_edited(|t| t.replacen(r#""scene":0,"#, r#""scene":0,,"#, 1), &[]).unwrap_err();
    assert!(err.to_string().contains("line 4 column"), "{err}");
}

#[test]
fn unlit_materials_load_as_unlit() {
    let unlit = |t: String| {
        t.replace(r#"{"name":"chrome","#, r#"{"name":"chrome","extensions":{"KHR_materials_unlit":{}},"#).replacen(
            r#""extensionsUsed":["#,
            r#""extensionsUsed":["KHR_materials_unlit","#,
            1,
        )
    };
    let mesh = load_edited(unlit, &[]).unwrap();
    assert!(mesh.warnings.is_empty(), "{:?}", mesh.warnings);
    assert!(mesh.materials[0].unlit && !mesh.materials[1].unlit);
}

/// A material of `extensions.gltf` given a base colour texture from image `uri`.
fn textured(uri: &'static str) -> impl Fn(String) -> String {
    move |t: String| {
        t.replace(
            r#"{"name":"smoke","alphaMode":"BLEND","pbrMetallicRoughness":{"#,
            r#"{"name":"smoke","alphaMode":"BLEND","pbrMetallicRoughness":{"baseColorTexture":{"index":0},"#,
        )
        .replacen(
            r#""materials":"#,
            &format!(r#""textures":[{{"source":0,"sampler":0}}],"samplers":[{{"magFilter":9728}}],"images":[{{"uri":"{uri}"}}],"materials":"#),
            1,
        )
    }
}

#[test]
fn jpeg_textures_decode_to_their_colours() {
    let jpeg = std::fs::read(data("textured/colours.jpg")).unwrap();
    let mesh = load_edited(textured("colours.jpg"), &[("colours.jpg", &jpeg)]).unwrap();
    assert!(mesh.warnings.is_empty(), "{:?}", mesh.warnings);
    let t = &mesh.textures[0];
    assert_eq!((t.width, t.height, t.filter, t.min_alpha), (4, 2, Filter::Nearest, 1.0));
    assert_eq!(mesh.materials[4].base_color_texture, Some(0));
    // Red, green, blue, white / black, grey, yellow, cyan (sRGB).
    let srgb = [[255, 0, 0], [0, 255, 0], [0, 0, 255], [255; 3], [0; 3], [128; 3], [255, 255, 0], [0, 255, 255]];
    for (i, want) in srgb.iter().enumerate() {
        // Stored as the image holds them, sRGB-encoded, 8 bits a channel.
        let got = mesh.texels[i * TEXEL_WORDS].to_le_bytes();
        for c in 0..3 {
            // JPEG is lossy (quality 100, no chroma subsampling): within two levels.
            assert!((got[c] as i64 - want[c] as i64).abs() <= 2, "texel {i} channel {c}: {} vs {}", got[c], want[c]);
        }
        assert_eq!(got[3], 0xff);
    }
}

/// Broken JPEGs are refused as broken PNGs are (issue 33): cut to a third, or a
/// 4 x 2 image whose header says 2000 x 2000: a warning names the image, no filler
/// texels.
#[test]
fn broken_jpegs_are_left_out_with_a_warning() {
    let jpeg = std::fs::read(data("textured/colours.jpg")).unwrap();
    let cut = jpeg[..jpeg.len() / 3].to_vec();
    let cut_in_scan = jpeg[..jpeg.len() - 60].to_vec();
    let mut lying = jpeg.clone();
    let sof = lying.windows(2).position(|w| w[0] == 0xFF && (w[1] == 0xC0 || w[1] == 0xC2)).expect("a frame header");
    lying[sof + 5..sof + 9].copy_from_slice(&[0x07, 0xD0, 0x07, 0xD0]);
    for (name, bytes) in [("cut.jpg", &cut), ("cut-in-scan.jpg", &cut_in_scan), ("lying.jpg", &lying)] {
        let mesh = load_edited(textured(name), &[(name, bytes)]).unwrap();
        let note = mesh.warnings.iter().find(|w| w.contains(&format!("image 0 '{name}'")));
        let note = note.unwrap_or_else(|| panic!("{name}: {:?}", mesh.warnings));
        assert!(note.contains("JPEG"), "{note}");
        assert!(mesh.textures.is_empty() && mesh.texels.is_empty(), "{name}: {} texels", mesh.texels.len());
    }
}

#[test]
fn textures_that_cannot_be_read_are_left_out_with_a_warning_naming_the_image() {
    for (uri, why) in [
        ("missing.png", "No such file"),
        ("../outside.png", "outside"),
        ("not-an-image.png", "neither a PNG nor a JPEG"),
    ] {
        let mesh = load_edited(textured(uri), &[("not-an-image.png", b"GIF89a")]).unwrap();
        let note = mesh.warnings.iter().find(|w| w.contains(&format!("image 0 '{uri}'")));
        let note = note.unwrap_or_else(|| panic!("{uri}: {:?}", mesh.warnings));
        assert!(note.contains("base colour texture of material 'smoke'") && note.contains(why), "{note}");
        assert!(mesh.textures.is_empty() && mesh.materials[4].base_color_texture.is_none());
    }
}

/// A PNG whose header declares 4096 x 4096 pixels in a few dozen bytes: refused from
/// its header, before 64 MiB of pixels are allocated, and left out with a warning.
#[test]
fn an_image_declaring_far_more_pixels_than_its_bytes_hold_is_refused_before_decoding() {
    fn crc32(bytes: &[u8]) -> u32 {
        let mut crc = !0u32;
        for &b in bytes {
            crc ^= u32::from(b);
            for _ in 0..8 {
                crc = if crc & 1 != 0 { (crc >> 1) ^ 0xedb8_8320 } else { crc >> 1 };
            }
        }
        !crc
    }
    let chunk = |kind: &[u8], data: &[u8]| {
        let mut out = (data.len() as u32).to_be_bytes().to_vec();
        out.extend_from_slice(kind);
        out.extend_from_slice(data);
        out.extend_from_slice(&crc32(&[kind, data].concat()).to_be_bytes());
        out
    };
    let mut header = 4096u32.to_be_bytes().to_vec();
    header.extend_from_slice(&4096u32.to_be_bytes());
    header.extend_from_slice(&[8, 6, 0, 0, 0]);
    let mut bomb = b"\x89PNG\r\n\x1a\n".to_vec();
    bomb.extend(chunk(b"IHDR", &header));
    bomb.extend(chunk(b"IDAT", &[0x78, 0x9c, 0x03, 0x00, 0x00, 0x00, 0x00, 0x01]));
    bomb.extend(chunk(b"IEND", &[]));
    let mesh = load_edited(textured("bomb.png"), &[("bomb.png", &bomb)]).unwrap();
    let note = mesh.warnings.iter().find(|w| w.contains("image 0 'bomb.png'")).expect("a warning");
    assert!(note.contains("4096 x 4096 pixels, more than the"), "{note}");
    assert!(mesh.textures.is_empty() && mesh.texels.is_empty());
}

/// Found by fuzzing `load_gltf`: the gltf crate unwraps an image's `uri` (or, for an
/// image in a buffer view, its `mimeType`), so an image with neither panicked inside
/// it. Now one without either is an error naming it, and one in a buffer view without
/// `mimeType` loads, its type read from its bytes.
#[test]
fn images_without_a_source_or_a_mime_type_are_an_error_or_repaired() {
    let err = load_edited(
        |t| textured("x.png")(t).replace(r#""images":[{"uri":"x.png"}]"#, r#""images":[{"name":"none"}]"#),
        &[],
    )
    .unwrap_err();
    let msg = err.to_string();
    assert!(matches!(err, Error::Parse { ref element, .. } if element == "images[0]"), "{msg}");
    assert!(msg.contains("neither a uri nor a bufferView"), "{msg}");
    // The texture's PNG as a second buffer, in a buffer view of its own, no mimeType.
    let png = std::fs::read(data("textured/leaf.png")).unwrap();
    let mut doc: serde_json::Value =
        serde_json::from_str(&textured("x.png")(std::fs::read_to_string(data("extensions.gltf")).unwrap())).unwrap();
    let views = doc["bufferViews"].as_array().unwrap().len();
    doc["buffers"].as_array_mut().unwrap().push(serde_json::json!({"uri": "leaf.bin", "byteLength": png.len()}));
    doc["bufferViews"].as_array_mut().unwrap().push(serde_json::json!({"buffer": 1, "byteLength": png.len()}));
    doc["images"] = serde_json::json!([{ "bufferView": views }]);
    let text = doc.to_string();
    let mesh = load_edited(|_| text.clone(), &[("leaf.bin", &png)]).unwrap();
    assert!(
        warned(&mesh, "image 0 has a bufferView but no mimeType; its type is read from its bytes"),
        "{:?}",
        mesh.warnings
    );
    assert_eq!((mesh.textures.len(), mesh.textures[0].width), (1, 64));
}

/// Animations, skins and morph targets, which a static bake leaves out, are a warning
/// with their counts (issue 34): the Khronos sample AnimatedTriangle.
#[test]
#[cfg_attr(not(octrace_shared), ignore = "needs ../shared beside the clone (README: Set up)")]
fn an_animation_left_out_is_said_with_its_count() {
    let test = "an_animation_left_out_is_said_with_its_count";
    let Some(animated) = octrace_tests::shared_file("gltf/AnimatedTriangle.gltf", test) else { return };
    let mesh = octrace_bake::Mesh::load(animated).unwrap();
    assert!(
        mesh.warnings.iter().any(|w| w.contains("1 animation, 0 skins and 0 meshes with morph targets")),
        "{:?}",
        mesh.warnings
    );
}

/// What a static bake leaves out, and files it cannot read, said aloud (issue 34):
/// animations, skins and morph targets are a warning with their counts (above); glTF 1.0 is
/// refused by name; a GLB chunk of unknown type is skipped with a warning naming its
/// byte offset (glTF asks readers to ignore them), and a chunk that runs past the end
/// is an error naming its offset.
#[test]
fn what_a_static_bake_leaves_out_and_what_it_cannot_read_are_said() {
    let path = Path::new("s.gltf");
    let v1 = r#"{"asset":{"version":"1.0"},"accessors":{"a":{}}}"#;
    let err = Mesh::from_bytes(v1.as_bytes(), MeshFormat::Gltf, path, None).unwrap_err();
    assert!(err.to_string().contains("asset.version: glTF version '1.0': octrace reads glTF 2.0 only"), "{err}");

    // A GLB: the extensions sample's JSON (its buffers embedded) and an unknown chunk.
    let json = std::fs::read(data("extensions.gltf")).unwrap();
    let padded = |mut b: Vec<u8>, pad: u8| {
        while !b.len().is_multiple_of(4) {
            b.push(pad);
        }
        b
    };
    let json = padded(json, b' ');
    let glb = |chunks: &[(u32, &[u8])]| {
        let mut body = Vec::new();
        for (kind, data) in chunks {
            body.extend((data.len() as u32).to_le_bytes());
            body.extend(kind.to_le_bytes());
            body.extend_from_slice(data);
        }
        let mut out = b"glTF".to_vec();
        out.extend(2u32.to_le_bytes());
        out.extend((12 + body.len() as u32).to_le_bytes());
        out.extend(body);
        out
    };
    let extra = glb(&[(0x4E4F_534A, &json), (0x1234_5678, b"abcd")]);
    let mesh = Mesh::from_bytes(&extra, MeshFormat::Gltf, Path::new("s.glb"), None).unwrap();
    let at = 12 + 8 + json.len();
    assert!(
        mesh.warnings.iter().any(|w| w.contains(&format!("GLB chunk at byte {at} has the unknown type 0x12345678"))),
        "{:?}",
        mesh.warnings
    );
    let mut cut = glb(&[(0x4E4F_534A, &json)]);
    cut[12..16].copy_from_slice(&(json.len() as u32 + 8).to_le_bytes());
    let err = Mesh::from_bytes(&cut, MeshFormat::Gltf, Path::new("s.glb"), None).unwrap_err();
    assert!(err.to_string().contains("GLB container: the chunk at byte 12 declares"), "{err}");
}
