//! Every crossing along a ray, and crossing counts, in the tracing kernel
//! (`cross` in trace.wgsl, compiled with `MODE` 1 for counts and 2 for lists): the
//! CPU's walk (`cpu::crossings`), leaf for leaf, with the same edge ownership, the
//! same pieces of the ray, the same order within a leaf, so the answers are the
//! CPU's bit for bit.
//!
//! A list takes two passes: the counts, then the records at offsets the counts give
//! (memory follows the crossings found). Walks that run out of the adapter's loop
//! budget, and rays with more crossings than one binding holds, are walked again on
//! the CPU, from the same scene.

use super::stream::{Kernel, Source};
use super::{Answers, GpuError, GpuResult, GpuTracer, HitOut, Ray, OVER_BUDGET, RAYS_PER_DISPATCH};
use crate::cpu::{BatchCrossings, Crossing, CrossingCount, Solid};

/// Bytes of one record (a ray's crossing, or its count) in the hits binding.
const RECORD: u64 = std::mem::size_of::<HitOut>() as u64;
/// Bytes of one ray in the rays binding.
const RAY: u64 = std::mem::size_of::<Ray>() as u64;

impl GpuTracer<'_> {
    /// How many times each ray crosses the mesh, and how many of those arrive on a
    /// front: [`crate::Tracer::count_crossings`], ray for ray, bit for bit.
    ///
    /// # Errors
    /// [`super::GpuError::Device`] if the device is lost or a buffer cannot be read.
    ///
    /// # Example
    /// ```no_run
    /// use octrace_runtime::gpu::{GpuContext, GpuTracer};
    /// use octrace_runtime::{Ray, Scene};
    /// # fn main() -> Result<(), Box<dyn std::error::Error>> {
    /// let scene = Scene::open("skull.oct")?;
    /// let gpu = GpuContext::new()?;
    /// let tracer = GpuTracer::new(&gpu.device, &gpu.queue, &scene)?;
    /// let rays = [Ray::new(glam::Vec3::new(0.0, 0.0, 0.0), glam::Vec3::X)];
    /// let count = tracer.count_crossings(&rays)?[0];
    /// println!("{} crossings, winding {}", count.total, count.winding());
    /// # Ok(()) }
    /// ```
    pub fn count_crossings(&self, rays: &[Ray]) -> GpuResult<Vec<CrossingCount>> {
        let tracer = self.cpu_tracer();
        let counts = self.kernel_counts(rays)?;
        self.finished_here(counts.iter().filter(|c| c.is_none()).count());
        Ok(counts.iter().zip(rays).map(|(c, r)| c.unwrap_or_else(|| tracer.count_crossings(r))).collect())
    }

    /// The counting kernel's answers; `None` for a walk that ran out of loop budget.
    fn kernel_counts(&self, rays: &[Ray]) -> GpuResult<Vec<Option<CrossingCount>>> {
        let mut out = vec![HitOut::default(); rays.len()];
        self.stream(Source::Rays(rays), Kernel::Counts, Answers::Full(&mut out), false)?;
        Ok(out
            .iter()
            .map(|h| (h.steps != OVER_BUDGET).then_some(CrossingCount { total: h.triangle, entries: h.leaf }))
            .collect())
    }

    /// Every crossing of each ray, in order along it, in one flat list with per-ray
    /// splits: [`crate::Tracer::crossings_batch`] with no limit, ray for ray, bit for
    /// bit.
    ///
    /// # Errors
    /// As [`GpuTracer::count_crossings`].
    pub fn crossings(&self, rays: &[Ray]) -> GpuResult<BatchCrossings> {
        self.crossings_within(rays, usize::MAX, u64::MAX)
    }

    /// The first `limit` crossings of each ray, in order along it, in one flat list
    /// with per-ray splits, taking at most `max_bytes`
    /// ([`crate::cpu::CROSSING_BYTES`] a crossing):
    /// [`crate::Tracer::par_crossings_batch_within`], ray for ray, bit for bit. The
    /// counts come first, so a batch past the budget is refused before its lists are
    /// made, and the kernel writes only the first `limit` of a ray.
    ///
    /// # Errors
    /// As [`GpuTracer::count_crossings`]; [`GpuError::Memory`] with
    /// [`crate::Error::Budget`] past the budget, [`crate::Error::Alloc`] where the
    /// allocator refuses the lists.
    pub fn crossings_within(&self, rays: &[Ray], limit: usize, max_bytes: u64) -> GpuResult<BatchCrossings> {
        use crate::cpu::CROSSING_BYTES;
        use octrace_format::memory::try_vec;
        // A walk the counting kernel could not finish is listed on the CPU once, and
        // its list gives its count.
        let tracer = self.cpu_tracer();
        let gpu_counts = self.kernel_counts(rays)?;
        self.finished_here(gpu_counts.iter().filter(|c| c.is_none()).count());
        let cpu_lists: Vec<Option<Vec<Crossing>>> =
            gpu_counts.iter().zip(rays).map(|(c, r)| c.is_none().then(|| tracer.first_crossings(r, limit))).collect();
        let total = |i: usize| {
            gpu_counts[i].map_or_else(|| cpu_lists[i].as_ref().map_or(0, Vec::len), |c| (c.total as usize).min(limit))
        };
        let mut splits = try_vec(rays.len() + 1, "crossing splits").map_err(|e| GpuError::Memory(e.into()))?;
        for i in 0..rays.len() {
            splits[i + 1] = splits[i] + total(i);
        }
        let needed = splits[rays.len()] as u64 * CROSSING_BYTES;
        if needed > max_bytes {
            return Err(GpuError::Memory(crate::cpu::over_budget(needed, max_bytes)));
        }
        let mut crossings = try_vec(splits[rays.len()], "crossings").map_err(|e| GpuError::Memory(e.into()))?;
        // Dispatches of at most `per_dispatch` rays whose rays and offsets fit one
        // binding, and whose records fit another; a ray whose records alone do not, or
        // that the CPU listed already, is given no room (`capacity` 0).
        let limits = self.device.limits();
        let max_binding = limits.max_storage_buffer_binding_size.min(limits.max_buffer_size);
        let max_records = (max_binding / RECORD).min(u32::MAX as u64) as usize;
        let per_dispatch =
            (self.budget.per_dispatch(RAYS_PER_DISPATCH as u32) as u64).min((max_binding - 16) / (RAY + 4)) as usize;
        let on_gpu = |i: usize| cpu_lists[i].is_none() && total(i) <= max_records;
        let mut start = 0;
        while start < rays.len() {
            let mut end = start;
            let mut records = 0usize;
            while end < rays.len() && end - start < per_dispatch {
                let n = if on_gpu(end) { total(end) } else { 0 };
                if records + n > max_records {
                    break;
                }
                records += n;
                end += 1;
            }
            let part = &rays[start..end];
            let mut offsets = Vec::with_capacity(part.len() + 1);
            offsets.push(0u32);
            for i in start..end {
                let n = if on_gpu(i) { total(i) as u32 } else { 0 };
                offsets.push(offsets[offsets.len() - 1] + n);
            }
            let out = if records > 0 { self.list_kernel(part, &offsets)? } else { Vec::new() };
            for (k, i) in (start..end).enumerate() {
                let (a, b) = (offsets[k] as usize, offsets[k + 1] as usize);
                let dest = &mut crossings[splits[i]..splits[i + 1]];
                if dest.is_empty() {
                    continue;
                }
                if let Some(list) = &cpu_lists[i] {
                    dest.copy_from_slice(list);
                    continue;
                }
                if b - a != dest.len() || out[a].flags == OVER_BUDGET {
                    self.finished_here(1);
                    dest.copy_from_slice(&tracer.first_crossings(&rays[i], limit));
                    continue;
                }
                for (c, h) in dest.iter_mut().zip(&out[a..b]) {
                    *c = Crossing { t: h.t, triangle: h.triangle, u: h.u, v: h.v, enters: h.leaf != 0 };
                }
            }
            start = end;
        }
        Ok(BatchCrossings { splits, crossings })
    }

    /// The length of each ray's `[tmin, tmax]` inside the scene, a closed mesh (`solid`,
    /// from [`crate::Scene::solid`]): [`crate::Tracer::length_inside`], ray for ray, bit
    /// for bit, from the GPU's crossings to infinity.
    ///
    /// # Errors
    /// As [`GpuTracer::count_crossings`].
    pub fn length_inside(&self, solid: &Solid, rays: &[Ray]) -> GpuResult<Vec<f32>> {
        let _ = solid;
        let to_infinity: Vec<Ray> = rays.iter().map(|r| Ray { tmax: f32::INFINITY, ..*r }).collect();
        let all = self.crossings(&to_infinity)?;
        Ok(rays.iter().enumerate().map(|(i, r)| crate::cpu::inside::length_from(r, all.of(i))).collect())
    }

    /// The list kernel over `rays` (one dispatch), ray `i`'s records at
    /// `offsets[i]..offsets[i + 1]` of what comes back.
    fn list_kernel(&self, rays: &[Ray], offsets: &[u32]) -> GpuResult<Vec<HitOut>> {
        let records = *offsets.last().unwrap_or(&0) as u64;
        let params = super::Params { ray_count: rays.len() as u32, ..self.params };
        let inputs = [bytemuck::cast_slice(rays), bytemuck::cast_slice(offsets)];
        self.dispatch_with(&self.crossing_kernels()?[1], params, &[], &inputs, records * RECORD)
    }

    /// The counting and listing kernels, built on first use.
    pub(super) fn crossing_kernels(&self) -> GpuResult<&[wgpu::ComputePipeline; 2]> {
        self.crossing_kernels
            .get_or_init(|| {
                let source = self.source();
                let make = |label, mode: f64| {
                    self.compiler
                        .pipeline(
                            &self.device,
                            &self.pipeline_layout,
                            &source,
                            "main",
                            &[("MODE", mode), ("FANS", self.fans_constant()), ("EXACT", self.exact_constant())],
                            label,
                        )
                        .map_err(|e| e.to_string())
                };
                Ok([make("octrace count crossings", 1.0)?, make("octrace crossings", 2.0)?])
            })
            .as_ref()
            .map_err(|e: &String| GpuError::Device(e.clone()))
    }
}
