//! octrace for Python: bake meshes, open baked scenes and ask them exact ray queries
//! with numpy arrays in and out, in the shape of Open3D's `RaycastingScene` (so that a
//! script switches by changing a line).
//!
//! The module is built by maturin (`pip install ./python`); its Python-facing docs are
//! the docstrings below and the type stubs in `octrace.pyi`. Every query releases the
//! GIL and runs on all cores unless `nthreads` says otherwise.

use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use numpy::{PyArray1, PyArrayDescrMethods, PyArrayMethods, PyReadonlyArrayDyn, PyUntypedArray, PyUntypedArrayMethods};
use octrace_bake::{BuildParams, LoadOptions, Mesh, References};
use octrace_runtime::cpu::CrossingCount;
use octrace_runtime::glam::{DVec3, Vec3};
use octrace_runtime::Ray;
use pyo3::create_exception;
use pyo3::exceptions::{PyMemoryError, PyOSError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};
use rayon::prelude::*;

/// The id of "no triangle" and "no part" in the arrays the queries return (Open3D's
/// `RaycastingScene.INVALID_ID`).
const INVALID_ID: u32 = u32::MAX;

/// The most threads a call may ask for (as the command line's `--threads`).
const MAX_THREADS: usize = 1024;

create_exception!(
    octrace,
    FormatError,
    PyValueError,
    "A file that is not a valid octrace scene: bad magic, another format version, a \
     checksum that does not match, contents that break the format's rules."
);
create_exception!(
    octrace,
    BakeError,
    PyValueError,
    "A mesh that cannot be baked: it does not parse, names files it may not read, has \
     non-finite coordinates, is empty, or passes a budget (the message says which and where)."
);
create_exception!(
    octrace,
    NotClosedError,
    PyValueError,
    "A query that needs an inside (compute_occupancy, contains, length_inside) on a scene \
     that is not closed: some edge is used by an odd number of triangles."
);

/// An I/O error as Python's `OSError` subclass for its kind (`FileNotFoundError`,
/// `PermissionError`, ...), with the message that names the file.
fn os_error(source: &std::io::Error, message: String) -> PyErr {
    PyErr::from(std::io::Error::new(source.kind(), message))
}

fn format_error(e: octrace_format::Error) -> PyErr {
    match &e {
        octrace_format::Error::Io { source, .. } | octrace_format::Error::Write { source, .. } => {
            os_error(source, e.to_string())
        }
        _ => FormatError::new_err(e.to_string()),
    }
}

fn runtime_error(e: octrace_runtime::Error) -> PyErr {
    match e {
        octrace_runtime::Error::Format(e) => format_error(e),
        e @ (octrace_runtime::Error::Alloc(_) | octrace_runtime::Error::Budget { .. }) => {
            PyMemoryError::new_err(e.to_string())
        }
        e @ octrace_runtime::Error::NotClosed { .. } => NotClosedError::new_err(e.to_string()),
        e => PyOSError::new_err(e.to_string()),
    }
}

/// An error opening `path`, the file named in the message.
fn open_error(e: octrace_runtime::Error, path: &Path) -> PyErr {
    match e {
        // I/O errors name the file already.
        octrace_runtime::Error::Format(
            e @ (octrace_format::Error::Io { .. } | octrace_format::Error::Write { .. }),
        ) => format_error(e),
        octrace_runtime::Error::Format(e) => FormatError::new_err(format!("{}: {e}", path.display())),
        e => runtime_error(e),
    }
}

fn bake_error(e: octrace_bake::Error) -> PyErr {
    match e {
        octrace_bake::Error::Format(e) => format_error(e),
        octrace_bake::Error::Unreadable { ref source, .. } => os_error(source, e.to_string()),
        e => BakeError::new_err(e.to_string()),
    }
}

/// Thread pools kept for reuse, the most recently used first: a pool past these is
/// dropped (its threads end once its calls are done), so that a program trying every
/// `nthreads` holds at most this many pools, not one a count.
const POOLS_KEPT: usize = 4;

/// Runs `work` on `nthreads` threads (0: all cores, rayon's global pool). The last
/// [`POOLS_KEPT`] counts' pools are kept for the next calls.
fn on_threads<R: Send>(nthreads: usize, work: impl FnOnce() -> R + Send) -> PyResult<R> {
    if nthreads == 0 {
        return Ok(work());
    }
    if nthreads > MAX_THREADS {
        return Err(PyValueError::new_err(format!("nthreads: {nthreads} is more than {MAX_THREADS}")));
    }
    static POOLS: Mutex<Vec<(usize, Arc<rayon::ThreadPool>)>> = Mutex::new(Vec::new());
    let pool = {
        let mut pools = POOLS.lock().unwrap_or_else(|e| e.into_inner());
        let pool = match pools.iter().position(|(n, _)| *n == nthreads) {
            Some(i) => pools.remove(i).1,
            None => Arc::new(
                rayon::ThreadPoolBuilder::new()
                    .num_threads(nthreads)
                    .thread_name(|i| format!("octrace-{i}"))
                    .build()
                    .map_err(|e| PyOSError::new_err(format!("cannot start {nthreads} threads: {e}")))?,
            ),
        };
        pools.insert(0, (nthreads, pool.clone()));
        pools.truncate(POOLS_KEPT);
        pool
    };
    Ok(pool.install(work))
}

/// `n` default values, or `MemoryError` naming `what` and the bytes where the
/// allocator refuses (an input's size decides `n`: never an abort).
fn zeros<T: Clone + Default>(n: usize, what: &'static str) -> PyResult<Vec<T>> {
    octrace_format::memory::try_vec(n, what).map_err(memory_error)
}

/// An empty vector with room for `n` values, or `MemoryError` ([`zeros`]).
fn room<T>(n: usize, what: &'static str) -> PyResult<Vec<T>> {
    octrace_format::memory::try_with_capacity(n, what).map_err(memory_error)
}

/// `n` values from `values` in a vector allocated once, or `MemoryError` ([`zeros`]).
fn collected<T>(n: usize, what: &'static str, values: impl Iterator<Item = T>) -> PyResult<Vec<T>> {
    let mut out = room(n, what)?;
    out.extend(values);
    Ok(out)
}

fn memory_error(e: octrace_format::memory::AllocError) -> PyErr {
    PyMemoryError::new_err(e.to_string())
}

/// A contiguous float32 array of shape `(..., k)` read in place: `what` names it in
/// errors.
struct Floats<'py> {
    array: PyReadonlyArrayDyn<'py, f32>,
    /// The shape without its last axis.
    lead: Vec<usize>,
}

impl<'py> Floats<'py> {
    /// Takes a numpy float32 array (read without a copy when C-contiguous) or anything
    /// `numpy.asarray` turns into one (a list of lists). Other dtypes are refused:
    /// converting them would hide a copy, and float64 rays rounded to float32 are other
    /// rays.
    fn new(obj: &Bound<'py, PyAny>, what: &str, k: usize) -> PyResult<Floats<'py>> {
        let py = obj.py();
        let np = py.import("numpy")?;
        let obj = match obj.cast::<PyUntypedArray>() {
            Ok(array) => {
                if !array.dtype().is_equiv_to(&numpy::dtype::<f32>(py)) {
                    return Err(PyValueError::new_err(format!(
                        "{what}: dtype {}, expected float32 (convert with .astype(numpy.float32))",
                        array.dtype()
                    )));
                }
                if array.is_c_contiguous() {
                    array.clone().into_any()
                } else {
                    np.call_method1("ascontiguousarray", (array,))?
                }
            }
            Err(_) => np
                .call_method1("asarray", (obj, np.getattr("float32")?))
                .map_err(|e| PyValueError::new_err(format!("{what}: not an array of numbers: {e}")))?,
        };
        let array: PyReadonlyArrayDyn<'py, f32> =
            obj.extract().map_err(|e| PyValueError::new_err(format!("{what}: not a float32 array: {e}")))?;
        let shape = array.shape().to_vec();
        if shape.last() != Some(&k) {
            return Err(PyValueError::new_err(format!("{what}: shape {}, expected (..., {k})", tuple(&shape))));
        }
        let lead = shape[..shape.len() - 1].to_vec();
        Ok(Floats { array, lead })
    }

    fn values(&self) -> &[f32] {
        self.array.as_slice().expect("made C-contiguous")
    }

    fn count(&self) -> usize {
        self.lead.iter().product()
    }

    /// The shape of a result with `tail` values an element.
    fn shape(&self, tail: &[usize]) -> Vec<usize> {
        self.lead.iter().chain(tail).copied().collect()
    }
}

/// A shape as Python writes it: `(3, 5)`, `(6,)`.
fn tuple(shape: &[usize]) -> String {
    match shape {
        [n] => format!("({n},)"),
        _ => format!("({})", shape.iter().map(usize::to_string).collect::<Vec<_>>().join(", ")),
    }
}

/// Rays converted and traced a piece at a time: the buffers stay in the caches and
/// are reused, where whole batches of `Ray` and `Option<Hit>` cost 60 bytes a ray of
/// fresh memory (page faults: a third of the module's overhead over the Rust batch
/// call at 10^6 primary rays). Large enough for the batch walk's memory order.
const PIECE: usize = 1 << 18;

/// Calls `trace(first, rays)` with the rays `[ox, oy, oz, dx, dy, dz]` of `values`
/// over `[tmin, tmax]`, a piece of at most [`PIECE`] at a time (`first`: the index of
/// the piece's first ray); a NaN anywhere is an error naming the ray, before any work.
fn each_piece(values: &[f32], tmin: f32, tmax: f32, mut trace: impl FnMut(usize, &[Ray])) -> PyResult<()> {
    refuse_nan_rays(values)?;
    let mut rays = Vec::new();
    for (p, chunk) in values.chunks(6 * PIECE).enumerate() {
        chunk.par_chunks_exact(6).map(|r| ray_of(r, tmin, tmax)).collect_into_vec(&mut rays);
        trace(p * PIECE, &rays);
    }
    Ok(())
}

/// The ray `[ox, oy, oz, dx, dy, dz]` over `[tmin, tmax]`.
fn ray_of(r: &[f32], tmin: f32, tmax: f32) -> Ray {
    Ray::segment(Vec3::new(r[0], r[1], r[2]), Vec3::new(r[3], r[4], r[5]), tmin, tmax)
}

/// An error naming the first ray with a NaN, if one has.
fn refuse_nan_rays(values: &[f32]) -> PyResult<()> {
    // A branch-free pass (it vectorises); the ray is looked for only once one is there.
    if values.par_chunks(1 << 14).any(|c| c.iter().fold(false, |nan, x| nan | x.is_nan())) {
        let i = values.chunks_exact(6).position(|r| r.iter().any(|x| x.is_nan())).expect("a NaN was seen");
        let r = &values[6 * i..6 * i + 6];
        return Err(PyValueError::new_err(format!("rays: ray {i} has a NaN: {r:?}")));
    }
    Ok(())
}

/// Every ray of `values` at once (for the calls whose answers are not one a ray).
fn to_rays(values: &[f32], tmin: f32, tmax: f32) -> PyResult<Vec<Ray>> {
    refuse_nan_rays(values)?;
    let mut rays = room(values.len() / 6, "rays")?;
    rays.par_extend(values.par_chunks_exact(6).map(|r| ray_of(r, tmin, tmax)));
    Ok(rays)
}

/// Points `[x, y, z]`; a NaN is an error naming the point.
fn to_points(values: &[f32]) -> PyResult<Vec<[f32; 3]>> {
    if let Some(i) = values.par_chunks_exact(3).position_first(|p| p.iter().any(|x| x.is_nan())) {
        let p = &values[3 * i..3 * i + 3];
        return Err(PyValueError::new_err(format!("query_points: point {i} has a NaN: {p:?}")));
    }
    let mut points = room(values.len() / 3, "query points")?;
    points.par_extend(values.par_chunks_exact(3).map(|p| [p[0], p[1], p[2]]));
    Ok(points)
}

/// A hit's `geometry_ids` entry: its part's index, 0 in a mesh without parts.
fn geometry_id(shading: &octrace_format::Shading, triangle: u32) -> u32 {
    if shading.parts.is_empty() {
        0
    } else {
        shading.part_index_of(triangle).unwrap_or(INVALID_ID)
    }
}

/// The zstd level to write at, or `None` uncompressed; a level outside 1-22 is an error.
fn compression(compress: bool, level: i32) -> PyResult<Option<i32>> {
    if compress && !(1..=22).contains(&level) {
        return Err(PyValueError::new_err(format!("level: {level}, expected 1 to 22")));
    }
    Ok(compress.then_some(level))
}

/// A numpy array of `shape` holding `values`.
fn array<'py, T: numpy::Element>(py: Python<'py>, values: Vec<T>, shape: Vec<usize>) -> PyResult<Bound<'py, PyAny>> {
    Ok(PyArray1::from_vec(py, values).reshape(shape)?.into_any())
}

/// A baked octrace scene, opened and validated, ready for ray queries.
///
/// The calls follow Open3D's ``RaycastingScene``: rays are float32 arrays of shape
/// ``(..., 6)``, ``[ox, oy, oz, dx, dy, dz]`` (the direction need not be unit; distances
/// are in units of it), and results are dicts of arrays of the rays' leading shape.
/// Triangles are named by their index in the input mesh; parts (``geometry_ids``) by
/// their index in ``parts`` (glTF node primitives, OBJ objects; 0 for a mesh without).
///
/// Answers are exact: every query agrees ray for ray with a brute-force double
/// precision reference, and one thread answers as all threads do.
///
/// Example::
///
///     import numpy as np, octrace
///     octrace.bake("bunny.obj", "bunny.oct")
///     scene = octrace.Scene("bunny.oct")
///     rays = scene.create_rays_pinhole(fov_deg=60, center=[0, 0.1, 0], eye=[0, 0.1, 0.5],
///                                      up=[0, 1, 0], width_px=640, height_px=480)
///     depth = scene.cast_rays(rays)["t_hit"]          # (480, 640), inf where missed
#[pyclass(module = "octrace", frozen)]
struct Scene {
    inner: octrace_runtime::Scene,
    /// The file's size on disk, for `inspect` (0 for a scene baked in memory).
    file_bytes: u64,
}

/// The bake's options, as `octrace bake` takes them.
struct BakeOptions {
    params: BuildParams,
    threads: usize,
}

impl BakeOptions {
    fn new(
        max_depth: Option<u32>,
        leaf_size: u32,
        margin: f32,
        max_memory: Option<u64>,
        threads: usize,
    ) -> PyResult<Self> {
        let params = BuildParams { max_depth, leaf_size: Some(leaf_size), margin, max_tree_bytes: max_memory };
        params.check().map_err(|e| PyValueError::new_err(e.to_string()))?;
        Ok(BakeOptions { params, threads })
    }

    fn bake(&self, mesh: &Mesh) -> PyResult<octrace_format::BakedScene> {
        on_threads(self.threads, || octrace_bake::bake(mesh, &self.params))?.map_err(bake_error)
    }
}

/// A mesh from numpy arrays: `vertices` `(n, 3)` (any real dtype, stored as float32)
/// and `triangles` `(m, 3)` integer indices into them.
fn mesh_of_arrays(vertices: &Bound<'_, PyAny>, triangles: &Bound<'_, PyAny>) -> PyResult<Mesh> {
    let py = vertices.py();
    let np = py.import("numpy")?;
    let v = np.call_method1("ascontiguousarray", (vertices, np.getattr("float32")?))?;
    let v = Floats::new(&v, "vertices", 3)?;
    let t = np.call_method1("asarray", (triangles,))?;
    let kind: String = t.getattr("dtype")?.getattr("kind")?.extract()?;
    if kind != "i" && kind != "u" {
        return Err(PyValueError::new_err(format!(
            "triangles: dtype {}, expected integer indices",
            t.getattr("dtype")?
        )));
    }
    let t = np.call_method1("ascontiguousarray", (t, np.getattr("int64")?))?;
    let t: PyReadonlyArrayDyn<'_, i64> = t.extract()?;
    if t.shape().len() != 2 || t.shape()[1] != 3 {
        return Err(PyValueError::new_err(format!("triangles: shape {}, expected (m, 3)", tuple(t.shape()))));
    }
    if v.lead.len() != 1 {
        return Err(PyValueError::new_err(format!("vertices: shape {}, expected (n, 3)", tuple(&v.shape(&[3])))));
    }
    let vertices = v.values();
    let n = v.count() as i64;
    let mut out = room(t.shape()[0], "triangles")?;
    for (i, tri) in t.as_slice().expect("contiguous").chunks_exact(3).enumerate() {
        let mut corners = [[0f32; 3]; 3];
        for (c, &index) in corners.iter_mut().zip(tri) {
            if !(0..n).contains(&index) {
                return Err(PyValueError::new_err(format!(
                    "triangles[{i}]: vertex index {index} out of range (there are {n} vertices)"
                )));
            }
            let at = 3 * index as usize;
            *c = [vertices[at], vertices[at + 1], vertices[at + 2]];
        }
        out.push(corners);
    }
    Ok(Mesh::from_triangles(out))
}

/// A baked scene's dict: what `bake` returns.
fn bake_summary<'py>(py: Python<'py>, scene: &octrace_format::BakedScene, bytes: u64) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("triangles", scene.stats.input_triangles)?;
    d.set_item("degenerate_triangles", scene.stats.degenerate_triangles)?;
    d.set_item("leaves", scene.leaf_count())?;
    d.set_item("max_depth", scene.params.max_depth)?;
    d.set_item("bytes", bytes)?;
    Ok(d)
}

/// Refuses an output that is one of the inputs (the mesh or a file it reads), as
/// `octrace bake` does: the same file by any path or hard link.
fn refuse_overwriting(output: &Path, inputs: &[&Path]) -> PyResult<()> {
    if !std::fs::metadata(output).is_ok_and(|m| m.is_file()) {
        return Ok(());
    }
    for input in inputs {
        if octrace_format::same_file(output, input) {
            return Err(PyValueError::new_err(format!(
                "output {} is one of the bake's inputs; choose another name",
                output.display()
            )));
        }
    }
    Ok(())
}

/// Writes `scene` to `output` (atomically: a complete file or none), zstd-compressed
/// at `level` when asked; the uncompressed size.
fn write_scene(
    scene: &octrace_format::BakedScene,
    output: &Path,
    compress: Option<i32>,
    time_us: u64,
) -> PyResult<u64> {
    match compress {
        Some(level) => scene.write_compressed(output, time_us, level).map(|(raw, _)| raw),
        None => scene.write(output, time_us),
    }
    .map_err(format_error)
}

/// Bakes a mesh file (``.obj``, ``.gltf``, ``.glb``, optionally ``.zst``) into a scene
/// file, as ``octrace bake MESH -o OUTPUT`` does, with the same options and errors.
///
/// Args:
///     mesh: the mesh file.
///     output: the ``.oct`` file to write (``.oct.zst`` with ``compress=True``); written
///         whole or not at all.
///     max_depth: the deepest octree level (default: from the triangle count).
///     leaf_size: split cells holding more triangles than this.
///     margin: cell enlargement, a fraction of the root edge (0 to 2**-10).
///     threads: threads to bake with (0: all cores); the file does not depend on it.
///     allow_outside_references: let the mesh read files outside its folder.
///     max_memory: the octree's memory budget in bytes while it is built (default:
///         1 KiB a triangle, at least 2 GiB, at most a third of the memory the process
///         may use).
///     max_instances: the most node placements a glTF scene may make.
///     max_triangles: the most triangles the mesh may hold once instanced.
///     compress: write the file zstd-compressed, at ``level`` (1-22).
///     record_time: record the bake's duration in the header (files then differ).
///
/// Returns:
///     a dict: ``triangles``, ``degenerate_triangles``, ``leaves``, ``max_depth``,
///     ``bytes`` (uncompressed), ``warnings`` (also issued as ``UserWarning``).
///
/// Raises:
///     OSError: the mesh cannot be read or the output written.
///     BakeError: the mesh does not parse or passes a budget (message names where).
///     ValueError: an option out of range.
///
/// Example::
///
///     summary = octrace.bake("bunny.obj", "bunny.oct")
///     print(summary["leaves"])
#[pyfunction]
#[pyo3(signature = (mesh, output, *, max_depth=None, leaf_size=octrace_bake::octree::DEFAULT_LEAF_SIZE,
    margin=octrace_bake::octree::DEFAULT_MARGIN, threads=0, allow_outside_references=false,
    max_memory=None, max_instances=octrace_bake::DEFAULT_MAX_INSTANCES,
    max_triangles=octrace_bake::DEFAULT_MAX_TRIANGLES, compress=false, level=3, record_time=false))]
#[allow(clippy::too_many_arguments)]
fn bake<'py>(
    py: Python<'py>,
    mesh: PathBuf,
    output: PathBuf,
    max_depth: Option<u32>,
    leaf_size: u32,
    margin: f32,
    threads: usize,
    allow_outside_references: bool,
    max_memory: Option<u64>,
    max_instances: u64,
    max_triangles: u64,
    compress: bool,
    level: i32,
    record_time: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let options = BakeOptions::new(max_depth, leaf_size, margin, max_memory, threads)?;
    let compress = compression(compress, level)?;
    let load = LoadOptions {
        references: if allow_outside_references { References::Anywhere } else { References::Confined },
        max_instances,
        max_triangles,
        ..LoadOptions::default()
    };
    refuse_overwriting(&output, &[&mesh])?;
    let (scene, bytes, warnings) = py.detach(|| -> PyResult<_> {
        let loaded = Mesh::load_with(&mesh, &load).map_err(bake_error)?;
        let sources: Vec<&Path> = loaded.sources.iter().map(PathBuf::as_path).collect();
        refuse_overwriting(&output, &sources)?;
        let started = std::time::Instant::now();
        let scene = options.bake(&loaded)?;
        let time_us = if record_time { started.elapsed().as_micros() as u64 } else { 0 };
        let mut warnings = loaded.warnings.clone();
        drop(loaded);
        warnings.extend(octrace_bake::octree::degenerate_warning(&scene));
        let bytes = write_scene(&scene, &output, compress, time_us)?;
        Ok((scene, bytes, warnings))
    })?;
    let warn = py.import("warnings")?;
    for w in &warnings {
        warn.call_method1("warn", (w.as_str(),))?;
    }
    let d = bake_summary(py, &scene, bytes)?;
    d.set_item("warnings", warnings)?;
    Ok(d)
}

/// Bakes a mesh given as numpy arrays into a scene file.
///
/// Args:
///     vertices: ``(n, 3)`` vertex positions (any real dtype; stored as float32).
///     triangles: ``(m, 3)`` integer vertex indices; triangle ``i`` is
///         ``primitive_ids == i`` in the answers.
///     output: the ``.oct`` file to write.
///     max_depth, leaf_size, margin, threads, max_memory, compress, level: as ``bake``.
///
/// Returns:
///     a dict as ``bake``'s.
///
/// Example::
///
///     v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)
///     octrace.bake_arrays(v, [[0, 1, 2]], "tri.oct")
#[pyfunction]
#[pyo3(signature = (vertices, triangles, output, *, max_depth=None, leaf_size=octrace_bake::octree::DEFAULT_LEAF_SIZE,
    margin=octrace_bake::octree::DEFAULT_MARGIN, threads=0, max_memory=None, compress=false, level=3))]
#[allow(clippy::too_many_arguments)]
fn bake_arrays<'py>(
    py: Python<'py>,
    vertices: &Bound<'py, PyAny>,
    triangles: &Bound<'py, PyAny>,
    output: PathBuf,
    max_depth: Option<u32>,
    leaf_size: u32,
    margin: f32,
    threads: usize,
    max_memory: Option<u64>,
    compress: bool,
    level: i32,
) -> PyResult<Bound<'py, PyDict>> {
    let options = BakeOptions::new(max_depth, leaf_size, margin, max_memory, threads)?;
    let compress = compression(compress, level)?;
    let mesh = mesh_of_arrays(vertices, triangles)?;
    let (scene, bytes) = py.detach(|| -> PyResult<_> {
        let scene = options.bake(&mesh)?;
        let bytes = write_scene(&scene, &output, compress, 0)?;
        Ok((scene, bytes))
    })?;
    bake_summary(py, &scene, bytes)
}

#[pymethods]
impl Scene {
    /// Opens a baked scene file.
    ///
    /// Args:
    ///     path: a ``.oct`` file (or ``.oct.zst``, read into memory).
    ///     mmap: memory-map the file instead of reading it (no copy; pages load on
    ///         demand). The file must then not be modified or truncated while the
    ///         scene is open: a truncated map kills the process (SIGBUS). Files that
    ///         ``octrace bake`` writes are replaced by rename, never in place.
    ///     trusted: check only the header and the archive's structure, not checksums
    ///         or the format's rules: microseconds whatever the size, for files this
    ///         pipeline baked (implies ``mmap``). A damaged file then answers wrongly,
    ///         never crashes.
    ///
    /// Raises:
    ///     OSError: the file cannot be read.
    ///     FormatError: the file is not a valid octrace scene.
    #[new]
    #[pyo3(signature = (path, *, mmap=false, trusted=false))]
    fn new(py: Python<'_>, path: PathBuf, mmap: bool, trusted: bool) -> PyResult<Scene> {
        py.detach(|| {
            let inner = if trusted {
                // SAFETY: the caller asked for a map and was told (above) that the
                // file must not change while the scene is open.
                unsafe { octrace_runtime::Scene::map_unchecked(&path) }
            } else if mmap {
                // SAFETY: as above.
                unsafe { octrace_runtime::Scene::map(&path) }
            } else {
                octrace_runtime::Scene::open(&path)
            }
            .map_err(|e| open_error(e, &path))?;
            let file_bytes = std::fs::metadata(&path).map(|m| m.len()).unwrap_or(0);
            Ok(Scene { inner, file_bytes })
        })
    }

    /// Bakes a mesh given as numpy arrays into a scene held in memory (no file).
    ///
    /// Args:
    ///     vertices: ``(n, 3)`` vertex positions (any real dtype; stored as float32).
    ///     triangles: ``(m, 3)`` integer vertex indices.
    ///     max_depth, leaf_size, margin, threads, max_memory: as ``octrace.bake``.
    ///
    /// Example::
    ///
    ///     v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)
    ///     scene = octrace.Scene.from_arrays(v, np.array([[0, 1, 2]]))
    ///     scene.cast_rays(np.array([[0.2, 0.2, 1, 0, 0, -1]], np.float32))["t_hit"]  # [1.]
    #[staticmethod]
    #[pyo3(signature = (vertices, triangles, *, max_depth=None, leaf_size=octrace_bake::octree::DEFAULT_LEAF_SIZE,
        margin=octrace_bake::octree::DEFAULT_MARGIN, threads=0, max_memory=None))]
    #[allow(clippy::too_many_arguments)]
    fn from_arrays(
        py: Python<'_>,
        vertices: &Bound<'_, PyAny>,
        triangles: &Bound<'_, PyAny>,
        max_depth: Option<u32>,
        leaf_size: u32,
        margin: f32,
        threads: usize,
        max_memory: Option<u64>,
    ) -> PyResult<Scene> {
        let options = BakeOptions::new(max_depth, leaf_size, margin, max_memory, threads)?;
        let mesh = mesh_of_arrays(vertices, triangles)?;
        py.detach(|| {
            let baked = options.bake(&mesh)?;
            // Through the file's bytes, so that the scene has a header for `inspect`.
            let bytes = baked.to_file_bytes(0).map_err(format_error)?;
            drop(baked);
            let inner = octrace_runtime::Scene::from_bytes(&bytes).map_err(runtime_error)?;
            Ok(Scene { inner, file_bytes: 0 })
        })
    }

    /// Input triangles (degenerate ones included: they are never hit).
    #[getter]
    fn triangle_count(&self) -> u64 {
        self.inner.view().stats.input_triangles
    }

    /// The mesh's parts, indexed by ``geometry_ids``: dicts of ``name`` (``node 3
    /// 'wheel', mesh 1 'tyre', primitive 0`` for glTF, ``object 'lid'`` for OBJ),
    /// ``first_triangle``, ``triangles``, and the part's numbers in its file: ``node``,
    /// ``mesh``, ``primitive`` (glTF) or ``object`` (OBJ, in file order). Empty for a
    /// mesh made from arrays.
    #[getter]
    fn parts<'py>(&self, py: Python<'py>) -> PyResult<Vec<Bound<'py, PyDict>>> {
        self.inner
            .shading()
            .parts
            .iter()
            .map(|p| {
                let d = PyDict::new(py);
                d.set_item("name", &p.name)?;
                d.set_item("first_triangle", p.first)?;
                d.set_item("triangles", p.count)?;
                for (key, value) in octrace_bake::summary::source_json(&p.source) {
                    d.set_item(key, value.as_u64())?;
                }
                Ok(d)
            })
            .collect()
    }

    /// The mesh's bounding box, ``(lo, hi)``, each ``[x, y, z]``.
    #[getter]
    fn bounds(&self) -> ([f32; 3], [f32; 3]) {
        let b = self.inner.view().bounds;
        (b.mesh_lo, b.mesh_hi)
    }

    /// Whether the mesh is closed (every edge used by an even number of triangles):
    /// ``compute_occupancy``, ``contains`` and ``length_inside`` need it. Counted from
    /// the triangles on first use, not read from the file.
    #[getter]
    fn is_closed(&self) -> bool {
        self.inner.edges().is_closed()
    }

    /// What ``octrace inspect --json`` prints, as a dict: triangles, leaves, depths,
    /// the surface's topology, bytes by section, materials, parts, lights, effects.
    fn inspect<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let view = self.inner.view();
        let file = self.inner.file().expect("scenes of this module come from files' bytes");
        let stats = octrace_format::stats::SceneStatistics::compute(&view).map_err(format_error)?;
        let on_disk = if self.file_bytes > 0 {
            self.file_bytes
        } else {
            octrace_format::HEADER_LEN as u64 + file.header().payload_len
        };
        let mut json = octrace_bake::summary::json(&view, &stats, &view.count_surface(), file.header(), on_disk);
        let fans = octrace_runtime::cpu::FanIndex::survey(&view);
        json["fans"] = fans.named().iter().map(|&(k, v)| (k.to_string(), serde_json::Value::from(v))).collect();
        py.import("json")?.call_method1("loads", (json.to_string(),))
    }

    /// The nearest hit of each ray (Open3D's ``cast_rays``).
    ///
    /// Args:
    ///     rays: float32 ``(..., 6)``, ``[ox, oy, oz, dx, dy, dz]``; hits at ``t >= 0``.
    ///     nthreads: threads (0: all cores).
    ///
    /// Returns:
    ///     a dict of arrays of the rays' leading shape: ``t_hit`` (float32, ``inf`` on a
    ///     miss), ``geometry_ids`` (uint32 part, ``INVALID_ID`` on a miss),
    ///     ``primitive_ids`` (uint32 input triangle, ``INVALID_ID`` on a miss),
    ///     ``primitive_uvs`` (float32 ``(..., 2)``: barycentrics of the second and third
    ///     vertices), ``primitive_normals`` (float32 ``(..., 3)``: the triangle's unit
    ///     normal, ``(v1 - v0) x (v2 - v0)`` normalised).
    ///
    /// Raises:
    ///     ValueError: not float32, not ``(..., 6)``, or a NaN (the message names the ray).
    ///
    /// Of hits at the same distance, the lowest triangle index is answered.
    #[pyo3(signature = (rays, nthreads=0))]
    fn cast_rays<'py>(&self, rays: &Bound<'py, PyAny>, nthreads: usize) -> PyResult<Bound<'py, PyDict>> {
        let py = rays.py();
        let input = Floats::new(rays, "rays", 6)?;
        let values = input.values();
        let n = input.count();
        let (t, geometry, primitive, uvs, normals) = py.detach(|| {
            on_threads(nthreads, || -> PyResult<_> {
                let tracer = self.inner.tracer();
                let (mut t, mut geometry, mut primitive) =
                    (zeros(n, "t_hit")?, zeros(n, "geometry_ids")?, zeros(n, "primitive_ids")?);
                let (mut uvs, mut normals) = (zeros(2 * n, "primitive_uvs")?, zeros(3 * n, "primitive_normals")?);
                let view = self.inner.view();
                let shading = self.inner.shading();
                let mut hits = vec![None; PIECE.min(n)];
                each_piece(values, 0.0, f32::INFINITY, |first, rays| {
                    let (hits, end) = (&mut hits[..rays.len()], first + rays.len());
                    tracer.par_intersect_batch(rays, hits);
                    t[first..end]
                        .par_iter_mut()
                        .zip(&mut geometry[first..end])
                        .zip(&mut primitive[first..end])
                        .zip(uvs[2 * first..2 * end].par_chunks_mut(2))
                        .zip(normals[3 * first..3 * end].par_chunks_mut(3))
                        .zip(&*hits)
                        .for_each(|(((((t, g), p), uv), normal), hit)| match hit {
                            Some(h) => {
                                *t = h.t;
                                *g = geometry_id(shading, h.triangle);
                                *p = h.triangle;
                                uv.copy_from_slice(&[h.u, h.v]);
                                let tri = view.triangle(h.prim);
                                normal.copy_from_slice(&octrace_runtime::spawn::face_normal(&tri).to_array());
                            }
                            None => {
                                *t = f32::INFINITY;
                                *g = INVALID_ID;
                                *p = INVALID_ID;
                            }
                        });
                })?;
                Ok((t, geometry, primitive, uvs, normals))
            })?
        })?;
        let d = PyDict::new(py);
        d.set_item("t_hit", array(py, t, input.shape(&[]))?)?;
        d.set_item("geometry_ids", array(py, geometry, input.shape(&[]))?)?;
        d.set_item("primitive_ids", array(py, primitive, input.shape(&[]))?)?;
        d.set_item("primitive_uvs", array(py, uvs, input.shape(&[2]))?)?;
        d.set_item("primitive_normals", array(py, normals, input.shape(&[3]))?)?;
        Ok(d)
    }

    /// Whether anything lies on each ray in ``[tnear, tfar]`` (Open3D's
    /// ``test_occlusions``): a bool array of the rays' leading shape.
    #[pyo3(signature = (rays, tnear=0.0, tfar=f32::INFINITY, nthreads=0))]
    fn test_occlusions<'py>(
        &self,
        rays: &Bound<'py, PyAny>,
        tnear: f32,
        tfar: f32,
        nthreads: usize,
    ) -> PyResult<Bound<'py, PyAny>> {
        let py = rays.py();
        let input = Floats::new(rays, "rays", 6)?;
        let (values, n) = (input.values(), input.count());
        let occluded = py.detach(|| {
            on_threads(nthreads, || -> PyResult<_> {
                let tracer = self.inner.tracer();
                let mut occluded = zeros(n, "occlusions")?;
                each_piece(values, tnear, tfar, |first, rays| {
                    tracer.par_occluded_batch(rays, &mut occluded[first..first + rays.len()])
                })?;
                Ok(occluded)
            })?
        })?;
        array(py, occluded, input.shape(&[]))
    }

    /// How many times each ray crosses the scene at ``t >= 0`` (Open3D's
    /// ``count_intersections``): int32, each crossing once (a ray through an edge or
    /// vertex that triangles share crosses once).
    #[pyo3(signature = (rays, nthreads=0))]
    fn count_intersections<'py>(&self, rays: &Bound<'py, PyAny>, nthreads: usize) -> PyResult<Bound<'py, PyAny>> {
        let py = rays.py();
        let input = Floats::new(rays, "rays", 6)?;
        let (values, n) = (input.values(), input.count());
        let counts = py.detach(|| {
            on_threads(nthreads, || -> PyResult<_> {
                let tracer = self.inner.tracer();
                let mut counts = zeros(n, "intersection counts")?;
                let mut piece = vec![CrossingCount::default(); PIECE.min(n)];
                each_piece(values, 0.0, f32::INFINITY, |first, rays| {
                    let piece = &mut piece[..rays.len()];
                    tracer.par_count_crossings_batch(rays, piece);
                    counts[first..first + rays.len()]
                        .par_iter_mut()
                        .zip(&*piece)
                        .for_each(|(out, c)| *out = c.total.min(i32::MAX as u32) as i32);
                })?;
                Ok(counts)
            })?
        })?;
        array(py, counts, input.shape(&[]))
    }

    /// Every crossing of each ray at ``t >= 0``, in order along it (Open3D's
    /// ``list_intersections``).
    ///
    /// Returns:
    ///     a dict: ``ray_splits`` (uint32, ``n + 1``: ray ``i``'s crossings are
    ///     ``ray_splits[i]:ray_splits[i + 1]``), ``ray_ids``, ``geometry_ids``,
    ///     ``primitive_ids`` (uint32), ``primitive_uvs`` (float32 ``(k, 2)``), ``t_hit``
    ///     (float32), and ``enters`` (bool: the ray arrives on the triangle's front,
    ///     entering a closed mesh wound outward). ``n`` counts the rays of any leading
    ///     shape, flattened in C order.
    ///
    /// Args:
    ///     max_hits: keep at most this many crossings a ray (its first ones).
    ///     max_memory: the most bytes the lists may take while they are found (20 a
    ///         crossing; the arrays returned take 25 a crossing more). Default: a
    ///         quarter of the memory this process may use (physical memory, or
    ///         ``ulimit -v`` where lower).
    ///
    /// Raises:
    ///     MemoryError: the lists pass ``max_memory``, or memory cannot be had; the
    ///         message says how much they took (pass ``max_hits``, or fewer rays).
    #[pyo3(signature = (rays, nthreads=0, *, max_hits=None, max_memory=None))]
    fn list_intersections<'py>(
        &self,
        rays: &Bound<'py, PyAny>,
        nthreads: usize,
        max_hits: Option<usize>,
        max_memory: Option<u64>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let py = rays.py();
        let input = Floats::new(rays, "rays", 6)?;
        let values = input.values();
        let budget = max_memory.unwrap_or_else(|| octrace_format::memory::share(4));
        let lists = py.detach(|| {
            on_threads(nthreads, || -> PyResult<_> {
                let rays = to_rays(values, 0.0, f32::INFINITY)?;
                self.inner.crossings_batch_within(&rays, max_hits.unwrap_or(usize::MAX), budget).map_err(runtime_error)
            })?
        })?;
        let k = lists.crossings.len();
        if k > u32::MAX as usize {
            return Err(PyValueError::new_err(format!(
                "{k} crossings do not fit ray_splits' uint32: pass max_hits, or fewer rays a call"
            )));
        }
        let shading = self.inner.shading();
        let c = &lists.crossings;
        let splits = collected(lists.splits.len(), "ray_splits", lists.splits.iter().map(|&s| s as u32))?;
        let ray_ids = collected(
            k,
            "ray_ids",
            lists.splits.windows(2).enumerate().flat_map(|(i, w)| std::iter::repeat_n(i as u32, w[1] - w[0])),
        )?;
        let geometry = collected(k, "geometry_ids", c.iter().map(|c| geometry_id(shading, c.triangle)))?;
        let primitive = collected(k, "primitive_ids", c.iter().map(|c| c.triangle))?;
        let uvs = collected(2 * k, "primitive_uvs", c.iter().flat_map(|c| [c.u, c.v]))?;
        let t = collected(k, "t_hit", c.iter().map(|c| c.t))?;
        let enters = collected(k, "enters", c.iter().map(|c| c.enters))?;
        drop(lists);
        let d = PyDict::new(py);
        d.set_item("ray_splits", PyArray1::from_vec(py, splits))?;
        d.set_item("ray_ids", PyArray1::from_vec(py, ray_ids))?;
        d.set_item("geometry_ids", PyArray1::from_vec(py, geometry))?;
        d.set_item("primitive_ids", PyArray1::from_vec(py, primitive))?;
        d.set_item("primitive_uvs", array(py, uvs, vec![k, 2])?)?;
        d.set_item("t_hit", PyArray1::from_vec(py, t))?;
        d.set_item("enters", PyArray1::from_vec(py, enters))?;
        Ok(d)
    }

    /// Whether each point lies inside the scene, a closed mesh (Open3D's
    /// ``compute_occupancy``): float32 1.0 inside, 0.0 outside, exact (``nsamples`` is
    /// accepted for Open3D's signature and not needed: there is no vote).
    ///
    /// Raises:
    ///     NotClosedError: the mesh is not closed (``is_closed``), so has no inside.
    #[pyo3(signature = (query_points, nthreads=0, nsamples=1))]
    fn compute_occupancy<'py>(
        &self,
        query_points: &Bound<'py, PyAny>,
        nthreads: usize,
        nsamples: usize,
    ) -> PyResult<Bound<'py, PyAny>> {
        let _ = nsamples;
        let (inside, shape) = self.inside(query_points, nthreads)?;
        array(query_points.py(), inside.into_iter().map(|b| if b { 1.0f32 } else { 0.0 }).collect(), shape)
    }

    /// Whether each point of ``query_points`` (float32 ``(..., 3)``) lies inside the
    /// scene, a closed mesh: a bool array of the points' leading shape, exact.
    ///
    /// Raises:
    ///     NotClosedError: the mesh is not closed.
    #[pyo3(signature = (query_points, nthreads=0))]
    fn contains<'py>(&self, query_points: &Bound<'py, PyAny>, nthreads: usize) -> PyResult<Bound<'py, PyAny>> {
        let (inside, shape) = self.inside(query_points, nthreads)?;
        array(query_points.py(), inside, shape)
    }

    /// The length of each ray's part ``t`` in ``[0, tmax]`` inside the scene, a
    /// closed mesh, in units of ``t`` (float32, the rays' leading shape).
    ///
    /// Raises:
    ///     NotClosedError: the mesh is not closed.
    #[pyo3(signature = (rays, tmax=f32::INFINITY, nthreads=0))]
    fn length_inside<'py>(&self, rays: &Bound<'py, PyAny>, tmax: f32, nthreads: usize) -> PyResult<Bound<'py, PyAny>> {
        let py = rays.py();
        let input = Floats::new(rays, "rays", 6)?;
        let values = input.values();
        let lengths = py.detach(|| {
            on_threads(nthreads, || -> PyResult<_> {
                self.inner.length_inside_batch(&to_rays(values, 0.0, tmax)?).map_err(runtime_error)
            })?
        })?;
        array(py, lengths, input.shape(&[]))
    }

    /// Rays of a pinhole camera, as Open3D's ``create_rays_pinhole``: float32
    /// ``(height_px, width_px, 6)``, directions through pixel centres on the image
    /// plane at distance 1 (not unit).
    ///
    /// Two forms, by keyword or position:
    ///
    /// * ``create_rays_pinhole(fov_deg, center, eye, up, width_px, height_px)``: a
    ///   horizontal field of view, looking from ``eye`` at ``center``;
    /// * ``create_rays_pinhole(intrinsic_matrix, extrinsic_matrix, width_px, height_px)``:
    ///   a 3x3 intrinsic matrix and the 4x4 world-to-camera transform.
    ///
    /// Example::
    ///
    ///     rays = octrace.Scene.create_rays_pinhole(fov_deg=90, center=[1, 0, 0],
    ///         eye=[0, 0, 0], up=[0, 0, 1], width_px=2, height_px=2)
    ///     rays.shape  # (2, 2, 6)
    #[staticmethod]
    #[pyo3(signature = (*args, **kwargs))]
    fn create_rays_pinhole<'py>(
        py: Python<'py>,
        args: &Bound<'py, PyTuple>,
        kwargs: Option<&Bound<'py, PyDict>>,
    ) -> PyResult<Bound<'py, PyAny>> {
        pinhole(py, args, kwargs)
    }

    fn __repr__(&self) -> String {
        let v = self.inner.view();
        format!(
            "octrace.Scene({} triangles, {} leaves, {} parts{})",
            v.stats.input_triangles,
            v.leaf_count(),
            self.inner.shading().parts.len(),
            if self.inner.edges().is_closed() { ", closed" } else { "" }
        )
    }
}

impl Scene {
    /// The inside of each query point, and the result's shape.
    fn inside(&self, query_points: &Bound<'_, PyAny>, nthreads: usize) -> PyResult<(Vec<bool>, Vec<usize>)> {
        let input = Floats::new(query_points, "query_points", 3)?;
        let values = input.values();
        let inside = query_points.py().detach(|| {
            on_threads(nthreads, || -> PyResult<_> {
                self.inner.contains_batch(&to_points(values)?).map_err(runtime_error)
            })?
        })?;
        Ok((inside, input.shape(&[])))
    }
}

/// `Scene.create_rays_pinhole`'s two forms.
fn pinhole<'py>(
    py: Python<'py>,
    args: &Bound<'py, PyTuple>,
    kwargs: Option<&Bound<'py, PyDict>>,
) -> PyResult<Bound<'py, PyAny>> {
    const FOV: [&str; 6] = ["fov_deg", "center", "eye", "up", "width_px", "height_px"];
    const MATRICES: [&str; 4] = ["intrinsic_matrix", "extrinsic_matrix", "width_px", "height_px"];
    let fov_form = match kwargs {
        Some(k) if k.contains("fov_deg")? => true,
        Some(k) if k.contains("intrinsic_matrix")? => false,
        _ => match args.get_item(0) {
            Ok(first) => first.extract::<f64>().is_ok(),
            Err(_) => {
                return Err(PyValueError::new_err(
                    "create_rays_pinhole: give fov_deg, center, eye, up, width_px, height_px \
                     or intrinsic_matrix, extrinsic_matrix, width_px, height_px",
                ))
            }
        },
    };
    let names: &[&str] = if fov_form { &FOV } else { &MATRICES };
    let mut given: Vec<Option<Bound<'py, PyAny>>> = vec![None; names.len()];
    if args.len() > names.len() {
        return Err(PyValueError::new_err(format!(
            "create_rays_pinhole: {} arguments, expected {}",
            args.len(),
            names.len()
        )));
    }
    for (slot, arg) in given.iter_mut().zip(args.iter()) {
        *slot = Some(arg);
    }
    if let Some(kwargs) = kwargs {
        for (key, value) in kwargs.iter() {
            let key: String = key.extract()?;
            let Some(i) = names.iter().position(|&n| n == key) else {
                return Err(PyValueError::new_err(format!(
                    "create_rays_pinhole: unexpected argument '{key}' (this form takes {})",
                    names.join(", ")
                )));
            };
            if given[i].replace(value).is_some() {
                return Err(PyValueError::new_err(format!("create_rays_pinhole: '{key}' given twice")));
            }
        }
    }
    let arg = |i: usize| {
        given[i].clone().ok_or_else(|| PyValueError::new_err(format!("create_rays_pinhole: '{}' missing", names[i])))
    };
    let np = py.import("numpy")?;
    let doubles = |i: usize, n: usize| -> PyResult<Vec<f64>> {
        let a = np.call_method1("asarray", (arg(i)?, np.getattr("float64")?))?;
        let a = np.call_method1("ascontiguousarray", (a,))?;
        let a: PyReadonlyArrayDyn<'_, f64> = a.extract()?;
        let values = a.as_slice().expect("contiguous").to_vec();
        if values.len() != n || values.iter().any(|x| !x.is_finite()) {
            return Err(PyValueError::new_err(format!(
                "create_rays_pinhole: '{}' must hold {n} finite numbers",
                names[i]
            )));
        }
        Ok(values)
    };
    let size = |i: usize| -> PyResult<usize> {
        let n: usize = arg(i)?.extract()?;
        if n == 0 || n > 1 << 16 {
            return Err(PyValueError::new_err(format!(
                "create_rays_pinhole: '{}' = {n}, expected 1 to 65536",
                names[i]
            )));
        }
        Ok(n)
    };
    let (width, height) = (size(names.len() - 2)?, size(names.len() - 1)?);
    // The camera: its centre, and the world-space directions of its x, y and z axes
    // (z forward; a pixel's direction is z + x * px + y * py on the plane at 1).
    let (origin, axes, k) = if fov_form {
        let fov: f64 = arg(0)?.extract()?;
        if !(fov > 0.0 && fov < 180.0) {
            return Err(PyValueError::new_err(format!("create_rays_pinhole: fov_deg = {fov}, expected (0, 180)")));
        }
        let v3 = |v: Vec<f64>| DVec3::new(v[0], v[1], v[2]);
        let (center, eye, up) = (v3(doubles(1, 3)?), v3(doubles(2, 3)?), v3(doubles(3, 3)?));
        let z = (center - eye).normalize_or_zero();
        let x = up.cross(z).normalize_or_zero();
        if z == DVec3::ZERO || x == DVec3::ZERO {
            return Err(PyValueError::new_err(
                "create_rays_pinhole: eye equals center, or up is parallel to the view direction",
            ));
        }
        let y = z.cross(x);
        let focal = 0.5 * width as f64 / (0.5 * fov.to_radians()).tan();
        (eye, [x, y, z], [focal, focal, 0.5 * width as f64, 0.5 * height as f64])
    } else {
        let k = doubles(0, 9)?;
        let e = doubles(1, 16)?;
        if k[0] == 0.0 || k[4] == 0.0 {
            return Err(PyValueError::new_err("create_rays_pinhole: intrinsic_matrix has a zero focal length"));
        }
        // World to camera: p_cam = R p + t; the camera's axes are R's rows, its centre
        // -R^T t.
        let row = |r: usize| DVec3::new(e[4 * r], e[4 * r + 1], e[4 * r + 2]);
        let t = DVec3::new(e[3], e[7], e[11]);
        let axes = [row(0), row(1), row(2)];
        let origin = -(axes[0] * t.x + axes[1] * t.y + axes[2] * t.z);
        if k[1] != 0.0 {
            return Err(PyValueError::new_err("create_rays_pinhole: intrinsic_matrix with skew is not supported"));
        }
        (origin, axes, [k[0], k[4], k[2], k[5]])
    };
    let [fx, fy, cx, cy] = k;
    let mut out = room(width * height * 6, "rays")?;
    for row in 0..height {
        for col in 0..width {
            let px = (col as f64 + 0.5 - cx) / fx;
            let py_ = (row as f64 + 0.5 - cy) / fy;
            let d = axes[0] * px + axes[1] * py_ + axes[2];
            out.extend([origin.x, origin.y, origin.z, d.x, d.y, d.z].map(|x| x as f32));
        }
    }
    array(py, out, vec![height, width, 6])
}

/// Bake meshes into octrace scenes and ask them exact ray queries from numpy.
#[pymodule(name = "octrace")]
fn octrace(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add("INVALID_ID", INVALID_ID)?;
    m.add_class::<Scene>()?;
    m.add_function(wrap_pyfunction!(bake, m)?)?;
    m.add_function(wrap_pyfunction!(bake_arrays, m)?)?;
    m.add("FormatError", py.get_type::<FormatError>())?;
    m.add("BakeError", py.get_type::<BakeError>())?;
    m.add("NotClosedError", py.get_type::<NotClosedError>())?;
    Ok(())
}
