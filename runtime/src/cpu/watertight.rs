//! Watertight ray/triangle intersection (Woop, Benthin & Wald, "Watertight
//! Ray/Triangle Intersection", JCGT 2013).
//!
//! The ray is sheared so that it runs along +z through the origin; a triangle's three
//! edge functions are then 2D cross products of sheared vertices. Two triangles that
//! share an edge evaluate that edge's function from the same two sheared vertices,
//! in the same order up to sign, so a ray through the shared edge is inside one of
//! them (or both): it cannot pass between. When a function rounds to exactly zero it is
//! evaluated again in `f64`, where the products of `f32` values are exact, so its sign
//! is right too. Triangles are closed (edges and vertices count), as in Möller-Trumbore.

/// The per-ray shear: computed once, used for every triangle.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Shear {
    /// Axes permuted so that `kz` is the direction's largest component and the
    /// winding is kept (`kx`, `ky` swapped when `d[kz] < 0`).
    k: [usize; 3],
    /// `d[kx] / d[kz]`, `d[ky] / d[kz]`, `1 / d[kz]`.
    s: [f32; 3],
    o: [f32; 3],
}

impl Shear {
    /// The shear of a ray (direction not zero).
    #[inline(always)]
    pub fn new(o: [f32; 3], d: [f32; 3]) -> Shear {
        let a = d.map(f32::abs);
        let kz = if a[0] >= a[1] && a[0] >= a[2] {
            0
        } else if a[1] >= a[2] {
            1
        } else {
            2
        };
        let (mut kx, mut ky) = ((kz + 1) % 3, (kz + 2) % 3);
        if d[kz] < 0.0 {
            std::mem::swap(&mut kx, &mut ky);
        }
        Shear { k: [kx, ky, kz], s: [d[kx] / d[kz], d[ky] / d[kz], 1.0 / d[kz]], o }
    }

    /// The permuted axes `(kx, ky, kz)`.
    pub fn axes(&self) -> [usize; 3] {
        self.k
    }

    /// The shear `(d[kx] / d[kz], d[ky] / d[kz], 1 / d[kz])`.
    pub fn scales(&self) -> [f32; 3] {
        self.s
    }

    /// The ray's origin.
    pub fn origin(&self) -> [f32; 3] {
        self.o
    }

    /// The hit `(t, u, v)` of the triangle `v0 v1 v2` (nine floats) within
    /// `[tmin, tmax]`; `u` and `v` weigh `v1` and `v2`.
    #[inline(always)]
    pub fn intersect(&self, t: &[f32], tmin: f32, tmax: f32) -> Option<(f32, f32, f32)> {
        let [kx, ky, kz] = self.k;
        let [sx, sy, sz] = self.s;
        let o = self.o;
        // Vertices relative to the origin.
        let rel = |i: usize| [t[3 * i] - o[0], t[3 * i + 1] - o[1], t[3 * i + 2] - o[2]];
        let (a, b, c) = (rel(0), rel(1), rel(2));
        // Sheared x and y.
        let (ax, ay) = (a[kx] - sx * a[kz], a[ky] - sy * a[kz]);
        let (bx, by) = (b[kx] - sx * b[kz], b[ky] - sy * b[kz]);
        let (cx, cy) = (c[kx] - sx * c[kz], c[ky] - sy * c[kz]);
        // Edge functions; exact zeros are decided again in f64.
        let mut u = cx * by - cy * bx;
        let mut v = ax * cy - ay * cx;
        let mut w = bx * ay - by * ax;
        if u == 0.0 || v == 0.0 || w == 0.0 {
            let e = |px: f32, py: f32, qx: f32, qy: f32| (px as f64 * qy as f64 - py as f64 * qx as f64) as f32;
            u = e(cx, cy, bx, by);
            v = e(ax, ay, cx, cy);
            w = e(bx, by, ax, ay);
        }
        // Inside when the three agree in sign (zeros allowed: edges are closed).
        if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
            return None;
        }
        let det = u + v + w;
        if det == 0.0 {
            return None; // the ray lies in the triangle's plane
        }
        // Scaled distance, compared before the division.
        let (az, bz, cz) = (sz * a[kz], sz * b[kz], sz * c[kz]);
        let scaled = u * az + v * bz + w * cz;
        let inv = 1.0 / det;
        let dist = scaled * inv;
        (dist >= tmin && dist <= tmax).then_some((dist, v * inv, w * inv))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_ray_through_a_shared_edge_hits_one_of_the_two_triangles() {
        // Two triangles sharing the edge (0,0,0)-(1,1,0); rays cross it at many points.
        let t1 = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0, 1.0, 0.0];
        let t2 = [0.0, 0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 1.0, 0.0];
        // Points inside the edge (its ends are corners of the union, where a ray
        // rounded a hair outside may truly miss both).
        for k in 1..1000 {
            let p = k as f32 / 1000.0;
            for d in [[0.0, 0.0, 1.0], [0.3, -0.2, 1.0], [-0.7, 0.1, -1.0]] {
                let o = [p - d[0], p - d[1], -d[2]];
                let s = Shear::new(o, d);
                let hits = [&t1, &t2].iter().filter(|t| s.intersect(&t[..], 0.0, f32::INFINITY).is_some()).count();
                assert!(hits >= 1, "a ray through ({p}, {p}, 0) along {d:?} slipped between");
            }
        }
    }

    #[test]
    fn hits_agree_with_the_plain_distance() {
        let tri = [0.0, 0.0, 2.0, 1.0, 0.0, 2.0, 0.0, 1.0, 2.0];
        let s = Shear::new([0.25, 0.25, 0.0], [0.0, 0.0, 1.0]);
        let (t, u, v) = s.intersect(&tri, 0.0, f32::INFINITY).unwrap();
        assert_eq!((t, u, v), (2.0, 0.25, 0.25));
        assert!(s.intersect(&tri, 0.0, 1.5).is_none());
        let back = Shear::new([0.25, 0.25, 5.0], [0.0, 0.0, -1.0]);
        assert_eq!(back.intersect(&tri, 0.0, f32::INFINITY).map(|h| h.0), Some(3.0));
        let miss = Shear::new([2.0, 2.0, 0.0], [0.0, 0.0, 1.0]);
        assert!(miss.intersect(&tri, 0.0, f32::INFINITY).is_none());
    }
}
