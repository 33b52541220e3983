//! The portable micro-kernel: plain Rust the compiler vectorises for the baseline ISA.

/// Rows of the portable tile.
pub(crate) const MR: usize = 4;
/// Columns of the portable tile.
pub(crate) const NR: usize = 16;

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
    let a = std::slice::from_raw_parts(a, kc * MR);
    let b = std::slice::from_raw_parts(b, kc * NR);
    let mut t = [[0.0f32; NR]; MR];
    for (ak, bk) in a.chunks_exact(MR).zip(b.chunks_exact(NR)) {
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
    let a = std::slice::from_raw_parts(a, kc * MR);
    let offs = std::slice::from_raw_parts(offs, kc);
    let mut t = [[0.0f32; NR]; MR];
    for (ak, &o) in a.chunks_exact(MR).zip(offs) {
        let bk = std::slice::from_raw_parts(b.add(o), NR);
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
