//! `picker extract`: the product's main job — the material under a picked
//! point as a tileable texture, Phong parameters and exports.
//!
//! The networks run once per photo (or `--elements DIR` supplies render
//! elements, e.g. a synthetic scene's ground truth or a `picker infer` output);
//! every pick (`--pick` repeated, or `--all`) shares that inference. With one
//! pick the files go straight into `--out`; with several, each material gets
//! `--out/<name>/` and the shared files (`envmap.exr`, `summary.json`,
//! `palette_ids.png` for `--all`) stay at the top.
//!
//! The pieces ([`Models`], [`load_inputs`], [`write_materials`]) are shared
//! with `picker batch`, which loads the networks once for a folder of photos.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{anyhow, bail, Context, Result};
use picker_extract::export::{self, ExportOptions};
use picker_extract::mask::{Mask, MaskOptions};
use picker_extract::report::{self, Tile};
use picker_extract::{
    pipeline, Inputs, LensChoice, Material, PassDisagreement, Prepared, Quad, UserPlane, UvChoice,
};
use picker_inpaint::{DiffusionInpainter, Inpainter, LearnedInpainter, PatchMatchInpainter};
use picker_nets::conventions as conv;
use picker_nets::mirror;
use picker_nets::{Net, NetKind};
use picker_render::io::{self as rio, Image};
use picker_render::{ElementImages, EnvMap, Shader};
use picker_tensor::Tensor;
use serde_json::{json, Value};

use crate::photo;
use crate::staging::Staging;

/// `--uv` values.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum UvArg {
    /// The predicted texture coordinates.
    Net,
    /// A plane fitted to the predicted normals, rectified by a homography.
    Plane,
    /// The more consistent of the two.
    Auto,
}

impl UvArg {
    /// The pipeline's choice for this flag.
    pub fn choice(self) -> UvChoice {
        match self {
            UvArg::Net => UvChoice::Net,
            UvArg::Plane => UvChoice::Plane,
            UvArg::Auto => UvChoice::Auto,
        }
    }
}

/// How materials are extracted: the flags `picker extract` and `picker batch` share.
#[derive(Clone, Debug, clap::Args)]
pub struct Flags {
    /// Network weights: a directory with irn/msn[/envmap].safetensors, or files.
    /// Default: the `lite` weights embedded in the binary.
    #[arg(long, value_name = "DIR_OR_FILE")]
    pub weights: Vec<PathBuf>,
    /// Smallest image fraction of a material for --all.
    #[arg(long, default_value_t = 0.02)]
    pub min_area: f64,
    /// Long side of the networks' working resolution.
    #[arg(long, default_value_t = 320, value_parser = clap::value_parser!(u32).range(8..=4096))]
    pub work_size: u32,
    /// Run the networks once. By default they run twice, on the photo and on its mirror image,
    /// and the outputs that mirror with the photo (albedos, glossiness, normals, view vectors,
    /// segmentation, lighting) are averaged: better estimates for twice the networks' time.
    #[arg(long)]
    pub single_pass: bool,
    /// Keep only the connected region at the pick.
    #[arg(long)]
    pub connected: bool,
    /// Keep only the picked colour of a two-colour pattern (a chessboard's black squares, a
    /// striped fabric's dark stripes) instead of the whole pattern. By default an automatic mask
    /// whose surroundings are mostly one other material, interleaved with it, takes it in.
    #[arg(long)]
    pub no_pattern: bool,
    /// Keep the regions the photo sets apart in a mask of the networks' segmentation. By default
    /// a region that looks different in the photo (chromaticity) and that the segmentation also
    /// gives another colour, one object rather than a repeated element of a pattern (a plant in
    /// front of the picked wallpaper, the objects on a picked table), leaves the mask.
    #[arg(long)]
    pub no_split: bool,
    /// Segmentation-colour tolerance (an RGB distance, 0 to 1, in the segmentation the masks read:
    /// the network's, smoothed along the photo; with an MSN that has a material embedding, as the
    /// embedded one does, a distance in the embedding scaled by 0.25); default automatic. A given
    /// tolerance is applied as it is: without the automatic mode's leak guard, which stops the
    /// mask at the segmentation's edge with clearly other colours (give one when the automatic
    /// mask stops short on a strongly shaded or vignetted surface).
    #[arg(long)]
    pub tolerance: Option<f32>,
    /// Texture coordinates: predicted UVs, a rectified plane, or the more consistent.
    #[arg(long, value_enum, default_value_t = UvArg::Auto)]
    pub uv: UvArg,
    /// Vertical field of view in degrees for --uv plane (default: from the view vectors).
    #[arg(long)]
    pub fov: Option<f32>,
    /// The surface's orientation instead of the predicted one: `front` (facing the camera: a
    /// scan, a head-on photo of a floor, a wall or a fabric) or `X,Y,Z`, its normal in camera
    /// space (x right, y up, z towards the camera). That plane is rectified as --uv plane
    /// rectifies the predicted one, without refining it by the photo's lines.
    #[arg(long, value_name = "front|X,Y,Z", value_parser = parse_normal, allow_hyphen_values = true)]
    pub normal: Option<UserPlane>,
    /// The lens distortion the plane mode undoes before rectifying: `auto` (estimated from the
    /// photo's long straight edges; barrel distortion only, none when they do not agree), `none`,
    /// or the division model's coefficient (radii in half-diagonals of the photo; negative for
    /// barrel distortion, e.g. -0.15 for a wide-angle webcam; material.json reports the one used
    /// under `diagnostics.uv.lens`).
    #[arg(long, value_name = "auto|none|LAMBDA", default_value = "auto", value_parser = parse_lens, allow_hyphen_values = true)]
    pub lens: LensChoice,
    /// Keep the predicted normals' plane for --uv plane: do not refine it with the vanishing
    /// directions of the photo's straight lines in the picked region.
    #[arg(long)]
    pub no_lines: bool,
    /// Keep the plane mode's texture axes where the photo's lines give none: do not turn them
    /// to the direction the texture's pattern runs along (a table's wood grain).
    #[arg(long)]
    pub no_grain: bool,
    /// Do not use a texture's repeats: keep the whole rectified region for --uv plane (no fold of
    /// a texture that repeats along both axes into one tile of whole periods), and do not fill the
    /// holes of a net-UV texture square that repeats a whole number of times from its other
    /// repeats (the inpainter fills them all).
    #[arg(long)]
    pub no_fold: bool,
    /// Fold a texture whose repeat is centred (a checkerboard, bricks in running bond: it also
    /// repeats shifted by half a period along both axes) only by its periods, not a second time
    /// by that shift (which pools twice the pixels into each texel).
    #[arg(long)]
    pub no_centring: bool,
    /// Inpaint every texel the mask's surest part did not show, instead of first filling them
    /// from the rest of the mask (its less sure pixels) where it showed them.
    #[arg(long)]
    pub no_mask_fill: bool,
    /// Keep the observed texels along the wrap edges even when the two sides of an edge differ
    /// (by default a band across each such edge is inpainted so the texture tiles without a seam).
    #[arg(long)]
    pub keep_seams: bool,
    /// Inpaint a band across a rectified crop's wrap edges where its sides differ instead of
    /// first cutting each edge through the crop's observed surroundings where the two sides look
    /// alike (the cut keeps the observed texels; with no surroundings seen and no --size, a tile
    /// 7/8 of the side, or smaller down to half, is folded within the observed square; an edge
    /// whose cut would show gets the band either way).
    #[arg(long)]
    pub no_seam_cut: bool,
    /// Keep the texture's level as the part of the material it came from shows it. By default a
    /// texture whose mean luminance lies outside the quartiles of the material's local mean
    /// luminances (its de-lit colours averaged over about a quarter of the texture's square,
    /// where they have the texture's chromaticity) is scaled, all channels alike, to the nearer
    /// quartile, by at most 8x: a texture taken from a vignetted corner or a shadow gets the
    /// material's level (material.json diagnostics.level).
    #[arg(long)]
    pub keep_level: bool,
    /// The de-lighting's shading where the networks estimated the albedo: the ratio of their
    /// albedo to the photo is taken over a Gaussian window of the material's pixels of this many
    /// working pixels (the ratio of the two's local sums, so a print's dark channels do not tint
    /// their surroundings), so the texture's detail comes from the photo and its level and colour from
    /// the network (0: the network's albedo as it is at the working resolution, which is the
    /// texture itself for a photo no larger than it). Albedo given with --elements from a
    /// renderer is exact and used as it is.
    #[arg(long, value_name = "PX", default_value_t = picker_extract::shading::SHADING_SIGMA,
          value_parser = parse_sigma, allow_negative_numbers = true)]
    pub shading_sigma: f32,
    /// Texture side in texels (default: the observed texel density, capped by --max-size). A side
    /// above the observed density is made at that side where the photo's pixels cover it (many
    /// repeats, a near view), else at the observed side and enlarged (bicubic) at the end.
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=8192))]
    pub size: Option<u32>,
    /// Cap of the automatic texture side.
    #[arg(long, default_value_t = 1024, value_parser = clap::value_parser!(u32).range(16..=8192))]
    pub max_size: u32,
    /// Do not make the texture tileable (no toroidal inpainting).
    #[arg(long)]
    pub no_tile: bool,
    /// Where the texture's wrap seams show (seam ratio above 1.25), replace it
    /// by its periodic component (Moisan 2011): removes colour jumps across
    /// the edges left by uneven lighting, at the cost of a smooth change of
    /// colour near them; patterns cut at an edge stay cut. Off by default: on
    /// synthetic scenes it cost 0.7-0.9 dB of texture PSNR.
    #[arg(long, conflicts_with = "no_tile")]
    pub seamless: bool,
    /// Even out broad light and dark patches the de-lighting left in the texture: its brightness
    /// divided by a blur of it, SCALE times the texture's side wide (default 0.125 when given
    /// without a value), that wraps around the edges (mirrors them with --no-tile); colour and
    /// fine detail stay. Off by default: it also flattens a pattern whose own light and dark
    /// areas are that wide (a chessboard of few squares, a marble's veins).
    #[arg(long, value_name = "SCALE", num_args = 0..=1, default_missing_value = "0.125")]
    pub even_out: Option<f64>,
    /// Inpainter: `patchmatch` (default), `diffusion`, or a learned inpainter's weights file.
    #[arg(long, default_value = "patchmatch", value_name = "NAME_OR_FILE")]
    pub inpainter: String,
    /// Write texture.png with 16 bits per channel.
    #[arg(long = "16bit")]
    pub sixteen_bit: bool,
    /// Seed of every random choice (inpainting).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Refuse photos with more pixels than this many megapixels (decompression
    /// bombs). Extraction holds about 64 bytes per photo pixel at its peak.
    #[arg(long, default_value_t = 100.0)]
    pub max_megapixels: f64,
    /// Photos with more pixels than this many megapixels are analysed at this
    /// size: area-downsampled (aspect ratio kept) before the masks, de-lighting,
    /// coordinates and reprojection, which otherwise run at the photo's full
    /// resolution. The networks see the same input either way, and --pick,
    /// --quad, --mask and the outputs (mask.png, material.json's pick) stay in
    /// the photo's own pixels. The texture's automatic size follows the
    /// analysed pixels' density: one that reaches --max-size at full
    /// resolution mostly still does, one sized below it (a far, small or
    /// grazing surface) comes out up to √(photo MP / this) times smaller a
    /// side. Raise this (0: always the full resolution) for those, at ~0.2 s
    /// and ~64 bytes per extra pixel. Not with --elements (the render
    /// elements keep the photo's own size).
    #[arg(long, default_value_t = DEFAULT_ANALYSIS_MEGAPIXELS, value_name = "MP", allow_negative_numbers = true)]
    pub analysis_megapixels: f64,
}

/// Default of `--analysis-megapixels`: above a 12-megapixel phone photo, so
/// those are analysed at their full resolution.
pub const DEFAULT_ANALYSIS_MEGAPIXELS: f64 = 16.0;

/// The size a photo is analysed at when it has more pixels than
/// `--analysis-megapixels` allows, and the mapping between its pixels and
/// the photo's (pixel centres at integer coordinates, as `--pick` and `--quad`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Analysis {
    /// The photo's size `(width, height)` as decoded (EXIF orientation applied).
    pub original: (usize, usize),
    /// The size `(width, height)` the extraction works at.
    pub size: (usize, usize),
}

impl Analysis {
    /// The analysis size of a `w × h` photo under a cap of `megapixels`
    /// (`None` when it fits, the cap is 0 or the photo has no pixels): the
    /// aspect ratio kept, each side rounded and at least 1 (a strip one
    /// pixel wide keeps that pixel and gets the cap's pixels along its length).
    pub fn for_photo(w: usize, h: usize, megapixels: f64) -> Option<Self> {
        let pixels = (w as f64) * (h as f64);
        let cap = megapixels * 1e6;
        if megapixels <= 0.0 || pixels <= cap || w == 0 || h == 0 {
            return None;
        }
        let s = (cap / pixels).sqrt();
        let side = |n: usize| ((n as f64 * s).round() as usize).clamp(1, n);
        // A side that cannot shrink below 1 pixel (a strip) leaves the
        // other the rest of the pixels.
        let size = match (side(w), side(h)) {
            (1, _) => (1, (cap.round() as usize).clamp(1, h)),
            (_, 1) => ((cap.round() as usize).clamp(1, w), 1),
            wh => wh,
        };
        (size != (w, h)).then_some(Self {
            original: (w, h),
            size,
        })
    }

    /// The analysis pixel whose area holds the centre of photo pixel `p`
    /// (`p` inside the photo).
    pub fn pick(&self, p: [u32; 2]) -> [u32; 2] {
        let cell = |v: u32, from: usize, to: usize| {
            (((2 * u64::from(v) + 1) * to as u64) / (2 * from as u64)).min(to as u64 - 1) as u32
        };
        [
            cell(p[0], self.original.0, self.size.0),
            cell(p[1], self.original.1, self.size.1),
        ]
    }

    /// The photo pixel whose area holds the centre of analysis pixel `p`.
    pub fn pick_back(&self, p: [u32; 2]) -> [u32; 2] {
        Analysis {
            original: self.size,
            size: self.original,
        }
        .pick(p)
    }

    /// A point in photo pixels (pixel centres at integers, fractions
    /// allowed) in analysis pixels.
    pub fn point(&self, p: [f32; 2]) -> [f32; 2] {
        let map = |v: f32, from: usize, to: usize| {
            ((f64::from(v) + 0.5) * to as f64 / from as f64 - 0.5) as f32
        };
        [
            map(p[0], self.original.0, self.size.0),
            map(p[1], self.original.1, self.size.1),
        ]
    }

    /// The photo's pixels, interleaved RGB (`[h, w, 3]`, row-major), as
    /// planar RGB (`[3, h', w']`) at the analysis size: each pixel the mean
    /// of the photo's pixels under its area, weighted by how much of each it
    /// covers, rounded to a 16-bit code (`k / 65535`). Rows in parallel,
    /// each value one fixed-order sum (the same bits for any thread count).
    pub fn downsample_rgb(&self, rgb: &[f32]) -> Vec<f32> {
        // 16-bit codes (`k / 65535`, ≤ 7.6e-6 from the mean): the
        // preparation decodes those from a table, not by `powf`.
        let code = |v: f32| ((v.clamp(0.0, 1.0) * 65535.0 + 0.5) as u32) as f32 / 65535.0;
        picker_extract::resample::area_interleaved_rgb(rgb, self.original, self.size, code)
    }

    /// A mask at the photo's size at the analysis size: a pixel is in where
    /// at least half its area is (area average ≥ ½).
    pub fn downsample_mask(&self, data: &[bool]) -> Vec<bool> {
        let ((w, h), (aw, ah)) = (self.original, self.size);
        let f: Vec<f32> = data.iter().map(|&b| f32::from(u8::from(b))).collect();
        picker_extract::resample::area_plane(&f, w, h, aw, ah)
            .into_iter()
            .map(|v| v >= 0.5)
            .collect()
    }

    /// A one-channel mask image at the analysis size back at the photo's
    /// size: bilinear, then 1 where at least ½, else 0.
    pub fn upsample_mask(&self, mask: &Image) -> Image {
        let ((w, h), (aw, ah)) = (self.original, self.size);
        let data = picker_extract::resample::bilinear_plane(mask.plane(0), aw, ah, w, h)
            .into_iter()
            .map(|v| if v >= 0.5 { 1.0 } else { 0.0 })
            .collect();
        Image {
            channels: 1,
            height: h,
            width: w,
            data,
        }
    }

    /// `photo.json`'s description of the analysis size.
    pub fn describe(&self) -> Value {
        json!({
            "width": self.size.0,
            "height": self.size.1,
            "scale": self.size.0 as f64 / self.original.0 as f64,
            "rule": "the photo had more pixels than --analysis-megapixels: masks, de-lighting, coordinates and reprojection ran on this area-downsampled copy (sRGB values averaged over each pixel's area); the networks saw the same input as at full resolution; pick, quad and mask.png are in the photo's own pixels, the diagnostics' pixel quantities (focal_px, companion_pick) in the analysis copy's; the texture's automatic size follows the analysed pixels' density",
        })
    }
}

impl Flags {
    /// Checks the values clap cannot check.
    pub fn validate(&self) -> Result<()> {
        if !(0.0..1.0).contains(&self.min_area) {
            bail!("--min-area {} must be in [0, 1)", self.min_area);
        }
        if let Some(t) = self.tolerance {
            if !(t > 0.0 && t <= 1.0) {
                bail!("--tolerance {t} must be in (0, 1]");
            }
        }
        if self.normal.is_some() && self.uv == UvArg::Net {
            bail!("--normal gives the plane to rectify: it cannot be used with --uv net");
        }
        if let Some(f) = self.fov {
            if !(1.0..=179.0).contains(&f) {
                bail!("--fov {f} must be between 1 and 179 degrees");
            }
        }
        if !(self.max_megapixels.is_finite() && self.max_megapixels > 0.0) {
            bail!(
                "--max-megapixels {} must be a positive, finite number",
                self.max_megapixels
            );
        }
        if let Some(s) = self.even_out {
            check_even_out(s)?;
        }
        if !(self.analysis_megapixels.is_finite() && self.analysis_megapixels >= 0.0) {
            bail!(
                "--analysis-megapixels {} must be a finite number, 0 or more (0: the full resolution)",
                self.analysis_megapixels
            );
        }
        Ok(())
    }

    /// The pipeline options (the inpainter is passed separately).
    pub fn options<'a>(&self, inpainter: &'a dyn Inpainter) -> pipeline::Options<'a> {
        pipeline::Options {
            mask: self.mask_options(),
            uv: self.uv.choice(),
            size: self.size.map(|s| s as usize),
            max_size: self.max_size as usize,
            fov_deg: self.fov,
            plane: self.normal,
            quad_size_m: None,
            line_refine: !self.no_lines,
            align_grain: !self.no_grain,
            fold_period: !self.no_fold,
            fold_centring: !self.no_centring,
            fill_from_mask: !self.no_mask_fill,
            heal_seams: !self.keep_seams,
            cut_seams: !self.no_seam_cut,
            shading_sigma: self.shading_sigma,
            wrap_placement: true,
            tileable: !self.no_tile,
            seamless: self.seamless,
            even_out: self.even_out,
            level: !self.keep_level,
            seed: self.seed,
            inpainter,
        }
    }

    fn mask_options(&self) -> MaskOptions {
        MaskOptions {
            connected: self.connected,
            tolerance: self.tolerance,
            no_pattern: self.no_pattern,
            no_split: self.no_split,
        }
    }

    /// The photo limits (decompression bombs).
    pub fn photo_limits(&self) -> photo::PhotoLimits {
        let max_pixels = (self.max_megapixels * 1e6) as u64;
        photo::PhotoLimits {
            max_pixels,
            // The decoders' buffers for the largest photo allowed.
            max_alloc: max_pixels
                .saturating_mul(picker_extract::photo::PEAK_BYTES_PER_PIXEL)
                .max(picker_extract::photo::DEFAULT_MAX_ALLOC),
        }
    }

    /// Every setting that changes the outputs, as JSON (the batch manifest
    /// compares it to decide whether a finished photo is stale).
    pub fn output_settings(&self) -> Value {
        json!({
            "min_area": self.min_area,
            "work_size": self.work_size,
            "mirror_pass": !self.single_pass,
            "connected": self.connected,
            "tolerance": self.tolerance,
            "pattern": !self.no_pattern,
            "split": !self.no_split,
            "uv": format!("{:?}", self.uv).to_lowercase(),
            "fov": self.fov,
            "normal": self.normal.map(|p| match p {
                UserPlane::Normal(n) => json!(n.to_array()),
                UserPlane::Quad(q) => json!(q.0),
            }),
            "lines": !self.no_lines,
            "lens": match self.lens {
                LensChoice::Auto => json!("auto"),
                LensChoice::Given(v) => json!(v),
            },
            "grain": !self.no_grain,
            "fold": !self.no_fold,
            "centring": !self.no_centring,
            "mask_fill": !self.no_mask_fill,
            "heal_seams": !self.keep_seams,
            "seam_cut": !self.no_seam_cut,
            "level": !self.keep_level,
            "shading_sigma": self.shading_sigma,
            "size": self.size,
            "max_size": self.max_size,
            "tileable": !self.no_tile,
            "seamless": self.seamless,
            "even_out": self.even_out,
            "inpainter": self.inpainter,
            "sixteen_bit": self.sixteen_bit,
            "seed": self.seed,
            "precision": picker_tensor::precision().name(),
            "analysis_megapixels": self.analysis_megapixels,
        })
    }
}

/// Arguments of `picker extract`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The photograph (PNG, JPEG, TIFF, WebP, BMP, EXR or HDR). Optional with --elements
    /// (then DIR/image.png, or DIR/input.png for a `picker infer` folder).
    #[arg(value_name = "PHOTO")]
    pub photo: Option<PathBuf>,
    /// A point on the material, `X,Y` in photo pixels (x right, y down, after EXIF
    /// orientation). May be repeated.
    #[arg(long, value_name = "X,Y", value_parser = parse_pick, allow_hyphen_values = true)]
    pub pick: Vec<[u32; 2]>,
    /// Extract every material covering at least --min-area of the image (a palette).
    #[arg(long)]
    pub all: bool,
    /// Four corners of a rectangle on the picked surface (a tile, a board, a sheet of paper or a
    /// book lying on it), `X1,Y1,X2,Y2,X3,Y3,X4,Y4` in photo pixels (as --pick; fractions
    /// allowed), in order around it. Its plane is rectified instead of the predicted one (not
    /// refined by the photo's lines), the texture's axes along its sides; the focal length comes from it when it tells it (a rectangle seen at an
    /// angle), else from --fov or the photo as usual. Without --pick it picks the quad's
    /// centre. One material: not with several picks, --all or --normal.
    #[arg(long, value_name = "X1,Y1,..,X4,Y4", value_parser = parse_quad, allow_hyphen_values = true, conflicts_with_all = ["all", "normal"])]
    pub quad: Option<Quad>,
    /// The real size of the --quad's rectangle, `WxH` (first side, corner 1 to 2, by the second,
    /// 2 to 3) in metres, or with a unit: `210x297mm` (a sheet of A4), `30x30cm` (a floor tile),
    /// `8.5x11in`. It gives the rectified plane its scale, so material.json gives the texture's
    /// size on the surface (`texture.size_m`: repeat it every that many metres).
    #[arg(long, value_name = "WxH[mm|cm|m|in]", value_parser = parse_size_m, requires = "quad")]
    pub quad_size: Option<[f32; 2]>,
    /// The material's pixels, instead of the segmentation's at the pick: a mask image the
    /// photo's size as a viewer shows it, or another size of its aspect ratio (scaled to it),
    /// white on black or a selection exported with transparency (its alpha); or `quad` for the
    /// --quad's interior (`./quad` for a file of that name). One material; the pick, if given, must lie in it (default: the mask's pixel
    /// nearest its centroid).
    #[arg(long, value_name = "FILE|quad", value_parser = parse_mask, conflicts_with_all = ["all", "tolerance", "connected"])]
    pub mask: Option<MaskArg>,
    /// Render elements instead of the networks: a folder with diffuse_albedo.exr,
    /// specular_albedo.exr, glossiness.exr, normals.exr, view_vector.exr, uv.exr,
    /// segmentation.exr and optionally embedding.exr and envmap.exr (as `picker synth` or
    /// `picker infer` write).
    #[arg(long, value_name = "DIR", conflicts_with = "weights")]
    pub elements: Option<PathBuf>,
    /// Output directory (default: `<photo stem>.material/` next to the photo).
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// The extraction settings.
    #[command(flatten)]
    pub flags: Flags,
    /// Print the summary as JSON on stdout.
    #[arg(long)]
    pub json: bool,
    /// Leave timings and thread counts out of material.json and summary.json,
    /// so that the same inputs give byte-identical files (golden tests).
    #[arg(long)]
    pub no_timings: bool,
    /// Worker threads (default: one per logical core).
    #[arg(long)]
    pub threads: Option<usize>,
}

/// Refuses an `--even-out` scale outside `(0, 1]`.
pub fn check_even_out(s: f64) -> Result<()> {
    if !(s > 0.0 && s <= 1.0) {
        bail!("--even-out {s} must be in (0, 1] (a fraction of the texture's side)");
    }
    Ok(())
}

/// Parses `--normal`: `front`, or `X,Y,Z` (any length but zero).
pub fn parse_normal(s: &str) -> std::result::Result<UserPlane, String> {
    if s.trim().eq_ignore_ascii_case("front") {
        return Ok(UserPlane::FRONT);
    }
    let v = parse_numbers::<3>(s, "front or X,Y,Z (e.g. 0,0.7,0.7)")?;
    UserPlane::normal(v)
}

/// Parses `--lens`: `auto`, `none`, or a division-model coefficient within
/// [`picker_extract::lens::LAMBDA_MIN`]..=[`picker_extract::lens::LAMBDA_MAX`].
pub fn parse_lens(s: &str) -> std::result::Result<LensChoice, String> {
    let t = s.trim();
    if t.eq_ignore_ascii_case("auto") {
        return Ok(LensChoice::Auto);
    }
    if t.eq_ignore_ascii_case("none") {
        return Ok(LensChoice::Given(0.0));
    }
    let (lo, hi) = (
        picker_extract::lens::LAMBDA_MIN,
        picker_extract::lens::LAMBDA_MAX,
    );
    match t.parse::<f32>() {
        Ok(v) if (lo..=hi).contains(&v) => Ok(LensChoice::Given(v)),
        Ok(v) => Err(format!(
            "lens coefficient {v} is outside {lo}..={hi} (negative: barrel distortion)"
        )),
        Err(_) => Err(format!(
            "expected auto, none or a number such as -0.15, found {s:?}"
        )),
    }
}

/// Parses `--quad`: eight pixel coordinates `X1,Y1,X2,Y2,X3,Y3,X4,Y4`.
pub fn parse_quad(s: &str) -> std::result::Result<Quad, String> {
    let v = parse_numbers::<8>(
        s,
        "X1,Y1,X2,Y2,X3,Y3,X4,Y4 (e.g. 10,20,200,30,190,150,15,140)",
    )?;
    Ok(Quad([
        [v[0], v[1]],
        [v[2], v[3]],
        [v[4], v[5]],
        [v[6], v[7]],
    ]))
}

/// Largest relative difference between a `--mask`'s aspect ratio and the
/// photo's for a mask of another size to be scaled to the photo.
pub const MASK_ASPECT_TOLERANCE: f64 = 0.01;

/// Where `--mask` takes the material's pixels from.
#[derive(Clone, Debug, PartialEq)]
pub enum MaskArg {
    /// A mask image.
    File(PathBuf),
    /// The `--quad`'s interior ([`Quad::interior`]).
    Quad,
}

/// Parses `--mask`: `quad`, or a file.
pub fn parse_mask(s: &str) -> std::result::Result<MaskArg, String> {
    match s {
        "" => Err("expected a mask image or `quad`".into()),
        "quad" => Ok(MaskArg::Quad),
        f => Ok(MaskArg::File(PathBuf::from(f))),
    }
}

/// Parses `--quad-size`: `WxH` in metres, or with a unit suffix (`mm`,
/// `cm`, `m`, `in`) for both; positive, finite.
pub fn parse_size_m(s: &str) -> std::result::Result<[f32; 2], String> {
    let t = s.trim();
    let (num, scale) = [("mm", 1e-3), ("cm", 1e-2), ("in", 0.0254), ("m", 1.0)]
        .iter()
        .find_map(|&(u, k)| t.strip_suffix(u).map(|n| (n, k)))
        .unwrap_or((t, 1.0));
    let (w, h) = num.split_once(['x', 'X', '×']).ok_or_else(|| {
        format!("expected WxH with an optional unit (e.g. 210x297mm, 0.3x0.3), got {s:?}")
    })?;
    let v = |x: &str| {
        x.trim()
            .parse::<f64>()
            .ok()
            .filter(|v| v.is_finite() && *v > 0.0)
            .map(|v| (v * scale) as f32)
            .filter(|v| v.is_finite() && *v > 0.0)
            .ok_or_else(|| format!("{x:?} in {s:?} is not a positive size"))
    };
    Ok([v(w)?, v(h)?])
}

/// `N` comma-separated finite numbers.
fn parse_numbers<const N: usize>(s: &str, expected: &str) -> std::result::Result<[f32; N], String> {
    let parts: Vec<&str> = s.split(',').collect();
    if parts.len() != N {
        return Err(format!(
            "expected {expected}, got {s:?} ({} values)",
            parts.len()
        ));
    }
    let mut out = [0.0f32; N];
    for (o, v) in out.iter_mut().zip(&parts) {
        *o = v
            .trim()
            .parse::<f32>()
            .ok()
            .filter(|x| x.is_finite())
            .ok_or_else(|| format!("{v:?} in {s:?} is not a finite number"))?;
    }
    Ok(out)
}

/// Parses `X,Y` pixel coordinates.
pub fn parse_pick(s: &str) -> std::result::Result<[u32; 2], String> {
    let (x, y) = s
        .split_once(',')
        .ok_or_else(|| format!("expected X,Y (e.g. 120,88), got {s:?}"))?;
    let p = |v: &str| {
        v.trim()
            .parse::<u32>()
            .map_err(|_| format!("{v:?} in {s:?} is not a pixel coordinate (a whole number ≥ 0)"))
    };
    Ok([p(x)?, p(y)?])
}

fn tensor_image(t: &Tensor) -> Image {
    Image {
        channels: t.c(),
        height: t.h(),
        width: t.w(),
        data: t.image(0).to_vec(),
    }
}

fn ms(t: Instant) -> f64 {
    (t.elapsed().as_secs_f64() * 1e6).round() / 1e3
}

/// One loaded network.
struct LoadedNet {
    path: PathBuf,
    embedded: Option<&'static [u8]>,
    kind: NetKind,
    preset: String,
    net: Net,
}

/// The networks of `--weights`, loaded once and shared by every photo.
pub struct Models {
    nets: Vec<LoadedNet>,
    mirror_pass: bool,
}

impl Models {
    /// Loads the weights of `--weights` (directories or files; none: the embedded
    /// defaults); IRN and MSN are required.
    pub fn load(weights: &[PathBuf]) -> Result<Self> {
        let chosen = crate::infer::resolve_weights(weights)?;
        let has = |k| chosen.iter().any(|c| c.weights.kind() == k);
        if !has(NetKind::Irn) {
            bail!("no IRN weights among --weights (picker extract needs irn.safetensors and msn.safetensors)");
        }
        if !has(NetKind::Msn) {
            bail!("no MSN weights among --weights (picker extract needs irn.safetensors and msn.safetensors)");
        }
        let mut nets = Vec::new();
        for c in chosen {
            let net =
                Net::load(&c.weights).with_context(|| format!("loading {}", c.path.display()))?;
            nets.push(LoadedNet {
                kind: c.weights.kind(),
                preset: c.weights.preset().to_string(),
                path: c.path,
                embedded: c.embedded,
                net,
            });
        }
        Ok(Self {
            nets,
            mirror_pass: true,
        })
    }

    /// Whether each network also runs on the mirrored photo, the outputs that
    /// mirror with it averaged ([`picker_nets::mirror`]; the default), or
    /// runs once (`--single-pass`).
    pub fn with_mirror_pass(mut self, on: bool) -> Self {
        self.mirror_pass = on;
        self
    }

    /// The weights files, in network order (`<embedded lite>/FILE` for the defaults).
    pub fn paths(&self) -> Vec<&Path> {
        self.nets.iter().map(|n| n.path.as_path()).collect()
    }

    /// The bytes of each weights file that is embedded in the binary (`None` for
    /// a file on disk), in the order of [`Models::paths`].
    pub fn embedded_bytes(&self) -> Vec<Option<&'static [u8]>> {
        self.nets.iter().map(|n| n.embedded).collect()
    }

    /// Runs the networks on the photo (sRGB, `[0, 1]`) at `work_size` (long side).
    fn infer(
        &self,
        photo_rgb: &image::Rgb32FImage,
        work_size: u32,
        timings: &mut serde_json::Map<String, Value>,
    ) -> Result<Inferred> {
        let (pw, ph) = photo_rgb.dimensions();
        let (ww, wh) = photo::working_size(pw, ph, work_size);
        self.infer_work(&photo::resize(photo_rgb, ww, wh), timings)
    }

    /// [`Models::infer`] of the photo already resized to the working size.
    fn infer_work(
        &self,
        work: &image::Rgb32FImage,
        timings: &mut serde_json::Map<String, Value>,
    ) -> Result<Inferred> {
        let (ww, wh) = work.dimensions();
        let mut x = Tensor::new([1, 3, wh as usize, ww as usize], photo::to_planar(work))
            .map_err(|e| anyhow!("making the input tensor: {e}"))?;
        conv::normalize_input(&mut x);
        let xm = self.mirror_pass.then(|| x.mirror_w());
        let (mut elements, mut seg, mut env, mut disagreement) = (None, None, None, None);
        let mut seam: Option<Value> = None;
        let mut described = Vec::new();
        for n in &self.nets {
            let t = Instant::now();
            let what = || format!("running the {} network ({})", n.kind, n.path.display());
            match &n.net {
                Net::Irn(irn) => {
                    let (out, dis) = irn
                        .forward_mirrored_measured(&x, xm.as_ref())
                        .with_context(what)?;
                    disagreement = dis.map(|d| PassDisagreement {
                        albedo: tensor_image(&d.albedo),
                        normals_deg: tensor_image(&d.normals_deg),
                    });
                    let re = conv::RenderElements::from_irn(&out).with_context(|| {
                        format!("decoding the IRN outputs of {}", n.path.display())
                    })?;
                    elements = Some(
                        ElementImages::new(
                            tensor_image(&re.diffuse_albedo),
                            tensor_image(&re.specular_albedo),
                            tensor_image(&re.glossiness),
                            tensor_image(&re.normals),
                            tensor_image(&re.view_vector),
                            Some(tensor_image(&re.uv)),
                        )
                        .map_err(|e| anyhow!("IRN outputs: {e}"))?,
                    );
                }
                Net::Msn(msn) => {
                    let out = mirror::forward_mirrored(&x, xm.as_ref(), |t| msn.forward(t))
                        .with_context(what)?;
                    seg = Some(MsnImages {
                        segmentation: tensor_image(&conv::decode_segmentation_tensor(
                            &out.segmentation,
                        )),
                        embedding: out.embedding.as_ref().map(tensor_image),
                    });
                }
                Net::EnvMap(e) => {
                    let out = mirror::forward_mirrored(&x, xm.as_ref(), |t| e.forward(t))
                        .with_context(what)?;
                    let img = tensor_image(&conv::decode_envmap(&out.envmap));
                    let mut map =
                        EnvMap::from_image(&img).map_err(|e| anyhow!("environment map: {e}"))?;
                    seam = Some(regularise(&mut map));
                    env = Some(map);
                }
                #[allow(unreachable_patterns)]
                _ => bail!(
                    "{}: a {} network has no place in `--weights`; pass a learned inpainter with --inpainter",
                    n.path.display(),
                    n.kind
                ),
            }
            timings.insert(format!("net_{}", n.kind.as_str()), json!(ms(t)));
            described.push(json!({"net": n.kind.as_str(), "weights": n.path.display().to_string(), "preset": n.preset}));
        }
        let elements = elements.ok_or_else(|| anyhow!("the IRN network gave no outputs"))?;
        let seg = seg.ok_or_else(|| anyhow!("the MSN network gave no outputs"))?;
        Ok(Inferred {
            elements,
            msn: seg,
            envmap: env,
            disagreement,
            source: json!({
                "source": "networks",
                "nets": described,
                "working_size": {"width": ww, "height": wh},
                "mirror_pass": self.mirror_pass,
                "envmap_regularised": seam,
            }),
        })
    }
}

/// The networks' outputs for one photo ([`Models::infer`]).
struct Inferred {
    elements: ElementImages,
    msn: MsnImages,
    envmap: Option<EnvMap>,
    /// How far the mirror pass's two passes disagreed (IRN), when it ran.
    disagreement: Option<PassDisagreement>,
    /// What ran, for `material.json`'s inputs.
    source: Value,
}

/// Where the render elements come from.
pub enum Source<'a> {
    /// The networks, run on the photo.
    Nets(&'a Models),
    /// A folder of render elements (`picker synth` ground truth, `picker infer` output).
    Elements(&'a Path),
}

/// A photo with its inputs prepared for any number of picks.
pub struct Loaded {
    /// The prepared inputs.
    pub prepared: Prepared,
    /// What the photo is (path as given by the caller, size, format, orientation).
    pub photo_info: Value,
    /// Where the render elements came from.
    pub source: Value,
    /// Milliseconds per step so far.
    pub timings: serde_json::Map<String, Value>,
    /// The size the photo is analysed at, when smaller than the photo
    /// (`--analysis-megapixels`); `None`: its full resolution.
    pub analysis: Option<Analysis>,
}

/// Reads the photo (once), runs the networks or reads the elements, and
/// prepares the inputs. `label` is how the photo is named in the outputs.
pub fn load_inputs(
    source: &Source<'_>,
    photo_path: &Path,
    label: &str,
    flags: &Flags,
) -> Result<Loaded> {
    load_inputs_from(source, photo_path, None, label, flags)
}

/// [`load_inputs`] with the photo file's bytes when the caller has read them
/// already (`picker batch` hashes them first); they are dropped once decoded.
pub fn load_inputs_from(
    source: &Source<'_>,
    photo_path: &Path,
    bytes: Option<Vec<u8>>,
    label: &str,
    flags: &Flags,
) -> Result<Loaded> {
    let mut timings = serde_json::Map::new();
    let t = Instant::now();
    let p = match bytes {
        Some(b) => photo::decode_with(&b, photo_path, &flags.photo_limits())?,
        None => photo::load_with(photo_path, &flags.photo_limits())?,
    };
    let (w, h) = p.rgb.dimensions();
    // A photo larger than --analysis-megapixels is analysed at a smaller
    // size (the networks' working copy is made from the full photo either
    // way). Render elements given with the photo keep its full size.
    let analysis = match source {
        Source::Nets(_) => Analysis::for_photo(w as usize, h as usize, flags.analysis_megapixels),
        Source::Elements(_) => None,
    };
    // The planar copy (parallel; at the analysis size, straight from the
    // decoded pixels) and the networks' working copy (the `image` crate's
    // resize of the whole photo, one thread) side by side.
    let (planar, work) = rayon::join(
        || match &analysis {
            Some(a) => a.downsample_rgb(p.rgb.as_raw()),
            None => photo::to_planar(&p.rgb),
        },
        || match source {
            Source::Nets(_) => {
                let (ww, wh) = photo::working_size(w, h, flags.work_size);
                Some(photo::resize(&p.rgb, ww, wh))
            }
            Source::Elements(_) => None,
        },
    );
    let (aw, ah) = analysis.map_or((w as usize, h as usize), |a| a.size);
    let photo_img =
        Image::new(3, ah, aw, planar).map_err(|e| anyhow!("{}: {e}", photo_path.display()))?;
    let mut photo_info = json!({
        "path": label,
        "width": w, "height": h,
        "format": p.format.map(|f| format!("{f:?}")),
        "linear_input": p.linear_input,
        "bits_per_sample": p.bit_depth,
        "channels_in_file": p.channels_in_file,
        "exif_orientation": format!("{:?}", p.orientation),
        "exif_focal_35mm": p.focal_35mm,
        "colour_profile": p.colour_profile,
        "transparent_pixels": p.opaque.as_ref().map(|o| o.iter().filter(|&&v| !v).count()),
        "alpha_ignored": p.alpha_ignored,
    });
    if let Some(a) = &analysis {
        photo_info["analysis"] = a.describe();
    }
    let focal_35mm = p.focal_35mm;
    let opaque = opaque_mask(&p).map(|m| match &analysis {
        Some(a) => Mask {
            width: aw,
            height: ah,
            data: a.downsample_mask(&m.data),
        },
        None => m,
    });
    timings.insert("read_photo".into(), json!(ms(t)));
    let t = Instant::now();
    let (inputs, source) = match source {
        Source::Nets(models) => {
            drop(p);
            let work = work.expect("resized for the networks");
            let r = models.infer_work(&work, &mut timings)?;
            // The networks' pooled activations are not needed again before
            // the extraction's own full-resolution buffers peak.
            picker_tensor::release_buffers();
            (
                Inputs {
                    photo: photo_img,
                    elements: r.elements,
                    segmentation: r.msn.segmentation,
                    embedding: r.msn.embedding,
                    segmentation_estimated: true,
                    albedo_estimated: true,
                    envmap: r.envmap,
                    opaque,
                    disagreement: r.disagreement,
                },
                r.source,
            )
        }
        Source::Elements(dir) => {
            drop(p);
            read_elements(dir, photo_img, opaque)?
        }
    };
    timings.insert("inputs".into(), json!(ms(t)));
    let mut prepared =
        Prepared::new(inputs).with_context(|| format!("preparing {}", photo_path.display()))?;
    prepared.focal_35mm = focal_35mm;
    prepared.lens_choice = flags.lens;
    timings.insert("prepare".into(), json!(prepared.prepare_ms));
    Ok(Loaded {
        prepared,
        photo_info,
        source,
        timings,
        analysis,
    })
}

/// Makes the networks' environment map whole where it is one direction:
/// its left and right edges (straight behind the camera, predicted apart: a
/// line in reflections looking behind) and each pole's row (every column
/// within half a row of straight up or down: a pinched cone in a glossy
/// sphere's reflection of the zenith). What was done, for `material.json`.
fn regularise(map: &mut EnvMap) -> Value {
    let seam = map.close_wrap_seam();
    let poles = map.regularise_poles();
    json!({
        "wrap_seam_largest_change": seam,
        "poles_largest_change": poles,
        "rule": "wrap seam: the log step across the left/right edges made the mean of the steps beside it, spread over 1/8 of the width on each side; poles: in the 1/8 of the rows nearest each pole, harmonic m >= 1 of each row's log radiance around the pole scaled by (theta/theta_band)^m",
    })
}

/// The MSN's outputs as images at the working resolution.
struct MsnImages {
    /// Segmentation colours in `[0, 1]`.
    segmentation: Image,
    /// The material embedding (raw tanh values), from an MSN that has one.
    embedding: Option<Image>,
}

/// The photo's opaque pixels as a mask, when some are transparent.
fn opaque_mask(p: &photo::Photo) -> Option<Mask> {
    let (w, h) = p.rgb.dimensions();
    p.opaque.clone().map(|data| Mask {
        width: w as usize,
        height: h as usize,
        data,
    })
}

/// Reads render elements from a folder.
fn read_elements(dir: &Path, photo: Image, opaque: Option<Mask>) -> Result<(Inputs, Value)> {
    let elements = ElementImages::load(dir)
        .with_context(|| format!("reading render elements from {}", dir.display()))?;
    let seg_path = dir.join(format!("{}.exr", conv::SEGMENTATION));
    let segmentation =
        rio::read_exr(&seg_path).with_context(|| format!("reading {}", seg_path.display()))?;
    check_finite(&seg_path, &segmentation)?;
    let emb_path = dir.join(format!("{}.exr", conv::EMBEDDING));
    let embedding = if emb_path.exists() {
        let e =
            rio::read_exr(&emb_path).with_context(|| format!("reading {}", emb_path.display()))?;
        check_finite(&emb_path, &e)?;
        Some(e)
    } else {
        None
    };
    let env_path = dir.join(format!("{}.exr", conv::ENVMAP));
    let envmap = if env_path.exists() {
        let img =
            rio::read_exr(&env_path).with_context(|| format!("reading {}", env_path.display()))?;
        Some(EnvMap::from_image(&img).map_err(|e| anyhow!("{}: {e}", env_path.display()))?)
    } else {
        None
    };
    let segmentation_estimated = output_is_estimated(dir, conv::SEGMENTATION)?;
    let albedo_estimated = output_is_estimated(dir, conv::DIFFUSE_ALBEDO)?;
    // A `picker infer` folder holds the network's map as predicted: its
    // wrap seam is closed as when the networks run here.
    let mut envmap = envmap;
    let seam = match envmap.as_mut() {
        Some(e) if segmentation_estimated => Some(regularise(e)),
        _ => None,
    };
    Ok((
        Inputs {
            photo,
            elements,
            segmentation,
            embedding,
            segmentation_estimated,
            albedo_estimated,
            envmap,
            opaque,
            disagreement: None,
        },
        json!({
            "source": "elements",
            "elements": dir.display().to_string(),
            "envmap_regularised": seam,
        }),
    ))
}

/// Refuses an image read from `path` that holds NaN or infinite values
/// (a corrupt EXR), naming the file: colours are compared (segmentation,
/// embedding) or rendered (`picker render`), and such a value matches or
/// lights nothing.
pub(crate) fn check_finite(path: &Path, img: &Image) -> Result<()> {
    let bad = img.data.iter().filter(|v| !v.is_finite()).count();
    if bad > 0 {
        bail!(
            "{}: {bad} of its {} values are NaN or infinite",
            path.display(),
            img.data.len()
        );
    }
    Ok(())
}

/// Whether an elements folder's `output` (the segmentation, the albedo) is
/// a network's estimate: the folder is `picker infer` output (its
/// `manifest.json` names a network for it). A folder without a manifest
/// (`picker synth` ground truth, a renderer's passes) holds exact ones.
fn output_is_estimated(dir: &Path, output: &str) -> Result<bool> {
    let path = dir.join("manifest.json");
    if !path.exists() {
        return Ok(false);
    }
    let text =
        std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
    let v: Value =
        serde_json::from_str(&text).with_context(|| format!("parsing {}", path.display()))?;
    Ok(v["files"].as_array().is_some_and(|files| {
        files
            .iter()
            .any(|f| f["output"] == output && !f["net"].is_null())
    }))
}

/// The inpainter named by `--inpainter`.
pub fn inpainter(spec: &str) -> Result<Box<dyn Inpainter>> {
    Ok(match spec {
        "patchmatch" => Box::new(PatchMatchInpainter::default()),
        "diffusion" => Box::new(DiffusionInpainter::default()),
        path => {
            let p = Path::new(path);
            if !p.exists() {
                bail!("--inpainter {path:?}: not `patchmatch`, `diffusion` or an existing weights file");
            }
            Box::new(
                LearnedInpainter::load(p)
                    .with_context(|| format!("loading the learned inpainter {}", p.display()))?,
            )
        }
    })
}

/// The largest side of a picture the report sheet shows as it is: a larger
/// one is area-averaged down to it first ([`for_report`]). Four times the
/// sheet's tile height, so every picture of a default extraction (working
/// resolution elements, observed-size textures) is shown from its own
/// values; a 8192² texture's tiles took 7 s and 1.6 GB before.
const REPORT_SOURCE_MAX: usize = 1024;

/// `img`, or, when a side exceeds [`REPORT_SOURCE_MAX`], its area average
/// down to that side (aspect kept).
fn for_report(img: &Image) -> std::borrow::Cow<'_, Image> {
    let side = img.width.max(img.height);
    if side <= REPORT_SOURCE_MAX {
        return std::borrow::Cow::Borrowed(img);
    }
    let fit = |v: usize| (v * REPORT_SOURCE_MAX / side).max(1);
    std::borrow::Cow::Owned(picker_extract::resample::area(
        img,
        fit(img.width),
        fit(img.height),
    ))
}

/// A linear value as shown: clipped to [0, 1] and sRGB-encoded.
fn display_value(v: f32) -> f32 {
    conv::srgb_encode(v.clamp(0.0, 1.0))
}

fn tone_mapped(linear: &Image) -> Image {
    let n = linear.plane_len();
    Image {
        channels: 3,
        height: linear.height,
        width: linear.width,
        data: conv::tone_map_rgb(&linear.data, n),
    }
}

/// Side of `preview.png` in pixels.
const PREVIEW_SIZE: usize = 256;

/// Linear RGB shown with a known exposure (`conv::expose_rgb`).
fn exposed(linear: &Image, exposure: f32) -> Image {
    Image {
        channels: 3,
        height: linear.height,
        width: linear.width,
        data: conv::expose_rgb(&linear.data, exposure),
    }
}

fn direction_colours(img: &Image) -> Image {
    let n = img.plane_len();
    let mut out = Image::zeros(3, img.height, img.width);
    for i in 0..n {
        let c = conv::encode_direction_color([img.at(0, i), img.at(1, i), img.at(2, i)]);
        for (k, v) in c.into_iter().enumerate() {
            out.data[k * n + i] = v;
        }
    }
    out
}

/// `photo` with its transparent pixels (not in `opaque`) shown as the usual
/// light and dark grey checkerboard (sRGB 0.6 / 0.4, squares a 48th of the
/// photo's longer side), as image editors show transparency.
fn checkered(photo: &Image, opaque: &Mask) -> Image {
    let (w, h) = (photo.width, photo.height);
    let side = (w.max(h) / 48).max(1);
    let mut out = photo.clone();
    let n = w * h;
    for (i, _) in opaque.data.iter().enumerate().filter(|(_, &o)| !o) {
        let (x, y) = (i % w, i / w);
        let v = if (x / side + y / side) % 2 == 0 {
            0.6
        } else {
            0.4
        };
        for c in 0..3 {
            out.data[c * n + i] = v;
        }
    }
    out
}

/// The report sheet (thesis fig. 6.7 and more). The photo-resolution tiles
/// (photo + pick, mask overlay) and the 2×2 tiling are made row by row at
/// the tile size ([`report::LazyTile`]): the same sheet as resizing copies of
/// the whole pictures.
/// A given quadrilateral (`--quad`, pick convention) is outlined on the photo.
fn report_sheet(p: &Prepared, m: &Material, preview: &Image, quad: Option<[[f32; 2]; 4]>) -> Image {
    let el = &p.inputs.elements;
    let checkered = p
        .inputs
        .opaque
        .as_ref()
        .map(|o| checkered(&p.inputs.photo, o));
    let full = checkered.as_ref().unwrap_or(&p.inputs.photo);
    // A photo larger than REPORT_SOURCE_MAX a side is shown from its area
    // average (its display values averaged, as resizing them would), and
    // the mask with it: the two tiles read it once instead of the whole
    // photo each (~0.2 s at 12 megapixels).
    let photo = for_report(full);
    let photo: &Image = &photo;
    let mask = for_report(&m.mask);
    let (sx, sy) = (
        photo.width as f32 / full.width.max(1) as f32,
        photo.height as f32 / full.height.max(1) as f32,
    );
    let shown = |label: &str, image: Image| {
        report::LazyTile::from(Tile {
            label: label.into(),
            image,
        })
    };
    let photo_tile = match m.pick {
        Some([x, y]) => {
            let r = (full.width.max(full.height) as f32 / 40.0).max(4.0);
            report::marked_tile(
                "photo + pick".into(),
                photo,
                (x as f32 + 0.5) * sx,
                (y as f32 + 0.5) * sy,
                r * sx,
            )
        }
        None => report::borrowed_tile("photo + pick".into(), photo),
    };
    let photo_tile = match quad {
        Some(q) => report::outlined(
            photo_tile,
            q.map(|[x, y]| [(x + 0.5) * sx, (y + 0.5) * sy]).to_vec(),
        ),
        None => photo_tile,
    };
    // Linear pictures are shown sRGB-encoded per value, row by row as the
    // tiles are made (no displayed copy of them), from at most
    // REPORT_SOURCE_MAX texels a side (a 12-megapixel element or an 8192²
    // texture is area-averaged down first, in linear light).
    let displayed = |label: &str, img, k| report::mapped_tile(label.into(), img, k, display_value);
    let (diffuse, specular) = (for_report(&el.diffuse), for_report(&el.specular));
    let textures = m
        .texture
        .as_ref()
        .map(|t| (for_report(&t.raw), for_report(&t.texture)));
    let mut tiles = vec![
        photo_tile,
        displayed("diffuse albedo", &diffuse, 1),
        displayed("specular albedo", &specular, 1),
        report::borrowed_tile("glossiness".into(), &el.glossiness),
        shown("normals", direction_colours(&el.normals)),
        report::borrowed_tile("segmentation".into(), &p.inputs.segmentation),
    ];
    if let Some(e) = &p.inputs.embedding {
        // What the masks read when the MSN has one, shown as `picker infer`
        // shows it in `embedding.png`: (e + 1)/2 per channel.
        let mut shown_embedding = e.clone();
        for v in &mut shown_embedding.data {
            *v = conv::unit_from_tanh(*v).clamp(0.0, 1.0);
        }
        tiles.push(shown("material embedding", shown_embedding));
    }
    tiles.push(report::dimmed_tile("mask".into(), photo, &mask.data, 0.25));
    if let Some(e) = &p.inputs.envmap {
        tiles.push(shown("lighting (envmap)", tone_mapped(&e.to_image())));
    }
    if let (Some(t), Some((raw, texture))) = (&m.texture, &textures) {
        tiles.push(displayed("reprojected", raw, 1));
        tiles.push(report::borrowed_tile("coverage".into(), &t.coverage));
        tiles.push(displayed(&format!("texture ({})", t.inpainter), texture, 1));
        tiles.push(displayed("texture tiled 2x2", texture, 2));
    }
    tiles.push(shown("preview", preview.clone()));
    report::compose_lazy_sheet(&tiles, 4, 192)
}

/// What to extract from one photo.
#[derive(Clone, Debug, Default)]
pub struct Request {
    /// Named picks (name, `[x, y]`).
    pub picks: Vec<(String, [u32; 2])>,
    /// Also every material covering at least `--min-area` (a palette).
    pub all: bool,
    /// The plane of the one pick given by a rectangle's corners (`--quad`).
    pub quad: Option<Quad>,
    /// The quad's real size in metres (`--quad-size`).
    pub quad_size_m: Option<[f32; 2]>,
    /// The plane of this photo's materials, instead of `--normal`'s
    /// (`picker batch --normals`).
    pub normal: Option<UserPlane>,
    /// The material's pixels given (`--mask`): one material, the pick (if
    /// any) inside it.
    pub mask: Option<MaskArg>,
    /// How material.json names a mask file (`given_mask`); default: its
    /// path as given (a batch names it relative to its folder instead, so
    /// that its outputs hold no absolute paths).
    pub mask_label: Option<String>,
}

/// How [`write_materials`] lays out and annotates its files.
#[derive(Clone, Copy, Debug)]
pub struct Layout<'a> {
    /// A folder per material even when there is only one.
    pub always_subdirs: bool,
    /// Put timings and the thread count into material.json / summary.json.
    pub timings: bool,
    /// The output folder as the summaries name it (`out`, each `dir`
    /// under it), when it is not where the files are written (a staging
    /// folder); `None`: paths relative to the output folder (batch).
    pub shown_root: Option<&'a Path>,
}

/// Extracts the requested materials from a loaded photo into `out_dir`
/// (created if needed) and returns the summary written to `summary.json`.
pub fn write_materials(
    loaded: &Loaded,
    req: &Request,
    flags: &Flags,
    inpainter: &dyn Inpainter,
    out_dir: &Path,
    layout: Layout<'_>,
) -> Result<Value> {
    let t_total = Instant::now();
    let prepared = &loaded.prepared;
    let label = loaded.photo_info["path"]
        .as_str()
        .unwrap_or("photo")
        .to_string();
    // Picks and the quad are given in the photo's pixels; the extraction
    // works at the analysis size when the photo is larger
    // (`--analysis-megapixels`).
    let analysis = loaded.analysis;
    let (ow, oh) = analysis.map_or(prepared.photo_size(), |a| a.original);
    // The quad first: without --pick the pick is its centre.
    let quad = match &req.quad {
        Some(q) => {
            if req.picks.len() > 1 || req.all {
                bail!("--quad gives the plane of one material: use it with at most one --pick and without --all");
            }
            q.check(ow, oh)
                .map_err(|e| anyhow!("{label}: --quad: {e}"))?;
            match &analysis {
                Some(a) => {
                    let qa = Quad(q.0.map(|c| a.point(c)));
                    let (fw, fh) = prepared.photo_size();
                    qa.check(fw, fh).map_err(|e| {
                        anyhow!(
                            "{label}: --quad at the photo's analysis size {fw}x{fh}: {e} (--analysis-megapixels 0 analyses the full {ow}x{oh})"
                        )
                    })?;
                    Some(qa)
                }
                None => Some(*q),
            }
        }
        None => None,
    };
    // (name, the pick as given, the pick at the analysis size).
    let mut picks = Vec::with_capacity(req.picks.len());
    for (name, pk) in &req.picks {
        let at = match &analysis {
            Some(a) => {
                let [x, y] = *pk;
                pipeline::check_pick_inside(*pk, (ow, oh)).with_context(|| label.clone())?;
                let at = a.pick(*pk);
                prepared.check_pick(at).map_err(|_| {
                    anyhow!(
                        "{label}: pick ({x}, {y}) is on a transparent pixel of the photo (alpha below ½): pick a visible one"
                    )
                })?;
                at
            }
            None => {
                prepared.check_pick(*pk).with_context(|| label.clone())?;
                *pk
            }
        };
        picks.push((name.clone(), *pk, at));
    }
    // A pick at the analysis size in the photo's pixels.
    let to_photo = |pk: [u32; 2]| analysis.map_or(pk, |a| a.pick_back(pk));
    // A given mask: the one material, its pick inside it.
    let given = match &req.mask {
        None => None,
        Some(arg) => {
            if req.picks.len() > 1 || req.all {
                bail!("--mask gives the pixels of one material: use it with at most one --pick and without --all");
            }
            let (fw, fh) = prepared.photo_size();
            let (full, shown) = match arg {
                MaskArg::Quad => {
                    let q = quad.ok_or_else(|| anyhow!("--mask quad needs --quad"))?;
                    // Its sides bent as the photo's lens bends them.
                    let lens = picker_extract::lens::Lens::new(prepared.lens().lambda, fw, fh);
                    (
                        q.interior_through(&lens, fw, fh),
                        "the --quad's interior".to_string(),
                    )
                }
                MaskArg::File(f) => {
                    let m = picker_extract::photo::load_mask(f, &flags.photo_limits())
                        .map_err(|e| anyhow!("--mask {e}"))?;
                    // Another size with the photo's aspect ratio (a mask
                    // painted on a smaller copy): scaled to the photo.
                    let aspect = |w: usize, h: usize| w as f64 / h.max(1) as f64;
                    let (mw, mh) = (m.width, m.height);
                    if (mw, mh) != (ow, oh)
                        && (aspect(mw, mh) / aspect(ow, oh) - 1.0).abs() > MASK_ASPECT_TOLERANCE
                    {
                        bail!(
                            "--mask {}: the mask is {mw}x{mh} but the photo {label} is {ow}x{oh} (as a viewer shows it, EXIF orientation applied); a mask of another size needs the photo's aspect ratio",
                            f.display(),
                        );
                    }
                    let full = picker_extract::mask::Mask {
                        width: mw,
                        height: mh,
                        data: m.data,
                    }
                    .scaled_to(fw, fh);
                    if full.count() == 0 {
                        bail!(
                            "--mask {}: no pixel is set (white, or opaque where the file has transparency)",
                            f.display()
                        );
                    }
                    let mut shown = req
                        .mask_label
                        .clone()
                        .unwrap_or_else(|| f.display().to_string());
                    if (mw, mh) != (fw, fh) {
                        shown = format!("{shown} ({mw}x{mh}, scaled to {fw}x{fh})");
                    }
                    (full, shown)
                }
            };
            let pick = match picks.first() {
                Some((_, given, at)) => {
                    let (x, y) = (at[0] as usize, at[1] as usize);
                    if !full.data[y * fw + x] {
                        bail!(
                            "--pick {},{} is outside the mask ({shown})",
                            given[0],
                            given[1]
                        );
                    }
                    *at
                }
                None => {
                    let [x, y] = full.central_pixel().expect("a non-empty mask");
                    [x as u32, y as u32]
                }
            };
            let name = req
                .picks
                .first()
                .map_or_else(|| "material_0".to_string(), |(n, _)| n.clone());
            let pm = prepared
                .given_mask(full)
                .with_context(|| format!("--mask {shown}"))?;
            Some((name, pick, pm, shown))
        }
    };
    std::fs::create_dir_all(out_dir)
        .with_context(|| format!("creating output directory {}", out_dir.display()))?;
    let mask_opts = flags.mask_options();
    let mut jobs = Vec::new();
    let mask_shown = given.as_ref().map(|g| g.3.clone());
    if let Some((name, pick, pm, _)) = given {
        // (The mask's central pixel when no pick is given.)
        let given = picks.first().map_or_else(|| to_photo(pick), |p| p.1);
        jobs.push((name, Some(pick), pm, given));
    }
    for (name, given, at) in picks.iter().filter(|_| req.mask.is_none()) {
        let pm = prepared
            .pick_mask(*at, &mask_opts)
            .with_context(|| format!("pick {},{} in {label}", given[0], given[1]))?;
        jobs.push((name.clone(), Some(*at), pm, *given));
    }
    let mut palette_ids = None;
    if req.all {
        let pal = prepared.palette(flags.min_area, 64, !flags.no_pattern, !flags.no_split);
        if pal.is_empty() {
            bail!(
                "{label}: no material covers --min-area {} of the image",
                flags.min_area
            );
        }
        let (w, h) = prepared.work_size();
        let mut ids = Image::zeros(1, h, w);
        let base = jobs.len();
        for (k, (pk, pm)) in pal.into_iter().enumerate() {
            for (i, &m) in pm.mask.data.iter().enumerate() {
                if m && ids.data[i] == 0.0 {
                    ids.data[i] = (k + 1) as f32 / 65535.0;
                }
            }
            jobs.push((format!("material_{}", base + k), Some(pk), pm, to_photo(pk)));
        }
        palette_ids = Some(ids);
    }
    if jobs.is_empty() {
        bail!("{label}: nothing to extract (no pick and no --all)");
    }
    let mut opts = flags.options(inpainter);
    if let Some(n) = req.normal {
        opts.plane = Some(n);
    }
    if let Some(q) = quad {
        opts.plane = Some(UserPlane::Quad(q));
        opts.quad_size_m = req.quad_size_m;
    }
    let env = prepared.inputs.envmap.clone();
    // One prefiltered lighting for every preview of the run and their
    // exposure: the one the re-render self-checks use, or a white sky.
    let white_sky;
    let preview_shader = match prepared.shader() {
        Some(s) => s,
        None => {
            white_sky = Shader::resolving(&EnvMap::uniform(64, 32, glam::Vec3::ONE));
            &white_sky
        }
    };
    let exposure = picker_render::preview_exposure(preview_shader);
    let single = jobs.len() == 1 && !layout.always_subdirs;
    let export_opts = ExportOptions {
        sixteen_bit: flags.sixteen_bit,
    };
    let mut summaries = Vec::new();
    for (name, pick, pm, given) in &jobs {
        let t = Instant::now();
        let (m, mut diag) = pipeline::extract(prepared, name, *pick, pm, &opts)
            .with_context(|| format!("extracting {name} from {label}"))?;
        // What the files say is in the photo's pixels: the pick and the
        // mask (the report sheet shows the analysed copy).
        let photo_m = analysis.map(|a| picker_extract::Material {
            pick: m.pick.map(|_| *given),
            mask: a.upsample_mask(&m.mask),
            ..m.clone()
        });
        let out_m = photo_m.as_ref().unwrap_or(&m);
        let extract_ms = ms(t);
        let repeats = pipeline::material_preview_repeats(&m, PREVIEW_SIZE);
        let dir = if single {
            out_dir.to_path_buf()
        } else {
            out_dir.join(name)
        };
        std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
        // The image files (texture, coverage, mask) are written while the
        // preview and the report sheet are made; the descriptions, which
        // hold their timings, after both.
        let (timed, images) = rayon::join(
            || -> Result<_> {
                let t = Instant::now();
                let preview = exposed(
                    &pipeline::preview_sphere_with(&m, preview_shader, PREVIEW_SIZE, repeats),
                    exposure,
                );
                rio::write_png(&dir.join("preview.png"), &preview)?;
                let preview_ms = ms(t);
                let t_sheet = Instant::now();
                let quad = diag
                    .uv
                    .as_ref()
                    .and_then(|u| u.user_plane.as_ref())
                    .and_then(|u| u.quad);
                let sheet = report_sheet(prepared, &m, &preview, quad);
                rio::write_png(&dir.join("report.png"), &sheet)?;
                Ok((preview_ms, ms(t_sheet), ms(t)))
            },
            || export::write_material_images(&dir, out_m, &export_opts),
        );
        let (preview_ms, sheet_ms, report_ms) = timed?;
        if let (Some(_), Some(q)) = (analysis, req.quad) {
            if let Some(u) = diag.uv.as_mut().and_then(|u| u.user_plane.as_mut()) {
                u.quad = Some(q.0);
            }
        }
        let mut files = images.with_context(|| format!("writing {name} to {}", dir.display()))?;
        let mut diagnostics = serde_json::to_value(&diag).context("serialising diagnostics")?;
        if !layout.timings {
            if let Some(o) = diagnostics.as_object_mut() {
                o.remove("timings_ms");
            }
        }
        let mut extra = json!({
            "photo": loaded.photo_info,
            "inputs": loaded.source,
            "diagnostics": diagnostics,
            "picker_version": env!("CARGO_PKG_VERSION"),
            "seed": flags.seed,
            "preview": {"file": "preview.png", "envmap": if env.is_some() { "estimated" } else { "uniform white (no envmap network given)" }, "texture_repeats": repeats, "texture_repeats_rule": "about one texel per preview pixel at the sphere's centre (pi x 256 / texture side, whole, 1 to 8)", "exposure": exposure, "display": "linear radiance x exposure (a white diffuse sphere under this lighting averages 0.75), identity up to 0.8 then a soft roll-off towards 1, sRGB-encoded"},
            "report": "report.png",
        });
        if let Some(shown) = &mask_shown {
            extra["given_mask"] = json!(shown);
        }
        if layout.timings {
            extra["timings_ms"] = json!({"extract": extract_ms, "preview_and_report": report_ms, "preview": preview_ms, "report_sheet": sheet_ms, "steps": diag.timings_ms});
        }
        files.extend(
            export::write_material_descriptions(&dir, out_m, &extra, &export_opts)
                .with_context(|| format!("writing {name} to {}", dir.display()))?,
        );
        let mut s = export::material_json(out_m, &Value::Null, &export_opts)?;
        if let Some(o) = s.as_object_mut() {
            let shown = if let Some(root) = layout.shown_root {
                if single {
                    root.to_path_buf()
                } else {
                    root.join(name)
                }
                .display()
                .to_string()
            } else if single {
                ".".into()
            } else {
                name.clone()
            };
            o.insert("dir".into(), json!(shown));
            if let Some(why) = &diag.texture_fallback {
                o.insert("texture_fallback".into(), json!(why));
            }
            let hints = hints(&m, &diag);
            if !hints.is_empty() {
                o.insert("hints".into(), json!(hints));
            }
            let mut names: Vec<String> = files
                .iter()
                .filter_map(|f| f.file_name().map(|n| n.to_string_lossy().into_owned()))
                .collect();
            names.extend(["preview.png".to_string(), "report.png".to_string()]);
            names.sort();
            o.insert("files".into(), json!(names));
        }
        summaries.push(s);
    }
    if let Some(e) = &env {
        e.write_exr(&out_dir.join("envmap.exr"))
            .with_context(|| format!("writing {}", out_dir.join("envmap.exr").display()))?;
    }
    if let Some(ids) = &palette_ids {
        rio::write_png16(&out_dir.join("palette_ids.png"), ids)?;
    }
    // Several materials: one USD layer that references them all.
    if !single {
        let entries: Vec<(String, String)> = jobs
            .iter()
            .map(|(name, ..)| (name.clone(), format!("{name}/{}", export::MATERIAL_USDA)))
            .collect();
        let path = out_dir.join(export::MATERIALS_USDA);
        crate::output::write_atomic(&path, export::usda_library_text(&entries).as_bytes())?;
    }
    let mut summary = json!({
        "format": "material-picker-extract",
        "format_version": 1,
        "picker_version": env!("CARGO_PKG_VERSION"),
        "photo": loaded.photo_info,
        "inputs": loaded.source,
        "settings": flags.output_settings(),
        "out": layout.shown_root.map_or_else(|| ".".into(), |r| r.display().to_string()),
        "materials": summaries,
        "envmap": env.as_ref().map(|_| "envmap.exr"),
        "palette_ids": palette_ids.as_ref().map(|_| "palette_ids.png (16-bit: 0 = none, k = material_{k-1})"),
        "usd": (!single).then_some(export::MATERIALS_USDA),
    });
    if layout.timings {
        let mut timings = loaded.timings.clone();
        timings.insert("materials".into(), json!(ms(t_total)));
        summary["timings_ms"] = Value::Object(timings);
        summary["threads"] = json!(rayon::current_num_threads());
    }
    let text = serde_json::to_string_pretty(&summary).context("serialising summary.json")?;
    crate::output::write_atomic(
        &out_dir.join("summary.json"),
        format!("{text}\n").as_bytes(),
    )?;
    Ok(summary)
}

/// The photo path `picker extract` reads: PHOTO, or the image of `--elements DIR`.
fn photo_path(a: &Args) -> Result<PathBuf> {
    Ok(match (&a.photo, &a.elements) {
        (Some(p), _) => p.clone(),
        (None, Some(d)) => {
            let img = d.join("image.png");
            if img.exists() {
                img
            } else {
                d.join("input.png")
            }
        }
        (None, None) => bail!("give a PHOTO (or --elements DIR holding image.png)"),
    })
}

/// Below this share of observed texels `picker extract` says that most of
/// the texture was inpainted ([`hints`]).
const LOW_COVERAGE: f64 = 0.25;
/// Share of a mask the photo's split took out ([`picker_extract::split`]) from which a note says so.
const SPLIT_NOTE_SHARE: f64 = 0.01;

/// Advice for the user from what the extraction found (`summary.json`,
/// `materials[].hints`; printed by `picker extract`).
fn hints(m: &Material, diag: &pipeline::Diagnostics) -> Vec<String> {
    let mut out = Vec::new();
    if let Some(t) = m
        .texture
        .as_ref()
        .filter(|t| t.coverage_fraction < LOW_COVERAGE)
    {
        out.push(format!(
            "the photo shows {:.0} % of the texture; the rest was filled in by inpainting \
             (coverage.png): a closer or more frontal photo of the material shows more of it",
            100.0 * t.coverage_fraction
        ));
    }
    if let Some(s) = diag
        .split
        .as_ref()
        .filter(|s| s.removed_share >= SPLIT_NOTE_SHARE)
    {
        out.push(format!(
            "the photo sets {} region(s) apart from the picked material that the segmentation had \
             taken in ({:.0} % of its mask): they were left out; --no-split keeps them",
            s.regions_removed,
            100.0 * s.removed_share
        ));
    }
    if let Some(p) = diag.pattern.as_ref().filter(|p| p.merged) {
        out.push(format!(
            "the picked colour interleaves with another ({} elements of one colour): the mask is \
             the two-colour pattern, of which the picked colour is {:.0} %; --no-pattern keeps \
             only the picked colour",
            p.measured
                .elements
                .count
                .max(p.measured.companion_elements.count),
            100.0 * p.own_share
        ));
    }
    let uv = diag.uv.as_ref();
    if let Some(l) = uv
        .and_then(|u| u.lens.as_ref())
        .filter(|l| l.source == "lines")
    {
        out.push(format!(
            "the photo's straight edges bow outwards (a wide-angle or webcam lens): the plane was \
             rectified with that distortion undone (λ {:.3}, the corners moved by {:.0} px); \
             --lens none keeps the photo as taken",
            l.lambda, l.corner_shift_px
        ));
    }
    if let Some(turn) = uv
        .and_then(|u| u.lines.as_ref())
        .and_then(|l| l.refused_turn_deg)
    {
        out.push(format!(
            "the photo's lines in the picked region disagree with the predicted plane by {turn:.0}°; \
             if the texture is streaky or in perspective, give the plane: --normal front for a \
             head-on photo, or --quad with the corners of a rectangle on the surface"
        ));
    }
    if let Some(r) = uv
        .and_then(|u| u.user_plane.as_ref())
        .and_then(|u| u.size_ratio)
        .filter(|r| !(1.0 / SIZE_RATIO_HINT..=SIZE_RATIO_HINT).contains(r))
    {
        out.push(format!(
            "the quad's sides, rectified, are in proportion {r:.2} to the --quad-size given \
             (1 when they agree), so texture.size_m is uncertain: check that W is the side from \
             corner 1 to 2 and H from 2 to 3, that the corners lie on the rectangle's corners, \
             or give the camera's --fov"
        ));
    }
    out
}

/// A `--quad-size` whose proportions the rectified quad's differ from by
/// more than this factor (either way) brings a hint.
pub const SIZE_RATIO_HINT: f64 = 1.15;

/// Runs `picker extract`.
pub fn run(a: Args) -> Result<()> {
    let t_total = Instant::now();
    crate::threads::init(a.threads)?;
    if a.pick.is_empty() && !a.all && a.quad.is_none() && a.mask.is_none() {
        bail!("nothing to extract: give --pick X,Y (may be repeated), --all, --quad or --mask");
    }
    if a.mask == Some(MaskArg::Quad) && a.quad.is_none() {
        bail!("--mask quad needs --quad (the quadrilateral whose interior is the material)");
    }
    if a.mask.is_some() && a.pick.len() > 1 {
        bail!("--mask gives the pixels of one material: use it with at most one --pick");
    }
    if a.quad.is_some() && a.flags.uv == UvArg::Net {
        bail!("--quad gives the plane to rectify: it cannot be used with --uv net");
    }
    a.flags.validate()?;
    let photo_path = photo_path(&a)?;
    let inpainter = inpainter(&a.flags.inpainter)?;
    let out_dir = match &a.out {
        Some(o) => o.clone(),
        None => {
            let stem = photo_path
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_else(|| "photo".into());
            photo_path.with_file_name(format!("{stem}.material"))
        }
    };
    let models;
    let source = match &a.elements {
        Some(dir) => Source::Elements(dir),
        None => {
            models = Models::load(&a.flags.weights)?.with_mirror_pass(!a.flags.single_pass);
            Source::Nets(&models)
        }
    };
    let loaded = load_inputs(
        &source,
        &photo_path,
        &photo_path.display().to_string(),
        &a.flags,
    )?;
    let mut picks: Vec<[u32; 2]> = a.pick.clone();
    // Without --pick: a quad's centre, unless a mask gives the material.
    if let (Some(q), true, None) = (&a.quad, picks.is_empty(), &a.mask) {
        picks.push(q.centre_pixel());
    }
    let req = Request {
        picks: picks
            .iter()
            .enumerate()
            .map(|(k, &p)| (format!("material_{k}"), p))
            .collect(),
        all: a.all,
        quad: a.quad,
        quad_size_m: a.quad_size,
        normal: None,
        mask: a.mask.clone(),
        mask_label: None,
    };
    let layout = Layout {
        always_subdirs: false,
        timings: !a.no_timings,
        shown_root: Some(&out_dir),
    };
    // Every file of the run, or none (see `staging`).
    let staging = Staging::begin(&out_dir, crate::staging::SUMMARY, true)?;
    let summary = write_materials(
        &loaded,
        &req,
        &a.flags,
        inpainter.as_ref(),
        staging.path(),
        layout,
    )
    .map_err(|e| staging.in_out(e))?;
    staging.commit()?;
    if a.json {
        let text = serde_json::to_string_pretty(&summary).context("serialising the summary")?;
        println!("{text}");
    } else {
        for s in summary["materials"].as_array().cloned().unwrap_or_default() {
            let kind = match (s["textured"].as_bool(), s["texture_fallback"].as_str()) {
                (Some(true), _) => "textured".to_string(),
                (_, Some(why)) => format!("single colour (its texture could not be taken: {why})"),
                _ => "single colour".to_string(),
            };
            let size = match s["texture"]["size_m"].as_array().map(|a| a.as_slice()) {
                Some([w, h]) => format!(
                    ", repeats every {:.3} x {:.3} m",
                    w.as_f64().unwrap_or(f64::NAN),
                    h.as_f64().unwrap_or(f64::NAN)
                ),
                _ => String::new(),
            };
            println!(
                "{}: {kind}{size} -> {}",
                s["name"].as_str().unwrap_or("?"),
                s["dir"].as_str().unwrap_or("?")
            );
            for h in s["hints"].as_array().into_iter().flatten() {
                eprintln!(
                    "hint: {}: {}",
                    s["name"].as_str().unwrap_or("?"),
                    h.as_str().unwrap_or("?")
                );
            }
        }
        println!("done in {:.2} s", t_total.elapsed().as_secs_f64());
    }
    Ok(())
}

/// Runs the networks on a photo at `work_size` (long side) and returns the
/// extraction inputs (for `picker eval`).
pub fn infer_inputs(models: &Models, photo_path: &Path, work_size: u32) -> Result<Inputs> {
    let p = photo::load(photo_path)?;
    let (w, h) = p.rgb.dimensions();
    let photo_img = Image::new(3, h as usize, w as usize, photo::to_planar(&p.rgb))
        .map_err(|e| anyhow!("{}: {e}", photo_path.display()))?;
    let r = models.infer(&p.rgb, work_size, &mut serde_json::Map::new())?;
    Ok(Inputs {
        photo: photo_img,
        elements: r.elements,
        segmentation: r.msn.segmentation,
        embedding: r.msn.embedding,
        segmentation_estimated: true,
        albedo_estimated: true,
        envmap: r.envmap,
        opaque: opaque_mask(&p),
        disagreement: r.disagreement,
    })
}

/// A `--shading-sigma`: a finite number of working pixels, at least 0.
pub fn parse_sigma(s: &str) -> std::result::Result<f32, String> {
    let v: f32 = s.parse().map_err(|e| format!("{s:?}: {e}"))?;
    if (0.0..=1000.0).contains(&v) {
        Ok(v)
    } else {
        Err(format!(
            "{s:?}: give a number of working pixels from 0 to 1000"
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn analysis_size_keeps_the_aspect_and_only_shrinks() {
        // Fits, no cap, no pixels: none.
        assert_eq!(Analysis::for_photo(4000, 3000, 16.0), None);
        assert_eq!(Analysis::for_photo(4000, 3000, 12.0), None);
        assert_eq!(Analysis::for_photo(8000, 6000, 0.0), None);
        assert_eq!(Analysis::for_photo(0, 6000, 1.0), None);
        let a = Analysis::for_photo(8000, 6000, 16.0).unwrap();
        assert_eq!(a.size, (4619, 3464));
        assert!((a.size.0 * a.size.1) as f64 <= 16.0e6 + 8000.0);
        // A 1-pixel-wide strip keeps its side of 1.
        let s = Analysis::for_photo(1, 40_000, 0.001).unwrap();
        assert_eq!(s.size, (1, 1000));
    }

    #[test]
    fn picks_map_to_the_analysis_pixel_under_their_centre_and_back() {
        for (w, h, mp) in [(8000, 6000, 16.0), (321, 213, 0.03), (7, 1000, 0.002)] {
            let a = Analysis::for_photo(w, h, mp).unwrap();
            let (aw, ah) = a.size;
            for y in 0..h as u32 {
                for x in [0, 1, w as u32 / 2, w as u32 - 1] {
                    let [px, py] = a.pick([x, y]);
                    assert!((px as usize) < aw && (py as usize) < ah);
                    // The analysis pixel's area holds the photo pixel's centre.
                    let inside = |v: u32, p: u32, n: usize, an: usize| {
                        let c = (f64::from(v) + 0.5) * an as f64 / n as f64;
                        f64::from(p) <= c && c <= f64::from(p) + 1.0
                    };
                    assert!(inside(x, px, w, aw) && inside(y, py, h, ah), "{x},{y}");
                    // The continuous mapping agrees.
                    let [fx, fy] = a.point([x as f32, y as f32]);
                    assert!((fx + 0.5 - px as f32) > -1e-3 && (fx + 0.5 - px as f32) < 1.0 + 1e-3);
                    assert!((fy + 0.5 - py as f32) > -1e-3 && (fy + 0.5 - py as f32) < 1.0 + 1e-3);
                    // Back: a photo pixel inside the same analysis pixel.
                    assert_eq!(a.pick(a.pick_back([px, py])), [px, py]);
                }
            }
            assert_eq!(a.pick([0, 0]), [0, 0]);
            assert_eq!(
                a.pick([w as u32 - 1, h as u32 - 1]),
                [aw as u32 - 1, ah as u32 - 1]
            );
        }
    }

    #[test]
    fn downsampled_photo_is_the_area_average_in_16_bit_codes() {
        let mut rng = picker_tensor::Rng::new(31);
        for (w, h, aw, ah) in [(12, 8, 6, 4), (23, 19, 7, 6), (1, 9, 1, 4)] {
            let a = Analysis {
                original: (w, h),
                size: (aw, ah),
            };
            let rgb: Vec<f32> = rng.uniform_vec(3 * w * h, 0.0, 1.0);
            let got = a.downsample_rgb(&rgb);
            let exact =
                picker_extract::resample::area_interleaved_rgb(&rgb, (w, h), (aw, ah), |v| v);
            assert_eq!(got.len(), 3 * aw * ah);
            for (g, e) in got.iter().zip(&exact) {
                assert!((g - e).abs() <= 0.5 / 65535.0 + 1e-7, "{g} vs {e}");
                let k = (g * 65535.0).round();
                assert_eq!((k / 65535.0).to_bits(), g.to_bits(), "a 16-bit code");
            }
        }
    }

    #[test]
    fn masks_go_down_by_majority_and_up_by_their_half_level() {
        let a = Analysis {
            original: (8, 6),
            size: (4, 3),
        };
        // The left 3 columns: each analysis pixel of column 1 holds one in
        // and one out (½: in), column 0 all in.
        let data: Vec<bool> = (0..48).map(|i| i % 8 < 3).collect();
        let down = a.downsample_mask(&data);
        assert_eq!(
            down,
            (0..12).map(|i| i % 4 < 2).collect::<Vec<_>>(),
            "area >= 1/2 is in"
        );
        let img = Image {
            channels: 1,
            height: 3,
            width: 4,
            data: down.iter().map(|&b| f32::from(u8::from(b))).collect(),
        };
        let up = a.upsample_mask(&img);
        assert_eq!((up.width, up.height, up.channels), (8, 6, 1));
        assert!(up.data.iter().all(|&v| v == 0.0 || v == 1.0));
        // Columns 0..4 in (the edge falls halfway between analysis columns 1 and 2).
        for (i, &v) in up.data.iter().enumerate() {
            assert_eq!(v == 1.0, i % 8 < 4, "pixel {i}");
        }
    }

    #[test]
    fn transparent_pixels_show_as_a_checkerboard_in_the_report() {
        // 96 × 10: squares of 2 pixels; the left half transparent.
        let (w, h) = (96usize, 10usize);
        let photo = Image::new(
            3,
            h,
            w,
            (0..3 * w * h).map(|i| (i % 7) as f32 / 7.0).collect(),
        )
        .unwrap();
        let opaque = Mask {
            width: w,
            height: h,
            data: (0..w * h).map(|i| i % w >= 48).collect(),
        };
        let shown = checkered(&photo, &opaque);
        for i in 0..w * h {
            let (x, y) = (i % w, i / w);
            for c in 0..3 {
                let want = if x >= 48 {
                    photo.data[c * w * h + i]
                } else if (x / 2 + y / 2) % 2 == 0 {
                    0.6
                } else {
                    0.4
                };
                assert_eq!(shown.data[c * w * h + i], want, "({x}, {y})");
            }
        }
    }

    #[test]
    fn lens_choices_parse() {
        assert_eq!(parse_lens("auto"), Ok(LensChoice::Auto));
        assert_eq!(parse_lens(" AUTO "), Ok(LensChoice::Auto));
        assert_eq!(parse_lens("none"), Ok(LensChoice::Given(0.0)));
        assert_eq!(parse_lens("-0.15"), Ok(LensChoice::Given(-0.15)));
        assert_eq!(parse_lens("0"), Ok(LensChoice::Given(0.0)));
        assert_eq!(parse_lens("0.4"), Ok(LensChoice::Given(0.4)));
        for bad in [
            "", "-0.61", "0.41", "nan", "inf", "-inf", "barrel", "-0.1,0.2",
        ] {
            let e = parse_lens(bad).expect_err(bad);
            assert!(
                e.contains("outside") || e.contains("expected"),
                "{bad:?}: {e}"
            );
        }
        assert!(parse_lens("-0.7").unwrap_err().contains("barrel"));
    }

    #[test]
    fn quad_sizes_parse_in_every_unit() {
        let close = |s: &str, want: [f32; 2]| {
            let got = parse_size_m(s).unwrap_or_else(|e| panic!("{s}: {e}"));
            for k in 0..2 {
                assert!((got[k] / want[k] - 1.0).abs() < 1e-6, "{s}: {got:?}");
            }
        };
        close("210x297mm", [0.21, 0.297]);
        close("30x30cm", [0.3, 0.3]);
        close("8.5x11in", [0.2159, 0.2794]);
        close("0.3X0.45", [0.3, 0.45]);
        close("2×3m", [2.0, 3.0]);
        close(" 1.5 x 2 m ", [1.5, 2.0]);
        close("1e-3x2e-3", [1e-3, 2e-3]);
        for bad in [
            "", "x", "1x", "x1", "1", "1x2x3", "0x1", "-1x1", "1xnan", "infx1", "1x1ft",
            "1x1 mm m", "1e-50x1", "1e39x1",
        ] {
            assert!(parse_size_m(bad).is_err(), "{bad:?} accepted");
        }
    }
}
