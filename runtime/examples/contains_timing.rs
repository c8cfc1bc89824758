//! Inside/outside of points on one thread: points uniform in 1.1x the mesh's box, and
//! points within 1 % of the box's diagonal from the surface; prints the labels' time
//! and size, then points a second (median of three batches). `CONTAINS_CHECK=k` first
//! compares `k` points of each kind with the exact oracle (`reference::InsideReference`).
//!
//! `cargo run --release -p octrace-runtime --example contains_timing -- scene.oct [points]`
use std::time::Instant;

use octrace_runtime::cpu::Solid;
use octrace_runtime::reference::{InsideReference, Side};
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
    let (lo, hi) = (view.bounds.mesh_lo, view.bounds.mesh_hi);
    let size: [f32; 3] = [0, 1, 2].map(|k| hi[k] - lo[k]);
    let diag = size.iter().map(|s| s * s).sum::<f32>().sqrt();
    let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
    let uniform: Vec<[f32; 3]> =
        (0..n).map(|_| [0, 1, 2].map(|k| lo[k] - 0.05 * size[k] + 1.1 * size[k] * rng.unit())).collect();
    let triangles = view.triangle_count() as u64;
    let near: Vec<[f32; 3]> = (0..n)
        .map(|_| {
            let t = view.triangle(octrace_format::StoredIndex((rng.next() % triangles) as u32));
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
    for (name, pts) in [("uniform 1.1x box", &uniform), ("within 1% of the surface", &near)] {
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
