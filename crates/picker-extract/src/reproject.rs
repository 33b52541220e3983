//! Reprojection of the picked pixels into the texture square (thesis §3.3).
//!
//! Every picked pixel carries texture coordinates `(u, v)` (the IRN's wrapped
//! UVs, or plane coordinates from [`crate::plane`]) and a de-lit colour. The
//! colours are splatted into a `size × size` texture with the pixel's own
//! footprint: a tent one pixel wide on each pixel axis, mapped into the texture
//! by the coordinates' Jacobian (`Footprint`: an oblique parallelogram for a
//! surface seen at a grazing angle, so a pixel is spread along the direction it
//! is stretched in and not across it; pixels seen from afar cover the texels
//! between them), accumulating per-texel weights. The
//! texel colour is the weighted mean; one reweighting pass downweights samples
//! far from their texel's mean (Cauchy weights), which rejects misplaced UVs
//! and highlights that survived de-lighting; [`BACK_PROJECTIONS`] rounds of
//! damped iterative back-projection then take back part of the splat's blur.
//! Coverage is `W/(W + ½)` of the accumulated weight `W` (0 never observed,
//! → 1 well observed). A texel counts as known for the inpainter when its
//! observation weight (the same tent weights without the pixels' confidence)
//! reaches [`KNOWN_WEIGHT`] (or, when no texel reaches it, half the largest):
//! low-confidence pixels still observe a texel, they only count less in its
//! colour. When the texture is capped below the photo's density (a
//! 12-megapixel photo, a 1024² texture), coherent blocks of sub-texel pixels
//! are merged into one sample each first ([`MAX_MERGE_BLOCK`]): they would all
//! get the smallest tent anyway.

use glam::Vec3;
use picker_render::io::Image;
use rayon::prelude::*;

/// Observation weight (tent weights per unit of footprint, whatever the
/// pixels' confidence) from which a texel counts as known.
pub const KNOWN_WEIGHT: f32 = 0.05;
/// Largest half-axis of a splat footprint in texels (very distant or very
/// oblique pixels are blurred, not spread further); the smallest is one texel.
pub const MAX_SPLAT_RADIUS: f32 = 4.0;

/// Texture coordinates of pixels: per-pixel `(u, v)` on a `width × height`
/// grid, `NaN` where a pixel has none.
#[derive(Clone, Debug)]
pub struct Coords {
    /// Columns.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// `u` per pixel.
    pub u: Vec<f32>,
    /// `v` per pixel.
    pub v: Vec<f32>,
    /// Whether the coordinates wrap (periodic texture; `false`: outside [0,1) is dropped).
    pub wrap: bool,
}

impl Coords {
    /// The coordinates of a `w × h` image that is the texture square itself
    /// (a frontal photo of it filling the frame): pixel centre `(x, y)` at
    /// `((x + ½)/w, (y + ½)/h)`.
    pub fn identity(w: usize, h: usize, wrap: bool) -> Self {
        Self {
            width: w,
            height: h,
            u: (0..w * h)
                .map(|i| ((i % w) as f32 + 0.5) / w as f32)
                .collect(),
            v: (0..w * h)
                .map(|i| ((i / w) as f32 + 0.5) / h as f32)
                .collect(),
            wrap,
        }
    }

    fn delta(&self, a: f32, b: f32) -> f32 {
        let d = b - a;
        if self.wrap {
            d - round_f32(d)
        } else {
            d
        }
    }

    /// The texture-square area covered by pixel `i` (|Jacobian| of the
    /// coordinates by forward differences), if its right and lower neighbours
    /// are in `mask` too.
    pub fn pixel_area(&self, mask: &[bool], i: usize) -> Option<f32> {
        let w = self.width;
        self.pixel_area_at(mask, i % w, i / w)
    }

    /// [`Coords::pixel_area`] of the pixel at column `x`, row `y` (`x` below
    /// the width): the quantiles call it for millions of pixels, and the
    /// index's division by the width was a good part of its cost.
    #[inline]
    fn pixel_area_at(&self, mask: &[bool], x: usize, y: usize) -> Option<f32> {
        let w = self.width;
        let i = y * w + x;
        if x + 1 >= w || y + 1 >= self.height || !mask[i] || !mask[i + 1] || !mask[i + w] {
            return None;
        }
        let (u0, v0) = (self.u[i], self.v[i]);
        let (ux, vx) = (self.delta(u0, self.u[i + 1]), self.delta(v0, self.v[i + 1]));
        let (uy, vy) = (self.delta(u0, self.u[i + w]), self.delta(v0, self.v[i + w]));
        let a = (ux * vy - uy * vx).abs();
        a.is_finite().then_some(a)
    }

    /// The coordinates' Jacobian at picked pixel `i`: how `(u, v)` move per
    /// pixel step along `x` and along `y` (`(du/dx, dv/dx), (du/dy, dv/dy)`),
    /// each by a forward difference to the next picked pixel, or a backward
    /// one where that is not picked; `None` where `i` is not picked, a step
    /// has no picked neighbour or a difference is not finite.
    pub fn jacobian(&self, mask: &[bool], i: usize) -> Option<([f32; 2], [f32; 2])> {
        let w = self.width;
        let (x, y) = (i % w, i / w);
        if !mask[i] {
            return None;
        }
        let step = |fwd: Option<usize>, back: Option<usize>| {
            let (a, b) = match (fwd.filter(|&j| mask[j]), back.filter(|&j| mask[j])) {
                (Some(j), _) => (i, j),
                (None, Some(j)) => (j, i),
                (None, None) => return None,
            };
            let d = [
                self.delta(self.u[a], self.u[b]),
                self.delta(self.v[a], self.v[b]),
            ];
            d.iter().all(|t| t.is_finite()).then_some(d)
        };
        let jx = step((x + 1 < w).then_some(i + 1), (x > 0).then(|| i - 1))?;
        let jy = step(
            (y + 1 < self.height).then_some(i + w),
            (y > 0).then(|| i - w),
        )?;
        Some((jx, jy))
    }

    /// The `q`-quantile (0 = smallest) of the texture-square area per picked pixel.
    pub fn area_quantile(&self, mask: &[bool], q: f32) -> Option<f32> {
        self.area_quantile_rows(mask, q, 1)
    }

    /// [`Coords::area_quantile`] over every `step`-th row only (`step ≥ 1`):
    /// an estimate at a fraction of the cost.
    ///
    /// Found in parallel without collecting the areas
    /// ([`crate::select::kth_smallest`]): the value that
    /// `select_nth_unstable` on the collected areas gives.
    fn area_quantile_rows(&self, mask: &[bool], q: f32, step: usize) -> Option<f32> {
        if self.width == 0 || self.height == 0 {
            return None;
        }
        let (w, step) = (self.width, step.max(1));
        let rows = self.height.div_ceil(step);
        let area = |j: usize| {
            let (r, x) = (j / w, j % w);
            self.pixel_area_at(mask, x, r * step).filter(|&a| a > 0.0)
        };
        let rank = |len: usize| Some(vec![((len - 1) as f32 * q.clamp(0.0, 1.0)).round() as usize]);
        crate::select::kth_smallest(rows * w, area, rank).map(|v| v[0])
    }

    /// The texture-square area per pixel at which the texture is sized: the
    /// [`DENSITY_QUANTILE`] quantile of the picked pixels' texture areas (the
    /// median: half the pixels see the texture at least this finely).
    ///
    /// Photos taller than [`SIZING_ROWS`] rows are measured on every
    /// `height / SIZING_ROWS`-th row (an estimate: the size is rounded to a
    /// multiple of 4 and capped anyway).
    pub fn sizing_area(&self, mask: &[bool]) -> Option<f32> {
        self.area_quantile_rows(mask, DENSITY_QUANTILE, (self.height / SIZING_ROWS).max(1))
    }

    /// The fraction of a `cells × cells` grid over the texture square that
    /// the coordinates of the `mask`ed pixels fall into (wrapped into [0,1)
    /// when the coordinates wrap, else only those inside). Near 0 when the
    /// coordinates have collapsed onto a point or a line; `None` for an
    /// empty mask, `cells == 0` or a grid too large to hold (`cells²`
    /// overflows).
    pub fn footprint(&self, mask: &[bool], cells: usize) -> Option<f64> {
        if cells == 0 || cells.checked_mul(cells).is_none() || !mask.iter().any(|&m| m) {
            return None;
        }
        let mut hit = vec![false; cells * cells];
        let cell = |t: f32| -> Option<usize> {
            let t = if self.wrap { t - t.floor() } else { t };
            (t.is_finite() && (0.0..1.0).contains(&t))
                .then(|| ((t * cells as f32) as usize).min(cells - 1))
        };
        for (i, _) in mask.iter().enumerate().filter(|(_, &m)| m) {
            if let (Some(cu), Some(cv)) = (cell(self.u[i]), cell(self.v[i])) {
                hit[cv * cells + cu] = true;
            }
        }
        Some(hit.iter().filter(|&&h| h).count() as f64 / (cells * cells) as f64)
    }
}

/// Quantile of the per-pixel texture area that sizes the texture (0.5: the
/// median picked pixel gets about one texel). Sized finer, the texture is
/// mostly interpolated: textures 1.5× and 2× this side scored 36.7 and 35.7 dB
/// against 38.8 dB (`picker eval`, seed 4242, ground-truth elements).
pub const DENSITY_QUANTILE: f32 = 0.5;

/// Rows up to which [`Coords::sizing_area`] measures every row.
pub const SIZING_ROWS: usize = 512;

/// The texture side that gives about one texel per picked pixel at the
/// observed density `area` (see [`Coords::sizing_area`]), rounded to a multiple of 4 and clamped to
/// `[16, max]` (`max ≥ 16`).
pub fn texture_size(area: Option<f32>, max: usize) -> usize {
    let max = max.max(16);
    let side = match area {
        Some(a) if a > 0.0 => (1.0 / a.sqrt()) as f64,
        _ => 256.0,
    };
    // Clamped in f64 first: a tiny area's side does not fit a usize.
    (((side / 4.0).round().min(max as f64 / 4.0 + 1.0)) as usize * 4).clamp(16, max)
}

/// The reprojected texture.
#[derive(Clone, Debug)]
pub struct Reprojected {
    /// Weighted mean colour per texel (linear RGB; 0 where unobserved).
    pub texture: Image,
    /// Accumulated weight per texel (1 channel).
    pub weight: Image,
    /// Coverage `W/(W+½)` per texel (1 channel, [0,1)).
    pub coverage: Image,
    /// Texels whose observation weight (tent weights per unit of footprint,
    /// without the pixels' confidence) is `≥ KNOWN_WEIGHT` (or ≥ half the
    /// largest when none reaches it).
    pub known: Vec<bool>,
}

/// The share of `known`'s flags that are set (0 for none).
pub fn known_share(known: &[bool]) -> f64 {
    known.iter().filter(|&&b| b).count() as f64 / known.len().max(1) as f64
}

impl Reprojected {
    /// Fraction of texels observed.
    pub fn known_fraction(&self) -> f64 {
        known_share(&self.known)
    }

    /// The `side × side` texels from column `x0`, row `y0` on.
    ///
    /// # Panics
    /// When they reach past the square.
    pub fn crop(&self, x0: usize, y0: usize, side: usize) -> Reprojected {
        let n = self.texture.width;
        assert!(
            x0 + side <= n && y0 + side <= n,
            "Reprojected::crop: {side}² at ({x0}, {y0}) outside {n}²"
        );
        let cut = |img: &Image| {
            let mut out = Image::zeros(img.channels, side, side);
            for c in 0..img.channels {
                let src = img.plane(c);
                for y in 0..side {
                    let from = (y0 + y) * n + x0;
                    let to = c * side * side + y * side;
                    out.data[to..to + side].copy_from_slice(&src[from..from + side]);
                }
            }
            out
        };
        let known = (0..side * side)
            .map(|i| self.known[(y0 + i / side) * n + x0 + i % side])
            .collect();
        Reprojected {
            texture: cut(&self.texture),
            weight: cut(&self.weight),
            coverage: cut(&self.coverage),
            known,
        }
    }
}

/// One picked pixel (or merged pixel block) to splat: 32 bytes, its
/// footprint kept apart in [`Samples::fps`] and referred to by index.
///
/// Most samples share one footprint, the one-texel tent (merged blocks, and
/// pixels finer than a texel: 87% of the 4 million samples of a 12-MP
/// photo's fold), and the shifted copies of a centred fold share their
/// original's. The splats and back-projection rounds read every sample
/// several times: with the 28-byte footprint inline (56 bytes a sample),
/// padding the sample to 80 bytes made that photo's reprojection ~20%
/// slower, and these 32 bytes made it ~10% faster (peak RSS ~90 MB lower).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Sample {
    u: f32,
    v: f32,
    colour: Vec3,
    weight: f32,
    /// Where the sample's tent reaches in the texture: its index in
    /// [`Samples::fps`] (0: [`Footprint::UNIT`]).
    fp: u32,
    /// Photo pixels this sample stands for (1, or more for a merged block:
    /// [`merge_block`]); its observation weight counts each of them.
    count: f32,
}

const _: () = assert!(std::mem::size_of::<Sample>() == 32);

/// Samples with the footprints they refer to.
#[derive(Clone, Debug, Default, PartialEq)]
struct Samples {
    list: Vec<Sample>,
    /// The footprints, [`Footprint::UNIT`] first.
    fps: Vec<Footprint>,
}

impl Samples {
    /// The footprint of `s` (one of `self.list`).
    #[inline]
    fn fp(&self, s: &Sample) -> &Footprint {
        &self.fps[s.fp as usize]
    }

    /// Samples each given with its own footprint (the tests' way to make
    /// them; [`RowSamples::push`] shares the unit one).
    #[cfg(test)]
    fn from_inline(items: impl IntoIterator<Item = (Sample, Footprint)>) -> Self {
        let mut row = RowSamples::default();
        for (s, fp) in items {
            row.push(s, fp);
        }
        row.into_samples()
    }
}

/// One row's samples as they are made: `list[k].fp` is 0 for
/// [`Footprint::UNIT`], else `j + 1` for `fps[j]` (the row's own; made
/// global when the rows are put together, [`samples_with_room`]).
#[derive(Default)]
struct RowSamples {
    list: Vec<Sample>,
    fps: Vec<Footprint>,
}

impl RowSamples {
    /// Appends `s` with footprint `fp` (its `fp` field is set here).
    fn push(&mut self, s: Sample, fp: Footprint) {
        let r = if fp.is_unit() {
            0
        } else {
            self.fps.push(fp);
            u32::try_from(self.fps.len()).expect("fewer than 2³² footprints")
        };
        self.list.push(Sample { fp: r, ..s });
    }

    /// The row as the whole set of samples (its local footprint indices
    /// are then global: the unit footprint goes first).
    #[cfg(test)]
    fn into_samples(self) -> Samples {
        Samples {
            list: self.list,
            fps: std::iter::once(Footprint::UNIT).chain(self.fps).collect(),
        }
    }
}

/// Where a sample's tent reaches in the texture: the pixel's tent (one pixel
/// wide on each pixel axis, `(1 − |a|)(1 − |b|)` at pixel offset `(a, b)`)
/// mapped into texel units by a Jacobian `J` (texels per pixel step) whose
/// singular values are clamped to `[1, MAX_SPLAT_RADIUS]` texels; a pixel
/// finer than a texel on both axes gets the texel's axis-aligned tent.
///
/// A pixel of a surface seen at a grazing angle covers a long, thin
/// parallelogram of the texture: this footprint spreads its colour along the
/// stretched axis (where the pixel averaged the texture) and not across it
/// (where it resolved it). The lower clamp keeps every texel between
/// neighbouring samples reached (a pixel finer than a texel still spreads
/// over one); the upper one limits the blur of very distant pixels. A
/// frontal, axis-aligned view (`J = s·I`) gives the square tent of radius
/// `clamp(s, 1, MAX_SPLAT_RADIUS)`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Footprint {
    /// `J'⁻¹`, row-major: a texel offset `(dx, dy)` is pixel offset
    /// `(inv[0]·dx + inv[1]·dy, inv[2]·dx + inv[3]·dy)`.
    inv: [f32; 4],
    /// Half-extents in texels of the footprint's bounding box along `x` and `y`.
    ext: [f32; 2],
    /// `|det J'|`: the footprint's area in texels, the integral of its tent.
    area: f32,
}

impl Footprint {
    /// The one-texel tent, [`Footprint::isotropic`]`(1)`.
    const UNIT: Footprint = Footprint {
        inv: [1.0, 0.0, 0.0, 1.0],
        ext: [1.0, 1.0],
        area: 1.0,
    };

    /// Whether this is [`Footprint::UNIT`], bit for bit.
    fn is_unit(&self) -> bool {
        let bits = |f: &Footprint| {
            (
                f.inv.map(f32::to_bits),
                f.ext.map(f32::to_bits),
                f.area.to_bits(),
            )
        };
        bits(self) == bits(&Footprint::UNIT)
    }

    /// The square tent of radius `r` texels (`r > 0`).
    fn isotropic(r: f32) -> Self {
        Footprint {
            inv: [1.0 / r, 0.0, 0.0, 1.0 / r],
            ext: [r, r],
            area: r * r,
        }
    }

    /// The footprint of a pixel whose coordinates move by `jx` texels per
    /// pixel step along `x` and `jy` per step along `y` (the columns of
    /// `J`), with `J`'s singular values clamped to `[1, MAX_SPLAT_RADIUS]`
    /// and its singular vectors kept. When both are at most 1 (and for
    /// non-finite input) it is the one-texel tent ([`Footprint::isotropic`]`(1)`); a
    /// degenerate `J` (coordinates collapsed onto a line) keeps its one
    /// direction and gets one texel across it.
    fn from_jacobian(jx: [f32; 2], jy: [f32; 2]) -> Self {
        let (a, b, c, d) = (
            f64::from(jx[0]),
            f64::from(jy[0]),
            f64::from(jx[1]),
            f64::from(jy[1]),
        );
        if ![a, b, c, d].iter().all(|v| v.is_finite()) {
            return Footprint::isotropic(1.0);
        }
        // JᵀJ = [[p, q], [q, r]]: its eigenvectors are J's right singular
        // vectors, its eigenvalues the squared singular values.
        let (p, q, r) = (a * a + c * c, a * b + c * d, b * b + d * d);
        let m = 0.5 * (p + r);
        let h = (0.25 * (p - r) * (p - r) + q * q).sqrt();
        let (l1, l2) = (m + h, (m - h).max(0.0));
        let (s1, s2) = (l1.sqrt(), l2.sqrt());
        if s1.is_nan() || s1 <= 1.0 {
            // A pixel finer than a texel on both axes: the texel's own
            // (axis-aligned, bilinear) tent, as for a merged pixel block.
            return Footprint::isotropic(1.0);
        }
        // v1 from the better-conditioned row of (JᵀJ − λ₁I)v = 0.
        let (vx, vy) = if h <= 1e-12 * m {
            (1.0, 0.0)
        } else if p >= r {
            (l1 - r, q)
        } else {
            (q, l1 - p)
        };
        let nv = (vx * vx + vy * vy).sqrt();
        let v1 = (vx / nv, vy / nv);
        let v2 = (-v1.1, v1.0);
        let apply = |v: (f64, f64)| (a * v.0 + b * v.1, c * v.0 + d * v.1);
        let (j1, j2) = (apply(v1), apply(v2));
        let u1 = (j1.0 / s1, j1.1 / s1);
        let u2 = if s2 > 1e-9 * s1 {
            (j2.0 / s2, j2.1 / s2)
        } else {
            (-u1.1, u1.0)
        };
        let max = f64::from(MAX_SPLAT_RADIUS);
        let (t1, t2) = (s1.clamp(1.0, max), s2.clamp(1.0, max));
        // J' = t1·u1·v1ᵀ + t2·u2·v2ᵀ and J'⁻¹ = v1·u1ᵀ/t1 + v2·u2ᵀ/t2.
        let jp = [
            t1 * u1.0 * v1.0 + t2 * u2.0 * v2.0,
            t1 * u1.0 * v1.1 + t2 * u2.0 * v2.1,
            t1 * u1.1 * v1.0 + t2 * u2.1 * v2.0,
            t1 * u1.1 * v1.1 + t2 * u2.1 * v2.1,
        ];
        let inv = [
            v1.0 * u1.0 / t1 + v2.0 * u2.0 / t2,
            v1.0 * u1.1 / t1 + v2.0 * u2.1 / t2,
            v1.1 * u1.0 / t1 + v2.1 * u2.0 / t2,
            v1.1 * u1.1 / t1 + v2.1 * u2.1 / t2,
        ];
        Footprint {
            inv: inv.map(|x| x as f32),
            ext: [
                (jp[0].abs() + jp[1].abs()) as f32,
                (jp[2].abs() + jp[3].abs()) as f32,
            ],
            area: (t1 * t2) as f32,
        }
    }

    /// The part of the pixel offsets that depends on the texel row offset
    /// `dy` (shared by a row's texels: [`Footprint::weight`]).
    #[inline]
    fn row(&self, dy: f32) -> [f32; 2] {
        [self.inv[1] * dy, self.inv[3] * dy]
    }

    /// The tent's value at texel offset `(dx, dy)` from the sample, `row`
    /// being [`Footprint::row`]`(dy)`; 0 outside the footprint.
    #[inline]
    fn weight(&self, row: [f32; 2], dx: f32) -> f32 {
        let a = 1.0 - (self.inv[0] * dx + row[0]).abs();
        let b = 1.0 - (self.inv[2] * dx + row[1]).abs();
        if a <= 0.0 || b <= 0.0 {
            0.0
        } else {
            a * b
        }
    }

    /// [`Footprint::weight`] written out for one offset (the references'
    /// version: the same operations, so the same bits).
    #[cfg(test)]
    fn weight_at(&self, dx: f32, dy: f32) -> f32 {
        let a = 1.0 - (self.inv[0] * dx + self.inv[1] * dy).abs();
        let b = 1.0 - (self.inv[2] * dx + self.inv[3] * dy).abs();
        if a > 0.0 && b > 0.0 {
            a * b
        } else {
            0.0
        }
    }
}

/// Pixel `i`'s de-lit colour when it is picked with a positive confidence
/// and finite coordinates and colour (else `None`: it gives no sample).
#[inline]
fn kept(
    coords: &Coords,
    mask: &[bool],
    colour: &Image,
    confidence: &[f32],
    i: usize,
) -> Option<Vec3> {
    if !mask[i] || confidence[i] <= 0.0 {
        return None;
    }
    let c = colour.rgb(i);
    (coords.u[i].is_finite() && coords.v[i].is_finite() && c.is_finite()).then_some(c)
}

/// Largest side, in photo pixels, of the pixel blocks that [`reproject`]
/// merges into one sample when its texture is capped below the photo's
/// density: the largest power of two up to this with the block at most a
/// texel wide, each block merged only where its coordinates are coherent.
pub const MAX_MERGE_BLOCK: usize = 8;

/// The side `f` of the pixel blocks that [`samples_with_room`] merges: 1 (no merging)
/// unless twice the median picked pixel's side in texels is at most one
/// texel; then the largest power of two up to [`MAX_MERGE_BLOCK`] with `f`
/// times the [`MERGE_QUANTILE`] pixel's side at most one texel (a block that
/// is not coherent is split into its quadrants, down to single pixels:
/// [`block_samples`]).
///
/// A texture sized by the observed density ([`texture_size`]) gets about one
/// texel per median pixel, so `f` is 1 unless the size was capped below the
/// photo's density (a 12-MP photo and a 1024² texture: ~7 pixels per
/// texel, `f` = 2). Such pixels are all splatted with the smallest tent (one
/// texel radius), so a coherent block of them adds almost the same tents as
/// one sample at their weighted centre: the texture barely changes
/// (`tests::merged_blocks_give_the_same_texture`) while the splats and
/// back-projection rounds handle `f²` times fewer samples.
fn merge_block(coords: &Coords, mask: &[bool], size: usize) -> usize {
    let Some(area) = coords.sizing_area(mask) else {
        return 1;
    };
    let largest = |area: f32| {
        let side = area.sqrt() * size as f32;
        let mut f = 1;
        while 2 * f <= MAX_MERGE_BLOCK && (2 * f) as f32 * side <= 1.0 {
            f *= 2;
        }
        f
    };
    let f = largest(area);
    if f == 1 {
        return 1;
    }
    // The finer pixels (the near part of a receding plane) may merge in
    // larger blocks; the coarser ones are reached by splitting.
    let step = (coords.height / SIZING_ROWS).max(1);
    coords
        .area_quantile_rows(mask, MERGE_QUANTILE, step)
        .map_or(f, |a| largest(a).max(f))
}

/// The quantile of the picked pixels' texture areas that sets the largest
/// merged pixel block once [`reproject`] merges blocks (when the median
/// pixel allows 2×2 ones; see [`MAX_MERGE_BLOCK`]).
pub const MERGE_QUANTILE: f32 = 0.1;

/// The samples of the `f × f` pixel block with top-left pixel `(x0, y0)`
/// (clipped to the image), appended to `out`: one merged sample when the
/// block holds at least two kept pixels whose coordinates span at most
/// `(f − 1)/f` texel on each axis (so the block's footprint is at most a
/// texel, the smallest tent's radius); else, for `f ≥ 4`, the samples of its
/// four quadrants in turn (top-left, top-right, bottom-left, bottom-right),
/// and for `f = 2` each kept pixel's own sample in row-major order. A merged
/// sample sits at the confidence-weighted mean of the pixels' coordinates
/// (unwrapped around the first pixel's when the coordinates wrap) with their
/// confidence-weighted mean colour, the sum of their confidences as weight
/// (each would have had its confidence: a one-texel tent), a one-texel tent and
/// `count` the number of pixels. `px` is scratch space.
fn block_samples(
    src: &Picked<'_>,
    f: usize,
    (x0, y0): (usize, usize),
    px: &mut Vec<(usize, Vec3)>,
    out: &mut RowSamples,
) {
    let Picked {
        coords,
        mask,
        colour,
        confidence,
        size,
    } = *src;
    let w = coords.width;
    if x0 >= w || y0 >= coords.height {
        return;
    }
    let (x1, y1) = ((x0 + f).min(w), (y0 + f).min(coords.height));
    px.clear();
    for y in y0..y1 {
        for i in y * w + x0..y * w + x1 {
            if let Some(c) = kept(coords, mask, colour, confidence, i) {
                px.push((i, c));
            }
        }
    }
    let k = px.len();
    let merged = (k >= 2).then(|| {
        let (u0, v0) = (coords.u[px[0].0], coords.v[px[0].0]);
        let at = |i: usize| {
            (
                u0 + coords.delta(u0, coords.u[i]),
                v0 + coords.delta(v0, coords.v[i]),
            )
        };
        let (mut lo, mut hi) = ((u0, v0), (u0, v0));
        let (mut cw, mut cu, mut cv, mut cc) = (0.0f32, 0.0f32, 0.0f32, Vec3::ZERO);
        for &(i, c) in px.iter() {
            let (u, v) = at(i);
            lo = (lo.0.min(u), lo.1.min(v));
            hi = (hi.0.max(u), hi.1.max(v));
            let q = confidence[i];
            cw += q;
            cu += q * u;
            cv += q * v;
            cc += c * q;
        }
        let limit = (f - 1) as f32 / (f as f32 * size as f32);
        (hi.0 - lo.0 <= limit && hi.1 - lo.1 <= limit).then(|| Sample {
            u: cu / cw,
            v: cv / cw,
            colour: cc / cw,
            weight: cw,
            fp: 0,
            count: k as f32,
        })
    });
    match merged.flatten() {
        Some(s) => out.push(s, Footprint::UNIT),
        None if f >= 4 && k >= 2 => {
            let g = f / 2;
            for (dx, dy) in [(0, 0), (g, 0), (0, g), (g, g)] {
                block_samples(src, g, (x0 + dx, y0 + dy), px, out);
            }
        }
        None => {
            for &(i, c) in px.iter() {
                let (s, fp) = splat_sample(coords, mask, confidence, size, i, c);
                out.push(s, fp);
            }
        }
    }
}

/// The samples of block row `by` ([`block_samples`] of each block, left to
/// right), appended to `out`.
fn block_row(src: &Picked<'_>, f: usize, by: usize, out: &mut RowSamples) {
    let mut px = Vec::with_capacity(f * f);
    for bx in 0..src.coords.width.div_ceil(f) {
        block_samples(src, f, (bx * f, by * f), &mut px, out);
    }
}

/// The inputs of [`samples_with_room`]: the pixels' coordinates, the mask, the de-lit
/// colours and confidences, and the texture size.
#[derive(Clone, Copy)]
struct Picked<'a> {
    coords: &'a Coords,
    mask: &'a [bool],
    colour: &'a Image,
    confidence: &'a [f32],
    size: usize,
}

/// [`samples_with_room`] without the room (the tests' shorthand).
#[cfg(test)]
fn samples(src: &Picked<'_>, block: usize) -> Samples {
    samples_with_room(src, block, false)
}

/// The picked pixels with a positive confidence and finite coordinates and
/// colour ([`kept`]), in pixel order, with their footprint and weight;
/// with `block > 1`, by `block × block` pixel blocks in row-major order,
/// each merged into one sample where it is coherent ([`block_samples`]).
/// With `room`, the vector has room for as many more (the shifted copies of
/// [`with_shifted_copies`]): it is allocated once, at its final capacity.
///
/// Rows in parallel: the samples of each row are made into the row's own
/// vectors, then copied into their place in parallel (the same samples and
/// footprints in the same order as the plain filter over the pixels,
/// `tests::parallel_samples_match_reference`).
fn samples_with_room(src: &Picked<'_>, block: usize, room: bool) -> Samples {
    let w = src.coords.width;
    // Rows (of blocks, or of pixels) in parallel, each made into its own
    // vectors, then copied into place in order with their footprint
    // indices made global. (No pixels, no rows: a 0-wide image has no
    // pixels in any of its rows.)
    let rows_n = if w == 0 {
        0
    } else {
        src.coords.height.div_ceil(block.max(1))
    };
    let rows: Vec<RowSamples> = (0..rows_n)
        .into_par_iter()
        .map(|r| {
            let mut out = RowSamples::default();
            if block > 1 {
                block_row(src, block, r, &mut out);
            } else {
                pixel_row(src, r * w..(r + 1) * w, &mut out);
            }
            out
        })
        .collect();
    // Row `r`'s footprint `j + 1` is `fps[first[r] + j + 1]` (`fps[0]` is the unit one).
    let mut first = Vec::with_capacity(rows.len());
    let mut total = 0usize;
    for r in &rows {
        first.push(u32::try_from(total).expect("fewer than 2³² footprints"));
        total += r.fps.len();
    }
    assert!(total < u32::MAX as usize, "fewer than 2³² footprints");
    let counts: Vec<usize> = rows.iter().map(|r| r.list.len()).collect();
    let list = filled_in_parts(&counts, room, |r, part| {
        for (slot, s) in part.iter_mut().zip(&rows[r].list) {
            let fp = if s.fp == 0 { 0 } else { s.fp + first[r] };
            slot.write(Sample { fp, ..*s });
        }
        rows[r].list.len()
    });
    // The unit footprint, then each row's.
    let fp_counts: Vec<usize> = std::iter::once(1)
        .chain(rows.iter().map(|r| r.fps.len()))
        .collect();
    let fps = filled_in_parts(&fp_counts, false, |r, part| {
        let src: &[Footprint] = if r == 0 {
            std::slice::from_ref(&Footprint::UNIT)
        } else {
            &rows[r - 1].fps
        };
        for (slot, f) in part.iter_mut().zip(src) {
            slot.write(*f);
        }
        src.len()
    });
    Samples { list, fps }
}

/// The samples of the pixels `range` (one row), in order ([`kept`],
/// [`splat_sample`]), appended to `out`.
fn pixel_row(src: &Picked<'_>, range: std::ops::Range<usize>, out: &mut RowSamples) {
    for i in range {
        if let Some(c) = kept(src.coords, src.mask, src.colour, src.confidence, i) {
            let (s, fp) = splat_sample(src.coords, src.mask, src.confidence, src.size, i, c);
            out.push(s, fp);
        }
    }
}

/// A vector of `counts.iter().sum()` values made of consecutive parts, part
/// `r` (`counts[r]` long) written by `write(r, part)`, which returns how many
/// of the part's slots it wrote; the parts in parallel. With `room`, its
/// capacity is twice its length.
///
/// Written in place without first filling the vector: at 12 MP a filled
/// `vec![Sample::default(); n]` (~140 MB, one thread, every page faulted
/// in by that thread) took 216 ms of the samples' 300 ms, and concatenating
/// per-row vectors on one thread cost as much again.
///
/// # Panics
/// When a part writes more or fewer slots than its count.
fn filled_in_parts<T: Copy + Send + Sync>(
    counts: &[usize],
    room: bool,
    write: impl Fn(usize, &mut [std::mem::MaybeUninit<T>]) -> usize + Sync,
) -> Vec<T> {
    let total: usize = counts.iter().sum();
    let mut out: Vec<T> = Vec::with_capacity(if room { 2 * total } else { total });
    let mut parts = Vec::with_capacity(counts.len());
    let mut rest = &mut out.spare_capacity_mut()[..total];
    for &k in counts {
        let (part, tail) = rest.split_at_mut(k);
        parts.push(part);
        rest = tail;
    }
    parts.into_par_iter().enumerate().for_each(|(r, part)| {
        let k = part.len();
        // Every slot of the part written: the set_len below relies on it.
        assert_eq!(
            write(r, part),
            k,
            "part {r}: not every counted sample written"
        );
    });
    // SAFETY: the first `total` slots were split into the parts, and every
    // part wrote each of its slots (asserted above; a panic there never
    // reaches this line). `T` is `Copy`, so nothing needs dropping.
    unsafe { out.set_len(total) };
    out
}

/// Pixel `i`'s sample of colour `c`: its footprint is the pixel's tent
/// mapped by the coordinates' Jacobian in texels ([`Coords::jacobian`],
/// [`Footprint::from_jacobian`]; a one-texel tent where the Jacobian is
/// unknown), its weight the confidence over the footprint's area `A`
/// squared.
///
/// One factor `1/A` spreads the confidence over the footprint (the tent
/// integrates to `A`); the other is an inverse-variance weight: a pixel
/// that averaged `A` texels tells about each of them with an error that
/// grows with `A` (the other texels under it), so where sharp and blurred
/// pixels see the same texel (a floor's near and far repeats of one tile),
/// the sharp ones decide. `picker eval` on ground-truth elements, mean
/// aligned texture PSNR (seed 4242 / 9191, 40 scenes each): 38.78 / 38.84 dB
/// with the former isotropic tent of radius `√A` and weight `1/A`; 38.88 /
/// 39.05 with this footprint and `1/A`; 39.37 / 39.46 with `1/A²`.
fn splat_sample(
    coords: &Coords,
    mask: &[bool],
    confidence: &[f32],
    size: usize,
    i: usize,
    c: Vec3,
) -> (Sample, Footprint) {
    let s = size as f32;
    let fp = coords
        .jacobian(mask, i)
        .map_or(Footprint::isotropic(1.0), |(jx, jy)| {
            Footprint::from_jacobian([jx[0] * s, jx[1] * s], [jy[0] * s, jy[1] * s])
        });
    let sample = Sample {
        u: coords.u[i],
        v: coords.v[i],
        colour: c,
        weight: confidence[i] / (fp.area * fp.area),
        fp: 0,
        count: 1.0,
    };
    (sample, fp)
}

/// The plain implementation of [`samples`] (a filter over the pixels, or
/// over the blocks one after the other).
#[cfg(test)]
fn samples_reference(src: &Picked<'_>, block: usize) -> Samples {
    let mut all = RowSamples::default();
    if block > 1 {
        for by in 0..src.coords.height.div_ceil(block) {
            block_row(src, block, by, &mut all);
        }
    } else {
        for i in 0..src.mask.len() {
            if !src.mask[i] || src.confidence[i] <= 0.0 {
                continue;
            }
            let (u, v) = (src.coords.u[i], src.coords.v[i]);
            let c = src.colour.rgb(i);
            if !u.is_finite() || !v.is_finite() || !c.is_finite() {
                continue;
            }
            let (s, fp) = splat_sample(src.coords, src.mask, src.confidence, src.size, i, c);
            all.push(s, fp);
        }
    }
    all.into_samples()
}

/// The rows of texture band `k` (`SPLAT_BAND_ROWS` rows each).
const SPLAT_BAND_ROWS: usize = 16;

/// Samples per parallel chunk when [`band_members`] sorts them into bands.
const MEMBER_CHUNK: usize = 1 << 16;

/// `x.floor() as i64` without a call to `floorf` (the baseline x86-64
/// target has no rounding instruction): the same value for every `f32`,
/// NaN and infinities included (`tests::integer_floor_and_ceil`).
#[inline]
fn floor_i64(x: f32) -> i64 {
    let t = x as i64;
    if (t as f32) > x {
        t.saturating_sub(1)
    } else {
        t
    }
}

/// `x.floor()` without a call to `floorf` (see [`floor_i64`]): the same
/// value for every `f32`, the sign of zero, NaN and infinities included
/// (`tests::integer_floor_and_ceil`).
#[inline]
pub(crate) fn floor_f32(x: f32) -> f32 {
    // Below 2²³ in magnitude `x` truncates exactly into an i32; above, every
    // f32 is an integer (and NaN fails the test).
    if x.abs() < 8_388_608.0 {
        let t = (x as i32) as f32;
        let f = if t > x { t - 1.0 } else { t };
        // floor(−0.0) is −0.0; every other result already has x's sign.
        f.copysign(x)
    } else {
        x
    }
}

/// `x.round()` (half away from zero) without a call to `roundf`: the same
/// value for every `f32` (see [`floor_f32`]).
#[inline]
pub(crate) fn round_f32(x: f32) -> f32 {
    if x.abs() < 8_388_608.0 {
        let t = (x as i32) as f32;
        // The fraction, exactly.
        let r = x - t;
        let y = if r >= 0.5 {
            t + 1.0
        } else if r <= -0.5 {
            t - 1.0
        } else {
            t
        };
        y.copysign(x)
    } else {
        x
    }
}

/// `x.ceil() as i64` (see [`floor_i64`]).
#[inline]
fn ceil_i64(x: f32) -> i64 {
    let t = x as i64;
    if (t as f32) < x {
        t.saturating_add(1)
    } else {
        t
    }
}

/// `v.rem_euclid(n)` for `n > 0`, without a division for the values within
/// one period of `0..n` (a splat reaches at most a few texels past an edge).
#[inline]
fn wrap_i64(v: i64, n: i64) -> i64 {
    if (0..n).contains(&v) {
        v
    } else if (-n..0).contains(&v) {
        v + n
    } else if (n..2 * n).contains(&v) {
        v - n
    } else {
        v.rem_euclid(n)
    }
}

/// The texture rows a sample's tent covers (before wrapping).
#[inline]
fn sample_rows(s: &Sample, fp: &Footprint, size: usize) -> (i64, i64) {
    let py = s.v * size as f32 - 0.5;
    let e = fp.ext[1];
    (ceil_i64(py - e), floor_i64(py + e))
}

/// For every band of [`SPLAT_BAND_ROWS`] texture rows, the indices of the
/// samples whose tent reaches it, in sample order (each sample once).
///
/// Chunks of samples in parallel, each chunk's lists then concatenated per
/// band in chunk order: the lists of the plain sequential pass.
fn band_members(samples: &Samples, size: usize, wrap: bool) -> Vec<Vec<u32>> {
    let bands = size.div_ceil(SPLAT_BAND_ROWS);
    let n = size as i64;
    let chunks: Vec<Vec<Vec<u32>>> = samples
        .list
        .par_chunks(MEMBER_CHUNK)
        .enumerate()
        .map(|(c, chunk)| {
            let mut members: Vec<Vec<u32>> = vec![Vec::new(); bands];
            let mut seen = vec![usize::MAX; bands];
            for (j, s) in chunk.iter().enumerate() {
                let k = c * MEMBER_CHUNK + j;
                let (y0, y1) = sample_rows(s, samples.fp(s), size);
                for ty in y0..=y1 {
                    let yy = if wrap { wrap_i64(ty, n) } else { ty };
                    if yy < 0 || yy >= n {
                        continue;
                    }
                    let b = yy as usize / SPLAT_BAND_ROWS;
                    if seen[b] != k {
                        seen[b] = k;
                        members[b].push(k as u32);
                    }
                }
            }
            members
        })
        .collect();
    (0..bands)
        .into_par_iter()
        .map(|b| {
            let mut all = Vec::with_capacity(chunks.iter().map(|c| c[b].len()).sum());
            for c in &chunks {
                all.extend_from_slice(&c[b]);
            }
            all
        })
        .collect()
}

/// Accumulates the tent-weighted samples (optionally Cauchy-reweighted
/// against `reference` with `scale`) into per-texel sums and weights;
/// `members` are the samples of every band ([`band_members`]). With
/// `values`, sample `k` adds `values[k]` instead of its colour (same weights:
/// the back-projection of residuals). With `track_seen`, also returns each
/// texel's observation weight: the same tent weights per unit of footprint
/// without the samples' confidence or robust weights (how well the texel was
/// seen, whatever the quality of the pixels that saw it); else that vector
/// is empty.
///
/// Parallel over bands of texture rows: each band adds the samples that
/// touch it in sample order, so every texel receives its contributions in
/// the same order as `splat_reference` (same bits, whatever the threads).
#[allow(clippy::too_many_arguments)]
fn splat(
    samples: &Samples,
    members: &[Vec<u32>],
    size: usize,
    wrap: bool,
    reference: Option<&[Vec3]>,
    scale: f32,
    values: Option<&[Vec3]>,
    track_seen: bool,
) -> (Vec<Vec3>, Vec<f32>, Vec<f32>) {
    let mut sum = vec![Vec3::ZERO; size * size];
    let mut wsum = vec![0.0f32; size * size];
    let mut seen = vec![0.0f32; if track_seen { size * size } else { 0 }];
    if size == 0 {
        return (sum, wsum, seen);
    }
    let n = size as i64;
    let band_len = SPLAT_BAND_ROWS * size;
    // One (possibly empty) slice of `seen` per band.
    let seen_bands: Vec<&mut [f32]> = if track_seen {
        seen.chunks_mut(band_len).collect()
    } else {
        (0..size.div_ceil(SPLAT_BAND_ROWS))
            .map(|_| Default::default())
            .collect()
    };
    sum.par_chunks_mut(band_len)
        .zip(wsum.par_chunks_mut(band_len))
        .zip(seen_bands.into_par_iter())
        .zip(members.par_iter())
        .enumerate()
        .for_each(|(b, (((bsum, bw), bseen), idx))| {
            let (lo, hi) = (
                (b * SPLAT_BAND_ROWS) as i64,
                ((b + 1) * SPLAT_BAND_ROWS).min(size) as i64,
            );
            for &k in idx {
                let s = &samples.list[k as usize];
                let value = values.map_or(s.colour, |v| v[k as usize]);
                let px = s.u * size as f32 - 0.5;
                let py = s.v * size as f32 - 0.5;
                let fp = samples.fp(s);
                let per_area = s.count / fp.area;
                let (x0, x1) = (ceil_i64(px - fp.ext[0]), floor_i64(px + fp.ext[0]));
                let (y0, y1) = (ceil_i64(py - fp.ext[1]), floor_i64(py + fp.ext[1]));
                for ty in y0..=y1 {
                    // (The band test first: both tests only skip the row.)
                    let yy = if wrap { wrap_i64(ty, n) } else { ty };
                    if yy < lo || yy >= hi {
                        continue;
                    }
                    let row_t = fp.row(ty as f32 - py);
                    let row = (yy - lo) as usize * size;
                    for tx in x0..=x1 {
                        let t = fp.weight(row_t, tx as f32 - px);
                        if t <= 0.0 {
                            continue;
                        }
                        let xx = if wrap { wrap_i64(tx, n) } else { tx };
                        if xx < 0 || xx >= n {
                            continue;
                        }
                        let lt = row + xx as usize;
                        let mut w = s.weight * t;
                        if let Some(mean) = reference {
                            let d = (s.colour - mean[lt + lo as usize * size]).length() / scale;
                            w /= 1.0 + d * d;
                        }
                        bsum[lt] += value * w;
                        bw[lt] += w;
                        if track_seen {
                            bseen[lt] += per_area * t;
                        }
                    }
                }
            }
        });
    (sum, wsum, seen)
}

/// Rounds of damped iterative back-projection (Irani & Peleg 1991) after the
/// splat: each round predicts every picked pixel from the texture with its
/// tent, splats the residuals with the texture's weights and adds
/// [`BACK_PROJECTION_STEP`] times their mean to each texel.
///
/// Measured with `picker eval` on ground-truth elements (two sets of 40
/// synthetic scenes, seeds 4242 and 9191): rounds × step 2 × ½ raised the
/// mean aligned texture PSNR by ~1.9 dB and cut the colour-statistics
/// distance by ~18% on both; one full step, or more rounds, raised the mean
/// too but sharpened more textures past their truth (more of them under
/// 25 dB), as did a narrower, variance-matched prediction tent.
pub const BACK_PROJECTIONS: usize = 2;

/// The fraction of the back-projected residual each round adds.
pub const BACK_PROJECTION_STEP: f32 = 0.5;

/// Sample `s` (footprint `fp`) as the texture `tex` predicts it: the tent-weighted mean of the
/// texels under its footprint (the splat's kernel, without the confidence and
/// robust weights); `None` when no texel lies under it.
fn predict(s: &Sample, fp: &Footprint, tex: &[Vec3], size: usize, wrap: bool) -> Option<Vec3> {
    let n = size as i64;
    let px = s.u * size as f32 - 0.5;
    let py = s.v * size as f32 - 0.5;
    let (x0, x1) = (ceil_i64(px - fp.ext[0]), floor_i64(px + fp.ext[0]));
    let (y0, y1) = (ceil_i64(py - fp.ext[1]), floor_i64(py + fp.ext[1]));
    let (mut acc, mut wsum) = (Vec3::ZERO, 0.0f32);
    for ty in y0..=y1 {
        let yy = if wrap { wrap_i64(ty, n) } else { ty };
        if yy < 0 || yy >= n {
            continue;
        }
        let row_t = fp.row(ty as f32 - py);
        for tx in x0..=x1 {
            let w = fp.weight(row_t, tx as f32 - px);
            let xx = if wrap { wrap_i64(tx, n) } else { tx };
            if w <= 0.0 || xx < 0 || xx >= n {
                continue;
            }
            acc += tex[yy as usize * size + xx as usize] * w;
            wsum += w;
        }
    }
    (wsum > 0.0).then(|| acc / wsum)
}

/// Weighted mean per texel (`sum / weight`; 0 where nothing was splatted).
fn texel_means(sum: &[Vec3], wsum: &[f32]) -> Vec<Vec3> {
    sum.iter()
        .zip(wsum)
        .map(|(s, &w)| if w > 0.0 { *s / w } else { Vec3::ZERO })
        .collect()
}

/// The robust splat of one set of picked pixels, ready for back-projection.
struct Fit {
    samples: Samples,
    members: Vec<Vec<u32>>,
    size: usize,
    wrap: bool,
    /// A centred fold's shift in texels by which every splat's sums are
    /// added to themselves ([`reproject_centred`]).
    shift: Option<[f32; 2]>,
    /// The first (plain) pass's texel means, which the robust weights compare with.
    mean: Vec<Vec3>,
    /// The robust weights' scale.
    scale: f32,
    /// Accumulated robust weight per texel.
    wsum: Vec<f32>,
    /// Observation weight per texel (tent weights per unit of footprint,
    /// whatever the samples' confidence): whether the texel was seen.
    seen: Vec<f32>,
    /// The texture (robust weighted means, then back-projected).
    tex: Vec<Vec3>,
}

impl Fit {
    /// Splats the pixels (`size > 0`), then reweights them robustly.
    fn new(
        coords: &Coords,
        mask: &[bool],
        colour: &Image,
        confidence: &[f32],
        size: usize,
        block: usize,
        shift: Option<[f32; 2]>,
    ) -> Self {
        let src = Picked {
            coords,
            mask,
            colour,
            confidence,
            size,
        };
        // A centred fold's second place for every sample. Where the shift is
        // half the square (or none) along each axis and a whole number of
        // texels, moving twice is the identity and the texture comes out
        // symmetric, so each splat's sums plus the same sums moved
        // ([`plus_shifted`]) are those of the copies: robust weights and
        // back-projection residuals alike. Otherwise the copies are made
        // (in room the samples are made with).
        let by_sums = shift.filter(|by| {
            by.iter()
                .all(|&b| (b * size as f32).fract() == 0.0 && (2.0 * b).fract() == 0.0)
        });
        let copies = shift.is_some() && by_sums.is_none();
        let mut samples = samples_with_room(&src, block, copies);
        if let (Some(by), None) = (shift, by_sums) {
            samples.list = with_shifted_copies(std::mem::take(&mut samples.list), by);
        }
        let members = band_members(&samples, size, coords.wrap);
        let shift = by_sums.map(|by| [by[0] * size as f32, by[1] * size as f32]);
        let sym = |(sum, wsum, seen): (Vec<Vec3>, Vec<f32>, Vec<f32>)| match shift {
            Some(by) => (
                plus_shifted(&sum, size, by),
                plus_shifted(&wsum, size, by),
                // (Not tracked: empty.)
                if seen.is_empty() {
                    seen
                } else {
                    plus_shifted(&seen, size, by)
                },
            ),
            None => (sum, wsum, seen),
        };
        let (sum, wsum, seen) = sym(splat(
            &samples,
            &members,
            size,
            coords.wrap,
            None,
            1.0,
            None,
            true,
        ));
        let mean = texel_means(&sum, &wsum);
        // Robust pass: Cauchy weights on the distance to the first-pass texel mean,
        // scale = 2 × the median deviation (at least 0.02).
        // (The median found in parallel without collecting the deviations:
        // `select::kth_smallest`.)
        let n = size as i64;
        let dev = |k: usize| {
            let s = &samples.list[k];
            let px = wrap_i64((s.u * size as f32) as i64, n) as usize;
            let py = wrap_i64((s.v * size as f32) as i64, n) as usize;
            Some((s.colour - mean[py * size + px]).length())
        };
        let scale =
            match crate::select::kth_smallest(samples.list.len(), dev, |len| Some(vec![len / 2])) {
                None => 1.0,
                Some(m) => (2.0 * m[0]).max(0.02),
            };
        let (sum, wsum, _) = sym(splat(
            &samples,
            &members,
            size,
            coords.wrap,
            Some(&mean),
            scale,
            None,
            false,
        ));
        let tex = texel_means(&sum, &wsum);
        Fit {
            samples,
            members,
            size,
            wrap: coords.wrap,
            shift,
            mean,
            scale,
            wsum,
            seen,
            tex,
        }
    }

    /// `rounds` more rounds of iterative back-projection (Irani & Peleg 1991):
    /// the splat is a blurred estimate (each sample is spread over its tent,
    /// and the tents of neighbouring samples overlap), so each round predicts
    /// every sample from the texture ([`predict`]), splats the residuals with
    /// the texture's weights and adds [`BACK_PROJECTION_STEP`] times their
    /// mean to each texel. Without the robust weights this is a damped
    /// Landweber iteration on `A·tex = colours` with `A` the tents: it undoes
    /// part of the splat's own blur and amplifies no frequency more than
    /// `1 + rounds · step` times (2 with the defaults), so noise in the
    /// de-lit colours is not blown up. Texels stay within `[0, the splat's
    /// largest value]` per channel, so ringing at hard edges cannot overshoot
    /// into negative colours. Samples in parallel, each texel's sum in the
    /// splat's fixed order: deterministic.
    fn back_project(&mut self, rounds: usize) {
        let (samples, size, wrap) = (&self.samples, self.size, self.wrap);
        let hi = self
            .tex
            .iter()
            .zip(&self.wsum)
            .filter(|(_, &w)| w > 0.0)
            .fold(Vec3::ZERO, |m, (c, _)| m.max(*c));
        // One residual buffer for all rounds (a fresh one per round costs its
        // page faults again: 12 bytes per picked pixel), made by the first
        // round's predictions in parallel (a zeroed one first took ~20 ms
        // on one thread at 12 MP).
        let mut residual: Vec<Vec3> = Vec::new();
        for round in 0..rounds {
            let t: &[Vec3] = &self.tex;
            let r = |s: &Sample| {
                predict(s, samples.fp(s), t, size, wrap).map_or(Vec3::ZERO, |p| s.colour - p)
            };
            if round == 0 {
                residual = samples.list.par_iter().map(r).collect();
            } else {
                residual
                    .par_iter_mut()
                    .zip(samples.list.par_iter())
                    .for_each(|(o, s)| *o = r(s));
            }
            let (rsum, _, _) = splat(
                samples,
                &self.members,
                size,
                wrap,
                Some(&self.mean),
                self.scale,
                Some(&residual),
                false,
            );
            let rsum = match self.shift {
                Some(by) => plus_shifted(&rsum, size, by),
                None => rsum,
            };
            self.tex
                .par_iter_mut()
                .zip(rsum.par_iter().zip(self.wsum.par_iter()))
                .for_each(|(c, (r, &w))| {
                    if w > 0.0 {
                        *c = (*c + *r / w * BACK_PROJECTION_STEP).clamp(Vec3::ZERO, hi);
                    }
                });
        }
    }
}

/// Which of two halves pixel `i` of a `w`-wide image falls in (0 or 1): a
/// hash of its 16×16-pixel block, so the split cannot alias with a texture
/// period.
fn block_half(w: usize, i: usize) -> usize {
    let (bx, by) = ((i % w) / 16, (i / w) / 16);
    let mut hsh = (bx as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
        ^ (by as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F);
    hsh ^= hsh >> 29;
    hsh = hsh.wrapping_mul(0xBF58_476D_1CE4_E5B9);
    hsh ^= hsh >> 32;
    (hsh & 1) as usize
}

/// Splats the picked pixels (`mask`, colours `colour` (3 channels), per-pixel
/// confidence `confidence`) through `coords` into a `size × size` texture.
pub fn reproject(
    coords: &Coords,
    mask: &[bool],
    colour: &Image,
    confidence: &[f32],
    size: usize,
) -> Reprojected {
    let how = Splatting::full(coords, mask, size, None);
    reproject_rounds(coords, mask, colour, confidence, size, how)
}

/// [`reproject`] of a folded tile whose repeat is centred
/// ([`crate::period::Fold::centring_shift`]): every picked pixel is splatted
/// twice, at its coordinates and shifted by `shift` (units of the square,
/// wrapped), so each texel is seen by the pixels of both its places in the
/// pattern. Both copies go through one robust fit: a texel's colour is the
/// robust mean of the pixels of both places. Where the shift is half the
/// square along each axis (or none) and a whole number of texels (a tile of
/// one period each way: a chessboard's), the copies are not made: each
/// splat's per-texel sums get themselves, moved, added (`plus_shifted`),
/// which gives the same texture (it is symmetric, so the copies' robust
/// weights and back-projection residuals are their originals') at the cost
/// of [`reproject`]; otherwise the copies are made and splatted, at twice
/// the cost.
///
/// # Panics
/// When `coords` do not wrap (only a folded tile repeats by the shift), or
/// as [`reproject`].
pub fn reproject_centred(
    coords: &Coords,
    mask: &[bool],
    colour: &Image,
    confidence: &[f32],
    size: usize,
    shift: [f32; 2],
) -> Reprojected {
    assert!(
        coords.wrap,
        "reproject_centred: the coordinates must wrap (a folded tile)"
    );
    let how = Splatting::full(coords, mask, size, Some(shift));
    reproject_rounds(coords, mask, colour, confidence, size, how)
}

/// `samples` followed by a copy of each moved by `by` (units of the square)
/// and wrapped into `[0, 1)`; their footprints, relative to their centres,
/// are unchanged. The copies are written in parallel, into the vector's
/// spare room when it has it ([`samples_with_room`]: at 12 MP, 4 million
/// samples, pushing them one by one after growing the vector took 80–100
/// ms).
fn with_shifted_copies(mut samples: Vec<Sample>, by: [f32; 2]) -> Vec<Sample> {
    let wrap = |t: f32, d: f32| {
        let x = t + d;
        let x = x - floor_f32(x);
        // `x − floor(x)` of a value just below an integer rounds to 1.
        if x >= 1.0 {
            0.0
        } else {
            x
        }
    };
    let n = samples.len();
    samples.reserve_exact(n);
    let base = samples.as_mut_ptr();
    // SAFETY: the first `n` slots are initialised and only read here; the
    // next `n` lie within the capacity (reserved above), are only written
    // here, and do not overlap the first `n`. The vector is not touched
    // through `samples` until `set_len`.
    let (orig, spare) = unsafe {
        (
            std::slice::from_raw_parts(base.cast_const(), n),
            std::slice::from_raw_parts_mut(base.add(n).cast::<std::mem::MaybeUninit<Sample>>(), n),
        )
    };
    spare
        .par_chunks_mut(COPY_CHUNK)
        .zip(orig.par_chunks(COPY_CHUNK))
        .for_each(|(dst, src)| {
            for (d, s) in dst.iter_mut().zip(src) {
                d.write(Sample {
                    u: wrap(s.u, by[0]),
                    v: wrap(s.v, by[1]),
                    ..*s
                });
            }
        });
    // SAFETY: every one of the `n` copies was written above.
    unsafe { samples.set_len(2 * n) };
    samples
}

/// Samples per parallel chunk of [`with_shifted_copies`].
const COPY_CHUNK: usize = 1 << 14;

/// A `size × size` square of per-texel sums `a` (wrapping) plus the same
/// sums moved by `by` texels: what the sums would be if every sample were
/// also splatted `by` texels further on. The moved copy is read at
/// `t − by`, bilinearly between texels when `by` is not whole (exact when
/// it is). An empty square stays empty.
///
/// # Panics
/// When `a` does not hold `size²` values.
fn plus_shifted<T>(a: &[T], size: usize, by: [f32; 2]) -> Vec<T>
where
    T: Copy + Send + Sync + std::ops::Add<Output = T> + std::ops::Mul<f32, Output = T>,
{
    assert_eq!(a.len(), size * size, "plus_shifted: a square of sums");
    if size == 0 {
        return Vec::new();
    }
    let n = size as i64;
    // Source column/row for destination `d` along one axis: the two texels
    // and the weight of the second (0 when `by` is whole).
    let taps = |d: usize, by: f32| {
        let f = d as f32 - by;
        let f0 = f.floor();
        let t = f - f0;
        let i0 = (f0 as i64).rem_euclid(n) as usize;
        (i0, ((f0 as i64 + 1).rem_euclid(n)) as usize, t)
    };
    let cols: Vec<(usize, usize, f32)> = (0..size).map(|x| taps(x, by[0])).collect();
    let mut out = a.to_vec();
    out.par_chunks_mut(size).enumerate().for_each(|(y, row)| {
        let (y0, y1, ty) = taps(y, by[1]);
        for (x, o) in row.iter_mut().enumerate() {
            let (x0, x1, tx) = cols[x];
            let at = |yy: usize| {
                let r = &a[yy * size..(yy + 1) * size];
                if tx == 0.0 {
                    r[x0]
                } else {
                    r[x0] * (1.0 - tx) + r[x1] * tx
                }
            };
            let v = if ty == 0.0 {
                at(y0)
            } else {
                at(y0) * (1.0 - ty) + at(y1) * ty
            };
            *o = *o + v;
        }
    });
    out
}

/// Where `other` outweighs `own` by this factor at a texel both observed
/// (`own` with at least [`OUTWEIGHED_MIN_SHARE`] of its median weight),
/// [`fill_unknown_from`] takes the texel from `other`.
pub const OUTWEIGHED: f32 = 4.0;
/// The least weight of `own` at a texel [`OUTWEIGHED`] applies to, as a
/// share of the median weight of the texels `own` knows. Below it `own`
/// saw the texel only with the tails of its splats, at the border of the
/// regions it holds (the surest part of a chessboard's mask holds its
/// squares' interiors), where the rest of the mask is the other colour's
/// border and would erode the squares; such texels keep `own`'s values.
/// (Measured: on a synthetic centred chessboard such tails weigh under
/// 0.006 of the median; on `left01.jpg`'s board the strip of its frame that
/// the fold lays into the black squares weighs 0.04 to 0.35 of it.)
pub const OUTWEIGHED_MIN_SHARE: f32 = 0.02;

/// The texels `own` did not observe that `other` (a reprojection of other
/// pixels through the same coordinates at the same size) did, taken from
/// `other`: colour, weight, coverage and the known flag; and the texels
/// `own` observed with less than `1 / OUTWEIGHED` of `other`'s weight (and
/// at least [`OUTWEIGHED_MIN_SHARE`] of its median). In
/// a fold of repeats (`own` the surest part of the mask, `other` the rest)
/// such a texel was shown by a few repeats of the surest part only, while
/// many repeats of the rest showed it: a strip of the material's border or
/// of something else that the mask took in and that lines up with the
/// pattern's phase there (a chessboard's white frame, folded into the
/// bottom of its black squares, which only the rest of the mask shows),
/// not the pattern. The other texels `own` knows keep their values. Returns
/// how many were taken.
///
/// # Panics
/// When the two squares' sizes or channels differ.
pub fn fill_unknown_from(own: &mut Reprojected, other: &Reprojected) -> usize {
    let (t, o) = (&own.texture, &other.texture);
    assert!(
        (t.channels, t.height, t.width) == (o.channels, o.height, o.width)
            && own.known.len() == other.known.len(),
        "fill_unknown_from: sizes differ"
    );
    let (n, channels) = (own.known.len(), t.channels);
    let mut filled = 0;
    // The least weight of `own` the outweighing applies to.
    let mut known_weights: Vec<f32> = (0..n)
        .filter(|&i| own.known[i])
        .map(|i| own.weight.data[i])
        .collect();
    let min_own = if known_weights.is_empty() {
        f32::INFINITY
    } else {
        let mid = known_weights.len() / 2;
        OUTWEIGHED_MIN_SHARE * *known_weights.select_nth_unstable_by(mid, f32::total_cmp).1
    };
    let outweighed = |i: usize| {
        other.known[i] && own.known[i] && other.weight.data[i] >= OUTWEIGHED * own.weight.data[i]
    };
    // Which texels come from `other`: those `own` did not see, and those it
    // saw with a fair weight that `other` outweighs.
    let mut take: Vec<bool> = (0..n)
        .map(|i| {
            other.known[i] && (!own.known[i] || (outweighed(i) && own.weight.data[i] >= min_own))
        })
        .collect();
    // A faint outweighed texel among texels taken from `other` (a speck of
    // the frame's faintest part inside a black square) goes too: one with
    // at least three of its four neighbours (wrapping) taken, until none is
    // left, so a short dash goes from its ends. A faint texel along the
    // border of `own`'s region (a splat's tail) has `own`'s texels on two
    // sides and stays. Taking only adds takers, so the texels taken do not
    // depend on the order they are looked at in (a worklist: each texel is
    // looked at again only when a neighbour was taken).
    let (w, h) = (t.width, t.height);
    let near = |i: usize| {
        let (x, y) = (i % w, i / w);
        [
            y * w + (x + w - 1) % w,
            y * w + (x + 1) % w,
            ((y + h - 1) % h) * w + x,
            ((y + 1) % h) * w + x,
        ]
    };
    let mut work: Vec<usize> = (0..n).filter(|&i| !take[i] && outweighed(i)).collect();
    while let Some(i) = work.pop() {
        if take[i] || near(i).iter().filter(|&&j| take[j]).count() < 3 {
            continue;
        }
        take[i] = true;
        work.extend(near(i).into_iter().filter(|&j| !take[j] && outweighed(j)));
    }
    for (i, _) in take.iter().enumerate().filter(|(_, &t)| t) {
        for c in 0..channels {
            own.texture.data[c * n + i] = other.texture.data[c * n + i];
        }
        own.weight.data[i] = other.weight.data[i];
        own.coverage.data[i] = other.coverage.data[i];
        own.known[i] = true;
        filled += 1;
    }
    filled
}

/// [`reproject`] without the back-projection rounds: the plain robust
/// splat, for a quick look at the texture (the plane mode's period search).
pub fn reproject_unsharpened(
    coords: &Coords,
    mask: &[bool],
    colour: &Image,
    confidence: &[f32],
    size: usize,
) -> Reprojected {
    let block = merge_block(coords, mask, size);
    reproject_rounds(
        coords,
        mask,
        colour,
        confidence,
        size,
        Splatting {
            rounds: 0,
            block,
            shift: None,
        },
    )
}

/// How [`reproject_rounds`] splats.
#[derive(Clone, Copy, Debug)]
struct Splatting {
    /// Rounds of back-projection.
    rounds: usize,
    /// Side of the pixel blocks merged where coherent ([`merge_block`]; 1:
    /// every pixel its own sample).
    block: usize,
    /// Each sample splatted again, shifted by this (a centred fold:
    /// [`reproject_centred`]).
    shift: Option<[f32; 2]>,
}

impl Splatting {
    /// [`reproject`]'s: every back-projection round, blocks merged as
    /// [`merge_block`] finds them coherent.
    fn full(coords: &Coords, mask: &[bool], size: usize, shift: Option<[f32; 2]>) -> Self {
        Splatting {
            rounds: BACK_PROJECTIONS,
            block: merge_block(coords, mask, size),
            shift,
        }
    }
}

/// [`reproject`] as `how` says.
fn reproject_rounds(
    coords: &Coords,
    mask: &[bool],
    colour: &Image,
    confidence: &[f32],
    size: usize,
    how: Splatting,
) -> Reprojected {
    let Splatting {
        rounds,
        block,
        shift,
    } = how;
    let n = coords.width * coords.height;
    assert_eq!(mask.len(), n, "mask size");
    assert_eq!(colour.plane_len(), n, "colour size");
    if size == 0 {
        // No texel to splat into: an empty texture, nothing known.
        return Reprojected {
            texture: Image::zeros(3, 0, 0),
            weight: Image::zeros(1, 0, 0),
            coverage: Image::zeros(1, 0, 0),
            known: Vec::new(),
        };
    }
    let mut fit = Fit::new(coords, mask, colour, confidence, size, block, shift);
    fit.back_project(rounds);
    let (tex, wsum, seen) = (&fit.tex, &fit.wsum, &fit.seen);
    let mut texture = Image::zeros(3, size, size);
    let mut weight = Image::zeros(1, size, size);
    let mut coverage = Image::zeros(1, size, size);
    let mut known = vec![false; size * size];
    // Whether a texel is known goes by how well it was seen, not by the
    // confidence of the pixels that saw it: a texel seen only through
    // low-confidence pixels (a white grout line clipped in the photo, a mask
    // edge) keeps their colour rather than being inpainted from other
    // texels; where better pixels saw it too, they dominate its mean. When
    // no texel reaches the threshold (a material seen from very far), it
    // drops to half the largest observation weight.
    let max_seen = seen.iter().copied().fold(0.0f32, f32::max);
    let threshold = KNOWN_WEIGHT.min(0.5 * max_seen);
    for t in 0..size * size {
        let w = wsum[t];
        weight.data[t] = w;
        coverage.data[t] = w / (w + 0.5);
        if w > 0.0 && seen[t] >= threshold {
            known[t] = true;
            texture.set_rgb(t, tex[t]);
        }
    }
    Reprojected {
        texture,
        weight,
        coverage,
        known,
    }
}

/// Cross-validated consistency of the coordinates: the picked pixels are
/// split into two halves by 16×16-pixel blocks assigned by a hash of the
/// block index (so the split cannot alias with a texture period), each half is
/// reprojected alone, and the two textures are compared on the texels both
/// observe. Returns `(R², overlap fraction)` where `R² = 1 − MSE/(2·var)`
/// (1: the halves agree perfectly; ≤ 0: no better than chance), or `None`
/// when fewer than 5% of the texels are seen by both halves.
pub fn consistency(
    coords: &Coords,
    mask: &[bool],
    colour: &Image,
    size: usize,
) -> Option<(f64, f64)> {
    let w = coords.width;
    let half = |parity: usize| -> Vec<f32> {
        (0..mask.len())
            .into_par_iter()
            .map(|i| (block_half(w, i) == parity) as u8 as f32)
            .collect()
    };
    let size = size.min(128);
    let a = reproject(coords, mask, colour, &half(0), size);
    let b = reproject(coords, mask, colour, &half(1), size);
    let both: Vec<usize> = (0..size * size)
        .filter(|&t| a.known[t] && b.known[t])
        .collect();
    let overlap = both.len() as f64 / (size * size) as f64;
    if overlap < 0.05 {
        return None;
    }
    let mut mse = 0.0f64;
    let mut mean = [0.0f64; 3];
    for &t in &both {
        let (x, y) = (a.texture.rgb(t), b.texture.rgb(t));
        mse += (x - y).length_squared() as f64;
        for c in 0..3 {
            mean[c] += (x[c] + y[c]) as f64 / 2.0;
        }
    }
    let k = both.len() as f64;
    mse /= k;
    let m = Vec3::new(
        (mean[0] / k) as f32,
        (mean[1] / k) as f32,
        (mean[2] / k) as f32,
    );
    let mut var = 0.0f64;
    for &t in &both {
        var += ((a.texture.rgb(t) - m).length_squared() + (b.texture.rgb(t) - m).length_squared())
            as f64
            / 2.0;
    }
    var /= k;
    let r2 = if var > 1e-12 {
        1.0 - mse / (2.0 * var)
    } else if mse < 1e-12 {
        1.0
    } else {
        0.0
    };
    Some((r2, overlap))
}

/// The plain, sequential splat (the reference of [`splat`]).
#[cfg(test)]
fn splat_reference(
    samples: &Samples,
    size: usize,
    wrap: bool,
    reference: Option<&[Vec3]>,
    scale: f32,
    values: Option<&[Vec3]>,
) -> (Vec<Vec3>, Vec<f32>, Vec<f32>) {
    let mut sum = vec![Vec3::ZERO; size * size];
    let mut wsum = vec![0.0f32; size * size];
    let mut seen = vec![0.0f32; size * size];
    let n = size as i64;
    for (k, s) in samples.list.iter().enumerate() {
        let fp = samples.fp(s);
        let value = values.map_or(s.colour, |v| v[k]);
        let px = s.u * size as f32 - 0.5;
        let py = s.v * size as f32 - 0.5;
        let [ex, ey] = fp.ext;
        let (x0, x1) = ((px - ex).ceil() as i64, (px + ex).floor() as i64);
        let (y0, y1) = ((py - ey).ceil() as i64, (py + ey).floor() as i64);
        for ty in y0..=y1 {
            let yy = if wrap { ty.rem_euclid(n) } else { ty };
            if yy < 0 || yy >= n {
                continue;
            }
            for tx in x0..=x1 {
                let k = fp.weight_at(tx as f32 - px, ty as f32 - py);
                if k <= 0.0 {
                    continue;
                }
                let xx = if wrap { tx.rem_euclid(n) } else { tx };
                if xx < 0 || xx >= n {
                    continue;
                }
                let t = yy as usize * size + xx as usize;
                let mut w = s.weight * k;
                if let Some(mean) = reference {
                    let d = (s.colour - mean[t]).length() / scale;
                    w /= 1.0 + d * d;
                }
                sum[t] += value * w;
                wsum[t] += w;
                seen[t] += s.count / fp.area * k;
            }
        }
    }
    (sum, wsum, seen)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A picture of a periodic texture seen frontally: pixel (x, y) has
    /// u = x/p, v = y/p (wrapped) and the texture's colour there.
    fn frontal(w: usize, h: usize, p: f32, tex: impl Fn(f32, f32) -> Vec3) -> (Coords, Image) {
        let mut u = vec![0.0; w * h];
        let mut v = vec![0.0; w * h];
        let mut img = Image::zeros(3, h, w);
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                u[i] = ((x as f32 + 0.5) / p).fract();
                v[i] = ((y as f32 + 0.5) / p).fract();
                img.set_rgb(i, tex(u[i], v[i]));
            }
        }
        (
            Coords {
                width: w,
                height: h,
                u,
                v,
                wrap: true,
            },
            img,
        )
    }

    /// Two halves of a picture reprojected apart: filling the first's
    /// unknown texels from the second's gives exactly the union's known set,
    /// keeps every texel the first knew bit for bit unless the second saw it
    /// [`OUTWEIGHED`] times as much (along the seam between the halves),
    /// and takes the second's values elsewhere.
    #[test]
    fn unknown_texels_are_filled_from_another_reprojection() {
        let tex = |u: f32, v: f32| Vec3::new(u, v, (u * 7.0).sin().abs());
        let (coords, img) = frontal(24, 24, 24.0, tex);
        let left: Vec<bool> = (0..24 * 24).map(|i| i % 24 < 12).collect();
        let right: Vec<bool> = left.iter().map(|&l| !l).collect();
        let conf = vec![1.0; 24 * 24];
        let a = reproject(&coords, &left, &img, &conf, 24);
        let b = reproject(&coords, &right, &img, &conf, 24);
        let mut f = a.clone();
        let n = fill_unknown_from(&mut f, &b);
        let outweighed = |i: usize| {
            a.known[i] && b.known[i] && b.weight.data[i] >= OUTWEIGHED * a.weight.data[i]
        };
        let expect = (0..24 * 24)
            .filter(|&i| b.known[i] && (!a.known[i] || outweighed(i)))
            .count();
        assert_eq!(n, expect);
        assert!(n > 0);
        let seam = (0..24 * 24).filter(|&i| outweighed(i)).count();
        assert!(seam <= 2 * 24, "{seam} texels outweighed");
        for i in 0..24 * 24 {
            assert_eq!(f.known[i], a.known[i] || b.known[i]);
            let src = if a.known[i] && !outweighed(i) {
                &a
            } else if b.known[i] {
                &b
            } else {
                &a
            };
            for c in 0..3 {
                assert_eq!(
                    f.texture.data[c * 576 + i].to_bits(),
                    src.texture.data[c * 576 + i].to_bits()
                );
            }
            assert_eq!(f.weight.data[i].to_bits(), src.weight.data[i].to_bits());
            assert_eq!(f.coverage.data[i].to_bits(), src.coverage.data[i].to_bits());
        }
        // Filling from itself changes nothing.
        let mut g = a.clone();
        assert_eq!(fill_unknown_from(&mut g, &a), 0);
        assert_eq!(g.known, a.known);
    }

    /// A fold of 8 × 8 repeats of a chessboard (wrapped coordinates of
    /// period 12 pixels) whose surest part is the white squares and a strip
    /// of white frame one repeat tall lying across the black squares' lower
    /// rows; the rest of the mask is the black squares. The strip's texels,
    /// shown by one row of repeats of the surest part and by seven of the
    /// rest, come out black, as the rest shows them; the white squares keep
    /// the surest part's values.
    #[test]
    fn a_strip_the_surest_part_shows_in_few_repeats_gives_way_to_the_rest() {
        let (w, h, p) = (96usize, 96usize, 12.0f32);
        let board = |x: usize, y: usize| ((x / 6) + (y / 6)).is_multiple_of(2);
        // The frame: the last row of repeats, its black squares' lower rows white.
        let frame = |x: usize, y: usize| y >= 84 && y % 12 >= 9 && !board(x, y);
        let mut img = Image::zeros(3, h, w);
        let (mut u, mut v) = (vec![0.0; w * h], vec![0.0; w * h]);
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                u[i] = ((x as f32 + 0.5) / p).fract();
                v[i] = ((y as f32 + 0.5) / p).fract();
                let white = board(x, y) || frame(x, y);
                img.set_rgb(i, Vec3::splat(if white { 0.8 } else { 0.05 }));
            }
        }
        let coords = Coords {
            width: w,
            height: h,
            u,
            v,
            wrap: true,
        };
        let sure: Vec<bool> = (0..w * h)
            .map(|i| board(i % w, i / w) || frame(i % w, i / w))
            .collect();
        let rest: Vec<bool> = sure.iter().map(|&b| !b).collect();
        let conf = vec![1.0; w * h];
        let size = 12;
        let mut own = reproject(&coords, &sure, &img, &conf, size);
        let other = reproject(&coords, &rest, &img, &conf, size);
        let before = own.clone();
        let n = fill_unknown_from(&mut own, &other);
        assert!(n > 0);
        let lum = |r: &Reprojected, x: usize, y: usize| r.texture.rgb(y * size + x).x;
        // A strip texel (a black square's lower rows): white before, black after.
        assert!(lum(&before, 2, 10) > 0.5, "{}", lum(&before, 2, 10));
        assert!(lum(&own, 2, 10) < 0.2, "{}", lum(&own, 2, 10));
        // A black square's upper rows: never shown by the surest part.
        assert!(!before.known[7 * size + 2]);
        assert!(lum(&own, 2, 7) < 0.2);
        // The white squares' centres keep the surest part's values.
        for (x, y) in [(2, 2), (8, 8)] {
            assert_eq!(lum(&own, x, y).to_bits(), lum(&before, x, y).to_bits());
        }
    }

    /// `fill_unknown_from`'s faint texels: a lone one inside a hole of
    /// `own`'s (a speck) is taken from `other`; a row of them along `own`'s
    /// strong texels (a splat's tail) keeps `own`'s values.
    #[test]
    fn a_faint_speck_goes_and_a_faint_border_stays() {
        let n = 8;
        let at = |x: usize, y: usize| y * n + x;
        let hole = |x: usize, y: usize| (2..6).contains(&x) && (3..7).contains(&y);
        let mut own = Reprojected {
            texture: Image::zeros(3, n, n),
            weight: Image::zeros(1, n, n),
            coverage: Image::zeros(1, n, n),
            known: vec![false; n * n],
        };
        let mut other = own.clone();
        for y in 0..n {
            for x in 0..n {
                let i = at(x, y);
                other.texture.set_rgb(i, Vec3::splat(0.05));
                other.weight.data[i] = 5.0;
                other.known[i] = true;
                // Strong everywhere but the hole and a faint row 2 (the
                // tail along the hole's top border).
                let w = if hole(x, y) {
                    continue;
                } else if y == 2 {
                    0.01
                } else {
                    10.0
                };
                own.texture.set_rgb(i, Vec3::splat(0.8));
                own.weight.data[i] = w;
                own.known[i] = true;
            }
        }
        // The speck.
        own.known[at(3, 4)] = true;
        own.weight.data[at(3, 4)] = 0.01;
        own.texture.set_rgb(at(3, 4), Vec3::splat(0.8));
        let before = own.clone();
        let taken = fill_unknown_from(&mut own, &other);
        assert_eq!(taken, 16, "the hole, its speck included");
        assert_eq!(own.texture.rgb(at(3, 4)).x, 0.05);
        for x in 0..n {
            assert_eq!(
                own.texture.rgb(at(x, 2)),
                before.texture.rgb(at(x, 2)),
                "row 2, x {x}"
            );
        }
    }

    /// A frontal chessboard (squares of 6 pixels, a 12-pixel period that
    /// is the wrapped square): splatted again shifted by half the square,
    /// the board lands on itself, so the texture is the plain one's; with
    /// only one of the two black places in the mask, the shifted copy shows
    /// the other place black, where the plain splat knows nothing.
    #[test]
    fn a_centred_splat_sees_both_places_of_a_chessboard() {
        let board = |u: f32, v: f32| {
            let k = (u * 2.0).floor() as i32 + (v * 2.0).floor() as i32;
            Vec3::splat(if k % 2 == 0 { 0.9 } else { 0.1 })
        };
        let (w, h) = (48, 36);
        let (coords, img) = frontal(w, h, 12.0, board);
        let conf = vec![1.0; w * h];
        let all = vec![true; w * h];
        let size = 12;
        let plain = reproject(&coords, &all, &img, &conf, size);
        let centred = reproject_centred(&coords, &all, &img, &conf, size, [0.5, 0.5]);
        assert_eq!(plain.known, centred.known);
        for (a, b) in plain.texture.data.iter().zip(&centred.texture.data) {
            assert!((a - b).abs() < 0.02, "{a} vs {b}");
        }
        for (a, b) in plain.weight.data.iter().zip(&centred.weight.data) {
            assert!((b / a - 2.0).abs() < 1e-3, "weights {a} {b}");
        }
        // White squares and the black squares of one place: (even, odd).
        let (sq_x, sq_y) = (|i: usize| (i % w) / 6, |i: usize| (i / w) / 6);
        let half: Vec<bool> = (0..w * h)
            .map(|i| (sq_x(i) + sq_y(i)) % 2 == 0 || sq_x(i) % 2 == 0)
            .collect();
        let plain = reproject(&coords, &half, &img, &conf, size);
        let centred = reproject_centred(&coords, &half, &img, &conf, size, [0.5, 0.5]);
        // The other black place's texels, away from the squares' edges.
        let other = |t: usize| {
            let (x, y) = (t % size, t / size);
            (7..11).contains(&x) && (1..5).contains(&y)
        };
        for t in (0..size * size).filter(|&t| other(t)) {
            assert!(!plain.known[t], "texel {t} known without the shift");
            assert!(centred.known[t], "texel {t} unknown with the shift");
            assert!(
                centred.texture.rgb(t).x < 0.2,
                "texel {t}: {}",
                centred.texture.rgb(t)
            );
        }
        // Every texel the plain splat knows, the centred one knows.
        assert!(plain
            .known
            .iter()
            .zip(&centred.known)
            .all(|(&a, &b)| !a || b));
    }

    /// The reference for [`reproject_centred`]: the picture stacked twice
    /// (a row outside the mask between), the second copy's coordinates
    /// moved by the shift, reprojected plainly. Both of its ways agree with
    /// it on noisy colours and a ragged mask, robust weights and
    /// back-projection included: half-square shifts by their sums (to
    /// rounding: a moved sample's texel, `(u + ½)·size`, can round the
    /// other way at a texel's edge, which moves the robust weights' scale a
    /// little), other shifts, fractions of a texel too, by their copies.
    #[test]
    fn a_centred_splat_is_the_splat_of_shifted_copies() {
        let (w, h) = (40, 30);
        let mut rng = picker_tensor::Rng::new(12);
        let noise: Vec<f32> = (0..w * h).map(|_| rng.uniform(-0.1, 0.1)).collect();
        let mask: Vec<bool> = (0..w * h).map(|_| rng.f64() < 0.7).collect();
        let conf: Vec<f32> = (0..w * h).map(|_| rng.uniform(0.3, 1.0)).collect();
        let (coords, img) = frontal(w, h, 20.0, |u, v| {
            Vec3::new(u, v * v, (u * 9.0).sin().abs())
        });
        let mut noisy = img.clone();
        for (i, n) in noise.iter().enumerate() {
            noisy.set_rgb(i, img.rgb(i) + Vec3::splat(*n));
        }
        for (size, shift) in [
            (20, [0.5f32, 0.5f32]),
            (20, [0.5, 0.0]),
            (40, [0.0, 0.5]),
            (16, [0.25, 0.25]),
            (42, [0.25, 0.75]),
            (21, [0.5, 0.5]),
        ] {
            let h2 = 2 * h + 1;
            let mut c2 = Coords {
                width: w,
                height: h2,
                u: vec![f32::NAN; w * h2],
                v: vec![f32::NAN; w * h2],
                wrap: true,
            };
            let mut img2 = Image::zeros(3, h2, w);
            let (mut m2, mut conf2) = (vec![false; w * h2], vec![0.0; w * h2]);
            for i in 0..w * h {
                for (j, by) in [(i, [0.0, 0.0]), (i + w * (h + 1), shift)] {
                    c2.u[j] = (coords.u[i] + by[0]).fract();
                    c2.v[j] = (coords.v[i] + by[1]).fract();
                    img2.set_rgb(j, noisy.rgb(i));
                    m2[j] = mask[i];
                    conf2[j] = conf[i];
                }
            }
            let got = reproject_centred(&coords, &mask, &noisy, &conf, size, shift);
            let want = reproject(&c2, &m2, &img2, &conf2, size);
            let case = format!("size {size} shift {shift:?}");
            assert_eq!(got.known, want.known, "{case}");
            for (a, b) in got.texture.data.iter().zip(&want.texture.data) {
                assert!((a - b).abs() < 1e-3, "{case}: {a} vs {b}");
            }
            for (a, b) in got.weight.data.iter().zip(&want.weight.data) {
                assert!(
                    (a - b).abs() <= 1e-3 * b.abs().max(1.0),
                    "{case}: {a} vs {b}"
                );
            }
        }
    }

    #[test]
    fn shifted_copies_wrap_and_keep_their_footprints() {
        // (The copies share their originals' footprint index.)
        let s = |u: f32, v: f32| Sample {
            u,
            v,
            colour: Vec3::new(u, v, 1.0),
            weight: 0.5,
            fp: 7,
            count: 3.0,
        };
        let out = with_shifted_copies(vec![s(0.0, 0.75), s(0.6, 0.999_999_9)], [0.5, 0.25]);
        assert_eq!(out.len(), 4);
        assert_eq!(out[..2], [s(0.0, 0.75), s(0.6, 0.999_999_9)]);
        assert_eq!((out[2].u, out[2].v), (0.5, 0.0));
        assert!((out[3].u - 0.1).abs() < 1e-6 && (out[3].v - 0.25).abs() < 1e-6);
        for c in &out[2..] {
            assert!((0.0..1.0).contains(&c.u) && (0.0..1.0).contains(&c.v));
            assert_eq!((c.weight, c.fp, c.count), (0.5, 7, 3.0));
        }
        assert_eq!(out[3].colour, Vec3::new(0.6, 0.999_999_9, 1.0));
        assert!(with_shifted_copies(Vec::new(), [0.5, 0.5]).is_empty());
    }

    /// Whole shifts move the sums exactly (wrapping); a half-texel shift
    /// reads the average of two neighbours; a shift by the whole square
    /// doubles.
    #[test]
    fn shifted_sums_are_added_wrapping() {
        let size = 4;
        let a: Vec<f32> = (0..16).map(|i| i as f32).collect();
        let b = plus_shifted(&a, size, [1.0, 0.0]);
        for y in 0..4 {
            for x in 0..4 {
                let src = y * 4 + (x + 3) % 4;
                assert_eq!(b[y * 4 + x], a[y * 4 + x] + a[src], "({x}, {y})");
            }
        }
        let b = plus_shifted(&a, size, [0.0, -1.0]);
        assert_eq!(b[0], a[0] + a[4]);
        assert_eq!(b[12], a[12] + a[0]);
        let b = plus_shifted(&a, size, [0.5, 0.0]);
        assert_eq!(b[1], a[1] + 0.5 * (a[0] + a[1]));
        assert_eq!(b[0], a[0] + 0.5 * (a[3] + a[0]));
        let b = plus_shifted(&a, size, [4.0, 8.0]);
        assert!(b.iter().zip(&a).all(|(x, y)| *x == 2.0 * y));
        // Vectors too, and the empty square.
        let v = vec![Vec3::new(1.0, 2.0, 3.0); 9];
        assert!(plus_shifted(&v, 3, [1.5, 2.25])
            .iter()
            .all(|c| (*c - Vec3::new(2.0, 4.0, 6.0)).length() < 1e-6));
        assert!(plus_shifted::<f32>(&[], 0, [0.5, 0.5]).is_empty());
    }

    #[test]
    #[should_panic(expected = "must wrap")]
    fn a_centred_splat_needs_wrapping_coordinates() {
        let (mut coords, img) = frontal(8, 8, 8.0, |u, v| Vec3::new(u, v, 0.0));
        coords.wrap = false;
        reproject_centred(&coords, &[true; 64], &img, &[1.0; 64], 8, [0.5, 0.5]);
    }

    #[test]
    #[should_panic(expected = "sizes differ")]
    fn filling_from_another_size_is_refused() {
        let (coords, img) = frontal(8, 8, 8.0, |u, v| Vec3::new(u, v, 0.0));
        let m = vec![true; 64];
        let mut a = reproject(&coords, &m, &img, &[1.0; 64], 8);
        let b = reproject(&coords, &m, &img, &[1.0; 64], 16);
        fill_unknown_from(&mut a, &b);
    }

    #[test]
    fn low_confidence_pixels_still_give_known_texels() {
        let tex = |u: f32, v: f32| Vec3::new(u, v, 0.5);
        let (coords, img) = frontal(8, 8, 32.0, tex);
        let mut mask = vec![false; 64];
        mask[27] = true;
        mask[28] = true;
        // Clipped highlights on the mask edge: confidence far below KNOWN_WEIGHT.
        let r = reproject(&coords, &mask, &img, &vec![0.0125; 64], 16);
        assert!(r.known_fraction() > 0.0);
        for t in 0..16 * 16 {
            if r.known[t] {
                assert!(r.weight.data[t] > 0.0);
            }
        }
        // No usable pixel: nothing known.
        let r = reproject(&coords, &mask, &img, &vec![0.0; 64], 16);
        assert_eq!(r.known_fraction(), 0.0);
        // No texel at all: an empty texture.
        let r = reproject(&coords, &mask, &img, &vec![1.0; 64], 0);
        assert!(r.known.is_empty() && r.texture.width == 0);
        assert_eq!(r.known_fraction(), 0.0);
    }

    /// A bright line seen only through clipped pixels on the mask's edge
    /// (confidence 0.25 · 0.05, as the pipeline gives them) is known and
    /// keeps its colour: it is not left to the inpainter to fill from the
    /// dark texels around it.
    #[test]
    fn texels_seen_only_by_low_confidence_pixels_are_known() {
        // 32×32 pixels, one period: one pixel per texel of a 32-texel
        // texture; rows 8..10 are a white line.
        let line = |v: f32| (8.0 / 32.0..10.0 / 32.0).contains(&v);
        let tex = |_u: f32, v: f32| {
            if line(v) {
                Vec3::splat(0.9)
            } else {
                Vec3::splat(0.1)
            }
        };
        let (coords, img) = frontal(32, 32, 32.0, tex);
        let mask = vec![true; 32 * 32];
        let confidence: Vec<f32> = (0..32 * 32)
            .map(|i| if line(coords.v[i]) { 0.0125 } else { 1.0 })
            .collect();
        let r = reproject(&coords, &mask, &img, &confidence, 32);
        for ty in 8..10 {
            for tx in 0..32 {
                let t = ty * 32 + tx;
                assert!(r.known[t], "line texel ({tx}, {ty}) not known");
                let c = r.texture.rgb(t);
                assert!(c.x > 0.5, "line texel ({tx}, {ty}) = {c}");
            }
        }
        assert_eq!(r.known_fraction(), 1.0);
    }

    #[test]
    fn frontal_texture_is_recovered_and_sized_by_density() {
        let tex = |u: f32, v: f32| Vec3::new(u, v, 0.5);
        let (coords, img) = frontal(96, 64, 32.0, tex);
        let mask = vec![true; 96 * 64];
        let area = coords.sizing_area(&mask).unwrap();
        assert!((area - 1.0 / 1024.0).abs() < 1e-5, "{area}");
        let size = texture_size(Some(area), 1024);
        assert_eq!(size, 32);
        let r = reproject(&coords, &mask, &img, &vec![1.0; 96 * 64], size);
        assert_eq!(r.known_fraction(), 1.0);
        for y in 1..size - 1 {
            for x in 1..size - 1 {
                let c = r.texture.rgb(y * size + x);
                let t = tex((x as f32 + 0.5) / 32.0, (y as f32 + 0.5) / 32.0);
                assert!((c - t).abs().max_element() < 0.02, "{x},{y}: {c} vs {t}");
            }
        }
        let (r2, overlap) = consistency(&coords, &mask, &img, size).unwrap();
        assert!(r2 > 0.95 && overlap > 0.5, "{r2} {overlap}");
    }

    #[test]
    fn back_projection_sharpens_the_splat() {
        // A smooth periodic texture seen frontally, a pixel every 0.6 texels:
        // the tent splat blurs it, back-projection takes most of that back
        // (here the RMSE drops from 0.035 to 0.015; the clamp to the splat's
        // largest value caps the peaks).
        let tex = |u: f32, v: f32| {
            let t = std::f32::consts::TAU;
            Vec3::splat(0.5 + 0.4 * (t * 4.0 * u).sin() * (t * 3.0 * v).cos())
        };
        let (coords, img) = frontal(120, 96, 40.0, tex);
        let mask = vec![true; 120 * 96];
        let conf = vec![1.0; 120 * 96];
        let rmse = |r: &Reprojected| {
            let mut e = 0.0f64;
            for y in 0..24 {
                for x in 0..24 {
                    let t = tex((x as f32 + 0.5) / 24.0, (y as f32 + 0.5) / 24.0);
                    e += f64::from((r.texture.rgb(y * 24 + x) - t).length_squared());
                }
            }
            (e / (3.0 * 576.0)).sqrt()
        };
        assert_eq!(merge_block(&coords, &mask, 24), 1);
        let plain = reproject_rounds(
            &coords,
            &mask,
            &img,
            &conf,
            24,
            Splatting {
                rounds: 0,
                block: 1,
                shift: None,
            },
        );
        let sharp = reproject(&coords, &mask, &img, &conf, 24);
        let (a, b) = (rmse(&plain), rmse(&sharp));
        assert!(a > 0.02, "the splat should blur this texture: {a}");
        assert!(b < 0.6 * a, "back-projection {b} vs splat {a}");
        // Same bits whatever the number of threads.
        let one = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        let again = one.install(|| reproject(&coords, &mask, &img, &conf, 24));
        let bits = |r: &Reprojected| {
            r.texture
                .data
                .iter()
                .map(|x| x.to_bits())
                .collect::<Vec<_>>()
        };
        assert_eq!(bits(&again), bits(&sharp));
    }

    #[test]
    fn scrambled_coordinates_are_inconsistent() {
        let tex = |u: f32, v: f32| Vec3::splat(((u * 8.0) as i32 + (v * 8.0) as i32) as f32 % 2.0);
        let (mut coords, img) = frontal(128, 128, 32.0, tex);
        let mut rng = picker_tensor::Rng::new(1);
        for i in 0..coords.u.len() {
            coords.u[i] = rng.uniform(0.0, 1.0);
            coords.v[i] = rng.uniform(0.0, 1.0);
        }
        let (r2, _) = consistency(&coords, &vec![true; 128 * 128], &img, 32).unwrap();
        assert!(r2 < 0.3, "{r2}");
    }

    /// A sample coordinate in `[-0.2, 1.2)`, on a texel centre (or an edge
    /// between two) one time in four: where a tent's end taps weigh 0.
    fn random_position(rng: &mut picker_tensor::Rng, size: usize) -> f32 {
        let t = rng.uniform(-0.2, 1.2);
        if rng.range(0, 4) == 0 {
            let half = 2.0 * size as f32;
            (t * half).round() / half
        } else {
            t
        }
    }

    /// The plain implementation of [`predict`]: every texel of the tent's
    /// bounding box, its weight written out ([`Footprint::weight_at`]).
    fn predict_reference(
        s: &Sample,
        fp: &Footprint,
        tex: &[Vec3],
        size: usize,
        wrap: bool,
    ) -> Option<Vec3> {
        let n = size as i64;
        let px = s.u * size as f32 - 0.5;
        let py = s.v * size as f32 - 0.5;
        let [ex, ey] = fp.ext;
        let (x0, x1) = ((px - ex).ceil() as i64, (px + ex).floor() as i64);
        let (y0, y1) = ((py - ey).ceil() as i64, (py + ey).floor() as i64);
        let (mut acc, mut wsum) = (Vec3::ZERO, 0.0f32);
        for ty in y0..=y1 {
            let yy = if wrap { ty.rem_euclid(n) } else { ty };
            if yy < 0 || yy >= n {
                continue;
            }
            for tx in x0..=x1 {
                let w = fp.weight_at(tx as f32 - px, ty as f32 - py);
                let xx = if wrap { tx.rem_euclid(n) } else { tx };
                if w <= 0.0 || xx < 0 || xx >= n {
                    continue;
                }
                acc += tex[yy as usize * size + xx as usize] * w;
                wsum += w;
            }
        }
        (wsum > 0.0).then(|| acc / wsum)
    }

    #[test]
    fn prediction_matches_reference() {
        let mut rng = picker_tensor::Rng::new(31);
        for &size in &[1usize, 2, 3, 16, 17, 40] {
            let tex: Vec<Vec3> = (0..size * size)
                .map(|_| Vec3::new(rng.uniform(0.0, 1.0), rng.uniform(0.0, 1.0), 0.5))
                .collect();
            for wrap in [true, false] {
                for k in 0..400 {
                    let s = Sample {
                        u: random_position(&mut rng, size),
                        v: random_position(&mut rng, size),
                        colour: Vec3::ZERO,
                        weight: 1.0,
                        fp: 0,
                        count: 1.0,
                    };
                    let fp = random_footprint(&mut rng);
                    let bits = |p: Option<Vec3>| p.map(|c| c.to_array().map(f32::to_bits));
                    assert_eq!(
                        bits(predict(&s, &fp, &tex, size, wrap)),
                        bits(predict_reference(&s, &fp, &tex, size, wrap)),
                        "size {size} wrap {wrap} sample {k}: {s:?}"
                    );
                }
            }
        }
    }

    /// A footprint from a random Jacobian: isotropic, the one-texel tent, oblique, degenerate
    /// (collapsed onto a line) or far beyond the clamps.
    fn random_footprint(rng: &mut picker_tensor::Rng) -> Footprint {
        let mut j = || rng.uniform(-6.0, 6.0);
        let (jx, mut jy) = ([j(), j()], [j(), j()]);
        match rng.range(0, 6) {
            0 => Footprint::isotropic(rng.uniform(1.0, MAX_SPLAT_RADIUS * 3.0)),
            // The one-texel tent (merged blocks, fine pixels).
            4 | 5 => Footprint::isotropic(1.0),
            1 => {
                // Parallel columns: a degenerate Jacobian.
                let t = rng.uniform(-2.0, 2.0);
                jy = [jx[0] * t, jx[1] * t];
                Footprint::from_jacobian(jx, jy)
            }
            _ => Footprint::from_jacobian(jx, jy),
        }
    }

    /// `J'` of a footprint, recovered by inverting `inv`.
    fn forward(fp: &Footprint) -> [f64; 4] {
        let m = fp.inv.map(f64::from);
        let det = m[0] * m[3] - m[1] * m[2];
        [m[3] / det, -m[1] / det, -m[2] / det, m[0] / det]
    }

    /// Singular values (largest first) of a row-major 2×2 matrix.
    fn singular_values(m: [f64; 4]) -> (f64, f64) {
        let fro = m.iter().map(|x| x * x).sum::<f64>();
        let det = (m[0] * m[3] - m[1] * m[2]).abs();
        let disc = (fro * fro - 4.0 * det * det).max(0.0).sqrt();
        (
            ((fro + disc) / 2.0).sqrt(),
            ((fro - disc) / 2.0).max(0.0).sqrt(),
        )
    }

    #[test]
    fn footprint_clamps_the_singular_values_and_keeps_the_rest() {
        let mut rng = picker_tensor::Rng::new(5);
        let max = f64::from(MAX_SPLAT_RADIUS);
        for case in 0..2000 {
            let scale = [0.05, 0.5, 1.0, 3.0, 20.0][case % 5];
            let mut j = || rng.uniform(-1.0, 1.0) * scale;
            let (jx, jy) = ([j(), j()], [j(), j()]);
            let fp = Footprint::from_jacobian(jx, jy);
            let jm = [jx[0], jy[0], jx[1], jy[1]].map(f64::from);
            let (s1, s2) = singular_values(jm);
            if s1 <= 1.0 {
                // Finer than a texel: the texel's own tent.
                assert_eq!(fp, Footprint::isotropic(1.0), "{case}");
                continue;
            }
            let jp = forward(&fp);
            let (t1, t2) = singular_values(jp);
            let tol = 1e-4 * t1.max(1.0);
            assert!(
                (t1 - s1.clamp(1.0, max)).abs() < tol,
                "{case}: {t1} vs {s1}"
            );
            assert!(
                (t2 - s2.clamp(1.0, max)).abs() < tol,
                "{case}: {t2} vs {s2}"
            );
            assert!((f64::from(fp.area) - t1 * t2).abs() < 1e-4 * t1 * t2);
            // Unclamped singular values: J' is J itself.
            if s2 >= 1.0 && s1 <= max {
                for k in 0..4 {
                    assert!(
                        (jp[k] - jm[k]).abs() < 1e-4 * s1,
                        "{case}: {jp:?} vs {jm:?}"
                    );
                }
            }
            // The bounding box holds the parallelogram's corners.
            assert!((f64::from(fp.ext[0]) - (jp[0].abs() + jp[1].abs())).abs() < 1e-4 * t1);
            assert!((f64::from(fp.ext[1]) - (jp[2].abs() + jp[3].abs())).abs() < 1e-4 * t1);
            // Same singular vectors: J'⁻¹·J = V·S'⁻¹·S·Vᵀ is symmetric
            // positive semi-definite.
            let inv = fp.inv.map(f64::from);
            let mj = [
                inv[0] * jm[0] + inv[1] * jm[2],
                inv[0] * jm[1] + inv[1] * jm[3],
                inv[2] * jm[0] + inv[3] * jm[2],
                inv[2] * jm[1] + inv[3] * jm[3],
            ];
            let big = mj.iter().fold(1.0f64, |m, x| m.max(x.abs()));
            assert!((mj[1] - mj[2]).abs() < 1e-4 * big, "{case}: {mj:?}");
            assert!(
                mj[0] >= -1e-4 * big && mj[3] >= -1e-4 * big,
                "{case}: {mj:?}"
            );
            assert!(
                mj[0] * mj[3] - mj[1] * mj[2] >= -1e-4 * big * big,
                "{case}: {mj:?}"
            );
        }
    }

    #[test]
    fn footprint_tent_follows_the_pixel_axes() {
        // A pixel stretched 3× along a direction at 30° and 0.2× across it
        // (clamped to 1): its tent is 1 at the centre, ½ a third of the way
        // along the stretched axis (1.5 texels out of 3, times 1 − 0 across),
        // 0 at a texel across, and symmetric.
        let (c, s) = (30f32.to_radians().cos(), 30f32.to_radians().sin());
        // J = R · diag(3, 0.2): columns are the texel steps of the pixel axes.
        let fp = Footprint::from_jacobian([3.0 * c, 3.0 * s], [-0.2 * s, 0.2 * c]);
        let at = |dx: f32, dy: f32| fp.weight(fp.row(dy), dx);
        assert!((at(0.0, 0.0) - 1.0).abs() < 1e-6);
        assert!((at(1.5 * c, 1.5 * s) - 0.5).abs() < 1e-5);
        assert!((at(-1.5 * c, -1.5 * s) - 0.5).abs() < 1e-5);
        assert!((at(-0.5 * s, 0.5 * c) - 0.5).abs() < 1e-5);
        assert_eq!(at(-1.01 * s, 1.01 * c), 0.0);
        assert_eq!(at(3.01 * c, 3.01 * s), 0.0);
        assert!((fp.area - 3.0).abs() < 1e-5);
        // The frontal case: the square tent of the old isotropic splat.
        let iso = Footprint::from_jacobian([2.5, 0.0], [0.0, 2.5]);
        for (dx, dy) in [(0.3f32, -1.2f32), (2.0, 0.5), (-2.4, 2.4)] {
            let want = (1.0 - dx.abs() / 2.5) * (1.0 - dy.abs() / 2.5);
            assert!((iso.weight(iso.row(dy), dx) - want).abs() < 1e-6);
        }
        assert_eq!(iso.ext, [2.5, 2.5]);
        // Degenerate and non-finite Jacobians.
        let line = Footprint::from_jacobian([2.0, 0.0], [4.0, 0.0]);
        let (t1, t2) = singular_values(forward(&line));
        assert!((t1 - f64::from(MAX_SPLAT_RADIUS)).abs() < 1e-4 && (t2 - 1.0).abs() < 1e-4);
        assert_eq!(
            Footprint::from_jacobian([f32::NAN, 0.0], [0.0, 1.0]),
            Footprint::isotropic(1.0)
        );
        assert_eq!(
            Footprint::from_jacobian([0.0, 0.0], [0.0, 0.0]),
            Footprint::isotropic(1.0)
        );
    }

    /// Wrapping coordinates of a `w × h` photo, all 0 (to fill in).
    fn wrapping_zeros(w: usize, h: usize) -> Coords {
        Coords {
            width: w,
            height: h,
            u: vec![0.0; w * h],
            v: vec![0.0; w * h],
            wrap: true,
        }
    }

    #[test]
    fn sharp_pixels_outweigh_blurred_ones_on_the_same_texels() {
        // Rows 0..16: the 16² texture square seen frontally, one texel per
        // pixel, colour 1. Row 16: not picked. Rows 17..33: the same square
        // seen from twice as far (two texels per pixel, wrapping four times
        // over it), colour 0. Both halves splat the same total weight per
        // texel under a plain `1/A` weight (texels near 0.5); the
        // inverse-variance `1/A²` lets the sharp half decide.
        let (w, h, size) = (16usize, 33usize, 16usize);
        let (mut coords, mut img) = (wrapping_zeros(w, h), Image::zeros(3, h, w));
        let mut mask = vec![true; w * h];
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                let (step, row, c) = match y {
                    0..=15 => (1.0, y, 1.0),
                    16 => {
                        mask[i] = false;
                        continue;
                    }
                    _ => (2.0, y - 17, 0.0),
                };
                coords.u[i] = ((x as f32 + 0.5) * step / size as f32).fract();
                coords.v[i] = ((row as f32 + 0.5) * step / size as f32).fract();
                img.set_rgb(i, Vec3::splat(c));
            }
        }
        let conf = vec![1.0; w * h];
        let r = reproject_rounds(
            &coords,
            &mask,
            &img,
            &conf,
            size,
            Splatting {
                rounds: 0,
                block: 1,
                shift: None,
            },
        );
        let mean = r.texture.data.iter().sum::<f32>() / r.texture.data.len() as f32;
        assert!(mean > 0.7 && mean <= 1.0, "{mean}");
        assert!(r.known.iter().all(|&k| k));
    }

    #[test]
    fn oblique_pixels_keep_the_detail_across_their_stretch() {
        // A plane seen obliquely: each pixel spans one texel along u and
        // four along v. Stripes across u (period 4 texels) survive in the
        // pixels (box averages over one texel); the footprint spreads each
        // pixel along v only, so they survive reprojection exactly (RMSE
        // 2e-7; an isotropic tent of the same area, radius 2, blurs them
        // across: RMSE 0.051).
        let (w, h, size) = (64usize, 64usize, 32usize);
        let t = |u: f32| 0.5 + 0.4 * (std::f32::consts::TAU * 8.0 * u).sin();
        let boxed = |u0: f32, du: f32| {
            (0..16)
                .map(|k| t(u0 + du * (k as f32 + 0.5) / 16.0))
                .sum::<f32>()
                / 16.0
        };
        let (mut coords, mut img) = (wrapping_zeros(w, h), Image::zeros(3, h, w));
        let px = 1.0 / size as f32;
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                coords.u[i] = ((x as f32 + 0.5) * px).fract();
                coords.v[i] = ((y as f32 + 0.5) * 4.0 * px).fract();
                img.set_rgb(i, Vec3::splat(boxed(x as f32 * px, px)));
            }
        }
        let (mask, conf) = (vec![true; w * h], vec![1.0; w * h]);
        let r = reproject(&coords, &mask, &img, &conf, size);
        let mut e = 0.0f64;
        for ty in 0..size {
            for tx in 0..size {
                let want = boxed(tx as f32 * px, px);
                e += f64::from(r.texture.data[ty * size + tx] - want).powi(2);
            }
        }
        let rmse = (e / (size * size) as f64).sqrt();
        assert!(rmse < 0.01, "{rmse}");
    }

    #[test]
    fn banded_splat_matches_reference() {
        let mut rng = picker_tensor::Rng::new(12);
        for &size in &[1usize, 3, 16, 17, 40] {
            for wrap in [true, false] {
                let samples = Samples::from_inline((0..500).map(|_| {
                    let s = Sample {
                        u: random_position(&mut rng, size),
                        v: random_position(&mut rng, size),
                        colour: Vec3::new(rng.uniform(0.0, 1.0), rng.uniform(0.0, 1.0), 0.3),
                        weight: rng.uniform(0.01, 1.0),
                        fp: 0,
                        count: rng.range(1, 64) as f32,
                    };
                    (s, random_footprint(&mut rng))
                }));
                let mean: Vec<Vec3> = (0..size * size)
                    .map(|_| Vec3::splat(rng.uniform(0.0, 1.0)))
                    .collect();
                for reference in [None, Some(mean.as_slice())] {
                    let members = band_members(&samples, size, wrap);
                    let values: Vec<Vec3> = (0..samples.list.len())
                        .map(|_| Vec3::splat(rng.uniform(-1.0, 1.0)))
                        .collect();
                    for vals in [None, Some(values.as_slice())] {
                        let (a, aw, aseen) =
                            splat(&samples, &members, size, wrap, reference, 0.2, vals, true);
                        let (b, bw, bseen) =
                            splat_reference(&samples, size, wrap, reference, 0.2, vals);
                        let bits = |v: &[Vec3]| {
                            v.iter()
                                .flat_map(|c| c.to_array().map(f32::to_bits))
                                .collect::<Vec<_>>()
                        };
                        assert_eq!(bits(&a), bits(&b), "size {size} wrap {wrap}");
                        let wb = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                        assert_eq!(wb(&aw), wb(&bw));
                        assert_eq!(wb(&aseen), wb(&bseen));
                        // Not tracked: the same sums, no observation weights.
                        let (c, cw, cseen) =
                            splat(&samples, &members, size, wrap, reference, 0.2, vals, false);
                        assert_eq!(bits(&c), bits(&a));
                        assert_eq!(wb(&cw), wb(&aw));
                        assert!(cseen.is_empty());
                    }
                }
            }
        }
    }

    /// Random coordinates in [−0.1, 1.1) on a `w × h` grid, `u` NaN at every
    /// `nan_every`-th pixel.
    fn random_coords(
        rng: &mut picker_tensor::Rng,
        w: usize,
        h: usize,
        wrap: bool,
        nan_every: usize,
    ) -> Coords {
        let n = w * h;
        let mut u = rng.uniform_vec(n, -0.1, 1.1);
        let v = rng.uniform_vec(n, -0.1, 1.1);
        for i in (0..n).step_by(nan_every) {
            u[i] = f32::NAN;
        }
        Coords {
            width: w,
            height: h,
            u,
            v,
            wrap,
        }
    }

    #[test]
    fn filled_in_parts_writes_every_part_in_order() {
        let counts = [3usize, 0, 5, 1];
        let v = filled_in_parts(&counts, true, |r, part| {
            for (k, slot) in part.iter_mut().enumerate() {
                slot.write(Sample {
                    u: r as f32,
                    v: k as f32,
                    ..Sample::default()
                });
            }
            part.len()
        });
        let got: Vec<(f32, f32)> = v.iter().map(|s| (s.u, s.v)).collect();
        let want: Vec<(f32, f32)> = counts
            .iter()
            .enumerate()
            .flat_map(|(r, &k)| (0..k).map(move |j| (r as f32, j as f32)))
            .collect();
        assert_eq!(got, want);
    }

    #[test]
    #[should_panic(expected = "not every counted sample written")]
    fn filled_in_parts_refuses_a_short_part() {
        filled_in_parts(&[2, 2], false, |r, part| {
            let n = if r == 1 { 1 } else { part.len() };
            for slot in &mut part[..n] {
                slot.write(Sample::default());
            }
            n
        });
    }

    #[test]
    fn unit_footprint_is_the_one_texel_tent() {
        assert!(Footprint::isotropic(1.0).is_unit());
        assert!(Footprint::from_jacobian([0.5, 0.0], [0.0, 0.25]).is_unit());
        assert!(!Footprint::isotropic(2.0).is_unit());
        // Bit for bit: a negative zero is another footprint.
        let mut z = Footprint::UNIT;
        z.inv[1] = -0.0;
        assert!(!z.is_unit());
        // Inline footprints: the unit ones share index 0, the others get
        // their own entries in order.
        let s = Sample::default();
        let two = Footprint::isotropic(2.0);
        let all = Samples::from_inline([
            (s, two),
            (s, Footprint::UNIT),
            (s, two),
            (s, Footprint::isotropic(1.0)),
        ]);
        assert_eq!(
            all.list.iter().map(|s| s.fp).collect::<Vec<_>>(),
            [1, 0, 2, 0]
        );
        assert_eq!(all.fps, [Footprint::UNIT, two, two]);
    }

    #[test]
    fn parallel_samples_match_reference() {
        let mut rng = picker_tensor::Rng::new(13);
        // (Empty images too: no rows, or rows of no pixels.)
        for &(w, h) in &[(1usize, 1usize), (5, 1), (1, 6), (37, 23), (0, 4), (3, 0)] {
            for wrap in [true, false] {
                let n = w * h;
                let coords = random_coords(&mut rng, w, h, wrap, 5);
                let mut colour = Image::new(3, h, w, rng.uniform_vec(3 * n, 0.0, 1.0)).unwrap();
                if n > 0 {
                    colour.data[n / 2] = f32::INFINITY;
                }
                let mask: Vec<bool> = (0..n).map(|_| rng.f64() < 0.7).collect();
                let conf: Vec<f32> = (0..n)
                    .map(|_| {
                        if rng.f64() < 0.2 {
                            0.0
                        } else {
                            rng.uniform(0.01, 1.0)
                        }
                    })
                    .collect();
                for size in [1, 16, 1024] {
                    for block in [1, 2, 3, 8] {
                        let src = Picked {
                            coords: &coords,
                            mask: &mask,
                            colour: &colour,
                            confidence: &conf,
                            size,
                        };
                        let a = samples(&src, block);
                        let b = samples_reference(&src, block);
                        assert_eq!(a, b, "{w}x{h} wrap {wrap} size {size} block {block}");
                        assert!(a.fps[0].is_unit());
                        if block == 1 {
                            // Each sample refers to its own pixel's footprint,
                            // the unit one always by index 0.
                            let pixels: Vec<usize> = (0..n)
                                .filter(|&i| kept(&coords, &mask, &colour, &conf, i).is_some())
                                .collect();
                            assert_eq!(pixels.len(), a.list.len());
                            for (s, &i) in a.list.iter().zip(&pixels) {
                                let (_, fp) =
                                    splat_sample(&coords, &mask, &conf, size, i, colour.rgb(i));
                                assert_eq!(a.fp(s), &fp);
                                assert_eq!(s.fp == 0, fp.is_unit());
                            }
                        }
                    }
                }
            }
        }
    }

    /// Smooth coordinates at `side` texels per pixel (of a `size` texture)
    /// with a jump of 0.37 from column `w / 2 + 1` on (inside a block) and
    /// wrapped, and the colours of a fine texture `tex` there.
    fn dense_view(
        w: usize,
        h: usize,
        size: usize,
        side: f32,
    ) -> (Coords, Image, impl Fn(f32, f32) -> Vec3) {
        let t = std::f32::consts::TAU;
        let tex = move |u: f32, v: f32| {
            Vec3::new(
                0.5 + 0.3 * (t * 5.0 * u).sin() * (t * 3.0 * v).cos(),
                0.4 + 0.2 * (t * 7.0 * (u + v)).cos(),
                0.3 + 0.25 * (t * 4.0 * v).sin(),
            )
        };
        let step = side / size as f32;
        let (mut u, mut v) = (vec![0.0; w * h], vec![0.0; w * h]);
        let mut img = Image::zeros(3, h, w);
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                let jump = if x > w / 2 { 0.37 } else { 0.0 };
                u[i] = ((x as f32 + 0.5) * step + 0.02 * y as f32 * step + jump).rem_euclid(1.0);
                v[i] = ((y as f32 + 0.5) * step * 0.9).rem_euclid(1.0);
                img.set_rgb(i, tex(u[i], v[i]));
            }
        }
        let coords = Coords {
            width: w,
            height: h,
            u,
            v,
            wrap: true,
        };
        (coords, img, tex)
    }

    #[test]
    fn merged_blocks_give_the_same_texture() {
        // Pixels of 0.3 texel (a photo denser than its capped texture):
        // 2×2 blocks are merged, not across the coordinate jump, and the
        // texture is the same as from every pixel (within 40 dB of each other,
        // and as close to the truth) from about a quarter of the samples.
        let (w, h, size) = (360usize, 300usize, 64usize);
        let (coords, img, tex) = dense_view(w, h, size, 0.3);
        let mut mask = vec![true; w * h];
        for i in (0..w * h).step_by(7) {
            mask[i] = false;
        }
        let conf: Vec<f32> = (0..w * h)
            .map(|i| if i % 11 == 0 { 0.25 } else { 1.0 })
            .collect();
        let f = merge_block(&coords, &mask, size);
        assert_eq!(f, 2);
        let src = Picked {
            coords: &coords,
            mask: &mask,
            colour: &img,
            confidence: &conf,
            size,
        };
        let all = samples(&src, 1).list;
        let merged = samples(&src, f).list;
        assert!(
            merged.len() * 3 < all.len(),
            "{} of {}",
            merged.len(),
            all.len()
        );
        // Each jumping block (its columns straddle w/2 + 1) stays unmerged.
        assert!(merged.iter().filter(|s| s.count == 1.0).count() >= h);
        let count: f32 = merged.iter().map(|s| s.count).sum();
        assert_eq!(count as usize, all.len());
        let a = reproject_rounds(
            &coords,
            &mask,
            &img,
            &conf,
            size,
            Splatting {
                rounds: BACK_PROJECTIONS,
                block: 1,
                shift: None,
            },
        );
        let b = reproject(&coords, &mask, &img, &conf, size);
        assert_eq!(a.known, b.known);
        let (mut d, mut ea, mut eb, mut k) = (0.0f64, 0.0f64, 0.0f64, 0usize);
        for t in (0..size * size).filter(|&t| a.known[t]) {
            let truth = tex(
                ((t % size) as f32 + 0.5) / size as f32,
                ((t / size) as f32 + 0.5) / size as f32,
            );
            let (x, y) = (a.texture.rgb(t), b.texture.rgb(t));
            d += f64::from((x - y).length_squared());
            ea += f64::from((x - truth).length_squared());
            eb += f64::from((y - truth).length_squared());
            k += 1;
        }
        assert!(k > size * size / 2, "{k}");
        let psnr = |e: f64| 10.0 * (3.0 * k as f64 / e).log10();
        assert!(psnr(d) > 40.0, "merged vs every pixel: {:.1} dB", psnr(d));
        assert!(
            psnr(eb) > psnr(ea) - 0.5,
            "truth: merged {:.1} dB, every pixel {:.1} dB",
            psnr(eb),
            psnr(ea)
        );
        // The observation weights count every pixel.
        let max = |r: &Reprojected| r.weight.data.iter().copied().fold(0.0f32, f32::max);
        assert!(
            (max(&a) - max(&b)).abs() < 0.1 * max(&a),
            "{} {}",
            max(&a),
            max(&b)
        );
    }

    #[test]
    fn area_quantile_matches_sorting() {
        let mut rng = picker_tensor::Rng::new(15);
        for &(w, h) in &[(0usize, 0usize), (1, 1), (2, 2), (7, 3), (31, 29)] {
            for wrap in [true, false] {
                let n = w * h;
                let coords = random_coords(&mut rng, w, h, wrap, 9);
                let mask: Vec<bool> = (0..n).map(|_| rng.f64() < 0.8).collect();
                for step in [1, 2, 4] {
                    let mut a: Vec<f32> = (0..n)
                        .filter(|i| (i / w.max(1)) % step == 0)
                        .filter_map(|i| coords.pixel_area(&mask, i))
                        .filter(|&a| a > 0.0)
                        .collect();
                    for q in [0.0, 0.3, 0.5, 1.0] {
                        let want = (!a.is_empty()).then(|| {
                            let k = ((a.len() - 1) as f32 * q).round() as usize;
                            *a.select_nth_unstable_by(k, |x, y| x.total_cmp(y)).1
                        });
                        let got = coords.area_quantile_rows(&mask, q, step);
                        assert_eq!(got, want, "{w}x{h} wrap {wrap} step {step} q {q}");
                        if step == 1 {
                            assert_eq!(coords.area_quantile(&mask, q), want);
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn incoherent_blocks_split_into_coherent_quadrants() {
        // An 8×8 image, texture 64: each 4×4 quadrant's pixels are 0.1
        // texel apart (coherent at every level), but the quadrants sit 10
        // texels apart, so the 8×8 block splits into four merged 4×4 ones.
        let (w, h, size) = (8usize, 8usize, 64usize);
        let at = |x: usize, y: usize| {
            let (qx, qy) = (x / 4, y / 4);
            (
                (10.0 * qx as f32 + 0.1 * (x % 4) as f32 + 5.0) / size as f32,
                (10.0 * qy as f32 + 0.1 * (y % 4) as f32 + 5.0) / size as f32,
            )
        };
        let coords = Coords {
            width: w,
            height: h,
            u: (0..w * h).map(|i| at(i % w, i / w).0).collect(),
            v: (0..w * h).map(|i| at(i % w, i / w).1).collect(),
            wrap: false,
        };
        let img = Image::zeros(3, h, w);
        let mask = vec![true; w * h];
        let conf = vec![1.0f32; w * h];
        let src = Picked {
            coords: &coords,
            mask: &mask,
            colour: &img,
            confidence: &conf,
            size,
        };
        let s = samples(&src, 8).list;
        assert_eq!(s.len(), 4, "{s:?}");
        // In quadrant order: top-left, top-right, bottom-left, bottom-right.
        let centres: Vec<(f32, f32)> = s.iter().map(|s| (s.u * 64.0, s.v * 64.0)).collect();
        for (c, want) in
            centres
                .iter()
                .zip([(5.15, 5.15), (15.15, 5.15), (5.15, 15.15), (15.15, 15.15)])
        {
            assert!(
                (c.0 - want.0).abs() < 1e-3 && (c.1 - want.1).abs() < 1e-3,
                "{centres:?}"
            );
        }
        assert!(s.iter().all(|s| s.count == 16.0));
        assert_eq!(samples_reference(&src, 8).list.len(), 4);
        // A quadrant whose pixels are themselves spread (one pixel moved
        // 5 texels) splits again: its other three 2×2 blocks merge, the
        // moved pixel's 2×2 block gives one sample per pixel.
        let mut u = coords.u.clone();
        u[0] += 5.0 / size as f32;
        let spread = Coords {
            u,
            ..coords.clone()
        };
        let src = Picked {
            coords: &spread,
            ..src
        };
        let s = samples(&src, 8).list;
        assert_eq!(s.len(), 3 + 3 + 4, "{s:?}");
        let count: f32 = s.iter().map(|s| s.count).sum();
        assert_eq!(count, 64.0);
        assert_eq!(s.len(), samples_reference(&src, 8).list.len());
    }

    #[test]
    fn merge_block_follows_the_density() {
        for (side, want) in [
            (1.0f32, 1usize),
            (0.6, 1),
            (0.5, 2),
            (0.3, 2),
            (0.2, 4),
            (0.05, 8),
        ] {
            let (coords, _, _) = dense_view(64, 48, 64, side);
            let mask = vec![true; 64 * 48];
            // The median pixel is `side` × 0.9·`side` texels.
            assert_eq!(merge_block(&coords, &mask, 64), want, "side {side}");
        }
        let empty = vec![false; 64 * 48];
        let (coords, _, _) = dense_view(64, 48, 64, 0.1);
        assert_eq!(merge_block(&coords, &empty, 64), 1);
    }

    #[test]
    fn integer_floor_and_ceil() {
        let mut rng = picker_tensor::Rng::new(14);
        let mut values = rng.uniform_vec(20_000, -3000.0, 3000.0);
        values.extend(rng.uniform_vec(2000, -2.0, 2.0));
        for k in -50..50 {
            let x = k as f32 * 0.5;
            values.extend([x, x.next_up(), x.next_down()]);
        }
        values.extend([
            0.0,
            -0.0,
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::MAX,
            f32::MIN,
            1e20,
            -1e20,
            8388608.5,
            -8388607.5,
            8388607.5,
            -8388608.0,
            8388608.0,
            4194303.5,
            -4194304.5,
            0.49999997,
            -0.49999997,
            f32::MIN_POSITIVE / 2.0,
            f32::MIN_POSITIVE,
        ]);
        for x in values {
            assert_eq!(floor_i64(x), x.floor() as i64, "floor {x}");
            assert_eq!(floor_f32(x).to_bits(), x.floor().to_bits(), "floor {x}");
            assert_eq!(round_f32(x).to_bits(), x.round().to_bits(), "round {x}");
        }
        // Every 61st bit pattern (both signs, every exponent): the same
        // values, and NaN for NaN (whose payload the library may quieten).
        let same = |a: f32, b: f32| a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan());
        for bits in (0..=u32::MAX).step_by(61) {
            let x = f32::from_bits(bits);
            assert!(same(floor_f32(x), x.floor()), "floor {x} ({bits:#x})");
            assert!(same(round_f32(x), x.round()), "round {x} ({bits:#x})");
            assert_eq!(ceil_i64(x), x.ceil() as i64, "ceil {x}");
        }
        for n in [1i64, 2, 7, 1024] {
            for v in -5 * n..5 * n {
                assert_eq!(wrap_i64(v, n), v.rem_euclid(n), "{v} mod {n}");
            }
        }
    }

    #[test]
    fn texture_size_bounds() {
        assert_eq!(texture_size(None, 1024), 256);
        assert_eq!(texture_size(Some(1e-9), 1024), 1024);
        assert_eq!(texture_size(Some(0.5), 1024), 16);
        assert_eq!(texture_size(Some(1e-4), 8), 16);
    }

    #[test]
    fn footprint_tells_collapsed_from_spread_coordinates() {
        let (w, h) = (40, 30);
        let mask = vec![true; w * h];
        let make = |f: &dyn Fn(usize, usize) -> (f32, f32)| {
            let (mut u, mut v) = (vec![0.0; w * h], vec![0.0; w * h]);
            for y in 0..h {
                for x in 0..w {
                    (u[y * w + x], v[y * w + x]) = f(x, y);
                }
            }
            Coords {
                width: w,
                height: h,
                u,
                v,
                wrap: true,
            }
        };
        // One repeat over the picture: the 8×8 grid is covered.
        let spread = make(&|x, y| (x as f32 / w as f32, y as f32 / h as f32));
        assert_eq!(spread.footprint(&mask, 8), Some(1.0));
        // Constant coordinates: one cell; a line: one row of cells.
        let point = make(&|_, _| (0.3, 0.7));
        assert_eq!(point.footprint(&mask, 8), Some(1.0 / 64.0));
        let line = make(&|x, _| (x as f32 / w as f32, 0.5));
        assert_eq!(line.footprint(&mask, 8), Some(8.0 / 64.0));
        // Wrapping: u = 1.25 is cell 2 of 8; without wrapping it is outside.
        let mut out = make(&|_, _| (1.25, 0.5));
        assert_eq!(out.footprint(&mask, 8), Some(1.0 / 64.0));
        out.wrap = false;
        assert_eq!(out.footprint(&mask, 8), Some(0.0));
        // Only masked pixels count; an empty mask or grid has no footprint.
        let mut one = vec![false; w * h];
        one[5] = true;
        assert_eq!(spread.footprint(&one, 8), Some(1.0 / 64.0));
        assert_eq!(spread.footprint(&vec![false; w * h], 8), None);
        assert_eq!(spread.footprint(&mask, 0), None);
    }
}
