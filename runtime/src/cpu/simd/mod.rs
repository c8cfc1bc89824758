//! SIMD forms of the octree step, one file per instruction set, chosen at compile
//! time; the scalar step in `traverse.rs` is the portable fallback and the reference
//! the SIMD forms are tested against (bit for bit: the same operations in the same
//! order, no fused multiply-adds).
//!
//! All of the runtime's `unsafe` lives in this folder.

#[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
pub(crate) mod sse2;
