//! x86-64 micro-kernels (AVX-512F and AVX2+FMA), selected at runtime.

use std::arch::x86_64::*;

/// Rows of the AVX-512 tile.
pub(crate) const AVX512_MR: usize = 8;
/// Columns of the AVX-512 tile (three zmm registers).
pub(crate) const AVX512_NR: usize = 48;
/// Rows of the AVX2 tile.
pub(crate) const AVX2_MR: usize = 6;
/// Columns of the AVX2 tile (two ymm registers).
pub(crate) const AVX2_NR: usize = 16;

/// The AVX-512 tile `C[8 × 16·NV] (+)= A · B`: row `k` of B is the `16·NV`
/// floats at `b_row(k)`. Every AVX-512 kernel is this loop with its own way
/// of finding B rows (packed panel, rows in place, narrow panel).
///
/// # Safety
/// As [`super::KernelFn`], with `b_row(k)` valid for `16·NV` floats for every
/// `k < kc`; only called from functions with AVX-512F enabled.
#[inline(always)]
unsafe fn avx512_tile<const NV: usize>(
    kc: usize,
    a: *const f32,
    b_row: impl Fn(usize) -> *const f32,
    c: *mut f32,
    ldc: usize,
    accumulate: bool,
) {
    const MR: usize = AVX512_MR;
    let mut acc = [[_mm512_setzero_ps(); NV]; MR];
    let mut a = a;
    for k in 0..kc {
        let bk = b_row(k);
        let bv: [__m512; NV] = std::array::from_fn(|j| _mm512_loadu_ps(bk.add(16 * j)));
        for (r, row) in acc.iter_mut().enumerate() {
            let ar = _mm512_set1_ps(*a.add(r));
            for j in 0..NV {
                row[j] = _mm512_fmadd_ps(ar, bv[j], row[j]);
            }
        }
        a = a.add(MR);
    }
    for (r, row) in acc.iter().enumerate() {
        let p = c.add(r * ldc);
        for (j, v) in row.iter().enumerate() {
            let q = p.add(16 * j);
            let v = if accumulate {
                _mm512_add_ps(*v, _mm512_loadu_ps(q))
            } else {
                *v
            };
            _mm512_storeu_ps(q, v);
        }
    }
}

/// The AVX2 tile `C[6×16] (+)= A · B` (12 ymm accumulators): row `k` of B is
/// the 16 floats at `b_row(k)`.
///
/// # Safety
/// As [`super::KernelFn`], with `b_row(k)` valid for 16 floats for every
/// `k < kc`; only called from functions with AVX2 and FMA enabled.
#[inline(always)]
unsafe fn avx2_tile(
    kc: usize,
    a: *const f32,
    b_row: impl Fn(usize) -> *const f32,
    c: *mut f32,
    ldc: usize,
    accumulate: bool,
) {
    const MR: usize = AVX2_MR;
    let mut acc = [[_mm256_setzero_ps(); 2]; MR];
    let mut a = a;
    for k in 0..kc {
        let bk = b_row(k);
        let b0 = _mm256_loadu_ps(bk);
        let b1 = _mm256_loadu_ps(bk.add(8));
        for (r, row) in acc.iter_mut().enumerate() {
            let ar = _mm256_broadcast_ss(&*a.add(r));
            row[0] = _mm256_fmadd_ps(ar, b0, row[0]);
            row[1] = _mm256_fmadd_ps(ar, b1, row[1]);
        }
        a = a.add(MR);
    }
    for (r, row) in acc.iter().enumerate() {
        let p = c.add(r * ldc);
        for (j, v) in row.iter().enumerate() {
            let q = p.add(8 * j);
            let v = if accumulate {
                _mm256_add_ps(*v, _mm256_loadu_ps(q))
            } else {
                *v
            };
            _mm256_storeu_ps(q, v);
        }
    }
}

/// `C[8×48] (+)= A · B` with 24 zmm accumulators; see [`super::KernelFn`].
///
/// # Safety
/// As [`super::KernelFn`]; the CPU must have AVX-512F.
#[target_feature(enable = "avx512f")]
pub(crate) unsafe fn avx512_sgemm_8x48(
    kc: usize,
    a: *const f32,
    b: *const f32,
    c: *mut f32,
    ldc: usize,
    accumulate: bool,
) {
    avx512_tile::<3>(kc, a, |k| b.add(k * AVX512_NR), c, ldc, accumulate)
}

/// `C[6×16] (+)= A · B` with 12 ymm accumulators; see [`super::KernelFn`].
///
/// # Safety
/// As [`super::KernelFn`]; the CPU must have AVX2 and FMA.
#[target_feature(enable = "avx2,fma")]
pub(crate) unsafe fn avx2_sgemm_6x16(
    kc: usize,
    a: *const f32,
    b: *const f32,
    c: *mut f32,
    ldc: usize,
    accumulate: bool,
) {
    avx2_tile(kc, a, |k| b.add(k * AVX2_NR), c, ldc, accumulate)
}

/// As [`avx512_sgemm_8x48`], with row `k` of B read in place at
/// `b.add(offs[k])` (48 floats) instead of from a packed panel; see
/// [`super::RowsKernelFn`].
///
/// # Safety
/// As [`super::RowsKernelFn`]; the CPU must have AVX-512F.
#[target_feature(enable = "avx512f")]
pub(crate) unsafe fn avx512_sgemm_rows_8x48(
    kc: usize,
    a: *const f32,
    b: *const f32,
    offs: *const usize,
    c: *mut f32,
    ldc: usize,
    accumulate: bool,
) {
    avx512_tile::<3>(kc, a, |k| b.add(*offs.add(k)), c, ldc, accumulate)
}

/// As [`avx2_sgemm_6x16`], with row `k` of B read in place at `b.add(offs[k])`
/// (16 floats); see [`super::RowsKernelFn`].
///
/// # Safety
/// As [`super::RowsKernelFn`]; the CPU must have AVX2 and FMA.
#[target_feature(enable = "avx2,fma")]
pub(crate) unsafe fn avx2_sgemm_rows_6x16(
    kc: usize,
    a: *const f32,
    b: *const f32,
    offs: *const usize,
    c: *mut f32,
    ldc: usize,
    accumulate: bool,
) {
    avx2_tile(kc, a, |k| b.add(*offs.add(k)), c, ldc, accumulate)
}

/// `C[8 × 16·NV] (+)= A · B` for the narrow last panel of a product: B rows
/// are `ldb` floats apart (a packed 48-wide panel whose columns past `16·NV`
/// are not needed), `NV` ∈ 1..=3 zmm columns; see [`super::NarrowKernelFn`].
///
/// # Safety
/// As [`super::NarrowKernelFn`]; the CPU must have AVX-512F.
#[target_feature(enable = "avx512f")]
unsafe fn avx512_sgemm_8xnv<const NV: usize>(
    kc: usize,
    a: *const f32,
    b: *const f32,
    ldb: usize,
    c: *mut f32,
    ldc: usize,
    accumulate: bool,
) {
    avx512_tile::<NV>(kc, a, |k| b.add(k * ldb), c, ldc, accumulate)
}
/// [`avx512_sgemm_8xnv`] for `16·nv` columns, `nv` ∈ 1..=3.
///
/// # Safety
/// As [`super::NarrowKernelFn`]; the CPU must have AVX-512F.
#[allow(clippy::too_many_arguments)] // the kernel ABI: shape, operands, strides
pub(crate) unsafe fn avx512_sgemm_narrow_8x16n(
    nv: usize,
    kc: usize,
    a: *const f32,
    b: *const f32,
    ldb: usize,
    c: *mut f32,
    ldc: usize,
    accumulate: bool,
) {
    match nv {
        1 => avx512_sgemm_8xnv::<1>(kc, a, b, ldb, c, ldc, accumulate),
        2 => avx512_sgemm_8xnv::<2>(kc, a, b, ldb, c, ldc, accumulate),
        _ => avx512_sgemm_8xnv::<3>(kc, a, b, ldb, c, ldc, accumulate),
    }
}
