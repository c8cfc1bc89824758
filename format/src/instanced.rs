//! Instanced files: baked scenes stored once and placed many times. A glTF whose
//! nodes share a mesh (or that places one by `EXT_mesh_gpu_instancing`) bakes each
//! distinct geometry once, as an ordinary baked scene embedded whole in the file,
//! and its placements as an instance table: the embedded scene, a transform (3 rows
//! of 4, local to world, `f64`), and the material map it draws with (which of that
//! scene's materials it draws in place of each), maps shared by the instances that
//! draw alike.
//!
//! The layout (little-endian; `format/FORMAT.md`, "Instanced files"):
//!
//! | bytes | what |
//! |---|---|
//! | 0..8 | [`INSTANCED_MAGIC`] |
//! | 8..12 | [`INSTANCED_VERSION`] |
//! | 12..16, 16..20, 20..24, 24..28 | scenes, instances, material maps, their words |
//! | 28..32 | zero |
//! | 32..40, 40..48 | the table's length and its xxh3-64 |
//! | 48..56 | the file's length |
//! | 56..64 | zero |
//! | 64.. | the table: each scene's `(offset, length)` (`u64` each); each map's length (`u32`), then the maps' words (`u32`); each instance's scene and map (`u32` each, the map `u32::MAX` for none) and 12 `f64` rows |
//! | then | each scene, a whole `.oct` file at a multiple of [`SCENE_ALIGN`] (so each maps on its own, zero-copy, and validates as a file) |
//!
//! Opening one as a scene ([`crate::SceneFile`]) fails with [`Error::Instanced`];
//! the runtime's `World::open` opens it as a world of instances.
//!
//! # Example
//! ```
//! use octrace_format::instanced::{InstanceRecord, InstancedFile};
//! # let scene = octrace_format::testing::single_leaf_scene();
//! let dir = tempfile::tempdir().unwrap();
//! let path = dir.path().join("two.oct");
//! let shift = |x: f64| [[1.0, 0.0, 0.0, x], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]];
//! let instances = vec![InstanceRecord { scene: 0, rows: shift(0.0), map: None },
//!                      InstanceRecord { scene: 0, rows: shift(2.0), map: None }];
//! let table = InstancedFile { scenes: vec![], maps: vec![], instances };
//! table.write(&path, &[scene.to_file_bytes(0)?])?;
//! let table = InstancedFile::read(&path)?;
//! assert_eq!((table.scenes.len(), table.instances.len()), (1, 2));
//! let first = table.read_scene(&path, 0)?; // validated, as SceneFile::read
//! assert_eq!(first.view().triangle_count(), 1);
//! # Ok::<(), octrace_format::Error>(())
//! ```

use std::io::{Read, Seek, SeekFrom};
use std::path::Path;

use crate::error::{Error, Result};
use crate::file::SceneFile;

/// The eight bytes every instanced file starts with.
pub const INSTANCED_MAGIC: [u8; 8] = *b"OCTINST\0";
/// The instanced-file version this build writes and reads.
pub const INSTANCED_VERSION: u32 = 1;
/// Where each embedded scene starts: a multiple of this (a page).
pub const SCENE_ALIGN: u64 = 4096;
/// Length of the fixed header.
const HEAD_LEN: usize = 64;
/// Bytes of an instance's record in the table.
const INSTANCE_LEN: usize = 8 + 12 * 8;
/// No material map: an instance's map field.
const NO_MAP: u32 = u32::MAX;
/// The most embedded scenes a file may hold.
pub const MAX_SCENES: u32 = 1 << 16;
/// The most instances a file may place (a world takes some 300 bytes an instance).
pub const MAX_INSTANCES: u32 = 1 << 22;
/// The most material maps a file may hold, and words in them all (16 MiB).
pub const MAX_MAP_WORDS: u32 = 1 << 22;

/// One placement of an embedded scene.
#[derive(Clone, Debug, PartialEq)]
pub struct InstanceRecord {
    /// The embedded scene placed (its index in [`InstancedFile::scenes`]).
    pub scene: u32,
    /// Local to world: 3 rows of 4 (the last row of the matrix is `0 0 0 1`).
    pub rows: [[f64; 4]; 3],
    /// The material map it draws with (its index in [`InstancedFile::maps`]), if any.
    pub map: Option<u32>,
}

/// An instanced file's table: where its scenes lie, its material maps and its
/// instances.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct InstancedFile {
    /// Each embedded scene's `(offset, length)` in the file (set by
    /// [`InstancedFile::write`]).
    pub scenes: Vec<(u64, u64)>,
    /// The material maps: entry `k` of a map replaces material `k` of the scene an
    /// instance drawing with it places (an index into that scene's own materials); a
    /// material past the map's end is drawn as it is.
    pub maps: Vec<Vec<u32>>,
    /// The instances, in order.
    pub instances: Vec<InstanceRecord>,
}

/// The material drawn in place of material `material` through material map `map`:
/// entry `material` where the map has one, else `material` itself.
///
/// ```
/// use octrace_format::instanced::drawn;
/// assert_eq!((drawn(&[2, 0], 0), drawn(&[2, 0], 1), drawn(&[2, 0], 5), drawn(&[], 3)), (2, 0, 5, 3));
/// ```
#[inline]
pub fn drawn(map: &[u32], material: u32) -> u32 {
    map.get(material as usize).copied().unwrap_or(material)
}

/// Whether `bytes` (a file's first bytes) start an instanced file.
pub fn is_instanced(bytes: &[u8]) -> bool {
    bytes.starts_with(&INSTANCED_MAGIC)
}

/// Whether the file at `path` is an instanced file (its first eight bytes).
///
/// # Errors
/// [`Error::Io`] where it cannot be opened or read.
pub fn is_instanced_file(path: impl AsRef<Path>) -> Result<bool> {
    let path = path.as_ref();
    let mut file = crate::open_regular_file(path).map_err(|e| Error::io(path, e))?;
    let mut magic = [0u8; 8];
    let mut n = 0;
    while n < 8 {
        match file.read(&mut magic[n..]).map_err(|e| Error::io(path, e))? {
            0 => break,
            k => n += k,
        }
    }
    Ok(is_instanced(&magic[..n]))
}

fn corrupt(what: impl std::fmt::Display) -> Error {
    Error::corrupt(format!("instanced file: {what}"))
}

impl InstancedFile {
    /// Writes the instances and maps with `scenes` as an instanced file, atomically
    /// (as [`crate::write_atomically`]): the scenes are whole `.oct` files
    /// ([`crate::BakedScene::to_file_bytes`]); `self.scenes` is not read.
    ///
    /// # Errors
    /// [`Error::Corrupt`] for an instance naming no scene or map, a transform not
    /// finite, or counts past [`MAX_SCENES`], [`MAX_INSTANCES`] or [`MAX_MAP_WORDS`];
    /// [`Error::Write`] naming `path`.
    pub fn write(&self, path: impl AsRef<Path>, scenes: &[Vec<u8>]) -> Result<()> {
        let path = path.as_ref();
        let (maps, instances) = (&self.maps, &self.instances);
        let map_words: usize = maps.iter().map(Vec::len).sum();
        if scenes.is_empty()
            || scenes.len() > MAX_SCENES as usize
            || instances.len() > MAX_INSTANCES as usize
            || maps.len() + map_words > MAX_MAP_WORDS as usize
        {
            return Err(corrupt(format!(
                "{} scenes, {} instances, {} maps of {map_words} words (1 to {MAX_SCENES} scenes, at most \
                 {MAX_INSTANCES} instances and {MAX_MAP_WORDS} maps and words)",
                scenes.len(),
                instances.len(),
                maps.len()
            )));
        }
        for (i, instance) in instances.iter().enumerate() {
            let finite = instance.rows.iter().flatten().all(|x| x.is_finite());
            if instance.scene as usize >= scenes.len()
                || instance.map.is_some_and(|m| m as usize >= maps.len())
                || !finite
            {
                return Err(corrupt(format!("instance {i} names no scene or map, or its transform is not finite")));
            }
        }
        let table_len = 16 * scenes.len() + 4 * maps.len() + 4 * map_words + INSTANCE_LEN * instances.len();
        let align = |x: u64| x.div_ceil(SCENE_ALIGN) * SCENE_ALIGN;
        let mut offsets = Vec::with_capacity(scenes.len());
        let mut at = align((HEAD_LEN + table_len) as u64);
        for s in scenes {
            offsets.push((at, s.len() as u64));
            at = align(at + s.len() as u64);
        }
        let file_len = offsets.last().map_or(at, |&(o, l)| o + l);
        let mut table = Vec::with_capacity(table_len);
        for &(o, l) in &offsets {
            table.extend_from_slice(&o.to_le_bytes());
            table.extend_from_slice(&l.to_le_bytes());
        }
        for m in maps {
            table.extend_from_slice(&(m.len() as u32).to_le_bytes());
        }
        for w in maps.iter().flatten() {
            table.extend_from_slice(&w.to_le_bytes());
        }
        for i in instances {
            table.extend_from_slice(&i.scene.to_le_bytes());
            table.extend_from_slice(&i.map.unwrap_or(NO_MAP).to_le_bytes());
            for x in i.rows.iter().flatten() {
                table.extend_from_slice(&x.to_le_bytes());
            }
        }
        let mut head = Vec::with_capacity(HEAD_LEN);
        head.extend_from_slice(&INSTANCED_MAGIC);
        let counts = [INSTANCED_VERSION, scenes.len() as u32, instances.len() as u32, maps.len() as u32];
        for n in counts.into_iter().chain([map_words as u32, 0]) {
            head.extend_from_slice(&n.to_le_bytes());
        }
        for n in [table_len as u64, xxhash_rust::xxh3::xxh3_64(&table), file_len] {
            head.extend_from_slice(&n.to_le_bytes());
        }
        head.resize(HEAD_LEN, 0);
        let mut parts: Vec<&[u8]> = vec![&head, &table];
        let zeros = vec![0u8; SCENE_ALIGN as usize];
        let mut written = (HEAD_LEN + table_len) as u64;
        for (s, &(o, _)) in scenes.iter().zip(&offsets) {
            parts.push(&zeros[..(o - written) as usize]);
            parts.push(s);
            written = o + s.len() as u64;
        }
        crate::write_atomically(path, &parts)
    }

    /// Reads and checks an instanced file's table: magic, version, lengths, the
    /// table's checksum, every scene inside the file, aligned and apart, every
    /// instance naming a scene with a finite transform. Reads only the table (its
    /// length checked against the file's first).
    ///
    /// # Errors
    /// [`Error::Io`]; [`Error::NotInstanced`] for one baked scene, [`Error::BadMagic`] for
    /// another kind of file;
    /// [`Error::UnsupportedVersion`]; [`Error::Truncated`] and [`Error::Checksum`];
    /// [`Error::Corrupt`] naming what is wrong.
    pub fn read(path: impl AsRef<Path>) -> Result<InstancedFile> {
        let path = path.as_ref();
        let io = |e| Error::io(path, e);
        let mut file = crate::open_regular_file(path).map_err(io)?;
        let len = file.metadata().map_err(io)?.len();
        let mut head = Vec::with_capacity(HEAD_LEN);
        (&mut file).take(HEAD_LEN as u64).read_to_end(&mut head).map_err(io)?;
        let (counts, table_len, sum, file_len) = decode_head(&head, len)?;
        let mut table = vec![0u8; table_len];
        file.seek(SeekFrom::Start(HEAD_LEN as u64)).map_err(io)?;
        file.read_exact(&mut table).map_err(io)?;
        decode_table(&table, counts, sum, file_len)
    }

    /// Embedded scene `index`, read into memory and validated completely (as
    /// [`SceneFile::read`]).
    ///
    /// # Errors
    /// [`Error::Corrupt`] for an index past the scenes; [`Error::Io`]; the scene's own
    /// header and validation errors.
    pub fn read_scene(&self, path: impl AsRef<Path>, index: usize) -> Result<SceneFile> {
        let path = path.as_ref();
        let &(offset, len) = self.scenes.get(index).ok_or_else(|| corrupt(format!("no scene {index}")))?;
        let io = |e| Error::io(path, e);
        let mut file = crate::open_regular_file(path).map_err(io)?;
        file.seek(SeekFrom::Start(offset)).map_err(io)?;
        // The length was checked against the file's when the table was read.
        let mut bytes = vec![0u8; len as usize];
        file.read_exact(&mut bytes).map_err(io)?;
        SceneFile::from_bytes(&bytes).map_err(|e| in_scene(index, e))
    }

    /// Embedded scene `index`, memory-mapped and validated completely (as
    /// [`SceneFile::map`]).
    ///
    /// # Safety
    /// As [`SceneFile::map`]: no one may modify or truncate the file while it is mapped.
    ///
    /// # Errors
    /// As [`InstancedFile::read_scene`].
    pub unsafe fn map_scene(&self, path: impl AsRef<Path>, index: usize) -> Result<SceneFile> {
        let &(offset, len) = self.scenes.get(index).ok_or_else(|| corrupt(format!("no scene {index}")))?;
        // SAFETY: the caller's promise, as for `SceneFile::map`.
        unsafe { SceneFile::map_range(path.as_ref(), offset, len, true) }.map_err(|e| in_scene(index, e))
    }

    /// Embedded scene `index`, memory-mapped with [`SceneFile::map_unchecked`]'s
    /// checks alone (the trusted path).
    ///
    /// # Safety
    /// As [`SceneFile::map_unchecked`].
    ///
    /// # Errors
    /// As [`InstancedFile::read_scene`], less the semantic and checksum checks.
    pub unsafe fn map_scene_unchecked(&self, path: impl AsRef<Path>, index: usize) -> Result<SceneFile> {
        let &(offset, len) = self.scenes.get(index).ok_or_else(|| corrupt(format!("no scene {index}")))?;
        // SAFETY: the caller's promise, as for `SceneFile::map_unchecked`.
        unsafe { SceneFile::map_range(path.as_ref(), offset, len, false) }.map_err(|e| in_scene(index, e))
    }
}

/// An embedded scene's error, saying which scene.
fn in_scene(index: usize, e: Error) -> Error {
    match e {
        Error::Corrupt(what) => Error::Corrupt(format!("instanced file, scene {index}: {what}")),
        e => e,
    }
}

/// The head's counts (scenes, instances, maps, map words), the table's length and
/// checksum, and the file's length, checked against the file's real length `len`.
fn decode_head(head: &[u8], len: u64) -> Result<([u32; 4], usize, u64, u64)> {
    if head.starts_with(&crate::MAGIC) {
        return Err(Error::NotInstanced);
    }
    if !is_instanced(head) {
        let mut found = [0u8; 8];
        let n = head.len().min(8);
        found[..n].copy_from_slice(&head[..n]);
        return Err(Error::BadMagic { found });
    }
    if head.len() < HEAD_LEN {
        return Err(Error::Truncated { what: "instanced file's header", needed: HEAD_LEN as u64, available: len });
    }
    let word = |at: usize| u32::from_le_bytes(head[at..at + 4].try_into().expect("four bytes"));
    let long = |at: usize| u64::from_le_bytes(head[at..at + 8].try_into().expect("eight bytes"));
    let version = word(8);
    if version != INSTANCED_VERSION {
        let v = |n: u32| crate::Version { major: n.min(u32::from(u16::MAX)) as u16, minor: 0 };
        return Err(Error::UnsupportedVersion { found: v(version), supported: v(INSTANCED_VERSION) });
    }
    let counts = [word(12), word(16), word(20), word(24)];
    let (table_len, sum, file_len) = (long(32), long(40), long(48));
    if word(28) != 0 || head[56..HEAD_LEN].iter().any(|&b| b != 0) {
        return Err(corrupt("reserved header bytes are not zero"));
    }
    let [scenes, instances, maps, words] = counts.map(u64::from);
    if scenes == 0
        || scenes > u64::from(MAX_SCENES)
        || instances > u64::from(MAX_INSTANCES)
        || maps + words > u64::from(MAX_MAP_WORDS)
    {
        return Err(corrupt(format!(
            "{scenes} scenes, {instances} instances, {maps} maps of {words} words (1 to {MAX_SCENES} scenes, at \
             most {MAX_INSTANCES} instances and {MAX_MAP_WORDS} maps and words)"
        )));
    }
    let expected = 16 * scenes + 4 * maps + 4 * words + INSTANCE_LEN as u64 * instances;
    if table_len != expected {
        return Err(corrupt(format!("a table of {table_len} bytes, where its counts make {expected}")));
    }
    if file_len != len {
        let what = "instanced file";
        return Err(if len < file_len {
            Error::Truncated { what, needed: file_len, available: len }
        } else {
            corrupt(format!("{len} bytes, where its header says {file_len}"))
        });
    }
    if HEAD_LEN as u64 + table_len > len {
        return Err(Error::Truncated {
            what: "instanced file's table",
            needed: HEAD_LEN as u64 + table_len,
            available: len,
        });
    }
    Ok((counts, table_len as usize, sum, file_len))
}

fn decode_table(
    table: &[u8],
    [scenes, instances, maps, words]: [u32; 4],
    sum: u64,
    file_len: u64,
) -> Result<InstancedFile> {
    let computed = xxhash_rust::xxh3::xxh3_64(table);
    if computed != sum {
        return Err(Error::Checksum { section: "instance table", stored: sum, computed });
    }
    let mut at = 0usize;
    let mut take = |n: usize| {
        let bytes = &table[at..at + n];
        at += n;
        bytes
    };
    let u32_of = |b: &[u8]| u32::from_le_bytes(b.try_into().expect("four bytes"));
    let u64_of = |b: &[u8]| u64::from_le_bytes(b.try_into().expect("eight bytes"));
    let mut ranges: Vec<(u64, u64)> = Vec::with_capacity(scenes as usize);
    let table_end = HEAD_LEN as u64 + table.len() as u64;
    for s in 0..scenes {
        let (offset, len) = (u64_of(take(8)), u64_of(take(8)));
        let after = ranges.last().map_or(table_end, |&(o, l)| o + l);
        if !offset.is_multiple_of(SCENE_ALIGN) || offset < after || len > file_len || offset > file_len - len {
            return Err(corrupt(format!(
                "scene {s} at {offset}, {len} bytes: not on a {SCENE_ALIGN}-byte boundary after the one before, or \
                 past the file's {file_len} bytes"
            )));
        }
        ranges.push((offset, len));
    }
    let lens: Vec<u64> = (0..maps).map(|_| u64::from(u32_of(take(4)))).collect();
    if lens.iter().sum::<u64>() != u64::from(words) {
        return Err(corrupt(format!("the material maps' lengths do not add up to the {words} words stored")));
    }
    let maps_read: Vec<Vec<u32>> =
        lens.iter().map(|&n| take(4 * n as usize).chunks_exact(4).map(u32_of).collect()).collect();
    let mut records = Vec::with_capacity(instances as usize);
    for i in 0..instances {
        let (scene, map) = (u32_of(take(4)), u32_of(take(4)));
        let mut rows = [[0.0f64; 4]; 3];
        for x in rows.iter_mut().flatten() {
            *x = f64::from_le_bytes(take(8).try_into().expect("eight bytes"));
        }
        let map = (map != NO_MAP).then_some(map);
        if scene >= scenes || map.is_some_and(|m| m >= maps) || !rows.iter().flatten().all(|x| x.is_finite()) {
            return Err(corrupt(format!(
                "instance {i} names scene {scene} of {scenes} or map {map:?} of {maps}, or its transform is not \
                 finite"
            )));
        }
        records.push(InstanceRecord { scene, rows, map });
    }
    Ok(InstancedFile { scenes: ranges, maps: maps_read, instances: records })
}
