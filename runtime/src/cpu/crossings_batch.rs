//! Every crossing of a batch of rays ([`Tracer::crossings_batch`] and the calls
//! built on it: counts, budgets, all threads): the rays walked eight at a time in AVX2
//! lanes where the processor has them (`simd::lanes_crossings`), else one by one
//! ([`Tracer::crossings`], `crossings`), their lists gathered by a sink.

use std::ops::ControlFlow;

use super::crossings::{Crossing, CrossingCount, CrossingSink, LeafCrossings};
use super::tracer::Tracer;
use crate::ray::Ray;

/// The crossings of a batch of rays, in one flat list: ray `i`'s are
/// `crossings[splits[i]..splits[i + 1]]` (`splits` has one more entry than there are
/// rays, as Open3D's `ray_splits`).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct BatchCrossings {
    /// Where each ray's crossings start in `crossings`, and the end.
    pub splits: Vec<usize>,
    /// Every ray's crossings, in ray order, each ray's in order along it.
    pub crossings: Vec<Crossing>,
}

impl BatchCrossings {
    /// Ray `i`'s crossings.
    pub fn of(&self, i: usize) -> &[Crossing] {
        &self.crossings[self.splits[i]..self.splits[i + 1]]
    }
}

/// Rays per rayon task in the parallel crossing calls.
const CHUNK: usize = 1024;

impl Tracer<'_> {
    /// Every crossing of each ray of a batch (at most `limit` a ray, the first ones),
    /// on this thread: eight walks at a time in AVX2 lanes where the processor has
    /// them, each ray's answer that of [`Tracer::crossings`], bit for bit. Memory
    /// follows the crossings found.
    ///
    /// # Example
    /// ```
    /// use octrace_bake::{bake, procedural, BuildParams};
    /// use octrace_runtime::{Ray, Scene};
    /// let scene = Scene::from_baked(bake(&procedural::sphere([0.0; 3], 1.0, 16, 24), &BuildParams::auto())?)?;
    /// let rays = [
    ///     Ray::new([-3.0, 0.1, 0.2].into(), [1.0, 0.0, 0.0].into()), // through: 2
    ///     Ray::new([0.0; 3].into(), [0.0, 1.0, 0.0].into()),        // from inside: 1
    ///     Ray::new([3.0, 3.0, 3.0].into(), [1.0, 0.0, 0.0].into()), // misses: 0
    /// ];
    /// let all = scene.tracer().crossings_batch(&rays, usize::MAX);
    /// assert_eq!(all.splits, [0, 2, 3, 3]);
    /// assert!(all.of(0)[0].enters && !all.of(1)[0].enters);
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn crossings_batch(&self, rays: &[Ray], limit: usize) -> BatchCrossings {
        let mut sink = Flat::new(rays.len());
        self.crossings_into_sink(rays, limit, &mut sink);
        sink.finish()
    }

    /// [`Tracer::crossings_batch`] on all threads of the current rayon pool.
    pub fn par_crossings_batch(&self, rays: &[Ray], limit: usize) -> BatchCrossings {
        use rayon::prelude::*;
        let parts: Vec<BatchCrossings> = rays.par_chunks(CHUNK).map(|c| self.crossings_batch(c, limit)).collect();
        let total = parts.iter().map(|p| p.crossings.len()).sum();
        joined(parts, Vec::with_capacity(rays.len() + 1), Vec::with_capacity(total))
    }

    /// [`Tracer::par_crossings_batch`] within a memory budget: the lists may take at
    /// most `max_bytes` ([`CROSSING_BYTES`] a crossing; the whole call's peak is about
    /// twice that, while the threads' lists are joined). A batch whose lists pass it
    /// stops there (each thread finishes at most the chunk of rays it walks) and
    /// answers [`Error::Budget`](crate::Error::Budget), with nothing returned; memory
    /// the allocator refuses is [`Error::Alloc`](crate::Error::Alloc), never an abort.
    ///
    /// # Example
    /// ```
    /// use octrace_bake::{bake, procedural, BuildParams};
    /// use octrace_runtime::{cpu::CROSSING_BYTES, Error, Ray, Scene};
    /// let scene = Scene::from_baked(bake(&procedural::sphere([0.0; 3], 1.0, 16, 24), &BuildParams::auto())?)?;
    /// let rays = vec![Ray::new([-3.0, 0.1, 0.2].into(), [1.0, 0.0, 0.0].into()); 100]; // 2 crossings each
    /// let all = scene.tracer().par_crossings_batch_within(&rays, usize::MAX, 200 * CROSSING_BYTES)?;
    /// assert_eq!(all.crossings.len(), 200);
    /// let refused = scene.tracer().par_crossings_batch_within(&rays, usize::MAX, 199 * CROSSING_BYTES);
    /// assert!(matches!(refused, Err(Error::Budget { what: "crossings", .. })));
    /// // The first crossing of each ray fits.
    /// let first = scene.tracer().par_crossings_batch_within(&rays, 1, 100 * CROSSING_BYTES)?;
    /// assert_eq!(first.crossings.len(), 100);
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn par_crossings_batch_within(
        &self,
        rays: &[Ray],
        limit: usize,
        max_bytes: u64,
    ) -> crate::Result<BatchCrossings> {
        use rayon::prelude::*;
        use std::sync::atomic::Ordering::Relaxed;
        use std::sync::atomic::{AtomicBool, AtomicUsize};
        let budget = Budget {
            most: usize::try_from(max_bytes / CROSSING_BYTES).unwrap_or(usize::MAX),
            listed: AtomicUsize::new(0),
            passed: AtomicBool::new(false),
        };
        let parts: Vec<BatchCrossings> = rays
            .par_chunks(CHUNK)
            .map(|c| {
                if budget.passed.load(Relaxed) {
                    return BatchCrossings::default();
                }
                let mut sink = Flat { budget: Some(&budget), ..Flat::new(c.len()) };
                self.crossings_into_sink(c, limit, &mut sink);
                sink.finish()
            })
            .collect();
        if budget.passed.load(Relaxed) {
            return Err(over_budget(budget.listed.load(Relaxed) as u64 * CROSSING_BYTES, max_bytes));
        }
        let total = parts.iter().map(|p| p.crossings.len()).sum();
        let splits = octrace_format::memory::try_with_capacity(rays.len() + 1, "crossing splits")?;
        Ok(joined(parts, splits, octrace_format::memory::try_with_capacity(total, "crossings")?))
    }

    /// The crossing count of each ray of a batch ([`Tracer::count_crossings`]), on this
    /// thread.
    pub fn count_crossings_batch(&self, rays: &[Ray], out: &mut [CrossingCount]) {
        assert_eq!(rays.len(), out.len(), "one result slot a ray");
        let mut sink = Counts(out);
        self.crossings_into_sink(rays, usize::MAX, &mut sink);
    }

    /// [`Tracer::count_crossings_batch`] on all threads of the current rayon pool.
    pub fn par_count_crossings_batch(&self, rays: &[Ray], out: &mut [CrossingCount]) {
        use rayon::prelude::*;
        assert_eq!(rays.len(), out.len(), "one result slot a ray");
        rays.par_chunks(CHUNK).zip(out.par_chunks_mut(CHUNK)).for_each(|(r, o)| self.count_crossings_batch(r, o));
    }

    /// The first `capacity` crossings of each ray of a batch into `out` (ray `i`'s at
    /// `out[i * capacity..]`), their number into `lens[i]`, and whether the ray has
    /// more (`truncated[i]`: the list was cut, never silently), on all threads.
    ///
    /// # Panics
    /// If `out` is not `rays.len() * capacity` long, or `lens` or `truncated` not
    /// `rays.len()`.
    pub fn par_crossings_into(
        &self,
        rays: &[Ray],
        capacity: usize,
        out: &mut [Crossing],
        lens: &mut [u32],
        truncated: &mut [bool],
    ) {
        use rayon::prelude::*;
        assert_eq!(out.len(), rays.len() * capacity, "capacity slots a ray");
        assert!(lens.len() == rays.len() && truncated.len() == rays.len(), "one length and flag a ray");
        let chunks = out.par_chunks_mut((CHUNK * capacity).max(1));
        let work = rays.par_chunks(CHUNK).zip(lens.par_chunks_mut(CHUNK)).zip(truncated.par_chunks_mut(CHUNK));
        if capacity == 0 {
            work.for_each(|((r, l), tr)| {
                let mut counts = vec![CrossingCount::default(); r.len()];
                self.count_crossings_batch(r, &mut counts);
                l.fill(0);
                tr.iter_mut().zip(&counts).for_each(|(t, c)| *t = c.total > 0);
            });
            return;
        }
        work.zip(chunks).for_each(|(((r, l), tr), o)| {
            let mut sink = Capped { capacity, out: o, lens: l, truncated: tr };
            // One more than fits: a ray that has it was cut.
            self.crossings_into_sink(r, capacity + 1, &mut sink);
        });
    }

    /// Every ray's first `limit` crossings into `sink`: in the lanes where the
    /// processor has them, else ray by ray.
    fn crossings_into_sink(&self, rays: &[Ray], limit: usize, sink: &mut impl CrossingSink) {
        #[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
        if self.uses_x86_64_v3() && self.uses_lanes() && super::simd::lanes::fits(self) {
            // SAFETY: the processor has the features (`uses_x86_64_v3` is never true
            // where it does not), and the arrays fit the gathers.
            return unsafe { super::simd::lanes_crossings::trace(self, rays, limit, sink) };
        }
        let (mut buffer, mut list) = (LeafCrossings::default(), Vec::new());
        for (i, r) in rays.iter().enumerate() {
            list.clear();
            if limit > 0 {
                self.crossings_with(r, &mut buffer, |c| {
                    list.push(c);
                    if list.len() >= limit {
                        ControlFlow::Break(())
                    } else {
                        ControlFlow::Continue(())
                    }
                });
            }
            sink.ray(i, &list);
        }
    }
}

/// The chunks' lists `parts`, in order, joined into one list, in `splits` and
/// `crossings` (empty, with room made for the rays' splits and every crossing).
fn joined(parts: Vec<BatchCrossings>, mut splits: Vec<usize>, mut crossings: Vec<Crossing>) -> BatchCrossings {
    splits.push(0);
    for p in parts {
        let base = crossings.len();
        splits.extend(p.splits[1..].iter().map(|s| s + base));
        crossings.extend(p.crossings);
    }
    BatchCrossings { splits, crossings }
}

/// A batch's lists past their budget: `needed` bytes at least, `limit` allowed.
pub(crate) fn over_budget(needed: u64, limit: u64) -> crate::Error {
    crate::Error::Budget {
        what: "crossings",
        needed,
        limit,
        advice: "keep fewer a ray (max_hits, --max-hits), trace fewer rays a call, or raise the budget",
    }
}

/// Bytes a listed crossing takes in a [`BatchCrossings`]: the unit of
/// [`Tracer::par_crossings_batch_within`]'s budget.
pub const CROSSING_BYTES: u64 = std::mem::size_of::<Crossing>() as u64;

/// Crossings every thread of a batch may list together, and how many they have.
struct Budget {
    most: usize,
    listed: std::sync::atomic::AtomicUsize,
    /// Set once `listed` passes `most`: lists stop being kept.
    passed: std::sync::atomic::AtomicBool,
}

/// Lists in one flat array, in ray order (rays finish out of order in the lanes: each
/// list is kept where it arrived, and placed once all have).
#[derive(Default)]
struct Flat<'a> {
    /// Each ray's count and where its list arrived in `arrived`.
    placed: Vec<(usize, usize)>,
    arrived: Vec<Crossing>,
    /// The batch's budget, shared by its threads, if it has one.
    budget: Option<&'a Budget>,
}

impl CrossingSink for Flat<'_> {
    fn ray(&mut self, index: usize, crossings: &[Crossing]) {
        use std::sync::atomic::Ordering::Relaxed;
        if let Some(b) = self.budget {
            if b.passed.load(Relaxed) || b.listed.fetch_add(crossings.len(), Relaxed) + crossings.len() > b.most {
                b.passed.store(true, Relaxed);
                return;
            }
        }
        self.placed[index] = (crossings.len(), self.arrived.len());
        self.arrived.extend_from_slice(crossings);
    }
}

impl Flat<'_> {
    fn new(rays: usize) -> Flat<'static> {
        Flat { placed: vec![(0, 0); rays], arrived: Vec::new(), budget: None }
    }

    fn finish(self) -> BatchCrossings {
        let mut splits = Vec::with_capacity(self.placed.len() + 1);
        let mut crossings = Vec::with_capacity(self.arrived.len());
        splits.push(0);
        for &(n, at) in &self.placed {
            crossings.extend_from_slice(&self.arrived[at..at + n]);
            splits.push(crossings.len());
        }
        BatchCrossings { splits, crossings }
    }
}

/// Counts alone.
struct Counts<'a>(&'a mut [CrossingCount]);

impl CrossingSink for Counts<'_> {
    fn ray(&mut self, index: usize, crossings: &[Crossing]) {
        let entries = crossings.iter().filter(|c| c.enters).count() as u32;
        self.0[index] = CrossingCount { total: crossings.len() as u32, entries };
    }
}

/// The first `capacity` of each ray into fixed slots.
struct Capped<'a> {
    capacity: usize,
    out: &'a mut [Crossing],
    lens: &'a mut [u32],
    truncated: &'a mut [bool],
}

impl CrossingSink for Capped<'_> {
    fn ray(&mut self, index: usize, crossings: &[Crossing]) {
        let n = crossings.len().min(self.capacity);
        self.out[index * self.capacity..][..n].copy_from_slice(&crossings[..n]);
        self.lens[index] = n as u32;
        self.truncated[index] = crossings.len() > self.capacity;
    }
}
