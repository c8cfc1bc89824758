//! Properties of the baked octree that must fail loudly if they break.

use std::collections::{HashMap, HashSet};

use octrace_format::layout::{face_axis, face_is_high, opposite_face};
use octrace_format::validate::CellKey;
use octrace_format::{BakedScene, SceneFile};

use super::overlap::{triangle_overlaps_box, Box3};
use super::{bake, BuildParams};
use crate::mesh::Mesh;
use crate::procedural;

fn params(depth: u32, leaf: u32) -> BuildParams {
    BuildParams { max_depth: Some(depth), leaf_size: Some(leaf), ..BuildParams::auto() }
}

fn meshes() -> Vec<(&'static str, Mesh)> {
    let mut both = procedural::sphere([0.0; 3], 1.0, 12, 16);
    both.triangles.extend(procedural::soup(3, 200, 2.0, 0.3).triangles);
    vec![
        ("sphere", procedural::sphere([0.3, -0.2, 0.1], 2.0, 24, 32)),
        ("torus", procedural::torus([0.0; 3], 1.0, 0.3, 24, 12)),
        ("cube", procedural::cube([-1.0, -1.0, -1.0], [1.0, 2.0, 0.5], 6)),
        ("grid", procedural::grid(16, 4.0)),
        ("fan", procedural::fan(64, 1.0)),
        ("soup", procedural::soup(1, 500, 10.0, 1.0)),
        ("sphere+soup", both),
    ]
}

fn leaf_keys(scene: &BakedScene) -> (Vec<CellKey>, Vec<u32>) {
    let index = scene.view().index_tree().expect("valid tree");
    (index.leaf_keys, index.leaf_addresses)
}

/// For each leaf, the level of the leaf across each face at the same level or coarser.
fn assert_balanced(name: &str, scene: &BakedScene) {
    let (keys, _) = leaf_keys(scene);
    let set: HashSet<(u32, [u32; 3])> = keys.iter().map(|k| (k.level, k.cell)).collect();
    for k in &keys {
        for face in 0..6 {
            let axis = face_axis(face);
            let mut across = k.cell;
            if face_is_high(face) {
                if across[axis] + 1 == 1 << k.level {
                    continue;
                }
                across[axis] += 1;
            } else {
                if across[axis] == 0 {
                    continue;
                }
                across[axis] -= 1;
            }
            // The leaf holding `across`, if it is at this level or coarser.
            if let Some(up) = (0..=k.level).find(|&up| set.contains(&(k.level - up, across.map(|c| c >> up)))) {
                assert!(up <= 1, "{name}: leaf {k:?} face {face} borders a leaf {up} levels coarser");
            }
        }
    }
}

#[test]
fn balance_no_two_face_adjacent_leaves_differ_by_more_than_one_level() {
    for (name, mesh) in meshes() {
        for depth in [3, 5, 7] {
            let scene = bake(&mesh, &params(depth, 2)).unwrap();
            assert_balanced(name, &scene);
            assert!(scene.leaf_count() as u64 >= scene.stats.leaves_before_balance);
        }
    }
}

#[test]
fn balance_check_catches_an_unbalanced_tree() {
    // Two tiny triangles at a generic interior point forces deep leaves beside big ones
    // (refinement towards a root corner would be balanced by itself); two more tiny
    // triangles at opposite corners fix the bounds.
    let tiny = |p: f32| [[p, p, p], [p + 0.001, p, p], [p, p + 0.001, p]];
    let mesh = Mesh::from_triangles(vec![tiny(0.0), tiny(0.3), tiny(0.3004), tiny(0.999)]);
    let scene = bake(&mesh, &params(8, 1)).unwrap();
    assert!(scene.leaf_count() as u64 > scene.stats.leaves_before_balance, "balancing added no leaf");
    assert_balanced("corner", &scene);
}

#[test]
fn links_are_symmetric_and_land_across_the_stated_face() {
    for (name, mesh) in meshes() {
        let scene = bake(&mesh, &params(6, 3)).unwrap();
        let view = scene.view();
        view.validate().unwrap_or_else(|e| panic!("{name}: {e}"));
        let (keys, addresses) = leaf_keys(&scene);
        let by_address: HashMap<u32, usize> = addresses.iter().enumerate().map(|(b, &a)| (a, b)).collect();
        for (b, &address) in addresses.iter().enumerate() {
            let rec = view.leaf(address).unwrap();
            for face in 0..6 {
                for &link in rec.face_links(face) {
                    let other = view.leaf(link).unwrap();
                    assert!(
                        other.face_links(opposite_face(face)).contains(&address),
                        "{name}: leaf {:?} -> {:?} across face {face} is not linked back",
                        keys[b],
                        keys[by_address[&link]]
                    );
                    // Across the face: the boxes touch on the face's plane.
                    let (mine, theirs) = (view.leaf_box(rec.box_index), view.leaf_box(other.box_index));
                    let axis = face_axis(face);
                    let plane = if face_is_high(face) {
                        (mine[axis + 3], theirs[axis])
                    } else {
                        (mine[axis], theirs[axis + 3])
                    };
                    assert_eq!(plane.0, plane.1, "{name}: link across face {face} does not share the plane");
                }
            }
        }
    }
}

#[test]
fn each_triangle_is_in_exactly_the_leaves_it_overlaps() {
    for (name, mesh) in meshes() {
        let scene = bake(&mesh, &params(5, 4)).unwrap();
        let view = scene.view();
        let margin = scene.params.margin as f64 * scene.bounds.root_size as f64;
        for rec in view.leaves() {
            let b = view.leaf_box(rec.box_index);
            let cell =
                Box3 { lo: [0, 1, 2].map(|a| b[a] as f64 - margin), hi: [0, 1, 2].map(|a| b[a + 3] as f64 + margin) };
            let refs = &view.tri_refs[rec.tri_offset as usize..][..rec.tri_count as usize];
            let got: HashSet<u32> = refs.iter().copied().collect();
            assert_eq!(got.len(), refs.len(), "{name}: a triangle listed twice in one leaf");
            let brute: HashSet<u32> = (0..view.triangle_count() as u32)
                .filter(|&t| triangle_overlaps_box(&view.triangle(octrace_format::StoredIndex(t)), &cell))
                .collect();
            assert_eq!(got, brute, "{name}: leaf {} references differ from brute force", rec.box_index);
        }
    }
}

#[test]
fn triangle_ids_name_the_input_triangles_and_skip_degenerate_ones() {
    let mut mesh = procedural::sphere([0.0; 3], 1.0, 6, 8);
    mesh.triangles.insert(3, [[0.0; 3], [1.0, 1.0, 1.0], [2.0, 2.0, 2.0]]); // collinear
    mesh.triangles.insert(7, [[0.5; 3]; 3]); // a point
    let scene = bake(&mesh, &params(4, 2)).unwrap();
    assert_eq!(scene.stats.degenerate_triangles, 2);
    assert_eq!(scene.stats.input_triangles, mesh.triangles.len() as u64);
    let view = scene.view();
    for (stored, &id) in scene.triangle_ids.iter().enumerate() {
        assert_ne!(id, 3);
        assert_ne!(id, 7);
        let t = view.triangle(octrace_format::StoredIndex(stored as u32));
        assert_eq!(t, mesh.triangles[id as usize], "stored triangle {stored} is not input {id}");
    }
}

#[test]
fn bake_write_open_gives_back_the_arrays() {
    for (name, mesh) in meshes() {
        let scene = bake(&mesh, &BuildParams::auto()).unwrap();
        let bytes = scene.to_file_bytes(1234).unwrap();
        let file = SceneFile::from_bytes(&bytes).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(file.header().bake_time_us, 1234);
        let v = file.view();
        let w = scene.view();
        assert_eq!(v.octree, w.octree);
        assert_eq!(v.tri_refs, w.tri_refs);
        assert_eq!(v.triangles, w.triangles);
        assert_eq!(v.triangle_ids, w.triangle_ids);
        assert_eq!(v.boxes, w.boxes);
        assert_eq!(v.cube_map, w.cube_map);
        assert_eq!(v.nodes, w.nodes);
        assert_eq!((v.root, v.params, v.bounds, v.stats), (w.root, w.params, w.bounds, w.stats));
    }
}

#[test]
fn one_thread_and_two_threads_give_byte_identical_files() {
    let mesh = procedural::soup(9, 20_000, 10.0, 0.5);
    let bake_on = |threads| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| bake(&mesh, &BuildParams::auto()).unwrap().to_file_bytes(0).unwrap())
    };
    let (one, two) = (bake_on(1), bake_on(2));
    assert!(one == two, "files differ between 1 and 2 threads");
}

/// Regression, found by fuzzing (fuzz/load_gltf): a mesh 1e-39 across got a
/// subnormal root edge, and the bake wrote a file its own validation refused. Such a
/// mesh is now refused with a clear error (the tracer's f32 products underflow there:
/// rays from inside a sphere 1e-22 across all leaked), and so is one beyond 2^60.
#[test]
fn scenes_smaller_or_larger_than_the_tracer_serves_are_refused() {
    let tiny = Mesh::from_triangles(vec![
        [[0.0, 0.0, 0.0], [1e-39, 0.0, 0.0], [0.0, 1e-39, 0.0]],
        [[0.0; 3], [2e-45, 0.0, 0.0], [0.0, 3e-45, 0.0]],
    ]);
    let scaled = |k: f32| {
        let mut m = procedural::sphere([0.3, -0.2, 0.1], 1.0, 8, 12);
        m.triangles.iter_mut().flatten().for_each(|v| *v = v.map(|c| c * k));
        m
    };
    let far = Mesh::from_triangles(vec![[[2e18, 0.0, 0.0], [2e18, 1e16, 0.0], [2e18, 0.0, 1e16]]]);
    for (name, mesh) in [("1e-39", tiny), ("1e-22", scaled(1e-22)), ("1e20", scaled(1e20)), ("far", far)] {
        let err = bake(&mesh, &BuildParams::auto()).unwrap_err();
        assert!(matches!(err, crate::Error::Scale { .. }), "{name}: {err}");
        assert!(err.to_string().contains("2^-60 (8.7e-19)") && err.to_string().contains("2^60"), "{err}");
    }
    // The scales, 1e-14 and 1e14, and the limits' neighbours bake and validate.
    for k in [1e-18, 1e-14, 1e14, 1e17] {
        let scene = bake(&scaled(k), &BuildParams::auto()).unwrap();
        scene.view().validate().unwrap();
    }
}

#[test]
fn the_root_cube_holds_the_mesh_and_has_a_power_of_two_edge() {
    for (lo, hi) in [
        ([0.0f32; 3], [1.0f32; 3]),
        ([1e7, -3.0, 0.5], [1e7 + 1.0, -2.5, 0.75]),
        ([-1e-5; 3], [1e-5; 3]),
        ([2.0; 3], [2.0; 3]),
    ] {
        let (root_lo, size) = super::root_cube(lo, hi).unwrap();
        assert_eq!(size.log2().fract(), 0.0, "{size}");
        for a in 0..3 {
            assert!(root_lo[a] <= lo[a] && (root_lo[a] as f64 + size as f64) >= hi[a] as f64);
        }
    }
}

/// The format's index limits, lowered to what a small mesh reaches, are enforced where
/// the documentation says: the triangles alone before the build, a tree past a limit
/// while it grows (the build stops, and no arrays are laid out), the exact record
/// words when the arrays are laid out; a tree exactly at a limit bakes.
#[test]
fn a_tree_past_a_limit_is_refused_as_soon_as_it_passes_it() {
    use super::build::Limits;
    use super::BakeStage;
    let mesh = procedural::sphere([0.1, -0.2, 0.3], 1.0, 96, 128);
    let p = params(8, 4);
    let full = bake(&mesh, &p).unwrap();
    let (refs, words) = (full.tri_refs.len() as u64, full.octree.len() as u64);
    let leaf_words = full.leaf_count() as u64 * octrace_format::layout::LEAF_HEADER_WORDS as u64;
    let kept = full.triangle_ids.len() as u64;
    let within = |limits: Limits| {
        let stages = std::sync::Mutex::new(Vec::new());
        let baked = super::bake_within(&mesh, &p, &|s| stages.lock().unwrap().push(s), limits);
        (baked, stages.into_inner().unwrap())
    };
    let limit_error = |baked: crate::Result<BakedScene>| match baked {
        Err(crate::Error::Limit { what, needed, limit }) => (what, needed, limit),
        other => panic!("expected a limit error, got {:?}", other.map(|_| "a scene")),
    };

    // Exactly at both limits: baked, the same file.
    let (at, _) = within(Limits { refs, words, bytes: u64::MAX });
    assert_eq!(at.unwrap().to_file_bytes(0).unwrap(), full.to_file_bytes(0).unwrap());

    // The triangles alone: refused before the build starts.
    let (baked, stages) = within(Limits { refs: kept - 1, words, bytes: u64::MAX });
    assert_eq!(limit_error(baked), ("triangle references", kept, kept - 1));
    assert_eq!(stages, [BakeStage::Prepare]);

    // Past a limit while building: stopped well short of the whole tree, never laid out.
    for (limits, what, whole) in [
        (Limits { refs: refs / 4, words, bytes: u64::MAX }, "triangle references", refs),
        (Limits { refs, words: leaf_words / 4, bytes: u64::MAX }, "words of leaf records", leaf_words),
    ] {
        let (baked, stages) = within(limits);
        let (name, needed, limit) = limit_error(baked);
        assert_eq!(name, what);
        let limit_set = if what == "triangle references" { limits.refs } else { limits.words };
        assert_eq!(limit, limit_set);
        assert!(needed > limit && needed < whole / 2, "{what}: stopped at {needed} of {whole}, limit {limit}");
        assert!(!stages.contains(&BakeStage::Link), "{what}: {stages:?}");
    }

    // Past the words limit only by the links, which the layout counts exactly.
    let (baked, stages) = within(Limits { refs, words: words - 1, bytes: u64::MAX });
    assert_eq!(limit_error(baked), ("words of leaf records", words, words - 1));
    assert_eq!(stages.last(), Some(&BakeStage::Link));
    let message = within(Limits { refs, words: words - 1, bytes: u64::MAX }).0.unwrap_err().to_string();
    assert!(message.contains("needs at least") && message.contains("--leaf-size"), "{message}");
}

/// A mesh that collapses at f32 precision (the audit's icosphere of radius 1e-3 at
/// 1e6, where f32's spacing is 1/16) is refused by name instead of baking into an
/// empty scene; one whose triangles mostly collapse bakes with a warning naming the
/// share and the cause.
#[test]
fn meshes_that_collapse_at_f32_precision_are_said_aloud() {
    let far = crate::procedural::sphere([1e6; 3], 1e-3, 16, 24);
    let err = bake(&far, &BuildParams::auto()).unwrap_err();
    assert!(matches!(err, crate::Error::Collapsed { triangles, .. } if triangles == far.triangles.len() as u64));
    let message = err.to_string();
    assert!(message.contains("6.250e-2") && message.contains("1.000e6"), "{message}");
    // Half of it collapsed: baked, with the share and the cause.
    let mut mixed = crate::procedural::sphere([0.0; 3], 1.0, 16, 24);
    let near = mixed.triangles.len();
    mixed.triangles.extend(crate::procedural::sphere([3.0e6; 3], 1e-3, 8, 12).triangles);
    let scene = bake(&mixed, &BuildParams::auto()).unwrap();
    assert_eq!(scene.triangle_ids.len(), near);
    let warning = super::degenerate_warning(&scene).expect("a warning");
    assert!(warning.contains("left out") && warning.contains('%'), "{warning}");
    // The extents in messages: zero as 0, not 0e0.
    assert_eq!(crate::error::number(0.0), "0");
}
