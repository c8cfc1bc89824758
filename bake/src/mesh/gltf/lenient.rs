//! Reading a glTF document as viewers do: harmless violations of the spec are
//! repaired with a warning naming the element, extensions are checked, and a document
//! that still does not parse is refused with the JSON path of what is wrong.

use std::path::Path;

use serde_json::Value;

use crate::error::{Error, Result};

/// The extensions octrace honours: a file that requires only these loads.
pub(super) const HONOURED_EXTENSIONS: [&str; 7] = [
    "EXT_mesh_gpu_instancing",
    "KHR_lights_punctual",
    "KHR_materials_emissive_strength",
    "KHR_materials_ior",
    "KHR_materials_transmission",
    "KHR_materials_unlit",
    "KHR_texture_transform",
];

/// A GLB file's chunks: JSON, binary if any, and those of unknown type it skipped
/// (byte offset, type).
type GlbChunks<'a> = (&'a [u8], Option<&'a [u8]>, Vec<(usize, u32)>);

/// A GLB file's chunks ([`GlbChunks`]). Errors name the byte offset of what is wrong.
fn glb_chunks(bytes: &[u8]) -> std::result::Result<GlbChunks<'_>, String> {
    let word = |at: usize| bytes.get(at..at + 4).map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]));
    let version = word(4).ok_or("the file ends inside the 12-byte header")?;
    if version != 2 {
        return Err(format!("GLB version {version} at byte 4: octrace reads version 2 (glTF 2.0) only"));
    }
    // The header's length (checked against the file's before this is called).
    let end = (word(8).ok_or("the file ends inside the 12-byte header")? as usize).min(bytes.len());
    let (mut json, mut bin, mut skipped) = (None, None, Vec::new());
    let mut at = 12;
    while at < end {
        let (Some(len), Some(kind)) = (word(at), word(at + 4)) else {
            return Err(format!("the chunk header at byte {at} runs past the end ({end} bytes)"));
        };
        let data = at + 8;
        let stop = data
            .checked_add(len as usize)
            .filter(|&s| s <= end)
            .ok_or_else(|| format!("the chunk at byte {at} declares {len} bytes, past the end ({end} bytes)"))?;
        match kind {
            0x4E4F_534A if json.is_none() && at == 12 => json = Some(&bytes[data..stop]),
            0x004E_4942 if bin.is_none() && json.is_some() => bin = Some(&bytes[data..stop]),
            0x4E4F_534A | 0x004E_4942 => {
                return Err(format!("the chunk at byte {at} is a second JSON or binary chunk, or out of order"))
            }
            _ if at == 12 => return Err(format!("the first chunk (byte 12) has type 0x{kind:08X}, not JSON")),
            _ => skipped.push((at, kind)),
        }
        // Chunks are padded to 4 bytes.
        at = stop.next_multiple_of(4);
    }
    let json = json.ok_or("no JSON chunk")?;
    Ok((json, bin, skipped))
}

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
    let warn = |warnings: &mut Vec<String>, what: String| warnings.push(format!("{}: {what}", path.display()));
    let (json, blob) = if bytes.starts_with(b"glTF") {
        let (json, bin, skipped) = glb_chunks(bytes).map_err(|e| parse_error("GLB container", e))?;
        for (at, kind) in skipped {
            warn(warnings, format!("GLB chunk at byte {at} has the unknown type 0x{kind:08X}: ignored, as glTF asks"));
        }
        // The binary chunk stays borrowed from the file's bytes: no copy of what can
        // be most of a big file.
        (json, bin.map(std::borrow::Cow::Borrowed))
    } else {
        (bytes, None)
    };
    let mut value: Value = serde_json::from_slice(json).map_err(|e| parse_error("document", format!("JSON: {e}")))?;
    // glTF 1.0 (and any other major version) is another schema: say so rather than
    // fail on its first difference.
    let version = value.get("asset").and_then(|a| a.get("version")).and_then(Value::as_str).unwrap_or("");
    if !version.starts_with("2.") {
        return Err(parse_error(
            "asset.version",
            format!(
                "glTF version '{version}': octrace reads glTF 2.0 only (convert older files, e.g. with \
                 gltf-pipeline or Blender)"
            ),
        ));
    }
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
