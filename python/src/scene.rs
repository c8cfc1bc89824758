//! `octrace.Scene`: opening a baked file or baking arrays into memory, what the scene
//! holds (parts, bounds, materials, statistics), and its queries' Python faces (the
//! work is in `queries`).

use std::path::PathBuf;
use std::sync::Arc;

use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};

use crate::arrays::{array, Threads};
use crate::baking::{mesh_of_arrays, BakeOptions};
use crate::device::{Device, Rays};
use crate::errors::{format_error, open_error, runtime_error};
use crate::pinhole::pinhole;

///
/// The calls follow Open3D's ``RaycastingScene``: rays are float32 arrays of shape
/// ``(..., 6)``, ``[ox, oy, oz, dx, dy, dz]`` (the direction need not be unit; distances
/// are in units of it), and results are dicts of arrays of the rays' leading shape.
/// Triangles are named by their index in the input mesh; parts (``geometry_ids``) by
/// their index in ``parts`` (glTF node primitives, OBJ objects; a mesh without has one, 0).
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
pub(crate) struct Scene {
    pub(crate) inner: Arc<octrace_runtime::Scene>,
    /// The file's size on disk, for `inspect` (0 for a scene baked in memory).
    file_bytes: u64,
    /// The file and the options it was opened with, absolute (what a pickle holds);
    /// `None` for a scene baked in memory.
    opened: Option<(PathBuf, bool, bool)>,
    /// Where the ray queries run.
    device: Device,
    /// The scene on the GPU, where `device` is `Gpu`.
    #[cfg(feature = "gpu")]
    gpu: Option<crate::device::gpu::OnGpu>,
}

impl Scene {
    /// A scene whose ray queries run on `device`.
    fn on(
        inner: octrace_runtime::Scene,
        device: Device,
        file_bytes: u64,
        opened: Option<(PathBuf, bool, bool)>,
    ) -> PyResult<Scene> {
        let inner = Arc::new(inner);
        #[cfg(feature = "gpu")]
        let gpu = match device {
            Device::Gpu => Some(crate::device::gpu::OnGpu::new(&inner)?),
            Device::Cpu => None,
        };
        #[cfg(not(feature = "gpu"))]
        if device == Device::Gpu {
            return Err(crate::device::without_gpu());
        }
        Ok(Scene {
            inner,
            file_bytes,
            opened,
            device,
            #[cfg(feature = "gpu")]
            gpu,
        })
    }

    /// The tracer the ray queries go to: the CPU's, or the scene's on the GPU.
    pub(crate) fn rays(&self) -> Rays<'_> {
        #[cfg(feature = "gpu")]
        if let Some(gpu) = &self.gpu {
            return Rays::Gpu(gpu.tracer());
        }
        Rays::Cpu(&self.inner)
    }
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
    ///     device: where the ray queries (``cast_rays``, ``test_occlusions``,
    ///         ``count_intersections``, ``list_intersections``, ``length_inside``) run:
    ///         ``"cpu"``, or ``"gpu"`` (a module built with the GPU, ``HAS_GPU``; a
    ///         Vulkan adapter with 64-bit floats), which answers as the CPU does, ray for
    ///         ray, bit for bit: the CPU's triangle test (exact; watertight in a
    ///         scene with fans), the rays the exact test's filter cannot decide
    ///         finished on the CPU. Of the point queries, ``contains``
    ///         (and ``compute_occupancy`` of a closed mesh) run there too, the points
    ///         near the surface finished on the CPU; the others run on the CPU.
    ///
    /// Raises:
    ///     OSError: the file cannot be read.
    ///     FormatError: the file is not a valid octrace scene.
    ///     GpuError: ``device="gpu"`` and the GPU cannot serve the scene (the message
    ///         says why).
    ///
    /// Example::
    ///
    ///     scene = octrace.Scene("bunny.oct", device="gpu")
    ///     scene.cast_rays(rays)["t_hit"]   # as Scene("bunny.oct"), bit for bit
    #[new]
    #[pyo3(signature = (path, *, mmap=false, trusted=false, device="cpu"))]
    fn new(py: Python<'_>, path: PathBuf, mmap: bool, trusted: bool, device: &str) -> PyResult<Scene> {
        let device = Device::parse(device)?;
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
            let absolute = std::path::absolute(&path).unwrap_or(path);
            Scene::on(inner, device, file_bytes, Some((absolute, mmap, trusted)))
        })
    }

    /// What a pickle holds: the file's absolute path and the options it was opened
    /// with, ``device`` among them (a worker without the GPU raises ``GpuError``), so
    /// that a worker process (``multiprocessing``, Dask, Ray) opens the same file
    /// (mapped scenes share its pages through the page cache; ``trusted=True`` opens
    /// in microseconds). A scene baked in memory (``from_arrays``) has no file:
    /// ``bake_arrays`` writes one to share.
    ///
    /// Raises:
    ///     TypeError: the scene has no file.
    fn __getnewargs_ex__<'py>(&self, py: Python<'py>) -> PyResult<(Bound<'py, PyTuple>, Bound<'py, PyDict>)> {
        let Some((path, mmap, trusted)) = &self.opened else {
            return Err(pyo3::exceptions::PyTypeError::new_err(
                "cannot pickle a scene baked in memory (Scene.from_arrays): it has no file for \
                 another process to open; write one with octrace.bake_arrays and open that",
            ));
        };
        let kwargs = PyDict::new(py);
        kwargs.set_item("mmap", mmap)?;
        kwargs.set_item("trusted", trusted)?;
        kwargs.set_item("device", self.device.name())?;
        Ok((PyTuple::new(py, [path])?, kwargs))
    }

    /// Bakes a mesh given as numpy arrays into a scene held in memory (no file).
    ///
    /// Args:
    ///     vertices: ``(n, 3)`` vertex positions (any real dtype; stored as float32).
    ///     triangles: ``(m, 3)`` integer vertex indices.
    ///     max_depth, leaf_size, margin, threads, max_memory: as ``octrace.bake``.
    ///     device: where the ray queries run, as ``Scene``'s.
    ///
    /// Example::
    ///
    ///     v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)
    ///     scene = octrace.Scene.from_arrays(v, np.array([[0, 1, 2]]))
    ///     scene.cast_rays(np.array([[0.2, 0.2, 1, 0, 0, -1]], np.float32))["t_hit"]  # [1.]
    #[staticmethod]
    #[pyo3(signature = (vertices, triangles, *, max_depth=None, leaf_size=octrace_bake::octree::DEFAULT_LEAF_SIZE,
        margin=octrace_bake::octree::DEFAULT_MARGIN, threads=0, max_memory=None, device="cpu"),
        text_signature = "(vertices, triangles, *, max_depth=None, leaf_size=16, margin=9.5367431640625e-07, threads=0, max_memory=None, device='cpu')")]
    #[allow(clippy::too_many_arguments)]
    fn from_arrays(
        py: Python<'_>,
        vertices: &Bound<'_, PyAny>,
        triangles: &Bound<'_, PyAny>,
        max_depth: Option<u32>,
        leaf_size: u32,
        margin: f32,
        threads: Threads,
        max_memory: Option<u64>,
        device: &str,
    ) -> PyResult<Scene> {
        let device = Device::parse(device)?;
        let options = BakeOptions::new(max_depth, leaf_size, margin, max_memory, false, threads)?;
        let mesh = mesh_of_arrays(vertices, triangles)?;
        py.detach(|| {
            let baked = options.bake(&mesh)?;
            // Through the file's bytes, so that the scene has a header for `inspect`.
            let bytes = baked.to_file_bytes(0).map_err(format_error)?;
            drop(baked);
            let inner = octrace_runtime::Scene::from_bytes(&bytes).map_err(runtime_error)?;
            Scene::on(inner, device, 0, None)
        })
    }

    /// Where the ray queries run: ``"cpu"`` or ``"gpu"``.
    #[getter]
    fn device(&self) -> &'static str {
        self.device.name()
    }

    /// What runs the ray queries: ``"cpu"``, or the GPU adapter's name, driver and kind
    /// (lavapipe, Mesa's software Vulkan, says ``Cpu``).
    #[getter]
    fn adapter(&self) -> String {
        #[cfg(feature = "gpu")]
        if let Some(gpu) = &self.gpu {
            return gpu.adapter().to_string();
        }
        "cpu".to_string()
    }

    /// Input triangles (degenerate ones included: they are never hit).
    #[getter]
    fn triangle_count(&self) -> u64 {
        self.inner.view().stats.input_triangles
    }

    /// The mesh's parts, indexed by ``geometry_ids``: dicts of ``name`` (``node 3
    /// 'wheel', mesh 1 'tyre', primitive 0`` for glTF, ``object 'lid'`` for OBJ),
    /// ``first_triangle``, ``triangles``, and the part's numbers in its file: ``node``,
    /// ``mesh``, ``primitive`` (glTF) or ``object`` (OBJ, in file order). A mesh whose
    /// file names no parts (arrays, an OBJ without objects) has one, the whole mesh
    /// (``name`` ``"whole mesh"``), which ``geometry_ids`` 0 names.
    #[getter]
    fn parts<'py>(&self, py: Python<'py>) -> PyResult<Vec<Bound<'py, PyDict>>> {
        let parts = &self.inner.shading().parts;
        if parts.is_empty() {
            let d = PyDict::new(py);
            d.set_item("name", "whole mesh")?;
            d.set_item("first_triangle", 0)?;
            d.set_item("triangles", self.inner.view().stats.input_triangles)?;
            return Ok(vec![d]);
        }
        parts
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

    /// The mesh's materials, indexed by ``cast_rays(..., surface=True)``'s
    /// ``material_ids``: dicts as ``inspect()["scene_data"]["materials"]`` (``name``,
    /// ``base_color``, ``metallic``, ``roughness``, ``emissive``, ``alpha_mode``,
    /// ``transmission``, ``ior``, the texture slots' indices, ...). Empty for a mesh
    /// without materials.
    #[getter]
    fn materials<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let json: Vec<_> = self.inner.shading().materials.iter().map(octrace_bake::summary::material_json).collect();
        py.import("json")?.call_method1("loads", (serde_json::Value::from(json).to_string(),))
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
    ///     surface: also answer what each hit is on, as the renderer sees it (the
    ///         four arrays below).
    ///
    /// Returns:
    ///     a dict of arrays of the rays' leading shape: ``t_hit`` (float32, ``inf`` on a
    ///     miss), ``geometry_ids`` (uint32 part, ``INVALID_ID`` on a miss),
    ///     ``primitive_ids`` (uint32 input triangle, ``INVALID_ID`` on a miss),
    ///     ``primitive_uvs`` (float32 ``(..., 2)``: barycentrics of the second and third
    ///     vertices), ``primitive_normals`` (float32 ``(..., 3)``: the triangle's unit
    ///     normal, ``(v1 - v0) x (v2 - v0)`` normalised). With ``surface=True`` also
    ///     ``points`` (float32 ``(..., 3)``: the hit point from the triangle's vertices
    ///     and the barycentrics; NaN on a miss), ``shading_normals`` (float32
    ///     ``(..., 3)``: the file's vertex normals interpolated and normalised, on the
    ///     geometric normal's side; the geometric normal where the file has none),
    ///     ``texture_uvs`` (float32 ``(..., 2)``: the first channel's texture
    ///     coordinates, with the material's texture transform; NaN where the file has
    ///     none, or on a miss) and ``material_ids`` (uint32, the index in
    ///     ``materials``; ``INVALID_ID`` on a miss or without materials).
    ///
    /// Raises:
    ///     ValueError: not float32, not ``(..., 6)``, or a NaN (the message names the ray).
    ///
    /// Of hits at the same distance, the lowest triangle index is answered.
    #[pyo3(signature = (rays, nthreads=0, *, surface=false))]
    fn cast_rays<'py>(
        &self,
        rays: &Bound<'py, PyAny>,
        nthreads: Threads,
        surface: bool,
    ) -> PyResult<Bound<'py, PyDict>> {
        self.nearest(rays, nthreads, surface)
    }

    /// Whether anything lies on each ray in ``[tnear, tfar]`` (Open3D's
    /// ``test_occlusions``): a bool array of the rays' leading shape.
    #[pyo3(signature = (rays, tnear=0.0, tfar=f32::INFINITY, nthreads=0),
        text_signature = "($self, rays, tnear=0.0, tfar=1e999, nthreads=0)")]
    fn test_occlusions<'py>(
        &self,
        rays: &Bound<'py, PyAny>,
        tnear: f32,
        tfar: f32,
        nthreads: Threads,
    ) -> PyResult<Bound<'py, PyAny>> {
        self.occluded(rays, tnear, tfar, nthreads)
    }

    /// How many times each ray crosses the scene at ``t >= 0`` (Open3D's
    /// ``count_intersections``): int32, each crossing once (a ray through an edge or
    /// vertex that triangles share crosses once).
    #[pyo3(signature = (rays, nthreads=0))]
    fn count_intersections<'py>(&self, rays: &Bound<'py, PyAny>, nthreads: Threads) -> PyResult<Bound<'py, PyAny>> {
        self.counts(rays, nthreads)
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
        nthreads: Threads,
        max_hits: Option<usize>,
        max_memory: Option<u64>,
    ) -> PyResult<Bound<'py, PyDict>> {
        self.lists(rays, nthreads, max_hits, max_memory)
    }

    /// Whether each point lies inside the scene (Open3D's ``compute_occupancy``):
    /// float32 1.0 inside, 0.0 outside, of the points' leading shape.
    ///
    /// On a closed mesh (``is_closed``) the answer is exact and ``nsamples`` is not
    /// needed (there is no vote). An open mesh has no inside: there ``nsamples`` rays
    /// a point vote by the parity of their crossings, as Open3D answers (its rays
    /// are others, so a point that the rays disagree on may get the other answer);
    /// without ``nsamples`` an open mesh raises.
    ///
    /// Args:
    ///     query_points: float32 ``(..., 3)``.
    ///     nthreads: threads (0: all cores).
    ///     nsamples: rays a point for the vote on an open mesh: odd, 1 to 255.
    ///
    /// Raises:
    ///     NotClosedError: the mesh is open and ``nsamples`` is not given.
    ///     ValueError: ``nsamples`` even or past 255; points not ``(..., 3)`` or NaN.
    #[pyo3(signature = (query_points, nthreads=0, nsamples=None))]
    fn compute_occupancy<'py>(
        &self,
        query_points: &Bound<'py, PyAny>,
        nthreads: Threads,
        nsamples: Option<usize>,
    ) -> PyResult<Bound<'py, PyAny>> {
        self.occupancy(query_points, nthreads, nsamples)
    }

    /// The nearest point of the surface to each query point (Open3D's
    /// ``compute_closest_points``), exact: the nearest triangle (of equally near ones,
    /// the lowest index), its distance correctly rounded to float32.
    ///
    /// Args:
    ///     query_points: float32 ``(..., 3)``.
    ///     nthreads: threads (0: all cores).
    ///     max_distance: points farther than this from the surface answer "none"
    ///         (and are answered sooner): a band around the surface, as signed
    ///         distance sampling wants.
    ///
    /// Returns:
    ///     a dict of arrays of the points' leading shape: ``points`` (float32
    ///     ``(..., 3)``, NaN for none), ``geometry_ids`` (uint32 part, ``INVALID_ID``
    ///     for none), ``primitive_ids`` (uint32 input triangle, ``INVALID_ID`` for none),
    ///     ``primitive_uvs`` (float32 ``(..., 2)``: barycentrics of the second and third
    ///     vertices), ``primitive_normals`` (float32 ``(..., 3)``: the triangle's unit
    ///     normal).
    ///
    /// Raises:
    ///     ValueError: points not float32 ``(..., 3)`` or NaN; ``max_distance`` NaN or
    ///         negative.
    #[pyo3(signature = (query_points, nthreads=0, *, max_distance=f32::INFINITY),
        text_signature = "($self, query_points, nthreads=0, *, max_distance=1e999)")]
    fn compute_closest_points<'py>(
        &self,
        query_points: &Bound<'py, PyAny>,
        nthreads: Threads,
        max_distance: f32,
    ) -> PyResult<Bound<'py, PyDict>> {
        self.closest_points(query_points, nthreads, max_distance)
    }

    /// The distance from each query point to the surface (Open3D's
    /// ``compute_distance``): float32 of the points' leading shape, exact (correctly
    /// rounded); ``inf`` past ``max_distance``.
    ///
    /// Raises:
    ///     ValueError: points not float32 ``(..., 3)`` or NaN; ``max_distance`` NaN or
    ///         negative.
    #[pyo3(signature = (query_points, nthreads=0, *, max_distance=f32::INFINITY),
        text_signature = "($self, query_points, nthreads=0, *, max_distance=1e999)")]
    fn compute_distance<'py>(
        &self,
        query_points: &Bound<'py, PyAny>,
        nthreads: Threads,
        max_distance: f32,
    ) -> PyResult<Bound<'py, PyAny>> {
        self.distances(query_points, nthreads, max_distance)
    }

    /// The signed distance from each query point to the surface, negative inside
    /// (Open3D's ``compute_signed_distance``): float32 of the points' leading shape,
    /// the distance exact (``compute_distance``'s); ``+-inf`` past ``max_distance``;
    /// ``0.0`` on the surface.
    ///
    /// On a closed mesh (``is_closed``) the sign is the exact inside/outside
    /// (``contains``), never a vote, and ``nsamples`` is not needed. An open mesh has
    /// no inside: there the sign is the generalized winding number's (inside where it
    /// is above 1/2, libigl's rule), decided with certainty (``winding_number``); or,
    /// given ``nsamples``, ``nsamples`` rays a point vote by the parity of their
    /// crossings, as Open3D signs.
    ///
    /// Args:
    ///     query_points: float32 ``(..., 3)``.
    ///     nthreads: threads (0: all cores).
    ///     nsamples: rays a point for the vote on an open mesh: odd, 1 to 255
    ///         (``None``: the winding number's sign).
    ///     max_distance: a band around the surface; points past it answer ``+-inf``.
    ///
    /// Raises:
    ///     ValueError: ``nsamples`` even or past 255; points not ``(..., 3)`` or NaN;
    ///         ``max_distance`` NaN or negative.
    #[pyo3(signature = (query_points, nthreads=0, nsamples=None, *, max_distance=f32::INFINITY),
        text_signature = "($self, query_points, nthreads=0, nsamples=None, *, max_distance=1e999)")]
    fn compute_signed_distance<'py>(
        &self,
        query_points: &Bound<'py, PyAny>,
        nthreads: Threads,
        nsamples: Option<usize>,
        max_distance: f32,
    ) -> PyResult<Bound<'py, PyAny>> {
        self.signed_distances(query_points, nthreads, nsamples, max_distance)
    }

    /// The generalized winding number of each query point (Jacobson et al. 2013):
    /// float64 of the points' leading shape; 1 inside a closed mesh wound
    /// counter-clockwise seen from outside, 0 outside, fractions where the surface has
    /// holes (inside where above 1/2, libigl's rule).
    ///
    /// On a closed mesh whose every edge is in two triangles running it opposite ways
    /// the answer is exact (an integer: 2 inside two nested shells, -1 inside an
    /// inside-out one), from the signed crossings of one ray under the exact test.
    /// Elsewhere: with ``tolerance``, within it of the exact
    /// winding number of the triangles, guaranteed (a rigorous bound on the
    /// expansions, refined where largest); without, Barill et al.'s fast rule
    /// (``beta = 2``, as libigl's ``fast_winding_number``): errors measured below
    /// 4e-3 on the bunny, not promised.
    ///
    /// Args:
    ///     query_points: float32 ``(..., 3)``.
    ///     nthreads: threads (0: all cores).
    ///     tolerance: the largest error allowed, or ``None`` for the fast rule.
    ///
    /// Raises:
    ///     ValueError: points not float32 ``(..., 3)`` or NaN; ``tolerance`` negative.
    ///
    /// Example:
    ///     >>> w = scene.winding_number(points, tolerance=1e-4)
    #[pyo3(signature = (query_points, nthreads=0, *, tolerance=None))]
    fn winding_number<'py>(
        &self,
        query_points: &Bound<'py, PyAny>,
        nthreads: Threads,
        tolerance: Option<f64>,
    ) -> PyResult<Bound<'py, PyAny>> {
        self.winding_numbers(query_points, nthreads, tolerance)
    }

    /// Whether each point of ``query_points`` (float32 ``(..., 3)``) lies inside the
    /// scene, a closed mesh: a bool array of the points' leading shape, exact.
    ///
    /// Raises:
    ///     NotClosedError: the mesh is not closed (``contains_by_vote`` answers any
    ///         mesh, approximately).
    #[pyo3(signature = (query_points, nthreads=0))]
    fn contains<'py>(&self, query_points: &Bound<'py, PyAny>, nthreads: Threads) -> PyResult<Bound<'py, PyAny>> {
        let (inside, shape) = self.inside(query_points, nthreads)?;
        array(query_points.py(), inside, shape)
    }

    /// Whether each point of ``query_points`` (float32 ``(..., 3)``) lies inside, by
    /// the vote of ``nsamples`` rays in fixed directions, each counting the parity of
    /// its crossings: any mesh, open or closed, approximately (``contains`` is exact
    /// on a closed mesh). A bool array of the points' leading shape.
    ///
    /// Raises:
    ///     ValueError: ``nsamples`` even or past 255.
    #[pyo3(signature = (query_points, nsamples=3, nthreads=0))]
    fn contains_by_vote<'py>(
        &self,
        query_points: &Bound<'py, PyAny>,
        nsamples: usize,
        nthreads: Threads,
    ) -> PyResult<Bound<'py, PyAny>> {
        let (inside, shape) = self.vote(query_points, nsamples, nthreads)?;
        array(query_points.py(), inside, shape)
    }

    /// The length of each ray's part ``t`` in ``[0, tmax]`` inside the scene, a
    /// closed mesh, in units of ``t`` (float32, the rays' leading shape).
    ///
    /// Raises:
    ///     NotClosedError: the mesh is not closed.
    #[pyo3(signature = (rays, tmax=f32::INFINITY, nthreads=0),
        text_signature = "($self, rays, tmax=1e999, nthreads=0)")]
    fn length_inside<'py>(
        &self,
        rays: &Bound<'py, PyAny>,
        tmax: f32,
        nthreads: Threads,
    ) -> PyResult<Bound<'py, PyAny>> {
        self.lengths(rays, tmax, nthreads)
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
    /// Open3D's conventions, kept: ``fov_deg`` is the horizontal field of view (the
    /// command line's ``--fov`` is vertical; its ``--hfov`` is this one), and the
    /// camera's x axis is ``up x forward``, so row 0 is the bottom of the picture and
    /// column 0 its right edge: ``t_hit[::-1, ::-1]`` is the image ``octrace render
    /// --hfov FOV_DEG --target CENTER --eye EYE --up UP`` draws for the same camera.
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
            "octrace.Scene({} triangles, {} leaves, {} parts{}{})",
            v.stats.input_triangles,
            v.leaf_count(),
            self.inner.shading().parts.len(),
            if self.inner.edges().is_closed() { ", closed" } else { "" },
            if self.device == Device::Gpu { ", on the gpu" } else { "" }
        )
    }
}
