//! report.md: the tables.

use std::fmt::Write as _;

use super::hard::{FAR, KINDS as HARD_KINDS};
use super::leaks::{LeakCount, KINDS as LEAK_KINDS};
use super::measure::Speed;
use super::{count, machine, paper, render_knobs, today, Args, MeshReport, Report, Row};

/// report.md.
pub(super) fn markdown(report: &Report, args: &Args) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "# What accuracy costs: octrace report\n");
    let _ = writeln!(
        s,
        "octrace {} on {} ({} threads available; the tracing figures are single-threaded), {} UTC. \
         Mrays/s: median of {} runs on the standard sets of bench/RAYS.md, with the fastest and \
         slowest run in brackets: only a difference beyond them is a difference. Errors: each \
         configuration's answers on {} rays of each set against the f64 brute-force oracle \
         (`runtime::reference`); \"wrong\" excludes ties within rounding (two triangles at one \
         distance, hits on an edge as the oracle sees it, origins on a surface). Hard rays: {} rays of \
         each hard kind (below), nearest hits, against the oracle. Leaks: rays from inside the \
         procedural closed solids (not the meshes of this report) that hit nothing.\n",
        env!("CARGO_PKG_VERSION"),
        machine(),
        rayon::current_num_threads(),
        today(),
        args.runs,
        count(args.sample),
        count(args.hard_rays),
    );
    if let Some(n) = args.max_rays {
        let _ = writeln!(s, "Quick run: at most {} rays of each set (every k-th ray).\n", count(n));
    }
    if !cfg!(feature = "embree") {
        let _ = writeln!(
            s,
            "Embree: not in this build (`cargo build --release -p octrace --features embree`, with Debian's \
             libembree-dev installed, adds it in fast and robust modes).\n"
        );
    }
    for r in &report.meshes {
        mesh_section(&mut s, r);
    }
    if let Some(first) = report.meshes.first() {
        leak_table(&mut s, first, args);
    }
    render_section(&mut s, report);
    s
}

fn mesh_section(s: &mut String, r: &MeshReport) {
    let _ = writeln!(s, "## {} ({} triangles)\n", r.name, count(r.triangles));
    let _ = writeln!(
        s,
        "The octree's walk ran its {} build; the seeds' structures, the scalar steps and obvhs are \
         compiled for the x86-64 baseline, Embree picks its own. The slab exit test runs one walk at a \
         time (its batches give up the eight-lane walk): the \"Plücker, one walk at a time\" row runs \
         that loop with the default test, so the two rows compare the tests alone.\n",
        if r.x86_64_v3 { "x86-64-v3 (AVX2)" } else { "baseline (SSE2)" }
    );
    let _ = writeln!(
        s,
        "| knob | setting | bake s | MB | leaves | refs / tri | primary | incoherent | shadow | wrong / rays | ties | hard wrong / M | max \\|Δt\\|/t | leaks / M (solids) |"
    );
    let _ = writeln!(
        s,
        "| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"
    );
    for row in r.rows.iter().filter(|r| r.knob != "baseline") {
        let peer = row.knob == "peer";
        let dash = |x: String| if peer { "—".to_string() } else { x };
        let _ = writeln!(
            s,
            "| {} | {} | {:.2} | {} | {} | {} | {} | {} / {} | {} | {:.0} | {:.1e} | {:.1} |",
            row.knob,
            row.setting,
            row.bake_seconds,
            dash(format!("{:.1}", row.bytes as f64 / 1e6)),
            dash(count(row.leaves as usize)),
            dash(format!("{:.2}", row.references_per_triangle)),
            speeds(row),
            row.errors.wrong,
            count(row.errors.compared),
            row.errors.ties,
            row.hard_wrong_per_million,
            row.errors.max_relative_dt,
            row.leaks_per_million,
        );
    }
    let front: Vec<String> = pareto(&r.rows).iter().map(|row| format!("{} ({})", row.knob, row.setting)).collect();
    let _ = writeln!(
        s,
        "\nPareto front (no other configuration clearly faster on a set, beyond both spreads, and \
         no slower on any, with no more wrong answers, hard or random, and leaks): {}.\n",
        front.join(", ")
    );
    let b = &r.balance;
    let _ = writeln!(
        s,
        "2:1 balanced against unconstrained (the \"octree\" rows; scalar steps both, the unconstrained \
         tree's MB in memory without boxes or cube map): on the {} incoherent rays, a walk visits {:.1} \
         leaves and runs {:.1} triangle tests in the balanced tree, {:.1} leaves and {:.1} tests in the \
         unconstrained one, which descends {:.2} levels a ray below its ropes (at most {} in one step).\n",
        count(b.rays),
        b.balanced_leaves_per_ray,
        b.balanced_tests_per_ray,
        b.unconstrained_leaves_per_ray,
        b.unconstrained_tests_per_ray,
        b.descents_per_ray,
        b.deepest_descent,
    );
    baseline_table(s, r);
    hard_table(s, r);
    if !r.paper.is_empty() {
        paper::paper_tables(s, &r.paper);
    }
}

/// The three sets' Mrays/s with their spreads: `12.34 (11.9–12.8)`.
fn speeds(row: &Row) -> String {
    let one = |sp: &Speed| format!("{:.2} ({:.1}–{:.1})", sp.median, sp.min, sp.max);
    row.speeds().iter().map(one).collect::<Vec<_>>().join(" | ")
}

/// The seeds' baselines beside the octree's defaults.
fn baseline_table(s: &mut String, r: &MeshReport) {
    let _ = writeln!(
        s,
        "The seeds' baselines (seed 001's BVH builds, stack traversal near child first; seed 003's SAH kd-tree, \
         stack traversal front to back; the same watertight triangle test, rays and oracle; one thread):\n"
    );
    let _ = writeln!(
        s,
        "| structure | build s | nodes | SAH cost | primary | incoherent | shadow | wrong / rays | hard wrong / M | leaks / M (solids) |"
    );
    let _ = writeln!(s, "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |");
    for row in r.rows.iter().filter(|r| r.knob == "defaults" || r.knob == "baseline") {
        let (nodes, cost) = match row.sah_cost {
            Some(c) => (count(row.leaves as usize), format!("{c:.1}")),
            None => (format!("{} leaves", count(row.leaves as usize)), "—".into()),
        };
        let name = if row.knob == "defaults" { format!("octree ({})", row.setting) } else { row.setting.clone() };
        let _ = writeln!(
            s,
            "| {name} | {:.2} | {nodes} | {cost} | {} | {} / {} | {:.0} | {:.1} |",
            row.bake_seconds,
            speeds(row),
            row.errors.wrong,
            count(row.errors.compared),
            row.hard_wrong_per_million,
            row.leaks_per_million,
        );
    }
    let _ = writeln!(s);
}

/// Wrong answers on each kind of hard ray, every configuration.
fn hard_table(s: &mut String, r: &MeshReport) {
    let _ = writeln!(
        s,
        "Hard rays, wrong answers (ties within rounding apart) of {} rays a kind: in a cell plane of the \
         octree (a zero direction component, +0.0 or -0.0), along a cell edge, from or through a cell \
         corner, grazing a triangle (1e-2 to 1e-6 radians), aimed exactly at a vertex, at the thinnest 1 % \
         of the triangles, from origins on the surface, and the same mix at the mesh moved {FAR:e} root \
         edges from the origin (each configuration built again there):\n",
        count(r.hard_rays)
    );
    let _ = writeln!(s, "| knob | setting | {} |", HARD_KINDS.join(" | "));
    let _ = writeln!(s, "| --- | --- |{}", " ---: |".repeat(HARD_KINDS.len()));
    for row in &r.rows {
        let cells: Vec<String> = HARD_KINDS
            .iter()
            .map(|k| {
                row.hard.iter().find(|h| h.kind == *k).map_or("—".into(), |h| {
                    if h.errors.ties > 0 {
                        let s = if h.errors.ties == 1 { "" } else { "s" };
                        format!("{} ({} tie{s})", h.errors.wrong, h.errors.ties)
                    } else {
                        h.errors.wrong.to_string()
                    }
                })
            })
            .collect();
        let _ = writeln!(s, "| {} | {} | {} |", row.knob, row.setting, cells.join(" | "));
    }
    let _ = writeln!(s);
}

/// Leaks per million by solid and by kind of ray, every configuration (the solids'
/// counts do not depend on the report's meshes: the first mesh's rows carry them).
fn leak_table(s: &mut String, r: &MeshReport, args: &Args) {
    let solids: Vec<&str> = {
        let mut v: Vec<&str> = Vec::new();
        for c in r.rows.first().map_or(&[][..], |row| &row.leaks[..]) {
            if !v.contains(&c.solid) {
                v.push(c.solid);
            }
        }
        v
    };
    let _ = writeln!(s, "## Leaks from the procedural closed solids\n");
    let _ = writeln!(
        s,
        "Rays from points well inside `octrace soak`'s closed solids (not the meshes above), each solid baked \
         or built with the configuration: {} random rays, rays at every vertex and edge midpoint (\"aimed\"), \
         and {} rays on the octree's planes (\"grid\": in cell planes with +0.0 and -0.0 components, along \
         cell edges, from and through cell corners) a solid. Leaks per million, by solid and by kind:\n",
        count(args.leak_rays),
        count(args.leak_rays),
    );
    let _ = writeln!(s, "| knob | setting | {} | {} | all |", solids.join(" | "), LEAK_KINDS.join(" | "));
    let _ = writeln!(s, "| --- | --- |{}", " ---: |".repeat(solids.len() + LEAK_KINDS.len() + 1));
    let rate = |counts: Vec<&LeakCount>| {
        let rays: usize = counts.iter().map(|c| c.rays).sum();
        let leaks: usize = counts.iter().map(|c| c.leaks).sum();
        format!("{:.1}", leaks as f64 * 1e6 / rays.max(1) as f64)
    };
    for row in &r.rows {
        let by_solid = solids.iter().map(|&x| rate(row.leaks.iter().filter(|c| c.solid == x).collect()));
        let by_kind = LEAK_KINDS.iter().map(|&k| rate(row.leaks.iter().filter(|c| c.kind == k).collect()));
        let cells: Vec<String> = by_solid.chain(by_kind).collect();
        let _ =
            writeln!(s, "| {} | {} | {} | {:.1} |", row.knob, row.setting, cells.join(" | "), row.leaks_per_million);
    }
    let _ = writeln!(s);
}

/// The renderer's own knobs, priced.
fn render_section(s: &mut String, report: &Report) {
    if report.render_knobs.is_empty() {
        return;
    }
    let (soft, depth) = render_knobs::references();
    let _ = writeln!(s, "## The renderer's knobs\n");
    let _ = writeln!(
        s,
        "The effects scene (`octrace demo --scene effects`) rendered on all threads with one knob turned from \
         the defaults: its error against a reference render ({soft} soft-shadow samples; reflection depth \
         {depth}) as the root mean square difference in 8-bit levels of the image, and its time (one render, \
         wall clock).\n"
    );
    let _ = writeln!(s, "| knob | value | seconds | rays | RMSE (8-bit levels) |");
    let _ = writeln!(s, "| --- | ---: | ---: | ---: | ---: |");
    for k in &report.render_knobs {
        let value = if k.default { format!("{} (default)", k.value) } else { k.value.to_string() };
        let _ = writeln!(s, "| {} | {value} | {:.3} | {} | {:.2} |", k.knob, k.seconds, count(k.rays as usize), k.rmse);
    }
    let _ = writeln!(s);
}

/// The rows no other row dominates: no slower on any set (the runs' ranges overlap or
/// it is clearly faster), clearly faster on one or with fewer errors, and no more
/// wrong answers (random and hard) and leaks.
pub(super) fn pareto(rows: &[Row]) -> Vec<&Row> {
    let error = |r: &Row| (r.errors.wrong, r.hard_wrong_per_million, r.leaks_per_million);
    let dominates = |a: &Row, b: &Row| {
        let (sa, sb) = (a.speeds(), b.speeds());
        let no_slower = sa.iter().zip(&sb).all(|(x, y)| x.not_slower(y));
        let clearly_faster = sa.iter().zip(&sb).any(|(x, y)| x.clearly_faster(y));
        let (ea, eb) = (error(a), error(b));
        let no_worse = ea.0 <= eb.0 && ea.1 <= eb.1 && ea.2 <= eb.2;
        let fewer = ea.0 < eb.0 || ea.1 < eb.1 || ea.2 < eb.2;
        no_slower && no_worse && (clearly_faster || fewer)
    };
    rows.iter().filter(|b| !rows.iter().any(|a| dominates(a, b))).collect()
}
