//! Inside/outside of points on the GPU: the kernel (`MODE` 3, `side_of` in
//! trace.wgsl) locates each point's leaf and answers where the leaf is empty, wholly on
//! one side of the closed mesh (its label, from [`Solid`], in the points' binding), and
//! under the exact test ([`super::GpuOptions::triangle_test`]) where the leaf has a
//! reference point, by the crossings of the segment to it (what the exact test's
//! filter leaves in doubt, and points on the surface, excepted); the points it leaves
//! undecided are answered by the CPU's exact [`crate::Tracer::contains`].

use rayon::prelude::*;

use super::{GpuResult, GpuTracer, RAYS_PER_DISPATCH};
use crate::cpu::Solid;

/// Bytes a point takes in the kernel's rays binding: its three floats, as given.
const POINT: u64 = 12;
/// The kernel's answer for a point the host decides (`UNDECIDED` in trace.wgsl).
const UNDECIDED: u32 = 2;

impl GpuTracer<'_> {
    /// Whether each point lies inside the closed mesh `solid` labels (made for this
    /// tracer's scene: [`crate::Scene::solid`]): [`crate::Tracer::contains`], point
    /// for point, exact whatever the tracer's test. The GPU answers the points in empty
    /// leaves and, under the exact test, most of those in leaves with a reference
    /// point; the CPU the rest ([`GpuTracer::rays_finished_on_cpu`] counts them); a
    /// scene whose labels do not fit a binding beside a dispatch of points is answered
    /// on the CPU.
    ///
    /// # Errors
    /// [`super::GpuError::Device`] if the device is lost or a buffer cannot be read.
    ///
    /// # Example
    /// ```no_run
    /// use octrace_runtime::gpu::{GpuContext, GpuTracer};
    /// use octrace_runtime::Scene;
    /// # fn main() -> Result<(), Box<dyn std::error::Error>> {
    /// let scene = Scene::open("skull.oct")?;
    /// let gpu = GpuContext::new()?;
    /// let tracer = GpuTracer::new(&gpu.device, &gpu.queue, &scene)?;
    /// let inside = tracer.contains(scene.solid()?, &[[0.0, 0.0, 0.0], [9.0, 9.0, 9.0]])?;
    /// # Ok(()) }
    /// ```
    pub fn contains(&self, solid: &Solid, points: &[[f32; 3]]) -> GpuResult<Vec<bool>> {
        // A byte a leaf: the kernel reads them four to a word, little-endian. They stay
        // on the device between calls (`dispatch_with`'s head).
        let labels = solid.leaf_labels();
        let label_bytes = (labels.len() as u64).next_multiple_of(16);
        let limits = self.device.limits();
        let max_binding = limits.max_storage_buffer_binding_size.min(limits.max_buffer_size);
        // The points after the labels, rounded up to a vec4.
        let room = max_binding.saturating_sub(label_bytes + 16) / POINT;
        let per_dispatch = (self.budget.per_dispatch(RAYS_PER_DISPATCH as u32) as u64).min(room) as usize;
        let mut sides = vec![UNDECIDED; points.len()];
        if per_dispatch >= 64 && labels.len() <= u32::MAX as usize {
            for (part, out) in points.chunks(per_dispatch).zip(sides.chunks_mut(per_dispatch)) {
                self.side_kernel(part, labels, out)?;
            }
        }
        // The scene's own tracer, exact whatever the kernels' test.
        let tracer = self.scene.tracer();
        self.finished_here(sides.par_iter().filter(|&&s| s == UNDECIDED).count());
        Ok(sides
            .par_iter()
            .zip(points)
            .map(|(&side, &p)| if side == UNDECIDED { tracer.contains(solid, p) } else { side == 1 })
            .collect())
    }

    /// The kernel over `points` (one dispatch): each one's side into `out`. The points
    /// follow the labels in the rays binding.
    fn side_kernel(&self, points: &[[f32; 3]], labels: &[u8], out: &mut [u32]) -> GpuResult<()> {
        let params = super::Params { ray_count: points.len() as u32, labels: labels.len() as u32, ..self.params };
        let inputs = [bytemuck::cast_slice(points)];
        let pipeline = self.side_pipeline()?;
        out.copy_from_slice(&self.dispatch_with::<u32>(pipeline, params, labels, &inputs, points.len() as u64 * 4)?);
        Ok(())
    }

    /// The inside/outside kernel, built on first use.
    fn side_pipeline(&self) -> GpuResult<&wgpu::ComputePipeline> {
        self.side_kernel
            .get_or_init(|| {
                self.compiler
                    .pipeline(
                        &self.device,
                        &self.pipeline_layout,
                        &self.source(),
                        "main",
                        &[("MODE", 3.0), ("FANS", self.fans_constant()), ("EXACT", self.exact_constant())],
                        "octrace inside",
                    )
                    .map_err(|e| e.to_string())
            })
            .as_ref()
            .map_err(|e: &String| super::GpuError::Device(e.clone()))
    }
}
