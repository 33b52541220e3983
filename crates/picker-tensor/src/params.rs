//! Block sizes of the packed GEMM, in one place (tuned on a 2-core Zen 5 with
//! 48 KiB L1d and 1 MiB L2 per core; see `benches/kernels.rs`).

/// Depth of one packed block: `KC × NR` floats of B stay in L1 while the
/// micro-kernel streams the packed A panels from L2.
pub const KC: usize = 256;

/// Depth of one block of the shifted GEMM (B rows read in place): `SHIFTED_KC × NR`
/// floats of B stay in L1 while every row panel of A passes over them.
pub const SHIFTED_KC: usize = 128;

/// Most NR-wide B panels one task packs for a K block (`KC × NR × this` floats, kept in L2).
pub const MAX_PANELS_PER_TASK: usize = 8;

/// Tasks per worker thread the GEMM driver aims for, so work stealing can even out the load.
pub const TASKS_PER_THREAD: usize = 4;

/// Alignment in bytes of packed buffers (one cache line, one zmm register).
pub const ALIGN: usize = 64;

/// Widest micro-kernel tile of any family (`NR` of the AVX-512 kernel).
pub const MAX_NR: usize = 48;

/// Winograd: input tiles per block, in `NR`-wide panels of the micro-kernel. A
/// block's transformed input (`36 × c_in × NR × this` floats) is shared by all
/// threads and should stay in L2/L3 while every output-channel chunk reads it.
pub const WINO_PANELS_PER_BLOCK: usize = 2;

/// Winograd with lazy weights: bytes of transformed input one block may
/// hold (shared by all threads in L3), so each output-channel chunk makes
/// its part of `U` once per block rather than once per panel.
pub const WINO_LAZY_V_BYTES: usize = 16 << 20;

/// Winograd in f32: input channels per depth block of the products. With
/// lazy weights (the networks' default) the products of every panel of a
/// block are kept together (megabytes, past the L2) and accumulated onto
/// once per depth block after the first; one block for up to 256 channels
/// writes them once and never reads them back before the output transform,
/// at the cost of a B panel (48 KiB at 256 channels) that overflows the L1
/// into the L2, which the kernel's three vector loads per 24 FMAs tolerate.
/// Measured on the 2-core Zen 4 host, 2 threads, 256 against 128 built in
/// one process and their passes alternated (`pair_bench`, each order run):
/// EnvMap 480×640 0.955, MSN 240×320 0.962, MSN 480×640 0.95, IRN 240×320
/// 0.92, EnvMap 240×320 1.00 (its 30×40 blocks are one panel); with packed
/// weights within the noise (`tune res`, F(4×4) 0.976, F(5×5) 1.004), and
/// packed and lazy weights keep giving the same bits with one constant.
pub const WINO_KC: usize = 256;

/// Winograd in bf16: pair words (two input channels each) per depth block, so
/// a block's `WINO_BF16_KC × NR` B panel (24 KiB) stays in L1.
pub const WINO_BF16_KC: usize = 128;

/// Winograd: fewest output channels one product task computes for a block
/// (rounded to whole `MR` panels; a task takes `c_out / threads` of them,
/// within this and `WINO_CO_PER_TASK_MAX`).
pub const WINO_CO_PER_TASK: usize = 32;

/// Winograd: most output channels per product task. More channels read each
/// B panel for more rows (measured on a 2-core AVX-512 Xeon at 60×80×256:
/// 128 gave the products ~20% over 32); the task's `36 × this × NR`
/// products per panel stay in L2 for the output transform.
pub const WINO_CO_PER_TASK_MAX: usize = 128;

/// Stride-2 Winograd (81 points): most output channels per product task, so
/// that a task's `81 × this × NR` products per panel (0.5 MB) stay in L2
/// for the output transform (2-core Zen 4, 2 threads, five interleaved
/// rounds of `tune` on the thesis layers: the EnvMap's 64→128 at 120×160
/// 3.0–3.7 ms and 128→256 at 60×80 2.62–2.74 ms with 32, against 3.0–4.1
/// and 2.72–2.87 ms with 128; the IRN's 128→256 at 120×160 10.6–12.0 ms
/// against 10.9–11.6).
pub const WINO_S2_CO_PER_TASK_MAX: usize = 32;

/// Winograd: most tile panels whose products one task runs before their
/// output transform, each `U` panel being read once for all of them (fewer
/// where the L2 cannot hold their products).
pub const WINO_PANELS_PER_GROUP: usize = 2;

/// Winograd with lazy f32 weights: most tile panels per block of tiles. For
/// each block, each output-channel chunk makes its `U` one transform row
/// (`T` of the `ξ`) and one depth block at a time, small enough to stay in
/// L2, and runs the products of every panel of the block with it at once,
/// keeping all the block's products. Larger maps take several blocks, the
/// tiles split evenly (IRN 480×640, 120×160 blocks, 2 threads on an Intel
/// Xeon: 5.2–5.4 s against 5.8 s when the chunk's whole `U` was made once per
/// 16 MB block and read back from L3 for each group of panels; blocks of 2,
/// 3, 4 and 6 panels gave 5.3, 5.2–5.3, 5.2–5.4 and 5.6 s).
pub const WINO_ROW_BLOCK_PANELS: usize = 4;
