//! Mesh input: OBJ and glTF 2.0 (`.gltf`, `.glb`), each optionally zstd-compressed.

mod gltf;
mod obj;
mod obj_plain;
mod refs;

pub use refs::{
    LoadOptions, References, DEFAULT_MAX_FILE_BYTES, DEFAULT_MAX_INSTANCES, DEFAULT_MAX_TRIANGLES, MAX_MTL_BYTES,
};

use std::path::{Path, PathBuf};

use crate::error::{Error, Result};

/// A triangle soup in input order: triangle `i` is the `i`-th triangle of the file
/// (OBJ: faces fan-triangulated in file order; glTF: the default scene's nodes in
/// depth-first order, then their primitives in order), so a hit can name it; with the
/// materials, lights and cameras the file describes.
///
/// The per-triangle attributes (`material_ids`, `normals`, `uvs`, each of `more_uvs`,
/// `colors`, `tangents`) are either empty or one entry per triangle: [`Mesh::push`] and
/// its siblings keep them so.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Mesh {
    /// The triangles' vertices, world space.
    pub triangles: Vec<[[f32; 3]; 3]>,
    /// Index into `materials` of each triangle, or empty.
    pub material_ids: Vec<u32>,
    /// Shading normals of each triangle's corners, world space, or empty. Triangles of
    /// a part of the file without normals get their face normal.
    pub normals: Vec<[[f32; 3]; 3]>,
    /// Texture coordinates of each triangle's corners, or empty (zeros for the parts of
    /// the file without them).
    pub uvs: Vec<[[f32; 2]; 3]>,
    /// Texture coordinates of each triangle's corners in the channels after the first
    /// ([`octrace_format::Material::uv_channels`]: channel `c` is `more_uvs[c - 1]`),
    /// each empty or one entry a triangle (zeros where a part has none).
    pub more_uvs: Vec<Vec<[[f32; 2]; 3]>>,
    /// Vertex colours (glTF `COLOR_0`) of each triangle's corners, linear RGBA at 16
    /// bits a channel, or empty (white for the parts of the file without them).
    pub colors: Vec<[[u16; 4]; 3]>,
    /// Tangents of each triangle's corners, world space (`x y z` along which the normal
    /// texture's `u` grows, `w` the bitangent's sign, 1 or -1), or empty: from glTF
    /// `TANGENT`, else MikkTSpace, for the parts whose material has a normal texture;
    /// zeros for the others (the renderer then takes each triangle's own tangent).
    pub tangents: Vec<[[f32; 4]; 3]>,
    /// Materials (glTF materials, MTL materials), in file order, then a `"default"`
    /// one when some triangles have none.
    pub materials: Vec<octrace_format::Material>,
    /// Punctual lights (glTF `KHR_lights_punctual`), world space.
    pub lights: Vec<octrace_format::Light>,
    /// Cameras (glTF), world space.
    pub cameras: Vec<octrace_format::Camera>,
    /// The parts of the mesh (glTF primitives of nodes, OBJ objects or groups), in
    /// order, each a run of `triangles`.
    pub parts: Vec<octrace_format::MeshPart>,
    /// Texture images (glTF base colour textures), their texels in `texels`.
    pub textures: Vec<octrace_format::Texture>,
    /// The textures' texels, decoded, 8 bits a channel ([`octrace_format::Texture`]),
    /// those of the images kept encoded included.
    pub texels: Vec<u32>,
    /// The encoded images of the textures kept encoded ([`octrace_format::Encoded`]).
    pub images: Vec<u8>,
    /// Things skipped while loading (non-triangle glTF primitives, ...), one line each.
    pub warnings: Vec<String>,
    /// The files read besides the mesh file itself (glTF buffers, OBJ material
    /// libraries), as resolved: what a command must not overwrite.
    pub sources: Vec<PathBuf>,
}

/// A scene loaded with its repeated meshes kept once ([`Mesh::load_instanced`]): the
/// meshes to bake, each into a scene of its own, and their placements. Bakes to an
/// instanced file (`octrace_format::instanced`), which opens as a world of instances.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct InstancedMesh {
    /// The meshes: first the geometry the scene places once (world space, with its
    /// lights and cameras) where there is any, then each geometry placed more than
    /// once, in its own space.
    pub meshes: Vec<Mesh>,
    /// Every placement of a mesh.
    pub placements: Vec<Placement>,
    /// The material maps the placements draw with, each once: entry `k` of a map
    /// replaces material `k` of the mesh (past the end, its own).
    pub maps: Vec<Vec<u32>>,
    /// Things skipped while loading, one line each (the meshes' own are moved here).
    pub warnings: Vec<String>,
    /// The files read besides the mesh file itself (as [`Mesh::sources`]).
    pub sources: Vec<PathBuf>,
}

/// One placement of an [`InstancedMesh`]'s mesh.
#[derive(Clone, Debug, PartialEq)]
pub struct Placement {
    /// The mesh placed (its index in [`InstancedMesh::meshes`]).
    pub mesh: u32,
    /// Local to world: 3 rows of 4.
    pub rows: [[f64; 4]; 3],
    /// The material map it draws with (its index in [`InstancedMesh::maps`]), where it
    /// draws other materials than the mesh's own: placements of one geometry with
    /// different materials.
    pub map: Option<u32>,
}

/// A loaded scene: one mesh, or meshes placed many times.
#[derive(Clone, Debug, PartialEq)]
#[allow(clippy::large_enum_variant)] // one a load: a box would only burden the match
pub enum Loaded {
    /// One mesh, every placement's triangles in it.
    One(Mesh),
    /// Meshes placed more than once, kept once.
    Instanced(InstancedMesh),
}

impl InstancedMesh {
    /// The triangles the placements make (each mesh's times its placements): what
    /// a flat bake would store.
    pub fn placed_triangles(&self) -> u64 {
        self.placements.iter().map(|p| self.meshes[p.mesh as usize].triangles.len() as u64).sum()
    }

    /// The triangles stored (each mesh's once).
    pub fn stored_triangles(&self) -> u64 {
        self.meshes.iter().map(|m| m.triangles.len() as u64).sum()
    }
}

impl Mesh {
    /// The textures and texel arrays as a baked scene stores them: the texels of the
    /// textures kept whole first, then (without their texels) the textures kept
    /// encoded, whose texels follow in the array the file's readers decode; and the
    /// images' bytes in words.
    pub(crate) fn texel_sections(&self) -> (Vec<octrace_format::Texture>, Vec<u32>, Vec<u32>) {
        let mut textures = self.textures.clone();
        let mut stored = Vec::new();
        for t in textures.iter_mut().filter(|t| t.encoded.is_none()) {
            let n = t.width as usize * t.height as usize * octrace_format::TEXEL_WORDS;
            let from = (t.first as usize * octrace_format::TEXEL_WORDS).min(self.texels.len());
            t.first = (stored.len() / octrace_format::TEXEL_WORDS) as u32;
            stored.extend_from_slice(&self.texels[from..(from + n).min(self.texels.len())]);
        }
        let mut next = (stored.len() / octrace_format::TEXEL_WORDS) as u32;
        for t in textures.iter_mut().filter(|t| t.encoded.is_some()) {
            t.first = next;
            next = next.saturating_add(t.width * t.height);
        }
        let images = self.images.chunks(4).map(|c| c.iter().rev().fold(0u32, |w, &b| w << 8 | u32::from(b))).collect();
        (textures, stored, images)
    }

    /// A mesh of bare triangles: no materials, lights or cameras.
    ///
    /// # Example
    /// ```
    /// let mesh = octrace_bake::Mesh::from_triangles(vec![[[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]]);
    /// assert!(mesh.materials.is_empty());
    /// ```
    pub fn from_triangles(triangles: Vec<[[f32; 3]; 3]>) -> Mesh {
        Mesh { triangles, ..Mesh::default() }
    }

    /// Appends a triangle with its attributes, keeping every attribute array either
    /// empty or one entry a triangle: the first triangle that has normals (or texture
    /// coordinates) gives the earlier ones face normals (or zeros), and a triangle
    /// without an attribute the others have gets what [`Mesh::pad_attributes`] gives.
    pub fn push(&mut self, triangle: [[f32; 3]; 3], normals: Option<[[f32; 3]; 3]>, uvs: Option<[[f32; 2]; 3]>) {
        self.push_colored(triangle, normals, uvs, None);
    }

    /// [`Mesh::push`], then the triangle's vertex colours: the first triangle that has
    /// them gives the earlier ones white.
    pub fn push_colored(
        &mut self,
        triangle: [[f32; 3]; 3],
        normals: Option<[[f32; 3]; 3]>,
        uvs: Option<[[f32; 2]; 3]>,
        colors: Option<[[u16; 4]; 3]>,
    ) {
        self.triangles.push(triangle);
        let n = self.triangles.len();
        if let Some(normals) = normals {
            let triangles = &self.triangles;
            set_last(&mut self.normals, n, [normals], |t| [face_normal(&triangles[t]); 3]);
        }
        if let Some(uvs) = uvs {
            set_last(&mut self.uvs, n, [uvs], |_| NO_UVS);
        }
        if let Some(colors) = colors {
            set_last(&mut self.colors, n, [colors], |_| WHITE);
        }
        self.pad_attributes();
    }

    /// Sets the tangents of the triangles pushed last, `count` of them (those
    /// `tangents` leaves out get none): the first that has them gives the earlier
    /// triangles zeros (none).
    ///
    /// # Panics
    /// If `count` is more than the triangles pushed.
    ///
    /// # Example
    /// ```
    /// let mut mesh = octrace_bake::Mesh::default();
    /// mesh.push([[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], None, None);
    /// mesh.push([[0.0; 3], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], None, None);
    /// mesh.push_tangents(vec![[[1.0, 0.0, 0.0, 1.0]; 3]], 1);
    /// mesh.push([[0.0; 3], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]], None, None);
    /// assert_eq!(mesh.tangents, [[[0.0; 4]; 3], [[1.0, 0.0, 0.0, 1.0]; 3], [[0.0; 4]; 3]]);
    /// ```
    pub fn push_tangents(&mut self, tangents: Vec<[[f32; 4]; 3]>, count: usize) {
        let n = self.triangles.len();
        self.tangents.truncate(n - count);
        set_last(&mut self.tangents, n, tangents, |_| NO_TANGENTS);
        self.pad_attributes();
    }

    /// Gives every per-triangle attribute array that has entries one entry a triangle,
    /// what a triangle without the attribute gets: its face normal, zero texture
    /// coordinates (in every channel), white, no tangent (the renderer then takes the
    /// triangle's own). The one place the arrays are padded: a part without an
    /// attribute may come before or after the parts with it, in any order.
    pub fn pad_attributes(&mut self) {
        let n = self.triangles.len();
        let triangles = &self.triangles;
        pad(&mut self.normals, n, |t| [face_normal(&triangles[t]); 3]);
        pad(&mut self.uvs, n, |_| NO_UVS);
        for channel in &mut self.more_uvs {
            pad(channel, n, |_| NO_UVS);
        }
        pad(&mut self.colors, n, |_| WHITE);
        pad(&mut self.tangents, n, |_| NO_TANGENTS);
    }

    /// Has the bake store every texture's texels rather than its encoded image: a larger
    /// file (DamagedHelmet: 85.8 MB rather than 5.5 MB) whose first render decodes
    /// nothing (0.16 s less on two cores for DamagedHelmet's five 2048² JPEGs).
    ///
    /// # Example
    /// ```
    /// let mut mesh = octrace_bake::procedural::shaded_torus(8, 4);
    /// assert!(mesh.textures.iter().any(|t| t.encoded.is_some()));
    /// mesh.store_texels();
    /// assert!(mesh.textures.iter().all(|t| t.encoded.is_none()) && mesh.images.is_empty());
    /// ```
    pub fn store_texels(&mut self) {
        self.textures.iter_mut().for_each(|t| t.encoded = None);
        self.images = Vec::new();
    }

    /// Sets the texture coordinates in channel `channel` (1 or more) of the triangles
    /// pushed last, `count` of them: the first that has them gives the earlier
    /// triangles zeros.
    ///
    /// # Panics
    /// If `channel` is 0 or `count` is more than the triangles pushed.
    pub fn push_uv_channel(&mut self, channel: usize, uvs: Vec<[[f32; 2]; 3]>, count: usize) {
        if self.more_uvs.len() < channel {
            self.more_uvs.resize(channel, Vec::new());
        }
        let n = self.triangles.len();
        let array = &mut self.more_uvs[channel - 1];
        array.truncate(n - count);
        set_last(array, n, uvs, |_| NO_UVS);
        self.pad_attributes();
    }

    /// The texture coordinates of triangle `t`'s corners in `channel`, when the mesh
    /// has them.
    pub fn corner_uvs(&self, t: usize, channel: usize) -> Option<[[f32; 2]; 3]> {
        match channel {
            0 => self.uvs.get(t).copied(),
            c => self.more_uvs.get(c - 1)?.get(t).copied(),
        }
    }

    /// Ends a part: the triangles pushed since the last part (none: nothing), from
    /// `source` in the file and named `name()`.
    pub fn end_part(&mut self, source: octrace_format::PartSource, name: impl FnOnce() -> String) {
        let first = self.parts.last().map_or(0, |p| p.first as usize + p.count as usize);
        let count = self.triangles.len().saturating_sub(first);
        if count > 0 {
            self.parts.push(octrace_format::MeshPart {
                name: name(),
                first: first as u32,
                count: count as u32,
                source,
                edges: Default::default(),
            });
        }
    }

    /// What a mesh must be to bake, checked where it is loaded and again where it is
    /// baked (a mesh may be made in code): attributes that fit
    /// ([`Mesh::check_attributes`]), some triangles ([`Error::EmptyScene`]), and fewer
    /// than 2^32 - 1 of them, the format's 32-bit triangle indices ([`Error::TooLarge`]).
    pub(crate) fn check_bakeable(&self, path: &Path) -> Result<()> {
        self.check_attributes(path)?;
        if self.triangles.is_empty() {
            return Err(Error::EmptyScene { path: path.into() });
        }
        if self.triangles.len() as u64 >= u64::from(u32::MAX) {
            return Err(Error::TooLarge { path: path.into(), count: self.triangles.len() as u64 });
        }
        Ok(())
    }

    /// Checks that each attribute array is empty or one entry a triangle, and that
    /// material ids are in range.
    ///
    /// # Errors
    /// [`Error::Parse`] naming the attribute.
    pub fn check_attributes(&self, path: &Path) -> Result<()> {
        let n = self.triangles.len();
        let bad = |what: &str, len: usize| Error::Parse {
            path: path.into(),
            element: what.into(),
            message: format!("{len} entries for {n} triangles"),
        };
        for (what, len) in [
            ("material ids", self.material_ids.len()),
            ("normals", self.normals.len()),
            ("uvs", self.uvs.len()),
            ("colors", self.colors.len()),
            ("tangents", self.tangents.len()),
        ] {
            if len != 0 && len != n {
                return Err(bad(what, len));
            }
        }
        let max = octrace_format::layout::MAX_UV_CHANNELS;
        if self.more_uvs.len() >= max {
            return Err(Error::Parse {
                path: path.into(),
                element: "texture-coordinate channels".into(),
                message: format!("{} channels, at most {max}", self.more_uvs.len() + 1),
            });
        }
        if let Some((c, channel)) = self.more_uvs.iter().enumerate().find(|(_, c)| !c.is_empty() && c.len() != n) {
            return Err(bad(&format!("texture coordinates of channel {}", c + 1), channel.len()));
        }
        if let Some(&m) = self.material_ids.iter().find(|&&m| m as usize >= self.materials.len()) {
            return Err(Error::IndexOutOfRange {
                path: path.into(),
                element: "material id".into(),
                index: m as i64,
                count: self.materials.len(),
            });
        }
        Ok(())
    }
}

/// Texture coordinates of a triangle without them.
const NO_UVS: [[f32; 2]; 3] = [[0.0; 2]; 3];
/// Vertex colours of a triangle without them.
const WHITE: [[u16; 4]; 3] = [[u16::MAX; 4]; 3];
/// Tangents of a triangle without them.
const NO_TANGENTS: [[f32; 4]; 3] = [[0.0; 4]; 3];

/// Appends `values`, the attribute of the last triangles up to `n`, to `array`: the
/// triangles before them that it lacks get `none(t)`, as do any of them that `values`
/// leaves out.
fn set_last<T>(array: &mut Vec<T>, n: usize, values: impl IntoIterator<Item = T>, none: impl Fn(usize) -> T) {
    let values = values.into_iter();
    let first = n - values.size_hint().0.min(n);
    while array.len() < first {
        array.push(none(array.len()));
    }
    array.extend(values.take(n - array.len()));
    while array.len() < n {
        array.push(none(array.len()));
    }
}

/// Pads `array`, when it has entries, to `n`, triangle `t` getting `none(t)`.
fn pad<T>(array: &mut Vec<T>, n: usize, none: impl Fn(usize) -> T) {
    if !array.is_empty() {
        while array.len() < n {
            array.push(none(array.len()));
        }
    }
}

/// The unit normal of a triangle's plane (counter-clockwise winding), or zero for a
/// degenerate one.
pub fn face_normal(t: &[[f32; 3]; 3]) -> [f32; 3] {
    let n = edge_cross(t);
    let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
    if len > 0.0 && len.is_finite() {
        n.map(|c| (c / len) as f32)
    } else {
        [0.0; 3]
    }
}

/// The mesh formats the loader reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MeshFormat {
    /// Wavefront OBJ.
    Obj,
    /// glTF 2.0, JSON or binary (the parser tells them apart by their first bytes).
    Gltf,
}

impl MeshFormat {
    /// The format a file name calls for, and whether it is zstd-compressed.
    pub fn from_path(path: &Path) -> Option<(MeshFormat, bool)> {
        let name = path.file_name()?.to_str()?.to_ascii_lowercase();
        let (stem, zst) = match name.strip_suffix(".zst") {
            Some(s) => (s.to_string(), true),
            None => (name, false),
        };
        let ext = Path::new(&stem).extension()?.to_str()?;
        let format = match ext {
            "obj" => MeshFormat::Obj,
            "gltf" | "glb" => MeshFormat::Gltf,
            _ => return None,
        };
        Some((format, zst))
    }

    /// The format's name as people write it: `OBJ`, `glTF`.
    pub fn name(self) -> &'static str {
        match self {
            MeshFormat::Obj => "OBJ",
            MeshFormat::Gltf => "glTF",
        }
    }
}

impl Mesh {
    /// Loads a mesh file, choosing the format by its extension, with the default
    /// [`LoadOptions`]: the files it names must lie inside its folder, and no file
    /// read may exceed [`DEFAULT_MAX_FILE_BYTES`].
    ///
    /// # Errors
    /// [`Error::Unreadable`] (also for a FIFO, a device or a file over the limit),
    /// [`Error::UnknownFormat`], [`Error::Reference`], and the parse errors of the
    /// format: each names the file and the element at fault.
    ///
    /// # Example
    /// ```no_run
    /// let mesh = octrace_bake::Mesh::load("bunny.obj.zst")?;
    /// println!("{} triangles", mesh.triangles.len());
    /// # Ok::<(), octrace_bake::Error>(())
    /// ```
    pub fn load(path: impl AsRef<Path>) -> Result<Mesh> {
        Mesh::load_with(path, &LoadOptions::default())
    }

    /// [`Mesh::load`] with the given options (where references may lead, how large a
    /// file may be).
    ///
    /// # Errors
    /// As [`Mesh::load`].
    pub fn load_with(path: impl AsRef<Path>, options: &LoadOptions) -> Result<Mesh> {
        let path = path.as_ref();
        let not_a_mesh = || Error::UnknownFormat { path: path.into() };
        if path.is_dir() {
            return Err(not_a_mesh());
        }
        let (format, zst) = MeshFormat::from_path(path).ok_or_else(not_a_mesh)?;
        let unreadable = |source| Error::Unreadable { path: path.into(), source };
        if format == MeshFormat::Obj {
            // A plain OBJ (positions and triangles) is read a block at a time, never
            // whole, under the triangle budget; any other is read again below, whole,
            // under the file-size limit, for tobj.
            if let Some(mesh) = Mesh::read_plain_obj(path, zst, options)? {
                return mesh.checked(path, options);
            }
        }
        let raw = octrace_format::read_regular_file(path, options.max_file_bytes).map_err(unreadable)?;
        let bytes = if zst { decompress(&raw, options.max_file_bytes).map_err(unreadable)? } else { raw };
        let base = path.parent().map(Path::to_path_buf);
        Mesh::from_bytes_with(&bytes, format, path, base.as_deref(), options)
    }

    /// [`Mesh::load_with`], the meshes a glTF scene places more than once (by several
    /// nodes, by `EXT_mesh_gpu_instancing`, or meshes that share a geometry's
    /// accessors) kept once as instances ([`Loaded::Instanced`]); a scene that places
    /// no mesh twice, and an OBJ, load as one mesh ([`Loaded::One`]).
    ///
    /// # Errors
    /// As [`Mesh::load`].
    ///
    /// # Example
    /// ```no_run
    /// use octrace_bake::{Loaded, LoadOptions, Mesh};
    /// match Mesh::load_instanced("spheres.glb", &LoadOptions::default())? {
    ///     Loaded::One(mesh) => println!("{} triangles", mesh.triangles.len()),
    ///     Loaded::Instanced(i) => println!("{} meshes placed {} times", i.meshes.len(), i.placements.len()),
    /// }
    /// # Ok::<(), octrace_bake::Error>(())
    /// ```
    pub fn load_instanced(path: impl AsRef<Path>, options: &LoadOptions) -> Result<Loaded> {
        let path = path.as_ref();
        match MeshFormat::from_path(path) {
            Some((MeshFormat::Gltf, zst)) if !path.is_dir() => {
                let unreadable = |source| Error::Unreadable { path: path.into(), source };
                let raw = octrace_format::read_regular_file(path, options.max_file_bytes).map_err(unreadable)?;
                let bytes = if zst { decompress(&raw, options.max_file_bytes).map_err(unreadable)? } else { raw };
                let base = path.parent().map(Path::to_path_buf);
                Mesh::from_bytes_instanced(&bytes, MeshFormat::Gltf, path, base.as_deref(), options)
            }
            _ => Mesh::load_with(path, options).map(Loaded::One),
        }
    }

    /// [`Mesh::from_bytes_with`], as [`Mesh::load_instanced`].
    ///
    /// # Errors
    /// As [`Mesh::load`].
    pub fn from_bytes_instanced(
        bytes: &[u8],
        format: MeshFormat,
        name: &Path,
        base: Option<&Path>,
        options: &LoadOptions,
    ) -> Result<Loaded> {
        match format {
            MeshFormat::Obj => Mesh::from_bytes_with(bytes, format, name, base, options).map(Loaded::One),
            MeshFormat::Gltf => match gltf::parse_instanced(bytes, name, base, options)? {
                Loaded::One(mesh) => mesh.checked(name, options).map(Loaded::One),
                Loaded::Instanced(i) if i.meshes.is_empty() => Err(Error::EmptyScene { path: name.into() }),
                Loaded::Instanced(mut i) => {
                    for mesh in &mut i.meshes {
                        mesh.check_bakeable(name)?;
                    }
                    // One mesh placed once as it is is a mesh.
                    if i.placements.len() == 1 && i.placements[0].rows == IDENTITY_ROWS && i.meshes.len() == 1 {
                        let mut mesh = i.meshes.remove(0);
                        mesh.warnings = i.warnings;
                        return Ok(Loaded::One(mesh));
                    }
                    Ok(Loaded::Instanced(i))
                }
            },
        }
    }

    /// A plain OBJ file's mesh, read (and decompressed) a block at a time, or `None`
    /// for an OBJ that is not plain. Its size is not limited (it is never held whole:
    /// what it costs follows its triangles, which are counted against
    /// [`LoadOptions::max_triangles`] as they are read); a compressed one may expand
    /// [`MAX_MESH_COMPRESSION_RATIO`] times.
    fn read_plain_obj(path: &Path, zst: bool, options: &LoadOptions) -> Result<Option<Mesh>> {
        let read = |file: std::fs::File| match zst {
            true => {
                let len = file.metadata()?.len();
                let decoder = zstd::stream::read::Decoder::new(file)?;
                Ok(obj_plain::read(Capped::zstd(decoder, len, u64::MAX), options.max_triangles))
            }
            false => Ok(obj_plain::read(file, options.max_triangles)),
        };
        let unreadable = |source| Error::Unreadable { path: path.into(), source };
        let file = octrace_format::open_regular_file(path).map_err(unreadable)?;
        match read(file).map_err(unreadable)? {
            Ok(mesh) => Ok(mesh),
            Err(obj_plain::Stop::Read(source)) => Err(unreadable(source)),
            Err(obj_plain::Stop::Budget { what, needed, limit }) => Err(Error::Budget {
                path: path.into(),
                what: what.into(),
                needed,
                limit,
                option: "--max-triangles (positions: three a triangle), LoadOptions::max_triangles",
            }),
        }
    }

    /// The checks every loaded mesh passes: the triangle budget, and
    /// [`Mesh::check_bakeable`].
    fn checked(self, name: &Path, options: &LoadOptions) -> Result<Mesh> {
        // glTF's triangles are counted before they are read; an OBJ's are bounded by
        // its size, and counted here.
        if self.triangles.len() as u64 > options.max_triangles {
            return Err(Error::Budget {
                path: name.into(),
                what: "triangles".into(),
                needed: self.triangles.len() as u64,
                limit: options.max_triangles,
                option: "--max-triangles, LoadOptions::max_triangles",
            });
        }
        self.check_bakeable(name)?;
        Ok(self)
    }

    /// Parses a mesh held in memory. `name` is used in error messages; `base` is the
    /// folder external glTF buffers and OBJ material libraries are read from (none:
    /// only embedded buffers, no MTL materials), under the default [`LoadOptions`].
    ///
    /// # Errors
    /// As [`Mesh::load`].
    pub fn from_bytes(bytes: &[u8], format: MeshFormat, name: &Path, base: Option<&Path>) -> Result<Mesh> {
        Mesh::from_bytes_with(bytes, format, name, base, &LoadOptions::default())
    }

    /// [`Mesh::from_bytes`] with the given options.
    ///
    /// # Errors
    /// As [`Mesh::load`].
    pub fn from_bytes_with(
        bytes: &[u8],
        format: MeshFormat,
        name: &Path,
        base: Option<&Path>,
        options: &LoadOptions,
    ) -> Result<Mesh> {
        let mesh = match format {
            MeshFormat::Obj => obj::parse(bytes, name, base, options)?,
            MeshFormat::Gltf => gltf::parse(bytes, name, base, options)?,
        };
        mesh.checked(name, options)
    }
}

/// The identity's rows.
const IDENTITY_ROWS: [[f64; 4]; 3] = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]];

/// Checks that every coordinate of `v` is finite.
pub(crate) fn check_finite(v: [f32; 3], path: &Path, element: impl FnOnce() -> String) -> Result<()> {
    match v.iter().find(|c| !c.is_finite()) {
        None => Ok(()),
        Some(&value) => Err(Error::NonFinite { path: PathBuf::from(path), element: element(), value }),
    }
}

/// The most a compressed mesh may expand: decompression stops with an error past this
/// many times the compressed size, so a small hostile file cannot claim all memory.
/// (Text meshes compress 3-10×; a million identical lines, 1000× at most.)
pub const MAX_MESH_COMPRESSION_RATIO: u64 = 1024;

/// Decompresses a zstd mesh, refusing to expand past [`MAX_MESH_COMPRESSION_RATIO`]
/// times its size or past `max` bytes, whichever is less: it stops reading there.
fn decompress(raw: &[u8], max: u64) -> std::io::Result<Vec<u8>> {
    use std::io::Read;
    let mut out = Vec::new();
    Capped::zstd(zstd::stream::read::Decoder::new(raw)?, raw.len() as u64, max).read_to_end(&mut out)?;
    Ok(out)
}

/// A zstd stream that fails once it expands past [`MAX_MESH_COMPRESSION_RATIO`] times
/// its compressed size or `max` bytes, whichever is less: a compressed bomb is refused
/// there, whatever reads it.
struct Capped<R> {
    inner: R,
    /// Bytes still allowed.
    left: u64,
    refusal: String,
}

impl<R> Capped<R> {
    /// A zstd stream of `len` bytes that may expand to at most `max` bytes.
    fn zstd(inner: R, len: u64, max: u64) -> Capped<R> {
        let limit = len.saturating_mul(MAX_MESH_COMPRESSION_RATIO).min(max);
        let at_most = if max == u64::MAX { String::new() } else { format!(", at most {max}") };
        let refusal =
            format!("decompresses to more than {limit} bytes ({MAX_MESH_COMPRESSION_RATIO} times its size{at_most})");
        Capped { inner, left: limit, refusal }
    }
}

impl<R: std::io::Read> std::io::Read for Capped<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        // One byte past the limit is asked for, to tell a stream that ends there from
        // one that goes on.
        let room = buf.len().min(usize::try_from(self.left.saturating_add(1)).unwrap_or(usize::MAX));
        let n = self.inner.read(&mut buf[..room])?;
        if n as u64 > self.left {
            return Err(too_large(self.refusal.clone()));
        }
        self.left -= n as u64;
        Ok(n)
    }
}

fn too_large(message: String) -> std::io::Error {
    std::io::Error::new(std::io::ErrorKind::InvalidInput, message)
}

/// The cross product of a triangle's edges from its first vertex, in `f64`: products
/// of `f32` values are exact there, so it is zero exactly when the edges (each rounded
/// once) are collinear.
pub(crate) fn edge_cross(t: &[[f32; 3]; 3]) -> [f64; 3] {
    let d = |i: usize, a: usize| t[i][a] as f64 - t[0][a] as f64;
    [
        d(1, 1) * d(2, 2) - d(1, 2) * d(2, 1),
        d(1, 2) * d(2, 0) - d(1, 0) * d(2, 2),
        d(1, 0) * d(2, 1) - d(1, 1) * d(2, 0),
    ]
}
