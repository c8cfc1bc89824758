//! Wavefront OBJ through tobj: every object and group, polygons fan-triangulated
//! (files of positions and triangles alone: `obj_plain`, in parallel).

use std::path::Path;

use octrace_format::{AlphaMode, Material};

use super::refs::{self, LoadOptions, MAX_MTL_BYTES};
use super::{check_finite, Mesh};
use crate::error::{Error, Result};

pub(super) fn parse(bytes: &[u8], path: &Path, base: Option<&Path>, options: &LoadOptions) -> Result<Mesh> {
    // Text that is not UTF-8 (a Latin-1 comment or name) is read with U+FFFD in place
    // of each bad byte, and a warning names the first one's line.
    let (bytes, note) = match std::str::from_utf8(bytes) {
        Ok(_) => (std::borrow::Cow::Borrowed(bytes), None),
        Err(e) => {
            let at = e.valid_up_to();
            let line = bytes[..at].iter().filter(|&&b| b == b'\n').count() + 1;
            let note = format!(
                "{}: line {line}: byte 0x{:02X} is not UTF-8 (Latin-1?): read as U+FFFD, here and wherever else",
                path.display(),
                bytes[at]
            );
            (std::borrow::Cow::Owned(String::from_utf8_lossy(bytes).into_owned().into_bytes()), Some(note))
        }
    };
    // Positions and triangles only: parsed in parallel, the same mesh tobj makes.
    let mut mesh = match super::obj_plain::parse(&bytes) {
        Some(mesh) => mesh,
        None => parse_with_tobj(&bytes, path, base, options)?,
    };
    mesh.warnings.extend(note);
    Ok(mesh)
}

/// Any OBJ file, through tobj.
pub(super) fn parse_with_tobj(bytes: &[u8], path: &Path, base: Option<&Path>, options: &LoadOptions) -> Result<Mesh> {
    check_face_indices(bytes, path)?;
    let load_options =
        tobj::LoadOptions { triangulate: true, single_index: false, ignore_points: true, ignore_lines: true };
    // Material libraries are read beside the OBJ, under the same rules as glTF buffers
    // (`refs`); one that is refused, missing or unreadable costs the materials (a
    // warning naming it), never the bake.
    let refused = std::cell::RefCell::new(Vec::new());
    let sources = std::cell::RefCell::new(Vec::<std::path::PathBuf>::new());
    let load_mtl = |p: &Path| {
        let read = refs::resolve(base, p, options.references).and_then(|file| {
            let text = octrace_format::read_regular_file(&file, MAX_MTL_BYTES).map_err(|e| e.to_string())?;
            sources.borrow_mut().push(file);
            Ok(text)
        });
        match read {
            Ok(text) => tobj::load_mtl_buf(&mut text.as_slice()),
            Err(reason) => {
                refused.borrow_mut().push(format!("'{}' not loaded ({reason})", p.display()));
                Err(tobj::LoadError::OpenFileFailed)
            }
        }
    };
    let (models, materials) =
        tobj::load_obj_buf(&mut { bytes }, &load_options, load_mtl).map_err(|e| obj_error(e, bytes, path))?;
    let mut mesh = Mesh { sources: sources.into_inner(), ..Mesh::default() };
    let wants_materials = bytes.windows(7).any(|w| w == b"mtllib ");
    for why in refused.borrow().iter() {
        mesh.warnings.push(format!("{}: material library {why}: its materials are left out", path.display()));
    }
    match materials {
        Ok(list) => mesh.materials = list.iter().map(material).collect(),
        Err(_) if !refused.borrow().is_empty() => {}
        Err(e) if wants_materials => {
            mesh.warnings.push(format!("{}: material library not loaded ({e}): no materials", path.display()))
        }
        Err(_) => {}
    }
    let total: usize = models.iter().map(|m| m.mesh.indices.len() / 3).sum();
    mesh.triangles.reserve(total);
    // tobj makes up normals and texture coordinates for faces without them (the
    // previous face's): which triangles really have them comes from the face lines.
    let given = attributes_given(bytes);
    let given = |t: usize| if given.len() == total { given[t] } else { (true, true) };
    let mut material_ids = Vec::new();
    for (object, model) in models.iter().enumerate() {
        let m = &model.mesh;
        let element = |face: usize| format!("object '{}', triangle {face}", model.name);
        for (face, idx) in m.indices.chunks_exact(3).enumerate() {
            let tri = corners(&m.positions, idx, 3, path, || element(face))?;
            let tri = tri.map(|c| [c[0], c[1], c[2]]);
            for corner in &tri {
                check_finite(*corner, path, || {
                    format!("object '{}', triangle {face} (triangle {} of the file)", model.name, mesh.triangles.len())
                })?;
            }
            let (has_uv, has_normal) = given(mesh.triangles.len());
            let normals = match m.normal_indices.get(3 * face..3 * face + 3).filter(|_| has_normal) {
                Some(ni) => Some(corners(&m.normals, ni, 3, path, || format!("{}: normal", element(face)))?),
                None => None,
            };
            let uvs = match m.texcoord_indices.get(3 * face..3 * face + 3).filter(|_| has_uv) {
                Some(ti) => Some(corners(&m.texcoords, ti, 2, path, || format!("{}: uv", element(face)))?),
                None => None,
            };
            mesh.push(
                tri,
                normals.map(|n| n.map(|c| [c[0], c[1], c[2]])).filter(|n| n.iter().flatten().all(|v| v.is_finite())),
                uvs.map(|t| t.map(|c| [c[0], c[1]])).filter(|t| t.iter().flatten().all(|v| v.is_finite())),
            );
            material_ids.push(m.material_id.filter(|&i| i < mesh.materials.len()));
        }
        mesh.end_part(octrace_format::PartSource::Obj { object: object as u32 }, || format!("object '{}'", model.name));
    }
    // Faces without a (known) material get a default one, when there are materials.
    if !mesh.materials.is_empty() {
        let default = mesh.materials.len() as u32;
        if material_ids.iter().any(Option::is_none) {
            mesh.materials.push(default_obj_material());
        }
        mesh.material_ids = material_ids.iter().map(|m| m.map_or(default, |i| i as u32)).collect();
    }
    Ok(mesh)
}

/// The largest index a face may hold: the format stores at most 2^32 - 1 triangles,
/// so no real file comes near it.
const MAX_FACE_INDEX: u64 = 1 << 32;

/// Refuses face indices (`v/vt/vn` of `f`, `l` and `p` lines) tobj would turn into
/// garbage before it reads them: 0, a relative (negative) index reaching before the
/// first element, or one beyond [`MAX_FACE_INDEX`]. tobj makes such an index a huge
/// `usize` and multiplies it by 3 unchecked: an overflow panic where overflow checks are
/// on, a read of the wrong element where they are off (found by fuzzing).
fn check_face_indices(bytes: &[u8], path: &Path) -> Result<()> {
    let text = String::from_utf8_lossy(bytes);
    let mut counts = [0u64; 3];
    for (n, line) in text.lines().enumerate() {
        let mut words = line.split_whitespace();
        match words.next() {
            Some("v") => counts[0] += 1,
            Some("vt") => counts[1] += 1,
            Some("vn") => counts[2] += 1,
            Some(what @ ("usemtl" | "mtllib")) if words.next().is_none() => {
                return Err(Error::Parse {
                    path: path.into(),
                    element: format!("line {}", n + 1),
                    message: format!("{what} without a name"),
                });
            }
            Some("f" | "l" | "p") => {
                for corner in words {
                    for (kind, index) in corner.split('/').enumerate().take(3) {
                        let Ok(i) = index.parse::<i128>() else { continue };
                        let fine = match i {
                            0 => false,
                            i if i < 0 => i.unsigned_abs() <= counts[kind] as u128,
                            i => i as u128 <= MAX_FACE_INDEX as u128,
                        };
                        if !fine {
                            let what = ["vertex", "texture coordinate", "normal"][kind];
                            let many = ["vertices", "texture coordinates", "normals"][kind];
                            let so_far = if counts[kind] == 1 {
                                format!("1 {what}")
                            } else {
                                format!("{} {many}", counts[kind])
                            };
                            return Err(Error::Parse {
                                path: path.into(),
                                element: format!("line {}", n + 1),
                                message: format!(
                                    "{what} index {i}: indices count from 1 (or back from -1, within the {so_far} \
                                     so far) and stay below 2^32"
                                ),
                            });
                        }
                    }
                }
            }
            _ => {}
        }
    }
    Ok(())
}

/// For each triangle the file's faces make (fan-triangulated, in file order), whether
/// its face line gives texture coordinates and normals (`v/vt/vn`, `v//vn`).
fn attributes_given(bytes: &[u8]) -> Vec<(bool, bool)> {
    let text = String::from_utf8_lossy(bytes);
    let mut out = Vec::new();
    for line in text.lines() {
        let mut words = line.split_whitespace();
        if words.next() != Some("f") {
            continue;
        }
        let corners: Vec<&str> = words.collect();
        let all = |k: usize| corners.iter().all(|c| c.split('/').nth(k).is_some_and(|x| !x.is_empty()));
        let flags = (all(1), all(2));
        out.extend(std::iter::repeat_n(flags, corners.len().saturating_sub(2)));
    }
    out
}

/// The `stride`-float entries of `values` at three indices, or an index error.
fn corners(
    values: &[f32],
    idx: &[u32],
    stride: usize,
    path: &Path,
    element: impl Fn() -> String,
) -> Result<[[f32; 3]; 3]> {
    let count = values.len() / stride;
    let mut out = [[0.0f32; 3]; 3];
    for (corner, &i) in out.iter_mut().zip(idx) {
        let i = i as usize;
        if i >= count {
            return Err(Error::IndexOutOfRange { path: path.into(), element: element(), index: i as i64, count });
        }
        corner[..stride].copy_from_slice(&values[stride * i..stride * i + stride]);
    }
    Ok(out)
}

/// MTL's defaults for a face with no material: grey diffuse.
fn default_obj_material() -> Material {
    Material {
        name: "default".into(),
        base_color: [0.8, 0.8, 0.8, 1.0],
        metallic: 0.0,
        illum: Some(1),
        ..Material::default()
    }
}

/// An MTL material in octrace's terms (see [`Material`]'s fields). Values out of their
/// range are clamped; a number that is not finite falls back to the default.
fn material(m: &tobj::Material) -> Material {
    let finite = |v: f32, default: f32| if v.is_finite() { v } else { default };
    let colour = |c: Option<[f32; 3]>, default: f32| c.unwrap_or([default; 3]).map(|v| finite(v, default).max(0.0));
    let kd = colour(m.diffuse, 0.8);
    let tr = m.unknown_param.get("Tr").and_then(|t| t.trim().parse::<f32>().ok()).map(|tr| 1.0 - tr);
    let d = finite(m.dissolve.or(tr).unwrap_or(1.0), 1.0).clamp(0.0, 1.0);
    let ior = m.optical_density.map(|n| finite(n, 1.0).max(1.0));
    let ns = finite(m.shininess.unwrap_or(0.0), 0.0).max(0.0);
    let refracts = d < 1.0 && ior.is_some();
    Material {
        name: m.name.clone(),
        base_color: [kd[0], kd[1], kd[2], if refracts { 1.0 } else { d }],
        metallic: 0.0,
        roughness: (2.0 / (ns + 2.0)).sqrt().clamp(0.0, 1.0),
        emissive: colour(m.emissive, 0.0),
        alpha_mode: if d < 1.0 && !refracts { AlphaMode::Blend } else { AlphaMode::Opaque },
        alpha_cutoff: 0.5,
        transmission: if refracts { 1.0 - d } else { 0.0 },
        ior: ior.unwrap_or(1.5),
        specular: colour(m.specular, 0.0),
        illum: Some(m.illumination_model.map_or(2, u32::from)),
        // No textures: MTL maps are not read.
        ..Material::default()
    }
}

/// Turns a tobj error into one that names the element: tobj does not say where, so
/// the offending line is looked up again for the errors that have one.
fn obj_error(err: tobj::LoadError, bytes: &[u8], path: &Path) -> Error {
    if err == tobj::LoadError::FaceVertexOutOfBounds {
        if let Some((line, index, count)) = find_bad_face(bytes) {
            return Error::IndexOutOfRange { path: path.into(), element: format!("line {line}"), index, count };
        }
    }
    let (element, message) = match locate(&err, bytes) {
        Some((line, text)) => {
            let text: String = text.trim().chars().take(80).collect();
            (format!("line {line}"), format!("{err}: '{text}'"))
        }
        None => ("file".into(), err.to_string()),
    };
    Error::Parse { path: path.into(), element, message }
}

/// The line (1-based, with its text) tobj's error `err` comes from, found again by
/// tobj's own rules for each statement: three numbers for `v` (then none, a `w`
/// that is not 0, or three colour values), two for `vt`, three for `vn`; face
/// corners `v`, `v/vt`, `v//vn` or `v/vt/vn` with indices in range; a name for `o`
/// and `g`.
fn locate(err: &tobj::LoadError, bytes: &[u8]) -> Option<(usize, String)> {
    use tobj::LoadError as E;
    let text = String::from_utf8_lossy(bytes);
    let numbers = |words: &[&str], n: usize| words.len() >= n && words[..n].iter().all(|w| w.parse::<f32>().is_ok());
    // Vertices, texture coordinates and normals so far.
    let mut counts = [0i64; 3];
    let corner_bad = |corner: &str, counts: &[i64; 3], slots: &[usize]| {
        let parts: Vec<&str> = corner.split('/').collect();
        if parts.len() > 3 || parts[0].is_empty() {
            return slots.contains(&0) && slots.len() == 3;
        }
        slots.iter().any(|&s| match parts.get(s) {
            None | Some(&"") => false,
            Some(w) => match w.parse::<i64>() {
                Ok(i) => {
                    let resolved = if i < 0 { counts[s] + i } else { i - 1 };
                    i == 0 || resolved < 0 || resolved >= counts[s]
                }
                Err(_) => slots.len() == 3,
            },
        })
    };
    for (n, line) in text.lines().enumerate() {
        let mut words = line.split_whitespace();
        let key = words.next();
        let rest: Vec<&str> = words.collect();
        let bad = match (key, err) {
            (Some("v"), E::PositionParseError | E::ColorParseError | E::ScalingByZeroError) => {
                !numbers(&rest, 3)
                    || match rest.len() {
                        3 => false,
                        4 => rest[3].parse::<f32>().map_or(true, |w| w == 0.0),
                        6 => false,
                        _ => true,
                    }
            }
            (Some("vt"), E::TexcoordParseError) => !numbers(&rest, 2),
            (Some("vn"), E::NormalParseError) => !numbers(&rest, 3),
            (Some("f" | "l"), E::FaceParseError) => rest.iter().any(|c| corner_bad(c, &counts, &[0, 1, 2])),
            (Some("f" | "l"), E::FaceTexCoordOutOfBounds) => rest.iter().any(|c| corner_bad(c, &counts, &[1])),
            (Some("f" | "l"), E::FaceNormalOutOfBounds) => rest.iter().any(|c| corner_bad(c, &counts, &[2])),
            (Some("o" | "g"), E::InvalidObjectName) => rest.is_empty(),
            _ => false,
        };
        if bad {
            return Some((n + 1, line.to_string()));
        }
        match key {
            Some("v") => counts[0] += 1,
            Some("vt") => counts[1] += 1,
            Some("vn") => counts[2] += 1,
            _ => {}
        }
    }
    None
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
