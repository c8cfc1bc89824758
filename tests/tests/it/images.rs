//! Textures kept as their source encodes them (format 8.0, issue 34): a baked scene
//! holds a glTF's PNGs and JPEGs rather than their texels, decodes them the first time
//! texels are read, and reads exactly the texels the bake decoded; a damaged image is
//! refused by name.

use octrace_bake::{bake, procedural, BuildParams, Mesh};
use octrace_format::{ImageKind, SceneFile, Texture};
use octrace_runtime::Scene;

/// The texels of `t` in an array laid out as `t.first` says.
fn texels_of<'a>(t: &Texture, texels: &'a [u32]) -> &'a [u32] {
    &texels[t.first as usize..][..(t.width * t.height) as usize]
}

/// Bakes `path`, opens the file from its bytes, and checks that every texture of the
/// file samples the texels the loader decoded: the ones kept encoded once decoded,
/// the others as stored. Returns the file's size and the kinds of the encoded images.
fn bake_and_compare(path: &std::path::Path) -> (usize, Vec<Option<ImageKind>>) {
    let mesh = Mesh::load(path).unwrap();
    let bytes = bake(&mesh, &BuildParams::auto()).unwrap().to_file_bytes(0).unwrap();
    let scene = Scene::from_bytes(&bytes).unwrap();
    let view = scene.view();
    let textures = &view.shading.textures;
    assert_eq!(textures.len(), mesh.textures.len());
    let encoded = textures.iter().any(|t| t.encoded.is_some());
    assert_eq!(view.texels.is_decoded(), !encoded, "opening decodes nothing");
    scene.decode_textures().unwrap();
    assert!(view.texels.is_decoded());
    for (stored, loaded) in textures.iter().zip(&mesh.textures) {
        assert_eq!((stored.width, stored.height, stored.srgb), (loaded.width, loaded.height, loaded.srgb));
        assert!(
            texels_of(stored, view.texels.get()) == texels_of(loaded, &mesh.texels),
            "{}: other texels than the loader's",
            stored.name
        );
    }
    (bytes.len(), textures.iter().map(|t| t.encoded.map(|e| e.kind)).collect())
}

/// DamagedHelmet's five 2048 x 2048 JPEGs are kept as JPEGs: the baked file is no
/// larger than 1.5 times the GLB (it was 22.7 times with every texel stored, 85.8 MB),
/// and decodes to exactly the loader's texels.
#[test]
#[cfg_attr(not(octrace_shared), ignore = "needs ../shared beside the clone (README: Set up)")]
fn a_glbs_jpegs_stay_jpegs_and_decode_to_the_loaders_texels() {
    let test = "a_glbs_jpegs_stay_jpegs_and_decode_to_the_loaders_texels";
    let Some(path) = octrace_tests::shared_file("gltf/DamagedHelmet.glb", test) else { return };
    let (size, kinds) = bake_and_compare(&path);
    let glb = std::fs::metadata(&path).unwrap().len() as usize;
    eprintln!("DamagedHelmet: {size} bytes baked, {glb} in the GLB ({:.2}x)", size as f64 / glb as f64);
    assert!(size * 2 <= glb * 3, "{size} bytes baked from a GLB of {glb}");
    assert_eq!(kinds, vec![Some(ImageKind::Jpeg); 5]);
}

/// PNGs (the leaf's external PNG and embedded checker) are kept as PNGs and decode to the loader's texels.
#[test]
fn pngs_stay_pngs_and_decode_to_the_loaders_texels() {
    let (_, kinds) = bake_and_compare(&octrace_tests::data("textured/leaf.gltf"));
    assert!(kinds.contains(&Some(ImageKind::Png)), "{kinds:?}");
}

/// The same on TextureTransformTest's five PNGs, and the bake stays small.
#[test]
#[cfg_attr(not(octrace_shared), ignore = "needs ../shared beside the clone (README: Set up)")]
fn texture_transform_tests_pngs_stay_pngs() {
    let test = "texture_transform_tests_pngs_stay_pngs";
    let Some(path) = octrace_tests::shared_file("gltf/TextureTransformTest/TextureTransformTest.gltf", test) else {
        return;
    };
    let (size, kinds) = bake_and_compare(&path);
    assert!(kinds.iter().all(|k| *k == Some(ImageKind::Png)), "{kinds:?}");
    assert!(size < 100_000, "{size} bytes (530,640 with every texel stored)");
}

/// A scene whose encoded image decodes to other texels than the bake's (its hash
/// altered, as a file edited after the bake would be), or does not decode at all, opens
/// (the open reads headers only), then refuses to decode, naming the texture and why;
/// the texture reads as white; nothing panics on the trusted path either.
#[test]
fn a_damaged_encoded_image_is_refused_by_name_and_reads_white() {
    let base = bake(&procedural::shaded_torus(8, 4), &BuildParams::auto()).unwrap();
    let t = base.shading.textures[1].clone();
    assert_eq!(t.encoded.map(|e| e.kind), Some(ImageKind::Png));
    let good = SceneFile::from_bytes(&base.to_file_bytes(0).unwrap()).unwrap();
    assert!(good.view().texels.check().is_ok());
    assert!(texels_of(&t, good.view().texels.get()).iter().any(|&w| w != u32::MAX));

    let mut altered = base.clone();
    altered.shading.textures[1].encoded.as_mut().unwrap().texels_hash ^= 1;
    // The last byte of the PNG's compressed data (its Adler-32 checksum).
    let mut damaged = base.clone();
    let at = 78 - 12 - 4 - 1;
    damaged.images[at / 4] ^= 0xff << (8 * (at % 4));
    for (scene, says) in [(altered, "decodes to other texels than at bake"), (damaged, "PNG:")] {
        let bytes = scene.to_file_bytes(0).unwrap();
        let scene = Scene::from_bytes(&bytes).expect("a file whose headers are sound opens");
        let err = scene.decode_textures().unwrap_err().to_string();
        assert!(err.contains("texture '2 x 2 PNG'") && err.contains(says), "{err}");
        assert!(texels_of(&t, scene.view().texels.get()).iter().all(|&w| w == u32::MAX), "white");
        // Rendering goes on (the texture white); the CLI refuses first (cli tests).
        octrace_runtime::testing::exercise(&scene, &[octrace_runtime::Ray::new(glam::Vec3::Z * 3.0, -glam::Vec3::Z)]);
    }
    // The trusted path: an image range far past the images, and a huge texture.
    for change in [
        (|s: &mut octrace_format::BakedScene| s.shading.textures[1].encoded.as_mut().unwrap().offset = u64::MAX - 8)
            as fn(&mut octrace_format::BakedScene),
        |s| {
            s.shading.textures[1].width = 8192;
            s.shading.textures[1].height = 8192;
        },
    ] {
        let mut s = base.clone();
        change(&mut s);
        let bytes = s.to_file_bytes(0).unwrap();
        assert!(Scene::from_bytes(&bytes).is_err(), "the validated open refuses it");
        let scene = Scene::from_bytes_unchecked(&bytes).unwrap();
        let err = scene.decode_textures().unwrap_err().to_string();
        assert!(err.contains("texture '2 x 2 PNG'"), "{err}");
    }
}
