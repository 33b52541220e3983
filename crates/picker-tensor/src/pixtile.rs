//! Convolutions with the output channels in the SIMD lanes (AVX-512), for
//! strided layers: no phase planes, no padded copy.
//!
//! A tile is [`PX`] consecutive output pixels of one row times [`CO`] output
//! channels (four 16-lane registers). For every tap `k = (ci, ky, kx)` the
//! micro-kernel loads the `CO` weights of `k` and broadcasts the tile's `PX`
//! input values `x[ci][iy + ky][ix + kx + r·s]`, which lie `s` floats apart in
//! one input row: a stride costs nothing. One task computes one output row,
//! panel by panel; the taps run in depth blocks of [`PIXTILE_KC`] over all
//! the row's tiles (the block's weights stay in L1; the tiles' 24
//! accumulators are kept in a row buffer between blocks). A tile whose input
//! window leaves the image (padding) or whose pixels pass the row's end reads
//! a small copy of its window, made once per row and filled as the padding
//! says; every other tile reads the input where it lies. Measured against
//! the shifted GEMM over phase planes on Zen 4 (2 threads): the stride-2
//! encoder convs 3–19% faster, the EnvMap's encoder 14.6 → 10.5 ms in the
//! network; a stride-1 7×7 conv with 3 inputs is 2× slower, so
//! [`crate::ConvAlgorithm::Auto`] takes this path only for strided layers.
//!
//! Each output is the sum over `k` in order of one fused multiply-add per
//! tap, so results do not depend on the number of threads.

use rayon::prelude::*;

use crate::activation::Activation;
use crate::aligned::AlignedBuf;
use crate::gemm::Epilogue;
use crate::pad::{padded_source, Fill};

/// Output pixels per tile (one row).
pub(crate) const PX: usize = 6;
/// Output channels per tile (4 × 16 lanes).
pub(crate) const CO: usize = 64;
/// Taps per depth block: a block's `PIXTILE_KC × CO` weights (16 KiB) stay in
/// L1 while the row's tiles run over them.
const PIXTILE_KC: usize = 64;
/// Largest stride the micro-kernel is compiled for.
pub(crate) const MAX_STRIDE: usize = 4;

/// A layer's weights for [`PixelTiles::forward_image`]: per panel of [`CO`]
/// output channels (zero past `c_out`), `[k][CO]` with `k = (ci, ky, kx)`.
#[derive(Clone)]
pub(crate) struct PixelTiles {
    c_in: usize,
    c_out: usize,
    kh: usize,
    kw: usize,
    stride: usize,
    /// Aligned to a cache line: each tap's `CO` weights are whole lines
    /// (misaligned, every load of a block streamed from L2 split in two).
    w: AlignedBuf,
}

thread_local! {
    /// Per-thread scratch of [`PixelTiles::forward_image`]'s row tasks: the
    /// edge tiles' window copies and the row's tile sums, kept rather than
    /// made (and zero-filled) for every task.
    static SCRATCH: std::cell::RefCell<(Vec<f32>, Vec<f32>)> =
        const { std::cell::RefCell::new((Vec::new(), Vec::new())) };
}

struct SharedPtr(*mut f32);
// SAFETY: each task writes the outputs of its own (panel, row) only.
unsafe impl Sync for SharedPtr {}
unsafe impl Send for SharedPtr {}

impl PixelTiles {
    /// Packs `weight` (`[c_out, c_in, kh, kw]`). `stride` must be in
    /// `1..=MAX_STRIDE` and the CPU must have AVX-512F (the caller checks).
    pub(crate) fn new(
        weight: &[f32],
        c_in: usize,
        c_out: usize,
        kh: usize,
        kw: usize,
        stride: usize,
    ) -> Self {
        assert!((1..=MAX_STRIDE).contains(&stride), "stride {stride}");
        let k = c_in * kh * kw;
        assert_eq!(weight.len(), c_out * k, "weight length");
        let panels = c_out.div_ceil(CO);
        let mut w = AlignedBuf::zeroed(panels * k * CO);
        let wm = w.as_mut_slice();
        for co in 0..c_out {
            let (p, j) = (co / CO, co % CO);
            for kk in 0..k {
                wm[(p * k + kk) * CO + j] = weight[co * k + kk];
            }
        }
        Self {
            c_in,
            c_out,
            kh,
            kw,
            stride,
            w,
        }
    }

    /// One image: `x` is `[c_in, h, w]`, extended by `pad` on every side as
    /// `fill` says; `out` is `[c_out, oh, ow]` with `(oh, ow)` the layer's
    /// output size, then `epi` (its residual, if any, shaped like `out`).
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn forward_image(
        &self,
        x: &[f32],
        h: usize,
        w: usize,
        pad: usize,
        fill: Fill,
        epi: &Epilogue<'_>,
        out: &mut [f32],
    ) {
        let (bias, act, residual) = (epi.bias, epi.act, epi.residual);
        let (c_in, kh, kw, s) = (self.c_in, self.kh, self.kw, self.stride);
        let (hp, wp) = (h + 2 * pad, w + 2 * pad);
        assert!(hp >= kh && wp >= kw, "input smaller than the kernel");
        let (oh, ow) = ((hp - kh) / s + 1, (wp - kw) / s + 1);
        assert_eq!(x.len(), c_in * h * w, "input length");
        assert_eq!(out.len(), self.c_out * oh * ow, "output length");
        if let Some(r) = residual {
            assert_eq!(r.len(), out.len(), "residual length");
        }
        let k = c_in * kh * kw;
        let win_w = (PX - 1) * s + kw;
        // Tap offsets: in the image (from the window's top-left input) and
        // in a tile's own window copy (`[ci][ky][win_w]`).
        let in_image: Vec<usize> = (0..c_in)
            .flat_map(|ci| {
                (0..kh).flat_map(move |ky| (0..kw).map(move |kx| (ci * h + ky) * w + kx))
            })
            .collect();
        let in_window: Vec<usize> = (0..c_in)
            .flat_map(|ci| {
                (0..kh).flat_map(move |ky| (0..kw).map(move |kx| (ci * kh + ky) * win_w + kx))
            })
            .collect();
        let panels = self.c_out.div_ceil(CO);
        let tiles_x = ow.div_ceil(PX);
        let optr = SharedPtr(out.as_mut_ptr());
        let optr = &optr;
        let kernel = match s {
            1 => tile::<1> as TileFn,
            2 => tile::<2>,
            3 => tile::<3>,
            _ => tile::<4>,
        };
        let kc_block = PIXTILE_KC.max(1);
        (0..oh).into_par_iter().for_each(|oy| {
            SCRATCH.with(|scratch| {
                let (windows, accs) = &mut *scratch.borrow_mut();
                // Every tile's sums are written by its first depth block
                // before they are read: stale values do not matter.
                if accs.len() < tiles_x * PX * CO {
                    accs.resize(tiles_x * PX * CO, 0.0);
                }
                // Padded-grid row of the windows' top.
                let qy = oy * s;
                let rows_inside = qy >= pad && qy + kh <= pad + h;
                // The tiles that read a copy of their window (padding, or
                // pixels past the row's end), copied once for the row.
                let win_len = c_in * kh * win_w;
                let inside = |tx: usize| {
                    let (ox0, qx) = (tx * PX, tx * PX * s);
                    rows_inside && qx >= pad && qx + win_w <= pad + w && ox0 + PX <= ow
                };
                let edge: Vec<usize> = (0..tiles_x).filter(|&tx| !inside(tx)).collect();
                windows.resize(edge.len() * win_len, 0.0);
                for (e, &tx) in edge.iter().enumerate() {
                    let dst = &mut windows[e * win_len..(e + 1) * win_len];
                    fill_window(
                        x,
                        h,
                        w,
                        pad,
                        hp,
                        wp,
                        fill,
                        qy,
                        tx * PX * s,
                        c_in,
                        kh,
                        win_w,
                        dst,
                    );
                }
                for p in 0..panels {
                    let wp_ = &self.w.as_slice()[p * k * CO..(p + 1) * k * CO];
                    // Depth blocks outside, tiles inside: a block's weights
                    // (`PIXTILE_KC × CO` floats) stay in L1 over the row's tiles.
                    let mut k0 = 0;
                    while k0 < k {
                        let kc = kc_block.min(k - k0);
                        let mut e = 0;
                        for tx in 0..tiles_x {
                            let acc = accs[tx * PX * CO..(tx + 1) * PX * CO].as_mut_ptr();
                            let wk = wp_[k0 * CO..].as_ptr();
                            // SAFETY: the CPU has AVX-512F (checked when the layer
                            // was built); every tap offset plus (PX − 1)·s lies
                            // inside the image (inside tiles) or the tile's window
                            // copy, `wk` holds kc·CO weights and `acc` PX·CO floats.
                            unsafe {
                                if edge.get(e) == Some(&tx) {
                                    let win = windows[e * win_len..].as_ptr();
                                    kernel(kc, wk, win, in_window[k0..].as_ptr(), acc, k0 > 0);
                                    e += 1;
                                } else {
                                    let base = x.as_ptr().add((qy - pad) * w + (tx * PX * s - pad));
                                    kernel(kc, wk, base, in_image[k0..].as_ptr(), acc, k0 > 0);
                                }
                            }
                        }
                        k0 += kc;
                    }
                    let rows = CO.min(self.c_out - p * CO);
                    if residual.is_none() && matches!(act, Activation::None | Activation::Relu) {
                        // SAFETY: AVX-512F (as above); `accs` holds the sums
                        // of `tiles_x · PX ≥ ow` pixels, and the `rows`
                        // channels of the panel at (oy, 0..ow) are inside
                        // `out` and belong to this task.
                        unsafe {
                            store_row(
                                &accs[..tiles_x * PX * CO],
                                ow,
                                rows,
                                bias.map(|b| &b[p * CO..p * CO + rows]),
                                act == Activation::Relu,
                                optr.0.add((p * CO * oh + oy) * ow),
                                oh * ow,
                            )
                        };
                        continue;
                    }
                    for tx in 0..tiles_x {
                        let ox0 = tx * PX;
                        let acc: &[f32; PX * CO] = accs[tx * PX * CO..(tx + 1) * PX * CO]
                            .try_into()
                            .expect("tile sums");
                        let px = PX.min(ow - ox0);
                        for j in 0..rows {
                            let co = p * CO + j;
                            let b = bias.map_or(0.0, |b| b[co]);
                            let at = (co * oh + oy) * ow + ox0;
                            for r in 0..px {
                                let mut v = act.apply_one(acc[r * CO + j] + b);
                                if let Some(res) = residual {
                                    v += res[at + r];
                                }
                                // SAFETY: (co, oy, ox0 + r) is inside `out` and
                                // belongs to this task's (panel, row).
                                unsafe { *optr.0.add(at + r) = v };
                            }
                        }
                    }
                }
            })
        });
    }
}

/// Copies the input window of a tile (padded-grid top-left `(qy, qx)`,
/// `kh × win_w` per channel) into `dst`, padding as `fill` says (zero past the
/// padded grid).
#[allow(clippy::too_many_arguments)]
fn fill_window(
    x: &[f32],
    h: usize,
    w: usize,
    pad: usize,
    hp: usize,
    wp: usize,
    fill: Fill,
    qy: usize,
    qx: usize,
    c_in: usize,
    kh: usize,
    win_w: usize,
    dst: &mut [f32],
) {
    // The window's columns as runs: `(first column, its source column or
    // zero, length)`, consecutive source columns in one run, so that a row
    // is a few slice copies (the padding columns alone break a run).
    let mut runs: Vec<(usize, Option<usize>, usize)> = Vec::with_capacity(4);
    for c in 0..win_w {
        let src = padded_source(qx + c, pad, w, wp, fill);
        match runs.last_mut() {
            Some((_, Some(s0), len)) if src == Some(*s0 + *len) => *len += 1,
            Some((_, None, len)) if src.is_none() => *len += 1,
            _ => runs.push((c, src, 1)),
        }
    }
    for ky in 0..kh {
        let sy = padded_source(qy + ky, pad, h, hp, fill);
        for ci in 0..c_in {
            let d = &mut dst[(ci * kh + ky) * win_w..][..win_w];
            match sy {
                None => d.fill(0.0),
                Some(y) => {
                    let row = &x[(ci * h + y) * w..][..w];
                    for &(c0, src, len) in &runs {
                        let d = &mut d[c0..c0 + len];
                        match src {
                            Some(s0) => d.copy_from_slice(&row[s0..s0 + len]),
                            None => d.fill(0.0),
                        }
                    }
                }
            }
        }
    }
}

/// Writes a row's sums (`accs`: pixel `x` at `accs[x·CO..]`, its `CO`
/// channels side by side; at least `ow` pixels) to the `ow` pixels of
/// `rows` output channels: channel `j` of pixel `x` goes to
/// `out[j·plane + x]`, plus `bias[j]`, through ReLU when `relu`. Blocks of
/// 16 pixels × 16 channels are transposed in registers, so every channel's
/// pixels are written as whole vectors.
///
/// # Safety
/// The CPU has AVX-512F; every `out[j·plane + x]` (`j < rows ≤ CO`,
/// `x < ow`) is writable.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
unsafe fn store_row(
    accs: &[f32],
    ow: usize,
    rows: usize,
    bias: Option<&[f32]>,
    relu: bool,
    out: *mut f32,
    plane: usize,
) {
    use std::arch::x86_64::*;
    let px_avail = accs.len() / CO;
    assert!(px_avail >= ow && rows <= CO, "store_row: sizes");
    for jb in 0..rows.div_ceil(16) {
        let n = (rows - 16 * jb).min(16);
        let cmask: __mmask16 = if n == 16 { !0 } else { (1u16 << n) - 1 };
        let b = match bias {
            Some(b) => _mm512_maskz_loadu_ps(cmask, b.as_ptr().add(16 * jb)),
            None => _mm512_setzero_ps(),
        };
        let mut x0 = 0;
        while x0 < ow {
            let m = (ow - x0).min(16);
            let r: [__m512; 16] = std::array::from_fn(|i| {
                if i < m {
                    let mut v = _mm512_add_ps(
                        _mm512_loadu_ps(accs.as_ptr().add((x0 + i) * CO + 16 * jb)),
                        b,
                    );
                    if relu {
                        v = _mm512_max_ps(v, _mm512_setzero_ps());
                    }
                    v
                } else {
                    _mm512_setzero_ps()
                }
            });
            let t = transpose16(r);
            let pmask: __mmask16 = if m == 16 { !0 } else { (1u16 << m) - 1 };
            for (j, tj) in t.iter().enumerate().take(n) {
                _mm512_mask_storeu_ps(out.add((16 * jb + j) * plane + x0), pmask, *tj);
            }
            x0 += 16;
        }
    }
}

/// The transpose of a 16 × 16 block: lane `i` of result `j` is lane `j` of
/// `r[i]` (unpacks within 128-bit lanes, then 128-bit lane shuffles).
///
/// # Safety
/// The CPU has AVX-512F.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
unsafe fn transpose16(r: [std::arch::x86_64::__m512; 16]) -> [std::arch::x86_64::__m512; 16] {
    use std::arch::x86_64::*;
    // t[2k], t[2k + 1]: rows 2k and 2k + 1 interleaved, low and high pairs.
    let t: [__m512; 16] = std::array::from_fn(|i| {
        let (a, b) = (r[i & !1], r[i | 1]);
        if i & 1 == 0 {
            _mm512_unpacklo_ps(a, b)
        } else {
            _mm512_unpackhi_ps(a, b)
        }
    });
    // u[4k + m], 128-bit lane L: column 4L + m of rows 4k … 4k + 3.
    let pd = _mm512_castps_pd;
    let u: [__m512; 16] = std::array::from_fn(|i| {
        let (k, m) = (i / 4, i % 4);
        let (a, b) = (pd(t[4 * k + m / 2]), pd(t[4 * k + 2 + m / 2]));
        _mm512_castpd_ps(if m % 2 == 0 {
            _mm512_unpacklo_pd(a, b)
        } else {
            _mm512_unpackhi_pd(a, b)
        })
    });
    // Column 4L + m: lane L of u[m], u[4 + m], u[8 + m], u[12 + m].
    let mut out = [_mm512_setzero_ps(); 16];
    for m in 0..4 {
        let v0 = _mm512_shuffle_f32x4::<0x44>(u[m], u[4 + m]);
        let v1 = _mm512_shuffle_f32x4::<0xee>(u[m], u[4 + m]);
        let v2 = _mm512_shuffle_f32x4::<0x44>(u[8 + m], u[12 + m]);
        let v3 = _mm512_shuffle_f32x4::<0xee>(u[8 + m], u[12 + m]);
        out[m] = _mm512_shuffle_f32x4::<0x88>(v0, v2);
        out[4 + m] = _mm512_shuffle_f32x4::<0xdd>(v0, v2);
        out[8 + m] = _mm512_shuffle_f32x4::<0x88>(v1, v3);
        out[12 + m] = _mm512_shuffle_f32x4::<0xdd>(v1, v3);
    }
    out
}

/// Not x86-64: never called.
#[cfg(not(target_arch = "x86_64"))]
unsafe fn store_row(
    _: &[f32],
    _: usize,
    _: usize,
    _: Option<&[f32]>,
    _: bool,
    _: *mut f32,
    _: usize,
) {
    unreachable!("PixelTiles needs AVX-512")
}

/// A tile micro-kernel: `acc[r][j] = Σ_k w[k][j] · x[offs[k] + r·s]`.
type TileFn = unsafe fn(usize, *const f32, *const f32, *const usize, *mut f32, bool);

/// The micro-kernel for stride `S`: `k` taps, weights `w` (`k × CO`), input
/// values at `x + offs[kk] + r·S`, sums to `acc` (`PX × CO`, pixel-major),
/// added to what `acc` holds when `accumulate`.
///
/// # Safety
/// The CPU has AVX-512F; the pointers hold what is described above.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
unsafe fn tile<const S: usize>(
    k: usize,
    w: *const f32,
    x: *const f32,
    offs: *const usize,
    acc: *mut f32,
    accumulate: bool,
) {
    use std::arch::x86_64::*;
    let mut a = [[_mm512_setzero_ps(); 4]; PX];
    if accumulate {
        for (r, ar) in a.iter_mut().enumerate() {
            for (j, aj) in ar.iter_mut().enumerate() {
                *aj = _mm512_loadu_ps(acc.add(r * CO + j * 16));
            }
        }
    }
    for kk in 0..k {
        let wp = w.add(kk * CO);
        let wv = [
            _mm512_loadu_ps(wp),
            _mm512_loadu_ps(wp.add(16)),
            _mm512_loadu_ps(wp.add(32)),
            _mm512_loadu_ps(wp.add(48)),
        ];
        let xp = x.add(*offs.add(kk));
        for (r, ar) in a.iter_mut().enumerate() {
            let b = _mm512_set1_ps(*xp.add(r * S));
            for (aj, &wj) in ar.iter_mut().zip(&wv) {
                *aj = _mm512_fmadd_ps(b, wj, *aj);
            }
        }
    }
    for (r, ar) in a.iter().enumerate() {
        for (j, aj) in ar.iter().enumerate() {
            _mm512_storeu_ps(acc.add(r * CO + j * 16), *aj);
        }
    }
}

/// Not x86-64: never called ([`crate::ConvAlgorithm::PixelTiles`] runs only
/// on the AVX-512 family).
#[cfg(not(target_arch = "x86_64"))]
unsafe fn tile<const S: usize>(
    _: usize,
    _: *const f32,
    _: *const f32,
    _: *const usize,
    _: *mut f32,
    _: bool,
) {
    unreachable!("PixelTiles needs AVX-512")
}

#[cfg(all(test, target_arch = "x86_64"))]
mod tests {
    use super::*;

    /// `store_row` against the plain loop it stands for, on every width of
    /// the last block of pixels and channels, with and without bias and ReLU.
    #[test]
    fn store_row_matches_the_plain_loop() {
        if !std::arch::is_x86_feature_detected!("avx512f") {
            eprintln!("SKIPPED: store_row needs AVX-512F, which this CPU lacks");
            return;
        }
        let mut rng = crate::Rng::new(17);
        for &(ow, rows) in &[
            (1usize, 1usize),
            (6, 64),
            (16, 16),
            (17, 33),
            (35, 64),
            (40, 5),
        ] {
            let px = ow.div_ceil(PX) * PX;
            let accs = rng.normal_vec(px * CO, 1.0);
            let bias = rng.normal_vec(rows, 1.0);
            for (b, relu) in [
                (None, false),
                (Some(&bias[..]), true),
                (Some(&bias[..]), false),
            ] {
                let plane = ow + 3;
                let mut out = vec![f32::NAN; rows * plane];
                // SAFETY: AVX-512F is present; `out` holds `rows` planes of `ow`.
                unsafe { store_row(&accs, ow, rows, b, relu, out.as_mut_ptr(), plane) };
                for j in 0..rows {
                    for x in 0..plane {
                        let got = out[j * plane + x];
                        if x >= ow {
                            assert!(got.is_nan(), "wrote past the row: {ow} {rows} {j} {x}");
                            continue;
                        }
                        let mut v = accs[x * CO + j] + b.map_or(0.0, |b| b[j]);
                        if relu {
                            v = v.max(0.0);
                        }
                        assert_eq!(got, v, "ow {ow} rows {rows} channel {j} pixel {x}");
                    }
                }
            }
        }
    }
}
