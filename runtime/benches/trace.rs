//! Tracing benchmarks on the standard ray sets of `bench/RAYS.md` over the
//! bunny the repository carries: `cargo bench -p octrace-runtime`.
//! `OCTRACE_BENCH_SMALL=1` traces a 64 x 64 image instead of 1024 x 1024 (for CI).
use std::sync::OnceLock;

use octrace_runtime::raysets::{self, Camera, Frame};
use octrace_runtime::{Hit, Ray, Scene, TriangleTest};

fn main() {
    divan::main();
}

fn small() -> bool {
    std::env::var_os("OCTRACE_BENCH_SMALL").is_some()
}

/// The bunny, baked once, and its primary and incoherent rays.
fn fixture() -> &'static (Scene, Vec<Ray>, Vec<Ray>) {
    static F: OnceLock<(Scene, Vec<Ray>, Vec<Ray>)> = OnceLock::new();
    F.get_or_init(|| {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../assets/bunny.obj.zst");
        let mesh = octrace_bake::Mesh::load(path).expect("the repository's bunny");
        let scene = Scene::from_baked(octrace_bake::bake(&mesh, &octrace_bake::BuildParams::auto()).unwrap()).unwrap();
        let frame = Frame::from_triangles(&mesh.triangles);
        let n = if small() { 64 } else { 1024 };
        let primary = Camera::standard_sized(&frame, n, n).rays();
        let incoherent = raysets::incoherent(&frame, (n * n) as usize);
        (scene, primary, incoherent)
    })
}

#[divan::bench(args = [TriangleTest::Watertight, TriangleTest::MollerTrumbore, TriangleTest::Exact])]
fn primary_single_thread(bencher: divan::Bencher, test: TriangleTest) {
    let (scene, rays, _) = fixture();
    let tracer = scene.tracer().with_triangle_test(test);
    let mut out: Vec<Option<Hit>> = vec![None; rays.len()];
    bencher.counter(divan::counter::ItemsCount::new(rays.len())).bench_local(|| tracer.intersect_batch(rays, &mut out));
}

#[divan::bench(args = [TriangleTest::Watertight, TriangleTest::Exact])]
fn incoherent_single_thread(bencher: divan::Bencher, test: TriangleTest) {
    let (scene, _, rays) = fixture();
    let tracer = scene.tracer().with_triangle_test(test);
    let mut out: Vec<Option<Hit>> = vec![None; rays.len()];
    bencher.counter(divan::counter::ItemsCount::new(rays.len())).bench_local(|| tracer.intersect_batch(rays, &mut out));
}

#[divan::bench]
fn primary_all_threads(bencher: divan::Bencher) {
    let (scene, rays, _) = fixture();
    bencher.counter(divan::counter::ItemsCount::new(rays.len())).bench_local(|| scene.intersect_batch(rays));
}

/// Every crossing of a quarter of the incoherent set (counted: `count_crossings_batch`,
/// the all-hits walk without the lists' memory).
#[divan::bench(args = [TriangleTest::Watertight, TriangleTest::Exact])]
fn crossings_single_thread(bencher: divan::Bencher, test: TriangleTest) {
    let (scene, _, rays) = fixture();
    let rays = &rays[..rays.len() / 4];
    let tracer = scene.tracer().with_triangle_test(test);
    let mut out = vec![octrace_runtime::cpu::CrossingCount::default(); rays.len()];
    bencher
        .counter(divan::counter::ItemsCount::new(rays.len()))
        .bench_local(|| tracer.count_crossings_batch(rays, &mut out));
}

/// [`crossings_single_thread`] walked ray by ray (no lanes): what the lanes are worth.
#[divan::bench(args = [TriangleTest::Watertight, TriangleTest::Exact])]
fn crossings_single_thread_no_lanes(bencher: divan::Bencher, test: TriangleTest) {
    let (scene, _, rays) = fixture();
    let rays = &rays[..rays.len() / 4];
    let tracer = scene.tracer().with_triangle_test(test).with_lanes(false);
    let mut out = vec![octrace_runtime::cpu::CrossingCount::default(); rays.len()];
    bencher
        .counter(divan::counter::ItemsCount::new(rays.len()))
        .bench_local(|| tracer.count_crossings_batch(rays, &mut out));
}
