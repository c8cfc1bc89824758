//! The default scene's node placements: how many times each node is placed (counted
//! before the walk), then the walk itself, which places meshes, lights and cameras.

use glam::{DMat4, DVec3};

use octrace_format::{Camera, Light, LightKind};

use super::{to_f32, Loader};
use crate::error::{thousands, Error, Result};

/// Why a scene's placements were not counted.
pub(super) enum Placements {
    /// The hierarchy has a cycle through this node.
    Cycle(usize),
    /// The placements passed the budget at this node, having reached `total`.
    Over { node: usize, total: u64 },
}

/// How many times the scene places each node (a child listed twice, or under two
/// parents, is placed once for each listing, its children with it), counted over the
/// hierarchy's edges before it is walked: a small file whose nodes share children may
/// ask for 2^60 placements.
pub(super) fn placements(
    document: &gltf::Document,
    scene: &gltf::Scene<'_>,
    limit: u64,
) -> std::result::Result<Vec<u64>, Placements> {
    let n = document.nodes().len();
    let children: Vec<Vec<usize>> = document.nodes().map(|node| node.children().map(|c| c.index()).collect()).collect();
    // Depth first from the scene's roots: the nodes reached in post-order, a cycle
    // refused as it is met (a child already on the path).
    let (new, open, done) = (0u8, 1u8, 2u8);
    let mut state = vec![new; n];
    let mut order = Vec::with_capacity(n);
    for root in scene.nodes().map(|r| r.index()) {
        if state[root] != new {
            continue;
        }
        state[root] = open;
        let mut path = vec![(root, 0usize)];
        while let Some(&(node, next)) = path.last() {
            match children[node].get(next) {
                Some(&child) => {
                    if let Some(top) = path.last_mut() {
                        top.1 += 1;
                    }
                    if state[child] == open {
                        return Err(Placements::Cycle(child));
                    }
                    if state[child] == new {
                        state[child] = open;
                        path.push((child, 0));
                    }
                }
                None => {
                    state[node] = done;
                    order.push(node);
                    path.pop();
                }
            }
        }
    }
    // Parents before children (the reverse post-order): each node's count is whole
    // when it is reached.
    let mut count = vec![0u64; n];
    for root in scene.nodes() {
        count[root.index()] += 1;
    }
    let mut total = 0u64;
    for &node in order.iter().rev() {
        let c = count[node];
        total = total.saturating_add(c);
        if total > limit {
            return Err(Placements::Over { node, total });
        }
        for &child in &children[node] {
            count[child] = count[child].saturating_add(c);
        }
    }
    Ok(count)
}

/// The instances `EXT_mesh_gpu_instancing` asks of a node that has a mesh: its
/// attributes' accessor count (1 without the extension; the attributes are checked
/// when the node is placed).
pub(super) fn gpu_instances(document: &gltf::Document, node: &gltf::Node<'_>) -> u64 {
    let Some(attributes) =
        node.extension_value(GPU_INSTANCING).and_then(|e| e.get("attributes")).and_then(serde_json::Value::as_object)
    else {
        return 1;
    };
    let counts = attributes.values().filter_map(|v| v.as_u64()).filter_map(|i| document.accessors().nth(i as usize));
    counts.map(|a| a.count() as u64).max().unwrap_or(1)
}

/// glTF's extension placing a mesh many times from one node.
pub(super) const GPU_INSTANCING: &str = "EXT_mesh_gpu_instancing";

/// The triangles a primitive makes, from its accessors' counts (a list's indices or
/// positions over 3; a strip's or fan's less 2; other modes none).
pub(super) fn primitive_triangles(p: &gltf::Primitive<'_>) -> u64 {
    use gltf::mesh::Mode;
    let vertices = p.indices().or_else(|| p.get(&gltf::Semantic::Positions)).map_or(0, |a| a.count() as u64);
    match p.mode() {
        Mode::Triangles => vertices / 3,
        Mode::TriangleStrip | Mode::TriangleFan => vertices.saturating_sub(2),
        _ => 0,
    }
}

/// The triangles the placed meshes make.
pub(super) fn instanced_triangles(document: &gltf::Document, placed: &[u64]) -> u64 {
    let per_mesh: Vec<u64> = document
        .meshes()
        .map(|m| m.primitives().map(|p| primitive_triangles(&p)).fold(0u64, u64::saturating_add))
        .collect();
    document
        .nodes()
        .filter_map(|node| Some(placed[node.index()].saturating_mul(per_mesh[node.mesh()?.index()])))
        .fold(0, u64::saturating_add)
}

/// Geometry stored at least this many times over (placements of a mesh, meshes that
/// share accessors) is named in a warning at bake, when the copies add at least
/// [`REPEATED_MIN_TRIANGLES`].
pub(super) const REPEATED_FACTOR: u64 = 2;
/// Triangles the copies must add for the warning (about 0.4 MB of baked file): a few
/// repeated triangles cost nothing worth a word.
pub(super) const REPEATED_MIN_TRIANGLES: u64 = 4096;

/// A warning when the scene's placements store its distinct geometry
/// [`REPEATED_FACTOR`] times over or more (and [`REPEATED_MIN_TRIANGLES`] more): each placement of a mesh (and each mesh
/// that shares another's accessors) is baked whole, one triangle each time (`why`
/// says why, or how not to). Names the geometry repeated most, by the triangles its
/// copies add.
pub(super) fn repeated_geometry(document: &gltf::Document, placed: &[u64], why: &str) -> Option<String> {
    use std::collections::BTreeMap;
    let mut geometry: BTreeMap<GeometryKey, Geometry> = BTreeMap::new();
    for node in document.nodes() {
        let (Some(mesh), times) = (node.mesh(), placed[node.index()]) else { continue };
        for p in mesh.primitives() {
            let key = (
                p.get(&gltf::Semantic::Positions).map(|a| a.index()),
                p.indices().map(|a| a.index()),
                p.mode().as_gl_enum(),
            );
            let g = geometry.entry(key).or_insert(Geometry {
                triangles: primitive_triangles(&p),
                placed: 0,
                first_mesh: mesh.index(),
                meshes: Vec::new(),
            });
            g.placed = g.placed.saturating_add(times);
            if times > 0 && !g.meshes.contains(&mesh.index()) {
                g.meshes.push(mesh.index());
            }
        }
    }
    let distinct: u64 = geometry.values().filter(|g| g.placed > 0).map(|g| g.triangles).sum();
    let stored = geometry.values().map(|g| g.triangles.saturating_mul(g.placed)).fold(0u64, u64::saturating_add);
    if distinct == 0 || stored < distinct.saturating_mul(REPEATED_FACTOR) || stored - distinct < REPEATED_MIN_TRIANGLES
    {
        return None;
    }
    let mut worst: Vec<&Geometry> = geometry.values().filter(|g| g.placed > 1).collect();
    worst.sort_by_key(|g| std::cmp::Reverse(g.triangles.saturating_mul(g.placed - 1)));
    let named: Vec<String> = worst
        .iter()
        .take(3)
        .map(|g| {
            let mesh = document.meshes().nth(g.first_mesh);
            let name = mesh.and_then(|m| m.name()).map(|n| format!(" '{n}'")).unwrap_or_default();
            let shared = match g.meshes.len() {
                0 | 1 => String::new(),
                n => format!(" (and {} other meshes with the same accessors)", n - 1),
            };
            format!(
                "mesh {}{name}{shared}: {} triangles placed {} times",
                g.first_mesh,
                thousands(g.triangles),
                thousands(g.placed)
            )
        })
        .collect();
    Some(format!(
        "the scene stores its {} triangles of distinct geometry as {} ({:.1}x): each placement is baked \
         whole{why}; repeated most: {}",
        thousands(distinct),
        thousands(stored),
        stored as f64 / distinct as f64,
        named.join("; ")
    ))
}

/// A primitive's geometry: its positions' and indices' accessors and its mode.
type GeometryKey = (Option<usize>, Option<usize>, u32);

/// One geometry of the scene, and where it is placed.
struct Geometry {
    /// Its triangles.
    triangles: u64,
    /// The times the scene places it (each node of each mesh that has it).
    placed: u64,
    /// The first mesh that has it.
    first_mesh: usize,
    /// The meshes that have it and are placed.
    meshes: Vec<usize>,
}

/// Node hierarchies deeper than this are refused (a cycle, or a hostile file).
const MAX_NODE_DEPTH: usize = 256;

impl Loader<'_> {
    pub(super) fn node(&mut self, node: &gltf::Node<'_>, parent: DMat4, depth: usize) -> Result<()> {
        if depth > MAX_NODE_DEPTH {
            return Err(Error::Parse {
                path: self.path.into(),
                element: format!("node {}", node.index()),
                message: format!("node hierarchy deeper than {MAX_NODE_DEPTH}"),
            });
        }
        let local = node.transform().matrix().map(|c| c.map(f64::from));
        let world = parent * DMat4::from_cols_array_2d(&local);
        // EXT_mesh_gpu_instancing: the mesh placed once an instance, each instance's
        // TRS in the node's space.
        let placements = match node.extension_value(GPU_INSTANCING) {
            Some(e) if node.mesh().is_some() => self.gpu_instances(node.index(), e)?,
            _ => vec![DMat4::IDENTITY],
        };
        if let Some(light) = node.light() {
            self.light(&light, &world, node.index())?;
        }
        if let Some(camera) = node.camera() {
            self.camera(&camera, &world, node.index());
        }
        // A mesh kept once (an instanced load) is placed, not loaded, here.
        let kept = node.mesh().and_then(|m| Some((m.index(), self.grouped.as_ref()?.group_of_mesh[m.index()]?)));
        if let (Some((mesh, group)), Some(grouped)) = (kept, self.grouped.as_mut()) {
            let node = node.index();
            grouped.placements.extend(placements.iter().map(|p| super::instances::Placed {
                group,
                mesh,
                node,
                world: world * *p,
            }));
        } else if let Some(mesh) = node.mesh() {
            for (instance, prim) in placements.iter().flat_map(|p| mesh.primitives().map(move |prim| (p, prim))) {
                let element = format!("node {} mesh {} primitive {}", node.index(), mesh.index(), prim.index());
                self.primitive(&prim, &(world * *instance), element)?;
                let quoted = |name: Option<&str>| name.map(|n| format!(" '{n}'")).unwrap_or_default();
                let source = octrace_format::PartSource::Gltf {
                    node: node.index() as u32,
                    mesh: mesh.index() as u32,
                    primitive: prim.index() as u32,
                };
                self.mesh.end_part(source, || {
                    format!(
                        "node {}{}, mesh {}{}, primitive {}",
                        node.index(),
                        quoted(node.name()),
                        mesh.index(),
                        quoted(mesh.name()),
                        prim.index()
                    )
                });
            }
        }
        for child in node.children() {
            self.node(&child, world, depth + 1)?;
        }
        Ok(())
    }

    /// The instances' transforms of `EXT_mesh_gpu_instancing` on node `node`: its
    /// `TRANSLATION`, `ROTATION` (a unit quaternion, `x y z w`) and `SCALE` attributes,
    /// float accessors of one count, each instance `T * R * S`.
    fn gpu_instances(&self, node: usize, extension: &serde_json::Value) -> Result<Vec<DMat4>> {
        use glam::{DQuat, DVec3};
        let fail = |message: String| Error::Parse {
            path: self.path.into(),
            element: format!("node {node} {GPU_INSTANCING}"),
            message,
        };
        let attributes = extension
            .get("attributes")
            .and_then(serde_json::Value::as_object)
            .ok_or_else(|| fail("has no \"attributes\" object".into()))?;
        let mut count = None;
        let mut read = |name: &str, width: usize| -> Result<Option<Vec<[f64; 4]>>> {
            let Some(index) = attributes.get(name) else { return Ok(None) };
            let accessor = index
                .as_u64()
                .and_then(|i| self.document.accessors().nth(i as usize))
                .ok_or_else(|| fail(format!("{name}: {index} names no accessor")))?;
            let dimensions =
                if width == 3 { gltf::accessor::Dimensions::Vec3 } else { gltf::accessor::Dimensions::Vec4 };
            if accessor.data_type() != gltf::accessor::DataType::F32 || accessor.dimensions() != dimensions {
                return Err(fail(format!(
                    "{name}: accessor {} is {:?} {:?}, expected float VEC{width} (quantized instances are not read)",
                    accessor.index(),
                    accessor.data_type(),
                    accessor.dimensions()
                )));
            }
            self.check_accessor(&accessor).map_err(|e| fail(format!("{name}: accessor {}: {e}", accessor.index())))?;
            if *count.get_or_insert(accessor.count()) != accessor.count() {
                return Err(fail(format!("{name}: {} instances, another attribute has {count:?}", accessor.count())));
            }
            let get = |b: gltf::Buffer<'_>| self.buffers.get(b.index()).map(|d| &d[..]);
            let values: Vec<[f64; 4]> = if width == 3 {
                let it = gltf::accessor::Iter::<[f32; 3]>::new(accessor.clone(), get)
                    .ok_or_else(|| fail(format!("{name}: accessor {} cannot be read", accessor.index())))?;
                it.map(|v| [f64::from(v[0]), f64::from(v[1]), f64::from(v[2]), 0.0]).collect()
            } else {
                let it = gltf::accessor::Iter::<[f32; 4]>::new(accessor.clone(), get)
                    .ok_or_else(|| fail(format!("{name}: accessor {} cannot be read", accessor.index())))?;
                it.map(|v| v.map(f64::from)).collect()
            };
            Ok(Some(values))
        };
        let translation = read("TRANSLATION", 3)?;
        let rotation = read("ROTATION", 4)?;
        let scale = read("SCALE", 3)?;
        let n = count.ok_or_else(|| fail("names none of TRANSLATION, ROTATION, SCALE".into()))?;
        let mut out = Vec::with_capacity(n);
        for i in 0..n {
            let t = translation.as_ref().map_or(DVec3::ZERO, |v| DVec3::new(v[i][0], v[i][1], v[i][2]));
            let r = rotation.as_ref().map_or(DQuat::IDENTITY, |v| DQuat::from_xyzw(v[i][0], v[i][1], v[i][2], v[i][3]));
            let s = scale.as_ref().map_or(DVec3::ONE, |v| DVec3::new(v[i][0], v[i][1], v[i][2]));
            if !(t.is_finite() && r.is_finite() && s.is_finite()) || (r.length() - 1.0).abs() > 1e-3 {
                return Err(fail(format!("instance {i}: not finite, or its rotation is not a unit quaternion")));
            }
            out.push(DMat4::from_scale_rotation_translation(s, r.normalize(), t));
        }
        Ok(out)
    }

    /// A `KHR_lights_punctual` light placed by `world`: at its origin, shining along
    /// its `-z` axis.
    fn light(&mut self, light: &gltf::khr_lights_punctual::Light<'_>, world: &DMat4, node: usize) -> Result<()> {
        use gltf::khr_lights_punctual::Kind;
        let name = light.name().map_or_else(|| format!("light {}", light.index()), str::to_string);
        let (kind, inner, outer) = match light.kind() {
            Kind::Point => (LightKind::Point, 0.0, 0.0),
            Kind::Directional => (LightKind::Directional, 0.0, 0.0),
            Kind::Spot { inner_cone_angle, outer_cone_angle } => {
                let outer = outer_cone_angle.clamp(0.0, std::f32::consts::FRAC_PI_2);
                (LightKind::Spot, inner_cone_angle.clamp(0.0, outer), outer)
            }
        };
        let out = Light {
            kind,
            color: light.color().map(|c| c.clamp(0.0, 1.0)),
            intensity: light.intensity().max(0.0),
            position: to_f32(world.transform_point3(DVec3::ZERO)),
            direction: to_f32(world.transform_vector3(DVec3::NEG_Z).normalize_or_zero()),
            range: light.range().filter(|r| *r > 0.0).unwrap_or(f32::INFINITY),
            inner_cone: inner,
            outer_cone: outer,
            name,
        };
        let numbers = out.color.iter().chain(&out.position).chain(&out.direction).chain([&out.intensity]);
        if numbers.into_iter().any(|v| !v.is_finite()) || out.range.is_nan() || out.direction == [0.0; 3] {
            return Err(Error::Parse {
                path: self.path.into(),
                element: format!("node {node}, light '{}'", out.name),
                message: "a value is not finite, or the node's transform collapses the light's direction".into(),
            });
        }
        self.mesh.lights.push(out);
        Ok(())
    }

    /// A camera placed by `world` (glTF cameras look along `-z`, up `+y`), perspective
    /// or orthographic (its `ymag` the half height of view, `xmag / ymag` the aspect);
    /// a degenerate transform or view is skipped with a warning.
    fn camera(&mut self, camera: &gltf::Camera<'_>, world: &DMat4, node: usize) {
        let name = camera.name().map_or_else(|| format!("camera {}", camera.index()), str::to_string);
        let (yfov, aspect, orthographic) = match camera.projection() {
            gltf::camera::Projection::Perspective(p) => (p.yfov(), p.aspect_ratio(), None),
            // yfov is unused by an orthographic camera; it holds a valid angle.
            gltf::camera::Projection::Orthographic(o) => {
                (std::f32::consts::FRAC_PI_4, Some(o.xmag().abs() / o.ymag().abs()), Some(o.ymag().abs()))
            }
        };
        let forward = world.transform_vector3(DVec3::NEG_Z).normalize_or_zero();
        let up = world.transform_vector3(DVec3::Y);
        let up = (up - forward * up.dot(forward)).normalize_or_zero();
        let out = Camera {
            position: to_f32(world.transform_point3(DVec3::ZERO)),
            forward: to_f32(forward),
            up: to_f32(up),
            yfov,
            aspect,
            orthographic,
            gltf_camera: Some(camera.index() as u32),
            name,
        };
        let finite = out.position.iter().chain([&out.yfov]).chain(out.aspect.as_ref()).all(|v| v.is_finite());
        let fov_ok = out.yfov > 0.0 && out.yfov < std::f32::consts::PI && out.aspect.is_none_or(|a| a > 0.0);
        let ortho_ok = out.orthographic.is_none_or(|h| h.is_finite() && h > 0.0);
        if !finite || !fov_ok || !ortho_ok || forward == DVec3::ZERO || up == DVec3::ZERO {
            self.mesh.warnings.push(format!(
                "{}: node {node}: camera '{}' skipped (degenerate transform or field of view)",
                self.path.display(),
                out.name
            ));
            return;
        }
        self.mesh.cameras.push(out);
    }
}
