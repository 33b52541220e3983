//! The shared conventions of Material Picker (design.md §2): how images become
//! network inputs and how each raw tanh output `y ∈ [-1, 1]` is decoded. This
//! module is the one place that owns them; the renderer, synthetic data and
//! training code reuse (or mirror) these functions and constants, and
//! `weights-format.md` documents them.
//!
//! **Coordinate systems.**
//! - Image pixels: x right, y down, origin at the top-left corner of the
//!   top-left pixel; pixel `(row, col)` has its centre at `(col + 0.5, row + 0.5)`.
//! - Camera space (normals, view vectors, environment directions): +x right,
//!   +y up, +z towards the camera (OpenGL view space); the camera looks along −z.
//! - Environment maps: equirectangular, `H × W`; row 0 is straight up (+y), the
//!   centre column (`x = W/2`) is straight ahead (−z), `x = 3W/4` is right (+x),
//!   the left/right edges are behind (+z). See [`envmap_direction`].

pub use crate::display::{
    expose_rgb, soft_clip, srgb_encode, tone_map_rgb, SOFT_CLIP_KNEE, TONE_MAP_KEY,
};

use picker_tensor::Tensor;

use crate::error::{Error, Result};
use crate::nets::IrnOutput;

/// Name of the IRN head with the diffuse albedo ρd.
pub const DIFFUSE_ALBEDO: &str = "diffuse_albedo";
/// Name of the IRN head with the specular albedo ρs.
pub const SPECULAR_ALBEDO: &str = "specular_albedo";
/// Name of the IRN head with the normals.
pub const NORMALS: &str = "normals";
/// Name of the IRN head with the glossiness.
pub const GLOSSINESS: &str = "glossiness";
/// Name of the IRN head with the view vectors.
pub const VIEW_VECTOR: &str = "view_vector";
/// Name of the IRN head with the texture coordinates (u, v, t).
pub const UV: &str = "uv";
/// Name of the MSN output.
pub const SEGMENTATION: &str = "segmentation";
/// Name of the MSN's material embedding output (an MSN with 6 output channels).
pub const EMBEDDING: &str = "embedding";
/// Name of the EnvMap output.
pub const ENVMAP: &str = "envmap";
/// Name of the learned inpainter's output.
pub const INPAINTED: &str = "inpainted";
/// Mask-plane value of a known (observed) texel in the inpainter's input.
pub const INPAINT_KNOWN: f32 = 1.0;
/// Mask-plane value of an unknown texel in the inpainter's input; its texture
/// planes are 0 (mid-grey in `[-1, 1]`).
pub const INPAINT_UNKNOWN: f32 = -1.0;

/// Phong exponent of full glossiness: `n = 2^(PHONG_EXPONENT_LOG2_MAX · g)`, so `g ∈ [0, 1]` maps to `n ∈ [1, 8192]`.
pub const PHONG_EXPONENT_LOG2_MAX: f32 = 13.0;
/// Largest radiance an environment map encodes: `y = 1` decodes to this (y = −1 to 0).
pub const ENVMAP_MAX_RADIANCE: f32 = 1000.0;
/// Threshold on the decoded `t` channel above which a pixel counts as textured.
pub const TEXTURED_THRESHOLD: f32 = 0.5;

/// Network input value of an sRGB value `v ∈ [0, 1]`: `2v − 1`.
pub fn input_from_srgb(v: f32) -> f32 {
    2.0 * v - 1.0
}

/// Inverse of [`input_from_srgb`]: `(x + 1)/2`.
pub fn srgb_from_input(x: f32) -> f32 {
    (x + 1.0) / 2.0
}

/// Maps a tensor of sRGB values in `[0, 1]` to network inputs in place ([`input_from_srgb`]).
pub fn normalize_input(x: &mut Tensor) {
    x.data_mut()
        .iter_mut()
        .for_each(|v| *v = input_from_srgb(*v));
}

/// The learned inpainter's input `[N, C + 1, H, W]` from a texture of sRGB
/// values in `[0, 1]` (`srgb`: `[N, C, H, W]`) and the known mask (`known[row·W + col]`,
/// shared by the batch): planes `0..C` hold `2v − 1` ([`input_from_srgb`]) at known
/// texels and `0` at unknown ones, plane `C` holds [`INPAINT_KNOWN`] (`+1`) or
/// [`INPAINT_UNKNOWN`] (`−1`). Decode the output with [`srgb_from_input`].
pub fn inpaint_input(srgb: &Tensor, known: &[bool]) -> Result<Tensor> {
    let [n, c, h, w] = srgb.shape();
    let hw = h * w;
    if known.len() != hw {
        return Err(Error::Input {
            reason: format!(
                "inpainting mask has {} entries for a {h}x{w} texture (expected {hw})",
                known.len()
            ),
        });
    }
    let src = srgb.data();
    let mut out = vec![0.0f32; n * (c + 1) * hw];
    for b in 0..n {
        let (si, oi) = (b * c * hw, b * (c + 1) * hw);
        for ch in 0..c {
            for (i, &k) in known.iter().enumerate() {
                if k {
                    out[oi + ch * hw + i] = input_from_srgb(src[si + ch * hw + i]);
                }
            }
        }
        for (i, &k) in known.iter().enumerate() {
            out[oi + c * hw + i] = if k { INPAINT_KNOWN } else { INPAINT_UNKNOWN };
        }
    }
    Ok(Tensor::new([n, c + 1, h, w], out)?)
}

/// `(y + 1)/2`: the decoding of albedos, glossiness, segmentation colours and `uv` channels.
pub fn unit_from_tanh(y: f32) -> f32 {
    (y + 1.0) / 2.0
}

/// `2v − 1`: inverse of [`unit_from_tanh`] (training targets).
pub fn tanh_from_unit(v: f32) -> f32 {
    2.0 * v - 1.0
}

/// Albedo (diffuse or specular), **linear** RGB in `[0, 1]`: `(y + 1)/2`.
pub fn decode_albedo(y: f32) -> f32 {
    unit_from_tanh(y)
}

/// Glossiness `g = (y + 1)/2 ∈ [0, 1]`.
pub fn decode_glossiness(y: f32) -> f32 {
    unit_from_tanh(y)
}

/// Phong exponent of glossiness `g`: `n = 2^(13 g)` (g = 0 → 1, g = 1 → 8192).
pub fn phong_exponent(g: f32) -> f32 {
    (PHONG_EXPONENT_LOG2_MAX * g).exp2()
}

/// Inverse of [`phong_exponent`]: `g = log2(n)/13`, clamped to `[0, 1]` (n ≤ 1 → 0).
pub fn glossiness_from_exponent(n: f32) -> f32 {
    if n.is_nan() || n <= 1.0 {
        return 0.0;
    }
    (n.log2() / PHONG_EXPONENT_LOG2_MAX).min(1.0)
}

/// A unit vector from three raw outputs (normals, view vectors): the outputs
/// are renormalised; a zero vector decodes to `+z` (facing the camera).
pub fn decode_direction(y: [f32; 3]) -> [f32; 3] {
    let len = (y[0] * y[0] + y[1] * y[1] + y[2] * y[2]).sqrt();
    if len.is_nan() || len <= 1e-12 || len.is_infinite() {
        return [0.0, 0.0, 1.0];
    }
    [y[0] / len, y[1] / len, y[2] / len]
}

/// Image encoding of a unit vector: `(n + 1)/2` per component (the usual normal-map colours).
pub fn encode_direction_color(n: [f32; 3]) -> [f32; 3] {
    n.map(unit_from_tanh)
}

/// Inverse of [`encode_direction_color`], renormalised.
pub fn decode_direction_color(c: [f32; 3]) -> [f32; 3] {
    decode_direction(c.map(tanh_from_unit))
}

/// Wraps a texture coordinate into `[0, 1)`.
pub fn wrap_unit(u: f32) -> f32 {
    let f = u - u.floor();
    if f >= 1.0 || !f.is_finite() {
        0.0
    } else {
        f
    }
}

/// Decoded texture coordinates of a pixel.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TexCoord {
    /// u ∈ [0, 1), wrapped.
    pub u: f32,
    /// v ∈ [0, 1), wrapped.
    pub v: f32,
    /// t ∈ [0, 1]: 1 textured material, 0 single-colour material.
    pub t: f32,
}

impl TexCoord {
    /// Whether the pixel's material is textured (`t ≥ 0.5`).
    pub fn is_textured(&self) -> bool {
        self.t >= TEXTURED_THRESHOLD
    }
}

/// The `uv` head's channels `(u, v, t)`: each `(y + 1)/2`, with u and v wrapped to `[0, 1)`.
pub fn decode_uv(y: [f32; 3]) -> TexCoord {
    TexCoord {
        u: wrap_unit(unit_from_tanh(y[0])),
        v: wrap_unit(unit_from_tanh(y[1])),
        t: unit_from_tanh(y[2]),
    }
}

/// Segmentation colour (MSN), RGB in `[0, 1]`: `(y + 1)/2`.
pub fn decode_segmentation(y: f32) -> f32 {
    unit_from_tanh(y)
}

/// Environment-map radiance of a raw output: `L = expm1(ln(1 + 1000)·(y + 1)/2)`,
/// linear HDR, `y = −1 → 0`, `y = 1 → 1000` (log encoding: equal steps of y are equal
/// ratios of 1 + L). Inputs outside `[-1, 1]` are clamped.
pub fn decode_radiance(y: f32) -> f32 {
    let t = unit_from_tanh(y.clamp(-1.0, 1.0)) as f64;
    ((1.0 + ENVMAP_MAX_RADIANCE as f64).ln() * t).exp_m1() as f32
}

/// Inverse of [`decode_radiance`] (training targets): `y = 2·ln(1 + L)/ln(1001) − 1`,
/// with `L` clamped to `[0, 1000]`.
pub fn encode_radiance(l: f32) -> f32 {
    let l = if l.is_nan() {
        0.0
    } else {
        l.clamp(0.0, ENVMAP_MAX_RADIANCE)
    } as f64;
    (2.0 * l.ln_1p() / (1.0 + ENVMAP_MAX_RADIANCE as f64).ln() - 1.0) as f32
}

/// Latitude (radians, +π/2 = straight up) of the centre of environment-map row `row` of `h`.
pub fn envmap_row_latitude(row: usize, h: usize) -> f64 {
    std::f64::consts::FRAC_PI_2 - std::f64::consts::PI * (row as f64 + 0.5) / h as f64
}

/// Solid angle (steradians) of a pixel in row `row` of an `h × w` environment map:
/// the exact area of its latitude band, `(2π/w)·(sin(lat_top) − sin(lat_bottom))`.
///
/// It equals the thesis' `(2π/w)(π/h)·cos(latitude)` ([`pixel_solid_angle_thesis`])
/// up to a factor `sinc(π/2h) = 1 − (π/h)²/24 + …` (1.6·10⁻³ at h = 16, 4·10⁻⁵ at
/// h = 100), and the pixels of a map sum to exactly 4π.
pub fn pixel_solid_angle(row: usize, h: usize, w: usize) -> f64 {
    use std::f64::consts::PI;
    let top = PI / 2.0 - PI * row as f64 / h as f64;
    let bottom = PI / 2.0 - PI * (row as f64 + 1.0) / h as f64;
    2.0 * PI / w as f64 * (top.sin() - bottom.sin())
}

/// The thesis' pixel solid angle `(2π/w)(π/h)·cos(latitude of the row centre)`
/// (its fix of Sengupta et al.'s constant `4π·(π/2)/648`).
pub fn pixel_solid_angle_thesis(row: usize, h: usize, w: usize) -> f64 {
    use std::f64::consts::PI;
    2.0 * PI / w as f64 * (PI / h as f64) * envmap_row_latitude(row, h).cos()
}

/// The solid angle of every row of an `h × w` map ([`pixel_solid_angle`]).
pub fn envmap_row_solid_angles(h: usize, w: usize) -> Vec<f64> {
    (0..h).map(|r| pixel_solid_angle(r, h, w)).collect()
}

/// Camera-space unit direction of the continuous environment-map position `(x, y)`
/// (pixels; `x ∈ [0, w)` right, `y ∈ [0, h)` down, pixel centres at `+0.5`):
/// latitude `lat = π/2 − π·y/h`, longitude `φ = 2π·(x/w − 1/2)`,
/// `d = (cos lat · sin φ, sin lat, −cos lat · cos φ)`.
pub fn envmap_direction(x: f64, y: f64, h: usize, w: usize) -> [f64; 3] {
    use std::f64::consts::PI;
    let lat = PI / 2.0 - PI * y / h as f64;
    let phi = 2.0 * PI * (x / w as f64 - 0.5);
    [lat.cos() * phi.sin(), lat.sin(), -lat.cos() * phi.cos()]
}

/// Direction of the centre of pixel `(row, col)`.
pub fn envmap_pixel_direction(row: usize, col: usize, h: usize, w: usize) -> [f64; 3] {
    envmap_direction(col as f64 + 0.5, row as f64 + 0.5, h, w)
}

/// Inverse of [`envmap_direction`]: the continuous position `(x, y)` of direction `d`
/// (need not be unit length; zero maps to the straight-ahead centre). `x ∈ [0, w)`, `y ∈ [0, h]`.
pub fn envmap_position(d: [f64; 3], h: usize, w: usize) -> (f64, f64) {
    use std::f64::consts::PI;
    let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    if len.is_nan() || len <= 0.0 {
        return (w as f64 / 2.0, h as f64 / 2.0);
    }
    let lat = (d[1] / len).clamp(-1.0, 1.0).asin();
    let phi = d[0].atan2(-d[2]);
    let mut x = (phi / (2.0 * PI) + 0.5) * w as f64;
    if x >= w as f64 {
        x -= w as f64;
    }
    let y = (PI / 2.0 - lat) / PI * h as f64;
    (x.max(0.0), y)
}

/// The pixel `(row, col)` containing direction `d`.
///
/// # Panics
/// When the map has no pixels (`h` or `w` is 0).
pub fn envmap_pixel(d: [f64; 3], h: usize, w: usize) -> (usize, usize) {
    assert!(h > 0 && w > 0, "envmap_pixel: a {h}x{w} map has no pixels");
    let (x, y) = envmap_position(d, h, w);
    ((y as usize).min(h - 1), (x as usize).min(w - 1))
}

fn map_tensor(t: &Tensor, f: impl Fn(f32) -> f32) -> Tensor {
    let mut out = t.clone();
    out.data_mut().iter_mut().for_each(|v| *v = f(*v));
    out
}

/// Radiance of every value of a raw EnvMap output ([`decode_radiance`]).
pub fn decode_envmap(y: &Tensor) -> Tensor {
    map_tensor(y, decode_radiance)
}

/// Segmentation colours of a raw MSN output ([`decode_segmentation`]).
pub fn decode_segmentation_tensor(y: &Tensor) -> Tensor {
    map_tensor(y, decode_segmentation)
}

/// Normalises every pixel's 3-vector of a `[N, 3, H, W]` tensor ([`decode_direction`]).
pub fn decode_directions(y: &Tensor) -> Result<Tensor> {
    let mut out = y.clone();
    let [n, c, h, w] = y.shape();
    if c != 3 {
        return Err(Error::Output {
            name: "direction".into(),
            reason: format!("needs 3 channels, has {c}"),
        });
    }
    let hw = h * w;
    let d = out.data_mut();
    for b in 0..n {
        let o = b * 3 * hw;
        for i in 0..hw {
            let v = decode_direction([d[o + i], d[o + hw + i], d[o + 2 * hw + i]]);
            d[o + i] = v[0];
            d[o + hw + i] = v[1];
            d[o + 2 * hw + i] = v[2];
        }
    }
    Ok(out)
}

/// The render elements of the IRN, decoded (each `[N, c, H, W]`, f32).
#[derive(Clone, Debug)]
pub struct RenderElements {
    /// ρd, linear RGB in [0, 1].
    pub diffuse_albedo: Tensor,
    /// ρs, linear RGB in [0, 1].
    pub specular_albedo: Tensor,
    /// Glossiness g ∈ [0, 1] (one channel); Phong exponent via [`phong_exponent`].
    pub glossiness: Tensor,
    /// Unit normals, camera space.
    pub normals: Tensor,
    /// Unit vectors from the surface towards the camera, camera space.
    pub view_vector: Tensor,
    /// Texture coordinates: channels u, v ∈ [0, 1) (wrapped) and t ∈ [0, 1].
    pub uv: Tensor,
}

fn head<'a>(out: &'a IrnOutput, name: &str, channels: usize) -> Result<&'a Tensor> {
    let t = out.get(name).ok_or_else(|| Error::Output {
        name: name.to_string(),
        reason: format!(
            "the IRN has no such head (it has: {})",
            out.heads
                .iter()
                .map(|(n, _)| n.as_str())
                .collect::<Vec<_>>()
                .join(", ")
        ),
    })?;
    if t.c() != channels {
        return Err(Error::Output {
            name: name.to_string(),
            reason: format!("expected {channels} channels, found {}", t.c()),
        });
    }
    Ok(t)
}

impl RenderElements {
    /// Decodes the six standard heads of an IRN output; refuses a missing head or
    /// a head with the wrong channel count.
    pub fn from_irn(out: &IrnOutput) -> Result<Self> {
        let uv_raw = head(out, UV, 3)?;
        let mut uv = map_tensor(uv_raw, unit_from_tanh);
        let [n, _, h, w] = uv.shape();
        let hw = h * w;
        for b in 0..n {
            let o = b * 3 * hw;
            uv.data_mut()[o..o + 2 * hw]
                .iter_mut()
                .for_each(|v| *v = wrap_unit(*v));
        }
        Ok(Self {
            diffuse_albedo: map_tensor(head(out, DIFFUSE_ALBEDO, 3)?, decode_albedo),
            specular_albedo: map_tensor(head(out, SPECULAR_ALBEDO, 3)?, decode_albedo),
            glossiness: map_tensor(head(out, GLOSSINESS, 1)?, decode_glossiness),
            normals: decode_directions(head(out, NORMALS, 3)?)?,
            view_vector: decode_directions(head(out, VIEW_VECTOR, 3)?)?,
            uv,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use picker_tensor::Rng;

    #[test]
    fn inpaint_input_layout() {
        let srgb = Tensor::from_fn([1, 3, 1, 2], |_, c, _, x| 0.25 * (c + x) as f32);
        let x = inpaint_input(&srgb, &[true, false]).unwrap();
        assert_eq!(x.shape(), [1, 4, 1, 2]);
        // Plane-major: R, G, B (unknown texel zeroed), then the mask.
        assert_eq!(x.data(), [-1.0, 0.0, -0.5, 0.0, 0.0, 0.0, 1.0, -1.0]);
        assert!(inpaint_input(&srgb, &[true]).is_err());
    }

    #[test]
    fn unit_round_trips() {
        for i in 0..=100 {
            let v = i as f32 / 100.0;
            assert!((srgb_from_input(input_from_srgb(v)) - v).abs() < 1e-6);
            assert!((unit_from_tanh(tanh_from_unit(v)) - v).abs() < 1e-6);
            let g = v;
            assert!((glossiness_from_exponent(phong_exponent(g)) - g).abs() < 1e-5);
        }
        assert_eq!(phong_exponent(0.0), 1.0);
        assert_eq!(phong_exponent(1.0), 8192.0);
        assert_eq!(decode_albedo(-1.0), 0.0);
        assert_eq!(decode_albedo(1.0), 1.0);
        assert_eq!(glossiness_from_exponent(0.5), 0.0);
        assert_eq!(glossiness_from_exponent(1e9), 1.0);
    }

    #[test]
    fn radiance_round_trips() {
        assert_eq!(decode_radiance(-1.0), 0.0);
        assert!((decode_radiance(1.0) - 1000.0).abs() < 1e-3);
        for i in 0..=200 {
            let y = -1.0 + i as f32 / 100.0;
            let back = encode_radiance(decode_radiance(y));
            assert!((back - y).abs() < 1e-5, "{y} {back}");
        }
        for l in [0.0f32, 0.01, 0.5, 1.0, 7.0, 100.0, 999.0] {
            let back = decode_radiance(encode_radiance(l));
            assert!((back - l).abs() <= 1e-5 * (1.0 + l), "{l} {back}");
        }
        // Monotone.
        assert!(decode_radiance(0.1) > decode_radiance(0.0));
    }

    #[test]
    fn uv_wraps() {
        let t = decode_uv([1.0, -1.0, 1.0]);
        assert_eq!((t.u, t.v, t.t), (0.0, 0.0, 1.0));
        assert!(t.is_textured());
        let t = decode_uv([0.0, 0.5, -1.0]);
        assert_eq!((t.u, t.v), (0.5, 0.75));
        assert!(!t.is_textured());
        assert_eq!(wrap_unit(-0.25), 0.75);
        assert_eq!(wrap_unit(-1e-9), 0.0);
    }

    #[test]
    fn solid_angles_sum_to_4pi() {
        let four_pi = 4.0 * std::f64::consts::PI;
        for (h, w) in [(16, 32), (30, 40), (1, 1), (7, 3)] {
            let s: f64 = (0..h).map(|r| pixel_solid_angle(r, h, w) * w as f64).sum();
            assert!((s / four_pi - 1.0).abs() < 1e-12, "{h}x{w}: {s}");
        }
        for (h, w) in [(30, 40), (64, 128)] {
            let s: f64 = (0..h)
                .map(|r| pixel_solid_angle_thesis(r, h, w) * w as f64)
                .sum();
            assert!((s / four_pi - 1.0).abs() < 1e-3, "{h}x{w}: {s}");
        }
        // The two agree closely row by row.
        for r in 0..16 {
            let (a, b) = (
                pixel_solid_angle(r, 16, 32),
                pixel_solid_angle_thesis(r, 16, 32),
            );
            assert!((a / b - 1.0).abs() < 2e-3);
        }
    }

    #[test]
    fn envmap_axes_and_round_trip() {
        let close = |a: [f64; 3], b: [f64; 3]| (0..3).all(|i| (a[i] - b[i]).abs() < 1e-9);
        let (h, w) = (16, 32);
        assert!(close(envmap_direction(16.0, 8.0, h, w), [0.0, 0.0, -1.0])); // ahead
        assert!(close(envmap_direction(24.0, 8.0, h, w), [1.0, 0.0, 0.0])); // right
        assert!(close(envmap_direction(0.0, 8.0, h, w), [0.0, 0.0, 1.0])); // behind
        assert!(close(
            envmap_direction(5.0, 0.0, h, w).map(|v| (v * 1e6).round() / 1e6),
            [0.0, 1.0, 0.0]
        ));
        for row in 0..h {
            for col in 0..w {
                let d = envmap_pixel_direction(row, col, h, w);
                let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
                assert!((len - 1.0).abs() < 1e-12);
                assert_eq!(envmap_pixel(d, h, w), (row, col));
                let (x, y) = envmap_position(d, h, w);
                assert!(
                    (x - (col as f64 + 0.5)).abs() < 1e-9 && (y - (row as f64 + 0.5)).abs() < 1e-9
                );
            }
        }
    }

    #[test]
    fn render_elements_decode() {
        let mut rng = Rng::new(5);
        let heads = crate::config::STANDARD_HEADS
            .iter()
            .map(|&(n, c)| (n.to_string(), rng.tensor([2, c, 5, 7])))
            .collect();
        let out = IrnOutput { heads };
        let el = RenderElements::from_irn(&out).unwrap();
        for t in [&el.normals, &el.view_vector] {
            let hw = 35;
            for b in 0..2 {
                for i in 0..hw {
                    let img = t.image(b);
                    let l = (img[i].powi(2) + img[hw + i].powi(2) + img[2 * hw + i].powi(2)).sqrt();
                    assert!((l - 1.0).abs() < 1e-5);
                }
            }
        }
        assert!(el.uv.data().iter().all(|&v| (0.0..=1.0).contains(&v)));
        assert!(el.uv.image(0)[..70].iter().all(|&v| v < 1.0));
        assert!(el
            .glossiness
            .data()
            .iter()
            .all(|&v| (0.0..=1.0).contains(&v)));
        let mut out = out;
        out.heads.retain(|(n, _)| n != NORMALS);
        let e = RenderElements::from_irn(&out).unwrap_err().to_string();
        assert!(e.contains("normals"), "{e}");
    }

    #[test]
    fn directions_renormalise() {
        let d = decode_direction([0.0, 0.0, 0.0]);
        assert_eq!(d, [0.0, 0.0, 1.0]);
        let d = decode_direction([0.3, -0.4, 0.0]);
        assert!((d[0] - 0.6).abs() < 1e-6 && (d[1] + 0.8).abs() < 1e-6);
        let c = encode_direction_color(d);
        let back = decode_direction_color(c);
        assert!((0..3).all(|i| (back[i] - d[i]).abs() < 1e-6));
    }
}
