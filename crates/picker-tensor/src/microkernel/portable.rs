//! The portable micro-kernel: plain Rust the compiler vectorises for the baseline ISA.

/// Rows of the portable tile.
pub(crate) const MR: usize = 4;
/// Columns of the portable tile.
pub(crate) const NR: usize = 16;

/// The tile `C[4×16] (+)= A · B` with row `k` of B at `b_row(k)`: both
/// portable kernels are this loop with their own way of finding B rows.
///
/// # Safety
/// As [`super::KernelFn`], with `b_row(k)` valid for `NR` floats for every `k < kc`.
#[inline(always)]
unsafe fn tile(
    kc: usize,
    a: *const f32,
    b_row: impl Fn(usize) -> *const f32,
    c: *mut f32,
    ldc: usize,
    accumulate: bool,
) {
    let a = std::slice::from_raw_parts(a, kc * MR);
    let mut t = [[0.0f32; NR]; MR];
    for (k, ak) in a.chunks_exact(MR).enumerate() {
        let bk = std::slice::from_raw_parts(b_row(k), NR);
        for r in 0..MR {
            let ar = ak[r];
            for j in 0..NR {
                t[r][j] += ar * bk[j];
            }
        }
    }
    for (r, row) in t.iter().enumerate() {
        let dst = std::slice::from_raw_parts_mut(c.add(r * ldc), NR);
        if accumulate {
            dst.iter_mut().zip(row).for_each(|(d, v)| *d += v);
        } else {
            dst.copy_from_slice(row);
        }
    }
}

/// `C[4×16] (+)= A · B`; see [`super::KernelFn`] for the contract.
///
/// # Safety
/// As [`super::KernelFn`].
pub(crate) unsafe fn portable_sgemm_4x16(
    kc: usize,
    a: *const f32,
    b: *const f32,
    c: *mut f32,
    ldc: usize,
    accumulate: bool,
) {
    tile(kc, a, |k| b.add(k * NR), c, ldc, accumulate)
}

/// As [`portable_sgemm_4x16`], with row `k` of B read in place at
/// `b.add(offs[k])` (16 floats); see [`super::RowsKernelFn`].
///
/// # Safety
/// As [`super::RowsKernelFn`].
pub(crate) unsafe fn portable_sgemm_rows_4x16(
    kc: usize,
    a: *const f32,
    b: *const f32,
    offs: *const usize,
    c: *mut f32,
    ldc: usize,
    accumulate: bool,
) {
    tile(kc, a, |k| b.add(*offs.add(k)), c, ldc, accumulate)
}
