//! `octrace soak`: many rays from inside closed meshes; every one must hit.

use std::time::Instant;

use glam::Vec3;
use octrace_bake::{bake, procedural, BuildParams};
use octrace_runtime::{Ray, Scene, TriangleTest};
use serde_json::json;

use crate::output::thousands;

/// Shoot rays from inside closed meshes (a sphere, a torus, a box and a bumpy blob)
/// and count the leaks: rays that hit nothing although they cannot get out. Rays go
/// in uniform random directions and exactly at every vertex and edge midpoint. Exits
/// with an error if any ray leaks.
#[derive(clap::Args, Debug)]
pub(crate) struct Args {
    /// Random rays per mesh (the vertex and edge rays come on top).
    #[arg(long, default_value_t = 10_000_000)]
    pub rays: usize,
    /// Seed of the ray generator.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Use the Möller-Trumbore triangle test instead of the watertight one.
    #[arg(long)]
    pub moller_trumbore: bool,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
}

pub(crate) fn run(args: Args) -> anyhow::Result<()> {
    let test = if args.moller_trumbore { TriangleTest::MollerTrumbore } else { TriangleTest::Watertight };
    let mut rows = Vec::new();
    let mut total_leaks = 0;
    for solid in procedural::closed_solids() {
        let scene = Scene::from_baked(bake(&solid.mesh, &BuildParams::auto())?)?;
        let tracer = scene.tracer().with_triangle_test(test);
        let mut leaks = 0usize;
        let mut rays_done = 0usize;
        let t = Instant::now();
        // In batches, so ten million rays need not sit in memory at once.
        let batch = 1 << 20;
        let mut done = 0;
        let mut first_leak = None;
        while done < args.rays || done == 0 {
            let n = batch.min(args.rays - done);
            let mut rays: Vec<Ray> = solid
                .leak_rays(n, args.seed.wrapping_add(done as u64))
                .iter()
                .map(|(o, d)| Ray::new(Vec3::from(*o), Vec3::from(*d)))
                .collect();
            if done > 0 {
                rays.truncate(n); // the vertex and edge rays only once
            }
            let mut hits = vec![None; rays.len()];
            tracer.par_intersect_batch(&rays, &mut hits);
            for (r, h) in rays.iter().zip(&hits) {
                if h.is_none() {
                    leaks += 1;
                    first_leak.get_or_insert(*r);
                }
            }
            rays_done += rays.len();
            done += n.max(1);
        }
        let secs = t.elapsed().as_secs_f64();
        total_leaks += leaks;
        rows.push((
            solid.name,
            solid.mesh.triangles.len(),
            rays_done,
            leaks,
            rays_done as f64 / secs / 1e6,
            first_leak,
        ));
    }
    if args.json {
        let meshes: Vec<_> = rows
            .iter()
            .map(|(name, tris, rays, leaks, mrays, first)| {
                json!({ "mesh": name, "triangles": tris, "rays": rays, "leaks": leaks, "mrays_per_s": mrays,
                        "first_leak": first.map(|r| format!("{r:?}")) })
            })
            .collect();
        crate::out!(
            "{}",
            serde_json::to_string_pretty(&json!({ "triangle_test": format!("{test:?}"), "meshes": meshes }))?
        );
    } else {
        for (name, tris, rays, leaks, mrays, first) in &rows {
            crate::out!(
                "{name:<7} {} triangles: {} rays, {} leaks ({mrays:.2} Mrays/s){}",
                thousands(*tris as u64),
                thousands(*rays as u64),
                leaks,
                first.map_or(String::new(), |r| format!("; first leak {r:?}"))
            );
        }
    }
    anyhow::ensure!(total_leaks == 0, "{total_leaks} rays leaked out of closed meshes");
    Ok(())
}
