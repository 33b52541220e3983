//! Writing an extracted [`Material`] as files an artist can use.
//!
//! [`write_material_files`] writes, into one directory, every file atomically
//! (temporary file beside the target, fsync, rename — `picker_render::io`):
//!
//! | file | content |
//! |---|---|
//! | `texture.png` | the tileable diffuse texture, sRGB-encoded, 8-bit (16-bit with [`ExportOptions::sixteen_bit`]) |
//! | `texture.exr` | the same texture as linear RGB `f32` |
//! | `coverage.png` | per-texel coverage in `[0, 1]`, grey |
//! | `mask.png` | the material's mask at photo resolution, grey (always written) |
//! | `material.json` | every parameter with its convention, plus the caller's `extra` |
//! | `material.mtl` | Wavefront MTL (Phong) |
//! | `material.gltf` | glTF 2.0 material (metallic-roughness + `KHR_materials_specular`) |
//! | `material.usda` | USD material (`UsdPreviewSurface`, specular workflow) |
//!
//! The texture files and `coverage.png` exist only for a textured material
//! (one with a [`TextureResult`](crate::TextureResult)); an untextured material
//! is exported with constant colours.
//!
//! **Phong → glTF metallic-roughness** ([`GltfConversion`]):
//! - `metallicFactor = 0` (every extracted material is treated as a dielectric);
//! - base colour = ρd: `texture.png` when textured (`baseColorFactor = 1`),
//!   otherwise `baseColorFactor = (ρd, 1)` (linear, as glTF wants);
//! - roughness from the Phong exponent `n` (`n = 2^(13 g)`,
//!   [`picker_nets::conventions::phong_exponent`]). The renderer's lobe is the
//!   *reflection-vector* Phong lobe `(V·R)ⁿ` (`picker_render::phong::specular_lobe`),
//!   whose equivalent Blinn-Phong (half-vector) exponent is `n_b = 4 n`
//!   (`cos θ_r ≈ cos(2 θ_h)` near the peak). The standard Blinn-Phong ↔
//!   Beckmann/GGX correspondence (Walter et al. 2007) then gives
//!   `α = sqrt(2 / (n_b + 2))` and glTF's perceptual roughness
//!   `roughnessFactor = sqrt(α)`, clamped to `[0, 1]`;
//! - `KHR_materials_specular` (ratified): `specularFactor = 1` and
//!   `specularColorFactor = ρs / 0.04` ([`GLTF_DIELECTRIC_F0`]; the spec allows
//!   values above 1), so that glTF's dielectric Fresnel at normal incidence,
//!   `F0 = min(0.04 · specularColorFactor, 1) · specularFactor`, is `ρs`: the
//!   Phong lobe's directional albedo at normal incidence
//!   (`∫ ρs (n+2)/2π cosⁿθ cos θ dω = ρs`). A material with `ρs = 0` gets
//!   `specularFactor = 0` (no specular layer). (Before stop 43 the factor was
//!   `max ρs` and the colour `ρs / max ρs`, which made `F0 = 0.04 ρs`: a
//!   typical `ρs = 0.04` wall came out 25× too weakly specular.)
//!
//! **USD** ([`usda_text`]): one `Material` prim named after the material (made
//! a USD identifier) with a `UsdPreviewSurface` in the specular workflow
//! (`useSpecularWorkflow = 1`): `diffuseColor` = ρd (a `UsdUVTexture` of
//! `texture.png`, sRGB, wrapped `repeat` both ways, read through a
//! `UsdPrimvarReader_float2` of the `st` primvar; a constant when untextured),
//! `specularColor` = ρs (the specular workflow's colour at normal incidence,
//! the Phong lobe's albedo there, as for glTF's F0), `roughness` = glTF's
//! perceptual roughness (`UsdPreviewSurface` squares it, as glTF does),
//! `metallic` 0, `opacity` 1. USD's `st` has `(0, 0)` at the bottom left of the
//! image, glTF's UV at the top left: the texture tiles, so that flip only
//! mirrors it vertically relative to glTF.
//!
//! **MTL**: `Kd` = mean diffuse ρd (linear; white when textured, because MTL
//! multiplies `map_Kd` by `Kd` — the mean is then a comment), `Ks` = ρs, `Ns` = the Phong
//! exponent clamped to `[0, 1000]` (what MTL readers accept), `d 1`, `illum 2`,
//! `map_Kd texture.png` when textured.
//!
//! The same formulas are written, as text, into `material.json`'s
//! `conventions` object (JSON has no comments).

use std::path::{Path, PathBuf};

use picker_nets::conventions::srgb_encode;
use picker_render::io::{write_atomic, write_exr, write_png, write_png_mapped, Image};
use serde_json::{json, Map, Value};

use crate::error::{Error, Result};
use crate::material::Material;

/// File name of the sRGB texture.
pub const TEXTURE_PNG: &str = "texture.png";
/// File name of the linear texture.
pub const TEXTURE_EXR: &str = "texture.exr";
/// File name of the coverage map.
pub const COVERAGE_PNG: &str = "coverage.png";
/// File name of the mask.
pub const MASK_PNG: &str = "mask.png";
/// File name of the JSON description.
pub const MATERIAL_JSON: &str = "material.json";
/// File name of the Wavefront material.
pub const MATERIAL_MTL: &str = "material.mtl";
/// File name of the glTF material.
pub const MATERIAL_GLTF: &str = "material.gltf";
/// File name of the USD material (ASCII `.usda`, `UsdPreviewSurface`).
pub const MATERIAL_USDA: &str = "material.usda";

/// Version of the `material.json` layout (bumped on incompatible changes).
pub const MATERIAL_JSON_VERSION: u32 = 1;

/// Largest `Ns` written to `material.mtl` (MTL readers accept `0..=1000`).
pub const MTL_MAX_NS: f32 = 1000.0;

/// Ratio between the Blinn-Phong (half-vector) exponent and the equivalent
/// reflection-vector Phong exponent: `n_b = 4 n`.
pub const BLINN_PER_PHONG_EXPONENT: f64 = 4.0;

/// glTF's dielectric reflectance at normal incidence (ior 1.5), which
/// `KHR_materials_specular.specularColorFactor` scales.
pub const GLTF_DIELECTRIC_F0: f64 = 0.04;

/// How [`write_material_files`] writes its images.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ExportOptions {
    /// Write `texture.png` with 16 bits per sample instead of 8.
    pub sixteen_bit: bool,
}

/// The Phong → glTF metallic-roughness conversion of one material (see the
/// module docs for the formulas).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GltfConversion {
    /// Equivalent Blinn-Phong exponent `n_b = 4 n`.
    pub blinn_phong_exponent: f64,
    /// GGX/Beckmann roughness `α = sqrt(2 / (n_b + 2))`.
    pub alpha: f64,
    /// glTF `roughnessFactor = sqrt(α)` in `[0, 1]`.
    pub perceptual_roughness: f64,
    /// `KHR_materials_specular.specularFactor`: 1, or 0 when `ρs = 0`.
    pub specular_factor: f64,
    /// `KHR_materials_specular.specularColorFactor = ρs / GLTF_DIELECTRIC_F0`
    /// (each `ρs,c` clamped to `[0, 1]`; white when `ρs = 0`), so that
    /// `min(0.04 · specularColorFactor, 1) · specularFactor = ρs`.
    pub specular_color: [f64; 3],
}

impl GltfConversion {
    /// The conversion of Phong exponent `exponent` and specular albedo `specular` (linear RGB).
    pub fn new(exponent: f32, specular: [f32; 3]) -> Self {
        let n = if exponent.is_finite() {
            short(exponent).max(0.0)
        } else if exponent == f32::INFINITY {
            f64::MAX
        } else {
            0.0
        };
        let blinn_phong_exponent = BLINN_PER_PHONG_EXPONENT * n;
        let alpha = (2.0 / (blinn_phong_exponent + 2.0)).sqrt().clamp(0.0, 1.0);
        let rho = specular.map(|v| {
            if v.is_finite() {
                short(v).clamp(0.0, 1.0)
            } else {
                0.0
            }
        });
        let (specular_factor, specular_color) = if rho.iter().any(|&v| v > 0.0) {
            (1.0, rho.map(|v| v / GLTF_DIELECTRIC_F0))
        } else {
            (0.0, [1.0; 3])
        };
        Self {
            blinn_phong_exponent,
            alpha,
            perceptual_roughness: alpha.sqrt(),
            specular_factor,
            specular_color,
        }
    }
}

/// Writes the files of material `m` into the existing directory `dir` (see the
/// module docs for the list) and returns their paths in the order written.
///
/// `extra` is merged into the top level of `material.json` (timings, versions,
/// photo information, ...): it must be a JSON object (or `null` for nothing),
/// and a key that `material.json` already has is refused with
/// [`Error::Invalid`] rather than silently overwritten. Keys are written in
/// sorted order, so the file is stable from run to run.
///
/// Errors: [`Error::Io`] naming `dir` when it is not an existing directory;
/// the writer's error (naming the file) when a file cannot be written.
pub fn write_material_files(
    dir: &Path,
    m: &Material,
    extra: &Value,
    opts: &ExportOptions,
) -> Result<Vec<PathBuf>> {
    // (A bad directory fails before any file is made.)
    check_dir(dir)?;
    material_json(m, extra, opts)?;
    let mut written = write_material_images(dir, m, opts)?;
    written.extend(write_material_descriptions(dir, m, extra, opts)?);
    Ok(written)
}

/// An error unless `dir` is an existing directory.
fn check_dir(dir: &Path) -> Result<()> {
    if !dir.is_dir() {
        let source = if dir.exists() {
            std::io::Error::other("not a directory")
        } else {
            std::io::Error::new(
                std::io::ErrorKind::NotFound,
                "export directory does not exist",
            )
        };
        return Err(Error::Io {
            path: dir.to_path_buf(),
            source,
        });
    }
    Ok(())
}

/// The image files of [`write_material_files`]: `texture.png`,
/// `texture.exr` and `coverage.png` when textured, and `mask.png`, encoded
/// and written side by side (the same bytes as one after the other; the
/// first failure in that order is returned). Returns the paths in that order.
pub fn write_material_images(
    dir: &Path,
    m: &Material,
    opts: &ExportOptions,
) -> Result<Vec<PathBuf>> {
    use rayon::prelude::*;
    check_dir(dir)?;
    type Job<'a> = (PathBuf, Box<dyn Fn(&Path) -> Result<()> + Sync + 'a>);
    let mut jobs: Vec<Job<'_>> = Vec::new();
    if let Some(tex) = &m.texture {
        let sixteen = opts.sixteen_bit;
        jobs.push((
            dir.join(TEXTURE_PNG),
            Box::new(move |path| {
                // sRGB-encoded as it is quantised: no encoded copy of the texture.
                Ok(write_png_mapped(path, &tex.texture, sixteen, srgb_encode)?)
            }),
        ));
        jobs.push((
            dir.join(TEXTURE_EXR),
            Box::new(move |path| Ok(write_exr(path, &tex.texture)?)),
        ));
        jobs.push((
            dir.join(COVERAGE_PNG),
            Box::new(move |path| Ok(write_png(path, &first_plane(&tex.coverage))?)),
        ));
    }
    jobs.push((
        dir.join(MASK_PNG),
        Box::new(move |path| Ok(write_png(path, &first_plane(&m.mask))?)),
    ));
    let results: Vec<Result<()>> = jobs.par_iter().map(|(path, job)| job(path)).collect();
    results.into_iter().collect::<Result<Vec<()>>>()?;
    Ok(jobs.into_iter().map(|(path, _)| path).collect())
}

/// The description files of [`write_material_files`]: `material.json` (with
/// `extra`), `material.mtl`, `material.gltf` and `material.usda`. Returns
/// their paths.
pub fn write_material_descriptions(
    dir: &Path,
    m: &Material,
    extra: &Value,
    opts: &ExportOptions,
) -> Result<Vec<PathBuf>> {
    check_dir(dir)?;
    let json = material_json(m, extra, opts)?;
    let mut written = Vec::new();
    let path = dir.join(MATERIAL_JSON);
    write_json(&path, &json, "material.json")?;
    written.push(path);

    let path = dir.join(MATERIAL_MTL);
    write_atomic(&path, mtl_text(m).as_bytes())?;
    written.push(path);

    let path = dir.join(MATERIAL_GLTF);
    write_json(&path, &gltf_json(m), "material.gltf")?;
    written.push(path);

    let path = dir.join(MATERIAL_USDA);
    write_atomic(&path, usda_text(m).as_bytes())?;
    written.push(path);

    Ok(written)
}

/// The contents of `material.json` for `m` (see [`write_material_files`]).
pub fn material_json(m: &Material, extra: &Value, opts: &ExportOptions) -> Result<Value> {
    let p = &m.params;
    let conv = GltfConversion::new(p.exponent, p.specular);
    let textured_files = m.texture.is_some();
    let file = |name: &str| {
        if textured_files {
            json!(name)
        } else {
            Value::Null
        }
    };
    let texture = m.texture.as_ref().map(|t| {
        json!({
            "width": t.texture.width,
            "height": t.texture.height,
            "coverage_fraction": t.coverage_fraction,
            "observed_size": t.observed_size,
            "size_m": t.size_m,
            "seam": {
                "wrap": t.seam.wrap,
                "interior": t.seam.interior,
                "ratio": t.seam.ratio,
                "corrected": t.seam_corrected,
            },
            "uv_mode": t.uv_mode,
            "inpainter": t.inpainter,
        })
    });
    let mut root = json!({
        "format": "material-picker/material",
        "format_version": MATERIAL_JSON_VERSION,
        "name": m.name,
        "pick": m.pick,
        "textured": m.textured,
        "area_fraction": m.area_fraction,
        "rerender_psnr_db": m.rerender_psnr,
        "phong": {
            "diffuse": p.diffuse.map(short),
            "specular": p.specular.map(short),
            "glossiness": short(p.glossiness),
            "exponent": short(p.exponent),
        },
        "texture": texture,
        "gltf": {
            "metallic": 0.0,
            "blinn_phong_exponent": conv.blinn_phong_exponent,
            "alpha": conv.alpha,
            "roughness": conv.perceptual_roughness,
            "specular_factor": conv.specular_factor,
            "specular_color": conv.specular_color,
        },
        "mtl": {
            "ns": short(mtl_ns(p.exponent)),
        },
        "files": {
            "texture_png": file(TEXTURE_PNG),
            "texture_png_bits": if textured_files { json!(if opts.sixteen_bit { 16 } else { 8 }) } else { Value::Null },
            "texture_exr": file(TEXTURE_EXR),
            "coverage_png": file(COVERAGE_PNG),
            "mask_png": MASK_PNG,
            "mtl": MATERIAL_MTL,
            "gltf": MATERIAL_GLTF,
            "usda": MATERIAL_USDA,
        },
        "conventions": conventions(),
    });
    match extra {
        Value::Null => {}
        Value::Object(map) => {
            let obj = root
                .as_object_mut()
                .ok_or_else(|| Error::Invalid("material.json root is not an object".into()))?;
            for (k, v) in map {
                if obj.contains_key(k) {
                    return Err(Error::Invalid(format!(
                        "extra key {k:?} clashes with a key material.json already has"
                    )));
                }
                obj.insert(k.clone(), v.clone());
            }
        }
        other => {
            return Err(Error::Invalid(format!(
                "extra must be a JSON object or null, got {other}"
            )))
        }
    }
    Ok(sorted(root))
}

/// Every convention of `material.json`, as text.
fn conventions() -> Value {
    let mut c = Map::new();
    let mut put = |k: &str, v: &str| {
        c.insert(k.into(), Value::String(v.into()));
    };
    put(
        "pick",
        "photo pixels [x, y], x right, y down, origin at the top-left corner; null when every material was extracted",
    );
    put(
        "area_fraction",
        "fraction of the photo's pixels inside the material's mask",
    );
    put(
        "rerender_psnr_db",
        "PSNR in dB (sRGB, peak 1) of the masked region re-rendered from the extracted material against the photo; null if not computed or infinite",
    );
    put(
        "phong.diffuse",
        "diffuse albedo rho_d, linear RGB in [0,1]; for a textured material the mean of the final texture",
    );
    put(
        "phong.specular",
        "specular albedo rho_s, linear RGB in [0,1] (median over the mask)",
    );
    put(
        "phong.glossiness",
        "glossiness g in [0,1] (median over the mask)",
    );
    put(
        "phong.exponent",
        "Phong exponent n = 2^(13 g) (g = 0 -> 1, g = 1 -> 8192); inverse g = log2(n)/13",
    );
    put(
        "phong.brdf",
        "f = rho_d/pi + rho_s (n+2)/(2 pi) max(0, V.R)^n with R the mirror direction of the light (reflection-vector Phong)",
    );
    put(
        "texture",
        "texture.png: sRGB-encoded (IEC 61966-2-1) diffuse albedo, tileable; texture.exr: the same, linear RGB f32; texel (col,row) centre at u=(col+0.5)/w, v=(row+0.5)/h, row 0 at the top",
    );
    put(
        "texture.coverage_fraction",
        "fraction of texels observed in the photo (coverage > 0), counting those filled from another repeat of a texture square that repeats (diagnostics.uv.repeats.filled)",
    );
    put(
        "texture.observed_size",
        "texels per unit of texture square at the photo's density: the automatic side; a larger --size than the photo covers is made at this side and enlarged (bicubic), a smaller one is made at its own",
    );
    put(
        "texture.size_m",
        "the texture's size on the surface in metres [along u, along v] (its width and height: repeat it every that many metres), when known: a --quad with its real --quad-size gives the rectified plane its scale; null otherwise",
    );
    put(
        "texture.seam",
        "wrap = mean |difference| across the wrap edges, interior = mean |difference| of neighbouring texels, ratio = wrap/interior (<= ~1: invisible seam), of the final texture; corrected = --seamless was given, the inpainted texture's ratio was above 1.25, and it was replaced by its periodic component (Moisan 2011: colour jumps across the wrap edges removed by a smooth correction)",
    );
    put(
        "texture.uv_mode",
        "net: the network's texture coordinates; plane: a plane fitted to the normals, rectified by a homography",
    );
    put(
        "texture.inpainter",
        "name of the inpainter that filled the unobserved texels",
    );
    put(
        "coverage_png",
        "per-texel coverage/confidence in [0,1], grey, 0 = never observed; a texel filled from another repeat of a repeating texture square has that repeat's coverage",
    );
    put(
        "mask_png",
        "the material's mask at photo resolution, 1 inside, 0 outside",
    );
    put(
        "gltf.metallic",
        "metallicFactor = 0: treated as a dielectric",
    );
    put(
        "gltf.base_color",
        "baseColorTexture = texture.png when textured (baseColorFactor 1), otherwise baseColorFactor = rho_d (linear)",
    );
    put(
        "gltf.blinn_phong_exponent",
        "n_b = 4 n: the half-vector exponent equivalent to the reflection-vector Phong exponent n",
    );
    put(
        "gltf.alpha",
        "GGX/Beckmann roughness alpha = sqrt(2/(n_b + 2)) (Walter et al. 2007)",
    );
    put(
        "gltf.roughness",
        "glTF perceptual roughnessFactor = sqrt(alpha), in [0,1]",
    );
    put(
        "gltf.specular_factor",
        "KHR_materials_specular.specularFactor = 1 (0 when rho_s = 0)",
    );
    put(
        "gltf.specular_color",
        "KHR_materials_specular.specularColorFactor = rho_s / 0.04 (white if rho_s = 0), so that glTF's dielectric F0 = min(0.04 specularColorFactor, 1) specularFactor = rho_s, the Phong lobe's albedo at normal incidence",
    );
    put(
        "mtl",
        "Kd = rho_d (mean, linear; 1 1 1 when textured since map_Kd is multiplied by Kd), Ks = rho_s, Ns = n clamped to [0, 1000], d 1, illum 2, map_Kd texture.png when textured",
    );
    Value::Object(c)
}

/// `value` with every object's keys in sorted order (independent of
/// `serde_json`'s `preserve_order` feature).
fn sorted(value: Value) -> Value {
    match value {
        Value::Object(map) => {
            let mut entries: Vec<(String, Value)> = map.into_iter().collect();
            entries.sort_by(|a, b| a.0.cmp(&b.0));
            Value::Object(entries.into_iter().map(|(k, v)| (k, sorted(v))).collect())
        }
        Value::Array(items) => Value::Array(items.into_iter().map(sorted).collect()),
        other => other,
    }
}

fn write_json(path: &Path, value: &Value, what: &str) -> Result<()> {
    let mut bytes = serde_json::to_vec_pretty(value).map_err(|source| Error::Json {
        what: what.into(),
        source,
    })?;
    bytes.push(b'\n');
    write_atomic(path, &bytes)?;
    Ok(())
}

/// Plane 0 of `img` as a one-channel image (a mask or coverage map).
fn first_plane(img: &Image) -> std::borrow::Cow<'_, Image> {
    if img.channels == 1 {
        return std::borrow::Cow::Borrowed(img);
    }
    std::borrow::Cow::Owned(Image {
        channels: 1,
        height: img.height,
        width: img.width,
        data: if img.channels == 0 {
            vec![0.0; img.plane_len()]
        } else {
            img.plane(0).to_vec()
        },
    })
}

/// `v` as the `f64` with the shortest decimal form that reads back as `v`
/// (`0.4f32` → `0.4`, not `0.4000000059604645`); NaN/inf → NaN (JSON `null`).
fn short(v: f32) -> f64 {
    if v.is_finite() {
        v.to_string().parse().unwrap_or(f64::from(v))
    } else {
        f64::NAN
    }
}

/// `Ns` of exponent `n`: clamped to `[0, MTL_MAX_NS]` (NaN → 0).
fn mtl_ns(n: f32) -> f32 {
    if n.is_nan() {
        0.0
    } else {
        n.clamp(0.0, MTL_MAX_NS)
    }
}

/// A finite number for text formats (NaN/inf → 0).
fn finite(v: f32) -> f32 {
    if v.is_finite() {
        v
    } else {
        0.0
    }
}

/// The material name as an MTL identifier (no whitespace; never empty).
fn mtl_name(name: &str) -> String {
    let s: String = name
        .chars()
        .map(|c| {
            if c.is_whitespace() || c.is_control() {
                '_'
            } else {
                c
            }
        })
        .collect();
    if s.is_empty() {
        "material".into()
    } else {
        s
    }
}

/// The contents of `material.mtl` for `m`.
pub fn mtl_text(m: &Material) -> String {
    let p = &m.params;
    let rgb = |v: [f32; 3]| {
        format!(
            "{:.6} {:.6} {:.6}",
            finite(v[0]),
            finite(v[1]),
            finite(v[2])
        )
    };
    let mut s = String::new();
    s.push_str("# Material Picker export: Phong material, linear RGB albedos\n");
    s.push_str(&format!(
        "# glossiness g = {:.6}, Phong exponent n = 2^(13 g) = {:.6}\n",
        finite(p.glossiness),
        finite(p.exponent)
    ));
    s.push_str(&format!("newmtl {}\n", mtl_name(&m.name)));
    s.push_str("Ka 0.000000 0.000000 0.000000\n");
    // The MTL format multiplies map_Kd by Kd: with a texture Kd is white and
    // the mean colour goes in a comment.
    if m.texture.is_some() {
        s.push_str(&format!(
            "# mean diffuse albedo (texture mean) = {}\n",
            rgb(p.diffuse)
        ));
        s.push_str("Kd 1.000000 1.000000 1.000000\n");
    } else {
        s.push_str(&format!("Kd {}\n", rgb(p.diffuse)));
    }
    s.push_str(&format!("Ks {}\n", rgb(p.specular)));
    s.push_str(&format!("Ns {:.6}\n", mtl_ns(p.exponent)));
    s.push_str("d 1\n");
    s.push_str("illum 2\n");
    if m.texture.is_some() {
        s.push_str(&format!("map_Kd {TEXTURE_PNG}\n"));
    }
    s
}

/// The contents of `material.usda` for `m`: a USD layer holding one
/// `Material` prim (the layer's default prim) with a `UsdPreviewSurface` in
/// the specular workflow (see the module docs for the mapping).
pub fn usda_text(m: &Material) -> String {
    let p = &m.params;
    let conv = GltfConversion::new(p.exponent, p.specular);
    let name = usd_identifier(&m.name);
    let colour = |v: [f32; 3]| {
        let c = v.map(|x| short(finite(x)).clamp(0.0, 1.0));
        format!("({}, {}, {})", c[0], c[1], c[2])
    };
    let diffuse = match m.texture {
        Some(_) => {
            format!("color3f inputs:diffuseColor.connect = </{name}/DiffuseTexture.outputs:rgb>")
        }
        None => format!("color3f inputs:diffuseColor = {}", colour(p.diffuse)),
    };
    let specular = colour(p.specular);
    let roughness = conv.perceptual_roughness as f32;
    let mut s = usda_header(
        &name,
        "Phong material as UsdPreviewSurface (specular workflow), linear colours",
    );
    s.push_str(&format!(
        r#"def Material "{name}"
{{
    token outputs:surface.connect = </{name}/PreviewSurface.outputs:surface>

    def Shader "PreviewSurface"
    {{
        uniform token info:id = "UsdPreviewSurface"
        {diffuse}
        int inputs:useSpecularWorkflow = 1
        color3f inputs:specularColor = {specular}
        float inputs:roughness = {roughness}
        float inputs:metallic = 0
        float inputs:opacity = 1
        token outputs:surface
    }}
"#
    ));
    if m.texture.is_some() {
        s.push_str(&format!(
            r#"
    def Shader "TexCoordReader"
    {{
        uniform token info:id = "UsdPrimvarReader_float2"
        string inputs:varname = "st"
        float2 outputs:result
    }}

    def Shader "DiffuseTexture"
    {{
        uniform token info:id = "UsdUVTexture"
        asset inputs:file = @{TEXTURE_PNG}@
        float2 inputs:st.connect = </{name}/TexCoordReader.outputs:result>
        token inputs:sourceColorSpace = "sRGB"
        token inputs:wrapS = "repeat"
        token inputs:wrapT = "repeat"
        float3 outputs:rgb
    }}
"#
        ));
    }
    s.push_str("}\n");
    s
}

/// File name of the USD layer that gathers several materials of one run
/// ([`usda_library_text`]).
pub const MATERIALS_USDA: &str = "materials.usda";

/// A USD layer gathering materials written by [`usda_text`] elsewhere: a
/// `Scope` named `Materials` (the default prim) holding, for each
/// `(name, layer)`, a prim that references the default prim of the layer
/// at the relative path `layer` (its texture paths stay relative to that
/// layer). Prim names are the names made USD identifiers, made unique by
/// `_2`, `_3`, … in order; a path is quoted `@…@`, or `@@@…@@@` when it
/// holds an `@`; an entry whose path holds `@@@` (no USD quoting admits
/// it) is left out.
pub fn usda_library_text(entries: &[(String, String)]) -> String {
    let mut s = usda_header(
        "Materials",
        "the materials of one run, each referenced from its own layer",
    );
    s.push_str("def Scope \"Materials\"\n{\n");
    let mut used = std::collections::HashSet::new();
    for (name, layer) in entries {
        if layer.contains("@@@") {
            continue;
        }
        let base = usd_identifier(name);
        let mut prim = base.clone();
        let mut k = 2;
        while !used.insert(prim.clone()) {
            prim = format!("{base}_{k}");
            k += 1;
        }
        let quoted = if layer.contains('@') {
            format!("@@@{layer}@@@")
        } else {
            format!("@{layer}@")
        };
        s.push_str(&format!(
            "    def \"{prim}\" (\n        prepend references = {quoted}\n    )\n    {{\n    }}\n"
        ));
    }
    s.push_str("}\n");
    s
}

/// The start of a `.usda` layer whose default prim is `default_prim`, with
/// `doc` and the stage metadata USD's validators ask for (there is no
/// geometry here; a layer referenced into a scene takes the scene's), and a
/// blank line.
fn usda_header(default_prim: &str, doc: &str) -> String {
    let version = env!("CARGO_PKG_VERSION");
    format!(
        r#"#usda 1.0
(
    defaultPrim = "{default_prim}"
    doc = "Material Picker picker-extract {version}: {doc}"
    metersPerUnit = 1
    upAxis = "Y"
)

"#
    )
}

/// `name` as a USD prim name: letters, digits and `_`, not starting with a
/// digit, never empty (every other character becomes `_`).
fn usd_identifier(name: &str) -> String {
    let mut s: String = name
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
        .collect();
    if s.is_empty() || s.starts_with(|c: char| c.is_ascii_digit()) {
        s.insert(0, '_');
    }
    s
}

/// The contents of `material.gltf` for `m` (glTF 2.0, one material, no meshes).
pub fn gltf_json(m: &Material) -> Value {
    let p = &m.params;
    let conv = GltfConversion::new(p.exponent, p.specular);
    let textured = m.texture.is_some();
    let base_color: Vec<f64> = if textured {
        vec![1.0; 4]
    } else {
        let d = p.diffuse.map(|v| short(finite(v)).clamp(0.0, 1.0));
        vec![d[0], d[1], d[2], 1.0]
    };
    let mut pbr = json!({
        "baseColorFactor": base_color,
        "metallicFactor": 0.0,
        "roughnessFactor": conv.perceptual_roughness,
    });
    if textured {
        pbr["baseColorTexture"] = json!({ "index": 0, "texCoord": 0 });
    }
    let mut root = json!({
        "asset": {
            "version": "2.0",
            "generator": concat!("Material Picker picker-extract ", env!("CARGO_PKG_VERSION")),
        },
        "extensionsUsed": ["KHR_materials_specular"],
        "materials": [{
            "name": m.name,
            "pbrMetallicRoughness": pbr,
            "extensions": {
                "KHR_materials_specular": {
                    "specularFactor": conv.specular_factor,
                    "specularColorFactor": conv.specular_color,
                }
            }
        }],
    });
    if textured {
        // 9729 LINEAR, 9987 LINEAR_MIPMAP_LINEAR, 10497 REPEAT.
        root["samplers"] = json!([{
            "magFilter": 9729,
            "minFilter": 9987,
            "wrapS": 10497,
            "wrapT": 10497,
        }]);
        root["images"] = json!([{ "uri": TEXTURE_PNG, "name": "texture" }]);
        root["textures"] = json!([{ "sampler": 0, "source": 0 }]);
    }
    sorted(root)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Prim names: letters, digits and `_` kept, anything else `_`, a leading
    /// digit or an empty name prefixed with `_`.
    #[test]
    fn usd_identifiers_are_valid_prim_names() {
        for (name, want) in [
            ("material_0", "material_0"),
            ("plain paint", "plain_paint"),
            ("3d wall", "_3d_wall"),
            ("", "_"),
            ("über-wand.1", "_ber_wand_1"),
            ("日本", "__"),
        ] {
            assert_eq!(usd_identifier(name), want, "{name:?}");
        }
    }

    /// The library layer: one referencing prim per entry, names made unique,
    /// paths quoted as USD asks, an unquotable path left out.
    #[test]
    fn usda_library_references_each_layer_once() {
        let e = |n: &str, l: &str| (n.to_string(), l.to_string());
        let text = usda_library_text(&[
            e("material_0", "material_0/material.usda"),
            e("a b", "a b/material.usda"),
            e("a_b", "a_b/material.usda"),
            e("odd", "x@y/material.usda"),
            e("bad", "x@@@y/material.usda"),
        ]);
        assert!(text.starts_with("#usda 1.0\n") && text.contains("defaultPrim = \"Materials\""));
        for (prim, path) in [
            ("material_0", "@material_0/material.usda@"),
            ("a_b", "@a b/material.usda@"),
            ("a_b_2", "@a_b/material.usda@"),
            ("odd", "@@@x@y/material.usda@@@"),
        ] {
            let def = format!("def \"{prim}\" (\n        prepend references = {path}\n    )");
            assert!(text.contains(&def), "{def}\n{text}");
        }
        assert!(!text.contains("bad") && !text.contains("x@@@y"));
        assert_eq!(text.matches('{').count(), text.matches('}').count());
        assert_eq!(text.matches("prepend references").count(), 4);
    }
}
