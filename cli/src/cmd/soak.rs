//! `octrace soak`: many rays from inside closed meshes; every one must hit.

use std::time::Instant;

use glam::Vec3;
use octrace_bake::hard_rays::{GridPlanes, HardKind};
use octrace_bake::procedural::{self, ClosedSolid};
use octrace_bake::{bake, BuildParams};
use octrace_runtime::{Ray, Scene, TriangleTest};
use serde_json::json;

use crate::output::thousands;

/// Shoot rays from inside closed meshes (a sphere, a torus, a box, a bumpy blob and a
/// room), at the origin and moved far from it (1e4; 1e7 and -3e6, scaled so that the
/// f32 grid keeps their shape), and count the leaks: rays that hit nothing although
/// they cannot get out. Three kinds of rays: uniform random directions; rays aimed
/// exactly at every vertex and edge midpoint; and rays on the octree's own planes (in
/// cell planes with +0.0 and -0.0 direction components, along cell edges, from and
/// through cell corners, on every axis, sign and level). Exits with an error if any
/// ray leaks.
#[derive(clap::Args, Debug)]
#[command(verbatim_doc_comment)]
pub(crate) struct Args {
    /// Random rays per solid and placement (the vertex and edge rays come on top).
    #[arg(long, default_value_t = 2_000_000)]
    pub rays: usize,
    /// Rays on the octree's planes per solid and placement.
    #[arg(long, default_value_t = 1_000_000)]
    pub grid_rays: usize,
    /// Only the solids at the origin (not moved far from it).
    #[arg(long)]
    pub near_only: bool,
    /// Seed of the ray generators.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Use the Möller-Trumbore triangle test instead of the watertight one.
    #[arg(long)]
    pub moller_trumbore: bool,
    /// Trace on the GPU too (Vulkan; Mesa's lavapipe without a GPU): the kernel's
    /// leaks, counted on the same rays.
    #[arg(long)]
    pub gpu: bool,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
}

/// Where the solids are shot: moved by the offset after scaling by the factor.
const PLACEMENTS: [(f64, f64); 4] = [(0.0, 1.0), (1e4, 1.0), (1e7, 1e3), (-3e6, 100.0)];

/// One solid, placement and kind of ray.
struct Row {
    solid: String,
    triangles: usize,
    kind: &'static str,
    rays: usize,
    leaks: usize,
    gpu_leaks: Option<usize>,
    mrays: f64,
    first_leak: Option<Ray>,
}

pub(crate) fn run(args: Args) -> anyhow::Result<()> {
    let test = if args.moller_trumbore { TriangleTest::MollerTrumbore } else { TriangleTest::Watertight };
    anyhow::ensure!(!(args.gpu && args.moller_trumbore), "--moller-trumbore is a CPU knob: the kernel is watertight");
    let gpu = args.gpu.then(octrace_runtime::gpu::GpuContext::new).transpose()?;
    let placements = if args.near_only { &PLACEMENTS[..1] } else { &PLACEMENTS[..] };
    let mut rows = Vec::new();
    for &(offset, scale) in placements {
        for solid in procedural::closed_solids() {
            let solid = solid.moved(offset, scale);
            let scene = Scene::from_baked(bake(&solid.mesh, &BuildParams::auto())?)?;
            let gpu_tracer =
                gpu.as_ref().map(|g| octrace_runtime::gpu::GpuTracer::new(&g.device, &g.queue, &scene)).transpose()?;
            let count = |kind: &'static str, rays: &mut dyn FnMut(usize, usize) -> Vec<Ray>, total: usize| {
                soak(&scene, test, gpu_tracer.as_ref(), &solid, kind, rays, total)
            };
            let seed = args.seed;
            rows.push(count(
                "random",
                &mut |done, n| random_rays(&solid, seed.wrapping_add(done as u64), n),
                args.rays,
            )?);
            let grid = GridPlanes::of(&scene.view());
            rows.push(count(
                "grid",
                &mut |done, n| {
                    let hard = solid.grid_rays(&grid, n, seed.wrapping_add(done as u64));
                    hard.iter().map(|r| Ray::new(Vec3::from(r.origin), Vec3::from(r.dir))).collect()
                },
                args.grid_rays,
            )?);
        }
    }
    print(&args, test, &rows)?;
    let leaks: usize = rows.iter().map(|r| r.leaks + r.gpu_leaks.unwrap_or(0)).sum();
    anyhow::ensure!(leaks == 0, "{leaks} rays leaked out of closed meshes");
    Ok(())
}

/// `n` random rays from inside `solid`, and, for the first batch, the rays at every
/// vertex and edge midpoint.
fn random_rays(solid: &ClosedSolid, seed: u64, n: usize) -> Vec<Ray> {
    solid.leak_rays(n, seed).iter().map(|(o, d)| Ray::new(Vec3::from(*o), Vec3::from(*d))).collect()
}

/// Traces `total` rays that `make(done, n)` gives in batches (so that ten million rays
/// need not sit in memory at once) and counts those that hit nothing.
fn soak(
    scene: &Scene,
    test: TriangleTest,
    gpu: Option<&octrace_runtime::gpu::GpuTracer>,
    solid: &ClosedSolid,
    kind: &'static str,
    make: &mut dyn FnMut(usize, usize) -> Vec<Ray>,
    total: usize,
) -> anyhow::Result<Row> {
    let tracer = scene.tracer().with_triangle_test(test);
    let batch = 1 << 20;
    let (mut done, mut rays_done, mut leaks, mut gpu_leaks) = (0, 0, 0, 0);
    let mut first_leak = None;
    let mut seconds = 0.0;
    while done < total || done == 0 {
        let n = batch.min(total - done);
        let mut rays = make(done, n);
        if done > 0 {
            rays.truncate(n); // the vertex and edge rays only once
        }
        let t = Instant::now();
        let mut hits = vec![None; rays.len()];
        tracer.par_intersect_batch(&rays, &mut hits);
        seconds += t.elapsed().as_secs_f64();
        for (r, h) in rays.iter().zip(&hits) {
            if h.is_none() {
                leaks += 1;
                first_leak.get_or_insert(*r);
            }
        }
        if let Some(gpu) = gpu {
            for (r, h) in rays.iter().zip(gpu.intersect(&rays)?) {
                if h.is_none() {
                    gpu_leaks += 1;
                    first_leak.get_or_insert(*r);
                }
            }
        }
        rays_done += rays.len();
        done += n.max(1);
    }
    Ok(Row {
        solid: solid.label(),
        triangles: solid.mesh.triangles.len(),
        kind,
        rays: rays_done,
        leaks,
        gpu_leaks: gpu.map(|_| gpu_leaks),
        mrays: rays_done as f64 / seconds.max(1e-9) / 1e6,
        first_leak,
    })
}

fn print(args: &Args, test: TriangleTest, rows: &[Row]) -> anyhow::Result<()> {
    if args.json {
        let meshes: Vec<_> = rows
            .iter()
            .map(|r| {
                json!({ "mesh": r.solid, "triangles": r.triangles, "rays_kind": r.kind, "rays": r.rays,
                        "leaks": r.leaks, "gpu_leaks": r.gpu_leaks, "mrays_per_s": r.mrays,
                        "first_leak": r.first_leak.map(|r| format!("{r:?}")) })
            })
            .collect();
        let kinds: Vec<&str> = HardKind::ALL.iter().map(|k| k.name()).collect();
        crate::out!(
            "{}",
            serde_json::to_string_pretty(&json!({ "triangle_test": format!("{test:?}"), "grid_ray_kinds": kinds,
                                                 "meshes": meshes }))?
        );
        return Ok(());
    }
    for r in rows {
        crate::out!(
            "{:<16} {} triangles, {:<6} rays: {}, {} leaks{} ({:.2} Mrays/s){}",
            r.solid,
            thousands(r.triangles as u64),
            r.kind,
            thousands(r.rays as u64),
            r.leaks,
            r.gpu_leaks.map_or(String::new(), |g| format!(", {g} on the GPU")),
            r.mrays,
            r.first_leak.map_or(String::new(), |l| format!("; first leak {l:?}"))
        );
    }
    Ok(())
}
