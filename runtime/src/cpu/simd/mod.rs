//! SIMD forms of the octree step: `sse2` (every x86-64 processor; the step, chosen
//! at compile time) and `avx2` (the watertight test on eight triangles at once,
//! which the step's x86-64-v3 build uses, chosen at run time). The scalar step in
//! `traverse.rs` is the portable fallback and the reference the SIMD forms are
//! tested against (bit for bit: the same operations in the same order, no fused
//! multiply-adds).
//!
//! All of the runtime's `unsafe` lives in this folder.

#[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
pub(crate) mod sse2;

#[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
pub(crate) mod avx2;

#[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
pub(crate) mod lanes;
