//! `octrace bake`.

use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::Context;
use octrace_bake::{bake_with_progress, BakeStage, BuildParams, InstancedMesh, LoadOptions, Loaded, Mesh, References};
use octrace_format::instanced::{InstanceRecord, InstancedFile};
use octrace_format::BakedScene;

use crate::output::{counted, mb, thousands};

#[derive(clap::Args, Debug)]
pub(crate) struct Args {
    /// Mesh to bake: .obj, .gltf or .glb, optionally compressed as .zst.
    pub input: PathBuf,
    /// The .oct file to write; `-` writes it to standard output (the summary then goes
    /// to standard error). (A bake killed outright leaves its temporary
    /// .octrace-XXXX.tmp beside it, which may be deleted.)
    #[arg(short, long)]
    pub output: PathBuf,
    /// Deepest octree level (root = 0). Default: ceil(log4(triangles / leaf size)) (bunny 7, dragon 8).
    /// Scenes far from the origin are limited further, so that cells stay wider than
    /// four f32 spacings of their coordinates.
    #[arg(long)]
    pub max_depth: Option<u32>,
    /// Split a cell while it holds more triangles than this (at least 1).
    #[arg(long, default_value_t = octrace_bake::octree::DEFAULT_LEAF_SIZE,
          value_parser = clap::value_parser!(u32).range(1..))]
    pub leaf_size: u32,
    /// Enlarge cells by this fraction of the root edge when assigning triangles
    /// (0 to 2^-10 = 0.0009765625: past that every triangle is copied into a growing
    /// cube of cells).
    #[arg(long, default_value_t = octrace_bake::octree::DEFAULT_MARGIN)]
    pub margin: f32,
    /// Threads to bake with (default: all cores; at most 1024). The output does not
    /// depend on it.
    #[arg(long)]
    pub threads: Option<usize>,
    /// Let the mesh read files outside its own folder: absolute paths, `file:` URIs and
    /// `..` in glTF buffer URIs and OBJ `mtllib` lines. Only for inputs you trust; by
    /// default such a buffer is an error and such a material library a warning. Devices,
    /// FIFOs and files over the size limit are refused either way.
    #[arg(long)]
    pub allow_outside_references: bool,
    /// The bake's memory budget: the bytes the octree may hold while it is built (4 a
    /// triangle reference, about 100 a leaf; the bake's peak is about twice this plus
    /// the mesh). Suffixes K, M, G, T (powers of 1024). A bake that passes it stops
    /// there with an error. Default: 1 KiB a triangle, at least 2 GiB, at most a third
    /// of the memory this process may use (physical memory, or `ulimit -v` where
    /// lower): a 56-million-triangle mesh gets 7.8 GB on a 24 GB machine, a handful of
    /// triangles that share cells at every depth stop at 2 GiB.
    #[arg(long, value_name = "BYTES", value_parser = crate::output::parse_bytes)]
    pub max_memory: Option<u64>,
    /// The most node placements a glTF scene may make (a node listed twice, or under
    /// two parents, is placed twice, and its children with it); counted before loading.
    #[arg(long, value_name = "N", default_value_t = octrace_bake::DEFAULT_MAX_INSTANCES)]
    pub max_instances: u64,
    /// The most triangles the mesh may hold once instanced; counted before loading a
    /// glTF's.
    #[arg(long, value_name = "N", default_value_t = octrace_bake::DEFAULT_MAX_TRIANGLES)]
    pub max_triangles: u64,
    /// Record the bake's duration in the file's header. Off by default, so that two
    /// bakes of the same input with the same options give identical files.
    #[arg(long)]
    pub record_time: bool,
    /// Accepted for older scripts: bakes are reproducible by default now.
    #[arg(long, hide = true, conflicts_with = "record_time")]
    pub reproducible: bool,
    /// Store textures as texels rather than as their PNG or JPEG images: a larger file
    /// (DamagedHelmet: 85.8 MB rather than 5.5 MB) whose renders decode nothing
    /// first (DamagedHelmet's five 2048² JPEGs: 0.16 s on two cores).
    #[arg(long)]
    pub raw_texels: bool,
    /// Write the file zstd-compressed (name it .oct.zst): smaller on disk, read into
    /// memory when opened instead of memory-mapped.
    #[arg(long)]
    pub compress: bool,
    /// Bake the closest-point search's tree into the file (its `distance` section, about
    /// 24 bytes a triangle: the dragon's file 1.34x as large, its bake 1.34x as long), so
    /// that the scene's first closest-point, distance or signed-distance query makes
    /// nothing (without it, the first query makes the tree: 0.3-0.4 s for the dragon).
    #[arg(long)]
    pub distance: bool,
    /// Bake every placement's triangles into one scene, even where a glTF places a mesh
    /// many times. By default such a mesh (placed by several nodes, by
    /// EXT_mesh_gpu_instancing, or meshes sharing its accessors) is baked once and its
    /// placements written as instances: an instanced file, which trace, render,
    /// contains, distance and inspect open as a world of instances (Python:
    /// octrace.World.open). MetalRoughSpheresNoTextures: 98 spheres of one mesh, 1.4 MB
    /// instead of 134 MB.
    #[arg(long)]
    pub flatten: bool,
    /// zstd level for --compress (1-22).
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(i32).range(1..=22))]
    pub level: i32,
}

pub(crate) fn run(args: Args) -> anyhow::Result<()> {
    crate::memory::return_large_frees();
    let params = BuildParams {
        max_depth: args.max_depth,
        leaf_size: Some(args.leaf_size),
        margin: args.margin,
        max_tree_bytes: args.max_memory,
        distance: args.distance,
    };
    // Each limit's message names its option.
    params.check()?;
    let progress = Progress::new();
    progress.stage("loading");
    let started = Instant::now();
    crate::output::refuse_overwriting(&args.output, "-o", &[&args.input])?;
    let references = if args.allow_outside_references { References::Anywhere } else { References::Confined };
    let options = LoadOptions {
        references,
        max_instances: args.max_instances,
        max_triangles: args.max_triangles,
        ..LoadOptions::default()
    };
    let loaded = if args.flatten {
        Loaded::One(Mesh::load_with(&args.input, &options)?)
    } else {
        Mesh::load_instanced(&args.input, &options)?
    };
    let mut mesh = match loaded {
        Loaded::One(mesh) => mesh,
        Loaded::Instanced(instanced) => return bake_instanced(&args, instanced, &params, &progress, started),
    };
    if args.raw_texels {
        mesh.store_texels();
    }
    let sources: Vec<&Path> = mesh.sources.iter().map(PathBuf::as_path).collect();
    crate::output::refuse_overwriting(&args.output, "-o", &sources)?;
    for w in &mesh.warnings {
        progress.warn(w);
    }
    let (scene, bake_time) = crate::with_threads(args.threads, || bake_mesh(&mesh, &params, &progress))??;
    if let Some(w) = octrace_bake::octree::degenerate_warning(&scene) {
        progress.warn(&w);
    }
    // The scene holds its own copy of everything it needs: the mesh is not held through
    // the write.
    drop(mesh);
    progress.stage("writing");
    let time_us = if args.record_time { bake_time.as_micros() as u64 } else { 0 };
    let to_stdout = crate::output::is_stdout(&args.output);
    let (bytes, on_disk) = if to_stdout {
        // `-o -`: the file's bytes to standard output, as `render`, `trace` and `rays`.
        let image = scene.to_file_bytes(time_us)?;
        let n = image.len() as u64;
        if args.compress {
            let compressed = zstd::bulk::compress(&image, args.level).context("compressing the scene")?;
            crate::output::write_data(&args.output, &[&compressed])?;
            (n, format!(" (zstd: {})", mb(compressed.len() as u64)))
        } else {
            crate::output::write_data(&args.output, &[&image])?;
            (n, String::new())
        }
    } else if args.compress {
        let (raw, compressed) = scene.write_compressed(&args.output, time_us, args.level)?;
        (raw, format!(" (zstd: {} on disk)", mb(compressed)))
    } else {
        (scene.write(&args.output, time_us)?, String::new())
    };
    progress.finish();
    crate::report!(
        to_stdout,
        "baked {}: {} ({} degenerate) -> {}, depth {}{}, {}{} in {:.2} s (bake {:.2} s) -> {}",
        crate::show(&args.input),
        counted(scene.stats.input_triangles, "triangle"),
        thousands(scene.stats.degenerate_triangles),
        counted(scene.leaf_count() as u64, "leaf"),
        scene.params.max_depth,
        depth_note(&scene, &params),
        mb(bytes),
        on_disk,
        started.elapsed().as_secs_f64(),
        bake_time.as_secs_f64(),
        crate::show(&args.output),
    );
    Ok(())
}

/// Bakes each mesh of `instanced` into a scene of its own and writes them with their
/// placements as an instanced file.
fn bake_instanced(
    args: &Args,
    mut instanced: InstancedMesh,
    params: &BuildParams,
    progress: &Progress,
    started: Instant,
) -> anyhow::Result<()> {
    let flatten = "or bake with --flatten for one scene";
    anyhow::ensure!(
        !crate::output::is_stdout(&args.output),
        "{} places meshes more than once: its bake is an instanced file, written to a named file, not to standard \
         output (give -o a path, {flatten})",
        crate::show(&args.input)
    );
    anyhow::ensure!(
        !args.compress,
        "{} places meshes more than once: its instanced file is not written compressed (drop --compress, {flatten})",
        crate::show(&args.input)
    );
    let sources: Vec<&Path> = instanced.sources.iter().map(PathBuf::as_path).collect();
    crate::output::refuse_overwriting(&args.output, "-o", &sources)?;
    for w in &instanced.warnings {
        progress.warn(w);
    }
    let placed = instanced.placed_triangles();
    let stored = instanced.stored_triangles();
    let (mut files, mut leaves, mut bake_time) = (Vec::new(), 0u64, Duration::ZERO);
    for mesh in &mut instanced.meshes {
        if args.raw_texels {
            mesh.store_texels();
        }
        let (scene, t) = crate::with_threads(args.threads, || bake_mesh(mesh, params, progress))??;
        if let Some(w) = octrace_bake::octree::degenerate_warning(&scene) {
            progress.warn(&w);
        }
        bake_time += t;
        leaves += scene.leaf_count() as u64;
        let time_us = if args.record_time { t.as_micros() as u64 } else { 0 };
        files.push(scene.to_file_bytes(time_us)?);
    }
    progress.stage("writing");
    let instances: Vec<InstanceRecord> =
        instanced.placements.iter().map(|p| InstanceRecord { scene: p.mesh, rows: p.rows, map: p.map }).collect();
    let table = InstancedFile { scenes: Vec::new(), maps: std::mem::take(&mut instanced.maps), instances };
    table.write(&args.output, &files)?;
    let bytes = std::fs::metadata(&args.output).map(|m| m.len()).unwrap_or(0);
    progress.finish();
    crate::report!(
        false,
        "baked {}: {} placed {} ({} triangles stored for {} placed) -> {}, {} in {:.2} s (bake {:.2} s) -> {} \
         (instanced)",
        crate::show(&args.input),
        counted(instanced.meshes.len() as u64, "mesh"),
        counted(table.instances.len() as u64, "time"),
        thousands(stored),
        thousands(placed),
        counted(leaves, "leaf"),
        mb(bytes),
        started.elapsed().as_secs_f64(),
        bake_time.as_secs_f64(),
        crate::show(&args.output),
    );
    Ok(())
}

/// What limited the depth, when it is less than asked for (or than the automatic
/// choice): `" (12 asked; f32 precision allows 3 at this position)"`, else nothing.
pub(crate) fn depth_note(scene: &BakedScene, params: &BuildParams) -> String {
    let kept = (scene.stats.input_triangles - scene.stats.degenerate_triangles) as usize;
    let wanted = params.resolve(kept).max_depth;
    let allowed = octrace_bake::octree::precision_depth(scene.bounds.root_lo, scene.bounds.root_size);
    if scene.params.max_depth < wanted {
        let how = if params.max_depth.is_some() { "asked" } else { "automatic" };
        format!(" ({wanted} {how}; f32 precision allows {allowed} at this position)")
    } else {
        String::new()
    }
}

/// Bakes with stage reports, returning the scene and the bake's wall time.
pub(crate) fn bake_mesh(
    mesh: &Mesh,
    params: &BuildParams,
    progress: &Progress,
) -> anyhow::Result<(BakedScene, Duration)> {
    let t = Instant::now();
    let scene = bake_with_progress(mesh, params, &|s: BakeStage| progress.stage(s.name())).context("bake failed")?;
    Ok((scene, t.elapsed()))
}

/// A spinner with the current stage on a terminal; silent otherwise.
pub(crate) struct Progress {
    bar: Option<indicatif::ProgressBar>,
}

impl Progress {
    pub(crate) fn new() -> Progress {
        let bar = std::io::stderr().is_terminal().then(|| {
            let bar = indicatif::ProgressBar::new_spinner();
            bar.set_style(
                indicatif::ProgressStyle::with_template("{spinner} {elapsed:>3} {msg}").expect("valid template"),
            );
            bar.enable_steady_tick(Duration::from_millis(100));
            bar
        });
        Progress { bar }
    }

    pub(crate) fn stage(&self, name: &str) {
        if let Some(b) = &self.bar {
            b.set_message(name.to_string());
        }
    }

    pub(crate) fn warn(&self, msg: &str) {
        let msg = crate::output::printable(msg);
        match &self.bar {
            Some(b) => b.println(format!("warning: {msg}")),
            None => eprintln!("warning: {msg}"),
        }
    }

    pub(crate) fn finish(&self) {
        if let Some(b) = &self.bar {
            b.finish_and_clear();
        }
    }
}

/// Whether a path names a baked scene (`.oct`, or `.oct.zst` compressed) rather than
/// a mesh.
pub(crate) fn is_scene(path: &Path) -> bool {
    let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("").to_ascii_lowercase();
    name.ends_with(".oct") || name.ends_with(".oct.zst")
}
