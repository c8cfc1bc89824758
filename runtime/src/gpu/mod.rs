//! Tracing on the GPU with wgpu (cargo feature `gpu`, on by default).
//!
//! [`GpuTracer`] uploads a scene's arrays as they are in the file (no re-encoding) and
//! walks the octree in a WGSL compute kernel that is the CPU's scalar step, line for
//! line: cube-map entry, Plücker exit face, neighbour index, point location for
//! origins inside the scene, the watertight triangle test. Its answers are the CPU's
//! (the tests compare every ray of the standard sets).
//!
//! [`GpuRenderer`] renders the effects renderer's image in one kernel on top of that
//! walk, tracing and shading, compiled for the effects in play (WGSL override
//! constants): the CPU's image and ray counts.
//!
//! The backend is Vulkan, asked for explicitly: a machine without a Vulkan driver gets
//! [`GpuError::NoAdapter`], not a silent fallback. Without a GPU, Mesa's software
//! driver (lavapipe; Debian's `mesa-vulkan-drivers`) runs the same kernel on the CPU.
//!
//! # Example
//! ```no_run
//! use octrace_runtime::gpu::{GpuContext, GpuTracer};
//! use octrace_runtime::{Ray, Scene};
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let scene = Scene::open("bunny.oct")?;
//! let gpu = GpuContext::new()?;
//! let tracer = GpuTracer::new(&gpu.device, &gpu.queue, &scene)?;
//! let rays = [Ray::new(glam::Vec3::new(0.0, 0.1, 1.0), glam::Vec3::NEG_Z)];
//! let hits = tracer.intersect(&rays)?;
//! println!("{:?} on {}", hits[0], gpu.info.name);
//! # Ok(()) }
//! ```

mod buffers;
mod crossings;
mod device;
mod render;
mod source;
mod spirv;

use std::time::{Duration, Instant};

pub use buffers::MAX_SCENE_BINDINGS;
pub use device::{lockstep_lanes, loop_cap, GpuContext};
pub use render::{GpuRenderer, MAX_GPU_DEPTH};

use buffers::{bind_group_layout, check_bindings, offsets_of, upload, TRACE_ARRAYS, TRACE_EXTRA_BINDINGS};
use device::{dispatch_once, read_buffer, read_buffer_append, wait, Budget, Stopwatch};
use source::shader_source;

use crate::ray::{Hit, Ray};
use crate::Scene;
use crate::WalkStats;
use octrace_format::StoredIndex;

/// What can go wrong on the GPU path.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum GpuError {
    /// No Vulkan adapter: no GPU driver, and no software one.
    #[error(
        "no Vulkan adapter found ({0}); install a GPU driver, or Mesa's software driver \
         (Debian: mesa-vulkan-drivers)"
    )]
    NoAdapter(String),
    /// The adapter refused the device or a resource.
    #[error("GPU device: {0}")]
    Device(String),
    /// The scene does not fit the adapter's limits.
    #[error("the scene does not fit this GPU: {0}")]
    TooLarge(String),
    /// A request the GPU path does not serve.
    #[error("not on the GPU: {0}")]
    Unsupported(String),
    /// The scene's data cannot be used (a texture's image that does not decode).
    #[error("{0}")]
    Scene(String),
}

/// The GPU result type.
pub type GpuResult<T> = std::result::Result<T, GpuError>;

/// Options of [`GpuTracer::with_options`].
#[derive(Clone, Copy, Debug, Default)]
pub struct GpuOptions {
    /// The largest storage binding to use, in bytes (default: the device's limit). The
    /// scene's words are split across as many bindings as this takes; smaller values
    /// exercise the split on scenes that would fit one.
    pub max_binding_bytes: Option<u64>,
}

/// The kernel's uniform block (`Params` in trace.wgsl).
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    ray_count: u32,
    max_depth: u32,
    max_steps: u32,
    cube_level: u32,
    root_node: u32,
    offsets: [u32; 7],
    /// The fans' words (`o_fans`), and whether there are any (`fans`; the kernel's
    /// `FANS` constant says the same), then padding to the vectors' alignment.
    o_fans: u32,
    fans: u32,
    pad: [u32; 2],
    root_lo: [f32; 4],
    root_hi: [f32; 4],
    box_lo: [f32; 4],
    box_hi: [f32; 4],
}

/// The kernel's output record (`HitOut` in trace.wgsl).
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
struct HitOut {
    t: f32,
    triangle: u32,
    u: f32,
    v: f32,
    leaf: u32,
    prim: u32,
    steps: u32,
    flags: u32,
}

/// Rays a dispatch takes at most (and at most 65,535 workgroups of [`Budget::workgroup`]).
const RAYS_PER_DISPATCH: usize = 1 << 21;
/// Traces rays through one scene on the GPU.
///
/// Where the adapter caps the loop iterations of a shader invocation ([`loop_cap`]:
/// lavapipe), a walk that would need more than the cap is traced again on the CPU, from
/// the same scene: the answers are whole whatever the adapter.
#[derive(Debug)]
pub struct GpuTracer<'s> {
    scene: &'s Scene,
    cap: Option<u32>,
    budget: Budget,
    device: wgpu::Device,
    queue: wgpu::Queue,
    nearest: wgpu::ComputePipeline,
    any: wgpu::ComputePipeline,
    /// How kernels are compiled on this device, the layout the crossing kernels are
    /// made with on first use (`crossings`), and those kernels: counts, lists.
    compiler: spirv::Compiler,
    pipeline_layout: wgpu::PipelineLayout,
    crossing_kernels: std::sync::OnceLock<Result<[wgpu::ComputePipeline; 2], String>>,
    layout: wgpu::BindGroupLayout,
    scene_buffers: Vec<wgpu::Buffer>,
    params: Params,
    chunk_words: u64,
    /// Whether the scene has fans (the kernels' `FANS` constant).
    fans: bool,
    f64_edges: bool,
    stopwatch: Option<Stopwatch>,
    compile: Duration,
}

/// Timings of one batch, for benchmarks.
#[derive(Clone, Copy, Debug, Default)]
pub struct GpuTimings {
    /// Uploading the rays.
    pub upload: Duration,
    /// The kernel, as the host sees it: from submitting its dispatches to their end
    /// (the submission's and the wait's latency included).
    pub kernel: Duration,
    /// The kernel on the device: from the first to the last timestamp of each dispatch
    /// (`None` where the adapter has no timestamp queries).
    pub kernel_device: Option<Duration>,
    /// Reading the hits back.
    pub download: Duration,
}

impl<'s> GpuTracer<'s> {
    /// Uploads `scene` to `device` and builds the kernels.
    ///
    /// # Errors
    /// [`GpuError::TooLarge`] when the scene needs more bindings or a larger buffer
    /// than the device allows; [`GpuError::Device`] for a refused resource.
    pub fn new(device: &wgpu::Device, queue: &wgpu::Queue, scene: &'s Scene) -> GpuResult<GpuTracer<'s>> {
        Self::with_options(device, queue, scene, GpuOptions::default())
    }

    /// [`GpuTracer::new`] with options.
    ///
    /// # Errors
    /// As [`GpuTracer::new`].
    pub fn with_options(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        scene: &'s Scene,
        options: GpuOptions,
    ) -> GpuResult<GpuTracer<'s>> {
        let view = scene.view();
        let limits = device.limits();
        let binding_limit = limits.max_storage_buffer_binding_size.min(limits.max_buffer_size);
        let max_binding = options.max_binding_bytes.map_or(binding_limit, |m| m.min(binding_limit));
        // Chunks of a power-of-two number of words, so the kernel splits an index with a
        // shift and a mask.
        let chunk_words = 1u64 << (max_binding / 4).max(1).ilog2().min(31);
        // The tracing arrays: the file's first seven sections (the shading arrays that
        // follow are the host's business), and the fans' hierarchies.
        let words = view.section_words();
        let fan_words = crate::cpu::FanIndex::gpu_words(&view);
        let arrays: [&[u32]; TRACE_ARRAYS] =
            std::array::from_fn(|i| if i + 1 < TRACE_ARRAYS { words[i] } else { &fan_words[..] });
        let fans = !fan_words.is_empty();
        let offsets = offsets_of(&arrays)?;
        let chunks = offsets.total.div_ceil(chunk_words).max(1);
        // The rays and hits take two storage bindings besides the scene's, and the
        // parameters a uniform one; the render kernel adds its own (`render::check_bindings`).
        check_bindings(&limits, chunks, TRACE_EXTRA_BINDINGS, offsets.total * 4, chunk_words * 4)?;
        let scene_buffers = upload(device, queue, &arrays, offsets.total, chunk_words);
        let f64_edges = device.features().contains(wgpu::Features::SHADER_F64);
        let cap = loop_cap(device, queue)?;
        let lanes = match cap {
            Some(cap) => lockstep_lanes(device, queue, cap)?,
            None => 1,
        };
        let budget = Budget::for_cap(cap, lanes);
        let compiler = spirv::Compiler::for_device(device, queue)?;
        let compiling = Instant::now();
        let source = shader_source(scene_buffers.len(), chunk_words, f64_edges, budget);
        let layout = bind_group_layout(device, chunks as usize);
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("octrace trace"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let pipeline = |any: bool| {
            let label = if any { "octrace occluded" } else { "octrace intersect" };
            compiler.pipeline(
                device,
                &pipeline_layout,
                &source,
                "main",
                &[("ANY_HIT", if any { 1.0 } else { 0.0 }), ("FANS", if fans { 1.0 } else { 0.0 })],
                label,
            )
        };
        let (nearest, any) = (pipeline(false)?, pipeline(true)?);
        let compile = compiling.elapsed();
        let b = view.bounds;
        let (root_lo, root_hi) = crate::cpu::root_corners(&view);
        // As the CPU tracer: a depth beyond the format's (a hostile file on the trusted
        // path) is walked as the format's limit. (WGSL bounds-checks every buffer read.)
        let max_depth = view.params.max_depth.min(octrace_format::layout::MAX_LEVEL);
        let (lo, hi) = crate::cpu::mesh_box(&view);
        let rule = crate::cpu::tables::RuleScale::of(root_lo, root_hi, b.root_size);
        let params = Params {
            ray_count: 0,
            max_depth,
            max_steps: crate::Tracer::new(view.clone()).max_steps(),
            cube_level: view.params.cube_level.min(max_depth),
            root_node: view.root,
            offsets: [
                offsets.octree,
                offsets.refs,
                offsets.tris,
                offsets.ids,
                offsets.boxes,
                offsets.cube,
                offsets.nodes,
            ],
            o_fans: offsets.fans,
            fans: fans as u32,
            pad: [0; 2],
            root_lo: [root_lo[0], root_lo[1], root_lo[2], b.root_size],
            root_hi: [root_hi[0], root_hi[1], root_hi[2], ((1u64 << max_depth) as f64 / b.root_size as f64) as f32],
            box_lo: [lo[0], lo[1], lo[2], rule.root as f32],
            box_hi: [hi[0], hi[1], hi[2], rule.reach as f32],
        };
        Ok(GpuTracer {
            scene,
            cap,
            budget,
            device: device.clone(),
            queue: queue.clone(),
            nearest,
            any,
            compile,
            compiler,
            pipeline_layout,
            crossing_kernels: std::sync::OnceLock::new(),
            layout,
            scene_buffers,
            params,
            chunk_words,
            fans,
            f64_edges,
            stopwatch: Stopwatch::new(device, queue),
        })
    }

    /// How many storage bindings the scene's words take (1 unless the scene is larger
    /// than one binding may be).
    pub fn scene_bindings(&self) -> usize {
        self.scene_buffers.len()
    }

    /// Words a scene binding holds.
    pub fn words_per_binding(&self) -> u64 {
        self.chunk_words
    }

    /// Whether the kernel runs its `f64` paths: where the adapter has 64-bit floats.
    /// Then every product of the triangle test is exact in `f64` and rounded to `f32`
    /// once, as the CPU rounds it, whatever the compiler fuses (so edge functions and
    /// barycentrics are the CPU's bits, and a shared edge is watertight); exact zeros
    /// are decided in `f64`, as on the CPU; point location and hit distances are the
    /// CPU's `f64` computations (`cpu::watertight::plane_distance`, in the same order).
    /// Without `f64` they are computed in `f32`: long thin triangles lose precision,
    /// the last bits are the adapter's, and a shared edge stays watertight only where
    /// the compiler does not fuse a product into the edge function's subtraction.
    pub fn uses_f64(&self) -> bool {
        self.f64_edges
    }

    /// The nearest hit of each ray, in ray order.
    ///
    /// # Errors
    /// [`GpuError::Device`] if the device is lost or a buffer cannot be read.
    pub fn intersect(&self, rays: &[Ray]) -> GpuResult<Vec<Option<Hit>>> {
        Ok(self.run(rays, false)?.0.iter().map(to_hit).collect())
    }

    /// Whether each ray hits anything in `[tmin, tmax]`, in ray order.
    ///
    /// # Errors
    /// As [`GpuTracer::intersect`].
    pub fn occluded(&self, rays: &[Ray]) -> GpuResult<Vec<bool>> {
        Ok(self.run(rays, true)?.0.iter().map(|h| h.triangle != u32::MAX).collect())
    }

    /// [`GpuTracer::intersect`] with what each walk did (leaves visited, triangle tests,
    /// whether the step bound stopped it), as the CPU's `Tracer::intersect_with_stats`.
    ///
    /// # Errors
    /// As [`GpuTracer::intersect`].
    pub fn intersect_with_stats(&self, rays: &[Ray]) -> GpuResult<Vec<(Option<Hit>, WalkStats)>> {
        let stats = |h: &HitOut| WalkStats {
            leaves: h.steps,
            triangle_tests: h.flags >> 1,
            stopped_at_bound: h.flags & 1 != 0,
        };
        Ok(self.run(rays, false)?.0.iter().map(|h| (to_hit(h), stats(h))).collect())
    }

    /// [`GpuTracer::intersect`] (or, with `any`, the occluder of each ray) with the
    /// time each part took.
    ///
    /// # Errors
    /// As [`GpuTracer::intersect`].
    pub fn trace_timed(&self, rays: &[Ray], any: bool) -> GpuResult<(Vec<Option<Hit>>, GpuTimings)> {
        let (out, timings) = self.run(rays, any)?;
        Ok((out.iter().map(to_hit).collect(), timings))
    }

    /// How long making the tracing kernels took (WGSL to the driver's pipelines; a
    /// driver may finish compiling at the first dispatch, which the first batch's
    /// timings then hold).
    pub fn compile_time(&self) -> Duration {
        self.compile
    }

    /// Whether the kernels were compiled here to SPIR-V with every float operation
    /// marked `NoContraction` (where the device takes SPIR-V as it is: every Vulkan
    /// device), so that no driver fuses a multiply into an add the CPU rounds apart.
    pub fn unfused(&self) -> bool {
        self.compiler.passthrough
    }

    /// Whether the kernels keep f32 subnormals, as the CPU does (a driver may flush
    /// them to zero; NVIDIA's does unless asked not to, which these kernels ask where
    /// the driver honours it).
    pub fn keeps_subnormals(&self) -> bool {
        self.compiler.denormals
    }

    /// Whether kernels are timed on the device ([`GpuTimings::kernel_device`]).
    pub fn has_timestamps(&self) -> bool {
        self.stopwatch.is_some()
    }

    /// Under a loop cap, the loop iterations each invocation may run before its ray or
    /// pixel is finished on the CPU (the cap shared by [`lockstep_lanes`], halved).
    pub fn lane_budget(&self) -> Option<u32> {
        self.cap.map(|_| self.budget.loops)
    }

    /// The loop cap of the adapter this tracer runs on, if it has one ([`loop_cap`]).
    pub fn loop_cap(&self) -> Option<u32> {
        self.cap
    }

    /// The scene this tracer traces.
    pub fn scene(&self) -> &'s Scene {
        self.scene
    }

    /// How the kernels bound their loops.
    pub(super) fn budget(&self) -> Budget {
        self.budget
    }

    /// Runs the kernel over `rays` in dispatches of at most [`RAYS_PER_DISPATCH`]; the
    /// walks that ran out of loop budget are traced again on the CPU.
    fn run(&self, rays: &[Ray], any: bool) -> GpuResult<(Vec<HitOut>, GpuTimings)> {
        let (mut out, timings) = self.run_kernel(rays, if any { &self.any } else { &self.nearest })?;
        let tracer = self.scene.tracer();
        for (h, r) in out.iter_mut().zip(rays).filter(|(h, _)| h.steps == OVER_BUDGET) {
            *h = if any {
                from_hit(tracer.occluder(r), WalkStats::default())
            } else {
                let (hit, stats) = tracer.intersect_with_stats(r);
                from_hit(hit, stats)
            };
        }
        Ok((out, timings))
    }

    /// The answers of `pipeline` (one record a ray) for `rays`, and the time each part
    /// took.
    fn run_kernel(&self, rays: &[Ray], pipeline: &wgpu::ComputePipeline) -> GpuResult<(Vec<HitOut>, GpuTimings)> {
        let mut out = Vec::with_capacity(rays.len());
        let mut timings = GpuTimings::default();
        if rays.is_empty() {
            return Ok((out, timings));
        }
        let per_dispatch = self.budget.per_dispatch(RAYS_PER_DISPATCH as u32) as usize;
        let batch = rays.len().min(per_dispatch);
        let ray_bytes = (batch * std::mem::size_of::<Ray>()) as u64;
        let hit_bytes = (batch * std::mem::size_of::<HitOut>()) as u64;
        use wgpu::BufferUsages as U;
        let ray_buffer = self.buffer("octrace rays", ray_bytes, U::STORAGE | U::COPY_DST);
        let hit_buffer = self.buffer("octrace hits", hit_bytes, U::STORAGE | U::COPY_SRC);
        let readback = self.buffer("octrace readback", hit_bytes, U::MAP_READ | U::COPY_DST);
        let params_buffer =
            self.buffer("octrace params", std::mem::size_of::<Params>() as u64, U::UNIFORM | U::COPY_DST);
        let bind_group = self.bind_group(&params_buffer, &ray_buffer, &hit_buffer);
        for part in rays.chunks(per_dispatch) {
            let t = Instant::now();
            let params = Params { ray_count: part.len() as u32, ..self.params };
            self.queue.write_buffer(&params_buffer, 0, bytemuck::bytes_of(&params));
            self.queue.write_buffer(&ray_buffer, 0, bytemuck::cast_slice(part));
            self.queue.submit([]);
            self.wait()?;
            timings.upload += t.elapsed();

            let t = Instant::now();
            let mut encoder = self.device.create_command_encoder(&Default::default());
            {
                let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                    label: Some("octrace trace"),
                    timestamp_writes: self.stopwatch.as_ref().map(Stopwatch::writes),
                });
                pass.set_pipeline(pipeline);
                pass.set_bind_group(0, &bind_group, &[]);
                pass.dispatch_workgroups((part.len() as u32).div_ceil(self.budget.workgroup), 1, 1);
            }
            if let Some(s) = &self.stopwatch {
                s.resolve(&mut encoder);
            }
            self.queue.submit([encoder.finish()]);
            self.wait()?;
            timings.kernel += t.elapsed();
            if let Some(s) = &self.stopwatch {
                let device = s.elapsed(&self.device, &self.queue)?;
                timings.kernel_device = Some(timings.kernel_device.unwrap_or_default() + device);
            }

            let t = Instant::now();
            let bytes = (part.len() * std::mem::size_of::<HitOut>()) as u64;
            read_buffer_append(&self.device, &self.queue, &hit_buffer, &readback, bytes, &mut out)?;
            timings.download += t.elapsed();
        }
        Ok((out, timings))
    }

    /// The kernels' `FANS` constant: 1 when the scene has fans (trace.wgsl, `fan_pick`).
    fn fans_constant(&self) -> f64 {
        if self.fans {
            1.0
        } else {
            0.0
        }
    }

    /// The kernel's source for this scene's bindings.
    fn source(&self) -> String {
        shader_source(self.scene_buffers.len(), self.chunk_words, self.f64_edges, self.budget)
    }

    /// A bind group for the tracing layout with the scene's buffers (and empty rays
    /// and hits: for kernels that trace rays of their own making).
    fn scene_bind_group(&self) -> wgpu::BindGroup {
        use wgpu::BufferUsages as U;
        let params = self.buffer("octrace params", std::mem::size_of::<Params>() as u64, U::UNIFORM | U::COPY_DST);
        self.queue.write_buffer(&params, 0, bytemuck::bytes_of(&self.params));
        let rays = self.buffer("octrace no rays", std::mem::size_of::<Ray>() as u64, U::STORAGE);
        let hits = self.buffer("octrace no hits", std::mem::size_of::<HitOut>() as u64, U::STORAGE);
        self.bind_group(&params, &rays, &hits)
    }

    /// The tracing layout's bind group: parameters, rays, hits, the scene's buffers.
    fn bind_group(&self, params: &wgpu::Buffer, rays: &wgpu::Buffer, hits: &wgpu::Buffer) -> wgpu::BindGroup {
        let mut entries = vec![
            wgpu::BindGroupEntry { binding: 0, resource: params.as_entire_binding() },
            wgpu::BindGroupEntry { binding: 1, resource: rays.as_entire_binding() },
            wgpu::BindGroupEntry { binding: 2, resource: hits.as_entire_binding() },
        ];
        for (k, b) in self.scene_buffers.iter().enumerate() {
            entries.push(wgpu::BindGroupEntry { binding: 3 + k as u32, resource: b.as_entire_binding() });
        }
        self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("octrace trace"),
            layout: &self.layout,
            entries: &entries,
        })
    }

    /// A buffer of `size` bytes (at least 4) for `usage`.
    fn buffer(&self, label: &str, size: u64, usage: wgpu::BufferUsages) -> wgpu::Buffer {
        self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: size.max(4),
            usage,
            mapped_at_creation: false,
        })
    }

    /// The first `bytes` of `buffer` (made with `COPY_SRC`), read back.
    fn read_back<T: bytemuck::Pod>(&self, buffer: &wgpu::Buffer, bytes: u64) -> GpuResult<Vec<T>> {
        read_buffer(&self.device, &self.queue, buffer, bytes)
    }

    fn wait(&self) -> GpuResult<()> {
        wait(&self.device)
    }
}

fn to_hit(h: &HitOut) -> Option<Hit> {
    (h.triangle != u32::MAX).then_some(Hit {
        t: h.t,
        triangle: h.triangle,
        u: h.u,
        v: h.v,
        leaf: h.leaf,
        prim: StoredIndex(h.prim),
    })
}

/// The kernel's record of a CPU answer (for the walks traced again on the CPU).
fn from_hit(hit: Option<Hit>, stats: WalkStats) -> HitOut {
    let flags = stats.stopped_at_bound as u32 | stats.triangle_tests.min(0x7FFF_FFFF) << 1;
    match hit {
        Some(h) => HitOut {
            t: h.t,
            triangle: h.triangle,
            u: h.u,
            v: h.v,
            leaf: h.leaf,
            prim: h.prim.0,
            steps: stats.leaves,
            flags,
        },
        None => HitOut { t: 0.0, triangle: u32::MAX, u: 0.0, v: 0.0, leaf: 0, prim: 0, steps: stats.leaves, flags },
    }
}

/// `HitOut::steps` of a walk that ran out of loop budget (`OVER_BUDGET` in trace.wgsl).
const OVER_BUDGET: u32 = u32::MAX;

#[cfg(test)]
mod tests {
    use super::*;

    /// The generated kernels (tracing, and rendering on top of it) parse and validate
    /// (naga, no device needed) for one binding and for a split scene, with and
    /// without f64, with and without a loop cap.
    #[test]
    fn the_kernel_source_is_valid_wgsl() {
        for (chunks, f64_edges) in [(1, false), (1, true), (3, false), (5, true)] {
            for budget in
                [Budget::for_cap(None, 1), Budget::for_cap(Some(65_535), 8), Budget::for_cap(Some(65_535), 64)]
            {
                let trace = shader_source(chunks, 1 << 10, f64_edges, budget);
                for source in [trace.clone(), render::render_source(&trace, 6)] {
                    validate(&source, f64_edges, chunks);
                }
                // And as the device gets them where it takes SPIR-V (`spirv`).
                spirv::compile(&trace, "main", &[("ANY_HIT", 1.0)], true).unwrap();
                spirv::compile(&render::render_source(&trace, 6), "render", &[("SHADOWS", 0.0)], false).unwrap();
            }
        }
    }

    /// The structs the host writes or reads have the WGSL layout: the same size,
    /// and every member at the Rust field's offset.
    #[test]
    fn host_structs_match_the_kernels() {
        use std::mem::{offset_of, size_of};
        let source = render::render_source(&shader_source(1, 1 << 10, false, Budget::for_cap(None, 1)), 6);
        let module = naga::front::wgsl::parse_str(&source).expect("valid");
        let layout = |name: &str| {
            let ty = module.types.iter().find(|(_, t)| t.name.as_deref() == Some(name)).expect(name).1;
            let naga::TypeInner::Struct { members, span } = &ty.inner else { panic!("{name} is not a struct") };
            (members.iter().map(|m| (m.name.clone().unwrap_or_default(), m.offset as usize)).collect::<Vec<_>>(), span)
        };
        let check = |name: &str, size: usize, offsets: &[(&str, usize)]| {
            let (members, span) = layout(name);
            assert_eq!(*span as usize, size, "{name}'s size");
            for (field, offset) in offsets {
                let found = members.iter().find(|(m, _)| m == field).unwrap_or_else(|| panic!("{name}.{field}"));
                assert_eq!(found.1, *offset, "{name}.{field}");
            }
        };
        check("HitOut", size_of::<HitOut>(), &[("t", offset_of!(HitOut, t)), ("flags", offset_of!(HitOut, flags))]);
        check(
            "Params",
            size_of::<Params>(),
            &[
                ("o_octree", offset_of!(Params, offsets)),
                ("root_lo", offset_of!(Params, root_lo)),
                ("box_hi", offset_of!(Params, box_hi)),
            ],
        );
        check("RenderParams", size_of::<render::RenderParams>(), &render::RenderParams::OFFSETS);
    }

    fn validate(source: &str, f64_edges: bool, chunks: usize) {
        let module = naga::front::wgsl::parse_str(source).unwrap_or_else(|e| panic!("{}", e.emit_to_string(source)));
        let caps = if f64_edges { naga::valid::Capabilities::FLOAT64 } else { naga::valid::Capabilities::empty() };
        naga::valid::Validator::new(naga::valid::ValidationFlags::all(), caps)
            .validate(&module)
            .unwrap_or_else(|e| panic!("{chunks} chunks, f64 {f64_edges}: {}", e.emit_to_string(source)));
    }
}
