//! Reading a glTF document as viewers do: harmless violations of the spec are
//! repaired with a warning naming the element, extensions are checked, and a document
//! that still does not parse is refused with the JSON path of what is wrong.

use std::path::Path;

use serde_json::Value;

use crate::error::{Error, Result};

/// The extensions octrace honours: a file that requires only these loads.
pub(super) const HONOURED_EXTENSIONS: [&str; 6] = [
    "KHR_lights_punctual",
    "KHR_materials_emissive_strength",
    "KHR_materials_ior",
    "KHR_materials_transmission",
    "KHR_materials_unlit",
    "KHR_texture_transform",
];

/// The document of a `.gltf` or `.glb` file and the GLB binary chunk, with the
/// repairs made (each one a line in `warnings`).
///
/// Repaired: a camera without `type` (taken from the projection object it has), a
/// `byteStride` of 0 (meaning tightly packed, as when absent), an image in a buffer
/// view without `mimeType` (its bytes say). Warned about once
/// each: extensions used but not honoured ([`HONOURED_EXTENSIONS`]).
///
/// # Errors
/// [`Error::Parse`] for JSON that does not parse (with its line and column), a
/// document that does not fit glTF's schema (with the JSON path of the element), or
/// an extension in `extensionsRequired` octrace cannot honour (naming it).
pub(super) fn document<'a>(
    bytes: &'a [u8],
    path: &Path,
    warnings: &mut Vec<String>,
) -> Result<(gltf::json::Root, Option<super::Buffer<'a>>)> {
    let parse_error =
        |element: &str, message: String| Error::Parse { path: path.into(), element: element.into(), message };
    let (json, blob) = if bytes.starts_with(b"glTF") {
        let glb = gltf::binary::Glb::from_slice(bytes).map_err(|e| parse_error("GLB container", e.to_string()))?;
        // The binary chunk stays borrowed from the file's bytes: no copy of what can
        // be most of a big file.
        (glb.json.into_owned(), glb.bin)
    } else {
        (bytes.to_vec(), None)
    };
    let mut value: Value = serde_json::from_slice(&json).map_err(|e| parse_error("document", format!("JSON: {e}")))?;
    let warn = |warnings: &mut Vec<String>, what: String| warnings.push(format!("{}: {what}", path.display()));
    if let Some(cameras) = value.get_mut("cameras").and_then(Value::as_array_mut) {
        for (i, camera) in cameras.iter_mut().enumerate() {
            let Some(camera) = camera.as_object_mut() else { continue };
            if camera.contains_key("type") {
                continue;
            }
            let kind = ["perspective", "orthographic"].into_iter().find(|k| camera.contains_key(*k));
            if let Some(kind) = kind {
                camera.insert("type".into(), Value::String(kind.into()));
                let name = camera.get("name").and_then(Value::as_str).map(|n| format!(" '{n}'")).unwrap_or_default();
                warn(
                    warnings,
                    format!("camera {i}{name} has no \"type\"; taken as {kind}, from its \"{kind}\" object"),
                );
            }
        }
    }
    if let Some(views) = value.get_mut("bufferViews").and_then(Value::as_array_mut) {
        for (i, view) in views.iter_mut().enumerate() {
            let Some(view) = view.as_object_mut() else { continue };
            if view.get("byteStride").and_then(Value::as_u64) == Some(0) {
                view.remove("byteStride");
                warn(warnings, format!("buffer view {i} has byteStride 0; taken as tightly packed"));
            }
        }
    }
    // The gltf crate unwraps an image's mimeType when it has a bufferView, and its uri
    // otherwise: a missing one is repaired (octrace tells PNG from JPEG by their
    // bytes) or refused here, not a panic there.
    if let Some(images) = value.get_mut("images").and_then(Value::as_array_mut) {
        for (i, image) in images.iter_mut().enumerate() {
            let Some(image) = image.as_object_mut() else { continue };
            if image.contains_key("bufferView") && !image.contains_key("mimeType") {
                image.insert("mimeType".into(), Value::String("application/octet-stream".into()));
                warn(warnings, format!("image {i} has a bufferView but no mimeType; its type is read from its bytes"));
            } else if !image.contains_key("bufferView") && !image.contains_key("uri") {
                return Err(parse_error(&format!("images[{i}]"), "has neither a uri nor a bufferView".into()));
            }
        }
    }
    let names = |key: &str| -> Vec<String> {
        let list = value.get(key).and_then(Value::as_array);
        list.into_iter().flatten().filter_map(Value::as_str).map(str::to_string).collect()
    };
    let required = names("extensionsRequired");
    if let Some(bad) = required.iter().find(|e| !HONOURED_EXTENSIONS.contains(&e.as_str())) {
        return Err(parse_error(
            "extensionsRequired",
            format!(
                "the file requires extension '{bad}', which octrace cannot honour (it honours {})",
                HONOURED_EXTENSIONS.join(", ")
            ),
        ));
    }
    for used in names("extensionsUsed") {
        if !HONOURED_EXTENSIONS.contains(&used.as_str()) {
            warn(warnings, format!("extension '{used}' is used by the file but ignored by octrace"));
        }
    }
    let root = serde_path_to_error::deserialize::<_, gltf::json::Root>(value).map_err(|e| {
        let element = e.path().to_string();
        parse_error(&element, e.into_inner().to_string())
    })?;
    Ok((root, blob))
}
