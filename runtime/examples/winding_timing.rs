//! Winding numbers on one thread (the batch call): points uniform in 1.1x the mesh's box and points
//! within 1 % of the box's diagonal from the surface, at several tolerances; prints
//! points a second and, for the first `WINDING_CHECK` points (default 50), the largest
//! error against the brute-force sum over every triangle, and the largest bound.
//! `WINDING_ONLY=fast` times Barill's rule alone (for a profile), at `beta = WINDING_BETA`
//! (default 2).
//!
//! `cargo run --release -p octrace-runtime --example winding_timing -- scene.oct [points]`
use std::time::Instant;

use octrace_runtime::winding::{solid_angle, Accuracy, WindingScratch, WindingTree};
use octrace_runtime::Scene;

#[path = "shared/point_sets.rs"]
mod point_sets;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let path = args.next().ok_or("usage: winding_timing SCENE.oct [points]")?;
    let n: usize = args.next().map_or(Ok(20_000), |s| s.parse())?;
    let check: usize = std::env::var("WINDING_CHECK").map_or(Ok(50), |s| s.parse())?;
    let scene = Scene::open(&path)?;
    let view = scene.view();
    let (uniform, near) = point_sets::point_sets(&view, n);
    let triangles: Vec<[[f32; 3]; 3]> = view.stored_triangles().collect();
    let one = rayon::ThreadPoolBuilder::new().num_threads(1).build()?;
    let t = Instant::now();
    let tree = WindingTree::new(triangles.clone())?;
    println!("tree: {} triangles, {:.1} MB, {:.3} s", tree.len(), tree.bytes() as f64 / 1e6, t.elapsed().as_secs_f64());
    for (name, pts) in [("uniform", &uniform), ("near", &near)] {
        let exact: Vec<f64> = pts[..check.min(pts.len())]
            .iter()
            .map(|p| {
                let p = p.map(f64::from);
                triangles.iter().map(|t| solid_angle(p, t)).sum::<f64>() / (4.0 * std::f64::consts::PI)
            })
            .collect();
        let first: f64 = std::env::var("WINDING_BETA").map_or(Ok(2.0), |s| s.parse())?;
        let all = [
            Accuracy::Beta(first),
            Accuracy::Beta(3.0),
            Accuracy::Beta(4.0),
            Accuracy::Within(1e-1),
            Accuracy::Within(1e-2),
            Accuracy::Within(1e-3),
        ];
        let fast_only = std::env::var("WINDING_ONLY").is_ok_and(|s| s == "fast");
        if scene.winds_exactly() {
            // Closed and oriented: the scene's exact integers (labels, one ray).
            let _ = one.install(|| scene.winding_numbers(&pts[..1], Accuracy::FAST))?;
            let mut best = f64::INFINITY;
            for _ in 0..3 {
                let t = Instant::now();
                std::hint::black_box(one.install(|| scene.winding_numbers(pts, Accuracy::FAST))?);
                best = best.min(t.elapsed().as_secs_f64());
            }
            println!("{name:8} exact (Scene::winding_numbers): {:.3} M points/s", pts.len() as f64 / best / 1e6);
        }
        for accuracy in if fast_only { &all[..1] } else { &all[..] } {
            let accuracy = *accuracy;
            let mut scratch = WindingScratch::default();
            let mut best = f64::INFINITY;
            let mut out = vec![Default::default(); pts.len()];
            for _ in 0..3 {
                let t = Instant::now();
                one.install(|| tree.winding_numbers(pts, accuracy, &mut out));
                best = best.min(t.elapsed().as_secs_f64());
            }
            let (mut worst, mut worst_bound) = (0.0f64, 0.0f64);
            for (p, e) in pts.iter().zip(&exact) {
                let w = tree.winding_number_as(&mut scratch, *p, accuracy);
                worst = worst.max((w.value - e).abs());
                worst_bound = worst_bound.max(w.bound);
                assert!((w.value - e).abs() <= w.bound + 1e-9, "{p:?}: {w:?} vs {e}");
            }
            println!(
                "{name:8} {accuracy:?}: {:.3} M points/s, worst error {worst:.2e}, worst bound {worst_bound:.2e}",
                pts.len() as f64 / best / 1e6
            );
        }
        if fast_only {
            continue;
        }
        let mut inside = vec![false; pts.len()];
        let t = Instant::now();
        one.install(|| tree.inside_batch(pts, &mut inside));
        let wrong = pts.iter().zip(&exact).zip(&inside).filter(|((_, e), i)| (**e > 0.5) != **i).count();
        println!(
            "{name:8} w > 1/2, certain: {:.3} M points/s, {wrong} of {} wrong",
            pts.len() as f64 / t.elapsed().as_secs_f64() / 1e6,
            exact.len()
        );
    }
    Ok(())
}
