//! Build parameters and their automatic defaults.

/// Default leaf target: a cell is split while it holds more triangles than this.
/// The paper's octrees averaged about six triangles a leaf; a target of 16 gives about
/// seven a non-empty leaf after splitting, and the dragon fits the 124 MB budget.
pub const DEFAULT_LEAF_SIZE: u32 = 16;

/// Default bake margin, as a fraction of the root cube's edge: cells are enlarged by
/// this much when triangles are assigned to them, so a ray whose entry point or exit
/// face is decided a few ulps off still meets the triangles near the cell's border.
/// 2^-20 of the root edge is about eight `f32` ulps of a coordinate the size of the
/// scene, well above the rounding of an entry point, and far below the finest cell
/// (2^-11 of the root at the dragon's depth).
///
/// Measured (`cargo run --release -p octrace-runtime --example margin_sweep`): from 0 to
/// 2^-16 no margin changed anything observable (0 leaks in 2.1 million rays from inside
/// closed meshes, 0 oracle mismatches in 42,500 rays through cell corners, along cell
/// edges and at random), because the walk computes every plane exactly; 2^-20 costs
/// 0.07 % more triangle references and no measurable speed, and is kept as insurance
/// for entry points rounded into a neighbouring cell.
pub const DEFAULT_MARGIN: f32 = 1.0 / (1u32 << 20) as f32;

/// The largest bake margin accepted: 2^-10 of the root edge. A margin copies each
/// triangle into every cell within it, so beyond a cell's own size the references (and
/// the bake's memory and time) grow with the cube of margin / cell edge: 0.1 took 5 GB
/// and minutes on the bunny. 2^-10 is 1,024 times the default and a cell's edge at
/// depth 10.
pub const MAX_MARGIN: f32 = 1.0 / 1024.0;

/// Deepest level the automatic formula picks.
pub const AUTO_DEPTH_LIMIT: u32 = 16;

/// How to build the octree. `None` fields are chosen from the triangle count.
///
/// # Example
/// ```
/// let p = octrace_bake::BuildParams { max_depth: Some(8), ..octrace_bake::BuildParams::auto() };
/// assert_eq!(p.resolve(69_451).max_depth, 8);
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BuildParams {
    /// Deepest level (root = 0); automatic when `None`. Either way the bake stops
    /// where cells would be narrower than a few `f32` spacings of the scene's
    /// coordinates (see `octree::precision_depth`).
    pub max_depth: Option<u32>,
    /// Leaf target; [`DEFAULT_LEAF_SIZE`] when `None`.
    pub leaf_size: Option<u32>,
    /// Cell enlargement as a fraction of the root edge; see [`DEFAULT_MARGIN`].
    pub margin: f32,
    /// The bake's memory budget: the bytes the tree may hold while it is built (4 a
    /// triangle reference, about 100 a leaf); the build stops with
    /// [`Error::TreeBudget`](crate::Error::TreeBudget) as soon as it passes. `None`:
    /// [`default_max_tree_bytes`] for the mesh's triangles. The bake's peak memory is
    /// about twice this plus the mesh.
    pub max_tree_bytes: Option<u64>,
    /// Bake the closest-point search's tree into the file (its `distance` section,
    /// [`octrace_format::distance`]; the stored triangles then follow its order), so
    /// that a scene answers its first closest-point query without making it: about
    /// 24 bytes a triangle (the dragon's file 1.34x, its bake 1.34x as long). Off: the
    /// runtime makes it on the first such query.
    pub distance: bool,
}

/// The least default [`BuildParams::max_tree_bytes`]: 2 GiB, 60 times what the
/// dragon's default bake holds (34 MB: 1.86 million references, 253,436 leaves),
/// unless the machine has less ([`default_max_tree_bytes`]).
pub const DEFAULT_MAX_TREE_BYTES: u64 = 2 << 30;

/// Tree bytes the default budget allows a triangle: 1 KiB, 26 times the dragon's
/// (39 bytes a triangle), so that a mesh large enough to need more than
/// [`DEFAULT_MAX_TREE_BYTES`] gets it.
pub const DEFAULT_TREE_BYTES_PER_TRIANGLE: u64 = 1024;

/// The default memory budget of a bake of `triangles` triangles: 1 KiB a triangle
/// ([`DEFAULT_TREE_BYTES_PER_TRIANGLE`]), at least [`DEFAULT_MAX_TREE_BYTES`], and at
/// most a third of the memory this process may use
/// ([`octrace_format::memory::usable_bytes`]: physical memory, or the address-space
/// limit where lower), the bake's peak being about twice the tree plus the mesh. A
/// budget stops hostile inputs (a few triangles that share cells at every depth),
/// not the meshes the toolchain is for: on a 24 GB machine 55.8 million triangles get
/// 7.8 GB.
///
/// # Example
/// ```
/// use octrace_bake::octree::{default_max_tree_bytes, DEFAULT_MAX_TREE_BYTES};
/// let third = octrace_format::memory::usable_bytes() / 3;
/// assert_eq!(default_max_tree_bytes(4), DEFAULT_MAX_TREE_BYTES.min(third));
/// assert!(default_max_tree_bytes(100_000_000) <= third);
/// ```
pub fn default_max_tree_bytes(triangles: usize) -> u64 {
    let third = octrace_format::memory::usable_bytes() / 3;
    (triangles as u64).saturating_mul(DEFAULT_TREE_BYTES_PER_TRIANGLE).max(DEFAULT_MAX_TREE_BYTES).min(third)
}

/// Parameters with every automatic choice made.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ResolvedParams {
    /// Deepest level.
    pub max_depth: u32,
    /// Leaf target.
    pub leaf_size: u32,
    /// Margin, fraction of the root edge.
    pub margin: f32,
}

impl BuildParams {
    /// Checks the parameters against their limits: a leaf target of at least 1, a
    /// depth of at most the format's [`MAX_LEVEL`](octrace_format::layout::MAX_LEVEL),
    /// a margin from 0 to [`MAX_MARGIN`].
    ///
    /// # Errors
    /// [`Error::Params`](crate::Error::Params) naming the parameter and its limit.
    ///
    /// # Example
    /// ```
    /// use octrace_bake::BuildParams;
    /// assert!(BuildParams { margin: 0.1, ..BuildParams::auto() }.check().is_err());
    /// assert!(BuildParams::auto().check().is_ok());
    /// ```
    pub fn check(&self) -> crate::Result<()> {
        let fail = |message: String| Err(crate::Error::Params { message });
        let max_level = octrace_format::layout::MAX_LEVEL;
        if self.leaf_size == Some(0) {
            return fail(
                "leaf size 0 (--leaf-size, BuildParams::leaf_size): the leaf target must be at least 1".into(),
            );
        }
        if let Some(d) = self.max_depth.filter(|&d| d > max_level) {
            return fail(format!(
                "depth {d} (--max-depth, BuildParams::max_depth) is beyond the format's deepest level, {max_level}"
            ));
        }
        if !(self.margin.is_finite() && (0.0..=MAX_MARGIN).contains(&self.margin)) {
            return fail(format!(
                "margin {} (--margin, BuildParams::margin) is outside 0 to {MAX_MARGIN} (2^-10) of the root edge; \
                 past it every triangle is copied into a growing cube of cells",
                self.margin
            ));
        }
        Ok(())
    }

    /// The tree's budget for `mesh`: [`BuildParams::max_tree_bytes`], or the default
    /// for its triangles ([`default_max_tree_bytes`]).
    pub fn tree_budget(&self, mesh: &crate::Mesh) -> u64 {
        self.max_tree_bytes.unwrap_or_else(|| default_max_tree_bytes(mesh.triangles.len()))
    }

    /// Everything automatic, default margin.
    pub fn auto() -> Self {
        BuildParams { max_depth: None, leaf_size: None, margin: DEFAULT_MARGIN, max_tree_bytes: None, distance: false }
    }

    /// Fixes the automatic choices for a mesh of `triangles` triangles.
    ///
    /// Depth: a surface mesh fills about `4^d` cells at depth `d`, so reaching about
    /// `leaf_size` triangles a cell takes `log4(n / leaf_size)` levels:
    /// `max_depth = clamp(ceil(log4(n / leaf_size)), 1, 16)`.
    /// With the default leaf target this gives 7 for the bunny (the paper used 8) and
    /// 8 for the dragon (the paper used 11). Letting dense regions go two levels finer
    /// (the previous rule, `+ 2`) doubled the dragon's file (117 MB against
    /// 61 MB) and traced no faster: `octrace report` and `octrace bench`, BENCHMARKS.md
    /// "What accuracy costs". Havran's kd-tree rule (seed 003), `1.2 ln n + 2` binary levels, gives 19 for
    /// the dragon: 6.3 octree levels, far too shallow because it counts all
    /// subdivisions, not just those around the surface.
    pub fn resolve(&self, triangles: usize) -> ResolvedParams {
        let leaf_size = self.leaf_size.unwrap_or(DEFAULT_LEAF_SIZE).max(1);
        let max_depth = self.max_depth.unwrap_or_else(|| {
            let ratio = (triangles as f64 / leaf_size as f64).max(1.0);
            let levels = (ratio.log2() / 2.0).ceil() as u32;
            levels.clamp(1, AUTO_DEPTH_LIMIT)
        });
        ResolvedParams { max_depth: max_depth.min(octrace_format::layout::MAX_LEVEL), leaf_size, margin: self.margin }
    }
}

impl Default for BuildParams {
    fn default() -> Self {
        Self::auto()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn automatic_depth_matches_the_documented_values() {
        assert_eq!(BuildParams::auto().resolve(69_451).max_depth, 7);
        assert_eq!(BuildParams::auto().resolve(871_414).max_depth, 8);
        assert_eq!(BuildParams::auto().resolve(1).max_depth, 1);
    }
}
