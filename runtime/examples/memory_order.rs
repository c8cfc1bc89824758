//! What memory order buys the batch calls on a scene's standard incoherent rays: the
//! one-thread batch walked as given and in memory order (sort included), interleaved
//! rounds, medians. `cargo run --release -p octrace-runtime --example memory_order --
//! dragon.oct`
use std::time::Instant;

use octrace_runtime::raysets::{incoherent, Frame};
use octrace_runtime::{MemoryOrder, Scene};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let path = std::env::args().nth(1).ok_or("usage: memory_order SCENE.oct")?;
    let scene = Scene::open(&path)?;
    let view = scene.view();
    let rays = incoherent(&Frame::from_bounds(view.bounds.mesh_lo, view.bounds.mesh_hi), 1_000_000);
    let given = scene.tracer().with_memory_order(MemoryOrder::Off);
    let sorted = scene.tracer().with_memory_order(MemoryOrder::Incoherent);
    let (mut a, mut b, mut sort) = (Vec::new(), Vec::new(), Vec::new());
    let (mut out_a, mut out_b) = (vec![None; rays.len()], vec![None; rays.len()]);
    for _ in 0..7 {
        let t = Instant::now();
        given.intersect_batch(&rays, &mut out_a);
        a.push(t.elapsed().as_secs_f64());
        let t = Instant::now();
        sorted.intersect_batch(&rays, &mut out_b);
        b.push(t.elapsed().as_secs_f64());
        let t = Instant::now();
        std::hint::black_box(sorted.memory_order(&rays));
        sort.push(t.elapsed().as_secs_f64());
        assert!(out_a == out_b, "the same answers in either order");
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let (a, b, sort) = (median(&mut a), median(&mut b), median(&mut sort));
    let auto = scene.tracer().memory_order(&rays).is_some();
    println!(
        "{path}: 1,000,000 incoherent rays, 1 thread: as given {:.2} Mrays/s, in memory order {:.2} Mrays/s \
         ({:.2}x; the order alone {:.1} ms); MemoryOrder::Auto {} this scene",
        1.0 / a,
        1.0 / b,
        a / b,
        sort * 1e3,
        if auto { "sorts for" } else { "leaves as given for" }
    );
    Ok(())
}
