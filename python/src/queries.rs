//! The queries' work: rays and points converted, traced on the caller's threads with
//! the GIL released, answers gathered into numpy arrays. Their Python faces, with the
//! docstrings, are in `scene`.

use numpy::PyArray1;
use octrace_format::StoredIndex;
use octrace_runtime::cpu::{signed, CrossingCount};
use octrace_runtime::winding::Accuracy;
use octrace_runtime::{ClosestPoint, Hit};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use rayon::prelude::*;

use crate::arrays::{array, each_piece, on_threads, to_points, to_rays, Floats, Threads, INVALID_ID};
use crate::errors::{collected, runtime_error, zeros, NotClosedError};
use crate::scene::Scene;

/// The most rays a point's vote may take (`nsamples`): Open3D's users take 3 to 11.
pub(crate) const MAX_VOTES: usize = 255;

/// A hit's `geometry_ids` entry: its part's index, 0 in a mesh without parts (the one
/// part `Scene.parts` then lists).
fn geometry_id(shading: &octrace_format::Shading, triangle: u32) -> u32 {
    if shading.parts.is_empty() {
        0
    } else {
        shading.part_index_of(triangle).unwrap_or(INVALID_ID)
    }
}

/// What `cast_rays` answers a ray: Open3D's five arrays, and with `surface` four more.
struct Nearest {
    t: Vec<f32>,
    geometry: Vec<u32>,
    primitive: Vec<u32>,
    uvs: Vec<f32>,
    normals: Vec<f32>,
    surface: Option<Surface>,
}

/// `cast_rays(..., surface=True)`'s arrays ([`octrace_runtime::HitSurface`]).
struct Surface {
    points: Vec<f32>,
    shading_normals: Vec<f32>,
    texture_uvs: Vec<f32>,
    material_ids: Vec<u32>,
}

impl Surface {
    fn new(n: usize) -> PyResult<Surface> {
        Ok(Surface {
            points: zeros(3 * n, "points")?,
            shading_normals: zeros(3 * n, "shading_normals")?,
            texture_uvs: zeros(2 * n, "texture_uvs")?,
            material_ids: zeros(n, "material_ids")?,
        })
    }
}

impl Scene {
    /// `cast_rays`.
    pub(crate) fn nearest<'py>(
        &self,
        rays: &Bound<'py, PyAny>,
        nthreads: Threads,
        surface: bool,
    ) -> PyResult<Bound<'py, PyDict>> {
        let py = rays.py();
        let input = Floats::new(rays, "rays", 6)?;
        let values = input.values();
        let n = input.count();
        let answers = py.detach(|| {
            on_threads(nthreads, || -> PyResult<_> {
                let tracer = self.rays();
                let mut out = Nearest {
                    t: zeros(n, "t_hit")?,
                    geometry: zeros(n, "geometry_ids")?,
                    primitive: zeros(n, "primitive_ids")?,
                    uvs: zeros(2 * n, "primitive_uvs")?,
                    normals: zeros(3 * n, "primitive_normals")?,
                    surface: if surface { Some(Surface::new(n)?) } else { None },
                };
                let mut hits = zeros(tracer.piece().min(n), "hits")?;
                each_piece(values, 0.0, f32::INFINITY, tracer.piece(), |first, rays| {
                    let (hits, end) = (&mut hits[..rays.len()], first + rays.len());
                    tracer.intersect(rays, hits)?;
                    self.gather(&mut out, first, end, hits);
                    Ok(())
                })?;
                Ok(out)
            })?
        })?;
        let d = PyDict::new(py);
        d.set_item("t_hit", array(py, answers.t, input.shape(&[]))?)?;
        d.set_item("geometry_ids", array(py, answers.geometry, input.shape(&[]))?)?;
        d.set_item("primitive_ids", array(py, answers.primitive, input.shape(&[]))?)?;
        d.set_item("primitive_uvs", array(py, answers.uvs, input.shape(&[2]))?)?;
        d.set_item("primitive_normals", array(py, answers.normals, input.shape(&[3]))?)?;
        if let Some(s) = answers.surface {
            d.set_item("points", array(py, s.points, input.shape(&[3]))?)?;
            d.set_item("shading_normals", array(py, s.shading_normals, input.shape(&[3]))?)?;
            d.set_item("texture_uvs", array(py, s.texture_uvs, input.shape(&[2]))?)?;
            d.set_item("material_ids", array(py, s.material_ids, input.shape(&[]))?)?;
        }
        Ok(d)
    }

    /// Writes the answers of rays `first..end` (their `hits`) into `out`.
    fn gather(&self, out: &mut Nearest, first: usize, end: usize, hits: &[Option<Hit>]) {
        let view = self.inner.view();
        let shading = self.inner.shading();
        let open3d = out.t[first..end]
            .par_iter_mut()
            .zip(&mut out.geometry[first..end])
            .zip(&mut out.primitive[first..end])
            .zip(out.uvs[2 * first..2 * end].par_chunks_mut(2))
            .zip(out.normals[3 * first..3 * end].par_chunks_mut(3))
            .zip(hits);
        open3d.for_each(|(((((t, g), p), uv), normal), hit)| match hit {
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
        let Some(s) = &mut out.surface else { return };
        s.points[3 * first..3 * end]
            .par_chunks_mut(3)
            .zip(s.shading_normals[3 * first..3 * end].par_chunks_mut(3))
            .zip(s.texture_uvs[2 * first..2 * end].par_chunks_mut(2))
            .zip(&mut s.material_ids[first..end])
            .zip(hits)
            .for_each(|((((point, normal), uv), material), hit)| match hit {
                Some(h) => {
                    let surface = self.inner.surface(h);
                    point.copy_from_slice(&surface.point.to_array());
                    normal.copy_from_slice(&surface.shading_normal.to_array());
                    uv.copy_from_slice(&surface.uv.unwrap_or([f32::NAN; 2]));
                    *material = surface.material.unwrap_or(INVALID_ID);
                }
                None => {
                    point.fill(f32::NAN);
                    uv.fill(f32::NAN);
                    *material = INVALID_ID;
                }
            });
    }

    /// `test_occlusions`.
    pub(crate) fn occluded<'py>(
        &self,
        rays: &Bound<'py, PyAny>,
        tnear: f32,
        tfar: f32,
        nthreads: Threads,
    ) -> PyResult<Bound<'py, PyAny>> {
        let py = rays.py();
        let input = Floats::new(rays, "rays", 6)?;
        let (values, n) = (input.values(), input.count());
        let occluded = py.detach(|| {
            on_threads(nthreads, || -> PyResult<_> {
                let tracer = self.rays();
                let mut occluded = zeros(n, "occlusions")?;
                each_piece(values, tnear, tfar, tracer.piece(), |first, rays| {
                    tracer.occluded(rays, &mut occluded[first..first + rays.len()])
                })?;
                Ok(occluded)
            })?
        })?;
        array(py, occluded, input.shape(&[]))
    }

    /// `count_intersections`.
    pub(crate) fn counts<'py>(&self, rays: &Bound<'py, PyAny>, nthreads: Threads) -> PyResult<Bound<'py, PyAny>> {
        let py = rays.py();
        let input = Floats::new(rays, "rays", 6)?;
        let (values, n) = (input.values(), input.count());
        let counts = py.detach(|| {
            on_threads(nthreads, || -> PyResult<_> {
                let tracer = self.rays();
                let mut counts = zeros(n, "intersection counts")?;
                let mut piece = zeros::<CrossingCount>(tracer.piece().min(n), "crossing counts")?;
                each_piece(values, 0.0, f32::INFINITY, tracer.piece(), |first, rays| {
                    let piece = &mut piece[..rays.len()];
                    tracer.count_crossings(rays, piece)?;
                    counts[first..first + rays.len()]
                        .par_iter_mut()
                        .zip(&*piece)
                        .for_each(|(out, c)| *out = c.total.min(i32::MAX as u32) as i32);
                    Ok(())
                })?;
                Ok(counts)
            })?
        })?;
        array(py, counts, input.shape(&[]))
    }

    /// `list_intersections`.
    pub(crate) fn lists<'py>(
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
        let lists = py.detach(|| {
            on_threads(nthreads, || -> PyResult<_> {
                let rays = to_rays(values, 0.0, f32::INFINITY)?;
                self.rays().crossings(&rays, max_hits.unwrap_or(usize::MAX), budget)
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

    /// `compute_occupancy`: exact on a closed mesh; on an open one a vote of
    /// `nsamples` rays where given, else [`NotClosedError`] saying to give it.
    pub(crate) fn occupancy<'py>(
        &self,
        query_points: &Bound<'py, PyAny>,
        nthreads: Threads,
        nsamples: Option<usize>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let (inside, shape) = match nsamples {
            Some(k) if !self.inner.edges().is_closed() => self.vote(query_points, k, nthreads)?,
            _ => self.inside(query_points, nthreads).map_err(|e| match nsamples {
                None if e.is_instance_of::<NotClosedError>(query_points.py()) => NotClosedError::new_err(format!(
                    "{}; compute_occupancy answers an open mesh by a vote, as Open3D does, when given \
                     nsamples (an odd number of rays a point, e.g. nsamples=3)",
                    e.value(query_points.py())
                )),
                _ => e,
            })?,
        };
        array(query_points.py(), inside.into_iter().map(|b| if b { 1.0f32 } else { 0.0 }).collect(), shape)
    }

    /// The inside of each query point, exact, and the result's shape.
    pub(crate) fn inside(
        &self,
        query_points: &Bound<'_, PyAny>,
        nthreads: Threads,
    ) -> PyResult<(Vec<bool>, Vec<usize>)> {
        let input = Floats::new(query_points, "query_points", 3)?;
        let values = input.values();
        let inside = query_points
            .py()
            .detach(|| on_threads(nthreads, || -> PyResult<_> { self.rays().contains(to_points(values)?) })?)?;
        Ok((inside, input.shape(&[])))
    }

    /// `winding_number`: float64 of the points' leading shape.
    pub(crate) fn winding_numbers<'py>(
        &self,
        query_points: &Bound<'py, PyAny>,
        nthreads: Threads,
        tolerance: Option<f64>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let accuracy = match tolerance {
            None => Accuracy::FAST,
            Some(t) if t >= 0.0 => Accuracy::Within(t),
            Some(t) => return Err(PyValueError::new_err(format!("tolerance: {t}, expected a number at least 0"))),
        };
        let input = Floats::new(query_points, "query_points", 3)?;
        let values = input.values();
        let w = query_points.py().detach(|| {
            on_threads(nthreads, || -> PyResult<_> {
                self.inner.winding_numbers(to_points(values)?, accuracy).map_err(runtime_error)
            })?
        })?;
        array(query_points.py(), collected(w.len(), "winding numbers", w.iter().map(|w| w.value))?, input.shape(&[]))
    }

    /// Each point inside by the parity vote of `nsamples` rays (any mesh), and the
    /// result's shape.
    pub(crate) fn vote(
        &self,
        query_points: &Bound<'_, PyAny>,
        nsamples: usize,
        nthreads: Threads,
    ) -> PyResult<(Vec<bool>, Vec<usize>)> {
        votes(nsamples)?;
        let input = Floats::new(query_points, "query_points", 3)?;
        let values = input.values();
        let inside = query_points.py().detach(|| {
            on_threads(nthreads, || -> PyResult<_> {
                let points = to_points(values)?;
                let mut inside = zeros(points.len(), "occupancy")?;
                self.inner.tracer().par_contains_by_vote(points, nsamples, &mut inside);
                Ok(inside)
            })?
        })?;
        Ok((inside, input.shape(&[])))
    }

    /// `length_inside`.
    pub(crate) fn lengths<'py>(
        &self,
        rays: &Bound<'py, PyAny>,
        tmax: f32,
        nthreads: Threads,
    ) -> PyResult<Bound<'py, PyAny>> {
        let py = rays.py();
        let input = Floats::new(rays, "rays", 6)?;
        let values = input.values();
        let lengths = py.detach(|| {
            on_threads(nthreads, || -> PyResult<_> { self.rays().length_inside(&to_rays(values, 0.0, tmax)?) })?
        })?;
        array(py, lengths, input.shape(&[]))
    }
}

/// One found point's answer in `compute_closest_points`' arrays.
pub(crate) struct ClosestRow {
    pub point: [f32; 3],
    pub geometry: u32,
    pub primitive: u32,
    pub uv: [f32; 2],
    pub normal: [f32; 3],
}

/// `compute_closest_points`' dict (Open3D's keys) of each point's answer in `near`
/// (`row` of a found one; NaN and `INVALID_ID` for none), arrays of the points' leading
/// `shape`: a scene's and a world's.
pub(crate) fn closest_dict<'py, T: Sync>(
    py: Python<'py>,
    near: &[Option<T>],
    shape: &[usize],
    row: impl Fn(&T) -> ClosestRow + Sync,
) -> PyResult<Bound<'py, PyDict>> {
    let n = near.len();
    let mut points = zeros(3 * n, "points")?;
    let mut geometry = zeros(n, "geometry_ids")?;
    let mut primitive = zeros(n, "primitive_ids")?;
    let mut uvs = zeros(2 * n, "primitive_uvs")?;
    let mut normals = zeros(3 * n, "primitive_normals")?;
    let arrays = points
        .par_chunks_mut(3)
        .zip(&mut geometry)
        .zip(&mut primitive)
        .zip(uvs.par_chunks_mut(2))
        .zip(normals.par_chunks_mut(3))
        .zip(near);
    arrays.for_each(|(((((point, g), p), uv), normal), near)| match near.as_ref().map(&row) {
        Some(r) => {
            point.copy_from_slice(&r.point);
            *g = r.geometry;
            *p = r.primitive;
            uv.copy_from_slice(&r.uv);
            normal.copy_from_slice(&r.normal);
        }
        None => {
            point.fill(f32::NAN);
            *g = INVALID_ID;
            *p = INVALID_ID;
        }
    });
    let d = PyDict::new(py);
    let at = |k: &[usize]| [shape, k].concat();
    d.set_item("points", array(py, points, at(&[3]))?)?;
    d.set_item("geometry_ids", array(py, geometry, at(&[]))?)?;
    d.set_item("primitive_ids", array(py, primitive, at(&[]))?)?;
    d.set_item("primitive_uvs", array(py, uvs, at(&[2]))?)?;
    d.set_item("primitive_normals", array(py, normals, at(&[3]))?)?;
    Ok(d)
}

/// `nsamples` for a vote, checked: odd, at most [`MAX_VOTES`].
fn votes(nsamples: usize) -> PyResult<()> {
    if nsamples.is_multiple_of(2) || nsamples > MAX_VOTES {
        return Err(PyValueError::new_err(format!(
            "nsamples: {nsamples}, expected an odd number of rays from 1 to {MAX_VOTES}"
        )));
    }
    Ok(())
}

/// `max_distance`, checked: not NaN, not negative.
pub(crate) fn band(max_distance: f32) -> PyResult<f32> {
    if max_distance.is_nan() || max_distance < 0.0 {
        return Err(PyValueError::new_err(format!(
            "max_distance: {max_distance}, expected a distance >= 0 (inf for no limit)"
        )));
    }
    Ok(max_distance)
}

impl Scene {
    /// Each query point's nearest point of the surface (`None` past `max_distance`),
    /// and the result's shape.
    fn closest(
        &self,
        query_points: &Bound<'_, PyAny>,
        nthreads: Threads,
        max_distance: f32,
    ) -> PyResult<(Vec<Option<ClosestPoint>>, Vec<usize>)> {
        let max_distance = band(max_distance)?;
        let input = Floats::new(query_points, "query_points", 3)?;
        let values = input.values();
        let near = query_points.py().detach(|| {
            on_threads(nthreads, || -> PyResult<_> {
                let points = to_points(values)?;
                let mut near = zeros(points.len(), "closest points")?;
                let bounds = self.inner.surface_bounds().map_err(runtime_error)?;
                self.inner.tracer().par_closest_point_batch(bounds, points, max_distance, &mut near);
                Ok(near)
            })?
        })?;
        Ok((near, input.shape(&[])))
    }

    /// `compute_closest_points`.
    pub(crate) fn closest_points<'py>(
        &self,
        query_points: &Bound<'py, PyAny>,
        nthreads: Threads,
        max_distance: f32,
    ) -> PyResult<Bound<'py, PyDict>> {
        let (near, shape) = self.closest(query_points, nthreads, max_distance)?;
        let view = self.inner.view();
        let shading = self.inner.shading();
        closest_dict(query_points.py(), &near, &shape, |c| ClosestRow {
            point: c.point,
            geometry: geometry_id(shading, c.triangle),
            primitive: c.triangle,
            uv: [c.u, c.v],
            normal: octrace_runtime::spawn::face_normal(&view.triangle(StoredIndex(c.prim))).to_array(),
        })
    }

    /// `compute_distance`.
    pub(crate) fn distances<'py>(
        &self,
        query_points: &Bound<'py, PyAny>,
        nthreads: Threads,
        max_distance: f32,
    ) -> PyResult<Bound<'py, PyAny>> {
        let (near, shape) = self.closest(query_points, nthreads, max_distance)?;
        let d = collected(near.len(), "distances", near.iter().map(|c| c.map_or(f32::INFINITY, |c| c.distance)))?;
        array(query_points.py(), d, shape)
    }

    /// `compute_signed_distance`: the sign exact on a closed mesh; on an open one by
    /// the vote of `nsamples` rays where given, else by the winding number (`w > 1/2`,
    /// decided with certainty). The points are read once for both answers.
    pub(crate) fn signed_distances<'py>(
        &self,
        query_points: &Bound<'py, PyAny>,
        nthreads: Threads,
        nsamples: Option<usize>,
        max_distance: f32,
    ) -> PyResult<Bound<'py, PyAny>> {
        let py = query_points.py();
        let max_distance = band(max_distance)?;
        let closed = self.inner.edges().is_closed();
        if let Some(k) = nsamples.filter(|_| !closed) {
            votes(k)?;
        }
        let input = Floats::new(query_points, "query_points", 3)?;
        let values = input.values();
        let signed = py.detach(|| {
            on_threads(nthreads, || -> PyResult<_> {
                let points = to_points(values)?;
                let inside = match nsamples {
                    Some(k) if !closed => {
                        let mut inside = zeros(points.len(), "occupancy")?;
                        self.inner.tracer().par_contains_by_vote(points, k, &mut inside);
                        inside
                    }
                    None if !closed => self.inner.inside_by_winding(points).map_err(runtime_error)?,
                    _ => self.inner.contains_batch(points).map_err(runtime_error)?,
                };
                let mut near = zeros(points.len(), "closest points")?;
                self.inner.tracer().par_closest_point_batch(
                    self.inner.surface_bounds().map_err(runtime_error)?,
                    points,
                    max_distance,
                    &mut near,
                );
                collected(
                    near.len(),
                    "signed distances",
                    near.iter().zip(inside).map(|(c, inside)| signed(c.map_or(f32::INFINITY, |c| c.distance), inside)),
                )
            })?
        })?;
        array(py, signed, input.shape(&[]))
    }
}
