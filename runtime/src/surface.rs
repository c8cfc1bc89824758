//! What a hit is on: the point, the normals, the texture coordinates and the mesh
//! part, from a [`Hit`] and its scene ([`Scene::surface`]).

use glam::Vec3;

use crate::ray::Hit;
use crate::Scene;

/// The surface at a hit ([`Scene::surface`]): everything an app usually wants from a
/// hit, computed from the stored triangle the way the renderer does.
#[derive(Clone, Debug, PartialEq)]
pub struct HitSurface {
    /// The hit point, from the triangle's vertices and the hit's barycentrics (more
    /// exact than `origin + t * dir` far from the origin).
    pub point: Vec3,
    /// The bound on each coordinate's rounding error in `point`.
    pub point_error: Vec3,
    /// The triangle's unit normal, `(v1 - v0) x (v2 - v0)` normalised (counter-clockwise
    /// winding; zero for a degenerate triangle). Not turned towards the ray.
    pub geometric_normal: Vec3,
    /// The file's vertex normals interpolated at the hit and normalised, on the
    /// geometric normal's side; the geometric normal where the file has none.
    pub shading_normal: Vec3,
    /// Texture coordinates at the hit in the first channel, the ones the material's
    /// first texture slot reads (with its texture transform applied at bake), where
    /// the file has them ([`octrace_format::SceneView::uv_at_in`] gives the others).
    pub uv: Option<[f32; 2]>,
    /// The input triangle ([`Hit::triangle`]): the index every other call takes.
    pub triangle: u32,
    /// The mesh part the triangle belongs to (its index in `Shading::parts`), where the
    /// file records parts.
    pub part: Option<u32>,
    /// Where the part comes from in its file, as numbers (glTF node, mesh and
    /// primitive indices; OBJ object index), where the file records parts.
    pub part_source: Option<octrace_format::PartSource>,
    /// The part's name (`node 3 'wheel', mesh 1 'tyre', primitive 0` for glTF,
    /// `object 'lid'` for OBJ).
    pub part_name: Option<String>,
    /// The triangle's material (its index in `Shading::materials`), where the file has
    /// materials.
    pub material: Option<u32>,
}

impl Scene {
    /// The surface at `hit`, a hit of this scene: the point, the geometric and shading
    /// normals, the texture coordinates, the mesh part and the material.
    ///
    /// # Example
    /// ```
    /// use octrace_bake::{bake, procedural, BuildParams};
    /// use octrace_runtime::{glam::Vec3, Ray, Scene};
    /// let scene = Scene::from_baked(bake(&procedural::sphere([0.0; 3], 1.0, 32, 48), &BuildParams::auto())?)?;
    /// let hit = scene.intersect(&Ray::new(Vec3::new(0.0, 0.0, -3.0), Vec3::Z)).unwrap();
    /// let s = scene.surface(&hit);
    /// assert!((s.point.z + 1.0).abs() < 0.01); // the sphere's near side
    /// assert!(s.geometric_normal.z < -0.99); // wound outward: facing the ray
    /// assert_eq!(s.triangle, hit.triangle);
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn surface(&self, hit: &Hit) -> HitSurface {
        let view = self.view();
        let tri = view.triangle(hit.prim);
        let (point, point_error) = crate::spawn::hit_point(&tri, hit);
        let geometric_normal = crate::spawn::face_normal(&tri);
        let shading_normal = view
            .corner_normals(hit.prim)
            .map(|corners| {
                let [n0, n1, n2] = corners.map(Vec3::from);
                (n0 * (1.0 - hit.u - hit.v) + n1 * hit.u + n2 * hit.v).normalize_or_zero()
            })
            .filter(|n| n.is_finite() && *n != Vec3::ZERO)
            .map_or(geometric_normal, |n| if n.dot(geometric_normal) < 0.0 { -n } else { n });
        let uv = view.corner_uvs(hit.prim).map(|_| view.uv_at(hit.prim, hit.u, hit.v));
        let shading = self.shading();
        let part = shading.part_index_of(hit.triangle);
        HitSurface {
            point,
            point_error,
            geometric_normal,
            shading_normal,
            uv,
            triangle: hit.triangle,
            part,
            part_source: part.map(|p| shading.parts[p as usize].source),
            part_name: part.map(|p| shading.parts[p as usize].name.clone()),
            material: view
                .material_ids
                .get(hit.prim.0 as usize)
                .copied()
                .filter(|&m| (m as usize) < shading.materials.len()),
        }
    }
}
