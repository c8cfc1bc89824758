//! The named hard cases: each test says why its rays or triangles are hard, and checks
//! the octree against the f64 brute-force oracle (or against what a closed mesh
//! guarantees).

use glam::Vec3;
use octrace_bake::{bake, procedural, BuildParams, Mesh};
use octrace_runtime::reference::{Agreement, Reference};
use octrace_runtime::{Ray, Scene};

pub(crate) fn scene(mesh: &Mesh, depth: Option<u32>, leaf: u32) -> Scene {
    let p = BuildParams { max_depth: depth, leaf_size: Some(leaf), ..BuildParams::auto() };
    Scene::from_baked(bake(mesh, &p).unwrap()).unwrap()
}

pub(crate) fn oracle(mesh: &Mesh) -> Reference {
    Reference::in_input_order(mesh.triangles.clone())
}

pub(crate) mod grid_rays;
pub(crate) mod slivers;
pub(crate) mod tiny_directions;

/// Every ray agrees with the oracle (see `reference::Agreement`: the same answer, or
/// a tie within rounding, as the oracle decides it), nearest hit and occlusion (also
/// where the nearest hit is a tie); every hit's distance is within the stated bound of
/// the exact distance to its triangle's plane (`reference::DISTANCE_RELATIVE`); the
/// batch calls give the one-ray answers bit for bit. Each ray with a zero direction
/// component is checked with the sign of its zeros flipped too (`+0.0` and `-0.0`
/// take different exit corners and walks).
pub(crate) fn all_agree(name: &str, scene: &Scene, oracle: &Reference, rays: &[Ray]) {
    let flipped = rays.iter().filter(|r| r.dir.to_array().contains(&0.0)).map(|r| {
        let d = octrace_bake::hard_rays::flip_zero_signs(r.dir.to_array());
        Ray { dir: Vec3::from(d), ..*r }
    });
    let rays: Vec<Ray> = rays.iter().copied().chain(flipped).collect();
    let tracer = scene.tracer();
    let mut bad = Vec::new();
    for r in &rays {
        let got = tracer.intersect(r);
        if oracle.compare(r, got.map(|h| (h.t, h.triangle, h.u, h.v))) == Agreement::Different {
            bad.push(format!("{r:?}: octree {got:?}, oracle {:?}", oracle.intersect(r)));
        }
        if let Some(h) = got {
            if let Some((err, bound)) = oracle.distance_error(r, h.t, h.triangle) {
                if err > bound {
                    bad.push(format!("{r:?}: t {} of {h:?} is {err:e} off its plane (bound {bound:e})", h.t));
                }
            }
        }
        let occluder = tracer.occluder(r);
        assert_eq!(occluder.is_some(), tracer.occluded(r), "{name}: occluder and occluded, {r:?}");
        if oracle.compare_occluder(r, occluder.map(|h| (h.t, h.triangle))) == Agreement::Different {
            bad.push(format!("{r:?}: occluder {occluder:?}, oracle occluded {}", oracle.occluded(r)));
        }
    }
    assert!(bad.is_empty(), "{name}: {} of {} rays disagree; first: {}", bad.len(), rays.len(), bad[0]);
    // The batch calls (eight walks a vector where the processor has AVX2) give the
    // one-ray calls' answers bit for bit.
    let mut hits = vec![None; rays.len()];
    tracer.intersect_batch(&rays, &mut hits);
    let mut occluded = vec![false; rays.len()];
    tracer.occluded_batch(&rays, &mut occluded);
    for (i, r) in rays.iter().enumerate() {
        assert_eq!(hits[i], tracer.intersect(r), "{name}: batch, {r:?}");
        assert_eq!(occluded[i], tracer.occluded(r), "{name}: batch occluded, {r:?}");
    }
}

pub(crate) fn test_scene() -> Mesh {
    let mut m = procedural::sphere([0.0; 3], 1.0, 24, 32);
    m.triangles.extend(procedural::cube([0.5, -1.5, -0.25], [1.5, -0.5, 0.75], 4).triangles);
    m.triangles.extend(procedural::torus([-0.5, 0.8, 0.3], 0.8, 0.2, 24, 12).triangles);
    m
}

/// Hard because zero direction components make `1/d` infinite and the slab test's
/// `0 * inf` undefined, and the exit-face choice must never pick an axis the ray does
/// not move along; `-0.0` has its sign bit set and picks the other exit corner.
#[test]
fn axis_parallel_rays_one_and_two_zero_components_every_axis_and_sign() {
    let mesh = test_scene();
    let (s, o) = (scene(&mesh, Some(6), 2), oracle(&mesh));
    let mut rays = Vec::new();
    for axis in 0..3 {
        for sign in [1.0f32, -1.0] {
            for zero in [0.0f32, -0.0] {
                for i in 0..24 {
                    for j in 0..24 {
                        let (u, v) = (-1.6 + 3.2 * i as f32 / 23.0, -1.6 + 3.2 * j as f32 / 23.0);
                        let mut d = [zero; 3];
                        d[axis] = sign;
                        let mut org = [0.0f32; 3];
                        org[axis] = -3.0 * sign;
                        org[(axis + 1) % 3] = u;
                        org[(axis + 2) % 3] = v;
                        rays.push(Ray::new(Vec3::from(org), Vec3::from(d)));
                        // One zero component: diagonal in a coordinate plane, from inside too.
                        let mut d2 = d;
                        d2[(axis + 1) % 3] = 0.5 * sign;
                        rays.push(Ray::new(Vec3::from(org), Vec3::from(d2)));
                        rays.push(Ray::new(Vec3::new(u * 0.5, v * 0.5, 0.1), Vec3::from(d2)));
                    }
                }
            }
        }
    }
    all_agree("axis-parallel", &s, &o, &rays);
}

/// The octree's own grid planes, edges and corners of every leaf: rays lying exactly in
/// a cell face plane, running along cell edges, or passing through cell corners, where
/// the exit test ties and a walk could skip a cell; leaves next to a coarser neighbour
/// cover the 2:1 level change.
#[test]
fn rays_in_cell_faces_along_cell_edges_and_through_cell_corners() {
    let mesh = test_scene();
    for depth in [3, 5, 7] {
        let s = scene(&mesh, Some(depth), 1);
        let o = oracle(&mesh);
        let view = s.view();
        let mut rays = Vec::new();
        for (k, rec) in view.leaves().enumerate().filter(|(k, _)| k % 7 == 0) {
            let b = view.leaf_box(rec.box_index);
            let (lo, hi) = (Vec3::new(b[0], b[1], b[2]), Vec3::new(b[3], b[4], b[5]));
            let corner = Vec3::new(if k % 2 == 0 { lo.x } else { hi.x }, if k % 3 == 0 { lo.y } else { hi.y }, lo.z);
            // In the face plane x = lo.x, crossing the cell diagonally.
            rays.push(Ray::new(Vec3::new(lo.x, lo.y - 1.0, lo.z - 0.5), Vec3::new(0.0, 1.0, 0.5)));
            // Along a cell edge (x = lo.x, y = lo.y), both ways.
            rays.push(Ray::new(Vec3::new(lo.x, lo.y, -4.0), Vec3::Z));
            rays.push(Ray::new(Vec3::new(lo.x, lo.y, 4.0), -Vec3::Z));
            // Through the corner, with power-of-two directions so origin and corner are
            // exactly on one line.
            for d in [Vec3::new(1.0, 1.0, 1.0), Vec3::new(-0.5, 1.0, 0.25), Vec3::new(1.0, -1.0, 0.0)] {
                rays.push(Ray::new(corner - 4.0 * d, d));
            }
            // Through the middle of a face towards a coarser neighbour (2:1 change).
            for face in 0..6 {
                if octrace_format::layout::neighbour_is_coarser(rec.ncount, face) {
                    let mid = (lo + hi) * 0.5;
                    let mut d = Vec3::ZERO;
                    d[face / 2] = if face % 2 == 1 { 1.0 } else { -1.0 };
                    rays.push(Ray::new(Vec3::new(lo.x, mid.y, mid.z) - 3.0 * d, d));
                    rays.push(Ray::new(lo - 3.0 * (d + Vec3::new(0.0, 0.5, 0.25)), d + Vec3::new(0.0, 0.5, 0.25)));
                }
            }
        }
        assert!(rays.len() > 100);
        all_agree(&format!("grid rays, depth {depth}"), &s, &o, &rays);
    }
}

/// Origins exactly on leaf faces and on the root cube's faces, edges and corners, inside
/// and outside: point location must pick a leaf the ray really starts in (or next to),
/// and the cube-map entry must handle a ray that starts on the boundary.
#[test]
fn origins_on_cell_faces_and_on_the_root_boundary() {
    let mesh = test_scene();
    let s = scene(&mesh, Some(6), 2);
    let o = oracle(&mesh);
    let view = s.view();
    let (rlo, size) = (Vec3::from(view.bounds.root_lo), view.bounds.root_size);
    let rhi = rlo + Vec3::splat(size);
    let dirs = [Vec3::new(0.3, 0.2, 0.9), Vec3::new(-0.7, 0.1, -0.2), Vec3::new(0.0, -1.0, 0.4), Vec3::X, -Vec3::Y];
    let mut origins = Vec::new();
    for rec in view.leaves().step_by(5) {
        let b = view.leaf_box(rec.box_index);
        origins.push(Vec3::new(b[0], (b[1] + b[4]) * 0.5, (b[2] + b[5]) * 0.5)); // on a face
        origins.push(Vec3::new(b[0], b[1], (b[2] + b[5]) * 0.5)); // on an edge
        origins.push(Vec3::new(b[3], b[4], b[5])); // on a corner
    }
    for cx in [rlo.x, (rlo.x + rhi.x) * 0.5, rhi.x] {
        for cy in [rlo.y, (rlo.y + rhi.y) * 0.5, rhi.y] {
            for cz in [rlo.z, (rlo.z + rhi.z) * 0.5, rhi.z] {
                origins.push(Vec3::new(cx, cy, cz)); // root corners, edges, faces, centre
            }
        }
    }
    let rays: Vec<Ray> =
        origins.iter().flat_map(|&p| dirs.iter().flat_map(move |&d| [Ray::new(p, d), Ray::new(p, -d)])).collect();
    all_agree("origins on faces", &s, &o, &rays);
}

/// Rays from inside a closed mesh must hit it: a walk that skips a leaf, or a triangle
/// test that lets a ray slip through a shared edge, leaks. Rays aimed exactly at
/// vertices and edge midpoints are where edges and leaf boundaries tie. A million rays a
/// mesh, plus every vertex and edge midpoint (`octrace soak` runs more).
#[test]
fn closed_meshes_do_not_leak() {
    for solid in procedural::closed_solids() {
        let s = scene(&solid.mesh, None, 8);
        let rays: Vec<Ray> =
            solid.leak_rays(1_000_000, 7).iter().map(|(o, d)| Ray::new(Vec3::from(*o), Vec3::from(*d))).collect();
        let hits = s.intersect_batch(&rays);
        let leaks: Vec<&Ray> = rays.iter().zip(&hits).filter(|(_, h)| h.is_none()).map(|(r, _)| r).collect();
        assert!(
            leaks.is_empty(),
            "{}: {} of {} rays leaked, first {:?}",
            solid.name,
            leaks.len(),
            rays.len(),
            leaks[0]
        );
        assert!(rays.len() >= 1_000_000);
    }
}

/// Rays nearly parallel to a triangle, or nearly in a cell face plane: the determinant
/// and the exit products are tiny and their signs fragile.
#[test]
fn grazing_rays() {
    let mesh = procedural::grid(16, 2.0);
    let s = scene(&mesh, Some(7), 2);
    let o = oracle(&mesh);
    let view = s.view();
    let mut rays = Vec::new();
    for k in 0..400 {
        let x = 0.005 * k as f32;
        for eps in [1e-3f32, 1e-5, 1e-7, -1e-7, -1e-5] {
            rays.push(Ray::new(Vec3::new(-0.5, x, 1e-3), Vec3::new(1.0, 0.01, -eps)));
            rays.push(Ray::new(Vec3::new(x, -0.5, eps), Vec3::new(0.02, 1.0, -eps * 0.5)));
        }
    }
    for rec in view.leaves().step_by(9) {
        let b = view.leaf_box(rec.box_index);
        for eps in [1e-6f32, -1e-6] {
            rays.push(Ray::new(Vec3::new(b[0] + eps, -1.0, 0.3), Vec3::new(eps, 1.0, -0.2)));
        }
    }
    all_agree("grazing", &s, &o, &rays);
}

/// Far from the origin and at extreme scales, `f32` spacing is coarse (1.0 at 1e7) or
/// tiny: cell planes, the cube-map entry and the exit products must stay consistent.
#[test]
fn far_and_wide_same_answers_as_the_reference() {
    let base = test_scene();
    for (shift, scale) in [(1e5f32, 1.0f32), (1e6, 1.0), (1e7, 1.0), (0.0, 1e-4), (0.0, 1e6), (3e6, 50.0)] {
        let mut m = base.clone();
        for v in m.triangles.iter_mut().flatten() {
            *v = v.map(|c| c * scale + shift);
        }
        let s = scene(&m, None, 4);
        let o = oracle(&m);
        let mut rng = procedural::SplitMix(11);
        let rays: Vec<Ray> = (0..3000)
            .map(|_| {
                let origin =
                    Vec3::new(rng.unit() - 0.5, rng.unit() - 0.5, rng.unit() - 0.5) * 6.0 * scale + Vec3::splat(shift);
                let target =
                    Vec3::new(rng.unit() - 0.5, rng.unit() - 0.5, rng.unit() - 0.5) * 2.0 * scale + Vec3::splat(shift);
                Ray::new(origin, target - origin)
            })
            .collect();
        all_agree(&format!("shift {shift:e} scale {scale:e}"), &s, &o, &rays);
    }
}

/// The extremes of the scales the bake accepts (`octree::MIN_ROOT_EDGE`,
/// `MAX_COORDINATE`) and the 1e-14 and 1e14 (which traced t = 0, t = inf and
/// wrong triangles before the distances came from the plane in f64): no ray from
/// inside a closed sphere leaks, random and vertex-aimed ones included, and every
/// answer is the oracle's with its distance within the bound.
#[test]
fn extreme_scales_within_the_limits_trace_right() {
    let sphere = || procedural::closed_solids().into_iter().find(|s| s.name == "sphere").unwrap();
    for scale in [1e-18, 1e-14, 1e14, 1e17] {
        let solid = sphere().moved(0.0, scale);
        let s = scene(&solid.mesh, None, 16);
        let rays: Vec<Ray> =
            solid.leak_rays(30_000, 4).iter().map(|(o, d)| Ray::new(Vec3::from(*o), Vec3::from(*d))).collect();
        let leaks = s.intersect_batch(&rays).iter().filter(|h| h.is_none()).count();
        assert_eq!(leaks, 0, "scale {scale:e}: {leaks} of {} rays leaked", rays.len());
        let sample: Vec<Ray> = rays.iter().step_by(40).copied().collect();
        all_agree(&format!("scale {scale:e}"), &s, &oracle(&solid.mesh), &sample);
    }
}

/// Collinear triangles, repeated vertices, slivers, stacks of coplanar copies, a
/// triangle lying exactly in cell faces and one spanning the whole root: degenerate
/// ones must be skipped, ties must resolve to a triangle at the right distance.
#[test]
fn degenerate_and_awkward_triangles() {
    let mut m = procedural::sphere([0.5, 0.5, 0.5], 0.3, 12, 16);
    m.triangles.push([[0.0, 0.0, 0.0], [0.5, 0.5, 0.5], [1.0, 1.0, 1.0]]); // collinear
    m.triangles.push([[0.2, 0.3, 0.4], [0.2, 0.3, 0.4], [0.9, 0.1, 0.2]]); // repeated vertex
    m.triangles.push([[0.0, 0.1, 0.9], [1.0, 0.1000001, 0.9], [0.5, 0.1, 0.9000001]]); // sliver
    for _ in 0..4 {
        m.triangles.push([[0.1, 0.8, 0.1], [0.9, 0.8, 0.1], [0.1, 0.8, 0.9]]); // coplanar stack
    }
    m.triangles.push([[0.5, 0.0, 0.0], [0.5, 1.0, 0.0], [0.5, 0.0, 1.0]]); // in the cell faces x = 0.5
    m.triangles.push([[-0.1, -0.1, 0.25], [2.0, -0.1, 0.25], [-0.1, 2.0, 0.25]]); // spans the root
    let s = scene(&m, Some(6), 2);
    assert_eq!(s.view().stats.degenerate_triangles, 2);
    let o = oracle(&m);
    let mut rng = procedural::SplitMix(3);
    let rays: Vec<Ray> = (0..20_000)
        .map(|_| {
            let origin = Vec3::new(rng.unit(), rng.unit(), rng.unit()) * 3.0 - 1.0;
            let target = Vec3::new(rng.unit(), rng.unit(), rng.unit());
            Ray::new(origin, target - origin)
        })
        .collect();
    all_agree("awkward triangles", &s, &o, &rays);
}

/// A ray spawned from a hit must not hit its own triangle again at the origin: the
/// hit point is off by its rounding error, and the offset (`runtime::spawn`) must cover
/// it on every mesh, in every direction leaving the surface.
#[test]
fn secondary_rays_do_not_hit_their_own_surface() {
    // The cube's faces lie on planes of exactly representable coordinates: hit points
    // there are exact, their error bound is zero, and only the offset's floor keeps a
    // spawned ray off its own plane (found by the effects renderer's floor).
    for (name, mesh) in [
        ("blob", procedural::blob(64, 96)),
        ("bunny", octrace_tests::bunny_mesh().clone()),
        ("cube", procedural::cube([-1.0, 0.0, -2.0], [3.0, 2.0, 2.0], 6)),
    ] {
        let s = scene(&mesh, None, 8);
        let view = s.view();
        let b = view.bounds;
        let c = (Vec3::from(b.mesh_lo) + Vec3::from(b.mesh_hi)) * 0.5;
        let r = (Vec3::from(b.mesh_hi) - Vec3::from(b.mesh_lo)).length();
        let mut rng = procedural::SplitMix(5);
        let mut self_hits = 0;
        let mut spawned = 0;
        for _ in 0..20_000 {
            let dir = Vec3::new(rng.unit() - 0.5, rng.unit() - 0.5, rng.unit() - 0.5).normalize();
            let Some(hit) = s.intersect(&Ray::new(c - dir * 2.0 * r, dir)) else { continue };
            let tri = view.triangle(hit.prim);
            let n =
                (Vec3::from(tri[1]) - Vec3::from(tri[0])).cross(Vec3::from(tri[2]) - Vec3::from(tri[0])).normalize();
            let n = if n.dot(dir) > 0.0 { -n } else { n };
            // Reflection, and a random direction into the outer hemisphere.
            let mut out = Vec3::new(rng.unit() - 0.5, rng.unit() - 0.5, rng.unit() - 0.5);
            if out.dot(n) < 0.0 {
                out = -out;
            }
            for d in [dir - 2.0 * dir.dot(n) * n, out] {
                let ray = octrace_runtime::spawn::spawn(&tri, &hit, d, f32::INFINITY);
                spawned += 1;
                if s.intersect(&ray).is_some_and(|h| h.prim == hit.prim) {
                    self_hits += 1;
                }
            }
        }
        assert!(spawned > 10_000, "{name}: {spawned}");
        assert_eq!(self_hits, 0, "{name}: {self_hits} of {spawned} secondary rays hit their own triangle");
    }
}

/// NaN and infinite components, `tmin > tmax`, NaN bounds and a zero direction have
/// no meaningful hit: each is a defined miss, in every call, without a panic or a hang.
#[test]
fn nan_inf_inverted_and_zero_rays_are_defined_misses() {
    let s = scene(&test_scene(), None, 4);
    let nan = f32::NAN;
    let inf = f32::INFINITY;
    let bad = [
        Ray::new(Vec3::new(nan, 0.0, 0.0), Vec3::Z),
        Ray::new(Vec3::ZERO, Vec3::new(0.0, nan, 1.0)),
        Ray::new(Vec3::new(inf, 0.0, 0.0), -Vec3::X),
        Ray::new(Vec3::ZERO, Vec3::new(inf, 0.0, 0.0)),
        Ray::new(Vec3::new(0.0, 0.0, -5.0), Vec3::ZERO),
        Ray::new(Vec3::new(0.0, 0.0, -5.0), Vec3::new(0.0, 0.0, -0.0)),
        Ray::segment(Vec3::new(0.0, 0.0, -5.0), Vec3::Z, 3.0, 2.0),
        Ray::segment(Vec3::new(0.0, 0.0, -5.0), Vec3::Z, nan, 10.0),
        Ray::segment(Vec3::new(0.0, 0.0, -5.0), Vec3::Z, 0.0, nan),
    ];
    let t = s.tracer();
    for r in &bad {
        assert_eq!(t.intersect(r), None, "{r:?}");
        assert!(!t.occluded(r), "{r:?}");
    }
    assert!(s.intersect_batch(&bad).iter().all(Option::is_none));
    assert!(s.occluded_batch(&bad).iter().all(|o| !o));
    // A huge but finite tmax and a ray that only starts beyond the scene are fine too.
    assert!(t.intersect(&Ray::segment(Vec3::new(0.0, 0.0, -5.0), Vec3::Z, 0.0, f32::MAX)).is_some());
    assert!(t.intersect(&Ray::segment(Vec3::new(0.0, 0.0, -5.0), Vec3::Z, 100.0, inf)).is_none());
}

/// Termination: a walk visits at most `Tracer::max_steps` leaves (9 * 2^depth + 64,
/// see `runtime/src/cpu/walk.rs`); every build stops there and says so. Long walks
/// through the deepest trees stay well inside the bound.
#[test]
fn walks_stay_within_the_proven_step_bound() {
    for depth in [1, 4, 8, 10] {
        let mesh = procedural::soup(8, 3000, 10.0, 0.05);
        let s = scene(&mesh, Some(depth), 1);
        let t = s.tracer();
        let bound = t.max_steps();
        let mut rng = procedural::SplitMix(depth as u64);
        let mut most = 0;
        for _ in 0..5000 {
            let o = Vec3::new(rng.unit(), rng.unit(), rng.unit()) * 10.0;
            let d = Vec3::new(rng.unit() - 0.5, rng.unit() - 0.5, rng.unit() - 0.5);
            // Misses walk the whole root: the longest walks.
            let (_, stats) = t.intersect_with_stats(&Ray::segment(o, d, 0.0, f32::INFINITY));
            most = most.max(stats.leaves);
            assert!(!stats.stopped_at_bound, "depth {depth}: a walk was stopped at the bound");
        }
        assert!(most <= bound, "depth {depth}: {most} steps > bound {bound}");
        assert!(most > 0);
    }
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig { cases: 40, ..Default::default() })]

    /// Random soups at random scales (1e-4 .. 1e6) and offsets (up to 1e7, either
    /// sign), random rays from inside and outside: the octree agrees with the oracle.
    #[test]
    fn random_scenes_at_every_magnitude_agree_with_the_oracle(
        seed in proptest::prelude::any::<u64>(),
        scale_exp in -4.0f32..6.0,
        offset_exp in 0.0f32..7.0,
        offset_sign in proptest::prelude::any::<bool>(),
        n in 1usize..300,
        leaf in 1u32..10,
    ) {
        let scale = 10f32.powf(scale_exp);
        let offset = if offset_sign { -1.0 } else { 1.0 } * 10f32.powf(offset_exp);
        let mut m = procedural::soup(seed, n, 4.0, 1.0);
        for v in m.triangles.iter_mut().flatten() {
            *v = v.map(|c| c * scale + offset);
        }
        // A soup small against its offset may collapse at f32 precision: refused by name.
        if m.triangles.iter().all(octrace_bake::octree::is_degenerate) {
            let p = BuildParams { leaf_size: Some(leaf), ..BuildParams::auto() };
            let collapsed = matches!(bake(&m, &p), Err(octrace_bake::Error::Collapsed { .. }));
            proptest::prop_assert!(collapsed);
            return Ok(());
        }
        let s = scene(&m, None, leaf);
        let o = oracle(&m);
        let mut rng = procedural::SplitMix(seed ^ 0x5EED);
        let rays: Vec<Ray> = (0..200)
            .map(|_| {
                let from = (Vec3::new(rng.unit(), rng.unit(), rng.unit()) * 8.0 - 2.0) * scale + Vec3::splat(offset);
                let to = Vec3::new(rng.unit(), rng.unit(), rng.unit()) * 4.0 * scale + Vec3::splat(offset);
                Ray::new(from, to - from)
            })
            .collect();
        all_agree(&format!("seed {seed} scale {scale:e} offset {offset:e}"), &s, &o, &rays);
    }
}

/// Regression, found by the cell-edge rays: a ray running along a cell edge with two
/// `-0.0` direction components lay in the exit plane of both axes it does not move
/// along; every Plücker product was zero and the walk stepped sideways along x until it
/// left the scene.
#[test]
fn regression_ray_along_a_cell_edge_with_negative_zero_components() {
    let s = scene(&test_scene(), Some(3), 1);
    let o = oracle(&test_scene());
    let r = Ray::new(Vec3::new(-0.5, -0.75, 4.0), Vec3::new(-0.0, -0.0, -1.0));
    let want = o.intersect(&r).expect("the oracle hits");
    let got = s.intersect(&r).expect("the octree hits too");
    assert!((got.t as f64 - want.t).abs() <= 1e-5 * want.t, "{got:?} vs {want:?}");
}

/// Regression, found by the far-and-wide case: at 1e6 a depth-7 bake of a unit-sized
/// scene had cells of 0.03 where f32 spacing is 0.0625; their planes rounded together
/// into zero-width boxes and this ray (d_y = 0) walked past its triangle.
#[test]
fn regression_zero_width_cells_far_from_the_origin() {
    let mut m = test_scene();
    for v in m.triangles.iter_mut().flatten() {
        *v = v.map(|c| c + 1e6);
    }
    let s = scene(&m, None, 4);
    assert!(
        s.view().params.max_depth
            <= octrace_bake::octree::precision_depth(s.view().bounds.root_lo, s.view().bounds.root_size)
    );
    let r = Ray::new(Vec3::new(999997.5, 1000000.06, 999997.7), Vec3::new(2.3125, 0.0, 3.25));
    let want = oracle(&m).intersect(&r).expect("the oracle hits triangle 706");
    assert_eq!(want.triangle, 706);
    assert!(s.intersect(&r).is_some(), "the octree misses the triangle the oracle hits");
}

/// Regression, found by the cell-edge rays: the procedural sphere computed each pole
/// once per slice from `sin(pi) != 0`, leaving slits 1e-16 wide around the axis; a ray
/// along the axis went through. The poles are now one exact point each, and the mesh
/// is closed.
#[test]
fn regression_sphere_poles_are_closed() {
    let mesh = procedural::sphere([0.0; 3], 1.0, 24, 32);
    let s = scene(&mesh, Some(5), 1);
    for (o, d) in [(Vec3::new(0.0, -4.0, 0.0), Vec3::Y), (Vec3::new(0.0, 4.0, 0.0), -Vec3::Y), (Vec3::ZERO, Vec3::Y)] {
        let hit = s.intersect(&Ray::new(o, d)).unwrap_or_else(|| panic!("a ray along the axis from {o} passed a pole"));
        assert!((hit.t - if o == Vec3::ZERO { 1.0 } else { 3.0 }).abs() < 1e-6, "{hit:?}");
    }
}

/// Regression, found by `octrace report`'s leak table: this ray, from inside the
/// sphere of `closed_solids` and aimed exactly at its north pole (where 64 triangles
/// meet), escaped the sphere baked with a margin of 0: near a cell boundary the walk's
/// rounding can route a ray into the neighbouring leaf, and without the margin that
/// leaf does not list the triangles that only touch it at the pole. The default margin
/// (2^-20 of the root) lists them there, so the walk finds the pole.
#[test]
fn regression_ray_at_a_pole_needs_the_bake_margin() {
    let solid = procedural::closed_solids().into_iter().find(|s| s.name == "sphere").unwrap();
    let o = Vec3::from([3197658959u32, 3206394743, 1059844790].map(f32::from_bits));
    let d = Vec3::from([1053530754u32, 1068843042, 3200142290].map(f32::from_bits));
    assert!((o + d).distance(Vec3::new(0.1, 0.8, 0.3)) < 1e-6, "aimed at the pole");
    let s = scene(&solid.mesh, None, 16);
    assert_eq!(s.view().params.margin, octrace_bake::octree::DEFAULT_MARGIN);
    let ray = Ray::new(o, d);
    let hit = s.intersect(&ray).expect("the ray at the pole hits the sphere");
    assert!((hit.t - 1.0).abs() < 1e-5, "{hit:?}");
    assert_ne!(oracle(&solid.mesh).compare(&ray, Some((hit.t, hit.triangle, hit.u, hit.v))), Agreement::Different);
}
