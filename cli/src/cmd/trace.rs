//! `octrace trace`.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;
use octrace_runtime::{Hit, Ray};

use crate::output::{counted, thousands};

/// `octrace trace`'s arguments; the formats are in its long help.
#[derive(clap::Args, Debug)]
#[command(after_long_help = concat!("\
RAYS.bin: little-endian, no header, 32 bytes a ray, f32 `ox oy oz tmin dx dy dz tmax`.
HITS.bin: 8 bytes a ray, in ray order, f32 `t` then u32 triangle id (its index in the
input mesh); a miss is `t = tmax`, id `0xFFFFFFFF`. With --occluded the id is that of
some occluding triangle, not necessarily the nearest.

With --all-hits, every crossing of each ray in [tmin, tmax], in order along it, each
once (a ray through an edge or vertex that triangles share crosses one of them):
first n + 1 u64 offsets for n rays (ray i's crossings are records offsets[i] ..
offsets[i + 1]; offsets[0] = 0), then the records, 20 bytes each: f32 `t`, u32
triangle id, f32 `u`, f32 `v` (barycentrics of the second and third vertices), u32
`enters` (1 where the ray arrives on the triangle's front, the side its normal
(v1 - v0) x (v2 - v0) points to: for a closed mesh wound outward, where it enters).
--max-hits K keeps each ray's first K (the summary counts the rays cut short).
In numpy: offsets = np.frombuffer(b, '<u8', n + 1); hits = np.frombuffer(b, [('t',
'<f4'), ('triangle', '<u4'), ('u', '<f4'), ('v', '<f4'), ('enters', '<u4')], offset=8 * (n + 1)).

With --counts, 8 bytes a ray: u32 crossings, u32 of them entering (arriving on a
front); for a ray from a point to infinity through a closed mesh wound outward,
entries - exits is -1 inside, 0 outside.

With --length-inside, 4 bytes a ray: f32 length of [tmin, tmax] inside the scene, a
closed mesh (refused when it is not: `octrace inspect` says), in units of t.

A scene description (a .json file) in place of the .oct traces a world of instances:
baked scenes placed by transforms, each ray carried into each instance's space.
  {\"scenes\": {\"bunny\": \"bunny.oct\"},
   \"instances\": [{\"scene\": \"bunny\"},
                 {\"scene\": \"bunny\", \"transform\": [[1,0,0,0.5],[0,1,0,0],[0,0,1,0]]}]}
Paths are relative to the description's folder; a transform is 3 or 4 rows of 4
(nested or flat; the last row 0 0 0 1), local to world, the identity where absent.
Its hits are 12 bytes a ray: f32 `t`, u32 instance (its index in \"instances\"), u32
triangle of that instance's scene (a miss: `t = tmax`, both 0xFFFFFFFF); with
--occluded, 4 bytes a ray, u32 1 or 0; with --counts, as above. With --gpu, the
instances' octrees are walked on the GPU (the top level and the rays' carrying on
the CPU): the same files as the CPU's.

", mapped_scene_help!()))]
pub(crate) struct Args {
    /// The .oct scene, or a world: a scene description (.json: baked scenes placed by
    /// transforms, traced as one world; see below) or an instanced file (what `bake`
    /// writes for a glTF that places a mesh many times).
    pub scene: PathBuf,
    /// Input rays (32 bytes each; a regular file of at most 2^32 rays, 128 GiB).
    #[arg(long)]
    pub rays: PathBuf,
    /// Output hits (8 bytes each); `-` writes them to standard output (the summary then
    /// goes to standard error). Never one of the inputs.
    #[arg(short = 'o', long = "output", visible_alias = "out")]
    pub out: PathBuf,
    /// Answer occlusion (any hit) instead of the nearest hit.
    #[arg(long, group = "mode")]
    pub occluded: bool,
    /// Write every crossing of each ray, in order (the layout below).
    #[arg(long, group = "mode")]
    pub all_hits: bool,
    /// With --all-hits, keep at most K crossings a ray (its first K).
    #[arg(long, value_name = "K", requires = "all_hits")]
    pub max_hits: Option<u32>,
    /// With --all-hits, the most memory the lists may take (20 bytes a crossing; the
    /// peak is about twice this while they are written out): past it the command
    /// stops with an error, writing nothing. Suffixes K, M, G, T (powers of 1024).
    /// Default: a quarter of the memory this process may use (physical memory, or
    /// `ulimit -v` where lower).
    #[arg(long, value_name = "BYTES", value_parser = crate::output::parse_bytes, requires = "all_hits")]
    pub max_memory: Option<u64>,
    /// Write how many times each ray crosses the scene, and how many of those enter.
    #[arg(long, group = "mode")]
    pub counts: bool,
    /// Write each ray's length inside the scene (a closed mesh).
    #[arg(long, group = "mode")]
    pub length_inside: bool,
    /// Print the summary as JSON.
    #[arg(long)]
    pub json: bool,
    /// Threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Trace on the GPU (Vulkan; Mesa's lavapipe without a GPU): the CPU's answers,
    /// bit for bit where the adapter has f64 (the exact test, its doubtful rays
    /// finished on the CPU; elsewhere the watertight test, whose answers differ from
    /// the exact ones only within rounding of edges and vertices). The Mrays/s printed are then of the
    /// kernel alone, without the transfers (of the whole call, transfers and both
    /// passes, with --all-hits, --counts and --length-inside).
    #[arg(long)]
    pub gpu: bool,
}

/// The GPU tracer of `trace --gpu`: the CPU tracer's test (the exact one; the
/// watertight one in a scene with fans) where the adapter can run it (the exact one
/// needs `f64`), else the watertight one (`GpuOptions::triangle_test`).
pub(crate) fn gpu_tracer<'s>(
    gpu: &octrace_runtime::gpu::GpuContext,
    scene: &'s octrace_runtime::Scene,
) -> anyhow::Result<octrace_runtime::gpu::GpuTracer<'s>> {
    use octrace_runtime::gpu::{GpuError, GpuOptions, GpuTracer};
    let cpus = GpuOptions { triangle_test: scene.tracer().triangle_test(), ..GpuOptions::default() };
    match GpuTracer::with_options(&gpu.device, &gpu.queue, scene, cpus) {
        Err(GpuError::Unsupported(_)) => Ok(GpuTracer::new(&gpu.device, &gpu.queue, scene)?),
        tracer => Ok(tracer?),
    }
}

/// The id written for a miss.
pub(crate) const MISS: u32 = u32::MAX;

/// The most rays a ray file may hold: 2^32 (128 GiB of rays, 32 GiB of hits).
pub(crate) const MAX_RAYS: u64 = 1 << 32;

impl Args {
    /// Whether the command asks a query along each ray (`--all-hits`, `--counts`,
    /// `--length-inside`: `trace_crossings`) rather than the nearest or any hit.
    pub(crate) fn along(&self) -> bool {
        self.all_hits || self.counts || self.length_inside
    }
}

/// The command's inputs, checked: the scene, the rays, and whether the output is
/// standard output.
pub(crate) fn inputs(args: &Args) -> anyhow::Result<(octrace_runtime::Scene, Vec<Ray>, bool)> {
    crate::output::refuse_overwriting(&args.out, "-o", &[&args.scene, &args.rays])?;
    let to_stdout = crate::output::is_stdout(&args.out);
    let scene = crate::open::open_scene(&args.scene)?;
    let rays: Vec<Ray> = octrace_format::read_records(&args.rays, MAX_RAYS, "ray")
        .with_context(|| format!("cannot read {}", args.rays.display()))?;
    Ok((scene, rays, to_stdout))
}

/// The nearest hit of each ray, or with `--occluded` any hit (the queries along a
/// ray: `trace_crossings::run`).
pub(crate) fn run(args: Args) -> anyhow::Result<()> {
    let (scene, rays, to_stdout) = inputs(&args)?;
    // Each ray's distance and triangle (a miss: `tmax`, `MISS`), as the file has them.
    let (hits, seconds, on) = if args.gpu {
        use octrace_runtime::gpu::{Answers, GpuNearest};
        let gpu = octrace_runtime::gpu::GpuContext::new()?;
        let tracer = gpu_tracer(&gpu, &scene)?;
        // Distance and triangle come back, 8 bytes a ray: what the file holds.
        let mut nearest = vec![GpuNearest::default(); rays.len()];
        let timings = tracer.trace_into(&rays, args.occluded, Answers::Nearest(&mut nearest))?;
        // The device's own clock where it has timestamps, else the host's.
        let (kernel, clock) = match timings.kernel_device {
            Some(d) => (d, "GPU timestamps"),
            None => (timings.kernel, "host clock"),
        };
        let hits =
            nearest.iter().zip(&rays).map(|(h, r)| if h.triangle == MISS { (r.tmax, MISS) } else { (h.t, h.triangle) });
        (hits.collect::<Vec<_>>(), kernel.as_secs_f64(), format!("kernel only, {clock}, {}", gpu.describe()))
    } else {
        let (hits, seconds) = trace_cpu(&scene, &rays, &args)?;
        let hits = hits.iter().zip(&rays).map(|(h, r)| h.map_or((r.tmax, MISS), |h| (h.t, h.triangle)));
        (
            hits.collect(),
            seconds,
            format!(
                "tracing only, {}",
                counted(args.threads.unwrap_or_else(rayon::current_num_threads) as u64, "thread")
            ),
        )
    };
    let mut out = Vec::with_capacity(8 * rays.len());
    for (t, id) in &hits {
        out.extend_from_slice(&t.to_le_bytes());
        out.extend_from_slice(&id.to_le_bytes());
    }
    crate::output::write_data(&args.out, &[&out])?;
    let n = hits.iter().filter(|h| h.1 != MISS).count();
    let rate = rays.len() as f64 / seconds.max(1e-9) / 1e6;
    let what = if args.occluded { "occluded" } else { "hits" };
    if args.json {
        let j = serde_json::json!({
            "rays": rays.len(), what: n, "seconds": seconds, "mrays_per_s": rate, "on": on,
        });
        crate::report!(to_stdout, "{j}");
    } else {
        crate::report!(
            to_stdout,
            "{} rays, {} {what}, {rate:.2} Mrays/s ({on})",
            thousands(rays.len() as u64),
            thousands(n as u64)
        );
    }
    Ok(())
}

/// `trace` of a scene description (a world of instances, `crate::world_file`): nearest
/// hits (12 bytes a ray: `t`, instance, triangle), `--occluded` (4 bytes: 1 or 0) or
/// `--counts` (as for a scene); with `--gpu`, each with the instances' walks on the
/// GPU (`GpuWorld`: the CPU's answers).
pub(crate) fn run_world(args: Args) -> anyhow::Result<()> {
    anyhow::ensure!(
        !(args.all_hits || args.length_inside),
        "{}: a scene description is traced for nearest hits, --occluded and --counts (--all-hits and \
         --length-inside take a .oct)",
        args.scene.display()
    );
    crate::output::refuse_overwriting(&args.out, "-o", &[&args.scene, &args.rays])?;
    let to_stdout = crate::output::is_stdout(&args.out);
    let (world, _scenes) = crate::world_file::open_world(&args.scene)?;
    let rays: Vec<Ray> = octrace_format::read_records(&args.rays, MAX_RAYS, "ray")
        .with_context(|| format!("cannot read {}", args.rays.display()))?;
    // On the GPU: the scenes uploaded before the clock starts.
    let mut gpu = match args.gpu {
        true => {
            let context = octrace_runtime::gpu::GpuContext::new()?;
            let mut on_gpu = octrace_runtime::world::GpuWorld::new(&context.device, &context.queue);
            on_gpu.upload(&world)?;
            Some((on_gpu, context.describe()))
        }
        false => None,
    };
    let (answers, seconds) = crate::with_threads(args.threads, || {
        let t = Instant::now();
        let answers = match (&mut gpu, args.counts, args.occluded) {
            (Some((on_gpu, _)), true, _) => on_gpu.count_crossings(&world, &rays).map(Answers::Counts),
            (Some((on_gpu, _)), false, true) => on_gpu.occluded(&world, &rays).map(Answers::Occluded),
            (Some((on_gpu, _)), false, false) => on_gpu.intersect(&world, &rays).map(Answers::Hits),
            (None, true, _) => Ok(Answers::Counts(world.count_crossings_batch(&rays))),
            (None, false, true) => Ok(Answers::Occluded(world.occluded_batch(&rays))),
            (None, false, false) => Ok(Answers::Hits(world.intersect_batch(&rays))),
        };
        (answers, t.elapsed().as_secs_f64())
    })?;
    let mut out = Vec::new();
    let n = match answers? {
        Answers::Counts(counts) => {
            for c in &counts {
                out.extend_from_slice(&c.total.to_le_bytes());
                out.extend_from_slice(&c.entries.to_le_bytes());
            }
            counts.iter().filter(|c| c.total > 0).count()
        }
        Answers::Occluded(occluded) => {
            for &o in &occluded {
                out.extend_from_slice(&u32::from(o).to_le_bytes());
            }
            occluded.iter().filter(|&&o| o).count()
        }
        Answers::Hits(hits) => {
            for (h, r) in hits.iter().zip(&rays) {
                let (t, instance, triangle) = h.map_or((r.tmax, MISS, MISS), |h| (h.hit.t, h.instance, h.hit.triangle));
                out.extend_from_slice(&t.to_le_bytes());
                out.extend_from_slice(&instance.to_le_bytes());
                out.extend_from_slice(&triangle.to_le_bytes());
            }
            hits.iter().flatten().count()
        }
    };
    let on = match &gpu {
        Some((_, adapter)) => format!("the world's answers, instances' walks on the GPU, {adapter}"),
        None => "the world's answers".to_string(),
    };
    crate::output::write_data(&args.out, &[&out])?;
    let rate = rays.len() as f64 / seconds.max(1e-9) / 1e6;
    let what = if args.counts {
        "crossing"
    } else if args.occluded {
        "occluded"
    } else {
        "hits"
    };
    if args.json {
        let j = serde_json::json!({
            "rays": rays.len(), what: n, "instances": world.len(), "seconds": seconds, "mrays_per_s": rate,
            "on": on,
        });
        crate::report!(to_stdout, "{j}");
    } else {
        crate::report!(
            to_stdout,
            "{} rays, {} {what}, {} instances, {rate:.2} Mrays/s ({on})",
            thousands(rays.len() as u64),
            thousands(n as u64),
            thousands(world.len() as u64)
        );
    }
    Ok(())
}

/// A world's answers, as `trace` of a scene description writes them.
enum Answers {
    Hits(Vec<Option<octrace_runtime::world::WorldHit>>),
    Occluded(Vec<bool>),
    Counts(Vec<octrace_runtime::cpu::CrossingCount>),
}

/// Traces on all cores (or `--threads`); the hits and the seconds of tracing alone.
fn trace_cpu(scene: &octrace_runtime::Scene, rays: &[Ray], args: &Args) -> anyhow::Result<(Vec<Option<Hit>>, f64)> {
    let tracer = scene.tracer();
    crate::with_threads(args.threads, || {
        let t = Instant::now();
        let mut hits = vec![None; rays.len()];
        if args.occluded {
            tracer.par_occluder_batch(rays, &mut hits);
        } else {
            tracer.par_intersect_batch(rays, &mut hits);
        }
        (hits, t.elapsed().as_secs_f64())
    })
}
