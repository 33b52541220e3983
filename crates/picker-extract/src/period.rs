//! The repeat of a periodic texture (tiles, bricks, planks, a checker) in a
//! rectified plane, so that the plane mode can fold every repeat it sees into
//! one tile, as the networks' wrapped UVs do.
//!
//! The plane mode rectifies the whole picked region: a tiled floor comes out
//! as a picture of the floor, dozens of tiles across, its far tiles blurred.
//! When the rectified texture repeats along both of its axes (the axes follow
//! the region's lines, [`crate::plane::plane_basis`], so a tile grid is
//! aligned with them), [`detect`] measures the two periods and the pipeline
//! wraps the plane coordinates by them: every observed repeat then lands in
//! the same tile, which comes out sharp, complete and tileable by
//! construction.
//!
//! **Method.** On the luma of the reprojected texture's known texels (box-
//! downsampled to at most [`MAX_SIDE`] texels), each row's mean removed for
//! the `x` axis (each column's for `y`: a grid's lines across the axis
//! would correlate at every shift; when that shows no period, each row's
//! linear trend, a drift of shading, is removed instead), the normalised
//! autocorrelation along
//! the axis, `r(d)` for shifts `d` up to half the side in steps of
//! 1/[`SUBSTEPS`] texel: the Pearson correlation of the known texel pairs
//! `d` apart, both sides interpolated by half the fractional shift so they
//! are equally smooth. The period is the first local maximum of `r` that
//! reaches [`MIN_WEAK_PEAK`] after `r` has fallen at least [`MIN_DIP`] below
//! it (a repeat, not the slow decay of a smooth texture) and is at least
//! [`FIRST_PEAK_SHARE`] of the highest such maximum (the fundamental, not a
//! subharmonic of a weaker in-between repeat). It is refined to a fraction
//! of a shift step by a parabola through its neighbours, then by the
//! farthest multiple `k·p` whose peak still reaches [`HARMONIC_SHARE`] of
//! the period's (`p = d_k / k`: the error of one peak divided by `k`). A
//! peak below [`MIN_PEAK`] (tiles or bricks of varied colour, whose grout
//! alone repeats exactly) counts only with its multiple at `2·p`. A shift
//! needs [`MIN_PAIR_SHARE`] of the known texels paired.
//!
//! Measured with `picker eval DIR --uv plane` (ground-truth elements, the
//! plane mode alone), mean aligned texture PSNR of the textured materials:
//! seed 4242 25.67 → 27.03 dB (17 of 76 folded), seed 9191 25.38 → 26.91
//! dB (22 of 78), seed 5151 (photographic textures) 25.38 → 26.16 dB (14 of
//! 72), none worse by more than 0.1 dB; a folded brick wall went from 15.7
//! to 33.3 dB.
//!
//! **Centred repeats.** A checkerboard, bricks in running bond, staggered
//! planks and half-drop wallpapers also repeat when shifted by half a
//! period along both axes at once ([`centring`], measured on the same
//! luma, sRGB-encoded, by the agreement `R²` of the texture and its shifted
//! self, which unlike a correlation also asks for equal values). Their
//! tile then holds each element twice (a chessboard's 2 × 2-square tile,
//! two black squares), and the fold splats every pixel at both places
//! ([`crate::reproject::reproject_centred`], one robust fit), so a place
//! no surest pixel showed (the chessboard's second black square, when the
//! pick's colour took the first) is seen there too.

use picker_render::io::Image;
use rayon::prelude::*;

use crate::reproject::Coords;

/// Largest side the autocorrelation is measured on (the texture is box-
/// downsampled by a whole factor to fit).
pub const MAX_SIDE: usize = 256;
/// Normalised autocorrelation from which a period's peak stands alone.
pub const MIN_PEAK: f32 = 0.5;
/// Least normalised autocorrelation of a period's peak: below
/// [`MIN_PEAK`] (tiles or bricks of varied colour, whose grout or mortar
/// alone repeats exactly) it needs a peak at twice the shift too.
pub const MIN_WEAK_PEAK: f32 = 0.25;
/// A multiple `k·p` of the period confirms or refines it when its peak
/// reaches this share of the period's.
pub const HARMONIC_SHARE: f32 = 0.5;
/// Least fall of the autocorrelation between shift 0 and the peak.
pub const MIN_DIP: f32 = 0.2;
/// The period's peak is at least this share of the highest qualifying peak.
pub const FIRST_PEAK_SHARE: f32 = 0.85;
/// Least share of the known texels paired at a shift for it to count.
pub const MIN_PAIR_SHARE: f32 = 0.2;
/// Shortest period, in texels of the measured (downsampled) texture.
pub const MIN_PERIOD: usize = 3;
/// Shifts per texel at which the autocorrelation is measured (the shifted
/// side interpolated linearly): a period that is not a whole number of
/// texels still lines a sharp pattern up with itself at some shift.
pub const SUBSTEPS: usize = 4;

/// A repeat along one axis of a texture.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct AxisPeriod {
    /// The period in texels of the texture given to [`detect`].
    pub texels: f32,
    /// The normalised autocorrelation at the period's peak.
    pub strength: f32,
    /// The normalised autocorrelation at the peak of twice the period,
    /// when there is one (it confirms a weak period; far above the
    /// period's own, it says the true period is the double: a running bond
    /// measured across its courses).
    pub double: Option<f32>,
}

/// The periods of `tex` (any channels, the first three as linear RGB, one as
/// grey) along `x` and along `y`, measured on its `known` texels; `None` for
/// an axis without a clear repeat (see the module docs).
///
/// # Panics
/// When `known` is not one flag per texel.
pub fn detect(tex: &Image, known: &[bool]) -> (Option<AxisPeriod>, Option<AxisPeriod>) {
    let (w, h) = (tex.width, tex.height);
    assert_eq!(
        known.len(),
        w * h,
        "period::detect: one known flag per texel"
    );
    let Some(LumaGrid {
        luma,
        ok,
        w: sw,
        h: sh,
        f,
    }) = LumaGrid::new(tex, known)
    else {
        return (None, None);
    };
    let scale = f as f32 / SUBSTEPS as f32;
    let along = |dx: usize, dy: usize, n: usize| {
        // What does not vary along the axis (a tile grid's grout lines
        // across it) correlates at every shift: each line's mean is removed,
        // and when that shows no period, each line's linear trend too (a
        // drift of shading along the axis that hides a weak repeat).
        [false, true].into_iter().find_map(|trend| {
            let v = without_line_trends(&luma, &ok, sw, sh, dy, trend);
            let grid = Grid {
                v: &v,
                ok: &ok,
                w: sw,
                h: sh,
            };
            let r = autocorrelation(grid, (dx, dy), n * SUBSTEPS);
            period_of(&r).map(|p| AxisPeriod {
                texels: p.texels * scale,
                ..p
            })
        })
    };
    (along(1, 0, sw / 2), along(0, 1, sh / 2))
}

/// The luma of a texture's known texels, box-downsampled by a whole factor
/// `f` to at most [`MAX_SIDE`] texels a side (a block is known when all its
/// texels are): what [`detect`] and [`snap_repeats`] measure on.
struct LumaGrid {
    luma: Vec<f32>,
    ok: Vec<bool>,
    w: usize,
    h: usize,
    f: usize,
}

impl LumaGrid {
    /// `None` for an empty texture (or one smaller than the factor).
    fn new(tex: &Image, known: &[bool]) -> Option<LumaGrid> {
        let (w, h) = (tex.width, tex.height);
        if w == 0 || h == 0 || tex.channels == 0 {
            return None;
        }
        let f = w.max(h).div_ceil(MAX_SIDE).max(1);
        let (sw, sh) = (w / f, h / f);
        if sw == 0 || sh == 0 {
            return None;
        }
        let mut luma = vec![0.0f32; sw * sh];
        let mut ok = vec![false; sw * sh];
        for by in 0..sh {
            for bx in 0..sw {
                let (mut sum, mut all) = (0.0f32, true);
                for y in by * f..(by + 1) * f {
                    for x in bx * f..(bx + 1) * f {
                        let i = y * w + x;
                        all &= known[i];
                        sum += texel_luma(tex, i);
                    }
                }
                luma[by * sw + bx] = sum / (f * f) as f32;
                ok[by * sw + bx] = all;
            }
        }
        Some(LumaGrid {
            luma,
            ok,
            w: sw,
            h: sh,
            f,
        })
    }
}

/// `v` with the mean (`trend == false`) or the least-squares line (`true`)
/// of the known values of each row (`by_column == 0`) or column
/// (`by_column == 1`) subtracted, along that row or column (on a `w × h`
/// grid): what does not vary along the axis, and a steady drift along it
/// (shading the de-lighting left), would otherwise correlate at every shift.
fn without_line_trends(
    v: &[f32],
    ok: &[bool],
    w: usize,
    h: usize,
    by_column: usize,
    trend: bool,
) -> Vec<f32> {
    let (lines, along) = if by_column == 1 { (w, h) } else { (h, w) };
    let index = |line: usize, k: usize| {
        if by_column == 1 {
            k * w + line
        } else {
            line * w + k
        }
    };
    let mut out = v.to_vec();
    for line in 0..lines {
        let (mut n, mut sk, mut sv, mut skk, mut skv) = (0.0f64, 0.0, 0.0, 0.0, 0.0);
        for k in 0..along {
            let i = index(line, k);
            if ok[i] {
                let (x, y) = (k as f64, f64::from(v[i]));
                n += 1.0;
                sk += x;
                sv += y;
                skk += x * x;
                skv += x * y;
            }
        }
        if n == 0.0 {
            continue;
        }
        let den = n * skk - sk * sk;
        let slope = if trend && den > 1e-9 {
            (n * skv - sk * sv) / den
        } else {
            0.0
        };
        let icpt = (sv - slope * sk) / n;
        for k in 0..along {
            out[index(line, k)] -= (icpt + slope * k as f64) as f32;
        }
    }
    out
}

/// Luma of texel `i` (Rec. 709 weights on the first three channels; the
/// first channel when there are fewer).
fn texel_luma(tex: &Image, i: usize) -> f32 {
    if tex.channels >= 3 {
        crate::pipeline::luminance(tex.rgb(i))
    } else {
        tex.data[i]
    }
}

/// `r[d]` for `d = 0 … n` along the step `(dx, dy)` (one of them 1, the
/// other 0) on a `w × h` grid: the Pearson correlation of the known pairs
/// `(p, p + (d / SUBSTEPS)·step)`, both sides interpolated linearly (the
/// texels used all known); NaN where fewer than
/// [`MIN_PAIR_SHARE`] of the known texels are paired or either side is
/// constant.
fn autocorrelation(g: Grid<'_>, (dx, dy): (usize, usize), n: usize) -> Vec<f32> {
    let least = least_pairs(g.ok);
    // Shifts in parallel, each summed alone: the same bits for any thread count.
    (0..=n)
        .into_par_iter()
        .map(|d| correlation_at(g, (dx, dy), d, least))
        .collect()
}

/// Values on a `w × h` grid with the flags of the known ones, as
/// [`autocorrelation`] and [`correlation_at`] read them.
#[derive(Clone, Copy)]
struct Grid<'a> {
    v: &'a [f32],
    ok: &'a [bool],
    w: usize,
    h: usize,
}

/// Known pairs a shift needs: [`MIN_PAIR_SHARE`] of the known texels, at
/// least 8.
fn least_pairs(ok: &[bool]) -> usize {
    let known = ok.iter().filter(|&&k| k).count();
    ((MIN_PAIR_SHARE * known as f32).ceil() as usize).max(8)
}

/// One shift `d` (in 1/[`SUBSTEPS`] texels) of [`autocorrelation`]: the
/// Pearson correlation of the known pairs, NaN with fewer than `least` of
/// them or a constant side.
fn correlation_at(g: Grid<'_>, (dx, dy): (usize, usize), d: usize, least: usize) -> f32 {
    let Grid { v, ok, w, h } = g;
    let (whole, part) = (d / SUBSTEPS, (d % SUBSTEPS) as f32 / SUBSTEPS as f32);
    // Both sides are interpolated by half the fractional shift, in
    // opposite directions (`a` at `p − part/2`, `b` at `p + whole +
    // part/2`), so they are equally smooth: a sharp pattern aligned
    // with itself still correlates fully at any fractional shift.
    let t = 0.5 * part;
    let frac = usize::from(part > 0.0);
    // `a` needs its texel and, when fractional, the one before; `b`
    // its texel and the one after.
    let span = whole + frac;
    if (dx > 0 && span + frac >= w) || (dy > 0 && span + frac >= h) {
        return f32::NAN;
    }
    let step = dy * w + dx;
    let (x0, y0) = (frac * dx, frac * dy);
    let (x1, y1) = (w - span * dx, h - span * dy);
    let mut sums = PairSums::default();
    for y in y0..y1 {
        for x in x0..x1 {
            let i = y * w + x;
            let j = i + whole * step;
            if !(ok[i] && ok[j]) {
                continue;
            }
            let (a, b) = if frac == 0 {
                (v[i], v[j])
            } else {
                if !(ok[i - step] && ok[j + step]) {
                    continue;
                }
                (
                    (1.0 - t) * v[i] + t * v[i - step],
                    (1.0 - t) * v[j] + t * v[j + step],
                )
            };
            sums.add(f64::from(a), f64::from(b));
        }
    }
    sums.moments(least)
        .map_or(f32::NAN, |m| (m.cov / (m.va * m.vb).sqrt()) as f32)
}

/// Sums over pairs `(a, b)` for their correlation or agreement.
#[derive(Clone, Copy, Debug, Default)]
struct PairSums {
    n: usize,
    a: f64,
    b: f64,
    aa: f64,
    bb: f64,
    ab: f64,
}

/// Centred second moments of [`PairSums`] (sums, not means).
struct PairMoments {
    /// Pairs.
    k: f64,
    /// `Σ(a − ā)²`, `Σ(b − b̄)²`, `Σ(a − ā)(b − b̄)`.
    va: f64,
    vb: f64,
    cov: f64,
    /// `ā − b̄`.
    mean_gap: f64,
}

impl PairSums {
    fn add(&mut self, a: f64, b: f64) {
        self.n += 1;
        self.a += a;
        self.b += b;
        self.aa += a * a;
        self.bb += b * b;
        self.ab += a * b;
    }

    /// The moments, `None` with fewer than `least` pairs or a constant side.
    fn moments(&self, least: usize) -> Option<PairMoments> {
        if self.n < least || self.n == 0 {
            return None;
        }
        let k = self.n as f64;
        let (va, vb) = (self.aa - self.a * self.a / k, self.bb - self.b * self.b / k);
        if va <= 1e-12 * k || vb <= 1e-12 * k {
            return None;
        }
        Some(PairMoments {
            k,
            va,
            vb,
            cov: self.ab - self.a * self.b / k,
            mean_gap: (self.a - self.b) / k,
        })
    }
}

/// The period in an autocorrelation `r` (index = shift), see the module docs.
fn period_of(r: &[f32]) -> Option<AxisPeriod> {
    let at = |d: usize| r.get(d).copied().filter(|v| v.is_finite());
    let is_peak = |d: usize| match (at(d - 1), at(d), at(d + 1)) {
        (Some(a), Some(b), Some(c)) => b >= a && b >= c,
        _ => false,
    };
    // Qualifying peaks: high enough, after a deep enough dip.
    let mut peaks = Vec::new();
    let mut low = f32::INFINITY;
    for d in 1..r.len().saturating_sub(1) {
        let Some(v) = at(d) else {
            continue;
        };
        low = low.min(v);
        if d >= MIN_PERIOD * SUBSTEPS && v >= MIN_WEAK_PEAK && v - low >= MIN_DIP && is_peak(d) {
            peaks.push((d, v));
        }
    }
    let best = peaks.iter().map(|p| p.1).fold(f32::NEG_INFINITY, f32::max);
    let &(d, v) = peaks.iter().find(|p| p.1 >= FIRST_PEAK_SHARE * best)?;
    let refine = |d: usize| -> f32 {
        match (at(d - 1), at(d), at(d + 1)) {
            (Some(a), Some(b), Some(c)) => {
                let den = a - 2.0 * b + c;
                let off = if den < 0.0 { 0.5 * (a - c) / den } else { 0.0 };
                d as f32 + off.clamp(-0.5, 0.5)
            }
            _ => d as f32,
        }
    };
    let mut p = refine(d);
    // The farthest multiple still seen refines it: the peak nearest k·p
    // (within a quarter period), when it is a peak and reaches
    // HARMONIC_SHARE of the period's. A weak peak needs the one at 2·p.
    let least = HARMONIC_SHARE * v;
    let mut k = 2;
    let mut double = None;
    loop {
        let target = k as f32 * p;
        let c = target.round() as usize;
        if c + 1 >= r.len() {
            break;
        }
        let reach = ((p / 4.0).floor() as usize).max(1);
        let found = (c.saturating_sub(reach)..=c + reach)
            .filter(|&e| e >= 1 && e + 1 < r.len() && is_peak(e))
            .filter(|&e| at(e).is_some_and(|x| x >= least))
            .min_by(|&a, &b| {
                (a as f32 - target)
                    .abs()
                    .total_cmp(&(b as f32 - target).abs())
            });
        match found {
            Some(e) => {
                if k == 2 {
                    double = at(e);
                }
                p = refine(e) / k as f32;
                k += 1;
            }
            None => break,
        }
    }
    if v < MIN_PEAK && k == 2 {
        return None;
    }
    Some(AxisPeriod {
        texels: p,
        strength: v,
        double,
    })
}

/// Most periods along one axis of a folded tile.
pub const MAX_PERIODS_PER_TILE: usize = 8;

/// How the plane mode folds a periodic texture into one tile
/// (`material.json`, `diagnostics.uv.period`).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Fold {
    /// The periods along the rectified texture's `u` and `v`, as fractions
    /// of the rectified square.
    pub period: [f32; 2],
    /// Periods per tile along `u` and `v`: a tile holds whole periods, as
    /// many as make it closest to square.
    pub periods_per_tile: [usize; 2],
    /// The tile's sides, as fractions of the rectified square.
    pub tile: [f32; 2],
    /// The tile's width over its height on the plane (the texture square
    /// stretches it to 1 when this is not 1).
    pub aspect: f32,
    /// The autocorrelation at each period ([`AxisPeriod::strength`]).
    pub strength: [f32; 2],
    /// The correlation of the texture with itself shifted by half a period
    /// along both axes at once, when that shift repeats it too
    /// ([`centring`]: a checkerboard, bricks in running bond, a half-drop
    /// wallpaper): every repeat is then folded into the tile twice, once
    /// shifted ([`Fold::centring_shift`],
    /// [`crate::reproject::reproject_centred`]), so each texel is seen by
    /// twice the pixels. `None`: no such repeat (or not looked for).
    pub centred: Option<f32>,
    /// The factors by which [`refine_tile`] scaled the measured tile's
    /// sides (`[u, v]`), when it did: the measured periods drifted over the
    /// repeats. `None`: the tile as measured.
    pub refined: Option<[f32; 2]>,
    /// The shear `[a, b]` applied to the rectified square's coordinates
    /// before they are folded: `u' = u + a·v`, `v' = v + b·u` ([`fold_coords`]).
    /// [`refine_tile`] sets it where the repeats' lattice is turned or
    /// skewed against the square's axes (a plane rectified a few degrees
    /// off), which an axis-aligned tile would fold misregistered; the
    /// tile's sides and periods are then measured along the sheared axes.
    /// `[0, 0]`: none.
    pub shear: [f32; 2],
}

impl Fold {
    /// With [`Fold::centred`]: the half-period shift along both axes, in
    /// units of the tile (`1 / (2 · periods per tile)` each).
    pub fn centring_shift(&self) -> Option<[f32; 2]> {
        self.centred.map(|_| {
            [
                0.5 / self.periods_per_tile[0].max(1) as f32,
                0.5 / self.periods_per_tile[1].max(1) as f32,
            ]
        })
    }

    /// The lengths, as fractions of the rectified square, of the tile's two
    /// sides on the plane: [`Fold::tile`] with [`Fold::shear`] undone (the
    /// sheared axes' unit steps are longer than the square's).
    pub fn sides(&self) -> [f32; 2] {
        let [a, b] = self.shear;
        let det = (1.0 - a * b).abs();
        [
            self.tile[0] * (1.0 + b * b).sqrt() / det,
            self.tile[1] * (1.0 + a * a).sqrt() / det,
        ]
    }
}

/// A half-period shift along both axes counts as a repeat ([`centring`])
/// when the texture's correlation with itself so shifted reaches this share
/// of the weaker axis period's ([`AxisPeriod::strength`]), and at least
/// [`MIN_WEAK_PEAK`].
pub const CENTRE_SHARE: f32 = 0.8;

/// Whether `tex` (its `known` texels), with periods `px` along `x` and `py`
/// along `y` ([`detect`]), also repeats when shifted by half of each at
/// once: the lattice of its repeats is centred (a checkerboard, whose
/// squares of one colour repeat along the diagonals; bricks in running
/// bond; a half-drop wallpaper). Measured as [`detect`] measures, on the
/// box-downsampled luma (sRGB-encoded, as differences are seen): the agreement of the known texels `a` at
/// `p − s/2` and `b` at `p + s/2` for `s = (px/2, py/2)`, both interpolated
/// bilinearly (so the two sides are equally smooth),
/// `R² = 1 − Σ(a − b)² / (Σ(a − ā)² + Σ(b − b̄)²)`: the Pearson correlation
/// when both sides have the same mean and spread, lower when they differ
/// (a pattern whose dark squares alternate between two darks correlates
/// fully with itself so shifted but is not repeated by the shift). Returns
/// it when it reaches [`CENTRE_SHARE`] of the weaker period's strength and
/// [`MIN_WEAK_PEAK`]; `None` otherwise, or where too few texels pair up
/// ([`MIN_PAIR_SHARE`]).
///
/// # Panics
/// When `known` is not one flag per texel.
pub fn centring(tex: &Image, known: &[bool], px: AxisPeriod, py: AxisPeriod) -> Option<f32> {
    assert_eq!(
        known.len(),
        tex.width * tex.height,
        "period::centring: one known flag per texel"
    );
    let mut g = LumaGrid::new(tex, known)?;
    // Compared as seen (sRGB-encoded): in linear light two darks a pattern
    // alternates (0.15 and 0.45 encoded) differ by a fifth of their gap
    // to its white, and would pass for one.
    for v in &mut g.luma {
        *v = crate::photo::srgb_encode(*v);
    }
    let f = g.f as f32;
    let r = half_shift_correlation(
        &g,
        px.texels / (2.0 * f),
        py.texels / (2.0 * f),
        least_pairs(&g.ok),
    );
    let least = MIN_WEAK_PEAK.max(CENTRE_SHARE * px.strength.min(py.strength));
    (r.is_finite() && r >= least).then_some(r)
}

/// The agreement `R²` ([`centring`]) of the bilinearly interpolated values
/// of `g` at `p − (sx, sy)/2` and `p + (sx, sy)/2` over the grid points `p`
/// whose eight neighbours are all known; NaN with fewer than `least` of
/// them, a shift the grid cannot hold or a constant side.
fn half_shift_correlation(g: &LumaGrid, sx: f32, sy: f32, least: usize) -> f32 {
    let (w, h) = (g.w, g.h);
    if !(sx.is_finite() && sy.is_finite() && sx >= 0.0 && sy >= 0.0) {
        return f32::NAN;
    }
    let (hx, hy) = (sx / 2.0, sy / 2.0);
    // Bilinear sample at (x, y), `None` unless its four texels are known.
    let at = |x: f32, y: f32| -> Option<f64> {
        let (x0, y0) = (x.floor(), y.floor());
        if x0 < 0.0 || y0 < 0.0 {
            return None;
        }
        let (ix, iy) = (x0 as usize, y0 as usize);
        let (tx, ty) = (x - x0, y - y0);
        let ix1 = if tx > 0.0 { ix + 1 } else { ix };
        let iy1 = if ty > 0.0 { iy + 1 } else { iy };
        if ix1 >= w || iy1 >= h {
            return None;
        }
        let k = |x: usize, y: usize| g.ok[y * w + x].then(|| f64::from(g.luma[y * w + x]));
        let (a, b, c, d) = (k(ix, iy)?, k(ix1, iy)?, k(ix, iy1)?, k(ix1, iy1)?);
        let (tx, ty) = (f64::from(tx), f64::from(ty));
        Some((a * (1.0 - tx) + b * tx) * (1.0 - ty) + (c * (1.0 - tx) + d * tx) * ty)
    };
    let mut sums = PairSums::default();
    for y in 0..h {
        for x in 0..w {
            let (px, py) = (x as f32, y as f32);
            let (Some(a), Some(b)) = (at(px - hx, py - hy), at(px + hx, py + hy)) else {
                continue;
            };
            sums.add(a, b);
        }
    }
    // Σ(a − b)² = va + vb − 2 cov + k (ā − b̄)².
    sums.moments(least).map_or(f32::NAN, |m| {
        ((2.0 * m.cov - m.k * m.mean_gap * m.mean_gap) / (m.va + m.vb)) as f32
    })
}

/// The tile for periods `px` and `py` measured on a texture of side `size`:
/// `kx·px × ky·py` with `kx, ky ≤ MAX_PERIODS_PER_TILE` and each side at
/// most half the texture (two tiles seen), the closest to square (ties: the
/// smaller tile).
pub fn fold_tile(px: AxisPeriod, py: AxisPeriod, size: usize) -> Fold {
    let half = size as f32 / 2.0;
    let mut best = (1usize, 1usize, f32::INFINITY);
    for ky in 1..=MAX_PERIODS_PER_TILE {
        for kx in 1..=MAX_PERIODS_PER_TILE {
            let (tx, ty) = (kx as f32 * px.texels, ky as f32 * py.texels);
            if (tx > half || ty > half) && (kx, ky) != (1, 1) {
                continue;
            }
            let err = (tx / ty).ln().abs();
            if err < best.2 - 1e-6 {
                best = (kx, ky, err);
            }
        }
    }
    let (kx, ky, _) = best;
    let s = size.max(1) as f32;
    Fold {
        period: [px.texels / s, py.texels / s],
        periods_per_tile: [kx, ky],
        tile: [kx as f32 * px.texels / s, ky as f32 * py.texels / s],
        aspect: (kx as f32 * px.texels) / (ky as f32 * py.texels),
        strength: [px.strength, py.strength],
        centred: None,
        refined: None,
        shear: [0.0, 0.0],
    }
}

/// The coordinates `coords` (the rectified square's, not wrapping) folded
/// by `fold`'s tile after its shear `[a, b]`: `u' = frac((u + a·v) / tile_u)`,
/// `v' = frac((v + b·u) / tile_v)`, wrapping. Pixels without coordinates
/// keep none.
pub fn fold_coords(coords: &Coords, fold: &Fold) -> Coords {
    let [a, b] = fold.shear;
    if a == 0.0 && b == 0.0 {
        return wrap_by_tile(coords, fold.tile);
    }
    let (uv, (tu, tv)) = (
        coords.u.par_iter().zip(&coords.v),
        (fold.tile[0], fold.tile[1]),
    );
    Coords {
        width: coords.width,
        height: coords.height,
        u: uv.clone().map(|(&u, &v)| frac_of(u + a * v, tu)).collect(),
        v: uv.map(|(&u, &v)| frac_of(v + b * u, tv)).collect(),
        wrap: true,
    }
}

/// The fraction of `t` in tiles of `side`: `frac(t / side)`; NaN stays NaN.
fn frac_of(t: f32, side: f32) -> f32 {
    let x = t / side;
    x - crate::reproject::floor_f32(x)
}

/// `coords` wrapped by a tile of sides `tile` (fractions of the square):
/// `u' = frac(u / tile_u)`, `v' = frac(v / tile_v)`, wrapping; NaN stays NaN.
///
/// In parallel (as [`fold_coords`]): at 12 MP the two maps, each writing
/// a fresh 48 MB vector, took ~70 ms on one thread, most of it the first
/// touch of the vectors' pages.
fn wrap_by_tile(coords: &Coords, tile: [f32; 2]) -> Coords {
    Coords {
        width: coords.width,
        height: coords.height,
        u: coords.u.par_iter().map(|&u| frac_of(u, tile[0])).collect(),
        v: coords.v.par_iter().map(|&v| frac_of(v, tile[1])).collect(),
        wrap: true,
    }
}

/// The plane mode's fold: `coords` (the rectified square's) folded into one
/// tile when the picked pixels (`mask`, de-lit `colour`, `confidence`)
/// splatted at `size` texels (at most [`MAX_SIDE`]; a quick splat without
/// back-projection) repeat along both axes ([`detect`], [`fold_tile`],
/// [`fold_coords`]), with its [`centring`] looked for in those pixels and,
/// failing that, in `centring_mask`'s (a wider set of pixels of the same
/// material: the pick's surest pixels may hold only one colour of a
/// two-colour pattern, whose texels then never pair with the other's);
/// else `coords` unchanged and no fold.
///
/// # Panics
/// When a mask does not hold one flag per pixel of `coords`.
pub fn fold_if_periodic(
    coords: Coords,
    mask: &[bool],
    centring_mask: Option<&[bool]>,
    colour: &Image,
    confidence: &[f32],
    size: usize,
) -> (Coords, Option<Fold>) {
    let probe = size.clamp(1, MAX_SIDE);
    let splat =
        |m: &[bool]| crate::reproject::reproject_unsharpened(&coords, m, colour, confidence, probe);
    let r = splat(mask);
    match detect(&r.texture, &r.known) {
        (Some(px), Some(py)) => {
            let centred = centring(&r.texture, &r.known, px, py).or_else(|| {
                let wide = splat(centring_mask?);
                centring(&wide.texture, &wide.known, px, py)
            });
            let f = Fold {
                centred,
                ..fold_tile(px, py, probe)
            };
            let f = refine_tile(&coords, mask, colour, confidence, f);
            (fold_coords(&coords, &f), Some(f))
        }
        _ => (coords, None),
    }
}

/// Most bins per tile side in which [`refine_tile`] measures how well a
/// fold lines the pixels up; fewer where the tile spans fewer pixels (a bin
/// is then about [`REFINE_BIN_PIXELS`] pixels of one repeat wide, so every
/// bin gathers pixels of many repeats: bins finer than the pixels would
/// favour the tile that scatters the repeats into bins of their own).
pub const REFINE_BINS: usize = 96;
/// Photo pixels (of one repeat) per bin side, at least.
pub const REFINE_BIN_PIXELS: f32 = 2.0;
/// Most pixels [`refine_tile`] reads (an even stride through the picked ones).
pub const REFINE_MAX_PIXELS: usize = 1 << 18;
/// [`refine_tile`]'s coarse steps read every this many of its pixels (the
/// quarter steps around the best read them all).
pub const REFINE_COARSE_STRIDE: usize = 4;
/// [`refine_tile`]'s coarse step (a share of the tile's side) ...
pub const REFINE_STEP: f32 = 0.004;
/// ... and how many steps it looks on each side (±3.2 %), then a quarter
/// step as far on each side of the best.
pub const REFINE_STEPS: i32 = 8;
/// [`refine_tile`]'s coarse step of shear (the tile's shift along one axis
/// per tile along the other, in tiles) ...
pub const REFINE_SHEAR_STEP: f32 = 0.01;
/// ... and how many steps it looks on each side (±0.1: a lattice turned by
/// up to ~6° against the square's axes), then a quarter step four times on
/// each side of the best.
pub const REFINE_SHEAR_STEPS: i32 = 10;
/// Fewest bins per tile side (a tile of about 40 pixels) with which
/// [`refine_tile`] shears: a coarse shear step moves a smaller tile by
/// under 0.4 pixel per repeat, where the spread is bumpy (how the pixels'
/// phases fall into the bins decides), and with ground-truth elements the
/// shears found on 20–32-texel tiles were chance (−0.4 to −3.2 dB, stop 56).
pub const REFINE_SHEAR_MIN_BINS: usize = 20;
/// A refined tile must lower the within-bin spread by at least this share
/// (else the measured one is kept). A drifting fold leaves far more spread
/// than one that lines the repeats up (a chessboard's: 63–89 % less once
/// refined); smaller gains, with ground-truth elements on the synthetic
/// scenes, were chance — noise, or an axis along which the texture hardly
/// changes — and refining by them lost up to 4 dB (stop 55).
pub const REFINE_MIN_GAIN: f64 = 0.4;
/// Fewest bins per tile side [`refine_tile`] measures with.
pub const REFINE_MIN_BINS: usize = 8;

/// A pixel [`refine_tile`] reads: `(u, v, luma, confidence, texture area)`.
type Taken = (f32, f32, f32, f32, f32);

/// The picked pixels' spread around their fold: the weighted mean, over the
/// `bins`² bins of a tile of sides `tile` after the shear `[a, b]` (as
/// [`fold_coords`] folds), of the squared distance of each pixel's luma
/// from its bin's mean (`samples`: `(u, v, luma, weight)` in the rectified
/// square, unfolded).
fn fold_spread(
    samples: &[(f32, f32, f32, f32)],
    tile: [f32; 2],
    shear: [f32; 2],
    bins: usize,
) -> f64 {
    let b = bins.max(1);
    let mut acc = vec![[0.0f64; 3]; b * b];
    // The bin of `t` in a tile of side `1 / inv`.
    let bf = b as f32;
    let bin = |t: f32, inv: f32| {
        let x = t * inv;
        (((x - crate::reproject::floor_f32(x)) * bf) as usize).min(b - 1)
    };
    let (su, sv) = (1.0 / tile[0], 1.0 / tile[1]);
    let [sa, sb] = shear;
    for &(u, v, l, w) in samples {
        let (u, v) = (u + sa * v, v + sb * u);
        let a = &mut acc[bin(v, sv) * b + bin(u, su)];
        let (l, w) = (f64::from(l), f64::from(w));
        a[0] += w;
        a[1] += w * l;
        a[2] += w * l * l;
    }
    let (mut within, mut total) = (0.0f64, 0.0f64);
    for a in &acc {
        if a[0] > 0.0 {
            within += a[2] - a[1] * a[1] / a[0];
            total += a[0];
        }
    }
    if total > 0.0 {
        within / total
    } else {
        0.0
    }
}

/// `fold` with its tile's sides (and periods) refined, and its axes
/// sheared, to line the picked pixels up best: the periods [`detect`]
/// measures are precise to about a percent (its shifts reach half the
/// square, so a square of four periods refines them by the second's peak at
/// most), and a tile a percent off drifts by a period's few percent over a
/// few repeats, which blurs the folded pattern's edges and lets one
/// colour's pixels land on the other's texels (a chessboard's white squares
/// came out smaller than its black ones); a lattice turned or skewed by a
/// few degrees against the square's axes (a plane rectified slightly off:
/// a calibration board held up to the camera) drifts the same way along
/// the other axis. Each side is scaled by `1 + k·`[`REFINE_STEP`] for `|k| ≤`
/// [`REFINE_STEPS`], then by a quarter step around the best, and each axis
/// sheared by `k·`[`REFINE_SHEAR_STEP`] tiles per tile for `|k| ≤`
/// [`REFINE_SHEAR_STEPS`], then by a quarter step: scale `u`, scale `v`,
/// shear `u`, shear `v`, then (unless those four rounds found less than half
/// the gain asked for: the fold then stays as measured) all four again
/// (the spread is bumpy at sub-pixel drifts; a tile spanning fewer than
/// [`REFINE_SHEAR_MIN_BINS`] bins is only scaled: `u`, `v`, then `u`
/// again after the same check), keeping the candidate whose fold leaves the least spread of the
/// pixels' luma within bins of the tile (`fold_spread`, on at most
/// [`REFINE_MAX_PIXELS`] pixels taken evenly); the result replaces the
/// measured tile only when it lowers that spread by [`REFINE_MIN_GAIN`].
/// Deterministic (ties: the smaller change).
///
/// # Panics
/// When `mask` or `confidence` do not hold one value per pixel of `coords`.
pub fn refine_tile(
    coords: &Coords,
    mask: &[bool],
    colour: &Image,
    confidence: &[f32],
    fold: Fold,
) -> Fold {
    let n = coords.width * coords.height;
    assert_eq!(mask.len(), n, "refine_tile: one flag per pixel");
    assert_eq!(confidence.len(), n, "refine_tile: one confidence per pixel");
    let ok = |t: f32| t.is_finite() && t > 0.0;
    if !fold.tile.iter().chain(&fold.period).all(|&t| ok(t)) {
        return fold;
    }
    let usable = |i: usize| {
        confidence[i] > 0.0
            && coords.u[i].is_finite()
            && coords.v[i].is_finite()
            && colour.rgb(i).is_finite()
    };
    // Every `stride`-th picked pixel in index order (at most about
    // REFINE_MAX_PIXELS), those with coordinates, colour and confidence,
    // found in parallel over blocks of pixels: each block's picked pixels
    // are counted, then taken where their rank among all the picked pixels
    // is a multiple of the stride (only the mask is read whole). Each
    // sample is `(u, v, luma, confidence, texture area)`.
    const BLOCK: usize = 1 << 16;
    let blocks: Vec<std::ops::Range<usize>> = (0..n)
        .step_by(BLOCK)
        .map(|s| s..(s + BLOCK).min(n))
        .collect();
    let counts: Vec<usize> = blocks
        .par_iter()
        .map(|r| mask[r.clone()].iter().filter(|&&m| m).count())
        .collect();
    let count: usize = counts.iter().sum();
    let stride = count.div_ceil(REFINE_MAX_PIXELS).max(1);
    let firsts: Vec<usize> = counts
        .iter()
        .scan(0, |acc, &c| {
            let first = *acc;
            *acc += c;
            Some(first)
        })
        .collect();
    let taken: Vec<Vec<Taken>> = blocks
        .par_iter()
        .zip(&firsts)
        .map(|(r, &first)| {
            let skip = (stride - first % stride) % stride;
            r.clone()
                .filter(|&i| mask[i])
                .skip(skip)
                .step_by(stride)
                .filter(|&i| usable(i))
                .filter_map(|i| {
                    let c = colour.rgb(i);
                    let luma = 0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z;
                    let a = coords.pixel_area(mask, i).filter(|a| *a > 0.0)?;
                    Some((coords.u[i], coords.v[i], luma, confidence[i], a))
                })
                .collect()
        })
        .collect();
    let taken: Vec<Taken> = taken.concat();
    // Bins about REFINE_BIN_PIXELS pixels wide (the median pixel's side,
    // the median of the samples' texture areas).
    let mut areas: Vec<f32> = taken.iter().map(|t| t.4).collect();
    if areas.is_empty() {
        return fold;
    }
    let mid = areas.len() / 2;
    let area = *areas.select_nth_unstable_by(mid, f32::total_cmp).1;
    if !ok(area) {
        return fold;
    }
    let tile_px = fold.tile[0].min(fold.tile[1]) / area.sqrt();
    let bins = ((tile_px / REFINE_BIN_PIXELS) as usize).min(REFINE_BINS);
    if bins < REFINE_MIN_BINS {
        return fold;
    }
    // Weighted as the splat weighs a pixel (its confidence over the squared
    // area it covers, here relative to the median pixel's): the sharp, near
    // pixels count most.
    let samples: Vec<(f32, f32, f32, f32)> = taken
        .iter()
        .filter_map(|&(u, v, l, c, a)| {
            let w = c * (area / a).powi(2);
            w.is_finite().then_some((u, v, l, w))
        })
        .collect();
    // Each repeat's own mean taken out (cells of one measured period each
    // way, in the unfolded square): what does not repeat from one period to
    // the next (a tile's own shade, a drift of light) would otherwise
    // favour a drifting tile, which bins neighbouring repeats together.
    let cell = |u: f32, v: f32| {
        (
            (u / fold.period[0]).floor() as i64,
            (v / fold.period[1]).floor() as i64,
        )
    };
    // Each sample's cell, numbered densely over the cells' bounding box when
    // that is small (it is: the square holds a few dozen periods each way),
    // else in order of first appearance.
    let (mut lo, mut hi) = ((i64::MAX, i64::MAX), (i64::MIN, i64::MIN));
    for &(u, v, _, _) in &samples {
        let (cu, cv) = cell(u, v);
        (lo, hi) = ((lo.0.min(cu), lo.1.min(cv)), (hi.0.max(cu), hi.1.max(cv)));
    }
    let cols = (hi.0 - lo.0 + 1).max(0) as usize;
    let rows = (hi.1 - lo.1 + 1).max(0) as usize;
    let ids: Vec<usize> = match cols.checked_mul(rows).filter(|&c| c <= 1 << 20) {
        Some(_) => samples
            .iter()
            .map(|&(u, v, _, _)| {
                let (cu, cv) = cell(u, v);
                (cv - lo.1) as usize * cols + (cu - lo.0) as usize
            })
            .collect(),
        None => {
            let mut seen = std::collections::HashMap::new();
            samples
                .iter()
                .map(|&(u, v, _, _)| {
                    let next = seen.len();
                    *seen.entry(cell(u, v)).or_insert(next)
                })
                .collect()
        }
    };
    let mut means = vec![(0.0f64, 0.0f64); ids.iter().max().map_or(0, |m| m + 1)];
    for (&(_, _, l, w), &id) in samples.iter().zip(&ids) {
        let e = &mut means[id];
        e.0 += f64::from(w);
        e.1 += f64::from(w) * f64::from(l);
    }
    let samples: Vec<(f32, f32, f32, f32)> = samples
        .iter()
        .zip(&ids)
        .map(|(&(u, v, l, w), &id)| {
            let (sw, sl) = means[id];
            let mean = if sw > 0.0 { (sl / sw) as f32 } else { l };
            (u, v, l - mean, w)
        })
        .collect();
    if samples.len() < 2 {
        return fold;
    }
    // The candidate: `[scale u, scale v, shear u, shear v]`, the shears in
    // tiles per tile (`u` moves by `p[2]` tiles per tile of `v`).
    let tile_of = |p: [f32; 4]| [fold.tile[0] * p[0], fold.tile[1] * p[1]];
    let shear_of = |p: [f32; 4]| {
        let t = tile_of(p);
        [p[2] * t[0] / t[1], p[3] * t[1] / t[0]]
    };
    let spread_at = |p: [f32; 4]| fold_spread(&samples, tile_of(p), shear_of(p), bins);
    // The coarse steps look on every REFINE_COARSE_STRIDE-th sample (the
    // same ones for every candidate), the fine steps on all of them.
    let coarse: Vec<(f32, f32, f32, f32)> = samples
        .iter()
        .step_by(REFINE_COARSE_STRIDE)
        .copied()
        .collect();
    let coarse_at = |p: [f32; 4]| fold_spread(&coarse, tile_of(p), shear_of(p), bins);
    let none = [1.0f32, 1.0, 0.0, 0.0];
    let base = spread_at(none);
    let mut best = (base, none);
    let moved = |at: [f32; 4], axis: usize, k: i32, step: f32| {
        let mut p = at;
        if axis < 2 {
            p[axis] *= 1.0 + k as f32 * step;
        } else {
            p[axis] += k as f32 * step;
        }
        p
    };
    // Scale and shear, twice; a tile spanning fewer bins only scaled (as
    // stop 55 did: u, v, u).
    let (rounds, axes): (&[usize], usize) = if bins >= REFINE_SHEAR_MIN_BINS {
        (&[0, 1, 2, 3, 0, 1, 2, 3], 4)
    } else {
        (&[0, 1, 0], 2)
    };
    for (round, &axis) in rounds.iter().enumerate() {
        // After a round along each axis, a fold still short of half the
        // gain asked for is not refined (the last rounds only polish).
        if round == axes && best.0 > base * (1.0 - REFINE_MIN_GAIN / 2.0) {
            return fold;
        }
        let (step, steps) = if axis < 2 {
            (REFINE_STEP, REFINE_STEPS)
        } else {
            (REFINE_SHEAR_STEP, REFINE_SHEAR_STEPS)
        };
        // Candidates nearest the current one first, so ties keep the
        // smaller change.
        let ks = |steps: i32| -> Vec<i32> { (0..=steps).flat_map(|k| [k, -k]).skip(1).collect() };
        let at = best.1;
        let mut centre = (coarse_at(at), at);
        let found: Vec<(f64, [f32; 4])> = ks(steps)
            .par_iter()
            .map(|&k| {
                let p = moved(at, axis, k, step);
                (coarse_at(p), p)
            })
            .collect();
        for c in found {
            if c.0 < centre.0 {
                centre = c;
            }
        }
        // The fine steps around the coarse best, itself included.
        let mut fine = vec![0];
        fine.extend(ks(4));
        let found: Vec<(f64, [f32; 4])> = fine
            .par_iter()
            .filter(|&&k| k != 0 || centre.1 != at)
            .map(|&k| {
                let p = moved(centre.1, axis, k, step / 4.0);
                (spread_at(p), p)
            })
            .collect();
        for c in found {
            if c.0 < best.0 {
                best = c;
            }
        }
    }
    let (spread, p) = best;
    if spread > base * (1.0 - REFINE_MIN_GAIN) || p == none {
        return fold;
    }
    let [su, sv, ..] = p;
    let refined = Fold {
        period: [fold.period[0] * su, fold.period[1] * sv],
        tile: tile_of(p),
        refined: Some([su, sv]),
        shear: shear_of(p),
        ..fold
    };
    let [a, b] = refined.sides();
    Fold {
        aspect: fold.aspect * (a / b) / (fold.tile[0] / fold.tile[1]),
        ..refined
    }
}

/// Largest drift, in periods, between `n` measured periods and the side of
/// the texture square for the square to count as `n` whole repeats
/// ([`whole_repeats`]).
pub const UV_REPEAT_TOLERANCE: f32 = 0.15;
/// Most whole repeats along one axis of the texture square that
/// [`fold_uv_if_periodic`] folds.
pub const MAX_UV_REPEATS: usize = 32;

/// How many times a period `p` (texels of a texture square of side `side`)
/// fits along the square when it fits a whole number `n ≥ 2` of times, to
/// within [`UV_REPEAT_TOLERANCE`] of a period over the whole side; else
/// `None`. A texture that tiles the square and repeats inside it repeats a
/// whole number of times.
pub fn whole_repeats(p: AxisPeriod, side: usize) -> Option<usize> {
    if p.texels.is_nan() || p.texels <= 0.0 || side == 0 {
        return None;
    }
    let exact = side as f32 / p.texels;
    let n = exact.round();
    let drift = (n * p.texels - side as f32).abs() / p.texels;
    (n >= 2.0 && n <= MAX_UV_REPEATS as f32 && drift <= UV_REPEAT_TOLERANCE).then_some(n as usize)
}

/// Largest gap between a measured period and `side / n` for
/// [`snap_repeats`] to try `n` repeats: a period measured on a small
/// observed part of the square is a few percent off, too much for
/// [`UV_REPEAT_TOLERANCE`] over twenty repeats.
pub const SNAP_TOLERANCE: f32 = 0.05;
/// Least margin by which the chosen number of repeats must correlate better
/// than the next best in [`snap_repeats`].
pub const SNAP_MARGIN: f32 = 0.05;

/// The whole number of repeats `n` of a texture square of side `side`
/// (texels of `tex`) along axis `(dx, dy)` when the measured period `p`
/// is within [`SNAP_TOLERANCE`] of `side / n` but [`whole_repeats`] cannot
/// tell (its estimate drifts by more than [`UV_REPEAT_TOLERANCE`] of a
/// period over the side): each candidate `n` (the one or two nearest
/// `side / p.texels`, from 2 to [`MAX_UV_REPEATS`]) is scored by the mean
/// correlation of `tex`'s known texels at the shifts `k · side / n` for
/// every `k ≥ 1` the known texels pair at, where a wrong `n` drifts off the
/// pattern by `k` times its error. The best is taken when it correlates at
/// least [`MIN_WEAK_PEAK`] on average and at its farthest multiple at least
/// [`HARMONIC_SHARE`] of the period's strength, over at least two
/// multiples, and beats every other candidate by [`SNAP_MARGIN`]. `None`
/// for the zero axis `(0, 0)`, which has no shifts.
pub fn snap_repeats(
    tex: &Image,
    known: &[bool],
    (dx, dy): (usize, usize),
    p: AxisPeriod,
    side: usize,
) -> Option<usize> {
    if p.texels.is_nan()
        || p.texels <= 0.0
        || side == 0
        || (dx, dy) == (0, 0)
        || known.len() != tex.width * tex.height
    {
        return None;
    }
    let g = LumaGrid::new(tex, known)?;
    let v = without_line_trends(&g.luma, &g.ok, g.w, g.h, dy, false);
    let grid = Grid {
        v: &v,
        ok: &g.ok,
        w: g.w,
        h: g.h,
    };
    let least = least_pairs(&g.ok);
    let exact = side as f32 / p.texels;
    let mut candidates: Vec<usize> = [exact.floor(), exact.ceil()]
        .into_iter()
        .map(|n| n as usize)
        .filter(|&n| (2..=MAX_UV_REPEATS).contains(&n))
        .filter(|&n| (side as f32 / n as f32 - p.texels).abs() <= SNAP_TOLERANCE * p.texels)
        .collect();
    candidates.dedup();
    // (n, mean correlation, farthest multiple's correlation)
    let scored: Vec<(usize, f32, f32)> = candidates
        .iter()
        .filter_map(|&n| {
            let period = side as f32 / n as f32 / g.f as f32 * SUBSTEPS as f32;
            // (Shifts past the grid pair no texels and end the run; the
            // bound only guards against a run that never ends.)
            let r: Vec<f32> = (1..=g.w + g.h)
                .map(|k| (k as f32 * period).round() as usize)
                .map(|d| correlation_at(grid, (dx, dy), d, least))
                .take_while(|r| r.is_finite())
                .collect();
            (r.len() >= 2).then(|| (n, r.iter().sum::<f32>() / r.len() as f32, r[r.len() - 1]))
        })
        .collect();
    let best = scored.iter().copied().max_by(|a, b| a.1.total_cmp(&b.1))?;
    let runner_up = scored
        .iter()
        .filter(|c| c.0 != best.0)
        .map(|c| c.1)
        .fold(f32::NEG_INFINITY, f32::max);
    (best.1 >= MIN_WEAK_PEAK
        && best.2 >= HARMONIC_SHARE * p.strength
        && best.1 >= runner_up + SNAP_MARGIN)
        .then_some(best.0)
}

/// The repeats found inside the wrapped texture square of the networks'
/// UVs (`material.json`, `diagnostics.uv.repeats`).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct UvRepeats {
    /// Whole repeats along `u` and `v` (1: none found along that axis).
    pub repeats: [usize; 2],
    /// The measured periods, as fractions of the square (`None`: no
    /// period along that axis, or not a whole number of them).
    pub period: [Option<f32>; 2],
    /// The autocorrelation at each period ([`AxisPeriod::strength`]).
    pub strength: [Option<f32>; 2],
    /// The autocorrelation at twice each period ([`AxisPeriod::double`]).
    pub double: [Option<f32>; 2],
    /// Share of the square's texels that no picked pixel reached and that
    /// were filled from another repeat (the rest of the holes is inpainted).
    pub filled: f64,
}

impl UvRepeats {
    /// The tile the square folds into: `1/repeats` of it along each axis.
    pub fn tile(&self) -> [f32; 2] {
        [1.0 / self.repeats[0] as f32, 1.0 / self.repeats[1] as f32]
    }
}

/// Least margin by which the autocorrelation at twice a period must exceed
/// the period's own for the double to be taken as the period
/// ([`fold_uv_if_periodic`]).
pub const DOUBLE_MARGIN: f32 = 0.1;

/// `p`, or its double when that correlates at least [`DOUBLE_MARGIN`]
/// better (its strength then the double's, no double measured).
fn prefer_double(p: AxisPeriod) -> AxisPeriod {
    match p.double {
        Some(d) if d >= p.strength + DOUBLE_MARGIN => AxisPeriod {
            texels: 2.0 * p.texels,
            strength: d,
            double: None,
        },
        _ => p,
    }
}

/// The networks' UV mode's counterpart of [`fold_if_periodic`]: when the
/// picked pixels (`mask`, de-lit `colour`, `confidence`) splatted through
/// the wrapped UVs `coords` at `size` texels (at most [`MAX_SIDE`], a quick
/// splat) repeat a whole number of times along an axis of the texture
/// square ([`detect`], [`whole_repeats`]), the UVs folded by those repeats
/// (`u' = frac(n_u·u)`, `v' = frac(n_v·v)`: every observed repeat lands in
/// one tile) and the repeats; else `None`. The pipeline fills the holes of
/// the square that another repeat showed from that tile ([`unfold`])
/// instead of having the inpainter invent them.
pub fn fold_uv_if_periodic(
    coords: &Coords,
    mask: &[bool],
    colour: &Image,
    confidence: &[f32],
    size: usize,
) -> Option<(Coords, UvRepeats)> {
    // The square wraps: measured on it and half of it again, so that
    // shifts reach three quarters of the side (twice a period of a quarter).
    let probe = size.clamp(1, MAX_SIDE * 2 / 3);
    let r = crate::reproject::reproject_unsharpened(coords, mask, colour, confidence, probe);
    let ext = probe + probe / 2;
    let mut tex = Image::zeros(r.texture.channels, ext, ext);
    let mut known = vec![false; ext * ext];
    for y in 0..ext {
        for x in 0..ext {
            let (i, j) = (y * ext + x, (y % probe) * probe + x % probe);
            known[i] = r.known[j];
            for c in 0..tex.channels {
                tex.data[c * ext * ext + i] = r.texture.data[c * probe * probe + j];
            }
        }
    }
    let (px, py) = detect(&tex, &known);
    // A period whose double correlates far better is half of the true one
    // (a running bond measured across its courses): the double is taken
    // when it still fits the square a whole number of times.
    let px = px.map(prefer_double);
    let py = py.map(prefer_double);
    // A whole number of repeats, or the nearest that the texels show better
    // than its neighbours (a period measured on a small part of the square).
    let n = |p: Option<AxisPeriod>, axis| {
        p.and_then(|p| {
            whole_repeats(p, probe).or_else(|| snap_repeats(&tex, &known, axis, p, probe))
        })
    };
    let (nx, ny) = (n(px, (1, 0)), n(py, (0, 1)));
    if nx.is_none() && ny.is_none() {
        return None;
    }
    let keep = |p: Option<AxisPeriod>, n: Option<usize>| n.and(p);
    let (px, py) = (keep(px, nx), keep(py, ny));
    let rep = UvRepeats {
        repeats: [nx.unwrap_or(1), ny.unwrap_or(1)],
        period: [px, py].map(|p| p.map(|p| p.texels / probe as f32)),
        strength: [px, py].map(|p| p.map(|p| p.strength)),
        double: [px, py].map(|p| p.and_then(|p| p.double)),
        filled: 0.0,
    };
    Some((wrap_by_tile(coords, rep.tile()), rep))
}

/// The texture square of side `side` made of `repeats[0] × repeats[1]`
/// copies of `tile` (any size and channels): the copies are laid side by
/// side and resampled to the square with wrap-around (area average along an
/// axis that shrinks, bilinear along one that grows; no resampling where
/// `repeats · tile side == side`).
///
/// # Panics
/// When `repeats` times the tile's size overflows `usize`.
pub fn unfold(tile: &Image, repeats: [usize; 2], side: usize) -> Image {
    let (c, th, tw) = (tile.channels, tile.height, tile.width);
    let (nx, ny) = (repeats[0].max(1), repeats[1].max(1));
    assert!(
        th.checked_mul(ny).is_some() && tw.checked_mul(nx).is_some(),
        "unfold: {repeats:?} repeats of a {tw}x{th} tile overflow"
    );
    crate::report::resize_rows((c, th * ny, tw * nx), side, side, true, |ch, r, out| {
        let src = &tile.plane(ch)[(r % th) * tw..(r % th + 1) * tw];
        for (x, o) in out.iter_mut().enumerate() {
            *o = src[x % tw];
        }
    })
}

/// Least distance, in periods (the shorter of the square's two), from the
/// nearest observed texel for a hole to be filled from another repeat
/// ([`fill_from_repeats`]); nearer holes are left to the inpainter.
pub const REPEAT_FILL_MIN_DISTANCE: f32 = 0.5;

/// The holes of a reprojected square (`tex`, its `known` texels) that
/// another repeat showed, filled from `over` (the tile of every repeat laid
/// over the square, [`unfold`]) where `over_seen` (the tile's known flags
/// laid over the same way, 1 = observed) is 1: the texture and its known
/// flags after filling, and how many texels were filled.
///
/// Only holes at least `min_distance` texels (chessboard, wrapping around)
/// from every observed texel are filled. A repeat is not an exact copy
/// (tiles and bricks of varied colour, a drift the de-lighting left): near
/// what was seen, the inpainter's continuation of the same tile or brick is
/// closer to the truth than another repeat's, and it blends the two where
/// they meet; far from it, only the repeats know where the grout runs.
///
/// # Panics
/// When the sizes disagree.
pub fn fill_from_repeats(
    tex: &Image,
    known: &[bool],
    over: &Image,
    over_seen: &Image,
    min_distance: usize,
) -> (Image, Vec<bool>, usize) {
    let (w, h) = (tex.width, tex.height);
    let n = w * h;
    assert!(
        known.len() == n
            && (over.width, over.height) == (w, h)
            && (over_seen.width, over_seen.height) == (w, h),
        "fill_from_repeats: sizes differ"
    );
    let far = distance_at_least(known, w, h, min_distance);
    let mut out = tex.clone();
    let mut k = known.to_vec();
    let mut filled = 0;
    for i in 0..n {
        if far[i] && over_seen.data[i] > 1.0 - 1e-4 {
            out.set_rgb(i, over.rgb(i));
            k[i] = true;
            filled += 1;
        }
    }
    (out, k, filled)
}

/// A reprojected square completed from its repeats
/// ([`complete_from_repeats`]).
#[derive(Clone, Debug)]
pub struct Completed {
    /// The texture, with the filled texels (linear RGB; 0 where still unknown).
    pub texture: Image,
    /// Known texels: observed, or filled from another repeat.
    pub known: Vec<bool>,
    /// Per-texel coverage: the square's own, or the repeats' tile's where filled.
    pub coverage: Image,
    /// How many texels were filled.
    pub filled: usize,
}

/// The square `own` (reprojected through the unfolded UVs, side `n`)
/// completed from its repeats: the picked pixels (`mask`, de-lit `colour`,
/// `confidence`) reprojected through the UVs `folded` by `rep`
/// ([`fold_uv_if_periodic`]) into one tile of side `n` over the fewest
/// repeats, laid over the square ([`unfold`]), and its holes at least
/// [`REPEAT_FILL_MIN_DISTANCE`] of the shorter period from every observed
/// texel filled from it ([`fill_from_repeats`]).
pub fn complete_from_repeats(
    own: &crate::reproject::Reprojected,
    folded: &Coords,
    rep: &UvRepeats,
    mask: &[bool],
    colour: &Image,
    confidence: &[f32],
) -> Completed {
    let size = own.texture.width;
    let side = size.div_ceil(rep.repeats[0].min(rep.repeats[1])).max(1);
    let t = crate::reproject::reproject(folded, mask, colour, confidence, side);
    let seen = Image {
        channels: 1,
        height: side,
        width: side,
        data: t.known.iter().map(|&k| f32::from(u8::from(k))).collect(),
    };
    let over = unfold(&t.texture, rep.repeats, size);
    let over_seen = unfold(&seen, rep.repeats, size);
    let period = size as f32 / rep.repeats[0].max(rep.repeats[1]) as f32;
    let (texture, known, filled) = fill_from_repeats(
        &own.texture,
        &own.known,
        &over,
        &over_seen,
        (REPEAT_FILL_MIN_DISTANCE * period).round() as usize,
    );
    let mut coverage = own.coverage.clone();
    let tile_coverage = unfold(&t.coverage, rep.repeats, size);
    for (i, (&k, &was)) in known.iter().zip(&own.known).enumerate() {
        if k && !was {
            coverage.data[i] = tile_coverage.data[i];
        }
    }
    Completed {
        texture,
        known,
        coverage,
        filled,
    }
}

/// Per texel of a `w × h` grid that wraps around: whether its chessboard
/// distance to the nearest `set` texel is at least `d` (all `true` when no
/// texel is set; `d = 0`: every texel).
fn distance_at_least(set: &[bool], w: usize, h: usize, d: usize) -> Vec<bool> {
    // Breadth-first from every set texel, 8-connected, `d − 1` steps.
    let mut near = set.to_vec();
    if d == 0 {
        return vec![true; w * h];
    }
    let mut front: Vec<usize> = (0..w * h).filter(|&i| set[i]).collect();
    for _ in 1..d {
        let mut next = Vec::new();
        for &i in &front {
            let (x, y) = ((i % w) as i64, (i / w) as i64);
            for dy in -1..=1i64 {
                for dx in -1..=1i64 {
                    let xx = (x + dx).rem_euclid(w as i64) as usize;
                    let yy = (y + dy).rem_euclid(h as i64) as usize;
                    let j = yy * w + xx;
                    if !near[j] {
                        near[j] = true;
                        next.push(j);
                    }
                }
            }
        }
        if next.is_empty() {
            break;
        }
        front = next;
    }
    near.into_iter().map(|b| !b).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    /// A `w × h` texture of `f(x, y)` grey, each texel the mean of 4×4
    /// samples over its area (as a camera or a renderer's filter gives).
    fn texture(w: usize, h: usize, f: impl Fn(f32, f32) -> f32) -> Image {
        let mut t = Image::zeros(3, h, w);
        for y in 0..h {
            for x in 0..w {
                let mut acc = 0.0;
                for sy in 0..4 {
                    for sx in 0..4 {
                        acc += f(
                            x as f32 + (sx as f32 + 0.5) / 4.0,
                            y as f32 + (sy as f32 + 0.5) / 4.0,
                        );
                    }
                }
                t.set_rgb(y * w + x, Vec3::splat(acc / 16.0));
            }
        }
        t
    }

    /// A frontal `w × h` photo of a chessboard of `sq`-pixel squares, its
    /// coordinates the rectified square's (`u = (x + ½)/w`, `v = (y + ½)/w`),
    /// every pixel picked, and the fold of its true tile (one period, two
    /// squares, each way) with the tile's sides scaled by `off`.
    fn board_fold(w: usize, h: usize, sq: usize, off: [f32; 2]) -> (Coords, Image, Fold) {
        let mut colour = Image::zeros(3, h, w);
        for i in 0..w * h {
            let dark = ((i % w) / sq + (i / w) / sq) % 2 == 1;
            colour.set_rgb(i, Vec3::splat(if dark { 0.04 } else { 0.7 }));
        }
        // The frame's coordinates, `v` in units of the width (square pixels).
        let mut coords = Coords::identity(w, h, false);
        coords.v.iter_mut().for_each(|v| *v *= h as f32 / w as f32);
        let p = 2.0 * sq as f32 / w as f32;
        let fold = Fold {
            period: [p * off[0], p * off[1]],
            periods_per_tile: [1, 1],
            tile: [p * off[0], p * off[1]],
            aspect: off[0] / off[1],
            strength: [0.9, 0.9],
            centred: Some(0.9),
            refined: None,
            shear: [0.0, 0.0],
        };
        (coords, colour, fold)
    }

    #[test]
    fn refine_tile_lines_a_drifting_fold_up() {
        let (w, h, sq) = (240, 200, 20);
        let truth = 2.0 * sq as f32 / w as f32;
        for off in [[1.025f32, 1.0], [1.0, 0.97], [0.985, 1.02]] {
            let (coords, colour, fold) = board_fold(w, h, sq, off);
            let conf = vec![1.0; w * h];
            let r = refine_tile(&coords, &vec![true; w * h], &colour, &conf, fold);
            for (a, extent) in [w, h].into_iter().enumerate() {
                // The fold drifts by at most about a pixel over the photo
                // (the squares' edges are whole pixels: a smaller error
                // moves no pixel to another bin), from 5–6 pixels.
                let drift = (r.tile[a] / truth - 1.0).abs() * extent as f32;
                assert!(
                    drift <= 1.2,
                    "off {off:?}: tile {:?} against {truth}: drift {drift} px",
                    r.tile
                );
                assert_eq!(r.period[a], r.tile[a], "one period per tile");
            }
            assert!((r.aspect - r.tile[0] / r.tile[1]).abs() < 1e-5);
            assert_eq!((r.centred, r.strength), (fold.centred, fold.strength));
            // The diagnostics give the factors applied.
            let sc = r.refined.expect("a refined tile says so");
            for ((t, t0), k) in r.tile.iter().zip(fold.tile).zip(sc) {
                assert!((t / (t0 * k) - 1.0).abs() < 1e-6);
            }
        }
    }

    #[test]
    fn refine_tile_keeps_a_right_or_unmeasurable_fold() {
        let (w, h, sq) = (240, 200, 20);
        let conf = vec![1.0; w * h];
        // The true tile: nothing to gain.
        let (coords, colour, fold) = board_fold(w, h, sq, [1.0, 1.0]);
        assert_eq!(
            refine_tile(&coords, &vec![true; w * h], &colour, &conf, fold),
            fold
        );
        // A flat colour: every tile explains it alike.
        let flat = Image::zeros(3, h, w);
        let (_, _, off) = board_fold(w, h, sq, [1.02, 1.0]);
        assert_eq!(
            refine_tile(&coords, &vec![true; w * h], &flat, &conf, off),
            off
        );
        // Nothing picked, or no weight: the fold as it was.
        assert_eq!(
            refine_tile(&coords, &vec![false; w * h], &colour, &conf, off),
            off
        );
        assert_eq!(
            refine_tile(&coords, &vec![true; w * h], &colour, &vec![0.0; w * h], off),
            off
        );
    }

    /// A frontal `w × h` photo of a chessboard of `sq`-pixel squares whose
    /// photo coordinates `(x, y)` are `m · (x', y')` of the board's own
    /// (`m` row-major, about the photo's centre: a board turned or skewed
    /// against the frame), with [`board_fold`]'s coordinates and true tile.
    fn turned_board(w: usize, h: usize, sq: usize, m: [f32; 4]) -> (Coords, Image, Fold) {
        let (coords, _, fold) = board_fold(w, h, sq, [1.0, 1.0]);
        let det = m[0] * m[3] - m[1] * m[2];
        let mut colour = Image::zeros(3, h, w);
        // Each pixel the mean of 4 × 4 samples, as a lens and sensor
        // average it (hard pixel edges would alias with the bins).
        for i in 0..w * h {
            let mut sum = 0.0;
            for s in 0..16 {
                let x = (i % w) as f32 + (s % 4) as f32 / 4.0 + 0.125 - w as f32 / 2.0;
                let y = (i / w) as f32 + (s / 4) as f32 / 4.0 + 0.125 - h as f32 / 2.0;
                // The board's coordinates of the sample: m⁻¹ · (x, y).
                let bx = (m[3] * x - m[1] * y) / det;
                let by = (-m[2] * x + m[0] * y) / det;
                let k = (bx / sq as f32).floor() as i64 + (by / sq as f32).floor() as i64;
                sum += if k.rem_euclid(2) == 1 { 0.04 } else { 0.7 };
            }
            colour.set_rgb(i, Vec3::splat(sum / 16.0));
        }
        (coords, colour, fold)
    }

    #[test]
    fn refine_tile_straightens_a_turned_or_skewed_fold() {
        let (w, h, sq) = (240, 200, 20);
        let conf = vec![1.0; w * h];
        let turn = |deg: f32| {
            let (s, c) = deg.to_radians().sin_cos();
            [c, -s, s, c]
        };
        for m in [
            turn(2.0),
            turn(-3.5),
            [1.0, 0.04, 0.0, 1.0],
            [1.0, 0.0, -0.05, 1.0],
        ] {
            let (coords, colour, fold) = turned_board(w, h, sq, m);
            let r = refine_tile(&coords, &vec![true; w * h], &colour, &conf, fold);
            assert!(r.refined.is_some(), "{m:?}: not refined");
            // The board's two lattice steps (one period each way, in units
            // of the square: the coordinates are pixels over the width)
            // must each move the sheared coordinates by one whole tile
            // along its own axis and none along the other, to within a
            // drift of two pixels over the photo (the spread has minima a
            // fine step either side of the true lattice: at sub-pixel
            // drifts, how the pixels' phases fall into the bins decides).
            let [a, b] = r.shear;
            let p = 2.0 * sq as f32 / w as f32;
            for (step, whole) in [
                ([m[0] * p, m[2] * p], [1.0, 0.0]),
                ([m[1] * p, m[3] * p], [0.0, 1.0]),
            ] {
                let moved = [
                    (step[0] + a * step[1]) / r.tile[0],
                    (step[1] + b * step[0]) / r.tile[1],
                ];
                for ax in 0..2 {
                    // Repeats across the photo times the error of one, in
                    // pixels of one tile (2·sq).
                    let drift = (moved[ax] - whole[ax]).abs()
                        * (w as f32 / (2.0 * sq as f32))
                        * 2.0
                        * sq as f32;
                    assert!(
                        drift <= 2.0,
                        "{m:?}: fold {r:?} drifts {drift} px along axis {ax}"
                    );
                }
            }
            // Pixels one lattice step apart fold onto each other.
            let f = fold_coords(&coords, &r);
            let (x0, y0) = (60.0f32, 50.0f32);
            let at = |x: f32, y: f32| (y.round() as usize) * w + x.round() as usize;
            let (i, j) = (
                at(x0, y0),
                at(x0 + 2.0 * sq as f32 * m[0], y0 + 2.0 * sq as f32 * m[2]),
            );
            let d = |s: f32, t: f32| (s - t - (s - t).round()).abs();
            assert!(
                d(f.u[i], f.u[j]) < 0.06 && d(f.v[i], f.v[j]) < 0.06,
                "{m:?}: {r:?}"
            );
        }
        // The sides on the plane undo the shear.
        let r = Fold {
            shear: [0.1, 0.0],
            ..board_fold(w, h, sq, [1.0, 1.0]).2
        };
        let s = r.sides();
        assert!((s[0] - r.tile[0]).abs() < 1e-6);
        assert!((s[1] - r.tile[1] * 1.01f32.sqrt()).abs() < 1e-6);
    }

    #[test]
    fn fold_coords_shears_before_wrapping() {
        let c = Coords {
            width: 2,
            height: 1,
            u: vec![0.3, f32::NAN],
            v: vec![0.5, 0.2],
            wrap: false,
        };
        let (_, _, fold) = board_fold(10, 10, 1, [1.0, 1.0]);
        let fold = Fold {
            tile: [0.25, 0.4],
            shear: [0.1, -0.2],
            ..fold
        };
        let g = fold_coords(&c, &fold);
        // u' = frac((0.3 + 0.05) / 0.25) = 0.4, v' = frac((0.5 − 0.06) / 0.4) = 0.1.
        assert!(
            (g.u[0] - 0.4).abs() < 1e-5 && (g.v[0] - 0.1).abs() < 1e-5,
            "{g:?}"
        );
        assert!(g.u[1].is_nan() && g.v[1].is_nan() && g.wrap);
    }

    /// A grid of tiles `px × py` with grout lines `g` wide, and brightness
    /// jitter per tile from a hash.
    fn tiles(px: f32, py: f32, g: f32) -> impl Fn(f32, f32) -> f32 {
        move |x, y| {
            let (tx, ty) = ((x / px).floor(), (y / py).floor());
            let (fx, fy) = (x - tx * px, y - ty * py);
            if fx < g || fy < g {
                0.9
            } else {
                // A little brightness per tile, from a hash of the tile.
                let mut z = (tx as i64 as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
                    ^ (ty as i64 as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F);
                z ^= z >> 31;
                z = z.wrapping_mul(0xBF58_476D_1CE4_E5B9);
                z ^= z >> 29;
                0.3 + 0.05 * (z % 1000) as f32 / 1000.0
            }
        }
    }

    #[test]
    fn the_periods_of_a_tile_grid_are_found_to_a_fraction_of_a_texel() {
        for &(px, py, w, h) in &[
            (12.5f32, 20.0f32, 200usize, 160usize),
            (7.3, 7.3, 100, 90),
            (31.0, 9.25, 300, 120),
            // Larger than MAX_SIDE: measured downsampled, reported full size.
            (40.4, 26.0, 700, 500),
        ] {
            let t = texture(w, h, tiles(px, py, 2.0));
            let (x, y) = detect(&t, &vec![true; w * h]);
            let (x, y) = (x.expect("x period"), y.expect("y period"));
            assert!((x.texels - px).abs() < 0.02 * px, "{px}: {x:?}");
            assert!((y.texels - py).abs() < 0.02 * py, "{py}: {y:?}");
            assert!(x.strength >= MIN_PEAK && y.strength >= MIN_PEAK);
        }
    }

    /// Bricks 24 × 10 (mortar 2 wide, 0.85; bricks 0.35) with every other
    /// course shifted by half a brick.
    fn running_bond(x: f32, y: f32) -> f32 {
        let course = (y / 10.0).floor();
        let x = x + if course as i64 % 2 == 1 { 12.0 } else { 0.0 };
        let (fx, fy) = (x.rem_euclid(24.0), y.rem_euclid(10.0));
        if fx < 2.0 || fy < 2.0 {
            0.85
        } else {
            0.35
        }
    }

    #[test]
    fn running_bond_bricks_repeat_every_two_courses() {
        // Along y the pattern repeats after two courses (20), along x after
        // one brick (24).
        let (w, h) = (240, 200);
        let (x, y) = detect(&texture(w, h, running_bond), &vec![true; w * h]);
        assert!((x.unwrap().texels - 24.0).abs() < 0.3, "{x:?}");
        assert!((y.unwrap().texels - 20.0).abs() < 0.3, "{y:?}");
    }

    /// A checkerboard, running bond bricks and a half-drop pattern repeat
    /// shifted by half a period along both axes, with holes too; a tile
    /// grid, a repeated random motif, a checkerboard of four colours and one
    /// whose dark squares alternate between two darks do not.
    #[test]
    fn centred_repeats_are_found_and_others_are_not() {
        let (w, h) = (200usize, 180usize);
        let checker = |x: f32, y: f32| {
            if ((x / 9.5).floor() + (y / 9.5).floor()) as i64 % 2 == 0 {
                0.8
            } else {
                0.2
            }
        };
        // A motif of 13 × 11 repeated, every other column of motifs
        // dropped by half its height.
        let mut rng = picker_tensor::Rng::new(21);
        let motif: Vec<f32> = (0..13 * 11).map(|_| rng.uniform(0.0, 1.0)).collect();
        let motif2 = motif.clone();
        let half_drop = move |x: f32, y: f32| {
            let col = (x / 13.0).floor() as i64;
            let y = y + if col % 2 == 1 { 5.5 } else { 0.0 };
            let (mx, my) = (x.rem_euclid(13.0) as usize, y.rem_euclid(11.0) as usize);
            motif2[my.min(10) * 13 + mx.min(12)]
        };
        let plain_motif = move |x: f32, y: f32| {
            let (mx, my) = (x.rem_euclid(13.0) as usize, y.rem_euclid(11.0) as usize);
            motif[my.min(10) * 13 + mx.min(12)]
        };
        // Four colours: the squares of one colour repeat only every two
        // squares along each axis, not along the diagonal.
        let four = |x: f32, y: f32| {
            let (i, j) = ((x / 9.5).floor() as i64, (y / 9.5).floor() as i64);
            [0.1, 0.4, 0.6, 0.9][(i.rem_euclid(2) + 2 * j.rem_euclid(2)) as usize]
        };
        // White and two darks: the dark squares alternate between 0.15
        // and 0.45, so they repeat every two squares, not along the diagonal.
        let two_darks = |x: f32, y: f32| {
            let (i, j) = ((x / 9.5).floor() as i64, (y / 9.5).floor() as i64);
            if (i + j).rem_euclid(2) == 0 {
                0.9
            } else if i.rem_euclid(2) == 0 {
                0.15
            } else {
                0.45
            }
        };
        let mut holes = vec![true; w * h];
        let mut rng = picker_tensor::Rng::new(5);
        for _ in 0..20 {
            let (x0, y0) = (rng.range(0, w - 1), rng.range(0, h - 1));
            for y in y0..(y0 + 15).min(h) {
                for x in x0..(x0 + 15).min(w) {
                    holes[y * w + x] = false;
                }
            }
        }
        let all = vec![true; w * h];
        let centred = |t: &Image, known: &[bool]| {
            let (x, y) = detect(t, known);
            let (x, y) = (x.expect("an x period"), y.expect("a y period"));
            (x, y, centring(t, known, x, y))
        };
        for (name, t, yes) in [
            ("checker", texture(w, h, checker), true),
            ("bond", texture(w, h, running_bond), true),
            ("half-drop", texture(w, h, &half_drop), true),
            ("tiles", texture(w, h, tiles(12.5, 20.0, 2.0)), false),
            ("motif", texture(w, h, plain_motif), false),
            ("four colours", texture(w, h, four), false),
            ("two darks", texture(w, h, two_darks), false),
        ] {
            for known in [&all, &holes] {
                let (x, y, c) = centred(&t, known);
                assert_eq!(c.is_some(), yes, "{name}: {x:?} {y:?} {c:?}");
                if let Some(c) = c {
                    assert!(
                        c >= CENTRE_SHARE * x.strength.min(y.strength),
                        "{name}: {c}"
                    );
                }
            }
        }
        // The periods the centring halves: 19 for the checker, 24 × 20 for
        // the bond, 26 × 11 for the half-drop.
        let (x, y, _) = centred(&texture(w, h, checker), &all);
        assert!((x.texels - 19.0).abs() < 0.3 && (y.texels - 19.0).abs() < 0.3);
        let (x, y, _) = centred(&texture(w, h, &half_drop), &all);
        assert!(
            (x.texels - 26.0).abs() < 0.3 && (y.texels - 11.0).abs() < 0.3,
            "{x:?} {y:?}"
        );
        // Downsampled (larger than MAX_SIDE) the same.
        let (w2, h2) = (600usize, 520usize);
        let big = texture(w2, h2, |x, y| checker(x / 2.0, y / 2.0));
        assert!(centred(&big, &vec![true; w2 * h2]).2.is_some());
    }

    #[test]
    fn centring_shifts_by_half_a_period_in_tile_units() {
        let p = |texels: f32| AxisPeriod {
            texels,
            strength: 0.9,
            double: None,
        };
        let f = fold_tile(p(10.0), p(40.0), 200);
        assert_eq!(f.centring_shift(), None);
        let f = Fold {
            centred: Some(0.95),
            ..f
        };
        assert_eq!(f.periods_per_tile, [4, 1]);
        assert_eq!(f.centring_shift(), Some([0.125, 0.5]));
    }

    #[test]
    fn the_same_periods_on_any_number_of_threads() {
        let (w, h) = (150usize, 130usize);
        let t = texture(w, h, tiles(13.3, 9.7, 2.0));
        let known = vec![true; w * h];
        let one = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        let a = one.install(|| detect(&t, &known));
        let b = detect(&t, &known);
        assert!(a.0.is_some() && a.1.is_some());
        let bits = |p: Option<AxisPeriod>| p.map(|p| (p.texels.to_bits(), p.strength.to_bits()));
        assert_eq!((bits(a.0), bits(a.1)), (bits(b.0), bits(b.1)));
    }

    #[test]
    fn a_shading_drift_does_not_hide_a_weak_repeat() {
        // A tile grid under a strong drift of shading across the texture:
        // with each row's mean removed the drift swamps the repeat along x;
        // with its linear trend removed too, the period is found.
        let (w, h, px) = (192usize, 160usize, 21.5f32);
        let f = |x: f32, y: f32| tiles(px, 13.0, 1.5)(x, y) + 2.0 * x / w as f32;
        let t = texture(w, h, f);
        let known = vec![true; w * h];
        let luma: Vec<f32> = (0..w * h).map(|i| texel_luma(&t, i)).collect();
        let found = |trend: bool| {
            let v = without_line_trends(&luma, &known, w, h, 0, trend);
            period_of(&autocorrelation(
                Grid {
                    v: &v,
                    ok: &known,
                    w,
                    h,
                },
                (1, 0),
                (w / 2) * SUBSTEPS,
            ))
        };
        let p = found(true).expect("a period with the trend removed");
        assert!((p.texels / SUBSTEPS as f32 - px).abs() < 0.5, "{p:?}");
        assert!(found(false).is_none(), "{:?}", found(false));
        let (x, _) = detect(&t, &known);
        assert!((x.expect("x period").texels - px).abs() < 0.5, "{x:?}");
    }

    #[test]
    fn holes_do_not_hide_the_period() {
        // 40% of the texels unknown (blocks, like a mask's gaps), set to a
        // wrong value that must not count.
        let (w, h, px, py) = (160usize, 160usize, 16.0f32, 11.0f32);
        let mut t = texture(w, h, tiles(px, py, 2.0));
        let mut rng = picker_tensor::Rng::new(3);
        let mut known = vec![true; w * h];
        for _ in 0..40 {
            let (x0, y0) = (rng.range(0, w - 1), rng.range(0, h - 1));
            for y in y0..(y0 + 20).min(h) {
                for x in x0..(x0 + 20).min(w) {
                    known[y * w + x] = false;
                    t.set_rgb(y * w + x, Vec3::splat(5.0));
                }
            }
        }
        let (x, y) = detect(&t, &known);
        assert!((x.unwrap().texels - px).abs() < 0.3, "{x:?}");
        assert!((y.unwrap().texels - py).abs() < 0.3, "{y:?}");
    }

    #[test]
    fn no_period_in_noise_a_gradient_or_a_single_repeat() {
        let (w, h) = (128usize, 96usize);
        let mut rng = picker_tensor::Rng::new(7);
        let noise: Vec<f32> = (0..w * h).map(|_| rng.uniform(0.0, 1.0)).collect();
        let t = texture(w, h, |x, y| {
            noise[(y as usize).min(h - 1) * w + (x as usize).min(w - 1)]
        });
        assert_eq!(detect(&t, &vec![true; w * h]), (None, None));
        // Smooth: a gradient and a slow wave (its period, 200, is longer
        // than half the texture).
        let t = texture(w, h, |x, y| {
            0.01 * x + 0.3 * (y / 200.0 * std::f32::consts::TAU).sin()
        });
        assert_eq!(detect(&t, &vec![true; w * h]), (None, None));
        // Nothing known, a constant, an empty image.
        let t = texture(w, h, tiles(10.0, 10.0, 2.0));
        assert_eq!(detect(&t, &vec![false; w * h]), (None, None));
        let c = texture(w, h, |_, _| 0.5);
        assert_eq!(detect(&c, &vec![true; w * h]), (None, None));
        assert_eq!(detect(&Image::zeros(3, 0, 0), &[]), (None, None));
    }

    #[test]
    fn tiles_hold_whole_periods_and_are_closest_to_square() {
        let p = |texels: f32| AxisPeriod {
            texels,
            strength: 0.9,
            double: None,
        };
        let f = fold_tile(p(10.0), p(40.0), 200);
        assert_eq!(f.periods_per_tile, [4, 1]);
        assert!((f.aspect - 1.0).abs() < 1e-6 && (f.tile[0] - 0.2).abs() < 1e-6);
        assert_eq!(fold_tile(p(10.0), p(25.0), 200).periods_per_tile, [5, 2]);
        // Each side at most half the texture: two tiles seen.
        let f = fold_tile(p(60.0), p(45.0), 128);
        assert_eq!(f.periods_per_tile, [1, 1]);
        assert!((f.aspect - 60.0 / 45.0).abs() < 1e-6);
        assert!((f.period[0] - 60.0 / 128.0).abs() < 1e-6);
        // Folded coordinates: the fraction of the tile, wrapping; none stays none.
        let c = Coords {
            width: 3,
            height: 1,
            u: vec![0.05, 0.45, f32::NAN],
            v: vec![0.1, 0.9, 0.5],
            wrap: false,
        };
        let fold = fold_tile(p(40.0), p(40.0), 200);
        let g = fold_coords(&c, &fold);
        assert!(g.wrap);
        assert!((g.u[0] - 0.25).abs() < 1e-5 && (g.u[1] - 0.25).abs() < 1e-5);
        assert!((g.v[0] - 0.5).abs() < 1e-5 && (g.v[1] - 0.5).abs() < 1e-5);
        assert!(g.u[2].is_nan());
    }

    #[test]
    fn a_frontal_tiled_square_folds_into_its_tile() {
        // A 160² photo of the rectified square (u = x/160, not wrapping)
        // showing tiles 20 × 16 pixels: folded by a tile of whole periods,
        // close to square, the coordinates wrap and every repeat lands in the
        // same place.
        let (w, h) = (160usize, 160usize);
        let img = texture(w, h, tiles(20.0, 16.0, 2.0));
        let coords = Coords::identity(w, h, false);
        let (mask, conf) = (vec![true; w * h], vec![1.0; w * h]);
        let (folded, fold) = fold_if_periodic(coords, &mask, None, &img, &conf, 160);
        let fold = fold.expect("a fold");
        assert!((fold.period[0] - 20.0 / 160.0).abs() < 0.01, "{fold:?}");
        assert!((fold.period[1] - 16.0 / 160.0).abs() < 0.01, "{fold:?}");
        assert!((fold.aspect - 1.0).abs() < 0.1, "{fold:?}");
        assert!(folded.wrap);
        // Pixels one tile apart share their folded coordinates.
        let [kx, ky] = fold.periods_per_tile;
        let (i, j) = (30 * w + 7, (30 + 16 * ky) * w + 7 + 20 * kx);
        assert!(
            (folded.u[i] - folded.u[j]).abs() < 0.02 && (folded.v[i] - folded.v[j]).abs() < 0.02
        );
        // Noise does not fold.
        let mut rng = picker_tensor::Rng::new(2);
        let noise: Vec<f32> = (0..w * h).map(|_| rng.uniform(0.0, 1.0)).collect();
        let img = texture(w, h, |x, y| {
            noise[(y as usize).min(h - 1) * w + (x as usize).min(w - 1)]
        });
        let c = folded.clone();
        let (same, none) = fold_if_periodic(c, &mask, None, &img, &conf, 160);
        assert!(none.is_none() && same.u == folded.u);
    }

    #[test]
    fn the_fundamental_wins_over_its_multiples() {
        // A checker of 8-texel squares: r peaks at 16, 32, 48 …; the period
        // is 16, not a multiple.
        let f = |x: f32, y: f32| (((x / 8.0).floor() + (y / 8.0).floor()) as i64 & 1) as f32;
        let (w, h) = (128, 128);
        let (x, y) = detect(&texture(w, h, f), &vec![true; w * h]);
        assert!((x.unwrap().texels - 16.0).abs() < 0.2, "{x:?}");
        assert!((y.unwrap().texels - 16.0).abs() < 0.2, "{y:?}");
    }

    #[test]
    fn whole_repeats_need_a_whole_number_within_the_tolerance() {
        let p = |texels: f32| AxisPeriod {
            texels,
            strength: 0.9,
            double: None,
        };
        assert_eq!(whole_repeats(p(25.0), 100), Some(4));
        // 4 periods drift 0.1 of a period from the side: still 4.
        assert_eq!(whole_repeats(p(25.6), 100), Some(4));
        // 3.5 periods: not whole.
        assert_eq!(whole_repeats(p(100.0 / 3.5), 100), None);
        // One period (the square itself), too many, none.
        assert_eq!(whole_repeats(p(100.0), 100), None);
        assert_eq!(whole_repeats(p(3.0), 3 * (MAX_UV_REPEATS + 1)), None);
        assert_eq!(
            whole_repeats(p(3.0), 3 * MAX_UV_REPEATS),
            Some(MAX_UV_REPEATS)
        );
        for bad in [0.0, -4.0, f32::NAN] {
            assert_eq!(whole_repeats(p(bad), 100), None);
        }
        assert_eq!(whole_repeats(p(10.0), 0), None);
    }

    #[test]
    fn a_double_that_correlates_far_better_is_the_period() {
        let p = AxisPeriod {
            texels: 12.0,
            strength: 0.4,
            double: Some(0.55),
        };
        let d = prefer_double(p);
        assert_eq!((d.texels, d.strength, d.double), (24.0, 0.55, None));
        let close = AxisPeriod {
            double: Some(0.45),
            ..p
        };
        assert_eq!(prefer_double(close), close);
        let none = AxisPeriod { double: None, ..p };
        assert_eq!(prefer_double(none), none);
    }

    #[test]
    fn unfold_lays_whole_copies_and_resamples_by_area() {
        let mut rng = picker_tensor::Rng::new(5);
        let mut tile = Image::zeros(2, 4, 6);
        tile.data
            .iter_mut()
            .for_each(|v| *v = rng.uniform(0.0, 1.0));
        // 2 × 3 copies of a 6 × 4 tile fill a 12² square exactly.
        let sq = unfold(&tile, [2, 3], 12);
        assert_eq!((sq.channels, sq.width, sq.height), (2, 12, 12));
        for c in 0..2 {
            for y in 0..12 {
                for x in 0..12 {
                    let want = tile.data[c * 24 + (y % 4) * 6 + x % 6];
                    assert_eq!(sq.data[c * 144 + y * 12 + x], want);
                }
            }
        }
        // Three copies of a 6-wide tile into 9 texels: each texel the area
        // mean of two texels of the copies laid side by side.
        let one = Image {
            channels: 1,
            height: 1,
            width: 6,
            data: (0..6).map(|i| i as f32).collect(),
        };
        let sq = unfold(&one, [3, 1], 9);
        let row: Vec<f32> = (0..18).map(|i| (i % 6) as f32).collect();
        for x in 0..9 {
            let want = 0.5 * (row[2 * x] + row[2 * x + 1]);
            assert!(
                (sq.data[x] - want).abs() < 1e-5,
                "{x}: {} vs {want}",
                sq.data[x]
            );
        }
        assert_eq!(
            unfold(&Image::zeros(3, 0, 0), [2, 2], 8).data,
            vec![0.0; 3 * 64]
        );
    }

    #[test]
    fn distance_at_least_matches_brute_force_on_a_torus() {
        let mut rng = picker_tensor::Rng::new(9);
        for &(w, h, share) in &[
            (17usize, 11usize, 0.05f32),
            (8, 8, 0.0),
            (5, 13, 0.3),
            (1, 1, 1.0),
        ] {
            let set: Vec<bool> = (0..w * h).map(|_| rng.uniform(0.0, 1.0) < share).collect();
            for d in 0..6 {
                let got = distance_at_least(&set, w, h, d);
                for (i, &g) in got.iter().enumerate() {
                    let (x, y) = ((i % w) as i64, (i / w) as i64);
                    let dist = (0..w * h)
                        .filter(|&j| set[j])
                        .map(|j| {
                            let dx = (x - (j % w) as i64).rem_euclid(w as i64);
                            let dy = (y - (j / w) as i64).rem_euclid(h as i64);
                            dx.min(w as i64 - dx).max(dy.min(h as i64 - dy)) as usize
                        })
                        .min();
                    let want = dist.is_none_or(|e| e >= d);
                    assert_eq!(g, want, "{w}x{h} d {d} texel {i}");
                }
            }
        }
    }

    #[test]
    fn fill_from_repeats_fills_far_holes_only() {
        let (w, h) = (10usize, 10usize);
        let mut tex = Image::zeros(3, h, w);
        let mut known = vec![false; w * h];
        for y in 0..h {
            for x in 0..3 {
                known[y * w + x] = true;
                tex.set_rgb(y * w + x, Vec3::splat(0.25));
            }
        }
        let mut over = Image::zeros(3, h, w);
        over.data.iter_mut().for_each(|v| *v = 0.75);
        let mut seen = Image::zeros(1, h, w);
        seen.data.iter_mut().for_each(|v| *v = 1.0);
        // Unseen by the repeats at column 6.
        for y in 0..h {
            seen.data[y * w + 6] = 0.5;
        }
        let (out, k, filled) = fill_from_repeats(&tex, &known, &over, &seen, 3);
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                // Columns 0–2 observed; 3, 4 (and 9, 0 wrapping: 9 is 1
                // away from 0) too near; 6 unseen by the repeats.
                let far = matches!(x, 5 | 7);
                if x < 3 {
                    assert!(k[i] && out.rgb(i) == Vec3::splat(0.25));
                } else if far {
                    assert!(k[i] && out.rgb(i) == Vec3::splat(0.75), "{x}");
                } else {
                    assert!(!k[i] && out.rgb(i) == Vec3::ZERO, "{x}");
                }
            }
        }
        assert_eq!(filled, 2 * h);
    }

    #[test]
    fn a_square_that_repeats_folds_and_its_unseen_repeats_are_filled() {
        // A frontal square with wrapped UVs (u = x/120) showing a grid of
        // 4 × 3 tiles, of which the photo sees only the left 40% and the
        // top 55%: the repeats are found, and the unseen tiles filled from
        // the seen ones match the truth.
        let (w, h) = (120usize, 120usize);
        let truth = texture(w, h, tiles(30.0, 40.0, 3.0));
        let coords = Coords::identity(w, h, true);
        let mask: Vec<bool> = (0..w * h).map(|i| i % w < 48 && i / w < 66).collect();
        let conf = vec![1.0; w * h];
        let (folded, rep) =
            fold_uv_if_periodic(&coords, &mask, &truth, &conf, 120).expect("repeats");
        assert_eq!(rep.repeats, [4, 3], "{rep:?}");
        // Pixels one tile apart share their folded coordinates.
        let (i, j) = (10 * w + 5, 50 * w + 35);
        assert!(
            (folded.u[i] - folded.u[j]).abs() < 1e-4 && (folded.v[i] - folded.v[j]).abs() < 1e-4
        );
        let size = 120;
        let own = crate::reproject::reproject(&coords, &mask, &truth, &conf, size);
        let c = complete_from_repeats(&own, &folded, &rep, &mask, &truth, &conf);
        let (out, known, filled) = (&c.texture, &c.known, c.filled);
        assert!(filled > size * size / 3, "{filled}");
        // Filled texels take the tile's coverage; observed ones keep theirs.
        for (i, (&k, &o)) in known.iter().zip(&own.known).enumerate() {
            if o {
                assert_eq!(c.coverage.data[i], own.coverage.data[i]);
            } else if k {
                assert!(c.coverage.data[i] > 0.0);
            }
        }
        // The filled texels hold the grid: small error against the truth
        // (its tiles differ a little in brightness, the grout does not move).
        let (mut se, mut n) = (0.0f64, 0usize);
        for (i, (&k, &o)) in known.iter().zip(&own.known).enumerate() {
            if k && !o {
                se += f64::from((out.rgb(i) - truth.rgb(i)).length_squared());
                n += 1;
            }
        }
        let rmse = (se / n as f64 / 3.0).sqrt();
        assert!(rmse < 0.03, "rmse {rmse}");
        // A texture that does not repeat does not fold.
        let mut rng = picker_tensor::Rng::new(4);
        let noise: Vec<f32> = (0..w * h).map(|_| rng.uniform(0.0, 1.0)).collect();
        let img = texture(w, h, |x, y| {
            noise[(y as usize).min(h - 1) * w + (x as usize).min(w - 1)]
        });
        assert!(fold_uv_if_periodic(&coords, &mask, &img, &conf, 120).is_none());
    }

    /// A square of side 150 whose pattern repeats exactly 21 times along x
    /// (a weave-like sharp stripe, period 7.14 texels), known only in a
    /// 48-texel window: a period measured 1.5 % off drifts by 0.3 of a
    /// period over the side, so `whole_repeats` refuses it, and
    /// `snap_repeats` finds the 21 the texels show. A pattern whose period
    /// does not divide the side (7.0: 21.4 repeats) seen over most of the
    /// square is not snapped; nor is an axis along which nothing varies,
    /// nor a period more than 5 % from `side / n` for every `n`.
    #[test]
    fn snap_repeats_finds_the_whole_number_a_small_window_shows() {
        let side = 150;
        let stripes = |period: f32| {
            move |x: f32, _y: f32| {
                if (x / period).fract() < 0.4 {
                    0.8
                } else {
                    0.2
                }
            }
        };
        let window = |x0: usize, y0: usize, n: usize| -> Vec<bool> {
            (0..side * side)
                .map(|i| {
                    let (x, y) = (i % side, i / side);
                    (x0..x0 + n).contains(&x) && (y0..y0 + n).contains(&y)
                })
                .collect()
        };
        let exact = texture(side, side, stripes(side as f32 / 21.0));
        let known = window(37, 61, 48);
        let measured = AxisPeriod {
            texels: side as f32 / 21.0 * 1.015,
            strength: 0.9,
            double: None,
        };
        assert_eq!(whole_repeats(measured, side), None);
        assert_eq!(
            snap_repeats(&exact, &known, (1, 0), measured, side),
            Some(21)
        );
        let low = AxisPeriod {
            texels: side as f32 / 21.0 * 0.988,
            ..measured
        };
        assert_eq!(snap_repeats(&exact, &known, (1, 0), low, side), Some(21));
        // Along y nothing varies: no correlation to score.
        assert_eq!(snap_repeats(&exact, &known, (0, 1), measured, side), None);
        // More than SNAP_TOLERANCE from side/n for every n (2.5 repeats):
        // no candidate. (Near 21 repeats, both neighbours are within it and
        // the texels choose.)
        let between = AxisPeriod {
            texels: side as f32 / 2.5,
            ..measured
        };
        assert_eq!(snap_repeats(&exact, &known, (1, 0), between, side), None);
        // A period of 7.0 (21.4 repeats) over most of the square: the
        // multiples of 150/21 and 150/22 drift off it.
        let off = texture(side, side, stripes(7.0));
        let wide = window(5, 5, 140);
        let seen = AxisPeriod {
            texels: 7.0,
            ..measured
        };
        assert_eq!(snap_repeats(&off, &wide, (1, 0), seen, side), None);
        // Mismatched `known` or an empty texture: nothing.
        assert_eq!(
            snap_repeats(&exact, &known[1..], (1, 0), measured, side),
            None
        );
        assert_eq!(
            snap_repeats(&Image::zeros(3, 0, 0), &[], (1, 0), measured, side),
            None
        );
    }
}
