//! A growable f32 buffer whose start is aligned to [`crate::params::ALIGN`] bytes.

use crate::params::ALIGN;

/// f32 storage aligned to a cache line; resizing and cloning keep the
/// alignment.
#[derive(Default)]
pub(crate) struct AlignedBuf {
    raw: Vec<f32>,
    off: usize,
    len: usize,
}

impl Clone for AlignedBuf {
    /// A copy in a buffer of its own, aligned in turn (a derived clone would
    /// keep the offset that aligned the original's allocation, not the
    /// copy's).
    fn clone(&self) -> Self {
        Self::from_slice(self.as_slice())
    }
}

impl AlignedBuf {
    /// An aligned copy of `values`.
    pub(crate) fn from_slice(values: &[f32]) -> Self {
        let mut b = Self::zeroed(values.len());
        b.as_mut_slice().copy_from_slice(values);
        b
    }

    /// A zero-filled buffer of `len` floats.
    pub(crate) fn zeroed(len: usize) -> Self {
        let mut b = Self::default();
        b.resize_zeroed(len);
        b
    }

    /// Makes the buffer hold `len` floats, all zero.
    pub(crate) fn resize_zeroed(&mut self, len: usize) {
        if self.raw.len() < len + ALIGN_FLOATS {
            self.raw = vec![0.0; len + ALIGN_FLOATS];
        } else {
            self.raw.iter_mut().for_each(|v| *v = 0.0);
        }
        self.off = aligned_offset(&self.raw);
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

/// Floats in one alignment unit ([`ALIGN`] bytes).
pub(crate) const ALIGN_FLOATS: usize = ALIGN / std::mem::size_of::<f32>();

/// The first index of `buf` whose address is aligned to [`ALIGN`] bytes
/// (below [`ALIGN_FLOATS`]; a buffer taken `ALIGN_FLOATS` floats longer than
/// needed holds the needed length from there).
pub(crate) fn aligned_offset(buf: &[f32]) -> usize {
    let addr = buf.as_ptr() as usize;
    (ALIGN - addr % ALIGN) % ALIGN / std::mem::size_of::<f32>()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// New, grown, copied and cloned buffers start on a cache line and hold
    /// what they should.
    #[test]
    fn buffers_stay_aligned() {
        let at_line = |b: &AlignedBuf| (b.as_slice().as_ptr() as usize).is_multiple_of(ALIGN);
        for len in [0usize, 1, 15, 16, 17, 1000, 1 << 18, (1 << 20) + 3] {
            let mut b = AlignedBuf::zeroed(len);
            assert!(at_line(&b) && b.as_slice().len() == len, "zeroed {len}");
            let values: Vec<f32> = (0..len).map(|i| i as f32).collect();
            let c = AlignedBuf::from_slice(&values);
            assert!(
                at_line(&c) && c.as_slice() == &values[..],
                "from_slice {len}"
            );
            // Clones are made many times so that some allocation lands
            // 16 bytes past a line, as glibc's large blocks do.
            for _ in 0..4 {
                let d = c.clone();
                assert!(at_line(&d) && d.as_slice() == &values[..], "clone {len}");
            }
            b.ensure(len + 40);
            assert!(
                at_line(&b) && b.as_slice().len() == len + 40,
                "ensure {len}"
            );
        }
        let s = [0.0f32; 40];
        for start in 0..16 {
            let o = aligned_offset(&s[start..]);
            assert!(o < ALIGN_FLOATS);
            assert_eq!(s[start + o..].as_ptr() as usize % ALIGN, 0);
        }
    }
}
