//! The batch calls: many rays walked on one thread with several in flight (their
//! memory loads overlap), or on all threads of the rayon pool.

use rayon::prelude::*;

use super::simd;
use super::tracer::{with_tests, Tracer, WalkStats};
use crate::ray::{Hit, Ray};

/// Rays per rayon task in the parallel batch calls: large enough to amortise the
/// task, small enough to balance two cores on uneven rays.
const CHUNK: usize = 1024;

/// The walk state and step of the batch calls: SSE2 where the build has it.
#[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
use simd::sse2::{begin as to_walk, step_safe as step, SseWalk as Walk};

#[cfg(not(all(target_arch = "x86_64", target_feature = "sse2")))]
use scalar_batch::{step, to_walk, Walk};

#[cfg(not(all(target_arch = "x86_64", target_feature = "sse2")))]
mod scalar_batch {
    pub(super) use super::walk::RayWalk as Walk;
    use super::{Tracer, WalkStats};
    pub(super) fn to_walk(_: &Tracer<'_>, w: &Walk) -> Walk {
        w.clone()
    }
    /// The scalar step reads the tests from the tracer: `TEST` and `SLAB` serve the
    /// SIMD steps' signature only.
    #[inline(always)]
    pub(super) fn step<const ANY: bool, const TEST: u8, const SLAB: bool>(
        t: &Tracer<'_>,
        w: &mut Walk,
        s: &mut WalkStats,
    ) -> bool {
        t.step::<ANY>(w, s)
    }
}

/// Rays in flight at once in the batch calls' one-at-a-time loop (the lanes of
/// `simd::lanes` keep sixteen). A walk is a chain of dependent loads (each leaf's
/// record gives the next address), so one ray leaves the core waiting on memory;
/// stepping several rays in turn lets their loads overlap.
const IN_FLIGHT: usize = 8;

impl Tracer<'_> {
    /// Nearest hits of a batch, on this thread (several rays in flight, interleaved).
    pub fn intersect_batch(&self, rays: &[Ray], out: &mut [Option<Hit>]) {
        assert_eq!(rays.len(), out.len(), "one result slot a ray");
        let done = |i: usize, h: Option<Hit>| out[i] = h;
        with_tests!(self; false; Self::interleaved; self, rays, done);
    }

    /// Walks `rays` with up to [`IN_FLIGHT`] in progress, one step each in turn;
    /// `done(i, answer)` receives each ray's answer. Where the processor has AVX2,
    /// sixteen walks step eight at a time in the lanes of vector registers
    /// (`simd::lanes`; the same operations, so the same bits): 1.4-1.6x on primary
    /// and shadow rays (BENCHMARKS.md, "Tracing"). The slab exit test, a
    /// measuring knob, keeps the one-walk-at-a-time loop, compiled for x86-64-v3
    /// there (VEX encodings, three-operand forms: 15-35 % faster than the
    /// baseline's).
    fn interleaved<const ANY: bool, const TEST: u8, const SLAB: bool>(
        &self,
        rays: &[Ray],
        done: impl FnMut(usize, Option<Hit>),
    ) {
        #[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
        if self.uses_x86_64_v3() {
            if !SLAB && self.uses_lanes() && simd::lanes::fits(self) {
                // SAFETY: the processor has the features (as below), and the arrays
                // fit the gathers.
                return unsafe { simd::lanes::trace::<ANY, TEST>(self, rays, done) };
            }
            // SAFETY: the processor has these features (`uses_x86_64_v3` is never
            // true where it does not).
            return unsafe { self.interleaved_v3::<ANY, TEST, SLAB>(rays, done) };
        }
        self.interleaved_loop::<ANY, TEST, SLAB>(rays, done)
    }

    /// [`Tracer::interleaved_loop`] compiled for x86-64-v3 (AVX2, FMA, BMI; the
    /// same list as `simd::sse2::walk_v3`). FMA is only allowed, never implied: Rust
    /// does not fuse `a * b + c`, so every result keeps its bits. AVX-512 (x86-64-v4)
    /// was measured too and bought nothing more.
    ///
    /// # Safety
    /// The processor must have the features.
    #[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
    #[target_feature(enable = "avx2,bmi1,bmi2,fma,lzcnt,popcnt")]
    unsafe fn interleaved_v3<const ANY: bool, const TEST: u8, const SLAB: bool>(
        &self,
        rays: &[Ray],
        done: impl FnMut(usize, Option<Hit>),
    ) {
        self.interleaved_loop::<ANY, TEST, SLAB>(rays, done)
    }

    #[inline(always)]
    fn interleaved_loop<const ANY: bool, const TEST: u8, const SLAB: bool>(
        &self,
        rays: &[Ray],
        mut done: impl FnMut(usize, Option<Hit>),
    ) {
        let mut stats = WalkStats::default();
        let mut next = 0;
        let mut slots: [Option<(usize, Walk)>; IN_FLIGHT] =
            std::array::from_fn(|_| self.start_next(rays, &mut next, &mut done));
        let mut active = slots.iter().filter(|s| s.is_some()).count();
        while active > 0 {
            for slot in slots.iter_mut() {
                let Some((i, w)) = slot else { continue };
                if step::<ANY, TEST, SLAB>(self, w, &mut stats) {
                    done(*i, self.answer(w.best));
                    *slot = self.start_next(rays, &mut next, &mut done);
                    active -= slot.is_none() as usize;
                }
            }
        }
    }

    /// The next ray from `rays[*next..]` that needs a walk, and its walk; rays that
    /// cannot hit are answered at once.
    #[inline(always)]
    fn start_next(
        &self,
        rays: &[Ray],
        next: &mut usize,
        done: &mut impl FnMut(usize, Option<Hit>),
    ) -> Option<(usize, Walk)> {
        while *next < rays.len() {
            let i = *next;
            *next += 1;
            match self.begin(&rays[i]) {
                Some(w) => return Some((i, to_walk(self, &w))),
                None => done(i, None),
            }
        }
        None
    }

    /// Nearest hits of a batch, on all threads of the current rayon pool.
    pub fn par_intersect_batch(&self, rays: &[Ray], out: &mut [Option<Hit>]) {
        assert_eq!(rays.len(), out.len(), "one result slot a ray");
        rays.par_chunks(CHUNK).zip(out.par_chunks_mut(CHUNK)).for_each(|(r, o)| self.intersect_batch(r, o));
    }

    /// Occlusion of a batch, on this thread (several rays in flight, interleaved).
    pub fn occluded_batch(&self, rays: &[Ray], out: &mut [bool]) {
        assert_eq!(rays.len(), out.len(), "one result slot a ray");
        let done = |i: usize, h: Option<Hit>| out[i] = h.is_some();
        with_tests!(self; true; Self::interleaved; self, rays, done);
    }

    /// Occlusion of a batch, on all threads of the current rayon pool.
    pub fn par_occluded_batch(&self, rays: &[Ray], out: &mut [bool]) {
        assert_eq!(rays.len(), out.len(), "one result slot a ray");
        rays.par_chunks(CHUNK).zip(out.par_chunks_mut(CHUNK)).for_each(|(r, o)| self.occluded_batch(r, o));
    }

    /// For each ray of a batch, a hit that occludes it ([`Tracer::occluder`]'s, the
    /// same triangle and distance), or `None`: the batch walk of
    /// [`Tracer::occluded_batch`], keeping the hit.
    pub fn occluder_batch(&self, rays: &[Ray], out: &mut [Option<Hit>]) {
        assert_eq!(rays.len(), out.len(), "one result slot a ray");
        let done = |i: usize, h: Option<Hit>| out[i] = h;
        with_tests!(self; true; Self::interleaved; self, rays, done);
    }

    /// [`Tracer::occluder_batch`] on all threads of the current rayon pool.
    pub fn par_occluder_batch(&self, rays: &[Ray], out: &mut [Option<Hit>]) {
        assert_eq!(rays.len(), out.len(), "one result slot a ray");
        rays.par_chunks(CHUNK).zip(out.par_chunks_mut(CHUNK)).for_each(|(r, o)| self.occluder_batch(r, o));
    }
}
