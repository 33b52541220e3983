//! bfloat16 for the optional reduced-precision path ([`crate::Precision::Bf16`]).
//!
//! The bf16 products store a *pair* of bf16 values in one 32-bit word: the
//! low half is depth `2k`, the high half depth `2k + 1`, the operand layout of
//! AVX512_BF16's `vdpbf16ps` (each 32-bit lane gets `a₀b₀ + a₁b₁` in f32).
//! Packed pair words live in the crate's f32 buffers as raw bit patterns:
//! they are only ever copied and handed to the bf16 kernels, never used as
//! floats.

/// True when this CPU can run the bf16 kernels (AVX-512F, AVX-512BW and
/// AVX512_BF16), detected once.
pub(crate) fn available() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        use std::sync::OnceLock;
        static HAS: OnceLock<bool> = OnceLock::new();
        *HAS.get_or_init(|| {
            std::arch::is_x86_feature_detected!("avx512f")
                && std::arch::is_x86_feature_detected!("avx512bw")
                && std::arch::is_x86_feature_detected!("avx512bf16")
        })
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// `x` rounded to bf16 as `vcvtneps2bf16` does: to nearest, ties to even;
/// denormal inputs become a zero of the same sign; a NaN stays a (quiet) NaN.
pub(crate) fn to_bits(x: f32) -> u16 {
    let b = x.to_bits();
    if x.is_nan() {
        return ((b >> 16) | 0x0040) as u16;
    }
    if b & 0x7f80_0000 == 0 {
        return ((b >> 16) & 0x8000) as u16;
    }
    let rounded = b.wrapping_add(0x7fff + ((b >> 16) & 1));
    (rounded >> 16) as u16
}

/// The f32 value of bf16 bits (exact).
#[cfg(test)]
pub(crate) fn from_bits(h: u16) -> f32 {
    f32::from_bits(u32::from(h) << 16)
}

/// The pair word of `(lo, hi)`, as the f32 with those bits.
pub(crate) fn pair(lo: f32, hi: f32) -> f32 {
    f32::from_bits(u32::from(to_bits(lo)) | (u32::from(to_bits(hi)) << 16))
}

/// The two values of a pair word, as f32 (`(lo, hi)`).
#[cfg(test)]
pub(crate) fn unpair(w: f32) -> (f32, f32) {
    let b = w.to_bits();
    (from_bits(b as u16), from_bits((b >> 16) as u16))
}

/// `dst[i] = pair(lo[i], hi[i])`, one element at a time (the reference of
/// [`pack_pairs`]).
pub(crate) fn pack_pairs_scalar(lo: &[f32], hi: &[f32], dst: &mut [f32]) {
    for ((d, &l), &h) in dst.iter_mut().zip(lo).zip(hi) {
        *d = pair(l, h);
    }
}

/// `dst[i] = pair(lo[i], hi[i])` for `i < dst.len()` (`lo` and `hi` at least
/// as long), with `vcvtne2ps2bf16` and an interleaving `vpermw` where the
/// CPU has them.
pub(crate) fn pack_pairs(lo: &[f32], hi: &[f32], dst: &mut [f32]) {
    let n = dst.len();
    assert!(lo.len() >= n && hi.len() >= n, "pack_pairs: short source");
    #[cfg(target_arch = "x86_64")]
    if available() {
        // SAFETY: the CPU has AVX-512F/BW and AVX512_BF16 (checked above);
        // the slices hold `n` floats each.
        unsafe { pack_pairs_avx512(lo.as_ptr(), hi.as_ptr(), dst.as_mut_ptr(), n) };
        return;
    }
    pack_pairs_scalar(&lo[..n], &hi[..n], dst);
}

/// # Safety
/// `lo`, `hi` and `dst` valid for `n` floats; the CPU has AVX-512F, AVX-512BW
/// and AVX512_BF16.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512bw,avx512bf16")]
unsafe fn pack_pairs_avx512(lo: *const f32, hi: *const f32, dst: *mut f32, n: usize) {
    use std::arch::x86_64::*;
    // Word 2i of the result is word i of the conversion (lo[i]), word 2i + 1
    // is word 16 + i (hi[i]).
    let idx: [i16; 32] = std::array::from_fn(|w| ((w / 2) + 16 * (w % 2)) as i16);
    let idx = _mm512_loadu_si512(idx.as_ptr().cast());
    let mut i = 0;
    while i < n {
        let m: __mmask16 = if n - i >= 16 {
            0xffff
        } else {
            (1u16 << (n - i)) - 1
        };
        let l = _mm512_maskz_loadu_ps(m, lo.add(i));
        let h = _mm512_maskz_loadu_ps(m, hi.add(i));
        // Low 256 bits: bf16(l); high 256 bits: bf16(h).
        let both: __m512i = std::mem::transmute(_mm512_cvtne2ps_pbh(h, l));
        let words = _mm512_permutexvar_epi16(idx, both);
        _mm512_mask_storeu_epi32(dst.add(i).cast(), m, words);
        i += 16;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Rng;

    fn specials() -> Vec<f32> {
        vec![
            0.0,
            -0.0,
            1.0,
            -1.0,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
            -f32::NAN,
            f32::MAX,
            -f32::MAX,
            f32::MIN_POSITIVE,
            f32::MIN_POSITIVE / 4.0, // denormal
            -f32::MIN_POSITIVE / 3.0,
            f32::from_bits(0x3f80_8000), // a tie: 1 + 2⁻⁸, rounds to even (1)
            f32::from_bits(0x3f81_8000), // a tie rounding up
            f32::from_bits(0x3f80_8001), // just above a tie
            f32::from_bits(0x7f7f_ffff), // rounds to infinity
        ]
    }

    #[test]
    fn rounding_known_values() {
        assert_eq!(to_bits(1.0), 0x3f80);
        assert_eq!(to_bits(f32::from_bits(0x3f80_8000)), 0x3f80);
        assert_eq!(to_bits(f32::from_bits(0x3f81_8000)), 0x3f82);
        assert_eq!(to_bits(f32::from_bits(0x3f80_8001)), 0x3f81);
        assert_eq!(to_bits(f32::from_bits(0x7f7f_ffff)), 0x7f80);
        assert_eq!(to_bits(-f32::MIN_POSITIVE / 3.0), 0x8000);
        assert!(from_bits(to_bits(f32::NAN)).is_nan());
        let (l, h) = unpair(pair(1.5, -2.0));
        assert_eq!((l, h), (1.5, -2.0));
        // bf16 keeps 8 significant bits: relative error ≤ 2⁻⁸.
        let mut rng = Rng::new(3);
        for _ in 0..10_000 {
            let x = rng.normal() * 100.0;
            let r = from_bits(to_bits(x));
            assert!((r - x).abs() <= x.abs() * (1.0 / 256.0), "{x} → {r}");
        }
    }

    /// The vector packing equals the scalar reference bit for bit, on every
    /// length up to three vectors and on special values.
    #[test]
    fn vector_pairs_match_scalar() {
        if !available() {
            eprintln!("SKIPPED: this CPU lacks AVX512_BF16; the vector packing is not tested");
            return;
        }
        let mut rng = Rng::new(11);
        for n in 0..50 {
            let mut lo: Vec<f32> = (0..n).map(|_| rng.normal() * 3.0).collect();
            let mut hi: Vec<f32> = (0..n).map(|_| rng.normal() * 1e-3).collect();
            for (i, s) in specials().into_iter().enumerate() {
                if i < n {
                    lo[i] = s;
                    hi[n - 1 - i] = s;
                }
            }
            let mut a = vec![7.0f32; n + 3];
            let mut b = vec![7.0f32; n + 3];
            pack_pairs(&lo, &hi, &mut a[..n]);
            pack_pairs_scalar(&lo, &hi, &mut b[..n]);
            let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&a), bits(&b), "n = {n}");
        }
    }
}
