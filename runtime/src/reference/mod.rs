//! The oracle: a brute-force tracer in `f64` over every triangle.
//!
//! Tests and `octrace verify` compare the octree tracer against it ray for ray. It is
//! slow on purpose (every triangle, every ray) and as accurate as the input allows:
//! the `f32` vertices and ray are widened to `f64` exactly, and Möller-Trumbore runs
//! in `f64`, whose rounding is some 2^29 times finer than the tracer's.
//! [`InsideReference`] answers inside and outside of points for closed meshes,
//! exactly.

use glam::DVec3;

mod closest;
mod inside;
pub use closest::{nearest_on_triangle, ReferenceClosest};
pub use inside::{InsideReference, Side};

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
        let tris = view.stored_triangles().collect();
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

    /// Every hit in `[tmin, tmax]` (both ends included) at a distance `f32` can hold
    /// (a tracer answers in `f32`: a hit past `f32::MAX`, which a tiny direction can
    /// put there, is none), in storage order.
    pub fn hits<'s>(&'s self, ray: &Ray) -> impl Iterator<Item = ReferenceHit> + 's {
        let ok = ray.is_traceable();
        let o = ray.origin.as_dvec3();
        let d = ray.dir.as_dvec3();
        let (tmin, tmax) = (ray.tmin as f64, ray.tmax as f64);
        self.triangles.iter().zip(&self.ids).filter(move |_| ok).filter_map(move |(t, &id)| {
            let (hit, u, v) = intersect_f64(o, d, t)?;
            let representable = (hit as f32).is_finite();
            (hit >= tmin && hit <= tmax && representable).then_some(ReferenceHit { t: hit, triangle: id, u, v })
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
    /// Different, but within rounding: the ray starts on a triangle (its hit is at a
    /// distance of zero within rounding, where the `f32` test and the `f64` oracle may
    /// put it on either side of `tmin`; a hit exactly at `tmin` counts, intervals being
    /// closed: [`Ray`]), or the hit lies within [`EDGE_SPACINGS`] of a triangle's
    /// boundary (the `f64` oracle is not watertight there, and a ray grazing an edge
    /// may be in or out by an ulp).
    Tie,
    /// A wrong answer.
    Different,
}

/// Two hits this close in distance (relative) are a tie between triangles.
pub const TIE_RELATIVE_T: f64 = 1e-5;
/// A hit this close to a triangle's boundary is on its edge, within the rounding of an
/// `f32` test: this many `f32` spacings (`2^-24`, relative) of the largest distance
/// from the ray's origin to the triangle's vertices. (An `f32` test works on vertices
/// relative to the origin, rounded there; in barycentric terms the tolerance is this
/// over the triangle's altitude, which is large for small triangles seen from afar.)
pub const EDGE_SPACINGS: f64 = 16.0;
/// Distances below this many `f32` spacings of the origin's largest coordinate are
/// zero: the origin lies on the triangle within rounding.
pub const ZERO_T_SPACINGS: f32 = 8.0;

/// The bound the octree tracer's distances keep (`cpu::watertight::plane_distance`):
/// the exact distance to the hit triangle's plane rounded to `f32`, so within one ulp,
/// which is at most `2^-23 |t|`; this allows two (the oracle's own `f64` rounding is
/// far below one) ...
pub const DISTANCE_RELATIVE: f64 = 1.0 / (1u64 << 22) as f64;
/// ... plus this much times the largest distance of the triangle's vertices from the
/// origin (over `|d|`): where `t` is tiny against the triangle (a ray starting on or
/// next to it), the `f64` products' rounding, relative to the vertices' distances, is
/// what remains.
pub const DISTANCE_ABSOLUTE: f64 = 1.0 / (1u64 << 40) as f64;

impl Reference {
    /// Compares a tracer's nearest hit `got` (distance, input triangle id, and
    /// barycentrics `u`, `v`) for `ray` with the oracle's; see [`Agreement`].
    pub fn compare(&self, ray: &Ray, got: Option<(f32, u32, f32, f32)>) -> Agreement {
        self.compare_with(ray, self.intersect(ray), got)
    }

    /// [`Reference::compare`] with the oracle's answer for `ray` already known
    /// (`want`, from [`Reference::intersect`]): for comparing several tracers with
    /// one oracle pass.
    ///
    /// A different answer is a tie only where rounding decides it, as the oracle sees
    /// it (never by the tracer's own barycentrics): the tracer missed the oracle's hit
    /// and that hit lies within [`EDGE_SPACINGS`] of its triangle's boundary; or
    /// the tracer hit a triangle nearer than the oracle's (or where the oracle hits
    /// nothing) that the oracle rejected by less than that; or the hit is at distance
    /// zero (the ray starts on a triangle).
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
        // The tracer's triangle, nearer than the oracle's answer: rejected by the
        // oracle within rounding of its boundary?
        let nearer_on_edge =
            |(t, id, _, _): (f32, u32, f32, f32)| want.is_none_or(|w| (t as f64) < w.t) && self.on_edge(ray, id);
        let tie = match (got, want) {
            (None, Some(w)) => self.on_edge(ray, w.triangle),
            (Some(g), None) => nearer_on_edge(g),
            (Some(g), Some(w)) => {
                if (g.0 as f64) < w.t {
                    nearer_on_edge(g)
                } else {
                    self.on_edge(ray, w.triangle)
                }
            }
            (None, None) => false,
        };
        if tie {
            Agreement::Tie
        } else {
            Agreement::Different
        }
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
            Some(w) if self.on_edge(ray, w.triangle) || (w.t - tmax).abs() <= TIE_RELATIVE_T * tmax.abs() => {
                Agreement::Tie
            }
            _ => Agreement::Different,
        }
    }

    /// Compares a tracer's any-hit answer `got` (the occluder it found: distance and
    /// input triangle id, or `None`) with the oracle's, whatever the nearest hits are.
    /// A different answer is a tie only where rounding decides it: every blocker the
    /// oracle finds lies on its triangle's boundary or at an end of the segment, or the
    /// tracer's occluder is one the oracle rejected within rounding.
    pub fn compare_occluder(&self, ray: &Ray, got: Option<(f32, u32)>) -> Agreement {
        let want = self.occluded(ray);
        if got.is_some() == want {
            return Agreement::Same;
        }
        let at_end = |t: f64| {
            let near = |end: f32| (t - end as f64).abs() <= TIE_RELATIVE_T * (end as f64).abs().max(1e-30);
            near(ray.tmin) || near(ray.tmax)
        };
        let tie = match got {
            None => self.hits(ray).all(|h| self.on_edge(ray, h.triangle) || at_end(h.t)),
            Some((t, id)) => at_end(t as f64) || self.on_edge(ray, id),
        };
        if tie {
            Agreement::Tie
        } else {
            Agreement::Different
        }
    }

    /// Whether the ray passes within [`EDGE_SPACINGS`] of triangle `id`'s boundary
    /// (inside or outside it), by the oracle's arithmetic: where an `f32` test may
    /// decide either way. Distances are measured across the ray (in the triangle
    /// projected along it, as the watertight test sees it): a ray nearly parallel to a
    /// triangle that passes next to a vertex meets the plane far from it.
    pub fn on_edge(&self, ray: &Ray, id: u32) -> bool {
        let Some(i) = self.ids.iter().position(|&x| x == id) else { return false };
        let tri = &self.triangles[i];
        let (o, d) = (ray.origin.as_dvec3(), ray.dir.as_dvec3().normalize());
        let Some((_, u, v)) = plane_hit_f64(o, d, tri) else { return false };
        // The barycentrics survive the projection along the ray; each times the
        // projected triangle's altitude onto the edge opposite its vertex (twice its
        // area, |n.d|, over the edge's projected length) is a signed distance.
        // (The edge's length across the ray is `|e x d|`: `|e|^2 - (e.d)^2` cancels to
        // zero for a ray along the edge, which made a grazing ray's tie a mismatch.)
        let area2 = (tri[1] - tri[0]).cross(tri[2] - tri[0]).dot(d).abs();
        let altitude = |p: DVec3, q: DVec3| area2 / (q - p).cross(d).length();
        let distances =
            [(1.0 - u - v) * altitude(tri[1], tri[2]), u * altitude(tri[2], tri[0]), v * altitude(tri[0], tri[1])];
        let nearest = distances.iter().copied().fold(f64::INFINITY, f64::min);
        let far = tri.iter().map(|p| (*p - o).length()).fold(0.0, f64::max);
        nearest.abs() <= EDGE_SPACINGS * f64::from(f32::EPSILON) * 0.5 * far
    }

    /// How far a tracer's distance `t` for `ray` on triangle `id` is from the exact
    /// distance to that triangle's plane (in `f64`), and the bound it must keep
    /// ([`DISTANCE_RELATIVE`], [`DISTANCE_ABSOLUTE`]): `(|error|, bound)`. `None` if the
    /// id is unknown or the ray parallel to the plane.
    pub fn distance_error(&self, ray: &Ray, t: f32, id: u32) -> Option<(f64, f64)> {
        let i = self.ids.iter().position(|&x| x == id)?;
        let (o, d) = (ray.origin.as_dvec3(), ray.dir.as_dvec3());
        let tri = &self.triangles[i];
        let (exact, _, _) = plane_hit_f64(o, d, tri)?;
        let far = tri.iter().map(|v| (*v - o).length()).fold(0.0, f64::max) / d.length();
        Some(((t as f64 - exact).abs(), DISTANCE_RELATIVE * exact.abs() + DISTANCE_ABSOLUTE * far))
    }
}

/// Möller-Trumbore in `f64` without the range checks: `(t, u, v)` of the ray's point on
/// the triangle's plane, `None` for a ray parallel to it.
fn plane_hit_f64(o: DVec3, d: DVec3, t: &[DVec3; 3]) -> Option<(f64, f64, f64)> {
    let e1 = t[1] - t[0];
    let e2 = t[2] - t[0];
    let p = d.cross(e2);
    let det = e1.dot(p);
    if det == 0.0 {
        return None;
    }
    let s = o - t[0];
    let q = s.cross(e1);
    Some((e2.dot(q) / det, s.dot(p) / det, d.dot(q) / det))
}
