//! The oracle's closest point: every triangle, in `f64`, by another construction than
//! the tracer's (the least of the plane's distance where the point projects into the
//! triangle and the three edges' as segments, not the Voronoi regions).

use glam::DVec3;

use super::Reference;

/// The oracle's nearest point of the surface.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReferenceClosest {
    /// Distance from the query point.
    pub distance: f64,
    /// Input index of the triangle (of those at the least `f64` distance, the lowest).
    pub triangle: u32,
    /// The nearest point.
    pub point: DVec3,
}

/// The nearest point of segment `a b` to `p`.
fn on_segment(p: DVec3, a: DVec3, b: DVec3) -> DVec3 {
    let e = b - a;
    let ee = e.length_squared();
    if ee == 0.0 {
        return a;
    }
    a + e * ((p - a).dot(e) / ee).clamp(0.0, 1.0)
}

/// The nearest point of triangle `t` to `p`.
pub fn nearest_on_triangle(p: DVec3, t: &[DVec3; 3]) -> DVec3 {
    let n = (t[1] - t[0]).cross(t[2] - t[0]);
    let nn = n.length_squared();
    if nn > 0.0 {
        let q = p - n * ((p - t[0]).dot(n) / nn);
        let inside = (0..3).all(|i| {
            let (a, b) = (t[i], t[(i + 1) % 3]);
            (b - a).cross(q - a).dot(n) >= 0.0
        });
        if inside {
            return q;
        }
    }
    let mut best = on_segment(p, t[0], t[1]);
    for (a, b) in [(1, 2), (2, 0)] {
        let q = on_segment(p, t[a], t[b]);
        if (q - p).length_squared() < (best - p).length_squared() {
            best = q;
        }
    }
    best
}

impl Reference {
    /// The nearest point of every triangle to `p`, the least distance's lowest input
    /// index; `None` without triangles.
    pub fn closest_point(&self, p: [f32; 3]) -> Option<ReferenceClosest> {
        let p = DVec3::from(p.map(f64::from));
        self.triangles
            .iter()
            .zip(&self.ids)
            .map(|(t, &id)| {
                let q = nearest_on_triangle(p, t);
                ReferenceClosest { distance: (q - p).length(), triangle: id, point: q }
            })
            .min_by(|a, b| a.distance.total_cmp(&b.distance).then(a.triangle.cmp(&b.triangle)))
    }

    /// The `f64` distance from `p` to the triangle of input index `id` (the first
    /// stored with it), or `None` where there is none.
    pub fn distance_to(&self, p: [f32; 3], id: u32) -> Option<f64> {
        let p = DVec3::from(p.map(f64::from));
        let i = self.ids.iter().position(|&x| x == id)?;
        Some((nearest_on_triangle(p, &self.triangles[i]) - p).length())
    }
}
