//! `octrace render`.

use std::path::PathBuf;
use std::time::Instant;

use glam::DVec3;
use octrace_runtime::raysets::{Camera, Frame};
use octrace_runtime::render::{render, RenderMode};
use octrace_runtime::Scene;

#[derive(clap::Args, Debug)]
pub(crate) struct Args {
    /// The .oct scene.
    pub scene: PathBuf,
    /// The PNG to write.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Image width.
    #[arg(long, default_value_t = 1024)]
    pub width: u32,
    /// Image height.
    #[arg(long, default_value_t = 1024)]
    pub height: u32,
    /// Eye position `x,y,z` (default: the standard camera of shared/bench/RAYS.md).
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    pub eye: Option<DVec3>,
    /// Point looked at `x,y,z` (default: the scene's centre).
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    pub target: Option<DVec3>,
    /// Vertical field of view in degrees.
    #[arg(long, default_value_t = 45.0)]
    pub fov: f64,
    /// shaded: grey by the angle to the camera; normals: normals as colours;
    /// cells: leaves each ray visited (the paper's Figure 6), with a legend.
    #[arg(long, value_enum, default_value_t = Mode::Shaded)]
    pub mode: Mode,
    /// Trace on the GPU (Vulkan; Mesa's lavapipe without a GPU): the same image.
    #[arg(long)]
    pub gpu: bool,
}

#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub(crate) enum Mode {
    Shaded,
    Normals,
    Cells,
}

fn parse_vec3(s: &str) -> Result<DVec3, String> {
    let v: Vec<f64> =
        s.split(',').map(|p| p.trim().parse::<f64>()).collect::<Result<_, _>>().map_err(|e| e.to_string())?;
    match v.as_slice() {
        [x, y, z] if v.iter().all(|c| c.is_finite()) => Ok(DVec3::new(*x, *y, *z)),
        _ => Err(format!("expected three finite numbers x,y,z, got '{s}'")),
    }
}

pub(crate) fn run(args: Args) -> anyhow::Result<()> {
    anyhow::ensure!(args.width > 0 && args.height > 0, "image size must be at least 1 x 1");
    anyhow::ensure!(args.fov > 0.0 && args.fov < 180.0, "--fov must be between 0 and 180 degrees");
    let scene = crate::open::open_scene(&args.scene)?;
    let camera = camera(&scene, &args);
    let mode = match args.mode {
        Mode::Shaded => RenderMode::Shaded,
        Mode::Normals => RenderMode::Normals,
        Mode::Cells => RenderMode::Cells,
    };
    let (image, stats, secs) = if args.gpu {
        let gpu = octrace_runtime::gpu::GpuContext::new()?;
        let tracer = octrace_runtime::gpu::GpuTracer::new(&gpu.device, &gpu.queue, &scene)?;
        eprintln!("tracing on {}", gpu.describe());
        let t = Instant::now();
        let (image, stats) = octrace_runtime::render::render_gpu(&scene, &tracer, &camera, mode)?;
        (image, stats, t.elapsed().as_secs_f64())
    } else {
        let t = Instant::now();
        let (image, stats) = render(&scene, &camera, mode);
        (image, stats, t.elapsed().as_secs_f64())
    };
    image.write_png(&args.output)?;
    crate::out!(
        "rendered {} ({} x {}, {:?}): {} of {} rays hit, {:.1} leaves and {:.1} triangle tests a ray (max {} leaves), {:.3} s -> {}",
        crate::show(&args.scene),
        args.width,
        args.height,
        mode,
        stats.hits,
        stats.rays,
        stats.mean_leaves,
        stats.mean_triangle_tests,
        stats.max_leaves,
        secs,
        crate::show(&args.output)
    );
    Ok(())
}

fn camera(scene: &Scene, args: &Args) -> Camera {
    let b = scene.view().bounds;
    let frame = Frame::from_bounds(b.mesh_lo, b.mesh_hi);
    match (args.eye, args.target) {
        (None, None) if args.fov == 45.0 => Camera::standard_sized(&frame, args.width, args.height),
        _ => {
            let standard = Camera::standard(&frame);
            Camera::look_at(
                args.eye.unwrap_or(standard.eye),
                args.target.unwrap_or(frame.c),
                args.fov,
                args.width,
                args.height,
            )
        }
    }
}
