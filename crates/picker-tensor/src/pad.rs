//! Reflection padding (PyTorch `ReflectionPad2d`) and its generalisation to
//! any pad width (mirror extension, used to pad network inputs of any size).

use rayon::prelude::*;

use crate::error::{shape_err, Result};
use crate::tensor::Tensor;

/// Pad widths `[top, bottom, left, right]`.
pub type Pads = [usize; 4];

/// Index into `0..n` of position `i` under mirror extension without repeating
/// the edge (`… 2 1 | 0 1 2 … n-1 | n-2 …`), periodic with period `2(n-1)`.
/// For `n == 1` every position maps to 0.
///
/// # Panics
/// When `n` is 0 (an empty axis has no index).
pub fn reflect_index(i: isize, n: usize) -> usize {
    assert!(n > 0, "reflect_index: an empty axis has no index");
    if n == 1 {
        return 0;
    }
    let period = 2 * (n as isize - 1);
    let m = i.rem_euclid(period);
    if m < n as isize {
        m as usize
    } else {
        (period - m) as usize
    }
}

/// How a padded copy (or a kernel that reads through padding) fills the
/// positions outside the image.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Fill {
    /// Zeros (PyTorch `Conv2d(padding=p)`).
    Zero,
    /// Reflection without repeating the edge (PyTorch `ReflectionPad2d`,
    /// each pad smaller than the side).
    Reflect,
}

/// The source index of position `q` of an axis of `n` values padded by `lo`
/// before it, `padded_len` positions in all: `q − lo` inside the image,
/// reflected (with [`Fill::Reflect`]) inside the padding, `None` (a zero)
/// for zero padding or past `padded_len`.
#[inline]
pub(crate) fn padded_source(
    q: usize,
    lo: usize,
    n: usize,
    padded_len: usize,
    fill: Fill,
) -> Option<usize> {
    let v = q as isize - lo as isize;
    if (0..n as isize).contains(&v) {
        Some(v as usize)
    } else if q < padded_len && fill == Fill::Reflect {
        Some(reflect_index(v, n))
    } else {
        None
    }
}

/// PyTorch `ReflectionPad2d`: every pad must be smaller than the padded axis.
pub fn reflect_pad(x: &Tensor, pads: Pads) -> Result<Tensor> {
    let [t, b, l, r] = pads;
    if t.max(b) >= x.h() || l.max(r) >= x.w() {
        return Err(shape_err(
            "reflect_pad",
            "pad widths",
            format!("smaller than the input {}x{}", x.h(), x.w()),
            format!("{pads:?}"),
        ));
    }
    Ok(mirror_pad(x, pads))
}

/// Mirror extension by any amount (equal to [`reflect_pad`] where that is defined).
///
/// # Panics
/// When the padded size overflows `usize`.
pub fn mirror_pad(x: &Tensor, pads: Pads) -> Tensor {
    let [t, b, l, r] = pads;
    let (h, w) = (x.h(), x.w());
    let grown = |n: usize, a: usize, b: usize| {
        n.checked_add(a)
            .and_then(|v| v.checked_add(b))
            .unwrap_or_else(|| panic!("mirror_pad: padding {pads:?} overflows the size"))
    };
    let (oh, ow) = (grown(h, t, b), grown(w, l, r));
    if x.is_empty() {
        return Tensor::zeros([x.n(), x.c(), oh, ow]);
    }
    let mut out = Tensor::for_overwrite([x.n(), x.c(), oh, ow]);
    let cols: Vec<usize> = (0..ow)
        .map(|j| reflect_index(j as isize - l as isize, w))
        .collect();
    let src = x.data();
    out.data_mut()
        .par_chunks_mut(oh * ow)
        .enumerate()
        .for_each(|(p, dst)| {
            let plane = &src[p * h * w..(p + 1) * h * w];
            for (i, drow) in dst.chunks_exact_mut(ow).enumerate() {
                let sy = reflect_index(i as isize - t as isize, h);
                let srow = &plane[sy * w..(sy + 1) * w];
                if l < ow && w <= ow - l {
                    drow[l..l + w].copy_from_slice(srow);
                    for j in (0..l).chain(l + w..ow) {
                        drow[j] = srow[cols[j]];
                    }
                } else {
                    for (d, &c) in drow.iter_mut().zip(&cols) {
                        *d = srow[c];
                    }
                }
            }
        });
    out
}
