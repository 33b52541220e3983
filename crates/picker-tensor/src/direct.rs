//! Direct stride-1 convolution for layers with very few output channels (the
//! networks' 7×7 → 3-channel output convs), vectorised along the output row.
//!
//! A GEMM would waste most of each `MR`-row tile on such layers. Here one task
//! computes a strip of [`STRIP_STEPS`] × [`ROWS`] output rows: for each input
//! channel it copies the strip's `rows + kh − 1` input rows into a small buffer, with the zero or
//! reflection padding filled in (so no padded copy of the whole input is
//! made), and then every block of output columns keeps `ROWS × c_out`
//! vector accumulators in registers while each input row is loaded once per
//! tap column and feeds both output rows. The running sums live in a per-task
//! row buffer between input channels.
//!
//! The AVX-512 kernel is written with intrinsics; the AVX2 and portable
//! kernels are the same loops in plain Rust, compiled for their ISA.

use rayon::prelude::*;

use crate::activation::Activation;
use crate::isa::Isa;
use crate::pad::{padded_source, Fill};

/// Most output channels the direct path takes.
pub(crate) const MAX_CO: usize = 4;
/// Output rows per task (each input row then feeds two output rows).
const ROWS: usize = 2;
/// Output columns per block: four 16-lane vectors.
const XB: usize = 64;
/// Kernel steps ([`ROWS`] output rows each) per task: the task copies the
/// padded input rows of its strip once for all of them (a task of one step
/// copied each input row `(ROWS + kh − 1) / ROWS` times: 4× for a 7×7 layer).
const STRIP_STEPS: usize = 4;

/// Geometry of one direct convolution (stride 1): the input `[c_in, h, w]`,
/// extended by `pad` on every side as `fill` says.
#[derive(Clone, Copy)]
pub(crate) struct DirectProblem<'a> {
    pub(crate) x: &'a [f32],
    pub(crate) c_in: usize,
    pub(crate) h: usize,
    pub(crate) w: usize,
    pub(crate) kh: usize,
    pub(crate) kw: usize,
    pub(crate) pad: usize,
    pub(crate) fill: Fill,
    pub(crate) oh: usize,
    pub(crate) ow: usize,
}

/// The weights `[c_out, c_in, kh, kw]` rearranged for the kernels: for
/// each `(ci, ky, kx)` the `c_out` values side by side, `[c_in][kh][kw][c_out]`.
pub(crate) fn pack_weights(weight: &[f32], c_out: usize, c_in: usize, kk: usize) -> Vec<f32> {
    let mut p = vec![0.0; weight.len()];
    for co in 0..c_out {
        for ci in 0..c_in {
            for t in 0..kk {
                p[(ci * kk + t) * c_out + co] = weight[(co * c_in + ci) * kk + t];
            }
        }
    }
    p
}

/// `acc[o][co][x] += Σ_{ky,kx} wt[ci][ky][kx][co] · rows[o + ky][x + kx]` for
/// one input channel: `rows` holds `ROWS + kh − 1` padded rows of `rs` floats,
/// `acc` is `[ROWS][CO][aw]` with `aw` a multiple of [`XB`]; rows are readable
/// up to `aw + kw − 1 + XB` floats.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn channel_generic<const CO: usize>(
    rows: &[f32],
    rs: usize,
    kh: usize,
    kw: usize,
    wt: &[f32],
    acc: &mut [f32],
    aw: usize,
) {
    for x0 in (0..aw).step_by(XB) {
        let mut a = [[[0.0f32; XB]; CO]; ROWS];
        for (o, ao) in a.iter_mut().enumerate() {
            for (co, aoc) in ao.iter_mut().enumerate() {
                aoc.copy_from_slice(&acc[(o * CO + co) * aw + x0..][..XB]);
            }
        }
        for r in 0..ROWS + kh - 1 {
            let row = &rows[r * rs..(r + 1) * rs];
            for kx in 0..kw {
                let v: &[f32; XB] = row[x0 + kx..x0 + kx + XB].try_into().expect("XB");
                for (o, ao) in a.iter_mut().enumerate() {
                    if r < o || r - o >= kh {
                        continue;
                    }
                    let wk = &wt[((r - o) * kw + kx) * CO..][..CO];
                    for (aoc, &wv) in ao.iter_mut().zip(wk) {
                        for t in 0..XB {
                            aoc[t] = wv.mul_add(v[t], aoc[t]);
                        }
                    }
                }
            }
        }
        for (o, ao) in a.iter().enumerate() {
            for (co, aoc) in ao.iter().enumerate() {
                acc[(o * CO + co) * aw + x0..][..XB].copy_from_slice(aoc);
            }
        }
    }
}

/// As [`channel_generic`], with the accumulators of one column block in
/// AVX-512 registers.
///
/// # Safety
/// The CPU has AVX-512F; the buffers are as [`channel_generic`] describes.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx2,fma")]
#[allow(clippy::too_many_arguments)]
unsafe fn channel_avx512<const CO: usize>(
    rows: &[f32],
    rs: usize,
    kh: usize,
    kw: usize,
    wt: &[f32],
    acc: &mut [f32],
    aw: usize,
) {
    use std::arch::x86_64::*;
    const NV: usize = XB / 16;
    debug_assert!(rows.len() >= (ROWS + kh - 2) * rs + aw + kw - 1 + XB);
    debug_assert!(acc.len() >= ROWS * CO * aw && wt.len() >= kh * kw * CO);
    let (rp, wp, ap) = (rows.as_ptr(), wt.as_ptr(), acc.as_mut_ptr());
    for x0 in (0..aw).step_by(XB) {
        let mut a = [[[_mm512_setzero_ps(); NV]; CO]; ROWS];
        for (o, ao) in a.iter_mut().enumerate() {
            for (co, aoc) in ao.iter_mut().enumerate() {
                for (j, v) in aoc.iter_mut().enumerate() {
                    *v = _mm512_loadu_ps(ap.add((o * CO + co) * aw + x0 + 16 * j));
                }
            }
        }
        for r in 0..ROWS + kh - 1 {
            let row = rp.add(r * rs + x0);
            for kx in 0..kw {
                let v: [__m512; NV] =
                    std::array::from_fn(|j| _mm512_loadu_ps(row.add(kx + 16 * j)));
                // Output row o uses this input row with ky = r − o.
                if r < kh {
                    let wk = wp.add((r * kw + kx) * CO);
                    for (co, acc) in a[0].iter_mut().enumerate() {
                        let wv = _mm512_set1_ps(*wk.add(co));
                        for (aj, vj) in acc.iter_mut().zip(&v) {
                            *aj = _mm512_fmadd_ps(wv, *vj, *aj);
                        }
                    }
                }
                if r >= 1 {
                    let wk = wp.add(((r - 1) * kw + kx) * CO);
                    for (co, acc) in a[1].iter_mut().enumerate() {
                        let wv = _mm512_set1_ps(*wk.add(co));
                        for (aj, vj) in acc.iter_mut().zip(&v) {
                            *aj = _mm512_fmadd_ps(wv, *vj, *aj);
                        }
                    }
                }
            }
        }
        for (o, ao) in a.iter().enumerate() {
            for (co, aoc) in ao.iter().enumerate() {
                for (j, v) in aoc.iter().enumerate() {
                    _mm512_storeu_ps(ap.add((o * CO + co) * aw + x0 + 16 * j), *v);
                }
            }
        }
    }
}

macro_rules! generic_for {
    ($name:ident, $($feat:literal)?) => {
        $(#[target_feature(enable = $feat)])?
        #[allow(clippy::too_many_arguments)]
        unsafe fn $name<const CO: usize>(
            rows: &[f32],
            rs: usize,
            kh: usize,
            kw: usize,
            wt: &[f32],
            acc: &mut [f32],
            aw: usize,
        ) {
            channel_generic::<CO>(rows, rs, kh, kw, wt, acc, aw)
        }
    };
}

#[cfg(target_arch = "x86_64")]
generic_for!(channel_avx2, "avx2,fma");
generic_for!(channel_portable,);

/// One input channel's contribution, with the kernel of `isa` and `c_out`.
#[allow(clippy::too_many_arguments)]
fn channel(
    isa: Isa,
    c_out: usize,
    rows: &[f32],
    rs: usize,
    kh: usize,
    kw: usize,
    wt: &[f32],
    acc: &mut [f32],
    aw: usize,
) {
    macro_rules! go {
        ($f:ident) => {
            match c_out {
                1 => $f::<1>(rows, rs, kh, kw, wt, acc, aw),
                2 => $f::<2>(rows, rs, kh, kw, wt, acc, aw),
                3 => $f::<3>(rows, rs, kh, kw, wt, acc, aw),
                _ => $f::<4>(rows, rs, kh, kw, wt, acc, aw),
            }
        };
    }
    // SAFETY: the layer was built for `isa`, which this CPU has; the buffer
    // sizes are set up by `conv_direct`.
    unsafe {
        match isa {
            #[cfg(target_arch = "x86_64")]
            Isa::Avx512 => go!(channel_avx512),
            #[cfg(target_arch = "x86_64")]
            Isa::Avx2Fma => go!(channel_avx2),
            _ => go!(channel_portable),
        }
    }
}

/// `out[co] = act(conv(pad(x), wt)[co] + bias[co]) [+ residual]` for
/// `co < c_out ≤ MAX_CO`; `wt` from [`pack_weights`]; `out` and `residual`
/// are `[c_out][oh][ow]`.
#[allow(clippy::too_many_arguments)]
pub(crate) fn conv_direct(
    isa: Isa,
    p: &DirectProblem<'_>,
    c_out: usize,
    wt: &[f32],
    bias: Option<&[f32]>,
    act: Activation,
    residual: Option<&[f32]>,
    out: &mut [f32],
) {
    assert!(
        (1..=MAX_CO).contains(&c_out),
        "direct conv takes 1..={MAX_CO} output channels"
    );
    let (oh, ow, kh, kw) = (p.oh, p.ow, p.kh, p.kw);
    assert_eq!(out.len(), c_out * oh * ow);
    assert_eq!(wt.len(), c_out * p.c_in * kh * kw);
    assert!(kh >= 1 && kw >= 1);
    assert_eq!(oh + kh - 1, p.h + 2 * p.pad, "direct conv: output height");
    assert_eq!(ow + kw - 1, p.w + 2 * p.pad, "direct conv: output width");
    if let Some(r) = residual {
        assert_eq!(r.len(), out.len(), "direct conv: residual length");
    }
    if oh == 0 || ow == 0 {
        return;
    }
    let (h, w, pad) = (p.h, p.w, p.pad);
    let (hp, wp) = (h + 2 * pad, w + 2 * pad);
    let aw = ow.next_multiple_of(XB);
    // A task's strip of output rows, in whole kernel steps of ROWS.
    let strip = (STRIP_STEPS * ROWS).min(oh.next_multiple_of(ROWS));
    let nrows = strip + kh - 1;
    // A padded row, plus the columns a full last block reads past it.
    let rs = (aw + kw - 1 + XB).max(wp);
    let kk = kh * kw;
    let plane = oh * ow;
    let cols: Vec<Option<usize>> = (0..wp)
        .map(|q| padded_source(q, pad, w, wp, p.fill))
        .collect();
    let out_ptr = SharedPtr(out.as_mut_ptr());
    let out_ptr = &out_ptr;
    let tasks = oh.div_ceil(strip);
    (0..tasks).into_par_iter().for_each_init(
        || (vec![0.0f32; nrows * rs], vec![0.0f32; strip * c_out * aw]),
        |(rows, acc), t| {
            let oy0 = t * strip;
            acc.fill(0.0);
            for ci in 0..p.c_in {
                let src = &p.x[ci * h * w..(ci + 1) * h * w];
                for r in 0..nrows {
                    let dst = &mut rows[r * rs..r * rs + wp];
                    match padded_source(oy0 + r, pad, h, hp, p.fill) {
                        None => dst.fill(0.0),
                        Some(sy) => {
                            let srow = &src[sy * w..(sy + 1) * w];
                            dst[pad..pad + w].copy_from_slice(srow);
                            for q in (0..pad).chain(pad + w..wp) {
                                dst[q] = cols[q].map_or(0.0, |c| srow[c]);
                            }
                        }
                    }
                }
                // Each kernel step: ROWS output rows from the strip's
                // rows, copied once for all of them.
                for q in 0..strip / ROWS {
                    channel(
                        isa,
                        c_out,
                        &rows[q * ROWS * rs..],
                        rs,
                        kh,
                        kw,
                        &wt[ci * kk * c_out..][..kk * c_out],
                        &mut acc[q * ROWS * c_out * aw..][..ROWS * c_out * aw],
                        aw,
                    );
                }
            }
            for o in 0..strip.min(oh - oy0) {
                let oy = oy0 + o;
                for co in 0..c_out {
                    let i0 = co * plane + oy * ow;
                    // SAFETY: row `oy` of every channel belongs to this task only.
                    let dst = unsafe { std::slice::from_raw_parts_mut(out_ptr.0.add(i0), ow) };
                    let b = bias.map_or(0.0, |b| b[co]);
                    let a = &acc[(o * c_out + co) * aw..][..ow];
                    match residual {
                        Some(res) => {
                            for ((d, &v), &r) in dst.iter_mut().zip(a).zip(&res[i0..i0 + ow]) {
                                *d = act.apply_one(v + b) + r;
                            }
                        }
                        None => {
                            for (d, &v) in dst.iter_mut().zip(a) {
                                *d = act.apply_one(v + b);
                            }
                        }
                    }
                }
            }
        },
    );
}

struct SharedPtr(*mut f32);
// SAFETY: tasks write disjoint output rows; see `conv_direct`.
unsafe impl Sync for SharedPtr {}
unsafe impl Send for SharedPtr {}
