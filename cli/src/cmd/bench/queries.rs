//! The queries the walk's order answers, in `bench`: every hit along a ray, crossing
//! counts, lengths inside and inside/outside of points, on the incoherent set and the
//! standard points; with Embree's (a context filter that records every hit, sorted
//! after; the same unsorted for counts; one ray a point for parity) beside them in a
//! build with the `embree` feature, timed in the same runs.

use octrace_runtime::cpu::{CrossingCount, COUNT_DIRECTION};
use octrace_runtime::raysets::{self, Frame};
use octrace_runtime::reference::{InsideReference, Side};
use octrace_runtime::{Ray, Scene, TriangleTest};
use serde_json::json;

use super::{first_counted, median_ratio, mrays_of, Spread};
use crate::output::thousands;

/// One query's figures.
pub(super) struct QueryRow {
    name: &'static str,
    /// Rays or points.
    items: usize,
    single: Spread,
    all: Spread,
    /// What the answers add up to (crossings, points inside).
    checksum: String,
    /// Embree on one thread, octrace / Embree (median of the runs' ratios), and how
    /// many answers differ from octrace's.
    peer: Option<(Spread, f64, usize)>,
    /// Calls of the exact test's integer stage in one single-thread pass.
    exact_stage: u64,
}

/// The queries' figures, and why inside/outside was left out where it was.
pub(super) struct QueryReport {
    rows: Vec<QueryRow>,
    skipped: Option<String>,
    /// Against the exact oracle (points it finds on neither side left out): points
    /// compared, octrace's wrong answers, and Embree's one-ray parity's.
    wrong: Option<(usize, usize, Option<usize>)>,
    /// Seconds to label the leaves (once a scene).
    solid_s: Option<f64>,
}

/// Embree's every-hit query, when the build has it.
#[cfg(feature = "embree")]
pub(super) type Peer<'a> = Option<&'a crate::embree::Embree>;
#[cfg(not(feature = "embree"))]
pub(super) type Peer<'a> = Option<&'a ()>;

/// The standard points: this many, uniform in the scene's box.
const POINTS: usize = 1_000_000;

/// Times the queries, `runs` times each, interleaved: octrace on one thread, Embree on
/// one thread, octrace on all threads of `pool` (`--threads`).
pub(super) fn measure(
    scene: &Scene,
    test: TriangleTest,
    rays: &[Ray],
    runs: usize,
    threads: Option<usize>,
    embree: Peer<'_>,
) -> anyhow::Result<QueryReport> {
    let tracer = scene.tracer().with_triangle_test(test);
    let n = rays.len();
    let mut rows = Vec::new();

    // Every hit, in order.
    let (mut single, mut all, mut peer) = (Vec::new(), Vec::new(), Vec::new());
    let mut ours = Default::default();
    let mut theirs: Vec<u32> = Vec::new();
    let mut stage = None;
    for _ in 0..runs {
        single.push(first_counted(&mut stage, || mrays_of(n, &mut || ours = tracer.crossings_batch(rays, usize::MAX))));
        if let Some(e) = embree {
            peer.push(mrays_of(n, &mut || theirs = every_hit_counts(e, rays, true)));
        }
        all.push(crate::with_threads(threads, || {
            mrays_of(n, &mut || ours = tracer.par_crossings_batch(rays, usize::MAX))
        })?);
    }
    let counts: Vec<u32> = (0..n).map(|i| ours.of(i).len() as u32).collect();
    rows.push(row(
        "all hits",
        n,
        single,
        all,
        peer,
        format!("{} crossings", thousands(ours.crossings.len() as u64)),
        &counts,
        &theirs,
        stage,
    ));

    // Counts alone.
    let (mut single, mut all, mut peer) = (Vec::new(), Vec::new(), Vec::new());
    let mut counts = vec![CrossingCount::default(); n];
    let mut stage = None;
    for _ in 0..runs {
        single.push(first_counted(&mut stage, || mrays_of(n, &mut || tracer.count_crossings_batch(rays, &mut counts))));
        if let Some(e) = embree {
            peer.push(mrays_of(n, &mut || theirs = every_hit_counts(e, rays, false)));
        }
        all.push(crate::with_threads(threads, || {
            mrays_of(n, &mut || tracer.par_count_crossings_batch(rays, &mut counts))
        })?);
    }
    let totals: Vec<u32> = counts.iter().map(|c| c.total).collect();
    let sum: u64 = totals.iter().map(|&c| c as u64).sum();
    let entries: u64 = counts.iter().map(|c| c.entries as u64).sum();
    let checksum = format!("{} crossings, {} entering", thousands(sum), thousands(entries));
    rows.push(row("counts", n, single, all, peer, checksum, &totals, &theirs, stage));

    // Inside/outside and lengths: closed scenes only.
    let t = std::time::Instant::now();
    let solid = match scene.solid() {
        Ok(s) => s,
        Err(e) => {
            let skipped = Some(format!("inside/outside and lengths left out: {e}"));
            return Ok(QueryReport { rows, skipped, wrong: None, solid_s: None });
        }
    };
    let solid_s = t.elapsed().as_secs_f64();
    let b = scene.view().bounds;
    let points = raysets::points(&Frame::from_bounds(b.mesh_lo, b.mesh_hi), POINTS);
    let (mut single, mut all, mut peer) = (Vec::new(), Vec::new(), Vec::new());
    let mut inside = vec![false; points.len()];
    let mut parity: Vec<u32> = Vec::new();
    let mut stage = None;
    for _ in 0..runs {
        single.push(first_counted(&mut stage, || {
            mrays_of(points.len(), &mut || tracer.contains_batch(solid, &points, &mut inside))
        }));
        if let Some(e) = embree {
            let rays: Vec<Ray> = points.iter().map(|&p| Ray::new(p.into(), COUNT_DIRECTION.into())).collect();
            peer.push(mrays_of(points.len(), &mut || parity = every_hit_counts(e, &rays, false)));
        }
        all.push(crate::with_threads(threads, || {
            mrays_of(points.len(), &mut || tracer.par_contains_batch(solid, &points, &mut inside))
        })?);
    }
    let ours: Vec<u32> = inside.iter().map(|&b| b as u32).collect();
    let theirs: Vec<u32> = parity.iter().map(|c| c % 2).collect();
    let n_inside = ours.iter().filter(|&&b| b == 1).count() as u64;
    rows.push(row(
        "inside",
        points.len(),
        single,
        all,
        peer,
        format!("{} inside", thousands(n_inside)),
        &ours,
        &theirs,
        stage,
    ));
    let wrong = against_the_oracle(scene, &points, &ours, &theirs, threads)?;

    let (mut single, mut all) = (Vec::new(), Vec::new());
    let mut lengths = vec![0.0f32; n];
    let mut stage = None;
    for _ in 0..runs {
        single.push(first_counted(&mut stage, || {
            mrays_of(n, &mut || tracer.length_inside_batch(solid, rays, &mut lengths))
        }));
        all.push(crate::with_threads(threads, || {
            mrays_of(n, &mut || tracer.par_length_inside(solid, rays, &mut lengths))
        })?);
    }
    let total: f64 = lengths.iter().map(|&l| l as f64).sum();
    let checksum = format!("total {total:.4}");
    rows.push(row("length inside", n, single, all, Vec::new(), checksum, &[], &[], stage));
    Ok(QueryReport { rows, skipped: None, wrong: Some(wrong), solid_s: Some(solid_s) })
}

/// A row, with Embree's figures where it ran and the answers that differ.
#[allow(clippy::too_many_arguments)]
fn row(
    name: &'static str,
    items: usize,
    single: Vec<f64>,
    all: Vec<f64>,
    peer: Vec<f64>,
    checksum: String,
    ours: &[u32],
    theirs: &[u32],
    exact_stage: Option<u64>,
) -> QueryRow {
    let differ = ours.iter().zip(theirs).filter(|(a, b)| a != b).count();
    let peer = (!peer.is_empty()).then(|| (Spread::of(peer.clone()), median_ratio(&single, &peer), differ));
    let exact_stage = exact_stage.unwrap_or(0);
    QueryRow { name, items, single: Spread::of(single), all: Spread::of(all), checksum, peer, exact_stage }
}

/// Embree's hit counts of each ray (its every-hit filter; sorted as for a list when
/// `sorted`, so the time is a list's).
#[cfg(feature = "embree")]
fn every_hit_counts(e: &crate::embree::Embree, rays: &[Ray], sorted: bool) -> Vec<u32> {
    let mut hits = Vec::new();
    rays.iter()
        .map(|r| {
            e.every_hit(r, &mut hits, sorted);
            hits.len() as u32
        })
        .collect()
}

#[cfg(not(feature = "embree"))]
fn every_hit_counts(_: &(), _: &[Ray], _: bool) -> Vec<u32> {
    Vec::new()
}

/// Points compared with the exact oracle, and the wrong answers of octrace's and
/// Embree's parity (`theirs`, 0 or 1 a point, empty where Embree did not run).
fn against_the_oracle(
    scene: &Scene,
    points: &[[f32; 3]],
    ours: &[u32],
    theirs: &[u32],
    threads: Option<usize>,
) -> anyhow::Result<(usize, usize, Option<usize>)> {
    use rayon::prelude::*;
    let v = scene.view();
    let triangles: Vec<[[f32; 3]; 3]> = v.stored_triangles().collect();
    let oracle = InsideReference::new(&triangles);
    let sides: Vec<Option<Side>> =
        crate::with_threads(threads, || points.par_iter().map(|&p| oracle.side(p)).collect())?;
    let (mut compared, mut wrong, mut peer_wrong) = (0, 0, 0);
    for (i, s) in sides.iter().enumerate() {
        let want = match s {
            Some(Side::Inside) => 1,
            Some(Side::Outside) => 0,
            _ => continue,
        };
        compared += 1;
        wrong += (ours[i] != want) as usize;
        peer_wrong += theirs.get(i).is_some_and(|&t| t != want) as usize;
    }
    Ok((compared, wrong, (!theirs.is_empty()).then_some(peer_wrong)))
}

impl QueryReport {
    pub(super) fn json(&self) -> serde_json::Value {
        json!({
            "rows": self.rows.iter().map(|r| json!({
                "query": r.name, "items": r.items, "octrace_single": r.single, "octrace_all_threads": r.all,
                "checksum": r.checksum, "exact_stage_calls": r.exact_stage,
                "embree_3_single": r.peer.as_ref().map(|p| json!({ "mrays": p.0, "ratio": p.1, "differ": p.2 })),
            })).collect::<Vec<_>>(),
            "skipped": self.skipped,
            "solid_s": self.solid_s,
            "oracle": self.wrong.map(|w| json!({ "compared": w.0, "octrace_wrong": w.1, "embree_wrong": w.2 })),
        })
    }

    pub(super) fn text(&self) -> String {
        let fmt = |s: &Spread| format!("{:.2} ({:.2}-{:.2})", s.median, s.min, s.max);
        let mut out = format!(
            "\nordered queries (the incoherent rays; {} points uniform in the box), M items/s:\n\
             {:<14} {:>9} {:>20} {:>20} {:>20} {:>7} {:>8}  checksum",
            thousands(POINTS as u64),
            "query",
            "items",
            "octrace 1 thread",
            "octrace all threads",
            "Embree 1 thread",
            "ratio",
            "differ"
        );
        for r in &self.rows {
            let (peer, ratio, differ) = r.peer.as_ref().map_or(("-".into(), "-".into(), "-".into()), |p| {
                (fmt(&p.0), format!("{:.2}x", p.1), thousands(p.2 as u64))
            });
            out.push_str(&format!(
                "\n{:<14} {:>9} {:>20} {:>20} {:>20} {:>7} {:>8}  {}",
                r.name,
                thousands(r.items as u64),
                fmt(&r.single),
                fmt(&r.all),
                peer,
                ratio,
                differ,
                r.checksum
            ));
        }
        let stage: Vec<String> = self.rows.iter().map(|r| format!("{} {}", r.name, thousands(r.exact_stage))).collect();
        out.push_str(&format!("\nexact integer stage, calls in one pass (0 under other tests): {}", stage.join(", ")));
        if let Some(s) = &self.skipped {
            out.push_str(&format!("\n{s}"));
        }
        if let Some((compared, wrong, peer)) = self.wrong {
            out.push_str(&format!(
                "\ninside against the exact oracle: {} points compared, octrace {} wrong{}; leaves labelled in {:.3} s",
                thousands(compared as u64),
                thousands(wrong as u64),
                peer.map_or(String::new(), |p| format!(", Embree's one-ray parity {} wrong", thousands(p as u64))),
                self.solid_s.unwrap_or(0.0)
            ));
        }
        out
    }
}
