//! The closest-point search's tree: the optional `distance` section, and how it is
//! made (at bake with `bake --distance`, or by the runtime on a scene's first
//! closest-point query when the file has none).
//!
//! The stored triangles (those the octree's leaves list, each once) in the Morton
//! order of their centroids, cut into clusters of at most [`LEAF`] consecutive ones,
//! under nodes of up to eight children; each child bounded by where its surface lies:
//! a box, and a slab across the surface's mean normal ([`Bounds8`]). A search opens
//! nodes nearest first and measures a cluster's triangles, reading their vertices from
//! the triangle array through `prims`.
//!
//! # Words
//! The section is `u32` words (empty when the scene has none):
//!
//! | words | content |
//! | --- | --- |
//! | 4 | `N` nodes, `C` clusters, `T` triangles, 0 |
//! | 96 | the root: a [`Node`] whose child 0 is the whole tree (the others unused) |
//! | `96 N` | the nodes ([`Node`]: eight children's bounds by coordinate, then their words) |
//! | `C + 1` | each cluster's first position in `prims`, then `T` |
//! | `T` | `prims`: stored triangle indices, cluster after cluster |
//!
//! A child word is a cluster's index with [`CLUSTER`] set, a node's index without, or
//! `u32::MAX` for an unused child (whose bound is [`NodeBound::EMPTY`]'s).
//!
//! # Example
//! ```
//! use octrace_format::distance::{self, Kid, Tree};
//! // Two triangles: one cluster under the root.
//! let triangles = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 1.0, 0.0, 1.0, 0.0, 1.0, 1.0];
//! let words = distance::build(&triangles, |_| true)?;
//! let tree = Tree::parse(&words).expect("sizes agree");
//! assert_eq!((tree.nodes.len(), tree.clusters(), tree.prims.len()), (0, 1, 2));
//! assert!(matches!(tree.kid(tree.root.kids[0]), Some(Kid::Cluster(&[0, 1]))));
//! # Ok::<(), octrace_format::memory::AllocError>(())
//! ```

use rayon::prelude::*;

use crate::layout::TRIANGLE_FLOATS;
use crate::memory::{try_with_capacity, AllocError};

/// At most this many triangles a cluster.
pub const LEAF: usize = 8;
/// A child word's bit for a cluster (else an internal node's index).
pub const CLUSTER: u32 = 1 << 31;
/// Words of the section's own header.
pub const HEADER_WORDS: usize = 4;
/// Words a [`Node`] takes.
pub const NODE_WORDS: usize = std::mem::size_of::<Node>() / 4;

/// `f64`'s unit roundoff, `2^-53`.
const U: f64 = 1.0 / (1u64 << 53) as f64;
const INF: f32 = f32::INFINITY;

/// Eight children's bounds side by side, by coordinate (lane `l` is child `l`): the
/// surface in child `l` lies in the box `lo..hi` and in the slab
/// `slab[0] <= m.x <= slab[1]`. An unused child's box is inverted (`+inf..-inf`).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Bounds8 {
    /// The boxes' low corners.
    pub lo: [[f32; 8]; 3],
    /// The boxes' high corners.
    pub hi: [[f32; 8]; 3],
    /// The slabs' directions (unit, as `f32`).
    pub m: [[f32; 8]; 3],
    /// The slabs' low and high ends.
    pub slab: [[f32; 8]; 2],
}

/// An internal node: its children's bounds, then their words.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Node {
    /// The children's bounds.
    pub bounds: Bounds8,
    /// The children's words ([`CLUSTER`] | cluster, node, or `u32::MAX` unused).
    pub kids: [u32; 8],
}

const _: () = assert!(NODE_WORDS == 96);

/// The tree borrowed from its words (the section's, or [`build`]'s).
#[derive(Clone, Copy, Debug)]
pub struct Tree<'a> {
    /// The root: child 0 is the whole tree.
    pub root: &'a Node,
    /// The internal nodes.
    pub nodes: &'a [Node],
    /// Each cluster's first position in `prims`, then `prims.len()`.
    pub firsts: &'a [u32],
    /// Stored triangle indices, cluster after cluster.
    pub prims: &'a [u32],
}

/// What a child word names.
#[derive(Clone, Copy, Debug)]
pub enum Kid<'a> {
    /// A cluster: its triangles' stored indices.
    Cluster(&'a [u32]),
    /// An internal node.
    Node(&'a Node),
}

impl<'a> Tree<'a> {
    /// The tree in `words`, or `None` where their sizes disagree (or there are none).
    /// Only the sizes are checked: [`crate::SceneView::validate`] checks the rest, and
    /// [`Tree::kid`] answers `None` for a word out of range.
    pub fn parse(words: &'a [u32]) -> Option<Tree<'a>> {
        let head = words.get(..HEADER_WORDS)?;
        let (n, c, t) = (head[0] as usize, head[1] as usize, head[2] as usize);
        let node_words = n.checked_add(1)?.checked_mul(NODE_WORDS)?;
        let len = HEADER_WORDS.checked_add(node_words)?.checked_add(c.checked_add(1)?)?.checked_add(t)?;
        if len != words.len() {
            return None;
        }
        let (nodes, rest) = words[HEADER_WORDS..].split_at(node_words);
        let (firsts, prims) = rest.split_at(c + 1);
        let nodes: &[Node] = bytemuck::try_cast_slice(nodes).ok()?;
        Some(Tree { root: &nodes[0], nodes: &nodes[1..], firsts, prims })
    }

    /// The number of clusters.
    pub fn clusters(&self) -> usize {
        self.firsts.len() - 1
    }

    /// What the child word `word` names (`None` for a word out of range, or a
    /// cluster whose range is not within `prims`).
    #[inline]
    pub fn kid(&self, word: u32) -> Option<Kid<'a>> {
        if word & CLUSTER != 0 {
            let c = (word & !CLUSTER) as usize;
            let (first, end) = (*self.firsts.get(c)?, *self.firsts.get(c + 1)?);
            self.prims.get(first as usize..end as usize).map(Kid::Cluster)
        } else {
            self.nodes.get(word as usize).map(Kid::Node)
        }
    }
}

/// Where the surface inside a node lies, while the tree is made: in a box, and in a
/// slab across a direction `m` (`slab[0] <= m.x <= slab[1]` for every point `x` of it).
/// The slab follows the surface's mean normal, so it is thin where the surface is
/// flat: a point beside a flat piece of surface is as far from it as the plane and
/// the box's reach along the plane allow, where a box alone (tilted surface) would be
/// much nearer.
#[derive(Clone, Copy, Debug)]
pub struct NodeBound {
    lo: [f32; 3],
    hi: [f32; 3],
    m: [f32; 3],
    slab: [f32; 2],
}

impl NodeBound {
    /// No surface.
    pub const EMPTY: NodeBound = NodeBound { lo: [INF; 3], hi: [-INF; 3], m: [1.0, 0.0, 0.0], slab: [INF, -INF] };

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

impl Bounds8 {
    /// Eight bounds side by side.
    pub fn of(b: &[NodeBound; 8]) -> Bounds8 {
        // An empty child (or one whose box is NaN) reads as the empty bound.
        let b = b.map(|b| if b.is_empty() { NodeBound::EMPTY } else { b });
        Bounds8 {
            lo: [0, 1, 2].map(|k| b.map(|b| b.lo[k])),
            hi: [0, 1, 2].map(|k| b.map(|b| b.hi[k])),
            m: [0, 1, 2].map(|k| b.map(|b| b.m[k])),
            slab: [0, 1].map(|k| b.map(|b| b.slab[k])),
        }
    }
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

/// `x` rounded to an `f32` at most `x` (NaN stays NaN).
pub(crate) fn down(x: f64) -> f32 {
    let f = x as f32;
    if f as f64 > x {
        f.next_down()
    } else {
        f
    }
}

/// `x` rounded to an `f32` at least `x` (NaN stays NaN).
pub(crate) fn up(x: f64) -> f32 {
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

/// The 63-bit Morton code of `g` in the box `lo..hi` (21 bits an axis).
pub fn morton(g: [f64; 3], lo: [f64; 3], hi: [f64; 3]) -> u64 {
    let mut code = 0u64;
    let cells = (1u64 << 21) as f64;
    let q = [0, 1, 2].map(|k| {
        let span = hi[k] - lo[k];
        let f = if span > 0.0 { (g[k] - lo[k]) / span } else { 0.0 };
        ((f * cells) as u64).min((1 << 21) - 1)
    });
    for bit in (0..21).rev() {
        for axis in q {
            code = code << 1 | (axis >> bit) & 1;
        }
    }
    code
}

/// The ranges of `codes[start..end]` (sorted, more than one) by the first three bits
/// below `63 - 3 level` in which they differ, each with the level of its own next
/// bits; past the codes' last bits (many equal centroids), equal parts. A tree's
/// children (this tree's, and the runtime's winding-number clusters).
pub fn split(codes: &[u64], start: usize, end: usize, level: u32) -> Vec<(usize, usize, u32)> {
    let mut cuts = Vec::with_capacity(9);
    let mut level = level;
    while level < 21 {
        let shift = 60 - 3 * level;
        cuts.clear();
        cuts.push(start);
        for digit in 1..8u64 {
            let at = start + codes[start..end].partition_point(|&c| (c >> shift) & 7 < digit);
            if at > *cuts.last().unwrap_or(&start) && at < end {
                cuts.push(at);
            }
        }
        cuts.push(end);
        if cuts.len() > 2 {
            break;
        }
        level += 1;
    }
    if level >= 21 {
        cuts.clear();
        let step = (end - start).div_ceil(8).max(1);
        cuts.extend((start..end).step_by(step));
        cuts.push(end);
    }
    cuts.windows(2).map(|w| (w[0], w[1], level + 1)).collect()
}

/// Stored triangle `i`'s vertices (of the nine-`f32` array `triangles`), if there.
fn vertices(triangles: &[f32], i: usize) -> Option<[[f64; 3]; 3]> {
    let t = triangles.get(i * TRIANGLE_FLOATS..(i + 1) * TRIANGLE_FLOATS)?;
    Some([0, 3, 6].map(|o| [t[o] as f64, t[o + 1] as f64, t[o + 2] as f64]))
}

fn centroid(v: &[[f64; 3]; 3]) -> [f64; 3] {
    [0, 1, 2].map(|k| (v[0][k] + v[1][k] + v[2][k]) / 3.0)
}

/// The tree of the stored triangles `triangles` (nine `f32` each) for which `listed`
/// holds, as the section's words. About 24 bytes a triangle (the nodes 19, `prims` 4,
/// the clusters' starts 1), and 16 more while it is made (the Morton codes sorted
/// with the indices).
///
/// # Errors
/// [`AllocError`] where the memory cannot be had.
pub fn build(triangles: &[f32], listed: impl Fn(usize) -> bool + Sync) -> Result<Vec<u32>, AllocError> {
    let count = triangles.len() / TRIANGLE_FLOATS;
    let kept = |i: usize| listed(i).then(|| vertices(triangles, i)).flatten();
    let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    for v in (0..count).filter_map(kept) {
        let g = centroid(&v);
        for k in 0..3 {
            lo[k] = lo[k].min(g[k]);
            hi[k] = hi[k].max(g[k]);
        }
    }
    // Morton order of the centroids, in their box: the codes sorted with the
    // triangles' indices.
    let n = (0..count).filter(|&i| kept(i).is_some()).count();
    let mut keyed: Vec<(u64, u32)> = try_with_capacity(n, "the distance tree's Morton codes")?;
    keyed.extend((0..count).filter_map(|i| kept(i).map(|v| (morton(centroid(&v), lo, hi), i as u32))));
    keyed.par_sort_unstable();
    let mut maker = Maker {
        triangles,
        prims: try_with_capacity(n, "the distance tree's triangles")?,
        codes: try_with_capacity(n, "the distance tree's Morton codes")?,
        nodes: Vec::new(),
        firsts: Vec::new(),
    };
    maker.prims.extend(keyed.iter().map(|k| k.1));
    maker.codes.extend(keyed.iter().map(|k| k.0));
    drop(keyed);
    let mut root = Node { bounds: Bounds8::of(&[NodeBound::EMPTY; 8]), kids: [u32::MAX; 8] };
    if n > 0 {
        let ((bound, _), word) = maker.build(0, n, 0)?;
        let mut top = [NodeBound::EMPTY; 8];
        top[0] = bound;
        root.bounds = Bounds8::of(&top);
        root.kids[0] = word;
    }
    maker.firsts.push(n as u32);
    let Maker { prims, nodes, firsts, .. } = maker;
    let len = HEADER_WORDS + NODE_WORDS * (nodes.len() + 1) + firsts.len() + prims.len();
    let mut words: Vec<u32> = try_with_capacity(len, "the distance tree's words")?;
    words.extend([nodes.len() as u32, firsts.len() as u32 - 1, prims.len() as u32, 0]);
    words.extend_from_slice(bytemuck::cast_slice(&[root]));
    words.extend_from_slice(bytemuck::cast_slice(&nodes));
    words.extend_from_slice(&firsts);
    words.extend_from_slice(&prims);
    Ok(words)
}

/// `groups` (consecutive ranges) with each run of neighbours that fit one cluster
/// together made one.
fn merged(groups: Vec<(usize, usize, u32)>) -> Vec<(usize, usize, u32)> {
    let mut out: Vec<(usize, usize, u32)> = Vec::with_capacity(groups.len());
    for g in groups {
        match out.last_mut() {
            Some(last) if g.1 - last.0 <= LEAF => last.1 = g.1,
            _ => out.push(g),
        }
    }
    out
}

/// A node's bound and the (area-weighted, aligned) sum of its surface's normals.
type Measured = (NodeBound, [f64; 3]);

/// The tree as it is made.
struct Maker<'t> {
    triangles: &'t [f32],
    /// Stored indices in Morton order, and their codes.
    prims: Vec<u32>,
    codes: Vec<u64>,
    nodes: Vec<Node>,
    firsts: Vec<u32>,
}

impl Maker<'_> {
    /// The bound and word of `prims[start..end]`, whose Morton codes agree above bit
    /// `63 - 3 level`; its descendants pushed to `nodes` and `firsts`.
    fn build(&mut self, start: usize, end: usize, level: u32) -> Result<(Measured, u32), AllocError> {
        if end - start <= LEAF {
            let word = CLUSTER | self.firsts.len() as u32;
            self.firsts.try_reserve(1).map_err(|_| AllocError { what: "the distance tree's clusters", bytes: 4 })?;
            self.firsts.push(start as u32);
            let triangles = self.prims[start..end].iter().filter_map(|&i| vertices(self.triangles, i as usize));
            return Ok((measure(triangles), word));
        }
        // The children: the next three bits' groups, neighbours that fit one cluster
        // together made one (a surface fills about half of a cube's eighths: clusters
        // would hold 3 triangles, not 6); then the largest group whose own children
        // fit opened in turn, so that nodes are full and the tree shallow.
        let mut groups = merged(split(&self.codes, start, end, level));
        loop {
            let mut big: Vec<usize> = (0..groups.len()).filter(|&g| groups[g].1 - groups[g].0 > LEAF).collect();
            big.sort_by_key(|&g| std::cmp::Reverse(groups[g].1 - groups[g].0));
            let opened = big.into_iter().find_map(|at| {
                let (s, e, l) = groups[at];
                let inner = merged(split(&self.codes, s, e, l));
                (groups.len() - 1 + inner.len() <= 8).then_some((at, inner))
            });
            let Some((at, inner)) = opened else { break };
            groups.splice(at..at + 1, inner);
        }
        let index = self.nodes.len();
        self.nodes
            .try_reserve(1)
            .map_err(|_| AllocError { what: "the distance tree's nodes", bytes: std::mem::size_of::<Node>() as u64 })?;
        self.nodes.push(Node { bounds: Bounds8::of(&[NodeBound::EMPTY; 8]), kids: [u32::MAX; 8] });
        let mut kids = [(NodeBound::EMPTY, [0.0; 3]); 8];
        let mut words = [u32::MAX; 8];
        for (child, &(s, e, l)) in groups.iter().enumerate() {
            (kids[child], words[child]) = self.build(s, e, l)?;
        }
        self.nodes[index] = Node { bounds: Bounds8::of(&kids.map(|k| k.0)), kids: words };
        Ok((internal(&kids), index as u32))
    }
}

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
            let (s, err) = slab_position(m, x);
            s_lo = s_lo.min(s - err);
            s_hi = s_hi.max(s + err);
        }
    }
    (bound.with_slab(m, s_lo, s_hi), sum)
}

/// `m.x` in `f64` and a bound on its rounding error.
fn slab_position(m: [f64; 3], x: [f64; 3]) -> (f64, f64) {
    (dot(m, x), 4.0 * U * (m[0].abs() * x[0].abs() + m[1].abs() * x[1].abs() + m[2].abs() * x[2].abs()))
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

/// Checks `words` as a scene's `distance` section over `triangle_count` stored
/// triangles (see [`crate::SceneView::validate`]): the sizes; every child word in
/// range, every node and cluster reached from the root exactly once (so a search ends,
/// and reaches every cluster); clusters of 1 to [`LEAF`] triangles tiling `prims`;
/// every stored triangle listed once; each cluster's box holding its
/// triangles' vertices and their slab positions, each node's box its children's. An
/// empty section is valid (a scene without one).
pub(crate) fn check(words: &[u32], triangles: &[f32]) -> Result<(), String> {
    if words.is_empty() {
        return Ok(());
    }
    let tree = Tree::parse(words).ok_or_else(|| format!("its sizes disagree with its {} words", words.len()))?;
    let count = triangles.len() / TRIANGLE_FLOATS;
    if tree.prims.len() != count {
        return Err(format!("it lists {} triangles, the scene stores {count}", tree.prims.len()));
    }
    if tree.firsts.first() != Some(&0) || tree.firsts.windows(2).any(|w| w[0] >= w[1] || w[1] - w[0] > LEAF as u32) {
        return Err(format!("its clusters are not runs of 1 to {LEAF} triangles from the first"));
    }
    if tree.firsts.last().map(|&l| l as usize) != Some(tree.prims.len()) {
        return Err("its clusters do not end with its triangles".into());
    }
    let mut seen = vec![false; count];
    for &p in tree.prims {
        match seen.get_mut(p as usize) {
            Some(s) if !*s => *s = true,
            Some(_) => return Err(format!("it lists stored triangle {p} twice")),
            None => return Err(format!("it lists stored triangle {p}, past the {count} stored")),
        }
    }
    drop(seen);
    let (mut nodes_seen, mut clusters_seen) = (vec![false; tree.nodes.len()], vec![false; tree.clusters()]);
    // Each entry: a node's bound lanes to check its children against.
    let mut stack: Vec<&Node> = vec![tree.root];
    if tree.root.kids[1..].iter().any(|&w| w != u32::MAX) {
        return Err("its root has more than one child".into());
    }
    while let Some(node) = stack.pop() {
        for (lane, &word) in node.kids.iter().enumerate() {
            if word == u32::MAX {
                continue;
            }
            let (lo, hi) = ([0, 1, 2].map(|k| node.bounds.lo[k][lane]), [0, 1, 2].map(|k| node.bounds.hi[k][lane]));
            let within = |x: [f32; 3]| (0..3).all(|k| lo[k] <= x[k] && x[k] <= hi[k]);
            let seen = if word & CLUSTER != 0 {
                clusters_seen.get_mut((word & !CLUSTER) as usize)
            } else {
                nodes_seen.get_mut(word as usize)
            };
            match seen {
                Some(s) if !*s => *s = true,
                Some(_) => return Err(format!("child word {word:#x} is reached twice")),
                None => return Err(format!("child word {word:#x} is out of range")),
            }
            match tree.kid(word) {
                Some(Kid::Cluster(prims)) => {
                    let m = [0, 1, 2].map(|k| node.bounds.m[k][lane] as f64);
                    let slab = [0, 1].map(|k| node.bounds.slab[k][lane] as f64);
                    for &p in prims {
                        let v = vertices(triangles, p as usize).unwrap_or([[f64::NAN; 3]; 3]);
                        for x in v {
                            let (s, err) = slab_position(m, x);
                            if !within(x.map(|c| c as f32)) || s + err < slab[0] || s - err > slab[1] {
                                return Err(format!("cluster {} does not hold stored triangle {p}", word & !CLUSTER));
                            }
                        }
                    }
                }
                Some(Kid::Node(child)) => {
                    for l in (0..8).filter(|&l| child.kids[l] != u32::MAX) {
                        let (clo, chi) =
                            ([0, 1, 2].map(|k| child.bounds.lo[k][l]), [0, 1, 2].map(|k| child.bounds.hi[k][l]));
                        if !within(clo) || !within(chi) {
                            return Err(format!("node {word}'s box does not hold its child {l}'s"));
                        }
                    }
                    stack.push(child);
                }
                None => return Err(format!("child word {word:#x} is out of range")),
            }
        }
    }
    if let Some(n) = nodes_seen.iter().position(|s| !s) {
        return Err(format!("node {n} is not reached from the root"));
    }
    if let Some(c) = clusters_seen.iter().position(|s| !s) {
        return Err(format!("cluster {c} is not reached from the root"));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A grid of `n x n` squares (two triangles each) on the plane `z = 0`.
    fn grid(n: usize) -> Vec<f32> {
        let mut t = Vec::new();
        for i in 0..n {
            for j in 0..n {
                let (x, y) = (i as f32, j as f32);
                t.extend([x, y, 0.0, x + 1.0, y, 0.0, x, y + 1.0, 0.0]);
                t.extend([x + 1.0, y, 0.0, x + 1.0, y + 1.0, 0.0, x, y + 1.0, 0.0]);
            }
        }
        t
    }

    #[test]
    fn every_listed_triangle_is_in_one_cluster_and_checks() {
        let t = grid(20);
        let words = build(&t, |i| i % 7 != 3).unwrap();
        assert!(check(&words, &t).unwrap_err().contains("the scene stores 800"));
        check(&build(&t, |_| true).unwrap(), &t).unwrap();
        let tree = Tree::parse(&words).unwrap();
        let mut listed: Vec<u32> = tree.prims.to_vec();
        listed.sort_unstable();
        assert_eq!(listed, (0..800).filter(|i| i % 7 != 3).collect::<Vec<u32>>());
        assert!(tree.firsts.windows(2).all(|w| w[1] - w[0] <= LEAF as u32));
        // Well under the triangles' own 36 bytes (a flat grid fills its nodes half).
        assert!(words.len() * 4 < 40 * listed.len(), "{} words", words.len());
    }

    #[test]
    fn an_empty_surface_has_a_root_and_no_cluster() {
        let words = build(&grid(2), |_| false).unwrap();
        let tree = Tree::parse(&words).unwrap();
        assert_eq!((tree.nodes.len(), tree.clusters(), tree.root.kids[0]), (0, 0, u32::MAX));
        check(&words, &[]).unwrap();
    }

    #[test]
    fn damaged_words_are_named() {
        let t = grid(10);
        let words = build(&t, |_| true).unwrap();
        let damage = |at: usize, value: u32| {
            let mut w = words.clone();
            w[at] = value;
            check(&w, &t).unwrap_err()
        };
        let tree = Tree::parse(&words).unwrap();
        let prims_at = words.len() - tree.prims.len();
        let kids_at = HEADER_WORDS + 88;
        assert!(damage(0, 5).contains("sizes"));
        assert!(damage(prims_at, tree.prims[1]).contains("twice"));
        assert!(damage(prims_at, 10_000).contains("past the"));
        assert!(damage(kids_at, 12345).contains("out of range"));
        // A box that no longer holds its triangles.
        assert!(damage(HEADER_WORDS, 50f32.to_bits()).contains("does not hold"));
        assert!(Tree::parse(&words[..words.len() - 1]).is_none());
        assert!(Tree::parse(&[]).is_none());
    }
}
