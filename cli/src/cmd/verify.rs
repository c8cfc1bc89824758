//! `octrace verify`: a file's invariants, and the octree against the f64 oracle.

use std::path::PathBuf;

use glam::Vec3;
use octrace_bake::procedural::SplitMix;
use octrace_runtime::reference::{Agreement, Reference};
use octrace_runtime::Ray;
use rayon::prelude::*;
use serde_json::json;

use crate::output::thousands;

/// Check a baked file: every invariant of the format (a validated open), then the
/// octree tracer against the f64 brute-force oracle on random rays, half from inside
/// the scene's box and half from outside aimed into it. Each mismatch is printed with
/// its ray in full precision; ties within rounding (a ray starting on a triangle, a
/// hit on a triangle's edge) are counted apart. Exits with an error on any mismatch.
#[derive(clap::Args, Debug)]
pub(crate) struct Args {
    /// The .oct scene.
    pub scene: PathBuf,
    /// Random rays to compare (the oracle tests every triangle for each).
    #[arg(long, default_value_t = 10_000)]
    pub rays: usize,
    /// Seed of the ray generator.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
}

pub(crate) fn run(args: Args) -> anyhow::Result<()> {
    let scene = crate::open::open_scene(&args.scene)?;
    let view = scene.view();
    let oracle = Reference::from_view(&view);
    let (lo, hi) = (Vec3::from(view.bounds.mesh_lo), Vec3::from(view.bounds.mesh_hi));
    let (c, e) = ((lo + hi) * 0.5, (hi - lo).max(Vec3::splat((hi - lo).max_element() * 1e-3)));
    let mut rng = SplitMix(args.seed);
    let mut unit3 = || Vec3::new(rng.unit(), rng.unit(), rng.unit()) - 0.5;
    let rays: Vec<Ray> = (0..args.rays)
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
    let tracer = scene.tracer();
    let verdicts: Vec<Agreement> =
        rays.par_iter().map(|r| oracle.compare(r, tracer.intersect(r).map(|h| (h.t, h.triangle, h.u, h.v)))).collect();
    let count = |a: Agreement| verdicts.iter().filter(|&&v| v == a).count();
    let (same, ties, wrong) = (count(Agreement::Same), count(Agreement::Tie), count(Agreement::Different));
    let mismatches: Vec<String> = rays
        .iter()
        .zip(&verdicts)
        .filter(|(_, v)| **v == Agreement::Different)
        .map(|(r, _)| format!("{r:?}: octree {:?}, oracle {:?}", tracer.intersect(r), oracle.intersect(r)))
        .collect();
    if args.json {
        crate::out!(
            "{}",
            serde_json::to_string_pretty(&json!({
                "file": crate::show(&args.scene), "invariants": "ok", "rays": rays.len(),
                "same": same, "ties": ties, "mismatches": mismatches,
            }))?
        );
    } else {
        crate::out!("{}: every invariant of the format holds", crate::show(&args.scene));
        crate::out!(
            "{} rays against the f64 oracle: {} same, {} ties within rounding, {} mismatches",
            thousands(rays.len() as u64),
            thousands(same as u64),
            thousands(ties as u64),
            wrong
        );
        for m in &mismatches {
            crate::out!("mismatch: {m}");
        }
    }
    anyhow::ensure!(wrong == 0, "{wrong} rays disagree with the oracle");
    Ok(())
}
