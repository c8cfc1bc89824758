//! Opening baked scenes: memory-mapped or read into aligned memory, validated or
//! trusted. All of the format crate's `unsafe` lives here.

use std::fs::File;
use std::io::Read;
use std::path::Path;

use rkyv::rancor;
use rkyv::util::AlignedVec;

use crate::error::{Error, Result};
use crate::header::{Header, Section, ARCHIVE_ALIGN, HEADER_LEN};
use crate::scene::{ArchivedBakedScene, BakeParams, BakeStats, Bounds};
use crate::shading::Shading;
use crate::view::SceneView;

#[cfg(target_endian = "big")]
compile_error!("octrace files are little-endian and read zero-copy: big-endian targets are not supported");

/// Where a scene's bytes live.
enum Storage {
    /// A read-only memory map of the whole file (header included).
    Mapped(memmap2::Mmap),
    /// The archive alone, copied into memory aligned for rkyv.
    Owned(AlignedVec<ARCHIVE_ALIGN>),
}

/// An open baked scene: its header and its archive, mapped or in memory.
///
/// Obtain one with [`SceneFile::read`] (safe: reads into memory and validates
/// everything), [`SceneFile::map`] (maps the file and validates everything),
/// [`SceneFile::from_bytes`], or the trusted [`SceneFile::map_unchecked`], which checks
/// the header alone and is meant for files this process or a trusted pipeline baked.
pub struct SceneFile {
    storage: Storage,
    header: Header,
    /// The archive's shading data, deserialized at open (a few kilobytes at most for
    /// materials, lights and cameras): the views borrow it.
    shading: Shading,
    /// The encoded images' texels, decoded when first read.
    decoded: crate::TexelCache,
}

impl std::fmt::Debug for SceneFile {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let kind = match self.storage {
            Storage::Mapped(_) => "mapped",
            Storage::Owned(_) => "in memory",
        };
        f.debug_struct("SceneFile").field("storage", &kind).field("header", &self.header).finish()
    }
}

impl SceneFile {
    /// Reads the file into aligned memory and validates it completely: header,
    /// checksum, archive structure and every semantic rule.
    ///
    /// This is the path for files that may change while open; see [`SceneFile::map`].
    ///
    /// # Errors
    /// [`Error::Io`] if the file cannot be read, or any of the header and validation
    /// errors.
    pub fn read(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let mut file = open_regular(path)?;
        let len = file.metadata().map_err(|e| Error::io(path, e))?.len();
        if is_compressed(&mut file).map_err(|e| Error::io(path, e))? {
            return Self::read_compressed(file, len, path);
        }
        let mut head = Vec::with_capacity(HEADER_LEN);
        (&mut file).take(HEADER_LEN as u64).read_to_end(&mut head).map_err(|e| Error::io(path, e))?;
        let header = Header::decode(&head, len)?;
        let payload_len = usize::try_from(header.payload_len)
            .map_err(|_| Error::corrupt("archive larger than this machine's address space"))?;
        let mut payload = AlignedVec::<ARCHIVE_ALIGN>::with_capacity(payload_len);
        huge_pages(&mut payload);
        payload.resize(payload_len, 0);
        file.read_exact(&mut payload).map_err(|e| Error::io(path, e))?;
        Self::validated(Storage::Owned(payload), header)
    }

    /// Reads a zstd-compressed scene: the header first, then exactly the archive it
    /// declares, decompressed into aligned memory. A declared archive more than
    /// [`MAX_COMPRESSION_RATIO`] times the compressed file is refused before anything
    /// is allocated.
    fn read_compressed(file: File, compressed_len: u64, path: &Path) -> Result<Self> {
        let io = |e: std::io::Error| Error::io(path, e);
        let mut stream = zstd::stream::read::Decoder::new(file).map_err(io)?;
        let mut head = Vec::with_capacity(HEADER_LEN);
        (&mut stream).take(HEADER_LEN as u64).read_to_end(&mut head).map_err(io)?;
        let header = Header::decode_stream(&head)?;
        let bound = compressed_len.saturating_mul(MAX_COMPRESSION_RATIO);
        if header.payload_len > bound {
            return Err(Error::corrupt(format!(
                "the archive declares {} bytes, more than {MAX_COMPRESSION_RATIO} times the compressed file",
                header.payload_len
            )));
        }
        let payload_len = usize::try_from(header.payload_len)
            .map_err(|_| Error::corrupt("archive larger than this machine's address space"))?;
        // Memory grows with what the stream really yields, in steps, never past the
        // declared length: a small file that claims a large archive and then ends costs
        // what it decompressed to, not what it claimed.
        let mut payload = AlignedVec::<ARCHIVE_ALIGN>::new();
        let mut chunk = vec![0u8; payload_len.min(4 << 20)];
        while payload.len() < payload_len {
            let want = (payload_len - payload.len()).min(chunk.len());
            match stream.read(&mut chunk[..want]).map_err(io)? {
                0 => break,
                n => {
                    let capacity = payload.capacity();
                    payload.extend_from_slice(&chunk[..n]);
                    if payload.capacity() != capacity {
                        huge_pages(&mut payload); // the part not written yet
                    }
                }
            }
        }
        let filled = payload.len();
        if filled < payload_len {
            return Err(Error::Truncated {
                what: "compressed archive",
                needed: header.payload_len,
                available: filled as u64,
            });
        }
        if stream.read(&mut [0u8; 1]).map_err(io)? != 0 {
            return Err(Error::corrupt("bytes after the archive in the compressed stream"));
        }
        Self::validated(Storage::Owned(payload), header)
    }

    /// Validates a whole file held in memory (it is copied into aligned memory).
    ///
    /// # Errors
    /// The header and validation errors.
    pub fn from_bytes(bytes: &[u8]) -> Result<Self> {
        let (payload, header) = copied(bytes)?;
        Self::validated(payload, header)
    }

    /// Memory-maps the file and validates it completely.
    ///
    /// # Safety
    /// The map is only sound while no one modifies or truncates the file: a change
    /// under a live map can make the validated data invalid after the fact (or raise
    /// SIGBUS on truncation). Call it on files that are not written while open — a bake
    /// replaces its output by renaming a new file, which never changes an open map.
    /// Use [`SceneFile::read`] for files that may change.
    ///
    /// # Errors
    /// [`Error::Io`] if the file cannot be opened or mapped, or the validation errors.
    pub unsafe fn map(path: impl AsRef<Path>) -> Result<Self> {
        let (map, header) = map_file(path.as_ref())?;
        Self::validated(Storage::Mapped(map), header)
    }

    /// Memory-maps `len` bytes at `offset` (a multiple of the page, checked by the
    /// caller: an instanced file's embedded scene), validated completely or with the
    /// trusted path's checks.
    ///
    /// # Safety
    /// As [`SceneFile::map`].
    pub(crate) unsafe fn map_range(path: &Path, offset: u64, len: u64, validate: bool) -> Result<Self> {
        let (map, header) = map_range_of(path, offset, len)?;
        if validate {
            Self::validated(Storage::Mapped(map), header)
        } else {
            Self::structured(Storage::Mapped(map), header)
        }
    }

    /// Memory-maps the file and checks its header, its section table and the archive's
    /// structure (rkyv's bytecheck: every pointer and length inside the file, a few
    /// microseconds for a 60 MB file), but neither the checksums nor the format's
    /// semantic rules: the trusted fast path, for files baked by octrace or validated
    /// earlier and not changed since.
    ///
    /// What it guarantees for a file that breaks the semantic rules (links to the wrong
    /// leaf, counts and offsets out of range, a depth beyond the format's, non-finite
    /// numbers): tracing it gives wrong answers or misses, never a panic, a hang (every
    /// walk is bounded by `Tracer::max_steps`) or a read out of bounds. Use
    /// [`SceneFile::map`] to have such a file refused instead.
    ///
    /// # Safety
    /// As [`SceneFile::map`]: no one may modify or truncate the file while it is mapped.
    ///
    /// # Errors
    /// [`Error::Io`], the header errors, and [`Error::Corrupt`] for an archive whose
    /// structure is broken.
    pub unsafe fn map_unchecked(path: impl AsRef<Path>) -> Result<Self> {
        let (map, header) = map_file(path.as_ref())?;
        Self::structured(Storage::Mapped(map), header)
    }

    /// [`SceneFile::map_unchecked`]'s checks on a file held in memory (copied into
    /// aligned memory): the header and the archive's structure, not the checksums or
    /// the semantic rules. Safe: the bytes cannot change under it.
    ///
    /// # Errors
    /// The header errors, and [`Error::Corrupt`] for a broken archive structure.
    ///
    /// # Example
    /// ```
    /// let scene = octrace_format::testing::single_leaf_scene();
    /// let file = octrace_format::SceneFile::from_bytes_unchecked(&scene.to_file_bytes(0)?)?;
    /// assert_eq!(file.view().triangle_count(), scene.view().triangle_count());
    /// # Ok::<(), octrace_format::Error>(())
    /// ```
    pub fn from_bytes_unchecked(bytes: &[u8]) -> Result<Self> {
        let (payload, header) = copied(bytes)?;
        Self::structured(payload, header)
    }

    /// Every check: the checksums, the archive's structure, its arrays in their
    /// sections, and the semantic rules.
    fn validated(storage: Storage, header: Header) -> Result<Self> {
        check_sections(&header, payload_of(&storage))?;
        let file = Self::structured(storage, header)?;
        check_arrays_in_sections(&header, file.payload(), file.archived())?;
        file.view().validate()?;
        Ok(file)
    }

    /// The trusted path's checks: the archive's structure (bytecheck), then the
    /// shading data read through it.
    fn structured(storage: Storage, header: Header) -> Result<Self> {
        let archived = rkyv::access::<ArchivedBakedScene, rancor::BoxedError>(payload_of(&storage))
            .map_err(|e| Error::corrupt(format!("archive structure: {e}")))?;
        let shading = deserialize_shading(archived)?;
        Ok(SceneFile { storage, header, shading, decoded: crate::TexelCache::new() })
    }

    /// The scene's materials, lights, cameras and effects.
    pub fn shading(&self) -> &Shading {
        &self.shading
    }

    /// The file's header.
    pub fn header(&self) -> &Header {
        &self.header
    }

    /// The archive's bytes.
    #[inline]
    pub fn payload(&self) -> &[u8] {
        payload_of(&self.storage)
    }

    /// Whether the bytes are a memory map (as opposed to a copy in memory).
    pub fn is_mapped(&self) -> bool {
        matches!(self.storage, Storage::Mapped(_))
    }

    /// The scene's arrays, borrowed.
    #[inline]
    pub fn view(&self) -> SceneView<'_> {
        view_of(self.archived(), &self.shading, &self.decoded)
    }

    /// The archive's root.
    #[inline]
    fn archived(&self) -> &ArchivedBakedScene {
        // SAFETY: every constructor ran `rkyv::access` (bytecheck, in `structured`) on
        // these exact bytes, which do not change (a map's caller promised as much). The
        // payload starts 16-byte aligned: a map starts on a page and the header is 64
        // bytes; owned bytes are an `AlignedVec<16>`.
        unsafe { rkyv::access_unchecked::<ArchivedBakedScene>(self.payload()) }
    }
}

/// Checks every section's checksum; the first that fails is named. Large files hash
/// their sections on two threads.
fn check_sections(header: &Header, payload: &[u8]) -> Result<()> {
    let check = |s: &Section| -> Result<()> {
        let bytes = s.bytes(payload).ok_or_else(|| Error::corrupt(format!("section {} past the archive", s.name)))?;
        let computed = xxhash_rust::xxh3::xxh3_64(bytes);
        if computed != s.xxh3 {
            return Err(Error::Checksum { section: s.name, stored: s.xxh3, computed });
        }
        Ok(())
    };
    const PARALLEL_BYTES: usize = 16 << 20;
    if payload.len() < PARALLEL_BYTES {
        return header.sections.iter().try_for_each(check);
    }
    // Split the sections into two runs of about equal bytes.
    let half = payload.len() as u64 / 2;
    let split = header.sections.iter().position(|s| s.offset + s.len / 2 >= half).unwrap_or(0);
    let (first, second) = header.sections.split_at(split);
    std::thread::scope(|scope| {
        let other = scope.spawn(|| second.iter().try_for_each(check));
        let mine = first.iter().try_for_each(check);
        let theirs = other.join().unwrap_or_else(|p| std::panic::resume_unwind(p));
        mine.and(theirs)
    })
}

/// Checks that each array lies exactly in its own section, so the section table
/// describes the archive it guards.
fn check_arrays_in_sections(header: &Header, payload: &[u8], a: &ArchivedBakedScene) -> Result<()> {
    let base = payload.as_ptr() as usize;
    for (words, s) in view_of(a, &EMPTY_SHADING, &NO_TEXELS).section_words().into_iter().zip(&header.sections) {
        let (at, len) = ((words.as_ptr() as usize).wrapping_sub(base) as u64, words.len());
        if 4 * len as u64 != s.len || (len > 0 && at != s.offset) {
            return Err(Error::corrupt(format!(
                "array {} ({len} words at offset {at}) is not its section ({} bytes at offset {})",
                s.name, s.len, s.offset
            )));
        }
    }
    Ok(())
}

/// The most a compressed scene may expand: its archive's declared length is checked
/// against this many times the compressed file before memory is allocated for it.
pub const MAX_COMPRESSION_RATIO: u64 = 1024;

/// The four bytes every zstd frame starts with.
pub const ZSTD_MAGIC: [u8; 4] = [0x28, 0xB5, 0x2F, 0xFD];

/// Whether the file at `path` is a zstd-compressed scene (starts with a zstd frame).
///
/// # Errors
/// [`Error::Io`] if the file cannot be opened or read.
pub fn is_compressed_file(path: impl AsRef<Path>) -> Result<bool> {
    let path = path.as_ref();
    let mut file = open_regular(path)?;
    is_compressed(&mut file).map_err(|e| Error::io(path, e))
}

/// Opens a scene file for reading ([`crate::open_regular_file`]: a FIFO or a device is
/// refused at once, so `inspect` on one answers instead of blocking).
fn open_regular(path: &Path) -> Result<File> {
    crate::open_regular_file(path).map_err(|e| Error::io(path, e))
}

/// Whether the file starts with a zstd frame (the read position is put back).
fn is_compressed(file: &mut File) -> std::io::Result<bool> {
    use std::io::Seek;
    let mut magic = [0u8; 4];
    let n = file.read(&mut magic)?;
    file.seek(std::io::SeekFrom::Start(0))?;
    Ok(n == 4 && magic == ZSTD_MAGIC)
}

/// Asks Linux to back `buffer`'s allocation with transparent huge pages (2 MiB) where
/// it is written next, when it spans at least two: a walk reads its records, references
/// and triangles at random across the scene, and with 4 KiB pages a scene larger than
/// the TLB's reach (12 MiB here) pays a page walk on most loads. Measured on the dragon
/// (61 MB) read into memory, one thread: incoherent rays one a call 1.17x, in a batch
/// 1.05x (BENCHMARKS.md). Only the 2 MiB-aligned part of the allocation is advised. A
/// kernel built without transparent huge pages refuses the advice (the answer is then
/// `false`); one set to `never` takes it and backs the buffer as before; other systems
/// are not asked. Returns whether the kernel took the advice.
fn huge_pages(buffer: &mut AlignedVec<ARCHIVE_ALIGN>) -> bool {
    #[cfg(target_os = "linux")]
    {
        const HUGE: usize = 2 << 20;
        let start = buffer.as_mut_ptr() as usize;
        let (first, end) = (start.next_multiple_of(HUGE), (start + buffer.capacity()) & !(HUGE - 1));
        if end >= first + 2 * HUGE {
            // SAFETY: the range lies inside the buffer's own allocation (rounded inwards
            // to whole huge pages); MADV_HUGEPAGE changes how pages are backed, never
            // their contents.
            let done = unsafe { libc::madvise(first as *mut libc::c_void, end - first, libc::MADV_HUGEPAGE) };
            return done == 0;
        }
    }
    #[cfg(not(target_os = "linux"))]
    let _ = buffer;
    false
}

fn map_file(path: &Path) -> Result<(memmap2::Mmap, Header)> {
    let mut file = open_regular(path)?;
    if is_compressed(&mut file).map_err(|e| Error::io(path, e))? {
        return Err(Error::Compressed { path: path.into() });
    }
    // SAFETY: the callers are `unsafe fn`s whose contract forbids changing the file
    // while it is mapped; the map is read-only.
    let map = unsafe { memmap2::Mmap::map(&file) }.map_err(|e| Error::io(path, e))?;
    let header = Header::decode(&map[..map.len().min(HEADER_LEN)], map.len() as u64)?;
    Ok((map, header))
}

/// Maps `len` bytes of the file at `offset` (a multiple of the page: an embedded
/// scene of an instanced file) and decodes its header.
fn map_range_of(path: &Path, offset: u64, len: u64) -> Result<(memmap2::Mmap, Header)> {
    let file = open_regular(path)?;
    let len = usize::try_from(len).map_err(|_| Error::corrupt("scene larger than this machine's address space"))?;
    // SAFETY: as `map_file`'s: the callers' contract forbids changing the file.
    let map =
        unsafe { memmap2::MmapOptions::new().offset(offset).len(len).map(&file) }.map_err(|e| Error::io(path, e))?;
    let header = Header::decode(&map[..map.len().min(HEADER_LEN)], map.len() as u64)?;
    Ok((map, header))
}

/// Builds a view with native-typed slices over an archive (inlined: a view is a few
/// hundred bytes, and a call per ray returning it by value was mostly `memmove`).
#[inline]
pub(crate) fn view_of<'a>(
    a: &'a ArchivedBakedScene,
    shading: &'a Shading,
    decoded: &'a crate::TexelCache,
) -> SceneView<'a> {
    let v3 = |x: &[rkyv::rend::f32_le; 3]| [x[0].to_native(), x[1].to_native(), x[2].to_native()];
    SceneView {
        params: BakeParams {
            max_depth: a.params.max_depth.to_native(),
            leaf_size: a.params.leaf_size.to_native(),
            margin: a.params.margin.to_native(),
            cube_level: a.params.cube_level.to_native(),
        },
        bounds: Bounds {
            mesh_lo: v3(&a.bounds.mesh_lo),
            mesh_hi: v3(&a.bounds.mesh_hi),
            root_lo: v3(&a.bounds.root_lo),
            root_size: a.bounds.root_size.to_native(),
        },
        stats: BakeStats {
            input_triangles: a.stats.input_triangles.to_native(),
            degenerate_triangles: a.stats.degenerate_triangles.to_native(),
            leaves_before_balance: a.stats.leaves_before_balance.to_native(),
            edges: {
                let e = &a.stats.edges;
                crate::topology::EdgeCensus {
                    edges: e.edges.to_native(),
                    boundary: e.boundary.to_native(),
                    non_manifold: e.non_manifold.to_native(),
                    flipped: e.flipped.to_native(),
                    degenerate: e.degenerate.to_native(),
                }
            },
        },
        // The archive is little-endian and so is the target (checked at compile time),
        // so rend's little-endian wrappers are the native values: a plain cast.
        octree: bytemuck::cast_slice(a.octree.as_slice()),
        tri_refs: bytemuck::cast_slice(a.tri_refs.as_slice()),
        triangles: bytemuck::cast_slice(a.triangles.as_slice()),
        triangle_ids: bytemuck::cast_slice(a.triangle_ids.as_slice()),
        boxes: bytemuck::cast_slice(a.boxes.as_slice()),
        cube_map: bytemuck::cast_slice(a.cube_map.as_slice()),
        nodes: bytemuck::cast_slice(a.nodes.as_slice()),
        material_ids: bytemuck::cast_slice(a.material_ids.as_slice()),
        normals: bytemuck::cast_slice(a.normals.as_slice()),
        uvs: bytemuck::cast_slice(a.uvs.as_slice()),
        colors: bytemuck::cast_slice(a.colors.as_slice()),
        tangents: bytemuck::cast_slice(a.tangents.as_slice()),
        texels: crate::Texels::new(
            bytemuck::cast_slice(a.texels.as_slice()),
            bytemuck::cast_slice(a.images.as_slice()),
            &shading.textures,
            decoded,
        ),
        distance: bytemuck::cast_slice(a.distance.as_slice()),
        root: a.root.to_native(),
        shading,
    }
}

/// No materials, lights, cameras or effects: for views that only need the arrays.
pub(crate) static EMPTY_SHADING: Shading = Shading {
    materials: Vec::new(),
    lights: Vec::new(),
    cameras: Vec::new(),
    textures: Vec::new(),
    parts: Vec::new(),
    effects: Vec::new(),
};

/// The cache of views with no textures.
pub(crate) static NO_TEXELS: crate::TexelCache = crate::TexelCache::new();

/// The archive's shading data as native values.
fn deserialize_shading(a: &ArchivedBakedScene) -> Result<Shading> {
    rkyv::deserialize::<Shading, rancor::BoxedError>(&a.shading)
        .map_err(|e| Error::corrupt(format!("shading data: {e}")))
}

/// The archive's bytes: past the header of a map, or the copy in memory.
#[inline]
fn payload_of(storage: &Storage) -> &[u8] {
    match storage {
        Storage::Mapped(map) => &map[HEADER_LEN..],
        Storage::Owned(bytes) => bytes,
    }
}

/// A file held in memory, its header decoded and its archive copied into aligned
/// memory.
fn copied(bytes: &[u8]) -> Result<(Storage, Header)> {
    let header = Header::decode(bytes, bytes.len() as u64)?;
    let mut payload = AlignedVec::<ARCHIVE_ALIGN>::with_capacity(bytes.len() - HEADER_LEN);
    huge_pages(&mut payload);
    payload.extend_from_slice(&bytes[HEADER_LEN..]);
    Ok((Storage::Owned(payload), header))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A buffer of at least two huge pages is advised (on a Linux kernel with
    /// transparent huge pages), one smaller is not, and the advice leaves what is
    /// written there as written.
    #[test]
    fn large_buffers_are_advised_to_use_huge_pages() {
        let mut small = AlignedVec::<ARCHIVE_ALIGN>::with_capacity(1 << 20);
        assert!(!huge_pages(&mut small));
        let mut large = AlignedVec::<ARCHIVE_ALIGN>::with_capacity(16 << 20);
        let advised = huge_pages(&mut large);
        let has_thp = std::path::Path::new("/sys/kernel/mm/transparent_hugepage").exists();
        assert_eq!(advised, cfg!(target_os = "linux") && has_thp);
        let bytes: Vec<u8> = (0..16u32 << 20).map(|i| (i.wrapping_mul(2_654_435_761) >> 24) as u8).collect();
        large.extend_from_slice(&bytes);
        assert!(large[..] == bytes[..]);
    }
}
