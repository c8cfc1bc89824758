//! OBJ files of positions and triangles only, read a block at a time and parsed in
//! parallel.
//!
//! Scanned meshes are mostly `v x y z` and `f a b c` lines and comments. Such a file is
//! read [`BLOCK_BYTES`] at a time (the whole text is never held: a 2.5 GB OBJ would
//! otherwise be its own peak), each block cut into chunks at line ends and parsed on
//! every core, its faces' indices resolved as they come. Any other statement, or
//! anything unusual in these (a fourth coordinate, a polygon, `v/vt/vn` corners, an
//! index out of range, a non-finite coordinate, bytes that are not UTF-8), and the
//! whole file goes through tobj instead ([`super::obj`]), which makes the same mesh of
//! a plain file (the tests compare them) and says what is wrong with the rest.

use std::io::Read;
use std::sync::atomic::{AtomicBool, Ordering};

use rayon::prelude::*;

use super::Mesh;

/// Bytes of text read and parsed at a time (a line longer than this is left to tobj).
const BLOCK_BYTES: usize = 16 << 20;

/// Chunks a core, so that uneven lines still balance.
const CHUNKS_PER_THREAD: usize = 4;

/// Lines between two looks at whether another chunk was refused.
const REFUSED_EVERY: usize = 4096;

/// What one chunk holds: its positions, and its faces' corners as given (1-based,
/// or negative: relative to the positions before the face).
#[derive(Default)]
struct Chunk {
    positions: Vec<[f32; 3]>,
    /// Each face's three indices as written, and the chunk's position count before it.
    faces: Vec<([i64; 3], u32)>,
}

/// A plain file's positions and faces so far.
#[derive(Default)]
struct Plain {
    positions: Vec<[f32; 3]>,
    /// Each face's three position indices from the file's first, 0-based (relative
    /// ones resolved as they are read); checked against every position at the end, as
    /// tobj lets a face name a position that comes after it.
    faces: Vec<[u32; 3]>,
}

/// Why a plain file's reading stopped.
#[derive(Debug)]
pub(super) enum Stop {
    /// The input's error, or [`std::io::ErrorKind::OutOfMemory`] where the allocator
    /// refused the positions, faces or triangles (never an abort).
    Read(std::io::Error),
    /// More faces than the triangle budget, or more positions than three a triangle
    /// of it: `what` and at least how many.
    Budget { what: &'static str, needed: u64, limit: u64 },
}

impl From<std::io::Error> for Stop {
    fn from(e: std::io::Error) -> Stop {
        Stop::Read(e)
    }
}

/// The mesh of a plain OBJ file held in memory, or `None` for any other (tobj then
/// reads it, and counts its triangles).
pub(super) fn parse(bytes: &[u8]) -> Option<Mesh> {
    // Reading from memory fails only where memory does.
    read(bytes, u64::MAX).ok().flatten()
}

/// The mesh of a plain OBJ file read from `input` a block at a time, or `None` for
/// any other (tobj then reads it): at most `max_triangles` faces and three times as
/// many positions, counted as they are read, so that the memory it takes follows
/// the mesh whatever the file's size.
///
/// # Errors
/// [`Stop`].
pub(super) fn read(input: impl Read, max_triangles: u64) -> Result<Option<Mesh>, Stop> {
    read_in_blocks(input, BLOCK_BYTES, max_triangles)
}

/// [`read`], `block_bytes` at a time.
fn read_in_blocks(mut input: impl Read, block_bytes: usize, max_triangles: u64) -> Result<Option<Mesh>, Stop> {
    let mut plain = Plain::default();
    let mut block = vec![0u8; block_bytes];
    let mut filled = 0;
    loop {
        let last = loop {
            match input.read(&mut block[filled..]) {
                Ok(0) => break true,
                Ok(n) => filled += n,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) => return Err(Stop::Read(e)),
            }
            if filled == block.len() {
                break false;
            }
        };
        // Whole lines only: a line end is one byte in UTF-8, so each block of whole
        // lines is UTF-8 exactly when the file is.
        let cut = match last {
            true => filled,
            false => match block.iter().rposition(|&b| b == b'\n') {
                Some(k) => k + 1,
                None => return Ok(None),
            },
        };
        let Ok(text) = std::str::from_utf8(&block[..cut]) else { return Ok(None) };
        if !plain.add(text)? {
            return Ok(None);
        }
        let counted = [
            ("triangles", plain.faces.len() as u64, max_triangles),
            ("positions", plain.positions.len() as u64, max_triangles.saturating_mul(3)),
        ];
        if let Some(&(what, needed, limit)) = counted.iter().find(|(_, n, limit)| n > limit) {
            return Err(Stop::Budget { what, needed, limit });
        }
        block.copy_within(cut..filled, 0);
        filled -= cut;
        if last {
            return Ok(plain.mesh()?);
        }
    }
}

impl Plain {
    /// Adds a block of whole lines: `false` where it is not plain.
    fn add(&mut self, text: &str) -> std::io::Result<bool> {
        let pieces = (rayon::current_num_threads() * CHUNKS_PER_THREAD).max(1);
        // The first chunk that is not plain stops the others: the file goes to tobj.
        let refused = AtomicBool::new(false);
        let chunks: Option<Vec<Chunk>> = split(text, pieces)
            .par_iter()
            .map(|t| {
                let chunk = parse_chunk(t, &refused);
                if chunk.is_none() {
                    refused.store(true, Ordering::Relaxed);
                }
                chunk
            })
            .collect();
        let Some(chunks) = chunks else { return Ok(false) };
        for chunk in chunks {
            let no_room = |what: &str, n: usize| {
                std::io::Error::new(
                    std::io::ErrorKind::OutOfMemory,
                    format!("its {n} {what} (so far) are more than this process could allocate"),
                )
            };
            let n = self.faces.len() + chunk.faces.len();
            self.faces.try_reserve(chunk.faces.len()).map_err(|_| no_room("faces", n))?;
            let n = self.positions.len() + chunk.positions.len();
            self.positions.try_reserve(chunk.positions.len()).map_err(|_| no_room("positions", n))?;
            let before = self.positions.len() as i64;
            for &(face, local) in &chunk.faces {
                let mut resolved = [0u32; 3];
                for (r, &i) in resolved.iter_mut().zip(&face) {
                    // tobj's rule: `-k` is the k-th position before the face, `p` the
                    // p-th of the file (any, once the file is read).
                    let index = if i < 0 { before + local as i64 + i } else { i - 1 };
                    let Ok(index) = u32::try_from(index) else { return Ok(false) };
                    *r = index;
                }
                self.faces.push(resolved);
            }
            self.positions.extend_from_slice(&chunk.positions);
        }
        Ok(true)
    }

    /// The mesh, once every line is read: `None` where a face names a position the
    /// file does not have.
    fn mesh(self) -> std::io::Result<Option<Mesh>> {
        let Plain { positions, faces } = self;
        let mut triangles: Vec<[[f32; 3]; 3]> = octrace_format::memory::try_vec_zeroed(faces.len()).map_err(|_| {
            std::io::Error::new(
                std::io::ErrorKind::OutOfMemory,
                format!("its {} triangles are more than this process could allocate", faces.len()),
            )
        })?;
        let missing = AtomicBool::new(false);
        triangles.par_iter_mut().zip(&faces).for_each(|(tri, face)| {
            for (corner, &i) in tri.iter_mut().zip(face) {
                match positions.get(i as usize) {
                    Some(&p) => *corner = p,
                    None => missing.store(true, Ordering::Relaxed),
                }
            }
        });
        if missing.into_inner() {
            return Ok(None);
        }
        drop((positions, faces));
        let mut mesh = Mesh::from_triangles(triangles);
        mesh.end_part(octrace_format::PartSource::Obj { object: 0 }, || "object 'unnamed_object'".to_string());
        Ok(Some(mesh))
    }
}

/// `text` cut into about `pieces` parts, each ending at a line end (or the text's).
fn split(text: &str, pieces: usize) -> Vec<&str> {
    let step = text.len().div_ceil(pieces).max(1);
    let mut parts = Vec::with_capacity(pieces);
    let mut start = 0;
    while start < text.len() {
        let end = match text.as_bytes()[(start + step).min(text.len())..].iter().position(|&b| b == b'\n') {
            Some(k) => (start + step).min(text.len()) + k + 1,
            None => text.len(),
        };
        parts.push(&text[start..end]);
        start = end;
    }
    parts
}

/// One chunk's positions and faces, or `None` at the first line that is not plain, or
/// once another chunk has been `refused` (asked every [`REFUSED_EVERY`] lines).
fn parse_chunk(text: &str, refused: &AtomicBool) -> Option<Chunk> {
    let mut chunk = Chunk::default();
    for (n, line) in text.split('\n').enumerate() {
        if n % REFUSED_EVERY == 0 && refused.load(Ordering::Relaxed) {
            return None;
        }
        let mut words = Words { line, at: 0 };
        match words.next() {
            None => {}
            Some(w) if w.starts_with('#') => {}
            // Statements of ASCII alone: other whitespace (which tobj also splits at)
            // is left to tobj.
            Some(_) if !line.is_ascii() => return None,
            Some("v") => {
                let mut p = [0.0f32; 3];
                for c in &mut p {
                    *c = words.next()?.parse().ok()?;
                }
                if words.next().is_some() || !p.iter().all(|c| c.is_finite()) {
                    return None;
                }
                chunk.positions.push(p);
            }
            Some("f") => {
                let mut f = [0i64; 3];
                for i in &mut f {
                    *i = index(words.next()?)?;
                }
                if words.next().is_some() {
                    return None;
                }
                chunk.faces.push((f, chunk.positions.len() as u32));
            }
            Some(_) => return None,
        }
    }
    Some(chunk)
}

/// A face's index: digits with an optional `-` (`v/vt/vn` corners go to tobj), not 0,
/// less than 2^32 in size.
fn index(word: &str) -> Option<i64> {
    let (sign, digits) = match word.strip_prefix('-') {
        Some(rest) => (-1, rest),
        None => (1, word),
    };
    // Ten digits hold any index below 2^32 (leading zeros aside, which tobj reads too).
    let digits = digits.trim_start_matches('0');
    if word.len() == usize::from(sign < 0) || digits.len() > 10 || !digits.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    let value = digits.bytes().fold(0i64, |v, b| 10 * v + i64::from(b - b'0'));
    (value != 0 && value < 1 << 32).then_some(sign * value)
}

/// The words of a line: runs of bytes between ASCII whitespace (the whitespace of
/// `str::split_whitespace` below 0x80, CR included).
struct Words<'a> {
    line: &'a str,
    at: usize,
}

impl<'a> Iterator for Words<'a> {
    type Item = &'a str;

    fn next(&mut self) -> Option<&'a str> {
        let bytes = self.line.as_bytes();
        let space = |b: u8| matches!(b, b' ' | b'\t' | b'\r' | b'\n' | 0x0b | 0x0c);
        let start = self.at + bytes[self.at..].iter().position(|&b| !space(b))?;
        let end = bytes[start..].iter().position(|&b| space(b)).map_or(bytes.len(), |k| start + k);
        self.at = end;
        Some(&self.line[start..end])
    }
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use super::super::LoadOptions;
    use super::*;

    /// Through tobj, as any file.
    fn tobj(text: &str) -> Option<Mesh> {
        super::super::obj::parse_with_tobj(text.as_bytes(), Path::new("t.obj"), None, &LoadOptions::default()).ok()
    }

    /// The paper's meshes: the same mesh as tobj's, triangle for triangle, on one
    /// thread and on four (other chunk boundaries). The bunny the repository carries
    /// always; the dragon where `../shared` is beside the clone (the tests crate's
    /// `the_standard_sets_on_the_dragon_match_the_cpu` is listed as ignored where not).
    #[test]
    fn plain_files_give_tobjs_mesh() {
        let manifest = Path::new(env!("CARGO_MANIFEST_DIR"));
        let bunny = std::fs::read(manifest.join("../assets/bunny.obj.zst")).expect("the repository's bunny");
        let bunny = zstd::stream::decode_all(&bunny[..]).expect("the bunny decompresses");
        let dragon_path = manifest.join("../../shared/meshes/dragon.obj");
        let dragon = std::fs::read(&dragon_path).ok();
        if dragon.is_none() {
            assert!(std::env::var_os("OCTRACE_REQUIRE_SHARED").is_none(), "{} is missing", dragon_path.display());
        }
        for (name, bytes) in [("bunny", Some(bunny)), ("dragon", dragon)] {
            let Some(bytes) = bytes else { continue };
            let text = std::str::from_utf8(&bytes).unwrap();
            let want = tobj(text).unwrap();
            for threads in [1, 4] {
                let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
                let got = pool.install(|| parse(&bytes)).expect("a plain file");
                assert!(got == want, "{name}, {threads} threads: not tobj's mesh");
            }
        }
    }

    /// Comments, blank lines, CRLF, relative indices, faces before and after their
    /// positions, chunk boundaries anywhere: tobj's mesh.
    #[test]
    fn plain_details_give_tobjs_mesh() {
        let mut text =
            String::from("# a comment\r\n\r\nv 0 0 0\r\nv 1 0 0\nv 0 1 0\n#no space\nf 1 2 3\n  f -3 -2 -1  \n");
        for k in 0..200 {
            text +=
                &format!("v {k} 0.1 -2.5e-3\nv {k} 1 0\nv {k}.5 0 1\nf -1 -2 -3\nf {} 2 {}\n", 3 * k + 4, 3 * k + 6);
        }
        text += "f 1 600 603\n";
        let want = tobj(&text).unwrap();
        for threads in [1, 2, 3, 7, 64] {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            let got = pool.install(|| parse(text.as_bytes())).expect("a plain file");
            assert!(got == want, "{threads} threads");
        }
    }

    /// Read in blocks of any size (each at least the longest line), the same mesh:
    /// lines, faces and their relative indices cut anywhere between blocks, a block
    /// ending exactly at the file's end, CRLF split from its line end.
    #[test]
    fn blocks_of_any_size_give_the_same_mesh() {
        let mut text = String::from("v 0 0 0\r\nv 1 0 0\nv 0 1 0\nf 1 2 3\n# comment\n\n");
        for k in 0..60 {
            text += &format!("v {k} 0.1 -2.5e-3\nv {k} 1 0\r\nv {k}.5 0 1\nf -1 -2 -3\nf {} 2 -1\n", 3 * k + 4);
        }
        text += "f 1 100 183";
        let want = tobj(&text).unwrap();
        let longest = text.lines().map(str::len).max().unwrap() + 2;
        for block in (longest..longest + 40).chain([text.len() - 1, text.len(), text.len() + 1, 1 << 20]) {
            for threads in [1, 3] {
                let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
                let got = pool.install(|| read_in_blocks(text.as_bytes(), block, u64::MAX)).unwrap();
                assert!(got.as_ref() == Some(&want), "{block}-byte blocks, {threads} threads");
            }
        }
        // A line longer than a block is left to tobj, as is a file that turns out not
        // to be plain in a later block.
        assert!(read_in_blocks(text.as_bytes(), 8, u64::MAX).unwrap().is_none());
        let late = format!("{text}\nvn 0 0 1\n");
        assert!(read_in_blocks(late.as_bytes(), longest, u64::MAX).unwrap().is_none());
        // A face naming a position no block has.
        let missing = format!("{text}\nf 1 2 999\n");
        assert!(read_in_blocks(missing.as_bytes(), longest, u64::MAX).unwrap().is_none());
        // The budget: 122 faces and 183 positions, counted as the blocks come.
        let stop = |max| match read_in_blocks(text.as_bytes(), longest, max) {
            Err(Stop::Budget { what, needed, limit }) => Some((what, needed > limit, limit)),
            Ok(_) => None,
            Err(e) => panic!("{e:?}"),
        };
        assert_eq!(stop(121), Some(("triangles", true, 121)));
        assert_eq!(stop(122), None);
        let positions = format!("{text}\n{}", "v 0 0 0\n".repeat(400));
        let stopped = read_in_blocks(positions.as_bytes(), longest, 122);
        assert!(matches!(stopped, Err(Stop::Budget { what: "positions", limit: 366, .. })), "{stopped:?}");
    }

    /// Anything else goes to tobj (which reads it, or says what is wrong).
    #[test]
    fn anything_else_is_left_to_tobj() {
        let base = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\n";
        for extra in [
            "f 1 2 3 4\n",          // a quad
            "f 1/1 2/2 3/3\n",      // corners with texture coordinates
            "f 1//1 2//1 3//1\n",   // with normals
            "vn 0 0 1\nf 1 2 3\n",  // normals
            "o thing\nf 1 2 3\n",   // an object name
            "usemtl m\nf 1 2 3\n",  // a material
            "v 1 2 3 1\nf 1 2 3\n", // a fourth coordinate
            "v nan 0 0\nf 1 2 3\n", // not finite
            "f 1 2 9\n",            // past the positions
            "f 0 1 2\n",            // zero
            "f -9 -1 -2\n",         // before the first
            "f 1 2\n",              // a line
            "f 1 2 x\n",            // not a number
            "f 1 2 +3\n",           // a sign tobj reads, not this parser
        ] {
            assert!(parse(format!("{base}{extra}").as_bytes()).is_none(), "{extra:?}");
        }
        assert!(parse(b"v 0 0 0\nv 1 0 0\nv 0 1 0\xff\nf 1 2 3\n").is_none(), "not UTF-8");
        // Whitespace beyond ASCII (tobj splits at it too): tobj's.
        for odd in ["v 1\u{a0}1 0\nf 1 2 5\n", "\u{2003}f 1 2 3\n", "f 1 2\u{3000}3\n"] {
            assert!(parse(format!("{base}{odd}").as_bytes()).is_none(), "{odd:?}");
        }
        // Comments may hold any text.
        let noted = format!("# caf\u{e9} \u{a0}\n{base}#\u{2003}x\nf 1 2 3\n");
        let got = parse(noted.as_bytes());
        assert!(got.is_some() && got == tobj(&noted), "{noted:?}");
    }

    /// `n` words for a statement: one in `one_in` from `tricky`, the others from `usual`.
    fn words<'w>(
        pick: &mut impl FnMut(usize) -> usize,
        n: usize,
        one_in: usize,
        tricky: &[&'w str],
        usual: &[&'w str],
    ) -> Vec<&'w str> {
        (0..n).map(|_| if pick(one_in) == 0 { tricky[pick(tricky.len())] } else { usual[pick(usual.len())] }).collect()
    }

    /// Random files of the plain statements with tricky words mixed in (signs,
    /// exponents, zeros, huge and relative indices, stray tokens, CRLF, tabs):
    /// wherever this parser takes a file, tobj takes it too and makes the same mesh;
    /// wherever tobj refuses one, this parser leaves it to tobj.
    #[test]
    fn random_plain_files_are_tobjs_or_left_to_it() {
        let floats = ["0", "-0", "1", "-1.5", "+2", "1e-3", "3.25E2", ".5", "5.", "1e39", "nan", "-inf", "0x1", "1,5"];
        let indices = ["1", "2", "3", "-1", "-2", "-3", "4", "0", "-0", "+1", "99", "1/1", "1//1", "x", "4294967296"];
        let mut rng = crate::procedural::SplitMix(7);
        let mut pick = |n: usize| (rng.next_u64() % n as u64) as usize;
        let (mut taken, mut left) = (0, 0);
        for case in 0..3000 {
            let mut text = String::new();
            for _ in 0..1 + pick(12) {
                let end = if pick(5) == 0 { "\r\n" } else { "\n" };
                let sep = if pick(6) == 0 { "\t" } else { " " };
                match pick(10) {
                    0..=4 => {
                        let n = if pick(8) == 0 { 2 + pick(3) } else { 3 };
                        let words = words(&mut pick, n, 4, &floats, &["0.5", "1", "2.25", "-3"]);
                        text += &format!("v{sep}{}{end}", words.join(sep));
                    }
                    5..=7 => {
                        let n = if pick(8) == 0 { 2 + 2 * pick(2) } else { 3 };
                        let words = words(&mut pick, n, 3, &indices, &["1", "2", "3", "-1"]);
                        text += &format!("f{sep}{}{end}", words.join(sep));
                    }
                    8 => text += ["# c", "#c", "", "   ", "g x", "vn 0 0 1", "s off"][pick(7)],
                    _ => text += end,
                }
                if pick(7) == 0 {
                    text += "\n";
                }
            }
            let pool = rayon::ThreadPoolBuilder::new().num_threads(1 + case % 3).build().unwrap();
            let fast = pool.install(|| parse(text.as_bytes()));
            match (fast, tobj(&text)) {
                (Some(got), Some(want)) => {
                    assert!(got == want, "{text:?}: not tobj's mesh");
                    taken += 1;
                }
                (Some(_), None) => panic!("{text:?}: taken here, refused by tobj"),
                (None, _) => left += 1,
            }
        }
        assert!(
            taken > 300 && left > 300,
            "{taken} files taken, {left} left to tobj: the generator should exercise both"
        );
    }
}
