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
//!
//! The edge functions decide *whether* the ray meets the triangle; *where* it meets it
//! is [`plane_distance`], in `f64`: the test's own distance loses its precision on long
//! thin triangles (see there).

/// The per-ray shear: computed once, used for every triangle.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Shear {
    /// Axes permuted so that `kz` is the direction's largest component and the
    /// winding is kept (`kx`, `ky` swapped when `d[kz] < 0`).
    k: [usize; 3],
    /// `d[kx] / d[kz]`, `d[ky] / d[kz]`, `1 / d[kz]`.
    s: [f32; 3],
    o: [f32; 3],
    d: [f32; 3],
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
        Shear { k: [kx, ky, kz], s: [d[kx] / d[kz], d[ky] / d[kz], 1.0 / d[kz]], o, d }
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

    /// The ray's direction.
    pub fn direction(&self) -> [f32; 3] {
        self.d
    }

    /// The hit `(t, u, v)` of the triangle `v0 v1 v2` (nine floats) within
    /// `[tmin, tmax]`; `u` and `v` weigh `v1` and `v2`.
    #[inline(always)]
    pub fn intersect(&self, t: &[f32], tmin: f32, tmax: f32) -> Option<(f32, f32, f32)> {
        let [kx, ky, kz] = self.k;
        let [sx, sy, _] = self.s;
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
        let dist = plane_distance(o, self.d, t);
        // Barycentrics by division: |v| and |w| are at most |det| (the three agree in
        // sign), so the quotients stay in [0, 1] even where det is subnormal (a
        // reciprocal there overflows).
        (dist >= tmin && dist <= tmax).then_some((dist, v / det, w / det))
    }
}

/// Where the ray `o + t d` meets the plane of triangle `t` (nine floats), in `f64`,
/// rounded to `f32` once: the distance of a hit the edge functions accepted. `NaN` when
/// the ray is parallel to the plane in `f64` or the distance is beyond `f32`'s range
/// (no interval holds it: a miss).
///
/// # Why not the test's own distance
/// Woop, Benthin & Wald's distance `(u az + v bz + w cz) / det` is the mean of the
/// vertices' distances along the ray weighted by the barycentrics. Each edge function
/// carries an error of about `2^-24` times the products of sheared coordinates it is
/// made of, and `det` is the triangle's projected area: on a long thin triangle seen
/// obliquely the products are large against `det`, the weights are off by far more
/// than `2^-24`, and the weighted terms (hundreds, cancelling to about 1 on the 952:1
/// slivers of the zig-zag polygon in the tests) carry that error into `t`: 1.3 % there.
///
/// # Error bound
/// Here `n = (b - a) x (c - a)` and `t = n.(a - o) / n.d`. Widened to `f64`, the
/// differences of `f32` coordinates are exact (unless their exponents are more than 29
/// apart: then off by `2^-53` relative), and each of the eleven products and sums that
/// follow rounds once to `u = 2^-53`. With `N_i = |e1_j e2_k| + |e1_k e2_j|` (the
/// magnitude of the cross product's terms) and `gamma_5 = 5u / (1 - 5u)`, the `f64`
/// quotient is within
///
/// `gamma_5 (sum |a - o|_i N_i / |n.(a - o)| + sum |d_i| N_i / |n.d| + 1) |t|`
///
/// of the exact distance, and the final rounding adds half an `f32` ulp of `t`. The
/// two ratios are condition numbers: about `1 / sin` of the triangle's smallest angle
/// times `1 / sin` of the ray's angle to the plane. Only triangles and rays that are
/// both degenerate to `2^-25` or so make the `f64` term reach an `f32` ulp: for every
/// other hit, `t` is the exact distance rounded to `f32`, within one ulp (the tests
/// check it against the oracle on slivers, fans and the bunny). The same function runs
/// in every walk (scalar, SSE, eight triangles at once) and in the WGSL kernels where
/// the adapter has `f64` (`runtime::gpu`).
#[inline(always)]
pub fn plane_distance(o: [f32; 3], d: [f32; 3], t: &[f32]) -> f32 {
    let v = |i: usize| [t[3 * i] as f64, t[3 * i + 1] as f64, t[3 * i + 2] as f64];
    let (a, b, c) = (v(0), v(1), v(2));
    let e1 = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
    let e2 = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
    let n = [e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]];
    let ao = [a[0] - o[0] as f64, a[1] - o[1] as f64, a[2] - o[2] as f64];
    let num = ao[0] * n[0] + ao[1] * n[1] + ao[2] * n[2];
    let den = d[0] as f64 * n[0] + d[1] as f64 * n[1] + d[2] as f64 * n[2];
    let t = (num / den) as f32;
    if t.abs() < f32::INFINITY {
        t
    } else {
        f32::NAN
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
