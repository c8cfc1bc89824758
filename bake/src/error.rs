//! The one error type of the bake crate.

use std::path::PathBuf;

/// Everything that can go wrong while loading a mesh or baking it.
///
/// Mesh errors name the file and the element at fault, so a pipeline log says what to
/// fix.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// The file could not be read (or decompressed).
    #[error("{path}: cannot read: {source}")]
    Unreadable {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// The file's extension is none of `.obj`, `.gltf`, `.glb` (optionally `.zst`); the
    /// message says when it is a folder or a baked scene.
    #[error("{}: {}", .path.display(), not_a_mesh(.path))]
    UnknownFormat {
        /// The file.
        path: PathBuf,
    },
    /// A file the mesh names (a glTF buffer URI) may not or cannot be read: outside
    /// the mesh's folder under [`References::Confined`](crate::References), not a
    /// regular file, over the size limit, missing, or an unsupported URI scheme.
    /// Nothing of it was read.
    #[error("{path}: {element}: reference '{reference}' not read: {reason}")]
    Reference {
        /// The mesh file.
        path: PathBuf,
        /// What names it (a glTF buffer).
        element: String,
        /// The reference as the file writes it.
        reference: String,
        /// Why it was not read.
        reason: String,
    },
    /// The file does not parse.
    #[error("{path}: {element}: {message}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// Where in the file (a line, a mesh primitive, ...).
        element: String,
        /// What is wrong.
        message: String,
    },
    /// A vertex coordinate is NaN or infinite.
    #[error("{path}: {element}: coordinate {value} is not finite")]
    NonFinite {
        /// The file.
        path: PathBuf,
        /// The vertex, and the primitive or object it belongs to.
        element: String,
        /// The offending value.
        value: f32,
    },
    /// A face or primitive refers to a vertex that does not exist.
    #[error("{path}: {element}: vertex index {index} out of range ({count} vertices)")]
    IndexOutOfRange {
        /// The file.
        path: PathBuf,
        /// The face or primitive.
        element: String,
        /// The index found.
        index: i64,
        /// How many vertices there are.
        count: usize,
    },
    /// The scene has primitives, but none made of triangles.
    #[error("{path}: {element}: primitive mode {mode} is not supported (only triangles, strips and fans)")]
    UnsupportedMode {
        /// The file.
        path: PathBuf,
        /// The first unsupported primitive.
        element: String,
        /// The glTF mode's name.
        mode: String,
    },
    /// The scene holds no triangle at all.
    #[error("{path}: the scene holds no triangles")]
    EmptyScene {
        /// The file.
        path: PathBuf,
    },
    /// Every triangle has zero area once its vertices are `f32`: a mesh small against
    /// its distance from the origin, whose vertices round together. Nothing would be
    /// left to trace.
    #[error(
        "every one of the {triangles} triangles is degenerate at f32 precision (zero area once its vertices \
         are rounded to f32): the mesh spans {} at coordinates up to {}, where f32's spacing is {}; \
         move it towards the origin (or scale it up) before baking",
        number(*extent),
        number(*largest),
        number(*spacing)
    )]
    Collapsed {
        /// Triangles in the input.
        triangles: u64,
        /// The largest extent of the (rounded) mesh's box.
        extent: f64,
        /// The largest coordinate magnitude.
        largest: f64,
        /// The spacing of `f32` at that magnitude.
        spacing: f64,
    },
    /// The mesh is too large for the format (more than 2^32 - 1 triangles).
    #[error("{path}: {count} triangles exceed the format's limit of 2^32 - 1")]
    TooLarge {
        /// The file.
        path: PathBuf,
        /// Triangles found.
        count: u64,
    },
    /// The octree the mesh needs does not fit the format's 32-bit indices: leaf
    /// records addressed below 2^31 words (the top bit marks internal nodes),
    /// triangle references counted in 32 bits. Found before the build when the
    /// triangles alone pass a limit, else the moment the tree being built passes it
    /// (the build stops: `needed` is what it had reached).
    #[error(
        "the octree needs at least {needed} {what}; the format holds at most {limit} (use a larger --leaf-size or a smaller \
         --max-depth, or split the mesh)"
    )]
    Limit {
        /// What overflows: "words of leaf records", "triangle references".
        what: &'static str,
        /// How many the octree needs at least.
        needed: u64,
        /// The format's limit.
        limit: u64,
    },
    /// The octree being built passed the bake's memory budget
    /// ([`BuildParams::max_tree_bytes`](crate::BuildParams::max_tree_bytes)); the build
    /// stopped there. Options that multiply references (a small leaf size, a deep
    /// tree) or triangles that share cells (many coincident copies, fans) get here.
    #[error(
        "the octree being built reached {} bytes, past the bake's memory budget of {} (raise it with \
         --max-memory or BuildParams::max_tree_bytes, or use a larger --leaf-size or a smaller --max-depth; \
         the default is 1 KiB a triangle, at least 2 GiB, at most a third of the memory the process may use)",
        thousands(*needed),
        thousands(*limit)
    )]
    TreeBudget {
        /// Bytes the tree had reached (at least).
        needed: u64,
        /// The budget.
        limit: u64,
    },
    /// The scene's size or position is beyond what the tracer's `f32` arithmetic
    /// serves: an extent below `2^-60` or a size or coordinate above `2^60`
    /// (`octree::MIN_ROOT_EDGE`, `octree::MAX_COORDINATE`). Rays would leak or miss.
    #[error(
        "scene extent {} and largest coordinate {} are beyond what the tracer serves: \
         extents from 2^-60 (8.7e-19) and coordinates up to 2^60 (1.2e18), where products of f32 \
         coordinates stay in f32's normal range; scale the mesh (or move it towards the origin)",
        number(*extent),
        number(*largest)
    )]
    Scale {
        /// The largest extent of the mesh's box.
        extent: f64,
        /// The largest coordinate magnitude.
        largest: f64,
    },
    /// An input asks for more work or memory than a budget allows, found before the
    /// work (or, for a tree being built, as soon as it passes): the budget, what was
    /// asked, and the option that raises it.
    #[error("{path}: {what}: {needed} is past the budget of {limit} (raise it with {option})")]
    Budget {
        /// The input.
        path: PathBuf,
        /// What is counted, and where.
        what: String,
        /// How many the input asks for (at least).
        needed: u64,
        /// The budget.
        limit: u64,
        /// The option that raises it: the command-line flag and the library field.
        option: &'static str,
    },
    /// A build parameter is beyond its limit ([`BuildParams::check`](crate::BuildParams::check)).
    #[error("invalid build parameters: {message}")]
    Params {
        /// Which parameter, and its limit.
        message: String,
    },
    /// Writing the baked file failed.
    #[error(transparent)]
    Format(#[from] octrace_format::Error),
    /// Memory the bake needed could not be had (what, and how much).
    #[error(transparent)]
    Alloc(#[from] octrace_format::memory::AllocError),
}

/// The bake crate's result type.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Why a path is not a mesh the loader reads: a folder, a baked scene, or another
/// extension.
fn not_a_mesh(path: &std::path::Path) -> &'static str {
    let name = path.file_name().map(|n| n.to_string_lossy().to_ascii_lowercase()).unwrap_or_default();
    if path.is_dir() {
        "a folder, not a mesh: give one mesh file (.obj, .gltf or .glb, optionally .zst)"
    } else if name.ends_with(".oct") || name.ends_with(".oct.zst") {
        "a baked scene already: bake reads meshes (.obj, .gltf or .glb, optionally .zst); inspect or render the .oct \
         itself"
    } else {
        "unknown mesh format (expected .obj, .gltf or .glb, optionally .zst)"
    }
}

/// A count with thousands separators: `1,234,567`.
pub(crate) fn thousands(n: u64) -> String {
    let digits = n.to_string();
    let mut out = String::new();
    for (i, c) in digits.chars().enumerate() {
        if i > 0 && (digits.len() - i).is_multiple_of(3) {
            out.push(',');
        }
        out.push(c);
    }
    out
}

/// A length for a message: `0`, or four significant digits (`1.000e6`, `2.384e-7`).
pub(crate) fn number(x: f64) -> String {
    if x == 0.0 {
        "0".to_string()
    } else {
        format!("{x:.3e}")
    }
}
