//! Rays and hits.

use glam::Vec3;
use octrace_format::StoredIndex;

/// A ray: points `origin + t * dir` for `t` in `[tmin, tmax]`.
///
/// The layout is the 32-byte record of `octrace trace`'s ray files:
/// `ox oy oz tmin dx dy dz tmax`, little-endian `f32`, so a file of rays can be
/// cast to `&[Ray]` with `bytemuck`. `dir` need not be normalised; `t` is measured in
/// units of `dir`.
///
/// # What counts as a hit
/// * The interval is closed: a hit at exactly `tmin` or `tmax` counts. A ray from a
///   surface with `tmin = 0` hits that surface at `t = 0`; secondary rays start off
///   it instead (`runtime::spawn`), or raise `tmin`.
/// * Distances are `f32`: a hit farther than `f32::MAX` (in units of `dir`, so a tiny
///   direction can put one there) is not reported.
/// * Any finite nonzero direction is traced exactly as the others, its components
///   subnormal or not, its length tiny or huge: the walk takes its exit decisions in
///   `f64` where `f32` products would underflow or overflow (`cpu::tables::exit_rule`).
/// * Of hits at the same rounded distance on different triangles, the nearest-hit
///   queries answer the exactly nearer under the exact test (the CPU's default,
///   `TriangleTest::Exact`), and of exactly equal ones the lowest input index (the
///   watertight test: the lowest input index); the any-hit queries answer whichever
///   they meet first.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Ray {
    /// Origin.
    pub origin: Vec3,
    /// Smallest accepted distance.
    pub tmin: f32,
    /// Direction.
    pub dir: Vec3,
    /// Largest accepted distance.
    pub tmax: f32,
}

const _: () = assert!(std::mem::size_of::<Ray>() == 32);

impl Ray {
    /// A ray over `[0, +inf)`.
    pub fn new(origin: Vec3, dir: Vec3) -> Ray {
        Ray { origin, tmin: 0.0, dir, tmax: f32::INFINITY }
    }

    /// A segment over `[tmin, tmax]`.
    pub fn segment(origin: Vec3, dir: Vec3, tmin: f32, tmax: f32) -> Ray {
        Ray { origin, tmin, dir, tmax }
    }

    /// The same ray with its direction scaled by a power of two so that its largest
    /// component lies in `[1, 2)`, and the factor its distances are to be multiplied
    /// by: the same line and the same hits (distances scaled exactly, barring a
    /// component that rounds as a subnormal). For the seeds' baselines, whose slab
    /// distances (`offset * (1 / d)`) lose their meaning for directions of 1e30 or
    /// 1e-40; the octree walk takes its own exact rule instead
    /// (`cpu::tables::exit_rule`). A direction already within `[2^-64, 2^64]` is
    /// returned as it is, factor 1.
    pub fn unit_scaled(&self) -> (Ray, f64) {
        let largest = self.dir.abs().max_element();
        if !(largest.is_finite() && largest > 0.0) || (2f32.powi(-64)..=2f32.powi(64)).contains(&largest) {
            return (*self, 1.0);
        }
        let e = crate::cpu::tables::exponent(largest);
        // 2^-e and 2^e as f64 (exact; either may be past f32's range).
        let (down, up) = (2f64.powi(-e), 2f64.powi(e));
        let dir = self.dir.as_dvec3() * down;
        let t = |x: f32| (x as f64 * up) as f32;
        let ray = Ray { origin: self.origin, tmin: t(self.tmin), dir: dir.as_vec3(), tmax: t(self.tmax) };
        (ray, down)
    }

    /// Whether the ray can hit anything: finite origin and direction, a non-zero
    /// direction, and `tmin <= tmax` with neither NaN. Any other ray is a defined miss.
    pub fn is_traceable(&self) -> bool {
        self.origin.is_finite()
            && self.dir.is_finite()
            && self.dir != Vec3::ZERO
            && self.tmin <= self.tmax
            && !self.tmin.is_nan()
    }
}

/// The nearest hit of a ray. [`Scene::surface`](crate::Scene::surface) gives what it
/// is on: the point, the geometric and shading normals, the texture coordinates, the
/// mesh part and the material ([`crate::HitSurface`]). Pass [`Hit::triangle`] (the
/// input's index) wherever a triangle goes back to the scene's shading data;
/// [`Hit::prim`] indexes the stored arrays ([`octrace_format::SceneView::triangle`]),
/// a type of its own, so that the one cannot be passed for the other:
///
/// ```compile_fail
/// # fn corners(scene: &octrace_runtime::Scene, hit: &octrace_runtime::Hit) {
/// scene.view().triangle(hit.triangle); // the input's index is not a stored index
/// # }
/// ```
/// ```
/// # fn corners(scene: &octrace_runtime::Scene, hit: &octrace_runtime::Hit) -> [[f32; 3]; 3] {
/// scene.view().triangle(hit.prim)
/// # }
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Distance along the ray, in units of its direction: with the exact test (the
    /// CPU's default), the exact distance to the hit triangle's plane correctly
    /// rounded to `f32`; with the watertight test (the GPU's default), within one ulp
    /// of it whatever the triangle's shape (`cpu::watertight::plane_distance` states
    /// the bound).
    pub t: f32,
    /// The hit triangle's index in the input mesh.
    pub triangle: u32,
    /// Barycentric coordinate of the second vertex.
    pub u: f32,
    /// Barycentric coordinate of the third vertex.
    pub v: f32,
    /// The leaf (box index) the hit was found in.
    pub leaf: u32,
    /// The triangle's index in the scene's stored arrays (`SceneView::triangle` and
    /// the other calls on stored triangles take it): a type of its own, so that it
    /// cannot be passed where the input's index ([`Hit::triangle`]) belongs.
    pub prim: StoredIndex,
}
