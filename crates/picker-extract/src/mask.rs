//! From a pick to the picked material's mask.
//!
//! The material's colour is read from the segmentation image around the pick
//! robustly: the per-channel median of the 3×3 pixels at the pick is the
//! reference, and the pick colour is the per-channel median of the pixels of
//! a 5×5 window within [`PICK_NEIGHBOUR_DISTANCE`] of that reference (so a
//! noisy pixel, or a pick next to an edge, does not decide the colour). The
//! spread of those pixels around the pick colour (1.4826·MAD) sets the
//! tolerance: `τ = clamp(τ_min + 3σ, τ_min, τ_max)` unless given. A pixel
//! belongs to the material when it has a surface and its segmentation colour
//! is within `τ` (Euclidean, RGB in `[0, 1]`) of the pick colour. Without
//! `connected`, every region of that colour counts (a floor split by a table
//! is one material) and specks smaller than [`MIN_SPECK_FRACTION`] of the
//! image are dropped; with `connected`, only the 8-connected region at the
//! pick (or nearest to it) is kept.

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
            data: self.data.iter().map(|&b| b as u8 as f32).collect(),
        }
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
}

/// The pick's material at the segmentation's resolution.
#[derive(Clone, Debug)]
pub struct PickMask {
    /// The mask.
    pub mask: Mask,
    /// The material's segmentation colour.
    pub colour: [f32; 3],
    /// The tolerance used.
    pub tolerance: f32,
}

fn median(v: &mut [f32]) -> f32 {
    if v.is_empty() {
        return 0.0;
    }
    let mid = v.len() / 2;
    v.select_nth_unstable_by(mid, |a, b| a.total_cmp(b));
    v[mid]
}

fn dist(a: [f32; 3], b: [f32; 3]) -> f32 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

fn colour(seg: &Image, i: usize) -> [f32; 3] {
    [seg.at(0, i), seg.at(1, i), seg.at(2, i)]
}

/// The robust segmentation colour at pixel `(x, y)` and its noise spread σ.
/// `valid[i]`: the pixel has a surface.
pub fn pick_colour(seg: &Image, valid: &[bool], x: usize, y: usize) -> Option<([f32; 3], f32)> {
    let (w, h) = (seg.width, seg.height);
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

/// The automatic tolerance: `τ = clamp(τ_min + 3σ, τ_min, τ_max)`, lowered
/// to the middle of the first empty band of colour distances beyond the
/// pick's own spread (at least [`GAP_MIN`] wide), so two materials whose
/// segmentation colours are close but distinct (as in clean segmentations)
/// stay apart.
fn gap_tolerance(seg: &Image, valid: &[bool], c: [f32; 3], sigma: f32) -> f32 {
    let tau = (TOLERANCE_MIN + 3.0 * sigma).clamp(TOLERANCE_MIN, TOLERANCE_MAX);
    let mut d: Vec<f32> = (0..seg.plane_len())
        .filter(|&i| valid[i])
        .map(|i| dist(colour(seg, i), c))
        .filter(|&x| x <= tau)
        .collect();
    d.sort_by(|a, b| a.total_cmp(b));
    let own = 3.0 * sigma;
    let gap = GAP_MIN.max(sigma);
    for p in d.windows(2) {
        if p[0] >= own && p[1] - p[0] >= gap {
            return (p[0] + p[1]) / 2.0;
        }
    }
    tau
}

/// Narrowest empty band of colour distances that separates two materials.
pub const GAP_MIN: f32 = 0.004;

/// 8-connected component labels of `mask` (0 = outside, 1.. = component).
pub fn components(mask: &Mask) -> (Vec<u32>, Vec<usize>) {
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
            for dy in -1..=1 {
                for dx in -1..=1 {
                    let (xx, yy) = (x + dx, y + dy);
                    if xx < 0 || yy < 0 || xx >= w as i64 || yy >= h as i64 {
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

/// The mask of the material at pixel `(x, y)` of the segmentation image.
pub fn pick_mask(
    seg: &Image,
    valid: &[bool],
    x: usize,
    y: usize,
    opts: &MaskOptions,
) -> Result<PickMask> {
    let (w, h) = (seg.width, seg.height);
    if seg.channels != 3 {
        return Err(Error::Shape {
            what: "segmentation".into(),
            expected: "3 channels".into(),
            found: format!("{}", seg.channels),
        });
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
    let tolerance = match opts.tolerance {
        Some(t) => t,
        None => gap_tolerance(seg, valid, c, sigma),
    };
    let data: Vec<bool> = (0..w * h)
        .map(|i| valid[i] && dist(colour(seg, i), c) <= tolerance)
        .collect();
    let mut mask = Mask {
        width: w,
        height: h,
        data,
    };
    let (label, sizes) = components(&mask);
    // The component at the pick, or the one nearest to it.
    let at = {
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
    };
    let min_size = ((MIN_SPECK_FRACTION * (w * h) as f64).ceil() as usize).max(1);
    for (i, m) in mask.data.iter_mut().enumerate() {
        let l = label[i];
        *m = l != 0 && (l == at || (!opts.connected && sizes[l as usize] >= min_size));
    }
    Ok(PickMask {
        mask,
        colour: c,
        tolerance,
    })
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
                tolerance: None,
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
}
