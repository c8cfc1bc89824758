//! `octrace verify`: a file's invariants, and the octree against the f64 oracle.

use std::path::PathBuf;

use anyhow::Context;

use glam::Vec3;
use octrace_bake::hard_rays::{grid_rays, GridPlanes};
use octrace_bake::procedural::SplitMix;
use octrace_runtime::reference::{Agreement, Reference, DISTANCE_RELATIVE};
use octrace_runtime::Ray;
use rayon::prelude::*;
use serde_json::json;

use crate::output::thousands;

/// Check a baked file: every invariant of the format (a validated open; each encoded
/// texture image decoded and checked against the bake's texels, as `render` does),
/// then the octree tracer against the f64 brute-force oracle: random rays, half from inside the
/// scene's box and half from outside aimed into it, and rays on the octree's own planes
/// (in cell planes with +0.0 and -0.0 components, along cell edges, from and through
/// cell corners, aimed at the mesh's vertices). Each mismatch is printed with its ray
/// in full precision; ties within rounding (a ray starting on a triangle, a hit on a
/// triangle's edge, as the oracle sees it) are counted apart. Every hit's distance is
/// checked against the exact distance to its triangle's plane. Exits with an error on
/// any mismatch or distance beyond the bound.
#[derive(clap::Args, Debug)]
pub(crate) struct Args {
    /// The .oct scene.
    pub scene: PathBuf,
    /// Random rays to compare (the oracle tests every triangle for each).
    #[arg(long, default_value_t = 10_000, value_parser = crate::output::parse_count)]
    pub rays: usize,
    /// Rays on the octree's planes to compare (default: half of --rays).
    #[arg(long, value_parser = crate::output::parse_count)]
    pub grid_rays: Option<usize>,
    /// Seed of the ray generators.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
}

/// What one set of rays gave against the oracle.
struct Tally {
    rays: usize,
    same: usize,
    ties: usize,
    mismatches: Vec<String>,
    /// The largest |Δt| / t over the hits, and the hits beyond the distance bound.
    max_relative_error: f64,
    beyond_bound: Vec<String>,
}

pub(crate) fn run(args: Args) -> anyhow::Result<()> {
    let scene = crate::open::open_scene(&args.scene)?;
    // The images `render` would decode: one that it would refuse fails here too.
    scene.decode_textures().with_context(|| format!("{}: a texture image", crate::show(&args.scene)))?;
    let view = scene.view();
    let oracle = Reference::from_view(&view);
    let (lo, hi) = (Vec3::from(view.bounds.mesh_lo), Vec3::from(view.bounds.mesh_hi));
    let (c, e) = ((lo + hi) * 0.5, (hi - lo).max(Vec3::splat((hi - lo).max_element() * 1e-3)));
    let mut rng = SplitMix(args.seed);
    let mut unit3 = || Vec3::new(rng.unit(), rng.unit(), rng.unit()) - 0.5;
    let random: Vec<Ray> = (0..args.rays)
        .map(|i| {
            let inside = c + unit3() * e;
            if i % 2 == 0 {
                Ray::new(inside, unit3())
            } else {
                let outside = c + unit3().normalize_or(Vec3::X) * e.length() * 1.5;
                Ray::new(outside, inside - outside)
            }
        })
        .collect();
    let grid = {
        let n = args.grid_rays.unwrap_or(args.rays / 2);
        let point = |r: &mut SplitMix| (c + (Vec3::new(r.unit(), r.unit(), r.unit()) - 0.5) * e * 1.2).to_array();
        let count = view.triangle_count() as u64;
        let aim = |r: &mut SplitMix| {
            view.triangle(octrace_format::StoredIndex((r.next_u64() % count.max(1)) as u32))
                [(r.next_u64() % 3) as usize]
        };
        let hard = grid_rays(&GridPlanes::of(&view), n, args.seed, point, (count > 0).then_some(aim), |_| true);
        hard.iter().map(|r| Ray::new(Vec3::from(r.origin), Vec3::from(r.dir))).collect::<Vec<Ray>>()
    };
    let tracer = scene.tracer();
    let tally = |rays: &[Ray]| {
        let answers: Vec<_> = rays.par_iter().map(|r| tracer.intersect(r)).collect();
        let verdicts: Vec<Agreement> = rays
            .par_iter()
            .zip(&answers)
            .map(|(r, h)| oracle.compare(r, h.map(|h| (h.t, h.triangle, h.u, h.v))))
            .collect();
        let errors: Vec<Option<(f64, f64, f64)>> = rays
            .par_iter()
            .zip(&answers)
            .map(|(r, h)| {
                let h = (*h)?;
                let (err, bound) = oracle.distance_error(r, h.t, h.triangle)?;
                Some((err, bound, err / (h.t as f64).abs().max(f64::MIN_POSITIVE)))
            })
            .collect();
        let count = |a: Agreement| verdicts.iter().filter(|&&v| v == a).count();
        let show =
            |i: usize| format!("{:?}: octree {:?}, oracle {:?}", rays[i], answers[i], oracle.intersect(&rays[i]));
        Tally {
            rays: rays.len(),
            same: count(Agreement::Same),
            ties: count(Agreement::Tie),
            mismatches: (0..rays.len()).filter(|&i| verdicts[i] == Agreement::Different).map(show).collect(),
            max_relative_error: errors.iter().flatten().map(|e| e.2).fold(0.0, f64::max),
            beyond_bound: (0..rays.len()).filter(|&i| errors[i].is_some_and(|e| e.0 > e.1)).map(show).collect(),
        }
    };
    let sets = [("random", tally(&random)), ("grid", tally(&grid))];
    let wrong: usize = sets.iter().map(|(_, t)| t.mismatches.len() + t.beyond_bound.len()).sum();
    if args.json {
        let sets: Vec<_> = sets
            .iter()
            .map(|(name, t)| {
                json!({ "set": name, "rays": t.rays, "same": t.same, "ties": t.ties, "mismatches": t.mismatches,
                        "max_relative_t_error": t.max_relative_error, "beyond_distance_bound": t.beyond_bound })
            })
            .collect();
        crate::out!(
            "{}",
            serde_json::to_string_pretty(&json!({
                "file": crate::show(&args.scene), "invariants": "ok", "distance_bound_relative": DISTANCE_RELATIVE,
                "sets": sets,
            }))?
        );
    } else {
        crate::out!("{}: every invariant of the format holds", crate::show(&args.scene));
        for (name, t) in &sets {
            crate::out!(
                "{} {name} rays against the f64 oracle: {} same, {} ties within rounding, {} mismatches; \
                 max |Δt|/t {:.1e} (bound {:.1e}), {} beyond it",
                thousands(t.rays as u64),
                thousands(t.same as u64),
                thousands(t.ties as u64),
                t.mismatches.len(),
                t.max_relative_error,
                DISTANCE_RELATIVE,
                t.beyond_bound.len(),
            );
            for m in &t.mismatches {
                crate::out!("mismatch: {m}");
            }
            for m in &t.beyond_bound {
                crate::out!("distance beyond the bound: {m}");
            }
        }
    }
    anyhow::ensure!(wrong == 0, "{wrong} rays disagree with the oracle");
    Ok(())
}
