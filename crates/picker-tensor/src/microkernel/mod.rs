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

/// A micro-kernel with its tile shape.
#[derive(Clone, Copy)]
pub(crate) struct MicroKernel {
    pub(crate) isa: Isa,
    pub(crate) mr: usize,
    pub(crate) nr: usize,
    pub(crate) run: KernelFn,
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
            }),
            #[cfg(target_arch = "x86_64")]
            Isa::Avx2Fma => Some(MicroKernel {
                isa,
                mr: x86::AVX2_MR,
                nr: x86::AVX2_NR,
                run: x86::avx2_sgemm_6x16,
            }),
            _ => Some(MicroKernel {
                isa: Isa::Portable,
                mr: portable::MR,
                nr: portable::NR,
                run: portable::portable_sgemm_4x16,
            }),
        }
    }
}
