//! OBJ files of positions and triangles only, parsed in parallel.
//!
//! Scanned meshes are mostly `v x y z` and `f a b c` lines and comments. Such a file is
//! cut into chunks at line ends and parsed on every core; any other statement, or
//! anything unusual in these (a fourth coordinate, a polygon, `v/vt/vn` corners, an
//! index out of range, a non-finite coordinate, bytes that are not UTF-8), and the
//! whole file goes through tobj instead ([`super::obj`]), which makes the same mesh of
//! a plain file (the tests compare them) and says what is wrong with the rest.

use std::sync::atomic::{AtomicBool, Ordering};

use rayon::prelude::*;

use super::Mesh;

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

/// The mesh of a plain OBJ file, or `None` for any other (tobj then reads it).
pub(super) fn parse(bytes: &[u8]) -> Option<Mesh> {
    let text = std::str::from_utf8(bytes).ok()?;
    let pieces = (rayon::current_num_threads() * CHUNKS_PER_THREAD).max(1);
    // The first chunk that is not plain stops the others: the file goes to tobj.
    let refused = AtomicBool::new(false);
    let chunks: Vec<Chunk> = split(text, pieces)
        .par_iter()
        .map(|t| {
            let chunk = parse_chunk(t, &refused);
            if chunk.is_none() {
                refused.store(true, Ordering::Relaxed);
            }
            chunk
        })
        .collect::<Option<_>>()?;
    // Positions stay in their chunks (no copy of them all): `starts[c]` is chunk `c`'s
    // first position's index in the file.
    let starts: Vec<usize> = std::iter::once(0)
        .chain(chunks.iter().scan(0, |n, c| {
            *n += c.positions.len();
            Some(*n)
        }))
        .collect();
    let position = |k: usize| {
        // The last chunk starting at or before `k` holds it (an empty chunk never is
        // that one: the next starts at the same index), or `k` is past every position.
        let c = starts.partition_point(|&s| s <= k) - 1;
        chunks.get(c)?.positions.get(k - starts[c]).copied()
    };
    let mut mesh = Mesh::default();
    mesh.triangles.reserve(chunks.iter().map(|c| c.faces.len()).sum());
    for (chunk, &before) in chunks.iter().zip(&starts) {
        for &(face, local) in &chunk.faces {
            let mut tri = [[0.0f32; 3]; 3];
            for (corner, &i) in tri.iter_mut().zip(&face) {
                // tobj's rule: `-k` is the k-th position before the face, `p` the p-th
                // of the file (any, once the file is read).
                let index = if i < 0 { before as i64 + local as i64 + i } else { i - 1 };
                *corner = usize::try_from(index).ok().and_then(position)?;
            }
            mesh.push(tri, None, None);
        }
    }
    mesh.end_part(octrace_format::PartSource::Obj { object: 0 }, || "object 'unnamed_object'".to_string());
    Some(mesh)
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
    for (n, line) in text.lines().enumerate() {
        if n % REFUSED_EVERY == 0 && refused.load(Ordering::Relaxed) {
            return None;
        }
        let mut words = line.split_whitespace();
        match words.next() {
            None => {}
            Some(w) if w.starts_with('#') => {}
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
                    // Digits with an optional sign only: `v/vt/vn` corners go to tobj.
                    let word = words.next()?;
                    if !word.trim_start_matches('-').bytes().all(|b| b.is_ascii_digit()) {
                        return None;
                    }
                    *i = word.parse().ok().filter(|&i: &i64| i != 0 && i.unsigned_abs() < 1 << 32)?;
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
    /// thread and on four (other chunk boundaries).
    #[test]
    fn plain_files_give_tobjs_mesh() {
        for name in ["bunny.obj", "dragon.obj"] {
            let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/meshes").join(name);
            let Ok(bytes) = std::fs::read(&path) else {
                assert!(std::env::var_os("OCTRACE_REQUIRE_SHARED").is_none(), "{} is missing", path.display());
                continue;
            };
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
