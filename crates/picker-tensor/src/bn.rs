//! BatchNorm (eval mode) folded into the preceding convolution's weight and bias.

use crate::error::{shape_err, Result};

/// BatchNorm statistics and affine parameters of `c` channels.
#[derive(Clone, Debug, PartialEq)]
pub struct BatchNorm {
    /// Scale γ.
    pub gamma: Vec<f32>,
    /// Shift β.
    pub beta: Vec<f32>,
    /// Running mean.
    pub mean: Vec<f32>,
    /// Running variance.
    pub var: Vec<f32>,
    /// ε added to the variance.
    pub eps: f32,
}

impl BatchNorm {
    /// Channels.
    pub fn channels(&self) -> usize {
        self.gamma.len()
    }

    /// Per-channel `(scale, shift)` with `bn(v) = scale·v + shift`, computed in f64.
    pub fn scale_shift(&self) -> Result<(Vec<f64>, Vec<f64>)> {
        let c = self.gamma.len();
        for (name, v) in [
            ("beta", &self.beta),
            ("mean", &self.mean),
            ("var", &self.var),
        ] {
            if v.len() != c {
                return Err(shape_err("batch_norm", name, c, v.len()));
            }
        }
        // var + eps is a variance: it must be positive (and finite) for the
        // scale to be a number.
        if let Some(i) = (0..c).find(|&i| {
            let v = self.var[i] as f64 + self.eps as f64;
            !(v > 0.0 && v.is_finite())
        }) {
            return Err(crate::error::invalid(
                "batch_norm",
                format!(
                    "channel {i}: var {} + eps {} must be positive and finite",
                    self.var[i], self.eps
                ),
            ));
        }
        let scale: Vec<f64> = (0..c)
            .map(|i| self.gamma[i] as f64 / (self.var[i] as f64 + self.eps as f64).sqrt())
            .collect();
        let shift = (0..c)
            .map(|i| self.beta[i] as f64 - self.mean[i] as f64 * scale[i])
            .collect();
        Ok((scale, shift))
    }
}

/// How a convolution weight is laid out, so [`fold_batchnorm`] can find its output axis.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WeightLayout {
    /// `Conv2d`: `[c_out, c_in, kh, kw]`.
    Conv,
    /// `ConvTranspose2d`: `[c_in, c_out, kh, kw]`, with `kernel_area = kh·kw`.
    Transposed {
        /// `kh · kw`.
        kernel_area: usize,
    },
}

/// Folds `bn` (eval mode) into a convolution: returns the new `(weight, bias)`
/// such that `conv'(x) = bn(conv(x) + bias)`. Computed in f64, rounded once.
pub fn fold_batchnorm(
    weight: &[f32],
    bias: Option<&[f32]>,
    bn: &BatchNorm,
    layout: WeightLayout,
) -> Result<(Vec<f32>, Vec<f32>)> {
    let c_out = bn.channels();
    let (scale, shift) = bn.scale_shift()?;
    let block = match layout {
        WeightLayout::Conv => c_out,
        WeightLayout::Transposed { kernel_area } => {
            c_out.checked_mul(kernel_area).ok_or_else(|| {
                crate::error::invalid(
                    "fold_batchnorm",
                    format!("{c_out} channels x kernel area {kernel_area} overflows"),
                )
            })?
        }
    };
    if c_out == 0 || block == 0 || !weight.len().is_multiple_of(block) {
        return Err(shape_err(
            "fold_batchnorm",
            "weight length",
            format!("a positive multiple of {block}"),
            weight.len(),
        ));
    }
    if let Some(b) = bias {
        if b.len() != c_out {
            return Err(shape_err("fold_batchnorm", "bias length", c_out, b.len()));
        }
    }
    let mut w = weight.to_vec();
    match layout {
        WeightLayout::Conv => {
            let inner = weight.len() / c_out;
            for (co, chunk) in w.chunks_exact_mut(inner).enumerate() {
                chunk
                    .iter_mut()
                    .for_each(|v| *v = (*v as f64 * scale[co]) as f32);
            }
        }
        WeightLayout::Transposed { kernel_area } => {
            for per_in in w.chunks_exact_mut(c_out * kernel_area) {
                for (co, chunk) in per_in.chunks_exact_mut(kernel_area).enumerate() {
                    chunk
                        .iter_mut()
                        .for_each(|v| *v = (*v as f64 * scale[co]) as f32);
                }
            }
        }
    }
    let b = (0..c_out)
        .map(|co| (bias.map_or(0.0, |b| b[co] as f64) * scale[co] + shift[co]) as f32)
        .collect();
    Ok((w, b))
}
