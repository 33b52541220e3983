//! Winograd convolutions for 3×3 layers (Lavin & Gray 2016), in three tile
//! sizes for stride 1 and two for stride 2 ([`Tile`]; transform matrices in
//! `points`): F(4×4, 3×3) takes 36 multiplies per input/output channel pair
//! for a 4×4 output tile instead of 144, F(5×5, 3×3) 49 for a 5×5 tile
//! instead of 225, F(6×6, 3×3) 64 for a 6×6 tile instead of 324, and the
//! stride-2 tiles 81 for a 4×4 tile instead of 144 and 121 for a 5×5 tile
//! instead of 225 (per axis their polyphase split: F(4, 2) or F(5, 2) for
//! the even taps on the even inputs, the middle tap on the odd ones; input
//! tiles 9 wide and 8 apart, or 11 wide and 10 apart; the output side is
//! F(4×4)'s or F(5×5)'s).
//!
//! With `d` a `T × T` input tile (`T = 6`, 7, 8, 9 or 11), `g` a 3×3 kernel:
//! `Y = Aᵀ [Σ_ci (G g Gᵀ) ⊙ (Bᵀ d B)] A`. The weights are transformed and
//! packed once (or at each pass, lazy `U`), as `T²` `c_out × c_in` matrices
//! `U[ξ]` in the micro-kernel's A-panel layout.
//!
//! F(6×6) on an Intel Xeon with AMX (2 threads, 60×80×256 layer, `tune res`):
//! 7.6–8.1 ms packed and 8.1 ms lazy, against F(4×4)'s 7.8–8.0 ms packed: the
//! products fall by 11% in micro-kernel samples, but its 8×8 output transform
//! spills registers and its column phases take gathers, and its packed `U`
//! (7.1× the 3×3 weights) streams from memory, so packed `U` stays F(4×4).
//! With lazy `U` (every network's default) the tile is chosen per image
//! ([`Tile::for_output`]): F(5×5) (since stop 60; its 7×7 transforms stay in
//! registers, and a 30×40 map is exactly one panel of its tiles) but for maps
//! of a few tiles; `PICKER_WINOGRAD_TILE=4|5|6` overrides
//! ([`crate::ConvAlgorithm::Auto`]).
//!
//! A forward pass walks the output tiles in blocks of `NR`-wide panels
//! ([`WINO_PANELS_PER_BLOCK`]), so that no transformed tensor ever leaves the
//! caches:
//! 1. the block's input tiles are gathered (zero or reflection padding fused
//!    into the gather) and transformed, in parallel over input channels,
//!    straight into the micro-kernel's packed B layout: `V[ξ]` is `c_in × tiles`;
//! 2. in parallel over chunks of output channels (`c_out / threads`, within
//!    [`WINO_CO_PER_TASK`]..[`WINO_CO_PER_TASK_MAX`]), the `T²` products
//!    `M[ξ] = U[ξ] · V[ξ]` are run by the GEMM micro-kernel into a per-thread
//!    buffer, for a group of panels at a time (as many as the L2 holds, at
//!    most [`WINO_PANELS_PER_GROUP`]: each `U` panel is read once per group,
//!    and each depth block's B panel stays in L1 for all the chunk's row
//!    panels); the output transform then turns them into output pixels at
//!    once, fused with bias, activation and residual add. With f32 weights
//!    made per pass (lazy `U`), blocks hold at most [`WINO_ROW_BLOCK_PANELS`]
//!    panels and the chunk makes `T` `U[ξ]` of one depth block at a time and
//!    runs them over every panel of the block.
//!
//! The tile transforms work on a panel of tiles at a time, with the tiles in
//! the SIMD lanes; they are compiled once per ISA (`#[target_feature]`) and
//! dispatched with the micro-kernel. Every output element is computed by one
//! task with a fixed order of operations, so results do not depend on the
//! number of threads.

use std::cell::RefCell;

use rayon::prelude::*;

use crate::activation::Activation;
use crate::aligned::AlignedBuf;
use crate::amx;
use crate::gemm::Epilogue;
use crate::isa::Isa;
use crate::microkernel::{KernelFn, MicroKernel, NarrowKernelFn};
use crate::pad::{padded_source, Fill};
use crate::params::{
    WINO_BF16_KC, WINO_CO_PER_TASK, WINO_CO_PER_TASK_MAX, WINO_KC, WINO_LAZY_V_BYTES,
    WINO_PANELS_PER_BLOCK, WINO_PANELS_PER_GROUP, WINO_ROW_BLOCK_PANELS, WINO_S2_CO_PER_TASK_MAX,
};
use points::{Points, F4, F5, F6, S4, S5};

/// `N` disjoint `len`-long lanes of `out`, at `base + i·stride` (`stride ≥ len`).
#[inline(always)]
fn lanes_mut<const N: usize>(
    out: &mut [f32],
    base: usize,
    stride: usize,
    len: usize,
) -> [&mut [f32]; N] {
    let mut rest = &mut out[base..];
    std::array::from_fn(|i| {
        let r = std::mem::take(&mut rest);
        let (lane, tail) = r.split_at_mut(if i + 1 < N { stride } else { len });
        rest = tail;
        &mut lane[..len]
    })
}

/// `N` `len`-long input lanes of `buf`, at `base + r·stride`.
#[inline(always)]
fn lanes<const N: usize>(buf: &[f32], base: usize, stride: usize, len: usize) -> [&[f32]; N] {
    std::array::from_fn(|r| &buf[base + r * stride..][..len])
}

/// `Bᵀ` applied lane-wise: `o_i[k] = (Bᵀ [s_0[k] … s_{T−1}[k]])_i`.
#[inline(always)]
fn bt_lanes<const T: usize, const M: usize, W: Points<T, M>>(s: [&[f32]; T], o: [&mut [f32]; T]) {
    let len = o[0].len();
    let mut o = o.map(|x| &mut x[..len]);
    let s: [&[f32]; T] = std::array::from_fn(|r| &s[r][..len]);
    for k in 0..len {
        let v = W::bt(std::array::from_fn(|r| s[r][k]));
        for (oi, vi) in o.iter_mut().zip(v) {
            oi[k] = vi;
        }
    }
}

/// `Aᵀ` applied lane-wise: `o_i[k] = (Aᵀ [s_0[k] … s_{T−1}[k]])_i`.
#[inline(always)]
fn at_lanes<const T: usize, const M: usize, W: Points<T, M>>(s: [&[f32]; T], o: [&mut [f32]; M]) {
    let len = o[0].len();
    let mut o = o.map(|x| &mut x[..len]);
    let s: [&[f32]; T] = std::array::from_fn(|r| &s[r][..len]);
    for k in 0..len {
        let v = W::at(std::array::from_fn(|r| s[r][k]));
        for (oi, vi) in o.iter_mut().zip(v) {
            oi[k] = vi;
        }
    }
}

/// A 3×3 stride-1 convolution's weights (transformed and packed, or kept to
/// be transformed at each pass; see [`UStore`]).
#[derive(Clone)]
pub(crate) struct Winograd {
    kernel: MicroKernel,
    c_in: usize,
    c_out: usize,
    /// Products in bf16 ([`crate::bf16`]): `U` and `V` hold pair words, two
    /// input channels per depth step.
    bf16: bool,
    /// bf16 products on AMX tiles ([`crate::amx`]): the CPU has them, and
    /// the depth pairs and output channels come in whole tiles of 16.
    amx: bool,
    /// Depth of the products: `c_in` floats, or `⌈c_in / 2⌉` pair words.
    depth: usize,
    /// The products' tile: the f32 kernel's, or the bf16 one.
    run: KernelFn,
    /// The products' narrow tiles for a partly filled last panel.
    narrow: Option<(usize, NarrowKernelFn)>,
    /// `MR`-row panels of `U[ξ]`.
    m_panels: usize,
    /// `(k0, kc, offset)` of each depth block inside one `U[ξ]` (in depth units).
    kblocks: Vec<(usize, usize, usize)>,
    /// The tile size (F4 for bf16), or `None` to choose it per image
    /// ([`Tile::for_output`]; lazy f32 `U` only).
    tile: Option<Tile>,
    /// `U[ξ]`, `c_out × c_in`, in the micro-kernel's A-panel layout.
    u: UStore,
}

/// The output tile of a Winograd layer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Tile {
    /// F(4×4, 3×3): 36 products per 16 outputs.
    F4,
    /// F(5×5, 3×3): 49 products per 25 outputs.
    F5,
    /// F(6×6, 3×3): 64 products per 36 outputs.
    F6,
    /// F(4×4, 3×3) with stride 2 (polyphase): 81 products per 16 outputs.
    S4,
    /// F(5×5, 3×3) with stride 2 (polyphase): 121 products per 25 outputs.
    S5,
}

impl Tile {
    /// Output pixels per tile side.
    pub(crate) fn outputs(self) -> usize {
        match self {
            Tile::F4 | Tile::S4 => 4,
            Tile::F5 | Tile::S5 => 5,
            Tile::F6 => 6,
        }
    }

    /// The convolution's stride.
    pub(crate) fn stride(self) -> usize {
        match self {
            Tile::F4 | Tile::F5 | Tile::F6 => 1,
            Tile::S4 | Tile::S5 => 2,
        }
    }

    /// Points of the transformed tile (`U[ξ]`, `V[ξ]` per layer).
    pub(crate) fn points(self) -> usize {
        let t = (self.outputs() - 1) * self.stride() + 3;
        t * t
    }

    /// The tile for an `oh × ow` output in panels of `nr` tiles, with lazy
    /// `U`: F(5×5) unless F(4×4) runs fewer product lanes (tiles in vectors
    /// of 16, times points: maps of at most a few tiles).
    ///
    /// F(5×5) measured against the earlier choice (F4 where its tiles fit in
    /// one block of [`WINO_ROW_BLOCK_PANELS`] panels, else F6), 2-core Zen 4,
    /// 2 threads, lazy `U`, five interleaved rounds of `tune` (256 channels,
    /// medians in ms): 30×40 output (the EnvMap's blocks; 48 F5 tiles fill
    /// one panel) 1.92–1.96 against F4's 2.33–2.53 and F6's 2.74–2.89;
    /// 60×80 (IRN/MSN blocks at 240×320) 7.8–9.6 against F6's 8.4–10.7;
    /// 120×160 31.4–33.1 against 32.6–34.0; 15×20 0.93 against F4's
    /// 1.05–1.08. `PICKER_WINOGRAD_TILE=4|5|6` still forces a tile.
    ///
    /// (The rule before, F4/F6 only, measured on an Intel Xeon with AMX:
    /// EnvMap 240×320 21.3, 22.7 ms with F4 vs 22.9, 23.4 with F6; IRN
    /// 240×320 1455, 1471 vs 1358, 1412; EnvMap 480×640 92.9, 88.5 vs
    /// 82.3, 81.4; IRN 480×640 5487, 5282 vs 5279, 5091.)
    pub(crate) fn for_output(oh: usize, ow: usize) -> Tile {
        let tiles = |t: Tile| oh.div_ceil(t.outputs()) * ow.div_ceil(t.outputs());
        let lanes = |t: Tile| tiles(t).next_multiple_of(16) * t.points();
        if lanes(Tile::F4) < lanes(Tile::F5) {
            Tile::F4
        } else {
            Tile::F5
        }
    }
}

/// Where one forward pass reads its input and writes its output.
struct Geometry<'a> {
    x: &'a [f32],
    h: usize,
    w: usize,
    /// Tiles per row of tiles.
    tw: usize,
    /// Source row of each padded row `0..step·th + T − step` (`None`: zero;
    /// `step = M · stride`).
    row_map: Vec<Option<usize>>,
    /// Padding on each side, and how it is filled.
    pad: usize,
    fill: Fill,
}

impl Geometry<'_> {
    /// Writes padded row `src_row` (a source row index) as `pw` floats: padded
    /// column `q` reads source column `q − pad`, reflected or zero outside.
    #[inline(always)]
    fn padded_row(&self, plane: &[f32], src_row: Option<usize>, dst: &mut [f32]) {
        let Some(sy) = src_row else {
            dst.fill(0.0);
            return;
        };
        let (w, p) = (self.w, self.pad);
        let src = &plane[sy * w..(sy + 1) * w];
        let pw = dst.len();
        // The image row in one copy; only the few padding columns go through the map.
        let n = w.min(pw.saturating_sub(p));
        dst[p.min(pw)..p.min(pw) + n].copy_from_slice(&src[..n]);
        for q in (0..p.min(pw)).chain(p + n..pw) {
            dst[q] = padded_source(q, p, w, w + 2 * p, self.fill).map_or(0.0, |c| src[c]);
        }
    }
}

/// A run of consecutive tiles in one row of tiles: `(lane0, ty, tx0, len)`.
fn segments(t0: usize, t1: usize, tw: usize, out: &mut Vec<(usize, usize, usize, usize)>) {
    out.clear();
    let mut t = t0;
    while t < t1 {
        let (ty, tx) = (t / tw, t % tw);
        let len = (tw - tx).min(t1 - t);
        out.push((t - t0, ty, tx, len));
        t += len;
    }
}

/// Where one input channel's rows of the transformed tiles go in a block
/// buffer: `V[ξ]`, panel `p` starts at `at(ξ, p)` (see [`Winograd::v_rows`]).
#[derive(Clone, Copy)]
struct VRows {
    xi_stride: usize,
    base: usize,
    panel_stride: usize,
}

impl VRows {
    #[inline(always)]
    fn at(&self, xi: usize, panel: usize) -> usize {
        xi * self.xi_stride + self.base + panel * self.panel_stride
    }
}

struct SharedPtr(*mut f32);
// SAFETY: tasks write disjoint parts of the buffer; see the call sites.
unsafe impl Sync for SharedPtr {}
unsafe impl Send for SharedPtr {}

thread_local! {
    /// Per-thread scratch: one panel's products `M` for one output-channel
    /// chunk, the output transform's rows and (lazy `U`) the chunk's `U`.
    static M_BUF: RefCell<AlignedBuf> = RefCell::new(AlignedBuf::default());
    /// Per-thread scratch of the weight transform (lazy `U`).
    static PACK_SCRATCH: RefCell<Vec<f32>> = const { RefCell::new(Vec::new()) };
    /// Per-thread scratch of the input transform (its rows; what an earlier
    /// call left in it is only read into lanes that are not stored), kept
    /// rather than made and zero-filled for every task: with the pixel
    /// tiles' scratch kept likewise, `tune envhead` 0.918× the time (12
    /// alternating rounds), the whole EnvMap 0.963× (14).
    static INPUT_SCRATCH: RefCell<Vec<f32>> = const { RefCell::new(Vec::new()) };
}

/// Floats between consecutive `U[ξ]` of a chunk's own `U` holding `len`
/// floats each: one cache line more when `len` is a multiple of 1 KiB, so
/// the weight transform's `T²` stores per lane block do not all fall into one
/// L1 set.
fn chunk_per_xi(len: usize) -> usize {
    if len.is_multiple_of(256) {
        len + 16
    } else {
        len
    }
}

/// Where the products read `U[ξ]`'s row panels: all of `U` (packed once), or
/// the `panels` row panels from `mp_base` on that one chunk made (lazy).
struct UView<'a> {
    u: &'a [f32],
    per_xi: usize,
    panels: usize,
    mp_base: usize,
}

impl UView<'_> {
    /// Depth block `(k0, kc)` of row panel `mp` of `U[ξ]`: `kc · mr` floats.
    #[inline(always)]
    fn at(&self, xi: usize, mp: usize, k0: usize, kc: usize, mr: usize) -> &[f32] {
        let at = xi * self.per_xi + k0 * self.panels * mr + (mp - self.mp_base) * kc * mr;
        &self.u[at..at + kc * mr]
    }
}

/// Input transform of one channel over one block of tiles `[t0, t1)`, written
/// into `v` (the block's packed B panels) where `rows` says.
///
/// Per panel and padded row `r` of each tile row: the row is split into its
/// `M` column phases (`q_c[k] = row[M·k + c]`, so tile `k` reads `q_0..q_M`
/// at `k` and `q_0, q_1` at `k + 1`), `Bᵀ` runs along the columns with the
/// tiles in the lanes, then `Bᵀ` along the rows over the whole panel.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn input_channel_body<const T: usize, const M: usize, W: Points<T, M>>(
    g: &Geometry<'_>,
    ci: usize,
    t0: usize,
    t1: usize,
    nr: usize,
    rows: VRows,
    v: *mut f32,
    scratch: &mut Vec<f32>,
) {
    let (h, w, tw) = (g.h, g.w, g.tw);
    let plane = &g.x[ci * h * w..(ci + 1) * h * w];
    // Tile k starts at padded column step·k (its input tile is T ≤ 2·step
    // columns wide).
    let step = M * W::STRIDE;
    debug_assert!(T > step && T <= 2 * step);
    // Padded row: tiles 0..tw need columns up to step·(tw − 1) + T − 1; one
    // more phase group keeps the k + 1 reads of the last tile inside.
    let pw = step * tw + step;
    let qlen = tw + 1;
    let d_len = T * T * nr;
    scratch.resize(pw + step * qlen + d_len, 0.0);
    let (row, rest) = scratch.split_at_mut(pw);
    let (q, t1buf) = rest.split_at_mut(step * qlen);
    let mut segs = Vec::with_capacity(4);
    let mut p0 = t0;
    let mut panel = 0;
    while p0 < t1 {
        let p1 = (p0 + nr).min(t1);
        // t1buf[(j·T + r)·nr + lane] = Σ_c Bᵀ[j][c] padded[M·ty + r][M·tx + c]
        if p1 - p0 < nr {
            t1buf.fill(0.0);
        }
        segments(p0, p1, tw, &mut segs);
        for &(l0, ty, tx0, len) in &segs {
            for r in 0..T {
                g.padded_row(plane, g.row_map[step * ty + r], row);
                // q_c[k] = row[step·(tx0 + k) + c], k in 0..=len
                let src = &row[step * tx0..step * (tx0 + len + 1)];
                for (k, cols) in src.chunks_exact(step).enumerate() {
                    for (c, &x) in cols.iter().enumerate() {
                        q[c * qlen + k] = x;
                    }
                }
                let s: [&[f32]; T] = std::array::from_fn(|c| {
                    if c < step {
                        &q[c * qlen..c * qlen + len]
                    } else {
                        &q[(c - step) * qlen + 1..(c - step) * qlen + 1 + len]
                    }
                });
                bt_lanes::<T, M, W>(s, lanes_mut(t1buf, r * nr + l0, T * nr, len));
            }
        }
        // V[ξ = T·i + j] = Σ_r Bᵀ[i][r] t1[j][r]
        for j in 0..T {
            let src = lanes::<T>(t1buf, j * T * nr, nr, nr);
            // SAFETY: `rows.at(ξ, panel)` rows of channel `ci` are written by
            // this task only, and lie inside the block buffer (see `VRows`).
            let o: [&mut [f32]; T] = std::array::from_fn(|i| unsafe {
                std::slice::from_raw_parts_mut(v.add(rows.at(i * T + j, panel)), nr)
            });
            bt_lanes::<T, M, W>(src, o);
        }
        p0 = p1;
        panel += 1;
    }
}

/// Where one output channel's panel of tiles goes, and what the output
/// transform fuses: the runs of tiles (see [`segments`]), the output size,
/// bias, activation and the residual plane to add.
#[derive(Clone, Copy)]
pub(super) struct OutPlane<'a> {
    pub(super) segs: &'a [(usize, usize, usize, usize)],
    pub(super) oh: usize,
    pub(super) ow: usize,
    pub(super) bias: f32,
    pub(super) act: Activation,
    pub(super) residual: Option<&'a [f32]>,
}

/// Output transform of one channel over one panel of tiles: `m` holds the
/// `T²` products (`m[ξ·stride ..][..nr]`), written to `plane` with bias,
/// activation and residual.
#[inline(always)]
fn output_panel_body<const T: usize, const M: usize, W: Points<T, M>>(
    m: &[f32],
    stride: usize,
    nr: usize,
    o: &OutPlane<'_>,
    plane: &mut [f32],
    scratch: &mut [f32],
) {
    let OutPlane {
        segs,
        oh,
        ow,
        bias,
        act,
        residual,
    } = *o;
    let (t1, y) = scratch.split_at_mut(T * M * nr);
    let y = &mut y[..M * M * nr];
    // t1[(c·M + i)·nr] = Σ_r Aᵀ[i][r] M[ξ = T·r + c]
    for c in 0..T {
        at_lanes::<T, M, W>(
            lanes(m, c * stride, T * stride, nr),
            lanes_mut(t1, c * M * nr, nr, nr),
        );
    }
    // y[(i·M + j)·nr] = Σ_c Aᵀ[j][c] t1[c][i]
    for i in 0..M {
        at_lanes::<T, M, W>(
            lanes(t1, i * nr, M * nr, nr),
            lanes_mut(y, i * M * nr, nr, nr),
        );
    }
    for &(l0, ty, tx0, len) in segs {
        let x0 = M * tx0;
        let x1 = (M * (tx0 + len)).min(ow);
        // Whole tiles, then the one cut by the right edge.
        let full = ((x1 - x0) / M).min(len);
        for i in 0..M {
            let oy = ty * M + i;
            if oy >= oh {
                break;
            }
            let orow = &mut plane[oy * ow..(oy + 1) * ow];
            let seg = &mut orow[x0..x1];
            let yl: [&[f32]; M] = std::array::from_fn(|j| &y[(i * M + j) * nr + l0..][..len]);
            {
                let yf: [&[f32]; M] = std::array::from_fn(|j| &yl[j][..full]);
                for (k, o) in seg.chunks_exact_mut(M).take(full).enumerate() {
                    for (oj, yj) in o.iter_mut().zip(&yf) {
                        *oj = yj[k];
                    }
                }
            }
            for (j, o) in seg[M * full..].iter_mut().enumerate() {
                *o = yl[j][full];
            }
            match residual {
                Some(r) => {
                    let rr = &r[oy * ow + x0..oy * ow + x1];
                    for (o, &r) in seg.iter_mut().zip(rr) {
                        *o = act.apply_one(*o + bias) + r;
                    }
                }
                None => {
                    for o in seg.iter_mut() {
                        *o = act.apply_one(*o + bias);
                    }
                }
            }
        }
    }
}

/// One instance of the transforms per ISA, so the lane loops are vectorised
/// for the widest registers the micro-kernel family has.
macro_rules! transforms_for {
    ($input:ident, $output:ident, $($feat:literal)?) => {
        $(#[target_feature(enable = $feat)])?
        #[allow(clippy::too_many_arguments)]
        unsafe fn $input<const T: usize, const M: usize, W: Points<T, M>>(
            g: &Geometry<'_>,
            ci: usize,
            t0: usize,
            t1: usize,
            nr: usize,
            rows: VRows,
            v: *mut f32,
            scratch: &mut Vec<f32>,
        ) {
            input_channel_body::<T, M, W>(g, ci, t0, t1, nr, rows, v, scratch)
        }

        $(#[target_feature(enable = $feat)])?
        unsafe fn $output<const T: usize, const M: usize, W: Points<T, M>>(
            m: &[f32],
            stride: usize,
            nr: usize,
            o: &OutPlane<'_>,
            plane: &mut [f32],
            scratch: &mut [f32],
        ) {
            output_panel_body::<T, M, W>(m, stride, nr, o, plane, scratch)
        }
    };
}

#[cfg(target_arch = "x86_64")]
mod avx512;
mod points;
#[cfg(target_arch = "x86_64")]
use avx512::{input as input_avx512, output as output_avx512};
#[cfg(target_arch = "x86_64")]
transforms_for!(input_avx2, output_avx2, "avx2,fma");
transforms_for!(input_portable, output_portable,);

/// Rows `rows` of `G g Gᵀ` lane-wise: `g[k]` holds tap `k` (row-major 3×3)
/// of many kernels, `u[((i − rows.start)·T + j)·stride ..]` gets their
/// transformed point `ξ = T·i + j`. All rows (`0..T`) give the `T²` points in
/// `ξ` order; one row gives `T` of them with the same operations (so the same
/// bits). Works on blocks of 16 lanes held in fixed-size arrays, so the
/// arithmetic is vectorised.
#[inline(always)]
fn transform_lanes<const T: usize, const M: usize, W: Points<T, M>>(
    g: [&[f32]; 9],
    u: &mut [f32],
    stride: usize,
    rows: std::ops::Range<usize>,
) {
    const L: usize = 16;
    let len = g[0].len();
    let mut l0 = 0;
    while l0 < len {
        let n = L.min(len - l0);
        let mut x = [[0.0f32; L]; 9];
        for (k, xk) in x.iter_mut().enumerate() {
            // A whole block as one fixed-size move (no memcpy call).
            match <&[f32; L]>::try_from(&g[k][l0..l0 + n]) {
                Ok(full) => *xk = *full,
                Err(_) => xk[..n].copy_from_slice(&g[k][l0..l0 + n]),
            }
        }
        let col = |a: usize, b: usize, c: usize| -> [[f32; L]; T] {
            let mut o = [[0.0f32; L]; T];
            for l in 0..L {
                let r = W::g(x[a][l], x[b][l], x[c][l]);
                for (oi, ri) in o.iter_mut().zip(r) {
                    oi[l] = ri;
                }
            }
            o
        };
        let (c0, c1, c2) = (col(0, 3, 6), col(1, 4, 7), col(2, 5, 8));
        for i in rows.clone() {
            let mut r = [[0.0f32; L]; T];
            for l in 0..L {
                let v = W::g(c0[i][l], c1[i][l], c2[i][l]);
                for (rj, vj) in r.iter_mut().zip(v) {
                    rj[l] = vj;
                }
            }
            for (j, rj) in r.iter().enumerate() {
                let at = ((i - rows.start) * T + j) * stride + l0;
                match <&mut [f32; L]>::try_from(&mut u[at..at + n]) {
                    Ok(full) => *full = *rj,
                    Err(_) => u[at..at + n].copy_from_slice(&rj[..n]),
                }
            }
        }
        l0 += n;
    }
}

macro_rules! weight_transform_for {
    ($name:ident, $($feat:literal)?) => {
        /// The weight transform of `g` into `u` (see [`transform_lanes`]):
        /// the points of transform rows `rows`.
        $(#[target_feature(enable = $feat)])?
        unsafe fn $name<const T: usize, const M: usize, W: Points<T, M>>(
            g: [&[f32]; 9],
            u: &mut [f32],
            stride: usize,
            rows: std::ops::Range<usize>,
        ) {
            transform_lanes::<T, M, W>(g, u, stride, rows)
        }
    };
}
#[cfg(target_arch = "x86_64")]
use avx512::weights as weights_avx512;
#[cfg(target_arch = "x86_64")]
weight_transform_for!(weights_avx2, "avx2,fma");
weight_transform_for!(weights_portable,);

/// How the transformed weights `U` are kept.
#[derive(Clone)]
enum UStore {
    /// Packed once when the layer is built: 4× the memory of the 3×3 weights.
    Packed(AlignedBuf),
    /// Only the 3×3 weights are kept (as `[m_panels][9][c_in][mr]`); each
    /// output-channel chunk makes its part of `U` in its own task, once per
    /// block of tiles (blocks of up to [`WINO_LAZY_V_BYTES`] of `V`), so a
    /// network holds its weights once. In f32 a block holds at most
    /// [`WINO_ROW_BLOCK_PANELS`] tile panels and the chunk's `U` is made one
    /// transform row and depth block at a time, into L2, and used at once by
    /// every panel of the block: the whole chunk's `U` (4.7 MB at 128 × 256
    /// channels in F(4×4), 8.4 MB in F(6×6)) cost more to write to L3 and
    /// read back than the products' own work (a 256-channel 30×40 layer, 2
    /// threads, Zen 4: 4.4–4.6 ms, now 2.8–3.2 ms, as with packed U; the IRN
    /// at 480×640 on an Intel Xeon: 5.8 s, now 5.2–5.4 s). The bf16 products
    /// still make the chunk's whole `U` per block.
    Lazy(AlignedBuf),
}

impl Winograd {
    /// Builds the layer for `weight` (`[c_out, c_in, 3, 3]`) and `kernel`,
    /// packing `U` once when `packed`, else at every forward pass; with
    /// `bf16` the products run in bf16 (the caller checks that the CPU has
    /// AVX512_BF16 and `kernel` is the AVX-512 family, and `tile` is F4).
    /// `tile: None` chooses the tile per image ([`Tile::for_output`]) and
    /// needs lazy f32 `U`.
    pub(crate) fn new(
        kernel: MicroKernel,
        c_in: usize,
        c_out: usize,
        weight: &[f32],
        packed: bool,
        bf16: bool,
        tile: Option<Tile>,
    ) -> Self {
        assert!(
            !bf16 || tile == Some(Tile::F4),
            "bf16 products use F(4×4, 3×3)"
        );
        assert!(
            tile.is_some() || !packed,
            "packed U needs a fixed tile size"
        );
        let mr = kernel.mr;
        let m_panels = c_out.div_ceil(mr);
        let (depth, block, run, narrow) = if bf16 {
            assert!(
                kernel.isa == Isa::Avx512 && crate::bf16::available(),
                "bf16 Winograd needs the AVX-512 kernels and AVX512_BF16"
            );
            bf16_products(c_in)
        } else {
            (c_in, WINO_KC, kernel.run, kernel.narrow)
        };
        let mut kblocks = Vec::new();
        let mut k0 = 0;
        while k0 < depth {
            let kc = block.min(depth - k0);
            kblocks.push((k0, kc, k0 * m_panels * mr));
            k0 += kc;
        }
        // [c_out, c_in, 9] → [m_panels][9][c_in][mr] (output channels past
        // c_out zero): one tap of one row panel is contiguous over (ci, r),
        // the lanes of the transform and the order of the A panel.
        let mut taps = AlignedBuf::zeroed(m_panels * 9 * c_in * mr);
        let tm = taps.as_mut_slice();
        for co in 0..c_out {
            let (mp, r) = (co / mr, co % mr);
            for ci in 0..c_in {
                for k in 0..9 {
                    tm[((mp * 9 + k) * c_in + ci) * mr + r] = weight[(co * c_in + ci) * 9 + k];
                }
            }
        }
        let mut w = Self {
            kernel,
            c_in,
            c_out,
            bf16,
            amx: bf16
                && kernel.nr == 3 * amx::COLS
                && crate::amx::available()
                && depth.is_multiple_of(amx::COLS)
                && c_out.is_multiple_of(amx::ROWS),
            depth,
            run,
            narrow,
            m_panels,
            kblocks,
            tile,
            u: UStore::Lazy(taps),
        };
        if let (true, Some(tile)) = (packed, tile) {
            let mut buf = AlignedBuf::zeroed(tile.points() * w.per_xi());
            if let UStore::Lazy(taps) = &w.u {
                match tile {
                    Tile::F4 => w.pack_u::<6, 4, F4>(taps.as_slice(), buf.as_mut_slice()),
                    Tile::F5 => w.pack_u::<7, 5, F5>(taps.as_slice(), buf.as_mut_slice()),
                    Tile::F6 => w.pack_u::<8, 6, F6>(taps.as_slice(), buf.as_mut_slice()),
                    Tile::S4 => w.pack_u::<9, 4, S4>(taps.as_slice(), buf.as_mut_slice()),
                    Tile::S5 => w.pack_u::<11, 5, S5>(taps.as_slice(), buf.as_mut_slice()),
                }
            }
            w.u = UStore::Packed(buf);
        }
        w
    }

    /// The tile size, `None` when it is chosen per image.
    pub(crate) fn tile(&self) -> Option<Tile> {
        self.tile
    }

    /// True when `U` is packed once (not made at every pass).
    pub(crate) fn is_packed(&self) -> bool {
        matches!(self.u, UStore::Packed(_))
    }

    /// True when the products run in bf16.
    pub(crate) fn is_bf16(&self) -> bool {
        self.bf16
    }

    /// Floats (or pair words) of one packed `U[ξ]`.
    fn per_xi(&self) -> usize {
        self.m_panels * self.kernel.mr * self.depth
    }

    /// Transforms `taps` (`[m_panels][9][c_in][mr]`) and writes every `U[ξ]`
    /// into `dst` (`T² · per_xi` floats, `ξ`-major, each in the
    /// micro-kernel's A-panel layout), in parallel over row panels.
    fn pack_u<const T: usize, const M: usize, W: Points<T, M>>(
        &self,
        taps: &[f32],
        dst: &mut [f32],
    ) {
        let p = T * T;
        let (mr, depth, per_xi, m_panels) =
            (self.kernel.mr, self.depth, self.per_xi(), self.m_panels);
        let ptr = SharedPtr(dst.as_mut_ptr());
        let ptr = &ptr;
        assert!(dst.len() >= p * per_xi);
        (0..m_panels).into_par_iter().for_each_init(
            || (Vec::new(), vec![0.0f32; p * depth * mr]),
            |(scratch, staged), mp| {
                // The panel as [ξ][d][r], then each depth block to its place.
                self.pack_panel::<T, M, W>(taps, mp, scratch, staged, depth * mr, |k0, _| k0 * mr);
                for xi in 0..p {
                    for &(k0, kc, _) in &self.kblocks {
                        let src = &staged[(xi * depth + k0) * mr..][..kc * mr];
                        let at = xi * per_xi + k0 * m_panels * mr + mp * kc * mr;
                        // SAFETY: row panel `mp` owns these kc·mr floats of U[ξ]
                        // (below `T² · per_xi`, checked above).
                        unsafe {
                            std::ptr::copy_nonoverlapping(src.as_ptr(), ptr.0.add(at), kc * mr)
                        };
                    }
                }
            },
        );
    }

    /// Row panels `mp0..mp1` of every `U[ξ]` into `dst`, laid out as a `U`
    /// of only those panels (see [`UView`]); one thread.
    fn pack_u_chunk<const T: usize, const M: usize, W: Points<T, M>>(
        &self,
        taps: &[f32],
        mp0: usize,
        mp1: usize,
        dst: &mut [f32],
        scratch: &mut Vec<f32>,
    ) {
        let (mr, n) = (self.kernel.mr, mp1 - mp0);
        let per_xi = chunk_per_xi(n * mr * self.depth);
        for mp in mp0..mp1 {
            self.pack_panel::<T, M, W>(taps, mp, scratch, dst, per_xi, |k0, kc| {
                k0 * n * mr + (mp - mp0) * kc * mr
            });
        }
    }

    /// The weight transform for this layer's ISA (see [`transform_lanes`]).
    fn transform<const T: usize, const M: usize, W: Points<T, M>>(
        &self,
        g: [&[f32]; 9],
        u: &mut [f32],
        stride: usize,
        rows: std::ops::Range<usize>,
    ) {
        assert!(rows.end <= T, "transform rows {rows:?} of {T}");
        // SAFETY: the CPU has the kernel family's ISA.
        unsafe {
            match self.kernel.isa {
                #[cfg(target_arch = "x86_64")]
                Isa::Avx512 => weights_avx512::<T, M, W>(g, u, stride, rows),
                #[cfg(target_arch = "x86_64")]
                Isa::Avx2Fma => weights_avx2::<T, M, W>(g, u, stride, rows),
                _ => weights_portable::<T, M, W>(g, u, stride, rows),
            }
        }
    }

    /// Row `row` of the transform (`U[ξ]` for `ξ = T·row .. T·row + T`) of
    /// depth block `(k0, kc)` of row panels `mp0..mp1` (f32 only), into `dst`
    /// as `T` `U[ξ]` of `xi_stride` floats, each holding the panels' `kc·MR`
    /// floats one after another (a [`UView`] with `k0 = 0`).
    #[allow(clippy::too_many_arguments)]
    fn pack_row_block<const T: usize, const M: usize, W: Points<T, M>>(
        &self,
        taps: &[f32],
        mps: std::ops::Range<usize>,
        k0: usize,
        kc: usize,
        row: usize,
        dst: &mut [f32],
        xi_stride: usize,
    ) {
        debug_assert!(!self.bf16);
        let (mr, c_in) = (self.kernel.mr, self.c_in);
        let lanes = kc * mr;
        for (i, mp) in mps.enumerate() {
            let g: [&[f32]; 9] =
                std::array::from_fn(|k| &taps[((mp * 9 + k) * c_in + k0) * mr..][..lanes]);
            let base = i * lanes;
            let len = (T - 1) * xi_stride + lanes;
            self.transform::<T, M, W>(g, &mut dst[base..base + len], xi_stride, row..row + 1);
        }
    }

    /// Transforms the weights of row panel `mp` (`MR` output channels):
    /// depth block `(k0, kc)` of `U[ξ]` (`kc` groups of `MR` floats, or of
    /// pair words in bf16) goes to `dst[ξ · xi_stride + at(k0, kc)..]`.
    fn pack_panel<const T: usize, const M: usize, W: Points<T, M>>(
        &self,
        taps: &[f32],
        mp: usize,
        scratch: &mut Vec<f32>,
        dst: &mut [f32],
        xi_stride: usize,
        at: impl Fn(usize, usize) -> usize,
    ) {
        let (mr, c_in) = (self.kernel.mr, self.c_in);
        let p = T * T;
        let transform = |g, u: &mut [f32], stride| self.transform::<T, M, W>(g, u, stride, 0..T);
        for &(k0, kc, _) in &self.kblocks {
            // Input channels of the block: kc, or up to 2·kc in bf16.
            let (c0, c1) = if self.bf16 {
                (2 * k0, (2 * (k0 + kc)).min(c_in))
            } else {
                (k0, k0 + kc)
            };
            let lanes = (c1 - c0) * mr;
            let g: [&[f32]; 9] =
                std::array::from_fn(|k| &taps[((mp * 9 + k) * c_in + c0) * mr..][..lanes]);
            let base = at(k0, kc);
            if !self.bf16 {
                // The lanes (ci, r) are the A panel's order: straight in place.
                let len = (p - 1) * xi_stride + lanes;
                transform(g, &mut dst[base..base + len], xi_stride);
                continue;
            }
            // bf16: the f32 points as [ξ][ci][r], then channel pairs to words.
            let cpad = 2 * kc * mr;
            scratch.resize(p * cpad, 0.0);
            transform(g, scratch, cpad);
            for xi in 0..p {
                let st = &mut scratch[xi * cpad..(xi + 1) * cpad];
                st[lanes..].fill(0.0);
                let out = &mut dst[base + xi * xi_stride..][..kc * mr];
                for (d, o) in out.chunks_exact_mut(mr).enumerate() {
                    let (lo, hi) = st[2 * d * mr..(2 * d + 2) * mr].split_at(mr);
                    crate::bf16::pack_pairs(lo, hi, o);
                }
            }
        }
    }

    /// The depth block `(k0, kc, offset)` holding depth row `d`.
    fn kblock_of(&self, d: usize) -> (usize, usize, usize) {
        self.kblocks
            .iter()
            .copied()
            .find(|&(k0, kc, _)| d < k0 + kc)
            .expect("d < depth")
    }

    /// Where depth row `d`'s rows (channel `d`, or pair `d` in bf16) of
    /// every `V[ξ]` lie in a block buffer of `tpb` tiles: `ξ`-major, then
    /// depth block `(k0, kc)`, then panel, then the `kc` rows of that panel.
    fn v_rows(&self, d: usize, tpb: usize) -> VRows {
        let (k0, kc, _) = self.kblock_of(d);
        let nr = self.kernel.nr;
        VRows {
            xi_stride: self.depth * tpb,
            base: k0 * tpb + (d - k0) * nr,
            panel_stride: kc * nr,
        }
    }

    /// The input transform of channel `ci` over tiles `[t0, t1)` into `v`
    /// where `rows` says, with this layer's ISA.
    #[allow(clippy::too_many_arguments)]
    fn input<const T: usize, const M: usize, W: Points<T, M>>(
        &self,
        g: &Geometry<'_>,
        ci: usize,
        t0: usize,
        t1: usize,
        rows: VRows,
        v: *mut f32,
        scratch: &mut Vec<f32>,
    ) {
        let nr = self.kernel.nr;
        // SAFETY: the caller gives each channel its own rows of `v`; the CPU
        // has the ISA of the kernel family (checked when built).
        unsafe {
            match self.kernel.isa {
                #[cfg(target_arch = "x86_64")]
                Isa::Avx512 => input_avx512::<T, M, W>(g, ci, t0, t1, nr, rows, v, scratch),
                #[cfg(target_arch = "x86_64")]
                Isa::Avx2Fma => input_avx2::<T, M, W>(g, ci, t0, t1, nr, rows, v, scratch),
                _ => input_portable::<T, M, W>(g, ci, t0, t1, nr, rows, v, scratch),
            }
        }
    }

    /// The output transform of one channel's panel (`m`, the `T²` products
    /// `stride` apart) into `plane`, with this layer's ISA.
    fn output<const T: usize, const M: usize, W: Points<T, M>>(
        &self,
        m: &[f32],
        stride: usize,
        o: &OutPlane<'_>,
        plane: &mut [f32],
        scratch: &mut [f32],
    ) {
        let nr = self.kernel.nr;
        // SAFETY: the CPU has the ISA of the kernel family (checked when built).
        unsafe {
            match self.kernel.isa {
                #[cfg(target_arch = "x86_64")]
                Isa::Avx512 => output_avx512::<T, M, W>(m, stride, nr, o, plane, scratch),
                #[cfg(target_arch = "x86_64")]
                Isa::Avx2Fma => output_avx2::<T, M, W>(m, stride, nr, o, plane, scratch),
                _ => output_portable::<T, M, W>(m, stride, nr, o, plane, scratch),
            }
        }
    }

    /// One depth block `(k0, kc)` of the products `M[ξ] += U[ξ] · V[ξ]` for one
    /// tile panel: row panels `mps` of the chunk's `U` (`u`) times the panel's
    /// B sub-panel `b` (`kc` rows of `NR`, of which the first `cols` columns
    /// hold tiles) into `c` (the chunk's rows of `M[ξ]` for this panel, `NR`
    /// floats per row), accumulating onto `c` when `accumulate`. A partly
    /// filled panel takes the narrow kernel when one exists.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn panel_products(
        &self,
        u: &UView<'_>,
        xi: usize,
        mps: std::ops::Range<usize>,
        k0: usize,
        kc: usize,
        b: &[f32],
        cols: usize,
        c: &mut [f32],
        accumulate: bool,
    ) {
        let (mr, nr) = (self.kernel.mr, self.kernel.nr);
        assert!(b.len() >= kc * nr, "B sub-panel too short");
        let mp0 = mps.start;
        for mp in mps {
            let ap = u.at(xi, mp, k0, kc, mr).as_ptr();
            let c = &mut c[(mp - mp0) * mr * nr..][..mr * nr];
            // SAFETY: the A panel holds kc·mr floats, the B panel kc·nr
            // (checked above), and C mr rows of nr floats (ldc nr); a narrow
            // kernel touches only its first columns.
            unsafe {
                match self.narrow {
                    Some((lanes, narrow)) if cols + lanes <= nr => narrow(
                        cols.div_ceil(lanes),
                        kc,
                        ap,
                        b.as_ptr(),
                        nr,
                        c.as_mut_ptr(),
                        nr,
                        accumulate,
                    ),
                    _ => (self.run)(kc, ap, b.as_ptr(), c.as_mut_ptr(), nr, accumulate),
                }
            }
        }
    }

    /// The bf16 input transform of a block: in parallel over channel pairs,
    /// each pair is transformed in f32 into a task buffer, then rounded and
    /// interleaved into pair words at its rows of `v` (a missing odd channel
    /// is zero).
    fn input_bf16(&self, g: &Geometry<'_>, t0: usize, t1: usize, tpb: usize, v: &SharedPtr) {
        let (nr, points) = (self.kernel.nr, Tile::F4.points());
        let panels = (t1 - t0).div_ceil(nr);
        // The task buffer holds [panel][ξ][channel of the pair][nr].
        let local = |which: usize| VRows {
            xi_stride: 2 * nr,
            base: which * nr,
            panel_stride: 2 * points * nr,
        };
        (0..self.depth)
            .into_par_iter()
            .with_min_len(4)
            .for_each_init(
                || (Vec::new(), Vec::new()),
                |(scratch, pairbuf): &mut (Vec<f32>, Vec<f32>), d| {
                    pairbuf.resize(2 * points * nr * panels, 0.0);
                    for which in 0..2 {
                        let ci = 2 * d + which;
                        if ci < self.c_in {
                            self.input::<6, 4, F4>(
                                g,
                                ci,
                                t0,
                                t1,
                                local(which),
                                pairbuf.as_mut_ptr(),
                                scratch,
                            );
                        } else {
                            for p in 0..panels {
                                for xi in 0..points {
                                    let at = local(which).at(xi, p);
                                    pairbuf[at..at + nr].fill(0.0);
                                }
                            }
                        }
                    }
                    let rows = self.v_rows(d, tpb);
                    for p in 0..panels {
                        for xi in 0..points {
                            let (lo, hi) = (local(0).at(xi, p), local(1).at(xi, p));
                            // SAFETY: pair row `d` of `V[ξ]`, panel `p`, is
                            // written by this task only and lies inside the
                            // block buffer (see `VRows`).
                            let dst = unsafe {
                                std::slice::from_raw_parts_mut(v.0.add(rows.at(xi, p)), nr)
                            };
                            crate::bf16::pack_pairs(
                                &pairbuf[lo..lo + nr],
                                &pairbuf[hi..hi + nr],
                                dst,
                            );
                        }
                    }
                },
            );
    }

    /// One image: `x` is `[c_in, h, w]`, extended by `pad` on every side as
    /// `fill` says; `out` is `[c_out, h + 2·pad − 2, w + 2·pad − 2]`, then
    /// `epi` (its residual, if any, shaped like `out`).
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn forward_image(
        &self,
        x: &[f32],
        h: usize,
        w: usize,
        pad: usize,
        fill: Fill,
        epi: &Epilogue<'_>,
        out: &mut [f32],
    ) {
        self.forward_image_top(x, h, w, pad, pad, fill, epi, out);
    }

    /// [`Winograd::forward_image`] with `top ≤ pad` rows of padding above
    /// the image instead of `pad` (the other three sides keep `pad`): `out`
    /// is `[c_out, (h + top + pad − 3) / stride + 1, (w + 2·pad − 3) / stride
    /// + 1]`. A band of a larger image starts with `top = 0` on the row its
    /// first output reads, so that it computes no row it then drops
    /// ([`crate::Conv2d::reflect_then`]).
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn forward_image_top(
        &self,
        x: &[f32],
        h: usize,
        w: usize,
        top: usize,
        pad: usize,
        fill: Fill,
        epi: &Epilogue<'_>,
        out: &mut [f32],
    ) {
        debug_assert!(top <= pad);
        let tile = self.tile.unwrap_or_else(|| {
            let (oh, ow) = (h + top + pad - 2, w + 2 * pad - 2);
            Tile::for_output(oh, ow)
        });
        match tile {
            Tile::F4 => self.forward_tiles::<6, 4, F4>(x, h, w, top, pad, fill, epi, out),
            Tile::F5 => self.forward_tiles::<7, 5, F5>(x, h, w, top, pad, fill, epi, out),
            Tile::F6 => self.forward_tiles::<8, 6, F6>(x, h, w, top, pad, fill, epi, out),
            Tile::S4 => self.forward_tiles::<9, 4, S4>(x, h, w, top, pad, fill, epi, out),
            Tile::S5 => self.forward_tiles::<11, 5, S5>(x, h, w, top, pad, fill, epi, out),
        }
    }

    /// [`Winograd::forward_image`] with the tile of `T × T` points.
    #[allow(clippy::too_many_arguments)]
    fn forward_tiles<const T: usize, const M: usize, W: Points<T, M>>(
        &self,
        x: &[f32],
        h: usize,
        w: usize,
        top: usize,
        pad: usize,
        fill: Fill,
        epi: &Epilogue<'_>,
        out: &mut [f32],
    ) {
        let points = T * T;
        let (bias, act, residual) = (epi.bias, epi.act, epi.residual);
        let s = W::STRIDE;
        let (oh, ow) = ((h + top + pad - 3) / s + 1, (w + 2 * pad - 3) / s + 1);
        let (th, tw) = (oh.div_ceil(M), ow.div_ceil(M));
        let tiles = th * tw;
        let (mr, nr) = (self.kernel.mr, self.kernel.nr);
        let hp = h + top + pad;
        // Tile row ty reads padded rows step·ty .. step·ty + T.
        let step = M * s;
        let row_map = (0..step * th + T - step)
            .map(|q| padded_source(q, top, h, hp, fill))
            .collect();
        let g = Geometry {
            x,
            h,
            w,
            tw,
            row_map,
            pad,
            fill,
        };
        let lazy = matches!(self.u, UStore::Lazy(_));
        // Packed U: blocks of WINO_PANELS_PER_BLOCK panels, all of U read per
        // block. Lazy U: blocks as large as WINO_LAZY_V_BYTES of V allows, and
        // each output-channel chunk makes its own part of U once per block.
        let panels_per_block = if lazy || self.amx {
            let per_panel = points * self.depth * nr * std::mem::size_of::<f32>();
            (WINO_LAZY_V_BYTES / per_panel).clamp(1, 32)
        } else {
            WINO_PANELS_PER_BLOCK
        };
        // Lazy f32 U: the products are run one U row block at a time (see
        // below) for all of a block's panels, whose products are kept
        // together, so a block holds at most WINO_ROW_BLOCK_PANELS panels,
        // the tiles split evenly over the blocks.
        let row_blocks = lazy && !self.bf16 && !self.amx;
        let panels_per_block = if row_blocks {
            let total = tiles.div_ceil(nr);
            let cap = panels_per_block.min(WINO_ROW_BLOCK_PANELS);
            total.div_ceil(total.div_ceil(cap))
        } else {
            panels_per_block
        };
        let tpb = nr * panels_per_block;
        // The first rows of each depth block, for the products.
        let block_rows: Vec<VRows> = self
            .kblocks
            .iter()
            .map(|&(k0, ..)| self.v_rows(k0, tpb))
            .collect();
        let block_rows = &block_rows;
        // V from the pool, its start aligned to a cache line: the products
        // load its B panels 16 floats at a time.
        let v_len = points * self.depth * tpb;
        let (mut v_buf, v_off) = crate::pool::take_aligned(v_len);
        let v = &mut v_buf[v_off..v_off + v_len];
        let m_panels = self.m_panels;
        // Output-channel chunks: one per thread, within bounds (a larger
        // chunk reads each B panel for more rows; the products' buffer is
        // `group · T² · chunk · NR` floats and should stay in L2). At least
        // one panel: `m_panels ≥ 1` (c_out > 0 is checked at build).
        let chunk_panels = m_panels
            .div_ceil(rayon::current_num_threads().max(1))
            .clamp(
                WINO_CO_PER_TASK.div_ceil(mr),
                if W::STRIDE == 1 {
                    WINO_CO_PER_TASK_MAX
                } else {
                    WINO_S2_CO_PER_TASK_MAX
                }
                .div_ceil(mr),
            );
        // AMX: whole tiles of 16 output channels per chunk.
        let chunk_panels = if self.amx {
            chunk_panels.next_multiple_of(amx::ROWS / mr)
        } else {
            chunk_panels
        };
        let chunk_rows = chunk_panels * mr;
        let plane_len = oh * ow;
        let stride = chunk_rows * nr;
        let m_len = points * stride;
        // Panels whose products a task keeps at once: as many as the L2
        // holds (each U panel is then read once for all of them), at most
        // WINO_PANELS_PER_GROUP.
        let m_panel_bytes = m_len * std::mem::size_of::<f32>();
        let group = (crate::isa::l2_cache_bytes() / m_panel_bytes)
            .clamp(1, WINO_PANELS_PER_GROUP)
            .min(panels_per_block);
        let group = if row_blocks { panels_per_block } else { group };
        let u_chunk_len = if row_blocks {
            let kc_max = self.kblocks.iter().map(|b| b.1).max().unwrap_or(0);
            T * chunk_per_xi(chunk_rows * kc_max)
        } else {
            points * chunk_per_xi(chunk_rows * self.depth)
        };
        // AMX: the chunk's U as A tiles, [ξ][16-row block][16-pair block].
        let amx_len = if self.amx {
            points * chunk_rows * self.depth
        } else {
            0
        };

        let mut t0 = 0;
        while t0 < tiles {
            let t1 = (t0 + tpb).min(tiles);
            let panels = (t1 - t0).div_ceil(nr);

            // 1. Input transform, parallel over channels (pairs of them in bf16).
            let vp = SharedPtr(v.as_mut_ptr());
            let vp = &vp;
            if self.bf16 {
                self.input_bf16(&g, t0, t1, tpb, vp);
            } else {
                (0..self.c_in)
                    .into_par_iter()
                    .with_min_len(8)
                    .for_each(|ci| {
                        INPUT_SCRATCH.with(|scratch| {
                            let scratch = &mut scratch.borrow_mut();
                            self.input::<T, M, W>(
                                &g,
                                ci,
                                t0,
                                t1,
                                self.v_rows(ci, tpb),
                                vp.0,
                                scratch,
                            );
                        })
                    });
            }

            // 2. Products and output transform, parallel over output-channel
            // chunks, a group of tile panels at a time.
            let v_ref = &*v;
            let g_ref = &g;
            out.par_chunks_mut(chunk_rows * plane_len)
                .enumerate()
                .for_each(|(chunk, dst)| {
                    let mp0 = chunk * chunk_panels;
                    let mp1 = (mp0 + chunk_panels).min(m_panels);
                    let co0 = chunk * chunk_rows;
                    let rows = dst.len() / plane_len;
                    M_BUF.with(|buf| {
                        let mut buf = buf.borrow_mut();
                        let lazy_len = if lazy { u_chunk_len } else { 0 };
                        buf.ensure(group * m_len + (T * M + M * M) * nr + lazy_len + amx_len);
                        let (mbuf, rest) = buf.as_mut_slice().split_at_mut(group * m_len);
                        let (scratch, rest) = rest.split_at_mut((T * M + M * M) * nr);
                        let (u_chunk, a_tiles) = rest.split_at_mut(lazy_len);
                        let mut segs = Vec::with_capacity(4);
                        // The output transform of tile panel `p` from its
                        // products `m` (the chunk's rows of every M[ξ]).
                        let mut output_panel = |m: &[f32], p: usize, scratch: &mut [f32]| {
                            let pt0 = t0 + p * nr;
                            segments(pt0, (pt0 + nr).min(t1), g_ref.tw, &mut segs);
                            for r in 0..rows {
                                let co = co0 + r;
                                let plane = &mut dst[r * plane_len..(r + 1) * plane_len];
                                let o = OutPlane {
                                    segs: &segs,
                                    oh,
                                    ow,
                                    bias: bias.map_or(0.0, |b| b[co]),
                                    act,
                                    residual: residual.map(|rs| &rs[co * plane_len..][..plane_len]),
                                };
                                self.output::<T, M, W>(&m[r * nr..], stride, &o, plane, scratch);
                            }
                        };
                        if row_blocks {
                            // U one transform row (six ξ) and one depth
                            // block at a time, into L2, each used at once by
                            // every panel of the block; the products of all
                            // the block's panels are kept.
                            let UStore::Lazy(taps) = &self.u else {
                                unreachable!("row blocks need lazy U")
                            };
                            let n = mp1 - mp0;
                            for (bi, &(k0, kc, _)) in self.kblocks.iter().enumerate() {
                                let per_xi = chunk_per_xi(n * mr * kc);
                                for row in 0..T {
                                    self.pack_row_block::<T, M, W>(
                                        taps.as_slice(),
                                        mp0..mp1,
                                        k0,
                                        kc,
                                        row,
                                        u_chunk,
                                        per_xi,
                                    );
                                    let u = UView {
                                        u: u_chunk,
                                        per_xi,
                                        panels: n,
                                        mp_base: mp0,
                                    };
                                    for j in 0..T {
                                        let xi = row * T + j;
                                        for p in 0..panels {
                                            let cols = nr.min(t1 - t0 - p * nr);
                                            let bp = &v_ref[block_rows[bi].at(xi, p)..];
                                            let c = &mut mbuf[p * m_len + xi * stride..];
                                            self.panel_products(
                                                &u,
                                                j,
                                                mp0..mp1,
                                                0,
                                                kc,
                                                bp,
                                                cols,
                                                c,
                                                bi > 0,
                                            );
                                        }
                                    }
                                }
                            }
                            for p in 0..panels {
                                output_panel(&mbuf[p * m_len..], p, scratch);
                            }
                            return;
                        }
                        let u = match &self.u {
                            UStore::Packed(all) => UView {
                                u: all.as_slice(),
                                per_xi: self.per_xi(),
                                panels: m_panels,
                                mp_base: 0,
                            },
                            UStore::Lazy(taps) => {
                                PACK_SCRATCH.with(|ps| {
                                    self.pack_u_chunk::<T, M, W>(
                                        taps.as_slice(),
                                        mp0,
                                        mp1,
                                        u_chunk,
                                        &mut ps.borrow_mut(),
                                    )
                                });
                                UView {
                                    u: u_chunk,
                                    per_xi: chunk_per_xi((mp1 - mp0) * mr * self.depth),
                                    panels: mp1 - mp0,
                                    mp_base: mp0,
                                }
                            }
                        };
                        let (nj, nkk) = (rows / amx::ROWS, self.depth / amx::COLS);
                        let tiles = if self.amx {
                            for xi in 0..points {
                                let dst = &mut a_tiles[xi * nj * nkk * amx::TILE..];
                                for &(k0, kc, _) in &self.kblocks {
                                    for mp in mp0..mp1 {
                                        let src = u.at(xi, mp, k0, kc, mr);
                                        amx::pack_a_panel(src, mp * mr - co0, k0, nkk, mr, dst);
                                    }
                                }
                            }
                            amx::Tiles::new()
                        } else {
                            None
                        };
                        // Groups of `group` panels: each U panel is read
                        // once per group, from L2, and each B sub-panel of
                        // the depth block stays in L1 for the chunk's row
                        // panels.
                        for g0 in (0..panels).step_by(group) {
                            let g1 = (g0 + group).min(panels);
                            for xi in 0..points {
                                for (bi, &(k0, kc, _)) in self.kblocks.iter().enumerate() {
                                    if let Some(tiles) = &tiles {
                                        for p in g0..g1 {
                                            let bp = v_ref[block_rows[bi].at(xi, p)..].as_ptr();
                                            for j in 0..nj {
                                                let a = &a_tiles[((xi * nj + j) * nkk
                                                    + k0 / amx::COLS)
                                                    * amx::TILE..];
                                                let c = &mut mbuf[(p - g0) * m_len
                                                    + xi * stride
                                                    + j * amx::ROWS * nr..];
                                                // SAFETY: `a` holds the block's kc/16 tiles,
                                                // the panel's kc pair rows of nr = 48 words
                                                // lie in the block buffer, and C is 16 rows of
                                                // nr floats in this task's buffer.
                                                unsafe {
                                                    tiles.panel(
                                                        kc / amx::COLS,
                                                        a.as_ptr(),
                                                        bp,
                                                        nr,
                                                        c.as_mut_ptr(),
                                                        nr,
                                                        bi > 0,
                                                    )
                                                };
                                            }
                                        }
                                        continue;
                                    }
                                    for p in g0..g1 {
                                        let cols = nr.min(t1 - t0 - p * nr);
                                        let bp = &v_ref[block_rows[bi].at(xi, p)..];
                                        let c = &mut mbuf[(p - g0) * m_len + xi * stride..];
                                        self.panel_products(
                                            &u,
                                            xi,
                                            mp0..mp1,
                                            k0,
                                            kc,
                                            bp,
                                            cols,
                                            c,
                                            bi > 0,
                                        );
                                    }
                                }
                            }
                            for p in g0..g1 {
                                output_panel(&mbuf[(p - g0) * m_len..], p, scratch);
                            }
                        }
                    });
                });
            t0 = t1;
        }
        debug_assert_eq!(out.len(), self.c_out * plane_len);
        crate::pool::give(v_buf);
    }
}

/// The bf16 products' depth, block depth and tiles for `c_in` input channels.
fn bf16_products(c_in: usize) -> (usize, usize, KernelFn, Option<(usize, NarrowKernelFn)>) {
    #[cfg(target_arch = "x86_64")]
    {
        use crate::microkernel::x86;
        (
            c_in.div_ceil(2),
            WINO_BF16_KC,
            x86::avx512bf16_gemm_8x48,
            Some((16, x86::avx512bf16_gemm_narrow_8x16n as NarrowKernelFn)),
        )
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        let _ = c_in;
        unreachable!("bf16 products exist only on x86-64 (checked by the caller)")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The AVX-512 weight transform gives the generic one's bits, for all
    /// rows and each single row, with full and partial lane blocks.
    fn avx512_weights_match<const T: usize, const M: usize, W: Points<T, M>>() {
        let mut rng = crate::Rng::new(77);
        for len in [1, 15, 16, 17, 40, 64] {
            let taps: Vec<Vec<f32>> = (0..9).map(|_| rng.normal_vec(len, 1.0)).collect();
            let g: [&[f32]; 9] = std::array::from_fn(|k| taps[k].as_slice());
            let stride = len + 3;
            let mut generic = vec![0.0f32; T * T * stride];
            transform_lanes::<T, M, W>(g, &mut generic, stride, 0..T);
            let all = std::iter::once(0..T).chain((0..T).map(|r| r..r + 1));
            for rows in all {
                let mut fast = vec![f32::NAN; rows.len() * T * stride];
                // SAFETY: the CPU has AVX-512F (checked by the caller).
                unsafe { weights_avx512::<T, M, W>(g, &mut fast, stride, rows.clone()) };
                let first = rows.start * T;
                for k in 0..rows.len() * T {
                    let (a, b) = (
                        &fast[k * stride..][..len],
                        &generic[(first + k) * stride..][..len],
                    );
                    assert!(
                        a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits()),
                        "T {T}, len {len}, rows {rows:?}, point {}",
                        first + k
                    );
                }
            }
        }
    }

    /// The per-image tile: F4 where its tiles fit the row-block panels (a
    /// 30×40 map: 80 tiles, 2 panels of 48) or F6 would not save product
    /// columns (a 4×4 or 8×8 output: one panel either way), F6 on the 60×80
    /// and 120×160 maps (7 and 25 F4 panels; 9216 vs 12096 and 36864 vs
    /// 43200 columns).
    #[test]
    fn tile_choice_per_image() {
        // 48 F5 tiles fill one panel: 2352 product lanes against F4's 2880.
        assert_eq!(Tile::for_output(30, 40), Tile::F5);
        assert_eq!(Tile::for_output(15, 20), Tile::F5);
        assert_eq!(Tile::for_output(60, 80), Tile::F5);
        assert_eq!(Tile::for_output(120, 160), Tile::F5);
        // A few tiles: F4's 16 lanes of 36 points against F5's of 49.
        assert_eq!(Tile::for_output(4, 4), Tile::F4);
        assert_eq!(Tile::for_output(8, 8), Tile::F4);
        assert_eq!(Tile::for_output(8, 10), Tile::F4);
    }

    #[test]
    #[cfg(target_arch = "x86_64")]
    fn avx512_weight_transform_matches_generic_bits() {
        if !Isa::Avx512.is_available() {
            eprintln!("SKIPPED: AVX-512 weight transform (the CPU lacks AVX-512)");
            return;
        }
        avx512_weights_match::<6, 4, F4>();
        avx512_weights_match::<8, 6, F6>();
        avx512_weights_match::<7, 5, F5>();
        avx512_weights_match::<9, 4, S4>();
        avx512_weights_match::<11, 5, S5>();
    }
}
