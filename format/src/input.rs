//! Opening input files as untrusted: only regular files, never waiting on a FIFO, and
//! never more bytes than a stated limit. Scenes are opened this way, and so are the
//! meshes, buffers, material libraries and ray files the other crates read.

use std::fs::File;
use std::io::Read;
use std::path::Path;

/// Opens a file for reading, refusing what is not a regular file (a FIFO, a device, a
/// socket, a folder) before a byte is read; the error says which it is. A FIFO is
/// opened without waiting for a writer, so refusing one cannot hang.
///
/// # Errors
/// The I/O error, or [`std::io::ErrorKind::InvalidInput`] for a file that is not
/// regular.
pub fn open_regular_file(path: &Path) -> std::io::Result<File> {
    let mut options = std::fs::OpenOptions::new();
    options.read(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        // O_NONBLOCK: opening a FIFO for reading would otherwise wait for a writer
        // (it changes nothing for a regular file).
        options.custom_flags(libc::O_NONBLOCK);
    }
    let file = options.open(path)?;
    let kind = file.metadata()?.file_type();
    if !kind.is_file() {
        return Err(invalid(format!("not a regular file ({})", kind_of(&kind))));
    }
    Ok(file)
}

/// Reads a whole regular file of at most `max` bytes ([`open_regular_file`]'s rules):
/// a larger file is refused before a byte is read, and one that grows past `max` while
/// it is read is refused too.
///
/// # Errors
/// As [`open_regular_file`], [`std::io::ErrorKind::InvalidInput`] for a file over
/// the limit, and [`std::io::ErrorKind::OutOfMemory`] where the allocator refuses its
/// size (never an abort).
///
/// # Example
/// ```
/// let err = octrace_format::read_regular_file("/dev/zero".as_ref(), 1 << 20).unwrap_err();
/// assert!(err.to_string().contains("not a regular file (a device)"));
/// ```
pub fn read_regular_file(path: &Path, max: u64) -> std::io::Result<Vec<u8>> {
    let file = open_regular_file(path)?;
    let len = file.metadata()?.len();
    if len > max {
        return Err(invalid(format!("{len} bytes, more than the limit of {max}")));
    }
    let mut out = crate::memory::try_with_capacity(len as usize, "bytes")
        .map_err(|_| out_of_memory(format!("its {len} bytes are more than this process could allocate")))?;
    file.take(max + 1).read_to_end(&mut out)?;
    if out.len() as u64 > max {
        return Err(invalid(format!("grew past the limit of {max} bytes while read")));
    }
    Ok(out)
}

/// Reads a whole regular file of fixed-size records ([`open_regular_file`]'s rules)
/// straight into a vector of them: at most `max` records, whole ones, in one
/// allocation the size of the file made fallibly (a file larger than the memory this
/// process may have is an error naming its size, never an abort).
///
/// # Errors
/// As [`open_regular_file`]; [`std::io::ErrorKind::InvalidInput`] for a file over the
/// limit, changed while it is read, or not a whole number of records (naming `what`,
/// the record in words, and its size); [`std::io::ErrorKind::OutOfMemory`] where the
/// allocator refuses.
///
/// # Example
/// ```
/// let dir = tempfile::tempdir().unwrap();
/// let path = dir.path().join("points.bin");
/// std::fs::write(&path, bytemuck::cast_slice::<f32, u8>(&[1.0, 2.0, 3.0, 4.0, 5.0, 6.0])).unwrap();
/// let points: Vec<[f32; 3]> = octrace_format::read_records(&path, 10, "point").unwrap();
/// assert_eq!(points, [[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]);
/// assert!(octrace_format::read_records::<[f32; 4]>(&path, 10, "ray").is_err()); // 24 bytes
/// ```
pub fn read_records<T: bytemuck::Pod>(path: &Path, max: u64, what: &str) -> std::io::Result<Vec<T>> {
    let size = std::mem::size_of::<T>() as u64;
    let mut file = open_regular_file(path)?;
    let len = file.metadata()?.len();
    if len > max.saturating_mul(size) {
        return Err(invalid(format!("{len} bytes, more than the limit of {max} {what}s ({} bytes)", max * size)));
    }
    if len % size != 0 {
        return Err(invalid(format!("{len} bytes is not a whole number of {size}-byte {what}s")));
    }
    let n = (len / size) as usize;
    let mut out: Vec<T> = crate::memory::try_vec_zeroed(n).map_err(|_| {
        out_of_memory(format!("its {n} {what}s need {len} bytes, more than this process could allocate"))
    })?;
    file.read_exact(bytemuck::cast_slice_mut(&mut out)).map_err(|e| match e.kind() {
        std::io::ErrorKind::UnexpectedEof => invalid("shrank while it was read".into()),
        _ => e,
    })?;
    if file.read(&mut [0u8; 1])? != 0 {
        return Err(invalid("grew while it was read".into()));
    }
    Ok(out)
}

fn out_of_memory(message: String) -> std::io::Error {
    std::io::Error::new(std::io::ErrorKind::OutOfMemory, message)
}

fn invalid(message: String) -> std::io::Error {
    std::io::Error::new(std::io::ErrorKind::InvalidInput, message)
}

/// What a file that is not regular is, in words.
fn kind_of(t: &std::fs::FileType) -> &'static str {
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if t.is_fifo() {
            return "a FIFO";
        }
        if t.is_char_device() || t.is_block_device() {
            return "a device";
        }
        if t.is_socket() {
            return "a socket";
        }
    }
    if t.is_dir() {
        "a folder"
    } else {
        "not a file"
    }
}

/// Whether `a` and `b` name the same existing file: the same device and inode on Unix
/// (so another path to it, or a hard link, counts), the same canonical path elsewhere.
/// What a command checks before it writes, so that its output never destroys an input.
///
/// # Example
/// ```
/// let dir = tempfile::tempdir()?;
/// let (a, b) = (dir.path().join("a.oct"), dir.path().join("b.oct"));
/// std::fs::write(&a, b"x")?;
/// std::fs::hard_link(&a, &b)?;
/// assert!(octrace_format::same_file(&a, &b));
/// assert!(!octrace_format::same_file(&a, &dir.path().join("missing")));
/// # Ok::<(), std::io::Error>(())
/// ```
pub fn same_file(a: &Path, b: &Path) -> bool {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        matches!((std::fs::metadata(a), std::fs::metadata(b)), (Ok(a), Ok(b)) if a.dev() == b.dev() && a.ino() == b.ino())
    }
    #[cfg(not(unix))]
    {
        matches!((a.canonicalize(), b.canonicalize()), (Ok(a), Ok(b)) if a == b)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_regular_files_within_the_limit_are_read() {
        let dir = tempfile::tempdir().unwrap();
        let f = dir.path().join("f");
        std::fs::write(&f, [7u8; 100]).unwrap();
        assert_eq!(read_regular_file(&f, 100).unwrap().len(), 100);
        let err = read_regular_file(&f, 99).unwrap_err().to_string();
        assert!(err.contains("more than the limit of 99"), "{err}");
        let err = read_regular_file(dir.path(), 1 << 20).unwrap_err().to_string();
        assert!(err.contains("not a regular file (a folder)"), "{err}");
        #[cfg(unix)]
        {
            let err = read_regular_file(Path::new("/dev/zero"), 1 << 20).unwrap_err().to_string();
            assert!(err.contains("a device"), "{err}");
        }
    }
}
