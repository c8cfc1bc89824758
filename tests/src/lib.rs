//! Helpers shared by the integration tests: the bunny the repository carries, baked
//! once per test binary.

pub mod exact;
pub mod gltf;

use std::path::PathBuf;
use std::sync::OnceLock;

use octrace_bake::{bake, BuildParams, Mesh};
use octrace_runtime::Scene;

/// The repository's root: `OCTRACE_REPO` where set (a test binary carried to another
/// machine, `scripts/gpu-check.sh`), else the checkout it was built from.
pub fn repo_root() -> PathBuf {
    match std::env::var_os("OCTRACE_REPO") {
        Some(root) => PathBuf::from(root),
        None => PathBuf::from(env!("CARGO_MANIFEST_DIR")).parent().expect("tests/ is in the repo").to_path_buf(),
    }
}

/// The folder of shared meshes: `OCTRACE_SHARED` where set, else `../shared` beside
/// the repository.
pub fn shared_root() -> PathBuf {
    std::env::var_os("OCTRACE_SHARED").map_or_else(|| repo_root().join("../shared"), PathBuf::from)
}

/// The zstd-compressed bunny the repository carries.
pub fn bunny_path() -> PathBuf {
    repo_root().join("assets/bunny.obj.zst")
}

/// The bunny mesh, loaded once.
pub fn bunny_mesh() -> &'static Mesh {
    static MESH: OnceLock<Mesh> = OnceLock::new();
    MESH.get_or_init(|| Mesh::load(bunny_path()).expect("the repository's bunny loads"))
}

/// The bunny baked with the default parameters, once.
pub fn bunny_scene() -> &'static Scene {
    static SCENE: OnceLock<Scene> = OnceLock::new();
    SCENE.get_or_init(|| {
        Scene::from_baked(bake(bunny_mesh(), &BuildParams::auto()).expect("bunny bakes")).expect("valid")
    })
}

/// The shaded torus (`procedural::shaded_torus`: texture, mask, normals, texture
/// coordinates, vertex colours), baked to depth 5 with four triangles a leaf and its
/// closest-point tree (`distance`): every section of the file holds bytes.
pub fn torus_scene() -> octrace_format::BakedScene {
    let mesh = octrace_bake::procedural::shaded_torus(16, 8);
    bake(&mesh, &BuildParams { max_depth: Some(5), leaf_size: Some(4), distance: true, ..BuildParams::auto() })
        .expect("the torus bakes")
}

/// A test data file under `tests/data`.
pub fn data(name: &str) -> PathBuf {
    repo_root().join("tests/data").join(name)
}

/// zstd-compresses bytes (for `.zst` inputs made by tests).
pub fn zstd_compress(bytes: &[u8]) -> Vec<u8> {
    zstd::stream::encode_all(bytes, 3).expect("in-memory compression")
}

/// Standard base64 with padding (for embedded glTF buffers made by tests).
pub fn base64(bytes: &[u8]) -> String {
    const TABLE: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::new();
    for chunk in bytes.chunks(3) {
        let b = [chunk[0], *chunk.get(1).unwrap_or(&0), *chunk.get(2).unwrap_or(&0)];
        let n = (b[0] as u32) << 16 | (b[1] as u32) << 8 | b[2] as u32;
        for k in 0..4 {
            if k <= chunk.len() {
                out.push(TABLE[(n >> (18 - 6 * k) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

/// A file of `../shared` (beside the repository, or `OCTRACE_SHARED`), for the tests
/// that use the shared meshes, or `None` with a skip notice when it is missing.
///
/// # Panics
/// With `OCTRACE_REQUIRE_SHARED=1` (CI, which always has `../shared`), when the file
/// is missing: a test CI runs must never pass by skipping.
pub fn shared_file(relative: &str, test: &str) -> Option<PathBuf> {
    let path = shared_root().join(relative);
    if path.exists() {
        return Some(path);
    }
    if std::env::var("OCTRACE_REQUIRE_SHARED").is_ok_and(|v| v == "1") {
        panic!("OCTRACE_REQUIRE_SHARED=1 but {} is missing", path.display());
    }
    eprintln!("SKIPPED {test}: no {} (set OCTRACE_REQUIRE_SHARED=1 to make this a failure)", path.display());
    None
}

/// The GPU (a Vulkan adapter) for the GPU tests, opened once.
///
/// Without an adapter: with `OCTRACE_REQUIRE_GPU=1` (CI, which installs Mesa's software
/// driver), a panic; without it, `None` and a visible skip notice on stderr.
pub fn gpu(test: &str) -> Option<&'static octrace_runtime::gpu::GpuContext> {
    static GPU: OnceLock<Result<octrace_runtime::gpu::GpuContext, String>> = OnceLock::new();
    let required = std::env::var("OCTRACE_REQUIRE_GPU").is_ok_and(|v| v == "1");
    match GPU.get_or_init(|| octrace_runtime::gpu::GpuContext::new().map_err(|e| e.to_string())) {
        Ok(gpu) => Some(gpu),
        Err(e) if required => panic!("OCTRACE_REQUIRE_GPU=1 but {e}"),
        Err(e) => {
            eprintln!("SKIPPED {test}: {e} (set OCTRACE_REQUIRE_GPU=1 to make this a failure)");
            None
        }
    }
}

/// The CPU tracer whose answers a GPU tracer with the default options gives: the
/// watertight test (`GpuOptions::triangle_test`'s default; the CPU's is the exact one).
pub fn gpu_default_cpu(scene: &Scene) -> octrace_runtime::Tracer<'_> {
    scene.tracer().with_triangle_test(octrace_runtime::TriangleTest::Watertight)
}

/// [`Scene::intersect_batch`] with [`gpu_default_cpu`]'s tracer.
pub fn gpu_default_hits(scene: &Scene, rays: &[octrace_runtime::Ray]) -> Vec<Option<octrace_runtime::Hit>> {
    let mut out = vec![None; rays.len()];
    gpu_default_cpu(scene).par_intersect_batch(rays, &mut out);
    out
}

/// [`Scene::occluded_batch`] with [`gpu_default_cpu`]'s tracer.
pub fn gpu_default_occluded(scene: &Scene, rays: &[octrace_runtime::Ray]) -> Vec<bool> {
    let mut out = vec![false; rays.len()];
    gpu_default_cpu(scene).par_occluded_batch(rays, &mut out);
    out
}
