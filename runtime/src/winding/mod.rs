//! Generalized winding numbers (Jacobson et al. 2013) of any triangle mesh, fast
//! (Barill et al. 2018) and within a stated bound.
//!
//! The winding number of a point is the signed solid angle the surface subtends at it,
//! over `4 pi`: 1 inside a closed mesh whose triangles wind counter-clockwise seen from
//! outside, 0 outside, and in between, smoothly, where the surface has holes, so
//! `w > 1/2` says inside for meshes that are not closed (libigl's rule).
//!
//! # How
//! The triangles are grouped by the Morton order of their centroids into a tree of
//! clusters (at most [`LEAF`] triangles a leaf, eight children a node). Each cluster
//! keeps its centre `c` (the area-weighted centroid), a radius `r` (every point of its
//! triangles lies within `r` of `c`), its area `A`, and the first two moments of its
//! area vectors `a_t` (half the cross product of the edges, counter-clockwise):
//! `N = sum a_t` and `M = sum a_t (g_t - c)^T` (`g_t` a triangle's centroid). A
//! triangle's solid angle is `integral over T of n.(x - p) / |x - p|^3 dA`; expanded
//! about `c` to first order in `x - c`, a cluster's is
//! `N.y / R^3 + tr M / R^3 - 3 y^T M y / R^5` (`y = c - p`, `R = |y|`): the dipole
//! and its correction, exact for the linear term because `n` is constant on each
//! triangle and `integral over T of (x - c) dA = A_t (g_t - c)`.
//!
//! # The bound
//! The integrand is `-D_n phi` with `phi(x) = 1 / |x - p|`; the remainder of its
//! first-order expansion is `1/2 D^3 phi(xi)[u, u, n] |x - c|^2`. A `k`-th directional
//! derivative of `phi` in one unit direction is `k! P_k(cos t) / |y|^(k+1)`, at most
//! `k! / |y|^(k+1)` (Legendre polynomials are bounded by 1), and by Banach's theorem on
//! symmetric forms the same bound holds for mixed directions. So a cluster's error is
//! at most `3 A r^2 / (R - r)^4` (for `R > r`; over `4 pi` for the winding number).
//! A query refines the clusters with the largest bounds first (leaves summed
//! triangle by triangle, with the exact formula of Van Oosterom and Strackee) until
//! the bounds of those left add up to at most the tolerance. So the answer is within
//! the tolerance of the winding number of the stored triangles, up to `f64` rounding
//! (some `1e-15` of each term, far below any useful tolerance) everywhere but on the
//! surface, where the winding number jumps and is not defined.
//!
//! # The fast rule
//! Barill et al.'s rule (a cluster farther than `beta` times its radius by its
//! expansion, a nearer one opened) evaluates a node's children eight at a time in
//! `f32` (`fast`: AVX2 and fused multiply-adds where the processor has them), their
//! rounding added to the bound; near leaves' triangles eight at a time in `f32` too,
//! each bounded, and in `f64` where that bound is too large. A batch walks two points
//! at a time, taking turns, so that one walk's arithmetic fills the other's waits.

use std::collections::BinaryHeap;

use rayon::prelude::*;

use octrace_format::distance::{morton, split};
use octrace_format::memory::{try_with_capacity, AllocError};

use crate::cpu::{cross, dot, sub};

mod fast;

/// At most this many triangles a leaf cluster.
pub const LEAF: usize = 16;

/// A cluster of triangles: a leaf (its triangles) or a node (its children).
#[derive(Clone, Copy, Debug)]
struct Cluster {
    centre: [f64; 3],
    /// Every point of the cluster's triangles lies within this of the centre.
    radius: f64,
    /// The triangles' total area.
    area: f64,
    /// The sum of the area vectors.
    n: [f64; 3],
    /// `sum a_t (g_t - c)^T`, by rows: `integral of n (x - c)^T dA`.
    m: [[f64; 3]; 3],
    /// `integral of n_i (x - c)(x - c)^T dA` for each `i`, symmetric: `xx yy zz xy xz yz`.
    t: [[f64; 6]; 3],
    /// First child (in `nodes`) or first triangle (in `triangles`), and how many.
    first: u32,
    count: u32,
    leaf: bool,
}

/// A mesh's triangles grouped for fast winding numbers ([`WindingTree::winding_number`]).
///
/// # Example
/// ```
/// use octrace_runtime::winding::WindingTree;
/// // A tetrahedron, counter-clockwise seen from outside.
/// let v = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
/// let faces = [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]];
/// let tree = WindingTree::new(faces.iter().map(|f| f.map(|i| v[i])).collect())?;
/// let inside = tree.winding_number([0.1, 0.1, 0.1], 1e-6);
/// assert!((inside.value - 1.0).abs() <= inside.bound + 1e-12 && inside.bound <= 1e-6);
/// assert!(tree.winding_number([2.0, 2.0, 2.0], 1e-6).value.abs() < 1e-6);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
#[derive(Clone, Debug)]
pub struct WindingTree {
    nodes: Vec<Cluster>,
    /// The triangles, in the leaves' order.
    triangles: Vec<[[f32; 3]; 3]>,
    root: Option<Cluster>,
    /// The nodes' children eight at a time in `f32`, for Barill's rule
    /// ([`fast`]); `None` where the scale would not keep `f32`'s precision.
    groups: Option<fast::Groups>,
}

/// A winding number and a bound on its error ([`WindingTree::winding_number`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Winding {
    /// The winding number.
    pub value: f64,
    /// The exact winding number of the triangles lies within this of `value` (up to
    /// `f64` rounding); 0 where every triangle was summed one by one.
    pub bound: f64,
}

fn wide(p: [f32; 3]) -> [f64; 3] {
    p.map(f64::from)
}

/// The signed solid angle triangle `t` subtends at `p` (Van Oosterom and Strackee):
/// positive seen from behind (where the triangle's vertices turn clockwise).
#[inline]
pub fn solid_angle(p: [f64; 3], t: &[[f32; 3]; 3]) -> f64 {
    let a = sub(wide(t[0]), p);
    let b = sub(wide(t[1]), p);
    let c = sub(wide(t[2]), p);
    let (la, lb, lc) = (dot(a, a).sqrt(), dot(b, b).sqrt(), dot(c, c).sqrt());
    let det = dot(a, cross(b, c));
    let den = la * lb * lc + dot(a, b) * lc + dot(b, c) * la + dot(c, a) * lb;
    2.0 * det.atan2(den)
}

/// A triangle's area vector and centroid.
fn moments(t: &[[f32; 3]; 3]) -> ([f64; 3], [f64; 3]) {
    let v = t.map(wide);
    let n = cross(sub(v[1], v[0]), sub(v[2], v[0])).map(|x| 0.5 * x);
    let g = [0, 1, 2].map(|k| (v[0][k] + v[1][k] + v[2][k]) / 3.0);
    (n, g)
}

fn norm(a: [f64; 3]) -> f64 {
    dot(a, a).sqrt()
}

/// A symmetric 3x3 matrix from its entries' formula, as `xx yy zz xy xz yz`.
fn sym(f: impl Fn(usize, usize) -> f64) -> [f64; 6] {
    [f(0, 0), f(1, 1), f(2, 2), f(0, 1), f(0, 2), f(1, 2)]
}

/// The cluster's radius rounded up past the rounding of its measure.
fn outward(r: f64) -> f64 {
    r * (1.0 + 1e-12) + f64::MIN_POSITIVE
}

impl Cluster {
    /// The centre of mass of `(weight, point)`s (their mean where every weight is 0).
    fn centre_of(items: impl Iterator<Item = (f64, [f64; 3])> + Clone) -> [f64; 3] {
        let (mut w, mut s, mut count, mut plain) = (0.0, [0.0; 3], 0.0f64, [0.0; 3]);
        for (a, g) in items {
            w += a;
            count += 1.0;
            for k in 0..3 {
                s[k] += a * g[k];
                plain[k] += g[k];
            }
        }
        if w > 0.0 && w.is_finite() {
            s.map(|x| x / w)
        } else {
            plain.map(|x| x / count.max(1.0))
        }
    }

    /// A cluster at `centre` with nothing measured yet.
    fn empty(centre: [f64; 3], first: u32, count: u32, leaf: bool) -> Cluster {
        Cluster { centre, radius: 0.0, area: 0.0, n: [0.0; 3], m: [[0.0; 3]; 3], t: [[0.0; 6]; 3], first, count, leaf }
    }

    fn of_triangles(triangles: &[[[f32; 3]; 3]], first: u32) -> Cluster {
        let measured: Vec<([f64; 3], [f64; 3])> = triangles.iter().map(moments).collect();
        let centre = Cluster::centre_of(measured.iter().map(|(n, g)| (norm(*n), *g)));
        let mut c = Cluster::empty(centre, first, triangles.len() as u32, true);
        for (t, (a, g)) in triangles.iter().zip(&measured) {
            let d = t.map(|v| sub(wide(v), *g));
            for v in t {
                c.radius = c.radius.max(norm(sub(wide(*v), centre)));
            }
            let offset = sub(*g, centre);
            c.add_moments(*a, norm(*a), offset);
            // The triangle's second moment about the centre: its centroid's, plus
            // `1/12 sum (v - g)(v - g)^T` (the uniform triangle's covariance).
            let second =
                sym(|j, k| offset[j] * offset[k] + (d[0][j] * d[0][k] + d[1][j] * d[1][k] + d[2][j] * d[2][k]) / 12.0);
            for i in 0..3 {
                for e in 0..6 {
                    c.t[i][e] += a[i] * second[e];
                }
            }
        }
        c.radius = outward(c.radius);
        c
    }

    fn add_moments(&mut self, n: [f64; 3], area: f64, offset: [f64; 3]) {
        self.area += area;
        for i in 0..3 {
            self.n[i] += n[i];
            for j in 0..3 {
                self.m[i][j] += n[i] * offset[j];
            }
        }
    }

    fn of_children(children: &[Cluster], first: u32) -> Cluster {
        let centre = Cluster::centre_of(children.iter().map(|k| (k.area, k.centre)));
        let mut c = Cluster::empty(centre, first, children.len() as u32, false);
        for k in children {
            let d = sub(k.centre, centre);
            c.radius = c.radius.max(norm(d) + k.radius);
            // About the new centre: x - c = (x - c_k) + d.
            for i in 0..3 {
                let moved = sym(|j, l| k.m[i][j] * d[l] + k.m[i][l] * d[j] + k.n[i] * d[j] * d[l]);
                for e in 0..6 {
                    c.t[i][e] += k.t[i][e] + moved[e];
                }
            }
            c.add_moments(k.n, k.area, d);
            for i in 0..3 {
                for j in 0..3 {
                    c.m[i][j] += k.m[i][j];
                }
            }
        }
        c.radius = outward(c.radius);
        c
    }

    /// The cluster's solid angle at `p` by its expansion, and the bound on its error
    /// (infinite where `p` lies within the radius).
    #[inline]
    fn far(&self, p: [f64; 3]) -> (f64, f64) {
        let y = sub(self.centre, p);
        let r2 = dot(y, y);
        let dist = r2.sqrt() * (1.0 - 4.0 * f64::EPSILON);
        if dist <= self.radius || self.area == 0.0 && self.radius == 0.0 && dist == 0.0 {
            return (0.0, f64::INFINITY);
        }
        let inv3 = 1.0 / (r2 * dist);
        let my = [dot(self.m[0], y), dot(self.m[1], y), dot(self.m[2], y)];
        let trace = self.m[0][0] + self.m[1][1] + self.m[2][2];
        let dipole = dot(self.n, y) * inv3;
        let first = trace * inv3 - 3.0 * dot(y, my) * inv3 / r2;
        // (1/2) T_ijk d_j d_k K_i(y), with d_j d_k K_i = -3 (delta_ij y_k + delta_ik y_j
        // + delta_jk y_i) / R^5 + 15 y_i y_j y_k / R^7.
        let t = &self.t;
        let u = [t[0][0] + t[1][3] + t[2][4], t[0][3] + t[1][1] + t[2][5], t[0][4] + t[1][5] + t[2][2]];
        let v = [0, 1, 2].map(|i| t[i][0] + t[i][1] + t[i][2]);
        let yty = [0, 1, 2].map(|i| {
            let t = &t[i];
            t[0] * y[0] * y[0]
                + t[1] * y[1] * y[1]
                + t[2] * y[2] * y[2]
                + 2.0 * (t[3] * y[0] * y[1] + t[4] * y[0] * y[2] + t[5] * y[1] * y[2])
        });
        let inv5 = inv3 / r2;
        let second = 0.5 * (-3.0 * (2.0 * dot(u, y) + dot(v, y)) * inv5 + 15.0 * dot(y, yty) * inv5 / r2);
        let gap = dist - self.radius;
        let r3 = self.radius * self.radius * self.radius;
        let truncation = 4.0 * self.area * r3 / (gap * gap * gap * gap * gap);
        let rounding = 64.0
            * f64::EPSILON
            * (dipole.abs()
                + first.abs()
                + 6.0 * norm(my) * inv3 / dist
                + second.abs()
                + 24.0 * (norm(u) + norm(v)) * inv5 / dist * r2);
        (dipole + first + second, truncation + rounding)
    }
}

/// A node's children: the ranges of `codes[start..end]` its Morton split gives, the
/// largest that fits opened into its own while the node has room for them (at most
/// [`fast::LANES`]). A Morton split alone leaves some 4.8 children a node on the
/// bunny (a surface crosses about half a cell's octants), so the groups' eight lanes
/// ran part empty; opened, 5.6 a node, a fifth fewer nodes, and a query opens fewer
/// groups (1.1x on the bunny's points; joining neighbours small enough for one leaf
/// as well was slower, 0.85x: the joined leaves' radii are larger).
fn children_of(codes: &[u64], start: usize, end: usize, level: u32) -> Vec<(usize, usize, u32)> {
    let mut ranges = split(codes, start, end, level);
    loop {
        let mut inner: Vec<usize> = (0..ranges.len()).filter(|&i| ranges[i].1 - ranges[i].0 > LEAF).collect();
        inner.sort_by_key(|&i| std::cmp::Reverse(ranges[i].1 - ranges[i].0));
        let opened = inner.into_iter().find_map(|i| {
            let (s, e, l) = ranges[i];
            let own = split(codes, s, e, l);
            (ranges.len() + own.len() - 1 <= fast::LANES).then_some((i, own))
        });
        let Some((i, own)) = opened else { return ranges };
        ranges.splice(i..=i, own);
    }
}

/// A cluster waiting to be refined, by its bound.
#[derive(Clone, Copy, Debug)]
struct Open {
    bound: f64,
    value: f64,
    node: u32,
}

impl PartialEq for Open {
    fn eq(&self, other: &Self) -> bool {
        self.bound.total_cmp(&other.bound).is_eq()
    }
}
impl Eq for Open {}
impl PartialOrd for Open {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Open {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.bound.total_cmp(&other.bound)
    }
}

/// A sum of clusters' solid angles and of their bounds.
#[derive(Clone, Copy, Debug, Default)]
struct Sum {
    value: f64,
    bound: f64,
}

impl Sum {
    fn add(&mut self, value: f64, bound: f64) {
        self.value += value;
        self.bound += bound;
    }

    /// The solid angles' sum as a winding number.
    fn winding(self) -> Winding {
        Winding { value: self.value / SPHERE, bound: self.bound / SPHERE }
    }
}

/// Reusable space for queries ([`WindingTree::winding_number_with`]).
#[derive(Debug, Default)]
pub struct WindingScratch {
    heap: BinaryHeap<Open>,
    stack: Vec<u32>,
    /// The groups' walks, [`PAIR`] at a time.
    queues: [Vec<u32>; PAIR],
}

/// Points whose walks through the groups take turns ([`fast::Groups::sum`]).
const PAIR: usize = 2;

/// How near the exact winding number an answer must be.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Accuracy {
    /// Within this of the exact winding number, guaranteed
    /// ([`WindingTree::winding_number`]).
    Within(f64),
    /// Barill et al.'s rule with this `beta` ([`WindingTree::winding_number_beta`]):
    /// fast, no promise.
    Beta(f64),
}

impl Accuracy {
    /// Barill et al.'s (and libigl's) default, `beta = 2`.
    pub const FAST: Accuracy = Accuracy::Beta(2.0);
}

/// `4 pi`: a whole sphere's solid angle.
const SPHERE: f64 = 4.0 * std::f64::consts::PI;

impl WindingTree {
    /// Groups `triangles` (each three vertices, counter-clockwise seen from outside).
    ///
    /// # Errors
    /// Where the tree's memory (about 210 bytes a triangle) cannot be had.
    pub fn new(triangles: Vec<[[f32; 3]; 3]>) -> Result<WindingTree, AllocError> {
        let (lo, hi) = triangles.iter().flatten().fold(([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]), |(lo, hi), v| {
            let v = wide(*v);
            ([0, 1, 2].map(|k| lo[k].min(v[k])), [0, 1, 2].map(|k| hi[k].max(v[k])))
        });
        let mut keyed: Vec<(u64, u32)> = try_with_capacity(triangles.len(), "winding-number clusters")?;
        keyed.extend(triangles.iter().enumerate().map(|(i, t)| (morton(moments(t).1, lo, hi), i as u32)));
        keyed.par_sort_unstable();
        let mut sorted: Vec<[[f32; 3]; 3]> = try_with_capacity(triangles.len(), "winding-number clusters")?;
        sorted.extend(keyed.iter().map(|&(_, i)| triangles[i as usize]));
        drop(triangles);
        let codes: Vec<u64> = keyed.iter().map(|&(k, _)| k).collect();
        drop(keyed);
        let mut tree = WindingTree { nodes: Vec::new(), triangles: Vec::new(), root: None, groups: None };
        if !sorted.is_empty() {
            let root = tree.build(&sorted, &codes, 0, sorted.len(), 0);
            tree.root = Some(root);
        }
        tree.triangles = sorted;
        tree.groups = fast::Groups::of(&tree);
        Ok(tree)
    }

    /// The cluster of `triangles[start..end]`, whose Morton codes agree above bit
    /// `63 - 3 level`; its descendants pushed to `nodes`.
    fn build(&mut self, triangles: &[[[f32; 3]; 3]], codes: &[u64], start: usize, end: usize, level: u32) -> Cluster {
        if end - start <= LEAF {
            return Cluster::of_triangles(&triangles[start..end], start as u32);
        }
        let children: Vec<Cluster> = children_of(codes, start, end, level)
            .into_iter()
            .map(|(s, e, l)| self.build(triangles, codes, s, e, l))
            .collect();
        let first = self.nodes.len() as u32;
        self.nodes.extend_from_slice(&children);
        Cluster::of_children(&children, first)
    }

    /// How many triangles there are.
    pub fn len(&self) -> usize {
        self.triangles.len()
    }

    /// Whether there are no triangles.
    pub fn is_empty(&self) -> bool {
        self.triangles.is_empty()
    }

    /// The bytes the tree takes.
    pub fn bytes(&self) -> usize {
        self.nodes.len() * std::mem::size_of::<Cluster>()
            + self.triangles.len() * 36
            + self.groups.as_ref().map_or(0, fast::Groups::bytes)
    }

    /// The winding number at `p`, within `tolerance` of the exact one of the triangles
    /// ([`Winding::bound`] says by how much at most; 0 sums every triangle). A point
    /// with an infinite coordinate winds 0; one with a NaN answers NaN.
    pub fn winding_number(&self, p: [f32; 3], tolerance: f64) -> Winding {
        self.winding_number_with(&mut WindingScratch::default(), p, tolerance, None)
    }

    /// [`WindingTree::winding_number`] with reusable space; with `decide = Some(t)`
    /// it stops as soon as the bound says on which side of `t` the number lies (or
    /// within `tolerance`).
    pub fn winding_number_with(
        &self,
        scratch: &mut WindingScratch,
        p: [f32; 3],
        tolerance: f64,
        decide: Option<f64>,
    ) -> Winding {
        let Some(root) = self.root else { return Winding { value: 0.0, bound: 0.0 } };
        if let Some(w) = not_finite(p) {
            return w;
        }
        let p = wide(p);
        let tolerance = if tolerance.is_nan() { 0.0 } else { tolerance.max(0.0) } * SPHERE;
        let threshold = decide.map(|t| t * SPHERE);
        // Clusters whose bound is this small are taken as they are.
        let small = tolerance * 1e-3;
        let heap = &mut scratch.heap;
        heap.clear();
        // Clusters summed or taken as they are, and the open ones' sums (those with
        // an infinite bound counted apart).
        let mut settled = Sum::default();
        let mut open = Sum::default();
        let mut unbounded = 0usize;
        let take = |c: &Cluster, node: u32, heap: &mut BinaryHeap<Open>, settled: &mut Sum, open: &mut Sum| {
            let (value, bound) = c.far(p);
            if bound <= small && settled.bound + bound <= 0.5 * tolerance {
                settled.add(value, bound);
                false
            } else {
                heap.push(Open { bound, value, node });
                if bound.is_finite() {
                    open.add(value, bound);
                    false
                } else {
                    true
                }
            }
        };
        unbounded += take(&root, u32::MAX, heap, &mut settled, &mut open) as usize;
        loop {
            while let Some(top) = heap.peek().copied() {
                if unbounded == 0 {
                    let bound = settled.bound + open.bound;
                    if bound <= tolerance {
                        break;
                    }
                    if threshold.is_some_and(|t| (settled.value + open.value - t).abs() > bound * (1.0 + 1e-9)) {
                        break;
                    }
                }
                heap.pop();
                if top.bound.is_finite() {
                    open.add(-top.value, -top.bound);
                } else {
                    unbounded -= 1;
                }
                let c = if top.node == u32::MAX { &root } else { &self.nodes[top.node as usize] };
                let (first, count) = (c.first as usize, c.count as usize);
                if c.leaf {
                    settled.value +=
                        self.triangles[first..first + count].iter().map(|t| solid_angle(p, t)).sum::<f64>();
                    continue;
                }
                for (k, child) in self.nodes[first..first + count].iter().enumerate() {
                    unbounded += take(child, (first + k) as u32, heap, &mut settled, &mut open) as usize;
                }
            }
            // The open sums drift as clusters come and go: count them again, and go on
            // if the true sum of the bounds is still too large.
            open = heap.iter().fold(Sum::default(), |mut s, o| {
                s.add(o.value, o.bound);
                s
            });
            let bound = settled.bound + open.bound;
            let decided = threshold.is_some_and(|t| (settled.value + open.value - t).abs() > bound * (1.0 + 1e-9));
            if heap.is_empty() || bound <= tolerance || decided {
                break;
            }
        }
        Winding { value: (settled.value + open.value) / SPHERE, bound: (settled.bound + open.bound) / SPHERE }
    }

    /// The winding number at `p` by Barill et al.'s rule: a cluster farther than
    /// `beta` times its radius is taken by its expansion, a nearer one opened. Faster
    /// than [`WindingTree::winding_number`] for the same measured error, but with no
    /// promise: [`Winding::bound`] is what the analysis guarantees for the answer (at
    /// `beta = 2`, often more than 1), the expansions' `f32` rounding included.
    /// `beta` below 1 is taken as 1.
    pub fn winding_number_beta(&self, scratch: &mut WindingScratch, p: [f32; 3], beta: f64) -> Winding {
        // The batch's code (fused where the processor fuses): the same answer.
        let mut out = [Winding::default()];
        self.beta_each(scratch, &[p], beta, &mut out);
        out[0]
    }

    /// [`WindingTree::winding_number_beta`] in `f64`, a cluster at a time: for trees
    /// without [`fast::Groups`] (a scale `f32` would lose).
    fn beta_wide(&self, scratch: &mut WindingScratch, p: [f32; 3], beta: f64) -> Winding {
        let Some(root) = self.root else { return Winding { value: 0.0, bound: 0.0 } };
        if let Some(w) = not_finite(p) {
            return w;
        }
        let p = wide(p);
        let beta = beta.max(1.0);
        let beta2 = beta * beta;
        let stack = &mut scratch.stack;
        stack.clear();
        let mut sum = Sum::default();
        let mut visit = |c: &Cluster, stack: &mut Vec<u32>, node: u32| {
            let y = sub(c.centre, p);
            if dot(y, y) > beta2 * c.radius * c.radius {
                let (value, bound) = c.far(p);
                if bound.is_finite() {
                    sum.add(value, bound);
                    return;
                }
            }
            if c.leaf {
                let (first, count) = (c.first as usize, c.count as usize);
                sum.value += self.triangles[first..first + count].iter().map(|t| solid_angle(p, t)).sum::<f64>();
            } else {
                stack.push(node);
            }
        };
        visit(&root, stack, u32::MAX);
        while let Some(node) = stack.pop() {
            let c = if node == u32::MAX { &root } else { &self.nodes[node as usize] };
            let first = c.first as usize;
            for (k, child) in self.nodes[first..first + c.count as usize].iter().enumerate() {
                visit(child, stack, (first + k) as u32);
            }
        }
        sum.winding()
    }

    /// Barill's rule where the root alone answers: a point that is not finite, or far
    /// from the whole tree (`beta >= 1` of its radii, as for every cluster). `None`
    /// where the root's groups are to be walked ([`fast::Groups::sum`]).
    #[inline(always)]
    fn beta_root(&self, root: &Cluster, p: [f32; 3], beta: f64) -> Option<Winding> {
        if let Some(w) = not_finite(p) {
            return Some(w);
        }
        let p = wide(p);
        let y = sub(root.centre, p);
        let beta = beta.max(1.0);
        if dot(y, y) > beta * beta * root.radius * root.radius {
            let (value, bound) = root.far(p);
            if bound.is_finite() {
                return Some(Sum { value, bound }.winding());
            }
        }
        None
    }

    /// The winding number at `p` as `accuracy` asks.
    pub fn winding_number_as(&self, scratch: &mut WindingScratch, p: [f32; 3], accuracy: Accuracy) -> Winding {
        match accuracy {
            Accuracy::Within(tolerance) => self.winding_number_with(scratch, p, tolerance, None),
            Accuracy::Beta(beta) => self.winding_number_beta(scratch, p, beta),
        }
    }

    /// Winding numbers of many points, on all cores.
    ///
    /// The points are taken along a space-filling curve (neighbours share the tree's
    /// clusters in cache), the answers written where their points are.
    pub fn winding_numbers(&self, points: &[[f32; 3]], accuracy: Accuracy, out: &mut [Winding]) {
        let Some(r) = self.root else {
            return self.winding_numbers_as_they_come(points, accuracy, out);
        };
        let (lo, hi) = (r.centre.map(|c| c - r.radius), r.centre.map(|c| c + r.radius));
        crate::cpu::along_curve(lo, hi, points, out, |p, o| self.winding_numbers_as_they_come(p, accuracy, o));
    }

    fn winding_numbers_as_they_come(&self, points: &[[f32; 3]], accuracy: Accuracy, out: &mut [Winding]) {
        points.par_chunks(256).zip(out.par_chunks_mut(256)).for_each(|(p, o)| {
            let mut scratch = WindingScratch::default();
            match accuracy {
                Accuracy::Beta(beta) => self.beta_each(&mut scratch, p, beta, o),
                Accuracy::Within(_) => {
                    for (p, o) in p.iter().zip(o) {
                        *o = self.winding_number_as(&mut scratch, *p, accuracy);
                    }
                }
            }
        });
    }

    /// Barill's rule for each point, on this thread: compiled for x86-64-v3 where the
    /// processor has it (a group's eight lanes in one AVX2 register).
    fn beta_each(&self, scratch: &mut WindingScratch, points: &[[f32; 3]], beta: f64, out: &mut [Winding]) {
        #[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
        if crate::cpu::hw::x86_64_v3() {
            // SAFETY: the processor has the features.
            return unsafe { self.beta_each_v3(scratch, points, beta, out) };
        }
        self.beta_each_loop::<false>(scratch, points, beta, out)
    }

    /// [`WindingTree::beta_each`] compiled for x86-64-v3.
    ///
    /// # Safety
    /// The processor must have the features.
    #[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
    #[target_feature(enable = "avx2,bmi1,bmi2,fma,lzcnt,popcnt")]
    unsafe fn beta_each_v3(&self, scratch: &mut WindingScratch, points: &[[f32; 3]], beta: f64, out: &mut [Winding]) {
        self.beta_each_loop::<true>(scratch, points, beta, out)
    }

    /// Barill's rule for each point, the groups' walks two points at a time
    /// ([`fast::Groups::sum`]; each point's answer as if alone, bit for bit).
    #[inline(always)]
    fn beta_each_loop<const FUSED: bool>(
        &self,
        scratch: &mut WindingScratch,
        points: &[[f32; 3]],
        beta: f64,
        out: &mut [Winding],
    ) {
        let (Some(root), Some(groups)) = (self.root, &self.groups) else {
            for (p, o) in points.iter().zip(out) {
                *o = self.beta_wide(scratch, *p, beta);
            }
            return;
        };
        let queues = &mut scratch.queues;
        let (mut waiting, mut held) = ([(0, [0.0f32; 3]); PAIR], 0);
        for (i, p) in points.iter().enumerate() {
            if let Some(w) = self.beta_root(&root, *p, beta) {
                out[i] = w;
                continue;
            }
            waiting[held] = (i, *p);
            held += 1;
            if held == PAIR {
                let sums = groups.sum::<PAIR, FUSED>(self, queues, waiting.map(|(_, p)| p), beta as f32);
                for ((i, _), sum) in waiting.iter().zip(sums) {
                    out[*i] = sum.winding();
                }
                held = 0;
            }
        }
        for &(i, p) in &waiting[..held] {
            let [sum] = groups.sum::<1, FUSED>(self, std::array::from_mut(&mut queues[0]), [p], beta as f32);
            out[i] = sum.winding();
        }
    }

    /// Whether each point has a winding number above 1/2 (inside, by libigl's rule,
    /// for meshes that are not closed), decided with certainty: each point's clusters
    /// are refined until the bound says on which side of 1/2 its number lies (every
    /// triangle summed, if need be, where it lies within rounding of 1/2). On all cores.
    pub fn inside_batch(&self, points: &[[f32; 3]], out: &mut [bool]) {
        points.par_chunks(256).zip(out.par_chunks_mut(256)).for_each(|(p, o)| {
            let mut scratch = WindingScratch::default();
            for (p, o) in p.iter().zip(o) {
                *o = self.winding_number_with(&mut scratch, *p, 0.0, Some(0.5)).value > 0.5;
            }
        });
    }
}

/// The answer for a point with a coordinate that is not finite: NaN for a NaN; 0,
/// exactly, for a point at infinity (a finite surface subtends no solid angle there).
fn not_finite(p: [f32; 3]) -> Option<Winding> {
    if p.iter().any(|x| x.is_nan()) {
        Some(Winding { value: f64::NAN, bound: f64::NAN })
    } else if p.iter().any(|x| x.is_infinite()) {
        Some(Winding { value: 0.0, bound: 0.0 })
    } else {
        None
    }
}
