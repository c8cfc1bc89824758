//! `octrace trace --all-hits / --counts / --length-inside`: the queries along a ray
//! that the walk's order answers.

use std::time::Instant;

use octrace_runtime::cpu::{BatchCrossings, CrossingCount};
use octrace_runtime::{Ray, Scene};
use serde_json::json;

use super::trace::Args;
use crate::output::{counted, thousands};

/// Traces `rays` in the mode `args` asks for and writes its layout (`trace --help`).
pub(crate) fn run(args: &Args, scene: &Scene, rays: &[Ray], to_stdout: bool) -> anyhow::Result<()> {
    let threads = args.threads.unwrap_or_else(rayon::current_num_threads);
    let gpu = args.gpu.then(octrace_runtime::gpu::GpuContext::new).transpose()?;
    let gpu_tracer =
        gpu.as_ref().map(|g| octrace_runtime::gpu::GpuTracer::new(&g.device, &g.queue, scene)).transpose()?;
    let (mode, seconds, summary) = if args.all_hits {
        let limit = args.max_hits.map_or(usize::MAX, |k| k as usize);
        let (all, seconds) = match &gpu_tracer {
            Some(g) => {
                let t = Instant::now();
                let all = truncated(g.crossings(rays)?, limit);
                (all, t.elapsed().as_secs_f64())
            }
            None => crate::with_threads(args.threads, || {
                let t = Instant::now();
                let all = scene.crossings_batch(rays, limit);
                (all, t.elapsed().as_secs_f64())
            })?,
        };
        let mut out = Vec::with_capacity(8 * all.splits.len() + 20 * all.crossings.len());
        for &s in &all.splits {
            out.extend_from_slice(&(s as u64).to_le_bytes());
        }
        for c in &all.crossings {
            for word in [c.t.to_bits(), c.triangle, c.u.to_bits(), c.v.to_bits(), c.enters as u32] {
                out.extend_from_slice(&word.to_le_bytes());
            }
        }
        crate::output::write_data(&args.out, &[&out])?;
        // A ray cut short: it has K crossings and more lie beyond (a count says).
        let cut = match args.max_hits {
            Some(k) => {
                let full: Vec<usize> = (0..rays.len()).filter(|&i| all.of(i).len() == k as usize).collect();
                let sub: Vec<Ray> = full.iter().map(|&i| rays[i]).collect();
                let counts = scene.count_crossings_batch(&sub);
                counts.iter().filter(|c| c.total > k).count()
            }
            None => 0,
        };
        let n = all.crossings.len();
        let text = format!(
            "{}{}",
            counted(n as u64, "crossing"),
            if args.max_hits.is_some() {
                format!(" ({} cut short at --max-hits)", counted(cut as u64, "ray"))
            } else {
                String::new()
            }
        );
        ("all-hits", seconds, (text, json!({ "crossings": n, "cut_short": cut })))
    } else if args.counts {
        let (counts, seconds) = match &gpu_tracer {
            Some(g) => {
                let t = Instant::now();
                let counts = g.count_crossings(rays)?;
                (counts, t.elapsed().as_secs_f64())
            }
            None => crate::with_threads(args.threads, || {
                let t = Instant::now();
                let counts = scene.count_crossings_batch(rays);
                (counts, t.elapsed().as_secs_f64())
            })?,
        };
        let mut out = Vec::with_capacity(8 * counts.len());
        for c in &counts {
            out.extend_from_slice(&c.total.to_le_bytes());
            out.extend_from_slice(&c.entries.to_le_bytes());
        }
        crate::output::write_data(&args.out, &[&out])?;
        let total: u64 = counts.iter().map(|c: &CrossingCount| c.total as u64).sum();
        let entries: u64 = counts.iter().map(|c| c.entries as u64).sum();
        let text = format!("{}, {} entering", counted(total, "crossing"), thousands(entries));
        ("counts", seconds, (text, json!({ "crossings": total, "entries": entries })))
    } else {
        let solid = scene.solid()?;
        let (lengths, seconds) = match &gpu_tracer {
            Some(g) => {
                let t = Instant::now();
                let lengths = g.length_inside(solid, rays)?;
                (lengths, t.elapsed().as_secs_f64())
            }
            None => crate::with_threads(args.threads, || -> anyhow::Result<_> {
                let t = Instant::now();
                let lengths = scene.length_inside_batch(rays)?;
                Ok((lengths, t.elapsed().as_secs_f64()))
            })??,
        };
        crate::output::write_data(&args.out, &[bytemuck::cast_slice(&lengths)])?;
        let inside = lengths.iter().filter(|&&l| l > 0.0).count();
        let total: f64 = lengths.iter().map(|&l| l as f64).sum();
        let text = format!("{} partly inside, total length {total:.6}", counted(inside as u64, "ray"));
        ("length-inside", seconds, (text, json!({ "rays_inside": inside, "total_length": total })))
    };
    let rate = rays.len() as f64 / seconds.max(1e-9) / 1e6;
    let (text, fields) = summary;
    let on = match &gpu {
        Some(g) => format!("whole call, {}", g.describe()),
        None => format!("tracing only, {}", counted(threads as u64, "thread")),
    };
    if args.json {
        let mut j = json!({
            "rays": rays.len(), "mode": mode, "seconds": seconds, "mrays_per_s": rate, "threads": threads, "on": on,
        });
        if let (Some(j), Some(f)) = (j.as_object_mut(), fields.as_object()) {
            j.extend(f.clone());
        }
        crate::report!(to_stdout, "{j}");
    } else {
        crate::report!(to_stdout, "{} rays, {text}, {rate:.2} Mrays/s ({mode}, {on})", thousands(rays.len() as u64),);
    }
    Ok(())
}

/// `all` with each ray's list cut to its first `limit` (the GPU lists them whole).
fn truncated(all: BatchCrossings, limit: usize) -> BatchCrossings {
    if limit == usize::MAX {
        return all;
    }
    let mut out = BatchCrossings { splits: vec![0], crossings: Vec::new() };
    for i in 0..all.splits.len() - 1 {
        let list = all.of(i);
        out.crossings.extend_from_slice(&list[..list.len().min(limit)]);
        out.splits.push(out.crossings.len());
    }
    out
}
