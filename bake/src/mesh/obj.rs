//! Wavefront OBJ through tobj: every object and group, polygons fan-triangulated.

use std::path::Path;

use super::{check_finite, Mesh};
use crate::error::{Error, Result};

pub(super) fn parse(bytes: &[u8], path: &Path) -> Result<Mesh> {
    let options = tobj::LoadOptions { triangulate: true, single_index: false, ignore_points: true, ignore_lines: true };
    // Materials are not needed for geometry; a missing .mtl must not fail the bake.
    let no_materials = |_: &Path| Err(tobj::LoadError::OpenFileFailed);
    let (models, _) =
        tobj::load_obj_buf(&mut { bytes }, &options, no_materials).map_err(|e| obj_error(e, bytes, path))?;
    let mut mesh = Mesh::default();
    let total: usize = models.iter().map(|m| m.mesh.indices.len() / 3).sum();
    mesh.triangles.reserve(total);
    for model in &models {
        let p = &model.mesh.positions;
        let count = p.len() / 3;
        for (face, idx) in model.mesh.indices.chunks_exact(3).enumerate() {
            let mut tri = [[0.0f32; 3]; 3];
            for (corner, &i) in tri.iter_mut().zip(idx) {
                let i = i as usize;
                if i >= count {
                    return Err(Error::IndexOutOfRange {
                        path: path.into(),
                        element: format!("object '{}', triangle {face}", model.name),
                        index: i as i64,
                        count,
                    });
                }
                *corner = [p[3 * i], p[3 * i + 1], p[3 * i + 2]];
                check_finite(*corner, path, || {
                    format!("object '{}', triangle {face} (triangle {} of the file)", model.name, mesh.triangles.len())
                })?;
            }
            mesh.triangles.push(tri);
        }
    }
    Ok(mesh)
}

/// Turns a tobj error into one that names the element: tobj does not say where, so
/// the offending line is looked up again for the errors that have one.
fn obj_error(err: tobj::LoadError, bytes: &[u8], path: &Path) -> Error {
    if err == tobj::LoadError::FaceVertexOutOfBounds {
        if let Some((line, index, count)) = find_bad_face(bytes) {
            return Error::IndexOutOfRange { path: path.into(), element: format!("line {line}"), index, count };
        }
    }
    let element = match err {
        tobj::LoadError::PositionParseError => first_line_starting(bytes, "v ").map(|l| format!("near line {l}")),
        _ => None,
    };
    Error::Parse { path: path.into(), element: element.unwrap_or_else(|| "file".into()), message: err.to_string() }
}

/// The first face line whose vertex index is out of range: (line, index, vertices so far).
fn find_bad_face(bytes: &[u8]) -> Option<(usize, i64, usize)> {
    let text = String::from_utf8_lossy(bytes);
    let mut vertices = 0usize;
    for (n, line) in text.lines().enumerate() {
        let mut words = line.split_whitespace();
        match words.next() {
            Some("v") => vertices += 1,
            Some("f") => {
                for w in words {
                    let Ok(i) = w.split('/').next().unwrap_or("").parse::<i64>() else { continue };
                    let resolved = if i < 0 { vertices as i64 + i } else { i - 1 };
                    if resolved < 0 || resolved >= vertices as i64 {
                        return Some((n + 1, i, vertices));
                    }
                }
            }
            _ => {}
        }
    }
    None
}

/// The first line (1-based) starting with `prefix` whose numbers do not parse.
fn first_line_starting(bytes: &[u8], prefix: &str) -> Option<usize> {
    let text = String::from_utf8_lossy(bytes);
    text.lines().enumerate().find_map(|(n, line)| {
        let rest = line.strip_prefix(prefix)?;
        rest.split_whitespace().any(|w| w.parse::<f32>().is_err()).then_some(n + 1)
    })
}
