//! Semantic validation: every address, offset and count in range, the point-location
//! tree a real octree, every link on the leaf across the stated face, the cube map exact.
//!
//! rkyv's bytecheck has already proved the archive well-formed; this proves it means
//! something a tracer can walk without reading out of bounds or looping.

use crate::error::{Error, Result};
use crate::layout::{
    cell_box, face_axis, face_is_high, other_axes, texel_index, NodeRef, BOX_FLOATS, LEAF_HEADER_WORDS, MAX_LEVEL,
    MAX_UV_CHANNELS, TANGENT_WORDS, TRIANGLE_FLOATS, UV_FLOATS,
};
use crate::view::SceneView;

/// An octree cell: its level and integer coordinates at that level.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct CellKey {
    /// Depth of the cell (the root is 0).
    pub level: u32,
    /// Coordinates in `0 .. 2^level` along x, y, z.
    pub cell: [u32; 3],
}

impl CellKey {
    /// Whether `self` contains `other` (or is it).
    pub fn contains(&self, other: &CellKey) -> bool {
        other.level >= self.level && (0..3).all(|a| other.cell[a] >> (other.level - self.level) == self.cell[a])
    }
}

/// What a walk of the point-location tree learns: the key of each leaf (by box index),
/// the address of each leaf record, and the key of each internal node.
#[derive(Debug, Default)]
pub struct TreeIndex {
    /// Key of each leaf, indexed by box index.
    pub leaf_keys: Vec<CellKey>,
    /// Word address of each leaf's record, indexed by box index.
    pub leaf_addresses: Vec<u32>,
    /// Key of each internal node, indexed by node index.
    pub node_keys: Vec<CellKey>,
}

impl SceneView<'_> {
    /// Checks every rule of the format (see the module docs of [`crate::validate`]).
    ///
    /// # Errors
    /// [`Error::Corrupt`] naming the first broken rule.
    pub fn validate(&self) -> Result<()> {
        self.check_sizes()?;
        let leaves = self.leaf_count();
        if leaves < PARALLEL_LEAVES {
            self.check_triangle_ids()?;
            let index = self.index_tree()?;
            self.check_records(&index)?;
            self.check_leaves(&index, 0..leaves)?;
            self.check_cube_map(&index)?;
            return self.check_distance();
        }
        // A large file: the independent checks run side by side on two threads.
        std::thread::scope(|s| {
            let ids = s.spawn(|| self.check_triangle_ids().and_then(|()| self.check_distance()));
            let index = &self.index_tree()?;
            self.check_records(index)?;
            std::thread::scope(|s| {
                let half = leaves / 2;
                let upper = s.spawn(move || self.check_leaves(index, half..leaves));
                self.check_leaves(index, 0..half)?;
                self.check_cube_map(index)?;
                join(upper)
            })?;
            join(ids)
        })
    }
}

/// Leaves from which validation runs on two threads (below, a thread costs more than
/// it saves).
const PARALLEL_LEAVES: usize = 1 << 16;

/// A checking thread's result (a panic there is a bug, and goes on here).
fn join(handle: std::thread::ScopedJoinHandle<'_, Result<()>>) -> Result<()> {
    handle.join().unwrap_or_else(|panic| std::panic::resume_unwind(panic))
}

impl SceneView<'_> {
    /// The closest-point tree, where the scene has one ([`crate::distance`]).
    fn check_distance(&self) -> Result<()> {
        crate::distance::check(self.distance, self.triangles)
            .map_err(|why| Error::corrupt(format!("the distance section: {why}")))
    }

    fn check_sizes(&self) -> Result<()> {
        let p = &self.params;
        if p.max_depth > MAX_LEVEL || p.cube_level > p.max_depth {
            return Err(Error::corrupt(format!(
                "depth {} or cube level {} beyond the format's limit {MAX_LEVEL}",
                p.max_depth, p.cube_level
            )));
        }
        if !(p.margin.is_finite() && p.margin >= 0.0) {
            return Err(Error::corrupt(format!("margin {} is not a finite non-negative number", p.margin)));
        }
        let b = &self.bounds;
        let finite = b.root_lo.iter().chain(&b.mesh_lo).chain(&b.mesh_hi).all(|v| v.is_finite());
        if !(finite && b.root_size.is_finite() && b.root_size > 0.0) {
            return Err(Error::corrupt("scene bounds are not finite"));
        }
        // A power-of-two edge makes every cell size exact, so a tracer that recomputes
        // a box from its cell gets the stored box bit for bit.
        if b.root_size.to_bits() & 0x007F_FFFF != 0 || !b.root_size.is_normal() {
            return Err(Error::corrupt(format!("root edge {} is not a power of two", b.root_size)));
        }
        if !self.triangles.len().is_multiple_of(TRIANGLE_FLOATS) || !self.boxes.len().is_multiple_of(BOX_FLOATS) {
            return Err(Error::corrupt("triangle or box array length is not a whole number of entries"));
        }
        if self.triangle_ids.len() != self.triangle_count() {
            return Err(Error::corrupt("triangle-id map and triangle array differ in length"));
        }
        if !self.nodes.len().is_multiple_of(8) {
            return Err(Error::corrupt("node array length is not a multiple of 8"));
        }
        let res = 1usize << p.cube_level;
        if self.cube_map.len() != 6 * res * res {
            return Err(Error::corrupt(format!(
                "cube map has {} texels, level {} needs {}",
                self.cube_map.len(),
                p.cube_level,
                6 * res * res
            )));
        }
        let tri_count = self.triangle_count() as u64;
        // Every reference in range, and every stored triangle referenced: a triangle
        // no leaf lists is one no walk can hit (the leaves' lists tile the references,
        // `check_records`).
        let mut listed = vec![0u64; (tri_count as usize).div_ceil(64)];
        for &r in self.tri_refs {
            if r as u64 >= tri_count {
                return Err(Error::corrupt(format!("triangle reference {r} out of range")));
            }
            listed[r as usize / 64] |= 1 << (r % 64);
        }
        let unlisted = listed.iter().enumerate().find_map(|(i, &w)| {
            let full = if (i + 1) * 64 <= tri_count as usize { u64::MAX } else { (1u64 << (tri_count % 64)) - 1 };
            (w != full).then(|| i * 64 + (!w & full).trailing_zeros() as usize)
        });
        if let Some(t) = unlisted {
            return Err(Error::corrupt(format!(
                "stored triangle {t} (input triangle {}) is listed by no leaf: no ray could hit it",
                self.triangle_ids.get(t).copied().unwrap_or(u32::MAX)
            )));
        }
        let stats = &self.stats;
        if tri_count.checked_add(stats.degenerate_triangles) != Some(stats.input_triangles) {
            return Err(Error::corrupt("triangle counts in the statistics do not add up"));
        }
        self.check_geometry()?;
        self.check_shading()
    }

    /// Every vertex finite and inside the mesh box, the mesh box inside the root cube.
    fn check_geometry(&self) -> Result<()> {
        let b = &self.bounds;
        let root_hi = b.root_lo.map(|lo| lo as f64 + b.root_size as f64);
        for a in 0..3 {
            let (lo, hi) = (b.mesh_lo[a], b.mesh_hi[a]);
            if !(lo <= hi && lo >= b.root_lo[a] && hi as f64 <= root_hi[a]) {
                return Err(Error::corrupt(format!(
                    "the mesh box {:?}-{:?} is not inside the root cube",
                    b.mesh_lo, b.mesh_hi
                )));
            }
        }
        // One branch-free pass: a NaN or infinite coordinate fails the comparisons with
        // the (finite) mesh box too.
        let (lo, hi) = (b.mesh_lo, b.mesh_hi);
        let inside = |c: &[f32]| {
            (c[0] >= lo[0]) & (c[0] <= hi[0]) & (c[1] >= lo[1]) & (c[1] <= hi[1]) & (c[2] >= lo[2]) & (c[2] <= hi[2])
        };
        if let Some(corner) = self.triangles.chunks_exact(3).position(|c| !inside(c)) {
            let c = &self.triangles[3 * corner..3 * corner + 3];
            let what = if c.iter().all(|v| v.is_finite()) {
                "a vertex outside the mesh box"
            } else {
                "a coordinate that is not finite"
            };
            return Err(Error::corrupt(format!("triangle {} has {what}", corner / 3)));
        }
        Ok(())
    }

    /// The shading arrays are absent or one entry a stored triangle; material ids in
    /// range; the shading data's numbers finite.
    fn check_shading(&self) -> Result<()> {
        let n = self.triangle_count();
        for (name, len, per) in [
            ("material-id", self.material_ids.len(), 1),
            ("normal", self.normals.len(), TRIANGLE_FLOATS),
            ("vertex-colour", self.colors.len(), crate::COLOR_WORDS),
            ("tangent", self.tangents.len(), TANGENT_WORDS),
        ] {
            if len != 0 && Some(len) != n.checked_mul(per) {
                return Err(Error::corrupt(format!(
                    "{name} array holds {len} values, {n} triangles need {} (or none)",
                    n.saturating_mul(per)
                )));
            }
        }
        // Texture coordinates: one to MAX_UV_CHANNELS channels of six a triangle, and
        // every material's slots reading one of them.
        let channels = self.uv_channel_count();
        if !self.uvs.is_empty()
            && (channels == 0
                || channels > MAX_UV_CHANNELS
                || Some(self.uvs.len()) != n.checked_mul(UV_FLOATS * channels))
        {
            return Err(Error::corrupt(format!(
                "texture-coordinate array holds {} values, {n} triangles need {} a channel, 1 to \
                 {MAX_UV_CHANNELS} channels (or none)",
                self.uvs.len(),
                n.saturating_mul(UV_FLOATS)
            )));
        }
        if let Some(m) =
            self.shading.materials.iter().find(|m| m.uv_channels.iter().any(|&c| c as usize >= channels.max(1)))
        {
            return Err(Error::corrupt(format!(
                "material '{}' reads texture-coordinate channels {:?}; the scene has {}",
                m.name, m.uv_channels, channels
            )));
        }
        if self.normals.iter().chain(self.uvs).any(|v| !v.is_finite()) {
            return Err(Error::corrupt("a shading normal or texture coordinate is not finite"));
        }
        // A corner's tangent: a unit vector and a sign, or all zero (none).
        for (i, words) in self.tangents.chunks_exact(2).enumerate() {
            let t = crate::layout::decode_tangent([words[0], words[1]]);
            let sign = words[1] >> 16;
            let none = words == [0, 0];
            if !none && (![32767, 32769].contains(&sign) || !crate::shading::is_unit([t[0], t[1], t[2]])) {
                return Err(Error::corrupt(format!(
                    "tangent of corner {} of stored triangle {} is ({}, {}, {}, {}): not a unit vector and a sign \
                     of 1 or -1, nor zero",
                    i % 3,
                    i / 3,
                    t[0],
                    t[1],
                    t[2],
                    t[3]
                )));
            }
        }
        let materials = self.shading.materials.len();
        if let Some(bad) = self.material_ids.iter().find(|&&m| m as usize >= materials) {
            return Err(Error::corrupt(format!("material id {bad} out of range ({materials} materials)")));
        }
        self.shading.validate()?;
        if let Some(last) = self.shading.parts.last() {
            let end = u64::from(last.first) + u64::from(last.count);
            if end > self.stats.input_triangles {
                return Err(Error::corrupt(format!(
                    "mesh part '{}' ends at triangle {end}; the input has {}",
                    last.name, self.stats.input_triangles
                )));
            }
        }
        self.shading.validate_texels(&self.texels)
    }

    fn check_triangle_ids(&self) -> Result<()> {
        let stats = &self.stats;
        // Ids name distinct input triangles. Sorting a copy costs memory in proportion
        // to the file, never to a count the file declares.
        let mut ids = self.triangle_ids.to_vec();
        ids.sort_unstable();
        if let Some(w) = ids.windows(2).find(|w| w[0] == w[1]) {
            return Err(Error::corrupt(format!("triangle id {} appears twice", w[0])));
        }
        if ids.last().is_some_and(|&id| id as u64 >= stats.input_triangles) {
            return Err(Error::corrupt("a triangle id is beyond the input's count"));
        }
        Ok(())
    }

    /// Walks the point-location tree from the root, checking that it is a proper octree
    /// whose leaves are exactly the records of the octree array, in box order.
    ///
    /// # Errors
    /// [`Error::Corrupt`] if a reference is out of range, a node is reached twice, the
    /// tree is deeper than the bake's depth, or a leaf's record or box disagrees.
    pub fn index_tree(&self) -> Result<TreeIndex> {
        let leaves = self.leaf_count();
        let node_count = self.nodes.len() / 8;
        let mut index = TreeIndex {
            leaf_keys: vec![CellKey::default(); leaves],
            leaf_addresses: vec![u32::MAX; leaves],
            node_keys: vec![CellKey::default(); node_count],
        };
        let mut node_seen = vec![false; node_count];
        let mut stack = vec![(self.root, CellKey::default())];
        while let Some((word, key)) = stack.pop() {
            if key.level > self.params.max_depth {
                return Err(Error::corrupt("point-location tree deeper than the bake's depth"));
            }
            match NodeRef::decode(word) {
                NodeRef::Internal(i) => {
                    let i = i as usize;
                    if i >= node_count || std::mem::replace(&mut node_seen[i], true) {
                        return Err(Error::corrupt(format!("internal node {i} out of range or reached twice")));
                    }
                    index.node_keys[i] = key;
                    for child in (0..8).rev() {
                        let mut c = key;
                        c.level += 1;
                        for a in 0..3 {
                            c.cell[a] = 2 * key.cell[a] + ((child >> a) & 1);
                        }
                        stack.push((self.nodes[8 * i + child as usize], c));
                    }
                }
                NodeRef::Leaf(address) => self.index_leaf(address, key, &mut index)?,
            }
        }
        if let Some(b) = index.leaf_addresses.iter().position(|&a| a == u32::MAX) {
            return Err(Error::corrupt(format!("leaf {b} is not reachable from the root")));
        }
        if node_seen.iter().any(|s| !s) {
            return Err(Error::corrupt("an internal node is not reachable from the root"));
        }
        Ok(index)
    }

    fn index_leaf(&self, address: u32, key: CellKey, index: &mut TreeIndex) -> Result<()> {
        let rec = self.leaf(address).ok_or_else(|| Error::corrupt(format!("leaf address {address} out of range")))?;
        let b = rec.box_index as usize;
        if b >= index.leaf_addresses.len() || index.leaf_addresses[b] != u32::MAX {
            return Err(Error::corrupt(format!("box index {b} out of range or used twice")));
        }
        index.leaf_addresses[b] = address;
        index.leaf_keys[b] = key;
        let expect = cell_box(self.bounds.root_lo, self.bounds.root_size, key.level, key.cell);
        if self.leaf_box(rec.box_index) != expect {
            return Err(Error::corrupt(format!("box {b} is not the box of its cell {key:?}")));
        }
        Ok(())
    }

    fn check_records(&self, index: &TreeIndex) -> Result<()> {
        // Records tile the octree array in box order, so an address is a record start
        // exactly when it is some leaf's address.
        // And the leaves' lists of triangles tile the references in the same order.
        let (mut next, mut next_ref) = (0u64, 0u64);
        for (b, &address) in index.leaf_addresses.iter().enumerate() {
            if address as u64 != next {
                return Err(Error::corrupt(format!("record {b} starts at {address}, expected {next}")));
            }
            let rec = self.leaf(address).expect("indexed leaves fit");
            next += (LEAF_HEADER_WORDS + rec.links.len()) as u64;
            if rec.tri_offset as u64 != next_ref {
                return Err(Error::corrupt(format!(
                    "leaf {b}'s triangles start at reference {}, expected {next_ref} (the leaves list theirs back to back)",
                    rec.tri_offset
                )));
            }
            let end = rec.tri_offset as u64 + rec.tri_count as u64;
            next_ref = end;
            if end > self.tri_refs.len() as u64 {
                return Err(Error::corrupt(format!("leaf {b}'s triangles end at {end}, past the references")));
            }
            if rec.ncount >> (crate::layout::COARSER_SHIFT + 6) != 0 {
                return Err(Error::corrupt(format!("leaf {b} has stray bits in its neighbour counts")));
            }
        }
        if next != self.octree.len() as u64 {
            return Err(Error::corrupt("octree array has words after the last record"));
        }
        if next_ref != self.tri_refs.len() as u64 {
            return Err(Error::corrupt(format!(
                "{} triangle references after the last leaf's: no walk reads them",
                self.tri_refs.len() as u64 - next_ref
            )));
        }
        Ok(())
    }

    /// Each triangle a leaf lists reaches its cell, enlarged by the bake margin: their
    /// boxes overlap (a necessary condition of the bake's exact overlap test; it catches
    /// a triangle moved away from the cells that list it).
    fn check_leaf_triangles(&self, b: usize, rec: &crate::view::LeafRecord<'_>) -> Result<()> {
        let cell = self.leaf_box(rec.box_index);
        let margin = self.params.margin as f64 * self.bounds.root_size as f64;
        // The enlarged cell in f32, rounded outwards: comparisons with the f32 vertices
        // can then only accept more, never refuse a triangle the bake kept.
        let lo: [f32; 3] = std::array::from_fn(|a| crate::distance::down(cell[a] as f64 - margin));
        let hi: [f32; 3] = std::array::from_fn(|a| crate::distance::up(cell[a + 3] as f64 + margin));
        let refs = &self.tri_refs[rec.tri_offset as usize..][..rec.tri_count as usize];
        // Descending input order (the walks' tie rule rests on it), which also rules
        // out a triangle listed twice.
        if let Some(w) = refs.windows(2).find(|w| self.triangle_ids[w[0] as usize] <= self.triangle_ids[w[1] as usize])
        {
            let (first, then) = (self.triangle_ids[w[0] as usize], self.triangle_ids[w[1] as usize]);
            let why = if first == then { "twice" } else { "out of descending input order" };
            return Err(Error::corrupt(format!("leaf {b} lists input triangles {first} and {then} {why}")));
        }
        for &t in refs {
            let v = &self.triangles[t as usize * TRIANGLE_FLOATS..][..TRIANGLE_FLOATS];
            let mut apart = false;
            for a in 0..3 {
                apart |= (v[a].min(v[a + 3]).min(v[a + 6]) > hi[a]) | (v[a].max(v[a + 3]).max(v[a + 6]) < lo[a]);
            }
            if apart {
                return Err(Error::corrupt(format!("leaf {b} lists triangle {t}, which does not reach its cell")));
            }
        }
        Ok(())
    }

    /// Checks the links and the triangles of leaves `range` (box indices): the part of
    /// validation that runs on two threads for a large file.
    fn check_leaves(&self, index: &TreeIndex, range: std::ops::Range<usize>) -> Result<()> {
        for b in range {
            let address = index.leaf_addresses[b];
            let rec = self.leaf(address).expect("indexed leaves fit");
            self.check_leaf_triangles(b, &rec)?;
            let key = index.leaf_keys[b];
            for face in 0..6 {
                let links = rec.face_links(face);
                // A link is a record start exactly when the box index it would hold
                // names a leaf whose record starts there.
                let coarser = crate::layout::neighbour_is_coarser(rec.ncount, face);
                let expected = expected_neighbours(key, face, links, coarser, |link| {
                    let b = *self.octree.get(link as usize + crate::layout::WORD_BOX)? as usize;
                    (index.leaf_addresses.get(b) == Some(&link)).then(|| index.leaf_keys[b])
                });
                expected.map_err(|why| Error::corrupt(format!("leaf {b} {key:?}, face {face}: {why}")))?;
            }
        }
        Ok(())
    }

    fn check_cube_map(&self, index: &TreeIndex) -> Result<()> {
        let level = self.params.cube_level;
        let res = 1u32 << level;
        for face in 0..6 {
            let axis = face_axis(face);
            let (u, v) = other_axes(axis);
            for iv in 0..res {
                for iu in 0..res {
                    let mut cell = [0u32; 3];
                    cell[axis] = if face_is_high(face) { res - 1 } else { 0 };
                    cell[u] = iu;
                    cell[v] = iv;
                    let texel = CellKey { level, cell };
                    let word = self.cube_map[texel_index(face, res as usize, iu as usize, iv as usize)];
                    let ok = match NodeRef::decode(word) {
                        NodeRef::Internal(i) => index.node_keys.get(i as usize) == Some(&texel),
                        NodeRef::Leaf(a) => {
                            index.leaf_addresses.binary_search(&a).is_ok_and(|b| index.leaf_keys[b].contains(&texel))
                        }
                    };
                    if !ok {
                        return Err(Error::corrupt(format!("cube-map texel {face}/{iu}/{iv} does not hold its cell")));
                    }
                }
            }
        }
        Ok(())
    }
}

/// Checks the links of one face against the neighbour cells the geometry calls for.
/// `key_of` gives the key of the leaf at a link, or `None` if the link is not a record.
fn expected_neighbours(
    key: CellKey,
    face: usize,
    links: &[u32],
    coarser: bool,
    key_of: impl Fn(u32) -> Option<CellKey>,
) -> std::result::Result<(), String> {
    if coarser && links.len() != 1 {
        return Err("the coarser-neighbour flag is set on a face without one neighbour".into());
    }
    let axis = face_axis(face);
    let high = face_is_high(face);
    let last = (1u32 << key.level) - 1;
    let on_boundary = if high { key.cell[axis] == last } else { key.cell[axis] == 0 };
    if on_boundary {
        return if links.is_empty() { Ok(()) } else { Err("links across the root's boundary".into()) };
    }
    let mut across = key;
    across.cell[axis] = if high { key.cell[axis] + 1 } else { key.cell[axis] - 1 };
    let mut keys = [CellKey::default(); 4];
    if links.len() > 4 {
        return Err(format!("{} links", links.len()));
    }
    for (k, &l) in keys.iter_mut().zip(links) {
        *k = key_of(l).ok_or_else(|| format!("link {l} is not a leaf record"))?;
    }
    match &keys[..links.len()] {
        [n] if n.level == key.level || n.level + 1 == key.level => {
            if !n.contains(&across) {
                Err(format!("neighbour {n:?} is not across the face"))
            } else if coarser != (n.level < key.level) {
                Err(format!("the coarser-neighbour flag says {coarser} for neighbour {n:?}"))
            } else {
                Ok(())
            }
        }
        [_, _, _, _] => {
            let (u, v) = other_axes(axis);
            for (q, n) in keys.iter().enumerate() {
                let mut want = CellKey { level: key.level + 1, cell: [0; 3] };
                want.cell[axis] = if high { 2 * across.cell[axis] } else { 2 * across.cell[axis] + 1 };
                want.cell[u] = 2 * key.cell[u] + (q as u32 & 1);
                want.cell[v] = 2 * key.cell[v] + (q as u32 >> 1);
                if *n != want {
                    return Err(format!("quadrant {q} links to {n:?}, expected {want:?}"));
                }
            }
            Ok(())
        }
        other => Err(format!("{} links, or a neighbour more than one level away", other.len())),
    }
}
