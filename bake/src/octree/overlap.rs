//! Exact triangle/box overlap by separating axes (Akenine-Möller, "Fast 3D
//! triangle-box overlap testing", 2001), in `f64`.
//!
//! Boxes are closed: a triangle that only touches a box counts as overlapping it, so
//! a triangle lying in the face shared by two cells is referenced by both, and a ray
//! walking either cell finds it.

/// An axis-aligned box in `f64`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Box3 {
    /// Low corner.
    pub lo: [f64; 3],
    /// High corner.
    pub hi: [f64; 3],
}

impl Box3 {
    /// Whether `other` lies entirely inside `self` (closed).
    pub fn contains_box(&self, other: &Box3) -> bool {
        (0..3).all(|a| self.lo[a] <= other.lo[a] && other.hi[a] <= self.hi[a])
    }

    /// Whether the two closed boxes share a point.
    pub fn touches(&self, other: &Box3) -> bool {
        (0..3).all(|a| self.lo[a] <= other.hi[a] && other.lo[a] <= self.hi[a])
    }

    /// The bounding box of a triangle.
    pub fn of_triangle(t: &[[f32; 3]; 3]) -> Box3 {
        let mut b = Box3 { lo: [f64::INFINITY; 3], hi: [f64::NEG_INFINITY; 3] };
        for v in t {
            for a in 0..3 {
                b.lo[a] = b.lo[a].min(v[a] as f64);
                b.hi[a] = b.hi[a].max(v[a] as f64);
            }
        }
        b
    }
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Whether triangle `t` and closed box `b` share a point.
pub fn triangle_overlaps_box(t: &[[f32; 3]; 3], b: &Box3) -> bool {
    if !b.touches(&Box3::of_triangle(t)) {
        return false; // the three box axes
    }
    let c = [0, 1, 2].map(|a| 0.5 * (b.lo[a] + b.hi[a]));
    let h = [0, 1, 2].map(|a| 0.5 * (b.hi[a] - b.lo[a]));
    let v = t.map(|p| sub(p.map(f64::from), c));
    let e = [sub(v[1], v[0]), sub(v[2], v[1]), sub(v[0], v[2])];
    let separated_on = |axis: [f64; 3]| {
        let p = v.map(|q| dot(axis, q));
        let r = h[0] * axis[0].abs() + h[1] * axis[1].abs() + h[2] * axis[2].abs();
        p[0].min(p[1]).min(p[2]) > r || p[0].max(p[1]).max(p[2]) < -r
    };
    // The triangle's plane first: near a surface it rejects most boxes the bounding
    // box let through.
    if separated_on(cross(e[0], e[1])) {
        return false;
    }
    // The nine cross products of box axes and triangle edges.
    for edge in e {
        for unit in [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]] {
            if separated_on(cross(unit, edge)) {
                return false;
            }
        }
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    const UNIT: Box3 = Box3 { lo: [0.0; 3], hi: [1.0; 3] };

    #[test]
    fn a_triangle_inside_overlaps() {
        assert!(triangle_overlaps_box(&[[0.2, 0.2, 0.2], [0.8, 0.2, 0.2], [0.2, 0.8, 0.2]], &UNIT));
    }

    #[test]
    fn a_triangle_cutting_the_corner_region_without_touching_is_separated() {
        // Its bounding box overlaps the box, but the triangle passes beyond the corner
        // (1, 1, 1): only the plane or an edge axis separates it.
        let t = [[1.6, 0.5, 1.0], [0.5, 1.6, 1.0], [1.0, 1.0, 1.6]];
        assert!(!triangle_overlaps_box(&t, &UNIT));
    }

    #[test]
    fn touching_counts_as_overlap() {
        let t = [[1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [1.0, 0.0, 1.0]];
        assert!(triangle_overlaps_box(&t, &UNIT));
        let corner = [[1.0, 1.0, 1.0], [2.0, 1.0, 1.0], [1.0, 2.0, 1.0]];
        assert!(triangle_overlaps_box(&corner, &UNIT));
    }

    #[test]
    fn a_large_triangle_through_the_box_overlaps() {
        let t = [[-10.0, -10.0, 0.5], [10.0, -10.0, 0.5], [0.0, 10.0, 0.5]];
        assert!(triangle_overlaps_box(&t, &UNIT));
    }
}
