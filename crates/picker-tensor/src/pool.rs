//! A small process-wide pool of large f32 buffers, so a network's forward pass
//! reuses the memory of the activations it has dropped instead of asking the
//! OS for fresh (page-faulting, kernel-zeroed) pages for every layer.
//!
//! Only buffers of at least [`MIN_POOLED`] floats are pooled, at most
//! [`MAX_POOLED_BYTES`] in all; the rest go back to the allocator. Buffers
//! come back with stale contents: callers that need zeros fill them.

use std::sync::Mutex;

/// Smallest buffer worth pooling (1 MiB of f32).
pub const MIN_POOLED: usize = 1 << 18;
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

/// A buffer of exactly `len` floats whose contents are unspecified (but initialised).
pub(crate) fn take(len: usize) -> Vec<f32> {
    if len >= MIN_POOLED {
        let mut pool = POOL.lock().unwrap_or_else(|e| e.into_inner());
        // The smallest free buffer that fits, if it is not wastefully large.
        let best = pool
            .free
            .iter()
            .enumerate()
            .filter(|(_, v)| v.capacity() >= len && v.capacity() <= 2 * len)
            .min_by_key(|(_, v)| v.capacity())
            .map(|(i, _)| i);
        if let Some(i) = best {
            let mut v = pool.free.swap_remove(i);
            pool.bytes -= bytes_of(&v);
            drop(pool);
            if v.len() >= len {
                v.truncate(len);
            } else {
                v.resize(len, 0.0);
            }
            return v;
        }
    }
    vec![0.0; len]
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
