//! Leaks: rays from inside the procedural closed solids (not the report's meshes) that
//! hit nothing, per configuration, solid and kind of ray.

use glam::Vec3;
use octrace_bake::hard_rays::GridPlanes;
use octrace_bake::octree::ResolvedParams;
use octrace_bake::procedural::{self, ClosedSolid};
use octrace_bake::{bake, BuildParams};
use octrace_runtime::Ray;
use rayon::prelude::*;
use serde::Serialize;

use super::configs::Config;
use super::measure::{Answer, Traced};

/// The kinds of leak rays: uniform random directions; aimed exactly at every vertex
/// and edge midpoint; on the octree's planes (in cell planes with +0.0 and -0.0
/// components, along cell edges, from and through cell corners).
pub(super) const KINDS: [&str; 3] = ["random", "aimed", "grid"];

/// Leaks of one configuration on one solid and kind of ray.
#[derive(Clone, Debug, Serialize)]
pub(super) struct LeakCount {
    pub solid: &'static str,
    pub kind: &'static str,
    pub rays: usize,
    pub leaks: usize,
}

/// A closed solid, its automatic parameters and its rays, by kind.
struct Solid {
    solid: ClosedSolid,
    base: ResolvedParams,
    kinds: Vec<(&'static str, Vec<Ray>)>,
}

/// The closed solids and their rays.
pub(super) struct Solids(Vec<Solid>);

impl Solids {
    /// `random` random rays and as many grid rays a solid, and the aimed ones.
    pub(super) fn new(random: usize) -> anyhow::Result<Solids> {
        let to_rays = |v: Vec<([f32; 3], [f32; 3])>| -> Vec<Ray> {
            v.iter().map(|(o, d)| Ray::new(Vec3::from(*o), Vec3::from(*d))).collect()
        };
        let mut out = Vec::new();
        for solid in procedural::closed_solids() {
            let base = BuildParams::auto().resolve(solid.mesh.triangles.len());
            let mut leak = to_rays(solid.leak_rays(random, 1));
            let aimed = leak.split_off(random);
            let grid = GridPlanes::of(&bake(&solid.mesh, &BuildParams::auto())?.view());
            let grid: Vec<Ray> = solid
                .grid_rays(&grid, random, 1)
                .iter()
                .map(|r| Ray::new(Vec3::from(r.origin), Vec3::from(r.dir)))
                .collect();
            out.push(Solid { solid, base, kinds: vec![("random", leak), ("aimed", aimed), ("grid", grid)] });
        }
        Ok(Solids(out))
    }

    /// The leaks of `config`, built on each solid.
    pub(super) fn leaks(&self, config: Config) -> anyhow::Result<Vec<LeakCount>> {
        let mut out = Vec::new();
        for Solid { solid, base, kinds } in &self.0 {
            let built = config.build(&solid.mesh, base)?;
            for (kind, rays) in kinds {
                out.push(LeakCount { solid: solid.name, kind, rays: rays.len(), leaks: misses(&*built.traced, rays) });
            }
        }
        Ok(out)
    }
}

/// The rays of `rays` that `traced` finds no hit for, on all threads.
fn misses(traced: &dyn Traced, rays: &[Ray]) -> usize {
    rays.par_chunks(4096)
        .map(|c| traced.answers(c, false).iter().filter(|a| matches!(a, Answer::Nearest(None))).count())
        .sum()
}

/// Leaks per million over all the counts, and the rays shot.
pub(super) fn rate(counts: &[LeakCount]) -> (f64, usize) {
    let rays: usize = counts.iter().map(|c| c.rays).sum();
    let leaks: usize = counts.iter().map(|c| c.leaks).sum();
    (leaks as f64 * 1e6 / rays.max(1) as f64, rays)
}
