//! Times each part of a validated open:
//! `cargo run --release -p octrace-format --example time_open -- SCENE.oct`.
use std::time::Instant;

use octrace_format::SceneFile;

fn ms(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let path = std::env::args().nth(1).ok_or("usage: time_open SCENE.oct")?;
    let t = Instant::now();
    // SAFETY: a timing tool reading a file nobody writes meanwhile.
    let file = unsafe { SceneFile::map_unchecked(&path)? };
    println!("map + header      {:>7.2} ms", ms(t));
    let t = Instant::now();
    let payload = file.payload();
    let sums: Vec<u64> = file
        .header()
        .sections
        .iter()
        .map(|s| xxhash_rust::xxh3::xxh3_64(s.bytes(payload).unwrap_or_default()))
        .collect();
    println!("section xxh3s     {:>7.2} ms (one thread; {} sections)", ms(t), sums.len());
    let t = Instant::now();
    let view = file.view();
    let index = view.index_tree()?;
    println!("point-location    {:>7.2} ms ({} leaves)", ms(t), index.leaf_keys.len());
    let t = Instant::now();
    view.validate()?;
    println!("semantic rules    {:>7.2} ms (tree walk included)", ms(t));
    let t = Instant::now();
    // SAFETY: as above.
    drop(unsafe { SceneFile::map(&path)? });
    println!("validated map     {:>7.2} ms (all of it)", ms(t));
    Ok(())
}
