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

mod error;
mod file;
mod header;
pub mod layout;
mod scene;
mod shading;
pub mod stats;
pub mod validate;
mod view;
mod write;

pub use error::{Error, Result, Version};
pub use file::{is_compressed_file, SceneFile, MAX_COMPRESSION_RATIO, ZSTD_MAGIC};
pub use header::{
    Header, Section, ARCHIVE_ALIGN, FIXED_HEADER_LEN, HEADER_LEN, MAGIC, RKYV_SETTINGS, SECTION_COUNT, SECTION_NAMES,
    VERSION,
};
pub use layout::NodeRef;
pub use scene::{BakeParams, BakeStats, BakedScene, Bounds};
pub use shading::{
    AlphaMode, Camera, Effect, EffectReason, Light, LightKind, Material, Shading, DIELECTRIC_F0, VISIBLE_WEIGHT,
};
pub use view::{LeafRecord, SceneView};
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
            for (len, words) in
                lens.iter_mut().zip(crate::file::view_of(a, &crate::file::EMPTY_SHADING).section_words())
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
            stats: BakeStats { input_triangles: 1, degenerate_triangles: 0, leaves_before_balance: 1 },
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
            root: 0,
            shading: Default::default(),
        }
    }
}
