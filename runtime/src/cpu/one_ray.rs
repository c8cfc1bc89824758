//! The one-ray calls: one walk, on the SIMD step where the build has one.

#[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
use super::tracer::with_tests;
use super::tracer::{NoTally, Tally, Tracer, WalkStats};
use super::walk::RayWalk;
use crate::ray::{Hit, Ray};
use octrace_format::layout::LEAF_HEADER_WORDS;

impl Tracer<'_> {
    /// The nearest hit in `[tmin, tmax]`, if any.
    pub fn intersect(&self, ray: &Ray) -> Option<Hit> {
        self.walk::<false>(ray, &mut NoTally)
    }

    /// [`Tracer::intersect`] on the portable scalar step, whatever SIMD the build
    /// has: the reference the SIMD steps are tested against.
    pub fn intersect_scalar(&self, ray: &Ray) -> Option<Hit> {
        self.walk_scalar::<false>(self.begin(ray)?, &mut NoTally)
    }

    /// [`Tracer::occluded`] on the portable scalar step.
    pub fn occluded_scalar(&self, ray: &Ray) -> bool {
        let Some(mut w) = self.begin(ray) else { return false };
        while !self.step::<true>(&mut w, &mut NoTally) {}
        w.best.is_some()
    }

    /// Whether anything is hit in `[tmin, tmax]`; stops at the first hit found.
    pub fn occluded(&self, ray: &Ray) -> bool {
        self.walk::<true>(ray, &mut NoTally).is_some()
    }

    /// Some hit in `[tmin, tmax]` (not necessarily the nearest): the occluder that
    /// [`Tracer::occluded`] found.
    pub fn occluder(&self, ray: &Ray) -> Option<Hit> {
        self.walk::<true>(ray, &mut NoTally)
    }

    /// [`Tracer::intersect`], counting what the walk did.
    pub fn intersect_with_stats(&self, ray: &Ray) -> (Option<Hit>, WalkStats) {
        let mut stats = WalkStats::default();
        (self.walk::<false>(ray, &mut stats), stats)
    }

    /// The leaves the walk for [`Tracer::intersect`] visits, in order, each named by
    /// its box index (as [`Hit::leaf`] names the leaf of a hit): the same leaves
    /// whichever walk traces the ray (one-ray, batch, SIMD or scalar; the tests
    /// check their answers bit for bit). For tools and statistics: which cells a ray
    /// crosses, how often the rays of a tile stand in the same leaf. Empty for a ray
    /// that cannot hit (it misses the scene's box, or is not traceable).
    ///
    /// # Example
    /// ```
    /// use octrace_bake::{bake, procedural, BuildParams};
    /// use octrace_runtime::{Ray, Scene};
    /// let scene = Scene::from_baked(bake(&procedural::sphere([0.0; 3], 1.0, 16, 24), &BuildParams::auto())?)?;
    /// let tracer = scene.tracer();
    /// let ray = Ray::new([-3.0, 0.1, 0.2].into(), [1.0, 0.0, 0.0].into());
    /// let leaves = tracer.leaves_visited(&ray);
    /// let hit = tracer.intersect(&ray).expect("the ray meets the sphere");
    /// assert!(leaves.contains(&hit.leaf)); // found in a leaf the walk visited
    /// assert_eq!(leaves.len() as u32, tracer.intersect_with_stats(&ray).1.leaves);
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn leaves_visited(&self, ray: &Ray) -> Vec<u32> {
        let mut leaves = Vec::new();
        let Some(mut w) = self.begin(ray) else { return leaves };
        let mut stats = WalkStats::default();
        loop {
            let a = w.address() as usize;
            // The record's box index (a hostile file's link past the array: the step
            // ends the walk there, and no leaf is named).
            if let Some(&box_index) = self.view().octree.get(a..a + LEAF_HEADER_WORDS).and_then(|r| r.get(2)) {
                leaves.push(box_index);
            }
            if self.step::<false>(&mut w, &mut stats) {
                return leaves;
            }
        }
    }

    /// Any hit for `ANY`, else the nearest: on the SIMD step where the build has one
    /// (rays under the exact exit rule on the scalar step, which alone follows it).
    fn walk<const ANY: bool>(&self, ray: &Ray, stats: &mut impl Tally) -> Option<Hit> {
        let w = self.begin(ray)?;
        #[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
        if !w.scalar_only() {
            return with_tests!(self; ANY; super::simd::sse2::walk; self, &w, stats);
        }
        self.walk_scalar::<ANY>(w, stats)
    }

    /// Walks `w` to its end on the scalar step (the only walk that takes the exact
    /// exit rule and re-originated rays: `RayWalk::scalar_only`).
    #[inline(never)]
    pub(super) fn walk_scalar<const ANY: bool>(&self, mut w: RayWalk, stats: &mut impl Tally) -> Option<Hit> {
        while !self.step::<ANY>(&mut w, stats) {}
        w.unshift(self.answer(w.best), self.view().triangles)
    }
}
