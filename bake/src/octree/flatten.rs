//! From the balanced tree to the file's arrays: leaf records with their face links
//! (Portalez & Duguet 2016, section 3.1), the point-location tree, the cube map of
//! boundary cells (section 4.1), and triangles in the order the leaves use them.

use rayon::prelude::*;

use octrace_format::layout::{
    cell_box, face_axis, face_is_high, other_axes, pack_counts, texel_index, total_links, NodeRef, LEAF_HEADER_WORDS,
};

use super::build::{child_cell, octant, Cell, Node};

/// The tree as flat arrays, leaves and internal nodes in depth-first order.
pub(crate) struct FlatTree {
    /// Children of each internal node; leaves referenced by ordinal.
    pub nodes: Vec<[NodeRef; 8]>,
    /// Root reference (ordinal for a leaf).
    pub root: NodeRef,
    /// Cell of each leaf.
    pub leaf_cells: Vec<Cell>,
    /// Triangles of each leaf (build indices).
    pub leaf_tris: Vec<Vec<u32>>,
    /// Internal node holding each leaf (`u32::MAX` for a root leaf).
    pub leaf_parent: Vec<u32>,
}

impl FlatTree {
    /// Flattens `root` depth first, children in octant order (Morton order for leaves).
    pub(crate) fn new(root: Node) -> FlatTree {
        let mut flat = FlatTree {
            nodes: Vec::new(),
            root: NodeRef::Leaf(0),
            leaf_cells: Vec::new(),
            leaf_tris: Vec::new(),
            leaf_parent: Vec::new(),
        };
        flat.root = flat.push(root, (0, [0; 3]), u32::MAX);
        flat
    }

    fn push(&mut self, node: Node, cell: Cell, parent: u32) -> NodeRef {
        match node {
            Node::Leaf(tris) => {
                self.leaf_cells.push(cell);
                self.leaf_tris.push(tris);
                self.leaf_parent.push(parent);
                NodeRef::Leaf(self.leaf_cells.len() as u32 - 1)
            }
            Node::Internal(children) => {
                let index = self.nodes.len();
                self.nodes.push([NodeRef::Leaf(0); 8]);
                for (i, child) in children.into_iter().enumerate() {
                    self.nodes[index][i] = self.push(child, child_cell(cell, i), index as u32);
                }
                NodeRef::Internal(index as u32)
            }
        }
    }

    /// The leaf holding cell `(level, at)`, or the internal node that is that cell.
    pub(crate) fn locate(&self, (level, at): Cell) -> NodeRef {
        let mut r = self.root;
        let mut depth = 0;
        while let (NodeRef::Internal(i), true) = (r, depth < level) {
            r = self.nodes[i as usize][octant(depth, at, level)];
            depth += 1;
        }
        r
    }

    /// Appends the neighbour ordinals of leaf `ordinal` across `face` to `out` and
    /// returns how many, and whether a single neighbour is one level coarser: none on
    /// the root's boundary, one leaf of the same level or the next coarser, or four
    /// finer leaves in quadrant order (see `octrace_format::layout`).
    pub(crate) fn push_neighbours(&self, ordinal: usize, face: usize, out: &mut Vec<u32>) -> (u32, bool) {
        let (level, c) = self.leaf_cells[ordinal];
        let axis = face_axis(face);
        let high = face_is_high(face);
        let last = (1u32 << level) - 1;
        if (high && c[axis] == last) || (!high && c[axis] == 0) {
            return (0, false);
        }
        let mut across = c;
        across[axis] = if high { c[axis] + 1 } else { c[axis] - 1 };
        // Inside the parent, the cell across is a sibling: no descent from the root.
        let sibling = (c[axis] & 1 == 0) == high;
        let found = if sibling {
            let me: usize = (0..3).map(|a| ((c[a] & 1) as usize) << a).sum();
            self.nodes[self.leaf_parent[ordinal] as usize][me ^ (1 << axis)]
        } else {
            self.locate((level, across))
        };
        match found {
            NodeRef::Leaf(o) => {
                out.push(o);
                (1, self.leaf_cells[o as usize].0 < level)
            }
            NodeRef::Internal(i) => {
                let (u, v) = other_axes(axis);
                // The children of the cell across that touch our face: on its near side.
                let near = if high { 0 } else { 1 };
                for q in 0..4 {
                    let child = near << axis | (q & 1) << u | (q >> 1) << v;
                    match self.nodes[i as usize][child] {
                        NodeRef::Leaf(o) => out.push(o),
                        NodeRef::Internal(_) => panic!("2:1 balance broken at {:?} face {face}", (level, c)),
                    }
                }
                (4, false)
            }
        }
    }
}

/// The arrays of a baked scene, minus parameters and bounds.
pub(crate) struct Arrays {
    pub octree: Vec<u32>,
    pub tri_refs: Vec<u32>,
    /// Build triangle index of each stored triangle.
    pub tri_order: Vec<u32>,
    pub boxes: Vec<f32>,
    pub cube_map: Vec<u32>,
    pub nodes: Vec<u32>,
    pub root: u32,
}

/// Lays the flat tree out as the file's arrays.
pub(crate) fn arrays(
    flat: &FlatTree,
    triangle_count: usize,
    root_lo: [f32; 3],
    root_size: f32,
    cube_level: u32,
    limits: super::build::Limits,
) -> crate::error::Result<Arrays> {
    let leaves = flat.leaf_cells.len();
    let references: u64 = flat.leaf_tris.iter().map(|t| t.len() as u64).sum();
    if references > limits.refs {
        return Err(crate::Error::Limit { what: "triangle references", needed: references, limit: limits.refs });
    }
    // Records with links by ordinal first, in chunks (one allocation each): `nCount`
    // then the links. Addresses are known once every record's length is.
    const CHUNK: usize = 4096;
    let chunks: Vec<Vec<u32>> = (0..leaves.div_ceil(CHUNK))
        .into_par_iter()
        .map(|k| {
            let range = k * CHUNK..((k + 1) * CHUNK).min(leaves);
            let mut out = Vec::with_capacity(range.len() * 9);
            for ordinal in range {
                let at = out.len();
                out.push(0);
                let found: [(u32, bool); 6] = std::array::from_fn(|face| flat.push_neighbours(ordinal, face, &mut out));
                out[at] = pack_counts(found.map(|f| f.0), found.map(|f| f.1));
            }
            out
        })
        .collect();
    // Leaf addresses are words below the internal-node bit of a node reference.
    let words: u64 =
        chunks.iter().map(|c| c.len() as u64).sum::<u64>() + (LEAF_HEADER_WORDS as u64 - 1) * leaves as u64;
    if words > limits.words {
        return Err(crate::Error::Limit { what: "words of leaf records", needed: words, limit: limits.words });
    }
    let mut address = Vec::with_capacity(leaves);
    let mut next = 0u32;
    for chunk in &chunks {
        let mut i = 0;
        while i < chunk.len() {
            let links = total_links(chunk[i]) as usize;
            address.push(next);
            next += (LEAF_HEADER_WORDS + links) as u32;
            i += 1 + links;
        }
    }
    // Triangles are stored in the order the leaves first use them, so a leaf's
    // triangles sit near each other and near its neighbours'.
    let mut new_index = vec![u32::MAX; triangle_count];
    let mut tri_order = Vec::with_capacity(triangle_count);
    let mut tri_refs = Vec::with_capacity(flat.leaf_tris.iter().map(Vec::len).sum());
    let mut octree = Vec::with_capacity(next as usize);
    let mut boxes = Vec::with_capacity(6 * leaves);
    let mut records = chunks.iter().flat_map(|c| c.iter().copied());
    for (ordinal, tris) in flat.leaf_tris.iter().enumerate() {
        let ncount = records.next().expect("one record a leaf");
        octree.extend([tris.len() as u32, tri_refs.len() as u32, ordinal as u32, ncount]);
        for _ in 0..total_links(ncount) {
            octree.push(address[records.next().expect("links") as usize]);
        }
        // A leaf lists its triangles in descending input order (`tris` is ascending):
        // the walks keep the last of equal hits, so a tie goes to the lowest input id
        // (the format requires it: FORMAT.md).
        for &t in tris.iter().rev() {
            if new_index[t as usize] == u32::MAX {
                new_index[t as usize] = tri_order.len() as u32;
                tri_order.push(t);
            }
            tri_refs.push(new_index[t as usize]);
        }
        let (level, c) = flat.leaf_cells[ordinal];
        boxes.extend(cell_box(root_lo, root_size, level, c));
    }
    let encode = |r: NodeRef| match r {
        NodeRef::Leaf(o) => NodeRef::Leaf(address[o as usize]).encode(),
        internal => internal.encode(),
    };
    let nodes = flat.nodes.iter().flat_map(|n| n.map(encode)).collect();
    let res = 1u32 << cube_level;
    let cube_map = (0..6 * res as usize * res as usize)
        .into_par_iter()
        .map(|t| {
            let (face, rest) = (t / (res * res) as usize, t % (res * res) as usize);
            let (iu, iv) = ((rest % res as usize) as u32, (rest / res as usize) as u32);
            debug_assert_eq!(texel_index(face, res as usize, iu as usize, iv as usize), t);
            let axis = face_axis(face);
            let (u, v) = other_axes(axis);
            let mut cell = [0u32; 3];
            cell[axis] = if face_is_high(face) { res - 1 } else { 0 };
            cell[u] = iu;
            cell[v] = iv;
            encode(flat.locate((cube_level, cell)))
        })
        .collect();
    Ok(Arrays { octree, tri_refs, tri_order, boxes, cube_map, nodes, root: encode(flat.root) })
}
