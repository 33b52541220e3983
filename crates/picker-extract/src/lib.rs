//! `picker-extract`: from a photo's render elements and a pick to a material
//! an artist can use (see `docs/contract-extract.md`). Work in progress.

#![warn(missing_docs)]

pub mod error;
pub mod eval;
pub mod export;
pub mod material;
pub mod report;

pub use error::{Error, Result};
pub use material::{Material, MaterialParams, TextureResult, UvMode};
