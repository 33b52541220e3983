//! The extracted material: what every export writes.

use glam::Vec3;
use picker_render::io::Image;
use serde::Serialize;

/// How texture coordinates were obtained for the picked pixels.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum UvMode {
    /// The IRN's predicted (wrapped) texture coordinates.
    Net,
    /// A plane fitted to the predicted normals, rectified by a homography.
    Plane,
}

/// Phong parameters of a material (linear RGB albedos; `design.md` §3).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct MaterialParams {
    /// Mean diffuse albedo ρd over the material (linear RGB); for a textured
    /// material the mean colour of the final texture.
    pub diffuse: [f32; 3],
    /// Specular albedo ρs (linear RGB), a robust statistic (median) over the mask.
    pub specular: [f32; 3],
    /// Glossiness g ∈ `[0, 1]` (median over the mask).
    pub glossiness: f32,
    /// Phong exponent n = `picker_nets::conventions::phong_exponent(g)`.
    pub exponent: f32,
}

impl MaterialParams {
    /// As the renderer's material.
    pub fn phong(&self) -> picker_render::PhongMaterial {
        picker_render::PhongMaterial {
            diffuse: Vec3::from(self.diffuse),
            specular: Vec3::from(self.specular),
            exponent: self.exponent,
        }
    }
}

/// The texture of a textured material.
#[derive(Clone, Debug)]
pub struct TextureResult {
    /// The final tileable diffuse texture, linear RGB, `size × size`.
    pub texture: Image,
    /// The reprojected texture before inpainting (unknown texels 0), linear
    /// RGB, with the texels filled from another repeat of a repeating
    /// square ([`crate::period::fill_from_repeats`]), at the side it was
    /// made at ([`crate::pipeline::Diagnostics::texture_made_size`]: smaller
    /// than `texture` when a `--size` above the photo's density enlarged it).
    pub raw: Image,
    /// Per-texel coverage/confidence in `[0, 1]` (1 channel): 0 = never
    /// observed; a texel filled from another repeat has the repeats' tile's.
    pub coverage: Image,
    /// Fraction of texels observed (coverage > 0), the repeat-filled ones included.
    pub coverage_fraction: f64,
    /// Texels per unit of texture square at the photo's density (the
    /// automatic side, [`crate::pipeline::Diagnostics::texture_observed_size`]): the
    /// texture's own side unless `--size` chose another. It keeps the scale
    /// the material had in the photo (the preview sphere wraps the texture
    /// by it).
    pub observed_size: usize,
    /// The texture's size on the surface, metres `[along u, along v]`, when
    /// it is known: a quad's real size was given
    /// ([`crate::pipeline::Options::quad_size_m`]).
    pub size_m: Option<[f64; 2]>,
    /// How the coordinates were obtained.
    pub uv_mode: UvMode,
    /// Seam score of the final texture (wrap-edge difference vs interior).
    pub seam: picker_inpaint::SeamScore,
    /// Whether `seamless` was asked for, the inpainted texture's seams showed (seam ratio above
    /// [`picker_inpaint::SEAMLESS_MIN_RATIO`]) and it was replaced by its
    /// periodic component ([`picker_inpaint::make_seamless`]).
    pub seam_corrected: bool,
    /// Name of the inpainter used.
    pub inpainter: String,
}

/// One extracted material.
#[derive(Clone, Debug)]
pub struct Material {
    /// A short name (`material_0`, ...), unique within a run.
    pub name: String,
    /// The pick, in photo pixels (x right, y down), or `None` for `--all`.
    pub pick: Option<[u32; 2]>,
    /// Phong parameters.
    pub params: MaterialParams,
    /// Whether the material is textured (`t` flag of the UVs over the mask).
    pub textured: bool,
    /// The texture when textured.
    pub texture: Option<TextureResult>,
    /// The material's mask at photo resolution (1 channel, 1 inside, 0 outside).
    pub mask: Image,
    /// Fraction of the photo's pixels in the mask.
    pub area_fraction: f64,
    /// Re-render self-check: PSNR (dB, sRGB) of the masked region re-rendered
    /// from the extracted material against the photo.
    pub rerender_psnr: Option<f64>,
}
