//! `octrace bench`: Mrays/s on the standard ray sets, against obvhs in the same run.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use octrace_runtime::raysets::{self, Frame};
use octrace_runtime::{Hit, Ray, Scene, Tracer, TriangleTest};
use serde_json::json;

use crate::output::{mb, thousands};

/// Measure tracing speed on the standard ray sets of bench/RAYS.md.
///
/// The input is a baked .oct or a mesh (baked first, and the bake timed). Each figure
/// is the median (with min and max) of --runs timed runs of tracing alone, single
/// threaded and on all threads, with a checksum (rays that hit, sum of hit distances).
/// obvhs's CWBVH, built on the same triangles, traces the same rays in the same runs,
/// interleaved, and the ratio octrace / obvhs is printed: the median of the runs'
/// ratios, each run timing octrace then obvhs on one thread back to back, which holds
/// steadier than a ratio of medians on a shared machine.
///
/// In a build with the `embree` feature, Embree 3 (fast mode) joins on one thread:
/// one ray a call (`rtcIntersect1`, `rtcOccluded1`) on every set, and 4 x 4 pixel
/// packets (`rtcIntersect16`) on the primary rays; beside it octrace's one-ray calls
/// (`Scene::intersect` / `Scene::occluded` once per ray), and the ratios. With more
/// than one thread the same is timed again on all of them: octrace's parallel batch
/// call, and both tracers' one-ray calls and Embree's packets spread over the same
/// rayon pool (chunks of 1,024 rays, or of 64 packets).
#[derive(clap::Args, Debug)]
pub(crate) struct Args {
    /// A .oct scene, or a mesh to bake first.
    pub input: PathBuf,
    /// Which ray set.
    #[arg(long, value_enum, default_value_t = SetChoice::All)]
    pub set: SetChoice,
    /// Threads for the all-threads figures (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Timed runs per figure (at least 5).
    #[arg(long, default_value_t = 5, value_parser = crate::output::parse_runs)]
    pub runs: usize,
    /// Skip the peers (obvhs; Embree too in a build with the `embree` feature).
    #[arg(long)]
    pub no_peer: bool,
    /// Trace with the Möller-Trumbore triangle test instead of the exact one (to
    /// measure what watertightness and exactness cost).
    #[arg(long, conflicts_with_all = ["exact", "watertight"])]
    pub moller_trumbore: bool,
    /// Trace with the watertight test in f32 (`TriangleTest::Watertight`, the GPU's
    /// default) instead of the exact one: to measure what exactness costs.
    #[arg(long, conflicts_with = "exact")]
    pub watertight: bool,
    /// Trace with the exact triangle test (`TriangleTest::Exact`, the CPU's default:
    /// every decision as exact arithmetic on the f32 inputs decides, distances
    /// correctly rounded), and with --gpu on the GPU too (its filter, the rays it
    /// leaves in doubt finished on the CPU; the GPU traces with the watertight test
    /// otherwise, as by default).
    #[arg(long)]
    pub exact: bool,
    /// Also trace each set on the GPU (Vulkan; Mesa's lavapipe without a GPU): the
    /// adapter, Mrays/s of the kernel alone and with the transfers, and whether every
    /// ray's answer is the CPU's.
    #[arg(long)]
    pub gpu: bool,
    /// With --gpu: trace each set this many times over in one batch (16 makes the
    /// primary set a 16M-ray batch), to measure the transfers of large batches.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=64))]
    pub gpu_repeat: u32,
    /// Skip the ordered queries (every hit, counts, inside/outside of points, lengths
    /// inside), which run with the incoherent set.
    #[arg(long)]
    pub no_queries: bool,
    /// Instead of the standard sets: the scene placed this many times in a lattice
    /// (1.2 of its extents apart, each turned about y) and traced as a world of
    /// instances (`octrace_runtime::world`), the standard camera's rays of the
    /// world's box on one thread; the world's add and commit times; Embree 3's
    /// instances of the scene beside it in a build with the `embree` feature; with
    /// --gpu, the world traced with the instances' walks on the GPU beside the CPU's
    /// batch on all cores, and whether every answer is the CPU's.
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=1_000_000))]
    pub instances: Option<u32>,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
}

#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum SetChoice {
    Primary,
    Incoherent,
    Shadow,
    All,
}

/// Median, min and max of a set of Mrays/s figures.
#[derive(Clone, Copy, Debug, serde::Serialize)]
pub(crate) struct Spread {
    pub median: f64,
    pub min: f64,
    pub max: f64,
}

impl Spread {
    fn of(mut v: Vec<f64>) -> Spread {
        v.sort_by(f64::total_cmp);
        Spread { median: v[v.len() / 2], min: v[0], max: v[v.len() - 1] }
    }
}

/// A scene ready to bench, with how long it took to get it.
pub(crate) struct Loaded {
    pub scene: Scene,
    pub bake: Option<Duration>,
    pub open_validated: Duration,
    /// None for a compressed file, which is read, never mapped.
    pub open_trusted: Option<Duration>,
    pub bytes: u64,
    _dir: Option<tempfile::TempDir>,
}

pub(crate) fn load(input: &Path) -> anyhow::Result<Loaded> {
    let (path, bake, dir) = if super::bake::is_scene(input) {
        (input.to_path_buf(), None, None)
    } else {
        let mesh = octrace_bake::Mesh::load(input)?;
        let progress = super::bake::Progress::new();
        let (scene, time) = super::bake::bake_mesh(&mesh, &octrace_bake::BuildParams::auto(), &progress)?;
        progress.finish();
        let dir = tempfile::tempdir()?;
        let path = dir.path().join("bench.oct");
        scene.write(&path, time.as_micros() as u64)?;
        (path, Some(time), Some(dir))
    };
    let t = Instant::now();
    let scene = crate::open::open_scene(&path)?;
    let open_validated = t.elapsed();
    // Validated just above: the header-only open is sound, and what apps that trust
    // their pipeline pay (compressed files cannot be mapped).
    let open_trusted = if octrace_format::is_compressed_file(&path)? {
        None
    } else {
        let t = Instant::now();
        drop(crate::open::map_scene(&path, crate::open::Trust::HeaderOnly)?);
        Some(t.elapsed())
    };
    let bytes = std::fs::metadata(&path)?.len();
    Ok(Loaded { scene, bake, open_validated, open_trusted, bytes, _dir: dir })
}

struct SetResult {
    name: &'static str,
    rays: usize,
    single: Spread,
    all: Spread,
    hits: usize,
    sum_t: f64,
    peer: Option<(Spread, usize, f64)>,
    /// octrace / obvhs: the median of the runs' ratios (each run times the two one
    /// after the other, so a slow spell of a shared machine slows both).
    ratio: Option<f64>,
    /// The answers of the last run: nearest hits, or (for occlusion) whether each
    /// ray is occluded; what the GPU's answers are compared with.
    nearest: Vec<Option<Hit>>,
    occluded: Vec<bool>,
    /// Embree and octrace's one-ray calls, when the build has Embree.
    embree: Option<EmbreeFigures>,
    /// Calls of the exact test's integer stage in one single-thread pass
    /// ([`octrace_runtime::exact_stage_runs`]): how often the filter could not decide.
    exact_stage: u64,
}

/// One thread, interleaved with octrace's batch runs: Embree one ray a call, in
/// packets (primary rays), and octrace's one-ray calls.
#[derive(Clone, Copy, Debug, serde::Serialize)]
struct EmbreeFigures {
    embree_one_ray: Spread,
    embree_packets: Option<Spread>,
    /// Embree's one-ray calls on the rays in the order octrace's batch walks them,
    /// where that is not the given order (`Tracer::memory_order`), and octrace batch /
    /// that, median of the runs'.
    embree_memory_order: Option<(Spread, f64)>,
    octrace_one_ray: Spread,
    /// Rays Embree finds hit (or occluded): the checksum's count, to compare.
    embree_hits: usize,
    /// octrace batch / Embree's best (packets where measured), median of the runs'.
    ratio_batch: f64,
    /// octrace one-ray calls / Embree one-ray calls, median of the runs'.
    ratio_one_ray: f64,
    /// octrace's and Embree's calls on all threads, where there are several.
    all_threads: Option<EmbreeAllThreads>,
}

/// octrace's parallel batch call, and octrace's and Embree's one-ray calls and
/// Embree's packets spread over the same threads (rayon, chunks of 1,024 rays or 64
/// packets).
#[derive(Clone, Copy, Debug, serde::Serialize)]
struct EmbreeAllThreads {
    threads: usize,
    octrace_batch: Spread,
    octrace_one_ray: Spread,
    embree_one_ray: Spread,
    embree_packets: Option<Spread>,
    /// octrace batch / Embree's best, median of the runs'.
    ratio_batch: f64,
    /// octrace one-ray calls / Embree one-ray calls, median of the runs'.
    ratio_one_ray: f64,
}

/// The triangle test the flags ask for.
fn args_test(args: &Args) -> TriangleTest {
    match (args.moller_trumbore, args.watertight) {
        (true, _) => TriangleTest::MollerTrumbore,
        (_, true) => TriangleTest::Watertight,
        _ => TriangleTest::Exact,
    }
}

/// How the report names a triangle test.
fn test_name(test: TriangleTest) -> &'static str {
    match test {
        TriangleTest::MollerTrumbore => "moller-trumbore",
        TriangleTest::Exact => "exact",
        TriangleTest::F64 => "f64",
        _ => "watertight",
    }
}

pub(crate) fn run(args: Args) -> anyhow::Result<()> {
    anyhow::ensure!(args.runs >= 5, "--runs must be at least 5 (medians of fewer are noise)");
    let loaded = load(&args.input)?;
    if let Some(n) = args.instances {
        return world::run(loaded, n as usize, &args);
    }
    let view = loaded.scene.view();
    let frame = Frame::from_bounds(view.bounds.mesh_lo, view.bounds.mesh_hi);
    let test = args_test(&args);
    let tracer = loaded.scene.tracer().with_triangle_test(test);
    let threads = crate::with_threads(args.threads, rayon::current_num_threads)?;
    #[cfg(feature = "obvhs")]
    let peer = (!args.no_peer).then(|| crate::peer::Peer::build(&view));
    #[cfg(not(feature = "obvhs"))]
    let peer: Option<()> = None;
    let want = |s: SetChoice| args.set == s || args.set == SetChoice::All;
    let primary = raysets::primary(&frame);
    let mut sets: Vec<(&'static str, Vec<Ray>, bool)> = Vec::new();
    if want(SetChoice::Primary) {
        sets.push(("primary", primary.clone(), false));
    }
    if want(SetChoice::Incoherent) {
        sets.push(("incoherent", raysets::incoherent(&frame, 1_000_000), false));
    }
    if want(SetChoice::Shadow) {
        let mut hits = vec![None; primary.len()];
        tracer.intersect_batch(&primary, &mut hits);
        sets.push(("shadow", raysets::shadow(&frame, |i| hits[i].map(|h| (h.t, view.triangle(h.prim)))), true));
    }
    #[cfg(feature = "embree")]
    let embree = (!args.no_peer).then(|| crate::embree::Embree::build(&view, false)).transpose()?;
    let mut results = Vec::new();
    for (name, rays, occlusion) in &sets {
        #[cfg_attr(not(feature = "embree"), allow(unused_mut))]
        let mut r = measure(name, rays, *occlusion, &tracer, peer.as_ref(), &args)?;
        #[cfg(feature = "embree")]
        if let Some(e) = &embree {
            let mut figures = embree_runs::embree_figures(e, &loaded.scene, name, rays, *occlusion, &tracer, args.runs);
            if threads > 1 {
                figures.all_threads = Some(crate::with_threads(args.threads, || {
                    embree_runs::embree_all_threads(e, &loaded.scene, name, rays, *occlusion, &tracer, args.runs)
                })?);
            }
            r.embree = Some(figures);
        }
        results.push(r);
    }
    let gpu = if args.gpu {
        Some(gpu::measure(
            &loaded.scene,
            &sets,
            &results,
            args.runs,
            (test, args.exact),
            args.gpu_repeat as usize,
            &frame,
        )?)
    } else {
        None
    };
    let queries = match sets.iter().find(|s| s.0 == "incoherent") {
        Some((_, rays, _)) if !args.no_queries => {
            #[cfg(feature = "embree")]
            let collecting = (!args.no_peer).then(|| crate::embree::Embree::build_collecting(&view)).transpose()?;
            #[cfg(feature = "embree")]
            let peer = collecting.as_ref();
            #[cfg(not(feature = "embree"))]
            let peer = None;
            Some(queries::measure(&loaded.scene, test, rays, args.runs, args.threads, peer)?)
        }
        _ => None,
    };
    #[cfg(feature = "obvhs")]
    let peer_build = peer.as_ref().map(|p| p.build_time);
    #[cfg(not(feature = "obvhs"))]
    let peer_build: Option<Duration> = None;
    report(&args, &loaded, threads, &results, peer_build, gpu.as_ref(), queries.as_ref())
}

#[cfg(feature = "obvhs")]
type PeerRef<'a> = Option<&'a crate::peer::Peer>;
#[cfg(not(feature = "obvhs"))]
type PeerRef<'a> = Option<&'a ()>;

fn measure(
    name: &'static str,
    rays: &[Ray],
    occlusion: bool,
    tracer: &Tracer<'_>,
    peer: PeerRef<'_>,
    args: &Args,
) -> anyhow::Result<SetResult> {
    let mut hits: Vec<Option<Hit>> = vec![None; rays.len()];
    let mut occluded = vec![false; rays.len()];
    let (mut single, mut all, mut peer_runs) = (Vec::new(), Vec::new(), Vec::new());
    let mrays = |d: Duration| rays.len() as f64 / d.as_secs_f64().max(1e-9) / 1e6;
    let mut peer_sum = (0usize, 0.0f64);
    let mut exact_stage = None;
    for _ in 0..args.runs {
        // Interleaved: octrace single, peer single, octrace all threads.
        let t = Instant::now();
        first_counted(&mut exact_stage, || {
            if occlusion {
                tracer.occluded_batch(rays, &mut occluded);
            } else {
                tracer.intersect_batch(rays, &mut hits);
            }
        });
        single.push(mrays(t.elapsed()));
        #[cfg(feature = "obvhs")]
        if let Some(p) = peer {
            let t = Instant::now();
            peer_sum = p.trace(rays, occlusion);
            peer_runs.push(mrays(t.elapsed()));
        }
        #[cfg(not(feature = "obvhs"))]
        let _ = (peer, &mut peer_runs, &mut peer_sum);
        let d = crate::with_threads(args.threads, || {
            let t = Instant::now();
            if occlusion {
                tracer.par_occluded_batch(rays, &mut occluded);
            } else {
                tracer.par_intersect_batch(rays, &mut hits);
            }
            t.elapsed()
        })?;
        all.push(mrays(d));
    }
    let (n, sum_t) = if occlusion { (occluded.iter().filter(|&&o| o).count(), 0.0) } else { hit_sums(&hits) };
    let ratio = (!peer_runs.is_empty() && !rays.is_empty())
        .then(|| Spread::of(single.iter().zip(&peer_runs).map(|(o, p)| o / p).collect()).median);
    Ok(SetResult {
        name,
        rays: rays.len(),
        single: Spread::of(single),
        all: Spread::of(all),
        hits: n,
        sum_t,
        peer: (!peer_runs.is_empty()).then(|| (Spread::of(peer_runs), peer_sum.0, peer_sum.1)),
        ratio,
        nearest: if occlusion { Vec::new() } else { hits },
        occluded: if occlusion { occluded } else { Vec::new() },
        embree: None,
        exact_stage: exact_stage.unwrap_or(0),
    })
}

/// `f()`, and the calls of the exact test's integer stage it made
/// ([`octrace_runtime::exact_stage_runs`]) into `count` if it holds none yet (the
/// first of a query's passes: each pass makes the same calls).
pub(crate) fn first_counted<T>(count: &mut Option<u64>, f: impl FnOnce() -> T) -> T {
    let before = octrace_runtime::exact_stage_runs();
    let out = f();
    count.get_or_insert(octrace_runtime::exact_stage_runs() - before);
    out
}

/// Mrays/s of `f`, which traces `rays` rays (or answers as many points).
fn mrays_of(rays: usize, f: &mut dyn FnMut()) -> f64 {
    let t = Instant::now();
    f();
    rays as f64 / t.elapsed().as_secs_f64().max(1e-9) / 1e6
}

/// The median of the runs' ratios `a / b`.
fn median_ratio(a: &[f64], b: &[f64]) -> f64 {
    Spread::of(a.iter().zip(b).map(|(x, y)| x / y).collect()).median
}

/// Rays that hit and the sum of their distances (`+ 0.0`: an empty sum is -0.0).
fn hit_sums(hits: &[Option<Hit>]) -> (usize, f64) {
    (hits.iter().flatten().count(), hits.iter().flatten().map(|h| h.t as f64).sum::<f64>() + 0.0)
}

fn report(
    args: &Args,
    l: &Loaded,
    threads: usize,
    results: &[SetResult],
    peer_build: Option<Duration>,
    gpu: Option<&gpu::GpuReport>,
    queries: Option<&queries::QueryReport>,
) -> anyhow::Result<()> {
    let secs = |d: Duration| d.as_secs_f64();
    if args.json {
        let sets: Vec<_> = results
            .iter()
            .map(|r| {
                json!({
                    "set": r.name, "rays": r.rays,
                    "mrays_single": r.single, "mrays_all_threads": r.all,
                    "hits": r.hits, "sum_t": r.sum_t,
                    "obvhs_cwbvh_single": r.peer.map(|p| json!({ "mrays": p.0, "hits": p.1, "sum_t": p.2 })),
                    "ratio_single": r.ratio,
                    "embree_3_fast_single": r.embree,
                    "exact_stage_calls": r.exact_stage,
                })
            })
            .collect();
        crate::out!(
            "{}",
            serde_json::to_string_pretty(&json!({
                "input": crate::show(&args.input), "threads": threads, "runs": args.runs,
                "triangle_test": test_name(args_test(args)),
                "bake_s": l.bake.map(secs), "open_validated_s": secs(l.open_validated),
                "open_trusted_s": l.open_trusted.map(secs), "bytes": l.bytes,
                "obvhs_build_s": peer_build.map(secs), "sets": sets,
                "gpu": gpu.map(gpu::GpuReport::json),
                "queries": queries.map(queries::QueryReport::json),
            }))?
        );
        return Ok(());
    }
    crate::out!(
        "{}: {}{}, open {:.1} ms validated / {} header only; {} triangle test; {}, median (min-max) of {} runs",
        crate::show(&args.input),
        mb(l.bytes),
        l.bake.map_or(String::new(), |b| format!(", baked in {:.2} s", b.as_secs_f64())),
        l.open_validated.as_secs_f64() * 1e3,
        l.open_trusted.map_or("n/a (compressed)".into(), |d| format!("{:.3} ms", d.as_secs_f64() * 1e3)),
        test_name(args_test(args)),
        crate::output::counted(threads as u64, "thread"),
        args.runs
    );
    if let Some(b) = peer_build {
        crate::out!("obvhs CWBVH (medium build) built in {:.2} s", b.as_secs_f64());
    }
    crate::out!(
        "{:<11} {:>9} {:>22} {:>22} {:>22} {:>7}  checksum",
        "set",
        "rays",
        "octrace 1 thread",
        "octrace all threads",
        "obvhs 1 thread",
        "ratio"
    );
    let fmt = |s: &Spread| format!("{:.2} ({:.2}-{:.2})", s.median, s.min, s.max);
    for r in results {
        let peer = r.peer.map_or("-".into(), |p| fmt(&p.0));
        let ratio = r.ratio.map_or("-".into(), |q| format!("{q:.2}x"));
        let check = checksum(r.name, r.hits, r.sum_t);
        let peer_check = r.peer.map_or(String::new(), |p| format!(" (obvhs {})", thousands(p.1 as u64)));
        crate::out!(
            "{:<11} {:>9} {:>22} {:>22} {:>22} {:>7}  {}{}",
            r.name,
            thousands(r.rays as u64),
            fmt(&r.single),
            fmt(&r.all),
            peer,
            ratio,
            check,
            peer_check
        );
    }
    if args_test(args) == TriangleTest::Exact {
        let per_set: Vec<String> = results
            .iter()
            .map(|r| format!("{} {} ({:.4} %)", r.name, thousands(r.exact_stage), percent(r.exact_stage, r.rays)))
            .collect();
        crate::out!(
            "exact test: the filter left to exact integer arithmetic, calls in one pass: {}",
            per_set.join(", ")
        );
    }
    if results.iter().any(|r| r.embree.is_some()) {
        crate::out!(
            "\nEmbree 3 (fast mode), 1 thread, the same runs:\n{:<11} {:>22} {:>22} {:>22} {:>22} {:>10} {:>10}",
            "set",
            "octrace batch",
            "octrace 1-ray calls",
            "Embree 1-ray calls",
            "Embree 16-ray packets",
            "batch/best",
            "1-ray/1-ray"
        );
        for r in results {
            let Some(e) = &r.embree else { continue };
            crate::out!(
                "{:<11} {:>22} {:>22} {:>22} {:>22} {:>9.2}x {:>9.2}x  (Embree {} {})",
                r.name,
                fmt(&r.single),
                fmt(&e.octrace_one_ray),
                fmt(&e.embree_one_ray),
                e.embree_packets.as_ref().map_or("-".into(), fmt),
                e.ratio_batch,
                e.ratio_one_ray,
                thousands(e.embree_hits as u64),
                if r.name == "shadow" { "occluded" } else { "hits" }
            );
        }
        if let Some(n) = results.iter().find_map(|r| r.embree.as_ref()?.all_threads.as_ref().map(|a| a.threads)) {
            crate::out!(
                "\nEmbree 3, all {n} threads (rayon: chunks of 1,024 rays, or of 64 packets), the same runs:\n\
                 {:<11} {:>22} {:>22} {:>22} {:>22} {:>10} {:>10}",
                "set",
                "octrace batch",
                "octrace 1-ray calls",
                "Embree 1-ray calls",
                "Embree 16-ray packets",
                "batch/best",
                "1-ray/1-ray"
            );
            for r in results {
                let Some(a) = r.embree.as_ref().and_then(|e| e.all_threads.as_ref()) else { continue };
                crate::out!(
                    "{:<11} {:>22} {:>22} {:>22} {:>22} {:>9.2}x {:>9.2}x",
                    r.name,
                    fmt(&a.octrace_batch),
                    fmt(&a.octrace_one_ray),
                    fmt(&a.embree_one_ray),
                    a.embree_packets.as_ref().map_or("-".into(), fmt),
                    a.ratio_batch,
                    a.ratio_one_ray
                );
            }
        }
        for r in results {
            let Some((spread, ratio)) = r.embree.as_ref().and_then(|e| e.embree_memory_order.as_ref()) else {
                continue;
            };
            crate::out!(
                "{:<11} Embree 1-ray calls on the rays in octrace's memory order (its batch sorts these): {}, \
                 octrace batch / that {:.2}x",
                r.name,
                fmt(spread),
                ratio
            );
        }
    }
    if let Some(q) = queries {
        crate::out!("{}", q.text());
    }
    if let Some(g) = gpu {
        crate::out!("{}", g.text());
    }
    Ok(())
}

/// `part` as a percentage of `whole` (zero of nothing).
fn percent(part: u64, whole: usize) -> f64 {
    if whole == 0 {
        0.0
    } else {
        100.0 * part as f64 / whole as f64
    }
}

/// A set's checksum in words: rays occluded for shadow rays, else hits and their sum of t.
fn checksum(set: &str, hits: usize, sum_t: f64) -> String {
    if set == "shadow" {
        format!("{} occluded", thousands(hits as u64))
    } else {
        format!("{} hits, sum t {:.2}", thousands(hits as u64), sum_t)
    }
}

#[cfg(feature = "embree")]
mod embree_runs;
mod gpu;
mod queries;
mod world;
