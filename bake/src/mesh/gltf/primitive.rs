//! A mesh primitive's triangles and their per-vertex attributes (normals, texture
//! coordinates in each of its material's channels, colours, tangents), pushed into the
//! mesh's per-triangle arrays ([`Mesh::push_colored`](super::super::Mesh::push_colored)
//! and its siblings pad them, whatever order primitives with and without an attribute
//! come in).

use glam::{DMat4, DVec3};
use gltf::mesh::Mode;

use octrace_format::Material;

use super::super::check_finite;
use super::material::UvMap;
use super::tangents::Corners;
use super::{to_f32, Loader};
use crate::error::{Error, Result};

impl Loader<'_> {
    /// The primitive's `NORMAL`s in world space (the inverse transpose of `world`),
    /// when it has usable ones: an attribute of the wrong type, a short one, or one
    /// whose ranges do not fit its buffer is left out with a warning.
    fn normals(
        &mut self,
        prim: &gltf::Primitive<'_>,
        world: &DMat4,
        vertices: usize,
        element: &str,
    ) -> Option<Vec<[f32; 3]>> {
        use gltf::accessor::{DataType, Dimensions};
        let a = prim.get(&gltf::Semantic::Normals)?;
        let usable = a.data_type() == DataType::F32 && a.dimensions() == Dimensions::Vec3;
        if let Err(why) = self.attribute_usable(&a, usable, vertices) {
            self.mesh.warnings.push(format!("{}: {element}: NORMAL left out: {why}", self.path.display()));
            return None;
        }
        let reader = prim.reader(|b| self.buffers.get(b.index()).map(|d| &d[..]));
        let normal_matrix = glam::DMat3::from_mat4(*world).inverse().transpose();
        let out = reader.read_normals()?.take(vertices).map(|n| {
            let w = (normal_matrix * DVec3::from(n.map(f64::from))).normalize_or_zero();
            to_f32(if w.is_finite() { w } else { DVec3::ZERO })
        });
        Some(out.collect())
    }

    /// The primitive's texture coordinates in one of its material's channels, when it
    /// has usable ones (as [`Loader::normals`]): the set `map` reads, through its
    /// transform.
    fn uvs(&mut self, prim: &gltf::Primitive<'_>, map: UvMap, vertices: usize, element: &str) -> Option<Vec<[f32; 2]>> {
        use gltf::accessor::{DataType, Dimensions};
        let a = prim.get(&gltf::Semantic::TexCoords(map.set))?;
        let usable = matches!(a.data_type(), DataType::F32 | DataType::U8 | DataType::U16)
            && a.dimensions() == Dimensions::Vec2
            && (a.data_type() == DataType::F32 || a.normalized());
        if let Err(why) = self.attribute_usable(&a, usable, vertices) {
            self.mesh.warnings.push(format!(
                "{}: {element}: TEXCOORD_{} left out: {why}",
                self.path.display(),
                map.set
            ));
            return None;
        }
        let reader = prim.reader(|b| self.buffers.get(b.index()).map(|d| &d[..]));
        let out = reader.read_tex_coords(map.set)?.into_f32().take(vertices);
        Some(out.map(|t| if t.iter().all(|v| v.is_finite()) { map.apply(t) } else { [0.0; 2] }).collect())
    }

    /// The primitive's `COLOR_0` (RGB or RGBA; floats, or normalized unsigned bytes or
    /// shorts), linear, at 16 bits a channel, when it has usable ones (as
    /// [`Loader::normals`]).
    fn colors(&mut self, prim: &gltf::Primitive<'_>, vertices: usize, element: &str) -> Option<Vec<[u16; 4]>> {
        use gltf::accessor::{DataType, Dimensions};
        let a = prim.get(&gltf::Semantic::Colors(0))?;
        let usable = matches!(a.data_type(), DataType::F32 | DataType::U8 | DataType::U16)
            && matches!(a.dimensions(), Dimensions::Vec3 | Dimensions::Vec4)
            && (a.data_type() == DataType::F32 || a.normalized());
        if let Err(why) = self.attribute_usable(&a, usable, vertices) {
            self.mesh.warnings.push(format!("{}: {element}: COLOR_0 left out: {why}", self.path.display()));
            return None;
        }
        let reader = prim.reader(|b| self.buffers.get(b.index()).map(|d| &d[..]));
        let out = reader.read_colors(0)?.into_rgba_f32().take(vertices);
        let channel = |c: f32| if c.is_finite() { (c.clamp(0.0, 1.0) * 65535.0).round() as u16 } else { u16::MAX };
        Some(out.map(|c| c.map(channel)).collect())
    }

    /// Whether a vertex attribute can be read: the spec's type, ranges inside the
    /// buffers, and one value a vertex.
    pub(super) fn attribute_usable(
        &self,
        a: &gltf::Accessor<'_>,
        type_ok: bool,
        vertices: usize,
    ) -> std::result::Result<(), String> {
        if !type_ok {
            return Err("a type the glTF spec does not allow".into());
        }
        self.check_accessor(a)?;
        if a.count() < vertices {
            return Err(format!("{} values for {vertices} vertices", a.count()));
        }
        Ok(())
    }

    /// The material index of a primitive: its glTF material, or glTF's default one.
    pub(super) fn material_of(&mut self, prim: &gltf::Primitive<'_>) -> u32 {
        match prim.material().index().and_then(|i| self.slot(i)) {
            Some(slot) => slot,
            None => *self.default_material.get_or_insert_with(|| {
                // glTF's default material is single-sided, as every material is unless
                // it says otherwise.
                self.mesh.materials.push(Material { double_sided: false, ..Material::default() });
                self.mesh.materials.len() as u32 - 1
            }),
        }
    }

    pub(super) fn primitive(&mut self, prim: &gltf::Primitive<'_>, world: &DMat4, element: String) -> Result<()> {
        let mode = prim.mode();
        if !matches!(mode, Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan) {
            let name = format!("{mode:?}");
            self.mesh.warnings.push(format!("{}: {element}: skipped {name} primitive", self.path.display()));
            self.skipped.get_or_insert((element, name));
            return Ok(());
        }
        // The spec's types, checked before the gltf crate reads (it panics on others).
        use gltf::accessor::{DataType, Dimensions};
        let bad_type = |what: &str| Error::Parse {
            path: self.path.into(),
            element: element.clone(),
            message: format!("{what} accessor has a type the glTF spec does not allow"),
        };
        if prim.indices().is_some_and(|a| !matches!(a.data_type(), DataType::U8 | DataType::U16 | DataType::U32)) {
            return Err(bad_type("index"));
        }
        if prim
            .get(&gltf::Semantic::Positions)
            .is_some_and(|a| a.data_type() != DataType::F32 || a.dimensions() != Dimensions::Vec3)
        {
            return Err(bad_type("POSITION"));
        }
        // The gltf crate's reader trusts counts, offsets and strides (it panics or
        // allocates what a count declares): every range is checked here first.
        for (what, accessor) in [("index", prim.indices()), ("POSITION", prim.get(&gltf::Semantic::Positions))] {
            if let Some(a) = accessor {
                self.check_accessor(&a).map_err(|message| Error::Parse {
                    path: self.path.into(),
                    element: format!("{element}: {what} accessor {}", a.index()),
                    message,
                })?;
            }
        }
        let reader = prim.reader(|b| self.buffers.get(b.index()).map(|d| &d[..]));
        let Some(positions) = reader.read_positions() else {
            self.mesh.warnings.push(format!("{}: {element}: no POSITION, skipped", self.path.display()));
            return Ok(());
        };
        let mut verts = Vec::with_capacity(positions.len());
        for (i, p) in positions.enumerate() {
            check_finite(p, self.path, || format!("{element}, vertex {i}"))?;
            let w = world.transform_point3(DVec3::from(p.map(f64::from)));
            let v = [w.x as f32, w.y as f32, w.z as f32];
            check_finite(v, self.path, || format!("{element}, vertex {i} after the node transform"))?;
            verts.push(v);
        }
        // Without indices, vertex j is index j: nothing is made for them.
        let indices: Option<Vec<u32>> = reader.read_indices().map(|idx| idx.into_u32().collect());
        if let Some(&bad) = indices.iter().flatten().find(|&&i| i as usize >= verts.len()) {
            return Err(Error::IndexOutOfRange {
                path: self.path.into(),
                element,
                index: bad as i64,
                count: verts.len(),
            });
        }
        let index = |j: usize| indices.as_ref().map_or(j as u32, |i| i[j]);
        let n = indices.as_ref().map_or(verts.len(), Vec::len);
        // Corner indices of triangle k, in the file's winding (no list of them is
        // made: a big primitive's would be as large as its indices).
        let (count, in_file): (usize, &dyn Fn(usize) -> [u32; 3]) = match mode {
            Mode::Triangles => (n / 3, &|k| [index(3 * k), index(3 * k + 1), index(3 * k + 2)]),
            // Every other strip triangle swaps its first two corners to keep the winding.
            Mode::TriangleStrip => (n.saturating_sub(2), &|k| {
                let t = [index(k), index(k + 1), index(k + 2)];
                if k % 2 == 0 {
                    t
                } else {
                    [t[1], t[0], t[2]]
                }
            }),
            _ => (n.saturating_sub(2), &|k| [index(0), index(k + 1), index(k + 2)]),
        };
        // A node whose transform mirrors (a negative determinant) turns the file's
        // counter-clockwise front faces clockwise in the world, where glTF keeps them
        // the front: the last two corners swap, so that the stored winding says the
        // front (for single-sided materials, and closed meshes' outward orientation).
        let mirrored = glam::DMat3::from_mat4(*world).determinant() < 0.0;
        let swapped = |k: usize| {
            let [a, b, c] = in_file(k);
            if mirrored {
                [a, c, b]
            } else {
                [a, b, c]
            }
        };
        let corner: &dyn Fn(usize) -> [u32; 3] = &swapped;
        let normals = self.normals(prim, world, verts.len(), &element);
        // A channel for each distinct set and transform the material's textures read.
        let maps =
            prim.material().index().and_then(|i| self.slot(i)).and_then(|s| self.uv_maps.get(s as usize)).cloned();
        let maps = maps.unwrap_or_else(|| vec![UvMap { set: 0, transform: None }]);
        let mut channels: Vec<_> = maps.iter().map(|&map| self.uvs(prim, map, verts.len(), &element)).collect();
        let uvs = channels.first_mut().and_then(Option::take);
        let colors = self.colors(prim, verts.len(), &element);
        let material = self.material_of(prim);
        let normal_mapped = self.mesh.materials.get(material as usize).filter(|m| m.normal_texture.is_some());
        // The coordinates the normal texture reads.
        let normal_uvs = match normal_mapped.map(|m| m.uv_channel(4)) {
            Some(0) => uvs.as_ref(),
            Some(c) => channels.get(c).and_then(Option::as_ref),
            None => None,
        };
        let tangents = match (normal_uvs, &normals) {
            (Some(uvs), Some(normals)) => {
                let corners = Corners { verts: &verts, normals, uvs, count, corner };
                Some(self.tangents(prim, world, &corners, &element))
            }
            _ => None,
        };
        // Room for them all at once: growing by doubling holds up to three times a
        // big primitive's triangles while it copies.
        self.mesh.triangles.reserve(count);
        self.mesh.material_ids.reserve(count);
        for c in (0..count).map(corner) {
            let tri = c.map(|i| verts[i as usize]);
            let n = normals.as_ref().map(|n| c.map(|i| n[i as usize]));
            let t = uvs.as_ref().map(|t| c.map(|i| t[i as usize]));
            let k = colors.as_ref().map(|k| c.map(|i| k[i as usize]));
            self.mesh.push_colored(tri, n, t, k);
            self.mesh.material_ids.push(material);
        }
        if let Some(tangents) = tangents {
            self.mesh.push_tangents(tangents, count);
        }
        for (c, values) in channels.iter().enumerate().skip(1) {
            if let Some(values) = values {
                let corners = (0..count).map(corner).map(|t| t.map(|i| values[i as usize])).collect();
                self.mesh.push_uv_channel(c, corners, count);
            }
        }
        Ok(())
    }
}
