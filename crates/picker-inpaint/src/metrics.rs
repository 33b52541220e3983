//! Metrics to compare an inpainted texture with the truth.

use crate::Image;

/// Bins per channel of the colour histogram of [`colour_stats_distance`].
pub const HISTOGRAM_BINS: usize = 8;

/// Peak signal-to-noise ratio in dB, `10·log10(1 / MSE)` with peak 1.0, over
/// all channels of the texels where `mask` is true (every texel when `None`).
/// Values are compared as given (no clamping or encoding).
///
/// Returns `f64::INFINITY` for identical values and `NaN` when the shapes
/// differ, the mask has the wrong length or selects no texel.
pub fn psnr(a: &Image, b: &Image, mask: Option<&[bool]>) -> f64 {
    let n = a.height * a.width;
    if a.channels != b.channels
        || a.height != b.height
        || a.width != b.width
        || a.data.len() != a.channels * n
        || b.data.len() != b.channels * n
        || mask.is_some_and(|m| m.len() != n)
    {
        return f64::NAN;
    }
    let (mut se, mut count) = (0.0f64, 0usize);
    for c in 0..a.channels {
        let (pa, pb) = (&a.data[c * n..(c + 1) * n], &b.data[c * n..(c + 1) * n]);
        for i in 0..n {
            if mask.is_none_or(|m| m[i]) {
                let d = pa[i] as f64 - pb[i] as f64;
                se += d * d;
                count += 1;
            }
        }
    }
    if count == 0 {
        return f64::NAN;
    }
    let mse = se / count as f64;
    if mse == 0.0 {
        f64::INFINITY
    } else {
        -10.0 * mse.log10()
    }
}

/// Per-channel mean and standard deviation plus the normalised colour histogram.
fn colour_stats(img: &Image) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let n = img.height * img.width;
    let c = img.channels;
    let hc = c.min(3);
    let mut means = Vec::with_capacity(c);
    let mut stds = Vec::with_capacity(c);
    for ch in 0..c {
        let p = &img.data[ch * n..(ch + 1) * n];
        let m = p.iter().map(|&v| v as f64).sum::<f64>() / n as f64;
        let var = p.iter().map(|&v| (v as f64 - m).powi(2)).sum::<f64>() / n as f64;
        means.push(m);
        stds.push(var.sqrt());
    }
    let mut hist = vec![0.0f64; HISTOGRAM_BINS.pow(hc as u32)];
    let bin =
        |v: f32| ((v.clamp(0.0, 1.0) * HISTOGRAM_BINS as f32) as usize).min(HISTOGRAM_BINS - 1);
    for i in 0..n {
        let mut k = 0;
        for ch in 0..hc {
            k = k * HISTOGRAM_BINS + bin(img.data[ch * n + i]);
        }
        hist[k] += 1.0 / n as f64;
    }
    (means, stds, hist)
}

/// A distance between the colour statistics of two images (of any sizes, same
/// channel count), insensitive to where things are:
///
/// `D = (1/C) Σ_c (|μ_a,c − μ_b,c| + |σ_a,c − σ_b,c|) + ½ Σ_k |H_a,k − H_b,k|`
///
/// where `μ`, `σ` are the per-channel mean and (population) standard deviation
/// and `H` the normalised joint histogram of the first `min(C, 3)` channels,
/// each clamped to `[0, 1]` and cut into [`HISTOGRAM_BINS`] bins. The
/// histogram term (total variation distance) lies in `[0, 1]`. `D` is
/// symmetric, non-negative, 0 for identical images and satisfies the triangle
/// inequality (a pseudo-metric: images with equal statistics are at 0).
/// Returns `NaN` when the channel counts differ or an image is empty or
/// inconsistent.
pub fn colour_stats_distance(a: &Image, b: &Image) -> f64 {
    let ok = |i: &Image| {
        i.channels > 0 && i.height * i.width > 0 && i.data.len() == i.channels * i.height * i.width
    };
    if a.channels != b.channels || !ok(a) || !ok(b) {
        return f64::NAN;
    }
    let (ma, sa, ha) = colour_stats(a);
    let (mb, sb, hb) = colour_stats(b);
    let moments = ma
        .iter()
        .zip(&mb)
        .map(|(x, y)| (x - y).abs())
        .chain(sa.iter().zip(&sb).map(|(x, y)| (x - y).abs()))
        .sum::<f64>()
        / a.channels as f64;
    let hist = 0.5 * ha.iter().zip(&hb).map(|(x, y)| (x - y).abs()).sum::<f64>();
    moments + hist
}
