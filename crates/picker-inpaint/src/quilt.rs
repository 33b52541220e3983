//! A tileable square cut from a larger observed crop: the texels past one
//! wrap edge of the square continue the texels before the other, so each wrap
//! edge is moved onto a minimum-error cut through an overlap band where the
//! two sides look most alike (image quilting, Efros & Freeman 2001, "Image
//! quilting for texture synthesis and transfer", §2.1, with the cut cost of
//! Kwatra et al. 2003, "Graphcut textures", §3: a cut between two neighbours
//! costs the two sides' difference at both). Only the detail is cut: the two
//! sides' difference in brightness (a robust median along the edge) is taken
//! out before comparing them and spread linearly over the tile instead, so a
//! slow change of light across the crop (imperfect de-lighting) leaves no
//! step at the cut or the wrap edge.
//!
//! The alternative ([`crate::seam_band`]) inpaints a band across each wrap
//! edge, inventing a quarter of the square's texels; the cut keeps the
//! observed ones.

use picker_render::io::Image;

/// Share of the overlap band's texel pairs with either side observed that
/// must have both observed for [`wrap_cut`] to cut along an axis; below it (the crop's
/// surroundings were not seen) that axis is cropped at the centre and left
/// to the caller ([`WrapCut::columns`] / [`WrapCut::rows`] `None`).
pub const CUT_MIN_BOTH_KNOWN: f64 = 0.5;

/// The largest [`AxisCut::ratio`] at which a cut is as good as invisible:
/// where the two sides differ more than that along the best cut, the cut
/// shows (a grout line broken off, a pattern that does not continue), and
/// the pipeline inpaints a band across that edge instead.
pub const CUT_MAX_RATIO: f64 = 1.3;

/// The overlap band of [`wrap_cut`] as a share of the texture's side: the
/// content reprojected for the cut reaches this far past each side of the
/// square (at least [`CUT_MIN_OVERLAP`] texels), and the overlap is that wide.
pub const CUT_MARGIN: f64 = 1.0 / 8.0;

/// The narrowest overlap [`wrap_cut`] cuts through (texels); narrower, the
/// axis is only cropped.
pub const CUT_MIN_OVERLAP: usize = 2;

/// The margin, in texels, past each side of a `side`-texel square that
/// [`wrap_cut`] needs: [`CUT_MARGIN`] of the side, at least
/// [`CUT_MIN_OVERLAP`].
pub fn cut_margin(side: usize) -> usize {
    ((side as f64 * CUT_MARGIN).round() as usize).max(CUT_MIN_OVERLAP)
}

/// The cost of giving up an observed texel for an unobserved one in
/// [`wrap_cut`]'s cut, in units of the median squared difference of the
/// overlap's two sides: an invented texel is worse than a typical mismatch.
pub const LOSE_COST: f64 = 4.0;

/// How [`wrap_cut`] made one axis tile.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AxisCut {
    /// The content column (row, for the rows) the tile starts at.
    pub offset: usize,
    /// Width of the overlap band, in texels.
    pub overlap: usize,
    /// Share of the overlap's texel pairs with either side observed that
    /// have both observed.
    pub both_known: f64,
    /// Mean difference of the two sides where the cut passes (mean absolute,
    /// summed over channels, at the two texels either side of the cut, pairs
    /// observed on both sides) over the mean difference between
    /// neighbouring observed texels of the content: 0 where the sides agree
    /// exactly (the crop is one period), about 1 where they differ as much as
    /// neighbours; `None` when either mean has nothing to measure.
    pub ratio: Option<f64>,
}

/// A tileable texture made by [`wrap_cut`].
#[derive(Clone, Debug, PartialEq)]
pub struct WrapCut {
    /// The texture (the content's channels, `width × height`).
    pub texture: Image,
    /// Which texels hold an observed content texel.
    pub known: Vec<bool>,
    /// The coverage of the content texel each texel came from.
    pub coverage: Image,
    /// How the columns' wrap edge was cut; `None`: cropped at the centre
    /// (too narrow a margin, or too little of it observed).
    pub columns: Option<AxisCut>,
    /// How the rows' wrap edge was cut, as [`WrapCut::columns`].
    pub rows: Option<AxisCut>,
}

/// A `width × height` texture that tiles, cut from `content`, a crop at
/// least that large whose centre is the texture's square and whose margins
/// continue it (`known`: which content texels were observed; `coverage`: one
/// plane of per-texel coverage, carried along). A texture smaller than the
/// observed square can be folded within it, with no margins seen.
///
/// Along each axis (columns first, then the rows of the result), with an
/// overlap of `b = min(overlap, extra)` texels (`extra`: the content's
/// texels past the texture's side): the tile takes `width + b` consecutive
/// columns, starting at the offset whose overlap has the most texel pairs
/// observed on both sides (ties: the most centred), and folds the last `b`
/// onto the first `b`. In each row a cut through the overlap takes the far
/// side's texels before it and the near side's after it, so the tile
/// continues across its wrap edge as the content does; the cuts form the path
/// of least total cost (the two sides' squared difference at the texels
/// either side of each cut, and at the texels a jog between rows passes; an
/// unobserved pair costs the median difference, an observed texel given up
/// for an unobserved one [`LOSE_COST`] times it), found exactly by dynamic
/// programming. Only the detail is cut: the far side's texels are brought to
/// the near side's brightness (the median of the two sides' differences
/// over the rows within half the overlap), and the jump this leaves across the wrap edge
/// is spread linearly over the row, the row's mean kept (a linear change of
/// brightness across the crop is removed). Texels whose chosen side was not observed stay
/// unknown (0) for an inpainter. Only the `axes` asked for are cut
/// (`[columns, rows]`); the others are cropped at the centre, as is an axis
/// with an overlap under
/// [`CUT_MIN_OVERLAP`] or over the texture's side, or under
/// [`CUT_MIN_BOTH_KNOWN`] of its pairs seen on either side seen on both, is cropped at the
/// centre instead (its field `None`). Colours are kept non-negative.
/// Deterministic.
///
/// # Panics
/// If `content` is smaller than `width × height`, or `known` / `coverage`
/// (one plane) do not match it.
pub fn wrap_cut(
    content: &Image,
    known: &[bool],
    coverage: &Image,
    width: usize,
    height: usize,
    overlap: usize,
    axes: [bool; 2],
) -> WrapCut {
    let (w, h) = (content.width, content.height);
    assert!(
        w >= width && h >= height,
        "wrap_cut: content {w}x{h} smaller than the texture {width}x{height}"
    );
    assert_eq!(known.len(), w * h, "wrap_cut: one known flag per texel");
    assert!(
        coverage.channels == 1 && coverage.width == w && coverage.height == h,
        "wrap_cut: one coverage plane of the content's size"
    );
    // An axis not to cut: an overlap of 0, which crops.
    let overlap_of = |cut: bool| if cut { overlap } else { 0 };
    let (img, kn, cov, columns) =
        fold_columns(content, known, coverage, width, overlap_of(axes[0]));
    let (img, kn, cov) = (
        transpose(&img),
        transpose_flags(&kn, width, h),
        transpose(&cov),
    );
    let (img, kn, cov, rows) = fold_columns(&img, &kn, &cov, height, overlap_of(axes[1]));
    WrapCut {
        texture: transpose(&img),
        known: transpose_flags(&kn, height, width),
        coverage: transpose(&cov),
        columns,
        rows,
    }
}

/// `img` with rows and columns swapped.
fn transpose(img: &Image) -> Image {
    let (c, h, w) = (img.channels, img.height, img.width);
    let mut out = Image::zeros(c, w, h);
    for ch in 0..c {
        let (src, dst) = (&img.data[ch * h * w..(ch + 1) * h * w], ch * h * w);
        for y in 0..h {
            for x in 0..w {
                out.data[dst + x * h + y] = src[y * w + x];
            }
        }
    }
    out
}

/// `w × h` flags with rows and columns swapped.
fn transpose_flags(k: &[bool], w: usize, h: usize) -> Vec<bool> {
    let mut out = vec![false; w * h];
    for y in 0..h {
        for x in 0..w {
            out[x * h + y] = k[y * w + x];
        }
    }
    out
}

/// Columns `off..off + side` of the image (0 where unobserved), flags and
/// coverage.
fn crop_columns(
    img: &Image,
    known: &[bool],
    cov: &Image,
    off: usize,
    side: usize,
) -> (Image, Vec<bool>, Image) {
    let (c, h, w) = (img.channels, img.height, img.width);
    let mut t = Image::zeros(c, h, side);
    let mut k = vec![false; h * side];
    let mut cv = Image::zeros(1, h, side);
    for y in 0..h {
        for x in 0..side {
            let s = y * w + off + x;
            if known[s] {
                for ch in 0..c {
                    t.data[ch * h * side + y * side + x] = img.data[ch * h * w + s];
                }
            }
            k[y * side + x] = known[s];
            cv.data[y * side + x] = cov.data[s];
        }
    }
    (t, k, cv)
}

/// The columns' pass of [`wrap_cut`]: `side` columns that wrap.
fn fold_columns(
    img: &Image,
    known: &[bool],
    cov: &Image,
    side: usize,
    overlap: usize,
) -> (Image, Vec<bool>, Image, Option<AxisCut>) {
    let (c, h, w) = (img.channels, img.height, img.width);
    let extra = w - side;
    let b = overlap.min(extra);
    let centre = extra / 2;
    let crop = |off: usize| {
        let (t, k, cv) = crop_columns(img, known, cov, off, side);
        (t, k, cv, None)
    };
    if b < CUT_MIN_OVERLAP || b > side || h == 0 {
        return crop(centre);
    }
    // Texel pairs observed on both sides, per content column.
    let both = |y: usize, x: usize| known[y * w + x] && known[y * w + x + side];
    let pairs: Vec<usize> = (0..extra)
        .map(|x| (0..h).filter(|&y| both(y, x)).count())
        .collect();
    // The offset with the most pairs in its overlap, ties to the most centred.
    let mid2 = extra - b; // twice the centred offset
    let (mut off, mut best) = (0usize, 0usize);
    for o in 0..=extra - b {
        let n: usize = pairs[o..o + b].iter().sum();
        let closer = (2 * o).abs_diff(mid2) < (2 * off).abs_diff(mid2);
        if o == 0 || n > best || (n == best && closer) {
            (off, best) = (o, n);
        }
    }
    // Of the overlap's pairs with either side observed (rows neither side
    // saw, a margin past the photo's region or a hole, do not count).
    let either: usize = (0..h)
        .map(|y| {
            (off..off + b)
                .filter(|&x| known[y * w + x] || known[y * w + x + side])
                .count()
        })
        .sum();
    let both_known = if either == 0 {
        0.0
    } else {
        best as f64 / either as f64
    };
    if both_known < CUT_MIN_BOTH_KNOWN {
        return crop(centre);
    }
    let plane = |ch: usize| &img.data[ch * h * w..(ch + 1) * h * w];
    let near = |x: isize| off as isize + x;
    let far = |x: isize| (off + side) as isize + x;
    let jump = side_jump(img, known, h, w, b, off, side);
    // Squared difference of the two sides at band column x ∈ −1..=b (index
    // x + 1), the far side brought to the near side's low frequencies; NaN
    // where either side is unobserved or outside the content.
    let mut e = vec![f64::NAN; h * (b + 2)];
    for y in 0..h {
        for xi in 0..b + 2 {
            let x = xi as isize - 1;
            let (a, f) = (near(x), far(x));
            if a < 0 || f >= w as isize {
                continue;
            }
            let (a, f) = (y * w + a as usize, y * w + f as usize);
            if known[a] && known[f] {
                e[y * (b + 2) + xi] = (0..c)
                    .map(|ch| {
                        let d = plane(ch)[a] as f64 - plane(ch)[f] as f64 + jump[ch][y] as f64;
                        d * d
                    })
                    .sum();
            }
        }
    }
    // The median observed difference: the cost of an unobserved pair and of
    // an observed texel given up.
    let mut seen: Vec<f64> = (0..h)
        .flat_map(|y| (1..=b).map(move |xi| y * (b + 2) + xi))
        .map(|i| e[i])
        .filter(|v| !v.is_nan())
        .collect();
    let mid = seen.len() / 2;
    let delta = *seen.select_nth_unstable_by(mid, f64::total_cmp).1;
    let ev = |y: usize, xi: usize| {
        let v = e[y * (b + 2) + xi];
        if v.is_nan() {
            delta
        } else {
            v
        }
    };
    let lose = LOSE_COST * delta.max(f64::MIN_POSITIVE);
    // Node costs: the cut before band column `cut` in row y.
    let mut node = vec![0.0f64; h * (b + 1)];
    for y in 0..h {
        let kn = |p: isize| known[y * w + p as usize];
        // Observed texels given up: the far side's before the cut where only
        // the near one was seen, the near side's after it likewise.
        let far_lost: Vec<usize> = std::iter::once(0)
            .chain((0..b as isize).scan(0usize, |s, x| {
                *s += (kn(near(x)) && !kn(far(x))) as usize;
                Some(*s)
            }))
            .collect();
        let near_lost: Vec<usize> = {
            let mut v = vec![0usize; b + 1];
            for x in (0..b).rev() {
                let xi = x as isize;
                v[x] = v[x + 1] + (kn(far(xi)) && !kn(near(xi))) as usize;
            }
            v
        };
        for cut in 0..=b {
            node[y * (b + 1) + cut] =
                ev(y, cut) + ev(y, cut + 1) + lose * (far_lost[cut] + near_lost[cut]) as f64;
        }
    }
    // Jog costs between rows y − 1 and y: prefix sums over band columns.
    let jog = |y: usize| -> Vec<f64> {
        let mut p = vec![0.0f64; b + 1];
        for x in 0..b {
            p[x + 1] = p[x] + ev(y - 1, x + 1) + ev(y, x + 1);
        }
        p
    };
    let cuts = min_cut_path(&node, h, b + 1, jog);
    let mut t = Image::zeros(c, h, side);
    let mut k = vec![false; h * side];
    let mut cv = Image::zeros(1, h, side);
    for (y, &cut) in cuts.iter().enumerate() {
        for x in 0..side {
            let far_side = x < b && x < cut;
            let src = if far_side {
                y * w + far(x as isize) as usize
            } else {
                y * w + off + x
            };
            let o = y * side + x;
            k[o] = known[src];
            cv.data[o] = cov.data[src];
            if !known[src] {
                continue;
            }
            // The far side's texels are brought to the near side's low
            // frequencies (so the tile's low frequencies are the content's
            // from `off` on, continuous but for the wrap edge), and that
            // jump is spread linearly over the whole row, centred so that
            // the row's mean is kept: column 0 is raised by half the jump,
            // the last column lowered by half, and the two meet across the
            // wrap edge. A linear change of brightness across the crop is
            // removed.
            let ramp = 0.5 - (x as f32 + 0.5) / side as f32;
            let shift = if far_side { ramp - 1.0 } else { ramp };
            for (ch, j) in jump.iter().enumerate() {
                let v = plane(ch)[src] + shift * j[y];
                t.data[ch * h * side + o] = v.max(0.0);
            }
        }
    }
    // How well the sides agree where cut, against neighbouring texels.
    let l1 = |a: usize, f: usize| -> f64 {
        (0..c)
            .map(|ch| (plane(ch)[a] as f64 - plane(ch)[f] as f64).abs())
            .sum()
    };
    let l1_sides = |y: usize, a: usize, f: usize| -> f64 {
        (0..c)
            .map(|ch| (plane(ch)[a] as f64 - plane(ch)[f] as f64 + jump[ch][y] as f64).abs())
            .sum()
    };
    let (mut at_cut, mut n_cut) = (0.0f64, 0usize);
    for (y, &cut) in cuts.iter().enumerate() {
        for x in [cut as isize - 1, cut as isize] {
            let (a, f) = (near(x), far(x));
            if a < 0 || f >= w as isize {
                continue;
            }
            let (a, f) = (y * w + a as usize, y * w + f as usize);
            if known[a] && known[f] {
                at_cut += l1_sides(y, a, f);
                n_cut += 1;
            }
        }
    }
    let (mut inside, mut n_in) = (0.0f64, 0usize);
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            if !known[i] {
                continue;
            }
            if x + 1 < w && known[i + 1] {
                inside += l1(i, i + 1);
                n_in += 1;
            }
            if y + 1 < h && known[i + w] {
                inside += l1(i, i + w);
                n_in += 1;
            }
        }
    }
    let ratio = (n_cut > 0 && n_in > 0 && inside > 0.0)
        .then(|| (at_cut / n_cut as f64) / (inside / n_in as f64));
    let axis = AxisCut {
        offset: off,
        overlap: b,
        both_known,
        ratio,
    };
    (t, k, cv, Some(axis))
}

/// The path of least cost through `rows × cols` nodes, one column per row:
/// `node[y·cols + c]` plus, between rows `y − 1` and `y`, `|P(c′) − P(c)|`
/// where `P = jog(y)` is non-decreasing (`cols` values). Exact (dynamic
/// programming with a one-dimensional L1 distance transform per row, O(rows ·
/// cols)); ties go to the smaller column.
fn min_cut_path(
    node: &[f64],
    rows: usize,
    cols: usize,
    jog: impl Fn(usize) -> Vec<f64>,
) -> Vec<usize> {
    if rows == 0 {
        return Vec::new();
    }
    let mut back = vec![0u32; rows * cols];
    let mut d: Vec<f64> = node[..cols].to_vec();
    for y in 1..rows {
        let p = jog(y);
        // best[c'] = min_c d[c] + |P(c') − P(c)|, with its argument.
        let mut best: Vec<(f64, usize)> = d.iter().copied().zip(0..cols).collect();
        for c in 1..cols {
            let via = best[c - 1].0 + (p[c] - p[c - 1]);
            if via < best[c].0 {
                best[c] = (via, best[c - 1].1);
            }
        }
        for c in (0..cols - 1).rev() {
            let via = best[c + 1].0 + (p[c + 1] - p[c]);
            if via < best[c].0 || (via == best[c].0 && best[c + 1].1 < best[c].1) {
                best[c] = (via, best[c + 1].1);
            }
        }
        for c in 0..cols {
            d[c] = best[c].0 + node[y * cols + c];
            back[y * cols + c] = best[c].1 as u32;
        }
    }
    let mut c = (0..cols)
        .min_by(|&a, &b| d[a].total_cmp(&d[b]).then(a.cmp(&b)))
        .unwrap_or(0);
    let mut path = vec![0usize; rows];
    for y in (0..rows).rev() {
        path[y] = c;
        c = back[y * cols + c] as usize;
    }
    path
}

/// Rows between which [`side_jump`] measures (a quarter of the overlap).
fn jump_step(b: usize) -> usize {
    (b / 4).max(1)
}

/// Per channel and row, the two sides' low-frequency difference (far minus
/// near) over the overlap of `b` columns at `off` (the far side `side`
/// further): the median of the differences of the pairs observed on both
/// sides in the rows within `b / 2` of the row (a median, so that a
/// pattern's edge passing one side only — a grout line — is not taken for a
/// change of light), measured every [`jump_step`] rows and interpolated
/// linearly between; 0 where no pair was observed.
fn side_jump(
    img: &Image,
    known: &[bool],
    h: usize,
    w: usize,
    b: usize,
    off: usize,
    side: usize,
) -> Vec<Vec<f32>> {
    let c = img.channels;
    let (reach, step) = ((b / 2).max(1), jump_step(b));
    let mut centres: Vec<usize> = (0..h).step_by(step).collect();
    if centres.last() != Some(&(h - 1)) {
        centres.push(h - 1);
    }
    let mut diffs = Vec::new();
    let at: Vec<Vec<Option<f32>>> = (0..c)
        .map(|ch| {
            let p = &img.data[ch * h * w..(ch + 1) * h * w];
            centres
                .iter()
                .map(|&y| {
                    diffs.clear();
                    for r in y.saturating_sub(reach)..(y + reach + 1).min(h) {
                        for x in 0..b {
                            let (a, f) = (r * w + off + x, r * w + off + side + x);
                            if known[a] && known[f] {
                                diffs.push(p[f] - p[a]);
                            }
                        }
                    }
                    if diffs.is_empty() {
                        return None;
                    }
                    let mid = diffs.len() / 2;
                    Some(*diffs.select_nth_unstable_by(mid, f32::total_cmp).1)
                })
                .collect()
        })
        .collect();
    at.iter()
        .map(|vals| {
            (0..h)
                .map(|y| {
                    // The measured centres either side of y.
                    let k = centres.partition_point(|&cy| cy <= y);
                    let below = (0..k).rev().find_map(|i| vals[i].map(|v| (centres[i], v)));
                    let above = (k..centres.len()).find_map(|i| vals[i].map(|v| (centres[i], v)));
                    match (below, above) {
                        (Some((y0, v0)), Some((y1, v1))) if y1 > y0 => {
                            let t = (y - y0) as f32 / (y1 - y0) as f32;
                            v0 + t * (v1 - v0)
                        }
                        (Some((_, v)), _) | (None, Some((_, v))) => v,
                        (None, None) => 0.0,
                    }
                })
                .collect()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A seeded value in [0, 1) per index (splitmix-style).
    fn noise(i: usize) -> f32 {
        let mut z = (i as u64).wrapping_add(0x9E37_79B9_7F4A_7C15);
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 40) as f32 / (1u64 << 24) as f32
    }

    fn image(c: usize, h: usize, w: usize, f: impl Fn(usize, usize, usize) -> f32) -> Image {
        let data = (0..c * h * w)
            .map(|i| f(i / (h * w), (i / w) % h, i % w))
            .collect();
        Image::new(c, h, w, data).unwrap()
    }

    /// Every path of `rows` columns in `0..cols`, by brute force.
    fn brute_min_cut(
        node: &[f64],
        rows: usize,
        cols: usize,
        jog: &dyn Fn(usize) -> Vec<f64>,
    ) -> f64 {
        let total = cols.pow(rows as u32);
        let mut best = f64::INFINITY;
        for code in 0..total {
            let path: Vec<usize> = (0..rows)
                .map(|y| (code / cols.pow(y as u32)) % cols)
                .collect();
            best = best.min(path_cost(node, cols, jog, &path));
        }
        best
    }

    fn path_cost(
        node: &[f64],
        cols: usize,
        jog: &dyn Fn(usize) -> Vec<f64>,
        path: &[usize],
    ) -> f64 {
        let mut s = 0.0;
        for (y, &c) in path.iter().enumerate() {
            s += node[y * cols + c];
            if y > 0 {
                let p = jog(y);
                s += (p[c] - p[path[y - 1]]).abs();
            }
        }
        s
    }

    /// The dynamic programme finds a path as cheap as the cheapest of all.
    #[test]
    fn min_cut_path_is_optimal_against_brute_force() {
        for seed in 0..60usize {
            let rows = 1 + seed % 4;
            let cols = 1 + (seed / 4) % 5;
            let node: Vec<f64> = (0..rows * cols)
                .map(|i| noise(seed * 1000 + i) as f64 * 3.0)
                .collect();
            let steps: Vec<f64> = (0..rows * cols)
                .map(|i| {
                    noise(seed * 1000 + 500 + i) as f64 * if seed % 3 == 0 { 0.0 } else { 2.0 }
                })
                .collect();
            let jog = |y: usize| -> Vec<f64> {
                let mut p = vec![0.0; cols];
                for c in 1..cols {
                    p[c] = p[c - 1] + steps[y * cols + c];
                }
                p
            };
            let path = min_cut_path(&node, rows, cols, jog);
            assert_eq!(path.len(), rows);
            let got = path_cost(&node, cols, &jog, &path);
            let want = brute_min_cut(&node, rows, cols, &jog);
            assert!(
                (got - want).abs() < 1e-9,
                "seed {seed} ({rows}x{cols}): path {path:?} costs {got}, best {want}"
            );
        }
    }

    /// A crop of a texture of period `side` along both axes, fully observed,
    /// tiles into exactly that period (shifted by the chosen offsets), with
    /// a cut ratio of 0.
    #[test]
    fn one_period_crop_gives_the_period_back() {
        for &(side, channels) in &[(16usize, 3usize), (23, 1), (40, 3)] {
            let m = cut_margin(side);
            let n = side + 2 * m;
            let tile =
                |ch: usize, y: usize, x: usize| noise((ch * 97 + y % side) * 1000 + x % side);
            let content = image(channels, n, n, tile);
            let known = vec![true; n * n];
            let cov = image(1, n, n, |_, _, _| 1.0);
            let cut = wrap_cut(&content, &known, &cov, side, side, m, [true, true]);
            let (cx, cy) = (cut.columns.unwrap(), cut.rows.unwrap());
            assert_eq!(cx.both_known, 1.0);
            assert_eq!(cx.ratio, Some(0.0));
            assert_eq!(cy.ratio, Some(0.0));
            assert!(cut.known.iter().all(|&k| k));
            for ch in 0..channels {
                for y in 0..side {
                    for x in 0..side {
                        let want = tile(ch, y + cy.offset, x + cx.offset);
                        let got = cut.texture.data[ch * side * side + y * side + x];
                        assert!(
                            (got - want).abs() < 1e-5,
                            "side {side}: texel ({x},{y}) ch {ch}: {got} vs {want}"
                        );
                    }
                }
            }
        }
    }

    /// A crop of a texture that does not repeat: the result's wrap edges
    /// continue the content exactly (each edge texel and its neighbour
    /// across the wrap were neighbours in the content), every texel comes
    /// from the content, and the seam ratio is far below a plain crop's.
    #[test]
    fn wrap_edges_continue_the_content() {
        let side = 48;
        let m = cut_margin(side);
        let n = side + 2 * m;
        // Noise on a gradient: the crop's opposite edges differ.
        let f = |_: usize, y: usize, x: usize| 0.2 + 0.01 * x as f32 + 0.3 * noise(y * 1000 + x);
        let content = image(1, n, n, f);
        let known = vec![true; n * n];
        let cov = image(1, n, n, |_, _, _| 1.0);
        let cut = wrap_cut(&content, &known, &cov, side, side, m, [true, true]);
        let plain = image(1, side, side, |c, y, x| f(c, y + m, x + m));
        let s_cut = crate::seam_score(&cut.texture).ratio;
        let s_plain = crate::seam_score(&plain).ratio;
        assert!(s_plain > 2.0, "the plain crop's seams show: {s_plain}");
        assert!(
            s_cut < 1.1,
            "the cut's wrap edges continue the content: {s_cut}"
        );
        assert!(cut.known.iter().all(|&k| k));
        assert!(cut.texture.data.iter().all(|v| v.is_finite() && *v >= 0.0));
        // Only the rows asked for: the columns are the centre crop's.
        let rows_only = wrap_cut(&content, &known, &cov, side, side, m, [false, true]);
        assert!(rows_only.columns.is_none() && rows_only.rows.is_some());
        let (off, b) = (
            rows_only.rows.unwrap().offset,
            rows_only.rows.unwrap().overlap,
        );
        for y in (b..side).step_by(7) {
            let x = side - 1;
            let want = f(0, y + off, x + m);
            let got = rows_only.texture.data[y * side + x];
            // (Past the rows' overlap: the content itself, but for the rows'
            // spread jump, small next to the noise.)
            assert!((got - want).abs() < 0.1, "({x},{y}) {got} vs {want}");
        }
    }

    /// Unobserved surroundings: the axis is cropped at the centre, the
    /// other is cut.
    #[test]
    fn unobserved_margin_crops_that_axis() {
        let side = 32;
        let m = cut_margin(side);
        let n = side + 2 * m;
        let content = image(3, n, n, |c, y, x| noise((c * 100 + y) * 100 + x));
        // Only the square's own columns observed; every row.
        let known: Vec<bool> = (0..n * n)
            .map(|i| (m..m + side).contains(&(i % n)))
            .collect();
        let cov = image(1, n, n, |_, _, _| 0.5);
        let cut = wrap_cut(&content, &known, &cov, side, side, m, [true, true]);
        assert!(cut.columns.is_none());
        let rows = cut.rows.expect("the rows' margins were observed");
        assert_eq!(rows.both_known, 1.0);
        // The columns are the square's own: content column m + x.
        for y in 0..side {
            for x in 0..side {
                let i = y * side + x;
                assert!(cut.known[i]);
                assert_eq!(cut.coverage.data[i], 0.5);
            }
        }
        // No margin at all: both axes cropped, the content itself.
        let exact = image(3, side, side, |c, y, x| noise((c * 100 + y) * 100 + x));
        let kn = vec![true; side * side];
        let cv = image(1, side, side, |_, _, _| 1.0);
        let same = wrap_cut(&exact, &kn, &cv, side, side, cut_margin(side), [true, true]);
        assert!(same.columns.is_none() && same.rows.is_none());
        assert_eq!(same.texture, exact);
    }

    /// The share of the overlap's pairs seen on both sides decides: with the
    /// columns' margins seen in every `k`-th row only (the near side in all),
    /// the axis is cut from a share of [`CUT_MIN_BOTH_KNOWN`] on, cropped
    /// below it; the texels the cut takes from unseen rows stay unknown.
    #[test]
    fn the_columns_are_cut_from_the_least_share_of_pairs_seen_on() {
        let side = 32;
        let m = cut_margin(side);
        let n = side + 2 * m;
        let content = image(1, n, n, |_, y, x| noise(y * 1000 + x));
        let cov = image(1, n, n, |_, _, _| 1.0);
        let mut seen = Vec::new();
        for k in 1..=8usize {
            let known: Vec<bool> = (0..n * n)
                .map(|i| (m..m + side).contains(&(i % n)) || (i / n).is_multiple_of(k))
                .collect();
            let cut = wrap_cut(&content, &known, &cov, side, side, m, [true, false]);
            let share = (0..n).filter(|y| y.is_multiple_of(k)).count() as f64 / n as f64;
            // The best offset's overlap holds at least the margin's rows' share.
            assert_eq!(
                cut.columns.is_some(),
                cut.columns.map_or(share, |c| c.both_known) >= CUT_MIN_BOTH_KNOWN,
                "k {k}: {:?}",
                cut.columns
            );
            if let Some(c) = cut.columns {
                assert!(c.both_known >= share - 1e-9, "k {k}: {c:?}, share {share}");
            }
            seen.push(cut.columns.is_some());
        }
        // Every row seen, and half: cut; an eighth: cropped.
        assert_eq!(&seen[..2], &[true, true]);
        assert!(!seen[7]);
    }

    /// Unobserved texels on the chosen side stay unknown, and the cut keeps
    /// observed texels where one side alone was seen.
    #[test]
    fn a_hole_on_one_side_is_cut_around() {
        let side = 40;
        let m = cut_margin(side);
        let n = side + 2 * m;
        let content = image(1, n, n, |_, y, x| noise(y * 1000 + x));
        // A hole in the far side of the columns' overlap, rows 10..20.
        let mut known = vec![true; n * n];
        for y in 10..20 {
            for x in side + m..n {
                known[y * n + x] = false;
            }
        }
        let cov = image(1, n, n, |_, _, _| 1.0);
        let cut = wrap_cut(&content, &known, &cov, side, side, m, [true, true]);
        assert!(cut.columns.is_some());
        let lost = cut.known.iter().filter(|&&k| !k).count();
        // The near side was seen there: nothing need be lost.
        assert_eq!(lost, 0, "observed texels given up");
    }

    /// No surroundings seen: a tile smaller than the square by the overlap
    /// is folded within it, every texel observed, its wrap edges continuing
    /// the content.
    #[test]
    fn a_smaller_tile_folds_within_the_observed_square() {
        let side = 64;
        let m = cut_margin(side);
        let n = side + 2 * m;
        let f = |c: usize, y: usize, x: usize| {
            0.3 + 0.004 * (x + y) as f32 + 0.2 * noise((c * 1000 + y) * 1000 + x)
        };
        let content = image(3, n, n, f);
        let inside =
            |i: usize| (m..m + side).contains(&(i % n)) && (m..m + side).contains(&(i / n));
        let known: Vec<bool> = (0..n * n).map(inside).collect();
        let cov = image(1, n, n, |_, _, _| 1.0);
        let full = wrap_cut(&content, &known, &cov, side, side, m, [true, true]);
        assert!(full.columns.is_none() && full.rows.is_none());
        let t = side - m;
        let cut = wrap_cut(&content, &known, &cov, t, t, m, [true, true]);
        let (cx, cy) = (cut.columns.unwrap(), cut.rows.unwrap());
        // (The margin rows, seen by neither side, do not count.)
        assert_eq!((cx.both_known, cy.both_known), (1.0, 1.0));
        assert_eq!((cx.offset, cy.offset), (m, m));
        assert!(cut.known.iter().all(|&k| k));
        let s_cut = crate::seam_score(&cut.texture).ratio;
        let s_crop = crate::seam_score(&full.texture).ratio;
        assert!(s_crop > 1.5 && s_cut < 1.1, "crop {s_crop}, cut {s_cut}");
    }

    /// The sides' jump is the light's, not a pattern's: a constant offset
    /// between the sides is measured exactly though a bright line runs
    /// along one side only, and it follows a change along the edge.
    #[test]
    fn a_line_on_one_side_is_not_taken_for_light() {
        let (side, b) = (40usize, 6usize);
        let (h, w) = (50usize, side + 2 * b);
        let off = 3;
        let content = image(1, h, w, |_, y, x| {
            let far = x >= off + side;
            let base = 0.3 + 0.2 * noise(y * 1000 + x % side);
            let light = if far { 0.1 + 0.002 * y as f32 } else { 0.0 };
            // A bright line two texels wide in the far side's overlap only.
            let line = if far && (x - off - side) / 2 == 1 {
                0.6
            } else {
                0.0
            };
            base + light + line
        });
        let known = vec![true; h * w];
        let jump = side_jump(&content, &known, h, w, b, off, side);
        for (y, &j) in jump[0].iter().enumerate() {
            let want = 0.1 + 0.002 * y as f32;
            assert!((j - want).abs() < 0.01, "row {y}: {j} vs {want}");
        }
        // Nothing observed on one side: no jump.
        let none: Vec<bool> = (0..h * w).map(|i| i % w < off + side).collect();
        assert!(side_jump(&content, &none, h, w, b, off, side)[0]
            .iter()
            .all(|&j| j == 0.0));
    }

    /// Every shape the signature admits, on seeded random problems (empty
    /// textures, no margin, overlaps of 0, 1 and past the side, random
    /// masks, one to three channels, either axis): the result has the asked
    /// shape, every known texel is finite and non-negative, unknown ones are
    /// 0, and it is the same on a second call.
    #[test]
    fn every_admitted_shape_gives_a_texture_of_that_shape() {
        let mut seed = 1usize;
        let mut next = |n: usize| {
            seed += 1;
            (noise(seed * 7919) * n as f32) as usize
        };
        for case in 0..300 {
            let (width, height) = (next(20), next(20));
            let (w, h) = (width + next(12), height + next(12));
            let channels = 1 + next(3);
            let overlap = [0, 1, 2, next(16), 40][case % 5];
            let axes = [case % 3 != 0, case % 4 != 1];
            let density = noise(case * 31);
            let content = image(channels, h, w, |c, y, x| {
                noise((case * 100 + c) * 10000 + y * 100 + x)
            });
            let known: Vec<bool> = (0..w * h)
                .map(|i| noise(case * 1_000_003 + i) < density)
                .collect();
            let cov = image(1, h, w, |_, y, x| noise(y * 131 + x));
            let a = wrap_cut(&content, &known, &cov, width, height, overlap, axes);
            assert_eq!(
                (a.texture.channels, a.texture.height, a.texture.width),
                (channels, height, width),
                "case {case}"
            );
            assert_eq!(a.known.len(), width * height);
            assert_eq!((a.coverage.height, a.coverage.width), (height, width));
            for ch in 0..channels {
                for i in 0..width * height {
                    let v = a.texture.data[ch * width * height + i];
                    if a.known[i] {
                        assert!(v.is_finite() && v >= 0.0, "case {case}: {v}");
                    } else {
                        assert_eq!(v, 0.0, "case {case}");
                    }
                }
            }
            assert!(a.columns.is_none() || axes[0], "case {case}");
            assert!(a.rows.is_none() || axes[1], "case {case}");
            let b = wrap_cut(&content, &known, &cov, width, height, overlap, axes);
            assert_eq!(a, b, "case {case}: not deterministic");
        }
    }
}
