//! Hostile meshes: files that name other files of the machine (absolute paths, `file:`
//! URIs, `..` and percent-encoded escapes, devices, FIFOs, `/proc`), each a fixture in
//! `tests/data/hostile/`. By default nothing outside the mesh's folder is read, and
//! nothing that is not a regular file anywhere.

use std::path::{Path, PathBuf};
use std::time::Duration;

use octrace_bake::{Error, LoadOptions, Mesh, References};

/// The fixture copied into `<tmp>/outer/scene/`, beside a valid `<tmp>/outer/outside.mtl`
/// it may try to reach; returns the copy's path.
fn staged(dir: &Path, fixture: &str) -> PathBuf {
    let scene = dir.join("outer/scene");
    std::fs::create_dir_all(&scene).unwrap();
    std::fs::write(dir.join("outer/outside.mtl"), "newmtl red\nKd 1 0 0\n").unwrap();
    let from = Path::new(env!("CARGO_MANIFEST_DIR")).join("data/hostile").join(fixture);
    let to = scene.join(fixture);
    std::fs::copy(from, &to).unwrap();
    to
}

const ANYWHERE: LoadOptions = LoadOptions {
    references: References::Anywhere,
    max_file_bytes: 1 << 30,
    max_instances: octrace_bake::DEFAULT_MAX_INSTANCES,
    max_triangles: octrace_bake::DEFAULT_MAX_TRIANGLES,
};

/// Loads on a thread and fails the test if it takes more than ten seconds: a FIFO or a
/// device must be refused, not waited on.
fn load_within_seconds(path: PathBuf, options: LoadOptions) -> Result<Mesh, Error> {
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let _ = tx.send(Mesh::load_with(&path, &options));
    });
    rx.recv_timeout(Duration::from_secs(10)).expect("the load hung")
}

fn refused(result: Result<Mesh, Error>, reference: &str, reason: &str) {
    match result {
        Err(Error::Reference { reference: r, reason: why, element, .. }) => {
            assert_eq!(r, reference);
            assert_eq!(element, "buffer 0");
            assert!(why.contains(reason), "'{reference}': expected '{reason}' in: {why}");
        }
        other => panic!("'{reference}' should be refused, got {other:?}"),
    }
}

#[test]
fn gltf_buffers_outside_the_folder_are_refused_and_not_read() {
    let dir = tempfile::tempdir().unwrap();
    for (fixture, reference, reason) in [
        ("uri-absolute.gltf", "/etc/passwd", "an absolute path"),
        ("uri-file-scheme.gltf", "file:///etc/passwd", "an absolute path"),
        ("uri-dot-dot.gltf", "../../../../../../../../etc/passwd", "outside the mesh's folder"),
        (
            "uri-percent-encoded.gltf",
            "%2e%2e/%2E%2E/%2e%2e/%2e%2e/%2e%2e/%2e%2e/%2e%2e/etc/passwd",
            "outside the mesh's folder",
        ),
        ("uri-dev-zero.gltf", "/dev/zero", "an absolute path"),
        ("uri-dev-zero-huge.gltf", "/dev/zero", "an absolute path"),
        ("uri-proc.gltf", "/proc/self/environ", "an absolute path"),
        ("uri-http.gltf", "https://example.invalid/buffer.bin", "not a relative path"),
    ] {
        let path = staged(dir.path(), fixture);
        let err = load_within_seconds(path, LoadOptions::default());
        refused(err, reference, reason);
    }
    // The refusal says how to allow it.
    let err = Mesh::load(staged(dir.path(), "uri-absolute.gltf")).unwrap_err().to_string();
    assert!(err.contains("--allow-outside-references"), "{err}");
}

#[cfg(unix)]
#[test]
fn devices_and_fifos_are_refused_even_for_trusted_inputs() {
    let dir = tempfile::tempdir().unwrap();
    for fixture in ["uri-dev-zero.gltf", "uri-dev-zero-huge.gltf"] {
        let err = load_within_seconds(staged(dir.path(), fixture), ANYWHERE);
        refused(err, "/dev/zero", "not a regular file (a device)");
    }
    // A FIFO in the mesh's own folder: refused at once, not waited on.
    let path = staged(dir.path(), "uri-fifo.gltf");
    mkfifo(&path.with_file_name("fifo.bin"));
    refused(load_within_seconds(path.clone(), LoadOptions::default()), "fifo.bin", "(a FIFO)");
    refused(load_within_seconds(path, ANYWHERE), "fifo.bin", "(a FIFO)");
    // The mesh file itself as a FIFO or a device.
    let fifo = dir.path().join("pipe.obj");
    mkfifo(&fifo);
    let err = load_within_seconds(fifo, LoadOptions::default()).unwrap_err();
    assert!(matches!(err, Error::Unreadable { .. }) && err.to_string().contains("a FIFO"), "{err}");
    let dev = dir.path().join("zero.obj");
    std::os::unix::fs::symlink("/dev/zero", &dev).unwrap();
    let err = load_within_seconds(dev, LoadOptions::default()).unwrap_err();
    assert!(err.to_string().contains("not a regular file (a device)"), "{err}");
}

#[cfg(unix)]
fn mkfifo(path: &Path) {
    let status = std::process::Command::new("mkfifo").arg(path).status().expect("mkfifo runs");
    assert!(status.success());
}

#[test]
fn obj_material_libraries_outside_the_folder_cost_a_warning() {
    let dir = tempfile::tempdir().unwrap();
    for (fixture, reason) in [
        ("mtllib-outside.obj", "outside the mesh's folder"),
        ("mtllib-absolute.obj", "an absolute path"),
        ("mtllib-dev-zero.obj", "an absolute path"),
    ] {
        let mesh = load_within_seconds(staged(dir.path(), fixture), LoadOptions::default()).unwrap();
        assert!(mesh.materials.is_empty(), "{fixture}");
        assert_eq!(mesh.triangles.len(), 1);
        let warning = mesh.warnings.join("\n");
        assert!(warning.contains("material library") && warning.contains(reason), "{fixture}: {warning}");
    }
    // Trusted: the library beside the folder is read; a device still is not.
    let mesh = load_within_seconds(staged(dir.path(), "mtllib-outside.obj"), ANYWHERE).unwrap();
    assert_eq!(mesh.materials[0].name, "red");
    let mesh = load_within_seconds(staged(dir.path(), "mtllib-dev-zero.obj"), ANYWHERE).unwrap();
    assert!(mesh.materials.is_empty());
    assert!(mesh.warnings.join("\n").contains("not a regular file (a device)"), "{:?}", mesh.warnings);
}

#[test]
fn references_inside_the_folder_load() {
    let dir = tempfile::tempdir().unwrap();
    let sub = dir.path().join("scene/buffers");
    std::fs::create_dir_all(&sub).unwrap();
    let triangle: Vec<u8> =
        [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0].iter().flat_map(|c| c.to_le_bytes()).collect();
    std::fs::write(sub.join("tri angle.bin"), &triangle).unwrap();
    let text = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("data/hostile/uri-absolute.gltf"))
        .unwrap()
        .replace("/etc/passwd", "./buffers/../buffers/tri%20angle.bin");
    let path = dir.path().join("scene/ok.gltf");
    std::fs::write(&path, text).unwrap();
    let mesh = Mesh::load(&path).unwrap();
    assert_eq!(mesh.triangles, vec![[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]]);
    // A buffer shorter than its byteLength is an error, not a read past its end.
    std::fs::write(sub.join("tri angle.bin"), &triangle[..20]).unwrap();
    let err = Mesh::load(&path).unwrap_err();
    assert!(err.to_string().contains("20 bytes, but its byteLength says 36"), "{err}");
    // Nor a read past the size limit (the glTF itself is under it, the buffer not).
    let long: Vec<u8> = triangle.iter().copied().chain(std::iter::repeat_n(0, 4000)).collect();
    std::fs::write(sub.join("tri angle.bin"), long).unwrap();
    assert_eq!(Mesh::load(&path).unwrap().triangles.len(), 1);
    let small = LoadOptions { max_file_bytes: 2000, ..LoadOptions::default() };
    let err = Mesh::load_with(&path, &small).unwrap_err();
    assert!(
        matches!(err, Error::Reference { ref reason, .. } if reason.contains("4036 bytes, more than the limit of 2000")),
        "{err}"
    );
}
