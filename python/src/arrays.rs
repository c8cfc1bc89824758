//! numpy in and out: float32 arrays read in place (or through `.numpy()`), rays and
//! points converted a piece at a time, results shaped as the inputs, and the thread
//! pools the calls run on.

use std::sync::{Arc, Mutex};

use numpy::{PyArray1, PyArrayDescrMethods, PyArrayMethods, PyReadonlyArrayDyn, PyUntypedArray, PyUntypedArrayMethods};
use octrace_runtime::glam::Vec3;
use octrace_runtime::Ray;
use pyo3::exceptions::{PyOSError, PyValueError};
use pyo3::prelude::*;
use rayon::prelude::*;

use crate::errors::room;

/// `nthreads` as Python gives it: 0 for all cores, else a count (a negative one is an
/// error naming it, not an `OverflowError` naming nothing).
pub(crate) type Threads = i64;

/// The id of "no triangle" and "no part" in the arrays the queries return (Open3D's
/// `RaycastingScene.INVALID_ID`).
pub(crate) const INVALID_ID: u32 = u32::MAX;

/// The most threads a call may ask for (as the command line's `--threads`).
pub(crate) const MAX_THREADS: usize = 1024;

/// Thread pools kept for reuse, the most recently used first: a pool past these is
/// dropped (its threads end once its calls are done), so that a program trying every
/// `nthreads` holds at most this many pools, not one a count.
const POOLS_KEPT: usize = 4;

/// Runs `work` on `nthreads` threads (0: all cores, rayon's global pool). The last
/// [`POOLS_KEPT`] counts' pools are kept for the next calls.
pub(crate) fn on_threads<R: Send>(nthreads: Threads, work: impl FnOnce() -> R + Send) -> PyResult<R> {
    if nthreads == 0 {
        return Ok(work());
    }
    if !(0..=MAX_THREADS as i64).contains(&nthreads) {
        return Err(PyValueError::new_err(format!("nthreads: {nthreads}, expected 0 (all cores) to {MAX_THREADS}")));
    }
    let nthreads = nthreads as usize;
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

/// `obj` itself, or where it is not a numpy array but has a `numpy()` method (an
/// Open3D or PyTorch tensor on the CPU) what that returns: Open3D's code passes its
/// tensors, and numpy cannot read them element by element ("setting an array element
/// with a sequence").
pub(crate) fn numpy_of<'py>(obj: &Bound<'py, PyAny>, what: &str) -> PyResult<Bound<'py, PyAny>> {
    if obj.cast::<PyUntypedArray>().is_ok() || !obj.hasattr("numpy")? {
        return Ok(obj.clone());
    }
    obj.call_method0("numpy").map_err(|e| {
        PyValueError::new_err(format!("{what}: its numpy() failed ({e}); pass a numpy array (on the CPU)"))
    })
}

/// A contiguous float32 array of shape `(..., k)` read in place: `what` names it in
/// errors.
pub(crate) struct Floats<'py> {
    array: PyReadonlyArrayDyn<'py, f32>,
    /// The shape without its last axis.
    pub(crate) lead: Vec<usize>,
}

impl<'py> Floats<'py> {
    /// Takes a numpy float32 array (read without a copy when C-contiguous) or anything
    /// `numpy.asarray` turns into one (a list of lists). Other dtypes are refused:
    /// converting them would hide a copy, and float64 rays rounded to float32 are other
    /// rays.
    pub(crate) fn new(obj: &Bound<'py, PyAny>, what: &str, k: usize) -> PyResult<Floats<'py>> {
        let py = obj.py();
        let np = py.import("numpy")?;
        let obj = &numpy_of(obj, what)?;
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

    pub(crate) fn values(&self) -> &[f32] {
        self.array.as_slice().expect("made C-contiguous")
    }

    pub(crate) fn count(&self) -> usize {
        self.lead.iter().product()
    }

    /// The shape of a result with `tail` values an element.
    pub(crate) fn shape(&self, tail: &[usize]) -> Vec<usize> {
        self.lead.iter().chain(tail).copied().collect()
    }
}

/// A shape as Python writes it: `(3, 5)`, `(6,)`.
pub(crate) fn tuple(shape: &[usize]) -> String {
    match shape {
        [n] => format!("({n},)"),
        _ => format!("({})", shape.iter().map(usize::to_string).collect::<Vec<_>>().join(", ")),
    }
}

/// Rays converted and traced a piece at a time: the buffers stay in the caches and
/// are reused, where whole batches of `Ray` and `Option<Hit>` cost 60 bytes a ray of
/// fresh memory (page faults: a third of the module's overhead over the Rust batch
/// call at 10^6 primary rays). Large enough for the batch walk's memory order.
pub(crate) const PIECE: usize = 1 << 18;

/// Calls `trace(first, rays)` with the rays `[ox, oy, oz, dx, dy, dz]` of `values`
/// over `[tmin, tmax]`, a piece of at most `piece` at a time ([`PIECE`] on the CPU;
/// `first`: the index of the piece's first ray), until one fails; a NaN anywhere is an
/// error naming the ray, before any work.
pub(crate) fn each_piece(
    values: &[f32],
    tmin: f32,
    tmax: f32,
    piece: usize,
    mut trace: impl FnMut(usize, &[Ray]) -> PyResult<()>,
) -> PyResult<()> {
    refuse_nan_rays(values)?;
    let mut rays = room(piece.min(values.len() / 6), "rays")?;
    for (p, chunk) in values.chunks(6 * piece).enumerate() {
        chunk.par_chunks_exact(6).map(|r| ray_of(r, tmin, tmax)).collect_into_vec(&mut rays);
        trace(p * piece, &rays)?;
    }
    Ok(())
}

/// The ray `[ox, oy, oz, dx, dy, dz]` over `[tmin, tmax]`.
fn ray_of(r: &[f32], tmin: f32, tmax: f32) -> Ray {
    Ray::segment(Vec3::new(r[0], r[1], r[2]), Vec3::new(r[3], r[4], r[5]), tmin, tmax)
}

/// An error naming the first ray with a NaN, if one has.
fn refuse_nan_rays(values: &[f32]) -> PyResult<()> {
    match first_nan(values, 6) {
        Some(i) => Err(PyValueError::new_err(format!("rays: ray {i} has a NaN: {:?}", &values[6 * i..6 * i + 6]))),
        None => Ok(()),
    }
}

/// The first of the `k`-float items of `values` holding a NaN: a branch-free pass (it
/// vectorises), the item looked for only once one is there.
fn first_nan(values: &[f32], k: usize) -> Option<usize> {
    if values.par_chunks(1 << 14).any(|c| c.iter().fold(false, |nan, x| nan | x.is_nan())) {
        values.chunks_exact(k).position(|r| r.iter().any(|x| x.is_nan()))
    } else {
        None
    }
}

/// Every ray of `values` at once (for the calls whose answers are not one a ray).
pub(crate) fn to_rays(values: &[f32], tmin: f32, tmax: f32) -> PyResult<Vec<Ray>> {
    refuse_nan_rays(values)?;
    let mut rays = room(values.len() / 6, "rays")?;
    rays.par_extend(values.par_chunks_exact(6).map(|r| ray_of(r, tmin, tmax)));
    Ok(rays)
}

/// Points `[x, y, z]`, read in place; a NaN is an error naming the point.
pub(crate) fn to_points(values: &[f32]) -> PyResult<&[[f32; 3]]> {
    if let Some(i) = first_nan(values, 3) {
        let p = &values[3 * i..3 * i + 3];
        return Err(PyValueError::new_err(format!("query_points: point {i} has a NaN: {p:?}")));
    }
    Ok(values.as_chunks::<3>().0)
}

/// A numpy array of `shape` holding `values`.
pub(crate) fn array<'py, T: numpy::Element>(
    py: Python<'py>,
    values: Vec<T>,
    shape: Vec<usize>,
) -> PyResult<Bound<'py, PyAny>> {
    Ok(PyArray1::from_vec(py, values).reshape(shape)?.into_any())
}
