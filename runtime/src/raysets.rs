//! The standard ray sets of `bench/RAYS.md`, bit for bit.
//!
//! All arithmetic is `f64`, evaluated left to right as RAYS.md writes it (Rust never
//! fuses `*` and `+` on its own), and rounded to `f32` once at the end, so any
//! independent generator that follows RAYS.md produces the same bits.

use glam::DVec3;

use crate::ray::Ray;

/// The scene frame: the box of the triangles' vertices and its derived values.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frame {
    /// Low corner (of the `f32` vertices, widened).
    pub lo: DVec3,
    /// High corner.
    pub hi: DVec3,
    /// Centre, `(lo + hi) / 2`.
    pub c: DVec3,
    /// Extent, `hi - lo`.
    pub e: DVec3,
    /// Radius of the box's bounding sphere, `|e| / 2`.
    pub r: f64,
}

fn normalize(v: DVec3) -> DVec3 {
    let len = (v.x * v.x + v.y * v.y + v.z * v.z).sqrt();
    DVec3::new(v.x / len, v.y / len, v.z / len)
}

fn cross(a: DVec3, b: DVec3) -> DVec3 {
    DVec3::new(a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x)
}

fn to_f32(v: DVec3) -> glam::Vec3 {
    glam::Vec3::new(v.x as f32, v.y as f32, v.z as f32)
}

impl Frame {
    /// The frame of a box given by its `f32` corners.
    pub fn from_bounds(lo: [f32; 3], hi: [f32; 3]) -> Frame {
        let lo = DVec3::from(lo.map(f64::from));
        let hi = DVec3::from(hi.map(f64::from));
        let c = DVec3::new((lo.x + hi.x) / 2.0, (lo.y + hi.y) / 2.0, (lo.z + hi.z) / 2.0);
        let e = DVec3::new(hi.x - lo.x, hi.y - lo.y, hi.z - lo.z);
        let r = (e.x * e.x + e.y * e.y + e.z * e.z).sqrt() / 2.0;
        Frame { lo, hi, c, e, r }
    }

    /// The frame of a triangle list (every vertex counts, degenerate triangles too).
    pub fn from_triangles(tris: &[[[f32; 3]; 3]]) -> Frame {
        let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
        for v in tris.iter().flatten() {
            for a in 0..3 {
                lo[a] = lo[a].min(v[a]);
                hi[a] = hi[a].max(v[a]);
            }
        }
        Frame::from_bounds(lo, hi)
    }

    /// The point light of the shadow set, `c + 2 r normalize(-0.5, 1.0, 0.3)`.
    pub fn light(&self) -> DVec3 {
        let l = normalize(DVec3::new(-0.5, 1.0, 0.3));
        let k = 2.0 * self.r;
        DVec3::new(self.c.x + k * l.x, self.c.y + k * l.y, self.c.z + k * l.z)
    }
}

/// A pinhole camera in the form RAYS.md defines (basis `u`, `s`, `w`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// Eye position.
    pub eye: DVec3,
    /// Right.
    pub u: DVec3,
    /// Up.
    pub s: DVec3,
    /// Backwards (from the target to the eye).
    pub w: DVec3,
    /// `tan(fov / 2)`.
    pub tan_half_fov: f64,
    /// An orthographic camera's half height of view: its rays are parallel (along
    /// `-w`) and start on the image rectangle through the eye. `None`: perspective.
    pub orthographic: Option<f64>,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
}

impl Camera {
    /// A camera at `eye` looking at `target` with world up `+y`, vertical field of
    /// view `fov_deg` degrees.
    pub fn look_at(eye: DVec3, target: DVec3, fov_deg: f64, width: u32, height: u32) -> Camera {
        let up = DVec3::new(0.0, 1.0, 0.0);
        let w = normalize(DVec3::new(eye.x - target.x, eye.y - target.y, eye.z - target.z));
        let mut u = cross(up, w);
        if u.length_squared() == 0.0 {
            u = cross(DVec3::new(0.0, 0.0, 1.0), w); // looking straight up or down
        }
        let u = normalize(u);
        let s = cross(w, u);
        let tan_half_fov = (fov_deg / 2.0 * (std::f64::consts::PI / 180.0)).tan();
        Camera { eye, u, s, w, tan_half_fov, orthographic: None, width, height }
    }

    /// A camera of the scene file (`Shading::cameras`): its position, direction and up
    /// vector, with a vertical field of view of `fov_deg` degrees (the file's is
    /// `yfov`, in radians); an orthographic camera keeps its height of view and
    /// ignores `fov_deg`.
    pub fn from_scene(c: &octrace_format::Camera, fov_deg: f64, width: u32, height: u32) -> Camera {
        let eye = DVec3::from(c.position.map(f64::from));
        let mut cam = Camera::look_at(eye, eye + DVec3::from(c.forward.map(f64::from)), fov_deg, width, height);
        // The file's up vector, not the world's +y.
        let up = DVec3::from(c.up.map(f64::from)).normalize();
        cam.u = up.cross(cam.w).normalize();
        cam.s = cam.w.cross(cam.u);
        cam.orthographic = c.orthographic.map(f64::from);
        cam
    }

    /// The standard camera of the `primary` set, 1024 x 1024: eye `c + 2.7 r v` with
    /// `v = normalize(0.35, 0.25, 1)`, looking at `c`, 45 degrees.
    pub fn standard(frame: &Frame) -> Camera {
        Camera::standard_sized(frame, 1024, 1024)
    }

    /// The standard camera at another resolution.
    pub fn standard_sized(frame: &Frame, width: u32, height: u32) -> Camera {
        let v = normalize(DVec3::new(0.35, 0.25, 1.0));
        let k = 2.7 * frame.r;
        let eye = DVec3::new(frame.c.x + k * v.x, frame.c.y + k * v.y, frame.c.z + k * v.z);
        let mut cam = Camera::look_at(eye, frame.c, 45.0, width, height);
        // RAYS.md writes tan(22.5 * (pi / 180)); 45 / 2 is exactly 22.5.
        cam.tan_half_fov = (22.5 * (std::f64::consts::PI / 180.0)).tan();
        cam
    }

    /// The unrounded direction through pixel `(x, y)` (`y` from the top).
    pub fn direction(&self, x: u32, y: u32) -> DVec3 {
        if self.orthographic.is_some() {
            return -self.w;
        }
        let aspect = self.width as f64 / self.height as f64;
        let px = (2.0 * (x as f64 + 0.5) / self.width as f64 - 1.0) * self.tan_half_fov * aspect;
        let py = (1.0 - 2.0 * (y as f64 + 0.5) / self.height as f64) * self.tan_half_fov;
        let (u, s, w) = (self.u, self.s, self.w);
        normalize(DVec3::new(px * u.x + py * s.x - w.x, px * u.y + py * s.y - w.y, px * u.z + py * s.z - w.z))
    }

    /// The origin of the ray through pixel `(x, y)`: the eye, or for an orthographic
    /// camera the pixel's centre on the image rectangle through the eye.
    pub fn origin(&self, x: u32, y: u32) -> DVec3 {
        let Some(half) = self.orthographic else { return self.eye };
        let aspect = self.width as f64 / self.height as f64;
        let px = (2.0 * (x as f64 + 0.5) / self.width as f64 - 1.0) * half * aspect;
        let py = (1.0 - 2.0 * (y as f64 + 0.5) / self.height as f64) * half;
        self.eye + self.u * px + self.s * py
    }

    /// The ray through pixel `(x, y)`.
    pub fn ray(&self, x: u32, y: u32) -> Ray {
        Ray::new(to_f32(self.origin(x, y)), to_f32(self.direction(x, y)))
    }

    /// All the camera's rays, row by row.
    pub fn rays(&self) -> Vec<Ray> {
        (0..self.height).flat_map(|y| (0..self.width).map(move |x| self.ray(x, y))).collect()
    }
}

/// The `primary` set: 1024 x 1024 rays of the standard camera, row by row.
pub fn primary(frame: &Frame) -> Vec<Ray> {
    Camera::standard(frame).rays()
}

/// PCG32, O'Neill's `pcg32_random_r`, seeded as `pcg32_srandom_r`.
#[derive(Clone, Debug)]
pub struct Pcg32 {
    state: u64,
    inc: u64,
}

impl Pcg32 {
    /// Seeds like the reference `pcg32_srandom_r(initstate, initseq)`.
    pub fn new(initstate: u64, initseq: u64) -> Pcg32 {
        let mut g = Pcg32 { state: 0, inc: (initseq << 1) | 1 };
        g.next_u32();
        g.state = g.state.wrapping_add(initstate);
        g.next_u32();
        g
    }

    /// The generator RAYS.md seeds the incoherent set with.
    pub fn rays_md() -> Pcg32 {
        Pcg32::new(0x853c49e6748fea9b, 0xda3e39cb94b95bdb)
    }

    /// The next 32 random bits.
    pub fn next_u32(&mut self) -> u32 {
        let old = self.state;
        self.state = old.wrapping_mul(6364136223846793005).wrapping_add(self.inc);
        let x = (((old >> 18) ^ old) >> 27) as u32;
        x.rotate_right((old >> 59) as u32)
    }

    /// Uniform in `[0, 1)` with 24 bits: `(next_u32() >> 8) * 2^-24`.
    pub fn rand(&mut self) -> f64 {
        (self.next_u32() >> 8) as f64 * (1.0 / (1u64 << 24) as f64)
    }
}

/// The `incoherent` set: `n` rays (1,000,000 in RAYS.md) with origins uniform in the
/// scene's box and directions uniform on the sphere.
pub fn incoherent(frame: &Frame, n: usize) -> Vec<Ray> {
    let mut g = Pcg32::rays_md();
    (0..n)
        .map(|_| {
            let o = DVec3::new(
                frame.lo.x + g.rand() * frame.e.x,
                frame.lo.y + g.rand() * frame.e.y,
                frame.lo.z + g.rand() * frame.e.z,
            );
            let z = 1.0 - 2.0 * g.rand();
            let phi = 2.0 * std::f64::consts::PI * g.rand();
            let s = (1.0 - z * z).sqrt();
            Ray::new(to_f32(o), to_f32(DVec3::new(s * phi.cos(), s * phi.sin(), z)))
        })
        .collect()
}

/// One shadow ray for a primary hit: from just above the hit point (offset along the
/// normal facing the ray by `1e-4 r`) towards the light, `tmax` its distance.
///
/// `eye` and `dir` are the unrounded primary ray, `t` the tracer's `f32` distance,
/// `tri` the hit triangle's vertices.
pub fn shadow_ray(frame: &Frame, eye: DVec3, dir: DVec3, t: f32, tri: &[[f32; 3]; 3]) -> Ray {
    let v = tri.map(|p| DVec3::from(p.map(f64::from)));
    let e1 = DVec3::new(v[1].x - v[0].x, v[1].y - v[0].y, v[1].z - v[0].z);
    let e2 = DVec3::new(v[2].x - v[0].x, v[2].y - v[0].y, v[2].z - v[0].z);
    let mut n = normalize(cross(e1, e2));
    if n.x * dir.x + n.y * dir.y + n.z * dir.z > 0.0 {
        n = DVec3::new(-n.x, -n.y, -n.z);
    }
    let t = t as f64;
    let p = |a: usize| eye[a] + t * dir[a] + n[a] * 1e-4 * frame.r;
    let p = DVec3::new(p(0), p(1), p(2));
    let l = frame.light();
    let to = DVec3::new(l.x - p.x, l.y - p.y, l.z - p.z);
    let len = (to.x * to.x + to.y * to.y + to.z * to.z).sqrt();
    let d = DVec3::new(to.x / len, to.y / len, to.z / len);
    Ray::segment(to_f32(p), to_f32(d), 0.0, len as f32)
}

/// The `shadow` set from the primary set's hits, in primary order: `hit(i)` gives the
/// `f32` distance and triangle of primary ray `i`'s hit, or `None`.
pub fn shadow(frame: &Frame, hit: impl Fn(usize) -> Option<(f32, [[f32; 3]; 3])>) -> Vec<Ray> {
    let cam = Camera::standard(frame);
    let mut out = Vec::new();
    for y in 0..cam.height {
        for x in 0..cam.width {
            let i = (y * cam.width + x) as usize;
            if let Some((t, tri)) = hit(i) {
                out.push(shadow_ray(frame, cam.eye, cam.direction(x, y), t, &tri));
            }
        }
    }
    out
}

/// The `points` set: `n` points (1,000,000 for the benchmarks) uniform in the scene's
/// box, for inside/outside queries: PCG32 seeded as `pcg32_srandom_r(0x853c49e6748fea9b,
/// 0x5eed0f9011175)` (the incoherent set's state, another stream), and for each point
/// `x = lo.x + rand() * e.x`, then `y`, then `z`, in `f64`, rounded to `f32` once.
///
/// # Example
/// ```
/// use octrace_runtime::raysets::{self, Frame};
/// let frame = Frame::from_bounds([0.0; 3], [1.0, 2.0, 3.0]);
/// let points = raysets::points(&frame, 1000);
/// assert!(points.iter().all(|p| (0..3).all(|k| 0.0 <= p[k] && p[k] <= [1.0, 2.0, 3.0][k])));
/// ```
pub fn points(frame: &Frame, n: usize) -> Vec<[f32; 3]> {
    let mut g = Pcg32::new(0x853c49e6748fea9b, 0x5eed0f9011175);
    (0..n)
        .map(|_| {
            let x = frame.lo.x + g.rand() * frame.e.x;
            let y = frame.lo.y + g.rand() * frame.e.y;
            let z = frame.lo.z + g.rand() * frame.e.z;
            [x as f32, y as f32, z as f32]
        })
        .collect()
}

/// The `near` set: `n` points within `distance` of the surface, half on each side:
/// point `i` picks triangle `next_u32() % len` of `triangles`, a point in it by two
/// `rand()` folded into the triangle (`a + b > 1` taken as `1 - a`, `1 - b`), and moves
/// it along the triangle's unit normal by `+distance` for even `i`, `-distance` for odd
/// (`f64`, one rounding to `f32`; degenerate triangles give the point on them). The
/// same generator and stream as [`points`], restarted.
pub fn near_surface(triangles: &[[[f32; 3]; 3]], n: usize, distance: f64) -> Vec<[f32; 3]> {
    if triangles.is_empty() {
        return Vec::new();
    }
    let mut g = Pcg32::new(0x853c49e6748fea9b, 0x5eed0f9011175);
    (0..n)
        .map(|i| {
            let t = triangles[g.next_u32() as usize % triangles.len()].map(|v| DVec3::from(v.map(f64::from)));
            let (a, b) = (g.rand(), g.rand());
            let (a, b) = if a + b > 1.0 { (1.0 - a, 1.0 - b) } else { (a, b) };
            let on = t[0] + (t[1] - t[0]) * a + (t[2] - t[0]) * b;
            let normal = (t[1] - t[0]).cross(t[2] - t[0]).normalize_or_zero();
            let side = if i % 2 == 0 { distance } else { -distance };
            to_f32(on + normal * side).to_array()
        })
        .collect()
}
