//! The scene a bake produces: what goes into the rkyv archive.

use rkyv::{Archive, Deserialize, Serialize};

/// The parameters a scene was baked with.
#[derive(Archive, Serialize, Deserialize, Clone, Copy, Debug, PartialEq)]
#[rkyv(derive(Debug))]
pub struct BakeParams {
    /// Deepest level a cell may be split to (the root is level 0).
    pub max_depth: u32,
    /// A cell is split while it holds more triangles than this.
    pub leaf_size: u32,
    /// Cells are enlarged by this fraction of the root's edge when triangles are
    /// assigned to them, so that a ray misrouted by rounding still meets its triangle.
    pub margin: f32,
    /// The cube map has `2^cube_level` texels along each face edge.
    pub cube_level: u32,
}

/// Scene bounds: the mesh's box and the root cube around it.
#[derive(Archive, Serialize, Deserialize, Clone, Copy, Debug, PartialEq)]
#[rkyv(derive(Debug))]
pub struct Bounds {
    /// Low corner of the box of all vertices of non-degenerate triangles.
    pub mesh_lo: [f32; 3],
    /// High corner of that box.
    pub mesh_hi: [f32; 3],
    /// Low corner of the root cube.
    pub root_lo: [f32; 3],
    /// Edge length of the root cube (a power of two).
    pub root_size: f32,
}

/// Statistics recorded at bake time that cannot be recomputed from the arrays.
#[derive(Archive, Serialize, Deserialize, Clone, Debug, PartialEq, Default)]
#[rkyv(derive(Debug))]
pub struct BakeStats {
    /// Triangles in the input, degenerate ones included.
    pub input_triangles: u64,
    /// Zero-area triangles kept out of the octree.
    pub degenerate_triangles: u64,
    /// Leaves before the 2:1 balance (the paper's "non contraint", Table 1).
    pub leaves_before_balance: u64,
    /// Whether the stored triangles make a closed, consistently oriented surface.
    pub edges: crate::topology::EdgeCensus,
}

/// A baked scene in memory: the contents of a `.oct` file's archive.
///
/// The octree array holds the leaf records described in [`crate::layout`]; the
/// triangle-reference array lists, leaf after leaf, indices into the triangle array;
/// `triangle_ids` maps a triangle's index in the triangle array to its index in the
/// input mesh; `nodes` is the point-location tree (eight [`crate::NodeRef`] words a
/// node) and `root` its root; `cube_map` holds one [`crate::NodeRef`] word a texel.
/// The per-triangle shading arrays (`material_ids`, `normals`, `uvs`) follow the
/// triangle array's order and are empty when the input has none.
#[derive(Archive, Serialize, Deserialize, Clone, Debug, PartialEq)]
#[rkyv(derive(Debug))]
pub struct BakedScene {
    /// How it was baked.
    pub params: BakeParams,
    /// Mesh box and root cube.
    pub bounds: Bounds,
    /// What the bake counted.
    pub stats: BakeStats,
    /// Leaf records, paper layout.
    pub octree: Vec<u32>,
    /// Triangle references of the leaves, `tOffset .. tOffset + tCount` per leaf.
    pub tri_refs: Vec<u32>,
    /// Triangle vertices, nine `f32` a triangle.
    pub triangles: Vec<f32>,
    /// Input index of each triangle of the triangle array.
    pub triangle_ids: Vec<u32>,
    /// Leaf boxes, six `f32` a leaf, indexed by the record's box index.
    pub boxes: Vec<f32>,
    /// The cube map, `6 * 4^cube_level` node references.
    pub cube_map: Vec<u32>,
    /// Internal nodes of the point-location tree, eight references each.
    pub nodes: Vec<u32>,
    /// Material index of each stored triangle (into `shading.materials`), or empty
    /// when the mesh has no materials.
    pub material_ids: Vec<u32>,
    /// Shading normals of each stored triangle's three corners (nine `f32`), or empty.
    pub normals: Vec<f32>,
    /// Texture coordinates of each stored triangle's three corners (six `f32`), or empty.
    pub uvs: Vec<f32>,
    /// Vertex colours (glTF `COLOR_0`) of each stored triangle's three corners, linear
    /// RGBA at 16 bits a channel, two words a corner (`r | g << 16`, `b | a << 16`),
    /// or empty.
    pub colors: Vec<u32>,
    /// Tangents of each stored triangle's three corners, world space (two words a
    /// corner, [`crate::layout::encode_tangent`]: a unit `x y z` along which the normal
    /// texture's `u` grows, and `w`, the sign of the bitangent `w (n x t)`; all zero on
    /// the triangles of a part that has none), or empty. From the file's `TANGENT`,
    /// else MikkTSpace, for the parts whose material has a normal texture.
    pub tangents: Vec<u32>,
    /// The texels of every texture whose texels are stored ([`crate::Texture`],
    /// [`crate::TEXEL_WORDS`] words a texel), or empty.
    pub texels: Vec<u32>,
    /// The encoded images of the textures kept encoded ([`crate::Encoded`]), their
    /// bytes four to a word (little-endian, the last word padded with zeros), or empty.
    pub images: Vec<u32>,
    /// The closest-point search's tree ([`crate::distance`]: `bake --distance`), or
    /// empty (the runtime then makes it on the first closest-point query).
    pub distance: Vec<u32>,
    /// The point-location tree's root reference.
    pub root: u32,
    /// Materials, lights, cameras and the effects the scene calls for.
    pub shading: crate::Shading,
    /// The encoded images' texels once decoded (not part of the file).
    #[rkyv(with = rkyv::with::Skip)]
    pub decoded: crate::TexelCache,
}

impl BakedScene {
    /// The number of leaves (one box per leaf).
    pub fn leaf_count(&self) -> usize {
        self.boxes.len() / crate::layout::BOX_FLOATS
    }

    /// A borrowed view of the arrays, the same type the tracers read from a file.
    #[inline]
    pub fn view(&self) -> crate::SceneView<'_> {
        crate::SceneView {
            params: self.params,
            bounds: self.bounds,
            stats: self.stats.clone(),
            octree: &self.octree,
            tri_refs: &self.tri_refs,
            triangles: &self.triangles,
            triangle_ids: &self.triangle_ids,
            boxes: &self.boxes,
            cube_map: &self.cube_map,
            nodes: &self.nodes,
            material_ids: &self.material_ids,
            normals: &self.normals,
            uvs: &self.uvs,
            colors: &self.colors,
            tangents: &self.tangents,
            texels: crate::Texels::new(
                &self.texels,
                bytemuck::cast_slice(&self.images),
                &self.shading.textures,
                &self.decoded,
            ),
            distance: &self.distance,
            root: self.root,
            shading: &self.shading,
        }
    }
}
