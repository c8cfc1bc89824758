//! Baking from Python: `octrace.bake` (a mesh file) and `octrace.bake_arrays` (numpy
//! arrays), with `octrace bake`'s options and errors.

use std::path::{Path, PathBuf};

use numpy::{PyReadonlyArrayDyn, PyUntypedArrayMethods};
use octrace_bake::{BuildParams, LoadOptions, Mesh, References};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::arrays::{numpy_of, on_threads, tuple, Floats, Threads};
use crate::errors::{bake_error, format_error, room};

fn compression(compress: bool, level: i32) -> PyResult<Option<i32>> {
    if compress && !(1..=22).contains(&level) {
        return Err(PyValueError::new_err(format!("level: {level}, expected 1 to 22")));
    }
    Ok(compress.then_some(level))
}

/// The defaults the text signatures below show (pyo3 shows `...` for a default that
/// is not a literal); a change to them fails the build here.
const _: () = assert!(octrace_bake::octree::DEFAULT_LEAF_SIZE == 16);
const _: () = assert!(octrace_bake::octree::DEFAULT_MARGIN == 1.0 / (1u32 << 20) as f32);
const _: () = assert!(octrace_bake::DEFAULT_MAX_INSTANCES == 1 << 20);
const _: () = assert!(octrace_bake::DEFAULT_MAX_TRIANGLES == 1 << 27);

/// The bake's options, as `octrace bake` takes them.
pub(crate) struct BakeOptions {
    params: BuildParams,
    threads: Threads,
}

impl BakeOptions {
    pub(crate) fn new(
        max_depth: Option<u32>,
        leaf_size: u32,
        margin: f32,
        max_memory: Option<u64>,
        distance: bool,
        threads: Threads,
    ) -> PyResult<Self> {
        let params =
            BuildParams { max_depth, leaf_size: Some(leaf_size), margin, max_tree_bytes: max_memory, distance };
        params.check().map_err(|e| PyValueError::new_err(e.to_string()))?;
        Ok(BakeOptions { params, threads })
    }

    pub(crate) fn bake(&self, mesh: &Mesh) -> PyResult<octrace_format::BakedScene> {
        on_threads(self.threads, || octrace_bake::bake(mesh, &self.params))?.map_err(bake_error)
    }
}

/// A mesh from numpy arrays: `vertices` `(n, 3)` (any real dtype, stored as float32)
/// and `triangles` `(m, 3)` integer indices into them.
pub(crate) fn mesh_of_arrays(vertices: &Bound<'_, PyAny>, triangles: &Bound<'_, PyAny>) -> PyResult<Mesh> {
    let py = vertices.py();
    let np = py.import("numpy")?;
    let v = np.call_method1("ascontiguousarray", (numpy_of(vertices, "vertices")?, np.getattr("float32")?))?;
    let v = Floats::new(&v, "vertices", 3)?;
    let t = np.call_method1("asarray", (numpy_of(triangles, "triangles")?,))?;
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
///     distance: bake the closest-point search's tree into the file (about 24 bytes
///         a triangle), so that the scene's first closest-point, distance or
///         signed-distance query makes nothing (without it, the first query makes it:
///         0.3-0.4 s for the dragon's 871k triangles).
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
    max_triangles=octrace_bake::DEFAULT_MAX_TRIANGLES, distance=false, compress=false, level=3, record_time=false),
    text_signature = "(mesh, output, *, max_depth=None, leaf_size=16, margin=9.5367431640625e-07, threads=0, \
        allow_outside_references=False, max_memory=None, max_instances=1048576, max_triangles=134217728, distance=False, \
        compress=False, level=3, record_time=False)")]
#[allow(clippy::too_many_arguments)]
pub(crate) fn bake<'py>(
    py: Python<'py>,
    mesh: PathBuf,
    output: PathBuf,
    max_depth: Option<u32>,
    leaf_size: u32,
    margin: f32,
    threads: Threads,
    allow_outside_references: bool,
    max_memory: Option<u64>,
    max_instances: u64,
    max_triangles: u64,
    distance: bool,
    compress: bool,
    level: i32,
    record_time: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let options = BakeOptions::new(max_depth, leaf_size, margin, max_memory, distance, threads)?;
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
///     max_depth, leaf_size, margin, threads, max_memory, distance, compress, level: as
///         ``bake``.
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
    margin=octrace_bake::octree::DEFAULT_MARGIN, threads=0, max_memory=None, distance=false, compress=false, level=3),
    text_signature = "(vertices, triangles, output, *, max_depth=None, leaf_size=16, margin=9.5367431640625e-07, threads=0, \
        max_memory=None, distance=False, compress=False, level=3)")]
#[allow(clippy::too_many_arguments)]
pub(crate) fn bake_arrays<'py>(
    py: Python<'py>,
    vertices: &Bound<'py, PyAny>,
    triangles: &Bound<'py, PyAny>,
    output: PathBuf,
    max_depth: Option<u32>,
    leaf_size: u32,
    margin: f32,
    threads: Threads,
    max_memory: Option<u64>,
    distance: bool,
    compress: bool,
    level: i32,
) -> PyResult<Bound<'py, PyDict>> {
    let options = BakeOptions::new(max_depth, leaf_size, margin, max_memory, distance, threads)?;
    let compress = compression(compress, level)?;
    let mesh = mesh_of_arrays(vertices, triangles)?;
    let (scene, bytes) = py.detach(|| -> PyResult<_> {
        let scene = options.bake(&mesh)?;
        let bytes = write_scene(&scene, &output, compress, 0)?;
        Ok((scene, bytes))
    })?;
    bake_summary(py, &scene, bytes)
}
