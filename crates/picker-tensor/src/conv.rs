//! Convolution layers with packed weights: [`Conv2d`] and [`ConvTranspose2d`]
//! (PyTorch semantics, zero padding, any kernel and stride).

use rayon::prelude::*;

use crate::activation::Activation;
use crate::error::{invalid, shape_err, Result};
use crate::gemm::{gemm, BSource, DenseB, Epilogue, PackedA};
use crate::isa::Isa;
use crate::microkernel::MicroKernel;
use crate::tensor::Tensor;

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
        Ok(())
    }

    /// Output `(height, width)` for an input of `h × w`; refuses inputs smaller than the kernel.
    pub fn out_hw(&self, h: usize, w: usize) -> Result<(usize, usize)> {
        self.validate()?;
        let (hp, wp) = (h + 2 * self.pad, w + 2 * self.pad);
        if hp < self.kh || wp < self.kw {
            return Err(shape_err(
                "conv2d",
                "padded input",
                format!("at least {}x{}", self.kh, self.kw),
                format!("{hp}x{wp}"),
            ));
        }
        Ok(((hp - self.kh) / self.stride + 1, (wp - self.kw) / self.stride + 1))
    }

    /// Length of the weight `[c_out, c_in, kh, kw]`.
    pub fn weight_len(&self) -> usize {
        self.c_out * self.c_in * self.kh * self.kw
    }

    /// Floating-point operations (2 × multiply-adds) for one `h × w` input image.
    pub fn flops(&self, h: usize, w: usize) -> u64 {
        match self.out_hw(h, w) {
            Ok((oh, ow)) => 2 * (self.weight_len() * oh * ow) as u64,
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
        let full = |n: usize, k: usize| (n.max(1) - 1) * self.stride + k + self.output_padding;
        let (fh, fw) = (full(h, self.kh), full(w, self.kw));
        if h == 0 || w == 0 || fh <= 2 * self.pad || fw <= 2 * self.pad {
            return Err(shape_err(
                "conv_transpose2d",
                "output size",
                "positive",
                format!("input {h}x{w} with {self:?}"),
            ));
        }
        Ok((fh - 2 * self.pad, fw - 2 * self.pad))
    }

    /// Length of the weight `[c_in, c_out, kh, kw]`.
    pub fn weight_len(&self) -> usize {
        self.c_in * self.c_out * self.kh * self.kw
    }

    /// Floating-point operations (2 × multiply-adds, direct form) for one `h × w` input image.
    pub fn flops(&self, h: usize, w: usize) -> u64 {
        2 * (self.weight_len() * h * w) as u64
    }
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
    packed: PackedA,
}

impl std::fmt::Debug for Conv2d {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Conv2d")
            .field("spec", &self.spec)
            .field("act", &self.act)
            .field("bias", &self.bias.is_some())
            .field("isa", &self.packed.kernel.isa)
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

/// Implicit im2col over one image: row `k = (ci, ky, kx)`, column = output pixel.
struct Im2col<'a> {
    x: &'a [f32],
    h: usize,
    w: usize,
    spec: ConvSpec,
    ow: usize,
}

impl BSource for Im2col<'_> {
    fn pack(&self, k0: usize, kc: usize, n0: usize, cols: usize, nr: usize, dst: &mut [f32]) {
        let s = self.spec;
        let khw = s.kh * s.kw;
        let (h, w, ow) = (self.h as isize, self.w, self.ow);
        for kk in 0..kc {
            let k = k0 + kk;
            let (ci, ky, kx) = (k / khw, (k % khw) / s.kw, k % s.kw);
            let plane = &self.x[ci * self.h * w..(ci + 1) * self.h * w];
            let row = &mut dst[kk * nr..(kk + 1) * nr];
            row[cols..].fill(0.0);
            let mut j = 0;
            let mut n = n0;
            while j < cols {
                let (oy, ox) = (n / ow, n % ow);
                let run = (cols - j).min(ow - ox);
                let out = &mut row[j..j + run];
                let iy = (oy * s.stride + ky) as isize - s.pad as isize;
                if iy < 0 || iy >= h {
                    out.fill(0.0);
                } else {
                    let src = &plane[iy as usize * w..(iy as usize + 1) * w];
                    let ix0 = (ox * s.stride + kx) as isize - s.pad as isize;
                    if s.stride == 1 {
                        let lo = (-ix0).clamp(0, run as isize) as usize;
                        let hi = (w as isize - ix0).clamp(lo as isize, run as isize) as usize;
                        out[..lo].fill(0.0);
                        if hi > lo {
                            let a = (ix0 + lo as isize) as usize;
                            out[lo..hi].copy_from_slice(&src[a..a + (hi - lo)]);
                        }
                        out[hi..].fill(0.0);
                    } else {
                        for (t, o) in out.iter_mut().enumerate() {
                            let ix = ix0 + (t * s.stride) as isize;
                            *o = if ix >= 0 && (ix as usize) < w {
                                src[ix as usize]
                            } else {
                                0.0
                            };
                        }
                    }
                }
                j += run;
                n += run;
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
        spec.validate()?;
        check_weight("conv2d", weight.len(), spec.weight_len())?;
        let bias = check_bias("conv2d", bias, spec.c_out)?;
        let kernel = kernel_for("conv2d", isa)?;
        let k = spec.c_in * spec.kh * spec.kw;
        let packed = PackedA::pack(kernel, spec.c_out, k, |r, c| weight[r * k + c]);
        Ok(Self {
            spec,
            act,
            bias,
            packed,
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
        self.packed.kernel.isa
    }

    /// `act(conv(x) + b)`.
    pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
        self.run(x, None)
    }

    /// `act(conv(x) + b) + residual`; `residual` has the output's shape.
    pub fn forward_add(&self, x: &Tensor, residual: &Tensor) -> Result<Tensor> {
        self.run(x, Some(residual))
    }

    fn run(&self, x: &Tensor, residual: Option<&Tensor>) -> Result<Tensor> {
        let s = self.spec;
        check_input("conv2d", x, s.c_in)?;
        let (oh, ow) = s.out_hw(x.h(), x.w())?;
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
        let mut out = Tensor::zeros(shape);
        let per_out = s.c_out * oh * ow;
        for b in 0..x.n() {
            let img = x.image(b);
            let c = &mut out.data_mut()[b * per_out..(b + 1) * per_out];
            let epi = Epilogue {
                bias: self.bias.as_deref(),
                act: self.act,
                residual: residual.map(|r| r.image(b)),
            };
            if s.kh == 1 && s.kw == 1 && s.stride == 1 && s.pad == 0 {
                let src = DenseB { data: img, n: oh * ow };
                gemm(&self.packed, &src, oh * ow, c, &epi);
            } else {
                let src = Im2col {
                    x: img,
                    h: x.h(),
                    w: x.w(),
                    spec: s,
                    ow,
                };
                gemm(&self.packed, &src, oh * ow, c, &epi);
            }
        }
        Ok(out)
    }
}

/// A transposed convolution with packed weights: a GEMM into columns followed
/// by a parallel col2im scatter, bias and activation.
#[derive(Clone)]
pub struct ConvTranspose2d {
    spec: ConvTransposeSpec,
    act: Activation,
    bias: Option<Vec<f32>>,
    packed: PackedA,
}

impl std::fmt::Debug for ConvTranspose2d {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ConvTranspose2d")
            .field("spec", &self.spec)
            .field("act", &self.act)
            .field("bias", &self.bias.is_some())
            .field("isa", &self.packed.kernel.isa)
            .finish()
    }
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
        let khw = spec.kh * spec.kw;
        // A[(co, ky, kx)][ci] = w[ci][co][ky][kx]
        let packed = PackedA::pack(kernel, spec.c_out * khw, spec.c_in, |r, ci| {
            weight[ci * spec.c_out * khw + r]
        });
        Ok(Self {
            spec,
            act,
            bias,
            packed,
        })
    }

    /// The layer's shape.
    pub fn spec(&self) -> ConvTransposeSpec {
        self.spec
    }
    /// The kernel family the weights are packed for.
    pub fn isa(&self) -> Isa {
        self.packed.kernel.isa
    }

    /// `act(conv_transpose(x) + b)`.
    pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
        let s = self.spec;
        check_input("conv_transpose2d", x, s.c_in)?;
        let (oh, ow) = s.out_hw(x.h(), x.w())?;
        let (h, w) = (x.h(), x.w());
        let khw = s.kh * s.kw;
        let mut out = Tensor::zeros([x.n(), s.c_out, oh, ow]);
        let mut cols = vec![0.0f32; s.c_out * khw * h * w];
        let no_epi = Epilogue {
            bias: None,
            act: Activation::None,
            residual: None,
        };
        for b in 0..x.n() {
            let src = DenseB {
                data: x.image(b),
                n: h * w,
            };
            gemm(&self.packed, &src, h * w, &mut cols, &no_epi);
            let per_out = s.c_out * oh * ow;
            let dst = &mut out.data_mut()[b * per_out..(b + 1) * per_out];
            let cols = &cols;
            dst.par_chunks_mut(oh * ow).enumerate().for_each(|(co, plane)| {
                plane.fill(self.bias.as_ref().map_or(0.0, |bb| bb[co]));
                for ky in 0..s.kh {
                    for kx in 0..s.kw {
                        let col = &cols[(co * khw + ky * s.kw + kx) * h * w..][..h * w];
                        for iy in 0..h {
                            let oy = (iy * s.stride + ky) as isize - s.pad as isize;
                            if oy < 0 || oy >= oh as isize {
                                continue;
                            }
                            let orow = &mut plane[oy as usize * ow..(oy as usize + 1) * ow];
                            let crow = &col[iy * w..(iy + 1) * w];
                            for (ix, v) in crow.iter().enumerate() {
                                let ox = (ix * s.stride + kx) as isize - s.pad as isize;
                                if ox >= 0 && (ox as usize) < ow {
                                    orow[ox as usize] += v;
                                }
                            }
                        }
                    }
                }
                self.act.apply(plane);
            });
        }
        Ok(out)
    }
}
