//! The render's own accuracy knobs priced: soft-shadow samples and reflection depth,
//! each render's error against a reference render of the effects scene, and its time.

use std::time::Instant;

use octrace_bake::{bake, procedural};
use octrace_runtime::raysets::Camera;
use octrace_runtime::render::effects::{render_effects, RenderOptions};
use octrace_runtime::render::Image;
use octrace_runtime::Scene;
use serde::Serialize;

/// Soft-shadow samples measured, and the reference's.
const SOFT_SAMPLES: [u32; 7] = [1, 2, 4, 8, 16, 32, 64];
const SOFT_REFERENCE: u32 = 256;
/// Reflection (and refraction) depths measured, and the reference's.
const DEPTHS: [u32; 6] = [1, 2, 3, 4, 6, 8];
const DEPTH_REFERENCE: u32 = 16;

/// One render against its reference.
#[derive(Debug, Serialize)]
pub(super) struct RenderKnobRow {
    /// "soft-shadow samples" or "reflection depth".
    pub knob: &'static str,
    pub value: u32,
    /// Whether this is the renderer's default.
    pub default: bool,
    /// Wall-clock seconds of the render, all threads.
    pub seconds: f64,
    /// Rays traced, every kind.
    pub rays: u64,
    /// Root mean square difference from the reference, in 8-bit levels of the image.
    pub rmse: f64,
}

/// The effects scene rendered at `width` x `3/4 width` with each knob turned from the
/// defaults, against references of 256 soft samples and depth 16.
pub(super) fn render_knobs(width: u32) -> anyhow::Result<Vec<RenderKnobRow>> {
    let scene = Scene::from_baked(bake(&procedural::effects_scene(), &Default::default())?)?;
    let height = (width * 3 / 4).max(1);
    let camera = Camera::from_scene(&scene.shading().cameras[0], 40.0, width, height);
    let defaults = RenderOptions::for_scene(scene.shading());
    let render = |options: &RenderOptions| {
        let t = Instant::now();
        let (radiance, counts) = render_effects(&scene, &camera, options, &|_| {});
        (radiance.to_image(), counts.total(), t.elapsed().as_secs_f64())
    };
    let mut rows = Vec::new();
    let reference = render(&RenderOptions { soft_samples: SOFT_REFERENCE, ..defaults }).0;
    for samples in SOFT_SAMPLES {
        let (image, rays, seconds) = render(&RenderOptions { soft_samples: samples, ..defaults });
        let default = samples == defaults.soft_samples;
        rows.push(RenderKnobRow {
            knob: "soft-shadow samples",
            value: samples,
            default,
            seconds,
            rays,
            rmse: rmse(&image, &reference),
        });
    }
    let reference = render(&RenderOptions { max_depth: DEPTH_REFERENCE, ..defaults }).0;
    for depth in DEPTHS {
        let (image, rays, seconds) = render(&RenderOptions { max_depth: depth, ..defaults });
        let default = depth == defaults.max_depth;
        rows.push(RenderKnobRow {
            knob: "reflection depth",
            value: depth,
            default,
            seconds,
            rays,
            rmse: rmse(&image, &reference),
        });
    }
    Ok(rows)
}

/// Root mean square difference of two images of one size, in 8-bit levels.
fn rmse(a: &Image, b: &Image) -> f64 {
    let sum: f64 = a.rgb.iter().zip(&b.rgb).map(|(&x, &y)| (x as f64 - y as f64).powi(2)).sum();
    (sum / a.rgb.len().max(1) as f64).sqrt()
}

/// The references the rows are measured against, for the report's text.
pub(super) fn references() -> (u32, u32) {
    (SOFT_REFERENCE, DEPTH_REFERENCE)
}
