//! AVX-512 tile transforms of the Winograd F(4×4, 3×3) convolution, written
//! with intrinsics: the generic transforms (`super::input_channel_body`,
//! `super::output_panel_body`) spend most of their time splitting rows into
//! column phases and back one float at a time; here those are two permutes
//! per 16 tiles, and each pass reads its rows where they lie.
//!
//! **Input** (one channel, one block of tiles), per run of tiles in one tile
//! row: `Bᵀ` first runs down the six source rows of the band (contiguous
//! loads straight from the image; padding rows are a zero row or the
//! reflected row, padding columns are computed from their source column),
//! giving six rows `z_i`; each `z_i` is split into its four column phases
//! with `vpermt2ps`, and `Bᵀ` along the columns writes `V[6i + j]` for 16
//! tiles at once.
//!
//! **Output** (one output channel, one panel): `Aᵀ` over the rows and then
//! the columns of the 36 products, 16 tiles per register; the four columns
//! of each tile row are interleaved back into pixels with permutes, and bias,
//! activation and residual are applied on whole vectors before a masked store.
//!
//! Same arithmetic as the generic transforms (`Bᵀ`, `Aᵀ` coefficients and
//! operation order per pass), with the input passes in the other order (rows
//! first), so results agree with them to rounding.

use std::arch::x86_64::*;

use super::{segments, Geometry, OutPlane, VRows, M, P, T};
use crate::activation::Activation;
use crate::pad::padded_source;

/// `Bᵀ d` (the points 0, ±1, ±2, ∞), as [`super::bt`], with the arithmetic
/// given as functions so that one text serves `f32` and `__m512`.
macro_rules! bt6 {
    ($d:expr, $add:ident, $sub:ident, $mul:ident, $k:ident) => {{
        let d = $d;
        [
            $add($sub($mul($k(4.0), d[0]), $mul($k(5.0), d[2])), d[4]),
            $add(
                $add($sub($mul($k(-4.0), d[1]), $mul($k(4.0), d[2])), d[3]),
                d[4],
            ),
            $add(
                $sub($sub($mul($k(4.0), d[1]), $mul($k(4.0), d[2])), d[3]),
                d[4],
            ),
            $add(
                $add($sub($mul($k(-2.0), d[1]), d[2]), $mul($k(2.0), d[3])),
                d[4],
            ),
            $add(
                $sub($sub($mul($k(2.0), d[1]), d[2]), $mul($k(2.0), d[3])),
                d[4],
            ),
            $add($sub($mul($k(4.0), d[1]), $mul($k(5.0), d[3])), d[5]),
        ]
    }};
}

/// `Aᵀ m`, as [`super::at`].
macro_rules! at4 {
    ($m:expr, $add:ident, $sub:ident, $mul:ident, $k:ident) => {{
        let m = $m;
        [
            $add($add($add($add(m[0], m[1]), m[2]), m[3]), m[4]),
            $add($sub(m[1], m[2]), $mul($k(2.0), $sub(m[3], m[4]))),
            $add($add(m[1], m[2]), $mul($k(4.0), $add(m[3], m[4]))),
            $add(
                $add($sub(m[1], m[2]), $mul($k(8.0), $sub(m[3], m[4]))),
                m[5],
            ),
        ]
    }};
}

#[inline(always)]
fn sadd(a: f32, b: f32) -> f32 {
    a + b
}
#[inline(always)]
fn ssub(a: f32, b: f32) -> f32 {
    a - b
}
#[inline(always)]
fn smul(a: f32, b: f32) -> f32 {
    a * b
}
#[inline(always)]
fn sk(a: f32) -> f32 {
    a
}

/// The mask of the first `n ≤ 16` lanes.
#[inline(always)]
fn first(n: usize) -> __mmask16 {
    if n >= 16 {
        0xffff
    } else {
        ((1u32 << n) - 1) as __mmask16
    }
}

/// The four column phases of 16 tiles: `q_c[t] = z[4t + c]` for the 64
/// floats at `p`.
#[inline(always)]
unsafe fn phases(p: *const f32) -> [__m512; 4] {
    // Lanes 0..8: phase a of 8 tiles; lanes 8..16: phase a + 1.
    let i01 = _mm512_setr_epi32(0, 4, 8, 12, 16, 20, 24, 28, 1, 5, 9, 13, 17, 21, 25, 29);
    let i23 = _mm512_setr_epi32(2, 6, 10, 14, 18, 22, 26, 30, 3, 7, 11, 15, 19, 23, 27, 31);
    let (z0, z1, z2, z3) = (
        _mm512_loadu_ps(p),
        _mm512_loadu_ps(p.add(16)),
        _mm512_loadu_ps(p.add(32)),
        _mm512_loadu_ps(p.add(48)),
    );
    let a01 = _mm512_permutex2var_ps(z0, i01, z1);
    let b01 = _mm512_permutex2var_ps(z2, i01, z3);
    let a23 = _mm512_permutex2var_ps(z0, i23, z1);
    let b23 = _mm512_permutex2var_ps(z2, i23, z3);
    [
        _mm512_shuffle_f32x4::<0x44>(a01, b01),
        _mm512_shuffle_f32x4::<0xee>(a01, b01),
        _mm512_shuffle_f32x4::<0x44>(a23, b23),
        _mm512_shuffle_f32x4::<0xee>(a23, b23),
    ]
}

/// Lanes `1..16` of `a` followed by lane 0 of `b`.
#[inline(always)]
unsafe fn next_lane(a: __m512, b: __m512) -> __m512 {
    _mm512_castsi512_ps(_mm512_alignr_epi32::<1>(
        _mm512_castps_si512(b),
        _mm512_castps_si512(a),
    ))
}

/// Input transform of channel `ci` over the tiles `[t0, t1)`; see
/// `super::input_channel_body` for the contract.
///
/// # Safety
/// The CPU has AVX-512F; `v` and `rows` as for the generic transform.
#[target_feature(enable = "avx512f,avx2,fma")]
#[allow(clippy::too_many_arguments)]
pub(super) unsafe fn input(
    g: &Geometry<'_>,
    ci: usize,
    t0: usize,
    t1: usize,
    nr: usize,
    rows: VRows,
    v: *mut f32,
    scratch: &mut Vec<f32>,
) {
    let (h, w, tw, pad) = (g.h, g.w, g.tw, g.pad);
    let plane = g.x[ci * h * w..(ci + 1) * h * w].as_ptr();
    // A run has at most `tw` tiles; the phase split reads whole groups of
    // 16 tiles, and one group past the run.
    let groups = tw.div_ceil(16) + 1;
    let zs = 64 * groups;
    scratch.resize(T * zs + w, 0.0);
    let (z, zero_row) = scratch.split_at_mut(T * zs);
    zero_row.fill(0.0);
    let (z, zero_row) = (z.as_mut_ptr(), zero_row.as_ptr());
    let mut segs = Vec::with_capacity(4);
    let mut p0 = t0;
    let mut panel = 0;
    while p0 < t1 {
        let p1 = (p0 + nr).min(t1);
        segments(p0, p1, tw, &mut segs);
        for &(l0, ty, tx0, len) in &segs {
            let src: [*const f32; 6] = std::array::from_fn(|r| match g.row_map[M * ty + r] {
                Some(sy) => plane.add(sy * w),
                None => zero_row,
            });
            // z_i[x] = Σ_r Bᵀ[i][r] padded[4ty + r][4tx0 + x], x < nx.
            let nx = M * len + 2;
            let qb = M * tx0;
            let xa = pad.saturating_sub(qb).min(nx);
            let xb = (pad + w).saturating_sub(qb).min(nx).max(xa);
            let mut x = xa;
            while x < xb {
                let mask = first(xb - x);
                let c = qb + x - pad;
                let d: [__m512; 6] =
                    std::array::from_fn(|r| _mm512_maskz_loadu_ps(mask, src[r].add(c)));
                let o = bt6!(
                    d,
                    _mm512_add_ps,
                    _mm512_sub_ps,
                    _mm512_mul_ps,
                    _mm512_set1_ps
                );
                for (i, oi) in o.iter().enumerate() {
                    _mm512_mask_storeu_ps(z.add(i * zs + x), mask, *oi);
                }
                x += 16;
            }
            for x in (0..xa).chain(xb..nx) {
                let o = match padded_source(qb + x, pad, w, w + 2 * pad, g.fill) {
                    Some(c) => {
                        let d: [f32; 6] = std::array::from_fn(|r| *src[r].add(c));
                        bt6!(d, sadd, ssub, smul, sk)
                    }
                    None => [0.0; 6],
                };
                for (i, oi) in o.iter().enumerate() {
                    *z.add(i * zs + x) = *oi;
                }
            }
            // The phase split reads whole groups of 16 tiles, one past the run.
            let zlen = 64 * (len.div_ceil(16) + 1);
            for i in 0..T {
                std::ptr::write_bytes(z.add(i * zs + nx), 0, zlen - nx);
            }
            // V[6i + j] = Σ_c Bᵀ[j][c] z_i[4k + c] for the run's tiles k:
            // tile k reads phases 0..4 at k and phases 0, 1 at k + 1.
            for i in 0..T {
                let zi = z.add(i * zs);
                let mut cur = phases(zi);
                let mut k = 0;
                while k < len {
                    let mask = first(len - k);
                    let next = phases(zi.add(M * (k + 16)));
                    let d = [
                        cur[0],
                        cur[1],
                        cur[2],
                        cur[3],
                        next_lane(cur[0], next[0]),
                        next_lane(cur[1], next[1]),
                    ];
                    let o = bt6!(
                        d,
                        _mm512_add_ps,
                        _mm512_sub_ps,
                        _mm512_mul_ps,
                        _mm512_set1_ps
                    );
                    for (j, oj) in o.iter().enumerate() {
                        let dst = v.add(rows.at(i * T + j, panel) + l0 + k);
                        _mm512_mask_storeu_ps(dst, mask, *oj);
                    }
                    cur = next;
                    k += 16;
                }
            }
        }
        // A partial panel's missing tiles are zero columns of B.
        let used = p1 - p0;
        if used < nr {
            for xi in 0..P {
                std::ptr::write_bytes(v.add(rows.at(xi, panel) + used), 0, nr - used);
            }
        }
        p0 = p1;
        panel += 1;
    }
}

/// Output transform of one output channel over one panel; see
/// `super::output_panel_body` for the contract (`scratch` holds at least
/// `16·nr + 16` floats).
///
/// # Safety
/// The CPU has AVX-512F; `nr` is a multiple of 16; `m` holds the 36 products
/// at `ξ·stride` (`nr` floats each).
#[target_feature(enable = "avx512f,avx2,fma")]
pub(super) unsafe fn output(
    m: &[f32],
    stride: usize,
    nr: usize,
    o: &OutPlane<'_>,
    plane: &mut [f32],
    scratch: &mut [f32],
) {
    let OutPlane {
        segs,
        oh,
        ow,
        bias,
        act,
        residual,
    } = *o;
    debug_assert!(nr.is_multiple_of(16) && scratch.len() >= M * M * nr + 16);
    debug_assert!(m.len() >= (P - 1) * stride + nr);
    let y = scratch.as_mut_ptr();
    let mp = m.as_ptr();
    // y[(i·4 + j)·nr + lane] = Σ_c Aᵀ[j][c] Σ_r Aᵀ[i][r] M[6r + c][lane]
    for l in (0..nr).step_by(16) {
        let t1: [[__m512; 4]; 6] = std::array::from_fn(|c| {
            let s: [__m512; 6] =
                std::array::from_fn(|r| _mm512_loadu_ps(mp.add((T * r + c) * stride + l)));
            at4!(
                s,
                _mm512_add_ps,
                _mm512_sub_ps,
                _mm512_mul_ps,
                _mm512_set1_ps
            )
        });
        #[allow(clippy::needless_range_loop)] // i indexes the inner arrays of t1
        for i in 0..M {
            let s: [__m512; 6] = std::array::from_fn(|c| t1[c][i]);
            let o = at4!(
                s,
                _mm512_add_ps,
                _mm512_sub_ps,
                _mm512_mul_ps,
                _mm512_set1_ps
            );
            for (j, oj) in o.iter().enumerate() {
                _mm512_storeu_ps(y.add((i * M + j) * nr + l), *oj);
            }
        }
    }
    // Pixel 4t + j of a tile row comes from lane t of column j.
    let lo = _mm512_setr_epi32(0, 8, 16, 24, 1, 9, 17, 25, 2, 10, 18, 26, 3, 11, 19, 27);
    let hi = _mm512_setr_epi32(4, 12, 20, 28, 5, 13, 21, 29, 6, 14, 22, 30, 7, 15, 23, 31);
    let vb = _mm512_set1_ps(bias);
    let zero = _mm512_setzero_ps();
    let out = plane.as_mut_ptr();
    for &(l0, ty, tx0, len) in segs {
        let x0 = M * tx0;
        let x1 = (M * (tx0 + len)).min(ow);
        for i in 0..M {
            let oy = ty * M + i;
            if oy >= oh {
                break;
            }
            let row = oy * ow + x0;
            let n = x1 - x0;
            let mut k = 0;
            while k < len {
                let yl = |j: usize| _mm512_loadu_ps(y.add((i * M + j) * nr + l0 + k));
                let (y0, y1, y2, y3) = (yl(0), yl(1), yl(2), yl(3));
                let a01 = _mm512_shuffle_f32x4::<0x44>(y0, y1);
                let b01 = _mm512_shuffle_f32x4::<0xee>(y0, y1);
                let a23 = _mm512_shuffle_f32x4::<0x44>(y2, y3);
                let b23 = _mm512_shuffle_f32x4::<0xee>(y2, y3);
                let px = [
                    _mm512_permutex2var_ps(a01, lo, a23),
                    _mm512_permutex2var_ps(a01, hi, a23),
                    _mm512_permutex2var_ps(b01, lo, b23),
                    _mm512_permutex2var_ps(b01, hi, b23),
                ];
                for (s, &p) in px.iter().enumerate() {
                    let at = M * k + 16 * s;
                    if at >= n {
                        break;
                    }
                    let mask = first(n - at);
                    let dst = out.add(row + at);
                    let mut p = _mm512_add_ps(p, vb);
                    match act {
                        Activation::None => {}
                        Activation::Relu => p = _mm512_max_ps(p, zero),
                        Activation::Tanh => {
                            // No vector tanh: finish these lanes one by one.
                            _mm512_mask_storeu_ps(dst, mask, p);
                            for e in 0..(n - at).min(16) {
                                let o = &mut *dst.add(e);
                                *o = match residual {
                                    Some(r) => act.apply_one(*o) + r[row + at + e],
                                    None => act.apply_one(*o),
                                };
                            }
                            continue;
                        }
                    }
                    if let Some(r) = residual {
                        let rp = r[row..].as_ptr().add(at);
                        p = _mm512_add_ps(p, _mm512_maskz_loadu_ps(mask, rp));
                    }
                    _mm512_mask_storeu_ps(dst, mask, p);
                }
                k += 16;
            }
        }
    }
}

/// `G x` for one column `(x0, x1, x2)` of taps, as [`super::g3`] (same
/// operations in the same order, so the same bits).
#[inline(always)]
unsafe fn g3(x0: __m512, x1: __m512, x2: __m512) -> [__m512; 6] {
    let k = |v: f32| _mm512_set1_ps(v);
    let (a, b) = (_mm512_add_ps(x0, x2), x1);
    let c = _mm512_add_ps(
        _mm512_mul_ps(x0, k(1.0 / 24.0)),
        _mm512_mul_ps(x2, k(1.0 / 6.0)),
    );
    // −(s)·(1/6) is s·(−1/6) bit for bit: rounding is symmetric in sign.
    [
        _mm512_mul_ps(x0, k(0.25)),
        _mm512_mul_ps(_mm512_add_ps(a, b), k(-(1.0 / 6.0))),
        _mm512_mul_ps(_mm512_sub_ps(a, b), k(-(1.0 / 6.0))),
        _mm512_add_ps(c, _mm512_mul_ps(b, k(1.0 / 12.0))),
        _mm512_sub_ps(c, _mm512_mul_ps(b, k(1.0 / 12.0))),
        x2,
    ]
}

/// Rows `R0..R1` of the weight transform `G g Gᵀ`, as
/// [`super::transform_lanes`]: `g[k]` holds tap `k` of many kernels (all of
/// one length), `u[((i − R0)·6 + j)·stride ..]` gets point `6i + j` of each,
/// 16 lanes per register with a masked tail.
///
/// # Safety
/// The CPU has AVX-512F; `u` holds `((R1 − R0)·6 − 1)·stride + len` floats.
#[target_feature(enable = "avx512f,avx2,fma")]
pub(super) unsafe fn weights<const R0: usize, const R1: usize>(
    g: [&[f32]; 9],
    u: &mut [f32],
    stride: usize,
) {
    let len = g[0].len();
    assert!(g.iter().all(|t| t.len() == len), "taps of unequal length");
    assert!(
        len == 0 || u.len() >= ((R1 - R0) * T - 1) * stride + len,
        "weight transform output too short"
    );
    let up = u.as_mut_ptr();
    let mut l0 = 0;
    while l0 < len {
        let n = (len - l0).min(16);
        let mask: __mmask16 = if n == 16 { !0 } else { (1u16 << n) - 1 };
        let x: [__m512; 9] =
            std::array::from_fn(|k| _mm512_maskz_loadu_ps(mask, g[k].as_ptr().add(l0)));
        // Columns: G along the kernel rows (taps c, c+3, c+6).
        let cols = [
            g3(x[0], x[3], x[6]),
            g3(x[1], x[4], x[7]),
            g3(x[2], x[5], x[8]),
        ];
        // `i` picks the same point of the three columns and places the row.
        #[allow(clippy::needless_range_loop)]
        for i in R0..R1 {
            let r = g3(cols[0][i], cols[1][i], cols[2][i]);
            for (j, rj) in r.iter().enumerate() {
                // SAFETY: below `((R1 − R0)·6 − 1)·stride + len` (checked).
                _mm512_mask_storeu_ps(up.add(((i - R0) * T + j) * stride + l0), mask, *rj);
            }
        }
        l0 += n;
    }
}
