//! Embree 3 beside octrace in `bench` (the `embree` feature): one-ray calls, 16-ray
//! packets and octrace's one-ray calls, timed in the same runs.

use octrace_runtime::{Ray, Scene, Tracer};

use super::{median_ratio, mrays_of, EmbreeAllThreads, EmbreeFigures, Spread};

/// Embree's figures on one set, and octrace's one-ray calls, `runs` times interleaved
/// with octrace's batch: each run times octrace's batch, Embree one ray a call,
/// Embree's packets (primary), and octrace one ray a call, back to back.
pub(super) fn embree_figures(
    e: &crate::embree::Embree,
    scene: &Scene,
    name: &str,
    rays: &[Ray],
    occlusion: bool,
    tracer: &Tracer<'_>,
    runs: usize,
) -> EmbreeFigures {
    let timed = |f: &mut dyn FnMut()| mrays_of(rays.len(), f);
    let packets = camera_packets(name, rays);
    // Rays octrace's batch sorts (incoherent ones), in its order: Embree timed on them
    // too, so that the ratio says what the order buys either tracer.
    let ordered: Option<Vec<Ray>> = tracer.memory_order(rays).map(|o| o.iter().map(|&i| rays[i as usize]).collect());
    let (mut batch, mut one, mut packet, mut ours) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut one_ordered = Vec::new();
    let embree_count = |rays: &[Ray]| embree_one_ray_count(e, rays, occlusion);
    let mut hits = vec![None; rays.len()];
    let mut occluded = vec![false; rays.len()];
    let mut embree_hits = 0;
    for _ in 0..runs {
        batch.push(timed(&mut || {
            if occlusion {
                tracer.occluded_batch(rays, &mut occluded);
            } else {
                tracer.intersect_batch(rays, &mut hits);
            }
        }));
        one.push(timed(&mut || embree_hits = embree_count(rays)));
        if let Some(ordered) = &ordered {
            one_ordered.push(timed(&mut || {
                std::hint::black_box(embree_count(ordered));
            }));
        }
        if let Some(packets) = &packets {
            packet.push(timed(&mut || {
                std::hint::black_box(embree_packet_hits(e, rays, packets));
            }));
        }
        ours.push(timed(&mut || {
            std::hint::black_box(octrace_one_ray_count(scene, rays, occlusion));
        }));
    }
    EmbreeFigures {
        ratio_batch: median_ratio(&batch, &best_of(&one, &packet)),
        ratio_one_ray: median_ratio(&ours, &one),
        embree_one_ray: Spread::of(one),
        embree_packets: (!packet.is_empty()).then(|| Spread::of(packet)),
        embree_memory_order: (!one_ordered.is_empty()).then(|| {
            let ratio = median_ratio(&batch, &one_ordered);
            (Spread::of(one_ordered), ratio)
        }),
        octrace_one_ray: Spread::of(ours),
        embree_hits,
        all_threads: None,
    }
}

/// octrace's one-ray calls (`Scene::intersect`, `Scene::occluded`) on `rays`: how many
/// hit (or, for `occlusion`, are occluded).
fn octrace_one_ray_count(scene: &Scene, rays: &[Ray], occlusion: bool) -> usize {
    if occlusion {
        rays.iter().filter(|r| scene.occluded(r)).count()
    } else {
        rays.iter().filter(|r| scene.intersect(r).is_some()).count()
    }
}

/// Embree's one-ray calls on `rays`: how many hit (or, for `occlusion`, are occluded).
fn embree_one_ray_count(e: &crate::embree::Embree, rays: &[Ray], occlusion: bool) -> usize {
    if occlusion {
        rays.iter().filter(|r| e.occluded(r)).count()
    } else {
        rays.iter().filter(|r| e.nearest(r).is_some()).count()
    }
}

/// Embree's 16-ray packets of `rays` (indices, [`camera_packets`]): how many hit.
fn embree_packet_hits(e: &crate::embree::Embree, rays: &[Ray], packets: &[[usize; 16]]) -> usize {
    let mut out = [None; 16];
    packets
        .iter()
        .map(|p| {
            e.nearest16(&p.map(|i| rays[i]), &mut out);
            out.iter().flatten().count()
        })
        .sum()
}

/// Run by run, Embree's best: the better of one-ray calls and packets where packets ran.
fn best_of(one: &[f64], packet: &[f64]) -> Vec<f64> {
    if packet.is_empty() {
        one.to_vec()
    } else {
        one.iter().zip(packet).map(|(a, b)| a.max(*b)).collect()
    }
}

/// The standard camera's 1024 x 1024 rays (row by row) as 4 x 4 pixel packets, for
/// the primary set.
fn camera_packets(name: &str, rays: &[Ray]) -> Option<Vec<[usize; 16]>> {
    (name == "primary" && rays.len() == 1 << 20).then(|| {
        let tile = |tx: usize, ty: usize| std::array::from_fn(|k| (4 * ty + k / 4) * 1024 + 4 * tx + k % 4);
        (0..256).flat_map(|ty| (0..256).map(move |tx| tile(tx, ty))).collect()
    })
}

/// [`embree_figures`]'s figures on all threads of the current pool.
pub(super) fn embree_all_threads(
    e: &crate::embree::Embree,
    scene: &Scene,
    name: &str,
    rays: &[Ray],
    occlusion: bool,
    tracer: &Tracer<'_>,
    runs: usize,
) -> EmbreeAllThreads {
    use rayon::prelude::*;
    let timed = |f: &mut dyn FnMut()| mrays_of(rays.len(), f);
    let packets = camera_packets(name, rays);
    let (mut batch, mut one, mut packet, mut ours) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut hits = vec![None; rays.len()];
    let mut occluded = vec![false; rays.len()];
    for _ in 0..runs {
        batch.push(timed(&mut || {
            if occlusion {
                tracer.par_occluded_batch(rays, &mut occluded);
            } else {
                tracer.par_intersect_batch(rays, &mut hits);
            }
        }));
        one.push(timed(&mut || {
            std::hint::black_box(rays.par_chunks(1024).map(|c| embree_one_ray_count(e, c, occlusion)).sum::<usize>());
        }));
        if let Some(packets) = &packets {
            packet.push(timed(&mut || {
                std::hint::black_box(packets.par_chunks(64).map(|c| embree_packet_hits(e, rays, c)).sum::<usize>());
            }));
        }
        ours.push(timed(&mut || {
            std::hint::black_box(
                rays.par_chunks(1024).map(|c| octrace_one_ray_count(scene, c, occlusion)).sum::<usize>(),
            );
        }));
    }
    EmbreeAllThreads {
        threads: rayon::current_num_threads(),
        ratio_batch: median_ratio(&batch, &best_of(&one, &packet)),
        ratio_one_ray: median_ratio(&ours, &one),
        octrace_batch: Spread::of(batch),
        octrace_one_ray: Spread::of(ours),
        embree_one_ray: Spread::of(one),
        embree_packets: (!packet.is_empty()).then(|| Spread::of(packet)),
    }
}
