//! What reading ahead buys the one-ray calls (`Tracer::with_read_ahead`) on a scene's
//! standard rays: each set traced one ray at a time (`Tracer::intersect`, or
//! `Tracer::occluded` for the shadow set) with reading ahead off and on, 7 interleaved
//! rounds, one thread; medians, and the median of the rounds' on/off ratios.
//! `cargo run --release -p octrace-runtime --example read_ahead -- dragon.oct`
use std::time::Instant;

use octrace_runtime::raysets::{incoherent, primary, shadow, Frame};
use octrace_runtime::{Ray, Scene};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let path = std::env::args().nth(1).ok_or("usage: read_ahead SCENE.oct")?;
    let scene = Scene::open(&path)?;
    let view = scene.view();
    let frame = Frame::from_bounds(view.bounds.mesh_lo, view.bounds.mesh_hi);
    let camera = primary(&frame);
    let hits: Vec<_> = camera.iter().map(|r| scene.intersect(r)).collect();
    let lights = shadow(&frame, |i| hits[i].map(|h| (h.t, view.triangle(h.prim))));
    let sets: [(&str, Vec<Ray>, bool); 3] =
        [("incoherent", incoherent(&frame, 300_000), false), ("primary", camera, false), ("shadow", lights, true)];
    for (name, rays, occlusion) in sets {
        let (mut off, mut on) = (Vec::new(), Vec::new());
        for _ in 0..7 {
            for (ahead, rates) in [(false, &mut off), (true, &mut on)] {
                let tracer = scene.tracer().with_read_ahead(ahead);
                let start = Instant::now();
                let hit = rays
                    .iter()
                    .filter(|r| if occlusion { tracer.occluded(r) } else { tracer.intersect(r).is_some() })
                    .count();
                rates.push(rays.len() as f64 / start.elapsed().as_secs_f64() / 1e6);
                std::hint::black_box(hit);
            }
        }
        let median = |v: &mut Vec<f64>| {
            v.sort_by(f64::total_cmp);
            v[v.len() / 2]
        };
        let mut ratios: Vec<f64> = off.iter().zip(&on).map(|(a, b)| b / a).collect();
        let (off, on, ratio) = (median(&mut off), median(&mut on), median(&mut ratios));
        println!("{path} {name}, one ray a call: off {off:.3}, on {on:.3} Mrays/s, on / off {ratio:.3}");
    }
    Ok(())
}
