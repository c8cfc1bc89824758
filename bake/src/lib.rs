//! Bakes triangle meshes into octrace's constrained octree.
//!
//! [`Mesh::load`] reads OBJ and glTF 2.0 (optionally zstd-compressed); [`bake`] builds
//! the 2:1-balanced, neighbour-linked octree of Portalez & Duguet, *Lancer de rayons
//! dans un octree* (2016), and returns an [`octrace_format::BakedScene`] ready to write.
//!
//! # Example
//! ```
//! use octrace_bake::{bake, BuildParams, Mesh};
//! // Two triangles making a unit square.
//! let mesh = Mesh::from_triangles(vec![
//!     [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0]],
//!     [[0.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]],
//! ]);
//! let scene = bake(&mesh, &BuildParams::auto())?;
//! let dir = tempfile::tempdir()?;
//! scene.write(dir.path().join("square.oct"), 0)?;
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
#![forbid(unsafe_code)]

pub mod effects;
mod error;
pub mod hard_rays;
pub mod mesh;
pub mod octree;
pub mod procedural;
pub mod summary;
pub mod topology;

pub use error::{Error, Result};
pub use mesh::{
    InstancedMesh, LoadOptions, Loaded, Mesh, MeshFormat, Placement, References, DEFAULT_MAX_INSTANCES,
    DEFAULT_MAX_TRIANGLES, MAX_MESH_COMPRESSION_RATIO,
};
pub use octree::{bake, bake_with_progress, BakeStage, BuildParams};
