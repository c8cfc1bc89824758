//! The effects renderer: a Whitted-style integrator that runs only the passes the
//! scene's effect set (decided at bake) enables, ray kind by ray kind.
//!
//! It works in waves: all rays of a wave are traced together (the CPU's batch walk, or
//! one GPU dispatch), their hits shaded, and what the shading asks for — shadow rays,
//! reflection, refraction, rays continuing through cut-out surfaces — traced as the
//! next waves. An effect that is absent or turned off never creates a ray of its kind,
//! and [`RayCounts`] shows it.

use std::borrow::Cow;
use std::sync::atomic::{AtomicU32, Ordering};

use glam::Vec3;
use octrace_format::{Effect, Light, Material, SceneView, Shading, StoredIndex, VISIBLE_WEIGHT};
use rayon::prelude::*;

use super::lighting::{self, Emitters, PLAIN};
use super::stage::{SceneStage, Stage, WorldStage};
use super::Image;
use crate::raysets::Camera;
use crate::scene::Scene;
use crate::spawn::{face_normal, spawn, SpawnPoint};
use crate::world::World;
use crate::{Hit, Ray};

/// A set of [`Effect`]s.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct EffectSet(u8);

impl EffectSet {
    /// No effect: primary rays only.
    pub const NONE: EffectSet = EffectSet(0);

    /// The effects a scene calls for.
    pub fn of(shading: &Shading) -> EffectSet {
        shading.effects.iter().fold(EffectSet::NONE, |s, e| s.with(e.effect))
    }

    /// Whether `effect` is in the set.
    pub fn contains(self, effect: Effect) -> bool {
        self.0 & bit(effect) != 0
    }

    /// The set with `effect` added.
    #[must_use]
    pub fn with(self, effect: Effect) -> EffectSet {
        EffectSet(self.0 | bit(effect))
    }

    /// The set without `effect`.
    #[must_use]
    pub fn without(self, effect: Effect) -> EffectSet {
        EffectSet(self.0 & !bit(effect))
    }

    /// The effects in the set, in [`Effect::ALL`] order.
    pub fn iter(self) -> impl Iterator<Item = Effect> {
        Effect::ALL.into_iter().filter(move |&e| self.contains(e))
    }
}

fn bit(effect: Effect) -> u8 {
    1 << Effect::ALL.iter().position(|&e| e == effect).unwrap_or(0)
}

/// The kinds of rays the renderer traces.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum RayKind {
    /// Camera rays.
    Primary,
    /// Shadow rays towards punctual lights, or towards the centre of an area light when
    /// soft shadows are off.
    Shadow,
    /// Shadow rays towards sampled points of area lights.
    SoftShadow,
    /// Mirror reflection rays (and glass's Fresnel reflection).
    Reflection,
    /// Refraction rays.
    Refraction,
    /// Rays that continue through a cut-out or blended surface.
    Alpha,
}

impl RayKind {
    /// Every kind, in counter order.
    pub const ALL: [RayKind; 6] = [
        RayKind::Primary,
        RayKind::Shadow,
        RayKind::SoftShadow,
        RayKind::Reflection,
        RayKind::Refraction,
        RayKind::Alpha,
    ];

    /// The kind's name in reports.
    pub fn name(self) -> &'static str {
        match self {
            RayKind::Primary => "primary",
            RayKind::Shadow => "shadow",
            RayKind::SoftShadow => "soft_shadow",
            RayKind::Reflection => "reflection",
            RayKind::Refraction => "refraction",
            RayKind::Alpha => "alpha",
        }
    }
}

/// Rays traced, per kind.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RayCounts([u64; 6]);

impl RayCounts {
    /// Rays of `kind`.
    pub fn get(&self, kind: RayKind) -> u64 {
        self.0[kind as usize]
    }

    /// Rays of every kind together.
    pub fn total(&self) -> u64 {
        self.0.iter().sum()
    }

    #[cfg(feature = "gpu")]
    pub(crate) fn from_array(counts: [u64; 6]) -> RayCounts {
        RayCounts(counts)
    }

    fn add(&mut self, kind: RayKind, n: u64) {
        self.0[kind as usize] += n;
    }

    pub(crate) fn merge(mut self, other: RayCounts) -> RayCounts {
        for (a, b) in self.0.iter_mut().zip(other.0) {
            *a += b;
        }
        self
    }
}

/// How to render with effects.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RenderOptions {
    /// The effects to simulate: the scene's set, less any turned off. Effects the scene
    /// does not call for have nothing to act on.
    pub effects: EffectSet,
    /// Secondary rays (reflection, refraction, alpha) a path may take before it stops.
    pub max_depth: u32,
    /// Shadow rays towards area lights per shading point (per pixel for the surfaces
    /// the camera sees).
    pub soft_samples: u32,
    /// The light that comes from all around ([`Environment`]).
    pub environment: Environment,
}

impl RenderOptions {
    /// Every effect the scene calls for, depth 6, 16 soft-shadow samples, the
    /// environment [`Environment::Auto`] decides.
    pub fn for_scene(shading: &Shading) -> RenderOptions {
        RenderOptions {
            effects: EffectSet::of(shading),
            max_depth: 6,
            soft_samples: 16,
            environment: Environment::Auto,
        }
    }
}

/// Light from all around the scene: a sky ([`Sky`]) that every surface receives times
/// its diffuse albedo and its occlusion texture (no shadow rays: an ambient term, as
/// glTF viewers' image-based light looks on a diffuse surface), and which rays that
/// leave the scene see.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum Environment {
    /// [`Sky::NEUTRAL`] for scenes lit only by emissive surfaces (no punctual light; an
    /// emitter whose emission does not come through a texture), which glTF viewers
    /// light with their neutral environment: without it the surfaces that face away
    /// from the emitters are black. Scenes with punctual lights get none (their lights
    /// are what their authors set), scenes without lights the headlight.
    #[default]
    Auto,
    /// None: direct light only (the lights, the emitters, or the headlight), rays that
    /// leave the scene see the dark background.
    Off,
    /// This sky, for any scene; the headlight is then off.
    Sky(Sky),
}

/// A sky whose radiance along a unit direction `d` is `radiance (1 + gradient d.y)`:
/// brighter above than below (glTF's up is `+y`), uniform for a gradient of 0. A diffuse
/// surface of unit normal `n` receives `radiance (1 + 2/3 gradient n.y)` from it (times
/// pi: the cosine-weighted integral of a radiance linear in the direction), exactly.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sky {
    /// The radiance at the horizon, each channel; at least 0.
    pub radiance: f32,
    /// How much brighter the zenith is (and darker the nadir), in `[0, 1]`.
    pub gradient: f32,
}

impl Sky {
    /// The neutral sky [`Environment::Auto`] gives: radiance 0.75 above, 0.5 at the
    /// horizon, 0.25 below, so that a metal shows it where a uniform sky would make it
    /// look like the background.
    pub const NEUTRAL: Sky = Sky { radiance: 0.5, gradient: 0.5 };

    /// A uniform sky of `radiance`.
    pub fn uniform(radiance: f32) -> Sky {
        Sky { radiance, gradient: 0.0 }
    }

    /// The radiance seen along unit direction `d`.
    pub(crate) fn seen(&self, d: Vec3) -> f32 {
        self.radiance * (1.0 + self.gradient * d.y)
    }

    /// What a diffuse surface of unit normal `n` receives, over pi.
    pub(crate) fn received(&self, n: Vec3) -> f32 {
        self.radiance * (1.0 + self.gradient * (2.0 / 3.0) * n.y)
    }
}

impl Environment {
    /// What lights the scene besides its `lights` and `emitters`: whether the headlight
    /// does ([`Emitters::need_headlight`], when no sky does), and the sky, if any (its
    /// values made valid). The CPU renderer and the GPU kernel both ask this.
    pub(crate) fn resolve(self, lights: &[Light], emitters: &Emitters) -> (bool, Option<Sky>) {
        let sky = match self {
            Environment::Off => None,
            Environment::Sky(sky) => Some(Sky {
                radiance: if sky.radiance.is_finite() { sky.radiance.max(0.0) } else { 0.0 },
                gradient: if sky.gradient.is_finite() { sky.gradient.clamp(0.0, 1.0) } else { 0.0 },
            }),
            Environment::Auto => (lights.is_empty() && emitters.untextured()).then_some(Sky::NEUTRAL),
        };
        (emitters.need_headlight(lights) && sky.is_none(), sky)
    }
}

/// The light a pixel receives, summed term by term (background, emission, each light
/// a surface receives) in 32.32 fixed point per channel: integer additions, so the sum
/// does not depend on the order the terms arrive in. The CPU adds them wave by wave,
/// the GPU kernel ray tree by ray tree (`gpu/render.wgsl`'s `add_light`, the same
/// conversion in 32-bit halves); with the same terms both get the same bits. Each term
/// is rounded down to a multiple of `2^-32` (a term below that, or not positive, adds
/// nothing) and the sum saturates at `2^32`: far finer and far wider than any image of
/// it (sRGB's first 8-bit step is about `3e-4`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct LightSum(pub(crate) [u64; 3]);

/// `2^32`, the fixed point's one.
const FIXED_ONE: f32 = 4_294_967_296.0;

impl LightSum {
    /// Adds one term.
    pub(crate) fn add(&mut self, term: Vec3) {
        for (sum, x) in self.0.iter_mut().zip(term.to_array()) {
            let fixed = if x.is_nan() || x <= 0.0 {
                0
            } else if x >= FIXED_ONE {
                u64::MAX
            } else {
                // Exact: a power-of-two scaling below 2^64; then rounded down.
                (x * FIXED_ONE) as u64
            };
            *sum = sum.saturating_add(fixed);
        }
    }

    /// The sum as radiance.
    pub(crate) fn radiance(&self) -> Vec3 {
        Vec3::from_array(self.0.map(|s| (s as f64 / FIXED_ONE as f64) as f32))
    }
}

/// A linear-light image: radiance per pixel.
#[derive(Clone, Debug, PartialEq)]
pub struct Radiance {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Linear RGB radiance, row by row from the top.
    pub pixels: Vec<Vec3>,
}

impl Radiance {
    /// The radiance of pixel `(x, y)`.
    pub fn at(&self, x: u32, y: u32) -> Vec3 {
        self.pixels[(y * self.width + x) as usize]
    }

    /// An 8-bit sRGB image: each channel clamped to `[0, 1]` and encoded with the sRGB
    /// transfer function.
    pub fn to_image(&self) -> Image {
        let encode = |x: f32| {
            let x = if x.is_nan() { 0.0 } else { x.clamp(0.0, 1.0) };
            let s = if x <= 0.003_130_8 { 12.92 * x } else { 1.055 * x.powf(1.0 / 2.4) - 0.055 };
            (s * 255.0 + 0.5) as u8
        };
        let rgb = self.pixels.iter().flat_map(|p| p.to_array().map(encode)).collect();
        Image { width: self.width, height: self.height, rgb }
    }
}

/// What lights the scene: its punctual lights and emissive triangles, or, when it has
/// neither, a headlight at the camera that casts no shadows.
struct Context<'a, S: Stage> {
    stage: &'a S,
    camera: &'a Camera,
    options: RenderOptions,
    emitters: Emitters,
    headlight: bool,
    /// The environment's sky ([`Environment`]), if any.
    environment: Option<Sky>,
    /// Whether some material is single-sided ([`Material::double_sided`]): camera and
    /// shadow rays then pass through the backs of such surfaces.
    culling: bool,
}

/// Colour of rays that leave the scene.
const BACKGROUND: Vec3 = Vec3::new(0.08, 0.08, 0.1);
/// Ambient and direct parts of the headlight (the `shaded` look of scenes without lights).
const HEADLIGHT: (f32, f32) = (0.1, 0.85);
/// Shadow rays towards area lights stop this far short of the light (a fraction of
/// the distance), so they do not find the emitter itself.
const AREA_SHADOW_END: f32 = 1.0 - 1e-3;
/// Shadow rays traced together at most (plus one shading point's): what bounds a
/// tile's memory in a scene of many lights.
const SHADOW_CHUNK: usize = 4096;

/// Alpha layers a shadow ray may pass through before it counts as blocked.
const MAX_SHADOW_LAYERS: u32 = 16;

/// Backs of single-sided surfaces a camera ray may pass through before it counts as
/// seeing nothing.
const MAX_CULLED_LAYERS: u32 = 16;

/// Whether a scene's renders pass through the backs of some surfaces: it has a
/// single-sided material. The CPU renderer and the GPU kernel (its `CULLING` constant)
/// both ask this.
pub(crate) fn culls(shading: &Shading) -> bool {
    shading.materials.iter().any(|m| !m.double_sided)
}

/// A ray of a wave and what it carries to its pixel.
struct Task {
    ray: Ray,
    pixel: u32,
    weight: Vec3,
    depth: u32,
    kind: RayKind,
}

/// A shadow ray: `value` reaches its pixel if nothing blocks it.
struct ShadowTask {
    ray: Ray,
    pixel: u32,
    value: Vec3,
    kind: RayKind,
    layers: u32,
}

/// Rows a CPU work item renders.
const TILE_ROWS: u32 = 8;

/// Renders `scene` through `camera` with the effects of `options`, on all cores,
/// calling `progress` with the number of rows done as rows complete.
///
/// The image depends on the scene, camera and options only (not on the thread count).
///
/// # Example
/// ```
/// use octrace_runtime::raysets::{Camera, Frame};
/// use octrace_runtime::render::effects::{render_effects, RayKind, RenderOptions};
/// let mesh = octrace_bake::procedural::sphere([0.0; 3], 1.0, 8, 12);
/// let scene = octrace_runtime::Scene::from_baked(octrace_bake::bake(&mesh, &Default::default())?)?;
/// let b = scene.view().bounds;
/// let camera = Camera::standard_sized(&Frame::from_bounds(b.mesh_lo, b.mesh_hi), 32, 32);
/// let options = RenderOptions::for_scene(scene.shading());
/// let (radiance, counts) = render_effects(&scene, &camera, &options, &|_| {});
/// assert_eq!(counts.get(RayKind::Primary), 32 * 32);
/// assert_eq!(counts.get(RayKind::Shadow), 0); // no lights: a headlight, no shadow rays
/// radiance.to_image();
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn render_effects(
    scene: &Scene,
    camera: &Camera,
    options: &RenderOptions,
    progress: &(dyn Fn(u32) + Sync),
) -> (Radiance, RayCounts) {
    let stage = SceneStage { view: scene.view(), tracer: super::renderers_tracer(scene) };
    render_stage(&stage, camera, options, progress)
}

/// [`render_effects`] of a world of instances: each hit's corners, normals and
/// tangents carried to the world, its materials and textures its own scene's; lit by
/// the instances' punctual lights and emissive triangles, placed with them, else by
/// the environment or the headlight as a scene is. The same effects as a scene
/// (`options`).
///
/// # Errors
/// [`crate::Error::Budget`] where the instances' placed lights and emissive triangles
/// (each instance's copies of its scene's) would take more than 1 GiB;
/// [`crate::Error::Alloc`] where their memory cannot be had.
///
/// # Example
/// ```
/// use std::sync::Arc;
/// use octrace_runtime::raysets::{Camera, Frame};
/// use octrace_runtime::render::effects::{render_effects_world, RayKind, RenderOptions};
/// use octrace_runtime::world::{Transform, World};
/// let mesh = octrace_bake::procedural::sphere([0.0; 3], 1.0, 8, 12);
/// let ball = Arc::new(octrace_runtime::Scene::from_baked(octrace_bake::bake(&mesh, &Default::default())?)?);
/// let mut world = World::new();
/// world.add(&ball, Transform::translation([-1.5, 0.0, 0.0]))?;
/// world.add(&ball, Transform::translation([1.5, 0.0, 0.0]))?;
/// world.commit();
/// let camera = Camera::standard_sized(&Frame::from_bounds([-2.5, -1.0, -1.0], [2.5, 1.0, 1.0]), 32, 16);
/// let (radiance, counts) = render_effects_world(&world, &camera, &RenderOptions::for_scene(ball.shading()), &|_| {})?;
/// assert_eq!(counts.get(RayKind::Primary), 32 * 16);
/// radiance.to_image();
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn render_effects_world(
    world: &World,
    camera: &Camera,
    options: &RenderOptions,
    progress: &(dyn Fn(u32) + Sync),
) -> crate::Result<(Radiance, RayCounts)> {
    Ok(render_stage(&WorldStage::new(world)?, camera, options, progress))
}

/// The effects render of `stage`, tiles on all cores.
fn render_stage<S: Stage>(
    stage: &S,
    camera: &Camera,
    options: &RenderOptions,
    progress: &(dyn Fn(u32) + Sync),
) -> (Radiance, RayCounts) {
    let ctx = Context::new(stage, camera, options);
    let rows_done = AtomicU32::new(0);
    let tiles: Vec<(Vec<Vec3>, RayCounts)> = (0..camera.height.div_ceil(TILE_ROWS))
        .into_par_iter()
        .map(|tile| {
            let rows = tile * TILE_ROWS..((tile + 1) * TILE_ROWS).min(camera.height);
            let n = rows.len() as u32;
            let pixels = rows.start * camera.width..rows.end * camera.width;
            let out = ctx.run(pixels);
            progress(rows_done.fetch_add(n, Ordering::Relaxed) + n);
            out
        })
        .collect();
    let mut counts = RayCounts::default();
    let mut pixels = Vec::with_capacity((camera.width * camera.height) as usize);
    for (p, c) in tiles {
        pixels.extend(p);
        counts = counts.merge(c);
    }
    (Radiance { width: camera.width, height: camera.height, pixels }, counts)
}

/// [`render_effects`] on the GPU, tracing and shading in one kernel made for the
/// options' effects ([`GpuRenderer`](crate::gpu::GpuRenderer)): the same image up to
/// rounding, the same rays.
///
/// # Errors
/// The GPU's errors.
#[cfg(feature = "gpu")]
pub fn render_effects_gpu(
    gpu: &crate::gpu::GpuTracer<'_>,
    camera: &Camera,
    options: &RenderOptions,
) -> crate::gpu::GpuResult<(Radiance, RayCounts)> {
    crate::gpu::GpuRenderer::new(gpu, options)?.render(camera)
}

/// [`render_effects`] for some pixels only (row-major indices, in any order): their
/// radiance in that order and the rays traced. Each pixel is rendered alone, which
/// gives the bits it gets in the whole image (a pixel's sums do not depend on its
/// neighbours'). For the GPU renderer's pixels that an adapter's loop cap stopped.
#[cfg(feature = "gpu")]
pub(crate) fn render_pixels(
    scene: &Scene,
    camera: &Camera,
    options: &RenderOptions,
    pixels: &[u32],
) -> (Vec<Vec3>, RayCounts) {
    let stage = SceneStage { view: scene.view(), tracer: super::renderers_tracer(scene) };
    let ctx = Context::new(&stage, camera, options);
    let done: Vec<(Vec3, RayCounts)> = pixels.par_iter().map(|&p| ctx.run(p..p + 1)).map(|(r, c)| (r[0], c)).collect();
    let counts = done.iter().fold(RayCounts::default(), |a, (_, c)| a.merge(*c));
    (done.into_iter().map(|(r, _)| r).collect(), counts)
}

impl<'a, S: Stage> Context<'a, S> {
    fn new(stage: &'a S, camera: &'a Camera, options: &RenderOptions) -> Context<'a, S> {
        let emitters = stage.emitters();
        let (headlight, environment) = options.environment.resolve(stage.lights(), &emitters);
        let culling = stage.culls();
        Context { stage, camera, options: *options, emitters, headlight, environment, culling }
    }

    /// The arrays of `instance`'s scene.
    fn view(&self, instance: u32) -> &'a SceneView<'a> {
        self.stage.view(instance)
    }

    /// The front's normal of the hit triangle, from its corners in the stage's space
    /// (turned where the instance mirrors: its corners then run the other way).
    fn front_normal(&self, instance: u32, prim: StoredIndex) -> Vec3 {
        let n = face_normal(&self.stage.triangle(instance, prim));
        if self.stage.mirrored(instance) {
            -n
        } else {
            n
        }
    }

    /// Whether `hit` is on the back of a single-sided surface, seen along `dir`: the
    /// view meets the triangle against its winding (the geometric normal, from the
    /// stored corners, along `dir`). A camera ray looks along its direction; a shadow
    /// ray is the light's view the other way.
    fn culled(&self, h: &S::Hit, dir: Vec3) -> bool {
        let (instance, prim) = (S::instance(h), S::hit(h).prim);
        self.culling && !self.material(instance, prim).double_sided && self.front_normal(instance, prim).dot(dir) > 0.0
    }

    /// Carries camera rays (and the alpha rays that continue them) past the backs of
    /// single-sided surfaces: each such hit is traced again from beyond it, the same
    /// ray (not counted again), up to [`MAX_CULLED_LAYERS`] times, after which the ray
    /// sees nothing.
    fn pass_back_faces(&self, wave: &[Task], hits: &mut [Option<S::Hit>]) {
        if !self.culling {
            return;
        }
        for (task, hit) in wave.iter().zip(hits.iter_mut()) {
            if !matches!(task.kind, RayKind::Primary | RayKind::Alpha) {
                continue;
            }
            let mut layers = 0;
            while let Some(h) = *hit {
                if !self.culled(&h, task.ray.dir) {
                    break;
                }
                if layers == MAX_CULLED_LAYERS {
                    *hit = None;
                    break;
                }
                layers += 1;
                let (instance, hit_) = (S::instance(&h), S::hit(&h));
                let at = SpawnPoint::new(&self.stage.triangle(instance, hit_.prim), &hit_);
                *hit = self.stage.intersect(&at.ray(task.ray.dir, f32::INFINITY));
            }
        }
    }

    /// What a ray along `dir` that leaves the scene sees: the sky, else the background.
    fn background(&self, dir: Vec3) -> Vec3 {
        self.environment.map_or(BACKGROUND, |sky| Vec3::splat(sky.seen(dir.normalize())))
    }

    fn has(&self, effect: Effect) -> bool {
        self.options.effects.contains(effect)
    }

    /// Renders pixels `pixels` (row-major indices) wave by wave.
    fn run(&self, pixels: std::ops::Range<u32>) -> (Vec<Vec3>, RayCounts) {
        let first = pixels.start;
        let mut out = vec![LightSum::default(); pixels.len()];
        let mut counts = RayCounts::default();
        let w = self.camera.width;
        let mut wave: Vec<Task> = pixels
            .map(|p| Task {
                ray: self.camera.ray(p % w, p / w),
                pixel: p,
                weight: Vec3::ONE,
                depth: 0,
                kind: RayKind::Primary,
            })
            .collect();
        while !wave.is_empty() {
            for t in &wave {
                counts.add(t.kind, 1);
            }
            let rays: Vec<Ray> = wave.iter().map(|t| t.ray).collect();
            let mut hits = self.stage.intersect_batch(&rays);
            self.pass_back_faces(&wave, &mut hits);
            let (mut next, mut shadows) = (Vec::new(), Vec::new());
            for (task, hit) in wave.iter().zip(hits) {
                let sum = &mut out[(task.pixel - first) as usize];
                match hit {
                    None => sum.add(task.weight * self.background(task.ray.dir)),
                    Some(hit) => self.shade(task, &hit, sum, &mut next, &mut shadows),
                }
                // Shadow rays in chunks, whatever the number of lights: a tile's memory
                // is its pixels' and one chunk's (the sums are exact and commute, so
                // the image does not depend on where a chunk ends).
                if shadows.len() >= SHADOW_CHUNK {
                    self.trace_shadows(std::mem::take(&mut shadows), &mut out, first, &mut counts);
                }
            }
            self.trace_shadows(shadows, &mut out, first, &mut counts);
            wave = next;
        }
        (out.iter().map(LightSum::radiance).collect(), counts)
    }

    /// Traces shadow rays and adds the light of those that get through. With the alpha
    /// or refraction effects, a shadow ray that meets a cut-out, blended or
    /// transmissive surface goes on past it, dimmed by what the surface lets through.
    fn trace_shadows(&self, mut shadows: Vec<ShadowTask>, out: &mut [LightSum], first: u32, counts: &mut RayCounts) {
        while !shadows.is_empty() {
            for s in &shadows {
                counts.add(s.kind, 1);
            }
            let rays: Vec<Ray> = shadows.iter().map(|s| s.ray).collect();
            if !self.has(Effect::Alpha) && !self.has(Effect::Refraction) && !self.culling {
                let blocked = self.stage.occluded_batch(&rays);
                for (s, blocked) in shadows.iter().zip(blocked) {
                    if !blocked {
                        out[(s.pixel - first) as usize].add(s.value);
                    }
                }
                return;
            }
            let mut next = Vec::new();
            for (s, hit) in shadows.iter().zip(self.stage.intersect_batch(&rays)) {
                let Some(h) = hit else {
                    out[(s.pixel - first) as usize].add(s.value);
                    continue;
                };
                // A single-sided surface whose back the light sees casts no shadow
                // (seen from the light, the ray runs the other way).
                let pass = if self.culled(&h, -s.ray.dir) { Vec3::ONE } else { self.shadow_pass(&self.surface(&h)) };
                if pass.max_element() > 0.0 && s.layers < MAX_SHADOW_LAYERS {
                    let hit = S::hit(&h);
                    let tri = self.stage.triangle(S::instance(&h), hit.prim);
                    let ray = spawn(&tri, &hit, s.ray.dir, s.ray.tmax - hit.t);
                    next.push(ShadowTask { ray, value: s.value * pass, layers: s.layers + 1, ..*s });
                }
            }
            shadows = next;
        }
    }

    /// What a shadow ray keeps of its light past a surface of `m`: what the alpha
    /// coverage leaves, and what a transmissive material lets through.
    fn shadow_pass(&self, m: &Material) -> Vec3 {
        let coverage = if self.has(Effect::Alpha) { m.coverage() } else { 1.0 };
        let transmitted = if self.has(Effect::Refraction) { lighting::shadow_transmittance(m) } else { Vec3::ZERO };
        Vec3::splat(1.0 - coverage) + coverage * transmitted
    }

    fn material(&self, instance: u32, prim: StoredIndex) -> &'a Material {
        self.stage.material(instance, prim).unwrap_or(&PLAIN)
    }

    /// The material at `hit`, its base colour taken where the hit is (times its
    /// texture and the vertex colour there, when there are), its emission (times its
    /// emissive texture there) and its metallic and roughness (times its
    /// metallic-roughness texture there).
    fn surface(&self, h: &S::Hit) -> Cow<'a, Material> {
        let (instance, hit) = (S::instance(h), S::hit(h));
        let m = self.material(instance, hit.prim);
        let view = self.view(instance);
        let textured =
            m.base_color_texture.is_some() || m.emissive_texture.is_some() || m.metallic_roughness_texture.is_some();
        if !textured && view.colors.is_empty() {
            return Cow::Borrowed(m);
        }
        let (prim, u, v) = (hit.prim, hit.u, hit.v);
        let base_color = view.base_color_at(m, prim, u, v);
        let emissive = view.emissive_at(m, prim, u, v);
        let (metallic, roughness) = view.metallic_roughness_at(m, prim, u, v);
        Cow::Owned(Material { name: String::new(), base_color, emissive, metallic, roughness, ..*m })
    }

    /// Adds to `sum` the light `task` receives from its hit that needs no further ray,
    /// and queues the rays that bring the rest.
    fn shade(&self, task: &Task, h: &S::Hit, sum: &mut LightSum, next: &mut Vec<Task>, shadows: &mut Vec<ShadowTask>) {
        let (instance, hit) = (S::instance(h), &S::hit(h));
        let view = self.view(instance);
        // The hit point, normal and offset, once for every ray that leaves this hit.
        let at = SpawnPoint::new(&self.stage.triangle(instance, hit.prim), hit);
        let surface = self.surface(h);
        let m = &*surface;
        let dir = task.ray.dir.normalize();
        let mut ng = at.normal();
        let entering = ng.dot(dir) < 0.0;
        if !entering {
            ng = -ng;
        }
        let n = self.shading_normal(instance, hit, ng, m);
        let can_continue = task.depth < self.options.max_depth;
        let coverage = if self.has(Effect::Alpha) { m.coverage() } else { 1.0 };
        if coverage < 1.0 && can_continue {
            next.push(Task {
                ray: at.ray(task.ray.dir, f32::INFINITY),
                weight: task.weight * (1.0 - coverage),
                depth: task.depth + 1,
                kind: RayKind::Alpha,
                ..*task
            });
        }
        if coverage <= 0.0 {
            return;
        }
        let weight = task.weight * coverage;
        if m.unlit {
            // KHR_materials_unlit: the base colour as it is, no light, no further ray.
            sum.add(weight * lighting::base(m));
            return;
        }
        let v = -dir;
        let transmits = self.has(Effect::Refraction) && m.transmission > 0.0;
        sum.add(weight * Vec3::from(m.emissive));
        if let Some(sky) = self.environment {
            // The sky, all around: an ambient term for the shading normal, darkened by
            // the occlusion texture as the headlight's is.
            let occlusion = view.occlusion_at(m, hit.prim, hit.u, hit.v);
            sum.add(weight * lighting::albedo(m, transmits) * (sky.received(n) * occlusion));
        }
        if self.headlight {
            let (ambient, direct) = HEADLIGHT;
            // The occlusion texture darkens the ambient part, the light from all around.
            let ambient = ambient * view.occlusion_at(m, hit.prim, hit.u, hit.v);
            sum.add(weight * lighting::albedo(m, transmits) * (ambient + direct * n.dot(v).abs()));
        } else {
            let mut light = |to: Vec3, tmax: f32, incident: Vec3, kind: RayKind| {
                let l = to.normalize_or_zero();
                let cos = n.dot(l);
                if cos <= 0.0 || ng.dot(l) <= 0.0 {
                    return;
                }
                let value = weight * lighting::reflectance(m, transmits, n, v, l) * incident * cos;
                // Below f32's normal range is nothing: GPUs flush it to zero.
                if value.max_element() < f32::MIN_POSITIVE {
                    return;
                }
                if self.has(Effect::Shadows) {
                    let ray = at.ray(to, tmax);
                    shadows.push(ShadowTask { ray, pixel: task.pixel, value, kind, layers: 0 });
                } else {
                    sum.add(value);
                }
            };
            let p = at.point();
            for l in self.stage.lights() {
                if let Some((to, tmax, incident)) = lighting::punctual(l, p) {
                    light(to, tmax, incident, RayKind::Shadow);
                }
            }
            if !self.emitters.is_empty() {
                self.sample_area_lights(task, p, &mut light);
            }
        }
        if can_continue {
            self.secondary(task, &at, m, (n, ng, dir), entering, weight, next);
        }
    }

    /// Light from emissive triangles: `soft_samples` points spread over them by power
    /// with soft shadows (stratified: [`lighting::stratified2`]), else the centre of
    /// one (hard shadows).
    fn sample_area_lights(&self, task: &Task, p: Vec3, light: &mut impl FnMut(Vec3, f32, Vec3, RayKind)) {
        let soft = self.has(Effect::SoftShadows);
        let samples = if soft { self.options.soft_samples.max(1) } else { 1 };
        let scale = self.emitters.total() / samples as f32;
        let grid = lighting::grid_side(samples);
        for s in 0..samples {
            let [along, across] = lighting::stratified2(task.pixel, task.depth, s, samples, grid);
            let (instance, prim, emitted, within) = self.emitters.pick(along);
            // The sample's weight: the total power over the samples and this emitter's
            // strength (its area is in the density too).
            let weight = scale / lighting::strength(emitted);
            let tri = self.stage.triangle(instance, StoredIndex(prim));
            let [a, b, c] = tri.map(Vec3::from);
            let (y, [bu, bv]) =
                if soft { lighting::point_on(&tri, within, across) } else { ((a + b + c) / 3.0, [1.0 / 3.0; 2]) };
            // The emission where the point is, through the material's emissive texture.
            let m = self.material(instance, StoredIndex(prim));
            let emitted = if m.emissive_texture.is_some() {
                Vec3::from(self.view(instance).emissive_at(m, StoredIndex(prim), bu, bv))
            } else {
                emitted
            };
            let to = y - p;
            let d2 = to.length_squared();
            let cos_y = face_normal(&tri).dot(to).abs() / d2.sqrt();
            if d2 > 0.0 && cos_y > 0.0 {
                let kind = if soft { RayKind::SoftShadow } else { RayKind::Shadow };
                light(to, AREA_SHADOW_END, emitted * (cos_y * weight / d2), kind);
            }
        }
    }

    /// Reflection and refraction rays from a hit.
    #[allow(clippy::too_many_arguments)]
    fn secondary(
        &self,
        task: &Task,
        at: &SpawnPoint,
        m: &Material,
        (n, ng, dir): (Vec3, Vec3, Vec3),
        entering: bool,
        weight: Vec3,
        next: &mut Vec<Task>,
    ) {
        let mut push = |d: Vec3, w: Vec3, kind: RayKind| {
            if w.max_element() >= VISIBLE_WEIGHT {
                let ray = at.ray(d, f32::INFINITY);
                next.push(Task { ray, pixel: task.pixel, weight: w, depth: task.depth + 1, kind });
            }
        };
        // A direction on the wrong side of the surface (a shading normal far from the
        // geometric one) is mirrored about the geometric normal instead.
        let reflect = |d: Vec3| {
            let r = d - 2.0 * d.dot(n) * n;
            if r.dot(ng) > 0.0 {
                r
            } else {
                d - 2.0 * d.dot(ng) * ng
            }
        };
        // What the surface reflects as a mirror: glass's Fresnel share (all of it under
        // total internal reflection) and a polished material's mirror colour, one ray.
        let mut reflected = Vec3::ZERO;
        if self.has(Effect::Refraction) && m.transmission > 0.0 {
            let t = m.transmission.clamp(0.0, 1.0);
            let eta = if entering { 1.0 / m.ior } else { m.ior };
            let cos_i = -dir.dot(n);
            let k = 1.0 - eta * eta * (1.0 - cos_i * cos_i);
            if k < 0.0 {
                reflected += weight * t;
            } else {
                let cos_t = k.sqrt();
                let fresnel = lighting::fresnel(cos_i, cos_t, eta);
                let refracted = eta * dir + (eta * cos_i - cos_t) * n;
                if refracted.dot(ng) < 0.0 {
                    push(refracted, weight * t * (1.0 - fresnel) * lighting::base(m), RayKind::Refraction);
                }
                reflected += weight * t * fresnel;
            }
        }
        if self.has(Effect::Reflection) {
            push(reflect(dir), reflected + weight * lighting::mirror(m), RayKind::Reflection);
        }
    }

    /// The interpolated shading normal on the side of `ng`, or `ng` when the scene has
    /// no normals (or they are degenerate there); perturbed by `m`'s normal map when it
    /// has one.
    fn shading_normal(&self, instance: u32, hit: &Hit, ng: Vec3, m: &Material) -> Vec3 {
        let n = self.interpolated_normal(instance, hit, ng);
        match m.normal_texture.and_then(|t| self.view(instance).shading.textures.get(t as usize)) {
            Some(texture) => self.mapped_normal(instance, hit, n, ng, texture, m),
            None => n,
        }
    }

    /// The corners' normals mixed at the hit and turned to `ng`'s side, else `ng`.
    fn interpolated_normal(&self, instance: u32, hit: &Hit, ng: Vec3) -> Vec3 {
        let Some(corners) = self.stage.corner_normals(instance, hit.prim) else { return ng };
        let [n0, n1, n2] = corners.map(Vec3::from);
        let n = (n0 * (1.0 - hit.u - hit.v) + n1 * hit.u + n2 * hit.v).normalize_or_zero();
        if !n.is_finite() || n == Vec3::ZERO {
            return ng;
        }
        if n.dot(ng) < 0.0 {
            -n
        } else {
            n
        }
    }

    /// Normal `n` perturbed by a normal map (glTF `normalTexture`): the texel's
    /// tangent-space normal `((2 r - 1) scale, (2 g - 1) scale, 2 b - 1)` in the frame
    /// of the tangent `t` made orthogonal to the front's normal, the bitangent
    /// `w (n x t)`, and the normal. The tangent is the corners' (`x y z w`, from the
    /// file's `TANGENT` or MikkTSpace at bake) mixed at the hit, `w` its sign; where the
    /// scene has none, the triangle's own direction of increasing `u` (from its
    /// corners' coordinates) with `w` 1, as Khronos' sample viewer builds it without
    /// tangents. On the back of the triangle (`n` faces the ray), the front's result
    /// reversed, as that viewer does. `n` itself where there is no tangent or the
    /// result is not a direction on `ng`'s side. The GPU kernel computes the same
    /// operations in the same order.
    fn mapped_normal(
        &self,
        instance: u32,
        hit: &Hit,
        n: Vec3,
        ng: Vec3,
        texture: &octrace_format::Texture,
        m: &Material,
    ) -> Vec3 {
        let view = self.view(instance);
        let scale = m.normal_scale;
        let channel = m.uv_channel(4);
        let Some([uv0, uv1, uv2]) = view.corner_uvs_in(hit.prim, channel) else { return n };
        let [p0, p1, p2] = self.stage.triangle(instance, hit.prim).map(Vec3::from);
        let (e1, e2) = (p1 - p0, p2 - p0);
        // A mirroring instance's corners run the other way round its front.
        let front_side = if self.stage.mirrored(instance) { -e1.cross(e2) } else { e1.cross(e2) };
        let back = n.dot(front_side) < 0.0;
        let front = if back { -n } else { n };
        let (t, sign) = match self.stage.corner_tangents(instance, hit.prim) {
            Some(corners) => {
                let [t0, t1, t2] = corners.map(|c| Vec3::new(c[0], c[1], c[2]));
                let w = corners[0][3] * (1.0 - hit.u - hit.v) + corners[1][3] * hit.u + corners[2][3] * hit.v;
                (t0 * (1.0 - hit.u - hit.v) + t1 * hit.u + t2 * hit.v, if w < 0.0 { -1.0 } else { 1.0 })
            }
            None => {
                let (du1, dv1, du2, dv2) = (uv1[0] - uv0[0], uv1[1] - uv0[1], uv2[0] - uv0[0], uv2[1] - uv0[1]);
                let det = du1 * dv2 - du2 * dv1;
                if det == 0.0 || !det.is_finite() {
                    return n;
                }
                ((e1 * dv2 - e2 * dv1) * if det > 0.0 { 1.0 } else { -1.0 }, 1.0)
            }
        };
        let t = (t - front * front.dot(t)).normalize_or_zero();
        if t == Vec3::ZERO || !t.is_finite() {
            return n;
        }
        let b = front.cross(t) * sign;
        let texel = texture.sample(view.texels.get(), view.uv_at_in(hit.prim, channel, hit.u, hit.v));
        let (x, y, z) = ((texel[0] * 2.0 - 1.0) * scale, (texel[1] * 2.0 - 1.0) * scale, texel[2] * 2.0 - 1.0);
        let mapped = (t * x + b * y + front * z).normalize_or_zero();
        let mapped = if back { -mapped } else { mapped };
        // A map that tips the normal below the surface: the interpolated normal.
        if mapped == Vec3::ZERO || !mapped.is_finite() || mapped.dot(ng) <= 0.0 {
            n
        } else {
            mapped
        }
    }
}
