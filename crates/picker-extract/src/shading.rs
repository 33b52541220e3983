//! The de-lighting's shading from a network's albedo: only its low
//! frequencies.
//!
//! The texture's colours are the photo de-lit: `photo × albedo ÷ photo`,
//! the ratio taken at the working resolution, where the networks run, and
//! carried onto the photo's own pixels ([`crate::pipeline`]). Where the photo
//! is no larger than the working resolution, that is the network's albedo
//! itself, whose detail is the network's (smoothed, with its own speckle)
//! rather than the photo's; larger photos still take the ratio's detail at
//! the working pixels' scale. A network's albedo gets its level and colour
//! from the whole scene, but the light does not change from pixel to pixel
//! on one surface: so the ratio (one over the shading) is taken over a
//! Gaussian window of the material's own pixels ([`SHADING_SIGMA`]), as the
//! ratio of the albedo's and the photo's local sums ([`delighting_ratio`];
//! the mean of the pixels' own ratios, [`smooth_in_mask`] of them, until
//! stop 54, let a print's dark channels tint its surroundings), and the
//! detail comes from the photo. Where the photo is clipped
//! ([`crate::pipeline::CLIPPED_SRGB`]) its detail is not the material's and
//! the network's albedo stands in. Ground-truth albedo is exact and is used
//! as it is ([`crate::Inputs::albedo_estimated`]).

use picker_render::Image;
use rayon::prelude::*;

/// σ, in working pixels, of the Gaussian window in which
/// [`delighting_ratio`] takes the de-lighting ratio of a network's albedo.
///
/// Measured (stop 51, with the mean of the pixels' ratios; stop 54's ratio
/// of sums re-checked at σ 2 and 8, README *The ratio of local sums*) with the embedded networks, `picker eval --embedded
/// --shading-sigma S` on proc-4242 / proc-9191 / proc-5151 (40 scenes
/// each), mean aligned texture PSNR and colour-statistics distance:
///
/// | σ | PSNR (dB) | colour distance |
/// |---|---|---|
/// | 0 (the network's albedo) | 18.397 / 18.876 / 19.434 | 0.988 / 0.939 / 0.939 |
/// | 1 | 17.909 / 18.461 / 19.151 | 0.964 / 0.910 / 0.926 |
/// | 2 | 17.908 / 18.356 / 19.222 | 0.962 / 0.906 / 0.931 |
/// | 4 | 18.045 / 18.423 / 19.279 | 0.970 / 0.906 / 0.929 |
///
/// The texture's statistics come closer to the truth's on every set; the
/// aligned PSNR falls, most on fine patterns the renders alias (two weaves
/// seen at a quarter of their texel density: −14.6 and −4.7 dB at σ 4, a flat mean
/// scoring better than the photo's moiré). Against the ground-truth albedo
/// pixel by pixel (8 scenes of proc-4242, 24 textured materials), the
/// de-lit photo's high-pass correlation with the truth's went from 0.50 (the
/// network's albedo) to 0.86 / 0.90 / 0.90 at σ 1 / 2 / 4, its PSNR after a
/// gain per channel from 27.4 to 29.0 / 29.5 / 30.1 dB. On real photos at
/// the working size the texture shows the photo's bricks, tiles and wood
/// grain instead of the network's smoothed, speckled albedo.
pub const SHADING_SIGMA: f32 = 4.0;

/// Taps each side of the centre per σ.
const REACH: f32 = 3.0;

/// The 1-D Gaussian of `sigma` (unnormalised; the weights normalise).
fn kernel(sigma: f32) -> Vec<f32> {
    let r = (REACH * sigma).ceil() as usize;
    (0..=2 * r)
        .map(|i| {
            let d = i as f32 - r as f32;
            (-d * d / (2.0 * sigma * sigma)).exp()
        })
        .collect()
}

/// `img` (any channels, `width × height`) smoothed by a Gaussian of `sigma`
/// pixels over the pixels with `weight > 0`, each weighted by it
/// (normalised convolution): every pixel becomes the weighted mean of the
/// weighted pixels around it, so pixels of weight 0 (another material, a
/// pixel without a reliable value) give nothing, and a pixel with none
/// around it keeps its value. The window reaches 3σ and stops at the
/// image's edges. `sigma ≤ 0` (or not finite) returns `img` unchanged.
///
/// # Panics
/// When `weight` does not hold one value per pixel.
pub fn smooth_in_mask(img: &Image, weight: &[f32], sigma: f32) -> Image {
    let (c, h, w) = (img.channels, img.height, img.width);
    assert_eq!(weight.len(), w * h, "smooth_in_mask: one weight per pixel");
    if !(sigma.is_finite() && sigma > 0.0) || w * h == 0 {
        return img.clone();
    }
    let k = kernel(sigma);
    let r = k.len() / 2;
    // Planes: the weighted channels, then the weight.
    let n = w * h;
    let mut planes = vec![0.0f32; (c + 1) * n];
    for (i, &wt) in weight.iter().enumerate() {
        let wt = wt.max(0.0);
        planes[c * n + i] = wt;
        for ch in 0..c {
            planes[ch * n + i] = img.data[ch * n + i] * wt;
        }
    }
    // Rows, then columns, each plane in turn.
    let mut tmp = vec![0.0f32; (c + 1) * n];
    planes
        .par_chunks(n)
        .zip(tmp.par_chunks_mut(n))
        .for_each(|(src, dst)| {
            for y in 0..h {
                let row = &src[y * w..(y + 1) * w];
                for x in 0..w {
                    let (lo, hi) = (x.saturating_sub(r), (x + r + 1).min(w));
                    dst[y * w + x] = (lo..hi).map(|xx| row[xx] * k[xx + r - x]).sum();
                }
            }
        });
    tmp.par_chunks(n)
        .zip(planes.par_chunks_mut(n))
        .for_each(|(src, dst)| {
            for y in 0..h {
                let (lo, hi) = (y.saturating_sub(r), (y + r + 1).min(h));
                for x in 0..w {
                    dst[y * w + x] = (lo..hi).map(|yy| src[yy * w + x] * k[yy + r - y]).sum();
                }
            }
        });
    let mut out = img.clone();
    for i in 0..n {
        let s = planes[c * n + i];
        if s > 0.0 {
            for ch in 0..c {
                out.data[ch * n + i] = planes[ch * n + i] / s;
            }
        }
    }
    out
}

/// Largest de-lighting ratio (albedo ÷ photo, per channel) kept: a photo
/// channel near black over a network's albedo is no measurement of the light.
pub const RATIO_MAX: f32 = 100.0;

/// The de-lighting ratio (one over the shading, per channel) at each pixel
/// of a `width × height` image: the network's `albedo` over the `photo`
/// (both linear RGB) as the ratio of their local sums, `Σ w·albedo ÷ Σ w·photo`
/// over a Gaussian of `sigma` pixels ([`smooth_in_mask`] of both, so the
/// same window and the same `weight`s), capped at [`RATIO_MAX`]. That is
/// the gain that maps the photo onto the albedo best in the window (least
/// squares, each pixel weighted by `w / photo`): where the photo is dark in
/// a channel — a red print's green and blue — the pixel says little about the
/// light in that channel and weighs little, where the mean of the pixels'
/// own ratios let a network's blurred, desaturated albedo over a few dark
/// pixels (a ratio of 30 in their green) tint a whole window around them:
/// a cyan halo around each red pip of a playing card. Pixels whose weighted
/// window is empty, or whose photo sum is 0 in a channel, get 0 there (no
/// ratio: callers read only weighted pixels). `sigma ≤ 0` (or not finite)
/// gives each weighted pixel its own ratio.
///
/// # Panics
/// When the images' sizes differ, are not 3 channels, or `weight` does not
/// hold one value per pixel.
pub fn delighting_ratio(albedo: &Image, photo: &Image, weight: &[f32], sigma: f32) -> Image {
    ratio_of_sums(albedo, photo, weight, sigma, smooth_in_mask)
}

/// The plain implementation of [`delighting_ratio`] (the sums by
/// [`smooth_in_mask_reference`]).
pub fn delighting_ratio_reference(
    albedo: &Image,
    photo: &Image,
    weight: &[f32],
    sigma: f32,
) -> Image {
    ratio_of_sums(albedo, photo, weight, sigma, smooth_in_mask_reference)
}

fn ratio_of_sums(
    albedo: &Image,
    photo: &Image,
    weight: &[f32],
    sigma: f32,
    smooth: fn(&Image, &[f32], f32) -> Image,
) -> Image {
    let (h, w) = (albedo.height, albedo.width);
    assert!(
        albedo.channels == 3 && photo.channels == 3 && (photo.height, photo.width) == (h, w),
        "delighting_ratio: two 3-channel images of one size"
    );
    assert_eq!(
        weight.len(),
        w * h,
        "delighting_ratio: one weight per pixel"
    );
    let n = w * h;
    // Both images as one six-plane image, so one pass smooths both alike;
    // unweighted pixels hold 0 (they are not read, and mark "no value").
    let mut both = Image {
        channels: 6,
        height: h,
        width: w,
        data: vec![0.0; 6 * n],
    };
    for i in (0..n).filter(|&i| weight[i] > 0.0) {
        for c in 0..3 {
            both.data[c * n + i] = albedo.data[c * n + i];
            both.data[(3 + c) * n + i] = photo.data[c * n + i];
        }
    }
    let smoothed = if sigma.is_finite() && sigma > 0.0 {
        smooth(&both, weight, sigma)
    } else {
        both
    };
    let mut out = Image {
        channels: 3,
        height: h,
        width: w,
        data: vec![0.0; 3 * n],
    };
    for c in 0..3 {
        let (a, rest) = smoothed.data[c * n..].split_at(n);
        let q = &rest[2 * n..3 * n];
        for ((o, &a), &q) in out.data[c * n..(c + 1) * n].iter_mut().zip(a).zip(q) {
            if q > 0.0 {
                *o = (a / q).min(RATIO_MAX);
            }
        }
    }
    out
}

/// The plain implementation of [`smooth_in_mask`]: the 2-D window summed
/// directly per pixel.
pub fn smooth_in_mask_reference(img: &Image, weight: &[f32], sigma: f32) -> Image {
    let (c, h, w) = (img.channels, img.height, img.width);
    assert_eq!(weight.len(), w * h, "smooth_in_mask: one weight per pixel");
    if !(sigma.is_finite() && sigma > 0.0) || w * h == 0 {
        return img.clone();
    }
    let k = kernel(sigma);
    let r = k.len() / 2;
    let n = w * h;
    let mut out = img.clone();
    for y in 0..h {
        for x in 0..w {
            let mut acc = vec![0.0f64; c];
            let mut s = 0.0f64;
            for yy in y.saturating_sub(r)..(y + r + 1).min(h) {
                for xx in x.saturating_sub(r)..(x + r + 1).min(w) {
                    let g = f64::from(k[xx + r - x]) * f64::from(k[yy + r - y]);
                    let wt = f64::from(weight[yy * w + xx].max(0.0)) * g;
                    s += wt;
                    for (ch, a) in acc.iter_mut().enumerate() {
                        *a += wt * f64::from(img.data[ch * n + yy * w + xx]);
                    }
                }
            }
            if s > 0.0 {
                for (ch, a) in acc.iter().enumerate() {
                    out.data[ch * n + y * w + x] = (a / s) as f32;
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use picker_tensor::Rng;

    fn random(rng: &mut Rng, c: usize, h: usize, w: usize) -> (Image, Vec<f32>) {
        let img = Image {
            channels: c,
            height: h,
            width: w,
            data: (0..c * h * w).map(|_| rng.uniform(0.0, 2.0)).collect(),
        };
        // About a third of the pixels without weight, the rest 0.2–1.
        let weight = (0..h * w)
            .map(|_| {
                let u = rng.uniform(0.0, 1.0);
                if u < 0.33 {
                    0.0
                } else {
                    0.2 + 0.8 * u
                }
            })
            .collect();
        (img, weight)
    }

    /// The separable version matches the plain 2-D sum on seeded random
    /// problems, edge shapes included (one pixel, one row or column, a
    /// window wider than the image).
    #[test]
    fn matches_the_reference() {
        let mut rng = Rng::new(11);
        let shapes = [
            (1, 1, 1),
            (3, 1, 7),
            (3, 9, 1),
            (1, 2, 2),
            (3, 13, 17),
            (2, 30, 40),
        ];
        for &(c, h, w) in &shapes {
            for sigma in [0.5f32, 1.0, 2.0, 7.5] {
                let (img, wt) = random(&mut rng, c, h, w);
                let a = smooth_in_mask(&img, &wt, sigma);
                let b = smooth_in_mask_reference(&img, &wt, sigma);
                for (i, (x, y)) in a.data.iter().zip(&b.data).enumerate() {
                    assert!(
                        (x - y).abs() <= 1e-4 * y.abs().max(1.0),
                        "{c}x{h}x{w} σ {sigma} at {i}: {x} vs {y}"
                    );
                }
            }
        }
    }

    /// A constant over the weighted pixels stays that constant there,
    /// whatever the unweighted pixels hold (another material's values do not
    /// leak in); a pixel with no weighted pixel in reach keeps its value;
    /// σ 0 changes nothing.
    #[test]
    fn weighted_pixels_only_are_averaged() {
        let (h, w) = (12, 16);
        let mut rng = Rng::new(3);
        let inside = |i: usize| (i % w) < 8;
        let img = Image {
            channels: 3,
            height: h,
            width: w,
            data: (0..3 * h * w)
                .map(|j| {
                    if inside(j % (h * w)) {
                        0.7
                    } else {
                        rng.uniform(5.0, 9.0)
                    }
                })
                .collect(),
        };
        let wt: Vec<f32> = (0..h * w).map(|i| f32::from(u8::from(inside(i)))).collect();
        let out = smooth_in_mask(&img, &wt, 2.0);
        for ch in 0..3 {
            for i in (0..h * w).filter(|&i| inside(i)) {
                assert!((out.data[ch * h * w + i] - 0.7).abs() < 1e-6);
            }
            // Column 15 is 8 columns from the weighted ones: beyond 3σ.
            for y in 0..h {
                let i = ch * h * w + y * w + 15;
                assert_eq!(out.data[i], img.data[i]);
            }
        }
        assert_eq!(smooth_in_mask(&img, &wt, 0.0), img);
        assert_eq!(smooth_in_mask(&img, &wt, f32::NAN), img);
    }

    fn rgb(rng: &mut Rng, h: usize, w: usize, lo: f32, hi: f32) -> Image {
        Image {
            channels: 3,
            height: h,
            width: w,
            data: (0..3 * h * w).map(|_| rng.uniform(lo, hi)).collect(),
        }
    }

    /// The separable ratio of sums matches the plain 2-D sums on seeded
    /// random problems (edge shapes included; σ 0 and NaN: each weighted
    /// pixel's own ratio), and is 0 exactly where no weighted pixel is in
    /// reach or the photo's sum is 0.
    #[test]
    fn delighting_ratio_matches_the_reference() {
        let mut rng = Rng::new(29);
        for &(h, w) in &[(1, 1), (1, 9), (8, 1), (2, 2), (13, 17), (30, 41)] {
            for sigma in [0.0f32, f32::NAN, 0.5, 1.0, 4.0, 9.0] {
                let (_, wt) = random(&mut rng, 1, h, w);
                let albedo = rgb(&mut rng, h, w, 0.0, 1.0);
                // Some photo values 0 (a black channel), the rest 0.01–1.
                let mut photo = rgb(&mut rng, h, w, 0.01, 1.0);
                for v in photo.data.iter_mut().step_by(7) {
                    *v = 0.0;
                }
                let a = delighting_ratio(&albedo, &photo, &wt, sigma);
                let b = delighting_ratio_reference(&albedo, &photo, &wt, sigma);
                for (i, (x, y)) in a.data.iter().zip(&b.data).enumerate() {
                    assert!(
                        (x - y).abs() <= 1e-4 * y.abs().max(1.0) && (*x == 0.0) == (*y == 0.0),
                        "{h}x{w} σ {sigma} at {i}: {x} vs {y}"
                    );
                    assert!((0.0..=RATIO_MAX).contains(x), "{x}");
                }
                if sigma.is_nan() || sigma <= 0.0 {
                    for (i, &wi) in wt.iter().enumerate() {
                        for c in 0..3 {
                            let n = h * w;
                            let (al, ph) = (albedo.data[c * n + i], photo.data[c * n + i]);
                            let want = if wi > 0.0 && ph > 0.0 {
                                (al / ph).min(RATIO_MAX)
                            } else {
                                0.0
                            };
                            assert_eq!(a.data[c * n + i], want, "{h}x{w} σ {sigma}");
                        }
                    }
                }
            }
        }
    }

    /// Where the network's albedo is the photo times one gain per channel
    /// (the light's colour, one over the shading), the ratio is that gain at
    /// every weighted pixel, whatever the photo's texture.
    #[test]
    fn a_uniform_light_is_recovered() {
        let mut rng = Rng::new(5);
        let (h, w) = (24, 31);
        let photo = rgb(&mut rng, h, w, 0.02, 1.0);
        let gain = [0.5f32, 0.8, 1.7];
        let n = h * w;
        let mut albedo = photo.clone();
        for (c, g) in gain.iter().enumerate() {
            albedo.data[c * n..(c + 1) * n]
                .iter_mut()
                .for_each(|v| *v *= g);
        }
        let (_, wt) = random(&mut rng, 1, h, w);
        let r = delighting_ratio(&albedo, &photo, &wt, 4.0);
        for i in (0..n).filter(|&i| wt[i] > 0.0) {
            for (c, g) in gain.iter().enumerate() {
                let v = r.data[c * n + i];
                assert!((v - g).abs() < 1e-4 * g, "{c} at {i}: {v}");
            }
        }
    }

    /// A saturated red dot on a white card whose network albedo is blurred
    /// and desaturated (green 0.15 over a photo green of 0.005: a pixel
    /// ratio of 30): the card around it keeps a neutral de-lit colour with
    /// the ratio of sums, within 2 % at 5 pixels from the dot (σ 4), where
    /// the mean of the pixels' ratios ([`smooth_in_mask`]) tints it cyan.
    #[test]
    fn a_dark_channel_does_not_tint_its_surroundings() {
        let (h, w) = (40, 40);
        let n = h * w;
        let (mut photo, mut albedo) = (Image::zeros(3, h, w), Image::zeros(3, h, w));
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                let dot = (18..21).contains(&x) && (18..21).contains(&y);
                let (ph, al) = if dot {
                    ([0.6, 0.005, 0.005], [0.35, 0.15, 0.15])
                } else {
                    ([0.8; 3], [0.4; 3])
                };
                for c in 0..3 {
                    photo.data[c * n + i] = ph[c];
                    albedo.data[c * n + i] = al[c];
                }
            }
        }
        let wt = vec![1.0f32; n];
        let spread = |r: &Image, i: usize| {
            let v: Vec<f32> = (0..3)
                .map(|c| photo.data[c * n + i] * r.data[c * n + i])
                .collect();
            let (lo, hi) = (
                v.iter().copied().fold(f32::MAX, f32::min),
                v.iter().copied().fold(0.0, f32::max),
            );
            (hi - lo) / (v.iter().sum::<f32>() / 3.0)
        };
        let sums = delighting_ratio(&albedo, &photo, &wt, 4.0);
        // Rows and columns 5 pixels out from the dot's edges.
        for &(x, y) in &[(25, 19), (13, 19), (19, 25), (19, 13), (24, 24)] {
            let i = y * w + x;
            let s = spread(&sums, i);
            assert!(s < 0.02, "ratio of sums at ({x}, {y}): spread {s}");
        }
        // The mean of the pixels' own ratios, for contrast.
        let mut own = Image::zeros(3, h, w);
        for i in 0..n {
            for c in 0..3 {
                own.data[c * n + i] = albedo.data[c * n + i] / photo.data[c * n + i];
            }
        }
        let means = smooth_in_mask(&own, &wt, 4.0);
        assert!(spread(&means, 19 * w + 25) > 0.3);
    }
}
