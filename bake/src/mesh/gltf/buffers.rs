//! A glTF document's buffers (the GLB blob, `data:` URIs, files beside it) and the
//! ranges an accessor may read in them, checked before the gltf crate reads.

use std::borrow::Cow;
use std::path::Path;

use super::super::refs::{self, LoadOptions};
use super::{Buffer, Loader};
use crate::error::{Error, Result};

/// Every buffer's bytes: the GLB blob, a `data:` URI, or a file the URI names, read
/// only where `options` allow (`refs::resolve`) and only if it is a regular file within
/// the size limit. A buffer shorter than its declared length is an error.
pub(super) fn load_buffers<'a>(
    document: &gltf::Document,
    mut blob: Option<Buffer<'a>>,
    path: &Path,
    base: Option<&Path>,
    options: &LoadOptions,
    sources: &mut Vec<std::path::PathBuf>,
) -> Result<Vec<Buffer<'a>>> {
    let mut out = Vec::new();
    for buffer in document.buffers() {
        let element = || format!("buffer {}", buffer.index());
        let mut data = match buffer.source() {
            gltf::buffer::Source::Bin => blob.take().ok_or_else(|| Error::Parse {
                path: path.into(),
                element: element(),
                message: "refers to the GLB binary chunk, which the file lacks (or an earlier buffer took)".into(),
            })?,
            gltf::buffer::Source::Uri(uri) if uri.starts_with("data:") => {
                Cow::Owned(data_uri(uri).map_err(|message| Error::Parse {
                    path: path.into(),
                    element: element(),
                    message,
                })?)
            }
            gltf::buffer::Source::Uri(uri) => {
                let refused = |reason: String| Error::Reference {
                    path: path.into(),
                    element: element(),
                    reference: uri.chars().take(200).collect(),
                    reason,
                };
                let target = uri_path(uri).map_err(&refused)?;
                let file = refs::resolve(base, Path::new(&target), options.references).map_err(&refused)?;
                let data = octrace_format::read_regular_file(&file, options.max_file_bytes)
                    .map_err(|e| refused(e.to_string()))?;
                sources.push(file);
                Cow::Owned(data)
            }
        };
        if data.len() < buffer.length() {
            return Err(Error::Parse {
                path: path.into(),
                element: element(),
                message: format!("{} bytes, but its byteLength says {}", data.len(), buffer.length()),
            });
        }
        while data.len() % 4 != 0 {
            data.to_mut().push(0);
        }
        out.push(data);
    }
    Ok(out)
}

/// The bytes of a `data:` URI (RFC 2397): `data:[type][;base64],DATA`, base64 or
/// percent-encoded.
pub(super) fn data_uri(uri: &str) -> std::result::Result<Vec<u8>, String> {
    let rest = &uri["data:".len().min(uri.len())..];
    let Some((head, data)) = rest.split_once(',') else {
        return Err("a data: URI without the ',' that starts its data".into());
    };
    if head.ends_with(";base64") {
        return base64_decode(data).map_err(|at| {
            format!("a base64 data: URI with a character base64 does not have at position {at} of its data")
        });
    }
    refs::percent_decode_bytes(data).ok_or_else(|| "a data: URI with a broken %-escape".into())
}

/// Standard base64 (padding optional), or the position of the first character that is
/// not.
fn base64_decode(text: &str) -> std::result::Result<Vec<u8>, usize> {
    let value = |c: u8| match c {
        b'A'..=b'Z' => Some(c - b'A'),
        b'a'..=b'z' => Some(c - b'a' + 26),
        b'0'..=b'9' => Some(c - b'0' + 52),
        b'+' => Some(62),
        b'/' => Some(63),
        _ => None,
    };
    let bytes = text.trim_end_matches('=').as_bytes();
    let mut out = Vec::with_capacity(bytes.len() * 3 / 4);
    let (mut acc, mut bits) = (0u32, 0);
    for (i, &c) in bytes.iter().enumerate() {
        acc = (acc << 6) | value(c).ok_or(i)? as u32;
        bits += 6;
        if bits >= 8 {
            bits -= 8;
            out.push((acc >> bits) as u8);
        }
    }
    Ok(out)
}

/// The path a buffer URI names: `file:` URIs and relative references, percent-decoded;
/// other schemes are refused.
pub(super) fn uri_path(uri: &str) -> std::result::Result<String, String> {
    // file://HOST/PATH names PATH on HOST: an absolute path on this machine for an
    // empty host or localhost, refused for any other.
    let local = |rest: &str| -> std::result::Result<String, String> {
        let (host, path) = rest.split_at(rest.find('/').unwrap_or(rest.len()));
        if host.is_empty() || host.eq_ignore_ascii_case("localhost") {
            Ok(path.to_string())
        } else {
            Err(format!("a file: URI on another host ('{host}')"))
        }
    };
    let owned;
    let rest = match uri.strip_prefix("file://") {
        Some(rest) => {
            owned = local(rest)?;
            Some(owned.as_str())
        }
        None => uri.strip_prefix("file:"),
    };
    let rest = match rest {
        Some(rest) => rest,
        None if uri.contains(':') => return Err("not a relative path, a file: URI or a data: URI".into()),
        None => uri,
    };
    refs::percent_decode(rest).ok_or_else(|| "does not decode to UTF-8".to_string())
}

/// An accessor may declare at most this many elements per byte of input (document and
/// buffers) beyond [`VIEWLESS_SLACK`]: an accessor without a buffer view (all zeros,
/// perhaps with sparse values) is not backed by bytes, and its count is what the
/// reader allocates.
const ELEMENTS_PER_INPUT_BYTE: usize = 16;
/// Elements any accessor may declare whatever the input's size.
const VIEWLESS_SLACK: usize = 1 << 16;

/// Checks that `bytes` bytes of `elem`-byte elements, `stride` apart, from `offset`
/// fit in a buffer view of `view_len` bytes, and that the view fits in its buffer.
fn check_range(
    view: &gltf::buffer::View<'_>,
    buffers: &[Buffer<'_>],
    offset: usize,
    count: usize,
    elem: usize,
) -> std::result::Result<(), String> {
    let stride = view.stride().unwrap_or(elem);
    if stride < elem {
        return Err(format!("buffer view {} has stride {stride}, less than the element's {elem} bytes", view.index()));
    }
    let end = count
        .checked_sub(1)
        .and_then(|n| n.checked_mul(stride))
        .and_then(|n| n.checked_add(elem))
        .and_then(|n| n.checked_add(offset))
        .ok_or_else(|| format!("{count} elements of {elem} bytes, stride {stride}, overflow"))?;
    if end > view.length() {
        return Err(format!(
            "{count} elements of {elem} bytes from offset {offset} (stride {stride}) need {end} bytes, buffer view {} has {}",
            view.index(),
            view.length()
        ));
    }
    let buffer = view.buffer().index();
    let available = buffers.get(buffer).map_or(0, |d| d.len());
    match view.offset().checked_add(view.length()) {
        Some(view_end) if view_end <= available => Ok(()),
        _ => Err(format!(
            "buffer view {} ({} bytes at {}) runs past buffer {buffer} ({available} bytes)",
            view.index(),
            view.length(),
            view.offset()
        )),
    }
}

impl Loader<'_> {
    /// Every range the reader will touch for `a`, and its count against the input size.
    pub(super) fn check_accessor(&self, a: &gltf::Accessor<'_>) -> std::result::Result<(), String> {
        let count = a.count();
        if count == 0 {
            return Err("count is 0 (the glTF spec requires at least 1)".into());
        }
        let limit = self.input_bytes.saturating_mul(ELEMENTS_PER_INPUT_BYTE).saturating_add(VIEWLESS_SLACK);
        if count > limit {
            return Err(format!(
                "declares {count} elements, more than {limit} for an input of {} bytes",
                self.input_bytes
            ));
        }
        if let Some(view) = a.view() {
            check_range(&view, self.buffers, a.offset(), count, a.size())?;
        }
        if let Some(sparse) = a.sparse() {
            let n = sparse.count();
            if n == 0 || n > count {
                return Err(format!("sparse count {n} outside 1..={count}"));
            }
            let indices = sparse.indices();
            check_range(&indices.view(), self.buffers, indices.offset(), n, indices.index_type().size())
                .map_err(|e| format!("sparse indices: {e}"))?;
            let values = sparse.values();
            check_range(&values.view(), self.buffers, values.offset(), n, a.size())
                .map_err(|e| format!("sparse values: {e}"))?;
        }
        Ok(())
    }
}
