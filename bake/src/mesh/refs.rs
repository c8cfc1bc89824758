//! The files a mesh names (glTF buffers, OBJ material libraries): where they may lead
//! (by default only inside the mesh's own folder) and how large a file may be. Every
//! file is read as untrusted input, through `octrace_format::read_regular_file`.

use std::path::{Component, Path, PathBuf};

/// Where the files a mesh names (glTF buffer URIs, OBJ `mtllib`) may be.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum References {
    /// Relative paths that stay inside the mesh file's folder once `..` and symbolic
    /// links are resolved. Absolute paths, `file:` URIs and paths that climb out are
    /// refused. The default: a mesh from a stranger reads nothing else of the machine.
    #[default]
    Confined,
    /// Any path the mesh names, absolute paths and `file:` URIs included, for inputs
    /// you trust. The other rules (regular files, size limits) still hold.
    Anywhere,
}

/// How a mesh is loaded: where its references may lead, how large a file (the mesh
/// itself, decompressed, or a buffer it names) may be, and the budgets a small file
/// could otherwise multiply: node placements and triangles after instancing, counted
/// before anything is read into the mesh.
///
/// # Example
/// ```no_run
/// use octrace_bake::{LoadOptions, Mesh, References};
/// let trusted = LoadOptions { references: References::Anywhere, ..LoadOptions::default() };
/// let mesh = Mesh::load_with("assets/scene.gltf", &trusted)?;
/// # Ok::<(), octrace_bake::Error>(())
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LoadOptions {
    /// Where the mesh's references may lead.
    pub references: References,
    /// The largest file read whole, in bytes: the mesh file, its decompressed contents,
    /// each glTF buffer. Checked before anything is read. A plain OBJ (positions and
    /// triangles alone) is read a block at a time, never whole, and is not held to it:
    /// what it costs follows its triangles, counted against `max_triangles` as it is
    /// read (and its positions, three a triangle).
    pub max_file_bytes: u64,
    /// The most node placements a glTF scene may make ([`DEFAULT_MAX_INSTANCES`]): a
    /// node listed twice as a child, or under two parents, is placed twice, and its
    /// children with it, so 2 KB of nodes that share children can ask for 2^60.
    /// Counted over the hierarchy before it is walked.
    pub max_instances: u64,
    /// The most triangles the mesh may hold once instanced ([`DEFAULT_MAX_TRIANGLES`]):
    /// for glTF counted from the accessors and placements before any is read; for OBJ
    /// as faces are read.
    pub max_triangles: u64,
}

/// The default [`LoadOptions::max_instances`]: 2^20 node placements, far beyond real
/// assets (Khronos' samples place at most a few thousand).
pub const DEFAULT_MAX_INSTANCES: u64 = 1 << 20;

/// The default [`LoadOptions::max_triangles`]: 2^27 (134 million), 150 times the
/// dragon; about 5 GB of vertex positions alone.
pub const DEFAULT_MAX_TRIANGLES: u64 = 1 << 27;

/// The default [`LoadOptions::max_file_bytes`]: 4 GiB, eight times the dragon's
/// glTF-sized data (a plain OBJ, read a block at a time, is not held to it).
pub const DEFAULT_MAX_FILE_BYTES: u64 = 4 << 30;

/// The largest material library read (MTL files are a few kilobytes).
pub const MAX_MTL_BYTES: u64 = 16 << 20;

impl Default for LoadOptions {
    fn default() -> Self {
        LoadOptions {
            references: References::Confined,
            max_file_bytes: DEFAULT_MAX_FILE_BYTES,
            max_instances: DEFAULT_MAX_INSTANCES,
            max_triangles: DEFAULT_MAX_TRIANGLES,
        }
    }
}

/// The file a reference names, or why it may not be read. `base` is the mesh's folder
/// (none when the mesh came as bytes: then nothing outside it is read).
pub(crate) fn resolve(base: Option<&Path>, reference: &Path, references: References) -> Result<PathBuf, String> {
    let Some(base) = base else {
        return Err("the mesh was given without a folder, so it may not name files".into());
    };
    if reference.as_os_str().is_empty() {
        return Err("empty path".into());
    }
    let absolute = reference.components().any(|c| matches!(c, Component::RootDir | Component::Prefix(_)));
    if references == References::Anywhere {
        return Ok(if absolute { reference.to_path_buf() } else { base.join(reference) });
    }
    let hint = "; a mesh may name only files inside its own folder (`octrace bake --allow-outside-references` \
                or `References::Anywhere` for inputs you trust)";
    if absolute {
        return Err(format!("an absolute path{hint}"));
    }
    let folder = base_folder(base).map_err(|e| format!("the mesh's folder: {e}"))?;
    let target = folder.join(reference).canonicalize().map_err(|e| e.to_string())?;
    if !target.starts_with(&folder) {
        return Err(format!("it leads outside the mesh's folder{hint}"));
    }
    Ok(target)
}

/// The canonical form of the mesh's folder (`""` is the current one).
fn base_folder(base: &Path) -> std::io::Result<PathBuf> {
    if base.as_os_str().is_empty() {
        Path::new(".").canonicalize()
    } else {
        base.canonicalize()
    }
}

/// Decodes `%XX` escapes; `None` when the result is not UTF-8. Malformed escapes are
/// kept as they are, as URI decoders do.
pub(crate) fn percent_decode(uri: &str) -> Option<String> {
    String::from_utf8(percent_decode_bytes(uri)?).ok()
}

/// The bytes `%XX` escapes in `uri` stand for (anything else as it is).
pub(crate) fn percent_decode_bytes(uri: &str) -> Option<Vec<u8>> {
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
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn confined_references_stay_in_the_folder() {
        let dir = tempfile::tempdir().unwrap();
        let inner = dir.path().join("scene");
        std::fs::create_dir_all(inner.join("sub")).unwrap();
        std::fs::write(inner.join("sub/a.bin"), b"a").unwrap();
        std::fs::write(dir.path().join("outside.bin"), b"b").unwrap();
        let ok = resolve(Some(&inner), Path::new("sub/../sub/a.bin"), References::Confined).unwrap();
        assert_eq!(ok, inner.join("sub/a.bin").canonicalize().unwrap());
        for bad in ["../outside.bin", "/etc/passwd", "sub/../../outside.bin", ""] {
            assert!(resolve(Some(&inner), Path::new(bad), References::Confined).is_err(), "{bad}");
        }
        assert!(resolve(None, Path::new("sub/a.bin"), References::Confined).is_err());
        let anywhere = resolve(Some(&inner), Path::new("../outside.bin"), References::Anywhere).unwrap();
        assert_eq!(std::fs::read(anywhere).unwrap(), b"b");
    }

    #[cfg(unix)]
    #[test]
    fn a_symlink_out_of_the_folder_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let inner = dir.path().join("scene");
        std::fs::create_dir(&inner).unwrap();
        std::fs::write(dir.path().join("secret"), b"s").unwrap();
        std::os::unix::fs::symlink(dir.path().join("secret"), inner.join("link.bin")).unwrap();
        let err = resolve(Some(&inner), Path::new("link.bin"), References::Confined).unwrap_err();
        assert!(err.contains("outside"), "{err}");
    }

    #[test]
    fn percent_decoding() {
        assert_eq!(percent_decode("%2e%2E/a%20b").as_deref(), Some("../a b"));
        assert_eq!(percent_decode("100%").as_deref(), Some("100%"));
        assert_eq!(percent_decode("%ff"), None);
    }
}
