//! The trusted path (`Scene::map_unchecked`) on files that break the format's semantic
//! rules but whose archive is sound (a scene serialized as it is, checksums right):
//! every walk ends, with some answer, never a panic or an out-of-bounds read. This is
//! what FORMAT.md and the `# Safety` docs promise; a fuzz target does the same at
//! length (`fuzz/fuzz_targets/trusted_scene.rs`).

use glam::Vec3;
use octrace_bake::procedural::SplitMix;
use octrace_runtime::{Ray, Scene};

/// Rays through the scene, from outside and inside, axis-aligned with both zeros too.
fn rays(rng: &mut SplitMix) -> Vec<Ray> {
    let mut out = Vec::new();
    for k in 0..24 {
        let d = match k % 4 {
            0 => Vec3::new(rng.unit() - 0.5, rng.unit() - 0.5, rng.unit() - 0.5),
            1 => Vec3::new(0.0, -0.0, 1.0),
            2 => Vec3::new(-1.0, 0.0, -0.0),
            _ => Vec3::new(0.3, 1.0, 0.0),
        };
        let o =
            if k % 2 == 0 { Vec3::new(rng.unit(), rng.unit(), rng.unit()) * 0.6 } else { -d * 5.0 + Vec3::splat(0.1) };
        out.push(Ray::segment(o, d, 0.0, f32::INFINITY));
    }
    out
}

#[test]
fn semantically_broken_files_on_the_trusted_path_never_panic_or_hang() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("broken.oct");
    let original = octrace_tests::torus_scene();
    let seed = std::env::var("OCTRACE_TRUSTED_SEED").ok().and_then(|n| n.parse().ok()).unwrap_or(2026);
    let mut rng = SplitMix(seed);
    let mut failures = Vec::new();
    let mut refused = 0;
    // OCTRACE_TRUSTED_CASES runs more (the fuzz target runs for minutes).
    let cases = std::env::var("OCTRACE_TRUSTED_CASES").ok().and_then(|n| n.parse().ok()).unwrap_or(2000);
    for case in 0..cases {
        let mut s = original.clone();
        octrace_format::testing::mutate_semantics(&mut s, &mut || rng.next_u64());
        s.write(&path, 0).unwrap();
        if Scene::open(&path).is_err() {
            refused += 1;
        }
        let rays = rays(&mut rng);
        let traced = std::panic::catch_unwind(|| {
            // SAFETY: this test's own file, not changed while mapped; its archive is
            // sound (a scene serialized as it is), which is all the trusted path needs.
            let Ok(scene) = (unsafe { Scene::map_unchecked(&path) }) else { return };
            octrace_runtime::testing::exercise(&scene, &rays);
        });
        if let Err(panic) = traced {
            let why =
                panic.downcast_ref::<String>().cloned().or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string()));
            failures.push(format!("case {case}: {}", why.unwrap_or_default()));
        }
    }
    eprintln!(
        "{refused} of {cases} mutated files refused by validation; {} panicked on the trusted path",
        failures.len()
    );
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// The arrays of `b` that differ from `a`'s, by name.
fn changed(a: &octrace_format::BakedScene, b: &octrace_format::BakedScene) -> Vec<&'static str> {
    let mut out = Vec::new();
    let mut check = |name, same: bool| {
        if !same {
            out.push(name)
        }
    };
    check("octree", a.octree == b.octree);
    check("tri_refs", a.tri_refs == b.tri_refs);
    check("triangles", a.triangles.iter().map(|f| f.to_bits()).eq(b.triangles.iter().map(|f| f.to_bits())));
    check("triangle_ids", a.triangle_ids == b.triangle_ids);
    check("boxes", a.boxes.iter().map(|f| f.to_bits()).eq(b.boxes.iter().map(|f| f.to_bits())));
    check("cube_map", a.cube_map == b.cube_map);
    check("nodes", a.nodes == b.nodes && a.root == b.root);
    check("params", a.params == b.params);
    check("bounds", a.bounds == b.bounds);
    out
}

/// A mutation run like the audit's (issue 33): mutated files the validated open
/// accepts answer as the f64 oracle does on their own stored triangles, except where
/// validation cannot see the change: a triangle moved (or a reference swapped) such
/// that a leaf no longer lists a triangle that overlaps it, which only redoing the
/// bake's exact overlap tests would find. The run counts those; every other accepted
/// mutant must answer right. `OCTRACE_MUTANTS` runs more (the audit ran 2,231).
#[test]
fn mutants_the_validated_open_accepts_answer_right_or_moved_geometry() {
    let original = octrace_tests::torus_scene();
    let mutants = std::env::var("OCTRACE_MUTANTS").ok().and_then(|n| n.parse().ok()).unwrap_or(400);
    let mut rng = SplitMix(33);
    let (mut refused, mut accepted, mut unseen) = (0, 0, Vec::new());
    let mut wrong = Vec::new();
    for case in 0..mutants {
        let mut s = original.clone();
        octrace_format::testing::mutate_semantics(&mut s, &mut || rng.next_u64());
        let Ok(bytes) = s.to_file_bytes(0) else { continue };
        let Ok(scene) = Scene::from_bytes(&bytes) else {
            refused += 1;
            continue;
        };
        accepted += 1;
        let oracle = octrace_runtime::reference::Reference::from_view(&scene.view());
        let mut rays = rays(&mut rng);
        rays.extend((0..200).map(|_| {
            let o = Vec3::new(rng.unit(), rng.unit(), rng.unit()) * 3.0 - 1.5;
            Ray::new(o, Vec3::new(rng.unit(), rng.unit(), rng.unit()) - 0.5)
        }));
        let tracer = scene.tracer();
        let bad = rays
            .iter()
            .filter(|r| {
                let h = tracer.intersect(r).map(|h| (h.t, h.triangle, h.u, h.v));
                oracle.compare(r, h) == octrace_runtime::reference::Agreement::Different
            })
            .count();
        if bad > 0 {
            let what = changed(&original, &s);
            if what.iter().any(|w| matches!(*w, "triangles" | "tri_refs")) {
                unseen.push(format!("case {case}: {what:?}, {bad} rays"));
            } else {
                wrong.push(format!("case {case}: {what:?}, {bad} rays"));
            }
        }
    }
    eprintln!(
        "{mutants} mutants: {refused} refused, {accepted} accepted; {} accepted answering wrong where validation \
         cannot see (moved triangles, swapped references): {unseen:?}",
        unseen.len()
    );
    assert!(refused > accepted / 4, "{refused} refused, {accepted} accepted");
    assert!(wrong.is_empty(), "accepted and wrong:\n{}", wrong.join("\n"));
}
