//! Re-rendering images from render elements, material previews, and image
//! comparison scores.

use std::path::Path;

use glam::{Mat3, Vec3};
use picker_nets::conventions as conv;
use rayon::prelude::*;

use crate::envmap::EnvMap;
use crate::error::{Error, Result};
use crate::io::{self, Image};
use crate::phong::{EnvQuadrature, PhongMaterial};
use crate::prefilter::PrefilteredEnv;

/// Which renderer evaluates eq. 3.7.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Quality {
    /// Exact quadrature over every env-map pixel ([`crate::shade_exact`]); the reference.
    #[default]
    Exact,
    /// The prefiltered fast path ([`PrefilteredEnv`]).
    Fast,
    /// The prefiltered fast path reading the map as the continuous function
    /// its bilinear sampling makes of it, so that lobes narrower than its
    /// pixels do not alias ([`PrefilteredEnv::resolving`]): `picker synth`'s
    /// images, previews, re-renders of a photo.
    Continuous,
}

/// An environment map prepared for shading many points at one [`Quality`].
#[derive(Clone, Debug)]
pub enum Shader {
    /// Exact quadrature.
    Exact(EnvQuadrature),
    /// Prefiltered fast path.
    Fast(PrefilteredEnv),
}

impl Shader {
    /// Prepares `env` for `quality`.
    pub fn new(env: &EnvMap, quality: Quality) -> Self {
        match quality {
            Quality::Exact => Shader::Exact(EnvQuadrature::new(env)),
            Quality::Fast => Shader::Fast(PrefilteredEnv::new(env)),
            Quality::Continuous => Shader::Fast(PrefilteredEnv::resolving(env)),
        }
    }

    /// The fast path reading `env` as a continuous function, so that lobes
    /// narrower than its pixels do not alias ([`PrefilteredEnv::resolving`]):
    /// for images shown to people (previews, re-renders of a photo).
    pub fn resolving(env: &EnvMap) -> Self {
        Shader::new(env, Quality::Continuous)
    }

    /// Eq. 3.7 at one point (unit camera-space `normal` and `view`; zero normal → black).
    pub fn shade(&self, normal: Vec3, view: Vec3, material: &PhongMaterial) -> Vec3 {
        match self {
            Shader::Exact(q) => q.shade(normal, view, material),
            Shader::Fast(p) => p.shade(normal, view, material),
        }
    }
}

/// The render elements of one image, decoded (as `picker infer` and `picker
/// synth` write them), all `height × width`.
#[derive(Clone, Debug)]
pub struct ElementImages {
    /// ρd, linear RGB (3 channels).
    pub diffuse: Image,
    /// ρs, linear RGB (3 channels).
    pub specular: Image,
    /// Glossiness g ∈ [0, 1] (1 channel); exponent [`conv::phong_exponent`].
    pub glossiness: Image,
    /// Unit camera-space normals (3 channels); a zero normal marks a pixel with no surface.
    pub normals: Image,
    /// Unit vectors from the surface to the camera (3 channels); zero → `+z`.
    pub view: Image,
    /// Texture coordinates (u, v, t) (3 channels), if present; not used by the renderer.
    pub uv: Option<Image>,
}

fn check(name: &str, img: &Image, channels: usize, h: usize, w: usize) -> Result<()> {
    if img.channels != channels {
        return Err(Error::shape(
            format!("{name} channels"),
            channels,
            img.channels,
        ));
    }
    if (img.height, img.width) != (h, w) {
        return Err(Error::shape(
            format!("{name} size"),
            format!("{h}x{w} (as {})", conv::DIFFUSE_ALBEDO),
            format!("{}x{}", img.height, img.width),
        ));
    }
    Ok(())
}

impl ElementImages {
    /// Bundles element images, checking channel counts (3, 3, 1, 3, 3, 3) and
    /// that every size equals the diffuse albedo's.
    pub fn new(
        diffuse: Image,
        specular: Image,
        glossiness: Image,
        normals: Image,
        view: Image,
        uv: Option<Image>,
    ) -> Result<Self> {
        let (h, w) = (diffuse.height, diffuse.width);
        check(conv::DIFFUSE_ALBEDO, &diffuse, 3, h, w)?;
        check(conv::SPECULAR_ALBEDO, &specular, 3, h, w)?;
        check(conv::GLOSSINESS, &glossiness, 1, h, w)?;
        check(conv::NORMALS, &normals, 3, h, w)?;
        check(conv::VIEW_VECTOR, &view, 3, h, w)?;
        if let Some(uv) = &uv {
            check(conv::UV, uv, 3, h, w)?;
        }
        Ok(Self {
            diffuse,
            specular,
            glossiness,
            normals,
            view,
            uv,
        })
    }

    /// Loads `<dir>/<head name>.exr` for the five elements the renderer needs
    /// (`diffuse_albedo`, `specular_albedo`, `glossiness`, `normals`,
    /// `view_vector`) and `uv.exr` if present. Errors name the file.
    pub fn load(dir: &Path) -> Result<Self> {
        let read = |name: &str| -> Result<Image> {
            let p = dir.join(format!("{name}.exr"));
            if !p.exists() {
                return Err(Error::io(
                    &p,
                    "read",
                    std::io::Error::new(std::io::ErrorKind::NotFound, "missing render element"),
                ));
            }
            io::read_exr(&p)
        };
        let uv_path = dir.join(format!("{}.exr", conv::UV));
        let uv = if uv_path.exists() {
            Some(io::read_exr(&uv_path)?)
        } else {
            None
        };
        let named = |r: Result<()>, name: &str| {
            r.map_err(|e| match e {
                Error::Shape {
                    what,
                    expected,
                    found,
                } => Error::Shape {
                    what: format!("{}: {what}", dir.join(format!("{name}.exr")).display()),
                    expected,
                    found,
                },
                other => other,
            })
        };
        let d = read(conv::DIFFUSE_ALBEDO)?;
        let (h, w) = (d.height, d.width);
        named(
            check(conv::DIFFUSE_ALBEDO, &d, 3, h, w),
            conv::DIFFUSE_ALBEDO,
        )?;
        let s = read(conv::SPECULAR_ALBEDO)?;
        named(
            check(conv::SPECULAR_ALBEDO, &s, 3, h, w),
            conv::SPECULAR_ALBEDO,
        )?;
        let g = read(conv::GLOSSINESS)?;
        named(check(conv::GLOSSINESS, &g, 1, h, w), conv::GLOSSINESS)?;
        let n = read(conv::NORMALS)?;
        named(check(conv::NORMALS, &n, 3, h, w), conv::NORMALS)?;
        let v = read(conv::VIEW_VECTOR)?;
        named(check(conv::VIEW_VECTOR, &v, 3, h, w), conv::VIEW_VECTOR)?;
        if let Some(uv) = &uv {
            named(check(conv::UV, uv, 3, h, w), conv::UV)?;
        }
        Self::new(d, s, g, n, v, uv)
    }

    /// Rows.
    pub fn height(&self) -> usize {
        self.diffuse.height
    }

    /// Columns.
    pub fn width(&self) -> usize {
        self.diffuse.width
    }

    /// Whether pixel `i` has a surface (finite, non-zero normal).
    pub fn is_valid(&self, i: usize) -> bool {
        let n = self.normals.rgb(i);
        n.is_finite() && n.length() > 1e-6
    }

    /// The material of pixel `i`.
    pub fn material(&self, i: usize) -> PhongMaterial {
        PhongMaterial::from_glossiness(
            self.diffuse.rgb(i),
            self.specular.rgb(i),
            self.glossiness.at(0, i).clamp(0.0, 1.0),
        )
    }
}

/// Re-renders an image from render elements under `env` (eq. 3.7 per pixel,
/// rayon over rows): linear RGB, 3 channels, the elements' size. Pixels with a
/// zero or non-finite normal are black; a zero view vector counts as `+z`.
pub fn rerender(elements: &ElementImages, env: &EnvMap, quality: Quality) -> Image {
    let shader = Shader::new(env, quality);
    rerender_with(elements, &shader)
}

/// [`rerender`] with a prepared [`Shader`].
pub fn rerender_with(elements: &ElementImages, shader: &Shader) -> Image {
    let (h, w) = (elements.height(), elements.width());
    let rows: Vec<Vec<Vec3>> = (0..h)
        .into_par_iter()
        .map(|row| {
            (0..w)
                .map(|col| {
                    let i = row * w + col;
                    if !elements.is_valid(i) {
                        return Vec3::ZERO;
                    }
                    shader.shade(
                        elements.normals.rgb(i),
                        elements.view.rgb(i),
                        &elements.material(i),
                    )
                })
                .collect()
        })
        .collect();
    let mut out = Image::zeros(3, h, w);
    for (i, v) in rows.into_iter().flatten().enumerate() {
        out.set_rgb(i, v);
    }
    out
}

/// The camera-space unit normal at pixel (`row`, `col`) of an orthographic
/// view of a unit sphere filling a `size × size` image: image position
/// `(x, y) ∈ [−1, 1]²` of the pixel's centre (y up), normal
/// `(x, y, √(1 − x² − y²))`; `None` off the sphere (`x² + y² ≥ 1`). The view
/// vector is `+z` everywhere. Shared by the material previews.
pub fn sphere_normal(size: usize, row: usize, col: usize) -> Option<Vec3> {
    let x = (col as f32 + 0.5) / size as f32 * 2.0 - 1.0;
    let y = 1.0 - (row as f32 + 0.5) / size as f32 * 2.0;
    let r2 = x * x + y * y;
    (r2 < 1.0).then(|| Vec3::new(x, y, (1.0 - r2).sqrt()))
}

/// Linear level a white diffuse surface averages in a [`preview_sphere`] once
/// exposed by [`preview_exposure`] (below the display curve's knee,
/// `conv::SOFT_CLIP_KNEE`, so albedos up to 1 show as themselves).
pub const PREVIEW_WHITE: f32 = 0.75;

/// Normals per side of the grid over the sphere's visible disc that
/// [`preview_exposure`] averages.
const EXPOSURE_GRID: usize = 32;

/// The exposure of a material preview drawn with `shader` ([`preview_sphere`], [`preview_tile`]): the factor that
/// makes a white Lambertian sphere (ρd = 1, no specular) under the same
/// lighting average [`PREVIEW_WHITE`] over its visible disc. Exposing by the
/// lighting, not by the rendered pixels, shows a material's own lightness (a
/// dark material stays dark, a white one white, whatever the background
/// share of the square) and makes the preview independent of the lighting's
/// overall scale. Display: `conv::expose_rgb(planes, exposure)`. A lighting
/// that leaves the white sphere black gives 1.
pub fn preview_exposure(shader: &Shader) -> f32 {
    let white = PhongMaterial {
        diffuse: Vec3::ONE,
        specular: Vec3::ZERO,
        exponent: 1.0,
    };
    let (mut sum, mut count) = (0.0f64, 0usize);
    for row in 0..EXPOSURE_GRID {
        for col in 0..EXPOSURE_GRID {
            let Some(n) = sphere_normal(EXPOSURE_GRID, row, col) else {
                continue;
            };
            let c = shader.shade(n, Vec3::Z, &white);
            let lum = 0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z;
            if lum.is_finite() {
                sum += lum.max(0.0) as f64;
                count += 1;
            }
        }
    }
    let mean = if count > 0 { sum / count as f64 } else { 0.0 };
    if mean > 1e-12 {
        (PREVIEW_WHITE as f64 / mean) as f32
    } else {
        1.0
    }
}

/// A preview of `material` on a sphere under `env` (fast path): an
/// orthographic view of a unit sphere filling a `size × size` image, camera
/// space (normal `(x, y, √(1−x²−y²))` at image position `(x, y) ∈ [−1, 1]²`,
/// y up), view `+z` everywhere. Linear RGB; pixels outside the sphere are black.
pub fn preview_sphere(material: &PhongMaterial, env: &EnvMap, size: usize) -> Image {
    preview_sphere_with(material, &Shader::new(env, Quality::Fast), size)
}

/// [`preview_sphere`] with a prepared [`Shader`].
pub fn preview_sphere_with(material: &PhongMaterial, shader: &Shader, size: usize) -> Image {
    let mut out = Image::zeros(3, size, size);
    let px: Vec<Vec3> = (0..size * size)
        .into_par_iter()
        .map(|i| match sphere_normal(size, i / size, i % size) {
            Some(n) => shader.shade(n, Vec3::Z, material),
            None => Vec3::ZERO,
        })
        .collect();
    for (i, v) in px.into_iter().enumerate() {
        out.set_rgb(i, v);
    }
    out
}

/// Tilt of the preview tile: its top edge leans away from the camera by this angle.
pub const TILE_TILT_DEGREES: f32 = 30.0;

/// A preview of `material` on a flat square tile under `env` (fast path): a
/// pinhole camera at the origin (40° field of view, looking down −z) sees a
/// square of side 1 centred 1.6 units ahead, tilted [`TILE_TILT_DEGREES`]
/// about the x axis (normal `(0, sin 30°, cos 30°)`) so the specular
/// reflection of the environment shows and varies across the tile. With a
/// `texture` (linear RGB, 3 channels, wrapped once over the tile, bilinear) it
/// replaces the diffuse albedo. Linear RGB; pixels off the tile are black.
///
/// # Panics
/// When `texture` is malformed ([`Image::check_readable`]: no channel, or
/// data that does not match its size).
pub fn preview_tile(
    material: &PhongMaterial,
    env: &EnvMap,
    size: usize,
    texture: Option<&Image>,
) -> Image {
    preview_tile_with(material, &Shader::new(env, Quality::Fast), size, texture)
}

/// [`preview_tile`] with a prepared [`Shader`].
///
/// # Panics
/// As [`preview_tile`].
pub fn preview_tile_with(
    material: &PhongMaterial,
    shader: &Shader,
    size: usize,
    texture: Option<&Image>,
) -> Image {
    if let Some(t) = texture {
        if let Err(e) = t.check_readable("preview texture") {
            panic!("preview_tile: {e}");
        }
    }
    let tilt = Mat3::from_rotation_x(-TILE_TILT_DEGREES.to_radians());
    let normal = tilt * Vec3::Z;
    let (u_axis, v_axis) = (tilt * Vec3::X, tilt * Vec3::NEG_Y);
    let centre = Vec3::new(0.0, 0.0, -1.6);
    let focal = 1.0 / (20.0f32).to_radians().tan();
    let px: Vec<Vec3> = (0..size * size)
        .into_par_iter()
        .map(|i| {
            let x = ((i % size) as f32 + 0.5) / size as f32 * 2.0 - 1.0;
            let y = 1.0 - ((i / size) as f32 + 0.5) / size as f32 * 2.0;
            let ray = Vec3::new(x, y, -focal).normalize();
            let denom = ray.dot(normal);
            if denom.abs() < 1e-6 {
                return Vec3::ZERO;
            }
            let t = centre.dot(normal) / denom;
            if t <= 0.0 {
                return Vec3::ZERO;
            }
            let p = ray * t;
            let (u, v) = (
                (p - centre).dot(u_axis) + 0.5,
                (p - centre).dot(v_axis) + 0.5,
            );
            if !(0.0..=1.0).contains(&u) || !(0.0..=1.0).contains(&v) {
                return Vec3::ZERO;
            }
            let mut m = *material;
            if let Some(tex) = texture {
                m.diffuse = sample_texture(tex, u, v);
            }
            shader.shade(normal, -ray, &m)
        })
        .collect();
    let mut out = Image::zeros(3, size, size);
    for (i, v) in px.into_iter().enumerate() {
        out.set_rgb(i, v);
    }
    out
}

/// Bilinear, wrapped lookup of a texture at `(u, v)` (u right, v down, `[0, 1)`).
fn sample_texture(tex: &Image, u: f32, v: f32) -> Vec3 {
    let (w, h) = (tex.width as i64, tex.height as i64);
    if w == 0 || h == 0 {
        return Vec3::ZERO;
    }
    let fx = u * w as f32 - 0.5;
    let fy = v * h as f32 - 0.5;
    let (x0, y0) = (fx.floor(), fy.floor());
    let (tx, ty) = (fx - x0, fy - y0);
    let at = |x: i64, y: i64| {
        let i = (y.rem_euclid(h) * w + x.rem_euclid(w)) as usize;
        tex.rgb(i)
    };
    let (x0, y0) = (x0 as i64, y0 as i64);
    let top = at(x0, y0).lerp(at(x0 + 1, y0), tx);
    let bottom = at(x0, y0 + 1).lerp(at(x0 + 1, y0 + 1), tx);
    top.lerp(bottom, ty)
}

/// Differences between a rendered image and a reference, both linear RGB.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ErrorScore {
    /// Pixels compared.
    pub pixels: usize,
    /// Root-mean-square difference of linear values (all channels).
    pub rmse_linear: f64,
    /// `10·log10(1/MSE)` of linear values (peak 1).
    pub psnr_linear: f64,
    /// RMSE after [`conv::srgb_encode`] (clamped to `[0, 1]`).
    pub rmse_srgb: f64,
    /// PSNR after sRGB encoding (peak 1).
    pub psnr_srgb: f64,
}

/// Scale of [`error_heatmap`]: a mean absolute sRGB difference of this much is white.
pub const HEATMAP_FULL_SCALE: f32 = 0.25;

fn psnr(mse: f64) -> f64 {
    if mse <= 0.0 {
        f64::INFINITY
    } else {
        -10.0 * mse.log10()
    }
}

fn check_pair(render: &Image, reference: &Image) -> Result<()> {
    render.check_readable("rendered image")?;
    reference.check_readable("reference image")?;
    if render.channels != 3 {
        return Err(Error::shape("rendered image channels", 3, render.channels));
    }
    if (reference.height, reference.width) != (render.height, render.width) {
        return Err(Error::shape(
            "reference image size",
            format!("{}x{}", render.height, render.width),
            format!("{}x{}", reference.height, reference.width),
        ));
    }
    Ok(())
}

/// Compares `render` (linear RGB) with `reference` (linear, 3 or 1 channels) over
/// the pixels where `mask` is true (all when `None`). Refuses different sizes.
pub fn compare(render: &Image, reference: &Image, mask: Option<&[bool]>) -> Result<ErrorScore> {
    check_pair(render, reference)?;
    let (mut sl, mut ss, mut count) = (0.0f64, 0.0f64, 0usize);
    for i in 0..render.plane_len() {
        if mask.is_some_and(|m| !m.get(i).copied().unwrap_or(false)) {
            continue;
        }
        let (a, b) = (render.rgb(i), reference.rgb(i));
        for c in 0..3 {
            let d = (a[c] - b[c]) as f64;
            sl += d * d;
            let e = (conv::srgb_encode(a[c]) - conv::srgb_encode(b[c])) as f64;
            ss += e * e;
        }
        count += 1;
    }
    let n = (3 * count).max(1) as f64;
    Ok(ErrorScore {
        pixels: count,
        rmse_linear: (sl / n).sqrt(),
        psnr_linear: psnr(sl / n),
        rmse_srgb: (ss / n).sqrt(),
        psnr_srgb: psnr(ss / n),
    })
}

/// A heat map (display values, 3 channels) of the mean absolute sRGB difference
/// per pixel, scaled so [`HEATMAP_FULL_SCALE`] is white: black → red → yellow → white.
/// Pixels outside `mask` are black.
pub fn error_heatmap(render: &Image, reference: &Image, mask: Option<&[bool]>) -> Result<Image> {
    check_pair(render, reference)?;
    let mut out = Image::zeros(3, render.height, render.width);
    for i in 0..render.plane_len() {
        if mask.is_some_and(|m| !m.get(i).copied().unwrap_or(false)) {
            continue;
        }
        let (a, b) = (render.rgb(i), reference.rgb(i));
        let e: f32 = (0..3)
            .map(|c| (conv::srgb_encode(a[c]) - conv::srgb_encode(b[c])).abs())
            .sum::<f32>()
            / 3.0;
        let t = (e / HEATMAP_FULL_SCALE).clamp(0.0, 1.0) * 3.0;
        out.set_rgb(
            i,
            Vec3::new(
                t.min(1.0),
                (t - 1.0).clamp(0.0, 1.0),
                (t - 2.0).clamp(0.0, 1.0),
            ),
        );
    }
    Ok(out)
}

/// Display values of a linear image: [`conv::srgb_encode`] per value (clamped to `[0, 1]`).
pub fn to_srgb(linear: &Image) -> Image {
    linear.map(conv::srgb_encode)
}
