//! `octrace bench --instances N`: the scene placed N times in a lattice, traced as a
//! world of instances (`octrace_runtime::world`), beside Embree 3's instances of it
//! (the `embree` feature), on the standard camera's rays of the world's box; with
//! `--gpu`, the world on the GPU (`GpuWorld`) beside the CPU's batch on all cores.

use std::sync::Arc;
use std::time::Instant;

use octrace_bake::procedural::SplitMix;
use octrace_runtime::raysets::{Camera, Frame};
use octrace_runtime::world::{Transform, World};
#[cfg(feature = "embree")]
use octrace_runtime::Ray;
use serde_json::json;

#[cfg(feature = "embree")]
use super::median_ratio;
use super::{mrays_of, Args, Loaded, Spread};
use crate::output::thousands;

/// The placements: a lattice of `n` (side the cube root, rounded up), 1.2 times the
/// scene's largest extent apart, each turned about y by a seeded random angle.
fn lattice(lo: [f32; 3], hi: [f32; 3], n: usize) -> Vec<Transform> {
    let size = (0..3).fold(0.0f32, |m, k| m.max(hi[k] - lo[k])) as f64;
    let side = (1..).find(|s: &usize| s * s * s >= n).unwrap_or(1);
    let mut rng = SplitMix(100);
    (0..n)
        .map(|k| {
            let at = [k % side, k / side % side, k / (side * side)].map(|c| c as f64 * 1.2 * size);
            let turn = Transform::rotation([0.0, 1.0, 0.0], std::f64::consts::TAU * rng.unit() as f64);
            turn.then(&Transform::translation(at))
        })
        .collect()
}

/// The world box of `placements` of the box `lo..hi`.
fn world_box(lo: [f32; 3], hi: [f32; 3], placements: &[Transform]) -> ([f32; 3], [f32; 3]) {
    let (mut wlo, mut whi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    for p in placements {
        for c in 0..8 {
            let v = p.point([0, 1, 2].map(|k| f64::from(if c >> k & 1 == 0 { lo[k] } else { hi[k] })));
            for k in 0..3 {
                wlo[k] = wlo[k].min(v[k]);
                whi[k] = whi[k].max(v[k]);
            }
        }
    }
    (wlo.map(|c| c as f32), whi.map(|c| c as f32))
}

pub(super) fn run(loaded: Loaded, n: usize, args: &Args) -> anyhow::Result<()> {
    let scene = Arc::new(loaded.scene);
    let view = scene.view();
    let (lo, hi) = (view.bounds.mesh_lo, view.bounds.mesh_hi);
    let placements = lattice(lo, hi, n);
    let mut world = World::new();
    let t = Instant::now();
    for p in &placements {
        world.add(&scene, *p)?;
    }
    let adds = t.elapsed();
    let t = Instant::now();
    world.commit();
    let commit = t.elapsed();
    let (wlo, whi) = world_box(lo, hi, &placements);
    let rays = Camera::standard(&Frame::from_bounds(wlo, whi)).rays();
    let one = rayon::ThreadPoolBuilder::new().num_threads(1).build()?;
    let hits_of = |hits: &[Option<octrace_runtime::world::WorldHit>]| hits.iter().flatten().count();
    let (mut batch, mut single) = (Vec::new(), Vec::new());
    let mut octrace_hits = 0;
    #[cfg(feature = "embree")]
    let embree = if args.no_peer {
        None
    } else {
        let rows: Vec<[[f32; 4]; 3]> = placements.iter().map(|p| p.rows.map(|r| r.map(|x| x as f32))).collect();
        Some(crate::embree::Embree::build(&view, false)?.instanced(&rows)?)
    };
    #[cfg(feature = "embree")]
    let (mut embree_one, mut embree_packets, mut embree_hits) = (Vec::new(), Vec::new(), 0);
    for _ in 0..args.runs {
        batch.push(mrays_of(rays.len(), &mut || octrace_hits = hits_of(&one.install(|| world.intersect_batch(&rays)))));
        single.push(mrays_of(rays.len(), &mut || {
            std::hint::black_box(rays.iter().filter(|r| world.intersect(r).is_some()).count());
        }));
        #[cfg(feature = "embree")]
        if let Some(e) = &embree {
            embree_one.push(mrays_of(rays.len(), &mut || embree_hits = embree_count(e, &rays)));
            embree_packets.push(mrays_of(rays.len(), &mut || {
                std::hint::black_box(embree_packet_count(e, &rays));
            }));
        }
    }
    let gpu = if args.gpu { Some(on_gpu(&world, &rays, args.runs)?) } else { None };
    #[cfg_attr(not(feature = "embree"), allow(unused_mut))]
    let mut report = json!({
        "instances": n,
        "scene_triangles": view.triangle_count(),
        "world_triangles": view.triangle_count() * n,
        "scene_bytes": loaded.bytes,
        "world_bytes": world.bytes(),
        "add_ms": adds.as_secs_f64() * 1e3,
        "commit_ms": commit.as_secs_f64() * 1e3,
        "rays": rays.len(),
        "octrace_hits": octrace_hits,
        "octrace_batch": Spread::of(batch.clone()),
        "octrace_one_ray": Spread::of(single.clone()),
    });
    if let Some(g) = gpu {
        report["gpu"] = g;
    }
    #[cfg(feature = "embree")]
    if let Some(e) = &embree {
        let best: Vec<f64> = embree_one.iter().zip(&embree_packets).map(|(a, b)| a.max(*b)).collect();
        report["embree"] = json!({
            "build_ms": e.build_time.as_secs_f64() * 1e3,
            "hits": embree_hits,
            "one_ray": Spread::of(embree_one.clone()),
            "packets": Spread::of(embree_packets.clone()),
            "ratio_batch": median_ratio(&batch, &best),
            "ratio_one_ray": median_ratio(&single, &embree_one),
        });
    }
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
        return Ok(());
    }
    let s = |v: &serde_json::Value| {
        format!(
            "{:.3} ({:.3}-{:.3})",
            v["median"].as_f64().unwrap_or(0.0),
            v["min"].as_f64().unwrap_or(0.0),
            v["max"].as_f64().unwrap_or(0.0)
        )
    };
    println!(
        "world: {n} instances of {} triangles ({} placed), {} KB beside the scene's {} KB; {} adds in {:.2} ms, commit {:.2} ms",
        thousands(view.triangle_count() as u64),
        thousands((view.triangle_count() * n) as u64),
        world.bytes() / 1000,
        loaded.bytes / 1000,
        thousands(n as u64),
        adds.as_secs_f64() * 1e3,
        commit.as_secs_f64() * 1e3
    );
    println!(
        "{} camera rays of the world's box, one thread, Mrays/s, median (min-max) of {} runs:",
        thousands(rays.len() as u64),
        args.runs
    );
    println!("  octrace world, batch      {}  ({} hits)", s(&report["octrace_batch"]), thousands(octrace_hits as u64));
    println!("  octrace world, one ray    {}", s(&report["octrace_one_ray"]));
    if let Some(g) = report.get("gpu") {
        println!("on the GPU ({}), all cores for the host's part:", g["adapter"].as_str().unwrap_or("?"));
        println!(
            "  octrace world, GPU         {}  (the CPU's answers: {}; scenes uploaded in {:.1} ms)",
            s(&g["world"]),
            if g["same_as_cpu"].as_bool() == Some(true) { "yes" } else { "NO" },
            g["upload_ms"].as_f64().unwrap_or(0.0)
        );
        println!("  octrace world, CPU batch   {}  (all cores)", s(&g["cpu_all_cores"]));
        let t = &g["last_batch_ms"];
        let f = |k: &str| t[k].as_f64().unwrap_or(0.0);
        println!(
            "  the last GPU batch: {:.1} ms = top level {:.1} + GPU calls {:.1} + carrying and merging {:.1} + \
             finished on the CPU {:.1} ({} rays); {} rounds",
            f("total"),
            f("top_level"),
            f("device"),
            f("rounds"),
            f("finish"),
            t["finished_on_cpu"],
            t["round_count"]
        );
    }
    if let Some(e) = report.get("embree") {
        println!(
            "  Embree 3 instances, one ray   {}  ({} hits; built in {:.2} ms)",
            s(&e["one_ray"]),
            e["hits"],
            e["build_ms"].as_f64().unwrap_or(0.0)
        );
        println!("  Embree 3 instances, packets   {}", s(&e["packets"]));
        println!(
            "  octrace / Embree: batch / best {:.2}x, one ray / one ray {:.2}x",
            e["ratio_batch"].as_f64().unwrap_or(0.0),
            e["ratio_one_ray"].as_f64().unwrap_or(0.0)
        );
    }
    Ok(())
}

/// The world on the GPU (`GpuWorld`): the scenes' upload, Mrays/s of `runs` batches
/// beside the CPU's batch on all cores in the same runs, and whether every answer is
/// the CPU's (the leaf a walk found a hit in aside).
fn on_gpu(world: &World, rays: &[octrace_runtime::Ray], runs: usize) -> anyhow::Result<serde_json::Value> {
    let context = octrace_runtime::gpu::GpuContext::new()?;
    let mut gpu = octrace_runtime::world::GpuWorld::new(&context.device, &context.queue);
    let t = Instant::now();
    gpu.upload(world)?;
    let upload = t.elapsed();
    let (mut on_gpu, mut on_cpu) = (Vec::new(), Vec::new());
    let (mut gpu_hits, mut cpu_hits) = (Vec::new(), Vec::new());
    for _ in 0..runs {
        let mut failed = None;
        on_gpu.push(mrays_of(rays.len(), &mut || match gpu.intersect(world, rays) {
            Ok(h) => gpu_hits = h,
            Err(e) => failed = Some(e),
        }));
        if let Some(e) = failed {
            return Err(e.into());
        }
        on_cpu.push(mrays_of(rays.len(), &mut || cpu_hits = world.intersect_batch(rays)));
    }
    let key = |h: &Option<octrace_runtime::world::WorldHit>| {
        h.map(|h| (h.instance, h.hit.triangle, h.hit.t.to_bits(), h.hit.u.to_bits(), h.hit.v.to_bits()))
    };
    let same = gpu_hits.iter().zip(&cpu_hits).all(|(g, c)| key(g) == key(c));
    let t = gpu.timings();
    let ms = |d: std::time::Duration| d.as_secs_f64() * 1e3;
    Ok(json!({
        "adapter": context.describe(),
        "upload_ms": upload.as_secs_f64() * 1e3,
        "last_batch_ms": {
            "total": ms(t.total), "top_level": ms(t.top), "device": ms(t.device), "rounds": ms(t.rounds),
            "finish": ms(t.finish), "round_count": t.round_count, "finished_on_cpu": t.finished_on_cpu,
        },
        "world": Spread::of(on_gpu),
        "cpu_all_cores": Spread::of(on_cpu),
        "same_as_cpu": same,
    }))
}

/// Embree's one-ray calls: how many hit.
#[cfg(feature = "embree")]
fn embree_count(e: &crate::embree::Embree, rays: &[Ray]) -> usize {
    rays.iter().filter(|r| e.nearest(r).is_some()).count()
}

/// Embree's 4 x 4 pixel packets of the 1024 x 1024 camera: how many hit.
#[cfg(feature = "embree")]
fn embree_packet_count(e: &crate::embree::Embree, rays: &[Ray]) -> usize {
    let mut out = [None; 16];
    let mut hits = 0;
    for ty in 0..256 {
        for tx in 0..256 {
            let packet: [Ray; 16] = std::array::from_fn(|k| rays[(4 * ty + k / 4) * 1024 + 4 * tx + k % 4]);
            e.nearest16(&packet, &mut out);
            hits += out.iter().flatten().count();
        }
    }
    hits
}
