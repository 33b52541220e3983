//! A small process-wide pool of large f32 buffers, so a network's forward pass
//! reuses the memory of the activations it has dropped instead of asking the
//! OS for fresh (page-faulting, kernel-zeroed) pages for every layer.
//!
//! Only buffers of at least [`MIN_POOLED`] floats are pooled, at most
//! [`MAX_POOLED_BYTES`] in all; the rest go back to the allocator. Buffers
//! come back with stale contents: callers that need zeros fill them.

use std::sync::Mutex;

/// Smallest buffer worth pooling (128 KiB of f32; glibc's initial `mmap`
/// threshold). Was 1 MiB: a band of the EnvMap's head (its input window,
/// 246 KB, and its `down.0` rows, 614 KB) was then a fresh, zero-filled
/// allocation every time (`memset` ~0.8% of the net): the whole EnvMap
/// 0.965× and 0.969× the time (medians of 14 alternating rounds, 2 threads,
/// 240×320), the MSN and IRN within the noise (1.008×, 1.024×), the IRN's
/// peak RSS 557 → 552 MB.
pub const MIN_POOLED: usize = 1 << 15;
/// Most memory the pool keeps.
pub const MAX_POOLED_BYTES: usize = 256 << 20;

struct Pool {
    free: Vec<Vec<f32>>,
    bytes: usize,
}

static POOL: Mutex<Pool> = Mutex::new(Pool {
    free: Vec::new(),
    bytes: 0,
});

fn bytes_of(v: &Vec<f32>) -> usize {
    v.capacity() * std::mem::size_of::<f32>()
}

/// Takes out of the pool the free buffer with the smallest `size` (its
/// capacity or its length) in `len..=2·len`, if any: the smallest that
/// fits, if it is not wastefully large.
fn pop_best(len: usize, size: fn(&Vec<f32>) -> usize) -> Option<Vec<f32>> {
    if len < MIN_POOLED {
        return None;
    }
    let mut pool = POOL.lock().unwrap_or_else(|e| e.into_inner());
    let best = pool
        .free
        .iter()
        .enumerate()
        .filter(|(_, v)| (len..=2 * len).contains(&size(v)))
        .min_by_key(|(_, v)| size(v))
        .map(|(i, _)| i)?;
    let v = pool.free.swap_remove(best);
    pool.bytes -= bytes_of(&v);
    Some(v)
}

/// A buffer of exactly `len` floats whose contents are unspecified (but initialised).
pub(crate) fn take(len: usize) -> Vec<f32> {
    match pop_best(len, Vec::capacity) {
        Some(mut v) => {
            if v.len() >= len {
                v.truncate(len);
            } else {
                v.resize(len, 0.0);
            }
            v
        }
        None => vec![0.0; len],
    }
}

/// A buffer of at least `len` floats, all of them initialised, contents
/// unspecified: a pooled buffer whose length (not only capacity) covers
/// `len` is handed out whole, so none of it is zero-filled, where [`take`]
/// would fill the part between a shorter earlier use and `len`. For
/// callers that keep their own length (tensors, the Winograd `V` buffer);
/// give the buffer back whole so its length stays known.
pub(crate) fn take_at_least(len: usize) -> Vec<f32> {
    pop_best(len, Vec::len).unwrap_or_else(|| take(len))
}

/// [`take_at_least`] `len` floats from a cache line on: the buffer (give it
/// back whole) and the index where the aligned `len` floats start.
pub(crate) fn take_aligned(len: usize) -> (Vec<f32>, usize) {
    let buf = take_at_least(len + crate::aligned::ALIGN_FLOATS);
    let off = crate::aligned::aligned_offset(&buf);
    (buf, off)
}

/// Frees every buffer the pool keeps (see [`crate::release_buffers`]).
pub(crate) fn release() {
    let mut pool = POOL.lock().unwrap_or_else(|e| e.into_inner());
    pool.free = Vec::new();
    pool.bytes = 0;
}

/// Hands a buffer back (kept if large and the pool has room, else freed).
pub(crate) fn give(v: Vec<f32>) {
    if v.capacity() < MIN_POOLED {
        return;
    }
    let mut pool = POOL.lock().unwrap_or_else(|e| e.into_inner());
    let b = bytes_of(&v);
    if pool.bytes + b <= MAX_POOLED_BYTES {
        pool.bytes += b;
        pool.free.push(v);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `take` gives exactly the length asked for; `take_at_least` at least
    /// that and at most twice it (a pooled buffer handed out whole), and a
    /// buffer given back whole is handed out again without losing length.
    #[test]
    fn lengths_of_taken_buffers() {
        let n = MIN_POOLED + 123;
        for len in [n, n + 1, 2 * n, 3 * n / 2] {
            let v = take(len);
            assert_eq!(v.len(), len);
            give(v);
            let w = take_at_least(len);
            assert!(
                w.len() >= len && w.len() <= 2 * len,
                "{} for {len}",
                w.len()
            );
            give(w);
            // Smaller requests than what was given back.
            let u = take_at_least(len - 100);
            assert!(u.len() >= len - 100 && u.len() <= 2 * (len - 100));
            let t = take(len - 100);
            assert_eq!(t.len(), len - 100);
            give(u);
            give(t);
        }
        // Below the pooled size: plain allocations of the exact length.
        assert_eq!(take_at_least(10).len(), 10);
        assert_eq!(take(10).len(), 10);
    }
}
