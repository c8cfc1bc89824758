//! What two ways of skipping work could save on a scene's standard rays, on paper, from
//! every ray's leaves (`Tracer::leaves_visited`):
//! * empty-space jumps: a walk standing in an empty leaf jumps to where it leaves the
//!   leaf's largest empty ancestor cell (the highest cell holding it whose subtree has no
//!   triangle) and locates the leaf there again; the leaves it crossed inside that cell
//!   are not visited. Prints the leaves a walk visits today, the steps it would take
//!   (non-empty leaves, empty leaves with no larger empty ancestor, and jumps), and how
//!   many of those are jumps;
//! * mailboxes: a triangle listed in several leaves is tested again in each. Prints the
//!   triangle tests and batches of eight (`hit8` calls) a walk makes today, the batches
//!   left when a leaf whose triangles were all tested in the previous non-empty leaf is
//!   skipped, and the tests and batches left when no triangle is tested twice.
//!
//! `cargo run --release -p octrace-runtime --example skip_estimates -- scene.oct`
use std::collections::HashSet;

use octrace_runtime::raysets::{incoherent, primary, shadow, Frame};
use octrace_runtime::Scene;

/// A cell: its level and its integer coordinates at that level.
type Cell = (u32, [u32; 3]);

fn parent((level, c): Cell) -> Cell {
    (level - 1, [c[0] >> 1, c[1] >> 1, c[2] >> 1])
}

fn holds(outer: Cell, inner: Cell) -> bool {
    inner.0 >= outer.0 && (0..3).all(|a| inner.1[a] >> (inner.0 - outer.0) == outer.1[a])
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let path = std::env::args().nth(1).ok_or("usage: skip_estimates SCENE.oct")?;
    let scene = Scene::open(&path)?;
    let view = scene.view();
    let b = &view.bounds;
    // Every leaf's cell and triangle references, by box index.
    let mut cells = vec![(0u32, [0u32; 3]); view.leaf_count()];
    let mut occupied: HashSet<Cell> = HashSet::new();
    let mut refs_of = vec![Vec::new(); view.leaf_count()];
    for rec in view.leaves() {
        let bx = view.leaf_box(rec.box_index);
        let size = bx[3] - bx[0];
        let level = (b.root_size / size).log2().round() as u32;
        let c = [0, 1, 2].map(|a| ((bx[a] - b.root_lo[a]) / size).round() as u32);
        let cell = (level, c);
        cells[rec.box_index as usize] = cell;
        refs_of[rec.box_index as usize] =
            view.tri_refs[rec.tri_offset as usize..(rec.tri_offset + rec.tri_count) as usize].to_vec();
        if rec.tri_count > 0 {
            let mut up = cell;
            while occupied.insert(up) && up.0 > 0 {
                up = parent(up);
            }
        }
    }
    // The largest empty cell holding each empty leaf.
    let widest: Vec<Cell> = cells
        .iter()
        .map(|&cell| {
            let mut top = cell;
            while top.0 > 0 && !occupied.contains(&parent(top)) {
                top = parent(top);
            }
            top
        })
        .collect();

    let frame = Frame::from_bounds(b.mesh_lo, b.mesh_hi);
    let tracer = scene.tracer();
    let camera = primary(&frame);
    let mut hits = vec![None; camera.len()];
    tracer.intersect_batch(&camera, &mut hits);
    let sets = [
        ("primary", camera),
        ("incoherent", incoherent(&frame, 200_000)),
        ("shadow", shadow(&frame, |i| hits[i].map(|h| (h.t, view.triangle(h.prim))))),
    ];
    println!("{path}: {} leaves, {} empty", cells.len(), refs_of.iter().filter(|r| r.is_empty()).count());
    for (name, rays) in sets {
        let (mut walks, mut visits, mut empty, mut steps, mut jumps, mut jumped) = (0usize, 0, 0, 0, 0, 0);
        let (mut calls, mut calls_prev, mut calls_any, mut tests, mut tests_any) = (0usize, 0, 0, 0, 0);
        for ray in &rays {
            let leaves = tracer.leaves_visited(ray);
            if leaves.is_empty() {
                continue;
            }
            walks += 1;
            visits += leaves.len();
            let mut seen: HashSet<u32> = HashSet::new();
            let mut prev: Vec<u32> = Vec::new();
            for &l in &leaves {
                let refs = &refs_of[l as usize];
                if refs.is_empty() {
                    continue;
                }
                calls += refs.len().div_ceil(8);
                tests += refs.len();
                if !refs.iter().all(|r| prev.contains(r)) {
                    calls_prev += refs.len().div_ceil(8);
                }
                let fresh = refs.iter().filter(|r| !seen.contains(r)).count();
                calls_any += fresh.div_ceil(8);
                tests_any += fresh;
                seen.extend(refs.iter().copied());
                prev = refs.clone();
            }
            let mut i = 0;
            while i < leaves.len() {
                let leaf = leaves[i] as usize;
                steps += 1;
                i += 1;
                if !refs_of[leaf].is_empty() {
                    continue;
                }
                empty += 1;
                let top = widest[leaf];
                if top == cells[leaf] {
                    continue;
                }
                jumps += 1;
                while i < leaves.len() && holds(top, cells[leaves[i] as usize]) {
                    i += 1;
                    jumped += 1;
                }
            }
        }
        let per = |n: usize| n as f64 / walks as f64;
        println!(
            "  {name}: {walks} walks, {:.2} leaves a walk ({:.2} empty); with jumps {:.2} steps a walk, \
             {:.2} of them jumps over {:.2} leaves each",
            per(visits),
            per(empty),
            per(steps),
            per(jumps),
            if jumps > 0 { (jumped + jumps) as f64 / jumps as f64 } else { 0.0 }
        );
        println!(
            "    tests {:.2} in {:.2} batches of 8; leaves all tested in the previous non-empty leaf skipped: {:.2} batches; \
             every triangle tested once: {:.2} tests in {:.2} batches",
            per(tests),
            per(calls),
            per(calls_prev),
            per(tests_any),
            per(calls_any)
        );
    }
    Ok(())
}
