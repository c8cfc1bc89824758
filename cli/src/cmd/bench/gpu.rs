//! The GPU figures of `bench --gpu`.
use std::time::{Duration, Instant};

use octrace_runtime::gpu::{Answers, GpuCamera, GpuContext, GpuHit, GpuNearest, GpuOptions, GpuTracer};
use octrace_runtime::{Hit, Ray, Scene, TriangleTest};
use serde_json::json;

use super::Spread;
use crate::output::thousands;

pub(super) struct GpuSet {
    name: &'static str,
    rays: usize,
    /// The kernel on the device (timestamp queries), where the adapter has them.
    kernel_device: Option<Spread>,
    /// Waiting for the device, as the host sees it (copies and kernels less what
    /// overlapped with the host's copies).
    kernel: Spread,
    /// Whole calls with full records (32 bytes a ray back).
    end_to_end: Spread,
    /// Whole calls with the record the query needs: distance and triangle (8 bytes)
    /// for nearest hits, one bit for occlusion.
    compact: Spread,
    /// Milliseconds writing the rays into mapped memory and copying the answers out.
    upload_ms: Spread,
    download_ms: Spread,
    /// Milliseconds of a call's transfers alone (the kernel over no rays), full
    /// records, and of a `memcpy` of the same bytes (rays and answers) on the host.
    transfers_ms: Spread,
    memcpy_ms: Spread,
    /// The set's first, untimed call (the driver may compile at its first dispatch).
    first_call: Duration,
    hits: usize,
    sum_t: f64,
    /// Rays whose answer differs from the CPU's: in any bit of (triangle, t, u, v)
    /// where the kernel computes as the CPU does (f64 on the adapter, the watertight
    /// test), else by another distance (1e-5 t; another triangle at the same distance
    /// counts as the same answer); compact records the same way, distance and triangle.
    differ: usize,
}

/// Camera rays made on the device (the primary set's view, unnormalized directions).
pub(super) struct GpuCameraFigures {
    rays: usize,
    /// Mrays/s of whole calls, distance and triangle back.
    nearest: Spread,
    /// Mrays/s of whole calls, distance back.
    distance: Spread,
    kernel_device: Option<Spread>,
    /// Pixels whose answer differs from the CPU's for the same rays made on the host.
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
    /// Times each set was repeated in one batch.
    repeat: usize,
    buffers: u64,
    /// Rays the CPU finished (out of loop budget, or left in doubt by the exact
    /// test's filter), over every call.
    finished_on_cpu: u64,
    sets: Vec<GpuSet>,
    camera: GpuCameraFigures,
}

/// A `memcpy` of `bytes` into a buffer already touched: the host's speed for the
/// transfers' bytes.
fn memcpy_ms(src: &[u8], dst: &mut [u8]) -> f64 {
    let t = Instant::now();
    dst.copy_from_slice(src);
    std::hint::black_box(&dst);
    t.elapsed().as_secs_f64() * 1e3
}

/// Times each set on the GPU and compares its answers with the CPU's (`cpu`, the
/// sets' CPU results, in the same order, traced with `test`); each set repeated
/// `repeat` times in a batch. The GPU traces with the exact test where `exact` (the
/// flag) asks, else with its default, the watertight one.
pub(super) fn measure(
    scene: &Scene,
    sets: &[(&'static str, Vec<Ray>, bool)],
    cpu: &[super::SetResult],
    runs: usize,
    (test, exact): (TriangleTest, bool),
    repeat: usize,
    frame: &octrace_runtime::raysets::Frame,
) -> anyhow::Result<GpuReport> {
    let gpu = GpuContext::new()?;
    let t = Instant::now();
    // The exact test where asked (--exact); else the GPU's default, the watertight
    // one, compared with the CPU's watertight answers (Möller-Trumbore is the CPU's
    // only: its answers are compared by distance).
    let gpu_test = if exact { TriangleTest::Exact } else { TriangleTest::Watertight };
    let options = GpuOptions { triangle_test: gpu_test, ..GpuOptions::default() };
    let tracer = GpuTracer::with_options(&gpu.device, &gpu.queue, scene, options)?;
    let setup = t.elapsed();
    let bitwise = test != TriangleTest::MollerTrumbore && tracer.uses_f64();
    let again = (test != TriangleTest::MollerTrumbore && test != gpu_test).then(|| tracer.cpu_tracer());
    let mut out = Vec::new();
    for ((name, set, occlusion), cpu) in sets.iter().zip(cpu) {
        let rays: Vec<Ray> =
            if repeat > 1 { set.iter().copied().cycle().take(set.len() * repeat).collect() } else { set.clone() };
        let n = rays.len();
        let mrays = |d: Duration| n as f64 / d.as_secs_f64().max(1e-9) / 1e6;
        let mut full = vec![GpuHit::default(); n];
        let mut nearest = vec![GpuNearest::default(); n];
        let mut bits = vec![0u32; n.div_ceil(32)];
        let t = Instant::now();
        tracer.trace_into(&rays, *occlusion, Answers::Full(&mut full))?;
        let first_call = t.elapsed();
        let compact_call = |nearest: &mut [GpuNearest], bits: &mut [u32]| {
            if *occlusion {
                tracer.trace_into(&rays, true, Answers::Occluded(bits))
            } else {
                tracer.trace_into(&rays, false, Answers::Nearest(nearest))
            }
        };
        compact_call(&mut nearest, &mut bits)?;
        let (ray_bytes, answer_bytes): (&[u8], usize) = (bytemuck::cast_slice(&rays), n * 32);
        let mut scratch = vec![1u8; ray_bytes.len() + answer_bytes];
        let answer_source = vec![2u8; answer_bytes];
        let (mut device, mut kernel, mut total, mut compact) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        let (mut up, mut down, mut transfers, mut memcpy) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        for _ in 0..runs {
            let timings = tracer.trace_into(&rays, *occlusion, Answers::Full(&mut full))?;
            device.extend(timings.kernel_device.map(mrays));
            kernel.push(mrays(timings.kernel));
            total.push(mrays(timings.total));
            up.push(timings.upload.as_secs_f64() * 1e3);
            down.push(timings.download.as_secs_f64() * 1e3);
            compact.push(mrays(compact_call(&mut nearest, &mut bits)?.total));
            transfers.push(tracer.time_transfers(&rays, Answers::Full(&mut full))?.total.as_secs_f64() * 1e3);
            let (a, b) = scratch.split_at_mut(ray_bytes.len());
            memcpy.push(memcpy_ms(ray_bytes, a) + memcpy_ms(&answer_source, b));
        }
        // The answers of the last timed run, checked (time_transfers left `full` as
        // it liked: traced again).
        tracer.trace_into(&rays, *occlusion, Answers::Full(&mut full))?;
        let m = set.len();
        // The CPU's answers with the GPU's test, where the sets were timed with another.
        let recomputed;
        let (cpu_nearest, cpu_occluded): (&[Option<Hit>], &[bool]) = match &again {
            Some(t) => {
                let (mut nearest, mut occluded) = (vec![None; m], vec![false; m]);
                match *occlusion {
                    true => t.par_occluded_batch(set, &mut occluded),
                    false => t.par_intersect_batch(set, &mut nearest),
                }
                recomputed = (nearest, occluded);
                (&recomputed.0, &recomputed.1)
            }
            None => (&cpu.nearest, &cpu.occluded),
        };
        let differ = (0..n)
            .filter(|&i| {
                let (g, c) = (full[i].hit(), i % m);
                if *occlusion {
                    cpu_occluded[c] != g.is_some() || cpu_occluded[c] != (bits[i / 32] >> (i % 32) & 1 != 0)
                } else {
                    let same_full = if bitwise {
                        bits_of(&cpu_nearest[c]) == bits_of(&g)
                    } else {
                        same(nearest_of(&cpu_nearest[c]), nearest_of(&g), false)
                    };
                    let compact = (nearest[i].triangle != u32::MAX).then_some((nearest[i].triangle, nearest[i].t));
                    let same_compact = same(nearest_of(&cpu_nearest[c]), compact, bitwise);
                    !same_full || !same_compact
                }
            })
            .count();
        let hits_found: Vec<Option<Hit>> = full[..m].iter().map(GpuHit::hit).collect();
        let (found, sum_t) = super::hit_sums(&hits_found);
        out.push(GpuSet {
            name,
            rays: n,
            kernel_device: (!device.is_empty()).then(|| Spread::of(device)),
            kernel: Spread::of(kernel),
            end_to_end: Spread::of(total),
            compact: Spread::of(compact),
            upload_ms: Spread::of(up),
            download_ms: Spread::of(down),
            transfers_ms: Spread::of(transfers),
            memcpy_ms: Spread::of(memcpy),
            first_call,
            hits: found,
            sum_t: if *occlusion { 0.0 } else { sum_t },
            differ,
        });
    }
    let camera = camera_figures(&tracer, frame, runs, repeat)?;
    Ok(GpuReport {
        adapter: gpu.describe(),
        exact_edges: tracer.uses_f64(),
        bitwise,
        unfused: tracer.unfused(),
        subnormals: tracer.keeps_subnormals(),
        setup,
        compile: tracer.compile_time(),
        loop_cap: tracer.loop_cap(),
        lane_budget: tracer.lane_budget(),
        repeat,
        buffers: tracer.buffers_created(),
        finished_on_cpu: tracer.rays_finished_on_cpu(),
        sets: out,
        camera,
    })
}

/// The primary set's view made on the device (`repeat` times the pixels: a taller
/// image), traced to distance and triangle, and to distance alone.
fn camera_figures(
    tracer: &GpuTracer<'_>,
    frame: &octrace_runtime::raysets::Frame,
    runs: usize,
    repeat: usize,
) -> anyhow::Result<GpuCameraFigures> {
    let standard = octrace_runtime::raysets::Camera::standard(frame);
    let mut camera = GpuCamera::from_camera(&standard)?;
    // A taller image of the same view for larger batches (rows past the frame miss).
    camera.height *= repeat as u32;
    let n = camera.len();
    let mrays = |d: Duration| n as f64 / d.as_secs_f64().max(1e-9) / 1e6;
    let mut nearest = vec![GpuNearest::default(); n];
    let mut distance = vec![0f32; n];
    tracer.trace_camera_into(&camera, false, Answers::Nearest(&mut nearest))?;
    tracer.trace_camera_into(&camera, false, Answers::Distance(&mut distance))?;
    let (mut a, mut b, mut device) = (Vec::new(), Vec::new(), Vec::new());
    for _ in 0..runs {
        let t = tracer.trace_camera_into(&camera, false, Answers::Nearest(&mut nearest))?;
        a.push(mrays(t.total));
        device.extend(t.kernel_device.map(mrays));
        b.push(mrays(tracer.trace_camera_into(&camera, false, Answers::Distance(&mut distance))?.total));
    }
    // The CPU's answers for the same rays made on the host (the first frame's rows),
    // with the GPU tracer's triangle test.
    let m = (standard.width * standard.height) as usize;
    let rays: Vec<Ray> = (0..m).map(|i| camera.ray_at(i)).collect();
    let mut cpu = vec![None; m];
    tracer.cpu_tracer().par_intersect_batch(&rays, &mut cpu);
    let differ = cpu
        .iter()
        .enumerate()
        .filter(|(i, c)| {
            let (t, triangle) = c.map_or((f32::INFINITY, u32::MAX), |h| (h.t, h.triangle));
            nearest[*i].triangle != triangle
                || nearest[*i].t.to_bits() != t.to_bits()
                || distance[*i].to_bits() != t.to_bits()
        })
        .count();
    Ok(GpuCameraFigures {
        rays: n,
        nearest: Spread::of(a),
        distance: Spread::of(b),
        kernel_device: (!device.is_empty()).then(|| Spread::of(device)),
        differ,
    })
}

/// A hit's bits: (triangle, t, u, v).
fn bits_of(h: &Option<Hit>) -> Option<[u32; 4]> {
    h.map(|h| [h.triangle, h.t.to_bits(), h.u.to_bits(), h.v.to_bits()])
}

/// A hit's triangle and distance, what compact records keep.
fn nearest_of(h: &Option<Hit>) -> Option<(u32, f32)> {
    h.map(|h| (h.triangle, h.t))
}

/// The same answer: both miss, or hits on the same triangle or at the same distance
/// (1e-5 relative); with `bitwise`, the same triangle and distance bits.
fn same(a: Option<(u32, f32)>, b: Option<(u32, f32)>, bitwise: bool) -> bool {
    match (a, b) {
        (None, None) => true,
        (Some(a), Some(b)) if bitwise => a.0 == b.0 && a.1.to_bits() == b.1.to_bits(),
        (Some(a), Some(b)) => a.0 == b.0 || (a.1 - b.1).abs() <= 1e-5 * a.1.abs(),
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
                "{:<11} {:>10} {:>22} {:>22} {:>22} {:>22} {:>13} {:>19} {:>11}  checksum",
                "set",
                "rays",
                "kernel Mrays/s (GPU)",
                "waiting (host)",
                "full records",
                "compact records",
                "up + down ms",
                "transfers / memcpy",
                "first call"
            ),
        ];
        for s in &self.sets {
            let check = super::checksum(s.name, s.hits, s.sum_t);
            lines.push(format!(
                "{:<11} {:>10} {:>22} {:>22} {:>22} {:>22} {:>13} {:>19} {:>8.1} ms  {}; {} rays differ from the CPU{}",
                s.name,
                thousands(s.rays as u64),
                s.kernel_device.as_ref().map_or("no timestamps".to_string(), fmt),
                fmt(&s.kernel),
                fmt(&s.end_to_end),
                fmt(&s.compact),
                format!("{:.1} + {:.1}", s.upload_ms.median, s.download_ms.median),
                format!("{:.1} / {:.1} ms", s.transfers_ms.median, s.memcpy_ms.median),
                ms(s.first_call),
                check,
                s.differ,
                if self.bitwise || s.name == "shadow" { "" } else { " (by distance)" }
            ));
        }
        let c = &self.camera;
        lines.push(format!(
            "camera rays made on the GPU (the primary view{}): {} rays, {} Mrays/s with distance and \
             triangle back, {} with distance back, kernel {} (GPU clock); {} pixels differ from the CPU",
            if self.repeat > 1 { format!(", {} times as tall", self.repeat) } else { String::new() },
            thousands(c.rays as u64),
            fmt(&c.nearest),
            fmt(&c.distance),
            c.kernel_device.as_ref().map_or("untimed".to_string(), fmt),
            c.differ
        ));
        lines.push(format!(
            "(full records: 32 bytes a ray back; compact: 8 for nearest hits, a bit for occlusion; {} buffers made; \
             {} rays finished on the CPU over every call)",
            self.buffers, self.finished_on_cpu
        ));
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
            "repeat": self.repeat,
            "buffers_created": self.buffers,
            "rays_finished_on_cpu": self.finished_on_cpu,
            "camera": json!({
                "rays": self.camera.rays, "mrays_nearest": self.camera.nearest,
                "mrays_distance": self.camera.distance, "mrays_kernel_device": self.camera.kernel_device,
                "differ_from_cpu": self.camera.differ,
            }),
            "sets": self.sets.iter().map(|s| json!({
                "set": s.name, "rays": s.rays, "mrays_kernel_device": s.kernel_device,
                "mrays_kernel": s.kernel, "mrays_end_to_end": s.end_to_end,
                "mrays_compact": s.compact, "transfers_ms": s.transfers_ms, "memcpy_ms": s.memcpy_ms,
                "upload_ms": s.upload_ms, "download_ms": s.download_ms,
                "first_call_s": s.first_call.as_secs_f64(),
                "hits": s.hits, "sum_t": s.sum_t, "differ_from_cpu": s.differ,
            })).collect::<Vec<_>>(),
        })
    }
}
