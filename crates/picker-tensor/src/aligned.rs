//! A growable f32 buffer whose start is aligned to [`crate::params::ALIGN`] bytes.

use crate::params::{ALIGN, HUGE_PAGE_MIN_BYTES};

/// A zero-filled `Vec` of `len` floats. Large ones ask the kernel for
/// transparent huge pages (Linux `madvise(MADV_HUGEPAGE)`, before the pages
/// are first touched): the weights and activations are streamed in MiB-sized
/// sweeps, and with 4 KiB pages nearly every page of them misses the TLB.
/// Elsewhere, or when the kernel refuses, the pages are the ordinary ones.
pub(crate) fn zeroed_vec(len: usize) -> Vec<f32> {
    let bytes = len * std::mem::size_of::<f32>();
    if bytes < HUGE_PAGE_MIN_BYTES {
        return vec![0.0; len];
    }
    let mut v: Vec<f32> = Vec::with_capacity(len);
    advise_huge(v.as_ptr() as usize, bytes);
    v.resize(len, 0.0);
    v
}

/// `madvise(MADV_HUGEPAGE)` on the whole pages inside `[addr, addr + bytes)`;
/// a hint, so a failure is ignored.
#[cfg(target_os = "linux")]
fn advise_huge(addr: usize, bytes: usize) {
    const PAGE: usize = 4096;
    let start = addr.div_ceil(PAGE) * PAGE;
    let end = (addr + bytes) / PAGE * PAGE;
    if end > start {
        // SAFETY: the range lies inside an allocation this process owns;
        // MADV_HUGEPAGE changes no contents and no mapping.
        unsafe {
            libc::madvise(start as *mut libc::c_void, end - start, libc::MADV_HUGEPAGE);
        }
    }
}

/// No huge-page hint outside Linux.
#[cfg(not(target_os = "linux"))]
fn advise_huge(_addr: usize, _bytes: usize) {}

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
            self.raw = zeroed_vec(len + pad);
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn zeroed_vecs_are_zero_at_every_size() {
        for len in [
            0,
            1,
            1000,
            HUGE_PAGE_MIN_BYTES / 4 - 1,
            HUGE_PAGE_MIN_BYTES / 4 + 3,
            3 << 20,
        ] {
            let v = zeroed_vec(len);
            assert_eq!(v.len(), len);
            assert!(v.iter().all(|&x| x == 0.0), "len {len}");
        }
        let mut b = AlignedBuf::zeroed(5 << 20);
        assert_eq!(b.as_slice().as_ptr() as usize % ALIGN, 0);
        b.as_mut_slice()[7] = 1.0;
        b.resize_zeroed(5 << 20);
        assert!(b.as_slice().iter().all(|&x| x == 0.0));
    }
}
