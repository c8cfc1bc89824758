//! Closest points on one thread: points uniform in 1.1x the mesh's box, and points within
//! 1 % of the box's diagonal from the surface; prints points a second (median of three
//! batches) and the spread of one point's time. `CLOSEST_CHECK=k` first compares `k`
//! points of each kind with the brute-force `f64` oracle; `CLOSEST_SLOW=1` prints the
//! uniform points that take over a millisecond; `CLOSEST_ONLY=uniform` (or `near`) times
//! one pass over that set alone and prints its M points/s and distances' sum (for A/B
//! runs of two builds).
//!
//! `cargo run --release -p octrace-runtime --example closest_timing -- scene.oct [points]`
use std::time::Instant;

use octrace_runtime::Scene;

#[path = "shared/point_sets.rs"]
mod point_sets;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let path = args.next().ok_or("usage: closest_timing SCENE.oct [points]")?;
    let n: usize = args.next().map_or(Ok(20_000), |s| s.parse())?;
    let scene = Scene::open(&path)?;
    let view = scene.view();
    let (uniform, near) = point_sets::point_sets(&view, n);
    let bounds = scene.surface_bounds()?;
    let tracer = scene.tracer();
    if let Ok(which) = std::env::var("CLOSEST_ONLY") {
        let pts = if which == "near" { &near } else { &uniform };
        let mut out = vec![None; pts.len()];
        let t = Instant::now();
        tracer.closest_point_batch(bounds, pts, f32::INFINITY, &mut out);
        let sum: f64 = out.iter().flatten().map(|c| c.distance as f64).sum();
        println!("{:.5} {sum}", pts.len() as f64 / t.elapsed().as_secs_f64() / 1e6);
        return Ok(());
    }
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
