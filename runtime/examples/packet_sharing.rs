//! How much a packet walk could share on a scene's standard camera rays: every ray's
//! leaves (`Tracer::leaves_visited`), then packets of `w x h` pixels walked in
//! lockstep on paper. Each round, the packet's first unfinished ray names its current
//! leaf and every ray standing in that leaf takes its step there; the others wait.
//! A round stands for one packet step (one record load, one pass over the leaf's
//! triangles for all the rays in it); the rays stepped in a round are the lanes it
//! fills. The batch walk fills its eight lanes every step (a finished walk hands its
//! lane to the next ray), so a packet walk shares more than it wastes only where a
//! round steps more rays than that.
//!
//! `cargo run --release -p octrace-runtime --example packet_sharing -- scene.oct`
use octrace_runtime::raysets::{primary, Frame};
use octrace_runtime::Scene;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let path = std::env::args().nth(1).ok_or("usage: packet_sharing SCENE.oct")?;
    let scene = Scene::open(&path)?;
    let view = scene.view();
    let rays = primary(&Frame::from_bounds(view.bounds.mesh_lo, view.bounds.mesh_hi));
    let tracer = scene.tracer();
    let leaves: Vec<Vec<u32>> = rays.iter().map(|r| tracer.leaves_visited(r)).collect();
    let walked = leaves.iter().filter(|l| !l.is_empty()).count();
    let visits: usize = leaves.iter().map(Vec::len).sum();
    println!("{path}: {} camera rays, {walked} walked, {:.2} leaves a walk", rays.len(), visits as f64 / walked as f64);
    let side = 1024;
    for (w, h) in [(4, 2), (4, 4), (8, 8)] {
        let mut rounds = 0usize;
        for y0 in (0..side).step_by(h) {
            for x0 in (0..side).step_by(w) {
                let packet: Vec<&[u32]> = (0..h)
                    .flat_map(|y| (0..w).map(move |x| (y0 + y) * side + x0 + x))
                    .map(|i| leaves[i].as_slice())
                    .filter(|l| !l.is_empty())
                    .collect();
                let mut at = vec![0; packet.len()];
                while let Some(first) = (0..packet.len()).find(|&r| at[r] < packet[r].len()) {
                    let leaf = packet[first][at[first]];
                    rounds += 1;
                    for (r, l) in packet.iter().enumerate() {
                        if l.get(at[r]) == Some(&leaf) {
                            at[r] += 1;
                        }
                    }
                }
            }
        }
        println!(
            "  {w} x {h} packets: {rounds} rounds, {:.2} rays stepped a round (of {}; the batch walk's lanes: 8)",
            visits as f64 / rounds as f64,
            w * h
        );
    }
    Ok(())
}
