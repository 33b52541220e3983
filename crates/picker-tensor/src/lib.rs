//! f32 NCHW tensors and the CPU kernels of Material Picker's networks.
//!
//! Every op exists twice: a fast path (packed GEMM with per-ISA micro-kernels,
//! implicit im2col, rayon) and a plain version in [`reference`](mod@reference) that the tests
//! hold the fast path to. The micro-kernel family is chosen once at runtime
//! ([`Isa::best`]); layers can be built for a given family ([`Conv2d::with_isa`]).
//!
//! | op | fast path | reference |
//! |---|---|---|
//! | conv2d 3×3 stride 1 | Winograd F(4×4, 3×3) over cache-sized tile blocks, reflection padding in the gather, fused bias/act/residual | [`reference::conv2d`] |
//! | conv2d, other shapes | shifted GEMM: B rows read in place from a padded copy (strides through phase planes; few outputs fold `kx` into the rows); 1×1 as plain packed GEMM | [`reference::conv2d`] |
//! | conv-transpose2d | sub-pixel: one shifted GEMM per output phase, written interleaved | [`reference::conv_transpose2d`] |
//! | BatchNorm (eval) | folded into the conv at load: [`fold_batchnorm`] | [`reference::batch_norm`] |
//! | reflection pad | row copies, parallel per plane | [`reference::reflect_pad`] |
//! | ReLU, Tanh, add | fused into conv epilogues; [`activate`], [`add_assign`] | [`reference::activate`], [`reference::add`] |
//! | bilinear resize | separable taps, parallel per plane | [`reference::resize_bilinear`] |
//!
//! ```
//! use picker_tensor::{Activation, Conv2d, ConvSpec, Rng};
//! let mut rng = Rng::new(7);
//! let spec = ConvSpec::square(3, 8, 3, 1, 1);
//! let w = rng.normal_vec(spec.weight_len(), 0.1);
//! let conv = Conv2d::new(spec, &w, None, Activation::Relu).unwrap();
//! let y = conv.forward(&rng.tensor([1, 3, 5, 7])).unwrap();
//! assert_eq!(y.shape(), [1, 8, 5, 7]);
//! ```

#![warn(missing_docs)]

mod activation;
mod aligned;
mod amx;
mod bf16;
mod bn;
mod conv;
mod direct;
mod elementwise;
mod error;
mod gemm;
mod isa;
mod microkernel;
mod pad;
pub mod params;
mod pixtile;
mod pool;
pub mod reference;
mod resize;
mod rng;
mod shifted;
mod tensor;
mod tolerance;
mod winograd;

pub use activation::Activation;

/// Frees the buffers that the crate keeps for reuse between layers and
/// passes (the activations a network has dropped, at most 256 MiB in all):
/// for a caller that is done with the networks for a while, e.g. an
/// extraction once its inference has run. The next pass allocates afresh.
pub fn release_buffers() {
    pool::release();
}

/// The low-memory mode, `PICKER_MEMORY=low` in the environment (read when
/// layers are built and when a network runs): 3×3 layers keep only their
/// 3×3 weights and make the Winograd ones at every pass
/// ([`ConvAlgorithm::WinogradLowMemoryAutoTile`]), and networks with several towers
/// run them one after another, so that one tower's activations are live at a
/// time. Slower (IRN at 240×320 on 2 cores: ~10–15%), for machines where
/// memory is the limit.
pub fn low_memory() -> bool {
    std::env::var("PICKER_MEMORY").as_deref() == Ok("low")
}

/// Arithmetic precision of the 3×3 stride-1 (Winograd) layers, chosen when
/// layers are built ([`precision`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum Precision {
    /// f32 everywhere (the default; the PyTorch-parity tolerance holds).
    F32,
    /// The Winograd layers' products in bfloat16 (AVX512_BF16 `vdpbf16ps`:
    /// transformed weights and inputs rounded to bf16, sums in f32); every
    /// other layer stays f32. Twice the products' throughput; the thesis
    /// networks' tanh outputs move by up to ~6e-2 (mean ~7e-3; see the crate
    /// README).
    Bf16,
}

impl Precision {
    /// Parses `f32` or `bf16`.
    pub fn parse(s: &str) -> Option<Precision> {
        match s.trim().to_ascii_lowercase().as_str() {
            "f32" | "fp32" => Some(Precision::F32),
            "bf16" | "bfloat16" => Some(Precision::Bf16),
            _ => None,
        }
    }

    /// Short name, as [`Precision::parse`] takes it.
    pub fn name(self) -> &'static str {
        match self {
            Precision::F32 => "f32",
            Precision::Bf16 => "bf16",
        }
    }

    /// True when this CPU can run the precision (bf16 needs AVX-512F,
    /// AVX-512BW and AVX512_BF16).
    pub fn is_available(self) -> bool {
        match self {
            Precision::F32 => true,
            Precision::Bf16 => bf16::available(),
        }
    }
}

impl std::fmt::Display for Precision {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// 0: not set; else 1 + the `Precision` discriminant.
static PRECISION: std::sync::atomic::AtomicU8 = std::sync::atomic::AtomicU8::new(0);

/// The precision new layers are built with: the one given to
/// [`set_precision`], else `PICKER_PRECISION` from the environment (`f32`
/// or `bf16`; anything else reads as f32), else f32.
pub fn precision() -> Precision {
    match PRECISION.load(std::sync::atomic::Ordering::Relaxed) {
        1 => Precision::F32,
        2 => Precision::Bf16,
        _ => std::env::var("PICKER_PRECISION")
            .ok()
            .and_then(|s| Precision::parse(&s))
            .unwrap_or(Precision::F32),
    }
}

/// Sets the precision of the layers built from now on, for the whole
/// process; refused (and nothing changed) when this CPU cannot run it.
pub fn set_precision(p: Precision) -> Result<()> {
    if !p.is_available() {
        return Err(error::invalid(
            "set_precision",
            format!("{p} needs AVX-512F, AVX-512BW and AVX512_BF16, which this CPU lacks"),
        ));
    }
    let code = match p {
        Precision::F32 => 1,
        Precision::Bf16 => 2,
    };
    PRECISION.store(code, std::sync::atomic::Ordering::Relaxed);
    Ok(())
}
pub use bn::{fold_batchnorm, BatchNorm, WeightLayout};
pub use conv::{Conv2d, ConvAlgorithm, ConvSpec, ConvTranspose2d, ConvTransposeSpec};
pub use elementwise::{activate, add_assign};
pub use error::{Error, Result};
pub use isa::Isa;
pub use pad::{mirror_pad, reflect_index, reflect_pad, Pads};
pub use resize::resize_bilinear;
pub use rng::Rng;
pub use tensor::Tensor;
pub use tolerance::Tolerance;
