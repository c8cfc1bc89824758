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
    /// Writing a file failed. Writes go to a temporary file beside the target and are
    /// renamed over it only when complete, so the target is unchanged (and the
    /// temporary file removed).
    #[error("cannot write {path}: {reason} (nothing under that name was changed)")]
    Write {
        /// The target file.
        path: PathBuf,
        /// What went wrong, in words: "no space left on the device", "permission
        /// denied in DIR", ...
        reason: String,
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
    /// The file is an instanced file ([`crate::instanced`]): scenes placed many times,
    /// which opens as a world of instances, not as one scene.
    #[error(
        "an instanced file (meshes placed many times, each stored once): open it as a world (Rust: \
         World::open; Python: octrace.World.open; the CLI's trace, render, contains, distance and inspect \
         open it so), or bake with --flatten for one scene"
    )]
    Instanced,
    /// An instanced file was asked for ([`crate::instanced::InstancedFile::read`]) and
    /// the file is one baked scene.
    #[error(
        "one baked scene, not an instanced file: open it as a scene (Rust: Scene::open; Python: octrace.Scene), \
         and place it in a world with World::add"
    )]
    NotInstanced,
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

    /// A failed write to `path`, with the reason in words.
    pub(crate) fn write(path: &std::path::Path, source: std::io::Error) -> Self {
        let reason = write_failure(path, &source);
        // tempfile appends the temporary file's name ("... at path \"dir/.octrace-x.tmp\"),
        // which means nothing to the user: the source keeps the OS's words alone.
        let text = source.to_string();
        let source = match text.find(" at path ") {
            Some(cut) => std::io::Error::new(source.kind(), &text[..cut]),
            None => source,
        };
        Error::Write { path: path.into(), reason, source }
    }

    pub(crate) fn corrupt(msg: impl Into<String>) -> Self {
        Error::Corrupt(msg.into())
    }
}

/// The format crate's result type.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Says why writing `path` failed in the terms a user acts on.
pub(crate) fn write_failure(path: &std::path::Path, e: &std::io::Error) -> String {
    use std::io::ErrorKind;
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.display().to_string(),
        _ => ".".into(),
    };
    if path.as_os_str().is_empty() {
        return "the name is empty: give a file's name (folder/scene.oct)".into();
    }
    if path.as_os_str().as_encoded_bytes().ends_with(b"/") {
        return "the name ends in '/', a folder's: give the file's name (folder/scene.oct)".into();
    }
    match e.kind() {
        ErrorKind::StorageFull => "no space left on the device".into(),
        ErrorKind::QuotaExceeded => "disk quota exceeded".into(),
        ErrorKind::FileTooLarge => "the file is larger than this process may write (see `ulimit -f`)".into(),
        ErrorKind::PermissionDenied => format!("permission denied in {dir}"),
        ErrorKind::ReadOnlyFilesystem => format!("{dir} is on a read-only file system"),
        ErrorKind::NotFound if std::path::Path::new(&dir).is_dir() => {
            format!("{dir} takes no new files (a virtual file system such as /proc or /sys): write elsewhere")
        }
        ErrorKind::NotFound => format!("the directory {dir} does not exist"),
        ErrorKind::NotADirectory => format!("{dir} is not a directory"),
        // The raw OS error without the temporary file's path that tempfile adds.
        _ => match e.raw_os_error() {
            Some(code) => std::io::Error::from_raw_os_error(code).to_string(),
            None => match e.to_string().split(" at path ").next() {
                Some(words) if !words.is_empty() => words.to_string(),
                _ => e.kind().to_string(),
            },
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::ErrorKind;

    #[test]
    fn write_failures_say_what_to_do() {
        let path = std::path::Path::new("out/scene.oct");
        for (kind, says) in [
            (ErrorKind::StorageFull, "cannot write out/scene.oct: no space left on the device"),
            (ErrorKind::PermissionDenied, "permission denied in out"),
            (ErrorKind::NotFound, "the directory out does not exist"),
            (ErrorKind::FileTooLarge, "ulimit -f"),
            (ErrorKind::ReadOnlyFilesystem, "out is on a read-only file system"),
        ] {
            // What tempfile reports: the OS's words, then the temporary file's path.
            let os = || std::io::Error::new(kind, "os words (os error 1) at path \"out/.octrace-x.tmp\"");
            let msg = Error::write(path, os()).to_string();
            assert!(msg.contains(says) && msg.contains("nothing under that name was changed"), "{msg}");
            let e = Error::write(path, os());
            let source = std::error::Error::source(&e).unwrap().to_string();
            assert!(!msg.contains(".tmp") && !source.contains(".tmp"), "{msg}: {source}");
        }
        let msg = Error::write(path, std::io::Error::from_raw_os_error(28)).to_string();
        assert!(msg.contains("no space left on the device"), "{msg}");
        // An empty name, and a folder that exists but takes no files (issue 46, item 9:
        // they were "the directory . does not exist" and "the directory /proc/self does
        // not exist").
        let not_found = || std::io::Error::from(ErrorKind::NotFound);
        let msg = Error::write(std::path::Path::new(""), not_found()).to_string();
        assert!(msg.contains("the name is empty"), "{msg}");
        let msg = Error::write(std::path::Path::new("/proc/self/mem"), not_found()).to_string();
        assert!(msg.contains("/proc/self takes no new files"), "{msg}");
    }
}
