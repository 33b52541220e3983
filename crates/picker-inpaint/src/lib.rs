//! `picker-inpaint`: filling the unobserved texels of a reprojected texture
//! (see `docs/contract-extract.md`). Work in progress.

#![warn(missing_docs)]

pub mod error;
pub mod seam;

pub use error::{Error, Result};
pub use seam::{seam_score, SeamScore};
