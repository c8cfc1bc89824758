//! SIMD forms of the octree step: `sse2` (every x86-64 processor; the step, chosen
//! at compile time), `avx2` (the watertight test on eight triangles at once,
//! which the step's x86-64-v3 build uses, chosen at run time), `lanes` (eight walks
//! stepped at once in AVX2 lanes, for batches) and `begin8` (the lanes' walks begun
//! eight at a time: clips and point location). The scalar step in
//! `walk.rs` is the portable fallback and the reference the SIMD forms are
//! tested against (bit for bit: the same operations in the same order, no fused
//! multiply-adds).
//!
//! These modules use the walk (`tracer`, `walk`) and `hw`'s primitives; nothing
//! beneath them uses these. The runtime's `unsafe` is here, in `hw.rs` (prefetch,
//! the SSE2 clip) and in `scene.rs` (the shared tracer's borrow).

#[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
pub(crate) mod sse2;

#[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
pub(crate) mod avx2;

#[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
pub(crate) mod begin8;

#[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
pub(crate) mod lanes;

#[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
pub(crate) mod lanes_crossings;
