//! Bake benchmarks: `cargo bench -p octrace-bake`. `OCTRACE_BENCH_SMALL=1` bakes a
//! procedural sphere instead of the bunny (for CI).
use octrace_bake::{bake, procedural, BuildParams, Mesh};

fn main() {
    divan::main();
}

fn mesh() -> Mesh {
    if std::env::var_os("OCTRACE_BENCH_SMALL").is_some() {
        procedural::sphere([0.0; 3], 1.0, 32, 48)
    } else {
        Mesh::load(concat!(env!("CARGO_MANIFEST_DIR"), "/../assets/bunny.obj.zst")).expect("the repository's bunny")
    }
}

#[divan::bench(args = [8, 16, 32])]
fn bake_with_leaf_size(bencher: divan::Bencher, leaf: u32) {
    let mesh = mesh();
    let params = BuildParams { leaf_size: Some(leaf), ..BuildParams::auto() };
    bencher.counter(divan::counter::ItemsCount::new(mesh.triangles.len())).bench(|| bake(&mesh, &params).unwrap());
}

#[divan::bench]
fn bake_and_serialize(bencher: divan::Bencher) {
    let mesh = mesh();
    bencher.bench(|| bake(&mesh, &BuildParams::auto()).unwrap().to_file_bytes(0).unwrap().len());
}
