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
    /// `[tmin, tmax]`; `u` and `v` weigh `v1` and `v2`. Edges and vertices belong to
    /// the triangle (closed): a ray through an edge two triangles share hits both.
    #[inline(always)]
    pub fn intersect(&self, t: &[f32], tmin: f32, tmax: f32) -> Option<(f32, f32, f32)> {
        self.test::<false>(t, tmin, tmax)
    }

    /// [`Shear::intersect`] with each edge and vertex owned by one triangle: a ray
    /// through an edge or a vertex that triangles share crosses exactly one of them, so
    /// every crossing of a closed surface is counted once (the queries that list or
    /// count every crossing: `Tracer::crossings`).
    ///
    /// # The rule
    /// A ray through an edge makes that edge's function exactly zero (after the `f64`
    /// check, exact for the sheared `f32` vertices both triangles share). The point
    /// counts for the triangle when its edge, as the triangle runs it, points "up or
    /// right" once turned by the sign of the triangle's projected area: with
    /// `e = sign(det) (end - start)` in the sheared plane, when `e.y > 0`, or
    /// `e.y == 0` and `e.x > 0` (rasterisers' top-left rule). Two triangles on either
    /// side of a shared edge run it in opposite senses relative to their areas, so
    /// exactly one owns it, whichever way they are wound; two folded onto the same side
    /// (a silhouette) both own it or neither, an even count for a ray that only grazes.
    /// At a vertex two functions are zero and both edges must be owned, which gives
    /// the vertex to exactly one triangle of a fan around it.
    #[inline(always)]
    pub fn intersect_owned(&self, t: &[f32], tmin: f32, tmax: f32) -> Option<(f32, f32, f32)> {
        self.test::<true>(t, tmin, tmax)
    }

    /// [`Shear::intersect`] in `f64` throughout (vertices relative to the origin, the
    /// shear, the edge functions): the test of the rays under the walk's exact exit
    /// rule (`tables::exit_rule`), whose components are so small against each other
    /// that `f32` shear factors lose their bits (a subnormal `d[kx] / d[kz]`): a ray
    /// lying in a face's plane within that rounding then met every triangle of the
    /// plane its line crosses, at `t = 0`. In `f64` those products are exact or
    /// nearly, and the test is watertight for the same reason the `f32` one is (two
    /// triangles sharing an edge compute its function from the same sheared vertices).
    #[inline(never)]
    pub fn intersect_f64(&self, t: &[f32], tmin: f32, tmax: f32) -> Option<(f32, f32, f32)> {
        self.test_f64::<false>(t, tmin, tmax)
    }

    /// [`Shear::intersect_owned`] in `f64` throughout ([`Shear::intersect_f64`]).
    #[inline(never)]
    pub fn intersect_owned_f64(&self, t: &[f32], tmin: f32, tmax: f32) -> Option<(f32, f32, f32)> {
        self.test_f64::<true>(t, tmin, tmax)
    }

    /// [`Shear::intersect`] as exact arithmetic decides it: the same `f32` edge
    /// functions, each with an error bound; where a bound leaves a sign in doubt (the
    /// ray passes within rounding of an edge or a vertex, or lies nearly in the plane),
    /// the test runs again on integers (`exact::hit`), and the distance is the exact
    /// one correctly rounded to `f32` ([`plane_distance_rounded`]). See
    /// [`crate::TriangleTest::Exact`].
    #[inline(always)]
    pub fn intersect_exact(&self, t: &[f32], tmin: f32, tmax: f32) -> Option<(f32, f32, f32)> {
        self.test_exact::<false>(t, tmin, tmax)
    }

    /// [`Shear::intersect_owned`] as exact arithmetic decides it (its edge rule made
    /// exact: the sheared coordinates' differences are signed exactly).
    #[inline(always)]
    pub fn intersect_owned_exact(&self, t: &[f32], tmin: f32, tmax: f32) -> Option<(f32, f32, f32)> {
        self.test_exact::<true>(t, tmin, tmax)
    }

    /// Whether the ray meets triangle `a` exactly nearer (`Less`), at the same exact
    /// distance (`Equal`) or farther than triangle `b` (both hit: their planes are not
    /// parallel to the ray).
    pub fn compare_distances(&self, a: &[f32], b: &[f32]) -> std::cmp::Ordering {
        crate::exact::compare_distances(self.o, self.d, a, b)
    }

    /// What the `f32` tests start from: the vertices of triangle `t` relative to the
    /// origin, their sheared `x` and `y`, and the edge functions of the edges B->C,
    /// C->A and A->B.
    #[inline(always)]
    fn edges(&self, t: &[f32]) -> Edges {
        let [kx, ky, kz] = self.k;
        let [sx, sy, _] = self.s;
        let o = self.o;
        let rel = |i: usize| [t[3 * i] - o[0], t[3 * i + 1] - o[1], t[3 * i + 2] - o[2]];
        let (a, b, c) = (rel(0), rel(1), rel(2));
        let (ax, ay) = (a[kx] - sx * a[kz], a[ky] - sy * a[kz]);
        let (bx, by) = (b[kx] - sx * b[kz], b[ky] - sy * b[kz]);
        let (cx, cy) = (c[kx] - sx * c[kz], c[ky] - sy * c[kz]);
        let f = [cx * by - cy * bx, ax * cy - ay * cx, bx * ay - by * ax];
        Edges { rel: [a, b, c], sheared: [(ax, ay), (bx, by), (cx, cy)], f }
    }

    #[inline(always)]
    fn test_exact<const OWNED: bool>(&self, t: &[f32], tmin: f32, tmax: f32) -> Option<(f32, f32, f32)> {
        let Edges { rel, sheared, f: [u, v, w] } = self.edges(t);
        let bound = edge_error_bound(rel, sheared);
        let (pos, neg) = (u > bound || v > bound || w > bound, u < -bound || v < -bound || w < -bound);
        if pos && neg {
            return None; // two edges decided, on opposite sides
        }
        let decided = u.abs() > bound && v.abs() > bound && w.abs() > bound;
        if !decided {
            return self.test_exact_f64::<OWNED>(t, tmin, tmax);
        }
        // All three decided and agreeing: inside, off every edge (so no edge rule),
        // and the plane not parallel to the ray (det is their sum, of one sign).
        let det = u + v + w;
        let dist = plane_distance_rounded(self.o, self.d, t)?;
        (dist >= tmin && dist <= tmax).then_some((dist, v / det, w / det))
    }

    /// The second stage of [`Shear::intersect_exact`], where the `f32` bound left a
    /// sign in doubt: the edge functions times `d[kz]^2` (no quotient:
    /// `X = r[kx] d[kz] - d[kx] r[kz]`, the form `exact::hit` evaluates on integers)
    /// in `f64`, each with its error bound, some 2^29 times finer than the `f32` one.
    /// Only what this leaves in doubt (a ray within about 2^-50 of an edge or a
    /// vertex, relatively) goes to the integers.
    ///
    /// With `m` the largest `|r|` (vertices relative to the origin, exact or within
    /// `2^-53` in `f64`), each `X` is off by at most `4 (|r[kx] d[kz]| + |d[kx] r[kz]|)
    /// 2^-53 <= 2^-50 |d[kz]| m`, taken twice over as `E`; an edge function by at most
    /// `2 E T + 2^-51 T^2` with `T` the largest `|X| + |Y|` plus `E`. Nothing
    /// underflows or overflows: the products of at most four `f32` values stay within
    /// `2^-600` to `2^520`.
    #[cold]
    #[inline(never)]
    fn test_exact_f64<const OWNED: bool>(&self, t: &[f32], tmin: f32, tmax: f32) -> Option<(f32, f32, f32)> {
        let [kx, ky, kz] = self.k;
        let d = self.d.map(f64::from);
        let o = self.o.map(f64::from);
        let rel = |i: usize| [0, 1, 2].map(|k| t[3 * i + k] as f64 - o[k]);
        let (a, b, c) = (rel(0), rel(1), rel(2));
        let m = [a, b, c].iter().flatten().fold(0.0f64, |m, x| m.max(x.abs()));
        let sheared = |r: [f64; 3]| (r[kx] * d[kz] - d[kx] * r[kz], r[ky] * d[kz] - d[ky] * r[kz]);
        let (pa, pb, pc) = (sheared(a), sheared(b), sheared(c));
        let edge = |p: (f64, f64), q: (f64, f64)| q.0 * p.1 - q.1 * p.0;
        let (u, v, w) = (edge(pb, pc), edge(pc, pa), edge(pa, pb));
        let e = 2f64.powi(-49) * d[kz].abs() * m;
        let size = |p: (f64, f64)| p.0.abs() + p.1.abs();
        let big = size(pa).max(size(pb)).max(size(pc)) + e;
        let bound = big * (2.0 * e + big * 2f64.powi(-51)) * (1.0 + 2f64.powi(-20));
        let (pos, neg) = (u > bound || v > bound || w > bound, u < -bound || v < -bound || w < -bound);
        if pos && neg {
            return None;
        }
        if !(u.abs() > bound && v.abs() > bound && w.abs() > bound) {
            return crate::exact::hit(self.o, self.d, self.k, t, tmin, tmax, OWNED);
        }
        let det = u + v + w;
        let dist = plane_distance_rounded(self.o, self.d, t)?;
        (dist >= tmin && dist <= tmax).then_some((dist, (v / det) as f32, (w / det) as f32))
    }

    fn test_f64<const OWNED: bool>(&self, t: &[f32], tmin: f32, tmax: f32) -> Option<(f32, f32, f32)> {
        let [kx, ky, kz] = self.k;
        let d = self.d.map(f64::from);
        let (sx, sy) = (d[kx] / d[kz], d[ky] / d[kz]);
        let o = self.o.map(f64::from);
        let rel = |i: usize| [0, 1, 2].map(|k| t[3 * i + k] as f64 - o[k]);
        let (a, b, c) = (rel(0), rel(1), rel(2));
        let (ax, ay) = (a[kx] - sx * a[kz], a[ky] - sy * a[kz]);
        let (bx, by) = (b[kx] - sx * b[kz], b[ky] - sy * b[kz]);
        let (cx, cy) = (c[kx] - sx * c[kz], c[ky] - sy * c[kz]);
        let (u, v, w) = (cx * by - cy * bx, ax * cy - ay * cx, bx * ay - by * ax);
        if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
            return None;
        }
        let det = u + v + w;
        if det == 0.0 {
            return None;
        }
        if OWNED && (u == 0.0 || v == 0.0 || w == 0.0) {
            let owned = |e: f64, from: (f64, f64), to: (f64, f64)| e != 0.0 || owns64(det > 0.0, from, to);
            let (a, b, c) = ((ax, ay), (bx, by), (cx, cy));
            if !(owned(u, b, c) && owned(v, c, a) && owned(w, a, b)) {
                return None;
            }
        }
        let dist = plane_distance(self.o, self.d, t);
        (dist >= tmin && dist <= tmax).then_some((dist, (v / det) as f32, (w / det) as f32))
    }

    #[inline(always)]
    fn test<const OWNED: bool>(&self, t: &[f32], tmin: f32, tmax: f32) -> Option<(f32, f32, f32)> {
        let Edges { sheared: [(ax, ay), (bx, by), (cx, cy)], f: [mut u, mut v, mut w], .. } = self.edges(t);
        // Exact zeros are decided again in f64.
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
        if OWNED && (u == 0.0 || v == 0.0 || w == 0.0) {
            // U, V, W are the functions of edges B->C, C->A, A->B.
            let owned = |e: f32, from: (f32, f32), to: (f32, f32)| e != 0.0 || owns(det, from, to);
            let (a, b, c) = ((ax, ay), (bx, by), (cx, cy));
            if !(owned(u, b, c) && owned(v, c, a) && owned(w, a, b)) {
                return None;
            }
        }
        let dist = plane_distance(self.o, self.d, t);
        // Barycentrics by division: |v| and |w| are at most |det| (the three agree in
        // sign), so the quotients stay in [0, 1] even where det is subnormal (a
        // reciprocal there overflows).
        (dist >= tmin && dist <= tmax).then_some((dist, v / det, w / det))
    }
}

/// [`Shear::edges`]: a triangle against the sheared ray, in `f32`.
struct Edges {
    rel: [[f32; 3]; 3],
    sheared: [(f32, f32); 3],
    f: [f32; 3],
}

/// Whether a triangle whose projected area has the sign of `det` owns its edge from
/// `from` to `to` (sheared coordinates) where the ray crosses it: the rule of
/// [`Shear::intersect_owned`]. The differences are exact in sign in `f64`.
#[cold]
#[inline(never)]
fn owns(det: f32, from: (f32, f32), to: (f32, f32)) -> bool {
    owns64(det > 0.0, (from.0 as f64, from.1 as f64), (to.0 as f64, to.1 as f64))
}

/// [`owns`] on `f64` coordinates (the signs of their differences are what counts).
fn owns64(positive: bool, from: (f64, f64), to: (f64, f64)) -> bool {
    let s = if positive { 1.0 } else { -1.0 };
    let (ex, ey) = (s * (to.0 - from.0), s * (to.1 - from.1));
    ey > 0.0 || (ey == 0.0 && ex > 0.0)
}

/// A bound on the error of each of [`Shear::intersect`]'s `f32` edge functions for
/// the triangle whose vertices relative to the origin are `r` and whose sheared
/// coordinates are `s` (as that test computes them): a function whose magnitude
/// exceeds it has the sign of the exact one, which is the sign of the Plücker product
/// of the ray and the edge.
///
/// Each sheared coordinate `x = r[kx] - (d[kx] / d[kz]) r[kz]` is off by at most
/// `(2 |r[kx]| + 4 |r[kz]|) 2^-24` (the difference, the quotient, the product and the
/// subtraction round once each; `|d[kx] / d[kz]| <= 1`), under `E = 2^-21 m` with `m`
/// the largest `|r|`, plus `2^-147` for underflow. An edge function
/// `x_q y_p - y_q x_p` is then off by at most `2 E T + 2^-22 T^2` with `T` the largest
/// `|x| + |y|` plus `E` (the two products and the difference round once each). The
/// bound is computed with a margin for its own rounding; an overflow makes it
/// infinite, and the exact test decides.
#[inline(always)]
pub(crate) fn edge_error_bound(r: [[f32; 3]; 3], s: [(f32, f32); 3]) -> f32 {
    let big = |p: [f32; 3]| p[0].abs().max(p[1].abs()).max(p[2].abs());
    let m = big(r[0]).max(big(r[1])).max(big(r[2]));
    let e = m * (1.0 / (1u32 << 21) as f32) + f32::from_bits(4); // 2^-147
    let size = |p: (f32, f32)| p.0.abs() + p.1.abs();
    let t = size(s[0]).max(size(s[1])).max(size(s[2])) + e;
    let bound = t * (2.0 * e + t * (1.0 / (1u32 << 22) as f32));
    bound * (1.0 + 1.0 / (1u32 << 16) as f32) + f32::from_bits(4)
}

/// The sums of [`plane_distance`] in `f64`: with `n = (b - a) x (c - a)`, the
/// numerator `n.(a - o)` and denominator `n.d`, and for their error bound
/// ([`plane_distance_rounded`]) `a - o` and the magnitude of each of `n`'s components'
/// two terms.
struct PlaneSums {
    num: f64,
    den: f64,
    ao: [f64; 3],
    big: [f64; 3],
}

impl PlaneSums {
    /// The error bound's `A = sum |a - o|_i N_i` and `B = sum |d_i| N_i`
    /// ([`plane_distance_rounded`]) for the direction `d`.
    #[inline(always)]
    fn spreads(&self, d: [f32; 3]) -> (f64, f64) {
        let (ao, big) = (self.ao, self.big);
        let d = d.map(f64::from);
        let spread_num = ao[0].abs() * big[0] + ao[1].abs() * big[1] + ao[2].abs() * big[2];
        let spread_den = d[0].abs() * big[0] + d[1].abs() * big[1] + d[2].abs() * big[2];
        (spread_num, spread_den)
    }
}

#[inline(always)]
fn plane_sums(o: [f32; 3], d: [f32; 3], t: &[f32]) -> PlaneSums {
    let v = |i: usize| [t[3 * i] as f64, t[3 * i + 1] as f64, t[3 * i + 2] as f64];
    let (a, b, c) = (v(0), v(1), v(2));
    let e1 = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
    let e2 = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
    let terms = |j: usize, k: usize| (e1[j] * e2[k], e1[k] * e2[j]);
    let (n0, n1, n2) = (terms(1, 2), terms(2, 0), terms(0, 1));
    let n = [n0.0 - n0.1, n1.0 - n1.1, n2.0 - n2.1];
    let big = [n0.0.abs() + n0.1.abs(), n1.0.abs() + n1.1.abs(), n2.0.abs() + n2.1.abs()];
    let ao = [a[0] - o[0] as f64, a[1] - o[1] as f64, a[2] - o[2] as f64];
    let num = ao[0] * n[0] + ao[1] * n[1] + ao[2] * n[2];
    let den = d[0] as f64 * n[0] + d[1] as f64 * n[1] + d[2] as f64 * n[2];
    PlaneSums { num, den, ao, big }
}

/// [`plane_distance`] correctly rounded: the `f64` quotient where its error bound
/// leaves one `f32` it can round to, else the exact one (`exact::distance`). `None`
/// where the ray is parallel to the plane or the distance is past `f32`'s range.
///
/// The `f64` numerator `n.(a - o)` and denominator `n.d` (see [`plane_distance`]) are
/// within `g A` and `g B` of their exact values, with `g = 2^-49` (eight roundings and
/// more), `A = sum |a - o|_i N_i`, `B = sum |d_i| N_i`, `N_i` the magnitude of the
/// normal's terms; the quotient then within `(g A + |t| g B) / |n.d|`, plus its own
/// rounding.
#[inline(always)]
pub fn plane_distance_rounded(o: [f32; 3], d: [f32; 3], t: &[f32]) -> Option<f32> {
    let sums = plane_sums(o, d, t);
    let (spread_num, spread_den) = sums.spreads(d);
    rounded_if_certain(sums.num, sums.den, spread_num, spread_den).or_else(|| crate::exact::distance(o, d, t))
}

/// [`plane_distance_rounded`] less `shift.0 + shift.1` (a re-originated walk's
/// distance of a hit on the ray as given: `cpu::walk::Far`), correctly rounded: in
/// `f64` where the error bound allows (the numerator `n.(a - o) - s n.d` adds `|s|`
/// times the denominator's error and the rounding of the three products and
/// differences, `4 u (|n.(a - o)| + |s n.d|)`, written as `0.25 g` times that), else
/// exactly (`exact::shifted_distance`).
#[inline(always)]
pub(crate) fn shifted_distance_rounded(o: [f32; 3], d: [f32; 3], t: &[f32], shift: (f32, f32)) -> Option<f32> {
    let sums = plane_sums(o, d, t);
    let (spread_num, spread_den) = sums.spreads(d);
    let (num, den) = (sums.num, sums.den);
    let (hi, lo) = (shift.0 as f64 * den, shift.1 as f64 * den);
    let moved = num - hi - lo;
    let s = shift.0.abs() as f64 + shift.1.abs() as f64;
    let spread_moved = spread_num + s * spread_den + 0.25 * (num.abs() + hi.abs() + lo.abs());
    rounded_if_certain(moved, den, spread_moved, spread_den).or_else(|| crate::exact::shifted_distance(o, d, t, shift))
}

/// The `f32` that the quotient `num / den` of [`plane_distance_rounded`]'s sums
/// rounds to, where their error bound leaves only one (`None` where it does not: the
/// exact path decides). `spread_num` and `spread_den` are `sum |a - o|_i N_i` and
/// `sum |d_i| N_i` (the bound's `A` and `B`), within rounding: the bound has room for it.
#[inline(always)]
pub(crate) fn rounded_if_certain(num: f64, den: f64, spread_num: f64, spread_den: f64) -> Option<f32> {
    let g = 2f64.powi(-49);
    let (err_num, err_den) = (g * spread_num, g * spread_den);
    let q = num / den;
    // Decided only where den is far from its error (then |t| <= 2 |q| below).
    if err_den < 0.25 * den.abs() && q.is_finite() {
        let err = (err_num + 2.0 * q.abs() * err_den) / den.abs() * (1.0 + 1e-6) + q.abs() * 2f64.powi(-52);
        let (lo, hi) = ((q - err) as f32, (q + err) as f32);
        // (Zeros go to the exact path, which signs them.)
        if lo == hi && lo != 0.0 && lo.is_finite() {
            return Some(lo);
        }
    }
    None
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
    let PlaneSums { num, den, .. } = plane_sums(o, d, t);
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

    /// Owned hits of a ray over a triangle list: how many triangles claim it.
    fn owners(tris: &[[f32; 9]], o: [f32; 3], d: [f32; 3]) -> usize {
        let s = Shear::new(o, d);
        tris.iter().filter(|t| s.intersect_owned(&t[..], f32::NEG_INFINITY, f32::INFINITY).is_some()).count()
    }

    /// A grid of `n x n` unit squares in the plane z = 0, two triangles each, every
    /// other one wound the other way when `mixed` (ownership must not care).
    fn grid(n: usize, mixed: bool) -> Vec<[f32; 9]> {
        let mut tris = Vec::new();
        for y in 0..n {
            for x in 0..n {
                let (x0, y0, x1, y1) = (x as f32, y as f32, x as f32 + 1.0, y as f32 + 1.0);
                let mut a = [x0, y0, 0.0, x1, y0, 0.0, x1, y1, 0.0];
                let mut b = [x0, y0, 0.0, x1, y1, 0.0, x0, y1, 0.0];
                if mixed && (x + y) % 2 == 1 {
                    a = [a[0], a[1], a[2], a[6], a[7], a[8], a[3], a[4], a[5]];
                    b = [b[0], b[1], b[2], b[6], b[7], b[8], b[3], b[4], b[5]];
                }
                tris.extend([a, b]);
            }
        }
        tris
    }

    /// Every vertex, edge midpoint and random point strictly inside a grid of squares
    /// is owned by exactly one triangle, for rays from above and below, straight and
    /// tilted, whichever way the triangles are wound; outside the grid by none.
    #[test]
    fn every_point_of_a_grid_is_owned_once() {
        let mut seed = 0x0DD5_u64;
        let mut next = || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (seed >> 40) as f32 / (1u64 << 24) as f32
        };
        let dirs = [[0.0, 0.0, 1.0], [0.0, 0.0, -1.0], [0.25, -0.5, 1.0], [-0.375, 0.125, -1.0], [1.0, 0.5, 0.25]];
        for mixed in [false, true] {
            let tris = grid(4, mixed);
            for d in dirs {
                // Rays through p at t = 1.
                let through = |p: [f32; 3]| [p[0] - d[0], p[1] - d[1], p[2] - d[2]];
                for i in 0..=8 {
                    for j in 0..=8 {
                        let p = [i as f32 * 0.5, j as f32 * 0.5, 0.0];
                        let inside = (1..8).contains(&i) && (1..8).contains(&j);
                        let on_rim = !inside && (0..=8).contains(&i) && (0..=8).contains(&j);
                        let n = owners(&tris, through(p), d);
                        if inside {
                            assert_eq!(n, 1, "mixed {mixed}, d {d:?}, point {p:?}: {n} owners");
                        } else {
                            assert!(on_rim && n <= 2, "rim point {p:?}: {n}");
                        }
                    }
                }
                for _ in 0..2000 {
                    let p = [0.01 + 3.98 * next(), 0.01 + 3.98 * next(), 0.0];
                    assert_eq!(owners(&tris, through(p), d), 1, "mixed {mixed}, d {d:?}, point {p:?}");
                }
                assert_eq!(owners(&tris, through([4.5, 1.0, 0.0]), d), 0);
            }
        }
    }

    /// A fan of 12 triangles around a centre vertex (and the centre on a shared edge of
    /// a second fan turned over): a ray through the centre, straight or tilted, is owned
    /// once; a closed cube's every vertex and edge midpoint, once entering and once
    /// leaving.
    #[test]
    fn fans_and_closed_cubes_are_crossed_once_at_vertices_and_edges() {
        let n = 12;
        let rim = |k: usize| {
            let a = std::f64::consts::TAU * (k % n) as f64 / n as f64;
            [(2.0 * a.cos()) as f32, (2.0 * a.sin()) as f32, 0.0]
        };
        let fan: Vec<[f32; 9]> = (0..n)
            .map(|k| {
                let (p, q) = (rim(k), rim(k + 1));
                [0.0, 0.0, 0.0, p[0], p[1], p[2], q[0], q[1], q[2]]
            })
            .collect();
        for d in [[0.0, 0.0, 1.0], [0.3, 0.1, 1.0], [-0.2, 0.7, -1.0], [0.0, 0.5, 1.0]] {
            assert_eq!(owners(&fan, [-d[0], -d[1], -d[2]], d), 1, "fan centre, d {d:?}");
            for k in 0..n {
                let p = rim(k).map(|c| c * 0.5);
                assert_eq!(owners(&fan, [p[0] - d[0], p[1] - d[1], p[2] - d[2]], d), 1, "spoke {k}, d {d:?}");
            }
        }
        // A closed cube (12 triangles, outward): lines through each vertex, edge midpoint
        // and face centre, in generic directions into the cube: two crossings each.
        let cube: Vec<[f32; 9]> = [
            [[0., 0., 0.], [0., 1., 0.], [1., 1., 0.]],
            [[0., 0., 0.], [1., 1., 0.], [1., 0., 0.]],
            [[0., 0., 1.], [1., 0., 1.], [1., 1., 1.]],
            [[0., 0., 1.], [1., 1., 1.], [0., 1., 1.]],
            [[0., 0., 0.], [1., 0., 0.], [1., 0., 1.]],
            [[0., 0., 0.], [1., 0., 1.], [0., 0., 1.]],
            [[0., 1., 0.], [0., 1., 1.], [1., 1., 1.]],
            [[0., 1., 0.], [1., 1., 1.], [1., 1., 0.]],
            [[0., 0., 0.], [0., 0., 1.], [0., 1., 1.]],
            [[0., 0., 0.], [0., 1., 1.], [0., 1., 0.]],
            [[1., 0., 0.], [1., 1., 0.], [1., 1., 1.]],
            [[1., 0., 0.], [1., 1., 1.], [1., 0., 1.]],
        ]
        .map(|t: [[f32; 3]; 3]| [t[0][0], t[0][1], t[0][2], t[1][0], t[1][1], t[1][2], t[2][0], t[2][1], t[2][2]])
        .to_vec();
        let centre = [0.5f32; 3];
        for x in 0..=2 {
            for y in 0..=2 {
                for z in 0..=2 {
                    let p = [x as f32 * 0.5, y as f32 * 0.5, z as f32 * 0.5];
                    if p == centre {
                        continue;
                    }
                    // The line from the far side through the centre and p.
                    let d = [centre[0] - p[0], centre[1] - p[1], centre[2] - p[2]];
                    let o = [p[0] - 2.0 * d[0], p[1] - 2.0 * d[1], p[2] - 2.0 * d[2]];
                    assert_eq!(owners(&cube, o, d), 2, "through {p:?}");
                }
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
