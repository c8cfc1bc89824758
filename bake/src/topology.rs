//! Whether a triangle mesh is closed and consistently oriented: its edges counted by
//! their two end points (exact `f32` coordinates, `-0.0` and `+0.0` the same point).
//!
//! A mesh is **closed** when every edge is used by an even number of triangles (a ray
//! from inside then crosses its surface an odd number of times on the way out, and
//! parity tells inside from outside), and **manifold** when that number is two.
//! Two triangles are **consistently oriented** along an edge they share when they run
//! it in opposite directions; a flip there turns a normal inside out.

/// The edge counts of a mesh.
///
/// # Example
/// ```
/// use octrace_bake::{procedural, topology::EdgeCensus};
/// let cube = EdgeCensus::of(&procedural::cube([0.0; 3], [1.0; 3], 2).triangles);
/// assert!(cube.is_closed() && cube.is_manifold() && cube.is_oriented());
/// let grid = EdgeCensus::of(&procedural::grid(4, 1.0).triangles);
/// assert_eq!(grid.boundary, 16); // the square's rim, four edges a side
/// ```
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct EdgeCensus {
    /// Distinct edges.
    pub edges: u64,
    /// Edges used by an odd number of triangles (one, for a mesh with holes): the
    /// surface has a rim there.
    pub boundary: u64,
    /// Edges used by more than two triangles.
    pub non_manifold: u64,
    /// Edges used by exactly two triangles running it the same way.
    pub flipped: u64,
    /// Triangles left out: zero area (no edge of theirs is counted).
    pub degenerate: u64,
}

impl EdgeCensus {
    /// Counts the edges of `triangles` (each three vertices).
    pub fn of(triangles: &[[[f32; 3]; 3]]) -> EdgeCensus {
        // Each edge once per triangle: its end points' keys (lower first) and whether
        // the triangle runs it from the lower to the higher.
        let key = |p: [f32; 3]| p.map(|c| if c == 0.0 { 0 } else { c.to_bits() });
        let mut ends: Vec<([u32; 3], [u32; 3], bool)> = Vec::with_capacity(3 * triangles.len());
        let mut degenerate = 0;
        for t in triangles {
            if crate::octree::is_degenerate(t) {
                degenerate += 1;
                continue;
            }
            for (a, b) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
                let (ka, kb) = (key(a), key(b));
                ends.push(if ka < kb { (ka, kb, true) } else { (kb, ka, false) });
            }
        }
        ends.sort_unstable();
        let mut census = EdgeCensus { degenerate, ..EdgeCensus::default() };
        for run in ends.chunk_by(|x, y| (x.0, x.1) == (y.0, y.1)) {
            census.edges += 1;
            let forward = run.iter().filter(|e| e.2).count();
            census.boundary += (run.len() % 2 == 1) as u64;
            census.non_manifold += (run.len() > 2) as u64;
            census.flipped += (run.len() == 2 && forward != 1) as u64;
        }
        census
    }

    /// Every edge used an even number of times: inside and outside are well defined.
    pub fn is_closed(&self) -> bool {
        self.boundary == 0
    }

    /// Every edge used exactly twice.
    pub fn is_manifold(&self) -> bool {
        self.boundary == 0 && self.non_manifold == 0
    }

    /// No two triangles sharing an edge run it the same way.
    pub fn is_oriented(&self) -> bool {
        self.flipped == 0
    }
}

/// The signed volume a mesh encloses, in `f64`: positive when a closed mesh's
/// triangles are wound counter-clockwise seen from outside (their normals point out),
/// negative when they point in.
pub fn signed_volume(triangles: &[[[f32; 3]; 3]]) -> f64 {
    let v = |p: [f32; 3]| p.map(f64::from);
    triangles
        .iter()
        .map(|t| {
            let (a, b, c) = (v(t[0]), v(t[1]), v(t[2]));
            a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0]) + a[2] * (b[0] * c[1] - b[1] * c[0])
        })
        .sum::<f64>()
        / 6.0
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::procedural;

    #[test]
    fn closed_solids_are_closed_and_opened_ones_are_not() {
        for solid in procedural::closed_solids() {
            let c = EdgeCensus::of(&solid.mesh.triangles);
            assert!(c.is_manifold() && c.is_oriented(), "{}: {c:?}", solid.name);
            assert!(signed_volume(&solid.mesh.triangles) > 0.0, "{}: wound inward", solid.name);
            // One triangle removed: its three edges become the rim of a hole.
            let mut holed = solid.mesh.triangles.clone();
            holed.remove(holed.len() / 2);
            assert_eq!(EdgeCensus::of(&holed).boundary, 3, "{}", solid.name);
            // One triangle turned over: its three edges are flipped.
            let mut turned = solid.mesh.triangles.clone();
            let t = &mut turned[7];
            t.swap(1, 2);
            assert_eq!(EdgeCensus::of(&turned).flipped, 3, "{}", solid.name);
        }
        // The box faces out: its volume, positive.
        let cube = procedural::cube([-1.0, 0.0, 2.0], [1.0, 0.5, 3.0], 3).triangles;
        assert!((signed_volume(&cube) - 1.0).abs() < 1e-9, "{}", signed_volume(&cube));
        // Two cubes sharing an edge: four faces on it, closed but not manifold.
        let mut two = procedural::cube([0.0; 3], [1.0; 3], 1).triangles;
        two.extend(procedural::cube([1.0, 1.0, 0.0], [2.0, 2.0, 1.0], 1).triangles);
        let c = EdgeCensus::of(&two);
        assert!(c.is_closed() && !c.is_manifold(), "{c:?}");
        // -0.0 and +0.0 are the same point.
        let a = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        let b = [[-0.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]];
        assert_eq!(EdgeCensus::of(&[a, b]), EdgeCensus { edges: 3, ..Default::default() });
    }
}
