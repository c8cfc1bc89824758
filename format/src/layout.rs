//! Conventions of the octree words, shared by the baker, the tracers and validation.
//!
//! These replace the paper's lost Figure 4 (Portalez & Duguet 2016, section 4.2).
//!
//! # Faces
//! A cell's six faces are numbered `face = 2 * axis + side`, with `axis` 0, 1, 2 for
//! x, y, z and `side` 0 for the low face (normal towards `-axis`) and 1 for the high
//! face. So 0 = -x, 1 = +x, 2 = -y, 3 = +y, 4 = -z, 5 = +z.
//!
//! # The two other axes of a face
//! For a face across `axis`, `(u, v)` are the two other axes in increasing order:
//! x -> (y, z), y -> (x, z), z -> (x, y). The cube map's texels and the four
//! neighbours of a face are both indexed in that `(u, v)` frame.
//!
//! # Four neighbours
//! When a face has four (finer) neighbours, they are stored in quadrant order
//! `q = u_high | v_high << 1`, where `u_high` is 1 for the neighbour on the high side of
//! the face's median line across `u` (the line `u = centre_u`).
//!
//! # Leaf record
//! In the octree array, a leaf is `tCount | tOffset | boxIndex | nCount | links...`
//! (the paper's equation 3). `tOffset` indexes the triangle-reference array,
//! `boxIndex` the box array (and is the leaf's ordinal), and `nCount` packs the six
//! neighbour counts, face `f` in bits `4f .. 4f + 4`, each 0, 1 or 4, and in bit
//! `24 + f` whether the single neighbour across `f` is one level coarser (clear when it
//! is the same size). With that bit a walk knows every leaf's cell, and so its box,
//! without loading it. The links follow, face 0's first; a link is the word address of
//! the neighbour's record.
//!
//! # Node references
//! The point-location tree and the cube map hold [`NodeRef`]s: a leaf's word address,
//! or, with [`INTERNAL_BIT`] set, the index of an internal node whose eight children
//! (`child = x_high | y_high << 1 | z_high << 2`) follow at `8 * index` in the node array.

/// Words before a leaf's links: `tCount`, `tOffset`, `boxIndex`, `nCount`.
pub const LEAF_HEADER_WORDS: usize = 4;
/// Word index of `tCount` in a leaf record.
pub const WORD_TRI_COUNT: usize = 0;
/// Word index of `tOffset` in a leaf record.
pub const WORD_TRI_OFFSET: usize = 1;
/// Word index of the box index in a leaf record.
pub const WORD_BOX: usize = 2;
/// Word index of the packed neighbour counts in a leaf record.
pub const WORD_NCOUNT: usize = 3;
/// Bit of a [`NodeRef`] that marks an internal node of the point-location tree.
pub const INTERNAL_BIT: u32 = 1 << 31;
/// `f32`s a triangle takes in the triangle array: three vertices, `x y z` each.
pub const TRIANGLE_FLOATS: usize = 9;
/// `f32`s a triangle's texture coordinates take: `u v` for each of its three corners.
pub const UV_FLOATS: usize = 6;
/// Texture-coordinate channels a scene may have: one a texture slot of a material.
pub const MAX_UV_CHANNELS: usize = 5;
/// Words a triangle's tangents take: two a corner, `x | y << 16` and `z | w << 16`, each
/// a signed 16-bit fraction of 32767 ([`decode_tangent`]).
pub const TANGENT_WORDS: usize = 6;
/// From a stored tangent component to its value: `1 / 32767`.
pub const TANGENT_SCALE: f32 = 1.0 / 32767.0;

/// A corner's tangent stored as two words (`x | y << 16`, `z | w << 16`, signed 16-bit
/// fractions of 32767; `w` is 32767 or -32767, the bitangent's sign, or all four are
/// zero where there is no tangent).
pub fn encode_tangent(t: [f32; 4]) -> [u32; 2] {
    let q = |c: f32| ((c.clamp(-1.0, 1.0) * 32767.0).round() as i16 as u16) as u32;
    [q(t[0]) | q(t[1]) << 16, q(t[2]) | q(t[3]) << 16]
}

/// A corner's tangent from its two words: `x y z` each `i16 * TANGENT_SCALE` (one
/// rounding, as the GPU kernel computes it), `w` 1, -1 or 0 by the sign of its `i16`.
pub fn decode_tangent(words: [u32; 2]) -> [f32; 4] {
    let c = |word: u32, high: bool| (if high { word >> 16 } else { word & 0xffff }) as u16 as i16;
    let w = c(words[1], true);
    let f = |q: i16| f32::from(q) * TANGENT_SCALE;
    [f(c(words[0], false)), f(c(words[0], true)), f(c(words[1], false)), f32::from(w.signum())]
}
/// `f32`s a box takes in the box array: `lo.xyz`, then `hi.xyz`.
pub const BOX_FLOATS: usize = 6;
/// Deepest octree level the format allows (cell coordinates must fit in 24 bits and
/// the cube map's texel grid in 2^48 entries).
pub const MAX_LEVEL: u32 = 20;

/// The axis a face is across.
#[inline]
pub const fn face_axis(face: usize) -> usize {
    face >> 1
}

/// Whether a face is the high face of its axis.
#[inline]
pub const fn face_is_high(face: usize) -> bool {
    face & 1 == 1
}

/// The face opposite `face`.
#[inline]
pub const fn opposite_face(face: usize) -> usize {
    face ^ 1
}

/// The two other axes of `axis`, in increasing order.
#[inline]
pub const fn other_axes(axis: usize) -> (usize, usize) {
    match axis {
        0 => (1, 2),
        1 => (0, 2),
        _ => (0, 1),
    }
}

/// First bit of the "coarser neighbour" flags in `nCount`.
pub const COARSER_SHIFT: u32 = 24;

/// Whether the single neighbour across `face` is one level coarser.
#[inline]
pub const fn neighbour_is_coarser(ncount: u32, face: usize) -> bool {
    (ncount >> (COARSER_SHIFT as usize + face)) & 1 == 1
}

/// The neighbour count of `face` in a packed `nCount` word.
#[inline]
pub const fn neighbour_count(ncount: u32, face: usize) -> u32 {
    (ncount >> (4 * face)) & 0xF
}

/// Where `face`'s links start, counted from the first link: the sum of the counts of
/// the faces before it. Branch-free: the nibbles below `face` are summed in bytes.
#[inline]
pub const fn links_before(ncount: u32, face: usize) -> u32 {
    let below = ncount & ((1u32 << (4 * face)) - 1);
    // Each nibble is at most 4, so pairs of nibbles fit in a byte...
    let pairs = (below & 0x0F0F0F) + ((below >> 4) & 0x0F0F0F);
    // ...and three bytes of at most 8 sum without carrying past the top byte.
    (pairs.wrapping_mul(0x010101) >> 16) & 0xFF
}

/// Total links of a leaf.
#[inline]
pub const fn total_links(ncount: u32) -> u32 {
    links_before(ncount & 0x00FF_FFFF, 6)
}

/// Packs six neighbour counts and the six "coarser neighbour" flags into an `nCount`
/// word.
pub fn pack_counts(counts: [u32; 6], coarser: [bool; 6]) -> u32 {
    (0..6).fold(0, |acc, f| acc | (counts[f] & 0xF) << (4 * f) | (coarser[f] as u32) << (COARSER_SHIFT as usize + f))
}

/// A reference held by the point-location tree and the cube map.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum NodeRef {
    /// The word address of a leaf record in the octree array.
    Leaf(u32),
    /// The index of an internal node in the node array.
    Internal(u32),
}

impl NodeRef {
    /// Decodes a stored word.
    #[inline]
    pub const fn decode(word: u32) -> Self {
        if word & INTERNAL_BIT != 0 {
            NodeRef::Internal(word & !INTERNAL_BIT)
        } else {
            NodeRef::Leaf(word)
        }
    }

    /// Encodes to a stored word.
    #[inline]
    pub const fn encode(self) -> u32 {
        match self {
            NodeRef::Leaf(a) => a,
            NodeRef::Internal(i) => i | INTERNAL_BIT,
        }
    }
}

/// The low coordinate of grid line `index` at `level` along one axis, as stored in the
/// box array: `lo + index * size / 2^level`, computed in `f64` and rounded once to `f32`,
/// so that two cells sharing a face store the same plane bit for bit.
#[inline]
pub fn grid_plane(root_lo: f32, root_size: f32, level: u32, index: u32) -> f32 {
    let cell = root_size as f64 / (1u64 << level) as f64;
    (root_lo as f64 + index as f64 * cell) as f32
}

/// The box of cell `(level, cell)`: `[lo.x, lo.y, lo.z, hi.x, hi.y, hi.z]`.
pub fn cell_box(root_lo: [f32; 3], root_size: f32, level: u32, cell: [u32; 3]) -> [f32; 6] {
    let mut b = [0.0; 6];
    for a in 0..3 {
        b[a] = grid_plane(root_lo[a], root_size, level, cell[a]);
        b[a + 3] = grid_plane(root_lo[a], root_size, level, cell[a] + 1);
    }
    b
}

/// Index of texel `(iu, iv)` of cube-map face `face` at resolution `res`.
#[inline]
pub const fn texel_index(face: usize, res: usize, iu: usize, iv: usize) -> usize {
    (face * res + iv) * res + iu
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn links_before_sums_the_counts_of_earlier_faces() {
        for code in 0..3u32.pow(6) {
            let mut counts = [0u32; 6];
            let mut c = code;
            for slot in counts.iter_mut() {
                *slot = [0, 1, 4][(c % 3) as usize];
                c /= 3;
            }
            let packed = pack_counts(counts, [false, true, false, true, true, false]);
            for f in 0..6 {
                assert_eq!(neighbour_count(packed, f), counts[f]);
                let expect: u32 = counts[..f].iter().sum();
                assert_eq!(links_before(packed, f), expect, "{counts:?} face {f}");
            }
            assert_eq!(total_links(packed), counts.iter().sum::<u32>());
        }
    }

    #[test]
    fn node_refs_round_trip() {
        for r in [NodeRef::Leaf(0), NodeRef::Leaf(12345), NodeRef::Internal(0), NodeRef::Internal(7)] {
            assert_eq!(NodeRef::decode(r.encode()), r);
        }
    }

    #[test]
    fn neighbouring_cells_share_their_face_plane_exactly() {
        let lo = [-1.337f32, 0.1, 1e5];
        let size = 3.7f32;
        for level in 0..12 {
            let a = cell_box(lo, size, level, [3 % (1 << level), 0, 0]);
            let next = cell_box(lo, size, level + 1, [2 * (3 % (1 << level)) + 2, 0, 0]);
            assert_eq!(a[3], next[0]);
        }
    }
}

#[cfg(test)]
mod tangent_tests {
    use super::*;

    /// The GPU kernel's `tangent_at` reads the scale from these bits; stored unit
    /// tangents decode within 2^-15 of their components, signs and absence kept.
    #[test]
    fn tangents_round_trip_within_the_quantum() {
        assert_eq!(TANGENT_SCALE.to_bits(), 0x3800_0100);
        for t in [[1.0, 0.0, 0.0, 1.0], [0.0, -1.0, 0.0, -1.0], [0.6, 0.0, -0.8, 1.0], [0.0; 4]] {
            let back = decode_tangent(encode_tangent(t));
            assert!(t.iter().zip(back).all(|(a, b)| (a - b).abs() <= 1.0 / 65534.0), "{t:?} {back:?}");
        }
        assert_eq!(encode_tangent([0.0; 4]), [0, 0]);
    }
}
