//! A scene's repeated meshes kept once: the meshes the default scene places more than
//! once (by several nodes, by `EXT_mesh_gpu_instancing`, or as meshes that share one
//! geometry's accessors) are grouped by their geometry, each group loaded once in its
//! own space, and every placement becomes an instance with a transform and a
//! material map ([`super::super::InstancedMesh`]).
//!
//! Two meshes share a group where their primitives read the same accessors in the
//! same mode, their materials fall into the same pattern (primitives that share a
//! material in one share one in the other), and any textured material is the same
//! one (what a primitive stores, its texture coordinates' channels and its tangents,
//! follows its material's textures). Untextured materials may differ: a placement
//! draws its own through its instance's material map.

use std::collections::HashMap;

use glam::DMat4;

use super::super::{InstancedMesh, Loaded, Mesh, Placement};
use super::Loader;
use crate::error::Result;

/// The meshes kept once, and their placements as the scene is walked.
pub(in crate::mesh) struct Grouped {
    /// Each glTF mesh's group, for the meshes kept once.
    pub group_of_mesh: Vec<Option<u32>>,
    /// How many groups there are.
    pub groups: u32,
    /// Each placement of a grouped mesh, in the walk's order.
    pub placements: Vec<Placed>,
}

/// A placement of a grouped mesh met in the walk.
pub(in crate::mesh) struct Placed {
    pub group: u32,
    pub mesh: usize,
    pub node: usize,
    /// Local to world.
    pub world: DMat4,
}

impl Placed {
    fn determinant(&self) -> f64 {
        glam::DMat3::from_mat4(self.world).determinant()
    }
}

/// What a primitive's stored triangles follow: its attributes' accessors, its
/// indices' accessor and mode, its material where that is textured, and the first
/// primitive of its mesh with its material.
type PrimitiveKey = (Vec<(String, usize)>, Option<usize>, u32, Option<usize>, usize);

/// Whether material `index` reads a texture (any `"index"` in its JSON: the core
/// slots and every extension's).
fn textured(document: &gltf::Document, index: usize) -> bool {
    let json = document.as_json();
    json.materials.get(index).and_then(|m| serde_json::to_string(m).ok()).is_some_and(|text| text.contains("\"index\""))
}

fn mesh_key(document: &gltf::Document, mesh: &gltf::Mesh<'_>) -> Vec<PrimitiveKey> {
    let materials: Vec<Option<usize>> = mesh.primitives().map(|p| p.material().index()).collect();
    mesh.primitives()
        .enumerate()
        .map(|(i, p)| {
            let mut attributes: Vec<(String, usize)> =
                p.attributes().map(|(semantic, a)| (semantic.to_string(), a.index())).collect();
            attributes.sort();
            let material = materials[i];
            let texture = material.filter(|&m| textured(document, m));
            let first = materials.iter().position(|&m| m == material).unwrap_or(i);
            (attributes, p.indices().map(|a| a.index()), p.mode().as_gl_enum(), texture, first)
        })
        .collect()
}

/// The groups of meshes the scene places more than once (`placed`: each node's
/// placements) where their copies would add [`super::scene::REPEATED_MIN_TRIANGLES`]
/// or more; `Err(None)` where there are none, `Err(why)` where it places lights or
/// cameras but no mesh once (they would have no scene of their own to go with: such
/// a scene is baked whole).
pub(super) fn groups(document: &gltf::Document, placed: &[u64]) -> Result<Grouped, Option<&'static str>> {
    let mut times = vec![0u64; document.meshes().len()];
    for node in document.nodes() {
        if let Some(mesh) = node.mesh() {
            times[mesh.index()] = times[mesh.index()].saturating_add(placed[node.index()]);
        }
    }
    let mut by_key: HashMap<Vec<PrimitiveKey>, usize> = HashMap::new();
    let mut keyed: Vec<Option<usize>> = vec![None; times.len()];
    let mut total: Vec<u64> = Vec::new();
    let mut triangles: Vec<u64> = Vec::new();
    for mesh in document.meshes().filter(|m| times[m.index()] > 0) {
        let key = mesh_key(document, &mesh);
        let k = *by_key.entry(key).or_insert_with(|| {
            total.push(0);
            triangles.push(mesh.primitives().map(|p| super::scene::primitive_triangles(&p)).sum());
            total.len() - 1
        });
        total[k] = total[k].saturating_add(times[mesh.index()]);
        keyed[mesh.index()] = Some(k);
    }
    // The keys placed more than once, whose copies would add at least
    // REPEATED_MIN_TRIANGLES, become groups, numbered in order (a few repeated
    // triangles are cheaper baked whole than as a scene of their own).
    let mut number = vec![None; total.len()];
    let mut groups = 0;
    for (k, &t) in total.iter().enumerate() {
        if t > 1 && triangles[k].saturating_mul(t - 1) >= super::scene::REPEATED_MIN_TRIANGLES {
            number[k] = Some(groups);
            groups += 1;
        }
    }
    if groups == 0 {
        return Err(None);
    }
    let group_of_mesh: Vec<Option<u32>> = keyed.iter().map(|k| k.and_then(|k| number[k])).collect();
    let once = (0..times.len()).any(|m| times[m] > 0 && group_of_mesh[m].is_none());
    let lit = document.nodes().any(|n| placed[n.index()] > 0 && (n.light().is_some() || n.camera().is_some()));
    if lit && !once {
        return Err(Some(
            "its lights or cameras have no mesh placed once to go with, so it is baked as one scene (an \
             instance's lights would be placed with every copy)",
        ));
    }
    Ok(Grouped { group_of_mesh, groups, placements: Vec::new() })
}

impl Grouped {
    /// The materials the meshes placed once use (by glTF index).
    pub fn used_by_rest(&self, document: &gltf::Document) -> Vec<bool> {
        let mut used = vec![false; document.materials().len()];
        for mesh in document.meshes().filter(|m| self.group_of_mesh[m.index()].is_none()) {
            for i in mesh.primitives().filter_map(|p| p.material().index()) {
                used[i] = true;
            }
        }
        used
    }
}

/// Rows of `m`'s top three (local to world).
fn rows(m: &DMat4) -> [[f64; 4]; 3] {
    let c = m.to_cols_array_2d();
    std::array::from_fn(|i| std::array::from_fn(|j| c[j][i]))
}

impl<'a> Loader<'a> {
    /// A loader of the document's materials with nothing loaded yet (each mesh
    /// keeps its own textures).
    fn materials_loader(&self) -> super::material::Materials<'a> {
        super::material::Materials {
            path: self.path,
            base: self.base,
            options: self.options,
            buffers: self.buffers,
            loaded: Default::default(),
            kept: Default::default(),
        }
    }

    /// The materials of the document into the mesh, in glTF order, with their
    /// textures where `used` says so (all when `None`); the others a placeholder
    /// named as they are (no triangle of this mesh draws them).
    pub(super) fn load_materials(&mut self, used: Option<&[bool]>) -> Result<()> {
        let mut materials = self.materials_loader();
        for m in self.document.materials() {
            let index = m.index().unwrap_or(0);
            if used.is_none_or(|u| u.get(index).copied().unwrap_or(false)) {
                let (m, uv) = materials.material(&m, &mut self.mesh)?;
                self.mesh.materials.push(m);
                self.uv_maps.push(uv);
            } else {
                let name = m.name().map_or_else(|| format!("material {index}"), str::to_string);
                self.mesh.materials.push(octrace_format::Material { name, double_sided: true, ..Default::default() });
                self.uv_maps.push(Vec::new());
            }
        }
        Ok(())
    }

    /// Only the glTF materials `only` into the mesh, in that order, with their
    /// textures (a group's scene: what its placements draw).
    fn load_only(&mut self, only: &[usize]) -> Result<()> {
        let mut materials = self.materials_loader();
        let mut slots = HashMap::with_capacity(only.len());
        for &index in only {
            let Some(m) = self.document.materials().nth(index) else { continue };
            let (m, uv) = materials.material(&m, &mut self.mesh)?;
            slots.insert(index, self.mesh.materials.len() as u32);
            self.mesh.materials.push(m);
            self.uv_maps.push(uv);
        }
        self.slots = Some(slots);
        Ok(())
    }

    /// The loaded scene as instances: the meshes placed once (with the lights and
    /// cameras) as the first mesh, placed as they are, where there are any; each
    /// group's representative mesh loaded in its own space (and once more mirrored,
    /// where some placements mirror), placed once for each of its placements with the
    /// materials they draw, in the order the scene places them.
    pub(super) fn instanced(self, grouped: Grouped) -> Result<Loaded> {
        let Loader { path, options, base, document, buffers, input_bytes, mesh: mut rest, .. } = self;
        let mut out = InstancedMesh::default();
        let mut warnings = std::mem::take(&mut rest.warnings);
        out.sources = std::mem::take(&mut rest.sources);
        if !rest.triangles.is_empty() {
            out.meshes.push(rest);
            out.placements.push(Placement { mesh: 0, rows: rows(&DMat4::IDENTITY), map: None });
        } else if !rest.lights.is_empty() || !rest.cameras.is_empty() {
            // The meshes placed once made no triangle (points or lines alone).
            warnings.push(format!(
                "{}: {} lights and {} cameras left out: no triangle is placed once to go with them (bake with \
                 --flatten to keep them)",
                path.display(),
                rest.lights.len(),
                rest.cameras.len()
            ));
        }
        let mut walked: Vec<(usize, Placement)> = Vec::with_capacity(grouped.placements.len());
        // The distinct material maps, each stored once.
        let mut maps: HashMap<Vec<u32>, u32> = HashMap::new();
        let meshes: Vec<gltf::Mesh<'_>> = document.meshes().collect();
        // Each group's placements (by their place in the walk).
        let mut by_group: Vec<Vec<usize>> = vec![Vec::new(); grouped.groups as usize];
        for (walk, p) in grouped.placements.iter().enumerate() {
            by_group[p.group as usize].push(walk);
        }
        for walks in &by_group {
            let mut all: Vec<(usize, &Placed)> = Vec::with_capacity(walks.len());
            for &walk in walks {
                let p = &grouped.placements[walk];
                let det = p.determinant();
                if det == 0.0 || !det.is_finite() {
                    warnings.push(format!(
                        "{}: node {}: mesh {} placed by a singular transform (it flattens the mesh): left out",
                        path.display(),
                        p.node,
                        p.mesh
                    ));
                    continue;
                }
                all.push((walk, p));
            }
            // The mirroring placements place a mirrored copy (x negated, exactly; its
            // winding turned as the loader turns a mirroring node's) by their transform
            // times the mirror, which does not mirror: glTF's front stays the stored
            // winding's, as in a flat bake.
            for mirrored in [false, true] {
                let placements: Vec<(usize, &Placed)> =
                    all.iter().copied().filter(|(_, p)| (p.determinant() < 0.0) == mirrored).collect();
                let local =
                    if mirrored { DMat4::from_scale(glam::DVec3::new(-1.0, 1.0, 1.0)) } else { DMat4::IDENTITY };
                // The first placement's mesh is loaded (the group's meshes share its
                // geometry).
                let Some(&(_, first)) = placements.first() else { continue };
                let mut used: Vec<usize> = placements
                    .iter()
                    .filter_map(|(_, p)| meshes.get(p.mesh))
                    .flat_map(|m| m.primitives().filter_map(|q| q.material().index()))
                    .collect();
                used.sort_unstable();
                used.dedup();
                let mut sub = Loader {
                    path,
                    options,
                    base,
                    document,
                    buffers,
                    input_bytes,
                    mesh: Mesh::default(),
                    uv_maps: Vec::new(),
                    skipped: None,
                    default_material: None,
                    grouped: None,
                    slots: None,
                };
                sub.load_only(&used)?;
                let Some(mesh) = meshes.get(first.mesh) else { continue };
                for prim in mesh.primitives() {
                    let element = format!("mesh {} primitive {}", mesh.index(), prim.index());
                    sub.primitive(&prim, &local, element)?;
                    let quoted = |name: Option<&str>| name.map(|n| format!(" '{n}'")).unwrap_or_default();
                    let source = octrace_format::PartSource::Gltf {
                        node: first.node as u32,
                        mesh: mesh.index() as u32,
                        primitive: prim.index() as u32,
                    };
                    sub.mesh.end_part(source, || {
                        format!("mesh {}{}, primitive {}", mesh.index(), quoted(mesh.name()), prim.index())
                    });
                }
                warnings.append(&mut sub.mesh.warnings);
                if sub.mesh.triangles.is_empty() {
                    continue;
                }
                // Each placement's materials, primitive by primitive (glTF indices, or
                // the default material's).
                let own: Vec<u32> = mesh.primitives().map(|p| sub.material_of(&p)).collect();
                let drawn: Vec<Vec<u32>> = placements
                    .iter()
                    .map(|(_, p)| match meshes.get(p.mesh) {
                        Some(placed) => placed.primitives().map(|q| sub.material_of(&q)).collect(),
                        None => own.clone(),
                    })
                    .collect();
                // The scene keeps the materials its placements draw, the
                // representative's first (so a map is no longer than its distinct
                // materials), the others after.
                let mut new_index = vec![u32::MAX; sub.mesh.materials.len()];
                let mut order: Vec<u32> = Vec::new();
                for &m in own.iter().chain(drawn.iter().flatten()) {
                    if new_index[m as usize] == u32::MAX {
                        new_index[m as usize] = order.len() as u32;
                        order.push(m);
                    }
                }
                sub.mesh.materials = order.iter().map(|&m| sub.mesh.materials[m as usize].clone()).collect();
                for id in &mut sub.mesh.material_ids {
                    *id = new_index[*id as usize];
                }
                let index = out.meshes.len() as u32;
                for (&(walk, p), drawn) in placements.iter().zip(&drawn) {
                    let mut map: Vec<u32> = Vec::new();
                    for (&k, &j) in own.iter().zip(drawn) {
                        let (k, j) = (new_index[k as usize], new_index[j as usize]);
                        if j != k {
                            if map.len() <= k as usize {
                                map.extend(map.len() as u32..=k);
                            }
                            map[k as usize] = j;
                        }
                    }
                    let map = (!map.is_empty()).then(|| {
                        *maps.entry(map).or_insert_with_key(|m| {
                            out.maps.push(m.clone());
                            out.maps.len() as u32 - 1
                        })
                    });
                    walked.push((walk, Placement { mesh: index, rows: rows(&(p.world * local)), map }));
                }
                out.meshes.push(sub.mesh);
            }
        }
        // The instances in the order the scene places them.
        walked.sort_by_key(|(walk, _)| *walk);
        out.placements.extend(walked.into_iter().map(|(_, p)| p));
        out.warnings = warnings;
        Ok(Loaded::Instanced(out))
    }
}
