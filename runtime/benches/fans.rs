//! Rays through fans (`cpu/fans.rs`): a disk of `n` triangles fanned from its centre,
//! traced on one thread with and without the fans' hierarchies:
//! `cargo bench -p octrace-runtime --bench fans`. Three ray sets, from origins on the
//! sphere of twice the disk's radius around its centre: aimed at uniform points of
//! the disk's square (`random`), at points within a thousandth of the radius of the
//! centre (`near_centre`: what a camera looking at a pole sends), and at the centre
//! itself (`centre`). `OCTRACE_BENCH_SMALL=1` bakes only the 2,000-triangle disk.
use std::collections::HashMap;
use std::sync::{Mutex, OnceLock};

use glam::Vec3;
use octrace_bake::procedural::{self, SplitMix};
use octrace_bake::{bake, BuildParams};
use octrace_runtime::{Hit, Ray, Scene};

fn main() {
    divan::main();
}

const SIZES: [u32; 3] = [2_000, 20_000, 200_000];
const RAYS: usize = 4_000;

fn scene(n: u32) -> &'static Scene {
    static SCENES: OnceLock<Mutex<HashMap<u32, &'static Scene>>> = OnceLock::new();
    let mut map = SCENES.get_or_init(Default::default).lock().unwrap();
    map.entry(n).or_insert_with(|| {
        let baked = bake(&procedural::fan(n, 1.0), &BuildParams::auto()).expect("bake");
        Box::leak(Box::new(Scene::from_baked(baked).expect("scene")))
    })
}

/// The ray set `kind` (module docs).
fn rays(kind: &str) -> Vec<Ray> {
    let mut rng = SplitMix(11);
    (0..RAYS)
        .map(|_| {
            let z = 1.0 - 2.0 * rng.unit();
            let phi = std::f32::consts::TAU * rng.unit();
            let s = (1.0 - z * z).max(0.0).sqrt();
            let o = Vec3::new(s * phi.cos(), z, s * phi.sin()) * 2.0;
            let (x, y) = (rng.unit() * 2.0 - 1.0, rng.unit() * 2.0 - 1.0);
            let at = match kind {
                "random" => Vec3::new(x, 0.0, y),
                "near_centre" => Vec3::new(x, 0.0, y) * 1e-3,
                _ => Vec3::ZERO,
            };
            Ray::new(o, (at - o).normalize())
        })
        .collect()
}

fn sizes() -> &'static [u32] {
    if std::env::var_os("OCTRACE_BENCH_SMALL").is_some() {
        &SIZES[..1]
    } else {
        &SIZES
    }
}

#[divan::bench(args = sizes(), consts = [true, false], sample_count = 5, sample_size = 1)]
fn random<const FANS: bool>(bencher: divan::Bencher, n: u32) {
    run::<FANS>(bencher, n, "random");
}

#[divan::bench(args = sizes(), consts = [true, false], sample_count = 5, sample_size = 1)]
fn near_centre<const FANS: bool>(bencher: divan::Bencher, n: u32) {
    run::<FANS>(bencher, n, "near_centre");
}

#[divan::bench(args = sizes(), consts = [true, false], sample_count = 5, sample_size = 1)]
fn centre<const FANS: bool>(bencher: divan::Bencher, n: u32) {
    run::<FANS>(bencher, n, "centre");
}

fn run<const FANS: bool>(bencher: divan::Bencher, n: u32, kind: &str) {
    let scene = scene(n);
    let tracer = if FANS { scene.tracer() } else { scene.tracer().with_fans(None) };
    let rays = rays(kind);
    let mut out: Vec<Option<Hit>> = vec![None; rays.len()];
    bencher
        .counter(divan::counter::ItemsCount::new(rays.len()))
        .bench_local(|| tracer.intersect_batch(&rays, &mut out));
}
