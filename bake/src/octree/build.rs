//! The adaptive octree: recursive subdivision with exact triangle/cell overlap.
//!
//! Portalez & Duguet 2016, section 2.2: split a cell while it is shallower than the
//! depth limit and holds more than the leaf target; a triangle goes to every child it
//! really overlaps (separating axes, [`super::overlap`]), not to every child its
//! bounding box touches.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

use rayon::prelude::*;

use super::overlap::{triangle_overlaps_box, Box3};
use octrace_format::layout::grid_plane;

/// A node of the tree under construction.
#[derive(Debug)]
pub(crate) enum Node {
    /// A leaf and the indices of the triangles it overlaps, ascending.
    Leaf(Vec<u32>),
    /// Eight children, `child = x_high | y_high << 1 | z_high << 2`.
    Internal(Box<[Node; 8]>),
}

/// A cell: level and integer coordinates at that level.
pub(crate) type Cell = (u32, [u32; 3]);

/// The child octant of `cell` that contains the level-`level` coordinates `at`.
pub(crate) fn octant(level: u32, at: [u32; 3], depth: u32) -> usize {
    let shift = depth - level - 1;
    (0..3).map(|a| (((at[a] >> shift) & 1) as usize) << a).sum()
}

/// The children's cells.
pub(crate) fn child_cell((level, c): Cell, child: usize) -> Cell {
    (level + 1, [0, 1, 2].map(|a| 2 * c[a] + ((child >> a) & 1) as u32))
}

/// The most the format's indices hold: leaf records are addressed below 2^31 words
/// (the top bit of a node reference marks internal nodes), triangle references are
/// counted in 32 bits. Lower in tests, to reach them with small meshes.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Limits {
    /// Triangle references (`tri_refs`).
    pub refs: u64,
    /// Words of leaf records (`octree`).
    pub words: u64,
    /// Bytes the tree may hold while it is built ([`tree_bytes`]): the bake's memory
    /// budget (`BuildParams::max_tree_bytes`).
    pub bytes: u64,
}

impl Limits {
    /// The format's, with no memory budget.
    pub(crate) const FORMAT: Limits =
        Limits { refs: u32::MAX as u64, words: octrace_format::layout::INTERNAL_BIT as u64, bytes: u64::MAX };
}

/// Bytes a tree of `leaves` leaves holding `refs` references takes while it is built:
/// 4 a reference and [`LEAF_BYTES`] a leaf. The bake's peak is about twice this
/// (the tree, then the file's arrays made from it) plus the mesh.
pub(crate) fn tree_bytes(leaves: u64, refs: u64) -> u64 {
    refs.saturating_mul(4).saturating_add(leaves.saturating_mul(LEAF_BYTES))
}

/// A leaf's bytes while the tree is built: its node (32), its list's header (24), an
/// eighth of its parent's children array (32), its record in the file (16).
pub(crate) const LEAF_BYTES: u64 = 104;

/// What the tree has grown to while it is built, so that a tree passing a limit stops
/// growing then, not after the whole build.
///
/// Every leaf counts its references and [`octrace_format::layout::LEAF_HEADER_WORDS`]
/// words (its record without links, a lower bound), and a split leaf is taken back;
/// the counts are exact for the tree built so far, and the layout checks the exact
/// words again ([`super::flatten::arrays`]).
#[derive(Debug)]
pub(crate) struct Growth {
    limits: Limits,
    refs: AtomicU64,
    leaves: AtomicU64,
    passed: AtomicBool,
}

impl Growth {
    pub(crate) fn new(limits: Limits) -> Growth {
        Growth { limits, refs: AtomicU64::new(0), leaves: AtomicU64::new(0), passed: AtomicBool::new(false) }
    }

    /// Counts a change of `leaves` leaves holding `refs` more references.
    fn add(&self, leaves: i64, refs: i64) {
        let refs = self.refs.fetch_add(refs as u64, Ordering::Relaxed).wrapping_add(refs as u64);
        let leaves = self.leaves.fetch_add(leaves as u64, Ordering::Relaxed).wrapping_add(leaves as u64);
        let words = leaves * octrace_format::layout::LEAF_HEADER_WORDS as u64;
        if refs > self.limits.refs || words > self.limits.words || tree_bytes(leaves, refs) > self.limits.bytes {
            self.passed.store(true, Ordering::Relaxed);
        }
    }

    /// Whether a limit was passed: the build has stopped growing.
    pub(crate) fn passed(&self) -> bool {
        self.passed.load(Ordering::Relaxed)
    }

    /// The limit passed, as the error to report, once [`Growth::passed`].
    pub(crate) fn error(&self) -> crate::Error {
        let refs = self.refs.load(Ordering::Relaxed);
        let leaves = self.leaves.load(Ordering::Relaxed);
        let words = leaves * octrace_format::layout::LEAF_HEADER_WORDS as u64;
        let bytes = tree_bytes(leaves, refs);
        if bytes > self.limits.bytes && refs <= self.limits.refs && words <= self.limits.words {
            crate::Error::TreeBudget { needed: bytes, limit: self.limits.bytes }
        } else if refs > self.limits.refs {
            crate::Error::Limit { what: "triangle references", needed: refs, limit: self.limits.refs }
        } else {
            crate::Error::Limit { what: "words of leaf records", needed: words, limit: self.limits.words }
        }
    }
}

/// Geometry shared by the whole build.
pub(crate) struct Builder<'a> {
    /// Non-degenerate triangles, indexed by the build's triangle index.
    pub triangles: &'a [[[f32; 3]; 3]],
    /// Low corner of the root cube.
    pub root_lo: [f32; 3],
    /// Edge of the root cube.
    pub root_size: f32,
    /// Absolute enlargement of cells when assigning triangles.
    pub margin: f64,
    /// Depth limit.
    pub max_depth: u32,
    /// Leaf target.
    pub leaf_size: usize,
    /// The tree's size so far, against the format's limits.
    pub growth: Growth,
}

/// A thread's tally of leaves and references reaches the shared [`Growth`] at least
/// this often (4,096 leaves are 426 KB of tree, 65,536 references 256 KB): a budget is
/// passed by at most this much a thread before the build stops.
const FLUSH_LEAVES: i64 = 4096;
const FLUSH_REFS: i64 = 65536;

/// Above this many triangles, a node's children are built in parallel.
const PARALLEL_GRAIN: usize = 2048;

impl Builder<'_> {
    /// The cell's box as the file stores it (planes rounded to `f32`), enlarged by the
    /// margin.
    pub(crate) fn cell_box(&self, (level, c): Cell) -> Box3 {
        let plane = |a: usize, i: u32| grid_plane(self.root_lo[a], self.root_size, level, i) as f64;
        Box3 {
            lo: [0, 1, 2].map(|a| plane(a, c[a]) - self.margin),
            hi: [0, 1, 2].map(|a| plane(a, c[a] + 1) + self.margin),
        }
    }

    /// Builds the subtree of `cell` from the triangles that overlap it. Once the tree
    /// passes a limit ([`Growth`]), what is left to build becomes empty leaves.
    pub(crate) fn build(&self, cell: Cell, tris: Vec<u32>) -> Node {
        let mut grown = (0, 0);
        let node = self.build_counting(cell, tris, &mut grown);
        self.growth.add(grown.0, grown.1);
        node
    }

    /// [`Builder::build`], adding the leaves made and their references to `grown`
    /// rather than to the shared [`Growth`] leaf by leaf (two atomic additions a leaf,
    /// contended by every thread, cost the build 4 %): a subtree built on one thread
    /// counts into its caller's tally, and each subtree handed to another thread
    /// ([`Builder::build`]) adds its own when it is done.
    fn build_counting(&self, cell: Cell, tris: Vec<u32>, grown: &mut (i64, i64)) -> Node {
        if self.growth.passed() {
            return Node::Leaf(Vec::new());
        }
        if cell.0 >= self.max_depth || tris.len() <= self.leaf_size {
            *grown = (grown.0 + 1, grown.1 + tris.len() as i64);
            // A subtree built on one thread (a small mesh's whole tree) reports as it
            // grows, not only when it is done, so that the budget stops it in time.
            if grown.0 >= FLUSH_LEAVES || grown.1 >= FLUSH_REFS {
                self.growth.add(grown.0, grown.1);
                *grown = (0, 0);
            }
            return Node::Leaf(tris);
        }
        let parts = self.split_uncounted(cell, &tris);
        drop(tris);
        let children: Vec<Node> = if parts.iter().map(Vec::len).sum::<usize>() > PARALLEL_GRAIN {
            parts.into_par_iter().enumerate().map(|(i, p)| self.build(child_cell(cell, i), p)).collect()
        } else {
            parts.into_iter().enumerate().map(|(i, p)| self.build_counting(child_cell(cell, i), p, grown)).collect()
        };
        Node::Internal(Box::new(children.try_into().expect("eight children")))
    }

    /// Distributes a cell's triangles to its eight children, exactly.
    ///
    /// Per axis, the triangle's bounding box tells which halves it can touch. A
    /// triangle inside the cell that crosses at most one mid-plane overlaps every
    /// child its box touches (it is connected), so the separating-axis test runs only
    /// for triangles crossing two or three mid-planes or poking out of the cell.
    pub(crate) fn split(&self, cell: Cell, tris: &[u32]) -> [Vec<u32>; 8] {
        let parts = self.split_uncounted(cell, tris);
        self.growth.add(7, parts.iter().map(|p| p.len() as i64).sum::<i64>() - tris.len() as i64);
        parts
    }

    /// [`Builder::split`] without counting: for [`Builder::build_counting`], whose
    /// children count themselves as leaves.
    fn split_uncounted(&self, cell: Cell, tris: &[u32]) -> [Vec<u32>; 8] {
        let (level, c) = cell;
        let plane = |a: usize, i: u32| grid_plane(self.root_lo[a], self.root_size, level + 1, i) as f64;
        let m = self.margin;
        let lo = [0, 1, 2].map(|a| plane(a, 2 * c[a]) - m);
        let mid = [0, 1, 2].map(|a| plane(a, 2 * c[a] + 1));
        let hi = [0, 1, 2].map(|a| plane(a, 2 * c[a] + 2) + m);
        let mut parts: [Vec<u32>; 8] = Default::default();
        for &t in tris {
            let tri = &self.triangles[t as usize];
            let bb = Box3::of_triangle(tri);
            let inside = (0..3).all(|a| lo[a] <= bb.lo[a] && bb.hi[a] <= hi[a]);
            // Bit 0: touches the low half; bit 1: the high half.
            let halves =
                [0, 1, 2].map(|a| (bb.lo[a] <= mid[a] + m) as usize | ((bb.hi[a] >= mid[a] - m) as usize) << 1);
            let crossing = halves.iter().filter(|&&h| h == 3).count();
            let exact = !inside || crossing >= 2;
            for child in 0..8 {
                if (0..3).any(|a| halves[a] >> ((child >> a) & 1) & 1 == 0) {
                    continue;
                }
                if !exact || triangle_overlaps_box(tri, &self.cell_box(child_cell(cell, child))) {
                    parts[child].push(t);
                }
            }
        }
        parts
    }
}

impl Node {
    /// Number of leaves.
    pub(crate) fn leaf_count(&self) -> usize {
        match self {
            Node::Leaf(_) => 1,
            Node::Internal(c) => c.iter().map(Node::leaf_count).sum(),
        }
    }

    /// Calls `f` on every leaf, depth first, children in octant order.
    pub(crate) fn for_each_leaf<'a>(&'a self, cell: Cell, f: &mut impl FnMut(Cell, &'a [u32])) {
        match self {
            Node::Leaf(t) => f(cell, t),
            Node::Internal(c) => {
                for (i, child) in c.iter().enumerate() {
                    child.for_each_leaf(child_cell(cell, i), f);
                }
            }
        }
    }

    /// The level of the leaf that contains cell `(level, at)`, or `level` if the cell
    /// is inside the tree's internal nodes.
    pub(crate) fn leaf_level_at(&self, (level, at): Cell) -> u32 {
        let mut node = self;
        let mut depth = 0;
        while depth < level {
            match node {
                Node::Leaf(_) => return depth,
                Node::Internal(c) => node = &c[octant(depth, at, level)],
            }
            depth += 1;
        }
        level
    }
}
