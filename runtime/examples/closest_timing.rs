//! Closest points on one thread: points uniform in 1.1x the mesh's box, and points within
//! 1 % of the box's diagonal from the surface; prints points a second (median of three
//! batches) and the spread of one point's time. `CLOSEST_CHECK=k` first compares `k`
//! points of each kind with the brute-force `f64` oracle; `CLOSEST_SLOW=1` prints the
//! uniform points that take over a millisecond.
//!
//! `cargo run --release -p octrace-runtime --example closest_timing -- scene.oct [points]`
use std::time::Instant;

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
    let path = args.next().ok_or("usage: closest_timing SCENE.oct [points]")?;
    let n: usize = args.next().map_or(Ok(20_000), |s| s.parse())?;
    let scene = Scene::open(&path)?;
    let view = scene.view();
    let (lo, hi) = (view.bounds.mesh_lo, view.bounds.mesh_hi);
    let size: [f32; 3] = [0, 1, 2].map(|k| hi[k] - lo[k]);
    let diag = size.iter().map(|s| s * s).sum::<f32>().sqrt();
    let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
    let uniform: Vec<[f32; 3]> =
        (0..n).map(|_| [0, 1, 2].map(|k| lo[k] - 0.05 * size[k] + 1.1 * size[k] * rng.unit())).collect();
    let triangles = view.triangle_count();
    let near: Vec<[f32; 3]> = (0..n)
        .map(|_| {
            let t = view.triangle(octrace_format::StoredIndex((rng.next() % triangles as u64) as u32));
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
    let bounds = scene.surface_bounds();
    let tracer = scene.tracer();
    for pts in [&uniform, &near] {
        let mut us: Vec<f64> = pts
            .iter()
            .map(|p| {
                let t = Instant::now();
                std::hint::black_box(tracer.closest_point(bounds, *p, f32::INFINITY));
                t.elapsed().as_secs_f64() * 1e6
            })
            .collect();
        let mean = us.iter().sum::<f64>() / us.len() as f64;
        us.sort_by(f64::total_cmp);
        println!(
            "per point us: mean {mean:.1} p10 {:.1} p50 {:.1} p90 {:.1} p99 {:.1} max {:.1}",
            us[us.len() / 10],
            us[us.len() / 2],
            us[us.len() * 9 / 10],
            us[us.len() * 99 / 100],
            us[us.len() - 1]
        );
    }
    if let Some(k) = std::env::var_os("CLOSEST_CHECK") {
        // Against the brute-force f64 oracle: the distance within one f32 rounding.
        let k: usize = k.to_str().and_then(|s| s.parse().ok()).unwrap_or(500);
        let oracle = octrace_runtime::reference::Reference::from_view(&view);
        let mut wrong = 0;
        for p in uniform.iter().take(k).chain(near.iter().take(k)) {
            let ours = tracer.closest_point(bounds, *p, f32::INFINITY).map(|c| c.distance);
            let theirs = oracle.closest_point(*p).map(|c| c.distance);
            let ok = match (ours, theirs) {
                (Some(a), Some(b)) => (a as f64 - b).abs() <= (b * 1.2e-7).max(1e-15),
                (a, b) => a.is_none() && b.is_none(),
            };
            if !ok {
                wrong += 1;
                println!("{p:?}: {ours:?} against {theirs:?}");
            }
        }
        println!("{wrong} of {} points off the oracle", 2 * k);
    }
    if std::env::var_os("CLOSEST_SLOW").is_some() {
        for (i, p) in uniform.iter().enumerate() {
            let t = Instant::now();
            let c = tracer.closest_point(bounds, *p, f32::INFINITY);
            let us = t.elapsed().as_secs_f64() * 1e6;
            if us > 1000.0 {
                println!("{i} {p:?} {us:.0} us {c:?}");
            }
        }
    }
    for (name, points) in [("uniform 1.1x box", &uniform), ("within 1% of the surface", &near)] {
        let mut out = vec![None; points.len()];
        let mut rates = Vec::new();
        for _ in 0..3 {
            let t = Instant::now();
            tracer.closest_point_batch(bounds, points, f32::INFINITY, &mut out);
            rates.push(points.len() as f64 / t.elapsed().as_secs_f64() / 1e6);
        }
        rates.sort_by(f64::total_cmp);
        let sum: f64 = out.iter().flatten().map(|c| c.distance as f64).sum();
        println!("{name}: {:.4} M points/s (median of 3), distances sum {sum:.6}", rates[1]);
    }
    Ok(())
}
