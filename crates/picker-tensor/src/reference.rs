//! Plain, obviously-correct reference versions of every op (f64 accumulation,
//! direct loops, no packing, no threads). The fast paths are tested against these.

use crate::activation::Activation;
use crate::bn::BatchNorm;
use crate::conv::{ConvSpec, ConvTransposeSpec};
use crate::error::{shape_err, Result};
use crate::pad::{reflect_index, Pads};
use crate::tensor::Tensor;

/// Direct convolution with zero padding, then `+ bias`.
pub fn conv2d(x: &Tensor, weight: &[f32], bias: Option<&[f32]>, s: ConvSpec) -> Result<Tensor> {
    let (oh, ow) = s.out_hw(x.h(), x.w())?;
    if x.c() != s.c_in {
        return Err(shape_err("conv2d", "input channels", s.c_in, x.c()));
    }
    if weight.len() != s.weight_len() {
        return Err(shape_err(
            "conv2d",
            "weight length",
            s.weight_len(),
            weight.len(),
        ));
    }
    if let Some(b) = bias {
        if b.len() != s.c_out {
            return Err(shape_err("conv2d", "bias length", s.c_out, b.len()));
        }
    }
    let mut out = Tensor::zeros([x.n(), s.c_out, oh, ow]);
    for n in 0..x.n() {
        for co in 0..s.c_out {
            for oy in 0..oh {
                for ox in 0..ow {
                    let mut acc = bias.map_or(0.0, |b| b[co] as f64);
                    for ci in 0..s.c_in {
                        for ky in 0..s.kh {
                            for kx in 0..s.kw {
                                let iy = (oy * s.stride + ky) as isize - s.pad as isize;
                                let ix = (ox * s.stride + kx) as isize - s.pad as isize;
                                if iy < 0 || ix < 0 || iy >= x.h() as isize || ix >= x.w() as isize
                                {
                                    continue;
                                }
                                let wv = weight[((co * s.c_in + ci) * s.kh + ky) * s.kw + kx];
                                acc += wv as f64 * x.at(n, ci, iy as usize, ix as usize) as f64;
                            }
                        }
                    }
                    let i = out.index(n, co, oy, ox);
                    out.data_mut()[i] = acc as f32;
                }
            }
        }
    }
    Ok(out)
}

/// Direct transposed convolution (scatter form), then `+ bias`.
pub fn conv_transpose2d(
    x: &Tensor,
    weight: &[f32],
    bias: Option<&[f32]>,
    s: ConvTransposeSpec,
) -> Result<Tensor> {
    let (oh, ow) = s.out_hw(x.h(), x.w())?;
    if x.c() != s.c_in {
        return Err(shape_err(
            "conv_transpose2d",
            "input channels",
            s.c_in,
            x.c(),
        ));
    }
    if weight.len() != s.weight_len() {
        return Err(shape_err(
            "conv_transpose2d",
            "weight length",
            s.weight_len(),
            weight.len(),
        ));
    }
    if let Some(b) = bias {
        if b.len() != s.c_out {
            return Err(shape_err(
                "conv_transpose2d",
                "bias length",
                s.c_out,
                b.len(),
            ));
        }
    }
    let mut acc = vec![0.0f64; x.n() * s.c_out * oh * ow];
    for n in 0..x.n() {
        for ci in 0..s.c_in {
            for iy in 0..x.h() {
                for ix in 0..x.w() {
                    let v = x.at(n, ci, iy, ix) as f64;
                    for co in 0..s.c_out {
                        for ky in 0..s.kh {
                            for kx in 0..s.kw {
                                let oy = (iy * s.stride + ky) as isize - s.pad as isize;
                                let ox = (ix * s.stride + kx) as isize - s.pad as isize;
                                if oy < 0 || ox < 0 || oy >= oh as isize || ox >= ow as isize {
                                    continue;
                                }
                                let wv = weight[((ci * s.c_out + co) * s.kh + ky) * s.kw + kx];
                                acc[((n * s.c_out + co) * oh + oy as usize) * ow + ox as usize] +=
                                    v * wv as f64;
                            }
                        }
                    }
                }
            }
        }
    }
    let plane = oh * ow;
    let data = acc
        .iter()
        .enumerate()
        .map(|(i, v)| (v + bias.map_or(0.0, |b| b[(i / plane) % s.c_out] as f64)) as f32)
        .collect();
    Tensor::new([x.n(), s.c_out, oh, ow], data)
}

/// PyTorch `ReflectionPad2d` element by element (pads must be smaller than the axis).
pub fn reflect_pad(x: &Tensor, pads: Pads) -> Result<Tensor> {
    let [t, b, l, r] = pads;
    if t.max(b) >= x.h() || l.max(r) >= x.w() {
        return Err(shape_err(
            "reflect_pad",
            "pad widths",
            format!("smaller than {}x{}", x.h(), x.w()),
            format!("{pads:?}"),
        ));
    }
    Ok(mirror_pad(x, pads))
}

/// Mirror extension element by element.
pub fn mirror_pad(x: &Tensor, pads: Pads) -> Tensor {
    let [t, b, l, r] = pads;
    Tensor::from_fn(
        [x.n(), x.c(), x.h() + t + b, x.w() + l + r],
        |n, c, y, xx| {
            let sy = reflect_index(y as isize - t as isize, x.h());
            let sx = reflect_index(xx as isize - l as isize, x.w());
            x.at(n, c, sy, sx)
        },
    )
}

/// Applies an activation element by element.
pub fn activate(x: &Tensor, act: Activation) -> Tensor {
    let data = x
        .data()
        .iter()
        .map(|&v| act.apply_f64(v as f64) as f32)
        .collect();
    Tensor::new(x.shape(), data).expect("same shape")
}

/// `x + y`.
pub fn add(x: &Tensor, y: &Tensor) -> Result<Tensor> {
    if x.shape() != y.shape() {
        return Err(shape_err(
            "add",
            "shape",
            format!("{:?}", x.shape()),
            format!("{:?}", y.shape()),
        ));
    }
    let data = x.data().iter().zip(y.data()).map(|(a, b)| a + b).collect();
    Tensor::new(x.shape(), data)
}

/// BatchNorm in eval mode: `γ (x − μ) / sqrt(σ² + ε) + β` per channel.
pub fn batch_norm(x: &Tensor, bn: &BatchNorm) -> Result<Tensor> {
    if bn.channels() != x.c() {
        return Err(shape_err("batch_norm", "channels", x.c(), bn.channels()));
    }
    bn.scale_shift()?;
    Ok(Tensor::from_fn(x.shape(), |n, c, y, xx| {
        let v = x.at(n, c, y, xx) as f64;
        let d = (bn.var[c] as f64 + bn.eps as f64).sqrt();
        ((v - bn.mean[c] as f64) / d * bn.gamma[c] as f64 + bn.beta[c] as f64) as f32
    }))
}

/// Bilinear resize, `align_corners=False`, written from the definition.
pub fn resize_bilinear(x: &Tensor, oh: usize, ow: usize) -> Result<Tensor> {
    if oh == 0 || ow == 0 || x.h() == 0 || x.w() == 0 {
        return Err(crate::error::invalid(
            "resize_bilinear",
            "sizes must be positive",
        ));
    }
    let src = |i: usize, inl: usize, outl: usize| -> (usize, usize, f64) {
        let s = ((i as f64 + 0.5) * inl as f64 / outl as f64 - 0.5).max(0.0);
        let i0 = (s.floor() as usize).min(inl - 1);
        let i1 = (i0 + 1).min(inl - 1);
        (i0, i1, s - i0 as f64)
    };
    Ok(Tensor::from_fn([x.n(), x.c(), oh, ow], |n, c, y, xx| {
        let (y0, y1, ly) = src(y, x.h(), oh);
        let (x0, x1, lx) = src(xx, x.w(), ow);
        let g = |yy, xx| x.at(n, c, yy, xx) as f64;
        let v = (1.0 - ly) * ((1.0 - lx) * g(y0, x0) + lx * g(y0, x1))
            + ly * ((1.0 - lx) * g(y1, x0) + lx * g(y1, x1));
        v as f32
    }))
}
