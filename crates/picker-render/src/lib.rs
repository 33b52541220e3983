//! `picker-render`: the physically based Phong direct renderer of the thesis
//! (eq. 3.7; `design.md` §3) over equirectangular environment maps, plus the
//! image and environment-map files of Material Picker.
//!
//! A tour:
//! - [`EnvMap`]: linear HDR radiance in the conventions' equirectangular
//!   mapping (row 0 up, centre column straight ahead = −z, camera space):
//!   bilinear [`EnvMap::sample`], area-correct [`EnvMap::resample`],
//!   [`EnvMap::rotated`], EXR and Radiance `.hdr` files.
//! - [`shade_exact`]: eq. 3.7,
//!   `L = Σ_i (ρd/π + ρs(n+2)·max(0,V·R_i)ⁿ/2π) · L_i · max(0, ω_i·N) · ΔΩ_i`,
//!   by exact quadrature over every map pixel — the reference. `ΔΩ_i` is the
//!   exact band area [`conv::pixel_solid_angle`](picker_nets::conventions::pixel_solid_angle)
//!   (the thesis' `cos`-latitude formula differs by `sinc(π/2H)`).
//! - [`PrefilteredEnv`]: the fast path (irradiance grid + prefiltered Phong
//!   lobes), tested against `shade_exact`.
//! - [`rerender`] a photo from its render elements ([`ElementImages`]),
//!   [`preview_sphere`] / [`preview_tile`] of a material (exposed by [`preview_exposure`]),
//!   [`compare`] against a reference.
//! - [`io`]: planar `f32` images ↔ EXR / PNG, atomic writes.
//!
//! ```
//! use glam::Vec3;
//! use picker_render::{shade_exact, EnvMap, PhongMaterial, PrefilteredEnv};
//!
//! // The white furnace: a uniform unit environment and a white Lambertian surface.
//! let env = EnvMap::uniform(64, 32, Vec3::ONE);
//! let white = PhongMaterial { diffuse: Vec3::ONE, specular: Vec3::ZERO, exponent: 1.0 };
//! let l = shade_exact(&env, Vec3::new(0.0, 0.6, 0.8), Vec3::Z, &white);
//! assert!((l - Vec3::ONE).abs().max_element() < 2e-3);
//! let fast = PrefilteredEnv::new(&env).shade(Vec3::Y, Vec3::Z, &white);
//! assert!((fast - Vec3::ONE).abs().max_element() < 2e-3);
//! ```

#![warn(missing_docs)]

pub mod envmap;
pub mod error;
pub mod io;
pub mod phong;
pub mod prefilter;
pub mod render;

pub use envmap::EnvMap;
pub use error::{Error, Result};
pub use glam;
pub use io::Image;
pub use phong::{brdf, shade_exact, EnvQuadrature, PhongMaterial};
pub use prefilter::PrefilteredEnv;
pub use render::{
    compare, error_heatmap, preview_exposure, preview_sphere, preview_tile, rerender,
    rerender_with, sphere_normal, to_srgb, ElementImages, ErrorScore, Quality, Shader,
    PREVIEW_WHITE,
};
