//! What the fuzz targets and the hostile-file tests run on a scene that opened: every
//! way a caller traces and renders it. Hidden from the docs; not an API to build on.

use crate::raysets::{Camera, Frame};
use crate::render::effects::{render_effects, RenderOptions};
use crate::{Ray, Scene};

/// Traces `rays` through `scene` one at a time (nearest hit and any hit) and in
/// batches, then renders 6 x 4 pixels through the standard camera with every effect
/// the scene's shading calls for (two soft-shadow samples, ray trees three deep). On a
/// hostile file each must end, with some answer: a panic or a hang here is a bug.
pub fn exercise(scene: &Scene, rays: &[Ray]) {
    let _ = scene.decode_textures();
    let tracer = scene.tracer();
    for r in rays {
        let _ = tracer.intersect(r);
        let _ = tracer.occluded(r);
    }
    let _ = scene.intersect_batch(rays);
    let _ = scene.occluded_batch(rays);
    let _ = scene.crossings_batch(rays, 64);
    let _ = scene.count_crossings_batch(rays);
    let _ = scene.length_inside_batch(rays);
    let points: Vec<[f32; 3]> = rays.iter().map(|r| r.origin.to_array()).collect();
    let _ = scene.contains_batch(&points);
    let _ = scene.closest_points_batch(&points, f32::INFINITY);
    for p in &points {
        let _ = scene.closest_point_within(*p, 0.5);
    }
    for p in &points {
        let _ = tracer.contains_by_vote(*p, 3);
    }
    let b = scene.view().bounds;
    let camera = Camera::standard_sized(&Frame::from_bounds(b.mesh_lo, b.mesh_hi), 6, 4);
    let options = RenderOptions { soft_samples: 2, max_depth: 3, ..RenderOptions::for_scene(scene.shading()) };
    let _ = render_effects(scene, &camera, &options, &|_| {}).0.to_image();
}
