//! The GPU figures of `bench --gpu`.
use std::time::{Duration, Instant};

use octrace_runtime::gpu::{GpuContext, GpuTracer};
use octrace_runtime::{Hit, Ray, Scene};
use serde_json::json;

use super::Spread;
use crate::output::thousands;

pub(super) struct GpuSet {
    name: &'static str,
    rays: usize,
    kernel: Spread,
    end_to_end: Spread,
    hits: usize,
    sum_t: f64,
    /// Rays whose answer differs from the CPU's (another triangle at the same
    /// distance counts as the same answer).
    differ: usize,
}

pub(super) struct GpuReport {
    adapter: String,
    exact_edges: bool,
    upload: Duration,
    sets: Vec<GpuSet>,
}

/// Times each set on the GPU and compares its answers with the CPU's (`cpu`, the
/// sets' CPU results, in the same order).
pub(super) fn measure(
    scene: &Scene,
    sets: &[(&'static str, Vec<Ray>, bool)],
    cpu: &[super::SetResult],
    runs: usize,
) -> anyhow::Result<GpuReport> {
    let gpu = GpuContext::new()?;
    let t = Instant::now();
    let tracer = GpuTracer::new(&gpu.device, &gpu.queue, scene)?;
    let upload = t.elapsed();
    let mut out = Vec::new();
    for ((name, rays, occlusion), cpu) in sets.iter().zip(cpu) {
        let mrays = |d: Duration| rays.len() as f64 / d.as_secs_f64().max(1e-9) / 1e6;
        let (mut kernel, mut total, mut hits) = (Vec::new(), Vec::new(), Vec::new());
        for _ in 0..runs {
            let (h, timings) = tracer.trace_timed(rays, *occlusion)?;
            kernel.push(mrays(timings.kernel));
            total.push(mrays(timings.upload + timings.kernel + timings.download));
            hits = h;
        }
        let differ = if *occlusion {
            cpu.occluded.iter().zip(&hits).filter(|(c, g)| **c != g.is_some()).count()
        } else {
            cpu.nearest.iter().zip(&hits).filter(|(c, g)| !same(c, g)).count()
        };
        let (found, sum_t) = super::hit_sums(&hits);
        out.push(GpuSet {
            name,
            rays: rays.len(),
            kernel: Spread::of(kernel),
            end_to_end: Spread::of(total),
            hits: found,
            sum_t: if *occlusion { 0.0 } else { sum_t },
            differ,
        });
    }
    Ok(GpuReport { adapter: gpu.describe(), exact_edges: tracer.uses_f64(), upload, sets: out })
}

/// The same answer: both miss, or hits at the same distance (1e-5 relative).
fn same(a: &Option<Hit>, b: &Option<Hit>) -> bool {
    match (a, b) {
        (None, None) => true,
        (Some(a), Some(b)) => a.triangle == b.triangle || (a.t - b.t).abs() <= 1e-5 * a.t.abs(),
        _ => false,
    }
}

impl GpuReport {
    pub(super) fn text(&self) -> String {
        let fmt = |s: &Spread| format!("{:.1} ({:.1}-{:.1})", s.median, s.min, s.max);
        let mut lines = vec![
            format!(
                "GPU: {}; scene uploaded in {:.1} ms; {} edge functions",
                self.adapter,
                self.upload.as_secs_f64() * 1e3,
                if self.exact_edges { "f64 (exact)" } else { "f32" }
            ),
            format!("{:<11} {:>9} {:>22} {:>22}  checksum", "set", "rays", "kernel Mrays/s", "with transfers"),
        ];
        for s in &self.sets {
            let check = super::checksum(s.name, s.hits, s.sum_t);
            lines.push(format!(
                "{:<11} {:>9} {:>22} {:>22}  {}; {} rays differ from the CPU",
                s.name,
                thousands(s.rays as u64),
                fmt(&s.kernel),
                fmt(&s.end_to_end),
                check,
                s.differ
            ));
        }
        lines.join("\n")
    }

    pub(super) fn json(&self) -> serde_json::Value {
        json!({
            "adapter": self.adapter,
            "exact_edges": self.exact_edges,
            "upload_s": self.upload.as_secs_f64(),
            "sets": self.sets.iter().map(|s| json!({
                "set": s.name, "rays": s.rays, "mrays_kernel": s.kernel, "mrays_end_to_end": s.end_to_end,
                "hits": s.hits, "sum_t": s.sum_t, "differ_from_cpu": s.differ,
            })).collect::<Vec<_>>(),
        })
    }
}
