//! Images of a scene: the effects renderer ([`effects`]: materials, lights, shadows,
//! reflection, refraction, alpha, only those the scene calls for), and diagnostic
//! images (normals, or the number of leaves each ray visited, the paper's Figure 6),
//! written as PNG.

pub mod effects;
pub(crate) mod lighting;
pub(crate) mod stage;

use std::path::Path;

use glam::Vec3;
use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::raysets::Camera;
use crate::scene::Scene;
use crate::{Hit, WalkStats};

/// What a pixel shows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RenderMode {
    /// Grey, lit by a headlight (`|n . d|`).
    Shaded,
    /// The geometric normal facing the camera, as colour.
    Normals,
    /// Leaves visited by the pixel's ray, on a colour scale with a legend.
    Cells,
}

/// An 8-bit RGB image.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Image {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Pixels, row by row from the top, `r g b` each.
    pub rgb: Vec<u8>,
}

impl Image {
    /// Writes the image as PNG (as [`octrace_format::write_atomically`] writes).
    ///
    /// # Errors
    /// [`Error::Image`] naming the path.
    pub fn write_png(&self, path: impl AsRef<Path>) -> Result<()> {
        let path = path.as_ref();
        let err = |e: &dyn std::fmt::Display| Error::Image { path: path.into(), message: e.to_string() };
        let bytes = self.png_bytes()?;
        octrace_format::write_atomically(path, &[&bytes]).map_err(|e| err(&e))
    }

    /// The image as a PNG file's bytes.
    ///
    /// # Errors
    /// [`Error::Image`] if the encoder fails (an image too large for PNG).
    ///
    /// # Example
    /// ```
    /// let image = octrace_runtime::render::Image { width: 1, height: 1, rgb: vec![255, 0, 0] };
    /// assert_eq!(&image.png_bytes()?[1..4], b"PNG");
    /// # Ok::<(), octrace_runtime::Error>(())
    /// ```
    pub fn png_bytes(&self) -> Result<Vec<u8>> {
        let err = |e: &dyn std::fmt::Display| Error::Image { path: "-".into(), message: e.to_string() };
        let mut bytes = Vec::new();
        {
            let mut enc = png::Encoder::new(&mut bytes, self.width, self.height);
            enc.set_color(png::ColorType::Rgb);
            enc.set_depth(png::BitDepth::Eight);
            let mut w = enc.write_header().map_err(|e| err(&e))?;
            w.write_image_data(&self.rgb).map_err(|e| err(&e))?;
        }
        Ok(bytes)
    }

    /// Mean absolute difference per channel, in `[0, 255]`, or `None` if the sizes differ.
    pub fn mean_abs_diff(&self, other: &Image) -> Option<f64> {
        if (self.width, self.height) != (other.width, other.height) {
            return None;
        }
        let sum: u64 = self.rgb.iter().zip(&other.rgb).map(|(&a, &b)| a.abs_diff(b) as u64).sum();
        Some(sum as f64 / self.rgb.len().max(1) as f64)
    }
}

/// What a render counted.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RenderStats {
    /// Primary rays traced.
    pub rays: u64,
    /// Rays that hit.
    pub hits: u64,
    /// Most leaves one ray visited.
    pub max_leaves: u32,
    /// Mean leaves visited a ray.
    pub mean_leaves: f64,
    /// Mean triangle tests a ray.
    pub mean_triangle_tests: f64,
}

/// The tracer the renderers trace with: the watertight test, as the GPU's renderer
/// (a pixel's colour does not hang on which side of an edge an ulp-close ray passes,
/// and the CPU's and the GPU's images stay the same, bit for bit).
pub(crate) fn renderers_tracer(scene: &Scene) -> crate::Tracer<'_> {
    scene.tracer().with_triangle_test(crate::TriangleTest::Watertight)
}

/// Renders `scene` through `camera` on all cores.
pub fn render(scene: &Scene, camera: &Camera, mode: RenderMode) -> (Image, RenderStats) {
    let tracer = renderers_tracer(scene);
    let walks: Vec<(Option<Hit>, WalkStats)> = (0..camera.width * camera.height)
        .into_par_iter()
        .map(|i| tracer.intersect_with_stats(&pixel_ray(camera, i)))
        .collect();
    compose(scene, camera, mode, &walks)
}

/// Renders the tracer's scene through `camera` on the GPU: the same image as [`render`]
/// (the GPU walk gives the CPU's hits and visits the same leaves).
///
/// # Errors
/// The GPU's errors.
#[cfg(feature = "gpu")]
pub fn render_gpu(
    gpu: &crate::gpu::GpuTracer<'_>,
    camera: &Camera,
    mode: RenderMode,
) -> crate::gpu::GpuResult<(Image, RenderStats)> {
    let rays: Vec<_> = (0..camera.width * camera.height).map(|i| pixel_ray(camera, i)).collect();
    Ok(compose(gpu.scene(), camera, mode, &gpu.intersect_with_stats(&rays)?))
}

/// Pixel `i`'s ray, row by row from the top.
fn pixel_ray(camera: &Camera, i: u32) -> crate::Ray {
    camera.ray(i % camera.width, i / camera.width)
}

/// The image from each pixel's hit and walk.
fn compose(
    scene: &Scene,
    camera: &Camera,
    mode: RenderMode,
    walks: &[(Option<Hit>, WalkStats)],
) -> (Image, RenderStats) {
    let view = scene.view();
    let (w, h) = (camera.width, camera.height);
    let pixels: Vec<(Option<Vec3>, Vec3, u32, u32)> = walks
        .par_iter()
        .enumerate()
        .map(|(i, (hit, stats))| {
            let ray = pixel_ray(camera, i as u32);
            let normal = hit.map(|hit| {
                let n = crate::spawn::face_normal(&view.triangle(hit.prim));
                if n.dot(ray.dir) > 0.0 {
                    -n
                } else {
                    n
                }
            });
            (normal, ray.dir.normalize(), stats.leaves, stats.triangle_tests)
        })
        .collect();
    let max_leaves = pixels.iter().map(|p| p.2).max().unwrap_or(0);
    let stats = RenderStats {
        rays: pixels.len() as u64,
        hits: pixels.iter().filter(|p| p.0.is_some()).count() as u64,
        max_leaves,
        mean_leaves: pixels.iter().map(|p| p.2 as f64).sum::<f64>() / pixels.len().max(1) as f64,
        mean_triangle_tests: pixels.iter().map(|p| p.3 as f64).sum::<f64>() / pixels.len().max(1) as f64,
    };
    let mut rgb = Vec::with_capacity(pixels.len() * 3);
    for (normal, dir, leaves, _) in &pixels {
        let c = match (mode, normal) {
            (RenderMode::Shaded, Some(n)) => Vec3::splat(0.1 + 0.85 * n.dot(-*dir).abs()),
            (RenderMode::Normals, Some(n)) => *n * 0.5 + 0.5,
            (RenderMode::Cells, _) => heat(*leaves as f32 / max_leaves.max(1) as f32),
            (_, None) => Vec3::new(0.08, 0.08, 0.1),
        };
        rgb.extend(c.to_array().map(|x| (x.clamp(0.0, 1.0) * 255.0 + 0.5) as u8));
    }
    let mut image = Image { width: w, height: h, rgb };
    if mode == RenderMode::Cells {
        draw_legend(&mut image, max_leaves);
    }
    (image, stats)
}

/// A perceptual-ish colour scale from dark blue through green to yellow.
fn heat(x: f32) -> Vec3 {
    let stops = [
        Vec3::new(0.05, 0.03, 0.25),
        Vec3::new(0.15, 0.35, 0.6),
        Vec3::new(0.15, 0.65, 0.45),
        Vec3::new(0.7, 0.85, 0.2),
        Vec3::new(1.0, 0.95, 0.6),
    ];
    let x = x.clamp(0.0, 1.0) * (stops.len() - 1) as f32;
    let i = (x as usize).min(stops.len() - 2);
    stops[i].lerp(stops[i + 1], x - i as f32)
}

/// A colour bar along the bottom with "0" at its left end and the maximum at its right.
fn draw_legend(img: &mut Image, max: u32) {
    let (w, h) = (img.width as usize, img.height as usize);
    let bar_h = (h / 40).max(4);
    let scale = (h / 160).max(1);
    let label_h = 5 * scale + 4;
    if h < bar_h + label_h + 4 || w < 32 {
        return;
    }
    let (x0, x1) = (w / 20, w - w / 20);
    let y1 = h - 2 - label_h;
    let y0 = y1 - bar_h;
    let mut put = |x: usize, y: usize, c: Vec3| {
        let p = 3 * (y * w + x);
        img.rgb[p..p + 3].copy_from_slice(&c.to_array().map(|v| (v.clamp(0.0, 1.0) * 255.0) as u8));
    };
    for x in x0..x1 {
        let c = heat((x - x0) as f32 / (x1 - x0 - 1) as f32);
        for y in y0..y1 {
            put(x, y, c);
        }
    }
    let text_y = y1 + 2;
    draw_text(img, "0", x0, text_y, scale);
    let label = format!("{max} leaves");
    let width = label.len() * 4 * scale;
    draw_text(img, &label, x1.saturating_sub(width), text_y, scale);
}

/// Draws digits, spaces and the letters of "leaves" in a 3x5 bitmap font.
fn draw_text(img: &mut Image, text: &str, x: usize, y: usize, scale: usize) {
    for (k, ch) in text.chars().enumerate() {
        let glyph: [u8; 5] = match ch {
            '0' => [7, 5, 5, 5, 7],
            '1' => [2, 6, 2, 2, 7],
            '2' => [7, 1, 7, 4, 7],
            '3' => [7, 1, 7, 1, 7],
            '4' => [5, 5, 7, 1, 1],
            '5' => [7, 4, 7, 1, 7],
            '6' => [7, 4, 7, 5, 7],
            '7' => [7, 1, 1, 1, 1],
            '8' => [7, 5, 7, 5, 7],
            '9' => [7, 5, 7, 1, 7],
            'l' => [6, 2, 2, 2, 7],
            'e' => [0, 7, 7, 4, 7],
            'a' => [0, 7, 1, 7, 7],
            'v' => [0, 5, 5, 5, 2],
            's' => [0, 7, 6, 1, 7],
            _ => [0; 5],
        };
        for (row, bits) in glyph.iter().enumerate() {
            for col in 0..3 {
                if bits >> (2 - col) & 1 == 1 {
                    for dy in 0..scale {
                        for dx in 0..scale {
                            let (px, py) = (x + (4 * k + col) * scale + dx, y + row * scale + dy);
                            if px < img.width as usize && py < img.height as usize {
                                let p = 3 * (py * img.width as usize + px);
                                img.rgb[p..p + 3].copy_from_slice(&[235, 235, 235]);
                            }
                        }
                    }
                }
            }
        }
    }
}
