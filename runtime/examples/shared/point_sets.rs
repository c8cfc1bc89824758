//! The point sets the timing examples measure, made the same way in each: `n` points
//! uniform in 1.1x the mesh's box, and `n` within 1 % of the box's diagonal from the
//! surface (a random point of a random stored triangle, moved a random distance in a
//! random direction), from one seeded generator (`raysets::Pcg32`).

use octrace_format::{SceneView, StoredIndex};
use octrace_runtime::raysets::Pcg32;

/// (uniform, near) points of `view`'s scene.
pub fn point_sets(view: &SceneView<'_>, n: usize) -> (Vec<[f32; 3]>, Vec<[f32; 3]>) {
    let (lo, hi) = (view.bounds.mesh_lo, view.bounds.mesh_hi);
    let size: [f32; 3] = [0, 1, 2].map(|k| hi[k] - lo[k]);
    let diag = size.iter().map(|s| s * s).sum::<f32>().sqrt();
    let mut rng = Pcg32::new(0x9e37_79b9_7f4a_7c15, 54);
    let mut unit = move || rng.rand() as f32;
    let uniform = (0..n).map(|_| [0, 1, 2].map(|k| lo[k] - 0.05 * size[k] + 1.1 * size[k] * unit())).collect();
    let triangles = view.triangle_count().max(1);
    let near = (0..n)
        .map(|_| {
            let t = view.triangle(StoredIndex(((unit() * triangles as f32) as usize).min(triangles - 1) as u32));
            let (mut a, mut b) = (unit(), unit());
            if a + b > 1.0 {
                (a, b) = (1.0 - a, 1.0 - b);
            }
            let offset = 0.01 * diag * unit();
            let dir = [0, 1, 2].map(|_| unit() * 2.0 - 1.0);
            let len = dir.iter().map(|d| d * d).sum::<f32>().sqrt().max(1e-6);
            [0, 1, 2].map(|k| t[0][k] + a * (t[1][k] - t[0][k]) + b * (t[2][k] - t[0][k]) + offset * dir[k] / len)
        })
        .collect();
    (uniform, near)
}
