//! The octree walk agrees with the f64 brute-force oracle, ray for ray.

use glam::Vec3;
use proptest::prelude::*;

use crate::reference::{Agreement, Reference};
use crate::{MemoryOrder, Ray, Scene, TriangleTest};
use octrace_bake::{bake, procedural, BuildParams, Mesh};

fn scene_of(mesh: &Mesh, params: BuildParams) -> (Scene, Reference) {
    let baked = bake(mesh, &params).unwrap();
    let oracle = Reference::in_input_order(mesh.triangles.clone());
    (Scene::from_baked(baked).unwrap(), oracle)
}

/// Random rays: origins in a box twice the scene's (inside and outside), uniform
/// directions.
fn random_rays(seed: u64, n: usize, lo: Vec3, hi: Vec3) -> Vec<Ray> {
    let mut rng = procedural::SplitMix(seed);
    // Origins span the largest extent on every axis, so a flat mesh's rays do not all
    // start on its plane (where t = 0 ties decide nothing).
    let (c, e) = ((lo + hi) * 0.5, Vec3::splat((hi - lo).max_element()));
    (0..n)
        .map(|_| {
            let o = c + (Vec3::new(rng.unit(), rng.unit(), rng.unit()) - 0.5) * 2.0 * e;
            let z = 1.0 - 2.0 * rng.unit();
            let phi = std::f32::consts::TAU * rng.unit();
            let s = (1.0 - z * z).max(0.0).sqrt();
            Ray::new(o, Vec3::new(s * phi.cos(), s * phi.sin(), z))
        })
        .collect()
}

/// `rays` bent where the `f32` arithmetic gives out, ray by ray in turn: a component
/// made the smallest subnormal or a tiny number (its sign kept), the origin moved onto
/// the cell plane of `grid` nearest it first (where underflowing products decide
/// nothing); the whole direction scaled by `2^k`, `k` from -120 to 100 (its length
/// from about 1e-36 to 1e30); or both.
fn bend(rays: &[Ray], seed: u64, grid: Option<(Vec3, f32)>) -> Vec<Ray> {
    let mut rng = procedural::SplitMix(seed);
    rays.iter()
        .enumerate()
        .map(|(i, r)| {
            let (mut o, mut d) = (r.origin.to_array(), r.dir.to_array());
            let k = (rng.next_u64() % 3) as usize;
            if i % 3 != 2 {
                let e = -149 + (rng.next_u64() % 110) as i32;
                let tiny =
                    if i % 2 == 0 { f32::from_bits(1) } else { (2f64.powi(e) * (1.0 + rng.unit() as f64)) as f32 };
                d[k] = tiny.copysign(d[k]);
                if let Some((lo, cell)) = grid.filter(|_| rng.unit() < 0.5) {
                    o[k] = lo[k] + ((o[k] - lo[k]) / cell).round() * cell;
                }
            }
            if i % 3 != 0 {
                let by = -120 + (rng.next_u64() % 221) as i32;
                d = d.map(|c| (c as f64 * 2f64.powi(by)) as f32);
            }
            Ray { origin: o.into(), dir: d.into(), ..*r }
        })
        .collect()
}

fn check(name: &str, mesh: &Mesh, params: BuildParams, rays: &[Ray]) {
    let (scene, oracle) = scene_of(mesh, params);
    let tracer = scene.tracer();
    let mut wrong = Vec::new();
    for r in rays {
        // The same answer: the same triangle, or the same distance (a tie).
        let got = tracer.intersect(r);
        if oracle.compare(r, got.map(|h| (h.t, h.triangle, h.u, h.v))) != Agreement::Same {
            wrong.push((r, got, oracle.intersect(r)));
        }
        assert_eq!(tracer.occluded(r), oracle.occluded(r), "{name}: occluded {r:?}");
    }
    assert!(wrong.is_empty(), "{name}: {} of {} rays disagree, first: {:?}", wrong.len(), rays.len(), wrong[0]);
}

fn bounds(mesh: &Mesh) -> (Vec3, Vec3) {
    let pts = mesh.triangles.iter().flatten().map(|&p| Vec3::from(p));
    pts.fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), p| (lo.min(p), hi.max(p)))
}

#[test]
fn procedural_meshes_agree_with_the_oracle() {
    let meshes = [
        ("sphere", procedural::sphere([0.1, 0.2, -0.3], 1.5, 20, 28)),
        ("torus", procedural::torus([0.0; 3], 1.0, 0.35, 30, 14)),
        ("cube", procedural::cube([-1.0, -0.5, -2.0], [1.0, 0.5, 2.0], 5)),
        ("grid", procedural::grid(12, 3.0)),
        ("fan", procedural::fan(48, 1.0)),
        ("soup", procedural::soup(5, 3000, 8.0, 0.8)),
    ];
    for (name, mesh) in &meshes {
        let (lo, hi) = bounds(mesh);
        let rays = random_rays(17, 4000, lo, hi);
        for (depth, leaf) in [(2, 4), (5, 2), (8, 1)] {
            let p = BuildParams { max_depth: Some(depth), leaf_size: Some(leaf), ..BuildParams::auto() };
            check(&format!("{name} d{depth} l{leaf}"), mesh, p, &rays);
        }
        check(name, mesh, BuildParams::auto(), &rays);
    }
}

/// The SIMD step (where the build has one) gives the scalar step's answers bit for
/// bit: the same operations in the same order; compiled for x86-64-v3 or for the
/// baseline alike, reading ahead or not.
#[test]
fn the_simd_walk_equals_the_scalar_walk_bit_for_bit() {
    let mut mesh = procedural::soup(21, 4000, 6.0, 0.6);
    mesh.triangles.extend(procedural::torus([3.0; 3], 2.0, 0.5, 40, 20).triangles);
    let (lo, hi) = bounds(&mesh);
    let mut rays = random_rays(5, 20_000, lo, hi);
    rays.extend(bend(&rays[..4000], 3, None));
    for params in [BuildParams::auto(), BuildParams { max_depth: Some(7), leaf_size: Some(2), ..BuildParams::auto() }] {
        let (scene, _) = scene_of(&mesh, params);
        let tests = [crate::TriangleTest::Watertight, crate::TriangleTest::MollerTrumbore, crate::TriangleTest::F64];
        let configs = tests.into_iter().map(|t| (t, crate::ExitTest::Plucker));
        let configs = configs.chain([(crate::TriangleTest::Watertight, crate::ExitTest::Slab)]);
        // Reading ahead (off for a scene this small) changes no answer: on in one run
        // of each build.
        for ((test, exit), v3, ahead) in
            configs.flat_map(|c| [(c, true, false), (c, false, false), (c, true, true), (c, false, true)])
        {
            let t =
                scene.tracer().with_triangle_test(test).with_exit_test(exit).with_x86_64_v3(v3).with_read_ahead(ahead);
            assert!(v3 || !t.uses_x86_64_v3(), "off means the baseline");
            let mut batch = vec![None; rays.len()];
            t.intersect_batch(&rays, &mut batch);
            let mut occluded = vec![false; rays.len()];
            t.occluded_batch(&rays, &mut occluded);
            let mut occluders = vec![None; rays.len()];
            t.occluder_batch(&rays, &mut occluders);
            for (i, r) in rays.iter().enumerate() {
                let scalar = t.intersect_scalar(r);
                assert_eq!(t.intersect(r), scalar, "ray {r:?}");
                assert_eq!(batch[i], scalar, "batch, ray {r:?}");
                assert_eq!(occluded[i], t.occluded_scalar(r), "occluded, ray {r:?}");
                assert_eq!(occluders[i], t.occluder(r), "occluder, ray {r:?}");
            }
        }
    }
}

/// The report's other knobs — the `f64` triangle test, the slab exit-face test —
/// give the oracle's answers too (ties on edges aside, where `f64` Möller-Trumbore
/// is not watertight).
#[test]
fn the_f64_test_and_the_slab_exit_agree_with_the_oracle() {
    let meshes = [
        ("sphere", procedural::sphere([0.1, 0.2, -0.3], 1.5, 20, 28)),
        ("soup", procedural::soup(5, 3000, 8.0, 0.8)),
        ("cube", procedural::cube([-1.0, -0.5, -2.0], [1.0, 0.5, 2.0], 5)),
    ];
    let configs = [
        (crate::TriangleTest::F64, crate::ExitTest::Plucker),
        (crate::TriangleTest::Watertight, crate::ExitTest::Slab),
    ];
    for (name, mesh) in &meshes {
        let (lo, hi) = bounds(mesh);
        let rays = random_rays(23, 3000, lo, hi);
        for params in
            [BuildParams::auto(), BuildParams { max_depth: Some(6), leaf_size: Some(2), ..BuildParams::auto() }]
        {
            let (scene, oracle) = scene_of(mesh, params);
            for (test, exit) in configs {
                let tracer = scene.tracer().with_triangle_test(test).with_exit_test(exit);
                let wrong = rays
                    .iter()
                    .filter(|r| {
                        let got = tracer.intersect(r).map(|h| (h.t, h.triangle, h.u, h.v));
                        oracle.compare(r, got) == Agreement::Different
                    })
                    .count();
                assert_eq!(wrong, 0, "{name} {params:?} {test:?} {exit:?}");
            }
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]

    /// Random soups of random size, random rays from inside and outside.
    #[test]
    fn random_soups_agree_with_the_oracle(seed in any::<u64>(), n in 1usize..400, size in 0.01f32..3.0, depth in 1u32..9, leaf in 1u32..12) {
        let mesh = procedural::soup(seed, n, 4.0, size);
        let (lo, hi) = bounds(&mesh);
        let rays = random_rays(seed ^ 0xABCD, 300, lo, hi);
        let p = BuildParams { max_depth: Some(depth), leaf_size: Some(leaf), ..BuildParams::auto() };
        check("soup", &mesh, p, &rays);
    }

    /// The same with the rays bent ([`bend`]): subnormal and tiny components, origins
    /// on cell planes, directions of every length; the oracle's answers, and the SIMD
    /// walks' answers the scalar walk's, bit for bit.
    #[test]
    fn bent_rays_agree_with_the_oracle(seed in any::<u64>(), n in 1usize..300, size in 0.01f32..3.0, depth in 1u32..9, leaf in 1u32..8) {
        let mesh = procedural::soup(seed, n, 4.0, size);
        let (lo, hi) = bounds(&mesh);
        let p = BuildParams { max_depth: Some(depth), leaf_size: Some(leaf), ..BuildParams::auto() };
        let (scene, _) = scene_of(&mesh, p);
        let (b, depth) = (scene.view().bounds, scene.view().params.max_depth);
        let grid = (Vec3::from(b.root_lo), b.root_size / (1u64 << depth) as f32);
        let rays = bend(&random_rays(seed ^ 0x5EED, 300, lo, hi), seed, Some(grid));
        // Most of them are for the exact rule: the case is not left to chance.
        let (root_lo, root_hi) = super::root_corners(&scene.view());
        let scale = super::tables::RuleScale::of(root_lo, root_hi, b.root_size);
        let rule = |r: &Ray| super::tables::exit_rule(r.origin.to_array(), r.dir.to_array(), scale);
        let exact = rays.iter().filter(|r| rule(r) == super::tables::ExitRule::Exact).count();
        prop_assert!(exact > 100, "{exact} rays of 300 for the exact rule");
        check("bent soup", &mesh, p, &rays);
        same_on_every_walk(&scene, &rays);
    }
}

/// Every walk (one ray, batch, lanes or not, x86-64-v3 or not; nearest, occluded,
/// occluder, every crossing), under the default and the exact test, answers each ray
/// as the scalar walk does, bit for bit.
fn same_on_every_walk(scene: &Scene, rays: &[Ray]) {
    let tests = [TriangleTest::Watertight, TriangleTest::Exact];
    for (test, v3, lanes) in tests.into_iter().flat_map(|t| [(t, true, true), (t, true, false), (t, false, false)]) {
        let t = scene.tracer().with_triangle_test(test).with_x86_64_v3(v3).with_lanes(lanes);
        let lists = t.crossings_batch(rays, usize::MAX);
        let mut batch = vec![None; rays.len()];
        t.intersect_batch(rays, &mut batch);
        let mut occluded = vec![false; rays.len()];
        t.occluded_batch(rays, &mut occluded);
        let mut occluders = vec![None; rays.len()];
        t.occluder_batch(rays, &mut occluders);
        for (i, r) in rays.iter().enumerate() {
            let scalar = t.intersect_scalar(r);
            assert_eq!(t.intersect(r), scalar, "ray {r:?}");
            assert_eq!(batch[i], scalar, "batch, ray {r:?}");
            assert_eq!(occluded[i], t.occluded_scalar(r), "occluded, ray {r:?}");
            assert_eq!(occluders[i], t.occluder(r), "occluder, ray {r:?}");
            assert_eq!(lists.of(i), t.all_crossings(r).as_slice(), "crossings, {test:?}, ray {r:?}");
        }
    }
}

/// The clip `begin` runs (two vector divisions on SSE2) gives the scalar clip's
/// answer: the same interval and the same entry axis, ties to the first axis
/// included.
#[test]
fn the_clip_agrees_with_the_scalar_clip() {
    use super::walk::{clip, clip_scalar};
    let mut rng = procedural::SplitMix(7);
    let (lo, hi) = ([-1.0f32, -2.0, 0.5], [3.0f32, 2.0, 4.5]);
    // Directions with equal components and origins on the box's planes make ties in
    // the entry distance; the rest are random, from inside and outside.
    let mut cases = vec![
        ([-2.0f32, -3.0, -0.5], [1.0f32, 1.0, 1.0]),
        ([-1.0, -2.0, 0.5], [1.0, 1.0, 1.0]),
        ([5.0, 4.0, 6.5], [-1.0, -1.0, -1.0]),
        ([-1.0, 0.0, 1.0], [1.0, -1.0, 1.0]),
        ([1.0, 0.0, 2.0], [1e-30, 1e30, -1e-30]),
        ([0.0, 0.0, 0.0], [0.0, 1.0, 0.0]),
        ([9.0, 0.0, 0.0], [0.0, 1.0, 0.0]),
    ];
    for _ in 0..20_000 {
        let p =
            |rng: &mut procedural::SplitMix| [rng.unit() * 8.0 - 3.0, rng.unit() * 8.0 - 4.0, rng.unit() * 8.0 - 2.0];
        let o = p(&mut rng);
        let d = [rng.unit() - 0.5, rng.unit() - 0.5, rng.unit() - 0.5];
        cases.push((o, d));
        // Snapped to a coarse grid: origins on the planes and equal distances.
        cases.push((o.map(|c| c.round()), d.map(|c| (c * 4.0).round() / 4.0)));
    }
    for (o, d) in cases {
        if d == [0.0; 3] {
            continue;
        }
        let (a, b) = (clip(o, d, lo, hi), clip_scalar(o, d, lo, hi));
        // Equal as numbers (a zero's sign may differ: both are only compared).
        let same = match (a, b) {
            (Some(x), Some(y)) => x.0 == y.0 && x.1 == y.1 && x.2 == y.2,
            (None, None) => true,
            _ => false,
        };
        assert!(same, "o {o:?} d {d:?}: {a:?} against {b:?}");
    }
}

/// Point location's grid coordinates (SSE2 where the build has it) are the scalar
/// form's, cell for cell: points inside and outside the root, on cell planes, and
/// with NaN, infinite, zero (both signs) and extreme coordinates, at several depths.
#[test]
fn grid_coordinates_agree_with_the_scalar_form() {
    let mut rng = procedural::SplitMix(23);
    let odd = [0.0f32, -0.0, f32::NAN, f32::INFINITY, f32::NEG_INFINITY, f32::MAX, f32::MIN, 1e-38, -1e30];
    let mut compared = 0;
    for depth in [1, 4, 7, 10] {
        let params = BuildParams { max_depth: Some(depth), ..BuildParams::auto() };
        let scene =
            Scene::from_baked(bake(&procedural::sphere([0.5, -1.0, 2.0], 1.5, 12, 16), &params).unwrap()).unwrap();
        let t = scene.tracer();
        let (lo, size) = (scene.view().bounds.root_lo, scene.view().bounds.root_size);
        let cell = size / (1u32 << depth) as f32;
        for i in 0..20_000 {
            let mut p: [f32; 3] = std::array::from_fn(|k| lo[k] - 1.0 + rng.unit() * (size + 2.0));
            match i % 4 {
                // On a cell plane (as rounding puts it) on every axis.
                1 => p = std::array::from_fn(|k| lo[k] + (p[k] - lo[k]).div_euclid(cell) * cell),
                // An odd value on one axis.
                2 => p[i / 4 % 3] = odd[i / 12 % odd.len()],
                3 => p = [odd[i / 4 % odd.len()], odd[i / 36 % odd.len()], p[2]],
                _ => {}
            }
            assert_eq!(t.grid_coords(p), t.grid_coords_scalar(p), "depth {depth}, point {p:?}");
            compared += 1;
        }
    }
    assert_eq!(compared, 80_000);
}

/// The eight-ray begin of the lanes (`simd::begin8`) answers each ray as
/// `Tracer::begin` does: a ray it marks as missing is one `begin` refuses, and a ray
/// it begins starts in `begin`'s leaf (address, level, cell) with its stopping
/// distance. Rays from inside the root and from outside it, through the mesh box's
/// faces and the root's, on cell planes, with zeros of both signs, NaN, infinities,
/// extremes and inverted intervals mixed in, in scenes of several depths (and one
/// tracer without a locate grid, which begins none). Most rays must be decided here,
/// so that the check is not vacuous.
#[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
#[test]
fn eight_rays_begin_as_begin_does() {
    use super::simd::begin8::begin8;
    if !std::arch::is_x86_feature_detected!("avx2") {
        return; // the lanes (the only caller) do not run here either
    }
    let mut rng = procedural::SplitMix(17);
    let sub = f32::from_bits(1);
    let odd = [0.0, -0.0, f32::NAN, f32::INFINITY, f32::NEG_INFINITY, 1e30, -1e-30, f32::MAX, 3.0, -1.0, sub, -1e-40];
    for (depth, leaf) in [(3, 4), (7, 2), (9, 1)] {
        let params = BuildParams { max_depth: Some(depth), leaf_size: Some(leaf), ..BuildParams::auto() };
        let mesh = procedural::sphere([0.5, -1.0, 2.0], 1.5, 24, 32);
        let scene = Scene::from_baked(bake(&mesh, &params).unwrap()).unwrap();
        let (lo, size) = (scene.view().bounds.root_lo, scene.view().bounds.root_size);
        let cell = size / (1u32 << depth) as f32;
        let mut rays = Vec::new();
        for i in 0..40_000 {
            let mut o: [f32; 3] = std::array::from_fn(|k| lo[k] - 0.5 * size + rng.unit() * 2.0 * size);
            let mut d = [rng.unit() - 0.5, rng.unit() - 0.5, rng.unit() - 0.5];
            match i % 6 {
                // On cell planes, with equal slab distances.
                1 => {
                    (o, d) =
                        (o.map(|c| lo[0] + ((c - lo[0]) / cell).round() * cell), d.map(|c| (c * 4.0).round() / 4.0))
                }
                // An odd value (zeros of both signs, NaN, infinities, extremes) somewhere.
                2 => d[i / 6 % 3] = odd[i / 18 % odd.len()],
                3 => o[i / 6 % 3] = odd[i / 18 % odd.len()],
                // From far outside, towards the sphere.
                4 => d = std::array::from_fn(|k| [0.5, -1.0, 2.0][k] + rng.unit() - 0.5 - o[k]),
                _ => {}
            }
            let (tmin, tmax) = match i % 7 {
                0 => (0.0, -1.0),
                1 => (rng.unit() * size, rng.unit() * 3.0 * size),
                2 => (0.0, f32::NAN),
                _ => (0.0, f32::INFINITY),
            };
            rays.push(Ray::segment(o.into(), d.into(), tmin, tmax));
        }
        let tracer = scene.tracer();
        let without_grid = crate::Tracer::new(scene.view());
        for t in [&tracer, &without_grid] {
            let (mut missed, mut begun) = (0, 0);
            for block in rays.chunks_exact(8) {
                // SAFETY: the processor has AVX2 (checked above).
                let b = unsafe { begin8(t, block.try_into().unwrap()) };
                assert_eq!(b.misses & b.begun, 0);
                for (l, r) in block.iter().enumerate() {
                    let w = t.begin(r);
                    if b.misses >> l & 1 != 0 {
                        assert!(w.is_none(), "depth {depth}: marked as missing, but begun: {r:?}");
                        missed += 1;
                    } else if b.begun >> l & 1 != 0 {
                        let w = w.unwrap_or_else(|| panic!("depth {depth}: begun, but begin refuses it: {r:?}"));
                        assert_ne!(w.rule(), super::tables::ExitRule::Exact, "the lanes walk no exact-rule ray: {r:?}");
                        let cell = [b.cell[0][l], b.cell[1][l], b.cell[2][l]];
                        assert_eq!((b.address[l], b.level[l], cell), (w.address(), w.level(), w.cell()), "{r:?}");
                        assert!(b.tmax[l] == w.tmax(), "depth {depth}: tmax {} against {}: {r:?}", b.tmax[l], w.tmax());
                        begun += 1;
                    }
                }
            }
            if std::ptr::eq(t, &without_grid) {
                assert_eq!(begun, 0, "a tracer without a grid leaves the walks to the scalar begin");
            } else {
                assert!(
                    begun > rays.len() / 10 && missed > rays.len() / 5,
                    "depth {depth}: {begun} begun, {missed} missed"
                );
            }
        }
    }
}

/// Incoherent batches are walked in memory order and coherent ones as given, and
/// either way every batch call (one thread and all, nearest, occluded, occluder)
/// answers each ray as the one-ray calls do, bit for bit, with the order on or off.
/// The rays include untraceable ones (NaN, zero direction, inverted interval) and
/// rays with zero direction components, whose keys must not disturb the sort.
#[test]
fn batches_in_memory_order_answer_each_ray_as_the_one_ray_calls() {
    let mut mesh = procedural::sphere([0.0; 3], 1.0, 24, 32);
    mesh.triangles.extend(procedural::soup(5, 3000, 2.5, 0.2).triangles);
    let (scene, _) = scene_of(&mesh, BuildParams::auto());
    let (lo, hi) = bounds(&mesh);
    let mut incoherent = random_rays(11, 20_000, lo, hi);
    for (i, r) in incoherent.iter_mut().enumerate().step_by(97) {
        match i % 4 {
            0 => r.origin.x = f32::NAN,
            1 => r.dir = Vec3::ZERO,
            2 => (r.tmin, r.tmax) = (2.0, 1.0),
            _ => r.dir.y = if i % 8 == 3 { 0.0 } else { -0.0 },
        }
    }
    let camera: Vec<Ray> = (0..128 * 128)
        .map(|i| {
            let (x, y) = ((i % 128) as f32 / 64.0 - 1.0, (i / 128) as f32 / 64.0 - 1.0);
            Ray::new(Vec3::new(0.3, 0.2, 4.0), Vec3::new(x, y, -2.0).normalize())
        })
        .collect();
    // The scene is small: in memory order only when asked.
    assert!(scene.tracer().memory_order(&incoherent).is_none(), "a scene in the cache, as given");
    let tracer = scene.tracer().with_memory_order(MemoryOrder::Incoherent);
    assert!(tracer.memory_order(&incoherent).is_some(), "random rays are sorted");
    assert!(tracer.memory_order(&camera).is_none(), "camera rays are walked as given");
    assert!(tracer.memory_order(&incoherent[..4000]).is_none(), "short batches as given");
    for (name, rays) in [("incoherent", &incoherent), ("camera", &camera)] {
        let nearest: Vec<_> = rays.iter().map(|r| tracer.intersect(r)).collect();
        let any: Vec<_> = rays.iter().map(|r| tracer.occluder(r)).collect();
        let occluded: Vec<_> = rays.iter().map(|r| tracer.occluded(r)).collect();
        let hit = nearest.iter().filter(|h| h.is_some()).count();
        assert!(hit > rays.len() / 20, "{name}: {hit} of {} rays hit", rays.len());
        for t in [tracer.clone(), tracer.clone().with_memory_order(MemoryOrder::Off), scene.tracer()] {
            let mut hits = vec![None; rays.len()];
            let mut flags = vec![false; rays.len()];
            t.intersect_batch(rays, &mut hits);
            assert_eq!(hits, nearest, "{name}: intersect_batch");
            hits.fill(None);
            t.par_intersect_batch(rays, &mut hits);
            assert_eq!(hits, nearest, "{name}: par_intersect_batch");
            t.occluder_batch(rays, &mut hits);
            assert_eq!(hits, any, "{name}: occluder_batch");
            hits.fill(None);
            t.par_occluder_batch(rays, &mut hits);
            assert_eq!(hits, any, "{name}: par_occluder_batch");
            t.occluded_batch(rays, &mut flags);
            assert_eq!(flags, occluded, "{name}: occluded_batch");
            flags.fill(false);
            t.par_occluded_batch(rays, &mut flags);
            assert_eq!(flags, occluded, "{name}: par_occluded_batch");
        }
    }
}

/// `leaves_visited` names the walk's leaves in order: as many as the walk counts,
/// each the face neighbour of the one before (their boxes share a plane on one axis
/// and overlap on the other two), the hit found in one of them; random rays and rays
/// in cell planes (zero direction components of both signs on every axis).
#[test]
fn leaves_visited_are_the_walks_leaves_neighbour_after_neighbour() {
    let mut mesh = procedural::sphere([0.0; 3], 1.0, 24, 32);
    mesh.triangles.extend(procedural::soup(7, 2000, 2.5, 0.2).triangles);
    let (lo, hi) = bounds(&mesh);
    let mut rays = random_rays(13, 6000, lo, hi);
    for (i, r) in rays.iter_mut().enumerate().skip(1).step_by(3) {
        let axis = i % 3;
        r.dir[axis] = if i % 2 == 0 { 0.0 } else { -0.0 };
        r.origin[axis] = 0.0; // the plane through the centre: a cell plane at every level
    }
    for params in [BuildParams::auto(), BuildParams { max_depth: Some(6), leaf_size: Some(3), ..BuildParams::auto() }] {
        let (scene, _) = scene_of(&mesh, params);
        let t = scene.tracer();
        let boxes = &scene.view().boxes;
        let b = |leaf: u32| &boxes[leaf as usize * 6..leaf as usize * 6 + 6];
        let (mut walked, mut steps) = (0, 0);
        for r in &rays {
            let leaves = t.leaves_visited(r);
            let (hit, stats) = t.intersect_with_stats(r);
            assert_eq!(leaves.len() as u32, stats.leaves, "ray {r:?}");
            if let Some(h) = hit {
                assert!(leaves.contains(&h.leaf), "hit in leaf {} not visited, ray {r:?}", h.leaf);
            }
            for pair in leaves.windows(2) {
                let (p, q) = (b(pair[0]), b(pair[1]));
                let touching = (0..3).filter(|&k| p[k + 3] == q[k] || q[k + 3] == p[k]).count();
                let overlapping = (0..3).filter(|&k| p[k] < q[k + 3] && q[k] < p[k + 3]).count();
                assert!(touching == 1 && overlapping == 2, "leaves {pair:?} are not face neighbours, ray {r:?}");
            }
            walked += !leaves.is_empty() as usize;
            steps += leaves.len();
        }
        assert!(walked > rays.len() / 4 && steps > 3 * walked, "{walked} walks, {steps} leaves");
    }
}
