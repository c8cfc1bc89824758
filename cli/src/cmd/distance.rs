//! `octrace distance`: the nearest point of the surface to each point, its distance
//! (signed with `--signed`), exact.

use std::path::PathBuf;
use std::time::Instant;

use octrace_runtime::reference::{InsideReference, Reference, Side};
use octrace_runtime::ClosestPoint;
use rayon::prelude::*;
use serde_json::json;

use super::contains::{read_points, stored_triangles};
use crate::output::{counted, thousands};

/// `octrace distance`'s arguments; the formats are in its long help.
#[derive(clap::Args, Debug)]
#[command(after_long_help = concat!("\
POINTS.bin: little-endian, no header, 12 bytes a point, f32 `x y z` (`octrace points`
writes the standard sets).
OUT: 28 bytes a point, in point order, little-endian: f32 distance (negative inside
with --signed; inf where none lies within --max-distance, -inf for such a point
inside), f32 `x y z` of the nearest point (NaN for none), u32 input triangle
(4294967295 for none), f32 `u v`, the point's barycentrics on the triangle's second
and third vertices.

A scene description (a .json file, as `trace` takes) in place of the .oct answers
through its world of instances: each instance searched in its own space, the point
carried back in f64 (the distance within the rounding of the carried point); OUT then
has 32 bytes a point, the instance (u32, 4294967295 for none) before the triangle.
--signed signs by the exact inside of its closed instances; its placements must scale
distances evenly (rotations, mirrors, uniform scales, translations).

The distance is exact: the distance from the point to the stored (f32) triangles,
correctly rounded to f32; the triangle is the nearest, the lowest input index of
equally near ones. --signed takes the sign from the exact inside/outside of a closed
scene (`octrace contains`). An open scene has no inside: its sign is its generalized
winding number's (inside where above 1/2, libigl's rule, decided with certainty), or
with --vote K the majority of K rays' crossing parities, approximately, as Open3D's
compute_signed_distance(nsamples=K).

--check compares every answer with the brute-force oracle (every triangle in f64, by
another construction; signs by the exact inside/outside oracle) and fails if any
differs: a distance more than half an f32 rounding from the oracle's, a triangle
farther than the oracle's nearest, a wrong sign (exact signs only: a vote's are
approximate). The oracle is much slower: a few thousand points for a large mesh.

", mapped_scene_help!()))]
pub(crate) struct Args {
    /// The .oct scene, or a world as `trace` takes (a scene description or an
    /// instanced file; see below).
    pub scene: PathBuf,
    /// Input points (12 bytes each).
    #[arg(long)]
    pub points: PathBuf,
    /// Output answers (28 bytes each); `-` writes them to standard output (the summary
    /// then goes to standard error). Never one of the inputs.
    #[arg(short = 'o', long = "output", visible_alias = "out")]
    pub out: PathBuf,
    /// Negative inside: the exact inside/outside of a closed scene; an open one's
    /// winding number above 1/2 (or --vote).
    #[arg(long)]
    pub signed: bool,
    /// With --signed, sign an open scene's distances by a majority of K rays' parities
    /// (odd K, 1 to 99).
    #[arg(long, value_name = "K", requires = "signed")]
    pub vote: Option<u32>,
    /// Answer only points within this distance of the surface (faster); others get
    /// infinity.
    #[arg(long, value_name = "D", default_value_t = f32::INFINITY)]
    pub max_distance: f32,
    /// Compare with the brute-force oracle; fail on any difference.
    #[arg(long)]
    pub check: bool,
    /// Threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Print the summary as JSON.
    #[arg(long)]
    pub json: bool,
}

/// A point's record in the output.
fn record(near: &Option<ClosestPoint>, distance: f32) -> [u32; 7] {
    match near {
        Some(c) => [
            distance.to_bits(),
            c.point[0].to_bits(),
            c.point[1].to_bits(),
            c.point[2].to_bits(),
            c.triangle,
            c.u.to_bits(),
            c.v.to_bits(),
        ],
        None => {
            let nan = f32::NAN.to_bits();
            [distance.to_bits(), nan, nan, nan, u32::MAX, 0, 0]
        }
    }
}

pub(crate) fn run(args: Args) -> anyhow::Result<()> {
    crate::output::refuse_overwriting(&args.out, "-o", &[&args.scene, &args.points])?;
    check_max_distance(args.max_distance)?;
    if let Some(k) = args.vote {
        anyhow::ensure!(k % 2 == 1 && k <= 99, "--vote must be odd, from 1 to 99 (a majority of K rays): {k}");
    }
    let to_stdout = crate::output::is_stdout(&args.out);
    let scene = crate::open::open_scene(&args.scene)?;
    let points = read_points(&args.points)?;
    let threads = args.threads.unwrap_or_else(rayon::current_num_threads);
    let closed = scene.edges().is_closed();
    let (near, inside, seconds) = crate::with_threads(args.threads, || -> anyhow::Result<_> {
        // The search's bounds (and the inside labels) are made once, before the clock.
        scene.surface_bounds()?;
        if args.signed && closed {
            scene.solid()?;
        } else if args.signed && args.vote.is_none() {
            scene.winding_tree()?;
        }
        let t = Instant::now();
        let near = scene.closest_points_batch(&points, args.max_distance)?;
        let inside = match (args.signed, args.vote) {
            (false, _) => None,
            (true, Some(k)) if !closed => {
                let mut inside = octrace_format::memory::try_vec(points.len(), "inside answers")?;
                scene.tracer().par_contains_by_vote(&points, k as usize, &mut inside);
                Some(inside)
            }
            (true, None) if !closed => Some(scene.inside_by_winding(&points)?),
            (true, _) => Some(scene.contains_batch(&points)?),
        };
        Ok((near, inside, t.elapsed().as_secs_f64()))
    })??;
    let distances: Vec<f32> = near
        .iter()
        .enumerate()
        .map(|(i, c)| {
            let d = c.map_or(f32::INFINITY, |c| c.distance);
            inside.as_ref().map_or(d, |inside| octrace_runtime::cpu::signed(d, inside[i]))
        })
        .collect();
    let out: Vec<[u32; 7]> = near.iter().zip(&distances).map(|(c, &d)| record(c, d)).collect();
    crate::output::write_data(&args.out, &[bytemuck::cast_slice(&out)])?;
    let answered = near.iter().filter(|c| c.is_some()).count() as u64;
    let inside_count = distances.iter().filter(|d| d.is_sign_negative()).count() as u64;
    let mut check = None;
    if args.check {
        // A vote's signs are approximate by design: only exact signs are checked.
        let exact_signs = if closed { inside.as_deref() } else { None };
        check = Some(against_the_oracle(&scene, &points, &near, exact_signs, args.max_distance, args.threads)?);
    }
    let rate = points.len() as f64 / seconds.max(1e-9) / 1e6;
    let how = match (args.signed, args.vote) {
        (false, _) => "unsigned",
        (true, Some(_)) if !closed => "signed by a vote",
        (true, None) if !closed => "signed by the winding number",
        (true, _) => "signed, exact",
    };
    if args.json {
        let mut j = json!({
            "points": points.len(), "answered": answered, "seconds": seconds, "mpoints_per_s": rate,
            "threads": threads, "answer": how,
            "max_distance": if args.max_distance.is_finite() { json!(args.max_distance) } else { json!("inf") },
        });
        if args.signed {
            j["inside"] = json!(inside_count);
        }
        if let Some(c) = &check {
            j["check"] = json!({ "compared": c.compared, "wrong": c.wrong.len(),
                "first_wrong": c.wrong.first().map(|(i, why)| json!({ "index": i, "point": points[*i], "why": why })) });
        }
        crate::report!(to_stdout, "{j}");
    } else {
        if let Some(c) = &check {
            crate::report!(
                to_stdout,
                "check against the brute-force oracle: {} compared, {} wrong",
                thousands(c.compared),
                thousands(c.wrong.len() as u64)
            );
        }
        let signed = if args.signed { format!(", {} inside", thousands(inside_count)) } else { String::new() };
        crate::report!(
            to_stdout,
            "{}, {} within reach{signed}, {rate:.3} M points/s ({how}; {})",
            counted(points.len() as u64, "point"),
            thousands(answered),
            counted(threads as u64, "thread")
        );
    }
    if let Some((i, why)) = check.as_ref().and_then(|c| c.wrong.first()) {
        anyhow::bail!(
            "{} points answered unlike the oracle; the first, point {i} {:?}: {why}",
            thousands(check.as_ref().map_or(0, |c| c.wrong.len()) as u64),
            points[*i]
        );
    }
    Ok(())
}

/// `distance` of a scene description (a world of instances, `crate::world_file`):
/// 32 bytes a point (distance, point, instance, triangle, `u v`).
pub(crate) fn run_world(args: Args) -> anyhow::Result<()> {
    anyhow::ensure!(
        args.vote.is_none() && !args.check,
        "{}: a scene description is answered exactly, signed by its closed instances (--vote and --check take \
         a .oct)",
        args.scene.display()
    );
    crate::output::refuse_overwriting(&args.out, "-o", &[&args.scene, &args.points])?;
    check_max_distance(args.max_distance)?;
    let to_stdout = crate::output::is_stdout(&args.out);
    let (world, scenes) = crate::world_file::open_world(&args.scene)?;
    let points = read_points(&args.points)?;
    let threads = args.threads.unwrap_or_else(rayon::current_num_threads);
    let (near, inside, seconds) = crate::with_threads(args.threads, || -> anyhow::Result<_> {
        // The scenes' search trees (and the closed ones' labels) are made once, before
        // the clock.
        for scene in scenes.values() {
            scene.surface_bounds()?;
            if args.signed && scene.edges().is_closed() {
                scene.solid()?;
            }
        }
        let t = Instant::now();
        let near = world.closest_points_batch(&points, args.max_distance)?;
        let inside = args.signed.then(|| world.contains_batch(&points));
        Ok((near, inside, t.elapsed().as_secs_f64()))
    })??;
    let mut out: Vec<[u32; 8]> = Vec::with_capacity(points.len());
    let mut inside_count = 0u64;
    for (i, c) in near.iter().enumerate() {
        let d = c.map_or(f32::INFINITY, |c| c.closest.distance);
        let d = inside.as_ref().map_or(d, |inside| octrace_runtime::cpu::signed(d, inside[i]));
        inside_count += u64::from(d.is_sign_negative());
        let r = record(&c.map(|c| c.closest), d);
        let instance = c.map_or(u32::MAX, |c| c.instance);
        out.push([r[0], r[1], r[2], r[3], instance, r[4], r[5], r[6]]);
    }
    crate::output::write_data(&args.out, &[bytemuck::cast_slice(&out)])?;
    let answered = near.iter().filter(|c| c.is_some()).count() as u64;
    let rate = points.len() as f64 / seconds.max(1e-9) / 1e6;
    let how = if args.signed { "signed by the closed instances, exact" } else { "unsigned" };
    if args.json {
        let mut j = json!({
            "points": points.len(), "answered": answered, "seconds": seconds, "mpoints_per_s": rate,
            "threads": threads, "answer": how, "instances": world.len(),
            "max_distance": if args.max_distance.is_finite() { json!(args.max_distance) } else { json!("inf") },
        });
        if args.signed {
            j["inside"] = json!(inside_count);
        }
        crate::report!(to_stdout, "{j}");
    } else {
        let signed = if args.signed { format!(", {} inside", thousands(inside_count)) } else { String::new() };
        crate::report!(
            to_stdout,
            "{}, {} within reach{signed}, {} instances, {rate:.3} M points/s ({how}; {})",
            counted(points.len() as u64, "point"),
            thousands(answered),
            thousands(world.len() as u64),
            counted(threads as u64, "thread")
        );
    }
    Ok(())
}

/// `--max-distance` is a distance: not negative, not NaN.
fn check_max_distance(d: f32) -> anyhow::Result<()> {
    anyhow::ensure!(d >= 0.0, "--max-distance must be a distance, not negative or NaN: {d}");
    Ok(())
}

/// What `--check` found.
struct Check {
    compared: u64,
    /// Each wrong point's index and what was wrong.
    wrong: Vec<(usize, String)>,
}

/// Every answer against the brute force: the distance within half an f32 rounding
/// (and `f64`'s own error) of the oracle's, the triangle as near as the oracle's, the
/// sign the exact inside/outside's (where the oracle decides it).
fn against_the_oracle(
    scene: &octrace_runtime::Scene,
    points: &[[f32; 3]],
    near: &[Option<ClosestPoint>],
    inside: Option<&[bool]>,
    max_distance: f32,
    threads: Option<usize>,
) -> anyhow::Result<Check> {
    let oracle = Reference::from_view(&scene.view());
    let sides = inside.map(|_| InsideReference::new(&stored_triangles(scene)));
    let wrong: Vec<(usize, String)> = crate::with_threads(threads, || {
        points
            .par_iter()
            .enumerate()
            .filter_map(|(i, &p)| {
                let want = oracle.closest_point(p)?;
                let slack = want.distance * f64::from(f32::EPSILON) * 0.5
                    + 1e-15 * (1.0 + p.iter().fold(0.0f64, |m, c| m.max(f64::from(c.abs()))));
                let within = want.distance <= f64::from(max_distance);
                let why = match near[i] {
                    None if within && want.distance + slack < f64::from(max_distance) => {
                        Some(format!("none answered, the oracle's is at {}", want.distance))
                    }
                    None => None,
                    Some(c) if (f64::from(c.distance) - want.distance).abs() > slack => Some(format!(
                        "distance {} (triangle {}), the oracle's {}",
                        c.distance, c.triangle, want.distance
                    )),
                    Some(c) => match oracle.distance_to(p, c.triangle) {
                        Some(d) if d > want.distance + slack => Some(format!(
                            "triangle {} at {d}, the oracle's {} at {}",
                            c.triangle, want.triangle, want.distance
                        )),
                        _ => None,
                    },
                };
                let sign = match (inside, &sides) {
                    (Some(inside), Some(sides)) => match sides.side(p) {
                        Some(Side::Inside) if !inside[i] => Some("outside, the exact oracle says inside".to_string()),
                        Some(Side::Outside) if inside[i] => Some("inside, the exact oracle says outside".to_string()),
                        _ => None,
                    },
                    _ => None,
                };
                why.or(sign).map(|w| (i, w))
            })
            .collect()
    })?;
    Ok(Check { compared: points.len() as u64, wrong })
}
