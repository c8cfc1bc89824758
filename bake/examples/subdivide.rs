//! Makes a big test mesh without committing one: splits every triangle of a mesh into
//! four (at its edges' midpoints), `n` times, and writes the result as a binary glTF
//! (one non-indexed triangle list: 36 bytes a triangle, at most 4 GiB), or as OBJ for
//! an output named `.obj` (three `v` lines and an `f -3 -2 -1` a triangle, coordinates
//! written so that they read back exactly).
//!
//! ```sh
//! cargo run --release -p octrace-bake --example subdivide -- ../shared/meshes/dragon.obj 3 dragon64.glb
//! cargo run --release -p octrace-bake --example subdivide -- ../shared/meshes/dragon.obj 1 dragon4.obj
//! ```
//!
//! The dragon (871,414 triangles) split 1, 2 and 3 times gives 3.5 M, 13.9 M and
//! 55.8 M triangles: the meshes of BENCHMARKS.md's "Scale" section.

use std::io::Write;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let [_, input, times, output] = &args[..] else {
        return Err("usage: subdivide MESH TIMES OUT.glb|OUT.obj".into());
    };
    let times: u32 = times.parse()?;
    let mut triangles = octrace_bake::Mesh::load(input)?.triangles;
    for _ in 0..times {
        triangles = triangles.iter().flat_map(split).collect();
    }
    if output.ends_with(".obj") {
        let mut out = std::io::BufWriter::with_capacity(1 << 22, std::fs::File::create(output)?);
        writeln!(out, "# {} split {times} times by octrace-bake examples/subdivide", input)?;
        for t in &triangles {
            for v in t {
                writeln!(out, "v {} {} {}", v[0], v[1], v[2])?;
            }
            writeln!(out, "f -3 -2 -1")?;
        }
        out.flush()?;
        println!("{} triangles ({} split {times} times) -> {output}", triangles.len(), input);
        return Ok(());
    }
    let bytes = triangles.len() as u64 * 36;
    if bytes + 1024 > u64::from(u32::MAX) {
        return Err(format!("{} triangles need {bytes} bytes: more than a GLB holds", triangles.len()).into());
    }
    let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
    for v in triangles.iter().flatten() {
        for a in 0..3 {
            lo[a] = lo[a].min(v[a]);
            hi[a] = hi[a].max(v[a]);
        }
    }
    let vertices = 3 * triangles.len();
    let json = format!(
        r#"{{"asset":{{"version":"2.0","generator":"octrace-bake examples/subdivide"}},"scene":0,"scenes":[{{"nodes":[0]}}],"nodes":[{{"mesh":0}}],"meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}}}}]}}],"buffers":[{{"byteLength":{bytes}}}],"bufferViews":[{{"buffer":0,"byteLength":{bytes}}}],"accessors":[{{"bufferView":0,"componentType":5126,"count":{vertices},"type":"VEC3","min":[{},{},{}],"max":[{},{},{}]}}]}}"#,
        lo[0], lo[1], lo[2], hi[0], hi[1], hi[2]
    );
    let mut json = json.into_bytes();
    while json.len() % 4 != 0 {
        json.push(b' ');
    }
    let total = 12 + 8 + json.len() as u64 + 8 + bytes;
    let mut out = std::io::BufWriter::with_capacity(1 << 22, std::fs::File::create(output)?);
    out.write_all(b"glTF")?;
    out.write_all(&2u32.to_le_bytes())?;
    out.write_all(&(total as u32).to_le_bytes())?;
    out.write_all(&(json.len() as u32).to_le_bytes())?;
    out.write_all(b"JSON")?;
    out.write_all(&json)?;
    out.write_all(&(bytes as u32).to_le_bytes())?;
    out.write_all(b"BIN\0")?;
    for t in &triangles {
        for v in t {
            for c in v {
                out.write_all(&c.to_le_bytes())?;
            }
        }
    }
    out.flush()?;
    println!("{} triangles ({} split {times} times) -> {output}, {total} bytes", triangles.len(), input);
    Ok(())
}

/// A triangle's four: one at each corner and the middle one, all wound as it is.
fn split(t: &[[f32; 3]; 3]) -> [[[f32; 3]; 3]; 4] {
    let mid = |a: [f32; 3], b: [f32; 3]| [0, 1, 2].map(|k| (a[k] + b[k]) * 0.5);
    let [a, b, c] = *t;
    let (ab, bc, ca) = (mid(a, b), mid(b, c), mid(c, a));
    [[a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca]]
}
