//! Opening a baked file from arbitrary bytes on the validated path never panics,
//! hangs or reads out of bounds; whatever opens is traced (one ray at a time and in
//! batches) and rendered small with every effect its shading data calls for
//! (`octrace_runtime::testing::exercise`).
//!
//! The first byte picks how the rest is used: odd, as a whole file; even, as an archive
//! wrapped in a correct header (so mutations get past the checksums to bytecheck and
//! the semantic rules).
#![no_main]

use glam::Vec3;
use libfuzzer_sys::fuzz_target;
use octrace_format::HEADER_LEN;
use octrace_runtime::{Ray, Scene};

fuzz_target!(|data: &[u8]| {
    let Some((&mode, rest)) = data.split_first() else { return };
    let opened = if mode & 1 == 1 {
        Scene::from_bytes(rest)
    } else {
        let header = octrace_format::testing::header_for_archive(rest);
        let mut file = Vec::with_capacity(HEADER_LEN + rest.len());
        file.extend_from_slice(&header.encode());
        file.extend_from_slice(rest);
        Scene::from_bytes(&file)
    };
    let Ok(scene) = opened else { return };
    let _ = octrace_format::stats::SceneStatistics::compute(&scene.view());
    let b = scene.view().bounds;
    let c = (Vec3::from(b.mesh_lo) + Vec3::from(b.mesh_hi)) * 0.5;
    let mut rays = Vec::new();
    for (k, d) in [Vec3::X, -Vec3::Y, Vec3::new(0.3, -0.5, 0.8), Vec3::new(-1.0, 0.0, -0.0)].into_iter().enumerate() {
        let outside = c - d * (b.root_size * 2.0);
        rays.extend([Ray::new(c, d), Ray::new(outside, d), Ray::segment(c, d, 0.0, k as f32)]);
    }
    octrace_runtime::testing::exercise(&scene, &rays);
});
