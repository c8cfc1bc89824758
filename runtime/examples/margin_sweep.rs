//! Measures what the bake margin buys: leaks from closed meshes and disagreements
//! with the f64 oracle on rays along cell edges and through cell corners, for
//! several margins. `cargo run --release -p octrace-runtime --example margin_sweep`.
use glam::Vec3;
use octrace_bake::{bake, procedural, BuildParams};
use octrace_runtime::reference::{Agreement, Reference};
use octrace_runtime::{Ray, Scene};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let solids = procedural::closed_solids();
    let mut mixed = procedural::sphere([0.0; 3], 1.0, 48, 64);
    mixed.triangles.extend(procedural::soup(3, 20_000, 2.0, 0.2).triangles);
    println!("margin (of root edge) | leaks / rays (closed solids) | oracle mismatches / rays (grid + random) | refs per triangle");
    for margin in [0.0f32, 2f32.powi(-24), 2f32.powi(-22), 2f32.powi(-20), 2f32.powi(-18), 2f32.powi(-16)] {
        let params = BuildParams { margin, ..BuildParams::auto() };
        let (mut leaks, mut total) = (0, 0);
        for s in &solids {
            let scene = Scene::from_baked(bake(&s.mesh, &params)?)?;
            let rays: Vec<Ray> =
                s.leak_rays(500_000, 9).iter().map(|(o, d)| Ray::new(Vec3::from(*o), Vec3::from(*d))).collect();
            leaks += scene.intersect_batch(&rays).iter().filter(|h| h.is_none()).count();
            total += rays.len();
        }
        let baked =
            bake(&mixed, &BuildParams { max_depth: Some(8), leaf_size: Some(2), margin, ..BuildParams::auto() })?;
        let refs = baked.tri_refs.len() as f64 / baked.triangle_ids.len() as f64;
        let scene = Scene::from_baked(baked)?;
        let view = scene.view();
        let oracle = Reference::from_view(&view);
        let mut rays = Vec::new();
        for rec in view.leaves().step_by(97) {
            let b = view.leaf_box(rec.box_index);
            let corner = Vec3::new(b[3], b[4], b[5]);
            for d in [Vec3::new(1.0, 1.0, 1.0), Vec3::new(-1.0, 0.5, 0.25), Vec3::new(0.25, -1.0, 0.5)] {
                rays.push(Ray::new(corner - 3.0 * d, d));
            }
            rays.push(Ray::new(Vec3::new(b[0], b[1], -3.0), Vec3::new(1e-7, -1e-7, 1.0)));
        }
        let mut rng = procedural::SplitMix(4);
        for _ in 0..20_000 {
            let o = Vec3::new(rng.unit(), rng.unit(), rng.unit()) * 6.0 - 2.0;
            rays.push(Ray::new(o, Vec3::new(rng.unit(), rng.unit(), rng.unit()) * 2.0 - 1.0 - o * 0.1));
        }
        let t = scene.tracer();
        use rayon::prelude::*;
        let wrong = rays
            .par_iter()
            .filter(|r| oracle.compare(r, t.intersect(r).map(|h| (h.t, h.triangle, h.u, h.v))) == Agreement::Different)
            .count();
        println!("{margin:>12.3e} | {leaks} / {total} | {wrong} / {} | {refs:.3}", rays.len());
    }
    Ok(())
}
