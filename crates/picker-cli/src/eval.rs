//! `picker eval DIR`: extraction quality on synthetic scenes with ground truth.
//!
//! For every scene folder under DIR (as `picker synth` writes, with
//! `materials/`), every material covering at least `--min-area` of the image
//! is picked at its most interior pixel (largest chamfer distance to the
//! material's border, ties to the lowest index) and extracted — from the
//! ground-truth render elements by default, or from the networks with
//! `--weights`. Scores per material:
//! - mask IoU of the extracted mask against the true material mask;
//! - albedo RMSE (linear) and mean normal error (degrees) of the elements over
//!   the true mask (0 with ground-truth elements);
//! - for textured materials, the texture score against the true source texture
//!   ignoring the tiling's offset and scale ([`picker_extract::eval::aligned_texture_score`]:
//!   best over cyclic shifts and a few scales, PSNR on sRGB values, plus a
//!   colour-statistics distance) and the seam ratio of the result next to the
//!   true texture's own; a textured material extracted as a single colour is
//!   scored as that flat colour (what the artist gets), so that calling a
//!   texture plain is not left out of the mean; for the plane mode also the
//!   score at the best quarter turn of the texture
//!   ([`picker_extract::eval::turned_texture_score`]);
//! - for single-colour materials, the RMSE of the diffuse colour.
//!
//! - the IoU of a baseline without networks: a 4-connected flood fill from the
//!   pick over the photo's sRGB colours, for each of [`FLOOD_TOLERANCES`]; the
//!   aggregate reports every tolerance's mean and the best one (an oracle
//!   choice, generous to the baseline);
//! - what any thresholding of the segmentation could reach at this pick:
//!   the best IoU over [`oracle_tolerance_iou`]'s tolerances of the pixels
//!   whose segmentation colour lies within the tolerance of the pick colour
//!   (an oracle, told the truth: it tells a segmentation network's limits
//!   from the mask rule's).
//!
//! Prints a table and writes the rows and their aggregates as JSON (`--json-out`).

use std::borrow::Cow;
use std::path::{Path, PathBuf};

use anyhow::{anyhow, bail, Context, Result};
use picker_extract::eval as metrics;
use picker_extract::mask::Mask;
use picker_extract::resample;
use picker_extract::{pipeline, Inputs, Prepared, UvMode};
use picker_inpaint::{seam_score, PatchMatchInpainter};
use picker_render::io as rio;
use picker_render::{ElementImages, EnvMap};
use serde::Serialize;
use serde_json::json;

/// `img` at `w × h`: itself when it has that size, else area-averaged
/// (shrinking) or bilinearly interpolated (otherwise), for comparing the
/// networks' elements (working size) with a scene's truth (its own size).
fn at_size(img: &rio::Image, w: usize, h: usize) -> Cow<'_, rio::Image> {
    if (img.width, img.height) == (w, h) {
        Cow::Borrowed(img)
    } else if img.width >= w && img.height >= h {
        Cow::Owned(resample::area(img, w, h))
    } else {
        Cow::Owned(resample::bilinear(img, w, h))
    }
}

/// Side of the flat texture a textured material extracted as a single colour
/// is scored as (any size gives the same score).
const FLAT_SIZE: usize = 16;

/// Arguments of `picker eval`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// A folder of synthetic scenes (`picker synth --out DIR`), or one scene folder.
    #[arg(value_name = "DIR")]
    pub dir: PathBuf,
    /// Smallest image fraction of a material to evaluate (materials the image does not show are never evaluated).
    #[arg(long, default_value_t = 0.05)]
    pub min_area: f64,
    /// Network weights (else the ground-truth elements stand in for the networks).
    #[arg(long, value_name = "DIR_OR_FILE", conflicts_with = "embedded")]
    pub weights: Vec<PathBuf>,
    /// Run the default weights embedded in the binary.
    #[arg(long)]
    pub embedded: bool,
    /// Write the rows and aggregates as JSON here.
    #[arg(long, value_name = "FILE")]
    pub json_out: Option<PathBuf>,
    /// Worker threads (default: one per logical core).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Do not refine the plane mode's focal and normal with the photo's lines (`extract --no-lines`).
    #[arg(long)]
    pub no_lines: bool,
    /// The lens distortion the plane mode undoes (`extract --lens`): auto, none or a coefficient.
    #[arg(long, value_name = "auto|none|LAMBDA", default_value = "auto", value_parser = crate::extract::parse_lens, allow_hyphen_values = true)]
    pub lens: picker_extract::LensChoice,
    /// Do not turn the plane mode's texture axes to the pattern's grain (`extract --no-grain`).
    #[arg(long)]
    pub no_grain: bool,
    /// Do not use a texture's repeats: no plane-mode fold, no net-UV fill from other repeats
    /// (`extract --no-fold`).
    #[arg(long)]
    pub no_fold: bool,
    /// Do not fold a centred repeat a second time by its half-period shift
    /// (`extract --no-centring`).
    #[arg(long)]
    pub no_centring: bool,
    /// Keep only the picked colour of a two-colour pattern (`extract --no-pattern`).
    #[arg(long)]
    pub no_pattern: bool,
    /// Keep the regions the photo sets apart in the networks' masks (`extract --no-split`).
    #[arg(long)]
    pub no_split: bool,
    /// Keep a folded tile's wrap edges where the fold put them, rather than where its texels change
    /// least (for measuring what the placement does).
    #[arg(long)]
    pub no_wrap_placement: bool,
    /// Keep each texture's level as the part of the material it came from shows it
    /// (`extract --keep-level`).
    #[arg(long)]
    pub keep_level: bool,
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
    /// As `extract --shading-sigma`: the de-lighting's shading from the networks' albedo taken
    /// over a Gaussian window of the material of this many working pixels (ground-truth albedo is
    /// used as it is).
    #[arg(long, value_name = "PX", default_value_t = picker_extract::shading::SHADING_SIGMA,
          value_parser = crate::extract::parse_sigma, allow_negative_numbers = true)]
    pub shading_sigma: f32,
    /// As `extract --single-pass`: run the networks once, not also on the mirrored photo.
    #[arg(long)]
    pub single_pass: bool,
    /// Even out broad light and dark patches in each texture, as `extract --even-out [SCALE]`.
    #[arg(long, value_name = "SCALE", num_args = 0..=1, default_missing_value = "0.125")]
    pub even_out: Option<f64>,
    /// Texture coordinates, as `extract --uv`: `plane` with the ground-truth elements measures the
    /// plane mode alone (true normals, masks and albedo, rectified instead of the true UVs).
    #[arg(long, value_enum, default_value_t = crate::extract::UvArg::Auto)]
    pub uv: crate::extract::UvArg,
    /// Score the pick masks only (IoU, precision, recall, baselines, albedo and normals at the
    /// picks): no texture is extracted, so a run takes a fraction of the time; the texture
    /// figures and `textured_extracted` are null.
    #[arg(long)]
    pub masks_only: bool,
    /// With the networks (--embedded or --weights): use the scene's ground truth instead of the
    /// networks' estimate for these parts (comma-separated), to measure what each network's
    /// error costs the extraction. Needs the networks' working size to be the scene's.
    #[arg(long, value_enum, value_delimiter = ',', value_name = "PARTS")]
    pub truth: Vec<TruthPart>,
    /// Texture side in texels, as `extract --size` (default: the observed texel density).
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=8192))]
    pub size: Option<u32>,
    /// Long side of the networks' working resolution in pixels (as `extract --work-size`); with
    /// --truth it must make the working size the scene's.
    #[arg(long, default_value_t = 320, value_parser = clap::value_parser!(u32).range(8..=4096))]
    pub work_size: u32,
}

/// One evaluated material.
#[derive(Clone, Debug, Serialize)]
pub struct Row {
    scene: String,
    material_id: u32,
    name: String,
    family: String,
    area: f64,
    pick: [u32; 2],
    textured_truth: bool,
    /// Whether the extraction made a texture (null with `--masks-only`).
    textured_extracted: Option<bool>,
    iou: f64,
    /// Share of the extracted mask inside the true mask (1: no leak).
    mask_precision: f64,
    /// Share of the true mask the extracted mask covers (1: nothing missed).
    mask_recall: f64,
    /// IoU of the flood-fill baseline, one per [`FLOOD_TOLERANCES`] entry.
    flood_iou: Vec<f64>,
    /// The best IoU a single segmentation-colour tolerance gives at this
    /// pick ([`oracle_tolerance_iou`]).
    oracle_tolerance_iou: f64,
    albedo_rmse: f64,
    normal_error_deg: f64,
    texture_psnr_db: Option<f64>,
    /// Plane mode: the aligned PSNR at the best quarter turn of the texture
    /// ([`metrics::turned_texture_score`]; a rectified plane's axes are
    /// turned to the nearest axis of its lines or grain, which may be the
    /// truth's other one); other rows: `texture_psnr_db`.
    texture_psnr_any_turn_db: Option<f64>,
    /// Plane mode: the clockwise quarter turns that gave `texture_psnr_any_turn_db`.
    texture_turns: Option<usize>,
    texture_colour_distance: Option<f64>,
    texture_size: Option<usize>,
    texture_scale: Option<f64>,
    seam_ratio: Option<f64>,
    truth_seam_ratio: Option<f64>,
    coverage: Option<f64>,
    uv_mode: Option<String>,
    colour_rmse: Option<f64>,
    /// Plane mode: the angle (degrees) between the true plane normal at the
    /// pick ([`picker_extract::plane::coplanar_part`] of the true normals and
    /// mask, else the per-component median of the true normals over the true
    /// mask) and the plane the predicted normals give.
    plane_predicted_error_deg: Option<f64>,
    /// Plane mode: the same for the normal used (refined by the lines).
    plane_error_deg: Option<f64>,
    /// Plane mode: |focal used / true focal − 1|.
    focal_rel_error: Option<f64>,
    /// Plane mode: the periods per tile when the texture was folded into
    /// one tile (`diagnostics.uv.period`), else `None`.
    folded: Option<[usize; 2]>,
    /// Plane mode, folded: the centring's agreement when the repeat was
    /// centred and each pixel folded in twice (`diagnostics.uv.period.centred`).
    centred: Option<f32>,
    /// Networks' UV mode: the whole repeats found inside the texture square
    /// (`diagnostics.uv.repeats`), else `None`.
    uv_repeats: Option<[usize; 2]>,
    /// Networks' UV mode: share of the square filled from another repeat.
    repeat_filled: Option<f64>,
    /// Share of the texture's texels filled from the rest of the mask
    /// (`diagnostics.filled_from_mask`), when it was.
    mask_filled: Option<f64>,
    /// The observed seam ratio when a band across the wrap edges was
    /// inpainted (`diagnostics.seam_band`).
    seam_band: Option<f64>,
    /// The wrap edges cut through the square's surroundings (0, 1 or 2;
    /// `diagnostics.seam_cut`), when the cut was looked for.
    seam_cut: Option<u8>,
    /// Share of the texture's texels holding observed colours
    /// (`diagnostics.observed_kept`).
    observed_kept: Option<f64>,
    /// How far the networks' two passes disagreed over the mask
    /// (`diagnostics.mirror_disagreement`), when they ran twice.
    mirror_disagreement: Option<picker_extract::pipeline::DisagreementStats>,
    /// The gain the texture was brought to its material's level by
    /// (`diagnostics.level.gain`; 1: kept as it was), when it was checked.
    level_gain: Option<f32>,
}

fn scene_dirs(dir: &Path) -> Result<Vec<PathBuf>> {
    if dir.join("scene.json").exists() {
        return Ok(vec![dir.to_path_buf()]);
    }
    if dir.exists() && !dir.is_dir() {
        bail!(
            "{}: not a folder; give a folder of `picker synth` scenes or one scene folder",
            dir.display()
        );
    }
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .with_context(|| format!("reading {}", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.join("scene.json").exists())
        .collect();
    v.sort();
    if v.is_empty() {
        bail!(
            "{}: no scene folders (with scene.json) found",
            dir.display()
        );
    }
    Ok(v)
}

/// The share of `a`'s pixels that are also in `b` (1 for an empty `a`):
/// with `a` the extracted mask and `b` the truth, the mask's precision;
/// swapped, its recall.
fn share_inside(a: &[bool], b: &[bool]) -> f64 {
    let n = a.iter().filter(|&&x| x).count();
    if n == 0 {
        return 1.0;
    }
    let both = a.iter().zip(b).filter(|&(&x, &y)| x && y).count();
    both as f64 / n as f64
}

/// Tolerances of [`oracle_tolerance_iou`]: 0.005 to 0.5 in steps of 0.005.
pub const ORACLE_TOLERANCE_STEPS: usize = 100;

/// The best IoU against `truth` of `{i : |seg_i − colour| ≤ τ}` (Euclidean
/// RGB distance, no connectivity) over `τ = 0.005·k`, `k = 1..=`
/// [`ORACLE_TOLERANCE_STEPS`]: what thresholding the segmentation at the
/// pick colour could reach with the best tolerance for this pick. Pixels
/// where `valid` is false are never taken. `seg` is 3 planes of `truth.len()`.
/// An empty truth and an empty mask agree (IoU 1, as [`metrics::mask_iou`]).
pub fn oracle_tolerance_iou(seg: &[f32], valid: &[bool], colour: [f32; 3], truth: &[bool]) -> f64 {
    let n = truth.len();
    assert_eq!(
        seg.len(),
        3 * n,
        "oracle_tolerance_iou: seg is not 3 planes"
    );
    assert_eq!(valid.len(), n, "oracle_tolerance_iou: valid length");
    // Pixels by the first tolerance that takes them (bin k: τ = 0.005·(k+1)).
    let mut inside = vec![0u64; ORACLE_TOLERANCE_STEPS];
    let mut outside = vec![0u64; ORACLE_TOLERANCE_STEPS];
    for i in (0..n).filter(|&i| valid[i]) {
        let d = (0..3)
            .map(|c| (seg[c * n + i] - colour[c]).powi(2))
            .sum::<f32>()
            .sqrt();
        let k = (d / 0.005 - 1e-6).ceil().max(1.0) as usize - 1;
        if k < ORACLE_TOLERANCE_STEPS {
            if truth[i] {
                inside[k] += 1;
            } else {
                outside[k] += 1;
            }
        }
    }
    let total = truth.iter().filter(|&&b| b).count() as u64;
    let (mut tp, mut fp, mut best) = (0u64, 0u64, 0f64);
    for k in 0..ORACLE_TOLERANCE_STEPS {
        tp += inside[k];
        fp += outside[k];
        let union = total + fp;
        // Both empty agree ([`metrics::mask_iou`]'s convention).
        let iou = if union > 0 {
            tp as f64 / union as f64
        } else {
            1.0
        };
        best = best.max(iou);
    }
    best
}

/// Colour tolerances (Euclidean sRGB distance in `[0, 1]` units) of the flood-fill baseline.
pub const FLOOD_TOLERANCES: [f32; 6] = [0.04, 0.08, 0.12, 0.16, 0.24, 0.32];

/// The baseline pick mask without networks: the 4-connected region around
/// `pick` whose sRGB colour lies within `tol` of the pick's colour (the mean of
/// its 3×3 neighbourhood, clipped to the image). `rgb` is planar `[3, h, w]`.
pub fn flood_fill(rgb: &[f32], w: usize, h: usize, pick: [u32; 2], tol: f32) -> Vec<bool> {
    assert_eq!(rgb.len(), 3 * w * h, "flood_fill: rgb is not 3×{h}×{w}");
    let (px, py) = (pick[0] as usize, pick[1] as usize);
    assert!(px < w && py < h, "flood_fill: pick outside the image");
    let n = w * h;
    let mut seed = [0.0f32; 3];
    let mut count = 0.0f32;
    for y in py.saturating_sub(1)..(py + 2).min(h) {
        for x in px.saturating_sub(1)..(px + 2).min(w) {
            for (c, s) in seed.iter_mut().enumerate() {
                *s += rgb[c * n + y * w + x];
            }
            count += 1.0;
        }
    }
    seed.iter_mut().for_each(|s| *s /= count);
    let close = |i: usize| {
        (0..3)
            .map(|c| (rgb[c * n + i] - seed[c]).powi(2))
            .sum::<f32>()
            <= tol * tol
    };
    let mut mask = vec![false; n];
    let start = py * w + px;
    mask[start] = true;
    let mut stack = vec![start];
    while let Some(i) = stack.pop() {
        for j in picker_extract::mask::neighbours4(i, w, h) {
            if !mask[j] && close(j) {
                mask[j] = true;
                stack.push(j);
            }
        }
    }
    mask
}

/// A part of the render elements that `picker eval --truth` takes from the
/// scene's ground truth instead of the networks.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum TruthPart {
    /// The diffuse albedo (the de-lighting's reference).
    Albedo,
    /// The specular albedo and the glossiness.
    Specular,
    /// The surface normals (the plane mode's plane).
    Normals,
    /// The view vectors (the plane mode's focal length).
    View,
    /// The texture coordinates and textured flag.
    Uv,
    /// The segmentation (the masks; no material embedding, not smoothed).
    Segmentation,
    /// The environment map.
    Envmap,
}

/// `inputs` (the networks' estimate, at the working size) with the parts
/// `parts` replaced by the scene's ground truth (`truth`, the scene folder
/// `dir`); refused when the working size is not the scene's `w × h`.
fn with_truth(
    mut inputs: Inputs,
    parts: &[TruthPart],
    truth: &ElementImages,
    dir: &Path,
    (w, h): (usize, usize),
) -> Result<Inputs> {
    if parts.is_empty() {
        return Ok(inputs);
    }
    let (ww, wh) = (inputs.elements.width(), inputs.elements.height());
    if (ww, wh) != (w, h) {
        bail!(
            "{}: --truth needs the networks' working size ({ww}x{wh}) to be the scene's ({w}x{h}): give --work-size {}",
            dir.display(),
            w.max(h)
        );
    }
    let el = &mut inputs.elements;
    for part in parts {
        match part {
            // The passes' disagreement describes the networks' albedo and
            // normals: it goes with either.
            TruthPart::Albedo => {
                el.diffuse = truth.diffuse.clone();
                inputs.albedo_estimated = false;
                inputs.disagreement = None;
            }
            TruthPart::Specular => {
                el.specular = truth.specular.clone();
                el.glossiness = truth.glossiness.clone();
            }
            TruthPart::Normals => {
                el.normals = truth.normals.clone();
                inputs.disagreement = None;
            }
            TruthPart::View => el.view = truth.view.clone(),
            TruthPart::Uv => el.uv = truth.uv.clone(),
            TruthPart::Segmentation => {
                let p = dir.join("segmentation.exr");
                inputs.segmentation =
                    rio::read_exr(&p).with_context(|| format!("reading {}", p.display()))?;
                inputs.embedding = None;
                inputs.segmentation_estimated = false;
            }
            TruthPart::Envmap => {
                let p = dir.join("envmap.exr");
                inputs.envmap = Some(
                    EnvMap::from_image(
                        &rio::read_exr(&p).with_context(|| format!("reading {}", p.display()))?,
                    )
                    .map_err(|e| anyhow!("{}: {e}", p.display()))?,
                );
            }
        }
    }
    Ok(inputs)
}

fn f(v: &serde_json::Value) -> Option<f32> {
    v.as_f64().map(|x| x as f32)
}

fn eval_scene(dir: &Path, a: &Args, models: Option<&crate::extract::Models>) -> Result<Vec<Row>> {
    let scene: serde_json::Value = serde_json::from_slice(
        &std::fs::read(dir.join("scene.json"))
            .with_context(|| format!("reading {}", dir.join("scene.json").display()))?,
    )
    .with_context(|| format!("parsing {}", dir.join("scene.json").display()))?;
    let ids_img = rio::read_png(&dir.join("material_id.png"))
        .with_context(|| format!("reading {}", dir.join("material_id.png").display()))?;
    let (w, h) = (ids_img.width, ids_img.height);
    let ids: Vec<u32> = ids_img
        .plane(0)
        .iter()
        .map(|&v| (v * 65535.0).round() as u32)
        .collect();
    let photo_path = dir.join("image.png");
    let truth = ElementImages::load(dir)?;
    let inputs = if let Some(models) = models {
        let est = crate::extract::infer_inputs(models, &photo_path, a.work_size)?;
        with_truth(est, &a.truth, &truth, dir, (w, h))?
    } else {
        let env_path = dir.join("envmap.exr");
        Inputs {
            photo: rio::read_png(&photo_path)?,
            elements: truth.clone(),
            segmentation: rio::read_exr(&dir.join("segmentation.exr"))?,
            embedding: None,
            segmentation_estimated: false,
            albedo_estimated: false,
            opaque: None,
            envmap: Some(
                EnvMap::from_image(&rio::read_exr(&env_path)?)
                    .map_err(|e| anyhow!("{}: {e}", env_path.display()))?,
            ),
            disagreement: None,
        }
    };
    let photo = rio::read_png(&photo_path)?;
    if photo.channels != 3 || (photo.width, photo.height) != (w, h) {
        bail!(
            "{}: not a {w}×{h} RGB image like material_id.png",
            photo_path.display()
        );
    }
    let mut prepared = Prepared::new(inputs)?;
    prepared.lens_choice = a.lens;
    let inpainter = PatchMatchInpainter::default();
    let opts = pipeline::Options {
        mask: picker_extract::mask::MaskOptions {
            no_pattern: a.no_pattern,
            no_split: a.no_split,
            ..Default::default()
        },
        uv: a.uv.choice(),
        size: a.size.map(|s| s as usize),
        max_size: pipeline::DEFAULT_MAX_SIZE,
        fov_deg: None,
        plane: None,
        quad_size_m: None,
        line_refine: !a.no_lines,
        align_grain: !a.no_grain,
        fold_period: !a.no_fold,
        fold_centring: !a.no_centring,
        fill_from_mask: !a.no_mask_fill,
        heal_seams: !a.keep_seams,
        cut_seams: !a.no_seam_cut,
        shading_sigma: a.shading_sigma,
        wrap_placement: !a.no_wrap_placement,
        tileable: true,
        seamless: false,
        even_out: a.even_out,
        level: !a.keep_level,
        seed: 0,
        inpainter: &inpainter,
    };
    // The predicted elements at the scene's size: the networks run at the
    // working size, which differs from the scene's unless it is 240×320.
    let el_diffuse = at_size(&prepared.inputs.elements.diffuse, w, h);
    let el_normals = at_size(&prepared.inputs.elements.normals, w, h);
    // The segmentation the masks read, at the scene's size, for every material's oracle.
    let seg_here = at_size(prepared.mask_segmentation(), w, h);
    let valid_here: Vec<bool> = (0..w * h)
        .map(|i| (0..3).all(|c| seg_here.data[c * w * h + i].is_finite()))
        .collect();
    let mut rows = Vec::new();
    for m in scene["materials"].as_array().cloned().unwrap_or_default() {
        let id = m["id"].as_u64().unwrap_or(0) as u32;
        let true_mask: Vec<bool> = ids.iter().map(|&i| i == id).collect();
        let area = true_mask.iter().filter(|&&b| b).count() as f64 / (w * h) as f64;
        // A material the image does not show has no pick to score (even
        // with --min-area 0).
        if area == 0.0 || area < a.min_area {
            continue;
        }
        // Chamfer (3-4) distance to the material's outside.
        let dist = picker_extract::mask::chamfer_depth(&true_mask, w, h, 3, 4);
        let best = (0..w * h)
            .max_by_key(|&i| (dist[i], std::cmp::Reverse(i)))
            .expect("non-empty");
        let pick = [(best % w) as u32, (best / w) as u32];
        let pm = prepared.pick_mask(pick, &opts.mask)?;
        let oracle = oracle_tolerance_iou(&seg_here.data, &valid_here, pm.colour, &true_mask);
        let extracted = if a.masks_only {
            None
        } else {
            Some(
                pipeline::extract(&prepared, &format!("m{id}"), Some(pick), &pm, &opts)
                    .with_context(|| format!("{}: material {id}", dir.display()))?,
            )
        };
        let got = match &extracted {
            Some((mat, _)) => Mask {
                width: w,
                height: h,
                data: mat.mask.data.iter().map(|&v| v > 0.5).collect(),
            },
            None => pipeline::photo_mask(&prepared, &pm),
        };
        let textured_truth = m["textured"].as_bool().unwrap_or(false);
        let mut row = Row {
            scene: dir
                .file_name()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_default(),
            material_id: id,
            name: m["name"].as_str().unwrap_or("").to_string(),
            family: m["family"].as_str().unwrap_or("").to_string(),
            area,
            pick,
            textured_truth,
            textured_extracted: None,
            iou: metrics::mask_iou(&got.data, &true_mask),
            mask_precision: share_inside(&got.data, &true_mask),
            mask_recall: share_inside(&true_mask, &got.data),
            flood_iou: FLOOD_TOLERANCES
                .iter()
                .map(|&t| metrics::mask_iou(&flood_fill(&photo.data, w, h, pick, t), &true_mask))
                .collect(),
            oracle_tolerance_iou: oracle,
            albedo_rmse: metrics::albedo_error(&el_diffuse, &truth.diffuse, &true_mask),
            normal_error_deg: metrics::normal_error_deg(&el_normals, &truth.normals, &true_mask),
            texture_psnr_db: None,
            texture_psnr_any_turn_db: None,
            texture_turns: None,
            texture_colour_distance: None,
            texture_size: None,
            texture_scale: None,
            seam_ratio: None,
            truth_seam_ratio: None,
            coverage: None,
            uv_mode: None,
            colour_rmse: None,
            plane_predicted_error_deg: None,
            plane_error_deg: None,
            focal_rel_error: None,
            folded: None,
            centred: None,
            uv_repeats: None,
            repeat_filled: None,
            mask_filled: None,
            seam_band: None,
            seam_cut: None,
            observed_kept: None,
            mirror_disagreement: None,
            level_gain: None,
        };
        let Some((mat, diag)) = extracted else {
            rows.push(row);
            continue;
        };
        row.textured_extracted = Some(mat.textured);
        row.texture_size = diag.texture_size;
        row.uv_mode = diag
            .uv
            .as_ref()
            .map(|u| format!("{:?}", u.mode).to_lowercase());
        row.folded = diag
            .uv
            .as_ref()
            .and_then(|u| u.period)
            .map(|f| f.periods_per_tile);
        row.centred = diag
            .uv
            .as_ref()
            .and_then(|u| u.period)
            .and_then(|f| f.centred);
        row.uv_repeats = diag.uv.as_ref().and_then(|u| u.repeats).map(|r| r.repeats);
        row.repeat_filled = diag.uv.as_ref().and_then(|u| u.repeats).map(|r| r.filled);
        row.mask_filled = diag.filled_from_mask;
        row.seam_band = diag.seam_band;
        row.seam_cut = diag
            .seam_cut
            .map(|c| u8::from(c.columns.is_some()) + u8::from(c.rows.is_some()));
        row.observed_kept = diag.observed_kept;
        row.mirror_disagreement = diag.mirror_disagreement;
        row.level_gain = diag.level.map(|l| l.gain);
        if let Some(uv) = diag.uv.as_ref().filter(|u| u.mode == UvMode::Plane) {
            // The true plane at the pick (the same rule as the extraction's:
            // a material of several planes is rectified from the one picked),
            // else the whole material's.
            let anchor = (pick[0] as usize, pick[1] as usize);
            let truth_n = picker_extract::plane::coplanar_part(
                &truth.normals,
                &true_mask,
                w,
                h,
                anchor,
                picker_extract::pipeline::AUTO_MAX_PLANE_SPREAD_DEG,
            )
            .map(|p| p.normal)
            .filter(|&n| picker_extract::plane::faces_camera(n, anchor, w, h))
            .or_else(|| picker_extract::plane::plane_normal(&truth.normals, &true_mask));
            let angle = |a: glam::Vec3, b: glam::Vec3| {
                f64::from(
                    a.normalize()
                        .dot(b.normalize())
                        .clamp(-1.0, 1.0)
                        .acos()
                        .to_degrees(),
                )
            };
            let predicted = uv
                .plane_normal
                .map(glam::Vec3::from)
                .or_else(|| picker_extract::plane::plane_normal(&el_normals, &got.data));
            let used = uv
                .lines
                .as_ref()
                .map(|l| glam::Vec3::from(l.normal))
                .or(predicted);
            if let Some(t) = truth_n {
                row.plane_predicted_error_deg = predicted.map(|p| angle(p, t));
                row.plane_error_deg = used.map(|u| angle(u, t));
            }
            let fov = scene["camera"]["fov_y_deg"].as_f64();
            if let (Some(f), Some(fov)) = (uv.focal_px, fov) {
                let true_f = h as f64 / 2.0 / (fov.to_radians() / 2.0).tan();
                row.focal_rel_error = Some((f64::from(f) / true_f - 1.0).abs());
            }
        }
        if textured_truth {
            let tex_path = dir
                .join("materials")
                .join(id.to_string())
                .join("texture.exr");
            let true_tex = rio::read_exr(&tex_path)
                .with_context(|| format!("reading the true texture {}", tex_path.display()))?;
            row.truth_seam_ratio = Some(seam_score(&true_tex).ratio);
            if let Some(t) = &mat.texture {
                // The plane mode's also at its best quarter turn, from the
                // same resampled truth.
                let s = if t.uv_mode == UvMode::Plane {
                    let (s, turned, k) = metrics::turned_texture_score(&t.texture, &true_tex);
                    row.texture_psnr_any_turn_db = Some(turned.psnr_db);
                    row.texture_turns = Some(k);
                    s
                } else {
                    let s = metrics::aligned_texture_score(&t.texture, &true_tex);
                    row.texture_psnr_any_turn_db = Some(s.psnr_db);
                    s
                };
                row.texture_psnr_db = Some(s.psnr_db);
                row.texture_colour_distance = Some(s.colour_distance);
                row.texture_scale = Some(s.scale);
                row.seam_ratio = Some(t.seam.ratio);
                row.coverage = Some(t.coverage_fraction);
            } else {
                // Extracted as a single colour: score that flat colour.
                let flat = rio::Image::new(
                    3,
                    FLAT_SIZE,
                    FLAT_SIZE,
                    (0..3)
                        .flat_map(|k| {
                            std::iter::repeat_n(mat.params.diffuse[k], FLAT_SIZE * FLAT_SIZE)
                        })
                        .collect(),
                )?;
                let s = metrics::aligned_texture_score(&flat, &true_tex);
                row.texture_psnr_db = Some(s.psnr_db);
                row.texture_psnr_any_turn_db = Some(s.psnr_db);
                row.texture_colour_distance = Some(s.colour_distance);
            }
        } else if let Some(c) = m["diffuse_colour"].as_array() {
            let c: Vec<f32> = c.iter().filter_map(f).collect();
            if c.len() == 3 {
                let e: f32 = (0..3)
                    .map(|k| (mat.params.diffuse[k] - c[k]).powi(2))
                    .sum::<f32>()
                    / 3.0;
                row.colour_rmse = Some(e.sqrt() as f64);
            }
        }
        rows.push(row);
    }
    Ok(rows)
}

fn mean(v: impl Iterator<Item = f64>) -> Option<f64> {
    let v: Vec<f64> = v.filter(|x| x.is_finite()).collect();
    (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
}

fn median(mut v: Vec<f64>) -> Option<f64> {
    v.retain(|x| x.is_finite());
    v.sort_by(f64::total_cmp);
    (!v.is_empty()).then(|| v[v.len() / 2])
}

fn min(v: impl Iterator<Item = f64>) -> Option<f64> {
    v.filter(|x| !x.is_nan()).min_by(|a, b| a.total_cmp(b))
}

fn opt(v: Option<f64>, prec: usize) -> String {
    v.map(|x| format!("{x:.prec$}"))
        .unwrap_or_else(|| "-".into())
}

/// Runs `picker eval`.
pub fn run(a: Args) -> Result<()> {
    crate::threads::init(a.threads)?;
    if !a.truth.is_empty() && a.weights.is_empty() && !a.embedded {
        bail!("--truth replaces parts of the networks' estimate: give --embedded or --weights");
    }
    if let Some(s) = a.even_out {
        crate::extract::check_even_out(s)?;
    }
    let dirs = scene_dirs(&a.dir)?;
    let models = if a.weights.is_empty() && !a.embedded {
        None
    } else {
        // No --weights with --embedded: the embedded defaults.
        Some(crate::extract::Models::load(&a.weights)?.with_mirror_pass(!a.single_pass))
    };
    let mut rows = Vec::new();
    for d in &dirs {
        rows.extend(eval_scene(d, &a, models.as_ref())?);
    }
    println!(
        "{:<14} {:>3} {:<10} {:<14} {:>6} {:>6} {:>7} {:>7} {:>8} {:>6} {:>5} {:>6} {:>6} {:>5}",
        "scene",
        "id",
        "name",
        "family",
        "area",
        "IoU",
        "alb",
        "nrm°",
        "tex dB",
        "cdist",
        "size",
        "seam",
        "tseam",
        "uv"
    );
    for r in &rows {
        println!(
            "{:<14} {:>3} {:<10} {:<14} {:>6.3} {:>6.3} {:>7.4} {:>7.2} {:>8} {:>6} {:>5} {:>6} {:>6} {:>5}",
            r.scene,
            r.material_id,
            r.name.chars().take(10).collect::<String>(),
            r.family.chars().take(14).collect::<String>(),
            r.area,
            r.iou,
            r.albedo_rmse,
            r.normal_error_deg,
            opt(r.texture_psnr_db, 2),
            opt(r.texture_colour_distance, 3),
            r.texture_size.map(|s| s.to_string()).unwrap_or_else(|| "-".into()),
            opt(r.seam_ratio, 2),
            opt(r.truth_seam_ratio, 2),
            r.uv_mode.as_deref().unwrap_or("-"),
        );
    }
    let tex: Vec<&Row> = rows.iter().filter(|r| r.textured_truth).collect();
    let agg = json!({
        "materials": rows.len(),
        "textured": tex.len(),
        "mean_iou": mean(rows.iter().map(|r| r.iou)),
        "min_iou": min(rows.iter().map(|r| r.iou)),
        "mean_mask_precision": mean(rows.iter().map(|r| r.mask_precision)),
        "mean_mask_recall": mean(rows.iter().map(|r| r.mask_recall)),
        "fraction_iou_at_least_0_8": mean(rows.iter().map(|r| f64::from(u8::from(r.iou >= 0.8)))),
        "flood_fill_mean_iou": FLOOD_TOLERANCES.iter().enumerate().map(|(k, t)| json!({
            "tolerance": (f64::from(*t) * 1e4).round() / 1e4,
            "mean_iou": mean(rows.iter().map(|r| r.flood_iou[k])),
        })).collect::<Vec<_>>(),
        "flood_fill_best_mean_iou": (0..FLOOD_TOLERANCES.len())
            .filter_map(|k| mean(rows.iter().map(|r| r.flood_iou[k])))
            .max_by(|a, b| a.total_cmp(b)),
        "mean_oracle_tolerance_iou": mean(rows.iter().map(|r| r.oracle_tolerance_iou)),
        "fraction_oracle_tolerance_iou_at_least_0_8":
            mean(rows.iter().map(|r| f64::from(u8::from(r.oracle_tolerance_iou >= 0.8)))),
        "mean_texture_psnr_db": mean(tex.iter().filter_map(|r| r.texture_psnr_db)),
        "min_texture_psnr_db": min(tex.iter().filter_map(|r| r.texture_psnr_db)),
        "mean_texture_psnr_any_turn_db": mean(tex.iter().filter_map(|r| r.texture_psnr_any_turn_db)),
        "turned_rows": rows.iter().filter(|r| r.texture_turns.is_some_and(|k| k != 0)).count(),
        "mean_texture_colour_distance": mean(tex.iter().filter_map(|r| r.texture_colour_distance)),
        "mean_seam_ratio": mean(tex.iter().filter_map(|r| r.seam_ratio)),
        "mean_truth_seam_ratio": mean(tex.iter().filter_map(|r| r.truth_seam_ratio)),
        "mean_albedo_rmse": mean(rows.iter().map(|r| r.albedo_rmse)),
        "mean_normal_error_deg": mean(rows.iter().map(|r| r.normal_error_deg)),
        "mean_colour_rmse_single_colour": mean(rows.iter().filter_map(|r| r.colour_rmse)),
        "plane_rows": rows.iter().filter(|r| r.plane_error_deg.is_some()).count(),
        "folded_rows": rows.iter().filter(|r| r.folded.is_some()).count(),
        "centred_rows": rows.iter().filter(|r| r.centred.is_some()).count(),
        "uv_repeat_rows": rows.iter().filter(|r| r.uv_repeats.is_some()).count(),
        "mask_filled_rows": rows.iter().filter(|r| r.mask_filled.is_some()).count(),
        "seam_band_rows": rows.iter().filter(|r| r.seam_band.is_some()).count(),
        "seam_cut_rows": rows.iter().filter(|r| r.seam_cut.is_some_and(|n| n > 0)).count(),
        "mean_observed_kept": mean(tex.iter().filter_map(|r| r.observed_kept)),
        "levelled_rows": rows.iter().filter(|r| r.level_gain.is_some_and(|g| g != 1.0)).count(),
        "mean_plane_predicted_error_deg": mean(rows.iter().filter_map(|r| r.plane_predicted_error_deg)),
        "mean_plane_error_deg": mean(rows.iter().filter_map(|r| r.plane_error_deg)),
        "median_plane_error_deg": median(rows.iter().filter_map(|r| r.plane_error_deg).collect()),
        "median_plane_predicted_error_deg": median(rows.iter().filter_map(|r| r.plane_predicted_error_deg).collect()),
        "mean_focal_rel_error": mean(rows.iter().filter_map(|r| r.focal_rel_error)),
        "textured_detected": tex.iter().filter(|r| r.textured_extracted == Some(true)).count(),
    });
    println!("{}", serde_json::to_string_pretty(&agg)?);
    if let Some(p) = &a.json_out {
        let text = serde_json::to_string_pretty(&json!({
            "format": "material-picker-eval", "format_version": 1,
            "dir": a.dir.display().to_string(),
            "elements": if models.is_none() { "ground truth" } else { "networks" },
            "work_size": models.as_ref().map(|_| a.work_size),
            "mirror_pass": models.as_ref().map(|_| !a.single_pass),
            "level": !a.keep_level,
            "truth": &a.truth,
            "weights": models.as_ref().map(|m| m.paths().iter().map(|p| p.display().to_string()).collect::<Vec<_>>()),
            "min_area": a.min_area, "aggregate": agg, "rows": rows,
        }))?;
        crate::output::write_atomic(p, format!("{text}\n").as_bytes())?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Planar RGB from a per-pixel colour function.
    fn image(w: usize, h: usize, f: impl Fn(usize, usize) -> [f32; 3]) -> Vec<f32> {
        let mut v = vec![0.0; 3 * w * h];
        for y in 0..h {
            for x in 0..w {
                let c = f(x, y);
                for k in 0..3 {
                    v[k * w * h + y * w + x] = c[k];
                }
            }
        }
        v
    }

    /// The plain oracle: every tolerance's mask, its IoU.
    fn oracle_reference(seg: &[f32], valid: &[bool], colour: [f32; 3], truth: &[bool]) -> f64 {
        let n = truth.len();
        (1..=ORACLE_TOLERANCE_STEPS)
            .map(|k| {
                let tau = 0.005 * k as f32;
                let m: Vec<bool> = (0..n)
                    .map(|i| {
                        valid[i]
                            && (0..3)
                                .map(|c| (seg[c * n + i] - colour[c]).powi(2))
                                .sum::<f32>()
                                .sqrt()
                                <= tau
                    })
                    .collect();
                metrics::mask_iou(&m, truth)
            })
            .fold(0.0, f64::max)
    }

    #[test]
    fn oracle_tolerance_matches_the_plain_sweep() {
        let mut rng = picker_tensor::Rng::new(40);
        for &n in &[1usize, 7, 300] {
            for spread in [0.01f32, 0.1, 0.6] {
                let seg: Vec<f32> = (0..3 * n)
                    .map(|_| rng.uniform(0.5 - spread, 0.5 + spread))
                    .collect();
                let valid: Vec<bool> = (0..n).map(|_| rng.f64() < 0.9).collect();
                let truth: Vec<bool> = (0..n).map(|_| rng.f64() < 0.4).collect();
                let c = [0.5, 0.5, 0.5];
                let a = oracle_tolerance_iou(&seg, &valid, c, &truth);
                let b = oracle_reference(&seg, &valid, c, &truth);
                assert!((a - b).abs() < 1e-12, "n {n} spread {spread}: {a} vs {b}");
            }
        }
        // Two clean colours: the oracle separates them exactly.
        let seg = [0.2, 0.2, 0.6, 0.2, 0.2, 0.6, 0.2, 0.2, 0.6];
        let truth = [true, true, false];
        assert_eq!(
            oracle_tolerance_iou(&seg, &[true; 3], [0.2; 3], &truth),
            1.0
        );
        // A true pixel beyond 0.5: 0; no true pixel and none taken: 1.
        assert_eq!(
            oracle_tolerance_iou(&[0.0; 3], &[true], [1.0; 3], &[false]),
            1.0
        );
        assert_eq!(
            oracle_tolerance_iou(&[0.0; 3], &[true], [1.0; 3], &[true]),
            0.0
        );
    }

    #[test]
    fn flood_fill_stops_at_a_colour_edge_and_at_disconnection() {
        // Left half red, right half blue, with a red island inside the blue part.
        let (w, h) = (10, 6);
        let rgb = image(w, h, |x, y| {
            if x < 5 || (x == 8 && y == 3) {
                [0.8, 0.1, 0.1]
            } else {
                [0.1, 0.1, 0.8]
            }
        });
        let m = flood_fill(&rgb, w, h, [0, 0], 0.1);
        for y in 0..h {
            for x in 0..w {
                assert_eq!(m[y * w + x], x < 5, "({x}, {y})");
            }
        }
        // A tolerance above the colour distance (≈ 0.99) takes everything.
        assert!(flood_fill(&rgb, w, h, [9, 5], 1.0).iter().all(|&b| b));
    }

    #[test]
    fn flood_fill_uses_the_mean_colour_around_the_pick() {
        // A gradient: the region is the band of columns within tol of the pick's column.
        let (w, h) = (21, 3);
        let rgb = image(w, h, |x, _| [x as f32 * 0.01; 3]);
        let m = flood_fill(&rgb, w, h, [10, 1], 0.0525);
        // |x − 10|·0.01·√3 ≤ 0.0525 ⇔ |x − 10| ≤ 3.
        for x in 0..w {
            assert_eq!(m[w + x], (7..=13).contains(&x), "column {x}");
        }
        // Picks on the border work (1-pixel image too).
        assert_eq!(flood_fill(&[0.5, 0.5, 0.5], 1, 1, [0, 0], 0.0), vec![true]);
    }
}
