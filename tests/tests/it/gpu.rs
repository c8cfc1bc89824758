//! The GPU tracer (wgpu, Vulkan) gives the CPU's answers, ray for ray.

use glam::{DVec3, Vec3};
use octrace_runtime::gpu::{GpuOptions, GpuTracer};
use octrace_runtime::raysets::{self, Frame};
use octrace_runtime::reference::ZERO_T_SPACINGS;
use octrace_runtime::render::effects::Radiance;
use octrace_runtime::{Hit, Ray, Scene};
use octrace_tests::{bunny_mesh, bunny_scene, gpu, gpu_default_cpu, gpu_default_hits, gpu_default_occluded};

/// How two answers for one ray compare.
#[derive(Debug, Default)]
struct Tally {
    same: usize,
    /// Different triangles at the same distance (a shared edge or vertex), or a hit
    /// on a triangle's very boundary that the other side's rounding put outside.
    ties: usize,
    different: Vec<usize>,
}

/// Distances this close (relative) are equal: the acceptance's |Δt| ≤ 1e-5 t.
const SAME_T: f32 = 1e-5;
/// A hit this close to its triangle's boundary (smallest barycentric) is on the edge.
const ON_EDGE: f32 = 1e-5;

fn on_edge(h: &Hit) -> bool {
    h.u.min(h.v).min(1.0 - h.u - h.v) <= ON_EDGE
}

/// |Δt| allowed between two answers for `ray`: 1e-5 t, plus the rounding of a point
/// on the ray near its origin (a few f32 spacings of the origin's coordinates; the
/// oracle's rule, `reference::ZERO_T_SPACINGS`), which dominates for hits at t ≈ 0.
fn t_tolerance(ray: &Ray, t: f32) -> f32 {
    let near_origin = ZERO_T_SPACINGS * f32::EPSILON * ray.origin.abs().max_element() / ray.dir.length();
    SAME_T * t.abs() + near_origin
}

fn compare(rays: &[Ray], cpu: &[Option<Hit>], gpu: &[Option<Hit>]) -> Tally {
    assert_eq!(cpu.len(), gpu.len());
    let mut tally = Tally::default();
    for (i, (c, g)) in cpu.iter().zip(gpu).enumerate() {
        match (c, g) {
            (None, None) => tally.same += 1,
            (Some(c), Some(g)) if (c.t - g.t).abs() <= t_tolerance(&rays[i], c.t) => {
                if c.triangle == g.triangle {
                    tally.same += 1;
                } else {
                    tally.ties += 1;
                }
            }
            (Some(h), None) | (None, Some(h)) if on_edge(h) => tally.ties += 1,
            _ => tally.different.push(i),
        }
    }
    tally
}

fn check(name: &str, rays: &[Ray], cpu: &[Option<Hit>], gpu: &[Option<Hit>]) {
    let t = compare(rays, cpu, gpu);
    eprintln!("{name}: {} rays, {} same, {} ties, {} different", rays.len(), t.same, t.ties, t.different.len());
    if let Some(&i) = t.different.first() {
        panic!("{name}: ray {i} {:?}: CPU {:?}, GPU {:?}", rays[i], cpu[i], gpu[i]);
    }
    // Ties are rays through shared edges: a handful in a million.
    assert!(t.ties * 10_000 <= rays.len(), "{name}: {} ties in {} rays", t.ties, rays.len());
}

/// The three standard sets of `bench/RAYS.md` on the bunny: the same triangle
/// (or a tie at the same distance) and |Δt| ≤ 1e-5 t for every ray; the same occlusion
/// for every shadow ray but those whose occluder lies on a triangle's boundary.
#[test]
fn the_standard_sets_on_the_bunny_match_the_cpu() {
    let Some(gpu) = gpu("the_standard_sets_on_the_bunny_match_the_cpu") else { return };
    standard_sets_match(gpu, bunny_scene(), &bunny_mesh().triangles);
}

/// Under the exact test (`GpuOptions::triangle_test`) the GPU gives the CPU's exact
/// answers bit for bit on the bunny's standard sets (a quarter of the camera rays,
/// 2^18 incoherent rays, the shadow rays' occlusion), its counts and lists too, and
/// its filter decides nearly every ray itself: the CPU finishes under 1 %.
#[test]
fn the_exact_test_on_the_gpu_gives_the_cpus_exact_answers_on_the_standard_sets() {
    use octrace_runtime::TriangleTest;
    let Some(gpu) = gpu("the_exact_test_on_the_gpu_gives_the_cpus_exact_answers_on_the_standard_sets") else {
        return;
    };
    let scene = bunny_scene();
    let options = GpuOptions { triangle_test: TriangleTest::Exact, ..GpuOptions::default() };
    let tracer = match GpuTracer::with_options(&gpu.device, &gpu.queue, scene, options) {
        Ok(t) => t,
        Err(e) if !gpu.device.features().contains(octrace_runtime::gpu::wgpu::Features::SHADER_F64) => {
            return eprintln!("SKIPPED: the adapter has no f64 ({e})");
        }
        Err(e) => panic!("{e}"),
    };
    let cpu = scene.tracer().with_triangle_test(TriangleTest::Exact);
    let frame = Frame::from_triangles(&bunny_mesh().triangles);
    let primary: Vec<Ray> = raysets::primary(&frame).into_iter().step_by(4).collect();
    let incoherent = raysets::incoherent(&frame, 1 << 18);
    let mut all = 0;
    for (name, rays) in [("primary", &primary), ("incoherent", &incoherent)] {
        let mut want = vec![None; rays.len()];
        cpu.intersect_batch(rays, &mut want);
        same_hits(name, rays, &want, &tracer.intersect(rays).unwrap());
        all += rays.len();
    }
    let view = scene.view();
    let hits: Vec<Option<Hit>> = primary.iter().map(|r| cpu.intersect(r)).collect();
    let shadow = raysets::shadow(&frame, |i| hits.get(i).copied().flatten().map(|h| (h.t, view.triangle(h.prim))));
    let want: Vec<bool> = shadow.iter().map(|r| cpu.occluder(r).is_some()).collect();
    assert!(tracer.occluded(&shadow).unwrap() == want, "shadow: occlusion differs from the CPU's exact test");
    all += shadow.len();
    let some = &incoherent[..1 << 14];
    let lists = tracer.crossings(some).unwrap();
    let counts = tracer.count_crossings(some).unwrap();
    for (i, r) in some.iter().enumerate() {
        let want = cpu.all_crossings(r);
        assert_eq!(lists.of(i), want.as_slice(), "incoherent ray {i} {r:?}: crossings");
        assert_eq!(counts[i], cpu.count_crossings(r), "incoherent ray {i} {r:?}: counts");
    }
    all += 2 * some.len();
    let back = tracer.rays_finished_on_cpu() as usize;
    eprintln!("exact test on the GPU: {back} of {all} ray queries finished on the CPU");
    assert!(back * 100 < all, "{back} of {all} ray queries finished on the CPU");
}

/// The same on the dragon (871k triangles, a 117 MB file), when `../shared` is there.
#[test]
#[cfg_attr(not(octrace_shared), ignore = "needs ../shared beside the clone (README: Set up)")]
fn the_standard_sets_on_the_dragon_match_the_cpu() {
    let Some(gpu) = gpu("the_standard_sets_on_the_dragon_match_the_cpu") else { return };
    let test = "the_standard_sets_on_the_dragon_match_the_cpu";
    let Some(path) = octrace_tests::shared_file("meshes/dragon.obj", test) else { return };
    let mesh = octrace_bake::Mesh::load(&path).unwrap();
    let scene = Scene::from_baked(octrace_bake::bake(&mesh, &octrace_bake::BuildParams::auto()).unwrap()).unwrap();
    standard_sets_match(gpu, &scene, &mesh.triangles);
}

fn standard_sets_match(gpu: &octrace_runtime::gpu::GpuContext, scene: &Scene, triangles: &[[[f32; 3]; 3]]) {
    let tracer = GpuTracer::new(&gpu.device, &gpu.queue, scene).unwrap();
    let frame = Frame::from_triangles(triangles);
    let primary = raysets::primary(&frame);
    let cpu_primary = gpu_default_hits(scene, &primary);
    let incoherent = raysets::incoherent(&frame, 1_000_000);
    let view = scene.view();
    let shadow = raysets::shadow(&frame, |i| cpu_primary[i].map(|h| (h.t, view.triangle(h.prim))));
    let cpu_occluded = gpu_default_occluded(scene, &shadow);
    if tracer.uses_f64() {
        // The kernel's arithmetic is the CPU's: every answer the same, bit for bit.
        same_hits("primary", &primary, &cpu_primary, &tracer.intersect(&primary).unwrap());
        same_hits(
            "incoherent",
            &incoherent,
            &gpu_default_hits(scene, &incoherent),
            &tracer.intersect(&incoherent).unwrap(),
        );
        same_hits("shadow", &shadow, &gpu_default_hits(scene, &shadow), &tracer.intersect(&shadow).unwrap());
        assert!(tracer.occluded(&shadow).unwrap() == cpu_occluded, "shadow: occlusion differs");
        return;
    }
    // Without f64 the edge functions and distances round differently: the same
    // triangle or a tie, within 1e-5 t.
    check("primary", &primary, &cpu_primary, &tracer.intersect(&primary).unwrap());
    check("incoherent", &incoherent, &gpu_default_hits(scene, &incoherent), &tracer.intersect(&incoherent).unwrap());
    let (occluders, _) = tracer.trace_timed(&shadow, true).unwrap();
    assert_eq!(tracer.occluded(&shadow).unwrap(), occluders.iter().map(Option::is_some).collect::<Vec<_>>());
    let cpu_occluders: Vec<Option<Hit>> = shadow.iter().map(|r| gpu_default_cpu(scene).occluder(r)).collect();
    let mut differ = 0;
    for (i, (&c, g)) in cpu_occluded.iter().zip(&occluders).enumerate() {
        if c != g.is_some() {
            let h = g.or(cpu_occluders[i]).unwrap();
            assert!(on_edge(&h), "shadow ray {i} {:?}: CPU {c}, GPU {g:?}", shadow[i]);
            differ += 1;
        }
    }
    eprintln!("shadow: {} rays, {differ} differ on a triangle's boundary", shadow.len());
    assert!(differ * 10_000 <= shadow.len());
}

/// A scene split across many storage bindings (as one larger than the device's binding
/// limit is) gives exactly the answers of one binding.
#[test]
fn a_scene_split_across_bindings_gives_the_same_answers() {
    let Some(gpu) = gpu("a_scene_split_across_bindings_gives_the_same_answers") else { return };
    let scene = bunny_scene();
    let whole = GpuTracer::new(&gpu.device, &gpu.queue, scene).unwrap();
    let options = GpuOptions { max_binding_bytes: Some(1 << 20), ..GpuOptions::default() };
    let split = GpuTracer::with_options(&gpu.device, &gpu.queue, scene, options).unwrap();
    assert_eq!(whole.scene_bindings(), 1);
    assert!(split.scene_bindings() >= 4, "{} bindings", split.scene_bindings());
    let frame = Frame::from_triangles(&bunny_mesh().triangles);
    let rays = raysets::incoherent(&frame, 200_000);
    let (a, b) = (whole.intersect(&rays).unwrap(), split.intersect(&rays).unwrap());
    assert!(a == b, "split and whole scenes disagree");
    assert_eq!(whole.occluded(&rays).unwrap(), split.occluded(&rays).unwrap());
}

/// A scene that needs more bindings than the device allows is a clear error, for the
/// trace kernel and for the render kernel (which needs four more), never a wgpu
/// panic (a 4 GB scene on lavapipe: 29 bindings traced, 36 refused for rendering).
#[test]
fn a_scene_needing_too_many_bindings_is_a_clear_error() {
    use octrace_runtime::gpu::{GpuError, GpuRenderer};
    use octrace_runtime::render::effects::RenderOptions;
    let Some(gpu) = gpu("a_scene_needing_too_many_bindings_is_a_clear_error") else { return };
    let scene = bunny_scene();
    let limits = gpu.device.limits();
    let storage = u64::from(limits.max_storage_buffers_per_shader_stage);
    // The scene's bind group holds its chunks and three bindings more (NVIDIA allows
    // millions of storage buffers a stage, and 1,000 bindings a group).
    let group = u64::from(limits.max_bindings_per_bind_group);
    let allowed = storage.min(group - 3).min(octrace_runtime::gpu::MAX_SCENE_BINDINGS);
    let words = scene.view().section_words()[..7].iter().map(|a| a.len() as u64).sum::<u64>();
    // Chunks of a power of two words: the largest size giving more chunks than allowed.
    let chunk = |n: u64| 4 << (words / n).max(1).ilog2();
    let options = GpuOptions { max_binding_bytes: Some(chunk(allowed + 1)), ..GpuOptions::default() };
    match GpuTracer::with_options(&gpu.device, &gpu.queue, scene, options) {
        Err(GpuError::TooLarge(why)) => assert!(why.contains("storage buffers"), "{why}"),
        other => panic!("{} words in chunks of {} bytes: {other:?}", words, chunk(allowed + 1)),
    }
    // The splits the tracer takes: the renderer, three storage bindings more, is made
    // exactly when they fit, and refused by name otherwise: tried on the split with the
    // fewest bindings, and on those either side of where the renderer stops fitting
    // (making a renderer is the slow part on a software adapter).
    let buffers = u64::from(limits.max_buffers_and_acceleration_structures_per_shader_stage);
    let fits = |chunks: u64| chunks + 5 <= storage && chunks + 7 <= buffers;
    let mut splits = Vec::new();
    for shift in 12..24 {
        let options = GpuOptions { max_binding_bytes: Some(1 << shift), ..GpuOptions::default() };
        let Ok(tracer) = GpuTracer::with_options(&gpu.device, &gpu.queue, scene, options) else { continue };
        let chunks = tracer.scene_bindings() as u64;
        assert!(chunks <= allowed, "{chunks} bindings made, {allowed} allowed");
        splits.push((chunks, tracer));
    }
    splits.sort_by_key(|s| s.0);
    let last_fit = splits.iter().rposition(|s| fits(s.0));
    let first_refused = splits.iter().position(|s| !fits(s.0));
    let tried: std::collections::BTreeSet<usize> = [Some(0), last_fit, first_refused].into_iter().flatten().collect();
    let mut refused_render = 0;
    for (chunks, tracer) in tried.into_iter().map(|i| &splits[i]) {
        let (chunks, fits) = (*chunks, fits(*chunks));
        match GpuRenderer::new(tracer, &RenderOptions::for_scene(scene.shading())) {
            Ok(_) => assert!(fits, "{chunks} bindings"),
            Err(GpuError::TooLarge(why)) => {
                assert!(!fits && why.contains("storage buffers"), "{chunks} bindings: {why}");
                refused_render += 1;
            }
            Err(e) => panic!("{chunks} bindings: {e}"),
        }
    }
    eprintln!("{refused_render} splits traced but refused for rendering");
}

/// Rays from inside the scene start by point location; rays that cannot hit (NaN,
/// zero direction, tmin > tmax, missing the root) are defined misses, as on the CPU.
#[test]
fn inside_origins_and_untraceable_rays_match_the_cpu() {
    let Some(gpu) = gpu("inside_origins_and_untraceable_rays_match_the_cpu") else { return };
    let mesh = octrace_bake::procedural::blob(48, 64);
    let scene = Scene::from_baked(octrace_bake::bake(&mesh, &octrace_bake::BuildParams::auto()).unwrap()).unwrap();
    let tracer = GpuTracer::new(&gpu.device, &gpu.queue, &scene).unwrap();
    let mut rng = octrace_bake::procedural::SplitMix(11);
    let mut rays: Vec<Ray> = (0..100_000)
        .map(|_| {
            let o = Vec3::new(rng.unit(), rng.unit(), rng.unit()) * 0.6 - 0.3;
            let d = Vec3::new(rng.unit() - 0.5, rng.unit() - 0.5, rng.unit() - 0.5);
            Ray::new(o, d)
        })
        .collect();
    let nan = f32::NAN;
    rays.extend([
        Ray::new(Vec3::new(nan, 0.0, 0.0), Vec3::X),
        Ray::new(Vec3::ZERO, Vec3::ZERO),
        Ray::new(Vec3::ZERO, Vec3::new(0.0, nan, 1.0)),
        Ray::segment(Vec3::ZERO, Vec3::X, 2.0, 1.0),
        Ray::segment(Vec3::ZERO, Vec3::X, nan, 1.0),
        Ray::new(Vec3::new(5.0, 5.0, 5.0), Vec3::X),
        Ray::new(Vec3::new(0.0, 0.0, -5.0), Vec3::new(0.0, -0.0, 1.0)),
    ]);
    let cpu = gpu_default_hits(&scene, &rays);
    let got = tracer.intersect(&rays).unwrap();
    if tracer.uses_f64() {
        same_hits("inside", &rays, &cpu, &got);
    } else {
        check("inside", &rays, &cpu, &got);
    }
    assert!(got[got.len() - 7..got.len() - 1].iter().all(Option::is_none));
    assert!(got.last().unwrap().is_some(), "an axis-parallel ray from outside hits the blob");
    assert!(cpu.iter().take(100_000).all(Option::is_some), "every inside ray of a closed blob hits it");
}

/// The effects renderer with every wave traced on the GPU gives the CPU's image, with
/// each effect turned off in turn: the same rays of every kind, exactly as many, and
/// the same pixels within the bound of `renders_agree`.
#[test]
fn effects_render_on_the_gpu_matches_the_cpu() {
    use octrace_format::Effect;
    use octrace_runtime::render::effects::{EffectSet, RenderOptions};
    let Some(ctx) = gpu("effects_render_on_the_gpu_matches_the_cpu") else { return };
    let mesh = octrace_bake::procedural::effects_scene();
    let scene = Scene::from_baked(octrace_bake::bake(&mesh, &Default::default()).unwrap()).unwrap();
    let camera = raysets::Camera::from_scene(&scene.shading().cameras[0], 40.0, 96, 72);
    let all = RenderOptions { soft_samples: 4, ..RenderOptions::for_scene(scene.shading()) };
    let tracer = GpuTracer::new(&ctx.device, &ctx.queue, &scene).unwrap();
    // Every effect, each one turned off (a pipeline compiled without it), none.
    let mut sets = vec![all.effects];
    sets.extend(all.effects.iter().map(|e| all.effects.without(e)));
    sets.push(EffectSet::NONE);
    for effects in sets {
        let options = RenderOptions { effects, ..all };
        let names = effects.iter().map(Effect::name).collect::<Vec<_>>();
        let counts = renders_as_on_the_cpu(&format!("effects {names:?}"), ctx, &tracer, &camera, &options);
        eprintln!("{names:?}: {counts:?}");
    }
    assert!(all.effects.iter().count() == Effect::ALL.len(), "the scene calls for every effect");
    // Deeper trees than the kernel's stack holds are refused, not cut short.
    let deep = RenderOptions { max_depth: octrace_runtime::gpu::MAX_GPU_DEPTH + 1, ..all };
    let err = octrace_runtime::gpu::GpuRenderer::new(&tracer, &deep).unwrap_err();
    assert!(err.to_string().contains("at most 31 deep"), "{err}");
    // No lights: the headlight, primary rays only.
    let sphere = octrace_bake::procedural::sphere([0.0; 3], 1.0, 16, 24);
    let scene = Scene::from_baked(octrace_bake::bake(&sphere, &Default::default()).unwrap()).unwrap();
    let b = scene.view().bounds;
    let camera = raysets::Camera::standard_sized(&Frame::from_bounds(b.mesh_lo, b.mesh_hi), 64, 48);
    let options = RenderOptions::for_scene(scene.shading());
    let tracer = GpuTracer::new(&ctx.device, &ctx.queue, &scene).unwrap();
    let counts = renders_as_on_the_cpu("headlight", ctx, &tracer, &camera, &options);
    assert_eq!(counts.total(), 64 * 48);
}

/// Rays on the octree's planes from inside the closed solids (`hard_cases::grid_rays`),
/// at the origin and far from it: none leaks through the kernel either, and every
/// answer is the CPU's, bit for bit (the kernel's walk follows the same slab rule for
/// zero components, and its distances are the same f64 plane distances).
#[test]
fn rays_on_cell_planes_never_leak_on_the_gpu() {
    use crate::hard_cases::grid_rays::{solid_rays, PLACEMENTS};
    let Some(gpu) = gpu("rays_on_cell_planes_never_leak_on_the_gpu") else { return };
    for (offset, scale) in PLACEMENTS {
        for solid in octrace_bake::procedural::closed_solids() {
            let solid = solid.moved(offset, scale);
            // Fewer than the CPU test's: the same kernel walk, on a slow software adapter.
            let (scene, _, rays) = solid_rays(&solid, 8_000, 5);
            let tracer = GpuTracer::new(&gpu.device, &gpu.queue, &scene).unwrap();
            let got = tracer.intersect(&rays).unwrap();
            let leaks = got.iter().filter(|h| h.is_none()).count();
            assert_eq!(leaks, 0, "{}: {leaks} of {} rays leaked through the kernel", solid.label(), rays.len());
            assert!(tracer.occluded(&rays).unwrap().iter().all(|&o| o), "{}: any-hit leaks", solid.label());
            if tracer.uses_f64() {
                same_hits(&solid.label(), &rays, &gpu_default_hits(&scene, &rays), &got);
            }
        }
    }
}

/// The two reproductions on the GPU: the bunny ray in a y plane with `-0.0`,
/// and a camera on a cell plane inside a closed room (no pixel sees through the wall).
#[test]
fn in_plane_reproductions_hit_on_the_gpu() {
    let Some(gpu) = gpu("in_plane_reproductions_hit_on_the_gpu") else { return };
    let o = Vec3::from([0xbc6bedfau32, 0x3ddd986c, 0x3e99999a].map(f32::from_bits));
    let rays = [Ray::new(o, Vec3::new(-0.25, -0.0, -1.0)), Ray::new(o, Vec3::new(-0.25, 0.0, -1.0))];
    let tracer = GpuTracer::new(&gpu.device, &gpu.queue, bunny_scene()).unwrap();
    for h in tracer.intersect(&rays).unwrap() {
        assert_eq!(h.map(|h| h.triangle), Some(38327), "{h:?}");
    }
    let room = octrace_bake::procedural::cube([-2.0, -1.0, -3.0], [2.0, 1.5, 3.0], 32);
    let scene = Scene::from_baked(octrace_bake::bake(&room, &Default::default()).unwrap()).unwrap();
    let grid = octrace_bake::hard_rays::GridPlanes::of(&scene.view());
    let y = grid.snap(1, grid.depth, 0.0625) as f64;
    let camera = raysets::Camera::look_at(glam::DVec3::new(0.3, y, 0.2), glam::DVec3::new(1.3, y, -0.8), 60.0, 96, 101);
    let tracer = GpuTracer::new(&gpu.device, &gpu.queue, &scene).unwrap();
    let missed = tracer.intersect(&camera.rays()).unwrap().iter().filter(|h| h.is_none()).count();
    assert_eq!(missed, 0, "{missed} pixels see through the wall");
}

/// Issue 31's reproductions on the GPU: subnormal components from inside the cube,
/// a whole direction of 1e-37, a hit beyond f32's range, duplicate triangles (the
/// lowest id), a hit at tmin = 0: the CPU's answers, bit for bit where the adapter has
/// f64 (the kernel follows the same exit rule, read from the same integer exponents).
#[test]
fn tiny_directions_ties_and_t_zero_answer_as_on_the_cpu() {
    use crate::hard_cases::tiny_directions::{duplicates, ray_of, subnormal_case, tiny_direction_case};
    let Some(gpu) = gpu("tiny_directions_ties_and_t_zero_answer_as_on_the_cpu") else { return };
    let (_, cube, subnormal) = subnormal_case();
    let (_, grid_cube, tiny) = tiny_direction_case();
    let beyond = ray_of([0, 0, 0], [0x00000001, 0, 0]);
    let on_face = Ray::new(Vec3::new(0.3, 0.2, 1.0), Vec3::new(0.1, -0.2, -1.0));
    let (_, copies) = duplicates();
    // From below and above, at points inside the shared triangle (z = 0.5).
    let through_copies: Vec<Ray> = (0..64)
        .map(|i| {
            let from = Vec3::new(0.1, 0.1, if i % 2 == 0 { -1.0 } else { 2.0 });
            let target = Vec3::new(0.05 + 0.003 * i as f32, 0.25 - 0.003 * i as f32, 0.5);
            Ray::new(from, target - from)
        })
        .collect();
    let cases: [(&str, &Scene, Vec<Ray>); 4] = [
        ("subnormal components", &cube, vec![subnormal, beyond, on_face]),
        ("a direction of 1e-37", &grid_cube, vec![tiny, Ray { dir: tiny.dir * 256.0, ..tiny }]),
        ("duplicates", &copies, through_copies),
        ("plain", &cube, vec![Ray::new(Vec3::new(0.3, 0.2, 0.5), Vec3::new(0.1, -0.2, -1.0))]),
    ];
    for (name, scene, rays) in cases {
        let tracer = GpuTracer::new(&gpu.device, &gpu.queue, scene).unwrap();
        let got = tracer.intersect(&rays).unwrap();
        let cpu = gpu_default_hits(scene, &rays);
        for (i, (c, g)) in cpu.iter().zip(&got).enumerate() {
            assert_eq!(c.is_some(), g.is_some(), "{name}: ray {i} {:?}: CPU {c:?}, GPU {g:?}", rays[i]);
            assert_eq!(c.map(|h| (h.triangle, h.t)), g.map(|h| (h.triangle, h.t)), "{name}: ray {i}");
        }
        let occluded = tracer.occluded(&rays).unwrap();
        assert_eq!(occluded, cpu.iter().map(Option::is_some).collect::<Vec<_>>(), "{name}: occlusion");
        if tracer.uses_f64() {
            same_hits(name, &rays, &cpu, &got);
        }
    }
    assert!(cube.intersect(&subnormal).is_some_and(|h| h.t == 1.0));
    assert!(cube.intersect(&beyond).is_none());
}

/// Rays that graze the root cube's edge where the mesh box reaches the root's faces
/// (the cube whose faces are the root's; the hard rays near its vertices and edges):
/// the root clip's rounding calls some a miss, and the walk starts where they enter
/// the enlarged mesh box, on the GPU as on the CPU (the kernel called them misses:
/// `[2.7158, 0.114807256, -0.29501683]` towards `[-0.76740384, -0.27497694,
/// 0.5792055]` meets the vertex `(1, -0.5, 1)` at t = 2.2358503).
#[test]
fn rays_grazing_the_roots_edge_are_walked_as_on_the_cpu() {
    use octrace_tests::exact::hard;
    let Some(gpu) = gpu("rays_grazing_the_roots_edge_are_walked_as_on_the_cpu") else { return };
    let mesh = octrace_bake::procedural::cube([-1.0; 3], [1.0; 3], 4);
    let scene = Scene::from_baked(octrace_bake::bake(&mesh, &octrace_bake::BuildParams::auto()).unwrap()).unwrap();
    let tracer = GpuTracer::new(&gpu.device, &gpu.queue, &scene).unwrap();
    let mut rays =
        vec![Ray::new(Vec3::new(2.7158, 0.114807256, -0.29501683), Vec3::new(-0.76740384, -0.27497694, 0.5792055))];
    for (k, kind) in ["near-vertex", "near-edge", "along-edge"].into_iter().enumerate() {
        let made = hard::rays(&mesh.triangles, kind, 300, 0xE8AC7 + k as u64);
        rays.extend(made.iter().map(|&(o, d)| Ray::new(Vec3::from(o), Vec3::from(d))));
    }
    let cpu = gpu_default_hits(&scene, &rays);
    assert!(cpu[0].is_some_and(|h| h.t == 2.2358503));
    let got = tracer.intersect(&rays).unwrap();
    assert_eq!(got.iter().filter(|h| h.is_some()).count(), cpu.iter().filter(|h| h.is_some()).count(), "hits");
    if tracer.uses_f64() {
        same_hits("grazing the root", &rays, &cpu, &got);
    }
}

/// Cameras far from a unit sphere (10 to 1e9 away) on the GPU: the kernel moves far
/// origins to the root as the CPU does (in f64 where the adapter has it): the same hits,
/// bit for bit there; and, either way, no more than the CPU's grazing misses.
#[test]
fn far_cameras_see_as_on_the_cpu() {
    use crate::hard_cases::tiny_directions::{far_rays, unit_sphere};
    let Some(gpu) = gpu("far_cameras_see_as_on_the_cpu") else { return };
    let (_, scene) = unit_sphere();
    let tracer = GpuTracer::new(&gpu.device, &gpu.queue, &scene).unwrap();
    for exp in 1..=9 {
        let rays = far_rays(10f32.powi(exp), 1500, exp as u64);
        let cpu = gpu_default_hits(&scene, &rays);
        let got = tracer.intersect(&rays).unwrap();
        if tracer.uses_f64() {
            same_hits(&format!("1e{exp}"), &rays, &cpu, &got);
        }
        // A segment ending exactly at its nearest hit still hits it (the moved tmax,
        // walk.rs `moved_tmax`; trace.wgsl the same).
        let ended: Vec<Ray> = rays.iter().zip(&cpu).filter_map(|(r, h)| h.map(|h| Ray { tmax: h.t, ..*r })).collect();
        let cpu_ended = gpu_default_hits(&scene, &ended);
        assert!(cpu_ended.iter().all(Option::is_some), "1e{exp}: a segment ending at its hit missed it");
        if tracer.uses_f64() {
            same_hits(&format!("1e{exp}, ending at the hit"), &ended, &cpu_ended, &tracer.intersect(&ended).unwrap());
        }
        let (c, g) = (cpu.iter().flatten().count(), got.iter().flatten().count());
        assert!(g + rays.len() / 100 >= c, "1e{exp}: {g} GPU hits against {c}");
    }
}

/// The zig-zag polygon of slivers on the GPU: every distance within the CPU's bound of
/// the exact plane distance (the same bits where the adapter has f64).
#[test]
fn slivers_keep_the_distance_bound_on_the_gpu() {
    let Some(gpu) = gpu("slivers_keep_the_distance_bound_on_the_gpu") else { return };
    let mesh = crate::hard_cases::slivers::zigzag();
    let scene = Scene::from_baked(octrace_bake::bake(&mesh, &Default::default()).unwrap()).unwrap();
    let oracle = octrace_runtime::reference::Reference::in_input_order(mesh.triangles.clone());
    let mut rng = octrace_bake::procedural::SplitMix(2);
    let rays: Vec<Ray> = (0..20_000)
        .map(|_| {
            let from = Vec3::new(rng.unit() * 1001.0 - 1.0, rng.unit() * 8.0 - 1.0, rng.unit() * 3.0 - 1.5);
            let to = Vec3::new(rng.unit() * 999.0, rng.unit() * 6.0, 0.0);
            Ray::new(from, to - from)
        })
        .collect();
    let tracer = GpuTracer::new(&gpu.device, &gpu.queue, &scene).unwrap();
    let got = tracer.intersect(&rays).unwrap();
    let mut hits = 0;
    for (r, h) in rays.iter().zip(&got) {
        let Some(h) = h else { continue };
        hits += 1;
        let (err, bound) = oracle.distance_error(r, h.t, h.triangle).unwrap();
        if tracer.uses_f64() {
            assert!(err <= bound, "{r:?}: {h:?} is {err:e} off its plane (bound {bound:e})");
        }
    }
    assert!(hits > 10_000, "{hits}");
    if tracer.uses_f64() {
        same_hits("zigzag", &rays, &gpu_default_hits(&scene, &rays), &got);
    }
}

/// The CPU's and the kernel's answers are the same, bit for bit: triangle, distance
/// and barycentrics. Where the adapter has f64 the kernel rounds every product of the
/// triangle test as the CPU does (each one exact in f64, then rounded to f32, so no
/// compiler fusing a multiply into an add changes a bit) and computes the distance
/// with the CPU's f64 operations in the CPU's order.
fn same_hits(name: &str, rays: &[Ray], cpu: &[Option<Hit>], gpu: &[Option<Hit>]) {
    assert_eq!(cpu.len(), gpu.len());
    let key = |h: &Option<Hit>| h.map(|h| (h.triangle, h.t.to_bits(), h.u.to_bits(), h.v.to_bits()));
    for (i, (c, g)) in cpu.iter().zip(gpu).enumerate() {
        assert_eq!(key(c), key(g), "{name}: ray {i} {:?}: CPU {c:?}, GPU {g:?}", rays[i]);
    }
}

/// One renderer renders many frames (an interactive viewer, an animation): its buffers
/// are made by its first render and kept, grown only for a larger image, and every
/// frame, larger or smaller than the one before, is the CPU's image with the CPU's rays.
#[test]
fn a_renderer_keeps_its_buffers_between_frames() {
    use octrace_runtime::gpu::GpuRenderer;
    use octrace_runtime::render::effects::{render_effects, RayKind, RenderOptions};
    let Some(ctx) = gpu("a_renderer_keeps_its_buffers_between_frames") else { return };
    let mesh = octrace_bake::procedural::effects_scene();
    let scene = Scene::from_baked(octrace_bake::bake(&mesh, &Default::default()).unwrap()).unwrap();
    let options = RenderOptions { soft_samples: 2, ..RenderOptions::for_scene(scene.shading()) };
    let tracer = GpuTracer::new(&ctx.device, &ctx.queue, &scene).unwrap();
    let renderer = GpuRenderer::new(&tracer, &options).unwrap();
    let c = &scene.shading().cameras[0];
    let frame = |w, h| raysets::Camera::from_scene(c, 40.0, w, h);
    let mut after_largest = None;
    for (i, (w, h)) in [(48, 36), (96, 72), (32, 24), (96, 72), (64, 48)].into_iter().enumerate() {
        let camera = frame(w, h);
        let (g, gc) = renderer.render(&camera).unwrap();
        let (cpu, cc) = render_effects(&scene, &camera, &options, &|_| {});
        for kind in RayKind::ALL {
            assert_eq!(gc.get(kind), cc.get(kind), "frame {i} ({w} x {h}): {} rays", kind.name());
        }
        renders_agree(&format!("frame {i} ({w} x {h})"), ctx, &cpu, &g);
        if i == 1 {
            after_largest = Some(tracer.buffers_created());
        } else if let Some(made) = after_largest {
            assert_eq!(tracer.buffers_created(), made, "buffers made by frame {i} ({w} x {h})");
        }
    }
}

/// The effects scene at the settings users run: every effect on, the default 16
/// soft-shadow samples (and 32), 256 x 192 (the glass sphere covers about 2,500
/// pixels). The GPU traces the CPU's rays, kind by kind, exactly as many; the images
/// agree pixel by pixel within the bound the arithmetic allows (see `renders_agree`).
/// At 16 samples the kernel used to drop rays in blocks of eight pixels (lavapipe:
/// 13,869 refraction rays instead of 14,777, 381 pixels off by up to 212 levels).
#[test]
fn effects_render_at_default_settings_gives_the_cpus_rays_and_image() {
    use octrace_runtime::render::effects::RenderOptions;
    let Some(ctx) = gpu("effects_render_at_default_settings_gives_the_cpus_rays_and_image") else { return };
    let mesh = octrace_bake::procedural::effects_scene();
    let scene = Scene::from_baked(octrace_bake::bake(&mesh, &Default::default()).unwrap()).unwrap();
    // `octrace render fx.oct --width 256`'s camera: the scene's, 256 x 192.
    let c = &scene.shading().cameras[0];
    let camera = raysets::Camera::from_scene(c, f64::from(c.yfov).to_degrees(), 256, 192);
    let tracer = GpuTracer::new(&ctx.device, &ctx.queue, &scene).unwrap();
    let defaults = RenderOptions::for_scene(scene.shading());
    assert_eq!(defaults.soft_samples, 16, "the defaults this test stands for");
    for samples in [16, 32] {
        let options = RenderOptions { soft_samples: samples, ..defaults };
        renders_as_on_the_cpu(&format!("{samples} samples"), ctx, &tracer, &camera, &options);
    }
}

/// Renders through `camera` on the GPU and on the CPU: the same rays of every kind,
/// exactly as many, and images that agree ([`renders_agree`]). The CPU's counts.
fn renders_as_on_the_cpu(
    name: &str,
    ctx: &octrace_runtime::gpu::GpuContext,
    tracer: &GpuTracer<'_>,
    camera: &raysets::Camera,
    options: &octrace_runtime::render::effects::RenderOptions,
) -> octrace_runtime::render::effects::RayCounts {
    use octrace_runtime::render::effects::{render_effects, render_effects_gpu, RayKind};
    let (g, gc) = render_effects_gpu(tracer, camera, options).unwrap();
    let (c, cc) = render_effects(tracer.scene(), camera, options, &|_| {});
    for kind in RayKind::ALL {
        assert_eq!(gc.get(kind), cc.get(kind), "{name}: {} rays, GPU against CPU", kind.name());
    }
    renders_agree(name, ctx, &c, &g);
    cc
}

/// Two renders of one scene agree pixel by pixel: every channel's radiance within
/// `RADIANCE` of the CPU's (relative), and so the 8-bit images equal but for channels
/// whose value lies that close to a rounding boundary (at most one level, and in at most
/// one channel in ten thousand).
///
/// # Why not the same bits
/// The kernel traces the CPU's rays (the camera's, passed in; the same triangle tests
/// and spawn points) and computes every shading term with the CPU's operations in the
/// CPU's order (`power` for `powf`, glam's `cross` and `normalize` for WGSL's), and a
/// pixel's terms are summed in fixed point, which no order changes. But WGSL lets a
/// compiler fuse a multiply into an add, and lavapipe's does in places (`power`'s
/// `e log2 x - n`): a term then differs in its last bits (on lavapipe: 0.06 % of the
/// pixels, by at most 1e-7 relative). A hardware compiler may fuse more: the
/// highlight's lobe `x^e` turns one ulp of `x` into `e` ulps (e up to 10^4), hence the
/// wider bound off lavapipe.
fn renders_agree(name: &str, ctx: &octrace_runtime::gpu::GpuContext, cpu: &Radiance, gpu: &Radiance) {
    // On lavapipe, where the README's claim was measured, the 8-bit images are identical
    // and the radiance differs only where the driver fuses a multiply and an add (1.4e-7
    // at worst); other drivers may round their builtins differently.
    let lavapipe = ctx.info.name.contains("llvmpipe");
    let bound = if lavapipe { 1e-6 } else { 1e-3 };
    let mut worst_radiance = 0.0f32;
    for (i, (c, g)) in cpu.pixels.iter().zip(&gpu.pixels).enumerate() {
        let error = ((*c - *g).abs() / c.abs().max(Vec3::splat(1e-3))).max_element();
        assert!(error <= bound, "{name}: pixel {i}: CPU {c}, GPU {g} ({error:e} apart)");
        worst_radiance = worst_radiance.max(error);
    }
    let (cpu, gpu) = (cpu.to_image(), gpu.to_image());
    let diffs: Vec<u8> = cpu.rgb.iter().zip(&gpu.rgb).map(|(a, b)| a.abs_diff(*b)).collect();
    let worst = diffs.iter().copied().max().unwrap_or(0);
    let off = diffs.iter().filter(|&&d| d > 0).count();
    eprintln!("{name}: radiance within {worst_radiance:e}; {off} of {} 8-bit channels differ", diffs.len());
    if lavapipe {
        assert_eq!(off, 0, "{name}: {off} of {} 8-bit channels differ (by up to {worst})", diffs.len());
    }
    assert!(worst <= 1, "{name}: a channel differs by {worst} levels ({off} differ)");
    assert!(off * 10_000 <= diffs.len(), "{name}: {off} of {} channels differ", diffs.len());
}

/// The driver behaviour behind the dropped rays, reduced: Mesa's llvmpipe (lavapipe)
/// stops every loop of a shader invocation once their iterations together reach
/// 65,535 (its guard against infinite loops), without an error, so one loop of 2^20
/// iterations runs 65,535 of them. `gpu::loop_cap` measures it; the kernels stay under
/// it on such an adapter, and a walk that would need more is traced on the CPU: here a
/// ray tests 70,000 triangles of one leaf before it reaches the one it hits, and gets
/// the CPU's answer.
#[test]
fn lavapipe_caps_loop_iterations_and_long_walks_still_get_whole_answers() {
    let Some(ctx) = gpu("lavapipe_caps_loop_iterations_and_long_walks_still_get_whole_answers") else { return };
    let cap = octrace_runtime::gpu::loop_cap(&ctx.device, &ctx.queue).unwrap();
    if ctx.info.name.contains("llvmpipe") {
        assert_eq!(cap, Some(65_535), "lavapipe's loop cap changed");
    }
    eprintln!("{}: loop cap {cap:?}", ctx.describe());
    // 70,000 slivers beside the ray's line in one leaf, then the triangle it hits.
    let mut tris: Vec<[[f32; 3]; 3]> = (0..70_000)
        .map(|i| {
            let x = 0.1 + (i % 1000) as f32 * 1e-3;
            let z = (i / 1000) as f32 * 1e-2;
            [[x, 0.5, z], [x + 1e-4, 0.5, z], [x, 0.6, z + 1e-3]]
        })
        .collect();
    tris.push([[-1.0, -1.0, 2.0], [1.0, -1.0, 2.0], [0.0, 1.0, 2.0]]);
    let mesh = octrace_bake::Mesh::from_triangles(tris);
    let params = octrace_bake::BuildParams { max_depth: Some(1), leaf_size: Some(1 << 20), ..Default::default() };
    let scene = Scene::from_baked(octrace_bake::bake(&mesh, &params).unwrap()).unwrap();
    let tracer = GpuTracer::new(&ctx.device, &ctx.queue, &scene).unwrap();
    let rays: Vec<Ray> = (0..16).map(|k| Ray::new(Vec3::new(k as f32 * 1e-3, 0.0, -1.0), Vec3::Z)).collect();
    let cpu = gpu_default_hits(&scene, &rays);
    assert!(cpu.iter().all(|h| h.is_some_and(|h| h.triangle == 70_000)), "{cpu:?}");
    let (g, stats): (Vec<_>, Vec<_>) = tracer.intersect_with_stats(&rays).unwrap().into_iter().unzip();
    same_hits("long walks", &rays, &cpu, &g);
    assert!(stats.iter().all(|s| s.triangle_tests > 65_535), "the walks test more triangles than the cap: {stats:?}");
    assert!(tracer.occluded(&rays).unwrap().iter().all(|&o| o));
    // The crossing walks too: counted and listed again on the CPU where they run out.
    let lists = tracer.crossings(&rays).unwrap();
    let counts = tracer.count_crossings(&rays).unwrap();
    for (i, r) in rays.iter().enumerate() {
        let cpu = gpu_default_cpu(&scene).all_crossings(r);
        assert!(cpu.iter().any(|c| c.triangle == 70_000), "ray {i}: {cpu:?}");
        assert_eq!(lists.of(i), &cpu[..], "ray {i}");
        assert_eq!(counts[i], gpu_default_cpu(&scene).count_crossings(r), "ray {i}");
    }
}

/// The textured sample (`tests/data/textured/leaf.gltf`: an alpha-masked leaf texture,
/// a nearest-filtered, repeated checker) as `octrace render` renders it by default
/// (1024 pixels wide, the scene's cameras: perspective and orthographic): the GPU
/// samples the CPU's texels, cuts out the same pixels, traces the same rays of every
/// kind and gives the same image.
#[test]
fn textured_alpha_masked_scene_renders_on_the_gpu_as_on_the_cpu() {
    use octrace_runtime::render::effects::{RayKind, RenderOptions};
    let Some(ctx) = gpu("textured_alpha_masked_scene_renders_on_the_gpu_as_on_the_cpu") else { return };
    let mesh = octrace_bake::Mesh::load(octrace_tests::data("textured/leaf.gltf")).unwrap();
    let scene = Scene::from_baked(octrace_bake::bake(&mesh, &Default::default()).unwrap()).unwrap();
    let tracer = GpuTracer::new(&ctx.device, &ctx.queue, &scene).unwrap();
    let options = RenderOptions::for_scene(scene.shading());
    for c in &scene.shading().cameras {
        let height = (1024.0 / c.aspect.unwrap()).round() as u32;
        let camera = raysets::Camera::from_scene(c, f64::from(c.yfov).to_degrees(), 1024, height);
        let counts = renders_as_on_the_cpu(&format!("camera '{}'", c.name), ctx, &tracer, &camera, &options);
        assert!(counts.get(RayKind::Alpha) > 10_000, "{}: {counts:?}", c.name);
    }
}

/// Vertex colours (`COLOR_0`, the Khronos sample) on the GPU: the CPU's image and rays.
#[test]
fn vertex_coloured_scene_renders_on_the_gpu_as_on_the_cpu() {
    use octrace_runtime::render::effects::RenderOptions;
    let Some(ctx) = gpu("vertex_coloured_scene_renders_on_the_gpu_as_on_the_cpu") else { return };
    let mesh = octrace_bake::Mesh::load(octrace_tests::data("gltf/BoxVertexColors.gltf")).unwrap();
    let scene = Scene::from_baked(octrace_bake::bake(&mesh, &Default::default()).unwrap()).unwrap();
    let tracer = GpuTracer::new(&ctx.device, &ctx.queue, &scene).unwrap();
    let options = RenderOptions::for_scene(scene.shading());
    let camera = raysets::Camera::standard_sized(&Frame::from_triangles(&mesh.triangles), 512, 512);
    renders_as_on_the_cpu("vertex colours", ctx, &tracer, &camera, &options);
}

/// Emission through emissive textures on the GPU (issue 34): the glow scene with its
/// light (the orange panel an area light, soft shadows, the black one none) and without
/// (the headlight): the CPU's rays of every kind and its image.
#[test]
fn emissive_textures_render_on_the_gpu_as_on_the_cpu() {
    let test = "emissive_textures_render_on_the_gpu_as_on_the_cpu";
    let Some(ctx) = gpu(test) else { return };
    let scenes = vec![
        ("glow, lit", crate::materials::glow_scene(true)),
        ("glow, headlight", crate::materials::glow_scene(false)),
    ];
    emissive_scenes_render_as_on_the_cpu(ctx, scenes);
}

/// The same on DamagedHelmet (its emissive texture a 2048 x 2048 JPEG).
#[test]
#[cfg_attr(not(octrace_shared), ignore = "needs ../shared beside the clone (README: Set up)")]
fn damaged_helmets_emission_renders_on_the_gpu_as_on_the_cpu() {
    let test = "damaged_helmets_emission_renders_on_the_gpu_as_on_the_cpu";
    let Some(ctx) = gpu(test) else { return };
    let Some(path) = octrace_tests::shared_file("gltf/DamagedHelmet.glb", test) else { return };
    emissive_scenes_render_as_on_the_cpu(ctx, vec![("DamagedHelmet", octrace_bake::Mesh::load(path).unwrap())]);
}

fn emissive_scenes_render_as_on_the_cpu(
    ctx: &octrace_runtime::gpu::GpuContext,
    scenes: Vec<(&str, octrace_bake::Mesh)>,
) {
    use octrace_format::Effect;
    use octrace_runtime::render::effects::{EffectSet, RayKind, RenderOptions};
    for (name, mesh) in scenes {
        let scene = Scene::from_baked(octrace_bake::bake(&mesh, &Default::default()).unwrap()).unwrap();
        let tracer = GpuTracer::new(&ctx.device, &ctx.queue, &scene).unwrap();
        let effects = EffectSet::NONE.with(Effect::Shadows).with(Effect::SoftShadows);
        let options = RenderOptions { effects, soft_samples: 4, ..RenderOptions::for_scene(scene.shading()) };
        let camera = raysets::Camera::standard_sized(&Frame::from_triangles(&mesh.triangles), 96, 96);
        let counts = renders_as_on_the_cpu(name, ctx, &tracer, &camera, &options);
        let soft = counts.get(RayKind::SoftShadow);
        assert_eq!(soft > 0, name == "glow, lit", "{name}: {counts:?}");
    }
}

/// Metallic-roughness, occlusion and normal textures on the GPU (issue 34): the panel
/// scene lit (the polished half reflects) and under the headlight with the floor's
/// occlusion texture, the normal-mapped floor, without tangents and with tangents that
/// turn from corner to corner (mixed at each hit) and change sign, and a quad whose
/// base colour, emissive, occlusion and normal textures read four texture-coordinate
/// channels: the CPU's rays of every kind and its image.
#[test]
fn metallic_roughness_occlusion_and_normal_textures_render_on_the_gpu_as_on_the_cpu() {
    use octrace_format::Effect;
    use octrace_runtime::render::effects::{EffectSet, RayKind, RenderOptions};
    let Some(ctx) = gpu("metallic_roughness_occlusion_and_normal_textures_render_on_the_gpu_as_on_the_cpu") else {
        return;
    };
    let scenes = [
        ("metal", crate::materials::metal_scene(true, false)),
        ("occlusion", crate::materials::metal_scene(true, true)),
        ("normal map", crate::materials::bump_scene(0.8)),
        ("normal map, tangents", {
            let mut mesh = crate::materials::bump_scene(0.8);
            mesh.tangents = (0..mesh.triangles.len())
                .map(|k| {
                    let a = k as f32 * 0.7;
                    let w = if k % 3 == 0 { -1.0 } else { 1.0 };
                    [0.0, 1.1, 2.3].map(|d| [(a + d).cos(), 0.0, (a + d).sin(), w])
                })
                .collect();
            mesh
        }),
        ("four channels", crate::texcoords::two_set_mesh()),
    ];
    for (name, mesh) in scenes {
        let scene = Scene::from_baked(octrace_bake::bake(&mesh, &Default::default()).unwrap()).unwrap();
        let tracer = GpuTracer::new(&ctx.device, &ctx.queue, &scene).unwrap();
        let effects = EffectSet::NONE.with(Effect::Shadows).with(Effect::Reflection);
        let options = RenderOptions { effects, ..RenderOptions::for_scene(scene.shading()) };
        let camera = raysets::Camera::standard_sized(&Frame::from_triangles(&mesh.triangles), 96, 96);
        let counts = renders_as_on_the_cpu(name, ctx, &tracer, &camera, &options);
        let wanted = match name {
            "four channels" => RayKind::Primary,
            n if n.starts_with("normal map") => RayKind::Shadow,
            _ => RayKind::Reflection,
        };
        assert!(counts.get(wanted) > 0, "{name}: {counts:?}");
    }
}

/// Fans on the GPU (issue 33): a disk and a cone, rays random, aimed at the centre and
/// aimed near it; the kernels' hierarchy picks the triangles the CPU's picks, every
/// nearest hit is the CPU's bit for bit, every occlusion and crossing list the same,
/// the rendered image the CPU's, and rays near the centre test a small part of what
/// the whole leaves hold (lavapipe:
/// the disk's 70,453 of 8,848,412, the cone's 1,106,202 of 11,771,916).
#[test]
fn fans_trace_on_the_gpu_as_on_the_cpu_and_test_few_triangles() {
    let Some(ctx) = gpu("fans_trace_on_the_gpu_as_on_the_cpu_and_test_few_triangles") else { return };
    let mut rng = octrace_bake::procedural::SplitMix(3);
    for (name, centre, height) in [("disk", [0.0f32; 3], 0.0f32), ("cone", [0.1234, -0.377, 0.05], 0.6)] {
        let mesh = octrace_bake::procedural::cone(2000, centre, 1.0, height);
        let scene = Scene::from_baked(octrace_bake::bake(&mesh, &Default::default()).unwrap()).unwrap();
        let tracer = GpuTracer::new(&ctx.device, &ctx.queue, &scene).unwrap();
        let apex = Vec3::new(centre[0], centre[1] + height, centre[2]);
        let mut sets: Vec<(&str, Vec<Ray>)> = Vec::new();
        for kind in ["random", "centre", "near"] {
            let rays = (0..3000)
                .map(|_| {
                    let o = apex + (Vec3::new(rng.unit(), rng.unit(), rng.unit()) - 0.5) * 4.0;
                    let off = Vec3::new(rng.unit(), rng.unit(), rng.unit()) - 0.5;
                    let at = match kind {
                        "random" => apex + off * 2.0,
                        "centre" => apex,
                        _ => apex + off * 10f32.powf(-2.0 - 3.0 * rng.unit()),
                    };
                    Ray::new(o, at - o)
                })
                .collect();
            sets.push((kind, rays));
        }
        // The render kernel walks with the same step: the CPU's image, looking at the
        // fan's centre.
        let options = octrace_runtime::render::effects::RenderOptions::for_scene(scene.shading());
        let camera = raysets::Camera::standard_sized(&Frame::from_triangles(&mesh.triangles), 64, 64);
        renders_as_on_the_cpu(name, ctx, &tracer, &camera, &options);
        let cpu = gpu_default_cpu(&scene);
        let whole = gpu_default_cpu(&scene).with_fans(None);
        for (kind, rays) in &sets {
            let label = format!("{name} {kind}");
            let mut want = vec![None; rays.len()];
            cpu.intersect_batch(rays, &mut want);
            let got = tracer.intersect_with_stats(rays).unwrap();
            let hits: Vec<Option<Hit>> = got.iter().map(|g| g.0).collect();
            same_hits(&label, rays, &want, &hits);
            let mut occluded = vec![false; rays.len()];
            cpu.occluded_batch(rays, &mut occluded);
            assert_eq!(tracer.occluded(rays).unwrap(), occluded, "{label}: occlusion");
            let lists = tracer.crossings(rays).unwrap();
            let cpu_lists = cpu.crossings_batch(rays, usize::MAX);
            assert_eq!((lists.splits, lists.crossings), (cpu_lists.splits, cpu_lists.crossings), "{label}: crossings");
            let gpu_tests: u64 = got.iter().map(|g| g.1.triangle_tests as u64).sum();
            let all_tests: u64 = rays.iter().map(|r| whole.intersect_with_stats(r).1.triangle_tests as u64).sum();
            let cpu_tests: u64 = rays.iter().map(|r| cpu.intersect_with_stats(r).1.triangle_tests as u64).sum();
            eprintln!(
                "{label}: the GPU tested {gpu_tests} triangles, the CPU {cpu_tests}, the whole leaves hold {all_tests}"
            );
            // The kernel picks what the CPU picks (a few more where its 64 picks run
            // out and it tests the leaf whole).
            assert!(gpu_tests * 10 <= cpu_tests * 11, "{label}: GPU {gpu_tests}, CPU {cpu_tests}");
            if *kind == "near" {
                assert!(gpu_tests * 5 < all_tests, "{label}: {gpu_tests} of {all_tests}");
            }
        }
    }
}

/// The environment on the GPU (issue 45, item 2): a scene lit only by an emissive
/// panel, with the neutral environment (auto) and without it, and a headlight scene
/// given a uniform one: the CPU's rays of every kind (soft shadows sampled at the same
/// stratified points) and its image.
#[test]
fn the_environment_renders_on_the_gpu_as_on_the_cpu() {
    use octrace_runtime::render::effects::{Environment, RayKind, RenderOptions, Sky};
    let test = "the_environment_renders_on_the_gpu_as_on_the_cpu";
    let Some(ctx) = gpu(test) else { return };
    let cases = [
        ("emitters only, auto", crate::environment::lit_from_above(), Environment::Auto),
        ("emitters only, off", crate::environment::lit_from_above(), Environment::Off),
        ("headlight scene, uniform", crate::effects::base_scene(|_| {}), Environment::Sky(Sky::uniform(0.8))),
        ("headlight scene, sky", crate::effects::base_scene(|_| {}), Environment::Sky(Sky::NEUTRAL)),
    ];
    for (name, mesh, environment) in cases {
        let scene = Scene::from_baked(octrace_bake::bake(&mesh, &Default::default()).unwrap()).unwrap();
        let tracer = GpuTracer::new(&ctx.device, &ctx.queue, &scene).unwrap();
        let options = RenderOptions { environment, soft_samples: 4, ..RenderOptions::for_scene(scene.shading()) };
        let camera = raysets::Camera::look_at(DVec3::new(0.0, 3.0, 5.0), DVec3::new(0.0, 0.5, 0.0), 50.0, 64, 64);
        let counts = renders_as_on_the_cpu(name, ctx, &tracer, &camera, &options);
        assert_eq!(counts.get(RayKind::SoftShadow) > 0, name.starts_with("emitters"), "{name}: {counts:?}");
    }
}

/// Single-sided materials on the GPU (issue 45, item 3): camera rays through a quad's
/// back to what lies beyond it, and shadows cast only where the light sees a
/// surface's front: the CPU's rays of every kind and its image.
#[test]
fn single_sided_surfaces_render_on_the_gpu_as_on_the_cpu() {
    use crate::effects::{add, diffuse, floor, point_light};
    use octrace_runtime::render::effects::RenderOptions;
    let test = "single_sided_surfaces_render_on_the_gpu_as_on_the_cpu";
    let Some(ctx) = gpu(test) else { return };
    let mut mesh = octrace_bake::Mesh::default();
    add(&mut mesh, floor(3.0, 0.0), diffuse("floor", 0.7));
    let one_side = |name: &str| octrace_format::Material { double_sided: false, ..diffuse(name, 0.5) };
    // A blocker whose front the light sees, one whose back it sees.
    let mut away = floor(0.4, 1.0);
    for t in &mut away.triangles {
        t.swap(1, 2);
    }
    let mut towards = floor(0.4, 1.2);
    for t in &mut towards.triangles {
        for v in t.iter_mut() {
            v[0] += 1.5;
        }
    }
    add(&mut mesh, away, one_side("away"));
    add(&mut mesh, towards, one_side("towards"));
    // A wall facing away from the camera, single-sided: it sees through it.
    let wall = octrace_bake::Mesh::from_triangles(vec![
        [[-1.0, 0.0, 1.5], [-1.0, 1.5, 1.5], [1.0, 1.5, 1.5]],
        [[-1.0, 0.0, 1.5], [1.0, 1.5, 1.5], [1.0, 0.0, 1.5]],
    ]);
    add(&mut mesh, wall, one_side("wall"));
    mesh.lights.push(point_light([0.3, 4.0, 0.2], 25.0));
    let scene = Scene::from_baked(octrace_bake::bake(&mesh, &Default::default()).unwrap()).unwrap();
    let tracer = GpuTracer::new(&ctx.device, &ctx.queue, &scene).unwrap();
    let camera = raysets::Camera::look_at(DVec3::new(0.5, 3.0, 5.0), DVec3::new(0.5, 0.3, 0.0), 50.0, 64, 64);
    renders_as_on_the_cpu("single-sided", ctx, &tracer, &camera, &RenderOptions::for_scene(scene.shading()));
}
