//! Resampling planar images between the working and the photo resolution.
//!
//! Pixel centres follow the conventions (`design.md` §2): pixel `(x, y)` covers
//! `[x, x+1) × [y, y+1)`, so a position `p` in an image of `n` pixels maps to
//! `(p + 0.5)·m/n − 0.5` in one of `m` pixels (PyTorch's `align_corners=False`).
//!
//! # Panics
//! Every function here panics, with a message, when asked to resample a
//! source that has no pixels to a destination that has some, and when a
//! plane's length is not its `width · height`.

use picker_render::io::Image;
use rayon::prelude::*;

use crate::equalize::Edges;

/// Source coordinate of destination index `i` when `src` pixels become `dst`
/// pixels (half-pixel centres), clamped to the source.
#[inline]
pub(crate) fn src_coord(i: usize, src: usize, dst: usize) -> (usize, usize, f32) {
    assert!(src > 0, "resample: the source has no pixels to sample");
    let p = ((i as f32 + 0.5) * src as f32 / dst as f32 - 0.5).max(0.0);
    let i0 = (p.floor() as usize).min(src - 1);
    let i1 = (i0 + 1).min(src - 1);
    (i0, i1, p - i0 as f32)
}

/// Bilinear resize of one plane (`w×h` → `dw×dh`), half-pixel centres, edges clamped.
pub fn bilinear_plane(src: &[f32], w: usize, h: usize, dw: usize, dh: usize) -> Vec<f32> {
    assert_eq!(src.len(), w * h, "plane length");
    let xs: Vec<_> = (0..dw).map(|x| src_coord(x, w, dw)).collect();
    let mut out = vec![0.0; dw * dh];
    // Rows in parallel: every output value is computed alone, so the bytes do
    // not depend on the thread count.
    out.par_chunks_mut(dw.max(1))
        .enumerate()
        .for_each(|(y, row)| {
            let (y0, y1, fy) = src_coord(y, h, dh);
            let (r0, r1) = (&src[y0 * w..(y0 + 1) * w], &src[y1 * w..(y1 + 1) * w]);
            for (o, &(x0, x1, fx)) in row.iter_mut().zip(&xs) {
                *o = lerp2(r0, r1, x0, x1, fx, fy);
            }
        });
    out
}

/// The bilinear blend of [`bilinear_plane`] (one definition, so that every
/// fast path gives the same bits).
#[inline(always)]
pub(crate) fn lerp2(r0: &[f32], r1: &[f32], x0: usize, x1: usize, fx: f32, fy: f32) -> f32 {
    let a = r0[x0] + (r0[x1] - r0[x0]) * fx;
    let b = r1[x0] + (r1[x1] - r1[x0]) * fx;
    a + (b - a) * fy
}

/// Resizes every plane of `img` to `dw × dh` with `resize_plane` (a copy when the size already fits).
fn per_plane(
    img: &Image,
    dw: usize,
    dh: usize,
    resize_plane: impl Fn(&[f32], usize, usize, usize, usize) -> Vec<f32>,
) -> Image {
    if (img.width, img.height) == (dw, dh) {
        return img.clone();
    }
    let mut data = Vec::with_capacity(img.channels * dw * dh);
    for c in 0..img.channels {
        data.extend(resize_plane(img.plane(c), img.width, img.height, dw, dh));
    }
    Image {
        channels: img.channels,
        height: dh,
        width: dw,
        data,
    }
}

/// Bilinear resize of every plane of `img` to `dw × dh`.
pub fn bilinear(img: &Image, dw: usize, dh: usize) -> Image {
    per_plane(img, dw, dh, bilinear_plane)
}

/// For each of `dn` destination cells over `n` source cells, the source
/// cells it overlaps and their share of it, `(index, weight)` (weights sum
/// to 1).
fn area_spans(n: usize, dn: usize) -> Vec<Vec<(usize, f32)>> {
    (0..dn)
        .map(|i| {
            let a = i as f64 * n as f64 / dn as f64;
            let b = (i + 1) as f64 * n as f64 / dn as f64;
            let mut v = Vec::new();
            let mut k = a.floor() as usize;
            while (k as f64) < b && k < n {
                let lo = a.max(k as f64);
                let hi = b.min((k + 1) as f64);
                if hi > lo {
                    v.push((k, ((hi - lo) / (b - a)) as f32));
                }
                k += 1;
            }
            v
        })
        .collect()
}

/// Area (box) downsampling of one plane: each destination pixel is the
/// coverage-weighted mean of the source pixels it overlaps. Works for any
/// ratio (upsampling degenerates to nearest-like sampling).
pub fn area_plane(src: &[f32], w: usize, h: usize, dw: usize, dh: usize) -> Vec<f32> {
    assert_eq!(src.len(), w * h, "plane length");
    let (sx, sy) = (area_spans(w, dw), area_spans(h, dh));
    let mut out = vec![0.0; dw * dh];
    // Rows in parallel (each value is one fixed-order sum: same bits).
    out.par_chunks_mut(dw.max(1))
        .zip(sy.par_iter())
        .for_each(|(row, ry)| {
            for (o, rx) in row.iter_mut().zip(&sx) {
                let mut s = 0.0;
                for &(yy, wy) in ry {
                    for &(xx, wx) in rx {
                        s += src[yy * w + xx] * wx * wy;
                    }
                }
                *o = s;
            }
        });
    out
}

/// Area (box) downsampling of interleaved RGB (`[h, w, 3]`, row-major, as
/// a decoded photo holds it) into planar RGB (`[3, dh, dw]`), each value the
/// coverage-weighted mean of the source values under its area (as
/// [`area_plane`] per channel), passed through `finish` as it is stored.
/// Rows in parallel, each value one fixed-order sum (the same bits for any
/// thread count); the source is read once, without a planar copy of it.
pub fn area_interleaved_rgb(
    rgb: &[f32],
    (w, h): (usize, usize),
    (dw, dh): (usize, usize),
    finish: impl Fn(f32) -> f32 + Sync,
) -> Vec<f32> {
    assert_eq!(rgb.len(), 3 * w * h, "interleaved RGB length");
    let (xs, ys) = (area_spans(w, dw), area_spans(h, dh));
    let n = dw * dh;
    let mut planes = vec![0.0f32; 3 * n];
    let (r, rest) = planes.split_at_mut(n);
    let (g, b) = rest.split_at_mut(n);
    let row = dw.max(1);
    r.par_chunks_mut(row)
        .zip(g.par_chunks_mut(row))
        .zip(b.par_chunks_mut(row))
        .zip(ys.par_iter())
        .for_each(|(((r, g), b), ry)| {
            let mut acc = vec![[0.0f32; 3]; dw];
            for &(sy, wy) in ry {
                let src = &rgb[3 * sy * w..3 * (sy + 1) * w];
                for (a, rx) in acc.iter_mut().zip(&xs) {
                    let mut s = [0.0f32; 3];
                    for &(sx, wx) in rx {
                        let p = &src[3 * sx..3 * sx + 3];
                        for c in 0..3 {
                            s[c] += p[c] * wx;
                        }
                    }
                    for c in 0..3 {
                        a[c] += s[c] * wy;
                    }
                }
            }
            for (x, a) in acc.iter().enumerate() {
                (r[x], g[x], b[x]) = (finish(a[0]), finish(a[1]), finish(a[2]));
            }
        });
    planes
}

/// Area downsampling of every plane of `img`.
pub fn area(img: &Image, dw: usize, dh: usize) -> Image {
    per_plane(img, dw, dh, area_plane)
}

/// Catmull-Rom weights of the four taps `i0 − 1 … i0 + 2` at fraction `t`
/// past `i0` (they sum to 1 and reproduce linear functions).
fn catmull_rom(t: f64) -> [f64; 4] {
    let (t2, t3) = (t * t, t * t * t);
    [
        0.5 * (-t3 + 2.0 * t2 - t),
        0.5 * (3.0 * t3 - 5.0 * t2 + 2.0),
        0.5 * (-3.0 * t3 + 4.0 * t2 + t),
        0.5 * (t3 - t2),
    ]
}

/// For each of `dn` destination pixels over `n` source pixels (half-pixel
/// centres), its four source taps and their Catmull-Rom weights.
fn cubic_taps(n: usize, dn: usize, edges: Edges) -> Vec<([usize; 4], [f32; 4])> {
    assert!(n > 0, "resample: the source has no pixels to sample");
    (0..dn)
        .map(|i| {
            let p = (i as f64 + 0.5) * n as f64 / dn as f64 - 0.5;
            let i0 = p.floor();
            let w = catmull_rom(p - i0);
            let idx = std::array::from_fn(|k| edges.index(i0 as isize - 1 + k as isize, n));
            (idx, w.map(|v| v as f32))
        })
        .collect()
}

/// Bicubic (Catmull-Rom) resize of one plane (`w×h` → `dw×dh`), half-pixel
/// centres, the edges wrapped or mirrored ([`Edges`]); separable, rows in
/// parallel (each value one fixed-order sum: the same bits for any thread
/// count). Meant for enlarging; it may overshoot near sharp edges.
pub fn bicubic_plane(
    src: &[f32],
    w: usize,
    h: usize,
    dw: usize,
    dh: usize,
    edges: Edges,
) -> Vec<f32> {
    assert_eq!(src.len(), w * h, "plane length");
    if dw == 0 || dh == 0 {
        return Vec::new();
    }
    let (tx, ty) = (cubic_taps(w, dw, edges), cubic_taps(h, dh, edges));
    // Horizontal pass: h rows of dw.
    let mut mid = vec![0.0f32; h * dw];
    mid.par_chunks_mut(dw)
        .zip(src.par_chunks(w))
        .for_each(|(row, s)| {
            for (o, (idx, wt)) in row.iter_mut().zip(&tx) {
                *o = wt[0] * s[idx[0]] + wt[1] * s[idx[1]] + wt[2] * s[idx[2]] + wt[3] * s[idx[3]];
            }
        });
    // Vertical pass.
    let mut out = vec![0.0f32; dh * dw];
    out.par_chunks_mut(dw)
        .zip(ty.par_iter())
        .for_each(|(row, (idx, wt))| {
            let r = |k: usize| &mid[idx[k] * dw..(idx[k] + 1) * dw];
            let (r0, r1, r2, r3) = (r(0), r(1), r(2), r(3));
            for (x, o) in row.iter_mut().enumerate() {
                *o = wt[0] * r0[x] + wt[1] * r1[x] + wt[2] * r2[x] + wt[3] * r3[x];
            }
        });
    out
}

/// [`bicubic_plane`] of every plane of `img`.
pub fn bicubic(img: &Image, dw: usize, dh: usize, edges: Edges) -> Image {
    per_plane(img, dw, dh, |s, w, h, dw, dh| {
        bicubic_plane(s, w, h, dw, dh, edges)
    })
}

/// Mask-aware (normalised) bilinear upsampling: only source pixels with
/// weight `> 0` contribute, `value = Σ wᵢ·m_i·vᵢ / Σ wᵢ·m_i`. Destination
/// pixels with no contributing source get the value of the nearest source
/// pixel with weight (found by growing the search), so every output is
/// defined as long as some weight is positive; with no weight at all the
/// plain bilinear result is returned.
pub fn masked_bilinear(img: &Image, weight: &[f32], dw: usize, dh: usize) -> Image {
    let (w, h) = (img.width, img.height);
    assert_eq!(weight.len(), w * h, "weight length");
    if !weight.iter().any(|&m| m > 0.0) {
        return bilinear(img, dw, dh);
    }
    let den = bilinear_plane(weight, w, h, dw, dh);
    let mut out = Image::zeros(img.channels, dh, dw);
    let nearest = nearest_weighted(weight, w, h);
    for c in 0..img.channels {
        let p = img.plane(c);
        let prod: Vec<f32> = p.iter().zip(weight).map(|(v, m)| v * m).collect();
        let num = bilinear_plane(&prod, w, h, dw, dh);
        let o = &mut out.data[c * dw * dh..(c + 1) * dw * dh];
        for y in 0..dh {
            for x in 0..dw {
                let i = y * dw + x;
                o[i] = if den[i] > 1e-6 {
                    num[i] / den[i]
                } else {
                    let sx = ((x as f32 + 0.5) * w as f32 / dw as f32) as usize;
                    let sy = ((y as f32 + 0.5) * h as f32 / dh as f32) as usize;
                    p[nearest[sy.min(h - 1) * w + sx.min(w - 1)]]
                };
            }
        }
    }
    out
}

/// [`masked_bilinear`] evaluated only at the destination pixels where `keep`
/// is true (the others are 0): the same values there, bit for bit, at the
/// cost of the kept pixels only, rows in parallel. For the photo-resolution
/// quantities that are only ever read inside the material's mask.
pub fn masked_bilinear_where(
    img: &Image,
    weight: &[f32],
    dw: usize,
    dh: usize,
    keep: &[bool],
) -> Image {
    let (w, h) = (img.width, img.height);
    assert_eq!(weight.len(), w * h, "weight length");
    assert_eq!(keep.len(), dw * dh, "keep length");
    if !weight.iter().any(|&m| m > 0.0) {
        let mut out = bilinear(img, dw, dh);
        for plane in out.data.chunks_mut((dw * dh).max(1)) {
            for (v, _) in plane.iter_mut().zip(keep).filter(|(_, &k)| !k) {
                *v = 0.0;
            }
        }
        return out;
    }
    let c = img.channels;
    let nearest = nearest_weighted(weight, w, h);
    let prods: Vec<Vec<f32>> = (0..c)
        .map(|ch| {
            img.plane(ch)
                .iter()
                .zip(weight)
                .map(|(v, m)| v * m)
                .collect()
        })
        .collect();
    let xs: Vec<_> = (0..dw).map(|x| src_coord(x, w, dw)).collect();
    let m = dw * dh;
    let mut out = Image::zeros(c, dh, dw);
    // Rows in parallel, each writing its row of every plane.
    let mut planes: Vec<_> = out
        .data
        .chunks_mut(m.max(1))
        .map(|p| p.chunks_mut(dw.max(1)))
        .collect();
    let rows: Vec<Vec<&mut [f32]>> = (0..dh)
        .map(|_| planes.iter_mut().filter_map(|p| p.next()).collect())
        .collect();
    rows.into_par_iter().enumerate().for_each(|(y, mut row)| {
        let (y0, y1, fy) = src_coord(y, h, dh);
        let (a0, a1) = (y0 * w, y1 * w);
        let (w0, w1) = (&weight[a0..a0 + w], &weight[a1..a1 + w]);
        for (x, &(x0, x1, fx)) in xs.iter().enumerate() {
            if !keep[y * dw + x] {
                continue;
            }
            let den = lerp2(w0, w1, x0, x1, fx, fy);
            for (ch, plane) in row.iter_mut().enumerate() {
                plane[x] = if den > 1e-6 {
                    let p = &prods[ch];
                    lerp2(&p[a0..a0 + w], &p[a1..a1 + w], x0, x1, fx, fy) / den
                } else {
                    let sx = ((x as f32 + 0.5) * w as f32 / dw as f32) as usize;
                    let sy = ((y as f32 + 0.5) * h as f32 / dh as f32) as usize;
                    img.plane(ch)[nearest[sy.min(h - 1) * w + sx.min(w - 1)]]
                };
            }
        }
    });
    out
}

/// For every pixel, the index of a nearest pixel (chamfer 3-4 distance) whose
/// weight is positive. Requires at least one positive weight.
pub fn nearest_weighted(weight: &[f32], w: usize, h: usize) -> Vec<usize> {
    const INF: u32 = u32::MAX / 2;
    let mut dist = vec![INF; w * h];
    let mut idx = vec![usize::MAX; w * h];
    for i in 0..w * h {
        if weight[i] > 0.0 {
            dist[i] = 0;
            idx[i] = i;
        }
    }
    let relax = |dist: &mut [u32], idx: &mut [usize], i: usize, j: usize, cost: u32| {
        if dist[j] != INF && dist[j] + cost < dist[i] {
            dist[i] = dist[j] + cost;
            idx[i] = idx[j];
        }
    };
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            if x > 0 {
                relax(&mut dist, &mut idx, i, i - 1, 3);
            }
            if y > 0 {
                relax(&mut dist, &mut idx, i, i - w, 3);
                if x > 0 {
                    relax(&mut dist, &mut idx, i, i - w - 1, 4);
                }
                if x + 1 < w {
                    relax(&mut dist, &mut idx, i, i - w + 1, 4);
                }
            }
        }
    }
    for y in (0..h).rev() {
        for x in (0..w).rev() {
            let i = y * w + x;
            if x + 1 < w {
                relax(&mut dist, &mut idx, i, i + 1, 3);
            }
            if y + 1 < h {
                relax(&mut dist, &mut idx, i, i + w, 3);
                if x + 1 < w {
                    relax(&mut dist, &mut idx, i, i + w + 1, 4);
                }
                if x > 0 {
                    relax(&mut dist, &mut idx, i, i + w - 1, 4);
                }
            }
        }
    }
    idx
}

/// The circular encoding of [`upsample_uv`]: `(cos 2πu, sin 2πu, cos 2πv,
/// sin 2πv, t)` per pixel, and the weights with every pixel whose `u` or `v`
/// is not finite set to 0 (its encoding 0), so that it never reaches a
/// resampled value (a 0 weight times NaN would still be NaN).
fn encode_uv(uv: &Image, weight: &[f32]) -> (Image, Vec<f32>) {
    use std::f32::consts::TAU;
    let n = uv.plane_len();
    let mut enc = Image::zeros(5, uv.height, uv.width);
    let mut w = weight.to_vec();
    for i in 0..n {
        let (u, v) = (uv.at(0, i), uv.at(1, i));
        if u.is_finite() && v.is_finite() {
            enc.data[i] = (TAU * u).cos();
            enc.data[n + i] = (TAU * u).sin();
            enc.data[2 * n + i] = (TAU * v).cos();
            enc.data[3 * n + i] = (TAU * v).sin();
        } else if let Some(x) = w.get_mut(i) {
            *x = 0.0;
        }
        enc.data[4 * n + i] = uv.at(2, i);
    }
    (enc, w)
}

/// `(u, v)` of pixel `i` of an upsampled encoding ([`encode_uv`], `m`
/// pixels a plane): NaN where the encoded directions vanish (no finite
/// coordinates reached the pixel, or opposite ones cancelled).
#[inline]
fn decode_uv(up: &[f32], m: usize, i: usize) -> (f32, f32) {
    use std::f32::consts::TAU;
    let (cu, su, cv, sv) = (up[i], up[m + i], up[2 * m + i], up[3 * m + i]);
    if cu.hypot(su) < 1e-6 || cv.hypot(sv) < 1e-6 {
        return (f32::NAN, f32::NAN);
    }
    (
        picker_nets::conventions::wrap_unit(su.atan2(cu) / TAU),
        picker_nets::conventions::wrap_unit(sv.atan2(cv) / TAU),
    )
}

/// Upsamples wrapped texture coordinates `(u, v, t)` without averaging across
/// the wrap: `u` and `v` go through their circular encoding
/// `(cos 2πu, sin 2πu)`, are resampled with [`masked_bilinear`] and decoded
/// with `atan2`; `t` is resampled as is. Pixels whose `u` or `v` is not
/// finite weigh nothing (they are filled like unweighted pixels); with no
/// finite coordinates at all, or where opposite directions cancel, `u` and
/// `v` are NaN (no coordinates, which reprojection skips).
pub fn upsample_uv(uv: &Image, weight: &[f32], dw: usize, dh: usize) -> Image {
    let (enc, w) = encode_uv(uv, weight);
    let up = masked_bilinear(&enc, &w, dw, dh);
    let m = dw * dh;
    let mut out = Image::zeros(3, dh, dw);
    for i in 0..m {
        (out.data[i], out.data[m + i]) = decode_uv(&up.data, m, i);
        out.data[2 * m + i] = up.data[4 * m + i];
    }
    out
}

/// [`upsample_uv`] evaluated only where `keep` is true (the other pixels get
/// NaN coordinates); the kept pixels equal the full version's (the same
/// operations in the same order).
pub fn upsample_uv_where(uv: &Image, weight: &[f32], dw: usize, dh: usize, keep: &[bool]) -> Image {
    let (enc, w) = encode_uv(uv, weight);
    let up = masked_bilinear_where(&enc, &w, dw, dh, keep);
    let m = dw * dh;
    let mut out = Image {
        channels: 3,
        height: dh,
        width: dw,
        data: vec![f32::NAN; 3 * m],
    };
    let (pu, rest) = out.data.split_at_mut(m);
    let (pv, pt) = rest.split_at_mut(m);
    let step = dw.max(1);
    pu.par_chunks_mut(step)
        .zip(pv.par_chunks_mut(step))
        .zip(pt.par_chunks_mut(step))
        .enumerate()
        .for_each(|(y, ((ru, rv), rt))| {
            for x in 0..ru.len() {
                let i = y * dw + x;
                if !keep[i] {
                    continue;
                }
                (ru[x], rv[x]) = decode_uv(&up.data, m, i);
                rt[x] = up.data[4 * m + i];
            }
        });
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each output the mean of the source over its area, by the overlap of
    /// every source pixel, in f64.
    fn area_reference(rgb: &[f32], (w, h): (usize, usize), (dw, dh): (usize, usize)) -> Vec<f64> {
        let overlap = |i: usize, n: usize, dn: usize, k: usize| {
            let s = n as f64 / dn as f64;
            let (a, b) = (i as f64 * s, (i + 1) as f64 * s);
            ((b.min(k as f64 + 1.0) - a.max(k as f64)).max(0.0)) / s
        };
        let mut out = vec![0.0; 3 * dw * dh];
        for c in 0..3 {
            for y in 0..dh {
                for x in 0..dw {
                    let mut v = 0.0;
                    for sy in 0..h {
                        for sx in 0..w {
                            v += f64::from(rgb[3 * (sy * w + sx) + c])
                                * overlap(x, w, dw, sx)
                                * overlap(y, h, dh, sy);
                        }
                    }
                    out[c * dw * dh + y * dw + x] = v;
                }
            }
        }
        out
    }

    #[test]
    fn interleaved_area_average_matches_its_definition_and_the_planes() {
        let mut rng = picker_tensor::Rng::new(31);
        // Integer and odd ratios, one side unchanged, a single column.
        for (w, h, dw, dh) in [
            (12, 8, 6, 4),
            (13, 7, 5, 3),
            (17, 11, 10, 11),
            (1, 9, 1, 4),
            (23, 19, 7, 6),
        ] {
            let rgb = rng.uniform_vec(3 * w * h, 0.0, 1.0);
            let got = area_interleaved_rgb(&rgb, (w, h), (dw, dh), |v| v);
            let want = area_reference(&rgb, (w, h), (dw, dh));
            for (g, r) in got.iter().zip(&want) {
                assert!(
                    (f64::from(*g) - r).abs() < 1e-5,
                    "{w}x{h} -> {dw}x{dh}: {g} vs {r}"
                );
            }
            // The planes' own area average, channel by channel.
            for c in 0..3 {
                let plane: Vec<f32> = (0..w * h).map(|i| rgb[3 * i + c]).collect();
                let p = area_plane(&plane, w, h, dw, dh);
                for (a, b) in p.iter().zip(&got[c * dw * dh..(c + 1) * dw * dh]) {
                    assert!((a - b).abs() < 1e-6, "{w}x{h} -> {dw}x{dh} channel {c}");
                }
            }
            // `finish` applies to every value.
            let shifted = area_interleaved_rgb(&rgb, (w, h), (dw, dh), |v| v + 1.0);
            for (a, b) in shifted.iter().zip(&got) {
                assert_eq!(*a, b + 1.0);
            }
        }
    }
    use picker_tensor::Rng;

    /// The Catmull-Rom kernel `k(x)` at offset `x` from a tap (support 2).
    fn keys(x: f64) -> f64 {
        let x = x.abs();
        if x < 1.0 {
            1.5 * x * x * x - 2.5 * x * x + 1.0
        } else if x < 2.0 {
            -0.5 * x * x * x + 2.5 * x * x - 4.0 * x + 2.0
        } else {
            0.0
        }
    }

    /// Plain reference of [`bicubic_plane`]: every destination pixel a
    /// direct 2-D sum in f64 over the source pixels within the kernel's
    /// support, the kernel written as a function of distance (not as the
    /// fast path's per-fraction tap weights), the edges resolved per tap.
    fn bicubic_reference(
        src: &[f32],
        w: usize,
        h: usize,
        dw: usize,
        dh: usize,
        edges: Edges,
    ) -> Vec<f64> {
        // Read past the edges by unrolling the line: wrapped, or mirrored
        // about the edge pixels (`…, 2, 1, 0, 1, 2, …`).
        let fetch = |j: i64, n: usize| {
            let n = n as i64;
            let mut j = j;
            match edges {
                Edges::Wrap => j.rem_euclid(n) as usize,
                Edges::Mirror => {
                    while n > 1 && !(0..n).contains(&j) {
                        j = if j < 0 { -j } else { 2 * (n - 1) - j };
                    }
                    if n == 1 {
                        0
                    } else {
                        j as usize
                    }
                }
            }
        };
        let mut out = Vec::with_capacity(dw * dh);
        for y in 0..dh {
            let py = (y as f64 + 0.5) * h as f64 / dh as f64 - 0.5;
            for x in 0..dw {
                let px = (x as f64 + 0.5) * w as f64 / dw as f64 - 0.5;
                let mut s = 0.0;
                for jy in (py.floor() as i64 - 3)..=(py.floor() as i64 + 3) {
                    for jx in (px.floor() as i64 - 3)..=(px.floor() as i64 + 3) {
                        let k = keys(px - jx as f64) * keys(py - jy as f64);
                        s += k * src[fetch(jy, h) * w + fetch(jx, w)] as f64;
                    }
                }
                out.push(s);
            }
        }
        out
    }

    /// Seeded random planes on edge shapes (1 pixel, one row or column,
    /// down- and up-scaling, odd ratios, both edge modes): the separable
    /// fast path equals the direct reference within f32 rounding.
    #[test]
    fn bicubic_matches_its_reference() {
        let mut rng = Rng::new(41);
        let shapes = [
            (1, 1, 1, 1),
            (1, 1, 5, 3),
            (1, 7, 4, 9),
            (6, 1, 13, 2),
            (2, 2, 2, 2),
            (3, 5, 17, 11),
            (8, 8, 64, 64),
            (9, 7, 4, 3),
            (16, 12, 50, 37),
            (5, 40, 5, 40),
        ];
        for (w, h, dw, dh) in shapes {
            for edges in [Edges::Wrap, Edges::Mirror] {
                let src = rng.uniform_vec(w * h, -1.0, 2.0);
                let fast = bicubic_plane(&src, w, h, dw, dh, edges);
                let slow = bicubic_reference(&src, w, h, dw, dh, edges);
                assert_eq!(fast.len(), dw * dh);
                for (i, (&f, &s)) in fast.iter().zip(&slow).enumerate() {
                    assert!(
                        (f as f64 - s).abs() <= 1e-5 * (1.0 + s.abs()),
                        "{w}x{h} -> {dw}x{dh} {edges:?} pixel {i}: {f} vs {s}"
                    );
                }
            }
        }
        assert!(bicubic_plane(&[1.0; 6], 3, 2, 0, 4, Edges::Wrap).is_empty());
    }

    /// Analytic cases: a constant stays constant; a linear ramp is
    /// reproduced exactly away from mirrored edges; a periodic sinusoid
    /// enlarged 8× with wrapped edges follows the continuous one closely at
    /// every pixel, across the wrap edges too (the result tiles); a
    /// same-size resize is the identity.
    #[test]
    fn bicubic_analytic_cases() {
        for edges in [Edges::Wrap, Edges::Mirror] {
            let c = bicubic_plane(&[0.25; 35], 7, 5, 29, 13, edges);
            assert!(c.iter().all(|&v| (v - 0.25).abs() < 1e-6));
        }
        let (w, dw) = (12usize, 48usize);
        let ramp: Vec<f32> = (0..w).map(|x| 0.1 * x as f32).collect();
        let up = bicubic_plane(&ramp, w, 1, dw, 1, Edges::Mirror);
        for (x, &v) in up.iter().enumerate() {
            let p = (x as f32 + 0.5) * w as f32 / dw as f32 - 0.5;
            if p >= 1.0 && p <= (w - 2) as f32 {
                assert!(
                    (v - 0.1 * p).abs() < 1e-5,
                    "ramp at {x}: {v} vs {}",
                    0.1 * p
                );
            }
        }
        let (n, m) = (32usize, 256usize);
        let wave = |t: f64| {
            (std::f64::consts::TAU * t).sin() + 0.5 * (2.0 * std::f64::consts::TAU * t).cos()
        };
        let src: Vec<f32> = (0..n * n)
            .map(|i| {
                (wave((i % n) as f64 / n as f64 + 0.5 / n as f64)
                    * wave((i / n) as f64 / n as f64 + 0.5 / n as f64)) as f32
            })
            .collect();
        let up = bicubic_plane(&src, n, n, m, m, Edges::Wrap);
        for (i, &v) in up.iter().enumerate() {
            let (x, y) = ((i % m) as f64, (i / m) as f64);
            let truth = wave((x + 0.5) / m as f64) * wave((y + 0.5) / m as f64);
            assert!(
                (v as f64 - truth).abs() < 0.01,
                "wave at {i}: {v} vs {truth}"
            );
        }
        let same = bicubic_plane(&src, n, n, n, n, Edges::Mirror);
        assert!(same.iter().zip(&src).all(|(a, b)| (a - b).abs() < 1e-6));
    }

    /// Random images, weights (some all zero, some sparse) and keep masks on
    /// edge shapes: the `_where` fast paths equal the full versions where kept.
    #[test]
    fn where_variants_match_the_full_versions() {
        let mut rng = Rng::new(5);
        let shapes = [
            (1, 1, 1, 1),
            (1, 1, 7, 5),
            (3, 2, 1, 9),
            (4, 3, 37, 29),
            (10, 7, 10, 7),
            (20, 15, 9, 4),
            (32, 24, 400, 300),
        ];
        for &(w, h, dw, dh) in &shapes {
            for density in [0.0, 0.05, 0.6, 1.0] {
                let img = Image::new(3, h, w, rng.uniform_vec(3 * w * h, 0.0, 1.0)).unwrap();
                let weight: Vec<f32> = (0..w * h)
                    .map(|_| {
                        if rng.f64() < density {
                            rng.uniform(0.1, 1.0)
                        } else {
                            0.0
                        }
                    })
                    .collect();
                let keep: Vec<bool> = (0..dw * dh).map(|_| rng.f64() < 0.7).collect();
                let full = masked_bilinear(&img, &weight, dw, dh);
                let fast = masked_bilinear_where(&img, &weight, dw, dh, &keep);
                let uv_full = upsample_uv(&img, &weight, dw, dh);
                let uv_fast = upsample_uv_where(&img, &weight, dw, dh, &keep);
                for c in 0..3 {
                    for (i, &k) in keep.iter().enumerate() {
                        let j = c * dw * dh + i;
                        if k {
                            assert_eq!(full.data[j].to_bits(), fast.data[j].to_bits());
                            assert_eq!(uv_full.data[j].to_bits(), uv_fast.data[j].to_bits());
                        } else {
                            assert_eq!(fast.data[j], 0.0);
                            assert!(uv_fast.data[j].is_nan());
                        }
                    }
                }
            }
        }
    }

    /// The parallel area resize equals the plain sequential double loop.
    #[test]
    fn area_matches_sequential_reference() {
        let mut rng = Rng::new(7);
        for &(w, h, dw, dh) in &[(1, 1, 1, 1), (7, 3, 2, 2), (40, 30, 7, 5), (5, 4, 9, 11)] {
            let src = rng.uniform_vec(w * h, -1.0, 1.0);
            let got = area_plane(&src, w, h, dw, dh);
            let (sx, sy) = (area_spans(w, dw), area_spans(h, dh));
            for (y, ry) in sy.iter().enumerate() {
                for (x, rx) in sx.iter().enumerate() {
                    let mut s = 0.0f32;
                    for &(yy, wy) in ry {
                        for &(xx, wx) in rx {
                            s += src[yy * w + xx] * wx * wy;
                        }
                    }
                    assert_eq!(got[y * dw + x].to_bits(), s.to_bits());
                }
            }
        }
    }

    /// The parallel bilinear resize equals a plain sequential loop.
    #[test]
    fn bilinear_matches_sequential_reference() {
        let mut rng = Rng::new(6);
        for &(w, h, dw, dh) in &[(1, 1, 3, 2), (5, 3, 17, 1), (9, 9, 4, 4), (13, 7, 50, 31)] {
            let src = rng.uniform_vec(w * h, -1.0, 1.0);
            let got = bilinear_plane(&src, w, h, dw, dh);
            for y in 0..dh {
                let (y0, y1, fy) = src_coord(y, h, dh);
                for x in 0..dw {
                    let (x0, x1, fx) = src_coord(x, w, dw);
                    let (r0, r1) = (&src[y0 * w..], &src[y1 * w..]);
                    let a = r0[x0] + (r0[x1] - r0[x0]) * fx;
                    let b = r1[x0] + (r1[x1] - r1[x0]) * fx;
                    assert_eq!(got[y * dw + x].to_bits(), (a + (b - a) * fy).to_bits());
                }
            }
        }
    }

    #[test]
    fn bilinear_identity_and_constant() {
        let src: Vec<f32> = (0..12).map(|v| v as f32).collect();
        assert_eq!(bilinear_plane(&src, 4, 3, 4, 3), src);
        let c = vec![0.25f32; 35];
        assert!(bilinear_plane(&c, 7, 5, 23, 11)
            .iter()
            .all(|&v| (v - 0.25).abs() < 1e-7));
    }

    #[test]
    fn area_preserves_mean_and_constants() {
        let src: Vec<f32> = (0..60).map(|v| (v % 7) as f32).collect();
        let d = area_plane(&src, 10, 6, 5, 3);
        let m0: f32 = src.iter().sum::<f32>() / 60.0;
        let m1: f32 = d.iter().sum::<f32>() / 15.0;
        assert!((m0 - m1).abs() < 1e-5);
        let d = area_plane(&src, 10, 6, 3, 4);
        let m2: f32 = d.iter().sum::<f32>() / 12.0;
        assert!((m0 - m2).abs() < 1e-4, "{m0} {m2}");
    }

    #[test]
    fn uv_upsampling_does_not_average_across_the_wrap() {
        // u = 0.95 | 0.05 side by side: the middle must be near 0 (wrapped), never 0.5.
        let uv = Image::new(3, 1, 2, vec![0.95, 0.05, 0.5, 0.5, 1.0, 1.0]).unwrap();
        let up = upsample_uv(&uv, &[1.0, 1.0], 4, 1);
        for x in 0..4 {
            let u = up.at(0, x);
            assert!(!(0.2..0.8).contains(&u), "u = {u}");
        }
    }

    #[test]
    fn non_finite_uvs_weigh_nothing() {
        // Left pixel NaN, right pixel fine: the NaN pixel weighs nothing, so
        // every output has the finite pixel's coordinates (as an unweighted
        // pixel would); before, NaN became u = v = 0 through `wrap_unit`.
        let uv = Image::new(3, 1, 2, vec![f32::NAN, 0.3, f32::NAN, 0.6, 1.0, 1.0]).unwrap();
        let keep = vec![true; 4];
        for up in [
            upsample_uv(&uv, &[1.0, 1.0], 4, 1),
            upsample_uv_where(&uv, &[1.0, 1.0], 4, 1, &keep),
        ] {
            for x in 0..4 {
                assert!((up.at(0, x) - 0.3).abs() < 1e-5, "{:?}", up.data);
                assert!((up.at(1, x) - 0.6).abs() < 1e-5, "{:?}", up.data);
            }
        }
        // No finite coordinates at all: none anywhere (NaN), not 0.
        let nan = Image::new(3, 2, 2, vec![f32::NAN; 12]).unwrap();
        for up in [
            upsample_uv(&nan, &[1.0; 4], 3, 3),
            upsample_uv_where(&nan, &[1.0; 4], 3, 3, &[true; 9]),
        ] {
            assert!(up.data[..18].iter().all(|v| v.is_nan()), "{:?}", up.data);
        }
    }

    #[test]
    fn masked_bilinear_ignores_unweighted_pixels() {
        let img = Image::new(1, 1, 4, vec![1.0, 1.0, 9.0, 9.0]).unwrap();
        let up = masked_bilinear(&img, &[1.0, 1.0, 0.0, 0.0], 8, 1);
        assert!(
            up.data.iter().all(|&v| (v - 1.0).abs() < 1e-6),
            "{:?}",
            up.data
        );
    }
}
