//! The dense f32 NCHW tensor every kernel works on.

use crate::error::{Error, Result};

/// A dense, contiguous, row-major f32 tensor of rank 4 in NCHW order
/// (batch, channels, height, width).
///
/// The elements are `buf[off..off + len]`: tensors the crate makes start on a
/// cache line (the kernels load 16 floats at a time, and a misaligned load
/// spans two lines), a wrapped `Vec` where it starts (`off = 0`). `buf` may
/// be longer than that (a reused buffer is kept whole, see
/// `pool::take_at_least`).
pub struct Tensor {
    shape: [usize; 4],
    buf: Vec<f32>,
    off: usize,
}

impl Drop for Tensor {
    fn drop(&mut self) {
        crate::pool::give(std::mem::take(&mut self.buf));
    }
}

impl Clone for Tensor {
    fn clone(&self) -> Self {
        let mut t = Self::for_overwrite(self.shape);
        t.data_mut().copy_from_slice(self.data());
        t
    }
}

impl PartialEq for Tensor {
    fn eq(&self, other: &Self) -> bool {
        self.shape == other.shape && self.data() == other.data()
    }
}

impl std::fmt::Debug for Tensor {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Tensor{:?}", self.shape)
    }
}

impl Tensor {
    /// Wraps `data` as a tensor of `shape`; refuses a length mismatch (and
    /// a shape whose element count overflows `usize`).
    pub fn new(shape: [usize; 4], data: Vec<f32>) -> Result<Self> {
        let Some(expected) = crate::conv::checked_product(&shape) else {
            return Err(crate::error::invalid(
                "tensor",
                format!("the element count of shape {shape:?} overflows"),
            ));
        };
        if data.len() != expected {
            return Err(Error::DataLength {
                shape,
                expected,
                found: data.len(),
            });
        }
        Ok(Self {
            shape,
            buf: data,
            off: 0,
        })
    }

    /// A tensor of zeros.
    ///
    /// # Panics
    /// When the element count of `shape` overflows `usize` (and, as for any
    /// allocation, aborts when memory runs out); [`Tensor::new`] refuses
    /// such shapes with an error instead.
    pub fn zeros(shape: [usize; 4]) -> Self {
        let mut t = Self::for_overwrite(shape);
        t.data_mut().fill(0.0);
        t
    }

    /// A tensor whose every element the caller overwrites before reading:
    /// its contents are unspecified (stale values of a reused buffer). Its
    /// elements start on a cache line.
    pub(crate) fn for_overwrite(shape: [usize; 4]) -> Self {
        let len = crate::conv::checked_product(&shape)
            .unwrap_or_else(|| panic!("tensor shape {shape:?}: the element count overflows"));
        let (buf, off) = crate::pool::take_aligned(len);
        Self { shape, buf, off }
    }

    /// A tensor filled by `f(n, c, y, x)`.
    ///
    /// # Panics
    /// As [`Tensor::zeros`].
    pub fn from_fn(
        shape: [usize; 4],
        mut f: impl FnMut(usize, usize, usize, usize) -> f32,
    ) -> Self {
        let len = crate::conv::checked_product(&shape)
            .unwrap_or_else(|| panic!("tensor shape {shape:?}: the element count overflows"));
        let mut data = Vec::with_capacity(len);
        for n in 0..shape[0] {
            for c in 0..shape[1] {
                for y in 0..shape[2] {
                    for x in 0..shape[3] {
                        data.push(f(n, c, y, x));
                    }
                }
            }
        }
        Self {
            shape,
            buf: data,
            off: 0,
        }
    }

    /// The shape `[n, c, h, w]`.
    pub fn shape(&self) -> [usize; 4] {
        self.shape
    }
    /// Batch size.
    pub fn n(&self) -> usize {
        self.shape[0]
    }
    /// Channels.
    pub fn c(&self) -> usize {
        self.shape[1]
    }
    /// Height.
    pub fn h(&self) -> usize {
        self.shape[2]
    }
    /// Width.
    pub fn w(&self) -> usize {
        self.shape[3]
    }
    /// Number of elements.
    pub fn len(&self) -> usize {
        self.shape.iter().product()
    }
    /// True when the tensor has no elements.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// The elements in NCHW order.
    pub fn data(&self) -> &[f32] {
        &self.buf[self.off..self.off + self.len()]
    }
    /// The elements in NCHW order, mutable.
    pub fn data_mut(&mut self) -> &mut [f32] {
        let (off, len) = (self.off, self.len());
        &mut self.buf[off..off + len]
    }
    /// Consumes the tensor, giving back its elements.
    pub fn into_data(mut self) -> Vec<f32> {
        let len = self.len();
        let mut v = std::mem::take(&mut self.buf);
        v.drain(..self.off);
        v.truncate(len);
        v
    }
    /// Element at `(n, c, y, x)`; panics when out of range (indexing, like slices).
    pub fn at(&self, n: usize, c: usize, y: usize, x: usize) -> f32 {
        self.data()[self.index(n, c, y, x)]
    }
    /// Flat index of `(n, c, y, x)`.
    pub fn index(&self, n: usize, c: usize, y: usize, x: usize) -> usize {
        let [_, cc, hh, ww] = self.shape;
        debug_assert!(c < cc && y < hh && x < ww);
        ((n * cc + c) * hh + y) * ww + x
    }
    /// The `h × w` plane of image `n`, channel `c`.
    pub fn plane(&self, n: usize, c: usize) -> &[f32] {
        let hw = self.shape[2] * self.shape[3];
        let o = (n * self.shape[1] + c) * hw;
        &self.data()[o..o + hw]
    }
    /// The `c × h × w` block of image `n`.
    pub fn image(&self, n: usize) -> &[f32] {
        let chw = self.shape[1] * self.shape[2] * self.shape[3];
        &self.data()[n * chw..(n + 1) * chw]
    }

    /// Every row mirrored left to right: element `(n, c, y, x)` of the result
    /// is `(n, c, y, w − 1 − x)` of `self`.
    pub fn mirror_w(&self) -> Tensor {
        let w = self.shape[3];
        let mut t = Self::for_overwrite(self.shape);
        if w > 0 {
            for (dst, src) in t.data_mut().chunks_mut(w).zip(self.data().chunks(w)) {
                for (d, s) in dst.iter_mut().zip(src.iter().rev()) {
                    *d = *s;
                }
            }
        }
        t
    }

    /// The window `[y0, y0+h) × [x0, x0+w)` of every plane.
    pub fn crop(&self, y0: usize, x0: usize, h: usize, w: usize) -> Result<Tensor> {
        let [n, c, hh, ww] = self.shape;
        let inside = |a: usize, len: usize, n: usize| a.checked_add(len).is_some_and(|e| e <= n);
        if !inside(y0, h, hh) || !inside(x0, w, ww) {
            return Err(crate::error::shape_err(
                "crop",
                "window",
                format!("inside {hh}x{ww}"),
                format!(
                    "rows {y0}..{} cols {x0}..{}",
                    y0.saturating_add(h),
                    x0.saturating_add(w)
                ),
            ));
        }
        let mut out = Vec::with_capacity(n * c * h * w);
        for p in 0..n * c {
            let plane = &self.data()[p * hh * ww..(p + 1) * hh * ww];
            for y in y0..y0 + h {
                out.extend_from_slice(&plane[y * ww + x0..y * ww + x0 + w]);
            }
        }
        Tensor::new([n, c, h, w], out)
    }

    /// Channels `[c0, c0+len)` of every image.
    pub fn channels(&self, c0: usize, len: usize) -> Result<Tensor> {
        let [n, c, h, w] = self.shape;
        if c0.checked_add(len).is_none_or(|e| e > c) {
            return Err(crate::error::shape_err(
                "channels",
                "range",
                format!("inside 0..{c}"),
                format!("{c0}..{}", c0.saturating_add(len)),
            ));
        }
        let hw = h * w;
        let mut out = Vec::with_capacity(n * len * hw);
        for b in 0..n {
            let o = (b * c + c0) * hw;
            out.extend_from_slice(&self.data()[o..o + len * hw]);
        }
        Tensor::new([n, len, h, w], out)
    }

    /// A copy as an `ndarray` array.
    pub fn to_ndarray(&self) -> ndarray::Array4<f32> {
        ndarray::Array4::from_shape_vec(self.shape, self.data().to_vec())
            .expect("shape and length agree by construction")
    }

    /// A tensor from any `ndarray` array of rank 4 (copied into NCHW order).
    pub fn from_ndarray(a: ndarray::ArrayView4<'_, f32>) -> Self {
        let d = a.dim();
        Self {
            shape: [d.0, d.1, d.2, d.3],
            buf: a.iter().copied().collect(),
            off: 0,
        }
    }

    /// Largest absolute element-wise difference to `other` (shapes must agree).
    pub fn max_abs_diff(&self, other: &Tensor) -> Result<f32> {
        if self.shape != other.shape {
            return Err(crate::error::shape_err(
                "max_abs_diff",
                "shape",
                format!("{:?}", self.shape),
                format!("{:?}", other.shape),
            ));
        }
        Ok(self
            .data()
            .iter()
            .zip(other.data())
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f32::max))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::params::ALIGN;

    fn aligned(t: &Tensor) -> bool {
        (t.data().as_ptr() as usize).is_multiple_of(ALIGN)
    }

    /// `mirror_w` reverses every row and nothing else, at every shape
    /// (one column, one row, empty); twice is the identity.
    #[test]
    fn mirror_w_reverses_the_rows() {
        let mut rng = crate::Rng::new(9);
        for &shape in &[
            [1, 1, 1, 1],
            [1, 3, 5, 7],
            [2, 2, 1, 6],
            [1, 4, 3, 1],
            [1, 2, 0, 3],
            [1, 2, 3, 0],
        ] {
            let len: usize = shape.iter().product();
            let t = Tensor::new(shape, rng.normal_vec(len, 1.0)).unwrap();
            let m = t.mirror_w();
            assert_eq!(m.shape(), shape);
            let [n, c, h, w] = shape;
            for ni in 0..n {
                for ci in 0..c {
                    for y in 0..h {
                        for x in 0..w {
                            assert_eq!(m.at(ni, ci, y, x), t.at(ni, ci, y, w - 1 - x), "{shape:?}");
                        }
                    }
                }
            }
            assert!(m.mirror_w() == t, "{shape:?}: twice");
            assert!(len == 0 || aligned(&m), "{shape:?}");
        }
    }

    /// Tensors the crate makes start on a cache line, at every size (small
    /// ones from the allocator, large ones from the pool, reused or not);
    /// clones too; equality, `into_data` and indexing see only the elements.
    #[test]
    fn made_tensors_start_on_a_cache_line() {
        let mut rng = crate::Rng::new(5);
        for &shape in &[
            [1, 1, 1, 1],
            [1, 3, 5, 7],
            [2, 64, 60, 80],
            [1, 256, 60, 80],
            [1, 1, 1 << 9, 1 << 9],
        ] {
            for _ in 0..3 {
                let mut t = Tensor::zeros(shape);
                assert!(aligned(&t), "zeros {shape:?}");
                assert_eq!(t.len(), shape.iter().product::<usize>());
                assert!(t.data().iter().all(|&v| v == 0.0));
                let values = rng.normal_vec(t.len(), 1.0);
                t.data_mut().copy_from_slice(&values);
                let u = Tensor::for_overwrite(shape);
                assert!(aligned(&u), "for_overwrite {shape:?}");
                let c = t.clone();
                assert!(aligned(&c), "clone {shape:?}");
                assert!(c == t, "clone equals");
                let [_, ch, h, w] = shape;
                assert_eq!(t.at(0, ch - 1, h - 1, w - 1), values[ch * h * w - 1]);
                assert_eq!(t.plane(0, ch - 1), &values[(ch - 1) * h * w..ch * h * w]);
                assert_eq!(c.into_data(), values, "into_data {shape:?}");
                drop(u);
            }
        }
        // A wrapped Vec stays where it is, and compares by its elements.
        let v: Vec<f32> = (0..24).map(|i| i as f32).collect();
        let a = Tensor::new([1, 2, 3, 4], v.clone()).unwrap();
        let mut b = Tensor::zeros([1, 2, 3, 4]);
        b.data_mut().copy_from_slice(&v);
        assert!(a == b);
        b.data_mut()[23] = 0.5;
        assert!(a != b);
        assert!(
            a != Tensor::new([1, 2, 4, 3], v.clone()).unwrap(),
            "shape counts"
        );
        assert_eq!(a.into_data(), v);
    }
}
