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
    const MR: usize = AVX512_MR;
    let mut acc = [[_mm512_setzero_ps(); 3]; MR];
    let mut a = a;
    let mut b = b;
    for _ in 0..kc {
        let b0 = _mm512_loadu_ps(b);
        let b1 = _mm512_loadu_ps(b.add(16));
        let b2 = _mm512_loadu_ps(b.add(32));
        for (r, row) in acc.iter_mut().enumerate() {
            let ar = _mm512_set1_ps(*a.add(r));
            row[0] = _mm512_fmadd_ps(ar, b0, row[0]);
            row[1] = _mm512_fmadd_ps(ar, b1, row[1]);
            row[2] = _mm512_fmadd_ps(ar, b2, row[2]);
        }
        a = a.add(MR);
        b = b.add(AVX512_NR);
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
    const MR: usize = AVX2_MR;
    let mut acc = [[_mm256_setzero_ps(); 2]; MR];
    let mut a = a;
    let mut b = b;
    for _ in 0..kc {
        let b0 = _mm256_loadu_ps(b);
        let b1 = _mm256_loadu_ps(b.add(8));
        for (r, row) in acc.iter_mut().enumerate() {
            let ar = _mm256_broadcast_ss(&*a.add(r));
            row[0] = _mm256_fmadd_ps(ar, b0, row[0]);
            row[1] = _mm256_fmadd_ps(ar, b1, row[1]);
        }
        a = a.add(MR);
        b = b.add(AVX2_NR);
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
    const MR: usize = AVX512_MR;
    let mut acc = [[_mm512_setzero_ps(); 3]; MR];
    let mut a = a;
    for k in 0..kc {
        let bk = b.add(*offs.add(k));
        let b0 = _mm512_loadu_ps(bk);
        let b1 = _mm512_loadu_ps(bk.add(16));
        let b2 = _mm512_loadu_ps(bk.add(32));
        for (r, row) in acc.iter_mut().enumerate() {
            let ar = _mm512_set1_ps(*a.add(r));
            row[0] = _mm512_fmadd_ps(ar, b0, row[0]);
            row[1] = _mm512_fmadd_ps(ar, b1, row[1]);
            row[2] = _mm512_fmadd_ps(ar, b2, row[2]);
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
    const MR: usize = AVX2_MR;
    let mut acc = [[_mm256_setzero_ps(); 2]; MR];
    let mut a = a;
    for k in 0..kc {
        let bk = b.add(*offs.add(k));
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
    const MR: usize = AVX512_MR;
    let mut acc = [[_mm512_setzero_ps(); NV]; MR];
    let mut a = a;
    let mut b = b;
    for _ in 0..kc {
        let bv: [__m512; NV] = std::array::from_fn(|j| _mm512_loadu_ps(b.add(16 * j)));
        for (r, row) in acc.iter_mut().enumerate() {
            let ar = _mm512_set1_ps(*a.add(r));
            for j in 0..NV {
                row[j] = _mm512_fmadd_ps(ar, bv[j], row[j]);
            }
        }
        a = a.add(MR);
        b = b.add(ldb);
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
