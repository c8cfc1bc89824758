//! Tracing a configuration on the standard sets and the hard rays, timed, and its
//! answers against the f64 oracle's.

use std::time::{Duration, Instant};

use octrace_runtime::raysets::{self, Frame};
use octrace_runtime::reference::{Agreement, Reference, ReferenceHit};
use octrace_runtime::{Hit, Ray, Scene, Tracer};
use rayon::prelude::*;
use serde::Serialize;

/// A tracer's answer for one ray.
#[derive(Clone, Copy, Debug)]
pub(super) enum Answer {
    /// Distance, input triangle id, barycentrics.
    Nearest(Option<(f32, u32, f32, f32)>),
    Occluded(bool),
}

/// A structure the report traces, built on some mesh: it answers rays in batches
/// (nearest hits, or occlusion), on the calling thread.
pub(super) trait Traced: Sync {
    fn answers(&self, rays: &[Ray], occlusion: bool) -> Vec<Answer>;
}

/// An octree tracer's answers (the batch calls).
pub(super) fn tracer_answers(tracer: &Tracer<'_>, rays: &[Ray], occlusion: bool) -> Vec<Answer> {
    if occlusion {
        let mut out = vec![false; rays.len()];
        tracer.occluded_batch(rays, &mut out);
        out.into_iter().map(Answer::Occluded).collect()
    } else {
        let mut out: Vec<Option<Hit>> = vec![None; rays.len()];
        tracer.intersect_batch(rays, &mut out);
        out.into_iter().map(|h| Answer::Nearest(h.map(|h| (h.t, h.triangle, h.u, h.v)))).collect()
    }
}

/// The answers of a structure traced ray by ray.
pub(super) fn answers_by(
    rays: &[Ray],
    occlusion: bool,
    nearest: impl Fn(&Ray) -> Option<(f32, u32, f32, f32)>,
    occluded: impl Fn(&Ray) -> bool,
) -> Vec<Answer> {
    rays.iter().map(|r| if occlusion { Answer::Occluded(occluded(r)) } else { Answer::Nearest(nearest(r)) }).collect()
}

/// Mrays/s over the timed runs: the median to quote, and the spread.
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub(super) struct Speed {
    pub median: f64,
    pub min: f64,
    pub max: f64,
}

impl Speed {
    fn of(rays: usize, times: &mut [Duration]) -> Speed {
        times.sort();
        let mrays = |t: Duration| rays as f64 / t.max(Duration::from_nanos(1)).as_secs_f64() / 1e6;
        Speed { median: mrays(times[times.len() / 2]), min: mrays(times[times.len() - 1]), max: mrays(times[0]) }
    }

    /// Whether this is faster than `other` beyond both spreads (the ranges of the runs
    /// do not overlap).
    pub fn clearly_faster(&self, other: &Speed) -> bool {
        self.min > other.max
    }

    /// Whether this is not clearly slower than `other`.
    pub fn not_slower(&self, other: &Speed) -> bool {
        !other.clearly_faster(self)
    }
}

/// Errors of one configuration against the oracle.
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub(super) struct Errors {
    /// Rays compared.
    pub compared: usize,
    /// Wrong answers (not explained by a tie or an edge).
    pub wrong: usize,
    /// Different answers within rounding: two triangles at one distance, a hit on an
    /// edge, an origin on a surface.
    pub ties: usize,
    /// Largest |Δt|/t where both found the same triangle.
    pub max_relative_dt: f64,
}

impl Errors {
    /// Wrong answers per million rays compared.
    pub fn per_million(&self) -> f64 {
        self.wrong as f64 * 1e6 / self.compared.max(1) as f64
    }

    fn add(&mut self, reference: &Reference, ray: &Ray, want: &Want, got: Answer) {
        let agreement = match (got, want) {
            (Answer::Nearest(got), Want::Nearest(want)) => {
                let a = reference.compare_with(ray, *want, got);
                if let (Agreement::Same, Some(g), Some(w)) = (a, got, want) {
                    if g.1 == w.triangle && w.t > 0.0 {
                        self.max_relative_dt = self.max_relative_dt.max((g.0 as f64 - w.t).abs() / w.t);
                    }
                }
                a
            }
            (Answer::Occluded(got), Want::Occluded(want)) => reference.compare_occluded_with(ray, *want, got),
            _ => Agreement::Different,
        };
        self.compared += 1;
        match agreement {
            Agreement::Same => {}
            Agreement::Tie => self.ties += 1,
            Agreement::Different => self.wrong += 1,
        }
    }
}

/// The oracle's answer for a sampled ray.
#[derive(Clone, Copy, Debug)]
pub(super) enum Want {
    Nearest(Option<ReferenceHit>),
    Occluded(bool),
}

/// The standard sets of one mesh, the sample indices and the oracle's answers there.
pub(super) struct Sets {
    /// (name, rays, occlusion?)
    pub sets: Vec<(&'static str, Vec<Ray>, bool)>,
    pub samples: Vec<Vec<usize>>,
    pub wants: Vec<Vec<Want>>,
    pub reference: Reference,
}

/// The standard sets of `scene` (shadow rays from its primary hits), a sample of each,
/// and the oracle's answers on the samples.
pub(super) fn standard_sets(scene: &Scene, sample: usize, max_rays: Option<usize>) -> Sets {
    let view = scene.view();
    let frame = Frame::from_bounds(view.bounds.mesh_lo, view.bounds.mesh_hi);
    let primary = raysets::primary(&frame);
    let mut hits = vec![None; primary.len()];
    scene.tracer().par_intersect_batch(&primary, &mut hits);
    let shadow = raysets::shadow(&frame, |i| hits[i].map(|h| (h.t, view.triangle(h.prim))));
    let thin = |rays: Vec<Ray>| match max_rays {
        Some(n) if n < rays.len() => spread(rays.len(), n).map(|i| rays[i]).collect(),
        _ => rays,
    };
    let sets = vec![
        ("primary", thin(primary), false),
        ("incoherent", thin(raysets::incoherent(&frame, 1_000_000)), false),
        ("shadow", thin(shadow), true),
    ];
    let reference = Reference::from_view(&view);
    let samples: Vec<Vec<usize>> = sets.iter().map(|(_, rays, _)| spread(rays.len(), sample).collect()).collect();
    let wants = sets
        .iter()
        .zip(&samples)
        .map(|((_, rays, occlusion), s)| s.par_iter().map(|&i| want(&reference, &rays[i], *occlusion)).collect())
        .collect();
    Sets { sets, samples, wants, reference }
}

/// The oracle's answer for `ray`.
pub(super) fn want(reference: &Reference, ray: &Ray, occlusion: bool) -> Want {
    if occlusion {
        Want::Occluded(reference.occluded(ray))
    } else {
        Want::Nearest(reference.intersect(ray))
    }
}

/// `n` indices (at least one, at most `len`) spread evenly over `0..len`.
pub(super) fn spread(len: usize, n: usize) -> impl Iterator<Item = usize> {
    let n = n.max(1).min(len);
    (0..n).map(move |i| i * len / n)
}

/// A configuration's measurements: Mrays/s (one thread) per standard set over the
/// runs, the errors of the last run's answers on the samples, and its errors on the
/// hard rays, kind by kind (`far`: the same structure built on the mesh moved far
/// from the origin, for the far kind).
pub(super) struct Measured {
    pub speeds: Vec<Speed>,
    pub errors: Errors,
    pub hard: Vec<(&'static str, Errors)>,
}

/// Measures `traced` on `sets` (`runs` timed runs a set); the hard rays' errors are
/// the caller's to fill in (`HardSet::errors`).
pub(super) fn measure(traced: &dyn Traced, sets: &Sets, runs: usize) -> Measured {
    let mut speeds = Vec::new();
    let mut errors = Errors::default();
    for (s, (_, rays, occlusion)) in sets.sets.iter().enumerate() {
        let mut times = Vec::new();
        let mut last = Vec::new();
        for _ in 0..runs {
            let t = Instant::now();
            last = traced.answers(rays, *occlusion);
            times.push(t.elapsed());
        }
        speeds.push(Speed::of(rays.len(), &mut times));
        for (j, &i) in sets.samples[s].iter().enumerate() {
            errors.add(&sets.reference, &rays[i], &sets.wants[s][j], last[i]);
        }
    }
    Measured { speeds, errors, hard: Vec::new() }
}

/// Errors of `answers` for `rays` against the oracle's `wants`.
pub(super) fn errors_of(reference: &Reference, rays: &[Ray], wants: &[Want], answers: &[Answer]) -> Errors {
    let mut errors = Errors::default();
    for ((r, w), a) in rays.iter().zip(wants).zip(answers) {
        errors.add(reference, r, w, *a);
    }
    errors
}
