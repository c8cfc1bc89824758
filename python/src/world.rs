//! `octrace.World`: scenes placed many times by transforms, moved and traced as one
//! (the runtime's `world`), with Open3D's ray calls and answers.

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::Arc;

use octrace_runtime::world::{Transform, WorldClosest};
use pyo3::exceptions::{PyKeyError, PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use rayon::prelude::*;

use crate::arrays::{array, numpy_of, on_threads, to_points, to_rays, Floats, Threads, INVALID_ID};
use crate::device::Device;
use crate::errors::{collected, runtime_error, zeros};
use crate::queries::{band, closest_dict, ClosestRow};
use crate::scene::Scene;

/// Baked scenes placed by transforms and traced as one: each ``Scene`` opened once and
/// shared by all its instances, which are added, moved and removed, then committed.
///
/// Edits (``add``, ``set_transform``, ``remove``) are staged; ``commit()`` makes them
/// visible to the queries at once (the top level over the instances' boxes refit
/// where only placements changed, rebuilt where instances came or went). A ray is
/// carried into each instance's space in double precision and traced there by the
/// instance's own exact walk; answers are those of the same triangles placed and baked
/// into one file, within the rounding of the carried rays (a ray within that of an
/// edge may hit the neighbouring triangle). The ray calls are Open3D's
/// ``RaycastingScene``'s, with ``geometry_ids`` the instances' ids and
/// ``primitive_ids`` the triangles of the instance's scene.
///
/// Example::
///
///     import numpy as np, octrace
///     bunny = octrace.Scene("bunny.oct")
///     world = octrace.World()
///     first = world.add(bunny)                    # the identity
///     moved = np.eye(4); moved[0, 3] = 0.3        # 0.3 along x
///     second = world.add(bunny, moved)
///     third = world.add("dragon.oct", moved)      # a file, opened once
///     fourth = world.add_triangles(v, t)          # numpy arrays, baked in memory
///     world.commit()
///     ans = world.cast_rays(rays)   # t_hit, geometry_ids (instance ids), primitive_ids, ...
///     moved[1, 3] = 0.1; world.set_transform(second, moved); world.commit()
#[pyclass(module = "octrace")]
pub(crate) struct World {
    inner: octrace_runtime::world::World,
    /// The files added by path, each opened once (by absolute path).
    files: HashMap<PathBuf, Arc<octrace_runtime::Scene>>,
    /// Where the ray queries run.
    device: Device,
    /// The world's scenes on the GPU, where `device` is `Gpu`.
    #[cfg(feature = "gpu")]
    gpu: Option<crate::device::gpu::WorldOnGpu>,
}

/// A 4x4 (last row `0 0 0 1`) or 3x4 placement from anything numpy reads.
fn transform(obj: &Bound<'_, PyAny>) -> PyResult<Transform> {
    let np = obj.py().import("numpy")?;
    let m = np.call_method1("asarray", (numpy_of(obj, "transform")?, np.getattr("float64")?))?;
    let shape: Vec<usize> = m.getattr("shape")?.extract()?;
    let rows: Vec<Vec<f64>> = m
        .call_method0("tolist")?
        .extract()
        .map_err(|_| PyValueError::new_err(format!("transform: shape {shape:?}, expected (4, 4) or (3, 4)")))?;
    let row = |i: usize| -> [f64; 4] { [rows[i][0], rows[i][1], rows[i][2], rows[i][3]] };
    match shape.as_slice() {
        [4, 4] => Transform::from_matrix([row(0), row(1), row(2), row(3)]).map_err(placement_error),
        [3, 4] => Ok(Transform::from_rows([row(0), row(1), row(2)])),
        _ => Err(PyValueError::new_err(format!("transform: shape {shape:?}, expected (4, 4) or (3, 4)"))),
    }
}

impl World {
    /// The scene `obj` names: a `Scene`'s own, or the file at a path, opened (as
    /// `octrace.Scene(path)` opens it) the first time this world sees the path.
    fn scene_of(&mut self, obj: &Bound<'_, PyAny>) -> PyResult<Arc<octrace_runtime::Scene>> {
        if let Ok(scene) = obj.extract::<PyRef<'_, Scene>>() {
            return Ok(Arc::clone(&scene.inner));
        }
        let Ok(path) = obj.extract::<PathBuf>() else {
            let kind = obj.get_type().name()?;
            return Err(PyTypeError::new_err(format!(
                "scene: expected an octrace.Scene or the path of a .oct file, got {kind}"
            )));
        };
        let key = std::path::absolute(&path).unwrap_or_else(|_| path.clone());
        if let Some(scene) = self.files.get(&key) {
            return Ok(Arc::clone(scene));
        }
        let opened = obj.py().get_type::<Scene>().call1((path,))?;
        let scene = Arc::clone(&opened.extract::<PyRef<'_, Scene>>()?.inner);
        self.files.insert(key, Arc::clone(&scene));
        Ok(scene)
    }
}

fn placement_error(e: octrace_runtime::Error) -> PyErr {
    match e {
        octrace_runtime::Error::NoInstance { .. } => PyKeyError::new_err(e.to_string()),
        _ => PyValueError::new_err(e.to_string()),
    }
}

#[pymethods]
impl World {
    /// An empty world.
    ///
    /// Args:
    ///     device: where the ray queries (``cast_rays``, ``test_occlusions``,
    ///         ``count_intersections``, ``list_intersections``) run: ``"cpu"``, or
    ///         ``"gpu"`` (a module built with the GPU, ``HAS_GPU``; a Vulkan adapter
    ///         with 64-bit floats): the instances' octrees walked on the GPU, the
    ///         top level and the carrying of rays into the instances on the CPU,
    ///         with the CPU's answers bit for bit. Each scene goes to the GPU once,
    ///         on the first query after it is placed; moving instances uploads
    ///         nothing. The point queries run on the CPU.
    ///
    /// Raises:
    ///     ValueError: an unknown device.
    ///     GpuError: ``device="gpu"`` and no GPU can serve it.
    #[new]
    #[pyo3(signature = (*, device="cpu"))]
    fn new(device: &str) -> PyResult<World> {
        let device = Device::parse(device)?;
        #[cfg(feature = "gpu")]
        let gpu = match device {
            Device::Gpu => Some(crate::device::gpu::WorldOnGpu::new()?),
            Device::Cpu => None,
        };
        #[cfg(not(feature = "gpu"))]
        if device == Device::Gpu {
            return Err(crate::device::without_gpu());
        }
        Ok(World {
            inner: octrace_runtime::world::World::new(),
            files: HashMap::new(),
            device,
            #[cfg(feature = "gpu")]
            gpu,
        })
    }

    /// The world an instanced file places: what ``octrace bake`` writes for a glTF
    /// that places a mesh many times (each such mesh stored once, each placement an
    /// instance, with the materials it draws). Every scene of the file is read and
    /// validated as ``octrace.Scene(path)`` reads one; the instances are committed,
    /// and may be moved, removed and added to as any world's.
    ///
    /// Example::
    ///
    ///     world = octrace.World.open("spheres.oct")   # octrace bake spheres.glb -o spheres.oct
    ///     ans = world.cast_rays(rays)
    ///
    /// Args:
    ///     path: the instanced file (``str`` or ``os.PathLike``).
    ///     device: as the constructor's.
    ///
    /// Raises:
    ///     OSError, FormatError: the file cannot be read, or is not a valid instanced
    ///         file (an ordinary ``.oct`` is opened by ``octrace.Scene``).
    ///     ValueError: an instance's transform or material map is invalid.
    #[staticmethod]
    #[pyo3(signature = (path, *, device="cpu"))]
    fn open(py: Python<'_>, path: PathBuf, device: &str) -> PyResult<World> {
        let mut world = World::new(device)?;
        world.inner = py.detach(|| octrace_runtime::world::World::open(&path)).map_err(|e| match e {
            octrace_runtime::Error::Format(_) => crate::errors::open_error(e, &path),
            e => placement_error(e),
        })?;
        Ok(world)
    }

    /// Where the ray queries run: ``"cpu"`` or ``"gpu"``.
    #[getter]
    fn device(&self) -> &'static str {
        self.device.name()
    }

    /// Places ``scene`` by ``transform`` (a 4x4 matrix whose last row is ``0 0 0 1``,
    /// or 3x4; local to world; the identity by default), visible after the next
    /// ``commit()``. Returns the instance's id (ids are never reused).
    ///
    /// ``scene`` is an ``octrace.Scene`` or the path of a ``.oct`` file (``str`` or
    /// ``os.PathLike``), read and validated as ``octrace.Scene(path)`` does the first
    /// time this world is given it and shared by every instance of it after that.
    ///
    /// Raises:
    ///     ValueError: the transform has the wrong shape, is not affine, cannot be
    ///         inverted, or places the scene beyond float32's range.
    ///     TypeError: ``scene`` is neither a ``Scene`` nor a path.
    ///     OSError, FormatError: the path's file cannot be read, or is not a valid
    ///         octrace scene.
    #[pyo3(signature = (scene, transform=None))]
    fn add(&mut self, scene: &Bound<'_, PyAny>, transform: Option<&Bound<'_, PyAny>>) -> PyResult<u32> {
        let place = transform.map_or(Ok(Transform::IDENTITY), self::transform)?;
        let scene = self.scene_of(scene)?;
        self.inner.add(&scene, place).map_err(placement_error)
    }

    /// Bakes a mesh given as numpy arrays in memory (as ``Scene.from_arrays``, with
    /// its defaults) and places it as ``add`` does: Open3D's ``add_triangles``, with a
    /// placement. Returns the instance's id. To place one mesh many times, bake it
    /// once (``Scene.from_arrays``) and ``add`` that scene.
    ///
    /// Args:
    ///     vertex_positions: ``(n, 3)`` vertex positions (stored as float32).
    ///     triangle_indices: ``(m, 3)`` integer vertex indices.
    ///     transform: as ``add``'s.
    ///
    /// Raises:
    ///     ValueError: bad arrays or transform, as ``Scene.from_arrays`` and ``add``.
    #[pyo3(signature = (vertex_positions, triangle_indices, transform=None))]
    fn add_triangles(
        &mut self,
        vertex_positions: &Bound<'_, PyAny>,
        triangle_indices: &Bound<'_, PyAny>,
        transform: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<u32> {
        let place = transform.map_or(Ok(Transform::IDENTITY), self::transform)?;
        let py = vertex_positions.py();
        let scene = py.get_type::<Scene>().call_method1("from_arrays", (vertex_positions, triangle_indices))?;
        let scene = Arc::clone(&scene.extract::<PyRef<'_, Scene>>()?.inner);
        self.inner.add(&scene, place).map_err(placement_error)
    }

    /// Moves instance ``id`` to ``transform``, at the next ``commit()``.
    ///
    /// Raises:
    ///     KeyError: no such instance; ValueError: as ``add``.
    fn set_transform(&mut self, id: u32, transform: &Bound<'_, PyAny>) -> PyResult<()> {
        let place = self::transform(transform)?;
        self.inner.set_transform(id, place).map_err(placement_error)
    }

    /// Removes instance ``id``, at the next ``commit()``.
    ///
    /// Raises:
    ///     KeyError: no such instance.
    fn remove(&mut self, id: u32) -> PyResult<()> {
        self.inner.remove(id).map_err(placement_error)
    }

    /// Makes the staged edits visible to the queries.
    fn commit(&mut self, py: Python<'_>) {
        let inner = &mut self.inner;
        py.detach(|| inner.commit());
    }

    /// The committed instances.
    fn __len__(&self) -> usize {
        self.inner.len()
    }

    /// Instance ``id``'s committed placement, a 4x4 float64 array.
    fn transform<'py>(&self, py: Python<'py>, id: u32) -> PyResult<Bound<'py, PyAny>> {
        let (_, t) = self.inner.instance(id).ok_or_else(|| PyKeyError::new_err(format!("no instance {id}")))?;
        let mut m: Vec<f64> = t.rows.iter().flatten().copied().collect();
        m.extend([0.0, 0.0, 0.0, 1.0]);
        array(py, m, vec![4, 4])
    }

    /// Nearest hits, as ``Scene.cast_rays``: ``t_hit``, ``geometry_ids`` (the
    /// instance), ``primitive_ids`` (the triangle of the instance's scene),
    /// ``primitive_uvs`` and ``primitive_normals`` (the placed triangle's unit normal,
    /// world space); a miss is ``inf`` and ``INVALID_ID``.
    #[pyo3(signature = (rays, nthreads=0))]
    fn cast_rays<'py>(&self, rays: &Bound<'py, PyAny>, nthreads: Threads) -> PyResult<Bound<'py, PyDict>> {
        let py = rays.py();
        let input = Floats::new(rays, "rays", 6)?;
        let values = input.values();
        let n = input.count();
        let world = &self.inner;
        let (t, geometry, primitive, uvs, normals) = py.detach(|| {
            on_threads(nthreads, || -> PyResult<_> {
                let rays = to_rays(values, 0.0, f32::INFINITY)?;
                let hits = self.nearest(&rays)?;
                let (mut t, mut g, mut p) = (zeros(n, "t_hit")?, zeros(n, "geometry_ids")?, zeros(n, "primitive_ids")?);
                let (mut uv, mut normal) = (zeros(2 * n, "primitive_uvs")?, zeros(3 * n, "primitive_normals")?);
                t.par_iter_mut()
                    .zip(&mut g)
                    .zip(&mut p)
                    .zip(uv.par_chunks_mut(2))
                    .zip(normal.par_chunks_mut(3))
                    .zip(&hits)
                    .for_each(|(((((t, g), p), uv), normal), hit)| match hit {
                        Some(h) => {
                            *t = h.hit.t;
                            *g = h.instance;
                            *p = h.hit.triangle;
                            uv.copy_from_slice(&[h.hit.u, h.hit.v]);
                            if let Some(s) = world.surface(h) {
                                normal.copy_from_slice(&s.geometric_normal.to_array());
                            }
                        }
                        None => {
                            *t = f32::INFINITY;
                            *g = INVALID_ID;
                            *p = INVALID_ID;
                        }
                    });
                Ok((t, g, p, uv, normal))
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

    /// Whether anything lies on each ray within ``[tnear, tfar]``, as
    /// ``Scene.test_occlusions``.
    #[pyo3(signature = (rays, tnear=0.0, tfar=f32::INFINITY, nthreads=0))]
    fn test_occlusions<'py>(
        &self,
        rays: &Bound<'py, PyAny>,
        tnear: f32,
        tfar: f32,
        nthreads: Threads,
    ) -> PyResult<Bound<'py, PyAny>> {
        let py = rays.py();
        let input = Floats::new(rays, "rays", 6)?;
        let values = input.values();
        let occluded =
            py.detach(|| on_threads(nthreads, || -> PyResult<_> { self.any(&to_rays(values, tnear, tfar)?) })?)?;
        array(py, occluded, input.shape(&[]))
    }

    /// How many times each ray crosses the world's triangles (every instance's), as
    /// ``Scene.count_intersections``.
    #[pyo3(signature = (rays, nthreads=0))]
    fn count_intersections<'py>(&self, rays: &Bound<'py, PyAny>, nthreads: Threads) -> PyResult<Bound<'py, PyAny>> {
        let py = rays.py();
        let input = Floats::new(rays, "rays", 6)?;
        let values = input.values();
        let counts = py.detach(|| {
            on_threads(nthreads, || -> PyResult<_> {
                let counts = self.counts(&to_rays(values, 0.0, f32::INFINITY)?)?;
                Ok(counts.iter().map(|c| c.total.min(i32::MAX as u32) as i32).collect::<Vec<i32>>())
            })?
        })?;
        array(py, counts, input.shape(&[]))
    }

    /// Every crossing of each ray at ``t >= 0`` with every instance's triangles, in
    /// order along it (of equal distances, the lower instance first), as
    /// ``Scene.list_intersections``: ``ray_splits``, ``ray_ids``, ``geometry_ids``
    /// (the instances), ``primitive_ids`` (the triangles of their scenes),
    /// ``primitive_uvs``, ``t_hit`` and ``enters`` (the placed triangle's side).
    ///
    /// Args:
    ///     max_hits: keep at most this many crossings a ray (its first ones).
    ///     max_memory: the most bytes the lists may take while they are found (24 a
    ///         crossing). Default: a quarter of the memory this process may use.
    ///
    /// Raises:
    ///     MemoryError: the lists pass ``max_memory`` (pass ``max_hits``, or fewer
    ///         rays), or memory cannot be had.
    #[pyo3(signature = (rays, nthreads=0, max_hits=None, max_memory=None))]
    fn list_intersections<'py>(
        &self,
        rays: &Bound<'py, PyAny>,
        nthreads: Threads,
        max_hits: Option<usize>,
        max_memory: Option<u64>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let py = rays.py();
        let input = Floats::new(rays, "rays", 6)?;
        let values = input.values();
        let budget = max_memory.unwrap_or_else(|| octrace_format::memory::share(4));
        let keep = max_hits.unwrap_or(usize::MAX);
        let lists = py.detach(|| {
            on_threads(nthreads, || -> PyResult<_> {
                let rays = to_rays(values, 0.0, f32::INFINITY)?;
                let mut lists: Vec<Vec<octrace_runtime::world::WorldCrossing>> = Vec::new();
                let mut bytes = 0u64;
                for piece in rays.chunks(4096) {
                    let mut found = self.lists(piece)?;
                    found.par_iter_mut().for_each(|c| c.truncate(keep));
                    bytes += found.iter().map(|c| c.len() as u64).sum::<u64>() * 24;
                    if bytes > budget {
                        return Err(pyo3::exceptions::PyMemoryError::new_err(format!(
                            "the crossings take at least {bytes} bytes, past max_memory {budget}: pass max_hits, or \
                             fewer rays a call"
                        )));
                    }
                    lists.extend(found);
                }
                Ok(lists)
            })?
        })?;
        let k: usize = lists.iter().map(Vec::len).sum();
        if k > u32::MAX as usize {
            return Err(PyValueError::new_err(format!(
                "{k} crossings do not fit ray_splits' uint32: pass max_hits, or fewer rays a call"
            )));
        }
        let all = || lists.iter().flatten();
        let mut at = 0u32;
        let splits = collected(
            lists.len() + 1,
            "ray_splits",
            std::iter::once(0).chain(lists.iter().map(|l| {
                at += l.len() as u32;
                at
            })),
        )?;
        let ray_ids = collected(
            k,
            "ray_ids",
            lists.iter().enumerate().flat_map(|(i, l)| std::iter::repeat_n(i as u32, l.len())),
        )?;
        let d = PyDict::new(py);
        d.set_item("ray_splits", array(py, splits, vec![lists.len() + 1])?)?;
        d.set_item("ray_ids", array(py, ray_ids, vec![k])?)?;
        d.set_item("geometry_ids", array(py, collected(k, "geometry_ids", all().map(|c| c.instance))?, vec![k])?)?;
        d.set_item(
            "primitive_ids",
            array(py, collected(k, "primitive_ids", all().map(|c| c.crossing.triangle))?, vec![k])?,
        )?;
        let uvs = collected(2 * k, "primitive_uvs", all().flat_map(|c| [c.crossing.u, c.crossing.v]))?;
        d.set_item("primitive_uvs", array(py, uvs, vec![k, 2])?)?;
        d.set_item("t_hit", array(py, collected(k, "t_hit", all().map(|c| c.crossing.t))?, vec![k])?)?;
        d.set_item("enters", array(py, collected(k, "enters", all().map(|c| c.crossing.enters))?, vec![k])?)?;
        Ok(d)
    }

    /// Whether each point lies inside some closed instance (exactly, as
    /// ``Scene.contains``, at the point carried into the instance's space), as
    /// Open3D's ``compute_occupancy``: 1.0 inside, 0.0 outside. Instances of scenes
    /// that are not closed contain nothing.
    #[pyo3(signature = (query_points, nthreads=0))]
    fn compute_occupancy<'py>(
        &self,
        query_points: &Bound<'py, PyAny>,
        nthreads: Threads,
    ) -> PyResult<Bound<'py, PyAny>> {
        let py = query_points.py();
        let input = Floats::new(query_points, "query_points", 3)?;
        let values = input.values();
        let world = &self.inner;
        let inside = py.detach(|| {
            on_threads(nthreads, || -> PyResult<_> {
                let inside = world.contains_batch(to_points(values)?);
                Ok(inside.iter().map(|&b| if b { 1.0f32 } else { 0.0 }).collect::<Vec<f32>>())
            })?
        })?;
        array(py, inside, input.shape(&[]))
    }

    /// The nearest point of the world's surface to each query point (Open3D's
    /// ``compute_closest_points``), through every instance, by its scene's exact
    /// search: where the placement scales distances evenly (rotations, mirrors,
    /// uniform scales, translations) in the instance's own space, the point carried
    /// back in double precision (``Scene.compute_closest_points``' answers, within the
    /// rounding of the carried point); where it stretches them, over the placed
    /// triangles themselves (the answers of those triangles baked into one scene).
    ///
    /// Returns:
    ///     ``Scene.compute_closest_points``' dict, with ``geometry_ids`` the
    ///     instances' ids, ``primitive_ids`` the triangles of the instance's scene and
    ///     ``primitive_normals`` the placed triangles' unit normals.
    ///
    /// Raises:
    ///     ValueError: points not float32 ``(..., 3)`` or NaN; ``max_distance`` NaN
    ///         or negative.
    #[pyo3(signature = (query_points, nthreads=0, *, max_distance=f32::INFINITY),
        text_signature = "($self, query_points, nthreads=0, *, max_distance=1e999)")]
    fn compute_closest_points<'py>(
        &self,
        query_points: &Bound<'py, PyAny>,
        nthreads: Threads,
        max_distance: f32,
    ) -> PyResult<Bound<'py, PyDict>> {
        let (near, shape) = self.closest(query_points, nthreads, max_distance)?;
        closest_dict(query_points.py(), &near, &shape, |c| ClosestRow {
            point: c.closest.point,
            geometry: c.instance,
            primitive: c.closest.triangle,
            uv: [c.closest.u, c.closest.v],
            normal: self.placed_normal(c),
        })
    }

    /// The distance from each query point to the world's surface (Open3D's
    /// ``compute_distance``), as ``compute_closest_points`` finds it: float32 of the
    /// points' leading shape, ``inf`` past ``max_distance``.
    ///
    /// Raises:
    ///     ValueError: as ``compute_closest_points``.
    #[pyo3(signature = (query_points, nthreads=0, *, max_distance=f32::INFINITY),
        text_signature = "($self, query_points, nthreads=0, *, max_distance=1e999)")]
    fn compute_distance<'py>(
        &self,
        query_points: &Bound<'py, PyAny>,
        nthreads: Threads,
        max_distance: f32,
    ) -> PyResult<Bound<'py, PyAny>> {
        let (near, shape) = self.closest(query_points, nthreads, max_distance)?;
        let d =
            collected(near.len(), "distances", near.iter().map(|c| c.map_or(f32::INFINITY, |c| c.closest.distance)))?;
        array(query_points.py(), d, shape)
    }

    /// The signed distance from each query point to the world's surface, negative
    /// inside some closed instance (Open3D's ``compute_signed_distance``): the
    /// distance ``compute_distance``'s, the sign ``compute_occupancy``'s (exact;
    /// instances of scenes that are not closed contain nothing); ``+-inf`` past
    /// ``max_distance``; ``0.0`` on the surface.
    ///
    /// Raises:
    ///     ValueError: as ``compute_closest_points``.
    #[pyo3(signature = (query_points, nthreads=0, *, max_distance=f32::INFINITY),
        text_signature = "($self, query_points, nthreads=0, *, max_distance=1e999)")]
    fn compute_signed_distance<'py>(
        &self,
        query_points: &Bound<'py, PyAny>,
        nthreads: Threads,
        max_distance: f32,
    ) -> PyResult<Bound<'py, PyAny>> {
        let world = &self.inner;
        let (signed, shape) = self.closest_then(query_points, nthreads, max_distance, |points, near| {
            let inside = world.contains_batch(points);
            collected(
                near.len(),
                "signed distances",
                near.iter().zip(inside).map(|(c, inside)| {
                    octrace_runtime::cpu::signed(c.map_or(f32::INFINITY, |c| c.closest.distance), inside)
                }),
            )
        })?;
        array(query_points.py(), signed, shape)
    }

    fn __repr__(&self) -> String {
        let on = if self.device == Device::Gpu { ", on the gpu" } else { "" };
        format!("octrace.World({} instances{on})", self.inner.len())
    }
}

impl World {
    /// The nearest hit of each ray, on the world's device.
    fn nearest(&self, rays: &[octrace_runtime::Ray]) -> PyResult<Vec<Option<octrace_runtime::world::WorldHit>>> {
        #[cfg(feature = "gpu")]
        if let Some(gpu) = &self.gpu {
            return gpu.with(|g| g.intersect(&self.inner, rays));
        }
        Ok(self.inner.intersect_batch(rays))
    }

    /// Each ray's crossings counted, on the world's device.
    fn counts(&self, rays: &[octrace_runtime::Ray]) -> PyResult<Vec<octrace_runtime::cpu::CrossingCount>> {
        #[cfg(feature = "gpu")]
        if let Some(gpu) = &self.gpu {
            return gpu.with(|g| g.count_crossings(&self.inner, rays));
        }
        Ok(self.inner.count_crossings_batch(rays))
    }

    /// Each ray's crossings in order, on the world's device.
    fn lists(&self, rays: &[octrace_runtime::Ray]) -> PyResult<Vec<Vec<octrace_runtime::world::WorldCrossing>>> {
        #[cfg(feature = "gpu")]
        if let Some(gpu) = &self.gpu {
            return gpu.with(|g| g.crossings(&self.inner, rays));
        }
        Ok(rays.par_iter().map(|r| self.inner.crossings(r)).collect())
    }

    /// Whether anything lies on each ray, on the world's device.
    fn any(&self, rays: &[octrace_runtime::Ray]) -> PyResult<Vec<bool>> {
        #[cfg(feature = "gpu")]
        if let Some(gpu) = &self.gpu {
            return gpu.with(|g| g.occluded(&self.inner, rays));
        }
        Ok(self.inner.occluded_batch(rays))
    }

    /// Each query point's closest point of the world (`None` past `max_distance`),
    /// and the points' leading shape.
    fn closest(
        &self,
        query_points: &Bound<'_, PyAny>,
        nthreads: Threads,
        max_distance: f32,
    ) -> PyResult<(Vec<Option<WorldClosest>>, Vec<usize>)> {
        self.closest_then(query_points, nthreads, max_distance, |_, near| Ok(near))
    }

    /// [`World::closest`], then `then` of the points and their closest points, on the
    /// same threads (the points read once).
    fn closest_then<R: Send>(
        &self,
        query_points: &Bound<'_, PyAny>,
        nthreads: Threads,
        max_distance: f32,
        then: impl FnOnce(&[[f32; 3]], Vec<Option<WorldClosest>>) -> PyResult<R> + Send,
    ) -> PyResult<(R, Vec<usize>)> {
        let max_distance = band(max_distance)?;
        let input = Floats::new(query_points, "query_points", 3)?;
        let values = input.values();
        let world = &self.inner;
        let out = query_points.py().detach(|| {
            on_threads(nthreads, || -> PyResult<_> {
                let points = to_points(values)?;
                let near = world.closest_points_batch(points, max_distance).map_err(runtime_error)?;
                then(points, near)
            })?
        })?;
        Ok((out, input.shape(&[])))
    }

    /// The unit normal of the placed triangle a closest point lies on (its corners
    /// carried to the world in `f64`).
    fn placed_normal(&self, c: &WorldClosest) -> [f32; 3] {
        let Some((scene, t)) = self.inner.instance(c.instance) else { return [0.0; 3] };
        let tri = scene.view().triangle(octrace_format::StoredIndex(c.closest.prim));
        let [a, b, d] = tri.map(|v| t.point(v.map(f64::from)));
        let (e, f) = ([0, 1, 2].map(|k| b[k] - a[k]), [0, 1, 2].map(|k| d[k] - a[k]));
        let n = [e[1] * f[2] - e[2] * f[1], e[2] * f[0] - e[0] * f[2], e[0] * f[1] - e[1] * f[0]];
        let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
        if len > 0.0 && len.is_finite() {
            n.map(|x| (x / len) as f32)
        } else {
            [0.0; 3]
        }
    }
}
