//! Mesh input: OBJ and glTF 2.0 (`.gltf`, `.glb`), each optionally zstd-compressed.

mod gltf;
mod obj;

use std::path::{Path, PathBuf};

use crate::error::{Error, Result};

/// A triangle soup in input order: triangle `i` is the `i`-th triangle of the file
/// (OBJ: faces fan-triangulated in file order; glTF: the default scene's nodes in
/// depth-first order, then their primitives in order), so a hit can name it.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Mesh {
    /// The triangles' vertices, world space.
    pub triangles: Vec<[[f32; 3]; 3]>,
    /// Things skipped while loading (non-triangle glTF primitives, ...), one line each.
    pub warnings: Vec<String>,
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
}

impl Mesh {
    /// Loads a mesh file, choosing the format by its extension.
    ///
    /// # Errors
    /// [`Error::Unreadable`], [`Error::UnknownFormat`], and the parse errors of the
    /// format: each names the file and the element at fault.
    ///
    /// # Example
    /// ```no_run
    /// let mesh = octrace_bake::Mesh::load("bunny.obj.zst")?;
    /// println!("{} triangles", mesh.triangles.len());
    /// # Ok::<(), octrace_bake::Error>(())
    /// ```
    pub fn load(path: impl AsRef<Path>) -> Result<Mesh> {
        let path = path.as_ref();
        let (format, zst) = MeshFormat::from_path(path).ok_or_else(|| Error::UnknownFormat { path: path.into() })?;
        let unreadable = |source| Error::Unreadable { path: path.into(), source };
        let raw = std::fs::read(path).map_err(unreadable)?;
        let bytes = if zst { decompress(&raw).map_err(unreadable)? } else { raw };
        let base = path.parent().map(Path::to_path_buf);
        Mesh::from_bytes(&bytes, format, path, base.as_deref())
    }

    /// Parses a mesh held in memory. `name` is used in error messages; `base` is the
    /// folder external glTF buffers are read from (none: only embedded buffers).
    ///
    /// # Errors
    /// As [`Mesh::load`].
    pub fn from_bytes(bytes: &[u8], format: MeshFormat, name: &Path, base: Option<&Path>) -> Result<Mesh> {
        let mesh = match format {
            MeshFormat::Obj => obj::parse(bytes, name)?,
            MeshFormat::Gltf => gltf::parse(bytes, name, base)?,
        };
        if mesh.triangles.is_empty() {
            return Err(Error::EmptyScene { path: name.into() });
        }
        if mesh.triangles.len() as u64 >= u32::MAX as u64 {
            return Err(Error::TooLarge { path: name.into(), count: mesh.triangles.len() as u64 });
        }
        Ok(mesh)
    }
}

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

/// Decompresses a zstd mesh, refusing to expand past [`MAX_MESH_COMPRESSION_RATIO`].
fn decompress(raw: &[u8]) -> std::io::Result<Vec<u8>> {
    use std::io::Read;
    let limit = (raw.len() as u64).saturating_mul(MAX_MESH_COMPRESSION_RATIO);
    let mut out = Vec::new();
    zstd::stream::read::Decoder::new(raw)?.take(limit + 1).read_to_end(&mut out)?;
    if out.len() as u64 > limit {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!("decompresses to more than {MAX_MESH_COMPRESSION_RATIO} times its size"),
        ));
    }
    Ok(out)
}
