//! The one error type of the format crate.

use std::path::PathBuf;

/// Everything that can go wrong while reading or writing a baked scene file.
///
/// Each variant is something a caller can act on: an I/O failure (with the path),
/// a file that is not ours, a file from another format version, or a file whose
/// contents break the format's rules (`Corrupt`, with what was wrong).
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// The file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file involved.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// The first bytes are not the octrace magic: this is not a baked scene.
    #[error("not an octrace scene (bad magic {found:02x?})")]
    BadMagic {
        /// The first eight bytes found.
        found: [u8; 8],
    },
    /// The file was written by another, incompatible version of the format.
    #[error("unsupported format version {found} (this build reads {supported})")]
    UnsupportedVersion {
        /// The version written in the file, as `major.minor`.
        found: Version,
        /// The newest version this build reads, as `major.minor`.
        supported: Version,
    },
    /// The file is shorter than its header says.
    #[error("truncated file: {what} needs {needed} bytes, the file has {available}")]
    Truncated {
        /// What was being read.
        what: &'static str,
        /// Bytes needed.
        needed: u64,
        /// Bytes present.
        available: u64,
    },
    /// A checksum does not match the bytes it covers.
    #[error("checksum mismatch in {section}: stored {stored:016x}, computed {computed:016x}")]
    Checksum {
        /// The section whose checksum failed.
        section: &'static str,
        /// The checksum stored in the file.
        stored: u64,
        /// The checksum of the bytes read.
        computed: u64,
    },
    /// The file is a zstd-compressed scene, which can be read but not memory-mapped.
    #[error("{path}: a zstd-compressed scene cannot be memory-mapped; read it (SceneFile::read) instead")]
    Compressed {
        /// The file.
        path: PathBuf,
    },
    /// The contents break a rule of the format (an address out of range, a link to a
    /// cell that is not adjacent, ...).
    #[error("corrupt scene: {0}")]
    Corrupt(String),
}

/// A format version, `major.minor`.
///
/// See `FORMAT.md`: a reader accepts the same major version and any minor version up
/// to its own.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub struct Version {
    /// Incompatible layout changes bump this.
    pub major: u16,
    /// Compatible additions bump this.
    pub minor: u16,
}

impl std::fmt::Display for Version {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}.{}", self.major, self.minor)
    }
}

impl Error {
    pub(crate) fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io { path: path.into(), source }
    }

    pub(crate) fn corrupt(msg: impl Into<String>) -> Self {
        Error::Corrupt(msg.into())
    }
}

/// The format crate's result type.
pub type Result<T, E = Error> = std::result::Result<T, E>;
