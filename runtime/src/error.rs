//! The one error type of the runtime crate.

/// What can go wrong opening or rendering a scene.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// The file could not be opened or is not a valid scene.
    #[error(transparent)]
    Format(#[from] octrace_format::Error),
    /// The scene is not closed (some edge of its triangles is used by an odd number of
    /// them), so inside and outside are not defined: a query that needs them is
    /// refused.
    #[error(
        "the scene is not closed: {boundary_edges} of its {edges} edges are boundary edges (used by an odd number \
         of triangles), so it has no inside; a parity vote (`contains_by_vote`) gives an approximate answer"
    )]
    NotClosed {
        /// Edges used by an odd number of triangles.
        boundary_edges: u64,
        /// Distinct edges.
        edges: u64,
    },
    /// Memory an input sized could not be allocated (the allocator refused).
    #[error(transparent)]
    Alloc(#[from] octrace_format::memory::AllocError),
    /// A query's answers would pass their memory budget; nothing was returned.
    #[error("the {what} take at least {needed} bytes, past the budget of {limit} bytes: {advice}")]
    Budget {
        /// What the memory is for (a plural: "crossings").
        what: &'static str,
        /// Bytes reached when the query stopped (a lower bound of what it needs).
        needed: u64,
        /// The budget.
        limit: u64,
        /// How to get the answers within it.
        advice: &'static str,
    },
    /// A transform that cannot place an instance ([`crate::world::World::add`]).
    #[error("cannot place an instance by {what}: {reason}")]
    Transform {
        /// The transform (its rows), or what was placed.
        what: String,
        /// Why not.
        reason: &'static str,
    },
    /// An instance id the world does not hold (never added, or removed).
    #[error("the world holds no instance {id} (never added, or removed)")]
    NoInstance {
        /// The id asked for.
        id: u32,
    },
    /// A material map that names a material its scene does not have
    /// ([`crate::world::World::add_with_materials`]).
    #[error("material map entry {entry} names material {material}; the scene has {materials}")]
    MaterialMap {
        /// The entry (the scene's material it replaces).
        entry: usize,
        /// The material it names.
        material: u32,
        /// How many materials the scene has.
        materials: usize,
    },
    /// An image could not be written.
    #[error("{path}: cannot write image: {message}")]
    Image {
        /// The image file.
        path: std::path::PathBuf,
        /// What failed.
        message: String,
    },
}

/// The runtime crate's result type.
pub type Result<T, E = Error> = std::result::Result<T, E>;
