//! The whole extraction (design.md §4): render elements at the working
//! resolution + the photo → for each pick, a [`Material`].
//!
//! Decisions the issue leaves open, stated once:
//! - **De-lighting** is a detail transfer: at the working resolution, where the
//!   photo and the network's albedo describe the same pixels, the ratio
//!   `ρd / photo` (per channel, linear) is the inverse shading; it is
//!   upsampled within the material (mask-aware bilinear) and multiplied by the
//!   full-resolution photo. The texture therefore has the photo's detail and
//!   the network's albedo level. Clipped (saturated) and black pixels get a low
//!   confidence (clipped ones take the network's albedo, unless a quarter of
//!   the material or more is clipped: [`CLIPPED_MATERIAL_SHARE`]). With
//!   ground-truth elements at the photo's size the ratio is exact and the
//!   de-lit colour is the true albedo.
//! - **UV mode `auto`** reprojects with the predicted UVs when their
//!   cross-validated consistency ([`reproject::consistency`]) reaches
//!   [`AUTO_MIN_R2`] (or cannot be measured because the material shows less
//!   than about one repeat) and reach at least [`AUTO_MIN_UV_FOOTPRINT`] of the
//!   texture square (collapsed UVs, all on a point or a line, do not), otherwise
//!   rectifies a plane when the picked normals agree within
//!   [`AUTO_MAX_PLANE_SPREAD_DEG`] or the UVs have collapsed, otherwise keeps
//!   the UVs. A plane is
//!   rectified from the part of the material on the plane at the pick
//!   ([`plane::coplanar_part`]: walls meeting at corners, a box's faces, a
//!   mask that took in a neighbour), which also decides whether a plane is
//!   usable when the whole material is not one.
//! - **Texture pixels**: the texture comes from the mask's surest part
//!   ([`PickMask::sure`], the pixels within the pick's own colour spread) when
//!   the mask grew beyond it; the mask, the parameters and the self-check use
//!   the whole mask.
//! - **Material parameters**: ρs and g are per-channel medians over the mask at
//!   the working resolution; n = 2^(13g); the diffuse colour is the mean of the
//!   final texture (textured) or the median de-lit colour (single colour).
//! - **Re-render self-check**: the masked pixels are re-rendered at the working
//!   resolution from the extracted material (texture looked up through the
//!   predicted UVs in UV mode, the mean colour otherwise), the predicted
//!   normals and view vectors and the estimated environment map (fast path),
//!   and compared with the photo (PSNR on sRGB values). Interreflections,
//!   shadows and lamps are not in eq. 3.7, so this is a consistency score, not
//!   an accuracy.

use std::time::Instant;

use glam::Vec3;
use picker_inpaint::{make_seamless, seam_score, InpaintOptions, Inpainter};
use picker_nets::conventions as conv;
use picker_render::io::Image;
use picker_render::{ElementImages, EnvMap, Shader};
use rayon::prelude::*;
use serde::Serialize;

use crate::mask::{Mask, MaskOptions, PickMask};
use crate::reproject::{self, Coords};
use crate::{
    mask, plane, resample, Error, Material, MaterialParams, Result, TextureResult, UserPlane,
    UvMode,
};

/// [`Prepared::palette`]: a segmentation-colour bin seeds a material while it
/// holds at least this share of the smallest material's area.
pub const PALETTE_SEED_SHARE: f64 = 0.25;
/// Smallest cross-validated R² for which `auto` trusts the predicted UVs.
pub const AUTO_MIN_R2: f64 = 0.5;
/// Smallest share of a [`AUTO_FOOTPRINT_CELLS`]² grid over the texture square
/// that the predicted UVs of the picked pixels (at the working resolution)
/// must reach for `auto` to keep them when a plane is usable: below it the UVs have collapsed (onto a
/// point or a line) and the texture would be almost all invented. 0.03 rather
/// than 0.01: with the embedded networks (`picker eval --embedded`, seeds 4242,
/// 9191, 5151) the mean aligned PSNR rose by 0.86, 0.87 and 0.71 dB and the
/// colour distance fell on all three; with ground-truth elements one box
/// seen on 1.6% of its square went to the plane mode (15.1 → 16.5 dB).
pub const AUTO_MIN_UV_FOOTPRINT: f64 = 0.03;
/// Side of the grid [`AUTO_MIN_UV_FOOTPRINT`] is measured on.
pub const AUTO_FOOTPRINT_CELLS: usize = 64;
/// Largest median normal deviation (degrees) for which `auto` rectifies a plane.
pub const AUTO_MAX_PLANE_SPREAD_DEG: f32 = 20.0;
/// Smallest share of a material that is one plane by its median normal
/// (spread ≤ [`AUTO_MAX_PLANE_SPREAD_DEG`]) that the plane at the pick must
/// hold to be rectified instead of the whole ([`plane::coplanar_part`]):
/// below it the normals at the pick are the odd ones out (the embedded
/// networks' noisy normals on the README example's ceiling, 9% of it).
/// Always taking the part, 0.2, 0.35 and 0.5 gave mean aligned PSNRs of
/// 18.44 / 18.51 / 18.54 / 18.50 dB (`picker eval --embedded`, seed 4242),
/// 18.16 / 18.12 / 18.13 / 18.14 (9191) and 19.38 / 19.34 / 18.90 / 18.86
/// (5151); with ground-truth elements and `--uv plane`, 27.36 / 27.36 /
/// 27.30 / 27.08 (4242), 27.34 / 27.34 / 27.32 / 27.12 (9191) and 26.48 for
/// all but 0.5 (26.46; 5151).
pub const PLANAR_PART_MIN_SHARE: f64 = 0.2;

/// With a given plane ([`Options::plane`]), the texture comes from the
/// part of the mask whose predicted normals are within this many degrees of
/// those at the pick ([`plane::coplanar_part`]): the other walls of a room
/// papered alike stay out (rectified through the picked wall's plane they
/// would smear its texture), while normals as noisy as the default
/// networks' on photos unlike their training rooms keep most of one
/// surface. Measured on 7 picks (the README wall by a quad and by its
/// normal, opencv-doc's chessboard by a quad and its table from above,
/// three head-on texture photos by `front`): 20° kept 6–75 % of the head-on
/// surfaces, 40° 29–98 %, and every share below
/// [`USER_PLANE_PART_MIN_SHARE`] was a surface that is one plane.
pub const USER_PLANE_MAX_DEV_DEG: f32 = 40.0;

/// With a given plane, the part of [`USER_PLANE_MAX_DEV_DEG`] is used only
/// when it holds at least this share of the mask; else the whole mask is
/// (the predicted normals are too noisy to tell surfaces apart: `--connected`
/// keeps the region at the pick).
pub const USER_PLANE_PART_MIN_SHARE: f64 = 0.5;
/// Default cap of the texture side.
pub const DEFAULT_MAX_SIZE: usize = 1024;
/// sRGB value from which a photo pixel counts as clipped.
pub const CLIPPED_SRGB: f32 = 0.995;
/// Share of a mask's pixels clipped from which the clipping counts as the
/// material's own colour overexposed (a white card, the white squares of a
/// chessboard, a lit screen) rather than highlights: those pixels are then
/// de-lit and weighted as the others instead of taking the networks'
/// albedo at a twentieth of the weight, whose blurred structure showed as
/// grey ghosts in the white (stop 56; highlights cover far less of a
/// material).
pub const CLIPPED_MATERIAL_SHARE: f64 = 0.25;

/// Which texture coordinates to use.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum UvChoice {
    /// The predicted UVs.
    Net,
    /// A rectified plane.
    Plane,
    /// The more consistent of the two (see the module docs).
    #[default]
    Auto,
}

/// Everything the extraction reads.
#[derive(Clone, Debug)]
pub struct Inputs {
    /// The photo at full resolution: sRGB-encoded display values in `[0, 1]`, 3 channels.
    pub photo: Image,
    /// The render elements at the working resolution (UVs needed for textures).
    pub elements: ElementImages,
    /// The segmentation at the working resolution (3 channels).
    pub segmentation: Image,
    /// The MSN's material embedding at the working resolution (3 channels of
    /// raw tanh values, [`picker_nets::MsnOutput::embedding`]), when the
    /// network has one: masks are then cut from it instead of the
    /// segmentation colours ([`mask::embedding_mask_space`]).
    pub embedding: Option<Image>,
    /// The segmentation is a network's estimate (`true`), not ground truth:
    /// masks then read it smoothed along the photo
    /// ([`crate::smooth::smooth_segmentation`]); ground truth is taken as exact.
    pub segmentation_estimated: bool,
    /// The diffuse albedo is a network's estimate (`true`), not ground
    /// truth: the de-lighting then takes only its low frequencies, the
    /// detail coming from the photo ([`crate::shading`],
    /// [`Options::shading_sigma`]); ground truth is taken as exact.
    pub albedo_estimated: bool,
    /// The estimated environment map (camera space), if any.
    pub envmap: Option<EnvMap>,
    /// The photo's opaque pixels at full resolution, when some are
    /// transparent ([`crate::photo::Photo::opaque`]); `None`: all are.
    /// Transparent pixels are never picked, masked or read: a pick on one is
    /// refused, masks (automatic or given) keep only opaque pixels, and a
    /// working pixel less than half opaque has no surface
    /// ([`Prepared::valid`]).
    pub opaque: Option<Mask>,
    /// How far the networks' two passes disagreed at each working pixel, when
    /// they ran twice ([`PassDisagreement`]); summed up per material in
    /// [`Diagnostics::mirror_disagreement`].
    pub disagreement: Option<PassDisagreement>,
}

/// How far the networks' pass on the photo and their pass on its mirror
/// image disagree at each working pixel
/// (`picker_nets::mirror::IrnDisagreement`): where the two estimates differ
/// the network is unsure, and the material's error tends to be larger.
#[derive(Clone, Debug)]
pub struct PassDisagreement {
    /// Mean over the channels of the two diffuse albedos' absolute
    /// difference (linear), 1 channel at the working resolution.
    pub albedo: Image,
    /// Angle in degrees between the two passes' normals, 1 channel.
    pub normals_deg: Image,
}

/// [`PassDisagreement`] averaged over a material's working-resolution mask.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct DisagreementStats {
    /// Mean absolute difference of the two passes' diffuse albedo (linear).
    pub albedo: f64,
    /// Mean angle between the two passes' normals, degrees.
    pub normals_deg: f64,
}

/// Options of one extraction.
pub struct Options<'a> {
    /// How picks become masks.
    pub mask: MaskOptions,
    /// Texture coordinate source.
    pub uv: UvChoice,
    /// Fixed texture side (else from the observed texel density).
    pub size: Option<usize>,
    /// Cap of the automatic texture side.
    pub max_size: usize,
    /// Vertical field of view (degrees) for the plane mode (else from the view vectors).
    pub fov_deg: Option<f32>,
    /// The plane to rectify instead of the predicted one: a normal, or a
    /// rectangle's four corners ([`UserPlane`]). Implies the plane mode
    /// ([`Options::uv_choice`]), whose texture comes from the part of the
    /// mask the predicted normals put on the pick's plane, as ever (they
    /// tell surfaces apart even where their orientation is off); the
    /// photo's lines do not refine it. A quad also gives the texture's axes
    /// (along its sides) and, without `fov_deg`, the focal length when it
    /// tells it ([`crate::quad::Quad::focal`]).
    pub plane: Option<UserPlane>,
    /// With a quad ([`UserPlane::Quad`]): the real size of its rectangle in
    /// metres, `[first side (corner 1 to 2), second side (2 to 3)]` (a sheet
    /// of A4 paper, a 30 cm tile). It gives the plane its scale, and the
    /// texture its size on the surface ([`TextureResult::size_m`]).
    pub quad_size_m: Option<[f32; 2]>,
    /// Refine the plane mode's normal with the vanishing directions of the
    /// photo's straight lines in the mask ([`crate::lines`]).
    pub line_refine: bool,
    /// In the plane mode, when the photo's lines give no axis, turn the
    /// texture's axes to the direction its pattern runs along (a table's
    /// wood grain; [`crate::grain`]).
    pub align_grain: bool,
    /// In the plane mode, fold the repeats of a texture that repeats along
    /// both of its axes into one tile; in the networks' UV mode, fold the
    /// whole repeats inside the texture square into one tile and lay it over
    /// the square ([`crate::period`]).
    pub fold_period: bool,
    /// With the plane mode's fold: when the texture also repeats shifted by
    /// half a period along both axes at once (a checkerboard, bricks in
    /// running bond: [`crate::period::centring`]), fold every pixel into the
    /// tile a second time, so shifted, in one robust fit
    /// ([`crate::reproject::reproject_centred`]).
    pub fold_centring: bool,
    /// When the texture comes from the mask's surest part and repeats (the
    /// plane mode's fold, the networks' UV repeats: see `fold_period`), fill
    /// the texels that no repeat of that part showed from the rest of the
    /// mask (reprojected through the same coordinates) before inpainting.
    /// The surest part is the pixels near the pick's own colour, so a
    /// pattern of two colours (a chessboard) gives it one of them and leaves
    /// the other's texels as holes that the inpainter would fill with the
    /// first colour. Only for repeating textures: on any texture, the rest's
    /// pixels (a neighbour the mask took in, the mask's edge) lowered the
    /// mean aligned texture PSNR on all seven evaluation sets (−0.06 to
    /// −0.17 dB with the embedded networks).
    pub fill_from_mask: bool,
    /// Make the texture tileable (toroidal inpainting).
    pub tileable: bool,
    /// With `tileable`, for a rectified plane (whose square is a crop of the
    /// photo's region, or a tile of a measured period): when the observed
    /// texels join worse across the wrap edges than inside
    /// ([`picker_inpaint::seam_band`]), inpaint a band across each wrap edge
    /// as well, so that the texture tiles without a visible seam; when they
    /// cannot tell (no edge has both sides observed) and the inpainted
    /// texture's seam ratio is above [`picker_inpaint::SEAM_BAND_MIN_RATIO`],
    /// inpaint again with the band cleared and keep that when it tiles
    /// better. Wrapped UVs join at the edges by construction and are left
    /// alone.
    pub heal_seams: bool,
    /// With `heal_seams`, for a rectified plane that does not repeat (its
    /// square a crop of the photo's region): reproject the square's
    /// surroundings too and cut each wrap edge where the square's two sides
    /// look alike ([`picker_inpaint::wrap_cut`]), keeping the observed
    /// texels; an axis whose surroundings were not observed gets the band.
    pub cut_seams: bool,
    /// When the inputs' albedo was estimated ([`Inputs::albedo_estimated`]):
    /// σ, in working pixels, of the Gaussian window over the material's
    /// pixels in which the de-lighting ratio (albedo ÷ photo) is taken, as
    /// the ratio of the two's local sums ([`crate::shading::delighting_ratio`]),
    /// so the texture's detail comes from the photo; 0 takes the network's
    /// albedo as it is.
    pub shading_sigma: f32,
    /// Put a folded tile's wrap edges where its observed texels change least
    /// (any cyclic shift of a repeating tile is the same texture), so that a
    /// pattern's edge is not taken for a seam ([`smoothest_wrap`]).
    pub wrap_placement: bool,
    /// Also remove colour jumps across the wrap edges when they show (see
    /// [`make_seamless`]); only with `tileable`. Off by default: on synthetic
    /// scenes with true elements it lowered the aligned texture PSNR (the
    /// seam ratio cannot tell a lighting jump from a pattern's own edge).
    pub seamless: bool,
    /// Even out the texture's broad brightness ([`crate::equalize::even_out`]):
    /// the blur's width as a fraction of the texture's side, or `None` (the
    /// default: it also flattens patterns whose light and dark areas are that
    /// wide).
    pub even_out: Option<f64>,
    /// Bring a texture whose mean luminance lies outside the quartiles of
    /// the material's local mean luminances (its de-lit colours averaged
    /// over about a quarter of the texture square, where they have the
    /// texture's chromaticity) to the nearer quartile, all channels by one
    /// gain ([`crate::level`]): a texture taken from a vignetted corner or a
    /// shadow gets the material's level.
    pub level: bool,
    /// Seed of the inpainter.
    pub seed: u64,
    /// The inpainter.
    pub inpainter: &'a dyn Inpainter,
}

impl Options<'_> {
    /// The texture coordinates' source in effect: [`UvChoice::Plane`] when a
    /// plane is given ([`Options::plane`]), else [`Options::uv`].
    pub fn uv_choice(&self) -> UvChoice {
        if self.plane.is_some() {
            UvChoice::Plane
        } else {
            self.uv
        }
    }
}

/// The inputs prepared once for any number of picks.
pub struct Prepared {
    /// The inputs.
    pub inputs: Inputs,
    /// The photo, linear RGB, full resolution.
    pub photo_linear: Image,
    /// The photo, linear RGB, area-downsampled to the working resolution
    /// (over its opaque pixels only, where some are transparent).
    pub photo_work: Image,
    /// Luma of the sRGB photo (the guide), full resolution.
    pub luma: Vec<f32>,
    /// Pixels with a surface at the working resolution (and, where the photo
    /// has transparent pixels, at least half opaque).
    pub valid: Vec<bool>,
    /// The photo has no colour: every pixel's three channels are equal (a
    /// greyscale file, or a colour file holding a greyscale picture). The
    /// networks' albedo then has a colour the photo cannot tell, so the
    /// extracted colours are grey: the de-lighting divides by the albedo's
    /// luminance ([`luminance`]) instead of per channel, and the estimated
    /// lighting is made grey the same way.
    pub greyscale: bool,
    /// Time spent preparing, ms.
    pub prepare_ms: f64,
    /// The camera's 35 mm-equivalent focal length (mm) when the photo's
    /// metadata states it ([`crate::photo::Photo::focal_35mm`]; `None` from
    /// [`Prepared::new`]): the plane mode's focal length is then
    /// `f35 / 43.27 mm` of the photo's diagonal in pixels (the 36 × 24 mm
    /// frame's diagonal), unless `--fov` or a quad that tells its own gives
    /// it ([`Diagnostics`] `uv.focal_source` `"exif"`). A photo cropped
    /// since it was taken has a shorter diagonal than the frame the
    /// equivalent refers to: give `--fov` for it.
    pub focal_35mm: Option<f32>,
    /// How the plane mode finds the photo's lens distortion
    /// ([`crate::lens`]; [`LensChoice::Auto`] from [`Prepared::new`]). Set it
    /// before the first pick: the estimate is made once.
    pub lens_choice: LensChoice,
    /// The photo's lens distortion and its focal length from its lines,
    /// found once at the first pick that needs them ([`Prepared::line_focal`]).
    line_focal: std::sync::OnceLock<LineCamera>,
    /// What masks are cut from before any smoothing: the segmentation, or the
    /// embedding in mask units when there is one ([`Prepared::mask_source`]).
    embedding_mask: Option<Image>,
    /// The segmentation the masks read ([`Prepared::mask_segmentation`]),
    /// made at the first pick when it is an estimate.
    smoothed: std::sync::OnceLock<Image>,
    /// The mask's leak-guard relief of the mask segmentation, made at the
    /// first automatic pick ([`mask::leak_guard_relief`]).
    relief: std::sync::OnceLock<Vec<f32>>,
    /// The estimated lighting prepared for shading ([`Prepared::shader`]).
    shader: std::sync::OnceLock<Option<Shader>>,
}

/// How the plane mode finds a photo's lens distortion ([`crate::lens`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LensChoice {
    /// Estimated from the photo's straight lines ([`crate::lens::estimate`]).
    Auto,
    /// Given: the division model's `λ` ([`crate::lens::Lens`]; 0: none),
    /// within [`crate::lens::LAMBDA_MIN`]..=[`crate::lens::LAMBDA_MAX`]
    /// (outside it the first plane-mode pick panics, as [`crate::lens::Lens::new`]).
    Given(f32),
}

/// What [`Prepared::line_focal`] and [`Prepared::lens`] find, once.
struct LineCamera {
    small: crate::lines::SmallLuma,
    lens: crate::lens::LensEstimate,
    focal: Option<crate::lines::LineFocal>,
}

fn check_size(what: &str, img: &Image, c: usize, w: usize, h: usize) -> Result<()> {
    if img.channels != c || img.width != w || img.height != h {
        return Err(Error::Shape {
            what: what.into(),
            expected: format!("{c} channels at {w}x{h}"),
            found: format!("{} channels at {}x{}", img.channels, img.width, img.height),
        });
    }
    Ok(())
}

impl Prepared {
    /// Checks and prepares `inputs`. A greyscale photo ([`Prepared::greyscale`])
    /// also makes the estimated lighting grey (each texel its luminance): the
    /// photo cannot tell the light's colour either.
    pub fn new(mut inputs: Inputs) -> Result<Self> {
        let t = Instant::now();
        let (w, h) = (inputs.elements.width(), inputs.elements.height());
        let (fw, fh) = (inputs.photo.width, inputs.photo.height);
        if fw == 0 || fh == 0 || w == 0 || h == 0 {
            return Err(Error::Invalid("empty photo or render elements".into()));
        }
        check_size("photo", &inputs.photo, 3, fw, fh)?;
        check_size("segmentation", &inputs.segmentation, 3, w, h)?;
        if let Some(e) = &inputs.embedding {
            check_size("material embedding", e, 3, w, h)?;
        }
        if let Some(o) = &inputs.opaque {
            if (o.width, o.height) != (fw, fh) || o.data.len() != fw * fh {
                return Err(Error::Shape {
                    what: "opaque pixels".into(),
                    expected: format!("{fw}x{fh} values"),
                    found: format!("{}x{} ({} values)", o.width, o.height, o.data.len()),
                });
            }
            if o.count() == 0 {
                return Err(Error::Invalid(
                    "every pixel of the photo is transparent".into(),
                ));
            }
        }
        let embedding_mask = inputs.embedding.as_ref().map(mask::embedding_mask_space);
        let (photo_linear, luma) = linear_and_luma(&inputs.photo);
        let mut valid: Vec<bool> = (0..w * h).map(|i| inputs.elements.is_valid(i)).collect();
        let photo_work = match &inputs.opaque {
            None => resample::area(&photo_linear, w, h),
            Some(o) => {
                let weight: Vec<f32> = o.data.iter().map(|&b| f32::from(u8::from(b))).collect();
                let share = resample::area_plane(&weight, fw, fh, w, h);
                for (v, &s) in valid.iter_mut().zip(&share) {
                    *v &= s >= 0.5;
                }
                opaque_area(&photo_linear, &weight, &share, w, h)
            }
        };
        let n = fw * fh;
        let (r, rest) = inputs.photo.data.split_at(n);
        let (g, b) = rest.split_at(n);
        let greyscale = r
            .par_chunks(4096)
            .zip(g.par_chunks(4096))
            .zip(b.par_chunks(4096))
            .all(|((r, g), b)| {
                r.iter()
                    .zip(g)
                    .zip(b)
                    .all(|((r, g), b)| r.to_bits() == g.to_bits() && g.to_bits() == b.to_bits())
            });
        if greyscale {
            if let Some(env) = inputs.envmap.as_mut() {
                for c in env.data_mut() {
                    *c = Vec3::splat(luminance(*c));
                }
            }
        }
        Ok(Self {
            inputs,
            photo_linear,
            photo_work,
            luma,
            valid,
            greyscale,
            prepare_ms: t.elapsed().as_secs_f64() * 1e3,
            focal_35mm: None,
            lens_choice: LensChoice::Auto,
            line_focal: std::sync::OnceLock::new(),
            embedding_mask,
            smoothed: std::sync::OnceLock::new(),
            relief: std::sync::OnceLock::new(),
            shader: std::sync::OnceLock::new(),
        })
    }

    /// The estimated lighting ([`Inputs::envmap`]) prepared once for shading
    /// as a continuous map ([`Shader::resolving`]): the re-render self-check
    /// of every pick and the previews share it. `None` without a map.
    pub fn shader(&self) -> Option<&Shader> {
        self.shader
            .get_or_init(|| self.inputs.envmap.as_ref().map(Shader::resolving))
            .as_ref()
    }

    /// The photo's downsampled luma (its segments undistorted by the
    /// photo's lens, [`Prepared::lens`]) and its focal length from its
    /// straight lines ([`crate::lines::focal_from_lines`]), computed once.
    pub fn line_focal(&self) -> (&crate::lines::SmallLuma, Option<&crate::lines::LineFocal>) {
        let c = self.line_camera();
        (&c.small, c.focal.as_ref())
    }

    /// The photo's lens distortion as [`Prepared::lens_choice`] says: given,
    /// or estimated from its lines ([`crate::lens::estimate`]) once.
    pub fn lens(&self) -> &crate::lens::LensEstimate {
        &self.line_camera().lens
    }

    fn line_camera(&self) -> &LineCamera {
        let (fw, fh) = self.photo_size();
        self.line_focal.get_or_init(|| {
            let mut small = crate::lines::SmallLuma::new(&self.luma, fw, fh);
            let lens = match self.lens_choice {
                LensChoice::Auto => crate::lens::estimate(&small).1,
                LensChoice::Given(lambda) => {
                    crate::lens::LensEstimate::given(&crate::lens::Lens::new(lambda, fw, fh))
                }
            };
            small.lambda = lens.lambda;
            let focal = crate::lines::focal_from_lines(&small);
            LineCamera { small, lens, focal }
        })
    }

    /// Photo size `(width, height)`.
    pub fn photo_size(&self) -> (usize, usize) {
        (self.inputs.photo.width, self.inputs.photo.height)
    }

    /// Working size `(width, height)`.
    pub fn work_size(&self) -> (usize, usize) {
        (self.inputs.elements.width(), self.inputs.elements.height())
    }

    /// The working-resolution pixel under the centre of photo pixel `(x, y)`
    /// (the same mapping that limits a photo mask to working pixels).
    pub fn to_work(&self, x: usize, y: usize) -> (usize, usize) {
        let (fw, fh) = self.photo_size();
        let (w, h) = self.work_size();
        (cell_under(x, fw, w), cell_under(y, fh, h))
    }

    /// [`Prepared::to_work`] as an index into working-resolution planes.
    fn to_work_index(&self, x: usize, y: usize) -> usize {
        let (xw, yw) = self.to_work(x, y);
        yw * self.work_size().0 + xw
    }

    /// Checks a pick given in photo pixels: inside the photo, on an opaque
    /// pixel ([`Inputs::opaque`]).
    pub fn check_pick(&self, pick: [u32; 2]) -> Result<()> {
        let (fw, fh) = self.photo_size();
        check_pick_inside(pick, (fw, fh))?;
        let [x, y] = pick.map(|v| v as usize);
        if let Some(o) = &self.inputs.opaque {
            if !o.data[y * fw + x] {
                return Err(Error::Invalid(format!(
                    "pick ({x}, {y}) is on a transparent pixel of the photo (alpha below ½): \
                     pick a visible one"
                )));
            }
        }
        Ok(())
    }

    /// `mask` (photo resolution) without the photo's transparent pixels
    /// ([`Inputs::opaque`]).
    fn visible(&self, mut mask: Mask) -> Mask {
        if let Some(o) = &self.inputs.opaque {
            for (m, &o) in mask.data.iter_mut().zip(&o.data) {
                *m &= o;
            }
        }
        mask
    }

    /// The mask of the material at `pick` (photo pixels), at the working resolution.
    pub fn pick_mask(&self, pick: [u32; 2], opts: &MaskOptions) -> Result<PickMask> {
        self.check_pick(pick)?;
        let (x, y) = self.to_work(pick[0] as usize, pick[1] as usize);
        let seg = self.mask_segmentation();
        let mut pm = mask::pick_mask_on(seg, self.relief(), &self.valid, x, y, opts)?;
        if opts.tolerance.is_some() {
            return Ok(pm);
        }
        if self.inputs.segmentation_estimated && !opts.no_split {
            self.split(&mut pm, x, y, opts.connected);
        }
        let pm = self.with_raw_sure(pm, &self.valid, x, y)?;
        if opts.no_pattern {
            return Ok(pm);
        }
        Ok(self.with_pattern(pm, opts, (x, y), &self.valid))
    }

    /// An automatic mask of an estimated segmentation without the regions
    /// the photo and the segmentation both set apart ([`crate::split`]): from
    /// the mask and from its surest part. The check is recorded in
    /// [`PickMask::split`].
    fn split(&self, pm: &mut PickMask, x: usize, y: usize, connected: bool) {
        let (sub, check) = crate::split::split_mask(
            &self.photo_work,
            self.mask_source(),
            &pm.mask,
            x,
            y,
            connected,
        );
        if let Some(sub) = sub {
            for (s, &m) in pm.sure.iter_mut().zip(&sub.data) {
                *s &= m;
            }
            pm.mask = sub;
        }
        pm.split = Some(check);
    }

    /// An automatic mask completed to its two-colour pattern when it is one
    /// of ([`crate::pattern`]): the companion is picked (as [`Self::pick_mask`]
    /// would, with the same options) on the mask's surroundings, and when the
    /// two interleave the mask becomes their union, all of it sure.
    /// With `connected`, the union's region at the pick (`at`, working
    /// pixels) is kept. Only `valid` pixels may join (the palette's pixels
    /// not yet taken). The check is recorded in [`PickMask::pattern`].
    fn with_pattern(
        &self,
        mut pm: PickMask,
        opts: &MaskOptions,
        at: (usize, usize),
        valid: &[bool],
    ) -> PickMask {
        let seg = self.mask_segmentation();
        let Some((seed, _)) = crate::pattern::companion_seed(seg, valid, &pm.mask) else {
            return pm;
        };
        let Ok(other) = mask::pick_mask_on(seg, self.relief(), valid, seed[0], seed[1], opts)
            .and_then(|o| self.with_raw_sure(o, valid, seed[0], seed[1]))
        else {
            return pm;
        };
        let blend = crate::pattern::blend(seg, valid, pm.colour, other.colour);
        let measured = crate::pattern::measure(&pm.mask, &other.mask, &blend);
        let merged = measured.is_pattern();
        let mut own_share = 1.0;
        if merged {
            let mut union = crate::pattern::merged(&pm.mask, &other.mask, &blend);
            if opts.connected {
                let (label, _) = mask::components(&union);
                let keep = mask::nearest_label(&label, union.width, at);
                for (m, &l) in union.data.iter_mut().zip(&label) {
                    *m = l != 0 && l == keep;
                }
            }
            // The texture comes from the whole pattern: the surest parts of
            // the two colours leave out the soft edge between them (where
            // the pattern's lines are) and, where either colour's mask grew
            // past its own spread, much of a colour (on left03.jpg, a pick
            // on a white square: no lines, no period, 65 % of the texture
            // observed, against 62 segments, the checker's period and all of
            // it with the whole union).
            pm.sure.clone_from(&union.data);
            let own = union
                .data
                .iter()
                .zip(&pm.mask.data)
                .filter(|(&u, &m)| u && m);
            own_share = own.count() as f64 / union.count().max(1) as f64;
            pm.mask = union;
        }
        pm.pattern = Some(crate::pattern::PatternCheck {
            companion_colour: other.colour,
            companion_pick: seed,
            measured,
            merged,
            own_share,
        });
        pm
    }

    /// An automatic mask's surest part joined with the mask's pixels that
    /// the network's raw colours put within the pick's spread
    /// ([`mask::sure_in`]), when the masks read a smoothed segmentation.
    fn with_raw_sure(
        &self,
        mut pm: PickMask,
        valid: &[bool],
        x: usize,
        y: usize,
    ) -> Result<PickMask> {
        if self.inputs.segmentation_estimated {
            let raw = mask::sure_in(self.mask_source(), valid, x, y, &pm.mask)?;
            for (s, r) in pm.sure.iter_mut().zip(raw) {
                *s |= r;
            }
        }
        Ok(pm)
    }

    /// The segmentation that masks are cut from: an estimated one smoothed
    /// along the photo ([`crate::smooth::smooth_segmentation`], computed
    /// once), ground truth as it is.
    pub fn mask_segmentation(&self) -> &Image {
        if !self.inputs.segmentation_estimated {
            return self.mask_source();
        }
        self.smoothed.get_or_init(|| {
            crate::smooth::smooth_segmentation(self.mask_source(), &self.photo_work, &self.valid)
                .expect("sizes checked in Prepared::new")
        })
    }

    /// What masks are cut from, before the smoothing of an estimate: the
    /// material embedding in mask units ([`mask::embedding_mask_space`]) when
    /// the inputs have one, else the segmentation colours.
    pub fn mask_source(&self) -> &Image {
        self.embedding_mask
            .as_ref()
            .unwrap_or(&self.inputs.segmentation)
    }

    /// A pick mask from a mask given at the photo's resolution (a user's
    /// selection, a quad's interior: [`crate::quad::Quad::interior`]) instead
    /// of one cut from the segmentation. The working-resolution mask holds
    /// the working pixels at least half covered by it (or, where none is,
    /// every working pixel it touches); all of it is sure; its colour is the
    /// mean segmentation colour over it; the tolerance is NaN (none was
    /// used). [`extract`] then uses `full` as the photo-resolution mask as it
    /// is.
    ///
    /// The photo's transparent pixels ([`Inputs::opaque`]) are taken out of
    /// `full` first.
    ///
    /// # Errors
    /// [`Error::Invalid`] when `full` is not the photo's size, is empty, or
    /// holds only transparent pixels.
    pub fn given_mask(&self, full: Mask) -> Result<PickMask> {
        let (w, h) = self.work_size();
        let (fw, fh) = self.photo_size();
        if (full.width, full.height) != (fw, fh) || full.data.len() != fw * fh {
            return Err(Error::Invalid(format!(
                "the given mask is {}x{} but the photo is {fw}x{fh}",
                full.width, full.height
            )));
        }
        if full.count() == 0 {
            return Err(Error::Invalid("the given mask has no pixels".into()));
        }
        let full = self.visible(full);
        if full.count() == 0 {
            return Err(Error::Invalid(
                "the given mask holds only transparent pixels of the photo".into(),
            ));
        }
        // Share of each working pixel's photo pixels in the mask.
        let mut hit = vec![0u32; w * h];
        let mut all = vec![0u32; w * h];
        for fy in 0..fh {
            let y = cell_under(fy, fh, h);
            for fx in 0..fw {
                let k = y * w + cell_under(fx, fw, w);
                all[k] += 1;
                hit[k] += u32::from(full.data[fy * fw + fx]);
            }
        }
        let mut data: Vec<bool> = hit
            .iter()
            .zip(&all)
            .map(|(&a, &n)| 2 * a >= n && a > 0)
            .collect();
        if !data.iter().any(|&b| b) {
            data = hit.iter().map(|&a| a > 0).collect();
        }
        let mask = Mask {
            width: w,
            height: h,
            data,
        };
        let seg = self.mask_segmentation();
        let (mut sum, mut n) = ([0f64; 3], 0usize);
        for (i, _) in mask.data.iter().enumerate().filter(|(_, &m)| m) {
            for (c, v) in sum.iter_mut().enumerate() {
                *v += f64::from(seg.at(c.min(seg.channels - 1), i));
            }
            n += 1;
        }
        Ok(PickMask {
            sure: mask.data.clone(),
            colour: sum.map(|v| (v / n.max(1) as f64) as f32),
            tolerance: f32::NAN,
            photo: Some(full),
            mask,
            pattern: None,
            split: None,
        })
    }

    /// The segmentation colour of a pick's material: the mask's colour in the
    /// segmentation, or, when masks read the embedding, the mean
    /// segmentation colour over the mask's surest pixels.
    pub fn segmentation_colour(&self, pm: &PickMask) -> [f32; 3] {
        if self.embedding_mask.is_none() {
            return pm.colour;
        }
        let seg = &self.inputs.segmentation;
        let (mut sum, mut n) = ([0f64; 3], 0usize);
        for (i, _) in pm.sure.iter().enumerate().filter(|(_, &s)| s) {
            for (c, v) in sum.iter_mut().enumerate() {
                *v += seg.at(c, i) as f64;
            }
            n += 1;
        }
        sum.map(|v| (v / n.max(1) as f64) as f32)
    }

    /// The mask segmentation's leak-guard relief, computed once.
    fn relief(&self) -> &[f32] {
        self.relief
            .get_or_init(|| mask::leak_guard_relief(self.mask_segmentation()))
    }

    /// The material palette: masks of every material covering at least
    /// `min_fraction` of the image (of its opaque part where some is
    /// transparent: [`Inputs::opaque`]) (greedy, largest segmentation-colour
    /// cluster first; a pixel belongs to at most one material), at most `max`.
    /// With `patterns`, a material whose mask makes a two-colour pattern
    /// with a companion among the pixels not yet taken is the whole pattern
    /// ([`crate::pattern`], as [`Self::pick_mask`] does). With `split`, the
    /// regions of an estimated segmentation's mask that the photo sets apart
    /// leave it and stay free for other materials ([`crate::split`], as
    /// [`Self::pick_mask`] does).
    pub fn palette(
        &self,
        min_fraction: f64,
        max: usize,
        patterns: bool,
        split: bool,
    ) -> Vec<([u32; 2], PickMask)> {
        let (w, h) = self.work_size();
        let (fw, fh) = self.photo_size();
        let seg = self.mask_segmentation();
        let mut remaining = self.valid.clone();
        // Pixels that may still seed a material: a bin whose most typical
        // pixel grew no material (or one under `min_fraction`) seeds no more
        // (its pixels stay free for other materials' masks). Before, only the
        // seed (and the small mask) left, and a noisy segmentation — random
        // weights on a 64 × 48 photo — made thousands of one-pixel attempts,
        // a minute each photo.
        let mut seedable = self.valid.clone();
        let mut out = Vec::new();
        let area = self.inputs.opaque.as_ref().map_or(1.0, Mask::fraction) * (w * h) as f64;
        while out.len() < max {
            let mut bins = std::collections::HashMap::<u32, Vec<usize>>::new();
            for i in (0..w * h).filter(|&i| remaining[i] && seedable[i]) {
                let q = |c: usize| (seg.at(c, i).clamp(0.0, 1.0) * 15.999) as u32;
                bins.entry(q(0) << 8 | q(1) << 4 | q(2))
                    .or_default()
                    .push(i);
            }
            let Some((_, members)) = bins
                .into_iter()
                .max_by_key(|(k, v)| (v.len(), std::cmp::Reverse(*k)))
            else {
                break;
            };
            // A material's segmentation colours can spread over several
            // bins (a white cup's shaded rim), so its mask grows past its
            // bin: bins down to PALETTE_SEED_SHARE of the area still seed
            // one, and only the mask must cover `min_fraction`.
            if (members.len() as f64) < PALETTE_SEED_SHARE * min_fraction * area {
                break;
            }
            // The member nearest to the bin's median colour seeds the mask.
            let med: Vec<f32> = (0..3)
                .map(|c| {
                    let mut v: Vec<f32> = members.iter().map(|&i| seg.at(c, i)).collect();
                    let mid = v.len() / 2;
                    v.select_nth_unstable_by(mid, |a, b| a.total_cmp(b));
                    v[mid]
                })
                .collect();
            let seed = *members
                .iter()
                .min_by(|&&a, &&b| {
                    let d = |i: usize| (0..3).map(|c| (seg.at(c, i) - med[c]).powi(2)).sum::<f32>();
                    d(a).total_cmp(&d(b)).then(a.cmp(&b))
                })
                .expect("non-empty bin");
            let (x, y) = (seed % w, seed / w);
            let pm = mask::pick_mask_on(
                seg,
                self.relief(),
                &remaining,
                x,
                y,
                &MaskOptions::default(),
            )
            .map(|mut pm| {
                if split && self.inputs.segmentation_estimated {
                    self.split(&mut pm, x, y, false);
                }
                pm
            })
            .and_then(|pm| self.with_raw_sure(pm, &remaining, x, y));
            let Ok(pm) = pm else {
                remaining[seed] = false;
                members.iter().for_each(|&i| seedable[i] = false);
                continue;
            };
            let pm = if patterns {
                self.with_pattern(pm, &MaskOptions::default(), (x, y), &remaining)
            } else {
                pm
            };
            let got = pm.mask.count();
            for (r, &m) in remaining.iter_mut().zip(&pm.mask.data) {
                if m {
                    *r = false;
                }
            }
            remaining[seed] = false;
            if (got as f64) < min_fraction * area {
                members.iter().for_each(|&i| seedable[i] = false);
                continue;
            }
            let pick = [
                (((x as f32 + 0.5) * fw as f32 / w as f32) as u32).min(fw as u32 - 1),
                (((y as f32 + 0.5) * fh as f32 / h as f32) as u32).min(fh as u32 - 1),
            ];
            out.push((pick, pm));
        }
        out
    }
}

/// The area average of `linear` (photo resolution) over the pixels whose
/// `weight` is 1, at `w × h`: `share` is the weight's own area average (the
/// opaque share of each working pixel). A working pixel with no opaque
/// pixel keeps the plain average.
fn opaque_area(linear: &Image, weight: &[f32], share: &[f32], w: usize, h: usize) -> Image {
    let (fw, fh) = (linear.width, linear.height);
    let mut out = Image::zeros(3, h, w);
    // The plain average only where no pixel is opaque (often nowhere).
    let all = share
        .iter()
        .any(|&s| s <= 0.0)
        .then(|| resample::area(linear, w, h));
    for c in 0..3 {
        let plane = linear.plane(c);
        let weighted: Vec<f32> = plane.iter().zip(weight).map(|(v, k)| v * k).collect();
        let kept = resample::area_plane(&weighted, fw, fh, w, h);
        for (i, o) in out.data[c * w * h..(c + 1) * w * h].iter_mut().enumerate() {
            *o = match &all {
                Some(all) if share[i] <= 0.0 => all.at(c, i),
                _ => kept[i] / share[i],
            };
        }
    }
    out
}

/// `photo.map(srgb_decode)` and [`crate::guided::luma`]`(photo)` of a 3-channel
/// photo in one pass, rows in parallel: 8-bit values decoded from a table
/// ([`SrgbDecodeTable`]), the luma by the same expression (per value: the same
/// bits; `tests::fused_linear_and_luma_match`).
fn linear_and_luma(photo: &Image) -> (Image, Vec<f32>) {
    let lut = SrgbDecodeTable::new();
    let (w, n) = (photo.width.max(1), photo.plane_len());
    let mut data = vec![0.0f32; 3 * n];
    let mut luma = vec![0.0f32; n];
    let (l0, rest) = data.split_at_mut(n);
    let (l1, l2) = rest.split_at_mut(n);
    let (p0, p1, p2) = (photo.plane(0), photo.plane(1), photo.plane(2));
    l0.par_chunks_mut(w)
        .zip(l1.par_chunks_mut(w))
        .zip(l2.par_chunks_mut(w))
        .zip(luma.par_chunks_mut(w))
        .enumerate()
        .for_each(|(y, (((l0, l1), l2), g))| {
            let o = y * w;
            let (r, gr, b) = (
                &p0[o..o + l0.len()],
                &p1[o..o + l0.len()],
                &p2[o..o + l0.len()],
            );
            for x in 0..l0.len() {
                l0[x] = lut.decode(r[x]);
                l1[x] = lut.decode(gr[x]);
                l2[x] = lut.decode(b[x]);
                g[x] = 0.2126 * r[x] + 0.7152 * gr[x] + 0.0722 * b[x];
            }
        });
    let linear = Image {
        channels: 3,
        height: photo.height,
        width: photo.width,
        data,
    };
    (linear, luma)
}

/// [`picker_render::io::srgb_decode`] with the 256 values of 8-bit photos
/// (`k / 255`, as the `image` crate converts them) and the 65 536 of 16-bit
/// ones (`k / 65535`) looked up in tables of that function's own results:
/// the same bits, without a `powf` per value.
pub struct SrgbDecodeTable {
    table: [f32; 256],
    /// The bits of `k / 255`.
    codes: [u32; 256],
    /// `srgb_decode(k / 65535)`, made once per process.
    table16: &'static [f32],
}

impl Default for SrgbDecodeTable {
    fn default() -> Self {
        Self::new()
    }
}

/// `srgb_decode(k / 65535)` for every 16-bit code `k` (~1 ms, once).
fn srgb_table16() -> &'static [f32] {
    static TABLE: std::sync::OnceLock<Vec<f32>> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| {
        (0..=u16::MAX)
            .map(|k| picker_render::io::srgb_decode(f32::from(k) / 65535.0))
            .collect()
    })
}

impl SrgbDecodeTable {
    /// The tables.
    pub fn new() -> Self {
        Self {
            table: std::array::from_fn(|k| picker_render::io::srgb_decode(k as f32 / 255.0)),
            codes: std::array::from_fn(|k| (k as f32 / 255.0).to_bits()),
            table16: srgb_table16(),
        }
    }

    /// `srgb_decode(v)`.
    #[inline]
    pub fn decode(&self, v: f32) -> f32 {
        if (0.0..=1.0).contains(&v) {
            // The nearest code (`v · 255 + ½` truncated: `round` for these
            // non-negative values wherever `v` can be a code at all).
            let k = ((v * 255.0 + 0.5) as usize).min(255);
            // Bit equality: −0.0 is not 0/255 (it decodes to −0.0).
            if self.codes[k] == v.to_bits() {
                return self.table[k];
            }
            // A 16-bit code: `k / 65535` computed as the table's was.
            let k = ((v * 65535.0 + 0.5) as usize).min(65535);
            if (k as f32 / 65535.0).to_bits() == v.to_bits() {
                return self.table16[k];
            }
        }
        picker_render::io::srgb_decode(v)
    }
}

/// Checks that `pick` (photo pixels) lies inside a photo of `(width,
/// height)` pixels ([`Prepared::check_pick`]'s first check, for a caller that
/// knows the photo at another size than the one prepared).
pub fn check_pick_inside(pick: [u32; 2], (w, h): (usize, usize)) -> Result<()> {
    let [x, y] = pick.map(|v| v as usize);
    if x >= w || y >= h {
        return Err(Error::Invalid(format!(
            "pick ({x}, {y}) is outside the {w}x{h} photo (x must be < {w}, y < {h})"
        )));
    }
    Ok(())
}

/// How the UV mode was decided (for material.json).
#[derive(Clone, Debug, Serialize)]
pub struct UvDecision {
    /// The mode used.
    pub mode: UvMode,
    /// What was asked.
    pub requested: UvChoice,
    /// Cross-validated R² of the predicted UVs, when measurable.
    pub net_r2: Option<f64>,
    /// Share of the texture square's grid cells the predicted UVs reach
    /// (see [`AUTO_MIN_UV_FOOTPRINT`]), in `auto` mode.
    pub net_uv_footprint: Option<f64>,
    /// Median deviation of the picked normals from the fitted plane (degrees).
    pub plane_spread_deg: Option<f32>,
    /// Focal length used by the plane mode (photo pixels).
    pub focal_px: Option<f32>,
    /// Where `focal_px` came from: `"fov"` (given), `"quad"` (the given
    /// quadrilateral, [`crate::quad::Quad::focal`]), `"exif"` (the photo's
    /// 35 mm-equivalent focal length, [`Prepared::focal_35mm`]), `"lines"` (the photo's
    /// vanishing points), `"view vectors"` (the predicted ones) or
    /// `"default"` ([`plane::DEFAULT_FOV_Y_DEG`]).
    pub focal_source: Option<&'static str>,
    /// The plane mode's lens distortion ([`crate::lens`]): estimated from
    /// the photo's lines, or given.
    pub lens: Option<crate::lens::LensEstimate>,
    /// The plane mode's line refinement, when it ran.
    pub lines: Option<crate::lines::LineRefinement>,
    /// The plane mode's grain ([`crate::grain`]), when it was measured (no
    /// axis from the lines, [`Options::align_grain`]); the axes were turned
    /// to it when `grain_applied`.
    pub grain: Option<crate::grain::Grain>,
    /// Whether the texture's axes were turned to the measured grain.
    pub grain_applied: bool,
    /// The plane mode's fold of a periodic texture into one tile, when one
    /// was found ([`crate::period`]).
    pub period: Option<crate::period::Fold>,
    /// The networks' UV mode: the whole repeats found inside the texture
    /// square, by which the UVs were folded ([`crate::period::fold_uv_if_periodic`]).
    pub repeats: Option<crate::period::UvRepeats>,
    /// When a plane was considered and the part of the material on the
    /// plane at the pick was taken instead of the whole: that part's share
    /// of the (sure) mask ([`plane::coplanar_part`], [`PLANAR_PART_MIN_SHARE`]).
    pub plane_part_share: Option<f64>,
    /// Plane mode: the plane's normal from the predicted normals (camera
    /// space), before any refinement by the photo's lines (`None` when a
    /// plane was given: see `user_plane`).
    pub plane_normal: Option<[f32; 3]>,
    /// Plane mode: the texture square framed on the plane (before any
    /// fold): its side as a share of the picked region's and the share of
    /// it the picked pixels cover ([`plane::Framing`]).
    pub square: Option<plane::Square>,
    /// The plane given instead of the predicted one ([`Options::plane`]),
    /// as it was used.
    pub user_plane: Option<UserPlaneUsed>,
}

/// A given plane ([`Options::plane`]) as the extraction used it.
#[derive(Clone, Debug, Serialize)]
pub struct UserPlaneUsed {
    /// `"normal"` or `"quad"`.
    pub source: &'static str,
    /// The plane's unit normal, camera space (from the quad under the focal
    /// length used, for a quad).
    pub normal: [f32; 3],
    /// The quadrilateral's corners (photo pixels), for a quad.
    pub quad: Option<[[f32; 2]; 4]>,
    /// For a quad: the angle between its two pairs of sides on the surface
    /// under the focal length used (90° for a rectangle seen with the right
    /// focal length; far from it, the focal length or the corners are off).
    pub corner_angle_deg: Option<f32>,
    /// The direction (camera space) the texture's axes were turned to: the
    /// quad's first side, or for a normal the best-supported vanishing
    /// direction of the region's lines in the plane
    /// ([`crate::lines::texture_axis`]; none without line refinement).
    pub texture_axis: Option<[f32; 3]>,
    /// The quad's real size given ([`Options::quad_size_m`]), metres.
    pub size_m: Option<[f32; 2]>,
    /// With `size_m`: metres per unit of the rectified plane (the plane
    /// through `N·P = −1`), the geometric mean of the two sides'.
    pub unit_m: Option<f64>,
    /// With `size_m`: the first side's metres per unit over the second's
    /// (1 when the quad's proportions on the rectified plane are the given
    /// ones; far from 1, the focal length, the corners or the size are off).
    pub size_ratio: Option<f64>,
}

/// A `--size` above the observed texel density is kept when the picked
/// pixels cover at least this share of what they cover at the observed
/// size; below it the texture is made at the observed size and enlarged
/// ([`Diagnostics::texture_made_size`]).
pub const ENLARGE_BELOW_COVERAGE: f64 = 0.9;

/// A `--size` more than this many times the observed side is first looked
/// at this many times the observed side (twice the largest splat radius,
/// [`reproject::MAX_SPLAT_RADIUS`]: past it the pixels stop covering the
/// texels between them); when that square is already too little covered
/// ([`ENLARGE_BELOW_COVERAGE`]), the larger one is not reprojected, and when
/// it is covered but the larger one is not, the texture is made at this
/// side and enlarged.
pub const ENLARGE_PROBE_FACTOR: usize = 8;

/// The picked pixels reprojected into the texture square at one size,
/// completed from the rest of the mask and from other repeats.
struct Observed {
    /// Mean colour per texel (0 where unobserved).
    texture: Image,
    /// Observed texels.
    known: Vec<bool>,
    /// Coverage per texel (1 channel).
    coverage: Image,
    /// Share of texels observed, the completed ones included.
    fraction: f64,
    /// Share observed by the picked pixels and the rest of the mask alone.
    own_fraction: f64,
    /// Share filled from the rest of the mask ([`Options::fill_from_mask`]).
    from_mask: Option<f64>,
    /// Share filled from other repeats of a repeating square.
    repeat_filled: Option<f64>,
}

/// The largest seam ratio ([`picker_inpaint::known_seam_ratio_axes`]) a cut
/// texture's wrap edge may keep for the cut to stand
/// ([`Options::cut_seams`]): a cut through unlike sides (another object past
/// the square's edge) can leave a step there (ratio 6.2 on a photo of a
/// cluttered table); a surface under a change of light keeps up to ~2 (the
/// tile's slope is spread out, so its neighbouring texels differ less than
/// the light's local slope at the edge: the ratio shows it, the eye does
/// not; 1.3 on a faint ramp, 2.1 on a ramp with bars in the tests).
pub const CUT_MAX_WRAP_RATIO: f64 = 2.5;

/// The smallest tile, as a share of the square's side, that a crop whose
/// wrap edges could not be cut is folded within
/// ([`Options::cut_seams`]): tiles one overlap smaller each time are tried
/// (the first, 7/8 of the side, always taken when both its edges cut; the
/// smaller ones only when they keep at least as many observed texels as the
/// square with a band inpainted across its uncut edges). On the real-photo
/// sweep of stop 51 (455 textured picks on 26 photos) the smaller tiles took
/// 14 picks off the band (250 → 236); without the observed-texel condition
/// 126, their tiles down to half the side and the tiled views more
/// repetitive.
pub const WITHIN_MIN_SIDE: f64 = 0.5;

/// The tileable texture cut from `r`, the reprojection of a `size`-texel
/// square with a margin of [`picker_inpaint::cut_margin`]`(size)` texels
/// past each side ([`Options::cut_seams`]): the wrap edges of the axes that
/// `need` it (`[columns, rows]`) are cut through the margins
/// ([`picker_inpaint::wrap_cut`]) where the cut would not show (its ratio at
/// most [`picker_inpaint::CUT_MAX_RATIO`], the cut texture's wrap seam ratio
/// along that axis at most [`CUT_MAX_WRAP_RATIO`]); the others are cropped
/// (the caller bands them). When an axis that needs it is not cut and `fold`
/// allows a smaller texture, tiles one overlap smaller each time (multiples
/// of 4, at least 16 texels and [`WITHIN_MIN_SIDE`] of the side) are folded
/// within the reprojection, placed where their overlaps were observed: the
/// first (7/8 of the side) is taken when both its edges cut, a smaller one
/// only when both cut and it keeps at least as many observed texels as the
/// square would once its uncut edges' bands were cleared.
fn cut_crop(
    r: &reproject::Reprojected,
    size: usize,
    need: [bool; 2],
    fold: bool,
) -> picker_inpaint::WrapCut {
    let m = picker_inpaint::cut_margin(size);
    // An axis is cut only where its sides look alike along the cut
    // (`CUT_MAX_RATIO`), and only where the cut texture's wrap edge then
    // joins (a cut through unlike sides — another object past the square's
    // edge — can leave its step on the wrap edge); a cut that would show is
    // taken back.
    let good = |a: Option<picker_inpaint::AxisCut>| {
        a.is_some_and(|a| a.ratio.is_none_or(|r| r <= picker_inpaint::CUT_MAX_RATIO))
    };
    let joins = |c: &picker_inpaint::WrapCut, axes| {
        picker_inpaint::known_seam_ratio_axes(&c.texture, &c.known, axes)
            .is_none_or(|r| r <= CUT_MAX_WRAP_RATIO)
    };
    let cut = |side, axes: [bool; 2]| {
        let raw =
            |axes| picker_inpaint::wrap_cut(&r.texture, &r.known, &r.coverage, side, side, m, axes);
        let c = raw(axes);
        let keep = [
            good(c.columns) && joins(&c, [true, false]),
            good(c.rows) && joins(&c, [false, true]),
        ];
        if keep == [c.columns.is_some(), c.rows.is_some()] {
            c
        } else {
            raw([axes[0] && keep[0], axes[1] && keep[1]])
        }
    };
    let c = cut(size, need);
    let uncut = [need[0] && c.columns.is_none(), need[1] && c.rows.is_none()];
    if !fold || uncut == [false, false] {
        return c;
    }
    let count = |k: &[bool]| k.iter().filter(|&&k| k).count();
    let banded =
        picker_inpaint::clear_seam_band_axes(&c.known, size, size, uncut).map_or(0, |k| count(&k));
    for step in 1.. {
        let side = size.saturating_sub(step * m) / 4 * 4;
        if side < 16 || (side as f64) < WITHIN_MIN_SIDE * size as f64 {
            break;
        }
        let within = cut(side, [true, true]);
        if within.columns.is_some()
            && within.rows.is_some()
            && (step == 1 || count(&within.known) >= banded)
        {
            return within;
        }
    }
    c
}

/// The de-lighting's use of an estimated albedo ([`Diagnostics::delight`]).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Delight {
    /// σ, in working pixels, of the smoothing of the ratio albedo ÷ photo
    /// ([`Options::shading_sigma`]).
    pub shading_sigma: f32,
    /// Share of the mask's photo pixels that were clipped
    /// ([`CLIPPED_SRGB`]): they took the network's albedo instead of the
    /// photo's detail, at a twentieth of the weight, unless
    /// [`Delight::clipped_as_material`].
    pub clipped_share: f64,
    /// The clipped pixels were de-lit and weighted as the others: at least
    /// [`CLIPPED_MATERIAL_SHARE`] of the mask was clipped, so the clipping
    /// is the material's colour overexposed, not highlights.
    pub clipped_as_material: bool,
}

/// How one axis's wrap edge was cut ([`picker_inpaint::AxisCut`]).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct SeamCutAxis {
    /// Width of the overlap band the cut runs through, in texels.
    pub overlap: usize,
    /// Share of the overlap's texel pairs observed on both sides.
    pub both_known: f64,
    /// The two sides' difference where cut over the difference between
    /// neighbouring texels (0: they agree exactly; about 1: as much as
    /// neighbours).
    pub ratio: Option<f64>,
}

/// The wrap edges cut through a rectified square's surroundings
/// ([`Options::cut_seams`]); an axis `None` was not cut (too little of its
/// surroundings observed) and gets the seam band when its sides differ.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct SeamCut {
    /// The columns' wrap edge (left against right).
    pub columns: Option<SeamCutAxis>,
    /// The rows' wrap edge (top against bottom).
    pub rows: Option<SeamCutAxis>,
    /// When no surroundings were seen, the side (texels) of the observed
    /// square the smaller tile was folded within; absent otherwise.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub within: Option<usize>,
}

impl SeamCut {
    fn from_cut(c: &picker_inpaint::WrapCut) -> Self {
        let axis = |a: Option<picker_inpaint::AxisCut>| {
            a.map(|a| SeamCutAxis {
                overlap: a.overlap,
                both_known: a.both_known,
                ratio: a.ratio,
            })
        };
        Self {
            columns: axis(c.columns),
            rows: axis(c.rows),
            within: None,
        }
    }
}

/// Diagnostics of one extraction, beyond the [`Material`].
#[derive(Clone, Debug, Serialize)]
pub struct Diagnostics {
    /// Segmentation colour of the material.
    pub segmentation_colour: [f32; 3],
    /// Tolerance used, in the mask image's units (segmentation colours, or
    /// the material embedding mapped by [`mask::embedding_mask_space`]).
    pub tolerance: f32,
    /// Median `t` (textured flag) over the mask.
    pub textured_flag: f32,
    /// UV decision, for textured materials.
    pub uv: Option<UvDecision>,
    /// The texture's side: `--size` when given, else
    /// [`Diagnostics::texture_observed_size`].
    pub texture_size: Option<usize>,
    /// Texels per unit of texture square at the median observed density
    /// (capped by `--max-size`): the side the texture is made at without a
    /// `--size`. When a smaller tile was folded within the observed square
    /// ([`SeamCut::within`]), the tile is the unit square: its side.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub texture_observed_size: Option<usize>,
    /// The side the texture was reprojected and inpainted at: the
    /// texture's, or, when a larger `--size` left the square markedly less
    /// covered ([`ENLARGE_BELOW_COVERAGE`]), the largest of
    /// [`ENLARGE_PROBE_FACTOR`] times the observed side and the observed side
    /// that was covered, the texture enlarged from it at the end.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub texture_made_size: Option<usize>,
    /// Why a material flagged textured came out as a single colour under
    /// `--uv auto`: neither mode's coordinates reached the texture square
    /// ([`Error::NoTexture`]); absent otherwise.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub texture_fallback: Option<String>,
    /// Share of the texture's texels that the mask's surest part did not
    /// show and the rest of the mask did ([`Options::fill_from_mask`]);
    /// absent when the texture came from the whole mask, did not repeat, or
    /// the fill was off.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub filled_from_mask: Option<f64>,
    /// The mask was given ([`Prepared::given_mask`]: a user's mask file, a
    /// quad's interior), not cut from the segmentation at the pick; the
    /// tolerance is then none (null).
    pub mask_given: bool,
    /// The two-colour pattern check of an automatic mask
    /// ([`crate::pattern`], [`PickMask::pattern`]): the companion material
    /// its surroundings show, how the two interleave, and whether it joined
    /// the mask; absent when the check did not run (a given mask or
    /// tolerance, `no_pattern`, a mask with no surroundings).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pattern: Option<crate::pattern::PatternCheck>,
    /// The photo's split of an automatic mask of an estimated segmentation
    /// ([`crate::split`], [`PickMask::split`]): the regions the photo and
    /// the segmentation both set apart that left the mask; absent when it
    /// did not run (ground truth, a given mask or tolerance, `no_split`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub split: Option<crate::split::SplitCheck>,
    /// The seam ratio for which a band across the wrap edges was inpainted
    /// ([`Options::heal_seams`]): the observed texels'
    /// ([`picker_inpaint::known_seam_ratio`]), or, when they could not tell,
    /// the first inpainted texture's; absent when no band was.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub seam_band: Option<f64>,
    /// How the wrap edges were cut through the square's surroundings
    /// ([`Options::cut_seams`]); absent when they were not.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub seam_cut: Option<SeamCut>,
    /// Share of the texture's texels (at the side it was made at) that hold
    /// observed colours; the rest were inpainted: the unobserved ones, and
    /// a seam band's. Absent without a texture.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub observed_kept: Option<f64>,
    /// The smallest and largest gain [`Options::even_out`] applied to the
    /// texture's texels; absent when it was off or had nothing to do.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub even_out_gain: Option<[f64; 2]>,
    /// The texture's level against the material's ([`crate::level`]): absent
    /// for a single-colour material or when the check is off.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub level: Option<crate::level::LevelCheck>,
    /// How far the networks' two passes (the mirror pass) disagreed over
    /// the material's mask ([`PassDisagreement`]): a measure of how sure they
    /// were. Absent when they ran once or the elements are given.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mirror_disagreement: Option<DisagreementStats>,
    /// How the de-lighting read the networks' albedo ([`crate::shading`]);
    /// absent when the albedo is ground truth or `shading_sigma` is 0 (the
    /// albedo as it is).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub delight: Option<Delight>,
    /// The photo has no colour ([`Prepared::greyscale`]): the extracted
    /// colours are grey.
    pub greyscale_photo: bool,
    /// Timings, ms.
    pub timings_ms: std::collections::BTreeMap<String, f64>,
}

/// Where a repeating square's wrap edges change least: the column `x` and
/// row `y` whose edge with the column (row) before it, wrapping, has the
/// smallest mean absolute luma step over the pairs of `known` texels across
/// it (an edge with fewer than half its pairs known is passed over; none:
/// 0). Ties: the lowest index.
pub fn smoothest_wrap(tex: &Image, known: &[bool]) -> [usize; 2] {
    let (w, h) = (tex.width, tex.height);
    assert_eq!(
        known.len(),
        w * h,
        "smoothest_wrap: known is the texture's size"
    );
    let luma = |i: usize| luminance(tex.rgb(i));
    let best = |n: usize, m: usize, at: &dyn Fn(usize, usize) -> usize| -> usize {
        // Edge k lies between line k−1 and line k (wrapping), m texels long.
        let mut choice = (f64::INFINITY, 0usize);
        for k in 0..n {
            let prev = (k + n - 1) % n;
            let (mut sum, mut count) = (0.0f64, 0usize);
            for j in 0..m {
                let (a, b) = (at(prev, j), at(k, j));
                if known[a] && known[b] {
                    sum += f64::from((luma(a) - luma(b)).abs());
                    count += 1;
                }
            }
            if 2 * count >= m && count > 0 {
                let cost = sum / count as f64;
                if cost < choice.0 {
                    choice = (cost, k);
                }
            }
        }
        choice.1
    };
    let x = best(w, h, &|col, row| row * w + col);
    let y = best(h, w, &|row, col| row * w + col);
    [x, y]
}

/// `img` rolled cyclically so that its column `at[0]` and row `at[1]` come
/// first.
pub fn roll(img: &Image, at: [usize; 2]) -> Image {
    let (w, h) = (img.width, img.height);
    let mut out = Image::zeros(img.channels, h, w);
    for c in 0..img.channels {
        let (src, dst) = (img.plane(c), &mut out.data[c * w * h..(c + 1) * w * h]);
        for y in 0..h {
            let sy = (y + at[1]) % h;
            for x in 0..w {
                dst[y * w + x] = src[sy * w + (x + at[0]) % w];
            }
        }
    }
    out
}

/// [`roll`] of a `w × h` mask.
fn roll_mask(m: &[bool], w: usize, h: usize, at: [usize; 2]) -> Vec<bool> {
    (0..w * h)
        .map(|i| m[((i / w + at[1]) % h) * w + (i % w + at[0]) % w])
        .collect()
}

/// The relative luminance of a linear Rec. 709 / sRGB colour.
pub fn luminance(c: Vec3) -> f32 {
    0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z
}

fn median(mut v: Vec<f32>) -> f32 {
    if v.is_empty() {
        return 0.0;
    }
    let mid = v.len() / 2;
    v.select_nth_unstable_by(mid, |a, b| a.total_cmp(b));
    v[mid]
}

/// Bilinear, wrapped lookup of an RGB texture at `(u, v)` (wrapped into
/// [0,1)²; a non-finite coordinate reads as 0).
///
/// # Panics
/// When the texture has no pixels.
pub fn sample_wrapped(tex: &Image, u: f32, v: f32) -> Vec3 {
    let (w, h) = (tex.width as i64, tex.height as i64);
    assert!(w > 0 && h > 0, "sample_wrapped: the texture has no pixels");
    let wrap = |t: f32| {
        if t.is_finite() {
            t.rem_euclid(1.0)
        } else {
            0.0
        }
    };
    let (u, v) = (wrap(u), wrap(v));
    let x = u * w as f32 - 0.5;
    let y = v * h as f32 - 0.5;
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = (x - x0, y - y0);
    let at = |xx: i64, yy: i64| tex.rgb((yy.rem_euclid(h) * w + xx.rem_euclid(w)) as usize);
    let (x0, y0) = (x0 as i64, y0 as i64);
    let a = at(x0, y0).lerp(at(x0 + 1, y0), fx);
    let b = at(x0, y0 + 1).lerp(at(x0 + 1, y0 + 1), fx);
    a.lerp(b, fy)
}

/// Extracts the material of the mask `pm` (working resolution), picked at `pick`.
///
/// Under `--uv auto` ([`UvChoice::Auto`]) a material whose texture cannot be
/// reprojected ([`Error::NoTexture`]: the predicted UVs unusable and no
/// plane to fall back on, e.g. one seen edge-on or from behind, as noisy
/// normals can make it) comes out as a single colour, with the reason in
/// [`Diagnostics::texture_fallback`], so that one such material does not
/// fail a palette or a batch; an explicit `--uv net|plane` reports the error.
pub fn extract(
    p: &Prepared,
    name: &str,
    pick: Option<[u32; 2]>,
    pm: &PickMask,
    opts: &Options,
) -> Result<(Material, Diagnostics)> {
    check_request(p, pm, opts)?;
    if let (Some(full), Some([x, y])) = (&pm.photo, pick) {
        let (x, y) = (x as usize, y as usize);
        if x >= full.width || y >= full.height || !full.data[y * full.width + x] {
            return Err(Error::Invalid(format!(
                "the pick {x},{y} is outside the given mask"
            )));
        }
    }
    match extract_as(p, name, pick, pm, opts, false) {
        Err(Error::NoTexture(why)) if opts.uv_choice() == UvChoice::Auto => {
            let (m, mut diag) = extract_as(p, name, pick, pm, opts, true)?;
            diag.texture_fallback = Some(why);
            Ok((m, diag))
        }
        r => r,
    }
}

/// The diagonal of the 35 mm film frame (36 × 24 mm), which 35 mm-equivalent
/// focal lengths refer to.
pub const FRAME_35MM_DIAGONAL_MM: f32 = 43.266_615;

/// The focal length in pixels of a `w × h` photo taken at the 35 mm-equivalent
/// focal length `f35` (mm): `f35` per [`FRAME_35MM_DIAGONAL_MM`] of the
/// photo's diagonal (the equivalent is defined by the diagonal angle of view).
pub fn focal_from_35mm(f35: f32, w: usize, h: usize) -> f32 {
    let d = ((w as f64).powi(2) + (h as f64).powi(2)).sqrt();
    (f64::from(f35) * d / f64::from(FRAME_35MM_DIAGONAL_MM)) as f32
}

/// Largest texture side [`extract`] makes ([`Options::size`],
/// [`Options::max_size`]): 64 M texels, 0.8 GB of f32 RGB.
pub const MAX_TEXTURE_SIDE: usize = 8192;

/// Refuses what [`extract`] cannot honour: a texture side beyond
/// [`MAX_TEXTURE_SIDE`] (or 0), a pick mask of another size than the
/// working resolution, or one whose fields disagree (they are public).
fn check_request(p: &Prepared, pm: &PickMask, opts: &Options) -> Result<()> {
    for (what, v) in [("size", opts.size), ("max_size", Some(opts.max_size))] {
        if let Some(v) = v.filter(|&v| v == 0 || v > MAX_TEXTURE_SIDE) {
            return Err(Error::Invalid(format!(
                "texture {what} {v} must be between 1 and {MAX_TEXTURE_SIDE}"
            )));
        }
    }
    match opts.plane {
        Some(UserPlane::Quad(q)) => {
            let (fw, fh) = p.photo_size();
            q.check(fw, fh)
                .map_err(|e| Error::Invalid(format!("the plane's quadrilateral: {e}")))?;
            if let Some([a, b]) = opts.quad_size_m {
                if !(a.is_finite() && b.is_finite() && a > 0.0 && b > 0.0) {
                    return Err(Error::Invalid(format!(
                        "the quadrilateral's size {a} x {b} m must be positive and finite"
                    )));
                }
            }
        }
        Some(UserPlane::Normal(_)) | None if opts.quad_size_m.is_some() => {
            return Err(Error::Invalid(
                "a quadrilateral's size needs the quadrilateral (UserPlane::Quad)".into(),
            ));
        }
        Some(UserPlane::Normal(n)) if !(n.is_finite() && (n.length() - 1.0).abs() < 1e-3) => {
            return Err(Error::Invalid(format!(
                "the plane's normal {n} is not a unit vector (UserPlane::normal makes one)"
            )));
        }
        _ => {}
    }
    if let Some(full) = &pm.photo {
        let (fw, fh) = p.photo_size();
        if (full.width, full.height) != (fw, fh) || full.data.len() != fw * fh {
            return Err(Error::Invalid(format!(
                "the given mask is {}x{} ({} values) but the photo is {fw}x{fh}",
                full.width,
                full.height,
                full.data.len()
            )));
        }
        if full.count() == 0 {
            return Err(Error::Invalid("the given mask has no pixels".into()));
        }
    }
    let (w, h) = p.work_size();
    let m = &pm.mask;
    if (m.width, m.height) != (w, h) || m.data.len() != w * h || pm.sure.len() != w * h {
        return Err(Error::Invalid(format!(
            "the pick mask is {}x{} ({} values, {} sure) but the working resolution is {w}x{h}",
            m.width,
            m.height,
            m.data.len(),
            pm.sure.len()
        )));
    }
    Ok(())
}

/// A pick mask ([`Prepared::pick_mask`], working resolution) at the photo's
/// resolution, as [`extract`] makes it: a given one ([`PickMask::photo`]) as
/// it is, else guided-upsampled to the photo's
/// edges ([`mask::refine`]); a material thinner than a photo-resolution edge
/// keeps its coarse mask, each masked working pixel also marking the photo
/// pixel under its centre, so a non-empty mask never becomes empty. The
/// photo's transparent pixels ([`Inputs::opaque`]) are left out (a working
/// pixel with a surface is at least half opaque, so a mask of them keeps
/// some).
pub fn photo_mask(p: &Prepared, pm: &PickMask) -> Mask {
    if let Some(full) = &pm.photo {
        return full.clone();
    }
    let (w, h) = p.work_size();
    let (fw, fh) = p.photo_size();
    let full = p.visible(mask::refine(&pm.mask, &p.luma, fw, fh));
    if full.count() == 0 {
        // A material thinner than a photo-resolution edge: keep the coarse mask.
        // Each masked working pixel also marks the photo pixel under its centre,
        // so a non-empty coarse mask never becomes empty (tiny or downscaled photos).
        let up = resample::bilinear_plane(&pm.mask.to_image().data, w, h, fw, fh);
        let mut data: Vec<bool> = up.iter().map(|&v| v >= 0.5).collect();
        for (i, _) in pm.mask.data.iter().enumerate().filter(|(_, &m)| m) {
            let (x, y) = (i % w, i / w);
            let (fx, fy) = (cell_under(x, w, fw), cell_under(y, h, fh));
            data[fy * fw + fx] = true;
        }
        let coarse = Mask {
            width: fw,
            height: fh,
            data,
        };
        match &p.inputs.opaque {
            None => coarse,
            Some(_) => {
                let seen = p.visible(coarse);
                if seen.count() > 0 {
                    seen
                } else {
                    // Every photo pixel the masked working pixels cover.
                    let keep: Vec<bool> = (0..fw * fh)
                        .map(|i| pm.mask.data[p.to_work_index(i % fw, i / fw)])
                        .collect();
                    p.visible(Mask {
                        width: fw,
                        height: fh,
                        data: keep,
                    })
                }
            }
        }
    } else {
        full
    }
}

/// [`extract`], as a single colour whatever the textured flag when `plain`.
fn extract_as(
    p: &Prepared,
    name: &str,
    pick: Option<[u32; 2]>,
    pm: &PickMask,
    opts: &Options,
    plain: bool,
) -> Result<(Material, Diagnostics)> {
    let uv_choice = opts.uv_choice();
    let mut timings = std::collections::BTreeMap::new();
    let mut lap = {
        let mut t = Instant::now();
        move |what: &str, timings: &mut std::collections::BTreeMap<String, f64>| {
            timings.insert(
                what.to_string(),
                (t.elapsed().as_secs_f64() * 1e6).round() / 1e3,
            );
            t = Instant::now();
        }
    };
    let el = &p.inputs.elements;
    let (w, h) = p.work_size();
    let (fw, fh) = p.photo_size();
    let mw = &pm.mask.data;
    if pm.mask.count() == 0 {
        return Err(Error::Invalid("the picked material has no pixels".into()));
    }
    let full = photo_mask(p, pm);
    lap("mask", &mut timings);

    // Parameters over the working-resolution mask.
    let idx: Vec<usize> = (0..w * h).filter(|&i| mw[i]).collect();
    let spec: Vec<f32> = (0..3)
        .map(|c| median(idx.iter().map(|&i| el.specular.at(c, i)).collect()))
        .collect();
    let gloss = median(idx.iter().map(|&i| el.glossiness.at(0, i)).collect()).clamp(0.0, 1.0);
    let t_flag = el
        .uv
        .as_ref()
        .map(|uv| median(idx.iter().map(|&i| uv.at(2, i)).collect()))
        .unwrap_or(0.0);

    // De-lit colours at full resolution.
    // The networks' albedo as the de-lighting reads it: grey (its
    // luminance) for a greyscale photo, whose colour it cannot tell.
    let grey;
    let albedo = if p.greyscale {
        let mut g = Image::zeros(3, h, w);
        for &i in &idx {
            g.set_rgb(i, Vec3::splat(luminance(el.diffuse.rgb(i))));
        }
        grey = g;
        &grey
    } else {
        &el.diffuse
    };
    let mut ratio = Image::zeros(3, h, w);
    let mut rw = vec![0.0f32; w * h];
    for &i in &idx {
        let ph = p.photo_work.rgb(i);
        let alb = albedo.rgb(i);
        if ph.min_element() > 0.004 {
            ratio.set_rgb(i, (alb / ph).min(Vec3::splat(crate::shading::RATIO_MAX)));
            rw[i] = 1.0;
        }
    }
    // A network's albedo: its low frequencies only (the light), the detail
    // the photo's.
    // Where the photo is clipped its detail is not the material's (a
    // highlight, a lamp's reflection): the network's albedo stands in there,
    // the ratio as it was — unless so much of the material is clipped
    // ([`CLIPPED_MATERIAL_SHARE`]) that the clipping is its own colour
    // overexposed (a white card, a chessboard's white squares).
    let mut unsmoothed = None;
    let mut clipped_share = 0.0;
    let mut clipped_as_material = false;
    if p.inputs.albedo_estimated && opts.shading_sigma > 0.0 {
        // The ratio of the albedo's and the photo's local sums, not the mean
        // of the pixels' own ratios (`crate::shading::delighting_ratio`).
        let smooth =
            crate::shading::delighting_ratio(albedo, &p.photo_work, &rw, opts.shading_sigma);
        unsmoothed = Some(std::mem::replace(&mut ratio, smooth));
    }
    // Only the masked pixels of the de-lit photo are ever read (reprojection,
    // consistency and medians all go through `full`): the others stay 0.
    let delit = if rw.iter().any(|&v| v > 0.0) {
        let mut d = resample::masked_bilinear_where(&ratio, &rw, fw, fh, &full.data);
        let n = fw * fh;
        if let Some(raw) = &unsmoothed {
            let clipped: Vec<bool> = (0..n)
                .into_par_iter()
                .map(|i| full.data[i] && (0..3).any(|k| p.inputs.photo.at(k, i) >= CLIPPED_SRGB))
                .collect();
            let count = clipped.iter().filter(|&&c| c).count();
            clipped_share = count as f64 / full.count().max(1) as f64;
            clipped_as_material = clipped_share >= CLIPPED_MATERIAL_SHARE;
            if count > 0 && !clipped_as_material {
                let r = resample::masked_bilinear_where(raw, &rw, fw, fh, &clipped);
                for (i, _) in clipped.iter().enumerate().filter(|(_, &c)| c) {
                    for c in 0..3 {
                        d.data[c * n + i] = r.data[c * n + i];
                    }
                }
            }
        }
        let (d0, rest) = d.data.split_at_mut(n);
        let (d1, d2) = rest.split_at_mut(n);
        let step = fw.max(1);
        d0.par_chunks_mut(step)
            .zip(d1.par_chunks_mut(step))
            .zip(d2.par_chunks_mut(step))
            .enumerate()
            .for_each(|(y, ((r0, r1), r2))| {
                for x in 0..r0.len() {
                    let i = y * fw + x;
                    if full.data[i] {
                        let v = p.photo_linear.rgb(i) * Vec3::new(r0[x], r1[x], r2[x]);
                        (r0[x], r1[x], r2[x]) = (v.x, v.y, v.z);
                    }
                }
            });
        d
    } else {
        resample::masked_bilinear_where(
            &el.diffuse,
            &mw.iter().map(|&b| b as u8 as f32).collect::<Vec<_>>(),
            fw,
            fh,
            &full.data,
        )
    };
    let interior = full.eroded();
    let confidence: Vec<f32> = (0..fw * fh)
        .into_par_iter()
        .map(|i| {
            if !full.data[i] {
                return 0.0;
            }
            let mut c = if interior.data[i] { 1.0 } else { 0.25 };
            let s = (0..3)
                .map(|k| p.inputs.photo.at(k, i))
                .fold(0.0f32, f32::max);
            if s >= CLIPPED_SRGB && !clipped_as_material {
                c *= 0.05;
            }
            c
        })
        .collect();
    lap("delight", &mut timings);

    let textured_by_flag = t_flag >= conv::TEXTURED_THRESHOLD && el.uv.is_some();
    let textured = !plain && (textured_by_flag || uv_choice == UvChoice::Plane);
    let mut diag = Diagnostics {
        segmentation_colour: p.segmentation_colour(pm),
        tolerance: pm.tolerance,
        textured_flag: t_flag,
        uv: None,
        texture_size: None,
        texture_observed_size: None,
        texture_made_size: None,
        texture_fallback: None,
        filled_from_mask: None,
        mask_given: pm.photo.is_some(),
        pattern: pm.pattern.clone(),
        split: pm.split.clone(),
        greyscale_photo: p.greyscale,
        seam_band: None,
        seam_cut: None,
        observed_kept: None,
        even_out_gain: None,
        level: None,
        mirror_disagreement: p
            .inputs
            .disagreement
            .as_ref()
            .filter(|d| {
                [&d.albedo, &d.normals_deg]
                    .iter()
                    .all(|i| (i.width, i.height, i.channels) == (w, h, 1))
            })
            .map(|d| {
                let mean = |img: &Image| {
                    idx.iter().map(|&i| f64::from(img.data[i])).sum::<f64>()
                        / idx.len().max(1) as f64
                };
                DisagreementStats {
                    albedo: mean(&d.albedo),
                    normals_deg: mean(&d.normals_deg),
                }
            }),
        delight: unsmoothed.as_ref().map(|_| Delight {
            shading_sigma: opts.shading_sigma,
            clipped_share,
            clipped_as_material,
        }),
        timings_ms: Default::default(),
    };
    let mut texture = None;
    let mut uv_work: Option<&Image> = None;
    let diffuse_mean;
    if textured {
        // The texture comes from the mask's surest part (`PickMask::sure`:
        // the pixels within the pick's own colour spread, where the mask
        // grew beyond it); the mask and the parameters stay whole.
        let (whole_mw, whole_full) = (mw, &full);
        let sure_full;
        let (mw, full) = if pm.sure != *mw {
            sure_full = restrict_to_work(&full, &pm.sure, w, h);
            (&pm.sure, &sure_full)
        } else {
            (mw, &full)
        };
        // The rest of the mask, when the texture's pixels are fewer
        // (`Options::fill_from_mask`).
        let rest_full = (opts.fill_from_mask && !std::ptr::eq(full, whole_full))
            .then(|| Mask {
                width: fw,
                height: fh,
                data: whole_full
                    .data
                    .iter()
                    .zip(&full.data)
                    .map(|(&a, &b)| a && !b)
                    .collect(),
            })
            .filter(|m| m.count() > 0);
        // Coordinates.
        // Upsampled only inside the mask (the only pixels any use reads), and
        // not at all when the plane was asked for.
        let normal = plane::plane_normal(&el.normals, mw);
        let spread = normal.map(|n| plane::normal_spread_deg(&el.normals, mw, n));
        let planar = spread.is_some_and(|s| s <= AUTO_MAX_PLANE_SPREAD_DEG);
        // The footprint of the predicted UVs, measured on the working-resolution
        // mask; collapsed UVs on a usable plane are never upsampled.
        let net_footprint = match (&el.uv, uv_choice) {
            (Some(uv), UvChoice::Auto) => Coords {
                width: w,
                height: h,
                u: uv.plane(0).to_vec(),
                v: uv.plane(1).to_vec(),
                wrap: true,
            }
            .footprint(mw, AUTO_FOOTPRINT_CELLS),
            _ => None,
        };
        let collapsed = net_footprint.is_some_and(|f| f < AUTO_MIN_UV_FOOTPRINT);
        let net_coords = el
            .uv
            .as_ref()
            .filter(|_| {
                uv_choice != UvChoice::Plane
                    && !(uv_choice == UvChoice::Auto && collapsed && planar)
            })
            .map(|uv| upsampled_uv(uv, mw, fw, fh, &full.data));
        let whole_cap = observed_cap(opts.max_size, full.count());
        // Collapsed UVs are not used whatever their consistency: skip measuring it.
        let net_r2 = match (&net_coords, uv_choice) {
            (Some(c), UvChoice::Auto) if !collapsed => {
                let probe_size = reproject::texture_size(c.sizing_area(&full.data), whole_cap);
                reproject::consistency(c, &full.data, &delit, probe_size).map(|r| r.0)
            }
            _ => None,
        };
        let net_ok = net_r2.is_none_or(|r| r >= AUTO_MIN_R2) && !collapsed;
        // Where a plane may be rectified, only the pixels on the plane at
        // the pick are: a material that is not one plane (walls meeting at
        // corners, a box's faces, a mask that took in a neighbour) gives
        // its texture from the part the user picked, and pixels of another
        // plane do not land at wrong places in it. The mask and parameters
        // stay whole.
        let wants_plane = match uv_choice {
            UvChoice::Net => false,
            UvChoice::Plane => true,
            UvChoice::Auto => !net_ok || net_coords.is_none(),
        };
        let anchor = match pick {
            Some(k) => p.to_work(k[0] as usize, k[1] as usize),
            None => central_pixel(mw, w),
        };
        let part = if opts.plane.is_some() {
            // A given plane: the predicted normals only tell surfaces apart
            // (their orientation is what the user overrode), so the part
            // is taken with a wide tolerance and only when it holds most of
            // the mask; a smaller one says they are too noisy to tell.
            plane::coplanar_part(&el.normals, mw, w, h, anchor, USER_PLANE_MAX_DEV_DEG)
                .filter(|pp| pp.share >= USER_PLANE_PART_MIN_SHARE)
        } else if wants_plane {
            plane::coplanar_part(&el.normals, mw, w, h, anchor, AUTO_MAX_PLANE_SPREAD_DEG)
                .filter(|pp| plane::faces_camera(pp.normal, anchor, w, h))
                // A material that is one plane by its median normal keeps
                // its whole unless the pick's plane holds most of it (else
                // the normals at the pick are the odd ones out).
                .filter(|pp| !planar || pp.share >= PLANAR_PART_MIN_SHARE)
        } else {
            None
        };
        let part_full;
        let (mw, full, normal, spread, planar) = match &part {
            Some(pp) => {
                part_full = restrict_to_work(full, &pp.mask, w, h);
                (
                    &pp.mask,
                    &part_full,
                    Some(pp.normal),
                    Some(pp.spread_deg),
                    true,
                )
            }
            None => (mw, full, normal, spread, planar),
        };
        let observed_cap = observed_cap(opts.max_size, full.count());
        // The plane mode's rest of the mask: the part of the whole mask on
        // the plane at the pick ([`plane::coplanar_part`] of the whole mask),
        // outside the texture's pixels.
        let rest_plane = || {
            let rest = rest_full.as_ref()?;
            if opts.plane.is_some() && part.is_none() {
                // A given plane that holds the whole mask holds its rest.
                return Some(rest.clone());
            }
            let pp = plane::coplanar_part(
                &el.normals,
                whole_mw,
                w,
                h,
                anchor,
                if opts.plane.is_some() {
                    USER_PLANE_MAX_DEV_DEG
                } else {
                    AUTO_MAX_PLANE_SPREAD_DEG
                },
            )?;
            let m = restrict_to_work(rest, &pp.mask, w, h);
            (m.count() > 0).then_some(m)
        };
        let plane_coords = |diag_focal: &mut Option<(f32, &'static str)>,
                            diag_lines: &mut Option<crate::lines::LineRefinement>,
                            diag_grain: &mut (Option<crate::grain::Grain>, bool),
                            diag_user: &mut Option<UserPlaneUsed>,
                            side_out: &mut Option<plane::Square>,
                            rest_src: &mut Option<Mask>,
                            replan: &mut Option<(Vec3, plane::Camera, Option<Vec3>, bool)>|
         -> Option<Coords> {
            // The photo's lens: the quad's corners and every pixel are
            // undistorted before they become rays.
            let lambda = p.lens().lambda;
            let lens = crate::lens::Lens::new(lambda, fw, fh);
            let quad = match opts.plane {
                Some(UserPlane::Quad(q)) => Some(q.undistorted(&lens)),
                _ => None,
            };
            // --fov, else a given quad's (when it tells it), else the
            // photo's EXIF, else the photo's lines (when refining with
            // them), else the predicted view vectors, else the default field
            // of view.
            let quad_focal = quad
                .filter(|_| opts.fov_deg.is_none())
                .and_then(|q| q.focal(fw, fh));
            let exif_focal = p
                .focal_35mm
                .filter(|f| f.is_finite() && *f > 0.0)
                .map(|f35| focal_from_35mm(f35, fw, fh));
            let line_focal = (opts.fov_deg.is_none()
                && quad_focal.is_none()
                && exif_focal.is_none()
                && opts.line_refine)
                .then(|| p.line_focal().1)
                .flatten();
            let (f, focal_source) = match (opts.fov_deg, quad_focal.or(exif_focal), line_focal) {
                (Some(fov), _, _) => (plane::focal_from_fov(fh, fov), "fov"),
                (None, Some(qf), _) if quad_focal.is_some() => (qf, "quad"),
                (None, Some(ef), _) => (ef, "exif"),
                (None, None, Some(lf)) => (lf.focal_px, "lines"),
                (None, None, None) => {
                    // The view vectors' focal, unless its field of view is
                    // implausible for a photo of a room (the default
                    // networks' view vectors often say ~20°).
                    let (lo, hi) = crate::lines::FOCAL_FOV_RANGE;
                    match plane::focal_from_view(&el.view, mw)
                        .filter(|&f| (lo..=hi).contains(&plane::fov_from_focal(h, f)))
                    {
                        Some(fv) => (fv * fh as f32 / h as f32, "view vectors"),
                        None => (
                            plane::focal_from_fov(h, plane::DEFAULT_FOV_Y_DEG) * fh as f32
                                / h as f32,
                            "default",
                        ),
                    }
                }
            };
            *diag_focal = Some((f, focal_source));
            let (n, along) = match opts.plane {
                Some(UserPlane::Normal(n)) => {
                    // The texture's axes along the region's lines that lie
                    // in the plane, when it has some (a floor's planks).
                    let along = opts.line_refine.then(|| {
                        let vanishing =
                            crate::lines::region_vanishing(p.line_focal().0, &full.data, f);
                        crate::lines::texture_axis(&vanishing, n)
                    });
                    *diag_user = Some(UserPlaneUsed {
                        source: "normal",
                        normal: n.to_array(),
                        quad: None,
                        corner_angle_deg: None,
                        texture_axis: along.flatten(),
                        size_m: None,
                        unit_m: None,
                        size_ratio: None,
                    });
                    (n, along.flatten().map(Vec3::from))
                }
                Some(UserPlane::Quad(given)) => {
                    let q = given.undistorted(&lens);
                    let qp = q.plane(fw, fh, f).ok()?;
                    // Metres per plane unit from the quad's real size: the
                    // geometric mean of its two sides' (they agree when the
                    // plane and focal length are right).
                    let scale = opts.quad_size_m.and_then(|[a, b]| {
                        let s = q.sides_on_plane(fw, fh, f, qp.normal)?;
                        let (ma, mb) = (
                            f64::from(a) / ((s[0] + s[2]) / 2.0),
                            f64::from(b) / ((s[1] + s[3]) / 2.0),
                        );
                        (ma.is_finite() && mb.is_finite()).then(|| ((ma * mb).sqrt(), ma / mb))
                    });
                    *diag_user = Some(UserPlaneUsed {
                        source: "quad",
                        normal: qp.normal.to_array(),
                        quad: Some(given.0),
                        corner_angle_deg: Some(qp.corner_angle_deg),
                        texture_axis: Some(qp.along.to_array()),
                        size_m: opts.quad_size_m,
                        unit_m: scale.map(|s| s.0),
                        size_ratio: scale.map(|s| s.1),
                    });
                    (qp.normal, Some(qp.along))
                }
                None => {
                    let n = normal?;
                    if opts.line_refine {
                        let (n, mut found) = crate::lines::refine_plane_normal(
                            p.line_focal().0,
                            &full.data,
                            n,
                            f,
                            line_focal.map(|lf| &lf.axes),
                        );
                        found.focal = line_focal.cloned();
                        let along = found.texture_axis.map(Vec3::from);
                        *diag_lines = Some(found);
                        (n, along)
                    } else {
                        (n, None)
                    }
                }
            };
            // A plane seen edge-on or from behind at every picked pixel
            // gives no coordinates: no plane.
            let rest = rest_plane();
            // With the fold, the whole square first (the most periods to
            // find); the covered one replaces it when nothing repeats.
            let framing = if opts.fold_period {
                plane::Framing::Whole
            } else {
                plane::Framing::Covered
            };
            let cam = plane::Camera::new(f, lambda);
            let coords_along = |along: Option<Vec3>| {
                plane::plane_coords_with_side(
                    fw,
                    fh,
                    &full.data,
                    rest.as_ref().map(|m| &m.data[..]),
                    n,
                    cam,
                    along,
                    framing,
                )
            };
            let (mut c, mut side) = coords_along(along);
            let mut along = along;
            // No axis from the lines: the pattern's own direction, if clear.
            if along.is_none() && opts.align_grain {
                let g = crate::grain::measure(&c, &full.data, &p.luma);
                if let Some(g) = g.filter(crate::grain::Grain::decisive) {
                    let (e1, e2) = plane::plane_basis(n, None);
                    // Texture direction (du, dv) is e1·du − e2·dv on the plane.
                    along = Some(e1 * g.along[0] - e2 * g.along[1]);
                    (c, side) = coords_along(along);
                    diag_grain.1 = true;
                }
                diag_grain.0 = g;
            }
            let usable = c.u.iter().zip(&full.data).any(|(u, &m)| m && u.is_finite());
            *rest_src = rest;
            *side_out = side;
            *replan = Some((n, cam, along, framing == plane::Framing::Whole));
            usable.then_some(c)
        };
        // Why auto finds no coordinates, if it finds none.
        let neither = || {
            Error::NoTexture(if el.uv.is_some() && collapsed {
                "the predicted texture coordinates have collapsed and no plane fits the picked pixels (none, or seen edge-on or from behind)".into()
            } else {
                "no texture coordinates and no plane fits the picked pixels (none, or seen edge-on or from behind)".into()
            })
        };
        let mut focal = None;
        let mut lines = None;
        let mut grain = (None, false);
        let mut plane_rest = None;
        let mut user_plane = None;
        let mut square_side = None;
        let mut replan = None;
        let (mode, coords) =
            match uv_choice {
                UvChoice::Net => match net_coords {
                    Some(c) => (UvMode::Net, c),
                    None => return Err(Error::Invalid(
                        "--uv net needs predicted texture coordinates (uv), which the inputs lack"
                            .into(),
                    )),
                },
                UvChoice::Plane => match plane_coords(&mut focal, &mut lines, &mut grain, &mut user_plane, &mut square_side, &mut plane_rest, &mut replan) {
                    Some(c) => (UvMode::Plane, c),
                    None if opts.plane.is_some() => {
                        return Err(Error::Invalid(
                            "the given plane is seen edge-on or from behind at every picked pixel (a normal must face the camera: z > 0 for a surface in front of it)".into(),
                        ))
                    }
                    None => {
                        return Err(Error::Invalid(
                            "--uv plane: no usable plane (the picked pixels have no normals, or the fitted plane is seen edge-on or from behind)".into(),
                        ))
                    }
                },
                UvChoice::Auto => {
                    // Unmeasurable (the halves share too few texels): trust the UVs,
                    // unless they have collapsed into a tiny part of the square.
                    // Inconsistent UVs are kept when no plane fits; collapsed
                    // ones are not: a rough plane through curved or noisy
                    // normals still shows most of the texture, UVs on a point
                    // or a line show almost none of it.
                    if net_ok || (!planar && !collapsed) {
                        match net_coords {
                            Some(c) => (UvMode::Net, c),
                            None => (
                                UvMode::Plane,
                                plane_coords(&mut focal, &mut lines, &mut grain, &mut user_plane, &mut square_side, &mut plane_rest, &mut replan).ok_or_else(neither)?,
                            ),
                        }
                    } else {
                        match plane_coords(&mut focal, &mut lines, &mut grain, &mut user_plane, &mut square_side, &mut plane_rest, &mut replan) {
                            Some(c) => (UvMode::Plane, c),
                            None => (
                                UvMode::Net,
                                net_coords.ok_or_else(neither)?,
                            ),
                        }
                    }
                }
            };
        // A rectified plane that repeats along both axes: every repeat
        // folded into one tile. The networks' square that repeats a whole
        // number of times along an axis: folded by its repeats, so that the
        // holes another repeat showed are filled from it before inpainting.
        // The observed density, measured once: the coordinates keep it
        // unless the plane mode folds them.
        let mut sizing_area = coords.sizing_area(&full.data);
        // The networks' UVs of the rest of the mask, upsampled within the
        // whole mask (its pixels lie outside the surest part the texture's
        // UVs were upsampled in); made when first needed.
        let rest_uv = std::cell::OnceCell::new();
        let rest_uv = || -> Option<&Coords> {
            let (rest, uv) = (rest_full.as_ref()?, el.uv.as_ref()?);
            Some(rest_uv.get_or_init(|| upsampled_uv(uv, whole_mw, fw, fh, &rest.data)))
        };
        let (coords, fold, mut uv_fold) = if opts.fold_period {
            let probe = reproject::texture_size(sizing_area, observed_cap);
            match mode {
                UvMode::Plane => {
                    // The surest part and the rest of the mask on the plane.
                    let seen: Option<Vec<bool>> = plane_rest.as_ref().map(|rest| {
                        full.data
                            .iter()
                            .zip(&rest.data)
                            .map(|(&a, &b)| a || b)
                            .collect()
                    });
                    let (c, f) = crate::period::fold_if_periodic(
                        coords,
                        &full.data,
                        seen.as_deref(),
                        &delit,
                        &confidence,
                        probe,
                    );
                    // No period in the texture's pixels: looked for again
                    // with the rest of the mask on the plane. A pattern of
                    // two colours repeats only with both, and the surest
                    // part may hold one of them, whose texels are then all
                    // alike. Only then: over the whole mask, a far, blurred
                    // part of a floor can hide the period the near part shows.
                    match (&f, &seen) {
                        (None, Some(seen)) => {
                            let (c, f) = crate::period::fold_if_periodic(
                                c,
                                seen,
                                None,
                                &delit,
                                &confidence,
                                probe,
                            );
                            (c, f, None)
                        }
                        _ => (c, f, None),
                    }
                }
                UvMode::Net => {
                    let mut r = crate::period::fold_uv_if_periodic(
                        &coords,
                        &full.data,
                        &delit,
                        &confidence,
                        probe,
                    );
                    // No repeats in the texture's pixels: looked for again
                    // with the rest of the mask, as the plane mode does.
                    if let (None, Some(rest), Some(ru)) = (&r, &rest_full, rest_uv()) {
                        let mut both = coords.clone();
                        let mut seen = full.data.clone();
                        for (i, _) in rest.data.iter().enumerate().filter(|(_, &b)| b) {
                            (both.u[i], both.v[i], seen[i]) = (ru.u[i], ru.v[i], true);
                        }
                        r = crate::period::fold_uv_if_periodic(
                            &both,
                            &seen,
                            &delit,
                            &confidence,
                            probe,
                        );
                    }
                    (coords, None, r)
                }
            }
        } else {
            (coords, None, None)
        };
        // A rectified plane that does not repeat: the square the photo
        // covers best replaces the whole one the periods were looked for in
        // (`plane::Framing`), and the texture is sized by its pixels.
        let coords = match replan {
            Some((n, f, along, true)) if mode == UvMode::Plane && fold.is_none() => {
                let (c, side) = plane::plane_coords_with_side(
                    fw,
                    fh,
                    &full.data,
                    plane_rest.as_ref().map(|m| &m.data[..]),
                    n,
                    f,
                    along,
                    plane::Framing::Covered,
                );
                if c.u.iter().zip(&full.data).any(|(u, &m)| m && u.is_finite()) {
                    square_side = side;
                    sizing_area = c.sizing_area(&full.data);
                    c
                } else {
                    coords
                }
            }
            _ => coords,
        };
        // The centring is only used when asked for.
        let fold = fold.map(|f| crate::period::Fold {
            centred: f.centred.filter(|_| opts.fold_centring),
            ..f
        });
        // The texture's size on the surface, when a quad's real size gave
        // the plane its scale: the square (or the folded tile) in metres.
        let mut size_m = match (user_plane.as_ref().and_then(|u| u.unit_m), square_side) {
            (Some(unit), Some(sq)) if mode == UvMode::Plane => {
                let side = f64::from(sq.side) * unit;
                let t = fold.map_or([1.0, 1.0], |f| f.sides());
                Some([side * f64::from(t[0]), side * f64::from(t[1])])
            }
            _ => None,
        };
        diag.uv = Some(UvDecision {
            mode,
            requested: uv_choice,
            net_r2,
            net_uv_footprint: net_footprint,
            plane_spread_deg: spread,
            focal_px: focal.map(|f| f.0),
            focal_source: focal.map(|f| f.1),
            lens: (mode == UvMode::Plane).then(|| p.lens().clone()),
            lines,
            grain: grain.0,
            grain_applied: grain.1,
            period: fold,
            repeats: None,
            plane_part_share: part.as_ref().map(|pp| pp.share),
            plane_normal: normal
                .filter(|_| mode == UvMode::Plane && opts.plane.is_none())
                .map(|n| n.to_array()),
            square: square_side.filter(|_| mode == UvMode::Plane),
            user_plane,
        });
        lap("coordinates", &mut timings);
        // A folded tile sees each texel in every repeat, so the observed-
        // pixel cap does not apply; half of --max-size does, so that a
        // 12-megapixel photo's pixels merge into blocks instead of each
        // being splatted (~2× faster reprojection there).
        let cap = if fold.is_some() {
            (opts.max_size / 2).max(16)
        } else {
            observed_cap
        };
        let mut observed = {
            let area = if fold.is_some() {
                coords.sizing_area(&full.data)
            } else {
                sizing_area
            };
            reproject::texture_size(area, cap)
        };
        // A centred repeat: each pixel's second place in the tile.
        let centring = fold.and_then(|f| f.centring_shift());
        let rest = match (mode, &rest_full) {
            (UvMode::Plane, _) if fold.is_some() => plane_rest.as_ref().map(|m| (m, None)),
            (UvMode::Net, Some(rest)) if uv_fold.is_some() => rest_uv().map(|c| (rest, Some(c))),
            _ => None,
        };
        // A rectified crop that does not repeat: its wrap edges are cut
        // through the square's surroundings (`Options::cut_seams`), which
        // are reprojected with it: a square `cut_margin` texels larger on
        // every side, whose centre is the texture's square (the same texel
        // grid). The last one made is kept for the cut.
        let around = match (replan, square_side) {
            (Some((n, f, along, _)), Some(sq))
                if mode == UvMode::Plane
                    && fold.is_none()
                    && opts.tileable
                    && opts.heal_seams
                    && opts.cut_seams =>
            {
                Some((n, f, along, sq))
            }
            _ => None,
        };
        let around_made: std::cell::RefCell<Option<(usize, reproject::Reprojected)>> =
            std::cell::RefCell::new(None);
        let reproject_around = |size: usize| -> Option<reproject::Reprojected> {
            let (n, f, along, sq) = around?;
            let m = picker_inpaint::cut_margin(size);
            let big = size + 2 * m;
            let grow = sq.side * m as f32 / size as f32;
            let c = plane::plane_coords_in(
                fw,
                fh,
                &full.data,
                n,
                f,
                along,
                [sq.origin[0] - grow, sq.origin[1] - grow],
                sq.side * big as f32 / size as f32,
            );
            Some(reproject::reproject(
                &c,
                &full.data,
                &delit,
                &confidence,
                big,
            ))
        };
        // The picked pixels reprojected into a square of `size` texels a
        // side, completed from the rest of the mask and from other repeats.
        let observe = |size: usize| -> Observed {
            if let Some(r) = reproject_around(size) {
                let m = picker_inpaint::cut_margin(size);
                let inner = r.crop(m, m, size);
                *around_made.borrow_mut() = Some((size, r));
                let fraction = inner.known_fraction();
                return Observed {
                    texture: inner.texture,
                    known: inner.known,
                    coverage: inner.coverage,
                    fraction,
                    own_fraction: fraction,
                    from_mask: None,
                    repeat_filled: None,
                };
            }
            // The pixels through `c`, and again shifted by the centring
            // when the plane's fold has one.
            let splat = |c: &Coords, shift: Option<[f32; 2]>, m: &[bool]| match shift {
                Some(by) => reproject::reproject_centred(c, m, &delit, &confidence, size, by),
                None => reproject::reproject(c, m, &delit, &confidence, size),
            };
            let mut r = splat(&coords, centring, &full.data);
            // A texture that repeats: the texels no repeat of the surest part
            // showed, from the rest of the mask where it showed them
            // (`Options::fill_from_mask`).
            let mut from_mask = None;
            if let Some((rest, rest_coords)) = rest {
                let o = match rest_coords {
                    Some(c) => splat(c, None, &rest.data),
                    None => splat(&coords, centring, &rest.data),
                };
                let n = reproject::fill_unknown_from(&mut r, &o);
                from_mask = Some(n as f64 / r.known.len().max(1) as f64);
            }
            let own_fraction = r.known_fraction();
            match uv_fold.as_ref() {
                // A square that repeats: a hole that another repeat showed is
                // filled from the tile of every repeat seen; the observed texels
                // are kept (they hold each repeat's own variation) and what no
                // repeat showed is inpainted as usual.
                Some((folded, rep)) => {
                    let c = crate::period::complete_from_repeats(
                        &r,
                        folded,
                        rep,
                        &full.data,
                        &delit,
                        &confidence,
                    );
                    let len = c.known.len().max(1) as f64;
                    Observed {
                        fraction: reproject::known_share(&c.known),
                        texture: c.texture,
                        known: c.known,
                        coverage: c.coverage,
                        own_fraction,
                        from_mask,
                        repeat_filled: Some(c.filled as f64 / len),
                    }
                }
                None => Observed {
                    texture: r.texture,
                    known: r.known,
                    coverage: r.coverage,
                    fraction: own_fraction,
                    own_fraction,
                    from_mask,
                    repeat_filled: None,
                },
            }
        };
        let mut size = opts.size.unwrap_or(observed);
        // A `--size` above the observed density: the photo's pixels may land
        // in that square as sparse dots (a 2048² square of a 60-texel
        // observation was 0.5 % observed) that no inpainter completes into the
        // texture they came from (and PatchMatch takes minutes there). When
        // the square at the requested size is markedly less covered than at
        // the observed size, the texture is made at the observed size and
        // enlarged at the end instead. (Where many repeats or a close view
        // cover the larger square, it is kept: they hold the finer detail.)
        // Coverage only falls as the square grows, so a square
        // `ENLARGE_PROBE_FACTOR` times the observed side is looked at first: a
        // far larger one (`--size 4096` of a 60-texel view) is not reprojected
        // in vain (2.2 s and 1 GB there); when that square is covered and the
        // requested one is not, the texture is made at the probe's side.
        let seen = if size > observed {
            let at_observed = observe(observed);
            let enough = |o: &Observed| o.fraction >= ENLARGE_BELOW_COVERAGE * at_observed.fraction;
            let probe = size.min(observed.saturating_mul(ENLARGE_PROBE_FACTOR));
            let sides: &[usize] = if probe < size {
                &[probe, size]
            } else {
                &[size]
            };
            let mut chosen = None;
            for &side in sides {
                let o = observe(side);
                if !enough(&o) {
                    break;
                }
                chosen = Some((side, o));
            }
            let (side, o) = chosen.unwrap_or((observed, at_observed));
            size = side;
            o
        } else {
            observe(size)
        };
        let mut out_size = opts.size.unwrap_or(size);
        diag.texture_size = Some(out_size);
        diag.texture_observed_size = Some(observed);
        diag.texture_made_size = Some(size);
        diag.filled_from_mask = seen.from_mask;
        if let (Some(f), Some((_, rep))) = (seen.repeat_filled, uv_fold.as_mut()) {
            rep.filled = f;
        }
        lap("reproject", &mut timings);
        if seen.own_fraction == 0.0 {
            return Err(Error::NoTexture(format!(
                "no picked pixel landed in the texture square ({} coordinates unusable); try --uv plane or --uv net",
                match mode {
                    UvMode::Net => "the predicted texture",
                    UvMode::Plane => "the plane's",
                }
            )));
        }
        // What the report and coverage.png show as observed: the
        // reprojection, with the texels filled from other repeats (at the
        // tile's coverage there) when the square repeats; for a crop whose
        // wrap edges were cut through its surroundings, the cut square.
        let Observed {
            texture: raw,
            known,
            coverage,
            fraction: known_fraction,
            ..
        } = seen;
        // (Made again when a larger size was looked at last.)
        let made = match around_made.into_inner() {
            Some((side, r)) if side == size => Some(r),
            _ => reproject_around(size),
        };
        // (With the cut, the observed ratio that called for healing: the
        // band then goes across the edges not cut, whatever they show.)
        let mut decided: Option<f64> = None;
        let (raw, known, coverage, band_axes, known_fraction) = match made {
            Some(r) => {
                // When the square's observed edges do not join (as the seam
                // band decides, over both wrap edges: ratio above the bound,
                // or nothing to measure), its edges are cut through its
                // surroundings; else it is left as it is. (Decided per axis,
                // an axis whose own ratio was just under the bound kept a
                // visible seam: a photo of fur.)
                let ratio = picker_inpaint::known_seam_ratio(&raw, &known);
                let seams_show = ratio.is_none_or(|r| r > picker_inpaint::SEAM_BAND_MIN_RATIO);
                decided = ratio.filter(|_| seams_show);
                let need = [seams_show; 2];
                let c = cut_crop(&r, size, need, opts.size.is_none());
                let side = c.texture.width;
                let within = (side != size).then_some(size);
                if side != size {
                    let k = side as f64 / size as f64;
                    size_m = size_m.map(|[a, b]| [a * k, b * k]);
                    (size, out_size, observed) = (side, side, side);
                    diag.texture_size = Some(side);
                    diag.texture_observed_size = Some(side);
                    diag.texture_made_size = Some(side);
                }
                diag.seam_cut = Some(SeamCut {
                    within,
                    ..SeamCut::from_cut(&c)
                });
                // The band: across the edges that needed healing and were
                // not cut.
                let axes = [need[0] && c.columns.is_none(), need[1] && c.rows.is_none()];
                let fraction = reproject::known_share(&c.known);
                (c.texture, c.known, c.coverage, axes, fraction)
            }
            None => (raw, known, coverage, [true, true], known_fraction),
        };
        let inpaint = |t: &Image,
                       known: &[bool],
                       band: &mut Option<f64>|
         -> picker_inpaint::Result<(Image, f64)> {
            let share = reproject::known_share;
            // A band across the wrap edges where the observed sides differ:
            // only for a rectified plane, whose square is a crop of the
            // photo's region (folded, its tile's sides meet only as well as
            // the measured period is right). Wrapped UVs meet themselves at
            // the edges by construction (a texture whose period ends on a
            // strong edge, a brick's mortar, has a high seam ratio of its
            // own: banding them cost 0.5–0.7 dB with ground-truth UVs).
            // (Only across the edges not cut through the surroundings.)
            let heal = opts.tileable
                && opts.heal_seams
                && mode == UvMode::Plane
                && band_axes.iter().any(|&a| a);
            let healed = heal
                .then(|| match decided {
                    Some(r) => {
                        picker_inpaint::clear_seam_band_axes(known, t.width, t.height, band_axes)
                            .map(|k| (k, r))
                    }
                    None => picker_inpaint::seam_band_axes(t, known, band_axes),
                })
                .flatten();
            let healed = healed.map(|(k, ratio)| {
                *band = Some(ratio);
                k
            });
            let io = InpaintOptions {
                toroidal: opts.tileable,
                seed: opts.seed,
                ..InpaintOptions::default()
            };
            let used = healed.as_deref().unwrap_or(known);
            let out = opts.inpainter.inpaint(t, used, &io)?;
            if !heal || healed.is_some() {
                return Ok((out, share(used)));
            }
            // The observed texels could not tell (an edge whose other side
            // was not observed) and the inpainted square still shows its
            // seams: inpainted again with the band cleared, kept when it
            // tiles better.
            let all = vec![true; out.plane_len()];
            let ratio = |img: &Image| {
                picker_inpaint::known_seam_ratio_axes(img, &all, band_axes).unwrap_or(1.0)
            };
            let first = ratio(&out);
            if first <= picker_inpaint::SEAM_BAND_MIN_RATIO {
                return Ok((out, share(known)));
            }
            let Some(k) = picker_inpaint::clear_seam_band_axes(known, t.width, t.height, band_axes)
            else {
                return Ok((out, share(known)));
            };
            let again = opts.inpainter.inpaint(t, &k, &io)?;
            if ratio(&again) < first {
                *band = Some(first);
                Ok((again, share(&k)))
            } else {
                Ok((out, share(known)))
            }
        };
        // A folded tile repeats: any cyclic shift of it is the same texture.
        // Its wrap edges are put where the observed texels change least, so
        // that a pattern's edge (a chessboard's square) does not lie on them,
        // where the seam band would inpaint over it.
        let (raw, known, coverage) = match fold.as_ref() {
            Some(_) if opts.tileable && opts.wrap_placement => {
                let at = smoothest_wrap(&raw, &known);
                (
                    roll(&raw, at),
                    roll_mask(&known, raw.width, raw.height, at),
                    roll(&coverage, at),
                )
            }
            _ => (raw, known, coverage),
        };
        let (final_tex, kept) = inpaint(&raw, &known, &mut diag.seam_band)?;
        diag.observed_kept = Some(kept);
        // The texture's level against the material's (`Options::level`):
        // the de-lit colours of the material's pixels at the working
        // resolution, averaged over about a quarter of the texture square's
        // side in the photo (the whole mask: where the texture comes from a
        // part of it, that part is what may be untypical).
        diag.level = opts
            .level
            .then(|| {
                let n = w * h;
                let mut values = Image::zeros(3, h, w);
                for &i in idx.iter().filter(|&&i| rw[i] > 0.0) {
                    let v = p.photo_work.rgb(i) * ratio.rgb(i);
                    for (c, x) in v.to_array().into_iter().enumerate() {
                        values.data[c * n + i] = x;
                    }
                }
                let in_square = coords
                    .u
                    .par_iter()
                    .zip(&full.data)
                    .filter(|(u, &m)| m && u.is_finite())
                    .count();
                let scale = (w * h) as f64 / (fw * fh).max(1) as f64;
                let sigma = crate::level::level_sigma(in_square as f64 * scale);
                crate::level::check(&final_tex, &values, &rw, sigma)
            })
            .flatten();
        let final_tex = match diag.level {
            Some(l) => crate::level::apply_gain(final_tex, l.gain),
            None => final_tex,
        };
        if let Some(d) = diag.uv.as_mut() {
            d.repeats = uv_fold.as_ref().map(|f| f.1);
        }
        // On request, broad light and dark patches evened out (before the
        // seam correction, which then sees the evened texture).
        // A texture that does not tile is mirrored at its edges, not wrapped.
        let edges = if opts.tileable {
            crate::equalize::Edges::Wrap
        } else {
            crate::equalize::Edges::Mirror
        };
        let final_tex = match opts
            .even_out
            .and_then(|s| crate::equalize::even_out(&final_tex, s, edges))
        {
            Some((t, info)) => {
                diag.even_out_gain = Some(info.gain_range);
                t
            }
            None => final_tex,
        };
        // The observed texels at opposite edges need not match (imperfect
        // de-lighting, a rectified region that is not one period): on
        // request, remove the colour jumps across the wrap edges when they
        // show. Colours stay non-negative.
        let (final_tex, seam_corrected) = if opts.tileable && opts.seamless {
            let (mut t, corrected) = make_seamless(final_tex);
            if corrected {
                t.data.iter_mut().for_each(|v| *v = v.max(0.0));
            }
            (t, corrected)
        } else {
            (final_tex, false)
        };
        // Enlarged to a `--size` above the observed one: the texture smoothly
        // (bicubic, wrapped when it tiles, else mirrored; negative overshoot
        // clipped), the coverage as blocks (coverage.png lines up with the
        // texture); the reprojection stays what was reprojected.
        let (final_tex, raw, coverage) = if out_size > size {
            let mut t = crate::resample::bicubic(&final_tex, out_size, out_size, edges);
            t.data.iter_mut().for_each(|v| *v = v.max(0.0));
            (t, raw, crate::resample::area(&coverage, out_size, out_size))
        } else {
            (final_tex, raw, coverage)
        };
        lap("inpaint", &mut timings);
        // The final texture's mean, as the level check measures it.
        diffuse_mean = Vec3::from_array(crate::level::mean_colour(&final_tex));
        if mode == UvMode::Net {
            uv_work = el.uv.as_ref();
        }
        texture = Some(TextureResult {
            seam: seam_score(&final_tex),
            seam_corrected,
            texture: final_tex,
            raw,
            coverage,
            coverage_fraction: known_fraction,
            observed_size: observed,
            size_m,
            uv_mode: mode,
            inpainter: opts.inpainter.name().to_string(),
        });
    } else {
        let fi: Vec<usize> = (0..fw * fh)
            .filter(|&i| full.data[i] && confidence[i] > 0.0)
            .collect();
        diffuse_mean = Vec3::from_array(std::array::from_fn(|c| {
            median(fi.iter().map(|&i| delit.at(c, i)).collect())
        }));
    }
    let params = MaterialParams {
        diffuse: diffuse_mean.to_array(),
        specular: [spec[0], spec[1], spec[2]],
        glossiness: gloss,
        exponent: conv::phong_exponent(gloss),
    };

    // Re-render self-check at the working resolution.
    let rerender_psnr = p.shader().and_then(|shader| {
        let mut render = Image::zeros(3, h, w);
        // Every pixel on its own (in parallel, the same values as in turn).
        let shaded: Vec<Vec3> = idx
            .par_iter()
            .map(|&i| {
                let mut phong = params.phong();
                if let (Some(uv), Some(t)) = (uv_work, texture.as_ref()) {
                    phong.diffuse = sample_wrapped(&t.texture, uv.at(0, i), uv.at(1, i));
                }
                shader.shade(el.normals.rgb(i), el.view.rgb(i), &phong)
            })
            .collect();
        for (&i, &c) in idx.iter().zip(&shaded) {
            render.set_rgb(i, c);
        }
        picker_render::compare(&render, &p.photo_work, Some(mw))
            .ok()
            .map(|s| s.psnr_srgb)
    });
    lap("rerender", &mut timings);
    diag.timings_ms = timings;
    let area_fraction = full.fraction();
    Ok((
        Material {
            name: name.to_string(),
            pick,
            params,
            textured: texture.is_some(),
            texture,
            mask: full.to_image(),
            area_fraction,
            rerender_psnr,
        },
        diag,
    ))
}

/// Most times the texture wraps around the preview sphere
/// ([`preview_repeats`]): a tiny texture (a 16-texel tile) is shown larger
/// than its texels rather than as a fine noise.
pub const PREVIEW_MAX_REPEATS: usize = 8;

/// How many times a `side`-texel texture wraps around a preview sphere
/// `size` pixels wide ([`preview_sphere`]) so that at the sphere's centre one
/// texel spans about one preview pixel: `π·size/side` (a longitude radian is
/// `size/2` pixels there and holds `repeats·side/2π` texels), rounded, in
/// `[1, PREVIEW_MAX_REPEATS]`. The automatic texture side follows the
/// photo's pixel density ([`reproject::texture_size`]), so the preview shows
/// the material at about the scale it had in the photo: a large texture
/// once, a folded one-period tile (a chessboard's two squares) as many
/// periods, not as two huge checks. `side` 0 (no texture) gives 1.
pub fn preview_repeats(side: usize, size: usize) -> f32 {
    if side == 0 {
        return 1.0;
    }
    let r = (std::f64::consts::PI * size as f64 / side as f64).round();
    r.clamp(1.0, PREVIEW_MAX_REPEATS as f64) as f32
}

/// The repeats of [`preview_repeats`] for material `m`'s texture (1 for a
/// single-colour material), by the side the texture had at the photo's
/// density ([`TextureResult::observed_size`]): a `--size` does not change the
/// scale the preview shows the material at.
pub fn material_preview_repeats(m: &Material, size: usize) -> f32 {
    m.texture
        .as_ref()
        .map_or(1.0, |t| preview_repeats(t.observed_size, size))
}

/// A textured preview sphere (orthographic, `size × size`, linear RGB; the
/// texture wraps `repeats` times around the equator with the sphere's
/// longitude/latitude mapping), shaded by eq. 3.7 with the fast path.
pub fn preview_sphere(m: &Material, env: &EnvMap, size: usize, repeats: f32) -> Image {
    preview_sphere_with(m, &Shader::resolving(env), size, repeats)
}

/// [`preview_sphere`] with a prepared shader (one per lighting: several
/// materials' previews and `picker_render::preview_exposure` share it).
pub fn preview_sphere_with(m: &Material, shader: &Shader, size: usize, repeats: f32) -> Image {
    let mut out = Image::zeros(3, size, size);
    // Rows in parallel: every pixel is shaded alone (the same bits whatever
    // the threads; `tests::parallel_preview_matches_reference`).
    let n = size * size;
    let (r, rest) = out.data.split_at_mut(n);
    let (g, b) = rest.split_at_mut(n);
    let step = size.max(1);
    r.par_chunks_mut(step)
        .zip(g.par_chunks_mut(step))
        .zip(b.par_chunks_mut(step))
        .enumerate()
        .for_each(|(row, ((r, g), b))| {
            let mut phong = m.params.phong();
            for col in 0..size {
                if let Some(c) = preview_pixel(m, shader, &mut phong, size, repeats, row, col) {
                    (r[col], g[col], b[col]) = (c.x, c.y, c.z);
                }
            }
        });
    out
}

/// One pixel of [`preview_sphere`] (`None` off the sphere).
fn preview_pixel(
    m: &Material,
    shader: &Shader,
    phong: &mut picker_render::PhongMaterial,
    size: usize,
    repeats: f32,
    row: usize,
    col: usize,
) -> Option<Vec3> {
    let n = picker_render::sphere_normal(size, row, col)?;
    if let Some(t) = &m.texture {
        let u = (n.x.atan2(n.z) / std::f32::consts::TAU + 0.5) * repeats;
        let v = n.y.clamp(-1.0, 1.0).acos() / std::f32::consts::PI * repeats / 2.0;
        phong.diffuse = sample_wrapped(&t.texture, u.rem_euclid(1.0), v.rem_euclid(1.0));
    }
    Some(shader.shade(n, Vec3::Z, phong))
}

/// The cap of the automatic texture side for `observed` picked photo pixels:
/// never more than ~4 texels per observed pixel (beyond that the texture is
/// mostly invented), nor `max_size`, nor under 16.
fn observed_cap(max_size: usize, observed: usize) -> usize {
    max_size
        .min((2.0 * (observed as f64).sqrt()) as usize)
        .max(16)
}

/// The masked pixel nearest to the mask's median row and column (`mask` on
/// a grid `w` wide, not empty): where a material without a pick is anchored.
fn central_pixel(mask: &[bool], w: usize) -> (usize, usize) {
    let mut xs: Vec<usize> = Vec::new();
    let mut ys: Vec<usize> = Vec::new();
    for (i, _) in mask.iter().enumerate().filter(|(_, &m)| m) {
        xs.push(i % w);
        ys.push(i / w);
    }
    if xs.is_empty() {
        return (0, 0);
    }
    let (mx, my) = (xs.len() / 2, ys.len() / 2);
    let cx = *xs.select_nth_unstable(mx).1;
    let cy = *ys.select_nth_unstable(my).1;
    mask.iter()
        .enumerate()
        .filter(|(_, &m)| m)
        .map(|(i, _)| (i % w, i / w))
        .min_by_key(|&(x, y)| (x.abs_diff(cx).pow(2) + y.abs_diff(cy).pow(2), y, x))
        .unwrap_or((cx, cy))
}

/// The cell of a `to`-cell grid under the centre of cell `i` of a `from`-cell
/// grid spanning the same extent (photo pixel → working pixel and back).
fn cell_under(i: usize, from: usize, to: usize) -> usize {
    (((i as f64 + 0.5) * to as f64 / from as f64) as usize).min(to.saturating_sub(1))
}

/// The photo-resolution mask `full` limited to the photo pixels whose
/// working-resolution pixel (`w × h` grid, the one under the pixel's centre)
/// is in `part`.
/// The networks' UVs `uv` (working resolution) upsampled to `fw × fh`
/// within the working mask `within` ([`resample::upsample_uv_where`]), as
/// wrapping coordinates at the pixels `keep` (NaN elsewhere).
fn upsampled_uv(uv: &Image, within: &[bool], fw: usize, fh: usize, keep: &[bool]) -> Coords {
    let weight: Vec<f32> = within.iter().map(|&b| b as u8 as f32).collect();
    let up = resample::upsample_uv_where(uv, &weight, fw, fh, keep);
    Coords {
        width: fw,
        height: fh,
        u: up.plane(0).to_vec(),
        v: up.plane(1).to_vec(),
        wrap: true,
    }
}

fn restrict_to_work(full: &Mask, part: &[bool], w: usize, h: usize) -> Mask {
    let (fw, fh) = (full.width, full.height);
    let col: Vec<usize> = (0..fw).map(|x| cell_under(x, fw, w)).collect();
    let mut data = full.data.clone();
    data.par_chunks_mut(fw.max(1))
        .enumerate()
        .for_each(|(y, row)| {
            let wy = cell_under(y, fh, h);
            for (x, v) in row.iter_mut().enumerate() {
                *v = *v && part[wy * w + col[x]];
            }
        });
    Mask {
        width: fw,
        height: fh,
        data,
    }
}

/// The plain, sequential [`preview_sphere`].
#[cfg(test)]
fn preview_sphere_reference(m: &Material, env: &EnvMap, size: usize, repeats: f32) -> Image {
    let shader = Shader::resolving(env);
    let mut out = Image::zeros(3, size, size);
    let mut phong = m.params.phong();
    for row in 0..size {
        for col in 0..size {
            let x = (col as f32 + 0.5) / size as f32 * 2.0 - 1.0;
            let y = 1.0 - (row as f32 + 0.5) / size as f32 * 2.0;
            let r2 = x * x + y * y;
            if r2 >= 1.0 {
                continue;
            }
            let n = Vec3::new(x, y, (1.0 - r2).sqrt());
            if let Some(t) = &m.texture {
                let u = (n.x.atan2(n.z) / std::f32::consts::TAU + 0.5) * repeats;
                let v = n.y.clamp(-1.0, 1.0).acos() / std::f32::consts::PI * repeats / 2.0;
                phong.diffuse = sample_wrapped(&t.texture, u.rem_euclid(1.0), v.rem_euclid(1.0));
            }
            out.set_rgb(row * size + col, shader.shade(n, Vec3::Z, &phong));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The options the tests start from: `uv`, automatic size capped at 256,
    /// no `--fov`, no line refinement, fold and fill and seam band on,
    /// tileable, seed 1, with `inpainter`.
    fn test_options(inpainter: &dyn Inpainter, uv: UvChoice) -> Options<'_> {
        Options {
            mask: MaskOptions::default(),
            uv,
            size: None,
            max_size: 256,
            fov_deg: None,
            plane: None,
            quad_size_m: None,
            line_refine: false,
            align_grain: false,
            fold_period: true,
            fold_centring: true,
            fill_from_mask: true,
            tileable: true,
            heal_seams: true,
            cut_seams: true,
            shading_sigma: crate::shading::SHADING_SIGMA,
            wrap_placement: true,
            seamless: false,
            even_out: None,
            level: true,
            seed: 1,
            inpainter,
        }
    }

    #[test]
    fn requests_extract_cannot_honour_are_refused() {
        let p = twins(false, false);
        let inpainter = picker_inpaint::DiffusionInpainter::default();
        let pm = p.pick_mask([4, 4], &MaskOptions::default()).unwrap();
        for (size, max) in [
            (Some(1usize << 40), 256),
            (Some(0), 256),
            (None, 0),
            (None, 9000),
        ] {
            let opts = Options {
                size,
                max_size: max,
                ..test_options(&inpainter, UvChoice::Auto)
            };
            let e = extract(&p, "m", Some([4, 4]), &pm, &opts).unwrap_err();
            assert!(e.to_string().contains("texture"), "{e}");
        }
        let opts = test_options(&inpainter, UvChoice::Auto);
        let mut small = pm.clone();
        small.mask = Mask {
            width: 2,
            height: 2,
            data: vec![true; 4],
        };
        let e = extract(&p, "m", Some([1, 1]), &small, &opts).unwrap_err();
        assert!(e.to_string().contains("working resolution"), "{e}");
        let mut short = pm.clone();
        short.sure.pop();
        assert!(extract(&p, "m", Some([4, 4]), &short, &opts).is_err());
        assert!(extract(&p, "m", Some([4, 4]), &pm, &opts).is_ok());
    }

    #[test]
    fn helpers_at_the_edges_of_their_inputs() {
        // A zero axis has no shifts: no answer, and no endless search.
        let tex = Image::new(3, 8, 8, vec![0.5; 192]).unwrap();
        let p = crate::period::AxisPeriod {
            texels: 4.0,
            strength: 0.9,
            double: None,
        };
        assert_eq!(
            crate::period::snap_repeats(&tex, &[true; 64], (0, 0), p, 8),
            None
        );
        assert_eq!(crate::reproject::texture_size(Some(1e-45), 64), 64);
        assert_eq!(crate::photo::working_size(0, 0, 512), (0, 0));
        assert_eq!(crate::photo::working_size(0, 7, 512), (0, 0));
        assert_eq!(
            crate::guided::luma(&Image::new(0, 2, 2, vec![]).unwrap()),
            vec![0.0; 4]
        );
        let t = Image::new(3, 1, 2, vec![0.0, 1.0, 0.0, 1.0, 0.0, 1.0]).unwrap();
        assert!(sample_wrapped(&t, f32::NAN, 0.5).is_finite());
        assert!(sample_wrapped(&t, 1e30, -3.25).is_finite());
        assert_eq!(crate::mask::neighbours4(0, 0, 0).count(), 0);
        assert_eq!(crate::mask::neighbours4(9, 3, 3).count(), 0);
        assert_eq!(crate::mask::neighbours4(4, 3, 3).count(), 4);
        assert_eq!(crate::mask::nearest_label(&[1], 0, (0, 0)), 0);
        let seg2 = Image::new(2, 2, 2, vec![0.5; 8]).unwrap();
        assert_eq!(crate::mask::pick_colour(&seg2, &[true; 4], 0, 0), None);
        let seg3 = Image::new(3, 2, 2, vec![0.5; 12]).unwrap();
        assert_eq!(crate::mask::pick_colour(&seg3, &[true; 4], 3, 3), None);
        assert!(crate::mask::pick_colour(&seg3, &[true; 4], 1, 1).is_some());
        let plane: Vec<f32> = (0..12).map(|i| i as f32).collect();
        assert_eq!(
            crate::guided::box_mean(&plane, 4, 3, usize::MAX),
            crate::guided::box_mean(&plane, 4, 3, 4)
        );
        let seg = Image::new(3, 2, 2, vec![0.5; 12]).unwrap();
        let opts = MaskOptions::default();
        assert!(crate::mask::pick_mask(&seg, &[true; 3], 1, 1, &opts).is_err());
        for t in [f32::NAN, -0.1, 0.0] {
            let o = MaskOptions {
                tolerance: Some(t),
                ..MaskOptions::default()
            };
            assert!(
                crate::mask::pick_mask(&seg, &[true; 4], 1, 1, &o).is_err(),
                "{t}"
            );
        }
        let empty = Image::new(3, 0, 0, vec![]).unwrap();
        let r = std::panic::catch_unwind(|| crate::resample::bilinear(&empty, 4, 4));
        let msg = r.unwrap_err();
        let msg = msg.downcast_ref::<&str>().copied().unwrap_or_default();
        assert!(msg.contains("no pixels"), "{msg}");
    }

    #[test]
    fn cell_under_maps_centres_both_ways() {
        for (small, big) in [
            (1, 1),
            (1, 7),
            (3, 3),
            (80, 320),
            (60, 4000),
            (7, 9),
            (240, 241),
        ] {
            for i in 0..big {
                let c = cell_under(i, big, small);
                assert!(c < small);
                // The cell holds the centre of big cell i.
                let centre = (i as f64 + 0.5) / big as f64;
                assert!(
                    c as f64 / small as f64 <= centre && centre < (c + 1) as f64 / small as f64
                );
            }
            for j in 0..small {
                // A small cell's centre lies in the big cell it maps to, which maps back.
                let b = cell_under(j, small, big);
                assert!(b < big);
                assert_eq!(cell_under(b, big, small), j, "{small} {big} {j}");
            }
            // Monotone.
            assert!((1..big).all(|i| cell_under(i - 1, big, small) <= cell_under(i, big, small)));
        }
    }

    /// A material of one colour (no texture) for the preview tests.
    fn plain_material(diffuse: [f32; 3], specular: f32) -> Material {
        Material {
            name: "m".into(),
            pick: None,
            params: MaterialParams {
                diffuse,
                specular: [specular; 3],
                glossiness: 0.5,
                exponent: conv::phong_exponent(0.5),
            },
            textured: false,
            texture: None,
            mask: Image::zeros(1, 1, 1),
            area_fraction: 1.0,
            rerender_psnr: None,
        }
    }

    /// `m` with the texture `tex` (fully observed, plane mode, as if inpainted by "test").
    fn with_texture(mut m: Material, tex: &Image) -> Material {
        m.textured = true;
        m.texture = Some(crate::TextureResult {
            seam: seam_score(tex),
            seam_corrected: false,
            texture: tex.clone(),
            raw: tex.clone(),
            coverage: Image::zeros(1, tex.height, tex.width),
            coverage_fraction: 1.0,
            observed_size: tex.width.max(tex.height),
            size_m: None,
            uv_mode: UvMode::Plane,
            inpainter: "test".into(),
        });
        m
    }

    /// The exposure of the previews under `env` (the fast shader they use).
    fn preview_exposure(env: &EnvMap) -> f32 {
        picker_render::preview_exposure(&Shader::new(env, picker_render::Quality::Fast))
    }

    #[test]
    fn preview_exposure_shows_albedo_under_uniform_light() {
        // Under a uniform environment of radiance L a Lambertian sphere of
        // albedo ρ has radiance ρL everywhere: the exposure is WHITE / L and
        // the exposed preview shows ρ·WHITE whatever L is.
        for l in [0.01f32, 1.0, 37.0] {
            let env = EnvMap::uniform(64, 32, Vec3::splat(l));
            let e = preview_exposure(&env);
            assert!(
                (e * l / picker_render::PREVIEW_WHITE - 1.0).abs() < 2e-2,
                "L {l}: exposure {e}"
            );
            for rho in [0.05f32, 0.5, 0.9] {
                let img = preview_sphere(&plain_material([rho; 3], 0.0), &env, 33, 2.0);
                let shown = conv::expose_rgb(&img.data, e);
                let centre = 16 * 33 + 16;
                let want = conv::srgb_encode(conv::soft_clip(rho * picker_render::PREVIEW_WHITE));
                assert!(
                    (shown[centre] - want).abs() < 1e-2,
                    "L {l} rho {rho}: {} vs {want}",
                    shown[centre]
                );
                // Off the sphere: black.
                assert_eq!(shown[0], 0.0);
            }
        }
    }

    #[test]
    fn preview_exposure_follows_the_lighting_not_the_material() {
        let mut rng = picker_tensor::Rng::new(12);
        let img = Image::new(3, 8, 16, rng.uniform_vec(3 * 8 * 16, 0.0, 3.0)).unwrap();
        let env = EnvMap::from_image(&img).unwrap();
        let brighter = EnvMap::from_image(
            &Image::new(3, 8, 16, img.data.iter().map(|v| v * 20.0).collect()).unwrap(),
        )
        .unwrap();
        let (e, e20) = (preview_exposure(&env), preview_exposure(&brighter));
        assert!(e.is_finite() && e > 0.0);
        assert!((e / e20 / 20.0 - 1.0).abs() < 1e-4, "{e} {e20}");
        // The same material shows the same under both (scale invariance), and a
        // darker material darker.
        let m = plain_material([0.6, 0.4, 0.2], 0.04);
        let a = conv::expose_rgb(&preview_sphere(&m, &env, 24, 2.0).data, e);
        let b = conv::expose_rgb(&preview_sphere(&m, &brighter, 24, 2.0).data, e20);
        assert!(a.iter().zip(&b).all(|(x, y)| (x - y).abs() < 1e-3));
        let dark = conv::expose_rgb(
            &preview_sphere(&plain_material([0.06, 0.04, 0.02], 0.04), &env, 24, 2.0).data,
            e,
        );
        let mean = |v: &[f32]| v.iter().sum::<f32>() / v.len() as f32;
        assert!(mean(&dark) < 0.5 * mean(&a), "{} {}", mean(&dark), mean(&a));
        // A black environment: exposure 1, not a division by zero.
        assert_eq!(preview_exposure(&EnvMap::uniform(8, 4, Vec3::ZERO)), 1.0);
    }

    #[test]
    fn preview_repeats_give_about_a_texel_per_pixel() {
        // π·size/side, whole, within [1, PREVIEW_MAX_REPEATS].
        assert_eq!(preview_repeats(256, 256), 3.0);
        assert_eq!(preview_repeats(128, 256), 6.0);
        assert_eq!(preview_repeats(100, 256), 8.0);
        assert_eq!(preview_repeats(16, 256), PREVIEW_MAX_REPEATS as f32);
        assert_eq!(preview_repeats(1024, 256), 1.0);
        assert_eq!(preview_repeats(4096, 1), 1.0);
        assert_eq!(preview_repeats(0, 256), 1.0);
        assert_eq!(preview_repeats(usize::MAX, usize::MAX), 3.0);
        // On the sphere: a texture black on its left half and white on its
        // right shows, along the centre row, one edge per half period of
        // u·r within the row's longitudes (counted inside 0.9 of the radius,
        // away from the limb, where a longitude φ has x = R·sin φ and
        // u = φ/2π + ½).
        let env = EnvMap::uniform(16, 8, Vec3::ONE);
        let side = 64;
        let tex = Image::new(
            3,
            side,
            side,
            (0..3 * side * side)
                .map(|i| if i % side < side / 2 { 0.0 } else { 1.0 })
                .collect(),
        )
        .unwrap();
        let m = with_texture(plain_material([0.5; 3], 0.0), &tex);
        assert_eq!(material_preview_repeats(&m, 256), 8.0);
        // A texture made larger than the photo showed it (`--size`) wraps
        // as often as at the photo's density.
        let mut big = with_texture(plain_material([0.5; 3], 0.0), &Image::zeros(3, 512, 512));
        big.texture.as_mut().unwrap().observed_size = 100;
        assert_eq!(material_preview_repeats(&big, 256), 8.0);
        assert_eq!(preview_repeats(512, 256), 2.0);
        assert_eq!(
            material_preview_repeats(&plain_material([0.5; 3], 0.0), 256),
            1.0
        );
        let size = 401;
        let reach = 0.9f64;
        let span = reach.asin() / std::f64::consts::TAU;
        for r in 1..=PREVIEW_MAX_REPEATS {
            let img = preview_sphere(&m, &env, size, r as f32);
            let row = size / 2;
            let half = size as f64 / 2.0;
            let bright: Vec<bool> = (0..size)
                .filter(|&c| ((c as f64 + 0.5 - half) / half).abs() < reach)
                .map(|c| img.data[row * size + c] > 0.2)
                .collect();
            let edges = bright.windows(2).filter(|p| p[0] != p[1]).count();
            let rf = r as f64;
            let (lo, hi) = (rf * (0.5 - span), rf * (0.5 + span));
            let want = (1..4 * r)
                .filter(|&k| (k as f64 / 2.0) > lo && (k as f64 / 2.0) < hi)
                .count();
            assert_eq!(edges, want, "repeats {r}");
        }
    }

    /// A constant 24×32 image of `c` channels with the values `v`.
    fn flat(c: usize, v: &[f32]) -> Image {
        let (h, w) = (24, 32);
        Image::new(c, h, w, (0..c).flat_map(|k| vec![v[k]; h * w]).collect()).unwrap()
    }

    /// Constant 24×32 render elements of one material (albedo (0.5, 0.4, 0.3),
    /// specular 0.04, glossiness 0.5, the view vector +z) with `normal` and `uv`.
    fn flat_elements(normal: [f32; 3], uv: Option<[f32; 3]>) -> ElementImages {
        ElementImages::new(
            flat(3, &[0.5, 0.4, 0.3]),
            flat(3, &[0.04; 3]),
            flat(1, &[0.5]),
            flat(3, &normal),
            flat(3, &[0.0, 0.0, 1.0]),
            uv.map(|uv| flat(3, &uv)),
        )
        .unwrap()
    }

    /// A 24×32 material with a textured flag but UVs that are all NaN and
    /// normals facing away from the camera (no plane can be rectified).
    fn unreprojectable() -> Prepared {
        let (h, w) = (24, 32);
        let mut rng = picker_tensor::Rng::new(21);
        let photo = Image::new(3, h, w, rng.uniform_vec(3 * h * w, 0.3, 0.7)).unwrap();
        let elements = flat_elements([0.0, 0.0, -1.0], Some([f32::NAN, f32::NAN, 1.0]));
        Prepared::new(Inputs {
            photo,
            elements,
            segmentation: flat(3, &[0.2, 0.5, 0.7]),
            embedding: None,
            segmentation_estimated: false,
            albedo_estimated: false,
            envmap: None,
            opaque: None,
            disagreement: None,
        })
        .unwrap()
    }

    /// Two materials side by side (left and right halves of a 24×32 image)
    /// with the same segmentation colour, a photo that looks alike on both
    /// and, when `embedded`, a material embedding that tells them apart.
    fn twins(embedded: bool, estimated: bool) -> Prepared {
        let (h, w) = (24, 32);
        let mut rng = picker_tensor::Rng::new(5);
        let photo = Image::new(3, h, w, rng.uniform_vec(3 * h * w, 0.45, 0.55)).unwrap();
        let elements = flat_elements([0.0, 0.0, 1.0], None);
        let noise = rng.uniform_vec(3 * h * w, -0.05, 0.05);
        let embedding = (0..3 * h * w)
            .map(|i| {
                let (c, x) = (i / (h * w), i % w);
                let centre = match (c, x < w / 2) {
                    (0, true) => -0.4,
                    (0, false) => 0.4,
                    _ => 0.1,
                };
                centre + noise[i]
            })
            .collect();
        Prepared::new(Inputs {
            photo,
            elements,
            segmentation: flat(3, &[0.3, 0.3, 0.3]),
            embedding: embedded.then(|| Image::new(3, h, w, embedding).unwrap()),
            segmentation_estimated: estimated,
            albedo_estimated: false,
            envmap: None,
            opaque: None,
            disagreement: None,
        })
        .unwrap()
    }

    /// A palette of two materials on 24×32 pixels: the left 22 columns one
    /// segmentation colour, the right 10 a second material whose colour
    /// ramps over two quantisation bins (its shading), each under the
    /// smallest area asked for but the material over it. Both are found,
    /// the ramp as one material; asked for more than the ramp covers, only
    /// the first.
    #[test]
    fn a_palette_finds_a_material_whose_colours_span_several_bins() {
        let (h, w) = (24, 32);
        let seg = Image::new(
            3,
            h,
            w,
            (0..3 * h * w)
                .map(|k| {
                    let (c, x) = (k / (h * w), k % w);
                    match (c, x < 22) {
                        (_, true) => 0.2,
                        (0, false) => 0.52 + 0.09 * (x - 22) as f32 / 9.0,
                        _ => 0.7,
                    }
                })
                .collect(),
        )
        .unwrap();
        let p = Prepared::new(Inputs {
            photo: flat(3, &[0.5, 0.5, 0.5]),
            elements: flat_elements([0.0, 0.0, 1.0], None),
            segmentation: seg,
            embedding: None,
            segmentation_estimated: false,
            albedo_estimated: false,
            envmap: None,
            opaque: None,
            disagreement: None,
        })
        .unwrap();
        // Bins 8 and 9 of channel 0 hold 4 and 6 columns: 12.5 % and 19 %.
        let pal = p.palette(0.25, 8, true, true);
        assert_eq!(
            pal.len(),
            2,
            "{:?}",
            pal.iter().map(|m| m.0).collect::<Vec<_>>()
        );
        let right = &pal[1].1.mask;
        for y in 0..h {
            for x in 0..w {
                assert_eq!(right.data[y * w + x], x >= 22, "({x}, {y})");
            }
        }
        assert_eq!(p.palette(0.4, 8, true, true).len(), 1);
    }

    #[test]
    fn masks_follow_the_material_embedding_when_there_is_one() {
        for estimated in [false, true] {
            // Without an embedding the two materials' equal colours are one mask.
            let p = twins(false, estimated);
            let pm = p.pick_mask([5, 12], &MaskOptions::default()).unwrap();
            assert_eq!(pm.mask.count(), 24 * 32, "estimated {estimated}");
            // With one, the pick's half only, on either side.
            let p = twins(true, estimated);
            for (pick, left) in [([5, 12], true), ([27, 3], false)] {
                let pm = p.pick_mask(pick, &MaskOptions::default()).unwrap();
                // A smoothed estimate mixes the two across their border where the
                // photo does not tell them apart: a band of 3 pixels either side
                // may go either way there.
                let band = if estimated { 3 } else { 0 };
                for y in 0..24 {
                    for x in (0..32).filter(|&x| (x as i32 * 2 - 31).abs() > 2 * band) {
                        assert_eq!(
                            pm.mask.data[y * 32 + x],
                            (x < 16) == left,
                            "estimated {estimated}, pick {pick:?}: pixel ({x}, {y})"
                        );
                    }
                }
                // The reported colour is the segmentation's, not the embedding's.
                let c = p.segmentation_colour(&pm);
                assert!(c.iter().all(|&v| (v - 0.3).abs() < 1e-6), "{c:?}");
                assert!(
                    (pm.colour[0] - (0.5 + mask::EMBEDDING_SCALE * if left { -0.4 } else { 0.4 }))
                        .abs()
                        < 0.03
                );
            }
        }
        // A misshaped embedding is refused.
        let p = twins(true, true);
        let mut inputs = p.inputs.clone();
        inputs.embedding = Some(Image::new(3, 12, 16, vec![0.0; 3 * 12 * 16]).unwrap());
        let e = Prepared::new(inputs).err().expect("refused").to_string();
        assert!(e.contains("material embedding"), "{e}");
    }

    /// The photo's split ([`crate::split`]) runs on the automatic masks of an
    /// estimated segmentation, and is recorded; not on ground truth, nor with
    /// `no_split` or a given tolerance.
    #[test]
    fn the_photos_split_runs_on_estimated_automatic_masks_only() {
        let split = |estimated: bool, opts: MaskOptions| {
            twins(true, estimated)
                .pick_mask([5, 12], &opts)
                .unwrap()
                .split
        };
        let check = split(true, MaskOptions::default()).expect("ran");
        // One look (the photo is uniform noise): nothing leaves.
        assert_eq!(check.regions_removed, 0);
        assert_eq!(check.removed_share, 0.0);
        assert!(split(false, MaskOptions::default()).is_none());
        let no_split = MaskOptions {
            no_split: true,
            ..Default::default()
        };
        assert!(split(true, no_split).is_none());
        let given = MaskOptions {
            tolerance: Some(0.1),
            ..Default::default()
        };
        assert!(split(true, given).is_none());
    }

    /// A 64×48 photo (working resolution 32×24) of one flat material whose
    /// columns left of `edge` are transparent (grey, as decoding leaves
    /// them) and the rest show the sRGB grey `shown`.
    fn cut_out(edge: usize, shown: f32) -> Prepared {
        let (fw, fh) = (64, 48);
        let data = (0..3 * fw * fh)
            .map(|k| if k % fw < edge { 0.5 } else { shown })
            .collect();
        Prepared::new(Inputs {
            photo: Image::new(3, fh, fw, data).unwrap(),
            elements: flat_elements([0.0, 0.0, 1.0], None),
            segmentation: flat(3, &[0.2, 0.5, 0.7]),
            embedding: None,
            segmentation_estimated: false,
            albedo_estimated: false,
            envmap: None,
            opaque: Some(Mask {
                width: fw,
                height: fh,
                data: (0..fw * fh).map(|i| i % fw >= edge).collect(),
            }),
            disagreement: None,
        })
        .unwrap()
    }

    #[test]
    fn transparent_pixels_are_never_picked_masked_or_read() {
        // Column 21 on: working column 10 (photo columns 20, 21) is half
        // opaque and keeps its surface, columns 0–9 lose theirs.
        let p = cut_out(21, 0.8);
        let (w, h) = p.work_size();
        for i in 0..w * h {
            assert_eq!(p.valid[i], i % w >= 10, "working pixel {i}");
        }
        // The working photo averages the opaque pixels only: the half-opaque
        // column is the opaque colour, not a blend with the grey fill.
        let lin = SrgbDecodeTable::new().decode(0.8);
        for y in 0..h {
            let v = p.photo_work.at(0, y * w + 10);
            assert!((v - lin).abs() < 1e-6, "row {y}: {v} vs {lin}");
        }
        // Picks on transparent pixels are refused; on opaque ones taken.
        let e = p.check_pick([20, 5]).unwrap_err().to_string();
        assert!(e.contains("(20, 5)") && e.contains("transparent"), "{e}");
        p.check_pick([21, 5]).unwrap();
        assert!(p.pick_mask([3, 40], &MaskOptions::default()).is_err());
        // The whole visible material, and nothing transparent.
        let pm = p.pick_mask([40, 20], &MaskOptions::default()).unwrap();
        let full = photo_mask(&p, &pm);
        let opaque = p.inputs.opaque.as_ref().unwrap();
        assert_eq!(full.count(), opaque.count());
        assert!(full.data.iter().zip(&opaque.data).all(|(&m, &o)| !m || o));
        // A given mask loses its transparent pixels; one of only those is refused.
        let given = |keep: &dyn Fn(usize) -> bool| Mask {
            width: 64,
            height: 48,
            data: (0..64 * 48).map(keep).collect(),
        };
        let pm = p.given_mask(given(&|i| i % 64 < 30)).unwrap();
        assert_eq!(pm.photo.as_ref().unwrap().count(), 9 * 48);
        let e = p
            .given_mask(given(&|i| i % 64 < 21))
            .unwrap_err()
            .to_string();
        assert!(e.contains("only transparent"), "{e}");
        // The material extracted from the opaque part is its colour, the
        // grey fill nowhere in it.
        let inpainter = picker_inpaint::DiffusionInpainter::default();
        let pm = p.pick_mask([40, 20], &MaskOptions::default()).unwrap();
        let opts = test_options(&inpainter, UvChoice::Auto);
        let (m, _) = extract(&p, "m", Some([40, 20]), &pm, &opts).unwrap();
        assert!(
            (m.area_fraction - 43.0 / 64.0).abs() < 1e-9,
            "{}",
            m.area_fraction
        );
        // The palette's threshold is a share of the visible area: the one
        // material covers all of it.
        let all = p.palette(0.99, 4, false, true);
        assert_eq!(all.len(), 1);
        assert!(all[0]
            .1
            .mask
            .data
            .iter()
            .zip(&p.valid)
            .all(|(&m, &v)| !m || v));
        // Misshaped or wholly transparent opacity is refused.
        let mut inputs = p.inputs.clone();
        inputs.opaque.as_mut().unwrap().data.pop();
        let e = Prepared::new(inputs).err().expect("refused").to_string();
        assert!(e.contains("opaque pixels"), "{e}");
        let mut inputs = p.inputs.clone();
        inputs.opaque.as_mut().unwrap().data.fill(false);
        let e = Prepared::new(inputs).err().expect("refused").to_string();
        assert!(e.contains("every pixel of the photo is transparent"), "{e}");
    }

    #[test]
    fn auto_falls_back_to_a_single_colour_when_no_texture_can_be_reprojected() {
        let p = unreprojectable();
        let pm = p.pick_mask([16, 12], &MaskOptions::default()).unwrap();
        let inpainter = picker_inpaint::DiffusionInpainter::default();
        let opts = |uv| test_options(&inpainter, uv);
        let (m, diag) = extract(&p, "m", Some([16, 12]), &pm, &opts(UvChoice::Auto)).unwrap();
        assert!(!m.textured && m.texture.is_none());
        assert!(diag.textured_flag >= conv::TEXTURED_THRESHOLD);
        let why = diag.texture_fallback.expect("the fallback is recorded");
        assert!(
            why.contains("collapsed") && why.contains("edge-on or from behind"),
            "{why}"
        );
        // The single colour is the material's de-lit colour (photo ÷ shading
        // with the albedo as the shading's reference: the albedo here).
        for (c, want) in m.params.diffuse.iter().zip([0.5, 0.4, 0.3]) {
            assert!((c - want).abs() < 1e-3, "{:?}", m.params.diffuse);
        }
        // Asked for explicitly, either mode reports why it cannot.
        let e = extract(&p, "m", None, &pm, &opts(UvChoice::Plane)).unwrap_err();
        assert!(e.to_string().contains("no usable plane"), "{e}");
        let e = extract(&p, "m", None, &pm, &opts(UvChoice::Net)).unwrap_err();
        assert!(matches!(e, Error::NoTexture(_)), "{e}");
        assert!(
            e.to_string().contains("landed in the texture square"),
            "{e}"
        );
    }

    /// A `w × h` photo of a frontal plane (normals and view vectors +z,
    /// every pixel one material flagged textured) whose pixel `i` shows the
    /// grey sRGB value `shown(i)`; the albedo is that value decoded, so the
    /// de-lit colours are the albedo.
    fn frontal_plane(w: usize, h: usize, shown: &dyn Fn(usize) -> f32) -> Prepared {
        frontal_plane_with(
            w,
            h,
            shown,
            &|i| picker_render::io::srgb_decode(shown(i)),
            false,
        )
    }

    /// [`frontal_plane`] with the albedo given (`albedo(i)`, linear) and
    /// taken as the networks' estimate or as ground truth.
    fn frontal_plane_with(
        w: usize,
        h: usize,
        shown: &dyn Fn(usize) -> f32,
        albedo: &dyn Fn(usize) -> f32,
        albedo_estimated: bool,
    ) -> Prepared {
        let plane = |c: usize, f: &dyn Fn(usize) -> f32| {
            Image::new(c, h, w, (0..c * h * w).map(|k| f(k % (h * w))).collect()).unwrap()
        };
        let z = || {
            let data = [0.0, 0.0, 1.0]
                .iter()
                .flat_map(|&v| vec![v; h * w])
                .collect();
            Image::new(3, h, w, data).unwrap()
        };
        let elements = ElementImages::new(
            plane(3, albedo),
            plane(3, &|_| 0.04),
            plane(1, &|_| 0.5),
            z(),
            z(),
            Some(plane(3, &|_| 1.0)),
        )
        .unwrap();
        Prepared::new(Inputs {
            photo: plane(3, shown),
            elements,
            segmentation: plane(3, &|_| 0.5),
            embedding: None,
            segmentation_estimated: false,
            albedo_estimated,
            envmap: None,
            opaque: None,
            disagreement: None,
        })
        .unwrap()
    }

    /// The material picked at (20, 50) of a frontal plane, extracted in the
    /// plane mode with a 60° field of view and the options `tweak` makes of
    /// [`test_options`]'s (diffusion inpainting): the material, its
    /// diagnostics and the mask's pixel count.
    fn pick_plane(
        p: &Prepared,
        tweak: impl for<'a> FnOnce(Options<'a>) -> Options<'a>,
    ) -> (Material, Diagnostics, usize) {
        let pick = [20, 50];
        let pm = p.pick_mask(pick, &MaskOptions::default()).unwrap();
        let inpainter = picker_inpaint::DiffusionInpainter::default();
        let opts = tweak(Options {
            fov_deg: Some(60.0),
            ..test_options(&inpainter, UvChoice::Plane)
        });
        let (m, diag) = extract(p, "m", Some(pick), &pm, &opts).unwrap();
        (m, diag, pm.mask.count())
    }

    /// The first channel of the texture picked at (20, 50) on a 96×64
    /// frontal plane showing `shown` (display values), whose albedo is a
    /// flat 0.3, taken as the networks' estimate or as ground truth, with
    /// the de-lighting's `shading_sigma`; the plane's raw crop (no fold, no
    /// tiling) at 48 texels; and the share of clipped pixels the
    /// de-lighting reported.
    fn flat_albedo_texture(
        shown: &dyn Fn(usize) -> f32,
        estimated: bool,
        shading_sigma: f32,
    ) -> (Vec<f32>, usize, f64) {
        let p = frontal_plane_with(96, 64, shown, &|_| 0.3, estimated);
        let (m, diag, _) = pick_plane(&p, |o| Options {
            size: Some(48),
            fold_period: false,
            line_refine: false,
            tileable: false,
            heal_seams: false,
            shading_sigma,
            ..o
        });
        let t = m.texture.unwrap().texture;
        // Recorded when the networks' albedo was smoothed, and only then.
        let d = diag.delight;
        assert_eq!(d.is_some(), estimated && shading_sigma > 0.0, "{d:?}");
        assert!(d.is_none_or(|d| d.shading_sigma == shading_sigma));
        let clipped = d.map_or(0.0, |d| d.clipped_share);
        (t.data[..t.width * t.height].to_vec(), t.width, clipped)
    }

    /// Mean and contrast (standard deviation over mean) of `v`.
    fn mean_contrast(v: &[f32]) -> (f32, f32) {
        let n = v.len() as f32;
        let mean = v.iter().sum::<f32>() / n;
        let sd = (v.iter().map(|x| (x - mean).powi(2)).sum::<f32>() / n).sqrt();
        (mean, sd / mean)
    }

    /// Fine stripes of albedo (period 4 pixels) under light that rises from
    /// left to right, the photo of [`flat_albedo_texture`]'s plane.
    fn striped(i: usize) -> f32 {
        let albedo = if (i % 96) % 4 < 2 { 0.2 } else { 0.4 };
        let light = 0.5 + 0.5 * (i % 96) as f32 / 96.0;
        crate::photo::srgb_encode(albedo * light)
    }

    /// A frontal plane whose photo is an albedo of fine stripes under light
    /// that rises from left to right, and whose "network" albedo is flat at
    /// the stripes' mean (the detail lost, the level right). With the albedo
    /// estimated, the de-lighting takes its shading smoothed
    /// ([`crate::shading`]): the texture shows the photo's stripes at the
    /// network's level, without the light's ramp. With σ 0, or with the
    /// albedo taken as ground truth, the texture is the flat albedo.
    #[test]
    fn an_estimated_albedo_gives_the_light_and_the_photo_the_detail() {
        let (v, w, clipped) = flat_albedo_texture(&striped, true, crate::shading::SHADING_SIGMA);
        assert_eq!(clipped, 0.0);
        let (mean, contrast) = mean_contrast(&v);
        assert!((mean - 0.3).abs() < 0.05, "level {mean}");
        // The stripes' own contrast is 1/3.
        assert!(contrast > 0.2, "contrast {contrast}");
        // The right half's mean over the left's: the light's ramp is gone.
        let half = |right: bool| {
            let s: Vec<f32> = (0..v.len())
                .filter(|i| (i % w >= w / 2) == right)
                .map(|i| v[i])
                .collect();
            s.iter().sum::<f32>() / s.len() as f32
        };
        let ramp = half(true) / half(false);
        assert!((ramp - 1.0).abs() < 0.1, "light left in: {ramp}");
        for (estimated, sigma) in [(true, 0.0), (false, crate::shading::SHADING_SIGMA)] {
            let (mean, contrast) =
                mean_contrast(&flat_albedo_texture(&striped, estimated, sigma).0);
            assert!((mean - 0.3).abs() < 0.01, "level {mean}");
            assert!(contrast < 0.02, "{estimated} {sigma}: contrast {contrast}");
        }
    }

    /// As above with a clipped highlight (a 10×10 patch of the photo at
    /// full white): there the photo's detail is not the material's and the
    /// network's albedo stands in, so the texture has no bright patch; the
    /// rest keeps the photo's stripes.
    #[test]
    fn a_clipped_highlight_takes_the_networks_albedo() {
        let blob = |i: usize| (40..50).contains(&(i % 96)) && (20..30).contains(&(i / 96));
        let shown = |i: usize| if blob(i) { 1.0 } else { striped(i) };
        let (v, _, clipped) = flat_albedo_texture(&shown, true, crate::shading::SHADING_SIGMA);
        // 100 of the plane's 96 × 64 pixels.
        assert!((clipped - 100.0 / (96.0 * 64.0)).abs() < 1e-9, "{clipped}");
        let max = v.iter().fold(0.0f32, |a, &b| a.max(b));
        // The stripes reach 0.4 at the network's level (0.3 mean); the
        // clipped patch de-lit by the smoothed shading would be above 1.
        assert!(max < 0.6, "brightest texel {max}");
        let (_, contrast) = mean_contrast(&v);
        assert!(contrast > 0.2, "stripes kept: {contrast}");
    }

    /// A material half of whose photo is clipped (stripes of full white
    /// and dark, a chessboard's white squares overexposed): the clipping is
    /// the material's own colour, so the clipped pixels are de-lit as the
    /// others and the texture keeps the stripes' full contrast, where the
    /// networks' flat albedo standing in for the white would flatten it.
    #[test]
    fn a_mostly_clipped_material_keeps_its_white() {
        let shown = |i: usize| {
            if (i % 96) % 8 < 4 {
                1.0
            } else {
                crate::photo::srgb_encode(0.05)
            }
        };
        let (v, w, clipped) = flat_albedo_texture(&shown, true, crate::shading::SHADING_SIGMA);
        assert!((clipped - 0.5).abs() < 1e-9, "{clipped}");
        // The median white and dark texel (split at the mean): the photo
        // has them at least 20 : 1 (white clipped at 1, dark 0.05). With the
        // networks' flat albedo standing in for the white, about 10 : 1.
        let mean = v.iter().sum::<f32>() / v.len() as f32;
        let median = |bright: bool| {
            let mut s: Vec<f32> = v
                .iter()
                .copied()
                .filter(|&t| (t > mean) == bright)
                .collect();
            s.sort_by(f32::total_cmp);
            s[s.len() / 2]
        };
        let (white, dark) = (median(true), median(false));
        assert!(
            white / dark > 15.0,
            "white {white} over dark {dark} (width {w})"
        );
    }

    /// The networks' two passes' disagreement, when given, is averaged over
    /// the material's working mask into `diagnostics.mirror_disagreement`
    /// (the plane's whole 96×64 frame here: the mean of two ramps); without
    /// it, or with maps of another size, the diagnostic is absent.
    #[test]
    fn the_passes_disagreement_is_averaged_over_the_mask() {
        let (w, h) = (96, 64);
        let mut p = frontal_plane_with(w, h, &striped, &|_| 0.3, true);
        let ramp = |scale: f32| {
            Image::new(
                1,
                h,
                w,
                (0..w * h).map(|i| scale * (i % w) as f32).collect(),
            )
            .unwrap()
        };
        let run = |p: &Prepared| {
            let (_, diag, count) = pick_plane(p, |o| Options {
                size: Some(16),
                ..o
            });
            (diag.mirror_disagreement, count)
        };
        assert_eq!(run(&p).0, None);
        p.inputs.disagreement = Some(PassDisagreement {
            albedo: ramp(0.001),
            normals_deg: ramp(0.5),
        });
        let (d, count) = run(&p);
        assert_eq!(count, w * h, "the whole plane is the material");
        let d = d.unwrap();
        // Mean column index 47.5.
        assert!((d.albedo - 0.0475).abs() < 1e-6, "{d:?}");
        assert!((d.normals_deg - 23.75).abs() < 1e-4, "{d:?}");
        p.inputs.disagreement = Some(PassDisagreement {
            albedo: Image::new(1, 2, 2, vec![0.0; 4]).unwrap(),
            normals_deg: Image::new(1, 2, 2, vec![0.0; 4]).unwrap(),
        });
        assert_eq!(run(&p).0, None, "maps of another size are not read");
    }

    /// A material whose texture comes from an untypical part of it
    /// ([`crate::level`]): on a 128×96 frontal plane, the material is a
    /// 32×32 block at the top left (albedo 0.08) and a 16-pixel band along
    /// the right and bottom edges (0.3), 3.25 times the block's pixels. The
    /// pick is in the block, so the plane mode's texture is the block's
    /// (the part of the mask at the pick); its level is brought to the
    /// first quartile of the material's local mean luminances, which is the
    /// band's, and the texture is the unlevelled one times the recorded
    /// gain. `level: false` keeps it and records nothing; a uniform plane's
    /// texture is typical and kept.
    #[test]
    fn a_texture_from_an_untypical_part_gets_the_materials_level() {
        let (w, h) = (128, 96);
        let block = |i: usize| i % w < 32 && i / w < 32;
        let band = |i: usize| i % w >= 112 || i / w >= 80;
        let albedo = |i: usize| if block(i) { 0.08 } else { 0.3 };
        let p = frontal_plane_with(
            w,
            h,
            &|i| crate::photo::srgb_encode(albedo(i)),
            &albedo,
            false,
        );
        let given = Mask {
            width: w,
            height: h,
            data: (0..w * h).map(|i| block(i) || band(i)).collect(),
        };
        let inpainter = picker_inpaint::DiffusionInpainter::default();
        let run = |level: bool| {
            let pm = p.given_mask(given.clone()).unwrap();
            let opts = Options {
                fov_deg: Some(60.0),
                size: Some(24),
                fold_period: false,
                level,
                ..test_options(&inpainter, UvChoice::Plane)
            };
            extract(&p, "m", Some([10, 10]), &pm, &opts).unwrap()
        };
        let (kept, kept_diag) = run(false);
        assert_eq!(kept_diag.level, None);
        let before = crate::level::mean_colour(&kept.texture.as_ref().unwrap().texture);
        for c in before {
            assert!((c - 0.08).abs() < 0.005, "the block's texture: {before:?}");
        }
        let (levelled, diag) = run(true);
        let check = diag.level.unwrap();
        assert_eq!(check.texture_mean, before);
        assert!((check.median - 0.3).abs() < 1e-3, "{check:?}");
        assert!((check.q1 - 0.3).abs() < 1e-3, "{check:?}");
        let lum = crate::level::luminance(before);
        assert!((check.gain - check.q1 / lum).abs() < 1e-4, "{check:?}");
        let (a, b) = (
            &kept.texture.as_ref().unwrap().texture,
            &levelled.texture.as_ref().unwrap().texture,
        );
        for (k, (x, y)) in a.data.iter().zip(&b.data).enumerate() {
            assert!((x * check.gain - y).abs() < 1e-6, "texel {k}: {x} → {y}");
        }
        for (d, b) in levelled.params.diffuse.iter().zip(before) {
            assert!(
                (d - b * check.gain).abs() < 1e-4,
                "{:?}",
                levelled.params.diffuse
            );
        }
        // A uniform plane: typical, kept as it is.
        let uniform = frontal_plane_with(w, h, &|_| 0.5, &|_| 0.214, false);
        let (_, diag, _) = pick_plane(&uniform, |o| Options {
            size: Some(16),
            ..o
        });
        assert_eq!(diag.level.map(|l| l.gain), Some(1.0));
    }

    /// A 160×96 scene: a chessboard of 8-pixel squares (80×48, from (40,
    /// 24)) whose two colours the segmentation tells apart, on a background
    /// of a third colour with a grey 20×20 object on it (at (130, 40)); and
    /// the board's pixels.
    fn chessboard_on_a_floor() -> (Prepared, Vec<bool>) {
        let (w, h) = (160, 96);
        let on_board = |x: usize, y: usize| (40..120).contains(&x) && (24..72).contains(&y);
        let dark =
            |x: usize, y: usize| on_board(x, y) && ((x - 40) / 8 + (y - 24) / 8).is_multiple_of(2);
        let object = |x: usize, y: usize| (130..150).contains(&x) && (40..60).contains(&y);
        let colour = |i: usize| -> [f32; 3] {
            let (x, y) = (i % w, i / w);
            if dark(x, y) {
                [0.1, 0.1, 0.12]
            } else if on_board(x, y) {
                [0.9, 0.85, 0.8]
            } else if object(x, y) {
                [0.5, 0.5, 0.5]
            } else {
                [0.3, 0.6, 0.9]
            }
        };
        let mut p = frontal_plane(w, h, &|i| colour(i)[0]);
        p.inputs.segmentation = Image::new(
            3,
            h,
            w,
            (0..3 * h * w)
                .map(|k| colour(k % (h * w))[k / (h * w)])
                .collect(),
        )
        .unwrap();
        let board = (0..w * h).map(|i| on_board(i % w, i / w)).collect();
        (p, board)
    }

    /// On [`chessboard_on_a_floor`]: a pick on either colour gives the whole
    /// board (and the check says so), not the background's fringe;
    /// `no_pattern` keeps the picked colour; a pick on the object or the
    /// background gives it alone.
    #[test]
    fn a_pick_on_one_colour_of_a_chessboard_gives_the_board() {
        let (p, board) = chessboard_on_a_floor();
        for pick in [[44u32, 28], [52, 28], [115, 67]] {
            let pm = p.pick_mask(pick, &MaskOptions::default()).unwrap();
            // The board (all but the corners of its corner squares, where
            // the leak guard's relief leaves the picked colour's own mask
            // short and the other colour is not near) and nothing else.
            let area = board.iter().filter(|&&b| b).count();
            let (inside, outside) = pm
                .mask
                .data
                .iter()
                .zip(&board)
                .fold((0, 0), |(i, o), (&m, &b)| {
                    (i + (m && b) as usize, o + (m && !b) as usize)
                });
            assert!(
                outside == 0 && inside >= area - 4,
                "pick {pick:?}: {inside} of {area} inside, {outside} outside, {:?}",
                pm.pattern
            );
            let check = pm.pattern.as_ref().unwrap();
            assert!(
                check.merged && (check.own_share - 0.5).abs() < 0.05,
                "{check:?}"
            );
            assert!(pm.sure.iter().zip(&board).all(|(&s, &b)| !s || b));
            // The texture is taken from both colours.
            assert!(pm.sure.iter().filter(|&&s| s).count() > 3000);
            let with = |o: MaskOptions| p.pick_mask(pick, &o).unwrap();
            let own = with(MaskOptions {
                no_pattern: true,
                ..Default::default()
            });
            assert!(own.pattern.is_none());
            let own_n = own.mask.count();
            assert!(
                own_n <= area / 2 && own_n >= area * 9 / 20,
                "{own_n} of {area}"
            );
            // Connected: the region of the picked colour at the pick (its
            // squares joined at the corners the leak guard left whole), and
            // the companion's region at its own pick: a piece of the board
            // at most, here no pattern.
            let con = with(MaskOptions {
                connected: true,
                ..Default::default()
            });
            let n = con.mask.count();
            assert!(n >= 48 && n <= own_n, "connected: {n} pixels");
            assert!(!con.pattern.is_some_and(|c| c.merged));
        }
        for pick in [[140u32, 50], [10, 10]] {
            let pm = p.pick_mask(pick, &MaskOptions::default()).unwrap();
            assert!(
                !pm.pattern.as_ref().is_some_and(|c| c.merged),
                "pick {pick:?}"
            );
            assert!(pm.mask.data.iter().zip(&board).all(|(&m, &b)| !(m && b)));
        }
    }

    /// `--all` on [`chessboard_on_a_floor`]: the board is one material of
    /// the palette with patterns, its two colours two without.
    #[test]
    fn the_palette_takes_a_chessboard_whole() {
        let (p, board) = chessboard_on_a_floor();
        let area = board.iter().filter(|&&b| b).count();
        let on_board = |pm: &PickMask| {
            pm.mask
                .data
                .iter()
                .zip(&board)
                .filter(|(&m, &b)| m && b)
                .count()
        };
        let pal = p.palette(0.05, 8, true, true);
        let boards: Vec<usize> = pal
            .iter()
            .map(|(_, pm)| on_board(pm))
            .filter(|&n| n > 0)
            .collect();
        assert_eq!(boards.len(), 1, "{boards:?}");
        assert!(boards[0] >= area - 4, "{boards:?} of {area}");
        let pal = p.palette(0.05, 8, false, true);
        let boards: Vec<usize> = pal
            .iter()
            .map(|(_, pm)| on_board(pm))
            .filter(|&n| n > 0)
            .collect();
        assert_eq!(boards.len(), 2, "{boards:?}");
        assert!(boards.iter().all(|&n| n <= area / 2), "{boards:?}");
    }

    /// Collapsed UVs (every pixel at one point of the square) on a material
    /// whose normals are too noisy for a plane by the spread rule (a third
    /// facing the camera, a third tilted 31° either way): `auto` rectifies a
    /// plane anyway, since UVs on a point show almost nothing of the texture;
    /// inconsistent but not collapsed UVs would have been kept.
    #[test]
    fn collapsed_uvs_give_way_to_a_rough_plane() {
        let (h, w) = (48, 64);
        let mut p = frontal_plane(w, h, &|i| {
            let (x, y) = (i % w, i / w);
            if (x / 4 + y / 4) % 2 == 0 {
                0.8
            } else {
                0.3
            }
        });
        let tilt = |i: usize| [-0.6f32, 0.0, 0.6][(i % w + i / w) % 3];
        let normals: Vec<f32> = (0..3 * h * w)
            .map(|k| {
                let (c, i) = (k / (h * w), k % (h * w));
                let n = Vec3::new(tilt(i), 0.0, 1.0).normalize();
                n[c]
            })
            .collect();
        p.inputs.elements.normals = Image::new(3, h, w, normals).unwrap();
        let pm = p.pick_mask([30, 20], &MaskOptions::default()).unwrap();
        let inpainter = picker_inpaint::DiffusionInpainter::default();
        let opts = Options {
            fov_deg: Some(60.0),
            ..test_options(&inpainter, UvChoice::Auto)
        };
        let (m, diag) = extract(&p, "rough", Some([30, 20]), &pm, &opts).unwrap();
        let uv = diag.uv.unwrap();
        assert!(
            uv.plane_spread_deg.unwrap() > AUTO_MAX_PLANE_SPREAD_DEG,
            "{uv:?}"
        );
        assert!(
            uv.net_uv_footprint.unwrap() < AUTO_MIN_UV_FOOTPRINT,
            "{uv:?}"
        );
        assert_eq!(uv.mode, UvMode::Plane, "{uv:?}");
        assert!(m.texture.unwrap().coverage_fraction > 0.5);
    }

    /// The grain of a texture square measured with the square as its own
    /// photo.
    fn texture_grain(t: &Image) -> crate::grain::Grain {
        let (w, h) = (t.width, t.height);
        let coords = Coords::identity(w, h, false);
        let luma: Vec<f32> = (0..w * h).map(|i| luminance(t.rgb(i))).collect();
        crate::grain::measure(&coords, &vec![true; w * h], &luma).unwrap()
    }

    /// Stripes running at 30° across a frontal plane, no straight-line axis
    /// (the lines are off): with the grain alignment the texture's stripes run
    /// along one of its axes and the diagnostics say so; without it they keep
    /// the photo's angle and nothing is recorded.
    #[test]
    fn the_plane_modes_axes_follow_the_grain() {
        let (h, w) = (96, 128);
        let (c, s) = (120f32.to_radians().cos(), 120f32.to_radians().sin());
        let p = frontal_plane(w, h, &|i| {
            let (x, y) = ((i % w) as f32, (i / w) as f32);
            0.45 + 0.3 * (std::f32::consts::TAU * (x * c + y * s) / 11.0).sin()
        });
        let pm = p.pick_mask([60, 50], &MaskOptions::default()).unwrap();
        let inpainter = picker_inpaint::DiffusionInpainter::default();
        let run = |align_grain| {
            let opts = Options {
                size: Some(64),
                fov_deg: Some(60.0),
                fold_period: false,
                fold_centring: true,
                align_grain,
                ..test_options(&inpainter, UvChoice::Plane)
            };
            extract(&p, "stripes", Some([60, 50]), &pm, &opts).unwrap()
        };
        let (turned, diag) = run(true);
        let uv = diag.uv.unwrap();
        let g = uv.grain.expect("measured");
        assert!(uv.grain_applied, "{g:?}");
        // Drawn at 30° below the x axis in the photo (y down): (du, dv) at +30°.
        assert!((g.angle_deg - 30.0).abs() < 1.5, "{g:?}");
        let out = texture_grain(&turned.texture.unwrap().texture);
        assert!(out.turn_deg.abs() < 3.0 && out.coherence > 0.5, "{out:?}");
        let (kept, diag) = run(false);
        let uv = diag.uv.unwrap();
        assert!(uv.grain.is_none() && !uv.grain_applied);
        let out = texture_grain(&kept.texture.unwrap().texture);
        assert!((out.angle_deg - 30.0).abs() < 3.0, "{out:?}");
    }

    /// A frontal plane whose photo is a ramp with fine bars (a crop: its left
    /// and right edges are two different places): the plane mode cuts the
    /// columns' wrap edge through the square's surroundings (or, without the
    /// cut, inpaints a band across it), and the texture tiles with a seam
    /// ratio far below that of the texture that keeps its observed edges;
    /// the cut keeps more observed texels than the band.
    #[test]
    fn a_rectified_crop_gets_its_seams_healed() {
        let (h, w) = (64, 96);
        let p = frontal_plane(w, h, &|i| {
            let (x, y) = (i % w, i / w);
            0.2 + 0.5 * x as f32 / w as f32 + if (x + y / 3) % 5 == 0 { 0.03 } else { 0.0 }
        });
        let pm = p.pick_mask([40, 30], &MaskOptions::default()).unwrap();
        assert_eq!(pm.mask.count(), w * h);
        let run = |heal_seams, cut_seams| plane_crop_with(&p, &pm, [40, 30], heal_seams, cut_seams);
        let (cut, cut_diag) = run(true, true);
        let (banded, band_diag) = run(true, false);
        let (kept, kept_diag) = run(false, true);
        // The square's left and right surroundings were seen: cut there.
        let seam_cut = cut_diag.seam_cut.expect("cut");
        assert!(seam_cut.columns.is_some(), "{seam_cut:?}");
        assert!(band_diag.seam_cut.is_none());
        assert!(band_diag
            .seam_band
            .is_some_and(|r| r > picker_inpaint::SEAM_BAND_MIN_RATIO));
        assert!(kept_diag.seam_band.is_none() && kept_diag.seam_cut.is_none());
        let b = kept.texture.unwrap().seam;
        for (what, t) in [("cut", &cut), ("band", &banded)] {
            let a = t.texture.as_ref().unwrap().seam;
            assert!(
                b.ratio > 2.0 && a.ratio < b.ratio / 2.0,
                "{what}: {b:?} -> {a:?}"
            );
        }
        let (kc, kb) = (
            cut_diag.observed_kept.unwrap(),
            band_diag.observed_kept.unwrap(),
        );
        assert!(kc > kb + 0.1, "observed texels kept: cut {kc}, band {kb}");
    }

    /// A square photo of a frontal plane, a diagonal ramp with a faint
    /// noise (a change of light across a plain surface), a patch of it the
    /// material: the texture square is the photo itself, so no surroundings
    /// were seen along either axis and its opposite edges differ. The
    /// texture is folded within the observed square (its side smaller by
    /// the overlap, the texels per unit square following), every texel
    /// observed, and it tiles; without the cut a band is inpainted instead,
    /// keeping far fewer observed texels. A `--size` keeps its side (the
    /// band then).
    #[test]
    fn a_crop_with_no_surroundings_is_folded_within_itself() {
        let (h, w) = (72, 72);
        let p = frontal_plane(w, h, &|i| {
            let (x, y) = ((i % w) as f32, (i / w) as f32);
            // A hash of the index (splitmix64's finaliser): no period.
            let mut z = (i as u64).wrapping_add(0x9E37_79B9_7F4A_7C15);
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            let n = ((z ^ (z >> 31)) >> 40) as f32 / (1u64 << 24) as f32;
            0.2 + 0.4 * (x + y) / (w + h) as f32 + 0.004 * n
        });
        // The material: a 48 × 48 patch in the middle; past it, nothing.
        let patch = |i: usize| (12..60).contains(&(i % w)) && (12..60).contains(&(i / w));
        let pm = mask_of(w, h, &patch, &patch);
        let inpainter = picker_inpaint::PatchMatchInpainter::default();
        let run = |cut_seams, size| {
            let opts = Options {
                max_size: 64,
                size,
                fov_deg: Some(60.0),
                cut_seams,
                ..test_options(&inpainter, UvChoice::Plane)
            };
            extract(&p, "ramp", Some([36, 36]), &pm, &opts).unwrap()
        };
        let (_, band_diag) = run(false, None);
        let s = band_diag.texture_size.unwrap();
        assert!(band_diag.seam_band.is_some());
        let (cut, diag) = run(true, None);
        let seam_cut = diag.seam_cut.expect("cut");
        assert!(
            seam_cut.columns.is_some() && seam_cut.rows.is_some(),
            "{seam_cut:?}"
        );
        assert!(diag.seam_band.is_none());
        assert_eq!(seam_cut.within, Some(s));
        let t = cut.texture.unwrap();
        let side = t.texture.width;
        let m = picker_inpaint::cut_margin(s);
        assert_eq!(side, (s - m) / 4 * 4, "observed side {s}");
        assert_eq!(diag.texture_size, Some(side));
        assert_eq!(diag.texture_made_size, Some(side));
        assert_eq!(t.observed_size, side);
        assert_eq!((t.raw.width, t.coverage.width), (side, side));
        let (kc, kb) = (
            diag.observed_kept.unwrap(),
            band_diag.observed_kept.unwrap(),
        );
        assert!(
            kc > 0.95 && kb < 0.8,
            "observed texels kept: cut {kc}, band {kb}"
        );
        // (A cut between unrelated texels of a noise is a little more visible
        // than neighbouring texels, which share photo pixels.)
        assert!(t.seam.ratio < 1.5, "{:?}", t.seam);
        // A requested side is kept: no fold within, the band.
        let (sized, sized_diag) = run(true, Some(s));
        assert_eq!(sized.texture.unwrap().texture.width, s);
        assert!(sized_diag.seam_band.is_some());
    }

    /// The reprojection of a `side`-texel square of a ramp with a faint
    /// noise (no period) with a margin of `cut_margin(side)` texels on every
    /// side, of which the texels `seen(x, y)` were observed (content
    /// coordinates).
    fn crop_content(side: usize, seen: &dyn Fn(usize, usize) -> bool) -> reproject::Reprojected {
        let m = picker_inpaint::cut_margin(side);
        let n = side + 2 * m;
        let mut texture = Image::zeros(3, n, n);
        let mut known = vec![false; n * n];
        let mut rng = picker_tensor::Rng::new(5);
        for y in 0..n {
            for x in 0..n {
                let i = y * n + x;
                let v = 0.2 + 0.4 * (x + y) as f32 / (2 * n) as f32 + 0.004 * rng.uniform(0.0, 1.0);
                for c in 0..3 {
                    texture.data[c * n * n + i] = v;
                }
                known[i] = seen(x, y);
                if !known[i] {
                    for c in 0..3 {
                        texture.data[c * n * n + i] = 0.0;
                    }
                }
            }
        }
        let coverage = Image {
            channels: 1,
            height: n,
            width: n,
            data: known.iter().map(|&k| if k { 0.9 } else { 0.0 }).collect(),
        };
        let weight = coverage.clone();
        reproject::Reprojected {
            texture,
            weight,
            coverage,
            known,
        }
    }

    /// A crop with no surroundings observed: its tile is folded within it,
    /// 7/8 of the side, both edges cut. With a strip just inside its left
    /// edge not observed, every overlap that tile could take holds the strip
    /// (its columns cannot be cut), and a tile one overlap smaller, placed
    /// past the strip, is: fully observed, more texels than the square keeps
    /// once its bands are cleared. With the rows' surroundings observed the
    /// square's rows are cut, and that smaller tile would keep fewer observed
    /// texels than the square with a band across its columns' edge: the
    /// square it is. Without the fold (a requested size) the square is only
    /// cropped.
    #[test]
    fn a_crop_is_folded_within_the_largest_tile_whose_edges_cut() {
        let s = 48;
        let m = picker_inpaint::cut_margin(s);
        let inside = |v: usize| (m..m + s).contains(&v);
        let strip = |x: usize| (m + 1..m + 7).contains(&x);
        let plain = crop_content(s, &|x, y| inside(x) && inside(y));
        let c = cut_crop(&plain, s, [true, true], true);
        assert_eq!(c.texture.width, (s - m) / 4 * 4);
        assert!(c.columns.is_some() && c.rows.is_some());
        let holed = crop_content(s, &|x, y| inside(x) && inside(y) && !strip(x));
        let c = cut_crop(&holed, s, [true, true], true);
        assert_eq!(
            c.texture.width,
            (s - 2 * m) / 4 * 4,
            "{:?} {:?}",
            c.columns,
            c.rows
        );
        assert!(c.columns.is_some() && c.rows.is_some());
        assert!(c.known.iter().all(|&k| k), "the tile lies past the strip");
        // The rows' surroundings seen: their edge is cut on the square.
        let rows_seen = crop_content(s, &|x, _| inside(x) && !strip(x));
        let c = cut_crop(&rows_seen, s, [true, true], true);
        assert_eq!(c.texture.width, s);
        assert!(
            c.columns.is_none() && c.rows.is_some(),
            "{:?} {:?}",
            c.columns,
            c.rows
        );
        // No fold: the square, cropped.
        let c = cut_crop(&holed, s, [true, true], false);
        assert_eq!(c.texture.width, s);
        assert!(c.columns.is_none() && c.rows.is_none());
        // Edges that need no cut: the square as it is.
        let c = cut_crop(&holed, s, [false, false], true);
        assert_eq!(c.texture.width, s);
        assert!(c.columns.is_none() && c.rows.is_none());
    }

    /// A mask of the whole `w × h` image whose surest part is `sure`.
    fn whole_mask(w: usize, h: usize, sure: &dyn Fn(usize) -> bool) -> PickMask {
        mask_of(w, h, &|_| true, sure)
    }

    /// The pick mask `mask` of a `w × h` image with the surest part `sure`.
    fn mask_of(
        w: usize,
        h: usize,
        mask: &dyn Fn(usize) -> bool,
        sure: &dyn Fn(usize) -> bool,
    ) -> PickMask {
        PickMask {
            mask: Mask {
                width: w,
                height: h,
                data: (0..w * h).map(mask).collect(),
            },
            colour: [0.5; 3],
            tolerance: 0.1,
            photo: None,
            sure: (0..w * h).map(sure).collect(),
            pattern: None,
            split: None,
        }
    }

    #[test]
    fn a_repeating_tile_is_rolled_to_its_smoothest_wrap() {
        // A 12×8 tile: a bright band at columns 5..9 and rows 2..5 (a
        // pattern's edges at 5, 9, 2 and 5); every other edge is flat.
        let (w, h) = (12, 8);
        let v = |x: usize, y: usize| {
            if (5..9).contains(&x) || (2..5).contains(&y) {
                0.9
            } else {
                0.1
            }
        };
        let tex = Image::new(
            3,
            h,
            w,
            (0..3 * w * h).map(|k| v(k % w, (k / w) % h)).collect(),
        )
        .unwrap();
        let known = vec![true; w * h];
        let at = smoothest_wrap(&tex, &known);
        // The lowest flat edges: column 0 (between 11 and 0), row 0.
        assert_eq!(at, [0, 0]);
        // Moved by (3, 1): the flat edges are elsewhere, the lowest found.
        let moved = roll(&tex, [3, 1]);
        let at = smoothest_wrap(&moved, &known);
        let step_x = |c: usize| step_x_of(&moved, c, w, h);
        let step_y = |r: usize| {
            (0..w)
                .map(|x| (moved.at(0, r * w + x) - moved.at(0, ((r + h - 1) % h) * w + x)).abs())
                .sum::<f32>()
        };
        assert_eq!(
            step_x(at[0]),
            (0..w).map(step_x).fold(f32::INFINITY, f32::min)
        );
        assert_eq!(
            step_y(at[1]),
            (0..h).map(step_y).fold(f32::INFINITY, f32::min)
        );
        // Rolling back undoes the roll; the rolled tile wraps as smoothly.
        let back = roll(&moved, [w - 3, h - 1]);
        assert_eq!(back.data, tex.data);
        let r = roll(&moved, at);
        assert_eq!(
            step_x_of(&r, 0, w, h),
            (0..w).map(step_x).fold(f32::INFINITY, f32::min)
        );
        // Unknown texels do not count; an edge with under half its pairs
        // known is passed over; nothing known: no roll.
        let mut partly = vec![false; w * h];
        for y in 0..h {
            for x in 0..w {
                partly[y * w + x] = x != 0 && x != 11;
            }
        }
        assert_ne!(smoothest_wrap(&tex, &partly)[0], 0);
        assert_eq!(smoothest_wrap(&tex, &vec![false; w * h]), [0, 0]);
        let m = roll_mask(&partly, w, h, [1, 0]);
        assert!(!m[10] && !m[11] && m[0]);
    }

    fn step_x_of(t: &Image, c: usize, w: usize, h: usize) -> f32 {
        (0..h)
            .map(|y| (t.at(0, y * w + c) - t.at(0, y * w + (c + w - 1) % w)).abs())
            .sum()
    }

    /// The plane-mode extraction of `pm` in `p` at `pick` (PatchMatch, sides
    /// up to 64, a 60° field of view, no period folding: a crop), with or
    /// without the seam band.
    fn plane_crop(
        p: &Prepared,
        pm: &PickMask,
        pick: [u32; 2],
        heal_seams: bool,
    ) -> (Material, Diagnostics) {
        plane_crop_with(p, pm, pick, heal_seams, true)
    }

    /// [`plane_crop`], with or without the cut through the surroundings.
    fn plane_crop_with(
        p: &Prepared,
        pm: &PickMask,
        pick: [u32; 2],
        heal_seams: bool,
        cut_seams: bool,
    ) -> (Material, Diagnostics) {
        let inpainter = picker_inpaint::PatchMatchInpainter::default();
        let opts = Options {
            max_size: 64,
            fov_deg: Some(60.0),
            heal_seams,
            cut_seams,
            fold_period: false,
            ..test_options(&inpainter, UvChoice::Plane)
        };
        extract(p, "crop", Some(pick), pm, &opts).unwrap()
    }

    /// A `--size` above the observed texel density: one texel more is still
    /// covered (made at that size); twelve times the side (past the largest
    /// splat footprint, [`reproject::MAX_SPLAT_RADIUS`]) is not, so the
    /// texture is made at the observed size and enlarged at the end, bit for
    /// bit the wrapped bicubic enlargement (clipped at 0) of the
    /// observed-size extraction, its coverage as blocks, its raw reprojection
    /// the observed-size one.
    /// A smaller `--size` is made at that size. All report the observed size.
    #[test]
    fn a_size_above_the_observed_density_enlarges_the_observed_texture() {
        let (h, w) = (48, 64);
        // Seeded noise: no period to fold, so the square holds one view.
        let noise = picker_tensor::Rng::new(7).uniform_vec(w * h, 0.2, 0.7);
        let p = frontal_plane(w, h, &|i| noise[i]);
        let pick = [30, 20];
        let pm = p.pick_mask(pick, &MaskOptions::default()).unwrap();
        let inpainter = picker_inpaint::PatchMatchInpainter::default();
        // (Without the cut through the surroundings: with no `--size` it may
        // fold a smaller tile within the square, which a given size never
        // does, so the two would not be the same texture.)
        let run = |size| {
            let opts = Options {
                size,
                max_size: 64,
                fov_deg: Some(60.0),
                cut_seams: false,
                ..test_options(&inpainter, UvChoice::Plane)
            };
            extract(&p, "m", Some(pick), &pm, &opts).unwrap()
        };
        let (m0, d0) = run(None);
        let s = d0.texture_observed_size.unwrap();
        assert_eq!((d0.texture_size, d0.texture_made_size), (Some(s), Some(s)));
        assert!(s >= 16, "observed size {s}");
        let t0 = m0.texture.unwrap();
        let sizes =
            |d: &Diagnostics| (d.texture_size, d.texture_observed_size, d.texture_made_size);

        let (m1, d1) = run(Some(s + 1));
        assert_eq!(sizes(&d1), (Some(s + 1), Some(s), Some(s + 1)));
        assert_eq!(m1.texture.unwrap().texture.width, s + 1);

        let big = 12 * s;
        let (m2, d2) = run(Some(big));
        // The same bits on one thread as on two.
        let one = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        let (m1t, _) = one.install(|| run(Some(big)));
        let (t2a, t2b) = (
            &m2.texture.as_ref().unwrap().texture,
            &m1t.texture.unwrap().texture,
        );
        assert!(
            t2a.data == t2b.data,
            "the enlargement depends on the thread count"
        );
        assert_eq!(sizes(&d2), (Some(big), Some(s), Some(s)));
        let t2 = m2.texture.unwrap();
        let mut want =
            crate::resample::bicubic(&t0.texture, big, big, crate::equalize::Edges::Wrap);
        want.data.iter_mut().for_each(|v| *v = v.max(0.0));
        assert!(
            t2.texture.data == want.data,
            "not the enlarged observed texture"
        );
        assert_eq!((t2.coverage.width, t2.coverage.height), (big, big));
        assert!(t2.coverage.data == crate::resample::area(&t0.coverage, big, big).data);
        assert!(t2.raw.data == t0.raw.data && t2.raw.width == s);
        assert_eq!(t2.coverage_fraction, t0.coverage_fraction);
        assert_eq!((t0.observed_size, t2.observed_size), (s, s));

        let small = s / 2;
        let (m3, d3) = run(Some(small));
        assert_eq!(sizes(&d3), (Some(small), Some(s), Some(small)));
        let t3 = m3.texture.unwrap();
        assert_eq!((t3.texture.width, t3.coverage.width), (small, small));
    }

    /// A `w × h` photo (focal `f`, principal point at the centre) of an
    /// endless chessboard of `cell`-sided squares on the plane of unit
    /// normal `n` through `(0, 0, −3)`, squares along `e1` (the camera's x
    /// axis on the plane, turned by `turn_deg` about `n`) and `n × e1`, 4×4
    /// supersampled; with the networks' normals saying `predicted`
    /// everywhere (a wrong plane). Returns the prepared inputs and the
    /// plane's point at `(s, t)` along the squares' axes.
    fn chessboard_photo(
        w: usize,
        h: usize,
        f: f32,
        plane: (Vec3, f32),
        cell: f32,
        predicted: Vec3,
    ) -> (Prepared, impl Fn(f32, f32) -> Vec3) {
        chessboard_photo_through(w, h, f, plane, cell, predicted, 0.0)
    }

    /// [`chessboard_photo`] seen through a lens of distortion `lambda`
    /// ([`crate::lens::Lens`]): each sample point of the photo is
    /// undistorted before its ray meets the board.
    fn chessboard_photo_through(
        w: usize,
        h: usize,
        f: f32,
        (n, turn_deg): (Vec3, f32),
        cell: f32,
        predicted: Vec3,
        lambda: f32,
    ) -> (Prepared, impl Fn(f32, f32) -> Vec3) {
        let lens = crate::lens::Lens::new(lambda, w, h);
        let (x, y) = plane::plane_basis(n, None);
        let turn = turn_deg.to_radians();
        let e1 = x * turn.cos() + y * turn.sin();
        let e2 = n.cross(e1);
        let o = Vec3::new(0.0, 0.0, -3.0);
        let (cx, cy) = (w as f32 / 2.0, h as f32 / 2.0);
        let shade = |x: f32, y: f32| {
            let u = lens.undistort(glam::Vec2::new(x, y));
            let d = Vec3::new((u.x - cx) / f, -(u.y - cy) / f, -1.0);
            let q = d * (n.dot(o) / n.dot(d)) - o;
            let (s, t) = ((q.dot(e1) / cell).floor(), (q.dot(e2) / cell).floor());
            if (s + t).rem_euclid(2.0) == 0.0 {
                0.8
            } else {
                0.2
            }
        };
        let photo: Vec<f32> = (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f32, (i / w) as f32);
                let mut acc = 0.0;
                for k in 0..16 {
                    acc += shade(
                        x + (k % 4) as f32 / 4.0 + 0.125,
                        y + (k / 4) as f32 / 4.0 + 0.125,
                    );
                }
                acc / 16.0
            })
            .collect();
        let mut p = frontal_plane(w, h, &|i| photo[i]);
        for (c, v) in predicted.to_array().into_iter().enumerate() {
            p.inputs.elements.normals.data[c * w * h..(c + 1) * w * h].fill(v);
        }
        (p, move |s: f32, t: f32| o + e1 * s + e2 * t)
    }

    /// The photo pixel (pick convention) of camera-space point `q`.
    fn pixel_of(q: Vec3, w: usize, h: usize, f: f32) -> [f32; 2] {
        [
            w as f32 / 2.0 + f * q.x / -q.z - 0.5,
            h as f32 / 2.0 - f * q.y / -q.z - 0.5,
        ]
    }

    /// The fold's two periods on the plane (their ratio is 1 for a
    /// chessboard of squares rectified right), when a period was found.
    fn period_ratio(d: &Diagnostics) -> Option<f32> {
        let f = d.uv.as_ref()?.period.as_ref()?;
        Some(f.period[0] / f.period[1])
    }

    /// A chessboard on a floor seen at 50°, turned 30° on it, whose
    /// predicted normals face the camera (a wrong plane): rectifying the
    /// predicted plane leaves the squares in perspective (no square period
    /// is found); the corners of a 4 × 4-square block given as a quad give
    /// the true plane (within 0.5°), the focal length (within 1 %), squares
    /// of equal periods, the texture's axes along the board, whatever `uv`
    /// asks. The true normal with the field of view given does the same
    /// for the board unturned.
    #[test]
    fn a_given_plane_replaces_the_predicted_one() {
        let (w, h, f) = (240, 180, 180.0f32);
        let tilt = 50f32.to_radians();
        let n = Vec3::new(0.0, tilt.sin(), tilt.cos());
        let cell = 0.25;
        let (p, at) = chessboard_photo(w, h, f, (n, 30.0), cell, Vec3::Z);
        let pick = [120, 90];
        let pm = p.pick_mask(pick, &MaskOptions::default()).unwrap();
        let inpainter = picker_inpaint::DiffusionInpainter::default();
        let run = |plane: Option<UserPlane>, fov_deg: Option<f32>| {
            let opts = Options {
                plane,
                fov_deg,
                ..test_options(&inpainter, UvChoice::Auto)
            };
            extract(&p, "board", Some(pick), &pm, &opts).unwrap().1
        };

        let predicted = Options {
            fov_deg: Some(plane::fov_from_focal(h, f)),
            ..test_options(&inpainter, UvChoice::Plane)
        };
        let d0 = extract(&p, "board", Some(pick), &pm, &predicted).unwrap().1;
        assert!(
            period_ratio(&d0).is_none_or(|r| (r - 1.0).abs() > 0.15),
            "the predicted (wrong) plane gave square periods: {:?}",
            d0.uv.as_ref().unwrap().period
        );
        assert!(d0.uv.as_ref().unwrap().user_plane.is_none());

        let a = 3.0 * cell;
        let corners =
            [(-a, -a), (a, -a), (a, a), (-a, a)].map(|(s, t)| pixel_of(at(s, t), w, h, f));
        let d1 = run(Some(UserPlane::Quad(crate::quad::Quad(corners))), None);
        let uv = d1.uv.as_ref().unwrap();
        assert_eq!((uv.mode, uv.requested), (UvMode::Plane, UvChoice::Plane));
        let used = uv.user_plane.as_ref().unwrap();
        assert_eq!(used.source, "quad");
        let angle = Vec3::from(used.normal).angle_between(n).to_degrees();
        assert!(angle < 0.5, "quad normal {:?} is {angle}° off", used.normal);
        assert_eq!(uv.focal_source, Some("quad"));
        let focal = uv.focal_px.unwrap();
        assert!((focal / f - 1.0).abs() < 0.01, "focal {focal}");
        assert!(
            (used.corner_angle_deg.unwrap() - 90.0).abs() < 1.0,
            "{used:?}"
        );
        assert!(uv.plane_normal.is_none() && uv.lines.is_none());
        let r = period_ratio(&d1).expect("the board's period");
        assert!((r - 1.0).abs() < 0.05, "periods {:?}", uv.period);
        // With the quad's real size (6 squares of 0.25 a side), the
        // texture's size on the board: its tile of 2 × 2 squares.
        let opts = Options {
            plane: Some(UserPlane::Quad(crate::quad::Quad(corners))),
            quad_size_m: Some([6.0 * cell, 6.0 * cell]),
            ..test_options(&inpainter, UvChoice::Auto)
        };
        let (m, d) = extract(&p, "board", Some(pick), &pm, &opts).unwrap();
        let used = d.uv.as_ref().unwrap().user_plane.as_ref().unwrap();
        assert!((used.size_ratio.unwrap() - 1.0).abs() < 0.01, "{used:?}");
        // The plane through N·P = −1 is 1/(3 cos 50°) of the true one's distance.
        let unit = 3.0 * f64::from(tilt.cos());
        assert!((used.unit_m.unwrap() / unit - 1.0).abs() < 0.01, "{used:?}");
        let size = m.texture.unwrap().size_m.expect("a size");
        for s in size {
            assert!((s / (2.0 * f64::from(cell)) - 1.0).abs() < 0.03, "{size:?}");
        }
        assert_eq!(
            d1.uv.as_ref().unwrap().user_plane.as_ref().unwrap().unit_m,
            None
        );
        let bad = Options {
            plane: Some(UserPlane::FRONT),
            quad_size_m: Some([1.0, 1.0]),
            ..test_options(&inpainter, UvChoice::Auto)
        };
        let e = extract(&p, "board", Some(pick), &pm, &bad)
            .unwrap_err()
            .to_string();
        assert!(e.contains("needs the quadrilateral"), "{e}");

        let (p, _) = chessboard_photo(w, h, f, (n, 0.0), cell, Vec3::Z);
        let pm = p.pick_mask(pick, &MaskOptions::default()).unwrap();
        let opts = Options {
            plane: Some(UserPlane::Normal(n)),
            fov_deg: Some(plane::fov_from_focal(h, f)),
            ..test_options(&inpainter, UvChoice::Auto)
        };
        let d2 = extract(&p, "board", Some(pick), &pm, &opts).unwrap().1;
        let uv = d2.uv.as_ref().unwrap();
        assert_eq!(uv.user_plane.as_ref().unwrap().source, "normal");
        assert_eq!(uv.focal_source, Some("fov"));
        let r = period_ratio(&d2).expect("the board's period");
        assert!((r - 1.0).abs() < 0.05, "periods {:?}", uv.period);
    }

    /// A chessboard on a floor seen through a barrel lens (λ = −0.25), the
    /// true plane and focal length given: with the lens given, the fold's
    /// periods are square and its repeats line up (a stronger period) and
    /// `diagnostics.uv.lens` says so; taken as a pinhole (none given, and a
    /// photo of one board has no long edges to estimate it from), the
    /// rectified board bends and its periods are neither. A quad picked on
    /// the distorted photo (the corners of a 4 × 4-square block) gives the
    /// true plane through the lens, and a plane off by its distortion
    /// without it.
    #[test]
    fn a_given_lens_is_undone_before_the_plane_is_rectified() {
        let (w, h, f) = (240, 180, 150.0f32);
        let tilt = 45f32.to_radians();
        let n = Vec3::new(0.0, tilt.sin(), tilt.cos());
        let cell = 0.25;
        let lambda = -0.25;
        let pick = [120, 90];
        let inpainter = picker_inpaint::DiffusionInpainter::default();
        let run = |choice: LensChoice, plane: UserPlane| {
            let (mut p, at) = chessboard_photo_through(w, h, f, (n, 0.0), cell, Vec3::Z, lambda);
            p.lens_choice = choice;
            let pm = p.pick_mask(pick, &MaskOptions::default()).unwrap();
            let opts = Options {
                plane: Some(plane),
                fov_deg: Some(plane::fov_from_focal(h, f)),
                ..test_options(&inpainter, UvChoice::Plane)
            };
            let d = extract(&p, "board", Some(pick), &pm, &opts).unwrap().1;
            (d, at)
        };
        let strength = |d: &Diagnostics| {
            let s = d.uv.as_ref().unwrap().period.as_ref().unwrap().strength;
            s[0].min(s[1])
        };
        let (lens, _) = run(LensChoice::Given(lambda), UserPlane::Normal(n));
        let (pinhole, _) = run(LensChoice::Auto, UserPlane::Normal(n));
        let used = lens.uv.as_ref().unwrap().lens.clone().unwrap();
        assert_eq!((used.source, used.lambda), ("given", lambda), "{used:?}");
        let none = pinhole.uv.as_ref().unwrap().lens.clone().unwrap();
        assert_eq!((none.source, none.lambda), ("none", 0.0), "{none:?}");
        let r = period_ratio(&lens).expect("the board's period");
        assert!((r - 1.0).abs() < 0.03, "{:?}", lens.uv.unwrap().period);
        assert!(
            period_ratio(&pinhole).is_none_or(|r| (r - 1.0).abs() > 0.03),
            "{:?}",
            pinhole.uv.as_ref().unwrap().period
        );
        assert!(
            pinhole.uv.as_ref().unwrap().period.is_none()
                || strength(&pinhole) + 0.1 < strength(&lens),
            "{} vs {}",
            strength(&pinhole),
            strength(&lens)
        );
        // A quad on the photo: its corners where the lens put them.
        let (_, at) = run(LensChoice::Given(lambda), UserPlane::Normal(n));
        let a = 2.0 * cell;
        let lens_of = crate::lens::Lens::new(lambda, w, h);
        let corners = [(0.0, -a), (2.0 * a, -a), (2.0 * a, a), (0.0, a)].map(|(s, t)| {
            let [x, y] = pixel_of(at(s, t), w, h, f);
            let d = lens_of.distort(glam::Vec2::new(x + 0.5, y + 0.5)).unwrap();
            [d.x - 0.5, d.y - 0.5]
        });
        let quad = UserPlane::Quad(crate::quad::Quad(corners));
        let angle = |d: &Diagnostics| {
            let used = d.uv.as_ref().unwrap().user_plane.as_ref().unwrap();
            Vec3::from(used.normal).angle_between(n).to_degrees()
        };
        let (through, _) = run(LensChoice::Given(lambda), quad);
        let (without, _) = run(LensChoice::Given(0.0), quad);
        assert!(angle(&through) < 1.0, "{}", angle(&through));
        assert!(angle(&without) > 2.0, "{}", angle(&without));
        assert_eq!(
            through.uv.unwrap().user_plane.unwrap().quad,
            Some(corners),
            "the quad is reported as given"
        );
    }

    /// A head-on photo of a chessboard whose predicted normals say a floor
    /// seen at 60°: `UserPlane::FRONT` rectifies it as the plane it is
    /// (square periods); a normal facing away is refused with a clear error.
    #[test]
    fn the_front_plane_rectifies_a_head_on_photo() {
        let (w, h, f) = (96, 72, 90.0f32);
        let wrong = Vec3::new(0.0, 60f32.to_radians().sin(), 60f32.to_radians().cos());
        let (p, _) = chessboard_photo(w, h, f, (Vec3::Z, 0.0), 0.3, wrong);
        let pick = [48, 36];
        let pm = p.pick_mask(pick, &MaskOptions::default()).unwrap();
        let inpainter = picker_inpaint::DiffusionInpainter::default();
        let run = |plane| {
            let opts = Options {
                plane: Some(plane),
                ..test_options(&inpainter, UvChoice::Auto)
            };
            extract(&p, "board", Some(pick), &pm, &opts)
        };
        let d = run(UserPlane::FRONT).unwrap().1;
        let r = period_ratio(&d).expect("the board's period");
        assert!((r - 1.0).abs() < 0.05, "periods {:?}", d.uv.unwrap().period);
        let e = run(UserPlane::Normal(-Vec3::Z)).unwrap_err().to_string();
        assert!(
            e.contains("the given plane is seen edge-on or from behind"),
            "{e}"
        );
        let e = run(UserPlane::Normal(Vec3::new(0.0, 0.0, 2.0)))
            .unwrap_err()
            .to_string();
        assert!(e.contains("not a unit vector"), "{e}");
        let bad = crate::quad::Quad([[0.0, 0.0], [90.0, 0.0], [200.0, 60.0], [0.0, 60.0]]);
        let e = run(UserPlane::Quad(bad)).unwrap_err().to_string();
        assert!(e.contains("corner 3") && e.contains("outside"), "{e}");
    }

    /// The extraction of `pm` in `p` (diffusion inpainting, seed 1,
    /// tileable) with `uv`, `size`, `fov_deg`, `fold_period` and
    /// `fill_from_mask`: the share of its texture's texels darker than 0.4
    /// (linear red) and the diagnostics.
    fn dark_share(
        p: &Prepared,
        pm: &PickMask,
        uv: UvChoice,
        size: Option<usize>,
        fov_deg: Option<f32>,
        fold_period: bool,
        fill_from_mask: bool,
    ) -> (f64, Diagnostics) {
        let inpainter = picker_inpaint::DiffusionInpainter::default();
        let opts = Options {
            size,
            fov_deg,
            fold_period,
            fill_from_mask,
            ..test_options(&inpainter, uv)
        };
        let (m, diag) = extract(p, "board", Some([4, 4]), pm, &opts).unwrap();
        let t = m.texture.expect("textured").texture;
        let n = t.width * t.height;
        let dark = (0..n).filter(|&i| t.rgb(i).x < 0.4).count() as f64 / n as f64;
        (dark, diag)
    }

    /// The networks' UV mode's counterpart of the folded chessboard: wrapped
    /// UVs whose square (64 pixels) holds 4 × 4 periods of a chessboard of
    /// 8-pixel squares; the mask is the board, its surest part the white
    /// squares, with or without the black ones of the top-left quarter (with
    /// them it shows the period; without, the repeats are found with the
    /// rest of the mask). The square repeats, and the black squares the
    /// surest part did not show are filled from the rest of the mask; without
    /// the fill they are left to the inpainter, which paints them white.
    #[test]
    fn repeating_uvs_take_the_unseen_squares_from_the_rest_of_the_mask() {
        let (h, w) = (96, 128);
        let white = |i: usize| ((i % w) / 8 + (i / w) / 8).is_multiple_of(2);
        let mut p = frontal_plane(w, h, &|i| if white(i) { 0.9 } else { 0.15 });
        let uv = |c: usize, i: usize| match c {
            0 => ((i % w) as f32 + 0.5) / 64.0 % 1.0,
            1 => ((i / w) as f32 + 0.5) / 64.0 % 1.0,
            _ => 1.0,
        };
        p.inputs.elements.uv = Some(
            Image::new(
                3,
                h,
                w,
                (0..3 * h * w)
                    .map(|k| uv(k / (h * w), k % (h * w)))
                    .collect(),
            )
            .unwrap(),
        );
        // The surest part shows the period (black squares in its top-left
        // quarter), or does not (white squares only: the repeats are then
        // found with the rest of the mask).
        for quarter in [true, false] {
            let pm = whole_mask(w, h, &|i| white(i) || (quarter && i % w < 32 && i / w < 32));
            let run = |fill| dark_share(&p, &pm, UvChoice::Net, Some(64), None, true, fill);
            let (dark, diag) = run(true);
            assert!(
                diag.uv.as_ref().unwrap().repeats.is_some(),
                "quarter {quarter}: the square repeats"
            );
            let filled = diag.filled_from_mask.expect("filled from the mask");
            assert!(filled > 0.2, "quarter {quarter}: filled {filled}");
            assert!(
                (0.35..0.6).contains(&dark),
                "quarter {quarter}: dark share {dark}"
            );
            let (dark_without, diag) = run(false);
            assert!(diag.filled_from_mask.is_none());
            assert_eq!(diag.uv.as_ref().unwrap().repeats.is_some(), quarter);
            assert!(
                dark_without < dark - 0.2,
                "quarter {quarter}: dark share without the fill {dark_without}"
            );
        }
    }

    /// A thin diagonal strip of a ramp (a table seen along its length; no
    /// axis-aligned square is mostly covered by it, so the square framed is
    /// the best covered, `plane::Framing::Covered`): no wrap edge has both
    /// sides observed, so the observed texels cannot tell the seam; the first inpainting shows it (ratio ~20), and the square is
    /// inpainted again with the band cleared, which tiles (ratio ~1).
    #[test]
    fn a_strip_whose_edges_were_not_both_observed_gets_a_second_look() {
        let (h, w) = (96, 96);
        let p = frontal_plane(w, h, &|i| {
            let (x, y) = ((i % w) as f32, (i / w) as f32);
            let n =
                ((i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 40) as f32 / (1u64 << 24) as f32;
            0.1 + 0.8 * (x + y) / (w + h) as f32 + 0.01 * n
        });
        let strip = |i: usize| ((i % w) as i64 - (i / w) as i64).abs() < 6;
        let pm = mask_of(w, h, &strip, &strip);
        let run = |heal_seams| plane_crop(&p, &pm, [48, 48], heal_seams);
        let (kept, kept_diag) = run(false);
        let (healed, diag) = run(true);
        assert!(kept_diag.seam_band.is_none());
        // Neither axis could be cut (a strip: no surroundings on either).
        let seam_cut = diag.seam_cut.expect("looked for");
        assert!(seam_cut.columns.is_none() && seam_cut.rows.is_none());
        let first = diag.seam_band.expect("a second look");
        let (a, b) = (healed.texture.unwrap().seam, kept.texture.unwrap().seam);
        // The kept texture's (its square reprojected alone, not within its
        // surroundings: the texels at its edges differ slightly).
        assert!(
            (first - b.ratio).abs() < 0.01 * b.ratio,
            "the first look is the kept texture: {first} {b:?}"
        );
        assert!(b.ratio > 5.0 && a.ratio < 2.0, "{b:?} -> {a:?}");
    }

    /// A frontal chessboard (squares of 8 pixels, sRGB 0.9 and 0.15) whose
    /// mask is the whole board but whose surest part is the white squares
    /// only, as an embedding that follows the squares makes it: with the
    /// fold and the fill from the rest of the mask the texture holds both
    /// colours; without the fill the black squares are
    /// holes that the inpainter fills from the white ones.
    #[test]
    fn a_folded_chessboard_takes_its_black_squares_from_the_rest_of_the_mask() {
        let (h, w) = (96, 128);
        let white = |i: usize| ((i % w) / 8 + (i / w) / 8).is_multiple_of(2);
        let p = frontal_plane(w, h, &|i| if white(i) { 0.9 } else { 0.15 });
        let pm = whole_mask(w, h, &white);
        let run = |fold, fill| dark_share(&p, &pm, UvChoice::Plane, None, Some(60.0), fold, fill);
        let (dark, diag) = run(true, true);
        assert!(
            diag.uv.as_ref().unwrap().period.is_some(),
            "the board folds"
        );
        let filled = diag.filled_from_mask.expect("filled from the mask");
        assert!((0.25..0.6).contains(&filled), "filled {filled}");
        // The white squares' pixels spread a texel into the black squares
        // (the splat's tent), so those are a little smaller than half.
        assert!((0.25..0.6).contains(&dark), "dark share {dark}");
        let (dark, diag) = run(true, false);
        assert!(diag.filled_from_mask.is_none());
        assert!(dark < 0.1, "dark share without the fill {dark}");
        // No fold: no fill (the rest of a mask is only trusted in repeats).
        let (_, diag) = run(false, true);
        assert!(diag.uv.as_ref().unwrap().period.is_none());
        assert!(diag.filled_from_mask.is_none());
    }

    /// A frontal chessboard whose surest part is the white squares and the
    /// black squares of one of the two places a black square has in its
    /// 2 × 2-square tile (the rest of the mask holding the others): the
    /// repeat is centred (a shift of one square along both axes repeats
    /// it), found with the rest of the mask, and the fold then takes the
    /// second place's squares from the surest pixels too, instead of from
    /// the rest; `fold_centring: false` keeps the plain fold. A board whose
    /// black squares alternate between two darks is not centred, and keeps
    /// both darks.
    #[test]
    fn a_centred_fold_takes_both_places_from_the_surest_pixels() {
        let (h, w) = (96, 128);
        let (i, j) = (|k: usize| (k % w) / 8, |k: usize| (k / w) / 8);
        let white = move |k: usize| (i(k) + j(k)).is_multiple_of(2);
        let first_place = move |k: usize| !white(k) && i(k).is_multiple_of(2);
        let inpainter = picker_inpaint::DiffusionInpainter::default();
        let run = |p: &Prepared, centring: bool| {
            let pm = whole_mask(w, h, &|k| white(k) || first_place(k));
            let opts = Options {
                fov_deg: Some(60.0),
                fold_centring: centring,
                ..test_options(&inpainter, UvChoice::Plane)
            };
            let (m, d) = extract(p, "board", Some([4, 4]), &pm, &opts).unwrap();
            (m.texture.expect("textured").texture, d)
        };
        let p = frontal_plane(w, h, &|k| if white(k) { 0.9 } else { 0.15 });
        let (t, d) = run(&p, true);
        let fold = d.uv.as_ref().unwrap().period.expect("the board folds");
        assert_eq!(fold.periods_per_tile, [1, 1], "{fold:?}");
        let c = fold.centred.expect("a centred repeat");
        assert!(c > 0.9, "{fold:?}");
        let filled = d.filled_from_mask.expect("the rest of the mask looked at");
        // (Under a tenth: a row of texels along the squares' edges, which
        // the rest of the mask shows ten times as much as the surest part.)
        assert!(filled < 0.1, "filled {filled}");
        let n = t.width * t.height;
        let dark = (0..n).filter(|&k| t.rgb(k).x < 0.4).count() as f64 / n as f64;
        assert!((0.3..0.6).contains(&dark), "dark share {dark}");
        let (t0, d0) = run(&p, false);
        let fold0 = d0.uv.as_ref().unwrap().period.expect("the board folds");
        assert_eq!(fold0.centred, None);
        let filled0 = d0.filled_from_mask.expect("filled from the mask");
        assert!(filled0 > 0.1, "filled {filled0}");
        let dark0 = (0..n).filter(|&k| t0.rgb(k).x < 0.4).count() as f64 / n as f64;
        assert!((0.3..0.6).contains(&dark0), "dark share {dark0}");

        // Two darks: the second place's squares are 0.45 (sRGB).
        let p = frontal_plane(w, h, &|k| {
            if white(k) {
                0.9
            } else if first_place(k) {
                0.15
            } else {
                0.45
            }
        });
        let (t, d) = run(&p, true);
        let fold = d.uv.as_ref().unwrap().period.expect("the board folds");
        assert_eq!(fold.centred, None, "{fold:?}");
        // Both darks in the texture: texels near 0.15 and near 0.45 (sRGB),
        // linear 0.02 and 0.17.
        let lin = |v: f32| picker_render::io::srgb_decode(v);
        let near = |v: f32| {
            (0..n)
                .filter(|&k| (t.rgb(k).x - lin(v)).abs() < 0.03)
                .count()
        };
        assert!(
            near(0.15) > n / 10 && near(0.45) > n / 10,
            "{} {}",
            near(0.15),
            near(0.45)
        );
    }

    /// A 35 mm-equivalent focal length from the photo's EXIF sets the plane
    /// mode's focal length (`f35 / 43.27` of the diagonal) unless `--fov`
    /// does; the conversion matches a 36 × 24 frame's: 36 mm at the 35 mm
    /// equivalent of 36 mm is the width.
    #[test]
    fn the_exif_focal_length_is_used_for_the_plane() {
        assert!((focal_from_35mm(36.0, 3600, 2400) - 3600.0).abs() < 0.01);
        // A 4032 × 3024 phone photo at 26 mm: 26 / 43.27 of its 5040-pixel diagonal.
        assert!((focal_from_35mm(26.0, 4032, 3024) - 3028.66).abs() < 0.1);
        let (w, h) = (64, 48);
        let mut p = frontal_plane(w, h, &|i| if (i % w / 4) % 2 == 0 { 0.8 } else { 0.3 });
        let pm = p.pick_mask([10, 10], &MaskOptions::default()).unwrap();
        let inpainter = picker_inpaint::DiffusionInpainter::default();
        let opts = test_options(&inpainter, UvChoice::Plane);
        let uv = |p: &Prepared, opts: &Options| {
            let (_, d) = extract(p, "m", Some([10, 10]), &pm, opts).unwrap();
            let u = d.uv.unwrap();
            (u.focal_px.unwrap(), u.focal_source.unwrap())
        };
        assert_ne!(uv(&p, &opts).1, "exif");
        p.focal_35mm = Some(26.0);
        let (f, src) = uv(&p, &opts);
        assert_eq!(src, "exif");
        assert!((f - focal_from_35mm(26.0, w, h)).abs() < 1e-3, "{f}");
        let fov = Options {
            fov_deg: Some(50.0),
            ..test_options(&inpainter, UvChoice::Plane)
        };
        assert_eq!(uv(&p, &fov).1, "fov");
        // A focal length of no length is ignored.
        p.focal_35mm = Some(f32::NAN);
        assert_ne!(uv(&p, &opts).1, "exif");
    }

    /// A mask given at the photo's resolution (twice the working one) is
    /// the material's mask pixel for pixel, though the segmentation would
    /// have taken the whole photo; its working mask holds the working pixels
    /// at least half covered; a pick outside it, a mask of another size and
    /// an empty one are refused.
    #[test]
    fn a_given_mask_is_the_material_at_the_photos_resolution() {
        let (w, h, fw, fh) = (32usize, 24usize, 64usize, 48usize);
        let photo = Image::new(
            3,
            fh,
            fw,
            (0..3 * fw * fh)
                .map(|k| if (k % fw / 4) % 2 == 0 { 0.8 } else { 0.3 })
                .collect(),
        )
        .unwrap();
        let plane = |c: usize, v: f32| Image::new(c, h, w, vec![v; c * w * h]).unwrap();
        let z = || {
            let data = [0.0, 0.0, 1.0]
                .iter()
                .flat_map(|&v| vec![v; h * w])
                .collect();
            Image::new(3, h, w, data).unwrap()
        };
        let elements = ElementImages::new(
            plane(3, 0.4),
            plane(3, 0.04),
            plane(1, 0.5),
            z(),
            z(),
            Some(plane(3, 1.0)),
        )
        .unwrap();
        let p = Prepared::new(Inputs {
            photo,
            elements,
            segmentation: plane(3, 0.5),
            embedding: None,
            segmentation_estimated: false,
            albedo_estimated: false,
            envmap: None,
            opaque: None,
            disagreement: None,
        })
        .unwrap();
        let disc = Mask {
            width: fw,
            height: fh,
            data: (0..fw * fh)
                .map(|i| {
                    let (x, y) = ((i % fw) as f32 - 40.0, (i / fw) as f32 - 20.0);
                    x * x + y * y <= 225.0
                })
                .collect(),
        };
        let pm = p.given_mask(disc.clone()).unwrap();
        assert!(pm.tolerance.is_nan() && pm.photo.as_ref() == Some(&disc));
        assert_eq!(pm.sure, pm.mask.data);
        for k in 0..w * h {
            let (x, y) = (k % w, k / w);
            let hits = (0..4)
                .filter(|&j| disc.data[(2 * y + j / 2) * fw + 2 * x + j % 2])
                .count();
            assert_eq!(
                pm.mask.data[k],
                hits >= 2,
                "working pixel ({x}, {y}): {hits}"
            );
        }
        let pick = disc.central_pixel().unwrap();
        assert_eq!(pick, [40, 20]);
        let inpainter = picker_inpaint::DiffusionInpainter::default();
        let opts = test_options(&inpainter, UvChoice::Plane);
        let pick = Some([40, 20]);
        let (m, d) = extract(&p, "disc", pick, &pm, &opts).unwrap();
        assert!(d.mask_given && d.tolerance.is_nan());
        let got: Vec<bool> = m.mask.data.iter().map(|&v| v > 0.5).collect();
        assert_eq!(got, disc.data);
        assert!((m.area_fraction - disc.fraction()).abs() < 1e-9);
        // The segmentation's own mask at that pick is the whole photo.
        let seg = p.pick_mask([40, 20], &MaskOptions::default()).unwrap();
        assert_eq!(seg.mask.count(), w * h);
        let (_, d) = extract(&p, "all", pick, &seg, &opts).unwrap();
        assert!(!d.mask_given);

        let e = extract(&p, "disc", Some([2, 2]), &pm, &opts).unwrap_err();
        assert!(e.to_string().contains("outside the given mask"), "{e}");
        let small = Mask {
            width: w,
            height: h,
            data: vec![true; w * h],
        };
        let e = p.given_mask(small.clone()).unwrap_err().to_string();
        assert!(e.contains("32x24 but the photo is 64x48"), "{e}");
        let empty = Mask {
            width: fw,
            height: fh,
            data: vec![false; fw * fh],
        };
        assert!(p
            .given_mask(empty)
            .unwrap_err()
            .to_string()
            .contains("no pixels"));
        // A pick mask whose (public) photo mask was swapped for one that does
        // not fit is refused by extract.
        let bad = PickMask {
            photo: Some(small),
            ..pm.clone()
        };
        let e = extract(&p, "disc", None, &bad, &opts)
            .unwrap_err()
            .to_string();
        assert!(e.contains("given mask is 32x24"), "{e}");
    }

    /// A greyscale photo gives a grey material and grey lighting whatever
    /// colour the networks' albedo and environment map have; one coloured
    /// pixel makes it a colour photo again.
    #[test]
    fn a_greyscale_photo_gives_grey_colours() {
        let (h, w) = (24, 32);
        let mut rng = picker_tensor::Rng::new(8);
        let grey = rng.uniform_vec(h * w, 0.3, 0.7);
        let photo = Image::new(3, h, w, [grey.clone(), grey.clone(), grey].concat()).unwrap();
        let env = EnvMap::uniform(8, 4, Vec3::new(1.0, 0.5, 0.25));
        let inputs = Inputs {
            photo,
            elements: flat_elements([0.0, 0.0, 1.0], None),
            segmentation: flat(3, &[0.2, 0.5, 0.7]),
            embedding: None,
            segmentation_estimated: false,
            albedo_estimated: false,
            envmap: Some(env),
            opaque: None,
            disagreement: None,
        };
        let inpainter = picker_inpaint::DiffusionInpainter::default();
        let opts = Options {
            max_size: 64,
            ..test_options(&inpainter, UvChoice::Auto)
        };
        let p = Prepared::new(inputs.clone()).unwrap();
        assert!(p.greyscale);
        let y = luminance(Vec3::new(0.5, 0.4, 0.3));
        let e = p.inputs.envmap.as_ref().unwrap().get(1, 1);
        assert!(
            (e - Vec3::splat(luminance(Vec3::new(1.0, 0.5, 0.25))))
                .abs()
                .max_element()
                < 1e-6
        );
        let pm = p.pick_mask([16, 12], &MaskOptions::default()).unwrap();
        let (m, diag) = extract(&p, "m", Some([16, 12]), &pm, &opts).unwrap();
        assert!(diag.greyscale_photo && !m.textured);
        for c in m.params.diffuse {
            assert!((c - y).abs() < 1e-3, "{:?} against {y}", m.params.diffuse);
        }
        // One pixel with colour: the networks' albedo colour is kept.
        let mut coloured = inputs;
        coloured.photo.data[5] += 0.01;
        let p = Prepared::new(coloured).unwrap();
        assert!(!p.greyscale);
        let pm = p.pick_mask([16, 12], &MaskOptions::default()).unwrap();
        let (m, diag) = extract(&p, "m", Some([16, 12]), &pm, &opts).unwrap();
        assert!(!diag.greyscale_photo);
        for (c, want) in m.params.diffuse.iter().zip([0.5, 0.4, 0.3]) {
            assert!((c - want).abs() < 1e-3, "{:?}", m.params.diffuse);
        }
    }

    #[test]
    fn parallel_preview_matches_reference() {
        let mut rng = picker_tensor::Rng::new(10);
        let env = EnvMap::from_image(
            &Image::new(3, 8, 16, rng.uniform_vec(3 * 8 * 16, 0.0, 2.0)).unwrap(),
        )
        .unwrap();
        let tex = Image::new(3, 8, 8, rng.uniform_vec(3 * 64, 0.0, 1.0)).unwrap();
        let mut m = with_texture(plain_material([0.5, 0.3, 0.2], 0.04), &tex);
        let bits = |v: &Image| v.data.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        for size in [1, 2, 17, 64] {
            assert_eq!(
                bits(&preview_sphere(&m, &env, size, 2.0)),
                bits(&preview_sphere_reference(&m, &env, size, 2.0)),
                "{size}"
            );
        }
        m.texture = None;
        assert_eq!(
            bits(&preview_sphere(&m, &env, 33, 2.0)),
            bits(&preview_sphere_reference(&m, &env, 33, 2.0))
        );
    }

    #[test]
    fn fused_linear_and_luma_match() {
        let mut rng = picker_tensor::Rng::new(8);
        for (w, h) in [(1, 1), (7, 3), (33, 17)] {
            let n = w * h;
            let data: Vec<f32> = (0..3 * n)
                .map(|i| match i % 3 {
                    0 => rng.range(0, 255) as f32 / 255.0,
                    1 => rng.uniform(-0.2, 1.2),
                    _ => rng.range(0, 65535) as f32 / 65535.0,
                })
                .collect();
            let photo = Image::new(3, h, w, data).unwrap();
            let (lin, luma) = linear_and_luma(&photo);
            let want = photo.map(picker_render::io::srgb_decode);
            let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&lin.data), bits(&want.data), "{w}x{h}");
            assert_eq!((lin.channels, lin.height, lin.width), (3, h, w));
            assert_eq!(bits(&luma), bits(&crate::guided::luma(&photo)), "{w}x{h}");
        }
    }

    #[test]
    fn srgb_table_matches_the_function() {
        let lut = SrgbDecodeTable::new();
        let mut rng = picker_tensor::Rng::new(4);
        let mut values: Vec<f32> = (0..=255).map(|k| k as f32 / 255.0).collect();
        values.extend((0..=65535).map(|k| k as f32 / 65535.0));
        values.extend(rng.uniform_vec(10_000, -0.5, 1.5));
        values.extend([f32::NAN, f32::INFINITY, -0.0, 1.0 + f32::EPSILON, -1e-30]);
        for v in values {
            assert_eq!(
                lut.decode(v).to_bits(),
                picker_render::io::srgb_decode(v).to_bits(),
                "{v}"
            );
        }
    }
}
