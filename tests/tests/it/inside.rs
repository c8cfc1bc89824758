//! Inside or outside of points (`Scene::contains`): exact for closed meshes against an
//! exact reference (`InsideReference`: Shewchuk's predicates along the axes), points on
//! the surface answered as the points beside them, open meshes refused; lengths inside
//! along rays.

use glam::Vec3;
use octrace_bake::hard_rays::GridPlanes;
use octrace_bake::procedural::{self, ClosedSolid, SplitMix};
use octrace_bake::{bake, BuildParams, Mesh};
use octrace_runtime::reference::{InsideReference, Side};
use octrace_runtime::{Error, Ray, Scene};

/// Points of three kinds: uniform in the mesh's box (a margin around it), within
/// `near` of the surface on either side (along the triangle's normal), and snapped to
/// the octree's cell planes.
pub(crate) fn points(mesh: &Mesh, scene: &Scene, n: usize, near: f32, seed: u64) -> Vec<Vec3> {
    let mut rng = SplitMix(seed);
    let (lo, hi) = mesh_box(mesh);
    let e = hi - lo;
    let grid = GridPlanes::of(&scene.view());
    let mut out = Vec::with_capacity(3 * n);
    for i in 0..n {
        let u = Vec3::new(rng.unit(), rng.unit(), rng.unit());
        out.push(lo - 0.05 * e + u * 1.1 * e);
        let t = mesh.triangles[(rng.next_u64() % mesh.triangles.len() as u64) as usize].map(Vec3::from);
        let (a, b) = (rng.unit(), rng.unit());
        let (a, b) = if a + b > 1.0 { (1.0 - a, 1.0 - b) } else { (a, b) };
        let on = t[0] + a * (t[1] - t[0]) + b * (t[2] - t[0]);
        let normal = (t[1] - t[0]).cross(t[2] - t[0]).normalize_or_zero();
        out.push(on + normal * if i % 2 == 0 { near } else { -near });
        let level = 1 + (rng.next_u64() % grid.depth.max(1) as u64) as u32;
        let mut q = lo + u * e;
        let axis = i % 3;
        q[axis] = grid.snap(axis, level, q[axis]);
        out.push(q);
    }
    out
}

/// The box of a mesh's vertices.
pub(crate) fn mesh_box(mesh: &Mesh) -> (Vec3, Vec3) {
    mesh.triangles
        .iter()
        .flatten()
        .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(l, h), &p| (l.min(Vec3::from(p)), h.max(Vec3::from(p))))
}

fn check_solid(name: &str, mesh: &Mesh, n: usize, near: f32) -> (usize, usize) {
    check_solid_with(name, mesh, &BuildParams::auto(), n, near)
}

fn check_solid_with(name: &str, mesh: &Mesh, params: &BuildParams, n: usize, near: f32) -> (usize, usize) {
    let scene = Scene::from_baked(bake(mesh, params).unwrap()).unwrap();
    let oracle = InsideReference::new(&mesh.triangles);
    let pts = points(mesh, &scene, n, near, 3);
    let got = scene.contains_batch(&pts.iter().map(|p| p.to_array()).collect::<Vec<_>>()).unwrap();
    let (mut compared, mut inside) = (0, 0);
    for (p, &g) in pts.iter().zip(&got) {
        assert_eq!(g, scene.contains(p.to_array()).unwrap(), "{name}: batch and one point, {p}");
        if let Some(want @ (Side::Inside | Side::Outside)) = oracle.side(p.to_array()) {
            let want = want == Side::Inside;
            assert_eq!(g, want, "{name}: point {p:?} ({:?})", p.to_array().map(f32::to_bits));
            compared += 1;
            inside += want as usize;
        }
    }
    (compared, inside)
}

/// The closed solids, at the origin and far from it: every point the exact oracle
/// finds inside or outside gets its answer (points on the surface have theirs by
/// definition, tested below); nearly all points are compared, inside and out.
#[test]
fn closed_solids_contain_what_the_oracle_says() {
    // OCTRACE_INSIDE_POINTS runs more (three points of each: 350,000 is 1.05 million
    // points a solid, minutes in a release build).
    let n = std::env::var("OCTRACE_INSIDE_POINTS").ok().and_then(|n| n.parse().ok()).unwrap_or(700);
    for (offset, scale) in [(0.0, 1.0), (1e4, 1.0), (-3e6, 100.0)] {
        for solid in procedural::closed_solids() {
            let solid: ClosedSolid = solid.moved(offset, scale);
            // 1e-6 of the solid's size, and at least a few f32 spacings where it lies.
            let near = (1e-6 * scale + 16.0 * f32::EPSILON as f64 * offset.abs()) as f32;
            let (compared, inside) = check_solid(&solid.label(), &solid.mesh, n, near);
            assert!(
                compared > 2 * n + n * 7 / 10 && inside > n * 3 / 7 && compared - inside > n * 3 / 7,
                "{}: {compared}, {inside}",
                solid.label()
            );
        }
    }
}

/// The label grid's fine cells (8 x 8 x 8 a coarse cell where the surface passes,
/// labelled where no triangle touches them) answer as the exact oracle does, on
/// points beside the surface at every distance from a hundredth of a fine cell to a
/// few coarse cells, both sides, where the cells hold many fine cells each (shallow
/// bakes: leaves far larger than a fine cell) and few (the default), at the origin
/// and far from it.
#[test]
fn the_fine_label_grid_answers_as_the_oracle_beside_the_surface() {
    for (offset, scale) in [(0.0, 1.0), (1e4, 1.0)] {
        for solid in procedural::closed_solids() {
            let solid: ClosedSolid = solid.moved(offset, scale);
            let mesh = &solid.mesh;
            let oracle = InsideReference::new(&mesh.triangles);
            for max_depth in [Some(2), None] {
                let params = BuildParams { max_depth, ..BuildParams::auto() };
                let scene = Scene::from_baked(bake(mesh, &params).unwrap()).unwrap();
                let solid_labels = scene.solid().unwrap();
                // Blocks of fine labels exist beside the coarse cells' entries.
                assert!(solid_labels.grid_blocks() > 20, "{}: {} blocks", solid.label(), solid_labels.grid_blocks());
                let level = (scene.view().params.max_depth + 1).min(7);
                let fine = scene.view().bounds.root_size / (8u32 << level) as f32;
                let mut rng = SplitMix(11);
                let (mut compared, mut inside) = (0, 0);
                let mut pts = Vec::new();
                for i in 0..3000 {
                    let t = mesh.triangles[(rng.next_u64() % mesh.triangles.len() as u64) as usize].map(Vec3::from);
                    let (a, b) = (rng.unit(), rng.unit());
                    let (a, b) = if a + b > 1.0 { (1.0 - a, 1.0 - b) } else { (a, b) };
                    let on = t[0] + a * (t[1] - t[0]) + b * (t[2] - t[0]);
                    let normal = (t[1] - t[0]).cross(t[2] - t[0]).normalize_or_zero();
                    // 0.01 to 100 fine cells, log-uniform, either side.
                    let d = fine * 10f32.powf(-2.0 + 4.0 * rng.unit());
                    pts.push((on + normal * if i % 2 == 0 { d } else { -d }).to_array());
                }
                let got = scene.contains_batch(&pts).unwrap();
                for (p, g) in pts.iter().zip(got) {
                    if let Some(want @ (Side::Inside | Side::Outside)) = oracle.side(*p) {
                        let want = want == Side::Inside;
                        assert_eq!(g, want, "{} (max depth {max_depth:?}): point {p:?}", solid.label());
                        compared += 1;
                        inside += want as usize;
                    }
                }
                assert!(compared > 2500 && inside > 1000 && compared - inside > 1000, "{compared}, {inside}");
            }
        }
    }
}

/// Points on the surface are answered as the points just beside them along the
/// counting direction: points exactly on a closed box's faces, edges and corners (its
/// planes are coordinates: inside where the direction, all of whose components are
/// positive, leaves no face it lies on at the box's high end), and the vertices of a
/// sphere (inside where the direction points into every triangle around the vertex;
/// vertices where it all but grazes one, within the rounding of the faceted sphere's
/// f32 vertices, are left out).
#[test]
fn points_on_the_surface_are_answered_as_the_points_beside_them() {
    let d = Vec3::from(octrace_runtime::cpu::COUNT_DIRECTION);
    let (lo, hi) = (Vec3::new(-1.0, 0.0, 0.5), Vec3::new(1.0, 2.0, 1.5));
    let cube = procedural::cube(lo.to_array(), hi.to_array(), 3);
    let scene = Scene::from_baked(bake(&cube, &BuildParams::auto()).unwrap()).unwrap();
    let mut rng = SplitMix(4);
    let mut inside = 0;
    for i in 0..600 {
        let mut p = lo + Vec3::new(rng.unit(), rng.unit(), rng.unit()) * (hi - lo);
        // One, two or three coordinates on the box's planes: a face, an edge, a corner.
        for k in 0..=(i % 3) {
            let axis = (i / 3 + k) % 3;
            p[axis] = if rng.unit() < 0.5 { lo[axis] } else { hi[axis] };
        }
        let want = (0..3).all(|k| p[k] < hi[k]);
        assert_eq!(scene.contains(p.to_array()).unwrap(), want, "{p} on the box");
        inside += want as usize;
    }
    assert!(inside > 100 && inside < 500, "{inside} of 600");

    let sphere = procedural::sphere([0.1; 3], 1.0, 12, 16);
    let scene = Scene::from_baked(bake(&sphere, &BuildParams::auto()).unwrap()).unwrap();
    let (mut checked, mut inside) = (0, 0);
    let vertices: Vec<Vec3> = sphere.triangles.iter().flatten().map(|&v| Vec3::from(v)).collect();
    for &p in &vertices {
        let facing: Vec<f64> = sphere
            .triangles
            .iter()
            .filter(|t| t.contains(&p.to_array()))
            .filter_map(|t| {
                let [a, b, c] = t.map(|v| Vec3::from(v).as_dvec3());
                let n = (b - a).cross(c - a).try_normalize()?;
                Some(n.dot(d.as_dvec3()))
            })
            .collect();
        if facing.iter().any(|f| f.abs() < 1e-4) {
            continue;
        }
        let want = facing.iter().all(|&f| f < 0.0);
        assert_eq!(scene.contains(p.to_array()).unwrap(), want, "sphere vertex {p}");
        checked += 1;
        inside += want as usize;
    }
    assert!(checked > vertices.len() * 9 / 10 && inside > 0 && inside < checked, "{inside} of {checked}");
    assert!(!scene.contains([f32::NAN, 0.0, 0.0]).unwrap());
    assert!(!scene.contains([100.0, 0.0, 0.0]).unwrap());
}

/// An open mesh has no inside: refused, naming its boundary edges; the parity vote
/// answers anyway (a grid: below and above it, outside either way).
#[test]
fn open_meshes_are_refused_by_name() {
    let scene = Scene::from_baked(bake(&procedural::grid(4, 2.0), &BuildParams::auto()).unwrap()).unwrap();
    match scene.contains([1.0, 1.0, 0.5]) {
        Err(Error::NotClosed { boundary_edges, edges }) => assert_eq!((boundary_edges, edges), (16, 56)),
        other => panic!("{other:?}"),
    }
    let message = scene.solid().unwrap_err().to_string();
    assert!(message.contains("16 of its 56 edges are boundary edges"), "{message}");
    assert!(!scene.tracer().contains_by_vote([1.0, 1.0, 0.5], 5));
    // The batch vote answers as the one-point vote, point for point (the bunny: open,
    // and inside mostly where the votes agree).
    let bunny = octrace_tests::bunny_scene();
    let b = bunny.view().bounds;
    let frame = octrace_runtime::raysets::Frame::from_bounds(b.mesh_lo, b.mesh_hi);
    let pts = octrace_runtime::raysets::points(&frame, 3000);
    for k in [1, 3] {
        let mut batch = vec![false; pts.len()];
        bunny.tracer().par_contains_by_vote(&pts, k, &mut batch);
        let one: Vec<bool> = pts.iter().map(|&p| bunny.tracer().contains_by_vote(p, k)).collect();
        assert_eq!(batch, one, "{k} votes");
        assert!(batch.iter().filter(|&&b| b).count() > 300, "{k} votes");
    }
    // The bunny this repository carries is open too (223 boundary edges).
    let bunny = octrace_tests::bunny_scene();
    assert!(matches!(bunny.solid(), Err(Error::NotClosed { boundary_edges: 223, .. })));
}

/// Lengths inside: along the axes of a box, its sides; a chord of a sphere within the
/// tessellation's error of the analytic chord; from inside, the part up to the wall;
/// a segment that stops inside, up to where it stops.
#[test]
fn lengths_inside_closed_meshes() {
    let cube = procedural::cube([-1.0, -0.5, 0.0], [1.0, 0.5, 4.0], 2);
    let scene = Scene::from_baked(bake(&cube, &BuildParams::auto()).unwrap()).unwrap();
    let rays = [
        Ray::new(Vec3::new(-5.0, 0.1, 1.3), Vec3::X),
        Ray::new(Vec3::new(0.2, -5.0, 1.3), Vec3::Y),
        Ray::new(Vec3::new(0.2, 0.1, -3.0), Vec3::Z * 2.0),
        Ray::new(Vec3::new(0.2, 0.1, 1.0), Vec3::Z),
        Ray::segment(Vec3::new(-5.0, 0.1, 1.3), Vec3::X, 0.0, 4.5),
        Ray::new(Vec3::new(-5.0, 3.0, 1.3), Vec3::X),
    ];
    let lengths = scene.length_inside_batch(&rays).unwrap();
    assert_eq!(lengths, [2.0, 1.0, 2.0, 3.0, 0.5, 0.0]);
    // A ray that can hit nothing has no length, as it has no crossings (issue 46, item
    // 9: a NaN tmax gave 0 crossings and a positive length).
    let untraceable = [
        Ray::segment(Vec3::new(0.2, 0.1, 1.0), Vec3::Z, 0.0, f32::NAN),
        Ray::segment(Vec3::new(0.2, 0.1, 1.0), Vec3::Z, 2.0, 1.0),
        Ray::new(Vec3::new(0.2, 0.1, 1.0), Vec3::ZERO),
    ];
    assert_eq!(scene.length_inside_batch(&untraceable).unwrap(), [0.0; 3]);
    assert!(scene.count_crossings_batch(&untraceable).iter().all(|c| c.total == 0));
    let ball =
        Scene::from_baked(bake(&procedural::sphere([0.0; 3], 1.0, 48, 64), &BuildParams::auto()).unwrap()).unwrap();
    let mut rng = SplitMix(1);
    for _ in 0..200 {
        let b = 0.9 * rng.unit();
        let ray = Ray::new(Vec3::new(-3.0, b, 0.0), Vec3::X);
        let chord = 2.0 * (1.0 - b * b).sqrt();
        let got = ball.length_inside_batch(&[ray]).unwrap()[0];
        assert!((got - chord).abs() < 0.01, "impact {b}: {got} against {chord}");
    }
}

/// The exact oracle itself, against geometry: a fine sphere away from its facets'
/// error, and a box's faces, edges and corners (on the surface) and its inside and
/// outside, including points in the planes of its faces.
#[test]
fn the_exact_oracle_agrees_with_a_sphere_and_a_box() {
    let sphere = procedural::sphere([0.25, -0.5, 1.0], 1.0, 48, 64);
    let oracle = InsideReference::new(&sphere.triangles);
    let mut rng = SplitMix(11);
    let (mut checked, mut inside) = (0, 0);
    for _ in 0..20_000 {
        let p = Vec3::new(0.25, -0.5, 1.0) + (Vec3::new(rng.unit(), rng.unit(), rng.unit()) * 2.4 - 1.2);
        let r = p.distance(Vec3::new(0.25, -0.5, 1.0));
        if (r - 1.0).abs() < 0.01 {
            continue; // within the facets' distance from the sphere
        }
        let want = if r < 1.0 { Side::Inside } else { Side::Outside };
        assert_eq!(oracle.side(p.to_array()), Some(want), "{p}");
        checked += 1;
        inside += (r < 1.0) as usize;
    }
    assert!(checked > 18_000 && inside > 4_000, "{checked} {inside}");

    let cube = procedural::cube([0.0, 0.0, 0.0], [1.0, 2.0, 4.0], 4);
    let oracle = InsideReference::new(&cube.triangles);
    for (p, want) in [
        ([0.5, 1.0, 2.0], Side::Inside),
        ([1.0, 1.0, 2.0], Side::Surface),
        ([1.0, 2.0, 2.0], Side::Surface),
        ([0.0, 0.0, 0.0], Side::Surface),
        ([1.0, 2.0, 4.0], Side::Surface),
        ([1.5, 1.0, 2.0], Side::Outside),
        ([1.5, 2.0, 4.0], Side::Outside),
        ([0.5, 2.0, 4.5], Side::Outside),
        ([0.5, 0.5, -1e-30], Side::Outside),
        ([0.5, 0.5, 1e-30], Side::Inside),
        ([0.25, 0.5, 1.0], Side::Inside), // on the grid lines of the faces' triangles
    ] {
        assert_eq!(oracle.side(p), Some(want), "{p:?}");
    }
    assert_eq!(oracle.side([f32::NAN, 0.0, 0.0]), None);
}
