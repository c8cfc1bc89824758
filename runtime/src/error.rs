//! The one error type of the runtime crate.

/// What can go wrong opening or rendering a scene.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// The file could not be opened or is not a valid scene.
    #[error(transparent)]
    Format(#[from] octrace_format::Error),
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
