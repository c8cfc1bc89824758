//! glTF 2.0 through the `gltf` crate: the default scene's mesh primitives, node
//! transforms applied; triangle lists, strips and fans; other modes skipped.

mod buffers;
mod instances;
mod lenient;
mod material;
mod primitive;
mod scene;
mod tangents;

use std::borrow::Cow;
use std::path::Path;

use glam::DMat4;

use super::refs::LoadOptions;
use super::{Loaded, Mesh};
use crate::error::{Error, Result};
use buffers::load_buffers;
use material::UvMap;
use scene::{instanced_triangles, placements, Placements};

/// A buffer's bytes: borrowed from the file for a GLB's binary chunk, else owned.
pub(super) type Buffer<'a> = Cow<'a, [u8]>;

pub(super) fn parse(bytes: &[u8], path: &Path, base: Option<&Path>, options: &LoadOptions) -> Result<Mesh> {
    match parse_guarded(bytes, path, base, options, false)? {
        Loaded::One(mesh) => Ok(mesh),
        Loaded::Instanced(_) => unreachable!("a flat parse makes one mesh"),
    }
}

/// [`parse`], the meshes the scene places more than once kept once, as instances
/// ([`Loaded::Instanced`]), where it places any.
pub(super) fn parse_instanced(bytes: &[u8], path: &Path, base: Option<&Path>, options: &LoadOptions) -> Result<Loaded> {
    parse_guarded(bytes, path, base, options, true)
}

fn parse_guarded(
    bytes: &[u8],
    path: &Path,
    base: Option<&Path>,
    options: &LoadOptions,
    instancing: bool,
) -> Result<Loaded> {
    // The gltf crate (gltf-json 1.4) indexes arrays with unchecked indices while it
    // validates, and panics on some malformed files (a POSITION accessor index out of
    // range, found by fuzzing). A panic there is a malformed file, not a bug of ours:
    // it becomes a parse error.
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| parse_unguarded(bytes, path, base, options, instancing)))
        .unwrap_or_else(|_| {
            Err(Error::Parse {
                path: path.into(),
                element: "document".into(),
                message: "malformed glTF (an index out of range made the glTF parser give up)".into(),
            })
        })
}

fn parse_unguarded(
    bytes: &[u8],
    path: &Path,
    base: Option<&Path>,
    options: &LoadOptions,
    instancing: bool,
) -> Result<Loaded> {
    let parse_error = |element: &str, e: gltf::Error| Error::Parse {
        path: path.into(),
        element: element.into(),
        message: e.to_string(),
    };
    // The gltf crate subtracts the GLB header's size from its declared length without
    // a check (a panic where overflow checks are on, found by fuzzing): check it first.
    if bytes.starts_with(b"glTF") {
        let declared = bytes.get(8..12).map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize);
        if declared.is_none_or(|n| n < 12 || n > bytes.len()) {
            return Err(Error::Parse {
                path: path.into(),
                element: "GLB header".into(),
                message: match declared {
                    Some(n) => format!("declares {n} bytes; the file has {} and the header alone 12", bytes.len()),
                    None => format!("is cut short: the file has {} bytes, the header alone 12", bytes.len()),
                },
            });
        }
    }
    let mut warnings = Vec::new();
    let (json, blob) = lenient::document(bytes, path, &mut warnings)?;
    // gltf-json's validation reads `accessors[i]` for every primitive attribute before
    // checking `i`: refuse out-of-range accessor indices first, then validate.
    let accessors = json.accessors.len();
    for (m, mesh) in json.meshes.iter().enumerate() {
        for (p, prim) in mesh.primitives.iter().enumerate() {
            let targets = prim.targets.iter().flatten().flat_map(|t| [t.positions, t.normals, t.tangents]).flatten();
            if let Some(bad) =
                prim.attributes.values().copied().chain(prim.indices).chain(targets).find(|i| i.value() >= accessors)
            {
                return Err(Error::IndexOutOfRange {
                    path: path.into(),
                    element: format!("mesh {m} primitive {p}: accessor"),
                    index: bad.value() as i64,
                    count: accessors,
                });
            }
        }
    }
    let document = gltf::Document::from_json(json).map_err(|e| parse_error("document", e))?;
    // What a static bake leaves out, said once with the counts.
    let (animations, skins) = (document.animations().count(), document.skins().count());
    let morphed = document.meshes().filter(|m| m.primitives().any(|p| p.morph_targets().next().is_some())).count();
    if animations + skins + morphed > 0 {
        let n = |count: usize, one: &str, many: &str| format!("{count} {}", if count == 1 { one } else { many });
        warnings.push(format!(
            "{}: {}, {} and {}: baked still, in the rest pose (nodes' stored transforms, joints ignored, each \
             mesh's base positions without its morph targets)",
            path.display(),
            n(animations, "animation", "animations"),
            n(skins, "skin", "skins"),
            n(morphed, "mesh with morph targets", "meshes with morph targets"),
        ));
    }
    let mut sources = Vec::new();
    let buffers = load_buffers(&document, blob, path, base, options, &mut sources).map_err(|e| match e {
        // A binary chunk the file lacks may be one it mislabelled: say which were skipped.
        Error::Parse { path, element, message } if message.contains("GLB binary chunk") => {
            let skipped: Vec<&str> =
                warnings.iter().filter(|w| w.contains("GLB chunk at byte")).map(String::as_str).collect();
            let message = if skipped.is_empty() { message } else { format!("{message}; {}", skipped.join("; ")) };
            Error::Parse { path, element, message }
        }
        e => e,
    })?;
    // The default scene, or scene 0 when the file names none.
    let Some(scene) = document.default_scene().or_else(|| document.scenes().next()) else {
        return Err(Error::EmptyScene { path: path.into() });
    };
    // The work the scene asks for, before any of it: its placements of nodes, and the
    // triangles they make.
    let placed = placements(&document, &scene, options.max_instances).map_err(|e| match e {
        Placements::Cycle(node) => Error::Parse {
            path: path.into(),
            element: format!("node {node}"),
            message: "the node hierarchy has a cycle through this node".into(),
        },
        Placements::Over { node, total } => Error::Budget {
            path: path.into(),
            what: format!("node placements (shared children counted each time; passed at node {node})"),
            needed: total,
            limit: options.max_instances,
            option: "--max-instances, LoadOptions::max_instances",
        },
    })?;
    // EXT_mesh_gpu_instancing: a node's placements once an instance.
    let placed: Vec<u64> =
        document.nodes().map(|n| placed[n.index()].saturating_mul(scene::gpu_instances(&document, &n))).collect();
    let instances = placed.iter().fold(0u64, |a, &p| a.saturating_add(p));
    if instances > options.max_instances {
        return Err(Error::Budget {
            path: path.into(),
            what: "node placements (EXT_mesh_gpu_instancing's instances counted each)".into(),
            needed: instances,
            limit: options.max_instances,
            option: "--max-instances, LoadOptions::max_instances",
        });
    }
    let triangles = instanced_triangles(&document, &placed);
    if triangles > options.max_triangles {
        return Err(Error::Budget {
            path: path.into(),
            what: "triangles once instanced (each mesh's triangles times its placements)".into(),
            needed: triangles,
            limit: options.max_triangles,
            option: "--max-triangles, LoadOptions::max_triangles",
        });
    }
    let input_bytes = bytes.len() + buffers.iter().map(|b| b.len()).sum::<usize>();
    // Where each placement is baked whole although meshes repeat, the warning says why
    // (or how not to).
    let (groups, why) = match instancing.then(|| instances::groups(&document, &placed)) {
        Some(Ok(groups)) => (Some(groups), None),
        Some(Err(why)) => (None, Some(why.map_or(String::new(), |w| format!(" ({w})")))),
        None => (
            None,
            Some(
                " (bake without --flatten, or load with Mesh::load_instanced, to keep such meshes once, as instances)"
                    .into(),
            ),
        ),
    };
    if let Some(repeated) = why.and_then(|why| scene::repeated_geometry(&document, &placed, &why)) {
        warnings.push(format!("{}: {repeated}", path.display()));
    }
    let mesh = Mesh { sources, warnings, ..Mesh::default() };
    let mut loader = Loader {
        path,
        options,
        base,
        document: &document,
        buffers: &buffers,
        input_bytes,
        mesh,
        uv_maps: Vec::new(),
        skipped: None,
        default_material: None,
        grouped: groups,
        slots: None,
    };
    let used = loader.grouped.as_ref().map(|g| g.used_by_rest(&document));
    loader.load_materials(used.as_deref())?;
    for node in scene.nodes() {
        loader.node(&node, DMat4::IDENTITY, 0)?;
    }
    if loader.mesh.triangles.is_empty() && loader.grouped.is_none() {
        if let Some((element, mode)) = loader.skipped {
            return Err(Error::UnsupportedMode { path: path.into(), element, mode });
        }
    }
    match loader.grouped.take() {
        None => Ok(Loaded::One(loader.mesh)),
        Some(grouped) => loader.instanced(grouped),
    }
}

pub(super) struct Loader<'a> {
    path: &'a Path,
    options: &'a LoadOptions,
    /// The folder external buffers and images are read from.
    base: Option<&'a Path>,
    document: &'a gltf::Document,
    buffers: &'a [Buffer<'a>],
    /// Bytes of the document and its buffers: what bounds the elements an accessor
    /// without a buffer view may declare.
    input_bytes: usize,
    mesh: Mesh,
    /// Where each material's texture coordinates come from.
    /// Each glTF material's texture-coordinate channels (its distinct sets and
    /// transforms, [`octrace_format::Material::uv_channels`]).
    uv_maps: Vec<Vec<UvMap>>,
    /// The first primitive skipped for its mode, for the error when nothing else is left.
    skipped: Option<(String, String)>,
    /// Index of glTF's default material, once a primitive without one needed it.
    default_material: Option<u32>,
    /// The meshes placed more than once, kept apart while the scene is walked.
    grouped: Option<instances::Grouped>,
    /// Where each glTF material is in `mesh.materials`, for a mesh that holds only
    /// some (a group's scene); `None`: each at its glTF index.
    slots: Option<std::collections::HashMap<usize, u32>>,
}

impl Loader<'_> {
    /// Where glTF material `index` is in the mesh's materials, if it is there.
    fn slot(&self, index: usize) -> Option<u32> {
        match &self.slots {
            None => (index < self.mesh.materials.len()).then_some(index as u32),
            Some(slots) => slots.get(&index).copied(),
        }
    }
}

/// A `f64` vector rounded to `f32`.
fn to_f32(v: glam::DVec3) -> [f32; 3] {
    [v.x as f32, v.y as f32, v.z as f32]
}
