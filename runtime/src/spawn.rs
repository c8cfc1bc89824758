//! Secondary rays that do not hit the surface they leave (after Pharr, Jakob &
//! Humphreys, *Physically Based Rendering*, 4th ed., section 6.8.6).
//!
//! A hit point computed from barycentrics in `f32` is off by at most
//! `gamma(7) * (|b0 v0| + |b1 v1| + |b2 v2|)` per axis, `gamma(n) = n eps / (1 - n eps)`
//! with `eps = 2^-24` (pbrt's bound for this sum of three products). The spawned
//! ray's origin is moved along the geometric normal, to the side the new direction
//! leaves by, by that error projected on the normal (and at least `gamma(7)` of the
//! triangle's largest coordinate, for exact hit points), then each coordinate one float
//! further out, so that the true surface lies behind it whatever the rounding.

use glam::Vec3;

use crate::ray::{Hit, Ray};

/// `gamma(n)` of the error analysis: `n eps / (1 - n eps)`, `eps = 2^-24`.
pub fn gamma(n: u32) -> f32 {
    let e = f32::EPSILON * 0.5 * n as f32;
    e / (1.0 - e)
}

/// The hit point of `hit` on triangle `tri`, from its barycentrics, and the
/// per-axis bound on that point's rounding error.
pub fn hit_point(tri: &[[f32; 3]; 3], hit: &Hit) -> (Vec3, Vec3) {
    let [v0, v1, v2] = tri.map(Vec3::from);
    let b0 = 1.0 - hit.u - hit.v;
    let p = b0 * v0 + hit.u * v1 + hit.v * v2;
    let err = gamma(7) * ((b0 * v0).abs() + (hit.u * v1).abs() + (hit.v * v2).abs());
    (p, err)
}

/// The unit normal of triangle `tri` (counter-clockwise winding), or zero when it is
/// degenerate.
pub fn face_normal(tri: &[[f32; 3]; 3]) -> Vec3 {
    let [v0, v1, v2] = tri.map(Vec3::from);
    (v1 - v0).cross(v2 - v0).normalize_or_zero()
}

/// A hit prepared for spawning rays: the hit point, the triangle's normal and the
/// offset's length, computed once for all the rays that leave the same hit (shadow
/// rays towards every light sample, reflection, refraction).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SpawnPoint {
    point: Vec3,
    normal: Vec3,
    offset: f32,
}

impl SpawnPoint {
    /// Prepares the hit of `hit` on `tri`.
    pub fn new(tri: &[[f32; 3]; 3], hit: &Hit) -> SpawnPoint {
        let (point, err) = hit_point(tri, hit);
        let normal = face_normal(tri);
        // At least gamma(7) of the triangle's largest coordinate: where the hit point is
        // exact (vertices on a plane of representable coordinates) its error bound is
        // zero, yet the triangle test that meets the spawned ray rounds its coordinates'
        // differences by up to that much, and would find the surface again at t = 0.
        let scale = tri.iter().flatten().fold(0.0f32, |m, c| m.max(c.abs()));
        SpawnPoint { point, normal, offset: err.dot(normal.abs()).max(gamma(7) * scale) }
    }

    /// The hit point, from the barycentrics.
    pub fn point(&self) -> Vec3 {
        self.point
    }

    /// The triangle's unit normal (counter-clockwise winding), or zero.
    pub fn normal(&self) -> Vec3 {
        self.normal
    }

    /// A ray towards `dir`, over `[0, tmax]`, whose origin is offset so that it cannot
    /// hit the triangle again at the origin (see the module docs).
    pub fn ray(&self, dir: Vec3, tmax: f32) -> Ray {
        let n = if self.normal.dot(dir) < 0.0 { -self.normal } else { self.normal };
        let offset = n * self.offset;
        let mut o = self.point + offset;
        // One float further out, in the direction of the offset, per axis.
        for a in 0..3 {
            if offset[a] > 0.0 {
                o[a] = o[a].next_up();
            } else if offset[a] < 0.0 {
                o[a] = o[a].next_down();
            }
        }
        Ray::segment(o, dir, 0.0, tmax)
    }
}

/// A ray from the hit of `hit` on `tri` towards `dir`, over `[0, tmax]`, whose origin
/// is offset so that it cannot hit `tri` again at the origin (see the module docs).
/// Several rays from one hit: [`SpawnPoint`].
pub fn spawn(tri: &[[f32; 3]; 3], hit: &Hit, dir: Vec3, tmax: f32) -> Ray {
    SpawnPoint::new(tri, hit).ray(dir, tmax)
}
