//! `octrace rays`: the standard ray sets as files, for `octrace trace` and other tools.

use std::path::PathBuf;

use octrace_runtime::raysets::{self, Frame};

use crate::output::thousands;

/// Write a standard ray set of bench/RAYS.md for a scene, in the 32-byte
/// format `octrace trace` reads (f32 `ox oy oz tmin dx dy dz tmax`, little-endian).
#[derive(clap::Args, Debug)]
pub(crate) struct Args {
    /// The .oct scene whose frame the rays are made for.
    pub scene: PathBuf,
    /// primary (1024 x 1024 camera rays), incoherent (1,000,000 random rays) or shadow
    /// (from each primary hit towards the standard light; for `trace --occluded`).
    #[arg(long, value_enum, default_value_t = Set::Primary)]
    pub set: Set,
    /// The file to write; `-` writes the rays to standard output. Never the scene.
    #[arg(short, long)]
    pub output: PathBuf,
}

#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub(crate) enum Set {
    Primary,
    Incoherent,
    Shadow,
}

pub(crate) fn run(args: Args) -> anyhow::Result<()> {
    crate::output::refuse_overwriting(&args.output, "-o", &[&args.scene])?;
    let scene = crate::open::open_scene(&args.scene)?;
    let b = scene.view().bounds;
    let frame = Frame::from_bounds(b.mesh_lo, b.mesh_hi);
    let rays = match args.set {
        Set::Primary => raysets::primary(&frame),
        Set::Incoherent => raysets::incoherent(&frame, 1_000_000),
        Set::Shadow => {
            // As `bench` makes them: the primary set traced here, one ray a hit.
            let primary = raysets::primary(&frame);
            let hits = scene.intersect_batch(&primary);
            let view = scene.view();
            raysets::shadow(&frame, |i| hits[i].map(|h| (h.t, view.triangle(h.prim))))
        }
    };
    crate::output::write_data(&args.output, &[bytemuck::cast_slice(&rays)])?;
    crate::report!(
        crate::output::is_stdout(&args.output),
        "wrote {} {} rays to {}",
        thousands(rays.len() as u64),
        crate::output::choice(args.set),
        crate::show(&args.output)
    );
    Ok(())
}
