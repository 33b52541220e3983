//! Convolution layers with packed weights: [`Conv2d`] and [`ConvTranspose2d`]
//! (PyTorch semantics, zero padding, any kernel and stride).

use crate::activation::Activation;
use crate::direct::{self, conv_direct, DirectProblem};
use crate::error::{invalid, shape_err, Result};
use crate::gemm::{gemm, BSource, DenseB, Epilogue, PackedA};
use crate::isa::Isa;
use rayon::prelude::*;

use crate::microkernel::MicroKernel;
use crate::pad::{reflect_index, reflect_pad, Fill};
use crate::params::{MAX_NR, SHIFTED_KC};
use crate::pixtile::{self, PixelTiles};
use crate::shifted::{
    padded_copy, phase_copy, row_window_copy, shifted_gemm, shifted_gemm_interleaved, OutMap,
    PhasePart, RowPhaseMap, ShiftedB,
};
use crate::tensor::Tensor;
use crate::winograd::{Tile, Winograd};

/// Shape of a 2-D convolution (PyTorch `Conv2d`, zero padding, no dilation, no groups).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct ConvSpec {
    /// Input channels.
    pub c_in: usize,
    /// Output channels.
    pub c_out: usize,
    /// Kernel height.
    pub kh: usize,
    /// Kernel width.
    pub kw: usize,
    /// Stride (both axes).
    pub stride: usize,
    /// Zero padding (all four sides).
    pub pad: usize,
}

impl ConvSpec {
    /// A square `k × k` convolution.
    pub fn square(c_in: usize, c_out: usize, k: usize, stride: usize, pad: usize) -> Self {
        Self {
            c_in,
            c_out,
            kh: k,
            kw: k,
            stride,
            pad,
        }
    }

    fn validate(&self) -> Result<()> {
        if self.c_in == 0 || self.c_out == 0 || self.kh == 0 || self.kw == 0 || self.stride == 0 {
            return Err(invalid(
                "conv2d",
                format!("channels, kernel and stride must be positive: {self:?}"),
            ));
        }
        if checked_product(&[self.c_out, self.c_in, self.kh, self.kw]).is_none() {
            return Err(invalid(
                "conv2d",
                format!("the weight's length overflows: {self:?}"),
            ));
        }
        Ok(())
    }

    /// Output `(height, width)` for an input of `h × w`; refuses inputs smaller than the kernel.
    pub fn out_hw(&self, h: usize, w: usize) -> Result<(usize, usize)> {
        self.validate()?;
        let padded = |n: usize| self.pad.checked_mul(2).and_then(|p| p.checked_add(n));
        let (Some(hp), Some(wp)) = (padded(h), padded(w)) else {
            return Err(invalid(
                "conv2d",
                format!("the padded {h}x{w} input overflows: {self:?}"),
            ));
        };
        if hp < self.kh || wp < self.kw {
            return Err(shape_err(
                "conv2d",
                "padded input",
                format!("at least {}x{}", self.kh, self.kw),
                format!("{hp}x{wp}"),
            ));
        }
        Ok((
            (hp - self.kh) / self.stride + 1,
            (wp - self.kw) / self.stride + 1,
        ))
    }

    /// Length of the weight `[c_out, c_in, kh, kw]` (`usize::MAX` when it
    /// overflows, a length no weight has; such specs are refused by every
    /// layer and op).
    pub fn weight_len(&self) -> usize {
        checked_product(&[self.c_out, self.c_in, self.kh, self.kw]).unwrap_or(usize::MAX)
    }

    /// Floating-point operations (2 × multiply-adds) for one `h × w` input image.
    pub fn flops(&self, h: usize, w: usize) -> u64 {
        match self.out_hw(h, w) {
            Ok((oh, ow)) => sat_flops(self.weight_len(), oh, ow),
            Err(_) => 0,
        }
    }
}

/// Shape of a 2-D transposed convolution (PyTorch `ConvTranspose2d`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct ConvTransposeSpec {
    /// Input channels.
    pub c_in: usize,
    /// Output channels.
    pub c_out: usize,
    /// Kernel height.
    pub kh: usize,
    /// Kernel width.
    pub kw: usize,
    /// Stride (both axes).
    pub stride: usize,
    /// Padding removed from each side of the full output.
    pub pad: usize,
    /// Extra rows/columns added at the bottom/right (must be < stride).
    pub output_padding: usize,
}

impl ConvTransposeSpec {
    /// A square `k × k` transposed convolution.
    pub fn square(
        c_in: usize,
        c_out: usize,
        k: usize,
        stride: usize,
        pad: usize,
        output_padding: usize,
    ) -> Self {
        Self {
            c_in,
            c_out,
            kh: k,
            kw: k,
            stride,
            pad,
            output_padding,
        }
    }

    fn validate(&self) -> Result<()> {
        if self.c_in == 0 || self.c_out == 0 || self.kh == 0 || self.kw == 0 || self.stride == 0 {
            return Err(invalid(
                "conv_transpose2d",
                format!("channels, kernel and stride must be positive: {self:?}"),
            ));
        }
        if checked_product(&[self.c_in, self.c_out, self.kh, self.kw]).is_none() {
            return Err(invalid(
                "conv_transpose2d",
                format!("the weight's length overflows: {self:?}"),
            ));
        }
        if self.output_padding >= self.stride {
            return Err(invalid(
                "conv_transpose2d",
                format!(
                    "output_padding {} must be smaller than stride {}",
                    self.output_padding, self.stride
                ),
            ));
        }
        Ok(())
    }

    /// Output `(height, width)`: `(h-1)·stride − 2·pad + k + output_padding`.
    pub fn out_hw(&self, h: usize, w: usize) -> Result<(usize, usize)> {
        self.validate()?;
        let full = |n: usize, k: usize| {
            (n.max(1) - 1)
                .checked_mul(self.stride)
                .and_then(|v| v.checked_add(k + self.output_padding))
        };
        let (Some(fh), Some(fw), Some(pads)) =
            (full(h, self.kh), full(w, self.kw), self.pad.checked_mul(2))
        else {
            return Err(invalid(
                "conv_transpose2d",
                format!("the output of a {h}x{w} input overflows: {self:?}"),
            ));
        };
        if h == 0 || w == 0 || fh <= pads || fw <= pads {
            return Err(shape_err(
                "conv_transpose2d",
                "output size",
                "positive",
                format!("input {h}x{w} with {self:?}"),
            ));
        }
        Ok((fh - pads, fw - pads))
    }

    /// Length of the weight `[c_in, c_out, kh, kw]` (`usize::MAX` when it
    /// overflows; such specs are refused by every layer and op).
    pub fn weight_len(&self) -> usize {
        checked_product(&[self.c_in, self.c_out, self.kh, self.kw]).unwrap_or(usize::MAX)
    }

    /// Floating-point operations (2 × multiply-adds, direct form) for one `h × w` input image.
    pub fn flops(&self, h: usize, w: usize) -> u64 {
        sat_flops(self.weight_len(), h, w)
    }
}

/// The product of `v`, or `None` when it overflows `usize`.
pub(crate) fn checked_product(v: &[usize]) -> Option<usize> {
    v.iter().try_fold(1usize, |a, &b| a.checked_mul(b))
}

/// `2 · weights · h · w`, saturating at `u64::MAX` instead of overflowing.
fn sat_flops(weight_len: usize, h: usize, w: usize) -> u64 {
    2u64.saturating_mul(weight_len as u64)
        .saturating_mul(h as u64)
        .saturating_mul(w as u64)
}

fn check_weight(op: &'static str, len: usize, expected: usize) -> Result<()> {
    if len != expected {
        return Err(shape_err(op, "weight length", expected, len));
    }
    Ok(())
}

fn check_bias(op: &'static str, bias: Option<&[f32]>, c_out: usize) -> Result<Option<Vec<f32>>> {
    match bias {
        Some(b) if b.len() != c_out => Err(shape_err(op, "bias length", c_out, b.len())),
        b => Ok(b.map(<[f32]>::to_vec)),
    }
}

fn kernel_for(op: &'static str, isa: Isa) -> Result<MicroKernel> {
    MicroKernel::for_isa(isa)
        .ok_or_else(|| invalid(op, format!("this CPU cannot run the {isa} kernels")))
}

/// A convolution with its weights packed for the GEMM, its bias and activation
/// fused: `y = act(conv(x, w) + b) [+ residual]`.
#[derive(Clone)]
pub struct Conv2d {
    spec: ConvSpec,
    act: Activation,
    bias: Option<Vec<f32>>,
    path: ConvPath,
}

/// Which algorithm a [`Conv2d`] uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum ConvAlgorithm {
    /// Chosen from the shape: the direct convolution for stride-1 layers
    /// with ≤ 4 outputs and kernels wider than 1; Winograd for 3×3 stride-1 layers with
    /// ≥ 16 input and output channels, F(4×4, 3×3) (`PICKER_WINOGRAD_TILE=5`
    /// or `=6` takes F(5×5, 3×3) or F(6×6, 3×3) for f32; `=4` keeps F(4×4)
    /// where the low-memory variant would choose per image; `PICKER_WINOGRAD_WEIGHTS=lazy` or
    /// [`crate::low_memory`] picks
    /// [`ConvAlgorithm::WinogradLowMemory`]; [`crate::precision`] bf16 the
    /// bf16 variants); on the AVX-512 family, the stride-2 Winograd
    /// ([`ConvAlgorithm::Winograd5Stride2`], or
    /// [`ConvAlgorithm::WinogradStride2`] with `PICKER_WINOGRAD_S2_TILE=4`;
    /// the weights made per pass with
    /// `PICKER_WINOGRAD_WEIGHTS=lazy` or [`crate::low_memory`]; in f32 at
    /// either precision) for 3×3 stride-2 layers with ≥ 16 input channels
    /// and at least as many outputs (the encoders' down convs: 13–24% faster
    /// than the pixel tiles on a 2-core Zen 4; slower than the pixel tiles
    /// where the outputs are fewer, e.g. 256→128, and than the shifted GEMM
    /// with the AVX2 kernels, which keep those), and the pixel tiles
    /// ([`ConvAlgorithm::PixelTiles`]) for other strided layers with ≥ 32
    /// outputs; the shifted GEMM for other kernels larger than 1×1 or with
    /// padding; else (1×1) the packed GEMM.
    /// With the environment variable `PICKER_CONV=gemm` set when a layer is
    /// built, every layer takes the packed GEMM (for comparisons).
    Auto,
    /// As [`ConvAlgorithm::Auto`], with the Winograd weights made at every
    /// pass ([`ConvAlgorithm::WinogradLowMemoryAutoTile`] in f32, the tile
    /// chosen per image, or the bf16 twin;
    /// [`ConvAlgorithm::WinogradStride2LowMemory`] for stride 2) unless
    /// `PICKER_WINOGRAD_WEIGHTS=packed`: for layers that see few tiles (the
    /// EnvMap's residual blocks, at 1/8 of the input), where making each
    /// chunk's weights from the 3×3 ones beats reading the packed ones (4×
    /// the memory) from RAM.
    AutoLowMemory,
    /// Packed GEMM over an implicit im2col (any shape).
    Gemm,
    /// Direct row-vectorised convolution (stride 1, ≤ 4 outputs; the
    /// padding filled in per task, no padded copy).
    Direct,
    /// Winograd F(4×4, 3×3) (3×3 kernels, stride 1, any zero padding), its
    /// transformed weights packed once (4× the memory of the 3×3 weights).
    Winograd,
    /// Winograd F(4×4, 3×3) keeping only the 3×3 weights: the transformed
    /// weights are made at every forward pass into a reused buffer (slower,
    /// for memory-bound use).
    WinogradLowMemory,
    /// Winograd F(6×6, 3×3) (3×3 kernels, stride 1, any zero padding): 64
    /// products per 36 outputs, 21% fewer than F(4×4) per output, for about
    /// twice its rounding error (still within
    /// [`crate::Tolerance::WINOGRAD_F32`]); its transformed weights packed
    /// once (7.1× the memory of the 3×3 weights).
    Winograd6,
    /// [`ConvAlgorithm::Winograd6`] keeping only the 3×3 weights, as
    /// [`ConvAlgorithm::WinogradLowMemory`] does.
    Winograd6LowMemory,
    /// Winograd F(5×5, 3×3) (3×3 kernels, stride 1, any zero padding): 49
    /// products per 25 outputs, for maps whose tiles fill its panels (a
    /// 30×40 output is 48 tiles); its transformed weights packed once (5.4×
    /// the memory of the 3×3 weights).
    Winograd5,
    /// [`ConvAlgorithm::Winograd5`] keeping only the 3×3 weights, as
    /// [`ConvAlgorithm::WinogradLowMemory`] does.
    Winograd5LowMemory,
    /// Winograd keeping only the 3×3 weights, with the tile chosen per
    /// image: F(4×4, 3×3) for maps of a few tiles, else F(5×5, 3×3) (see
    /// `winograd::Tile::for_output`: on a 2-core Zen 4 it beat F(4×4) by
    /// 12–18% on 15×20 and 30×40 maps and F(6×6) by 3–8% on 60×80 and
    /// 120×160 ones). What [`ConvAlgorithm::AutoLowMemory`] takes for f32
    /// 3×3 layers.
    WinogradLowMemoryAutoTile,
    /// Winograd F(4×4, 3×3) with its products in bfloat16 (AVX512_BF16
    /// `vdpbf16ps`; transformed weights and inputs rounded to bf16, sums in
    /// f32), the transformed weights packed once (2× the memory of the 3×3
    /// weights). Needs the AVX-512 family and AVX512_BF16
    /// ([`ConvAlgorithm::runs_on`]). One layer is off by up to ~0.2 on
    /// outputs of standard deviation 1 ([`crate::Tolerance::WINOGRAD_BF16`]).
    WinogradBf16,
    /// [`ConvAlgorithm::WinogradBf16`] keeping only the 3×3 weights, as
    /// [`ConvAlgorithm::WinogradLowMemory`] does.
    WinogradBf16LowMemory,
    /// Winograd for 3×3 stride-2 layers (any zero padding): per axis the
    /// polyphase split, F(4, 2) on the even inputs with the even taps and the
    /// odd inputs times the middle tap, 81 products per 4×4 output tile
    /// instead of 144; its transformed weights packed once (9× the memory
    /// of the 3×3 weights).
    WinogradStride2,
    /// [`ConvAlgorithm::WinogradStride2`] keeping only the 3×3 weights, as
    /// [`ConvAlgorithm::WinogradLowMemory`] does.
    WinogradStride2LowMemory,
    /// The stride-2 Winograd with 5×5 output tiles (any zero padding): per
    /// axis F(5, 2) on the even inputs with the even taps and the odd inputs
    /// times the middle tap, 121 products per 5×5 output tile (4.84 per
    /// output against [`ConvAlgorithm::WinogradStride2`]'s 5.06), and whole
    /// panels of 48 tiles on the EnvMap's 30×40 and 60×80 outputs (48 and
    /// 192 tiles, against 80 and 300 of 4×4); its transformed weights
    /// packed once (13.4× the memory of the 3×3 weights).
    /// [`ConvAlgorithm::Auto`] takes it on AVX-512.
    Winograd5Stride2,
    /// [`ConvAlgorithm::Winograd5Stride2`] keeping only the 3×3 weights, as
    /// [`ConvAlgorithm::WinogradLowMemory`] does.
    Winograd5Stride2LowMemory,
    /// Packed-A GEMM that reads the B rows in place from a padded copy of
    /// the input (any kernel; stride `s > 1` through the `s × s` phase planes
    /// of the input): no im2col packing.
    Shifted,
    /// Output channels in the SIMD lanes: tiles of 6 output pixels × 64
    /// output channels, the input values broadcast where they lie (any
    /// kernel, stride 1–4; no phase planes, no padded copy but for the
    /// tiles on the border). Needs the AVX-512 family
    /// ([`ConvAlgorithm::runs_on`]). [`ConvAlgorithm::Auto`] takes it for
    /// strided layers with at least 32 outputs on AVX-512.
    PixelTiles,
}

impl ConvAlgorithm {
    /// Every algorithm that can be asked for explicitly.
    pub const EXPLICIT: [ConvAlgorithm; 17] = [
        ConvAlgorithm::Gemm,
        ConvAlgorithm::Direct,
        ConvAlgorithm::Winograd,
        ConvAlgorithm::WinogradLowMemory,
        ConvAlgorithm::Winograd6,
        ConvAlgorithm::Winograd6LowMemory,
        ConvAlgorithm::Winograd5,
        ConvAlgorithm::Winograd5LowMemory,
        ConvAlgorithm::WinogradLowMemoryAutoTile,
        ConvAlgorithm::WinogradBf16,
        ConvAlgorithm::WinogradBf16LowMemory,
        ConvAlgorithm::WinogradStride2,
        ConvAlgorithm::WinogradStride2LowMemory,
        ConvAlgorithm::Winograd5Stride2,
        ConvAlgorithm::Winograd5Stride2LowMemory,
        ConvAlgorithm::Shifted,
        ConvAlgorithm::PixelTiles,
    ];

    /// True when the algorithm computes in bf16.
    pub fn is_bf16(self) -> bool {
        matches!(
            self,
            ConvAlgorithm::WinogradBf16 | ConvAlgorithm::WinogradBf16LowMemory
        )
    }

    /// True when this CPU can run the algorithm with the `isa` family: the
    /// bf16 variants need [`Isa::Avx512`] and AVX512_BF16, the others any
    /// family the CPU has.
    pub fn runs_on(self, isa: Isa) -> bool {
        isa.is_available()
            && (!self.is_bf16() || (isa == Isa::Avx512 && crate::bf16::available()))
            && (self != ConvAlgorithm::PixelTiles || isa == Isa::Avx512)
    }

    /// True for the Winograd algorithms (any tile, stride, weights or
    /// precision): their rounding differs from a direct sum's
    /// ([`crate::Tolerance::WINOGRAD_F32`], [`crate::Tolerance::WINOGRAD_BF16`]).
    pub fn is_winograd(self) -> bool {
        matches!(
            self,
            ConvAlgorithm::Winograd
                | ConvAlgorithm::WinogradLowMemory
                | ConvAlgorithm::Winograd6
                | ConvAlgorithm::Winograd6LowMemory
                | ConvAlgorithm::Winograd5
                | ConvAlgorithm::Winograd5LowMemory
                | ConvAlgorithm::WinogradLowMemoryAutoTile
                | ConvAlgorithm::WinogradBf16
                | ConvAlgorithm::WinogradBf16LowMemory
                | ConvAlgorithm::WinogradStride2
                | ConvAlgorithm::WinogradStride2LowMemory
                | ConvAlgorithm::Winograd5Stride2
                | ConvAlgorithm::Winograd5Stride2LowMemory
        )
    }

    /// True when the algorithm can run a layer of this shape.
    pub fn applies(self, s: &ConvSpec) -> bool {
        match self {
            ConvAlgorithm::Auto | ConvAlgorithm::AutoLowMemory | ConvAlgorithm::Gemm => true,
            ConvAlgorithm::Direct => s.stride == 1 && s.c_out <= direct::MAX_CO,
            ConvAlgorithm::WinogradStride2
            | ConvAlgorithm::WinogradStride2LowMemory
            | ConvAlgorithm::Winograd5Stride2
            | ConvAlgorithm::Winograd5Stride2LowMemory => s.kh == 3 && s.kw == 3 && s.stride == 2,
            ConvAlgorithm::Shifted => true,
            ConvAlgorithm::PixelTiles => s.stride <= pixtile::MAX_STRIDE,
            // The stride-1 Winograd variants.
            a => {
                debug_assert!(a.is_winograd());
                s.kh == 3 && s.kw == 3 && s.stride == 1
            }
        }
    }

    fn resolve(self, s: &ConvSpec, isa: Isa) -> ConvAlgorithm {
        let force_gemm = std::env::var("PICKER_CONV").as_deref() == Ok("gemm");
        let weights = std::env::var("PICKER_WINOGRAD_WEIGHTS");
        let auto = matches!(self, ConvAlgorithm::Auto | ConvAlgorithm::AutoLowMemory);
        match self {
            _ if auto && force_gemm => ConvAlgorithm::Gemm,
            _ if auto && s.stride == 1 && s.c_out <= direct::MAX_CO && s.kw > 1 => {
                ConvAlgorithm::Direct
            }
            _ if auto && ConvAlgorithm::Winograd.applies(s) && s.c_in >= 16 && s.c_out >= 16 => {
                let lazy = crate::low_memory()
                    || weights.as_deref() == Ok("lazy")
                    || (self == ConvAlgorithm::AutoLowMemory && weights.as_deref() != Ok("packed"));
                let tile = std::env::var("PICKER_WINOGRAD_TILE");
                match (crate::precision(), lazy, tile.as_deref()) {
                    (crate::Precision::Bf16, true, _) => ConvAlgorithm::WinogradBf16LowMemory,
                    (crate::Precision::Bf16, false, _) => ConvAlgorithm::WinogradBf16,
                    (_, true, Ok("6")) => ConvAlgorithm::Winograd6LowMemory,
                    (_, true, Ok("5")) => ConvAlgorithm::Winograd5LowMemory,
                    (_, true, Ok("4")) => ConvAlgorithm::WinogradLowMemory,
                    (_, true, _) => ConvAlgorithm::WinogradLowMemoryAutoTile,
                    (_, false, Ok("6")) => ConvAlgorithm::Winograd6,
                    (_, false, Ok("5")) => ConvAlgorithm::Winograd5,
                    (_, false, _) => ConvAlgorithm::Winograd,
                }
            }
            _ if auto
                && isa == Isa::Avx512
                && s.c_out >= s.c_in
                && ConvAlgorithm::WinogradStride2.applies(s)
                && s.c_in >= 16
                && s.c_out >= 16 =>
            {
                // Small packed weights (`WINO_S2_PACKED_MAX_BYTES`) stay
                // packed even when low on memory: the encoders' first down
                // conv runs in bands (`reflect_then`), each of which would
                // make them again.
                // 5×5 tiles (see `THEN_CONV_S5_BAND`) unless 4×4 ones are
                // asked for.
                let five = std::env::var("PICKER_WINOGRAD_S2_TILE").as_deref() != Ok("4");
                let tile = if five { Tile::S5 } else { Tile::S4 };
                let packed_bytes = tile.points() * s.c_in * s.c_out * 4;
                let lazy = crate::low_memory()
                    || weights.as_deref() == Ok("lazy")
                    || (self == ConvAlgorithm::AutoLowMemory
                        && weights.as_deref() != Ok("packed")
                        && packed_bytes > WINO_S2_PACKED_MAX_BYTES);
                match (five, lazy) {
                    (true, true) => ConvAlgorithm::Winograd5Stride2LowMemory,
                    (true, false) => ConvAlgorithm::Winograd5Stride2,
                    (false, true) => ConvAlgorithm::WinogradStride2LowMemory,
                    (false, false) => ConvAlgorithm::WinogradStride2,
                }
            }
            _ if auto
                && isa == Isa::Avx512
                && s.stride > 1
                && s.c_out >= 32
                && ConvAlgorithm::PixelTiles.applies(s) =>
            {
                ConvAlgorithm::PixelTiles
            }
            _ if auto && (s.kh > 1 || s.kw > 1 || s.pad > 0) => ConvAlgorithm::Shifted,
            _ if auto => ConvAlgorithm::Gemm,
            other => other,
        }
    }
}

/// How a [`Conv2d`] runs.
#[derive(Clone)]
enum ConvPath {
    /// Packed GEMM over an implicit im2col with these `(dy, dx)` taps.
    Gemm {
        packed: PackedA,
        taps: Vec<(isize, isize)>,
    },
    /// Direct convolution (stride 1, ≤ `direct::MAX_CO` outputs), weights as
    /// `direct::pack_weights` lays them out.
    Direct { isa: Isa, weight: Vec<f32> },
    /// Winograd F(4×4, 3×3), f32 or bf16 products.
    Winograd { isa: Isa, wino: Winograd },
    /// Packed A, B rows read in place from a padded copy.
    /// `fold_kx`: the rows of A are `(co, kx)` and the columns `(ci, ky)`, so
    /// a layer with few outputs still fills the micro-kernel's rows; the `kw`
    /// partial sums of an output are added, shifted, afterwards.
    Shifted { packed: PackedA, fold_kx: bool },
    /// Output channels in the lanes (AVX-512).
    PixelTiles { tiles: PixelTiles },
}

/// Layers with at most this many outputs fold the kernel's columns into the
/// rows of the product (see `ConvPath::Shifted`).
const FOLD_MAX_CO: usize = 4;

impl std::fmt::Debug for Conv2d {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Conv2d")
            .field("spec", &self.spec)
            .field("act", &self.act)
            .field("bias", &self.bias.is_some())
            .field("isa", &self.isa())
            .field("algorithm", &self.algorithm())
            .finish()
    }
}

/// Checks `x` is an NCHW tensor with `c` channels.
fn check_input(op: &'static str, x: &Tensor, c: usize) -> Result<()> {
    if x.c() != c {
        return Err(shape_err(op, "input channels", c, x.c()));
    }
    Ok(())
}

/// Copies a short run (a panel row is at most a few dozen floats) without a
/// libc call: 16-float blocks move as vectors, the rest one by one.
#[inline(always)]
pub(crate) fn copy_short(dst: &mut [f32], src: &[f32]) {
    let mut d = dst.chunks_exact_mut(16);
    let mut s = src.chunks_exact(16);
    for (d, s) in (&mut d).zip(&mut s) {
        let v: [f32; 16] = s.try_into().expect("16");
        d.copy_from_slice(&v);
    }
    for (d, s) in d.into_remainder().iter_mut().zip(s.remainder()) {
        *d = *s;
    }
}

/// Zeroes a short run without a libc call.
#[inline(always)]
pub(crate) fn zero_short(dst: &mut [f32]) {
    let mut d = dst.chunks_exact_mut(16);
    for d in &mut d {
        d.copy_from_slice(&[0.0; 16]);
    }
    for v in d.into_remainder() {
        *v = 0.0;
    }
}

/// Implicit im2col over one image, generalised to any list of taps: row
/// `k = (ci, tap)` with `tap = (dy, dx)`, column `(oy, ox)` reads
/// `x[ci][oy·stride + dy][ox·stride + dx]`, zero outside the image.
struct Gather<'a> {
    x: &'a [f32],
    h: usize,
    w: usize,
    stride: usize,
    taps: &'a [(isize, isize)],
    ow: usize,
}

impl BSource for Gather<'_> {
    fn pack(&self, k0: usize, kc: usize, n0: usize, cols: usize, nr: usize, dst: &mut [f32]) {
        let (h, w, ow, s) = (self.h as isize, self.w, self.ow, self.stride);
        let panels = cols.div_ceil(nr);
        // Split the columns into runs that stay inside one output row and one
        // panel: `(offset in a panel-major k-row, oy, ox, len)`; the same for every k.
        let mut runs = Vec::with_capacity(2 * panels + 2);
        let (mut j, mut n) = (0, n0);
        while j < cols {
            let (oy, ox) = (n / ow, n % ow);
            let run = (cols - j).min(ow - ox).min(nr - j % nr);
            runs.push(((j / nr) * kc * nr + j % nr, oy, ox, run));
            j += run;
            n += run;
        }
        let tail = panels * nr - cols;
        let nt = self.taps.len();
        for kk in 0..kc {
            let k = k0 + kk;
            let (ci, (dy, dx)) = (k / nt, self.taps[k % nt]);
            let plane = &self.x[ci * self.h * w..(ci + 1) * self.h * w];
            let row_off = kk * nr;
            if tail > 0 {
                let last = (panels - 1) * kc * nr + row_off;
                zero_short(&mut dst[last + nr - tail..last + nr]);
            }
            for &(off, oy, ox, run) in &runs {
                let out = &mut dst[off + row_off..off + row_off + run];
                let iy = (oy * s) as isize + dy;
                if iy < 0 || iy >= h {
                    zero_short(out);
                    continue;
                }
                let src = &plane[iy as usize * w..(iy as usize + 1) * w];
                let ix0 = (ox * s) as isize + dx;
                if s == 1 {
                    let lo = (-ix0).clamp(0, run as isize) as usize;
                    let hi = (w as isize - ix0).clamp(lo as isize, run as isize) as usize;
                    zero_short(&mut out[..lo]);
                    if hi > lo {
                        let a = (ix0 + lo as isize) as usize;
                        copy_short(&mut out[lo..hi], &src[a..a + (hi - lo)]);
                    }
                    zero_short(&mut out[hi..]);
                } else {
                    // ix = ix0 + t·s lies in [0, w) for t in [lo, hi)
                    let si = s as isize;
                    let lo = (((-ix0).max(0) + si - 1) / si).min(run as isize);
                    let hi = (((w as isize - ix0).max(0) + si - 1) / si).clamp(lo, run as isize);
                    let (lo, hi) = (lo as usize, hi as usize);
                    zero_short(&mut out[..lo]);
                    let base = ix0 + (lo * s) as isize;
                    for (t, o) in out[lo..hi].iter_mut().enumerate() {
                        *o = src[base as usize + t * s];
                    }
                    zero_short(&mut out[hi..]);
                }
            }
        }
    }
}

impl Conv2d {
    /// Packs `weight` (`[c_out, c_in, kh, kw]`, PyTorch order) for the fastest kernels of this CPU.
    pub fn new(
        spec: ConvSpec,
        weight: &[f32],
        bias: Option<&[f32]>,
        act: Activation,
    ) -> Result<Self> {
        Self::with_isa(Isa::best(), spec, weight, bias, act)
    }

    /// As [`Conv2d::new`], with the micro-kernel family chosen by the caller
    /// (refused when this CPU lacks it).
    pub fn with_isa(
        isa: Isa,
        spec: ConvSpec,
        weight: &[f32],
        bias: Option<&[f32]>,
        act: Activation,
    ) -> Result<Self> {
        Self::with_algorithm(isa, ConvAlgorithm::Auto, spec, weight, bias, act)
    }

    /// As [`Conv2d::with_isa`], with the algorithm chosen by the caller
    /// (refused when it cannot run this shape).
    pub fn with_algorithm(
        isa: Isa,
        algorithm: ConvAlgorithm,
        spec: ConvSpec,
        weight: &[f32],
        bias: Option<&[f32]>,
        act: Activation,
    ) -> Result<Self> {
        spec.validate()?;
        check_weight("conv2d", weight.len(), spec.weight_len())?;
        let bias = check_bias("conv2d", bias, spec.c_out)?;
        let kernel = kernel_for("conv2d", isa)?;
        if !algorithm.applies(&spec) {
            return Err(invalid(
                "conv2d",
                format!("algorithm {algorithm:?} cannot run {spec:?}"),
            ));
        }
        let resolved = algorithm.resolve(&spec, isa);
        if !resolved.runs_on(isa) {
            return Err(invalid(
                "conv2d",
                format!(
                    "{resolved:?} (precision {}) needs the avx512 kernels and AVX512_BF16; \
                     this CPU or the chosen family ({isa}) lacks them",
                    crate::Precision::Bf16
                ),
            ));
        }
        let path = match resolved {
            ConvAlgorithm::PixelTiles => ConvPath::PixelTiles {
                tiles: PixelTiles::new(
                    weight,
                    spec.c_in,
                    spec.c_out,
                    spec.kh,
                    spec.kw,
                    spec.stride,
                ),
            },
            ConvAlgorithm::Direct => ConvPath::Direct {
                isa,
                weight: direct::pack_weights(weight, spec.c_out, spec.c_in, spec.kh * spec.kw),
            },
            algo if algo.is_winograd() => ConvPath::Winograd {
                isa,
                wino: Winograd::new(
                    kernel,
                    spec.c_in,
                    spec.c_out,
                    weight,
                    matches!(
                        algo,
                        ConvAlgorithm::Winograd
                            | ConvAlgorithm::Winograd6
                            | ConvAlgorithm::Winograd5
                            | ConvAlgorithm::WinogradBf16
                            | ConvAlgorithm::WinogradStride2
                            | ConvAlgorithm::Winograd5Stride2
                    ),
                    algo.is_bf16(),
                    match algo {
                        ConvAlgorithm::Winograd6 | ConvAlgorithm::Winograd6LowMemory => {
                            Some(Tile::F6)
                        }
                        ConvAlgorithm::Winograd5 | ConvAlgorithm::Winograd5LowMemory => {
                            Some(Tile::F5)
                        }
                        ConvAlgorithm::WinogradStride2
                        | ConvAlgorithm::WinogradStride2LowMemory => Some(Tile::S4),
                        ConvAlgorithm::Winograd5Stride2
                        | ConvAlgorithm::Winograd5Stride2LowMemory => Some(Tile::S5),
                        ConvAlgorithm::WinogradLowMemoryAutoTile => None,
                        _ => Some(Tile::F4),
                    },
                ),
            },
            ConvAlgorithm::Shifted
                if spec.stride == 1 && spec.c_out <= FOLD_MAX_CO && spec.kw > 1 =>
            {
                let (kh, kw, c_in) = (spec.kh, spec.kw, spec.c_in);
                ConvPath::Shifted {
                    packed: PackedA::pack_with_depth(
                        kernel,
                        spec.c_out * kw,
                        c_in * kh,
                        SHIFTED_KC,
                        |r, c| {
                            let (co, kx, ci, ky) = (r / kw, r % kw, c / kh, c % kh);
                            weight[((co * c_in + ci) * kh + ky) * kw + kx]
                        },
                    ),
                    fold_kx: true,
                }
            }
            ConvAlgorithm::Shifted => {
                let k = spec.c_in * spec.kh * spec.kw;
                ConvPath::Shifted {
                    packed: PackedA::pack_with_depth(kernel, spec.c_out, k, SHIFTED_KC, |r, c| {
                        weight[r * k + c]
                    }),
                    fold_kx: false,
                }
            }
            _ => {
                let k = spec.c_in * spec.kh * spec.kw;
                let p = spec.pad as isize;
                let taps = (0..spec.kh as isize)
                    .flat_map(|ky| (0..spec.kw as isize).map(move |kx| (ky - p, kx - p)))
                    .collect();
                ConvPath::Gemm {
                    packed: PackedA::pack(kernel, spec.c_out, k, |r, c| weight[r * k + c]),
                    taps,
                }
            }
        };
        Ok(Self {
            spec,
            act,
            bias,
            path,
        })
    }

    /// The layer's shape.
    pub fn spec(&self) -> ConvSpec {
        self.spec
    }
    /// The fused activation.
    pub fn activation(&self) -> Activation {
        self.act
    }
    /// The kernel family the weights are packed for.
    pub fn isa(&self) -> Isa {
        match &self.path {
            ConvPath::Gemm { packed, .. } | ConvPath::Shifted { packed, .. } => packed.kernel.isa,
            ConvPath::Direct { isa, .. } | ConvPath::Winograd { isa, .. } => *isa,
            ConvPath::PixelTiles { .. } => Isa::Avx512,
        }
    }

    /// The algorithm the layer runs with.
    pub fn algorithm(&self) -> ConvAlgorithm {
        match &self.path {
            ConvPath::Gemm { .. } => ConvAlgorithm::Gemm,
            ConvPath::Direct { .. } => ConvAlgorithm::Direct,
            ConvPath::Winograd { wino, .. } => {
                match (wino.is_bf16(), wino.is_packed(), wino.tile()) {
                    (false, true, Some(Tile::S4)) => ConvAlgorithm::WinogradStride2,
                    (false, false, Some(Tile::S4)) => ConvAlgorithm::WinogradStride2LowMemory,
                    (false, true, Some(Tile::S5)) => ConvAlgorithm::Winograd5Stride2,
                    (false, false, Some(Tile::S5)) => ConvAlgorithm::Winograd5Stride2LowMemory,
                    (false, true, Some(Tile::F5)) => ConvAlgorithm::Winograd5,
                    (false, false, Some(Tile::F5)) => ConvAlgorithm::Winograd5LowMemory,
                    (false, true, Some(Tile::F6)) => ConvAlgorithm::Winograd6,
                    (false, false, Some(Tile::F6)) => ConvAlgorithm::Winograd6LowMemory,
                    (false, false, None) => ConvAlgorithm::WinogradLowMemoryAutoTile,
                    (false, true, _) => ConvAlgorithm::Winograd,
                    (false, false, _) => ConvAlgorithm::WinogradLowMemory,
                    (true, true, _) => ConvAlgorithm::WinogradBf16,
                    (true, false, _) => ConvAlgorithm::WinogradBf16LowMemory,
                }
            }
            ConvPath::Shifted { .. } => ConvAlgorithm::Shifted,
            ConvPath::PixelTiles { .. } => ConvAlgorithm::PixelTiles,
        }
    }

    /// `act(conv(x) + b)`.
    pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
        self.run(x, 0, None)
    }

    /// `act(conv(x) + b) + residual`; `residual` has the output's shape.
    pub fn forward_add(&self, x: &Tensor, residual: &Tensor) -> Result<Tensor> {
        self.run(x, 0, Some(residual))
    }

    /// `next.forward(&self.forward_reflect(x, pad, None)?)`, the same values
    /// bit for bit (a Winograd `next`: within its rounding, see
    /// [`Conv2d::reflect_then_bands`]; its bands are 15 or 16 rows whatever
    /// the threads, so its bits do not depend on them either), without ever
    /// holding this layer's whole output: `next`'s
    /// output is made a band of rows at a time, each from the rows of this
    /// layer's output it reads (computed from the reflection-padded input rows
    /// they read), `next` run on them with its own zero padding (a Winograd
    /// `next` with none above a band that starts inside the image), and the
    /// rows that padding touches at a band's inner edges dropped. An encoder's first
    /// two layers run this way: the first one's output (64 channels at the
    /// input's full size) is the largest activation it makes.
    pub fn reflect_then(&self, x: &Tensor, pad: usize, next: &Conv2d) -> Result<Tensor> {
        let s = self.spec;
        let (_, w1) = s.out_hw(x.h() + 2 * pad, x.w() + 2 * pad)?;
        let row_bytes = s.c_out * w1 * std::mem::size_of::<f32>();
        // This layer's rows for one band of `next`'s: about `stride` each.
        let per_band = THEN_CONV_BAND_BYTES / rayon::current_num_threads().max(1);
        let band = match &next.path {
            // Four rows of its 4×4 tiles, or three of its 5×5 ones (a band
            // computes exactly its rows, see `reflect_then_bands`): measured
            // fastest (2-core Zen 4, `tune head` / `envhead`, five
            // interleaved rounds: 20.2–21.0 ms against 22.3–25.3 with the
            // bytes' 12-row bands for the IRN/MSN's 240×320 head, 5.5–6.6
            // against 5.9–8.6 with 20-row bands for the EnvMap's, whose
            // three bands left one thread idle a third of the time).
            ConvPath::Winograd { wino, .. } if wino.tile() == Some(Tile::S4) => THEN_CONV_S2_BAND,
            ConvPath::Winograd { wino, .. } if wino.tile() == Some(Tile::S5) => THEN_CONV_S5_BAND,
            _ => (per_band / row_bytes.max(1) / next.spec.stride.max(1)).max(THEN_CONV_MIN_BAND),
        };
        self.reflect_then_bands(x, pad, next, band)
    }

    /// As [`Conv2d::reflect_then`] with bands of `band` rows of `next`'s output
    /// (at least 1; any band size gives the same values, bit for bit unless
    /// `next` is a Winograd layer, whose tiles a band cuts differently: then
    /// within its rounding, and the same bits for the same band size whatever
    /// the threads), in one contiguous run of bands per thread of the pool,
    /// side by side. A Winograd `next` runs on exactly the rows its band's
    /// outputs read, with no zero padding above a band that starts inside
    /// the image; another one starts a row early on its stride grid and drops
    /// the output row that its padding touched.
    pub fn reflect_then_bands(
        &self,
        x: &Tensor,
        pad: usize,
        next: &Conv2d,
        band: usize,
    ) -> Result<Tensor> {
        let (s, ns) = (self.spec, next.spec);
        check_input("conv2d", x, s.c_in)?;
        let (h, w) = (x.h(), x.w());
        check_reflect(&s, pad, h, w)?;
        if ns.c_in != s.c_out {
            return Err(shape_err(
                "conv2d after conv2d",
                "input channels",
                s.c_out,
                ns.c_in,
            ));
        }
        if band == 0 {
            return Err(invalid("conv2d after conv2d", "a band of 0 rows"));
        }
        let (h1, w1) = s.out_hw(h + 2 * pad, w + 2 * pad)?;
        let (oh, ow) = ns.out_hw(h1, w1)?;
        let band = oh.div_ceil(oh.div_ceil(band.min(oh)));
        let mut out = Tensor::for_overwrite([x.n(), ns.c_out, oh, ow]);
        let per_out = ns.c_out * oh * ow;
        for b in 0..x.n() {
            let img = x.image(b);
            let run = |b0: usize, b1: usize, emit: &dyn Fn(BandOut)| -> Result<()> {
                for q0 in (b0..b1).map(|i| i * band) {
                    let q1 = (q0 + band).min(oh);
                    // This layer's rows `[g0, g1)` that rows `[q0, q1)` of
                    // `next` read, `g0` on `next`'s stride grid so that row
                    // `j` of `next` over them is row `k + j` of the whole.
                    // (Rows that read only `next`'s padding below the image
                    // take `g0` on the image's last grid row.)
                    // A Winograd `next` starts on the first row its first
                    // output reads, with only the padding above the image
                    // (`top`), so it computes exactly the band's rows:
                    // `g0 = q0·stride − pad`, any phase.
                    let exact = (q0 * ns.stride)
                        .checked_sub(ns.pad)
                        .map_or(Some(0), |g| (g < h1).then_some(g))
                        .filter(|_| matches!(next.path, ConvPath::Winograd { .. }));
                    let k = ((q0 * ns.stride).saturating_sub(ns.pad) / ns.stride)
                        .min((h1 - 1) / ns.stride);
                    let g0 = exact.unwrap_or(k * ns.stride);
                    // (At least one row: a band whose rows read only `next`'s
                    // zero padding still needs an input to run on.)
                    let g1 = ((q1 - 1) * ns.stride + ns.kh)
                        .saturating_sub(ns.pad)
                        .clamp(g0 + 1, h1);
                    // The reflection-padded input rows they read.
                    let r0 = (g0 * s.stride) as isize - pad as isize;
                    let r1 = ((g1 - 1) * s.stride + s.kh) as isize - pad as isize;
                    let (buf, hp, wp) =
                        row_window_copy(img, s.c_in, h, w, r0..r1, [pad, pad], Fill::Reflect, 0);
                    let xb = Tensor::new([1, s.c_in, hp, wp], buf)?;
                    let mid = self.forward(&xb)?;
                    drop(xb);
                    let (y, off) = match exact {
                        Some(_) => {
                            let top = ns.pad.saturating_sub(q0 * ns.stride);
                            (next.forward_top(&mid, top)?, 0)
                        }
                        None => (next.forward(&mid)?, q0 - k),
                    };
                    drop(mid);
                    emit(BandOut { q0, q1, off, y });
                }
                Ok(())
            };
            let dst = &mut out.data_mut()[b * per_out..(b + 1) * per_out];
            in_bands(oh, ow, band, dst, run)?;
        }
        Ok(out)
    }

    /// The Winograd path's forward pass with `top ≤ pad` zero rows above
    /// the input instead of the layer's `pad` (the other sides keep it): the
    /// rows of a band that starts on the row its first output reads.
    fn forward_top(&self, x: &Tensor, top: usize) -> Result<Tensor> {
        let s = self.spec;
        let ConvPath::Winograd { wino, .. } = &self.path else {
            return Err(invalid(
                "conv2d band",
                "a top padding on a non-Winograd layer",
            ));
        };
        if top > s.pad {
            return Err(invalid(
                "conv2d band",
                "a top padding larger than the layer's",
            ));
        }
        check_input("conv2d", x, s.c_in)?;
        let (_, ow) = s.out_hw(x.h(), x.w())?;
        let oh = (x.h() + top + s.pad)
            .checked_sub(s.kh)
            .map(|v| v / s.stride + 1)
            .ok_or_else(|| invalid("conv2d band", "fewer rows than the kernel"))?;
        let mut out = Tensor::for_overwrite([x.n(), s.c_out, oh, ow]);
        let per_out = s.c_out * oh * ow;
        let epi = Epilogue {
            bias: self.bias.as_deref(),
            act: self.act,
            residual: None,
        };
        for b in 0..x.n() {
            let c = &mut out.data_mut()[b * per_out..(b + 1) * per_out];
            wino.forward_image_top(x.image(b), x.h(), x.w(), top, s.pad, Fill::Zero, &epi, c);
        }
        Ok(out)
    }

    /// `act(conv(reflect_pad(x, pad)) + b) [+ residual]`: the convolution of
    /// the input extended by PyTorch `ReflectionPad2d(pad)`, which needs `pad`
    /// smaller than the input's height and width. The layer itself must have
    /// no zero padding. The Winograd path reads the reflection in its gather;
    /// the other paths pad a copy first.
    pub fn forward_reflect(
        &self,
        x: &Tensor,
        pad: usize,
        residual: Option<&Tensor>,
    ) -> Result<Tensor> {
        check_reflect(&self.spec, pad, x.h(), x.w())?;
        self.run(x, pad, residual)
    }

    fn run(&self, x: &Tensor, reflect: usize, residual: Option<&Tensor>) -> Result<Tensor> {
        if reflect > 0
            && !matches!(
                self.path,
                ConvPath::Winograd { .. }
                    | ConvPath::Shifted { .. }
                    | ConvPath::Direct { .. }
                    | ConvPath::PixelTiles { .. }
            )
        {
            let padded = reflect_pad(x, [reflect; 4])?;
            return self.run(&padded, 0, residual);
        }
        let s = self.spec;
        check_input("conv2d", x, s.c_in)?;
        let (oh, ow) = s.out_hw(x.h() + 2 * reflect, x.w() + 2 * reflect)?;
        let shape = [x.n(), s.c_out, oh, ow];
        if let Some(r) = residual {
            if r.shape() != shape {
                return Err(shape_err(
                    "conv2d",
                    "residual shape",
                    format!("{shape:?}"),
                    format!("{:?}", r.shape()),
                ));
            }
        }
        let mut out = Tensor::for_overwrite(shape);
        let per_out = s.c_out * oh * ow;
        // The padding the paths that pad themselves apply.
        let (pad, fill) = if reflect > 0 {
            (reflect, Fill::Reflect)
        } else {
            (s.pad, Fill::Zero)
        };
        for b in 0..x.n() {
            let img = x.image(b);
            let c = &mut out.data_mut()[b * per_out..(b + 1) * per_out];
            let epi = Epilogue {
                bias: self.bias.as_deref(),
                act: self.act,
                residual: residual.map(|r| r.image(b)),
            };
            match &self.path {
                ConvPath::PixelTiles { tiles } => {
                    tiles.forward_image(img, x.h(), x.w(), pad, fill, &epi, c);
                }
                ConvPath::Direct { isa, weight } => {
                    let p = DirectProblem {
                        x: img,
                        c_in: s.c_in,
                        h: x.h(),
                        w: x.w(),
                        kh: s.kh,
                        kw: s.kw,
                        pad,
                        fill,
                        oh,
                        ow,
                    };
                    conv_direct(
                        *isa,
                        &p,
                        s.c_out,
                        weight,
                        epi.bias,
                        epi.act,
                        epi.residual,
                        c,
                    );
                }
                ConvPath::Winograd { wino, .. } => {
                    wino.forward_image(img, x.h(), x.w(), pad, fill, &epi, c);
                }
                ConvPath::Shifted { packed, fold_kx } => {
                    let slack = packed.kernel.nr + s.kw + s.stride;
                    let map = OutMap {
                        base: 0,
                        cs: oh * ow,
                        rs: ow,
                        xs: 1,
                        oh,
                        ow,
                    };
                    if s.stride > 1 {
                        let st = s.stride;
                        let (src, hq, wq) =
                            phase_copy(img, s.c_in, x.h(), x.w(), pad, fill, st, slack);
                        // Tap (ky, kx) reads phase (ky % s, kx % s) at (oy + ky / s, ox + kx / s).
                        let offs: Vec<usize> = (0..s.c_in)
                            .flat_map(|ci| {
                                (0..s.kh).flat_map(move |ky| {
                                    (0..s.kw).map(move |kx| {
                                        let ph = (ky % st) * st + kx % st;
                                        (ph * s.c_in + ci) * hq * wq + (ky / st) * wq + kx / st
                                    })
                                })
                            })
                            .collect();
                        let b = ShiftedB {
                            src: &src,
                            offs: &offs,
                            wp: wq,
                        };
                        shifted_gemm(packed, &b, &map, c, &epi);
                        crate::pool::give(src);
                        continue;
                    }
                    let (src, hp, wp) =
                        padded_copy(img, s.c_in, x.h(), x.w(), [pad; 4], fill, slack);
                    if *fold_kx {
                        self.folded(packed, &src, hp, wp, oh, ow, &epi, c);
                    } else {
                        let offs: Vec<usize> = (0..s.c_in)
                            .flat_map(|ci| {
                                (0..s.kh).flat_map(move |ky| {
                                    (0..s.kw).map(move |kx| ci * hp * wp + ky * wp + kx)
                                })
                            })
                            .collect();
                        let b = ShiftedB {
                            src: &src,
                            offs: &offs,
                            wp,
                        };
                        shifted_gemm(packed, &b, &map, c, &epi);
                    }
                    crate::pool::give(src);
                }
                ConvPath::Gemm { packed, taps } => {
                    if s.kh == 1 && s.kw == 1 && s.stride == 1 && s.pad == 0 {
                        let src = DenseB {
                            data: img,
                            n: oh * ow,
                        };
                        gemm(packed, &src, oh * ow, c, &epi);
                    } else {
                        let src = Gather {
                            x: img,
                            h: x.h(),
                            w: x.w(),
                            stride: s.stride,
                            taps,
                            ow,
                        };
                        gemm(packed, &src, oh * ow, c, &epi);
                    }
                }
            }
        }
        Ok(out)
    }
}

impl Conv2d {
    /// The folded shifted product: `C'[(co, kx)][n] = Σ_(ci, ky) w · src[ci][n + ky·wp]`
    /// on the padded-width grid, then `out[co][y][x] = epilogue(Σ_kx C'[(co, kx)][y·wp + x + kx])`.
    #[allow(clippy::too_many_arguments)]
    fn folded(
        &self,
        packed: &PackedA,
        src: &[f32],
        hp: usize,
        wp: usize,
        oh: usize,
        ow: usize,
        epi: &Epilogue<'_>,
        out: &mut [f32],
    ) {
        let s = self.spec;
        let offs: Vec<usize> = (0..s.c_in)
            .flat_map(|ci| (0..s.kh).map(move |ky| ci * hp * wp + ky * wp))
            .collect();
        let b = ShiftedB {
            src,
            offs: &offs,
            wp,
        };
        let wide = oh * wp;
        let mut partial = crate::pool::take(s.c_out * s.kw * wide);
        let map = OutMap {
            base: 0,
            cs: wide,
            rs: wp,
            xs: 1,
            oh,
            ow: wp,
        };
        let none = Epilogue {
            bias: None,
            act: Activation::None,
            residual: None,
        };
        shifted_gemm(packed, &b, &map, &mut partial, &none);
        let part = &partial;
        let kw = s.kw;
        out.par_chunks_mut(ow).enumerate().for_each(|(row, orow)| {
            let (co, y) = (row / oh, row % oh);
            let bias = epi.bias.map_or(0.0, |b| b[co]);
            let base = co * kw * wide + y * wp;
            orow.fill(bias);
            for kx in 0..kw {
                let p = &part[base + kx * wide + kx..][..ow];
                orow.iter_mut().zip(p).for_each(|(o, &v)| *o += v);
            }
            epi.act.apply(orow);
            if let Some(r) = epi.residual {
                orow.iter_mut()
                    .zip(&r[row * ow..(row + 1) * ow])
                    .for_each(|(o, &v)| *o += v);
            }
        });
        crate::pool::give(partial);
    }
}

/// One output phase `(ry, rx)` of a transposed convolution: the outputs
/// `(s·m + ry, s·n + rx)` are an ordinary stride-1 convolution of the input
/// with the taps whose kernel index lines up with that phase.
#[derive(Clone)]
struct Phase {
    ry: usize,
    rx: usize,
    /// `(dy, dx)` input offsets, one per tap, matching the packed columns.
    taps: Vec<(isize, isize)>,
    /// `None` when no tap reaches this phase (kernel smaller than the stride).
    packed: Option<PackedA>,
}

/// A transposed convolution run as sub-pixel convolutions: one packed GEMM per
/// output phase over a gather of the input (no zero insertion, no col2im), with
/// bias and activation fused, interleaved into the output.
#[derive(Clone)]
pub struct ConvTranspose2d {
    spec: ConvTransposeSpec,
    act: Activation,
    bias: Option<Vec<f32>>,
    isa: Isa,
    phases: Vec<Phase>,
}

impl std::fmt::Debug for ConvTranspose2d {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ConvTranspose2d")
            .field("spec", &self.spec)
            .field("act", &self.act)
            .field("bias", &self.bias.is_some())
            .field("isa", &self.isa)
            .finish()
    }
}

/// Kernel indices reaching output phase `r` along one axis, with their input offsets:
/// `o = i·s − p + k` and `o = s·m + r` give `i = m + (r + p − k)/s` when `s | (r + p − k)`.
fn phase_taps(r: usize, k: usize, s: usize, p: usize) -> Vec<(usize, isize)> {
    (0..k)
        .filter_map(|kk| {
            let num = r as isize + p as isize - kk as isize;
            (num.rem_euclid(s as isize) == 0).then(|| (kk, num.div_euclid(s as isize)))
        })
        .collect()
}

impl ConvTranspose2d {
    /// Packs `weight` (`[c_in, c_out, kh, kw]`, PyTorch order) for the fastest kernels of this CPU.
    pub fn new(
        spec: ConvTransposeSpec,
        weight: &[f32],
        bias: Option<&[f32]>,
        act: Activation,
    ) -> Result<Self> {
        Self::with_isa(Isa::best(), spec, weight, bias, act)
    }

    /// As [`ConvTranspose2d::new`] with the kernel family chosen by the caller.
    pub fn with_isa(
        isa: Isa,
        spec: ConvTransposeSpec,
        weight: &[f32],
        bias: Option<&[f32]>,
        act: Activation,
    ) -> Result<Self> {
        spec.validate()?;
        check_weight("conv_transpose2d", weight.len(), spec.weight_len())?;
        let bias = check_bias("conv_transpose2d", bias, spec.c_out)?;
        let kernel = kernel_for("conv_transpose2d", isa)?;
        let s = spec.stride;
        let mut phases = Vec::with_capacity(s * s);
        for ry in 0..s {
            let ty = phase_taps(ry, spec.kh, s, spec.pad);
            for rx in 0..s {
                let tx = phase_taps(rx, spec.kw, s, spec.pad);
                let kidx: Vec<(usize, usize)> = ty
                    .iter()
                    .flat_map(|&(ky, _)| tx.iter().map(move |&(kx, _)| (ky, kx)))
                    .collect();
                let taps = ty
                    .iter()
                    .flat_map(|&(_, dy)| tx.iter().map(move |&(_, dx)| (dy, dx)))
                    .collect();
                let nt = kidx.len();
                let packed = (nt > 0).then(|| {
                    PackedA::pack_with_depth(
                        kernel,
                        spec.c_out,
                        spec.c_in * nt,
                        SHIFTED_KC,
                        |co, k| {
                            let (ci, (ky, kx)) = (k / nt, kidx[k % nt]);
                            weight[((ci * spec.c_out + co) * spec.kh + ky) * spec.kw + kx]
                        },
                    )
                });
                phases.push(Phase {
                    ry,
                    rx,
                    taps,
                    packed,
                });
            }
        }
        Ok(Self {
            spec,
            act,
            bias,
            isa,
            phases,
        })
    }

    /// The layer's shape.
    pub fn spec(&self) -> ConvTransposeSpec {
        self.spec
    }
    /// The kernel family the weights are packed for.
    pub fn isa(&self) -> Isa {
        self.isa
    }

    /// `act(conv_transpose(x) + b)`.
    pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
        check_input("conv_transpose2d", x, self.spec.c_in)?;
        let (oh, _) = self.spec.out_hw(x.h(), x.w())?;
        self.forward_rows(x, 0..oh)
    }

    /// Output rows `rows` of [`ConvTranspose2d::forward`]: `[N, c_out,
    /// rows.len(), ow]`, the same values bit for bit, computed from the input
    /// rows they need and no others (a decoder can run its full-size layers
    /// a band of rows at a time).
    pub fn forward_rows(&self, x: &Tensor, rows: std::ops::Range<usize>) -> Result<Tensor> {
        let sp = self.spec;
        check_input("conv_transpose2d", x, sp.c_in)?;
        let (oh, ow) = sp.out_hw(x.h(), x.w())?;
        if rows.start > rows.end || rows.end > oh {
            return Err(shape_err(
                "conv_transpose2d",
                "output rows",
                format!("a range within 0..{oh}"),
                format!("{rows:?}"),
            ));
        }
        let nr = rows.len();
        let mut out = Tensor::for_overwrite([x.n(), sp.c_out, nr, ow]);
        let per_out = sp.c_out * nr * ow;
        for b in 0..x.n() {
            let dst = &mut out.data_mut()[b * per_out..(b + 1) * per_out];
            let layout = RowsLayout {
                cs: nr * ow,
                rs: ow,
                col0: 0,
            };
            self.rows_into(x.image(b), x.h(), x.w(), rows.clone(), dst, layout);
        }
        Ok(out)
    }

    /// `conv.forward_reflect(&self.forward(x)?, pad, None)`, the same values
    /// bit for bit, without ever holding this layer's whole output: `conv`'s
    /// output is made a band of rows at a time, from the rows of this layer's
    /// output that the band reads (kept from one band to the next, so no row
    /// is computed twice) and their reflection. A decoder's last upsampling
    /// and output convolution run this way: their full-size activation (64
    /// channels at the photo's size) is the largest a network holds.
    pub fn then_reflect_conv(&self, x: &Tensor, conv: &Conv2d, pad: usize) -> Result<Tensor> {
        let c = self.spec.c_out;
        let (_, ow) = self.spec.out_hw(x.h().max(1), x.w().max(1))?;
        let row_bytes = c * (ow + 2 * pad) * std::mem::size_of::<f32>();
        // The bands' buffers together take about `THEN_CONV_BAND_BYTES`:
        // one band per thread at a time (see `then_reflect_conv_bands`).
        let per_band = THEN_CONV_BAND_BYTES / rayon::current_num_threads().max(1);
        let band = (per_band / row_bytes.max(1)).max(THEN_CONV_MIN_BAND);
        self.then_reflect_conv_bands(x, conv, pad, band)
    }

    /// As [`ConvTranspose2d::then_reflect_conv`] with bands of `band` rows of
    /// `conv`'s output (at least 1; any band size gives the same values). The
    /// bands are split into one contiguous run per thread of the pool, the
    /// runs side by side, each with its own band buffer.
    pub fn then_reflect_conv_bands(
        &self,
        x: &Tensor,
        conv: &Conv2d,
        pad: usize,
        band: usize,
    ) -> Result<Tensor> {
        let sp = self.spec;
        let cs = conv.spec();
        check_input("conv_transpose2d", x, sp.c_in)?;
        let (h, w) = sp.out_hw(x.h(), x.w())?;
        if cs.c_in != sp.c_out {
            return Err(shape_err(
                "conv2d after conv_transpose2d",
                "input channels",
                sp.c_out,
                cs.c_in,
            ));
        }
        check_reflect(&cs, pad, h, w)?;
        if band == 0 {
            return Err(invalid("conv2d after conv_transpose2d", "a band of 0 rows"));
        }
        let (hp, wp) = (h + 2 * pad, w + 2 * pad);
        let (oh, ow) = cs.out_hw(hp, wp)?;
        let (c, st) = (sp.c_out, cs.stride);
        let mut out = Tensor::for_overwrite([x.n(), cs.c_out, oh, ow]);
        let per_out = cs.c_out * oh * ow;
        // Bands of even height; each reads `span` padded rows.
        let band = oh.div_ceil(oh.div_ceil(band.min(oh)));
        let span = (band - 1) * st + cs.kh;
        let plane = span * wp;
        let at_col = RowsLayout {
            cs: plane,
            rs: wp,
            col0: pad,
        };
        // Padded row `p` is this layer's output row `src(p)`.
        let src = |p: usize| reflect_index(p as isize - pad as isize, h);
        let reflect_cols = |pt: &mut Tensor, r0: usize, r1: usize| {
            for ch in pt.data_mut().chunks_exact_mut(plane) {
                for row in ch[r0 * wp..r1 * wp].chunks_exact_mut(wp) {
                    for j in (0..pad).chain(pad + w..wp) {
                        row[j] = row[pad + reflect_index(j as isize - pad as isize, w)];
                    }
                }
            }
        };
        // Bands `[b0, b1)` of image `img`, one after another: `conv`'s
        // output for each band, with its first row.
        let run_bands = |img: &[f32], b0: usize, b1: usize, emit: &dyn Fn(BandOut)| -> Result<()> {
            // The band's reflection-padded input: padded rows `[p0, p0 +
            // span)` (rows past the padded image, read only by the rows past
            // the output that the last band computes and drops, are zeros).
            let mut pt = Tensor::for_overwrite([1, c, span, wp]);
            // Padded rows `[k0, k1)` held at the top of `pt` from the last band.
            let mut held: Option<(usize, usize)> = None;
            for q0 in (b0..b1).map(|i| i * band) {
                let p0 = q0 * st;
                let end = (p0 + span).min(hp);
                // Rows `[p0, filled)` are in place once the shared ones move up.
                let mut filled = p0;
                if let Some((k0, k1)) = held {
                    if k0 <= p0 && p0 < k1 {
                        for ch in pt.data_mut().chunks_exact_mut(plane) {
                            ch.copy_within((p0 - k0) * wp..(k1 - k0) * wp, 0);
                        }
                        filled = k1;
                    }
                    debug_assert!(filled <= end);
                }
                // The rows inside the image, computed in place.
                let (d0, d1) = (filled.max(pad), end.min(pad + h));
                if d1 > d0 {
                    let dst = &mut pt.data_mut()[(d0 - p0) * wp..];
                    self.rows_into(img, x.h(), x.w(), d0 - pad..d1 - pad, dst, at_col);
                    reflect_cols(&mut pt, d0 - p0, d1 - p0);
                }
                // The reflected rows: copies of rows in place, or computed.
                for p in (filled..end).filter(|&p| p < pad || p >= pad + h) {
                    let sp_row = pad + src(p);
                    let ready = sp_row >= p0
                        && sp_row < end
                        && (sp_row < filled || (d0..d1).contains(&sp_row));
                    if ready {
                        for ch in pt.data_mut().chunks_exact_mut(plane) {
                            ch.copy_within(
                                (sp_row - p0) * wp..(sp_row - p0 + 1) * wp,
                                (p - p0) * wp,
                            );
                        }
                    } else {
                        let dst = &mut pt.data_mut()[(p - p0) * wp..];
                        self.rows_into(img, x.h(), x.w(), src(p)..src(p) + 1, dst, at_col);
                        reflect_cols(&mut pt, p - p0, p - p0 + 1);
                    }
                }
                for ch in pt.data_mut().chunks_exact_mut(plane) {
                    ch[(end - p0) * wp..].fill(0.0);
                }
                held = Some((p0, end));
                emit(BandOut {
                    q0,
                    q1: (q0 + band).min(oh),
                    off: 0,
                    y: conv.forward(&pt)?,
                });
            }
            Ok(())
        };
        for b in 0..x.n() {
            let img = x.image(b);
            let dst = &mut out.data_mut()[b * per_out..(b + 1) * per_out];
            in_bands(oh, ow, band, dst, |b0, b1, emit| {
                run_bands(img, b0, b1, emit)
            })?;
        }
        Ok(out)
    }

    /// Output rows `rows` (within the output height) of one image `img`
    /// (`c_in × h × w`), written to `dst`: output `(co, o, j)` at
    /// `dst[co·cs + (o − rows.start)·rs + col0 + j]`.
    ///
    /// Each row phase `ry` computes its grid rows `m` with `s·m + ry` in
    /// `rows` from a zero-extended copy of the input rows they read, and
    /// writes them interleaved with its column phases. A row's arithmetic
    /// (the taps and their order, the depth blocks) does not depend on the
    /// window, so any window gives the full output's values.
    pub(crate) fn rows_into(
        &self,
        img: &[f32],
        h: usize,
        w: usize,
        rows: std::ops::Range<usize>,
        dst: &mut [f32],
        layout: RowsLayout,
    ) {
        let sp = self.spec;
        let (oh, ow) = sp
            .out_hw(h, w)
            .expect("rows_into: input checked by the caller");
        debug_assert!(rows.end <= oh);
        if rows.is_empty() {
            return;
        }
        let s = sp.stride;
        // Grid rows `[m0, m1)` of row phase `ry` inside the window.
        let grid = |ry: usize| {
            let m0 = rows.start.saturating_sub(ry).div_ceil(s);
            let m1 = rows.end.saturating_sub(ry).div_ceil(s);
            (m0, m1.max(m0))
        };
        // The input rows (zero outside the image) the window reads, and the
        // column pads every phase's taps reach.
        let (mut i_lo, mut i_hi) = (isize::MAX, isize::MIN);
        let (mut pl, mut pr) = (0usize, 0usize);
        for ph in &self.phases {
            let (m0, m1) = grid(ph.ry);
            let mw = ow.saturating_sub(ph.rx).div_ceil(s);
            for &(dy, dx) in &ph.taps {
                if m1 > m0 {
                    i_lo = i_lo.min(m0 as isize + dy);
                    i_hi = i_hi.max(m1 as isize + dy);
                }
                pl = pl.max((-dx).max(0) as usize);
                pr = pr.max((mw as isize + dx - w as isize).max(0) as usize);
            }
        }
        let epi = Epilogue {
            bias: self.bias.as_deref(),
            act: self.act,
            residual: None,
        };
        if i_lo > i_hi {
            // No tap reaches any row of the window: every value is the bias.
            (i_lo, i_hi) = (0, 0);
        }
        // One padded row of slack covers every tap's column offset.
        let slack = MAX_NR + w + pl + pr;
        let (src, hp, wp) =
            row_window_copy(img, sp.c_in, h, w, i_lo..i_hi, [pl, pr], Fill::Zero, slack);
        // Per row phase, its column phases side by side, written as
        // whole interleaved rows.
        for row in self.phases.chunks(s) {
            let ry = row[0].ry;
            let (m0, m1) = grid(ry);
            if m1 == m0 {
                continue;
            }
            let mh = m1 - m0;
            let offs: Vec<Option<Vec<usize>>> = row
                .iter()
                .map(|ph| {
                    let nt = ph.taps.len();
                    ph.packed.as_ref().map(|_| {
                        (0..sp.c_in * nt)
                            .map(|k| {
                                let (ci, (dy, dx)) = (k / nt, ph.taps[k % nt]);
                                let r = (m0 as isize + dy - i_lo) as usize;
                                let c = (dx + pl as isize) as usize;
                                ci * hp * wp + r * wp + c
                            })
                            .collect()
                    })
                })
                .collect();
            let parts: Vec<Option<PhasePart<'_>>> = row
                .iter()
                .zip(&offs)
                .map(|(ph, o)| {
                    Some(PhasePart {
                        a: ph.packed.as_ref()?,
                        offs: o.as_deref()?,
                    })
                })
                .collect();
            let map = RowPhaseMap {
                base: (s * m0 + ry - rows.start) * layout.rs + layout.col0,
                cs: layout.cs,
                rs: s * layout.rs,
                oh: mh,
                ow,
                s,
            };
            if parts.iter().any(Option::is_some) {
                shifted_gemm_interleaved(&parts, &src, wp, &map, dst, &epi);
            } else {
                // No tap reaches this row phase: every value is the bias.
                for co in 0..sp.c_out {
                    let v = self
                        .act
                        .apply_one(self.bias.as_ref().map_or(0.0, |bb| bb[co]));
                    for m in 0..mh {
                        let i0 = map.base + co * map.cs + m * map.rs;
                        dst[i0..i0 + ow].fill(v);
                    }
                }
            }
        }
        crate::pool::give(src);
    }
}

/// What a reflection-padded convolution needs: a layer without zero padding
/// of its own, and a pad smaller than its `h × w` input (PyTorch's
/// `ReflectionPad2d`).
fn check_reflect(spec: &ConvSpec, pad: usize, h: usize, w: usize) -> Result<()> {
    if spec.pad != 0 {
        return Err(invalid(
            "conv2d",
            format!(
                "forward_reflect needs a layer without zero padding, this one has pad {}",
                spec.pad
            ),
        ));
    }
    if pad >= h || pad >= w {
        return Err(shape_err(
            "conv2d",
            "reflection pad",
            format!("smaller than the input {h}x{w}"),
            pad,
        ));
    }
    Ok(())
}

/// Output rows `[q0, q1)` of one band: rows `[off, off + q1 − q0)` of `y`
/// (`[1, c, rows, ow]`).
struct BandOut {
    q0: usize,
    q1: usize,
    off: usize,
    y: Tensor,
}

/// The output image that [`in_bands`]' bands write, each its own rows.
struct BandDst(*mut f32);
// SAFETY: the bands write disjoint rows of it (see `in_bands`).
unsafe impl Sync for BandDst {}

impl BandDst {
    /// The address of float `i` (a method, so closures capture the whole
    /// `Sync` wrapper, not its raw pointer field).
    fn at(&self, i: usize) -> *mut f32 {
        self.0.wrapping_add(i)
    }
}

/// Fills one output image `dst` (`c` planes of `oh × ow`) band by band:
/// `run(b0, b1, emit)` computes bands `b0..b1` (band `i`: rows `[i·band,
/// (i + 1)·band)`) one after another and hands each to `emit`, which copies
/// it into `dst` at once (so no band outlives its copy), without a lock: the
/// bands' rows are disjoint (with a lock the two threads' copies waited for
/// each other: `tune envhead` 0.929× and 0.941× the locked copy's time over
/// 16 and 12 alternating rounds, `tune head` 0.961×). The bands are split
/// into one contiguous run per thread of the pool, the runs side by side: the
/// kernels inside a band are small, and a band's steps would otherwise wait
/// for each other on every thread (each run recomputes what it shares with
/// the run before it).
fn in_bands(
    oh: usize,
    ow: usize,
    band: usize,
    dst: &mut [f32],
    run: impl Fn(usize, usize, &dyn Fn(BandOut)) -> Result<()> + Sync,
) -> Result<()> {
    let n_bands = oh.div_ceil(band.max(1));
    let runs = rayon::current_num_threads().clamp(1, n_bands.max(1));
    let plane = oh * ow;
    let (len, dst) = (dst.len(), BandDst(dst.as_mut_ptr()));
    let emit = |BandOut { q0, q1, off, y }: BandOut| {
        let (rows, yplane) = ((q1 - q0) * ow, y.h() * y.w());
        assert!(y.w() == ow && off + q1 - q0 <= y.h() && q0 <= q1 && q1 <= oh);
        for (co, yc) in y.data().chunks_exact(yplane).enumerate() {
            let at = co * plane + q0 * ow;
            assert!(at + rows <= len, "band rows past the output");
            let src = &yc[off * ow..][..rows];
            // SAFETY: `[at, at + rows)` lies in `dst` (checked) and holds
            // rows `[q0, q1)` of plane `co`, which only this band writes:
            // every band index is run once, and bands do not overlap.
            unsafe { std::ptr::copy_nonoverlapping(src.as_ptr(), dst.at(at), rows) };
        }
    };
    if runs == 1 {
        return run(0, n_bands, &emit);
    }
    (0..runs)
        .into_par_iter()
        .try_for_each(|r| run(r * n_bands / runs, (r + 1) * n_bands / runs, &emit))
}

/// Bytes of the bands of a decoder's reflection-padded full-size activation
/// that [`ConvTranspose2d::then_reflect_conv`] holds at a time, one band per
/// thread (the only buffers it holds besides its input and output).
const THEN_CONV_BAND_BYTES: usize = 4 << 20;
/// Fewest output rows a band of [`ConvTranspose2d::then_reflect_conv`] has.
const THEN_CONV_MIN_BAND: usize = 8;
/// [`ConvAlgorithm::AutoLowMemory`] keeps a stride-2 Winograd layer's
/// transformed weights packed up to this size: the encoders' 64→128 down
/// conv with 4×4 tiles (2.7 MB; in bands, 2-core Zen 4, `tune head`:
/// 21.9–23.9 ms packed against 24.6–25.1 made per band). With 5×5 tiles
/// (4.0 MB) they are made per band: `tune envhead`, 8 alternating rounds,
/// 0.932× and 0.960× the packed ones' time, `tune head` 0.943× (stop 64).
/// Larger ones are made per pass.
const WINO_S2_PACKED_MAX_BYTES: usize = 3 << 20;

/// Rows of `next`'s output per band in [`Conv2d::reflect_then`] when `next`
/// is a stride-2 Winograd layer with 4×4 tiles (four rows of its tiles).
const THEN_CONV_S2_BAND: usize = 16;

/// As [`THEN_CONV_S2_BAND`] for 5×5 tiles: three rows of them, which on the
/// EnvMap's 60-row and the IRN/MSN's 120-row `down.0` outputs are four and
/// eight bands of one and two whole panels (16 and 32 tiles a row). The
/// encoders' `down.0` (64 → 128) runs so since a band computes exactly its
/// rows (stop 64; before, each computed one more, four rows of 5×5 tiles,
/// and 4×4 tiles were faster there): `tune envhead`, 10 alternating rounds,
/// 0.911× the 4×4 tiles' time, `tune head` 0.916×; `down.1` (128 → 256)
/// runs alone, where 5×5 tiles fill whole panels on the EnvMap's 30×40 and
/// 60×80 outputs (one thread, `down.1` 4.96–5.09 ms against 5.94–6.04).
const THEN_CONV_S5_BAND: usize = 15;

/// Where [`ConvTranspose2d::rows_into`] writes: channel stride `cs`, row
/// stride `rs`, first column `col0`.
#[derive(Clone, Copy, Debug)]
pub(crate) struct RowsLayout {
    pub(crate) cs: usize,
    pub(crate) rs: usize,
    pub(crate) col0: usize,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Rng, Tolerance};

    /// `Conv2d::forward_top` (the Winograd path with `top ≤ pad` zero rows
    /// above the input) against the reference convolution of the input
    /// padded explicitly that way, for every Winograd tile the CPU runs,
    /// every `top`, and inputs from one row past the kernel up.
    #[test]
    fn forward_top_matches_the_reference_with_fewer_rows_above() {
        let mut rng = Rng::new(64);
        let algos = [
            ConvAlgorithm::Winograd,
            ConvAlgorithm::Winograd5,
            ConvAlgorithm::Winograd6,
            ConvAlgorithm::WinogradLowMemoryAutoTile,
            ConvAlgorithm::WinogradStride2,
            ConvAlgorithm::Winograd5Stride2LowMemory,
        ];
        let mut ran = 0;
        for isa in Isa::ALL.into_iter().filter(|i| i.is_available()) {
            for algo in algos.into_iter().filter(|a| a.runs_on(isa)) {
                let stride = if format!("{algo:?}").contains("Stride2") {
                    2
                } else {
                    1
                };
                for pad in 1..=2 {
                    let s = ConvSpec::square(16, 17, 3, stride, pad);
                    let wt = rng.normal_vec(s.weight_len(), 0.2);
                    let bias = rng.normal_vec(s.c_out, 0.1);
                    let conv =
                        Conv2d::with_algorithm(isa, algo, s, &wt, Some(&bias), Activation::Relu)
                            .unwrap();
                    for _ in 0..3 {
                        let (h, w) = (rng.range(1, 23), rng.range(1, 23));
                        let x = rng.tensor([1, s.c_in, h, w]);
                        for top in 0..=pad {
                            // The input with `top` zero rows above and `pad`
                            // below and on either side.
                            let (hp, wp) = (h + top + pad, w + 2 * pad);
                            let mut padded = vec![0.0; s.c_in * hp * wp];
                            for c in 0..s.c_in {
                                for y in 0..h {
                                    let dst = &mut padded[(c * hp + y + top) * wp + pad..][..w];
                                    dst.copy_from_slice(&x.image(0)[(c * h + y) * w..][..w]);
                                }
                            }
                            let xp = Tensor::new([1, s.c_in, hp, wp], padded).unwrap();
                            let what = format!("{isa} {algo:?} {h}x{w} pad {pad} top {top}");
                            let got = conv.forward_top(&x, top);
                            if hp < 3 || wp < 3 {
                                assert!(got.is_err(), "{what}: no output rows");
                                continue;
                            }
                            let s0 = ConvSpec { pad: 0, ..s };
                            let want = crate::reference::conv2d(&xp, &wt, Some(&bias), s0).unwrap();
                            let want = crate::reference::activate(&want, Activation::Relu);
                            let got = got.unwrap();
                            assert_eq!(got.shape(), want.shape(), "{what}");
                            if let Err(e) = Tolerance::WINOGRAD_F32.check(got.data(), want.data()) {
                                panic!("{what}: {e}");
                            }
                            ran += 1;
                        }
                    }
                }
            }
        }
        assert!(ran > 0, "no Winograd layer runs on this CPU");
        // Refused: a larger top than the layer's padding, a non-Winograd layer.
        let s = ConvSpec::square(16, 16, 3, 1, 1);
        let wt = rng.normal_vec(s.weight_len(), 0.2);
        let x = rng.tensor([1, 16, 6, 6]);
        let gemm = Conv2d::with_algorithm(
            Isa::best(),
            ConvAlgorithm::Gemm,
            s,
            &wt,
            None,
            Activation::None,
        )
        .unwrap();
        assert!(gemm.forward_top(&x, 0).is_err());
        if let Ok(w) = Conv2d::with_algorithm(
            Isa::best(),
            ConvAlgorithm::Winograd,
            s,
            &wt,
            None,
            Activation::None,
        ) {
            assert!(w.forward_top(&x, 2).is_err());
        }
    }
}
