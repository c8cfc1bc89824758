//! `octrace trace --all-hits / --counts / --length-inside`: the queries along a ray
//! that the walk's order answers.

use std::time::Instant;

use anyhow::Context;

use octrace_runtime::cpu::CrossingCount;
use octrace_runtime::Ray;
use serde_json::json;

use super::trace::Args;
use crate::output::{counted, thousands};

/// Traces the rays in the mode `args` asks for and writes its layout (`trace --help`).
pub(crate) fn run(args: Args) -> anyhow::Result<()> {
    let (scene, rays, to_stdout) = super::trace::inputs(&args)?;
    let (args, scene, rays) = (&args, &scene, &rays[..]);
    let threads = args.threads.unwrap_or_else(rayon::current_num_threads);
    let gpu = args.gpu.then(octrace_runtime::gpu::GpuContext::new).transpose()?;
    let gpu_tracer = gpu.as_ref().map(|g| super::trace::gpu_tracer(g, scene)).transpose()?;
    let (mode, seconds, summary) = if args.all_hits {
        let limit = args.max_hits.map_or(usize::MAX, |k| k as usize);
        let budget = args.max_memory.unwrap_or_else(|| octrace_format::memory::share(4));
        let advice = "pass --max-hits, fewer rays, or a larger --max-memory";
        let (all, seconds) = match &gpu_tracer {
            Some(g) => {
                let t = Instant::now();
                let all = g.crossings_within(rays, limit, budget).context(advice)?;
                (all, t.elapsed().as_secs_f64())
            }
            None => crate::with_threads(args.threads, || {
                let t = Instant::now();
                let all = scene.crossings_batch_within(rays, limit, budget).context(advice)?;
                anyhow::Ok((all, t.elapsed().as_secs_f64()))
            })??,
        };
        // Little-endian words, written as they lie in memory.
        let offsets: Vec<u64> = all.splits.iter().map(|&s| (s as u64).to_le()).collect();
        let mut records: Vec<[u32; 5]> = octrace_format::memory::try_with_capacity(all.crossings.len(), "crossings")?;
        records.extend(
            all.crossings
                .iter()
                .map(|c| [c.t.to_bits(), c.triangle, c.u.to_bits(), c.v.to_bits(), c.enters as u32].map(u32::to_le)),
        );
        crate::output::write_data(&args.out, &[bytemuck::cast_slice(&offsets), bytemuck::cast_slice(&records)])?;
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
