//! Stride-1 convolutions as a GEMM whose B operand is read in place.
//!
//! Over a padded copy of the input (`c_in` planes of `hp × wp`), the
//! im2col row of tap `(ci, dy, dx)` is the image itself shifted by
//! `ci·hp·wp + dy·wp + dx`, if the output is computed on the padded width:
//! column `n` of the product is output pixel `(n / wp, n % wp)`, and the
//! columns with `n % wp ≥ ow` are computed and dropped. So the micro-kernel
//! reads every B row straight from the image ([`RowsKernelFn`]) and nothing is
//! packed; the `(kw − 1) / wp` wasted columns are the price.
//!
//! Used by 3×3 transposed convolutions (one such product per output phase,
//! written interleaved) and by stride-1 convolutions that Winograd does not
//! take (7×7, few channels).
//!
//! [`RowsKernelFn`]: crate::microkernel::RowsKernelFn

use rayon::prelude::*;

use crate::activation::Activation;
use crate::gemm::{Epilogue, PackedA};
use crate::pad::{padded_source, reflect_index, Fill};
use crate::params::{MAX_NR, MAX_PANELS_PER_TASK, TASKS_PER_THREAD};

/// The B operand: row `k` is `src[offs[k] ..]`, column `n` is output pixel
/// `(n / wp, n % wp)` of the padded-width grid.
pub(crate) struct ShiftedB<'a> {
    pub(crate) src: &'a [f32],
    pub(crate) offs: &'a [usize],
    pub(crate) wp: usize,
}

/// Where output `(co, y, x)` goes: `out[base + co·cs + y·rs + x·xs]`, for
/// `y < oh`, `x < ow`. The residual, if any, is indexed the same way.
#[derive(Clone, Copy, Debug)]
pub(crate) struct OutMap {
    pub(crate) base: usize,
    pub(crate) cs: usize,
    pub(crate) rs: usize,
    pub(crate) xs: usize,
    pub(crate) oh: usize,
    pub(crate) ow: usize,
}

impl OutMap {
    #[inline(always)]
    fn at(&self, co: usize, y: usize, x: usize) -> usize {
        self.base + co * self.cs + y * self.rs + x * self.xs
    }
}

/// Largest `MR` of any micro-kernel family.
const MAX_MR: usize = 8;

struct SharedPtr(*mut f32);
// SAFETY: every output element belongs to one column panel, so tasks (which
// own disjoint panels) write disjoint elements.
unsafe impl Sync for SharedPtr {}
unsafe impl Send for SharedPtr {}

/// `out = epilogue(a · b)` on the rayon pool, through `map`.
///
/// # Panics
/// When some row of `b` is shorter than the padded grid needs (`src` must
/// hold `max(offs) + ceil(oh·wp / NR)·NR` floats), or `out` is too short for `map`.
pub(crate) fn shifted_gemm(
    a: &PackedA,
    b: &ShiftedB<'_>,
    map: &OutMap,
    out: &mut [f32],
    epi: &Epilogue<'_>,
) {
    let (m, mr, nr) = (a.m, a.kernel.mr, a.kernel.nr);
    assert!(mr <= MAX_MR && nr <= MAX_NR);
    assert_eq!(
        b.offs.len(),
        a.k,
        "shifted_gemm: one offset per column of A"
    );
    if m == 0 || map.oh == 0 || map.ow == 0 {
        return;
    }
    assert!(
        map.ow <= b.wp,
        "shifted_gemm: valid width beyond the padded width"
    );
    let n_wide = map.oh * b.wp;
    let n_panels = n_wide.div_ceil(nr);
    let max_off = b.offs.iter().copied().max().unwrap_or(0);
    assert!(
        max_off + n_panels * nr <= b.src.len(),
        "shifted_gemm: the padded input has too little slack"
    );
    let last = map.at(m - 1, map.oh - 1, map.ow - 1);
    assert!(last < out.len(), "shifted_gemm: output too short");
    if let Some(r) = epi.residual {
        assert!(last < r.len(), "shifted_gemm: residual too short");
    }
    if let Some(bias) = epi.bias {
        assert_eq!(bias.len(), m, "shifted_gemm: bias has the wrong length");
    }
    if a.k == 0 {
        for co in 0..m {
            for y in 0..map.oh {
                for x in 0..map.ow {
                    let i = map.at(co, y, x);
                    out[i] = finish(0.0, co, i, epi);
                }
            }
        }
        return;
    }
    let out_ptr = SharedPtr(out.as_mut_ptr());
    let out_ptr = &out_ptr;
    let task = |(p0, p1): (usize, usize)| {
        // One tile of partial sums per row panel, for the tiles that cannot be
        // accumulated in place.
        let mut tmps = vec![0.0f32; a.m_panels * mr * nr];
        for p in p0..p1 {
            let n0 = p * nr;
            let (y, x) = (n0 / b.wp, n0 % b.wp);
            let whole_cols = map.xs == 1 && x + nr <= map.ow;
            // Depth block outside, row panels inside: the block's B rows
            // (kc × nr floats) stay in L1 while every row panel uses them.
            for (bi, &(k0, kc, aoff)) in a.kblocks.iter().enumerate() {
                let offs = b.offs[k0..k0 + kc].as_ptr();
                for mp in 0..a.m_panels {
                    let row0 = mp * mr;
                    let direct = whole_cols && mr.min(m - row0) == mr;
                    let ap = a.data.as_slice()[aoff + mp * kc * mr..].as_ptr();
                    let tmp = &mut tmps[mp * mr * nr..(mp + 1) * mr * nr];
                    // SAFETY: the A panel holds kc·mr floats; every B row has nr
                    // floats from n0 (slack checked above); C is either `tmp`
                    // (mr rows of nr) or mr whole rows of nr inside `out`, owned
                    // by this task.
                    unsafe {
                        let bp = b.src.as_ptr().add(n0);
                        if direct {
                            let c = out_ptr.0.add(map.at(row0, y, x));
                            (a.kernel.run_rows)(kc, ap, bp, offs, c, map.cs, bi > 0);
                        } else {
                            (a.kernel.run_rows)(kc, ap, bp, offs, tmp.as_mut_ptr(), nr, bi > 0);
                        }
                    }
                }
            }
            for mp in 0..a.m_panels {
                let row0 = mp * mr;
                let rows = mr.min(m - row0);
                let direct = whole_cols && rows == mr;
                let tmp = &tmps[mp * mr * nr..(mp + 1) * mr * nr];
                // SAFETY: the elements touched are this panel's, inside `out`
                // (checked above through `last`), written by this task only.
                unsafe {
                    if direct {
                        for r in 0..rows {
                            let i0 = map.at(row0 + r, y, x);
                            let dst = std::slice::from_raw_parts_mut(out_ptr.0.add(i0), nr);
                            let res = epi.residual.map(|rs| &rs[i0..i0 + nr]);
                            finish_run_isa(a.kernel.isa, dst, bias_of(epi, row0 + r), epi.act, res);
                        }
                    } else {
                        // Runs of the panel that stay in one output row.
                        let end = (n0 + nr).min(n_wide);
                        let mut n = n0;
                        while n < end {
                            let (yy, xx) = (n / b.wp, n % b.wp);
                            let run = (b.wp - xx).min(end - n);
                            let valid = run.min(map.ow.saturating_sub(xx));
                            if valid > 0 {
                                let j0 = n - n0;
                                for r in 0..rows {
                                    let i0 = map.at(row0 + r, yy, xx);
                                    let src = &tmp[r * nr + j0..][..valid];
                                    let bias = bias_of(epi, row0 + r);
                                    if map.xs == 1 {
                                        let dst = std::slice::from_raw_parts_mut(
                                            out_ptr.0.add(i0),
                                            valid,
                                        );
                                        let res = epi.residual.map(|rs| &rs[i0..i0 + valid]);
                                        copy_finish(a.kernel.isa, src, dst, bias, epi.act, res);
                                    } else {
                                        for (k, &v) in src.iter().enumerate() {
                                            let i = i0 + k * map.xs;
                                            let mut o = epi.act.apply_one(v + bias);
                                            if let Some(rs) = epi.residual {
                                                o += rs[i];
                                            }
                                            *out_ptr.0.add(i) = o;
                                        }
                                    }
                                }
                            }
                            n += run;
                        }
                    }
                }
            }
        }
    };
    for_each_panel_range(n_panels, task);
}

/// `dst[j] = src[s·j]` (`src` holds at least `s·(len − 1) + 1` floats).
#[inline(always)]
fn strided_copy_body(src: &[f32], s: usize, dst: &mut [f32]) {
    let n = dst.len();
    if n == 0 {
        return;
    }
    if s == 2 {
        // Whole pairs, so the loop vectorises into two loads and a permute.
        let pairs = (src.len() / 2).min(n);
        for (d, p) in dst[..pairs].iter_mut().zip(src.chunks_exact(2)) {
            *d = p[0];
        }
        for (j, d) in dst.iter_mut().enumerate().skip(pairs) {
            *d = src[2 * j];
        }
    } else {
        for (d, v) in dst.iter_mut().zip(src.iter().step_by(s)) {
            *d = *v;
        }
    }
}

crate::isa::per_isa! {
    /// [`strided_copy_body`] compiled for `isa`.
    fn strided_copy(src: &[f32], s: usize, dst: &mut [f32]) => strided_copy_body
}

/// One column phase of [`shifted_gemm_interleaved`]: the product `a · b`
/// with B row `k` at `src[offs[k] ..]`.
pub(crate) struct PhasePart<'a> {
    pub(crate) a: &'a PackedA,
    pub(crate) offs: &'a [usize],
}

/// Where [`shifted_gemm_interleaved`] writes: output `(co, y, j)` is
/// `out[base + co·cs + y·rs + j]` for `y < oh`, `j < ow`, column `j` from
/// column phase `j % s` at grid column `j / s`.
#[derive(Clone, Copy, Debug)]
pub(crate) struct RowPhaseMap {
    pub(crate) base: usize,
    pub(crate) cs: usize,
    pub(crate) rs: usize,
    pub(crate) oh: usize,
    pub(crate) ow: usize,
    pub(crate) s: usize,
}

/// One row phase of a stride-`s` transposed convolution with its `s` column
/// phases computed side by side, on the rayon pool: for each panel of the
/// padded-width grid (column `n` is grid point `(n / wp, n % wp)`), every
/// column phase `rx` runs its product (`parts[rx]`; `None`: no taps, a zero
/// product) into a tile, and the tiles are interleaved into whole output
/// rows, `out[… + s·x + rx] = epilogue(product_rx[y][x])`. Each output line
/// is written once and contiguously, instead of once per column phase with
/// stride `s`.
///
/// # Panics
/// When `parts` is not `map.s` long, holds no product or products of
/// different heights or kernels, a B row is shorter than the grid needs, or
/// `out` is too short for `map`.
pub(crate) fn shifted_gemm_interleaved(
    parts: &[Option<PhasePart<'_>>],
    src: &[f32],
    wp: usize,
    map: &RowPhaseMap,
    out: &mut [f32],
    epi: &Epilogue<'_>,
) {
    assert_eq!(
        parts.len(),
        map.s,
        "shifted_gemm_interleaved: one part per column phase"
    );
    let first = parts
        .iter()
        .flatten()
        .next()
        .expect("shifted_gemm_interleaved: at least one column phase with taps");
    let (m, kernel) = (first.a.m, first.a.kernel);
    let (mr, nr, m_panels) = (kernel.mr, kernel.nr, first.a.m_panels);
    assert!(mr <= MAX_MR && nr <= MAX_NR);
    for p in parts.iter().flatten() {
        assert!(p.a.m == m && p.a.kernel.isa == kernel.isa && p.a.kernel.nr == nr);
        assert_eq!(
            p.offs.len(),
            p.a.k,
            "shifted_gemm_interleaved: one offset per column of A"
        );
    }
    if m == 0 || map.oh == 0 || map.ow == 0 {
        return;
    }
    assert!(
        map.s >= 1 && map.ow.div_ceil(map.s) <= wp,
        "shifted_gemm_interleaved: grid narrower than the output"
    );
    let n_wide = map.oh * wp;
    let n_panels = n_wide.div_ceil(nr);
    for p in parts.iter().flatten() {
        let max_off = p.offs.iter().copied().max().unwrap_or(0);
        assert!(
            max_off + n_panels * nr <= src.len(),
            "shifted_gemm_interleaved: the padded input has too little slack"
        );
    }
    let last = map.base + (m - 1) * map.cs + (map.oh - 1) * map.rs + map.ow - 1;
    assert!(
        last < out.len(),
        "shifted_gemm_interleaved: output too short"
    );
    if let Some(r) = epi.residual {
        assert!(
            last < r.len(),
            "shifted_gemm_interleaved: residual too short"
        );
    }
    if let Some(bias) = epi.bias {
        assert_eq!(
            bias.len(),
            m,
            "shifted_gemm_interleaved: bias has the wrong length"
        );
    }
    let s = map.s;
    let out_ptr = SharedPtr(out.as_mut_ptr());
    let out_ptr = &out_ptr;
    let tile = m_panels * mr * nr;
    let task = |(p0, p1): (usize, usize)| {
        // One tile per column phase and row panel; a phase without taps
        // keeps its zeros.
        let mut tmps = vec![0.0f32; s * tile];
        for p in p0..p1 {
            let n0 = p * nr;
            for (rx, part) in parts.iter().enumerate() {
                let Some(part) = part else { continue };
                let a = part.a;
                for (bi, &(k0, kc, aoff)) in a.kblocks.iter().enumerate() {
                    let offs = part.offs[k0..k0 + kc].as_ptr();
                    for mp in 0..m_panels {
                        let ap = a.data.as_slice()[aoff + mp * kc * mr..].as_ptr();
                        let c = &mut tmps[rx * tile + mp * mr * nr..][..mr * nr];
                        // SAFETY: the A panel holds kc·mr floats; every B row has
                        // nr floats from n0 (slack checked above); C is `mr` rows
                        // of `nr` in this task's tile.
                        unsafe {
                            let bp = src.as_ptr().add(n0);
                            (a.kernel.run_rows)(kc, ap, bp, offs, c.as_mut_ptr(), nr, bi > 0);
                        }
                    }
                }
            }
            // Runs of the panel that stay in one grid row.
            let end = (n0 + nr).min(n_wide);
            let mut n = n0;
            while n < end {
                let (yy, xx) = (n / wp, n % wp);
                let run = (wp - xx).min(end - n);
                let (j0, j1) = (s * xx, (s * (xx + run)).min(map.ow));
                if j1 > j0 {
                    let lane0 = n - n0;
                    for co in 0..m {
                        let (mp, r) = (co / mr, co % mr);
                        let i0 = map.base + co * map.cs + yy * map.rs + j0;
                        // SAFETY: output row `yy` of channel `co`, columns
                        // [j0, j1), lies inside `out` (checked through `last`)
                        // and belongs to this task's panel only.
                        let dst =
                            unsafe { std::slice::from_raw_parts_mut(out_ptr.0.add(i0), j1 - j0) };
                        let at = |rx: usize| &tmps[rx * tile + (mp * mr + r) * nr + lane0..][..run];
                        let res = epi.residual.map(|rs| &rs[i0..i0 + (j1 - j0)]);
                        let bias = bias_of(epi, co);
                        interleave_finish(kernel.isa, s, at, dst, bias, epi.act, res);
                    }
                }
                n += run;
            }
        }
    };
    for_each_panel_range(n_panels, task);
}

/// `dst[j] = act(src(j % s)[j / s] + bias) [+ res[j]]`.
#[inline(always)]
fn interleave_finish_body<'a>(
    s: usize,
    src: impl Fn(usize) -> &'a [f32],
    dst: &mut [f32],
    bias: f32,
    act: Activation,
    res: Option<&[f32]>,
) {
    if s == 2 {
        let (a, b) = (src(0), src(1));
        let pairs = dst.len() / 2;
        let (a, b) = (&a[..pairs + dst.len() % 2], &b[..pairs]);
        // The bias and ReLU in the same pass (the same operations as
        // `finish_run`, so the same values): the decoders' layers.
        #[inline(always)]
        fn fused(a: &[f32], b: &[f32], dst: &mut [f32], f: impl Fn(f32) -> f32) {
            let pairs = dst.len() / 2;
            for ((o, &x), &y) in dst.chunks_exact_mut(2).zip(a).zip(b) {
                o[0] = f(x);
                o[1] = f(y);
            }
            if dst.len() % 2 == 1 {
                dst[2 * pairs] = f(a[pairs]);
            }
        }
        match (act, res) {
            (Activation::Relu, None) => return fused(a, b, dst, |v| (v + bias).max(0.0)),
            (Activation::None, None) => return fused(a, b, dst, |v| v + bias),
            _ => {}
        }
        for (k, o) in dst.chunks_exact_mut(2).enumerate() {
            o[0] = a[k];
            o[1] = b[k];
        }
        if dst.len() % 2 == 1 {
            dst[2 * pairs] = a[pairs];
        }
    } else {
        for (j, o) in dst.iter_mut().enumerate() {
            *o = src(j % s)[j / s];
        }
    }
    finish_run(dst, bias, act, res);
}

crate::isa::per_isa! {
    /// [`interleave_finish_body`] compiled for `isa`.
    fn interleave_finish<'a>(
        s: usize,
        src: impl Fn(usize) -> &'a [f32],
        dst: &mut [f32],
        bias: f32,
        act: Activation,
        res: Option<&[f32]>,
    ) => interleave_finish_body
}

/// Runs `task` on consecutive ranges `[p0, p1)` of `n_panels` column panels
/// on the rayon pool: about [`TASKS_PER_THREAD`] ranges per thread (so work
/// stealing can even out the load), at most [`MAX_PANELS_PER_TASK`] panels
/// each; in order on the calling thread when the pool has one thread.
fn for_each_panel_range(n_panels: usize, task: impl Fn((usize, usize)) + Sync + Send) {
    let threads = rayon::current_num_threads().max(1);
    let per_task = n_panels
        .div_ceil(threads * TASKS_PER_THREAD)
        .clamp(1, MAX_PANELS_PER_TASK);
    let n_tasks = n_panels.div_ceil(per_task);
    let range = |t: usize| (t * per_task, ((t + 1) * per_task).min(n_panels));
    if threads == 1 {
        (0..n_tasks).map(range).for_each(task);
    } else {
        (0..n_tasks).into_par_iter().map(range).for_each(task);
    }
}

/// `act(v + bias[co]) + residual[i]`.
#[inline(always)]
fn finish(v: f32, co: usize, i: usize, epi: &Epilogue<'_>) -> f32 {
    let r = epi.act.apply_one(v + bias_of(epi, co));
    match epi.residual {
        Some(res) => r + res[i],
        None => r,
    }
}

#[inline(always)]
fn bias_of(epi: &Epilogue<'_>, co: usize) -> f32 {
    epi.bias.map_or(0.0, |b| b[co])
}

crate::isa::per_isa! {
    /// [`finish_run`] compiled for `isa` (the epilogue of every panel).
    fn finish_run_isa<'a>(
        dst: &'a mut [f32],
        bias: f32,
        act: Activation,
        res: Option<&'a [f32]>,
    ) => finish_run
}

crate::isa::per_isa! {
    /// [`copy_finish_body`] compiled for `isa`.
    fn copy_finish<'a>(
        src: &'a [f32],
        dst: &'a mut [f32],
        bias: f32,
        act: Activation,
        res: Option<&'a [f32]>,
    ) => copy_finish_body
}

/// `dst = act(src + bias) [+ res]`, element-wise: a copy and
/// [`finish_run`] in one pass (the same operations, the same values).
#[inline(always)]
fn copy_finish_body(src: &[f32], dst: &mut [f32], bias: f32, act: Activation, res: Option<&[f32]>) {
    let src = &src[..dst.len()];
    match (act, res) {
        (Activation::Relu, None) => {
            for (d, &v) in dst.iter_mut().zip(src) {
                *d = (v + bias).max(0.0);
            }
        }
        (Activation::None, None) => {
            for (d, &v) in dst.iter_mut().zip(src) {
                *d = v + bias;
            }
        }
        _ => {
            dst.copy_from_slice(src);
            finish_run(dst, bias, act, res);
        }
    }
}

/// `dst = act(dst + bias) [+ res]`, element-wise.
#[inline(always)]
fn finish_run(dst: &mut [f32], bias: f32, act: Activation, res: Option<&[f32]>) {
    match (act, res) {
        (Activation::Relu, None) => dst.iter_mut().for_each(|v| *v = (*v + bias).max(0.0)),
        (Activation::None, None) => dst.iter_mut().for_each(|v| *v += bias),
        (_, None) => dst.iter_mut().for_each(|v| *v = act.apply_one(*v + bias)),
        (_, Some(r)) => dst
            .iter_mut()
            .zip(r)
            .for_each(|(v, &r)| *v = act.apply_one(*v + bias) + r),
    }
}

/// A padded copy of one image (`c` planes of `h × w`) with `[top, bottom,
/// left, right]` pads, plus `slack` zero floats at the end, from the pool.
/// Returns the buffer and the padded `(hp, wp)`.
pub(crate) fn padded_copy(
    x: &[f32],
    c: usize,
    h: usize,
    w: usize,
    [t, bo, l, r]: [usize; 4],
    fill: Fill,
    slack: usize,
) -> (Vec<f32>, usize, usize) {
    let rows = -(t as isize)..(h + bo) as isize;
    row_window_copy(x, c, h, w, rows, [l, r], fill, slack)
}

/// Rows `rows` of one image (`c` planes of `h × w`; rows outside `0..h` are
/// the `fill`'s: zeros or the reflection), each extended by `[left, right]`
/// columns of the same fill, plus `slack` zero floats at the end, from the
/// pool. Returns the buffer and its `(rows.len(), w + left + right)` plane
/// size.
#[allow(clippy::too_many_arguments)]
pub(crate) fn row_window_copy(
    x: &[f32],
    c: usize,
    h: usize,
    w: usize,
    rows: std::ops::Range<isize>,
    [l, r]: [usize; 2],
    fill: Fill,
    slack: usize,
) -> (Vec<f32>, usize, usize) {
    let (hp, wp) = (rows.len(), w + l + r);
    let plane = hp * wp;
    let mut buf = crate::pool::take(c * plane + slack);
    let (body, tail) = buf.split_at_mut(c * plane);
    tail.fill(0.0);
    let source_row = |py: usize| {
        let v = rows.start + py as isize;
        if (0..h as isize).contains(&v) {
            Some(v as usize)
        } else {
            (fill == Fill::Reflect).then(|| reflect_index(v, h))
        }
    };
    body.par_chunks_mut(plane.max(1))
        .enumerate()
        .for_each(|(ci, dst)| {
            let src = &x[ci * h * w..(ci + 1) * h * w];
            for (py, drow) in dst.chunks_exact_mut(wp).enumerate() {
                let Some(sy) = source_row(py) else {
                    drow.fill(0.0);
                    continue;
                };
                let srow = &src[sy * w..(sy + 1) * w];
                drow[l..l + w].copy_from_slice(srow);
                for j in (0..l).chain(l + w..wp) {
                    drow[j] = padded_source(j, l, w, wp, fill).map_or(0.0, |c| srow[c]);
                }
            }
        });
    (buf, hp, wp)
}

/// The `s × s` phase planes of one padded image, for a stride-`s` convolution
/// as a stride-1 product: plane `(a, b, ci)` holds `padded[ci][s·i + a][s·j + b]`
/// (`hq × wq`, zero past the padded image), planes ordered `(a·s + b)·c + ci`,
/// plus `slack` zero floats. Returns the buffer and `(hq, wq)`.
#[allow(clippy::too_many_arguments)]
pub(crate) fn phase_copy(
    x: &[f32],
    c: usize,
    h: usize,
    w: usize,
    pad: usize,
    fill: Fill,
    s: usize,
    slack: usize,
) -> (Vec<f32>, usize, usize) {
    let (hp, wp) = (h + 2 * pad, w + 2 * pad);
    let (hq, wq) = (hp.div_ceil(s), wp.div_ceil(s));
    let plane = hq * wq;
    let src_of = |q: usize, n: usize, np: usize| padded_source(q, pad, n, np, fill);
    let cols: Vec<Vec<Option<usize>>> = (0..s)
        .map(|b| (0..wq).map(|j| src_of(s * j + b, w, wp)).collect())
        .collect();
    // Per column phase b: the range of j whose source column is inside the row.
    let interior: Vec<(usize, usize)> = (0..s)
        .map(|b| {
            let lo = pad.saturating_sub(b).div_ceil(s).min(wq);
            let hi = ((w + pad).saturating_sub(b)).div_ceil(s).clamp(lo, wq);
            (lo, hi)
        })
        .collect();
    let mut buf = crate::pool::take(s * s * c * plane + slack);
    let (body, tail) = buf.split_at_mut(s * s * c * plane);
    tail.fill(0.0);
    let isa = crate::isa::Isa::best();
    let ptr = SharedPtr(body.as_mut_ptr());
    let ptr = &ptr;
    // One task per (row phase a, channel): it reads each source row once and
    // writes that row of all `s` column-phase planes.
    (0..s * c).into_par_iter().for_each(|idx| {
        let (a, ci) = (idx / c, idx % c);
        let src = &x[ci * h * w..(ci + 1) * h * w];
        // SAFETY: planes (a, b, ci) for b < s are written by this task only,
        // and lie inside `body` (s·s·c planes of `plane` floats).
        let mut planes: Vec<&mut [f32]> = (0..s)
            .map(|b| unsafe {
                std::slice::from_raw_parts_mut(ptr.0.add(((a * s + b) * c + ci) * plane), plane)
            })
            .collect();
        for i in 0..hq {
            match src_of(s * i + a, h, hp) {
                None => planes
                    .iter_mut()
                    .for_each(|p| p[i * wq..(i + 1) * wq].fill(0.0)),
                Some(sy) => {
                    let srow = &src[sy * w..(sy + 1) * w];
                    for (b, p) in planes.iter_mut().enumerate() {
                        let drow = &mut p[i * wq..(i + 1) * wq];
                        // Columns j with 0 ≤ s·j + b − pad < w read the row with
                        // stride s; the few others go through the map.
                        let (lo, hi) = interior[b];
                        if lo < hi {
                            let first = s * lo + b - pad;
                            strided_copy(isa, &srow[first..], s, &mut drow[lo..hi]);
                        }
                        for j in (0..lo.min(wq)).chain(hi.max(lo)..wq) {
                            drow[j] = cols[b][j].map_or(0.0, |cx| srow[cx]);
                        }
                    }
                }
            }
        }
    });
    (buf, hq, wq)
}
