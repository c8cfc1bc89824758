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

", mapped_scene_help!()))]
pub(crate) struct Args {
    /// The .oct scene.
    pub scene: PathBuf,
    /// Input rays (32 bytes each; a regular file of at most 2^32 rays, 128 GiB).
    #[arg(long)]
    pub rays: PathBuf,
    /// Output hits (8 bytes each); `-` writes them to standard output (the summary then
    /// goes to standard error). Never one of the inputs.
    #[arg(long)]
    pub out: PathBuf,
    /// Answer occlusion (any hit) instead of the nearest hit.
    #[arg(long)]
    pub occluded: bool,
    /// Threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Trace on the GPU (Vulkan; Mesa's lavapipe without a GPU). The Mrays/s printed
    /// are then of the kernel alone, without the transfers.
    #[arg(long)]
    pub gpu: bool,
}

/// The id written for a miss.
pub(crate) const MISS: u32 = u32::MAX;

/// The most rays a ray file may hold: 2^32 (128 GiB of rays, 32 GiB of hits).
pub(crate) const MAX_RAYS: u64 = 1 << 32;

pub(crate) fn run(args: Args) -> anyhow::Result<()> {
    crate::output::refuse_overwriting(&args.out, "--out", &[&args.scene, &args.rays])?;
    let to_stdout = crate::output::is_stdout(&args.out);
    let scene = crate::open::open_scene(&args.scene)?;
    let bytes = octrace_format::read_regular_file(&args.rays, 32 * MAX_RAYS)
        .with_context(|| format!("cannot read {}", args.rays.display()))?;
    anyhow::ensure!(
        bytes.len() % 32 == 0,
        "{}: {} bytes is not a whole number of 32-byte rays",
        args.rays.display(),
        bytes.len()
    );
    let rays: Vec<Ray> = bytemuck::pod_collect_to_vec(&bytes);
    let (hits, seconds, on) = if args.gpu {
        let gpu = octrace_runtime::gpu::GpuContext::new()?;
        let tracer = octrace_runtime::gpu::GpuTracer::new(&gpu.device, &gpu.queue, &scene)?;
        let (hits, timings) = tracer.trace_timed(&rays, args.occluded)?;
        (hits, timings.kernel.as_secs_f64(), format!("kernel only, {}", gpu.describe()))
    } else {
        let (hits, seconds) = trace_cpu(&scene, &rays, &args)?;
        (
            hits,
            seconds,
            format!(
                "tracing only, {}",
                counted(args.threads.unwrap_or_else(rayon::current_num_threads) as u64, "thread")
            ),
        )
    };
    let mut out = Vec::with_capacity(8 * rays.len());
    for (r, h) in rays.iter().zip(&hits) {
        let (t, id) = h.map_or((r.tmax, MISS), |h| (h.t, h.triangle));
        out.extend_from_slice(&t.to_le_bytes());
        out.extend_from_slice(&id.to_le_bytes());
    }
    crate::output::write_data(&args.out, &[&out])?;
    let n = hits.iter().flatten().count();
    crate::report!(
        to_stdout,
        "{} rays, {} {}, {:.2} Mrays/s ({on})",
        thousands(rays.len() as u64),
        thousands(n as u64),
        if args.occluded { "occluded" } else { "hits" },
        rays.len() as f64 / seconds.max(1e-9) / 1e6,
    );
    Ok(())
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
