//! Where the surface lies inside each node of the point-location tree: the closest-point
//! search's lower bounds.

use octrace_format::layout::{NodeRef, TRIANGLE_FLOATS};

use super::{cross, dot, sub, U};
use crate::cpu::tracer::Tracer;

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

    /// A lower bound on the squared distance from `p` to the surface in the node
    /// (infinity where it holds none): the larger of the box's and the slab's. For `x`
    /// in both, `|p - x|^2 = (m.(p - x))^2 / m.m + |P(p - x)|^2` (`P` the projection
    /// across `m`): the first is at least the squared gap between `m.p` and the slab,
    /// the second at least `|P(p - c)| - R` squared (`c` the box's centre, `R` its half
    /// diagonal). Each term shrunk by its rounding.
    /// Past `enough` (the nearest surface found so far) a part of it is answered as
    /// soon as it is past: the box's, or the gap across the slab's.
    #[inline]
    pub(super) fn distance2(&self, p: [f64; 3], enough: f64) -> f64 {
        if self.is_empty() {
            return f64::INFINITY;
        }
        let (mut boxed, mut r2) = (0.0, 0.0);
        let mut c = [0.0; 3];
        for k in 0..3 {
            let (lo, hi) = (self.lo[k] as f64, self.hi[k] as f64);
            let gap = (lo - p[k]).max(p[k] - hi).max(0.0);
            boxed += gap * gap;
            c[k] = 0.5 * (lo + hi);
            r2 += 0.25 * (hi - lo) * (hi - lo);
        }
        if boxed > enough {
            return boxed;
        }
        let m = [self.m[0] as f64, self.m[1] as f64, self.m[2] as f64];
        let mm = dot(m, m);
        let s = dot(m, p);
        let s_err = 4.0 * U * (m[0].abs() * p[0].abs() + m[1].abs() * p[1].abs() + m[2].abs() * p[2].abs());
        let gap = ((self.slab[0] as f64 - s).max(s - self.slab[1] as f64) - s_err).max(0.0);
        let across = gap * gap / mm * (1.0 - 16.0 * U);
        if across > enough {
            return boxed.max(across);
        }
        let w = sub(p, c);
        let along = dot(m, w) / mm;
        let perp = [w[0] - m[0] * along, w[1] - m[1] * along, w[2] - m[2] * along];
        let w_len = dot(w, w).sqrt();
        let lateral = (dot(perp, perp).sqrt() - r2.sqrt() * (1.0 + 4.0 * U) - 16.0 * U * w_len).max(0.0);
        let disk = (gap * gap / mm + lateral * lateral) * (1.0 - 16.0 * U);
        boxed.max(disk)
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

/// The bound of each node of the point-location tree: an internal node's eight
/// children's side by side (what the search reads when it opens the node), and the
/// root's. Empty leaves have empty bounds, so the search never opens them. Made once
/// a scene from its leaves and triangles ([`crate::Scene`] keeps it).
#[derive(Clone, Debug)]
pub struct SurfaceBounds {
    root: NodeBound,
    /// By internal node index, its children's.
    children: Vec<[NodeBound; 8]>,
}

/// A node's bound and the (area-weighted, aligned) sum of its surface's normals.
type Measured = (NodeBound, [f64; 3]);

impl SurfaceBounds {
    /// The bounds of `tracer`'s scene.
    pub fn of(tracer: &Tracer<'_>) -> SurfaceBounds {
        let v = tracer.view();
        let internal = v.nodes.len() / 8;
        let mut bounds = SurfaceBounds { root: NodeBound::EMPTY, children: vec![[NodeBound::EMPTY; 8]; internal] };
        // Each internal node's own bound once done (or under way: a hostile file's
        // cycle reads it as empty); leaves are measured once.
        let mut nodes: Vec<Option<Measured>> = vec![None; internal];
        let mut leaves: Vec<Option<Measured>> = vec![None; v.leaf_count()];
        let (root, _) = bounds.visit(tracer, v.root, 0, [0; 3], &mut nodes, &mut leaves);
        bounds.root = root;
        bounds
    }

    /// The root's bound.
    #[inline]
    pub(super) fn root(&self) -> &NodeBound {
        &self.root
    }

    /// The bounds of internal node `index`'s children.
    #[inline]
    pub(super) fn children(&self, index: u32) -> Option<&[NodeBound; 8]> {
        self.children.get(index as usize)
    }

    /// How many nodes there are (a bound on a search's steps).
    pub(super) fn node_count(&self) -> usize {
        self.children.len() * 9 + 1
    }

    fn visit(
        &mut self,
        tracer: &Tracer<'_>,
        word: u32,
        level: u32,
        cell: [u32; 3],
        nodes: &mut [Option<Measured>],
        leaves: &mut [Option<Measured>],
    ) -> Measured {
        let empty = (NodeBound::EMPTY, [0.0; 3]);
        match NodeRef::decode(word) {
            NodeRef::Leaf(address) => {
                let v = tracer.view();
                let Some(rec) = v.octree.get(address as usize..address as usize + 3) else { return empty };
                let b = rec[2] as usize;
                match leaves.get(b) {
                    None => return empty,
                    Some(Some(done)) => return *done,
                    Some(None) => {}
                }
                let refs = v.tri_refs.get(rec[1] as usize..rec[1] as usize + rec[0] as usize).unwrap_or_default();
                let (lo, hi) = tracer.cell_box(level, cell);
                let measured = leaf(v, refs, lo, hi);
                leaves[b] = Some(measured);
                measured
            }
            NodeRef::Internal(i) => {
                let i = i as usize;
                if i >= nodes.len() || level >= tracer.frame.max_depth {
                    return empty;
                }
                if let Some(done) = nodes[i] {
                    return done;
                }
                nodes[i] = Some(empty);
                let v = tracer.view();
                let mut kids = [empty; 8];
                for (child, kid) in kids.iter_mut().enumerate() {
                    let Some(&w) = v.nodes.get(8 * i + child) else { continue };
                    let c = [0, 1, 2].map(|k| cell[k] * 2 + ((child >> k) & 1) as u32);
                    *kid = self.visit(tracer, w, level + 1, c, nodes, leaves);
                }
                self.children[i] = kids.map(|k| k.0);
                let measured = internal(&kids);
                nodes[i] = Some(measured);
                measured
            }
        }
    }
}

/// A leaf's bound: its triangles' boxes clipped to its cell (`lo`, `hi`, rounded
/// outwards), and their vertices' slab across their mean normal, clipped to the box's
/// reach.
fn leaf(v: &octrace_format::SceneView<'_>, refs: &[u32], lo: [f32; 3], hi: [f32; 3]) -> Measured {
    let triangle = |prim: u32| {
        v.triangles
            .get(prim as usize * TRIANGLE_FLOATS..)
            .and_then(|t| t.get(..TRIANGLE_FLOATS))
            .map(|t| [0, 3, 6].map(|o| [t[o] as f64, t[o + 1] as f64, t[o + 2] as f64]))
    };
    let mut bound = NodeBound::EMPTY;
    let (mut reference, mut largest) = ([0.0; 3], -1.0);
    for t in refs.iter().filter_map(|&prim| triangle(prim)) {
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
    for k in 0..3 {
        bound.lo[k] = bound.lo[k].max(lo[k]);
        bound.hi[k] = bound.hi[k].min(hi[k]);
    }
    if bound.is_empty() {
        return (NodeBound::EMPTY, [0.0; 3]);
    }
    let mut sum = [0.0; 3];
    for t in refs.iter().filter_map(|&prim| triangle(prim)) {
        add_aligned(&mut sum, cross(sub(t[1], t[0]), sub(t[2], t[0])), reference);
    }
    let m = direction(sum);
    let (mut s_lo, mut s_hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for t in refs.iter().filter_map(|&prim| triangle(prim)) {
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
