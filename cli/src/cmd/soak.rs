//! `octrace soak`: many rays from inside closed meshes; every one must hit.

use std::time::Instant;

use std::path::{Path, PathBuf};

use glam::Vec3;
use octrace_bake::hard_rays::{grid_rays, GridPlanes, HardKind, Twist};
use octrace_bake::procedural::{self, ClosedSolid, SplitMix};
use octrace_bake::topology::EdgeCensus;
use octrace_bake::{bake, BuildParams};
use octrace_runtime::baselines::bvh::{Bvh, BvhBuild};
use octrace_runtime::{Ray, Scene, TriangleTest};
use serde_json::json;

use crate::output::thousands;

/// Shoot rays from inside closed meshes (a sphere, a torus, a box, a bumpy blob and a
/// room), at the origin and moved far from it (1e4; 1e7 and -3e6, scaled so that the
/// f32 grid keeps their shape), or from inside a closed mesh of yours, and count the
/// leaks: rays that hit nothing although they cannot get out. Three kinds of rays:
/// uniform random directions; rays aimed exactly at every vertex and edge midpoint
/// (the built-in solids); and rays on the octree's own planes (in cell planes with
/// +0.0 and -0.0 direction components, along cell edges, from and through cell
/// corners, on every axis, sign and level), each twisted in turn where f32 gives out:
/// zero components made the smallest subnormal or tiny numbers, origins moved a few
/// ulps off their planes, whole directions scaled from tiny to huge lengths.
/// Exits with an error if any ray leaks.
///
/// Your own mesh (a .oct scene, or a mesh file to bake first) must be closed: every
/// edge shared by an even number of triangles (it is refused, with its count of
/// boundary edges, otherwise). Origins inside it are found by counting crossings
/// along three random directions (an independent BVH, every crossing, unanimous).
#[derive(clap::Args, Debug)]
#[command(verbatim_doc_comment)]
pub(crate) struct Args {
    /// A closed mesh to soak instead of the built-in solids: a .oct scene, or a mesh
    /// to bake first.
    pub scene: Option<PathBuf>,
    /// Random rays per solid and placement (the vertex and edge rays come on top).
    #[arg(long, default_value_t = 2_000_000, value_parser = crate::output::parse_count)]
    pub rays: usize,
    /// Rays on the octree's planes per solid and placement.
    #[arg(long, default_value_t = 1_000_000, value_parser = crate::output::parse_count)]
    pub grid_rays: usize,
    /// Only the solids at the origin (not moved far from it).
    #[arg(long)]
    pub near_only: bool,
    /// Seed of the ray generators.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Use the Möller-Trumbore triangle test instead of the exact one (the default).
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
    let test = if args.moller_trumbore { TriangleTest::MollerTrumbore } else { TriangleTest::default() };
    anyhow::ensure!(!(args.gpu && args.moller_trumbore), "--moller-trumbore is a CPU knob: the kernel is watertight");
    let gpu = args.gpu.then(octrace_runtime::gpu::GpuContext::new).transpose()?;
    let placements = if args.near_only { &PLACEMENTS[..1] } else { &PLACEMENTS[..] };
    let mut rows = Vec::new();
    if let Some(path) = &args.scene {
        rows = soak_scene(path, &args, test, gpu.as_ref())?;
        return finish(&args, test, &rows);
    }
    for &(offset, scale) in placements {
        for solid in procedural::closed_solids() {
            let solid = solid.moved(offset, scale);
            let scene = Scene::from_baked(bake(&solid.mesh, &BuildParams::auto())?)?;
            let gpu_tracer =
                gpu.as_ref().map(|g| octrace_runtime::gpu::GpuTracer::new(&g.device, &g.queue, &scene)).transpose()?;
            let target = Target { label: solid.label(), triangles: solid.mesh.triangles.len() };
            let count = |kind: &'static str, rays: &mut dyn FnMut(usize, usize) -> Vec<Ray>, total: usize| {
                soak(&scene, test, gpu_tracer.as_ref(), &target, kind, rays, total)
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
    finish(&args, test, &rows)
}

/// Prints the rows; an error if any ray leaked.
fn finish(args: &Args, test: TriangleTest, rows: &[Row]) -> anyhow::Result<()> {
    print(args, test, rows)?;
    let leaks: usize = rows.iter().map(|r| r.leaks + r.gpu_leaks.unwrap_or(0)).sum();
    anyhow::ensure!(leaks == 0, "{leaks} rays leaked out of closed meshes");
    Ok(())
}

/// Origins drawn before giving up on finding one inside a mesh.
const INSIDE_TRIES: usize = 1_000_000;
/// Inside origins the random rays start from (in turn) and the grid rays are drawn
/// near.
const INSIDE_POOL: usize = 4096;

/// The soak of a closed mesh of the user's: random rays from inside and grid rays on
/// its octree's planes, each origin checked inside.
fn soak_scene(
    path: &Path,
    args: &Args,
    test: TriangleTest,
    gpu: Option<&octrace_runtime::gpu::GpuContext>,
) -> anyhow::Result<Vec<Row>> {
    let loaded = super::bench::load(path)?;
    let scene = &loaded.scene;
    let view = scene.view();
    let triangles: Vec<[[f32; 3]; 3]> = view.stored_triangles().collect();
    let census = EdgeCensus::of(&triangles);
    anyhow::ensure!(
        census.is_closed(),
        "{} is not closed: {} of its {} edges are boundary edges (used by an odd number of triangles), so rays \
         from inside can get out; soak shoots rays from inside closed meshes",
        crate::show(path),
        thousands(census.boundary),
        thousands(census.edges)
    );
    let inside = Inside::new(&triangles);
    let (lo, hi) = (view.bounds.mesh_lo, view.bounds.mesh_hi);
    let mut rng = SplitMix(args.seed);
    let mut pool = Vec::with_capacity(INSIDE_POOL);
    for _ in 0..INSIDE_TRIES {
        let p = [0, 1, 2].map(|a| lo[a] + (hi[a] - lo[a]) * rng.unit());
        if inside.contains(p) {
            pool.push(p);
            if pool.len() == INSIDE_POOL {
                break;
            }
        }
    }
    anyhow::ensure!(
        !pool.is_empty(),
        "{}: no point inside the mesh among {} drawn in its box (does it enclose a volume?)",
        crate::show(path),
        thousands(INSIDE_TRIES as u64)
    );
    let gpu_tracer = gpu.map(|g| octrace_runtime::gpu::GpuTracer::new(&g.device, &g.queue, scene)).transpose()?;
    let target = Target { label: crate::show(path).to_string(), triangles: triangles.len() };
    let seed = args.seed;
    let random = soak(
        scene,
        test,
        gpu_tracer.as_ref(),
        &target,
        "random",
        &mut |done, n| {
            let mut rng = SplitMix(seed.wrapping_add(done as u64));
            (0..n).map(|i| Ray::new(Vec3::from(pool[(done + i) % pool.len()]), unit_direction(&mut rng))).collect()
        },
        args.rays,
    )?;
    let grid = GridPlanes::of(&view);
    let hard = soak(
        scene,
        test,
        gpu_tracer.as_ref(),
        &target,
        "grid",
        &mut |done, n| {
            let point = |rng: &mut SplitMix| pool[(rng.next_u64() % pool.len() as u64) as usize];
            let rays = grid_rays(&grid, n, seed.wrapping_add(done as u64), point, None::<fn(&mut _) -> _>, |p| {
                inside.contains(p)
            });
            rays.iter().map(|r| Ray::new(Vec3::from(r.origin), Vec3::from(r.dir))).collect()
        },
        args.grid_rays,
    )?;
    Ok(vec![random, hard])
}

/// A uniform random unit direction.
fn unit_direction(rng: &mut SplitMix) -> Vec3 {
    let z = 1.0 - 2.0 * rng.unit();
    let phi = std::f32::consts::TAU * rng.unit();
    let r = (1.0 - z * z).max(0.0).sqrt();
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

/// Inside or outside a closed mesh, by the parity of the crossings along three fixed
/// random directions, counted on a BVH (code independent of the octree walk being
/// soaked): every crossing, by nearest hits one after the other. A point is inside
/// when all three counts are odd; one that the three do not agree on (a direction
/// grazing an edge), or that lies within rounding of the surface (a crossing nearer
/// than [`Inside::CLEARANCE`] of the mesh's scale: an `f32` test rounds vertices
/// relative to the origin by that much, and a ray from there may be answered on either
/// side of `t = 0`, as the oracle's ties allow), is left out as neither.
struct Inside {
    bvh: Bvh,
    directions: [Vec3; 3],
    /// The least distance to the surface (along the probes) of a point counted inside.
    clearance: f32,
}

impl Inside {
    /// Crossings counted along one direction before the count is given up.
    const MAX_CROSSINGS: usize = 1 << 16;

    /// The clearance, relative to the mesh's largest coordinate or extent: 2^6 f32
    /// spacings.
    const CLEARANCE: f32 = 1.0 / (1 << 18) as f32;

    fn new(triangles: &[[[f32; 3]; 3]]) -> Inside {
        let ids: Vec<u32> = (0..triangles.len() as u32).collect();
        let mut rng = SplitMix(0x1A51DE);
        let directions = [0; 3].map(|_| unit_direction(&mut rng));
        let points = triangles.iter().flatten();
        let (lo, hi) = points.fold(([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]), |(lo, hi), p| {
            ([0, 1, 2].map(|a| lo[a].min(p[a])), [0, 1, 2].map(|a| hi[a].max(p[a])))
        });
        let scale = (0..3).map(|a| lo[a].abs().max(hi[a].abs()).max(hi[a] - lo[a])).fold(0.0, f32::max);
        let clearance = Self::CLEARANCE * scale;
        Inside { bvh: Bvh::build(triangles, &ids, BvhBuild::SahBinned), directions, clearance }
    }

    fn contains(&self, p: [f32; 3]) -> bool {
        self.directions.iter().all(|&d| self.crossings(Vec3::from(p), d).is_some_and(|n| n % 2 == 1))
    }

    /// The crossings of the ray from `o` along `d`, or `None` for a point on the
    /// surface or past the cap.
    fn crossings(&self, o: Vec3, d: Vec3) -> Option<usize> {
        let mut tmin = 0.0f32;
        for n in 0..Self::MAX_CROSSINGS {
            match self.bvh.intersect(&Ray::segment(o, d, tmin, f32::INFINITY)) {
                Some((t, ..)) if t <= self.clearance => return None,
                Some((t, ..)) => tmin = t.next_up(),
                None => return Some(n),
            }
        }
        None
    }
}

/// What a soaked mesh is called in the table.
struct Target {
    label: String,
    triangles: usize,
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
    target: &Target,
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
        solid: target.label.clone(),
        triangles: target.triangles,
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
        let twists: Vec<&str> = Twist::ALL.iter().map(|k| k.name()).collect();
        crate::out!(
            "{}",
            serde_json::to_string_pretty(&json!({ "triangle_test": format!("{test:?}"), "grid_ray_kinds": kinds,
                                                 "grid_ray_twists": twists, "meshes": meshes }))?
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
