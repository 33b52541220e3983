//! Bilinear resize with PyTorch `align_corners=False` semantics (no antialiasing).

use rayon::prelude::*;

use crate::error::{invalid, Result};
use crate::tensor::Tensor;

/// Source sample of output index `i`: `(i0, i1, weight of i1)`, as PyTorch's
/// `area_pixel_compute_source_index` with `align_corners=False`.
pub(crate) fn source_taps(i: usize, in_len: usize, out_len: usize) -> (usize, usize, f32) {
    let scale = in_len as f64 / out_len as f64;
    let src = ((i as f64 + 0.5) * scale - 0.5).max(0.0);
    let i0 = (src.floor() as usize).min(in_len - 1);
    let i1 = if i0 < in_len - 1 { i0 + 1 } else { i0 };
    let l1 = (src - i0 as f64) as f32;
    (i0, i1, l1)
}

/// Resizes every plane to `oh × ow` (PyTorch `F.interpolate(mode="bilinear",
/// align_corners=False)` with an explicit size).
pub fn resize_bilinear(x: &Tensor, oh: usize, ow: usize) -> Result<Tensor> {
    if oh == 0 || ow == 0 || x.h() == 0 || x.w() == 0 {
        return Err(invalid(
            "resize_bilinear",
            format!("sizes must be positive: {}x{} -> {oh}x{ow}", x.h(), x.w()),
        ));
    }
    let (h, w) = (x.h(), x.w());
    let ys: Vec<_> = (0..oh).map(|i| source_taps(i, h, oh)).collect();
    let xs: Vec<_> = (0..ow).map(|j| source_taps(j, w, ow)).collect();
    let mut out = Tensor::for_overwrite([x.n(), x.c(), oh, ow]);
    let src = x.data();
    out.data_mut()
        .par_chunks_mut(oh * ow)
        .enumerate()
        .for_each(|(p, dst)| {
            let plane = &src[p * h * w..(p + 1) * h * w];
            let mut tmp0 = vec![0.0f32; ow];
            let mut tmp1 = vec![0.0f32; ow];
            for (drow, &(y0, y1, ly)) in dst.chunks_exact_mut(ow).zip(&ys) {
                let (r0, r1) = (&plane[y0 * w..(y0 + 1) * w], &plane[y1 * w..(y1 + 1) * w]);
                for (j, &(x0, x1, lx)) in xs.iter().enumerate() {
                    tmp0[j] = (1.0 - lx) * r0[x0] + lx * r0[x1];
                    tmp1[j] = (1.0 - lx) * r1[x0] + lx * r1[x1];
                }
                for ((d, a), b) in drow.iter_mut().zip(&tmp0).zip(&tmp1) {
                    *d = (1.0 - ly) * a + ly * b;
                }
            }
        });
    Ok(out)
}
