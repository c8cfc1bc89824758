//! The batch calls: many rays walked on one thread with several in flight (their
//! memory loads overlap), or on all threads of the rayon pool; incoherent batches in
//! memory order (`order.rs`).

use rayon::prelude::*;

use super::order::memory_order;
#[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
use super::simd;
use super::tracer::{with_tests, NoTally, Tracer};
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
    use super::Tracer;
    use crate::cpu::tracer::Tally;
    pub(super) use crate::cpu::walk::RayWalk as Walk;
    pub(super) fn to_walk(_: &Tracer<'_>, w: &Walk) -> Walk {
        w.clone()
    }
    /// The scalar step reads the tests from the tracer: `TEST` and `SLAB` serve the
    /// SIMD steps' signature only.
    #[inline(always)]
    pub(super) fn step<const ANY: bool, const TEST: u8, const SLAB: bool>(
        t: &Tracer<'_>,
        w: &mut Walk,
        s: &mut impl Tally,
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
    /// Nearest hits of a batch, on this thread (several rays in flight, interleaved;
    /// an incoherent batch in memory order, [`Tracer::with_memory_order`]).
    pub fn intersect_batch(&self, rays: &[Ray], out: &mut [Option<Hit>]) {
        assert_eq!(rays.len(), out.len(), "one result slot a ray");
        self.in_memory_order(rays, out, |r, o| self.nearest_as_given(r, o));
    }

    /// [`Tracer::intersect_batch`] in the order given.
    fn nearest_as_given(&self, rays: &[Ray], out: &mut [Option<Hit>]) {
        let done = |i: usize, h: Option<Hit>| out[i] = h;
        with_tests!(self; false; Self::interleaved; self, rays, done);
    }

    /// [`Tracer::occluder_batch`] in the order given.
    fn any_as_given(&self, rays: &[Ray], out: &mut [Option<Hit>]) {
        let done = |i: usize, h: Option<Hit>| out[i] = h;
        with_tests!(self; true; Self::interleaved; self, rays, done);
    }

    /// [`Tracer::occluded_batch`] in the order given.
    fn occluded_as_given(&self, rays: &[Ray], out: &mut [bool]) {
        let done = |i: usize, h: Option<Hit>| out[i] = h.is_some();
        with_tests!(self; true; Self::interleaved; self, rays, done);
    }

    /// The order the batch calls walk `rays` in, as indices into `rays`, or `None`
    /// where they walk them as given ([`MemoryOrder`](crate::MemoryOrder) says when): rays sorted by the
    /// cell of a 64^3 grid over the scene that their origin lies in (Morton order),
    /// then by their direction's octant. For callers who want the same locality
    /// elsewhere: to shade hits in that order, or to hand another tracer the same rays
    /// in the same order.
    ///
    /// # Example
    /// ```
    /// use octrace_bake::{bake, procedural, BuildParams};
    /// use octrace_runtime::{MemoryOrder, Ray, Scene};
    /// let scene = Scene::from_baked(bake(&procedural::sphere([0.0; 3], 1.0, 16, 24), &BuildParams::auto())?)?;
    /// let mut rng = procedural::SplitMix(1);
    /// let mut unit = || 2.0 * rng.unit() - 1.0;
    /// let rays: Vec<Ray> =
    ///     (0..10_000).map(|_| Ray::new([unit(), unit(), unit()].into(), [unit(), unit(), unit()].into())).collect();
    /// // A small scene stays in the cache: walked as given, unless asked.
    /// assert!(scene.tracer().memory_order(&rays).is_none());
    /// let tracer = scene.tracer().with_memory_order(MemoryOrder::Incoherent);
    /// let mut order = tracer.memory_order(&rays).expect("random rays are reordered");
    /// order.sort_unstable();
    /// assert!(order.iter().enumerate().all(|(i, &j)| j as usize == i)); // a permutation
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn memory_order(&self, rays: &[Ray]) -> Option<Vec<u32>> {
        memory_order(self, rays, self.memory_order)
    }

    /// Runs `walk` (a batch call in the order given) on `rays`, sorted into memory
    /// order first where `order.rs` says it pays, each answer put back in its ray's
    /// slot.
    fn in_memory_order<T: Copy + Default + Send>(
        &self,
        rays: &[Ray],
        out: &mut [T],
        walk: impl FnOnce(&[Ray], &mut [T]),
    ) {
        let Some(order) = self.memory_order(rays) else { return walk(rays, out) };
        let sorted: Vec<Ray> = order.iter().map(|&i| rays[i as usize]).collect();
        let mut answers = vec![T::default(); rays.len()];
        walk(&sorted, &mut answers);
        for (&i, answer) in order.iter().zip(answers) {
            out[i as usize] = answer;
        }
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
        let mut stats = NoTally;
        let mut next = 0;
        let mut slots: [Option<(usize, Walk)>; IN_FLIGHT] =
            std::array::from_fn(|_| self.start_next::<ANY>(rays, &mut next, &mut done));
        let mut active = slots.iter().filter(|s| s.is_some()).count();
        while active > 0 {
            for slot in slots.iter_mut() {
                let Some((i, w)) = slot else { continue };
                if step::<ANY, TEST, SLAB>(self, w, &mut stats) {
                    done(*i, self.answer(w.best));
                    *slot = self.start_next::<ANY>(rays, &mut next, &mut done);
                    active -= slot.is_none() as usize;
                }
            }
        }
    }

    /// The next ray from `rays[*next..]` that needs a walk, and its walk; rays that
    /// cannot hit are answered at once, and so are those only the scalar step walks
    /// (the exact exit rule, re-originated rays: walked to their end here).
    #[inline(always)]
    fn start_next<const ANY: bool>(
        &self,
        rays: &[Ray],
        next: &mut usize,
        done: &mut impl FnMut(usize, Option<Hit>),
    ) -> Option<(usize, Walk)> {
        while *next < rays.len() {
            let i = *next;
            *next += 1;
            match self.begin(&rays[i]) {
                Some(w) if w.scalar_only() => done(i, self.walk_scalar::<ANY>(w, &mut NoTally)),
                Some(w) => return Some((i, to_walk(self, &w))),
                None => done(i, None),
            }
        }
        None
    }

    /// Nearest hits of a batch, on all threads of the current rayon pool.
    pub fn par_intersect_batch(&self, rays: &[Ray], out: &mut [Option<Hit>]) {
        assert_eq!(rays.len(), out.len(), "one result slot a ray");
        self.in_memory_order(rays, out, |r, o| self.in_parallel(r, o, Self::nearest_as_given));
    }

    /// Occlusion of a batch, on this thread (several rays in flight, interleaved).
    pub fn occluded_batch(&self, rays: &[Ray], out: &mut [bool]) {
        assert_eq!(rays.len(), out.len(), "one result slot a ray");
        self.in_memory_order(rays, out, |r, o| self.occluded_as_given(r, o));
    }

    /// Occlusion of a batch, on all threads of the current rayon pool.
    pub fn par_occluded_batch(&self, rays: &[Ray], out: &mut [bool]) {
        assert_eq!(rays.len(), out.len(), "one result slot a ray");
        self.in_memory_order(rays, out, |r, o| self.in_parallel(r, o, Self::occluded_as_given));
    }

    /// For each ray of a batch, a hit that occludes it ([`Tracer::occluder`]'s, the
    /// same triangle and distance), or `None`: the batch walk of
    /// [`Tracer::occluded_batch`], keeping the hit.
    pub fn occluder_batch(&self, rays: &[Ray], out: &mut [Option<Hit>]) {
        assert_eq!(rays.len(), out.len(), "one result slot a ray");
        self.in_memory_order(rays, out, |r, o| self.any_as_given(r, o));
    }

    /// [`Tracer::occluder_batch`] on all threads of the current rayon pool.
    pub fn par_occluder_batch(&self, rays: &[Ray], out: &mut [Option<Hit>]) {
        assert_eq!(rays.len(), out.len(), "one result slot a ray");
        self.in_memory_order(rays, out, |r, o| self.in_parallel(r, o, Self::any_as_given));
    }

    /// `walk` on chunks of the batch, on all threads of the current rayon pool.
    fn in_parallel<T: Send>(&self, rays: &[Ray], out: &mut [T], walk: fn(&Self, &[Ray], &mut [T])) {
        rays.par_chunks(CHUNK).zip(out.par_chunks_mut(CHUNK)).for_each(|(r, o)| walk(self, r, o));
    }
}
