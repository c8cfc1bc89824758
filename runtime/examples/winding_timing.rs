//! Winding numbers on one thread: points uniform in 1.1x the mesh's box and points
//! within 1 % of the box's diagonal from the surface, at several tolerances; prints
//! points a second and, for the first `WINDING_CHECK` points (default 50), the largest
//! error against the brute-force sum over every triangle, and the largest bound.
//!
//! `cargo run --release -p octrace-runtime --example winding_timing -- scene.oct [points]`
use std::time::Instant;

use octrace_runtime::winding::{solid_angle, Accuracy, WindingScratch, WindingTree};
use octrace_runtime::Scene;

struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }
    fn unit(&mut self) -> f32 {
        (self.next() >> 40) as f32 / (1u64 << 24) as f32
    }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let path = args.next().ok_or("usage: winding_timing SCENE.oct [points]")?;
    let n: usize = args.next().map_or(Ok(20_000), |s| s.parse())?;
    let check: usize = std::env::var("WINDING_CHECK").map_or(Ok(50), |s| s.parse())?;
    let scene = Scene::open(&path)?;
    let view = scene.view();
    let (lo, hi) = (view.bounds.mesh_lo, view.bounds.mesh_hi);
    let size: [f32; 3] = [0, 1, 2].map(|k| hi[k] - lo[k]);
    let diag = size.iter().map(|s| s * s).sum::<f32>().sqrt();
    let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
    let uniform: Vec<[f32; 3]> =
        (0..n).map(|_| [0, 1, 2].map(|k| lo[k] - 0.05 * size[k] + 1.1 * size[k] * rng.unit())).collect();
    let triangles: Vec<[[f32; 3]; 3]> = view.stored_triangles().collect();
    let near: Vec<[f32; 3]> = (0..n)
        .map(|_| {
            let t = triangles[(rng.next() % triangles.len() as u64) as usize];
            let (mut a, mut b) = (rng.unit(), rng.unit());
            if a + b > 1.0 {
                (a, b) = (1.0 - a, 1.0 - b);
            }
            let offset = 0.01 * diag * rng.unit();
            let dir = [0, 1, 2].map(|_| rng.unit() * 2.0 - 1.0);
            let len = dir.iter().map(|d| d * d).sum::<f32>().sqrt().max(1e-6);
            [0, 1, 2].map(|k| t[0][k] + a * (t[1][k] - t[0][k]) + b * (t[2][k] - t[0][k]) + offset * dir[k] / len)
        })
        .collect();
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
        for accuracy in [
            Accuracy::Beta(2.0),
            Accuracy::Beta(3.0),
            Accuracy::Beta(4.0),
            Accuracy::Within(1e-1),
            Accuracy::Within(1e-2),
            Accuracy::Within(1e-3),
        ] {
            let mut scratch = WindingScratch::default();
            let mut best = f64::INFINITY;
            for _ in 0..3 {
                let t = Instant::now();
                for p in pts.iter() {
                    std::hint::black_box(tree.winding_number_as(&mut scratch, *p, accuracy));
                }
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
        let mut inside = vec![false; pts.len()];
        let t = Instant::now();
        rayon::ThreadPoolBuilder::new().num_threads(1).build()?.install(|| tree.inside_batch(pts, &mut inside));
        let wrong = pts.iter().zip(&exact).zip(&inside).filter(|((_, e), i)| (**e > 0.5) != **i).count();
        println!(
            "{name:8} w > 1/2, certain: {:.3} M points/s, {wrong} of {} wrong",
            pts.len() as f64 / t.elapsed().as_secs_f64() / 1e6,
            exact.len()
        );
    }
    Ok(())
}
