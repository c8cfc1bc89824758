//! Point location: the leaf holding a point (rays that start inside the root) and the
//! leaf a ray from outside enters first (through the cube map), through the grid of
//! the point-location tree's top levels (`locate_grid`).

use octrace_format::layout::{other_axes, texel_index, NodeRef};

use super::locate_grid::descend_to;
use super::tracer::Tracer;
use super::walk::point_at;

impl Tracer<'_> {
    /// Finest-grid coordinates of a point, clamped into the root: in SSE2 where the
    /// build has it (`hw::grid_coords_sse2`, the same cells).
    #[inline(always)]
    pub(super) fn grid_coords(&self, p: [f32; 3]) -> [u32; 3] {
        #[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
        return super::hw::grid_coords_sse2(p, self.frame.root_lo, self.frame.grid_scale, self.grid_last());
        #[cfg(not(all(target_arch = "x86_64", target_feature = "sse2")))]
        self.grid_coords_scalar(p)
    }

    /// The last finest-grid cell's index on each axis.
    #[inline(always)]
    pub(super) fn grid_last(&self) -> f64 {
        ((1u64 << self.frame.max_depth) - 1) as f64
    }

    /// [`Tracer::grid_coords`] in portable scalar arithmetic (what the SSE2 form is
    /// tested against).
    #[cfg(any(test, not(all(target_arch = "x86_64", target_feature = "sse2"))))]
    #[inline(always)]
    pub(super) fn grid_coords_scalar(&self, p: [f32; 3]) -> [u32; 3] {
        let last = self.grid_last();
        // Clamped to [0, last] first, so truncation is the floor; NaN clamps to 0.
        // Rounding can only move a point to a neighbouring cell, which the bake
        // margin covers.
        let q =
            |a: usize| ((p[a] as f64 - self.frame.root_lo[a] as f64) * self.frame.grid_scale).max(0.0).min(last) as u32;
        [q(0), q(1), q(2)]
    }

    /// The address of the leaf holding point `p` (clamped into the root).
    pub fn locate(&self, p: [f32; 3]) -> u32 {
        self.locate_cell(p).0
    }

    /// The leaf holding point `p`: its address, level and cell. With a locate grid,
    /// one load replaces the top levels of the descent.
    #[inline(always)]
    pub(super) fn locate_cell(&self, p: [f32; 3]) -> (u32, u32, [u32; 3]) {
        let q = self.grid_coords(p);
        match self.grid {
            Some(grid) => {
                let (word, level) = grid.entry(q, self.frame.max_depth);
                self.descend(word, level, q)
            }
            None => self.descend(self.view.root, 0, q),
        }
    }

    /// Descends from `word` (a node at `level`) to the leaf holding finest-grid cell
    /// `q`: its address, level and cell.
    #[inline(always)]
    fn descend(&self, word: u32, level: u32, q: [u32; 3]) -> (u32, u32, [u32; 3]) {
        let (address, level) = descend_to(&self.view, word, level, q, self.frame.max_depth, self.frame.max_depth);
        let shift = self.frame.max_depth.saturating_sub(level).min(31);
        (address, level, q.map(|c| c >> shift))
    }

    /// The leaf a ray from outside enters first (address, level, cell): the cube-map
    /// texel under its entry point holds that leaf, or the node to descend from.
    #[inline(always)]
    pub(super) fn enter_through_cube_map(&self, o: [f32; 3], d: [f32; 3], t: f32, axis: usize) -> (u32, u32, [u32; 3]) {
        let mut q = self.grid_coords(point_at(o, d, t));
        let high = d[axis] < 0.0;
        q[axis] = if high { (1u32 << self.frame.max_depth) - 1 } else { 0 };
        let face = 2 * axis + high as usize;
        let Some(level) = self.frame.cube_level else {
            return self.descend(self.view.root, 0, q);
        };
        let res = 1usize << level;
        let (u, v) = other_axes(axis);
        let shift = self.frame.max_depth - level;
        let texel = texel_index(face, res, (q[u] >> shift) as usize, (q[v] >> shift) as usize);
        let word = self.view.cube_map[texel];
        match NodeRef::decode(word) {
            NodeRef::Internal(_) => self.descend(word, level, q),
            // The texel's leaf may be coarser than the texel: its level is read off its
            // box, whose edge is the root's divided by a power of two.
            NodeRef::Leaf(address) => {
                let view = &self.view;
                let edge =
                    view.octree.get(address as usize + 2).and_then(|&b| view.boxes.get(b as usize * 6..)?.get(..6));
                // A leaf or box past its array (a hostile file): from the root instead.
                let Some(edge) = edge.map(|b| b[3] as f64 - b[0] as f64) else {
                    return self.descend(view.root, 0, q);
                };
                // Edges are the root's over powers of two: compare binary exponents
                // (rounding of the planes moves an edge by far less than a factor 2).
                let ratio = self.view.bounds.root_size as f64 / edge * std::f64::consts::SQRT_2;
                let leaf_level = (((ratio.to_bits() >> 52) & 0x7FF) as i64 - 1023).clamp(0, level as i64) as u32;
                let shift = self.frame.max_depth - leaf_level;
                (address, leaf_level, [q[0] >> shift, q[1] >> shift, q[2] >> shift])
            }
        }
    }
}
