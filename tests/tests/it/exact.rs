//! The queries against exact arithmetic (`octrace_tests::exact`, rational, formulas of
//! its own) on the rays and points that floating point gets wrong: within ulps of
//! vertices and edges, exactly through vertices, grazing faces, along edges, in
//! coordinate planes, from far away; points at, beside and a subnormal off vertices.
//! `OCTRACE_EXACT_RAYS` sets how many of each kind a mesh gets, and
//! `OCTRACE_EXACT_MESHES` (mesh files, comma-separated; closed ones) audits those meshes
//! instead of the built-in ones (the audit: 10^5 a kind on a skull, a CAD part
//! and a scan, `BENCHMARKS.md` gives the command).

use std::collections::BTreeMap;

use glam::Vec3;
use octrace_bake::procedural::{closed_solids, cube};
use octrace_bake::{bake, BuildParams, Mesh};
use octrace_runtime::cpu::{CrossingCount, Solid};
use octrace_runtime::{Ray, Scene, Tracer, TriangleTest};
use octrace_tests::exact::{exact_inside, hard, ExactOracle};
use rayon::prelude::*;

/// Whether to run kind `kind`: every kind, or those `OCTRACE_EXACT_KINDS` names
/// (comma-separated; to reproduce an audit's finding).
fn runs_kind(kind: &str) -> bool {
    std::env::var("OCTRACE_EXACT_KINDS").map_or(true, |kinds| kinds.split(',').any(|k| k == kind))
}

fn per_kind(default: usize) -> usize {
    std::env::var("OCTRACE_EXACT_RAYS").ok().and_then(|s| s.parse().ok()).unwrap_or(default)
}

/// The closed meshes: the files `OCTRACE_EXACT_MESHES` names, else the leak tests'
/// solids and a cube whose vertices have zero coordinates (where subnormal neighbours
/// live).
fn meshes() -> Vec<(String, Mesh)> {
    if let Some(files) = audited_meshes() {
        return files;
    }
    let mut out: Vec<(String, Mesh)> = closed_solids().into_iter().map(|s| (s.name.to_string(), s.mesh)).collect();
    out.push(("zero-cube".into(), cube([-1.0; 3], [1.0; 3], 4)));
    out
}

/// The meshes of `OCTRACE_EXACT_MESHES`, by file stem, if it is set.
fn audited_meshes() -> Option<Vec<(String, Mesh)>> {
    let files = std::env::var("OCTRACE_EXACT_MESHES").ok()?;
    let load = |path: &str| {
        let name = std::path::Path::new(path).file_stem().map_or(path.into(), |s| s.to_string_lossy().into_owned());
        (name, Mesh::load(path).unwrap_or_else(|e| panic!("{path}: {e}")))
    };
    Some(files.split(',').filter(|p| !p.is_empty()).map(load).collect())
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
    occluded: usize,
    not_cpus: usize,
}

impl std::ops::Add for Wrong {
    type Output = Wrong;
    fn add(self, b: Wrong) -> Wrong {
        Wrong {
            rays: self.rays + b.rays,
            nearest: self.nearest + b.nearest,
            nearest_batch: self.nearest_batch + b.nearest_batch,
            lists: self.lists + b.lists,
            lists_batch: self.lists_batch + b.lists_batch,
            counts: self.counts + b.counts,
            lengths: self.lengths + b.lengths,
            occluded: self.occluded + b.occluded,
            not_cpus: self.not_cpus + b.not_cpus,
        }
    }
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
    for (k, kind) in hard::RAY_KINDS.iter().enumerate().filter(|(_, kind)| runs_kind(kind)) {
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
            .reduce(Wrong::default, |a, b| a + b);
        total += wrong.nearest + wrong.nearest_batch + wrong.lists + wrong.lists_batch + wrong.counts + wrong.lengths;
        report.push(format!(
            "{name:10} {kind:15} rays {:6}  nearest {:5}  batch {:5}  lists {:5}  batch {:5}  counts {:5}  lengths {:5}",
            wrong.rays, wrong.nearest, wrong.nearest_batch, wrong.lists, wrong.lists_batch, wrong.counts, wrong.lengths
        ));
    }
    total
}

/// A ray from far away (its origin moved near the scene for the walk, rounded there)
/// passing 1e-7 beside the edge two triangles share: exact arithmetic on the ray as
/// given says it crosses the second, 2.8e-7 inside it; the moved ray crossed the first
/// (found by the audit at 10^5 rays a kind, far-vertex rays at a wing nut: 1 list in
/// 10^5 wrong, 8 at the skull). Every path, the GPU's exact kernels included, answers
/// as the ray as given does.
#[test]
fn far_rays_are_decided_on_the_ray_as_given() {
    let tris = [
        [[0.37935317, 0.9502956, 2.9122145], [0.33912173, 0.5617214, 2.6394887], [0.38971922, 0.5621814, 2.6328294]],
        [[0.33912173, 0.5617214, 2.6394887], [0.37935317, 0.9502956, 2.9122145], [0.28712046, 0.95480144, 2.8944392]],
        // A third, so that the scene has room around the two (a far part of the mesh).
        [[-1.0, -1.0, -1.0], [-0.9, -1.0, -1.0], [-1.0, -0.9, -1.0]],
    ];
    let mesh = Mesh { triangles: tris.to_vec(), ..Mesh::default() };
    let scene = Scene::from_baked(bake(&mesh, &BuildParams::auto()).unwrap()).unwrap();
    let (o, d) = ([34595.234f32, 46363.543, -42844.344], [-0.4805684f32, -0.6440379, 0.5952052]);
    let oracle = ExactOracle::new(&mesh.triangles);
    let want = oracle.crossings(o, d, 0.0, f32::INFINITY);
    assert_eq!(want.iter().map(|h| (h.t32, h.triangle)).collect::<Vec<_>>(), [(71987.37, 1)]);
    let ray = Ray::new(Vec3::from(o), Vec3::from(d));
    for (lanes, v3) in [(true, true), (false, false)] {
        let tracer = scene.tracer().with_triangle_test(TriangleTest::Exact).with_lanes(lanes).with_x86_64_v3(v3);
        let hit = tracer.intersect(&ray).expect("a hit");
        assert_eq!((hit.t, hit.triangle), (71987.37, 1), "lanes {lanes}");
        let mut batch = [None];
        tracer.intersect_batch(&[ray], &mut batch);
        assert_eq!(batch[0].map(|h| (h.t, h.triangle)), Some((71987.37, 1)));
        let list: Vec<(f32, u32)> = tracer.all_crossings(&ray).iter().map(|c| (c.t, c.triangle)).collect();
        assert_eq!(list, [(71987.37, 1)], "lanes {lanes}");
        assert_eq!(tracer.crossings_batch(&[ray], usize::MAX).of(0), tracer.all_crossings(&ray).as_slice());
        assert_eq!(tracer.crossings_by_brute_force(&ray), tracer.all_crossings(&ray));
    }
    use octrace_runtime::gpu::{GpuOptions, GpuTracer};
    let Some(gpu) = octrace_tests::gpu("far_rays_are_decided_on_the_ray_as_given") else { return };
    if !gpu.device.features().contains(octrace_runtime::gpu::wgpu::Features::SHADER_F64) {
        eprintln!("SKIPPED on the GPU: the adapter has no f64");
        return;
    }
    let options = GpuOptions { triangle_test: TriangleTest::Exact, ..GpuOptions::default() };
    let tracer = GpuTracer::with_options(&gpu.device, &gpu.queue, &scene, options).unwrap();
    let hits = tracer.intersect(&[ray]).unwrap();
    assert_eq!(hits[0].map(|h| (h.t, h.triangle)), Some((71987.37, 1)));
    let lists = tracer.crossings(&[ray]).unwrap();
    assert_eq!(lists.of(0).iter().map(|c| (c.t, c.triangle)).collect::<Vec<_>>(), [(71987.37, 1)]);
}

/// A ray exactly through a vertex is one the exact test's filter cannot decide (its
/// edge functions there are exactly zero): the integer stage answers it, and
/// `exact_stage_runs` counts it (what `octrace bench` reports per set).
#[test]
fn rays_the_filter_cannot_decide_reach_the_exact_stage_and_are_counted() {
    let mesh = cube([-1.0; 3], [1.0; 3], 4);
    let scene = Scene::from_baked(bake(&mesh, &BuildParams::auto()).unwrap()).unwrap();
    let tracer = scene.tracer().with_triangle_test(TriangleTest::Exact);
    // From above, exactly through the top face's vertex (0, 0, 1) (a power-of-two
    // difference, so the direction is exact).
    let ray = Ray::new(Vec3::new(0.5, 0.25, 3.0), Vec3::new(-0.5, -0.25, -2.0));
    let before = octrace_runtime::exact_stage_runs();
    let hit = tracer.intersect(&ray).expect("the cube's top");
    assert!(octrace_runtime::exact_stage_runs() > before, "the integer stage ran");
    let oracle = ExactOracle::new(&mesh.triangles);
    let want = oracle.nearest([0.5, 0.25, 3.0], [-0.5, -0.25, -2.0], 0.0, f32::INFINITY).unwrap();
    assert_eq!((hit.t, hit.triangle), (want.t32, want.triangle));
    assert_eq!(hit.t, 1.0);
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
    for (k, kind) in hard::POINT_KINDS.iter().enumerate().filter(|(_, kind)| runs_kind(kind)) {
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
    // Files to audit (OCTRACE_EXACT_MESHES): the exact test only, against the oracle.
    let audit = std::env::var_os("OCTRACE_EXACT_MESHES").is_some();
    for (name, mesh) in meshes() {
        let scene = Scene::from_baked(bake(&mesh, &BuildParams::auto()).unwrap()).unwrap();
        let solid = scene.solid().unwrap_or_else(|e| panic!("{name}: {e}"));
        // The exact test, the default where no fan is crowded (an audited file's may be).
        let exact = scene.tracer().with_triangle_test(TriangleTest::Exact);
        wrong += check_rays(&format!("{name}*"), &mesh, (&exact, solid), n, &mut report);
        wrong += check_points(&name, &mesh, &exact, solid, n, &mut report);
        if !audit {
            assert_eq!(scene.tracer().triangle_test(), TriangleTest::Exact, "the default");
            let watertight = scene.tracer().with_triangle_test(TriangleTest::Watertight);
            default_wrong += check_rays(&name, &mesh, (&watertight, solid), n, &mut default_report);
        }
    }
    eprintln!("exact test:\n{}\nwatertight test:\n{}", report.join("\n"), default_report.join("\n"));
    if audit {
        eprintln!("wrong answers: exact test {wrong} (the watertight test not run on audited files)");
    } else {
        eprintln!("wrong answers: exact test {wrong}, watertight test {default_wrong}");
    }
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
        let solid = scene.solid().unwrap_or_else(|e| panic!("{name}: {e}"));
        let oracle = ExactOracle::new(&mesh.triangles);
        for (k, kind) in hard::RAY_KINDS.iter().enumerate() {
            let rays = hard::rays(&mesh.triangles, kind, n, 0xE8AC7 + k as u64);
            let rs: Vec<Ray> = rays.iter().map(|&(o, d)| Ray::new(Vec3::from(o), Vec3::from(d))).collect();
            let before = tracer.rays_finished_on_cpu();
            let nearest = tracer.intersect(&rs).unwrap();
            let occluded = tracer.occluded(&rs).unwrap();
            let counts = tracer.count_crossings(&rs).unwrap();
            let lists = tracer.crossings(&rs).unwrap();
            let lengths = tracer.length_inside(solid, &rs).unwrap();
            let back = (tracer.rays_finished_on_cpu() - before) as usize;
            let w = rays
                .par_iter()
                .enumerate()
                .map(|(i, &(o, d))| {
                    let mut w = Wrong { rays: 1, ..Wrong::default() };
                    let want = oracle.nearest(o, d, 0.0, f32::INFINITY);
                    w.nearest +=
                        (nearest[i].map(|h| (h.t, h.triangle)) != want.as_ref().map(|h| (h.t32, h.triangle))) as usize;
                    w.occluded += (occluded[i] != want.is_some()) as usize;
                    let key = |h: Option<octrace_runtime::Hit>| {
                        h.map(|h| (h.t.to_bits(), h.triangle, h.u.to_bits(), h.v.to_bits()))
                    };
                    let on_cpu = cpu.intersect(&rs[i]);
                    w.not_cpus += (key(nearest[i]) != key(on_cpu)) as usize;
                    if std::env::var_os("OCTRACE_EXACT_SHOW").is_some() && key(nearest[i]) != key(on_cpu) {
                        eprintln!("{name} {kind} o {o:?} d {d:?}: GPU {:?}, CPU {on_cpu:?}", nearest[i]);
                    }
                    let exact = oracle.crossings(o, d, 0.0, f32::INFINITY);
                    // The GPU's length: the CPU's bit for bit, so within the exact
                    // length's bound as the CPU's is.
                    let length = cpu.length_inside(solid, &rs[i]);
                    w.lengths += !length_within(&exact, length, lengths[i]) as usize;
                    let want: Vec<(f32, u32, bool)> = exact.iter().map(|h| (h.t32, h.triangle, h.enters)).collect();
                    let got: Vec<(f32, u32, bool)> = lists.of(i).iter().map(|c| (c.t, c.triangle, c.enters)).collect();
                    w.lists += (got != want) as usize;
                    let entries = want.iter().filter(|c| c.2).count() as u32;
                    w.counts += (counts[i].total != want.len() as u32 || counts[i].entries != entries) as usize;
                    w.not_cpus += (lists.of(i) != cpu.all_crossings(&rs[i]).as_slice()) as usize;
                    w
                })
                .reduce(Wrong::default, |a, b| a + b);
            let (occlusion, not_cpus) = (w.occluded, w.not_cpus);
            wrong += w.nearest + w.lists + w.counts + w.lengths + occlusion + not_cpus;
            rays_in_all += 5 * rs.len();
            handed_back += back;
            report.push(format!(
                "{name:10} {kind:15} rays {:6}  nearest {:5}  occluded {occlusion:5}  lists {:5}  counts {:5}  \
                 lengths {:5}  not the CPU's {not_cpus:5}  finished on the CPU {back:6} of {}",
                w.rays,
                w.nearest,
                w.lists,
                w.counts,
                w.lengths,
                5 * rs.len()
            ));
        }
    }
    eprintln!("GPU, exact test:\n{}", report.join("\n"));
    eprintln!("wrong answers: {wrong}; {handed_back} of {rays_in_all} ray queries finished on the CPU");
    assert_eq!(wrong, 0, "GPU answers that differ from exact arithmetic or the CPU's:\n{}", report.join("\n"));
}
