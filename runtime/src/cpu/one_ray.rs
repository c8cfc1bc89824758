//! The one-ray calls: one walk, on the SIMD step where the build has one.

#[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
use super::tracer::with_tests;
use super::tracer::{Tracer, WalkStats};
use crate::ray::{Hit, Ray};

impl Tracer<'_> {
    /// The nearest hit in `[tmin, tmax]`, if any.
    pub fn intersect(&self, ray: &Ray) -> Option<Hit> {
        self.walk::<false>(ray, &mut WalkStats::default())
    }

    /// [`Tracer::intersect`] on the portable scalar step, whatever SIMD the build
    /// has: the reference the SIMD steps are tested against.
    pub fn intersect_scalar(&self, ray: &Ray) -> Option<Hit> {
        let mut w = self.begin(ray)?;
        while !self.step::<false>(&mut w, &mut WalkStats::default()) {}
        self.answer(w.best)
    }

    /// [`Tracer::occluded`] on the portable scalar step.
    pub fn occluded_scalar(&self, ray: &Ray) -> bool {
        let Some(mut w) = self.begin(ray) else { return false };
        while !self.step::<true>(&mut w, &mut WalkStats::default()) {}
        w.best.is_some()
    }

    /// Whether anything is hit in `[tmin, tmax]`; stops at the first hit found.
    pub fn occluded(&self, ray: &Ray) -> bool {
        self.walk::<true>(ray, &mut WalkStats::default()).is_some()
    }

    /// Some hit in `[tmin, tmax]` (not necessarily the nearest): the occluder that
    /// [`Tracer::occluded`] found.
    pub fn occluder(&self, ray: &Ray) -> Option<Hit> {
        self.walk::<true>(ray, &mut WalkStats::default())
    }

    /// [`Tracer::intersect`], counting what the walk did.
    pub fn intersect_with_stats(&self, ray: &Ray) -> (Option<Hit>, WalkStats) {
        let mut stats = WalkStats::default();
        (self.walk::<false>(ray, &mut stats), stats)
    }

    /// Any hit for `ANY`, else the nearest: on the SIMD step where the build has one.
    fn walk<const ANY: bool>(&self, ray: &Ray, stats: &mut WalkStats) -> Option<Hit> {
        let w = self.begin(ray)?;
        #[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
        return with_tests!(self; ANY; super::simd::sse2::walk; self, &w, stats);
        #[cfg(not(all(target_arch = "x86_64", target_feature = "sse2")))]
        {
            let mut w = w;
            while !self.step::<ANY>(&mut w, stats) {}
            self.answer(w.best)
        }
    }
}
