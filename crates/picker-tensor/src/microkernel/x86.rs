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
    avx512_store(&acc, c, ldc, accumulate);
}

/// Calls the `NV` = 1, 2 or 3 (for `nv` ≥ 3) instance of a narrow kernel.
macro_rules! by_width {
    ($f:ident, $nv:expr, $($arg:expr),*) => {
        match $nv {
            1 => $f::<1>($($arg),*),
            2 => $f::<2>($($arg),*),
            _ => $f::<3>($($arg),*),
        }
    };
}

/// Writes (or, with `accumulate`, adds) an AVX-512 tile's accumulators to
/// `C`, rows `ldc` floats apart.
///
/// # Safety
/// `c` valid for `MR` rows of `16·NV` floats at stride `ldc`; only called
/// from functions with AVX-512F enabled.
#[inline(always)]
unsafe fn avx512_store<const NV: usize>(
    acc: &[[__m512; NV]; AVX512_MR],
    c: *mut f32,
    ldc: usize,
    accumulate: bool,
) {
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
    by_width!(avx512_sgemm_8xnv, nv, kc, a, b, ldb, c, ldc, accumulate)
}

/// The bf16 tile `C[8 × 16·NV] (+)= A · B` with AVX512_BF16 `vdpbf16ps`: the
/// A panel is `kp` groups of 8 pair words, row `k` of B the `16·NV` pair
/// words at `b_row(k)` (see [`crate::bf16`]); each step adds two depths, the
/// products exact and the sums in f32.
///
/// # Safety
/// As [`super::KernelFn`] with pair words for floats (`kp` pair rows);
/// only called from functions with AVX-512F and AVX512_BF16 enabled.
#[inline(always)]
unsafe fn avx512bf16_tile<const NV: usize>(
    kp: usize,
    a: *const f32,
    b_row: impl Fn(usize) -> *const f32,
    c: *mut f32,
    ldc: usize,
    accumulate: bool,
) {
    const MR: usize = AVX512_MR;
    let mut acc = [[_mm512_setzero_ps(); NV]; MR];
    let mut a = a.cast::<i32>();
    for k in 0..kp {
        let bk = b_row(k);
        let bv: [__m512bh; NV] = std::array::from_fn(|j| {
            std::mem::transmute::<__m512i, __m512bh>(_mm512_loadu_si512(bk.add(16 * j).cast()))
        });
        for (r, row) in acc.iter_mut().enumerate() {
            let ar = std::mem::transmute::<__m512i, __m512bh>(_mm512_set1_epi32(*a.add(r)));
            for j in 0..NV {
                row[j] = _mm512_dpbf16_ps(row[j], ar, bv[j]);
            }
        }
        a = a.add(MR);
    }
    avx512_store(&acc, c, ldc, accumulate);
}

/// `C[8×48] (+)= A · B` over `kp` bf16 pair rows; see [`avx512bf16_tile`].
///
/// # Safety
/// As [`super::KernelFn`] with pair words; the CPU must have AVX-512F and
/// AVX512_BF16.
#[target_feature(enable = "avx512f,avx512bf16")]
pub(crate) unsafe fn avx512bf16_gemm_8x48(
    kp: usize,
    a: *const f32,
    b: *const f32,
    c: *mut f32,
    ldc: usize,
    accumulate: bool,
) {
    avx512bf16_tile::<3>(kp, a, |k| b.add(k * AVX512_NR), c, ldc, accumulate)
}

/// # Safety
/// As [`avx512bf16_gemm_narrow_8x16n`].
#[target_feature(enable = "avx512f,avx512bf16")]
unsafe fn avx512bf16_gemm_8xnv<const NV: usize>(
    kp: usize,
    a: *const f32,
    b: *const f32,
    ldb: usize,
    c: *mut f32,
    ldc: usize,
    accumulate: bool,
) {
    avx512bf16_tile::<NV>(kp, a, |k| b.add(k * ldb), c, ldc, accumulate)
}

/// `C[8 × 16·nv] (+)= A · B` over `kp` bf16 pair rows, B rows `ldb` words
/// apart, `nv` ∈ 1..=3; see [`super::NarrowKernelFn`].
///
/// # Safety
/// As [`super::NarrowKernelFn`] with pair words; the CPU must have AVX-512F
/// and AVX512_BF16.
#[allow(clippy::too_many_arguments)] // the kernel ABI: shape, operands, strides
pub(crate) unsafe fn avx512bf16_gemm_narrow_8x16n(
    nv: usize,
    kp: usize,
    a: *const f32,
    b: *const f32,
    ldb: usize,
    c: *mut f32,
    ldc: usize,
    accumulate: bool,
) {
    by_width!(avx512bf16_gemm_8xnv, nv, kp, a, b, ldb, c, ldc, accumulate)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bf16;
    use crate::Rng;

    /// The bf16 kernels against a plain f64 sum over the same bf16 values,
    /// for every width, depths 1..=300 and both accumulate modes.
    #[test]
    fn bf16_kernels_match_reference() {
        if !bf16::available() {
            eprintln!("SKIPPED: this CPU lacks AVX512_BF16; the bf16 kernels are not tested");
            return;
        }
        let (mr, nr) = (AVX512_MR, AVX512_NR);
        let mut rng = Rng::new(5);
        for &kp in &[1usize, 2, 3, 7, 64, 128, 300] {
            for nv in 1..=4usize {
                let cols = 16 * nv.min(3);
                let a: Vec<f32> = (0..kp * mr)
                    .map(|_| bf16::pair(rng.normal(), rng.normal()))
                    .collect();
                let b: Vec<f32> = (0..kp * nr)
                    .map(|_| bf16::pair(rng.normal(), rng.normal() * 10.0))
                    .collect();
                for accumulate in [false, true] {
                    let ldc = nr + 5;
                    let c0: Vec<f32> = (0..mr * ldc).map(|_| rng.normal()).collect();
                    let mut c = c0.clone();
                    // SAFETY: the CPU has the ISA; A holds kp·8 words, B kp·48,
                    // C 8 rows of ldc ≥ 48 floats.
                    unsafe {
                        if nv == 4 {
                            avx512bf16_gemm_8x48(
                                kp,
                                a.as_ptr(),
                                b.as_ptr(),
                                c.as_mut_ptr(),
                                ldc,
                                accumulate,
                            )
                        } else {
                            avx512bf16_gemm_narrow_8x16n(
                                nv,
                                kp,
                                a.as_ptr(),
                                b.as_ptr(),
                                nr,
                                c.as_mut_ptr(),
                                ldc,
                                accumulate,
                            )
                        }
                    }
                    for r in 0..mr {
                        for j in 0..ldc {
                            let got = c[r * ldc + j];
                            if j >= cols {
                                assert_eq!(
                                    got.to_bits(),
                                    c0[r * ldc + j].to_bits(),
                                    "column {j} past the tile was written"
                                );
                                continue;
                            }
                            let (mut sum, mut mag) = (0.0f64, 0.0f64);
                            for k in 0..kp {
                                let (a0, a1) = bf16::unpair(a[k * mr + r]);
                                let (b0, b1) = bf16::unpair(b[k * nr + j]);
                                for p in
                                    [f64::from(a0) * f64::from(b0), f64::from(a1) * f64::from(b1)]
                                {
                                    sum += p;
                                    mag += p.abs();
                                }
                            }
                            if accumulate {
                                sum += f64::from(c0[r * ldc + j]);
                                mag += f64::from(c0[r * ldc + j]).abs();
                            }
                            let err = (f64::from(got) - sum).abs();
                            // f32 sums of 2·kp exact products.
                            let tol = mag * 2.0 * (kp as f64 + 2.0) * f64::from(f32::EPSILON);
                            assert!(err <= tol, "kp {kp} nv {nv} acc {accumulate} ({r},{j}): {got} vs {sum}, err {err:e} > {tol:e}");
                        }
                    }
                }
            }
        }
    }
}
