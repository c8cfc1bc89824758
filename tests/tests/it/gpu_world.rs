//! Worlds of instances with the instances' walks on the GPU ([`GpuWorld`]): the
//! CPU's world answers, bit for bit, on lavapipe in CI.

use std::sync::Arc;

use octrace_bake::procedural::{self, SplitMix};
use octrace_bake::Mesh;
use octrace_runtime::glam::Vec3;
use octrace_runtime::world::{GpuWorld, Transform, World, WorldCrossing, WorldHit};
use octrace_runtime::{Ray, Scene};
use octrace_tests::gpu;

use crate::world::{placement, rays, scene};

fn scenes(meshes: [Mesh; 3]) -> Vec<Arc<Scene>> {
    meshes.map(|m| scene(&m)).into()
}

/// The GPU's nearest and any hits, crossing counts and lists against the CPU's,
/// bit for bit: the
/// instance, triangle, part, distance and barycentrics (the leaf a walk found the hit
/// in is the walk's business, and may differ, as for a scene's GPU tracer).
fn same_as_cpu(on_gpu: &mut GpuWorld, world: &World, rays: &[Ray]) -> usize {
    let cpu = world.intersect_batch(rays);
    let gpu = on_gpu.intersect(world, rays).expect("traced on the GPU");
    let key = |h: &Option<WorldHit>| {
        h.map(|h| (h.instance, h.hit.triangle, h.hit.prim, h.hit.t.to_bits(), h.hit.u.to_bits(), h.hit.v.to_bits()))
    };
    for (i, (c, g)) in cpu.iter().zip(&gpu).enumerate() {
        assert_eq!(key(c), key(g), "ray {i} {:?}: CPU {c:?}, GPU {g:?}", rays[i]);
    }
    assert_eq!(on_gpu.occluded(world, rays).expect("traced on the GPU"), world.occluded_batch(rays));
    // Crossings, counted and listed in order: the CPU's (floats compared by bits).
    let counts = on_gpu.count_crossings(world, rays).expect("counted on the GPU");
    assert_eq!(counts, world.count_crossings_batch(rays));
    let lists = on_gpu.crossings(world, rays).expect("listed on the GPU");
    let bits = |c: &WorldCrossing| {
        let x = c.crossing;
        (c.instance, x.triangle, x.t.to_bits(), x.u.to_bits(), x.v.to_bits(), x.enters)
    };
    for (i, (ray, list)) in rays.iter().zip(&lists).enumerate() {
        let want: Vec<_> = world.crossings(ray).iter().map(bits).collect();
        assert_eq!(list.iter().map(bits).collect::<Vec<_>>(), want, "ray {i} {ray:?}: crossings");
    }
    assert!(counts.iter().any(|c| c.total >= 2), "rays should cross something twice");
    cpu.iter().flatten().count()
}

/// Hundreds of instances of three scenes, placed, moved, removed and added: the
/// GPU's answers are the CPU's after every commit, and a world whose instances move
/// uploads nothing again.
#[test]
fn a_world_on_the_gpu_answers_as_on_the_cpu() {
    let Some(gpu) = gpu("a_world_on_the_gpu_answers_as_on_the_cpu") else { return };
    let props = scenes([
        procedural::sphere([0.2, -0.1, 0.3], 1.0, 12, 18),
        procedural::cube([-1.0; 3], [1.0; 3], 3),
        procedural::grid(5, 2.0),
    ]);
    let mut rng = SplitMix(61);
    let reach = 12.0;
    let mut world = World::new();
    let mut ids: Vec<u32> =
        (0..240).map(|k| world.add(&props[k % 3], placement(&mut rng, reach)).expect("placed")).collect();
    world.commit();
    let mut rays = rays(&mut rng, 3000, reach as f32);
    // From far away (origins moved to just before the instances' boxes, distances
    // shifted back), segments ending at a hit, an ulp before and an ulp after it.
    let far: Vec<Ray> = rays.iter().take(600).map(|r| Ray::new(r.origin * 10.0, -r.origin)).collect();
    for (ray, hit) in far.iter().zip(world.intersect_batch(&far)) {
        let Some(h) = hit else { continue };
        for tmax in [h.hit.t, h.hit.t.next_down(), h.hit.t.next_up()] {
            rays.push(Ray { tmax, ..*ray });
        }
    }
    let mut on_gpu = GpuWorld::new(&gpu.device, &gpu.queue);
    let hits = same_as_cpu(&mut on_gpu, &world, &rays);
    assert!(hits > 1000, "{hits} hits: the rays should meet the crowd");
    assert_eq!(on_gpu.scenes(), 3);

    for &id in ids.iter().step_by(2) {
        world.set_transform(id, placement(&mut rng, reach)).expect("moved");
    }
    world.commit();
    same_as_cpu(&mut on_gpu, &world, &rays);
    assert_eq!(on_gpu.scenes(), 3, "moving instances uploads nothing");

    // The grids gone, a new scene come.
    for (k, &id) in ids.iter().enumerate() {
        if k % 3 == 2 {
            world.remove(id).expect("removed");
        }
    }
    let torus =
        scenes([procedural::torus([0.0; 3], 1.0, 0.3, 24, 12), procedural::grid(1, 1.0), procedural::grid(1, 1.0)]);
    for _ in 0..30 {
        ids.push(world.add(&torus[0], placement(&mut rng, reach)).expect("placed"));
    }
    world.commit();
    same_as_cpu(&mut on_gpu, &world, &rays);
    assert_eq!(on_gpu.scenes(), 4);
    on_gpu.retain(&world);
    assert_eq!(on_gpu.scenes(), 3, "the grids' scene is no longer placed");
    same_as_cpu(&mut on_gpu, &world, &rays);

    // An empty world, and rays that are not traceable.
    let empty = World::new();
    assert!(on_gpu.intersect(&empty, &rays).expect("traced").iter().all(Option::is_none));
    let odd = [Ray::new(Vec3::NAN, Vec3::X), Ray::new(Vec3::ZERO, Vec3::ZERO)];
    assert_eq!(on_gpu.intersect(&world, &odd).expect("traced"), vec![None, None]);
}

/// Thousands of small instances, crowded: rays whose walks enter more boxes than
/// the GPU's rounds take are finished on the CPU, with the same answers.
#[test]
fn a_crowded_world_on_the_gpu_answers_as_on_the_cpu() {
    let Some(gpu) = gpu("a_crowded_world_on_the_gpu_answers_as_on_the_cpu") else { return };
    let props = scenes([
        procedural::sphere([0.0; 3], 1.0, 6, 8),
        procedural::cube([-1.0; 3], [1.0; 3], 1),
        procedural::grid(2, 1.5),
    ]);
    let mut rng = SplitMix(63);
    let reach = 30.0;
    let mut world = World::new();
    for k in 0..4000 {
        world.add(&props[k % 3], placement(&mut rng, reach)).expect("placed");
    }
    // A row of 200 spheres along x, then a wall: a ray along the row through the
    // corners of the spheres' boxes enters 200 boxes before it meets the wall.
    for k in 0..200 {
        world.add(&props[0], Transform::translation([3.0 * f64::from(k) - 300.0, 100.0, 0.0])).expect("placed");
    }
    let wall = Transform::scaling([1.0, 4.0, 4.0]).then(&Transform::translation([310.0, 100.0, 0.0]));
    world.add(&props[1], wall).expect("placed");
    world.commit();
    // Enough rays for a round of the GPU's to carry its rays on all cores.
    let mut rays = rays(&mut rng, 20_000, reach as f32);
    let mut row = Vec::new();
    for k in 0..64 {
        let (y, z) = (100.9 + (k % 8) as f32 * 1e-3, 0.9 - (k / 8) as f32 * 1e-3);
        row.push(Ray::new(Vec3::new(-400.0, y, z), Vec3::new(1.0, 1e-6 * k as f32, 0.0)));
        // Segments ending before the wall, and at it.
        row.push(Ray::segment(Vec3::new(-400.0, y, z), Vec3::X, 0.0, 600.0 + 10.0 * k as f32));
    }
    let walled = row.iter().filter_map(|r| world.intersect(r)).filter(|h| h.instance == 4200).count();
    assert!(walled >= 64, "{walled} rays along the row meet the wall");
    rays.extend(row);
    let mut on_gpu = GpuWorld::new(&gpu.device, &gpu.queue);
    let hits = same_as_cpu(&mut on_gpu, &world, &rays);
    assert!(hits > 1000, "{hits} hits");
}
