//! Errors of `picker-extract`.

use std::path::PathBuf;

/// What went wrong while extracting a material.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        #[source]
        source: std::io::Error,
    },
    /// An image or render-element file error.
    #[error(transparent)]
    Render(#[from] picker_render::Error),
    /// An inpainting error.
    #[error(transparent)]
    Inpaint(#[from] picker_inpaint::Error),
    /// A request that cannot be served (pick outside the image, bad size, ...).
    #[error("{0}")]
    Invalid(String),
    /// The picked material's texture cannot be reprojected: no texture
    /// coordinates reach the texture square (`--uv auto` then falls back to
    /// a single colour, see `pipeline::extract`).
    #[error("the texture cannot be reprojected: {0}")]
    NoTexture(String),
    /// Inputs whose shapes do not agree.
    #[error("{what}: expected {expected}, found {found}")]
    Shape {
        /// What was checked.
        what: String,
        /// What was expected.
        expected: String,
        /// What was found.
        found: String,
    },
    /// Serialising JSON failed.
    #[error("serialising {what}: {source}")]
    Json {
        /// What was serialised.
        what: String,
        /// The cause.
        #[source]
        source: serde_json::Error,
    },
}

/// `Result` with [`Error`].
pub type Result<T> = std::result::Result<T, Error>;
