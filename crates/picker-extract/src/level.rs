//! The texture's level against the material's.
//!
//! A texture comes from one part of the material (the plane mode's square,
//! placed where the photo shows the most of the surface: often the part
//! nearest the camera, at a photo's edge), but its brightness is the
//! material's. Where the de-lighting leaves that part darker (a lens'
//! vignetting in a photo's corner, a shadow the networks took for albedo),
//! the whole material came out so: `stuff.jpg`'s light grey table, picked
//! near the vignetted corner, gave a texture and diffuse colour of
//! (0.07, 0.09, 0.08) linear while the table's de-lit colours have a median
//! of 0.42.
//!
//! [`level_band`] measures what brightness is typical of the material: the
//! de-lit colours averaged locally (a Gaussian about a quarter of the
//! texture square's side in the photo, so that a window holds a pattern's
//! colours together), kept where the local mean has the texture's
//! chromaticity (within [`CHROMA_RADIUS`]: vignetting and shadows change
//! the brightness, hardly the chromaticity, while another material the mask
//! took in usually has another: an aloe's leaves in a cloth's mask, an
//! orange's pith in its flesh's), and the quartiles of their luminance.
//! [`level_gain`] leaves a texture whose mean luminance lies within the
//! quartiles as it is (a part as typical as half the material is not
//! second-guessed) and otherwise scales it, all channels alike so that its
//! colour stays, to the nearer quartile, by at most [`MAX_GAIN`].

use picker_render::io::Image;

use crate::shading::smooth_in_mask;

/// The largest factor [`level_gain`] scales a texture by, either way: a
/// texture that much darker than its material has little left to show, and
/// a larger gain would turn its noise into the texture.
pub const MAX_GAIN: f32 = 8.0;

/// Fewest pixels [`level_band`] measures a level from: a smaller material
/// (a card's pip, a few working pixels that also hold its surroundings)
/// has no level the working resolution can tell.
pub const MIN_PIXELS: usize = 100;

/// Largest distance in rg-chromaticity (`r = R/(R+G+B)`, `g = G/(R+G+B)`,
/// linear) between a local mean and the texture's mean for the local mean
/// to count ([`level_band`]). `stuff.jpg`'s vignetted corner and the
/// table's centre are 0.06 apart; an aloe's leaf and the cloth behind it
/// 0.27, an orange's flesh and its pith 0.15.
pub const CHROMA_RADIUS: f32 = 0.08;

/// Local means' σ as a share of the texture square's side
/// ([`level_sigma`]).
pub const SIGMA_SHARE: f32 = 0.25;

/// Bounds of the local means' σ, in working pixels ([`level_sigma`]).
pub const SIGMA_RANGE: [f32; 2] = [2.0, 16.0];

/// The quartiles of a material's local mean luminances ([`level_band`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Band {
    /// First quartile (linear luminance).
    pub q1: f32,
    /// Median.
    pub median: f32,
    /// Third quartile.
    pub q3: f32,
    /// The share of the weighted pixels whose local mean had the texture's
    /// chromaticity (the pixels measured).
    pub share: f64,
}

/// What the level check found and did (`material.json` →
/// `diagnostics.level`).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct LevelCheck {
    /// The texture's mean colour before the gain (linear RGB).
    pub texture_mean: [f32; 3],
    /// Its luminance.
    pub texture_luminance: f32,
    /// First quartile of the material's local mean luminances (those of
    /// the texture's chromaticity).
    pub q1: f32,
    /// Their median.
    pub median: f32,
    /// Their third quartile.
    pub q3: f32,
    /// The share of the material's pixels measured (local means of the
    /// texture's chromaticity).
    pub share: f64,
    /// σ of the local means, working pixels.
    pub sigma_px: f32,
    /// The gain applied to the texture (1: kept).
    pub gain: f32,
}

/// Linear luminance of an RGB triple ([`crate::pipeline::luminance`]).
pub fn luminance(c: [f32; 3]) -> f32 {
    crate::pipeline::luminance(glam::Vec3::from_array(c))
}

/// The rg-chromaticity `(R, G) / (R + G + B)`; `None` when the sum is not
/// positive and finite (black has none).
pub fn chromaticity(c: [f32; 3]) -> Option<[f32; 2]> {
    let s = c[0] + c[1] + c[2];
    (s.is_finite() && s > 1e-6).then(|| [c[0] / s, c[1] / s])
}

/// σ of the local means for a texture square that `pixels` working pixels
/// (or the equivalent area) fall in: [`SIGMA_SHARE`] of its side, within
/// [`SIGMA_RANGE`].
pub fn level_sigma(pixels: f64) -> f32 {
    let side = pixels.max(0.0).sqrt() as f32;
    (SIGMA_SHARE * side).clamp(SIGMA_RANGE[0], SIGMA_RANGE[1])
}

/// The quartiles of the luminance of the local means of `values` (3
/// channels) over the pixels with `weight > 0` whose local mean lies within
/// [`CHROMA_RADIUS`] of the chromaticity `chroma`: every such pixel's
/// weighted Gaussian mean of `sigma` pixels ([`smooth_in_mask`]), then the
/// 25th, 50th and 75th percentiles (the lower of two middle values) of
/// those means' luminance. `None` when fewer than [`MIN_PIXELS`] pixels
/// are measured or `values` does not have 3 channels.
///
/// # Panics
/// When `weight` does not hold one value per pixel.
pub fn level_band(values: &Image, weight: &[f32], sigma: f32, chroma: [f32; 2]) -> Option<Band> {
    assert_eq!(
        weight.len(),
        values.width * values.height,
        "level_band: one weight per pixel"
    );
    if values.channels != 3 {
        return None;
    }
    let n = weight.len();
    let local = smooth_in_mask(values, weight, sigma);
    let rgb = |i: usize| -> [f32; 3] { std::array::from_fn(|c| local.data[c * n + i]) };
    let weighted = weight.iter().filter(|&&v| v > 0.0).count();
    let mut lum: Vec<f32> = (0..n)
        .filter(|&i| weight[i] > 0.0)
        .filter_map(|i| {
            let c = rgb(i);
            let k = chromaticity(c)?;
            let d = (k[0] - chroma[0]).hypot(k[1] - chroma[1]);
            (d <= CHROMA_RADIUS).then(|| luminance(c))
        })
        .collect();
    if lum.len() < MIN_PIXELS {
        return None;
    }
    lum.sort_unstable_by(f32::total_cmp);
    let at = |p: f64| lum[((lum.len() - 1) as f64 * p) as usize];
    Some(Band {
        q1: at(0.25),
        median: at(0.5),
        q3: at(0.75),
        share: lum.len() as f64 / weighted.max(1) as f64,
    })
}

/// The gain that brings a texture of mean luminance `mean` within `band`:
/// 1 where it lies between the quartiles, else the nearer quartile over
/// it, within `[1/MAX_GAIN, MAX_GAIN]`; 1 when the mean or the quartiles
/// are not positive and finite (nothing to scale, or nothing to scale to).
pub fn level_gain(mean: f32, band: &Band) -> f32 {
    let ok = |v: f32| v.is_finite() && v > 0.0;
    if !(ok(mean) && ok(band.q1) && ok(band.q3)) {
        return 1.0;
    }
    (mean.clamp(band.q1, band.q3) / mean).clamp(1.0 / MAX_GAIN, MAX_GAIN)
}

/// The mean colour of a 3-channel texture (0 for an empty one).
pub fn mean_colour(tex: &Image) -> [f32; 3] {
    let n = tex.width * tex.height;
    std::array::from_fn(|c| {
        let s: f64 = tex.data[c * n..(c + 1) * n]
            .iter()
            .map(|&v| f64::from(v))
            .sum();
        (s / n.max(1) as f64) as f32
    })
}

/// The level check of a texture against the de-lit `values` of its
/// material's pixels (`weight > 0`), local means of `sigma` pixels
/// ([`level_band`], [`level_gain`]); `None` when the texture's mean has no
/// chromaticity or no band can be measured.
///
/// # Panics
/// When `weight` does not hold one value per pixel of `values`.
pub fn check(tex: &Image, values: &Image, weight: &[f32], sigma: f32) -> Option<LevelCheck> {
    let mean = mean_colour(tex);
    let band = level_band(values, weight, sigma, chromaticity(mean)?)?;
    let texture_luminance = luminance(mean);
    Some(LevelCheck {
        texture_mean: mean,
        texture_luminance,
        q1: band.q1,
        median: band.median,
        q3: band.q3,
        share: band.share,
        sigma_px: sigma,
        gain: level_gain(texture_luminance, &band),
    })
}

/// `tex` with every value multiplied by `gain`.
pub fn apply_gain(mut tex: Image, gain: f32) -> Image {
    if gain != 1.0 {
        tex.data.iter_mut().for_each(|v| *v *= gain);
    }
    tex
}

#[cfg(test)]
mod tests {
    use super::*;
    use picker_tensor::Rng;

    fn image(h: usize, w: usize, mut f: impl FnMut(usize, usize, usize) -> f32) -> Image {
        let mut data = vec![0.0; 3 * h * w];
        for c in 0..3 {
            for y in 0..h {
                for x in 0..w {
                    data[c * h * w + y * w + x] = f(c, y, x);
                }
            }
        }
        Image {
            channels: 3,
            height: h,
            width: w,
            data,
        }
    }

    /// The quartiles against a plain evaluation: the local means from the
    /// reference smoothing, those within the chromaticity radius, their
    /// luminances sorted, on seeded random images and masks of awkward
    /// shapes (one row, one column, one pixel, about MIN_PIXELS weighted
    /// pixels).
    #[test]
    fn the_band_is_the_local_means_quartiles() {
        let mut rng = Rng::new(11);
        for &(h, w) in &[
            (1usize, 160usize),
            (170, 1),
            (1, 1),
            (10, 15),
            (13, 17),
            (24, 31),
        ] {
            for sigma in [0.5f32, 2.0, 5.0] {
                // Grey-ish colours, some tinted beyond the radius.
                let tint: Vec<f32> = (0..h * w).map(|_| rng.uniform(0.0, 1.0)).collect();
                let img = image(h, w, |c, y, x| {
                    let t = tint[y * w + x];
                    let v = 0.2 + 0.5 * t;
                    if c == 0 && t > 0.8 {
                        3.0 * v
                    } else {
                        v
                    }
                });
                let weight: Vec<f32> = (0..h * w)
                    .map(|i| {
                        if i % 3 == 1 {
                            0.0
                        } else {
                            0.5 + (i % 5) as f32 * 0.1
                        }
                    })
                    .collect();
                let grey = [1.0 / 3.0; 2];
                let band = level_band(&img, &weight, sigma, grey);
                let local = crate::shading::smooth_in_mask_reference(&img, &weight, sigma);
                let n = h * w;
                let weighted = weight.iter().filter(|&&v| v > 0.0).count();
                let mut lum: Vec<f32> = (0..n)
                    .filter(|&i| weight[i] > 0.0)
                    .filter_map(|i| {
                        let c = [0, 1, 2].map(|k| local.data[k * n + i]);
                        let s = c[0] + c[1] + c[2];
                        let d =
                            ((c[0] / s - grey[0]).powi(2) + (c[1] / s - grey[1]).powi(2)).sqrt();
                        (d <= CHROMA_RADIUS).then(|| luminance(c))
                    })
                    .collect();
                if lum.len() < MIN_PIXELS {
                    assert!(band.is_none(), "{h}x{w} σ {sigma}: {} pixels", lum.len());
                    continue;
                }
                lum.sort_by(f32::total_cmp);
                let at = |p: f64| lum[((lum.len() - 1) as f64 * p) as usize];
                let band = band.expect("a band");
                for (got, want) in [
                    (band.q1, at(0.25)),
                    (band.median, at(0.5)),
                    (band.q3, at(0.75)),
                ] {
                    assert!(
                        (got - want).abs() < 1e-5,
                        "{h}x{w} σ {sigma}: {got} vs {want}"
                    );
                }
                assert!((band.share - lum.len() as f64 / weighted as f64).abs() < 1e-12);
            }
        }
    }

    /// A material lit evenly but for a dark corner (a quarter of it): the
    /// quartiles are the even part's, so a texture taken from the corner is
    /// brought to the first quartile, all channels alike, and one from
    /// elsewhere kept. Where the rest of the mask has another chromaticity
    /// (an orange's white pith, three quarters of the mask, around its
    /// flesh), only the flesh is measured: the texture of the flesh keeps
    /// its level (measured over the whole mask, the pith's would make it 6
    /// times brighter).
    #[test]
    fn a_dark_corner_texture_is_brought_to_the_material() {
        let (h, w) = (40, 40);
        let base = [0.42f32, 0.40, 0.40];
        let corner = |y: usize, x: usize| y >= 20 && x < 20;
        let img = image(h, w, |c, y, x| {
            if corner(y, x) {
                base[c] * 0.17
            } else {
                base[c]
            }
        });
        let tex = image(8, 8, |c, _, _| base[c] * 0.17);
        let l = check(&tex, &img, &vec![1.0; h * w], 2.0).unwrap();
        assert!((l.median - luminance(base)).abs() < 1e-5, "{l:?}");
        assert!((l.texture_luminance * l.gain - l.q1).abs() < 1e-5, "{l:?}");
        assert!(l.gain > 3.0 && l.share == 1.0, "{l:?}");
        let typical = image(8, 8, |c, _, _| base[c]);
        assert_eq!(
            check(&typical, &img, &vec![1.0; h * w], 2.0).unwrap().gain,
            1.0
        );
        // Flesh (orange) in the corner, pith (white, brighter) around it.
        let flesh = [0.27f32, 0.064, 0.005];
        let img = image(h, w, |c, y, x| if corner(y, x) { flesh[c] } else { 0.6 });
        let tex = image(8, 8, |c, _, _| flesh[c]);
        let l = check(&tex, &img, &vec![1.0; h * w], 2.0).unwrap();
        assert!(l.share < 0.3, "{l:?}");
        assert_eq!(l.gain, 1.0, "{l:?}");
    }

    /// The gain: 1 inside the quartiles (bounds included), the nearer
    /// quartile outside, capped at MAX_GAIN either way, 1 where nothing can
    /// be scaled.
    #[test]
    fn the_gain_follows_its_rule() {
        let band = Band {
            q1: 0.2,
            median: 0.3,
            q3: 0.4,
            share: 1.0,
        };
        for m in [0.2, 0.3, 0.4] {
            assert_eq!(level_gain(m, &band), 1.0);
        }
        assert!((level_gain(0.1, &band) - 2.0).abs() < 1e-6);
        assert!((level_gain(0.8, &band) - 0.5).abs() < 1e-6);
        assert_eq!(level_gain(0.01, &band), MAX_GAIN);
        assert_eq!(level_gain(10.0, &band), 1.0 / MAX_GAIN);
        for m in [0.0, f32::NAN, -1.0, f32::INFINITY] {
            assert_eq!(level_gain(m, &band), 1.0);
        }
        let empty = Band { q1: 0.0, ..band };
        assert_eq!(level_gain(0.1, &empty), 1.0);
    }

    /// Fewer than MIN_PIXELS measured pixels, not three channels, or a
    /// black texture: no band, no check.
    #[test]
    fn nothing_to_measure_gives_no_band() {
        let grey = [1.0 / 3.0; 2];
        let img = image(3, 4, |_, _, _| 0.5);
        assert!(level_band(&img, &[0.0; 12], 2.0, grey).is_none());
        let img = image(10, 20, |_, _, _| 0.5);
        let first =
            |k: usize| -> Vec<f32> { (0..200).map(|i| f32::from(u8::from(i < k))).collect() };
        assert!(level_band(&img, &first(MIN_PIXELS - 1), 2.0, grey).is_none());
        assert_eq!(
            level_band(&img, &first(MIN_PIXELS), 2.0, grey).map(|b| b.median),
            Some(0.5)
        );
        // Another chromaticity than all of them.
        assert!(level_band(&img, &first(200), 2.0, [0.6, 0.3]).is_none());
        let black = image(4, 4, |_, _, _| 0.0);
        assert!(check(&black, &img, &first(200), 2.0).is_none());
        let one = Image {
            channels: 1,
            height: 10,
            width: 20,
            data: vec![0.5; 200],
        };
        assert!(level_band(&one, &first(200), 2.0, grey).is_none());
    }

    /// The helpers: σ within its range, luminance, chromaticity, the mean,
    /// the gain applied.
    #[test]
    fn helpers() {
        assert_eq!(level_sigma(0.0), SIGMA_RANGE[0]);
        assert_eq!(level_sigma(1e9), SIGMA_RANGE[1]);
        assert!((level_sigma(1600.0) - 10.0).abs() < 1e-6);
        assert!((luminance([1.0; 3]) - 1.0).abs() < 1e-6);
        assert_eq!(chromaticity([2.0, 1.0, 1.0]), Some([0.5, 0.25]));
        assert_eq!(chromaticity([0.0; 3]), None);
        assert_eq!(chromaticity([f32::NAN, 0.0, 0.0]), None);
        let t = image(2, 2, |c, y, x| (c * 4 + y * 2 + x) as f32);
        assert_eq!(mean_colour(&t), [1.5, 5.5, 9.5]);
        assert_eq!(mean_colour(&apply_gain(t, 2.0)), [3.0, 11.0, 19.0]);
    }
}
