//! From a pick to the picked material's mask.
//!
//! The material's colour is read from the segmentation image around the pick
//! robustly: the per-channel median of the 3×3 pixels at the pick is the
//! reference, and the pick colour is the per-channel median of the pixels of
//! a 5×5 window within [`PICK_NEIGHBOUR_DISTANCE`] of that reference (so a
//! noisy pixel, or a pick next to an edge, does not decide the colour). The
//! spread σ of those pixels around the pick colour (1.4826·MAD) sets the
//! pick's own tolerance `τ₀ = clamp(τ_min + 3σ, τ_min, τ_max)`. Unless a
//! tolerance is given, the mask then follows the segmentation as it is
//! ([`auto_tolerance`]): `τ` rises to the first valley of the histogram of
//! colour distances to the pick colour (a soft segmentation spreads one
//! material's colours wider than σ says: shading leaks into an undertrained
//! network's output) and falls to the first empty band of distances (two
//! clean, close colours stay apart). A pixel belongs to the material when it
//! has a surface and its segmentation colour is within `τ` (Euclidean, RGB
//! in `[0, 1]`) of the pick colour, and, where `τ` grew beyond `τ₀`, its
//! region holds a pixel within [`CORE_SHARE`]`·τ₀` ([`hysteresis`]: a
//! separate object of a merely similar colour stays out). Without
//! `connected`, every such region counts (a floor split by a table is one
//! material) and specks smaller than [`MIN_SPECK_FRACTION`] of the image are
//! dropped; with `connected`, only the 8-connected region at the pick (or
//! nearest to it) is kept. With the automatic tolerance, a leak guard
//! ([`watershed`]) then keeps only the pixels that the pick's front reaches
//! first when the pick's surest pixels and the pixels of clearly other
//! colours ([`LEAK_GUARD_OTHER`]) flood the segmentation's gradient
//! magnitude ([`gradient_magnitude`]): where a soft segmentation's colours
//! run from the picked material into a neighbour's without a valley between
//! them, the mask stops at the edge between the two instead of taking the
//! neighbour in. The pixels within `τ₀` are the mask's surest part
//! ([`PickMask::sure`]), which the texture is taken from.

use picker_render::io::Image;

use crate::{Error, Result};

/// Segmentation-colour distance under which a window pixel counts as the
/// pick's material when estimating the pick colour.
pub const PICK_NEIGHBOUR_DISTANCE: f32 = 0.1;
/// Smallest tolerance `τ_min`.
pub const TOLERANCE_MIN: f32 = 0.02;
/// Largest automatic tolerance `τ_max`.
pub const TOLERANCE_MAX: f32 = 0.12;
/// Regions of the material smaller than this fraction of the image (and at
/// least 1 pixel) are dropped as specks, except the one at the pick.
pub const MIN_SPECK_FRACTION: f64 = 2e-4;

/// A binary mask over a `width × height` grid.
#[derive(Clone, Debug, PartialEq)]
pub struct Mask {
    /// Columns.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// `true` inside, row-major.
    pub data: Vec<bool>,
}

impl Mask {
    /// Pixels inside.
    pub fn count(&self) -> usize {
        self.data.iter().filter(|&&b| b).count()
    }
    /// Fraction of pixels inside.
    pub fn fraction(&self) -> f64 {
        self.count() as f64 / (self.width * self.height).max(1) as f64
    }
    /// As a 1-channel image (1 inside, 0 outside).
    pub fn to_image(&self) -> Image {
        Image {
            channels: 1,
            height: self.height,
            width: self.width,
            // In parallel: a 12-MP mask's 48 MB image took ~20 ms on one
            // thread, most of it the first touch of its pages.
            data: {
                use rayon::prelude::*;
                self.data.par_iter().map(|&b| b as u8 as f32).collect()
            },
        }
    }
    /// The mask resampled to `w × h` by nearest neighbour: each output
    /// pixel takes the input pixel under its centre (an empty input gives an
    /// empty output).
    pub fn scaled_to(&self, w: usize, h: usize) -> Mask {
        let (sw, sh) = (self.width, self.height);
        let at = |i: usize, from: usize, to: usize| {
            (((i as f64 + 0.5) * from as f64 / to as f64) as usize).min(from.saturating_sub(1))
        };
        let data = if sw == 0 || sh == 0 {
            vec![false; w * h]
        } else {
            let cols: Vec<usize> = (0..w).map(|x| at(x, sw, w)).collect();
            (0..w * h)
                .map(|i| self.data[at(i / w, sh, h) * sw + cols[i % w]])
                .collect()
        };
        Mask {
            width: w,
            height: h,
            data,
        }
    }
    /// The pixel of the mask nearest its centroid (ties: the first in row
    /// order), `[x, y]`; `None` for an empty mask. Inside the mask even when
    /// the centroid is not (a ring, an L).
    pub fn central_pixel(&self) -> Option<[usize; 2]> {
        let w = self.width.max(1);
        let (mut sx, mut sy, mut n) = (0f64, 0f64, 0usize);
        for (i, _) in self.data.iter().enumerate().filter(|(_, &b)| b) {
            sx += (i % w) as f64;
            sy += (i / w) as f64;
            n += 1;
        }
        if n == 0 {
            return None;
        }
        let (cx, cy) = (sx / n as f64, sy / n as f64);
        let d = |i: usize| ((i % w) as f64 - cx).powi(2) + ((i / w) as f64 - cy).powi(2);
        let i = self
            .data
            .iter()
            .enumerate()
            .filter(|(_, &b)| b)
            .map(|(i, _)| i)
            .min_by(|&a, &b| d(a).total_cmp(&d(b)).then(a.cmp(&b)))?;
        Some([i % w, i / w])
    }
    /// The mask eroded by one pixel (8-neighbourhood; the image border does not erode).
    pub fn eroded(&self) -> Mask {
        use rayon::prelude::*;
        let (w, h) = (self.width, self.height);
        let mut out = self.data.clone();
        // Rows in parallel (each output pixel depends on the input only),
        // the three input rows as slices: a pixel stays when it and its
        // neighbours inside the image are in (`tests::eroded_matches_reference`).
        out.par_chunks_mut(w.max(1))
            .enumerate()
            .for_each(|(y, row)| {
                let at = |yy: usize| &self.data[yy * w..(yy + 1) * w];
                let mid = at(y);
                let up = (y > 0).then(|| at(y - 1));
                let down = (y + 1 < h).then(|| at(y + 1));
                for (x, o) in row.iter_mut().enumerate() {
                    if !mid[x] {
                        continue;
                    }
                    let (l, r) = (x.saturating_sub(1), (x + 1).min(w - 1));
                    let all = |s: &[bool]| s[l] && s[x] && s[r];
                    *o = all(mid) && up.is_none_or(all) && down.is_none_or(all);
                }
            });
        Mask {
            width: w,
            height: h,
            data: out,
        }
    }
}

/// How to turn a pick into a mask.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct MaskOptions {
    /// Keep only the connected region at the pick.
    pub connected: bool,
    /// Fixed tolerance `τ` instead of the automatic one.
    pub tolerance: Option<f32>,
    /// Keep only the picked colour of a two-colour pattern (a chessboard's
    /// black squares) rather than the whole pattern ([`crate::pattern`]).
    pub no_pattern: bool,
    /// Keep the regions of an estimated segmentation's mask that the photo
    /// sets apart ([`crate::split`]) instead of leaving them out.
    pub no_split: bool,
}

/// The pick's material at the segmentation's resolution.
#[derive(Clone, Debug)]
pub struct PickMask {
    /// The mask.
    pub mask: Mask,
    /// The material's colour in the image the mask was cut from: its
    /// segmentation colour, or its embedding in mask units
    /// ([`embedding_mask_space`]; the pipeline reports the segmentation
    /// colour then, [`crate::Prepared::segmentation_colour`]).
    pub colour: [f32; 3],
    /// The tolerance used.
    pub tolerance: f32,
    /// The mask at the photo's resolution when it was given rather than cut
    /// from the segmentation (a user's mask: [`crate::Prepared::given_mask`]):
    /// used as it is, not refined from `mask` to the photo's edges.
    pub photo: Option<Mask>,
    /// The pixels of the mask within the pick's own colour spread `τ₀`
    /// ([`auto_tolerance`]): where the valley grew the mask, its surest
    /// part, from which the texture is taken (a pixel of another material
    /// that the growth took in would land in the texture). The whole mask
    /// when it did not grow or the tolerance was given.
    pub sure: Vec<bool>,
    /// The two-colour pattern check ([`crate::pattern`]), when it ran: an
    /// automatic mask's companion and whether it joined the mask.
    pub pattern: Option<crate::pattern::PatternCheck>,
    /// The photo's split of the mask ([`crate::split`]), when it ran.
    pub split: Option<crate::split::SplitCheck>,
}

/// The median of `v` (its upper middle for an even length; 0 when empty),
/// reordering it.
pub(crate) fn median(v: &mut [f32]) -> f32 {
    if v.is_empty() {
        return 0.0;
    }
    let mid = v.len() / 2;
    v.select_nth_unstable_by(mid, |a, b| a.total_cmp(b));
    v[mid]
}

/// Euclidean distance of two colours.
pub(crate) fn dist(a: [f32; 3], b: [f32; 3]) -> f32 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// The first three channels of pixel `i`.
pub(crate) fn colour(seg: &Image, i: usize) -> [f32; 3] {
    [seg.at(0, i), seg.at(1, i), seg.at(2, i)]
}

/// The robust segmentation colour at pixel `(x, y)` and its noise spread σ.
/// `valid[i]`: the pixel has a surface.
pub fn pick_colour(seg: &Image, valid: &[bool], x: usize, y: usize) -> Option<([f32; 3], f32)> {
    let (w, h) = (seg.width, seg.height);
    // A pick outside the image, or inputs that disagree, have no colour.
    if seg.channels < 3 || seg.data.len() != seg.channels * w * h || valid.len() != w * h {
        return None;
    }
    if x >= w || y >= h {
        return None;
    }
    let window = |r: usize| -> Vec<usize> {
        let mut v = Vec::new();
        for yy in y.saturating_sub(r)..(y + r + 1).min(h) {
            for xx in x.saturating_sub(r)..(x + r + 1).min(w) {
                if valid[yy * w + xx] {
                    v.push(yy * w + xx);
                }
            }
        }
        v
    };
    let near = window(1);
    if !valid[y * w + x] && near.is_empty() {
        return None;
    }
    let centre_set = if valid[y * w + x] { near.clone() } else { near };
    let mut reference = [0.0; 3];
    for (c, r) in reference.iter_mut().enumerate() {
        let mut v: Vec<f32> = centre_set.iter().map(|&i| seg.at(c, i)).collect();
        *r = median(&mut v);
    }
    // The centre pixel itself decides between two materials meeting at the pick.
    if valid[y * w + x] && dist(colour(seg, y * w + x), reference) > PICK_NEIGHBOUR_DISTANCE {
        reference = colour(seg, y * w + x);
    }
    let members: Vec<usize> = window(2)
        .into_iter()
        .filter(|&i| dist(colour(seg, i), reference) <= PICK_NEIGHBOUR_DISTANCE)
        .collect();
    let mut pick = [0.0; 3];
    for (c, p) in pick.iter_mut().enumerate() {
        let mut v: Vec<f32> = members.iter().map(|&i| seg.at(c, i)).collect();
        *p = median(&mut v);
    }
    let mut d: Vec<f32> = members
        .iter()
        .map(|&i| dist(colour(seg, i), pick))
        .collect();
    let sigma = 1.4826 * median(&mut d);
    Some((pick, sigma))
}

/// `τ₀ = clamp(τ_min + 3σ, τ_min, τ_max)`: the tolerance the pick's own
/// colour spread `σ` ([`pick_colour`]) asks for.
pub fn own_tolerance(sigma: f32) -> f32 {
    (TOLERANCE_MIN + 3.0 * sigma).clamp(TOLERANCE_MIN, TOLERANCE_MAX)
}

/// The automatic tolerance, from `d`, the colour distances of the valid
/// pixels to the pick colour (NaN and values beyond [`VALLEY_RANGE`] are
/// ignored by the valley), and `sigma`, the spread of the pick's own pixels:
///
/// 1. `τ₀ = clamp(τ_min + 3σ, τ_min, τ_max)`, the pick's own spread;
/// 2. raised to the first valley of the distances' histogram beyond the
///    mode the pick's material makes near 0 ([`valley_tolerance`]): a soft
///    segmentation (an undertrained or blurry network, shading that leaks
///    into it) spreads one material's colours wider than the spread around
///    the pick, and this follows them up to the dip before the next material;
/// 3. lowered to the middle of the first empty band of distances beyond the
///    pick's own spread (at least [`GAP_MIN`] wide), so two materials whose
///    segmentation colours are close but distinct (as in clean
///    segmentations) stay apart.
///
/// Returns `(τ₀, τ)`.
pub fn auto_tolerance(d: &[f32], sigma: f32) -> (f32, f32) {
    let tau0 = own_tolerance(sigma);
    let tau = valley_tolerance(d, tau0);
    let mut within: Vec<f32> = d.iter().copied().filter(|&x| x <= tau).collect();
    within.sort_by(|a, b| a.total_cmp(b));
    let own = 3.0 * sigma;
    let gap = GAP_MIN.max(sigma);
    for p in within.windows(2) {
        if p[0] >= own && p[1] - p[0] >= gap {
            return (tau0, (p[0] + p[1]) / 2.0);
        }
    }
    (tau0, tau)
}

/// Distances (RGB in `[0, 1]`) the valley search looks at: `[0, VALLEY_RANGE)`.
pub const VALLEY_RANGE: f32 = 0.5;
/// Histogram bins over [`VALLEY_RANGE`].
pub const VALLEY_BINS: usize = 100;
/// A valley is a bin whose (smoothed) count is below `VALLEY_DEPTH` times
/// the pick's mode, followed by a bin that rises above it by `1/VALLEY_DEPTH`.
///
/// With the embedded `lite` networks (`picker eval --embedded`, 40 scenes per
/// set) the valley raised the mean pick-mask IoU from 0.535 / 0.569 / 0.609
/// to 0.676 / 0.627 / 0.691 on seeds 4242 / 9191 / 5151 (0.5: 0.636 / 0.596 /
/// 0.632; 0.3: 0.618 / 0.561 / 0.633). Clean segmentations are unchanged:
/// their histogram is empty between materials.
///
/// Stop 31: with the segmentation smoothed along the photo ([`crate::smooth`])
/// its histograms have deeper valleys, and 0.5 (was 0.7) gained on every set:
/// mean IoU test split's first 100 scenes 0.720 → 0.726, procedural seeds
/// 4242 / 9191 / 6161 0.714 / 0.728 / 0.727 → 0.737 / 0.732 / 0.729, seed 5151
/// 0.764 → 0.775, 40 Blender scenes 0.621 → 0.624 (0.4: 0.727 / 0.740 / 0.727 /
/// 0.726 / 0.773 / 0.630; 0.3 and 0.85 lower); ground truth unchanged.
pub const VALLEY_DEPTH: f32 = 0.5;

/// The first valley of the histogram of the distances `d` beyond the mode
/// the pick's material makes at `[0, τ₀]`, or `τ₀` when there is none (or
/// when it lies below `τ₀`). The histogram has [`VALLEY_BINS`] bins over
/// [`VALLEY_RANGE`], smoothed by a Gaussian of one bin; from the mode, the
/// search walks outwards keeping the lowest bin seen, and stops at the
/// first bin that rises above that lowest by `1/`[`VALLEY_DEPTH`] while the
/// lowest is below [`VALLEY_DEPTH`] times the mode (or at the end of the
/// range, when the lowest is that deep). The tolerance is the centre of
/// that lowest bin.
pub fn valley_tolerance(d: &[f32], tau0: f32) -> f32 {
    const BIN: f32 = VALLEY_RANGE / VALLEY_BINS as f32;
    let mut raw = [0f64; VALLEY_BINS];
    for &x in d {
        if (0.0..VALLEY_RANGE).contains(&x) {
            raw[((x / BIN) as usize).min(VALLEY_BINS - 1)] += 1.0;
        }
    }
    // Gaussian, σ = 1 bin, radius 3, renormalised at the ends.
    let kernel: [f64; 7] = std::array::from_fn(|i| (-((i as f64 - 3.0).powi(2)) / 2.0).exp());
    let h: Vec<f64> = (0..VALLEY_BINS)
        .map(|k| {
            let (mut s, mut n) = (0.0, 0.0);
            for (j, w) in kernel.iter().enumerate() {
                if let Some(b) = (k + j).checked_sub(3).filter(|&b| b < VALLEY_BINS) {
                    s += w * raw[b];
                    n += w;
                }
            }
            s / n
        })
        .collect();
    let last_mode_bin = ((tau0.max(0.0) / BIN) as usize).min(VALLEY_BINS - 1);
    let mode = (0..=last_mode_bin).fold(0, |m, k| if h[k] > h[m] { k } else { m });
    let depth = f64::from(VALLEY_DEPTH);
    let mut lowest = mode;
    for k in mode + 1..VALLEY_BINS {
        if h[k] < h[lowest] {
            lowest = k;
        }
        if h[k] * depth > h[lowest] && h[lowest] < depth * h[mode] {
            return tau0.max((lowest as f32 + 0.5) * BIN);
        }
    }
    // No rise before the end of the range: the other materials are all
    // further away, and the lowest bin (the first empty one after a
    // material that ends) is the valley if it is deep enough.
    if h[lowest] < depth * h[mode] {
        tau0.max((lowest as f32 + 0.5) * BIN)
    } else {
        tau0
    }
}

/// A mask grown from a strict one: the 8-connected regions of `candidate`
/// that contain at least one pixel of `core` (hysteresis thresholding, as
/// Canny's edges). Pixels of `core` outside `candidate` are dropped.
///
/// # Panics
/// When `core` and `candidate` differ in length.
pub fn hysteresis(core: &[bool], candidate: &Mask) -> Mask {
    assert_eq!(
        core.len(),
        candidate.data.len(),
        "hysteresis: the core and the candidate mask differ in size"
    );
    let (label, sizes) = components(candidate);
    let mut keep = vec![false; sizes.len()];
    for (i, &l) in label.iter().enumerate() {
        if l != 0 && core[i] {
            keep[l as usize] = true;
        }
    }
    Mask {
        width: candidate.width,
        height: candidate.height,
        data: label.iter().map(|&l| l != 0 && keep[l as usize]).collect(),
    }
}

/// Share of the pick's own tolerance `τ₀` below which a pixel is certain:
/// a region grown by the valley is kept only when it holds such a pixel
/// ([`hysteresis`]), so a separate object of a merely similar colour is not
/// taken. With the embedded networks it added 0.004 / 0.010 / 0.018 to the
/// mean IoU of seeds 4242 / 9191 / 5151.
pub const CORE_SHARE: f32 = 0.5;

/// Narrowest empty band of colour distances that separates two materials.
pub const GAP_MIN: f32 = 0.004;

/// Leak guard: segmentation-colour distance (RGB in `[0, 1]`) to the pick
/// colour beyond which a pixel is certainly another material and seeds the
/// front that competes with the pick's ([`watershed`]); pixels without a
/// surface seed it too.
///
/// Measured with the embedded `lite` networks (`picker eval --embedded`,
/// materials ≥ 5% of the image), mean pick-mask IoU before → after the
/// guard (with its markers eroded, [`LEAK_GUARD_ERODE`]): test split's first
/// 100 scenes 0.659 → 0.680, procedural seeds 4242 / 9191 / 6161 0.670 /
/// 0.650 / 0.655 → 0.678 / 0.676 / 0.688, seed 5151 (photographic textures)
/// 0.712 → 0.742, and 40 Blender Cycles scenes (another renderer) 0.531 →
/// 0.596 (in a prototype, thresholds 0.15–0.25 and σ 0.7–1.5 all gained on
/// every set). With ground-truth segmentations the mean IoU stays ≥ 0.999
/// (one material of 105 at 0.967: a thin separate piece). On real photos it
/// removes the plant from a cloth's mask, a cup's rim from a table's and most
/// of a person from a chessboard's that took the whole image; a given
/// tolerance has no guard.
pub const LEAK_GUARD_OTHER: f32 = 0.2;

/// Leak guard: σ in working-resolution pixels of the Gaussian derivatives
/// whose gradient magnitude the fronts flood (a soft segmentation's edges
/// are a few pixels wide).
pub const LEAK_GUARD_SIGMA: f32 = 1.5;

/// Largest `sigma` [`gradient_magnitude`] takes (pixels).
pub const MAX_GRADIENT_SIGMA: f32 = 1e4;

/// Gradient magnitude of a multi-channel image with Gaussian derivatives of
/// scale `sigma` (pixels): per channel the derivative of a Gaussian along
/// one axis and the Gaussian along the other (kernel radius `⌈4σ⌉`, sampled
/// and normalised, borders reflected half-sample as `d c b a | a b c d`),
/// `√Σ_c (∂x² + ∂y²)`. `sigma ≤ 0` gives central differences.
///
/// # Panics
/// When `sigma` is NaN or above [`MAX_GRADIENT_SIGMA`] (its kernel would
/// not fit in memory), or `img`'s data is not `channels · width · height`.
pub fn gradient_magnitude(img: &Image, sigma: f32) -> Vec<f32> {
    assert!(
        sigma <= MAX_GRADIENT_SIGMA,
        "gradient_magnitude: sigma {sigma} must be at most {MAX_GRADIENT_SIGMA}"
    );
    assert_eq!(
        img.data.len(),
        img.channels * img.width * img.height,
        "gradient_magnitude: image data length"
    );
    let (w, h) = (img.width, img.height);
    let (smooth, deriv) = gaussian_kernels(sigma);
    let mut sum = vec![0f32; w * h];
    let mut tmp = vec![0f32; w * h];
    let mut out = vec![0f32; w * h];
    for c in 0..img.channels {
        let plane = &img.data[c * w * h..(c + 1) * w * h];
        for (along_x, across) in [(&deriv, &smooth), (&smooth, &deriv)] {
            convolve_rows(plane, w, h, along_x, &mut tmp);
            convolve_cols(&tmp, w, h, across, &mut out);
            for (s, v) in sum.iter_mut().zip(&out) {
                *s += v * v;
            }
        }
    }
    for s in &mut sum {
        *s = s.sqrt();
    }
    sum
}

/// The sampled Gaussian of scale `sigma` (normalised to sum 1) and its
/// derivative (`−i/σ²` times it), both of radius `⌈4σ⌉`, centre at index
/// `radius`; for `sigma ≤ 0`, `[0, 1, 0]` and the central difference.
fn gaussian_kernels(sigma: f32) -> (Vec<f32>, Vec<f32>) {
    if sigma <= 0.0 || !sigma.is_finite() {
        return (vec![0.0, 1.0, 0.0], vec![0.5, 0.0, -0.5]);
    }
    let r = (4.0 * sigma).ceil() as i64;
    let g: Vec<f64> = (-r..=r)
        .map(|i| (-(i as f64).powi(2) / (2.0 * f64::from(sigma).powi(2))).exp())
        .collect();
    let total: f64 = g.iter().sum();
    let smooth = g.iter().map(|v| (v / total) as f32).collect();
    // Correlation kernel of d/dx: the value at offset i weighs f(x + i), so
    // the derivative of the Gaussian, −(x − s)/σ² G(x − s), puts +i/σ².
    let deriv = (-r..=r)
        .zip(&g)
        .map(|(i, v)| (i as f64 / f64::from(sigma).powi(2) * v / total) as f32)
        .collect();
    (smooth, deriv)
}

/// Half-sample reflection of index `i` into `[0, n)` (`n ≥ 1`).
fn reflect(i: i64, n: usize) -> usize {
    let n = n as i64;
    let period = 2 * n;
    let m = i.rem_euclid(period);
    (if m < n { m } else { period - 1 - m }) as usize
}

/// `out[y][x] = Σ_k k[j]·src[y][reflect(x + j − r)]` (each row copied once
/// with its reflected borders, then a plain correlation).
fn convolve_rows(src: &[f32], w: usize, h: usize, k: &[f32], out: &mut [f32]) {
    let r = k.len() / 2;
    let mut padded = vec![0f32; w + 2 * r];
    for y in 0..h {
        let row = &src[y * w..(y + 1) * w];
        for (i, p) in padded.iter_mut().enumerate() {
            *p = row[reflect(i as i64 - r as i64, w)];
        }
        for (x, o) in out[y * w..(y + 1) * w].iter_mut().enumerate() {
            *o = k.iter().zip(&padded[x..]).map(|(kv, pv)| kv * pv).sum();
        }
    }
}

/// `out[y][x] = Σ_k k[j]·src[reflect(y + j − r)][x]`.
fn convolve_cols(src: &[f32], w: usize, h: usize, k: &[f32], out: &mut [f32]) {
    let r = (k.len() / 2) as i64;
    out.fill(0.0);
    for y in 0..h {
        let o = &mut out[y * w..(y + 1) * w];
        for (j, kv) in k.iter().enumerate() {
            let yy = reflect(y as i64 + j as i64 - r, h);
            for (ov, sv) in o.iter_mut().zip(&src[yy * w..(yy + 1) * w]) {
                *ov += kv * sv;
            }
        }
    }
}

/// Pixels by which the leak guard's markers are eroded: `⌈2σ⌉` of
/// [`LEAK_GUARD_SIGMA`], the half-width over which the relief spreads an
/// edge. A marker on the far slope of an edge it borders would start its
/// front past the ridge and flood the other side first: a dark ball's
/// blurred rim, more than 0.2 from a table's colour, took the whole table
/// from the pick's front on `stuff.jpg` until the markers were eroded.
pub const LEAK_GUARD_ERODE: usize = 3;

/// A leak guard marker set, eroded by [`LEAK_GUARD_ERODE`] pixels
/// ([`Mask::eroded`]: 8-neighbourhood, the image border does not erode).
/// A part thinner than the erosion seeds nothing (tried: seeding such parts
/// of the pick's side from their lowest relief kept thin separate pieces of
/// the picked colour, a cup's rim in a table's mask, and lost 0.002–0.016
/// mean IoU with the embedded nets; of the other side, a thin dark object's
/// seed on its blurred rim took a whole table again).
fn guard_markers(set: Vec<bool>, w: usize, h: usize) -> Vec<bool> {
    let mut m = Mask {
        width: w,
        height: h,
        data: set,
    };
    for _ in 0..LEAK_GUARD_ERODE {
        m = m.eroded();
    }
    m.data
}

/// Marker-controlled watershed (Meyer's flooding) of `relief` on a `w × h`
/// grid, 4-connected: every pixel with a non-zero `markers` label floods
/// its unlabelled neighbours, lowest relief first (ties: first queued
/// first), and each reached pixel takes the label of the pixel that reached
/// it. Returns the labels; pixels no marker reaches (none at all) stay 0.
/// Deterministic: the result depends only on the inputs.
pub fn watershed(relief: &[f32], w: usize, h: usize, markers: &[u8]) -> Vec<u8> {
    use std::cmp::Reverse;
    use std::collections::BinaryHeap;
    assert_eq!(relief.len(), w * h, "relief length");
    assert_eq!(markers.len(), w * h, "markers length");
    // Ordered key of a finite or infinite f32 (NaN sorts last).
    let key = |v: f32| -> u32 {
        let v = if v.is_nan() { f32::INFINITY } else { v };
        let b = v.to_bits();
        if b & 0x8000_0000 != 0 {
            !b
        } else {
            b | 0x8000_0000
        }
    };
    let mut label = markers.to_vec();
    let mut heap = BinaryHeap::new();
    let mut age = 0u64;
    for (i, &m) in markers.iter().enumerate() {
        if m != 0 {
            heap.push(Reverse((key(relief[i]), age, i)));
            age += 1;
        }
    }
    while let Some(Reverse((_, _, i))) = heap.pop() {
        let l = label[i];
        for j in neighbours4(i, w, h) {
            if label[j] == 0 {
                label[j] = l;
                heap.push(Reverse((key(relief[j]), age, j)));
                age += 1;
            }
        }
    }
    label
}

/// The 4-neighbours of pixel `i` inside a `w × h` grid (left, right, up,
/// down; those outside the grid left out).
pub fn neighbours4(i: usize, w: usize, h: usize) -> impl Iterator<Item = usize> {
    // An index outside the grid (or any index of an empty one) has none.
    let inside = w > 0 && i < w.saturating_mul(h);
    let (x, y) = if inside { (i % w, i / w) } else { (0, 0) };
    [
        (inside && x > 0).then(|| i - 1),
        (inside && x + 1 < w).then(|| i + 1),
        (inside && y > 0).then(|| i - w),
        (inside && y + 1 < h).then(|| i + w),
    ]
    .into_iter()
    .flatten()
}

/// 8-connected component labels of `mask` (0 = outside, 1.. = component)
/// and the components' sizes (index 0: 0).
pub fn components(mask: &Mask) -> (Vec<u32>, Vec<usize>) {
    labelled(mask, true)
}

/// [`components`] with 4-connectivity: regions that touch only at a corner
/// (a chessboard's squares of one colour) are apart.
pub fn components4(mask: &Mask) -> (Vec<u32>, Vec<usize>) {
    labelled(mask, false)
}

fn labelled(mask: &Mask, eight: bool) -> (Vec<u32>, Vec<usize>) {
    let (w, h) = (mask.width, mask.height);
    let mut label = vec![0u32; w * h];
    let mut sizes = vec![0usize];
    let mut stack = Vec::new();
    for start in 0..w * h {
        if !mask.data[start] || label[start] != 0 {
            continue;
        }
        let id = sizes.len() as u32;
        let mut size = 0;
        label[start] = id;
        stack.push(start);
        while let Some(i) = stack.pop() {
            size += 1;
            let (x, y) = ((i % w) as i64, (i / w) as i64);
            for dy in -1..=1i64 {
                for dx in -1..=1i64 {
                    let (xx, yy) = (x + dx, y + dy);
                    if xx < 0 || yy < 0 || xx >= w as i64 || yy >= h as i64 {
                        continue;
                    }
                    if !eight && dx != 0 && dy != 0 {
                        continue;
                    }
                    let j = yy as usize * w + xx as usize;
                    if mask.data[j] && label[j] == 0 {
                        label[j] = id;
                        stack.push(j);
                    }
                }
            }
        }
        sizes.push(size);
    }
    (label, sizes)
}

/// The holes of `set` (a `w × h` grid): the pixels outside it whose
/// 4-connected region outside it does not reach the grid's border (the
/// dual of `set`'s 8-connectivity: a diagonal gap in an 8-connected ring
/// does not let its inside out).
///
/// # Panics
/// When `set` does not hold `w × h` values.
pub fn enclosed(set: &[bool], w: usize, h: usize) -> Vec<bool> {
    assert_eq!(
        set.len(),
        w * h,
        "enclosed: {} values for {w}x{h}",
        set.len()
    );
    let mut reached = vec![false; w * h];
    let mut stack: Vec<usize> = (0..w * h)
        .filter(|&i| {
            let (x, y) = (i % w, i / w);
            !set[i] && (x == 0 || y == 0 || x + 1 == w || y + 1 == h)
        })
        .collect();
    for &i in &stack {
        reached[i] = true;
    }
    while let Some(i) = stack.pop() {
        for j in neighbours4(i, w, h) {
            if !set[j] && !reached[j] {
                reached[j] = true;
                stack.push(j);
            }
        }
    }
    (0..w * h).map(|i| !set[i] && !reached[i]).collect()
}

/// Chamfer distance from each pixel of `set` (a `w × h` grid) to the
/// nearest pixel outside it, 0 outside (the grid's border counts as
/// outside): two passes with steps of `straight` to the 4 and `diagonal` to
/// the diagonal neighbours. Steps of 1 and 1 give the Chebyshev distance
/// exactly (1 on the set's boundary); 3 and 4, three times a close
/// approximation of the Euclidean one.
///
/// # Panics
/// When `set` does not hold `w × h` values.
pub fn chamfer_depth(set: &[bool], w: usize, h: usize, straight: u32, diagonal: u32) -> Vec<u32> {
    assert_eq!(
        set.len(),
        w * h,
        "chamfer_depth: {} values for {w}x{h}",
        set.len()
    );
    let mut d: Vec<u32> = set.iter().map(|&b| if b { u32::MAX } else { 0 }).collect();
    let at = |d: &[u32], x: i64, y: i64| -> u32 {
        if x < 0 || y < 0 || x >= w as i64 || y >= h as i64 {
            0
        } else {
            d[y as usize * w + x as usize]
        }
    };
    let steps = |sign: i64| {
        [
            (-sign, 0, straight),
            (0, -sign, straight),
            (-sign, -sign, diagonal),
            (sign, -sign, diagonal),
        ]
    };
    for (sign, rows) in [(1i64, false), (-1, true)] {
        for yy in 0..h as i64 {
            let y = if rows { h as i64 - 1 - yy } else { yy };
            for xx in 0..w as i64 {
                let x = if rows { w as i64 - 1 - xx } else { xx };
                let i = y as usize * w + x as usize;
                if d[i] != 0 {
                    for (dx, dy, c) in steps(sign) {
                        d[i] = d[i].min(at(&d, x + dx, y + dy).saturating_add(c));
                    }
                }
            }
        }
    }
    d
}

/// The label (of [`components`], on a grid `w` wide) of the labelled pixel
/// nearest to `(x, y)` (Euclidean; ties: the first in row order), or 0 when
/// no pixel is labelled.
pub fn nearest_label(label: &[u32], w: usize, (x, y): (usize, usize)) -> u32 {
    if w == 0 {
        return 0;
    }
    let mut best = (u64::MAX, 0u32);
    for (i, &l) in label.iter().enumerate() {
        if l != 0 {
            let (xx, yy) = ((i % w) as i64, (i / w) as i64);
            let d = ((xx - x as i64).pow(2) + (yy - y as i64).pow(2)) as u64;
            if d < best.0 {
                best = (d, l);
            }
        }
    }
    best.1
}

/// The relief the leak guard floods: the segmentation's
/// [`gradient_magnitude`] at [`LEAK_GUARD_SIGMA`] (computed once per
/// segmentation for [`pick_mask_on`]).
pub fn leak_guard_relief(seg: &Image) -> Vec<f32> {
    gradient_magnitude(seg, LEAK_GUARD_SIGMA)
}

/// Scale from the MSN's material embedding (tanh units) to the mask's
/// colour-like units: the training pulls a material's pixels within 0.1 of
/// its mean and pushes different materials' means at least 0.8 apart
/// (`training/embedding.py`), which this maps to 0.025 and 0.2 — the spread
/// and the gaps the mask's tolerances ([`auto_tolerance`], [`valley_tolerance`],
/// [`LEAK_GUARD_OTHER`]) were made for on segmentation colours. Chosen by
/// `picker eval` (0.125 gave a lower mean mask IoU on four of the six sets
/// measured, docs/model-card.md).
pub const EMBEDDING_SCALE: f32 = 0.25;

/// The material embedding (3 channels, tanh units) as a mask image:
/// `0.5 + EMBEDDING_SCALE · e` per channel ([`EMBEDDING_SCALE`]).
pub fn embedding_mask_space(embedding: &Image) -> Image {
    Image {
        channels: embedding.channels,
        height: embedding.height,
        width: embedding.width,
        data: embedding
            .data
            .iter()
            .map(|&e| 0.5 + EMBEDDING_SCALE * e)
            .collect(),
    }
}

/// The mask of the material at pixel `(x, y)` of the segmentation image.
pub fn pick_mask(
    seg: &Image,
    valid: &[bool],
    x: usize,
    y: usize,
    opts: &MaskOptions,
) -> Result<PickMask> {
    let relief = if opts.tolerance.is_none() && seg.channels == 3 {
        leak_guard_relief(seg)
    } else {
        Vec::new()
    };
    pick_mask_on(seg, &relief, valid, x, y, opts)
}

/// [`pick_mask`] with the leak guard's relief given ([`leak_guard_relief`]
/// of `seg`; unused, and may be empty, when `opts` gives a tolerance), so
/// that many picks on one segmentation compute it once.
pub fn pick_mask_on(
    seg: &Image,
    relief: &[f32],
    valid: &[bool],
    x: usize,
    y: usize,
    opts: &MaskOptions,
) -> Result<PickMask> {
    let (w, h) = (seg.width, seg.height);
    if seg.channels != 3 || seg.data.len() != 3 * w * h {
        return Err(Error::Shape {
            what: "segmentation".into(),
            expected: "3 channels of width x height values".into(),
            found: format!("{} channels, {} values", seg.channels, seg.data.len()),
        });
    }
    if valid.len() != w * h {
        return Err(Error::Shape {
            what: "valid pixels".into(),
            expected: format!("{}", w * h),
            found: format!("{}", valid.len()),
        });
    }
    if let Some(t) = opts.tolerance.filter(|t| !(t.is_finite() && *t > 0.0)) {
        return Err(Error::Invalid(format!(
            "tolerance {t} must be a positive number"
        )));
    }
    if x >= w || y >= h {
        return Err(Error::Invalid(format!(
            "pick ({x}, {y}) is outside the {w}x{h} segmentation"
        )));
    }
    let (c, sigma) = pick_colour(seg, valid, x, y).ok_or_else(|| {
        Error::Invalid(format!(
            "no surface at the pick ({x}, {y}): the pixel and its neighbours show no material (sky or window)"
        ))
    })?;
    let d: Vec<f32> = (0..w * h)
        .map(|i| {
            if valid[i] {
                dist(colour(seg, i), c)
            } else {
                f32::INFINITY
            }
        })
        .collect();
    let (core, sure_below, tolerance) = match opts.tolerance {
        Some(t) => (t, t, t),
        None => {
            let finite: Vec<f32> = d.iter().copied().filter(|x| x.is_finite()).collect();
            let (tau0, tau) = auto_tolerance(&finite, sigma);
            (tau.min(CORE_SHARE * tau0), tau.min(tau0), tau)
        }
    };
    let mut mask = Mask {
        width: w,
        height: h,
        data: d.iter().map(|&x| x <= tolerance).collect(),
    };
    if core < tolerance {
        let strict: Vec<bool> = d.iter().map(|&x| x <= core).collect();
        mask = hysteresis(&strict, &mask);
    }
    if opts.tolerance.is_none() {
        // Leak guard: the pick's surest pixels (and the 3×3 at the pick)
        // against the pixels of clearly other colours or without a surface,
        // both kept off the edges ([`guard_markers`]).
        if relief.len() != w * h {
            return Err(Error::Shape {
                what: "leak guard relief".into(),
                expected: format!("{} values", w * h),
                found: format!("{}", relief.len()),
            });
        }
        let pick_side = guard_markers(d.iter().map(|&x| x <= core).collect(), w, h);
        let other_side = guard_markers(d.iter().map(|&x| x > LEAK_GUARD_OTHER).collect(), w, h);
        let mut markers: Vec<u8> = pick_side
            .iter()
            .zip(&other_side)
            .map(|(&p, &o)| {
                if p {
                    1
                } else if o {
                    2
                } else {
                    0
                }
            })
            .collect();
        for yy in y.saturating_sub(1)..(y + 2).min(h) {
            for xx in x.saturating_sub(1)..(x + 2).min(w) {
                if valid[yy * w + xx] {
                    markers[yy * w + xx] = 1;
                }
            }
        }
        let region = watershed(relief, w, h, &markers);
        for (m, &r) in mask.data.iter_mut().zip(&region) {
            *m &= r == 1;
        }
    }
    let (label, sizes) = components(&mask);
    // The component at the pick, or the one nearest to it.
    let at = nearest_label(&label, w, (x, y));
    let min_size = ((MIN_SPECK_FRACTION * (w * h) as f64).ceil() as usize).max(1);
    for (i, m) in mask.data.iter_mut().enumerate() {
        let l = label[i];
        *m = l != 0 && (l == at || (!opts.connected && sizes[l as usize] >= min_size));
    }
    let mut sure: Vec<bool> = mask
        .data
        .iter()
        .zip(&d)
        .map(|(&m, &x)| m && x <= sure_below)
        .collect();
    // A pick whose own pixels all lie beyond τ₀ (a noisy pick colour):
    // the whole mask.
    if !sure.iter().any(|&b| b) {
        sure.clone_from(&mask.data);
    }
    Ok(PickMask {
        mask,
        colour: c,
        tolerance,
        photo: None,
        sure,
        pattern: None,
        split: None,
    })
}

/// The pixels of `mask` within `τ₀` ([`auto_tolerance`]'s spread of the
/// pick's own pixels) of the pick colour in `seg`, another segmentation of
/// the same photo (none when the pick has no surface). Masks are cut from
/// the smoothed segmentation ([`crate::smooth`]), which keeps the
/// photo-different parts of one material apart (a chessboard's black and
/// white squares); the surest part of an automatic mask — what the texture
/// is made of — adds these pixels of the network's own colours, which see
/// the material as one ([`crate::Prepared::pick_mask`]).
pub fn sure_in(seg: &Image, valid: &[bool], x: usize, y: usize, mask: &Mask) -> Result<Vec<bool>> {
    let (w, h) = (seg.width, seg.height);
    if seg.channels != 3 || mask.width != w || mask.height != h || valid.len() != w * h {
        return Err(Error::Shape {
            what: "segmentation, validity and mask for the sure pixels".into(),
            expected: format!("3 channels, {} values and a mask at {}x{}", w * h, w, h),
            found: format!(
                "{} channels, {} values, a {}x{} mask",
                seg.channels,
                valid.len(),
                mask.width,
                mask.height
            ),
        });
    }
    if x >= w || y >= h {
        return Err(Error::Invalid(format!(
            "pick ({x}, {y}) is outside the {w}x{h} segmentation"
        )));
    }
    let Some((c, sigma)) = pick_colour(seg, valid, x, y) else {
        return Ok(vec![false; w * h]);
    };
    let tau0 = own_tolerance(sigma);
    Ok((0..w * h)
        .map(|i| mask.data[i] && valid[i] && dist(colour(seg, i), c) <= tau0)
        .collect())
}

/// Refines a mask computed at a lower resolution to the photo's edges: the
/// mask is guided-upsampled with the photo's luma `guide` (`fw×fh`) and
/// thresholded at ½, then limited to pixels within one low-resolution pixel
/// of the coarse mask. Equal sizes return the mask unchanged.
pub fn refine(mask: &Mask, guide: &[f32], fw: usize, fh: usize) -> Mask {
    use crate::resample::{lerp2, src_coord};
    use rayon::prelude::*;
    if (mask.width, mask.height) == (fw, fh) {
        return mask.clone();
    }
    assert_eq!(guide.len(), fw * fh, "guide length");
    // `refine_reference` fused per photo pixel: the guided coefficients and
    // the dilated mask are interpolated where needed instead of as whole
    // photo-resolution planes (the same bilinear formula, so the same bits),
    // rows in parallel.
    let (w, h) = (mask.width, mask.height);
    let g_low = crate::resample::area_plane(guide, fw, fh, w, h);
    let (ma, mb) = crate::guided::coefficients(&g_low, &mask.to_image().data, w, h, 1, 1e-3);
    let dilated = dilated(mask).to_image().data;
    let xs: Vec<_> = (0..fw).map(|x| src_coord(x, w, fw)).collect();
    let mut data = vec![false; fw * fh];
    data.par_chunks_mut(fw.max(1))
        .enumerate()
        .for_each(|(y, row)| {
            let (y0, y1, fy) = src_coord(y, h, fh);
            let (a0, a1) = (&ma[y0 * w..(y0 + 1) * w], &ma[y1 * w..(y1 + 1) * w]);
            let (b0, b1) = (&mb[y0 * w..(y0 + 1) * w], &mb[y1 * w..(y1 + 1) * w]);
            let (d0, d1) = (
                &dilated[y0 * w..(y0 + 1) * w],
                &dilated[y1 * w..(y1 + 1) * w],
            );
            let g = &guide[y * fw..(y + 1) * fw];
            for (x, (o, &(x0, x1, fx))) in row.iter_mut().zip(&xs).enumerate() {
                let soft = lerp2(a0, a1, x0, x1, fx, fy) * g[x] + lerp2(b0, b1, x0, x1, fx, fy);
                let near = lerp2(d0, d1, x0, x1, fx, fy);
                *o = soft > 0.5 && near > 0.0;
            }
        });
    Mask {
        width: fw,
        height: fh,
        data,
    }
}

/// The mask dilated by one pixel (8-neighbourhood).
fn dilated(mask: &Mask) -> Mask {
    let mut d = mask.clone();
    let inv = Mask {
        width: mask.width,
        height: mask.height,
        data: mask.data.iter().map(|b| !b).collect(),
    }
    .eroded();
    for (o, i) in d.data.iter_mut().zip(&inv.data) {
        *o = !i;
    }
    d
}

/// The plain implementation of [`refine`] (whole photo-resolution planes).
pub fn refine_reference(mask: &Mask, guide: &[f32], fw: usize, fh: usize) -> Mask {
    if (mask.width, mask.height) == (fw, fh) {
        return mask.clone();
    }
    let soft = crate::guided::guided_upsample(guide, fw, fh, &mask.to_image(), 1, 1e-3);
    let dilated = {
        let mut d = mask.clone();
        let inv = Mask {
            width: mask.width,
            height: mask.height,
            data: mask.data.iter().map(|b| !b).collect(),
        }
        .eroded();
        for (o, i) in d.data.iter_mut().zip(&inv.data) {
            *o = !i;
        }
        d
    };
    let near =
        crate::resample::bilinear_plane(&dilated.to_image().data, mask.width, mask.height, fw, fh);
    Mask {
        width: fw,
        height: fh,
        data: soft
            .data
            .iter()
            .zip(&near)
            .map(|(&s, &n)| s > 0.5 && n > 0.0)
            .collect(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The plain erosion [`Mask::eroded`] is tested against.
    fn eroded_reference(m: &Mask) -> Mask {
        let (w, h) = (m.width, m.height);
        let mut out = m.data.clone();
        for y in 0..h {
            for x in 0..w {
                if !m.data[y * w + x] {
                    continue;
                }
                'n: for dy in -1i64..=1 {
                    for dx in -1i64..=1 {
                        let (xx, yy) = (x as i64 + dx, y as i64 + dy);
                        if xx < 0 || yy < 0 || xx >= w as i64 || yy >= h as i64 {
                            continue;
                        }
                        if !m.data[yy as usize * w + xx as usize] {
                            out[y * w + x] = false;
                            break 'n;
                        }
                    }
                }
            }
        }
        Mask {
            width: w,
            height: h,
            data: out,
        }
    }

    /// The holes of `set` the slow way: 4-connected components outside
    /// it, those with a pixel on the border left out.
    fn enclosed_reference(set: &[bool], w: usize, h: usize) -> Vec<bool> {
        let outside = Mask {
            width: w,
            height: h,
            data: set.iter().map(|&b| !b).collect(),
        };
        let (label, sizes) = components4(&outside);
        let mut open = vec![false; sizes.len()];
        for (i, &l) in label.iter().enumerate() {
            let (x, y) = (i % w, i / w);
            if x == 0 || y == 0 || x + 1 == w || y + 1 == h {
                open[l as usize] = true;
            }
        }
        (0..w * h)
            .map(|i| label[i] != 0 && !open[label[i] as usize])
            .collect()
    }

    #[test]
    fn enclosed_matches_its_reference_and_lets_diagonals_through_nothing() {
        let mut rng = picker_tensor::Rng::new(59);
        for &(w, h) in &[(1, 1), (1, 6), (7, 1), (2, 2), (3, 3), (9, 7), (31, 17)] {
            for density in [0.2f32, 0.5, 0.7, 0.9] {
                for _ in 0..8 {
                    let set: Vec<bool> = (0..w * h)
                        .map(|_| rng.uniform(0.0, 1.0) < density)
                        .collect();
                    assert_eq!(
                        enclosed(&set, w, h),
                        enclosed_reference(&set, w, h),
                        "{w}x{h} density {density}: {set:?}"
                    );
                }
            }
        }
        // A diamond (8-connected ring, 4-connected gaps only at corners)
        // holds its centre; a ring cut open does not.
        #[rustfmt::skip]
        let diamond = [
            false, false, true,  false, false,
            false, true,  false, true,  false,
            true,  false, false, false, true,
            false, true,  false, true,  false,
            false, false, true,  false, false,
        ];
        let holes = enclosed(&diamond, 5, 5);
        let want: Vec<usize> = vec![7, 11, 12, 13, 17];
        assert_eq!((0..25).filter(|&i| holes[i]).collect::<Vec<_>>(), want);
        let mut cut = diamond;
        cut[2] = false;
        assert!(enclosed(&cut, 5, 5).iter().all(|&b| !b));
        assert!(enclosed(&[], 0, 0).is_empty());
    }

    #[test]
    fn scaled_masks_take_the_pixel_under_each_centre() {
        let m = Mask {
            width: 4,
            height: 2,
            data: vec![true, false, false, true, false, true, true, false],
        };
        assert_eq!(m.scaled_to(4, 2), m);
        let up = m.scaled_to(8, 4);
        for y in 0..4 {
            for x in 0..8 {
                assert_eq!(
                    up.data[y * 8 + x],
                    m.data[(y / 2) * 4 + x / 2],
                    "({x}, {y})"
                );
            }
        }
        assert_eq!(up.scaled_to(4, 2), m);
        // Odd ratios stay inside; empty sizes either way.
        let odd = m.scaled_to(7, 3);
        assert_eq!(odd.data.len(), 21);
        assert_eq!(odd.data[0], m.data[0]);
        assert_eq!(odd.data[20], m.data[7]);
        assert_eq!(m.scaled_to(0, 5).data.len(), 0);
        let none = Mask {
            width: 0,
            height: 0,
            data: vec![],
        };
        assert_eq!(none.scaled_to(3, 2).count(), 0);
    }

    #[test]
    fn the_central_pixel_is_in_the_mask() {
        let mk = |w: usize, h: usize, f: &dyn Fn(usize, usize) -> bool| Mask {
            width: w,
            height: h,
            data: (0..w * h).map(|i| f(i % w, i / w)).collect(),
        };
        // A filled square: its centre (ties go to the first in row order).
        let m = mk(9, 7, &|x, y| (2..=6).contains(&x) && (1..=5).contains(&y));
        assert_eq!(m.central_pixel(), Some([4, 3]));
        // A ring, whose centroid is outside it: a pixel of the ring.
        let ring = mk(21, 21, &|x, y| {
            let d = ((x as f64 - 10.0).powi(2) + (y as f64 - 10.0).powi(2)).sqrt();
            (6.0..8.0).contains(&d)
        });
        let [x, y] = ring.central_pixel().unwrap();
        assert!(ring.data[y * 21 + x]);
        // One pixel; none.
        assert_eq!(
            mk(5, 4, &|x, y| (x, y) == (4, 3)).central_pixel(),
            Some([4, 3])
        );
        assert_eq!(mk(5, 4, &|_, _| false).central_pixel(), None);
        assert_eq!(mk(0, 0, &|_, _| true).central_pixel(), None);
    }

    #[test]
    fn chamfer_depth_with_unit_steps_is_the_chebyshev_distance() {
        let mut rng = picker_tensor::Rng::new(11);
        for &(w, h) in &[(1usize, 1usize), (7, 1), (1, 5), (9, 7), (16, 12)] {
            for density in [0.3, 0.7, 0.95, 1.0] {
                let set: Vec<bool> = (0..w * h).map(|_| rng.f64() < density).collect();
                let brute: Vec<u32> = (0..w * h)
                    .map(|i| {
                        if !set[i] {
                            return 0;
                        }
                        let (x, y) = ((i % w) as i64, (i / w) as i64);
                        // Outside: unset pixels and the ring around the grid.
                        let mut best = i64::MAX;
                        for yy in -1..=h as i64 {
                            for xx in -1..=w as i64 {
                                let inside =
                                    (0..w as i64).contains(&xx) && (0..h as i64).contains(&yy);
                                if !inside || !set[yy as usize * w + xx as usize] {
                                    best = best.min((xx - x).abs().max((yy - y).abs()));
                                }
                            }
                        }
                        best as u32
                    })
                    .collect();
                assert_eq!(chamfer_depth(&set, w, h, 1, 1), brute, "{w}x{h} {density}");
            }
        }
        // 3-4 steps: three times the distance along an axis.
        let row = vec![true; 9];
        assert_eq!(chamfer_depth(&row, 9, 1, 3, 4), vec![3; 9]);
        let square = vec![true; 25];
        assert_eq!(chamfer_depth(&square, 5, 5, 3, 4)[12], 9);
    }

    #[test]
    fn eroded_matches_reference() {
        let mut rng = picker_tensor::Rng::new(22);
        for &(w, h) in &[(1, 1), (1, 5), (6, 1), (2, 2), (17, 13)] {
            for density in [0.0, 0.5, 0.9, 1.0] {
                let m = Mask {
                    width: w,
                    height: h,
                    data: (0..w * h).map(|_| rng.f64() < density).collect(),
                };
                assert_eq!(m.eroded(), eroded_reference(&m), "{w}x{h} {density}");
            }
        }
    }

    #[test]
    fn fused_refine_matches_reference() {
        let mut rng = picker_tensor::Rng::new(21);
        for &(w, h, fw, fh) in &[
            (1, 1, 3, 2),
            (4, 3, 4, 3),
            (4, 3, 9, 7),
            (10, 1, 37, 5),
            (16, 12, 160, 120),
            (20, 15, 47, 33),
        ] {
            for density in [0.0, 0.3, 0.7, 1.0] {
                let mask = Mask {
                    width: w,
                    height: h,
                    data: (0..w * h).map(|_| rng.f64() < density).collect(),
                };
                let guide = rng.uniform_vec(fw * fh, 0.0, 1.0);
                let a = refine(&mask, &guide, fw, fh);
                let b = refine_reference(&mask, &guide, fw, fh);
                assert_eq!(a.data, b.data, "{w}x{h} -> {fw}x{fh} density {density}");
            }
        }
    }

    /// [`pick_mask`] with the tolerance `t` given (no guard), unwrapped.
    fn pick_fixed(seg: &Image, valid: &[bool], (x, y): (usize, usize), t: f32) -> PickMask {
        let opts = MaskOptions {
            tolerance: Some(t),
            ..Default::default()
        };
        pick_mask(seg, valid, x, y, &opts).unwrap()
    }

    fn seg_from(ids: &[u8], w: usize, h: usize, palette: &[[f32; 3]]) -> Image {
        let mut img = Image::zeros(3, h, w);
        for (i, &id) in ids.iter().enumerate() {
            for (c, v) in palette[id as usize].iter().enumerate() {
                img.data[c * w * h + i] = *v;
            }
        }
        img
    }

    #[test]
    fn split_regions_are_one_material_unless_connected() {
        // 0 0 1 0 0 : material 0 split by material 1.
        let ids: Vec<u8> = (0..50)
            .map(|i| if i % 10 == 4 || i % 10 == 5 { 1 } else { 0 })
            .collect();
        let seg = seg_from(&ids, 10, 5, &[[0.2, 0.3, 0.4], [0.7, 0.1, 0.1]]);
        let valid = vec![true; 50];
        let all = pick_mask(&seg, &valid, 1, 2, &MaskOptions::default()).unwrap();
        assert_eq!(all.mask.count(), 40);
        let conn = pick_mask(
            &seg,
            &valid,
            1,
            2,
            &MaskOptions {
                connected: true,
                ..Default::default()
            },
        )
        .unwrap();
        assert_eq!(conn.mask.count(), 20);
    }

    #[test]
    fn noisy_centre_pixel_does_not_decide() {
        let mut ids = vec![0u8; 49];
        ids[24] = 1; // the picked pixel is a one-pixel outlier
        let seg = seg_from(&ids, 7, 7, &[[0.5, 0.5, 0.5], [0.53, 0.5, 0.5]]);
        let m = pick_mask(&seg, &[true; 49], 3, 3, &MaskOptions::default()).unwrap();
        assert!((m.colour[0] - 0.5).abs() < 1e-6);
    }

    #[test]
    fn pick_on_sky_is_a_clear_error_and_outside_too() {
        let seg = seg_from(&[0; 25], 5, 5, &[[0.5; 3]]);
        let e = pick_mask(&seg, &[false; 25], 2, 2, &MaskOptions::default()).unwrap_err();
        assert!(e.to_string().contains("no surface"), "{e}");
        let e = pick_mask(&seg, &[true; 25], 5, 0, &MaskOptions::default()).unwrap_err();
        assert!(e.to_string().contains("outside"), "{e}");
    }

    /// Distances of a soft segmentation: the material spreads over
    /// `[0, spread)`, the others sit around `other`.
    fn soft_distances(
        rng: &mut picker_tensor::Rng,
        n_own: usize,
        spread: f32,
        other: f32,
    ) -> Vec<f32> {
        let mut d: Vec<f32> = (0..n_own).map(|_| rng.uniform(0.0, spread)).collect();
        d.extend((0..3 * n_own).map(|_| other + rng.uniform(-0.03, 0.03)));
        d
    }

    #[test]
    fn valley_follows_a_soft_material_up_to_the_next_one() {
        let mut rng = picker_tensor::Rng::new(21);
        for (spread, other) in [(0.08f32, 0.3f32), (0.15, 0.3), (0.05, 0.12), (0.2, 0.45)] {
            let d = soft_distances(&mut rng, 4000, spread, other);
            let t = valley_tolerance(&d, 0.03);
            assert!(
                t > spread - 0.01 && t < other - 0.03,
                "spread {spread} other {other}: τ {t}"
            );
            // The pick's own tolerance is a floor.
            assert!(valley_tolerance(&d, 0.5) >= 0.5);
        }
    }

    #[test]
    fn valley_keeps_the_pick_tolerance_without_a_valley() {
        let mut rng = picker_tensor::Rng::new(22);
        // Uniform over the whole range: no dip.
        let d: Vec<f32> = (0..20000).map(|_| rng.uniform(0.0, 0.6)).collect();
        let t = valley_tolerance(&d, 0.05);
        assert!(t <= 0.08, "τ {t}");
        // Empty, one value, all beyond the range, NaN.
        assert_eq!(valley_tolerance(&[], 0.04), 0.04);
        assert_eq!(valley_tolerance(&[0.0], 0.04), 0.04);
        assert_eq!(valley_tolerance(&[0.7, 0.9, f32::NAN], 0.04), 0.04);
    }

    #[test]
    fn clean_segmentations_keep_close_colours_apart() {
        // Two flat materials 0.01 apart: the valley sees an empty band
        // beyond the spike at 0, and the gap rule lowers τ below 0.01.
        let mut d = vec![0.0f32; 3000];
        d.extend(vec![0.01f32; 3000]);
        d.extend(vec![0.3f32; 3000]);
        let (tau0, tau) = auto_tolerance(&d, 0.0);
        assert_eq!(tau0, TOLERANCE_MIN);
        assert!(tau > 0.0 && tau < 0.01, "τ {tau}");
    }

    #[test]
    fn hysteresis_keeps_regions_with_a_sure_pixel() {
        // Three blobs in a 12-wide row; only the first and last hold core pixels.
        let w = 12;
        let cand: Vec<bool> = (0..w).map(|x| x != 3 && x != 7).collect();
        let mut core = vec![false; w];
        core[1] = true;
        core[10] = true;
        let m = hysteresis(
            &core,
            &Mask {
                width: w,
                height: 1,
                data: cand,
            },
        );
        let want: Vec<bool> = (0..w).map(|x| !(3..=7).contains(&x)).collect();
        assert_eq!(m.data, want);
    }

    #[test]
    fn a_shaded_soft_material_is_taken_whole_and_a_similar_object_is_not() {
        // 200×20: the picked material's segmentation colour drifts with
        // shading from 0.30 to 0.40 across its 120 columns; the other 80
        // columns are another material at 0.75, except a 4×4 object of
        // colour 0.36 (the material's range, but a separate object, not
        // touching it).
        let (w, h) = (200, 20);
        let mut seg = Image::zeros(3, h, w);
        let mut truth = vec![false; w * h];
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                let v = if x < 120 {
                    truth[i] = true;
                    0.30 + 0.10 * x as f32 / 119.0
                } else if (150..154).contains(&x) && (8..12).contains(&y) {
                    0.36
                } else {
                    0.75
                };
                for c in 0..3 {
                    seg.data[c * w * h + i] = v;
                }
            }
        }
        let valid = vec![true; w * h];
        let m = pick_mask(&seg, &valid, 2, 10, &MaskOptions::default()).unwrap();
        assert_eq!(m.mask.data, truth, "τ {}", m.tolerance);
        // With a fixed tolerance, exactly that tolerance: less of the
        // drift, and no hysteresis (the object is in).
        let fixed = pick_fixed(&seg, &valid, (2, 10), 0.12);
        assert_eq!(fixed.tolerance, 0.12);
        let object = 10 * w + 151;
        assert!(fixed.mask.data[object]);
        assert!(!fixed.mask.data[10 * w + 119]);
    }

    #[test]
    fn the_leak_guard_stops_a_soft_material_at_its_edge() {
        // 200×20: the picked material's colour drifts from grey 0.30 to
        // 0.40 over columns 0..100 (distance to the pick 0 → 0.173); the
        // neighbour's starts at the same distance but another hue (a step
        // of 0.06 at the edge) and drifts on to 0.353 over 100..200. The
        // distances run on without a valley or an empty band, so the
        // tolerance takes the neighbour in.
        let (w, h) = (200, 20);
        let p = glam::Vec3::splat(0.30);
        let grey = glam::Vec3::ONE.normalize();
        let side = glam::Vec3::new(1.0, -1.0, 0.0).normalize();
        let theta = 2.0 * (0.03f32 / 0.1732).asin();
        let hue = (grey * theta.cos() + side * theta.sin()).normalize();
        let mut seg = Image::zeros(3, h, w);
        for y in 0..h {
            for x in 0..w {
                let v = if x < 100 {
                    p + grey * (0.1732 * x as f32 / 99.0)
                } else {
                    p + hue * (0.1732 + 0.18 * (x - 100) as f32 / 99.0)
                };
                for c in 0..3 {
                    seg.data[c * w * h + y * w + x] = v[c];
                }
            }
        }
        let valid = vec![true; w * h];
        let m = pick_mask(&seg, &valid, 2, 10, &MaskOptions::default()).unwrap();
        // The tolerance takes the neighbour in; the guard keeps it out.
        assert!(m.tolerance > 0.3, "τ {}", m.tolerance);
        // It stops at the edge, between columns 99 and 100.
        let cols: Vec<usize> = (0..w).filter(|&x| m.mask.data[10 * w + x]).collect();
        assert_eq!(cols, (0..100).collect::<Vec<_>>());
        assert_eq!(m.mask.count(), 100 * h);
        // The same tolerance given by hand has no guard: the neighbour is in.
        let fixed = pick_fixed(&seg, &valid, (2, 10), m.tolerance);
        assert!(fixed.mask.data[10 * w + 150]);
    }

    #[test]
    fn a_given_relief_gives_the_same_mask_and_a_misshaped_one_an_error() {
        let mut rng = picker_tensor::Rng::new(30);
        let (w, h) = (23, 17);
        let mut seg = Image::zeros(3, h, w);
        for (i, v) in seg.data.iter_mut().enumerate() {
            // Four blocks of colour with noise.
            let p = i % (w * h);
            let block = (p % w >= 11) as usize + 2 * ((p / w >= 8) as usize);
            *v = 0.2 * block as f32 + rng.uniform(-0.02, 0.02);
        }
        let valid = vec![true; w * h];
        let relief = leak_guard_relief(&seg);
        for (x, y) in [(0, 0), (5, 5), (20, 3), (12, 16), (22, 16)] {
            let a = pick_mask(&seg, &valid, x, y, &MaskOptions::default()).unwrap();
            let b = pick_mask_on(&seg, &relief, &valid, x, y, &MaskOptions::default()).unwrap();
            assert_eq!(a.mask, b.mask, "({x}, {y})");
            assert_eq!(a.sure, b.sure);
        }
        let e =
            pick_mask_on(&seg, &relief[1..], &valid, 5, 5, &MaskOptions::default()).unwrap_err();
        assert!(e.to_string().contains("relief"), "{e}");
        // A given tolerance needs no relief.
        let fixed = MaskOptions {
            tolerance: Some(0.05),
            ..Default::default()
        };
        assert!(pick_mask_on(&seg, &[], &valid, 5, 5, &fixed).is_ok());
    }

    #[test]
    fn degenerate_sizes_give_a_mask() {
        let mut rng = picker_tensor::Rng::new(31);
        for &(w, h) in &[(1, 1), (1, 5), (6, 1), (2, 2), (3, 7)] {
            let mut seg = Image::zeros(3, h, w);
            for v in &mut seg.data {
                *v = rng.uniform(0.0, 1.0);
            }
            for (x, y) in [(0, 0), (w - 1, h - 1)] {
                let m = pick_mask(&seg, &vec![true; w * h], x, y, &MaskOptions::default())
                    .unwrap_or_else(|e| panic!("{w}x{h} ({x}, {y}): {e}"));
                // At least half the pick's window members lie within
                // ½τ₀ of the pick colour: they seed the pick's front.
                assert!(m.mask.count() > 0, "{w}x{h} ({x}, {y})");
                assert!(m.sure.iter().any(|&b| b));
            }
        }
    }

    #[test]
    fn guard_markers_stay_off_the_edges() {
        // A 9×9 block inside a 15×15 grid shrinks to its 3×3 centre; a
        // block at the border keeps its border side; a thin line vanishes.
        let (w, h) = (15, 15);
        let block = |x0: usize, x1: usize, y0: usize, y1: usize| -> Vec<bool> {
            (0..w * h)
                .map(|i| (x0..x1).contains(&(i % w)) && (y0..y1).contains(&(i / w)))
                .collect()
        };
        assert_eq!(LEAK_GUARD_ERODE, 3);
        assert_eq!(guard_markers(block(3, 12, 3, 12), w, h), block(6, 9, 6, 9));
        assert_eq!(guard_markers(block(0, 9, 0, 15), w, h), block(0, 6, 0, 15));
        assert!(!guard_markers(block(0, 15, 7, 8), w, h).iter().any(|&b| b));
    }

    #[test]
    fn neighbours4_stay_inside_the_grid() {
        let n = |i, w, h| neighbours4(i, w, h).collect::<Vec<_>>();
        assert_eq!(n(0, 1, 1), Vec::<usize>::new());
        assert_eq!(n(0, 3, 2), vec![1, 3]);
        assert_eq!(n(4, 3, 2), vec![3, 5, 1]);
        assert_eq!(n(4, 3, 3), vec![3, 5, 1, 7]);
        assert_eq!(n(2, 1, 4), vec![1, 3]);
    }

    #[test]
    fn watershed_splits_at_the_ridge() {
        // One row: relief rising to a ridge at column 6, markers at both ends.
        let relief = [0.0, 0.1, 0.2, 0.1, 0.3, 0.5, 0.9, 0.4, 0.2, 0.1, 0.0];
        let mut markers = [0u8; 11];
        markers[0] = 1;
        markers[10] = 2;
        // The ridge itself goes to the front that reaches it first: the
        // one coming up the lower side (0.4 on the right, 0.5 on the left).
        let l = watershed(&relief, 11, 1, &markers);
        assert_eq!(l, [1, 1, 1, 1, 1, 1, 2, 2, 2, 2, 2]);
        let mut swapped = [0u8; 11];
        swapped[0] = 2;
        swapped[10] = 1;
        let l = watershed(&relief, 11, 1, &swapped);
        assert_eq!(l, [2, 2, 2, 2, 2, 2, 1, 1, 1, 1, 1]);
        // No markers: nothing is labelled; one marker: everything.
        assert_eq!(watershed(&relief, 11, 1, &[0; 11]), vec![0; 11]);
        let mut one = [0u8; 11];
        one[4] = 3;
        assert_eq!(watershed(&relief, 11, 1, &one), vec![3; 11]);
        // 2-D, 4-connected: a closed wall of high relief keeps the inside
        // apart from the outside (the wall itself goes to either front).
        let (w, h) = (7, 7);
        let relief: Vec<f32> = (0..w * h)
            .map(|i| {
                let (x, y) = (i % w, i / w);
                let wall = (1..=5).contains(&x)
                    && (1..=5).contains(&y)
                    && (x == 1 || x == 5 || y == 1 || y == 5);
                if wall {
                    1.0
                } else {
                    0.0
                }
            })
            .collect();
        let mut markers = vec![0u8; w * h];
        markers[3 * w + 3] = 1;
        markers[0] = 2;
        let l = watershed(&relief, w, h, &markers);
        for (i, &li) in l.iter().enumerate() {
            let (x, y) = (i % w, i / w);
            let inside = (2..=4).contains(&x) && (2..=4).contains(&y);
            let outside = !(1..=5).contains(&x) || !(1..=5).contains(&y);
            if inside || outside {
                assert_eq!(li, if inside { 1 } else { 2 }, "({x}, {y})");
            } else {
                assert!(li == 1 || li == 2, "({x}, {y})");
            }
        }
        // NaN and infinite relief are flooded last, deterministically.
        let relief = [0.0, f32::NAN, f32::INFINITY, 0.0];
        let l = watershed(&relief, 4, 1, &[1, 0, 0, 2]);
        assert_eq!(l, vec![1, 1, 2, 2]);
    }

    #[test]
    fn gradient_magnitude_of_ramps_and_steps() {
        // A ramp of slope 0.01 per column in all three channels: the
        // interior gradient is 0.01·√3 (the sampled Gaussian derivative's
        // first moment is 1 to well under 1%), at σ = 1.5 and with central
        // differences.
        let (w, h) = (40, 9);
        let mut img = Image::zeros(3, h, w);
        for c in 0..3 {
            for i in 0..w * h {
                img.data[c * w * h + i] = 0.01 * (i % w) as f32;
            }
        }
        for sigma in [1.5f32, 0.0] {
            let g = gradient_magnitude(&img, sigma);
            for y in 0..h {
                for x in 8..w - 8 {
                    let want = 0.01 * 3f32.sqrt();
                    assert!(
                        (g[y * w + x] - want).abs() < 0.005 * want,
                        "σ {sigma} ({x}, {y}) {}",
                        g[y * w + x]
                    );
                }
            }
        }
        // A flat image has none; a vertical step peaks at the step.
        let flat = Image::zeros(3, 5, 6);
        assert!(gradient_magnitude(&flat, 1.5).iter().all(|&v| v == 0.0));
        let mut step = Image::zeros(1, 5, 20);
        for i in 0..100 {
            step.data[i] = if i / 20 >= 3 { 1.0 } else { 0.0 };
        }
        let g = gradient_magnitude(&step, 1.0);
        for x in 0..20 {
            let col: Vec<f32> = (0..5).map(|y| g[y * 20 + x]).collect();
            assert!(col[2] > col[0] && col[3] > col[4], "{col:?}");
        }
        // 1×1 and reflection at the borders.
        assert_eq!(gradient_magnitude(&Image::zeros(3, 1, 1), 1.5), vec![0.0]);
        assert_eq!(
            (0..8).map(|i| reflect(i - 3, 3)).collect::<Vec<_>>(),
            vec![2, 1, 0, 0, 1, 2, 2, 1]
        );
        assert_eq!(reflect(-5, 1), 0);
    }

    #[test]
    fn sure_pixels_come_from_the_other_segmentation_within_the_picks_spread() {
        // A 12×4 segmentation: columns 0..8 one material (ids 0, colour
        // 0.5), columns 8..12 another (0.9); the mask given takes columns 0..10.
        let (w, h) = (12, 4);
        let ids: Vec<u8> = (0..w * h).map(|i| u8::from(i % w >= 8)).collect();
        let seg = seg_from(&ids, w, h, &[[0.5; 3], [0.9; 3]]);
        let valid = vec![true; w * h];
        let mask = Mask {
            width: w,
            height: h,
            data: (0..w * h).map(|i| i % w < 10).collect(),
        };
        let sure = sure_in(&seg, &valid, 2, 1, &mask).unwrap();
        for (i, &s) in sure.iter().enumerate() {
            assert_eq!(s, i % w < 8, "pixel {i}");
        }
        // Invalid pixels are never sure.
        let mut valid2 = valid.clone();
        valid2[3] = false;
        assert!(!sure_in(&seg, &valid2, 2, 1, &mask).unwrap()[3]);
        // A pick whose colour the mask does not hold: none.
        let only_right = Mask {
            width: w,
            height: h,
            data: (0..w * h).map(|i| i % w >= 9).collect(),
        };
        assert!(!sure_in(&seg, &valid, 2, 1, &only_right)
            .unwrap()
            .contains(&true));
        // No surface at the pick: none.
        let none = vec![false; w * h];
        assert!(!sure_in(&seg, &none, 2, 1, &mask).unwrap().contains(&true));
        // Refusals: a pick outside, a mask of another size, a grey image.
        assert!(sure_in(&seg, &valid, 12, 0, &mask).is_err());
        let small = Mask {
            width: 4,
            height: 4,
            data: vec![true; 16],
        };
        assert!(sure_in(&seg, &valid, 0, 0, &small).is_err());
        let grey = Image::new(1, h, w, vec![0.5; w * h]).unwrap();
        assert!(sure_in(&grey, &valid, 0, 0, &mask).is_err());
    }
}
