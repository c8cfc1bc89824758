//! The octrace baked-scene file: layout, version, reading, writing and validation.
//!
//! A `.oct` file is a 64-byte [`Header`] (magic, version, flags, rkyv settings, payload
//! length and checksums) followed by an rkyv archive of a [`BakedScene`]: the four
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
pub mod stats;
pub mod validate;
mod view;
mod write;

pub use error::{Error, Result, Version};
pub use file::{is_compressed_file, SceneFile, MAX_COMPRESSION_RATIO, ZSTD_MAGIC};
pub use header::{Header, ARCHIVE_ALIGN, HEADER_LEN, MAGIC, RKYV_SETTINGS, VERSION};
pub use layout::NodeRef;
pub use scene::{BakeParams, BakeStats, BakedScene, Bounds};
pub use view::{LeafRecord, SceneView};
pub use write::write_atomically;

#[doc(hidden)]
pub mod testing {
    //! Tiny hand-built scenes for doc examples and tests.
    use crate::layout::{cell_box, pack_counts};
    use crate::{BakeParams, BakeStats, BakedScene, Bounds};

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
            root: 0,
        }
    }
}
