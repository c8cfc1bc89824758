//! The effects renderer on the GPU: tracing and shading in one WGSL kernel
//! (`render.wgsl`), specialised per effect set with override constants.

use glam::Vec3;
use octrace_format::layout::{TRIANGLE_FLOATS, UV_FLOATS};
use octrace_format::{AlphaMode, Effect, Filter, LightKind, Material, Wrap};
use rayon::prelude::*;

use super::{GpuError, GpuResult, GpuTracer};
use crate::raysets::Camera;
use crate::render::effects::{EffectSet, LightSum, Radiance, RayCounts, RenderOptions};
use crate::render::lighting::{self, Emitters, PLAIN};
use crate::scene::Scene;
use crate::spawn::gamma;

/// The deepest ray tree the kernel's private stack holds (`--max-depth`).
pub const MAX_GPU_DEPTH: u32 = 31;
/// Pixels a dispatch renders at most.
const PIXELS_PER_DISPATCH: u32 = 1 << 20;
/// Bytes of the ray counts (six 64-bit counts, `ray_counts` in render.wgsl).
const COUNT_BYTES: u64 = 4 * 12;
/// Words of a pixel's record in the kernel's `pixel_io` (render.wgsl).
const PIXEL_WORDS: usize = 8;
/// Words of a material record (`material` in render.wgsl).
const MATERIAL_WORDS: usize = 52;
/// Words of a texture record (`sample` in render.wgsl).
const TEXTURE_WORDS: usize = 8;
/// Words of a light record (`punctual` in render.wgsl).
const LIGHT_WORDS: usize = 16;

/// The kernel's uniform block (`RenderParams` in render.wgsl).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub(super) struct RenderParams {
    eye: [f32; 4],
    width: u32,
    height: u32,
    first_pixel: u32,
    pixel_count: u32,
    max_depth: u32,
    soft_samples: u32,
    light_count: u32,
    emitter_count: u32,
    o_materials: u32,
    o_lights: u32,
    o_emitters: u32,
    o_material_ids: u32,
    o_normals: u32,
    has_material_ids: u32,
    has_normals: u32,
    plain_material: u32,
    /// The emitters' total power (`Emitters::total`).
    emitter_power: f32,
    o_uvs: u32,
    has_uvs: u32,
    o_textures: u32,
    o_texels: u32,
    o_colors: u32,
    has_colors: u32,
    /// `octrace_format::linear16`'s table, 256 words.
    o_srgb: u32,
    o_tangents: u32,
    has_tangents: u32,
    /// Words a texture-coordinate channel takes (six a triangle).
    uv_channel_words: u32,
    /// The environment's sky (`Sky`: radiance and gradient), read where the
    /// `ENVIRONMENT` constant is set.
    environment: f32,
    environment_gradient: f32,
    /// `lighting::grid_side` of `soft_samples`.
    soft_grid: u32,
    pad: [u32; 2],
}

#[cfg(test)]
impl RenderParams {
    /// Members of the WGSL struct and the Rust fields' offsets, for the layout test.
    pub(super) const OFFSETS: [(&'static str, usize); 7] = [
        ("eye", std::mem::offset_of!(RenderParams, eye)),
        ("width", std::mem::offset_of!(RenderParams, width)),
        ("o_materials", std::mem::offset_of!(RenderParams, o_materials)),
        ("plain_material", std::mem::offset_of!(RenderParams, plain_material)),
        ("emitter_power", std::mem::offset_of!(RenderParams, emitter_power)),
        ("o_tangents", std::mem::offset_of!(RenderParams, o_tangents)),
        ("environment_gradient", std::mem::offset_of!(RenderParams, environment_gradient)),
    ];
}

/// Renders one scene with one set of options on the GPU, shading included: the image
/// of [`render_effects`](crate::render::effects::render_effects), up to rounding.
///
/// The pipeline is made for the options' effect set: each effect is an override
/// constant of the kernel, and an effect the set leaves out is compiled away.
///
/// # Example
/// ```no_run
/// use octrace_runtime::gpu::{GpuContext, GpuRenderer, GpuTracer};
/// use octrace_runtime::raysets::Camera;
/// use octrace_runtime::render::effects::RenderOptions;
/// use octrace_runtime::Scene;
/// # fn main() -> Result<(), Box<dyn std::error::Error>> {
/// let scene = Scene::open("effects.oct")?;
/// let gpu = GpuContext::new()?;
/// let tracer = GpuTracer::new(&gpu.device, &gpu.queue, &scene)?;
/// let renderer = GpuRenderer::new(&tracer, &RenderOptions::for_scene(scene.shading()))?;
/// let camera = Camera::from_scene(&scene.shading().cameras[0], 40.0, 640, 480);
/// let (radiance, counts) = renderer.render(&camera)?;
/// radiance.to_image().write_png("effects.png")?;
/// println!("{} rays", counts.total());
/// # Ok(()) }
/// ```
#[derive(Debug)]
pub struct GpuRenderer<'t, 's> {
    tracer: &'t GpuTracer<'s>,
    pipeline: wgpu::ComputePipeline,
    scene_group: wgpu::BindGroup,
    render_layout: wgpu::BindGroupLayout,
    shade: wgpu::Buffer,
    params: RenderParams,
    /// The options, for the pixels rendered again on the CPU.
    options: RenderOptions,
    /// The buffers a render uses, kept between renders (one at a time) and grown.
    kept: std::sync::Mutex<RenderBuffers>,
}

/// The buffers [`GpuRenderer::render`] keeps between calls: its uniform block, the
/// pixels' records and the ray counts, their read-back copies, and the bind group
/// over them (made again where the pixels' buffer grows).
#[derive(Debug, Default)]
struct RenderBuffers {
    params: Option<wgpu::Buffer>,
    pixels: Option<wgpu::Buffer>,
    counts: Option<wgpu::Buffer>,
    pixels_back: Option<wgpu::Buffer>,
    counts_back: Option<wgpu::Buffer>,
    group: Option<wgpu::BindGroup>,
}

impl<'t, 's> GpuRenderer<'t, 's> {
    /// Uploads what shading needs besides the tracer's arrays (materials, lights,
    /// emitters, and the file's material ids and normals as they are), makes the
    /// pipeline for `options` and runs it once over no pixels (where a driver compiles
    /// kernels at their first dispatch, it does so here rather than in the first
    /// render).
    ///
    /// # Errors
    /// [`GpuError::Unsupported`] for `max_depth` above [`MAX_GPU_DEPTH`];
    /// [`GpuError::TooLarge`] when the shading data exceed one storage binding;
    /// [`GpuError::Device`] for a refused resource.
    pub fn new(tracer: &'t GpuTracer<'s>, options: &RenderOptions) -> GpuResult<GpuRenderer<'t, 's>> {
        if options.max_depth > MAX_GPU_DEPTH {
            return Err(GpuError::Unsupported(format!(
                "the GPU renders ray trees at most {MAX_GPU_DEPTH} deep; {} asked for (the CPU renders any depth)",
                options.max_depth
            )));
        }
        let device = &tracer.device;
        use wgpu::BufferUsages as U;
        let limits = device.limits();
        // The tracer's bindings, and the render kernel's: parameters, shading data,
        // pixels and ray counts.
        let (storage, buffers) = super::TRACE_EXTRA_BINDINGS;
        let chunks = tracer.scene_buffers.len() as u64;
        let scene_bytes = tracer.scene_buffers.iter().map(wgpu::Buffer::size).sum();
        let chunk_bytes = tracer.scene_buffers.first().map_or(0, wgpu::Buffer::size);
        super::check_bindings(&limits, chunks, (storage + 3, buffers + 4), scene_bytes, chunk_bytes)?;
        let texels = tracer.scene().view().texels.check().map_err(|e| GpuError::Scene(e.to_string()))?;
        let (words, mut params, emitters) = shading_words(tracer.scene(), texels);
        let (headlight, environment) = options.environment.resolve(&tracer.scene().shading().lights, &emitters);
        if let Some(sky) = environment {
            (params.environment, params.environment_gradient) = (sky.radiance, sky.gradient);
        }
        let limit = limits.max_storage_buffer_binding_size.min(limits.max_buffer_size);
        if 4 * words.len() as u64 > limit {
            return Err(GpuError::TooLarge(format!(
                "{} MB of shading data, {} MB of them the texels of {} textures (the rest materials, lights, \
                 material ids, normals, texture coordinates); one binding holds {} MB",
                4 * words.len() / 1_000_000,
                4 * texels.len() / 1_000_000,
                tracer.scene().shading().textures.len(),
                limit / 1_000_000
            )));
        }
        params.max_depth = options.max_depth;
        params.soft_samples = options.soft_samples.max(1);
        params.soft_grid = crate::render::lighting::grid_side(params.soft_samples);
        let shade = tracer.buffer("octrace shading", 4 * words.len() as u64, U::STORAGE | U::COPY_DST);
        tracer.queue.write_buffer(&shade, 0, bytemuck::cast_slice(&words));

        let source = render_source(&tracer.source_with(tracer.budget().for_render()), options.max_depth);
        let render_layout = render_layout(device);
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("octrace render"),
            bind_group_layouts: &[Some(&tracer.layout), Some(&render_layout)],
            immediate_size: 0,
        });
        let mut constants = overrides(options.effects, headlight, environment.is_some());
        constants.push(("CULLING", if crate::render::effects::culls(tracer.scene().shading()) { 1.0 } else { 0.0 }));
        constants.push(("FANS", tracer.fans_constant()));
        let pipeline =
            tracer.compiler.pipeline(device, &pipeline_layout, &source, "render", &constants, "octrace render")?;
        let scene_group = tracer.scene_bind_group();
        let renderer = GpuRenderer {
            tracer,
            pipeline,
            scene_group,
            render_layout,
            shade,
            params,
            options: *options,
            kept: Default::default(),
        };
        renderer.warm()?;
        Ok(renderer)
    }

    /// Renders through `camera`: the radiance of every pixel and the rays traced per
    /// kind. Where the adapter caps shader loops (lavapipe, `gpu::loop_cap`), a pixel
    /// whose ray tree needs more loop iterations than the render kernel's budget
    /// (`device::RENDER_LOOPS`, under the cap) is rendered again on the CPU, so the
    /// image and the counts are whole whatever the adapter.
    ///
    /// # Errors
    /// [`GpuError::Device`] if the device is lost or a buffer cannot be read.
    pub fn render(&self, camera: &Camera) -> GpuResult<(Radiance, RayCounts)> {
        let device = &self.tracer.device;
        let queue = &self.tracer.queue;
        let total = camera.width * camera.height;
        let batch = total.clamp(1, self.tracer.budget().per_dispatch(PIXELS_PER_DISPATCH));
        let out_bytes = 4 * PIXEL_WORDS as u64 * u64::from(batch);
        // One render at a time uses the kept buffers; a larger image grows them.
        let mut kept = self.kept.lock().unwrap_or_else(|e| e.into_inner());
        let Frame { params: params_buffer, out, counts, out_back, counts_back, group } =
            self.frame_buffers(&mut kept, out_bytes);
        let eye = camera.ray(0, 0).origin;
        let mut params =
            RenderParams { eye: [eye.x, eye.y, eye.z, 0.0], width: camera.width, height: camera.height, ..self.params };
        let mut pixels = Vec::with_capacity(total as usize);
        let mut over = Vec::new();
        let mut sums = [0u64; 6];
        let mut first = 0;
        while first < total {
            let n = (total - first).min(batch);
            params.first_pixel = first;
            params.pixel_count = n;
            queue.write_buffer(&params_buffer, 0, bytemuck::bytes_of(&params));
            // The primary rays are the CPU camera's, bit for bit (render.wgsl reads
            // them from the pixels' words, where it then writes their light).
            let w = camera.width;
            let directions: Vec<[u32; PIXEL_WORDS]> = (first..first + n)
                .into_par_iter()
                .map(|p| {
                    let ray = camera.ray(p % w, p / w);
                    let (d, o) = (ray.dir, ray.origin);
                    [d.x.to_bits(), d.y.to_bits(), d.z.to_bits(), o.x.to_bits(), o.y.to_bits(), o.z.to_bits(), 0, 0]
                })
                .collect();
            queue.write_buffer(&out, 0, bytemuck::cast_slice(&directions));
            let mut encoder = device.create_command_encoder(&Default::default());
            encoder.clear_buffer(&counts, 0, None);
            {
                let mut pass = encoder.begin_compute_pass(&Default::default());
                pass.set_pipeline(&self.pipeline);
                pass.set_bind_group(0, &self.scene_group, &[]);
                pass.set_bind_group(1, &group, &[]);
                pass.dispatch_workgroups(n.div_ceil(self.tracer.budget().workgroup), 1, 1);
            }
            queue.submit([encoder.finish()]);
            let mut words: Vec<u32> = Vec::new();
            let bytes = 4 * PIXEL_WORDS as u64 * u64::from(n);
            super::device::read_buffer_append(device, queue, &out, &out_back, bytes, &mut words)?;
            let sum = |w: &[u32], c: usize| u64::from(w[2 * c]) | u64::from(w[2 * c + 1]) << 32;
            for (i, w) in (first..).zip(words.chunks_exact(PIXEL_WORDS)) {
                pixels.push(LightSum([sum(w, 0), sum(w, 1), sum(w, 2)]).radiance());
                // Word 6: out of loop budget (render.wgsl), rendered again below.
                if w[6] != 0 {
                    over.push(i);
                }
            }
            let mut c: Vec<u32> = Vec::new();
            super::device::read_buffer_append(device, queue, &counts, &counts_back, COUNT_BYTES, &mut c)?;
            for (k, s) in sums.iter_mut().enumerate() {
                *s += u64::from(c[2 * k]) | u64::from(c[2 * k + 1]) << 32;
            }
            first += n;
        }
        let mut counts = RayCounts::from_array(sums);
        if !over.is_empty() {
            let (redone, cpu_counts) =
                crate::render::effects::render_pixels(self.tracer.scene(), camera, &self.options, &over);
            for (&i, p) in over.iter().zip(redone) {
                pixels[i as usize] = p;
            }
            counts = counts.merge(cpu_counts);
        }
        let radiance = Radiance { width: camera.width, height: camera.height, pixels };
        Ok((radiance, counts))
    }

    /// The kept buffers for `out_bytes` of pixels' records (made or grown where they
    /// are smaller) and the bind group over them.
    fn frame_buffers(&self, kept: &mut RenderBuffers, out_bytes: u64) -> Frame {
        use wgpu::BufferUsages as U;
        let (tracer, device) = (self.tracer, &self.tracer.device);
        let params_size = std::mem::size_of::<RenderParams>() as u64;
        let count_bytes = COUNT_BYTES;
        let limits = device.limits();
        let binding = limits.max_storage_buffer_binding_size.min(limits.max_buffer_size);
        let storage = U::STORAGE | U::COPY_SRC | U::COPY_DST;
        let uniform = U::UNIFORM | U::COPY_DST;
        let (params, new_params) =
            tracer.kept_buffer(&mut kept.params, "octrace render params", params_size, uniform, params_size);
        let (out, new_out) = tracer.kept_buffer(&mut kept.pixels, "octrace pixels", out_bytes, storage, binding);
        let (counts, new_counts) =
            tracer.kept_buffer(&mut kept.counts, "octrace ray counts", count_bytes, storage, count_bytes);
        let map = U::MAP_READ | U::COPY_DST;
        let (out_back, _) =
            tracer.kept_buffer(&mut kept.pixels_back, "octrace pixels back", out_bytes, map, limits.max_buffer_size);
        let (counts_back, _) =
            tracer.kept_buffer(&mut kept.counts_back, "octrace ray counts back", count_bytes, map, count_bytes);
        // The bind group again where a buffer it binds is new.
        if new_params || new_out || new_counts || kept.group.is_none() {
            kept.group = Some(device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("octrace render"),
                layout: &self.render_layout,
                entries: &[
                    wgpu::BindGroupEntry { binding: 0, resource: params.as_entire_binding() },
                    wgpu::BindGroupEntry { binding: 1, resource: self.shade.as_entire_binding() },
                    wgpu::BindGroupEntry { binding: 2, resource: out.as_entire_binding() },
                    wgpu::BindGroupEntry { binding: 3, resource: counts.as_entire_binding() },
                ],
            }));
        }
        let group = kept.group.clone().expect("made above");
        Frame { params, out, counts, out_back, counts_back, group }
    }

    /// Runs the kernel once over no pixels: a driver that compiles a kernel at its
    /// first dispatch (Mesa's lavapipe: some 11 s for the render kernel where its
    /// shader cache does not hold it) does it here, in [`GpuRenderer::new`], not in
    /// the first render.
    fn warm(&self) -> GpuResult<()> {
        let mut kept = self.kept.lock().unwrap_or_else(|e| e.into_inner());
        let frame = self.frame_buffers(&mut kept, 4 * PIXEL_WORDS as u64);
        let params = RenderParams { width: 1, height: 1, first_pixel: 0, pixel_count: 0, ..self.params };
        let (device, queue) = (&self.tracer.device, &self.tracer.queue);
        queue.write_buffer(&frame.params, 0, bytemuck::bytes_of(&params));
        super::dispatch_once(device, queue, &self.pipeline, &[&self.scene_group, &frame.group]);
        super::device::wait(device)
    }
}

/// The buffers of one render ([`GpuRenderer::frame_buffers`]).
struct Frame {
    params: wgpu::Buffer,
    out: wgpu::Buffer,
    counts: wgpu::Buffer,
    out_back: wgpu::Buffer,
    counts_back: wgpu::Buffer,
    group: wgpu::BindGroup,
}

/// The pipeline constants for `effects` (`SHADOWS`, ... in render.wgsl).
fn overrides(effects: EffectSet, headlight: bool, environment: bool) -> Vec<(&'static str, f64)> {
    let flag = |b: bool| if b { 1.0 } else { 0.0 };
    let mut constants: Vec<(&'static str, f64)> = [
        ("SHADOWS", Effect::Shadows),
        ("SOFT_SHADOWS", Effect::SoftShadows),
        ("REFLECTION", Effect::Reflection),
        ("REFRACTION", Effect::Refraction),
        ("ALPHA", Effect::Alpha),
    ]
    .into_iter()
    .map(|(name, e)| (name, flag(effects.contains(e))))
    .collect();
    constants.push(("HEADLIGHT", flag(headlight)));
    constants.push(("ENVIRONMENT", flag(environment)));
    constants
}

/// The words of the kernel's `shade` binding, the parameters that locate them, and
/// the scene's emitters (which, with its lights, decide whether the headlight or the
/// environment lights it).
fn shading_words(scene: &Scene, texels: &[u32]) -> (Vec<u32>, RenderParams, Emitters) {
    let view = scene.view();
    let shading = view.shading;
    let mut words: Vec<u32> = Vec::new();
    let mut params = RenderParams::default();
    let f = |words: &mut Vec<u32>, v: &[f32]| words.extend(v.iter().map(|x| x.to_bits()));
    params.o_materials = 0;
    for m in shading.materials.iter().chain([&*PLAIN]) {
        let before = words.len();
        f(&mut words, &material_record(m, shading.textures.len()));
        debug_assert_eq!(words.len() - before, MATERIAL_WORDS);
    }
    params.plain_material = shading.materials.len() as u32;
    params.o_lights = words.len() as u32;
    for l in &shading.lights {
        let kind = match l.kind {
            LightKind::Point => 0,
            LightKind::Spot => 1,
            LightKind::Directional => 2,
        };
        let colour = Vec3::from(l.color) * l.intensity;
        words.extend([kind, l.range.to_bits(), l.outer_cone.cos().to_bits(), l.inner_cone.cos().to_bits()]);
        for v in [colour.to_array(), l.position, l.direction] {
            f(&mut words, &[v[0], v[1], v[2], 0.0]);
        }
    }
    debug_assert_eq!(words.len() - params.o_lights as usize, LIGHT_WORDS * shading.lights.len());
    params.light_count = shading.lights.len() as u32;
    let emitters = Emitters::of(&view);
    params.o_emitters = words.len() as u32;
    for (_, emitted, running) in emitters.iter() {
        f(&mut words, &[emitted.x, emitted.y, emitted.z, running]);
    }
    words.extend(emitters.iter().map(|(prim, _, _)| prim));
    params.emitter_count = emitters.iter().count() as u32;
    params.emitter_power = emitters.total();
    params.o_material_ids = words.len() as u32;
    params.has_material_ids = u32::from(!view.material_ids.is_empty());
    words.extend_from_slice(view.material_ids);
    params.o_normals = words.len() as u32;
    params.has_normals = u32::from(!view.normals.is_empty());
    f(&mut words, view.normals);
    params.o_uvs = words.len() as u32;
    params.uv_channel_words = (view.triangles.len() / TRIANGLE_FLOATS * UV_FLOATS) as u32;
    params.has_uvs = u32::from(!view.uvs.is_empty());
    f(&mut words, view.uvs);
    params.o_tangents = words.len() as u32;
    params.has_tangents = u32::from(!view.tangents.is_empty());
    words.extend_from_slice(view.tangents);
    params.o_colors = words.len() as u32;
    params.has_colors = u32::from(!view.colors.is_empty());
    words.extend_from_slice(view.colors);
    params.o_textures = words.len() as u32;
    for t in &shading.textures {
        let wrap = |w: Wrap| match w {
            Wrap::Repeat => 0,
            Wrap::MirroredRepeat => 1,
            Wrap::ClampToEdge => 2,
        };
        let filter = match t.filter {
            Filter::Nearest => 0,
            Filter::Linear => 1,
        };
        words.extend([t.width, t.height, t.first, wrap(t.wrap[0]), wrap(t.wrap[1]), filter, u32::from(t.srgb), 0]);
    }
    debug_assert_eq!(words.len() - params.o_textures as usize, TEXTURE_WORDS * shading.textures.len());
    params.o_srgb = words.len() as u32;
    words.extend(octrace_format::linear16().iter().map(|&c| u32::from(c)));
    params.o_texels = words.len() as u32;
    words.extend_from_slice(texels);
    if words.is_empty() {
        words.push(0);
    }
    (words, params, emitters)
}

/// A material's record: the values shading derives from it, computed here by the
/// CPU's functions so both sides use the same numbers, then the factors the kernel
/// derives them from again where a texture changes the base colour (`surface` in
/// render.wgsl, the operations of lighting.rs and `Material::mirror`).
///
/// A texture index past the `textures` the scene has (a file on the trusted path) is
/// none, as the CPU's `SceneView::base_color_at` and `emissive_at` read it.
fn material_record(m: &Material, textures: usize) -> [f32; MATERIAL_WORDS] {
    let texture = |t: Option<u32>| t.filter(|&t| (t as usize) < textures).map_or(0, |t| t + 1);
    let (ks, exponent) = lighting::highlight(m);
    let parts: [(Vec3, f32); 7] = [
        (Vec3::from(m.emissive), m.coverage()),
        (lighting::albedo(m, false), m.transmission.clamp(0.0, 1.0)),
        (lighting::albedo(m, true), m.ior),
        (ks, exponent),
        (lighting::base(m), 0.0),
        (lighting::mirror(m), 0.0),
        (lighting::shadow_transmittance(m), 0.0),
    ];
    let mut record = [0.0; MATERIAL_WORDS];
    for (i, (v, w)) in parts.iter().enumerate() {
        record[4 * i..4 * i + 4].copy_from_slice(&[v.x, v.y, v.z, *w]);
    }
    let metallic = m.metallic.clamp(0.0, 1.0);
    let bits = |u: u32| f32::from_bits(u);
    let alpha_mode = match m.alpha_mode {
        AlphaMode::Opaque => 0,
        AlphaMode::Mask => 1,
        AlphaMode::Blend => 2,
    };
    record[28..51].copy_from_slice(&[
        m.base_color[0],
        m.base_color[1],
        m.base_color[2],
        m.base_color[3],
        bits(texture(m.base_color_texture)),
        bits(u32::from(m.unlit)),
        metallic,
        m.gloss(),
        1.0 - lighting::metal(m),
        1.0 - m.transmission.clamp(0.0, 1.0),
        m.dielectric_mirror(),
        m.dielectric_f0() * (1.0 - metallic),
        lighting::shadow_keep(m),
        bits(alpha_mode),
        m.alpha_cutoff,
        bits(texture(m.emissive_texture)),
        bits(texture(m.metallic_roughness_texture)),
        m.roughness.clamp(0.0, 1.0),
        m.dielectric_f0(),
        bits(texture(m.occlusion_texture)),
        m.occlusion_strength,
        bits(texture(m.normal_texture)),
        m.normal_scale,
    ]);
    // The texture-coordinate channel of each slot, three bits each (UV_CHANNELS_WORD
    // in render.wgsl).
    let channels = m.uv_channels.iter().enumerate().fold(0u32, |w, (k, &c)| w | u32::from(c.min(7)) << (3 * k));
    record[51] = bits(channels);
    // SINGLE_SIDED_WORD in render.wgsl (the base colour's fourth word, unused).
    record[19] = bits(u32::from(!m.double_sided));
    record
}

fn render_layout(device: &wgpu::Device) -> wgpu::BindGroupLayout {
    let entry = |binding, ty| wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Buffer { ty, has_dynamic_offset: false, min_binding_size: None },
        count: None,
    };
    use wgpu::BufferBindingType as B;
    device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some("octrace render"),
        entries: &[
            entry(0, B::Uniform),
            entry(1, B::Storage { read_only: true }),
            entry(2, B::Storage { read_only: false }),
            entry(3, B::Storage { read_only: false }),
        ],
    })
}

/// The render kernel's source: the tracing kernel's (`trace`), the constants the
/// host fixes, render.wgsl.
pub(super) fn render_source(trace: &str, max_depth: u32) -> String {
    let floats = |name: &str, xs: &[f32]| {
        let xs: Vec<String> = xs.iter().map(|x| format!("{x:e}f")).collect();
        format!("const {name}: array<f32, {}> = array<f32, {}>({});\n", xs.len(), xs.len(), xs.join(", "))
    };
    format!(
        "{trace}\nconst STACK_SIZE: u32 = {}u;\nconst GAMMA_7: f32 = {:e}f;\n\
         const SQRT_2: f32 = {:e}f;\nconst LOG2_E: f32 = {:e}f;\nconst LN_2: f32 = {:e}f;\n\
         const SAMPLE_SCALE: f32 = {:e}f;\nconst COLOR_SCALE: f32 = {:e}f;\n{}{}{}",
        2 * max_depth + 1,
        gamma(7),
        std::f32::consts::SQRT_2,
        std::f32::consts::LOG2_E,
        std::f32::consts::LN_2,
        octrace_format::TEXEL_SCALE,
        octrace_format::COLOR_SCALE,
        floats("POWER_LN", &lighting::POWER_LN),
        floats("POWER_EXP", &lighting::POWER_EXP),
        include_str!("render.wgsl")
    )
}
