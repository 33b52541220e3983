//! Evening out the broad brightness of a texture (`extract --even-out`), the
//! "equalise" step of photo-texture tools.
//!
//! The de-lighting divides the photo by an estimated shading; where that
//! estimate is off, the texture keeps the residue as broad light and dark
//! patches (a floor brighter towards the window, a vignette). For a
//! stationary material, brightness changes much wider than its features are
//! such residue: the luminance is blurred with a wide filter that wraps
//! around the edges as the texture tiles (or mirrors them, for one that does
//! not tile), and each texel is scaled by the texture's
//! mean luminance over the blurred one, one gain for the three channels, so
//! colour and fine detail stay. It also flattens a pattern whose own light
//! and dark areas are that wide (a chessboard of few squares, a marble's
//! veins), which is why it is not on by default: at [`DEFAULT_SCALE`], with
//! the embedded networks it raised the mean aligned texture PSNR of the
//! synthetic evaluation sets by 0.19–0.35 dB, with the scenes' true albedo
//! (no shading residue to remove) it lowered it by 2.4–2.7 dB (see the
//! README).

use glam::Vec3;
use picker_render::io::Image;

use crate::pipeline::luminance;

/// The default width of the blur, as a fraction of the texture's side
/// (`extract --even-out` without a value).
pub const DEFAULT_SCALE: f64 = 0.125;
/// Gains are kept within `[1 / MAX_GAIN, MAX_GAIN]`.
pub const MAX_GAIN: f64 = 4.0;
/// Box passes that approximate the Gaussian.
const PASSES: usize = 3;

/// What [`even_out`] changed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EvenOut {
    /// The smallest and largest gain applied to a texel.
    pub gain_range: [f64; 2],
    /// The half-width of the box filter, in texels (three passes).
    pub radius: usize,
}

/// How a blur reads past the edges of a texture.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Edges {
    /// The texture tiles: index `−1` is the last texel.
    Wrap,
    /// Mirrored about the edge texels (`…, 2, 1, 0, 1, 2, …`): a texture
    /// that does not tile (`extract --no-tile`).
    Mirror,
}

impl Edges {
    /// The period of [`Edges::index`] over a line of `n ≥ 1` values.
    fn period(self, n: usize) -> usize {
        match self {
            Edges::Wrap => n,
            Edges::Mirror if n == 1 => 1,
            Edges::Mirror => 2 * n - 2,
        }
    }

    /// Index `j` of a line of `n ≥ 1` values.
    pub(crate) fn index(self, j: isize, n: usize) -> usize {
        match self {
            Edges::Wrap => j.rem_euclid(n as isize) as usize,
            Edges::Mirror if n == 1 => 0,
            Edges::Mirror => {
                let m = 2 * n as isize - 2;
                let k = j.rem_euclid(m);
                (if k < n as isize { k } else { m - k }) as usize
            }
        }
    }
}

/// Box blur of a `w × h` plane (row-major) with half-width `r` along rows
/// and then columns, each output the mean of the `2r + 1` values around it,
/// read past the edges as `edges` says (a box wider than the plane wraps or
/// mirrors again). `plane.len()` must be `w · h`. A box wider than a line's
/// period is summed as whole periods plus the rest, so any `r` costs the
/// same.
pub fn box_blur(plane: &[f64], w: usize, h: usize, r: usize, edges: Edges) -> Vec<f64> {
    assert_eq!(plane.len(), w * h, "box_blur: plane is not {w}x{h}");
    let mut out = plane.to_vec();
    if w == 0 || h == 0 {
        return out;
    }
    let mut tmp = vec![0.0; plane.len()];
    // `count` lines of `n` values: line `l` starts at `l·step`, its values
    // `stride` apart. A running sum over the window.
    // The window [i − r, i + r] holds `whole` periods of the line and a
    // rest of `part` values from i − r ≡ i + start (mod the period); below
    // one period (every blur the pipeline makes) that is the plain running
    // sum over [i − r, i + r].
    let pass =
        |src: &[f64], dst: &mut [f64], n: usize, stride: usize, count: usize, step: usize| {
            let period = edges.period(n) as u128;
            let len = 2 * r as u128 + 1;
            let k = len as f64;
            let whole = (len / period) as f64;
            let part = (len % period) as isize;
            let start = -((r as u128 % period) as isize);
            for l in 0..count {
                let at = |j: isize| l * step + edges.index(j, n) * stride;
                let full: f64 = if whole > 0.0 {
                    (0..period as isize).map(|j| src[at(j)]).sum()
                } else {
                    0.0
                };
                let mut s: f64 = (start..start + part).map(|d| src[at(d)]).sum();
                for i in 0..n as isize {
                    dst[at(i)] = if whole > 0.0 {
                        (whole * full + s) / k
                    } else {
                        s / k
                    };
                    s += src[at(i + start + part)] - src[at(i + start)];
                }
            }
        };
    pass(&out, &mut tmp, w, 1, h, w);
    pass(&tmp, &mut out, h, w, w, 1);
    out
}

/// The box half-width whose [`PASSES`] passes have the variance of a
/// Gaussian of standard deviation `sigma` texels (at least 1).
fn radius_for(sigma: f64) -> usize {
    // One box of width 2r + 1 has variance ((2r + 1)² − 1) / 12.
    let width = (12.0 * sigma * sigma / PASSES as f64 + 1.0).sqrt();
    ((width - 1.0) / 2.0).round().max(1.0) as usize
}

/// `t` (linear RGB; tileable when `edges` is [`Edges::Wrap`]) with its
/// brightness evened out at scales above
/// `scale` times its side (the standard deviation of the Gaussian that the
/// box passes approximate): each texel scaled by the mean luminance over the
/// blurred luminance, within `[1/MAX_GAIN, MAX_GAIN]`, the same for every
/// colour channel. `None` (nothing to do) for fewer than 3 channels, an
/// empty or black texture, or a `scale` that is not a positive number.
pub fn even_out(t: &Image, scale: f64, edges: Edges) -> Option<(Image, EvenOut)> {
    let (w, h) = (t.width, t.height);
    if t.channels < 3 || w == 0 || h == 0 || !(scale > 0.0 && scale.is_finite()) {
        return None;
    }
    let n = w * h;
    let lum: Vec<f64> = (0..n)
        .map(|i| f64::from(luminance(t.rgb(i).max(Vec3::ZERO))))
        .collect();
    let mean = lum.iter().sum::<f64>() / n as f64;
    if !(mean > 0.0 && mean.is_finite()) {
        return None;
    }
    let radius = radius_for(scale * w.max(h) as f64);
    let mut blurred = lum;
    for _ in 0..PASSES {
        blurred = box_blur(&blurred, w, h, radius, edges);
    }
    let mut out = t.clone();
    let mut range = [f64::INFINITY, 0.0f64];
    for (i, b) in blurred.iter().enumerate() {
        let g = (mean / b.max(mean / MAX_GAIN)).clamp(1.0 / MAX_GAIN, MAX_GAIN);
        range = [range[0].min(g), range[1].max(g)];
        for c in 0..3 {
            out.data[c * n + i] *= g as f32;
        }
    }
    Some((
        out,
        EvenOut {
            gain_range: range,
            radius,
        },
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use picker_tensor::Rng;

    /// The plain definition: every output the mean over its window, indices
    /// past the edges wrapped, or mirrored by repeated reflection.
    fn blur_reference(p: &[f64], w: usize, h: usize, r: usize, edges: Edges) -> Vec<f64> {
        let k = (2 * r + 1) as f64;
        let wrap = |j: isize, n: usize| match edges {
            Edges::Wrap => j.rem_euclid(n as isize) as usize,
            Edges::Mirror => {
                let mut j = j;
                while !(0..n as isize).contains(&j) {
                    j = if n == 1 {
                        0
                    } else if j < 0 {
                        -j
                    } else {
                        2 * (n as isize - 1) - j
                    };
                }
                j as usize
            }
        };
        let rows: Vec<f64> = (0..w * h)
            .map(|i| {
                let (y, x) = (i / w, i % w);
                (-(r as isize)..=r as isize)
                    .map(|d| p[y * w + wrap(x as isize + d, w)])
                    .sum::<f64>()
                    / k
            })
            .collect();
        (0..w * h)
            .map(|i| {
                let (y, x) = (i / w, i % w);
                (-(r as isize)..=r as isize)
                    .map(|d| rows[wrap(y as isize + d, h) * w + x])
                    .sum::<f64>()
                    / k
            })
            .collect()
    }

    #[test]
    fn blur_matches_reference() {
        let mut rng = Rng::new(3);
        for (w, h, r) in [
            (1, 1, 1),
            (1, 7, 2),
            (9, 1, 3),
            (5, 4, 1),
            (16, 16, 3),
            (7, 11, 9),
            (3, 3, 20),
            (32, 17, 5),
            (5, 6, 1000),
        ] {
            let p: Vec<f64> = (0..w * h).map(|_| rng.f64() * 2.0 - 0.5).collect();
            for edges in [Edges::Wrap, Edges::Mirror] {
                let got = box_blur(&p, w, h, r, edges);
                let want = blur_reference(&p, w, h, r, edges);
                for (i, (a, b)) in got.iter().zip(&want).enumerate() {
                    assert!(
                        (a - b).abs() < 1e-12,
                        "{w}x{h} r {r} {edges:?} at {i}: {a} vs {b}"
                    );
                }
            }
            // Wrapped, the mean is kept (every value is spread over equal windows).
            let got = box_blur(&p, w, h, r, Edges::Wrap);
            let (ma, mb) = (got.iter().sum::<f64>(), p.iter().sum::<f64>());
            assert!(
                (ma - mb).abs() < 1e-9 * (w * h) as f64,
                "{w}x{h} r {r}: mean moved"
            );
        }
        assert!(box_blur(&[], 0, 3, 2, Edges::Wrap).is_empty());
        // Any half-width costs the same: an endless box is the plane's mean.
        let p: Vec<f64> = (0..12).map(|i| f64::from(i) * 0.25).collect();
        let mean = p.iter().sum::<f64>() / 12.0;
        for v in box_blur(&p, 4, 3, usize::MAX / 2, Edges::Wrap) {
            assert!((v - mean).abs() < 1e-9, "{v} vs {mean}");
        }
        // Mirrored, the period weights the inner texels twice: still finite.
        assert!(box_blur(&p, 4, 3, usize::MAX / 2, Edges::Mirror)
            .iter()
            .all(|v| v.is_finite()));
        // Mirrored, a ramp's ends are not pulled towards each other.
        let ramp: Vec<f64> = (0..16).map(f64::from).collect();
        let m = box_blur(&ramp, 16, 1, 2, Edges::Mirror);
        assert!(m[0] < 2.0 && m[15] > 13.0, "{m:?}");
        let t = box_blur(&ramp, 16, 1, 2, Edges::Wrap);
        assert!(t[0] > 5.0, "{t:?}");
    }

    #[test]
    fn radius_gives_the_gaussian_variance() {
        for sigma in [1.0, 2.5, 8.0, 32.0, 128.0] {
            let r = radius_for(sigma) as f64;
            let var = PASSES as f64 * ((2.0 * r + 1.0).powi(2) - 1.0) / 12.0;
            assert!(
                (var.sqrt() - sigma).abs() <= 0.35 * sigma.max(2.0),
                "{sigma}: r {r}"
            );
        }
        assert_eq!(radius_for(0.01), 1);
    }

    /// A fine pattern times a broad, tileable brightness change: evened out,
    /// the broad change is gone and the pattern stays.
    fn pattern(x: usize, y: usize) -> f32 {
        if (x / 4 + y / 4).is_multiple_of(2) {
            0.6
        } else {
            0.3
        }
    }

    #[test]
    fn removes_a_broad_change_and_keeps_the_pattern() {
        let s = 128;
        let n = s * s;
        let tau = std::f32::consts::TAU;
        let shade = |x: usize, y: usize| {
            1.0 + 0.6 * (tau * x as f32 / s as f32).sin() * (tau * y as f32 / s as f32).cos()
        };
        let colour = [0.9f32, 0.7, 0.5];
        let mut data = vec![0.0f32; 3 * n];
        for y in 0..s {
            for x in 0..s {
                for c in 0..3 {
                    data[c * n + y * s + x] = colour[c] * pattern(x, y) * shade(x, y);
                }
            }
        }
        let t = Image::new(3, s, s, data).unwrap();
        // A blur 8 texels wide passes the broad change (one period over
        // the side) almost whole and takes out the 8-texel pattern.
        let (e, info) = even_out(&t, 0.0625, Edges::Wrap).expect("evened out");
        // Texel over pattern: near constant after, far from it before.
        let spread = |img: &Image| {
            let r: Vec<f64> = (0..n)
                .map(|i| f64::from(img.data[i] / (colour[0] * pattern(i % s, i / s))))
                .collect();
            let m = r.iter().sum::<f64>() / n as f64;
            (r.iter().map(|v| (v - m).powi(2)).sum::<f64>() / n as f64).sqrt() / m
        };
        assert!(spread(&t) > 0.25, "{}", spread(&t));
        assert!(spread(&e) < 0.06, "{}", spread(&e));
        // At the default width (16 texels here) the blur passes only part
        // of the broad change: about half of it remains (0.16 of 0.30).
        let (d, _) = even_out(&t, DEFAULT_SCALE, Edges::Wrap).expect("evened out");
        assert!(
            spread(&d) < 0.6 * spread(&t),
            "{} vs {}",
            spread(&d),
            spread(&t)
        );
        // Colour (channel ratios) and the pattern's contrast are kept.
        for i in [0, 77, 4000, n - 1] {
            let g = e.data[i] / t.data[i];
            assert!((e.data[n + i] / t.data[n + i] - g).abs() < 1e-5);
            assert!((e.data[2 * n + i] / t.data[2 * n + i] - g).abs() < 1e-5);
        }
        assert!(
            info.gain_range[0] < 0.8 && info.gain_range[1] > 1.3,
            "{info:?}"
        );
    }

    #[test]
    fn flat_texture_is_unchanged_and_gains_are_bounded() {
        let flat = Image::new(3, 8, 12, vec![0.25; 3 * 96]).unwrap();
        let (e, info) = even_out(&flat, 0.3, Edges::Mirror).unwrap();
        for (a, b) in e.data.iter().zip(&flat.data) {
            assert!((a - b).abs() < 1e-6);
        }
        assert!((info.gain_range[0] - 1.0).abs() < 1e-9 && (info.gain_range[1] - 1.0).abs() < 1e-9);
        // A black half and a bright half: the black half's gain is capped.
        let (w, h) = (64, 64);
        let mut data = vec![0.0f32; 3 * w * h];
        for c in 0..3 {
            for i in 0..w * h {
                data[c * w * h + i] = if i % w < w / 2 { 1e-4 } else { 0.8 };
            }
        }
        let t = Image::new(3, h, w, data).unwrap();
        let (_, info) = even_out(&t, 0.05, Edges::Wrap).unwrap();
        assert!(info.gain_range[1] <= MAX_GAIN + 1e-12 && info.gain_range[0] >= 1.0 / MAX_GAIN);
        assert!(info.gain_range[1] > 3.9, "{info:?}");
    }

    #[test]
    fn nothing_to_do_is_none() {
        let grey = Image::new(1, 4, 4, vec![0.5; 16]).unwrap();
        assert!(even_out(&grey, 0.1, Edges::Wrap).is_none());
        let black = Image::new(3, 4, 4, vec![0.0; 48]).unwrap();
        assert!(even_out(&black, 0.1, Edges::Wrap).is_none());
        let rgb = Image::new(3, 4, 4, vec![0.5; 48]).unwrap();
        for s in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            assert!(even_out(&rgb, s, Edges::Wrap).is_none(), "{s}");
        }
        assert!(even_out(&Image::new(3, 0, 0, vec![]).unwrap(), 0.1, Edges::Mirror).is_none());
    }
}
