//! Tileable diffuse-albedo textures for the synthetic scenes: procedural families (tiles,
//! bricks, planks/wood grain, checker, noise/marble, woven fabric) and, when the
//! [`AssetLibrary`] has them, real photographs made tileable.
//!
//! **Values.** Linear RGB albedo in `[0, 1]` (colours are drawn in HSV on the sRGB display
//! scale, where ranges of real materials are easy to state, and decoded to linear).
//!
//! **Tileable by construction.** Every procedural pattern lives on the torus `[0,1)²`: grids
//! have an integer number of cells (with row offsets that return to zero after the last row),
//! ring and vein patterns have integer frequencies, and the noise is gradient noise on a
//! lattice with an integer period (wrapped indices), so the texture wraps seamlessly in u and
//! v. [`Texture::seam`] measures it. Rotation and scale are left to the geometry's UV mapping;
//! the textures themselves are axis-aligned.
//!
//! **Texel ↔ (u, v).** Texel `(col, row)` has its centre at `u = (col + 0.5)/width`,
//! `v = (row + 0.5)/height` (row 0 at `v = 0`, the top of the image); [`Texture::sample`] is
//! bilinear with wrap-around.
//!
//! **Photos.** A photograph that already tiles (its wrap-around seam is no worse than its worst
//! interior neighbour line — the Sweet Home 3D textures do) is repeated an integer number of
//! times along its short side to be about square (aspect change ≤ ~20 %), cyclically shifted
//! by a random offset and resampled with wrap-around. Any other photo is cropped to a random
//! square of side `s`, made tileable by an *offset cross-fade* of width `b = s/8` on each axis
//! (texel `x < b` of the `s − b` wide result is `t·I(x) + (1 − t)·I(x + s − b)`,
//! `t = (x + 0.5)/b`, so the last texel `I(s − b − 1)` meets the first ≈ `I(s − b)`, its true
//! neighbour; the band loses some contrast) and resampled. A random exposure gain in
//! `[0.8, 1.2]` is applied, clamped to `[0, 1]`.

use std::path::Path;

use glam::Vec3;
use picker_tensor::Rng;
use serde::{Deserialize, Serialize};

use picker_render::io::srgb_decode;

use crate::assets::{Asset, AssetError, AssetLibrary};

/// A linear-RGB texture, row-major, tileable in u and v.
#[derive(Clone, Debug, PartialEq)]
pub struct Texture {
    /// Width in texels.
    pub width: usize,
    /// Height in texels.
    pub height: usize,
    /// `width · height` texels, row-major, linear RGB.
    pub data: Vec<Vec3>,
}

/// How well a texture wraps: mean absolute difference (per channel) across the wrap-around
/// edge versus the interior neighbour lines of the same direction.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct SeamScore {
    /// Mean |T(w−1, y) − T(0, y)| over rows.
    pub wrap_u: f32,
    /// Mean over interior column pairs of the per-pair mean |T(x+1, y) − T(x, y)|.
    pub mean_u: f32,
    /// The largest per-pair mean over interior column pairs.
    pub max_u: f32,
    /// Mean |T(x, h−1) − T(x, 0)| over columns.
    pub wrap_v: f32,
    /// Mean over interior row pairs.
    pub mean_v: f32,
    /// The largest interior row pair.
    pub max_v: f32,
}

/// `w / m`, infinite when only `m` is zero, 0 when both are.
fn ratio(w: f32, m: f32) -> f32 {
    if m > 0.0 {
        w / m
    } else if w > 0.0 {
        f32::INFINITY
    } else {
        0.0
    }
}

impl SeamScore {
    /// `max(wrap_u/max_u, wrap_v/max_v)`: ≤ 1 when the wrap-around edge is no more visible
    /// than the most visible interior line (e.g. a grout line); a random non-tileable image
    /// scores well above 1.
    pub fn worst_ratio(&self) -> f32 {
        ratio(self.wrap_u, self.max_u).max(ratio(self.wrap_v, self.max_v))
    }

    /// `max(wrap_u/mean_u, wrap_v/mean_v)`: about 1 for seamless noise-like textures.
    pub fn mean_ratio(&self) -> f32 {
        ratio(self.wrap_u, self.mean_u).max(ratio(self.wrap_v, self.mean_v))
    }
}

impl Texture {
    /// A texture of one colour (sizes of 0 are raised to 1: a texture has
    /// at least one texel).
    pub fn uniform(width: usize, height: usize, rgb: Vec3) -> Self {
        let (width, height) = (width.max(1), height.max(1));
        Self {
            width,
            height,
            data: vec![rgb; width * height],
        }
    }

    /// A texture whose texel `(col, row)` is `f(u, v)` at its centre (sizes
    /// of 0 are raised to 1).
    pub fn from_fn(width: usize, height: usize, f: impl Fn(f32, f32) -> Vec3) -> Self {
        let (width, height) = (width.max(1), height.max(1));
        let mut data = Vec::with_capacity(width * height);
        for row in 0..height {
            let v = (row as f32 + 0.5) / height as f32;
            for col in 0..width {
                data.push(f((col as f32 + 0.5) / width as f32, v));
            }
        }
        Self {
            width,
            height,
            data,
        }
    }

    /// Texel `(col, row)`, wrapped.
    ///
    /// # Panics
    /// When the texture has no texels (its fields were set by hand: the
    /// constructors make at least one).
    pub fn get(&self, col: isize, row: isize) -> Vec3 {
        assert!(
            self.width > 0 && self.height > 0,
            "Texture::get: the texture has no texels"
        );
        let c = col.rem_euclid(self.width as isize) as usize;
        let r = row.rem_euclid(self.height as isize) as usize;
        self.data[r * self.width + c]
    }

    /// Bilinear sample at `(u, v)` (any real values; wraps in both directions).
    pub fn sample(&self, u: f32, v: f32) -> Vec3 {
        if self.data.is_empty() {
            return Vec3::ZERO;
        }
        let x = u * self.width as f32 - 0.5;
        let y = v * self.height as f32 - 0.5;
        if !x.is_finite() || !y.is_finite() {
            return self.data[0];
        }
        let (x0, y0) = (x.floor(), y.floor());
        let (tx, ty) = (x - x0, y - y0);
        let (c, r) = (x0 as isize, y0 as isize);
        let top = self.get(c, r).lerp(self.get(c + 1, r), tx);
        let bottom = self.get(c, r + 1).lerp(self.get(c + 1, r + 1), tx);
        top.lerp(bottom, ty)
    }

    /// Planar channels `[R plane, G plane, B plane]`, each `height · width` (for image writers).
    pub fn to_planes(&self) -> Vec<f32> {
        let n = self.data.len();
        let mut out = vec![0.0; 3 * n];
        for (i, c) in self.data.iter().enumerate() {
            out[i] = c.x;
            out[n + i] = c.y;
            out[2 * n + i] = c.z;
        }
        out
    }

    /// The mean colour.
    pub fn mean(&self) -> Vec3 {
        let s: glam::DVec3 = self.data.iter().map(|c| c.as_dvec3()).sum();
        (s / self.data.len().max(1) as f64).as_vec3()
    }

    /// The seam metric ([`SeamScore`]).
    ///
    /// # Panics
    /// As [`Texture::get`].
    pub fn seam(&self) -> SeamScore {
        let (w, h) = (self.width, self.height);
        assert!(w > 0 && h > 0, "Texture::seam: the texture has no texels");
        let d = |a: Vec3, b: Vec3| ((a - b).abs().element_sum() / 3.0) as f64;
        let col_pair = |x0: usize, x1: usize| {
            (0..h)
                .map(|y| d(self.data[y * w + x0], self.data[y * w + x1]))
                .sum::<f64>()
                / h as f64
        };
        let row_pair = |y0: usize, y1: usize| {
            (0..w)
                .map(|x| d(self.data[y0 * w + x], self.data[y1 * w + x]))
                .sum::<f64>()
                / w as f64
        };
        let stats = |pairs: Vec<f64>| {
            let mean = pairs.iter().sum::<f64>() / pairs.len().max(1) as f64;
            let max = pairs.iter().cloned().fold(0.0, f64::max);
            (mean as f32, max as f32)
        };
        let (mean_u, max_u) = stats(
            (0..w.saturating_sub(1))
                .map(|x| col_pair(x, x + 1))
                .collect(),
        );
        let (mean_v, max_v) = stats(
            (0..h.saturating_sub(1))
                .map(|y| row_pair(y, y + 1))
                .collect(),
        );
        SeamScore {
            wrap_u: col_pair(w - 1, 0) as f32,
            mean_u,
            max_u,
            wrap_v: row_pair(h - 1, 0) as f32,
            mean_v,
            max_v,
        }
    }

    /// Resampled to `width × height` with wrap-around: bilinear, box-averaged over the
    /// footprint of each output texel when shrinking (sizes of 0 are raised
    /// to 1).
    pub fn resample_wrapped(&self, width: usize, height: usize) -> Texture {
        let (width, height) = (width.max(1), height.max(1));
        let kx = self.width.div_ceil(width).max(1);
        let ky = self.height.div_ceil(height).max(1);
        let norm = 1.0 / (kx * ky) as f32;
        let mut data = Vec::with_capacity(width * height);
        for row in 0..height {
            for col in 0..width {
                let mut acc = Vec3::ZERO;
                for b in 0..ky {
                    let v = (row as f32 + (b as f32 + 0.5) / ky as f32) / height as f32;
                    for a in 0..kx {
                        let u = (col as f32 + (a as f32 + 0.5) / kx as f32) / width as f32;
                        acc += self.sample(u, v);
                    }
                }
                data.push(acc * norm);
            }
        }
        Texture {
            width,
            height,
            data,
        }
    }
}

/// The kinds of texture [`random_texture`] makes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TextureFamily {
    /// Ceramic/stone tiles with grout: square, rectangular or offset layouts.
    Tiles,
    /// Bricks in running bond with mortar.
    Bricks,
    /// Wooden planks with staggered ends and ring/grain patterns.
    Planks,
    /// Two-colour checkerboard.
    Checker,
    /// fBm noise with a 2–3 colour ramp, marble and stone variants.
    Noise,
    /// Woven fabric: plain, twill or basket weave.
    Weave,
    /// A photograph from the asset library, made tileable.
    Photo,
}

impl TextureFamily {
    /// The procedural families (all but [`TextureFamily::Photo`]).
    pub const PROCEDURAL: [TextureFamily; 6] = [
        TextureFamily::Tiles,
        TextureFamily::Bricks,
        TextureFamily::Planks,
        TextureFamily::Checker,
        TextureFamily::Noise,
        TextureFamily::Weave,
    ];
}

/// A colour as stored in [`TextureInfo`]: linear RGB.
pub type Rgb = [f32; 3];

fn rgb(c: Vec3) -> Rgb {
    c.to_array()
}

/// Grid layouts of [`TextureFamily::Tiles`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TileLayout {
    /// Square tiles.
    Square,
    /// Rectangular tiles in a straight grid.
    Rectangular,
    /// Rectangular tiles, every row shifted by half a tile.
    Offset,
}

/// Weave patterns of [`TextureFamily::Weave`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum WeavePattern {
    /// Over one, under one.
    Plain,
    /// Diagonal twill: a warp thread floats over `over` of every `period` weft threads.
    Twill {
        /// Repeat in threads.
        period: usize,
        /// Weft threads a warp thread passes over per repeat.
        over: usize,
    },
    /// Plain weave of thread pairs.
    Basket,
}

/// Variants of [`TextureFamily::Noise`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum NoiseVariant {
    /// fBm mapped through a 2–3 colour ramp.
    Fbm,
    /// Sinusoidal veins warped by fBm.
    Marble,
    /// Turbulence (sum of |noise|), stone-like.
    Stone,
}

/// The parameters a texture was made with (the ground truth of texture extraction).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TextureParams {
    /// [`TextureFamily::Tiles`].
    Tiles {
        /// Grid layout.
        layout: TileLayout,
        /// Tiles across u.
        nx: usize,
        /// Tiles across v.
        ny: usize,
        /// Grout width in texture units (fraction of the texture's side).
        grout_width: f32,
        /// Grout colour.
        grout_color: Rgb,
        /// Mean tile colour.
        tile_color: Rgb,
        /// Std. dev. of the per-tile brightness factor.
        tile_jitter: f32,
        /// Amplitude of the in-tile noise.
        noise: f32,
    },
    /// [`TextureFamily::Bricks`].
    Bricks {
        /// Bricks per row.
        nx: usize,
        /// Rows.
        ny: usize,
        /// Mortar width in texture units.
        mortar_width: f32,
        /// Mortar colour.
        mortar_color: Rgb,
        /// Mean brick colour.
        brick_color: Rgb,
        /// Std. dev. of the per-brick brightness factor.
        brick_jitter: f32,
        /// Amplitude of the speckle noise.
        noise: f32,
    },
    /// [`TextureFamily::Planks`].
    Planks {
        /// Plank columns across u.
        planks: usize,
        /// Boards per column (ends staggered at random).
        boards_per_column: usize,
        /// Growth rings across one plank's width (integer: continuous wood wraps).
        rings: usize,
        /// Width of the dark gaps between boards, texture units (0 = none).
        gap_width: f32,
        /// Earlywood (light) colour.
        light_color: Rgb,
        /// Latewood (dark) colour.
        dark_color: Rgb,
        /// Std. dev. of the per-board brightness factor.
        board_jitter: f32,
    },
    /// [`TextureFamily::Checker`].
    Checker {
        /// Cells across u (even).
        nx: usize,
        /// Cells across v (even).
        ny: usize,
        /// First colour.
        color_a: Rgb,
        /// Second colour.
        color_b: Rgb,
        /// Amplitude of the noise.
        noise: f32,
    },
    /// [`TextureFamily::Noise`].
    Noise {
        /// Variant.
        variant: NoiseVariant,
        /// Lattice cells of the coarsest octave per texture side.
        period: usize,
        /// Octaves.
        octaves: usize,
        /// Amplitude ratio between octaves.
        gain: f32,
        /// Colour ramp (2 or 3 colours).
        colors: Vec<Rgb>,
    },
    /// [`TextureFamily::Weave`].
    Weave {
        /// Pattern.
        pattern: WeavePattern,
        /// Warp threads (running along v) across u.
        warp_threads: usize,
        /// Weft threads (running along u) across v.
        weft_threads: usize,
        /// Warp colour.
        warp_color: Rgb,
        /// Weft colour.
        weft_color: Rgb,
        /// Std. dev. of the per-thread brightness factor.
        thread_jitter: f32,
    },
    /// [`TextureFamily::Photo`].
    Photo {
        /// Source width and height in pixels.
        source_size: [usize; 2],
        /// Whether the photo already tiled (repeated and shifted) or was cross-faded.
        already_tileable: bool,
        /// Repeats along u and v of the source (tileable path) — `[1, 1]` when cross-faded.
        repeats: [usize; 2],
        /// Crop / shift origin in source pixels.
        origin: [usize; 2],
        /// Crop side in source pixels (cross-fade path), else 0.
        crop: usize,
        /// Exposure gain applied.
        gain: f32,
    },
}

/// What a texture is: family, parameters, phase offset, and for photos the source file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TextureInfo {
    /// The family.
    pub family: TextureFamily,
    /// Width = height in texels.
    pub size: usize,
    /// Offset `(du, dv)` by which the periodic pattern was shifted (procedural families).
    pub phase: [f32; 2],
    /// Family parameters.
    pub params: TextureParams,
    /// The photo file ([`TextureFamily::Photo`]).
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub source: Option<String>,
    /// The photo's licence file, if the library has one.
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub licence: Option<String>,
}

/// Probability that [`random_texture`] uses a photo when the library has some.
pub const PHOTO_PROBABILITY: f64 = 0.3;

/// A random tileable `size × size` texture: a photo with probability [`PHOTO_PROBABILITY`]
/// when `assets` has photos, else one of the procedural families. Errors only when a photo
/// cannot be read (the error names the file).
pub fn random_texture(
    rng: &mut Rng,
    size: usize,
    assets: Option<&AssetLibrary>,
) -> Result<(Texture, TextureInfo), AssetError> {
    let has_photos = assets.is_some_and(|a| !a.photos.is_empty());
    let family = if has_photos && rng.f64() < PHOTO_PROBABILITY {
        TextureFamily::Photo
    } else {
        let weights = [0.2, 0.15, 0.2, 0.1, 0.2, 0.15];
        TextureFamily::PROCEDURAL[pick_weighted(rng, &weights)]
    };
    random_texture_of(family, rng, size, assets)
}

/// A random texture of the given family. [`TextureFamily::Photo`] picks a photo of `assets`
/// (an empty or absent library falls back to a random procedural family).
pub fn random_texture_of(
    family: TextureFamily,
    rng: &mut Rng,
    size: usize,
    assets: Option<&AssetLibrary>,
) -> Result<(Texture, TextureInfo), AssetError> {
    let size = size.max(1);
    if family == TextureFamily::Photo {
        return match assets.filter(|a| !a.photos.is_empty()) {
            Some(lib) => {
                let asset = &lib.photos[rng.range(0, lib.photos.len() - 1)];
                photo_texture(rng, size, lib, asset)
            }
            None => {
                let f = TextureFamily::PROCEDURAL[rng.range(0, 5)];
                random_texture_of(f, rng, size, None)
            }
        };
    }
    let phase = [rng.uniform(0.0, 1.0), rng.uniform(0.0, 1.0)];
    let (pattern, params) = pattern_of(family, rng, size);
    let tex = Texture::from_fn(size, size, |u, v| {
        let c = pattern(wrap(u + phase[0]), wrap(v + phase[1]));
        c.clamp(Vec3::ZERO, Vec3::ONE)
    });
    Ok((
        tex,
        TextureInfo {
            family,
            size,
            phase,
            params,
            source: None,
            licence: None,
        },
    ))
}

/// The periodic pattern `(u, v) ∈ [0,1)² → colour` of a procedural family.
fn pattern_of(family: TextureFamily, rng: &mut Rng, size: usize) -> Pattern {
    match family {
        TextureFamily::Tiles => tiles(rng, size),
        TextureFamily::Bricks => bricks(rng, size),
        TextureFamily::Planks => planks(rng, size),
        TextureFamily::Checker => checker(rng, size),
        TextureFamily::Noise => noise(rng),
        TextureFamily::Weave => weave(rng, size),
        // Photos are not patterns; callers handle them first.
        TextureFamily::Photo => noise(rng),
    }
}

/// A tileable `size × size` texture from the photo `asset` of `lib` (see the module docs).
pub fn photo_texture(
    rng: &mut Rng,
    size: usize,
    lib: &AssetLibrary,
    asset: &Asset,
) -> Result<(Texture, TextureInfo), AssetError> {
    let src = lib.photo(asset)?;
    let (w, h) = (src.width, src.height);
    let gain = rng.uniform(0.8, 1.2);
    let tileable = w >= 4 && h >= 4 && src.seam().worst_ratio() <= 1.0;
    let (tex, params) = if tileable {
        let (rx, ry) = if w >= h {
            (1, ((w as f32 / h as f32).round() as usize).max(1))
        } else {
            (((h as f32 / w as f32).round() as usize).max(1), 1)
        };
        let origin = [rng.range(0, w - 1), rng.range(0, h - 1)];
        let (ow, oh) = (w * rx, h * ry);
        let big = Texture::from_fn(ow, oh, |u, v| {
            let col = (u * ow as f32) as isize + origin[0] as isize;
            let row = (v * oh as f32) as isize + origin[1] as isize;
            src.get(col, row)
        });
        (
            big.resample_wrapped(size, size),
            TextureParams::Photo {
                source_size: [w, h],
                already_tileable: true,
                repeats: [rx, ry],
                origin,
                crop: 0,
                gain,
            },
        )
    } else {
        let s = w.min(h);
        let origin = [rng.range(0, w - s), rng.range(0, h - s)];
        let crop = Texture::from_fn(s, s, |u, v| {
            let col = (u * s as f32) as usize + origin[0];
            let row = (v * s as f32) as usize + origin[1];
            src.data[row * w + col]
        });
        (
            cross_fade_tileable(&crop).resample_wrapped(size, size),
            TextureParams::Photo {
                source_size: [w, h],
                already_tileable: false,
                repeats: [1, 1],
                origin,
                crop: s,
                gain,
            },
        )
    };
    let tex = Texture {
        data: tex
            .data
            .into_iter()
            .map(|c| (c * gain).clamp(Vec3::ZERO, Vec3::ONE))
            .collect(),
        ..tex
    };
    let path_str = |p: &Path| p.to_string_lossy().into_owned();
    Ok((
        tex,
        TextureInfo {
            family: TextureFamily::Photo,
            size,
            phase: [0.0, 0.0],
            params,
            source: Some(path_str(&asset.path)),
            licence: asset.licence.as_deref().map(path_str),
        },
    ))
}

/// Makes a square image tileable by the offset cross-fade of the module docs: the result is
/// `(s − b) × (s − b)` with `b = max(s/8, 1)` (an image smaller than 4 texels is returned as is).
pub fn cross_fade_tileable(img: &Texture) -> Texture {
    let s = img.width.min(img.height);
    if s < 4 {
        return img.clone();
    }
    let b = (s / 8).max(1);
    let n = s - b;
    let blend = |i: usize| -> (usize, usize, f32) {
        if i < b {
            (i, i + n, (i as f32 + 0.5) / b as f32)
        } else {
            (i, i, 1.0)
        }
    };
    // Along u, then along v.
    let mut tmp = vec![Vec3::ZERO; n * s];
    for row in 0..s {
        for col in 0..n {
            let (a, c, t) = blend(col);
            tmp[row * n + col] =
                img.data[row * img.width + a] * t + img.data[row * img.width + c] * (1.0 - t);
        }
    }
    let mut data = vec![Vec3::ZERO; n * n];
    for row in 0..n {
        let (a, c, t) = blend(row);
        for col in 0..n {
            data[row * n + col] = tmp[a * n + col] * t + tmp[c * n + col] * (1.0 - t);
        }
    }
    Texture {
        width: n,
        height: n,
        data,
    }
}

// ---------------------------------------------------------------- helpers

fn wrap(x: f32) -> f32 {
    let f = x - x.floor();
    if f >= 1.0 {
        0.0
    } else {
        f
    }
}

fn pick_weighted(rng: &mut Rng, weights: &[f64]) -> usize {
    let total: f64 = weights.iter().sum();
    let mut x = rng.f64() * total;
    for (i, w) in weights.iter().enumerate() {
        if x < *w {
            return i;
        }
        x -= w;
    }
    weights.len() - 1
}

fn smoothstep(e0: f32, e1: f32, x: f32) -> f32 {
    let t = ((x - e0) / (e1 - e0)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// HSV on the sRGB display scale (`h` in turns) → linear RGB.
pub fn hsv_to_linear(h: f32, s: f32, v: f32) -> Vec3 {
    let h = wrap(h) * 6.0;
    let s = s.clamp(0.0, 1.0);
    let v = v.clamp(0.0, 1.0);
    let i = h.floor();
    let f = h - i;
    let (p, q, t) = (v * (1.0 - s), v * (1.0 - s * f), v * (1.0 - s * (1.0 - f)));
    let (r, g, b) = match i as i32 {
        0 => (v, t, p),
        1 => (q, v, p),
        2 => (p, v, t),
        3 => (p, q, v),
        4 => (t, p, v),
        _ => (v, p, q),
    };
    Vec3::new(srgb_decode(r), srgb_decode(g), srgb_decode(b))
}

/// A colour with hue, saturation and value (display scale) uniform in the given ranges.
fn color_in(rng: &mut Rng, hue: (f32, f32), sat: (f32, f32), val: (f32, f32)) -> Vec3 {
    let h = rng.uniform(hue.0, hue.1);
    let s = rng.uniform(sat.0, sat.1);
    let v = rng.uniform(val.0, val.1);
    hsv_to_linear(h, s, v)
}

/// Any material colour: uniform hue, mostly low saturation (as real surfaces are), value
/// from dark to bright.
fn any_color(rng: &mut Rng) -> Vec3 {
    let h = rng.uniform(0.0, 1.0);
    let s = rng.uniform(0.0, 1.0).powf(1.7) * 0.9;
    let v = rng.uniform(0.08, 0.97);
    hsv_to_linear(h, s, v)
}

/// `c` scaled by a brightness factor `1 + σ·N` and a per-channel tint of σ/3.
fn jitter(rng: &mut Rng, c: Vec3, sigma: f32) -> Vec3 {
    let k = (1.0 + sigma * rng.normal()).max(0.2);
    let tint = Vec3::new(rng.normal(), rng.normal(), rng.normal()) * (sigma / 3.0);
    (c * k * (Vec3::ONE + tint)).clamp(Vec3::ZERO, Vec3::ONE)
}

/// 2-D gradient noise on a lattice of `px × py` cells over the unit torus, so it is periodic
/// in u and v with period 1. Values roughly in `[-1, 1]`.
pub(crate) struct PeriodicNoise {
    px: usize,
    py: usize,
    grads: Vec<[f32; 2]>,
}

impl PeriodicNoise {
    pub(crate) fn new(rng: &mut Rng, px: usize, py: usize) -> Self {
        let (px, py) = (px.max(1), py.max(1));
        let grads = (0..px * py)
            .map(|_| {
                let a = rng.uniform(0.0, std::f32::consts::TAU);
                [a.cos(), a.sin()]
            })
            .collect();
        Self { px, py, grads }
    }

    pub(crate) fn eval(&self, u: f32, v: f32) -> f32 {
        let x = u * self.px as f32;
        let y = v * self.py as f32;
        let (x0, y0) = (x.floor(), y.floor());
        let (tx, ty) = (x - x0, y - y0);
        let ix = (x0 as i64).rem_euclid(self.px as i64) as usize;
        let iy = (y0 as i64).rem_euclid(self.py as i64) as usize;
        let ix1 = if ix + 1 == self.px { 0 } else { ix + 1 };
        let iy1 = if iy + 1 == self.py { 0 } else { iy + 1 };
        let g = |i: usize, j: usize, dx: f32, dy: f32| {
            let g = self.grads[j * self.px + i];
            g[0] * dx + g[1] * dy
        };
        let fade = |t: f32| t * t * t * (t * (t * 6.0 - 15.0) + 10.0);
        let (sx, sy) = (fade(tx), fade(ty));
        let a = g(ix, iy, tx, ty) + sx * (g(ix1, iy, tx - 1.0, ty) - g(ix, iy, tx, ty));
        let b = g(ix, iy1, tx, ty - 1.0)
            + sx * (g(ix1, iy1, tx - 1.0, ty - 1.0) - g(ix, iy1, tx, ty - 1.0));
        1.4 * (a + sy * (b - a))
    }
}

/// Fractal sum of [`PeriodicNoise`] octaves (periods doubling), normalised to about `[-1, 1]`.
pub(crate) struct Fbm {
    octaves: Vec<PeriodicNoise>,
    weights: Vec<f32>,
}

impl Fbm {
    pub(crate) fn new(rng: &mut Rng, px: usize, py: usize, octaves: usize, gain: f32) -> Self {
        let mut w = 1.0;
        let mut weights = Vec::new();
        let octs = (0..octaves.max(1))
            .map(|k| {
                weights.push(w);
                w *= gain;
                PeriodicNoise::new(rng, px << k, py << k)
            })
            .collect();
        let total: f32 = weights.iter().sum();
        weights.iter_mut().for_each(|w| *w /= total);
        Self {
            octaves: octs,
            weights,
        }
    }

    pub(crate) fn eval(&self, u: f32, v: f32) -> f32 {
        self.octaves
            .iter()
            .zip(&self.weights)
            .map(|(n, w)| w * n.eval(u, v))
            .sum()
    }

    fn turbulence(&self, u: f32, v: f32) -> f32 {
        self.octaves
            .iter()
            .zip(&self.weights)
            .map(|(n, w)| w * n.eval(u, v).abs())
            .sum()
    }
}

/// A grid of `nx × ny` cells on the torus; row `r` is shifted by `offset·r` cells
/// (`offset·ny` must be an integer for the grid to wrap).
struct Grid {
    nx: usize,
    ny: usize,
    offset: f32,
}

struct Cell {
    ix: usize,
    iy: usize,
    /// Distance to the cell's nearest edge, in texture units.
    edge: f32,
}

impl Grid {
    fn locate(&self, u: f32, v: f32) -> Cell {
        let y = v * self.ny as f32;
        let iyf = y.floor();
        let ly = y - iyf;
        let iy = (iyf as i64).rem_euclid(self.ny as i64) as usize;
        let x = u * self.nx as f32 - self.offset * iy as f32;
        let ixf = x.floor();
        let lx = x - ixf;
        let ix = (ixf as i64).rem_euclid(self.nx as i64) as usize;
        let ex = lx.min(1.0 - lx) / self.nx as f32;
        let ey = ly.min(1.0 - ly) / self.ny as f32;
        Cell {
            ix,
            iy,
            edge: ex.min(ey),
        }
    }
}

type Pattern = (Box<dyn Fn(f32, f32) -> Vec3>, TextureParams);

// ---------------------------------------------------------------- families

fn tiles(rng: &mut Rng, size: usize) -> Pattern {
    let layout = [
        TileLayout::Square,
        TileLayout::Rectangular,
        TileLayout::Offset,
    ][pick_weighted(rng, &[0.5, 0.25, 0.25])];
    let (nx, ny, offset) = match layout {
        TileLayout::Square => {
            let n = rng.range(2, 8);
            (n, n, 0.0)
        }
        TileLayout::Rectangular => {
            let n = rng.range(1, 5);
            let k = rng.range(2, 3);
            if rng.f64() < 0.5 {
                (n, n * k, 0.0)
            } else {
                (n * k, n, 0.0)
            }
        }
        TileLayout::Offset => {
            let n = rng.range(1, 4);
            (n, 2 * n * rng.range(1, 2), 0.5)
        }
    };
    let grid = Grid { nx, ny, offset };
    let cell = 1.0 / nx.max(ny) as f32;
    let grout_width = cell * rng.uniform(0.02, 0.12);
    let tile_color = any_color(rng);
    let grout_color = if rng.f64() < 0.7 {
        color_in(rng, (0.05, 0.15), (0.0, 0.15), (0.35, 0.9))
    } else {
        color_in(rng, (0.0, 1.0), (0.0, 0.3), (0.1, 0.5))
    };
    let tile_jitter = rng.uniform(0.0, 0.15);
    let cells: Vec<Vec3> = (0..nx * ny)
        .map(|_| jitter(rng, tile_color, tile_jitter))
        .collect();
    let noise = rng.uniform(0.0, 0.12);
    let fbm = Fbm::new(rng, 4 * nx.max(ny), 4 * nx.max(ny), 3, 0.5);
    let bevel = grout_width * rng.uniform(0.3, 1.5);
    let aa = 1.0 / size as f32;
    let params = TextureParams::Tiles {
        layout,
        nx,
        ny,
        grout_width,
        grout_color: rgb(grout_color),
        tile_color: rgb(tile_color),
        tile_jitter,
        noise,
    };
    let f = move |u: f32, v: f32| {
        let c = grid.locate(u, v);
        let n = fbm.eval(u, v);
        let tile = cells[c.iy * nx + c.ix] * (1.0 + noise * n);
        let shade = 0.85 + 0.15 * smoothstep(0.0, bevel, c.edge - grout_width / 2.0);
        let grout = grout_color * (1.0 + 0.1 * n);
        grout.lerp(tile * shade, joint_mask(c.edge, grout_width, aa))
    };
    (Box::new(f), params)
}

/// 0 inside a joint (grout, mortar) of `width` centred on a cell edge, 1 on
/// the cell, anti-aliased over `aa`; `edge` is the distance to the nearest edge.
fn joint_mask(edge: f32, width: f32, aa: f32) -> f32 {
    smoothstep(width / 2.0 - aa / 2.0, width / 2.0 + aa / 2.0, edge)
}

fn bricks(rng: &mut Rng, size: usize) -> Pattern {
    let nx = rng.range(2, 6);
    let aspect = rng.uniform(2.0, 4.0);
    let ny = (((nx as f32 * aspect) / 2.0).round() as usize).max(1) * 2;
    let grid = Grid {
        nx,
        ny,
        offset: 0.5,
    };
    let mortar_width = rng.uniform(0.08, 0.3) / ny as f32;
    let brick_color = match pick_weighted(rng, &[0.5, 0.2, 0.2, 0.1]) {
        0 => color_in(rng, (0.98, 1.06), (0.4, 0.8), (0.3, 0.75)),
        1 => color_in(rng, (0.06, 0.13), (0.25, 0.6), (0.45, 0.85)),
        2 => color_in(rng, (0.0, 1.0), (0.0, 0.1), (0.4, 0.95)),
        _ => color_in(rng, (0.0, 0.1), (0.1, 0.5), (0.12, 0.3)),
    };
    let mortar_color = color_in(rng, (0.05, 0.15), (0.0, 0.2), (0.3, 0.85));
    let brick_jitter = rng.uniform(0.05, 0.2);
    let cells: Vec<Vec3> = (0..nx * ny)
        .map(|_| jitter(rng, brick_color, brick_jitter))
        .collect();
    let noise = rng.uniform(0.05, 0.25);
    let coarse = Fbm::new(rng, 2 * nx, 2 * nx, 2, 0.5);
    let speckle = PeriodicNoise::new(rng, 64 * nx, 64 * nx);
    let aa = 1.0 / size as f32;
    let params = TextureParams::Bricks {
        nx,
        ny,
        mortar_width,
        mortar_color: rgb(mortar_color),
        brick_color: rgb(brick_color),
        brick_jitter,
        noise,
    };
    let f = move |u: f32, v: f32| {
        let c = grid.locate(u, v);
        let s = speckle.eval(u, v);
        let n = coarse.eval(u, v);
        let brick = cells[c.iy * nx + c.ix] * (1.0 + noise * (0.6 * n + 0.6 * s));
        let edge_dark = 0.8 + 0.2 * smoothstep(0.0, mortar_width, c.edge - mortar_width / 2.0);
        let mortar = mortar_color * (0.85 + 0.3 * (0.5 + 0.5 * s)) * (1.0 + 0.1 * n);
        mortar.lerp(brick * edge_dark, joint_mask(c.edge, mortar_width, aa))
    };
    (Box::new(f), params)
}

fn planks(rng: &mut Rng, size: usize) -> Pattern {
    let planks = rng.range(1, 8);
    // Boards at least about twice as long as wide.
    let boards_per_column = rng.range(1, (planks / 2).clamp(1, 3));
    let rings = rng.range(2, 12);
    let gap_width = if planks == 1 && boards_per_column == 1 || rng.f64() < 0.15 {
        0.0
    } else {
        rng.uniform(0.002, 0.008)
    };
    let light = if rng.f64() < 0.85 {
        color_in(rng, (0.04, 0.12), (0.3, 0.75), (0.3, 0.9))
    } else {
        color_in(rng, (0.0, 1.0), (0.0, 0.15), (0.2, 0.9))
    };
    let dark = light * rng.uniform(0.35, 0.8);
    let board_jitter = rng.uniform(0.03, 0.2);
    // Per column: sorted cut positions in v; per board: colour factor and ring offset.
    let cuts: Vec<Vec<f32>> = (0..planks)
        .map(|_| {
            let start = rng.uniform(0.0, 1.0);
            let mut c: Vec<f32> = (0..boards_per_column)
                .map(|k| {
                    wrap(start + (k as f32 + rng.uniform(0.2, 0.8)) / boards_per_column as f32)
                })
                .collect();
            c.sort_by(f32::total_cmp);
            c
        })
        .collect();
    let boards: Vec<(f32, f32, f32)> = (0..planks * boards_per_column)
        .map(|_| {
            (
                (1.0 + board_jitter * rng.normal()).max(0.3),
                rng.uniform(0.0, 1.0),
                rng.uniform(0.0, 1.0),
            )
        })
        .collect();
    let warp = Fbm::new(rng, 2 * planks, 2, 3, 0.5);
    let warp_amount = rng.uniform(0.1, 0.6);
    let streaks = PeriodicNoise::new(rng, 48 * planks.max(2), 4);
    let fine = PeriodicNoise::new(rng, 96 * planks.max(2), 12);
    let sharp = rng.uniform(1.5, 4.0);
    let aa = 1.0 / size as f32;
    let params = TextureParams::Planks {
        planks,
        boards_per_column,
        rings,
        gap_width,
        light_color: rgb(light),
        dark_color: rgb(dark),
        board_jitter,
    };
    let f = move |u: f32, v: f32| {
        let x = u * planks as f32;
        let col = (x.floor() as usize).min(planks - 1);
        let lx = x - col as f32;
        let cut = &cuts[col];
        let seg = cut.iter().filter(|&&c| c <= v).count() % boards_per_column;
        let (k, ring_offset, grain_offset) = boards[col * boards_per_column + seg];
        // Rings across the plank width (integer count: wraps when there are no gaps).
        let w = warp.eval(u, wrap(v + grain_offset));
        let t = wrap(lx * rings as f32 + ring_offset + warp_amount * w);
        let ring = (1.0 - (2.0 * t - 1.0).abs()).powf(sharp);
        let grain = 0.08 * streaks.eval(u, v) + 0.05 * fine.eval(u, v);
        let c = light.lerp(dark, ring.clamp(0.0, 1.0)) * (k * (1.0 + grain));
        if gap_width <= 0.0 {
            return c;
        }
        // Distance to the plank sides and to the board ends, texture units.
        let dx = lx.min(1.0 - lx) / planks as f32;
        let dy = cut
            .iter()
            .map(|&c| {
                let d = (v - c).abs();
                d.min(1.0 - d)
            })
            .fold(f32::INFINITY, f32::min);
        let d = if planks == 1 { dy } else { dx.min(dy) };
        let gap = smoothstep(gap_width / 2.0 - aa / 2.0, gap_width / 2.0 + aa / 2.0, d);
        (dark * 0.35).lerp(c, gap)
    };
    (Box::new(f), params)
}

fn checker(rng: &mut Rng, size: usize) -> Pattern {
    let nx = 2 * rng.range(1, 8);
    let ny = if rng.f64() < 0.75 {
        nx
    } else {
        2 * rng.range(1, 8)
    };
    let color_a = any_color(rng);
    let color_b = if rng.f64() < 0.5 {
        // Classic contrast: light against dark.
        let v = rng.uniform(0.05, 0.3);
        let h = rng.uniform(0.0, 1.0);
        let s = rng.uniform(0.0, 0.5);
        let light = hsv_to_linear(h, s * 0.3, 1.0 - v);
        if color_a.element_sum() > 1.0 {
            hsv_to_linear(h, s, v)
        } else {
            light
        }
    } else {
        any_color(rng)
    };
    let noise = rng.uniform(0.0, 0.08);
    let fbm = Fbm::new(rng, 8, 8, 3, 0.5);
    let aa = 1.0 / size as f32;
    let params = TextureParams::Checker {
        nx,
        ny,
        color_a: rgb(color_a),
        color_b: rgb(color_b),
        noise,
    };
    let f = move |u: f32, v: f32| {
        let x = u * nx as f32;
        let y = v * ny as f32;
        let (ix, iy) = (x.floor() as i64, y.floor() as i64);
        let parity = (ix + iy).rem_euclid(2) == 0;
        // Soft edge (one texel) for a clean, alias-free boundary.
        let ex = (x - x.round()).abs() / nx as f32;
        let ey = (y - y.round()).abs() / ny as f32;
        let t = smoothstep(0.0, aa, ex.min(ey));
        let (own, other) = if parity {
            (color_a, color_b)
        } else {
            (color_b, color_a)
        };
        (own * t + (own + other) * 0.5 * (1.0 - t)) * (1.0 + noise * fbm.eval(u, v))
    };
    (Box::new(f), params)
}

fn ramp(colors: &[Vec3], t: f32) -> Vec3 {
    let t = t.clamp(0.0, 1.0) * (colors.len() - 1) as f32;
    let i = (t.floor() as usize).min(colors.len() - 2);
    colors[i].lerp(colors[i + 1], t - i as f32)
}

fn noise(rng: &mut Rng) -> Pattern {
    let variant = [NoiseVariant::Fbm, NoiseVariant::Marble, NoiseVariant::Stone]
        [pick_weighted(rng, &[0.4, 0.3, 0.3])];
    let period = rng.range(2, 8);
    let octaves = rng.range(3, 5);
    let gain = rng.uniform(0.4, 0.65);
    let ncolors = rng.range(2, 3);
    let base = any_color(rng);
    let mut colors = vec![base];
    for _ in 1..ncolors {
        let c = if rng.f64() < 0.6 {
            // A related shade: same hue family, different brightness.
            jitter(rng, base, 0.1) * rng.uniform(0.3, 1.6)
        } else {
            any_color(rng)
        };
        colors.push(c.clamp(Vec3::ZERO, Vec3::ONE));
    }
    let fbm = Fbm::new(rng, period, period, octaves, gain);
    let contrast = rng.uniform(1.5, 4.0);
    let kx = rng.range(0, 3) as f32;
    let ky = if kx == 0.0 {
        rng.range(1, 3) as f32
    } else {
        rng.range(0, 3) as f32
    };
    let warp = rng.uniform(1.0, 4.0);
    let vein_power = rng.uniform(4.0, 25.0);
    let params = TextureParams::Noise {
        variant,
        period,
        octaves,
        gain,
        colors: colors.iter().map(|c| rgb(*c)).collect(),
    };
    let f: Box<dyn Fn(f32, f32) -> Vec3> = match variant {
        NoiseVariant::Fbm => {
            Box::new(move |u, v| ramp(&colors, 0.5 + 0.5 * contrast * fbm.eval(u, v)))
        }
        NoiseVariant::Marble => Box::new(move |u, v| {
            let n = fbm.eval(u, v);
            let phase = std::f32::consts::TAU * (kx * u + ky * v) + warp * std::f32::consts::PI * n;
            let vein = (1.0 - phase.sin().abs()).powf(vein_power);
            let body = colors[0] * (1.0 + 0.15 * n);
            body.lerp(colors[colors.len() - 1], vein)
        }),
        NoiseVariant::Stone => {
            Box::new(move |u, v| ramp(&colors, (contrast * 0.8 * fbm.turbulence(u, v)).min(1.0)))
        }
    };
    (f, params)
}

fn weave(rng: &mut Rng, size: usize) -> Pattern {
    let pattern = match pick_weighted(rng, &[0.4, 0.4, 0.2]) {
        0 => WeavePattern::Plain,
        1 => {
            let period = rng.range(3, 4);
            WeavePattern::Twill {
                period,
                over: rng.range(1, period - 1),
            }
        }
        _ => WeavePattern::Basket,
    };
    let repeat = match pattern {
        WeavePattern::Plain => 2,
        WeavePattern::Twill { period, .. } => period,
        WeavePattern::Basket => 4,
    };
    // Threads at least ~3 texels wide.
    let max_threads = (size / 3).max(repeat);
    let warp_threads = (rng.range(8, 64).min(max_threads) / repeat).max(1) * repeat;
    let weft_threads = if rng.f64() < 0.6 {
        warp_threads
    } else {
        (rng.range(8, 64).min(max_threads) / repeat).max(1) * repeat
    };
    let warp_color = any_color(rng);
    let weft_color = if rng.f64() < 0.5 {
        jitter(rng, warp_color, 0.1)
    } else {
        any_color(rng)
    };
    let thread_jitter = rng.uniform(0.0, 0.12);
    let warp_cols: Vec<Vec3> = (0..warp_threads)
        .map(|_| jitter(rng, warp_color, thread_jitter))
        .collect();
    let weft_cols: Vec<Vec3> = (0..weft_threads)
        .map(|_| jitter(rng, weft_color, thread_jitter))
        .collect();
    let fibres = PeriodicNoise::new(rng, 4 * warp_threads, 4 * weft_threads);
    let mottle = Fbm::new(rng, 4, 4, 2, 0.5);
    let gap = rng.uniform(0.5, 0.9);
    let params = TextureParams::Weave {
        pattern,
        warp_threads,
        weft_threads,
        warp_color: rgb(warp_color),
        weft_color: rgb(weft_color),
        thread_jitter,
    };
    let f = move |u: f32, v: f32| {
        let x = u * warp_threads as f32;
        let y = v * weft_threads as f32;
        let i = (x.floor() as usize).min(warp_threads - 1);
        let j = (y.floor() as usize).min(weft_threads - 1);
        let (lx, ly) = (x - i as f32, y - j as f32);
        let warp_on_top = match pattern {
            WeavePattern::Plain => (i + j).is_multiple_of(2),
            WeavePattern::Twill { period, over } => (i + j) % period < over,
            WeavePattern::Basket => (i / 2 + j / 2).is_multiple_of(2),
        };
        // Across a thread: rounded profile; along it: dips where it goes under.
        let (across, along, c) = if warp_on_top {
            (lx, ly, warp_cols[i])
        } else {
            (ly, lx, weft_cols[j])
        };
        let profile = (std::f32::consts::PI * across).sin().max(0.0).powf(0.6);
        let dip = (std::f32::consts::PI * along).sin().max(0.0).powf(0.25);
        let shade = (1.0 - gap) + gap * profile * (0.75 + 0.25 * dip);
        let f = 1.0 + 0.1 * fibres.eval(u, v) + 0.05 * mottle.eval(u, v);
        c * shade * f
    };
    (Box::new(f), params)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn zero_sizes_are_raised_to_one_texel() {
        let c = Vec3::new(0.1, 0.2, 0.3);
        let t = Texture::uniform(0, 0, c);
        assert_eq!((t.width, t.height), (1, 1));
        assert_eq!(t.get(5, -3), c);
        assert_eq!(Texture::from_fn(0, 3, |_, _| c).width, 1);
        let r = Texture::uniform(4, 4, c).resample_wrapped(0, 4);
        assert_eq!((r.width, r.height), (1, 4));
        let _ = t.seam(); // a 1×1 texture has a seam score, without panicking
    }

    const SIZE: usize = 64;

    fn make(family: TextureFamily, seed: u64) -> (Texture, TextureInfo) {
        random_texture_of(family, &mut Rng::new(seed), SIZE, None).expect("procedural")
    }

    #[test]
    fn same_seed_same_texture() {
        for family in TextureFamily::PROCEDURAL {
            let (a, ia) = make(family, 11);
            let (b, ib) = make(family, 11);
            assert_eq!(a, b, "{family:?}");
            assert_eq!(ia, ib, "{family:?}");
            let (c, _) = make(family, 12);
            assert_ne!(a, c, "{family:?}: different seeds gave the same texture");
        }
    }

    #[test]
    fn values_are_linear_albedos_in_unit_range() {
        for family in TextureFamily::PROCEDURAL {
            for seed in 0..6 {
                let (t, info) = make(family, seed);
                assert_eq!(info.family, family);
                assert_eq!((t.width, t.height, t.data.len()), (SIZE, SIZE, SIZE * SIZE));
                for c in &t.data {
                    assert!(
                        c.is_finite() && c.min_element() >= 0.0 && c.max_element() <= 1.0,
                        "{family:?} seed {seed}: {c}"
                    );
                }
                let m = t.mean();
                let var = t
                    .data
                    .iter()
                    .map(|c| (*c - m).length_squared())
                    .sum::<f32>();
                assert!(var > 0.0, "{family:?} seed {seed} is flat");
                serde_json::to_string(&info).expect("info serialises");
            }
        }
    }

    /// The pattern lives on the torus: shifting its phase by half a texture gives the
    /// texture rolled by half, up to rounding at hard edges.
    #[test]
    fn patterns_are_periodic() {
        for family in TextureFamily::PROCEDURAL {
            for seed in 0..4 {
                let (t, _) = make(family, seed);
                // Rebuild the same pattern and evaluate it half a period further.
                let mut rng = Rng::new(seed);
                let phase = [rng.uniform(0.0, 1.0), rng.uniform(0.0, 1.0)];
                let (pattern, _) = pattern_of(family, &mut rng, SIZE);
                let shifted = Texture::from_fn(SIZE, SIZE, |u, v| {
                    pattern(wrap(u + phase[0] + 0.5), wrap(v + phase[1] + 0.5))
                        .clamp(Vec3::ZERO, Vec3::ONE)
                });
                let h = SIZE as isize / 2;
                let mut diff = 0.0;
                for row in 0..SIZE as isize {
                    for col in 0..SIZE as isize {
                        diff += (shifted.get(col, row) - t.get(col + h, row + h))
                            .abs()
                            .max_element();
                    }
                }
                let mean = diff / (SIZE * SIZE) as f32;
                assert!(mean < 2e-3, "{family:?} seed {seed}: mean |diff| {mean}");
            }
        }
    }

    #[test]
    fn seams_are_no_worse_than_interior_lines() {
        for family in TextureFamily::PROCEDURAL {
            let mut ratios: Vec<f32> = (0..8)
                .map(|seed| make(family, seed).0.seam().worst_ratio())
                .collect();
            ratios.sort_by(f32::total_cmp);
            let (median, max) = (ratios[ratios.len() / 2], ratios[ratios.len() - 1]);
            eprintln!("{family:?}: seam worst-ratio median {median:.3} max {max:.3}");
            assert!(median <= 1.0 && max <= 2.0, "{family:?}: {ratios:?}");
        }
    }

    #[test]
    fn seam_metric_flags_non_tileable_images_and_cross_fade_fixes_them() {
        // A smooth, non-periodic image: a ramp plus a diagonal wave.
        let img = Texture::from_fn(80, 80, |u, v| {
            Vec3::splat(0.2 + 0.5 * u * v) + Vec3::new(0.1 * (9.0 * u + 4.0 * v).sin(), 0.0, 0.1)
        });
        let before = img.seam().worst_ratio();
        assert!(before > 5.0, "ramp seam ratio {before}");
        let tiled = cross_fade_tileable(&img);
        assert_eq!((tiled.width, tiled.height), (70, 70));
        let after = tiled.seam().worst_ratio();
        assert!(after <= 1.1, "cross-faded seam ratio {after}");
        let resized = tiled.resample_wrapped(32, 32);
        assert!(resized.seam().worst_ratio() <= 1.1);
    }

    #[test]
    fn sample_is_bilinear_and_wraps() {
        let t = Texture::from_fn(4, 2, |u, v| Vec3::new(u, v, 0.0));
        // Texel centres are exact.
        assert_eq!(t.sample(0.125, 0.25), t.get(0, 0));
        assert_eq!(t.sample(0.875 + 3.0, 0.75 - 2.0), t.get(3, 1));
        // Halfway between the last and the first column: their average.
        let m = t.sample(1.0, 0.25);
        assert!((m - (t.get(3, 0) + t.get(0, 0)) * 0.5).length() < 1e-6);
        assert_eq!(t.to_planes().len(), 24);
    }

    #[test]
    fn photo_family_without_assets_falls_back_to_procedural() {
        let (_, info) =
            random_texture_of(TextureFamily::Photo, &mut Rng::new(3), 16, None).unwrap();
        assert_ne!(info.family, TextureFamily::Photo);
        let (_, info) = random_texture(&mut Rng::new(3), 16, Some(&AssetLibrary::empty())).unwrap();
        assert_ne!(info.family, TextureFamily::Photo);
    }

    #[test]
    fn photos_load_and_become_tileable() {
        let dir = std::env::temp_dir().join(format!("picker-synth-photo-{}", std::process::id()));
        let floor = dir.join("textures/x/floor");
        std::fs::create_dir_all(&floor).unwrap();
        // A non-tileable gradient photo, wider than high.
        let img = image::RgbImage::from_fn(90, 60, |x, y| {
            image::Rgb([(x * 2) as u8, (y * 3) as u8, ((x + y) % 200) as u8])
        });
        img.save(floor.join("grad.png")).unwrap();
        std::fs::write(floor.join("broken.jpg"), b"not a jpeg").unwrap();
        let lib = AssetLibrary::scan(&dir).unwrap();
        assert_eq!(lib.photos.len(), 2);
        let err = photo_texture(&mut Rng::new(1), 32, &lib, &lib.photos[0]).unwrap_err();
        assert!(err.to_string().contains("broken.jpg"), "{err}");
        let (t, info) = photo_texture(&mut Rng::new(1), 32, &lib, &lib.photos[1]).unwrap();
        assert_eq!(info.family, TextureFamily::Photo);
        assert!(info.source.as_deref().unwrap().ends_with("grad.png"));
        assert!(matches!(
            info.params,
            TextureParams::Photo {
                already_tileable: false,
                crop: 60,
                ..
            }
        ));
        assert!(t.seam().worst_ratio() <= 1.2, "{:?}", t.seam());
        assert!(t
            .data
            .iter()
            .all(|c| c.min_element() >= 0.0 && c.max_element() <= 1.0));
        let again = photo_texture(&mut Rng::new(1), 32, &lib, &lib.photos[1]).unwrap();
        let fresh = AssetLibrary::scan(&dir).unwrap();
        let uncached = photo_texture(&mut Rng::new(1), 32, &fresh, &fresh.photos[1]).unwrap();
        assert_eq!(t, again.0);
        assert_eq!(again, uncached);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// Generation time per family at 256² (run with
    /// `cargo test --release -p picker-synth -- --ignored --nocapture texture_timing`).
    #[test]
    #[ignore = "timing; run in release"]
    fn texture_timing() {
        for family in TextureFamily::PROCEDURAL {
            let n = 20;
            let start = std::time::Instant::now();
            let mut worst = 0.0f32;
            for seed in 0..n {
                let (t, _) = random_texture_of(family, &mut Rng::new(seed), 256, None).unwrap();
                worst = worst.max(t.seam().worst_ratio());
            }
            let ms = start.elapsed().as_secs_f64() * 1e3 / n as f64;
            eprintln!("{family:?}: {ms:.2} ms per 256² texture (incl. seam metric), worst seam ratio {worst:.3}");
        }
    }
}
