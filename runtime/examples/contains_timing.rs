//! Inside/outside of points on one thread: points uniform in 1.1x the mesh's box, and
//! points within 1 % of the box's diagonal from the surface; prints the labels' time
//! and size, then points a second (median of three batches). `CONTAINS_CHECK=k` first
//! compares `k` points of each kind with the exact oracle (`reference::InsideReference`);
//! `CONTAINS_ONLY=uniform` (or `near`) times that set alone (for profiles and A/B runs).
//!
//! `cargo run --release -p octrace-runtime --example contains_timing -- scene.oct [points]`
use std::time::Instant;

use octrace_runtime::cpu::Solid;
use octrace_runtime::reference::{InsideReference, Side};
use octrace_runtime::Scene;

#[path = "shared/point_sets.rs"]
mod point_sets;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let path = args.next().ok_or("usage: contains_timing SCENE.oct [points]")?;
    let n: usize = args.next().map_or(Ok(1_000_000), |s| s.parse())?;
    let scene = Scene::open(&path)?;
    let view = scene.view();
    let tracer = scene.tracer();
    let t = Instant::now();
    let solid = Solid::of(&tracer)?;
    println!(
        "labels: {:.0} ms, grid {:.1} MiB",
        t.elapsed().as_secs_f64() * 1e3,
        solid.grid_bytes() as f64 / (1 << 20) as f64
    );
    let (uniform, near) = point_sets::point_sets(&view, n);
    if let Some(k) = std::env::var_os("CONTAINS_CHECK") {
        let k: usize = k.to_str().and_then(|s| s.parse().ok()).unwrap_or(10_000);
        let oracle = InsideReference::new(&view.stored_triangles().collect::<Vec<_>>());
        let mut wrong = 0;
        for p in uniform.iter().take(k).chain(near.iter().take(k)) {
            let exact = oracle.side(*p);
            if exact != Some(Side::Surface)
                && exact.is_some()
                && (exact == Some(Side::Inside)) != tracer.contains(&solid, *p)
            {
                wrong += 1;
            }
        }
        println!("against the exact oracle: {wrong} wrong of {}", 2 * k);
    }
    let mut out = vec![false; n];
    let only = std::env::var("CONTAINS_ONLY").ok();
    for (name, pts) in [("uniform 1.1x box", &uniform), ("within 1% of the surface", &near)] {
        if only.as_deref().is_some_and(|o| !name.starts_with(if o == "near" { "within" } else { "uniform" })) {
            continue;
        }
        let mut rates: Vec<f64> = (0..3)
            .map(|_| {
                let t = Instant::now();
                tracer.contains_batch(&solid, pts, &mut out);
                n as f64 / t.elapsed().as_secs_f64() / 1e6
            })
            .collect();
        rates.sort_by(f64::total_cmp);
        let inside = out.iter().filter(|&&x| x).count();
        println!("{name}: {:.2} M points/s (median of 3), {inside} inside", rates[1]);
    }
    Ok(())
}
