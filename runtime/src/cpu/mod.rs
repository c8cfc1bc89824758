//! CPU tracing: the scalar octree walk (the always-compiled reference
//! implementation) and batch forms over slices of rays.

pub mod tables;
mod traverse;
mod triangle;

pub use traverse::{Tracer, WalkStats};

use rayon::prelude::*;

use crate::ray::{Hit, Ray};

/// Rays per rayon task in the parallel batch calls: large enough to amortise the
/// task, small enough to balance two cores on uneven rays.
const CHUNK: usize = 1024;

impl Tracer<'_> {
    /// Nearest hits of a batch, on this thread.
    pub fn intersect_batch(&self, rays: &[Ray], out: &mut [Option<Hit>]) {
        assert_eq!(rays.len(), out.len(), "one result slot a ray");
        for (r, o) in rays.iter().zip(out) {
            *o = self.intersect(r);
        }
    }

    /// Nearest hits of a batch, on all threads of the current rayon pool.
    pub fn par_intersect_batch(&self, rays: &[Ray], out: &mut [Option<Hit>]) {
        assert_eq!(rays.len(), out.len(), "one result slot a ray");
        rays.par_chunks(CHUNK).zip(out.par_chunks_mut(CHUNK)).for_each(|(r, o)| self.intersect_batch(r, o));
    }

    /// Occlusion of a batch, on this thread.
    pub fn occluded_batch(&self, rays: &[Ray], out: &mut [bool]) {
        assert_eq!(rays.len(), out.len(), "one result slot a ray");
        for (r, o) in rays.iter().zip(out) {
            *o = self.occluded(r);
        }
    }

    /// Occlusion of a batch, on all threads of the current rayon pool.
    pub fn par_occluded_batch(&self, rays: &[Ray], out: &mut [bool]) {
        assert_eq!(rays.len(), out.len(), "one result slot a ray");
        rays.par_chunks(CHUNK).zip(out.par_chunks_mut(CHUNK)).for_each(|(r, o)| self.occluded_batch(r, o));
    }
}

#[cfg(test)]
mod tests;
