//! The `octrace` binary, run in temporary directories.

mod common;

use std::path::Path;
use std::process::{Command, Output};

fn octrace(dir: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_octrace")).args(args).current_dir(dir).output().expect("octrace runs")
}

fn ok(dir: &Path, args: &[&str]) -> String {
    let out = octrace(dir, args);
    assert!(out.status.success(), "octrace {args:?} failed: {}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8(out.stdout).expect("utf-8 output")
}

/// A closed unit cube, 12 triangles, as OBJ, with one degenerate face appended.
const CUBE_OBJ: &str = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1\n\
f 1 3 2\nf 1 4 3\nf 5 6 7\nf 5 7 8\nf 1 2 6\nf 1 6 5\nf 4 7 3\nf 4 8 7\nf 1 5 8\nf 1 8 4\nf 2 3 7\nf 2 7 6\nf 1 2 2\n";

#[test]
fn bake_then_inspect_prints_exactly_this() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("cube.obj"), CUBE_OBJ).unwrap();
    let out = ok(dir.path(), &["bake", "cube.obj", "-o", "cube.oct", "--max-depth", "3", "--leaf-size", "2"]);
    assert!(out.starts_with("baked cube.obj: 13 triangles (1 degenerate) -> "), "{out}");
    let text = ok(dir.path(), &["inspect", "cube.oct"]);
    let expected = "\
cube.oct: octrace scene, format 10.0, 0.0 MB
triangles          12 stored, 1 degenerate left out, 13 in the input
leaves             246 (246 before 2:1 balance, +0.0 %; 52 empty)
depth histogram    2:38  3:208
triangles / leaf   mean 1.92 over non-empty leaves, max 6, 372 references
overfull leaves    0 (at depth 3, the limit, with more than 16 triangles: 8 x the leaf size)
fans               none (no leaf of 256+ references has 24+ triangles around one vertex)
neighbours / leaf  mean 5.46
cube map           4 x 4 texels a face, level 2
bytes              octree 0.0 MB, triangles 0.0 MB, boxes 0.0 MB, cube map 0.0 MB, point location 0.0 MB, shading 0.0 MB, distance 0.0 MB; total 0.0 MB
distance           none (closest points make their tree on the first query; bake --distance stores it)
bake               max depth 3, leaf size 2, margin 9.536743e-7 of the root edge; time not recorded (reproducible file)
bounds             mesh [0.0, 0.0, 0.0] .. [1.0, 1.0, 1.0]; root cube at [0.0, 0.0, 0.0], edge 1
surface            closed (18 edges, each in two triangles; all consistently oriented)
scene data         1 mesh part, 0 materials, 0 lights, 0 cameras, 0 textures; per triangle: none
effects            none (primary rays only)
";
    assert_eq!(text, expected);
    let json: serde_json::Value = serde_json::from_str(&ok(dir.path(), &["inspect", "cube.oct", "--json"])).unwrap();
    assert_eq!(json["leaves"], 246);
    assert_eq!(json["degenerate_triangles"], 1);
    assert_eq!(json["bake"]["time_s"], serde_json::Value::Null);
    assert_eq!(json["surface"]["closed"], true);
    assert_eq!(json["surface"]["edges"], 18);
    let sections = json["sections"].as_array().unwrap();
    let names: Vec<&str> = sections.iter().map(|s| s["name"].as_str().unwrap()).collect();
    assert_eq!(names, octrace_format::SECTION_NAMES);
    let bytes: u64 = sections.iter().map(|s| s["bytes"].as_u64().unwrap()).sum();
    assert_eq!(bytes + octrace_format::HEADER_LEN as u64, json["file_bytes"].as_u64().unwrap());
    assert_eq!(json["distance"], serde_json::Value::Null);
}

/// `bake --distance` stores the closest-point tree: `inspect` gives its size, and the
/// distances are those of the scene without it.
#[test]
fn bake_distance_stores_the_closest_point_tree() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("cube.obj"), CUBE_OBJ).unwrap();
    ok(dir.path(), &["bake", "cube.obj", "-o", "plain.oct"]);
    ok(dir.path(), &["bake", "cube.obj", "-o", "near.oct", "--distance"]);
    let json: serde_json::Value = serde_json::from_str(&ok(dir.path(), &["inspect", "near.oct", "--json"])).unwrap();
    let d = &json["distance"];
    assert_eq!((d["triangles"].as_u64(), d["clusters"].as_u64(), d["nodes"].as_u64()), (Some(12), Some(2), Some(1)));
    // 4 header words, root and one node of 96, 3 cluster starts, 12 triangles.
    assert_eq!(d["bytes"].as_u64(), Some(4 * (4 + 2 * 96 + 3 + 12)));
    assert_eq!(json["bytes"]["distance"], d["bytes"]);
    assert!(ok(dir.path(), &["inspect", "near.oct"]).contains("distance           1 nodes, 2 clusters"));
    ok(dir.path(), &["points", "plain.oct", "--count", "300", "-o", "p.bin"]);
    for scene in ["plain", "near"] {
        ok(dir.path(), &["distance", &format!("{scene}.oct"), "--points", "p.bin", "-o", &format!("{scene}.bin")]);
    }
    let (plain, near) =
        (std::fs::read(dir.path().join("plain.bin")).unwrap(), std::fs::read(dir.path().join("near.bin")).unwrap());
    assert_eq!(plain.len(), 300 * 28);
    // Distance, point, triangle and barycentrics (28 bytes a point) alike.
    assert_eq!(plain, near);
}

/// A disk fanned from its centre leaves a leaf at the depth limit holding every
/// triangle: `inspect` says it is a fan, which rays cross through a hierarchy.
#[test]
fn inspect_reports_the_leaves_that_are_fans() {
    let dir = tempfile::tempdir().unwrap();
    let n = 300;
    let mut obj = String::from("v 0 0 0\n");
    for k in 0..n {
        let a = std::f64::consts::TAU * k as f64 / n as f64;
        obj.push_str(&format!("v {} 0 {}\n", a.cos(), a.sin()));
    }
    for k in 0..n {
        obj.push_str(&format!("f 1 {} {}\n", k + 2, (k + 1) % n + 2));
    }
    std::fs::write(dir.path().join("disk.obj"), obj).unwrap();
    ok(dir.path(), &["bake", "disk.obj", "-o", "disk.oct"]);
    let text = ok(dir.path(), &["inspect", "disk.oct"]);
    let line = text.lines().find(|l| l.starts_with("fans ")).expect("a fans line");
    assert!(line.contains("around a shared vertex") && line.contains("up to 300 in one; 0 others"), "{line}");
    let json: serde_json::Value = serde_json::from_str(&ok(dir.path(), &["inspect", "disk.oct", "--json"])).unwrap();
    assert!(json["fans"]["leaves"].as_u64().unwrap() >= 1, "{}", json["fans"]);
    assert_eq!(json["fans"]["largest"], 300);
    assert_eq!(json["fans"]["other_references"], 0);
}

/// `inspect` names each texture's encoding and what reads it: the textured sample's
/// checker and leaf, both base colour textures (sRGB), each of its material.
#[test]
fn inspect_says_how_each_texture_is_encoded_and_what_reads_it() {
    let dir = tempfile::tempdir().unwrap();
    let leaf = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/data/textured/leaf.gltf");
    ok(dir.path(), &["bake", leaf.to_str().unwrap(), "-o", "leaf.oct"]);
    let text = ok(dir.path(), &["inspect", "leaf.oct"]);
    for want in [
        "image 0 'checker': 8 x 8, sRGB colour, nearest filter, wrap repeat / repeat, alpha down to 1.00, kept as a PNG of 85 bytes; base colour of 'checker floor'",
        "image 1 'leaf.png': 64 x 64, sRGB colour, linear filter, wrap clamp to edge / clamp to edge, alpha down to 0.00, kept as a PNG of 1,376 bytes; base colour of 'leaf'",
    ] {
        assert!(text.contains(want), "{want}\nnot in\n{text}");
    }
}

/// Two cubes and a lamp, with an MTL library: a mirror, a glass and an emitter.
const MTL_OBJ: &str = "mtllib scene.mtl
v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1
v 2 0 0\nv 3 0 0\nv 3 1 0\nv 2 1 0
v 0 3 0\nv 1 3 0\nv 1 3 1
usemtl chrome
f 1 2 3 4\nf 5 8 7 6\nf 1 5 6 2\nf 4 3 7 8\nf 1 4 8 5\nf 2 6 7 3
usemtl glass
f 9 10 11 12
usemtl lamp
f 13 14 15
";
const MTL: &str = "newmtl chrome\nKd 0.1 0.1 0.1\nKs 0.9 0.9 0.9\nNs 200\nillum 3
newmtl glass\nKd 1 1 1\nd 0.2\nNi 1.5\nillum 6
newmtl lamp\nKd 0 0 0\nKe 4 4 3\n";

#[test]
fn inspect_lists_each_effect_with_its_reason_and_render_turns_them_off() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("scene.obj"), MTL_OBJ).unwrap();
    std::fs::write(dir.path().join("scene.mtl"), MTL).unwrap();
    ok(dir.path(), &["bake", "scene.obj", "-o", "scene.oct"]);
    let text = ok(dir.path(), &["inspect", "scene.oct"]);
    let tail: Vec<&str> = text.lines().skip_while(|l| !l.starts_with("scene data")).collect();
    assert_eq!(
        tail,
        [
            "scene data         3 mesh parts, 3 materials, 0 lights, 0 cameras, 0 textures; per triangle: material ids",
            "                   part 0, object 'unnamed_object', triangles 0..12: closed (18 edges, each in two triangles; all consistently oriented)",
            "effects            shadows: area light: material 'lamp' emits (4.00, 4.00, 3.00) on 1 triangle",
            "                   soft-shadows: area light: material 'lamp' emits (4.00, 4.00, 3.00) on 1 triangle",
            "                   reflection: material 'chrome', illum 3, Ks (0.90, 0.90, 0.90) (and 1 more)",
            "                   refraction: material 'glass', d 0.20, Ni 1.50",
        ],
        "{text}"
    );
    let out = Command::new(env!("CARGO_BIN_EXE_octrace"))
        .current_dir(dir.path())
        .args(["render", "scene.oct", "-o", "s.png", "--width", "48", "--effects", "-reflection,-alpha", "--json"])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("effects: reflection: turned off"), "{stderr}");
    assert!(stderr.contains("effects: alpha: not in this scene, nothing to turn off"), "{stderr}");
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(json["effects"], serde_json::json!(["shadows", "soft-shadows", "refraction"]));
    assert_eq!(json["rays"]["primary"], 48 * 48);
    assert_eq!(json["rays"]["reflection"], 0);
    assert!(json["rays"]["soft_shadow"].as_u64().unwrap() > 0);
    let text = ok(dir.path(), &["render", "scene.oct", "-o", "s.png", "--width", "48", "--effects", "none", "--stats"]);
    assert!(text.contains("effects: none"), "{text}");
    assert!(text.contains("  shadow                    0"), "{text}");
    let out = octrace(dir.path(), &["render", "scene.oct", "-o", "s.png", "--effects", "-glow"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("unknown effect 'glow'"), "{err}");
}

#[test]
fn demo_renders_the_effects_scene() {
    let dir = tempfile::tempdir().unwrap();
    let out = ok(dir.path(), &["demo", "--scene", "effects", "-o", "fx.png"]);
    for kind in ["shadow", "soft_shadow", "reflection", "refraction", "alpha"] {
        let line =
            out.lines().find(|l| l.trim_start().starts_with(&format!("{kind} "))).unwrap_or_else(|| panic!("{out}"));
        assert!(!line.trim().ends_with(" 0"), "{line}");
    }
    assert!(dir.path().join("fx.png").exists());
}

#[test]
fn bakes_are_identical_whatever_the_thread_count() {
    let dir = tempfile::tempdir().unwrap();
    let bunny = Path::new(env!("CARGO_MANIFEST_DIR")).join("../assets/bunny.obj.zst");
    let b = bunny.to_str().unwrap();
    // With default options: identical files, the header included.
    ok(dir.path(), &["bake", b, "-o", "one.oct", "--threads", "1"]);
    ok(dir.path(), &["bake", b, "-o", "two.oct", "--threads", "2"]);
    let read = |name: &str| std::fs::read(dir.path().join(name)).unwrap();
    assert!(read("one.oct") == read("two.oct"), "1-thread and 2-thread bakes differ");
    // The bake time only when asked, and then only in the header.
    ok(dir.path(), &["bake", b, "-o", "timed.oct", "--record-time"]);
    let (one, timed) = (read("one.oct"), read("timed.oct"));
    assert_eq!(one.len(), timed.len());
    let differing: Vec<usize> = (0..one.len()).filter(|&i| one[i] != timed[i]).collect();
    assert!(!differing.is_empty() && differing.iter().all(|&i| i < 416), "{differing:?}");
    let inspect = ok(dir.path(), &["inspect", "timed.oct"]);
    assert!(!inspect.contains("not recorded"), "{inspect}");
}

#[test]
fn trace_writes_one_record_per_ray_in_ray_order() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("cube.obj"), CUBE_OBJ).unwrap();
    ok(dir.path(), &["bake", "cube.obj", "-o", "cube.oct"]);
    // Ray 0 hits the z = 0 face (triangles 0 or 1) at t = 1; ray 1 misses; ray 2 is a
    // segment that stops short; ray 3 has a NaN direction (a defined miss).
    let rays: [[f32; 8]; 4] = [
        [0.25, 0.5, -1.0, 0.0, 0.0, 0.0, 1.0, f32::INFINITY],
        [5.0, 5.0, 5.0, 0.0, 1.0, 0.0, 0.0, f32::INFINITY],
        [0.5, 0.5, -1.0, 0.0, 0.0, 0.0, 1.0, 0.5],
        [0.5, 0.5, 0.5, 0.0, f32::NAN, 0.0, 1.0, 9.0],
    ];
    let bytes: Vec<u8> = rays.iter().flatten().flat_map(|f| f.to_le_bytes()).collect();
    std::fs::write(dir.path().join("rays.bin"), bytes).unwrap();
    let out = ok(dir.path(), &["trace", "cube.oct", "--rays", "rays.bin", "--out", "hits.bin"]);
    assert!(out.starts_with("4 rays, 1 hits"), "{out}");
    let hits = std::fs::read(dir.path().join("hits.bin")).unwrap();
    assert_eq!(hits.len(), 32);
    let rec = |i: usize| {
        let t = f32::from_le_bytes(hits[8 * i..8 * i + 4].try_into().unwrap());
        let id = u32::from_le_bytes(hits[8 * i + 4..8 * i + 8].try_into().unwrap());
        (t, id)
    };
    assert!(rec(0).0 == 1.0 && rec(0).1 <= 1, "{:?}", rec(0));
    assert_eq!(rec(1), (f32::INFINITY, u32::MAX));
    assert_eq!(rec(2), (0.5, u32::MAX));
    assert_eq!(rec(3), (9.0, u32::MAX));
    // -o, --output and --out name the same output.
    let out = ok(dir.path(), &["trace", "cube.oct", "--rays", "rays.bin", "-o", "occ.bin", "--occluded"]);
    assert!(out.starts_with("4 rays, 1 occluded"), "{out}");
}

#[test]
fn errors_name_the_problem_and_exit_non_zero() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("bad.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 5\n").unwrap();
    std::fs::write(dir.path().join("notoct.oct"), "hello").unwrap();
    std::fs::write(dir.path().join("rays.bin"), [0u8; 33]).unwrap();
    for (args, needle) in [
        (vec!["bake", "bad.obj", "-o", "bad.oct"], "vertex index 5 out of range"),
        (vec!["bake", "missing.obj", "-o", "x.oct"], "missing.obj"),
        (vec!["inspect", "notoct.oct"], "not an octrace scene"),
        (vec!["inspect", "nothing.oct"], "nothing.oct"),
    ] {
        let out = octrace(dir.path(), &args);
        assert!(!out.status.success(), "{args:?} succeeded");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(needle), "{args:?}: {err}");
    }
    assert!(!dir.path().join("bad.oct").exists(), "a failed bake left a file");
    std::fs::write(dir.path().join("cube.obj"), CUBE_OBJ).unwrap();
    ok(dir.path(), &["bake", "cube.obj", "-o", "cube.oct"]);
    let out = octrace(dir.path(), &["trace", "cube.oct", "--rays", "rays.bin", "--out", "h.bin"]);
    assert!(String::from_utf8_lossy(&out.stderr).contains("32-byte"), "{out:?}");
}

#[test]
fn a_closed_pipe_is_not_an_error() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("cube.obj"), CUBE_OBJ).unwrap();
    ok(dir.path(), &["bake", "cube.obj", "-o", "cube.oct"]);
    let mut child = Command::new(env!("CARGO_BIN_EXE_octrace"))
        .args(["inspect", "cube.oct"])
        .current_dir(dir.path())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take()); // the reader goes away before octrace writes
    let out = child.wait_with_output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
}

#[test]
fn render_writes_a_png_of_the_requested_size() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("cube.obj"), CUBE_OBJ).unwrap();
    ok(dir.path(), &["bake", "cube.obj", "-o", "cube.oct"]);
    for mode in ["shaded", "normals", "cells"] {
        let out =
            ok(dir.path(), &["render", "cube.oct", "-o", "c.png", "--width", "96", "--height", "64", "--mode", mode]);
        assert!(out.contains("96 x 64"), "{out}");
        let png = std::fs::read(dir.path().join("c.png")).unwrap();
        assert_eq!(&png[1..4], b"PNG");
        assert_eq!(u32::from_be_bytes(png[16..20].try_into().unwrap()), 96);
    }
    let out = octrace(dir.path(), &["render", "cube.oct", "-o", "c.png", "--eye", "1,2"]);
    assert!(!out.status.success());
}

#[test]
fn verify_checks_a_file_against_the_oracle() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("cube.obj"), CUBE_OBJ).unwrap();
    ok(dir.path(), &["bake", "cube.obj", "-o", "cube.oct"]);
    let out = ok(dir.path(), &["verify", "cube.oct", "--rays", "3000"]);
    assert!(out.contains("every invariant") && out.contains(" 0 mismatches"), "{out}");
    let json: serde_json::Value =
        serde_json::from_str(&ok(dir.path(), &["verify", "cube.oct", "--rays", "500", "--json"])).unwrap();
    let sets = json["sets"].as_array().unwrap();
    assert_eq!((sets[0]["set"].as_str(), sets[0]["rays"].as_u64()), (Some("random"), Some(500)));
    assert_eq!((sets[1]["set"].as_str(), sets[1]["rays"].as_u64()), (Some("grid"), Some(250)));
    for set in sets {
        assert_eq!(set["mismatches"].as_array().unwrap().len(), 0, "{set}");
        assert_eq!(set["beyond_distance_bound"].as_array().unwrap().len(), 0, "{set}");
    }
    // Random rays hit at distances of the scene's size: within the relative bound. (Grid
    // rays moved off their planes graze faces at distances near zero, where the bound's
    // absolute part is what holds: checked above.)
    let random_error = sets[0]["max_relative_t_error"].as_f64().unwrap();
    assert!(random_error <= json["distance_bound_relative"].as_f64().unwrap(), "{random_error}");
    // A corrupt file fails the invariants.
    let mut bytes = std::fs::read(dir.path().join("cube.oct")).unwrap();
    let at = bytes.len() / 2;
    bytes[at] ^= 1;
    std::fs::write(dir.path().join("bad.oct"), bytes).unwrap();
    assert!(!octrace(dir.path(), &["verify", "bad.oct"]).status.success());
}

#[test]
fn soak_counts_no_leaks_with_the_watertight_test() {
    let dir = tempfile::tempdir().unwrap();
    let out = ok(dir.path(), &["soak", "--rays", "20000", "--grid-rays", "10000"]);
    for mesh in ["sphere", "torus", "box", "blob", "room"] {
        for at in ["", "@1e4", "@1e7", "@-3e6"] {
            for kind in ["random", "grid"] {
                let line = out
                    .lines()
                    .find(|l| l.starts_with(&format!("{mesh}{at} ")) && l.contains(&format!(" {kind} ")))
                    .unwrap_or_else(|| panic!("no {mesh}{at} {kind} row in {out}"));
                assert!(line.contains(" 0 leaks"), "{line}");
            }
        }
    }
}

/// `soak` takes a closed mesh of the user's (here the cube, its degenerate face left
/// out by the bake) and soaks it with random and twisted grid rays; an open mesh is
/// refused, naming its boundary edges.
#[test]
fn soak_takes_a_closed_mesh_and_refuses_an_open_one() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("cube.obj"), CUBE_OBJ).unwrap();
    let out = ok(dir.path(), &["soak", "cube.obj", "--rays", "20000", "--grid-rays", "20000", "--json"]);
    let json: serde_json::Value = serde_json::from_str(&out).unwrap();
    let rows = json["meshes"].as_array().unwrap();
    assert_eq!(rows.len(), 2, "{out}");
    for row in rows {
        assert_eq!((row["mesh"].as_str(), row["leaks"].as_u64()), (Some("cube.obj"), Some(0)), "{row}");
        assert!(row["rays"].as_u64().unwrap() >= 20_000, "{row}");
    }
    assert_eq!(json["grid_ray_twists"].as_array().unwrap().len(), 5);
    // The cube without its top face: open.
    let open: String =
        CUBE_OBJ.lines().filter(|l| *l != "f 5 6 7" && *l != "f 5 7 8").map(|l| format!("{l}\n")).collect();
    std::fs::write(dir.path().join("open.obj"), open).unwrap();
    fails_saying(dir.path(), &["soak", "open.obj", "--rays", "100"], "4 of its 17 edges are boundary edges");
}

/// The issue's subnormal ray from inside the cube (literal bits), through `trace` as
/// users run it: all threads, one thread, occlusion, and the GPU; every path hits the
/// bottom face at t = 1 (it missed on each before the exact exit rule).
#[test]
fn trace_answers_a_subnormal_direction_on_every_path() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // The cube [-1, 1]^3 (twelve triangles) at depth 2, a triangle a leaf.
    let cube = CUBE_OBJ.replace("v 0", "v -1").replace(" 0", " -1");
    std::fs::write(d.join("cube.obj"), cube).unwrap();
    ok(d, &["bake", "cube.obj", "-o", "cube.oct", "--max-depth", "2", "--leaf-size", "1"]);
    let ray: [u32; 8] = [0xbf600000, 0xbf000000, 0, 0, 0x80000001, 0x80000001, 0xbf800000, 0x7f800000];
    std::fs::write(d.join("ray.bin"), ray.iter().flat_map(|w| w.to_le_bytes()).collect::<Vec<u8>>()).unwrap();
    let t_of = |name: &str| f32::from_le_bytes(std::fs::read(d.join(name)).unwrap()[..4].try_into().unwrap());
    for (flags, out) in [(&[][..], "a.bin"), (&["--threads", "1"][..], "b.bin"), (&["--occluded"][..], "c.bin")] {
        let args = [&["trace", "cube.oct", "--rays", "ray.bin", "--out", out][..], flags].concat();
        let said = ok(d, &args);
        assert!(said.starts_with("1 rays, 1 "), "{flags:?}: {said}");
        assert_eq!(t_of(out), 1.0, "{flags:?}");
    }
    let args = ["trace", "cube.oct", "--rays", "ray.bin", "--out", "g.bin", "--gpu"];
    if on_gpu(d, &args, "trace_answers_a_subnormal_direction_on_every_path").is_some() {
        assert_eq!(std::fs::read(d.join("g.bin")).unwrap(), std::fs::read(d.join("a.bin")).unwrap());
    }
}

/// Without `XDG_RUNTIME_DIR` (a headless machine, a container) `--gpu` says nothing
/// about it: Vulkan's probe for a display wrote "XDG_RUNTIME_DIR is invalid or not set"
/// twice, on a run that then succeeded.
#[test]
fn the_gpu_without_a_runtime_dir_prints_no_display_error() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("cube.obj"), CUBE_OBJ).unwrap();
    ok(d, &["bake", "cube.obj", "-o", "cube.oct"]);
    let ray = [0.5f32, 0.5, -1.0, 0.0, 0.0, 0.0, 1.0, f32::INFINITY];
    std::fs::write(d.join("rays.bin"), ray.iter().flat_map(|w| w.to_le_bytes()).collect::<Vec<u8>>()).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_octrace"))
        .args(["trace", "cube.oct", "--rays", "rays.bin", "-o", "hits.bin", "--gpu"])
        .current_dir(d)
        .env_remove("XDG_RUNTIME_DIR")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    if !out.status.success()
        && err.contains("no Vulkan adapter")
        && std::env::var("OCTRACE_REQUIRE_GPU").as_deref() != Ok("1")
    {
        eprintln!("SKIPPED the_gpu_without_a_runtime_dir_prints_no_display_error: {err}");
        return;
    }
    assert!(out.status.success(), "{err}");
    assert!(!err.contains("XDG_RUNTIME_DIR"), "{err}");
}

#[test]
fn compressed_bakes_open_and_inspect_shows_both_sizes() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("cube.obj"), CUBE_OBJ).unwrap();
    let out = ok(dir.path(), &["bake", "cube.obj", "-o", "cube.oct.zst", "--compress"]);
    assert!(out.contains("zstd:"), "{out}");
    let text = ok(dir.path(), &["inspect", "cube.oct.zst"]);
    assert!(text.lines().next().unwrap().contains("zstd-compressed"), "{text}");
    let json: serde_json::Value =
        serde_json::from_str(&ok(dir.path(), &["inspect", "cube.oct.zst", "--json"])).unwrap();
    assert!(json["bytes_on_disk"].as_u64().unwrap() < json["file_bytes"].as_u64().unwrap());
    ok(dir.path(), &["bake", "cube.obj", "-o", "cube.oct"]);
    let raw: serde_json::Value = serde_json::from_str(&ok(dir.path(), &["inspect", "cube.oct", "--json"])).unwrap();
    assert_eq!(raw["file_bytes"], json["file_bytes"]);
    assert_eq!(raw["bytes_on_disk"], raw["file_bytes"]);
    assert!(ok(dir.path(), &["verify", "cube.oct.zst", "--rays", "300"]).contains(" 0 mismatches"));
}

/// The bunny the repository carries.
fn bunny_path() -> String {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../assets/bunny.obj.zst").to_str().unwrap().to_string()
}

/// Temporary files a write left in `dir`.
fn leftovers(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with(".octrace-"))
        .collect()
}

/// A bake killed (SIGKILL) while it writes leaves the old file under the target name,
/// whole: the new file is written beside it and renamed only when complete. The
/// compressed write is slow (zstd level 19), so the kill lands mid-write every time;
/// the plain write is fast, so it is tried a few times.
#[test]
fn a_bake_killed_mid_write_leaves_the_old_file_untouched() {
    let dir = tempfile::tempdir().unwrap();
    let bunny = bunny_path();
    for (target, extra, attempts) in
        [("scene.oct.zst", &["--compress", "--level", "19"][..], 1), ("scene.oct", &[][..], 10)]
    {
        let path = dir.path().join(target);
        std::fs::write(&path, b"the old file").unwrap();
        let mut caught = 0;
        for _ in 0..attempts {
            let mut child = Command::new(env!("CARGO_BIN_EXE_octrace"))
                .args(["bake", &bunny, "-o", target])
                .args(extra)
                .current_dir(dir.path())
                .stdout(std::process::Stdio::null())
                .stderr(std::process::Stdio::null())
                .spawn()
                .unwrap();
            // Wait for the temporary file to appear, then kill at once.
            let started = std::time::Instant::now();
            let mid_write = loop {
                if !leftovers(dir.path()).is_empty() {
                    child.kill().unwrap();
                    break true;
                }
                if child.try_wait().unwrap().is_some() || started.elapsed().as_secs() > 60 {
                    break false;
                }
                std::thread::sleep(std::time::Duration::from_micros(200));
            };
            child.wait().unwrap();
            if mid_write && leftovers(dir.path()).len() == 1 {
                caught += 1;
                assert_eq!(std::fs::read(&path).unwrap(), b"the old file", "{target}: the old file changed");
                // SIGKILL gives no chance to clean up: the temporary file stays, under
                // a name no reader opens.
                for name in leftovers(dir.path()) {
                    std::fs::remove_file(dir.path().join(name)).unwrap();
                }
                break;
            }
            // The bake finished first: the new file replaced the old one whole.
            if std::fs::read(&path).unwrap() != b"the old file" {
                ok(dir.path(), &["inspect", target]);
                std::fs::write(&path, b"the old file").unwrap();
            }
        }
        assert!(caught > 0, "{target}: no kill landed mid-write in {attempts} attempts");
    }
}

/// Runs `octrace` with `setup` applied in the child before it starts.
fn octrace_with(dir: &Path, args: &[&str], setup: fn() -> std::io::Result<()>) -> Output {
    use std::os::unix::process::CommandExt;
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_octrace"));
    cmd.args(args).current_dir(dir);
    // SAFETY: `setup` only makes async-signal-safe system calls (setrlimit, signal,
    // setgid, setuid), as a child between fork and exec requires.
    unsafe { cmd.pre_exec(setup) };
    cmd.output().unwrap()
}

/// A write that fails part way (the disk fills up, here simulated with a file-size
/// limit, which fails writes the same way without needing a small file system) gives a
/// clear message, leaves the old file and no temporary file.
#[test]
fn a_write_that_fails_part_way_says_why_and_leaves_nothing_behind() {
    fn limit_file_size() -> std::io::Result<()> {
        // SAFETY: plain system calls on this process; SIGXFSZ ignored (inherited across
        // exec) so that a write past the limit fails with EFBIG instead of killing.
        unsafe {
            libc::signal(libc::SIGXFSZ, libc::SIG_IGN);
            let limit = libc::rlimit { rlim_cur: 1 << 20, rlim_max: 1 << 20 };
            if libc::setrlimit(libc::RLIMIT_FSIZE, &limit) != 0 {
                return Err(std::io::Error::last_os_error());
            }
        }
        Ok(())
    }
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("scene.oct"), b"the old file").unwrap();
    for args in
        [&["bake", &bunny_path(), "-o", "scene.oct"][..], &["bake", &bunny_path(), "-o", "scene.oct", "--compress"]]
    {
        let out = octrace_with(dir.path(), args, limit_file_size);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{args:?}: {err}");
        assert!(
            err.contains("cannot write scene.oct")
                && err.contains("ulimit -f")
                && err.contains("nothing under that name"),
            "{args:?}: {err}"
        );
        assert!(!err.contains(".tmp"), "the message names the temporary file: {err}");
        assert_eq!(std::fs::read(dir.path().join("scene.oct")).unwrap(), b"the old file");
        assert_eq!(leftovers(dir.path()), Vec::<String>::new());
    }
}

/// Writing into a directory the user may not write gives a clear message. (Root may
/// write anywhere, so as root the child drops to the `nobody` user first.)
#[test]
fn a_directory_without_write_permission_says_so() {
    use std::os::unix::fs::PermissionsExt;
    fn unprivileged() -> std::io::Result<()> {
        // SAFETY: plain system calls on this process.
        unsafe {
            if libc::geteuid() == 0 && (libc::setgid(65534) != 0 || libc::setuid(65534) != 0) {
                return Err(std::io::Error::last_os_error());
            }
        }
        Ok(())
    }
    let dir = tempfile::tempdir().unwrap();
    std::fs::set_permissions(dir.path(), std::fs::Permissions::from_mode(0o755)).unwrap();
    std::fs::write(dir.path().join("cube.obj"), CUBE_OBJ).unwrap();
    std::fs::set_permissions(dir.path().join("cube.obj"), std::fs::Permissions::from_mode(0o644)).unwrap();
    std::fs::create_dir(dir.path().join("locked")).unwrap();
    std::fs::set_permissions(dir.path().join("locked"), std::fs::Permissions::from_mode(0o555)).unwrap();
    let out = octrace_with(dir.path(), &["bake", "cube.obj", "-o", "locked/cube.oct"], unprivileged);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("cannot write locked/cube.oct: permission denied in locked"), "{err}");
    let out = octrace(dir.path(), &["bake", "cube.obj", "-o", "missing/cube.oct"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("the directory missing does not exist"), "{err}");
}

/// Runs `octrace` with `--gpu`; `None` (and a visible skip) when there is no Vulkan
/// adapter and `OCTRACE_REQUIRE_GPU` is not 1.
fn on_gpu(dir: &Path, args: &[&str], test: &str) -> Option<String> {
    let out = octrace(dir, args);
    let err = String::from_utf8_lossy(&out.stderr);
    if !out.status.success()
        && err.contains("no Vulkan adapter")
        && std::env::var("OCTRACE_REQUIRE_GPU").as_deref() != Ok("1")
    {
        eprintln!("SKIPPED {test}: {err}");
        return None;
    }
    assert!(out.status.success(), "octrace {args:?} failed: {err}");
    Some(String::from_utf8(out.stdout).unwrap())
}

/// `trace --gpu` writes the CPU's hit file, and `render --gpu` the CPU's image.
#[test]
fn trace_and_render_on_the_gpu_give_the_cpus_files() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    ok(d, &["bake", &bunny_path(), "-o", "bunny.oct"]);
    // Rays from a ring around the bunny towards its middle, and some from inside.
    let mut bytes = Vec::new();
    for i in 0..20_000u32 {
        let a = i as f32 * 0.01;
        let (o, tmin) = if i % 4 == 0 {
            ([-0.02, 0.1, 0.0], 0.0)
        } else {
            ([0.3 * a.cos(), 0.1 + 0.1 * (a * 0.37).sin(), 0.3 * a.sin()], 0.0)
        };
        let d = [-0.02 - o[0] + 0.05 * (a * 1.3).sin(), 0.1 - o[1], -o[2] + 0.05 * (a * 0.7).cos()];
        for f in [o[0], o[1], o[2], tmin, d[0], d[1], d[2], f32::INFINITY] {
            bytes.extend_from_slice(&f.to_le_bytes());
        }
    }
    std::fs::write(d.join("rays.bin"), bytes).unwrap();
    let test = "trace_and_render_on_the_gpu_give_the_cpus_files";
    for extra in [&[][..], &["--occluded"][..]] {
        let cpu: Vec<&str> = [&["trace", "bunny.oct", "--rays", "rays.bin", "--out", "cpu.bin"][..], extra].concat();
        ok(d, &cpu);
        let gpu: Vec<&str> =
            [&["trace", "bunny.oct", "--rays", "rays.bin", "--out", "gpu.bin", "--gpu"][..], extra].concat();
        let Some(out) = on_gpu(d, &gpu, test) else { return };
        assert!(out.contains("kernel only"), "{out}");
        let (a, b) = (std::fs::read(d.join("cpu.bin")).unwrap(), std::fs::read(d.join("gpu.bin")).unwrap());
        let records = |x: &[u8]| -> Vec<(f32, u32)> {
            x.chunks(8)
                .map(|r| {
                    (f32::from_le_bytes(r[..4].try_into().unwrap()), u32::from_le_bytes(r[4..].try_into().unwrap()))
                })
                .collect()
        };
        let (a, b) = (records(&a), records(&b));
        let hits = a.iter().filter(|r| r.1 != u32::MAX).count();
        assert!(hits > 10_000, "{hits} hits: the rays should mostly hit");
        for (i, (x, y)) in a.iter().zip(&b).enumerate() {
            // Occluders may be any triangle on the way; nearest hits are the same one
            // at the same distance (or a triangle tied with it).
            let same = if extra.is_empty() {
                x == y || (x.0 - y.0).abs() <= 1e-5 * x.0.abs()
            } else {
                (x.1 == u32::MAX) == (y.1 == u32::MAX)
            };
            assert!(same, "{extra:?} ray {i}: CPU {x:?}, GPU {y:?}");
        }
    }
    ok(d, &["render", "bunny.oct", "-o", "cpu.png", "--width", "160", "--height", "120", "--mode", "cells"]);
    on_gpu(
        d,
        &["render", "bunny.oct", "-o", "gpu.png", "--width", "160", "--height", "120", "--mode", "cells", "--gpu"],
        test,
    )
    .unwrap();
    assert!(
        std::fs::read(d.join("cpu.png")).unwrap() == std::fs::read(d.join("gpu.png")).unwrap(),
        "the images differ"
    );
}

#[test]
fn report_measures_every_knob_and_writes_markdown_and_json() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("cube.obj"), CUBE_OBJ).unwrap();
    let quick = [
        "--runs",
        "2",
        "--sample",
        "64",
        "--hard-rays",
        "64",
        "--leak-rays",
        "2000",
        "--max-rays",
        "4096",
        "--render-width",
        "32",
    ];
    let run = octrace(dir.path(), &[&["report", "cube.obj", "-o", "rep", "--json"][..], &quick].concat());
    assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
    // Not a terminal: a line of progress a step on standard error.
    let progress = String::from_utf8_lossy(&run.stderr);
    assert!(progress.lines().filter(|l| l.starts_with("report: step ")).count() > 3, "{progress}");
    let out = String::from_utf8(run.stdout).unwrap();
    let json: serde_json::Value = serde_json::from_str(&out).unwrap();
    let mesh = &json["meshes"][0];
    assert_eq!((mesh["name"].as_str(), mesh["triangles"].as_u64()), (Some("cube.obj"), Some(13)));
    let rows = mesh["rows"].as_array().unwrap();
    let knobs: Vec<&str> = rows.iter().map(|r| r["knob"].as_str().unwrap()).collect();
    for knob in [
        "defaults",
        "triangle test",
        "exit face",
        "bake margin",
        "depth limit",
        "leaf target",
        "peer",
        "octree",
        "baseline",
    ] {
        assert!(knobs.contains(&knob), "{knob} missing from {knobs:?}");
    }
    let kinds = ["in-plane", "along-edge", "corners", "grazing", "vertex-aimed", "slivers", "on-surface", "far"];
    for row in rows {
        let mrays = row["mrays"].as_array().unwrap();
        assert_eq!(mrays.len(), 3, "{row}");
        for (m, spread) in mrays.iter().zip(row["mrays_spread"].as_array().unwrap()) {
            let (m, lo, hi) = (m.as_f64().unwrap(), spread[0].as_f64().unwrap(), spread[1].as_f64().unwrap());
            assert!(0.0 < lo && lo <= m && m <= hi, "{row}");
        }
        assert_eq!(row["errors"]["compared"], 3 * 64, "{row}");
        assert!(row["leak_rays"].as_u64().unwrap() > 5 * 2 * 2000, "{row}");
        let hard: Vec<&str> = row["hard"].as_array().unwrap().iter().map(|h| h["kind"].as_str().unwrap()).collect();
        assert_eq!(hard, kinds, "{row}");
        assert!(row["hard"].as_array().unwrap().iter().all(|h| h["compared"].as_u64().unwrap() >= 32), "{row}");
    }
    // The watertight configurations (the octree's and the seeds' baselines): no wrong
    // hit, random or hard, no leak.
    for row in rows.iter().filter(|r| r["knob"] != "peer" && r["knob"] != "triangle test") {
        let wrong = (row["errors"]["wrong"].as_u64(), row["hard_wrong_per_million"].as_f64());
        assert_eq!((wrong, row["leaks_per_million"].as_f64()), ((Some(0), Some(0.0)), Some(0.0)), "{row}");
    }
    // Leaks by solid and kind: every solid, every kind.
    let leaks = rows[0]["leaks"].as_array().unwrap();
    assert_eq!(leaks.len(), 5 * 3, "{leaks:?}");
    assert!(leaks.iter().any(|l| l["solid"] == "room" && l["kind"] == "grid"), "{leaks:?}");
    // Embree, in its two modes, where this build has it: the oracle's answers.
    let embree: Vec<&serde_json::Value> =
        rows.iter().filter(|r| r["setting"].as_str().unwrap().starts_with("Embree")).collect();
    assert_eq!(embree.len(), if cfg!(feature = "embree") { 2 } else { 0 }, "{knobs:?}");
    for row in embree {
        assert_eq!(row["errors"]["wrong"].as_u64(), Some(0), "{row}");
        assert!(row["mrays"].as_array().unwrap().iter().all(|m| m.as_f64().unwrap() > 0.0), "{row}");
    }
    // The paper's tree and the unconstrained one, walked (a tree of one leaf here:
    // the unconstrained tests have the uneven trees).
    let octree: Vec<&serde_json::Value> = rows.iter().filter(|r| r["knob"] == "octree").collect();
    assert_eq!(octree.len(), 2);
    assert!(octree[1]["setting"].as_str().unwrap().starts_with("unconstrained"));
    assert!(octree[1]["leaves"].as_u64() <= octree[0]["leaves"].as_u64(), "{octree:?}");
    let balance = &mesh["balance"];
    assert!(balance["unconstrained_leaves_per_ray"].as_f64().unwrap() > 0.0, "{balance}");
    // The seeds' four BVH builds and the kd-tree, on the same rays, with the
    // watertight test.
    let baselines: Vec<&serde_json::Value> = rows.iter().filter(|r| r["knob"] == "baseline").collect();
    assert_eq!(baselines.len(), 5);
    assert!(baselines[4]["setting"].as_str().unwrap().starts_with("SAH kd-tree"));
    assert!(baselines.iter().all(|b| b["sah_cost"].as_f64().unwrap() > 0.0), "{baselines:?}");
    // The renderer's knobs: soft samples and depth, each against its reference, more
    // samples closer to it.
    let render = json["render_knobs"].as_array().unwrap();
    assert_eq!(render.len(), 7 + 6, "{render:?}");
    let rmse = |knob: &str, value: u64| {
        let row = render.iter().find(|r| r["knob"] == knob && r["value"] == value).unwrap();
        row["rmse"].as_f64().unwrap()
    };
    assert!(rmse("soft-shadow samples", 1) > rmse("soft-shadow samples", 64), "{render:?}");
    assert!(rmse("reflection depth", 1) > rmse("reflection depth", 8), "{render:?}");
    let md = std::fs::read_to_string(dir.path().join("rep/report.md")).unwrap();
    assert!(md.contains("## cube.obj (13 triangles)") && md.contains("| defaults | watertight f32"), "{md}");
    assert!(
        md.contains("| octree | unconstrained, ropes, scalar step |") && md.contains("2:1 balanced against"),
        "{md}"
    );
    assert!(
        md.contains("| BVH, SAH, 16 bins |") && md.contains("| SAH kd-tree, Havran's depth and failures |"),
        "{md}"
    );
    for section in ["Hard rays, wrong answers", "## Leaks from the procedural closed solids", "## The renderer's knobs"]
    {
        assert!(md.contains(section), "{section} missing from {md}");
    }
    assert!(md.contains("slab distances (one walk at a time: no eight-lane walk)"), "{md}");
    assert!(dir.path().join("rep/report.json").exists());
    // The chart: two panels for the one mesh, a point per configuration in its knob's
    // colour (Möller-Trumbore's red among them), text drawn.
    let png = png::Decoder::new(std::io::Cursor::new(std::fs::read(dir.path().join("rep/report.png")).unwrap()));
    let mut reader = png.read_info().unwrap();
    let mut rgb = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut rgb).unwrap();
    assert_eq!((info.width, info.height, info.color_type), (1280, 440, png::ColorType::Rgb));
    let pixels: Vec<&[u8]> = rgb.chunks(3).collect();
    let count = |f: &dyn Fn(&[u8]) -> bool| pixels.iter().filter(|p| f(p)).count();
    assert!(count(&|p| p == [214, 39, 40]) > 2 * 40, "the triangle test's points");
    assert!(count(&|p| p[0] < 64 && p[1] < 64 && p[2] < 64) > 2000, "text and axes");
}

fn fails_saying(dir: &Path, args: &[&str], says: &str) -> String {
    let out = octrace(dir, args);
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(!out.status.success(), "octrace {args:?} succeeded");
    assert!(stderr.contains(says), "octrace {args:?}: expected '{says}' in: {stderr}");
    stderr
}

/// `bake same.obj -o same.obj`, `render x.oct -o x.oct`, `rays`, `trace --out`: an
/// output that is one of the command's inputs (also through a link, or a glTF's
/// buffer) is refused before any work, and the input is left as it was.
#[test]
fn an_output_that_is_an_input_is_refused_and_the_input_kept() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("cube.obj"), CUBE_OBJ).unwrap();
    fails_saying(d, &["bake", "cube.obj", "-o", "cube.obj"], "would destroy its input");
    assert_eq!(std::fs::read_to_string(d.join("cube.obj")).unwrap(), CUBE_OBJ);
    #[cfg(unix)]
    {
        std::os::unix::fs::symlink("cube.obj", d.join("alias.oct")).unwrap();
        fails_saying(d, &["bake", "cube.obj", "-o", "alias.oct"], "would destroy its input");
        assert_eq!(std::fs::read_to_string(d.join("cube.obj")).unwrap(), CUBE_OBJ);
    }
    ok(d, &["bake", "cube.obj", "-o", "cube.oct"]);
    let scene = std::fs::read(d.join("cube.oct")).unwrap();
    fails_saying(d, &["render", "cube.oct", "-o", "cube.oct", "--width", "8"], "would destroy its input");
    fails_saying(d, &["rays", "cube.oct", "-o", "cube.oct"], "would destroy its input");
    ok(d, &["rays", "cube.oct", "-o", "rays.bin", "--set", "incoherent"]);
    let rays = std::fs::read(d.join("rays.bin")).unwrap();
    fails_saying(d, &["trace", "cube.oct", "--rays", "rays.bin", "--out", "cube.oct"], "would destroy its input");
    fails_saying(d, &["trace", "cube.oct", "--rays", "rays.bin", "--out", "rays.bin"], "would destroy its input");
    assert!(std::fs::read(d.join("cube.oct")).unwrap() == scene && std::fs::read(d.join("rays.bin")).unwrap() == rays);
    // A glTF's external buffer is an input too.
    let gltf =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/data/hostile/uri-absolute.gltf"))
            .unwrap()
            .replace("/etc/passwd", "tri.bin");
    std::fs::write(d.join("tri.gltf"), gltf).unwrap();
    let tri: Vec<u8> = [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0].iter().flat_map(|c| c.to_le_bytes()).collect();
    std::fs::write(d.join("tri.bin"), &tri).unwrap();
    fails_saying(d, &["bake", "tri.gltf", "-o", "tri.bin"], "would destroy its input");
    assert_eq!(std::fs::read(d.join("tri.bin")).unwrap(), tri);
    ok(d, &["bake", "tri.gltf", "-o", "tri.oct"]);
}

/// A symbolic link is written through (it stays a link), `/dev/null` and a FIFO are
/// written into (never replaced by a regular file), and `-` writes to standard output
/// with the summary on standard error.
#[cfg(unix)]
#[test]
fn links_devices_fifos_and_stdout_as_outputs() {
    use std::os::unix::fs::FileTypeExt;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("cube.obj"), CUBE_OBJ).unwrap();
    std::fs::create_dir(d.join("store")).unwrap();
    std::os::unix::fs::symlink("store/cube.oct", d.join("cube.oct")).unwrap();
    ok(d, &["bake", "cube.obj", "-o", "cube.oct"]);
    assert!(std::fs::symlink_metadata(d.join("cube.oct")).unwrap().file_type().is_symlink());
    assert!(std::fs::metadata(d.join("store/cube.oct")).unwrap().len() > 416);
    ok(d, &["render", "cube.oct", "-o", "/dev/null", "--width", "16"]);
    assert!(std::fs::metadata("/dev/null").unwrap().file_type().is_char_device());
    // Standard output: the PNG alone; the summary on standard error.
    let out = octrace(d, &["render", "cube.oct", "-o", "-", "--width", "16"]);
    assert!(out.status.success());
    assert_eq!(&out.stdout[1..4], b"PNG");
    assert!(String::from_utf8_lossy(&out.stderr).contains("rendered cube.oct (16 x 16"));
    let rays = octrace(d, &["rays", "cube.oct", "-o", "-"]);
    assert_eq!(rays.stdout.len(), 32 * 1024 * 1024);
    ok(d, &["rays", "cube.oct", "-o", "rays.bin"]);
    let hits = octrace(d, &["trace", "cube.oct", "--rays", "rays.bin", "--out", "-"]);
    assert!(hits.status.success());
    assert_eq!(hits.stdout.len(), 8 * 1024 * 1024);
    // A FIFO: a reader gets the rays; the FIFO stays a FIFO.
    let status = Command::new("mkfifo").arg(d.join("pipe")).status().unwrap();
    assert!(status.success());
    let reader = {
        let pipe = d.join("pipe");
        std::thread::spawn(move || std::fs::read(pipe).unwrap())
    };
    ok(d, &["rays", "cube.oct", "-o", "pipe"]);
    assert_eq!(reader.join().unwrap(), std::fs::read(d.join("rays.bin")).unwrap());
    assert!(std::fs::symlink_metadata(d.join("pipe")).unwrap().file_type().is_fifo());
    // As an input, a FIFO is refused at once rather than waited on.
    fails_saying(d, &["inspect", "pipe"], "not a regular file");
    fails_saying(d, &["trace", "cube.oct", "--rays", "/dev/zero", "--out", "h.bin"], "not a regular file");
}

/// Sizes from the command line are checked against their documented limits before
/// any memory is taken: each of these used to allocate tens of gigabytes, run for
/// minutes or hang.
#[test]
fn oversized_requests_are_refused_before_work() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("cube.obj"), CUBE_OBJ).unwrap();
    // Each names its own option, not the three (issue 50, item 7).
    for (option, value, says) in [
        ("--margin", "0.1", "margin 0.1 (--margin, BuildParams::margin) is outside 0 to 0.0009765625"),
        (
            "--max-depth",
            "40",
            "depth 40 (--max-depth, BuildParams::max_depth) is beyond the format's deepest level, 20",
        ),
    ] {
        let err = fails_saying(d, &["bake", "cube.obj", "-o", "c.oct", option, value], says);
        assert!(!err.contains(" or --"), "{err}");
    }
    fails_saying(
        d,
        &["bake", "cube.obj", "-o", "c.oct", "--leaf-size", "0"],
        "'--leaf-size <LEAF_SIZE>': 0 is not in 1..",
    );
    fails_saying(d, &["bake", "cube.obj", "-o", "c.oct", "--threads", "100000"], "--threads must be from 1 to 1024");
    assert!(!d.join("c.oct").exists());
    ok(d, &["bake", "cube.obj", "-o", "c.oct"]);
    fails_saying(d, &["render", "c.oct", "-o", "x.png", "--width", "100000000"], "more than the limit of 8192 x 8192");
    fails_saying(d, &["render", "c.oct", "-o", "x.png", "--width", "9000", "--height", "9000"], "more than the limit");
    fails_saying(d, &["render", "c.oct", "-o", "x.png", "--soft-samples", "100000"], "--soft-samples");
    fails_saying(d, &["render", "c.oct", "-o", "x.png", "--max-depth", "1000"], "--max-depth");
    ok(d, &["rays", "c.oct", "-o", "r.bin", "--set", "incoherent"]);
    fails_saying(d, &["trace", "c.oct", "--rays", "r.bin", "--out", "h.bin", "--threads", "100000"], "--threads");
    assert!(!d.join("x.png").exists() && !d.join("h.bin").exists());
}

/// A mesh that names files outside its folder is refused by default, naming the
/// reference and the flag; `--allow-outside-references` reads them.
#[test]
fn bake_confines_mesh_references_unless_allowed() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::create_dir(d.join("scene")).unwrap();
    let tri: Vec<u8> = [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0].iter().flat_map(|c| c.to_le_bytes()).collect();
    std::fs::write(d.join("shared.bin"), &tri).unwrap();
    let gltf =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/data/hostile/uri-absolute.gltf"))
            .unwrap()
            .replace("/etc/passwd", "../shared.bin");
    std::fs::write(d.join("scene/tri.gltf"), gltf).unwrap();
    fails_saying(d, &["bake", "scene/tri.gltf", "-o", "t.oct"], "reference '../shared.bin' not read");
    fails_saying(d, &["bake", "scene/tri.gltf", "-o", "t.oct"], "--allow-outside-references");
    assert!(!d.join("t.oct").exists());
    ok(d, &["bake", "scene/tri.gltf", "-o", "t.oct", "--allow-outside-references"]);
    let hostile = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/data/hostile/uri-file-scheme.gltf");
    fails_saying(d, &["bake", hostile.to_str().unwrap(), "-o", "p.oct"], "reference 'file:///etc/passwd' not read");
    assert!(!d.join("p.oct").exists());
}

/// The commands that memory-map a scene say in their help what a file rewritten under
/// them does, and how to deploy files so that it cannot happen.
#[test]
fn help_of_mapping_commands_warns_about_files_rewritten_in_place() {
    let dir = tempfile::tempdir().unwrap();
    for command in ["inspect", "trace", "render"] {
        let help = ok(dir.path(), &[command, "--help"]);
        assert!(help.contains("SIGBUS") && help.contains("Replace baked files by renaming"), "{command}: {help}");
    }
}

/// `bench --instances`: the scene placed in a lattice and traced as a world of
/// instances; in a build with Embree, Embree's instances of it hit the same rays but
/// for a few grazing ones.
#[test]
fn bench_instances_traces_a_world_and_embrees_instances() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("cube.obj"), CUBE_OBJ).unwrap();
    ok(d, &["bake", "cube.obj", "-o", "cube.oct"]);
    let out = ok(d, &["bench", "cube.oct", "--instances", "27", "--runs", "5", "--json"]);
    let json: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(json["instances"].as_u64(), Some(27));
    assert_eq!(json["world_triangles"].as_u64(), json["scene_triangles"].as_u64().map(|t| 27 * t));
    let (rays, hits) = (json["rays"].as_u64().unwrap(), json["octrace_hits"].as_u64().unwrap());
    assert!(hits > rays / 10 && hits < rays, "{json}");
    for figure in ["octrace_batch", "octrace_one_ray"] {
        assert!(json[figure]["median"].as_f64().unwrap() > 0.0, "{json}");
    }
    assert_eq!(json.get("embree").is_some(), cfg!(feature = "embree"), "{json}");
    if let Some(e) = json.get("embree") {
        assert!(e["hits"].as_u64().unwrap().abs_diff(hits) <= rays / 1000, "{json}");
        assert!(e["packets"]["median"].as_f64().unwrap() > 0.0, "{json}");
    }
    let text = ok(d, &["bench", "cube.oct", "--instances", "8", "--runs", "5"]);
    assert!(text.contains("world: 8 instances") && text.contains("octrace world, batch"), "{text}");
}

/// `bench`'s checksums are those of the standard sets traced by `rays` and `trace`
/// (rays that hit, and the sum of their distances in ray order), its figures are
/// there for every set, and in a build with Embree its one-thread and all-threads
/// rows are filled, one-ray calls included.
#[test]
fn bench_checksums_are_the_standard_sets_traced() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("cube.obj"), CUBE_OBJ).unwrap();
    ok(d, &["bake", "cube.obj", "-o", "cube.oct"]);
    let out = ok(d, &["bench", "cube.oct", "--runs", "5", "--threads", "2", "--json"]);
    let json: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!((json["threads"].as_u64(), json["runs"].as_u64()), (Some(2), Some(5)));
    let sets = json["sets"].as_array().unwrap();
    let names: Vec<&str> = sets.iter().map(|s| s["set"].as_str().unwrap()).collect();
    assert_eq!(names, ["primary", "incoherent", "shadow"]);
    for set in ["primary", "incoherent"] {
        let b = sets.iter().find(|s| s["set"] == set).unwrap();
        ok(d, &["rays", "cube.oct", "--set", set, "-o", "rays.bin"]);
        ok(d, &["trace", "cube.oct", "--rays", "rays.bin", "--out", "hits.bin"]);
        let hits = std::fs::read(d.join("hits.bin")).unwrap();
        let records: Vec<(f32, u32)> = hits
            .chunks(8)
            .map(|r| (f32::from_le_bytes(r[..4].try_into().unwrap()), u32::from_le_bytes(r[4..].try_into().unwrap())))
            .filter(|r| r.1 != u32::MAX)
            .collect();
        let sum_t = records.iter().map(|r| r.0 as f64).sum::<f64>();
        assert_eq!(b["rays"].as_u64(), Some(hits.len() as u64 / 8), "{set}");
        assert_eq!(b["hits"].as_u64(), Some(records.len() as u64), "{set}");
        assert_eq!(b["sum_t"].as_f64(), Some(sum_t), "{set}");
        assert!(records.len() > 1000, "{set}: the cube is hit ({})", records.len());
        // How often the exact test's filter could not decide: a count of its calls, at
        // most a few per ray.
        let stage = b["exact_stage_calls"].as_u64().unwrap_or_else(|| panic!("{set}: {b}"));
        assert!(stage <= 4 * b["rays"].as_u64().unwrap(), "{set}: {b}");
    }
    // One shadow ray a primary hit; the cube is closed, so a ray from its surface
    // toward the light is either occluded by the cube itself or not, never more.
    let (primary, shadow) = (&sets[0], &sets[2]);
    assert_eq!(shadow["rays"], primary["hits"]);
    assert!(shadow["hits"].as_u64().unwrap() <= shadow["rays"].as_u64().unwrap());
    for s in sets {
        for figure in ["mrays_single", "mrays_all_threads"] {
            assert!(s[figure]["median"].as_f64().unwrap() > 0.0, "{s}");
        }
        let embree = &s["embree_3_fast_single"];
        assert_eq!(embree.is_null(), !cfg!(feature = "embree"), "{s}");
        if cfg!(feature = "embree") {
            let all = &embree["all_threads"];
            assert_eq!(all["threads"].as_u64(), Some(2), "{s}");
            for (row, f) in [
                (embree, "octrace_one_ray"),
                (embree, "embree_one_ray"),
                (all, "octrace_batch"),
                (all, "octrace_one_ray"),
                (all, "embree_one_ray"),
            ] {
                assert!(row[f]["median"].as_f64().unwrap() > 0.0, "{f}: {s}");
            }
            for ratio in ["ratio_batch", "ratio_one_ray"] {
                for row in [embree, all] {
                    assert!(row[ratio].as_f64().is_some_and(|r| r.is_finite() && r > 0.0), "{ratio}: {s}");
                }
            }
            assert_eq!(embree["embree_packets"].is_null(), s["set"] != "primary", "{s}");
        }
    }
    // The ordered queries, on the incoherent rays and the standard points: the closed
    // cube's every-hit lists and counts agree with `trace`'s, and (with Embree) Embree's
    // filter-function lists count the same; no point answers unlike the exact oracle.
    let q = &json["queries"];
    let rows = q["rows"].as_array().unwrap();
    let names: Vec<&str> = rows.iter().map(|r| r["query"].as_str().unwrap()).collect();
    assert_eq!(names, ["all hits", "counts", "inside", "length inside"]);
    ok(d, &["rays", "cube.oct", "--set", "incoherent", "-o", "rays.bin"]);
    let traced: serde_json::Value = serde_json::from_str(&ok(
        d,
        &["trace", "cube.oct", "--rays", "rays.bin", "--out", "c.bin", "--counts", "--json"],
    ))
    .unwrap();
    let crossings = traced["crossings"].as_u64().unwrap();
    assert!(crossings > 100_000, "{traced}");
    assert!(
        rows[0]["checksum"].as_str().unwrap().replace(',', "").starts_with(&format!("{crossings} crossings")),
        "{q}"
    );
    for r in rows {
        assert!(r["octrace_single"]["median"].as_f64().unwrap() > 0.0, "{r}");
        let embree = &r["embree_3_single"];
        if cfg!(feature = "embree") && r["query"] != "length inside" {
            assert!(embree["mrays"]["median"].as_f64().unwrap() > 0.0, "{r}");
        } else {
            assert!(embree.is_null(), "{r}");
        }
    }
    assert_eq!(q["oracle"]["octrace_wrong"].as_u64(), Some(0), "{q}");
    assert!(q["oracle"]["compared"].as_u64().unwrap() > 900_000, "{q}");
}

/// The closed unit cube with a face split along its diagonal: rays through its faces,
/// an edge and a vertex cross it twice, entering first; `--all-hits`, `--counts` and
/// `--length-inside` write the layouts `trace --help` gives, the same to a file and to
/// standard output, and the same with `--gpu`.
#[test]
fn trace_lists_every_crossing_counts_and_lengths() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("cube.obj"), CUBE_OBJ).unwrap();
    ok(dir.path(), &["bake", "cube.obj", "-o", "cube.oct"]);
    // Through two faces; through the edge x = 0, z = 0 and out through x = 1; through
    // the vertex (0, 0, 0) and out through (1, 1, 1); a miss; a segment that stops
    // inside.
    let s = 1.0 / 3f32.sqrt();
    let rays: [[f32; 8]; 5] = [
        [0.25, 0.5, -1.0, 0.0, 0.0, 0.0, 1.0, f32::INFINITY],
        [-1.0, 0.5, -1.0, 0.0, 1.0, 0.0, 1.0, f32::INFINITY],
        [-1.0, -1.0, -1.0, 0.0, s, s, s, f32::INFINITY],
        [5.0, 5.0, 5.0, 0.0, 1.0, 0.0, 0.0, f32::INFINITY],
        [0.25, 0.5, -1.0, 0.0, 0.0, 0.0, 1.0, 1.5],
    ];
    let bytes: Vec<u8> = rays.iter().flatten().flat_map(|f| f.to_le_bytes()).collect();
    std::fs::write(dir.path().join("rays.bin"), bytes).unwrap();
    let out = ok(dir.path(), &["trace", "cube.oct", "--rays", "rays.bin", "--out", "all.bin", "--all-hits"]);
    assert!(out.starts_with("5 rays, 7 crossings"), "{out}");
    let all = std::fs::read(dir.path().join("all.bin")).unwrap();
    let word = |b: &[u8], i: usize| u32::from_le_bytes(b[4 * i..4 * i + 4].try_into().unwrap());
    let offsets: Vec<u64> = (0..6).map(|i| u64::from_le_bytes(all[8 * i..8 * i + 8].try_into().unwrap())).collect();
    assert_eq!(offsets, [0, 2, 4, 6, 6, 7]);
    let records = &all[48..];
    assert_eq!(records.len(), 7 * 20);
    let record = |k: usize| {
        let r = &records[20 * k..20 * k + 20];
        (f32::from_bits(word(r, 0)), word(r, 1), word(r, 4))
    };
    // Entering first, then leaving, at the faces' distances.
    assert_eq!((record(0).0, record(0).2, record(1).0, record(1).2), (1.0, 1, 2.0, 0));
    assert_eq!((record(2).0, record(2).2, record(3).0, record(3).2), (1.0, 1, 2.0, 0));
    assert_eq!((record(4).2, record(5).2), (1, 0));
    assert!((record(4).0 - 3f32.sqrt()).abs() < 1e-6 && (record(5).0 - 2.0 * 3f32.sqrt()).abs() < 1e-6);
    assert_eq!((record(6).0, record(6).2), (1.0, 1));
    // Standard output carries the same bytes (the summary goes to standard error).
    let piped = octrace(dir.path(), &["trace", "cube.oct", "--rays", "rays.bin", "--out", "-", "--all-hits"]);
    assert!(piped.status.success() && piped.stdout == all, "{piped:?}");
    let capped = ok(
        dir.path(),
        &["trace", "cube.oct", "--rays", "rays.bin", "--out", "cap.bin", "--all-hits", "--max-hits", "1"],
    );
    assert!(capped.contains("4 crossings (3 rays cut short at --max-hits)"), "{capped}");

    let out = ok(dir.path(), &["trace", "cube.oct", "--rays", "rays.bin", "--out", "counts.bin", "--counts", "--json"]);
    let json: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!((json["crossings"].as_u64(), json["entries"].as_u64()), (Some(7), Some(4)));
    let counts = std::fs::read(dir.path().join("counts.bin")).unwrap();
    let pairs: Vec<(u32, u32)> = (0..5).map(|i| (word(&counts, 2 * i), word(&counts, 2 * i + 1))).collect();
    assert_eq!(pairs, [(2, 1), (2, 1), (2, 1), (0, 0), (1, 1)]);

    ok(dir.path(), &["trace", "cube.oct", "--rays", "rays.bin", "--out", "len.bin", "--length-inside"]);
    let len = std::fs::read(dir.path().join("len.bin")).unwrap();
    let lengths: Vec<f32> = (0..5).map(|i| f32::from_bits(word(&len, i))).collect();
    assert_eq!((lengths[0], lengths[1], lengths[3], lengths[4]), (1.0, 1.0, 0.0, 0.5));
    assert!((lengths[2] - 3f32.sqrt()).abs() < 1e-6, "{lengths:?}");
    // On the GPU: the same bytes, --max-hits included.
    for (mode, cpu_file) in [
        (&["--all-hits"][..], "all.bin"),
        (&["--all-hits", "--max-hits", "1"][..], "cap.bin"),
        (&["--counts"][..], "counts.bin"),
        (&["--length-inside"][..], "len.bin"),
    ] {
        let args = [&["trace", "cube.oct", "--rays", "rays.bin", "--out", "gpu.bin", "--gpu"][..], mode].concat();
        let Some(out) = on_gpu(dir.path(), &args, "trace_lists_every_crossing_counts_and_lengths") else { return };
        assert!(out.contains("whole call"), "{out}");
        let (cpu, gpu) =
            (std::fs::read(dir.path().join(cpu_file)).unwrap(), std::fs::read(dir.path().join("gpu.bin")).unwrap());
        assert_eq!(cpu, gpu, "{mode:?}");
    }
}

/// `octrace points` and `octrace contains`: the closed cube answers as the exact
/// oracle does (`--check`), to a file and to standard output; `--reference` writes the
/// oracle's answers; an open mesh is refused by name unless a vote is asked for; NaN
/// points, empty files and files of the wrong size are refused naming the problem.
#[test]
fn contains_answers_points_and_refuses_bad_input() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("cube.obj"), CUBE_OBJ).unwrap();
    ok(dir.path(), &["bake", "cube.obj", "-o", "cube.oct"]);
    let out = ok(dir.path(), &["points", "cube.oct", "--count", "5000", "-o", "uniform.bin"]);
    // Choices are named as the command line names them, numbers with separators
    // (issue 50, item 7: `Uniform`, `Incoherent`, `Cells` and `41484 of 262144`).
    assert!(out.starts_with("wrote 5,000 uniform points"), "{out}");
    let out = ok(dir.path(), &["rays", "cube.oct", "--set", "incoherent", "-o", "incoherent.bin"]);
    assert!(out.starts_with("wrote 1,000,000 incoherent rays"), "{out}");
    let out = ok(dir.path(), &["render", "cube.oct", "--mode", "cells", "--width", "64", "-o", "cells.png"]);
    assert!(out.contains("(64 x 64, cells): ") && out.contains(" of 4,096 rays hit"), "{out}");
    // A PNG is written under a PNG's name (issue 50, item 6: `-o x.jpg` held PNG bytes).
    for name in ["x.jpg", "x.JPEG", "x.ppm"] {
        fails_saying(dir.path(), &["render", "cube.oct", "-o", name], "render writes PNG images");
        assert!(!dir.path().join(name).exists());
    }
    ok(dir.path(), &["render", "cube.oct", "--width", "8", "-o", "upper.PNG"]);
    ok(dir.path(), &["render", "cube.oct", "--width", "8", "-o", "bare"]);
    ok(dir.path(), &["points", "cube.oct", "--set", "near", "--count", "5000", "-o", "near.bin"]);
    for set in ["uniform.bin", "near.bin"] {
        let out = ok(dir.path(), &["contains", "cube.oct", "--points", set, "--out", "in.bin", "--check"]);
        assert!(out.contains("5,000 compared, 0 wrong"), "{out}");
        let answers = std::fs::read(dir.path().join("in.bin")).unwrap();
        let points = std::fs::read(dir.path().join(set)).unwrap();
        let n_inside = (0..5000)
            .filter(|&i| {
                let p: Vec<f32> = (0..3)
                    .map(|k| f32::from_le_bytes(points[12 * i + 4 * k..12 * i + 4 * k + 4].try_into().unwrap()))
                    .collect();
                p.iter().all(|&c| c > 0.0 && c < 1.0)
            })
            .count();
        assert_eq!(answers.iter().filter(|&&a| a == 1).count(), n_inside, "{set}");
        assert!(answers.iter().all(|&a| a <= 1));
        let piped = octrace(dir.path(), &["contains", "cube.oct", "--points", set, "--out", "-"]);
        assert!(piped.status.success() && piped.stdout == answers);
        // On the GPU (lavapipe in CI): the same answers, checked.
        let gpu = ["contains", "cube.oct", "--points", set, "--out", "gpu.bin", "--check", "--gpu"];
        if let Some(out) = on_gpu(dir.path(), &gpu, "contains --gpu") {
            assert!(out.contains("5,000 compared, 0 wrong") && out.contains("on the GPU"), "{out}");
            assert!(std::fs::read(dir.path().join("gpu.bin")).unwrap() == answers, "{set}: contains --gpu");
        }
    }
    ok(dir.path(), &["contains", "cube.oct", "--points", "near.bin", "--out", "ref.bin", "--reference"]);
    assert_eq!(std::fs::read(dir.path().join("ref.bin")).unwrap(), std::fs::read(dir.path().join("in.bin")).unwrap());

    // Points of the wrong kinds.
    let point = |p: [f32; 3]| p.iter().flat_map(|c| c.to_le_bytes()).collect::<Vec<u8>>();
    std::fs::write(dir.path().join("nan.bin"), [point([0.5; 3]), point([0.1, f32::NAN, 0.2])].concat()).unwrap();
    std::fs::write(dir.path().join("empty.bin"), []).unwrap();
    std::fs::write(dir.path().join("odd.bin"), [0u8; 13]).unwrap();
    let contains = |p: &'static str| ["contains", "cube.oct", "--points", p, "--out", "o.bin"];
    fails_saying(dir.path(), &contains("nan.bin"), "point 1 is not finite");
    fails_saying(dir.path(), &contains("empty.bin"), "empty file, no points");
    // The count's limit in the same words from the parser and the command (issue 46).
    let points = |n: &'static str| ["points", "cube.oct", "--count", n, "-o", "n.bin"];
    fails_saying(dir.path(), &points("0"), "1 to the 134217728 (2^27)");
    fails_saying(dir.path(), &points("300000000"), "more than the 134217728 (2^27)");
    fails_saying(dir.path(), &contains("odd.bin"), "13 bytes is not a whole number of 12-byte points");
    fails_saying(dir.path(), &contains("missing.bin"), "missing.bin");

    // An open mesh: the cube without its last two triangles.
    let open: String = CUBE_OBJ
        .lines()
        .filter(|l| !l.starts_with("f 2 3 7") && !l.starts_with("f 2 7 6"))
        .map(|l| format!("{l}\n"))
        .collect();
    std::fs::write(dir.path().join("open.obj"), open).unwrap();
    ok(dir.path(), &["bake", "open.obj", "-o", "open.oct"]);
    fails_saying(
        dir.path(),
        &["contains", "open.oct", "--points", "uniform.bin", "--out", "o.bin"],
        "4 of its 17 edges are boundary edges",
    );
    let out = ok(dir.path(), &["contains", "open.oct", "--points", "uniform.bin", "--out", "o.bin", "--vote", "5"]);
    assert!(out.contains("approximate, majority of 5 rays"), "{out}");
    fails_saying(
        dir.path(),
        &["contains", "open.oct", "--points", "uniform.bin", "--out", "o.bin", "--vote", "4"],
        "--vote must be odd",
    );
    // 60,000 bytes of points read as 1,875 rays: lengths inside need a closed mesh.
    fails_saying(
        dir.path(),
        &["trace", "open.oct", "--rays", "uniform.bin", "--out", "o.bin", "--length-inside"],
        "the scene is not closed",
    );
}

/// `octrace distance`: exact distances from a cube's points (inside it the distance is
/// the nearest face's, `min(c, 1 - c)`, exact in f32), signs, the band, the records'
/// layout, and bad input.
#[test]
fn distance_answers_points_exactly_and_refuses_bad_input() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("cube.obj"), CUBE_OBJ).unwrap();
    ok(d, &["bake", "cube.obj", "-o", "cube.oct"]);
    ok(d, &["points", "cube.oct", "--count", "3000", "-o", "uniform.bin"]);
    let out = ok(d, &["distance", "cube.oct", "--points", "uniform.bin", "-o", "d.bin", "--signed", "--check"]);
    assert!(out.contains("3,000 compared, 0 wrong") && out.contains("signed, exact"), "{out}");
    let words = |name: &str| -> Vec<u32> {
        let bytes = std::fs::read(d.join(name)).unwrap();
        bytes.chunks_exact(4).map(|w| u32::from_le_bytes(w.try_into().unwrap())).collect()
    };
    let points: Vec<f32> = words("uniform.bin").into_iter().map(f32::from_bits).collect();
    let records = words("d.bin");
    assert_eq!(records.len(), 3000 * 7);
    for (p, r) in points.chunks_exact(3).zip(records.chunks_exact(7)) {
        let nearest_face = p.iter().map(|&c| c.min(1.0 - c)).fold(f32::INFINITY, f32::min);
        assert_eq!(f32::from_bits(r[0]), -nearest_face, "point {p:?}");
        let q: Vec<f32> = r[1..4].iter().map(|&w| f32::from_bits(w)).collect();
        let off: f32 = (0..3).map(|k| (q[k] - p[k]).powi(2)).sum::<f32>().sqrt();
        assert!((off - nearest_face).abs() <= 1e-6, "point {p:?}: nearest point {q:?}");
        assert!(r[4] < 12, "triangle {}", r[4]);
    }
    let piped = octrace(d, &["distance", "cube.oct", "--points", "uniform.bin", "-o", "-", "--signed"]);
    assert!(piped.status.success() && piped.stdout == std::fs::read(d.join("d.bin")).unwrap());
    // A band: points farther than 0.1 answer -inf (inside) and no triangle.
    let out =
        ok(d, &["distance", "cube.oct", "--points", "uniform.bin", "-o", "b.bin", "--signed", "--max-distance", "0.1"]);
    assert!(out.contains("within reach"), "{out}");
    for (r, all) in words("b.bin").chunks_exact(7).zip(records.chunks_exact(7)) {
        let d = f32::from_bits(all[0]);
        if d < -0.1 {
            assert_eq!((f32::from_bits(r[0]), r[4]), (f32::NEG_INFINITY, u32::MAX));
            assert!(f32::from_bits(r[1]).is_nan());
        } else {
            assert_eq!(r, all);
        }
    }
    fails_saying(
        d,
        &["distance", "cube.oct", "--points", "uniform.bin", "-o", "x.bin", "--max-distance=-1"],
        "--max-distance",
    );
    fails_saying(d, &["distance", "cube.oct", "--points", "uniform.bin", "-o", "x.bin", "--vote", "3"], "--signed");
    let open: String = CUBE_OBJ
        .lines()
        .filter(|l| !l.starts_with("f 2 3 7") && !l.starts_with("f 2 7 6"))
        .map(|l| format!("{l}\n"))
        .collect();
    std::fs::write(d.join("open.obj"), open).unwrap();
    ok(d, &["bake", "open.obj", "-o", "open.oct"]);
    let signed_open = ["distance", "open.oct", "--points", "uniform.bin", "-o", "o.bin", "--signed"];
    // Signed by the winding number: above 1/2 everywhere inside the cube with a face
    // open (the hole subtends less than half the sphere).
    let out = ok(d, &signed_open);
    assert!(out.contains("signed by the winding number"), "{out}");
    for (p, r) in points.chunks_exact(3).zip(words("o.bin").chunks_exact(7)) {
        let inside = p.iter().all(|&c| c > 0.0 && c < 1.0);
        assert_eq!(f32::from_bits(r[0]) < 0.0, inside, "point {p:?}");
    }
    let out = ok(d, &[&signed_open[..], &["--vote", "3", "--check", "--json"]].concat());
    let j: serde_json::Value = serde_json::from_str(out.trim()).unwrap();
    assert_eq!((j["answer"].as_str(), j["check"]["wrong"].as_u64()), (Some("signed by a vote"), Some(0)), "{j}");
    let out = ok(d, &["distance", "open.oct", "--points", "uniform.bin", "-o", "o.bin", "--check"]);
    assert!(out.contains("3,000 compared, 0 wrong"), "{out}");
}

/// `bake`'s budgets name themselves and the option that raises them: a glTF whose
/// nodes share children (2^39 placements from a few hundred bytes) is refused before
/// loading, and raising --max-instances is not enough to make it bake; a tree past
/// --max-memory stops; byte counts take suffixes.
#[test]
fn bake_budgets_name_their_options() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mut nodes: Vec<String> = (0..39).map(|i| format!(r#"{{"children":[{0},{0}]}}"#, i + 1)).collect();
    nodes.push(r#"{"mesh":0}"#.into());
    let b64 = "AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAA"; // (0,0,0), (1,0,0), (0,1,0)
    let gltf = format!(
        r#"{{"asset":{{"version":"2.0"}},"scene":0,"scenes":[{{"nodes":[0]}}],"nodes":[{}],
        "meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}}}}]}}],
        "buffers":[{{"byteLength":36,"uri":"data:application/octet-stream;base64,{b64}"}}],
        "bufferViews":[{{"buffer":0,"byteLength":36}}],
        "accessors":[{{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}}]}}"#,
        nodes.join(",")
    );
    std::fs::write(d.join("dag.gltf"), gltf).unwrap();
    fails_saying(
        d,
        &["bake", "dag.gltf", "-o", "dag.oct"],
        "past the budget of 1048576 (raise it with --max-instances",
    );
    fails_saying(
        d,
        &["bake", "dag.gltf", "-o", "dag.oct", "--max-instances", "10000000000000"],
        "(raise it with --max-triangles",
    );
    assert!(!d.join("dag.oct").exists());
    std::fs::write(d.join("cube.obj"), CUBE_OBJ).unwrap();
    let deep = ["bake", "cube.obj", "-o", "cube.oct", "--max-depth", "10", "--leaf-size", "1"];
    fails_saying(d, &[&deep[..], &["--max-memory", "64K"]].concat(), "past the bake's memory budget of 65,536");
    ok(d, &[&deep[..], &["--max-memory", "1G"]].concat());
    fails_saying(d, &[&deep[..], &["--max-memory", "2Q"]].concat(), "unknown suffix 'Q'");
    // Count options are bounded before anything is allocated.
    fails_saying(d, &["verify", "cube.oct", "--rays", "10000000000"], "more than the 134217728 (2^27)");
    fails_saying(d, &["verify", "cube.oct", "--grid-rays", "10000000000"], "more than the 134217728 (2^27)");
    fails_saying(d, &["bench", "cube.oct", "--runs", "100000000"], "runs are 1 to 1000");
}

/// The peak resident memory of `octrace args`, in bytes, read from its
/// `/proc/PID/status` (VmHWM, a high-water mark) while it runs; `None` where there is
/// no /proc.
fn peak_memory(dir: &Path, args: &[&str]) -> Option<u64> {
    let mut child = Command::new(env!("CARGO_BIN_EXE_octrace"))
        .args(args)
        .current_dir(dir)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("octrace runs");
    let (exit, peak) = common::wait_with_peak(&mut child);
    assert!(exit.success(), "octrace {args:?} failed");
    peak
}

/// A valid scene of 5,000 point lights over one triangle: the render's memory stays
/// bounded whatever the light count (shadow rays in chunks). Before, each 8-row tile
/// held width x lights shadow rays (the audit's 100,000 lights passed 6 GB).
#[test]
fn many_lights_render_in_bounded_memory() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let lights = 5000;
    let mut nodes = vec![r#"{"mesh":0}"#.to_string()];
    nodes.extend((0..lights).map(|i| {
        let (x, y) = ((i % 100) as f32 * 0.01, (i / 100) as f32 * 0.02);
        format!(r#"{{"extensions":{{"KHR_lights_punctual":{{"light":0}}}},"translation":[{x},{y},1]}}"#)
    }));
    let roots: Vec<String> = (0..=lights).map(|i| i.to_string()).collect();
    let b64 = "AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAA"; // (0,0,0), (1,0,0), (0,1,0)
    let gltf = format!(
        r#"{{"asset":{{"version":"2.0"}},"extensionsUsed":["KHR_lights_punctual"],
        "extensions":{{"KHR_lights_punctual":{{"lights":[{{"type":"point","intensity":0.001}}]}}}},
        "scene":0,"scenes":[{{"nodes":[{}]}}],"nodes":[{}],
        "meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}}}}]}}],
        "buffers":[{{"byteLength":36,"uri":"data:application/octet-stream;base64,{b64}"}}],
        "bufferViews":[{{"buffer":0,"byteLength":36}}],
        "accessors":[{{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}}]}}"#,
        roots.join(","),
        nodes.join(",")
    );
    std::fs::write(d.join("lights.gltf"), gltf).unwrap();
    ok(d, &["bake", "lights.gltf", "-o", "lights.oct"]);
    let json: serde_json::Value = serde_json::from_str(&ok(d, &["inspect", "lights.oct", "--json"])).unwrap();
    assert_eq!(json["scene_data"]["lights"].as_array().map(Vec::len), Some(lights));
    let args = ["render", "lights.oct", "-o", "lights.png", "--width", "96", "--height", "96"];
    let Some(peak) = peak_memory(d, &args) else { return };
    // 96 x 8 pixels a tile x 5,000 lights x 48 bytes a shadow ray: 184 MB a tile
    // before; now a chunk of 4,096.
    assert!(peak < 100 << 20, "peak {} MB", peak >> 20);
    assert!(d.join("lights.png").exists());
}

/// Strings from meshes reach the terminal escaped (issue 33): a material named with
/// an escape sequence that would clear the screen, a title-setting sequence in an
/// `mtllib` name, a C1 control: `inspect` and `bake`'s warnings print `\u001b`, never
/// the byte; `inspect --json` keeps the exact name.
#[test]
fn strings_from_meshes_are_escaped_on_the_terminal() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let name = "red\u{1b}[2J\u{9b}31m\u{202e}";
    let b64 = "AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAA";
    let gltf = format!(
        r#"{{"asset":{{"version":"2.0"}},"scene":0,"scenes":[{{"nodes":[0]}}],"nodes":[{{"mesh":0,"name":"n\u001b]0;title\u0007"}}],
        "materials":[{{"name":"red\u001b[2J\u009b31m\u202e","emissiveFactor":[1,0,0]}}],
        "meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}},"material":0}}]}}],
        "buffers":[{{"byteLength":36,"uri":"data:application/octet-stream;base64,{b64}"}}],
        "bufferViews":[{{"buffer":0,"byteLength":36}}],
        "accessors":[{{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}}]}}"#
    );
    std::fs::write(d.join("named.gltf"), gltf).unwrap();
    ok(d, &["bake", "named.gltf", "-o", "named.oct"]);
    let text = ok(d, &["inspect", "named.oct"]);
    assert!(!text.contains('\u{1b}') && !text.contains('\u{9b}') && !text.contains('\u{7}'), "{text:?}");
    assert!(text.contains("red\\u001b[2J\\u009b31m\\u202e"), "{text}");
    let json: serde_json::Value = serde_json::from_str(&ok(d, &["inspect", "named.oct", "--json"])).unwrap();
    assert_eq!(json["scene_data"]["materials"][0]["name"].as_str(), Some(name));
    // A material library whose name sets the window title: the warning names it escaped.
    std::fs::write(d.join("m.obj"), "mtllib \u{1b}]0;pwned\u{7}.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
    let out = octrace(d, &["bake", "m.obj", "-o", "m.oct"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success() && err.contains("\\u001b]0;pwned\\u0007.mtl"), "{err}");
    assert!(!err.contains('\u{1b}') && !err.contains('\u{7}'), "{err:?}");
}

/// `bake -o -` writes the scene to standard output as `render`, `trace` and `rays` do
/// (never a file named "-"), the same bytes as to a file; an output name ending in
/// '/' says it names a folder.
#[test]
fn bake_writes_to_standard_output_and_says_what_a_folder_name_is() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("cube.obj"), CUBE_OBJ).unwrap();
    ok(d, &["bake", "cube.obj", "-o", "cube.oct"]);
    let piped = octrace(d, &["bake", "cube.obj", "-o", "-"]);
    assert!(piped.status.success(), "{}", String::from_utf8_lossy(&piped.stderr));
    assert_eq!(piped.stdout, std::fs::read(d.join("cube.oct")).unwrap());
    assert!(String::from_utf8_lossy(&piped.stderr).contains("-> -"));
    assert!(!d.join("-").exists());
    fails_saying(d, &["bake", "cube.obj", "-o", "missing/"], "the name ends in '/', a folder's");
    // A mesh where a scene is wanted: what to do.
    fails_saying(d, &["inspect", "cube.obj"], "cube.obj is a mesh (OBJ), not a baked scene: bake it first");
}

/// `inspect` reports leaves that stay overfull at the depth limit: a fan of 2,000
/// slivers around one vertex leaves the centre's leaves holding most of them.
#[test]
fn inspect_reports_overfull_leaves() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let n = 2000;
    let mut obj = String::from("v 0 0 0\n");
    for i in 0..=n {
        let a = std::f32::consts::TAU * i as f32 / n as f32;
        obj += &format!("v {} {} 0\n", a.cos(), a.sin());
    }
    for i in 0..n {
        obj += &format!("f 1 {} {}\n", i + 2, i + 3);
    }
    std::fs::write(d.join("fan.obj"), obj).unwrap();
    ok(d, &["bake", "fan.obj", "-o", "fan.oct"]);
    let json: serde_json::Value = serde_json::from_str(&ok(d, &["inspect", "fan.oct", "--json"])).unwrap();
    let overfull = &json["overfull_leaves"];
    assert!(overfull["leaves"].as_u64().unwrap() >= 1, "{overfull}");
    assert!(overfull["references"].as_u64().unwrap() > 1000, "{overfull}");
    let text = ok(d, &["inspect", "fan.oct"]);
    assert!(
        text.contains("the limit, with more than ") && text.contains("references: triangles sharing cells"),
        "{text}"
    );
    std::fs::write(d.join("cube.obj"), CUBE_OBJ).unwrap();
    ok(d, &["bake", "cube.obj", "-o", "cube.oct"]);
    let json: serde_json::Value = serde_json::from_str(&ok(d, &["inspect", "cube.oct", "--json"])).unwrap();
    assert_eq!(json["overfull_leaves"]["leaves"].as_u64(), Some(0));
}

/// `scripts/gpu-check.sh`, the device check, fails and names the comparison when one
/// GPU answer differs from the CPU's: a wrapper of the CLI flips one bit of the GPU's
/// hits on the bunny's primary set (the scene's, and the world of bunnies'), and the
/// quick check (lavapipe in CI) reports those as differing, every other comparison as
/// the same, and exits 1.
#[test]
fn the_gpu_check_fails_when_a_gpu_answer_differs() {
    use std::os::unix::fs::PermissionsExt;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let wrapper = d.join("octrace-flipping");
    std::fs::write(
        &wrapper,
        "#!/bin/sh\n\"$OCTRACE_REAL\" \"$@\" || exit $?\n\
         case \" $* \" in *' --gpu '*) ;; *) exit 0 ;; esac\n\
         case \" $* \" in *' --counts '*|*' --all-hits '*|*' --occluded '*) exit 0 ;; esac\n\
         case \"$1 $*\" in 'trace '*primary*) ;; *) exit 0 ;; esac\n\
         out=''; prev=''; for a in \"$@\"; do [ \"$prev\" = -o ] && out=\"$a\"; prev=\"$a\"; done\n\
         python3 -c 'import sys; f = open(sys.argv[1], \"r+b\"); b = f.read(1); f.seek(0); f.write(bytes([b[0] ^ 1]))' \"$out\"\n",
    )
    .unwrap();
    std::fs::set_permissions(&wrapper, std::fs::Permissions::from_mode(0o755)).unwrap();
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap();
    let json = d.join("check.json");
    let out = Command::new("bash")
        .arg(root.join("scripts/gpu-check.sh"))
        .args(["run", "--quick", "--no-tests", "--no-bench", "--bundle"])
        .arg(d.join("no-bundle"))
        .arg("--octrace")
        .arg(&wrapper)
        .arg("--json")
        .arg(&json)
        .env("OCTRACE_REAL", env!("CARGO_BIN_EXE_octrace"))
        .output()
        .expect("bash runs");
    let (stdout, stderr) = (String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    if stdout.contains("no Vulkan adapter") && std::env::var("OCTRACE_REQUIRE_GPU").as_deref() != Ok("1") {
        eprintln!("SKIPPED the_gpu_check_fails_when_a_gpu_answer_differs: no Vulkan adapter");
        return;
    }
    assert_eq!(out.status.code(), Some(1), "{stdout}\n{stderr}");
    assert!(stdout.contains("FAILED"), "{stdout}");
    let line = |name: &str| {
        stdout.lines().find(|l| l.starts_with(name)).unwrap_or_else(|| panic!("no {name} line: {stdout}")).to_string()
    };
    // The wrapper flips the GPU's nearest hits of every primary-set trace: the scene's
    // and the world of 100 bunnies'.
    assert!(line("trace bunny primary nearest ").contains(" differs "), "{stdout}");
    assert!(line("world nearest ").contains(" differs "), "{stdout}");
    for name in [
        "trace bunny shadow occluded",
        "trace bunny primary counts",
        "trace bunny primary every hit",
        "world occluded",
        "world counts",
        "render effects",
    ] {
        assert!(line(name).contains(" same "), "{name}: {stdout}");
    }
    let report: serde_json::Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    assert_eq!(report["ok"], false);
    let failed: Vec<&str> = report["checks"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|c| c["ok"] == false)
        .map(|c| c["name"].as_str().unwrap())
        .collect();
    assert_eq!(failed, ["trace bunny primary nearest", "world nearest"], "{stdout}");
}

/// `bench --gpu` compares the GPU's nearest hits with the CPU's bit for bit where the
/// kernel computes as the CPU does (f64 on the adapter), times the kernel on the GPU's
/// clock where it has timestamps and the first call apart, the transfers beside a memcpy,
/// compact records and camera rays made on the device; `rays --set shadow` writes
/// the shadow set `bench` traces.
#[test]
fn bench_on_the_gpu_compares_bits_and_times_the_kernel_apart() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("cube.obj"), CUBE_OBJ).unwrap();
    ok(d, &["bake", "cube.obj", "-o", "cube.oct"]);
    let args = ["bench", "cube.oct", "--gpu", "--no-peer", "--no-queries", "--runs", "5", "--json"];
    let Some(out) = on_gpu(d, &args, "bench_on_the_gpu_compares_bits_and_times_the_kernel_apart") else { return };
    let json: serde_json::Value = serde_json::from_str(&out).unwrap();
    let gpu = &json["gpu"];
    assert_eq!(gpu["compared_bits"], gpu["exact_edges"], "{gpu}");
    for s in gpu["sets"].as_array().unwrap() {
        assert_eq!(s["differ_from_cpu"], 0, "{s}");
        assert!(s["first_call_s"].as_f64().unwrap() > 0.0, "{s}");
        assert!(s["mrays_kernel"]["median"].as_f64().unwrap() > 0.0, "{s}");
        assert!(s["upload_ms"]["median"].as_f64().unwrap() > 0.0, "{s}");
        assert!(s["download_ms"]["median"].as_f64().unwrap() > 0.0, "{s}");
        assert!(s["mrays_compact"]["median"].as_f64().unwrap() > 0.0, "{s}");
        // The transfers alone, beside a memcpy of the same bytes.
        assert!(s["transfers_ms"]["median"].as_f64().unwrap() > 0.0, "{s}");
        assert!(s["memcpy_ms"]["median"].as_f64().unwrap() > 0.0, "{s}");
    }
    // Camera rays made on the device answer as the host's rays do.
    assert_eq!(gpu["camera"]["differ_from_cpu"], 0, "{gpu}");
    assert_eq!(gpu["camera"]["rays"], 1 << 20, "{gpu}");
    assert!(gpu["buffers_created"].as_u64().unwrap() > 0, "{gpu}");
    ok(d, &["rays", "cube.oct", "--set", "shadow", "-o", "shadow.bin"]);
    let shadow = json["sets"].as_array().unwrap().iter().find(|s| s["set"] == "shadow").unwrap();
    assert_eq!(shadow["rays"].as_u64(), Some(std::fs::metadata(d.join("shadow.bin")).unwrap().len() / 32));
}

/// A scene whose encoded image decodes to other texels than the bake's (a file edited
/// after the bake, its checksums made good again) opens, and `render` refuses it naming
/// the texture, before rendering it with a white texture; `inspect` says how each
/// texture is kept.
#[test]
fn render_refuses_an_image_that_decodes_to_other_texels() {
    let dir = tempfile::tempdir().unwrap();
    let leaf = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/data/textured/leaf.gltf");
    let mesh = octrace_bake::Mesh::load(&leaf).unwrap();
    let mut scene = octrace_bake::bake(&mesh, &octrace_bake::BuildParams::auto()).unwrap();
    let t = scene.shading.textures.iter_mut().find(|t| t.encoded.is_some()).expect("a PNG kept encoded");
    let name = t.name.clone();
    t.encoded.as_mut().unwrap().texels_hash ^= 1;
    scene.write(dir.path().join("leaf.oct"), 0).unwrap();
    let text = ok(dir.path(), &["inspect", "leaf.oct"]);
    assert!(text.contains("kept as a PNG of "), "{text}");
    fails_saying(dir.path(), &["render", "leaf.oct", "-o", "leaf.png"], &format!("texture '{name}'"));
    fails_saying(dir.path(), &["render", "leaf.oct", "-o", "leaf.png"], "decodes to other texels than at bake");
    assert!(!dir.path().join("leaf.png").exists());
    // `verify` decodes the images too (issue 46: it passed files `render` refuses).
    fails_saying(dir.path(), &["verify", "leaf.oct", "--rays", "10"], &format!("texture '{name}'"));
}

/// The surface's edge census is counted from the triangles, not read from the file
/// (issue 46): an open mesh whose stored census says closed (its checksums made
/// again, as a writer of the format would) is still open to `inspect`.
#[test]
fn inspect_counts_the_edges_rather_than_trusting_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // The cube without its +x face (and its degenerate triangle): a square hole.
    let open: String =
        CUBE_OBJ.lines().filter(|l| !l.starts_with("f 2 ") && !l.starts_with("f 1 2 2")).collect::<Vec<_>>().join("\n");
    std::fs::write(d.join("open.obj"), open).unwrap();
    let mesh = octrace_bake::Mesh::load(d.join("open.obj")).unwrap();
    let mut scene = octrace_bake::bake(&mesh, &octrace_bake::BuildParams::auto()).unwrap();
    assert_eq!(scene.stats.edges.boundary, 4);
    scene.stats.edges.boundary = 0;
    scene.write(d.join("lying.oct"), 0).unwrap();
    let text = ok(d, &["inspect", "lying.oct"]);
    assert!(text.contains("surface            open: 4 boundary edges"), "{text}");
    let json: serde_json::Value = serde_json::from_str(&ok(d, &["inspect", "lying.oct", "--json"])).unwrap();
    assert_eq!(json["surface"]["closed"], false);
    assert_eq!(json["surface"]["boundary_edges"], 4);
    std::fs::write(d.join("p.bin"), point_bytes(0.5)).unwrap();
    fails_saying(d, &["contains", "lying.oct", "--points", "p.bin", "-o", "in.bin"], "not closed");
}

/// One point `(x, x, x)` as a point file's 12 bytes.
fn point_bytes(x: f32) -> Vec<u8> {
    [x, x, x].iter().flat_map(|c| c.to_le_bytes()).collect()
}

/// `bake --raw-texels` stores the leaf's textures as texels rather than PNGs: a larger
/// file that renders to the same PNG bytes.
#[test]
fn raw_texels_render_as_the_encoded_images_do() {
    let dir = tempfile::tempdir().unwrap();
    let leaf = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/data/textured/leaf.gltf");
    ok(dir.path(), &["bake", leaf.to_str().unwrap(), "-o", "kept.oct"]);
    ok(dir.path(), &["bake", leaf.to_str().unwrap(), "-o", "raw.oct", "--raw-texels"]);
    let size = |f: &str| std::fs::metadata(dir.path().join(f)).unwrap().len();
    assert!(size("raw.oct") > 3 * size("kept.oct"), "{} against {}", size("raw.oct"), size("kept.oct"));
    assert!(ok(dir.path(), &["inspect", "raw.oct"]).contains("alpha down to 0.00, stored as texels"));
    for f in ["kept", "raw"] {
        ok(dir.path(), &["render", &format!("{f}.oct"), "-o", &format!("{f}.png"), "--width", "160"]);
    }
    assert!(std::fs::read(dir.path().join("kept.png")).unwrap() == std::fs::read(dir.path().join("raw.png")).unwrap());
}

/// Data written to `-` that does not all arrive is an error, not success (issue 46,
/// item 7): with standard output closed every `-o -` command said "wrote ... to -"
/// and exited 0; a reader that closes the pipe early likewise. Text output whose
/// reader stops (`inspect | head`) stays a quiet success.
#[cfg(unix)]
#[test]
fn data_that_does_not_reach_a_closed_stdout_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("cube.obj"), CUBE_OBJ).unwrap();
    ok(d, &["bake", "cube.obj", "-o", "cube.oct"]);
    ok(d, &["rays", "cube.oct", "-o", "rays.bin", "--set", "primary"]);
    let bin = env!("CARGO_BIN_EXE_octrace");
    let commands = [
        "bake cube.obj -o -",
        "render cube.oct -o - --width 16",
        "rays cube.oct -o -",
        "trace cube.oct --rays rays.bin --out -",
        "trace cube.oct --rays rays.bin --all-hits --out -",
        "trace cube.oct --rays rays.bin --counts --out -",
        "trace cube.oct --rays rays.bin --length-inside --out -",
    ];
    for command in commands {
        // Standard output closed (`>&-`).
        let closed =
            Command::new("sh").arg("-c").arg(format!("'{bin}' {command} >&-")).current_dir(d).output().unwrap();
        let stderr = String::from_utf8_lossy(&closed.stderr);
        assert_eq!(closed.status.code(), Some(1), "{command}: {stderr}");
        assert!(stderr.contains("standard output is closed") && !stderr.contains("wrote"), "{command}: {stderr}");
        // A reader that takes one byte and closes the pipe (the outputs of megabytes:
        // a small one fits in the pipe before the reader closes it).
        if command.starts_with("bake") || command.starts_with("render") {
            continue;
        }
        let early = Command::new("bash")
            .arg("-c")
            .arg(format!("set -o pipefail; '{bin}' {command} | head -c 1 > /dev/null"))
            .current_dir(d)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&early.stderr);
        assert_eq!(early.status.code(), Some(1), "{command}: {stderr}");
        assert!(stderr.contains("writing -o - to standard output failed after"), "{command}: {stderr}");
    }
    // Text: a reader that stops early is not a failure.
    let text = Command::new("bash")
        .arg("-c")
        .arg(format!("set -o pipefail; '{bin}' inspect cube.oct | head -c 1 > /dev/null"))
        .current_dir(d)
        .status()
        .unwrap();
    assert!(text.success());
}

/// `render --camera N` takes glTF's camera index, and a number the scene does not place
/// is refused naming the cameras it has, by number (issue 45, item 5).
#[test]
fn render_takes_gltf_camera_numbers() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let gltf =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/data/extensions.gltf")).unwrap();
    // The file's one camera becomes camera 2 (two others before it, not placed).
    let cameras = r#""cameras":[{"name":"a","type":"perspective","perspective":{"yfov":0.5,"znear":0.1}},{"name":"b","type":"perspective","perspective":{"yfov":0.5,"znear":0.1}},{"name":"cam""#;
    let moved = gltf.replace(r#""camera":0,"#, r#""camera":2,"#).replace(r#""cameras":[{"name":"cam""#, cameras);
    assert_ne!(moved, gltf);
    std::fs::write(d.join("ext.gltf"), moved).unwrap();
    ok(d, &["bake", "ext.gltf", "-o", "ext.oct"]);
    assert!(ok(d, &["inspect", "ext.oct"]).contains("2: 'cam', perspective"));
    ok(d, &["render", "ext.oct", "-o", "c.png", "--width", "24", "--camera", "2"]);
    let out = octrace(d, &["render", "ext.oct", "-o", "c.png", "--width", "24", "--camera", "0"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("--camera 0: the scene places no camera 0 (its cameras: 2 'cam')"), "{stderr}");
}

/// `bake` given a folder or a baked scene says which (issue 50, item 7: both were
/// "unknown mesh format").
#[test]
fn bake_names_a_folder_and_a_baked_scene() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("cube.obj"), CUBE_OBJ).unwrap();
    ok(d, &["bake", "cube.obj", "-o", "cube.oct"]);
    std::fs::create_dir(d.join("meshes")).unwrap();
    std::fs::create_dir(d.join("meshes.obj")).unwrap();
    for (input, says) in [
        ("meshes", "meshes: a folder, not a mesh"),
        ("meshes.obj", "meshes.obj: a folder, not a mesh"),
        ("cube.oct", "cube.oct: a baked scene already: bake reads meshes"),
        ("notes.txt", "notes.txt: unknown mesh format"),
    ] {
        let out = octrace(d, &["bake", input, "-o", "out.oct"]);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{input}: {stderr}");
        assert!(stderr.contains(says), "{input}: {stderr}");
    }
}

/// A scene description (JSON: scenes placed by transforms) traced and inspected where a
/// `.oct` is taken: each ray's nearest hit names its instance and the triangle of that
/// instance's scene, as the scene alone answers the ray moved by hand; bad
/// descriptions are refused naming what and where.
#[test]
fn trace_and_inspect_take_a_scene_description() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("cube.obj"), CUBE_OBJ).unwrap();
    std::fs::create_dir(d.join("props")).unwrap();
    ok(d, &["bake", "cube.obj", "-o", "props/cube.oct"]);
    let description = r#"{"scenes": {"cube": "props/cube.oct"}, "instances": [
        {"scene": "cube"},
        {"scene": "cube", "transform": [[1, 0, 0, 3], [0, 1, 0, 0], [0, 0, 1, 0]]},
        {"scene": "cube", "transform": [2, 0, 0, 6, 0, 2, 0, 0, 0, 0, 2, 0, 0, 0, 0, 1]}]}"#;
    std::fs::write(d.join("world.json"), description).unwrap();
    let ray = |x: f32, y: f32| -> Vec<u8> {
        [x, y, -5.0, 0.0, 0.0, 0.0, 1.0, f32::INFINITY].iter().flat_map(|v| v.to_le_bytes()).collect()
    };
    let rays: Vec<u8> = [ray(0.5, 0.3), ray(3.5, 0.3), ray(7.0, 1.5), ray(5.0, 0.5)].concat();
    std::fs::write(d.join("rays.bin"), &rays).unwrap();
    ok(d, &["trace", "world.json", "--rays", "rays.bin", "-o", "hits.bin"]);
    let hits = std::fs::read(d.join("hits.bin")).unwrap();
    assert_eq!(hits.len(), 4 * 12);
    let record = |i: usize| {
        let r = &hits[12 * i..12 * i + 12];
        let word = |k: usize| u32::from_le_bytes(r[4 * k..4 * k + 4].try_into().unwrap());
        (f32::from_bits(word(0)), word(1), word(2))
    };
    assert_eq!(record(0).0, 5.0);
    assert_eq!((record(0).1, record(1).1, record(2).1), (0, 1, 2));
    assert_eq!(record(1).0, 5.0);
    assert_eq!(record(3), (f32::INFINITY, u32::MAX, u32::MAX));
    // The cube alone, the ray moved into instance 1's space by hand: the same triangle.
    std::fs::write(d.join("one.bin"), ray(0.5, 0.3)).unwrap();
    ok(d, &["trace", "props/cube.oct", "--rays", "one.bin", "-o", "one_hits.bin"]);
    let one = std::fs::read(d.join("one_hits.bin")).unwrap();
    assert_eq!(u32::from_le_bytes(one[4..8].try_into().unwrap()), record(1).2);
    ok(d, &["trace", "world.json", "--rays", "rays.bin", "-o", "occluded.bin", "--occluded"]);
    let occluded: Vec<u8> = std::fs::read(d.join("occluded.bin")).unwrap();
    assert_eq!(occluded, [1u32, 1, 1, 0].iter().flat_map(|v| v.to_le_bytes()).collect::<Vec<u8>>());
    ok(d, &["trace", "world.json", "--rays", "rays.bin", "-o", "counts.bin", "--counts"]);
    let counts = std::fs::read(d.join("counts.bin")).unwrap();
    assert_eq!(&counts[..8], [2u32, 1].iter().flat_map(|v| v.to_le_bytes()).collect::<Vec<u8>>());
    let text = ok(d, &["inspect", "world.json"]);
    assert!(text.contains("3 instances of 1 scene, 36 triangles placed"), "{text}");
    let json: serde_json::Value = serde_json::from_str(&ok(d, &["inspect", "world.json", "--json"])).unwrap();
    assert_eq!(json["instances"].as_u64(), Some(3));
    for (bad, says) in [
        (r#"{"scenes": {}, "instances": [{"scene": "cube"}]}"#, "instance 0 names scene \"cube\""),
        (r#"{"scenes": {"cube": "props/cube.oct"}, "instances": [], "lights": 1}"#, "unknown field"),
        (
            r#"{"scenes": {"cube": "props/cube.oct"}, "instances": [{"scene": "cube", "transform": [1, 2]}]}"#,
            "instance 0's transform",
        ),
        (
            r#"{"scenes": {"cube": "props/cube.oct"}, "instances": [{"scene": "cube"}, {"scene": "cube", "transform": [[1, 0, 0, 0], [0, 0, 0, 0], [0, 0, 1, 0]]}]}"#,
            "singular",
        ),
        (r#"{"scenes": {"cube": "missing.oct"}, "instances": []}"#, "scene \"cube\""),
    ] {
        std::fs::write(d.join("bad.json"), bad).unwrap();
        fails_saying(d, &["trace", "bad.json", "--rays", "rays.bin", "-o", "bad.bin"], says);
        fails_saying(d, &["inspect", "bad.json"], says);
    }
    fails_saying(d, &["trace", "world.json", "--rays", "rays.bin", "-o", "x.bin", "--all-hits"], "take a .oct");
    // On the GPU: the same files.
    let test = "trace_and_inspect_take_a_scene_description";
    if on_gpu(d, &["trace", "world.json", "--rays", "rays.bin", "-o", "gpu_hits.bin", "--gpu"], test).is_some() {
        assert_eq!(std::fs::read(d.join("gpu_hits.bin")).unwrap(), hits);
        let args = ["trace", "world.json", "--rays", "rays.bin", "-o", "gpu_occluded.bin", "--occluded", "--gpu"];
        let text = on_gpu(d, &args, test).expect("a GPU");
        assert!(text.contains("instances' walks on the GPU"), "{text}");
        assert_eq!(std::fs::read(d.join("gpu_occluded.bin")).unwrap(), occluded);
        let args = ["trace", "world.json", "--rays", "rays.bin", "-o", "gpu_counts.bin", "--counts", "--gpu"];
        on_gpu(d, &args, test).expect("a GPU");
        assert_eq!(std::fs::read(d.join("gpu_counts.bin")).unwrap(), counts);
    }
    // Past the instances' budget: refused before any is placed.
    let many = format!(
        r#"{{"scenes": {{"cube": "props/cube.oct"}}, "instances": [{}]}}"#,
        vec![r#"{"scene":"cube"}"#; (1 << 20) + 1].join(",")
    );
    std::fs::write(d.join("many.json"), many).unwrap();
    fails_saying(d, &["inspect", "many.json"], "1048577 instances, past the 1048576");
}

/// `contains` and `distance` take a scene description where they take a `.oct`: inside
/// any closed instance, and the nearest point of every instance with its instance id
/// (32 bytes a point); what a description cannot answer is refused by name.
#[test]
fn contains_and_distance_take_a_scene_description() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("cube.obj"), CUBE_OBJ).unwrap();
    ok(d, &["bake", "cube.obj", "-o", "cube.oct"]);
    // The unit cube [0, 1]^3 as it is, and doubled about the origin then moved to x = 5.
    let description = r#"{"scenes": {"cube": "cube.oct"}, "instances": [
        {"scene": "cube"},
        {"scene": "cube", "transform": [[2, 0, 0, 5], [0, 2, 0, 0], [0, 0, 2, 0]]}]}"#;
    std::fs::write(d.join("world.json"), description).unwrap();
    let points: Vec<[f32; 3]> = vec![[0.5, 0.5, 0.5], [6.0, 1.0, 1.0], [3.0, 0.5, 0.5], [6.0, 1.0, 4.0]];
    std::fs::write(d.join("points.bin"), points.iter().flatten().flat_map(|c| c.to_le_bytes()).collect::<Vec<u8>>())
        .unwrap();
    ok(d, &["contains", "world.json", "--points", "points.bin", "-o", "inside.bin"]);
    assert_eq!(std::fs::read(d.join("inside.bin")).unwrap(), [1, 1, 0, 0]);
    let text = ok(d, &["distance", "world.json", "--points", "points.bin", "-o", "near.bin", "--signed"]);
    assert!(text.contains("4 points, 4 within reach, 2 inside, 2 instances"), "{text}");
    let near = std::fs::read(d.join("near.bin")).unwrap();
    assert_eq!(near.len(), 4 * 32);
    let record = |i: usize| {
        let word = |k: usize| u32::from_le_bytes(near[32 * i + 4 * k..32 * i + 4 * k + 4].try_into().unwrap());
        let f = |k: usize| f32::from_bits(word(k));
        (f(0), [f(1), f(2), f(3)], word(4))
    };
    // Inside the first cube, 0.5 from each face; inside the second, 1 from its faces.
    assert_eq!((record(0).0, record(0).2), (-0.5, 0));
    assert_eq!((record(1).0, record(1).2), (-1.0, 1));
    // Between them: 2 from the first cube's face x = 1 (the second's is at x = 5).
    assert_eq!((record(2).0, record(2).1[0], record(2).2), (2.0, 1.0, 0));
    // Above the second cube (top at z = 2): 2 away, the point on its top.
    assert_eq!(record(3), (2.0, [6.0, 1.0, 2.0], 1));
    fails_saying(d, &["distance", "world.json", "--points", "points.bin", "-o", "x.bin", "--check"], "take a .oct");
    fails_saying(d, &["contains", "world.json", "--points", "points.bin", "-o", "x.bin", "--vote", "3"], "take a .oct");
    // A stretched placement (x in [5, 6], y in [0, 3], z in [0, 1]): its placed
    // triangles measured in the world.
    let stretched = r#"{"scenes": {"cube": "cube.oct"}, "instances": [
        {"scene": "cube"}, {"scene": "cube", "transform": [[1, 0, 0, 5], [0, 3, 0, 0], [0, 0, 1, 0]]}]}"#;
    std::fs::write(d.join("stretched.json"), stretched).unwrap();
    ok(d, &["distance", "stretched.json", "--points", "points.bin", "-o", "near.bin"]);
    let near = std::fs::read(d.join("near.bin")).unwrap();
    let record = |i: usize| {
        let word = |k: usize| u32::from_le_bytes(near[32 * i + 4 * k..32 * i + 4 * k + 4].try_into().unwrap());
        let f = |k: usize| f32::from_bits(word(k));
        (f(0), [f(1), f(2), f(3)], word(4))
    };
    assert_eq!(record(3), (3.0, [6.0, 1.0, 1.0], 1));
    // Between them, as near the first cube's face as the second's: the lower instance.
    assert_eq!(record(2), (2.0, [1.0, 0.5, 0.5], 0));
}

/// `render` takes a scene description: the effects renderer through the world, from
/// the standard camera of the world's box; what it cannot do (the GPU, the
/// diagnostic modes, a scene's cameras) is refused by name.
#[test]
fn render_takes_a_scene_description() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("cube.obj"), CUBE_OBJ).unwrap();
    ok(d, &["bake", "cube.obj", "-o", "cube.oct"]);
    let description = r#"{"scenes": {"cube": "cube.oct"}, "instances": [
        {"scene": "cube"}, {"scene": "cube", "transform": [[0, -1, 0, 3], [1, 0, 0, 0], [0, 0, 1, 0]]}]}"#;
    std::fs::write(d.join("world.json"), description).unwrap();
    let json: serde_json::Value =
        serde_json::from_str(&ok(d, &["render", "world.json", "-o", "w.png", "--width", "64", "--json"])).unwrap();
    assert_eq!((json["instances"].as_u64(), json["width"].as_u64()), (Some(2), Some(64)));
    assert_eq!(json["rays"]["primary"].as_u64(), Some(64 * 64));
    assert!(std::fs::read(d.join("w.png")).unwrap().starts_with(b"\x89PNG"));
    for extra in [&["--gpu"][..], &["--mode", "cells"]] {
        let mut args = vec!["render", "world.json", "-o", "x.png", "--width", "16"];
        args.extend_from_slice(extra);
        fails_saying(d, &args, "take a .oct");
    }
    // The cameras are those of the scenes placed as they are: the cube has none.
    fails_saying(d, &["render", "world.json", "-o", "x.png", "--camera", "0"], "(its cameras: none)");
    std::fs::write(d.join("empty.json"), r#"{"scenes": {"cube": "cube.oct"}, "instances": []}"#).unwrap();
    fails_saying(d, &["render", "empty.json", "-o", "x.png"], "places no instance");
}

/// A glTF that places a mesh many times bakes to an instanced file (issue 51): the
/// sphere stored once (and once mirrored, for the placement that mirrors), within 20
/// times its GLB; `inspect`, `trace`, `render`, `contains` and `distance` open it as a
/// world, and its crossing counts are the flat bake's, ray for ray. Standard output and
/// compression are refused by name, and a description may not place it.
#[test]
fn a_gltf_placing_a_mesh_many_times_bakes_to_an_instanced_file() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let glb = octrace_tests::gltf::placed_spheres(98, false);
    std::fs::write(d.join("spheres.glb"), &glb).unwrap();
    let out = octrace(d, &["bake", "spheres.glb", "-o", "spheres.oct"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let said = String::from_utf8_lossy(&out.stdout);
    assert!(said.contains("2 meshes placed 98 times (21,200 triangles stored for 1,038,800 placed)"), "{said}");
    let size = std::fs::metadata(d.join("spheres.oct")).unwrap().len();
    assert!(size <= 20 * glb.len() as u64, "{size} bytes for a GLB of {}", glb.len());
    ok(d, &["bake", "spheres.glb", "-o", "flat.oct", "--flatten"]);
    let flat = std::fs::metadata(d.join("flat.oct")).unwrap().len();
    assert!(flat > 20 * size, "flat {flat}, instanced {size}");
    let inspected: serde_json::Value =
        serde_json::from_str(&ok(d, &["inspect", "spheres.oct", "--json"])).expect("json");
    assert_eq!(inspected["kind"], "instanced");
    assert_eq!((inspected["instances"].as_u64(), inspected["placed_triangles"].as_u64()), (Some(98), Some(1_038_800)));
    assert_eq!(inspected["instances_with_material_maps"].as_u64(), Some(96));
    ok(d, &["rays", "flat.oct", "--set", "primary", "-o", "rays.bin"]);
    for scene in ["spheres.oct", "flat.oct"] {
        ok(d, &["trace", scene, "--rays", "rays.bin", "--counts", "-o", &format!("{scene}.counts")]);
    }
    let counts = std::fs::read(d.join("spheres.oct.counts")).unwrap();
    assert!(counts == std::fs::read(d.join("flat.oct.counts")).unwrap(), "the counts differ");
    assert!(counts.chunks(8).filter(|c| c[0] != 0).count() > 100_000);
    ok(d, &["render", "spheres.oct", "-o", "spheres.png", "--width", "64", "--height", "32"]);
    assert!(std::fs::metadata(d.join("spheres.png")).unwrap().len() > 100);
    ok(d, &["points", "flat.oct", "--count", "200", "-o", "points.bin"]);
    ok(d, &["contains", "spheres.oct", "--points", "points.bin", "-o", "inside.bin"]);
    ok(d, &["distance", "spheres.oct", "--points", "points.bin", "-o", "distance.bin"]);
    for (args, says) in [
        (&["bake", "spheres.glb", "-o", "-"][..], "not to standard output"),
        (&["bake", "spheres.glb", "-o", "s.oct.zst", "--compress"][..], "not written compressed"),
    ] {
        let out = octrace(d, args);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success() && err.contains(says) && err.contains("--flatten"), "{args:?}: {err}");
    }
    // With a floor placed once, a light and a camera (aspect 2): the render takes the
    // file's camera, as the flat bake's does.
    std::fs::write(d.join("lit.glb"), octrace_tests::gltf::placed_spheres(30, true)).unwrap();
    ok(d, &["bake", "lit.glb", "-o", "lit.oct"]);
    ok(d, &["bake", "lit.glb", "-o", "lit-flat.oct", "--flatten"]);
    for scene in ["lit.oct", "lit-flat.oct"] {
        let said: serde_json::Value =
            serde_json::from_str(&ok(d, &["render", scene, "-o", "lit.png", "--width", "64", "--json"])).unwrap();
        assert_eq!((said["width"].as_u64(), said["height"].as_u64()), (Some(64), Some(32)), "{scene}");
    }
    let description = r#"{"scenes": {"s": "spheres.oct"}, "instances": [{"scene": "s"}]}"#;
    std::fs::write(d.join("world.json"), description).unwrap();
    let out = octrace(d, &["inspect", "world.json"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("is a world itself"), "{err}");
}
