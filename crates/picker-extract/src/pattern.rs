//! Two-colour patterns: a pick on one colour of a chessboard, a striped
//! fabric or tiles with dark grout gives the whole pattern.
//!
//! The networks (and the photo-guided smoothing of their segmentation, which
//! keeps photo-different parts apart: [`crate::smooth`]) see a pattern whose
//! elements are larger than their receptive field as two materials, so a
//! pick takes only its own colour: the black squares of a chessboard, and a
//! texture of black squares with holes. A pattern is told apart from an
//! object on a background by how the two regions meet:
//!
//! - the **companion** is the material most of the mask's surroundings show:
//!   picked ([`crate::Prepared::pick_mask`]'s way) at the pixel of the ring
//!   2–3 pixels outside the mask ([`RING_NEAR`]..=[`RING_FAR`], past the soft
//!   edge between the two) nearest the ring's per-channel median colour
//!   ([`companion_seed`]), and kept within the mask's [`reach`];
//! - **border share**: the share of the mask's boundary that has the
//!   companion within [`RING_FAR`] pixels (≥ [`MIN_BORDER_SHARE`]: the mask is
//!   mostly surrounded by one material);
//! - **interleaving**: the length of that inner boundary against the outline
//!   of the two together, the photo's frame included (≥ [`MIN_INTERLEAVE`]):
//!   a chessboard of `n × n` squares has about `n/2` times more inner
//!   boundary than outline, a rug on a floor or a chair in a room less than
//!   one (the floor around the rug has a longer outline than the rug);
//! - **balance**: neither covers more than [`MAX_AREA_RATIO`] times the other
//!   (frames on a wall are not a pattern of the wall);
//! - **repetition**: one of the two comes in many elements (4-connected
//!   regions), none dominant ([`Elements::repeat`]): a pattern, not a fruit
//!   beside another.
//!
//! When all hold, the mask becomes the union of the two, with the thin soft
//! edge between them (pixels within [`GAP_FILL`] of both whose colour is a
//! blend of theirs, [`blend`]) filled, and the union's enclosed holes that
//! are missed bits of the pattern (no larger than an element, a blend of the
//! two colours throughout) filled too.

use crate::mask::Mask;
use picker_render::io::Image;
use serde::Serialize;

/// The ring the companion is read from starts this many pixels (Chebyshev)
/// outside the mask: past the soft edge a segmentation has between two
/// materials.
pub const RING_NEAR: usize = 2;
/// ... and ends this many pixels outside it.
pub const RING_FAR: usize = 3;
/// At least this share of the mask's boundary must have the companion within
/// [`RING_FAR`] pixels.
pub const MIN_BORDER_SHARE: f64 = 0.6;
/// Inner boundary (mask pixels within [`RING_FAR`] of the companion) over the
/// outline of the union, at least.
pub const MIN_INTERLEAVE: f64 = 1.0;
/// The larger of the two regions over the smaller, at most.
pub const MAX_AREA_RATIO: f64 = 12.0;
/// A soft-edge pixel's colour lies at most this far from the segment between
/// the two materials' colours ([`blend`]).
pub const BLEND_DISTANCE: f32 = 0.1;
/// Regions smaller than this many pixels, or than
/// [`crate::mask::MIN_SPECK_FRACTION`] of the grid, are specks, not elements
/// of a pattern.
pub const MIN_ELEMENT_PIXELS: usize = 4;
/// One of the two colours must come in at least this many elements ...
pub const MIN_ELEMENTS: usize = 8;
/// ... none of which holds more than this share of its colour's area.
pub const MAX_LARGEST_SHARE: f64 = 0.25;
/// Pixels within this distance (Chebyshev) of both regions join the union:
/// the soft edge between the colours.
pub const GAP_FILL: usize = 2;

/// How a mask and its companion meet ([`measure`]).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Interleaving {
    /// Share of the ring around the mask that the companion covers.
    pub border_share: f64,
    /// Inner boundary over the union's outline.
    pub interleave: f64,
    /// Larger area over smaller.
    pub area_ratio: f64,
    /// The mask's elements: its 4-connected regions that are not specks
    /// ([`MIN_ELEMENT_PIXELS`]), and the largest one's share of its area.
    pub elements: Elements,
    /// The companion's (its part within the mask's [`reach`]).
    pub companion_elements: Elements,
}

/// The elements of one colour of a pattern ([`Interleaving`]).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Elements {
    /// 4-connected regions that are not specks ([`MIN_ELEMENT_PIXELS`]).
    pub count: usize,
    /// The largest region's share of the area.
    pub largest_share: f64,
}

impl Elements {
    /// The elements of `set` on a `w`-wide grid.
    pub fn of(set: &[bool], w: usize) -> Elements {
        let h = set.len().checked_div(w).unwrap_or(0);
        let (_, sizes) = crate::mask::components4(&Mask {
            width: w,
            height: h,
            data: set.to_vec(),
        });
        let area: usize = sizes.iter().skip(1).sum();
        let speck = (crate::mask::MIN_SPECK_FRACTION * set.len() as f64).ceil() as usize;
        Elements {
            count: sizes
                .iter()
                .skip(1)
                .filter(|&&n| n >= MIN_ELEMENT_PIXELS.max(speck))
                .count(),
            largest_share: sizes.iter().skip(1).copied().max().unwrap_or(0) as f64
                / area.max(1) as f64,
        }
    }

    /// Many elements, none dominant ([`MIN_ELEMENTS`], [`MAX_LARGEST_SHARE`]).
    pub fn repeat(&self) -> bool {
        self.count >= MIN_ELEMENTS && self.largest_share <= MAX_LARGEST_SHARE
    }
}

impl Interleaving {
    /// Whether the two make one pattern (every threshold met).
    pub fn is_pattern(&self) -> bool {
        self.border_share >= MIN_BORDER_SHARE
            && self.interleave >= MIN_INTERLEAVE
            && self.area_ratio <= MAX_AREA_RATIO
            && (self.elements.repeat() || self.companion_elements.repeat())
    }
}

/// What the pattern completion found for a pick (reported in
/// `material.json`'s diagnostics).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PatternCheck {
    /// The companion's colour in the image the masks are cut from (its
    /// pick colour, [`crate::mask::pick_colour`]).
    pub companion_colour: [f32; 3],
    /// Where the companion was picked (working pixels).
    pub companion_pick: [usize; 2],
    /// How the two meet.
    pub measured: Interleaving,
    /// Whether the mask became the union of the two.
    pub merged: bool,
    /// Share of the merged mask that the pick's own mask held (1 when not
    /// merged).
    pub own_share: f64,
}

/// `set` grown by `r` pixels in the Chebyshev metric (a `(2r+1)²` square
/// max filter), on a `w × h` grid; pixels outside the grid are not set.
pub fn dilate(set: &[bool], w: usize, h: usize, r: usize) -> Vec<bool> {
    assert_eq!(set.len(), w * h, "dilate: {} values for {w}x{h}", set.len());
    if r == 0 || w == 0 || h == 0 {
        return set.to_vec();
    }
    // Rows then columns, each by a running count over the window.
    let run = |src: &[bool], n: usize, at: &dyn Fn(usize) -> usize, out: &mut [bool]| {
        let mut count = 0usize;
        for k in 0..n.min(r) {
            count += src[at(k)] as usize;
        }
        for k in 0..n {
            if k + r < n {
                count += src[at(k + r)] as usize;
            }
            if k > r {
                count -= src[at(k - r - 1)] as usize;
            }
            out[at(k)] = count > 0;
        }
    };
    let mut rows = vec![false; w * h];
    for y in 0..h {
        run(set, w, &|k| y * w + k, &mut rows);
    }
    let mut out = vec![false; w * h];
    for x in 0..w {
        run(&rows, h, &|k| k * w + x, &mut out);
    }
    out
}

/// The pixels `near..=far` (Chebyshev) outside `mask` that are `valid`.
pub fn ring(mask: &Mask, valid: &[bool], near: usize, far: usize) -> Vec<bool> {
    let (w, h) = (mask.width, mask.height);
    let inner = dilate(&mask.data, w, h, near.saturating_sub(1));
    let outer = dilate(&mask.data, w, h, far);
    (0..w * h)
        .map(|i| outer[i] && !inner[i] && valid[i])
        .collect()
}

/// Where to pick the companion of `mask` in `seg` (the image masks are cut
/// from): the pixel of the mask's ring ([`ring`], [`RING_NEAR`]..=
/// [`RING_FAR`]) nearest to the ring's per-channel median colour (ties: the
/// first in row order), and that median; `None` when the ring is empty.
pub fn companion_seed(seg: &Image, valid: &[bool], mask: &Mask) -> Option<([usize; 2], [f32; 3])> {
    let w = mask.width;
    let r = ring(mask, valid, RING_NEAR, RING_FAR);
    let members: Vec<usize> = (0..r.len()).filter(|&i| r[i]).collect();
    if members.is_empty() {
        return None;
    }
    let med: [f32; 3] = std::array::from_fn(|c| {
        let mut v: Vec<f32> = members.iter().map(|&i| seg.at(c, i)).collect();
        let mid = v.len() / 2;
        *v.select_nth_unstable_by(mid, |a, b| a.total_cmp(b)).1
    });
    let d = |i: usize| (0..3).map(|c| (seg.at(c, i) - med[c]).powi(2)).sum::<f32>();
    let best = members
        .iter()
        .copied()
        .min_by(|&a, &b| d(a).total_cmp(&d(b)).then(a.cmp(&b)))
        .expect("non-empty ring");
    Some(([best % w, best / w], med))
}

/// How far the companion is looked for around `mask`: twice the median,
/// over the mask's 4-connected regions, of each region's largest Chebyshev
/// distance to its outside ([`crate::mask::chamfer_depth`] with unit steps),
/// plus [`RING_FAR`] for the soft edge between the two (a chessboard's squares
/// of side `s`: about `s`, so a light square next to a picked dark one is
/// reached whole).
pub fn reach(mask: &Mask) -> usize {
    let (w, h) = (mask.width, mask.height);
    let d = crate::mask::chamfer_depth(&mask.data, w, h, 1, 1);
    let (label, sizes) = crate::mask::components4(mask);
    let mut deepest = vec![0u32; sizes.len()];
    for (i, &l) in label.iter().enumerate() {
        deepest[l as usize] = deepest[l as usize].max(d[i]);
    }
    let mut v: Vec<u32> = deepest.into_iter().skip(1).collect();
    if v.is_empty() {
        return RING_FAR;
    }
    let mid = v.len() / 2;
    let med = *v.select_nth_unstable(mid).1;
    2 * med as usize + RING_FAR
}

/// Pixels of `set` on its boundary: with a 4-neighbour that is not in
/// `set`, or on the grid's border when `border` (the photo's frame cuts the
/// region there).
fn edge(set: &[bool], w: usize, h: usize, border: bool) -> Vec<bool> {
    (0..w * h)
        .map(|i| {
            let (x, y) = (i % w, i / w);
            set[i]
                && ((border && (x == 0 || y == 0 || x + 1 == w || y + 1 == h))
                    || crate::mask::neighbours4(i, w, h).any(|j| !set[j]))
        })
        .collect()
}

/// The pixels of `seg` (the image masks are cut from) whose colour is a
/// blend of the colours `a` and `b`: within [`BLEND_DISTANCE`] of the
/// segment between them (a soft edge between the two materials; a third
/// material's colour lies off it), where `valid`.
pub fn blend(seg: &Image, valid: &[bool], a: [f32; 3], b: [f32; 3]) -> Vec<bool> {
    let n = seg.width * seg.height;
    assert!(
        seg.channels == 3 && valid.len() == n,
        "pattern::blend: {} channels, {} validity values for {n} pixels",
        seg.channels,
        valid.len()
    );
    let ab: [f32; 3] = std::array::from_fn(|c| b[c] - a[c]);
    let len2: f32 = ab.iter().map(|v| v * v).sum();
    (0..n)
        .map(|i| {
            if !valid[i] {
                return false;
            }
            let ap: [f32; 3] = std::array::from_fn(|c| seg.at(c, i) - a[c]);
            let t = if len2 > 0.0 {
                (ap.iter().zip(&ab).map(|(p, q)| p * q).sum::<f32>() / len2).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let d2: f32 = (0..3).map(|c| (ap[c] - t * ab[c]).powi(2)).sum();
            d2 <= BLEND_DISTANCE * BLEND_DISTANCE
        })
        .collect()
}

/// The companion's pixels within the mask's [`reach`] that are not the
/// mask's, and the union of the two with the soft edge between them
/// ([`GAP_FILL`]) filled where `blend` ([`blend`]).
fn union_parts(mask: &Mask, companion: &Mask, blend: &[bool]) -> (Vec<bool>, Vec<bool>) {
    let (w, h) = (mask.width, mask.height);
    let near = dilate(&mask.data, w, h, reach(mask));
    let other: Vec<bool> = (0..w * h)
        .map(|i| companion.data[i] && !mask.data[i] && near[i])
        .collect();
    let near_m = dilate(&mask.data, w, h, GAP_FILL);
    let near_o = dilate(&other, w, h, GAP_FILL);
    let union = (0..w * h)
        .map(|i| mask.data[i] || other[i] || (blend[i] && near_m[i] && near_o[i]))
        .collect();
    (other, union)
}

/// How `mask` and its `companion` (same grid; the companion's pixels that
/// are also the mask's count as the mask's) meet, the soft edge between them
/// being the `blend` pixels ([`blend`]): see the module docs.
///
/// # Panics
/// When the masks or `blend` differ in size.
pub fn measure(mask: &Mask, companion: &Mask, blend: &[bool]) -> Interleaving {
    let (w, h) = (mask.width, mask.height);
    assert!(
        companion.width == w && companion.height == h && blend.len() == w * h,
        "pattern::measure: a {w}x{h} mask, a {}x{} companion, {} blend values",
        companion.width,
        companion.height,
        blend.len()
    );
    let (other, union) = union_parts(mask, companion, blend);
    let near_other = dilate(&other, w, h, RING_FAR);
    let own_edge = edge(&mask.data, w, h, false);
    let edge_n = own_edge.iter().filter(|&&b| b).count();
    let inner = own_edge
        .iter()
        .zip(&near_other)
        .filter(|(&e, &n)| e && n)
        .count();
    let outline = edge(&union, w, h, true).iter().filter(|&&b| b).count();
    let (a, b) = (
        mask.data.iter().filter(|&&b| b).count(),
        other.iter().filter(|&&b| b).count(),
    );
    Interleaving {
        elements: Elements::of(&mask.data, w),
        companion_elements: Elements::of(&other, w),
        border_share: inner as f64 / edge_n.max(1) as f64,
        interleave: inner as f64 / outline.max(1) as f64,
        area_ratio: if a.min(b) == 0 {
            f64::INFINITY
        } else {
            a.max(b) as f64 / a.min(b) as f64
        },
    }
}

/// The union of `mask` and its `companion` (within the mask's [`reach`])
/// with the soft edge between them filled ([`GAP_FILL`], `blend` pixels),
/// and its holes that are missed bits of the pattern filled (enclosed, no
/// larger than an element of either colour, a blend of the two throughout).
pub fn merged(mask: &Mask, companion: &Mask, blend: &[bool]) -> Mask {
    let (other, mut union) = union_parts(mask, companion, blend);
    let (w, h) = (mask.width, mask.height);
    let largest = [&mask.data, &other]
        .iter()
        .map(|set| {
            crate::mask::components4(&Mask {
                width: w,
                height: h,
                data: set.to_vec(),
            })
            .1
            .into_iter()
            .skip(1)
            .max()
            .unwrap_or(0)
        })
        .max()
        .unwrap_or(0);
    for i in enclosed_pattern_holes(&union, w, h, blend, largest) {
        union[i] = true;
    }
    Mask {
        width: w,
        height: h,
        data: union,
    }
}

/// The pixels of the holes of `union` (4-connected regions outside it that
/// do not reach the grid's border) that are missed bits of the pattern:
/// no larger than `largest` pixels (one element of either colour) and
/// every pixel's colour a blend of the two ([`blend`]; a third material's
/// object lying on the pattern stays out).
fn enclosed_pattern_holes(
    union: &[bool],
    w: usize,
    h: usize,
    blend: &[bool],
    largest: usize,
) -> Vec<usize> {
    let holes = Mask {
        width: w,
        height: h,
        data: crate::mask::enclosed(union, w, h),
    };
    let (label, sizes) = crate::mask::components4(&holes);
    let mut ok = vec![true; sizes.len()];
    ok[0] = false;
    for (i, &l) in label.iter().enumerate() {
        if l != 0 && !blend[i] {
            ok[l as usize] = false;
        }
    }
    for (k, &n) in sizes.iter().enumerate() {
        if n > largest {
            ok[k] = false;
        }
    }
    (0..w * h).filter(|&i| ok[label[i] as usize]).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rng(seed: u64) -> impl FnMut() -> u64 {
        let mut s = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
        move || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            s
        }
    }

    fn dilate_reference(set: &[bool], w: usize, h: usize, r: usize) -> Vec<bool> {
        (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as i64, (i / w) as i64);
                (0..w * h).any(|j| {
                    let (xx, yy) = ((j % w) as i64, (j / w) as i64);
                    set[j] && (xx - x).abs() <= r as i64 && (yy - y).abs() <= r as i64
                })
            })
            .collect()
    }

    #[test]
    fn dilate_matches_reference() {
        let mut next = rng(7);
        for &(w, h) in &[(1, 1), (1, 7), (9, 1), (5, 4), (13, 11), (20, 3)] {
            for r in 0..6 {
                for density in [1u64, 5, 40] {
                    let set: Vec<bool> = (0..w * h).map(|_| next() % 100 < density).collect();
                    assert_eq!(
                        dilate(&set, w, h, r),
                        dilate_reference(&set, w, h, r),
                        "{w}x{h} r={r} density {density}"
                    );
                }
            }
        }
        assert!(dilate(&[], 0, 0, 3).is_empty());
    }

    fn mask(w: usize, h: usize, f: impl Fn(usize, usize) -> bool) -> Mask {
        Mask {
            width: w,
            height: h,
            data: (0..w * h).map(|i| f(i % w, i / w)).collect(),
        }
    }

    /// A chessboard of `s`-pixel squares inside a frame of `margin` pixels
    /// on a `w × h` image, each square shrunk by `gap` pixels on every side
    /// (the soft edge between the colours that neither mask takes).
    fn board(w: usize, h: usize, s: usize, margin: usize, gap: usize, dark: bool) -> Mask {
        mask(w, h, |x, y| {
            if x < margin || y < margin || x >= w - margin || y >= h - margin {
                return false;
            }
            let (u, v) = (x - margin, y - margin);
            let (iu, iv) = (u % s, v % s);
            let inside = iu >= gap && iu < s - gap && iv >= gap && iv < s - gap;
            inside && ((u / s) + (v / s)).is_multiple_of(2) == dark
        })
    }

    #[test]
    fn a_chessboard_is_a_pattern_either_way() {
        let (w, h) = (96, 80);
        let dark = board(w, h, 10, 8, 1, true);
        let light = board(w, h, 10, 8, 1, false);
        let valid = vec![true; w * h];
        for (a, b) in [(&dark, &light), (&light, &dark)] {
            let m = measure(a, b, &valid);
            assert!(m.is_pattern(), "{m:?}");
            assert!(m.border_share > 0.8, "{m:?}");
            let u = merged(a, b, &valid);
            // The union is the board, edges between squares filled (all but
            // the soft edge's pixels on the board's outer frame that only one
            // colour is near).
            let inner = (w - 18) * (h - 18);
            let inside = (0..w * h)
                .filter(|&i| {
                    let (x, y) = (i % w, i / w);
                    u.data[i] && (9..w - 9).contains(&x) && (9..h - 9).contains(&y)
                })
                .count();
            let missing: Vec<(usize, usize)> = (0..w * h)
                .filter(|&i| {
                    !u.data[i] && (9..w - 9).contains(&(i % w)) && (9..h - 9).contains(&(i / w))
                })
                .map(|i| (i % w, i / w))
                .collect();
            assert_eq!(inside, inner, "{missing:?}");
            // Nothing beyond the board's frame but the fill's reach.
            assert!((0..w * h).all(|i| !u.data[i] || {
                let (x, y) = (i % w, i / w);
                (6..w - 6).contains(&x) && (6..h - 6).contains(&y)
            }));
        }
    }

    /// Holes in the union where neither colour's mask reached (the centre
    /// of a dark square) are filled when they are a blend of the two colours
    /// and no larger than an element; a third material's object lying on
    /// the board, a hole larger than a square and the outside stay out.
    #[test]
    fn missed_bits_of_the_pattern_are_filled() {
        let (w, h) = (96, 80);
        let mut dark = board(w, h, 10, 8, 1, true);
        let light = board(w, h, 10, 8, 1, false);
        // Dark squares at (8..18, 8..18) [square (0, 0)] and (28..38, 28..38)
        // [square (2, 2)] lose their centres; square (4, 4) at (48..58, 48..58)
        // holds an object of another colour.
        let hole = |x: usize, y: usize, x0: usize, y0: usize| {
            (x0 + 3..x0 + 7).contains(&x) && (y0 + 3..y0 + 7).contains(&y)
        };
        for y in 0..h {
            for x in 0..w {
                if hole(x, y, 8, 8) || hole(x, y, 28, 28) || hole(x, y, 48, 48) {
                    dark.data[y * w + x] = false;
                }
            }
        }
        let mut blend = vec![true; w * h];
        for y in 0..h {
            for x in 0..w {
                // Off the two colours' segment: the object, and the outside.
                if hole(x, y, 48, 48) || x < 6 || y < 6 || x >= w - 6 || y >= h - 6 {
                    blend[y * w + x] = false;
                }
            }
        }
        let u = merged(&dark, &light, &blend);
        let at = |x: usize, y: usize| u.data[y * w + x];
        assert!(at(12, 12) && at(32, 32), "the missed centres are filled");
        assert!(!at(52, 52), "the object stays out");
        assert!(!at(2, 2), "the outside stays out");
        // A hole larger than an element (the 4 squares at 58..78, 18..38,
        // inside the board, emptied) stays, though its colour blends.
        let mut big = board(w, h, 10, 8, 1, true);
        let mut big_light = light.clone();
        for y in 18..38 {
            for x in 58..78 {
                big.data[y * w + x] = false;
                big_light.data[y * w + x] = false;
            }
        }
        let u = merged(&big, &big_light, &vec![true; w * h]);
        assert!(!u.data[28 * w + 68], "a hole of four squares stays");
        assert!(u.data[12 * w + 12] && u.data[42 * w + 68]);
    }

    #[test]
    fn a_fine_chessboard_has_many_elements() {
        // 4-pixel squares, 128 of each colour on 64×64: each well under 1 %
        // of its colour's area, all elements; single pixels are specks.
        let (w, h) = (64, 64);
        let dark = board(w, h, 4, 0, 0, true);
        let e = Elements::of(&dark.data, w);
        assert_eq!(e.count, 128);
        assert!(e.repeat(), "{e:?}");
        let dots: Vec<bool> = (0..w * h).map(|i| i % 7 == 0).collect();
        assert_eq!(Elements::of(&dots, w).count, 0);
        let m = measure(&dark, &board(w, h, 4, 0, 0, false), &vec![true; w * h]);
        assert!(m.is_pattern(), "{m:?}");
    }

    #[test]
    fn an_object_on_a_background_is_not() {
        // A rug on a floor that shows around it.
        let (w, h) = (80, 60);
        let rug = mask(w, h, |x, y| (20..60).contains(&x) && (20..45).contains(&y));
        let floor = mask(w, h, |x, y| {
            y >= 10 && !((19..61).contains(&x) && (19..46).contains(&y))
        });
        let valid = vec![true; w * h];
        let m = measure(&rug, &floor, &valid);
        assert!(m.border_share > 0.9, "{m:?}");
        assert!(!m.is_pattern(), "{m:?}");
        // And the floor is not a pattern of the rug.
        let m = measure(&floor, &rug, &valid);
        assert!(!m.is_pattern(), "{m:?}");
    }

    #[test]
    fn a_few_frames_on_a_wall_are_not() {
        let (w, h) = (120, 80);
        let frames = mask(w, h, |x, y| {
            (20..40).contains(&y)
                && [10usize, 40, 70, 100]
                    .iter()
                    .any(|&x0| (x0..x0 + 12).contains(&x))
        });
        let wall = mask(w, h, |x, y| {
            !(18..42).contains(&y)
                || ![8usize, 38, 68, 98]
                    .iter()
                    .any(|&x0| (x0..x0 + 16).contains(&x))
        });
        let m = measure(&frames, &wall, &vec![true; w * h]);
        assert!(!m.is_pattern(), "{m:?}");
    }

    #[test]
    fn stripes_are_a_pattern() {
        // A striped shirt: dark and light bands inside its outline.
        let (w, h) = (100, 100);
        let inside = |x: usize, y: usize| (20..80).contains(&x) && (10..90).contains(&y);
        let stripes = |period: usize| {
            let dark = mask(w, h, |x, y| {
                inside(x, y) && (y / period).is_multiple_of(2) && y % period != period - 1
            });
            let light = mask(w, h, |x, y| {
                inside(x, y) && (y / period) % 2 == 1 && y % period != period - 1
            });
            measure(&dark, &light, &vec![true; w * h])
        };
        // 10 stripes of each colour: a pattern.
        let m = stripes(4);
        assert!(m.is_pattern(), "{m:?}");
        // 4 or 5 wide bands of each: too few to tell from a few objects.
        let m = stripes(8);
        assert!(!m.is_pattern(), "{m:?}");
        assert!(m.elements.count < MIN_ELEMENTS, "{m:?}");
    }

    #[test]
    fn companion_seed_reads_the_surroundings() {
        // Mask: a square of colour A; around it colour B, further out C.
        let (w, h) = (40, 40);
        let m = mask(w, h, |x, y| (15..25).contains(&x) && (15..25).contains(&y));
        let mut seg = Image::zeros(3, h, w);
        for i in 0..w * h {
            let (x, y) = ((i % w) as i64, (i / w) as i64);
            let dist = (x - 19).abs().max((y - 19).abs());
            let c = if m.data[i] {
                [0.1, 0.1, 0.1]
            } else if dist <= 9 {
                [0.8, 0.7, 0.6]
            } else {
                [0.2, 0.9, 0.2]
            };
            for (k, v) in c.iter().enumerate() {
                seg.data[k * w * h + i] = *v;
            }
        }
        let (at, colour) = companion_seed(&seg, &vec![true; w * h], &m).unwrap();
        assert_eq!(colour, [0.8, 0.7, 0.6]);
        let i = at[1] * w + at[0];
        assert!(!m.data[i]);
        // Empty ring: nothing to pick.
        let all = mask(w, h, |_, _| true);
        assert!(companion_seed(&seg, &vec![true; w * h], &all).is_none());
    }
}
