//! `octrace inspect`.

use std::path::PathBuf;

use octrace_format::stats::SceneStatistics;
use octrace_format::{SceneView, Wrap};
use serde_json::json;

use crate::output::{counted, mb, thousands};

#[derive(clap::Args, Debug)]
#[command(after_long_help = mapped_scene_help!())]
pub(crate) struct Args {
    /// The .oct file.
    pub file: PathBuf,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
}

pub(crate) fn run(args: Args) -> anyhow::Result<()> {
    let scene = crate::open::open_scene(&args.file)?;
    let file = scene.file().expect("opened from a file");
    let report = Report::new(&scene.view(), file.header(), std::fs::metadata(&args.file)?.len())?;
    if args.json {
        crate::out!("{}", serde_json::to_string_pretty(&report.json())?);
    } else {
        crate::out!("{}", report.text(&crate::show(&args.file)));
    }
    Ok(())
}

/// Everything `inspect` prints.
pub(crate) struct Report<'a> {
    view: SceneView<'a>,
    stats: SceneStatistics,
    version: octrace_format::Version,
    bake_time_us: u64,
    payload_len: u64,
    sections: [octrace_format::Section; octrace_format::SECTION_COUNT],
    file_bytes: u64,
}

impl<'a> Report<'a> {
    pub(crate) fn new(view: &SceneView<'a>, header: &octrace_format::Header, file_bytes: u64) -> anyhow::Result<Self> {
        Ok(Report {
            stats: SceneStatistics::compute(view)?,
            view: view.clone(),
            version: header.version,
            bake_time_us: header.bake_time_us,
            payload_len: header.payload_len,
            sections: header.sections,
            file_bytes,
        })
    }

    fn balance_growth(&self) -> f64 {
        100.0 * (self.stats.leaves as f64 / self.view.stats.leaves_before_balance.max(1) as f64 - 1.0)
    }

    /// Bytes of the uncompressed file (header and archive).
    fn archive_file_bytes(&self) -> u64 {
        octrace_format::HEADER_LEN as u64 + self.payload_len
    }

    /// ", zstd: X on disk" when the file on disk is compressed.
    fn on_disk(&self) -> String {
        if self.file_bytes == self.archive_file_bytes() {
            String::new()
        } else {
            format!(" (zstd-compressed: {} on disk)", mb(self.file_bytes))
        }
    }

    /// Whether the depth is what f32 precision allows at the scene's position and less
    /// than the automatic choice for its triangles: the bake was limited there.
    fn depth_limited_by_precision(&self) -> bool {
        let v = &self.view;
        let allowed = octrace_bake::octree::precision_depth(v.bounds.root_lo, v.bounds.root_size);
        let kept = (v.stats.input_triangles - v.stats.degenerate_triangles) as usize;
        let automatic = octrace_bake::BuildParams { leaf_size: Some(v.params.leaf_size), ..Default::default() };
        v.params.max_depth == allowed && allowed < automatic.resolve(kept).max_depth
    }

    fn bake_time(&self) -> String {
        match self.bake_time_us {
            0 => "not recorded (reproducible file)".into(),
            us => format!("{:.3} s", us as f64 / 1e6),
        }
    }

    pub(crate) fn text(&self, name: &str) -> String {
        let (s, v) = (&self.stats, &self.view);
        let b = &s.bytes;
        let res = v.cube_resolution();
        let histogram: Vec<String> = s
            .depth_histogram
            .iter()
            .enumerate()
            .filter(|(_, &n)| n > 0)
            .map(|(level, &n)| format!("{level}:{}", thousands(n)))
            .collect();
        let lines = [
            format!(
                "{name}: octrace scene, format {}, {}{}",
                self.version,
                mb(self.archive_file_bytes()),
                self.on_disk()
            ),
            format!(
                "triangles          {} stored, {} degenerate left out, {} in the input",
                thousands(s.triangles),
                thousands(v.stats.degenerate_triangles),
                thousands(v.stats.input_triangles)
            ),
            format!(
                "leaves             {} ({} before 2:1 balance, +{:.1} %; {} empty)",
                thousands(s.leaves),
                thousands(v.stats.leaves_before_balance),
                self.balance_growth(),
                thousands(s.empty_leaves)
            ),
            format!("depth histogram    {}", histogram.join("  ")),
            format!(
                "triangles / leaf   mean {:.2} over non-empty leaves, max {}, {} references",
                s.triangles_per_leaf_mean,
                s.triangles_per_leaf_max,
                thousands(s.triangle_references)
            ),
            format!(
                "overfull leaves    {}{}",
                thousands(s.overfull_leaves),
                if s.overfull_leaves > 0 {
                    format!(
                        " at the depth limit with more than {} x the leaf size ({} references: triangles sharing \
                         cells at every depth, fans or copies; a ray through one tests them all)",
                        octrace_format::stats::OVERFULL_FACTOR,
                        thousands(s.overfull_references)
                    )
                } else {
                    String::new()
                }
            ),
            format!("neighbours / leaf  mean {:.2}", s.neighbours_per_leaf_mean),
            format!("cube map           {res} x {res} texels a face, level {}", v.params.cube_level),
            format!(
                "bytes              octree {}, triangles {}, boxes {}, cube map {}, point location {}, shading {}; total {}",
                mb(b.octree),
                mb(b.triangles),
                mb(b.boxes),
                mb(b.cube_map),
                mb(b.point_location),
                mb(b.shading),
                mb(b.total())
            ),
            format!(
                "bake               max depth {}{}, leaf size {}, margin {:e} of the root edge; time {}",
                v.params.max_depth,
                if self.depth_limited_by_precision() {
                    " (the most f32 precision allows at this position: cells of four spacings)"
                } else {
                    ""
                },
                v.params.leaf_size,
                v.params.margin,
                self.bake_time()
            ),
            format!(
                "bounds             mesh {:?} .. {:?}; root cube at {:?}, edge {}",
                v.bounds.mesh_lo, v.bounds.mesh_hi, v.bounds.root_lo, v.bounds.root_size
            ),
            format!("surface            {}", surface(&v.stats.edges)),
            self.scene_data(),
        ];
        let mut text = lines.join("\n");
        // Parts whose own surface says more than the whole's (a closed part in an open
        // scene, or the other way round), when there are several.
        let parts = &v.shading.parts;
        if parts.len() > 1 {
            let differing = parts.iter().enumerate().filter(|(_, p)| p.edges.is_closed() != v.stats.edges.is_closed());
            for (shown, (i, p)) in differing.enumerate() {
                if shown == 8 {
                    text.push_str(&format!("\n{:<18} ... (`--json` lists every part)", ""));
                    break;
                }
                let (first, end) = (p.first, p.first as u64 + p.count as u64);
                text.push_str(&format!(
                    "\n{:<18} part {i}, {}, triangles {first}..{end}: {}",
                    "",
                    p.name,
                    surface(&p.edges)
                ));
            }
        }
        let effects = &v.shading.effects;
        if effects.is_empty() {
            text.push_str("\neffects            none (primary rays only)");
        }
        for (i, e) in effects.iter().enumerate() {
            let label = if i == 0 { "effects" } else { "" };
            text.push_str(&format!("\n{label:<18} {}: {}", e.effect.name(), e.reason));
        }
        text
    }

    /// Materials, lights, cameras and the per-triangle attributes present.
    fn scene_data(&self) -> String {
        let v = &self.view;
        let sh = v.shading;
        let per_triangle: Vec<&str> = [
            (!v.material_ids.is_empty()).then_some("material ids"),
            (!v.normals.is_empty()).then_some("normals"),
            (!v.uvs.is_empty()).then_some("uvs"),
            (!v.colors.is_empty()).then_some("vertex colours"),
        ]
        .into_iter()
        .flatten()
        .collect();
        let attrs = if per_triangle.is_empty() { "none".to_string() } else { per_triangle.join(", ") };
        let n = |count: usize, thing: &str| counted(count as u64, thing);
        let mut text = format!(
            "scene data         {}, {}, {}, {}, {}; per triangle: {attrs}",
            n(sh.parts.len(), "mesh part"),
            n(sh.materials.len(), "material"),
            n(sh.lights.len(), "light"),
            n(sh.cameras.len(), "camera"),
            n(sh.textures.len(), "texture"),
        );
        // `render --camera N` takes these indices.
        for (i, c) in sh.cameras.iter().enumerate() {
            let label = if i == 0 { "cameras" } else { "" };
            let projection = match c.orthographic {
                Some(h) => format!("orthographic, {:.3} high", 2.0 * h),
                None => format!("perspective, yfov {:.1} degrees", c.yfov.to_degrees()),
            };
            text.push_str(&format!("\n{label:<18} {i}: '{}', {projection}", c.name));
        }
        for (i, t) in sh.textures.iter().enumerate() {
            let label = if i == 0 { "textures" } else { "" };
            text.push_str(&format!(
                "\n{label:<18} {}: {} x {}, {} filter, wrap {} / {}, alpha down to {:.2}",
                t.name,
                t.width,
                t.height,
                t.filter.name(),
                t.wrap[0].name(),
                t.wrap[1].name(),
                t.min_alpha
            ));
        }
        text
    }

    pub(crate) fn json(&self) -> serde_json::Value {
        let (s, v) = (&self.stats, &self.view);
        let b = &s.bytes;
        json!({
            "format_version": self.version.to_string(),
            "file_bytes": self.archive_file_bytes(),
            "bytes_on_disk": self.file_bytes,
            "triangles": s.triangles,
            "degenerate_triangles": v.stats.degenerate_triangles,
            "input_triangles": v.stats.input_triangles,
            "leaves": s.leaves,
            "leaves_before_balance": v.stats.leaves_before_balance,
            "empty_leaves": s.empty_leaves,
            "depth_histogram": s.depth_histogram,
            "triangle_references": s.triangle_references,
            "triangles_per_leaf": { "mean": s.triangles_per_leaf_mean, "max": s.triangles_per_leaf_max },
            "overfull_leaves": { "leaves": s.overfull_leaves, "references": s.overfull_references },
            "neighbours_per_leaf_mean": s.neighbours_per_leaf_mean,
            "cube_map": { "level": v.params.cube_level, "resolution": v.cube_resolution() },
            "surface": surface_json(&v.stats.edges),
            "bytes": {
                "octree": b.octree, "triangles": b.triangles, "boxes": b.boxes,
                "cube_map": b.cube_map, "point_location": b.point_location, "shading": b.shading,
                "total": b.total(),
            },
            "scene_data": {
                "materials": v.shading.materials.iter().map(|m| json!({
                    "name": m.name, "base_color": m.base_color, "metallic": m.metallic,
                    "roughness": m.roughness, "emissive": m.emissive,
                    "alpha_mode": format!("{:?}", m.alpha_mode).to_uppercase(), "alpha_cutoff": m.alpha_cutoff,
                    "transmission": m.transmission, "ior": m.ior, "specular": m.specular, "illum": m.illum,
                    "unlit": m.unlit, "base_color_texture": m.base_color_texture,
                })).collect::<Vec<_>>(),
                "parts": v.shading.parts.iter().map(|p| json!({
                    "name": p.name, "first_triangle": p.first, "triangles": p.count,
                    "surface": surface_json(&p.edges),
                })).collect::<Vec<_>>(),
                "textures": v.shading.textures.iter().map(|t| json!({
                    "name": t.name, "width": t.width, "height": t.height,
                    "filter": t.filter.name(), "wrap": t.wrap.map(Wrap::name), "min_alpha": t.min_alpha,
                })).collect::<Vec<_>>(),
                "lights": v.shading.lights.iter().map(|l| json!({
                    "name": l.name, "kind": format!("{:?}", l.kind).to_lowercase(), "color": l.color,
                    "intensity": l.intensity, "position": l.position, "direction": l.direction,
                    "range": l.range.is_finite().then_some(l.range),
                })).collect::<Vec<_>>(),
                "cameras": v.shading.cameras.iter().enumerate().map(|(i, c)| json!({
                    "index": i, "name": c.name, "position": c.position, "forward": c.forward, "up": c.up,
                    "projection": if c.orthographic.is_some() { "orthographic" } else { "perspective" },
                    "yfov": c.orthographic.is_none().then_some(c.yfov), "aspect": c.aspect,
                    "orthographic_height": c.orthographic.map(|h| 2.0 * h),
                })).collect::<Vec<_>>(),
                "per_triangle": {
                    "material_ids": !v.material_ids.is_empty(), "normals": !v.normals.is_empty(),
                    "uvs": !v.uvs.is_empty(), "colors": !v.colors.is_empty(),
                },
            },
            "effects": v.shading.effects.iter().map(|e| json!({
                "effect": e.effect.name(), "reason": e.reason,
            })).collect::<Vec<_>>(),
            "bake": {
                "max_depth": v.params.max_depth, "leaf_size": v.params.leaf_size,
                "depth_limited_by_precision": self.depth_limited_by_precision(),
                "precision_depth": octrace_bake::octree::precision_depth(v.bounds.root_lo, v.bounds.root_size),
                "margin": v.params.margin,
                "time_s": (self.bake_time_us > 0).then(|| self.bake_time_us as f64 / 1e6),
            },
            "bounds": {
                "mesh_lo": v.bounds.mesh_lo, "mesh_hi": v.bounds.mesh_hi,
                "root_lo": v.bounds.root_lo, "root_size": v.bounds.root_size,
            },
            "sections": self.sections.iter().map(|s| json!({
                "name": s.name,
                "offset": octrace_format::HEADER_LEN as u64 + s.offset,
                "bytes": s.len,
                "xxh3": format!("{:016x}", s.xxh3),
            })).collect::<Vec<_>>(),
        })
    }
}

/// A surface's topology in words: `closed (104,288 edges, each in two triangles, all
/// consistently oriented)`, or `open: 223 boundary edges, 2 non-manifold, 5 flipped
/// (of 104,288 edges)`.
pub(crate) fn surface(e: &octrace_format::topology::EdgeCensus) -> String {
    if e.is_closed() {
        let shape = if e.is_manifold() { "each in two triangles" } else { "each in an even number of triangles" };
        let turn = if e.is_oriented() {
            "all consistently oriented".to_string()
        } else {
            format!("{} flipped", thousands(e.flipped))
        };
        let more =
            if e.is_manifold() { String::new() } else { format!(", {} non-manifold", thousands(e.non_manifold)) };
        format!("closed ({} edges, {shape}{more}; {turn})", thousands(e.edges))
    } else {
        format!(
            "open: {} boundary edges, {} non-manifold, {} flipped (of {} edges)",
            thousands(e.boundary),
            thousands(e.non_manifold),
            thousands(e.flipped),
            thousands(e.edges)
        )
    }
}

/// [`surface`] for machines.
fn surface_json(e: &octrace_format::topology::EdgeCensus) -> serde_json::Value {
    json!({
        "closed": e.is_closed(), "manifold": e.is_manifold(), "oriented": e.is_oriented(),
        "edges": e.edges, "boundary_edges": e.boundary, "non_manifold_edges": e.non_manifold,
        "flipped_edges": e.flipped,
    })
}
