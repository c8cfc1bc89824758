//! Bounded work for every input (issue 33): the budgets decided before the work, each
//! refused with an error naming it and the option that raises it.

use std::path::Path;

use octrace_bake::{bake, procedural, BuildParams, Error, LoadOptions, Mesh, MeshFormat};

/// An embedded glTF of one triangle (mesh 0) with `nodes` (JSON objects) and a scene
/// listing `roots`.
fn gltf_with_nodes(nodes: &[String], roots: &[usize]) -> String {
    let positions: [[f32; 3]; 3] = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
    let buf: Vec<u8> = positions.iter().flatten().flat_map(|c| c.to_le_bytes()).collect();
    let b64 = octrace_tests::base64(&buf);
    let roots: Vec<String> = roots.iter().map(usize::to_string).collect();
    format!(
        r#"{{"asset":{{"version":"2.0"}},"scene":0,"scenes":[{{"nodes":[{roots}]}}],"nodes":[{nodes}],
        "meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}}}}]}}],
        "buffers":[{{"byteLength":36,"uri":"data:application/octet-stream;base64,{b64}"}}],
        "bufferViews":[{{"buffer":0,"byteLength":36}}],
        "accessors":[{{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}}]}}"#,
        roots = roots.join(","),
        nodes = nodes.join(","),
    )
}

/// Node i lists node i + 1 twice, `levels` deep, with the mesh on the last node:
/// 2^(levels - 1) placements of it from a file of a few hundred bytes.
fn doubling_chain(levels: usize) -> String {
    let mut nodes: Vec<String> = (0..levels - 1).map(|i| format!(r#"{{"children":[{0},{0}]}}"#, i + 1)).collect();
    nodes.push(r#"{"mesh":0}"#.into());
    gltf_with_nodes(&nodes, &[0])
}

fn load(text: &str, options: &LoadOptions) -> Result<Mesh, Error> {
    Mesh::from_bytes_with(text.as_bytes(), MeshFormat::Gltf, Path::new("scene.gltf"), None, options)
}

/// A 60-level chain of shared children (2^59 placements; the audit's bake never
/// finished) is refused before the walk, naming the budget and its option; a chain of
/// 11 levels (1,024 placements) loads 1,024 triangles; a cycle is named.
#[test]
fn shared_children_are_counted_before_the_walk() {
    let text = doubling_chain(60);
    assert!(text.len() < 2048, "{} bytes", text.len());
    let err = load(&text, &LoadOptions::default()).unwrap_err();
    assert!(matches!(err, Error::Budget { .. }), "{err}");
    let message = err.to_string();
    assert!(message.contains("node placements") && message.contains("--max-instances"), "{message}");
    assert!(message.contains(&octrace_bake::DEFAULT_MAX_INSTANCES.to_string()), "{message}");

    let mesh = load(&doubling_chain(11), &LoadOptions::default()).unwrap();
    assert_eq!(mesh.triangles.len(), 1024);
    let small = LoadOptions { max_instances: 1000, ..LoadOptions::default() };
    assert!(matches!(load(&doubling_chain(11), &small), Err(Error::Budget { .. })));

    let cycle = gltf_with_nodes(
        &[r#"{"children":[1]}"#.into(), r#"{"children":[2],"mesh":0}"#.into(), r#"{"children":[1]}"#.into()],
        &[0],
    );
    let err = load(&cycle, &LoadOptions::default()).unwrap_err();
    assert!(err.to_string().contains("node 1: the node hierarchy has a cycle"), "{err}");
}

/// A scene listing one node many times: its triangles once instanced are counted
/// from the accessors before any is read.
#[test]
fn instanced_triangles_are_counted_before_loading() {
    let roots = vec![0; 5000];
    let text = gltf_with_nodes(&[r#"{"mesh":0}"#.into()], &roots);
    assert_eq!(load(&text, &LoadOptions::default()).unwrap().triangles.len(), 5000);
    let small = LoadOptions { max_triangles: 4999, ..LoadOptions::default() };
    let err = load(&text, &small).unwrap_err();
    let message = err.to_string();
    assert!(message.contains("triangles once instanced") && message.contains("--max-triangles"), "{message}");
    assert!(message.contains("5000 is past the budget of 4999"), "{message}");
    // An OBJ's triangles are counted as read.
    let obj = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 3 2\n";
    let err = Mesh::from_bytes_with(
        obj.as_bytes(),
        MeshFormat::Obj,
        Path::new("m.obj"),
        None,
        &LoadOptions { max_triangles: 1, ..LoadOptions::default() },
    )
    .unwrap_err();
    assert!(err.to_string().contains("triangles: 2 is past the budget of 1"), "{err}");
    // And from a file, read a block at a time (a plain OBJ is not held to the file-size
    // limit: its triangles and positions are counted as the blocks come).
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("m.obj");
    std::fs::write(&path, obj).unwrap();
    let tiny = LoadOptions { max_file_bytes: 8, ..LoadOptions::default() };
    assert_eq!(Mesh::load_with(&path, &tiny).unwrap().triangles.len(), 2);
    let err = Mesh::load_with(&path, &LoadOptions { max_triangles: 1, ..tiny }).unwrap_err();
    assert!(err.to_string().contains("m.obj: triangles: 2 is past the budget of 1"), "{err}");
    std::fs::write(&path, format!("{obj}{}", "v 0 0 0\n".repeat(4))).unwrap();
    let err = Mesh::load_with(&path, &LoadOptions { max_triangles: 2, ..LoadOptions::default() }).unwrap_err();
    assert!(err.to_string().contains("m.obj: positions: 7 is past the budget of 6"), "{err}");
    // An OBJ that is not plain is read whole, under the file-size limit.
    std::fs::write(&path, format!("o named\n{obj}")).unwrap();
    let err = Mesh::load_with(&path, &tiny).unwrap_err();
    assert!(err.to_string().contains("more than the limit of 8"), "{err}");
}

/// Coincident copies of one triangle share every cell it meets, at every depth: the
/// tree's references grow as copies times cells. The build stops as soon as the tree
/// passes the memory budget, and the same mesh bakes within a larger one.
#[test]
fn the_bake_stops_at_its_memory_budget() {
    let one = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.25]];
    let mesh = Mesh::from_triangles(vec![one; 3000]);
    let tight = BuildParams { max_tree_bytes: Some(256 << 10), ..BuildParams::auto() };
    let Err(err) = bake(&mesh, &tight) else { panic!("the bake passed its budget") };
    assert!(matches!(err, Error::TreeBudget { limit, needed } if limit == 256 << 10 && needed > limit), "{err}");
    assert!(err.to_string().contains("--max-memory"), "{err}");
    let baked = bake(&mesh, &BuildParams::auto()).unwrap();
    assert_eq!(baked.triangle_ids.len(), 3000);
    // Options that multiply references: a leaf of one triangle at depth 12.
    let sphere = procedural::sphere([0.0; 3], 1.0, 64, 96);
    let deep =
        BuildParams { max_depth: Some(12), leaf_size: Some(1), max_tree_bytes: Some(32 << 20), ..BuildParams::auto() };
    assert!(matches!(bake(&sphere, &deep).err(), Some(Error::TreeBudget { .. })));
}

/// Messages that say where and what (issue 33): an OBJ with a Latin-1 byte loads with
/// a warning naming its line; `usemtl` without a name is an error naming its line; a
/// GLB header cut short says so without Rust's debug forms; data: URIs are decoded as
/// RFC 2397 says (percent-encoded or base64) or refused by what is wrong;
/// `file://localhost/...` is an absolute path (refused from a confined mesh), and a
/// file: URI on another host is refused.
#[test]
fn messages_say_where_and_what() {
    let obj =
        |text: &[u8]| Mesh::from_bytes_with(text, MeshFormat::Obj, Path::new("m.obj"), None, &LoadOptions::default());
    let mesh = obj(b"v 0 0 0\nv 1 0 0\nv 0 1 0\n# caf\xe9\nf 1 2 3\n").unwrap();
    assert_eq!(mesh.triangles.len(), 1);
    assert!(mesh.warnings.iter().any(|w| w.contains("line 4: byte 0xE9 is not UTF-8")), "{:?}", mesh.warnings);
    let err = obj(b"v 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl\nf 1 2 3\n").unwrap_err();
    assert!(err.to_string().contains("m.obj: line 4: usemtl without a name"), "{err}");

    let glb =
        |bytes: &[u8]| Mesh::from_bytes(bytes, MeshFormat::Gltf, Path::new("s.glb"), None).unwrap_err().to_string();
    let short = glb(b"glTF\x02\x00\x00\x00\x0b");
    assert!(short.contains("GLB header: is cut short: the file has 9 bytes") && !short.contains("Some("), "{short}");
    let lying = glb(b"glTF\x02\x00\x00\x00\xff\x00\x00\x00");
    assert!(lying.contains("declares 255 bytes; the file has 12"), "{lying}");

    // One triangle as a data: URI: base64, percent-encoded, broken.
    let floats: Vec<u8> = [0f32, 0., 0., 1., 0., 0., 0., 1., 0.].iter().flat_map(|f| f.to_le_bytes()).collect();
    let percent: String = floats.iter().map(|b| format!("%{b:02X}")).collect();
    let with_uri = |uri: &str| {
        gltf_with_nodes(&[r#"{"mesh":0}"#.into()], &[0])
            .replace("data:application/octet-stream;base64,AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAA", uri)
    };
    assert_eq!(load(&with_uri(&format!("data:,{percent}")), &LoadOptions::default()).unwrap().triangles.len(), 1);
    let err = load(&with_uri("data:application/octet-stream;base64,AAAA*AAA"), &LoadOptions::default()).unwrap_err();
    assert!(
        err.to_string().contains("buffer 0: a base64 data: URI with a character base64 does not have at position 4"),
        "{err}"
    );
    let err = load(&with_uri("data:no-comma"), &LoadOptions::default()).unwrap_err();
    assert!(err.to_string().contains("without the ',' that starts its data"), "{err}");

    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("localhost"), b"not read").unwrap();
    let file = dir.path().join("s.gltf");
    for (uri, why) in [
        ("file://localhost/etc/hostname", "an absolute path"),
        ("file:///etc/hostname", "an absolute path"),
        ("file://example.com/etc/hostname", "a file: URI on another host ('example.com')"),
    ] {
        std::fs::write(&file, with_uri(uri)).unwrap();
        let err = Mesh::load(&file).unwrap_err();
        assert!(matches!(err, Error::Reference { .. }) && err.to_string().contains(why), "{uri}: {err}");
    }
}
