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
//! on one surface: so the ratio (one over the shading) is smoothed over the
//! material's own pixels ([`smooth_in_mask`], [`SHADING_SIGMA`]) and the
//! detail comes from the photo. Where the photo is clipped
//! ([`crate::pipeline::CLIPPED_SRGB`]) its detail is not the material's and
//! the network's albedo stands in. Ground-truth albedo is exact and is used
//! as it is ([`crate::Inputs::albedo_estimated`]).

use picker_render::Image;
use rayon::prelude::*;

/// σ, in working pixels, of the Gaussian that [`smooth_in_mask`] applies
/// to the de-lighting ratio of a network's albedo.
///
/// Measured (stop 51) with the embedded networks, `picker eval --embedded
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
}
