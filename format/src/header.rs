//! The fixed header and its section table, readable without rkyv.

use crate::error::{Error, Result, Version};

/// The eight bytes every baked scene starts with.
pub const MAGIC: [u8; 8] = *b"OCTRACE\0";
/// The format version this build writes, and the newest it reads.
pub const VERSION: Version = Version { major: 10, minor: 0 };
/// Length of the fixed part of the header.
pub const FIXED_HEADER_LEN: usize = 64;
/// Length of one section-table entry: a 16-byte name, the length, the xxh3-64.
pub const SECTION_ENTRY_LEN: usize = 32;
/// The archive's sections, in file order. The arrays are those of [`crate::BakedScene`],
/// each exactly its bytes (an absent shading array is an empty section); `root` is what
/// follows the last array: the shading data (materials, lights, cameras, effects),
/// alignment padding, and the archive's root object (parameters, bounds, statistics).
pub const SECTION_NAMES: [&str; SECTION_COUNT] = [
    "octree",
    "tri_refs",
    "triangles",
    "triangle_ids",
    "boxes",
    "cube_map",
    "nodes",
    "material_ids",
    "normals",
    "uvs",
    "colors",
    "tangents",
    "texels",
    "images",
    "distance",
    "root",
];
/// Number of sections in a version 10.0 file (15 in 8.0 and 9.0).
pub const SECTION_COUNT: usize = 16;
/// Header length in bytes, section table included; the archive starts right after it.
pub const HEADER_LEN: usize = FIXED_HEADER_LEN + SECTION_COUNT * SECTION_ENTRY_LEN;
/// Alignment of the archive within the file and in memory.
pub const ARCHIVE_ALIGN: usize = 16;

const _: () = assert!(HEADER_LEN.is_multiple_of(ARCHIVE_ALIGN));

/// What a truncation inside each section is called in [`Error::Truncated`].
const SECTION_LABELS: [&str; SECTION_COUNT] = [
    "section octree",
    "section tri_refs",
    "section triangles",
    "section triangle_ids",
    "section boxes",
    "section cube_map",
    "section nodes",
    "section material_ids",
    "section normals",
    "section uvs",
    "section colors",
    "section tangents",
    "section texels",
    "section images",
    "section distance",
    "section root",
];

/// The rkyv settings the archive was written with, one byte each:
/// endianness (1 = little), alignment (1 = aligned primitives), pointer width in bits,
/// and the archive's alignment in bytes. A reader refuses other settings.
pub const RKYV_SETTINGS: [u8; 4] = [1, 1, 64, ARCHIVE_ALIGN as u8];

/// The flags this build understands (none yet: every bit is reserved).
pub const KNOWN_FLAGS: u32 = 0;

/// One section of the archive: a byte range with its own checksum, so a damaged file
/// names the part that is damaged.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Section {
    /// The section's name, one of [`SECTION_NAMES`].
    pub name: &'static str,
    /// Offset from the start of the archive (the sum of the lengths before it).
    pub offset: u64,
    /// Length in bytes.
    pub len: u64,
    /// xxh3-64 of the section's bytes.
    pub xxh3: u64,
}

impl Section {
    /// The section's bytes within `payload` (the archive), if it lies within it.
    pub fn bytes<'a>(&self, payload: &'a [u8]) -> Option<&'a [u8]> {
        let start = usize::try_from(self.offset).ok()?;
        let end = start.checked_add(usize::try_from(self.len).ok()?)?;
        payload.get(start..end)
    }
}

/// The decoded header of a baked scene.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Header {
    /// Format version of the file.
    pub version: Version,
    /// Flag bits.
    pub flags: u32,
    /// The rkyv settings, see [`RKYV_SETTINGS`].
    pub rkyv_settings: [u8; 4],
    /// Length of the archive that follows the header.
    pub payload_len: u64,
    /// The archive's sections, in order; they tile the archive exactly.
    pub sections: [Section; SECTION_COUNT],
    /// Wall time of the bake in microseconds; 0 when not recorded (reproducible bakes).
    /// It lies outside the archive and its checksums, so the archive is identical
    /// whatever the timing.
    pub bake_time_us: u64,
}

impl Header {
    /// A header for an archive whose sections have the given lengths and checksums
    /// (in [`SECTION_NAMES`] order).
    pub fn new(sums: [(u64, u64); SECTION_COUNT], bake_time_us: u64) -> Self {
        let mut offset = 0u64;
        let sections = std::array::from_fn(|i| {
            let (len, xxh3) = sums[i];
            let s = Section { name: SECTION_NAMES[i], offset, len, xxh3 };
            offset = offset.wrapping_add(len);
            s
        });
        Header { version: VERSION, flags: 0, rkyv_settings: RKYV_SETTINGS, payload_len: offset, sections, bake_time_us }
    }

    /// Encodes the header: the fixed part, its own checksum in bytes 56..64, then the
    /// section table (whose checksum is in bytes 40..48).
    pub fn encode(&self) -> [u8; HEADER_LEN] {
        let mut b = [0u8; HEADER_LEN];
        for (i, s) in self.sections.iter().enumerate() {
            let e = &mut b[FIXED_HEADER_LEN + i * SECTION_ENTRY_LEN..][..SECTION_ENTRY_LEN];
            e[..s.name.len()].copy_from_slice(s.name.as_bytes());
            e[16..24].copy_from_slice(&s.len.to_le_bytes());
            e[24..32].copy_from_slice(&s.xxh3.to_le_bytes());
        }
        let table_sum = xxhash_rust::xxh3::xxh3_64(&b[FIXED_HEADER_LEN..]);
        b[0..8].copy_from_slice(&MAGIC);
        b[8..10].copy_from_slice(&self.version.major.to_le_bytes());
        b[10..12].copy_from_slice(&self.version.minor.to_le_bytes());
        b[12..16].copy_from_slice(&self.flags.to_le_bytes());
        b[16..20].copy_from_slice(&self.rkyv_settings);
        b[20..24].copy_from_slice(&(SECTION_COUNT as u32).to_le_bytes());
        b[24..32].copy_from_slice(&(HEADER_LEN as u64).to_le_bytes());
        b[32..40].copy_from_slice(&self.payload_len.to_le_bytes());
        b[40..48].copy_from_slice(&table_sum.to_le_bytes());
        b[48..56].copy_from_slice(&self.bake_time_us.to_le_bytes());
        let sum = xxhash_rust::xxh3::xxh3_64(&b[..56]);
        b[56..64].copy_from_slice(&sum.to_le_bytes());
        b
    }

    /// Decodes and checks a header: magic first, then version, then the fixed part's
    /// checksum and fields, then the section table's checksum and entries, then the
    /// file's length. `bytes` starts at the file's start and holds at least the header
    /// when the file does; `file_len` is the length of the whole file. A file that ends
    /// early is reported as truncated in the section where it ends.
    ///
    /// # Errors
    /// [`Error::Truncated`], [`Error::BadMagic`], [`Error::UnsupportedVersion`],
    /// [`Error::Checksum`] or [`Error::Corrupt`], in that order of checking.
    pub fn decode(bytes: &[u8], file_len: u64) -> Result<Self> {
        Self::decode_with(bytes, Some(file_len))
    }

    /// Decodes a header whose file length is not known yet (the start of a
    /// decompressed stream): every check of [`Header::decode`] but the length ones.
    ///
    /// # Errors
    /// As [`Header::decode`], without [`Error::Truncated`] for the archive.
    pub fn decode_stream(bytes: &[u8]) -> Result<Self> {
        Self::decode_with(bytes, None)
    }

    /// The index (in `sections`) of the section in which a file of `file_len` bytes
    /// ends, when it ends inside the archive (the last section when it ends at or past
    /// the archive's end).
    pub fn section_at(&self, file_len: u64) -> Option<usize> {
        let at = file_len.checked_sub(HEADER_LEN as u64)?;
        Some(self.sections.iter().position(|s| at < s.offset + s.len).unwrap_or(SECTION_COUNT - 1))
    }

    fn decode_with(bytes: &[u8], file_len: Option<u64>) -> Result<Self> {
        if crate::instanced::is_instanced(bytes) {
            return Err(Error::Instanced);
        }
        if bytes.len() < 8 || bytes[..8] != MAGIC {
            let mut found = [0u8; 8];
            let n = bytes.len().min(8);
            found[..n].copy_from_slice(&bytes[..n]);
            if n < 8 && MAGIC.starts_with(&bytes[..n]) {
                return Err(truncated("header", FIXED_HEADER_LEN, bytes.len()));
            }
            return Err(Error::BadMagic { found });
        }
        if bytes.len() < 12 {
            return Err(truncated("header", FIXED_HEADER_LEN, bytes.len()));
        }
        let version = Version { major: u16_at(bytes, 8), minor: u16_at(bytes, 10) };
        if version.major != VERSION.major || version.minor > VERSION.minor {
            return Err(Error::UnsupportedVersion { found: version, supported: VERSION });
        }
        if bytes.len() < FIXED_HEADER_LEN {
            return Err(truncated("header", FIXED_HEADER_LEN, bytes.len()));
        }
        let stored = u64_at(bytes, 56);
        let computed = xxhash_rust::xxh3::xxh3_64(&bytes[..56]);
        if stored != computed {
            return Err(Error::Checksum { section: "header", stored, computed });
        }
        check_fixed_fields(bytes)?;
        if bytes.len() < HEADER_LEN {
            return Err(truncated("section table", HEADER_LEN, bytes.len()));
        }
        let stored = u64_at(bytes, 40);
        let computed = xxhash_rust::xxh3::xxh3_64(&bytes[FIXED_HEADER_LEN..HEADER_LEN]);
        if stored != computed {
            return Err(Error::Checksum { section: "section table", stored, computed });
        }
        let header = Header {
            version,
            flags: u32_at(bytes, 12),
            rkyv_settings: [bytes[16], bytes[17], bytes[18], bytes[19]],
            payload_len: u64_at(bytes, 32),
            sections: decode_sections(&bytes[FIXED_HEADER_LEN..HEADER_LEN])?,
            bake_time_us: u64_at(bytes, 48),
        };
        let tiled = header.sections.last().map_or(0, |s| s.offset + s.len);
        if tiled != header.payload_len {
            return Err(Error::corrupt(format!(
                "the sections cover {tiled} bytes, the archive is {} bytes",
                header.payload_len
            )));
        }
        let Some(file_len) = file_len else { return Ok(header) };
        let needed = (HEADER_LEN as u64).saturating_add(header.payload_len);
        if needed > file_len {
            let (what, needed) = match header.section_at(file_len) {
                Some(i) => {
                    let s = &header.sections[i];
                    (SECTION_LABELS[i], HEADER_LEN as u64 + s.offset + s.len)
                }
                None => ("archive", needed),
            };
            return Err(Error::Truncated { what, needed, available: file_len });
        }
        if needed < file_len {
            return Err(Error::corrupt(format!("{} bytes after the archive", file_len - needed)));
        }
        Ok(header)
    }
}

/// The fixed part's fields other than the version and lengths that need the table.
fn check_fixed_fields(bytes: &[u8]) -> Result<()> {
    let flags = u32_at(bytes, 12);
    if flags & !KNOWN_FLAGS != 0 {
        return Err(Error::corrupt(format!("unknown header flags {flags:#x}")));
    }
    let settings = [bytes[16], bytes[17], bytes[18], bytes[19]];
    if settings != RKYV_SETTINGS {
        return Err(Error::corrupt(format!(
            "archive written with rkyv settings {settings:?}, this build reads {RKYV_SETTINGS:?}"
        )));
    }
    if u32_at(bytes, 20) as usize != SECTION_COUNT || u64_at(bytes, 24) != HEADER_LEN as u64 {
        return Err(Error::corrupt(format!(
            "the header declares {} sections and an archive at offset {}; version {VERSION} has \
             {SECTION_COUNT} sections and the archive at {HEADER_LEN}",
            u32_at(bytes, 20),
            u64_at(bytes, 24)
        )));
    }
    Ok(())
}

/// Decodes the section table: each entry's name must be the expected one, in order.
fn decode_sections(table: &[u8]) -> Result<[Section; SECTION_COUNT]> {
    let mut offset = 0u64;
    let mut sections = [Section { name: "", offset: 0, len: 0, xxh3: 0 }; SECTION_COUNT];
    for (i, s) in sections.iter_mut().enumerate() {
        let e = &table[i * SECTION_ENTRY_LEN..][..SECTION_ENTRY_LEN];
        let name = SECTION_NAMES[i];
        let mut expected = [0u8; 16];
        expected[..name.len()].copy_from_slice(name.as_bytes());
        if e[..16] != expected {
            let found = String::from_utf8_lossy(&e[..16]).trim_end_matches('\0').to_string();
            return Err(Error::corrupt(format!("section {i} is named {found:?}, expected {name:?}")));
        }
        let len = u64_at(e, 16);
        *s = Section { name, offset, len, xxh3: u64_at(e, 24) };
        offset = offset
            .checked_add(len)
            .ok_or_else(|| Error::corrupt(format!("section {name:?}'s length {len} overflows the file")))?;
    }
    Ok(sections)
}

fn truncated(what: &'static str, needed: usize, available: usize) -> Error {
    Error::Truncated { what, needed: needed as u64, available: available as u64 }
}

fn u16_at(b: &[u8], at: usize) -> u16 {
    u16::from_le_bytes([b[at], b[at + 1]])
}

fn u32_at(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes(b[at..at + 4].try_into().expect("4 bytes"))
}

fn u64_at(b: &[u8], at: usize) -> u64 {
    u64::from_le_bytes(b[at..at + 8].try_into().expect("8 bytes"))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Sections of 4, 8, 0, ... bytes: 16 in all, with one empty section.
    fn sample() -> Header {
        let mut sums = [(0u64, 0u64); SECTION_COUNT];
        sums[0] = (4, 11);
        sums[1] = (8, 12);
        sums[SECTION_COUNT - 1] = (4, 13);
        Header::new(sums, 7)
    }

    const FILE_LEN: u64 = HEADER_LEN as u64 + 16;

    #[test]
    fn header_round_trips() {
        let h = sample();
        assert_eq!(h.payload_len, 16);
        assert_eq!(Header::decode(&h.encode(), FILE_LEN).unwrap(), h);
        assert_eq!(Header::decode_stream(&h.encode()).unwrap(), h);
    }

    #[test]
    fn wrong_magic_is_bad_magic() {
        let mut b = sample().encode();
        b[0] = b'X';
        assert!(matches!(Header::decode(&b, FILE_LEN), Err(Error::BadMagic { .. })));
    }

    #[test]
    fn other_versions_name_both_versions() {
        for (major, minor) in
            [(1u16, 0u16), (2, 0), (3, 0), (4, 0), (5, 0), (6, 0), (7, 0), (8, 0), (9, 0), (11, 0), (0, 10), (10, 1)]
        {
            let mut b = sample().encode();
            b[8..10].copy_from_slice(&major.to_le_bytes());
            b[10..12].copy_from_slice(&minor.to_le_bytes());
            let err = Header::decode(&b, FILE_LEN).unwrap_err();
            let msg = err.to_string();
            assert!(matches!(err, Error::UnsupportedVersion { .. }), "{msg}");
            assert!(msg.contains(&format!("{major}.{minor}")) && msg.contains("10.0"), "{msg}");
        }
    }

    #[test]
    fn short_files_are_truncated_where_they_end() {
        let b = sample().encode();
        for n in [0usize, 3, 8, 20, 63] {
            let err = Header::decode(&b[..n], n as u64).unwrap_err();
            assert!(matches!(err, Error::Truncated { what: "header", .. }), "{n}: {err}");
        }
        for n in [64usize, 100, HEADER_LEN - 1] {
            let err = Header::decode(&b[..n], n as u64).unwrap_err();
            assert!(matches!(err, Error::Truncated { what: "section table", .. }), "{n}: {err}");
        }
        for (len, what) in [(0, "section octree"), (3, "section octree"), (4, "section tri_refs"), (12, "section root")]
        {
            let err = Header::decode(&b, HEADER_LEN as u64 + len).unwrap_err();
            assert!(matches!(err, Error::Truncated { what: w, .. } if w == what), "{len}: {err}");
        }
    }

    #[test]
    fn a_flipped_bit_fails_the_checksum_of_its_part() {
        let mut b = sample().encode();
        b[33] ^= 4;
        assert!(matches!(Header::decode(&b, FILE_LEN), Err(Error::Checksum { section: "header", .. })));
        let mut b = sample().encode();
        b[FIXED_HEADER_LEN + 40] ^= 1;
        let err = Header::decode(&b, FILE_LEN).unwrap_err();
        assert!(matches!(err, Error::Checksum { section: "section table", .. }), "{err}");
    }

    #[test]
    fn lengths_that_overflow_or_do_not_tile_are_corrupt() {
        let mut sums = [(0u64, 0u64); SECTION_COUNT];
        sums[0] = (u64::MAX, 0);
        sums[1] = (2, 0);
        let b = Header::new(sums, 0).encode();
        assert!(matches!(Header::decode_stream(&b), Err(Error::Corrupt(m)) if m.contains("overflows")));
        let mut h = sample();
        h.payload_len = 17;
        assert!(matches!(Header::decode(&h.encode(), FILE_LEN + 1), Err(Error::Corrupt(m)) if m.contains("cover")));
    }

    #[test]
    fn a_renamed_section_is_corrupt() {
        let mut b = sample().encode();
        b[FIXED_HEADER_LEN + 2 * SECTION_ENTRY_LEN] = b'X';
        let sum = xxhash_rust::xxh3::xxh3_64(&b[FIXED_HEADER_LEN..]);
        b[40..48].copy_from_slice(&sum.to_le_bytes());
        let sum = xxhash_rust::xxh3::xxh3_64(&b[..56]);
        b[56..64].copy_from_slice(&sum.to_le_bytes());
        let err = Header::decode(&b, FILE_LEN).unwrap_err();
        assert!(err.to_string().contains("\"Xriangles\""), "{err}");
    }
}
