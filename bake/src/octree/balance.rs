//! The 2:1 constraint: no two face-adjacent leaves differ by more than one level.
//!
//! Portalez & Duguet 2016, section 2.2 ("contrainte de régularité"). Leaves are taken
//! deepest level first: a leaf at level `l` needs the cell across each of its faces to
//! be resolved down to level `l - 1` at least, so the leaf holding that cell is split
//! until it is. Splitting only creates leaves shallower than `l`, which later rounds
//! take care of; one pass over the levels therefore balances the whole tree.

use rayon::prelude::*;

use super::build::{child_cell, octant, Builder, Cell, Node};

/// Balances `root` in place. `leaves_by_level[l]` lists the cells of the leaves at
/// level `l`; it is updated as leaves are split.
pub(crate) fn balance(root: &mut Node, builder: &Builder<'_>) {
    let mut by_level: Vec<Vec<[u32; 3]>> = vec![Vec::new(); builder.max_depth as usize + 1];
    root.for_each_leaf((0, [0; 3]), &mut |(l, c), _| by_level[l as usize].push(c));
    for level in (2..=builder.max_depth).rev() {
        if builder.growth.passed() {
            return;
        }
        let coarse = level - 1;
        // The level-(l-1) cells across the faces of the level-l leaves, where they are
        // not the leaf's own parent.
        // Only the few that sit in a leaf too coarse are kept, then sorted (so the
        // splits happen in the same order whatever the thread count).
        let mut shallow: Vec<[u32; 3]> = {
            let root = &*root;
            by_level[level as usize]
                .par_iter()
                .flat_map_iter(|&c| faces_needing(level, c))
                .filter(|&t| root.leaf_level_at((coarse, t)) < coarse)
                .collect()
        };
        shallow.par_sort_unstable();
        shallow.dedup();
        for t in shallow {
            refine_to(root, builder, (coarse, t), &mut by_level);
        }
    }
}

/// The cells at level `level - 1` across the faces of leaf `(level, c)` that lie
/// outside its parent (inside the parent the neighbour is a sibling, fine already).
fn faces_needing(level: u32, c: [u32; 3]) -> impl Iterator<Item = [u32; 3]> {
    let last = (1u32 << level) - 1;
    (0..6).filter_map(move |face| {
        let axis = face >> 1;
        let high = face & 1 == 1;
        // The face is on the parent's boundary when the child is on that side.
        let on_parent_side = (c[axis] & 1 == 1) == high;
        if !on_parent_side || (high && c[axis] == last) || (!high && c[axis] == 0) {
            return None;
        }
        let mut across = c;
        across[axis] = if high { c[axis] + 1 } else { c[axis] - 1 };
        Some(across.map(|x| x >> 1))
    })
}

/// Splits leaves along the path to `cell` until the cell is a node of the tree.
fn refine_to(root: &mut Node, builder: &Builder<'_>, (level, at): Cell, by_level: &mut [Vec<[u32; 3]>]) {
    let mut node = root;
    let mut cell: Cell = (0, [0; 3]);
    while cell.0 < level {
        if let Node::Leaf(tris) = node {
            let parts = builder.split(cell, tris);
            let children: [Node; 8] = parts.map(Node::Leaf);
            for i in 0..8 {
                let (l, c) = child_cell(cell, i);
                by_level[l as usize].push(c);
            }
            *node = Node::Internal(Box::new(children));
        }
        let Node::Internal(children) = node else { unreachable!("just split") };
        let i = octant(cell.0, at, level);
        cell = child_cell(cell, i);
        node = &mut children[i];
    }
}
