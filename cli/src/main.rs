//! `octrace`: bake triangle meshes into octrace's constrained octree, inspect the
//! baked files, trace rays through them, render and benchmark them.
#![deny(unsafe_code)]

/// The long help's paragraph on memory-mapped scenes, for the commands that map one
/// (`inspect`, `trace`, `render`).
macro_rules! mapped_scene_help {
    () => {
        "The scene is memory-mapped: if the file is truncated or rewritten in place while this
runs, the process may die of SIGBUS or read wrong data. Replace baked files by renaming
a new file over the old one (as `octrace bake` does), never by writing into them; a
.oct.zst scene, and on Linux one of 16 MiB to 2 GiB, is read into memory instead."
    };
}

mod cmd;
mod memory;
mod open;
mod output;
mod world_file;
// Bindings to a C library, behind its feature (the other unsafe code: mapping files in
// `open`, the allocator's setting in `memory`).
#[cfg(feature = "embree")]
#[allow(unsafe_code)]
mod embree;
#[cfg(feature = "obvhs")]
mod peer;

use std::path::Path;
use std::process::ExitCode;

use clap::{Parser, Subcommand};

/// Bake triangle meshes into a neighbour-linked octree file, and trace rays through it.
///
/// A typical pipeline bakes once and traces many times:
///
///   octrace bake scene.glb -o scene.oct
///   octrace inspect scene.oct
///   octrace render scene.oct -o scene.png
///
/// `octrace demo` does all of it on the bunny this build carries.
#[derive(Parser, Debug)]
#[command(name = "octrace", version, about, long_about, verbatim_doc_comment)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Bake a mesh (OBJ, glTF, GLB; optionally .zst) into an .oct file.
    ///
    /// The file is written to a temporary name beside OUT and renamed when complete:
    /// an interrupted bake never leaves a partial OUT. The same input and options give
    /// the same file, byte for byte, whatever the machine or thread count (unless
    /// --record-time writes the bake's duration into the header).
    Bake(cmd::bake::Args),
    /// Print a baked file's statistics: counts, depth histogram, neighbours and
    /// triangles per leaf, bytes per array, bake parameters.
    Inspect(cmd::inspect::Args),
    /// Trace a file of rays and write the hits (the formats: `octrace trace --help`).
    Trace(cmd::trace::Args),
    /// Write a standard ray set (bench/RAYS.md) to a file for `trace`.
    Rays(cmd::rays::Args),
    /// Whether points lie inside a closed mesh (the formats: `octrace contains --help`).
    Contains(cmd::contains::Args),
    /// The nearest point of the surface to each point and its distance, signed with
    /// --signed, exact (the formats: `octrace distance --help`).
    Distance(cmd::distance::Args),
    /// Write a standard point set (uniform in the box, or near the surface) for
    /// `contains`.
    Points(cmd::contains::PointsArgs),
    /// Render a baked scene to PNG.
    Render(cmd::render::Args),
    /// Check a file's invariants and compare the tracer with the f64 oracle.
    Verify(cmd::verify::Args),
    /// Count rays leaking out of closed meshes (every one should hit).
    Soak(cmd::soak::Args),
    /// Measure Mrays/s on the standard ray sets (bench/RAYS.md), against obvhs.
    Bench(cmd::bench::Args),
    /// Bake the bunny this build carries, inspect it, render demo.png, measure it.
    Demo(cmd::demo::Args),
    /// What accuracy costs in time: each accuracy knob's Mrays/s next to its error
    /// against the f64 oracle, written to report.md and report.json.
    Report(cmd::report::Args),
}

fn main() -> ExitCode {
    quiet_display_probe();
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Bake(a) => cmd::bake::run(a),
        Command::Inspect(a) => cmd::inspect::run(a),
        Command::Trace(a) if world_file::is_world(&a.scene) => cmd::trace::run_world(a),
        Command::Trace(a) if a.along() => cmd::trace_crossings::run(a),
        Command::Trace(a) => cmd::trace::run(a),
        Command::Rays(a) => cmd::rays::run(a),
        Command::Contains(a) if world_file::is_world(&a.scene) => cmd::contains::run_world(a),
        Command::Contains(a) => cmd::contains::run(a),
        Command::Distance(a) if world_file::is_world(&a.scene) => cmd::distance::run_world(a),
        Command::Distance(a) => cmd::distance::run(a),
        Command::Points(a) => cmd::contains::points(a),
        Command::Render(a) => cmd::render::run(a),
        Command::Bench(a) => cmd::bench::run(a),
        Command::Verify(a) => cmd::verify::run(a),
        Command::Soak(a) => cmd::soak::run(a),
        Command::Demo(a) => cmd::demo::run(a),
        Command::Report(a) => cmd::report::run(a),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        // A closed pipe (`octrace inspect x.oct | head`) is not a failure.
        Err(e) if is_broken_pipe(&e) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("octrace: error: {}", output::printable(&message(&e)));
            ExitCode::FAILURE
        }
    }
}

/// Opening Vulkan (`--gpu`) probes for a Wayland display, and without
/// `XDG_RUNTIME_DIR` libwayland writes "error: XDG_RUNTIME_DIR is invalid or not set in
/// the environment." to standard error, once per probe, although nothing is wrong: no
/// display is needed. Where the variable is unset (or not an absolute path, which
/// libwayland refuses alike) this points it at a path that does not exist, so the probe
/// finds no display quietly. A session with a display has the variable and is left as
/// it is.
fn quiet_display_probe() {
    let set = std::env::var_os("XDG_RUNTIME_DIR").is_some_and(|d| Path::new(&d).is_absolute());
    if !set {
        // Single-threaded still: nothing else reads the environment yet.
        std::env::set_var("XDG_RUNTIME_DIR", std::env::temp_dir().join("octrace-no-display"));
    }
}

/// The error and its causes joined by ": ", leaving out a cause whose text the
/// message already holds (library errors often quote their source).
fn message(e: &anyhow::Error) -> String {
    let mut text = String::new();
    for cause in e.chain() {
        let part = cause.to_string();
        if text.contains(&part) {
            continue;
        }
        if !text.is_empty() {
            text.push_str(": ");
        }
        text.push_str(&part);
    }
    text
}

fn is_broken_pipe(e: &anyhow::Error) -> bool {
    e.chain().any(|c| c.downcast_ref::<std::io::Error>().is_some_and(|io| io.kind() == std::io::ErrorKind::BrokenPipe))
}

/// The most threads `--threads` asks for: each is a stack of its own, and a pool
/// of 100,000 never finishes starting.
pub(crate) const MAX_THREADS: usize = 1024;

/// Runs `f` on a rayon pool of `threads` threads (all cores when `None`).
pub(crate) fn with_threads<T: Send>(threads: Option<usize>, f: impl FnOnce() -> T + Send) -> anyhow::Result<T> {
    let mut b = rayon::ThreadPoolBuilder::new();
    if let Some(n) = threads {
        anyhow::ensure!((1..=MAX_THREADS).contains(&n), "--threads must be from 1 to {MAX_THREADS}");
        b = b.num_threads(n);
    }
    Ok(b.build()?.install(f))
}

/// Paths given on the command line, for messages.
pub(crate) fn show(p: &std::path::Path) -> String {
    p.display().to_string()
}
