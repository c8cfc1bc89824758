//! `octrace report`: what accuracy costs in time, one knob at a time.

mod chart;

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use glam::Vec3;
use octrace_bake::octree::{build_unbalanced, ResolvedParams};
use octrace_bake::{bake, procedural, BuildParams, Mesh, MeshFormat};
use octrace_runtime::bvh::{Bvh, BvhBuild};
use octrace_runtime::kdtree::KdTree;
use octrace_runtime::raysets::{self, Frame};
use octrace_runtime::reference::{Agreement, Reference, ReferenceHit};
use octrace_runtime::unconstrained::UnconstrainedOctree;
use octrace_runtime::{ExitTest, Hit, Ray, Scene, Tracer, TriangleTest};
use rayon::prelude::*;
use serde::Serialize;

use crate::output::thousands;

/// Measure what accuracy costs in time: one accuracy knob at a time, Mrays/s next to
/// the error against the f64 brute-force oracle. Writes report.md, report.json and
/// report.png (error against Mrays/s, one point per configuration).
///
/// For each mesh (default: the bunny this build carries, and
/// ../shared/meshes/dragon.obj when it is there) each knob is turned from the
/// defaults in turn: the triangle test (watertight f32, Möller-Trumbore f32 or f64),
/// the exit-face test (Plücker signs or slab distances), the bake margin, the depth
/// limit, the leaf target. Each configuration is baked (time,
/// bytes, leaves, references per triangle) and traced on the three standard ray sets
/// (shared/bench/RAYS.md) on one thread, the median of --runs; its answers on --sample
/// rays of each set are compared with the oracle's (wrong hits, largest |Δt|/t). Leaks
/// per million: rays from inside `octrace soak`'s closed solids that get out, baked and
/// traced with the same configuration. The paper's 2:1-balanced tree is walked
/// against the same tree without the constraint (ropes to the node across each face,
/// the median-line tests once per level below it), scalar steps both. obvhs's CWBVH,
/// Embree (built with `--features embree`, fast and robust modes), the seeds' BVH
/// builds and SAH kd-tree trace the same rays as reference points.
///
///   octrace report                     # the bunny (and the dragon beside the repository)
///   octrace report scene.glb -o out    # any mesh
#[derive(clap::Args, Debug)]
pub(crate) struct Args {
    /// Meshes (OBJ, glTF, GLB, optionally .zst) or .oct files (their triangles are
    /// baked again for each configuration).
    pub inputs: Vec<PathBuf>,
    /// Folder for report.md, report.json and report.png (created if missing).
    #[arg(short, long, default_value = "report")]
    pub output: PathBuf,
    /// Timed runs per figure (the median is reported).
    #[arg(long, default_value_t = 5)]
    pub runs: usize,
    /// Rays of each set compared with the f64 oracle (spread evenly over the set).
    #[arg(long, default_value_t = 2000)]
    pub sample: usize,
    /// Random rays per closed solid for the leak count (rays at every vertex and edge
    /// midpoint come on top).
    #[arg(long, default_value_t = 100_000)]
    pub leak_rays: usize,
    /// Trace at most this many rays of each set (every k-th ray; default: the whole
    /// sets), for a quick look.
    #[arg(long)]
    pub max_rays: Option<usize>,
    /// Also print the report as JSON on stdout.
    #[arg(long)]
    pub json: bool,
}

/// One accuracy knob turned from the defaults.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Knob {
    Defaults,
    MollerTrumbore,
    F64,
    SlabExit,
    Margin(f32),
    Depth(i32),
    LeafSize(u32),
}

/// The configurations of the report, in its order.
const KNOBS: [Knob; 11] = [
    Knob::Defaults,
    Knob::MollerTrumbore,
    Knob::F64,
    Knob::SlabExit,
    Knob::Margin(0.0),
    Knob::Margin(1.0 / 65536.0),
    Knob::Depth(-2),
    Knob::Depth(-1),
    Knob::Depth(1),
    Knob::LeafSize(8),
    Knob::LeafSize(32),
];

impl Knob {
    fn group(self) -> &'static str {
        match self {
            Knob::Defaults => "defaults",
            Knob::MollerTrumbore | Knob::F64 => "triangle test",
            Knob::SlabExit => "exit face",
            Knob::Margin(_) => "bake margin",
            Knob::Depth(_) => "depth limit",
            Knob::LeafSize(_) => "leaf target",
        }
    }

    fn setting(self, base: &ResolvedParams) -> String {
        match self {
            Knob::Defaults => format!(
                "watertight f32, Plücker exit, margin {}, depth {}, leaf {}",
                power_of_two(base.margin),
                base.max_depth,
                base.leaf_size
            ),
            Knob::MollerTrumbore => "Möller-Trumbore f32".into(),
            Knob::F64 => "Möller-Trumbore f64".into(),
            Knob::SlabExit => "slab distances".into(),
            Knob::Margin(m) => power_of_two(m),
            Knob::Depth(_) => self.params(base).resolve(0).max_depth.to_string(),
            Knob::LeafSize(_) => self.params(base).resolve(0).leaf_size.to_string(),
        }
    }

    /// The bake parameters: `base` (a mesh's automatic ones) with this knob turned.
    fn params(self, base: &ResolvedParams) -> BuildParams {
        let mut p =
            BuildParams { max_depth: Some(base.max_depth), leaf_size: Some(base.leaf_size), margin: base.margin };
        match self {
            Knob::Margin(m) => p.margin = m,
            Knob::Depth(d) => p.max_depth = Some(base.max_depth.saturating_add_signed(d).max(1)),
            Knob::LeafSize(n) => p.leaf_size = Some(n),
            Knob::Defaults | Knob::MollerTrumbore | Knob::F64 | Knob::SlabExit => {}
        }
        p
    }

    fn test(self) -> TriangleTest {
        match self {
            Knob::MollerTrumbore => TriangleTest::MollerTrumbore,
            Knob::F64 => TriangleTest::F64,
            _ => TriangleTest::Watertight,
        }
    }

    fn exit(self) -> ExitTest {
        if self == Knob::SlabExit {
            ExitTest::Slab
        } else {
            ExitTest::Plucker
        }
    }

    /// `scene`'s tracer with this knob's tests.
    fn tracer(self, scene: &Scene) -> Tracer<'_> {
        scene.tracer().with_triangle_test(self.test()).with_exit_test(self.exit())
    }
}

/// `2^-20` for a power of two, `0` for zero, else the number.
fn power_of_two(x: f32) -> String {
    if x == 0.0 {
        return "0".into();
    }
    let e = x.log2();
    if e == e.round() {
        format!("2^{}", e as i32)
    } else {
        format!("{x:e}")
    }
}

/// The standard sets of one mesh, the sample indices and the oracle's answers there.
struct Sets {
    /// (name, rays, occlusion?)
    sets: Vec<(&'static str, Vec<Ray>, bool)>,
    samples: Vec<Vec<usize>>,
    /// The oracle's nearest hit (empty for occlusion sets) and occlusion per sample.
    nearest: Vec<Vec<Option<ReferenceHit>>>,
    occluded: Vec<Vec<bool>>,
    reference: Reference,
}

/// Errors of one configuration against the oracle.
#[derive(Clone, Copy, Debug, Default, Serialize)]
struct Errors {
    /// Rays compared.
    compared: usize,
    /// Wrong answers (not explained by a tie or an edge).
    wrong: usize,
    /// Different answers within rounding: two triangles at one distance, a hit on an
    /// edge, an origin on a surface.
    ties: usize,
    /// Largest |Δt|/t where both found the same triangle.
    max_relative_dt: f64,
}

/// One row of a mesh's table.
#[derive(Debug, Serialize)]
struct Row {
    knob: &'static str,
    setting: String,
    bake_seconds: f64,
    bytes: u64,
    leaves: u64,
    references_per_triangle: f64,
    /// Single-threaded Mrays/s per set (primary, incoherent, shadow), medians.
    mrays: Vec<f64>,
    errors: Errors,
    /// Rays leaked from inside closed solids, per million, and rays shot.
    leaks_per_million: f64,
    leak_rays: usize,
}

#[derive(Debug, Serialize)]
struct MeshReport {
    name: String,
    triangles: usize,
    sets: Vec<(&'static str, usize)>,
    rows: Vec<Row>,
    /// The balanced and unconstrained walks compared.
    balance: BalanceStats,
    /// Whether the octree's SIMD walk ran its x86-64-v3 build.
    x86_64_v3: bool,
    /// The paper's Tables 1 and 3 at its depth, for the bunny and the dragon.
    paper: Vec<PaperRow>,
    /// The seeds' BVH builds on the same rays.
    baselines: Vec<BaselineRow>,
}

/// A baseline structure's row: build, cost model, speed and errors.
#[derive(Debug, Serialize)]
struct BaselineRow {
    structure: String,
    build_seconds: f64,
    nodes: usize,
    sah_cost: f64,
    mrays: Vec<f64>,
    errors: Errors,
}

/// One row of the paper's Table 1 (leaves without and with the 2:1 constraint) and
/// Table 3 (MB per array).
#[derive(Debug, Serialize)]
struct PaperRow {
    /// Who measured it: "octrace" or "paper (published)".
    source: &'static str,
    depth: u32,
    leaf_target: String,
    unconstrained: u64,
    constrained: u64,
    /// MB: cube map, octree, triangles, boxes, point location, total.
    mb: [f64; 6],
}

/// The paper's depth and published figures (Portalez & Duguet 2016, Tables 1 and 3)
/// for the meshes it measured, by the name the report gives them (`bunny`,
/// `dragon.obj`, ...).
fn published(name: &str) -> Option<(u32, PaperRow)> {
    let row = |depth, unconstrained, constrained, mb| PaperRow {
        source: "paper (published)",
        depth,
        leaf_target: "~6 a leaf".into(),
        unconstrained,
        constrained,
        mb,
    };
    match name.split('.').next().unwrap_or(name) {
        "bunny" => Some((8, row(8, 69_000, 83_000, [1.5, 3.6, 12.2, 1.3, f64::NAN, 18.6]))),
        "dragon" => Some((11, row(11, 855_000, 1_144_000, [24.0, 50.0, 156.0, 18.0, f64::NAN, 248.0]))),
        _ => None,
    }
}

/// The paper's tables for `mesh` at the paper's depth, leaf targets 16 (ours) and 6
/// (the paper's leaves), beside the published row.
fn paper_rows(name: &str, mesh: &Mesh) -> anyhow::Result<Vec<PaperRow>> {
    let Some((depth, published)) = published(name) else { return Ok(Vec::new()) };
    let mut rows = vec![published];
    for leaf in [16, 6] {
        let params = BuildParams { max_depth: Some(depth), leaf_size: Some(leaf), ..BuildParams::auto() };
        let scene = Scene::from_baked(bake(mesh, &params)?)?;
        let view = scene.view();
        let stats = octrace_format::stats::SceneStatistics::compute(&view)?;
        let b = stats.bytes;
        let mb = |x: u64| x as f64 / 1e6;
        rows.push(PaperRow {
            source: "octrace",
            depth: view.params.max_depth,
            leaf_target: leaf.to_string(),
            unconstrained: view.stats.leaves_before_balance,
            constrained: stats.leaves,
            mb: [mb(b.cube_map), mb(b.octree), mb(b.triangles), mb(b.boxes), mb(b.point_location), mb(b.total())],
        });
    }
    Ok(rows)
}

pub(crate) fn run(args: Args) -> anyhow::Result<()> {
    anyhow::ensure!(args.runs >= 1, "--runs must be at least 1");
    anyhow::ensure!(args.sample >= 1, "--sample must be at least 1");
    let meshes = inputs(&args)?;
    // Per mesh: the defaults' bake, each knob, the peers, the octree rows, the
    // baselines; then the leak table's knobs and the rest.
    let steps = (meshes.len() * (KNOBS.len() + 4) + KNOBS.len() + 1) as u64;
    let bar = Bar::new(steps);
    let leaks = leak_table(&args, &bar)?;
    let mut reports = Vec::new();
    for (name, mesh) in &meshes {
        reports.push(mesh_report(name, mesh, &args, &leaks, &bar)?);
    }
    bar.finish();
    std::fs::create_dir_all(&args.output)?;
    let md = markdown(&reports, &args);
    let json = serde_json::to_string_pretty(&serde_json::json!({ "meshes": reports, "runs": args.runs }))?;
    // Whole files or none (a temporary file renamed into place).
    octrace_format::write_atomically(&args.output.join("report.md"), &[md.as_bytes()])?;
    octrace_format::write_atomically(&args.output.join("report.json"), &[json.as_bytes()])?;
    octrace_format::write_atomically(&args.output.join("report.png"), &[&chart::png(&reports)?])?;
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
                for prim in 0..view.triangle_count() as u32 {
                    tris[view.triangle_ids[prim as usize] as usize] = view.triangle(prim);
                }
                Mesh::from_triangles(tris)
            } else {
                Mesh::load(p)?
            };
            Ok((name(p), mesh))
        })
        .collect()
}

/// Leaks per million rays from inside the closed solids, and rays shot.
type LeakRate = (f64, usize);

/// Leak rates: each knob, each peer of this build, the balanced tree's scalar step,
/// the unconstrained tree.
struct Leaks {
    knobs: Vec<LeakRate>,
    peers: Vec<LeakRate>,
    scalar: LeakRate,
    unconstrained: LeakRate,
}

/// Leaks per million rays from inside the closed solids, for each configuration.
fn leak_table(args: &Args, bar: &Bar) -> anyhow::Result<Leaks> {
    let solids = procedural::closed_solids();
    let rays: Vec<Vec<Ray>> = solids
        .iter()
        .map(|s| s.leak_rays(args.leak_rays, 1).iter().map(|(o, d)| Ray::new(Vec3::from(*o), Vec3::from(*d))).collect())
        .collect();
    let total: usize = rays.iter().map(Vec::len).sum();
    let per_million = |leaks: usize| leaks as f64 * 1e6 / total.max(1) as f64;
    let mut knobs = Vec::new();
    for knob in KNOBS {
        bar.step(&format!("leaks: {} {}", knob.group(), knob.setting(&BuildParams::auto().resolve(1))));
        let mut leaks = 0;
        for (solid, rays) in solids.iter().zip(&rays) {
            let base = BuildParams::auto().resolve(solid.mesh.triangles.len());
            let scene = Scene::from_baked(bake(&solid.mesh, &knob.params(&base))?)?;
            let tracer = knob.tracer(&scene);
            let mut hits = vec![None; rays.len()];
            tracer.par_intersect_batch(rays, &mut hits);
            leaks += hits.iter().filter(|h| h.is_none()).count();
        }
        knobs.push((per_million(leaks), total));
    }
    bar.step("leaks: the peers, the scalar step, the unconstrained tree");
    let (mut peers, mut scalar, mut unconstrained) = (Vec::new(), 0, 0);
    for (solid, rays) in solids.iter().zip(&rays) {
        let scene = Scene::from_baked(bake(&solid.mesh, &BuildParams::auto())?)?;
        for (k, peer) in build_peers(&scene.view())?.iter().enumerate() {
            let leaks = rays.par_iter().filter(|r| peer.nearest(r).is_none()).count();
            if peers.len() <= k {
                peers.push(0);
            }
            peers[k] += leaks;
        }
        let tracer = scene.tracer();
        scalar += rays.par_iter().filter(|r| tracer.intersect_scalar(r).is_none()).count();
        let tree = unconstrained_tree(&solid.mesh, &BuildParams::auto())?;
        unconstrained += rays.par_iter().filter(|r| tree.intersect(r).is_none()).count();
    }
    Ok(Leaks {
        knobs,
        peers: peers.into_iter().map(|leaks| (per_million(leaks), total)).collect(),
        scalar: (per_million(scalar), total),
        unconstrained: (per_million(unconstrained), total),
    })
}

/// A peer's nearest hit: distance, stored triangle, barycentrics where the library
/// gives them.
type PeerHit = (f32, u32, Option<(f32, f32)>);

/// A peer library on the same triangles.
trait Peer: Sync {
    fn name(&self) -> &'static str;
    fn build_seconds(&self) -> f64;
    fn nearest(&self, r: &Ray) -> Option<PeerHit>;
    fn occluded(&self, r: &Ray) -> bool;
}

#[cfg(feature = "obvhs")]
impl Peer for crate::peer::Peer {
    fn name(&self) -> &'static str {
        "obvhs CWBVH (Möller-Trumbore f32)"
    }
    fn build_seconds(&self) -> f64 {
        self.build_time.as_secs_f64()
    }
    fn nearest(&self, r: &Ray) -> Option<PeerHit> {
        crate::peer::Peer::nearest(self, r).map(|(t, prim)| (t, prim, None))
    }
    fn occluded(&self, r: &Ray) -> bool {
        crate::peer::Peer::occluded(self, r)
    }
}

#[cfg(feature = "embree")]
impl Peer for crate::embree::Embree {
    fn name(&self) -> &'static str {
        if self.robust {
            "Embree 3 BVH, robust mode"
        } else {
            "Embree 3 BVH, fast mode"
        }
    }
    fn build_seconds(&self) -> f64 {
        self.build_time.as_secs_f64()
    }
    fn nearest(&self, r: &Ray) -> Option<PeerHit> {
        crate::embree::Embree::nearest(self, r).map(|(t, prim, u, v)| (t, prim, Some((u, v))))
    }
    fn occluded(&self, r: &Ray) -> bool {
        crate::embree::Embree::occluded(self, r)
    }
}

/// The peers this build has (cargo features `obvhs`, on by default, and `embree`),
/// built on the view's triangles.
// Pushes under features: some builds push nothing, others one or three.
#[allow(clippy::vec_init_then_push)]
fn build_peers(view: &octrace_format::SceneView<'_>) -> anyhow::Result<Vec<Box<dyn Peer>>> {
    #[allow(unused_mut)]
    let mut peers: Vec<Box<dyn Peer>> = Vec::new();
    #[cfg(feature = "obvhs")]
    peers.push(Box::new(crate::peer::Peer::build(view)));
    #[cfg(feature = "embree")]
    for robust in [false, true] {
        peers.push(Box::new(crate::embree::Embree::build(view, robust)?));
    }
    let _ = view;
    Ok(peers)
}

/// The octree `bake` would build, without the 2:1 constraint, with ropes.
fn unconstrained_tree(mesh: &Mesh, params: &BuildParams) -> anyhow::Result<UnconstrainedOctree> {
    let t = build_unbalanced(mesh, params)?;
    Ok(UnconstrainedOctree::build(t.root_lo, t.root_size, &t.leaves, &t.triangles, &t.ids))
}

/// A configuration's bake: the scene, how long it took, the file's bytes, its
/// statistics.
struct Baked {
    scene: Scene,
    seconds: f64,
    bytes: u64,
    stats: octrace_format::stats::SceneStatistics,
}

/// Bakes `mesh` with `params`, writes it (for its size) into `dir` as `name`.
fn bake_timed(mesh: &Mesh, params: &BuildParams, dir: &Path, name: &str) -> anyhow::Result<Baked> {
    let t = Instant::now();
    let baked = bake(mesh, params)?;
    let bake_time = t.elapsed();
    let bytes = baked.write(dir.join(name), bake_time.as_micros() as u64)?;
    let scene = Scene::from_baked(baked)?;
    let stats = octrace_format::stats::SceneStatistics::compute(&scene.view())?;
    Ok(Baked { scene, seconds: bake_time.as_secs_f64(), bytes, stats })
}

fn mesh_report(name: &str, mesh: &Mesh, args: &Args, leaks: &Leaks, bar: &Bar) -> anyhow::Result<MeshReport> {
    let base = BuildParams::auto().resolve(mesh.triangles.len());
    let dir = tempfile::tempdir()?;
    // The defaults' bake serves every knob that leaves the bake as it is (the
    // triangle and exit tests), the standard sets and the oracle, obvhs and the
    // baselines.
    bar.step(&format!("{name}: the defaults' bake"));
    let defaults = bake_timed(mesh, &Knob::Defaults.params(&base), dir.path(), "defaults.oct")?;
    bar.message(&format!("{name}: the f64 oracle on {} rays of each set", thousands(args.sample as u64)));
    let sets = standard_sets(&defaults.scene, args.sample, args.max_rays);
    let mut rows = Vec::new();
    for (k, knob) in KNOBS.into_iter().enumerate() {
        bar.step(&format!("{name}: {} {}", knob.group(), knob.setting(&base)));
        let params = knob.params(&base);
        let own = if params == Knob::Defaults.params(&base) {
            None
        } else {
            Some(bake_timed(mesh, &params, dir.path(), &format!("{k}.oct"))?)
        };
        let baked = own.as_ref().unwrap_or(&defaults);
        let tracer = knob.tracer(&baked.scene);
        let (mrays, errors) = trace_config(&sets, args.runs, |rays, occlusion| answers(&tracer, rays, occlusion));
        let (leaks_per_million, leak_rays) = leaks.knobs[k];
        let stats = &baked.stats;
        rows.push(Row {
            knob: knob.group(),
            setting: knob.setting(&base),
            bake_seconds: baked.seconds,
            bytes: baked.bytes,
            leaves: stats.leaves,
            references_per_triangle: stats.triangle_references as f64 / stats.triangles.max(1) as f64,
            mrays,
            errors,
            leaks_per_million,
            leak_rays,
        });
    }
    let view = defaults.scene.view();
    bar.step(&format!("{name}: the peers"));
    for (peer, &(leaks_per_million, leak_rays)) in build_peers(&view)?.iter().zip(&leaks.peers) {
        // Stored triangle → input id. A peer without barycentrics gives the centre's:
        // the oracle then decides edge ties.
        let nearest = |r: &Ray| {
            peer.nearest(r).map(|(t, prim, uv)| {
                let (u, v) = uv.unwrap_or((0.3, 0.3));
                (t, view.triangle_ids[prim as usize], u, v)
            })
        };
        let (mrays, errors) = trace_config(&sets, args.runs, |rays, occlusion| {
            answers_by(rays, occlusion, nearest, |r| peer.occluded(r))
        });
        rows.push(Row {
            knob: "peer",
            setting: peer.name().into(),
            bake_seconds: peer.build_seconds(),
            bytes: 0,
            leaves: 0,
            references_per_triangle: 0.0,
            mrays,
            errors,
            leaks_per_million,
            leak_rays,
        });
    }
    bar.step(&format!("{name}: 2:1 balanced against unconstrained"));
    let (octree_rows, balance) = balance_rows(mesh, &base, &defaults, &sets, args.runs, leaks)?;
    rows.extend(octree_rows);
    bar.step(&format!("{name}: the seeds' BVH builds and kd-tree"));
    // The stored triangles and their input ids (degenerate ones left out, as the
    // octree does).
    let tris: Vec<[[f32; 3]; 3]> = (0..view.triangle_count() as u32).map(|p| view.triangle(p)).collect();
    let ids = view.triangle_ids;
    let mut baselines: Vec<BaselineRow> = BvhBuild::ALL
        .into_iter()
        .map(|build| baseline_row(format!("BVH, {}", build.name()), || Bvh::build(&tris, ids, build), &sets, args.runs))
        .collect();
    let kd_tree = || KdTree::build(&tris, ids);
    baselines.push(baseline_row("SAH kd-tree, Havran's depth and failures".into(), kd_tree, &sets, args.runs));
    bar.message(&format!("{name}: the paper's tables"));
    let paper = paper_rows(name, mesh)?;
    Ok(MeshReport {
        name: name.to_string(),
        triangles: mesh.triangles.len(),
        sets: sets.sets.iter().map(|(n, r, _)| (*n, r.len())).collect(),
        rows,
        balance,
        x86_64_v3: defaults.scene.tracer().uses_x86_64_v3(),
        paper,
        baselines,
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

/// What the 2:1 constraint costs and buys: the balanced tree's scalar step against
/// the unconstrained tree's walk (ropes, then the median-line tests once per level),
/// with the same triangle test on the same rays: two rows, and walk statistics.
fn balance_rows(
    mesh: &Mesh,
    base: &ResolvedParams,
    defaults: &Baked,
    sets: &Sets,
    runs: usize,
    leaks: &Leaks,
) -> anyhow::Result<(Vec<Row>, BalanceStats)> {
    let tracer = defaults.scene.tracer();
    let as_tuple = |h: Hit| (h.t, h.triangle, h.u, h.v);
    let (mrays, errors) = trace_config(sets, runs, |rays, occlusion| {
        answers_by(rays, occlusion, |r| tracer.intersect_scalar(r).map(as_tuple), |r| tracer.occluded_scalar(r))
    });
    let stats = &defaults.stats;
    let triangles = stats.triangles.max(1) as f64;
    let balanced = Row {
        knob: "octree",
        setting: "2:1 balanced (the paper), scalar step".into(),
        bake_seconds: defaults.seconds,
        bytes: defaults.bytes,
        leaves: stats.leaves,
        references_per_triangle: stats.triangle_references as f64 / triangles,
        mrays,
        errors,
        leaks_per_million: leaks.scalar.0,
        leak_rays: leaks.scalar.1,
    };
    let t = Instant::now();
    let tree = unconstrained_tree(mesh, &Knob::Defaults.params(base))?;
    let seconds = t.elapsed().as_secs_f64();
    let (mrays, errors) = trace_config(sets, runs, |rays, occlusion| {
        answers_by(rays, occlusion, |r| tree.intersect(r), |r| tree.occluded(r))
    });
    let unconstrained = Row {
        knob: "octree",
        setting: "unconstrained, ropes, scalar step".into(),
        bake_seconds: seconds,
        bytes: tree.memory_bytes() as u64,
        leaves: tree.leaf_count() as u64,
        references_per_triangle: tree.references() as f64 / triangles,
        mrays,
        errors,
        leaks_per_million: leaks.unconstrained.0,
        leak_rays: leaks.unconstrained.1,
    };
    let rays = &sets.sets[1].1;
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
    let balance = BalanceStats {
        rays: rays.len(),
        balanced_leaves_per_ray: per_ray(b_leaves),
        balanced_tests_per_ray: per_ray(b_tests),
        unconstrained_leaves_per_ray: per_ray(u_leaves),
        unconstrained_tests_per_ray: per_ray(u_tests),
        descents_per_ray: per_ray(descents),
        deepest_descent: deepest,
    };
    Ok((vec![balanced, unconstrained], balance))
}

/// What the report asks of a baseline structure.
trait Baseline {
    fn nearest(&self, ray: &Ray) -> Option<(f32, u32, f32, f32)>;
    fn occluded(&self, ray: &Ray) -> bool;
    fn nodes(&self) -> usize;
    fn sah_cost(&self) -> f64;
}

impl Baseline for Bvh {
    fn nearest(&self, ray: &Ray) -> Option<(f32, u32, f32, f32)> {
        self.intersect(ray)
    }
    fn occluded(&self, ray: &Ray) -> bool {
        Bvh::occluded(self, ray)
    }
    fn nodes(&self) -> usize {
        self.node_count()
    }
    fn sah_cost(&self) -> f64 {
        Bvh::sah_cost(self)
    }
}

impl Baseline for KdTree {
    fn nearest(&self, ray: &Ray) -> Option<(f32, u32, f32, f32)> {
        self.intersect(ray)
    }
    fn occluded(&self, ray: &Ray) -> bool {
        KdTree::occluded(self, ray)
    }
    fn nodes(&self) -> usize {
        self.node_count()
    }
    fn sah_cost(&self) -> f64 {
        KdTree::sah_cost(self)
    }
}

/// A baseline's row: `build` timed, then traced on the sets.
fn baseline_row<B: Baseline>(structure: String, build: impl FnOnce() -> B, sets: &Sets, runs: usize) -> BaselineRow {
    let t = Instant::now();
    let b = build();
    let build_seconds = t.elapsed().as_secs_f64();
    let (mrays, errors) =
        trace_config(sets, runs, |rays, occlusion| answers_by(rays, occlusion, |r| b.nearest(r), |r| b.occluded(r)));
    BaselineRow { structure, build_seconds, nodes: b.nodes(), sah_cost: b.sah_cost(), mrays, errors }
}

/// The answers of a structure traced ray by ray.
fn answers_by(
    rays: &[Ray],
    occlusion: bool,
    nearest: impl Fn(&Ray) -> Option<(f32, u32, f32, f32)>,
    occluded: impl Fn(&Ray) -> bool,
) -> Vec<Answer> {
    rays.iter().map(|r| if occlusion { Answer::Occluded(occluded(r)) } else { Answer::Nearest(nearest(r)) }).collect()
}

/// A tracer's answer for one ray.
#[derive(Clone, Copy, Debug)]
enum Answer {
    /// Distance, input triangle id, barycentrics.
    Nearest(Option<(f32, u32, f32, f32)>),
    Occluded(bool),
}

fn answers(tracer: &Tracer<'_>, rays: &[Ray], occlusion: bool) -> Vec<Answer> {
    if occlusion {
        let mut out = vec![false; rays.len()];
        tracer.occluded_batch(rays, &mut out);
        out.into_iter().map(Answer::Occluded).collect()
    } else {
        let mut out: Vec<Option<Hit>> = vec![None; rays.len()];
        tracer.intersect_batch(rays, &mut out);
        out.into_iter().map(|h| Answer::Nearest(h.map(|h| (h.t, h.triangle, h.u, h.v)))).collect()
    }
}

/// The standard sets of `scene` (shadow rays from its primary hits), a sample of each,
/// and the oracle's answers on the samples.
fn standard_sets(scene: &Scene, sample: usize, max_rays: Option<usize>) -> Sets {
    let view = scene.view();
    let frame = Frame::from_bounds(view.bounds.mesh_lo, view.bounds.mesh_hi);
    let primary = raysets::primary(&frame);
    let mut hits = vec![None; primary.len()];
    scene.tracer().par_intersect_batch(&primary, &mut hits);
    let shadow = raysets::shadow(&frame, |i| hits[i].map(|h| (h.t, view.triangle(h.prim))));
    let thin = |rays: Vec<Ray>| match max_rays {
        Some(n) if n < rays.len() => spread(rays.len(), n).map(|i| rays[i]).collect(),
        _ => rays,
    };
    let sets = vec![
        ("primary", thin(primary), false),
        ("incoherent", thin(raysets::incoherent(&frame, 1_000_000)), false),
        ("shadow", thin(shadow), true),
    ];
    let reference = Reference::from_view(&view);
    let samples: Vec<Vec<usize>> = sets.iter().map(|(_, rays, _)| spread(rays.len(), sample).collect()).collect();
    let nearest = sets
        .iter()
        .zip(&samples)
        .map(
            |((_, rays, occ), s)| {
                if *occ {
                    Vec::new()
                } else {
                    s.par_iter().map(|&i| reference.intersect(&rays[i])).collect()
                }
            },
        )
        .collect();
    let occluded = sets
        .iter()
        .zip(&samples)
        .map(
            |((_, rays, occ), s)| {
                if *occ {
                    s.par_iter().map(|&i| reference.occluded(&rays[i])).collect()
                } else {
                    Vec::new()
                }
            },
        )
        .collect();
    Sets { sets, samples, nearest, occluded, reference }
}

/// `n` indices (at least one, at most `len`) spread evenly over `0..len`.
fn spread(len: usize, n: usize) -> impl Iterator<Item = usize> {
    let n = n.max(1).min(len);
    (0..n).map(move |i| i * len / n)
}

/// Mrays/s (one thread, median of `runs`) on each set and the errors of the last
/// run's answers on the samples.
fn trace_config(sets: &Sets, runs: usize, trace: impl Fn(&[Ray], bool) -> Vec<Answer>) -> (Vec<f64>, Errors) {
    let mut mrays = Vec::new();
    let mut errors = Errors::default();
    for (s, (_, rays, occlusion)) in sets.sets.iter().enumerate() {
        let mut times = Vec::new();
        let mut last = Vec::new();
        for _ in 0..runs {
            let t = Instant::now();
            last = trace(rays, *occlusion);
            times.push(t.elapsed());
        }
        times.sort();
        mrays.push(rays.len() as f64 / times[times.len() / 2].max(Duration::from_nanos(1)).as_secs_f64() / 1e6);
        for (j, &i) in sets.samples[s].iter().enumerate() {
            let ray = &rays[i];
            let agreement = match last[i] {
                Answer::Nearest(got) => {
                    let want = sets.nearest[s][j];
                    let a = sets.reference.compare_with(ray, want, got);
                    if let (Agreement::Same, Some(g), Some(w)) = (a, got, want) {
                        if g.1 == w.triangle && w.t > 0.0 {
                            errors.max_relative_dt = errors.max_relative_dt.max((g.0 as f64 - w.t).abs() / w.t);
                        }
                    }
                    a
                }
                Answer::Occluded(got) => sets.reference.compare_occluded_with(ray, sets.occluded[s][j], got),
            };
            errors.compared += 1;
            match agreement {
                Agreement::Same => {}
                Agreement::Tie => errors.ties += 1,
                Agreement::Different => errors.wrong += 1,
            }
        }
    }
    (mrays, errors)
}

/// report.md.
fn markdown(reports: &[MeshReport], args: &Args) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "# What accuracy costs: octrace report\n");
    let _ = writeln!(
        s,
        "octrace {} on {} ({} threads available; the figures are single-threaded), {} UTC. \
         Mrays/s: median of {} runs on the standard sets of shared/bench/RAYS.md. Errors: each \
         configuration's answers on {} rays of each set against the f64 brute-force oracle \
         (`runtime::reference`); \"wrong\" excludes ties within rounding (two triangles at one \
         distance, hits on an edge, origins on a surface). Leaks: rays from inside `octrace \
         soak`'s four closed solids ({} random rays each, plus every vertex and edge midpoint) \
         that hit nothing, baked and traced with the same configuration.\n",
        env!("CARGO_PKG_VERSION"),
        machine(),
        rayon::current_num_threads(),
        today(),
        args.runs,
        thousands(args.sample as u64),
        thousands(args.leak_rays as u64),
    );
    if let Some(n) = args.max_rays {
        let _ = writeln!(s, "Quick run: at most {} rays of each set (every k-th ray).\n", thousands(n as u64));
    }
    if !cfg!(feature = "embree") {
        let _ = writeln!(
            s,
            "Embree: not in this build (`cargo build --release -p octrace --features embree`, with Debian's \
             libembree-dev installed, adds it in fast and robust modes).\n"
        );
    }
    for r in reports {
        let _ = writeln!(s, "## {} ({} triangles)\n", r.name, thousands(r.triangles as u64));
        let _ = writeln!(
            s,
            "The octree's walk ran its {} build; the seeds' structures, the scalar steps and obvhs are \
             compiled for the x86-64 baseline, Embree picks its own.\n",
            if r.x86_64_v3 { "x86-64-v3 (AVX2)" } else { "baseline (SSE2)" }
        );
        let _ = writeln!(
            s,
            "| knob | setting | bake s | MB | leaves | refs / tri | primary | incoherent | shadow | wrong / rays | ties | max \\|Δt\\|/t | leaks / M rays (solids) |"
        );
        let _ =
            writeln!(s, "| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |");
        for row in &r.rows {
            let peer = row.knob == "peer";
            let dash = |x: String| if peer { "—".to_string() } else { x };
            let _ = writeln!(
                s,
                "| {} | {} | {:.2} | {} | {} | {} | {} | {} / {} | {} | {:.1e} | {:.1} |",
                row.knob,
                row.setting,
                row.bake_seconds,
                dash(format!("{:.1}", row.bytes as f64 / 1e6)),
                dash(thousands(row.leaves)),
                dash(format!("{:.2}", row.references_per_triangle)),
                row.mrays.iter().map(|m| format!("{m:.2}")).collect::<Vec<_>>().join(" | "),
                row.errors.wrong,
                thousands(row.errors.compared as u64),
                row.errors.ties,
                row.errors.max_relative_dt,
                row.leaks_per_million,
            );
        }
        let _ = writeln!(s, "\nPareto front (no other configuration as fast on all three sets with no more wrong hits and leaks): {}.\n", pareto(&r.rows).join(", "));
        let b = &r.balance;
        let _ = writeln!(
            s,
            "2:1 balanced against unconstrained (the \"octree\" rows; scalar steps both, the unconstrained \
             tree's MB in memory without boxes or cube map): on the {} incoherent rays, a walk visits {:.1} \
             leaves and runs {:.1} triangle tests in the balanced tree, {:.1} leaves and {:.1} tests in the \
             unconstrained one, which descends {:.2} levels a ray below its ropes (at most {} in one step).\n",
            thousands(b.rays as u64),
            b.balanced_leaves_per_ray,
            b.balanced_tests_per_ray,
            b.unconstrained_leaves_per_ray,
            b.unconstrained_tests_per_ray,
            b.descents_per_ray,
            b.deepest_descent,
        );
        baseline_table(&mut s, r);
        if !r.paper.is_empty() {
            paper_tables(&mut s, &r.paper);
        }
    }
    s
}

/// The seeds' baselines beside the octree's defaults.
fn baseline_table(s: &mut String, r: &MeshReport) {
    let _ = writeln!(
        s,
        "The seeds' baselines (seed 001's BVH builds, stack traversal near child first; seed 003's SAH kd-tree, \
         stack traversal front to back; the same watertight triangle test, rays and oracle; one thread):\n"
    );
    let _ = writeln!(s, "| structure | build s | nodes | SAH cost | primary | incoherent | shadow | wrong / rays |");
    let _ = writeln!(s, "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |");
    let mrays = |m: &[f64]| m.iter().map(|x| format!("{x:.2}")).collect::<Vec<_>>().join(" | ");
    if let Some(o) = r.rows.first() {
        let _ = writeln!(
            s,
            "| octree ({}) | {:.2} | {} leaves | — | {} | {} / {} |",
            o.setting,
            o.bake_seconds,
            thousands(o.leaves),
            mrays(&o.mrays),
            o.errors.wrong,
            thousands(o.errors.compared as u64)
        );
    }
    for b in &r.baselines {
        let _ = writeln!(
            s,
            "| {} | {:.2} | {} | {:.1} | {} | {} / {} |",
            b.structure,
            b.build_seconds,
            thousands(b.nodes as u64),
            b.sah_cost,
            mrays(&b.mrays),
            b.errors.wrong,
            thousands(b.errors.compared as u64)
        );
    }
    let _ = writeln!(s);
}

/// The paper's Tables 1 and 3, ours beside the published figures.
fn paper_tables(s: &mut String, rows: &[PaperRow]) {
    let _ =
        writeln!(s, "The paper's Table 1 (leaves without / with the 2:1 constraint) and Table 3 (MB), at its depth:\n");
    let _ = writeln!(s, "| source | depth | leaf target | unconstrained | constrained | ratio | cube map | octree | triangles | boxes | point loc. | total MB |");
    let _ = writeln!(s, "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |");
    for p in rows {
        let mb: Vec<String> = p.mb.iter().map(|m| if m.is_nan() { "—".into() } else { format!("{m:.1}") }).collect();
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {} | {:.0} % | {} |",
            p.source,
            p.depth,
            p.leaf_target,
            thousands(p.unconstrained),
            thousands(p.constrained),
            100.0 * p.constrained as f64 / p.unconstrained.max(1) as f64,
            mb.join(" | ")
        );
    }
    let _ = writeln!(
        s,
        "\nOur \"triangles\" column holds the per-leaf reference lists, the triangles once each and the id map; \
         the paper stored each triangle once per leaf that lists it, and its leaf criterion is not given.\n"
    );
}

/// The rows no other row dominates: at least as fast on every set, with no more
/// wrong hits and leaks, and better in one.
fn pareto(rows: &[Row]) -> Vec<String> {
    let error = |r: &Row| (r.errors.wrong, r.leaks_per_million);
    let dominates = |a: &Row, b: &Row| {
        let faster = a.mrays.iter().zip(&b.mrays).all(|(x, y)| x >= y);
        let (ea, eb) = (error(a), error(b));
        let no_worse = ea.0 <= eb.0 && ea.1 <= eb.1;
        let strictly = a.mrays.iter().zip(&b.mrays).any(|(x, y)| x > y) || ea.0 < eb.0 || ea.1 < eb.1;
        faster && no_worse && strictly
    };
    rows.iter()
        .filter(|b| !rows.iter().any(|a| dominates(a, b)))
        .map(|r| format!("{} ({})", r.knob, r.setting))
        .collect()
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

/// A progress bar over the report's steps, on a terminal.
struct Bar(Option<indicatif::ProgressBar>);

impl Bar {
    fn new(steps: u64) -> Bar {
        use std::io::IsTerminal as _;
        Bar(std::io::stderr().is_terminal().then(|| {
            let bar = indicatif::ProgressBar::new(steps);
            bar.set_style(
                indicatif::ProgressStyle::with_template("{bar:30} {pos}/{len} {elapsed:>4} {msg}")
                    .expect("valid template"),
            );
            bar
        }))
    }

    /// Starts the next step.
    fn step(&self, what: &str) {
        if let Some(b) = &self.0 {
            b.inc(1);
            b.set_message(what.to_string());
        }
    }

    fn message(&self, what: &str) {
        if let Some(b) = &self.0 {
            b.set_message(what.to_string());
        }
    }

    fn finish(&self) {
        if let Some(b) = &self.0 {
            b.finish_and_clear();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The paper's tables: the published row, then ours at the paper's depth for leaf
    /// targets 16 and 6, with the balance adding leaves.
    #[test]
    fn paper_tables_put_our_bakes_beside_the_published_rows() {
        let mesh = procedural::sphere([0.0; 3], 1.0, 24, 32);
        let rows = paper_rows("bunny.obj", &mesh).unwrap();
        assert_eq!(rows.len(), 3);
        assert_eq!((rows[0].source, rows[0].constrained), ("paper (published)", 83_000));
        for (row, leaf) in rows[1..].iter().zip(["16", "6"]) {
            assert_eq!((row.source, row.depth, row.leaf_target.as_str()), ("octrace", 8, leaf));
            assert!(row.constrained >= row.unconstrained && row.unconstrained > 0, "{row:?}");
            assert!(row.mb[5] > 0.0 && row.mb[..5].iter().sum::<f64>() <= row.mb[5] + 1e-9, "{row:?}");
        }
        assert!(paper_rows("teapot.glb", &mesh).unwrap().is_empty());
        let mut md = String::new();
        paper_tables(&mut md, &rows);
        assert!(md.contains("| paper (published) | 8 | ~6 a leaf | 69,000 | 83,000 | 120 % |"), "{md}");
    }
}
