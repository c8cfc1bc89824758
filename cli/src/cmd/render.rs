//! `octrace render`.

use std::io::IsTerminal;
use std::path::PathBuf;
use std::time::Instant;

use glam::DVec3;
use octrace_format::Effect;
use octrace_runtime::gpu::GpuRenderer;
use octrace_runtime::raysets::{Camera, Frame};
use octrace_runtime::render::effects::{
    render_effects, render_effects_world, EffectSet, Environment, RayCounts, RayKind, RenderOptions, Sky,
};
use octrace_runtime::render::{render, RenderMode};
use octrace_runtime::world::Transform;
use octrace_runtime::Scene;

use crate::output::thousands;

#[derive(clap::Args, Debug)]
#[command(after_long_help = concat!("\
Shaded images simulate only the effects the scene calls for (see `octrace inspect`):
shadows, soft shadows, reflection, refraction, alpha. Turn some off with --effects:

  octrace render scene.oct -o fast.png --effects -soft-shadows,-reflection --stats

A scene without lights is lit by a headlight at the camera, without shadow rays. A
scene lit only by emissive surfaces also gets a neutral sky (radiance 0.75 above, 0.5
at the horizon, 0.25 below), as glTF viewers light it; --environment none renders
direct light only, --environment sky gives any scene that sky instead of the
headlight, --environment 0.8 a uniform one of that radiance.
--stats prints the rays traced per kind (primary, shadow, soft_shadow, reflection,
refraction, alpha); --json prints the same as JSON.

", mapped_scene_help!()))]
pub(crate) struct Args {
    /// The .oct scene, or a world as `trace` takes (a scene description or an
    /// instanced file), rendered shaded on the CPU from the standard camera of its box
    /// or --eye/--target.
    pub scene: PathBuf,
    /// The PNG to write; `-` writes it to standard output (the summary then goes to
    /// standard error). Never the scene itself.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Image width (width x height at most 8192 x 8192 pixels: a render holds about 50
    /// bytes a pixel).
    #[arg(long, default_value_t = 1024)]
    pub width: u32,
    /// Image height (default: the width, or the width over the scene camera's aspect).
    #[arg(long)]
    pub height: Option<u32>,
    /// Eye position `x,y,z` (default: the scene's first camera, else the standard
    /// camera of bench/RAYS.md).
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    pub eye: Option<DVec3>,
    /// Point looked at `x,y,z` (default: the scene's centre).
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    pub target: Option<DVec3>,
    /// Vertical field of view in degrees (default 45, or the scene camera's).
    #[arg(long)]
    pub fov: Option<f64>,
    /// Horizontal field of view in degrees, instead of --fov: Open3D's `fov_deg`
    /// (`create_rays_pinhole(fov_deg, center, eye, up, width_px, height_px)` is
    /// `--hfov FOV_DEG --target CENTER --eye EYE --up UP --width W --height H`; its
    /// rays, row by row, are this image turned half a turn: `depth[::-1, ::-1]`).
    #[arg(long, conflicts_with_all = ["fov", "camera"])]
    pub hfov: Option<f64>,
    /// The camera's up direction `x,y,z` (default `0,1,0`, or the scene camera's).
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true, conflicts_with = "camera")]
    pub up: Option<DVec3>,
    /// Render through the scene's camera with this number: a glTF file's camera index
    /// (its `cameras[N]`, placed by the first node that does), as `octrace inspect` lists
    /// them. A world's cameras are those of its scenes placed as they are (an instanced
    /// file's: the glTF's). Without it, the first camera, if any.
    #[arg(long, conflicts_with_all = ["eye", "target"])]
    pub camera: Option<usize>,
    /// shaded: materials, lights and effects; normals: normals as colours;
    /// cells: leaves each ray visited (the paper's Figure 6), with a legend.
    #[arg(long, value_enum, default_value_t = Mode::Shaded)]
    pub mode: Mode,
    /// Effects to turn off, e.g. `-shadows,-reflection` (names: shadows, soft-shadows,
    /// reflection, refraction, alpha), or `none` for primary rays only.
    #[arg(long, allow_hyphen_values = true)]
    pub effects: Option<String>,
    /// Shadow rays towards area lights per shading point (soft shadows), 1 to 4096.
    #[arg(long, default_value_t = 16, value_parser = clap::value_parser!(u32).range(1..=4096))]
    pub soft_samples: u32,
    /// Light from all around: `auto` (a neutral sky for scenes lit only by emissive
    /// surfaces: radiance 0.75 above, 0.5 at the horizon, 0.25 below), `none` (direct
    /// light only), `sky` (that sky for any scene, instead of the headlight), or a
    /// radiance such as `0.8` (a uniform sky for any scene).
    #[arg(long, default_value = "auto", value_parser = parse_environment)]
    pub environment: Environment,
    /// Secondary rays (reflection, refraction, alpha) a path may take, at most 31.
    #[arg(long, default_value_t = 6, value_parser = clap::value_parser!(u32).range(0..=31))]
    pub max_depth: u32,
    /// Print rays traced per kind.
    #[arg(long)]
    pub stats: bool,
    /// Print the summary and the rays per kind as JSON.
    #[arg(long)]
    pub json: bool,
    /// Render on the GPU (Vulkan; Mesa's lavapipe without a GPU): the same image. In
    /// shaded mode, tracing and shading run in one kernel compiled for the effects in
    /// play.
    #[arg(long)]
    pub gpu: bool,
}

#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Mode {
    Shaded,
    Normals,
    Cells,
}

fn parse_environment(s: &str) -> Result<Environment, String> {
    match s {
        "auto" => Ok(Environment::Auto),
        "none" => Ok(Environment::Off),
        "sky" => Ok(Environment::Sky(Sky::NEUTRAL)),
        _ => match s.parse::<f32>() {
            Ok(x) if x.is_finite() && x >= 0.0 => Ok(Environment::Sky(Sky::uniform(x))),
            _ => Err(format!("expected auto, none, sky or a radiance (a number, 0 or more), got '{s}'")),
        },
    }
}

fn parse_vec3(s: &str) -> Result<DVec3, String> {
    let v: Vec<f64> =
        s.split(',').map(|p| p.trim().parse::<f64>()).collect::<Result<_, _>>().map_err(|e| e.to_string())?;
    match v.as_slice() {
        [x, y, z] if v.iter().all(|c| c.is_finite()) => Ok(DVec3::new(*x, *y, *z)),
        _ => Err(format!("expected three finite numbers x,y,z, got '{s}'")),
    }
}

/// The effects to run: the scene's, less those `spec` turns off. Returns the set and
/// one line per effect turned off or asked for but absent.
pub(crate) fn effect_set(scene: EffectSet, spec: Option<&str>) -> anyhow::Result<(EffectSet, Vec<String>)> {
    let mut set = scene;
    let mut notes = Vec::new();
    for word in spec.unwrap_or("").split(',').map(str::trim).filter(|w| !w.is_empty()) {
        if word == "none" {
            set = EffectSet::NONE;
            notes.push("all effects turned off (primary rays only)".to_string());
            continue;
        }
        let (off, name) = match word.strip_prefix('-') {
            Some(name) => (true, name),
            None => (false, word.strip_prefix('+').unwrap_or(word)),
        };
        let effect = Effect::from_name(name).ok_or_else(|| {
            let names: Vec<&str> = Effect::ALL.iter().map(|e| e.name()).collect();
            anyhow::anyhow!(
                "--effects: unknown effect '{name}' (effects: {}; prefix - to turn one off)",
                names.join(", ")
            )
        })?;
        match (off, scene.contains(effect)) {
            (true, true) => {
                set = set.without(effect);
                notes.push(format!("{}: turned off", effect.name()));
            }
            (true, false) => notes.push(format!("{}: not in this scene, nothing to turn off", effect.name())),
            (false, true) => {}
            (false, false) => {
                notes.push(format!("{}: not in this scene (nothing calls for it), not simulated", effect.name()))
            }
        }
    }
    Ok((set, notes))
}

/// The render's options from `args`, for what calls for the effects `in_scene`
/// ([`effect_set`]'s notes with them).
fn render_options(args: &Args, in_scene: EffectSet) -> anyhow::Result<(RenderOptions, Vec<String>)> {
    let (effects, notes) = effect_set(in_scene, args.effects.as_deref())?;
    let options = RenderOptions {
        effects,
        max_depth: args.max_depth,
        soft_samples: args.soft_samples.max(1),
        environment: args.environment,
    };
    Ok((options, notes))
}

/// The most pixels a render may have: 8192 x 8192. A render holds about 50 bytes a
/// pixel (radiance, the image, the rays of a wave), so this bounds it near 3.4 GB.
pub(crate) const MAX_PIXELS: u64 = 8192 * 8192;

/// Refuses an image over [`MAX_PIXELS`] before anything is allocated.
fn check_size(width: u32, height: u32) -> anyhow::Result<()> {
    anyhow::ensure!(
        width as u64 * height as u64 <= MAX_PIXELS,
        "{width} x {height} pixels is more than the limit of 8192 x 8192 ({MAX_PIXELS} pixels)"
    );
    Ok(())
}

pub(crate) fn run(args: Args) -> anyhow::Result<()> {
    let height = args.height.unwrap_or(args.width);
    anyhow::ensure!(args.width > 0 && height > 0, "image size must be at least 1 x 1");
    check_size(args.width, height)?;
    crate::output::refuse_overwriting(&args.output, "-o", &[&args.scene])?;
    let to_stdout = crate::output::is_stdout(&args.output);
    // The bytes are a PNG's: a name that says another format would be a file that
    // lies about itself.
    if let Some(ext) = args.output.extension().filter(|e| !to_stdout && !e.eq_ignore_ascii_case("png")) {
        anyhow::bail!(
            "{}: render writes PNG images, and '.{}' names another format: give a .png name (or - for standard \
             output)",
            crate::show(&args.output),
            crate::output::printable(&ext.to_string_lossy())
        );
    }
    if let Some(fov) = args.hfov {
        anyhow::ensure!(fov > 0.0 && fov < 180.0, "--hfov must be between 0 and 180 degrees");
    }
    if let Some(fov) = args.fov {
        anyhow::ensure!(fov > 0.0 && fov < 180.0, "--fov must be between 0 and 180 degrees");
    }
    if crate::world_file::is_world(&args.scene) {
        return run_world(&args, to_stdout);
    }
    let scene = crate::open::open_scene(&args.scene)?;
    // The images kept encoded are decoded before the clock starts (and a damaged one
    // refused by name rather than rendered white).
    scene.decode_textures()?;
    let camera = camera(&scene, &args)?;
    // A scene camera's aspect ratio sets the height: checked again.
    check_size(camera.width, camera.height)?;
    let (options, notes) = render_options(&args, EffectSet::of(scene.shading()))?;
    anyhow::ensure!(args.effects.is_none() || args.mode == Mode::Shaded, "--effects applies to --mode shaded");
    for n in &notes {
        eprintln!("effects: {n}");
    }
    let effects = options.effects;
    let gpu = if args.gpu {
        let gpu = octrace_runtime::gpu::GpuContext::new()?;
        let tracer = octrace_runtime::gpu::GpuTracer::new(&gpu.device, &gpu.queue, &scene)?;
        eprintln!("rendering on {}", gpu.describe());
        Some((gpu, tracer))
    } else {
        None
    };
    // The render kernel is made (and compiled by the driver) before the clock starts:
    // `gpu_setup_seconds` in --json.
    let setup = Instant::now();
    let renderer = match (&gpu, args.mode) {
        (Some((_, tracer)), Mode::Shaded) => Some(GpuRenderer::new(tracer, &options)?),
        _ => None,
    };
    let setup = setup.elapsed().as_secs_f64();
    let t = Instant::now();
    let (image, summary) = match args.mode {
        Mode::Shaded => {
            let (radiance, counts) = match &renderer {
                Some(renderer) => renderer.render(&camera)?,
                None => {
                    let bar = RowsBar::new(camera.height);
                    let out = render_effects(&scene, &camera, &options, &|rows| bar.set(rows));
                    bar.finish();
                    out
                }
            };
            (radiance.to_image(), Summary::Effects(counts))
        }
        mode => {
            let mode = if mode == Mode::Normals { RenderMode::Normals } else { RenderMode::Cells };
            let (image, stats) = match &gpu {
                Some((_, tracer)) => octrace_runtime::render::render_gpu(tracer, &camera, mode)?,
                None => render(&scene, &camera, mode),
            };
            (image, Summary::Walks(stats))
        }
    };
    let secs = t.elapsed().as_secs_f64();
    crate::output::write_data(&args.output, &[&image.png_bytes()?])?;
    let effect_names: Vec<&str> = effects.iter().map(|e| e.name()).collect();
    if args.json {
        let mut j = serde_json::json!({
            "scene": crate::show(&args.scene), "output": crate::show(&args.output),
            "width": camera.width, "height": camera.height, "mode": crate::output::choice(args.mode),
            "seconds": secs, "gpu": args.gpu, "notes": notes,
            "gpu_setup_seconds": if args.gpu { Some(setup) } else { None },
        });
        match &summary {
            Summary::Effects(counts) => {
                j["effects"] = serde_json::json!(effect_names);
                j["rays"] = rays_json(counts);
            }
            Summary::Walks(s) => {
                j["rays"] = serde_json::json!({ "primary": s.rays, "total": s.rays });
                j["hits"] = s.hits.into();
                j["mean_leaves"] = s.mean_leaves.into();
            }
        }
        crate::report!(to_stdout, "{}", serde_json::to_string_pretty(&j)?);
        return Ok(());
    }
    match &summary {
        Summary::Effects(counts) => {
            let listed = if effect_names.is_empty() { "none".to_string() } else { effect_names.join(", ") };
            crate::report!(
                to_stdout,
                "rendered {} ({} x {}, shaded; effects: {listed}): {} rays, {:.3} s -> {}",
                crate::show(&args.scene),
                camera.width,
                camera.height,
                thousands(counts.total()),
                secs,
                crate::show(&args.output)
            );
            if args.stats {
                for kind in RayKind::ALL {
                    crate::report!(to_stdout, "  {:<12} {:>14}", kind.name(), thousands(counts.get(kind)));
                }
            }
        }
        Summary::Walks(stats) => crate::report!(
            to_stdout,
            "rendered {} ({} x {}, {}): {} of {} rays hit, {:.1} leaves and {:.1} triangle tests a ray (max {} leaves), {:.3} s -> {}",
            crate::show(&args.scene),
            camera.width,
            camera.height,
            crate::output::choice(args.mode),
            thousands(stats.hits),
            thousands(stats.rays),
            stats.mean_leaves,
            stats.mean_triangle_tests,
            stats.max_leaves,
            secs,
            crate::show(&args.output)
        ),
    }
    Ok(())
}

/// `render` of a scene description (a world of instances, `crate::world_file`): the
/// effects renderer through the world, on the CPU, from the standard camera of the
/// world's box (or `--eye`, `--target`, ...); the effects those of all its scenes.
fn run_world(args: &Args, to_stdout: bool) -> anyhow::Result<()> {
    anyhow::ensure!(
        !args.gpu && args.mode == Mode::Shaded,
        "{}: a world renders shaded, on the CPU, from its cameras, the standard camera or --eye/--target \
         (--gpu and --mode take a .oct)",
        crate::show(&args.scene)
    );
    let (world, scenes) = crate::world_file::open_world(&args.scene)?;
    for scene in scenes.values() {
        scene.decode_textures()?;
    }
    let (lo, hi) = world.bounds().ok_or_else(|| {
        anyhow::anyhow!("{}: the description places no instance: nothing to render", crate::show(&args.scene))
    })?;
    // The cameras of the scenes placed as they are (an instanced file's scene of the
    // meshes placed once, with the glTF's cameras): in the world already.
    let mut cameras = Vec::new();
    let mut seen = std::collections::HashSet::new();
    for id in 0..world.len() as u32 {
        if let Some((scene, t)) = world.instance(id) {
            if t.rows == Transform::IDENTITY.rows && seen.insert(std::sync::Arc::as_ptr(scene)) {
                cameras.extend(scene.shading().cameras.iter().cloned());
            }
        }
    }
    let camera = camera_in(&Frame::from_bounds(lo, hi), &cameras, args)?;
    check_size(camera.width, camera.height)?;
    let all =
        scenes.values().fold(EffectSet::NONE, |set, s| EffectSet::of(s.shading()).iter().fold(set, EffectSet::with));
    let (options, notes) = render_options(args, all)?;
    for n in &notes {
        eprintln!("effects: {n}");
    }
    let effects = options.effects;
    let t = Instant::now();
    let bar = RowsBar::new(camera.height);
    let (radiance, counts) = render_effects_world(&world, &camera, &options, &|rows| bar.set(rows))
        .map_err(|e| anyhow::anyhow!("cannot render {}: {e}", args.scene.display()))?;
    bar.finish();
    let secs = t.elapsed().as_secs_f64();
    crate::output::write_data(&args.output, &[&radiance.to_image().png_bytes()?])?;
    let effect_names: Vec<&str> = effects.iter().map(|e| e.name()).collect();
    if args.json {
        let j = serde_json::json!({
            "scene": crate::show(&args.scene), "output": crate::show(&args.output),
            "width": camera.width, "height": camera.height, "mode": crate::output::choice(args.mode),
            "seconds": secs, "gpu": false, "notes": notes, "instances": world.len(),
            "effects": effect_names, "rays": rays_json(&counts),
        });
        crate::report!(to_stdout, "{}", serde_json::to_string_pretty(&j)?);
        return Ok(());
    }
    let listed = if effect_names.is_empty() { "none".to_string() } else { effect_names.join(", ") };
    crate::report!(
        to_stdout,
        "rendered {} ({} x {}, shaded, {}; effects: {listed}): {} rays, {:.3} s -> {}",
        crate::show(&args.scene),
        camera.width,
        camera.height,
        crate::output::counted(world.len() as u64, "instance"),
        thousands(counts.total()),
        secs,
        crate::show(&args.output)
    );
    Ok(())
}

/// What a render reports.
enum Summary {
    Effects(RayCounts),
    Walks(octrace_runtime::render::RenderStats),
}

/// Rays per kind, and their total, as JSON.
pub(crate) fn rays_json(counts: &RayCounts) -> serde_json::Value {
    let mut j = serde_json::Map::new();
    for kind in RayKind::ALL {
        j.insert(kind.name().into(), counts.get(kind).into());
    }
    j.insert("total".into(), counts.total().into());
    j.into()
}

/// A progress bar over image rows on a terminal; silent otherwise.
pub(crate) struct RowsBar(Option<indicatif::ProgressBar>);

impl RowsBar {
    pub(crate) fn new(rows: u32) -> RowsBar {
        RowsBar(std::io::stderr().is_terminal().then(|| {
            let bar = indicatif::ProgressBar::new(u64::from(rows));
            bar.set_style(
                indicatif::ProgressStyle::with_template("{elapsed:>3} [{bar:40}] {pos}/{len} rows, {eta} left")
                    .expect("valid template"),
            );
            bar
        }))
    }

    pub(crate) fn set(&self, rows: u32) {
        if let Some(b) = &self.0 {
            b.set_position(u64::from(rows).max(b.position()));
        }
    }

    pub(crate) fn finish(&self) {
        if let Some(b) = &self.0 {
            b.finish_and_clear();
        }
    }
}

fn camera(scene: &Scene, args: &Args) -> anyhow::Result<Camera> {
    let b = scene.view().bounds;
    camera_in(&Frame::from_bounds(b.mesh_lo, b.mesh_hi), &scene.shading().cameras, args)
}

/// The camera `args` ask for in `frame` (the standard one by default), or of `cameras`.
fn camera_in(frame: &Frame, cameras: &[octrace_runtime::format::Camera], args: &Args) -> anyhow::Result<Camera> {
    let from_file = match args.camera {
        Some(n) => Some(
            cameras.iter().enumerate().find(|(i, c)| c.number(*i) as usize == n).map(|(_, c)| c).ok_or_else(|| {
                let placed: Vec<String> =
                    cameras.iter().enumerate().map(|(i, c)| format!("{} '{}'", c.number(i), c.name)).collect();
                let placed = if placed.is_empty() { "none".to_string() } else { placed.join(", ") };
                anyhow::anyhow!("--camera {n}: the scene places no camera {n} (its cameras: {placed})")
            })?,
        ),
        None if args.eye.is_none() && args.target.is_none() => cameras.first(),
        None => None,
    };
    if let Some(c) = from_file {
        let height = args.height.unwrap_or_else(|| match c.aspect {
            // `as` saturates: a hostile aspect gives u32::MAX, which the size check refuses.
            Some(a) => ((args.width as f32 / a).round() as u32).max(1),
            None => args.width,
        });
        let fov = args.fov.unwrap_or((c.yfov as f64).to_degrees());
        return Ok(Camera::from_scene(c, fov, args.width, height));
    }
    let height = args.height.unwrap_or(args.width);
    if (args.eye, args.target, args.fov, args.hfov, args.up) == (None, None, None, None, None) {
        return Ok(Camera::standard_sized(frame, args.width, height));
    }
    let eye = args.eye.unwrap_or(Camera::standard(frame).eye);
    let mut camera = Camera::look_at(eye, args.target.unwrap_or(frame.c), args.fov.unwrap_or(45.0), args.width, height);
    if let Some(up) = args.up {
        // As a scene camera's up: the image's x axis is up x backward.
        let u = up.cross(camera.w).normalize_or_zero();
        anyhow::ensure!(u != DVec3::ZERO, "--up is zero or along the view direction");
        camera.u = u;
        camera.s = camera.w.cross(u);
    }
    if let Some(hfov) = args.hfov {
        camera.tan_half_fov = (hfov / 2.0).to_radians().tan() * height as f64 / args.width as f64;
    }
    Ok(camera)
}
