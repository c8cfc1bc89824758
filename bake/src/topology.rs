//! Whether a triangle mesh is closed and consistently oriented: the census of
//! `octrace_format::topology`, which the bake records per mesh part and for the whole
//! scene (`inspect` prints it), re-exported here.

pub use octrace_format::topology::{is_degenerate, signed_volume, EdgeCensus};

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
