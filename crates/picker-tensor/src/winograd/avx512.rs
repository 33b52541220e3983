//! AVX-512 tile transforms of the Winograd convolutions (both tile sizes,
//! `T × T` points for `M × M` outputs), written with intrinsics: the generic
//! transforms (`super::input_channel_body`, `super::output_panel_body`) spend
//! most of their time splitting rows into column phases and back one float at
//! a time; here those are permutes per 16 tiles, and
//! each pass reads its rows where they lie.
//!
//! **Input** (one channel, one block of tiles), per run of tiles in one tile
//! row: `Bᵀ` first runs down the `T` source rows of the band (contiguous
//! loads straight from the image; padding rows are a zero row or the
//! reflected row, padding columns are computed from their source column),
//! giving `T` rows `z_i`; for 16 tiles at once, the `T` columns of each tile
//! (`z_i[M·k + c]`) are taken from `z_i` (F4: its four column phases by
//! `vpermt2ps`; F6: its six phases by three `vpermt2ps` each; the stride-2
//! tiles' eight phases by three stages of swaps, their ten by an even/odd
//! split and then five phases of each), and `Bᵀ` along the columns writes
//! `V[T·i + j]`. On maps of at most 8 tiles a row (the EnvMap's 30×40
//! blocks in F(5×5)) two runs share one vector: the second run's tiles are
//! moved up behind the first's (`vpermps`) before the column pass, so each
//! point is one transform and one store rather than two half ones (`tune
//! envres`, 2-core Zen 4, 12 alternating rounds: 0.85× the time).
//!
//! **Output** (one output channel, one panel): `Aᵀ` over the rows and then
//! the columns of the `T²` products, 16 tiles per register; the `M` columns
//! of each tile row are interleaved back into pixels (permutes; three per 16
//! pixels for F6), and bias, activation and residual are
//! applied on whole vectors before a masked store.
//!
//! The matrices are `super::points`' (the same operations as the generic
//! transforms), with the input passes in the other order (rows first), so
//! results agree with them to rounding.

use std::arch::x86_64::*;

use super::points::{Arith, Points};
use super::{segments, Geometry, OutPlane, VRows};
use crate::activation::Activation;
use crate::pad::padded_source;

/// 16 lanes for [`Arith`]: the tile matrices of [`Points`] run on vectors
/// with the same operations as on single floats.
#[derive(Clone, Copy)]
struct Z(__m512);

// SAFETY (of every `unsafe` block below): a `Z` is only made inside this
// module's `#[target_feature(enable = "avx512f")]` functions, which run only
// on CPUs with AVX-512F.
impl Arith for Z {
    #[inline(always)]
    fn add(self, o: Self) -> Self {
        Z(unsafe { _mm512_add_ps(self.0, o.0) })
    }
    #[inline(always)]
    fn sub(self, o: Self) -> Self {
        Z(unsafe { _mm512_sub_ps(self.0, o.0) })
    }
    #[inline(always)]
    fn mul(self, k: f32) -> Self {
        Z(unsafe { _mm512_mul_ps(self.0, _mm512_set1_ps(k)) })
    }
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

/// The F6 permute tables: for each of six result vectors, per pair of
/// source vectors `(2p, 2p + 1)`, the `vpermt2ps` index of every lane and
/// the mask of the lanes that pair supplies (the three masks partition the
/// lanes).
struct PairTables {
    idx: [[[i32; 16]; 3]; 6],
    mask: [[u16; 3]; 6],
}

/// The tables that make result vector `r`, lane `e`, from source vector
/// `v`, lane `l` (`source(r, e) = (v, l)`): pair `v / 2`, index
/// `l + 16·(v mod 2)`.
const fn pair_tables(join: bool, m: usize) -> PairTables {
    let mut t = PairTables {
        idx: [[[0; 16]; 3]; 6],
        mask: [[0; 3]; 6],
    };
    let mut r = 0;
    while r < m {
        let mut e = 0;
        while e < 16 {
            let (v, l) = if join {
                // Pixel f = 16r + e is column f mod m of tile f / m.
                let f = 16 * r + e;
                (f % m, f / m)
            } else {
                // Phase r of tile e is float m·e + r of the 16·m.
                let f = m * e + r;
                (f / 16, f % 16)
            };
            t.idx[r][v / 2][e] = (l + 16 * (v % 2)) as i32;
            t.mask[r][v / 2] |= 1 << e;
            e += 1;
        }
        r += 1;
    }
    t
}

/// Phase split, 16 tiles of 6 columns (96 floats in six vectors): phase `c`,
/// lane `k` is float `6k + c`.
const F6_SPLIT: PairTables = pair_tables(false, 6);

/// Interleave, the inverse: pixel `f = 16s + e` of 16 tiles is column
/// `f mod 6` (source vector `f mod 6`) of tile `f / 6`.
const F6_JOIN: PairTables = pair_tables(true, 6);

/// [`F6_SPLIT`] for 16 tiles of 5 columns (80 floats in five vectors; the
/// third pair is the fifth vector twice).
const F5_SPLIT: PairTables = pair_tables(false, 5);

/// [`F6_JOIN`] for five columns.
const F5_JOIN: PairTables = pair_tables(true, 5);

/// Result vector `r` of `t` from the six vectors `z`: three two-source
/// permutes blended by their masks.
#[inline(always)]
unsafe fn pair_permute(t: &PairTables, r: usize, z: &[__m512; 6]) -> __m512 {
    let idx = |p: usize| _mm512_loadu_si512(t.idx[r][p].as_ptr().cast());
    let a = _mm512_permutex2var_ps(z[0], idx(0), z[1]);
    let b = _mm512_permutex2var_ps(z[2], idx(1), z[3]);
    let c = _mm512_permutex2var_ps(z[4], idx(2), z[5]);
    let ab = _mm512_mask_mov_ps(a, t.mask[r][1], b);
    _mm512_mask_mov_ps(ab, t.mask[r][2], c)
}

/// The six column phases of 16 tiles: `q_c[t] = z[6t + c]` for the 96
/// floats at `p`, by permutes (a gather per phase was slower).
#[inline(always)]
unsafe fn phases6(p: *const f32) -> [__m512; 6] {
    let z: [__m512; 6] = std::array::from_fn(|v| _mm512_loadu_ps(p.add(16 * v)));
    std::array::from_fn(|c| pair_permute(&F6_SPLIT, c, &z))
}

/// The five column phases of 16 tiles: `q_c[t] = z[5t + c]` for the 80
/// floats at `p` (only those are read).
#[inline(always)]
unsafe fn phases5(p: *const f32) -> [__m512; 5] {
    let z: [__m512; 6] = std::array::from_fn(|v| _mm512_loadu_ps(p.add(16 * v.min(4))));
    std::array::from_fn(|c| pair_permute(&F5_SPLIT, c, &z))
}

/// Index tables of the three stages of [`phases8`]: per stage, for output
/// vectors whose stage bit is 0 and 1, the `vpermt2ps` index of every lane.
///
/// 128 floats `f = 16·v + l` (vector `v`, lane `l`) are `f = 8·t + c` (tile
/// `t`, phase `c`); phase `c` of tile `t` must end in vector `c`, lane `t`.
/// Stage `k` (0, 1, 2) swaps bit `k` of the vector index with bit `k` of
/// the lane: an output vector `v'` draws from the pair `v' & !(1 << k)`,
/// `v' | (1 << k)`, lane `l'` from lane `l'` with bit `k` set to bit `k` of
/// `v'`, of the pair's vector given by bit `k` of `l'`. After the three
/// swaps lane bits 3..0 hold `t₀ t₃ t₂ t₁`; the last stage's table also puts
/// the lanes in tile order.
const fn phase8_tables() -> [[[i32; 16]; 2]; 3] {
    let mut t = [[[0i32; 16]; 2]; 3];
    let mut k = 0;
    while k < 3 {
        let mut vb = 0;
        while vb < 2 {
            let mut lo = 0;
            while lo < 16 {
                // Lane `lo` of the output; in the last stage it takes what the
                // swap alone would leave at lane `(t₀ t₃ t₂ t₁)` for tile `lo`.
                let lp = if k == 2 {
                    ((lo & 1) << 3) | (lo >> 1)
                } else {
                    lo
                };
                let l = (lp & !(1 << k)) | (vb << k);
                let src = (lp >> k) & 1;
                t[k][vb][lo] = (l + 16 * src) as i32;
                lo += 1;
            }
            vb += 1;
        }
        k += 1;
    }
    t
}

/// See [`phase8_tables`].
const PHASE8: [[[i32; 16]; 2]; 3] = phase8_tables();

/// The eight column phases of 16 tiles: `q_c[t] = z[8t + c]` for the 128
/// floats at `p`, by three stages of eight two-source permutes.
#[inline(always)]
unsafe fn phases8(p: *const f32) -> [__m512; 8] {
    let mut z: [__m512; 8] = std::array::from_fn(|v| _mm512_loadu_ps(p.add(16 * v)));
    for (k, tables) in PHASE8.iter().enumerate() {
        let idx = tables.map(|t| _mm512_loadu_si512(t.as_ptr().cast()));
        z = std::array::from_fn(|v| {
            let vb = (v >> k) & 1;
            let (a, b) = (z[v & !(1 << k)], z[v | (1 << k)]);
            _mm512_permutex2var_ps(a, idx[vb], b)
        });
    }
    z
}

/// The ten column phases of 16 tiles: `q_c[t] = z[10t + c]` for the 160
/// floats at `p` (S5's tiles, 10 columns apart): the even and odd floats
/// first (one two-source permute per output vector each: 80 floats of each
/// parity, tile `t`'s at `5t..5t + 5`), then each parity's five phases by
/// the permutes of [`phases5`]; phase `2j` is the even floats' phase `j`,
/// `2j + 1` the odd ones'.
#[inline(always)]
unsafe fn phases10(p: *const f32) -> [__m512; 10] {
    let even = _mm512_setr_epi32(0, 2, 4, 6, 8, 10, 12, 14, 16, 18, 20, 22, 24, 26, 28, 30);
    let odd = _mm512_setr_epi32(1, 3, 5, 7, 9, 11, 13, 15, 17, 19, 21, 23, 25, 27, 29, 31);
    // Each parity's five vectors, the fifth twice (`F5_SPLIT`'s third pair).
    // (Loops, not closures: a closure does not inherit the target features,
    // and the intrinsics it calls were left as calls.)
    let mut e = [_mm512_setzero_ps(); 6];
    let mut o = [_mm512_setzero_ps(); 6];
    for k in 0..5 {
        let (a, b) = (
            _mm512_loadu_ps(p.add(32 * k)),
            _mm512_loadu_ps(p.add(32 * k + 16)),
        );
        e[k] = _mm512_permutex2var_ps(a, even, b);
        o[k] = _mm512_permutex2var_ps(a, odd, b);
    }
    (e[5], o[5]) = (e[4], o[4]);
    let mut q = [_mm512_setzero_ps(); 10];
    for c in 0..5 {
        q[2 * c] = pair_permute(&F5_SPLIT, c, &e);
        q[2 * c + 1] = pair_permute(&F5_SPLIT, c, &o);
    }
    q
}

/// Lanes `1..16` of `a` followed by lane 0 of `b`.
#[inline(always)]
unsafe fn next_lane(a: __m512, b: __m512) -> __m512 {
    _mm512_castsi512_ps(_mm512_alignr_epi32::<1>(
        _mm512_castps_si512(b),
        _mm512_castps_si512(a),
    ))
}

/// The `S` column phases of 16 tiles `S` floats apart at `p` (`S` = 4, 5,
/// 6, 8 or 10: [`phases`], [`phases5`], [`phases6`], [`phases8`],
/// [`phases10`]).
#[inline(always)]
unsafe fn split<const S: usize>(p: *const f32) -> [__m512; S] {
    let mut q = [_mm512_setzero_ps(); S];
    match S {
        4 => q.copy_from_slice(&phases(p)),
        5 => q.copy_from_slice(&phases5(p)),
        6 => q.copy_from_slice(&phases6(p)),
        8 => q.copy_from_slice(&phases8(p)),
        10 => q.copy_from_slice(&phases10(p)),
        _ => unreachable!("no phase split for {S} columns"),
    }
    q
}

/// The column pass of one transformed row `z` (see [`input`]) over a run of
/// `len` tiles `S` columns apart: `Bᵀ` of each tile's `T` columns, the tiles
/// in the lanes, point `j` of tiles `k..k + 16` stored at `v[at(j) + k..]`
/// (masked to the run).
///
/// # Safety
/// As [`input`]: `z` readable for `S · 16` floats past the run's last group
/// of 16 tiles, `v[at(j)..]` writable for the run's lanes.
#[inline(always)]
unsafe fn column_pass<const T: usize, const M: usize, W: Points<T, M>, const S: usize>(
    z: *const f32,
    len: usize,
    v: *mut f32,
    at: impl Fn(usize) -> usize,
) {
    let mut cur = split::<S>(z);
    let mut k = 0;
    while k < len {
        let mask = first(len - k);
        let next = split::<S>(z.add(S * (k + 16)));
        let d = tile_columns::<T, S>(&cur, &next);
        for (j, oj) in W::bt(d).iter().enumerate() {
            _mm512_mask_storeu_ps(v.add(at(j) + k), mask, oj.0);
        }
        cur = next;
        k += 16;
    }
}

/// The `T` columns of 16 tiles `S` apart (tile `k`'s column `c` in lane
/// `k`) from the `S` column phases of those tiles (`cur`) and of the next
/// 16 (`next`): tile `k` reads phases `0..S` at `k` and the first `T − S`
/// at `k + 1`.
///
/// # Safety
/// Only called from AVX-512F functions.
#[inline(always)]
unsafe fn tile_columns<const T: usize, const S: usize>(
    cur: &[__m512; S],
    next: &[__m512; S],
) -> [Z; T] {
    let mut d = [Z(_mm512_setzero_ps()); T];
    for (c, dc) in d.iter_mut().enumerate() {
        *dc = Z(if c < S {
            cur[c]
        } else {
            next_lane(cur[c - S], next[c - S])
        });
    }
    d
}

/// The `T` columns of the first 16 tiles of a run at `z`, as [`column_pass`]
/// takes them. (A function, not a closure: closures do not inherit the
/// caller's target features.)
///
/// # Safety
/// As [`column_pass`]; only called from AVX-512F functions.
#[inline(always)]
unsafe fn first_tiles<const T: usize, const S: usize>(z: *const f32) -> [Z; T] {
    tile_columns::<T, S>(&split::<S>(z), &split::<S>(z.add(S * 16)))
}

/// [`column_pass`] for two runs of `la` and `lb` tiles (`la + lb ≤ 16`)
/// whose lanes follow each other (tile rows of a narrow map): run `b`'s
/// tiles are moved up to lanes `la..la + lb` of run `a`'s before `Bᵀ`, so
/// each point is one transform and one store instead of two half ones (the
/// same operations per lane, so the same bits).
///
/// # Safety
/// As [`column_pass`] for each run.
#[inline(always)]
unsafe fn column_pass_pair<const T: usize, const M: usize, W: Points<T, M>, const S: usize>(
    za: *const f32,
    la: usize,
    zb: *const f32,
    lb: usize,
    v: *mut f32,
    at: impl Fn(usize) -> usize,
) {
    debug_assert!(la > 0 && lb > 0 && la + lb <= 16);
    let (a, b) = (first_tiles::<T, S>(za), first_tiles::<T, S>(zb));
    // Lane l ≥ la takes lane l − la of b (the index's low four bits).
    let idx = _mm512_sub_epi32(
        _mm512_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15),
        _mm512_set1_epi32(la as i32),
    );
    let upper = !first(la);
    let mut d = [Z(_mm512_setzero_ps()); T];
    for (c, dc) in d.iter_mut().enumerate() {
        *dc = Z(_mm512_mask_permutexvar_ps(a[c].0, upper, idx, b[c].0));
    }
    let mask = first(la + lb);
    for (j, oj) in W::bt(d).iter().enumerate() {
        _mm512_mask_storeu_ps(v.add(at(j)), mask, oj.0);
    }
}

/// Input transform of channel `ci` over the tiles `[t0, t1)`; see
/// `super::input_channel_body` for the contract.
///
/// # Safety
/// The CPU has AVX-512F; `v` and `rows` as for the generic transform.
#[target_feature(enable = "avx512f,avx2,fma")]
#[allow(clippy::too_many_arguments)]
pub(super) unsafe fn input<const T: usize, const M: usize, W: Points<T, M>>(
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
    // Tile k starts at padded column step·k.
    let step = M * W::STRIDE;
    // A run has at most `tw` tiles; the column pass reads whole groups of
    // 16 tiles (`16·step` floats), and one group past the run.
    let groups = tw.div_ceil(16) + 1;
    let zs = 16 * step * groups;
    // Two runs' rows: short runs (maps of at most 8 tiles a row) go two to
    // a vector in the column pass.
    scratch.resize(2 * T * zs + w, 0.0);
    let (z, zero_row) = scratch.split_at_mut(2 * T * zs);
    zero_row.fill(0.0);
    let (z, zero_row) = (z.as_mut_ptr(), zero_row.as_ptr());
    let mut segs = Vec::with_capacity(4);
    let mut p0 = t0;
    let mut panel = 0;
    while p0 < t1 {
        let p1 = (p0 + nr).min(t1);
        segments(p0, p1, tw, &mut segs);
        let mut si = 0;
        while si < segs.len() {
            // This run, and the next when the two fill at most one vector.
            let pair = segs
                .get(si + 1)
                .filter(|b| segs[si].3 + b.3 <= 16)
                .is_some();
            let runs = if pair { 2 } else { 1 };
            for (n, &(_, ty, tx0, len)) in segs[si..si + runs].iter().enumerate() {
                let z = z.add(n * T * zs);
                let src: [*const f32; T] =
                    std::array::from_fn(|r| match g.row_map[step * ty + r] {
                        Some(sy) => plane.add(sy * w),
                        None => zero_row,
                    });
                // z_i[x] = Σ_r Bᵀ[i][r] padded[step·ty + r][step·tx0 + x], x < nx.
                let nx = step * (len - 1) + T;
                let qb = step * tx0;
                let xa = pad.saturating_sub(qb).min(nx);
                let xb = (pad + w).saturating_sub(qb).min(nx).max(xa);
                let mut x = xa;
                while x < xb {
                    let mask = first(xb - x);
                    let c = qb + x - pad;
                    let d: [Z; T] =
                        std::array::from_fn(|r| Z(_mm512_maskz_loadu_ps(mask, src[r].add(c))));
                    for (i, oi) in W::bt(d).iter().enumerate() {
                        _mm512_mask_storeu_ps(z.add(i * zs + x), mask, oi.0);
                    }
                    x += 16;
                }
                for x in (0..xa).chain(xb..nx) {
                    let o = match padded_source(qb + x, pad, w, w + 2 * pad, g.fill) {
                        Some(c) => W::bt(std::array::from_fn(|r| *src[r].add(c))),
                        None => [0.0; T],
                    };
                    for (i, oi) in o.iter().enumerate() {
                        *z.add(i * zs + x) = *oi;
                    }
                }
            }
            // The column pass reads whole groups of 16 tiles, one past the
            // run: past `nx` it reads what earlier rows or calls left in `z`
            // (the scratch is kept per thread), only ever into lanes of tiles past
            // the run, which are not stored (tile `k < len` reads
            // `z[step·k + c] ≤ z[step·(len − 1) + T − 1]`, below `nx`).
            // Zeroing that tail here was 5% of a 60×80 F(6×6) layer (one
            // `memset` per row).
            // V[T·i + j] = Σ_c Bᵀ[j][c] z_i[step·k + c] for the run's tiles k.
            let (l0, len) = (segs[si].0, segs[si].3);
            for i in 0..T {
                let zi = z.add(i * zs);
                // Tile k reads phases 0..step at k and the first T − step
                // (one or two) at k + 1.
                let at = |j: usize| rows.at(i * T + j, panel) + l0;
                if pair {
                    let (zb, lb) = (zi.add(T * zs), segs[si + 1].3);
                    match step {
                        4 => column_pass_pair::<T, M, W, 4>(zi, len, zb, lb, v, at),
                        5 => column_pass_pair::<T, M, W, 5>(zi, len, zb, lb, v, at),
                        6 => column_pass_pair::<T, M, W, 6>(zi, len, zb, lb, v, at),
                        8 => column_pass_pair::<T, M, W, 8>(zi, len, zb, lb, v, at),
                        10 => column_pass_pair::<T, M, W, 10>(zi, len, zb, lb, v, at),
                        _ => unreachable!("no phase split for a step of {step}"),
                    }
                    continue;
                }
                match step {
                    4 => column_pass::<T, M, W, 4>(zi, len, v, at),
                    5 => column_pass::<T, M, W, 5>(zi, len, v, at),
                    6 => column_pass::<T, M, W, 6>(zi, len, v, at),
                    8 => column_pass::<T, M, W, 8>(zi, len, v, at),
                    10 => column_pass::<T, M, W, 10>(zi, len, v, at),
                    _ => unreachable!("no phase split for a step of {step}"),
                }
            }
            si += runs;
        }
        // A partial panel's missing tiles are zero columns of B.
        let used = p1 - p0;
        if used < nr {
            for xi in 0..T * T {
                std::ptr::write_bytes(v.add(rows.at(xi, panel) + used), 0, nr - used);
            }
        }
        p0 = p1;
        panel += 1;
    }
}

/// Output transform of one output channel over one panel; see
/// `super::output_panel_body` for the contract (`scratch` holds at least
/// `M²·nr + 16` floats).
///
/// # Safety
/// The CPU has AVX-512F; `nr` is a multiple of 16; `m` holds the `T²`
/// products at `ξ·stride` (`nr` floats each).
#[target_feature(enable = "avx512f,avx2,fma")]
pub(super) unsafe fn output<const T: usize, const M: usize, W: Points<T, M>>(
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
    debug_assert!(m.len() >= (T * T - 1) * stride + nr);
    let y = scratch.as_mut_ptr();
    let mp = m.as_ptr();
    // y[(i·M + j)·nr + lane] = Σ_c Aᵀ[j][c] Σ_r Aᵀ[i][r] M[T·r + c][lane]
    // Plain loops over fixed-size arrays: closures here were not inlined.
    let z = Z(_mm512_setzero_ps());
    // The next output channel's products lie `nr` floats on in each of the
    // `T²` rows, which are `stride` apart: too many streams for the
    // hardware prefetcher, so they are fetched here (a prefetch never
    // faults; past the last channel it is wasted).
    for xi in 0..T * T {
        let next = mp.wrapping_add(xi * stride + nr);
        for l in (0..nr).step_by(16) {
            _mm_prefetch::<_MM_HINT_T0>(next.wrapping_add(l).cast());
        }
    }
    for l in (0..nr).step_by(16) {
        let mut t1 = [[z; M]; T];
        for (c, t1c) in t1.iter_mut().enumerate() {
            let mut s = [z; T];
            for (r, sr) in s.iter_mut().enumerate() {
                *sr = Z(_mm512_loadu_ps(mp.add((T * r + c) * stride + l)));
            }
            *t1c = W::at(s);
        }
        #[allow(clippy::needless_range_loop)] // i indexes the inner arrays of t1
        for i in 0..M {
            let mut s = [z; T];
            for (c, sc) in s.iter_mut().enumerate() {
                *sc = t1[c][i];
            }
            for (j, oj) in W::at(s).iter().enumerate() {
                _mm512_storeu_ps(y.add((i * M + j) * nr + l), oj.0);
            }
        }
    }
    // F4: pixel 4t + j of a tile row comes from lane t of column j, by permutes.
    let lo = _mm512_setr_epi32(0, 8, 16, 24, 1, 9, 17, 25, 2, 10, 18, 26, 3, 11, 19, 27);
    let hi = _mm512_setr_epi32(4, 12, 20, 28, 5, 13, 21, 29, 6, 14, 22, 30, 7, 15, 23, 31);
    // F6: pixel 16s + e of 16 tiles by permutes of the six columns (`F6_JOIN`).
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
                let yrow = y.add(i * M * nr + l0 + k);
                let mut px = [zero; M];
                if M == 4 {
                    let yl = |j: usize| _mm512_loadu_ps(yrow.add(j * nr));
                    let (y0, y1, y2, y3) = (yl(0), yl(1), yl(2), yl(3));
                    let a01 = _mm512_shuffle_f32x4::<0x44>(y0, y1);
                    let b01 = _mm512_shuffle_f32x4::<0xee>(y0, y1);
                    let a23 = _mm512_shuffle_f32x4::<0x44>(y2, y3);
                    let b23 = _mm512_shuffle_f32x4::<0xee>(y2, y3);
                    px[0] = _mm512_permutex2var_ps(a01, lo, a23);
                    px[1] = _mm512_permutex2var_ps(a01, hi, a23);
                    px[2] = _mm512_permutex2var_ps(b01, lo, b23);
                    px[3] = _mm512_permutex2var_ps(b01, hi, b23);
                } else {
                    // The row's 16 lanes past `len` (garbage, never stored)
                    // lie inside `scratch` (its 16 spare floats). F5 has five
                    // columns: its third pair is the fifth twice.
                    let ys: [__m512; 6] =
                        std::array::from_fn(|j| _mm512_loadu_ps(yrow.add(j.min(M - 1) * nr)));
                    let join = if M == 5 { &F5_JOIN } else { &F6_JOIN };
                    for (s, p) in px.iter_mut().enumerate() {
                        if M * k + 16 * s < n {
                            *p = pair_permute(join, s, &ys);
                        }
                    }
                }
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

/// Rows `rows` of the weight transform `G g Gᵀ`, as
/// [`super::transform_lanes`] (the same operations, so the same bits):
/// `g[k]` holds tap `k` of many kernels (all of one length),
/// `u[((i − rows.start)·T + j)·stride ..]` gets point `T·i + j` of each, 16
/// lanes per register with a masked tail.
///
/// # Safety
/// The CPU has AVX-512F; `u` holds `(rows.len()·T − 1)·stride + len` floats.
#[target_feature(enable = "avx512f,avx2,fma")]
pub(super) unsafe fn weights<const T: usize, const M: usize, W: Points<T, M>>(
    g: [&[f32]; 9],
    u: &mut [f32],
    stride: usize,
    rows: std::ops::Range<usize>,
) {
    let len = g[0].len();
    assert!(g.iter().all(|t| t.len() == len), "taps of unequal length");
    assert!(
        len == 0 || rows.is_empty() || u.len() >= (rows.len() * T - 1) * stride + len,
        "weight transform output too short"
    );
    let up = u.as_mut_ptr();
    if rows.len() == 1 {
        // One row (lazy `U` made row by row): with the row a constant, only
        // its point of each column transform is computed.
        match rows.start {
            0 => return weights_row::<T, M, W, 0>(g, up, stride, len),
            1 => return weights_row::<T, M, W, 1>(g, up, stride, len),
            2 => return weights_row::<T, M, W, 2>(g, up, stride, len),
            3 => return weights_row::<T, M, W, 3>(g, up, stride, len),
            4 => return weights_row::<T, M, W, 4>(g, up, stride, len),
            5 => return weights_row::<T, M, W, 5>(g, up, stride, len),
            6 if T > 6 => return weights_row::<T, M, W, 6>(g, up, stride, len),
            7 if T > 7 => return weights_row::<T, M, W, 7>(g, up, stride, len),
            8 if T > 8 => return weights_row::<T, M, W, 8>(g, up, stride, len),
            9 if T > 9 => return weights_row::<T, M, W, 9>(g, up, stride, len),
            10 if T > 10 => return weights_row::<T, M, W, 10>(g, up, stride, len),
            _ => {}
        }
    }
    let mut l0 = 0;
    while l0 < len {
        let n = (len - l0).min(16);
        let mask: __mmask16 = if n == 16 { !0 } else { (1u16 << n) - 1 };
        let x: [Z; 9] =
            std::array::from_fn(|k| Z(_mm512_maskz_loadu_ps(mask, g[k].as_ptr().add(l0))));
        // Columns: G along the kernel rows (taps c, c+3, c+6).
        let cols = [
            W::g(x[0], x[3], x[6]),
            W::g(x[1], x[4], x[7]),
            W::g(x[2], x[5], x[8]),
        ];
        // `i` picks the same point of the three columns and places the row.
        for i in rows.clone() {
            let r = W::g(cols[0][i], cols[1][i], cols[2][i]);
            for (j, rj) in r.iter().enumerate() {
                // SAFETY: below `(rows.len()·T − 1)·stride + len` (checked).
                let at = ((i - rows.start) * T + j) * stride + l0;
                _mm512_mask_storeu_ps(up.add(at), mask, rj.0);
            }
        }
        l0 += n;
    }
}

/// Row `I` of [`weights`] (its `T` points `T·I + j` at `j·stride`): the same
/// operations for the points it keeps (the column transforms' other points
/// are never computed), so the same bits.
///
/// # Safety
/// As [`weights`], with `I < T` and `up` holding `(T − 1)·stride + len` floats.
#[inline(always)]
unsafe fn weights_row<const T: usize, const M: usize, W: Points<T, M>, const I: usize>(
    g: [&[f32]; 9],
    up: *mut f32,
    stride: usize,
    len: usize,
) {
    let mut l0 = 0;
    while l0 < len {
        let n = (len - l0).min(16);
        let mask: __mmask16 = if n == 16 { !0 } else { (1u16 << n) - 1 };
        let x: [Z; 9] =
            std::array::from_fn(|k| Z(_mm512_maskz_loadu_ps(mask, g[k].as_ptr().add(l0))));
        let col = |c: usize| W::g(x[c], x[c + 3], x[c + 6])[I];
        let r = W::g(col(0), col(1), col(2));
        for (j, rj) in r.iter().enumerate() {
            _mm512_mask_storeu_ps(up.add(j * stride + l0), mask, rj.0);
        }
        l0 += n;
    }
}
