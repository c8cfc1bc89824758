//! Worlds of instances, timed: 10,000 instances of a scene added and committed, a
//! frame that moves 1,000 of them, and primary rays and closest points through 100
//! instances against the same triangles placed and baked into one file, on one
//! thread.
//!
//! `cargo run --release -p octrace-runtime --example world_timing -- bunny.oct`
//! (`WORLD_SIDE=512` sets the image's side; `WORLD_NO_BAKE=1` skips the baked file.)
use std::sync::Arc;
use std::time::Instant;

use octrace_bake::procedural::SplitMix;
use octrace_bake::{bake, BuildParams, Mesh};
use octrace_runtime::raysets::{Camera, Frame};
use octrace_runtime::world::{Transform, World};
use octrace_runtime::Scene;

/// Instance `k` of a `side x side` grid in the x-z plane, turned about y.
fn grid_place(k: usize, side: usize, step: f64, rng: &mut SplitMix) -> Transform {
    let (i, j) = ((k % side) as f64, (k / side) as f64);
    let angle = std::f64::consts::TAU * rng.unit() as f64;
    Transform::rotation([0.0, 1.0, 0.0], angle).then(&Transform::translation([i * step, 0.0, j * step]))
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let path = std::env::args().nth(1).ok_or("usage: world_timing SCENE.oct")?;
    let side: u32 = std::env::var("WORLD_SIDE").map_or(Ok(512), |s| s.parse())?;
    let scene = Arc::new(Scene::open(&path)?);
    let view = scene.view();
    let b = view.bounds;
    let size = (0..3).fold(0.0f32, |m, k| m.max(b.mesh_hi[k] - b.mesh_lo[k])) as f64;
    let step = 1.5 * size;
    let one = rayon::ThreadPoolBuilder::new().num_threads(1).build()?;

    // 10,000 instances: the adds (each inverts its transform and boxes the scene),
    // then the commit (the top level built); then 1,000 moved and committed (refit).
    let (mut adds, mut commits, mut moves, mut refits, mut rebuilds) = (vec![], vec![], vec![], vec![], vec![]);
    for round in 0..5 {
        let mut rng = SplitMix(round);
        let places: Vec<Transform> = (0..10_000).map(|k| grid_place(k, 100, step, &mut rng)).collect();
        let mut world = World::new();
        let t = Instant::now();
        for p in &places {
            world.add(&scene, *p)?;
        }
        adds.push(t.elapsed().as_secs_f64() * 1e3);
        let t = Instant::now();
        world.commit();
        commits.push(t.elapsed().as_secs_f64() * 1e3);
        let moved: Vec<Transform> = (0..1000).map(|k| grid_place(k * 10, 100, step, &mut rng)).collect();
        let t = Instant::now();
        for (k, p) in moved.iter().enumerate() {
            world.set_transform((k * 10) as u32, *p)?;
        }
        moves.push(t.elapsed().as_secs_f64() * 1e3);
        let t = Instant::now();
        world.commit();
        refits.push(t.elapsed().as_secs_f64() * 1e3);
        let t = Instant::now();
        world.remove(5)?;
        world.commit();
        rebuilds.push(t.elapsed().as_secs_f64() * 1e3);
    }
    println!(
        "10,000 instances: adds {:.2} ms, commit {:.2} ms; 1,000 moved: set_transform {:.3} ms, commit {:.3} ms; \
         one removed: commit (rebuilt) {:.2} ms (medians of 5)",
        median(adds),
        median(commits),
        median(moves),
        median(refits),
        median(rebuilds)
    );

    // 100 instances, and the same triangles placed and baked into one file.
    let mut rng = SplitMix(100);
    // A 5 x 5 x 4 lattice, so that rays pass through several instances' boxes.
    let places: Vec<Transform> = (0..100)
        .map(|k| {
            let at = [(k % 5) as f64, (k / 5 % 5) as f64, (k / 25) as f64].map(|c| c * 1.2 * size);
            Transform::rotation([0.0, 1.0, 0.0], std::f64::consts::TAU * rng.unit() as f64)
                .then(&Transform::translation(at))
        })
        .collect();
    let mut world = World::new();
    for p in &places {
        world.add(&scene, *p)?;
    }
    world.commit();
    let (lo, hi) = (b.mesh_lo.map(f64::from), b.mesh_hi.map(f64::from));
    let mut wlo = [f64::INFINITY; 3];
    let mut whi = [f64::NEG_INFINITY; 3];
    for p in &places {
        for c in 0..8 {
            let v = p.point([0, 1, 2].map(|k| if c >> k & 1 == 0 { lo[k] } else { hi[k] }));
            for k in 0..3 {
                wlo[k] = wlo[k].min(v[k]);
                whi[k] = whi[k].max(v[k]);
            }
        }
    }
    let frame = Frame::from_bounds(wlo.map(|c| c as f32), whi.map(|c| c as f32));
    let rays = Camera::standard_sized(&frame, side, side).rays();
    let time = |f: &(dyn Fn() -> usize + Sync)| {
        let mut best = f64::INFINITY;
        let mut hits = 0;
        for _ in 0..3 {
            let t = Instant::now();
            hits = one.install(f);
            best = best.min(t.elapsed().as_secs_f64());
        }
        (rays.len() as f64 / best / 1e6, hits)
    };
    let (world_rate, world_hits) = time(&|| world.intersect_batch(&rays).iter().flatten().count());
    println!(
        "100 instances, {} primary rays: world {world_rate:.3} Mrays/s ({world_hits} hits), world {:.1} KB + scene {:.1} MB",
        rays.len(),
        world.bytes() as f64 / 1e3,
        std::fs::metadata(&path)?.len() as f64 / 1e6
    );
    if std::env::var_os("WORLD_NO_BAKE").is_some() {
        return Ok(());
    }
    let local: Vec<[[f32; 3]; 3]> =
        (0..view.triangle_count()).map(|i| view.triangle(octrace_runtime::format::StoredIndex(i as u32))).collect();
    let triangles: Vec<[[f32; 3]; 3]> = places
        .iter()
        .flat_map(|p| local.iter().map(move |t| t.map(|v| p.point(v.map(f64::from)).map(|c| c as f32))))
        .collect();
    let t = Instant::now();
    let baked = bake(&Mesh::from_triangles(triangles), &BuildParams::auto())?;
    let bake_s = t.elapsed().as_secs_f64();
    let file = std::env::temp_dir().join(format!("world_timing_{}.oct", std::process::id()));
    let file_bytes = baked.write(&file, 0)?;
    std::fs::remove_file(&file)?;
    let baked = Scene::from_baked(baked)?;
    let bytes = baked.view().triangle_count();
    let (one_rate, one_hits) = time(&|| baked.intersect_batch(&rays).iter().flatten().count());
    let (ray_rate, _) = time(&|| rays.iter().filter_map(|r| baked.intersect(r)).count());
    println!(
        "one file of the same {bytes} triangles ({:.1} MB, baked in {bake_s:.1} s): batch {one_rate:.3} Mrays/s \
         ({one_hits} hits), ray by ray {ray_rate:.3}; world / batch {:.2}x, world / ray by ray {:.2}x",
        file_bytes as f64 / 1e6,
        world_rate / one_rate,
        world_rate / ray_rate
    );
    let (world_any, _) = time(&|| world.occluded_batch(&rays).iter().filter(|&&b| b).count());
    let (one_any, _) = time(&|| baked.occluded_batch(&rays).iter().filter(|&&b| b).count());
    println!("occluded_batch: world {world_any:.3}, one file {one_any:.3} Mrays/s ({:.2}x)", world_any / one_any);
    // Closest points: 100,000 points uniform in the lattice's box (the search trees
    // made before the clock starts: best of three).
    let mut rng = SplitMix(7);
    let points: Vec<[f32; 3]> = (0..100_000)
        .map(|_| std::array::from_fn(|k| (wlo[k] + (whi[k] - wlo[k]) * rng.unit() as f64) as f32))
        .collect();
    let time_points = |f: &(dyn Fn() -> usize + Sync)| {
        let best = (0..3)
            .map(|_| {
                let t = Instant::now();
                one.install(f);
                t.elapsed().as_secs_f64()
            })
            .fold(f64::INFINITY, f64::min);
        points.len() as f64 / best / 1e6
    };
    let (world_near, one_near) = (
        time_points(&|| world.closest_points_batch(&points, f32::INFINITY).expect("even").len()),
        time_points(&|| baked.closest_points_batch(&points, f32::INFINITY).expect("memory").len()),
    );
    println!(
        "closest points, 100,000 uniform: world {world_near:.3}, one file {one_near:.3} M points/s ({:.2}x)",
        world_near / one_near
    );
    // Round twice, interleaved, for the noise.
    let (w2, _) = time(&|| world.intersect_batch(&rays).iter().flatten().count());
    let (o2, _) = time(&|| baked.intersect_batch(&rays).iter().flatten().count());
    println!("again: world {w2:.3}, one file {o2:.3} Mrays/s ({:.2}x)", w2 / o2);
    Ok(())
}
