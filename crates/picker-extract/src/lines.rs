//! The plane's normal from the photo's own straight lines.
//!
//! A planar textured region (bricks, tiles, planks, a window grid) shows
//! families of straight lines that are parallel on the plane, so in the photo
//! each family meets at a vanishing point whose direction lies *in* the
//! plane. The predicted normals of the small default networks can be tens of
//! degrees off; one vanishing direction `d` fixes the normal's component
//! along it (`n ← n − (n·d) d`), two of them fix the normal outright
//! (`n = d₁ × d₂`). A region without a consistent family (noise, stone,
//! fabric) keeps the predicted normal.
//!
//! 1. [`segments`]: line segments inside the mask, grown from pixels of
//!    strong gradient whose level-line angles agree (in the spirit of LSD,
//!    von Gioi et al. 2010), kept when long and thin.
//! 2. [`vanishing_directions`]: up to two directions, each found by a seeded
//!    RANSAC over pairs of segments (the intersection of their
//!    interpretation planes), scored by the length of the segments that point
//!    at it within [`INLIER_DEG`], refined by least squares, and kept when
//!    its segments make at least [`MIN_SUPPORT`] of the total length.
//! 3. [`refine_normal`]: the normal from them, kept only when the plane still
//!    faces the camera.
//!
//! Camera space as everywhere here: +x right, +y up, +z towards the camera;
//! pixel `(x, y)` (y down, centres at half-integers) looks along
//! `((x − cx)/f, −(y − cy)/f, −1)`.

use glam::{Vec2, Vec3};
use rayon::prelude::*;
use serde::Serialize;

/// A straight segment of the photo, in pixels.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Segment {
    /// One end.
    pub a: Vec2,
    /// The other end.
    pub b: Vec2,
}

impl Segment {
    /// Length in pixels.
    pub fn length(&self) -> f32 {
        (self.b - self.a).length()
    }
}

/// A vanishing direction and how well the photo supports it.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct Vanishing {
    /// Unit direction in camera space (sign arbitrary).
    pub direction: [f32; 3],
    /// Segments pointing at it.
    pub segments: usize,
    /// Their share of the total segment length.
    pub support: f32,
}

/// What the line refinement found and did (`material.json`,
/// `diagnostics.uv.lines`).
#[derive(Clone, Debug, Serialize)]
pub struct LineRefinement {
    /// Segments found in the mask.
    pub segments: usize,
    /// The vanishing directions kept (0–2).
    pub vanishing: Vec<Vanishing>,
    /// The plane normal from the predicted normals (camera space).
    pub predicted_normal: [f32; 3],
    /// The plane normal used (camera space).
    pub normal: [f32; 3],
    /// Angle between the two (degrees).
    pub normal_change_deg: f32,
    /// True when the normal was snapped to one of the scene's orthogonal
    /// directions ([`LineFocal::axes`]; see [`refine_plane_normal`]).
    pub snapped_to_axis: bool,
    /// True when the refined normal was used.
    pub applied: bool,
    /// When the region's one family of lines asked to turn the predicted
    /// normal by more than [`MAX_ONE_DIRECTION_TURN_DEG`] and was refused:
    /// that turn, degrees. The photo's lines and the predicted plane then
    /// disagree, and one of them is wrong: a pattern's strokes that are not
    /// in the plane, or a predicted plane far off (a head-on photo taken
    /// for a floor); the CLI then suggests giving the plane.
    pub refused_turn_deg: Option<f32>,
    /// The best-supported vanishing direction of the region that lies in the
    /// plane used (within [`crate::plane::MAX_AXIS_TILT_DEG`]): the
    /// rectified texture's axes are turned to follow it
    /// ([`crate::plane::plane_basis`]). `None` when there is none.
    pub texture_axis: Option<[f32; 3]>,
    /// The focal length the photo's lines gave, when they gave one and it
    /// was used (else the plane mode's focal came from `--fov`, the view
    /// vectors or the default).
    pub focal: Option<LineFocal>,
}

/// Largest side of the image the segments are found on (the photo is
/// box-downsampled by a whole factor to fit): enough for the lines of a
/// texture, cheap at 12 MP.
pub const MAX_SIDE: usize = 800;
/// Gradient magnitude (luma units per pixel) below which no pixel seeds or
/// joins a segment.
pub const MIN_GRADIENT: f32 = 0.02;
/// Level-line angle tolerance of the region growing (degrees).
pub const GROW_TOLERANCE_DEG: f32 = 22.5;
/// Shortest segment kept (pixels of the downsampled image).
pub const MIN_LENGTH: f32 = 10.0;
/// Smallest length / width of a kept segment.
pub const MIN_ELONGATION: f32 = 4.0;
/// A segment points at a vanishing point when the angle between it and the
/// line from its midpoint to the point is at most this (degrees).
pub const INLIER_DEG: f32 = 1.5;
/// Share of the total segment length a vanishing direction must gather.
pub const MIN_SUPPORT: f32 = 0.2;
/// Fewest segments a vanishing direction must gather.
pub const MIN_SEGMENTS: usize = 6;
/// Two vanishing directions closer than this (degrees, in 3-D) give no
/// reliable normal; the second is then dropped.
pub const MIN_VP_SEPARATION_DEG: f32 = 30.0;
/// RANSAC hypotheses per vanishing direction.
pub const HYPOTHESES: usize = 600;

/// Line segments of the masked part of a `w × h` grey image (`luma`, row
/// major, values in [0, 1]); only pixels whose whole 3×3 neighbourhood is in
/// the mask take part, so the mask's own outline makes no segment. Same
/// input, same segments.
pub fn segments(luma: &[f32], mask: &[bool], w: usize, h: usize) -> Vec<Segment> {
    let mut out = Vec::new();
    edge_regions(luma, mask, w, h, |region, mag| {
        if let Some(s) = fit_segment(region, w, mag) {
            out.push(s);
        }
    });
    out
}

/// The regions [`segments`] fits its segments to: pixels of strong gradient
/// grown while their level-line angles agree, each handed to `visit` with
/// the gradient magnitude of any pixel (index `y·w + x`), in a fixed order.
pub(crate) fn edge_regions(
    luma: &[f32],
    mask: &[bool],
    w: usize,
    h: usize,
    mut visit: impl FnMut(&[usize], &dyn Fn(usize) -> f32),
) {
    assert_eq!(luma.len(), w * h, "luma is w × h");
    assert_eq!(mask.len(), w * h, "mask is w × h");
    if w < 3 || h < 3 {
        return;
    }
    // Sobel gradients of interior pixels.
    let n = w * h;
    // (gx, gy, magnitude) per pixel, rows in parallel (each pixel alone).
    let mut grad = vec![(0.0f32, 0.0f32, 0.0f32); n];
    grad.par_chunks_mut(w)
        .enumerate()
        .filter(|(y, _)| *y >= 1 && *y + 1 < h)
        .for_each(|(y, row)| {
            for (x, g) in row.iter_mut().enumerate().take(w - 1).skip(1) {
                let inside = (0..3).all(|dy| (0..3).all(|dx| mask[(y + dy - 1) * w + x + dx - 1]));
                if !inside {
                    continue;
                }
                let p = |dx: usize, dy: usize| luma[(y + dy - 1) * w + x + dx - 1];
                let sx = (p(2, 0) + 2.0 * p(2, 1) + p(2, 2)) - (p(0, 0) + 2.0 * p(0, 1) + p(0, 2));
                let sy = (p(0, 2) + 2.0 * p(1, 2) + p(2, 2)) - (p(0, 0) + 2.0 * p(1, 0) + p(2, 0));
                let (gx, gy) = (sx / 8.0, sy / 8.0);
                *g = (gx, gy, (gx * gx + gy * gy).sqrt());
            }
        });
    let mag = |i: usize| grad[i].2;
    // Seeds by decreasing magnitude (ties by index: deterministic).
    let mut order: Vec<usize> = (0..n).filter(|&i| mag(i) >= MIN_GRADIENT).collect();
    order.par_sort_unstable_by(|&a, &b| mag(b).total_cmp(&mag(a)).then(a.cmp(&b)));
    // Level-line direction: along the edge, (−gy, gx) in image axes.
    let dir = |i: usize| Vec2::new(-grad[i].1, grad[i].0) / grad[i].2;
    let cos_tol = GROW_TOLERANCE_DEG.to_radians().cos();
    let mut used = vec![false; n];
    let mut region = Vec::new();
    let mut stack = Vec::new();
    for &seed in &order {
        if used[seed] {
            continue;
        }
        region.clear();
        stack.clear();
        used[seed] = true;
        stack.push(seed);
        let mut sum = dir(seed);
        while let Some(i) = stack.pop() {
            region.push(i);
            let mean = sum.normalize_or_zero();
            let (x, y) = (i % w, i / w);
            for dy in -1i64..=1 {
                for dx in -1i64..=1 {
                    let (nx, ny) = (x as i64 + dx, y as i64 + dy);
                    if nx < 0 || ny < 0 || nx >= w as i64 || ny >= h as i64 {
                        continue;
                    }
                    let j = ny as usize * w + nx as usize;
                    if used[j] || mag(j) < MIN_GRADIENT || dir(j).dot(mean) < cos_tol {
                        continue;
                    }
                    used[j] = true;
                    sum += dir(j);
                    stack.push(j);
                }
            }
        }
        visit(&region, &mag);
    }
}

/// The segment of a region of pixels: their magnitude-weighted principal
/// axis, from the extreme projections; `None` when short or not thin.
fn fit_segment(region: &[usize], w: usize, mag: impl Fn(usize) -> f32) -> Option<Segment> {
    if (region.len() as f32) < MIN_LENGTH {
        return None;
    }
    let pt = |i: usize| Vec2::new((i % w) as f32 + 0.5, (i / w) as f32 + 0.5);
    let mut wsum = 0.0f64;
    let mut c = [0.0f64; 2];
    for &i in region {
        let p = pt(i);
        let m = mag(i) as f64;
        wsum += m;
        c[0] += m * p.x as f64;
        c[1] += m * p.y as f64;
    }
    let c = Vec2::new((c[0] / wsum) as f32, (c[1] / wsum) as f32);
    let (mut sxx, mut sxy, mut syy) = (0.0f64, 0.0f64, 0.0f64);
    for &i in region {
        let d = pt(i) - c;
        let m = mag(i) as f64;
        sxx += m * (d.x * d.x) as f64;
        sxy += m * (d.x * d.y) as f64;
        syy += m * (d.y * d.y) as f64;
    }
    // The principal axis of the 2×2 scatter matrix.
    let theta = 0.5 * (2.0 * sxy).atan2(sxx - syy);
    let axis = Vec2::new(theta.cos() as f32, theta.sin() as f32);
    let across = axis.perp();
    let (mut lo, mut hi, mut wlo, mut whi) = (f32::MAX, f32::MIN, f32::MAX, f32::MIN);
    for &i in region {
        let d = pt(i) - c;
        let (s, t) = (d.dot(axis), d.dot(across));
        lo = lo.min(s);
        hi = hi.max(s);
        wlo = wlo.min(t);
        whi = whi.max(t);
    }
    let (length, width) = (hi - lo + 1.0, whi - wlo + 1.0);
    (length >= MIN_LENGTH && length >= MIN_ELONGATION * width).then(|| Segment {
        a: c + axis * lo,
        b: c + axis * hi,
    })
}

/// The camera-space ray through pixel `p` of an image with centre `c` and
/// focal `f` (pixels).
fn ray(p: Vec2, c: Vec2, f: f32) -> Vec3 {
    Vec3::new((p.x - c.x) / f, -(p.y - c.y) / f, -1.0)
}

/// The |cosine| of the angle between segment `s` and the line from its
/// midpoint towards the vanishing point of direction `d` (1: it points
/// exactly there).
fn pointing_cos(s: &Segment, d: Vec3, c: Vec2, f: f32) -> f32 {
    // The vanishing point, homogeneous: (c·(−d.z) + f·(d.x, −d.y), −d.z).
    let vz = -d.z;
    let v = Vec2::new(c.x * vz + f * d.x, c.y * vz - f * d.y);
    let m = (s.a + s.b) * 0.5;
    let to_vp = v - m * vz;
    let along = s.b - s.a;
    let (l1, l2) = (to_vp.length(), along.length());
    if l1 < 1e-9 || l2 < 1e-9 {
        return 0.0;
    }
    (to_vp.dot(along) / (l1 * l2)).abs()
}

/// True when segment `s` points at the vanishing point of direction `d`
/// (within [`INLIER_DEG`]).
fn points_at(s: &Segment, d: Vec3, c: Vec2, f: f32) -> bool {
    pointing_cos(s, d, c, f) >= INLIER_DEG.to_radians().cos()
}

/// The total length of the segments of `segs` that point at direction `d`.
fn length_pointing_at<'a>(
    segs: impl Iterator<Item = &'a Segment>,
    d: Vec3,
    c: Vec2,
    f: f32,
) -> f32 {
    segs.filter(|s| points_at(s, d, c, f))
        .map(Segment::length)
        .sum()
}

/// Up to two vanishing directions of `segs` in an image with principal
/// point `c` and focal `f` (pixels), the best supported first, each with at
/// least [`MIN_SUPPORT`] of the total length (see the module docs).
/// Deterministic for a given `seed`.
pub fn vanishing_directions(segs: &[Segment], c: Vec2, f: f32, seed: u64) -> Vec<Vanishing> {
    vanishing_search(segs, c, f, seed, 2, MIN_SUPPORT)
}

/// Up to `max` vanishing directions, each gathering at least `min_support`
/// of the total segment length.
fn vanishing_search(
    segs: &[Segment],
    c: Vec2,
    f: f32,
    seed: u64,
    max: usize,
    min_support: f32,
) -> Vec<Vanishing> {
    let total: f32 = segs.iter().map(Segment::length).sum();
    if segs.len() < MIN_SEGMENTS || total <= 0.0 || f.is_nan() || f <= 0.0 {
        return Vec::new();
    }
    // Interpretation-plane normals: a segment's 3-D direction is orthogonal
    // to its plane through the camera centre.
    let planes: Vec<Vec3> = segs
        .iter()
        .map(|s| ray(s.a, c, f).cross(ray(s.b, c, f)).normalize_or_zero())
        .collect();
    let mut rng = picker_tensor::Rng::new(seed);
    let mut left: Vec<usize> = (0..segs.len()).collect();
    let mut found: Vec<Vanishing> = Vec::new();
    while found.len() < max && left.len() >= MIN_SEGMENTS {
        // Hypotheses from pairs among the longest remaining segments.
        let mut cand = left.clone();
        cand.sort_by(|&a, &b| {
            segs[b]
                .length()
                .total_cmp(&segs[a].length())
                .then(a.cmp(&b))
        });
        cand.truncate(200);
        let inliers_of = |d: Vec3| -> (Vec<usize>, f32) {
            let mut ids = Vec::new();
            let mut len = 0.0;
            for &i in &left {
                if points_at(&segs[i], d, c, f) {
                    ids.push(i);
                    len += segs[i].length();
                }
            }
            (ids, len)
        };
        // The hypotheses drawn in order, scored in parallel; the best is
        // the first of the highest score (the same for any thread count).
        let hyps: Vec<Vec3> = (0..HYPOTHESES)
            .filter_map(|_| {
                let i = cand[rng.range(0, cand.len() - 1)];
                let j = cand[rng.range(0, cand.len() - 1)];
                let d = planes[i].cross(planes[j]);
                (i != j && d.length() >= 1e-6).then(|| d.normalize())
            })
            .collect();
        let score = |d: Vec3| length_pointing_at(left.iter().map(|&i| &segs[i]), d, c, f);
        let best = hyps
            .par_iter()
            .enumerate()
            .map(|(k, &d)| (score(d), k))
            .reduce(
                || (f32::NEG_INFINITY, usize::MAX),
                |a, b| {
                    if b.0 > a.0 || (b.0 == a.0 && b.1 < a.1) {
                        b
                    } else {
                        a
                    }
                },
            );
        let Some(&d0) = hyps.get(best.1) else { break };
        // Least squares: the direction most orthogonal to the inliers'
        // interpretation planes, weighted by length (two rounds).
        let mut d = d0;
        for _ in 0..2 {
            let (ids, _) = inliers_of(d);
            if ids.len() < 2 {
                break;
            }
            let mut m = glam::Mat3::ZERO;
            for &i in &ids {
                let p = planes[i];
                let wgt = segs[i].length();
                m += glam::Mat3::from_cols(p * p.x, p * p.y, p * p.z) * wgt;
            }
            let refined = smallest_eigenvector(m);
            if refined.is_finite() && refined.length() > 0.5 {
                d = refined.normalize();
            }
        }
        let (ids, len) = inliers_of(d);
        if ids.len() < MIN_SEGMENTS || len < min_support * total {
            break;
        }
        let separated = found.iter().all(|v| {
            let o = Vec3::from(v.direction);
            o.dot(d).abs() <= MIN_VP_SEPARATION_DEG.to_radians().cos()
        });
        let mut taken = vec![false; segs.len()];
        for &i in &ids {
            taken[i] = true;
        }
        left.retain(|&i| !taken[i]);
        if !separated {
            continue;
        }
        found.push(Vanishing {
            direction: d.to_array(),
            segments: ids.len(),
            support: len / total,
        });
    }
    found
}

/// The unit eigenvector of the smallest eigenvalue of a symmetric 3×3
/// matrix (inverse iteration on a slightly shifted matrix, from a start
/// not orthogonal to any axis).
fn smallest_eigenvector(m: glam::Mat3) -> Vec3 {
    // Shift by a small multiple of the trace so the inverse exists.
    let tr = m.x_axis.x + m.y_axis.y + m.z_axis.z;
    let shifted = m + glam::Mat3::IDENTITY * (1e-6 * tr.max(1e-12));
    let inv = shifted.inverse();
    let mut v = Vec3::new(0.577, 0.577, 0.578);
    for _ in 0..30 {
        let nv = inv * v;
        if !nv.is_finite() || nv.length() < 1e-20 {
            break;
        }
        v = nv.normalize();
    }
    v
}

/// The largest turn (degrees) of the predicted normal that one vanishing
/// direction alone may make ([`refine_normal`]). One line family fixes one
/// degree of freedom of the plane; a family that would turn the network's
/// normal further is more likely not in the plane at all (the strokes of a
/// graffiti converging on a false vanishing point turned `graf1.png`'s wall
/// by 85°, to an edge-on plane whose texture was a few streaks; a dog's fur
/// in `chicky_512.png` by 67°). No pick of the synthetic evaluation sets
/// (test100, proc-4242, assets-5151, 317 textured rows) or of the model
/// card's photos turned more than this.
pub const MAX_ONE_DIRECTION_TURN_DEG: f32 = 45.0;

/// The turn, degrees, that [`refine_normal`] refuses: with exactly one
/// vanishing direction that would turn `n` (unit) by more than
/// [`MAX_ONE_DIRECTION_TURN_DEG`]; else `None`.
pub fn refused_turn_deg(n: Vec3, vanishing: &[Vanishing]) -> Option<f32> {
    match vanishing {
        [a] => {
            let turn = n
                .dot(Vec3::from(a.direction))
                .abs()
                .min(1.0)
                .asin()
                .to_degrees();
            (turn > MAX_ONE_DIRECTION_TURN_DEG).then_some(turn)
        }
        _ => None,
    }
}

/// The plane normal given the predicted one (`n`, unit) and the vanishing
/// directions in the plane: the cross product of two, or `n` without its
/// component along one (when that turns `n` by at most
/// [`MAX_ONE_DIRECTION_TURN_DEG`]); oriented like `n`. `None` when there is
/// none, or when the result would not face a camera looking along `view`
/// (`n·view ≥ −0.05`).
pub fn refine_normal(n: Vec3, vanishing: &[Vanishing], view: Vec3) -> Option<Vec3> {
    let refined = match vanishing {
        [] => return None,
        [a] => {
            let d = Vec3::from(a.direction);
            // Turning `n` into the plane ⟂ `d` turns it by asin|n·d|.
            if n.dot(d).abs() > MAX_ONE_DIRECTION_TURN_DEG.to_radians().sin() {
                return None;
            }
            (n - n.dot(d) * d).normalize_or_zero()
        }
        [a, b, ..] => Vec3::from(a.direction)
            .cross(Vec3::from(b.direction))
            .normalize_or_zero(),
    };
    if refined == Vec3::ZERO {
        return None;
    }
    let refined = if refined.dot(n) < 0.0 {
        -refined
    } else {
        refined
    };
    (refined.dot(view.normalize_or_zero()) < -0.05).then_some(refined)
}

/// The best-supported of `vanishing` within
/// [`crate::plane::MAX_AXIS_TILT_DEG`] of the plane of normal `n` (ties: the
/// first): the direction the plane's texture runs along, if any.
pub fn texture_axis(vanishing: &[Vanishing], n: Vec3) -> Option<[f32; 3]> {
    let max_out = crate::plane::MAX_AXIS_TILT_DEG.to_radians().sin();
    vanishing
        .iter()
        .filter(|v| Vec3::from(v.direction).dot(n).abs() <= max_out)
        .fold(None::<&Vanishing>, |best, v| match best {
            Some(b) if b.support >= v.support => Some(b),
            _ => Some(v),
        })
        .map(|v| v.direction)
}

/// The vanishing directions of the straight lines of the photo's region
/// `mask` (photo resolution, read through `small`) under focal `focal`
/// (photo pixels), as [`refine_plane_normal`] finds them.
pub fn region_vanishing(small: &SmallLuma, mask: &[bool], focal: f32) -> Vec<Vanishing> {
    let m = small.mask(mask);
    let segs = small.segments(&m);
    vanishing_directions(&segs, small.centre(), focal / small.k as f32, 0x11ae5)
}

/// The focal length found by [`focal_from_lines`], and from what.
#[derive(Clone, Debug, Serialize)]
pub struct LineFocal {
    /// Focal length, full-photo pixels.
    pub focal_px: f32,
    /// Vertical field of view it gives (degrees).
    pub fov_y_deg: f32,
    /// The two vanishing points (full-photo pixels) whose directions were
    /// taken as orthogonal.
    pub vanishing_points: [[f32; 2]; 2],
    /// The scene's three orthogonal directions this focal gives (camera
    /// space, unit): the two vanishing directions and their cross product.
    pub axes: [[f32; 3]; 3],
}

/// Share of the whole photo's segment length a vanishing point must gather
/// for [`focal_from_lines`].
pub const FOCAL_MIN_SUPPORT: f32 = 0.02;
/// Vertical fields of view (degrees) [`focal_from_lines`] accepts.
pub const FOCAL_FOV_RANGE: (f32, f32) = (25.0, 110.0);

/// A photo's luma box-downsampled by a whole factor to at most
/// [`MAX_SIDE`]: what the segments are found on.
#[derive(Clone, Debug)]
pub struct SmallLuma {
    /// `w × h` values, row major.
    pub luma: Vec<f32>,
    /// Columns (`⌊fw / k⌋`).
    pub w: usize,
    /// Rows (`⌊fh / k⌋`).
    pub h: usize,
    /// The factor.
    pub k: usize,
    /// The photo's size.
    pub full: (usize, usize),
    /// The photo's lens distortion ([`crate::lens`]): the segments are
    /// undistorted by it before they point anywhere (0: a pinhole).
    pub lambda: f32,
}

impl SmallLuma {
    /// Downsamples a `fw × fh` luma plane (rows in parallel, each block
    /// summed in a fixed order).
    pub fn new(luma: &[f32], fw: usize, fh: usize) -> Self {
        assert_eq!(luma.len(), fw * fh, "luma is fw × fh");
        let k = fw.max(fh).div_ceil(MAX_SIDE).max(1);
        let (w, h) = (fw / k, fh / k);
        let mut l = vec![0.0f32; w * h];
        let inv = 1.0 / (k * k) as f32;
        l.par_chunks_mut(w.max(1)).enumerate().for_each(|(y, lr)| {
            for (x, lv) in lr.iter_mut().enumerate() {
                let mut s = 0.0f32;
                for yy in y * k..(y + 1) * k {
                    let row = yy * fw;
                    s += luma[row + x * k..row + (x + 1) * k].iter().sum::<f32>();
                }
                *lv = s * inv;
            }
        });
        Self {
            luma: l,
            w,
            h,
            k,
            full: (fw, fh),
            lambda: 0.0,
        }
    }

    /// The line segments of the region `m` (at this size, [`SmallLuma::mask`]),
    /// their ends undistorted by the photo's lens ([`SmallLuma::lambda`]).
    pub fn segments(&self, m: &[bool]) -> Vec<Segment> {
        let mut segs = segments(&self.luma, m, self.w, self.h);
        if self.lambda != 0.0 {
            let (fw, fh) = self.full;
            let lens = crate::lens::Lens::new(self.lambda, fw, fh);
            let k = self.k as f32;
            let undistort = |p: Vec2| lens.undistort(p * k) / k;
            for s in &mut segs {
                (s.a, s.b) = (undistort(s.a), undistort(s.b));
            }
        }
        segs
    }

    /// A full-resolution mask at this size: a block is in it when all its
    /// pixels are.
    ///
    /// # Panics
    /// When `mask` is not the full resolution's size.
    pub fn mask(&self, mask: &[bool]) -> Vec<bool> {
        let (fw, fh) = self.full;
        assert_eq!(mask.len(), fw * fh, "mask is the photo's size");
        let (w, k) = (self.w, self.k);
        let mut m = vec![false; w * self.h];
        m.par_chunks_mut(w.max(1)).enumerate().for_each(|(y, mr)| {
            for (x, mv) in mr.iter_mut().enumerate() {
                *mv = (y * k..(y + 1) * k).all(|yy| {
                    mask[yy * fw + x * k..yy * fw + (x + 1) * k]
                        .iter()
                        .all(|&b| b)
                });
            }
        });
        m
    }

    /// The photo's principal point (its centre) in these pixels.
    fn centre(&self) -> Vec2 {
        Vec2::new(self.full.0 as f32, self.full.1 as f32) / (2 * self.k) as f32
    }
}

/// The focal length of a photo (its downsampled sRGB luma) from its
/// straight lines, for scenes of mostly orthogonal structure (rooms,
/// furniture, tiles): up to three vanishing points of the whole photo, and
/// the best supported pair of finite ones on opposite sides of the centre
/// taken as orthogonal directions, `f² = −(v₁ − c)·(v₂ − c)`. `None` when no
/// such pair exists or the field of view would leave [`FOCAL_FOV_RANGE`].
pub fn focal_from_lines(small: &SmallLuma) -> Option<LineFocal> {
    let (w, h, k) = (small.w, small.h, small.k);
    let fh = small.full.1;
    let segs = small.segments(&vec![true; w * h]);
    let c = small.centre();
    // Any focal finds the same vanishing points (the test is in the image).
    let f0 = w.max(h) as f32;
    let vps = vanishing_search(&segs, c, f0, 0xf0ca1, 3, FOCAL_MIN_SUPPORT);
    // Each as a finite image point relative to the centre, where it is one.
    let points: Vec<(Vec2, f32)> = vps
        .iter()
        .filter_map(|v| {
            let d = Vec3::from(v.direction);
            // A point farther than 20 image sizes out says nothing of f.
            (d.z.abs() * 20.0 * f0 > f0 * Vec2::new(d.x, d.y).length())
                .then(|| (Vec2::new(d.x, -d.y) * (f0 / -d.z), v.support))
        })
        .collect();
    let mut best: Option<(f32, f32, [Vec2; 2])> = None;
    for i in 0..points.len() {
        for j in i + 1..points.len() {
            let ((a, sa), (b, sb)) = (points[i], points[j]);
            let p = a.dot(b);
            if p >= 0.0 {
                continue;
            }
            let f = (-p).sqrt();
            let fov = crate::plane::fov_from_focal(h, f);
            if !(FOCAL_FOV_RANGE.0..=FOCAL_FOV_RANGE.1).contains(&fov) {
                continue;
            }
            let weight = sa.min(sb);
            if best.is_none_or(|(_, w, _)| weight > w) {
                best = Some((f, weight, [a, b]));
            }
        }
    }
    let (f, _, [a, b]) = best?;
    let full = |p: Vec2| ((p + c) * k as f32).to_array();
    let focal_px = f * k as f32;
    // The directions through the two points (orthogonal by the choice of f).
    let dir = |p: Vec2| Vec3::new(p.x / f, -p.y / f, -1.0).normalize();
    let (d1, d2) = (dir(a), dir(b));
    Some(LineFocal {
        focal_px,
        fov_y_deg: crate::plane::fov_from_focal(fh, focal_px),
        vanishing_points: [full(a), full(b)],
        axes: [
            d1.to_array(),
            d2.to_array(),
            d1.cross(d2).normalize().to_array(),
        ],
    })
}

/// A scene axis lies in the region's plane when the region's segments that
/// point at its vanishing point make at least this share of their length.
pub const MIN_AXIS_SUPPORT: f32 = 0.1;
/// A scene axis can be the region's normal only when at most this share of
/// the region's pixels look at the back of a plane with that normal.
pub const MAX_BACKFACING: f32 = 0.02;
/// The largest turn (degrees) from the line-refined normal to the scene axis
/// it is snapped to (a sanity bound: the axes may be wrong in a scene
/// without orthogonal structure).
pub const MAX_SNAP_DEG: f32 = 60.0;

/// An axis is the photo's vertical when it is within this many degrees of
/// the image's up direction (camera `+y`): an upright camera, tilted or
/// rolled by less than this.
pub const MAX_VERTICAL_TILT_DEG: f32 = 30.0;

/// The index of the scene axis that is the photo's vertical (within
/// [`MAX_VERTICAL_TILT_DEG`] of camera `+y`, either sign), if one is.
pub fn vertical_axis(axes: &[[f32; 3]; 3]) -> Option<usize> {
    let cos = MAX_VERTICAL_TILT_DEG.to_radians().cos();
    (0..3)
        .map(|i| (i, Vec3::from(axes[i]).normalize_or_zero().y.abs()))
        .filter(|&(_, y)| y >= cos)
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(i, _)| i)
}

/// The scene axis to use as the region's normal, oriented like `n`: the
/// region's lines point at the axes marked `in_plane`, so the normal is an
/// axis that is not, and it must be `feasible` (a plane with that normal can
/// show every pixel of the region: it is not seen from behind anywhere).
///
/// - One such axis: it, when within [`MAX_SNAP_DEG`] of `n`.
/// - Two (a single horizontal line family on a region that could be a wall
///   or a floor or ceiling): the `vertical` axis ([`vertical_axis`]) when
///   it is one of them, whatever `n` says. Such a region lies wholly on one
///   side of the horizon (else a floor or ceiling would be seen from
///   behind), and its lines run level: in a photo taken upright indoors
///   that is a floor or a ceiling far more often than the lower or upper
///   part of a wall that shows no vertical line.
///
/// `None` when no axis is in the plane, or the choice is not made by the
/// above (the predicted normal is then all there is).
pub fn snap_to_axes(
    n: Vec3,
    axes: &[[f32; 3]; 3],
    in_plane: [bool; 3],
    feasible: [bool; 3],
    vertical: Option<usize>,
) -> Option<Vec3> {
    if !in_plane.iter().any(|&b| b) {
        return None;
    }
    let candidates: Vec<usize> = (0..3).filter(|&i| !in_plane[i] && feasible[i]).collect();
    let orient = |i: usize| {
        let a = Vec3::from(axes[i]);
        if a.dot(n) < 0.0 {
            -a
        } else {
            a
        }
    };
    match candidates[..] {
        [i] => {
            let a = orient(i);
            (a.dot(n) >= MAX_SNAP_DEG.to_radians().cos()).then_some(a)
        }
        [i, j] => vertical.filter(|&v| v == i || v == j).map(orient),
        _ => None,
    }
}

/// The whole refinement for the picked `mask` of a photo (full resolution)
/// whose downsampled luma is `small` (the mask is downsampled alike, a block
/// in it when all its pixels are): segments, vanishing directions with the
/// focal `focal` (full photo pixels), and the refined normal, snapped to
/// one of the scene's `axes` when they are known (found with this focal) and
/// the region's lines single one out ([`snap_to_axes`]: its segments point
/// at an axis, and only one of the others is a normal under which every
/// region pixel sees the plane's front). Returns the normal to use (`n`
/// when nothing was found) and what was found.
pub fn refine_plane_normal(
    small: &SmallLuma,
    mask: &[bool],
    n: Vec3,
    focal: f32,
    axes: Option<&[[f32; 3]; 3]>,
) -> (Vec3, LineRefinement) {
    let (w, k) = (small.w, small.k);
    let m = small.mask(mask);
    let segs = small.segments(&m);
    // In downsampled pixels: the photo's centre and focal divided by k.
    let (centre, f) = (small.centre(), focal / k as f32);
    let vanishing = vanishing_directions(&segs, centre, f, 0x11ae5);
    // The mask's mean viewing ray (on the downsampled mask).
    let (mut sx, mut sy, mut cnt) = (0.0f64, 0.0f64, 0usize);
    for (i, _) in m.iter().enumerate().filter(|(_, &b)| b) {
        sx += (i % w.max(1)) as f64 + 0.5;
        sy += (i / w.max(1)) as f64 + 0.5;
        cnt += 1;
    }
    let view = if cnt > 0 {
        ray(
            Vec2::new((sx / cnt as f64) as f32, (sy / cnt as f64) as f32),
            centre,
            f,
        )
    } else {
        Vec3::NEG_Z
    };
    let refined = refine_normal(n, &vanishing, view);
    let snapped = match (refined, axes) {
        (Some(r), Some(axes)) => {
            let total: f32 = segs.iter().map(Segment::length).sum();
            let in_plane = axes.map(|a| {
                let along = length_pointing_at(segs.iter(), Vec3::from(a), centre, f);
                total > 0.0 && along >= MIN_AXIS_SUPPORT * total
            });
            let feasible = axes.map(|a| {
                // Oriented to face the camera at the region's centre.
                let a = Vec3::from(a);
                let a = if a.dot(view) > 0.0 { -a } else { a };
                let behind = m
                    .iter()
                    .enumerate()
                    .filter(|(_, &b)| b)
                    .filter(|(i, _)| {
                        let p = Vec2::new((i % w) as f32 + 0.5, (i / w) as f32 + 0.5);
                        ray(p, centre, f).dot(a) >= 0.0
                    })
                    .count();
                (behind as f32) <= MAX_BACKFACING * cnt as f32
            });
            snap_to_axes(r, axes, in_plane, feasible, vertical_axis(axes))
                .filter(|s| s.dot(view.normalize_or_zero()) < -0.05)
        }
        _ => None,
    };
    let used = snapped.or(refined).unwrap_or(n);
    let texture_axis = texture_axis(&vanishing, used);
    let refused = refused_turn_deg(n, &vanishing);
    (
        used,
        LineRefinement {
            segments: segs.len(),
            vanishing,
            predicted_normal: n.to_array(),
            normal: used.to_array(),
            normal_change_deg: n.dot(used).clamp(-1.0, 1.0).acos().to_degrees(),
            applied: refined.is_some(),
            refused_turn_deg: refused,
            texture_axis,
            snapped_to_axis: snapped.is_some(),
            focal: None,
        },
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A `w × h` luma image of the plane through `(0, 0, −dist)` with unit
    /// normal `n` (facing the camera), seen with focal `f` from the origin:
    /// a checkerboard of `cell`-sized squares along the in-plane axes `e1`
    /// and `n × e1`, 4×4 supersampled; the background (rays missing the
    /// plane) is mid-grey.
    fn checker_plane(w: usize, h: usize, f: f32, n: Vec3, e1: Vec3, cell: f32) -> Vec<f32> {
        let e2 = n.cross(e1);
        let (dist, c) = (3.0, Vec2::new(w as f32 / 2.0, h as f32 / 2.0));
        let p0 = Vec3::new(0.0, 0.0, -dist);
        let mut out = vec![0.0f32; w * h];
        for y in 0..h {
            for x in 0..w {
                let mut acc = 0.0;
                for sy in 0..4 {
                    for sx in 0..4 {
                        let p = Vec2::new(
                            x as f32 + (sx as f32 + 0.5) / 4.0,
                            y as f32 + (sy as f32 + 0.5) / 4.0,
                        );
                        let d = ray(p, c, f);
                        let nd = n.dot(d);
                        acc += if nd < -1e-4 {
                            let hit = d * (n.dot(p0) / nd);
                            let (s, t) = ((hit - p0).dot(e1), (hit - p0).dot(e2));
                            let odd = ((s / cell).floor() + (t / cell).floor()) as i64 & 1;
                            if odd == 1 {
                                0.8
                            } else {
                                0.2
                            }
                        } else {
                            0.5
                        };
                    }
                }
                out[y * w + x] = acc / 16.0;
            }
        }
        out
    }

    fn angle_deg(a: Vec3, b: Vec3) -> f32 {
        a.normalize()
            .dot(b.normalize())
            .abs()
            .min(1.0)
            .acos()
            .to_degrees()
    }

    /// An oblique floor-like plane: its normal tilted back and turned.
    fn oblique() -> (Vec3, Vec3) {
        let n = Vec3::new(0.35, 0.75, 0.56).normalize();
        let e1 = (Vec3::X - Vec3::X.dot(n) * n).normalize();
        // Turn the grid 30° in the plane so both families converge.
        let e1 =
            (e1 * 30f32.to_radians().cos() + n.cross(e1) * 30f32.to_radians().sin()).normalize();
        (n, e1)
    }

    #[test]
    fn segments_follow_straight_edges_and_ignore_the_mask_outline() {
        // Vertical bars 8 px wide in the left half of the mask only.
        let (w, h) = (80, 60);
        let luma: Vec<f32> = (0..w * h)
            .map(|i| if (i % w) / 8 % 2 == 0 { 0.2 } else { 0.8 })
            .collect();
        let mask: Vec<bool> = (0..w * h).map(|i| i % w < 40 && i / w > 5).collect();
        let segs = segments(&luma, &mask, w, h);
        assert!(segs.len() >= 4, "{segs:?}");
        for s in &segs {
            let d = (s.b - s.a).normalize();
            assert!(d.x.abs() < 0.05, "not vertical: {s:?}");
            // On a bar edge (x a multiple of 8), inside the mask, not at its
            // right outline (x = 40).
            let x = (s.a.x + s.b.x) / 2.0;
            assert!((x / 8.0 - (x / 8.0).round()).abs() < 0.15, "{s:?}");
            assert!(x < 39.0, "on the mask's outline: {s:?}");
            assert!(s.length() >= MIN_LENGTH);
        }
        // A flat image and an empty mask give nothing.
        assert!(segments(&vec![0.5; w * h], &mask, w, h).is_empty());
        assert!(segments(&luma, &vec![false; w * h], w, h).is_empty());
        assert!(segments(&[0.0; 4], &[true; 4], 2, 2).is_empty());
    }

    #[test]
    fn vanishing_directions_of_a_checker_plane_lie_in_it() {
        let (w, h, f) = (320, 240, 260.0);
        let (n, e1) = oblique();
        let luma = checker_plane(w, h, f, n, e1, 0.25);
        let segs = segments(&luma, &vec![true; w * h], w, h);
        let c = Vec2::new(w as f32 / 2.0, h as f32 / 2.0);
        let vps = vanishing_directions(&segs, c, f, 1);
        assert_eq!(vps.len(), 2, "{vps:?}");
        let e2 = n.cross(e1);
        for v in &vps {
            let d = Vec3::from(v.direction);
            assert!(angle_deg(d, n) > 88.0, "not in the plane: {v:?}");
            let off = angle_deg(d, e1).min(angle_deg(d, e2));
            assert!(off < 1.5, "{off}° from the grid's axes: {v:?}");
        }
        // Same input, same output.
        let again = vanishing_directions(&segs, c, f, 1);
        assert_eq!(format!("{vps:?}"), format!("{again:?}"));
    }

    #[test]
    fn no_vanishing_direction_from_unrelated_segments() {
        let mut rng = picker_tensor::Rng::new(9);
        let segs: Vec<Segment> = (0..200)
            .map(|_| {
                let a = Vec2::new(rng.uniform(0.0, 320.0), rng.uniform(0.0, 240.0));
                let t = rng.uniform(0.0, std::f32::consts::PI);
                let l = rng.uniform(10.0, 30.0);
                Segment {
                    a,
                    b: a + Vec2::new(t.cos(), t.sin()) * l,
                }
            })
            .collect();
        let vps = vanishing_directions(&segs, Vec2::new(160.0, 120.0), 260.0, 3);
        assert!(vps.is_empty(), "{vps:?}");
        // Too few segments: nothing.
        assert!(vanishing_directions(&segs[..3], Vec2::ZERO, 260.0, 3).is_empty());
    }

    #[test]
    fn refined_normal_is_orthogonal_to_the_directions_and_faces_the_camera() {
        let n = Vec3::new(0.3, 0.1, 0.95).normalize();
        // A 31° turn (n·d = 0.52).
        let d = Vec3::new(0.8, 0.0, 0.2);
        let v = |d: Vec3| Vanishing {
            direction: d.normalize().to_array(),
            segments: 10,
            support: 0.5,
        };
        let view = Vec3::NEG_Z;
        // One direction: n without its component along d.
        let r = refine_normal(n, &[v(d)], view).unwrap();
        assert!(r.dot(d.normalize()).abs() < 1e-5);
        assert!(r.dot(n) > 0.0 && (r.length() - 1.0).abs() < 1e-5);
        let expected = (n - n.dot(d.normalize()) * d.normalize()).normalize();
        assert!(angle_deg(r, expected) < 1e-3);
        // Two: their cross product, oriented like n.
        let d2 = Vec3::new(0.0, 1.0, 0.0);
        let r2 = refine_normal(n, &[v(d), v(d2)], view).unwrap();
        assert!(angle_deg(r2, d.cross(d2).normalize()) < 1e-3 && r2.dot(n) > 0.0);
        // None: nothing to refine with; a plane seen edge-on; one direction
        // that would turn n by more than MAX_ONE_DIRECTION_TURN_DEG (54°
        // here; 44° still turns it).
        assert!(refine_normal(n, &[], view).is_none());
        assert!(refine_normal(n, &[v(Vec3::Z)], Vec3::NEG_Z).is_none());
        assert!(refine_normal(n, &[v(Vec3::new(0.8, 0.0, 0.6))], view).is_none());
        let turn = |d: Vec3| n.dot(d.normalize()).abs().asin().to_degrees();
        let d44 = Vec3::new(0.8, 0.0, 0.392);
        assert!((43.0..45.0).contains(&turn(d44)), "{}", turn(d44));
        let r44 = refine_normal(n, &[v(d44)], view).unwrap();
        assert!((angle_deg(r44, n) - turn(d44)).abs() < 1e-2);
        // The refused turn is reported (the 54° one), the made ones not.
        let d54 = Vec3::new(0.8, 0.0, 0.6);
        let refused = refused_turn_deg(n, &[v(d54)]).unwrap();
        assert!(
            (refused - turn(d54)).abs() < 1e-3 && refused > 50.0,
            "{refused}"
        );
        assert_eq!(refused_turn_deg(n, &[v(d44)]), None);
        assert_eq!(refused_turn_deg(n, &[v(d), v(d2)]), None);
        assert_eq!(refused_turn_deg(n, &[]), None);
    }

    #[test]
    fn snapping_needs_a_unique_feasible_axis_or_the_vertical() {
        let axes = [Vec3::X, Vec3::Y, Vec3::Z].map(|a| a.to_array());
        let n = Vec3::new(0.1, 0.3, 0.95).normalize();
        for vertical in [None, Some(1)] {
            // X in the plane, Y not feasible: Z, oriented like n.
            let got = snap_to_axes(
                n,
                &axes,
                [true, false, false],
                [true, false, true],
                vertical,
            );
            assert_eq!(got, Some(Vec3::Z));
            let got = snap_to_axes(
                -n,
                &axes,
                [true, false, false],
                [true, false, true],
                vertical,
            );
            assert_eq!(got, Some(-Vec3::Z));
            // Two axes in the plane: the third, even far from a poor n (50°).
            let poor = Vec3::new(0.0, 0.77, 0.64).normalize();
            let got = snap_to_axes(
                poor,
                &axes,
                [true, false, true],
                [true, true, true],
                vertical,
            );
            assert_eq!(got, Some(Vec3::Y));
            // No line family, nothing feasible, or too far from n: no snap.
            assert_eq!(
                snap_to_axes(n, &axes, [false; 3], [true; 3], vertical),
                None
            );
            assert_eq!(
                snap_to_axes(
                    n,
                    &axes,
                    [true, false, false],
                    [true, false, false],
                    vertical
                ),
                None
            );
            let far = Vec3::new(0.0, 0.9, 0.3).normalize();
            assert_eq!(
                snap_to_axes(
                    far,
                    &axes,
                    [true, false, false],
                    [true, false, true],
                    vertical
                ),
                None
            );
        }
        // Y and Z both possible: ambiguous without a vertical; with Y the
        // vertical, Y (a floor or ceiling), even where n is closer to Z.
        assert_eq!(
            snap_to_axes(n, &axes, [true, false, false], [true; 3], None),
            None
        );
        assert_eq!(
            snap_to_axes(n, &axes, [true, false, false], [true; 3], Some(1)),
            Some(Vec3::Y)
        );
        assert_eq!(
            snap_to_axes(-n, &axes, [true, false, false], [true; 3], Some(1)),
            Some(-Vec3::Y)
        );
        // The vertical not among the two (a vertical line family: two walls
        // possible), or the vertical in the plane: no snap.
        assert_eq!(
            snap_to_axes(n, &axes, [false, true, false], [true; 3], Some(1)),
            None
        );
        assert_eq!(
            snap_to_axes(n, &axes, [true, false, false], [true; 3], Some(0)),
            None
        );
    }

    #[test]
    fn the_vertical_axis_is_the_one_near_image_up() {
        let tilt = |deg: f32| {
            let r = deg.to_radians();
            [r.sin(), r.cos(), 0.0]
        };
        let axes = [[1.0, 0.0, 0.0], tilt(20.0), [0.0, 0.0, 1.0]];
        assert_eq!(vertical_axis(&axes), Some(1));
        let axes = [[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, -1.0, 0.0]];
        assert_eq!(vertical_axis(&axes), Some(2));
        let axes = [tilt(40.0), tilt(-50.0), [0.0, 0.0, 1.0]];
        assert_eq!(vertical_axis(&axes), None);
    }

    #[test]
    fn focal_and_normal_of_a_checker_plane_are_recovered() {
        let (w, h, f) = (320, 240, 230.0);
        let (n, e1) = oblique();
        let luma = checker_plane(w, h, f, n, e1, 0.25);
        let small = SmallLuma::new(&luma, w, h);
        // The grid's two families are orthogonal: the focal follows.
        let lf = focal_from_lines(&small).expect("a focal from the grid");
        assert!((lf.focal_px / f - 1.0).abs() < 0.04, "{lf:?}");
        // From a normal 25° off, and the true focal: the plane's normal.
        let wrong = (n + 0.47 * n.cross(e1)).normalize();
        assert!(angle_deg(wrong, n) > 20.0);
        let mask = vec![true; w * h];
        let (found, diag) = refine_plane_normal(&small, &mask, wrong, f, None);
        assert!(diag.applied && diag.vanishing.len() == 2, "{diag:?}");
        assert!(angle_deg(found, n) < 2.0, "{}° off", angle_deg(found, n));
        // Without lines in the mask, the normal is kept.
        let (kept, diag) = refine_plane_normal(&small, &vec![false; w * h], wrong, f, None);
        assert_eq!(kept, wrong);
        assert!(!diag.applied && diag.segments == 0);
        assert_eq!(diag.refused_turn_deg, None);
    }

    /// Vertical stripes seen head-on, with a predicted normal saying a floor
    /// (up): their one family (vertical, parallel in the photo) would turn
    /// the normal by 90°; refused, and the refused turn reported.
    #[test]
    fn a_family_that_contradicts_the_predicted_plane_is_reported() {
        let (w, h, f) = (320, 240, 230.0);
        let luma: Vec<f32> = (0..w * h)
            .map(|i| if (i % w / 16) % 2 == 0 { 0.8 } else { 0.2 })
            .collect();
        let small = SmallLuma::new(&luma, w, h);
        let up = Vec3::new(0.0, 1.0, 0.05).normalize();
        let (kept, diag) = refine_plane_normal(&small, &vec![true; w * h], up, f, None);
        assert_eq!(kept, up, "{diag:?}");
        assert!(!diag.applied && diag.vanishing.len() == 1, "{diag:?}");
        let turn = diag.refused_turn_deg.expect("a refused turn");
        assert!(turn > 80.0, "{turn}");
    }
}
