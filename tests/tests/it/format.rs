//! Opening bad files gives the named errors, never a panic.

use octrace_bake::{bake, procedural, BuildParams};
use octrace_format::layout::{NodeRef, LEAF_HEADER_WORDS};
use octrace_format::{BakedScene, Error, SceneFile, HEADER_LEN};

fn scene() -> BakedScene {
    let mesh = procedural::torus([0.0; 3], 1.0, 0.3, 16, 8);
    bake(&mesh, &BuildParams { max_depth: Some(5), leaf_size: Some(4), ..BuildParams::auto() }).unwrap()
}

fn open(bytes: &[u8]) -> Result<SceneFile, Error> {
    SceneFile::from_bytes(bytes)
}

#[test]
fn a_good_file_opens_from_bytes_and_from_disk() {
    let s = scene();
    let bytes = s.to_file_bytes(0).unwrap();
    assert_eq!(open(&bytes).unwrap().view().octree, s.octree.as_slice());
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("t.oct");
    s.write(&path, 5).unwrap();
    assert_eq!(std::fs::read(&path).unwrap().len(), bytes.len());
    let f = SceneFile::read(&path).unwrap();
    assert_eq!((f.header().bake_time_us, f.is_mapped()), (5, false));
}

#[test]
fn wrong_magic_is_bad_magic() {
    let mut bytes = scene().to_file_bytes(0).unwrap();
    bytes[..4].copy_from_slice(b"GLTF");
    assert!(matches!(open(&bytes), Err(Error::BadMagic { .. })));
    assert!(matches!(open(b"# an OBJ file\nv 0 0 0\n"), Err(Error::BadMagic { .. })));
}

#[test]
fn older_and_newer_versions_name_both_versions() {
    for (major, minor) in [(0u16, 3u16), (2, 0), (1, 7)] {
        let mut bytes = scene().to_file_bytes(0).unwrap();
        bytes[8..10].copy_from_slice(&major.to_le_bytes());
        bytes[10..12].copy_from_slice(&minor.to_le_bytes());
        let err = open(&bytes).unwrap_err();
        let msg = err.to_string();
        assert!(matches!(err, Error::UnsupportedVersion { .. }), "{msg}");
        assert!(msg.contains(&format!("{major}.{minor}")) && msg.contains("1.0"), "{msg}");
    }
}

#[test]
fn truncated_files_are_truncated_errors() {
    let bytes = scene().to_file_bytes(0).unwrap();
    let len = bytes.len();
    for cut in [0, 1, 7, 8, 12, 40, HEADER_LEN - 1, HEADER_LEN, HEADER_LEN + 1, len / 2, len - 16, len - 1] {
        let err = open(&bytes[..cut]).unwrap_err();
        assert!(matches!(err, Error::Truncated { .. }), "cut at {cut}: {err}");
    }
}

#[test]
fn a_flipped_bit_fails_a_checksum() {
    let bytes = scene().to_file_bytes(0).unwrap();
    for at in [HEADER_LEN + 3, bytes.len() / 3, bytes.len() - 5] {
        let mut b = bytes.clone();
        b[at] ^= 0x10;
        assert!(matches!(open(&b), Err(Error::Checksum { section: "archive", .. })), "flip at {at}");
    }
}

/// Rewrites a scene with one change and a valid checksum: only validation can refuse it.
fn corrupt(change: impl FnOnce(&mut BakedScene)) -> Error {
    let mut s = scene();
    change(&mut s);
    match open(&s.to_file_bytes(0).unwrap()) {
        Err(e) => e,
        Ok(_) => panic!("a corrupt scene opened"),
    }
}

/// The first link of the first record that has one, as (word index, value).
fn first_link(s: &BakedScene) -> usize {
    let v = s.view();
    let rec = v.leaves().find(|r| !r.links.is_empty()).unwrap();
    rec.address as usize + LEAF_HEADER_WORDS
}

#[test]
fn links_to_non_adjacent_leaves_and_link_cycles_are_rejected() {
    // A link to the leaf itself: a one-step cycle.
    let err = corrupt(|s| {
        let at = first_link(s);
        let own = s.view().leaves().find(|r| !r.links.is_empty()).unwrap().address;
        s.octree[at] = own;
    });
    assert!(matches!(err, Error::Corrupt(_)), "{err}");
    // A link to a real leaf that is not across that face.
    let err = corrupt(|s| {
        let at = first_link(s);
        let last = s.view().leaves().last().unwrap().address;
        let other = if s.octree[at] == last { 0 } else { last };
        s.octree[at] = other;
    });
    assert!(matches!(err, Error::Corrupt(ref m) if m.contains("face")), "{err}");
    // A link into the middle of a record.
    let err = corrupt(|s| {
        let at = first_link(s);
        s.octree[at] += 1;
    });
    assert!(matches!(err, Error::Corrupt(_)), "{err}");
}

#[test]
fn out_of_range_counts_and_offsets_are_rejected() {
    for (what, change) in [
        ("triangle count", Box::new(|s: &mut BakedScene| s.octree[0] = u32::MAX) as Box<dyn FnOnce(&mut BakedScene)>),
        ("triangle offset", Box::new(|s: &mut BakedScene| s.octree[1] = u32::MAX - 1)),
        ("box index", Box::new(|s: &mut BakedScene| s.octree[2] = 1 << 30)),
        ("neighbour counts", Box::new(|s: &mut BakedScene| s.octree[3] = 0xFFFF_FFFF)),
        ("triangle reference", Box::new(|s: &mut BakedScene| s.tri_refs[0] = u32::MAX)),
        ("root", Box::new(|s: &mut BakedScene| s.root = NodeRef::Internal(1 << 20).encode())),
        ("node", Box::new(|s: &mut BakedScene| s.nodes[3] = NodeRef::Internal(0).encode())),
        ("cube map", Box::new(|s: &mut BakedScene| s.cube_map.pop().map(drop).unwrap())),
        ("depth", Box::new(|s: &mut BakedScene| s.params.max_depth = 1000)),
        ("ids", Box::new(|s: &mut BakedScene| s.triangle_ids[1] = s.triangle_ids[0])),
        ("box", Box::new(|s: &mut BakedScene| s.boxes[4] += 1.0)),
        ("input count", Box::new(|s: &mut BakedScene| s.stats.input_triangles = u64::MAX)),
    ] {
        let err = corrupt(change);
        assert!(matches!(err, Error::Corrupt(_)), "{what}: {err}");
    }
}

#[test]
fn a_cube_map_texel_that_does_not_hold_its_cell_is_rejected() {
    let err = corrupt(|s| {
        let last = s.view().leaves().last().unwrap().address;
        s.cube_map[0] = NodeRef::Leaf(last).encode();
    });
    assert!(matches!(err, Error::Corrupt(ref m) if m.contains("cube-map")), "{err}");
}

#[test]
fn large_files_are_validated_on_two_threads_with_the_same_verdicts() {
    let mesh = procedural::soup(4, 40_000, 10.0, 0.3);
    let params = BuildParams { max_depth: Some(8), leaf_size: Some(1), ..BuildParams::auto() };
    let good = bake(&mesh, &params).unwrap();
    assert!(good.leaf_count() > 70_000, "only {} leaves: the two-thread path is not reached", good.leaf_count());
    open(&good.to_file_bytes(0).unwrap()).unwrap();
    // A broken link in the second half of the leaves (checked by the second thread).
    let mut bad = good.clone();
    let address = bad.view().leaves().filter(|r| !r.links.is_empty()).last().unwrap().address;
    bad.octree[address as usize + LEAF_HEADER_WORDS] = address;
    assert!(matches!(open(&bad.to_file_bytes(0).unwrap()), Err(Error::Corrupt(_))));
    // And a wrong cube-map texel (checked beside the links).
    let mut bad = good.clone();
    let last = bad.view().leaves().last().unwrap().address;
    bad.cube_map[0] = NodeRef::Leaf(last).encode();
    assert!(matches!(open(&bad.to_file_bytes(0).unwrap()), Err(Error::Corrupt(_))));
}

#[test]
fn compressed_files_round_trip_and_refuse_to_be_mapped() {
    let s = scene();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("t.oct.zst");
    let (raw, compressed) = s.write_compressed(&path, 9, 3).unwrap();
    assert_eq!(raw as usize, s.to_file_bytes(9).unwrap().len());
    assert!(compressed < raw, "{compressed} >= {raw}");
    let f = SceneFile::read(&path).unwrap();
    assert_eq!(f.view().octree, s.octree.as_slice());
    assert_eq!(f.header().bake_time_us, 9);
    // SAFETY: a file this test wrote and nobody changes.
    let mapped = unsafe { SceneFile::map(&path) };
    assert!(matches!(mapped, Err(Error::Compressed { .. })));
}

#[test]
fn broken_compressed_files_give_named_errors() {
    let s = scene();
    let dir = tempfile::tempdir().unwrap();
    let image = s.to_file_bytes(0).unwrap();
    // Truncated compressed stream.
    let full = octrace_tests::zstd_compress(&image);
    let cut = dir.path().join("cut.oct.zst");
    std::fs::write(&cut, &full[..full.len() / 2]).unwrap();
    assert!(SceneFile::read(&cut).is_err());
    // A header that declares a huge archive: refused before allocating.
    let mut huge = image[..HEADER_LEN].to_vec();
    huge[32..40].copy_from_slice(&(1u64 << 50).to_le_bytes());
    let sum = xxhash_rust::xxh3::xxh3_64(&huge[..56]);
    huge[56..64].copy_from_slice(&sum.to_le_bytes());
    let bomb = dir.path().join("bomb.oct.zst");
    std::fs::write(&bomb, octrace_tests::zstd_compress(&huge)).unwrap();
    let err = SceneFile::read(&bomb).unwrap_err();
    assert!(matches!(err, Error::Corrupt(ref m) if m.contains("times the compressed file")), "{err}");
    // Compressed garbage after a good archive.
    let mut trailing = image.clone();
    trailing.extend_from_slice(b"extra");
    let extra = dir.path().join("extra.oct.zst");
    std::fs::write(&extra, octrace_tests::zstd_compress(&trailing)).unwrap();
    assert!(matches!(SceneFile::read(&extra), Err(Error::Corrupt(_))));
}
