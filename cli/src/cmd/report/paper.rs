//! The paper's Tables 1 and 3 (Portalez & Duguet 2016): leaves without and with the
//! 2:1 constraint, and megabytes per array, ours at the paper's depth beside the
//! published rows.

use std::fmt::Write as _;

use octrace_bake::{bake, BuildParams, Mesh};
use octrace_runtime::Scene;
use serde::Serialize;

use crate::output::thousands;

/// One row of the paper's Table 1 (leaves without and with the 2:1 constraint) and
/// Table 3 (MB per array).
#[derive(Debug, Serialize)]
pub(super) struct PaperRow {
    /// Who measured it: "octrace" or "paper (published)".
    source: &'static str,
    depth: u32,
    leaf_target: String,
    unconstrained: u64,
    constrained: u64,
    /// MB: cube map, octree, triangles, boxes, point location, total.
    mb: [f64; 6],
}

/// The paper's depth and published figures (Portalez & Duguet 2016, Tables 1 and 3)
/// for the meshes it measured, by the name the report gives them (`bunny`,
/// `dragon.obj`, ...).
fn published(name: &str) -> Option<(u32, PaperRow)> {
    let row = |depth, unconstrained, constrained, mb| PaperRow {
        source: "paper (published)",
        depth,
        leaf_target: "~6 a leaf".into(),
        unconstrained,
        constrained,
        mb,
    };
    match name.split('.').next().unwrap_or(name) {
        "bunny" => Some((8, row(8, 69_000, 83_000, [1.5, 3.6, 12.2, 1.3, f64::NAN, 18.6]))),
        "dragon" => Some((11, row(11, 855_000, 1_144_000, [24.0, 50.0, 156.0, 18.0, f64::NAN, 248.0]))),
        _ => None,
    }
}

/// The paper's tables for `mesh` at the paper's depth, leaf targets 16 (ours) and 6
/// (the paper's leaves), beside the published row.
pub(super) fn paper_rows(name: &str, mesh: &Mesh) -> anyhow::Result<Vec<PaperRow>> {
    let Some((depth, published)) = published(name) else { return Ok(Vec::new()) };
    let mut rows = vec![published];
    for leaf in [16, 6] {
        let params = BuildParams { max_depth: Some(depth), leaf_size: Some(leaf), ..BuildParams::auto() };
        let scene = Scene::from_baked(bake(mesh, &params)?)?;
        let view = scene.view();
        let stats = octrace_format::stats::SceneStatistics::compute(&view)?;
        let b = stats.bytes;
        let mb = |x: u64| x as f64 / 1e6;
        rows.push(PaperRow {
            source: "octrace",
            depth: view.params.max_depth,
            leaf_target: leaf.to_string(),
            unconstrained: view.stats.leaves_before_balance,
            constrained: stats.leaves,
            mb: [mb(b.cube_map), mb(b.octree), mb(b.triangles), mb(b.boxes), mb(b.point_location), mb(b.total())],
        });
    }
    Ok(rows)
}

/// The paper's Tables 1 and 3, ours beside the published figures.
pub(super) fn paper_tables(s: &mut String, rows: &[PaperRow]) {
    let _ =
        writeln!(s, "The paper's Table 1 (leaves without / with the 2:1 constraint) and Table 3 (MB), at its depth:\n");
    let _ = writeln!(s, "| source | depth | leaf target | unconstrained | constrained | ratio | cube map | octree | triangles | boxes | point loc. | total MB |");
    let _ = writeln!(s, "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |");
    for p in rows {
        let mb: Vec<String> = p.mb.iter().map(|m| if m.is_nan() { "—".into() } else { format!("{m:.1}") }).collect();
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {} | {:.0} % | {} |",
            p.source,
            p.depth,
            p.leaf_target,
            thousands(p.unconstrained),
            thousands(p.constrained),
            100.0 * p.constrained as f64 / p.unconstrained.max(1) as f64,
            mb.join(" | ")
        );
    }
    let _ = writeln!(
        s,
        "\nOur \"triangles\" column holds the per-leaf reference lists, the triangles once each and the id map; \
         the paper stored each triangle once per leaf that lists it, and its leaf criterion is not given.\n"
    );
}

#[cfg(test)]
mod tests {
    use super::*;
    use octrace_bake::procedural;

    /// The paper's tables: the published row, then ours at the paper's depth for leaf
    /// targets 16 and 6, with the balance adding leaves.
    #[test]
    fn paper_tables_put_our_bakes_beside_the_published_rows() {
        let mesh = procedural::sphere([0.0; 3], 1.0, 24, 32);
        let rows = paper_rows("bunny.obj", &mesh).unwrap();
        assert_eq!(rows.len(), 3);
        assert_eq!((rows[0].source, rows[0].constrained), ("paper (published)", 83_000));
        for (row, leaf) in rows[1..].iter().zip(["16", "6"]) {
            assert_eq!((row.source, row.depth, row.leaf_target.as_str()), ("octrace", 8, leaf));
            assert!(row.constrained >= row.unconstrained && row.unconstrained > 0, "{row:?}");
            assert!(row.mb[5] > 0.0 && row.mb[..5].iter().sum::<f64>() <= row.mb[5] + 1e-9, "{row:?}");
        }
        assert!(paper_rows("teapot.glb", &mesh).unwrap().is_empty());
        let mut md = String::new();
        paper_tables(&mut md, &rows);
        assert!(md.contains("| paper (published) | 8 | ~6 a leaf | 69,000 | 83,000 | 120 % |"), "{md}");
    }
}
