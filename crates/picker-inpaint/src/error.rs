//! Errors of `picker-inpaint`.

use std::path::PathBuf;

/// What went wrong while inpainting.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// No texel of the image is known, so there is nothing to fill from.
    #[error("nothing to inpaint from: no texel of the {width}x{height} image is known")]
    NothingKnown {
        /// Columns.
        width: usize,
        /// Rows.
        height: usize,
    },
    /// Arguments that do not fit together.
    #[error("{0}")]
    Invalid(String),
    /// A learned inpainter's weights file is unusable.
    #[error("{path}: {reason}")]
    Weights {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// A network error.
    #[error(transparent)]
    Nets(#[from] picker_nets::Error),
}

/// `Result` with [`Error`].
pub type Result<T> = std::result::Result<T, Error>;
