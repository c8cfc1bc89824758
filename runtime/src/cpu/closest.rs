//! The point of the surface nearest a query point.
//!
//! A best-first search over the search's own tree ([`SurfaceBounds`]: the triangles
//! the octree's leaves list, each once, in clusters of eight under nodes of eight,
//! made once a scene): nodes in order of a lower bound on their distance from the
//! point (a heap), each cluster's triangles measured in `f64`, until the next node lies
//! farther than the nearest triangle found. Every triangle is in one cluster, under
//! bounds that hold all of its points, so no triangle nearer than the answer is
//! skipped. A triangle is dropped before it is measured where its box, or its plane
//! and the line of an edge, put it certainly farther than the best so far.
//!
//! # What is exact
//! Each triangle's squared distance is computed in `f64` with an error bound
//! ([`near_f64`]); where two triangles' intervals overlap, exact arithmetic
//! (`exact::distance`) decides which is nearer, ties going to the lower input index;
//! where the interval of the answer's distance straddles a rounding boundary of `f32`,
//! exact arithmetic rounds it. So the distance is the exact distance from the point to
//! the stored triangles (their `f32` vertices), correctly rounded to `f32`, and the
//! triangle is the nearest one, the lowest input index among equally near ones. The
//! nearest point and its barycentrics are rounded from `f64` (within a few `f64`
//! roundings of the exact ones, and so as near as `f32` holds them). A triangle with a
//! vertex that is not finite (only in a file opened on the trusted path that breaks
//! the format's rules) is never the answer.

use std::cmp::Ordering;
use std::collections::BinaryHeap;

use octrace_format::distance::{Kid, Tree};
use octrace_format::layout::TRIANGLE_FLOATS;
use octrace_format::StoredIndex;

use super::tracer::Tracer;
pub(crate) use bounds::along_curve;
pub use bounds::SurfaceBounds;

use crate::exact::distance::{point_on, squared_distance, Square};

mod bounds;
mod placed;

/// The point of a scene's surface nearest a query point ([`Tracer::closest_point`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ClosestPoint {
    /// The distance from the query point: exact, correctly rounded to `f32`.
    pub distance: f32,
    /// The nearest point of the surface.
    pub point: [f32; 3],
    /// Input index of its triangle (of equally near ones, the lowest).
    pub triangle: u32,
    /// Stored index of its triangle (`octrace_format::StoredIndex`), for the scene's
    /// per-triangle arrays.
    pub prim: u32,
    /// Barycentric coordinate of the point on the triangle's second vertex.
    pub u: f32,
    /// Barycentric coordinate of the point on the triangle's third vertex.
    pub v: f32,
}

/// A distance signed as the signed-distance calls sign it: negative inside, except 0
/// (a point on the surface is at 0 whatever side it is counted on), so a band's
/// infinity takes the point's side.
///
/// ```
/// use octrace_runtime::cpu::signed;
/// assert_eq!((signed(0.5, true), signed(0.5, false), signed(0.0, true)), (-0.5, 0.5, 0.0));
/// assert_eq!(signed(f32::INFINITY, true), f32::NEG_INFINITY);
/// ```
pub fn signed(distance: f32, inside: bool) -> f32 {
    if inside && distance != 0.0 {
        -distance
    } else {
        distance
    }
}

/// `f64`'s unit roundoff, `2^-53`.
const U: f64 = 1.0 / (1u64 << 53) as f64;

/// A triangle's distance from the query point as `f64` computes it.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Near {
    /// Squared distance.
    pub d2: f64,
    /// A bound on the error of `d2`: the exact squared distance lies in `d2 +- err`.
    pub err: f64,
    /// The nearest point, and its barycentrics on the second and third vertices.
    pub q: [f64; 3],
    pub u: f64,
    pub v: f64,
    /// Whether `q` may be off by more than `f32` can hold (a sliver seen from far, or
    /// a point whose projection lies too near an edge to tell): it is found again from
    /// the exact feature where this triangle is the answer.
    pub thin: bool,
    /// The part of the triangle its nearest point certainly lies on, where the tests
    /// are certain of it: two triangles certainly nearest at the same vertex, or on
    /// the same segment, are exactly equally near (a tie, for the input index).
    pub on: On,
}

/// Where a triangle's nearest point certainly lies ([`Near::on`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum On {
    /// Not certain (or the face).
    Unknown,
    /// This vertex.
    Vertex([f32; 3]),
    /// The segment between these vertices (in the order of their bits), ends
    /// included: the distance is the segment's.
    Segment([f32; 3], [f32; 3]),
}

pub(crate) fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

pub(crate) fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

pub(crate) fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

/// The nearest point of triangle `t` (nine floats) to `p`, in `f64`, with a bound on
/// the error of its squared distance. With `r = p - v` for a vertex `v` and `M` the
/// largest `|r|`:
/// * each edge `v -> w`, `e = w - v`, as a segment: `t = clamp(r.e / e.e)`, `|r - t e|^2`.
///   The point `v + t e` lies on the segment whatever the rounding of `t`, and a `t`
///   off by `d` adds `(d |e|)^2` (some `u^2 M^2`); `r`, `e` and the products are
///   rounded a few times each: within `32 u M^2` of the segment's exact distance;
/// * the plane: `(n.r_a)^2 / n.n` with `n = (b - a) x (c - a)`, off by at most
///   `eps = 7 u |b - a| |c - a|` (a rounding of each product and of their difference,
///   the edges' own), so the distance `D` by `M (2k + 4u)`, `k = eps / |n|` (the
///   inverse sine of the angle at `a`, times `7u`), and `D^2` by
///   `M^2 (4k + 11u + (2k + 4u)^2)` (with the rounding of the square; bounded by 16u);
/// * the projection is in the triangle where each edge's `n.(e x r)` is positive:
///   each is off by at most `|e| |r| (12 u |n| + eps)` (a cross product, a dot, `n`'s
///   own error), so its sign is certain beyond that.
///
/// The exact squared distance is the plane's where the projection is in the
/// triangle, the least segment's where it is out; it always lies between the two
/// (the plane's is the least distance to the plane, and a segment's is the plane's
/// plus the square of the in-plane distance to it). Where the sign tests cannot say,
/// the interval spans both (near an edge they differ by that edge's in-plane
/// distance squared: a few roundings). Checked against exact arithmetic in the tests,
/// near every feature and on slivers.
#[cfg(test)]
pub(crate) fn near_f64(p: [f64; 3], t: &[f32]) -> Near {
    match near_f64_within(p, t, f64::INFINITY) {
        Some(near) => near,
        None => unreachable!("nothing is farther than infinity"),
    }
}

/// [`near_f64`], or `None` where the triangle is certainly farther than `within`
/// (its exact squared distance above it), found before the segments are measured: the
/// exact squared distance is the plane's plus the square of the in-plane distance from
/// the projection to the triangle, which is at least the distance to the line of an
/// edge the projection is certainly outside of, `-n.(e x r) / (|n| |e|)` (each term
/// taken at the far end of its error bound). The segments measured are those of the
/// edges the projection is not certainly inside of: the nearest point lies on them.
#[inline(always)]
pub(crate) fn near_f64_within(p: [f64; 3], t: &[f32], within: f64) -> Option<Near> {
    // Written out rather than mapped: this runs for every triangle a search measures.
    let t = &t[..9];
    let v = [
        [t[0] as f64, t[1] as f64, t[2] as f64],
        [t[3] as f64, t[4] as f64, t[5] as f64],
        [t[6] as f64, t[7] as f64, t[8] as f64],
    ];
    let r = [sub(p, v[0]), sub(p, v[1]), sub(p, v[2])];
    let rr = [dot(r[0], r[0]), dot(r[1], r[1]), dot(r[2], r[2])];
    let m2 = rr[0].max(rr[1]).max(rr[2]) * (1.0 + 8.0 * U);
    let edges = [(0usize, 1usize), (1, 2), (2, 0)];
    let e = [sub(v[1], v[0]), sub(v[2], v[1]), sub(v[0], v[2])];
    let n = cross(e[0], sub(v[2], v[0]));
    let nn = dot(n, n);
    let e_len2 = [dot(e[0], e[0]), dot(e[1], e[1]), dot(e[2], e[2])];

    // The projection's side of each edge: +1 in, -1 out, 0 not certain.
    let mut inside = nn > 0.0;
    let mut outside = !inside;
    let mut k = f64::INFINITY;
    let mut side = [0.0f64; 3];
    // The edges the projection is certainly inside of.
    let mut inner = [false; 3];
    if inside {
        let n_len = nn.sqrt();
        let eps = 7.0 * U * (e_len2[0] * e_len2[2]).sqrt();
        k = eps / n_len;
        let slack = 12.0 * U * n_len + eps;
        // The largest squared in-plane distance, times |n|^2, to the line of an edge
        // the projection is certainly outside of.
        let mut beyond = 0.0f64;
        for (i, s) in side.iter_mut().enumerate() {
            *s = dot(n, cross(e[i], r[i]));
            let eta2 = e_len2[i] * rr[i] * (1.0 + 8.0 * U) * slack * slack;
            if *s * *s <= eta2 {
                inside = false;
            } else if *s < 0.0 {
                inside = false;
                outside = true;
                let gap = -*s - eta2.sqrt() * (1.0 + 2.0 * U);
                if gap > 0.0 {
                    beyond = beyond.max(gap * gap / (e_len2[i] * (1.0 + 8.0 * U)));
                }
            } else {
                inner[i] = true;
            }
        }
        if within < f64::INFINITY {
            let h = dot(n, r[0]);
            let g = 2.0 * k + 4.0 * U;
            let plane = (h * h / nn - m2 * (4.0 * k + 16.0 * U + g * g)).max(0.0);
            let n_up = n_len * (1.0 + 4.0 * U) + eps;
            if (plane + beyond / (n_up * n_up)) * (1.0 - 16.0 * U) > within {
                return None;
            }
        }
    }
    if inside {
        let h = dot(n, r[0]);
        let sum = side[0] + side[1] + side[2];
        // side[i] / sum weighs the vertex opposite edge i.
        let (u, w) = (side[2] / sum, side[0] / sum);
        let q = [0, 1, 2].map(|c| v[0][c] + e[0][c] * u - e[2][c] * w);
        let g = 2.0 * k + 4.0 * U;
        let err = m2 * (4.0 * k + 16.0 * U + g * g);
        return Some(Near { d2: h * h / nn, err, q, u, v: w, thin: thin(m2, k, &v), on: On::Unknown });
    }

    // The segments: the least one's distance, point and (where certain) feature. An
    // edge the projection is certainly inside of holds the nearest point at most at
    // its ends, which the other edges hold. A feature is coded within the triangle:
    // `0..3` a vertex, `3 + edge` an edge's inside.
    let mut seg = [(f64::INFINITY, 0.0f64, 0usize); 3];
    for (edge, &(i, j)) in edges.iter().enumerate() {
        if inner[edge] {
            continue;
        }
        let along = dot(r[i], e[edge]);
        let ee = e_len2[edge];
        // The foot is certainly at an end where r.e is certainly <= 0 or >= e.e (and
        // the point is then that vertex, exactly).
        let margin = 8.0 * U * (ee * rr[i]).sqrt();
        let (tt, code) = if along < -margin || ee == 0.0 {
            (0.0, i)
        } else if along - ee > margin + 4.0 * U * ee {
            (1.0, j)
        } else {
            ((along / ee).clamp(0.0, 1.0), 3 + edge)
        };
        let x = e[edge];
        let d = [r[i][0] - tt * x[0], r[i][1] - tt * x[1], r[i][2] - tt * x[2]];
        seg[edge] = (dot(d, d), tt, code);
    }
    let err_s = 32.0 * U * m2;
    let mut best = 0;
    for k in 1..3 {
        if seg[k].0.total_cmp(&seg[best].0).is_lt() {
            best = k;
        }
    }
    let (s2, tt, code) = seg[best];
    let (i, j) = edges[best];
    let q = match tt {
        0.0 => v[i],
        1.0 => v[j],
        _ => [0, 1, 2].map(|c| v[i][c] + tt * e[best][c]),
    };
    let (mut u, mut w) = (0.0, 0.0);
    for (vertex, weight) in [(i, 1.0 - tt), (j, tt)] {
        match vertex {
            1 => u = weight,
            2 => w = weight,
            _ => {}
        }
    }
    if outside {
        // Certain where every segment near the least agrees on a vertex, or it is one
        // segment alone.
        let agree = seg.iter().filter(|s| s.0 <= s2 + 2.0 * err_s).all(|s| s.2 == code);
        let bits = |x: [f64; 3]| x.map(|c| c as f32);
        let on = match (agree, code) {
            (false, _) => On::Unknown,
            (true, 0..3) => On::Vertex(bits(v[code])),
            (true, _) => {
                let (a, b) = (bits(v[i]), bits(v[j]));
                let key = |x: [f32; 3]| x.map(f32::to_bits);
                if key(a) <= key(b) {
                    On::Segment(a, b)
                } else {
                    On::Segment(b, a)
                }
            }
        };
        return Some(Near { d2: s2, err: err_s, q, u, v: w, thin: false, on });
    }
    // Not certain which side: between the plane's distance and the segments'.
    let g = 2.0 * k + 4.0 * U;
    let h = dot(n, r[0]);
    let lo = h * h / nn - m2 * (4.0 * k + 16.0 * U + g * g);
    let hi = s2 + err_s;
    let lo = if lo.is_finite() { lo.min(hi) } else { 0.0 };
    Some(Near {
        d2: 0.5 * (lo + hi),
        err: 0.5 * (hi - lo) * (1.0 + 4.0 * U),
        q,
        u,
        v: w,
        thin: thin(m2, k, &v),
        on: On::Unknown,
    })
}

/// Whether a nearest point found in `f64` may be off by more than `2^-32` of the
/// triangle's coordinates (its error is some `M (k + 12u)`).
#[inline]
fn thin(m2: f64, k: f64, v: &[[f64; 3]; 3]) -> bool {
    let scale = v.iter().flatten().fold(0.0f64, |s, c| s.max(c.abs()));
    let off = m2.sqrt() * (k + 12.0 * U);
    off.is_nan() || off > scale * (1.0 / (1u64 << 32) as f64)
}

/// The best triangle so far.
#[derive(Clone, Copy, Debug)]
struct Best {
    near: Near,
    prim: u32,
    /// Its exact squared distance, once asked.
    exact: Option<Square>,
}

/// A node of the search's tree waiting in the heap, nearest first.
#[derive(Clone, Copy, Debug)]
struct Pending {
    d2: f64,
    node: u32,
}

impl PartialEq for Pending {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == Ordering::Equal
    }
}
impl Eq for Pending {}
impl PartialOrd for Pending {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Pending {
    /// Reversed, so that the max-heap pops the nearest.
    fn cmp(&self, other: &Self) -> Ordering {
        other.d2.total_cmp(&self.d2)
    }
}

/// What a search reuses from one point to the next (its heap).
#[derive(Debug, Default)]
pub struct ClosestScratch {
    heap: BinaryHeap<Pending>,
}

impl Tracer<'_> {
    /// The point of the surface nearest `p` at most `max_distance` from it (infinity
    /// for no limit), or `None` where there is none (or `p` is not finite, or
    /// `max_distance` is NaN or negative). Exact as the module docs say: the distance
    /// correctly rounded, the nearest triangle, ties to the lowest input index; a
    /// `max_distance` compares with the rounded distance. `bounds` are the scene's
    /// ([`SurfaceBounds::of`]; [`crate::Scene::closest_point`] keeps them).
    ///
    /// # Example
    /// ```
    /// use octrace_bake::{bake, procedural, BuildParams};
    /// use octrace_runtime::cpu::SurfaceBounds;
    /// use octrace_runtime::Scene;
    /// let scene = Scene::from_baked(bake(&procedural::grid(4, 1.0), &BuildParams::auto())?)?;
    /// let tracer = scene.tracer();
    /// let bounds = SurfaceBounds::of(&tracer)?;
    /// let near = tracer.closest_point(&bounds, [0.3, 0.6, 0.25], f32::INFINITY).expect("a surface");
    /// assert_eq!(near.distance, 0.25);
    /// assert_eq!(near.point, [0.3, 0.6, 0.0]);
    /// assert!(tracer.closest_point(&bounds, [0.3, 0.6, 0.25], 0.2).is_none());
    /// # Ok::<(), Box<dyn std::error::Error>>(())
    /// ```
    pub fn closest_point(&self, bounds: &SurfaceBounds, p: [f32; 3], max_distance: f32) -> Option<ClosestPoint> {
        self.closest_point_with(bounds, &mut ClosestScratch::default(), p, max_distance)
    }

    /// [`Tracer::closest_point`] reusing `scratch`'s memory.
    pub fn closest_point_with(
        &self,
        bounds: &SurfaceBounds,
        scratch: &mut ClosestScratch,
        p: [f32; 3],
        max_distance: f32,
    ) -> Option<ClosestPoint> {
        self.closest_inline(&bounds.tree(&self.view)?, scratch, p, max_distance)
    }

    /// The search, inlined where it is called: into [`Tracer::closest_point_with`] and
    /// into the batch's loop compiled for x86-64-v3.
    #[inline(always)]
    fn closest_inline(
        &self,
        tree: &Tree<'_>,
        scratch: &mut ClosestScratch,
        p: [f32; 3],
        max_distance: f32,
    ) -> Option<ClosestPoint> {
        if !p.iter().all(|c| c.is_finite()) || max_distance.is_nan() || max_distance < 0.0 {
            return None;
        }
        let pd = p.map(f64::from);
        // Nodes farther than the limit are not opened (a margin for the rounding of the
        // answer's distance, which the limit compares with).
        let limit = max_distance as f64;
        let limit2 = limit * limit * (1.0 + 1e-6);
        let mut best: Option<Best> = None;
        let heap = &mut scratch.heap;
        heap.clear();
        let (d2, word) = bounds::root(tree, pd);
        heap.push(Pending { d2, node: word });
        let mut visits = 0usize;
        while let Some(next) = heap.pop() {
            let bound = best.map_or(limit2, |b| b.near.d2 + b.near.err);
            // Boxes' distances are rounded too: a relative margin keeps them below.
            if next.d2 * (1.0 - 1e-9) > bound {
                break;
            }
            visits += 1;
            if visits > bounds::node_count(tree) + 64 {
                break; // each is pushed once: a guard, not a limit
            }
            match tree.kid(next.node) {
                None => {}
                Some(Kid::Cluster(prims)) => self.closest_in_cluster(p, pd, prims, &mut best),
                Some(Kid::Node(node)) => {
                    let bound = best.map_or(limit2, |b| b.near.d2 + b.near.err);
                    for (&word, d2) in node.kids.iter().zip(bounds::distance2(&node.bounds, pd)) {
                        if d2 * (1.0 - 1e-9) <= bound {
                            bounds::prefetch(tree, self.view.triangles, word);
                            heap.push(Pending { d2, node: word });
                        }
                    }
                }
            }
        }
        self.closest_answer(p, best?, max_distance, |prim| self.view.triangle(StoredIndex(prim)))
    }

    /// The closest point a search found (`best`, of the triangles `triangle` gives),
    /// its distance correctly rounded; `None` past `max_distance`.
    #[inline(always)]
    fn closest_answer(
        &self,
        p: [f32; 3],
        mut best: Best,
        max_distance: f32,
        triangle: impl Fn(u32) -> [[f32; 3]; 3],
    ) -> Option<ClosestPoint> {
        let distance = self.rounded_distance(p, &mut best, &triangle);
        if distance > max_distance {
            return None;
        }
        let (q, u, v) = match best.exact {
            Some(exact) if best.near.thin => point_on(p, triangle(best.prim), exact.feature),
            _ => (best.near.q, best.near.u, best.near.v),
        };
        Some(ClosestPoint {
            distance,
            point: q.map(|x| x as f32),
            triangle: self.input_id(best.prim),
            prim: best.prim,
            u: u as f32,
            v: v as f32,
        })
    }

    /// Measures the triangles of a cluster against the best so far.
    #[inline(always)]
    fn closest_in_cluster(&self, p: [f32; 3], pd: [f64; 3], prims: &[u32], best: &mut Option<Best>) {
        let all = self.view.triangles;
        for &prim in prims {
            let at = prim as usize * TRIANGLE_FLOATS;
            if let Some(t) = all.get(at..at + TRIANGLE_FLOATS) {
                self.closest_in_triangle(p, pd, prim, t, best, |q| self.view.triangle(StoredIndex(q)));
            }
        }
    }

    /// Measures stored triangle `prim` (its vertices `t`, as `triangle` gives them for
    /// exact arithmetic) against the best so far.
    #[inline(always)]
    fn closest_in_triangle(
        &self,
        p: [f32; 3],
        pd: [f64; 3],
        prim: u32,
        t: &[f32],
        best: &mut Option<Best>,
        triangle: impl Fn(u32) -> [[f32; 3]; 3],
    ) {
        // The triangle's box is a cheap first look.
        if let Some(b) = best {
            let mut gap2 = 0.0;
            for k in 0..3 {
                // Plain comparisons (a NaN coordinate gives some gap, which the
                // triangle's own measure, NaN, then could not beat anyway).
                let (a, b, c) = (t[k], t[k + 3], t[k + 6]);
                let lo = if a < b { a } else { b };
                let lo = if lo < c { lo } else { c } as f64;
                let hi = if a > b { a } else { b };
                let hi = if hi > c { hi } else { c } as f64;
                let below = lo - pd[k];
                let above = pd[k] - hi;
                let gap = if below > 0.0 {
                    below
                } else if above > 0.0 {
                    above
                } else {
                    0.0
                };
                gap2 += gap * gap;
            }
            if gap2 * (1.0 - 1e-9) > b.near.d2 + b.near.err {
                return;
            }
        }
        let within = best.map_or(f64::INFINITY, |b| b.near.d2 + b.near.err);
        let Some(near) = near_f64_within(pd, t, within) else { return };
        // A vertex that is not finite (a file on the trusted path that breaks the
        // format's rules): never the answer, and never handed to exact arithmetic.
        if !near.d2.is_finite() {
            return;
        }
        let Some(b) = *best else {
            *best = Some(Best { near, prim, exact: None });
            return;
        };
        // Certainly farther, or certainly nearer.
        if near.d2 - near.err > b.near.d2 + b.near.err {
            return;
        }
        if near.d2 + near.err < b.near.d2 - b.near.err {
            *best = Some(Best { near, prim, exact: None });
            return;
        }
        // Certainly nearest at the same vertex or on the same segment: exactly as
        // near, the lower id wins (its exact distance, if known, is the same).
        if near.on != On::Unknown && near.on == b.near.on {
            if self.input_id(prim) < self.input_id(b.prim) {
                *best = Some(Best { near, prim, exact: None });
            }
            return;
        }
        // Too close to call in f64: exact arithmetic decides (ties to the lower id).
        let held = b.exact.unwrap_or_else(|| squared_distance(p, triangle(b.prim)));
        let this = squared_distance(p, triangle(prim));
        let wins = match this.cmp(&held) {
            Ordering::Less => true,
            Ordering::Equal => self.input_id(prim) < self.input_id(b.prim),
            Ordering::Greater => false,
        };
        *best = Some(if wins { Best { near, prim, exact: Some(this) } } else { Best { exact: Some(held), ..b } });
    }

    /// The input index of stored triangle `prim` (read only where a tie or the answer
    /// asks: one array fewer in the search's loop).
    fn input_id(&self, prim: u32) -> u32 {
        self.view.triangle_ids.get(prim as usize).copied().unwrap_or(u32::MAX)
    }

    /// The best triangle's distance, correctly rounded: from `f64` where its error
    /// interval rounds to one `f32` (and the triangle is not thin), else exactly (the
    /// exact value kept in `best`).
    fn rounded_distance(&self, p: [f32; 3], best: &mut Best, triangle: impl Fn(u32) -> [[f32; 3]; 3]) -> f32 {
        if best.exact.is_none() {
            let Near { d2, err, thin, .. } = best.near;
            let lo = ((d2 - err).max(0.0).sqrt() * (1.0 - 4.0 * U)) as f32;
            let hi = ((d2 + err).sqrt() * (1.0 + 4.0 * U)) as f32;
            if lo == hi && !thin {
                return lo;
            }
            best.exact = Some(squared_distance(p, triangle(best.prim)));
        }
        best.exact.map_or(f32::NAN, |e| e.rounded())
    }

    /// [`Tracer::closest_point`] for each point, on this thread. The points are taken
    /// in the order of a space-filling curve (neighbours share the tree's nodes in
    /// cache: 1.07-1.22x on 10^4 points of the dragon, less on smaller scenes), the
    /// answers written where their points are.
    pub fn closest_point_batch(
        &self,
        bounds: &SurfaceBounds,
        points: &[[f32; 3]],
        max_distance: f32,
        out: &mut [Option<ClosestPoint>],
    ) {
        self.batch(bounds, points, max_distance, out, false)
    }

    /// [`Tracer::closest_point_batch`] on all threads of the current rayon pool: the
    /// curve's order cut into runs of 1,024 points a thread takes at a time.
    pub fn par_closest_point_batch(
        &self,
        bounds: &SurfaceBounds,
        points: &[[f32; 3]],
        max_distance: f32,
        out: &mut [Option<ClosestPoint>],
    ) {
        self.batch(bounds, points, max_distance, out, true)
    }

    /// The batches: in the curve's order where it can be had, on this thread or on the
    /// pool's (runs of 1,024 points).
    fn batch(
        &self,
        bounds: &SurfaceBounds,
        points: &[[f32; 3]],
        max_distance: f32,
        out: &mut [Option<ClosestPoint>],
        parallel: bool,
    ) {
        use rayon::prelude::*;
        assert_eq!(points.len(), out.len(), "one result slot a point");
        let Some(tree) = bounds.tree(&self.view) else {
            out.fill(None);
            return;
        };
        let tree = &tree;
        // The points gathered along the curve first: each search then reads its point
        // from the run it walks, not from wherever the caller put it.
        let b = &tree.root.bounds;
        let (lo, hi) = ([0, 1, 2].map(|k| b.lo[k][0] as f64), [0, 1, 2].map(|k| b.hi[k][0] as f64));
        bounds::along_curve(lo, hi, points, out, |points, out| {
            if parallel {
                out.par_chunks_mut(1024)
                    .zip(points.par_chunks(1024))
                    .for_each(|(o, p)| self.closest_each(tree, p, max_distance, o));
            } else {
                self.closest_each(tree, points, max_distance, out);
            }
        });
    }

    /// `out[k]`: the answer for `points[k]`, on this thread.
    fn closest_each(&self, tree: &Tree<'_>, points: &[[f32; 3]], max_distance: f32, out: &mut [Option<ClosestPoint>]) {
        #[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
        if self.uses_x86_64_v3() {
            // SAFETY: the processor has these features (`uses_x86_64_v3` is never true
            // where it does not).
            return unsafe { self.closest_each_v3(tree, points, max_distance, out) };
        }
        self.closest_each_loop(tree, points, max_distance, out)
    }

    /// [`Tracer::closest_each`] compiled for x86-64-v3 (AVX2: a node's eight bounds
    /// four lanes at a time). Rust does not fuse `a * b + c`: the same bits.
    ///
    /// # Safety
    /// The processor must have the features.
    #[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
    #[target_feature(enable = "avx2,bmi1,bmi2,fma,lzcnt,popcnt")]
    unsafe fn closest_each_v3(
        &self,
        tree: &Tree<'_>,
        points: &[[f32; 3]],
        max_distance: f32,
        out: &mut [Option<ClosestPoint>],
    ) {
        self.closest_each_loop(tree, points, max_distance, out)
    }

    #[inline(always)]
    fn closest_each_loop(
        &self,
        tree: &Tree<'_>,
        points: &[[f32; 3]],
        max_distance: f32,
        out: &mut [Option<ClosestPoint>],
    ) {
        let mut scratch = ClosestScratch::default();
        for (o, &p) in out.iter_mut().zip(points) {
            *o = self.closest_inline(tree, &mut scratch, p, max_distance);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A small generator (xorshift), so the tests need no dependency.
    struct Rng(u64);
    impl Rng {
        fn next(&mut self) -> u64 {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 7;
            self.0 ^= self.0 << 17;
            self.0
        }
        fn unit(&mut self) -> f32 {
            (self.next() >> 40) as f32 / (1u64 << 24) as f32
        }
    }

    /// The f64 bound holds against exact arithmetic on random triangles (slivers among
    /// them) and points placed near each of their features: faces, edges, vertices,
    /// the regions' boundaries, far and near; the early "farther than" never says so
    /// of a bound the exact distance is within.
    #[test]
    fn the_f64_error_bound_holds_against_exact_arithmetic() {
        let mut rng = Rng(0x9E37_79B9_7F4A_7C15);
        let (mut worst, mut certain, mut rejected) = (0.0f64, 0, 0);
        for case in 0..40_000 {
            let scale = [1e-3f32, 1.0, 1e3][case % 3];
            let mut t = [0f32; 9];
            for x in &mut t {
                *x = (rng.unit() - 0.5) * scale;
            }
            if case % 5 == 0 {
                // A sliver: the third vertex near the first edge.
                for k in 0..3 {
                    let s = rng.unit();
                    t[6 + k] = t[k] + (t[3 + k] - t[k]) * s + (rng.unit() - 0.5) * scale * 1e-5;
                }
            }
            let w = [rng.unit(), rng.unit(), rng.unit()];
            let sum = w[0] + w[1] + w[2];
            let on = [0, 1, 2].map(|k| (w[0] * t[k] + w[1] * t[3 + k] + w[2] * t[6 + k]) / sum);
            let feature = match case % 4 {
                0 => on,
                1 => [t[0], t[1], t[2]],
                2 => [0, 1, 2].map(|k| (t[k] + t[3 + k]) * 0.5),
                _ => [0, 1, 2].map(|_| (rng.unit() - 0.5) * scale * 2.0),
            };
            let off = [1e-7f32, 1e-3, 1.0, 1e3][(case / 3) % 4] * scale;
            let p = feature.map(|x| x + (rng.unit() - 0.5) * off);
            let near = near_f64(p.map(f64::from), &t);
            let tri = [[t[0], t[1], t[2]], [t[3], t[4], t[5]], [t[6], t[7], t[8]]];
            let exact = squared_distance(p, tri);
            let e = exact.approx();
            assert!(
                (near.d2 - e).abs() <= near.err + e * 1e-14,
                "case {case}: f64 {} (bound {}) against exact {e}, p {p:?}, t {t:?}",
                near.d2,
                near.err
            );
            worst = worst.max((near.d2 - e).abs() / near.err.max(f64::MIN_POSITIVE));
            // Never "farther than" a bound the exact distance is within; often so
            // where it is not.
            let pd = p.map(f64::from);
            assert!(
                near_f64_within(pd, &t, e * (1.0 + 1e-12) + f64::MIN_POSITIVE).is_some(),
                "case {case}: called farther than its own distance, p {p:?}, t {t:?}"
            );
            if near_f64_within(pd, &t, e * 0.9).is_none() {
                rejected += 1;
            }
            // A certain feature is where the exact distance is.
            let on = match near.on {
                On::Unknown => continue,
                On::Vertex(x) => [x, x, x],
                On::Segment(a, b) => [a, b, b],
            };
            certain += 1;
            assert_eq!(
                squared_distance(p, on).cmp(&exact),
                Ordering::Equal,
                "case {case}: {:?} is not where the nearest point is, p {p:?}, t {t:?}",
                near.on
            );
        }
        // The bound is not loose by orders of magnitude, and features are certified.
        assert!(worst > 1e-4, "worst error {worst} of the bound");
        assert!(certain > 10_000, "{certain} certain features");
        assert!(rejected > 10_000, "{rejected} triangles found farther than 0.9 of their distance early");
    }
}
