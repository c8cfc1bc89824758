//! Tangents for normal-mapped primitives: the file's `TANGENT`, else MikkTSpace's.

use glam::{DMat4, DVec3};

use super::Loader;

impl Loader<'_> {
    /// The tangents of a normal-mapped primitive's triangles' corners, world space:
    /// the file's `TANGENT` (through `world`'s linear part, the sign reversed where it
    /// mirrors), else MikkTSpace's from the world-space positions, normals and
    /// texture coordinates, as the glTF spec asks (coordinates given with `v` up, so
    /// that `w (n x t)` points up the image, glTF's green).
    pub(super) fn tangents(
        &mut self,
        prim: &gltf::Primitive<'_>,
        world: &DMat4,
        corners: &Corners<'_>,
        element: &str,
    ) -> Vec<[[f32; 4]; 3]> {
        use gltf::accessor::{DataType, Dimensions};
        if let Some(a) = prim.get(&gltf::Semantic::Tangents) {
            let usable = a.data_type() == DataType::F32 && a.dimensions() == Dimensions::Vec4;
            match self.attribute_usable(&a, usable, corners.verts.len()) {
                Ok(()) => {
                    let reader = prim.reader(|b| self.buffers.get(b.index()).map(|d| &d[..]));
                    let linear = glam::DMat3::from_mat4(*world);
                    let mirror = if linear.determinant() < 0.0 { -1.0 } else { 1.0 };
                    let per_vertex: Vec<[f32; 4]> = reader
                        .read_tangents()
                        .into_iter()
                        .flatten()
                        .take(corners.verts.len())
                        .map(|t| {
                            let d = (linear * DVec3::from([t[0], t[1], t[2]].map(f64::from))).normalize_or_zero();
                            match d.is_finite() && t[3].is_finite() && t[3] != 0.0 {
                                true => [d.x as f32, d.y as f32, d.z as f32, t[3].signum() * mirror as f32],
                                false => [0.0; 4],
                            }
                        })
                        .collect();
                    if per_vertex.len() == corners.verts.len() {
                        return (0..corners.count)
                            .map(|k| (corners.corner)(k).map(|i| per_vertex[i as usize]))
                            .collect();
                    }
                }
                Err(why) => self.mesh.warnings.push(format!(
                    "{}: {element}: TANGENT left out ({why}): MikkTSpace tangents instead",
                    self.path.display()
                )),
            }
        }
        let mut out = MikkTSpace { corners, tangents: vec![[[0.0; 4]; 3]; corners.count] };
        // The crate's error type has no values: it cannot fail.
        let _ = bevy_mikktspace::generate_tangents(&mut out);
        out.tangents
    }
}

/// A primitive's triangles as corners of its vertex arrays (world space).
pub(super) struct Corners<'a> {
    pub(super) verts: &'a [[f32; 3]],
    pub(super) normals: &'a [[f32; 3]],
    pub(super) uvs: &'a [[f32; 2]],
    pub(super) count: usize,
    pub(super) corner: &'a dyn Fn(usize) -> [u32; 3],
}

/// MikkTSpace's view of a primitive, and the tangents it gives each corner.
struct MikkTSpace<'a> {
    corners: &'a Corners<'a>,
    tangents: Vec<[[f32; 4]; 3]>,
}

impl MikkTSpace<'_> {
    fn vertex(&self, face: usize, vert: usize) -> usize {
        (self.corners.corner)(face)[vert] as usize
    }
}

impl bevy_mikktspace::Geometry for MikkTSpace<'_> {
    fn num_faces(&self) -> usize {
        self.corners.count
    }

    fn num_vertices_of_face(&self, _: usize) -> usize {
        3
    }

    fn position(&self, face: usize, vert: usize) -> [f32; 3] {
        self.corners.verts[self.vertex(face, vert)]
    }

    fn normal(&self, face: usize, vert: usize) -> [f32; 3] {
        self.corners.normals[self.vertex(face, vert)]
    }

    /// glTF's `v` grows down the image; MikkTSpace's bitangent follows growing `v`,
    /// and glTF's normal maps put green up the image.
    fn tex_coord(&self, face: usize, vert: usize) -> [f32; 2] {
        let [u, v] = self.corners.uvs[self.vertex(face, vert)];
        [u, -v]
    }

    fn set_tangent(&mut self, space: Option<bevy_mikktspace::TangentSpace>, face: usize, vert: usize) {
        if let Some(space) = space {
            self.tangents[face][vert] = space.tangent_encoded();
        }
    }
}
