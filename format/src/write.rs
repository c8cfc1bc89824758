//! Writing baked scenes: archive, header, and an atomic replace of the target.

use std::io::Write;
use std::path::Path;

use rkyv::rancor;

use crate::error::{Error, Result};
use crate::header::{Header, RKYV_SETTINGS, VERSION};
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
        let payload = rkyv::to_bytes::<rancor::Error>(self)
            .map_err(|e| Error::corrupt(format!("cannot archive the scene: {e}")))?;
        let header = Header {
            version: VERSION,
            flags: 0,
            rkyv_settings: RKYV_SETTINGS,
            payload_len: payload.len() as u64,
            payload_xxh3: xxhash_rust::xxh3::xxh3_64(&payload),
            bake_time_us,
        };
        let mut out = Vec::with_capacity(crate::header::HEADER_LEN + payload.len());
        out.extend_from_slice(&header.encode());
        out.extend_from_slice(&payload);
        Ok(out)
    }

    /// Writes the scene to `path` atomically: into a temporary file beside it, flushed
    /// to disk, then renamed over `path`. An interrupted write never leaves a partial
    /// file under `path`. Returns the bytes written.
    ///
    /// # Errors
    /// [`Error::Io`] naming the path on any failure (the temporary file is removed).
    pub fn write(&self, path: impl AsRef<Path>, bake_time_us: u64) -> Result<u64> {
        let bytes = self.to_file_bytes(bake_time_us)?;
        write_atomically(path.as_ref(), &bytes)?;
        Ok(bytes.len() as u64)
    }
}

/// Writes `bytes` to `path` through a temporary file in the same directory and a rename.
///
/// # Errors
/// [`Error::Io`] naming `path`.
pub fn write_atomically(path: &Path, bytes: &[u8]) -> Result<()> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let io = |e: std::io::Error| Error::io(path, e);
    let mut tmp = tempfile::Builder::new()
        .prefix(".octrace-")
        .suffix(".tmp")
        .tempfile_in(dir)
        .map_err(io)?;
    tmp.write_all(bytes).map_err(io)?;
    tmp.as_file().sync_all().map_err(io)?;
    tmp.persist(path).map_err(|e| io(e.error))?;
    Ok(())
}
