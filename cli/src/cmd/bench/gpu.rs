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
    /// The kernel on the device (timestamp queries), where the adapter has them.
    kernel_device: Option<Spread>,
    /// The kernel as the host sees it (submitted to finished).
    kernel: Spread,
    end_to_end: Spread,
    /// Milliseconds uploading the rays and reading the hits back.
    upload_ms: Spread,
    download_ms: Spread,
    /// The set's first, untimed call (the driver may compile at its first dispatch).
    first_call: Duration,
    hits: usize,
    sum_t: f64,
    /// Rays whose answer differs from the CPU's: in any bit of (triangle, t, u, v)
    /// where the kernel computes as the CPU does (f64 on the adapter, the watertight
    /// test), else by another distance (1e-5 t; another triangle at the same distance
    /// counts as the same answer).
    differ: usize,
}

pub(super) struct GpuReport {
    adapter: String,
    exact_edges: bool,
    /// Whether nearest hits were compared bit for bit.
    bitwise: bool,
    unfused: bool,
    subnormals: bool,
    /// Uploading the scene and making the kernels.
    setup: Duration,
    /// Of which making the kernels.
    compile: Duration,
    loop_cap: Option<u32>,
    lane_budget: Option<u32>,
    sets: Vec<GpuSet>,
}

/// Times each set on the GPU and compares its answers with the CPU's (`cpu`, the
/// sets' CPU results, in the same order).
pub(super) fn measure(
    scene: &Scene,
    sets: &[(&'static str, Vec<Ray>, bool)],
    cpu: &[super::SetResult],
    runs: usize,
    watertight: bool,
) -> anyhow::Result<GpuReport> {
    let gpu = GpuContext::new()?;
    let t = Instant::now();
    let tracer = GpuTracer::new(&gpu.device, &gpu.queue, scene)?;
    let setup = t.elapsed();
    let mut out = Vec::new();
    for ((name, rays, occlusion), cpu) in sets.iter().zip(cpu) {
        let mrays = |d: Duration| rays.len() as f64 / d.as_secs_f64().max(1e-9) / 1e6;
        let t = Instant::now();
        tracer.trace_timed(rays, *occlusion)?;
        let first_call = t.elapsed();
        let (mut device, mut kernel, mut total, mut hits) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        let (mut up, mut down) = (Vec::new(), Vec::new());
        for _ in 0..runs {
            let (h, timings) = tracer.trace_timed(rays, *occlusion)?;
            device.extend(timings.kernel_device.map(mrays));
            kernel.push(mrays(timings.kernel));
            total.push(mrays(timings.upload + timings.kernel + timings.download));
            up.push(timings.upload.as_secs_f64() * 1e3);
            down.push(timings.download.as_secs_f64() * 1e3);
            hits = h;
        }
        let differ = if *occlusion {
            cpu.occluded.iter().zip(&hits).filter(|(c, g)| **c != g.is_some()).count()
        } else {
            let bitwise = watertight && tracer.uses_f64();
            cpu.nearest
                .iter()
                .zip(&hits)
                .filter(|(c, g)| if bitwise { bits(c) != bits(g) } else { !same(c, g) })
                .count()
        };
        let (found, sum_t) = super::hit_sums(&hits);
        out.push(GpuSet {
            name,
            rays: rays.len(),
            kernel_device: (!device.is_empty()).then(|| Spread::of(device)),
            kernel: Spread::of(kernel),
            end_to_end: Spread::of(total),
            upload_ms: Spread::of(up),
            download_ms: Spread::of(down),
            first_call,
            hits: found,
            sum_t: if *occlusion { 0.0 } else { sum_t },
            differ,
        });
    }
    Ok(GpuReport {
        adapter: gpu.describe(),
        exact_edges: tracer.uses_f64(),
        bitwise: watertight && tracer.uses_f64(),
        unfused: tracer.unfused(),
        subnormals: tracer.keeps_subnormals(),
        setup,
        compile: tracer.compile_time(),
        loop_cap: tracer.loop_cap(),
        lane_budget: tracer.lane_budget(),
        sets: out,
    })
}

/// A hit's bits: (triangle, t, u, v).
fn bits(h: &&Option<Hit>) -> Option<[u32; 4]> {
    h.map(|h| [h.triangle, h.t.to_bits(), h.u.to_bits(), h.v.to_bits()])
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
        let ms = |d: Duration| d.as_secs_f64() * 1e3;
        let mut lines = vec![
            format!(
                "GPU: {}; scene uploaded and kernels made in {:.1} ms (making them {:.1} ms); {} edge functions; \
                 {}; subnormals {}; {}",
                self.adapter,
                ms(self.setup),
                ms(self.compile),
                if self.exact_edges { "f64 (exact)" } else { "f32" },
                if self.unfused { "no fused multiply-adds" } else { "the driver may fuse multiply-adds" },
                if self.subnormals { "kept" } else { "may be flushed" },
                match self.loop_cap {
                    Some(cap) => format!(
                        "loops capped at {cap} iterations, {} an invocation (longer walks finish on the CPU)",
                        self.lane_budget.unwrap_or(cap)
                    ),
                    None => "no loop cap".to_string(),
                }
            ),
            format!(
                "{:<11} {:>9} {:>22} {:>22} {:>22} {:>15} {:>11}  checksum",
                "set", "rays", "kernel Mrays/s (GPU)", "kernel (host)", "with transfers", "up + down ms", "first call"
            ),
        ];
        for s in &self.sets {
            let check = super::checksum(s.name, s.hits, s.sum_t);
            lines.push(format!(
                "{:<11} {:>9} {:>22} {:>22} {:>22} {:>15} {:>8.1} ms  {}; {} rays differ from the CPU{}",
                s.name,
                thousands(s.rays as u64),
                s.kernel_device.as_ref().map_or("no timestamps".to_string(), fmt),
                fmt(&s.kernel),
                fmt(&s.end_to_end),
                format!("{:.1} + {:.1}", s.upload_ms.median, s.download_ms.median),
                ms(s.first_call),
                check,
                s.differ,
                if self.bitwise || s.name == "shadow" { "" } else { " (by distance)" }
            ));
        }
        lines.join("\n")
    }

    pub(super) fn json(&self) -> serde_json::Value {
        json!({
            "adapter": self.adapter,
            "exact_edges": self.exact_edges,
            "compared_bits": self.bitwise,
            "unfused": self.unfused,
            "keeps_subnormals": self.subnormals,
            "setup_s": self.setup.as_secs_f64(),
            "compile_s": self.compile.as_secs_f64(),
            "loop_cap": self.loop_cap,
            "lane_budget": self.lane_budget,
            "sets": self.sets.iter().map(|s| json!({
                "set": s.name, "rays": s.rays, "mrays_kernel_device": s.kernel_device,
                "mrays_kernel": s.kernel, "mrays_end_to_end": s.end_to_end,
                "upload_ms": s.upload_ms, "download_ms": s.download_ms,
                "first_call_s": s.first_call.as_secs_f64(),
                "hits": s.hits, "sum_t": s.sum_t, "differ_from_cpu": s.differ,
            })).collect::<Vec<_>>(),
        })
    }
}
