//! The network segmentation smoothed along the photo before masks are cut
//! from it: a joint (cross) bilateral filter whose range weight compares
//! the *photo's* colours, so each pixel's segmentation colour becomes the
//! mean over the photo-alike pixels around it.
//!
//! Why: the MSN's colours are noisy inside a material and soft across its
//! edges; thresholding them ([`crate::mask`]) loses pixels inside and leaks
//! at the edges. Averaging over a wide window of pixels that look alike in
//! the photo flattens the inside of a material (they share its look) and
//! does not mix two materials that look different. Ground-truth
//! segmentations are exact and are not smoothed ([`crate::Inputs`]).
//!
//! Measured with the embedded `lite` networks (`picker eval --embedded`,
//! every material ≥ 5 % of the image picked at its most interior pixel),
//! mean pick-mask IoU without → with: see [`SMOOTH_SIGMA_RANGE`].

use crate::{Error, Result};
use picker_render::Image;
use picker_tensor::Isa;
use rayon::prelude::*;

/// Range σ of the photo-colour weight, on `√linear` RGB (close to display
/// values), per channel distance summed over the three.
///
/// Measured with the embedded networks (mean mask IoU, without → with the
/// smoothing at σ_r = 0.07, σ_s = 1/30 of the shorter side): test split's
/// first 100 scenes 0.680 → 0.720, procedural seeds 4242 / 9191 / 6161
/// 0.678 / 0.676 / 0.688 → 0.714 / 0.728 / 0.727, seed 5151 (photographic
/// textures) 0.742 → 0.764, 40 Blender Cycles scenes 0.596 → 0.621. In the
/// sweep σ_r 0.05–0.15 and σ_s 5–12 px (at 240×320) all gained on every
/// set; wider windows gained more up to ~8 px.
pub const SMOOTH_SIGMA_RANGE: f32 = 0.07;

/// Spatial σ of the smoothing as a fraction of the image's shorter side
/// (8 px at the default 240×320 working size).
pub const SMOOTH_SIGMA_SPACE: f32 = 1.0 / 30.0;

/// The window reaches 2σ_s on each side, sampled on a grid of this many
/// taps per side of the centre, so the cost does not grow with the image
/// size (17×17 taps; sparser than every pixel: the sweep gave the same
/// figures with every pixel and every second one).
pub const SMOOTH_TAPS_PER_SIDE: usize = 8;

/// The filter's geometry for an image of `w×h`: spatial σ (pixels), tap
/// step (pixels) and radius (pixels, a multiple of the step).
pub fn smooth_geometry(w: usize, h: usize) -> (f32, usize, usize) {
    let sigma = (w.min(h) as f32 * SMOOTH_SIGMA_SPACE).max(0.5);
    let reach = (2.0 * sigma).ceil() as usize;
    let step = reach.div_ceil(SMOOTH_TAPS_PER_SIDE).max(1);
    (sigma, step, (reach / step) * step)
}

fn check(seg: &Image, photo: &Image, valid: &[bool]) -> Result<()> {
    let (w, h) = (seg.width, seg.height);
    if seg.channels != 3 || photo.channels != 3 || photo.width != w || photo.height != h {
        return Err(Error::Shape {
            what: "segmentation and photo for the smoothing".into(),
            expected: format!("3 channels each at {w}x{h}"),
            found: format!(
                "segmentation {} channels, photo {} channels at {}x{}",
                seg.channels, photo.channels, photo.width, photo.height
            ),
        });
    }
    if valid.len() != w * h {
        return Err(Error::Shape {
            what: "validity mask for the smoothing".into(),
            expected: format!("{} values", w * h),
            found: format!("{}", valid.len()),
        });
    }
    Ok(())
}

/// `e^x` for `x ≤ 0` (clamped at −87), branch-free so that loops over it
/// vectorise: `2^(x·log₂e)` split into the nearest integer `n` (by the
/// 1.5·2²³ rounding trick, whose low mantissa bits then hold `n`) and the
/// fraction in `[−½, ½]`; `2^n` built in the exponent bits, `2^f` a degree-6
/// Taylor polynomial of `e^(f·ln2)`. Relative error < 1e-5 against
/// `f32::exp` (most of it the rounding of `x·log₂e` near −87).
#[inline(always)]
fn exp_neg(x: f32) -> f32 {
    const MAGIC: f32 = 12_582_912.0; // 1.5·2²³
    let t = x.clamp(-87.0, 0.0) * std::f32::consts::LOG2_E;
    let r = t + MAGIC;
    let f = t - (r - MAGIC);
    let n = r.to_bits() as i32 - MAGIC.to_bits() as i32;
    let u = f * std::f32::consts::LN_2;
    let mut p = 1.0 / 720.0;
    for c in [1.0 / 120.0, 1.0 / 24.0, 1.0 / 6.0, 0.5, 1.0, 1.0] {
        p = p * u + c;
    }
    f32::from_bits(((n + 127) as u32) << 23) * p
}

/// Guide values: `√` of the linear photo, clamped at 0.
fn guide(photo: &Image) -> Vec<f32> {
    photo.data.iter().map(|&v| v.max(0.0).sqrt()).collect()
}

/// The segmentation `seg` (3 channels) smoothed along the linear photo
/// `photo` (3 channels, the same size): each valid pixel becomes the
/// weighted mean of the valid pixels on the tap grid around it
/// ([`smooth_geometry`]), weights `exp(−d²/2σ_s² − Σ_c (g_c − g'_c)²/2σ_r²)`
/// with `g = √photo`. Invalid pixels (`valid[i]` false: no surface) keep
/// their values and weigh nothing. Each row is computed on its own, in a
/// fixed order, so the result does not depend on the thread count.
pub fn smooth_segmentation(seg: &Image, photo: &Image, valid: &[bool]) -> Result<Image> {
    smooth_with(seg, photo, valid, Isa::best())
}

/// [`smooth_segmentation`] with the row loop compiled for `isa`, which this
/// CPU must have.
fn smooth_with(seg: &Image, photo: &Image, valid: &[bool], isa: Isa) -> Result<Image> {
    check(seg, photo, valid)?;
    let (w, h) = (seg.width, seg.height);
    let n = w * h;
    let (sigma, step, radius) = smooth_geometry(w, h);
    let g = guide(photo);
    let vf: Vec<f32> = valid.iter().map(|&v| f32::from(u8::from(v))).collect();
    let kr = 1.0 / (2.0 * SMOOTH_SIGMA_RANGE * SMOOTH_SIGMA_RANGE);
    let ks = 1.0 / (2.0 * sigma * sigma);
    let r = radius as i64;
    let taps: Vec<(i64, i64, f32)> = (-r..=r)
        .step_by(step)
        .flat_map(|dy| (-r..=r).step_by(step).map(move |dx| (dy, dx)))
        .map(|(dy, dx)| (dy, dx, (-((dy * dy + dx * dx) as f32) * ks).exp()))
        .collect();
    let ctx = Rows {
        w,
        h,
        g: &g,
        seg: &seg.data,
        vf: &vf,
        taps: &taps,
        kr,
    };
    let mut out = seg.clone();
    let rows: Vec<Vec<f32>> = (0..h)
        .into_par_iter()
        .map(|y| {
            let mut acc = vec![0f32; 4 * w];
            smooth_row_isa(isa, &ctx, y, &mut acc);
            acc
        })
        .collect();
    for (y, acc) in rows.iter().enumerate() {
        for x in 0..w {
            let i = y * w + x;
            let s = acc[3 * w + x];
            if valid[i] && s > 0.0 {
                for ch in 0..3 {
                    out.data[ch * n + i] = acc[ch * w + x] / s;
                }
            }
        }
    }
    Ok(out)
}

/// What every row of [`smooth_segmentation`] reads.
struct Rows<'a> {
    w: usize,
    h: usize,
    /// The guide, planar.
    g: &'a [f32],
    /// The segmentation, planar.
    seg: &'a [f32],
    /// 1 where valid, else 0.
    vf: &'a [f32],
    /// `(dy, dx, spatial weight)`.
    taps: &'a [(i64, i64, f32)],
    /// `1/(2σ_r²)`.
    kr: f32,
}

picker_tensor::per_isa! {
    /// [`smooth_row`] compiled for `isa`'s registers (AVX-512, AVX2 + FMA or
    /// the baseline): the same operations in the same order, so the same bits.
    fn smooth_row_isa<'a>(ctx: &Rows<'a>, y: usize, acc: &mut [f32]) => smooth_row
}

/// Row `y` of [`smooth_segmentation`]: `acc` (4 planes of `w`) receives the
/// weighted sums of the three channels and the sum of the weights.
#[inline(always)]
fn smooth_row(ctx: &Rows<'_>, y: usize, acc: &mut [f32]) {
    let Rows {
        w,
        h,
        g,
        seg,
        vf,
        taps,
        kr,
    } = *ctx;
    let n = w * h;
    let (a, rest) = acc.split_at_mut(w);
    let (b, rest) = rest.split_at_mut(w);
    let (c, ws) = rest.split_at_mut(w);
    let row = y * w;
    let (g0, g1, g2) = (
        &g[row..row + w],
        &g[n + row..n + row + w],
        &g[2 * n + row..2 * n + row + w],
    );
    for &(dy, dx, wsp) in taps {
        let yy = y as i64 + dy;
        if yy < 0 || yy >= h as i64 {
            continue;
        }
        // Output columns x whose source x + dx lies inside.
        let x0 = (-dx).max(0) as usize;
        let x1 = (w as i64 - dx).min(w as i64);
        if x1 <= x0 as i64 {
            continue;
        }
        let x1 = x1 as usize;
        let src = yy as usize * w;
        let s0 = (src as i64 + x0 as i64 + dx) as usize;
        let len = x1 - x0;
        let (h0, h1, h2) = (
            &g[s0..s0 + len],
            &g[n + s0..n + s0 + len],
            &g[2 * n + s0..2 * n + s0 + len],
        );
        let (p0, p1, p2) = (
            &seg[s0..s0 + len],
            &seg[n + s0..n + s0 + len],
            &seg[2 * n + s0..2 * n + s0 + len],
        );
        let vv = &vf[s0..s0 + len];
        // Equal-length slices: the loop runs without bounds checks
        // and vectorises.
        let (q0, q1, q2) = (&g0[x0..x1], &g1[x0..x1], &g2[x0..x1]);
        let (oa, ob) = (&mut a[x0..x1], &mut b[x0..x1]);
        let (oc, ow) = (&mut c[x0..x1], &mut ws[x0..x1]);
        for k in 0..len {
            let d0 = q0[k] - h0[k];
            let d1 = q1[k] - h1[k];
            let d2 = q2[k] - h2[k];
            let wt = wsp * vv[k] * exp_neg(-(d0 * d0 + d1 * d1 + d2 * d2) * kr);
            oa[k] += wt * p0[k];
            ob[k] += wt * p1[k];
            oc[k] += wt * p2[k];
            ow[k] += wt;
        }
    }
}

/// Plain reference of [`smooth_segmentation`]: the same taps and weights,
/// one pixel at a time, `f32::exp`, accumulated in `f64`.
pub fn smooth_segmentation_reference(seg: &Image, photo: &Image, valid: &[bool]) -> Result<Image> {
    check(seg, photo, valid)?;
    let (w, h) = (seg.width, seg.height);
    let n = w * h;
    let (sigma, step, radius) = smooth_geometry(w, h);
    let g = guide(photo);
    let mut out = seg.clone();
    let r = radius as i64;
    for y in 0..h as i64 {
        for x in 0..w as i64 {
            let i = (y as usize) * w + x as usize;
            if !valid[i] {
                continue;
            }
            let mut acc = [0f64; 3];
            let mut ws = 0f64;
            for dy in (-r..=r).step_by(step) {
                for dx in (-r..=r).step_by(step) {
                    let (yy, xx) = (y + dy, x + dx);
                    if yy < 0 || xx < 0 || yy >= h as i64 || xx >= w as i64 {
                        continue;
                    }
                    let j = (yy as usize) * w + xx as usize;
                    if !valid[j] {
                        continue;
                    }
                    let dc: f32 = (0..3).map(|c| (g[c * n + i] - g[c * n + j]).powi(2)).sum();
                    let wt = (-((dx * dx + dy * dy) as f32) / (2.0 * sigma * sigma)
                        - dc / (2.0 * SMOOTH_SIGMA_RANGE * SMOOTH_SIGMA_RANGE))
                        .exp() as f64;
                    for (c, a) in acc.iter_mut().enumerate() {
                        *a += wt * f64::from(seg.data[c * n + j]);
                    }
                    ws += wt;
                }
            }
            if ws > 0.0 {
                for (c, a) in acc.iter().enumerate() {
                    out.data[c * n + i] = (a / ws) as f32;
                }
            }
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Rng(u64);
    impl Rng {
        fn next(&mut self) -> f32 {
            self.0 = self
                .0
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((self.0 >> 40) as f32) / (1u64 << 24) as f32
        }
    }

    fn img(w: usize, h: usize, mut f: impl FnMut(usize, usize, usize) -> f32) -> Image {
        let mut data = Vec::with_capacity(3 * w * h);
        for c in 0..3 {
            for y in 0..h {
                for x in 0..w {
                    data.push(f(c, x, y));
                }
            }
        }
        Image::new(3, h, w, data).unwrap()
    }

    #[test]
    fn exp_neg_matches_exp() {
        let mut worst = 0f32;
        for k in 0..=200_000 {
            let x = -87.0 * k as f32 / 200_000.0;
            let (a, b) = (exp_neg(x), x.exp());
            if b > 0.0 {
                worst = worst.max(((a - b) / b).abs());
            }
        }
        assert!(worst < 1e-5, "worst relative error {worst}");
        assert_eq!(exp_neg(0.0), 1.0);
        assert!(exp_neg(-1e9) >= 0.0 && exp_neg(-1e9) < 1e-37);
    }

    #[test]
    fn fast_matches_reference_on_random_images() {
        // Shapes: 1×1, thin rows and columns, odd sizes, one bigger than the window.
        for (k, &(w, h)) in [
            (1, 1),
            (1, 9),
            (13, 1),
            (7, 5),
            (31, 17),
            (64, 48),
            (120, 90),
        ]
        .iter()
        .enumerate()
        {
            let mut rng = Rng(1000 + k as u64);
            let mut noise = |_: usize, _: usize, _: usize| rng.next();
            let seg = img(w, h, &mut noise);
            let mut rng2 = Rng(2000 + k as u64);
            let photo = img(w, h, |_, _, _| rng2.next() * rng2.next());
            let mut rng3 = Rng(3000 + k as u64);
            let valid: Vec<bool> = (0..w * h).map(|_| rng3.next() > 0.15).collect();
            let fast = smooth_segmentation(&seg, &photo, &valid).unwrap();
            let slow = smooth_segmentation_reference(&seg, &photo, &valid).unwrap();
            for (i, (a, b)) in fast.data.iter().zip(&slow.data).enumerate() {
                assert!((a - b).abs() < 2e-5, "{w}x{h} value {i}: {a} vs {b}");
            }
        }
    }

    #[test]
    fn every_isa_path_gives_the_portable_bits() {
        for isa in Isa::ALL {
            if !isa.is_available() {
                eprintln!("skipped: this CPU has no {isa}");
                continue;
            }
            for &(w, h) in &[(1, 1), (5, 3), (33, 21), (130, 70)] {
                let mut rng = Rng(w as u64 * 31 + h as u64);
                let seg = img(w, h, |_, _, _| rng.next());
                let photo = img(w, h, |_, _, _| rng.next());
                let valid: Vec<bool> = (0..w * h).map(|_| rng.next() > 0.1).collect();
                let a = smooth_with(&seg, &photo, &valid, isa).unwrap();
                let b = smooth_with(&seg, &photo, &valid, Isa::Portable).unwrap();
                assert_eq!(a.data, b.data, "{isa} {w}x{h}");
            }
        }
    }

    #[test]
    fn geometry_scales_with_the_image_and_keeps_the_tap_count() {
        assert_eq!(smooth_geometry(320, 240), (8.0, 2, 16));
        let (s, step, r) = smooth_geometry(640, 480);
        assert_eq!((s, step, r), (16.0, 4, 32));
        let (_, step, r) = smooth_geometry(1, 1);
        assert_eq!((step, r), (1, 1));
        for (w, h) in [(3, 3), (100, 37), (1000, 1000), (4000, 3000)] {
            let (_, step, r) = smooth_geometry(w, h);
            assert_eq!(r % step, 0);
            assert!(r / step <= SMOOTH_TAPS_PER_SIDE, "{w}x{h}");
        }
    }

    #[test]
    fn a_constant_segmentation_is_unchanged_and_noise_is_averaged_inside_a_material() {
        let (w, h) = (80, 60);
        let photo = img(w, h, |_, x, _| if x < 40 { 0.1 } else { 0.6 });
        let valid = vec![true; w * h];
        let flat = img(w, h, |c, _, _| 0.2 + 0.1 * c as f32);
        let s = smooth_segmentation(&flat, &photo, &valid).unwrap();
        for (a, b) in s.data.iter().zip(&flat.data) {
            assert!((a - b).abs() < 1e-6);
        }
        // Noisy segmentation (±0.1) of two materials that look different in the photo.
        let mut rng = Rng(7);
        let noisy = img(w, h, |_, x, _| {
            (if x < 40 { 0.3 } else { 0.7 }) + 0.2 * (rng.next() - 0.5)
        });
        let s = smooth_segmentation(&noisy, &photo, &valid).unwrap();
        let n = w * h;
        let spread = |im: &Image, lo: usize, hi: usize| {
            let v: Vec<f32> = (0..h)
                .flat_map(|y| (lo..hi).map(move |x| y * w + x))
                .map(|i| im.data[i])
                .collect();
            let m = v.iter().sum::<f32>() / v.len() as f32;
            (m, v.iter().map(|x| (x - m).abs()).fold(0f32, f32::max))
        };
        let (m_left, dev_left) = spread(&s, 0, 40);
        let (m_right, dev_right) = spread(&s, 40, 80);
        // The photo edge keeps the materials apart exactly: a step
        // of 0.5 in √photo weighs exp(-0.5²/(2·0.07²)) ≈ 1e-11.
        assert!(
            (m_left - 0.3).abs() < 0.01 && (m_right - 0.7).abs() < 0.01,
            "{m_left} {m_right}"
        );
        assert!(
            dev_left < 0.05 && dev_right < 0.05,
            "{dev_left} {dev_right}"
        );
        let (_, raw_dev) = spread(&noisy, 0, 40);
        assert!(raw_dev > 0.09);
        // Every channel is smoothed alike.
        for ch in 1..3 {
            let (a, b) = (s.data[ch * n + 20 * w + 10], s.data[20 * w + 10]);
            assert!((a - b).abs() < 0.05, "channel {ch}: {a} vs {b}");
        }
    }

    #[test]
    fn a_soft_edge_between_photo_alike_halves_is_not_invented_but_a_photo_edge_sharpens_it() {
        // The segmentation ramps from 0 to 1 over columns 150..170; the
        // photo steps at column 160: each side's ramp is pulled to its side
        // (320×240: σ_s = 8 px).
        let (w, h) = (320, 240);
        let seg = img(w, h, |_, x, _| ((x as f32 - 150.0) / 20.0).clamp(0.0, 1.0));
        let photo = img(w, h, |_, x, _| if x < 160 { 0.05 } else { 0.5 });
        let valid = vec![true; w * h];
        let s = smooth_segmentation(&seg, &photo, &valid).unwrap();
        let at = |x: usize| s.data[120 * w + x];
        let raw = |x: usize| seg.data[120 * w + x];
        assert!(at(158) < raw(158) - 0.1, "{}", at(158));
        assert!(at(161) > raw(161) + 0.1, "{}", at(161));
        assert!(at(161) - at(158) > 0.4, "{} {}", at(158), at(161));
        // Far from the edge on the flat side nothing changes.
        assert!(at(20).abs() < 1e-6 && (at(300) - 1.0).abs() < 1e-6);
    }

    #[test]
    fn invalid_pixels_keep_their_values_and_weigh_nothing() {
        let (w, h) = (20, 10);
        let seg = img(w, h, |_, x, _| if x < 10 { 0.2 } else { 9.0 });
        let photo = img(w, h, |_, _, _| 0.3);
        let valid: Vec<bool> = (0..w * h).map(|i| i % w < 10).collect();
        let s = smooth_segmentation(&seg, &photo, &valid).unwrap();
        for y in 0..h {
            for x in 0..w {
                let v = s.data[y * w + x];
                if x < 10 {
                    assert!((v - 0.2).abs() < 1e-6, "({x}, {y}) {v}");
                } else {
                    assert_eq!(v, 9.0);
                }
            }
        }
    }

    #[test]
    fn the_thread_count_does_not_change_a_bit() {
        let (w, h) = (97, 61);
        let mut rng = Rng(11);
        let seg = img(w, h, |_, _, _| rng.next());
        let mut rng = Rng(12);
        let photo = img(w, h, |_, _, _| rng.next());
        let valid = vec![true; w * h];
        let one = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        let a = one.install(|| smooth_segmentation(&seg, &photo, &valid).unwrap());
        let three = rayon::ThreadPoolBuilder::new()
            .num_threads(3)
            .build()
            .unwrap();
        let b = three.install(|| smooth_segmentation(&seg, &photo, &valid).unwrap());
        assert_eq!(a.data, b.data);
    }

    #[test]
    fn misshaped_inputs_are_refused() {
        let seg = img(4, 3, |_, _, _| 0.0);
        let photo = img(3, 4, |_, _, _| 0.0);
        assert!(smooth_segmentation(&seg, &photo, &[true; 12]).is_err());
        let photo = img(4, 3, |_, _, _| 0.0);
        assert!(smooth_segmentation(&seg, &photo, &[true; 11]).is_err());
        let grey = Image::new(1, 3, 4, vec![0.0; 12]).unwrap();
        assert!(smooth_segmentation(&grey, &photo, &[true; 12]).is_err());
        assert!(smooth_segmentation_reference(&grey, &photo, &[true; 12]).is_err());
    }
}
