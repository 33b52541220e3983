//! Procedural indoor scenes with ground-truth render elements — the synthetic
//! training and test data of Material Picker (`picker synth`).
//!
//! A scene ([`scene::generate`]) is an axis-aligned room (floor, ceiling, four
//! walls with windows, doors or one open side), 2–10 furniture-like primitives
//! (boxes, tables, cylinders, spheres) resting on the floor or on boxes, 1–3
//! ceiling lamps, a sky ([`sky`]) and a material per surface (a tileable texture
//! from [`textures`] or one colour, a specular albedo and a glossiness), seen by
//! a random camera inside the room. [`render::render`] ray-casts it into the image
//! and every render element in the conventions of `picker_nets::conventions`;
//! [`output::write_scene`] writes them. Everything is a function of
//! `(seed, index)`: the same seed gives identical bytes on any thread count.
//!
//! ```no_run
//! let cfg = picker_synth::scene::SceneConfig::for_size(240, 320);
//! picker_synth::generate_scene_to(std::path::Path::new("out/scene_000000"), 7, 0, cfg, None, true)?;
//! # Ok::<(), picker_synth::Error>(())
//! ```

#![warn(missing_docs)]

pub mod assets;
pub mod contact;
pub mod geometry;
pub mod output;
pub mod render;
pub mod scene;
pub mod sky;
pub mod textures;

use std::path::{Path, PathBuf};

/// Version of the generator, recorded in every `scene.json`; bump it whenever
/// the output of a given seed changes (and re-bless the golden fixtures).
/// Version 2 added the camera's `views` and `view` to `scene.json` (`--views`);
/// with the default room views every image and element is that of version 1.
pub const GENERATOR_VERSION: &str = "2";

/// Errors of the generator.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// Loading an asset (photo texture, HDRI) failed.
    #[error(transparent)]
    Asset(#[from] assets::AssetError),
    /// Rendering or image I/O failed.
    #[error(transparent)]
    Render(#[from] picker_render::Error),
    /// Writing a file (through `picker_nets::write_atomic`) failed.
    #[error(transparent)]
    Write(#[from] picker_nets::Error),
    /// Creating a folder failed.
    #[error("cannot create {path}: {source}")]
    Io {
        /// The folder.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// Serialising JSON failed.
    #[error("encoding JSON: {0}")]
    Json(String),
}

/// `Result` with [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// The folder name of scene `index`: `scene_000123`.
pub fn scene_dir_name(index: u64) -> String {
    format!("scene_{index:06}")
}

/// Generates, renders and writes scene `index` of the run `seed` into `dir`.
/// Returns the rendered buffers.
pub fn generate_scene_to(
    dir: &Path,
    seed: u64,
    index: u64,
    config: scene::SceneConfig,
    assets: Option<&assets::AssetLibrary>,
    materials: bool,
) -> Result<render::Buffers> {
    let s = scene::generate(seed, index, config, assets)?;
    let b = render::render(&s);
    output::write_scene(dir, &s, &b, materials)?;
    Ok(b)
}
