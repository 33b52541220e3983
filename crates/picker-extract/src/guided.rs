//! Guided filtering (He, Sun & Tang 2013) and fast guided upsampling (He &
//! Sun 2015): the network outputs, computed at the working resolution, are
//! brought to the photo's resolution so that their edges and fine detail
//! follow the photo rather than the network's coarse grid.
//!
//! With a grey guide `I` and an input `p`, each window `ω_k` of radius `r`
//! fits `p ≈ a_k·I + b_k` by least squares with ridge `ε`:
//! `a_k = cov_k(I,p)/(var_k(I)+ε)`, `b_k = mean_k(p) − a_k·mean_k(I)`; the
//! output is `q = mean(a)·I + mean(b)` (means over the windows covering each
//! pixel). Windows are clipped at the image border (means over the in-image
//! part). [`guided_upsample`] computes `a, b` at the low resolution and
//! upsamples them bilinearly before applying them to the full-resolution guide.

use picker_render::io::Image;
use rayon::prelude::*;

use crate::resample;

/// Mean of every `(2r+1)²` window (clipped at the borders) of a `w×h` plane,
/// through a summed-area table in `f64` (exact to rounding for any `r`).
pub fn box_mean(src: &[f32], w: usize, h: usize, r: usize) -> Vec<f32> {
    assert_eq!(src.len(), w * h, "plane length");
    // A box wider than the plane is clipped to it anyway.
    let r = r.min(w.max(h));
    let mut sat = vec![0.0f64; (w + 1) * (h + 1)];
    for y in 0..h {
        let mut row = 0.0f64;
        for x in 0..w {
            row += src[y * w + x] as f64;
            sat[(y + 1) * (w + 1) + x + 1] = sat[y * (w + 1) + x + 1] + row;
        }
    }
    let mut out = vec![0.0f32; w * h];
    out.par_chunks_mut(w.max(1))
        .enumerate()
        .for_each(|(y, orow)| {
            let y0 = y.saturating_sub(r);
            let y1 = (y + r + 1).min(h);
            for (x, o) in orow.iter_mut().enumerate() {
                let x0 = x.saturating_sub(r);
                let x1 = (x + r + 1).min(w);
                let s = sat[y1 * (w + 1) + x1] - sat[y0 * (w + 1) + x1] - sat[y1 * (w + 1) + x0]
                    + sat[y0 * (w + 1) + x0];
                *o = (s / ((y1 - y0) * (x1 - x0)) as f64) as f32;
            }
        });
    out
}

/// The plain definition of [`box_mean`]: sums every window directly. For tests.
pub fn box_mean_reference(src: &[f32], w: usize, h: usize, r: usize) -> Vec<f32> {
    let mut out = vec![0.0; w * h];
    for y in 0..h {
        for x in 0..w {
            let (mut s, mut n) = (0.0f64, 0usize);
            for yy in y.saturating_sub(r)..(y + r + 1).min(h) {
                for xx in x.saturating_sub(r)..(x + r + 1).min(w) {
                    s += src[yy * w + xx] as f64;
                    n += 1;
                }
            }
            out[y * w + x] = (s / n as f64) as f32;
        }
    }
    out
}

/// The window means of the linear coefficients `(mean(a), mean(b))` of the
/// guided filter of `p` by `guide`.
pub(crate) fn coefficients(
    guide: &[f32],
    p: &[f32],
    w: usize,
    h: usize,
    r: usize,
    eps: f32,
) -> (Vec<f32>, Vec<f32>) {
    let mi = box_mean(guide, w, h, r);
    let mp = box_mean(p, w, h, r);
    let ii: Vec<f32> = guide.iter().map(|v| v * v).collect();
    let ip: Vec<f32> = guide.iter().zip(p).map(|(a, b)| a * b).collect();
    let mii = box_mean(&ii, w, h, r);
    let mip = box_mean(&ip, w, h, r);
    let mut a = vec![0.0; w * h];
    let mut b = vec![0.0; w * h];
    for k in 0..w * h {
        let var = (mii[k] - mi[k] * mi[k]).max(0.0);
        let cov = mip[k] - mi[k] * mp[k];
        a[k] = cov / (var + eps);
        b[k] = mp[k] - a[k] * mi[k];
    }
    (box_mean(&a, w, h, r), box_mean(&b, w, h, r))
}

/// The guided filter of plane `p` (`w×h`) by the grey `guide`, radius `r`, ridge `eps`.
///
/// # Panics
/// When a plane's length is not `w · h`, or `eps` is not positive (a flat
/// guide would divide 0 by 0).
pub fn guided_filter(guide: &[f32], p: &[f32], w: usize, h: usize, r: usize, eps: f32) -> Vec<f32> {
    assert!(eps > 0.0, "guided_filter: eps {eps} must be positive");
    assert_eq!(guide.len(), w * h, "guide length");
    assert_eq!(p.len(), w * h, "input length");
    let (ma, mb) = coefficients(guide, p, w, h, r, eps);
    (0..w * h).map(|k| ma[k] * guide[k] + mb[k]).collect()
}

/// The plain definition of [`guided_filter`] (per-window least squares, then
/// averaging the coefficients of the windows that cover each pixel). For tests.
pub fn guided_filter_reference(
    guide: &[f32],
    p: &[f32],
    w: usize,
    h: usize,
    r: usize,
    eps: f32,
) -> Vec<f32> {
    let mut a = vec![0.0f64; w * h];
    let mut b = vec![0.0f64; w * h];
    for y in 0..h {
        for x in 0..w {
            let (mut si, mut sp, mut sii, mut sip, mut n) = (0.0f64, 0.0, 0.0, 0.0, 0.0);
            for yy in y.saturating_sub(r)..(y + r + 1).min(h) {
                for xx in x.saturating_sub(r)..(x + r + 1).min(w) {
                    let (i, q) = (guide[yy * w + xx] as f64, p[yy * w + xx] as f64);
                    si += i;
                    sp += q;
                    sii += i * i;
                    sip += i * q;
                    n += 1.0;
                }
            }
            let (mi, mp) = (si / n, sp / n);
            let var = (sii / n - mi * mi).max(0.0);
            let ak = (sip / n - mi * mp) / (var + eps as f64);
            a[y * w + x] = ak;
            b[y * w + x] = mp - ak * mi;
        }
    }
    let mut out = vec![0.0; w * h];
    for y in 0..h {
        for x in 0..w {
            let (mut sa, mut sb, mut n) = (0.0f64, 0.0, 0.0);
            for yy in y.saturating_sub(r)..(y + r + 1).min(h) {
                for xx in x.saturating_sub(r)..(x + r + 1).min(w) {
                    sa += a[yy * w + xx];
                    sb += b[yy * w + xx];
                    n += 1.0;
                }
            }
            out[y * w + x] = ((sa / n) * guide[y * w + x] as f64 + sb / n) as f32;
        }
    }
    out
}

/// The grey guide of an RGB image: Rec. 709 luma of its (display) values
/// (a one- or two-channel image's first channel; all zeros without any).
pub fn luma(img: &Image) -> Vec<f32> {
    if img.channels == 0 {
        return vec![0.0; img.plane_len()];
    }
    if img.channels < 3 {
        return img.plane(0).to_vec();
    }
    let (r, g, b) = (img.plane(0), img.plane(1), img.plane(2));
    (0..img.plane_len())
        .into_par_iter()
        .map(|i| 0.2126 * r[i] + 0.7152 * g[i] + 0.0722 * b[i])
        .collect()
}

/// Fast guided upsampling of `low` to the size of the full-resolution grey
/// `guide` (`fw×fh`): the guide is area-downsampled to `low`'s size, the
/// coefficients are fitted there with radius `r` (low-resolution pixels) and
/// ridge `eps`, upsampled bilinearly, and applied to the full guide. When the
/// sizes already agree this is the plain guided filter with radius `r`.
pub fn guided_upsample(
    guide: &[f32],
    fw: usize,
    fh: usize,
    low: &Image,
    r: usize,
    eps: f32,
) -> Image {
    assert_eq!(guide.len(), fw * fh, "guide length");
    let (w, h) = (low.width, low.height);
    let g_low = if (w, h) == (fw, fh) {
        guide.to_vec()
    } else {
        resample::area_plane(guide, fw, fh, w, h)
    };
    let mut data = Vec::with_capacity(low.channels * fw * fh);
    for c in 0..low.channels {
        let (ma, mb) = coefficients(&g_low, low.plane(c), w, h, r, eps);
        let (ua, ub) = if (w, h) == (fw, fh) {
            (ma, mb)
        } else {
            (
                resample::bilinear_plane(&ma, w, h, fw, fh),
                resample::bilinear_plane(&mb, w, h, fw, fh),
            )
        };
        let plane: Vec<f32> = (0..fw * fh)
            .into_par_iter()
            .map(|k| ua[k] * guide[k] + ub[k])
            .collect();
        data.extend(plane);
    }
    Image {
        channels: low.channels,
        height: fh,
        width: fw,
        data,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use picker_tensor::Rng;

    fn random(rng: &mut Rng, n: usize) -> Vec<f32> {
        rng.uniform_vec(n, 0.0, 1.0)
    }

    #[test]
    fn box_mean_matches_reference_on_edge_shapes() {
        let mut rng = Rng::new(11);
        for &(w, h, r) in &[
            (1, 1, 0),
            (1, 1, 3),
            (7, 1, 2),
            (1, 9, 4),
            (13, 8, 1),
            (16, 16, 5),
            (5, 4, 9),
        ] {
            let src = random(&mut rng, w * h);
            let a = box_mean(&src, w, h, r);
            let b = box_mean_reference(&src, w, h, r);
            for (x, y) in a.iter().zip(&b) {
                assert!((x - y).abs() < 1e-5, "{w}x{h} r{r}: {x} vs {y}");
            }
        }
    }

    #[test]
    fn guided_filter_matches_reference() {
        let mut rng = Rng::new(5);
        for &(w, h, r, eps) in &[
            (1, 1, 1, 1e-2),
            (9, 7, 1, 1e-3),
            (20, 11, 3, 1e-2),
            (4, 30, 2, 1e-4),
        ] {
            let g = random(&mut rng, w * h);
            let p = random(&mut rng, w * h);
            let a = guided_filter(&g, &p, w, h, r, eps);
            let b = guided_filter_reference(&g, &p, w, h, r, eps);
            for (x, y) in a.iter().zip(&b) {
                assert!((x - y).abs() < 2e-4, "{w}x{h} r{r}: {x} vs {y}");
            }
        }
    }

    #[test]
    fn guided_filter_reproduces_a_linear_function_of_the_guide() {
        // p = 0.3·I + 0.1 exactly: a = 0.3, b = 0.1 in every window (ε → 0).
        let mut rng = Rng::new(9);
        let (w, h) = (17, 13);
        let g = random(&mut rng, w * h);
        let p: Vec<f32> = g.iter().map(|v| 0.3 * v + 0.1).collect();
        let q = guided_filter(&g, &p, w, h, 2, 1e-7);
        for (x, y) in q.iter().zip(&p) {
            assert!((x - y).abs() < 1e-3);
        }
    }

    #[test]
    fn guided_upsampling_recovers_detail_that_follows_the_guide() {
        // Full-resolution detail d, low-resolution p = area(0.5·d + 0.2):
        // the guided upsampling recovers 0.5·d + 0.2 at full resolution far
        // better than bilinear upsampling does.
        let mut rng = Rng::new(3);
        let (fw, fh, w, h) = (64, 48, 16, 12);
        let d = random(&mut rng, fw * fh);
        let truth: Vec<f32> = d.iter().map(|v| 0.5 * v + 0.2).collect();
        let low = Image::new(1, h, w, resample::area_plane(&truth, fw, fh, w, h)).unwrap();
        let up = guided_upsample(&d, fw, fh, &low, 1, 1e-4);
        let bil = resample::bilinear(&low, fw, fh);
        let err = |q: &[f32]| {
            q.iter()
                .zip(&truth)
                .map(|(a, b)| (a - b).powi(2))
                .sum::<f32>()
        };
        assert!(
            err(&up.data) < 0.05 * err(&bil.data),
            "{} vs {}",
            err(&up.data),
            err(&bil.data)
        );
    }
}
