//! Statistics of a baked scene, as `octrace inspect` prints them (the paper's Tables 1
//! and 3 among them).

use crate::layout::{total_links, LEAF_HEADER_WORDS};
use crate::view::SceneView;
use crate::Result;

/// Bytes taken by each array of the archive.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ArrayBytes {
    /// Leaf records (the paper's "octree").
    pub octree: u64,
    /// Triangle references and vertices, and the triangle-id map (the paper's "triangles").
    pub triangles: u64,
    /// Leaf boxes.
    pub boxes: u64,
    /// The cube map.
    pub cube_map: u64,
    /// The point-location tree.
    pub point_location: u64,
    /// The shading arrays: material ids, normals, texture coordinates, vertex colours, texels.
    pub shading: u64,
    /// The closest-point search's tree ([`crate::distance`]; 0 where the scene has none).
    pub distance: u64,
}

impl ArrayBytes {
    /// Sum of the arrays.
    pub fn total(&self) -> u64 {
        self.octree + self.triangles + self.boxes + self.cube_map + self.point_location + self.shading + self.distance
    }
}

/// A leaf at the depth limit is overfull past this many times the leaf size
/// ([`SceneStatistics::overfull_leaves`]).
pub const OVERFULL_FACTOR: u64 = 8;

/// Statistics of a scene, computed from its arrays.
#[derive(Clone, Debug, PartialEq)]
pub struct SceneStatistics {
    /// Stored (non-degenerate) triangles.
    pub triangles: u64,
    /// Leaves.
    pub leaves: u64,
    /// Leaves holding no triangle.
    pub empty_leaves: u64,
    /// Leaves per level, index = level.
    pub depth_histogram: Vec<u64>,
    /// Triangle references in all leaves.
    pub triangle_references: u64,
    /// Mean triangles per non-empty leaf.
    pub triangles_per_leaf_mean: f64,
    /// Most triangles in one leaf.
    pub triangles_per_leaf_max: u64,
    /// Leaves at the depth limit holding more than [`OVERFULL_FACTOR`] times the leaf
    /// size: where triangles share cells at every depth (fans around one vertex,
    /// coincident copies) and a ray through the leaf tests them all.
    pub overfull_leaves: u64,
    /// Triangle references in those leaves.
    pub overfull_references: u64,
    /// Mean neighbour links per leaf (the paper observed 7).
    pub neighbours_per_leaf_mean: f64,
    /// Internal nodes of the point-location tree.
    pub internal_nodes: u64,
    /// Bytes of each array.
    pub bytes: ArrayBytes,
}

impl SceneStatistics {
    /// Computes the statistics of a validated view.
    ///
    /// # Errors
    /// [`crate::Error::Corrupt`] if the point-location tree cannot be walked (only on
    /// views that were not validated).
    pub fn compute(view: &SceneView<'_>) -> Result<Self> {
        let index = view.index_tree()?;
        let mut depth_histogram = vec![0u64; view.params.max_depth as usize + 1];
        for key in &index.leaf_keys {
            depth_histogram[key.level as usize] += 1;
        }
        let (mut refs, mut max, mut empty, mut links) = (0u64, 0u64, 0u64, 0u64);
        let (mut overfull, mut overfull_refs) = (0u64, 0u64);
        let crowded = OVERFULL_FACTOR * view.params.leaf_size.max(1) as u64;
        for (&address, key) in index.leaf_addresses.iter().zip(&index.leaf_keys) {
            let a = address as usize;
            let count = view.octree[a] as u64;
            if key.level >= view.params.max_depth && count > crowded {
                overfull += 1;
                overfull_refs += count;
            }
            refs += count;
            max = max.max(count);
            empty += (count == 0) as u64;
            links += total_links(view.octree[a + LEAF_HEADER_WORDS - 1]) as u64;
        }
        let leaves = view.leaf_count() as u64;
        let four = |n: usize| 4 * n as u64;
        Ok(SceneStatistics {
            triangles: view.triangle_count() as u64,
            leaves,
            empty_leaves: empty,
            depth_histogram,
            triangle_references: refs,
            triangles_per_leaf_mean: refs as f64 / (leaves - empty).max(1) as f64,
            triangles_per_leaf_max: max,
            overfull_leaves: overfull,
            overfull_references: overfull_refs,
            neighbours_per_leaf_mean: links as f64 / leaves.max(1) as f64,
            internal_nodes: (view.nodes.len() / 8) as u64,
            bytes: ArrayBytes {
                octree: four(view.octree.len()),
                triangles: four(view.tri_refs.len() + view.triangles.len() + view.triangle_ids.len()),
                boxes: four(view.boxes.len()),
                cube_map: four(view.cube_map.len()),
                point_location: four(view.nodes.len()),
                shading: four(
                    view.material_ids.len()
                        + view.normals.len()
                        + view.uvs.len()
                        + view.colors.len()
                        + view.tangents.len()
                        + view.texels.stored().len()
                        + view.texels.images().len() / 4,
                ),
                distance: four(view.distance.len()),
            },
        })
    }
}
