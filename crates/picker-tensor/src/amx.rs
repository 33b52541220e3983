//! Intel AMX (Advanced Matrix Extensions) bf16 tiles for the optional bf16
//! path ([`crate::Precision::Bf16`]): one `tdpbf16ps` multiplies a 16×32
//! bf16 tile by a 32×16 one into 16×16 f32 sums, 16× the work of an
//! AVX-512 FMA per instruction.
//!
//! Operands are the crate's bf16 *pair words* ([`crate::bf16`]): a B tile is
//! 16 rows of 16 pair words (32 bf16 of depth per column, pairs in the
//! VNNI order `tdpbf16ps` wants), read in place from the Winograd `V` panels;
//! an A tile is 16 rows (output channels) of 16 pair words, packed from
//! the AVX512_BF16 A panels by [`pack_a_panel`]. Sums are f32 as in `vdpbf16ps` (the order of the pair sums
//! differs, so the two bf16 kernels agree to f32 rounding, not bit for bit).
//!
//! The instructions are written with `asm!` (the AMX intrinsics are not in
//! stable Rust). Linux hands out the tile state only on request
//! (`arch_prctl(ARCH_REQ_XCOMP_PERM, XFEATURE_XTILEDATA)`), made once by
//! [`available`]; a thread configures its tiles for one batch of work with
//! [`Tiles::new`] and releases them when the guard drops. `PICKER_AMX=0`
//! turns the path off (the AVX512_BF16 kernels then run).

/// Rows of every tile (output channels of A and C, depth pairs of B).
pub(crate) const ROWS: usize = 16;
/// Pair words per tile row (depth pairs of A, columns of B and C).
pub(crate) const COLS: usize = 16;
/// Pair words of one packed A tile.
pub(crate) const TILE: usize = ROWS * COLS;

/// True when this CPU has AMX-TILE and AMX-BF16, the OS granted the tile
/// state, and `PICKER_AMX` is not `0` (detected and requested once).
pub(crate) fn available() -> bool {
    #[cfg(all(target_arch = "x86_64", target_os = "linux"))]
    {
        use std::sync::OnceLock;
        static HAS: OnceLock<bool> = OnceLock::new();
        *HAS.get_or_init(|| {
            std::env::var("PICKER_AMX").as_deref() != Ok("0") && cpu_has_amx() && request_tiles()
        })
    }
    #[cfg(not(all(target_arch = "x86_64", target_os = "linux")))]
    {
        false
    }
}

/// CPUID leaf 7: AMX-BF16 (EDX bit 22) and AMX-TILE (EDX bit 24).
#[cfg(all(target_arch = "x86_64", target_os = "linux"))]
fn cpu_has_amx() -> bool {
    use std::arch::x86_64::__cpuid_count;
    if __cpuid_count(0, 0).eax < 7 {
        return false;
    }
    let edx = __cpuid_count(7, 0).edx;
    edx & (1 << 22) != 0 && edx & (1 << 24) != 0
}

/// Asks Linux for the tile data state (`arch_prctl` 0x1023, feature 18).
#[cfg(all(target_arch = "x86_64", target_os = "linux"))]
fn request_tiles() -> bool {
    const SYS_ARCH_PRCTL: i64 = 158;
    const ARCH_REQ_XCOMP_PERM: i64 = 0x1023;
    const XFEATURE_XTILEDATA: i64 = 18;
    let ret: i64;
    // SAFETY: the arch_prctl system call with these arguments only changes
    // this process's permission to use the AMX state; it reads no memory.
    unsafe {
        std::arch::asm!(
            "syscall",
            inlateout("rax") SYS_ARCH_PRCTL => ret,
            in("rdi") ARCH_REQ_XCOMP_PERM,
            in("rsi") XFEATURE_XTILEDATA,
            lateout("rcx") _,
            lateout("r11") _,
            options(nostack),
        );
    }
    ret == 0
}

/// Tile configuration: palette 1, tiles 0–2 (C), 3 (A) and 4–6 (B), each
/// 16 rows of 64 bytes.
#[repr(C, align(64))]
struct Config([u8; 64]);

impl Config {
    fn new() -> Self {
        let mut c = [0u8; 64];
        c[0] = 1;
        for t in 0..7 {
            c[16 + 2 * t] = (COLS * 4) as u8;
            c[48 + t] = ROWS as u8;
        }
        Config(c)
    }
}

/// The tiles configured on this thread, released on drop. Create one per
/// batch of [`Tiles::panel`] calls that stays on one thread (no rayon
/// calls in between).
pub(crate) struct Tiles {
    _not_send: std::marker::PhantomData<*const ()>,
}

impl Tiles {
    /// Configures the tiles; `None` where [`available`] is false.
    pub(crate) fn new() -> Option<Tiles> {
        #[cfg(all(target_arch = "x86_64", target_os = "linux"))]
        if available() {
            let cfg = Config::new();
            // SAFETY: AMX is available and granted (checked above); the
            // configuration is 64 readable bytes.
            unsafe {
                std::arch::asm!("ldtilecfg [{}]", in(reg) cfg.0.as_ptr(), options(nostack, readonly));
            }
            return Some(Tiles {
                _not_send: std::marker::PhantomData,
            });
        }
        None
    }

    /// `C[16 × 48] (+)= A · B` over `nkk · 32` bf16 of depth: `a` is `nkk`
    /// packed A tiles ([`pack_a_panel`]), `b` the first of `16 · nkk` rows of 48
    /// pair words, `ldb` words apart, and `c` 16 rows of 48 floats, `ldc`
    /// floats apart (read first when `accumulate`).
    ///
    /// # Safety
    /// `a` holds `nkk · TILE` words, `b` `16·nkk` rows of 48 words at stride
    /// `ldb`, `c` 16 rows of 48 floats at stride `ldc`; `self` lives on this
    /// thread (tiles configured).
    #[allow(clippy::too_many_arguments)]
    pub(crate) unsafe fn panel(
        &self,
        nkk: usize,
        a: *const f32,
        b: *const f32,
        ldb: usize,
        c: *mut f32,
        ldc: usize,
        accumulate: bool,
    ) {
        #[cfg(target_arch = "x86_64")]
        {
            use std::arch::asm;
            let (sb, sc) = (ldb * 4, ldc * 4);
            let stride_a = COLS * 4;
            if accumulate {
                asm!(
                    "tileloadd tmm0, [{c} + {s}*1]",
                    "tileloadd tmm1, [{c} + {s}*1 + 64]",
                    "tileloadd tmm2, [{c} + {s}*1 + 128]",
                    c = in(reg) c, s = in(reg) sc, options(nostack, readonly),
                );
            } else {
                asm!(
                    "tilezero tmm0",
                    "tilezero tmm1",
                    "tilezero tmm2",
                    options(nostack, nomem)
                );
            }
            for kk in 0..nkk {
                let ap = a.add(kk * TILE);
                let bp = b.add(kk * ROWS * ldb);
                asm!(
                    "tileloadd tmm3, [{a} + {sa}*1]",
                    "tileloadd tmm4, [{b} + {sb}*1]",
                    "tileloadd tmm5, [{b} + {sb}*1 + 64]",
                    "tileloadd tmm6, [{b} + {sb}*1 + 128]",
                    "tdpbf16ps tmm0, tmm3, tmm4",
                    "tdpbf16ps tmm1, tmm3, tmm5",
                    "tdpbf16ps tmm2, tmm3, tmm6",
                    a = in(reg) ap, sa = in(reg) stride_a, b = in(reg) bp, sb = in(reg) sb,
                    options(nostack, readonly),
                );
            }
            asm!(
                "tilestored [{c} + {s}*1], tmm0",
                "tilestored [{c} + {s}*1 + 64], tmm1",
                "tilestored [{c} + {s}*1 + 128], tmm2",
                c = in(reg) c, s = in(reg) sc, options(nostack),
            );
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            let _ = (nkk, a, b, ldb, c, ldc, accumulate);
            unreachable!("AMX exists only on x86-64");
        }
    }
}

impl Drop for Tiles {
    fn drop(&mut self) {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: the tiles were configured by `Tiles::new` on this thread.
        unsafe {
            std::arch::asm!("tilerelease", options(nostack, nomem));
        }
    }
}

/// Packs one AVX512_BF16 A panel into A tiles: `src` is depth pairs
/// `k0..k0 + kc` of `mr` rows (`[d][r]`, `kc · mr` pair words) starting at
/// row `row0` of the chunk; row `row0 + r`, pair `d` goes to tile
/// `(j, kk) = ((row0 + r) / 16, d / 16)` of `dst` (`nkk` depth tiles per
/// row block, each `TILE` words `[row][pair]`), at `[(row0 + r) % 16][d % 16]`.
pub(crate) fn pack_a_panel(
    src: &[f32],
    row0: usize,
    k0: usize,
    nkk: usize,
    mr: usize,
    dst: &mut [f32],
) {
    let kc = src.len() / mr;
    let (j, r0) = (row0 / ROWS, row0 % ROWS);
    assert!(r0 + mr <= ROWS && k0.is_multiple_of(COLS) && (k0 + kc).div_ceil(COLS) <= nkk);
    for (dl, words) in src.chunks_exact(mr).enumerate() {
        let d = k0 + dl;
        let tile = &mut dst[(j * nkk + d / COLS) * TILE..][..TILE];
        for (r, &w) in words.iter().enumerate() {
            tile[(r0 + r) * COLS + d % COLS] = w;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bf16;

    /// The AMX panel against f64 sums of the same bf16 values, on seeded
    /// random problems with one and several depth tiles, overwrite and
    /// accumulate; skipped (and said so) where the CPU has no AMX.
    #[test]
    fn amx_panel_matches_reference() {
        let Some(tiles) = Tiles::new() else {
            eprintln!(
                "SKIPPED amx_panel_matches_reference: no AMX-BF16 on this CPU (or not granted)"
            );
            return;
        };
        let mut rng = crate::Rng::new(77);
        for (nkk, ldb, ldc, accumulate) in
            [(1, 48, 48, false), (3, 48, 50, true), (8, 64, 48, false)]
        {
            let depth = 32 * nkk;
            // Values as bf16 (the kernel sees only bf16).
            let av: Vec<f32> = (0..16 * depth)
                .map(|_| bf16::from_bits(bf16::to_bits(rng.normal())))
                .collect();
            let bv: Vec<f32> = (0..depth * 48)
                .map(|_| bf16::from_bits(bf16::to_bits(rng.normal())))
                .collect();
            // B: pair rows d (depths 2d, 2d+1) of 48 pair words, ldb apart.
            let mut b = vec![0.0f32; depth / 2 * ldb];
            for d in 0..depth / 2 {
                for n in 0..48 {
                    b[d * ldb + n] = bf16::pair(bv[2 * d * 48 + n], bv[(2 * d + 1) * 48 + n]);
                }
            }
            // A as two 8-row AVX512_BF16 panels ([d][r]), then packed.
            let mut a = vec![0.0f32; nkk * TILE];
            for half in 0..2 {
                let panel: Vec<f32> = (0..depth / 2)
                    .flat_map(|d| {
                        let av = &av;
                        (0..8).map(move |r| {
                            let co = 8 * half + r;
                            bf16::pair(av[co * depth + 2 * d], av[co * depth + 2 * d + 1])
                        })
                    })
                    .collect();
                pack_a_panel(&panel, 8 * half, 0, nkk, 8, &mut a);
            }
            let init: Vec<f32> = (0..16 * ldc).map(|_| rng.normal()).collect();
            let mut c = init.clone();
            // SAFETY: sizes as the contract asks; tiles configured above.
            unsafe {
                tiles.panel(
                    nkk,
                    a.as_ptr(),
                    b.as_ptr(),
                    ldb,
                    c.as_mut_ptr(),
                    ldc,
                    accumulate,
                )
            };
            for co in 0..16 {
                for n in 0..48 {
                    let mut s = if accumulate {
                        init[co * ldc + n] as f64
                    } else {
                        0.0
                    };
                    for k in 0..depth {
                        s += av[co * depth + k] as f64 * bv[k * 48 + n] as f64;
                    }
                    let got = c[co * ldc + n] as f64;
                    assert!(
                        (got - s).abs() <= 1e-5 * (1.0 + s.abs()) * depth as f64,
                        "nkk {nkk} co {co} n {n}: {got} vs {s}"
                    );
                }
                for n in 48..ldc {
                    assert_eq!(c[co * ldc + n], init[co * ldc + n], "wrote past 48 columns");
                }
            }
        }
    }
}
