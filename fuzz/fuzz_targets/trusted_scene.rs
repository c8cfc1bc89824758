//! The trusted path on semantically broken files never panics, hangs or reads out of
//! bounds: a valid scene (a small torus with shading data, baked once) has its
//! semantic fields changed as the input's bytes say (`testing::mutate_semantics`),
//! is serialized with correct checksums (a sound archive), written to a file of this
//! process, memory-mapped without validation (`Scene::map_unchecked`) and traced one
//! ray at a time and in batches, then rendered small.
#![no_main]

use std::sync::OnceLock;

use glam::Vec3;
use libfuzzer_sys::fuzz_target;
use octrace_bake::{bake, procedural, BuildParams};
use octrace_format::BakedScene;
use octrace_runtime::{Ray, Scene};

fn base() -> &'static BakedScene {
    static BASE: OnceLock<BakedScene> = OnceLock::new();
    BASE.get_or_init(|| {
        let mesh = procedural::shaded_torus(12, 6);
        bake(&mesh, &BuildParams { max_depth: Some(4), leaf_size: Some(4), ..BuildParams::auto() }).unwrap()
    })
}

fuzz_target!(|data: &[u8]| {
    // The input is the random source: eight bytes a draw, zeros once it runs out.
    let mut words = data.chunks(8).map(|c| {
        let mut w = [0u8; 8];
        w[..c.len()].copy_from_slice(c);
        u64::from_le_bytes(w)
    });
    let mut next = move || words.next().unwrap_or(0);
    let mut s = base().clone();
    octrace_format::testing::mutate_semantics(&mut s, &mut next);
    let path = std::env::temp_dir().join(format!("octrace-fuzz-{}.oct", std::process::id()));
    if s.write(&path, 0).is_err() {
        return;
    }
    // SAFETY: this process's own file, rewritten only by the next input, after this
    // scene (and its map) is dropped.
    let Ok(scene) = (unsafe { Scene::map_unchecked(&path) }) else { return };
    let mut rays = Vec::new();
    for (k, d) in [Vec3::X, -Vec3::Y, Vec3::new(0.3, -0.5, 0.8), Vec3::new(-1.0, 0.0, -0.0), Vec3::new(0.0, -0.0, 1.0)]
        .into_iter()
        .enumerate()
    {
        let inside = Vec3::new(0.5, 0.1, -0.2) * (k as f32 - 2.0);
        rays.extend([Ray::new(inside, d), Ray::new(inside - d * 5.0, d), Ray::segment(inside, d, 0.0, k as f32)]);
    }
    octrace_runtime::testing::exercise(&scene, &rays);
});
