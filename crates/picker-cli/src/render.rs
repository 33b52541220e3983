//! `picker render`: re-render an image from a folder of render elements under
//! an environment map (`picker_render::rerender`, thesis eq. 3.7) and score it
//! against a reference photo; or, with `--preview`, render a material on a
//! sphere and a tile (`picker_render::preview_sphere` / `preview_tile`).
//!
//! Outputs (`--out DIR`): `render.exr` (linear RGB, f32), `render.png` (sRGB
//! 8-bit) and `render.json`; with `--reference`, `error.png` (a heat map of the
//! mean absolute sRGB difference, white at `HEATMAP_FULL_SCALE`) and the scores
//! (RMSE and PSNR, linear and sRGB, over pixels with a surface) in
//! `render.json`. `--preview` writes `preview_sphere.png` and `preview_tile.png`.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use picker_nets::conventions as conv;
use picker_render::render::HEATMAP_FULL_SCALE;
use picker_render::{io, EnvMap, Image, PhongMaterial, Quality, Shader};
use serde_json::json;

use crate::output;

/// Arguments of `picker render`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Folder of render elements as written by `picker infer` or `picker synth`
    /// (diffuse_albedo.exr, specular_albedo.exr, glossiness.exr, normals.exr, view_vector.exr).
    #[arg(
        value_name = "ELEMENTS_DIR",
        required_unless_present = "preview",
        conflicts_with = "preview"
    )]
    pub elements: Option<PathBuf>,
    /// Environment map: equirectangular, camera space, linear radiance (.exr or Radiance .hdr).
    #[arg(long, value_name = "FILE")]
    pub envmap: PathBuf,
    /// Reference image to score the render against: PNG (sRGB) or EXR (linear), the elements' size.
    #[arg(long, value_name = "FILE", conflicts_with = "preview")]
    pub reference: Option<PathBuf>,
    /// Output directory (created if needed; files of the same names are replaced).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Use the fast (prefiltered) renderer instead of exact quadrature.
    #[arg(long, conflicts_with = "continuous")]
    pub fast: bool,
    /// Read the env map as the continuous function its bilinear sampling makes of it (the fast
    /// renderer over upsamplings of the map fine enough for each glossy lobe), as `picker synth`
    /// renders `direct_env` and previews are rendered: exact quadrature over the map's own pixels
    /// shows its pixel grid in lobes narrower than them.
    #[arg(long)]
    pub continuous: bool,
    /// Render a material preview (sphere and tile; fast renderer) instead of re-rendering elements.
    #[arg(long, requires_all = ["diffuse", "specular", "exponent"])]
    pub preview: bool,
    /// Preview: diffuse albedo, linear RGB, each channel 0 to 1.
    #[arg(long, value_name = "R,G,B", value_parser = parse_rgb, requires = "preview")]
    pub diffuse: Option<[f32; 3]>,
    /// Preview: specular albedo, linear RGB, each channel 0 to 1.
    #[arg(long, value_name = "R,G,B", value_parser = parse_rgb, requires = "preview")]
    pub specular: Option<[f32; 3]>,
    /// Preview: Phong exponent n (glossiness g ↔ n = 2^(13g): 1 … 8192).
    #[arg(long, value_name = "N", value_parser = parse_exponent, requires = "preview")]
    pub exponent: Option<f32>,
    /// Preview: optional diffuse texture for the tile (PNG, sRGB; or EXR, linear).
    #[arg(long, value_name = "FILE", requires = "preview")]
    pub texture: Option<PathBuf>,
    /// Preview: exposure of the PNGs, `auto` (default: a white diffuse sphere under
    /// the envmap averages 0.75, so a material shows its own lightness whatever the
    /// map's scale) or a factor on the linear radiance (1: the radiance as it is);
    /// then identity up to 0.8, a soft roll-off above, sRGB.
    #[arg(long, value_name = "auto|FACTOR", default_value = "auto", value_parser = parse_exposure, requires = "preview")]
    pub exposure: Exposure,
    /// Preview: image side in pixels.
    #[arg(long, default_value_t = 256, value_parser = clap::value_parser!(u32).range(1..=4096))]
    pub size: u32,
    /// Worker threads (default: one per logical core).
    #[arg(long)]
    pub threads: Option<usize>,
}

/// The `--exposure` of a preview.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Exposure {
    /// Set by the lighting (`picker_render::preview_exposure`).
    Auto,
    /// This factor on the linear radiance.
    Factor(f32),
}

/// Parses `auto` or a finite factor > 0.
fn parse_exposure(s: &str) -> Result<Exposure, String> {
    if s.trim().eq_ignore_ascii_case("auto") {
        return Ok(Exposure::Auto);
    }
    match s.trim().parse::<f32>() {
        Ok(v) if v.is_finite() && v > 0.0 => Ok(Exposure::Factor(v)),
        _ => Err(format!(
            "expected `auto` or a factor > 0 such as 0.5, got {s:?}"
        )),
    }
}

/// Parses `R,G,B` (three finite values in `[0, 1]`).
fn parse_rgb(s: &str) -> Result<[f32; 3], String> {
    let bad = || format!("expected R,G,B with values in [0,1] such as 0.5,0.2,0.1, got {s:?}");
    let v: Vec<f32> = s
        .split(',')
        .map(|p| p.trim().parse::<f32>())
        .collect::<Result<_, _>>()
        .map_err(|_| bad())?;
    match v[..] {
        [r, g, b] if v.iter().all(|x| (0.0..=1.0).contains(x)) => Ok([r, g, b]),
        _ => Err(bad()),
    }
}

/// Parses a Phong exponent (finite, ≥ 0).
fn parse_exponent(s: &str) -> Result<f32, String> {
    match s.trim().parse::<f32>() {
        Ok(n) if n.is_finite() && n >= 0.0 => Ok(n),
        _ => Err(format!(
            "expected a Phong exponent ≥ 0 such as 64, got {s:?}"
        )),
    }
}

fn ms(t: Instant) -> f64 {
    (t.elapsed().as_secs_f64() * 1e6).round() / 1e3
}

/// A JSON number, or null for a non-finite value (an infinite PSNR).
fn num(v: f64) -> serde_json::Value {
    if v.is_finite() {
        json!(v)
    } else {
        serde_json::Value::Null
    }
}

/// Reads an image in linear values: EXR as is, PNG decoded from sRGB; refuses
/// NaN or infinite values (a corrupt EXR), naming the file.
fn read_linear(path: &Path) -> Result<Image> {
    let img = io::read_image(path)?;
    crate::extract::check_finite(path, &img)?;
    let is_png = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("png"));
    Ok(if is_png {
        img.map(io::srgb_decode)
    } else {
        img
    })
}

/// Creates the output folder, once every input has been read (a run
/// refused for its inputs leaves no empty folder).
fn make_out(out: &Path) -> Result<()> {
    std::fs::create_dir_all(out)
        .with_context(|| format!("creating output directory {}", out.display()))
}

/// Runs `picker render`.
pub fn run(a: Args) -> Result<()> {
    let t_total = Instant::now();
    crate::threads::init(a.threads)?;
    let env = EnvMap::read(&a.envmap).context("reading the environment map")?;
    // Real HDRIs hold a few slightly negative pixels (kept, as everywhere);
    // a map without any positive radiance lights nothing.
    if !env.data().iter().any(|v| v.max_element() > 0.0) {
        bail!(
            "{}: holds no light (no pixel has positive radiance)",
            a.envmap.display()
        );
    }
    if a.preview {
        return preview(&a, &env, t_total);
    }
    let Some(dir) = &a.elements else {
        bail!("give an ELEMENTS_DIR, or --preview");
    };
    let elements = picker_render::ElementImages::load(dir).context("reading render elements")?;
    let (h, w) = (elements.height(), elements.width());
    let reference = match &a.reference {
        Some(p) => {
            let r = read_linear(p).context("reading the reference image")?;
            if (r.height, r.width) != (h, w) {
                bail!(
                    "{}: reference is {}x{} but the render elements are {h}x{w}",
                    p.display(),
                    r.height,
                    r.width
                );
            }
            Some(r)
        }
        None => None,
    };

    let (quality, quality_name) = if a.continuous {
        (Quality::Continuous, "continuous")
    } else if a.fast {
        (Quality::Fast, "fast")
    } else {
        (Quality::Exact, "exact")
    };
    let t = Instant::now();
    let shader = Shader::new(&env, quality);
    let prepare_ms = ms(t);
    let t = Instant::now();
    let render = picker_render::rerender_with(&elements, &shader);
    let render_ms = ms(t);

    make_out(&a.out)?;
    io::write_exr(&a.out.join("render.exr"), &render)?;
    io::write_png(&a.out.join("render.png"), &picker_render::to_srgb(&render))?;
    let mut summary = json!({
        "format": "material-picker-render",
        "format_version": 1,
        "elements": dir.display().to_string(),
        "envmap": {"path": a.envmap.display().to_string(), "width": env.width(), "height": env.height()},
        "quality": quality_name,
        "width": w,
        "height": h,
        "files": ["render.exr", "render.png"],
    });
    let mut line = format!("rendered {h}x{w} ({quality_name}) to {}", a.out.display());
    if let (Some(reference), Some(path)) = (&reference, &a.reference) {
        let mask: Vec<bool> = (0..h * w).map(|i| elements.is_valid(i)).collect();
        let score = picker_render::compare(&render, reference, Some(&mask))?;
        let heat = picker_render::error_heatmap(&render, reference, Some(&mask))?;
        io::write_png(&a.out.join("error.png"), &heat)?;
        summary["files"] = json!(["render.exr", "render.png", "error.png"]);
        summary["reference"] = json!(path.display().to_string());
        summary["score"] = json!({
            "pixels": score.pixels,
            "rmse_linear": score.rmse_linear,
            "psnr_linear_db": num(score.psnr_linear),
            "rmse_srgb": score.rmse_srgb,
            "psnr_srgb_db": num(score.psnr_srgb),
            "over": "pixels with a surface (non-zero normal), all three channels; PSNR peak 1",
            "error_png": format!("mean |sRGB difference| per pixel, black 0 → red → yellow → white at {HEATMAP_FULL_SCALE}"),
        });
        line.push_str(&format!(
            "; vs {}: RMSE {:.4} linear, {:.4} sRGB; PSNR {:.2} dB sRGB",
            path.display(),
            score.rmse_linear,
            score.rmse_srgb,
            score.psnr_srgb
        ));
    }
    summary["timings_ms"] =
        json!({"prepare": prepare_ms, "render": render_ms, "total": ms(t_total)});
    let text = serde_json::to_string_pretty(&summary).context("serialising render.json")?;
    output::write_atomic(&a.out.join("render.json"), format!("{text}\n").as_bytes())?;
    println!("{line}");
    Ok(())
}

/// `picker render --preview`.
fn preview(a: &Args, env: &EnvMap, t_total: Instant) -> Result<()> {
    let (Some(d), Some(s), Some(n)) = (a.diffuse, a.specular, a.exponent) else {
        bail!("--preview needs --diffuse, --specular and --exponent");
    };
    let material = PhongMaterial {
        diffuse: d.into(),
        specular: s.into(),
        exponent: n,
    };
    let texture = match &a.texture {
        Some(p) => Some(read_linear(p).context("reading the texture")?),
        None => None,
    };
    let size = a.size as usize;
    let shader = Shader::resolving(env);
    let sphere = picker_render::render::preview_sphere_with(&material, &shader, size);
    let tile = picker_render::render::preview_tile_with(&material, &shader, size, texture.as_ref());
    let exposure = match a.exposure {
        Exposure::Auto => picker_render::preview_exposure(&shader),
        Exposure::Factor(f) => f,
    };
    let shown = |img: &Image| Image {
        data: conv::expose_rgb(&img.data, exposure),
        ..img.clone()
    };
    make_out(&a.out)?;
    io::write_png(&a.out.join("preview_sphere.png"), &shown(&sphere))?;
    io::write_png(&a.out.join("preview_tile.png"), &shown(&tile))?;
    println!(
        "wrote preview_sphere.png and preview_tile.png ({size}x{size}, exposure {}) to {} in {:.2} s",
        if (1e-3..1e4).contains(&exposure) { format!("{exposure:.4}") } else { format!("{exposure:.3e}") },
        a.out.display(),
        t_total.elapsed().as_secs_f64()
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_values() {
        assert_eq!(parse_rgb("0.5, 0.25,1"), Ok([0.5, 0.25, 1.0]));
        assert!(parse_rgb("0.5,0.2").is_err());
        assert!(parse_rgb("2,0,0").is_err());
        assert!(parse_rgb("a,b,c").is_err());
        assert_eq!(parse_exponent("64"), Ok(64.0));
        assert_eq!(parse_exposure("auto"), Ok(Exposure::Auto));
        assert_eq!(parse_exposure("AUTO"), Ok(Exposure::Auto));
        assert_eq!(parse_exposure("0.5"), Ok(Exposure::Factor(0.5)));
        assert!(parse_exposure("0").is_err());
        assert!(parse_exposure("-1").is_err());
        assert!(parse_exposure("nan").is_err());
        assert!(parse_exposure("bright").is_err());
        assert!(parse_exponent("-1").is_err());
        assert!(parse_exponent("inf").is_err());
    }
}
