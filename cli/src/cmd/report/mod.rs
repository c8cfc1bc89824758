//! `octrace report`: what accuracy costs in time, one knob at a time.
//!
//! The parts: `configs` (the knobs, peers, octree walks and baselines, each built on
//! any mesh), `measure` (timing and the oracle on the standard sets), `hard` (the
//! hard rays), `leaks` (the closed solids), `render_knobs` (the renderer's own
//! knobs), `paper` (the paper's tables), `markdown` and `chart` (the outputs).

mod chart;
mod configs;
mod hard;
mod leaks;
mod markdown;
mod measure;
mod paper;
mod render_knobs;

use std::path::{Path, PathBuf};

use octrace_bake::octree::build_unbalanced;
use octrace_bake::{BuildParams, Mesh, MeshFormat};
use octrace_runtime::baselines::unconstrained::UnconstrainedOctree;
use serde::Serialize;

use crate::output::thousands;
use configs::{Config, Knob};
use hard::HardSet;
use leaks::{LeakCount, Solids};
use measure::{Errors, Speed};
use paper::PaperRow;
use render_knobs::RenderKnobRow;

/// Measure what accuracy costs in time: one accuracy knob at a time, Mrays/s next to
/// the error against the f64 brute-force oracle. Writes report.md, report.json and
/// report.png (error against Mrays/s, one point per configuration).
///
/// For each mesh (default: the bunny this build carries, and
/// ../shared/meshes/dragon.obj when it is there) each knob is turned from the
/// defaults in turn: the triangle test (watertight f32, Möller-Trumbore f32 or f64),
/// the exit-face test (Plücker signs or slab distances), the bake margin, the depth
/// limit, the leaf target. Each configuration is baked (time, bytes, leaves,
/// references per triangle) and traced on the three standard ray sets
/// (bench/RAYS.md) on one thread: the median of --runs, and their spread. Its
/// answers are compared with the oracle's on --sample rays of each set (wrong hits,
/// largest |Δt|/t) and on --hard-rays rays of each hard kind: in cell planes, along
/// cell edges, through cell corners, grazing, aimed at vertices, at slivers, from
/// origins on the surface, and at the mesh moved far from the origin. Leaks per
/// million: rays from inside the procedural closed solids (random, aimed at vertices
/// and edges, on the octree's planes) that get out, each solid baked or built with
/// the same configuration. The paper's 2:1-balanced tree is walked against the same
/// tree without the constraint; obvhs's CWBVH, Embree (built with `--features
/// embree`, fast and robust modes), the seeds' BVH builds and SAH kd-tree trace the
/// same rays. The renderer's own knobs (soft-shadow samples, reflection depth) are
/// priced on the effects scene against reference renders.
///
///   octrace report                     # the bunny (and the dragon beside the repository)
///   octrace report scene.glb -o out    # any mesh
#[derive(clap::Args, Debug)]
#[command(verbatim_doc_comment)]
pub(crate) struct Args {
    /// Meshes (OBJ, glTF, GLB, optionally .zst) or .oct files (their triangles are
    /// baked again for each configuration).
    pub inputs: Vec<PathBuf>,
    /// Folder for report.md, report.json and report.png (created if missing).
    #[arg(short, long, default_value = "report")]
    pub output: PathBuf,
    /// Timed runs per figure (the median is reported, with the spread).
    #[arg(long, default_value_t = 5, value_parser = crate::output::parse_runs)]
    pub runs: usize,
    /// Rays of each set compared with the f64 oracle (spread evenly over the set).
    #[arg(long, default_value_t = 2000, value_parser = crate::output::parse_count)]
    pub sample: usize,
    /// Rays of each hard kind compared with the f64 oracle.
    #[arg(long, default_value_t = 2000, value_parser = crate::output::parse_count)]
    pub hard_rays: usize,
    /// Random rays (and as many on the octree's planes) per closed solid for the leak
    /// counts (rays at every vertex and edge midpoint come on top).
    #[arg(long, default_value_t = 100_000, value_parser = crate::output::parse_count)]
    pub leak_rays: usize,
    /// Width of the renders that price the renderer's knobs (0: none).
    #[arg(long, default_value_t = 320)]
    pub render_width: u32,
    /// Trace at most this many rays of each set (every k-th ray; default: the whole
    /// sets), for a quick look.
    #[arg(long)]
    pub max_rays: Option<usize>,
    /// Also print the report as JSON on stdout.
    #[arg(long)]
    pub json: bool,
}

/// One configuration's row of a mesh's report.
#[derive(Debug, Serialize)]
pub(super) struct Row {
    knob: &'static str,
    setting: String,
    /// Seconds to bake or build.
    bake_seconds: f64,
    bytes: u64,
    /// Leaves (octrees) or nodes.
    leaves: u64,
    references_per_triangle: f64,
    /// The seeds' baselines: the SAH cost of the structure.
    sah_cost: Option<f64>,
    /// Single-threaded Mrays/s per set (primary, incoherent, shadow): medians, and the
    /// runs' fastest and slowest.
    mrays: Vec<f64>,
    mrays_spread: Vec<[f64; 2]>,
    errors: Errors,
    /// Errors on the hard rays, kind by kind.
    hard: Vec<HardErrors>,
    /// Wrong answers per million over all the hard rays.
    hard_wrong_per_million: f64,
    /// Rays leaked from inside the closed solids, per million, and rays shot.
    leaks_per_million: f64,
    leak_rays: usize,
    leaks: Vec<LeakCount>,
}

impl Row {
    fn speeds(&self) -> Vec<Speed> {
        self.mrays.iter().zip(&self.mrays_spread).map(|(&median, s)| Speed { median, min: s[0], max: s[1] }).collect()
    }
}

/// A configuration's errors on one kind of hard ray.
#[derive(Debug, Serialize)]
struct HardErrors {
    kind: &'static str,
    #[serde(flatten)]
    errors: Errors,
}

#[derive(Debug, Serialize)]
pub(super) struct MeshReport {
    name: String,
    triangles: usize,
    sets: Vec<(&'static str, usize)>,
    /// Rays of each hard kind.
    hard_rays: usize,
    rows: Vec<Row>,
    /// The balanced and unconstrained walks compared.
    balance: BalanceStats,
    /// Whether the octree's SIMD walk ran its x86-64-v3 build.
    x86_64_v3: bool,
    /// The paper's Tables 1 and 3 at its depth, for the bunny and the dragon.
    paper: Vec<PaperRow>,
}

/// Everything the report measured.
#[derive(Debug, Serialize)]
pub(super) struct Report {
    meshes: Vec<MeshReport>,
    render_knobs: Vec<RenderKnobRow>,
    runs: usize,
}

pub(crate) fn run(args: Args) -> anyhow::Result<()> {
    anyhow::ensure!(args.runs >= 1, "--runs must be at least 1");
    anyhow::ensure!(args.sample >= 1, "--sample must be at least 1");
    let meshes = inputs(&args)?;
    let configs = Config::all();
    // Per configuration: the leak counts, then for each mesh its build, its far copy's
    // and its measurement; then the renders.
    let steps = (configs.len() * (1 + meshes.len()) + 2 * meshes.len() + 1) as u64;
    let bar = Bar::new(steps);
    bar.message("the closed solids' rays");
    let solids = Solids::new(args.leak_rays)?;
    let mut leaks = Vec::new();
    for &config in &configs {
        bar.step(&format!("leaks: {}", config.setting(&BuildParams::auto().resolve(1))));
        leaks.push(solids.leaks(config)?);
    }
    let mut reports = Vec::new();
    for (name, mesh) in &meshes {
        reports.push(mesh_report(name, mesh, &args, &configs, &leaks, &bar)?);
    }
    bar.step("the renderer's knobs");
    let render_knobs = if args.render_width > 0 { render_knobs::render_knobs(args.render_width)? } else { Vec::new() };
    bar.finish();
    let report = Report { meshes: reports, render_knobs, runs: args.runs };
    std::fs::create_dir_all(&args.output)?;
    let md = markdown::markdown(&report, &args);
    let json = serde_json::to_string_pretty(&report)?;
    // Whole files or none (a temporary file renamed into place).
    octrace_format::write_atomically(&args.output.join("report.md"), &[md.as_bytes()])?;
    octrace_format::write_atomically(&args.output.join("report.json"), &[json.as_bytes()])?;
    octrace_format::write_atomically(&args.output.join("report.png"), &[&chart::png(&report.meshes)?])?;
    if args.json {
        crate::out!("{json}");
    } else {
        crate::out!("{md}");
        crate::out!("wrote {}, report.json and report.png", crate::show(&args.output.join("report.md")));
    }
    Ok(())
}

/// The meshes to report on: those given, else the bunny and the shared dragon.
fn inputs(args: &Args) -> anyhow::Result<Vec<(String, Mesh)>> {
    let name = |p: &Path| p.file_name().map_or_else(|| crate::show(p), |n| n.to_string_lossy().into_owned());
    if args.inputs.is_empty() {
        let obj = zstd::stream::decode_all(super::demo::BUNNY)?;
        let mut out = vec![("bunny".to_string(), Mesh::from_bytes(&obj, MeshFormat::Obj, "bunny.obj".as_ref(), None)?)];
        let dragon = Path::new("../shared/meshes/dragon.obj");
        if dragon.exists() {
            out.push(("dragon".to_string(), Mesh::load(dragon)?));
        }
        return Ok(out);
    }
    args.inputs
        .iter()
        .map(|p| {
            let mesh = if super::bake::is_scene(p) {
                let scene = crate::open::open_scene(p)?;
                let view = scene.view();
                // Input order, so triangle ids stay those of the file.
                let mut tris = vec![[[0.0f32; 3]; 3]; view.triangle_ids.iter().max().map_or(0, |&m| m as usize + 1)];
                for (&input, tri) in view.triangle_ids.iter().zip(view.stored_triangles()) {
                    tris[input as usize] = tri;
                }
                Mesh::from_triangles(tris)
            } else {
                Mesh::load(p)?
            };
            Ok((name(p), mesh))
        })
        .collect()
}

fn mesh_report(
    name: &str,
    mesh: &Mesh,
    args: &Args,
    configs: &[Config],
    leaks: &[Vec<LeakCount>],
    bar: &Bar,
) -> anyhow::Result<MeshReport> {
    let base = BuildParams::auto().resolve(mesh.triangles.len());
    bar.step(&format!("{name}: the standard sets, the hard rays and the f64 oracle"));
    let defaults = Config::Knob(Knob::Defaults).build(mesh, &base)?;
    let scene = defaults.scene.clone().expect("an octree");
    let sets = measure::standard_sets(&scene, args.sample, args.max_rays);
    let hard = HardSet::new(mesh, args.hard_rays)?;
    let far_base = BuildParams::auto().resolve(hard.far_mesh.triangles.len());
    let mut rows = Vec::new();
    for (&config, leaks) in configs.iter().zip(leaks) {
        bar.step(&format!("{name}: {} {}", config.group(), config.setting(&base)));
        let built = if config == Config::Knob(Knob::Defaults) { None } else { Some(config.build(mesh, &base)?) };
        let built = built.as_ref().unwrap_or(&defaults);
        let far = config.build(&hard.far_mesh, &far_base)?;
        let mut m = measure::measure(&*built.traced, &sets, args.runs);
        m.hard = hard.errors(&*built.traced, Some(&*far.traced));
        let (leaks_per_million, leak_rays) = leaks::rate(leaks);
        let hard_errors: Vec<HardErrors> =
            m.hard.into_iter().map(|(kind, errors)| HardErrors { kind, errors }).collect();
        let (wrong, compared) =
            hard_errors.iter().fold((0, 0), |(w, c), h| (w + h.errors.wrong, c + h.errors.compared));
        rows.push(Row {
            knob: config.group(),
            setting: config.setting(&base),
            bake_seconds: built.seconds,
            bytes: built.bytes,
            leaves: built.nodes,
            references_per_triangle: built.references_per_triangle,
            sah_cost: built.sah_cost,
            mrays: m.speeds.iter().map(|s| s.median).collect(),
            mrays_spread: m.speeds.iter().map(|s| [s.min, s.max]).collect(),
            errors: m.errors,
            hard: hard_errors,
            hard_wrong_per_million: wrong as f64 * 1e6 / compared.max(1) as f64,
            leaks_per_million,
            leak_rays,
            leaks: leaks.clone(),
        });
    }
    bar.step(&format!("{name}: 2:1 balanced against unconstrained, the paper's tables"));
    let balance = balance_stats(mesh, &Knob::Defaults.params(&base), &scene, &sets.sets[1].1)?;
    Ok(MeshReport {
        name: name.to_string(),
        triangles: mesh.triangles.len(),
        sets: sets.sets.iter().map(|(n, r, _)| (*n, r.len())).collect(),
        hard_rays: hard.rays_per_kind(),
        rows,
        balance,
        x86_64_v3: scene.tracer().uses_x86_64_v3(),
        paper: paper::paper_rows(name, mesh)?,
    })
}

/// How the balanced and the unconstrained walks go, per ray of the incoherent set.
#[derive(Debug, Serialize)]
struct BalanceStats {
    rays: usize,
    balanced_leaves_per_ray: f64,
    balanced_tests_per_ray: f64,
    unconstrained_leaves_per_ray: f64,
    unconstrained_tests_per_ray: f64,
    /// Levels descended below ropes per ray, and the most in one step.
    descents_per_ray: f64,
    deepest_descent: u32,
}

/// What the 2:1 constraint costs and buys, walk by walk: leaves visited and tests run
/// in the balanced tree and in the tree without the constraint, on `rays`.
fn balance_stats(
    mesh: &Mesh,
    params: &BuildParams,
    scene: &octrace_runtime::Scene,
    rays: &[octrace_runtime::Ray],
) -> anyhow::Result<BalanceStats> {
    let u = build_unbalanced(mesh, params)?;
    let tree = UnconstrainedOctree::build(u.root_lo, u.root_size, &u.leaves, &u.triangles, &u.ids);
    let tracer = scene.tracer();
    let (mut b_leaves, mut b_tests, mut u_leaves, mut u_tests, mut descents, mut deepest) =
        (0u64, 0u64, 0u64, 0u64, 0u64, 0);
    for r in rays {
        let (_, b) = tracer.intersect_with_stats(r);
        let (_, u) = tree.intersect_with_stats(r);
        (b_leaves, b_tests) = (b_leaves + b.leaves as u64, b_tests + b.triangle_tests as u64);
        (u_leaves, u_tests) = (u_leaves + u.leaves as u64, u_tests + u.triangle_tests as u64);
        descents += u.descents as u64;
        deepest = deepest.max(u.deepest_descent);
    }
    let per_ray = |x: u64| x as f64 / rays.len().max(1) as f64;
    Ok(BalanceStats {
        rays: rays.len(),
        balanced_leaves_per_ray: per_ray(b_leaves),
        balanced_tests_per_ray: per_ray(b_tests),
        unconstrained_leaves_per_ray: per_ray(u_leaves),
        unconstrained_tests_per_ray: per_ray(u_tests),
        descents_per_ray: per_ray(descents),
        deepest_descent: deepest,
    })
}

/// The processor's name, from /proc/cpuinfo where there is one.
fn machine() -> String {
    std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|c| {
            c.lines()
                .find(|l| l.starts_with("model name"))
                .map(|l| l.split(':').nth(1).unwrap_or("").trim().to_string())
        })
        .unwrap_or_else(|| std::env::consts::ARCH.to_string())
}

/// Today's date (UTC), `YYYY-MM-DD`.
fn today() -> String {
    let days =
        std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_secs() / 86_400) as i64;
    // Howard Hinnant's civil_from_days.
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    format!("{y:04}-{m:02}-{d:02}")
}

/// A progress bar over the report's steps on a terminal; elsewhere (a log, CI) a line
/// a step on standard error, so a run of minutes is never silent.
struct Bar {
    /// The bar, on a terminal.
    bar: Option<indicatif::ProgressBar>,
    /// Steps in all, and those begun (for the lines printed without a bar).
    steps: u64,
    begun: std::cell::Cell<u64>,
    started: std::time::Instant,
}

impl Bar {
    fn new(steps: u64) -> Bar {
        use std::io::IsTerminal as _;
        let bar = std::io::stderr().is_terminal().then(|| {
            let bar = indicatif::ProgressBar::new(steps);
            bar.set_style(
                indicatif::ProgressStyle::with_template("{bar:30} {pos}/{len} {elapsed:>4} {msg}")
                    .expect("valid template"),
            );
            bar
        });
        Bar { bar, steps, begun: std::cell::Cell::new(0), started: std::time::Instant::now() }
    }

    /// Starts the next step.
    fn step(&self, what: &str) {
        match &self.bar {
            Some(b) => {
                b.inc(1);
                b.set_message(what.to_string());
            }
            None => {
                self.begun.set(self.begun.get() + 1);
                eprintln!(
                    "report: step {}/{} at {:.0} s: {}",
                    self.begun.get(),
                    self.steps,
                    self.started.elapsed().as_secs_f64(),
                    crate::output::printable(what)
                );
            }
        }
    }

    fn message(&self, what: &str) {
        if let Some(b) = &self.bar {
            b.set_message(what.to_string());
        }
    }

    fn finish(&self) {
        if let Some(b) = &self.bar {
            b.finish_and_clear();
        }
    }
}

/// `1,234` for counts in the report's text.
fn count(n: usize) -> String {
    thousands(n as u64)
}
