//! Writing baked scenes: archive, header, and an atomic replace of the target.

use std::io::{Seek, Write};

use std::path::Path;
use xxhash_rust::xxh3::Xxh3;

use rkyv::rancor;
use rkyv::util::AlignedVec;

use crate::error::{Error, Result};
use crate::header::{Header, ARCHIVE_ALIGN, HEADER_LEN, SECTION_COUNT};
use crate::scene::{ArchivedBakedScene, BakedScene};

impl BakedScene {
    /// Serializes the scene to a complete file image: header, then archive.
    ///
    /// `bake_time_us` is recorded in the header (0 for a reproducible file). The
    /// archive is a pure function of the scene, so the same scene always gives the
    /// same archive bytes.
    ///
    /// # Errors
    /// [`Error::Corrupt`] if rkyv cannot serialize the scene (its relative pointers
    /// are 64-bit, so no size this machine can hold is refused for its size).
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
        let buffer = AlignedVec::<ARCHIVE_ALIGN>::with_capacity(self.array_bytes() as usize + 1024);
        let payload = rkyv::api::high::to_bytes_in::<_, rancor::BoxedError>(self, buffer)
            .map_err(|e| Error::corrupt(format!("cannot archive the scene: {e}")))?;
        let mut sections = SectionHasher::new(self);
        sections.update(&payload);
        Ok((Header::new(sections.finish()?, bake_time_us), payload))
    }

    /// Bytes of all the arrays together.
    fn array_bytes(&self) -> u64 {
        self.view().section_words().iter().map(|a| 4 * a.len() as u64).sum()
    }

    /// Writes the scene to `path` atomically: into a temporary file beside it, flushed
    /// to disk, then renamed over `path`. An interrupted write never leaves a partial
    /// file under `path`: on an error the temporary file is removed, and a process
    /// killed mid-write leaves only its temporary file (`.octrace-*.tmp` beside the
    /// target, which nothing reads and which may be deleted). Returns the bytes written.
    ///
    /// The archive is streamed to the file as rkyv produces it, hashed on the way, and
    /// the header written last: no in-memory copy of a file that can be hundreds of
    /// megabytes (on a fresh machine, zeroing the pages of such a copy costs more than
    /// writing it).
    ///
    /// `bake_time_us` is the bake's duration in microseconds, recorded in the header
    /// for `inspect`; pass 0 (what `octrace bake` writes unless `--record-time`) to keep
    /// the file reproducible: the same scene then always gives the same bytes.
    ///
    /// # Errors
    /// [`Error::Write`] naming the path on any failure (the temporary file is removed).
    pub fn write(&self, path: impl AsRef<Path>, bake_time_us: u64) -> Result<u64> {
        let path = path.as_ref();
        let io = |e: std::io::Error| Error::write(path, e);
        let path = match destination(path)? {
            Destination::Replace(target) => target,
            Destination::Direct(target) => {
                let image = self.to_file_bytes(bake_time_us)?;
                write_direct(path, &target, &[&image])?;
                return Ok(image.len() as u64);
            }
        };
        let path = path.as_path();
        let mut tmp = temporary_beside(path)?;
        let file = tmp.as_file_mut();
        file.write_all(&[0u8; HEADER_LEN]).map_err(io)?;
        let sections = {
            let mut sink = HashingWriter {
                inner: std::io::BufWriter::with_capacity(1 << 20, &mut *file),
                sections: SectionHasher::new(self),
                failure: None,
            };
            let archived = rkyv::api::high::to_bytes_in::<_, rancor::BoxedError>(
                self,
                rkyv::ser::writer::IoWriter::new(&mut sink),
            )
            .map(drop);
            if let Some(e) = sink.failure.take() {
                return Err(io(e));
            }
            archived.map_err(|e| Error::corrupt(format!("cannot archive the scene: {e}")))?;
            sink.inner.flush().map_err(io)?;
            sink.sections
        };
        let header = Header::new(sections.finish()?, bake_time_us);
        let payload_len = header.payload_len;
        file.seek(std::io::SeekFrom::Start(0)).map_err(io)?;
        file.write_all(&header.encode()).map_err(io)?;
        finish(tmp, path)?;
        Ok(HEADER_LEN as u64 + payload_len)
    }
}

impl BakedScene {
    /// Writes the scene zstd-compressed (`level` 1-22; 3 is a good default) to `path`,
    /// atomically like [`BakedScene::write`]. The stream decompresses to exactly the
    /// bytes of the uncompressed file. Returns (uncompressed, compressed) sizes.
    ///
    /// # Errors
    /// [`Error::Write`] naming the path.
    pub fn write_compressed(&self, path: impl AsRef<Path>, bake_time_us: u64, level: i32) -> Result<(u64, u64)> {
        let path = path.as_ref();
        let io = |e: std::io::Error| Error::write(path, e);
        let image = self.to_file_bytes(bake_time_us)?;
        let target = match destination(path)? {
            Destination::Replace(target) => target,
            Destination::Direct(target) => {
                let compressed = zstd::bulk::compress(&image, level).map_err(io)?;
                write_direct(path, &target, &[&compressed])?;
                return Ok((image.len() as u64, compressed.len() as u64));
            }
        };
        let mut tmp = temporary_beside(&target)?;
        let mut encoder = zstd::stream::write::Encoder::new(tmp.as_file_mut(), level).map_err(io)?;
        encoder.write_all(&image).map_err(io)?;
        encoder.finish().map_err(io)?;
        let compressed = tmp.as_file().metadata().map_err(io)?.len();
        finish(tmp, &target)?;
        Ok((image.len() as u64, compressed))
    }
}

/// Passes writes through and hashes them, section by section.
struct HashingWriter<W> {
    inner: W,
    sections: SectionHasher,
    /// The first write error: rkyv's error type keeps no trace of it.
    failure: Option<std::io::Error>,
}

impl<W: Write> Write for HashingWriter<W> {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        match self.inner.write(buf) {
            Ok(n) => {
                self.sections.update(&buf[..n]);
                Ok(n)
            }
            Err(e) => {
                let kind = e.kind();
                self.failure.get_or_insert(e);
                Err(kind.into())
            }
        }
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.inner.flush()
    }
}

/// Hashes an archive as it streams by, in the sections of
/// [`crate::header::SECTION_NAMES`]: each array's bytes, then the rest (`root`).
///
/// The arrays are `u32`/`f32` vectors, which rkyv writes back to back in field order
/// with no padding (4-byte elements, 4-byte alignment), so their sections' ends are
/// known before a byte is written; [`SectionHasher::finish`] checks that the archive
/// went on past them at least by the root object, and validation checks every array
/// against its section.
struct SectionHasher {
    /// End offset of each array's section.
    ends: [u64; SECTION_COUNT - 1],
    /// The shortest archive the layout allows: the arrays, then the root object.
    min_end: u64,
    pos: u64,
    start: u64,
    index: usize,
    hasher: Xxh3,
    sums: [(u64, u64); SECTION_COUNT],
}

impl SectionHasher {
    fn new(scene: &BakedScene) -> Self {
        let mut end = 0u64;
        let ends = scene.view().section_words().map(|a| {
            end += 4 * a.len() as u64;
            end
        });
        let align = std::mem::align_of::<ArchivedBakedScene>() as u64;
        let min_end = end.next_multiple_of(align) + std::mem::size_of::<ArchivedBakedScene>() as u64;
        SectionHasher { ends, min_end, pos: 0, start: 0, index: 0, hasher: Xxh3::new(), sums: [(0, 0); SECTION_COUNT] }
    }

    fn update(&mut self, mut buf: &[u8]) {
        while !buf.is_empty() {
            let room = match self.ends.get(self.index) {
                Some(&end) => end - self.pos,
                None => u64::MAX,
            };
            if room == 0 {
                self.close();
                continue;
            }
            let n = buf.len().min(usize::try_from(room).unwrap_or(usize::MAX));
            self.hasher.update(&buf[..n]);
            self.pos += n as u64;
            buf = &buf[n..];
        }
    }

    /// Ends the current section.
    fn close(&mut self) {
        self.sums[self.index] = (self.pos - self.start, self.hasher.digest());
        self.hasher.reset();
        self.start = self.pos;
        self.index += 1;
    }

    fn finish(mut self) -> Result<[(u64, u64); SECTION_COUNT]> {
        while self.index < SECTION_COUNT - 1 && self.pos == self.ends[self.index] {
            self.close();
        }
        if self.index != SECTION_COUNT - 1 || self.pos < self.min_end {
            return Err(Error::corrupt(format!(
                "internal: rkyv wrote {} bytes, the section layout expects at least {}",
                self.pos, self.min_end
            )));
        }
        self.close();
        Ok(self.sums)
    }
}

/// A temporary file in `path`'s directory, removed unless [`finish`]ed.
fn temporary_beside(path: &Path) -> Result<tempfile::NamedTempFile> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    tempfile::Builder::new().prefix(".octrace-").suffix(".tmp").tempfile_in(dir).map_err(|e| Error::write(path, e))
}

/// Gives the temporary file `path`'s permissions (or 0644), flushes it to disk and
/// renames it over `path`.
fn finish(tmp: tempfile::NamedTempFile, path: &Path) -> Result<()> {
    let io = |e: std::io::Error| Error::write(path, e);
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

/// Writes `parts`, one after the other, to `path` through a temporary file in the same
/// directory, `fsync`, and a rename: readers see the old file or the whole new one.
///
/// What `path` names decides how (every writer of this crate does the same):
/// - nothing, or a regular file: replaced atomically as above;
/// - a symbolic link: the file it leads to is replaced (the link stays a link);
/// - a FIFO, a character device (`/dev/null`, a terminal) or a socket: written to
///   directly, never replaced by a regular file (a FIFO waits for its reader);
/// - a folder: an error.
///
/// # Errors
/// [`Error::Write`] naming `path`.
pub fn write_atomically(path: &Path, parts: &[&[u8]]) -> Result<()> {
    let target = match destination(path)? {
        Destination::Replace(target) => target,
        Destination::Direct(target) => return write_direct(path, &target, parts),
    };
    let mut tmp = temporary_beside(&target)?;
    for part in parts {
        tmp.write_all(part).map_err(|e| Error::write(path, e))?;
    }
    finish(tmp, &target)
}

/// How a write to a path is done.
enum Destination {
    /// Through a temporary file renamed over this path (a regular file or nothing).
    Replace(std::path::PathBuf),
    /// Straight into this existing FIFO, device or socket.
    Direct(std::path::PathBuf),
}

/// Follows `path`'s symbolic links to what a write should replace or write into.
fn destination(path: &Path) -> Result<Destination> {
    let fail = |message: &str| Error::write(path, std::io::Error::other(message.to_string()));
    let mut p = path.to_path_buf();
    for _ in 0..40 {
        let meta = match std::fs::symlink_metadata(&p) {
            Ok(meta) => meta,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Destination::Replace(p)),
            Err(e) => return Err(Error::write(path, e)),
        };
        let kind = meta.file_type();
        if kind.is_symlink() {
            refuse_planted_link(path, &p, &meta)?;
            let link = std::fs::read_link(&p).map_err(|e| Error::write(path, e))?;
            // A relative link is relative to the link's folder; `join` keeps an absolute one.
            p = p.parent().map_or_else(|| link.clone(), |dir| dir.join(&link));
        } else if kind.is_file() {
            return Ok(Destination::Replace(p));
        } else if kind.is_dir() {
            return Err(fail("it is a folder"));
        } else {
            return Ok(Destination::Direct(p));
        }
    }
    Err(fail("too many levels of symbolic links"))
}

/// Refuses to follow the symbolic link `link` (met writing `path`) where someone else
/// could have planted it: in a sticky, world-writable folder (`/tmp`), a link owned by
/// neither this process's user nor the folder's owner. The kernel's
/// `fs.protected_symlinks` rule, applied by the writer itself: it resolves links to
/// replace their target atomically, so the kernel's check at open never runs.
#[cfg(unix)]
fn refuse_planted_link(path: &Path, link: &Path, meta: &std::fs::Metadata) -> Result<()> {
    use std::os::unix::fs::MetadataExt;
    let folder = match link.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let Ok(dir) = std::fs::metadata(folder) else { return Ok(()) };
    let shared = dir.mode() & 0o1002 == 0o1002;
    // SAFETY: geteuid has no preconditions and cannot fail.
    let me = unsafe { libc::geteuid() };
    if shared && meta.uid() != me && meta.uid() != dir.uid() {
        return Err(Error::write(
            path,
            std::io::Error::other(format!(
                "{} is a symbolic link owned by another user (uid {}) in the shared folder {}: not followed \
                 (a link someone else may have planted; the kernel's protected_symlinks rule)",
                link.display(),
                meta.uid(),
                folder.display()
            )),
        ));
    }
    Ok(())
}

#[cfg(not(unix))]
fn refuse_planted_link(_: &Path, _: &Path, _: &std::fs::Metadata) -> Result<()> {
    Ok(())
}

/// Writes `parts` into an existing FIFO, device or socket (not atomic: there is no file
/// to replace).
fn write_direct(path: &Path, target: &Path, parts: &[&[u8]]) -> Result<()> {
    let io = |e: std::io::Error| Error::write(path, e);
    let mut file = std::fs::OpenOptions::new().write(true).open(target).map_err(io)?;
    for part in parts {
        file.write_all(part).map_err(io)?;
    }
    file.flush().map_err(io)
}

#[cfg(all(test, unix))]
mod tests {
    use super::*;

    #[test]
    fn a_symlink_is_written_through_and_stays_a_link() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::create_dir(dir.path().join("real")).unwrap();
        std::fs::write(dir.path().join("real/target"), b"old").unwrap();
        let link = dir.path().join("link");
        std::os::unix::fs::symlink("real/target", &link).unwrap();
        write_atomically(&link, &[b"new"]).unwrap();
        assert!(std::fs::symlink_metadata(&link).unwrap().file_type().is_symlink());
        assert_eq!(std::fs::read(dir.path().join("real/target")).unwrap(), b"new");
        // A dangling link: its target is created.
        let dangling = dir.path().join("dangling");
        std::os::unix::fs::symlink("real/later", &dangling).unwrap();
        write_atomically(&dangling, &[b"made"]).unwrap();
        assert_eq!(std::fs::read(dir.path().join("real/later")).unwrap(), b"made");
        // A loop is an error, not a hang.
        let (a, b) = (dir.path().join("a"), dir.path().join("b"));
        std::os::unix::fs::symlink(&b, &a).unwrap();
        std::os::unix::fs::symlink(&a, &b).unwrap();
        let err = write_atomically(&a, &[b"x"]).unwrap_err().to_string();
        assert!(err.contains("symbolic links"), "{err}");
    }

    /// A link planted in a shared sticky folder by another user is not followed (the
    /// target is untouched); the user's own link there is. Needs to give a link away
    /// (root, as in CI); elsewhere the refusal is not reachable and the test says so.
    #[test]
    fn links_planted_in_shared_sticky_folders_are_not_followed() {
        use std::os::unix::fs::PermissionsExt;
        let dir = tempfile::tempdir().unwrap();
        let shared = dir.path().join("shared");
        std::fs::create_dir(&shared).unwrap();
        std::fs::set_permissions(&shared, std::fs::Permissions::from_mode(0o1777)).unwrap();
        let victim = dir.path().join("victim");
        std::fs::write(&victim, b"precious").unwrap();
        let mine = shared.join("mine");
        std::os::unix::fs::symlink(&victim, &mine).unwrap();
        let planted = shared.join("render.png");
        std::os::unix::fs::symlink(&victim, &planted).unwrap();
        let c = std::ffi::CString::new(planted.as_os_str().as_encoded_bytes()).unwrap();
        // SAFETY: a valid NUL-terminated path; lchown changes only the link's owner.
        if unsafe { libc::lchown(c.as_ptr(), 54_321, 54_321) } != 0 {
            eprintln!("SKIPPED links_planted_in_shared_sticky_folders_are_not_followed: cannot give a link away");
            return;
        }
        let err = write_atomically(&planted, &[b"overwritten"]).unwrap_err().to_string();
        assert!(err.contains("owned by another user (uid 54321)") && err.contains("not followed"), "{err}");
        assert_eq!(std::fs::read(&victim).unwrap(), b"precious");
        write_atomically(&mine, &[b"mine"]).unwrap();
        assert_eq!(std::fs::read(&victim).unwrap(), b"mine");
    }

    #[test]
    fn devices_and_fifos_are_written_into_never_replaced() {
        write_atomically(Path::new("/dev/null"), &[b"discarded"]).unwrap();
        use std::os::unix::fs::FileTypeExt;
        assert!(std::fs::metadata("/dev/null").unwrap().file_type().is_char_device());
        let dir = tempfile::tempdir().unwrap();
        let fifo = dir.path().join("pipe");
        let status = std::process::Command::new("mkfifo").arg(&fifo).status().unwrap();
        assert!(status.success());
        let reader = {
            let fifo = fifo.clone();
            std::thread::spawn(move || std::fs::read(fifo).unwrap())
        };
        write_atomically(&fifo, &[b"through ", b"the pipe"]).unwrap();
        assert_eq!(reader.join().unwrap(), b"through the pipe");
        assert!(std::fs::symlink_metadata(&fifo).unwrap().file_type().is_fifo());
        let err = write_atomically(dir.path(), &[b"x"]).unwrap_err().to_string();
        assert!(err.contains("it is a folder"), "{err}");
    }
}
