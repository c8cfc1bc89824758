//! The fixed 64-byte header, readable without rkyv.

use crate::error::{Error, Result, Version};

/// The eight bytes every baked scene starts with.
pub const MAGIC: [u8; 8] = *b"OCTRACE\0";
/// The format version this build writes, and the newest it reads.
pub const VERSION: Version = Version { major: 1, minor: 0 };
/// Header length in bytes; the archive starts right after it.
pub const HEADER_LEN: usize = 64;
/// Alignment of the archive within the file and in memory.
pub const ARCHIVE_ALIGN: usize = 16;

/// The rkyv settings the archive was written with, one byte each:
/// endianness (1 = little), alignment (1 = aligned primitives), pointer width in bits,
/// and the archive's alignment in bytes. A reader refuses other settings.
pub const RKYV_SETTINGS: [u8; 4] = [1, 1, 32, ARCHIVE_ALIGN as u8];

/// The flags this build understands (none yet: every bit is reserved).
pub const KNOWN_FLAGS: u32 = 0;

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
    /// xxh3-64 of the archive bytes.
    pub payload_xxh3: u64,
    /// Wall time of the bake in microseconds; 0 when not recorded (reproducible bakes).
    /// It lies outside the archive and its checksum, so the archive is identical
    /// whatever the timing.
    pub bake_time_us: u64,
}

impl Header {
    /// Encodes the header, its own checksum in the last eight bytes.
    pub fn encode(&self) -> [u8; HEADER_LEN] {
        let mut b = [0u8; HEADER_LEN];
        b[0..8].copy_from_slice(&MAGIC);
        b[8..10].copy_from_slice(&self.version.major.to_le_bytes());
        b[10..12].copy_from_slice(&self.version.minor.to_le_bytes());
        b[12..16].copy_from_slice(&self.flags.to_le_bytes());
        b[16..20].copy_from_slice(&self.rkyv_settings);
        b[20..24].copy_from_slice(&(HEADER_LEN as u32).to_le_bytes());
        b[24..32].copy_from_slice(&(HEADER_LEN as u64).to_le_bytes());
        b[32..40].copy_from_slice(&self.payload_len.to_le_bytes());
        b[40..48].copy_from_slice(&self.payload_xxh3.to_le_bytes());
        b[48..56].copy_from_slice(&self.bake_time_us.to_le_bytes());
        let sum = xxhash_rust::xxh3::xxh3_64(&b[..56]);
        b[56..64].copy_from_slice(&sum.to_le_bytes());
        b
    }

    /// Decodes and checks a header: magic first, then version, then the header's own
    /// checksum and fields. `file_len` is the length of the whole file.
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

    fn decode_with(bytes: &[u8], file_len: Option<u64>) -> Result<Self> {
        if bytes.len() < 8 || bytes[..8] != MAGIC {
            let mut found = [0u8; 8];
            let n = bytes.len().min(8);
            found[..n].copy_from_slice(&bytes[..n]);
            if n < 8 && MAGIC.starts_with(&bytes[..n]) {
                return Err(truncated("header", HEADER_LEN, bytes.len()));
            }
            return Err(Error::BadMagic { found });
        }
        if bytes.len() < 12 {
            return Err(truncated("header", HEADER_LEN, bytes.len()));
        }
        let version = Version { major: u16_at(bytes, 8), minor: u16_at(bytes, 10) };
        if version.major != VERSION.major || version.minor > VERSION.minor {
            return Err(Error::UnsupportedVersion { found: version, supported: VERSION });
        }
        if bytes.len() < HEADER_LEN {
            return Err(truncated("header", HEADER_LEN, bytes.len()));
        }
        let stored = u64_at(bytes, 56);
        let computed = xxhash_rust::xxh3::xxh3_64(&bytes[..56]);
        if stored != computed {
            return Err(Error::Checksum { section: "header", stored, computed });
        }
        let header = Header {
            version,
            flags: u32_at(bytes, 12),
            rkyv_settings: [bytes[16], bytes[17], bytes[18], bytes[19]],
            payload_len: u64_at(bytes, 32),
            payload_xxh3: u64_at(bytes, 40),
            bake_time_us: u64_at(bytes, 48),
        };
        header.check_fields(bytes, file_len)?;
        Ok(header)
    }

    fn check_fields(&self, bytes: &[u8], file_len: Option<u64>) -> Result<()> {
        if self.flags & !KNOWN_FLAGS != 0 {
            return Err(Error::corrupt(format!("unknown header flags {:#x}", self.flags)));
        }
        if self.rkyv_settings != RKYV_SETTINGS {
            return Err(Error::corrupt(format!(
                "archive written with rkyv settings {:?}, this build reads {:?}",
                self.rkyv_settings, RKYV_SETTINGS
            )));
        }
        if u32_at(bytes, 20) as usize != HEADER_LEN || u64_at(bytes, 24) != HEADER_LEN as u64 {
            return Err(Error::corrupt("header length or payload offset is not 64"));
        }
        let Some(file_len) = file_len else { return Ok(()) };
        let needed = (HEADER_LEN as u64).saturating_add(self.payload_len);
        if needed > file_len {
            return Err(Error::Truncated { what: "archive", needed, available: file_len });
        }
        if needed < file_len {
            return Err(Error::corrupt(format!("{} bytes after the archive", file_len - needed)));
        }
        Ok(())
    }
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

    fn sample() -> Header {
        Header {
            version: VERSION,
            flags: 0,
            rkyv_settings: RKYV_SETTINGS,
            payload_len: 16,
            payload_xxh3: 42,
            bake_time_us: 7,
        }
    }

    #[test]
    fn header_round_trips() {
        let h = sample();
        assert_eq!(Header::decode(&h.encode(), 80).unwrap(), h);
    }

    #[test]
    fn wrong_magic_is_bad_magic() {
        let mut b = sample().encode();
        b[0] = b'X';
        assert!(matches!(Header::decode(&b, 80), Err(Error::BadMagic { .. })));
    }

    #[test]
    fn other_versions_name_both_versions() {
        for (major, minor) in [(2u16, 0u16), (0, 9), (1, 1)] {
            let mut b = sample().encode();
            b[8..10].copy_from_slice(&major.to_le_bytes());
            b[10..12].copy_from_slice(&minor.to_le_bytes());
            let err = Header::decode(&b, 80).unwrap_err();
            let msg = err.to_string();
            assert!(matches!(err, Error::UnsupportedVersion { .. }), "{msg}");
            assert!(msg.contains(&format!("{major}.{minor}")) && msg.contains("1.0"), "{msg}");
        }
    }

    #[test]
    fn short_files_are_truncated() {
        let b = sample().encode();
        for n in [0usize, 3, 8, 20, 63] {
            let err = Header::decode(&b[..n], n as u64).unwrap_err();
            assert!(matches!(err, Error::Truncated { .. }), "{n}: {err}");
        }
        assert!(matches!(Header::decode(&b, 70), Err(Error::Truncated { .. })));
    }

    #[test]
    fn a_flipped_header_bit_fails_the_checksum() {
        let mut b = sample().encode();
        b[33] ^= 4;
        assert!(matches!(Header::decode(&b, 80), Err(Error::Checksum { .. })));
    }
}
