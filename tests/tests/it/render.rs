//! Rendered images match golden images within a tolerance (mean absolute difference
//! per channel, as wgpu's `ComparisonType::Mean`). `OCTRACE_BLESS=1` rewrites them.

use octrace_bake::{bake, procedural, BuildParams};
use octrace_runtime::raysets::{Camera, Frame};
use octrace_runtime::render::{render, Image, RenderMode};
use octrace_runtime::Scene;
use octrace_tests::data;

fn read_png(path: &std::path::Path) -> Image {
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).expect("golden image exists")));
    let mut reader = decoder.read_info().expect("a PNG");
    let mut rgb = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut rgb).expect("one frame");
    assert_eq!(info.color_type, png::ColorType::Rgb);
    rgb.truncate(info.buffer_size());
    Image { width: info.width, height: info.height, rgb }
}

fn check(name: &str, image: &Image) {
    let path = data(&format!("golden/{name}.png"));
    if std::env::var_os("OCTRACE_BLESS").is_some() {
        image.write_png(&path).unwrap();
    }
    let golden = read_png(&path);
    let diff = image.mean_abs_diff(&golden).expect("same size as the golden image");
    assert!(diff <= 0.5, "{name}: mean difference {diff:.3} per channel");
}

#[test]
fn a_torus_and_spheres_render_like_the_golden_images() {
    let mut mesh = procedural::torus([0.0; 3], 1.0, 0.35, 48, 24);
    mesh.triangles.extend(procedural::sphere([0.0, 0.0, 0.0], 0.5, 16, 24).triangles);
    mesh.triangles.extend(procedural::sphere([1.6, 0.4, -0.8], 0.3, 12, 16).triangles);
    let scene = Scene::from_baked(bake(&mesh, &BuildParams::auto()).unwrap()).unwrap();
    let b = scene.view().bounds;
    let camera = Camera::standard_sized(&Frame::from_bounds(b.mesh_lo, b.mesh_hi), 160, 120);
    for (name, mode) in [("torus_shaded", RenderMode::Shaded), ("torus_normals", RenderMode::Normals)] {
        let (image, stats) = render(&scene, &camera, mode);
        assert!(stats.hits > 1000, "{name}: only {} hits", stats.hits);
        check(name, &image);
    }
}
