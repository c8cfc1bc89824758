//! Opening bad files gives the named errors, never a panic.

use octrace_bake::{bake, procedural, BuildParams};
use octrace_format::layout::{NodeRef, LEAF_HEADER_WORDS};
use octrace_format::{BakedScene, Error, Header, SceneFile, Section, FIXED_HEADER_LEN, HEADER_LEN};

const SECTION_ENTRY_LEN: usize = (HEADER_LEN - FIXED_HEADER_LEN) / octrace_format::SECTION_COUNT;

fn scene() -> BakedScene {
    octrace_tests::torus_scene()
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
    for (major, minor) in
        [(1u16, 0u16), (0, 3), (2, 0), (3, 0), (4, 0), (5, 0), (6, 0), (7, 0), (8, 0), (9, 0), (10, 8), (11, 0)]
    {
        let mut bytes = scene().to_file_bytes(0).unwrap();
        bytes[8..10].copy_from_slice(&major.to_le_bytes());
        bytes[10..12].copy_from_slice(&minor.to_le_bytes());
        let err = open(&bytes).unwrap_err();
        let msg = err.to_string();
        assert!(matches!(err, Error::UnsupportedVersion { .. }), "{msg}");
        assert!(msg.contains(&format!("{major}.{minor}")) && msg.contains("10.0"), "{msg}");
    }
}

#[test]
fn truncated_files_are_truncated_errors() {
    let bytes = scene().to_file_bytes(0).unwrap();
    let len = bytes.len();
    for cut in [0, 1, 7, 8, 12, 40, 63, 64, 100, HEADER_LEN - 1, HEADER_LEN, HEADER_LEN + 1, len / 2, len - 16, len - 1]
    {
        let err = open(&bytes[..cut]).unwrap_err();
        assert!(matches!(err, Error::Truncated { .. }), "cut at {cut}: {err}");
    }
}

/// The section a byte of the archive belongs to (the first non-empty one that holds it).
fn section_of(header: &Header, at: u64) -> &'static str {
    header.sections.iter().find(|s| at < s.offset + s.len).unwrap().name
}

#[test]
fn truncation_at_every_section_boundary_names_the_section() {
    let bytes = scene().to_file_bytes(0).unwrap();
    let header = *open(&bytes).unwrap().header();
    assert!(header.sections.iter().all(|s| s.len > 0), "the test scene should fill every section");
    for s in &header.sections {
        // At the section's start, one byte in, in its middle, and one byte short of its end.
        for at in [s.offset, s.offset + 1, s.offset + s.len / 2, s.offset + s.len - 1] {
            let cut = HEADER_LEN + at as usize;
            let err = open(&bytes[..cut]).unwrap_err();
            let expected = format!("section {}", section_of(&header, at));
            assert!(
                matches!(&err, Error::Truncated { what, needed, available }
                    if *what == expected && *available == cut as u64 && *needed > *available),
                "cut at {cut} ({} + {}): {err}",
                s.name,
                at - s.offset
            );
            assert!(err.to_string().contains(&expected), "{err}");
        }
    }
    // Ending inside the header or the section table says so.
    assert!(matches!(open(&bytes[..40]), Err(Error::Truncated { what: "header", .. })));
    assert!(matches!(open(&bytes[..FIXED_HEADER_LEN + 5]), Err(Error::Truncated { what: "section table", .. })));
}

#[test]
fn a_flipped_bit_in_every_section_names_the_section() {
    let bytes = scene().to_file_bytes(0).unwrap();
    let header = *open(&bytes).unwrap().header();
    for s in &header.sections {
        for at in [s.offset, s.offset + s.len / 2, s.offset + s.len - 1] {
            for bit in [0, 7] {
                let mut b = bytes.clone();
                b[HEADER_LEN + at as usize] ^= 1 << bit;
                let err = open(&b).unwrap_err();
                assert!(
                    matches!(err, Error::Checksum { section, .. } if section == s.name),
                    "bit {bit} of byte {at} of {}: {err}",
                    s.name
                );
            }
        }
    }
    // The header's fixed part past the magic and version, and the section table.
    for at in [12, 20, 33, 50, 60] {
        let mut b = bytes.clone();
        b[at] ^= 2;
        assert!(matches!(open(&b), Err(Error::Checksum { section: "header", .. })), "header byte {at}");
    }
    for at in [FIXED_HEADER_LEN, FIXED_HEADER_LEN + 17, HEADER_LEN - 1] {
        let mut b = bytes.clone();
        b[at] ^= 2;
        assert!(matches!(open(&b), Err(Error::Checksum { section: "section table", .. })), "table byte {at}");
    }
}

/// Recomputes the section table's and the header's checksums after an edit.
fn reseal(b: &mut [u8]) {
    let sum = xxhash_rust::xxh3::xxh3_64(&b[FIXED_HEADER_LEN..HEADER_LEN]);
    b[40..48].copy_from_slice(&sum.to_le_bytes());
    let sum = xxhash_rust::xxh3::xxh3_64(&b[..56]);
    b[56..64].copy_from_slice(&sum.to_le_bytes());
}

#[test]
fn a_section_table_that_lies_about_the_archive_is_rejected() {
    let bytes = scene().to_file_bytes(0).unwrap();
    let header = *open(&bytes).unwrap().header();
    // Move four bytes from `tri_refs` to `octree`, checksums recomputed to match:
    // every checksum holds, but the arrays are not where the table says.
    let mut b = bytes.clone();
    let entry = |i: usize| FIXED_HEADER_LEN + i * SECTION_ENTRY_LEN;
    let (first, second) = (&header.sections[0], &header.sections[1]);
    let moved = |s: &Section, delta: i64| {
        let len = (s.len as i64 + delta) as u64;
        let start = HEADER_LEN + (s.offset as i64 + if delta < 0 { 4 } else { 0 }) as usize;
        (len, xxhash_rust::xxh3::xxh3_64(&bytes[start..start + len as usize]))
    };
    for (i, (len, sum)) in [(0, moved(first, 4)), (1, moved(second, -4))] {
        b[entry(i) + 16..entry(i) + 24].copy_from_slice(&len.to_le_bytes());
        b[entry(i) + 24..entry(i) + 32].copy_from_slice(&sum.to_le_bytes());
    }
    reseal(&mut b);
    let err = open(&b).unwrap_err();
    assert!(matches!(err, Error::Corrupt(ref m) if m.contains("not its section")), "{err}");
}

/// Rewrites a scene with one change and a valid checksum: only validation can refuse it.
/// The torus's texture kept encoded.
fn encoded(s: &mut BakedScene) -> &mut octrace_format::Encoded {
    s.shading.textures[1].encoded.as_mut().expect("the torus's occlusion texture is encoded")
}

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

/// Files the audit found accepted and then answered wrongly (issue 33): a leaf that
/// lists fewer triangles than before (one stored triangle listed by no leaf), the
/// references all zeroed (one triangle listed many times, the others nowhere), lists
/// that overlap or leave references behind. Each is refused by name.
#[test]
fn references_that_lose_triangles_are_rejected() {
    type Change = Box<dyn FnOnce(&mut BakedScene)>;
    let cases: [(&str, Change, &str); 4] = [
        (
            "a shorter list",
            Box::new(|s: &mut BakedScene| {
                let last = s.view().leaves().filter(|r| r.tri_count > 1).last().unwrap().address as usize;
                s.octree[last] -= 1;
            }),
            "",
        ),
        ("zeroed references", Box::new(|s: &mut BakedScene| s.tri_refs.fill(0)), "is listed by no leaf"),
        (
            "overlapping lists",
            Box::new(|s: &mut BakedScene| {
                let second = s.view().leaves().filter(|r| r.tri_count > 0).nth(1).unwrap().address as usize;
                s.octree[second + 1] -= 1;
            }),
            "back to back",
        ),
        (
            "a reference left over",
            Box::new(|s: &mut BakedScene| {
                let t = s.tri_refs[0];
                s.tri_refs.push(t);
            }),
            "after the last leaf's",
        ),
    ];
    for (what, change, says) in cases {
        let err = corrupt(change);
        assert!(matches!(err, Error::Corrupt(ref m) if m.contains(says)), "{what}: {err}");
    }
    // The audit's file: the textured leaf scene with its references zeroed.
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("data/textured/leaf.gltf");
    let mesh = octrace_bake::Mesh::load(&path).unwrap();
    let mut s = octrace_bake::bake(&mesh, &Default::default()).unwrap();
    s.tri_refs.fill(0);
    let Err(err) = open(&s.to_file_bytes(0).unwrap()) else { panic!("the zeroed references opened") };
    assert!(matches!(err, Error::Corrupt(_)), "{err}");
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
    let image = good.to_file_bytes(0).unwrap();
    let header = *open(&image).unwrap().header();
    // Section checksums run on two threads from 16 MiB: a flip in the first and in the
    // last array is named either way.
    assert!(image.len() > 16 << 20, "{} bytes: the two-thread checksum path is not reached", image.len());
    for s in [&header.sections[0], &header.sections[6]] {
        let mut b = image.clone();
        b[HEADER_LEN + (s.offset + s.len / 2) as usize] ^= 1;
        assert!(matches!(open(&b), Err(Error::Checksum { section, .. }) if section == s.name), "{}", s.name);
    }
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
    let root_entry = HEADER_LEN - SECTION_ENTRY_LEN;
    let root_len = u64::from_le_bytes(huge[root_entry + 16..root_entry + 24].try_into().unwrap()) + (1u64 << 50);
    huge[root_entry + 16..root_entry + 24].copy_from_slice(&root_len.to_le_bytes());
    let payload_len = u64::from_le_bytes(huge[32..40].try_into().unwrap()) + (1u64 << 50);
    huge[32..40].copy_from_slice(&payload_len.to_le_bytes());
    reseal(&mut huge);
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

/// Every link of a valid scene rewritten by `relink(own address, link)`, written
/// without validation (the archive stays structurally sound).
fn relinked(relink: impl Fn(u32, u32) -> u32) -> BakedScene {
    let mut s = scene();
    let records: Vec<(u32, usize)> = s.view().leaves().map(|r| (r.address, r.links.len())).collect();
    for (address, links) in records {
        let first = address as usize + LEAF_HEADER_WORDS;
        for word in &mut s.octree[first..first + links] {
            *word = relink(address, *word);
        }
    }
    s
}

#[test]
fn walks_through_link_cycles_stop_even_on_the_trusted_path() {
    use octrace_runtime::{Ray, Scene};
    let dir = tempfile::tempdir().unwrap();
    // Every face of every leaf flagged "coarser neighbour": each step climbs a level,
    // past the root, and the walk's cell arithmetic runs on garbage.
    let mut climbing = relinked(|own, _| own);
    let records: Vec<u32> = climbing.view().leaves().map(|r| r.address).collect();
    for address in records {
        climbing.octree[address as usize + 3] |= 0x3F << 24;
    }
    let cases: [(&str, BakedScene, bool); 3] = [
        // Every link back to its own leaf: each step is a one-leaf cycle.
        // Some walks never leave: the cell moves on while the leaf stays, and past the
        // root's boundary the stale leaf's links lead on forever; the bound ends them.
        ("self links", relinked(|own, _| own), true),
        // Every link to the first leaf: two-leaf cycles between far-apart cells.
        ("links to leaf 0", relinked(|_, _| 0), false),
        ("climbing cells", climbing, false),
    ];
    for (name, bad, reaches_bound) in cases {
        let path = dir.path().join("cycle.oct");
        bad.write(&path, 0).unwrap();
        let err = Scene::open(&path).unwrap_err();
        assert!(err.to_string().contains("corrupt"), "{name}: validation should refuse it: {err}");
        // SAFETY: this test's own file, not changed while mapped; its archive structure
        // is sound (only link values were changed), which is what tracing needs to stay
        // memory-safe.
        let scene = unsafe { Scene::map_unchecked(&path) }.unwrap();
        let tracer = scene.tracer();
        let mut rng = procedural::SplitMix(7);
        let mut stopped = 0;
        let mut rays = Vec::new();
        for _ in 0..2000 {
            let o = [rng.unit() * 4.0 - 2.0, rng.unit() * 4.0 - 2.0, rng.unit() * 4.0 - 2.0];
            let d = [rng.unit() - 0.5, rng.unit() - 0.5, rng.unit() - 0.5];
            let ray = Ray::segment(o.into(), d.into(), 0.0, f32::INFINITY);
            let (_, stats) = tracer.intersect_with_stats(&ray);
            assert!(stats.leaves <= tracer.max_steps() + 1, "{name}: {} steps", stats.leaves);
            stopped += stats.stopped_at_bound as u32;
            let _ = tracer.occluded(&ray);
            rays.push(ray);
        }
        // The batch paths (SIMD walks, eight in vector lanes where the processor has
        // AVX2) stop at the same bound, with the same answers.
        let single: Vec<_> = rays.iter().map(|r| tracer.intersect(r)).collect();
        assert_eq!(scene.intersect_batch(&rays), single, "{name}");
        let single: Vec<_> = rays.iter().map(|r| tracer.occluded(r)).collect();
        assert_eq!(scene.occluded_batch(&rays), single, "{name}");
        // Walks that would go on forever are stopped by the bound, not by luck.
        eprintln!("{name}: {stopped} of {} walks stopped at the bound", rays.len());
        if reaches_bound {
            assert!(stopped > 0, "{name}: no walk reached the step bound");
        }
    }
}

#[test]
fn the_fuzzing_header_helper_rebuilds_a_real_header() {
    let bytes = scene().to_file_bytes(0).unwrap();
    let real = *open(&bytes).unwrap().header();
    assert_eq!(octrace_format::testing::header_for_archive(&bytes[HEADER_LEN..]), real);
    // Garbage gets one `root` section whose checksum holds: the open fails past it.
    let junk = vec![7u8; 100];
    let mut file = octrace_format::testing::header_for_archive(&junk).encode().to_vec();
    file.extend_from_slice(&junk);
    // What bytecheck found, in every build (rancor's default error type keeps it only
    // where debug assertions are on).
    let err = open(&file).unwrap_err();
    assert!(
        matches!(err, Error::Corrupt(ref m) if m.contains("archive structure") && !m.contains("without error information")),
        "{err}"
    );
}

/// The geometry and shading rules: finite vertices inside the mesh box, the mesh box
/// inside the root cube, every listed triangle reaching its cell, finite normals and
/// texture coordinates, cameras with unit forward and up that are not parallel, lights
/// with unit directions. Each of these used to open.
#[test]
fn geometry_and_shading_that_break_the_rules_are_rejected() {
    use octrace_format::{Camera, Light, LightKind};
    let camera = Camera {
        name: "c".into(),
        position: [0.0, 0.0, 3.0],
        forward: [0.0, 0.0, -1.0],
        up: [0.0, 1.0, 0.0],
        yfov: 0.8,
        aspect: None,
        orthographic: None,
        gltf_camera: None,
    };
    let light = Light {
        name: "l".into(),
        kind: LightKind::Directional,
        color: [1.0; 3],
        intensity: 1.0,
        position: [0.0; 3],
        direction: [0.0, -1.0, 0.0],
        range: f32::INFINITY,
        inner_cone: 0.0,
        outer_cone: 0.0,
    };
    let with = |c: Camera, l: Light| {
        move |s: &mut BakedScene| {
            s.shading.cameras.push(c);
            s.shading.lights.push(l);
        }
    };
    // The rules hold for the scene with a good camera and light.
    let mut good = scene();
    with(camera.clone(), light.clone())(&mut good);
    open(&good.to_file_bytes(0).unwrap()).unwrap();
    type Change = Box<dyn FnOnce(&mut BakedScene)>;
    let cases: Vec<(&str, Change, &str)> = vec![
        ("NaN vertex", Box::new(|s| s.triangles[4] = f32::NAN), "not finite"),
        ("infinite vertex", Box::new(|s| s.triangles[0] = f32::INFINITY), "not finite"),
        ("mesh box too small", Box::new(|s| s.bounds.mesh_hi[1] -= 0.25), "outside the mesh box"),
        ("mesh box past the root", Box::new(|s| s.bounds.mesh_hi[2] += 100.0), "not inside the root cube"),
        (
            "triangle moved from its cells",
            Box::new(|s| {
                // The first stored triangle, mirrored through the centre: inside the mesh
                // box, far from the leaves that list it.
                for v in 0..3 {
                    for a in 0..3 {
                        s.triangles[3 * v + a] = -s.triangles[3 * v + a];
                    }
                }
            }),
            "does not reach its cell",
        ),
        ("NaN normal", Box::new(|s| s.normals[7] = f32::NAN), "not finite"),
        ("infinite uv", Box::new(|s| s.uvs[3] = f32::NEG_INFINITY), "not finite"),
        (
            "forward parallel to up",
            Box::new(with(Camera { up: [0.0, 0.0, 1.0], ..camera.clone() }, light.clone())),
            "not parallel",
        ),
        ("long forward", Box::new(with(Camera { forward: [0.0, 0.0, -2.0], ..camera.clone() }, light.clone())), "unit"),
        (
            "zero light direction",
            Box::new(with(camera.clone(), Light { direction: [0.0; 3], ..light.clone() })),
            "unit",
        ),
        // Found by fuzzing open_scene: the texel range's end overflowed (a panic with
        // overflow checks) before the sides were checked.
        (
            "a texture of 2^32 - 1 a side",
            Box::new(|s: &mut BakedScene| {
                s.shading.textures.push(octrace_format::Texture {
                    name: "huge".into(),
                    width: u32::MAX,
                    height: u32::MAX,
                    first: u32::MAX,
                    wrap: [octrace_format::Wrap::Repeat; 2],
                    filter: octrace_format::Filter::Linear,
                    min_alpha: 1.0,
                    srgb: true,
                    encoded: None,
                })
            }),
            "larger than 8192 a side",
        ),
        // The torus's tangents: a corner's direction halved, a sign of 2.
        (
            "a tangent that is not a unit vector",
            Box::new(|s: &mut BakedScene| {
                let t = octrace_format::layout::decode_tangent([s.tangents[0], s.tangents[1]]);
                s.tangents[0] = octrace_format::layout::encode_tangent(t.map(|c| c * 0.5))[0];
            }),
            "tangent of corner 0 of stored triangle 0",
        ),
        (
            "a tangent's sign of 2",
            Box::new(|s: &mut BakedScene| s.tangents[3] = (s.tangents[3] & 0xffff) | 2 << 16),
            "not a unit vector and a sign of 1 or -1",
        ),
        // The torus's occlusion texture is a 2 x 2 PNG kept encoded.
        ("an encoded image past the images", Box::new(|s: &mut BakedScene| encoded(s).bytes += 3), "runs past"),
        ("an encoded image's far offset", Box::new(|s: &mut BakedScene| encoded(s).offset = u64::MAX - 1), "runs past"),
        (
            "an encoded image of another size",
            Box::new(|s: &mut BakedScene| s.shading.textures[1].width = 3),
            "its image is a PNG of 2 x 2, its record says a PNG of 3 x 2",
        ),
        (
            "an encoded image of another kind",
            Box::new(|s: &mut BakedScene| encoded(s).kind = octrace_format::ImageKind::Jpeg),
            "its record says a JPEG",
        ),
        (
            "an encoded image's texels overlapping the stored ones",
            Box::new(|s: &mut BakedScene| s.shading.textures[1].first -= 1),
            "texels start at 3 rather than 4",
        ),
        (
            "an encoded image's bytes that are not an image",
            Box::new(|s: &mut BakedScene| s.images[0] ^= 1),
            "neither a PNG nor a JPEG",
        ),
    ];
    for (what, change, says) in cases {
        let err = corrupt(change);
        assert!(matches!(err, Error::Corrupt(ref m) if m.contains(says)), "{what}: {err}");
    }
}

/// The fuzzer's committed seeds for `open_scene` open in both of its modes (the first
/// byte: odd, a whole file; even, an archive behind a correct header): seeds the
/// current format refuses would leave the fuzzer mutating rejected bytes.
#[test]
fn the_fuzz_seeds_open_in_the_current_format() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../fuzz/seeds/open_scene");
    let mut opened = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        let data = std::fs::read(&path).unwrap();
        let (&mode, rest) = data.split_first().unwrap();
        let scene = if mode & 1 == 1 {
            octrace_runtime::Scene::from_bytes(rest)
        } else {
            let mut file = octrace_format::testing::header_for_archive(rest).encode().to_vec();
            file.extend_from_slice(rest);
            octrace_runtime::Scene::from_bytes(&file)
        };
        assert!(scene.is_ok(), "{}: {:?}", path.display(), scene.err());
        opened += 1;
    }
    assert_eq!(opened, 6);
}
