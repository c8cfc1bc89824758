//! `octrace contains` and `octrace points`: inside or outside of points, and the
//! standard point sets.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;
use octrace_runtime::raysets::{self, Frame};
use octrace_runtime::reference::{InsideReference, Side};
use octrace_runtime::Scene;
use rayon::prelude::*;
use serde_json::json;

use crate::output::{counted, thousands};

/// `octrace contains`'s arguments; the formats are in its long help.
#[derive(clap::Args, Debug)]
#[command(after_long_help = concat!("\
POINTS.bin: little-endian, no header, 12 bytes a point, f32 `x y z` (`octrace points`
writes the standard sets).
OUT: one byte a point, in point order: 1 inside, 0 outside. With --reference: 0
outside, 1 inside, 2 on the surface, 3 undecided.

The scene must be closed (`octrace inspect` says whether it is): every edge used by an
even number of triangles. The answer is exact: a point in an empty leaf of the octree
takes the leaf's side, labelled once per group of connected empty leaves; a point
near the surface counts crossings to the nearest empty leaf along a fixed direction,
edges shared by two triangles crossed once. A point on the surface is answered as the
points just beside it along that direction, (0.5773, 0.6151, 0.5371).

--vote K answers a scene that is not closed by the majority of K rays' crossing
parities from each point: approximate (an open mesh has no inside), as Open3D's
compute_occupancy(nsamples=K) is.

--check compares every answer with the exact oracle (`InsideReference`: crossings
along the coordinate axes decided by Shewchuk's predicates, independent of the
octree) and fails if any differs; points the oracle finds on the surface, or cannot
decide, are counted apart. The oracle is much slower than the octree.

", mapped_scene_help!()))]
pub(crate) struct Args {
    /// The .oct scene, or a world as `trace` takes (a scene description or an
    /// instanced file; inside any closed instance).
    pub scene: PathBuf,
    /// Input points (12 bytes each).
    #[arg(long)]
    pub points: PathBuf,
    /// Output answers (one byte each); `-` writes them to standard output (the summary
    /// then goes to standard error). Never one of the inputs.
    #[arg(short = 'o', long = "output", visible_alias = "out")]
    pub out: PathBuf,
    /// Answer an open scene by a majority of K rays' parities (odd K, 1 to 99).
    #[arg(long, value_name = "K")]
    pub vote: Option<u32>,
    /// Write the exact oracle's answers instead (0 outside, 1 inside, 2 surface, 3
    /// undecided), timed.
    #[arg(long, conflicts_with_all = ["vote", "check"])]
    pub reference: bool,
    /// Compare with the exact oracle; fail on any difference.
    #[arg(long)]
    pub check: bool,
    /// On the GPU (Vulkan): the kernel answers the points in empty leaves, the CPU those
    /// near the surface; the same answers. Timed with the transfers.
    #[arg(long, conflicts_with_all = ["vote", "reference"])]
    pub gpu: bool,
    /// Threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Print the summary as JSON.
    #[arg(long)]
    pub json: bool,
}

/// The most points a point file may hold: 2^32 (48 GiB).
const MAX_POINTS: u64 = 1 << 32;

/// Reads a point file: 12 bytes a point, every coordinate finite.
pub(crate) fn read_points(path: &std::path::Path) -> anyhow::Result<Vec<[f32; 3]>> {
    let points: Vec<[f32; 3]> = octrace_format::read_records(path, MAX_POINTS, "point")
        .with_context(|| format!("cannot read {} (f32 x y z points)", path.display()))?;
    anyhow::ensure!(!points.is_empty(), "{}: empty file, no points", path.display());
    if let Some(i) = points.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
        anyhow::bail!("{}: point {i} is not finite: {:?}", path.display(), points[i]);
    }
    Ok(points)
}

pub(crate) fn run(args: Args) -> anyhow::Result<()> {
    crate::output::refuse_overwriting(&args.out, "-o", &[&args.scene, &args.points])?;
    if let Some(k) = args.vote {
        anyhow::ensure!(k % 2 == 1 && k <= 99, "--vote must be odd, from 1 to 99 (a majority of K rays): {k}");
    }
    let to_stdout = crate::output::is_stdout(&args.out);
    let scene = crate::open::open_scene(&args.scene)?;
    let points = read_points(&args.points)?;
    let threads = args.threads.unwrap_or_else(rayon::current_num_threads);
    if args.reference {
        let triangles = stored_triangles(&scene);
        let (sides, seconds) = crate::with_threads(args.threads, || {
            let t = Instant::now();
            let oracle = InsideReference::new(&triangles);
            let sides: Vec<Option<Side>> = points.par_iter().map(|&p| oracle.side(p)).collect();
            (sides, t.elapsed().as_secs_f64())
        })?;
        let out: Vec<u8> = sides.iter().map(|s| code(*s)).collect();
        crate::output::write_data(&args.out, &[&out])?;
        let count = |c: u8| out.iter().filter(|&&o| o == c).count() as u64;
        return summary(
            &args,
            to_stdout,
            points.len(),
            count(1),
            seconds,
            threads,
            "exact oracle",
            json!({
                "surface": count(2), "undecided": count(3),
            }),
        );
    }
    let mut how = "exact".to_string();
    let (inside, seconds) = crate::with_threads(args.threads, || -> anyhow::Result<_> {
        match args.vote {
            None if args.gpu => {
                let solid = scene.solid()?;
                let gpu = octrace_runtime::gpu::GpuContext::new()?;
                let tracer = crate::cmd::trace::gpu_tracer(&gpu, &scene)?;
                let t = Instant::now();
                let inside = tracer.contains(solid, &points)?;
                let seconds = t.elapsed().as_secs_f64();
                how = format!(
                    "exact, on the GPU with the transfers, {} of them finished on the CPU, {}",
                    thousands(tracer.rays_finished_on_cpu()),
                    gpu.describe()
                );
                Ok((inside, seconds))
            }
            None => {
                // The labels are made once, before the clock (a crossing count a group).
                scene.solid().context("--vote K answers such a scene approximately")?;
                let t = Instant::now();
                let inside = scene.contains_batch(&points)?;
                Ok((inside, t.elapsed().as_secs_f64()))
            }
            Some(k) => {
                let tracer = scene.tracer();
                let t = Instant::now();
                let mut inside = vec![false; points.len()];
                tracer.par_contains_by_vote(&points, k as usize, &mut inside);
                Ok((inside, t.elapsed().as_secs_f64()))
            }
        }
    })??;
    let out: Vec<u8> = inside.iter().map(|&b| b as u8).collect();
    crate::output::write_data(&args.out, &[&out])?;
    let n_inside = inside.iter().filter(|&&b| b).count() as u64;
    if let Some(k) = args.vote {
        how = format!("approximate, majority of {}", counted(k as u64, "ray"));
    }
    let mut extra = json!({});
    if args.check {
        let triangles = stored_triangles(&scene);
        let oracle = InsideReference::new(&triangles);
        let sides: Vec<Option<Side>> =
            crate::with_threads(args.threads, || points.par_iter().map(|&p| oracle.side(p)).collect())?;
        let (mut compared, mut surface, mut undecided, mut wrong) = (0u64, 0u64, 0u64, Vec::new());
        for (i, (s, &got)) in sides.iter().zip(&inside).enumerate() {
            match s {
                Some(Side::Surface) => surface += 1,
                None => undecided += 1,
                Some(s) => {
                    compared += 1;
                    if (*s == Side::Inside) != got {
                        wrong.push(i);
                    }
                }
            }
        }
        extra = json!({ "check": {
            "compared": compared, "wrong": wrong.len(), "surface": surface, "undecided": undecided,
            "first_wrong": wrong.first().map(|&i| json!({ "index": i, "point": points[i], "answer": inside[i] })),
        }});
        if !args.json {
            crate::report!(
                to_stdout,
                "check against the exact oracle: {} compared, {} wrong; {} on the surface, {} undecided",
                thousands(compared),
                thousands(wrong.len() as u64),
                thousands(surface),
                thousands(undecided)
            );
        }
        summary(&args, to_stdout, points.len(), n_inside, seconds, threads, &how, extra)?;
        if let Some(&i) = wrong.first() {
            anyhow::bail!(
                "{} of {} points answered unlike the exact oracle; the first, point {i} {:?}, answered {}",
                thousands(wrong.len() as u64),
                thousands(compared),
                points[i],
                if inside[i] { "inside" } else { "outside" }
            );
        }
        return Ok(());
    }
    summary(&args, to_stdout, points.len(), n_inside, seconds, threads, &how, extra)
}

/// The oracle's answer as a byte.
fn code(side: Option<Side>) -> u8 {
    match side {
        Some(Side::Outside) => 0,
        Some(Side::Inside) => 1,
        Some(Side::Surface) => 2,
        None => 3,
    }
}

pub(crate) fn stored_triangles(scene: &Scene) -> Vec<[[f32; 3]; 3]> {
    let v = scene.view();
    v.stored_triangles().collect()
}

/// Prints the summary line (or JSON, with `extra`'s fields).
/// `contains` of a scene description (a world of instances, `crate::world_file`):
/// inside some closed instance, exactly (each closed instance's own inside/outside at
/// the point carried into its space); instances of open scenes contain nothing.
pub(crate) fn run_world(args: Args) -> anyhow::Result<()> {
    anyhow::ensure!(
        args.vote.is_none() && !args.reference && !args.check && !args.gpu,
        "{}: a scene description answers inside its closed instances, exactly (--vote, --reference, --check \
         and --gpu take a .oct)",
        args.scene.display()
    );
    crate::output::refuse_overwriting(&args.out, "-o", &[&args.scene, &args.points])?;
    let to_stdout = crate::output::is_stdout(&args.out);
    let (world, scenes) = crate::world_file::open_world(&args.scene)?;
    let points = read_points(&args.points)?;
    let threads = args.threads.unwrap_or_else(rayon::current_num_threads);
    let (inside, seconds) = crate::with_threads(args.threads, || -> anyhow::Result<_> {
        // The closed scenes' labels are made once, before the clock.
        for scene in scenes.values().filter(|s| s.edges().is_closed()) {
            scene.solid()?;
        }
        let t = Instant::now();
        let inside = world.contains_batch(&points);
        Ok((inside, t.elapsed().as_secs_f64()))
    })??;
    let out: Vec<u8> = inside.iter().map(|&b| b as u8).collect();
    crate::output::write_data(&args.out, &[&out])?;
    let n_inside = inside.iter().filter(|&&b| b).count() as u64;
    let closed = scenes.values().filter(|s| s.edges().is_closed()).count();
    let how = format!(
        "exact, inside a closed instance: {}, {closed} of {} closed",
        counted(world.len() as u64, "instance"),
        counted(scenes.len() as u64, "scene")
    );
    summary(&args, to_stdout, points.len(), n_inside, seconds, threads, &how, json!({ "instances": world.len() }))
}

#[allow(clippy::too_many_arguments)]
fn summary(
    args: &Args,
    to_stdout: bool,
    points: usize,
    inside: u64,
    seconds: f64,
    threads: usize,
    how: &str,
    extra: serde_json::Value,
) -> anyhow::Result<()> {
    let rate = points as f64 / seconds.max(1e-9) / 1e6;
    if args.json {
        let mut j = json!({
            "points": points, "inside": inside, "seconds": seconds, "mpoints_per_s": rate,
            "threads": threads, "answer": how,
        });
        if let (Some(j), Some(e)) = (j.as_object_mut(), extra.as_object()) {
            j.extend(e.clone());
        }
        crate::report!(to_stdout, "{j}");
    } else {
        crate::report!(
            to_stdout,
            "{}, {} inside, {rate:.2} M points/s ({how}; {})",
            counted(points as u64, "point"),
            thousands(inside),
            counted(threads as u64, "thread")
        );
    }
    Ok(())
}

/// `octrace points`'s arguments.
#[derive(clap::Args, Debug)]
pub(crate) struct PointsArgs {
    /// The .oct scene whose box (or surface) the points are made for.
    pub scene: PathBuf,
    /// uniform: random points in the scene's box (`raysets::points`); near: random
    /// points on the surface moved off it along the normal by --distance, half on each
    /// side (`raysets::near_surface`).
    #[arg(long, value_enum, default_value_t = PointSet::Uniform)]
    pub set: PointSet,
    /// How many points: 1 to 2^27 (134,217,728).
    #[arg(long, default_value_t = 1_000_000, value_parser = crate::output::parse_count)]
    pub count: usize,
    /// For --set near: the distance from the surface, relative to the box's diagonal.
    #[arg(long, default_value_t = 1e-6)]
    pub distance: f64,
    /// The file to write (12 bytes a point, f32 `x y z`); `-` writes to standard
    /// output. Never the scene.
    #[arg(short, long)]
    pub output: PathBuf,
}

#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub(crate) enum PointSet {
    Uniform,
    Near,
}

pub(crate) fn points(args: PointsArgs) -> anyhow::Result<()> {
    crate::output::refuse_overwriting(&args.output, "-o", &[&args.scene])?;
    // The parser bounds it above (`parse_count`); the same words either way.
    anyhow::ensure!(
        args.count >= 1,
        "--count: 0 points; a run may ask for 1 to the {} (2^27)",
        crate::output::MAX_COUNT
    );
    anyhow::ensure!(
        args.distance.is_finite() && args.distance >= 0.0,
        "--distance must be finite and not negative: {}",
        args.distance
    );
    let scene = crate::open::open_scene(&args.scene)?;
    let b = scene.view().bounds;
    let frame = Frame::from_bounds(b.mesh_lo, b.mesh_hi);
    let points = match args.set {
        PointSet::Uniform => raysets::points(&frame, args.count),
        PointSet::Near => {
            let diagonal = 2.0 * frame.r;
            raysets::near_surface(&stored_triangles(&scene), args.count, args.distance * diagonal)
        }
    };
    crate::output::write_data(&args.output, &[bytemuck::cast_slice(&points)])?;
    crate::report!(
        crate::output::is_stdout(&args.output),
        "wrote {} {} points to {}",
        thousands(points.len() as u64),
        crate::output::choice(args.set),
        crate::show(&args.output)
    );
    Ok(())
}
