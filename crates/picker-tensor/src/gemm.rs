//! The packed GEMM driver: `C[M×N] = A[M×K] · B[K×N]` followed by a fused
//! epilogue (bias per row, activation, residual add).
//!
//! A (the weights) is packed once, when a layer is built. B is packed per task
//! from a [`BSource`], which for convolutions reads the image directly
//! (implicit im2col), so the full im2col matrix is never materialised. Work is
//! split over column blocks of C (and, when there are too few, over row
//! blocks too) and run on the rayon pool.

use std::cell::RefCell;

use rayon::prelude::*;

use crate::activation::Activation;
use crate::aligned::AlignedBuf;
use crate::microkernel::MicroKernel;
use crate::params::{KC, MAX_PANELS_PER_TASK, TASKS_PER_THREAD};

/// A matrix packed into micro-kernel panels, for one kernel family.
#[derive(Clone)]
pub(crate) struct PackedA {
    pub(crate) kernel: MicroKernel,
    pub(crate) m: usize,
    pub(crate) k: usize,
    /// `(k0, kc, offset)` of each depth block.
    pub(crate) kblocks: Vec<(usize, usize, usize)>,
    /// Number of `MR`-row panels.
    pub(crate) m_panels: usize,
    /// The panels: depth block after depth block, each `m_panels` panels of `kc × MR`.
    pub(crate) data: AlignedBuf,
}

impl PackedA {
    /// Packs the `m × k` matrix whose element `(row, col)` is `at(row, col)`.
    pub(crate) fn pack(
        kernel: MicroKernel,
        m: usize,
        k: usize,
        at: impl Fn(usize, usize) -> f32,
    ) -> PackedA {
        Self::pack_with_depth(kernel, m, k, KC, at)
    }

    /// As [`PackedA::pack`], in depth blocks of `depth` columns.
    pub(crate) fn pack_with_depth(
        kernel: MicroKernel,
        m: usize,
        k: usize,
        depth: usize,
        at: impl Fn(usize, usize) -> f32,
    ) -> PackedA {
        let mr = kernel.mr;
        let m_panels = m.div_ceil(mr);
        let mut kblocks = Vec::new();
        let mut off = 0;
        let mut k0 = 0;
        while k0 < k {
            let kc = depth.min(k - k0);
            kblocks.push((k0, kc, off));
            off += m_panels * kc * mr;
            k0 += kc;
        }
        let mut data = AlignedBuf::zeroed(off);
        let d = data.as_mut_slice();
        for &(k0, kc, off) in &kblocks {
            for p in 0..m_panels {
                let base = off + p * kc * mr;
                for kk in 0..kc {
                    for r in 0..mr {
                        let row = p * mr + r;
                        if row < m {
                            d[base + kk * mr + r] = at(row, k0 + kk);
                        }
                    }
                }
            }
        }
        PackedA {
            kernel,
            m,
            k,
            kblocks,
            m_panels,
            data,
        }
    }
}

/// Where B comes from: anything that can pack a block of its columns.
pub(crate) trait BSource: Sync {
    /// Writes rows `[k0, k0+kc)` × columns `[n0, n0+cols)` into `dst` as
    /// `ceil(cols/nr)` consecutive panels of `kc` rows of `nr` floats; the
    /// columns of the last panel past `cols` must be zero.
    fn pack(&self, k0: usize, kc: usize, n0: usize, cols: usize, nr: usize, dst: &mut [f32]);
}

/// A plain row-major `k × n` matrix.
pub(crate) struct DenseB<'a> {
    pub(crate) data: &'a [f32],
    pub(crate) n: usize,
}

impl BSource for DenseB<'_> {
    fn pack(&self, k0: usize, kc: usize, n0: usize, cols: usize, nr: usize, dst: &mut [f32]) {
        let panels = cols.div_ceil(nr);
        for kk in 0..kc {
            let src = &self.data[(k0 + kk) * self.n + n0..][..cols];
            for (p, chunk) in src.chunks(nr).enumerate() {
                let row = &mut dst[(p * kc + kk) * nr..(p * kc + kk + 1) * nr];
                row[..chunk.len()].copy_from_slice(chunk);
                row[chunk.len()..].fill(0.0);
            }
        }
        debug_assert!(panels * kc * nr <= dst.len());
    }
}

/// What happens to each output element after the product, in this order:
/// `+ bias[row]`, the activation, `+ residual`.
pub(crate) struct Epilogue<'a> {
    pub(crate) bias: Option<&'a [f32]>,
    pub(crate) act: Activation,
    pub(crate) residual: Option<&'a [f32]>,
}

struct SharedPtr(*mut f32);
// SAFETY: tasks write disjoint tiles of C; see `gemm`.
unsafe impl Sync for SharedPtr {}
unsafe impl Send for SharedPtr {}

thread_local! {
    static B_PACK: RefCell<AlignedBuf> = RefCell::new(AlignedBuf::default());
}

/// `c = epilogue(a · b)` with `c` row-major `a.m × n`, on the rayon pool.
pub(crate) fn gemm<B: BSource>(a: &PackedA, b: &B, n: usize, c: &mut [f32], epi: &Epilogue<'_>) {
    gemm_on(a, b, n, c, epi, rayon::current_num_threads().max(1));
}

fn gemm_on<B: BSource>(
    a: &PackedA,
    b: &B,
    n: usize,
    c: &mut [f32],
    epi: &Epilogue<'_>,
    threads: usize,
) {
    let (m, mr, nr) = (a.m, a.kernel.mr, a.kernel.nr);
    assert_eq!(c.len(), m * n, "gemm: C has the wrong length");
    if let Some(r) = epi.residual {
        assert_eq!(r.len(), m * n, "gemm: residual has the wrong length");
    }
    if let Some(bias) = epi.bias {
        assert_eq!(bias.len(), m, "gemm: bias has the wrong length");
    }
    if m == 0 || n == 0 {
        return;
    }
    if a.k == 0 {
        c.fill(0.0);
        apply_epilogue(c, n, 0, m, 0, n, epi);
        return;
    }
    let n_panels = n.div_ceil(nr);
    let target = if threads == 1 {
        1
    } else {
        threads * TASKS_PER_THREAD
    };
    let per_task = n_panels.div_ceil(target).clamp(1, MAX_PANELS_PER_TASK);
    let n_tasks = n_panels.div_ceil(per_task);
    // Splitting M too makes every row block pack the same B again, so only do
    // it when there are fewer column tasks than threads.
    let m_split = if n_tasks < threads {
        (2 * threads).div_ceil(n_tasks).min(a.m_panels)
    } else {
        1
    };
    let m_per_split = a.m_panels.div_ceil(m_split);
    let m_split = a.m_panels.div_ceil(m_per_split);
    let c_ptr = SharedPtr(c.as_mut_ptr());
    let c_ptr = &c_ptr;

    let task = |t: usize| {
        let (nt, ms) = (t / m_split, t % m_split);
        let p0 = nt * per_task;
        let p1 = (p0 + per_task).min(n_panels);
        let mp0 = ms * m_per_split;
        let mp1 = (mp0 + m_per_split).min(a.m_panels);
        B_PACK.with(|buf| {
            let mut buf = buf.borrow_mut();
            buf.ensure((p1 - p0) * KC.min(a.k) * nr);
            let bbuf = buf.as_mut_slice();
            let mut tmp = [0.0f32; 8 * 48];
            let last = a.kblocks.len() - 1;
            for (bi, &(k0, kc, aoff)) in a.kblocks.iter().enumerate() {
                let cols = (p1 * nr).min(n) - p0 * nr;
                b.pack(k0, kc, p0 * nr, cols, nr, &mut bbuf[..(p1 - p0) * kc * nr]);
                for (j, p) in (p0..p1).enumerate() {
                    let col0 = p * nr;
                    let cols = nr.min(n - col0);
                    let bp = bbuf[j * kc * nr..].as_ptr();
                    for mp in mp0..mp1 {
                        let row0 = mp * mr;
                        let rows = mr.min(m - row0);
                        let ap = a.data.as_slice()[aoff + mp * kc * mr..].as_ptr();
                        // SAFETY: (row0, col0) tiles are disjoint between tasks; the
                        // tile lies inside C when full, else goes through `tmp`.
                        unsafe {
                            let cp = c_ptr.0.add(row0 * n + col0);
                            if rows == mr && cols == nr {
                                (a.kernel.run)(kc, ap, bp, cp, n, bi > 0);
                            } else {
                                let t = &mut tmp[..mr * nr];
                                t.fill(0.0);
                                if bi > 0 {
                                    for r in 0..rows {
                                        let src = std::slice::from_raw_parts(cp.add(r * n), cols);
                                        t[r * nr..r * nr + cols].copy_from_slice(src);
                                    }
                                }
                                (a.kernel.run)(kc, ap, bp, t.as_mut_ptr(), nr, true);
                                for r in 0..rows {
                                    let dst = std::slice::from_raw_parts_mut(cp.add(r * n), cols);
                                    dst.copy_from_slice(&t[r * nr..r * nr + cols]);
                                }
                            }
                            if bi == last {
                                let cs = std::slice::from_raw_parts_mut(c_ptr.0, m * n);
                                apply_epilogue(cs, n, row0, rows, col0, cols, epi);
                            }
                        }
                    }
                }
            }
        });
    };
    let total = n_tasks * m_split;
    if threads == 1 {
        (0..total).for_each(task);
    } else {
        (0..total).into_par_iter().for_each(task);
    }
}

/// Applies the epilogue to the `rows × cols` tile of `c` at `(row0, col0)`.
fn apply_epilogue(
    c: &mut [f32],
    ldc: usize,
    row0: usize,
    rows: usize,
    col0: usize,
    cols: usize,
    epi: &Epilogue<'_>,
) {
    for r in row0..row0 + rows {
        let o = r * ldc + col0;
        let dst = &mut c[o..o + cols];
        if let Some(bias) = epi.bias {
            let b = bias[r];
            dst.iter_mut().for_each(|v| *v += b);
        }
        epi.act.apply(dst);
        if let Some(res) = epi.residual {
            dst.iter_mut()
                .zip(&res[o..o + cols])
                .for_each(|(v, r)| *v += r);
        }
    }
}
