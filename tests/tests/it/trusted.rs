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
