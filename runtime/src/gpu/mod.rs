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
mod inside;
mod render;
mod source;
mod spirv;
mod stream;

use std::time::{Duration, Instant};

pub use buffers::MAX_SCENE_BINDINGS;
pub use device::{lockstep_lanes, loop_cap, GpuContext};
pub use render::{GpuRenderer, MAX_GPU_DEPTH};
pub use stream::{Answers, GpuCamera, GpuNearest, HitRecord};
/// The wgpu this crate is built with, for applications that share their device with a
/// tracer ([`GpuTracer::encode_trace`]).
pub use wgpu;

use buffers::{bind_group_layout, check_bindings, offsets_of, upload, TRACE_ARRAYS, TRACE_EXTRA_BINDINGS};
use device::{dispatch_once, timestamp_period, Budget};
use source::shader_source;
use stream::{Kernel, Pipelining, Source, Streams};

use crate::ray::{Hit, Ray};
use crate::WalkStats;
use crate::{Scene, TriangleTest};
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
    /// Answers or buffers that do not fit the rays given.
    #[error("{0}")]
    Mismatch(String),
    /// Answers past their memory budget ([`crate::Error::Budget`]) or memory the
    /// allocator refused ([`crate::Error::Alloc`]).
    #[error(transparent)]
    Memory(crate::Error),
}

/// The GPU result type.
pub type GpuResult<T> = std::result::Result<T, GpuError>;

/// Options of [`GpuTracer::with_options`].
#[derive(Clone, Copy, Debug)]
pub struct GpuOptions {
    /// The largest storage binding to use, in bytes (default: the device's limit). The
    /// scene's words are split across as many bindings as this takes; smaller values
    /// exercise the split on scenes that would fit one.
    pub max_binding_bytes: Option<u64>,
    /// Rays a chunk of a batch (default 2^21, the most a dispatch takes; rounded up to
    /// a multiple of 64). Chunks are uploaded, traced and read back in turn,
    /// overlapping one another.
    pub chunk_rays: Option<usize>,
    /// Chunks in flight at once (default 2, at most 8).
    pub in_flight: Option<usize>,
    /// The triangle test: [`TriangleTest::Watertight`] (the default here, where the
    /// CPU's is [`TriangleTest::Exact`]: every adapter runs it, and the exact kernels'
    /// cost on GPUs is not yet measured) or [`TriangleTest::Exact`]; the answers are
    /// those of the CPU's tracer with the same test ([`GpuTracer::cpu_tracer`]), ray
    /// for ray, bit for bit. Under the exact test the kernels decide what an error
    /// bound certifies (the `f32` edge functions' signs, the distance correctly
    /// rounded) and hand every other ray back to the CPU's exact test, as they hand
    /// back a walk out of loop budget ([`GpuTracer::rays_finished_on_cpu`] counts
    /// them); it needs an adapter with `f64` ([`GpuTracer::uses_f64`]). The renderer
    /// ([`GpuRenderer`]) traces with the watertight test.
    pub triangle_test: TriangleTest,
}

impl Default for GpuOptions {
    /// Every limit the device's, the watertight test.
    fn default() -> GpuOptions {
        GpuOptions {
            max_binding_bytes: None,
            chunk_rays: None,
            in_flight: None,
            triangle_test: TriangleTest::Watertight,
        }
    }
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
    /// The leaf labels' count before the points (MODE 3, `inside`), then padding.
    labels: u32,
    pad: u32,
    root_lo: [f32; 4],
    root_hi: [f32; 4],
    box_lo: [f32; 4],
    box_hi: [f32; 4],
}

/// The kernel's whole answer for a ray ([`HitRecord::Full`]; `HitOut` in trace.wgsl).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct GpuHit {
    /// Distance along the ray.
    pub t: f32,
    /// The triangle's input id; `u32::MAX` on a miss.
    pub triangle: u32,
    /// Barycentric coordinates of the hit.
    pub u: f32,
    /// See `u`.
    pub v: f32,
    /// The leaf the hit was found in.
    pub leaf: u32,
    /// The triangle's stored index.
    pub prim: u32,
    /// Leaves visited.
    pub steps: u32,
    /// Bit 0: the step bound stopped the walk; bits 1..32: triangle tests run.
    pub flags: u32,
}

impl GpuHit {
    /// The hit, or `None` on a miss.
    pub fn hit(&self) -> Option<Hit> {
        to_hit(self)
    }

    /// What the walk did.
    pub fn stats(&self) -> WalkStats {
        WalkStats { leaves: self.steps, triangle_tests: self.flags >> 1, stopped_at_bound: self.flags & 1 != 0 }
    }
}

type HitOut = GpuHit;

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
    /// How kernels are compiled on this device, the layout the crossing kernels are
    /// made with on first use (`crossings`), and those kernels: counts, lists.
    compiler: spirv::Compiler,
    pipeline_layout: wgpu::PipelineLayout,
    crossing_kernels: std::sync::OnceLock<Result<[wgpu::ComputePipeline; 2], String>>,
    /// The inside/outside kernel (`inside`), made on first use.
    side_kernel: std::sync::OnceLock<Result<wgpu::ComputePipeline, String>>,
    layout: wgpu::BindGroupLayout,
    scene_buffers: Vec<wgpu::Buffer>,
    params: Params,
    /// The batch path's buffers (`stream`), its chunks, and its kernels by (any hit,
    /// record, camera).
    streams: std::sync::Mutex<Streams>,
    /// The one-dispatch kernels' buffers (inside/outside, crossing lists), kept between
    /// calls and grown ([`GpuTracer::dispatch_with`]).
    kept: std::sync::Mutex<Kept>,
    /// Buffers made one at a time ([`GpuTracer::buffer`]; the kept ones among them).
    made: std::sync::atomic::AtomicU64,
    pipelining: Pipelining,
    pipelines: std::sync::Mutex<std::collections::HashMap<(bool, HitRecord, bool), wgpu::ComputePipeline>>,
    chunk_words: u64,
    /// Whether the scene has fans (the kernels' `FANS` constant).
    fans: bool,
    f64_edges: bool,
    /// The triangle test (the kernels' `EXACT` constant), and the rays the CPU
    /// finished (out of loop budget, or left in doubt by the exact test's filter).
    test: TriangleTest,
    finished_on_cpu: std::sync::atomic::AtomicU64,
    /// Nanoseconds a timestamp tick, where the device times passes.
    timestamps: Option<f64>,
    compile: Duration,
}

/// Timings of one batch, for benchmarks.
#[derive(Clone, Copy, Debug, Default)]
pub struct GpuTimings {
    /// Uploading the rays: writing them into mapped memory.
    pub upload: Duration,
    /// Waiting for the device: its copies and kernels, as the host sees them, less
    /// what overlapped with the host's own copies (`upload`, `download`).
    pub kernel: Duration,
    /// The kernel on the device: from the first to the last timestamp of each dispatch
    /// (`None` where the adapter has no timestamp queries).
    pub kernel_device: Option<Duration>,
    /// Reading the hits back: copying them out of mapped memory into the caller's.
    pub download: Duration,
    /// The whole call, from its start to the last answer in place.
    pub total: Duration,
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
        match options.triangle_test {
            TriangleTest::Watertight => {}
            TriangleTest::Exact if f64_edges => {}
            TriangleTest::Exact => {
                return Err(GpuError::Unsupported(
                    "the exact triangle test needs an adapter with 64-bit floats (shader f64); \
                     trace on the CPU, or with the watertight test"
                        .into(),
                ))
            }
            other => return Err(GpuError::Unsupported(format!("the {other:?} triangle test (the CPU's only)"))),
        }
        let cap = loop_cap(device, queue)?;
        let lanes = match cap {
            Some(cap) => lockstep_lanes(device, queue, cap)?,
            None => 1,
        };
        let budget = Budget::for_cap(cap, lanes);
        let compiler = spirv::Compiler::for_device(device, queue)?;
        let compiling = Instant::now();
        let layout = bind_group_layout(device, chunks as usize);
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("octrace trace"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        // `OCTRACE_GPU_CHUNK` and `OCTRACE_GPU_IN_FLIGHT` set the defaults, to measure a
        // GPU (answers do not depend on them).
        let knob = |name: &str| std::env::var(name).ok().and_then(|v| v.parse::<usize>().ok());
        let pipelining = Pipelining {
            chunk: (options.chunk_rays.or_else(|| knob("OCTRACE_GPU_CHUNK")))
                .unwrap_or(stream::DEFAULT_CHUNK)
                .clamp(1, 1 << 24)
                .next_multiple_of(64),
            in_flight: (options.in_flight.or_else(|| knob("OCTRACE_GPU_IN_FLIGHT")))
                .unwrap_or(stream::DEFAULT_IN_FLIGHT)
                .clamp(1, 8),
        };
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
            labels: 0,
            pad: 0,
            root_lo: [root_lo[0], root_lo[1], root_lo[2], b.root_size],
            root_hi: [root_hi[0], root_hi[1], root_hi[2], ((1u64 << max_depth) as f64 / b.root_size as f64) as f32],
            box_lo: [lo[0], lo[1], lo[2], rule.root as f32],
            box_hi: [hi[0], hi[1], hi[2], rule.reach as f32],
        };
        let mut tracer = GpuTracer {
            scene,
            cap,
            budget,
            device: device.clone(),
            queue: queue.clone(),
            compile: Duration::ZERO,
            compiler,
            pipeline_layout,
            crossing_kernels: std::sync::OnceLock::new(),
            side_kernel: std::sync::OnceLock::new(),
            layout,
            scene_buffers,
            params,
            streams: Default::default(),
            kept: Default::default(),
            made: Default::default(),
            pipelining,
            pipelines: Default::default(),
            chunk_words,
            fans,
            f64_edges,
            test: options.triangle_test,
            finished_on_cpu: Default::default(),
            timestamps: timestamp_period(device, queue),
        };
        // The nearest-hit and any-hit kernels, made now (the others on first use).
        tracer.pipeline(false, HitRecord::Full, false)?;
        tracer.pipeline(true, HitRecord::Full, false)?;
        tracer.compile = compiling.elapsed();
        Ok(tracer)
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

    /// Whether each ray hits anything in `[tmin, tmax]`, in ray order (the GPU sends
    /// one bit a ray back).
    ///
    /// # Errors
    /// As [`GpuTracer::intersect`].
    pub fn occluded(&self, rays: &[Ray]) -> GpuResult<Vec<bool>> {
        let mut words = vec![0u32; rays.len().div_ceil(32)];
        self.trace_into(rays, true, Answers::Occluded(&mut words))?;
        Ok((0..rays.len()).map(|i| words[i / 32] >> (i % 32) & 1 != 0).collect())
    }

    /// [`GpuTracer::intersect`] with what each walk did (leaves visited, triangle tests,
    /// whether the step bound stopped it), as the CPU's `Tracer::intersect_with_stats`.
    ///
    /// # Errors
    /// As [`GpuTracer::intersect`].
    pub fn intersect_with_stats(&self, rays: &[Ray]) -> GpuResult<Vec<(Option<Hit>, WalkStats)>> {
        Ok(self.run(rays, false)?.0.iter().map(|h| (to_hit(h), h.stats())).collect())
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

    /// Traces `rays` into the caller's `answers` (one record a ray, or one word for 32
    /// rays of [`Answers::Occluded`]), as compact as the record asked: the nearest hit,
    /// or with `any` any hit (occlusion bits always ask any hit). The batch is cut
    /// into chunks whose upload, kernel and read-back overlap ([`GpuOptions`]), through
    /// buffers kept from call to call; answers land straight in `answers`.
    ///
    /// # Errors
    /// [`GpuError::Mismatch`] if `answers` does not hold one record a ray;
    /// [`GpuError::Device`] as [`GpuTracer::intersect`].
    ///
    /// # Example
    /// ```no_run
    /// use octrace_runtime::gpu::{Answers, GpuContext, GpuNearest, GpuTracer};
    /// use octrace_runtime::{Ray, Scene};
    /// # fn main() -> Result<(), Box<dyn std::error::Error>> {
    /// let scene = Scene::open("bunny.oct")?;
    /// let gpu = GpuContext::new()?;
    /// let tracer = GpuTracer::new(&gpu.device, &gpu.queue, &scene)?;
    /// let rays = vec![Ray::new(glam::Vec3::new(0.0, 0.1, 1.0), glam::Vec3::NEG_Z); 1 << 20];
    /// // 8 bytes a ray come back: distance and triangle.
    /// let mut nearest = vec![GpuNearest::default(); rays.len()];
    /// let timings = tracer.trace_into(&rays, false, Answers::Nearest(&mut nearest))?;
    /// println!("{:?} in {:?}", nearest[0], timings.total);
    /// # Ok(()) }
    /// ```
    pub fn trace_into(&self, rays: &[Ray], any: bool, answers: Answers<'_>) -> GpuResult<GpuTimings> {
        self.stream(Source::Rays(rays), Kernel::Trace { any }, answers, false)
    }

    /// Traces the rays of `camera`, made on the device (no rays cross the bus), row by
    /// row into `answers`: the answers of [`GpuTracer::trace_into`] for
    /// [`GpuCamera::rays`], bit for bit.
    ///
    /// # Errors
    /// As [`GpuTracer::trace_into`].
    ///
    /// # Example
    /// ```no_run
    /// use octrace_runtime::gpu::{Answers, GpuCamera, GpuContext, GpuTracer};
    /// use octrace_runtime::Scene;
    /// # fn main() -> Result<(), Box<dyn std::error::Error>> {
    /// let scene = Scene::open("bunny.oct")?;
    /// let gpu = GpuContext::new()?;
    /// let tracer = GpuTracer::new(&gpu.device, &gpu.queue, &scene)?;
    /// let k = [[500.0, 0.0, 320.0], [0.0, 500.0, 240.0], [0.0, 0.0, 1.0]];
    /// let mut e = [[0.0; 4]; 4];
    /// (e[0][0], e[1][1], e[2][2], e[3][3], e[2][3]) = (1.0, -1.0, -1.0, 1.0, 1.0);
    /// let camera = GpuCamera::pinhole(k, e, 640, 480)?;
    /// let mut depth = vec![0.0f32; camera.len()];
    /// tracer.trace_camera_into(&camera, false, Answers::Distance(&mut depth))?;
    /// # Ok(()) }
    /// ```
    pub fn trace_camera_into(&self, camera: &GpuCamera, any: bool, answers: Answers<'_>) -> GpuResult<GpuTimings> {
        self.stream(Source::Camera(camera), Kernel::Trace { any }, answers, false)
    }

    /// The transfers of [`GpuTracer::trace_into`] alone, for benchmarks: the same
    /// chunks go up and come back, no kernel runs, and what
    /// `answers` holds afterwards is unspecified.
    ///
    /// # Errors
    /// As [`GpuTracer::trace_into`].
    pub fn time_transfers(&self, rays: &[Ray], answers: Answers<'_>) -> GpuResult<GpuTimings> {
        self.stream(Source::Rays(rays), Kernel::Trace { any: false }, answers, true)
    }

    /// Buffers the tracer has made since it was made (its scene's aside): the batch
    /// path's and the one-dispatch kernels' (inside/outside, crossing lists) are kept
    /// and reused, made again only when a call needs larger ones.
    pub fn buffers_created(&self) -> u64 {
        self.streams.lock().unwrap_or_else(|e| e.into_inner()).created()
            + self.made.load(std::sync::atomic::Ordering::Relaxed)
    }

    /// Encodes into `encoder` the tracing of `count` rays that are already on this
    /// tracer's device, in `rays` (32 bytes a ray, as [`Ray`]: origin, tmin, direction,
    /// tmax), writing `record`s into `answers` (made with `STORAGE`): for wgpu
    /// applications that make rays and use answers on the GPU, sharing the device and
    /// queue the tracer was made with, so nothing crosses the bus. Occlusion bits are
    /// followed by as many words of bits marking walks that ran out of the adapter's
    /// loop budget; compact records mark them with a NaN distance, full records with
    /// `steps == u32::MAX`. Only an adapter with a loop cap ([`GpuTracer::loop_cap`]:
    /// lavapipe, never hardware) has such walks, and under the exact test
    /// ([`GpuOptions::triangle_test`]) the rays its filter leaves in doubt, marked the
    /// same way: trace those with the CPU's exact test.
    ///
    /// # Errors
    /// [`GpuError::Mismatch`] if a buffer is too small or not a storage buffer, or
    /// `count` is more than one dispatch takes ([`GpuTracer::max_rays_per_encode`]).
    pub fn encode_trace(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        rays: &wgpu::Buffer,
        answers: &wgpu::Buffer,
        count: u32,
        any: bool,
        record: HitRecord,
    ) -> GpuResult<()> {
        let need = (32 * u64::from(count), record.bytes(u64::from(count)));
        if rays.size() < need.0 || answers.size() < need.1 {
            return Err(GpuError::Mismatch(format!(
                "{count} rays need {} bytes of rays and {} of {record:?} answers; the buffers have {} and {}",
                need.0,
                need.1,
                rays.size(),
                answers.size()
            )));
        }
        if !rays.usage().contains(wgpu::BufferUsages::STORAGE) || !answers.usage().contains(wgpu::BufferUsages::STORAGE)
        {
            return Err(GpuError::Mismatch("the rays and answers must be storage buffers".into()));
        }
        if u64::from(count) > self.max_rays_per_encode() {
            return Err(GpuError::Mismatch(format!(
                "{count} rays in one encode; at most {}",
                self.max_rays_per_encode()
            )));
        }
        if record == HitRecord::Occluded && !self.budget.workgroup.is_multiple_of(32) {
            return Err(GpuError::Unsupported("occlusion bits on an adapter whose workgroups are one lane".into()));
        }
        if count == 0 {
            return Ok(());
        }
        let pipeline = self.pipeline(any || record == HitRecord::Occluded, record, false)?;
        let params = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("octrace params"),
            size: std::mem::size_of::<Params>() as u64,
            usage: wgpu::BufferUsages::UNIFORM,
            mapped_at_creation: true,
        });
        {
            let mut view = params.slice(..).get_mapped_range_mut().map_err(|e| GpuError::Device(e.to_string()))?;
            view.copy_from_slice(bytemuck::bytes_of(&Params { ray_count: count, ..self.params }));
        }
        params.unmap();
        let group = self.bind_group(&params, rays, answers);
        let mut pass = encoder
            .begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("octrace trace"), timestamp_writes: None });
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &group, &[]);
        pass.dispatch_workgroups(count.div_ceil(self.budget.workgroup), 1, 1);
        Ok(())
    }

    /// Rays one [`GpuTracer::encode_trace`] takes at most.
    pub fn max_rays_per_encode(&self) -> u64 {
        u64::from(self.budget.per_dispatch(RAYS_PER_DISPATCH as u32))
    }

    /// The tracing kernel for (any hit, record, rays from a camera), made on first use.
    fn pipeline(&self, any: bool, record: HitRecord, camera: bool) -> GpuResult<wgpu::ComputePipeline> {
        let mut made = self.pipelines.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(p) = made.get(&(any, record, camera)) {
            return Ok(p.clone());
        }
        let flag = |b: bool| if b { 1.0 } else { 0.0 };
        let label = if any { "octrace any hit" } else { "octrace nearest hit" };
        let p = self.compiler.pipeline(
            &self.device,
            &self.pipeline_layout,
            &self.source(),
            "main",
            &[
                ("ANY_HIT", flag(any)),
                ("FANS", self.fans_constant()),
                ("RECORD", record.code()),
                ("CAMERA", flag(camera)),
                ("EXACT", self.exact_constant()),
            ],
            label,
        )?;
        made.insert((any, record, camera), p.clone());
        Ok(p)
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
        self.timestamps.is_some()
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

    /// The whole records of `rays` (walks out of loop budget traced on the CPU).
    fn run(&self, rays: &[Ray], any: bool) -> GpuResult<(Vec<HitOut>, GpuTimings)> {
        let mut out = vec![HitOut::default(); rays.len()];
        let timings = self.stream(Source::Rays(rays), Kernel::Trace { any }, Answers::Full(&mut out), false)?;
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

    /// The kernels' `EXACT` constant: 1 under the exact test.
    fn exact_constant(&self) -> f64 {
        if self.exact() {
            1.0
        } else {
            0.0
        }
    }

    /// Whether the kernels run the exact test's filter (and hand back what it leaves in
    /// doubt).
    fn exact(&self) -> bool {
        self.test == TriangleTest::Exact
    }

    /// The triangle test in use ([`GpuOptions::triangle_test`]).
    pub fn triangle_test(&self) -> TriangleTest {
        self.test
    }

    /// How many rays the CPU has traced for this tracer since it was made: walks out
    /// of the adapter's loop budget ([`GpuTracer::loop_cap`]), and under the exact test
    /// the rays whose decisions its filter left in doubt (a ray within about `2^-20`
    /// of an edge, relatively, or two crossings at one rounded distance).
    pub fn rays_finished_on_cpu(&self) -> u64 {
        self.finished_on_cpu.load(std::sync::atomic::Ordering::Relaxed)
    }

    /// The CPU tracer whose answers this one gives, and that finishes what the
    /// kernels hand back: the scene's, with this tracer's triangle test.
    pub fn cpu_tracer(&self) -> crate::Tracer<'s> {
        self.scene.tracer().with_triangle_test(self.test)
    }

    /// Counts `n` rays finished on the CPU.
    fn finished_here(&self, n: usize) {
        self.finished_on_cpu.fetch_add(n as u64, std::sync::atomic::Ordering::Relaxed);
    }

    /// The kernel's source for this scene's bindings.
    fn source(&self) -> String {
        self.source_with(self.budget)
    }

    /// [`GpuTracer::source`] with the loops bounded by `budget` (the render kernel's,
    /// [`Budget::for_render`]).
    fn source_with(&self, budget: Budget) -> String {
        shader_source(self.scene_buffers.len(), self.chunk_words, self.f64_edges, self.compiler.denormals, budget)
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

    /// A buffer of `size` bytes (at least 4) for `usage` (counted in
    /// [`GpuTracer::buffers_created`]).
    fn buffer(&self, label: &str, size: u64, usage: wgpu::BufferUsages) -> wgpu::Buffer {
        self.made.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: size.max(4),
            usage,
            mapped_at_creation: false,
        })
    }

    /// One dispatch of `pipeline` (made with the tracing layout) over `params.ray_count`
    /// items: `head` and then `inputs` written back to back into the rays binding, each
    /// starting on a vec4 (16 bytes; the gaps are zeros), and `answer_bytes` of the hits
    /// binding read back (the list and inside/outside kernels'). The buffers are kept
    /// between calls ([`Kept`]), the answers cleared first: what a new buffer would
    /// hold. `head` (what many calls share: the leaf labels) is written only where the
    /// buffer does not hold it already.
    fn dispatch_with<T: bytemuck::Pod>(
        &self,
        pipeline: &wgpu::ComputePipeline,
        params: Params,
        head: &[u8],
        inputs: &[&[u8]],
        answer_bytes: u64,
    ) -> GpuResult<Vec<T>> {
        use wgpu::BufferUsages as U;
        let head_bytes = (head.len() as u64).next_multiple_of(16);
        let at: Vec<u64> = inputs
            .iter()
            .scan(head_bytes, |end, input| {
                let start = *end;
                *end += (input.len() as u64).next_multiple_of(16);
                Some(start)
            })
            .collect();
        let input_bytes = head_bytes + inputs.iter().map(|i| (i.len() as u64).next_multiple_of(16)).sum::<u64>();
        // One call at a time uses the kept buffers.
        let mut kept = self.kept.lock().unwrap_or_else(|e| e.into_inner());
        let limits = self.device.limits();
        let binding = limits.max_storage_buffer_binding_size.min(limits.max_buffer_size);
        let (input, new_input) =
            self.kept_buffer(&mut kept.input, "octrace kernel input", input_bytes, U::STORAGE | U::COPY_DST, binding);
        if new_input {
            kept.head.clear(); // a new buffer holds no head
        }
        let answers_usage = U::STORAGE | U::COPY_SRC | U::COPY_DST;
        let (answers, _) =
            self.kept_buffer(&mut kept.answers, "octrace kernel answers", answer_bytes, answers_usage, binding);
        let params_size = std::mem::size_of::<Params>() as u64;
        let (params_buffer, _) =
            self.kept_buffer(&mut kept.params, "octrace params", params_size, U::UNIFORM | U::COPY_DST, params_size);
        let (readback, _) = self.kept_buffer(
            &mut kept.readback,
            "octrace readback",
            answer_bytes,
            U::MAP_READ | U::COPY_DST,
            limits.max_buffer_size,
        );
        self.queue.write_buffer(&params_buffer, 0, bytemuck::bytes_of(&params));
        let write = |bytes: &[u8], offset: u64| {
            // Whole vec4s, then the last one's bytes followed by zeros, as in a new
            // buffer (and copies stay multiples of four bytes).
            let whole = bytes.len() / 16 * 16;
            if whole > 0 {
                self.queue.write_buffer(&input, offset, &bytes[..whole]);
            }
            if whole < bytes.len() {
                let mut last = [0u8; 16];
                last[..bytes.len() - whole].copy_from_slice(&bytes[whole..]);
                self.queue.write_buffer(&input, offset + whole as u64, &last);
            }
        };
        if kept.head != head {
            if !head.is_empty() {
                write(head, 0);
            }
            kept.head.clear();
            kept.head.extend_from_slice(head);
        }
        for (bytes, &offset) in inputs.iter().zip(&at) {
            write(bytes, offset);
        }
        let bind_group = self.bind_group(&params_buffer, &input, &answers);
        let mut encoder = self.device.create_command_encoder(&Default::default());
        // The answers zeros, as in a new buffer (the last call's are there).
        if answer_bytes > 0 {
            encoder.clear_buffer(&answers, 0, Some(answer_bytes));
        }
        {
            let mut pass = encoder.begin_compute_pass(&Default::default());
            pass.set_pipeline(pipeline);
            pass.set_bind_group(0, &bind_group, &[]);
            pass.dispatch_workgroups(params.ray_count.div_ceil(self.budget.workgroup), 1, 1);
        }
        self.queue.submit([encoder.finish()]);
        let mut out = Vec::new();
        device::read_buffer_append(&self.device, &self.queue, &answers, &readback, answer_bytes, &mut out)?;
        Ok(out)
    }

    /// `slot`'s buffer where it holds `size` bytes, else a new one ([`GpuTracer::buffer`])
    /// of the next power of two (at most `limit`, at least `size`) put there, so that
    /// growing calls make buffers a few times, not every call; and whether it is new
    /// (what it holds, and bind groups over the old one, are then not its).
    fn kept_buffer(
        &self,
        slot: &mut Option<wgpu::Buffer>,
        label: &str,
        size: u64,
        usage: wgpu::BufferUsages,
        limit: u64,
    ) -> (wgpu::Buffer, bool) {
        match slot {
            Some(b) if b.size() >= size.max(4) => (b.clone(), false),
            _ => (slot.insert(self.buffer(label, size.next_power_of_two().min(limit).max(size), usage)).clone(), true),
        }
    }
}

/// The buffers [`GpuTracer::dispatch_with`] keeps between calls.
#[derive(Debug, Default)]
struct Kept {
    input: Option<wgpu::Buffer>,
    answers: Option<wgpu::Buffer>,
    params: Option<wgpu::Buffer>,
    readback: Option<wgpu::Buffer>,
    /// What `input` holds from its start, written by an earlier call (its `head`).
    head: Vec<u8>,
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
                let trace = shader_source(chunks, 1 << 10, f64_edges, chunks == 1, budget);
                for source in [trace.clone(), render::render_source(&trace, 6)] {
                    validate(&source, f64_edges, chunks);
                }
                // And as the device gets them where it takes SPIR-V (`spirv`).
                spirv::compile(&trace, "main", &[("ANY_HIT", 1.0)], true).unwrap();
                // Every record, rays read or made from a camera.
                for record in [HitRecord::Full, HitRecord::Nearest, HitRecord::Distance, HitRecord::Occluded] {
                    for camera in [0.0, 1.0] {
                        for exact in [0.0, 1.0] {
                            let constants =
                                [("RECORD", record.code()), ("CAMERA", camera), ("ANY_HIT", 1.0), ("EXACT", exact)];
                            spirv::compile(&trace, "main", &constants, true).unwrap();
                        }
                    }
                }
                spirv::compile(&render::render_source(&trace, 6), "render", &[("SHADOWS", 0.0)], false).unwrap();
            }
        }
    }

    /// The structs the host writes or reads have the WGSL layout: the same size,
    /// and every member at the Rust field's offset.
    #[test]
    fn host_structs_match_the_kernels() {
        use std::mem::{offset_of, size_of};
        let source = render::render_source(&shader_source(1, 1 << 10, false, true, Budget::for_cap(None, 1)), 6);
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
