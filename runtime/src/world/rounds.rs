//! The batch queries' rounds: each ray's first boxes, nearest first, taken a box a
//! round; a round's rays carried into their instances and walked together by a
//! [`Walker`] (the CPU's batch walk, or the GPU's kernel), each ray's reach
//! shortened by its nearest hit so far. The answers are the one-ray walk's: every
//! instance a ray's walk can hit within its nearest hit is asked, and a hit is kept
//! by the one rule of [`WorldHit::beats`].

use super::{carried, Carried, World, WorldHit, NO_HIT};
use rayon::prelude::*;

use crate::ray::{Hit, Ray};

/// Rounds of this many jobs or more are carried and taken back on all cores.
const WIDE_ROUND: usize = 1 << 14;

/// Groups of fewer rays than this (a round's rays for one instance) are walked one at
/// a time on the CPU: the batch walk's set-up does not pay for them.
const SMALL_GROUP: usize = 8;

/// Each ray's first boxes in the top level's walk order, nearest first:
/// `boxes[first[i]..first[i + 1]]` (entry distance, instance); `more[i]` where the
/// walk entered more than were kept.
#[derive(Default)]
pub(super) struct Boxes {
    boxes: Vec<(f32, u32)>,
    first: Vec<u32>,
    more: Vec<bool>,
}

impl Boxes {
    /// The first `cap` boxes of each ray's walk.
    pub(super) fn of(world: &World, rays: &[Ray], cap: usize) -> Boxes {
        let mut b =
            Boxes { boxes: Vec::new(), first: Vec::with_capacity(rays.len() + 1), more: vec![false; rays.len()] };
        b.first.push(0);
        for (ray, more) in rays.iter().zip(&mut b.more) {
            let start = b.boxes.len();
            if ray.is_traceable() {
                world.top.walk(ray.origin.to_array(), ray.dir.to_array(), ray.tmin, ray.tmax, |id, near, _| {
                    *more = b.boxes.len() - start == cap;
                    if !*more {
                        b.boxes.push((near, id));
                    }
                    *more
                });
            }
            b.boxes[start..].sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            b.first.push(b.boxes.len() as u32);
        }
        b
    }

    #[cfg(feature = "gpu")]
    /// `self` followed by `next` (the boxes of the rays after `self`'s).
    pub(super) fn append(&mut self, next: Boxes) {
        if self.first.is_empty() {
            *self = next;
            return;
        }
        let base = self.boxes.len() as u32;
        self.boxes.extend(next.boxes);
        self.first.extend(next.first[1..].iter().map(|f| f + base));
        self.more.extend(next.more);
    }

    /// Ray `i`'s boxes.
    pub(super) fn of_ray(&self, i: usize) -> &[(f32, u32)] {
        &self.boxes[self.first[i] as usize..self.first[i + 1] as usize]
    }

    /// Whether ray `i`'s walk entered more boxes than were kept.
    pub(super) fn more(&self, i: usize) -> bool {
        self.more[i]
    }
}

/// Walks a round's rays, each carried into one instance.
pub(super) trait Walker {
    type Error;

    /// For each `jobs[k] = (instance, ray)` (sorted by instance), the nearest hit of
    /// `local[k]` (the ray carried into the instance's space) in its scene, or with
    /// `any` a hit of it, into `hits[k]`.
    fn walk(
        &mut self,
        world: &World,
        any: bool,
        jobs: &[(u32, u32)],
        local: &[Ray],
        hits: &mut [Option<Hit>],
    ) -> Result<(), Self::Error>;
}

/// The CPU's walks: a group of an instance's rays by its scene's batch walk (or one
/// at a time, for a small group).
pub(super) struct OnCpu;

impl Walker for OnCpu {
    type Error = std::convert::Infallible;

    fn walk(
        &mut self,
        world: &World,
        any: bool,
        jobs: &[(u32, u32)],
        local: &[Ray],
        hits: &mut [Option<Hit>],
    ) -> Result<(), Self::Error> {
        let mut at = 0;
        for group in jobs.chunk_by(|a, b| a.0 == b.0) {
            let (local, hits) = (&local[at..at + group.len()], &mut hits[at..at + group.len()]);
            at += group.len();
            let Some(p) = &world.placed[group[0].0 as usize] else { continue };
            let scene = &world.scenes[p.scene as usize];
            if local.len() < SMALL_GROUP {
                for (ray, hit) in local.iter().zip(hits.iter_mut()) {
                    *hit = if any { scene.shared_occluder(ray) } else { scene.intersect(ray) };
                }
            } else if any {
                scene.tracer().occluder_batch(local, hits);
            } else {
                scene.tracer().intersect_batch(local, hits);
            }
        }
        Ok(())
    }
}

impl World {
    /// The rounds over each ray's `boxes`, answers (nearest hits, or with `any` a
    /// blocker) merged into `out`; rays whose walks entered more boxes than `boxes`
    /// holds are left to [`World::finish`].
    pub(super) fn rounds<W: Walker>(
        &self,
        any: bool,
        rays: &[Ray],
        boxes: &Boxes,
        out: &mut [Option<WorldHit>],
        walker: &mut W,
    ) -> Result<(), W::Error> {
        let mut round = 0usize;
        let mut jobs: Vec<(u32, u32)> = Vec::new(); // (instance, ray)
        let (mut carried_rays, mut local, mut hits) = (Vec::new(), Vec::new(), Vec::new());
        let mut found: Vec<Option<WorldHit>> = Vec::new();
        loop {
            jobs.clear();
            let mut left = false;
            for (i, ray) in rays.iter().enumerate() {
                let Some(&(near, id)) = boxes.of_ray(i).get(round) else { continue };
                left = true;
                if any && out[i].is_some() {
                    continue;
                }
                let reach = out[i].map_or(ray.tmax, |h: WorldHit| h.hit.t);
                // The walk's own test: a box entered past the best hit is skipped.
                if near <= reach + reach.abs() * 4.0 * f32::EPSILON {
                    jobs.push((id, i as u32));
                }
            }
            if !left {
                return Ok(());
            }
            jobs.sort_unstable();
            // Large rounds (the GPU's) carry and take back their rays on all cores; a
            // CPU piece's are smaller than this, on the thread that has the piece.
            let wide = jobs.len() >= WIDE_ROUND;
            let carry = |&(id, i): &(u32, u32)| {
                let ray = &rays[i as usize];
                let p = self.placed[id as usize].as_ref().expect("a box is a committed instance's");
                carried(p, ray, out[i as usize].map_or(ray.tmax, |h| h.hit.t))
            };
            carried_rays.clear();
            if wide {
                carried_rays.par_extend(jobs.par_iter().map(carry));
            } else {
                carried_rays.extend(jobs.iter().map(carry));
            }
            local.clear();
            local.extend(carried_rays.iter().map(|c: &Carried| c.ray));
            hits.clear();
            hits.resize(local.len(), None);
            walker.walk(self, any, &jobs, &local, &mut hits)?;
            // Each answer carried back (a ray has one job a round)...
            let back = |((&(id, i), raw), c): ((&(u32, u32), &Option<Hit>), &Carried)| {
                let ray = &rays[i as usize];
                let reach = out[i as usize].map_or(ray.tmax, |h| h.hit.t);
                let mut hit = raw.and_then(|h| c.back(h, reach));
                if any && hit.is_none() && raw.is_some() {
                    // The blocker found lies in the carried ray's margin past `tmax`:
                    // the nearest decides, as in `occluded`.
                    let scene = &self.scenes[self.placed[id as usize].expect("asked").scene as usize];
                    hit = scene.intersect(&c.ray).and_then(|h| c.back(h, reach));
                }
                hit.map(|hit| WorldHit { instance: id, hit })
            };
            found.clear();
            if wide {
                found.par_extend(jobs.par_iter().zip(&hits).zip(&carried_rays).map(back));
            } else {
                found.extend(jobs.iter().zip(&hits).zip(&carried_rays).map(back));
            }
            // ...then kept where it is the nearer.
            for (&(_, i), &this) in jobs.iter().zip(&found) {
                if let Some(this) = this.filter(|h| h.beats(out[i as usize])) {
                    out[i as usize] = Some(this);
                }
            }
            round += 1;
        }
    }

    /// Ray `i`'s answer after the rounds, where its walk entered more boxes than
    /// `boxes` kept: the one-ray walk within its nearest hit so far, the instances
    /// already asked skipped.
    pub(super) fn finish(&self, any: bool, ray: &Ray, asked: &[(f32, u32)], out: &mut Option<WorldHit>) {
        if any && out.is_some() {
            return;
        }
        let asked: Vec<u32> = asked.iter().map(|b| b.1).collect();
        *out = if any {
            self.occluded_from(ray, &asked).then_some(WorldHit { instance: u32::MAX, hit: NO_HIT })
        } else {
            self.intersect_from(ray, *out, &asked)
        };
    }

    /// [`World::finish`] for every ray of `rays` that needs it.
    pub(super) fn finish_all(&self, any: bool, rays: &[Ray], boxes: &Boxes, out: &mut [Option<WorldHit>]) {
        for (i, (ray, out)) in rays.iter().zip(out).enumerate() {
            if boxes.more(i) {
                self.finish(any, ray, boxes.of_ray(i), out);
            }
        }
    }
}
