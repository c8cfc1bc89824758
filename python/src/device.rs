//! Where a scene's ray queries run: on the CPU's cores, or (`Scene(..., device="gpu")`,
//! in a module built with the `gpu` feature) in the GPU's kernels, with the CPU
//! tracer's triangle test so that both answer the same, ray for ray, bit for bit.
//!
//! Of the point queries, inside/outside (`contains`, `compute_occupancy` on a closed
//! mesh) runs on the GPU too, the points its cells cannot decide finished on the CPU;
//! closest points, distances and winding numbers run on the CPU whatever the device.

use octrace_runtime::cpu::{BatchCrossings, CrossingCount};
use octrace_runtime::{Hit, Ray, Scene};
use pyo3::prelude::*;
#[cfg(feature = "gpu")]
use rayon::prelude::*;

use crate::arrays::PIECE;
use crate::errors::runtime_error;

/// The error for `device="gpu"` in a module built without the GPU.
#[cfg(not(feature = "gpu"))]
pub(crate) fn without_gpu() -> PyErr {
    crate::errors::GpuError::new_err(
        "this octrace module was built without the GPU: reinstall it with the gpu feature, \
         MATURIN_PEP517_ARGS=\"--features gpu\" pip install ./python (the README, \"On a GPU\")",
    )
}

/// The devices `Scene(..., device=...)` takes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Device {
    Cpu,
    Gpu,
}

impl Device {
    pub(crate) fn parse(name: &str) -> PyResult<Device> {
        match name {
            "cpu" => Ok(Device::Cpu),
            "gpu" => Ok(Device::Gpu),
            other => {
                Err(pyo3::exceptions::PyValueError::new_err(format!("device: {other:?}, expected \"cpu\" or \"gpu\"")))
            }
        }
    }

    pub(crate) fn name(self) -> &'static str {
        match self {
            Device::Cpu => "cpu",
            Device::Gpu => "gpu",
        }
    }
}

/// Where a query's rays (and inside/outside's points) go: the scene's CPU tracer, or
/// its GPU tracer.
pub(crate) enum Rays<'a> {
    Cpu(&'a Scene),
    #[cfg(feature = "gpu")]
    Gpu(&'a octrace_runtime::gpu::GpuTracer<'a>),
}

impl Rays<'_> {
    /// Rays converted and traced at a time: the CPU's cache-sized pieces, or for the
    /// GPU pieces of several of its chunks, so that one chunk's upload, another's
    /// kernel and a third's read-back overlap.
    pub(crate) fn piece(&self) -> usize {
        match self {
            Rays::Cpu(_) => PIECE,
            #[cfg(feature = "gpu")]
            Rays::Gpu(_) => gpu::PIECE,
        }
    }

    /// The nearest hit of each ray into `hits`.
    pub(crate) fn intersect(&self, rays: &[Ray], hits: &mut [Option<Hit>]) -> PyResult<()> {
        match self {
            Rays::Cpu(s) => s.tracer().par_intersect_batch(rays, hits),
            #[cfg(feature = "gpu")]
            Rays::Gpu(t) => {
                use octrace_runtime::gpu::{Answers, GpuHit};
                let mut full = crate::errors::zeros::<GpuHit>(rays.len(), "hits")?;
                t.trace_into(rays, false, Answers::Full(&mut full)).map_err(gpu::error)?;
                hits.par_iter_mut().zip(&full).for_each(|(h, g)| *h = g.hit());
            }
        }
        Ok(())
    }

    /// Whether anything lies on each ray, into `occluded`.
    pub(crate) fn occluded(&self, rays: &[Ray], occluded: &mut [bool]) -> PyResult<()> {
        match self {
            Rays::Cpu(s) => s.tracer().par_occluded_batch(rays, occluded),
            #[cfg(feature = "gpu")]
            Rays::Gpu(t) => {
                use octrace_runtime::gpu::Answers;
                let mut bits = crate::errors::zeros::<u32>(rays.len().div_ceil(32), "occlusion bits")?;
                t.trace_into(rays, true, Answers::Occluded(&mut bits)).map_err(gpu::error)?;
                occluded.par_iter_mut().enumerate().for_each(|(i, o)| *o = bits[i / 32] >> (i % 32) & 1 != 0);
            }
        }
        Ok(())
    }

    /// The crossings of each ray, counted, into `counts`.
    pub(crate) fn count_crossings(&self, rays: &[Ray], counts: &mut [CrossingCount]) -> PyResult<()> {
        match self {
            Rays::Cpu(s) => s.tracer().par_count_crossings_batch(rays, counts),
            #[cfg(feature = "gpu")]
            Rays::Gpu(t) => counts.copy_from_slice(&t.count_crossings(rays).map_err(gpu::error)?),
        }
        Ok(())
    }

    /// The first `limit` crossings of each ray, in at most `max_bytes`.
    pub(crate) fn crossings(&self, rays: &[Ray], limit: usize, max_bytes: u64) -> PyResult<BatchCrossings> {
        match self {
            Rays::Cpu(s) => s.crossings_batch_within(rays, limit, max_bytes).map_err(runtime_error),
            #[cfg(feature = "gpu")]
            Rays::Gpu(t) => t.crossings_within(rays, limit, max_bytes).map_err(gpu::error),
        }
    }

    /// Whether each point lies inside the scene, a closed mesh (on the GPU: the points
    /// the kernel decides, the rest on the CPU).
    pub(crate) fn contains(&self, points: &[[f32; 3]]) -> PyResult<Vec<bool>> {
        match self {
            Rays::Cpu(s) => s.contains_batch(points).map_err(runtime_error),
            #[cfg(feature = "gpu")]
            Rays::Gpu(t) => t.contains(t.scene().solid().map_err(runtime_error)?, points).map_err(gpu::error),
        }
    }

    /// The length of each ray inside the scene, a closed mesh.
    pub(crate) fn length_inside(&self, rays: &[Ray]) -> PyResult<Vec<f32>> {
        match self {
            Rays::Cpu(s) => s.length_inside_batch(rays).map_err(runtime_error),
            #[cfg(feature = "gpu")]
            Rays::Gpu(t) => t.length_inside(t.scene().solid().map_err(runtime_error)?, rays).map_err(gpu::error),
        }
    }
}

#[cfg(feature = "gpu")]
pub(crate) mod gpu {
    //! The GPU: one Vulkan device for the process, and a tracer a scene.

    use std::sync::{Arc, Mutex};

    use octrace_runtime::gpu::{GpuContext, GpuError as Failure, GpuOptions, GpuTracer};
    use octrace_runtime::Scene;
    use pyo3::prelude::*;

    use crate::errors::GpuError;

    /// Rays a piece on the GPU: two of the batch path's default chunks (2^21 rays), so
    /// that one's transfers overlap the other's kernel; a piece's rays, records and
    /// hits take about 350 MB while it is traced.
    pub(crate) const PIECE: usize = 1 << 22;

    /// A GPU error as Python's: memory as `MemoryError` (a budget passed, an allocation
    /// refused), the rest as [`GpuError`].
    pub(crate) fn error(e: Failure) -> PyErr {
        match e {
            Failure::Memory(e) => crate::errors::runtime_error(e),
            e => GpuError::new_err(e.to_string()),
        }
    }

    /// The process's device, opened on first use and shared by its scenes; opened again
    /// in a forked child (a Vulkan device does not survive `fork`).
    pub(crate) fn context() -> PyResult<Arc<GpuContext>> {
        static CONTEXT: Mutex<Option<(u32, Arc<GpuContext>)>> = Mutex::new(None);
        let mut held = CONTEXT.lock().unwrap_or_else(|e| e.into_inner());
        let pid = std::process::id();
        if let Some((owner, context)) = &*held {
            if *owner == pid {
                return Ok(context.clone());
            }
            // Inherited through fork: not ours to use, nor to drop (the parent's driver
            // state); forgotten.
            if let Some((_, inherited)) = held.take() {
                std::mem::forget(inherited);
            }
        }
        let context = Arc::new(GpuContext::new().map_err(error)?);
        *held = Some((pid, context.clone()));
        Ok(context)
    }

    /// A world's scenes on the process's GPU (`GpuWorld`), made in this process (a
    /// forked child makes its own on first use).
    pub(crate) struct WorldOnGpu {
        held: Mutex<Option<(u32, octrace_runtime::world::GpuWorld, Arc<GpuContext>)>>,
    }

    impl WorldOnGpu {
        /// Nothing uploaded yet; the device opened now, so that a world that cannot
        /// have it is refused when made.
        pub(crate) fn new() -> PyResult<WorldOnGpu> {
            let context = context()?;
            let world = octrace_runtime::world::GpuWorld::new(&context.device, &context.queue);
            Ok(WorldOnGpu { held: Mutex::new(Some((std::process::id(), world, context))) })
        }

        /// `f` with this process's `GpuWorld`.
        pub(crate) fn with<R>(
            &self,
            f: impl FnOnce(&mut octrace_runtime::world::GpuWorld) -> Result<R, Failure>,
        ) -> PyResult<R> {
            let mut held = self.held.lock().unwrap_or_else(|e| e.into_inner());
            let pid = std::process::id();
            if held.as_ref().is_none_or(|h| h.0 != pid) {
                // Inherited through fork: the parent's driver state, forgotten.
                if let Some(inherited) = held.take() {
                    std::mem::forget(inherited);
                }
                let context = context()?;
                let world = octrace_runtime::world::GpuWorld::new(&context.device, &context.queue);
                *held = Some((pid, world, context));
            }
            let (_, world, _) = held.as_mut().expect("made above");
            f(world).map_err(error)
        }
    }

    /// A scene's GPU tracer, which borrows the scene it holds.
    pub(crate) struct OnGpu {
        /// Borrows `_scene`'s value, which lives on the heap behind the `Arc`: it neither
        /// moves nor drops while this struct lives, and this field, declared first, is
        /// dropped first.
        tracer: GpuTracer<'static>,
        _scene: Arc<Scene>,
        _context: Arc<GpuContext>,
        adapter: String,
    }

    impl OnGpu {
        /// Uploads `scene` to the process's GPU, to be traced with the triangle test of
        /// the scene's CPU tracer (exact, or watertight where the scene has fans), so
        /// that both answer alike.
        pub(crate) fn new(scene: &Arc<Scene>) -> PyResult<OnGpu> {
            let context = context()?;
            let options = GpuOptions { triangle_test: scene.tracer().triangle_test(), ..GpuOptions::default() };
            // SAFETY: the reference is to the value the `Arc` kept in `_scene` owns; it is
            // neither moved nor dropped before `tracer`, which the struct drops first, and
            // `tracer()` hands the tracer out only for as long as `self` is borrowed.
            let borrowed: &'static Scene = unsafe { &*Arc::as_ptr(scene) };
            let tracer = GpuTracer::with_options(&context.device, &context.queue, borrowed, options).map_err(error)?;
            let adapter = context.describe();
            Ok(OnGpu { tracer, _scene: scene.clone(), _context: context, adapter })
        }

        /// The tracer, for as long as `self` is borrowed.
        pub(crate) fn tracer(&self) -> &GpuTracer<'_> {
            &self.tracer
        }

        /// The adapter: its name, driver and kind.
        pub(crate) fn adapter(&self) -> &str {
            &self.adapter
        }
    }
}
