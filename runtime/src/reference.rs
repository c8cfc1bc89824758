//! The oracle: a brute-force tracer in `f64` over every triangle.
//!
//! Tests and `octrace verify` compare the octree tracer against it ray for ray. It is
//! slow on purpose (every triangle, every ray) and as accurate as the input allows:
//! the `f32` vertices and ray are widened to `f64` exactly, and Möller-Trumbore runs
//! in `f64`, whose rounding is some 2^29 times finer than the tracer's.

use glam::DVec3;

use crate::ray::Ray;

/// A hit of the reference tracer.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReferenceHit {
    /// Distance along the ray.
    pub t: f64,
    /// Input index of the triangle.
    pub triangle: u32,
    /// Barycentric coordinates of the second and third vertices.
    pub u: f64,
    /// See `u`.
    pub v: f64,
}

/// Brute-force `f64` tracer over a triangle list.
///
/// # Example
/// ```
/// use glam::Vec3;
/// use octrace_runtime::{reference::Reference, Ray};
/// let tris = [[[0.0, 0.0, 1.0], [1.0, 0.0, 1.0], [0.0, 1.0, 1.0]]];
/// let oracle = Reference::new(tris.to_vec(), vec![7]);
/// let hit = oracle.intersect(&Ray::new(Vec3::new(0.2, 0.2, 0.0), Vec3::Z)).unwrap();
/// assert_eq!((hit.t, hit.triangle), (1.0, 7));
/// ```
#[derive(Clone, Debug)]
pub struct Reference {
    triangles: Vec<[DVec3; 3]>,
    ids: Vec<u32>,
}

impl Reference {
    /// An oracle over `triangles`, whose input indices are `ids`.
    pub fn new(triangles: Vec<[[f32; 3]; 3]>, ids: Vec<u32>) -> Reference {
        assert_eq!(triangles.len(), ids.len(), "one id a triangle");
        let triangles = triangles.iter().map(|t| t.map(|v| DVec3::from(v.map(f64::from)))).collect();
        Reference { triangles, ids }
    }

    /// An oracle over a mesh's triangles, whose ids are their positions in the list.
    pub fn in_input_order(triangles: Vec<[[f32; 3]; 3]>) -> Reference {
        let ids = (0..triangles.len() as u32).collect();
        Reference::new(triangles, ids)
    }

    /// An oracle over the triangles stored in a scene.
    pub fn from_view(view: &octrace_format::SceneView<'_>) -> Reference {
        let tris = (0..view.triangle_count() as u32).map(|t| view.triangle(t)).collect();
        Reference::new(tris, view.triangle_ids.to_vec())
    }

    /// Number of triangles.
    pub fn len(&self) -> usize {
        self.triangles.len()
    }

    /// Whether there are no triangles.
    pub fn is_empty(&self) -> bool {
        self.triangles.is_empty()
    }

    /// The nearest hit in `[tmin, tmax]`; ties go to the lower input index.
    pub fn intersect(&self, ray: &Ray) -> Option<ReferenceHit> {
        self.hits(ray).min_by(|a, b| a.t.total_cmp(&b.t).then(a.triangle.cmp(&b.triangle)))
    }

    /// Whether any triangle is hit in `[tmin, tmax]`.
    pub fn occluded(&self, ray: &Ray) -> bool {
        self.hits(ray).next().is_some()
    }

    /// Every hit in `[tmin, tmax]`, in storage order.
    pub fn hits<'s>(&'s self, ray: &Ray) -> impl Iterator<Item = ReferenceHit> + 's {
        let ok = ray.is_traceable();
        let o = ray.origin.as_dvec3();
        let d = ray.dir.as_dvec3();
        let (tmin, tmax) = (ray.tmin as f64, ray.tmax as f64);
        self.triangles.iter().zip(&self.ids).filter(move |_| ok).filter_map(move |(t, &id)| {
            let (hit, u, v) = intersect_f64(o, d, t)?;
            (hit >= tmin && hit <= tmax).then_some(ReferenceHit { t: hit, triangle: id, u, v })
        })
    }
}

/// Möller-Trumbore in `f64`, `(t, u, v)`; edges inclusive; `None` for a ray in the plane.
pub fn intersect_f64(o: DVec3, d: DVec3, t: &[DVec3; 3]) -> Option<(f64, f64, f64)> {
    let e1 = t[1] - t[0];
    let e2 = t[2] - t[0];
    let p = d.cross(e2);
    let det = e1.dot(p);
    if det == 0.0 {
        return None;
    }
    let s = o - t[0];
    let u = s.dot(p) / det;
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let q = s.cross(e1);
    let v = d.dot(q) / det;
    if v < 0.0 || u + v > 1.0 {
        return None;
    }
    Some((e2.dot(q) / det, u, v))
}

/// How an answer compares with the oracle's, for one ray.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Agreement {
    /// The same triangle, or a triangle at the same distance (within `1e-5 t`: two
    /// triangles tie there), or both miss.
    Same,
    /// Different, but within rounding: the ray starts on a triangle (a hit at distance
    /// zero is not counted by the tracer, as in pbrt), or the hit lies within `1e-5` of
    /// a triangle's boundary in barycentric terms (the `f64` oracle is not watertight
    /// there, and a ray grazing an edge may be in or out by an ulp).
    Tie,
    /// A wrong answer.
    Different,
}

/// Two hits this close in distance (relative) are a tie between triangles.
pub const TIE_RELATIVE_T: f64 = 1e-5;
/// A hit this close to a triangle's boundary (smallest barycentric coordinate) is on
/// its edge, within the rounding of an `f32` test.
pub const EDGE_BARYCENTRIC: f64 = 1e-5;
/// Distances below this many `f32` spacings of the origin's largest coordinate are
/// zero: the origin lies on the triangle within rounding.
pub const ZERO_T_SPACINGS: f32 = 8.0;

impl Reference {
    /// Compares a tracer's nearest hit `got` (distance, input triangle id, and
    /// barycentrics `u`, `v`) for `ray` with the oracle's; see [`Agreement`].
    pub fn compare(&self, ray: &Ray, got: Option<(f32, u32, f32, f32)>) -> Agreement {
        self.compare_with(ray, self.intersect(ray), got)
    }

    /// [`Reference::compare`] with the oracle's answer for `ray` already known
    /// (`want`, from [`Reference::intersect`]): for comparing several tracers with
    /// one oracle pass.
    pub fn compare_with(&self, ray: &Ray, want: Option<ReferenceHit>, got: Option<(f32, u32, f32, f32)>) -> Agreement {
        let same = |want: Option<ReferenceHit>| match (got, want) {
            (None, None) => true,
            (Some((t, id, _, _)), Some(w)) => {
                id == w.triangle || (t as f64 - w.t).abs() <= TIE_RELATIVE_T * w.t.abs().max(1e-30)
            }
            _ => false,
        };
        if same(want) {
            return Agreement::Same;
        }
        // Distances below a few f32 spacings of the origin's coordinates are zero.
        let delta = ZERO_T_SPACINGS * f32::EPSILON * ray.origin.abs().max_element().max(1e-30) / ray.dir.length();
        let near_zero = want.is_some_and(|w| w.t.abs() <= delta as f64);
        if near_zero {
            let later = Ray { tmin: delta, ..*ray };
            if got.is_some_and(|g| g.0 <= delta) || same(self.intersect(&later)) {
                return Agreement::Tie;
            }
        }
        if got.is_some_and(|g| on_edge(g.2 as f64, g.3 as f64)) || want.is_some_and(|w| on_edge(w.u, w.v)) {
            return Agreement::Tie;
        }
        Agreement::Different
    }

    /// Compares a tracer's occlusion answer `got` for `ray` with the oracle's,
    /// `want` (from [`Reference::occluded`]): a different answer is a tie when the
    /// oracle's nearest blocker lies on a triangle's edge or at the segment's end
    /// (within rounding of either).
    pub fn compare_occluded_with(&self, ray: &Ray, want: bool, got: bool) -> Agreement {
        if got == want {
            return Agreement::Same;
        }
        let tmax = f64::from(ray.tmax);
        match self.intersect(ray) {
            Some(w) if on_edge(w.u, w.v) || (w.t - tmax).abs() <= TIE_RELATIVE_T * tmax.abs() => Agreement::Tie,
            _ => Agreement::Different,
        }
    }
}

/// Whether barycentrics `(u, v)` lie within [`EDGE_BARYCENTRIC`] of the triangle's
/// boundary.
fn on_edge(u: f64, v: f64) -> bool {
    u.min(v).min(1.0 - u - v) <= EDGE_BARYCENTRIC
}
