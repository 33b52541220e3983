//! `picker-inpaint`: filling the unobserved texels of a reprojected texture
//! (see `docs/contract-extract.md`).
//!
//! A tour:
//! - [`Inpainter`]: the one interface. `inpaint(image, known, opts)` returns an
//!   image of the same shape in which every known texel is kept bit-exactly and
//!   every unknown one is filled; [`InpaintOptions::toroidal`] treats the image
//!   as periodic so the result tiles seamlessly.
//! - [`PatchMatchInpainter`]: multi-scale exemplar-based completion (Wexler,
//!   Shechtman & Irani 2007, "Space-time completion of video", eq. 1–3) with
//!   the nearest-neighbour field found by PatchMatch (Barnes et al. 2009) and
//!   weighted patch voting. Deterministic for a seed, whatever the number of
//!   rayon threads.
//! - [`DiffusionInpainter`]: the baseline, a harmonic (Laplace) fill solved
//!   coarse-to-fine (pull-push initialisation + Gauss–Seidel smoothing).
//! - [`metrics`]: [`psnr`] and [`colour_stats_distance`] to compare results;
//!   [`seam_score`] measures how visible the wrap edges are.
//!
//! ```
//! use picker_inpaint::{DiffusionInpainter, InpaintOptions, Inpainter, PatchMatchInpainter};
//! use picker_render::io::Image;
//!
//! // A 32×32 grey texture of vertical stripes with a hole in the middle.
//! let (h, w) = (32, 32);
//! let data: Vec<f32> = (0..h * w).map(|i| if (i % w) % 8 < 4 { 0.2 } else { 0.8 }).collect();
//! let image = Image::new(1, h, w, data).unwrap();
//! let known: Vec<bool> = (0..h * w)
//!     .map(|i| !((12..20).contains(&(i / w)) && (12..20).contains(&(i % w))))
//!     .collect();
//! let opts = InpaintOptions::default();
//! let filled = PatchMatchInpainter::default().inpaint(&image, &known, &opts).unwrap();
//! let smooth = DiffusionInpainter::default().inpaint(&image, &known, &opts).unwrap();
//! assert_eq!(filled.data[0], image.data[0]); // known texels are kept exactly
//! let psnr_pm = picker_inpaint::psnr(&filled, &image, None);
//! let psnr_diff = picker_inpaint::psnr(&smooth, &image, None);
//! assert!(psnr_pm > psnr_diff);
//! ```

#![warn(missing_docs)]

pub mod diffusion;
pub mod error;
pub mod learned;
pub mod metrics;
pub mod patchmatch;
pub mod quilt;
pub mod seam;

pub use diffusion::DiffusionInpainter;
pub use error::{Error, Result};
pub use learned::LearnedInpainter;
pub use metrics::{colour_stats_distance, psnr};
pub use patchmatch::PatchMatchInpainter;
pub use picker_render::io::Image;
pub use quilt::{
    cut_margin, wrap_cut, AxisCut, WrapCut, CUT_MARGIN, CUT_MAX_RATIO, CUT_MIN_BOTH_KNOWN,
    LOSE_COST,
};
pub use seam::{
    clear_seam_band, clear_seam_band_axes, known_seam_ratio, known_seam_ratio_axes, make_seamless,
    periodic_component, seam_band, seam_band_axes, seam_score, SeamScore, SEAMLESS_MIN_RATIO,
    SEAM_BAND_FRACTION, SEAM_BAND_MIN_RATIO,
};

/// Options common to every [`Inpainter`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct InpaintOptions {
    /// Treat the image as periodic: texel `(−1, y)` is `(w−1, y)` and
    /// `(x, −1)` is `(x, h−1)`, so the filled result tiles seamlessly.
    pub toroidal: bool,
    /// Seed of every random choice; the same seed gives the same bytes.
    pub seed: u64,
    /// Side of the square patches of exemplar-based methods (odd, ≥ 3).
    pub patch_size: usize,
}

impl Default for InpaintOptions {
    fn default() -> Self {
        Self {
            toroidal: true,
            seed: 0,
            patch_size: 7,
        }
    }
}

/// Fills the unknown texels of a texture.
pub trait Inpainter: Send + Sync {
    /// A short name for reports (`"patchmatch"`, `"diffusion"`, …).
    fn name(&self) -> &str;

    /// Fills `image` where `known[row·w + col]` is false.
    ///
    /// Returns an image of the same shape whose known texels are exactly those
    /// of `image` (the values of unknown texels in `image` are never read).
    /// Errors: [`Error::Invalid`] for inconsistent arguments (mask length,
    /// channel count outside 1..=4, even or too small patch, empty image,
    /// non-finite known values), [`Error::NothingKnown`] when no texel is known.
    fn inpaint(&self, image: &Image, known: &[bool], opts: &InpaintOptions) -> Result<Image>;
}

/// What [`validate`] found.
pub(crate) enum Plan {
    /// Every texel is known: this is the answer.
    Done(Image),
    /// Some texels must be filled.
    Fill,
}

/// Checks the arguments of [`Inpainter::inpaint`] (shared by all inpainters).
pub(crate) fn validate(image: &Image, known: &[bool], opts: &InpaintOptions) -> Result<Plan> {
    let (c, h, w) = (image.channels, image.height, image.width);
    if !(1..=4).contains(&c) {
        return Err(Error::Invalid(format!(
            "inpainting needs 1 to 4 channels, the image has {c}"
        )));
    }
    if h == 0 || w == 0 {
        return Err(Error::Invalid(format!(
            "cannot inpaint an empty {w}x{h} image"
        )));
    }
    if image.data.len() != c * h * w {
        return Err(Error::Invalid(format!(
            "a {c}x{h}x{w} image needs {} values, it has {}",
            c * h * w,
            image.data.len()
        )));
    }
    if known.len() != h * w {
        return Err(Error::Invalid(format!(
            "the known mask has {} entries, the {w}x{h} image needs {}",
            known.len(),
            h * w
        )));
    }
    if opts.patch_size < 3 || opts.patch_size.is_multiple_of(2) {
        return Err(Error::Invalid(format!(
            "patch_size must be odd and at least 3, got {}",
            opts.patch_size
        )));
    }
    let n = h * w;
    let mut count = 0usize;
    for (i, _) in known.iter().enumerate().filter(|(_, &k)| k) {
        count += 1;
        for ch in 0..c {
            let v = image.data[ch * n + i];
            if !v.is_finite() {
                return Err(Error::Invalid(format!(
                    "known texel (row {}, col {}) channel {ch} is not finite ({v})",
                    i / w,
                    i % w
                )));
            }
        }
    }
    if count == 0 {
        return Err(Error::NothingKnown {
            width: w,
            height: h,
        });
    }
    if count == n {
        return Ok(Plan::Done(image.clone()));
    }
    Ok(Plan::Fill)
}

/// A random stream derived from a seed and a path of integers (level,
/// iteration, band, …), so that parallel jobs draw independent, reproducible
/// numbers.
pub(crate) fn stream(seed: u64, parts: &[u64]) -> picker_tensor::Rng {
    let mut z = seed ^ 0x5EED_1A9A_1E7C_0DE5;
    for &p in parts {
        z = z.wrapping_add(0x9E37_79B9_7F4A_7C15).wrapping_add(p);
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
    }
    picker_tensor::Rng::new(z)
}
