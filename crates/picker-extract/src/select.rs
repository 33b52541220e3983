//! Order statistics of large sets of values without sorting or copying them.
//!
//! [`kth_smallest`] gives the value that
//! `*values.select_nth_unstable_by(k, f32::total_cmp).1` gives (the `k`-th
//! smallest in IEEE-754 total order), by two parallel radix-histogram passes
//! over the values: the high 16 bits of each value's order-preserving key find
//! the bucket holding rank `k`, the low 16 bits inside that bucket the value.
//! Counts are integers, so the answer does not depend on how the work is
//! split (the same bits whatever the thread count). The values come from a
//! function of the index, so photo-resolution quantities need not be
//! collected into a vector first.

use rayon::prelude::*;

/// Fewest indices per histogram range (each range fills its own 512 KiB histogram).
const MIN_JOB: usize = 1 << 16;

/// The order-preserving key of `x` under [`f32::total_cmp`] (the same bit
/// transform, made unsigned).
#[inline]
fn key(x: f32) -> u32 {
    let mut bits = x.to_bits() as i32;
    bits ^= (((bits >> 31) as u32) >> 1) as i32;
    (bits as u32) ^ 0x8000_0000
}

/// The value whose [`key`] is `k`.
#[inline]
fn value_of(k: u32) -> f32 {
    let mut bits = (k ^ 0x8000_0000) as i32;
    bits ^= (((bits >> 31) as u32) >> 1) as i32;
    f32::from_bits(bits as u32)
}

/// Indices per block of the interleaved ranges in [`histogram`].
const STRIPE: usize = 4096;

/// A 65 536-bucket histogram of `bucket(i)` over the indices `0..n` whose
/// bucket is `Some`, in parallel: one histogram per range of at least
/// [`MIN_JOB`] indices, at most two ranges per thread, so only a few
/// 512 KiB histograms are made (a fold would make one per rayon job, and
/// each is a fresh, page-faulting allocation). The ranges interleave in
/// blocks of [`STRIPE`] indices (range `r` takes blocks `r`, `r + R`, …):
/// the values are often a photo's pixels where only a region has one (a
/// mask), and contiguous ranges then gave one thread most of the work (at
/// 12 MP, ~30 ms of each sizing pass on one thread).
fn histogram(n: usize, bucket: impl Fn(usize) -> Option<u16> + Sync) -> Vec<u64> {
    let ranges = n
        .div_ceil(MIN_JOB)
        .clamp(1, 2 * rayon::current_num_threads().max(1));
    (0..ranges)
        .into_par_iter()
        .map(|r| {
            let mut h = vec![0u64; 1 << 16];
            for start in (r * STRIPE..n).step_by(ranges * STRIPE) {
                for i in start..(start + STRIPE).min(n) {
                    if let Some(b) = bucket(i) {
                        h[b as usize] += 1;
                    }
                }
            }
            h
        })
        .reduce(
            || vec![0u64; 1 << 16],
            |mut a, b| {
                for (x, y) in a.iter_mut().zip(&b) {
                    *x += y;
                }
                a
            },
        )
}

/// The bucket holding rank `k` of `hist` and the rank within it.
fn locate(hist: &[u64], k: u64) -> (usize, u64) {
    let mut below = 0u64;
    for (b, &c) in hist.iter().enumerate() {
        if k < below + c {
            return (b, k - below);
        }
        below += c;
    }
    unreachable!("rank {k} beyond the {below} values counted")
}

/// The values `value(i)` for `i` in `0..n` (those that are `Some`), and for
/// each rank that `ranks(count)` gives (0-based, each `< count`), the value
/// of that rank in [`f32::total_cmp`] order — what
/// `select_nth_unstable_by(rank, f32::total_cmp)` on the collected values
/// would give. `None` when no value is `Some` or `ranks` says so.
///
/// `value` is called once per index and pass (twice, plus once per further
/// rank), so it should be cheap.
pub fn kth_smallest(
    n: usize,
    value: impl Fn(usize) -> Option<f32> + Sync,
    ranks: impl FnOnce(usize) -> Option<Vec<usize>>,
) -> Option<Vec<f32>> {
    let high = histogram(n, |i| value(i).map(|x| (key(x) >> 16) as u16));
    let count = high.iter().sum::<u64>() as usize;
    if count == 0 {
        return None;
    }
    let ranks = ranks(count)?;
    Some(
        ranks
            .into_iter()
            .map(|k| {
                assert!(k < count, "rank {k} of {count} values");
                let (b, r) = locate(&high, k as u64);
                let low = histogram(n, |i| {
                    value(i)
                        .map(key)
                        .filter(|&x| (x >> 16) as usize == b)
                        .map(|x| x as u16)
                });
                let (l, _) = locate(&low, r);
                value_of(((b as u32) << 16) | l as u32)
            })
            .collect(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use picker_tensor::Rng;

    #[test]
    fn key_preserves_total_order_and_inverts() {
        let mut rng = Rng::new(2);
        let mut v: Vec<f32> = rng.uniform_vec(2000, -1e3, 1e3);
        v.extend([
            0.0,
            -0.0,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
            -f32::NAN,
            f32::MIN_POSITIVE,
            -f32::MIN_POSITIVE,
            f32::from_bits(1),
            f32::MAX,
            f32::MIN,
        ]);
        for &a in &v {
            assert_eq!(value_of(key(a)).to_bits(), a.to_bits());
            for &b in v.iter().step_by(37) {
                assert_eq!(key(a).cmp(&key(b)), a.total_cmp(&b), "{a} {b}");
            }
        }
    }

    #[test]
    fn histogram_counts_every_index_once() {
        // Range and stripe edges, for several thread counts (the ranges
        // depend on them): each index lands in its bucket exactly once.
        for threads in [1, 2, 3] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            for n in [
                0,
                1,
                STRIPE - 1,
                STRIPE,
                STRIPE + 1,
                MIN_JOB,
                MIN_JOB + 1,
                5 * MIN_JOB + 17,
                9 * MIN_JOB - 3,
            ] {
                // Only a band of the indices has a value (as a mask would).
                let bucket =
                    |i: usize| (i % 5 != 2 && i < n * 2 / 3).then_some((i * 31 % 65_536) as u16);
                let got = pool.install(|| histogram(n, bucket));
                let mut want = vec![0u64; 1 << 16];
                for b in (0..n).filter_map(bucket) {
                    want[b as usize] += 1;
                }
                assert!(got == want, "n {n}, {threads} threads");
            }
        }
    }

    #[test]
    fn matches_select_nth() {
        let mut rng = Rng::new(3);
        let specials = [0.0f32, -0.0, f32::NAN, -f32::NAN, f32::INFINITY, -1.5];
        for n in [1usize, 2, 3, 10, 1000, 70_000, 200_001] {
            for kind in 0..4 {
                let v: Vec<f32> = (0..n)
                    .map(|_| match kind {
                        // Wide range of signs and magnitudes.
                        0 => rng.uniform(-1.0, 1.0) * 10f32.powi(rng.range(0, 12) as i32 - 6),
                        // Few distinct values: big ties.
                        1 => rng.range(0, 3) as f32 * 0.25,
                        // A narrow range: everything in a few buckets.
                        2 => 0.5 + rng.uniform(0.0, 1e-4),
                        _ => specials[rng.range(0, specials.len() - 1)],
                    })
                    .collect();
                // Some indices have no value.
                let keep: Vec<bool> = (0..n).map(|i| i % 7 != 3).collect();
                let present: Vec<f32> = (0..n).filter(|&i| keep[i]).map(|i| v[i]).collect();
                if present.is_empty() {
                    assert_eq!(
                        kth_smallest(n, |i| keep[i].then(|| v[i]), |_| Some(vec![0])),
                        None
                    );
                    continue;
                }
                let m = present.len();
                let want: Vec<usize> = vec![0, m / 2, m - 1, (m - 1) * 3 / 4];
                let got = kth_smallest(
                    n,
                    |i| keep[i].then(|| v[i]),
                    |c| {
                        assert_eq!(c, m);
                        Some(want.clone())
                    },
                )
                .unwrap();
                for (&k, g) in want.iter().zip(got) {
                    let mut p = present.clone();
                    let e = *p.select_nth_unstable_by(k, f32::total_cmp).1;
                    assert_eq!(g.to_bits(), e.to_bits(), "n {n} kind {kind} rank {k}");
                }
            }
        }
        assert_eq!(kth_smallest(0, |_| Some(1.0), |_| Some(vec![0])), None);
        assert_eq!(kth_smallest(5, |_| Some(1.0), |_| None), None);
    }
}
