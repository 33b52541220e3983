//! Multi-scale exemplar-based completion: Wexler, Shechtman & Irani 2007,
//! "Space-time completion of video" (global coherence energy, eq. 1, solved by
//! alternating nearest-neighbour search and patch voting, eq. 3, coarse to
//! fine), with the nearest-neighbour field (NNF) found by PatchMatch (Barnes,
//! Shechtman, Finkelstein & Goldman 2009: random initialisation, propagation,
//! random search).
//!
//! Per pyramid level:
//! 1. *Targets* are the positions whose `p × p` patch overlaps an unknown texel;
//!    *sources* are positions whose patch is fully known (or, when too few
//!    exist, has the fewest unknown texels) and, unless toroidal, lies inside
//!    the image.
//! 2. PatchMatch improves `NNF(target) → source` under the SSD patch distance
//!    against the current estimate.
//! 3. Voting: every unknown texel `q` becomes the weighted mean over the target
//!    patches `P ∋ q` of the texel of `NNF(P)` at the same offset, with weight
//!    `exp(−d(P)/2σ²)` (`d` the mean squared patch difference, `σ²` its 75th
//!    percentile over the level, as in Wexler et al.). Source texels that are
//!    observed are preferred: estimated ones only vote where no observed one does.
//!
//! The pyramid halves the resolution (a coarse texel is the mean of its known
//! children, known when at least half of them are) until the coarsest level
//! reaches [`PatchMatchInpainter::min_size`] or, with
//! [`PatchMatchInpainter::adaptive_levels`], until every hole texel is within
//! half a patch of a known texel.
//!
//! The coarsest level starts from the harmonic fill of
//! [`DiffusionInpainter`](crate::DiffusionInpainter); each finer level starts from the upsampled NNF of the
//! level below, voted once. Each level runs up to
//! [`PatchMatchInpainter::em_iterations`] (finest:
//! [`PatchMatchInpainter::em_iterations_finest`]) search-and-vote iterations;
//! the finest one stops early once its estimate settles
//! ([`PatchMatchInpainter::finest_mean_tolerance`]). In toroidal mode every coordinate wraps, so target
//! and source patches may straddle the edges and the result tiles seamlessly.
//!
//! Determinism: PatchMatch runs on fixed bands of rows in parallel, each band
//! with its own seeded random stream; propagation inside a band is sequential,
//! across bands it reads the previous pass (Jacobi style). Voting and
//! distances are per texel. So the output depends only on the seed and the
//! configuration, never on the number of threads.

use rayon::prelude::*;

use crate::diffusion::diffuse_planes;
use crate::{stream, validate, Image, InpaintOptions, Inpainter, Plan, Result};
use picker_tensor::Isa;

/// Multi-scale PatchMatch inpainting with patch voting (see the [module docs](self)).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PatchMatchInpainter {
    /// The shorter side of the coarsest pyramid level is at least this
    /// (and at least twice the patch size).
    pub min_size: usize,
    /// At most this many pyramid levels (1 = no pyramid).
    pub max_levels: usize,
    /// EM iterations (search + vote) per level, coarser levels.
    pub em_iterations: usize,
    /// EM iterations at the finest level (the most expensive one).
    pub em_iterations_finest: usize,
    /// PatchMatch passes (propagation + random search) per EM iteration.
    pub pm_iterations: usize,
    /// Rows per parallel PatchMatch band. Part of the result's definition
    /// (changing it changes the output); the thread count is not.
    pub band_rows: usize,
    /// Sources should be fully known patches; when fewer than this fraction
    /// of the candidate positions are, patches with a few unknown texels are
    /// admitted, fewest first.
    pub min_source_fraction: f32,
    /// An EM loop at a level stops early once no texel moves by more than this.
    pub tolerance: f32,
    /// The finest level's EM loop, when that level starts from a coarser
    /// one's solution, also stops once the unknown texels move by at most
    /// this on average (a quarter of an 8-bit step: the result has settled).
    /// Not at coarser levels, whose product is the field handed down, which
    /// keeps improving while the estimate barely moves.
    pub finest_mean_tolerance: f64,
    /// Stop coarsening once every unknown texel of a level is within half a
    /// patch of a known texel (coarser levels would only lose detail).
    pub adaptive_levels: bool,
}

impl Default for PatchMatchInpainter {
    fn default() -> Self {
        Self {
            min_size: 8,
            max_levels: 8,
            em_iterations: 4,
            em_iterations_finest: 2,
            pm_iterations: 2,
            band_rows: 16,
            min_source_fraction: 0.05,
            tolerance: 1e-3,
            finest_mean_tolerance: 1e-3,
            adaptive_levels: true,
        }
    }
}

impl Inpainter for PatchMatchInpainter {
    fn name(&self) -> &str {
        "patchmatch"
    }

    fn inpaint(&self, image: &Image, known: &[bool], opts: &InpaintOptions) -> Result<Image> {
        if let Plan::Done(img) = validate(image, known, opts)? {
            return Ok(img);
        }
        let (c, h, w) = (image.channels, image.height, image.width);
        let p = opts.patch_size;
        let mut out = image.clone();
        if h < p || w < p {
            // Smaller than a patch: nothing to match, the harmonic fill it is.
            diffuse_planes(&mut out.data, known, c, h, w, opts.toroidal, 60, 1e-5);
            return Ok(out);
        }
        // Interleaved copy (unknown texels zeroed: never read the input there).
        let n = h * w;
        let mut img = vec![0.0f32; n * c];
        for i in 0..n {
            if known[i] {
                for ch in 0..c {
                    img[i * c + ch] = image.data[ch * n + i];
                }
            }
        }
        let mut levels = vec![Level {
            h,
            w,
            known: known.to_vec(),
            img,
        }];
        let min_side = self.min_size.max(2 * p);
        while levels.len() < self.max_levels.max(1) {
            let f = levels.last().expect("one level");
            if f.h.min(f.w) / 2 < min_side {
                break;
            }
            if self.adaptive_levels && hole_radius(&f.known, f.h, f.w) <= p / 2 {
                // Patches from the border already reach every hole texel.
                break;
            }
            let co = f.downsample(c);
            let frac =
                |l: &Level| l.known.iter().filter(|&&k| k).count() as f64 / l.known.len() as f64;
            if frac(&co) == 0.0 || frac(&co) < 0.5 * frac(f) {
                break;
            }
            levels.push(co);
        }
        let top = levels.len() - 1;
        // Coarsest level: harmonic initialisation.
        {
            let lv = &mut levels[top];
            let ln = lv.h * lv.w;
            let mut planar = vec![0.0f32; ln * c];
            for i in 0..ln {
                for ch in 0..c {
                    planar[ch * ln + i] = lv.img[i * c + ch];
                }
            }
            diffuse_planes(
                &mut planar,
                &lv.known,
                c,
                lv.h,
                lv.w,
                opts.toroidal,
                60,
                1e-5,
            );
            for i in 0..ln {
                for ch in 0..c {
                    lv.img[i * c + ch] = planar[ch * ln + i];
                }
            }
        }
        let mut nnf: Option<Vec<u32>> = None;
        for l in (0..=top).rev() {
            if l < top {
                let (lower, upper) = levels.split_at_mut(l + 1);
                lower[l].upsample_unknown(&upper[0], c);
            }
            let em = if l == 0 {
                self.em_iterations_finest
            } else {
                self.em_iterations
            };
            let prev = nnf.take().and_then(|nnf| {
                levels.get(l + 1).map(|u| CoarseField {
                    nnf,
                    h: u.h,
                    w: u.w,
                })
            });
            nnf = Some(self.solve_level(&mut levels[l], c, l, em, prev, opts));
        }
        let lv = &levels[0];
        for (i, _) in known.iter().enumerate().filter(|(_, k)| !**k) {
            for ch in 0..c {
                out.data[ch * n + i] = lv.img[i * c + ch];
            }
        }
        Ok(out)
    }
}

/// The NNF of the next coarser level (`h × w` positions), to initialise a level.
struct CoarseField {
    nnf: Vec<u32>,
    h: usize,
    w: usize,
}

/// One pyramid level: interleaved values (`img[(row·w + col)·c + ch]`) and the
/// mask of texels that are fixed at this level.
struct Level {
    h: usize,
    w: usize,
    known: Vec<bool>,
    img: Vec<f32>,
}

impl Level {
    /// Half resolution: a coarse texel is the mean of its known children and
    /// is known when at least half of its children are.
    fn downsample(&self, c: usize) -> Level {
        let (h2, w2) = (self.h.div_ceil(2), self.w.div_ceil(2));
        let mut known = vec![false; h2 * w2];
        let mut img = vec![0.0f32; h2 * w2 * c];
        let mut acc = vec![0.0f32; c];
        for y in 0..h2 {
            for x in 0..w2 {
                acc.fill(0.0);
                let (mut k, mut total) = (0usize, 0usize);
                for fy in 2 * y..(2 * y + 2).min(self.h) {
                    for fx in 2 * x..(2 * x + 2).min(self.w) {
                        total += 1;
                        let i = fy * self.w + fx;
                        if self.known[i] {
                            k += 1;
                            for (a, v) in acc.iter_mut().zip(&self.img[i * c..(i + 1) * c]) {
                                *a += v;
                            }
                        }
                    }
                }
                let j = y * w2 + x;
                if k > 0 {
                    for ch in 0..c {
                        img[j * c + ch] = acc[ch] / k as f32;
                    }
                }
                known[j] = k > 0 && 2 * k >= total;
            }
        }
        Level {
            h: h2,
            w: w2,
            known,
            img,
        }
    }

    /// Unknown texels take the value of their parent in the coarser level.
    fn upsample_unknown(&mut self, coarse: &Level, c: usize) {
        for i in 0..self.h * self.w {
            if !self.known[i] {
                let j = ((i / self.w) / 2).min(coarse.h - 1) * coarse.w
                    + ((i % self.w) / 2).min(coarse.w - 1);
                self.img[i * c..(i + 1) * c].copy_from_slice(&coarse.img[j * c..(j + 1) * c]);
            }
        }
    }
}

/// Read-only facts about one level shared by the search and the vote.
struct Ctx<'a> {
    h: usize,
    w: usize,
    c: usize,
    p: usize,
    r: usize,
    toroidal: bool,
    /// Position is a target (its patch overlaps an unknown texel).
    target: &'a [bool],
    /// Position is an admissible source.
    valid: &'a [bool],
    /// Rows (and columns) where non-toroidal source centres may lie.
    src_rows: (usize, usize),
    src_cols: (usize, usize),
}

impl Ctx<'_> {
    /// The padded estimate: `(h+2r) × (w+2r)` texels, wrapped (toroidal) or
    /// clamped at the borders, so every patch is `p` contiguous row slices.
    fn pad(&self, img: &[f32]) -> Vec<f32> {
        let (h, w, c, r) = (self.h, self.w, self.c, self.r);
        let (ph, pw) = (h + 2 * r, w + 2 * r);
        let mut out = vec![0.0f32; ph * pw * c];
        let map = |v: isize, n: usize| -> usize {
            if self.toroidal {
                v.rem_euclid(n as isize) as usize
            } else {
                v.clamp(0, n as isize - 1) as usize
            }
        };
        // Rows in parallel, the interior of a row as one copy (pure copies:
        // the same values as `pad_reference`).
        let cols: Vec<usize> = (0..pw).map(|px| map(px as isize - r as isize, w)).collect();
        out.par_chunks_mut(pw * c)
            .enumerate()
            .for_each(|(py, row)| {
                let sy = map(py as isize - r as isize, h);
                let src = &img[sy * w * c..(sy + 1) * w * c];
                row[r * c..(r + w) * c].copy_from_slice(src);
                for px in (0..r).chain(r + w..pw) {
                    let s = cols[px] * c;
                    row[px * c..(px + 1) * c].copy_from_slice(&src[s..s + c]);
                }
            });
        out
    }

    /// The plain implementation of [`Ctx::pad`].
    #[cfg(test)]
    fn pad_reference(&self, img: &[f32]) -> Vec<f32> {
        let (h, w, c, r) = (self.h, self.w, self.c, self.r);
        let (ph, pw) = (h + 2 * r, w + 2 * r);
        let mut out = vec![0.0f32; ph * pw * c];
        let map = |v: isize, n: usize| -> usize {
            if self.toroidal {
                v.rem_euclid(n as isize) as usize
            } else {
                v.clamp(0, n as isize - 1) as usize
            }
        };
        for py in 0..ph {
            let sy = map(py as isize - r as isize, h);
            for px in 0..pw {
                let sx = map(px as isize - r as isize, w);
                let s = (sy * w + sx) * c;
                out[(py * pw + px) * c..(py * pw + px + 1) * c].copy_from_slice(&img[s..s + c]);
            }
        }
        out
    }

    /// SSD between the patches centred at positions `t` and `s` of the padded
    /// estimate; stops early (returning a value ≥ `bound`) once past `bound`.
    ///
    /// The padded offsets of the two patches go to [`Ctx::dist_at`].
    #[inline]
    fn dist(&self, pad: &[f32], t: usize, s: usize, bound: f32) -> f32 {
        let w = self.w;
        let (ty, tx) = (t / w, t % w);
        let (sy, sx) = (s / w, s % w);
        self.dist_at(pad, self.pad_offset(ty, tx), self.pad_offset(sy, sx), bound)
    }

    /// Offset in the padded estimate of the top-left texel of the patch
    /// centred at position `(y, x)`.
    #[inline]
    fn pad_offset(&self, y: usize, x: usize) -> usize {
        (y * (self.w + 2 * self.r) + x) * self.c
    }

    /// [`Ctx::dist`] for patches whose top-left texels are at padded offsets
    /// `a` and `b` ([`Ctx::pad_offset`]).
    ///
    /// Dispatches to a row-length specialised copy of `Ctx::dist_reference`
    /// (the tests' plain loop) for the usual patch × channel sizes (same operations in the same
    /// order, so the same bits; `tests::fast_distance_matches_reference`).
    #[inline(always)]
    fn dist_at(&self, pad: &[f32], a: usize, b: usize, bound: f32) -> f32 {
        let stride = (self.w + 2 * self.r) * self.c;
        match (self.p, self.c) {
            (7, 3) => dist_fixed::<7, 21>(pad, a, b, stride, bound),
            (7, 4) => dist_fixed::<7, 28>(pad, a, b, stride, bound),
            (7, 1) => dist_fixed::<7, 7>(pad, a, b, stride, bound),
            (7, 2) => dist_fixed::<7, 14>(pad, a, b, stride, bound),
            (5, 3) => dist_fixed::<5, 15>(pad, a, b, stride, bound),
            (3, 3) => dist_fixed::<3, 9>(pad, a, b, stride, bound),
            _ => {
                let row = self.p * self.c;
                let mut acc = 0.0f32;
                for dy in 0..self.p {
                    let (oa, ob) = (a + dy * stride, b + dy * stride);
                    acc += ssd(&pad[oa..oa + row], &pad[ob..ob + row]);
                    if acc >= bound {
                        return acc;
                    }
                }
                acc
            }
        }
    }

    /// The plain implementation of [`Ctx::dist`], for any patch and channel count.
    #[cfg(test)]
    fn dist_reference(&self, pad: &[f32], t: usize, s: usize, bound: f32) -> f32 {
        let pw = self.w + 2 * self.r;
        let row = self.p * self.c;
        let (ty, tx) = (t / self.w, t % self.w);
        let (sy, sx) = (s / self.w, s % self.w);
        let mut acc = 0.0f32;
        for dy in 0..self.p {
            let a = ((ty + dy) * pw + tx) * self.c;
            let b = ((sy + dy) * pw + sx) * self.c;
            acc += ssd(&pad[a..a + row], &pad[b..b + row]);
            if acc >= bound {
                return acc;
            }
        }
        acc
    }

    /// Row and column of position `(y + dy, x + dx)`, wrapped or `None`
    /// outside the image (the position of [`Ctx::offset`]).
    #[inline]
    fn offset_yx(&self, y: usize, x: usize, dy: isize, dx: isize) -> Option<(usize, usize)> {
        let (ny, nx) = (y as isize + dy, x as isize + dx);
        if self.toroidal {
            Some((wrap(ny, self.h), wrap(nx, self.w)))
        } else if ny < 0 || nx < 0 || ny >= self.h as isize || nx >= self.w as isize {
            None
        } else {
            Some((ny as usize, nx as usize))
        }
    }

    /// Position `(y + dy, x + dx)`, wrapped or `None` outside the image.
    #[inline]
    fn offset(&self, y: usize, x: usize, dy: isize, dx: isize) -> Option<usize> {
        let (ny, nx) = (y as isize + dy, x as isize + dx);
        if self.toroidal {
            Some(wrap(ny, self.h) * self.w + wrap(nx, self.w))
        } else if ny < 0 || nx < 0 || ny >= self.h as isize || nx >= self.w as isize {
            None
        } else {
            Some(ny as usize * self.w + nx as usize)
        }
    }
}

/// `v` modulo `n` in `0..n` (`rem_euclid` without a division for the
/// values PatchMatch meets: within one period of the image).
#[inline]
fn wrap(v: isize, n: usize) -> usize {
    let n = n as isize;
    if (0..n).contains(&v) {
        v as usize
    } else if (-n..0).contains(&v) {
        (v + n) as usize
    } else if (n..2 * n).contains(&v) {
        (v - n) as usize
    } else {
        v.rem_euclid(n) as usize
    }
}

/// [`Ctx::dist`] for `P` rows of `ROW = P·c` values, `stride` apart, starting
/// at `a` and `b`: the operations of [`ssd`] in the same order, with the
/// lengths known at compile time (no bounds checks inside a row).
#[inline(always)]
fn dist_fixed<const P: usize, const ROW: usize>(
    pad: &[f32],
    a: usize,
    b: usize,
    stride: usize,
    bound: f32,
) -> f32 {
    let mut acc = 0.0f32;
    for dy in 0..P {
        let (oa, ob) = (a + dy * stride, b + dy * stride);
        let ra: &[f32; ROW] = pad[oa..oa + ROW].try_into().expect("patch row");
        let rb: &[f32; ROW] = pad[ob..ob + ROW].try_into().expect("patch row");
        acc += ssd_fixed(ra, rb);
        if acc >= bound {
            return acc;
        }
    }
    acc
}

/// [`ssd`] for a length known at compile time (same order of operations).
#[inline(always)]
fn ssd_fixed<const N: usize>(a: &[f32; N], b: &[f32; N]) -> f32 {
    let mut lanes = [0.0f32; 8];
    let full = N / 8 * 8;
    let mut j = 0;
    while j < full {
        for k in 0..8 {
            let d = a[j + k] - b[j + k];
            lanes[k] += d * d;
        }
        j += 8;
    }
    let mut s = 0.0f32;
    for i in full..N {
        s += (a[i] - b[i]) * (a[i] - b[i]);
    }
    s + lanes.iter().sum::<f32>()
}

/// Sum of squared differences, in 8 independent lanes (vectorises, and the
/// summation order is fixed).
#[inline]
fn ssd(a: &[f32], b: &[f32]) -> f32 {
    let mut lanes = [0.0f32; 8];
    let (ca, cb) = (a.chunks_exact(8), b.chunks_exact(8));
    let (ra, rb) = (ca.remainder(), cb.remainder());
    for (x, y) in ca.zip(cb) {
        for k in 0..8 {
            let d = x[k] - y[k];
            lanes[k] += d * d;
        }
    }
    let mut s = 0.0f32;
    for (x, y) in ra.iter().zip(rb) {
        s += (x - y) * (x - y);
    }
    s + lanes.iter().sum::<f32>()
}

/// The identity field over `n` positions.
fn nnf_identity(n: usize) -> Vec<u32> {
    (0..n as u32).collect()
}

/// The largest chessboard distance from an unknown texel to the nearest known
/// one (two-pass chamfer transform, not wrapping).
fn hole_radius(known: &[bool], h: usize, w: usize) -> usize {
    let big = (h + w) as u32;
    let mut d: Vec<u32> = known.iter().map(|&k| if k { 0 } else { big }).collect();
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let mut v = d[i];
            if x > 0 {
                v = v.min(d[i - 1] + 1);
            }
            if y > 0 {
                v = v.min(d[i - w] + 1);
                if x > 0 {
                    v = v.min(d[i - w - 1] + 1);
                }
                if x + 1 < w {
                    v = v.min(d[i - w + 1] + 1);
                }
            }
            d[i] = v;
        }
    }
    for y in (0..h).rev() {
        for x in (0..w).rev() {
            let i = y * w + x;
            let mut v = d[i];
            if x + 1 < w {
                v = v.min(d[i + 1] + 1);
            }
            if y + 1 < h {
                v = v.min(d[i + w] + 1);
                if x + 1 < w {
                    v = v.min(d[i + w + 1] + 1);
                }
                if x > 0 {
                    v = v.min(d[i + w - 1] + 1);
                }
            }
            d[i] = v;
        }
    }
    d.into_iter().max().unwrap_or(0) as usize
}

/// Number of unknown texels in the patch centred at every position.
fn unknown_counts(known: &[bool], h: usize, w: usize, r: usize, toroidal: bool) -> Vec<u32> {
    let map = |v: isize, n: usize| -> Option<usize> {
        if toroidal {
            Some(v.rem_euclid(n as isize) as usize)
        } else if v < 0 || v >= n as isize {
            None
        } else {
            Some(v as usize)
        }
    };
    // Horizontal window sums, then vertical ones (out-of-image texels count
    // as known: they are never voted and non-toroidal sources lie inside).
    // Integer sums, rows in parallel: exact whatever the order.
    let mut horiz = vec![0u32; h * w];
    horiz.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        for (x, o) in row.iter_mut().enumerate() {
            let mut s = 0;
            for dx in -(r as isize)..=r as isize {
                if let Some(xx) = map(x as isize + dx, w) {
                    s += (!known[y * w + xx]) as u32;
                }
            }
            *o = s;
        }
    });
    let mut out = vec![0u32; h * w];
    out.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        for dy in -(r as isize)..=r as isize {
            if let Some(yy) = map(y as isize + dy, h) {
                for (o, &v) in row.iter_mut().zip(&horiz[yy * w..(yy + 1) * w]) {
                    *o += v;
                }
            }
        }
    });
    out
}

impl PatchMatchInpainter {
    /// Runs the EM loop at one level; returns its NNF (every position, the
    /// identity at non-targets).
    fn solve_level(
        &self,
        lv: &mut Level,
        c: usize,
        level: usize,
        em_iterations: usize,
        prev: Option<CoarseField>,
        opts: &InpaintOptions,
    ) -> Vec<u32> {
        let (h, w) = (lv.h, lv.w);
        let n = h * w;
        let p = opts.patch_size;
        let r = p / 2;
        let counts = unknown_counts(&lv.known, h, w, r, opts.toroidal);
        let target: Vec<bool> = counts.iter().map(|&k| k > 0).collect();
        let (src_rows, src_cols) = if opts.toroidal {
            ((0, h - 1), (0, w - 1))
        } else {
            ((r, h - 1 - r), (r, w - 1 - r))
        };
        let eligible = |i: usize| {
            let (y, x) = (i / w, i % w);
            (src_rows.0..=src_rows.1).contains(&y) && (src_cols.0..=src_cols.1).contains(&x)
        };
        // Admit the fewest-unknown patches until there are enough sources.
        let mut hist = vec![0usize; p * p + 1];
        let mut n_eligible = 0usize;
        for i in (0..n).filter(|&i| eligible(i)) {
            hist[counts[i] as usize] += 1;
            n_eligible += 1;
        }
        let want =
            ((n_eligible as f32 * self.min_source_fraction) as usize).clamp(1, n_eligible.max(1));
        let (mut limit, mut have) = (0usize, hist[0]);
        while have < want && limit < p * p {
            limit += 1;
            have += hist[limit];
        }
        if limit >= p * p && prev.is_none() && level == 0 {
            // Too sparse for exemplars: fewer than `min_source_fraction` of
            // the patches hold a single observed texel, so every source would
            // be harmonic estimate matched against harmonic estimate. The
            // harmonic fill is the answer (PatchMatch gave the same hole PSNR
            // and colour statistics: the `density_sweep` test), at a fraction
            // of the cost.
            return nnf_identity(n);
        }
        let valid: Vec<bool> = (0..n)
            .map(|i| eligible(i) && counts[i] as usize <= limit)
            .collect();
        let sources: Vec<u32> = (0..n as u32).filter(|&i| valid[i as usize]).collect();
        let mut nnf: Vec<u32> = (0..n as u32).collect();
        if !target.iter().any(|&t| t) || sources.is_empty() {
            return nnf;
        }
        let ctx = Ctx {
            h,
            w,
            c,
            p,
            r,
            toroidal: opts.toroidal,
            target: &target,
            valid: &valid,
            src_rows,
            src_cols,
        };
        // Initial field: the upsampled coarse one where admissible, else random.
        let upsampled = prev.is_some();
        let init_rng_key = [level as u64, u64::MAX];
        nnf.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
            let mut rng = stream(opts.seed, &[init_rng_key[0], init_rng_key[1], y as u64]);
            for (x, slot) in row.iter_mut().enumerate() {
                let i = y * w + x;
                if !target[i] {
                    continue;
                }
                let mut cand = None;
                if let Some(CoarseField {
                    nnf: coarse,
                    h: ch,
                    w: cw,
                }) = prev.as_ref()
                {
                    let j = (y / 2).min(ch - 1) * cw + (x / 2).min(cw - 1);
                    let s = coarse[j] as usize;
                    let (sy, sx) = (2 * (s / cw) + y % 2, 2 * (s % cw) + x % 2);
                    let s = if opts.toroidal {
                        (sy % h) * w + sx % w
                    } else {
                        sy.min(h - 1) * w + sx.min(w - 1)
                    };
                    if valid[s] && s != i {
                        cand = Some(s as u32);
                    }
                }
                *slot = match cand {
                    Some(s) => s,
                    None => loop {
                        let s = sources[rng.range(0, sources.len() - 1)];
                        if s as usize != i || sources.len() == 1 {
                            break s;
                        }
                    },
                };
            }
        });
        let mut pad = ctx.pad(&lv.img);
        let mut dist = vec![0.0f32; n];
        compute_distances(&ctx, &pad, &nnf, &mut dist);
        if upsampled {
            lv.img = vote(&ctx, &lv.img, &lv.known, &nnf, &dist).0;
            pad = ctx.pad(&lv.img);
            compute_distances(&ctx, &pad, &nnf, &mut dist);
        }
        let mut pass = 0u64;
        for em in 0..em_iterations {
            for _ in 0..self.pm_iterations {
                self.pm_pass(
                    Isa::best(),
                    &ctx,
                    &pad,
                    &mut nnf,
                    &mut dist,
                    stream(opts.seed, &[level as u64, em as u64, pass]).next_u64(),
                    pass % 2 == 1,
                );
                pass += 1;
            }
            let (img, change) = vote(&ctx, &lv.img, &lv.known, &nnf, &dist);
            lv.img = img;
            // At the finest level the estimate is the result (no field goes
            // further down): started from a coarser solution, it has settled
            // once an iteration moves it by at most `finest_mean_tolerance`
            // on average.
            let settled = level == 0 && upsampled && change.mean <= self.finest_mean_tolerance;
            if change.max <= self.tolerance || settled || em + 1 == em_iterations {
                // Only the field leaves the level: the padded estimate and
                // the distances of the next iteration are not needed.
                break;
            }
            pad = ctx.pad(&lv.img);
            compute_distances(&ctx, &pad, &nnf, &mut dist);
        }
        nnf
    }

    /// One PatchMatch pass (propagation + random search) over every target.
    ///
    /// The operations of `pm_pass_reference` in the same order (the same
    /// candidates, random draws and distances, so the same field), with the
    /// rows and columns of the best match and of each candidate carried along
    /// instead of divided out of their positions at every use. `isa` picks
    /// the compiled copy of the band loop (every family gives the same bits).
    #[allow(clippy::too_many_arguments)]
    fn pm_pass(
        &self,
        isa: Isa,
        ctx: &Ctx,
        pad: &[f32],
        nnf: &mut [u32],
        dist: &mut [f32],
        key: u64,
        reverse: bool,
    ) {
        let (h, w) = (ctx.h, ctx.w);
        let snapshot = nnf.to_vec();
        let band = self.band_rows.max(1) * w;
        let max_radius = h.max(w) as isize;
        let stride = (w + 2 * ctx.r) * ctx.c;
        let (prefetch_rows, row_len) = (PREFETCH_ROWS.min(ctx.p), ctx.p * ctx.c);
        let args = PassArgs {
            ctx,
            pad,
            snapshot: &snapshot,
            band,
            max_radius,
            stride,
            prefetch_rows,
            row_len,
            key,
            reverse,
        };
        nnf.par_chunks_mut(band)
            .zip(dist.par_chunks_mut(band))
            .enumerate()
            .for_each(|(b, (nb, db))| band_pass_isa(isa, &args, b, nb, db));
    }

    /// The plain implementation of [`PatchMatchInpainter::pm_pass`] (a
    /// division per coordinate, the distance from positions), kept to test
    /// the fast one against.
    #[cfg(test)]
    fn pm_pass_reference(
        &self,
        ctx: &Ctx,
        pad: &[f32],
        nnf: &mut [u32],
        dist: &mut [f32],
        key: u64,
        reverse: bool,
    ) {
        let (h, w) = (ctx.h, ctx.w);
        let snapshot = nnf.to_vec();
        let band = self.band_rows.max(1) * w;
        let max_radius = h.max(w) as isize;
        nnf.par_chunks_mut(band)
            .zip(dist.par_chunks_mut(band))
            .enumerate()
            .for_each(|(b, (nb, db))| {
                let base = b * band;
                let rows = nb.len() / w;
                let mut rng = stream(key, &[b as u64]);
                let step: isize = if reverse { 1 } else { -1 };
                for yy in 0..rows {
                    let y = if reverse { rows - 1 - yy } else { yy } + base / w;
                    for xx in 0..w {
                        let x = if reverse { w - 1 - xx } else { xx };
                        let i = y * w + x;
                        if !ctx.target[i] {
                            continue;
                        }
                        let li = i - base;
                        let (mut best, mut bd) = (nb[li] as usize, db[li]);
                        let try_cand = |s: usize, best: &mut usize, bd: &mut f32| {
                            if s != i && s != *best && ctx.valid[s] {
                                let d = ctx.dist(pad, i, s, *bd);
                                if d < *bd {
                                    *best = s;
                                    *bd = d;
                                }
                            }
                        };
                        // Propagation from the neighbours already visited.
                        for (dy, dx) in [(0, step), (step, 0)] {
                            let Some(j) = ctx.offset(y, x, dy, dx) else {
                                continue;
                            };
                            let s = if (base..base + nb.len()).contains(&j) {
                                nb[j - base]
                            } else {
                                snapshot[j]
                            } as usize;
                            if let Some(cand) = ctx.offset(s / w, s % w, -dy, -dx) {
                                try_cand(cand, &mut best, &mut bd);
                            }
                        }
                        // Random search in shrinking windows around the best.
                        let mut radius = max_radius;
                        while radius >= 1 {
                            let (by, bx) = ((best / w) as isize, (best % w) as isize);
                            let sy = by + rng.range(0, 2 * radius as usize) as isize - radius;
                            let sx = bx + rng.range(0, 2 * radius as usize) as isize - radius;
                            let s = if ctx.toroidal {
                                wrap(sy, h) * w + wrap(sx, w)
                            } else {
                                let sy = sy.clamp(ctx.src_rows.0 as isize, ctx.src_rows.1 as isize);
                                let sx = sx.clamp(ctx.src_cols.0 as isize, ctx.src_cols.1 as isize);
                                sy as usize * w + sx as usize
                            };
                            try_cand(s, &mut best, &mut bd);
                            radius /= 2;
                        }
                        nb[li] = best as u32;
                        db[li] = bd;
                    }
                }
            });
    }
}

/// Patch rows of each random-search candidate that [`PatchMatchInpainter::pm_pass`]
/// prefetches (the early exit rarely reads further for a poor candidate).
/// What one PatchMatch pass shares between its bands.
struct PassArgs<'a> {
    ctx: &'a Ctx<'a>,
    pad: &'a [f32],
    snapshot: &'a [u32],
    band: usize,
    max_radius: isize,
    stride: usize,
    prefetch_rows: usize,
    row_len: usize,
    key: u64,
    reverse: bool,
}

picker_tensor::per_isa! {
    /// [`band_pass`] compiled for the CPU's instruction-set family
    /// (AVX-512, AVX2 + FMA, or the portable baseline): the same operations
    /// in the same order, so the same bits on every family (Rust never
    /// contracts `a * b + c` into an FMA); wider registers for the patch
    /// distances' lanes.
    fn band_pass_isa<'a>(args: &PassArgs<'a>, b: usize, nb: &mut [u32], db: &mut [f32]) => band_pass
}

/// One band (`b`, its matches `nb` and distances `db`) of
/// [`PatchMatchInpainter::pm_pass`].
#[inline(always)]
fn band_pass(args: &PassArgs<'_>, b: usize, nb: &mut [u32], db: &mut [f32]) {
    let PassArgs {
        ctx,
        pad,
        snapshot,
        band,
        max_radius,
        stride,
        prefetch_rows,
        row_len,
        key,
        reverse,
    } = *args;
    let w = ctx.w;
    let base = b * band;
    let rows = nb.len() / w;
    let mut rng = stream(key, &[b as u64]);
    let step: isize = if reverse { 1 } else { -1 };
    for yy in 0..rows {
        let y = if reverse { rows - 1 - yy } else { yy } + base / w;
        for xx in 0..w {
            let x = if reverse { w - 1 - xx } else { xx };
            let i = y * w + x;
            if !ctx.target[i] {
                continue;
            }
            let li = i - base;
            let a = ctx.pad_offset(y, x);
            let mut best = Match {
                s: nb[li] as usize,
                y: nb[li] as usize / w,
                x: nb[li] as usize % w,
                d: db[li],
            };
            // Propagation from the neighbours already visited.
            for (dy, dx) in [(0, step), (step, 0)] {
                let Some(j) = ctx.offset(y, x, dy, dx) else {
                    continue;
                };
                let s = if (base..base + nb.len()).contains(&j) {
                    nb[j - base]
                } else {
                    snapshot[j]
                } as usize;
                if let Some((cy, cx)) = ctx.offset_yx(s / w, s % w, -dy, -dx) {
                    try_candidate(ctx, pad, i, a, cy, cx, &mut best);
                }
            }
            // Random search in shrinking windows around the best.
            // The draws do not depend on the best match, so they
            // are made first (in the same order) and the
            // candidates around the current best are prefetched;
            // a candidate is then placed around the best at its
            // turn, as before.
            let mut offsets = [(0isize, 0isize); 64];
            let mut k = 0;
            let mut radius = max_radius;
            while radius >= 1 {
                let oy = rng.range(0, 2 * radius as usize) as isize - radius;
                let ox = rng.range(0, 2 * radius as usize) as isize - radius;
                offsets[k] = (oy, ox);
                k += 1;
                radius /= 2;
            }
            for &o in &offsets[..k] {
                let (sy, sx) = place(ctx, best.y, best.x, o);
                prefetch(ctx.valid, sy * w + sx);
                let b = ctx.pad_offset(sy, sx);
                for r in 0..prefetch_rows {
                    prefetch(pad, b + r * stride);
                    prefetch(pad, b + r * stride + row_len - 1);
                }
            }
            for &o in &offsets[..k] {
                let (sy, sx) = place(ctx, best.y, best.x, o);
                try_candidate(ctx, pad, i, a, sy, sx, &mut best);
            }
            nb[li] = best.s as u32;
            db[li] = best.d;
        }
    }
}

/// Tries source `(sy, sx)` for target `i` (patch at `a` in `pad`): keeps it
/// in `best` when it is a valid, different source with a smaller distance.
#[inline(always)]
fn try_candidate(
    ctx: &Ctx<'_>,
    pad: &[f32],
    i: usize,
    a: usize,
    sy: usize,
    sx: usize,
    best: &mut Match,
) {
    let s = sy * ctx.w + sx;
    if s != i && s != best.s && ctx.valid[s] {
        let d = ctx.dist_at(pad, a, ctx.pad_offset(sy, sx), best.d);
        if d < best.d {
            *best = Match { s, y: sy, x: sx, d };
        }
    }
}

/// The random-search candidate at offset `(oy, ox)` from `(by, bx)`:
/// wrapped on a torus, else clamped to the source rows and columns.
#[inline(always)]
fn place(ctx: &Ctx<'_>, by: usize, bx: usize, (oy, ox): (isize, isize)) -> (usize, usize) {
    let (sy, sx) = (by as isize + oy, bx as isize + ox);
    if ctx.toroidal {
        (wrap(sy, ctx.h), wrap(sx, ctx.w))
    } else {
        (
            sy.clamp(ctx.src_rows.0 as isize, ctx.src_rows.1 as isize) as usize,
            sx.clamp(ctx.src_cols.0 as isize, ctx.src_cols.1 as isize) as usize,
        )
    }
}

const PREFETCH_ROWS: usize = 3;

/// Asks the processor to bring `v[i]`'s cache line in (a hint: never faults).
#[inline(always)]
fn prefetch<T>(v: &[T], i: usize) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: a prefetch never faults, whatever the address.
    unsafe {
        use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
        _mm_prefetch::<_MM_HINT_T0>(v.as_ptr().wrapping_add(i) as *const i8);
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (v, i);
}

/// The current match of a target in [`PatchMatchInpainter::pm_pass`]: the
/// source position, its row and column, and the patch distance.
struct Match {
    s: usize,
    y: usize,
    x: usize,
    d: f32,
}

/// Full patch distances of every target to its NNF entry.
fn compute_distances(ctx: &Ctx, pad: &[f32], nnf: &[u32], dist: &mut [f32]) {
    let w = ctx.w;
    dist.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        for (x, d) in row.iter_mut().enumerate() {
            let i = y * w + x;
            *d = if ctx.target[i] {
                ctx.dist(pad, i, nnf[i] as usize, f32::INFINITY)
            } else {
                0.0
            };
        }
    });
}

/// How much a vote moved the unknown texels.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Change {
    /// The largest absolute change of a channel.
    max: f32,
    /// The mean absolute change over the unknown texels' channels.
    mean: f64,
}

impl Change {
    /// From each row's (largest, summed) absolute change, summed in row order
    /// (the same value whatever the threads).
    fn of_rows(rows: &[(f32, f64)], known: &[bool], c: usize) -> Change {
        let unknown = known.iter().filter(|&&k| !k).count() * c;
        let (max, sum) = rows
            .iter()
            .fold((0.0f32, 0.0f64), |(m, s), &(rm, rs)| (m.max(rm), s + rs));
        Change {
            max,
            mean: if unknown > 0 {
                sum / unknown as f64
            } else {
                0.0
            },
        }
    }
}

/// Patch voting: every unknown texel becomes the weighted mean of the texels
/// that the overlapping target patches' nearest neighbours put there.
/// Returns the new estimate and how much it moved.
///
/// Same sums in the same order as `vote_reference`, with the wrapped (or
/// clipped) coordinates looked up in tables instead of computed per texel.
fn vote(ctx: &Ctx, img: &[f32], known: &[bool], nnf: &[u32], dist: &[f32]) -> (Vec<f32>, Change) {
    let (h, w, c, r) = (ctx.h, ctx.w, ctx.c, ctx.r as isize);
    // σ² = 75th percentile of the mean squared patch differences.
    let norm = 1.0 / (ctx.p * ctx.p * c) as f32;
    let mut ds: Vec<f32> = (0..h * w)
        .filter(|&i| ctx.target[i])
        .map(|i| dist[i] * norm)
        .collect();
    let sigma2 = if ds.is_empty() {
        0.0
    } else {
        let k = (ds.len() * 3 / 4).min(ds.len() - 1);
        *ds.select_nth_unstable_by(k, |a, b| a.total_cmp(b)).1
    };
    drop(ds);
    let mut weight = vec![0.0f32; h * w];
    weight.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        for (x, wt) in row.iter_mut().enumerate() {
            let i = y * w + x;
            *wt = if !ctx.target[i] {
                0.0
            } else if sigma2 > 0.0 {
                (-(dist[i] * norm / (2.0 * sigma2)).min(50.0)).exp()
            } else {
                1.0
            };
        }
    });
    // Coordinate tables: entry `v + r` is the image row (column) of the
    // position `v` ∈ [−r, h + r), `NONE` outside a non-toroidal image.
    const NONE: usize = usize::MAX;
    let table = |n: usize| -> Vec<usize> {
        (-r..n as isize + r)
            .map(|v| {
                if ctx.toroidal {
                    wrap(v, n)
                } else if (0..n as isize).contains(&v) {
                    v as usize
                } else {
                    NONE
                }
            })
            .collect()
    };
    let (rows, cols) = (table(h), table(w));
    // Row and column of every target's match, divided out once.
    let mut src_yx = vec![(0u32, 0u32); h * w];
    src_yx.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        for (x, o) in row.iter_mut().enumerate() {
            let s = nnf[y * w + x] as usize;
            *o = ((s / w) as u32, (s % w) as u32);
        }
    });
    let mut out = img.to_vec();
    let rows = out
        .par_chunks_mut(w * c)
        .enumerate()
        .map(|(y, row)| {
            let (mut change, mut total) = (0.0f32, 0.0f64);
            let (mut acc, mut kacc) = ([0.0f32; 4], [0.0f32; 4]);
            for x in 0..w {
                let q = y * w + x;
                if known[q] {
                    continue;
                }
                acc.fill(0.0);
                kacc.fill(0.0);
                let (mut wsum, mut ksum) = (0.0f32, 0.0f32);
                for dy in -r..=r {
                    // Target row y − dy: table index y − dy + r.
                    let ty = rows[(y as isize - dy + r) as usize];
                    if ty == NONE {
                        continue;
                    }
                    for dx in -r..=r {
                        // Target patch centred at q − (dy, dx) sees q at offset (dy, dx).
                        let tx = cols[(x as isize - dx + r) as usize];
                        if tx == NONE {
                            continue;
                        }
                        let t = ty * w + tx;
                        let wt = weight[t];
                        if wt <= 0.0 {
                            continue;
                        }
                        let (my, mx) = src_yx[t];
                        let sy = rows[(my as isize + dy + r) as usize];
                        let sx = cols[(mx as isize + dx + r) as usize];
                        if sy == NONE || sx == NONE {
                            continue;
                        }
                        let src = sy * w + sx;
                        let a = if known[src] {
                            ksum += wt;
                            &mut kacc
                        } else {
                            wsum += wt;
                            &mut acc
                        };
                        for ch in 0..c {
                            a[ch] += wt * img[src * c + ch];
                        }
                    }
                }
                // Observed source texels only, when there are any.
                let (acc, wsum) = if ksum > 0.0 {
                    (&kacc, ksum)
                } else {
                    (&acc, wsum)
                };
                if wsum > 0.0 {
                    for ch in 0..c {
                        let v = acc[ch] / wsum;
                        let d = (v - row[x * c + ch]).abs();
                        change = change.max(d);
                        total += f64::from(d);
                        row[x * c + ch] = v;
                    }
                }
            }
            (change, total)
        })
        .collect::<Vec<_>>();
    (out, Change::of_rows(&rows, known, c))
}

/// The plain implementation of [`vote`] (per-texel offsets with `rem_euclid`),
/// kept to test the table-driven one against.
#[cfg(test)]
fn vote_reference(
    ctx: &Ctx,
    img: &[f32],
    known: &[bool],
    nnf: &[u32],
    dist: &[f32],
) -> (Vec<f32>, Change) {
    let (h, w, c, r) = (ctx.h, ctx.w, ctx.c, ctx.r as isize);
    // σ² = 75th percentile of the mean squared patch differences.
    let norm = 1.0 / (ctx.p * ctx.p * c) as f32;
    let mut ds: Vec<f32> = (0..h * w)
        .filter(|&i| ctx.target[i])
        .map(|i| dist[i] * norm)
        .collect();
    let sigma2 = if ds.is_empty() {
        0.0
    } else {
        let k = (ds.len() * 3 / 4).min(ds.len() - 1);
        *ds.select_nth_unstable_by(k, |a, b| a.total_cmp(b)).1
    };
    let weight: Vec<f32> = (0..h * w)
        .map(|i| {
            if !ctx.target[i] {
                0.0
            } else if sigma2 > 0.0 {
                (-(dist[i] * norm / (2.0 * sigma2)).min(50.0)).exp()
            } else {
                1.0
            }
        })
        .collect();
    let mut out = img.to_vec();
    let rows = out
        .par_chunks_mut(w * c)
        .enumerate()
        .map(|(y, row)| {
            let (mut change, mut total) = (0.0f32, 0.0f64);
            let (mut acc, mut kacc) = ([0.0f32; 4], [0.0f32; 4]);
            for x in 0..w {
                let q = y * w + x;
                if known[q] {
                    continue;
                }
                acc.fill(0.0);
                kacc.fill(0.0);
                let (mut wsum, mut ksum) = (0.0f32, 0.0f32);
                for dy in -r..=r {
                    for dx in -r..=r {
                        // Target patch centred at q − (dy, dx) sees q at offset (dy, dx).
                        let Some(t) = ctx.offset(y, x, -dy, -dx) else {
                            continue;
                        };
                        let wt = weight[t];
                        if wt <= 0.0 {
                            continue;
                        }
                        let s = nnf[t] as usize;
                        let Some(src) = ctx.offset(s / w, s % w, dy, dx) else {
                            continue;
                        };
                        let a = if known[src] {
                            ksum += wt;
                            &mut kacc
                        } else {
                            wsum += wt;
                            &mut acc
                        };
                        for ch in 0..c {
                            a[ch] += wt * img[src * c + ch];
                        }
                    }
                }
                // Observed source texels only, when there are any.
                let (acc, wsum) = if ksum > 0.0 {
                    (&kacc, ksum)
                } else {
                    (&acc, wsum)
                };
                if wsum > 0.0 {
                    for ch in 0..c {
                        let v = acc[ch] / wsum;
                        let d = (v - row[x * c + ch]).abs();
                        change = change.max(d);
                        total += f64::from(d);
                        row[x * c + ch] = v;
                    }
                }
            }
            (change, total)
        })
        .collect::<Vec<_>>();
    (out, Change::of_rows(&rows, known, c))
}

#[cfg(test)]
mod tests {
    use super::*;
    use picker_tensor::Rng;

    /// A random level: values, a mask with about `unknown` unknown texels, a
    /// random NNF and the matching context pieces.
    struct Case {
        h: usize,
        w: usize,
        c: usize,
        p: usize,
        toroidal: bool,
        img: Vec<f32>,
        known: Vec<bool>,
        target: Vec<bool>,
        valid: Vec<bool>,
        nnf: Vec<u32>,
        dist: Vec<f32>,
    }

    impl Case {
        fn new(rng: &mut Rng, h: usize, w: usize, c: usize, p: usize, toroidal: bool) -> Self {
            let n = h * w;
            let img = rng.uniform_vec(n * c, 0.0, 1.0);
            let known: Vec<bool> = (0..n).map(|_| rng.f64() > 0.3).collect();
            let target: Vec<bool> = (0..n).map(|_| rng.f64() > 0.2).collect();
            let valid = vec![true; n];
            let nnf: Vec<u32> = (0..n).map(|_| rng.range(0, n - 1) as u32).collect();
            // Distances with repeats and zeros (σ² ties, weight 1 paths).
            let dist: Vec<f32> = (0..n)
                .map(|_| (rng.range(0, 6) as f32 * rng.uniform(0.0, 2.0)).floor())
                .collect();
            Self {
                h,
                w,
                c,
                p,
                toroidal,
                img,
                known,
                target,
                valid,
                nnf,
                dist,
            }
        }

        fn ctx(&self) -> Ctx<'_> {
            let r = self.p / 2;
            let (src_rows, src_cols) = if self.toroidal {
                ((0, self.h - 1), (0, self.w - 1))
            } else {
                ((r, self.h - 1 - r), (r, self.w - 1 - r))
            };
            Ctx {
                h: self.h,
                w: self.w,
                c: self.c,
                p: self.p,
                r,
                toroidal: self.toroidal,
                target: &self.target,
                valid: &self.valid,
                src_rows,
                src_cols,
            }
        }
    }

    /// Shapes from one patch up, square and thin, every specialised (p, c) and others.
    fn shapes() -> Vec<(usize, usize, usize, usize)> {
        let mut v = vec![];
        for (p, c) in [
            (3, 1),
            (3, 3),
            (5, 3),
            (5, 4),
            (7, 1),
            (7, 2),
            (7, 3),
            (7, 4),
            (9, 3),
        ] {
            for (h, w) in [(p, p), (p, 3 * p + 1), (2 * p + 3, p), (23, 17)] {
                v.push((h, w, c, p));
            }
        }
        v
    }

    #[test]
    fn fast_distance_matches_reference() {
        let mut rng = Rng::new(41);
        for (h, w, c, p) in shapes() {
            for toroidal in [true, false] {
                let case = Case::new(&mut rng, h, w, c, p, toroidal);
                let ctx = case.ctx();
                let pad = ctx.pad(&case.img);
                for _ in 0..200 {
                    let t = rng.range(0, h * w - 1);
                    let s = rng.range(0, h * w - 1);
                    let full = ctx.dist_reference(&pad, t, s, f32::INFINITY);
                    for bound in [f32::INFINITY, full, full * 0.5, 0.0, full * 1.01] {
                        let a = ctx.dist(&pad, t, s, bound);
                        let b = ctx.dist_reference(&pad, t, s, bound);
                        assert_eq!(
                            a.to_bits(),
                            b.to_bits(),
                            "{h}x{w}x{c} p{p} t{t} s{s} bound {bound}"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn parallel_pad_matches_reference() {
        let mut rng = Rng::new(43);
        for (h, w, c, p) in shapes() {
            for toroidal in [true, false] {
                let case = Case::new(&mut rng, h, w, c, p, toroidal);
                let ctx = case.ctx();
                let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                assert_eq!(
                    bits(&ctx.pad(&case.img)),
                    bits(&ctx.pad_reference(&case.img)),
                    "{h}x{w}x{c} p{p} toroidal {toroidal}"
                );
            }
        }
    }

    #[test]
    fn wrap_matches_rem_euclid() {
        for n in [1usize, 2, 3, 7, 64] {
            for v in -(4 * n as isize)..(4 * n as isize) {
                assert_eq!(wrap(v, n), v.rem_euclid(n as isize) as usize, "{v} mod {n}");
            }
        }
    }

    #[test]
    fn table_vote_matches_reference() {
        let mut rng = Rng::new(42);
        for (h, w, c, p) in shapes() {
            for toroidal in [true, false] {
                let mut case = Case::new(&mut rng, h, w, c, p, toroidal);
                for round in 0..3 {
                    if round == 1 {
                        // Every distance equal: σ² = that value.
                        case.dist.fill(0.5);
                    } else if round == 2 {
                        // All zero: σ² = 0, unit weights.
                        case.dist.fill(0.0);
                    }
                    let ctx = case.ctx();
                    let (a, ca) = vote(&ctx, &case.img, &case.known, &case.nnf, &case.dist);
                    assert!(ca.mean.is_finite() && ca.mean <= f64::from(ca.max));
                    let (b, cb) =
                        vote_reference(&ctx, &case.img, &case.known, &case.nnf, &case.dist);
                    let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                    assert_eq!(bits(&a), bits(&b), "{h}x{w}x{c} p{p} toroidal {toroidal}");
                    assert_eq!(ca.max.to_bits(), cb.max.to_bits());
                    assert_eq!(ca.mean.to_bits(), cb.mean.to_bits());
                }
            }
        }
    }

    #[test]
    fn fast_pm_pass_matches_reference() {
        for isa in Isa::ALL {
            if !isa.is_available() {
                eprintln!("fast_pm_pass_matches_reference: SKIPPED {isa:?} (this CPU lacks it)");
                continue;
            }
            let mut rng = Rng::new(44);
            let pm = PatchMatchInpainter::default();
            for (h, w, c, p) in shapes() {
                for toroidal in [true, false] {
                    let mut case = Case::new(&mut rng, h, w, c, p, toroidal);
                    // Some inadmissible sources; non-toroidal sources inside the image.
                    let r = p / 2;
                    for (i, v) in case.valid.iter_mut().enumerate() {
                        let (y, x) = (i / w, i % w);
                        let inside = toroidal || (y >= r && y + r < h && x >= r && x + r < w);
                        *v = inside && rng.f64() > 0.2;
                    }
                    let ctx = case.ctx();
                    let pad = ctx.pad(&case.img);
                    let mut dist = vec![0.0f32; h * w];
                    compute_distances(&ctx, &pad, &case.nnf, &mut dist);
                    let (mut na, mut da) = (case.nnf.clone(), dist.clone());
                    let (mut nb, mut db) = (case.nnf.clone(), dist);
                    for pass in 0..4u64 {
                        let key = rng.next_u64();
                        let reverse = pass % 2 == 1;
                        pm.pm_pass(isa, &ctx, &pad, &mut na, &mut da, key, reverse);
                        pm.pm_pass_reference(&ctx, &pad, &mut nb, &mut db, key, reverse);
                        let at =
                            format!("{isa:?} {h}x{w}x{c} p{p} toroidal {toroidal} pass {pass}");
                        assert_eq!(na, nb, "{at}");
                        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                        assert_eq!(bits(&da), bits(&db), "{at}");
                    }
                }
            }
        }
    }
}
