//! glTF 2.0 through the `gltf` crate: the default scene's mesh primitives, node
//! transforms applied; triangle lists, strips and fans; other modes skipped.

mod lenient;
mod material;

use std::path::Path;

use glam::{DMat4, DVec3};
use gltf::mesh::Mode;

use octrace_format::{Camera, Light, LightKind, Material};

use super::refs::{self, LoadOptions};
use super::{check_finite, Mesh};
use crate::error::{Error, Result};
use material::UvMap;
use std::borrow::Cow;

/// A buffer's bytes: borrowed from the file for a GLB's binary chunk, else owned.
pub(super) type Buffer<'a> = Cow<'a, [u8]>;

pub(super) fn parse(bytes: &[u8], path: &Path, base: Option<&Path>, options: &LoadOptions) -> Result<Mesh> {
    // The gltf crate (gltf-json 1.4) indexes arrays with unchecked indices while it
    // validates, and panics on some malformed files (a POSITION accessor index out of
    // range, found by fuzzing). A panic there is a malformed file, not a bug of ours:
    // it becomes a parse error.
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| parse_unguarded(bytes, path, base, options)))
        .unwrap_or_else(|_| {
            Err(Error::Parse {
                path: path.into(),
                element: "document".into(),
                message: "malformed glTF (an index out of range made the glTF parser give up)".into(),
            })
        })
}

fn parse_unguarded(bytes: &[u8], path: &Path, base: Option<&Path>, options: &LoadOptions) -> Result<Mesh> {
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
    let mut mesh = Mesh { sources, warnings, ..Mesh::default() };
    let mut materials = material::Materials {
        path,
        base,
        options,
        buffers: &buffers,
        loaded: Default::default(),
        kept: Default::default(),
    };
    let mut uv_maps = Vec::new();
    for m in document.materials() {
        let (m, uv) = materials.material(&m, &mut mesh)?;
        mesh.materials.push(m);
        uv_maps.push(uv);
    }
    let mut loader =
        Loader { path, buffers: &buffers, input_bytes, mesh, uv_maps, skipped: None, default_material: None };
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

/// Why a scene's placements were not counted.
enum Placements {
    /// The hierarchy has a cycle through this node.
    Cycle(usize),
    /// The placements passed the budget at this node, having reached `total`.
    Over { node: usize, total: u64 },
}

/// How many times the scene places each node (a child listed twice, or under two
/// parents, is placed once for each listing, its children with it), counted over the
/// hierarchy's edges before it is walked: a small file whose nodes share children may
/// ask for 2^60 placements.
fn placements(
    document: &gltf::Document,
    scene: &gltf::Scene<'_>,
    limit: u64,
) -> std::result::Result<Vec<u64>, Placements> {
    let n = document.nodes().len();
    let children: Vec<Vec<usize>> = document.nodes().map(|node| node.children().map(|c| c.index()).collect()).collect();
    // Depth first from the scene's roots: the nodes reached in post-order, a cycle
    // refused as it is met (a child already on the path).
    let (new, open, done) = (0u8, 1u8, 2u8);
    let mut state = vec![new; n];
    let mut order = Vec::with_capacity(n);
    for root in scene.nodes().map(|r| r.index()) {
        if state[root] != new {
            continue;
        }
        state[root] = open;
        let mut path = vec![(root, 0usize)];
        while let Some(&(node, next)) = path.last() {
            match children[node].get(next) {
                Some(&child) => {
                    if let Some(top) = path.last_mut() {
                        top.1 += 1;
                    }
                    if state[child] == open {
                        return Err(Placements::Cycle(child));
                    }
                    if state[child] == new {
                        state[child] = open;
                        path.push((child, 0));
                    }
                }
                None => {
                    state[node] = done;
                    order.push(node);
                    path.pop();
                }
            }
        }
    }
    // Parents before children (the reverse post-order): each node's count is whole
    // when it is reached.
    let mut count = vec![0u64; n];
    for root in scene.nodes() {
        count[root.index()] += 1;
    }
    let mut total = 0u64;
    for &node in order.iter().rev() {
        let c = count[node];
        total = total.saturating_add(c);
        if total > limit {
            return Err(Placements::Over { node, total });
        }
        for &child in &children[node] {
            count[child] = count[child].saturating_add(c);
        }
    }
    Ok(count)
}

/// The triangles the placed meshes make, from their accessors' counts (a list's
/// indices or positions over 3; a strip's or fan's less 2; other modes none).
fn instanced_triangles(document: &gltf::Document, placed: &[u64]) -> u64 {
    use gltf::mesh::Mode;
    let per_mesh: Vec<u64> = document
        .meshes()
        .map(|m| {
            m.primitives()
                .map(|p| {
                    let vertices =
                        p.indices().or_else(|| p.get(&gltf::Semantic::Positions)).map_or(0, |a| a.count() as u64);
                    match p.mode() {
                        Mode::Triangles => vertices / 3,
                        Mode::TriangleStrip | Mode::TriangleFan => vertices.saturating_sub(2),
                        _ => 0,
                    }
                })
                .fold(0u64, u64::saturating_add)
        })
        .collect();
    document
        .nodes()
        .filter_map(|node| Some(placed[node.index()].saturating_mul(per_mesh[node.mesh()?.index()])))
        .fold(0, u64::saturating_add)
}

/// Every buffer's bytes: the GLB blob, a `data:` URI, or a file the URI names, read
/// only where `options` allow (`refs::resolve`) and only if it is a regular file within
/// the size limit. A buffer shorter than its declared length is an error.
fn load_buffers<'a>(
    document: &gltf::Document,
    mut blob: Option<Buffer<'a>>,
    path: &Path,
    base: Option<&Path>,
    options: &LoadOptions,
    sources: &mut Vec<std::path::PathBuf>,
) -> Result<Vec<Buffer<'a>>> {
    let mut out = Vec::new();
    for buffer in document.buffers() {
        let element = || format!("buffer {}", buffer.index());
        let mut data = match buffer.source() {
            gltf::buffer::Source::Bin => blob.take().ok_or_else(|| Error::Parse {
                path: path.into(),
                element: element(),
                message: "refers to the GLB binary chunk, which the file lacks (or an earlier buffer took)".into(),
            })?,
            gltf::buffer::Source::Uri(uri) if uri.starts_with("data:") => {
                Cow::Owned(data_uri(uri).map_err(|message| Error::Parse {
                    path: path.into(),
                    element: element(),
                    message,
                })?)
            }
            gltf::buffer::Source::Uri(uri) => {
                let refused = |reason: String| Error::Reference {
                    path: path.into(),
                    element: element(),
                    reference: uri.chars().take(200).collect(),
                    reason,
                };
                let target = uri_path(uri).map_err(&refused)?;
                let file = refs::resolve(base, Path::new(&target), options.references).map_err(&refused)?;
                let data = octrace_format::read_regular_file(&file, options.max_file_bytes)
                    .map_err(|e| refused(e.to_string()))?;
                sources.push(file);
                Cow::Owned(data)
            }
        };
        if data.len() < buffer.length() {
            return Err(Error::Parse {
                path: path.into(),
                element: element(),
                message: format!("{} bytes, but its byteLength says {}", data.len(), buffer.length()),
            });
        }
        while data.len() % 4 != 0 {
            data.to_mut().push(0);
        }
        out.push(data);
    }
    Ok(out)
}

/// The bytes of a `data:` URI (RFC 2397): `data:[type][;base64],DATA`, base64 or
/// percent-encoded.
pub(super) fn data_uri(uri: &str) -> std::result::Result<Vec<u8>, String> {
    let rest = &uri["data:".len().min(uri.len())..];
    let Some((head, data)) = rest.split_once(',') else {
        return Err("a data: URI without the ',' that starts its data".into());
    };
    if head.ends_with(";base64") {
        return base64_decode(data).map_err(|at| {
            format!("a base64 data: URI with a character base64 does not have at position {at} of its data")
        });
    }
    refs::percent_decode_bytes(data).ok_or_else(|| "a data: URI with a broken %-escape".into())
}

/// Standard base64 (padding optional), or the position of the first character that is
/// not.
fn base64_decode(text: &str) -> std::result::Result<Vec<u8>, usize> {
    let value = |c: u8| match c {
        b'A'..=b'Z' => Some(c - b'A'),
        b'a'..=b'z' => Some(c - b'a' + 26),
        b'0'..=b'9' => Some(c - b'0' + 52),
        b'+' => Some(62),
        b'/' => Some(63),
        _ => None,
    };
    let bytes = text.trim_end_matches('=').as_bytes();
    let mut out = Vec::with_capacity(bytes.len() * 3 / 4);
    let (mut acc, mut bits) = (0u32, 0);
    for (i, &c) in bytes.iter().enumerate() {
        acc = (acc << 6) | value(c).ok_or(i)? as u32;
        bits += 6;
        if bits >= 8 {
            bits -= 8;
            out.push((acc >> bits) as u8);
        }
    }
    Ok(out)
}

/// The path a buffer URI names: `file:` URIs and relative references, percent-decoded;
/// other schemes are refused.
pub(super) fn uri_path(uri: &str) -> std::result::Result<String, String> {
    // file://HOST/PATH names PATH on HOST: an absolute path on this machine for an
    // empty host or localhost, refused for any other.
    let local = |rest: &str| -> std::result::Result<String, String> {
        let (host, path) = rest.split_at(rest.find('/').unwrap_or(rest.len()));
        if host.is_empty() || host.eq_ignore_ascii_case("localhost") {
            Ok(path.to_string())
        } else {
            Err(format!("a file: URI on another host ('{host}')"))
        }
    };
    let owned;
    let rest = match uri.strip_prefix("file://") {
        Some(rest) => {
            owned = local(rest)?;
            Some(owned.as_str())
        }
        None => uri.strip_prefix("file:"),
    };
    let rest = match rest {
        Some(rest) => rest,
        None if uri.contains(':') => return Err("not a relative path, a file: URI or a data: URI".into()),
        None => uri,
    };
    refs::percent_decode(rest).ok_or_else(|| "does not decode to UTF-8".to_string())
}

struct Loader<'a> {
    path: &'a Path,
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
    buffers: &[Buffer<'_>],
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
    let available = buffers.get(buffer).map_or(0, |d| d.len());
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
        if let Some(light) = node.light() {
            self.light(&light, &world, node.index())?;
        }
        if let Some(camera) = node.camera() {
            self.camera(&camera, &world, node.index());
        }
        if let Some(mesh) = node.mesh() {
            for prim in mesh.primitives() {
                let element = format!("node {} mesh {} primitive {}", node.index(), mesh.index(), prim.index());
                self.primitive(&prim, &world, element)?;
                let quoted = |name: Option<&str>| name.map(|n| format!(" '{n}'")).unwrap_or_default();
                let source = octrace_format::PartSource::Gltf {
                    node: node.index() as u32,
                    mesh: mesh.index() as u32,
                    primitive: prim.index() as u32,
                };
                self.mesh.end_part(source, || {
                    format!(
                        "node {}{}, mesh {}{}, primitive {}",
                        node.index(),
                        quoted(node.name()),
                        mesh.index(),
                        quoted(mesh.name()),
                        prim.index()
                    )
                });
            }
        }
        for child in node.children() {
            self.node(&child, world, depth + 1)?;
        }
        Ok(())
    }

    /// A `KHR_lights_punctual` light placed by `world`: at its origin, shining along
    /// its `-z` axis.
    fn light(&mut self, light: &gltf::khr_lights_punctual::Light<'_>, world: &DMat4, node: usize) -> Result<()> {
        use gltf::khr_lights_punctual::Kind;
        let name = light.name().map_or_else(|| format!("light {}", light.index()), str::to_string);
        let (kind, inner, outer) = match light.kind() {
            Kind::Point => (LightKind::Point, 0.0, 0.0),
            Kind::Directional => (LightKind::Directional, 0.0, 0.0),
            Kind::Spot { inner_cone_angle, outer_cone_angle } => {
                let outer = outer_cone_angle.clamp(0.0, std::f32::consts::FRAC_PI_2);
                (LightKind::Spot, inner_cone_angle.clamp(0.0, outer), outer)
            }
        };
        let out = Light {
            kind,
            color: light.color().map(|c| c.clamp(0.0, 1.0)),
            intensity: light.intensity().max(0.0),
            position: to_f32(world.transform_point3(DVec3::ZERO)),
            direction: to_f32(world.transform_vector3(DVec3::NEG_Z).normalize_or_zero()),
            range: light.range().filter(|r| *r > 0.0).unwrap_or(f32::INFINITY),
            inner_cone: inner,
            outer_cone: outer,
            name,
        };
        let numbers = out.color.iter().chain(&out.position).chain(&out.direction).chain([&out.intensity]);
        if numbers.into_iter().any(|v| !v.is_finite()) || out.range.is_nan() || out.direction == [0.0; 3] {
            return Err(Error::Parse {
                path: self.path.into(),
                element: format!("node {node}, light '{}'", out.name),
                message: "a value is not finite, or the node's transform collapses the light's direction".into(),
            });
        }
        self.mesh.lights.push(out);
        Ok(())
    }

    /// A camera placed by `world` (glTF cameras look along `-z`, up `+y`), perspective
    /// or orthographic (its `ymag` the half height of view, `xmag / ymag` the aspect);
    /// a degenerate transform or view is skipped with a warning.
    fn camera(&mut self, camera: &gltf::Camera<'_>, world: &DMat4, node: usize) {
        let name = camera.name().map_or_else(|| format!("camera {}", camera.index()), str::to_string);
        let (yfov, aspect, orthographic) = match camera.projection() {
            gltf::camera::Projection::Perspective(p) => (p.yfov(), p.aspect_ratio(), None),
            // yfov is unused by an orthographic camera; it holds a valid angle.
            gltf::camera::Projection::Orthographic(o) => {
                (std::f32::consts::FRAC_PI_4, Some(o.xmag().abs() / o.ymag().abs()), Some(o.ymag().abs()))
            }
        };
        let forward = world.transform_vector3(DVec3::NEG_Z).normalize_or_zero();
        let up = world.transform_vector3(DVec3::Y);
        let up = (up - forward * up.dot(forward)).normalize_or_zero();
        let out = Camera {
            position: to_f32(world.transform_point3(DVec3::ZERO)),
            forward: to_f32(forward),
            up: to_f32(up),
            yfov,
            aspect,
            orthographic,
            name,
        };
        let finite = out.position.iter().chain([&out.yfov]).chain(out.aspect.as_ref()).all(|v| v.is_finite());
        let fov_ok = out.yfov > 0.0 && out.yfov < std::f32::consts::PI && out.aspect.is_none_or(|a| a > 0.0);
        let ortho_ok = out.orthographic.is_none_or(|h| h.is_finite() && h > 0.0);
        if !finite || !fov_ok || !ortho_ok || forward == DVec3::ZERO || up == DVec3::ZERO {
            self.mesh.warnings.push(format!(
                "{}: node {node}: camera '{}' skipped (degenerate transform or field of view)",
                self.path.display(),
                out.name
            ));
            return;
        }
        self.mesh.cameras.push(out);
    }

    /// The primitive's `NORMAL`s in world space (the inverse transpose of `world`),
    /// when it has usable ones: an attribute of the wrong type, a short one, or one
    /// whose ranges do not fit its buffer is left out with a warning.
    fn normals(
        &mut self,
        prim: &gltf::Primitive<'_>,
        world: &DMat4,
        vertices: usize,
        element: &str,
    ) -> Option<Vec<[f32; 3]>> {
        use gltf::accessor::{DataType, Dimensions};
        let a = prim.get(&gltf::Semantic::Normals)?;
        let usable = a.data_type() == DataType::F32 && a.dimensions() == Dimensions::Vec3;
        if let Err(why) = self.attribute_usable(&a, usable, vertices) {
            self.mesh.warnings.push(format!("{}: {element}: NORMAL left out: {why}", self.path.display()));
            return None;
        }
        let reader = prim.reader(|b| self.buffers.get(b.index()).map(|d| &d[..]));
        let normal_matrix = glam::DMat3::from_mat4(*world).inverse().transpose();
        let out = reader.read_normals()?.take(vertices).map(|n| {
            let w = (normal_matrix * DVec3::from(n.map(f64::from))).normalize_or_zero();
            to_f32(if w.is_finite() { w } else { DVec3::ZERO })
        });
        Some(out.collect())
    }

    /// The tangents of a normal-mapped primitive's triangles' corners, world space:
    /// the file's `TANGENT` (through `world`'s linear part, the sign reversed where it
    /// mirrors), else MikkTSpace's from the world-space positions, normals and
    /// texture coordinates, as the glTF spec asks (coordinates given with `v` up, so
    /// that `w (n x t)` points up the image, glTF's green).
    fn tangents(
        &mut self,
        prim: &gltf::Primitive<'_>,
        world: &DMat4,
        corners: &Corners<'_>,
        element: &str,
    ) -> Vec<[[f32; 4]; 3]> {
        use gltf::accessor::{DataType, Dimensions};
        if let Some(a) = prim.get(&gltf::Semantic::Tangents) {
            let usable = a.data_type() == DataType::F32 && a.dimensions() == Dimensions::Vec4;
            match self.attribute_usable(&a, usable, corners.verts.len()) {
                Ok(()) => {
                    let reader = prim.reader(|b| self.buffers.get(b.index()).map(|d| &d[..]));
                    let linear = glam::DMat3::from_mat4(*world);
                    let mirror = if linear.determinant() < 0.0 { -1.0 } else { 1.0 };
                    let per_vertex: Vec<[f32; 4]> = reader
                        .read_tangents()
                        .into_iter()
                        .flatten()
                        .take(corners.verts.len())
                        .map(|t| {
                            let d = (linear * DVec3::from([t[0], t[1], t[2]].map(f64::from))).normalize_or_zero();
                            match d.is_finite() && t[3].is_finite() && t[3] != 0.0 {
                                true => [d.x as f32, d.y as f32, d.z as f32, t[3].signum() * mirror as f32],
                                false => [0.0; 4],
                            }
                        })
                        .collect();
                    if per_vertex.len() == corners.verts.len() {
                        return (0..corners.count)
                            .map(|k| (corners.corner)(k).map(|i| per_vertex[i as usize]))
                            .collect();
                    }
                }
                Err(why) => self.mesh.warnings.push(format!(
                    "{}: {element}: TANGENT left out ({why}): MikkTSpace tangents instead",
                    self.path.display()
                )),
            }
        }
        let mut out = MikkTSpace { corners, tangents: vec![[[0.0; 4]; 3]; corners.count] };
        // The crate's error type has no values: it cannot fail.
        let _ = bevy_mikktspace::generate_tangents(&mut out);
        out.tangents
    }

    /// The primitive's texture coordinates in one of its material's channels, when it
    /// has usable ones (as [`Loader::normals`]): the set `map` reads, through its
    /// transform.
    fn uvs(&mut self, prim: &gltf::Primitive<'_>, map: UvMap, vertices: usize, element: &str) -> Option<Vec<[f32; 2]>> {
        use gltf::accessor::{DataType, Dimensions};
        let a = prim.get(&gltf::Semantic::TexCoords(map.set))?;
        let usable = matches!(a.data_type(), DataType::F32 | DataType::U8 | DataType::U16)
            && a.dimensions() == Dimensions::Vec2
            && (a.data_type() == DataType::F32 || a.normalized());
        if let Err(why) = self.attribute_usable(&a, usable, vertices) {
            self.mesh.warnings.push(format!(
                "{}: {element}: TEXCOORD_{} left out: {why}",
                self.path.display(),
                map.set
            ));
            return None;
        }
        let reader = prim.reader(|b| self.buffers.get(b.index()).map(|d| &d[..]));
        let out = reader.read_tex_coords(map.set)?.into_f32().take(vertices);
        Some(out.map(|t| if t.iter().all(|v| v.is_finite()) { map.apply(t) } else { [0.0; 2] }).collect())
    }

    /// The primitive's `COLOR_0` (RGB or RGBA; floats, or normalized unsigned bytes or
    /// shorts), linear, at 16 bits a channel, when it has usable ones (as
    /// [`Loader::normals`]).
    fn colors(&mut self, prim: &gltf::Primitive<'_>, vertices: usize, element: &str) -> Option<Vec<[u16; 4]>> {
        use gltf::accessor::{DataType, Dimensions};
        let a = prim.get(&gltf::Semantic::Colors(0))?;
        let usable = matches!(a.data_type(), DataType::F32 | DataType::U8 | DataType::U16)
            && matches!(a.dimensions(), Dimensions::Vec3 | Dimensions::Vec4)
            && (a.data_type() == DataType::F32 || a.normalized());
        if let Err(why) = self.attribute_usable(&a, usable, vertices) {
            self.mesh.warnings.push(format!("{}: {element}: COLOR_0 left out: {why}", self.path.display()));
            return None;
        }
        let reader = prim.reader(|b| self.buffers.get(b.index()).map(|d| &d[..]));
        let out = reader.read_colors(0)?.into_rgba_f32().take(vertices);
        let channel = |c: f32| if c.is_finite() { (c.clamp(0.0, 1.0) * 65535.0).round() as u16 } else { u16::MAX };
        Some(out.map(|c| c.map(channel)).collect())
    }

    /// Whether a vertex attribute can be read: the spec's type, ranges inside the
    /// buffers, and one value a vertex.
    fn attribute_usable(
        &self,
        a: &gltf::Accessor<'_>,
        type_ok: bool,
        vertices: usize,
    ) -> std::result::Result<(), String> {
        if !type_ok {
            return Err("a type the glTF spec does not allow".into());
        }
        self.check_accessor(a)?;
        if a.count() < vertices {
            return Err(format!("{} values for {vertices} vertices", a.count()));
        }
        Ok(())
    }

    /// The material index of a primitive: its glTF material, or glTF's default one.
    fn material_of(&mut self, prim: &gltf::Primitive<'_>) -> u32 {
        match prim.material().index() {
            Some(i) if i < self.mesh.materials.len() => i as u32,
            _ => *self.default_material.get_or_insert_with(|| {
                self.mesh.materials.push(Material::default());
                self.mesh.materials.len() as u32 - 1
            }),
        }
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
        let reader = prim.reader(|b| self.buffers.get(b.index()).map(|d| &d[..]));
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
        // Without indices, vertex j is index j: nothing is made for them.
        let indices: Option<Vec<u32>> = reader.read_indices().map(|idx| idx.into_u32().collect());
        if let Some(&bad) = indices.iter().flatten().find(|&&i| i as usize >= verts.len()) {
            return Err(Error::IndexOutOfRange {
                path: self.path.into(),
                element,
                index: bad as i64,
                count: verts.len(),
            });
        }
        let index = |j: usize| indices.as_ref().map_or(j as u32, |i| i[j]);
        let n = indices.as_ref().map_or(verts.len(), Vec::len);
        // Corner indices of triangle k, in the file's winding (no list of them is
        // made: a big primitive's would be as large as its indices).
        let (count, corner): (usize, &dyn Fn(usize) -> [u32; 3]) = match mode {
            Mode::Triangles => (n / 3, &|k| [index(3 * k), index(3 * k + 1), index(3 * k + 2)]),
            // Every other strip triangle swaps its first two corners to keep the winding.
            Mode::TriangleStrip => (n.saturating_sub(2), &|k| {
                let t = [index(k), index(k + 1), index(k + 2)];
                if k % 2 == 0 {
                    t
                } else {
                    [t[1], t[0], t[2]]
                }
            }),
            _ => (n.saturating_sub(2), &|k| [index(0), index(k + 1), index(k + 2)]),
        };
        let normals = self.normals(prim, world, verts.len(), &element);
        // A channel for each distinct set and transform the material's textures read.
        let maps = prim.material().index().and_then(|i| self.uv_maps.get(i)).cloned();
        let maps = maps.unwrap_or_else(|| vec![UvMap { set: 0, transform: None }]);
        let mut channels: Vec<_> = maps.iter().map(|&map| self.uvs(prim, map, verts.len(), &element)).collect();
        let uvs = channels.first_mut().and_then(Option::take);
        let colors = self.colors(prim, verts.len(), &element);
        let material = self.material_of(prim);
        let normal_mapped = self.mesh.materials.get(material as usize).filter(|m| m.normal_texture.is_some());
        // The coordinates the normal texture reads.
        let normal_uvs = match normal_mapped.map(|m| m.uv_channel(4)) {
            Some(0) => uvs.as_ref(),
            Some(c) => channels.get(c).and_then(Option::as_ref),
            None => None,
        };
        let tangents = match (normal_uvs, &normals) {
            (Some(uvs), Some(normals)) => {
                let corners = Corners { verts: &verts, normals, uvs, count, corner };
                Some(self.tangents(prim, world, &corners, &element))
            }
            _ => None,
        };
        // Room for them all at once: growing by doubling holds up to three times a
        // big primitive's triangles while it copies.
        self.mesh.triangles.reserve(count);
        self.mesh.material_ids.reserve(count);
        for c in (0..count).map(corner) {
            let tri = c.map(|i| verts[i as usize]);
            let n = normals.as_ref().map(|n| c.map(|i| n[i as usize]));
            let t = uvs.as_ref().map(|t| c.map(|i| t[i as usize]));
            let k = colors.as_ref().map(|k| c.map(|i| k[i as usize]));
            self.mesh.push_colored(tri, n, t, k);
            self.mesh.material_ids.push(material);
        }
        if let Some(tangents) = tangents {
            self.mesh.push_tangents(tangents, count);
        }
        for (c, values) in channels.iter().enumerate().skip(1) {
            if let Some(values) = values {
                let corners = (0..count).map(corner).map(|t| t.map(|i| values[i as usize])).collect();
                self.mesh.push_uv_channel(c, corners, count);
            }
        }
        Ok(())
    }
}

/// A `f64` vector rounded to `f32`.
fn to_f32(v: DVec3) -> [f32; 3] {
    [v.x as f32, v.y as f32, v.z as f32]
}

/// A primitive's triangles as corners of its vertex arrays (world space).
struct Corners<'a> {
    verts: &'a [[f32; 3]],
    normals: &'a [[f32; 3]],
    uvs: &'a [[f32; 2]],
    count: usize,
    corner: &'a dyn Fn(usize) -> [u32; 3],
}

/// MikkTSpace's view of a primitive, and the tangents it gives each corner.
struct MikkTSpace<'a> {
    corners: &'a Corners<'a>,
    tangents: Vec<[[f32; 4]; 3]>,
}

impl MikkTSpace<'_> {
    fn vertex(&self, face: usize, vert: usize) -> usize {
        (self.corners.corner)(face)[vert] as usize
    }
}

impl bevy_mikktspace::Geometry for MikkTSpace<'_> {
    fn num_faces(&self) -> usize {
        self.corners.count
    }

    fn num_vertices_of_face(&self, _: usize) -> usize {
        3
    }

    fn position(&self, face: usize, vert: usize) -> [f32; 3] {
        self.corners.verts[self.vertex(face, vert)]
    }

    fn normal(&self, face: usize, vert: usize) -> [f32; 3] {
        self.corners.normals[self.vertex(face, vert)]
    }

    /// glTF's `v` grows down the image; MikkTSpace's bitangent follows growing `v`,
    /// and glTF's normal maps put green up the image.
    fn tex_coord(&self, face: usize, vert: usize) -> [f32; 2] {
        let [u, v] = self.corners.uvs[self.vertex(face, vert)];
        [u, -v]
    }

    fn set_tangent(&mut self, space: Option<bevy_mikktspace::TangentSpace>, face: usize, vert: usize) {
        if let Some(space) = space {
            self.tangents[face][vert] = space.tangent_encoded();
        }
    }
}
