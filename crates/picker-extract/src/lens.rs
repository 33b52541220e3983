//! Radial lens distortion, estimated from the photo's own straight lines.
//!
//! Wide-angle and webcam lenses bend straight lines (barrel distortion: a
//! line away from the centre bows outwards). The plane mode maps photo
//! pixels to rays as through a pinhole, so on such a photo a rectified
//! surface comes out bent: a tiled floor's rows curve, its repeats do not
//! line up, and folding them into one period ([`crate::period`]) smears
//! their edges. This module undoes the bend before any pixel becomes a ray.
//!
//! **The model** is the one-parameter division model (Fitzgibbon 2001),
//! about the photo's centre `c`, with radii in units of the half-diagonal
//! `R` (so that `λ` does not depend on the photo's resolution):
//! `p_u = c + (p_d − c) / (1 + λ ‖p_d − c‖² / R²)`. Barrel distortion has
//! `λ < 0`; `λ = 0` is the pinhole. One parameter describes common lenses
//! closely (OpenCV's calibration of the webcam of its `left*.jpg` samples,
//! `k₁ = −0.27` with `k₂`, `k₃` and an off-centre principal point, is matched
//! by `λ = −0.17` to 0.09 px on average and 0.7 px at most over the part of
//! the photo its chessboard covers, after a homography, which the plane
//! absorbs), and it can be inverted in closed form ([`Lens::distort`]).
//!
//! **The estimate** ([`estimate`]) is a plumb-line fit on the photo's long
//! edges (`lines::edge_regions`, the regions the line segments are
//! fitted to): a straight edge of the scene is straight in the undistorted
//! photo, so each long region's sub-pixel edge points (one per column or
//! row, `edge_points`) give the `λ` that makes them most nearly collinear
//! (the smallest eigenvalue of their weighted scatter, over a grid of `λ`
//! refined by a parabola), and an information weight (that minimum's
//! sharpness times the points over their residual variance). An edge
//! through the centre is straight under any `λ` and weighs nothing; a
//! curved object (a plate's rim, a draped cloth) gives a `λ` of its own.
//! The photo's `λ` is the regions' weighted median, used only when regions
//! at enough places agree with it ([`MIN_AGREEING_REGIONS`],
//! [`MIN_AGREEMENT`]) and it is a clear barrel ([`MIN_BARREL`]): otherwise
//! the photo is taken as undistorted.
//! Assumed: the distortion's centre is the photo's centre (a photo cropped
//! off-centre breaks that), and the lines are straight in the scene (a
//! room's edges, tiles, frames, a keyboard).

use glam::Vec2;
use serde::Serialize;

use crate::lines::{edge_regions, SmallLuma};

/// A radial distortion of a `w × h` photo (see the module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lens {
    /// The division model's coefficient `λ` (radii in half-diagonals).
    pub lambda: f32,
    /// The centre, photo pixels.
    centre: Vec2,
    /// `R²`, `R` the half-diagonal in photo pixels ([`half_diagonal_sq`]).
    r2: f32,
}

/// `R²`, the square of a `w × h` photo's half-diagonal (pixels²): the unit
/// of the division model's radii.
pub fn half_diagonal_sq(w: usize, h: usize) -> f32 {
    (w * w + h * h) as f32 / 4.0
}

/// The division model on an offset `d` from the centre (pixels) of a photo
/// of half-diagonal `√r2`: `d / (1 + λ |d|² / r2)`, where the pinhole would
/// put it. `d` itself, bit for bit, for `λ = 0` (or an empty photo). The one
/// place the model is computed: [`Lens::undistort`] and the plane mode's
/// rays ([`crate::plane::Camera::ray`]) call it.
#[inline]
pub fn divide(d: Vec2, lambda: f32, r2: f32) -> Vec2 {
    if lambda == 0.0 || r2 <= 0.0 {
        return d;
    }
    d / (1.0 + lambda * d.length_squared() / r2)
}

/// The most negative `λ` accepted (given or estimated): a photo's corner
/// moves by a factor `1 / (1 + λ)`, so `λ → −1` sends it to infinity.
pub const LAMBDA_MIN: f32 = -0.6;
/// The most positive `λ` accepted (pincushion distortion is rare and mild).
pub const LAMBDA_MAX: f32 = 0.4;

impl Lens {
    /// The distortion `lambda` of a `w × h` photo.
    ///
    /// # Panics
    /// When `lambda` is not within [`LAMBDA_MIN`]..=[`LAMBDA_MAX`].
    pub fn new(lambda: f32, w: usize, h: usize) -> Self {
        assert!(
            (LAMBDA_MIN..=LAMBDA_MAX).contains(&lambda),
            "lens λ {lambda} outside {LAMBDA_MIN}..={LAMBDA_MAX}"
        );
        Self {
            lambda,
            centre: Vec2::new(w as f32, h as f32) / 2.0,
            r2: half_diagonal_sq(w, h),
        }
    }

    /// A pinhole (no distortion) for a `w × h` photo.
    pub fn pinhole(w: usize, h: usize) -> Self {
        Self::new(0.0, w, h)
    }

    /// True for a pinhole.
    pub fn is_pinhole(&self) -> bool {
        self.lambda == 0.0
    }

    /// Where the photo point `p` (pixels, the photo's own) would lie
    /// through a pinhole. With `λ = 0`, `p` itself, bit for bit.
    #[inline]
    pub fn undistort(&self, p: Vec2) -> Vec2 {
        if self.lambda == 0.0 {
            return p;
        }
        self.centre + divide(p - self.centre, self.lambda, self.r2)
    }

    /// The inverse of [`Lens::undistort`]: the photo point of the pinhole
    /// point `u`. The division model's radius `r_u = r_d / (1 + λ r_d²)`
    /// solved for `r_d` (the root that is continuous at `λ = 0`); `None`
    /// where no photo point maps to `u` (for `λ > 0`, beyond the largest
    /// radius the lens reaches, `R / (2√λ)`).
    pub fn distort(&self, u: Vec2) -> Option<Vec2> {
        if self.lambda == 0.0 {
            return Some(u);
        }
        let d = u - self.centre;
        if self.r2 <= 0.0 {
            return Some(u);
        }
        let ru = d.length() / self.r2.sqrt();
        if ru == 0.0 {
            return Some(u);
        }
        // λ ru rd² − rd + ru = 0, rd = (1 − √(1 − 4 λ ru²)) / (2 λ ru).
        let disc = 1.0 - 4.0 * self.lambda * ru * ru;
        if disc < 0.0 {
            return None;
        }
        let rd = 2.0 * ru / (1.0 + disc.sqrt());
        Some(self.centre + d * (rd / ru))
    }

    /// How far (pixels) the undistortion moves the photo's corners: a
    /// reading of how strong the distortion is.
    pub fn corner_shift_px(&self) -> f32 {
        let corner = self.centre * 2.0;
        (self.undistort(corner) - corner).length()
    }
}

/// Grid step of the per-region `λ` search.
pub const LAMBDA_STEP: f32 = 0.01;
/// Shortest region taken (its length over the half-diagonal).
pub const MIN_REGION_LENGTH: f32 = 0.12;
/// Fewest pixels of a region taken.
pub const MIN_REGION_PIXELS: usize = 24;
/// Fewest edge points (columns or rows) of a region taken.
pub const MIN_EDGE_POINTS: usize = 16;
/// Pixels this close to the photo's border (a share of its shorter side,
/// at least [`BORDER_MARGIN_PX`] downsampled pixels) take no part.
pub const BORDER_MARGIN: f32 = 0.015;
/// See [`BORDER_MARGIN`].
pub const BORDER_MARGIN_PX: usize = 4;
/// The least residual (pixels) a region's weight assumes: edges are not
/// located more finely than this, however straight their points lie.
pub const WIDTH_FLOOR_PX: f32 = 0.1;
/// A region agrees with the photo's `λ` when its own is within this much.
pub const AGREEMENT_TOLERANCE: f32 = 0.04;
/// ... or within this share of the median's size, when that is more (a
/// strong distortion's regions scatter more: OpenCV's `left11.jpg`,
/// −0.16 … −0.24 about −0.22).
pub const AGREEMENT_SHARE: f32 = 0.25;
/// Share of the information weight that must agree with the median.
pub const MIN_AGREEMENT: f32 = 0.6;
/// Fewest agreeing regions, counted once per place ([`MIN_SEPARATION`]).
pub const MIN_AGREEING_REGIONS: usize = 3;
/// Agreeing regions whose centroids lie closer than this (a share of the
/// half-diagonal) count as one: the two sides of one stripe, the pieces
/// of one curved object.
pub const MIN_SEPARATION: f32 = 0.1;
/// The weakest barrel distortion estimated: a median `λ` above `−MIN_BARREL`
/// (it moves the corners by under 5 % of the half-diagonal, and a
/// rectified plane bends by less than a few pixels) is taken as none, and
/// so is any pincushion (`λ > 0`). Curved things in a scene give both
/// signs, while the lenses that bend lines visibly (wide angles, webcams,
/// action cameras) bend them as barrels. Measured with
/// `examples/lens_probe.rs`: on the 160 synthetic (pinhole) scenes of
/// three `picker synth` sets and a set of wide views, none (one median
/// passed the other tests, at −0.035); on 25 of the 26 calibration photos
/// of OpenCV's samples (`left*.jpg`, `right*.jpg`) −0.157 to −0.223 (their
/// calibration, fitted by this model over the board's part of the photo:
/// −0.17); on the other 65 sample photos none but `right.jpg`'s −0.073.
pub const MIN_BARREL: f32 = 0.05;

/// One long edge region's own `λ` ([`estimate`]).
#[derive(Clone, Copy, Debug, Serialize)]
pub struct ArcFit {
    /// The `λ` that makes it straightest.
    pub lambda: f32,
    /// Its information weight (inverse variance of `lambda`, up to a
    /// common factor).
    pub weight: f32,
    /// Edge points it gave (columns or rows of the downsampled photo).
    pub points: usize,
    /// Its residual: RMS distance (downsampled pixels) of its edge points
    /// from their line at `lambda`.
    pub width_px: f32,
    /// Its weighted centroid (downsampled pixels, pinhole).
    pub centroid: [f32; 2],
    /// Its length (downsampled pixels).
    pub length_px: f32,
}

/// What the estimate found (`material.json`, `diagnostics.uv.lens`).
#[derive(Clone, Debug, Serialize)]
pub struct LensEstimate {
    /// The coefficient used (0 when none).
    pub lambda: f32,
    /// Where it came from: `"lines"` (estimated), `"given"` (the user's),
    /// `"none"` (no distortion found or asked).
    pub source: &'static str,
    /// The regions' weighted median, used or not (`None` without regions).
    pub median: Option<f32>,
    /// Long edge regions that gave a `λ`.
    pub regions: usize,
    /// Of them, those within [`AGREEMENT_TOLERANCE`] (or [`AGREEMENT_SHARE`])
    /// of the median, counted once per place ([`MIN_SEPARATION`]).
    pub agreeing: usize,
    /// Their share of the information weight.
    pub agreement: f32,
    /// How far the undistortion moves the photo's corners (photo pixels).
    pub corner_shift_px: f32,
}

impl LensEstimate {
    /// A given `λ` (none estimated).
    pub fn given(lens: &Lens) -> Self {
        Self {
            lambda: lens.lambda,
            source: if lens.is_pinhole() { "none" } else { "given" },
            median: None,
            regions: 0,
            agreeing: 0,
            agreement: 0.0,
            corner_shift_px: lens.corner_shift_px(),
        }
    }
}

/// The smallest eigenvalue of the weighted scatter of the points
/// `q / (1 + λ |q|²)`, over the square of their weighted mean scale (so
/// that shrinking the points does not make them look straighter).
fn straightness(q: &[(Vec2, f32)], lambda: f32) -> f64 {
    let (mut sw, mut sx, mut sy, mut ss) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
    let (mut sxx, mut sxy, mut syy) = (0.0f64, 0.0f64, 0.0f64);
    for &(p, m) in q {
        let s = 1.0 / (1.0 + lambda * p.length_squared()) as f64;
        let (x, y, m) = (p.x as f64 * s, p.y as f64 * s, m as f64);
        sw += m;
        ss += m * s;
        sx += m * x;
        sy += m * y;
        sxx += m * x * x;
        sxy += m * x * y;
        syy += m * y * y;
    }
    let (mx, my) = (sx / sw, sy / sw);
    let (cxx, cxy, cyy) = (sxx / sw - mx * mx, sxy / sw - mx * my, syy / sw - my * my);
    let half_trace = 0.5 * (cxx + cyy);
    let det = cxx * cyy - cxy * cxy;
    let small = half_trace - (half_trace * half_trace - det).max(0.0).sqrt();
    let scale = ss / sw;
    small.max(0.0) / (scale * scale)
}

/// The `λ` of one region (`q`: its edge points relative to the centre in
/// half-diagonals, with their weights; `centre` and `r_px` the centre and
/// half-diagonal in downsampled pixels), or `None` when its straightest `λ`
/// lies at the end of the searched range (a curved object).
fn arc_fit(q: &[(Vec2, f32)], r_px: f32, centre: Vec2) -> Option<ArcFit> {
    let steps = ((LAMBDA_MAX - LAMBDA_MIN) / LAMBDA_STEP).round() as usize;
    let at = |i: usize| LAMBDA_MIN + i as f32 * LAMBDA_STEP;
    let e: Vec<f64> = (0..=steps).map(|i| straightness(q, at(i))).collect();
    let (best, _) = e.iter().enumerate().min_by(|a, b| a.1.total_cmp(b.1))?;
    if best == 0 || best == steps {
        return None;
    }
    let (l, c, r) = (e[best - 1], e[best], e[best + 1]);
    let curv = l + r - 2.0 * c;
    let offset = if curv > 0.0 {
        0.5 * (l - r) / curv
    } else {
        0.0
    };
    let lambda = at(best) + offset as f32 * LAMBDA_STEP;
    // Sharpness per point (second difference in λ units) times the points
    // over the residual variance (at least WIDTH_FLOOR_PX squared): the
    // inverse variance of λ up to a common factor.
    let step = LAMBDA_STEP as f64;
    let floor = (WIDTH_FLOOR_PX as f64 / r_px as f64).powi(2);
    let weight = q.len() as f64 * (curv / (step * step)) / c.max(floor);
    let sw: f32 = q.iter().map(|p| p.1).sum();
    let mean = q.iter().map(|&(p, m)| p * m).sum::<Vec2>() / sw;
    let (lo, hi) = q.iter().fold((Vec2::MAX, Vec2::MIN), |(lo, hi), &(p, _)| {
        (lo.min(p), hi.max(p))
    });
    Some(ArcFit {
        lambda,
        weight: weight as f32,
        points: q.len(),
        width_px: (c.sqrt() * r_px as f64) as f32,
        centroid: (centre + mean * r_px).to_array(),
        length_px: (hi - lo).length() * r_px,
    })
}

/// The edge's points along a region of pixels: one per column the region
/// spans (per row when it runs closer to vertical), where the photo's
/// values step from one side's level to the other's. The position is the
/// step's area: with `a` and `b` the levels two pixels beyond the region on
/// either side, the window from one pixel before the region to one after
/// holds `Σ (v − b) / (a − b)` pixels of `a`'s side. Exact for a step
/// sampled by pixel areas and unchanged by any symmetric blur, it locates
/// an edge to a small fraction of a pixel where the centroid of the
/// gradient locks to pixel centres. Weighted by the step's contrast; the
/// outermost columns, cut obliquely by the region's growth, are dropped.
fn edge_points(region: &[usize], luma: &[f32], w: usize, h: usize) -> Vec<(Vec2, f32)> {
    // The region's extent along its columns (rows): per column, the first
    // and last row it holds.
    let (mut x0, mut x1, mut y0, mut y1) = (usize::MAX, 0, usize::MAX, 0);
    for &i in region {
        let (x, y) = (i % w, i / w);
        (x0, x1, y0, y1) = (x0.min(x), x1.max(x), y0.min(y), y1.max(y));
    }
    let by_column = x1 - x0 >= y1 - y0;
    let (first, len, across_len) = if by_column {
        (x0, x1 - x0 + 1, h)
    } else {
        (y0, y1 - y0 + 1, w)
    };
    let mut span = vec![(usize::MAX, 0usize); len];
    for &i in region {
        let (x, y) = (i % w, i / w);
        let (along, across) = if by_column { (x, y) } else { (y, x) };
        let s = &mut span[along - first];
        *s = (s.0.min(across), s.1.max(across));
    }
    let at = |along: usize, across: usize| {
        if by_column {
            luma[across * w + along]
        } else {
            luma[along * w + across]
        }
    };
    let mut out = Vec::with_capacity(len);
    for (k, &(lo, hi)) in span.iter().enumerate() {
        if k == 0 || k + 1 == len || lo == usize::MAX || lo < 3 || hi + 3 >= across_len {
            continue;
        }
        let along = first + k;
        let a = 0.5 * (at(along, lo - 3) + at(along, lo - 2));
        let b = 0.5 * (at(along, hi + 2) + at(along, hi + 3));
        if (a - b).abs() < crate::lines::MIN_GRADIENT {
            continue;
        }
        let side_a: f32 = (lo - 1..=hi + 1)
            .map(|c| ((at(along, c) - b) / (a - b)).clamp(0.0, 1.0))
            .sum();
        let edge = (lo - 1) as f32 + side_a;
        let p = if by_column {
            Vec2::new(along as f32 + 0.5, edge)
        } else {
            Vec2::new(edge, along as f32 + 0.5)
        };
        out.push((p, (a - b).abs()));
    }
    out
}

/// The `λ` of each long edge region of the downsampled photo `small`.
pub fn arc_fits(small: &SmallLuma) -> Vec<ArcFit> {
    let (w, h) = (small.w, small.h);
    let (fw, fh) = small.full;
    let k = small.k as f32;
    let centre = Vec2::new(fw as f32, fh as f32) / (2.0 * k);
    let r_px = ((fw * fw + fh * fh) as f32).sqrt() / (2.0 * k);
    // The photo's own frame (a scanner's or camera's border, a vignette's
    // edge) is straight in the image, not in the scene: pixels near the
    // border take no part.
    let margin = BORDER_MARGIN_PX.max((BORDER_MARGIN * w.min(h) as f32).round() as usize);
    let inside: Vec<bool> = (0..w * h)
        .map(|i| {
            let (x, y) = (i % w, i / w);
            x >= margin && y >= margin && x + margin < w && y + margin < h
        })
        .collect();
    let mut regions: Vec<Vec<(Vec2, f32)>> = Vec::new();
    edge_regions(&small.luma, &inside, w, h, |region, _| {
        if region.len() < MIN_REGION_PIXELS {
            return;
        }
        let q: Vec<(Vec2, f32)> = edge_points(region, &small.luma, w, h)
            .into_iter()
            .map(|(p, m)| ((p - centre) / r_px, m))
            .collect();
        if q.len() < MIN_EDGE_POINTS {
            return;
        }
        // Its extent along its principal direction (pinhole).
        let (lo, hi) = q.iter().fold((Vec2::MAX, Vec2::MIN), |(lo, hi), &(p, _)| {
            (lo.min(p), hi.max(p))
        });
        if (hi - lo).length() < MIN_REGION_LENGTH {
            return;
        }
        regions.push(q);
    });
    use rayon::prelude::*;
    regions
        .par_iter()
        .filter_map(|q| arc_fit(q, r_px, centre))
        .collect()
}

/// The photo's distortion from its straight lines (see the module docs),
/// for a photo of the size `small` was made from.
pub fn estimate(small: &SmallLuma) -> (Lens, LensEstimate) {
    let (fw, fh) = small.full;
    let fits = arc_fits(small);
    let pinhole = Lens::pinhole(fw, fh);
    let mut est = LensEstimate {
        lambda: 0.0,
        source: "none",
        median: None,
        regions: fits.len(),
        agreeing: 0,
        agreement: 0.0,
        corner_shift_px: 0.0,
    };
    let total: f64 = fits.iter().map(|f| f.weight as f64).sum();
    if fits.is_empty() || total <= 0.0 {
        return (pinhole, est);
    }
    let mut order: Vec<&ArcFit> = fits.iter().collect();
    order.sort_by(|a, b| a.lambda.total_cmp(&b.lambda));
    let mut acc = 0.0f64;
    let mut median = order[order.len() - 1].lambda;
    for f in &order {
        acc += f.weight as f64;
        if acc >= 0.5 * total {
            median = f.lambda;
            break;
        }
    }
    let agree: Vec<&&ArcFit> = order
        .iter()
        .filter(|f| {
            (f.lambda - median).abs() <= AGREEMENT_TOLERANCE.max(AGREEMENT_SHARE * median.abs())
        })
        .collect();
    let agreement = (agree.iter().map(|f| f.weight as f64).sum::<f64>() / total) as f32;
    // Agreeing regions count once per place: the two sides of one stripe,
    // or the pieces of one curved object, are one piece of evidence.
    let min_gap = MIN_SEPARATION * ((fw * fw + fh * fh) as f32).sqrt() / (2.0 * small.k as f32);
    let mut places: Vec<Vec2> = Vec::new();
    for f in &agree {
        let c = Vec2::from(f.centroid);
        if places.iter().all(|p| (*p - c).length() >= min_gap) {
            places.push(c);
        }
    }
    est.median = Some(median);
    est.agreeing = places.len();
    est.agreement = agreement;
    let lens = Lens::new(median.clamp(LAMBDA_MIN, LAMBDA_MAX), fw, fh);
    if places.len() >= MIN_AGREEING_REGIONS && agreement >= MIN_AGREEMENT && median <= -MIN_BARREL {
        est.lambda = lens.lambda;
        est.source = "lines";
        est.corner_shift_px = lens.corner_shift_px();
        (lens, est)
    } else {
        (pinhole, est)
    }
}

/// A `w × h` test photo for the lens estimate: `lines` straight edges
/// (half-planes through seeded points at seeded angles, each adding
/// `0.7 / lines` of light to a floor of 0.15, so luma lies in [0.15, 0.85])
/// seen through `lens`, each pixel the mean of 4 × 4 samples. The same
/// `seed` gives the same picture. Used by this module's tests and the CLI's.
pub fn straight_edges_photo(lens: &Lens, w: usize, h: usize, lines: usize, seed: u64) -> Vec<f32> {
    photo_through(w, h, lens, &straight_edges_scene(w, h, lines, seed))
}

/// A `w × h` luma image whose pinhole picture is `scene(x, y)` (pinhole
/// pixels), seen through `lens`: each pixel is the mean of 4 × 4 samples,
/// each sample's point undistorted before `scene` reads it.
fn photo_through(w: usize, h: usize, lens: &Lens, scene: &dyn Fn(f32, f32) -> f32) -> Vec<f32> {
    (0..w * h)
        .map(|i| {
            let (x, y) = ((i % w) as f32, (i / w) as f32);
            let mut acc = 0.0;
            for k in 0..16 {
                let p = Vec2::new(
                    x + (k % 4) as f32 / 4.0 + 0.125,
                    y + (k / 4) as f32 / 4.0 + 0.125,
                );
                let u = lens.undistort(p);
                acc += scene(u.x, u.y);
            }
            acc / 16.0
        })
        .collect()
}

/// The pinhole picture of [`straight_edges_photo`]: `lines` half-planes
/// through seeded points at seeded angles, each adding a step of light.
fn straight_edges_scene(w: usize, h: usize, lines: usize, seed: u64) -> impl Fn(f32, f32) -> f32 {
    let mut rng = picker_tensor::Rng::new(seed);
    let edges: Vec<(Vec2, f32)> = (0..lines)
        .map(|_| {
            let a = rng.uniform(0.0, std::f32::consts::PI);
            let n = Vec2::new(a.cos(), a.sin());
            let p = Vec2::new(
                rng.uniform(0.1, 0.9) * w as f32,
                rng.uniform(0.1, 0.9) * h as f32,
            );
            (n, n.dot(p))
        })
        .collect();
    let step = 0.7 / lines.max(1) as f32;
    move |x, y| {
        let p = Vec2::new(x, y);
        0.15 + edges
            .iter()
            .map(|&(n, d)| if n.dot(p) > d { step } else { 0.0 })
            .sum::<f32>()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use picker_tensor::Rng;

    fn estimate_of(w: usize, h: usize, luma: &[f32]) -> (Lens, LensEstimate) {
        estimate(&SmallLuma::new(luma, w, h))
    }

    #[test]
    fn undistort_and_distort_are_inverse() {
        let (w, h) = (640, 480);
        for lambda in [-0.5f32, -0.17, -0.02, 0.0, 0.1, 0.4] {
            let lens = Lens::new(lambda, w, h);
            for (x, y) in [
                (0.0, 0.0),
                (320.0, 240.0),
                (639.5, 10.0),
                (100.0, 470.0),
                (333.0, 250.0),
            ] {
                let p = Vec2::new(x, y);
                let u = lens.undistort(p);
                let back = lens.distort(u).expect("within the lens");
                assert!((back - p).length() < 1e-2, "λ {lambda}: {p} → {u} → {back}");
            }
        }
        // A pinhole moves nothing, bit for bit.
        let p = Vec2::new(12.345, 67.89);
        assert_eq!(Lens::pinhole(w, h).undistort(p), p);
        assert_eq!(Lens::pinhole(w, h).distort(p), Some(p));
        // Barrel: the corners move out by 1/(1 + λ). Pincushion: a pinhole
        // point past the lens' largest radius (R / (2√λ)) has no photo point.
        let barrel = Lens::new(-0.2, w, h);
        assert!((barrel.corner_shift_px() - 400.0 * (1.0 / 0.8 - 1.0)).abs() < 0.1);
        assert!(barrel.distort(Vec2::new(320.0 + 4000.0, 240.0)).is_some());
        let pincushion = Lens::new(0.25, w, h);
        assert_eq!(pincushion.distort(Vec2::new(320.0 + 401.0, 240.0)), None);
        assert!(pincushion
            .distort(Vec2::new(320.0 + 399.0, 240.0))
            .is_some());
    }

    #[test]
    #[should_panic(expected = "outside")]
    fn a_lambda_out_of_range_panics() {
        Lens::new(-0.9, 10, 10);
    }

    #[test]
    fn barrel_distortion_of_straight_edges_is_found() {
        let (w, h) = (320, 240);
        for (seed, truth) in [(1u64, -0.15f32), (2, -0.08), (3, -0.3), (4, -0.06)] {
            let luma = straight_edges_photo(&Lens::new(truth, w, h), w, h, 10, seed);
            let (lens, est) = estimate_of(w, h, &luma);
            assert_eq!(est.source, "lines", "seed {seed}: {est:?}");
            assert!(
                (lens.lambda - truth).abs() < 0.02,
                "seed {seed} truth {truth}: {est:?}"
            );
            assert_eq!(est.lambda, lens.lambda);
            assert!(est.agreeing >= MIN_AGREEING_REGIONS && est.agreement >= MIN_AGREEMENT);
        }
    }

    #[test]
    fn straight_edges_through_a_pinhole_give_none() {
        let (w, h) = (320, 240);
        for seed in 1..=4u64 {
            let luma = straight_edges_photo(&Lens::pinhole(w, h), w, h, 10, seed);
            let (lens, est) = estimate_of(w, h, &luma);
            assert!(lens.is_pinhole(), "seed {seed}: {est:?}");
            assert_eq!(est.source, "none");
            // The regions themselves say so.
            let m = est.median.expect("regions");
            assert!(m.abs() < 0.02, "seed {seed}: {est:?}");
        }
    }

    #[test]
    fn pincushion_and_weak_barrels_are_not_estimated() {
        let (w, h) = (320, 240);
        for truth in [0.15f32, -0.035] {
            let luma = straight_edges_photo(&Lens::new(truth, w, h), w, h, 10, 5);
            let (lens, est) = estimate_of(w, h, &luma);
            // The regions see it, the estimate does not take it.
            assert!(
                (est.median.unwrap() - truth).abs() < 0.02,
                "{truth}: {est:?}"
            );
            assert!(lens.is_pinhole(), "{truth}: {est:?}");
        }
    }

    #[test]
    fn curved_objects_and_flat_photos_give_none() {
        let (w, h) = (320, 240);
        let mut rng = Rng::new(11);
        let discs: Vec<(Vec2, f32)> = (0..12)
            .map(|_| {
                (
                    Vec2::new(rng.uniform(0.0, w as f32), rng.uniform(0.0, h as f32)),
                    rng.uniform(15.0, 90.0),
                )
            })
            .collect();
        let scene = |x: f32, y: f32| {
            0.2 + 0.05
                * discs
                    .iter()
                    .filter(|(c, r)| (Vec2::new(x, y) - *c).length() < *r)
                    .count() as f32
        };
        let luma = photo_through(w, h, &Lens::pinhole(w, h), &scene);
        let (lens, est) = estimate_of(w, h, &luma);
        assert!(lens.is_pinhole(), "{est:?}");
        // No edges at all; a photo smaller than a segment.
        let (lens, est) = estimate_of(w, h, &vec![0.5; w * h]);
        assert!(lens.is_pinhole() && est.regions == 0 && est.median.is_none());
        let (lens, _) = estimate_of(2, 1, &[0.0, 1.0]);
        assert!(lens.is_pinhole());
    }

    #[test]
    fn the_frame_of_the_photo_is_no_line() {
        // A barrel-distorted scene inside a dark frame drawn on the photo
        // (not through the lens): the frame's straight edges must not vote
        // for a pinhole.
        let (w, h) = (320, 240);
        let mut luma = straight_edges_photo(&Lens::new(-0.15, w, h), w, h, 10, 1);
        for (i, v) in luma.iter_mut().enumerate() {
            let (x, y) = (i % w, i / w);
            if x < 3 || y < 3 || x + 3 >= w || y + 3 >= h {
                *v = 0.0;
            }
        }
        let (lens, est) = estimate_of(w, h, &luma);
        assert!((lens.lambda + 0.15).abs() < 0.02, "{est:?}");
    }

    #[test]
    fn the_estimate_does_not_depend_on_the_resolution() {
        // The same scene at 320×240 and at 1600×1200 (downsampled by 2 to
        // the segments' 800): λ is in half-diagonals, so the same.
        let truth = -0.15;
        let scene_small = straight_edges_scene(320, 240, 10, 2);
        let small = photo_through(320, 240, &Lens::new(truth, 320, 240), &scene_small);
        let (a, _) = estimate_of(320, 240, &small);
        let big = photo_through(1600, 1200, &Lens::new(truth, 1600, 1200), &|x, y| {
            scene_small(x / 5.0, y / 5.0)
        });
        let (b, est) = estimate_of(1600, 1200, &big);
        assert!(
            (a.lambda - truth).abs() < 0.02 && (b.lambda - truth).abs() < 0.02,
            "{a:?} {b:?} {est:?}"
        );
    }
}
