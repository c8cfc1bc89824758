//! Times loading and baking a mesh: `cargo run --release -p octrace-bake --example time_bake -- MESH`.
fn main() {
    let path = std::env::args().nth(1).expect("usage: time_bake MESH");
    let t = std::time::Instant::now();
    let mesh = octrace_bake::Mesh::load(&path).unwrap();
    let load = t.elapsed();
    let t = std::time::Instant::now();
    let stage_start = std::sync::Mutex::new((std::time::Instant::now(), None::<octrace_bake::BakeStage>));
    let leaf: Option<u32> = std::env::var("LEAF").ok().map(|s| s.parse().unwrap()); let depth: Option<u32> = std::env::var("DEPTH").ok().map(|s| s.parse().unwrap());
    let scene = octrace_bake::bake_with_progress(&mesh, &octrace_bake::BuildParams { leaf_size: leaf, max_depth: depth, ..octrace_bake::BuildParams::auto() }, &|s| {
        let mut g = stage_start.lock().unwrap();
        if let Some(prev) = g.1 { eprintln!("  {:?}: {:?}", prev, g.0.elapsed()); }
        *g = (std::time::Instant::now(), Some(s));
    }).unwrap();
    { let g = stage_start.lock().unwrap(); eprintln!("  {:?}: {:?}", g.1.unwrap(), g.0.elapsed()); }
    let bake = t.elapsed();
    let t = std::time::Instant::now();
    let b = scene.to_file_bytes(0).unwrap(); eprintln!("to_file_bytes {:?}", t.elapsed());
    let t2 = std::time::Instant::now(); std::fs::write("/tmp/nosync.oct", &b).unwrap(); eprintln!("plain write {:?}", t2.elapsed());
    let t = std::time::Instant::now();
    let bytes = scene.write("/tmp/time_bake.oct", 0).unwrap();
    let write = t.elapsed();
    let t = std::time::Instant::now();
    let f = octrace_format::SceneFile::read("/tmp/time_bake.oct").unwrap();
    let open = t.elapsed();
    let t = std::time::Instant::now();
    let f2 = unsafe { octrace_format::SceneFile::map("/tmp/time_bake.oct") }.unwrap();
    let mopen = t.elapsed();
    let t = std::time::Instant::now();
    let f3 = unsafe { octrace_format::SceneFile::map_unchecked("/tmp/time_bake.oct") }.unwrap();
    let topen = t.elapsed();
    let s = octrace_format::stats::SceneStatistics::compute(&f.view()).unwrap();
    println!("load {load:?} bake {bake:?} write {write:?} read {open:?} map {mopen:?} trusted {topen:?} bytes {bytes} leaves {} before {} params {:?}", s.leaves, scene.stats.leaves_before_balance, scene.params);
    println!("{s:#?}");
    let v = f3.view();
    let t = std::time::Instant::now(); let idx = v.index_tree().unwrap(); eprintln!("index_tree {:?}", t.elapsed());
    let t = std::time::Instant::now(); v.validate().unwrap(); eprintln!("validate {:?}", t.elapsed());
    let t = std::time::Instant::now(); let h = xxhash_rust_free(f3.payload()); eprintln!("sum-ish {:?} {h}", t.elapsed());
    drop((f2, idx));
}
fn xxhash_rust_free(b: &[u8]) -> u64 { b.iter().step_by(64).map(|&x| x as u64).sum() }
