//! GEMM micro-kernels: `C[MR×NR] (+)= A_panel · B_panel` over a depth of `kc`.
//!
//! Packed layouts (shared by every kernel): the A panel is `kc` groups of `MR`
//! floats (column `k` of `MR` consecutive rows), the B panel is `kc` rows of `NR`
//! floats. `c` points at the tile's top-left element, rows `ldc` floats apart.
//! With `accumulate == false` the tile is overwritten, else added to.

use crate::isa::Isa;

pub(crate) mod portable;
#[cfg(target_arch = "x86_64")]
pub(crate) mod x86;

/// Signature of every micro-kernel.
///
/// # Safety
/// `a` must hold `kc * MR` floats, `b` `kc * NR` floats, and `c` must be valid
/// for `MR` rows of `NR` floats at stride `ldc`; the CPU must support the ISA.
pub(crate) type KernelFn =
    unsafe fn(kc: usize, a: *const f32, b: *const f32, c: *mut f32, ldc: usize, accumulate: bool);

/// Signature of the micro-kernels that read B in place: row `k` of the B
/// panel is the `NR` floats at `b.add(offs[k])` (so a stride-1 convolution
/// can take its rows straight from the padded image, with no packing).
///
/// # Safety
/// `a` must hold `kc * MR` floats, `offs` `kc` offsets with `NR` readable
/// floats at `b.add(offs[k])` each, and `c` must be valid for `MR` rows of
/// `NR` floats at stride `ldc`; the CPU must support the ISA.
pub(crate) type RowsKernelFn = unsafe fn(
    kc: usize,
    a: *const f32,
    b: *const f32,
    offs: *const usize,
    c: *mut f32,
    ldc: usize,
    accumulate: bool,
);

/// Signature of the narrow-panel kernels: `C[MR × lanes·nv] (+)= A · B` with
/// B rows `ldb` floats apart, for the last, partly filled panel of a product
/// (`lanes` is the family's vector width, `nv` at most `NR / lanes`).
///
/// # Safety
/// As [`KernelFn`], with `lanes·nv` columns of B and C instead of `NR`.
pub(crate) type NarrowKernelFn = unsafe fn(
    nv: usize,
    kc: usize,
    a: *const f32,
    b: *const f32,
    ldb: usize,
    c: *mut f32,
    ldc: usize,
    accumulate: bool,
);

/// A micro-kernel with its tile shape.
#[derive(Clone, Copy)]
pub(crate) struct MicroKernel {
    pub(crate) isa: Isa,
    pub(crate) mr: usize,
    pub(crate) nr: usize,
    pub(crate) run: KernelFn,
    /// The same tile with B rows read in place.
    pub(crate) run_rows: RowsKernelFn,
    /// Narrow tiles for a partly filled last panel: `(lanes, kernel)`, or
    /// `None` where the family only has the full tile.
    pub(crate) narrow: Option<(usize, NarrowKernelFn)>,
}

impl MicroKernel {
    /// The kernel of `isa`, or `None` when this CPU cannot run it.
    pub(crate) fn for_isa(isa: Isa) -> Option<MicroKernel> {
        if !isa.is_available() {
            return None;
        }
        match isa {
            #[cfg(target_arch = "x86_64")]
            Isa::Avx512 => Some(MicroKernel {
                isa,
                mr: x86::AVX512_MR,
                nr: x86::AVX512_NR,
                run: x86::avx512_sgemm_8x48,
                run_rows: x86::avx512_sgemm_rows_8x48,
                narrow: Some((16, x86::avx512_sgemm_narrow_8x16n)),
            }),
            #[cfg(target_arch = "x86_64")]
            Isa::Avx2Fma => Some(MicroKernel {
                isa,
                mr: x86::AVX2_MR,
                nr: x86::AVX2_NR,
                run: x86::avx2_sgemm_6x16,
                run_rows: x86::avx2_sgemm_rows_6x16,
                narrow: None,
            }),
            _ => Some(MicroKernel {
                isa: Isa::Portable,
                mr: portable::MR,
                nr: portable::NR,
                run: portable::portable_sgemm_4x16,
                run_rows: portable::portable_sgemm_rows_4x16,
                narrow: None,
            }),
        }
    }
}
