//! Times each stage of loading and baking a mesh, writing it and reading it back
//! validated:
//! `cargo run --release -p octrace-bake --example time_bake -- MESH [LEAF_SIZE [MAX_DEPTH]]`.
use std::sync::Mutex;
use std::time::Instant;

use octrace_bake::{bake_with_progress, BakeStage, BuildParams, Mesh};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let path = args.next().ok_or("usage: time_bake MESH [LEAF_SIZE [MAX_DEPTH]]")?;
    let leaf_size = args.next().map(|s| s.parse()).transpose()?;
    let max_depth = args.next().map(|s| s.parse()).transpose()?;
    let t = Instant::now();
    let mesh = Mesh::load(&path)?;
    println!("load      {:>8.1} ms", t.elapsed().as_secs_f64() * 1e3);
    let params = BuildParams { leaf_size, max_depth, ..BuildParams::auto() };
    let stage: Mutex<Option<(BakeStage, Instant)>> = Mutex::new(None);
    let report = |next: Option<BakeStage>| {
        let mut s = stage.lock().expect("not poisoned");
        if let Some((prev, since)) = s.take() {
            println!("{:<9} {:>8.1} ms", format!("{prev:?}").to_lowercase(), since.elapsed().as_secs_f64() * 1e3);
        }
        *s = next.map(|n| (n, Instant::now()));
    };
    let t = Instant::now();
    let scene = bake_with_progress(&mesh, &params, &|s| report(Some(s)))?;
    report(None);
    println!("bake      {:>8.1} ms", t.elapsed().as_secs_f64() * 1e3);
    let dir = std::env::temp_dir().join("octrace-time-bake.oct");
    let t = Instant::now();
    let bytes = scene.write(&dir, 0)?;
    println!("write     {:>8.1} ms ({bytes} bytes)", t.elapsed().as_secs_f64() * 1e3);
    let t = Instant::now();
    let file = octrace_format::SceneFile::read(&dir)?;
    println!("read      {:>8.1} ms (validated, into memory)", t.elapsed().as_secs_f64() * 1e3);
    let t = Instant::now();
    file.view().validate()?;
    println!("validate  {:>8.1} ms (semantic rules alone)", t.elapsed().as_secs_f64() * 1e3);
    println!(
        "leaves {} ({} before balance), {:?}",
        scene.leaf_count(),
        scene.stats.leaves_before_balance,
        scene.params
    );
    std::fs::remove_file(dir)?;
    Ok(())
}
