//! octrace for Python: bake meshes, open baked scenes and ask them exact ray queries
//! with numpy arrays in and out, in the shape of Open3D's `RaycastingScene` (so that a
//! script switches by changing a line).
//!
//! The module is built by maturin (`pip install ./python`); its Python-facing docs are
//! the docstrings in `scene` and `baking` and the type stubs in `octrace.pyi`. Every query
//! releases the GIL and runs on all cores unless `nthreads` says otherwise.
//!
//! - `scene`: `octrace.Scene`, opening and what a scene holds, and its calls' faces;
//! - `queries`: the calls' work (rays traced, points located, answers gathered);
//! - `device`: where ray queries run, the CPU or (the `gpu` feature) the GPU;
//! - `world`: `octrace.World`, scenes placed by transforms and traced as one;
//! - `pinhole`: `Scene.create_rays_pinhole`, Open3D's cameras;
//! - `baking`: `octrace.bake` and `octrace.bake_arrays`;
//! - `arrays`: numpy in and out, the thread pools;
//! - `errors`: exceptions, and allocations that fail as `MemoryError`;
//! - `raycasting_scene.py`: `octrace.RaycastingScene`, Open3D's class over `Scene`.

mod arrays;
mod baking;
mod device;
mod errors;
mod pinhole;
mod queries;
mod scene;
mod world;

use pyo3::prelude::*;

use crate::arrays::INVALID_ID;
use crate::baking::{bake, bake_arrays};
use crate::errors::{BakeError, FormatError, GpuError, NotClosedError};
use crate::scene::Scene;
use crate::world::World;

/// Bake meshes into octrace scenes and ask them exact ray queries from numpy.
#[pymodule(name = "octrace")]
fn octrace(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add("INVALID_ID", INVALID_ID)?;
    m.add_class::<Scene>()?;
    m.add_class::<World>()?;
    // Open3D's `RaycastingScene`, in Python over `Scene` (`raycasting_scene.py`).
    let code = std::ffi::CString::new(include_str!("raycasting_scene.py")).expect("no NUL in the source");
    let open3d = PyModule::from_code(py, &code, c"raycasting_scene.py", c"octrace._raycasting_scene")?;
    m.add("RaycastingScene", open3d.getattr("make")?.call1((py.get_type::<Scene>(), INVALID_ID))?)?;
    m.add("Tensor", open3d.getattr("Tensor")?)?;
    m.add_function(wrap_pyfunction!(bake, m)?)?;
    m.add_function(wrap_pyfunction!(bake_arrays, m)?)?;
    m.add("FormatError", py.get_type::<FormatError>())?;
    m.add("BakeError", py.get_type::<BakeError>())?;
    m.add("NotClosedError", py.get_type::<NotClosedError>())?;
    m.add("GpuError", py.get_type::<GpuError>())?;
    // Whether `Scene(..., device="gpu")` can be asked: the module was built with the
    // `gpu` feature (README: "On a GPU", "From Python").
    m.add("HAS_GPU", cfg!(feature = "gpu"))?;
    Ok(())
}
