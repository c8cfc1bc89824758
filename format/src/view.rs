//! A borrowed, validated view of a baked scene's arrays: what the tracers read.

use crate::layout::{
    neighbour_count, LEAF_HEADER_WORDS, TANGENT_WORDS, TRIANGLE_FLOATS, UV_FLOATS, WORD_BOX, WORD_NCOUNT,
    WORD_TRI_COUNT, WORD_TRI_OFFSET,
};
use crate::scene::{BakeParams, BakeStats, Bounds};

/// Words a stored triangle's vertex colours take in [`SceneView::colors`].
pub const COLOR_WORDS: usize = 6;
/// `1 / 65535`: from a 16-bit vertex colour channel to `[0, 1]`.
pub const COLOR_SCALE: f32 = 1.0 / 65535.0;

/// The corners' values `x` mixed at barycentrics `(u, v)` (the first corner's weight
/// `1 - u - v` in `f32`): each product exact in `f64`, the sum rounded once to `f32`.
/// The GPU kernel's generated `uv_mix` does the same operations.
fn mix(x: [f32; 3], u: f32, v: f32) -> f32 {
    let w = 1.0 - u - v;
    (x[0] as f64 * w as f64 + x[1] as f64 * u as f64 + x[2] as f64 * v as f64) as f32
}

/// The arrays of a baked scene as plain slices, borrowed from a file or from a
/// [`crate::BakedScene`].
///
/// A view obtained from [`crate::SceneFile`] or [`crate::BakedScene::view`] has passed
/// [`SceneView::validate`] (or was declared trusted by the caller of an `_unchecked`
/// function), so the tracers index its arrays without further checks beyond Rust's own
/// bounds checks.
#[derive(Clone, Debug)]
pub struct SceneView<'a> {
    /// How it was baked.
    pub params: BakeParams,
    /// Mesh box and root cube.
    pub bounds: Bounds,
    /// Bake-time counts.
    pub stats: BakeStats,
    /// Leaf records, see [`crate::layout`].
    pub octree: &'a [u32],
    /// Triangle references of the leaves.
    pub tri_refs: &'a [u32],
    /// Triangle vertices, nine `f32` a triangle.
    pub triangles: &'a [f32],
    /// Input index of each stored triangle.
    pub triangle_ids: &'a [u32],
    /// Leaf boxes, six `f32` a leaf.
    pub boxes: &'a [f32],
    /// The cube map.
    pub cube_map: &'a [u32],
    /// Point-location nodes, eight references each.
    pub nodes: &'a [u32],
    /// Material index of each stored triangle, or empty.
    pub material_ids: &'a [u32],
    /// Shading normals, nine `f32` a stored triangle, or empty.
    pub normals: &'a [f32],
    /// Texture coordinates, six `f32` a stored triangle a channel, channel after
    /// channel ([`crate::Material::uv_channels`]), or empty.
    pub uvs: &'a [f32],
    /// Vertex colours, six words a stored triangle, or empty.
    pub colors: &'a [u32],
    /// Tangents, six words a stored triangle ([`crate::layout::decode_tangent`]), or empty.
    pub tangents: &'a [u32],
    /// Texels of the scene's textures (stored, and decoded from the encoded images
    /// when first read), or empty.
    pub texels: crate::Texels<'a>,
    /// The closest-point search's tree ([`crate::distance`]), or empty.
    pub distance: &'a [u32],
    /// Root reference of the point-location tree.
    pub root: u32,
    /// Materials, lights, cameras and effects.
    pub shading: &'a crate::Shading,
}

/// One leaf record, decoded.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LeafRecord<'a> {
    /// Word address of the record.
    pub address: u32,
    /// Index into the triangle-reference array of the first reference.
    pub tri_offset: u32,
    /// Number of triangle references.
    pub tri_count: u32,
    /// Box index (the leaf's ordinal).
    pub box_index: u32,
    /// Packed neighbour counts.
    pub ncount: u32,
    /// The links, face 0's first.
    pub links: &'a [u32],
}

impl LeafRecord<'_> {
    /// The links across `face`.
    pub fn face_links(&self, face: usize) -> &[u32] {
        let start = crate::layout::links_before(self.ncount, face) as usize;
        let n = neighbour_count(self.ncount, face) as usize;
        &self.links[start..start + n]
    }
}

impl<'a> SceneView<'a> {
    /// The arrays as 32-bit words, in the file's section order (octree, tri_refs,
    /// triangles, triangle_ids, boxes, cube_map, nodes, material_ids, normals, uvs,
    /// colors, tangents, texels, images, distance):
    /// the sections before `root` hold exactly these bytes.
    pub fn section_words(&self) -> [&'a [u32]; crate::SECTION_COUNT - 1] {
        [
            self.octree,
            self.tri_refs,
            bytemuck::cast_slice(self.triangles),
            self.triangle_ids,
            bytemuck::cast_slice(self.boxes),
            self.cube_map,
            self.nodes,
            self.material_ids,
            bytemuck::cast_slice(self.normals),
            bytemuck::cast_slice(self.uvs),
            self.colors,
            self.tangents,
            self.texels.stored(),
            bytemuck::cast_slice(self.texels.images()),
            self.distance,
        ]
    }

    /// The material of stored triangle `index`: its entry in the scene's materials,
    /// or `None` when the scene has no materials.
    pub fn material(&self, index: StoredIndex) -> Option<&'a crate::Material> {
        self.material_mapped(index, &[])
    }

    /// The material of stored triangle `index` drawn through `map` (an instance's
    /// material map, [`crate::instanced::InstancedFile::maps`]: entry `k`
    /// replaces material `k`; an empty map, or one without an entry, keeps it).
    ///
    /// # Example
    /// ```
    /// use octrace_format::{Material, StoredIndex};
    /// let mut scene = octrace_format::testing::single_leaf_scene();
    /// scene.shading.materials = vec![Material { name: "red".into(), ..Material::default() },
    ///                                Material { name: "blue".into(), ..Material::default() }];
    /// scene.material_ids = vec![0];
    /// let view = scene.view();
    /// assert_eq!(view.material_mapped(StoredIndex(0), &[]).unwrap().name, "red");
    /// assert_eq!(view.material_mapped(StoredIndex(0), &[1]).unwrap().name, "blue");
    /// ```
    #[inline]
    pub fn material_mapped(&self, index: StoredIndex, map: &[u32]) -> Option<&'a crate::Material> {
        let id = *self.material_ids.get(index.0 as usize)?;
        self.shading.materials.get(crate::instanced::drawn(map, id) as usize)
    }

    /// The shading normals of stored triangle `index`'s corners, when the scene has them.
    pub fn corner_normals(&self, index: StoredIndex) -> Option<[[f32; 3]; 3]> {
        Some(corners(self.normals.get(index.0 as usize * TRIANGLE_FLOATS..)?.get(..TRIANGLE_FLOATS)?))
    }

    /// The tangents of stored triangle `index`'s corners (`x y z w`, decoded), when the
    /// scene has them and they are not all zero there.
    pub fn corner_tangents(&self, index: StoredIndex) -> Option<[[f32; 4]; 3]> {
        let t = self.tangents.get(index.0 as usize * TANGENT_WORDS..)?.get(..TANGENT_WORDS)?;
        let corners = [[t[0], t[1]], [t[2], t[3]], [t[4], t[5]]].map(crate::layout::decode_tangent);
        corners.iter().any(|c| c[3] != 0.0).then_some(corners)
    }

    /// The texture coordinates of stored triangle `index`'s corners (the first
    /// channel), when the scene has them.
    pub fn corner_uvs(&self, index: StoredIndex) -> Option<[[f32; 2]; 3]> {
        self.corner_uvs_in(index, 0)
    }

    /// The texture-coordinate channels the scene has (0 without coordinates).
    pub fn uv_channel_count(&self) -> usize {
        self.uvs.len() / (self.triangles.len() / TRIANGLE_FLOATS * UV_FLOATS).max(1)
    }

    /// The texture coordinates of stored triangle `index`'s corners in `channel`, when
    /// the scene has them.
    pub fn corner_uvs_in(&self, index: StoredIndex, channel: usize) -> Option<[[f32; 2]; 3]> {
        let n = self.triangles.len() / TRIANGLE_FLOATS;
        let at = channel.checked_mul(n)?.checked_add(index.0 as usize)?.checked_mul(UV_FLOATS)?;
        let t = self.uvs.get(at..)?.get(..UV_FLOATS)?;
        Some([[t[0], t[1]], [t[2], t[3]], [t[4], t[5]]])
    }

    /// The texture coordinates at barycentrics `(u, v)` of stored triangle `index`
    /// (`(0, 0)` when the scene has none): each product exact in `f64`, the sum
    /// rounded once to `f32`, so that the GPU kernel, which computes it the same way
    /// where it has `f64`, finds the same texels.
    pub fn uv_at(&self, index: StoredIndex, u: f32, v: f32) -> [f32; 2] {
        self.uv_at_in(index, 0, u, v)
    }

    /// [`SceneView::uv_at`] in texture-coordinate channel `channel`.
    pub fn uv_at_in(&self, index: StoredIndex, channel: usize, u: f32, v: f32) -> [f32; 2] {
        let Some([t0, t1, t2]) = self.corner_uvs_in(index, channel) else { return [0.0; 2] };
        [0, 1].map(|c| mix([t0[c], t1[c], t2[c]], u, v))
    }

    /// The vertex colour at barycentrics `(u, v)` of stored triangle `index`, when the
    /// scene has vertex colours: the corners' values (16 bits a channel, scaled by
    /// [`COLOR_SCALE`]) mixed as [`SceneView::uv_at`] mixes coordinates.
    pub fn color_at(&self, index: StoredIndex, u: f32, v: f32) -> Option<[f32; 4]> {
        let at = (index.0 as usize).checked_mul(COLOR_WORDS)?;
        let w = self.colors.get(at..at.checked_add(COLOR_WORDS)?)?;
        let corner = |k: usize| {
            let (a, b) = (w[2 * k], w[2 * k + 1]);
            [a & 0xffff, a >> 16, b & 0xffff, b >> 16].map(|c| c as f32 * COLOR_SCALE)
        };
        let [c0, c1, c2] = [corner(0), corner(1), corner(2)];
        Some([0, 1, 2, 3].map(|c| mix([c0[c], c1[c], c2[c]], u, v)))
    }

    /// The base colour (and alpha) of `material` at barycentrics `(u, v)` of stored
    /// triangle `index`: its factor times its texture there times the vertex colour
    /// there, channel by channel, in that order; the factor alone when it has neither.
    pub fn base_color_at(&self, material: &crate::Material, index: StoredIndex, u: f32, v: f32) -> [f32; 4] {
        let mut color = material.base_color;
        if let Some(texel) = self.texture_at(material, 0, index, u, v) {
            color = [0, 1, 2, 3].map(|c| color[c] * texel[c]);
        }
        if let Some(vertex) = self.color_at(index, u, v) {
            color = [0, 1, 2, 3].map(|c| color[c] * vertex[c]);
        }
        color
    }

    /// The light `material` emits at barycentrics `(u, v)` of stored triangle `index`:
    /// its emissive factor, times its emissive texture's colour there when it has one
    /// (sampled at its channel's coordinates, [`SceneView::uv_at_in`]).
    pub fn emissive_at(&self, material: &crate::Material, index: StoredIndex, u: f32, v: f32) -> [f32; 3] {
        let e = material.emissive;
        match self.texture_at(material, 1, index, u, v) {
            Some(texel) => [e[0] * texel[0], e[1] * texel[1], e[2] * texel[2]],
            None => e,
        }
    }

    /// `material`'s metallic and roughness at barycentrics `(u, v)` of stored triangle
    /// `index`: its factors, times its metallic-roughness texture's blue and green
    /// channels there when it has one.
    pub fn metallic_roughness_at(&self, material: &crate::Material, index: StoredIndex, u: f32, v: f32) -> (f32, f32) {
        match self.texture_at(material, 2, index, u, v) {
            Some(texel) => (material.metallic * texel[2], material.roughness * texel[1]),
            None => (material.metallic, material.roughness),
        }
    }

    /// How much of the light from all around reaches `material` at barycentrics
    /// `(u, v)` of stored triangle `index`: `1 + strength * (red - 1)` of its occlusion
    /// texture there, 1 without one.
    pub fn occlusion_at(&self, material: &crate::Material, index: StoredIndex, u: f32, v: f32) -> f32 {
        match self.texture_at(material, 3, index, u, v) {
            Some(texel) => 1.0 + material.occlusion_strength * (texel[0] - 1.0),
            None => 1.0,
        }
    }

    /// The sample of `material`'s texture in slot `slot` ([`crate::Material::TEXTURE_SLOTS`]'s
    /// order) at barycentrics `(u, v)` of stored
    /// triangle `index`, in the slot's channel; `None` for no texture (or one past the
    /// scene's).
    fn texture_at(
        &self,
        material: &crate::Material,
        slot: usize,
        index: StoredIndex,
        u: f32,
        v: f32,
    ) -> Option<[f32; 4]> {
        let texture = self.shading.textures.get(material.slot_textures()[slot]? as usize)?;
        Some(texture.sample(self.texels.get(), self.uv_at_in(index, material.uv_channel(slot), u, v)))
    }

    /// Number of leaves.
    pub fn leaf_count(&self) -> usize {
        self.boxes.len() / crate::layout::BOX_FLOATS
    }

    /// Number of stored (non-degenerate) triangles.
    pub fn triangle_count(&self) -> usize {
        self.triangles.len() / TRIANGLE_FLOATS
    }

    /// Decodes the leaf record at `address`, or `None` if it does not fit in the array.
    pub fn leaf(&self, address: u32) -> Option<LeafRecord<'a>> {
        let a = address as usize;
        let head = self.octree.get(a..a.checked_add(LEAF_HEADER_WORDS)?)?;
        let ncount = head[WORD_NCOUNT];
        let n = crate::layout::total_links(ncount) as usize;
        let links = self.octree.get(a + LEAF_HEADER_WORDS..a + LEAF_HEADER_WORDS + n)?;
        Some(LeafRecord {
            address,
            tri_offset: head[WORD_TRI_OFFSET],
            tri_count: head[WORD_TRI_COUNT],
            box_index: head[WORD_BOX],
            ncount,
            links,
        })
    }

    /// Iterates over the leaf records in storage order.
    pub fn leaves(&self) -> impl Iterator<Item = LeafRecord<'a>> + '_ {
        let mut address = 0usize;
        std::iter::from_fn(move || {
            let rec = self.leaf(u32::try_from(address).ok()?)?;
            address += LEAF_HEADER_WORDS + rec.links.len();
            Some(rec)
        })
    }

    /// The box of leaf `box_index`: `[lo.x, lo.y, lo.z, hi.x, hi.y, hi.z]`.
    pub fn leaf_box(&self, box_index: u32) -> [f32; 6] {
        let b = box_index as usize * crate::layout::BOX_FLOATS;
        self.boxes[b..b + 6].try_into().expect("six floats")
    }

    /// The input mesh's index of stored triangle `index` (what a hit's `triangle`
    /// says), or `None` past the stored triangles.
    pub fn input_index(&self, index: StoredIndex) -> Option<u32> {
        self.triangle_ids.get(index.0 as usize).copied()
    }

    /// Every stored triangle's vertices, in stored order (the `n`-th is
    /// `triangle(StoredIndex(n))`).
    pub fn stored_triangles(&self) -> impl ExactSizeIterator<Item = [[f32; 3]; 3]> + '_ {
        self.triangles.chunks_exact(TRIANGLE_FLOATS).map(corners)
    }

    /// The edge census of the stored triangles, counted from them (not read from
    /// [`crate::BakeStats::edges`], which a damaged file could get wrong while its
    /// checksums hold); `degenerate` is the file's count (degenerate triangles are not
    /// stored).
    pub fn count_edges(&self) -> crate::topology::EdgeCensus {
        let triangles: Vec<[[f32; 3]; 3]> = self.stored_triangles().collect();
        crate::topology::EdgeCensus {
            degenerate: self.stats.edges.degenerate,
            ..crate::topology::EdgeCensus::of(&triangles)
        }
    }

    /// The edge census of the whole surface ([`SceneView::count_edges`]) and of each
    /// part (over the stored triangles whose input ids lie in it, in the order of
    /// [`crate::Shading::parts`]; `degenerate` the file's). The whole is counted once:
    /// a part that holds every stored triangle (an OBJ without objects) takes its
    /// census.
    pub fn count_surface(&self) -> crate::topology::SurfaceCensus {
        let whole = self.count_edges();
        let parts = &self.shading.parts;
        let mut of_part: Vec<Vec<[[f32; 3]; 3]>> = vec![Vec::new(); parts.len()];
        for (triangle, &id) in self.stored_triangles().zip(self.triangle_ids) {
            if let Some(i) = self.shading.part_index_of(id) {
                of_part[i as usize].push(triangle);
            }
        }
        let parts = of_part
            .iter()
            .zip(parts.iter())
            .map(|(t, p)| {
                let counted = if t.len() == self.triangle_count() { whole } else { crate::topology::EdgeCensus::of(t) };
                crate::topology::EdgeCensus { degenerate: p.edges.degenerate, ..counted }
            })
            .collect();
        crate::topology::SurfaceCensus { whole, parts }
    }

    /// The three vertices of stored triangle `index`.
    pub fn triangle(&self, index: StoredIndex) -> [[f32; 3]; 3] {
        corners(&self.triangles[index.0 as usize * TRIANGLE_FLOATS..][..TRIANGLE_FLOATS])
    }

    /// Cube-map resolution along a face edge.
    pub fn cube_resolution(&self) -> usize {
        1usize << self.params.cube_level
    }
}

/// Three points from the nine floats of a triangle's record (vertices or normals).
fn corners(t: &[f32]) -> [[f32; 3]; 3] {
    [[t[0], t[1], t[2]], [t[3], t[4], t[5]], [t[6], t[7], t[8]]]
}

/// A triangle's index in a scene's stored arrays: what [`SceneView::triangle`] and the
/// other calls on stored triangles take, and what a hit's `prim` is. Not the
/// triangle's index in the input mesh (a hit's `triangle`, what the mesh parts, an
/// app's own arrays and every answer of the tracer name): the bake stores triangles
/// in its own order, so the two differ for nearly every triangle, and this type keeps
/// the compiler from taking one for the other. [`SceneView::input_index`] maps a
/// stored index to the input's.
///
/// # Example
/// ```
/// use octrace_format::StoredIndex;
/// let first = StoredIndex(0);
/// assert_eq!(first.0, 0);
/// ```
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord, Hash)]
#[repr(transparent)]
pub struct StoredIndex(pub u32);
