//! The closest-point search's own tree: the scene's triangles (those its leaves list,
//! each once) in the Morton order of their centroids, grouped into clusters of at most
//! [`LEAF`] (contiguous, with their stored and input indices beside them) under nodes of
//! up to eight children, each child bounded by where its surface lies ([`NodeBound`]).
//!
//! The octree's leaves are cubes that list every triangle crossing them: a triangle is
//! read again from each leaf it crosses, through an index, and a leaf's bound is its
//! cube's share of the surface. Clusters hold each triangle once, side by side, and
//! their bounds are as tight as their triangles: a search measures fewer triangles and
//! reads them in order.

use rayon::prelude::*;

use octrace_format::layout::TRIANGLE_FLOATS;
use octrace_format::memory::try_with_capacity;

use super::{cross, dot, sub, U};
use crate::cpu::tracer::Tracer;
use crate::winding::{morton, split};

/// At most this many triangles a cluster.
pub(super) const LEAF: usize = 8;

/// A child word's bit for a cluster (else an internal node's index).
const CLUSTER: u32 = 1 << 31;

const INF: f32 = f32::INFINITY;

/// Where the surface inside a node lies: in a box, and in a slab across a direction
/// `m` (`slab[0] <= m.x <= slab[1]` for every point `x` of it). The slab follows the
/// surface's mean normal, so it is thin where the surface is flat: a point beside a
/// flat piece of surface is as far from it as the plane and the box's reach along
/// the plane allow, where a box alone (tilted surface) would be much nearer.
#[derive(Clone, Copy, Debug)]
pub(super) struct NodeBound {
    lo: [f32; 3],
    hi: [f32; 3],
    m: [f32; 3],
    slab: [f32; 2],
}

impl NodeBound {
    /// No surface.
    const EMPTY: NodeBound = NodeBound { lo: [INF; 3], hi: [-INF; 3], m: [1.0, 0.0, 0.0], slab: [INF, -INF] };

    fn is_empty(&self) -> bool {
        self.lo[0].is_nan() || self.hi[0].is_nan() || self.lo[0] > self.hi[0]
    }

    /// `m.x`'s least and greatest over the box, widened by their rounding.
    fn reach(&self, m: [f64; 3]) -> (f64, f64) {
        let (mut lo, mut hi, mut size) = (0.0, 0.0, 0.0);
        for k in 0..3 {
            let (a, b) = (m[k] * self.lo[k] as f64, m[k] * self.hi[k] as f64);
            lo += a.min(b);
            hi += a.max(b);
            size += a.abs().max(b.abs());
        }
        (lo - 4.0 * U * size, hi + 4.0 * U * size)
    }

    /// The bound with the slab `[lo, hi]` across `m` (widened to `f32`), kept within
    /// the box's own reach along `m`.
    fn with_slab(mut self, m: [f64; 3], lo: f64, hi: f64) -> NodeBound {
        let (box_lo, box_hi) = self.reach(m);
        let (lo, hi) = (lo.max(box_lo), hi.min(box_hi));
        self.m = m.map(|x| x as f32);
        self.slab = if lo <= hi { [down(lo), up(hi)] } else { [down(box_lo), up(box_hi)] };
        self
    }
}

/// Eight children's bounds side by side, by coordinate, so that one node's eight
/// lower bounds run as one vector loop.
#[derive(Clone, Copy, Debug)]
pub(super) struct Bounds8 {
    lo: [[f32; 8]; 3],
    hi: [[f32; 8]; 3],
    m: [[f32; 8]; 3],
    slab: [[f32; 8]; 2],
}

impl Bounds8 {
    fn of(b: &[NodeBound; 8]) -> Bounds8 {
        // An empty child (or one whose box is NaN) reads as the empty bound.
        let b = b.map(|b| if b.is_empty() { NodeBound::EMPTY } else { b });
        Bounds8 {
            lo: [0, 1, 2].map(|k| b.map(|b| b.lo[k])),
            hi: [0, 1, 2].map(|k| b.map(|b| b.hi[k])),
            m: [0, 1, 2].map(|k| b.map(|b| b.m[k])),
            slab: [0, 1].map(|k| b.map(|b| b.slab[k])),
        }
    }

    /// For each child, a lower bound on the squared distance from `p` to the surface
    /// in it (infinity where it holds none: its box's gap is infinite): the larger of
    /// the box's and the slab's. For `x` in both, `|p - x|^2 = (m.(p - x))^2 / m.m +
    /// |P(p - x)|^2` (`P` the projection across `m`): the first is at least the squared
    /// gap between `m.p` and the slab, the second at least `|P(p - c)| - R` squared (`c`
    /// the box's centre, `R` its half diagonal). Each term shrunk by its rounding.
    #[inline(always)]
    pub(super) fn distance2(&self, p: [f64; 3]) -> [f64; 8] {
        let mut out = [0.0f64; 8];
        let p_abs = p.map(f64::abs);
        for (l, out) in out.iter_mut().enumerate() {
            let (mut boxed, mut r2) = (0.0f64, 0.0f64);
            let mut c = [0.0f64; 3];
            for k in 0..3 {
                let (lo, hi) = (self.lo[k][l] as f64, self.hi[k][l] as f64);
                let below = lo - p[k];
                let above = p[k] - hi;
                let gap = if below > above { below } else { above };
                let gap = if gap > 0.0 { gap } else { 0.0 };
                boxed += gap * gap;
                c[k] = 0.5 * (lo + hi);
                r2 += 0.25 * (hi - lo) * (hi - lo);
            }
            let m = [self.m[0][l] as f64, self.m[1][l] as f64, self.m[2][l] as f64];
            let mm = m[0] * m[0] + m[1] * m[1] + m[2] * m[2];
            let s = m[0] * p[0] + m[1] * p[1] + m[2] * p[2];
            let s_err = 4.0 * U * (m[0].abs() * p_abs[0] + m[1].abs() * p_abs[1] + m[2].abs() * p_abs[2]);
            let below = self.slab[0][l] as f64 - s;
            let above = s - self.slab[1][l] as f64;
            let gap = (if below > above { below } else { above }) - s_err;
            let gap = if gap > 0.0 { gap } else { 0.0 };
            let w = [p[0] - c[0], p[1] - c[1], p[2] - c[2]];
            let along = (m[0] * w[0] + m[1] * w[1] + m[2] * w[2]) / mm;
            let perp = [w[0] - m[0] * along, w[1] - m[1] * along, w[2] - m[2] * along];
            let w_len = (w[0] * w[0] + w[1] * w[1] + w[2] * w[2]).sqrt();
            let lateral = (perp[0] * perp[0] + perp[1] * perp[1] + perp[2] * perp[2]).sqrt()
                - r2.sqrt() * (1.0 + 4.0 * U)
                - 16.0 * U * w_len;
            let lateral = if lateral > 0.0 { lateral } else { 0.0 };
            let disk = (gap * gap / mm + lateral * lateral) * (1.0 - 16.0 * U);
            // An empty child: its box's gap is infinite (its centre NaN, so the disk's
            // NaN: the comparison keeps the box's).
            *out = if disk > boxed { disk } else { boxed };
        }
        out
    }
}

/// `x` rounded to an `f32` at most `x`.
fn down(x: f64) -> f32 {
    let f = x as f32;
    if f as f64 > x {
        f.next_down()
    } else {
        f
    }
}

/// `x` rounded to an `f32` at least `x`.
fn up(x: f64) -> f32 {
    let f = x as f32;
    if (f as f64) < x {
        f.next_up()
    } else {
        f
    }
}

/// The unit direction of a sum of normals (an axis where it is zero), as `f32` and
/// back, so that the query reads the `m` the slab was measured across.
fn direction(sum: [f64; 3]) -> [f64; 3] {
    let len = dot(sum, sum).sqrt();
    if !len.is_finite() || len <= 0.0 {
        return [1.0, 0.0, 0.0];
    }
    sum.map(|x| (x / len) as f32 as f64)
}

/// Adds `n` to `sum` turned to agree with `reference`: a sheet's two sides, or a
/// thin wall's, add up instead of cancelling.
fn add_aligned(sum: &mut [f64; 3], n: [f64; 3], reference: [f64; 3]) {
    let sign = if dot(n, reference) < 0.0 { -1.0 } else { 1.0 };
    for k in 0..3 {
        sum[k] += sign * n[k];
    }
}

/// A triangle as the search reads it: its vertices, stored index and input index.
#[derive(Clone, Copy, Debug)]
pub(super) struct Tri {
    pub t: [f32; TRIANGLE_FLOATS],
    pub prim: u32,
    pub id: u32,
}

/// An internal node: its children's bounds side by side (what the search reads when it
/// opens the node) and their words (a cluster's index with [`CLUSTER`], else a node's;
/// an unused child has an empty bound).
#[derive(Clone, Copy, Debug)]
pub(super) struct Node {
    pub bounds: Bounds8,
    pub kids: [u32; 8],
}

/// What a child word names.
pub(super) enum Kid<'a> {
    Cluster(&'a [Tri]),
    Node(&'a Node),
}

/// The closest-point search's tree of a scene (see the module docs). Made once a
/// scene from its leaves and triangles ([`crate::Scene`] keeps it): about 50 bytes a
/// triangle (and 75 while it is made).
#[derive(Clone, Debug)]
pub struct SurfaceBounds {
    /// The whole surface's bound, in lane 0 (the others empty).
    root: Bounds8,
    root_word: u32,
    nodes: Vec<Node>,
    /// Each cluster's range in `tris`.
    clusters: Vec<(u32, u32)>,
    tris: Vec<Tri>,
}

impl SurfaceBounds {
    /// The tree of `tracer`'s scene: the triangles its leaves list.
    pub fn of(tracer: &Tracer<'_>) -> SurfaceBounds {
        let v = tracer.view();
        let count = v.triangles.len() / TRIANGLE_FLOATS;
        let mut listed = vec![false; count];
        for &prim in v.tri_refs {
            if let Some(l) = listed.get_mut(prim as usize) {
                *l = true;
            }
        }
        let triangle = |i: usize| {
            let t = v.triangles.get(i * TRIANGLE_FLOATS..(i + 1) * TRIANGLE_FLOATS)?;
            let id = *v.triangle_ids.get(i)?;
            let mut copy = [0f32; TRIANGLE_FLOATS];
            copy.copy_from_slice(t);
            Some(Tri { t: copy, prim: i as u32, id })
        };
        let mut bounds = SurfaceBounds {
            root: Bounds8::of(&[NodeBound::EMPTY; 8]),
            root_word: CLUSTER,
            nodes: Vec::new(),
            clusters: Vec::new(),
            tris: Vec::new(),
        };
        // Morton order of the centroids, in the triangles' box: the codes sorted with
        // the triangles' indices (16 bytes a triangle), then the triangles copied once
        // in that order.
        let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
        for tri in (0..count).filter(|&i| listed[i]).filter_map(triangle) {
            for k in 0..3 {
                let g = centroid(&tri.t, k);
                lo[k] = lo[k].min(g);
                hi[k] = hi[k].max(g);
            }
        }
        let mut keyed: Vec<(u64, u32)> = (0..count)
            .filter(|&i| listed[i])
            .filter_map(triangle)
            .map(|tri| (morton([0, 1, 2].map(|k| centroid(&tri.t, k)), lo, hi), tri.prim))
            .collect();
        drop(listed);
        if keyed.is_empty() {
            bounds.clusters.push((0, 0));
            return bounds;
        }
        keyed.par_sort_unstable();
        bounds.tris = keyed.iter().filter_map(|&(_, i)| triangle(i as usize)).collect();
        let codes: Vec<u64> = keyed.iter().map(|k| k.0).collect();
        drop(keyed);
        let (root, word) = bounds.build(&codes, 0, codes.len(), 0);
        let mut top = [NodeBound::EMPTY; 8];
        top[0] = root.0;
        bounds.root = Bounds8::of(&top);
        bounds.root_word = word;
        bounds
    }

    /// The root's lower bound on the squared distance from `p` (as a node's children's)
    /// and its word.
    #[inline]
    pub(super) fn root(&self, p: [f64; 3]) -> (f64, u32) {
        (self.root.distance2(p)[0], self.root_word)
    }

    /// What the child word `word` names (`None` for a word out of range).
    #[inline]
    pub(super) fn kid(&self, word: u32) -> Option<Kid<'_>> {
        if word & CLUSTER != 0 {
            let &(first, count) = self.clusters.get((word & !CLUSTER) as usize)?;
            self.tris.get(first as usize..first as usize + count as usize).map(Kid::Cluster)
        } else {
            self.nodes.get(word as usize).map(Kid::Node)
        }
    }

    /// Asks the processor to start reading what `word` names (its first cache lines),
    /// which a search will likely open soon.
    #[inline(always)]
    pub(super) fn prefetch(&self, word: u32) {
        #[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
        {
            use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
            let at: Option<*const i8> = if word & CLUSTER != 0 {
                let first = self.clusters.get((word & !CLUSTER) as usize).map(|c| c.0 as usize);
                first.and_then(|f| self.tris.get(f)).map(|t| std::ptr::from_ref(t).cast())
            } else {
                self.nodes.get(word as usize).map(|n| std::ptr::from_ref(n).cast())
            };
            if let Some(at) = at {
                for line in 0..4 {
                    // SAFETY: a prefetch reads nothing architecturally and cannot fault;
                    // SSE (PREFETCHT0) is in every x86-64 target this compiles for.
                    unsafe { _mm_prefetch::<_MM_HINT_T0>(at.wrapping_add(64 * line)) };
                }
            }
        }
    }

    /// The indices of `points` in the order of a Morton curve through the surface's
    /// box (points outside it on its faces), or `None` for fewer than 64 points or
    /// where the memory (12 bytes a point) cannot be had.
    pub(super) fn curve_order(&self, points: &[[f32; 3]]) -> Option<Vec<u32>> {
        let (lo, hi) = ([0, 1, 2].map(|k| self.root.lo[k][0] as f64), [0, 1, 2].map(|k| self.root.hi[k][0] as f64));
        // (An empty surface's box is inverted.)
        if points.len() < 64 || points.len() > u32::MAX as usize || lo[0] > hi[0] {
            return None;
        }
        let scale = [0, 1, 2].map(|k| if hi[k] > lo[k] { 1023.0 / (hi[k] - lo[k]) } else { 0.0 });
        // Ten bits an axis: cells of a thousandth of the box.
        let spread = |x: u64| {
            let mut x = x & 0x3ff;
            x = (x | x << 16) & 0x0300_00ff;
            x = (x | x << 8) & 0x0300_f00f;
            x = (x | x << 4) & 0x030c_30c3;
            (x | x << 2) & 0x0924_9249
        };
        let mut keyed: Vec<(u32, u32)> = try_with_capacity(points.len(), "closest points in curve order").ok()?;
        keyed.extend(points.iter().enumerate().map(|(i, p)| {
            // NaN and the infinities clamp to an end (their answers are None anyway).
            let q = [0, 1, 2].map(|k| ((p[k] as f64 - lo[k]) * scale[k]).clamp(0.0, 1023.0) as u64);
            ((spread(q[0]) | spread(q[1]) << 1 | spread(q[2]) << 2) as u32, i as u32)
        }));
        keyed.par_sort_unstable();
        let mut order: Vec<u32> = try_with_capacity(points.len(), "closest points in curve order").ok()?;
        order.extend(keyed.iter().map(|k| k.1));
        Some(order)
    }

    /// How many nodes and clusters there are (a bound on a search's steps).
    pub(super) fn node_count(&self) -> usize {
        self.nodes.len() + self.clusters.len()
    }

    /// The bound and word of `tris[start..end]`, whose Morton codes agree above bit
    /// `63 - 3 level`; its descendants pushed to `nodes` and `clusters`.
    fn build(&mut self, codes: &[u64], start: usize, end: usize, level: u32) -> (Measured, u32) {
        if end - start <= LEAF {
            let word = CLUSTER | self.clusters.len() as u32;
            self.clusters.push((start as u32, (end - start) as u32));
            let triangles = self.tris[start..end].iter().map(|tri| widen(&tri.t));
            return (measure(triangles), word);
        }
        // The children: the next three bits' groups, the largest of them opened in
        // turn while the node has room, so that nodes are full and the tree shallow.
        let mut groups = split(codes, start, end, level);
        while let Some(at) =
            (0..groups.len()).filter(|&g| groups[g].1 - groups[g].0 > LEAF).max_by_key(|&g| groups[g].1 - groups[g].0)
        {
            let (s, e, l) = groups[at];
            let inner = split(codes, s, e, l);
            if groups.len() - 1 + inner.len() > 8 {
                break;
            }
            groups.splice(at..at + 1, inner);
        }
        let index = self.nodes.len();
        self.nodes.push(Node { bounds: Bounds8::of(&[NodeBound::EMPTY; 8]), kids: [u32::MAX; 8] });
        let mut kids = [(NodeBound::EMPTY, [0.0; 3]); 8];
        let mut words = [u32::MAX; 8];
        for (child, &(s, e, l)) in groups.iter().enumerate() {
            (kids[child], words[child]) = self.build(codes, s, e, l);
        }
        self.nodes[index] = Node { bounds: Bounds8::of(&kids.map(|k| k.0)), kids: words };
        (internal(&kids), index as u32)
    }
}

/// Coordinate `k` of a triangle's centroid.
fn centroid(t: &[f32; TRIANGLE_FLOATS], k: usize) -> f64 {
    (t[k] as f64 + t[3 + k] as f64 + t[6 + k] as f64) / 3.0
}

/// A triangle's vertices in `f64`.
fn widen(t: &[f32; TRIANGLE_FLOATS]) -> [[f64; 3]; 3] {
    [0, 3, 6].map(|o| [t[o] as f64, t[o + 1] as f64, t[o + 2] as f64])
}

/// A node's bound and the (area-weighted, aligned) sum of its surface's normals.
type Measured = (NodeBound, [f64; 3]);

/// A cluster's bound: its triangles' box, and their vertices' slab across their mean
/// normal, kept within the box's reach.
fn measure(triangles: impl Iterator<Item = [[f64; 3]; 3]> + Clone) -> Measured {
    let mut bound = NodeBound::EMPTY;
    let (mut reference, mut largest) = ([0.0; 3], -1.0);
    for t in triangles.clone() {
        for corner in t {
            for k in 0..3 {
                bound.lo[k] = bound.lo[k].min(corner[k] as f32);
                bound.hi[k] = bound.hi[k].max(corner[k] as f32);
            }
        }
        let n = cross(sub(t[1], t[0]), sub(t[2], t[0]));
        if dot(n, n) > largest {
            (reference, largest) = (n, dot(n, n));
        }
    }
    if bound.is_empty() {
        return (NodeBound::EMPTY, [0.0; 3]);
    }
    let mut sum = [0.0; 3];
    for t in triangles.clone() {
        add_aligned(&mut sum, cross(sub(t[1], t[0]), sub(t[2], t[0])), reference);
    }
    let m = direction(sum);
    let (mut s_lo, mut s_hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for t in triangles {
        for x in t {
            let s = dot(m, x);
            let err = 4.0 * U * (m[0].abs() * x[0].abs() + m[1].abs() * x[1].abs() + m[2].abs() * x[2].abs());
            s_lo = s_lo.min(s - err);
            s_hi = s_hi.max(s + err);
        }
    }
    (bound.with_slab(m, s_lo, s_hi), sum)
}

/// An internal node's bound from its children's: the union of their boxes, and the
/// slab across their normals' (aligned) sum `m` holding each child's box-and-slab.
/// A child's surface, across `m`: `m.x = a (m_c.x) + (m - a m_c).x` for any `a`
/// (`a = m.m_c / m_c.m_c`), the first term within the child's slab times `a`, the
/// second within the child box's reach along `m - a m_c` (small where the normals
/// agree); and within its box's reach along `m`.
fn internal(kids: &[Measured; 8]) -> Measured {
    let mut bound = NodeBound::EMPTY;
    let (mut reference, mut largest) = ([0.0; 3], -1.0);
    for (b, n) in kids.iter().filter(|k| !k.0.is_empty()) {
        for k in 0..3 {
            bound.lo[k] = bound.lo[k].min(b.lo[k]);
            bound.hi[k] = bound.hi[k].max(b.hi[k]);
        }
        if dot(*n, *n) > largest {
            (reference, largest) = (*n, dot(*n, *n));
        }
    }
    if bound.is_empty() {
        return (NodeBound::EMPTY, [0.0; 3]);
    }
    let mut sum = [0.0; 3];
    for (_, n) in kids.iter().filter(|k| !k.0.is_empty()) {
        add_aligned(&mut sum, *n, reference);
    }
    let m = direction(sum);
    let (mut s_lo, mut s_hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for (b, _) in kids.iter().filter(|k| !k.0.is_empty()) {
        let (mut lo, mut hi) = b.reach(m);
        let mc = b.m.map(f64::from);
        let a = dot(m, mc) / dot(mc, mc);
        if a.is_finite() {
            let rest = [m[0] - a * mc[0], m[1] - a * mc[1], m[2] - a * mc[2]];
            let (r_lo, r_hi) = b.reach(rest);
            let (c_lo, c_hi) = (a * b.slab[0] as f64, a * b.slab[1] as f64);
            let big = b.lo.iter().chain(&b.hi).fold(0.0f64, |s, &x| s.max((x as f64).abs()));
            let err = 64.0 * U * (1.0 + a.abs()) * (3.0 * big + (b.slab[0] as f64).abs().max(b.slab[1].abs() as f64));
            lo = lo.max(c_lo.min(c_hi) + r_lo - err);
            hi = hi.min(c_lo.max(c_hi) + r_hi + err);
        }
        s_lo = s_lo.min(lo);
        s_hi = s_hi.max(hi);
    }
    (bound.with_slab(m, s_lo, s_hi), sum)
}
