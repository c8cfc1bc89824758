//! `Scene.create_rays_pinhole`: Open3D's two camera forms.

use numpy::PyReadonlyArrayDyn;
use octrace_runtime::glam::DVec3;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};

use crate::arrays::{array, numpy_of};
use crate::errors::room;

/// `Scene.create_rays_pinhole`'s two forms.
pub(crate) fn pinhole<'py>(
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
        let a = np.call_method1("asarray", (numpy_of(&arg(i)?, names[i])?, np.getattr("float64")?))?;
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
