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

mod crossings;
mod render;
mod spirv;

use std::time::{Duration, Instant};

pub use render::{GpuRenderer, MAX_GPU_DEPTH};

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
}

/// The GPU result type.
pub type GpuResult<T> = std::result::Result<T, GpuError>;

/// A Vulkan device and its queue.
#[derive(Debug)]
pub struct GpuContext {
    /// The device.
    pub device: wgpu::Device,
    /// Its queue.
    pub queue: wgpu::Queue,
    /// What the adapter is (name, driver, device type).
    pub info: wgpu::AdapterInfo,
}

impl GpuContext {
    /// Opens the first Vulkan adapter (a discrete GPU preferred), with the largest
    /// storage bindings and buffers it allows and 64-bit floats where it has them.
    ///
    /// # Errors
    /// [`GpuError::NoAdapter`] without a Vulkan driver; [`GpuError::Device`] if the
    /// adapter refuses the device.
    pub fn new() -> GpuResult<GpuContext> {
        let mut desc = wgpu::InstanceDescriptor::new_without_display_handle();
        desc.backends = wgpu::Backends::VULKAN;
        let instance = wgpu::Instance::new(desc);
        let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
            power_preference: wgpu::PowerPreference::HighPerformance,
            force_fallback_adapter: false,
            compatible_surface: None,
            ..Default::default()
        }))
        .map_err(|e| GpuError::NoAdapter(e.to_string()))?;
        let limits = adapter.limits();
        let required_limits = wgpu::Limits {
            max_storage_buffer_binding_size: limits.max_storage_buffer_binding_size,
            max_buffer_size: limits.max_buffer_size,
            max_storage_buffers_per_shader_stage: limits.max_storage_buffers_per_shader_stage,
            max_buffers_and_acceleration_structures_per_shader_stage: limits
                .max_buffers_and_acceleration_structures_per_shader_stage,
            ..wgpu::Limits::defaults()
        };
        // 64-bit floats for the exact paths; kernels compiled here (`spirv`); timestamps to
        // time kernels on the device.
        let wanted = wgpu::Features::SHADER_F64 | wgpu::Features::PASSTHROUGH_SHADERS | wgpu::Features::TIMESTAMP_QUERY;
        let required_features = adapter.features() & wanted;
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("octrace"),
            required_features,
            required_limits,
            ..Default::default()
        }))
        .map_err(|e| GpuError::Device(e.to_string()))?;
        Ok(GpuContext { device, queue, info: adapter.get_info() })
    }

    /// One line about the adapter: name, driver, type.
    pub fn describe(&self) -> String {
        let i = &self.info;
        format!("{} ({} {}, {:?})", i.name, i.driver, i.driver_info, i.device_type)
    }
}

/// Options of [`GpuTracer::with_options`].
#[derive(Clone, Copy, Debug, Default)]
pub struct GpuOptions {
    /// The largest storage binding to use, in bytes (default: the device's limit). The
    /// scene's words are split across as many bindings as this takes; smaller values
    /// exercise the split on scenes that would fit one.
    pub max_binding_bytes: Option<u64>,
}

/// Word offsets of the scene's arrays in the uploaded words, in the kernel's order.
#[derive(Clone, Copy, Debug)]
struct Offsets {
    octree: u32,
    refs: u32,
    tris: u32,
    ids: u32,
    boxes: u32,
    cube: u32,
    nodes: u32,
    total: u64,
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
/// Threads a workgroup (`WORKGROUP_SIZE` in trace.wgsl) where the adapter runs loops
/// without a cap.
const WORKGROUP: u32 = 64;
/// Workgroups a dispatch dimension may hold (WebGPU's limit).
const MAX_WORKGROUPS: u32 = 65_535;

/// How the kernels bound their loops on this adapter (see [`loop_cap`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct Budget {
    /// Invocations a workgroup.
    pub workgroup: u32,
    /// Loop iterations an invocation may run (`u32::MAX`: no bound).
    pub loops: u32,
}

impl Budget {
    /// The budget for an adapter that caps the loop iterations of a group of `lanes`
    /// invocations run in lockstep at `cap` (`None`: no cap). The driver counts an
    /// iteration of a loop whenever one lane of the group runs it, over all loops
    /// together, so the group's count is at most the sum of its lanes' own: a lane gets
    /// `cap / (2 lanes)`, and workgroups stay full. Half, because the driver's count
    /// runs ahead of the kernel's own (lavapipe cut the render kernel short when the
    /// kernel had counted 58,000 to 61,300 iterations alone: loops of its own making,
    /// about 10 %). A lane that spends its budget stops, and the host finishes its ray
    /// or pixel on the CPU. Where the group is the whole workgroup (`lanes` =
    /// [`WORKGROUP`]), each invocation gets a workgroup of its own instead, and half the
    /// cap.
    fn for_cap(cap: Option<u32>, lanes: u32) -> Budget {
        match cap {
            Some(cap) if lanes < WORKGROUP => Budget { workgroup: WORKGROUP, loops: cap / (2 * lanes.max(1)) },
            Some(cap) => Budget { workgroup: 1, loops: cap / 2 },
            None => Budget { workgroup: WORKGROUP, loops: u32::MAX },
        }
    }

    /// Items (rays, pixels) a dispatch takes at most, given a preferred batch.
    pub(super) fn per_dispatch(&self, preferred: u32) -> u32 {
        preferred.min(MAX_WORKGROUPS * self.workgroup)
    }
}

/// Loop iterations a probe kernel asks one invocation for.
const PROBE_ITERATIONS: u32 = 1 << 20;

/// The cap the adapter puts on the loop iterations of one shader invocation, if it has
/// one: one invocation asked for 2^20 iterations of a loop reports how many it ran.
/// Mesa's llvmpipe (lavapipe) stops every loop of an invocation once their iterations
/// together reach 65,535 (its guard against infinite loops), without an error: a walk
/// or a ray tree that needs more is cut short. Hardware drivers have no such cap.
pub fn loop_cap(device: &wgpu::Device, queue: &wgpu::Queue) -> GpuResult<Option<u32>> {
    let source = format!(
        "@group(0) @binding(0) var<storage, read_write> out: array<u32>;\n\
         @compute @workgroup_size(1)\n\
         fn main() {{\n    var n = 0u;\n    for (var i = 0u; i < {PROBE_ITERATIONS}u; i++) {{\n        n += 1u;\n    }}\n    out[0] = n;\n}}\n"
    );
    let ran = run_probe(device, queue, &source, "octrace loop probe", 1)?[0];
    Ok((ran < PROBE_ITERATIONS).then_some(ran))
}

/// How many invocations of a workgroup share the adapter's loop count, under a loop
/// `cap` ([`loop_cap`]): the lanes of one SIMD group, run in lockstep (lavapipe: 8, the
/// 256-bit vectors of its LLVM build), or [`WORKGROUP`] if the whole workgroup does.
/// Lane `l` of a workgroup of [`WORKGROUP`] runs a loop of `m` iterations (more than
/// half the cap) at the `l`-th step of an outer loop: in a shared count, lane 0 runs
/// whole and its neighbours are cut short, until the lane that begins the next group
/// runs whole again.
pub fn lockstep_lanes(device: &wgpu::Device, queue: &wgpu::Queue, cap: u32) -> GpuResult<u32> {
    let m = cap / 2 + cap / 8;
    let source = format!(
        "@group(0) @binding(0) var<storage, read_write> out: array<u32>;\n\
         @compute @workgroup_size({WORKGROUP})\n\
         fn main(@builtin(local_invocation_index) l: u32) {{\n    var n = 0u;\n    \
         for (var k = 0u; k < {WORKGROUP}u; k++) {{\n        if k == l {{\n            \
         for (var j = 0u; j < {m}u; j++) {{\n                n += 1u;\n            }}\n        }}\n    }}\n    \
         out[l] = n;\n}}\n"
    );
    let ran = run_probe(device, queue, &source, "octrace lockstep probe", WORKGROUP)?;
    Ok((1..WORKGROUP).find(|&l| ran[l as usize] == m).unwrap_or(WORKGROUP))
}

/// Runs a one-workgroup probe kernel writing `words` words to its one binding, and
/// reads them back.
fn run_probe(device: &wgpu::Device, queue: &wgpu::Queue, source: &str, label: &str, words: u32) -> GpuResult<Vec<u32>> {
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some(label),
        source: wgpu::ShaderSource::Wgsl(source.into()),
    });
    let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some(label),
        layout: None,
        module: &module,
        entry_point: Some("main"),
        compilation_options: Default::default(),
        cache: None,
    });
    let out = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: 4 * u64::from(words),
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    });
    let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some(label),
        layout: &pipeline.get_bind_group_layout(0),
        entries: &[wgpu::BindGroupEntry { binding: 0, resource: out.as_entire_binding() }],
    });
    let mut encoder = device.create_command_encoder(&Default::default());
    {
        let mut pass = encoder.begin_compute_pass(&Default::default());
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &group, &[]);
        pass.dispatch_workgroups(1, 1, 1);
    }
    queue.submit([encoder.finish()]);
    read_buffer::<u32>(device, queue, &out, 4 * u64::from(words))
}

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

/// Two timestamps around each compute pass, where the device has timestamp queries.
#[derive(Debug)]
struct Stopwatch {
    queries: wgpu::QuerySet,
    resolve: wgpu::Buffer,
    /// Nanoseconds a timestamp tick.
    period: f64,
}

impl Stopwatch {
    fn new(device: &wgpu::Device, queue: &wgpu::Queue) -> Option<Stopwatch> {
        if !device.features().contains(wgpu::Features::TIMESTAMP_QUERY) {
            return None;
        }
        let queries = device.create_query_set(&wgpu::QuerySetDescriptor {
            label: Some("octrace kernel time"),
            ty: wgpu::QueryType::Timestamp,
            count: 2,
        });
        let resolve = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("octrace kernel time"),
            size: 16,
            usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        Some(Stopwatch { queries, resolve, period: f64::from(queue.get_timestamp_period()) })
    }

    /// The pass's timestamp writes.
    fn writes(&self) -> wgpu::ComputePassTimestampWrites<'_> {
        wgpu::ComputePassTimestampWrites {
            query_set: &self.queries,
            beginning_of_pass_write_index: Some(0),
            end_of_pass_write_index: Some(1),
        }
    }

    /// Resolves the pass's timestamps (after the pass, in the same encoder).
    fn resolve(&self, encoder: &mut wgpu::CommandEncoder) {
        encoder.resolve_query_set(&self.queries, 0..2, &self.resolve, 0);
    }

    /// The time between the pass's two timestamps (once its work is done).
    fn elapsed(&self, device: &wgpu::Device, queue: &wgpu::Queue) -> GpuResult<Duration> {
        let ticks = read_buffer::<u64>(device, queue, &self.resolve, 16)?;
        Ok(Duration::from_nanos((ticks[1].saturating_sub(ticks[0]) as f64 * self.period) as u64))
    }
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
        // follow are the host's business).
        let words = view.section_words();
        let arrays: [&[u32]; TRACE_ARRAYS] = std::array::from_fn(|i| words[i]);
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
                &[("ANY_HIT", if any { 1.0 } else { 0.0 })],
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
            out.extend(self.read_back_into::<HitOut>(&hit_buffer, &readback, bytes)?);
            timings.download += t.elapsed();
        }
        Ok((out, timings))
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
        let readback =
            self.buffer("octrace readback", bytes, wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST);
        self.read_back_into(buffer, &readback, bytes)
    }

    /// The first `bytes` of `buffer`, through `readback` (a mappable buffer).
    fn read_back_into<T: bytemuck::Pod>(
        &self,
        buffer: &wgpu::Buffer,
        readback: &wgpu::Buffer,
        bytes: u64,
    ) -> GpuResult<Vec<T>> {
        read_buffer_into(&self.device, &self.queue, buffer, readback, bytes)
    }

    fn wait(&self) -> GpuResult<()> {
        wait(&self.device)
    }
}

/// Waits for the device's work.
fn wait(device: &wgpu::Device) -> GpuResult<()> {
    device
        .poll(wgpu::PollType::Wait { submission_index: None, timeout: None })
        .map(drop)
        .map_err(|e| GpuError::Device(e.to_string()))
}

/// The first `bytes` of `buffer` (made with `COPY_SRC`), read back.
fn read_buffer<T: bytemuck::Pod>(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    buffer: &wgpu::Buffer,
    bytes: u64,
) -> GpuResult<Vec<T>> {
    let readback = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("octrace readback"),
        size: bytes.max(4),
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    read_buffer_into(device, queue, buffer, &readback, bytes)
}

/// The first `bytes` of `buffer`, through `readback` (a mappable buffer).
fn read_buffer_into<T: bytemuck::Pod>(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    buffer: &wgpu::Buffer,
    readback: &wgpu::Buffer,
    bytes: u64,
) -> GpuResult<Vec<T>> {
    let mut encoder = device.create_command_encoder(&Default::default());
    encoder.copy_buffer_to_buffer(buffer, 0, readback, 0, bytes);
    queue.submit([encoder.finish()]);
    let slice = readback.slice(..bytes);
    let (send, receive) = std::sync::mpsc::channel();
    slice.map_async(wgpu::MapMode::Read, move |r| {
        let _ = send.send(r);
    });
    wait(device)?;
    receive.recv().map_err(|e| GpuError::Device(e.to_string()))?.map_err(|e| GpuError::Device(e.to_string()))?;
    let out = {
        let mapped = slice.get_mapped_range().map_err(|e| GpuError::Device(e.to_string()))?;
        bytemuck::cast_slice(&mapped).to_vec()
    };
    readback.unmap();
    Ok(out)
}

/// The arrays the kernel walks: octree, tri_refs, triangles, triangle_ids, boxes,
/// cube_map, nodes.
const TRACE_ARRAYS: usize = 7;

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

fn offsets_of(arrays: &[&[u32]; TRACE_ARRAYS]) -> GpuResult<Offsets> {
    let mut at = [0u64; 8];
    for (i, a) in arrays.iter().enumerate() {
        at[i + 1] = at[i] + a.len() as u64;
    }
    let word = |i: usize| {
        u32::try_from(at[i]).map_err(|_| GpuError::TooLarge(format!("{} scene words, more than 2^32", at[7])))
    };
    Ok(Offsets {
        octree: word(0)?,
        refs: word(1)?,
        tris: word(2)?,
        ids: word(3)?,
        boxes: word(4)?,
        cube: word(5)?,
        nodes: word(6)?,
        total: at[7],
    })
}

/// Uploads the arrays back to back into buffers of `chunk_words` words (the last one
/// shorter), each array copied straight from its slice (the mapped file).
fn upload(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    arrays: &[&[u32]; TRACE_ARRAYS],
    total: u64,
    chunk_words: u64,
) -> Vec<wgpu::Buffer> {
    let chunks = total.div_ceil(chunk_words).max(1);
    let buffers: Vec<wgpu::Buffer> = (0..chunks)
        .map(|k| {
            let words = (total - k * chunk_words).min(chunk_words).max(1);
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("octrace scene"),
                size: 4 * words,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        })
        .collect();
    let mut at = 0u64;
    for array in arrays {
        let mut rest: &[u32] = array;
        while !rest.is_empty() {
            let (k, within) = (at / chunk_words, at % chunk_words);
            let n = rest.len().min((chunk_words - within) as usize);
            queue.write_buffer(&buffers[k as usize], 4 * within, bytemuck::cast_slice(&rest[..n]));
            rest = &rest[n..];
            at += n as u64;
        }
    }
    queue.submit([]);
    buffers
}

fn bind_group_layout(device: &wgpu::Device, chunks: usize) -> wgpu::BindGroupLayout {
    let storage = |binding, read_only| wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Storage { read_only },
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    };
    let mut entries = vec![
        wgpu::BindGroupLayoutEntry {
            binding: 0,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Uniform,
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            count: None,
        },
        storage(1, true),
        storage(2, false),
    ];
    entries.extend((0..chunks).map(|k| storage(3 + k as u32, true)));
    device
        .create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: Some("octrace trace"), entries: &entries })
}

/// The kernel's source: trace.wgsl with the scene's bindings, the `word` accessor over
/// them, and the precision-dependent helpers.
fn shader_source(chunks: usize, chunk_words: u64, f64_edges: bool, budget: Budget) -> String {
    let mut g =
        format!("const WORKGROUP_SIZE: u32 = {}u;\nconst LOOP_BUDGET: u32 = {}u;\n", budget.workgroup, budget.loops);
    for k in 0..chunks {
        g += &format!("@group(0) @binding({}) var<storage, read> scene_{k}: array<u32>;\n", 3 + k);
    }
    if chunks == 1 {
        g += "fn word(i: u32) -> u32 {\n    return scene_0[i];\n}\n";
    } else {
        let shift = chunk_words.ilog2();
        g +=
            &format!("fn word(i: u32) -> u32 {{\n    let j = i & {}u;\n    switch i >> {shift}u {{\n", chunk_words - 1);
        for k in 0..chunks {
            g += &format!("        case {k}u: {{ return scene_{k}[j]; }}\n");
        }
        g += "        default: { return 0u; }\n    }\n}\n";
    }
    if f64_edges {
        // Products of f32s are exact in f64, and so is the sign of their difference:
        // the edge function of a shared edge is the exact negation in both triangles,
        // whatever the compiler fuses.
        g += "fn edge(px: f32, py: f32, qx: f32, qy: f32) -> f32 {\n    \
              return f32(f64(px) * f64(qy) - f64(py) * f64(qx));\n}\n";
        // The product of two f32s is exact in f64: rounded to f32 it is the f32
        // product, bit for bit, and no longer a multiply a compiler may fuse.
        g += "fn product(a: f32, b: f32) -> f32 {\n    return f32(f64(a) * f64(b));\n}\n";
        // SceneView::uv_at: exact products, one f64 sum, rounded once.
        g += "fn uv_mix(a: f32, b: f32, c: f32, w: f32, u: f32, v: f32) -> f32 {\n    \
              return f32(f64(a) * f64(w) + f64(b) * f64(u) + f64(c) * f64(v));\n}\n";
        g += "fn grid_coord(p: f32, lo: f32) -> u32 {\n    \
              let last = f64((1u << params.max_depth) - 1u);\n    \
              let x = (f64(p) - f64(lo)) * f64(params.root_hi.w);\n    \
              return u32(f32(clamp(x, 0.0lf, last)));\n}\n";
        g += &triangle_source("f64");
        g += &plane_distance_source("f64");
        g += &front_source("f64");
        // tables::exact_exit and exact_side: exact products, the difference's sign exact.
        g += "fn exits_before(oi: f32, di: f32, oj: f32, dj: f32) -> bool {\n    \
              let p = f64(oi) * f64(dj) - f64(oj) * f64(di);\n    \
              return select(p > 0.0lf, p < 0.0lf, is_negative(di) == is_negative(dj));\n}\n";
        g += "fn exact_distance(off: f32, d: f32) -> f32 {\n    return f32(f64(off) / f64(d));\n}\n";
        // The f32 quotient and square root correctly rounded, as the CPU's: in f64
        // (rounding twice is exact for these: 53 >= 2 x 24 + 2 bits), where a driver's
        // f32 division may be 2.5 ulps off (NVIDIA's is) and its square root worse.
        g += "fn div(a: f32, b: f32) -> f32 {\n    return f32(f64(a) / f64(b));\n}\n";
        g += "fn root(x: f32) -> f32 {\n    return f32(sqrt(f64(x)));\n}\n";
        g += FAR_F64;
        g += HIT_F64;
        g += "fn exact_side(off_a: f32, d_a: f32, m: f32, dk: f32, negative_a: bool) -> u32 {\n    \
              let p = f64(off_a) * f64(dk) - f64(m) * f64(d_a);\n    \
              return select(0u, 1u, (p > 0.0lf) != negative_a);\n}\n";
    } else {
        g += "fn edge(px: f32, py: f32, qx: f32, qy: f32) -> f32 {\n    return px * qy - py * qx;\n}\n";
        g += "fn product(a: f32, b: f32) -> f32 {\n    return a * b;\n}\n";
        g += "fn uv_mix(a: f32, b: f32, c: f32, w: f32, u: f32, v: f32) -> f32 {\n    \
              return a * w + b * u + c * v;\n}\n";
        g += "fn grid_coord(p: f32, lo: f32) -> u32 {\n    \
              let last = f32((1u << params.max_depth) - 1u);\n    \
              return u32(clamp((p - lo) * params.root_hi.w, 0.0, last));\n}\n";
        g += &triangle_source("f32");
        g += &plane_distance_source("f32");
        g += &front_source("f32");
        // Without f64 the exact rule compares rounded f32 distances (no underflowing
        // products, but the adapter's division).
        g += "fn exits_before(oi: f32, di: f32, oj: f32, dj: f32) -> bool {\n    return oi / di < oj / dj;\n}\n";
        g += "fn exact_distance(off: f32, d: f32) -> f32 {\n    return off / d;\n}\n";
        // Without f64, the adapter's quotient and square root.
        g += "fn div(a: f32, b: f32) -> f32 {\n    return a / b;\n}\n";
        g += "fn root(x: f32) -> f32 {\n    return sqrt(x);\n}\n";
        g += FAR_F32;
        // Without f64 the exact rule's rays take the f32 test.
        g += "fn hit_triangle_exact(wk: ptr<function, Walk>, at: u32, tmin: f32, tmax: f32, owned: bool) -> vec4<f32> {\n    \
              return hit_triangle(wk, at, tmin, tmax, owned);\n}\n";
        g += "fn exact_side(off_a: f32, d_a: f32, m: f32, dk: f32, negative_a: bool) -> u32 {\n    \
              let x = (off_a / d_a) * dk - m;\n    \
              let p_positive = select(x > 0.0, x < 0.0, is_negative(d_a));\n    \
              return select(0u, 1u, p_positive != negative_a);\n}\n";
    }
    include_str!("trace.wgsl").replace("//GENERATED//\n", &g)
}

/// Moving a far origin to the root (`cpu::walk`'s `begin_far`), in `f64`: the entry
/// into the root cube, `max(tmin)`, split into two `f32` whose sum is exact; the moved
/// origin; distances shifted back and `tmin` forward, each rounded once (`tmax`
/// forward by `moved_tmax`, trace.wgsl).
/// `far_shift` answers `(hi, lo, 1)`, or `z = 0` for a ray that misses the root.
const FAR_F64: &str = "fn far_shift(o: vec3<f32>, d: vec3<f32>, tmin: f32) -> vec3<f32> {
    var t_enter = -1.0e300lf;
    var t_leave = 1.0e300lf;
    for (var k = 0u; k < 3u; k++) {
        let lo = f64(component(params.root_lo.xyz, k));
        let hi = f64(component(params.root_hi.xyz, k));
        let ok = f64(component(o, k));
        let dk = f64(component(d, k));
        if dk == 0.0lf {
            if ok < lo || ok > hi {
                return vec3<f32>(0.0);
            }
            continue;
        }
        let ta = (lo - ok) / dk;
        let tb = (hi - ok) / dk;
        t_enter = max(t_enter, min(ta, tb));
        t_leave = min(t_leave, max(ta, tb));
    }
    let entry = max(t_enter, f64(tmin));
    if entry > t_leave || !(entry < 3.4028234663852886e38lf) {
        return vec3<f32>(0.0);
    }
    let hi = f32(entry);
    return vec3<f32>(hi, f32(entry - f64(hi)), 1.0);
}
fn moved_origin(o: vec3<f32>, d: vec3<f32>, s: vec2<f32>) -> vec3<f32> {
    let shift = f64(s.x) + f64(s.y);
    return vec3<f32>(f32(f64(o.x) + shift * f64(d.x)), f32(f64(o.y) + shift * f64(d.y)), f32(f64(o.z) + shift * f64(d.z)));
}
fn shifted(t: f32, s: vec2<f32>) -> f32 {
    return f32(f64(s.x) + f64(s.y) + f64(t));
}
fn unshifted(t: f32, s: vec2<f32>) -> f32 {
    return f32(f64(t) - (f64(s.x) + f64(s.y)));
}
";

/// `cpu::watertight::Shear::intersect_f64`: the watertight test in `f64` throughout,
/// for the rays under the exact exit rule (the same operations in the same order).
const HIT_F64: &str = "fn c64(v: vec3<f64>, i: u32) -> f64 {
    return select(select(v.z, v.y, i == 1u), v.x, i == 0u);
}
fn owns64(positive: bool, fx: f64, fy: f64, tx: f64, ty: f64) -> bool {
    let up = select((ty < fy), (ty > fy), positive);
    let right = select((tx < fx), (tx > fx), positive);
    return up || (ty == fy && right);
}
fn hit_triangle_exact(wk: ptr<function, Walk>, at: u32, tmin: f32, tmax: f32, owned: bool) -> vec4<f32> {
    let k = (*wk).k;
    let d = vec3<f64>(f64((*wk).d.x), f64((*wk).d.y), f64((*wk).d.z));
    let sx = c64(d, k.x) / c64(d, k.z);
    let sy = c64(d, k.y) / c64(d, k.z);
    let o = vec3<f64>(f64((*wk).o.x), f64((*wk).o.y), f64((*wk).o.z));
    let a = corner(at) - o;
    let b = corner(at + 3u) - o;
    let c = corner(at + 6u) - o;
    let ax = c64(a, k.x) - sx * c64(a, k.z);
    let ay = c64(a, k.y) - sy * c64(a, k.z);
    let bx = c64(b, k.x) - sx * c64(b, k.z);
    let by = c64(b, k.y) - sy * c64(b, k.z);
    let cx = c64(c, k.x) - sx * c64(c, k.z);
    let cy = c64(c, k.y) - sy * c64(c, k.z);
    let u = cx * by - cy * bx;
    let v = ax * cy - ay * cx;
    let w = bx * ay - by * ax;
    if (u < 0.0lf || v < 0.0lf || w < 0.0lf) && (u > 0.0lf || v > 0.0lf || w > 0.0lf) {
        return vec4<f32>(0.0);
    }
    let det = u + v + w;
    if det == 0.0lf {
        return vec4<f32>(0.0);
    }
    if owned && (u == 0.0lf || v == 0.0lf || w == 0.0lf) {
        let p = det > 0.0lf;
        if (u == 0.0lf && !owns64(p, bx, by, cx, cy)) || (v == 0.0lf && !owns64(p, cx, cy, ax, ay))
            || (w == 0.0lf && !owns64(p, ax, ay, bx, by)) {
            return vec4<f32>(0.0);
        }
    }
    let plane = plane_distance((*wk).o, (*wk).d, at);
    let dist = plane.x;
    if plane.y != 0.0 && dist >= tmin && dist <= tmax {
        return vec4<f32>(dist, f32(v / det), f32(w / det), 1.0);
    }
    return vec4<f32>(0.0);
}
";

/// [`FAR_F64`] without `f64`: the entry from the kernel's `f32` clip, pulled back by
/// eight ulps so that the moved origin stays before the root, and the origin moved by a
/// fused multiply-add (on the ray's line within a rounding of the moved point).
const FAR_F32: &str = "fn far_shift(o: vec3<f32>, d: vec3<f32>, tmin: f32) -> vec3<f32> {
    let root = clip(o, d, params.root_lo.xyz, params.root_hi.xyz);
    let entry = max(root.x, tmin);
    if root.w == 0.0 || entry > root.y || !is_finite(entry) {
        return vec3<f32>(0.0);
    }
    return vec3<f32>(entry * (1.0 - 9.5367431640625e-7), 0.0, 1.0);
}
fn moved_origin(o: vec3<f32>, d: vec3<f32>, s: vec2<f32>) -> vec3<f32> {
    return fma(vec3<f32>(s.x), d, o);
}
fn shifted(t: f32, s: vec2<f32>) -> f32 {
    return s.x + t;
}
fn unshifted(t: f32, s: vec2<f32>) -> f32 {
    return t - s.x;
}
";

/// Bindings a kernel has besides the scene's chunks: (storage, all buffers). Tracing:
/// rays and hits, and the parameters.
pub(super) const TRACE_EXTRA_BINDINGS: (u64, u64) = (2, 3);

/// Scene bindings a kernel takes at most: each is a case of the `word` accessor's
/// switch, and a driver's compile time grows with them (NVIDIA's ran past five minutes
/// on 850). A device binds gigabytes a binding: 64 is far past any scene that fits.
pub const MAX_SCENE_BINDINGS: u64 = 64;

/// Whether `chunks` scene bindings plus `extra` (storage, all buffers) fit the device's
/// limits on buffers per shader stage; a scene that needs more is
/// [`GpuError::TooLarge`], naming the limit, before wgpu is asked (it would panic).
pub(super) fn check_bindings(
    limits: &wgpu::Limits,
    chunks: u64,
    (storage, buffers): (u64, u64),
    scene_bytes: u64,
    chunk_bytes: u64,
) -> GpuResult<()> {
    let storage_limit = u64::from(limits.max_storage_buffers_per_shader_stage);
    let buffer_limit = u64::from(limits.max_buffers_and_acceleration_structures_per_shader_stage);
    // The scene's group holds the chunks and the tracing kernel's own three bindings
    // (on NVIDIA the stage limits are in the millions: this one binds first).
    let group_limit = u64::from(limits.max_bindings_per_bind_group);
    let in_group = chunks + TRACE_EXTRA_BINDINGS.1;
    if chunks + storage > storage_limit
        || chunks + buffers > buffer_limit
        || in_group > group_limit
        || chunks > MAX_SCENE_BINDINGS
    {
        return Err(GpuError::TooLarge(format!(
            "{} MB of scene words need {chunks} bindings of {} MB, {} in all with the kernel's own; the device \
             allows {storage_limit} storage buffers and {buffer_limit} buffers a shader stage, {group_limit} \
             bindings a group, and the kernels take at most {MAX_SCENE_BINDINGS} scene bindings",
            scene_bytes / 1_000_000,
            chunk_bytes / 1_000_000,
            chunks + buffers
        )));
    }
    Ok(())
}

/// The stored triangle's corners and plane normal in `float` (`f64` where the adapter
/// has it), shared by the generated functions below: `corner(at)`, the three floats
/// from word `at`; `plane_normal(at)`, `(v1 - v0) x (v2 - v0)` of the triangle at word
/// `at`, the same operations in the same order as the CPU's.
fn triangle_source(float: &str) -> String {
    format!(
        "fn corner(at: u32) -> vec3<{float}> {{
    return vec3<{float}>({float}(wordf(at)), {float}(wordf(at + 1u)), {float}(wordf(at + 2u)));
}}
fn plane_normal(at: u32) -> vec3<{float}> {{
    let a = corner(at);
    let e1 = corner(at + 3u) - a;
    let e2 = corner(at + 6u) - a;
    return vec3<{float}>(e1.y * e2.z - e1.z * e2.y, e1.z * e2.x - e1.x * e2.z, e1.x * e2.y - e1.y * e2.x);
}}
"
    )
}

/// `plane_distance(o, d, at)`: where the ray meets the plane of the triangle at word
/// `at`, as `cpu::watertight::plane_distance` computes it (the same operations in the
/// same order), in `float` (`f64` where the adapter has it; else `f32`, whose error
/// grows on long thin triangles): `(t, 1)`, or `(0, 0)` for a ray parallel to the
/// plane or a distance beyond `f32`'s range.
fn plane_distance_source(float: &str) -> String {
    format!(
        "fn plane_distance(o: vec3<f32>, d: vec3<f32>, at: u32) -> vec2<f32> {{
    let n = plane_normal(at);
    let ao = corner(at) - vec3<{float}>({float}(o.x), {float}(o.y), {float}(o.z));
    let num = ao.x * n.x + ao.y * n.y + ao.z * n.z;
    let den = {float}(d.x) * n.x + {float}(d.y) * n.y + {float}(d.z) * n.z;
    if den == {float}(0.0) {{
        return vec2<f32>(0.0);
    }}
    let t = f32(num / den);
    if !is_finite(t) {{
        return vec2<f32>(0.0);
    }}
    return vec2<f32>(t, 1.0);
}}
"
    )
}

/// `arrives_on_front(d, at)`: whether a ray of direction `d` arrives on the front of
/// the triangle at word `at` (`cpu::crossings::arrives_on_front`: `d . n < 0`, the same
/// operations in the same order), in `float`.
fn front_source(float: &str) -> String {
    format!(
        "fn arrives_on_front(d: vec3<f32>, at: u32) -> bool {{
    let n = plane_normal(at);
    return {float}(d.x) * n.x + {float}(d.y) * n.y + {float}(d.z) * n.z < {float}(0.0);
}}
"
    )
}

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
