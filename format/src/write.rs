//! Writing baked scenes: archive, header, and an atomic replace of the target.

use std::io::Write;
use std::path::Path;

use rkyv::rancor;
use rkyv::util::AlignedVec;

use crate::error::{Error, Result};
use crate::header::{Header, ARCHIVE_ALIGN, RKYV_SETTINGS, VERSION};
use crate::scene::BakedScene;

impl BakedScene {
    /// Serializes the scene to a complete file image: header, then archive.
    ///
    /// `bake_time_us` is recorded in the header (0 for a reproducible file). The
    /// archive is a pure function of the scene, so the same scene always gives the
    /// same archive bytes.
    ///
    /// # Errors
    /// [`Error::Corrupt`] if rkyv cannot serialize the scene (arrays beyond 4 GiB).
    pub fn to_file_bytes(&self, bake_time_us: u64) -> Result<Vec<u8>> {
        let (header, payload) = self.archive(bake_time_us)?;
        let mut out = Vec::with_capacity(crate::header::HEADER_LEN + payload.len());
        out.extend_from_slice(&header.encode());
        out.extend_from_slice(&payload);
        Ok(out)
    }

    /// The archive and the header that describes it.
    fn archive(&self, bake_time_us: u64) -> Result<(Header, AlignedVec<ARCHIVE_ALIGN>)> {
        // Sized up front: growing a buffer of a hundred megabytes by doubling costs more
        // than the serialization itself.
        let arrays = self.octree.len()
            + self.tri_refs.len()
            + self.triangles.len()
            + self.triangle_ids.len()
            + self.boxes.len()
            + self.cube_map.len()
            + self.nodes.len();
        let buffer = AlignedVec::<ARCHIVE_ALIGN>::with_capacity(4 * arrays + 1024);
        let payload = rkyv::api::high::to_bytes_in::<_, rancor::Error>(self, buffer)
            .map_err(|e| Error::corrupt(format!("cannot archive the scene: {e}")))?;
        let header = Header {
            version: VERSION,
            flags: 0,
            rkyv_settings: RKYV_SETTINGS,
            payload_len: payload.len() as u64,
            payload_xxh3: xxhash_rust::xxh3::xxh3_64(&payload),
            bake_time_us,
        };
        Ok((header, payload))
    }

    /// Writes the scene to `path` atomically: into a temporary file beside it, flushed
    /// to disk, then renamed over `path`. An interrupted write never leaves a partial
    /// file under `path`. Returns the bytes written.
    ///
    /// # Errors
    /// [`Error::Io`] naming the path on any failure (the temporary file is removed).
    pub fn write(&self, path: impl AsRef<Path>, bake_time_us: u64) -> Result<u64> {
        let (header, payload) = self.archive(bake_time_us)?;
        write_atomically(path.as_ref(), &[&header.encode(), &payload])?;
        Ok((crate::header::HEADER_LEN + payload.len()) as u64)
    }
}

/// Writes `parts`, one after the other, to `path` through a temporary file in the same
/// directory, `fsync`, and a rename: readers see the old file or the whole new one.
///
/// # Errors
/// [`Error::Io`] naming `path`.
pub fn write_atomically(path: &Path, parts: &[&[u8]]) -> Result<()> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let io = |e: std::io::Error| Error::io(path, e);
    let mut tmp = tempfile::Builder::new().prefix(".octrace-").suffix(".tmp").tempfile_in(dir).map_err(io)?;
    for part in parts {
        tmp.write_all(part).map_err(io)?;
    }
    // A temporary file is private (0600); the result gets the target's permissions
    // when it replaces a file, else the usual 0644.
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let mode = std::fs::metadata(path).map(|m| m.permissions().mode()).unwrap_or(0o644);
        tmp.as_file().set_permissions(std::fs::Permissions::from_mode(mode)).map_err(io)?;
    }
    tmp.as_file().sync_all().map_err(io)?;
    tmp.persist(path).map_err(|e| io(e.error))?;
    Ok(())
}
