//! A growable f32 buffer whose start is aligned to [`crate::params::ALIGN`] bytes.

use crate::params::ALIGN;

/// f32 storage aligned to a cache line; resizing keeps the alignment.
#[derive(Clone, Default)]
pub(crate) struct AlignedBuf {
    raw: Vec<f32>,
    off: usize,
    len: usize,
}

impl AlignedBuf {
    /// A zero-filled buffer of `len` floats.
    pub(crate) fn zeroed(len: usize) -> Self {
        let mut b = Self::default();
        b.resize_zeroed(len);
        b
    }

    /// Makes the buffer hold `len` floats, all zero.
    pub(crate) fn resize_zeroed(&mut self, len: usize) {
        let pad = ALIGN / std::mem::size_of::<f32>();
        if self.raw.len() < len + pad {
            self.raw = vec![0.0; len + pad];
        } else {
            self.raw.iter_mut().for_each(|v| *v = 0.0);
        }
        let addr = self.raw.as_ptr() as usize;
        self.off = (ALIGN - addr % ALIGN) % ALIGN / std::mem::size_of::<f32>();
        self.len = len;
    }

    /// Makes the buffer hold at least `len` floats without clearing them.
    pub(crate) fn ensure(&mut self, len: usize) {
        if self.len < len {
            self.resize_zeroed(len);
        }
    }

    pub(crate) fn as_slice(&self) -> &[f32] {
        &self.raw[self.off..self.off + self.len]
    }

    pub(crate) fn as_mut_slice(&mut self) -> &mut [f32] {
        &mut self.raw[self.off..self.off + self.len]
    }
}
