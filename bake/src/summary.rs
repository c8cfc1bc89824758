//! What `octrace inspect --json` prints about a baked scene, as a JSON value: for
//! the command line and for the language bindings, which hand it out as they are.

use octrace_format::stats::SceneStatistics;
use octrace_format::topology::{EdgeCensus, SurfaceCensus};
use octrace_format::{Header, PartSource, SceneView, Wrap, HEADER_LEN};
use serde_json::json;

/// The scene's summary: the header, the tree's statistics (`stats`, from
/// [`SceneStatistics::compute`]), the surface's topology (`surface`, from
/// [`SceneView::count_surface`]), the scene data, the effects,
/// the bake's parameters, the bounds and the sections. `file_bytes` is the size on
/// disk (smaller than `file_bytes` in the summary for a zstd-compressed file).
///
/// # Example
/// ```
/// use octrace_bake::{bake, procedural, summary, BuildParams};
/// use octrace_format::{stats::SceneStatistics, SceneFile};
/// let baked = bake(&procedural::sphere([0.0; 3], 1.0, 8, 12), &BuildParams::auto())?;
/// let file = SceneFile::from_bytes(&baked.to_file_bytes(0)?)?;
/// let view = file.view();
/// let json = summary::json(&view, &SceneStatistics::compute(&view)?, &view.count_surface(), file.header(), 0);
/// assert_eq!(json["surface"]["closed"], true);
/// assert_eq!(json["triangles"], view.triangle_count() as u64);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn json(
    v: &SceneView<'_>,
    s: &SceneStatistics,
    surface: &SurfaceCensus,
    header: &Header,
    file_bytes: u64,
) -> serde_json::Value {
    let b = &s.bytes;
    json!({
        "format_version": header.version.to_string(),
        "file_bytes": HEADER_LEN as u64 + header.payload_len,
        "bytes_on_disk": file_bytes,
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
        "surface": surface_json(&surface.whole),
        "bytes": {
            "octree": b.octree, "triangles": b.triangles, "boxes": b.boxes,
            "cube_map": b.cube_map, "point_location": b.point_location, "shading": b.shading,
            "distance": b.distance, "total": b.total(),
        },
        "distance": distance_json(v),
        "scene_data": {
            "materials": v.shading.materials.iter().map(material_json).collect::<Vec<_>>(),
            "parts": v.shading.parts.iter().zip(&surface.parts).map(|(p, edges)| {
                let mut part = json!({
                    "name": p.name, "first_triangle": p.first, "triangles": p.count,
                    "surface": surface_json(edges),
                });
                part.as_object_mut().expect("an object").extend(source_json(&p.source));
                part
            }).collect::<Vec<_>>(),
            "textures": v.shading.textures.iter().map(|t| json!({
                "name": t.name, "width": t.width, "height": t.height,
                "filter": t.filter.name(), "wrap": t.wrap.map(Wrap::name), "min_alpha": t.min_alpha,
                "srgb": t.srgb,
                "kept_as": t.encoded.map_or("texels", |e| match e.kind {
                    octrace_format::ImageKind::Png => "png",
                    octrace_format::ImageKind::Jpeg => "jpeg",
                }),
                "encoded_bytes": t.encoded.map(|e| e.bytes),
            })).collect::<Vec<_>>(),
            "lights": v.shading.lights.iter().map(|l| json!({
                "name": l.name, "kind": format!("{:?}", l.kind).to_lowercase(), "color": l.color,
                "intensity": l.intensity, "position": l.position, "direction": l.direction,
                "range": l.range.is_finite().then_some(l.range),
            })).collect::<Vec<_>>(),
            "cameras": v.shading.cameras.iter().enumerate().map(|(i, c)| json!({
                "index": c.number(i), "gltf_camera": c.gltf_camera, "placement": i, "name": c.name, "position": c.position, "forward": c.forward, "up": c.up,
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
            "depth_limited_by_precision": depth_limited_by_precision(v),
            "precision_depth": crate::octree::precision_depth(v.bounds.root_lo, v.bounds.root_size),
            "margin": v.params.margin,
            "time_s": (header.bake_time_us > 0).then(|| header.bake_time_us as f64 / 1e6),
        },
        "bounds": {
            "mesh_lo": v.bounds.mesh_lo, "mesh_hi": v.bounds.mesh_hi,
            "root_lo": v.bounds.root_lo, "root_size": v.bounds.root_size,
        },
        "sections": header.sections.iter().map(|s| json!({
            "name": s.name,
            "offset": HEADER_LEN as u64 + s.offset,
            "bytes": s.len,
            "xxh3": format!("{:016x}", s.xxh3),
        })).collect::<Vec<_>>(),
    })
}

/// The closest-point search's tree baked into the scene (`bake --distance`), or null.
fn distance_json(v: &SceneView<'_>) -> serde_json::Value {
    match octrace_format::distance::Tree::parse(v.distance) {
        Some(t) => json!({
            "nodes": t.nodes.len(), "clusters": t.clusters(), "triangles": t.prims.len(),
            "bytes": 4 * v.distance.len() as u64,
            "bytes_per_triangle": 4.0 * v.distance.len() as f64 / t.prims.len().max(1) as f64,
        }),
        None => serde_json::Value::Null,
    }
}

/// Whether the bake's depth is what `f32` precision allows at the scene's position and
/// less than the automatic choice for its triangles: the bake was limited there.
pub fn depth_limited_by_precision(v: &SceneView<'_>) -> bool {
    let allowed = crate::octree::precision_depth(v.bounds.root_lo, v.bounds.root_size);
    let kept = (v.stats.input_triangles - v.stats.degenerate_triangles) as usize;
    let automatic = crate::BuildParams { leaf_size: Some(v.params.leaf_size), ..Default::default() };
    v.params.max_depth == allowed && allowed < automatic.resolve(kept).max_depth
}

/// A part's source as fields: `node`, `mesh`, `primitive` (glTF) or `object` (OBJ).
pub fn source_json(source: &PartSource) -> serde_json::Map<String, serde_json::Value> {
    let fields = match *source {
        PartSource::Gltf { node, mesh, primitive } => vec![("node", node), ("mesh", mesh), ("primitive", primitive)],
        PartSource::Obj { object } => vec![("object", object)],
        PartSource::None => vec![],
    };
    fields.into_iter().map(|(k, v)| (k.to_string(), v.into())).collect()
}

/// A surface's topology for machines.
fn surface_json(e: &EdgeCensus) -> serde_json::Value {
    json!({
        "closed": e.is_closed(), "manifold": e.is_manifold(), "oriented": e.is_oriented(),
        "edges": e.edges, "boundary_edges": e.boundary, "non_manifold_edges": e.non_manifold,
        "flipped_edges": e.flipped,
    })
}

/// A material as `inspect --json` prints it (`scene_data.materials`).
pub fn material_json(m: &octrace_format::Material) -> serde_json::Value {
    json!({
        "name": m.name, "base_color": m.base_color, "metallic": m.metallic,
        "roughness": m.roughness, "emissive": m.emissive,
        "alpha_mode": format!("{:?}", m.alpha_mode).to_uppercase(), "alpha_cutoff": m.alpha_cutoff,
        "transmission": m.transmission, "ior": m.ior, "specular": m.specular, "illum": m.illum,
        "unlit": m.unlit, "base_color_texture": m.base_color_texture,
        "emissive_texture": m.emissive_texture,
        "metallic_roughness_texture": m.metallic_roughness_texture,
        "occlusion_texture": m.occlusion_texture, "occlusion_strength": m.occlusion_strength,
    })
}
