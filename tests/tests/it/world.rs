//! Worlds of instances against the same triangles placed in `f64`, rounded, and
//! baked into one file, and against the brute-force oracle over them.

use std::sync::Arc;

use octrace_bake::procedural::{self, SplitMix};
use octrace_bake::{bake, BuildParams, Mesh};
use octrace_runtime::glam::Vec3;
use octrace_runtime::reference::{Agreement, Reference};
use octrace_runtime::world::{Transform, World};
use octrace_runtime::{Error, Ray, Scene};

pub(crate) fn scene(mesh: &Mesh) -> Arc<Scene> {
    Arc::new(Scene::from_baked(bake(mesh, &BuildParams::auto()).expect("bakes")).expect("opens"))
}

/// A closed sphere, a closed cube of 3x3 squares a face, an open grid.
fn props() -> Vec<(Mesh, Arc<Scene>)> {
    [
        procedural::sphere([0.2, -0.1, 0.3], 1.0, 12, 18),
        procedural::cube([-1.0; 3], [1.0; 3], 3),
        procedural::grid(5, 2.0),
    ]
    .into_iter()
    .map(|m| {
        let s = scene(&m);
        (m, s)
    })
    .collect()
}

/// A random placement: a rotation, a scale per axis (mirrored now and then) and a
/// translation within `reach`.
pub(crate) fn placement(rng: &mut SplitMix, reach: f64) -> Transform {
    let mut u = || rng.unit() as f64;
    let axis = [u() - 0.5, u() - 0.5, u() - 0.5];
    let angle = std::f64::consts::TAU * u();
    let mut scale = [0.4 + 1.6 * u(), 0.4 + 1.6 * u(), 0.4 + 1.6 * u()];
    if u() < 0.2 {
        scale[0] = -scale[0];
    }
    let at = [reach * (2.0 * u() - 1.0), reach * (2.0 * u() - 1.0), reach * (2.0 * u() - 1.0)];
    Transform::scaling(scale).then(&Transform::rotation(axis, angle)).then(&Transform::translation(at))
}

/// The world's triangles placed in `f64` and rounded, in instance order (removed ones
/// skipped), and each live instance's first global index.
fn placed_triangles(
    world: &World,
    meshes: &[(Mesh, Arc<Scene>)],
    ids: &[u32],
) -> (Vec<[[f32; 3]; 3]>, Vec<Option<u32>>) {
    let mut all = Vec::new();
    let mut first = Vec::new();
    for &id in ids {
        let Some((scene, transform)) = world.instance(id) else {
            first.push(None);
            continue;
        };
        first.push(Some(all.len() as u32));
        let mesh = &meshes.iter().find(|(_, s)| Arc::ptr_eq(s, scene)).expect("a prop").0;
        all.extend(mesh.triangles.iter().map(|t| t.map(|v| transform.point(v.map(f64::from)).map(|c| c as f32))));
    }
    (all, first)
}

pub(crate) fn rays(rng: &mut SplitMix, n: usize, reach: f32) -> Vec<Ray> {
    (0..n)
        .map(|i| {
            let mut u = || rng.unit();
            let o = Vec3::new(2.0 * u() - 1.0, 2.0 * u() - 1.0, 2.0 * u() - 1.0) * reach * 1.3;
            // Half of them aimed at the middle, so that they pass through crowds.
            let target = if i % 2 == 0 {
                Vec3::new(2.0 * u() - 1.0, 2.0 * u() - 1.0, 2.0 * u() - 1.0) * reach * 0.3
            } else {
                o + Vec3::new(u() - 0.5, u() - 0.5, u() - 0.5)
            };
            let tmax = if i % 5 == 0 { reach * u() } else { f32::INFINITY };
            Ray::segment(o, target - o, 0.0, tmax)
        })
        .collect()
}

/// Compares the world's nearest hits and occlusion with the oracle's and with the
/// baked file's; returns how many rays hit.
fn check(world: &World, props: &[(Mesh, Arc<Scene>)], ids: &[u32], rays: &[Ray]) -> usize {
    let (triangles, first) = placed_triangles(world, props, ids);
    let global = |instance: u32, triangle: u32| {
        let at = ids.iter().position(|&id| id == instance).expect("a live instance");
        first[at].expect("live") + triangle
    };
    let oracle = Reference::in_input_order(triangles.clone());
    let baked = Scene::from_baked(bake(&Mesh::from_triangles(triangles.clone()), &BuildParams::auto()).expect("bakes"))
        .expect("opens");
    let (mut hits, mut ties) = (0, 0);
    for (i, ray) in rays.iter().enumerate() {
        let want = oracle.intersect(ray);
        let got = world.intersect(ray).map(|h| (h.hit.t, global(h.instance, h.hit.triangle), h.hit.u, h.hit.v));
        match oracle.compare_with(ray, want, got) {
            Agreement::Same => {}
            Agreement::Tie => ties += 1,
            Agreement::Different => panic!("ray {i} {ray:?}: the world answers {got:?}, the oracle {want:?}"),
        }
        // The distance, where both name the same triangle and the ray does not graze
        // it: within the rounding of the carried ray (a few f32 ulps of the origin's
        // and the hit's coordinates, over the cosine).
        if let (Some(g), Some(w)) = (got, want) {
            hits += 1;
            if g.1 == w.triangle {
                let t = triangles[w.triangle as usize].map(Vec3::from_array);
                let n = (t[1] - t[0]).cross(t[2] - t[0]).normalize();
                let cos = n.dot(ray.dir.normalize()).abs();
                if cos > 0.05 {
                    let reach = (ray.origin.abs().max_element() + (ray.dir * w.t as f32).abs().max_element()) as f64;
                    let bound = 64.0 * f32::EPSILON as f64 * reach / cos as f64 / ray.dir.length() as f64;
                    assert!(
                        (g.0 as f64 - w.t).abs() <= bound + w.t * 2.4e-7,
                        "ray {i}: t {} against the oracle's {} (bound {bound})",
                        g.0,
                        w.t
                    );
                }
            }
        }
        // The same triangles baked into one file: the same triangle, or a tie as the
        // oracle sees it.
        let one = baked.intersect(ray).map(|h| (h.t, h.triangle, h.u, h.v));
        if got.map(|g| g.1) != one.map(|h| h.1) {
            assert_ne!(oracle.compare_with(ray, want, one), Agreement::Different, "ray {i}: the baked file is off");
            assert_ne!(oracle.compare_with(ray, want, got), Agreement::Same, "ray {i}: {got:?} against {one:?}");
        }
        let occluded = world.occluded(ray);
        assert_ne!(
            oracle.compare_occluded_with(ray, oracle.occluded(ray), occluded),
            Agreement::Different,
            "ray {i}: occluded {occluded}"
        );
    }
    assert!(ties * 100 <= rays.len(), "{ties} ties in {} rays", rays.len());
    hits
}

#[test]
fn a_world_answers_as_its_triangles_placed_and_baked_into_one_file() {
    let props = props();
    let mut rng = SplitMix(51);
    let reach = 12.0;
    let mut world = World::new();
    let mut ids = Vec::new();
    for k in 0..240 {
        let (_, s) = &props[k % props.len()];
        ids.push(world.add(s, placement(&mut rng, reach)).expect("placed"));
    }
    // Nothing is visible before the commit.
    let rays = rays(&mut rng, 1500, reach as f32);
    assert!(rays.iter().all(|r| world.intersect(r).is_none()));
    world.commit();
    assert_eq!(world.len(), 240);
    let hits = check(&world, &props, &ids, &rays);
    assert!(hits > 500, "{hits} hits: the rays should meet the crowd");
    let batch = world.intersect_batch(&rays);
    assert_eq!(batch, rays.iter().map(|r| world.intersect(r)).collect::<Vec<_>>());
    assert_eq!(world.occluded_batch(&rays), rays.iter().map(|r| world.occluded(r)).collect::<Vec<_>>());

    // Moves alone: the top level refit.
    for &id in ids.iter().step_by(2) {
        world.set_transform(id, placement(&mut rng, reach)).expect("moved");
    }
    world.commit();
    check(&world, &props, &ids, &rays);
    // Instances gone and come: rebuilt.
    for &id in ids.iter().skip(1).step_by(3) {
        world.remove(id).expect("removed");
    }
    for k in 0..40 {
        ids.push(world.add(&props[k % props.len()].1, placement(&mut rng, reach)).expect("placed"));
    }
    world.commit();
    assert_eq!(world.len(), 240 - 80 + 40);
    check(&world, &props, &ids, &rays);
    // Everything moved far apart, one at a time: a refit that degrades the tree is
    // rebuilt, and the answers stay right either way.
    for &id in &ids {
        if world.instance(id).is_some() {
            world.set_transform(id, placement(&mut rng, 3.0 * reach)).expect("moved");
        }
    }
    world.commit();
    check(&world, &props, &ids, &rays);
}

#[test]
fn many_instances_of_one_scene_share_it_and_name_their_hits() {
    let ball = scene(&procedural::sphere([0.0; 3], 1.0, 16, 24));
    let mut world = World::new();
    let row: Vec<u32> = (0..10)
        .map(|k| world.add(&ball, Transform::translation([3.0 * k as f64, 0.0, 0.0])).expect("placed"))
        .collect();
    world.commit();
    for (k, &id) in row.iter().enumerate() {
        let ray = Ray::new(Vec3::new(3.0 * k as f32, 0.1, -5.0), Vec3::Z);
        let hit = world.intersect(&ray).expect("a hit");
        assert_eq!(hit.instance, id);
        let s = world.surface(&hit).expect("a live instance");
        assert!((s.point.x - 3.0 * k as f32).abs() < 0.2 && (s.point.z + 1.0).abs() < 0.05, "{s:?}");
        assert!(s.geometric_normal.z < -0.95, "{s:?}");
        // Its scene's own hit, for the ray carried by hand.
        let local = Ray::new(Vec3::new(0.0, 0.1, -5.0), Vec3::Z);
        assert_eq!(ball.intersect(&local), Some(hit.hit));
    }
    // From far away (the origin moved to just before the box, the distance shifted
    // back): a segment ending exactly at the nearest hit still meets it, nearest and
    // any hit alike; one ending an ulp before does not.
    let mut rng = SplitMix(3);
    let mut met = 0;
    for _ in 0..200 {
        let k = (rng.unit() * 10.0) as usize % 10;
        let target = Vec3::new(3.0 * k as f32 + rng.unit() - 0.5, rng.unit() - 0.5, rng.unit() - 0.5);
        let origin = Vec3::new(40.0 * rng.unit() - 5.0, 30.0, -60.0);
        let ray = Ray::new(origin, target - origin);
        let Some(hit) = world.intersect(&ray) else { continue };
        met += 1;
        let up_to = Ray { tmax: hit.hit.t, ..ray };
        assert_eq!(world.intersect(&up_to), Some(hit));
        assert!(world.occluded(&up_to));
        let short = Ray { tmax: hit.hit.t.next_down(), ..ray };
        assert_eq!(world.intersect(&short), None, "{ray:?}");
        assert!(!world.occluded(&short));
        assert_eq!(world.intersect_batch(&[ray, up_to, short]), vec![Some(hit), Some(hit), None]);
    }
    assert!(met > 150, "{met} of 200 rays met a ball");
    // A ray along the row meets the first ball; tied distances go to the lower id.
    let along = Ray::new(Vec3::new(-5.0, 0.0, 0.0), Vec3::X);
    assert_eq!(world.intersect(&along).map(|h| h.instance), Some(row[0]));
    // A larger ball whose surface passes through the first's nearest vertex (-1, 0, 0):
    // the same distance in both, the lower id wins although the larger box is entered
    // first; removed, the other answers.
    let twin =
        world.add(&ball, Transform::scaling([2.0; 3]).then(&Transform::translation([1.0, 0.0, 0.0]))).expect("placed");
    world.commit();
    assert_eq!(world.intersect(&along).map(|h| (h.instance, h.hit.t)), Some((row[0], 4.0)));
    world.remove(row[0]).expect("removed");
    world.commit();
    assert_eq!(world.intersect(&along).map(|h| (h.instance, h.hit.t)), Some((twin, 4.0)));
    world.remove(twin).expect("removed");
    let first = world.add(&ball, Transform::IDENTITY).expect("placed");
    let row = [first];
    // A mirrored instance: its geometric normal still faces out of its triangles as placed.
    world.set_transform(row[0], Transform::scaling([-1.0, 1.0, 1.0])).expect("moved");
    world.commit();
    let hit = world.intersect(&Ray::new(Vec3::new(0.0, 0.1, -5.0), Vec3::Z)).expect("a hit");
    let n = world.surface(&hit).expect("live").geometric_normal;
    let (scene, transform) = world.instance(hit.instance).expect("live");
    let t = scene
        .view()
        .triangle(hit.hit.prim)
        .map(|v| Vec3::from_array(transform.point(v.map(f64::from)).map(|c| c as f32)));
    let placed = (t[1] - t[0]).cross(t[2] - t[0]).normalize();
    assert!(n.dot(placed) > 0.999, "{n} against {placed}");
    assert!(world.surface(&octrace_runtime::world::WorldHit { instance: twin, hit: hit.hit }).is_none());
}

#[test]
fn bad_placements_and_ids_are_refused_by_name() {
    let ball = scene(&procedural::sphere([0.0; 3], 1.0, 8, 12));
    let mut world = World::new();
    let flat = Transform::scaling([1.0, 0.0, 1.0]);
    assert!(matches!(world.add(&ball, flat), Err(Error::Transform { .. })));
    let nan = Transform::translation([f64::NAN, 0.0, 0.0]);
    assert!(matches!(world.add(&ball, nan), Err(Error::Transform { .. })));
    let huge = Transform::scaling([1e300, 1.0, 1.0]);
    let err = world.add(&ball, huge).expect_err("beyond f32");
    assert!(err.to_string().contains("f32"), "{err}");
    let mut projective = [[0.0; 4]; 4];
    (0..4).for_each(|k| projective[k][k] = 1.0);
    projective[3][2] = 1.0;
    assert!(matches!(Transform::from_matrix(projective), Err(Error::Transform { .. })));
    assert!(matches!(world.set_transform(7, Transform::IDENTITY), Err(Error::NoInstance { id: 7 })));
    let id = world.add(&ball, Transform::IDENTITY).expect("placed");
    world.remove(id).expect("removed");
    assert!(matches!(world.remove(id), Err(Error::NoInstance { .. })));
    world.commit();
    assert!(world.is_empty());
    assert_eq!(world.intersect(&Ray::new(Vec3::new(0.0, 0.0, -5.0), Vec3::Z)), None);
    // Inverses compose to the identity.
    let mut rng = SplitMix(7);
    for _ in 0..100 {
        let m = placement(&mut rng, 100.0);
        let back = m.then(&m.inverse().expect("invertible"));
        for (i, row) in back.rows.iter().enumerate() {
            for (j, x) in row.iter().enumerate() {
                let want = if i == j { 1.0 } else { 0.0 };
                assert!((x - want).abs() < 1e-9 * if j == 3 { 100.0 } else { 1.0 }, "{back:?}");
            }
        }
    }
}

#[test]
fn crossings_counts_and_inside_agree_with_the_baked_file_away_from_overlaps() {
    let props: Vec<(Mesh, Arc<Scene>)> = props().into_iter().take(2).collect(); // the closed ones
    let mut rng = SplitMix(52);
    let mut world = World::new();
    let mut ids = Vec::new();
    // One instance a cell of a lattice, each within its cell: no two overlap.
    let mut cells: Vec<usize> = (0..216).collect();
    for k in 0..150 {
        let at = cells.swap_remove(rng.next_u64() as usize % cells.len());
        let centre = [at % 6, at / 6 % 6, at / 36].map(|c| 4.0 * c as f64 - 10.0);
        let mut u = || rng.unit() as f64;
        let scale = [0.4 + 0.7 * u(), 0.4 + 0.7 * u(), if u() < 0.25 { -1.0 } else { 1.0 } * (0.4 + 0.7 * u())];
        let place = Transform::scaling(scale)
            .then(&Transform::rotation([u() - 0.5, u() - 0.5, u() - 0.5], 6.0 * u()))
            .then(&Transform::translation(centre));
        ids.push(world.add(&props[k % 2].1, place).expect("placed"));
    }
    world.commit();
    let (triangles, first) = placed_triangles(&world, &props, &ids);
    let global = |instance: u32, triangle: u32| {
        first[ids.iter().position(|&id| id == instance).expect("live")].expect("live") + triangle
    };
    let oracle = Reference::in_input_order(triangles.clone());
    let baked =
        Scene::from_baked(bake(&Mesh::from_triangles(triangles), &BuildParams::auto()).expect("bakes")).expect("opens");
    let mut crossed = 0;
    for (i, ray) in rays(&mut rng, 600, 12.0).iter().enumerate() {
        let ours = world.crossings(ray);
        let count = world.count_crossings(ray);
        assert_eq!(count.total as usize, ours.len(), "ray {i}");
        assert_eq!(count.entries as usize, ours.iter().filter(|c| c.crossing.enters).count(), "ray {i}");
        assert!(ours.windows(2).all(|w| w[0].crossing.t <= w[1].crossing.t), "ray {i}: in order");
        let mut mine: Vec<(u32, bool)> =
            ours.iter().map(|c| (global(c.instance, c.crossing.triangle), c.crossing.enters)).collect();
        let mut theirs: Vec<(u32, bool)> = baked.crossings(ray).iter().map(|c| (c.triangle, c.enters)).collect();
        crossed += theirs.len();
        mine.sort_unstable();
        theirs.sort_unstable();
        if mine != theirs {
            // Only triangles the ray passes within rounding of an edge of may differ.
            let odd = mine.iter().filter(|x| !theirs.contains(x)).chain(theirs.iter().filter(|x| !mine.contains(x)));
            for &(id, _) in odd {
                assert!(oracle.on_edge(ray, id), "ray {i} {ray:?}: triangle {id} crossed by one side only");
            }
        } else {
            assert_eq!(count, baked.count_crossings_batch(&[*ray])[0], "ray {i}");
        }
    }
    assert!(crossed > 300, "{crossed} crossings: the rays should pass through instances");
    // Inside and outside: the baked file's exact answer, but within rounding of a surface.
    let points: Vec<[f32; 3]> = (0..4000).map(|_| [0; 3].map(|_: i32| 24.0 * rng.unit() - 12.0)).collect();
    let inside = world.contains_batch(&points);
    let want = baked.contains_batch(&points).expect("closed");
    let (ins, wants) = (inside.iter().filter(|&&x| x).count(), want.iter().filter(|&&x| x).count());
    assert!(ins > 50, "{ins} points inside ({wants} in the baked file)");
    for (k, p) in points.iter().enumerate() {
        assert_eq!(world.contains(*p), inside[k]);
        if inside[k] != want[k] {
            let d = baked.closest_point(*p).expect("a surface").distance;
            assert!(d < 1e-5, "point {k} {p:?}: inside {} against {}, {d} from the surface", inside[k], want[k]);
        }
    }
}

/// Thousands of small instances, crowded and overlapping, against the oracle and the
/// one baked file, nearest and any hit, one ray at a time and in batches.
#[test]
fn thousands_of_random_instances_answer_as_the_placed_triangles() {
    let props: Vec<(Mesh, Arc<Scene>)> =
        [procedural::sphere([0.0; 3], 1.0, 6, 8), procedural::cube([-1.0; 3], [1.0; 3], 1), procedural::grid(2, 1.5)]
            .into_iter()
            .map(|m| {
                let s = scene(&m);
                (m, s)
            })
            .collect();
    let mut rng = SplitMix(53);
    let reach = 30.0;
    let mut world = World::new();
    let ids: Vec<u32> =
        (0..3000).map(|k| world.add(&props[k % 3].1, placement(&mut rng, reach)).expect("placed")).collect();
    world.commit();
    let rays = rays(&mut rng, 500, reach as f32);
    let hits = check(&world, &props, &ids, &rays);
    assert!(hits > 250, "{hits} hits");
    assert_eq!(world.intersect_batch(&rays), rays.iter().map(|r| world.intersect(r)).collect::<Vec<_>>());
    assert_eq!(world.occluded_batch(&rays), rays.iter().map(|r| world.occluded(r)).collect::<Vec<_>>());
}

/// A placement that scales distances evenly: a rotation, one scale (mirrored now
/// and then) and a translation within `reach`.
fn even_placement(rng: &mut SplitMix, reach: f64) -> Transform {
    let mut u = || rng.unit() as f64;
    let axis = [u() - 0.5, u() - 0.5, u() - 0.5];
    let angle = std::f64::consts::TAU * u();
    let s = 0.4 + 1.6 * u();
    let mirror = if u() < 0.2 { -1.0 } else { 1.0 };
    let at = [reach * (2.0 * u() - 1.0), reach * (2.0 * u() - 1.0), reach * (2.0 * u() - 1.0)];
    Transform::scaling([mirror * s, s, s]).then(&Transform::rotation(axis, angle)).then(&Transform::translation(at))
}

/// `n` points all around (in 1.3 times `reach`), then `n` just off the placed
/// `triangles` (within 0.01 of a point of one).
fn points_around(rng: &mut SplitMix, triangles: &[[[f32; 3]; 3]], reach: f64, n: usize) -> Vec<[f32; 3]> {
    let mut points: Vec<[f32; 3]> =
        (0..n).map(|_| [0; 3].map(|_| (2.0 * rng.unit() - 1.0) * reach as f32 * 1.3)).collect();
    for _ in 0..n {
        let t = triangles[(rng.next_u64() % triangles.len() as u64) as usize].map(Vec3::from_array);
        let (a, b) = (rng.unit(), rng.unit());
        let (a, b) = if a + b > 1.0 { (1.0 - a, 1.0 - b) } else { (a, b) };
        let off = Vec3::new(rng.unit() - 0.5, rng.unit() - 0.5, rng.unit() - 0.5) * 0.02;
        points.push((t[0] + (t[1] - t[0]) * a + (t[2] - t[0]) * b + off).to_array());
    }
    points
}

/// Closest points through a world against the brute-force oracle over the placed
/// triangles: the distance within the rounding of the carried point, the triangle
/// the oracle's or one as near within that; the batch the one-point call's, bit for
/// bit; the band's limit kept.
#[test]
fn closest_points_agree_with_the_oracle_over_the_placed_triangles() {
    let props = props();
    let mut rng = SplitMix(51);
    let mut world = World::new();
    let reach = 12.0;
    let ids: Vec<u32> = (0..240)
        .map(|i| world.add(&props[i % props.len()].1, even_placement(&mut rng, reach)).expect("placed"))
        .collect();
    world.commit();
    let (triangles, first) = placed_triangles(&world, &props, &ids);
    let global = |instance: u32, triangle: u32| first[instance as usize].expect("live") + triangle;
    let oracle = Reference::in_input_order(triangles.clone());
    let points = points_around(&mut rng, &triangles, reach, 300);
    let batch = world.closest_points_batch(&points, f32::INFINITY).expect("searched");
    let mut ties = 0;
    for (i, p) in points.iter().enumerate() {
        let got = world.closest_point(*p).expect("even placements").expect("a surface");
        assert_eq!(batch[i], Some(got), "point {i}: the batch's answer");
        let want = oracle.closest_point(*p).expect("triangles");
        let scale = p.iter().fold(0.0f64, |m, c| m.max(f64::from(c.abs()))) + reach;
        let bound = 16.0 * f64::from(f32::EPSILON) * scale;
        let d = f64::from(got.closest.distance);
        assert!((d - want.distance).abs() <= bound, "point {i}: distance {d} against the oracle's {}", want.distance);
        let at = Vec3::from_array(got.closest.point).as_dvec3();
        let measured = (at - Vec3::from_array(*p).as_dvec3()).length();
        assert!((measured - d).abs() <= bound, "point {i}: the point lies {measured} away, the distance says {d}");
        let triangle = global(got.instance, got.closest.triangle);
        if triangle != want.triangle {
            let theirs = oracle.distance_to(*p, triangle).expect("a triangle");
            assert!((theirs - want.distance).abs() <= bound, "point {i}: triangle {triangle} is {theirs} away");
            ties += 1;
        }
        // The band: nothing within half the distance, the point within a little more.
        if want.distance > 1e-3 {
            let half = world.closest_point_within(*p, (want.distance * 0.5) as f32).expect("even");
            assert_eq!(half, None, "point {i}");
            let more = world.closest_point_within(*p, (want.distance * 1.01) as f32).expect("even");
            assert_eq!(more, Some(got), "point {i}");
        }
    }
    assert!(ties * 50 <= points.len(), "{ties} ties in {} points", points.len());
    assert_eq!(World::new().closest_point([0.0; 3]).expect("empty"), None);
    assert_eq!(world.closest_point([f32::NAN, 0.0, 0.0]).expect("not finite"), None);
}

/// The effects renderer through a world: the effects scene placed once by the
/// identity renders as the scene itself (every light, material, texture and ray kind
/// the same, the radiance within the ulps of the triangle tests); moved by a translation and seen from a camera moved with
/// it, the image is the scene's but for the rounding of the carried rays and
/// corners; a mirrored copy beside it adds its own light and shade.
#[test]
fn a_world_renders_as_its_scenes_placed() {
    use octrace_runtime::raysets::Camera;
    use octrace_runtime::render::effects::{render_effects, render_effects_world, RayKind, RenderOptions};
    let fx = scene(&procedural::effects_scene());
    let options = RenderOptions::for_scene(fx.shading());
    let at = |eye: [f64; 3], target: [f64; 3]| {
        let v = |p: [f64; 3]| octrace_runtime::glam::DVec3::from_array(p);
        Camera::look_at(v(eye), v(target), 50.0, 96, 72)
    };
    let camera = at([0.0, 2.0, 6.0], [0.0, 0.0, 0.0]);
    let (alone, alone_rays) = render_effects(&fx, &camera, &options, &|_| {});
    let mut world = World::new();
    world.add(&fx, Transform::IDENTITY).expect("placed");
    world.commit();
    let (placed, placed_rays) = render_effects_world(&world, &camera, &options, &|_| {}).expect("renders");
    // The world walks each scene with its own (exact) triangle test, the scene's
    // render the watertight one: the same surfaces, barycentrics within ulps, and now
    // and then a ray within ulps of an edge on the other triangle (5 of these pixels).
    let off = placed.pixels.iter().zip(&alone.pixels).filter(|(p, q)| (**p - **q).abs().max_element() > 1e-5).count();
    let worst = placed.pixels.iter().zip(&alone.pixels).map(|(p, q)| (*p - *q).abs().max_element()).fold(0.0, f32::max);
    assert!(off * 200 <= alone.pixels.len() && worst < 0.02, "the identity placement: {off} pixels off, worst {worst}");
    let (a, b) = (placed.to_image(), alone.to_image());
    let same = a.rgb.iter().zip(&b.rgb).filter(|(x, y)| x == y).count();
    assert!(same * 1000 >= a.rgb.len() * 998, "{same} of {} bytes the same", a.rgb.len());
    assert_eq!(placed_rays, alone_rays);
    assert!(alone_rays.get(RayKind::SoftShadow) > 0 && alone_rays.get(RayKind::Refraction) > 0, "{alone_rays:?}");
    // Moved by (40, 0, -8), and the camera with it.
    world.set_transform(0, Transform::translation([40.0, 0.0, -8.0])).expect("live");
    world.commit();
    let (moved, _) =
        render_effects_world(&world, &at([40.0, 2.0, -2.0], [40.0, 0.0, -8.0]), &options, &|_| {}).expect("renders");
    let (a, b) = (moved.to_image(), alone.to_image());
    let same = a.rgb.iter().zip(&b.rgb).filter(|(x, y)| x == y).count();
    assert!(same * 100 >= a.rgb.len() * 95, "{same} of {} bytes the same", a.rgb.len());
    assert!(a.mean_abs_diff(&b).expect("same size") < 1.0, "{:?}", a.mean_abs_diff(&b));
    // A mirrored copy beside it: the image changes, and stays finite.
    world.add(&fx, Transform::scaling([-1.0, 1.0, 1.0]).then(&Transform::translation([46.0, 0.0, -8.0]))).expect("ok");
    world.commit();
    let (two, _) =
        render_effects_world(&world, &at([43.0, 4.0, 4.0], [43.0, 0.0, -8.0]), &options, &|_| {}).expect("renders");
    assert!(two.pixels.iter().all(|p| p.is_finite()));
    assert_ne!(two.to_image().rgb, moved.to_image().rgb);
}

/// A scene with many lights placed many times: each instance places its own copies,
/// and past the budget the render is refused by name before any is made.
#[test]
fn a_world_of_many_lit_instances_is_refused_past_the_lights_budget() {
    use octrace_runtime::raysets::Camera;
    use octrace_runtime::render::effects::{render_effects_world, RenderOptions};
    let mut mesh = procedural::cube([-1.0; 3], [1.0; 3], 1);
    let light = octrace_format::Light {
        name: "a lamp with a long name ".repeat(40),
        kind: octrace_format::LightKind::Point,
        color: [1.0; 3],
        intensity: 1.0,
        position: [0.0, 3.0, 0.0],
        direction: [0.0, -1.0, 0.0],
        range: f32::INFINITY,
        inner_cone: 0.0,
        outer_cone: 0.7,
    };
    mesh.lights = vec![light; 1000];
    let lit = scene(&mesh);
    let options = RenderOptions::for_scene(lit.shading());
    let camera = Camera::look_at([0.0, 2.0, 6.0].into(), [0.0; 3].into(), 50.0, 8, 6);
    let mut world = World::new();
    world.add(&lit, Transform::IDENTITY).expect("placed");
    world.commit();
    render_effects_world(&world, &camera, &options, &|_| {}).expect("one instance's lights fit");
    for k in 1..1200 {
        world.add(&lit, Transform::translation([3.0 * f64::from(k), 0.0, 0.0])).expect("placed");
    }
    world.commit();
    match render_effects_world(&world, &camera, &options, &|_| {}) {
        Err(Error::Budget { what, needed, limit, .. }) => {
            assert!(what.contains("lights") && needed > limit, "{what}: {needed} > {limit}");
        }
        other => panic!("expected the lights' budget, got {:?}", other.map(|(_, c)| c)),
    }
}

/// Closest points through placements that stretch distances unevenly (scales per
/// axis, shears, mirrors): the placed triangles measured in the world, so the answers
/// are the brute-force oracle's over those triangles, the distance within one `f32`
/// rounding and the triangle the oracle's or one at the same distance; the batch the
/// one-point call's; the band kept; mixed with evenly placed instances.
#[test]
fn closest_points_through_stretched_placements_are_the_placed_triangles() {
    let props = props();
    let mut rng = SplitMix(57);
    let reach = 10.0;
    let mut world = World::new();
    let mut ids = Vec::new();
    for i in 0..90 {
        let place = match i % 3 {
            0 => placement(&mut rng, reach),
            1 => {
                // Sheared: x moved by y.
                let shear = Transform::from_rows([[1.0, 0.7, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]]);
                shear.then(&placement(&mut rng, reach))
            }
            _ => even_placement(&mut rng, reach),
        };
        ids.push(world.add(&props[i % props.len()].1, place).expect("placed"));
    }
    world.commit();
    let (triangles, first) = placed_triangles(&world, &props, &ids);
    let global = |instance: u32, triangle: u32| first[instance as usize].expect("live") + triangle;
    let oracle = Reference::in_input_order(triangles.clone());
    let points = points_around(&mut rng, &triangles, reach, 200);
    let batch = world.closest_points_batch(&points, f32::INFINITY).expect("searched");
    let (mut stretched, mut ties) = (0, 0);
    for (i, p) in points.iter().enumerate() {
        let got = world.closest_point(*p).expect("searched").expect("a surface");
        assert_eq!(batch[i], Some(got), "point {i}: the batch's answer");
        let want = oracle.closest_point(*p).expect("triangles");
        let even = got.instance % 3 == 2;
        // Evenly placed instances within the rounding of the carried point; stretched
        // ones within one rounding of the distance (the oracle's is f64).
        let scale = p.iter().fold(0.0f64, |m, c| m.max(f64::from(c.abs()))) + reach;
        let bound = if even {
            16.0 * f64::from(f32::EPSILON) * scale
        } else {
            stretched += 1;
            f64::from(f32::EPSILON) * want.distance + 1e-12 * scale
        };
        let d = f64::from(got.closest.distance);
        assert!((d - want.distance).abs() <= bound, "point {i}: distance {d} against the oracle's {}", want.distance);
        let triangle = global(got.instance, got.closest.triangle);
        if triangle != want.triangle {
            let theirs = oracle.distance_to(*p, triangle).expect("a triangle");
            assert!((theirs - want.distance).abs() <= bound, "point {i}: triangle {triangle} is {theirs} away");
            ties += 1;
        }
        if !even {
            let at = Vec3::from_array(got.closest.point).as_dvec3();
            let measured = (at - Vec3::from_array(*p).as_dvec3()).length();
            assert!(
                (measured - d).abs() <= 4.0 * f64::from(f32::EPSILON) * scale,
                "point {i}: the point is {measured} away"
            );
        }
        if want.distance > 1e-3 {
            assert_eq!(world.closest_point_within(*p, (want.distance * 0.5) as f32).expect("searched"), None);
            assert_eq!(world.closest_point_within(*p, (want.distance * 1.01) as f32).expect("searched"), Some(got));
        }
    }
    assert!(stretched >= 200, "{stretched} answers from stretched instances");
    assert!(ties * 50 <= points.len(), "{ties} ties in {} points", points.len());
}
