//! Rays built on the octree's own planes (`octrace_bake::hard_rays`): in cell planes
//! with `+0.0` and `-0.0` components, along cell edges, from and through cell corners,
//! on every axis, sign and level. From inside closed solids none may leak; against the
//! oracle every one must agree.

use std::collections::HashSet;

use glam::Vec3;
use octrace_bake::hard_rays::{grid_rays, GridPlanes, HardKind, HardRay};
use octrace_bake::procedural::{self, ClosedSolid, SplitMix};
use octrace_bake::{bake, BuildParams};
use octrace_runtime::{Ray, Scene};

use super::{all_agree, oracle, scene, test_scene};

/// Where the closed solids are shot from: at the origin, and moved far from it (scaled
/// so that the `f32` grid there keeps their shape: spacing 1.0 at 1e7).
pub(crate) const PLACEMENTS: [(f64, f64); 4] = [(0.0, 1.0), (1e4, 1.0), (1e7, 1e3), (-3e6, 100.0)];

/// A solid's bake and its grid rays, as rays.
pub(crate) fn solid_rays(solid: &ClosedSolid, n: usize, seed: u64) -> (Scene, Vec<HardRay>, Vec<Ray>) {
    let scene = Scene::from_baked(bake(&solid.mesh, &BuildParams::auto()).unwrap()).unwrap();
    let hard = solid.grid_rays(&GridPlanes::of(&scene.view()), n, seed);
    let rays = hard.iter().map(|r| Ray::new(Vec3::from(r.origin), Vec3::from(r.dir))).collect();
    (scene, hard, rays)
}

/// Every case of the generator came out: each kind, axis and sign octant, each level.
pub(crate) fn covers_every_case(name: &str, hard: &[HardRay], depth: u32) {
    let seen: HashSet<_> = hard.iter().map(|r| (r.kind, r.axis, r.signs)).collect();
    assert_eq!(seen.len(), HardKind::ALL.len() * 3 * 8, "{name}: some kind, axis or sign never came out");
    let levels: HashSet<_> = hard.iter().map(|r| r.level).collect();
    assert_eq!(levels.len() as u32, depth, "{name}: some level never came out");
}

/// The leaks of a set of rays that must all hit, on one-ray and batch calls, with the
/// first of each for the message.
fn leaks(scene: &Scene, rays: &[Ray]) -> (Vec<Ray>, Vec<Ray>) {
    let tracer = scene.tracer();
    let one: Vec<Ray> = rays.iter().filter(|r| tracer.intersect(r).is_none()).copied().collect();
    let mut hits = vec![None; rays.len()];
    tracer.intersect_batch(rays, &mut hits);
    let mut occluded = vec![false; rays.len()];
    tracer.occluded_batch(rays, &mut occluded);
    let batch = rays.iter().zip(hits.iter().zip(&occluded)).filter(|(_, (h, o))| h.is_none() || !**o);
    (one, batch.map(|(r, _)| *r).collect())
}

/// No ray on the octree's planes escapes a closed solid: 60,000 rays a solid and
/// placement (the five solids at the origin, at 1e4, at 1e7 and at -3e6), one-ray and
/// batch calls, nearest and any hit. `octrace soak` runs a million a solid. Before the
/// slab rule for zero components, 2-3 % of these rays leaked (y planes with +0.0 and
/// -0.0, z planes with -0.0).
#[test]
fn rays_on_cell_planes_edges_and_corners_never_leak_from_closed_solids() {
    for (offset, scale) in PLACEMENTS {
        for solid in procedural::closed_solids() {
            let solid = solid.moved(offset, scale);
            let (scene, hard, rays) = solid_rays(&solid, 60_000, 11);
            let name = solid.label();
            assert_eq!(rays.len(), 60_000, "{name}");
            covers_every_case(&name, &hard, scene.view().params.max_depth);
            let (one, batch) = leaks(&scene, &rays);
            assert!(one.is_empty(), "{name}: {} of {} rays leaked, first {:?}", one.len(), rays.len(), one[0]);
            assert!(batch.is_empty(), "{name}: {} batch rays leaked, first {:?}", batch.len(), batch[0]);
        }
    }
}

/// Grid rays at the mesh, from everywhere in its box, against the oracle: the test
/// scene at depths 3, 5 and 7 (with a coarse leaf target, so that leaves differ in
/// level and rays cross 2:1 changes), every case of the generator.
#[test]
fn grid_rays_agree_with_the_oracle() {
    let mesh = test_scene();
    let o = oracle(&mesh);
    let vertices: Vec<[f32; 3]> = mesh.triangles.iter().flatten().copied().collect();
    for depth in [3, 5, 7] {
        let s = scene(&mesh, Some(depth), 2);
        let grid = GridPlanes::of(&s.view());
        let (lo, hi) = (s.view().bounds.mesh_lo, s.view().bounds.mesh_hi);
        let point = |r: &mut SplitMix| [0, 1, 2].map(|a| lo[a] - 0.5 + (hi[a] - lo[a] + 1.0) * r.unit());
        let aim = |r: &mut SplitMix| vertices[(r.next_u64() % vertices.len() as u64) as usize];
        let hard = grid_rays(&grid, 2400, depth as u64, point, Some(aim), |_| true);
        covers_every_case(&format!("depth {depth}"), &hard, depth);
        let rays: Vec<Ray> = hard.iter().map(|r| Ray::new(Vec3::from(r.origin), Vec3::from(r.dir))).collect();
        all_agree(&format!("grid rays, depth {depth}"), &s, &o, &rays);
    }
}

/// A ray as literal bits: origin and direction.
fn ray_of(o: [u32; 3], d: [u32; 3]) -> Ray {
    Ray::new(Vec3::from(o.map(f32::from_bits)), Vec3::from(d.map(f32::from_bits)))
}

/// Regressions found by the generator (each leaked before the slab rule): in-plane
/// rays in y planes with `-0.0` and `+0.0`, in a z plane with `-0.0`, from a corner of
/// the room, and in a y plane of the sphere moved to 1e7.
#[test]
fn regression_in_plane_rays_that_leaked() {
    let solid = |name: &str| procedural::closed_solids().into_iter().find(|s| s.name == name).unwrap();
    let cases = [
        (solid("sphere"), [3189840102, 3192704208, 1057856491], [3195574787, 2147483648, 3208615454]),
        (solid("sphere"), [1041650286, 1028443328, 1056330982], [1038531062, 0, 1064858224]),
        (solid("sphere"), [1049689199, 1041932351, 1050253720], [1065218513, 1059228296, 2147483648]),
        (solid("room"), [0, 1048576000, 1073741824], [3208245611, 2147483648, 3202655256]),
        (solid("sphere").moved(1e7, 1e3), [1259903068, 1259902392, 1259902763], [3190420630, 2147483648, 3205855898]),
    ];
    for (solid, o, d) in cases {
        let scene = Scene::from_baked(bake(&solid.mesh, &BuildParams::auto()).unwrap()).unwrap();
        let ray = ray_of(o, d);
        assert!(solid.contains(ray.origin.to_array()), "{}: the origin is inside", solid.label());
        assert!(scene.intersect(&ray).is_some(), "{}: {ray:?} leaks", solid.label());
        assert!(scene.occluded(&ray), "{}: {ray:?} is not occluded", solid.label());
        assert!(scene.intersect_batch(&[ray; 9]).iter().all(Option::is_some), "{}: batch", solid.label());
    }
}

/// The bunny ray: y is the root's low y plus 63 cells of the default bake,
/// the direction's y component `-0.0`; it missed (with `+0.0` it hit triangle 38327).
#[test]
fn regression_the_bunny_ray_in_a_y_plane_with_negative_zero() {
    let scene = octrace_tests::bunny_scene();
    let o = [0xbc6bedfa, 0x3ddd986c, 0x3e99999a];
    for dy in [0x8000_0000u32, 0] {
        let ray = ray_of(o, [(-0.25f32).to_bits(), dy, (-1.0f32).to_bits()]);
        let hit = scene.intersect(&ray).unwrap_or_else(|| panic!("{ray:?} misses"));
        assert_eq!(hit.triangle, 38327, "{ray:?}");
        assert!((hit.t - 0.27274).abs() < 1e-4, "{hit:?}");
        assert_eq!(scene.intersect_batch(&[ray; 17])[16], Some(hit), "batch");
    }
}

/// The room: a closed box of 32 x 32 quads a face, a camera inside on a cell
/// plane looking horizontally, an image 101 rows high: the middle row's rays lie in
/// the plane (their y component is zero) and showed the background through the wall.
/// Every pixel must see a wall.
#[test]
fn regression_a_camera_on_a_cell_plane_sees_no_crack() {
    let room = procedural::cube([-2.0, -1.0, -3.0], [2.0, 1.5, 3.0], 32);
    let scene = Scene::from_baked(bake(&room, &BuildParams::auto()).unwrap()).unwrap();
    let grid = GridPlanes::of(&scene.view());
    let y = grid.snap(1, grid.depth, 0.0625);
    for (eye, target) in
        [([0.3, y, 0.2], [1.3, y, -0.8]), ([-0.7, y, 0.0], [-0.7, y, 5.0]), ([0.0, y, 0.0], [-4.0, y, 0.0])]
    {
        let camera = octrace_runtime::raysets::Camera::look_at(
            glam::DVec3::from(eye.map(f64::from)),
            glam::DVec3::from(target.map(f64::from)),
            60.0,
            96,
            101,
        );
        let rays = camera.rays();
        let middle = &rays[50 * 96..51 * 96];
        assert!(middle.iter().all(|r| r.dir.y == 0.0 && r.origin.y == y), "the middle row lies in the plane");
        let hits = scene.intersect_batch(&rays);
        let missed = hits.iter().filter(|h| h.is_none()).count();
        assert_eq!(missed, 0, "camera at {eye:?}: {missed} pixels see through the wall");
        for r in middle {
            assert!(scene.intersect(r).is_some(), "{r:?}");
        }
    }
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig { cases: 24, ..Default::default() })]

    /// Random soups at random depths, shot with grid rays (every case of the
    /// generator, aimed at the soup's vertices): the octree agrees with the oracle.
    /// `all_agree` runs each ray with its zero components' signs flipped too.
    #[test]
    fn grid_rays_on_random_soups_agree_with_the_oracle(
        seed in proptest::prelude::any::<u64>(),
        n in 20usize..300,
        depth in 2u32..8,
        leaf in 1u32..6,
    ) {
        let mesh = procedural::soup(seed, n, 4.0, 1.0);
        let s = scene(&mesh, Some(depth), leaf);
        let grid = GridPlanes::of(&s.view());
        let vertices: Vec<[f32; 3]> = mesh.triangles.iter().flatten().copied().collect();
        let point = |r: &mut SplitMix| [0; 3].map(|_| r.unit() * 6.0 - 1.0);
        let aim = |r: &mut SplitMix| vertices[(r.next_u64() % vertices.len() as u64) as usize];
        let hard = grid_rays(&grid, 400, seed, point, Some(aim), |_| true);
        let rays: Vec<Ray> = hard.iter().map(|r| Ray::new(Vec3::from(r.origin), Vec3::from(r.dir))).collect();
        all_agree(&format!("soup {seed} depth {depth}"), &s, &oracle(&mesh), &rays);
    }
}
