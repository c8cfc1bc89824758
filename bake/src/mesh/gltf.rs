//! glTF 2.0 through the `gltf` crate: the default scene's mesh primitives, node
//! transforms applied; triangle lists, strips and fans; other modes skipped.

use std::path::Path;

use glam::{DMat4, DVec3};
use gltf::mesh::Mode;

use super::{check_finite, Mesh};
use crate::error::{Error, Result};

pub(super) fn parse(bytes: &[u8], path: &Path, base: Option<&Path>) -> Result<Mesh> {
    // The gltf crate (gltf-json 1.4) indexes arrays with unchecked indices while it
    // validates, and panics on some malformed files (a POSITION accessor index out of
    // range, found by fuzzing). A panic there is a malformed file, not a bug of ours:
    // it becomes a parse error.
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| parse_unguarded(bytes, path, base))).unwrap_or_else(|_| {
        Err(Error::Parse {
            path: path.into(),
            element: "document".into(),
            message: "malformed glTF (an index out of range made the glTF parser give up)".into(),
        })
    })
}

fn parse_unguarded(bytes: &[u8], path: &Path, base: Option<&Path>) -> Result<Mesh> {
    let parse_error = |element: &str, e: gltf::Error| Error::Parse {
        path: path.into(),
        element: element.into(),
        message: e.to_string(),
    };
    let gltf::Gltf { document, blob } =
        gltf::Gltf::from_slice_without_validation(bytes).map_err(|e| parse_error("document", e))?;
    // gltf-json's validation reads `accessors[i]` for every primitive attribute before
    // checking `i`: refuse out-of-range accessor indices first, then validate.
    let json = document.into_json();
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
    // gltf's import unwraps the percent-decoding of a file URI as UTF-8: check first.
    for buffer in document.buffers() {
        if let gltf::buffer::Source::Uri(uri) = buffer.source() {
            if !uri.starts_with("data:") && !percent_decodes_to_utf8(uri) {
                return Err(Error::Parse {
                    path: path.into(),
                    element: format!("buffer {}", buffer.index()),
                    message: "URI does not decode to UTF-8".into(),
                });
            }
        }
    }
    let buffers = gltf::import_buffers(&document, base, blob).map_err(|e| parse_error("buffers", e))?;
    // The default scene, or scene 0 when the file names none.
    let Some(scene) = document.default_scene().or_else(|| document.scenes().next()) else {
        return Err(Error::EmptyScene { path: path.into() });
    };
    let input_bytes = bytes.len() + buffers.iter().map(|b| b.0.len()).sum::<usize>();
    let mut loader = Loader { path, buffers: &buffers, input_bytes, mesh: Mesh::default(), skipped: None };
    for node in scene.nodes() {
        loader.node(&node, DMat4::IDENTITY, 0)?;
    }
    if loader.mesh.triangles.is_empty() {
        if let Some((element, mode)) = loader.skipped {
            return Err(Error::UnsupportedMode { path: path.into(), element, mode });
        }
    }
    Ok(loader.mesh)
}

/// Whether `%XX` escapes in `uri` decode to valid UTF-8 (malformed escapes are left
/// as they are, as percent-decoders do).
fn percent_decodes_to_utf8(uri: &str) -> bool {
    let b = uri.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        let hex = |c: u8| (c as char).to_digit(16);
        match (b[i], b.get(i + 1).and_then(|&c| hex(c)), b.get(i + 2).and_then(|&c| hex(c))) {
            (b'%', Some(h), Some(l)) => {
                out.push((h * 16 + l) as u8);
                i += 3;
            }
            (c, _, _) => {
                out.push(c);
                i += 1;
            }
        }
    }
    String::from_utf8(out).is_ok()
}

struct Loader<'a> {
    path: &'a Path,
    buffers: &'a [gltf::buffer::Data],
    /// Bytes of the document and its buffers: what bounds the elements an accessor
    /// without a buffer view may declare.
    input_bytes: usize,
    mesh: Mesh,
    /// The first primitive skipped for its mode, for the error when nothing else is left.
    skipped: Option<(String, String)>,
}

/// Node hierarchies deeper than this are refused (a cycle, or a hostile file).
const MAX_NODE_DEPTH: usize = 256;

/// An accessor may declare at most this many elements per byte of input (document and
/// buffers) beyond [`VIEWLESS_SLACK`]: an accessor without a buffer view (all zeros,
/// perhaps with sparse values) is not backed by bytes, and its count is what the
/// reader allocates.
const ELEMENTS_PER_INPUT_BYTE: usize = 16;
/// Elements any accessor may declare whatever the input's size.
const VIEWLESS_SLACK: usize = 1 << 16;

/// Checks that `bytes` bytes of `elem`-byte elements, `stride` apart, from `offset`
/// fit in a buffer view of `view_len` bytes, and that the view fits in its buffer.
fn check_range(
    view: &gltf::buffer::View<'_>,
    buffers: &[gltf::buffer::Data],
    offset: usize,
    count: usize,
    elem: usize,
) -> std::result::Result<(), String> {
    let stride = view.stride().unwrap_or(elem);
    if stride < elem {
        return Err(format!("buffer view {} has stride {stride}, less than the element's {elem} bytes", view.index()));
    }
    let end = count
        .checked_sub(1)
        .and_then(|n| n.checked_mul(stride))
        .and_then(|n| n.checked_add(elem))
        .and_then(|n| n.checked_add(offset))
        .ok_or_else(|| format!("{count} elements of {elem} bytes, stride {stride}, overflow"))?;
    if end > view.length() {
        return Err(format!(
            "{count} elements of {elem} bytes from offset {offset} (stride {stride}) need {end} bytes, buffer view {} has {}",
            view.index(),
            view.length()
        ));
    }
    let buffer = view.buffer().index();
    let available = buffers.get(buffer).map_or(0, |d| d.0.len());
    match view.offset().checked_add(view.length()) {
        Some(view_end) if view_end <= available => Ok(()),
        _ => Err(format!(
            "buffer view {} ({} bytes at {}) runs past buffer {buffer} ({available} bytes)",
            view.index(),
            view.length(),
            view.offset()
        )),
    }
}

impl Loader<'_> {
    /// Every range the reader will touch for `a`, and its count against the input size.
    fn check_accessor(&self, a: &gltf::Accessor<'_>) -> std::result::Result<(), String> {
        let count = a.count();
        if count == 0 {
            return Err("count is 0 (the glTF spec requires at least 1)".into());
        }
        let limit = self.input_bytes.saturating_mul(ELEMENTS_PER_INPUT_BYTE).saturating_add(VIEWLESS_SLACK);
        if count > limit {
            return Err(format!(
                "declares {count} elements, more than {limit} for an input of {} bytes",
                self.input_bytes
            ));
        }
        if let Some(view) = a.view() {
            check_range(&view, self.buffers, a.offset(), count, a.size())?;
        }
        if let Some(sparse) = a.sparse() {
            let n = sparse.count();
            if n == 0 || n > count {
                return Err(format!("sparse count {n} outside 1..={count}"));
            }
            let indices = sparse.indices();
            check_range(&indices.view(), self.buffers, indices.offset(), n, indices.index_type().size())
                .map_err(|e| format!("sparse indices: {e}"))?;
            let values = sparse.values();
            check_range(&values.view(), self.buffers, values.offset(), n, a.size())
                .map_err(|e| format!("sparse values: {e}"))?;
        }
        Ok(())
    }

    fn node(&mut self, node: &gltf::Node<'_>, parent: DMat4, depth: usize) -> Result<()> {
        if depth > MAX_NODE_DEPTH {
            return Err(Error::Parse {
                path: self.path.into(),
                element: format!("node {}", node.index()),
                message: format!("node hierarchy deeper than {MAX_NODE_DEPTH}"),
            });
        }
        let local = node.transform().matrix().map(|c| c.map(f64::from));
        let world = parent * DMat4::from_cols_array_2d(&local);
        if let Some(mesh) = node.mesh() {
            for prim in mesh.primitives() {
                let element = format!("node {} mesh {} primitive {}", node.index(), mesh.index(), prim.index());
                self.primitive(&prim, &world, element)?;
            }
        }
        for child in node.children() {
            self.node(&child, world, depth + 1)?;
        }
        Ok(())
    }

    fn primitive(&mut self, prim: &gltf::Primitive<'_>, world: &DMat4, element: String) -> Result<()> {
        let mode = prim.mode();
        if !matches!(mode, Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan) {
            let name = format!("{mode:?}");
            self.mesh.warnings.push(format!("{}: {element}: skipped {name} primitive", self.path.display()));
            self.skipped.get_or_insert((element, name));
            return Ok(());
        }
        // The spec's types, checked before the gltf crate reads (it panics on others).
        use gltf::accessor::{DataType, Dimensions};
        let bad_type = |what: &str| Error::Parse {
            path: self.path.into(),
            element: element.clone(),
            message: format!("{what} accessor has a type the glTF spec does not allow"),
        };
        if prim.indices().is_some_and(|a| !matches!(a.data_type(), DataType::U8 | DataType::U16 | DataType::U32)) {
            return Err(bad_type("index"));
        }
        if prim
            .get(&gltf::Semantic::Positions)
            .is_some_and(|a| a.data_type() != DataType::F32 || a.dimensions() != Dimensions::Vec3)
        {
            return Err(bad_type("POSITION"));
        }
        // The gltf crate's reader trusts counts, offsets and strides (it panics or
        // allocates what a count declares): every range is checked here first.
        for (what, accessor) in [("index", prim.indices()), ("POSITION", prim.get(&gltf::Semantic::Positions))] {
            if let Some(a) = accessor {
                self.check_accessor(&a).map_err(|message| Error::Parse {
                    path: self.path.into(),
                    element: format!("{element}: {what} accessor {}", a.index()),
                    message,
                })?;
            }
        }
        let reader = prim.reader(|b| self.buffers.get(b.index()).map(|d| &d.0[..]));
        let Some(positions) = reader.read_positions() else {
            self.mesh.warnings.push(format!("{}: {element}: no POSITION, skipped", self.path.display()));
            return Ok(());
        };
        let mut verts = Vec::with_capacity(positions.len());
        for (i, p) in positions.enumerate() {
            check_finite(p, self.path, || format!("{element}, vertex {i}"))?;
            let w = world.transform_point3(DVec3::from(p.map(f64::from)));
            let v = [w.x as f32, w.y as f32, w.z as f32];
            check_finite(v, self.path, || format!("{element}, vertex {i} after the node transform"))?;
            verts.push(v);
        }
        let indices: Vec<u32> = match reader.read_indices() {
            Some(idx) => idx.into_u32().collect(),
            None => (0..verts.len() as u32).collect(),
        };
        if let Some(&bad) = indices.iter().find(|&&i| i as usize >= verts.len()) {
            return Err(Error::IndexOutOfRange {
                path: self.path.into(),
                element,
                index: bad as i64,
                count: verts.len(),
            });
        }
        let v = |i: u32| verts[i as usize];
        let tris = &mut self.mesh.triangles;
        match mode {
            Mode::Triangles => tris.extend(indices.chunks_exact(3).map(|t| [v(t[0]), v(t[1]), v(t[2])])),
            // Every other strip triangle swaps its first two corners to keep the winding.
            Mode::TriangleStrip => tris.extend(indices.windows(3).enumerate().map(|(k, t)| {
                if k % 2 == 0 {
                    [v(t[0]), v(t[1]), v(t[2])]
                } else {
                    [v(t[1]), v(t[0]), v(t[2])]
                }
            })),
            _ => {
                if let Some((&first, rest)) = indices.split_first() {
                    tris.extend(rest.windows(2).map(|t| [v(first), v(t[0]), v(t[1])]));
                }
            }
        }
        Ok(())
    }
}
