//! The photo's split of an estimated mask: objects the segmentation merged
//! into the picked material are taken out where the photo *and* the
//! network's own colours both set them apart.
//!
//! An undertrained or out-of-domain segmentation network (the embedded
//! `lite` weights on a real photo) gives a patterned material a spread of
//! colours — a wallpaper's motifs each get their own tint — and the mask's
//! automatic tolerance ([`crate::mask::auto_tolerance`]) grows to hold them,
//! and with them the plant in front of the wallpaper or the objects on a
//! table. The texture then shows the leaves, the pencil and the cup.
//!
//! The guard looks at the mask `M` in the photo ([`split_mask`]):
//! 1. each pixel's chromaticity (linear `r/s`, `g/s`, `s = r+g+b`) and
//!    [`LUMA_WEIGHT`]`·ln(luminance)`, averaged over the mask's pixels within
//!    a Gaussian of [`SIGMA_FRACTION`] of the image's shorter side, is
//!    compared with its median in the 3×3 at the pick;
//! 2. Otsu's threshold splits those distances over `M` into a near class
//!    (the pick's look) and a far one; the far pixels whose segmentation
//!    colour (the image the mask was cut from, in mask units) lies at least
//!    half [`MIN_SEGMENTATION_GAP`] from the near class's median colour are
//!    the candidates (Otsu splits one look too — a table's lit and shaded
//!    halves —, and the segmentation does not set those apart);
//! 3. each 4-connected region of the candidates leaves the mask, with the
//!    mask's pixels touching it, when
//!    - its median segmentation colour lies at least
//!      [`MIN_SEGMENTATION_GAP`] from the near class's: the network also
//!      sees another material there (a pot's lit and shaded sides look
//!      different in the photo but not to the network: they stay),
//!    - its median feature distance is at least [`MIN_LOOK_DISTANCE`]: it
//!      looks clearly different, more than lighting makes one material look,
//!    - the mask holds at least [`MIN_ENCLOSURE`] of its outline: it lies in
//!      front of or within the material (a plant before the wallpaper, a
//!      cup on the table) rather than being another surface at the mask's
//!      edge (a second wall under another light), and
//!    - it is not one of a repeating set: fewer than [`MAX_REPEATS`] far
//!      regions are at least half its size (a wallpaper's motifs, a
//!      chessboard's squares are the material's own pattern), and it holds
//!      at least [`MIN_REGION_FRACTION`] of the mask (not a speck).
//!
//! Every test is needed, and the split is still cautious, not complete. It
//! sees colour, not texture: light-green leaves in front of a pale green
//! wallpaper look like the wallpaper's background and stay. Measured with
//! the embedded networks, `picker eval --embedded` (40 procedural scenes
//! per seed), mean mask IoU without → with the split: 4242 0.8567 →
//! 0.8547, 9191 0.8637 → 0.8645, 5151 0.8624 → 0.8595 (precision up, recall
//! down: synthetic rooms light their walls with strongly coloured lamps,
//! which neither the photo's colour nor the embedded network's embedding
//! tells from a change of material), wide views down at floors and tables
//! (seed 7171) 0.911 → 0.914; without [`MIN_LOOK_DISTANCE`] and
//! [`MIN_ENCLOSURE`] and with a gap of 0.08, 0.8373 / 0.8567 / 0.8341. On
//! real photos (`scripts/real-photo-sweep.sh`) it takes the dark aloe
//! leaves out of the wallpaper behind them and the pencil, cup, lighter
//! and cap out of the table they lie on (`aloeL.jpg`, `stuff.jpg`).
//!
//! Ground-truth segmentations are exact and are not split
//! ([`crate::Inputs::segmentation_estimated`]); a given tolerance
//! (`--tolerance`) is taken as the user's word and is not split either.

use picker_render::io::Image;

use crate::mask::{self, Mask};
use crate::shading::smooth_in_mask;

/// Weight of `ln(luminance)` against the chromaticity in the split's
/// features: a factor of `e` in brightness counts as 0.03 of chromaticity,
/// so shading alone (a lit and a shaded side) rarely splits a material.
pub const LUMA_WEIGHT: f32 = 0.03;
/// Spatial σ of the features' averaging, as a fraction of the shorter side
/// (2 px at 240×320): photo noise and JPEG blocks average out, a plant's
/// thin leaves do not.
pub const SIGMA_FRACTION: f32 = 1.0 / 120.0;
/// Smallest distance (mask units: RGB in `[0, 1]` or
/// [`mask::embedding_mask_space`]) between the median segmentation colours
/// of a far region and of the near class for the region to leave the mask:
/// half the gap [`mask::EMBEDDING_SCALE`] maps the embedding's trained
/// separation of two materials to, closer to another material than to the
/// picked one (0.08 took out two walls of one material in a synthetic room
/// at 0.093).
pub const MIN_SEGMENTATION_GAP: f32 = 0.1;
/// Smallest median distance of a far region's features from the look at the
/// pick for the region to leave the mask: a chromaticity shift of 0.08 (a
/// beige wall to a green leaf is ~0.12) or, in brightness alone, a factor
/// of `e^(0.08 / LUMA_WEIGHT)` ≈ 14. Lighting splits a material by less:
/// a paper sheet's shading 0.02–0.05, two walls of one material under
/// differently coloured lights 0.04–0.06 (`picker eval --embedded`).
pub const MIN_LOOK_DISTANCE: f32 = 0.08;
/// Smallest share of a far region's outline (its 4-neighbours outside it,
/// the image's border not counted) that the mask holds for the region to
/// leave it: an object in front of the material is surrounded by it, while
/// another surface of the material (a second wall) meets other materials
/// along most of its outline.
pub const MIN_ENCLOSURE: f64 = 0.6;
/// A far region stays when this many far regions (itself included) are at
/// least half its size: it is an element of the material's pattern.
pub const MAX_REPEATS: usize = 6;
/// Smallest far region (fraction of the mask) that may leave it.
pub const MIN_REGION_FRACTION: f64 = 1e-3;
/// Masks smaller than this many pixels are not split.
pub const MIN_MASK_PIXELS: usize = 64;

/// What the split did, for `material.json`'s diagnostics.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct SplitCheck {
    /// Otsu's threshold on the feature distances.
    pub threshold: f32,
    /// Fisher's ratio `(μ_far − μ_near)² / (σ²_near + σ²_far)` of the two
    /// classes (0 when the mask was too small): how bimodal the photo's look
    /// over the mask is (a single Gaussian look split at its middle gives
    /// ~3.5, a uniform one 6).
    pub fisher: f64,
    /// Share of the mask among the candidates.
    pub far_share: f64,
    /// Far regions taken out of the mask.
    pub regions_removed: usize,
    /// Share of the mask taken out.
    pub removed_share: f64,
}

/// The split's features of a linear RGB photo (3 channels): `r/s`, `g/s`
/// and [`LUMA_WEIGHT`]`·ln(Y)`, with small floors so black pixels stay finite.
pub fn features(photo: &Image) -> Image {
    let n = photo.width * photo.height;
    let mut data = vec![0f32; 3 * n];
    let (r, rest) = photo.data.split_at(n);
    let (g, b) = rest.split_at(n);
    for i in 0..n {
        let (r, g, b) = (r[i].max(0.0), g[i].max(0.0), b[i].max(0.0));
        let s = r + g + b + 3e-3;
        data[i] = (r + 1e-3) / s;
        data[n + i] = (g + 1e-3) / s;
        data[2 * n + i] = LUMA_WEIGHT * (0.2126 * r + 0.7152 * g + 0.0722 * b + 1e-3).ln();
    }
    Image {
        channels: 3,
        height: photo.height,
        width: photo.width,
        data,
    }
}

/// Otsu's threshold of `v` (sorted ascending, at least 2 values) and the
/// two classes' Fisher ratio. The threshold lies halfway between the last
/// value of the lower class and the first of the upper one.
pub fn otsu(v: &[f32]) -> (f32, f64) {
    let n = v.len();
    if n < 2 {
        return (v.first().copied().unwrap_or(0.0), 0.0);
    }
    let (mut s, mut s2) = (0f64, 0f64);
    let mut prefix = Vec::with_capacity(n);
    for &x in v {
        s += f64::from(x);
        s2 += f64::from(x) * f64::from(x);
        prefix.push((s, s2));
    }
    let (tot, tot2) = (s, s2);
    let mut best = (f64::NEG_INFINITY, 0usize);
    for i in 0..n - 1 {
        // Split only between distinct values.
        if v[i] == v[i + 1] {
            continue;
        }
        let (n0, n1) = ((i + 1) as f64, (n - i - 1) as f64);
        let (m0, m1) = (prefix[i].0 / n0, (tot - prefix[i].0) / n1);
        let between = n0 * n1 * (m1 - m0).powi(2);
        if between > best.0 {
            best = (between, i);
        }
    }
    if best.0 == f64::NEG_INFINITY {
        return (v[0], 0.0);
    }
    let i = best.1;
    let (n0, n1) = ((i + 1) as f64, (n - i - 1) as f64);
    let (m0, m1) = (prefix[i].0 / n0, (tot - prefix[i].0) / n1);
    let v0 = (prefix[i].1 / n0 - m0 * m0).max(0.0);
    let v1 = ((tot2 - prefix[i].1) / n1 - m1 * m1).max(0.0);
    let fisher = (m1 - m0).powi(2) / (v0 + v1).max(1e-18);
    ((v[i] + v[i + 1]) / 2.0, fisher)
}

fn median_colour(img: &Image, pixels: impl Iterator<Item = usize> + Clone) -> [f32; 3] {
    std::array::from_fn(|c| {
        mask::median(&mut pixels.clone().map(|i| img.at(c, i)).collect::<Vec<_>>())
    })
}

/// The mask `m` without the regions the photo and the segmentation both set
/// apart from the look at the pick `(x, y)` (module docs), with what was
/// checked; `None` for the mask when nothing leaves it.
///
/// `photo_linear` is the photo at the mask's resolution (linear RGB, 3
/// channels), `seg` the image the mask was cut from (3 channels, mask units).
/// The pixel at the pick always stays in the mask; regions left smaller than
/// [`mask::MIN_SPECK_FRACTION`] of the image are dropped as
/// [`mask::pick_mask_on`] drops them, and with `connected` only the region at
/// the pick is kept.
///
/// # Panics
/// When the images' or the mask's sizes differ, or an image has fewer than
/// 3 channels.
pub fn split_mask(
    photo_linear: &Image,
    seg: &Image,
    m: &Mask,
    x: usize,
    y: usize,
    connected: bool,
) -> (Option<Mask>, SplitCheck) {
    let (w, h) = (m.width, m.height);
    assert!(
        photo_linear.width == w
            && photo_linear.height == h
            && seg.width == w
            && seg.height == h
            && photo_linear.channels >= 3
            && seg.channels >= 3,
        "split_mask: a {}x{} mask, a {}x{}x{} photo and a {}x{}x{} segmentation",
        w,
        h,
        photo_linear.channels,
        photo_linear.width,
        photo_linear.height,
        seg.channels,
        seg.width,
        seg.height
    );
    let mut check = SplitCheck::default();
    let count = m.count();
    if count < MIN_MASK_PIXELS || x >= w || y >= h {
        return (None, check);
    }
    let weight: Vec<f32> = m.data.iter().map(|&b| f32::from(u8::from(b))).collect();
    let sigma = SIGMA_FRACTION * w.min(h) as f32;
    let f = smooth_in_mask(&features(photo_linear), &weight, sigma);
    // The look at the pick: the per-channel median over the mask's pixels
    // in the 3×3 at it (the pick's own pixel when none is in the mask).
    let around: Vec<usize> = (y.saturating_sub(1)..(y + 2).min(h))
        .flat_map(|yy| (x.saturating_sub(1)..(x + 2).min(w)).map(move |xx| yy * w + xx))
        .filter(|&i| m.data[i])
        .collect();
    let around = if around.is_empty() {
        vec![y * w + x]
    } else {
        around
    };
    let f0 = median_colour(&f, around.iter().copied());
    let d: Vec<f32> = (0..w * h)
        .map(|i| {
            if m.data[i] {
                mask::dist(mask::colour(&f, i), f0)
            } else {
                f32::NAN
            }
        })
        .collect();
    let mut inside: Vec<f32> = d.iter().copied().filter(|v| !v.is_nan()).collect();
    inside.sort_unstable_by(|a, b| a.total_cmp(b));
    let (t, fisher) = otsu(&inside);
    check.threshold = t;
    check.fisher = fisher;
    if d[y * w + x] > t {
        return (None, check);
    }
    let near_colour = median_colour(seg, (0..w * h).filter(|&i| m.data[i] && d[i] <= t));
    let gap_of = |c: [f32; 3]| mask::dist(c, near_colour);
    // Candidates: far in the photo and, pixel by pixel, at least half the
    // gap away in the segmentation (the far half of a shaded table is not).
    let far = Mask {
        width: w,
        height: h,
        data: (0..w * h)
            .map(|i| {
                m.data[i] && d[i] > t && gap_of(mask::colour(seg, i)) >= 0.5 * MIN_SEGMENTATION_GAP
            })
            .collect(),
    };
    check.far_share = far.count() as f64 / count as f64;
    let (label, sizes) = mask::components4(&far);
    let mut members: Vec<Vec<usize>> = vec![Vec::new(); sizes.len()];
    for (i, &l) in label.iter().enumerate() {
        if l != 0 {
            members[l as usize].push(i);
        }
    }
    let min_size = ((MIN_REGION_FRACTION * count as f64).ceil() as usize).max(1);
    let mut sorted: Vec<usize> = sizes[1..].to_vec();
    sorted.sort_unstable_by(|a, b| b.cmp(a));
    let mut out = m.clone();
    for (l, px) in members.iter().enumerate().skip(1) {
        let size = sizes[l];
        if size < min_size {
            continue;
        }
        // Far regions at least half this one's size (itself included).
        let alike = sorted.partition_point(|&s| 2 * s >= size);
        if alike >= MAX_REPEATS {
            continue;
        }
        // How much of the region's outline the mask holds (the image's
        // border does not count).
        let (mut held, mut outline) = (0usize, 0usize);
        for &i in px {
            for j in mask::neighbours4(i, w, h) {
                if label[j] != l as u32 {
                    outline += 1;
                    held += usize::from(m.data[j]);
                }
            }
        }
        let enclosed = held as f64 / outline.max(1) as f64;
        let gap = gap_of(median_colour(seg, px.iter().copied()));
        let look = mask::median(&mut px.iter().map(|&i| d[i]).collect::<Vec<_>>());
        if gap < MIN_SEGMENTATION_GAP || look < MIN_LOOK_DISTANCE || enclosed < MIN_ENCLOSURE {
            continue;
        }
        // The region and the mask's pixels touching it (8-neighbours): its
        // outline is a blend of the two looks.
        for &i in px {
            let (xi, yi) = (i % w, i / w);
            for yy in yi.saturating_sub(1)..(yi + 2).min(h) {
                for xx in xi.saturating_sub(1)..(xi + 2).min(w) {
                    out.data[yy * w + xx] = false;
                }
            }
        }
        check.regions_removed += 1;
    }
    if check.regions_removed == 0 {
        return (None, check);
    }
    // The pick's own pixel stays; what the regions leave of the mask is
    // kept as the mask's regions were (specks dropped, or the one region).
    out.data[y * w + x] = m.data[y * w + x];
    let (label, sizes) = mask::components(&out);
    let at = mask::nearest_label(&label, w, (x, y));
    let min_speck = ((mask::MIN_SPECK_FRACTION * (w * h) as f64).ceil() as usize).max(1);
    for (o, &l) in out.data.iter_mut().zip(&label) {
        *o = l != 0 && (l == at || (!connected && sizes[l as usize] >= min_speck));
    }
    check.removed_share = (count - out.count()) as f64 / count as f64;
    (Some(out), check)
}

#[cfg(test)]
mod tests {
    use super::*;

    const W: usize = 64;
    const H: usize = 48;

    /// A linear photo and a segmentation (mask units) of `W × H` from a
    /// per-pixel function giving (linear RGB, segmentation colour).
    fn scene(f: impl Fn(usize, usize) -> ([f32; 3], [f32; 3])) -> (Image, Image) {
        let n = W * H;
        let (mut photo, mut seg) = (vec![0f32; 3 * n], vec![0f32; 3 * n]);
        for y in 0..H {
            for x in 0..W {
                let (p, s) = f(x, y);
                for c in 0..3 {
                    photo[c * n + y * W + x] = p[c];
                    seg[c * n + y * W + x] = s[c];
                }
            }
        }
        (
            Image::new(3, H, W, photo).unwrap(),
            Image::new(3, H, W, seg).unwrap(),
        )
    }

    fn full() -> Mask {
        Mask {
            width: W,
            height: H,
            data: vec![true; W * H],
        }
    }

    const BEIGE: [f32; 3] = [0.6, 0.5, 0.35];
    const PINK: [f32; 3] = [0.7, 0.35, 0.4];
    const GREEN: [f32; 3] = [0.15, 0.4, 0.1];
    const SEG: [f32; 3] = [0.5, 0.5, 0.5];

    fn shifted(c: [f32; 3], by: f32) -> [f32; 3] {
        [c[0] + by, c[1], c[2]]
    }

    fn in_disc(x: usize, y: usize) -> bool {
        (x as f32 - 40.0).powi(2) + (y as f32 - 24.0).powi(2) <= 100.0
    }

    /// A patterned wallpaper (2×2 pink motifs every 8 pixels, each with its
    /// own segmentation tint, as a network gives a pattern's motifs) and a
    /// green disc whose segmentation colour is `disc_gap` away.
    fn wallpaper_and_disc(disc_gap: f32) -> (Image, Image) {
        scene(|x, y| {
            if in_disc(x, y) {
                (GREEN, shifted(SEG, disc_gap))
            } else if x % 8 < 2 && y % 8 < 2 {
                (PINK, shifted(SEG, 0.12))
            } else {
                (BEIGE, SEG)
            }
        })
    }

    #[test]
    fn otsu_splits_two_modes_and_measures_them() {
        let mut v: Vec<f32> = (0..100).map(|i| 0.1 + 0.001 * i as f32).collect();
        v.extend((0..50).map(|i| 0.5 + 0.001 * i as f32));
        let (t, fisher) = otsu(&v);
        assert!(t > 0.2 && t < 0.5, "{t}");
        assert!(fisher > 100.0, "{fisher}");
        // A single uniform look split at its middle: Fisher 6.
        let u: Vec<f32> = (0..1000).map(|i| i as f32 / 1000.0).collect();
        let (t, fisher) = otsu(&u);
        assert!((t - 0.5).abs() < 0.01, "{t}");
        assert!((fisher - 6.0).abs() < 0.1, "{fisher}");
        assert_eq!(otsu(&[0.3; 10]), (0.3, 0.0));
        assert_eq!(otsu(&[0.7]), (0.7, 0.0));
        assert_eq!(otsu(&[]), (0.0, 0.0));
    }

    #[test]
    fn an_object_the_segmentation_took_in_leaves_the_mask_and_the_motifs_stay() {
        let (photo, seg) = wallpaper_and_disc(0.15);
        let (out, check) = split_mask(&photo, &seg, &full(), 12, 12, false);
        let out = out.expect("the disc leaves");
        assert_eq!(check.regions_removed, 1);
        for y in 0..H {
            for x in 0..W {
                let i = y * W + x;
                if in_disc(x, y) {
                    assert!(!out.data[i], "disc pixel ({x}, {y}) kept");
                } else if (x as f32 - 40.0).powi(2) + (y as f32 - 24.0).powi(2) > 14f32.powi(2) {
                    assert!(out.data[i], "wallpaper pixel ({x}, {y}) removed");
                }
            }
        }
        // Picked on the disc, the wallpaper leaves instead.
        let (out, _) = split_mask(&photo, &seg, &full(), 40, 24, false);
        let out = out.expect("the wallpaper leaves");
        assert!(out.data[24 * W + 40]);
        assert!(!out.data[12 * W + 12]);
        let kept = out.count();
        // The disc (~317 pixels) less its outline.
        assert!((200..=320).contains(&kept), "{kept}");
    }

    #[test]
    fn what_the_segmentation_sees_as_one_material_stays() {
        // The disc looks different in the photo but not to the network (or
        // not enough: 0.07 is nearer the wallpaper than another material).
        for gap in [0.02, 0.07] {
            let (photo, seg) = wallpaper_and_disc(gap);
            let (out, check) = split_mask(&photo, &seg, &full(), 12, 12, false);
            assert!(out.is_none(), "gap {gap}: {check:?}");
        }
        // One material under a strong shading ramp, its segmentation
        // drifting with it: the photo's difference is brightness only.
        let (photo, seg) = scene(|x, _| {
            let s = 0.15 + 0.85 * x as f32 / W as f32;
            (
                BEIGE.map(|c| c * s),
                shifted(SEG, 0.2 * x as f32 / W as f32),
            )
        });
        let (out, check) = split_mask(&photo, &seg, &full(), 60, 20, false);
        assert!(out.is_none(), "{check:?}");
    }

    #[test]
    fn a_shadow_stays_however_the_segmentation_sees_it() {
        // A disc a third as bright as the wall around it, which the
        // segmentation gives another colour: the photo's difference is
        // brightness only (0.03 · ln 3 < MIN_LOOK_DISTANCE).
        let (photo, seg) = scene(|x, y| {
            if in_disc(x, y) {
                (BEIGE.map(|c| c / 3.0), shifted(SEG, 0.15))
            } else {
                (BEIGE, SEG)
            }
        });
        let (out, check) = split_mask(&photo, &seg, &full(), 12, 12, false);
        assert!(out.is_none(), "{check:?}");
    }

    #[test]
    fn a_repeating_pattern_is_the_material() {
        // A checkerboard of 8-pixel squares whose colours the segmentation
        // tells apart: 48 alike regions, none leaves.
        let (photo, seg) = scene(|x, y| {
            if (x / 8 + y / 8) % 2 == 0 {
                (BEIGE, SEG)
            } else {
                (GREEN, shifted(SEG, 0.2))
            }
        });
        let (out, check) = split_mask(&photo, &seg, &full(), 3, 3, false);
        assert!(out.is_none(), "{check:?}");
    }

    #[test]
    fn a_region_on_the_masks_edge_stays() {
        // The green band along the mask's bottom edge touches the pixels
        // outside the mask more than the mask: another surface of the
        // material (a second wall), not an object in front of it.
        let (photo, seg) = scene(|_, y| {
            if y >= 36 {
                (GREEN, shifted(SEG, 0.15))
            } else {
                (BEIGE, SEG)
            }
        });
        let narrow = Mask {
            width: W,
            height: H,
            data: (0..W * H)
                .map(|i| {
                    let (x, y) = (i % W, i / W);
                    y < 36 || (y < 40 && (8..56).contains(&x))
                })
                .collect(),
        };
        let (out, check) = split_mask(&photo, &seg, &narrow, 10, 10, false);
        assert!(out.is_none(), "{check:?}");
    }

    #[test]
    fn connected_keeps_the_region_at_the_pick() {
        // A green stripe splits the wallpaper in two: without `connected`
        // both halves stay, with it the half at the pick.
        let (photo, seg) = scene(|x, _| {
            if (28..36).contains(&x) {
                (GREEN, shifted(SEG, 0.15))
            } else {
                (BEIGE, SEG)
            }
        });
        let (both, _) = split_mask(&photo, &seg, &full(), 5, 5, false);
        let both = both.expect("the stripe leaves");
        assert!(both.data[5 * W + 5] && both.data[5 * W + 60]);
        assert!(!both.data[5 * W + 31]);
        let (one, _) = split_mask(&photo, &seg, &full(), 5, 5, true);
        let one = one.expect("the stripe leaves");
        assert!(one.data[5 * W + 5] && !one.data[5 * W + 60]);
    }

    #[test]
    fn small_masks_and_picks_outside_are_left_alone() {
        let (photo, seg) = wallpaper_and_disc(0.15);
        let tiny = Mask {
            width: W,
            height: H,
            data: (0..W * H).map(|i| i < MIN_MASK_PIXELS - 1).collect(),
        };
        assert!(split_mask(&photo, &seg, &tiny, 0, 0, false).0.is_none());
        assert!(split_mask(&photo, &seg, &full(), W, 0, false).0.is_none());
    }

    #[test]
    #[should_panic(expected = "split_mask")]
    fn mismatched_sizes_panic() {
        let (photo, seg) = wallpaper_and_disc(0.15);
        let m = Mask {
            width: 4,
            height: 4,
            data: vec![true; 16],
        };
        let _ = split_mask(&photo, &seg, &m, 0, 0, false);
    }
}
