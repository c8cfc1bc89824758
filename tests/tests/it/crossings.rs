//! Every crossing along a ray (`Tracer::crossings`): the walk's list equals a
//! brute-force list built with the same watertight test and edge rule, ray for ray,
//! bit for bit; counts of rays through every vertex and edge of closed meshes are
//! exactly right.

use glam::Vec3;
use octrace_bake::hard_rays::GridPlanes;
use octrace_bake::procedural::{self, SplitMix};
use octrace_bake::topology::signed_volume;
use octrace_bake::{bake, BuildParams, Mesh};
use octrace_runtime::cpu::Crossing;
use octrace_runtime::{Ray, Scene};

pub(crate) fn scene_of(mesh: &Mesh, params: &BuildParams) -> Scene {
    Scene::from_baked(bake(mesh, params).unwrap()).unwrap()
}

/// The walk's crossings equal the brute-force list for every ray, and every prefix
/// (`first_crossings`) and count agrees with it.
fn walk_equals_brute_force(name: &str, scene: &Scene, rays: &[Ray]) -> usize {
    let tracer = scene.tracer();
    let mut crossings = 0;
    for (i, r) in rays.iter().enumerate() {
        let walked = tracer.all_crossings(r);
        let brute = tracer.crossings_by_brute_force(r);
        assert_eq!(walked, brute, "{name}: ray {i} {r:?}");
        let k = i % 4;
        assert_eq!(tracer.first_crossings(r, k), brute[..k.min(brute.len())], "{name}: first {k}, ray {i}");
        let count = tracer.count_crossings(r);
        assert_eq!(count.total as usize, brute.len(), "{name}: count, ray {i}");
        assert_eq!(count.entries as usize, brute.iter().filter(|c| c.enters).count(), "{name}: entries, ray {i}");
        crossings += brute.len();
    }
    crossings
}

/// Random rays from a box twice the mesh's, and the same rays bent where f32 gives out
/// (tiny components, tiny and huge lengths) and from far away.
pub(crate) fn random_rays(mesh: &Mesh, n: usize, seed: u64) -> Vec<Ray> {
    let (lo, hi) = bounds(mesh);
    let (c, e) = ((lo + hi) * 0.5, (hi - lo).max_element());
    let mut rng = SplitMix(seed);
    let unit = |r: &mut SplitMix| Vec3::new(r.unit(), r.unit(), r.unit()) - 0.5;
    let mut rays: Vec<Ray> = (0..n).map(|_| Ray::new(c + unit(&mut rng) * 2.0 * e, unit(&mut rng))).collect();
    let bent: Vec<Ray> = rays
        .iter()
        .enumerate()
        .map(|(i, r)| match i % 4 {
            0 => Ray { dir: Vec3::new(r.dir.x, f32::from_bits(1).copysign(r.dir.y), r.dir.z), ..*r },
            1 => Ray { dir: r.dir * 1e-30, ..*r },
            2 => Ray { dir: r.dir * 1e25, ..*r },
            _ => Ray { origin: c - r.dir * 1e6 * e, ..*r },
        })
        .collect();
    rays.extend(bent);
    rays
}

fn bounds(mesh: &Mesh) -> (Vec3, Vec3) {
    let pts = mesh.triangles.iter().flatten().map(|&p| Vec3::from(p));
    pts.fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), p| (lo.min(p), hi.max(p)))
}

/// A soup, closed solids (a sphere, a torus), an open grid and a fan.
pub(crate) fn test_meshes() -> [(&'static str, Mesh); 5] {
    [
        ("soup", procedural::soup(3, 600, 4.0, 0.8)),
        ("sphere", procedural::sphere([0.1, 0.2, -0.3], 1.5, 20, 28)),
        ("torus", procedural::torus([0.0; 3], 1.0, 0.35, 30, 14)),
        ("grid", procedural::grid(12, 3.0)),
        ("fan", procedural::fan(48, 1.0)),
    ]
}

/// Soups, procedural meshes and the bunny, at several depths: the walk's list is the
/// brute force's, ray for ray.
#[test]
fn all_crossings_equal_the_brute_force_list() {
    for (name, mesh) in &test_meshes() {
        for params in [
            BuildParams::auto(),
            BuildParams { max_depth: Some(6), leaf_size: Some(1), ..BuildParams::auto() },
            BuildParams { max_depth: Some(2), leaf_size: Some(4), ..BuildParams::auto() },
        ] {
            let scene = scene_of(mesh, &params);
            let n = walk_equals_brute_force(name, &scene, &random_rays(mesh, 800, 7));
            assert!(n > 100, "{name}: {n} crossings");
        }
    }
}

/// Rays on the octree's own planes (every case and twist of the hard-ray generator),
/// aimed at the mesh's vertices: the walk's list is the brute force's.
#[test]
fn grid_rays_cross_as_the_brute_force_says() {
    let mesh = crate::hard_cases::test_scene();
    let vertices: Vec<[f32; 3]> = mesh.triangles.iter().flatten().copied().collect();
    for depth in [3, 6] {
        let scene = scene_of(&mesh, &BuildParams { max_depth: Some(depth), leaf_size: Some(2), ..BuildParams::auto() });
        let grid = GridPlanes::of(&scene.view());
        let (lo, hi) = bounds(&mesh);
        let point = |r: &mut SplitMix| [0, 1, 2].map(|a| lo[a] - 0.5 + (hi[a] - lo[a] + 1.0) * r.unit());
        let aim = |r: &mut SplitMix| vertices[(r.next_u64() % vertices.len() as u64) as usize];
        let hard = octrace_bake::hard_rays::grid_rays(&grid, 3000, depth as u64, point, Some(aim), |_| true);
        let rays: Vec<Ray> = hard.iter().map(|r| Ray::new(Vec3::from(r.origin), Vec3::from(r.dir))).collect();
        walk_equals_brute_force(&format!("grid rays, depth {depth}"), &scene, &rays);
    }
}

/// Lines through every vertex, edge midpoint and face centre of closed grid cubes, and
/// through every vertex and edge midpoint of the closed solids, from outside across the
/// solid: exactly two crossings each (in, out), entering first; from inside the
/// solids: exactly one, leaving. (Owned edges: with closed edges a line through a
/// shared edge counted four.)
#[test]
fn lines_through_every_vertex_and_edge_of_closed_meshes_cross_twice() {
    for n in [1, 3, 4] {
        let mesh = procedural::cube([-1.0, -0.5, 0.25], [1.0, 1.5, 2.25], n);
        assert!(signed_volume(&mesh.triangles) > 0.0, "the cube is wound outward");
        let scene = scene_of(&mesh, &BuildParams { max_depth: Some(4), leaf_size: Some(1), ..BuildParams::auto() });
        let tracer = scene.tracer();
        let centre = Vec3::new(0.0, 0.5, 1.25);
        let mut points = Vec::new();
        for t in &mesh.triangles {
            let [a, b, c] = t.map(Vec3::from);
            points.extend([a, b, c, (a + b) * 0.5, (b + c) * 0.5, (c + a) * 0.5, (a + b + c) / 3.0]);
        }
        for (i, p) in points.iter().enumerate() {
            // Through p from outside, across the centre's side, in a few directions.
            for tilt in [Vec3::ZERO, Vec3::new(0.013, -0.021, 0.007), Vec3::new(-0.3, 0.2, 0.1)] {
                let d = (centre + tilt - *p).normalize();
                let ray = Ray::new(*p - 5.0 * d, d);
                let c = tracer.all_crossings(&ray);
                assert_eq!(c.len(), 2, "cube {n}: point {i} {p}, tilt {tilt}: {c:?}");
                assert!(c[0].enters && !c[1].enters, "cube {n}: point {i}: {c:?}");
            }
        }
    }
    for solid in procedural::closed_solids() {
        let scene = scene_of(&solid.mesh, &BuildParams::auto());
        let tracer = scene.tracer();
        let outward = signed_volume(&solid.mesh.triangles) > 0.0;
        let mut rng = SplitMix(5);
        for (o, d) in solid.leak_rays(2000, 9) {
            let ray = Ray::new(Vec3::from(o), Vec3::from(d));
            let c = tracer.count_crossings(&ray);
            // From inside: an odd count; leaving one more time than entering.
            assert_eq!(c.total % 2, 1, "{}: {ray:?}: {c:?}", solid.name);
            assert_eq!(c.winding(), if outward { -1 } else { 1 }, "{}: {ray:?}", solid.name);
            // The same line from outside, through the same point.
            let back = Ray::new(Vec3::from(o) - Vec3::from(d) * 50.0, Vec3::from(d));
            assert_eq!(tracer.count_crossings(&back).winding(), 0, "{}: {back:?}", solid.name);
            let _ = rng.next_u64();
        }
    }
}

/// Coplanar copies are all listed, in input order, at the same distance.
#[test]
fn coplanar_copies_are_all_listed_in_input_order() {
    let (mesh, scene) = crate::hard_cases::tiny_directions::duplicates();
    let ray = Ray::new(Vec3::new(0.1, 0.1, -1.0), Vec3::new(0.0, 0.0, 1.0));
    let c: Vec<Crossing> = scene.tracer().all_crossings(&ray);
    let ids: Vec<u32> = c.iter().map(|c| c.triangle).collect();
    let mut expect = vec![0];
    expect.extend(49..149);
    assert_eq!(ids, expect);
    assert!(c.iter().all(|x| x.t == 1.5));
    assert_eq!(mesh.triangles.len(), 149);
}

/// The batch calls (eight walks a vector where the processor has AVX2, on one thread
/// and all, with and without the lanes) give each ray the one-ray call's list, bit for
/// bit: all of them, the first k, counts, and fixed slots with truncation flagged.
#[test]
fn batches_answer_each_ray_as_the_one_ray_walk() {
    let mut mesh = procedural::sphere([0.0; 3], 1.0, 24, 32);
    mesh.triangles.extend(procedural::soup(5, 2000, 2.5, 0.3).triangles);
    let scene = scene_of(&mesh, &BuildParams::auto());
    let mut rays = random_rays(&mesh, 3000, 11);
    rays.push(Ray::new(Vec3::splat(f32::NAN), Vec3::X));
    rays.push(Ray::new(Vec3::ZERO, Vec3::ZERO));
    for lanes in [true, false] {
        let tracer = scene.tracer().with_lanes(lanes);
        let one: Vec<Vec<Crossing>> = rays.iter().map(|r| tracer.all_crossings(r)).collect();
        let all = tracer.crossings_batch(&rays, usize::MAX);
        let par = tracer.par_crossings_batch(&rays, usize::MAX);
        assert_eq!(all, par, "lanes {lanes}: one thread and all");
        assert_eq!(all.splits.len(), rays.len() + 1);
        for (i, list) in one.iter().enumerate() {
            assert_eq!(all.of(i), &list[..], "lanes {lanes}: ray {i} {:?}", rays[i]);
        }
        let first = tracer.crossings_batch(&rays, 2);
        for (i, list) in one.iter().enumerate() {
            assert_eq!(first.of(i), &list[..list.len().min(2)], "lanes {lanes}: first 2, ray {i}");
        }
        let mut counts = vec![Default::default(); rays.len()];
        tracer.par_count_crossings_batch(&rays, &mut counts);
        for (i, list) in one.iter().enumerate() {
            assert_eq!(counts[i], tracer.count_crossings(&rays[i]), "lanes {lanes}: count, ray {i}");
            assert_eq!(counts[i].total as usize, list.len());
        }
        let cap = 3;
        let mut slots = vec![Crossing { t: 0.0, triangle: 0, u: 0.0, v: 0.0, enters: false }; rays.len() * cap];
        let (mut lens, mut cut) = (vec![0u32; rays.len()], vec![false; rays.len()]);
        tracer.par_crossings_into(&rays, cap, &mut slots, &mut lens, &mut cut);
        for (i, list) in one.iter().enumerate() {
            assert_eq!(lens[i] as usize, list.len().min(cap), "ray {i}");
            assert_eq!(cut[i], list.len() > cap, "ray {i}");
            assert_eq!(&slots[i * cap..][..lens[i] as usize], &list[..lens[i] as usize], "ray {i}");
        }
        assert!(cut.iter().any(|&c| c), "some ray crosses more than {cap} times");
    }
}
