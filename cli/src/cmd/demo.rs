//! `octrace demo`: the whole pipeline on the bunny this build carries.

use std::time::Instant;

use octrace_bake::{BuildParams, Mesh, MeshFormat};
use octrace_runtime::raysets::{self, Camera, Frame};
use octrace_runtime::render::{render, RenderMode};

use crate::output::thousands;

/// The Stanford bunny (69,451 triangles), zstd-compressed OBJ, built into the binary
/// so the demo runs from anywhere.
const BUNNY: &[u8] = include_bytes!("../../../assets/bunny.obj.zst");

#[derive(clap::Args, Debug)]
pub(crate) struct Args {
    /// Where to write the rendering.
    #[arg(short, long, default_value = "demo.png")]
    pub output: std::path::PathBuf,
}

pub(crate) fn run(args: Args) -> anyhow::Result<()> {
    let obj = zstd::stream::decode_all(BUNNY)?;
    let mesh = Mesh::from_bytes(&obj, MeshFormat::Obj, "bunny.obj".as_ref(), None)?;
    let progress = super::bake::Progress::new();
    let (scene, bake_time) = super::bake::bake_mesh(&mesh, &BuildParams::auto(), &progress)?;
    progress.finish();
    let dir = tempfile::tempdir()?;
    let path = dir.path().join("bunny.oct");
    let bytes = scene.write(&path, bake_time.as_micros() as u64)?;
    crate::out!("baked the bunny in {:.2} s: {} -> {}", bake_time.as_secs_f64(), thousands(bytes), crate::show(&path));
    let scene = crate::open::open_scene(&path)?;
    let file = scene.file().expect("from a file");
    let report = super::inspect::Report::new(&scene.view(), file.header(), bytes)?;
    crate::out!("{}", report.text("bunny.oct"));

    let frame = Frame::from_bounds(scene.view().bounds.mesh_lo, scene.view().bounds.mesh_hi);
    let (image, _) = render(&scene, &Camera::standard(&frame), RenderMode::Shaded);
    image.write_png(&args.output)?;
    crate::out!("rendered {}", crate::show(&args.output));

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
        "primary rays (1024 x 1024, shared/bench/RAYS.md): {:.2} Mrays/s on one thread, {:.2} Mrays/s on {} threads; {} hits",
        rays.len() as f64 / best / 1e6,
        rays.len() as f64 / all / 1e6,
        rayon::current_num_threads(),
        thousands(hits.iter().flatten().count() as u64)
    );
    Ok(())
}
