//! The octrace baked-scene file: layout, version, reading, writing and validation.
//!
//! A `.oct` file is a [`Header`] (magic, version, flags, rkyv settings, lengths, and a
//! table of the archive's sections, each with its own checksum) followed by an rkyv
//! archive of a [`BakedScene`]: the four
//! arrays of Portalez & Duguet, *Lancer de rayons dans un octree* (2016) — octree leaf
//! records, triangles, boxes, cube map — plus the point-location tree and the
//! triangle-id map. `format/FORMAT.md` gives the byte layout; [`layout`] gives the
//! conventions of the octree words.
//!
//! This crate depends on no other octrace crate: the baker writes with it, the runtime
//! reads with it.
//!
//! # Example
//! ```
//! use octrace_format::{BakedScene, SceneFile};
//! # fn main() -> Result<(), octrace_format::Error> {
//! # let scene = octrace_format::testing::single_leaf_scene();
//! let dir = tempfile::tempdir().unwrap();
//! let path = dir.path().join("scene.oct");
//! scene.write(&path, 0)?;
//! let file = SceneFile::read(&path)?; // validated, in memory
//! assert_eq!(file.view().octree, scene.octree.as_slice());
//! # Ok(()) }
//! ```
#![deny(missing_docs)]

pub mod distance;
mod error;
mod file;
mod header;
pub mod image;
mod input;
pub mod instanced;
pub mod layout;
pub mod memory;
mod scene;
mod shading;
pub mod stats;
mod texels;
mod texture;
pub mod topology;
pub mod validate;
mod view;
mod write;

pub use error::{Error, Result, Version};
pub use file::{is_compressed_file, SceneFile, MAX_COMPRESSION_RATIO, ZSTD_MAGIC};
pub use header::{
    Header, Section, ARCHIVE_ALIGN, FIXED_HEADER_LEN, HEADER_LEN, MAGIC, RKYV_SETTINGS, SECTION_COUNT, SECTION_NAMES,
    VERSION,
};
pub use input::{open_regular_file, read_records, read_regular_file, same_file};
pub use layout::NodeRef;
pub use scene::{BakeParams, BakeStats, BakedScene, Bounds};
pub use shading::{
    AlphaMode, Camera, Effect, EffectReason, Light, LightKind, Material, MeshPart, PartSource, Shading, DIELECTRIC_F0,
    VISIBLE_WEIGHT,
};
pub use texels::{TexelCache, Texels};
pub use texture::{
    linear16, srgb_to_linear16, texels_hash, EmissiveTriangles, Encoded, Filter, ImageKind, LitTexels, Texture, Wrap,
    MAX_TEXTURE_SIDE, TEXEL_SCALE, TEXEL_WORDS,
};
pub use view::{LeafRecord, SceneView, StoredIndex, COLOR_SCALE, COLOR_WORDS};
pub use write::write_atomically;

#[doc(hidden)]
pub mod testing {
    //! Tiny hand-built scenes for doc examples and tests.
    use crate::layout::{cell_box, pack_counts};
    use crate::{BakeParams, BakeStats, BakedScene, Bounds};

    /// A header that makes `payload` a complete file with correct checksums: the
    /// sections follow the arrays when the payload is a structurally sound archive,
    /// else the whole payload is the `root` section (so the open fails in bytecheck, not
    /// at a checksum). For fuzzing past the checksums.
    pub fn header_for_archive(payload: &[u8]) -> crate::Header {
        use crate::header::{ARCHIVE_ALIGN, SECTION_COUNT};
        let mut aligned = rkyv::util::AlignedVec::<ARCHIVE_ALIGN>::with_capacity(payload.len());
        aligned.extend_from_slice(payload);
        let mut lens = [0u64; SECTION_COUNT];
        if let Ok(a) = rkyv::access::<crate::scene::ArchivedBakedScene, rkyv::rancor::Error>(&aligned) {
            for (len, words) in lens
                .iter_mut()
                .zip(crate::file::view_of(a, &crate::file::EMPTY_SHADING, &crate::file::NO_TEXELS).section_words())
            {
                *len = 4 * words.len() as u64;
            }
        }
        let arrays: u64 = lens.iter().sum();
        if arrays > payload.len() as u64 {
            lens = [0; SECTION_COUNT];
        }
        lens[SECTION_COUNT - 1] = payload.len() as u64 - lens.iter().sum::<u64>();
        let mut offset = 0usize;
        let sums = lens.map(|len| {
            let bytes = &payload[offset..offset + len as usize];
            offset += len as usize;
            (len, xxhash_rust::xxh3::xxh3_64(bytes))
        });
        crate::Header::new(sums, 0)
    }

    /// A scene with one triangle in a single leaf (the root), no links.
    pub fn single_leaf_scene() -> BakedScene {
        let root_lo = [0.0f32; 3];
        BakedScene {
            params: BakeParams { max_depth: 0, leaf_size: 8, margin: 0.0, cube_level: 0 },
            bounds: Bounds { mesh_lo: [0.0; 3], mesh_hi: [1.0, 1.0, 0.0], root_lo, root_size: 1.0 },
            stats: BakeStats {
                input_triangles: 1,
                degenerate_triangles: 0,
                leaves_before_balance: 1,
                ..Default::default()
            },
            octree: vec![1, 0, 0, pack_counts([0; 6], [false; 6])],
            tri_refs: vec![0],
            triangles: vec![0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0],
            triangle_ids: vec![0],
            boxes: cell_box(root_lo, 1.0, 0, [0; 3]).to_vec(),
            cube_map: vec![0; 6],
            nodes: vec![],
            material_ids: vec![],
            normals: vec![],
            uvs: vec![],
            colors: vec![],
            tangents: vec![],
            texels: vec![],
            images: vec![],
            distance: vec![],
            root: 0,
            shading: Default::default(),
            decoded: Default::default(),
        }
    }

    /// One to three changes to the scene's semantic fields (array words and lengths,
    /// depth, cube level, bounds, shading arrays), drawn from `next`: the file it
    /// serializes to stays a sound archive, so only validation (or the trusted path's
    /// own checks) stands between it and a tracer. For the trusted-path test and fuzz
    /// target.
    pub fn mutate_semantics(s: &mut BakedScene, next: &mut dyn FnMut() -> u64) {
        let mut pick = |n: u64| next() % n;
        for _ in 0..1 + pick(3) {
            match pick(16) {
                0..=3 => poke_words(&mut s.octree, &mut pick),
                4 => poke_words(&mut s.tri_refs, &mut pick),
                5 => poke_floats(&mut s.triangles, &mut pick),
                6 => poke_words(&mut s.triangle_ids, &mut pick),
                7 => poke_floats(&mut s.boxes, &mut pick),
                8 => poke_words(&mut s.cube_map, &mut pick),
                9 => poke_words(&mut s.nodes, &mut pick),
                10 => s.root = word(s.nodes.len(), &mut pick),
                11 => s.params.max_depth = pick(40) as u32,
                12 => s.params.cube_level = pick(40) as u32,
                13 => {
                    let (field, value) = (pick(10) as usize, float(&mut pick));
                    let b = &mut s.bounds;
                    match field {
                        0..=2 => b.mesh_lo[field] = value,
                        3..=5 => b.mesh_hi[field - 3] = value,
                        6..=8 => b.root_lo[field - 6] = value,
                        _ => b.root_size = value,
                    }
                }
                14 => poke_words(&mut s.material_ids, &mut pick),
                _ => match pick(5) {
                    0 => poke_floats(&mut s.normals, &mut pick),
                    3 => poke_words(&mut s.tangents, &mut pick),
                    1 => poke_floats(&mut s.uvs, &mut pick),
                    2 => poke_words(&mut s.colors, &mut pick),
                    _ => match pick(3) {
                        0 => poke_words(&mut s.texels, &mut pick),
                        1 => poke_words(&mut s.distance, &mut pick),
                        _ => poke_words(&mut s.images, &mut pick),
                    },
                },
            }
        }
    }

    /// A value a hostile file might hold in a word: small, near a length, huge, a power
    /// of two or any.
    fn word(len: usize, pick: &mut dyn FnMut(u64) -> u64) -> u32 {
        match pick(6) {
            0 => pick(8) as u32,
            1 => len as u32 + pick(3) as u32,
            2 => u32::MAX - pick(3) as u32,
            3 => 1 << pick(32),
            _ => pick(1 << 32) as u32,
        }
    }

    fn float(pick: &mut dyn FnMut(u64) -> u64) -> f32 {
        [f32::NAN, f32::INFINITY, f32::NEG_INFINITY, 0.0, -0.0, 1e30, -1e-30, f32::MIN_POSITIVE, 3.0, -2.0]
            [pick(10) as usize]
    }

    fn poke_words(v: &mut Vec<u32>, pick: &mut dyn FnMut(u64) -> u64) {
        match (pick(5), v.len() as u64) {
            (_, 0) => v.push(word(0, pick)),
            (0, n) => v.truncate(pick(n) as usize),
            (1, _) => v.push(word(v.len(), pick)),
            (_, n) => {
                let i = pick(n) as usize;
                v[i] = word(v.len(), pick);
            }
        }
    }

    fn poke_floats(v: &mut Vec<f32>, pick: &mut dyn FnMut(u64) -> u64) {
        match (pick(4), v.len() as u64) {
            (_, 0) => {}
            (0, n) => v.truncate(pick(n) as usize),
            (_, n) => {
                let i = pick(n) as usize;
                v[i] = float(pick);
            }
        }
    }
}
