//! Direct stride-1 convolution for layers with very few output channels (the
//! networks' 7×7 → 3-channel output convs), vectorised along the output row.
//!
//! The packed GEMM would waste most of each `MR`-row tile on such layers and
//! spend its time building an im2col panel for 3 rows of weights; here each
//! block of [`XB`] outputs of a row keeps `CO × XB` accumulators in registers
//! and walks every input channel and tap once.

use rayon::prelude::*;

use crate::activation::Activation;
use crate::isa::Isa;

/// Outputs per block along a row.
pub(crate) const XB: usize = 64;
/// Most output channels the direct path takes.
pub(crate) const MAX_CO: usize = 4;

/// Geometry of one direct convolution (stride 1, padding already applied).
#[derive(Clone, Copy)]
pub(crate) struct DirectProblem<'a> {
    pub(crate) x: &'a [f32],
    pub(crate) c_in: usize,
    pub(crate) h: usize,
    pub(crate) w: usize,
    pub(crate) kh: usize,
    pub(crate) kw: usize,
    pub(crate) oh: usize,
    pub(crate) ow: usize,
}

#[inline(always)]
fn madd<const FMA: bool>(a: f32, b: f32, c: f32) -> f32 {
    if FMA {
        a.mul_add(b, c)
    } else {
        a * b + c
    }
}

/// One output row `oy` of `CO` channels; `wt` is `[CO][c_in][kh][kw]`.
#[inline(always)]
fn row<const CO: usize, const FMA: bool>(
    p: &DirectProblem<'_>,
    wt: &[f32],
    oy: usize,
    out: &mut [&mut [f32]],
) {
    let (h, w, kk) = (p.h, p.w, p.kh * p.kw);
    let mut x0 = 0;
    while x0 < p.ow {
        let len = XB.min(p.ow - x0);
        let mut acc = [[0.0f32; XB]; CO];
        for ci in 0..p.c_in {
            let plane = &p.x[ci * h * w..(ci + 1) * h * w];
            for ky in 0..p.kh {
                let src = &plane[(oy + ky) * w..(oy + ky + 1) * w];
                for kx in 0..p.kw {
                    let tap = ci * kk + ky * p.kw + kx;
                    if len == XB {
                        let r: &[f32; XB] = src[x0 + kx..x0 + kx + XB].try_into().expect("XB");
                        for (co, a) in acc.iter_mut().enumerate() {
                            let wv = wt[co * p.c_in * kk + tap];
                            for t in 0..XB {
                                a[t] = madd::<FMA>(wv, r[t], a[t]);
                            }
                        }
                    } else {
                        let r = &src[x0 + kx..x0 + kx + len];
                        for (co, a) in acc.iter_mut().enumerate() {
                            let wv = wt[co * p.c_in * kk + tap];
                            for t in 0..len {
                                a[t] = madd::<FMA>(wv, r[t], a[t]);
                            }
                        }
                    }
                }
            }
        }
        for (co, a) in acc.iter().enumerate() {
            out[co][x0..x0 + len].copy_from_slice(&a[..len]);
        }
        x0 += len;
    }
}

#[inline(always)]
fn rows_generic<const FMA: bool>(
    p: &DirectProblem<'_>,
    co: usize,
    wt: &[f32],
    oy: usize,
    out: &mut [&mut [f32]],
) {
    match co {
        1 => row::<1, FMA>(p, wt, oy, out),
        2 => row::<2, FMA>(p, wt, oy, out),
        3 => row::<3, FMA>(p, wt, oy, out),
        _ => row::<4, FMA>(p, wt, oy, out),
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx2,fma")]
unsafe fn rows_avx512(
    p: &DirectProblem<'_>,
    co: usize,
    wt: &[f32],
    oy: usize,
    out: &mut [&mut [f32]],
) {
    rows_generic::<true>(p, co, wt, oy, out)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn rows_avx2(
    p: &DirectProblem<'_>,
    co: usize,
    wt: &[f32],
    oy: usize,
    out: &mut [&mut [f32]],
) {
    rows_generic::<true>(p, co, wt, oy, out)
}

/// `out[co] = act(conv(x, wt)[co] + bias[co])` for `co < c_out ≤ MAX_CO`;
/// `out` is `[c_out][oh][ow]`.
pub(crate) fn conv_direct(
    isa: Isa,
    p: &DirectProblem<'_>,
    c_out: usize,
    wt: &[f32],
    bias: Option<&[f32]>,
    act: Activation,
    out: &mut [f32],
) {
    assert!(
        (1..=MAX_CO).contains(&c_out),
        "direct conv takes 1..={MAX_CO} output channels"
    );
    assert_eq!(out.len(), c_out * p.oh * p.ow);
    let plane = p.oh * p.ow;
    // Rows of each output plane, grouped by output row so one task writes row `oy` of every channel.
    let mut planes: Vec<&mut [f32]> = out.chunks_mut(plane).collect();
    let mut rows: Vec<Vec<&mut [f32]>> = (0..p.oh).map(|_| Vec::with_capacity(c_out)).collect();
    for pl in planes.iter_mut() {
        for (oy, r) in pl.chunks_mut(p.ow).enumerate() {
            rows[oy].push(r);
        }
    }
    rows.par_iter_mut().enumerate().for_each(|(oy, r)| {
        match isa {
            // SAFETY: the family was checked available when the layer was built.
            #[cfg(target_arch = "x86_64")]
            Isa::Avx512 => unsafe { rows_avx512(p, c_out, wt, oy, r) },
            #[cfg(target_arch = "x86_64")]
            Isa::Avx2Fma => unsafe { rows_avx2(p, c_out, wt, oy, r) },
            _ => rows_generic::<false>(p, c_out, wt, oy, r),
        }
        for (co, v) in r.iter_mut().enumerate() {
            if let Some(b) = bias {
                v.iter_mut().for_each(|x| *x += b[co]);
            }
            act.apply(v);
        }
    });
}
