//! Every crossing and crossing counts on the GPU (`GpuTracer::crossings`,
//! `GpuTracer::count_crossings`): the CPU's lists and counts, ray for ray, bit for bit
//! where the adapter has f64 (lavapipe has), on random rays bent where f32 gives out,
//! rays on the octree's planes aimed at vertices, rays from inside closed solids
//! through their vertices and edges, and far origins; lengths inside closed solids.

use glam::Vec3;
use octrace_bake::hard_rays::GridPlanes;
use octrace_bake::procedural::{self, SplitMix};
use octrace_bake::BuildParams;
use octrace_runtime::cpu::{BatchCrossings, Crossing};
use octrace_runtime::gpu::GpuTracer;
use octrace_runtime::{Ray, Scene};
use octrace_tests::{gpu, gpu_default_cpu};

use crate::crossings::{random_rays, scene_of, test_meshes};

/// A crossing's bits, so that -0.0 and 0.0 differ.
fn bits(c: &Crossing) -> (u32, u32, u32, u32, bool) {
    (c.t.to_bits(), c.triangle, c.u.to_bits(), c.v.to_bits(), c.enters)
}

/// The GPU's lists and counts for `rays` against the CPU's batch and one-ray walks.
/// Returns the crossings compared.
fn gpu_equals_cpu(name: &str, gpu: &octrace_runtime::gpu::GpuContext, scene: &Scene, rays: &[Ray]) -> usize {
    let tracer = GpuTracer::new(&gpu.device, &gpu.queue, scene).unwrap();
    let cpu = gpu_default_cpu(scene);
    let want: BatchCrossings = cpu.par_crossings_batch(rays, usize::MAX);
    let got = tracer.crossings(rays).unwrap();
    let counts = tracer.count_crossings(rays).unwrap();
    assert_eq!(got.splits.len(), rays.len() + 1, "{name}");
    let mut differ = 0;
    for (i, r) in rays.iter().enumerate() {
        let (w, g) = (want.of(i), got.of(i));
        let same = w.len() == g.len() && w.iter().zip(g).all(|(a, b)| bits(a) == bits(b));
        if tracer.uses_f64() {
            assert!(same, "{name}: ray {i} {r:?}\nCPU {w:?}\nGPU {g:?}");
            assert_eq!(w, &cpu.all_crossings(r)[..], "{name}: ray {i}: one ray and batch");
        }
        differ += !same as usize;
        let c = counts[i];
        assert_eq!(c.total as usize, g.len(), "{name}: ray {i}: count and list");
        assert_eq!(c.entries as usize, g.iter().filter(|x| x.enters).count(), "{name}: ray {i}: entries");
    }
    // Without f64 the last bits are the adapter's: nearly every list still agrees.
    assert!(differ * 100 <= rays.len(), "{name}: {differ} of {} rays differ", rays.len());
    want.crossings.len()
}

/// Random rays (with subnormal components, 1e-30 and 1e25 lengths, origins 1e6 mesh
/// sizes away) on meshes open and closed, at several depths.
#[test]
fn gpu_crossings_equal_the_cpus_on_random_and_far_rays() {
    let Some(gpu) = gpu("gpu_crossings_equal_the_cpus_on_random_and_far_rays") else { return };
    for (name, mesh) in &test_meshes() {
        for params in
            [BuildParams::auto(), BuildParams { max_depth: Some(6), leaf_size: Some(1), ..BuildParams::auto() }]
        {
            let scene = scene_of(mesh, &params);
            let n = gpu_equals_cpu(name, gpu, &scene, &random_rays(mesh, 1000, 3));
            assert!(n > 100, "{name}: {n} crossings");
        }
    }
}

/// Rays on the octree's planes (±0 components, every twist of the hard-ray generator)
/// aimed at vertices; rays from inside the closed solids through every vertex and
/// edge midpoint, and the same lines from outside.
#[test]
fn gpu_crossings_equal_the_cpus_on_grid_vertex_and_edge_rays() {
    let Some(gpu) = gpu("gpu_crossings_equal_the_cpus_on_grid_vertex_and_edge_rays") else { return };
    let mesh = crate::hard_cases::test_scene();
    let vertices: Vec<[f32; 3]> = mesh.triangles.iter().flatten().copied().collect();
    for depth in [3, 6] {
        let scene = scene_of(&mesh, &BuildParams { max_depth: Some(depth), leaf_size: Some(2), ..BuildParams::auto() });
        let grid = GridPlanes::of(&scene.view());
        let point = |r: &mut SplitMix| [0, 1, 2].map(|_| -2.0 + 4.0 * r.unit());
        let aim = |r: &mut SplitMix| vertices[(r.next_u64() % vertices.len() as u64) as usize];
        let hard = octrace_bake::hard_rays::grid_rays(&grid, 3000, depth as u64, point, Some(aim), |_| true);
        let rays: Vec<Ray> = hard.iter().map(|r| Ray::new(Vec3::from(r.origin), Vec3::from(r.dir))).collect();
        gpu_equals_cpu(&format!("grid rays, depth {depth}"), gpu, &scene, &rays);
    }
    for solid in procedural::closed_solids() {
        let scene = scene_of(&solid.mesh, &BuildParams::auto());
        // Every vertex and edge midpoint from inside, a third of those lines from
        // outside (software adapters are slow: the test's time is the GPU's work).
        let mut rays = Vec::new();
        for (i, (o, d)) in solid.leak_rays(200, 4).into_iter().enumerate() {
            let (o, d) = (Vec3::from(o), Vec3::from(d));
            rays.push(Ray::new(o, d));
            if i % 3 == 0 {
                rays.push(Ray::new(o - d * 50.0, d));
            }
        }
        let n = gpu_equals_cpu(solid.name, gpu, &scene, &rays);
        assert!(n >= rays.len(), "{}: {n} crossings for {} rays", solid.name, rays.len());
        // Lengths inside, of segments that start and end inside and out.
        let segments: Vec<Ray> = rays.iter().step_by(2).map(|r| Ray { tmin: 0.25, tmax: 40.0, ..*r }).collect();
        let tracer = GpuTracer::new(&gpu.device, &gpu.queue, &scene).unwrap();
        let got = tracer.length_inside(scene.solid().unwrap(), &segments).unwrap();
        let mut want = vec![0.0; segments.len()];
        gpu_default_cpu(&scene).par_length_inside(scene.solid().unwrap(), &segments, &mut want);
        let same = got.iter().zip(&want).filter(|(g, w)| g.to_bits() == w.to_bits()).count();
        if tracer.uses_f64() {
            assert_eq!(same, want.len(), "{}: lengths inside", solid.name);
        }
        assert!(want.iter().filter(|&&l| l > 0.0).count() * 4 > want.len(), "{}: most segments go inside", solid.name);
    }
}

/// Inside/outside of points on the GPU (`GpuTracer::contains`): the CPU's exact
/// answers, point for point, on the closed solids at the origin and far from it, for
/// points uniform in the box, beside the surface, on the octree's cell planes, on the
/// mesh's vertices, and on the corners and centres of the leaves' boxes (where the
/// kernel's point location meets its box check); the kernel decides most points away
/// from the surface itself.
#[test]
fn inside_outside_on_the_gpu_is_the_cpus() {
    use octrace_bake::procedural::ClosedSolid;
    let Some(gpu) = gpu("inside_outside_on_the_gpu_is_the_cpus") else { return };
    use octrace_runtime::gpu::wgpu::Features;
    use octrace_runtime::gpu::GpuOptions;
    use octrace_runtime::TriangleTest;
    const F64: Features = Features::SHADER_F64;
    let (mut points_in_all, mut decided) = ([0; 2], [0; 2]);
    for (offset, scale) in [(0.0, 1.0), (1e4, 1.0), (-3e6, 100.0)] {
        for solid in procedural::closed_solids() {
            let solid: ClosedSolid = solid.moved(offset, scale);
            let name = solid.label();
            let scene = scene_of(&solid.mesh, &BuildParams::auto());
            let near = (1e-6 * scale + 16.0 * f32::EPSILON as f64 * offset.abs()) as f32;
            let mut points: Vec<[f32; 3]> =
                crate::inside::points(&solid.mesh, &scene, 1000, near, 5).iter().map(|p| p.to_array()).collect();
            points.extend(solid.mesh.triangles.iter().flatten().step_by(7).take(400));
            let view = scene.view();
            for bx in view.boxes.chunks_exact(6).step_by(5).take(400) {
                points.push([bx[0], bx[1], bx[2]]);
                points.push([bx[3], bx[4], bx[5]]);
                points.push([0.5 * (bx[0] + bx[3]), 0.5 * (bx[1] + bx[4]), 0.5 * (bx[2] + bx[5])]);
            }
            let labels = scene.solid().unwrap();
            let want = scene.contains_batch(&points).unwrap();
            // The labels alone (the watertight kernels), and with the segments to the
            // reference points (the exact test's, where the adapter has f64).
            for test in [TriangleTest::Watertight, TriangleTest::Exact] {
                let options = GpuOptions { triangle_test: test, ..GpuOptions::default() };
                let Ok(tracer) = GpuTracer::with_options(&gpu.device, &gpu.queue, &scene, options) else {
                    assert!(test == TriangleTest::Exact && !gpu.device.features().contains(F64));
                    continue;
                };
                let got = tracer.contains(labels, &points).unwrap();
                if let Some(i) = (0..points.len()).find(|&i| got[i] != want[i]) {
                    panic!("{name}, {test:?}: point {i} {:?}: CPU {}, GPU {}", points[i], want[i], got[i]);
                }
                let k = (test == TriangleTest::Exact) as usize;
                points_in_all[k] += points.len();
                decided[k] += points.len() - tracer.rays_finished_on_cpu() as usize;
            }
        }
    }
    eprintln!("inside/outside on the GPU: {decided:?} of {points_in_all:?} points decided by the kernel");
    assert!(decided[0] * 3 >= points_in_all[0], "labels alone decided {} of {}", decided[0], points_in_all[0]);
    if points_in_all[1] > 0 {
        // With the segments the kernel leaves the host points on the surface, near
        // edges, and in leaves without a reference point.
        assert!(decided[1] * 4 >= points_in_all[1] * 3, "decided {} of {}", decided[1], points_in_all[1]);
    }
}

/// The one-dispatch kernels (inside/outside, crossing lists) keep their buffers
/// between calls: calls of every size after the largest make none, and each answers
/// as a tracer made for it alone would (the last call's answers and inputs are not
/// read: a smaller call after a larger one is the CPU's too).
#[test]
fn one_dispatch_kernels_keep_their_buffers_and_answer_alike() {
    let Some(gpu) = gpu("one_dispatch_kernels_keep_their_buffers_and_answer_alike") else { return };
    let solid = procedural::closed_solids().into_iter().next().expect("a solid");
    let scene = scene_of(&solid.mesh, &BuildParams::auto());
    let labels = scene.solid().unwrap();
    let cpu = gpu_default_cpu(&scene);
    let tracer = GpuTracer::new(&gpu.device, &gpu.queue, &scene).unwrap();
    let vertices = solid.mesh.triangles.iter().flatten();
    let lo: [f32; 3] = std::array::from_fn(|k| vertices.clone().map(|v| v[k]).fold(f32::INFINITY, f32::min));
    let hi: [f32; 3] = std::array::from_fn(|k| vertices.clone().map(|v| v[k]).fold(f32::NEG_INFINITY, f32::max));
    let mut rng = SplitMix(17);
    let mut point = || std::array::from_fn(|k| lo[k] + (hi[k] - lo[k]) * (1.2 * rng.unit() - 0.1));
    let many: Vec<[f32; 3]> = (0..3000).map(|_| point()).collect();
    let few: Vec<[f32; 3]> = (0..70).map(|_| point()).collect();
    let rays = random_rays(&solid.mesh, 600, 5);
    let check = |tracer: &GpuTracer<'_>| {
        for points in [&many, &few, &many[..1000]] {
            assert_eq!(tracer.contains(labels, points).unwrap(), scene.contains_batch(points).unwrap());
        }
        for rays in [&rays[..], &rays[..40], &rays[..300]] {
            let (got, want) = (tracer.crossings(rays).unwrap(), cpu.par_crossings_batch(rays, usize::MAX));
            assert_eq!(got.splits, want.splits);
            if tracer.uses_f64() {
                assert!(got.crossings.iter().zip(&want.crossings).all(|(a, b)| bits(a) == bits(b)));
            }
        }
    };
    check(&tracer);
    let first = tracer.buffers_created();
    assert!(first > 0);
    check(&tracer);
    assert_eq!(tracer.buffers_created(), first, "buffers made after the largest calls");
}
