//! The queries against exact arithmetic (`octrace_tests::exact`, rational, formulas of
//! its own) on the rays and points that floating point gets wrong: within ulps of
//! vertices and edges, exactly through vertices, grazing faces, along edges, in
//! coordinate planes, from far away; points at, beside and a subnormal off vertices.
//! `OCTRACE_EXACT_RAYS` sets how many of each kind a mesh gets (the audit ran
//! 10^5 a kind: `OCTRACE_EXACT_RAYS=20000 cargo test --release -p octrace-tests exact`).

use std::collections::BTreeMap;

use glam::Vec3;
use octrace_bake::procedural::{closed_solids, cube};
use octrace_bake::{bake, BuildParams, Mesh};
use octrace_runtime::cpu::{CrossingCount, Solid};
use octrace_runtime::{Ray, Scene, Tracer, TriangleTest};
use octrace_tests::exact::{exact_inside, hard, ExactOracle};
use rayon::prelude::*;

fn per_kind(default: usize) -> usize {
    std::env::var("OCTRACE_EXACT_RAYS").ok().and_then(|s| s.parse().ok()).unwrap_or(default)
}

/// The closed meshes: the leak tests' solids and a cube whose vertices have zero
/// coordinates (where subnormal neighbours live).
fn meshes() -> Vec<(String, Mesh)> {
    let mut out: Vec<(String, Mesh)> = closed_solids().into_iter().map(|s| (s.name.to_string(), s.mesh)).collect();
    out.push(("zero-cube".into(), cube([-1.0; 3], [1.0; 3], 4)));
    out
}

/// What a ray's answers got wrong.
#[derive(Default, Clone, Copy, Debug)]
struct Wrong {
    rays: usize,
    nearest: usize,
    nearest_batch: usize,
    lists: usize,
    lists_batch: usize,
    counts: usize,
    lengths: usize,
}

fn check_rays(
    name: &str,
    mesh: &Mesh,
    (tracer, solid): (&Tracer<'_>, &Solid),
    n: usize,
    report: &mut Vec<String>,
) -> usize {
    let oracle = ExactOracle::new(&mesh.triangles);
    let mut total = 0;
    for (k, kind) in hard::RAY_KINDS.iter().enumerate() {
        let rays = hard::rays(&mesh.triangles, kind, n, 0xE8AC7 + k as u64);
        let rs: Vec<Ray> = rays.iter().map(|&(o, d)| Ray::new(Vec3::from(o), Vec3::from(d))).collect();
        let mut batch = vec![None; rs.len()];
        tracer.intersect_batch(&rs, &mut batch);
        let mut counts = vec![CrossingCount::default(); rs.len()];
        tracer.count_crossings_batch(&rs, &mut counts);
        let lists = tracer.crossings_batch(&rs, usize::MAX);
        let mut lengths = vec![0.0; rs.len()];
        tracer.length_inside_batch(solid, &rs, &mut lengths);
        let wrong = rays
            .par_iter()
            .enumerate()
            .map(|(i, &(o, d))| {
                let mut w = Wrong { rays: 1, ..Wrong::default() };
                let want = oracle.nearest(o, d, 0.0, f32::INFINITY).map(|h| (h.t32, h.triangle));
                let got = tracer.intersect(&rs[i]).map(|h| (h.t, h.triangle));
                w.nearest += (got != want) as usize;
                if got != want && std::env::var_os("OCTRACE_EXACT_SHOW").is_some() {
                    eprintln!("{name} {kind} o {o:?} d {d:?}: nearest {got:?}, exact {want:?}");
                }
                w.nearest_batch += (batch[i].map(|h| (h.t, h.triangle)) != want) as usize;
                let exact = oracle.crossings(o, d, 0.0, f32::INFINITY);
                w.lengths += !length_within(&exact, tracer.length_inside(solid, &rs[i]), lengths[i]) as usize;
                let want: Vec<(f32, u32, bool)> = exact.iter().map(|h| (h.t32, h.triangle, h.enters)).collect();
                let one = tracer.all_crossings(&rs[i]);
                let got: Vec<(f32, u32, bool)> = one.iter().map(|c| (c.t, c.triangle, c.enters)).collect();
                w.lists += (got != want) as usize;
                // The batch's lists (the lanes where the processor has them): the one
                // ray's, barycentrics included.
                w.lists_batch += (lists.of(i) != one.as_slice() || got != want) as usize;
                if got != want && std::env::var_os("OCTRACE_EXACT_SHOW").is_some() {
                    eprintln!("{name} {kind} o {o:?} d {d:?}: crossings {got:?}, exact {want:?}");
                }
                let entries = want.iter().filter(|c| c.2).count() as u32;
                w.counts += (counts[i].total != want.len() as u32 || counts[i].entries != entries) as usize;
                w
            })
            .reduce(Wrong::default, |a, b| Wrong {
                rays: a.rays + b.rays,
                nearest: a.nearest + b.nearest,
                nearest_batch: a.nearest_batch + b.nearest_batch,
                lists: a.lists + b.lists,
                lists_batch: a.lists_batch + b.lists_batch,
                lengths: a.lengths + b.lengths,
                counts: a.counts + b.counts,
            });
        total += wrong.nearest + wrong.nearest_batch + wrong.lists + wrong.lists_batch + wrong.counts + wrong.lengths;
        report.push(format!(
            "{name:10} {kind:15} rays {:6}  nearest {:5}  batch {:5}  lists {:5}  batch {:5}  counts {:5}  lengths {:5}",
            wrong.rays, wrong.nearest, wrong.nearest_batch, wrong.lists, wrong.lists_batch, wrong.counts, wrong.lengths
        ));
    }
    total
}

/// Whether `one` and `batch`, a ray's `length_inside` from `t = 0` on, are within the
/// rounding the documented query allows of the exact length that the exact crossings
/// `exact` (in order) give: each crossing's distance rounded to `f32` (half an ulp of
/// the farthest distance each) and the sum's own rounding, `(crossings + 2)` ulps of
/// the farthest distance or the length, whichever is larger (the audit's criterion).
fn length_within(exact: &[octrace_tests::exact::ExactHit], one: f32, batch: f32) -> bool {
    use num_rational::BigRational;
    use num_traits::{ToPrimitive, Zero};
    // Inside where the crossings after a point are odd: from 0 if their count is odd.
    let mut inside = exact.len() % 2 == 1;
    let (mut from, mut length) = (BigRational::zero(), BigRational::zero());
    for h in exact {
        if inside {
            length += &h.t - &from;
        }
        from = h.t.clone();
        inside = !inside;
    }
    let want = length.to_f64().unwrap_or(f64::INFINITY);
    let far = exact.last().map_or(0.0, |h| h.t32.abs()).max(want.abs() as f32);
    let ulp = |x: f32| (f32::from_bits(x.to_bits() + 1) - x) as f64;
    let allowed = (exact.len() + 2) as f64 * ulp(far);
    (one as f64 - want).abs() <= allowed && one.to_bits() == batch.to_bits()
}

fn check_points(
    name: &str,
    mesh: &Mesh,
    tracer: &Tracer<'_>,
    solid: &Solid,
    n: usize,
    report: &mut Vec<String>,
) -> usize {
    let oracle = ExactOracle::new(&mesh.triangles);
    let dir = octrace_runtime::cpu::COUNT_DIRECTION;
    let mut total = 0;
    for (k, kind) in hard::POINT_KINDS.iter().enumerate() {
        let points = hard::points(&mesh.triangles, kind, n, 0x9017 + k as u64);
        let mut got = vec![false; points.len()];
        tracer.contains_batch(solid, &points, &mut got);
        let wrong: BTreeMap<usize, usize> = points
            .par_iter()
            .zip(&got)
            .map(|(&p, &g)| {
                let one = tracer.contains(solid, p);
                let want = exact_inside(&oracle, p, dir);
                BTreeMap::from([(0, (g != want) as usize), (1, (one != want) as usize)])
            })
            .reduce(BTreeMap::new, |mut a, b| {
                for (k, v) in b {
                    *a.entry(k).or_default() += v;
                }
                a
            });
        let (batch, one) = (wrong.get(&0).copied().unwrap_or(0), wrong.get(&1).copied().unwrap_or(0));
        total += batch + one;
        report.push(format!("{name:10} {kind:15} points {:5}  contains {one:5}  batch {batch:5}", points.len()));
    }
    total
}

/// The exact test (`TriangleTest::Exact`, the default) answers as exact arithmetic
/// does, ray for ray, on every kind; the watertight test's wrong answers are counted
/// beside it (the gap the exact test closes).
#[test]
fn the_exact_test_agrees_with_exact_arithmetic_on_hard_rays_and_points() {
    let n = per_kind(100);
    let (mut report, mut default_report) = (Vec::new(), Vec::new());
    let (mut wrong, mut default_wrong) = (0, 0);
    for (name, mesh) in meshes() {
        let scene = Scene::from_baked(bake(&mesh, &BuildParams::auto()).unwrap()).unwrap();
        let solid = scene.solid().expect("closed");
        let exact = scene.tracer();
        assert_eq!(exact.triangle_test(), TriangleTest::Exact, "the default");
        wrong += check_rays(&format!("{name}*"), &mesh, (&exact, solid), n, &mut report);
        wrong += check_points(&name, &mesh, &exact, solid, n, &mut report);
        let watertight = scene.tracer().with_triangle_test(TriangleTest::Watertight);
        default_wrong += check_rays(&name, &mesh, (&watertight, solid), n, &mut default_report);
    }
    eprintln!("exact test:\n{}\nwatertight test:\n{}", report.join("\n"), default_report.join("\n"));
    eprintln!("wrong answers: exact test {wrong}, watertight test {default_wrong}");
    assert_eq!(wrong, 0, "answers that differ from exact arithmetic:\n{}", report.join("\n"));
}

/// The GPU under the exact test (`GpuOptions::triangle_test`) answers as exact
/// arithmetic does on the same hard rays: nearest hits, occlusion, counts and lists,
/// its filter's decisions and the CPU's exact test for what it hands back, each
/// answer bit for bit the CPU exact tracer's (barycentrics included).
#[test]
fn the_gpu_exact_test_agrees_with_exact_arithmetic_on_hard_rays() {
    use octrace_runtime::gpu::{GpuOptions, GpuTracer};
    let Some(gpu) = octrace_tests::gpu("the_gpu_exact_test_agrees_with_exact_arithmetic_on_hard_rays") else {
        return;
    };
    let n = per_kind(100);
    let (mut report, mut wrong, mut rays_in_all, mut handed_back) = (Vec::new(), 0, 0, 0);
    for (name, mesh) in meshes() {
        let scene = Scene::from_baked(bake(&mesh, &BuildParams::auto()).unwrap()).unwrap();
        let options = GpuOptions { triangle_test: TriangleTest::Exact, ..GpuOptions::default() };
        let tracer = match GpuTracer::with_options(&gpu.device, &gpu.queue, &scene, options) {
            Ok(t) => t,
            Err(e) if !gpu.device.features().contains(octrace_runtime::gpu::wgpu::Features::SHADER_F64) => {
                eprintln!("SKIPPED: the adapter has no f64 ({e})");
                return;
            }
            Err(e) => panic!("{e}"),
        };
        let cpu = scene.tracer().with_triangle_test(TriangleTest::Exact);
        let oracle = ExactOracle::new(&mesh.triangles);
        for (k, kind) in hard::RAY_KINDS.iter().enumerate() {
            let rays = hard::rays(&mesh.triangles, kind, n, 0xE8AC7 + k as u64);
            let rs: Vec<Ray> = rays.iter().map(|&(o, d)| Ray::new(Vec3::from(o), Vec3::from(d))).collect();
            let before = tracer.rays_finished_on_cpu();
            let nearest = tracer.intersect(&rs).unwrap();
            let occluded = tracer.occluded(&rs).unwrap();
            let counts = tracer.count_crossings(&rs).unwrap();
            let lists = tracer.crossings(&rs).unwrap();
            let back = (tracer.rays_finished_on_cpu() - before) as usize;
            let mut w = Wrong::default();
            let (mut occlusion, mut not_cpus) = (0, 0);
            for (i, &(o, d)) in rays.iter().enumerate() {
                w.rays += 1;
                let want = oracle.nearest(o, d, 0.0, f32::INFINITY);
                w.nearest +=
                    (nearest[i].map(|h| (h.t, h.triangle)) != want.as_ref().map(|h| (h.t32, h.triangle))) as usize;
                occlusion += (occluded[i] != want.is_some()) as usize;
                let key = |h: Option<octrace_runtime::Hit>| {
                    h.map(|h| (h.t.to_bits(), h.triangle, h.u.to_bits(), h.v.to_bits()))
                };
                not_cpus += (key(nearest[i]) != key(cpu.intersect(&rs[i]))) as usize;
                if std::env::var_os("OCTRACE_EXACT_SHOW").is_some() && key(nearest[i]) != key(cpu.intersect(&rs[i])) {
                    eprintln!("{name} {kind} o {o:?} d {d:?}: GPU {:?}, CPU {:?}", nearest[i], cpu.intersect(&rs[i]));
                }
                let want: Vec<(f32, u32, bool)> =
                    oracle.crossings(o, d, 0.0, f32::INFINITY).iter().map(|h| (h.t32, h.triangle, h.enters)).collect();
                let got: Vec<(f32, u32, bool)> = lists.of(i).iter().map(|c| (c.t, c.triangle, c.enters)).collect();
                w.lists += (got != want) as usize;
                let entries = want.iter().filter(|c| c.2).count() as u32;
                w.counts += (counts[i].total != want.len() as u32 || counts[i].entries != entries) as usize;
                not_cpus += (lists.of(i) != cpu.all_crossings(&rs[i]).as_slice()) as usize;
            }
            wrong += w.nearest + w.lists + w.counts + occlusion + not_cpus;
            rays_in_all += 4 * rs.len();
            handed_back += back;
            report.push(format!(
                "{name:10} {kind:15} rays {:6}  nearest {:5}  occluded {occlusion:5}  lists {:5}  counts {:5}  \
                 not the CPU's {not_cpus:5}  finished on the CPU {back:6} of {}",
                w.rays,
                w.nearest,
                w.lists,
                w.counts,
                4 * rs.len()
            ));
        }
    }
    eprintln!("GPU, exact test:\n{}", report.join("\n"));
    eprintln!("wrong answers: {wrong}; {handed_back} of {rays_in_all} ray queries finished on the CPU");
    assert_eq!(wrong, 0, "GPU answers that differ from exact arithmetic or the CPU's:\n{}", report.join("\n"));
}
