//! The seeds' baseline: a bounding volume hierarchy built the four ways of the BVH
//! lecture (seed 001) — object median on the longest axis, middle of the centroid
//! bounds, SAH with a full sweep, SAH over 16 bins — and traversed near child first
//! with the octree's watertight triangle test, so that `octrace report` compares
//! structures, not triangle tests.
//!
//! # Example
//! ```
//! use glam::Vec3;
//! use octrace_runtime::baselines::bvh::{Bvh, BvhBuild};
//! use octrace_runtime::Ray;
//! let mesh = octrace_bake::procedural::sphere([0.0; 3], 1.0, 16, 24);
//! let ids: Vec<u32> = (0..mesh.triangles.len() as u32).collect();
//! let bvh = Bvh::build(&mesh.triangles, &ids, BvhBuild::SahBinned);
//! let (t, _id, _u, _v) = bvh.intersect(&Ray::new(Vec3::new(0.0, 0.0, -5.0), Vec3::Z)).expect("hits");
//! assert!((t - 4.0).abs() < 0.01);
//! assert!(bvh.sah_cost() > 1.0);
//! ```

use crate::cpu::watertight::Shear;
use crate::ray::Ray;

/// How a [`Bvh`] chooses its splits.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BvhBuild {
    /// Half the triangles on each side, by centroid, along the longest axis of the
    /// centroids' bounds.
    Median,
    /// The middle of the centroids' bounds along their longest axis.
    Middle,
    /// The surface area heuristic, every split between sorted centroids on all
    /// three axes.
    SahSweep,
    /// The surface area heuristic over 16 bins of the centroids' bounds per axis.
    SahBinned,
}

impl BvhBuild {
    /// Every build, in the lecture's order.
    pub const ALL: [BvhBuild; 4] = [BvhBuild::Median, BvhBuild::Middle, BvhBuild::SahSweep, BvhBuild::SahBinned];

    /// The build's name in reports.
    pub fn name(self) -> &'static str {
        match self {
            BvhBuild::Median => "median split",
            BvhBuild::Middle => "centroid-middle split",
            BvhBuild::SahSweep => "SAH, full sweep",
            BvhBuild::SahBinned => "SAH, 16 bins",
        }
    }
}

/// A node: a box, and either a leaf's triangle range or an inner node's second child
/// (the first follows it).
#[derive(Clone, Copy, Debug)]
struct Node {
    lo: [f32; 3],
    hi: [f32; 3],
    /// Leaf: first triangle. Inner: index of the second child.
    start: u32,
    /// Leaf: triangles (at least 1). Inner: 0.
    count: u32,
    /// Inner: the split axis.
    axis: u32,
}

/// Triangles a leaf holds at most (the SAH builds stop earlier when a split costs more).
const MAX_LEAF: usize = 4;
/// Cost of a traversal step against a triangle test, for the SAH.
const C_TRAVERSAL: f64 = 1.0;
/// Deepest tree the traversal's stack holds; builds stop splitting there.
const MAX_DEPTH: usize = 60;

/// A bounding volume hierarchy over triangles; see the module docs.
#[derive(Clone, Debug)]
pub struct Bvh {
    nodes: Vec<Node>,
    /// Vertices in leaf order, nine floats a triangle.
    tris: Vec<[f32; 9]>,
    /// The caller's id of each triangle, in leaf order.
    ids: Vec<u32>,
}

struct Builder<'a> {
    bounds: Vec<([f32; 3], [f32; 3])>,
    centroids: Vec<[f32; 3]>,
    build: BvhBuild,
    nodes: &'a mut Vec<Node>,
}

impl Bvh {
    /// Builds over `triangles` (with the caller's `ids`, returned by the queries).
    ///
    /// # Panics
    /// If `ids` and `triangles` differ in length.
    pub fn build(triangles: &[[[f32; 3]; 3]], ids: &[u32], build: BvhBuild) -> Bvh {
        assert_eq!(triangles.len(), ids.len(), "one id a triangle");
        let mut nodes = Vec::with_capacity(2 * triangles.len() / MAX_LEAF + 1);
        let mut order: Vec<u32> = (0..triangles.len() as u32).collect();
        if !triangles.is_empty() {
            let mut b = Builder {
                bounds: triangles.iter().map(tri_bounds).collect(),
                centroids: triangles.iter().map(|t| [0, 1, 2].map(|a| (t[0][a] + t[1][a] + t[2][a]) / 3.0)).collect(),
                build,
                nodes: &mut nodes,
            };
            b.split(&mut order, 0, 0);
        }
        let tris = order.iter().map(|&i| bytemuck::cast(triangles[i as usize])).collect();
        let ids = order.iter().map(|&i| ids[i as usize]).collect();
        Bvh { nodes, tris, ids }
    }

    /// Nodes, inner and leaves.
    pub fn node_count(&self) -> usize {
        self.nodes.len()
    }

    /// The tree's SAH cost: each node's surface area over the root's, times one
    /// traversal step for an inner node or its triangle count for a leaf.
    pub fn sah_cost(&self) -> f64 {
        let Some(root) = self.nodes.first() else { return 0.0 };
        let root_area = area(root.lo, root.hi).max(f64::MIN_POSITIVE);
        self.nodes
            .iter()
            .map(|n| area(n.lo, n.hi) / root_area * if n.count == 0 { C_TRAVERSAL } else { f64::from(n.count) })
            .sum()
    }

    /// The nearest hit in `[tmin, tmax]`: distance, id, barycentrics.
    pub fn intersect(&self, ray: &Ray) -> Option<(f32, u32, f32, f32)> {
        self.walk::<false>(ray)
    }

    /// Whether anything lies on the ray in `[tmin, tmax]`.
    pub fn occluded(&self, ray: &Ray) -> bool {
        self.walk::<true>(ray).is_some()
    }

    fn walk<const ANY: bool>(&self, ray: &Ray) -> Option<(f32, u32, f32, f32)> {
        if self.nodes.is_empty() || !ray.is_traceable() {
            return None;
        }
        // A direction of 1e30 or 1e-40, scaled to unit size (the same hits).
        let (scaled, factor) = ray.unit_scaled();
        if factor != 1.0 {
            return self.walk::<ANY>(&scaled).map(|(t, id, u, v)| ((t as f64 * factor) as f32, id, u, v));
        }
        let o = ray.origin.to_array();
        let d = ray.dir.to_array();
        let inv = d.map(|x| 1.0 / x);
        let shear = Shear::new(o, d);
        let (tmin, mut t_best) = (ray.tmin, ray.tmax);
        let mut best = None;
        let mut stack = [0u32; MAX_DEPTH + 2];
        let mut top = 1;
        while top > 0 {
            top -= 1;
            let node = &self.nodes[stack[top] as usize];
            if !hits_box(node, o, d, inv, tmin, t_best) {
                continue;
            }
            if node.count > 0 {
                let range = node.start as usize..(node.start + node.count) as usize;
                for (tri, &id) in self.tris[range.clone()].iter().zip(&self.ids[range]) {
                    if let Some((t, u, v)) = shear.intersect(tri, tmin, t_best) {
                        t_best = t;
                        best = Some((t, id, u, v));
                        if ANY {
                            return best;
                        }
                    }
                }
                continue;
            }
            // Near child first: the first child holds the low side of the split axis.
            let (first, second) = (stack[top] + 1, node.start);
            let (near, far) = if d[node.axis as usize] < 0.0 { (second, first) } else { (first, second) };
            stack[top] = far;
            stack[top + 1] = near;
            top += 2;
        }
        best
    }
}

impl Builder<'_> {
    /// Builds the node for `order` (triangle indices, reordered in place so that
    /// leaves are contiguous), `first` the position of `order[0]` in the whole order.
    fn split(&mut self, order: &mut [u32], first: usize, depth: usize) -> u32 {
        let index = self.nodes.len() as u32;
        let (lo, hi) = union(order.iter().map(|&i| self.bounds[i as usize]));
        self.nodes.push(Node { lo, hi, start: first as u32, count: order.len() as u32, axis: 0 });
        let (clo, chi) = union(order.iter().map(|&i| (self.centroids[i as usize], self.centroids[i as usize])));
        let extent = [0, 1, 2].map(|a| chi[a] - clo[a]);
        let longest = (0..3).fold(0, |m, a| if extent[a] > extent[m] { a } else { m });
        if order.len() <= 1 || depth >= MAX_DEPTH || extent[longest] <= 0.0 {
            return index;
        }
        let cut = match self.build {
            BvhBuild::Median | BvhBuild::Middle if order.len() <= MAX_LEAF => None,
            BvhBuild::Median => Some(self.median(order, longest)),
            BvhBuild::Middle => {
                let pivot = 0.5 * (clo[longest] + chi[longest]);
                let mid = partition(order, |i| self.centroids[i as usize][longest] < pivot);
                Some((longest, if mid == 0 || mid == order.len() { self.median(order, longest).1 } else { mid }))
            }
            BvhBuild::SahSweep => self.sweep(order, area(lo, hi)),
            BvhBuild::SahBinned => self.binned(order, area(lo, hi), clo, chi),
        };
        let Some((axis, mid)) = cut else { return index };
        let (left, right) = order.split_at_mut(mid);
        self.split(left, first, depth + 1);
        let second = self.split(right, first + mid, depth + 1);
        self.nodes[index as usize] = Node { lo, hi, start: second, count: 0, axis: axis as u32 };
        index
    }

    fn median(&self, order: &mut [u32], axis: usize) -> (usize, usize) {
        let mid = order.len() / 2;
        order.select_nth_unstable_by(mid, |&a, &b| {
            self.centroids[a as usize][axis].total_cmp(&self.centroids[b as usize][axis])
        });
        (axis, mid)
    }

    /// The cheapest split between sorted centroids on any axis, or `None` when a leaf
    /// is cheaper (and small enough).
    fn sweep(&self, order: &mut [u32], node_area: f64) -> Option<(usize, usize)> {
        let n = order.len();
        let mut best = (f64::INFINITY, 0, 0);
        let mut right_areas = vec![0.0; n];
        for axis in 0..3 {
            order.sort_unstable_by(|&a, &b| {
                self.centroids[a as usize][axis].total_cmp(&self.centroids[b as usize][axis])
            });
            let mut acc = empty_box();
            for i in (1..n).rev() {
                acc = grow(acc, self.bounds[order[i] as usize]);
                right_areas[i] = area(acc.0, acc.1);
            }
            let mut acc = empty_box();
            for i in 1..n {
                acc = grow(acc, self.bounds[order[i - 1] as usize]);
                let cost = area(acc.0, acc.1) * i as f64 + right_areas[i] * (n - i) as f64;
                if cost < best.0 {
                    best = (cost, axis, i);
                }
            }
        }
        let (cost, axis, mid) = best;
        if n <= MAX_LEAF && C_TRAVERSAL + cost / node_area.max(f64::MIN_POSITIVE) >= n as f64 {
            return None;
        }
        order.sort_unstable_by(|&a, &b| self.centroids[a as usize][axis].total_cmp(&self.centroids[b as usize][axis]));
        Some((axis, mid))
    }

    /// The cheapest split at a boundary of 16 equal bins of the centroids' bounds.
    fn binned(&self, order: &mut [u32], node_area: f64, clo: [f32; 3], chi: [f32; 3]) -> Option<(usize, usize)> {
        const BINS: usize = 16;
        let n = order.len();
        let bin_of = |i: u32, axis: usize| {
            let c = self.centroids[i as usize][axis];
            let x = (c - clo[axis]) / (chi[axis] - clo[axis]) * BINS as f32;
            (x as usize).min(BINS - 1)
        };
        let mut best = (f64::INFINITY, 0, 0);
        for axis in 0..3 {
            if chi[axis] <= clo[axis] {
                continue;
            }
            let mut boxes = [empty_box(); BINS];
            let mut counts = [0usize; BINS];
            for &i in order.iter() {
                let b = bin_of(i, axis);
                boxes[b] = grow(boxes[b], self.bounds[i as usize]);
                counts[b] += 1;
            }
            let mut right = [(0.0, 0usize); BINS];
            let (mut acc, mut count) = (empty_box(), 0);
            for b in (1..BINS).rev() {
                acc = union([acc, boxes[b]]);
                count += counts[b];
                right[b] = (area(acc.0, acc.1), count);
            }
            let (mut acc, mut count) = (empty_box(), 0);
            for b in 1..BINS {
                acc = union([acc, boxes[b - 1]]);
                count += counts[b - 1];
                if count == 0 || right[b].1 == 0 {
                    continue;
                }
                let cost = area(acc.0, acc.1) * count as f64 + right[b].0 * right[b].1 as f64;
                if cost < best.0 {
                    best = (cost, axis, b);
                }
            }
        }
        let (cost, axis, boundary) = best;
        if !cost.is_finite() || (n <= MAX_LEAF && C_TRAVERSAL + cost / node_area.max(f64::MIN_POSITIVE) >= n as f64) {
            return None;
        }
        let mid = partition(order, |i| bin_of(i, axis) < boundary);
        Some((axis, mid))
    }
}

/// Moves the elements for which `left` holds to the front; returns their count.
fn partition(order: &mut [u32], left: impl Fn(u32) -> bool) -> usize {
    let mut mid = 0;
    for i in 0..order.len() {
        if left(order[i]) {
            order.swap(i, mid);
            mid += 1;
        }
    }
    mid
}

/// A triangle's bounding box.
pub(crate) fn tri_bounds(t: &[[f32; 3]; 3]) -> ([f32; 3], [f32; 3]) {
    let lo = [0, 1, 2].map(|a| t[0][a].min(t[1][a]).min(t[2][a]));
    let hi = [0, 1, 2].map(|a| t[0][a].max(t[1][a]).max(t[2][a]));
    (lo, hi)
}

fn empty_box() -> ([f32; 3], [f32; 3]) {
    ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3])
}

fn grow(a: ([f32; 3], [f32; 3]), b: ([f32; 3], [f32; 3])) -> ([f32; 3], [f32; 3]) {
    ([0, 1, 2].map(|k| a.0[k].min(b.0[k])), [0, 1, 2].map(|k| a.1[k].max(b.1[k])))
}

fn union(boxes: impl IntoIterator<Item = ([f32; 3], [f32; 3])>) -> ([f32; 3], [f32; 3]) {
    boxes.into_iter().fold(empty_box(), grow)
}

/// Surface area (0 for an empty box).
pub(crate) fn area(lo: [f32; 3], hi: [f32; 3]) -> f64 {
    let e = [0, 1, 2].map(|a| f64::from(hi[a] - lo[a]).max(0.0));
    2.0 * (e[0] * e[1] + e[1] * e[2] + e[2] * e[0])
}

/// Whether the ray meets the node's box within `[tmin, tmax]` (slabs). An axis the ray
/// does not move along (a zero component) is the whole line or nothing: its slab
/// distances would be `0 * inf = NaN` for a ray lying in one of the box's planes, and
/// `min` / `max` would then pick the infinity of the other plane and miss the box
/// (rays in the octree's cell planes leaked through the BVH builds that way). A
/// component too small for its inverse (below `2^-128`) moves all the same: its slab
/// distances are divided instead (a subnormal component treated as zero leaked).
#[inline(always)]
fn hits_box(n: &Node, o: [f32; 3], d: [f32; 3], inv: [f32; 3], tmin: f32, tmax: f32) -> bool {
    let (mut t0, mut t1) = (tmin, tmax);
    for a in 0..3 {
        let (ta, tb) = if !inv[a].is_infinite() {
            ((n.lo[a] - o[a]) * inv[a], (n.hi[a] - o[a]) * inv[a])
        } else if d[a] != 0.0 {
            ((n.lo[a] - o[a]) / d[a], (n.hi[a] - o[a]) / d[a])
        } else {
            if o[a] < n.lo[a] || o[a] > n.hi[a] {
                return false;
            }
            continue;
        };
        t0 = t0.max(ta.min(tb));
        t1 = t1.min(ta.max(tb));
    }
    // Boxes are slightly enlarged in effect: a hit on the box's surface counts.
    t0 <= t1 * (1.0 + 4.0 * f32::EPSILON)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::reference::{Agreement, Reference};
    use glam::Vec3;

    /// Every build gives the oracle's answers on a soup and a closed mesh, and the
    /// SAH builds are cheaper by their own measure than the median split.
    #[test]
    fn every_build_agrees_with_the_oracle() {
        let mut mesh = octrace_bake::procedural::soup(3, 1500, 4.0, 0.5);
        mesh.triangles.extend(octrace_bake::procedural::sphere([0.5, 0.2, 0.1], 1.2, 16, 24).triangles);
        let ids: Vec<u32> = (0..mesh.triangles.len() as u32).collect();
        let oracle = Reference::in_input_order(mesh.triangles.clone());
        let mut rng = octrace_bake::procedural::SplitMix(9);
        let rays: Vec<Ray> = (0..3000)
            .map(|_| {
                let o = (Vec3::new(rng.unit(), rng.unit(), rng.unit()) - 0.5) * 10.0;
                let d = Vec3::new(rng.unit(), rng.unit(), rng.unit()) - 0.5;
                Ray::new(o, d)
            })
            .collect();
        let mut costs = Vec::new();
        for build in BvhBuild::ALL {
            let bvh = Bvh::build(&mesh.triangles, &ids, build);
            for r in &rays {
                assert_ne!(oracle.compare(r, bvh.intersect(r)), Agreement::Different, "{build:?} {r:?}");
                assert_eq!(bvh.occluded(r), bvh.intersect(r).is_some(), "{build:?} {r:?}");
            }
            costs.push(bvh.sah_cost());
        }
        assert!(costs[2] < costs[0] && costs[3] < costs[0], "SAH costs {costs:?}");
        let empty = Bvh::build(&[], &[], BvhBuild::SahBinned);
        assert!(empty.intersect(&rays[0]).is_none() && empty.sah_cost() == 0.0);
    }

    /// Rays on the octree's planes and rays aimed at vertices, from inside the closed
    /// solids, never leak through any build (rays in a node box's plane missed the box
    /// before: 3 % of them).
    #[test]
    fn rays_on_cell_planes_never_leak() {
        for build in BvhBuild::ALL {
            let leaks = solid_leaks(|tris, ids| {
                let bvh = Bvh::build(tris, ids, build);
                Box::new(move |r| bvh.intersect(r).is_some() && bvh.occluded(r))
            });
            assert!(leaks.is_empty(), "{build:?}: {} leaks, first {}", leaks.len(), leaks[0]);
        }
    }

    /// Rays from inside the closed solids that leak through a structure: rays on the
    /// octree's planes (`octrace_bake::hard_rays`: in cell planes with `+0.0` and `-0.0`
    /// components, along cell edges, from and through cell corners) and rays aimed at every
    /// vertex and edge midpoint. Shared by the BVH and kd-tree tests.
    pub(crate) fn solid_leaks(
        structure: impl Fn(&[[[f32; 3]; 3]], &[u32]) -> Box<dyn Fn(&Ray) -> bool>,
    ) -> Vec<String> {
        let mut out = Vec::new();
        for solid in octrace_bake::procedural::closed_solids() {
            let baked = octrace_bake::bake(&solid.mesh, &octrace_bake::BuildParams::auto()).unwrap();
            let view = baked.view();
            let tris: Vec<[[f32; 3]; 3]> = view.stored_triangles().collect();
            let hits = structure(&tris, view.triangle_ids);
            let grid = octrace_bake::hard_rays::GridPlanes::of(&view);
            let grid_rays = solid.grid_rays(&grid, 20_000, 3).into_iter().map(|r| (r.origin, r.dir));
            for (o, d) in grid_rays.chain(solid.leak_rays(0, 3)) {
                let ray = Ray::new(glam::Vec3::from(o), glam::Vec3::from(d));
                if !hits(&ray) {
                    out.push(format!("{}: {ray:?}", solid.name));
                }
            }
        }
        out
    }
}
