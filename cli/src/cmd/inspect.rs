//! `octrace inspect`.

use std::path::PathBuf;

use octrace_format::stats::SceneStatistics;
use octrace_format::topology::SurfaceCensus;
use octrace_format::SceneView;

use crate::output::{counted, mb, thousands};

#[derive(clap::Args, Debug)]
#[command(after_long_help = mapped_scene_help!())]
pub(crate) struct Args {
    /// The .oct file, or a world: a scene description (.json: `octrace trace --help`)
    /// or an instanced file (what `bake` writes for a glTF placing a mesh many times).
    pub file: PathBuf,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
}

pub(crate) fn run(args: Args) -> anyhow::Result<()> {
    if crate::world_file::is_world(&args.file) {
        return world(&args);
    }
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
    /// The leaves whose triangles share a vertex, walked through their hierarchies.
    fans: octrace_runtime::cpu::FanSummary,
    header: octrace_format::Header,
    file_bytes: u64,
    /// The surface's and each part's edge census, counted from the triangles (the
    /// file's stored census is not trusted: `SceneView::count_surface`).
    surface: SurfaceCensus,
}

impl<'a> Report<'a> {
    pub(crate) fn new(view: &SceneView<'a>, header: &octrace_format::Header, file_bytes: u64) -> anyhow::Result<Self> {
        Ok(Report {
            stats: SceneStatistics::compute(view)?,
            fans: octrace_runtime::cpu::FanIndex::survey(view),
            view: view.clone(),
            header: *header,
            file_bytes,
            surface: view.count_surface(),
        })
    }

    fn balance_growth(&self) -> f64 {
        100.0 * (self.stats.leaves as f64 / self.view.stats.leaves_before_balance.max(1) as f64 - 1.0)
    }

    /// Bytes of the uncompressed file (header and archive).
    fn archive_file_bytes(&self) -> u64 {
        octrace_format::HEADER_LEN as u64 + self.header.payload_len
    }

    /// ", zstd: X on disk" when the file on disk is compressed.
    fn on_disk(&self) -> String {
        if self.file_bytes == self.archive_file_bytes() {
            String::new()
        } else {
            format!(" (zstd-compressed: {} on disk)", mb(self.file_bytes))
        }
    }

    /// The fans line: how many crowded leaves are fans, and what a ray tests there.
    fn fans_line(&self) -> String {
        let f = &self.fans;
        if f.leaves == 0 {
            return format!(
                "fans               none (no leaf of {}+ references has {}+ triangles around one vertex)",
                octrace_runtime::cpu::FAN_MIN_REFERENCES,
                octrace_runtime::cpu::FAN_MIN_TRIANGLES
            );
        }
        format!(
            "fans               {} {} of {}+ references around a shared vertex ({} of their references, up to {} \
             in one; {} others): a ray tests the few whose wedge its plane crosses",
            thousands(f.leaves),
            if f.leaves == 1 { "leaf" } else { "leaves" },
            octrace_runtime::cpu::FAN_MIN_REFERENCES,
            thousands(f.fan_references),
            thousands(f.largest),
            thousands(f.other_references)
        )
    }

    fn bake_time(&self) -> String {
        match self.header.bake_time_us {
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
                self.header.version,
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
                "overfull leaves    {} (at depth {}, the limit, with more than {} triangles: {} x the leaf size){}",
                thousands(s.overfull_leaves),
                v.params.max_depth,
                thousands(octrace_format::stats::OVERFULL_FACTOR * u64::from(v.params.leaf_size.max(1))),
                octrace_format::stats::OVERFULL_FACTOR,
                if s.overfull_leaves > 0 {
                    format!(
                        "; {} references: triangles sharing cells at every depth, fans or copies",
                        thousands(s.overfull_references)
                    )
                } else {
                    String::new()
                }
            ),
            self.fans_line(),
            format!("neighbours / leaf  mean {:.2}", s.neighbours_per_leaf_mean),
            format!("cube map           {res} x {res} texels a face, level {}", v.params.cube_level),
            format!(
                "bytes              octree {}, triangles {}, boxes {}, cube map {}, point location {}, shading {}, \
                 distance {}; total {}",
                mb(b.octree),
                mb(b.triangles),
                mb(b.boxes),
                mb(b.cube_map),
                mb(b.point_location),
                mb(b.shading),
                mb(b.distance),
                mb(b.total())
            ),
            match octrace_format::distance::Tree::parse(v.distance) {
                Some(t) => format!(
                    "distance           {} nodes, {} clusters, {:.1} bytes a triangle (closest points: nothing to make \
                     at open)",
                    thousands(t.nodes.len() as u64),
                    thousands(t.clusters() as u64),
                    b.distance as f64 / t.prims.len().max(1) as f64
                ),
                None => "distance           none (closest points make their tree on the first query; \
                         bake --distance stores it)"
                    .to_string(),
            },
            format!(
                "bake               max depth {}{}, leaf size {}, margin {:e} of the root edge; time {}",
                v.params.max_depth,
                if octrace_bake::summary::depth_limited_by_precision(v) {
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
            format!("surface            {}", surface(&self.surface.whole)),
            self.scene_data(),
        ];
        let mut text = lines.join("\n");
        // Parts whose own surface says more than the whole's (a closed part in an open
        // scene, or the other way round), when there are several.
        let parts = &v.shading.parts;
        if parts.len() > 1 {
            let closed = self.surface.whole.is_closed();
            let differing =
                parts.iter().zip(&self.surface.parts).enumerate().filter(|(_, (_, e))| e.is_closed() != closed);
            for (shown, (i, (p, edges))) in differing.enumerate() {
                if shown == 8 {
                    text.push_str(&format!("\n{:<18} ... (`--json` lists every part)", ""));
                    break;
                }
                let (first, end) = (p.first, p.first as u64 + p.count as u64);
                text.push_str(&format!(
                    "\n{:<18} part {i}, {}, triangles {first}..{end}: {}",
                    "",
                    p.name,
                    surface(edges)
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
            text.push_str(&format!("\n{label:<18} {}: '{}', {projection}", c.number(i), c.name));
        }
        for (i, t) in sh.textures.iter().enumerate() {
            let label = if i == 0 { "textures" } else { "" };
            text.push_str(&format!(
                "\n{label:<18} {}: {} x {}, {}, {} filter, wrap {} / {}, alpha down to {:.2}, {}{}",
                t.name,
                t.width,
                t.height,
                if t.srgb { "sRGB colour" } else { "linear colour" },
                t.filter.name(),
                t.wrap[0].name(),
                t.wrap[1].name(),
                t.min_alpha,
                match t.encoded {
                    Some(e) => format!("kept as a {} of {} bytes", e.kind.name(), crate::output::thousands(e.bytes)),
                    None => "stored as texels".into(),
                },
                texture_uses(&sh.materials, i as u32)
            ));
        }
        text
    }

    pub(crate) fn json(&self) -> serde_json::Value {
        let mut json =
            octrace_bake::summary::json(&self.view, &self.stats, &self.surface, &self.header, self.file_bytes);
        json["fans"] = self.fans.named().iter().map(|&(k, v)| (k.to_string(), serde_json::Value::from(v))).collect();
        json
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

/// What reads texture `index`: "; emissive of 'Material_MR'", a material's slots named as
/// glTF names them, the first three and how many more; empty when nothing does.
fn texture_uses(materials: &[octrace_format::Material], index: u32) -> String {
    let mut uses = Vec::new();
    for m in materials {
        let slots = octrace_format::Material::TEXTURE_SLOTS.into_iter().zip(m.slot_textures());
        uses.extend(slots.filter(|(_, t)| *t == Some(index)).map(|(slot, _)| format!("{slot} of '{}'", m.name)));
    }
    match uses.len() {
        0 => String::new(),
        n if n <= 3 => format!("; {}", uses.join(", ")),
        n => format!("; {} and {} more", uses[..3].join(", "), n - 3),
    }
}

/// `inspect` of a world (a scene description, or an instanced file): its scenes and
/// instances, validated.
fn world(args: &Args) -> anyhow::Result<()> {
    let (world, scenes) = crate::world_file::open_world(&args.file)?;
    let (kind, what) = if crate::world_file::is_description(&args.file) {
        ("description", "a scene description".to_string())
    } else {
        let bytes = std::fs::metadata(&args.file)?.len();
        ("instanced", format!("an instanced file of {}", crate::output::mb(bytes)))
    };
    let mapped = (0..world.len() as u32).filter(|&id| world.materials(id).is_some_and(|m| !m.is_empty())).count();
    let mut triangles = 0u64;
    // Each scene's instances, by the scene's address (its name after).
    let mut by_scene = std::collections::HashMap::new();
    let ids: Vec<u32> = (0..u32::MAX).take_while(|&id| world.instance(id).is_some()).collect();
    for &id in &ids {
        if let Some((scene, _)) = world.instance(id) {
            triangles += scene.view().triangle_count() as u64;
            *by_scene.entry(std::sync::Arc::as_ptr(scene)).or_insert(0u64) += 1;
        }
    }
    let used: std::collections::BTreeMap<&String, u64> =
        scenes.iter().map(|(name, s)| (name, by_scene.get(&std::sync::Arc::as_ptr(s)).copied().unwrap_or(0))).collect();
    let scene_rows: Vec<serde_json::Value> = scenes
        .iter()
        .map(|(name, s)| {
            serde_json::json!({
                "name": name, "triangles": s.view().triangle_count(), "instances": used[name],
            })
        })
        .collect();
    if args.json {
        let j = serde_json::json!({
            "kind": kind, "instances": world.len(), "placed_triangles": triangles, "world_bytes": world.bytes(),
            "instances_with_material_maps": mapped, "scenes": scene_rows,
        });
        crate::out!("{}", serde_json::to_string_pretty(&j)?);
    } else {
        let mut text = format!(
            "{}: {what}, {} of {}, {} triangles placed; the world takes {} bytes beside its scenes\n",
            crate::show(&args.file),
            crate::output::counted(world.len() as u64, "instance"),
            crate::output::counted(scenes.len() as u64, "scene"),
            crate::output::thousands(triangles),
            crate::output::thousands(world.bytes() as u64)
        );
        if mapped > 0 {
            let n = crate::output::counted(mapped as u64, "instance");
            text += &format!("  {n} with a material map (drawing other materials than its scene's own)\n");
        }
        for (name, scene) in &scenes {
            text += &format!(
                "  {:<16} {:>12} triangles, {:>8} instances\n",
                name,
                crate::output::thousands(scene.view().triangle_count() as u64),
                crate::output::thousands(used[name])
            );
        }
        crate::out!("{}", text.trim_end());
    }
    Ok(())
}
