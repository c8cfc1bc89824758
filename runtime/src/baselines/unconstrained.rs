//! The walk through an octree *without* the 2:1 constraint: the paper's future work
//! ("remove the constraint and measure"), for `octrace report`.
//!
//! Across a face, a leaf of an unconstrained tree can have any number of neighbours:
//! one coarser leaf, one of its size, or any number of finer leaves, several levels
//! down. Each face of a leaf here links to one node (a *rope*, Havran's term): the
//! node of the leaf's level across the face when the tree has it (a leaf or an
//! internal node), else the coarser leaf that covers that cell. The walk leaves a leaf
//! exactly as the constrained walk does (exit face from three Plücker signs, same
//! tables), follows the rope, and, while it stands on an internal node, picks the child
//! on the near side whose quadrant holds the exit point by the same two sign tests
//! against the node face's median lines that pick one of four neighbours in the
//! constrained walk: the constrained walk's neighbour rule, applied once per level.
//! So a step costs one rope load plus two sign tests and one load per level descended,
//! instead of the constrained walk's fixed cost, and the tree has fewer leaves.
//!
//! In memory only (no file format): it exists to be measured against the constrained
//! walk, scalar step against scalar step ([`crate::Tracer::intersect_scalar`]), with the
//! same watertight triangle test.
//!
//! # Example
//! ```
//! use glam::Vec3;
//! use octrace_runtime::baselines::unconstrained::UnconstrainedOctree;
//! use octrace_runtime::Ray;
//! let mesh = octrace_bake::procedural::sphere([0.0; 3], 1.0, 16, 24);
//! let t = octrace_bake::octree::build_unbalanced(&mesh, &octrace_bake::BuildParams::auto())?;
//! let tree = UnconstrainedOctree::build(t.root_lo, t.root_size, &t.leaves, &t.triangles, &t.ids);
//! let (t, _id, _u, _v) = tree.intersect(&Ray::new(Vec3::new(0.0, 0.0, -5.0), Vec3::Z)).expect("hits");
//! assert!((t - 4.0).abs() < 0.01);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use octrace_format::layout::{NodeRef, MAX_LEVEL};

use crate::cpu::tables::{exact_exit, exact_side, exit_code, exit_rule, octant, ExitRule, RuleScale, EXIT_FACE};
use crate::cpu::watertight::Shear;
use crate::cpu::{box_slack, clip, exit_along_moving_axes, point_at, BOX_T_SLACK};
use crate::ray::Ray;

/// A face with nothing across it (the root's boundary).
const NO_ROPE: u32 = u32::MAX - 1;

/// A leaf: its triangles (a range of `refs`), its cell and its six ropes
/// (`NodeRef` words, or [`NO_ROPE`]).
#[derive(Clone, Copy, Debug)]
struct Leaf {
    start: u32,
    count: u32,
    level: u32,
    cell: [u32; 3],
    ropes: [u32; 6],
}

/// An octree without the 2:1 constraint, with ropes; see the module docs.
#[derive(Clone, Debug)]
pub struct UnconstrainedOctree {
    root_lo: [f32; 3],
    root_hi: [f32; 3],
    box_lo: [f32; 3],
    box_hi: [f32; 3],
    /// `2^max_depth / root_size`.
    grid_scale: f64,
    sizes: [f32; 32],
    max_depth: u32,
    max_steps: u32,
    /// Children of each internal node (`NodeRef` words; leaves by ordinal).
    nodes: Vec<[u32; 8]>,
    root: u32,
    leaves: Vec<Leaf>,
    refs: Vec<u32>,
    tris: Vec<[f32; 9]>,
    ids: Vec<u32>,
}

/// What a walk did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct UnconstrainedStats {
    /// Leaves visited.
    pub leaves: u32,
    /// Triangle tests run.
    pub triangle_tests: u32,
    /// Levels descended below a rope's node to reach the next leaf, in all.
    pub descents: u32,
    /// The most levels one step descended: two or more where a neighbour is more
    /// than one level finer, which the 2:1 constraint forbids.
    pub deepest_descent: u32,
}

/// One ray's walk in progress.
struct Walk {
    o: [f32; 3],
    d: [f32; 3],
    inv: [f32; 3],
    high: [u32; 3],
    exits: &'static [u8; 8],
    /// The exit rule (`tables::exit_rule`), as the constrained walk's.
    rule: ExitRule,
    shear: Shear,
    tmin: f32,
    tmax: f32,
    leaf: u32,
    best: Option<(f32, u32, f32, f32)>,
    t_best: f32,
    steps: u32,
}

impl UnconstrainedOctree {
    /// Builds the node tree and the ropes from the leaves of an octree over the root
    /// cube `root_lo`, `root_size`: `(level, cell, triangles)` each, triangles indexing
    /// `triangles`, whose input ids are `ids` (as `octrace_bake::octree::Unbalanced`
    /// holds them).
    ///
    /// # Panics
    /// If the leaves do not tile the root cube exactly (a cell outside its level's
    /// grid, deeper than the format's deepest level, overlapping another, or a hole),
    /// a triangle index is out of range, or `ids` and `triangles` differ in length.
    pub fn build(
        root_lo: [f32; 3],
        root_size: f32,
        leaves: &[(u32, [u32; 3], Vec<u32>)],
        triangles: &[[[f32; 3]; 3]],
        ids: &[u32],
    ) -> UnconstrainedOctree {
        assert_eq!(triangles.len(), ids.len(), "one id a triangle");
        const EMPTY: u32 = u32::MAX;
        // The node tree from the leaves' paths.
        let mut nodes: Vec<[u32; 8]> = Vec::new();
        let mut root = EMPTY;
        let max_depth = leaves.iter().map(|l| l.0).max().unwrap_or(0);
        for (ordinal, &(level, cell, _)) in leaves.iter().enumerate() {
            assert!(
                level <= MAX_LEVEL && cell.iter().all(|&c| c < 1 << level),
                "leaf {ordinal}: cell outside the grid"
            );
            let leaf = NodeRef::Leaf(ordinal as u32).encode();
            if level == 0 {
                assert!(root == EMPTY, "leaf {ordinal} overlaps another");
                root = leaf;
                continue;
            }
            if root == EMPTY {
                nodes.push([EMPTY; 8]);
                root = NodeRef::Internal(0).encode();
            }
            let mut node = root;
            for depth in 0..level {
                let NodeRef::Internal(i) = NodeRef::decode(node) else { panic!("leaf {ordinal} overlaps another") };
                let shift = level - depth - 1;
                let child = (0..3).map(|a| ((cell[a] >> shift) & 1) << a).sum::<u32>() as usize;
                let slot = nodes[i as usize][child];
                if depth + 1 == level {
                    assert!(slot == EMPTY, "leaf {ordinal} overlaps another");
                    nodes[i as usize][child] = leaf;
                } else if slot == EMPTY {
                    nodes.push([EMPTY; 8]);
                    let new = NodeRef::Internal(nodes.len() as u32 - 1).encode();
                    nodes[i as usize][child] = new;
                    node = new;
                } else {
                    node = slot;
                }
            }
        }
        assert!(root != EMPTY && nodes.iter().flatten().all(|&c| c != EMPTY), "the leaves leave a hole");
        let mut tree = UnconstrainedOctree {
            root_lo,
            root_hi: [0.0; 3],
            box_lo: [0.0; 3],
            box_hi: [0.0; 3],
            grid_scale: (1u64 << max_depth) as f64 / root_size as f64,
            sizes: std::array::from_fn(|l| (root_size as f64 / (1u64 << l) as f64) as f32),
            max_depth,
            max_steps: 9 * (1u32 << max_depth.min(26)) + 64,
            nodes,
            root,
            leaves: Vec::with_capacity(leaves.len()),
            refs: Vec::new(),
            tris: triangles.iter().map(|&t| bytemuck::cast(t)).collect(),
            ids: ids.to_vec(),
        };
        let cube = octrace_format::layout::cell_box(root_lo, root_size, 0, [0; 3]);
        tree.root_hi = [cube[3], cube[4], cube[5]];
        let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
        for v in triangles.iter().flatten() {
            for a in 0..3 {
                lo[a] = lo[a].min(v[a]);
                hi[a] = hi[a].max(v[a]);
            }
        }
        let slack = box_slack(root_lo, tree.root_hi, root_size);
        (tree.box_lo, tree.box_hi) = (lo.map(|c| c - slack), hi.map(|c| c + slack));
        for &(level, cell, ref tris) in leaves {
            assert!(tris.iter().all(|&t| (t as usize) < triangles.len()), "triangle index out of range");
            let ropes = std::array::from_fn(|face| tree.rope(level, cell, face));
            tree.leaves.push(Leaf { start: tree.refs.len() as u32, count: tris.len() as u32, level, cell, ropes });
            tree.refs.extend_from_slice(tris);
        }
        tree
    }

    /// The node across `face` of cell `(level, cell)`: of the same level when the
    /// tree has one there, else the coarser leaf covering it.
    fn rope(&self, level: u32, cell: [u32; 3], face: usize) -> u32 {
        let axis = face >> 1;
        let high = face & 1 == 1;
        if (high && cell[axis] == (1 << level) - 1) || (!high && cell[axis] == 0) {
            return NO_ROPE;
        }
        let mut across = cell;
        across[axis] = if high { cell[axis] + 1 } else { cell[axis] - 1 };
        let mut node = self.root;
        for depth in 0..level {
            let NodeRef::Internal(i) = NodeRef::decode(node) else { break };
            let shift = level - depth - 1;
            node = self.nodes[i as usize][(0..3).map(|a| ((across[a] >> shift) & 1) << a).sum::<u32>() as usize];
        }
        node
    }

    /// Leaves.
    pub fn leaf_count(&self) -> usize {
        self.leaves.len()
    }

    /// Triangle references in the leaves.
    pub fn references(&self) -> usize {
        self.refs.len()
    }

    /// Bytes of the structure in memory: nodes, leaves with their ropes, references,
    /// triangles and ids.
    pub fn memory_bytes(&self) -> usize {
        use std::mem::size_of;
        self.nodes.len() * size_of::<[u32; 8]>()
            + self.leaves.len() * size_of::<Leaf>()
            + (self.refs.len() + self.ids.len()) * 4
            + self.tris.len() * size_of::<[f32; 9]>()
    }

    /// The nearest hit in `[tmin, tmax]`: distance, input id, barycentrics.
    pub fn intersect(&self, ray: &Ray) -> Option<(f32, u32, f32, f32)> {
        self.walk::<false>(ray, &mut UnconstrainedStats::default())
    }

    /// Whether anything lies on the ray in `[tmin, tmax]`; stops at the first hit.
    pub fn occluded(&self, ray: &Ray) -> bool {
        self.walk::<true>(ray, &mut UnconstrainedStats::default()).is_some()
    }

    /// [`UnconstrainedOctree::intersect`], counting what the walk did.
    pub fn intersect_with_stats(&self, ray: &Ray) -> (Option<(f32, u32, f32, f32)>, UnconstrainedStats) {
        let mut stats = UnconstrainedStats::default();
        (self.walk::<false>(ray, &mut stats), stats)
    }

    fn walk<const ANY: bool>(&self, ray: &Ray, stats: &mut UnconstrainedStats) -> Option<(f32, u32, f32, f32)> {
        let mut w = self.begin(ray)?;
        while !self.step::<ANY>(&mut w, stats) {}
        w.best.map(|(t, prim, u, v)| (t, self.ids[prim as usize], u, v))
    }

    /// Clips the ray to the root cube and the mesh box and finds its first leaf, as
    /// [`crate::Tracer`] does (point location instead of the cube map).
    fn begin(&self, ray: &Ray) -> Option<Walk> {
        if !ray.is_traceable() {
            return None;
        }
        let o = ray.origin.to_array();
        let d = ray.dir.to_array();
        let (t_enter, t_leave, entry_axis) = clip(o, d, self.root_lo, self.root_hi)?;
        let (box_enter, box_leave, _) = clip(o, d, self.box_lo, self.box_hi)?;
        let t_start = t_enter.max(ray.tmin);
        let t_stop = ray.tmax.min(box_leave + box_leave.abs() * BOX_T_SLACK);
        if t_start > t_leave.min(ray.tmax) || t_start.max(box_enter) > t_stop {
            return None;
        }
        let leaf = if box_enter > t_start {
            self.locate(self.grid_coords(point_at(o, d, box_enter)))
        } else if t_enter > ray.tmin {
            // Entering the root through a face: the boundary cell under the entry point.
            let mut q = self.grid_coords(point_at(o, d, t_enter));
            q[entry_axis] = if d[entry_axis] < 0.0 { (1u32 << self.max_depth) - 1 } else { 0 };
            self.locate(q)
        } else {
            self.locate(self.grid_coords(point_at(o, d, t_start)))
        };
        Some(Walk {
            o,
            d,
            inv: d.map(|x| 1.0 / x),
            high: d.map(|x| !x.is_sign_negative() as u32),
            exits: &EXIT_FACE[octant(d)],
            rule: exit_rule(o, d, RuleScale::of(self.root_lo, self.root_hi, self.sizes[0])),
            shear: Shear::new(o, d),
            tmin: ray.tmin,
            tmax: t_stop,
            leaf,
            best: None,
            t_best: ray.tmax,
            steps: 0,
        })
    }

    /// Finest-grid coordinates of a point, clamped into the root.
    fn grid_coords(&self, p: [f32; 3]) -> [u32; 3] {
        let last = ((1u64 << self.max_depth) - 1) as f64;
        let q = |a: usize| ((p[a] as f64 - self.root_lo[a] as f64) * self.grid_scale).max(0.0).min(last) as u32;
        [q(0), q(1), q(2)]
    }

    /// The leaf holding finest-grid cell `q`.
    fn locate(&self, q: [u32; 3]) -> u32 {
        let mut node = self.root;
        let mut level = 0;
        while let NodeRef::Internal(i) = NodeRef::decode(node) {
            let shift = self.max_depth - level - 1;
            node = self.nodes[i as usize]
                [((q[0] >> shift & 1) | (q[1] >> shift & 1) << 1 | (q[2] >> shift & 1) << 2) as usize];
            level += 1;
        }
        node
    }

    /// Visits the walk's leaf and moves to the next; returns whether the walk is over.
    fn step<const ANY: bool>(&self, w: &mut Walk, stats: &mut UnconstrainedStats) -> bool {
        let leaf = &self.leaves[w.leaf as usize];
        stats.leaves += 1;
        w.steps += 1;
        if w.steps > self.max_steps {
            return true;
        }
        stats.triangle_tests += leaf.count;
        for &prim in &self.refs[leaf.start as usize..(leaf.start + leaf.count) as usize] {
            if let Some((t, u, v)) = w.shear.intersect(&self.tris[prim as usize], w.tmin, w.t_best) {
                w.t_best = t;
                w.best = Some((t, prim, u, v));
                if ANY {
                    return true;
                }
            }
        }
        // The exit face, as the constrained walk finds it.
        let (lo, size) = (self.root_lo, self.sizes[leaf.level as usize]);
        let off = [0, 1, 2].map(|k| (lo[k] + (leaf.cell[k] + w.high[k]) as f32 * size) - w.o[k]);
        let exact = w.rule == ExitRule::Exact;
        let (face, t_exit) = match w.rule {
            ExitRule::Table => (w.exits[exit_code(off, w.d)] as usize, None),
            ExitRule::Flat => (exit_along_moving_axes(off, w.d, w.inv), None),
            ExitRule::Exact => {
                let (face, t) = exact_exit(off, w.d);
                (face, Some(t))
            }
        };
        let axis = face >> 1;
        let (off_a, d_a) = (off[axis], w.d[axis]);
        let t_exit = t_exit.unwrap_or(off_a * w.inv[axis]);
        if w.best.is_some_and(|(t, ..)| t <= t_exit) || t_exit >= w.tmax {
            return true;
        }
        let rope = leaf.ropes[face];
        if rope == NO_ROPE {
            return true;
        }
        // Down from the rope's node to the leaf holding the exit point: at each level
        // the near-side child whose quadrant the exit point lies in, by the signs of
        // the Plücker products with the node face's median lines.
        let negative_a = face & 1 == 0;
        let mut node = rope;
        let (mut level, mut cell) = (leaf.level, leaf.cell);
        let start = level;
        cell[axis] = if negative_a { cell[axis].wrapping_sub(1) } else { cell[axis] + 1 };
        while let NodeRef::Internal(i) = NodeRef::decode(node) {
            let half = self.sizes[(level as usize + 1) & 31];
            let mut child = (negative_a as usize) << axis;
            for k in 0..3 {
                if k != axis {
                    let mid = lo[k] + (2 * cell[k] + 1) as f32 * half;
                    let side = if exact {
                        exact_side(off_a, d_a, mid - w.o[k], w.d[k], negative_a)
                    } else {
                        let p = off_a * w.d[k] - (mid - w.o[k]) * d_a;
                        ((p > 0.0) ^ negative_a) as u32
                    };
                    child |= (side as usize) << k;
                }
            }
            cell = [0, 1, 2].map(|k| 2 * cell[k] + ((child >> k) & 1) as u32);
            level += 1;
            stats.descents += 1;
            node = self.nodes[i as usize][child];
        }
        stats.deepest_descent = stats.deepest_descent.max(level - start);
        w.leaf = node;
        false
    }
}
