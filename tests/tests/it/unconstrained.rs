//! The walk through the octree without the 2:1 constraint (`runtime::unconstrained`):
//! the oracle's answers, neighbours several levels finer, no leaks.

use glam::Vec3;
use octrace_bake::octree::{build_unbalanced, Unbalanced};
use octrace_bake::{bake, procedural, BuildParams, Mesh};
use octrace_runtime::baselines::unconstrained::{UnconstrainedOctree, UnconstrainedStats};
use octrace_runtime::reference::{Agreement, Reference};
use octrace_runtime::Ray;

fn tree(mesh: &Mesh, params: &BuildParams) -> (Unbalanced, UnconstrainedOctree) {
    let t = build_unbalanced(mesh, params).unwrap();
    let tree = UnconstrainedOctree::build(t.root_lo, t.root_size, &t.leaves, &t.triangles, &t.ids);
    (t, tree)
}

/// A scene whose unconstrained tree has neighbours many levels apart: a dense small
/// sphere beside a large plane of two triangles and a sparse soup.
fn uneven_scene() -> Mesh {
    let mut m = procedural::sphere([0.3, 0.2, 0.1], 0.25, 32, 48);
    m.triangles.extend(procedural::grid(1, 4.0).triangles);
    m.triangles.extend(procedural::soup(3, 60, 3.0, 0.3).triangles);
    m.triangles.extend(procedural::torus([-0.8, 0.5, -0.4], 0.5, 0.1, 24, 12).triangles);
    m
}

/// Every ray agrees with the oracle, nearest hit and occlusion; returns the walks'
/// statistics summed (the deepest descent is the largest).
fn all_agree(name: &str, tree: &UnconstrainedOctree, oracle: &Reference, rays: &[Ray]) -> UnconstrainedStats {
    let mut bad = Vec::new();
    let mut sum = UnconstrainedStats::default();
    for r in rays {
        let (got, stats) = tree.intersect_with_stats(r);
        sum.leaves += stats.leaves;
        sum.triangle_tests += stats.triangle_tests;
        sum.descents += stats.descents;
        sum.deepest_descent = sum.deepest_descent.max(stats.deepest_descent);
        let verdict = oracle.compare(r, got);
        let occlusion_differs = tree.occluded(r) != oracle.occluded(r);
        if verdict == Agreement::Different || (occlusion_differs && verdict == Agreement::Same) {
            bad.push(format!("{r:?}: unconstrained {got:?}, oracle {:?}", oracle.intersect(r)));
        }
    }
    assert!(bad.is_empty(), "{name}: {} of {} rays disagree; first: {}", bad.len(), rays.len(), bad[0]);
    sum
}

/// Random rays from inside and outside, axis-parallel rays (zero and negative-zero
/// components), and rays along the leaves' edges and through their corners, where
/// exit tests tie and the descent's median-line tests are exactly zero.
#[test]
fn the_unconstrained_walk_agrees_with_the_oracle() {
    let mesh = uneven_scene();
    let params = BuildParams { max_depth: Some(8), leaf_size: Some(2), ..BuildParams::auto() };
    let (t, tree) = tree(&mesh, &params);
    let balanced = bake(&mesh, &params).unwrap();
    assert_eq!(tree.leaf_count() as u64, balanced.stats.leaves_before_balance);
    let constrained = balanced.view().leaves().count();
    assert!(
        tree.leaf_count() * 5 < constrained * 4,
        "the constraint adds leaves: {} → {constrained}",
        tree.leaf_count()
    );
    let oracle = Reference::in_input_order(mesh.triangles.clone());
    let mut rng = procedural::SplitMix(5);
    let mut rays = Vec::new();
    for _ in 0..6000 {
        let o = (Vec3::new(rng.unit(), rng.unit(), rng.unit()) - 0.5) * 8.0;
        let target = (Vec3::new(rng.unit(), rng.unit(), rng.unit()) - 0.5) * 2.0;
        rays.push(Ray::new(o, target - o));
        let inside = (Vec3::new(rng.unit(), rng.unit(), rng.unit()) - 0.5) * 3.0;
        rays.push(Ray::new(inside, Vec3::new(rng.unit(), rng.unit(), rng.unit()) - 0.5));
    }
    for axis in 0..3 {
        for (sign, zero) in [(1.0f32, 0.0f32), (-1.0, -0.0)] {
            for i in 0..40 {
                let mut d = [zero; 3];
                d[axis] = sign;
                let mut o = [0.0f32; 3];
                o[axis] = -4.0 * sign;
                o[(axis + 1) % 3] = -1.0 + 0.05 * i as f32;
                o[(axis + 2) % 3] = 0.2 - 0.01 * i as f32;
                rays.push(Ray::new(Vec3::from(o), Vec3::from(d)));
            }
        }
    }
    for (k, &(level, cell, _)) in t.leaves.iter().enumerate().step_by(5) {
        let b = octrace_format::layout::cell_box(t.root_lo, t.root_size, level, cell);
        let (lo, hi) = (Vec3::new(b[0], b[1], b[2]), Vec3::new(b[3], b[4], b[5]));
        rays.push(Ray::new(Vec3::new(lo.x, lo.y, -4.0), Vec3::Z));
        rays.push(Ray::new(Vec3::new(lo.x, lo.y - 1.0, lo.z - 0.5), Vec3::new(0.0, 1.0, 0.5)));
        let corner = if k % 2 == 0 { lo } else { hi };
        for d in [Vec3::new(1.0, 1.0, 1.0), Vec3::new(-0.5, 1.0, 0.25)] {
            rays.push(Ray::new(corner - 4.0 * d, d));
        }
        // Through the middle of each face: the point where the median lines cross.
        let mid = (lo + hi) * 0.5;
        rays.push(Ray::new(Vec3::new(lo.x - 3.0, mid.y, mid.z), Vec3::X));
    }
    let stats = all_agree("uneven scene", &tree, &oracle, &rays);
    assert!(stats.descents > 0, "ropes to internal nodes were followed");
    assert!(stats.deepest_descent >= 2, "a neighbour two or more levels finer was reached: {stats:?}");
    eprintln!("{} rays, {stats:?}, {} → {constrained} leaves", rays.len(), tree.leaf_count());
}

/// Rays from inside closed solids all hit: the ropes and the descent leave no gap
/// between leaves. Undefined rays are misses.
#[test]
fn closed_solids_do_not_leak_through_the_unconstrained_walk() {
    for solid in procedural::closed_solids() {
        let (_, tree) = tree(&solid.mesh, &BuildParams::auto());
        let rays = solid.leak_rays(100_000, 3);
        let leaks = rays.iter().filter(|(o, d)| tree.intersect(&Ray::new(Vec3::from(*o), Vec3::from(*d))).is_none());
        assert_eq!(leaks.count(), 0, "{}", solid.name);
    }
    let (_, tree) = tree(&uneven_scene(), &BuildParams::auto());
    for r in [
        Ray::new(Vec3::NAN, Vec3::X),
        Ray::new(Vec3::ZERO, Vec3::ZERO),
        Ray::new(Vec3::ZERO, Vec3::new(f32::INFINITY, 0.0, 0.0)),
    ] {
        assert_eq!((tree.intersect(&r), tree.occluded(&r)), (None, false), "{r:?}");
    }
}
