//! Closest points, distances and signed distances (`Scene::closest_point`): against
//! the exact oracle (`octrace_tests::exact::closest`, rational arithmetic by another
//! construction) on small meshes, bit for bit, and against the `f64` brute force on
//! the bunny (and the dragon where `../shared` has it), within one `f32` rounding.

use glam::Vec3;
use octrace_bake::procedural::{self, SplitMix};
use octrace_bake::{bake, BuildParams, Mesh};
use octrace_runtime::reference::{InsideReference, Reference, Side};
use octrace_runtime::{ClosestPoint, Scene};
use octrace_tests::exact;

/// Points of every kind a user's sampling meets: those of the inside tests (uniform in
/// 1.1x the mesh's box, within `near` of the surface on either side, on the octree's
/// cell planes), and points inside faces, on vertices, near edges' midpoints and off
/// the mesh by up to its size.
fn points(mesh: &Mesh, scene: &Scene, n: usize, near: f32, seed: u64) -> Vec<[f32; 3]> {
    let mut out = crate::inside::points(mesh, scene, n, near, seed);
    let mut rng = SplitMix(seed ^ 0x5EED);
    let (lo, hi) = crate::inside::mesh_box(mesh);
    let e = hi - lo;
    for i in 0..n {
        let t = mesh.triangles[(rng.next_u64() % mesh.triangles.len() as u64) as usize].map(Vec3::from);
        let (a, b) = (rng.unit(), rng.unit());
        let (a, b) = if a + b > 1.0 { (1.0 - a, 1.0 - b) } else { (a, b) };
        out.push(t[0] + a * (t[1] - t[0]) + b * (t[2] - t[0]));
        out.push(t[i % 3]);
        out.push((t[i % 3] + t[(i + 1) % 3]) * 0.5);
        let u = Vec3::new(rng.unit(), rng.unit(), rng.unit());
        out.push(lo + (u - 0.5) * 3.0 * e.max_element());
    }
    out.into_iter().map(|p| p.to_array()).collect()
}

fn scene_of(mesh: &Mesh) -> Scene {
    Scene::from_baked(bake(mesh, &BuildParams::auto()).unwrap()).unwrap()
}

/// The batch, and one point at a time, agree.
fn answers(scene: &Scene, pts: &[[f32; 3]]) -> Vec<Option<ClosestPoint>> {
    let got = scene.closest_points_batch(pts, f32::INFINITY).unwrap();
    for (p, g) in pts.iter().zip(&got).step_by(7) {
        assert_eq!(*g, scene.closest_point(*p), "batch and one point differ at {p:?}");
    }
    got
}

/// Bit for bit against exact arithmetic: the distance correctly rounded, the nearest
/// triangle, ties to the lowest input index; the point within a few `f64` roundings of
/// the triangle (its distance from the query point as said).
fn check_exactly(name: &str, mesh: &Mesh, n: usize, near: f32) {
    let scene = scene_of(mesh);
    let pts = points(mesh, &scene, n, near, 11);
    let view = scene.view();
    let stored: Vec<[[f32; 3]; 3]> = view.stored_triangles().collect();
    let got = answers(&scene, &pts);
    same_with_the_baked_tree(name, mesh, &pts, &got);
    for (p, got) in pts.iter().zip(got) {
        let got = got.unwrap_or_else(|| panic!("{name}: no closest point for {p:?}"));
        let (distance, triangle) = exact::closest(*p, &stored, view.triangle_ids).expect("triangles");
        assert_eq!(
            (got.distance, got.triangle),
            (distance, triangle),
            "{name}: point {p:?} ({:?})",
            p.map(f32::to_bits)
        );
        let t = mesh.triangles[triangle as usize].map(Vec3::from);
        let at = t[0] + got.u * (t[1] - t[0]) + got.v * (t[2] - t[0]);
        let scale = t.iter().fold(Vec3::from(*p).abs().max_element(), |m, v| m.max(v.abs().max_element()));
        assert!((at - Vec3::from(got.point)).length() <= 1e-5 * scale, "{name}: barycentrics of {p:?}");
        let said = (Vec3::from(got.point) - Vec3::from(*p)).length();
        assert!((said - distance).abs() <= 1e-5 * scale, "{name}: point of {p:?} at {said}, not {distance}");
    }
}

/// The scene baked with its tree (`bake --distance`: stored triangles in the tree's
/// order, the tree read from the validated file, nothing made at open) answers as the
/// one that makes its tree: the same distance, triangle, point and barycentrics.
fn same_with_the_baked_tree(name: &str, mesh: &Mesh, pts: &[[f32; 3]], want: &[Option<ClosestPoint>]) {
    let baked = bake(mesh, &BuildParams { distance: true, ..BuildParams::auto() }).unwrap();
    assert!(!baked.distance.is_empty(), "{name}: no distance section");
    let file = octrace_format::SceneFile::from_bytes(&baked.to_file_bytes(0).unwrap()).expect("validates");
    assert_eq!(file.view().distance, baked.distance.as_slice());
    let scene = Scene::from_baked(baked).unwrap();
    assert!(scene.surface_bounds().unwrap().is_baked(), "{name}: the tree was made, not read");
    let without_prim = |c: &Option<ClosestPoint>| c.map(|c| ClosestPoint { prim: 0, ..c });
    for (p, (a, b)) in pts.iter().zip(want.iter().zip(answers(&scene, pts))) {
        assert_eq!(without_prim(a), without_prim(&b), "{name}: {p:?} with the baked tree");
    }
}

#[test]
fn closest_points_are_exact_on_small_meshes() {
    check_exactly("sphere", &procedural::sphere([0.1, -0.2, 0.3], 1.0, 12, 16), 60, 1e-5);
    // Axis-aligned faces: points exactly on faces, edges and corners.
    check_exactly("cube", &procedural::cube([-1.0, 0.0, 0.5], [1.0, 2.0, 1.5], 3), 60, 1e-6);
    // Far from the origin, where f32 spacing is coarse.
    check_exactly("far sphere", &procedural::sphere([1e4, -3e4, 2e4], 1.0, 8, 12), 40, 2e-3);
    // Random triangles, slivers among them, and an open grid.
    check_exactly("soup", &procedural::soup(5, 120, 1.0, 0.4), 60, 1e-6);
    check_exactly("grid", &procedural::grid(6, 1.0), 40, 1e-6);
}

#[test]
fn slivers_and_needles_are_exact() {
    let mut tris = Vec::new();
    let mut rng = SplitMix(8);
    for _ in 0..80 {
        let a = [rng.unit(), rng.unit(), rng.unit()];
        let b = [rng.unit(), rng.unit(), rng.unit()];
        let s = rng.unit();
        // The third vertex a few ulps off the first edge: area all but zero.
        let c = [0, 1, 2].map(|k| (a[k] + (b[k] - a[k]) * s) * (1.0 + 4.0 * f32::EPSILON * (k as f32 - 1.0)));
        tris.push([a, b, c]);
    }
    check_exactly("slivers", &octrace_bake::Mesh::from_triangles(tris), 60, 1e-7);
}

/// Tilted flat surfaces, where the search's bounds are slabs across the surface's
/// normal rather than boxes: a fine grid turned off every axis, with a copy 1e-3 above
/// it wound the other way (a thin wall, whose two sides' normals cancel if summed
/// naively), and a crease folding it.
#[test]
fn tilted_sheets_and_thin_walls_are_exact() {
    let grid = procedural::grid(12, 1.0);
    let (c, s) = (0.6f32.cos(), 0.6f32.sin());
    let (c2, s2) = (1.1f32.cos(), 1.1f32.sin());
    let turn = |v: [f32; 3], lift: f32| {
        let (x, y, z) = (v[0], v[1], v[2] + lift);
        let (x, z) = (c * x - s * z, s * x + c * z);
        [x, c2 * y - s2 * z, s2 * y + c2 * z]
    };
    let mut tris = Vec::new();
    for t in &grid.triangles {
        tris.push(t.map(|v| turn(v, 0.0)));
        let [a, b, c] = t.map(|v| turn(v, 1e-3));
        tris.push([a, c, b]);
        // The crease: the grid bent up along x = 0.5.
        let fold = t.map(|v| turn([v[0].min(0.5), v[1], (v[0] - 0.5).max(0.0) + 0.3], 0.0));
        tris.push(fold);
    }
    check_exactly("tilted sheets", &Mesh::from_triangles(tris), 80, 1e-4);
}

/// Against the f64 brute force on the bunny: the same distance within one `f32`
/// rounding, the same triangle or one as near within f64's reach (a tie); signed
/// distances take the exact inside's sign (on a closed sphere).
#[test]
fn closest_points_agree_with_the_oracle_on_the_bunny() {
    let mesh = octrace_tests::bunny_mesh();
    let scene = octrace_tests::bunny_scene();
    let pts = points(mesh, scene, 12, 1e-4, 12);
    check_against_f64("bunny", scene, &pts);
    // Signs on a closed solid (the bunny is open).
    let solid = procedural::sphere([0.1, -0.2, 0.3], 1.0, 12, 16);
    let scene = scene_of(&solid);
    let pts = points(&solid, &scene, 30, 1e-4, 14);
    let signed = scene.signed_distance_batch(&pts, f32::INFINITY).unwrap();
    let inside = InsideReference::new(&solid.triangles);
    let mut wrong = 0;
    for (p, d) in pts.iter().zip(&signed) {
        match inside.side(*p) {
            Some(Side::Inside) => wrong += (*d > 0.0) as usize,
            Some(Side::Outside) => wrong += (*d < 0.0) as usize,
            _ => assert_eq!(*d, 0.0, "{p:?} on the surface"),
        }
    }
    assert_eq!(wrong, 0, "signs against the exact inside");
}

#[test]
#[cfg_attr(not(octrace_shared), ignore = "needs ../shared beside the clone (README: Set up)")]
fn closest_points_agree_with_the_oracle_on_the_dragon() {
    let Some(path) = octrace_tests::shared_file("meshes/dragon.obj", "closest points on the dragon") else { return };
    let mesh = Mesh::load(&path).unwrap();
    let scene = scene_of(&mesh);
    let pts = points(&mesh, &scene, 2, 1e-4, 13);
    check_against_f64("dragon", &scene, &pts);
}

fn check_against_f64(name: &str, scene: &Scene, pts: &[[f32; 3]]) {
    let oracle = Reference::from_view(&scene.view());
    let got = answers(scene, pts);
    for (p, got) in pts.iter().zip(got) {
        let want = oracle.closest_point(*p).unwrap();
        let got = got.unwrap();
        let w = want.distance as f32;
        // f64's own error where the distance is tiny against the coordinates.
        let near =
            (got.distance as f64 - want.distance).abs() <= 1e-15 * (1.0 + Vec3::from(*p).abs().max_element() as f64);
        assert!(
            near || got.distance == w || got.distance == w.next_up() || got.distance == w.next_down(),
            "{name}: {p:?} at {} against {}",
            got.distance,
            want.distance
        );
        if got.triangle != want.triangle {
            let other = oracle.distance_to(*p, got.triangle).unwrap();
            assert!(
                (other - want.distance).abs() <= 1e-12 * (1.0 + want.distance),
                "{name}: {p:?} on triangle {} at {other}, the oracle's {} at {}",
                got.triangle,
                want.triangle,
                want.distance
            );
        }
    }
}

#[test]
fn far_limits_and_bad_points_have_defined_answers() {
    let scene = scene_of(&procedural::sphere([0.0; 3], 1.0, 12, 16));
    let p = [0.0, 0.0, 3.0];
    let near = scene.closest_point(p).unwrap();
    assert_eq!(scene.closest_point_within(p, near.distance), Some(near), "the limit is inclusive");
    assert_eq!(scene.closest_point_within(p, near.distance.next_down()), None);
    assert_eq!(scene.closest_point_within(p, f32::NAN), None);
    assert_eq!(scene.closest_point_within(p, -1.0), None);
    for bad in [[f32::NAN, 0.0, 0.0], [0.0, f32::INFINITY, 0.0]] {
        assert_eq!(scene.closest_point(bad), None);
    }
    // Points at the ends of f32's range.
    let far = scene.closest_point([f32::MAX, -f32::MAX, 0.0]).unwrap();
    assert_eq!(far.distance, f32::INFINITY);
    let d = scene.signed_distance_batch(&[[0.0; 3], [0.0, 0.0, 5.0]], 2.0).unwrap();
    assert_eq!(d[1], f32::INFINITY);
    assert!(d[0] < -0.9, "{d:?}");
    let open = scene_of(&procedural::grid(4, 1.0));
    assert!(open.signed_distance_batch(&[[0.0; 3]], f32::INFINITY).is_err());
}
