//! Winograd F(4×4, 3×3) for stride-1 3×3 convolutions (Lavin & Gray 2016):
//! each 4×4 output tile takes 36 multiplies per input/output channel pair
//! instead of 144.
//!
//! With `d` a 6×6 input tile, `g` a 3×3 kernel: `Y = Aᵀ [Σ_ci (G g Gᵀ) ⊙ (Bᵀ d B)] A`.
//! The weights are transformed (in f64) and packed once, as 36 `c_out × c_in`
//! matrices `U[ξ]`. A forward pass transforms the input tiles into 36
//! `c_in × tiles` matrices `V[ξ]` (parallel over channels), runs the 36
//! independent products `M[ξ] = U[ξ] · V[ξ]` (parallel over ξ), and transforms
//! `M` back per output channel, fusing bias, activation and residual add.
//! Zero padding (and the overhang of the last tiles) is handled in the gather.

use rayon::prelude::*;

use crate::activation::Activation;
use crate::conv::{copy_short, zero_short};
use crate::gemm::{gemm_serial, BSource, Epilogue, PackedA};
use crate::microkernel::MicroKernel;

/// Points of the transformed tile.
const T: usize = 6;
/// Outputs per tile side.
const M: usize = 4;

/// `Bᵀ x` for the points 0, ±1, ±2, ∞.
#[inline(always)]
fn bt(d: [f32; 6]) -> [f32; 6] {
    [
        4.0 * d[0] - 5.0 * d[2] + d[4],
        -4.0 * d[1] - 4.0 * d[2] + d[3] + d[4],
        4.0 * d[1] - 4.0 * d[2] - d[3] + d[4],
        -2.0 * d[1] - d[2] + 2.0 * d[3] + d[4],
        2.0 * d[1] - d[2] - 2.0 * d[3] + d[4],
        4.0 * d[1] - 5.0 * d[3] + d[5],
    ]
}

/// `Aᵀ m`.
#[inline(always)]
fn at(m: [f32; 6]) -> [f32; 4] {
    [
        m[0] + m[1] + m[2] + m[3] + m[4],
        m[1] - m[2] + 2.0 * (m[3] - m[4]),
        m[1] + m[2] + 4.0 * (m[3] + m[4]),
        m[1] - m[2] + 8.0 * (m[3] - m[4]) + m[5],
    ]
}

/// Six disjoint `len`-long output lanes of `out`, at `base + i·stride` (`stride ≥ len`).
#[inline(always)]
fn lanes_mut<const N: usize>(
    out: &mut [f32],
    base: usize,
    stride: usize,
    len: usize,
) -> [&mut [f32]; N] {
    let mut rest = &mut out[base..];
    std::array::from_fn(|i| {
        let r = std::mem::take(&mut rest);
        let (lane, tail) = r.split_at_mut(if i + 1 < N { stride } else { len });
        rest = tail;
        &mut lane[..len]
    })
}

/// Six `len`-long input lanes of `buf`, at `base + r·stride`.
#[inline(always)]
fn lanes(buf: &[f32], base: usize, stride: usize, len: usize) -> [&[f32]; 6] {
    std::array::from_fn(|r| &buf[base + r * stride..][..len])
}

/// `Bᵀ` applied lane-wise: `o_i[k] = (Bᵀ [s_0[k] … s_5[k]])_i`.
#[inline(always)]
fn bt_lanes(s: [&[f32]; 6], o: [&mut [f32]; 6]) {
    let len = o[0].len();
    let [o0, o1, o2, o3, o4, o5] = o;
    let s: [&[f32]; 6] = std::array::from_fn(|r| &s[r][..len]);
    for k in 0..len {
        let v = bt([s[0][k], s[1][k], s[2][k], s[3][k], s[4][k], s[5][k]]);
        o0[k] = v[0];
        o1[k] = v[1];
        o2[k] = v[2];
        o3[k] = v[3];
        o4[k] = v[4];
        o5[k] = v[5];
    }
}

/// `Aᵀ` applied lane-wise: `o_i[k] = (Aᵀ [s_0[k] … s_5[k]])_i`.
#[inline(always)]
fn at_lanes(s: [&[f32]; 6], o: [&mut [f32]; 4]) {
    let len = o[0].len();
    let [o0, o1, o2, o3] = o;
    let s: [&[f32]; 6] = std::array::from_fn(|r| &s[r][..len]);
    for k in 0..len {
        let v = at([s[0][k], s[1][k], s[2][k], s[3][k], s[4][k], s[5][k]]);
        o0[k] = v[0];
        o1[k] = v[1];
        o2[k] = v[2];
        o3[k] = v[3];
    }
}

/// `G` (6×3), applied in f64 at load.
const G: [[f64; 3]; 6] = [
    [0.25, 0.0, 0.0],
    [-1.0 / 6.0, -1.0 / 6.0, -1.0 / 6.0],
    [-1.0 / 6.0, 1.0 / 6.0, -1.0 / 6.0],
    [1.0 / 24.0, 1.0 / 12.0, 1.0 / 6.0],
    [1.0 / 24.0, -1.0 / 12.0, 1.0 / 6.0],
    [0.0, 0.0, 1.0],
];

/// A 3×3 stride-1 convolution's weights, transformed and packed.
#[derive(Clone)]
pub(crate) struct Winograd {
    c_in: usize,
    c_out: usize,
    pad: usize,
    u: Vec<PackedA>,
}

/// `V[ξ]` inside the `[ci][ξ][tile]` buffer: row `ci` at `(ci·36 + ξ)·tiles`.
struct TransformedInput<'a> {
    v: &'a [f32],
    xi: usize,
    tiles: usize,
}

impl BSource for TransformedInput<'_> {
    fn pack(&self, k0: usize, kc: usize, n0: usize, cols: usize, nr: usize, dst: &mut [f32]) {
        for kk in 0..kc {
            let row = ((k0 + kk) * T * T + self.xi) * self.tiles;
            let src = &self.v[row + n0..row + n0 + cols];
            for (p, chunk) in src.chunks(nr).enumerate() {
                let d = &mut dst[(p * kc + kk) * nr..(p * kc + kk + 1) * nr];
                copy_short(&mut d[..chunk.len()], chunk);
                zero_short(&mut d[chunk.len()..]);
            }
        }
    }
}

impl Winograd {
    /// Transforms `weight` (`[c_out, c_in, 3, 3]`) for padding `pad`.
    pub(crate) fn new(
        kernel: MicroKernel,
        c_in: usize,
        c_out: usize,
        pad: usize,
        weight: &[f32],
    ) -> Self {
        let mut u = vec![vec![0.0f32; c_out * c_in]; T * T];
        for co in 0..c_out {
            for ci in 0..c_in {
                let g = &weight[(co * c_in + ci) * 9..][..9];
                // G g (6×3), then (G g) Gᵀ (6×6)
                let mut gg = [[0.0f64; 3]; T];
                for (i, row) in gg.iter_mut().enumerate() {
                    for (j, v) in row.iter_mut().enumerate() {
                        *v = (0..3).map(|k| G[i][k] * g[k * 3 + j] as f64).sum();
                    }
                }
                for i in 0..T {
                    for j in 0..T {
                        let v: f64 = (0..3).map(|k| gg[i][k] * G[j][k]).sum();
                        u[i * T + j][co * c_in + ci] = v as f32;
                    }
                }
            }
        }
        let u = u
            .iter()
            .map(|m| PackedA::pack(kernel, c_out, c_in, |r, c| m[r * c_in + c]))
            .collect();
        Self {
            c_in,
            c_out,
            pad,
            u,
        }
    }

    /// One image: `x` is `[c_in, h, w]`, `out` is `[c_out, oh, ow]`.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn forward_image(
        &self,
        x: &[f32],
        h: usize,
        w: usize,
        bias: Option<&[f32]>,
        act: Activation,
        residual: Option<&[f32]>,
        out: &mut [f32],
    ) {
        let p = self.pad as isize;
        let (oh, ow) = (h + 2 * self.pad - 2, w + 2 * self.pad - 2);
        let (th, tw) = (oh.div_ceil(M), ow.div_ceil(M));
        let tiles = th * tw;
        let mut v = crate::pool::take(self.c_in * T * T * tiles);
        let mut m = crate::pool::take(self.c_out * T * T * tiles);

        // Input transform, one channel per task: V[ci][ξ][tile]. A whole row of
        // tiles at a time: gather d[r][c][tx], then Bᵀ over r and over c with the
        // tiles in the lanes, so every step is a contiguous, vectorisable loop.
        v.par_chunks_mut(T * T * tiles)
            .enumerate()
            .for_each(|(ci, vc)| {
                let plane = &x[ci * h * w..(ci + 1) * h * w];
                let mut d = vec![0.0f32; T * T * tw];
                let mut t1 = vec![0.0f32; T * T * tw];
                for ty in 0..th {
                    // d[(r·6 + c)·tw + tx] = x[4ty − p + r][4tx − p + c]
                    for r in 0..T {
                        let iy = (ty * M + r) as isize - p;
                        let rows = &mut d[r * T * tw..(r + 1) * T * tw];
                        if iy < 0 || iy >= h as isize {
                            rows.fill(0.0);
                            continue;
                        }
                        let src = &plane[iy as usize * w..(iy as usize + 1) * w];
                        for (c, dst) in rows.chunks_exact_mut(tw).enumerate() {
                            // ix = 4·tx + off lies in [0, w) for tx in [lo, hi)
                            let off = c as isize - p;
                            let lo = ((-off).max(0) as usize).div_ceil(M).min(tw);
                            let hi = ((w as isize - off).max(0) as usize)
                                .div_ceil(M)
                                .clamp(lo, tw);
                            dst[..lo].fill(0.0);
                            let first = (lo * M) as isize + off;
                            for (k, o) in dst[lo..hi].iter_mut().enumerate() {
                                *o = src[first as usize + k * M];
                            }
                            dst[hi..].fill(0.0);
                        }
                    }
                    // t1[(c·6 + i)·tw + tx] = Σ_r Bᵀ[i][r] d[r][c]
                    for c in 0..T {
                        bt_lanes(
                            lanes(&d, c * tw, T * tw, tw),
                            lanes_mut(&mut t1, c * T * tw, tw, tw),
                        );
                    }
                    // V[ξ = 6i + j][ty·tw + tx] = Σ_c Bᵀ[j][c] t1[c][i]
                    for i in 0..T {
                        bt_lanes(
                            lanes(&t1, i * tw, T * tw, tw),
                            lanes_mut(vc, i * T * tiles + ty * tw, tiles, tw),
                        );
                    }
                }
            });

        // The 36 independent products M[ξ] = U[ξ] · V[ξ].
        let none = Epilogue {
            bias: None,
            act: Activation::None,
            residual: None,
        };
        let v_ref = &v;
        m.par_chunks_mut(self.c_out * tiles)
            .enumerate()
            .for_each(|(xi, mc)| {
                let src = TransformedInput {
                    v: v_ref,
                    xi,
                    tiles,
                };
                gemm_serial(&self.u[xi], &src, tiles, mc, &none);
            });

        // Output transform per output channel, a row of tiles at a time with the
        // tiles in the lanes, fused with bias, activation and residual.
        let m_ref = &m;
        out.par_chunks_mut(oh * ow)
            .enumerate()
            .for_each(|(co, plane)| {
                let b = bias.map_or(0.0, |b| b[co]);
                let mut t1 = vec![0.0f32; T * M * tw];
                let mut y = vec![0.0f32; M * M * tw];
                let xi_stride = self.c_out * tiles;
                for ty in 0..th {
                    let base = co * tiles + ty * tw;
                    // t1[(c·4 + i)·tw] = Σ_r Aᵀ[i][r] M[ξ = 6r + c]
                    for c in 0..T {
                        at_lanes(
                            lanes(m_ref, base + c * xi_stride, T * xi_stride, tw),
                            lanes_mut(&mut t1, c * M * tw, tw, tw),
                        );
                    }
                    // y[(i·4 + j)·tw] = Σ_c Aᵀ[j][c] t1[c][i]
                    for i in 0..M {
                        at_lanes(
                            lanes(&t1, i * tw, M * tw, tw),
                            lanes_mut(&mut y, i * M * tw, tw, tw),
                        );
                    }
                    for i in 0..M {
                        let oy = ty * M + i;
                        if oy >= oh {
                            break;
                        }
                        let orow = &mut plane[oy * ow..(oy + 1) * ow];
                        let rrow = residual.map(|r| &r[(co * oh + oy) * ow..][..ow]);
                        for j in 0..M {
                            let yl = &y[(i * M + j) * tw..][..tw];
                            for (tx, &val) in yl.iter().enumerate() {
                                let ox = tx * M + j;
                                if ox >= ow {
                                    break;
                                }
                                let mut r = act.apply_one(val + b);
                                if let Some(rr) = rrow {
                                    r += rr[ox];
                                }
                                orow[ox] = r;
                            }
                        }
                    }
                }
            });
        crate::pool::give(v);
        crate::pool::give(m);
    }
}
