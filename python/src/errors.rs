//! Errors as Python exceptions, and allocations sized by inputs that fail as
//! `MemoryError` rather than aborting.

use std::path::Path;

use pyo3::create_exception;
use pyo3::exceptions::{PyMemoryError, PyOSError, PyRuntimeError, PyValueError};
use pyo3::prelude::*;

create_exception!(
    octrace,
    FormatError,
    PyValueError,
    "A file that is not a valid octrace scene: bad magic, another format version, a \
     checksum that does not match, contents that break the format's rules."
);
create_exception!(
    octrace,
    BakeError,
    PyValueError,
    "A mesh that cannot be baked: it does not parse, names files it may not read, has \
     non-finite coordinates, is empty, or passes a budget (the message says which and where)."
);
create_exception!(
    octrace,
    NotClosedError,
    PyValueError,
    "A query that needs an inside (compute_occupancy, contains, length_inside) on a scene \
     that is not closed: some edge is used by an odd number of triangles."
);

create_exception!(
    octrace,
    GpuError,
    PyRuntimeError,
    "The GPU cannot serve a scene opened with device=\"gpu\": no Vulkan adapter, an adapter \
     without 64-bit floats (the exact triangle test needs them), a scene larger than the \
     adapter's buffers, a device lost; or a module built without the GPU."
);

/// An I/O error as Python's `OSError` subclass for its kind (`FileNotFoundError`,
/// `PermissionError`, ...), with the message that names the file.
pub(crate) fn os_error(source: &std::io::Error, message: String) -> PyErr {
    PyErr::from(std::io::Error::new(source.kind(), message))
}

pub(crate) fn format_error(e: octrace_format::Error) -> PyErr {
    match &e {
        octrace_format::Error::Io { source, .. } | octrace_format::Error::Write { source, .. } => {
            os_error(source, e.to_string())
        }
        _ => FormatError::new_err(e.to_string()),
    }
}

pub(crate) fn runtime_error(e: octrace_runtime::Error) -> PyErr {
    match e {
        octrace_runtime::Error::Format(e) => format_error(e),
        e @ (octrace_runtime::Error::Alloc(_) | octrace_runtime::Error::Budget { .. }) => {
            PyMemoryError::new_err(e.to_string())
        }
        e @ octrace_runtime::Error::NotClosed { .. } => NotClosedError::new_err(e.to_string()),
        e => PyOSError::new_err(e.to_string()),
    }
}

/// An error opening `path`, the file named in the message.
pub(crate) fn open_error(e: octrace_runtime::Error, path: &Path) -> PyErr {
    match e {
        // I/O errors name the file already.
        octrace_runtime::Error::Format(
            e @ (octrace_format::Error::Io { .. } | octrace_format::Error::Write { .. }),
        ) => format_error(e),
        // A mesh given where a baked scene is wanted: say what to do, as the CLI does.
        octrace_runtime::Error::Format(e) => match octrace_bake::MeshFormat::from_path(path) {
            Some((format, _)) => FormatError::new_err(format!(
                "{} is a mesh ({}), not a baked scene: bake it first (octrace.bake('{}', 'scene.oct')), then \
                 open scene.oct",
                path.display(),
                format.name(),
                path.display()
            )),
            None => FormatError::new_err(format!("{}: {e}", path.display())),
        },
        e => runtime_error(e),
    }
}

pub(crate) fn bake_error(e: octrace_bake::Error) -> PyErr {
    match e {
        octrace_bake::Error::Format(e) => format_error(e),
        octrace_bake::Error::Unreadable { ref source, .. } => os_error(source, e.to_string()),
        e => BakeError::new_err(e.to_string()),
    }
}

/// `n` default values, or `MemoryError` naming `what` and the bytes where the
/// allocator refuses (an input's size decides `n`: never an abort).
pub(crate) fn zeros<T: Clone + Default>(n: usize, what: &'static str) -> PyResult<Vec<T>> {
    octrace_format::memory::try_vec(n, what).map_err(memory_error)
}

/// An empty vector with room for `n` values, or `MemoryError` ([`zeros`]).
pub(crate) fn room<T>(n: usize, what: &'static str) -> PyResult<Vec<T>> {
    octrace_format::memory::try_with_capacity(n, what).map_err(memory_error)
}

/// `n` values from `values` in a vector allocated once, or `MemoryError` ([`zeros`]).
pub(crate) fn collected<T>(n: usize, what: &'static str, values: impl Iterator<Item = T>) -> PyResult<Vec<T>> {
    let mut out = room(n, what)?;
    out.extend(values);
    Ok(out)
}

pub(crate) fn memory_error(e: octrace_format::memory::AllocError) -> PyErr {
    PyMemoryError::new_err(e.to_string())
}
