//! `octrace demo`: the whole pipeline on the bunny this build carries.

use std::time::Instant;

use octrace_bake::{BuildParams, Mesh, MeshFormat};
use octrace_runtime::raysets::{self, Camera, Frame};
use octrace_runtime::render::effects::{render_effects, RayKind, RenderOptions};
use octrace_runtime::render::{render, RenderMode};

use crate::output::thousands;

/// The Stanford bunny (69,451 triangles), zstd-compressed OBJ, built into the binary
/// so the demo runs from anywhere.
pub(crate) const BUNNY: &[u8] = include_bytes!("../../../assets/bunny.obj.zst");

#[derive(clap::Args, Debug)]
pub(crate) struct Args {
    /// Where to write the rendering (default: demo.png, or effects.png for --scene effects).
    #[arg(short, long)]
    pub output: Option<std::path::PathBuf>,
    /// bunny: bake, inspect, render and measure the bunny; effects: a procedural scene
    /// with every effect (mirror, glass, blended pane, area light, hard and soft shadows).
    #[arg(long, value_enum, default_value_t = DemoScene::Bunny)]
    pub scene: DemoScene,
    /// Also keep the baked scene there (to render it again with other options).
    #[arg(long)]
    pub save_scene: Option<std::path::PathBuf>,
}

#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum DemoScene {
    Bunny,
    Effects,
}

pub(crate) fn run(args: Args) -> anyhow::Result<()> {
    match args.scene {
        DemoScene::Bunny => bunny(&args.output.unwrap_or_else(|| "demo.png".into()), args.save_scene.as_deref()),
        DemoScene::Effects => effects(&args.output.unwrap_or_else(|| "effects.png".into()), args.save_scene.as_deref()),
    }
}

/// Writes the baked scene where `--save-scene` says, else into a temporary folder
/// (which the returned guard removes).
fn write_scene(
    scene: &octrace_format::BakedScene,
    name: &str,
    save: Option<&std::path::Path>,
    bake_us: u64,
) -> anyhow::Result<(std::path::PathBuf, u64, Option<tempfile::TempDir>)> {
    let (path, dir) = match save {
        Some(p) => (p.to_path_buf(), None),
        None => {
            let dir = tempfile::tempdir()?;
            (dir.path().join(name), Some(dir))
        }
    };
    let bytes = scene.write(&path, bake_us)?;
    Ok((path, bytes, dir))
}

/// Bakes the effects scene, lists its effects, renders it with all of them.
fn effects(output: &std::path::Path, save: Option<&std::path::Path>) -> anyhow::Result<()> {
    let mesh = octrace_bake::procedural::effects_scene();
    let progress = super::bake::Progress::new();
    let (scene, bake_time) = super::bake::bake_mesh(&mesh, &BuildParams::auto(), &progress)?;
    progress.finish();
    let (path, bytes, _dir) = write_scene(&scene, "effects.oct", save, bake_time.as_micros() as u64)?;
    let scene = crate::open::open_scene(&path)?;
    let report = super::inspect::Report::new(&scene.view(), scene.file().expect("from a file").header(), bytes)?;
    crate::out!("{}", report.text("effects.oct"));
    let c = &scene.shading().cameras[0];
    let camera = Camera::from_scene(c, (c.yfov as f64).to_degrees(), 800, 600);
    let options = RenderOptions::for_scene(scene.shading());
    let bar = super::render::RowsBar::new(camera.height);
    let t = Instant::now();
    let (radiance, counts) = render_effects(&scene, &camera, &options, &|rows| bar.set(rows));
    let secs = t.elapsed().as_secs_f64();
    bar.finish();
    radiance.to_image().write_png(output)?;
    crate::out!(
        "rendered {} (800 x 600, every effect, {} soft-shadow samples) in {secs:.2} s on {}: {} rays",
        crate::show(output),
        options.soft_samples,
        crate::output::counted(rayon::current_num_threads() as u64, "thread"),
        thousands(counts.total())
    );
    for kind in RayKind::ALL {
        crate::out!("  {:<12} {:>12}", kind.name(), thousands(counts.get(kind)));
    }
    Ok(())
}

/// Bakes, inspects, renders and measures the bunny.
fn bunny(output: &std::path::Path, save: Option<&std::path::Path>) -> anyhow::Result<()> {
    let obj = zstd::stream::decode_all(BUNNY)?;
    let mesh = Mesh::from_bytes(&obj, MeshFormat::Obj, "bunny.obj".as_ref(), None)?;
    let progress = super::bake::Progress::new();
    let (scene, bake_time) = super::bake::bake_mesh(&mesh, &BuildParams::auto(), &progress)?;
    progress.finish();
    let (path, bytes, _dir) = write_scene(&scene, "bunny.oct", save, bake_time.as_micros() as u64)?;
    // A temporary file is gone when the demo ends: named only when it is kept.
    let kept = match save {
        Some(_) => crate::show(&path),
        None => "a temporary file (--save-scene keeps it)".to_string(),
    };
    crate::out!("baked the bunny in {:.2} s: {} bytes -> {kept}", bake_time.as_secs_f64(), thousands(bytes));
    let scene = crate::open::open_scene(&path)?;
    let file = scene.file().expect("from a file");
    let report = super::inspect::Report::new(&scene.view(), file.header(), bytes)?;
    crate::out!("{}", report.text("bunny.oct"));

    let frame = Frame::from_bounds(scene.view().bounds.mesh_lo, scene.view().bounds.mesh_hi);
    let (image, _) = render(&scene, &Camera::standard(&frame), RenderMode::Shaded);
    image.write_png(output)?;
    crate::out!("rendered {}", crate::show(output));

    let rays = raysets::primary(&frame);
    let tracer = scene.tracer();
    let mut hits = vec![None; rays.len()];
    let mut best = f64::INFINITY;
    for _ in 0..3 {
        let t = Instant::now();
        tracer.intersect_batch(&rays, &mut hits);
        best = best.min(t.elapsed().as_secs_f64());
    }
    let t = Instant::now();
    tracer.par_intersect_batch(&rays, &mut hits);
    let all = t.elapsed().as_secs_f64();
    crate::out!(
        "primary rays (1024 x 1024, bench/RAYS.md): {:.2} Mrays/s on one thread, {:.2} Mrays/s on {}; {} hits",
        rays.len() as f64 / best / 1e6,
        rays.len() as f64 / all / 1e6,
        crate::output::counted(rayon::current_num_threads() as u64, "thread"),
        thousands(hits.iter().flatten().count() as u64)
    );
    Ok(())
}
