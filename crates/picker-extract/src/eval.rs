//! Evaluation metrics against synthetic ground truth (pure functions, no file I/O).
//!
//! - [`mask_iou`]: intersection over union of two masks.
//! - [`aligned_texture_score`]: how close an extracted tileable texture is to
//!   the true source texture when the offset and scale of the tiling are
//!   unknown (best over cyclic shifts and a few scales, PSNR on sRGB values)
//!   plus a colour-statistics distance that needs no alignment.
//! - [`albedo_error`]: RMSE of linear albedos inside a mask.
//! - [`normal_error_deg`]: mean angular error of normals inside a mask.
//!
//! **Alignment search** (no FFT): for each scale `s` in [`ALIGN_SCALES`],
//! the (linear) truth is resampled with wrap-around to `round(s·h) × round(s·w)`
//! (area average when shrinking, bilinear when enlarging) and sRGB-encoded
//! like the extracted texture. At `s = 1/k` for a whole `k` (the texture
//! holds `k × k` periods) the truth tiled `k × k` is resampled to exactly the
//! texture's size and compared with it whole at every cyclic shift (resampled
//! to `round(s·h)` texels a period, a texture of 40 texels holding three
//! periods of 13⅓ lost 8 dB, and a cyclic roll of it moved the score); at
//! other `s < 1` the truth is treated as periodic (effectively tiled) and
//! the extracted texture is compared with a window of it; at `s > 1` the whole of it is compared with the extracted texture
//! tiled (the texture as an artist uses it, so a cyclic roll of the texture
//! changes only the shift found; comparing the texture with a window of the
//! truth was not invariant to such rolls). The
//! mean squared error over all cyclic shifts is minimised coarse-to-fine:
//! both images are box-downsampled by 2 until the smaller side of the
//! extracted one is below 32 texels, every shift is tried at that coarsest
//! level, and the best [`ALIGN_CANDIDATES`] shifts are refined level by level
//! in a ±[`ALIGN_REFINE_RADIUS`] window around their projection; the search
//! runs for the texture and for it rolled by one texel down, across and both,
//! so that every shift is seen aligned at the coarse levels by one of them (a
//! finely patterned texture at half-texel misalignment could rank a shift by
//! a whole number of the truth's periods above its true one, and a cyclic
//! roll of it moved the score by 0.5 dB). The tiling's
//! offset is continuous, so whole-texel shifts are not enough where the
//! truth is finer than the extracted texture (a 16-texel tile of a 128-pixel
//! truth may be off by any fraction of a texel): for every scale within 3 dB
//! of the best, the truth's resampled grid is then moved by a sub-texel
//! offset (a pattern search in steps of ½, ¼ and ⅛ texel, each offset scored
//! at the whole shifts within one texel of the best), along the axes where
//! the truth has at least [`SUBTEXEL_MIN_RATIO`] texels per extracted texel
//! (a moved area average stays as sharp as the unmoved one; where the truth
//! is coarser, moving would interpolate, blur it and flatter blurry
//! textures). A 256² pair takes well under a second. Rotations by 90° and mirror images are
//! **not** searched (the extracted texture's orientation follows the
//! recovered UVs, which keep the handedness and orientation of the truth in
//! the synthetic data).

use std::collections::HashSet;

use picker_nets::conventions::srgb_encode;
use picker_render::io::Image;
use rayon::prelude::*;

use crate::report::{resize, resize_periodic_at};

/// Scales tried by [`aligned_texture_score`], in order (ties keep the first):
/// the size of one period of the truth, in extracted texels, relative to the
/// extracted texture's size.
pub const ALIGN_SCALES: [f64; 7] = [1.0, 0.5, 2.0, 1.0 / 3.0, 0.25, 1.5, 2.0 / 3.0];
/// Shifts kept from one pyramid level to the next.
pub const ALIGN_CANDIDATES: usize = 8;
/// Half-width of the refinement window (texels at each level).
pub const ALIGN_REFINE_RADIUS: i64 = 2;
/// The sub-texel search runs along an axis where the truth has at least
/// this many texels per texel of the resampled grid (where it has fewer, a
/// moved grid would blur the truth and flatter a blurry texture).
pub const SUBTEXEL_MIN_RATIO: f64 = 2.0;
/// Scales whose whole-texel error is within this factor of the best one's
/// get the sub-texel search (2: 3 dB).
const SUBTEXEL_SCALE_MARGIN: f64 = 2.0;
/// The coarsest pyramid level's smaller side is below this many texels.
const COARSEST_SIDE: usize = 32;

/// Intersection over union of two masks of the same length.
///
/// Two empty masks (empty union) agree perfectly: 1.
///
/// # Panics
/// If the lengths differ (a programming error, not a data error).
pub fn mask_iou(a: &[bool], b: &[bool]) -> f64 {
    assert_eq!(a.len(), b.len(), "mask_iou: masks of different lengths");
    let (mut inter, mut union) = (0usize, 0usize);
    for (&x, &y) in a.iter().zip(b) {
        inter += usize::from(x && y);
        union += usize::from(x || y);
    }
    if union == 0 {
        1.0
    } else {
        inter as f64 / union as f64
    }
}

/// The result of [`aligned_texture_score`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AlignedScore {
    /// PSNR in dB of the sRGB-encoded textures (peak 1) at the best alignment;
    /// `+inf` for an exact match, NaN for an empty image.
    pub psnr_db: f64,
    /// The best cyclic shift `(rows, cols)`: extracted texel `(r, c)` is
    /// compared with texel `((r + rows) mod H, (c + cols) mod W)` of the truth
    /// resampled to `H × W = round(scale·h) × round(scale·w)` on a grid moved
    /// by [`offset`](Self::offset). At scales over 1 (one period of the truth
    /// spans more than the extracted texture) the roles swap: every texel
    /// `(R, C)` of the resampled truth is compared with extracted texel
    /// `((R + rows) mod h, (C + cols) mod w)`, i.e. with the texture tiled.
    pub shift: (usize, usize),
    /// The sub-texel part of the alignment `(rows, cols)`, in extracted
    /// texels (each in `(−1, 1)`, 0 along an axis where the truth is not at
    /// least [`SUBTEXEL_MIN_RATIO`] times finer than the resampled grid): the
    /// truth's resampled grid is moved by it (see the module docs).
    pub offset: (f64, f64),
    /// The best scale (one of [`ALIGN_SCALES`]): one period of the truth
    /// spans `scale` times the extracted texture (0.5: the truth appears
    /// tiled 2×2).
    pub scale: f64,
    /// Colour-statistics distance (alignment-free), see [`colour_distance`].
    pub colour_distance: f64,
}

/// Scores an extracted tileable texture against the true source texture,
/// ignoring the unknown offset and scale of the tiling (see the module docs).
///
/// Both images hold **linear** values (1 channel is treated as grey, only
/// the first 3 channels are used) and are sRGB-encoded before comparing;
/// their sizes may differ. An empty image gives NaN scores.
pub fn aligned_texture_score(extracted: &Image, truth: &Image) -> AlignedScore {
    score_turns(extracted, truth, 1)[0]
}

/// The truth's resampled candidates (one pyramid per [`ALIGN_SCALES`]
/// entry), made for the size and pyramid depth of the first extracted image
/// that needs them and kept for the next of the same size.
struct Candidates<'a> {
    truth: &'a Image,
    /// `(height, width, levels)` and one pyramid per scale.
    made: Vec<(SizeKey, Vec<Vec<Image>>)>,
    /// The truth tiled `k × k` for the scales `1/k` ([`whole_periods`]).
    tiled: &'a [(usize, Image)],
}

/// `k` when `scale` is `1/k` for a whole `k ≥ 2` (the extracted texture
/// holds `k × k` periods of the truth), else `None`.
fn whole_periods(scale: f64) -> Option<usize> {
    let k = (1.0 / scale).round();
    (k >= 2.0 && (k * scale - 1.0).abs() < 1e-9).then_some(k as usize)
}

/// The truth the scale `s` resamples: `truth` itself, or `truth` tiled
/// `k × k` (from `tiled`) for `s = 1/k` ([`whole_periods`]), where the
/// extracted texture is compared with exactly `k` periods resampled to its
/// own size: a cyclic roll of the texture then only moves the best shift (a
/// window of the truth resampled to `round(s·h)` texels a period was not
/// invariant, by up to 0.6 dB, where `s·h` is not whole).
fn source<'a>(truth: &'a Image, tiled: &'a [(usize, Image)], s: f64) -> &'a Image {
    whole_periods(s)
        .and_then(|k| tiled.iter().find(|(t, _)| *t == k))
        .map_or(truth, |(_, img)| img)
}

/// `img` repeated `k × k` times.
fn tile_image(img: &Image, k: usize) -> Image {
    let (h, w, c) = (img.height, img.width, img.channels);
    let (th, tw) = (k * h, k * w);
    let mut data = vec![0.0f32; c * th * tw];
    for ch in 0..c {
        let src = img.plane(ch);
        for y in 0..th {
            let row = &src[(y % h) * w..(y % h + 1) * w];
            let out = &mut data[(ch * th + y) * tw..(ch * th + y + 1) * tw];
            for (x, o) in out.iter_mut().enumerate() {
                *o = row[x % w];
            }
        }
    }
    Image::new(c, th, tw, data).expect("k·h × k·w values per channel")
}

/// An extracted image's `(height, width, pyramid levels)`.
type SizeKey = (usize, usize, usize);

impl Candidates<'_> {
    /// The resampled size for scale `s` at an extracted `h × w`.
    fn size(s: f64, h: usize, w: usize) -> (usize, usize) {
        if whole_periods(s).is_some() {
            return (h, w);
        }
        (
            ((s * h as f64).round() as usize).max(1),
            ((s * w as f64).round() as usize).max(1),
        )
    }

    fn for_size(&mut self, h: usize, w: usize, levels: usize) -> &[Vec<Image>] {
        let key = (h, w, levels);
        if let Some(k) = self.made.iter().position(|(k, _)| *k == key) {
            return &self.made[k].1;
        }
        let pyramids = ALIGN_SCALES
            .iter()
            .map(|&s| {
                let (hc, wc) = Self::size(s, h, w);
                // Resample in linear light, then encode.
                pyramid(
                    &srgb3(&resize(source(self.truth, self.tiled, s), hc, wc, true)),
                    levels,
                )
            })
            .collect();
        self.made.push((key, pyramids));
        &self.made.last().expect("just pushed").1
    }
}

/// [`aligned_texture_score`] of `extracted` turned by 0, 1, …, `turns − 1`
/// clockwise quarter turns, the truth's resampled candidates made once per
/// size and the colour distance (which no turn changes) once.
fn score_turns(extracted: &Image, truth: &Image, turns: usize) -> Vec<AlignedScore> {
    let empty = |i: &Image| i.width == 0 || i.height == 0 || i.channels == 0;
    if empty(extracted) || empty(truth) {
        let nan = AlignedScore {
            psnr_db: f64::NAN,
            shift: (0, 0),
            offset: (0.0, 0.0),
            scale: 1.0,
            colour_distance: f64::NAN,
        };
        return vec![nan; turns];
    }
    let e0 = srgb3(extracted);
    let t = three(truth);
    let colour_distance = colour_distance_srgb(&e0, &srgb3(&t));
    let tiled: Vec<(usize, Image)> = ALIGN_SCALES
        .iter()
        .filter_map(|&s| whole_periods(s))
        .map(|k| (k, tile_image(&t, k)))
        .collect();
    let mut cands = Candidates {
        truth: &t,
        made: Vec::new(),
        tiled: &tiled,
    };
    (0..turns)
        .map(|k| {
            let e = if k == 0 {
                e0.clone()
            } else {
                quarter_turn(&e0, k)
            };
            let e_pyr = pyramid(&e, levels(e.height, e.width));
            let c_pyrs = cands.for_size(e.height, e.width, e_pyr.len() - 1);
            // Where the truth's period spans more than the extracted texture
            // (scales over 1), the whole period is compared with the
            // extracted texture tiled, as an artist uses it: any cyclic roll
            // of the texture is then the same texture, at another shift.
            let whole: Vec<(f64, (usize, usize))> = c_pyrs
                .iter()
                .map(|c_pyr| {
                    if tiles(&e, (c_pyr[0].height, c_pyr[0].width)) {
                        best_shift_phased(c_pyr, &e_pyr)
                    } else {
                        best_shift_phased(&e_pyr, c_pyr)
                    }
                })
                .collect();
            let least = whole.iter().map(|w| w.0).fold(f64::INFINITY, f64::min);
            // Scales within SUBTEXEL_SCALE_MARGIN of the best whole-texel
            // alignment get their sub-texel search; ties keep the first scale.
            let mut best: Option<(Aligned, f64)> = None;
            for ((&s, c_pyr), &(mse, shift)) in ALIGN_SCALES.iter().zip(c_pyrs).zip(&whole) {
                let cand = if mse <= least * SUBTEXEL_SCALE_MARGIN {
                    let src = source(&t, &tiled, s);
                    subtexel(&e, src, (c_pyr[0].height, c_pyr[0].width), (mse, shift))
                } else {
                    (mse, shift, (0.0, 0.0))
                };
                if best.is_none_or(|(b, _)| cand.0 < b.0) {
                    best = Some((cand, s));
                }
            }
            let ((mse, shift, offset), scale) =
                best.unwrap_or(((f64::NAN, (0, 0), (0.0, 0.0)), 1.0));
            AlignedScore {
                psnr_db: psnr_from_mse(mse),
                shift,
                offset,
                scale,
                colour_distance,
            }
        })
        .collect()
}

/// `img` turned by `quarter_turns` × 90° clockwise (0–3; larger values wrap).
pub fn quarter_turn(img: &Image, quarter_turns: usize) -> Image {
    let (h, w, c) = (img.height, img.width, img.channels);
    let k = quarter_turns % 4;
    let (oh, ow) = if k.is_multiple_of(2) { (h, w) } else { (w, h) };
    let mut data = vec![0.0f32; c * oh * ow];
    for ch in 0..c {
        let src = img.plane(ch);
        let dst = &mut data[ch * oh * ow..(ch + 1) * oh * ow];
        for y in 0..oh {
            for x in 0..ow {
                // Output (y, x) reads the source texel that lands there.
                let (sy, sx) = match k {
                    0 => (y, x),
                    1 => (h - 1 - x, y),
                    2 => (h - 1 - y, w - 1 - x),
                    _ => (x, w - 1 - y),
                };
                dst[y * ow + x] = src[sy * w + sx];
            }
        }
    }
    Image::new(c, oh, ow, data).expect("same number of values")
}

/// [`aligned_texture_score`] of `extracted` as it is and at each of its
/// four quarter turns: `(unturned, best, clockwise quarter turns of the
/// best)` (ties keep the fewest turns). For a texture whose orientation is
/// a choice, not a measurement: a rectified plane's axes are turned to the
/// nearest axis of the region's lines or grain, which may be the truth's
/// other axis.
pub fn turned_texture_score(
    extracted: &Image,
    truth: &Image,
) -> (AlignedScore, AlignedScore, usize) {
    let scores = score_turns(extracted, truth, 4);
    let mut best = 0;
    for k in 1..4 {
        if scores[k].psnr_db > scores[best].psnr_db {
            best = k;
        }
    }
    (scores[0], scores[best], best)
}

/// `10·log10(1 / mse)` (peak 1); `+inf` for 0.
fn psnr_from_mse(mse: f64) -> f64 {
    if mse <= 0.0 {
        f64::INFINITY
    } else {
        -10.0 * mse.log10()
    }
}

/// A colour-statistics distance between two images of **linear** values
/// (any sizes; 1 channel treated as grey): [`picker_inpaint::colour_stats_distance`]
/// (per-channel mean and standard deviation gaps plus the total-variation
/// distance of the joint colour histograms) of their sRGB encodings, so that
/// the inpainting tests and the evaluation use one definition. 0 for identical
/// statistics. NaN for an empty image.
pub fn colour_distance(a: &Image, b: &Image) -> f64 {
    let empty = |i: &Image| i.width == 0 || i.height == 0 || i.channels == 0;
    if empty(a) || empty(b) {
        return f64::NAN;
    }
    colour_distance_srgb(&srgb3(a), &srgb3(b))
}

fn colour_distance_srgb(a: &Image, b: &Image) -> f64 {
    picker_inpaint::colour_stats_distance(a, b)
}

/// RMSE of linear albedos over the texels where `mask` is true, over the
/// first `min(channels)` channels. NaN for an empty mask.
///
/// # Panics
/// If the image sizes or the mask length disagree.
pub fn albedo_error(pred: &Image, truth: &Image, mask: &[bool]) -> f64 {
    check_same(pred, truth, mask, "albedo_error");
    let n = pred.plane_len();
    let c = pred.channels.min(truth.channels);
    let (mut sum, mut count) = (0.0f64, 0usize);
    for (i, _) in mask.iter().enumerate().filter(|(_, &m)| m) {
        for ch in 0..c {
            let d = f64::from(pred.data[ch * n + i]) - f64::from(truth.data[ch * n + i]);
            sum += d * d;
            count += 1;
        }
    }
    if count == 0 {
        f64::NAN
    } else {
        (sum / count as f64).sqrt()
    }
}

/// Mean angle in degrees between the normals of `pred` and `truth` (3-channel
/// direction images; both are renormalised) over the texels where `mask` is
/// true. A zero-length normal on either side counts as 90°. NaN for an empty mask.
///
/// # Panics
/// If the image sizes or the mask length disagree, or an image has fewer than 3 channels.
pub fn normal_error_deg(pred: &Image, truth: &Image, mask: &[bool]) -> f64 {
    check_same(pred, truth, mask, "normal_error_deg");
    assert!(
        pred.channels >= 3 && truth.channels >= 3,
        "normal_error_deg: normals need 3 channels"
    );
    let n = pred.plane_len();
    let v = |img: &Image, i: usize| [0, 1, 2].map(|c| f64::from(img.data[c * n + i]));
    let (mut sum, mut count) = (0.0f64, 0usize);
    for (i, _) in mask.iter().enumerate().filter(|(_, &m)| m) {
        let (a, b) = (v(pred, i), v(truth, i));
        let la = a.iter().map(|x| x * x).sum::<f64>().sqrt();
        let lb = b.iter().map(|x| x * x).sum::<f64>().sqrt();
        let angle = if la > 0.0 && lb > 0.0 && la.is_finite() && lb.is_finite() {
            let cos = (a[0] * b[0] + a[1] * b[1] + a[2] * b[2]) / (la * lb);
            cos.clamp(-1.0, 1.0).acos().to_degrees()
        } else {
            90.0
        };
        sum += angle;
        count += 1;
    }
    if count == 0 {
        f64::NAN
    } else {
        sum / count as f64
    }
}

fn check_same(a: &Image, b: &Image, mask: &[bool], what: &str) {
    assert!(
        a.height == b.height && a.width == b.width,
        "{what}: images of different sizes ({}x{} vs {}x{})",
        a.height,
        a.width,
        b.height,
        b.width
    );
    assert_eq!(mask.len(), a.plane_len(), "{what}: mask length");
}

/// Three planes of sRGB-encoded values (grey repeated; extra channels dropped).
fn srgb3(img: &Image) -> Image {
    three(img).map(srgb_encode)
}

/// Three planes of the same values (grey repeated; extra channels dropped).
fn three(img: &Image) -> Image {
    let n = img.plane_len();
    let mut data = Vec::with_capacity(3 * n);
    for c in 0..3 {
        data.extend_from_slice(img.plane(c.min(img.channels - 1)));
    }
    Image {
        channels: 3,
        height: img.height,
        width: img.width,
        data,
    }
}

/// Number of halvings until the smaller side drops below [`COARSEST_SIDE`].
fn levels(h: usize, w: usize) -> usize {
    let mut side = h.min(w);
    let mut l = 0;
    while side >= COARSEST_SIDE {
        side = side.div_ceil(2);
        l += 1;
    }
    l
}

/// `img` and `levels` successive box-filtered halvings (sides rounded up).
fn pyramid(img: &Image, levels: usize) -> Vec<Image> {
    let mut out = vec![img.clone()];
    for _ in 0..levels {
        let last = &out[out.len() - 1];
        let next = resize(last, last.height.div_ceil(2), last.width.div_ceil(2), true);
        out.push(next);
    }
    out
}

/// A periodic image extended so that any `h × w` window at a cyclic shift is
/// contiguous: `(H + h − 1) × (W + w − 1)` texels, `ext[R][C] = img[R mod H][C mod W]`.
struct Extended {
    planes: Vec<Vec<f32>>,
    height: usize,
    width: usize,
    period: (usize, usize),
}

impl Extended {
    fn new(img: &Image, h: usize, w: usize) -> Self {
        let (ph, pw) = (img.height, img.width);
        let (eh, ew) = (ph + h - 1, pw + w - 1);
        let planes = (0..img.channels)
            .map(|c| {
                let p = img.plane(c);
                let mut out = Vec::with_capacity(eh * ew);
                for r in 0..eh {
                    let row = &p[(r % ph) * pw..(r % ph + 1) * pw];
                    out.extend((0..ew).map(|x| row[x % pw]));
                }
                out
            })
            .collect();
        Self {
            planes,
            height: eh,
            width: ew,
            period: (ph, pw),
        }
    }

    /// Mean squared difference between `e` and the window at shift `(dy, dx)`.
    fn mse(&self, e: &Image, dy: usize, dx: usize) -> f64 {
        let (h, w) = (e.height, e.width);
        debug_assert!(dy + h <= self.height && dx + w <= self.width);
        let mut total = 0.0f64;
        for (c, plane) in self.planes.iter().enumerate() {
            let ep = e.plane(c);
            for r in 0..h {
                let a = &ep[r * w..(r + 1) * w];
                let start = (r + dy) * self.width + dx;
                let b = &plane[start..start + w];
                let row: f32 = a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum();
                total += f64::from(row);
            }
        }
        total / (self.planes.len() * h * w) as f64
    }
}

/// [`best_shift`] of `win_pyr` and of the window rolled by one texel down,
/// across and both (each coarse level sees every other shift at half-texel
/// misalignment, where a finely patterned texture can rank its true shift
/// below a shift by a whole number of periods of the truth; one of the four
/// phases sees it aligned), the best of the four mapped back to the unrolled
/// window (ties keep the unrolled one). A single level is searched whole.
fn best_shift_phased(win_pyr: &[Image], per_pyr: &[Image]) -> (f64, (usize, usize)) {
    let mut best = best_shift(win_pyr, per_pyr);
    if win_pyr.len() < 2 {
        return best;
    }
    let (ph, pw) = (per_pyr[0].height, per_pyr[0].width);
    for (ry, rx) in [(1usize, 0usize), (0, 1), (1, 1)] {
        let rolled = crate::pipeline::roll(&win_pyr[0], [rx, ry]);
        let (m, (sy, sx)) = best_shift(&pyramid(&rolled, win_pyr.len() - 1), per_pyr);
        if m < best.0 {
            best = (m, ((sy + ph - ry % ph) % ph, (sx + pw - rx % pw) % pw));
        }
    }
    best
}

/// The smallest mean squared error over cyclic shifts of the candidate
/// pyramid `c_pyr` against `e_pyr` (coarse to fine), and its shift at level 0.
fn best_shift(e_pyr: &[Image], c_pyr: &[Image]) -> (f64, (usize, usize)) {
    let top = e_pyr.len() - 1;
    let ext = Extended::new(&c_pyr[top], e_pyr[top].height, e_pyr[top].width);
    let (ph, pw) = ext.period;
    let mut scored: Vec<(f64, usize, usize)> = (0..ph)
        .into_par_iter()
        .flat_map_iter(|dy| {
            let ext = &ext;
            let e = &e_pyr[top];
            (0..pw).map(move |dx| (ext.mse(e, dy, dx), dy, dx))
        })
        .collect();
    keep_best(&mut scored);
    for level in (0..top).rev() {
        let e = &e_pyr[level];
        let ext = Extended::new(&c_pyr[level], e.height, e.width);
        let (ph, pw) = ext.period;
        let (qh, qw) = (c_pyr[level + 1].height, c_pyr[level + 1].width);
        let mut seen = HashSet::new();
        let mut next = Vec::new();
        for &(_, dy, dx) in &scored {
            let cy = (dy as f64 * ph as f64 / qh as f64).round() as i64;
            let cx = (dx as f64 * pw as f64 / qw as f64).round() as i64;
            for oy in -ALIGN_REFINE_RADIUS..=ALIGN_REFINE_RADIUS {
                for ox in -ALIGN_REFINE_RADIUS..=ALIGN_REFINE_RADIUS {
                    let y = (cy + oy).rem_euclid(ph as i64) as usize;
                    let x = (cx + ox).rem_euclid(pw as i64) as usize;
                    if seen.insert((y, x)) {
                        next.push((y, x));
                    }
                }
            }
        }
        scored = next
            .into_par_iter()
            .map(|(y, x)| (ext.mse(e, y, x), y, x))
            .collect();
        keep_best(&mut scored);
    }
    scored
        .first()
        .map(|&(m, y, x)| (m, (y, x)))
        .unwrap_or((f64::NAN, (0, 0)))
}

/// The sub-texel refinement of a whole-texel alignment `(mse, shift)` of
/// `e` (sRGB) against the linear `truth` resampled to `(hc, wc)`: a pattern
/// search over the resampled grid's offset (steps ½, ¼, ⅛ texel along the axes
/// where the truth is at least [`SUBTEXEL_MIN_RATIO`] times finer), each offset
/// scored at the whole shifts within one texel of the best so far. Returns
/// `(mse, shift, offset)`; never worse than the input.
fn subtexel(
    e: &Image,
    truth: &Image,
    (hc, wc): (usize, usize),
    (mse, shift): (f64, (usize, usize)),
) -> Aligned {
    let fine = |src: usize, dst: usize| src as f64 >= SUBTEXEL_MIN_RATIO * dst as f64;
    let (fy, fx) = (fine(truth.height, hc), fine(truth.width, wc));
    let mut best = (mse, shift, (0.0, 0.0));
    if !fy && !fx {
        return best;
    }
    // The periodic side of the comparison (see `tiles`): the extracted
    // texture tiled, made once, or each offset's resampled truth.
    let tiled = tiles(e, (hc, wc)).then(|| Extended::new(e, hc, wc));
    let period = if tiled.is_some() {
        (e.height, e.width)
    } else {
        (hc, wc)
    };
    // Scores one offset at the whole shifts around the best shift so far.
    let score = |off: (f64, f64), around: (usize, usize)| {
        let cand = srgb3(&resize_periodic_at(truth, hc, wc, off));
        let own;
        let (ext, window) = match &tiled {
            Some(ext) => (ext, &cand),
            None => {
                own = Extended::new(&cand, e.height, e.width);
                (&own, e)
            }
        };
        let mut out: Option<(f64, (usize, usize))> = None;
        for dy in -1i64..=1 {
            for dx in -1i64..=1 {
                let y = (around.0 as i64 + dy).rem_euclid(period.0 as i64) as usize;
                let x = (around.1 as i64 + dx).rem_euclid(period.1 as i64) as usize;
                let m = ext.mse(window, y, x);
                if out.is_none_or(|(b, _)| m < b) {
                    out = Some((m, (y, x)));
                }
            }
        }
        out.expect("nine shifts scored")
    };
    for step in [0.5, 0.25, 0.125] {
        let centre = best;
        let mut moves = Vec::new();
        for sy in [-1.0, 0.0, 1.0] {
            for sx in [-1.0, 0.0, 1.0] {
                let (my, mx) = (
                    if fy { sy * step } else { 0.0 },
                    if fx { sx * step } else { 0.0 },
                );
                if (my, mx) != (0.0, 0.0) && !moves.contains(&(my, mx)) {
                    moves.push((my, mx));
                }
            }
        }
        let scored: Vec<_> = moves
            .into_par_iter()
            .map(|(my, mx)| {
                let off = (centre.2 .0 + my, centre.2 .1 + mx);
                let (m, s) = score(off, centre.1);
                (m, s, off)
            })
            .collect();
        for cand in scored {
            if cand.0 < best.0 {
                best = cand;
            }
        }
    }
    best
}

/// True when the truth resampled to `(hc, wc)` spans more than the
/// extracted texture `e` (a scale over 1): the comparison is then of the
/// whole resampled truth with `e` tiled, not of `e` with a window of it.
fn tiles(e: &Image, (hc, wc): (usize, usize)) -> bool {
    hc > e.height || wc > e.width
}

/// An alignment and its error: `(mse, whole shift, sub-texel offset)`.
type Aligned = (f64, (usize, usize), (f64, f64));

/// Sorts by error (then shift, for determinism) and keeps [`ALIGN_CANDIDATES`].
fn keep_best(scored: &mut Vec<(f64, usize, usize)>) {
    scored.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)).then(a.2.cmp(&b.2)));
    scored.truncate(ALIGN_CANDIDATES);
}
