//! `picker-extract`: from a photo's render elements and a pick to a material
//! an artist can use (design.md §4–5, `docs/contract-extract.md`).
//!
//! The chain, one module per step:
//! - [`photo`]: the photograph read from any supported file, oriented, checked
//!   ([`jpeg`]: a JPEG's coded blocks walked, so a damaged file is refused).
//! - [`resample`], [`guided`]: the network outputs at the working resolution
//!   are brought to the photo's resolution guided by the photo.
//! - [`smooth`], [`mask`]: the segmentation smoothed along the photo; pick → mask
//!   from its colour.
//! - [`plane`], [`period`], [`reproject`]: texture coordinates (predicted UVs or a
//!   rectified plane) and the scatter into the texture square with coverage;
//!   [`quad`]: a plane the user gives (a normal, a rectangle's corners).
//! - inpainting ([`picker_inpaint`]) fills the unobserved texels, tileably;
//!   [`level`] brings a texture taken from an untypical part of the material
//!   (a vignetted corner) to the material's level; [`equalize`] evens out
//!   broad light and dark patches on request.
//! - [`select`]: order statistics (quantiles, medians) of photo-resolution
//!   values in parallel, without sorting them.
//! - [`pipeline`]: the whole extraction, material parameters and the
//!   re-render self-check; [`export`], [`report`]: files; [`eval`]: metrics.

#![warn(missing_docs)]

pub mod equalize;
pub mod error;
pub mod eval;
pub mod export;
pub mod grain;
pub mod guided;
pub mod jpeg;
pub mod lens;
pub mod level;
pub mod lines;
pub mod mask;
pub mod material;
pub mod pattern;
pub mod period;
pub mod photo;
pub mod pipeline;
pub mod plane;
pub mod quad;
pub mod report;
pub mod reproject;
pub mod resample;
pub mod select;
pub mod shading;
pub mod smooth;
pub mod split;

pub use error::{Error, Result};
pub use material::{Material, MaterialParams, TextureResult, UvMode};
pub use pipeline::{extract, Inputs, LensChoice, Options, PassDisagreement, Prepared, UvChoice};
pub use quad::{Quad, UserPlane};
