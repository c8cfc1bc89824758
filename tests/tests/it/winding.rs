//! Generalized winding numbers (`octrace_runtime::winding`, `Scene::winding_numbers`):
//! within their stated bound of the brute-force sum over every triangle, equal to the
//! closed form of a square's solid angle, exact integers on closed oriented meshes
//! (against the exact inside/outside), and `w > 1/2` decided with certainty.

use octrace_bake::procedural::{self, closed_solids, SplitMix};
use octrace_bake::{bake, BuildParams, Mesh};
use octrace_runtime::reference::{InsideReference, Side};
use octrace_runtime::winding::{solid_angle, Accuracy, WindingScratch, WindingTree};
use octrace_runtime::Scene;

fn scene_of(mesh: &Mesh) -> Scene {
    Scene::from_baked(bake(mesh, &BuildParams::auto()).unwrap()).unwrap()
}

/// The winding number by the sum over every triangle.
fn brute_force(triangles: &[[[f32; 3]; 3]], p: [f32; 3]) -> f64 {
    let p = p.map(f64::from);
    triangles.iter().map(|t| solid_angle(p, t)).sum::<f64>() / (4.0 * std::f64::consts::PI)
}

/// Within the bound, the bound within the tolerance, for every tolerance; Barill's
/// fast rule near (it promises nothing; measured below 4e-3 on the bunny).
fn check_bounds(name: &str, triangles: &[[[f32; 3]; 3]], pts: &[[f32; 3]], fast_error: f64) {
    let tree = WindingTree::new(triangles.to_vec()).unwrap();
    let mut scratch = WindingScratch::default();
    let mut worst_fast = 0.0f64;
    for p in pts {
        let exact = brute_force(triangles, *p);
        for tolerance in [0.1, 1e-3, 1e-6] {
            let w = tree.winding_number(*p, tolerance);
            assert!(w.bound <= tolerance, "{name}: {p:?} bound {} past {tolerance}", w.bound);
            assert!((w.value - exact).abs() <= w.bound + 1e-9, "{name}: {p:?} {w:?} against {exact}");
        }
        let fast = tree.winding_number_beta(&mut scratch, *p, 2.0);
        assert!((fast.value - exact).abs() <= fast.bound + 1e-9, "{name}: {p:?} fast {fast:?} against {exact}");
        worst_fast = worst_fast.max((fast.value - exact).abs());
    }
    assert!(worst_fast <= fast_error, "{name}: Barill's rule off by {worst_fast}");
    // The batch (on all cores, along a curve, walks taking turns) answers as one point
    // at a time, bit for bit.
    let mut batch = vec![Default::default(); pts.len()];
    tree.winding_numbers(pts, Accuracy::FAST, &mut batch);
    for (p, got) in pts.iter().zip(&batch) {
        assert_eq!(*got, tree.winding_number_beta(&mut scratch, *p, 2.0), "{name}: {p:?}");
    }
}

#[test]
fn winding_numbers_hold_their_bound_on_the_bunny_and_on_far_slivers() {
    let mesh = octrace_tests::bunny_mesh();
    let scene = octrace_tests::bunny_scene();
    let pts: Vec<[f32; 3]> =
        crate::inside::points(mesh, scene, 12, 1e-4, 21).into_iter().map(|p| p.to_array()).collect();
    check_bounds("bunny", &mesh.triangles, &pts, 1e-2);
    // Slivers and a soup, far from the origin.
    let mut soup = procedural::soup(7, 400, 0.3, 1.0);
    for t in soup.triangles.iter_mut() {
        for v in t.iter_mut() {
            v[0] += 1e5;
        }
        t[2] = [t[0][0] + 1e-3 * (t[1][0] - t[0][0]), t[0][1] + 1e-3, t[0][2]];
    }
    let mut rng = SplitMix(5);
    let pts: Vec<[f32; 3]> =
        (0..60).map(|_| [1e5 + rng.unit() * 1.2 - 0.1, rng.unit() * 1.2 - 0.1, rng.unit() * 1.2 - 0.1]).collect();
    check_bounds("far slivers", &soup.triangles, &pts, 1e-1);
}

/// A square's solid angle from a point above it is the sum of four rectangles' seen
/// from above a corner: `atan(a b / (h sqrt(a^2 + b^2 + h^2)))` each.
#[test]
fn a_square_winds_as_its_closed_form() {
    let size = 2.0f32;
    let sheet = procedural::grid(16, size);
    let tree = WindingTree::new(sheet.triangles.clone()).unwrap();
    let mut rng = SplitMix(3);
    for _ in 0..200 {
        let (x, y) = (rng.unit() as f64 * 2.0, rng.unit() as f64 * 2.0);
        let h = (rng.unit() as f64 - 0.5) * 3.0;
        if h.abs() < 1e-3 {
            continue;
        }
        let p = [x as f32, y as f32, h as f32];
        let (x, y, h) = (p[0] as f64, p[1] as f64, p[2] as f64);
        let corner = |a: f64, b: f64| (a * b / (h.abs() * (a * a + b * b + h * h).sqrt())).atan();
        let s = size as f64;
        let omega = corner(x, y) + corner(s - x, y) + corner(x, s - y) + corner(s - x, s - y);
        // Counter-clockwise seen from +z: from above, the front, so negative.
        let want = -h.signum() * omega / (4.0 * std::f64::consts::PI);
        let w = tree.winding_number(p, 1e-9);
        assert!((w.value - want).abs() <= 1e-9 + 1e-12, "{p:?}: {w:?} against {want}");
    }
    // Points at infinity wind 0 exactly; a NaN answers NaN, in both modes.
    let mut scratch = WindingScratch::default();
    for p in [[f32::INFINITY, 0.5, 0.5], [0.5, f32::NEG_INFINITY, 1.0]] {
        assert_eq!(tree.winding_number(p, 1e-3).value, 0.0);
        assert_eq!(tree.winding_number_beta(&mut scratch, p, 2.0).value, 0.0);
    }
    assert!(tree.winding_number([f32::NAN, 0.5, 0.5], 1e-3).value.is_nan());
}

/// Nested and inside-out spheres wind 2 and -1; the closed solids 0 and 1, as the
/// exact inside/outside says, near the surface and far from the origin too.
#[test]
fn closed_oriented_meshes_wind_exactly() {
    let outer = procedural::sphere([0.0; 3], 1.0, 12, 16);
    let inner = procedural::sphere([0.1, 0.0, 0.0], 0.5, 12, 16);
    let nested = Mesh::from_triangles(outer.triangles.iter().chain(&inner.triangles).copied().collect());
    let scene = scene_of(&nested);
    assert!(scene.winds_exactly());
    let w = scene.winding_numbers(&[[0.1, 0.0, 0.0], [0.0, 0.8, 0.0], [0.0, 0.0, 2.0]], Accuracy::FAST).unwrap();
    assert_eq!(w.iter().map(|w| (w.value, w.bound)).collect::<Vec<_>>(), [(2.0, 0.0), (1.0, 0.0), (0.0, 0.0)]);
    let flipped = Mesh::from_triangles(outer.triangles.iter().map(|t| [t[0], t[2], t[1]]).collect());
    let w = scene_of(&flipped).winding_numbers(&[[0.1, 0.2, 0.0], [3.0, 0.0, 0.0]], Accuracy::FAST).unwrap();
    assert_eq!((w[0].value, w[1].value), (-1.0, 0.0));

    for solid in closed_solids().into_iter().chain(closed_solids().into_iter().map(|s| s.moved(1e5, 10.0))) {
        let scene = scene_of(&solid.mesh);
        if !scene.winds_exactly() {
            continue;
        }
        let pts: Vec<[f32; 3]> =
            crate::inside::points(&solid.mesh, &scene, 60, 1e-4, 31).into_iter().map(|p| p.to_array()).collect();
        let w = scene.winding_numbers(&pts, Accuracy::FAST).unwrap();
        let inside = InsideReference::new(&solid.mesh.triangles);
        let tree = scene.winding_tree().unwrap();
        for (p, w) in pts.iter().zip(&w) {
            let want = match inside.side(*p) {
                Some(Side::Inside) => 1.0,
                Some(Side::Outside) => 0.0,
                _ => continue,
            };
            assert_eq!(w.value, want, "{}: {p:?}", solid.label());
            // The tree alone, guaranteed, agrees.
            let t = tree.winding_number(*p, 0.1);
            assert!((t.value - want).abs() <= t.bound, "{}: {p:?} tree {t:?}", solid.label());
        }
    }
}

/// `w > 1/2` on an open mesh (the bunny has holes) is decided with certainty: the
/// brute force's answer wherever it is not within rounding of 1/2.
#[test]
fn inside_by_winding_is_certain_on_open_meshes() {
    let mesh = octrace_tests::bunny_mesh();
    let scene = octrace_tests::bunny_scene();
    assert!(!scene.edges().is_closed());
    let pts: Vec<[f32; 3]> =
        crate::inside::points(mesh, scene, 20, 1e-4, 23).into_iter().map(|p| p.to_array()).collect();
    let got = scene.inside_by_winding(&pts).unwrap();
    let mut decided = 0;
    for (p, got) in pts.iter().zip(got) {
        let exact = brute_force(&mesh.triangles, *p);
        if (exact - 0.5).abs() > 1e-9 {
            assert_eq!(got, exact > 0.5, "{p:?}: w = {exact}");
            decided += 1;
        }
    }
    assert!(decided > pts.len() / 2);
    // A closed mesh answers by the exact inside/outside.
    let ball = scene_of(&procedural::sphere([0.0; 3], 1.0, 8, 12));
    assert_eq!(ball.inside_by_winding(&[[0.0; 3], [2.0, 0.0, 0.0]]).unwrap(), [true, false]);
}

/// An octahedron with its vertices on the axes, wound outward.
fn octahedron(centre: [f32; 3], r: f32) -> Vec<[[f32; 3]; 3]> {
    let mut out = Vec::new();
    for sx in [-1.0f32, 1.0] {
        for sy in [-1.0f32, 1.0] {
            for sz in [-1.0f32, 1.0] {
                let v = |k: usize, s: f32| {
                    let mut p = centre;
                    p[k] += s * r;
                    p
                };
                let t = [v(0, sx), v(1, sy), v(2, sz)];
                // Counter-clockwise seen from outside where the octant's signs multiply to +1.
                out.push(if sx * sy * sz > 0.0 { t } else { [t[0], t[2], t[1]] });
            }
        }
    }
    out
}

/// Whether `p` lies on a triangle, in `f64`: exact for the lattice's points (quarters
/// within a few units) and the triangles below; off the lattice a point lies in no plane.
fn on_surface_of(triangles: &[[[f32; 3]; 3]], p: [f32; 3]) -> bool {
    let d = |a: [f32; 3], b: [f32; 3]| [0, 1, 2].map(|k| f64::from(b[k]) - f64::from(a[k]));
    let cross =
        |a: [f64; 3], b: [f64; 3]| [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
    let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    triangles.iter().any(|t| {
        let n = cross(d(t[0], t[1]), d(t[0], t[2]));
        dot(n, d(t[0], p)) == 0.0 && (0..3).all(|k| dot(cross(d(t[k], t[(k + 1) % 3]), d(t[k], p)), n) >= 0.0)
    })
}

/// The signed crossings of one ray a point (`Tracer::winding_by_ray`, what
/// `Scene::winding_numbers` answers closed meshes with) against the tree's guaranteed
/// sum, which shares nothing with the tracer: shells nested, hollowed and turned inside
/// out, their vertices and edges on a lattice whose points send axis rays exactly
/// through vertices and edges, along faces and past silhouettes.
#[test]
fn one_rays_signed_crossings_wind_as_the_sum_says() {
    let flip = |t: &[[f32; 3]; 3]| [t[0], t[2], t[1]];
    let outer = procedural::cube([-2.0, -2.0, -2.0], [2.0, 2.0, 2.0], 4);
    let inner = procedural::cube([-1.0, -1.0, -1.0], [1.0, 1.0, 1.0], 2);
    let octa = octahedron([0.0; 3], 1.5);
    let side = octahedron([1.0, 1.0, 0.0], 0.5);
    let worlds: Vec<(&str, Vec<[[f32; 3]; 3]>)> = vec![
        ("nested cubes", outer.triangles.iter().chain(&inner.triangles).copied().collect()),
        ("hollow cube", outer.triangles.iter().copied().chain(inner.triangles.iter().map(flip)).collect()),
        ("octahedron in a cube", outer.triangles.iter().copied().chain(octa.iter().copied()).collect()),
        ("inside-out octahedra", octa.iter().map(flip).chain(side.iter().copied()).collect()),
    ];
    let mut rng = SplitMix(17);
    for (name, triangles) in worlds {
        let scene = scene_of(&Mesh::from_triangles(triangles.clone()));
        assert!(scene.winds_exactly(), "{name}");
        let tree = WindingTree::new(triangles.clone()).unwrap();
        // Lattice points (quarters, on every vertex, edge and face plane) and some off it.
        let mut pts: Vec<[f32; 3]> =
            (0..1500).map(|_| [0; 3].map(|_: i32| (rng.unit() * 18.0).floor() * 0.25 - 2.25)).collect();
        pts.extend((0..300).map(|_| [0; 3].map(|_: i32| rng.unit() * 4.4 - 2.2)));
        let tracer = scene.tracer();
        let (mut checked, mut on_surface) = (0, 0);
        let answers = scene.winding_numbers(&pts, Accuracy::FAST).unwrap();
        for (p, got) in pts.iter().zip(&answers) {
            if on_surface_of(&triangles, *p) {
                // Not defined there: the number of a point beside it, or none.
                // Points in the eight octants around it, and along the six axes (a
                // hair off them), as the ray goes.
                let octants = (0..8).map(|o| [0, 1, 2].map(|k| if o >> k & 1 == 1 { 1e-3 } else { -1e-3 }));
                let axes = (0..6).map(|a| [0, 1, 2].map(|k| if k == a / 2 { [-1e-3, 1e-3][a % 2] } else { 1e-5 }));
                let beside: Vec<f64> = octants
                    .chain(axes)
                    .map(|o: [f32; 3]| {
                        let q = [0, 1, 2].map(|k| p[k] + o[k] * (1.0 + 0.3 * k as f32));
                        tree.winding_number(q, 0.1).value.round()
                    })
                    .collect();
                let n = tracer.winding_by_ray(*p).unwrap();
                assert!(beside.contains(&(n as f64)), "{name}: {p:?} on the surface: {n}, beside {beside:?}");
                assert!(beside.contains(&got.value) && got.bound == 0.0, "{name}: {p:?} {got:?}, beside {beside:?}");
                on_surface += 1;
                continue;
            }
            let sum = tree.winding_number(*p, 0.1);
            assert!((sum.value - sum.value.round()).abs() < 0.2, "{name}: {p:?} sum {sum:?}");
            let want = sum.value.round() as i64;
            assert_eq!(tracer.winding_by_ray(*p), Some(want), "{name}: {p:?} by the ray");
            assert_eq!((got.value, got.bound), (want as f64, 0.0), "{name}: {p:?}");
            checked += 1;
        }
        assert!(checked > 1000 && on_surface > 50, "{name}: {checked} checked, {on_surface} on the surface");
    }
}
