//! The building blocks shared by the three networks (contract, "Modules and
//! state_dict keys"), each with its BatchNorm folded into the convolution at
//! load and its activation fused into the kernel epilogue.

use picker_tensor::{
    fold_batchnorm, Activation, BatchNorm, Conv2d, ConvAlgorithm, ConvSpec, ConvTranspose2d,
    ConvTransposeSpec, Isa, Tensor, WeightLayout,
};

use crate::error::{Error, Result};
use crate::weights::WeightsPrefix;

/// Options every layer of a network shares.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LayerOptions {
    /// Whether the convolutions before a BatchNorm have a bias (`conv_bias`).
    pub conv_bias: bool,
    /// BatchNorm ε.
    pub bn_eps: f32,
    /// Make the Winograd layers' transformed weights at every pass instead
    /// of keeping them packed ([`ConvAlgorithm::AutoLowMemory`]).
    pub lazy_winograd: bool,
}

impl Default for LayerOptions {
    fn default() -> Self {
        Self {
            conv_bias: false,
            bn_eps: 1e-5,
            lazy_winograd: false,
        }
    }
}

/// Where intermediate activations go when tracing: `(module path, tensor)`
/// pairs, e.g. `("heads.normals.blocks.0", ...)`.
pub type Trace = Vec<(String, Tensor)>;

/// Per-stage wall times of one profiled forward pass: `(module path, time)`
/// in execution order, each the time since the previous stage ended (the
/// first: since the pass began). The stages are the points a [`Trace`]
/// records, so the times add up to the whole pass (less the input padding
/// and output cropping), except that the layers that run fused unless
/// activations are traced are one stage each: the encoder's
/// `enc.conv_in+down.0` and a decoder's `….up.1+conv_out`.
pub type Timings = Vec<(String, std::time::Duration)>;

enum Sink<'a> {
    Off,
    Activations(&'a mut Trace),
    Timings {
        out: &'a mut Timings,
        last: std::time::Instant,
    },
}

/// An optional trace sink (activations or stage times); recording costs
/// nothing when it is off.
pub(crate) struct Tracer<'a> {
    sink: Sink<'a>,
}

impl<'a> Tracer<'a> {
    pub(crate) fn new(sink: Option<&'a mut Trace>) -> Self {
        Self {
            sink: match sink {
                Some(t) => Sink::Activations(t),
                None => Sink::Off,
            },
        }
    }
    /// A tracer that records the time of each stage into `out`, starting now.
    pub(crate) fn timing(out: &'a mut Timings) -> Self {
        Self {
            sink: Sink::Timings {
                out,
                last: std::time::Instant::now(),
            },
        }
    }
    /// True when activations or times are being recorded (the network then
    /// runs its stages one after another, in a fixed order).
    pub(crate) fn is_recording(&self) -> bool {
        !matches!(self.sink, Sink::Off)
    }
    /// True when activations are being recorded.
    pub(crate) fn records_activations(&self) -> bool {
        matches!(self.sink, Sink::Activations(_))
    }
    /// Records a clone of `t` (or the time since the last record) as
    /// `prefix.name` (or `name` when `prefix` is empty).
    pub(crate) fn record(&mut self, prefix: &str, name: &str, t: &Tensor) {
        let key = || {
            if prefix.is_empty() {
                name.to_string()
            } else if name.is_empty() {
                prefix.to_string()
            } else {
                format!("{prefix}.{name}")
            }
        };
        match &mut self.sink {
            Sink::Off => {}
            Sink::Activations(s) => s.push((key(), t.clone())),
            Sink::Timings { out, last } => {
                let now = std::time::Instant::now();
                // A record with an empty name repeats its module's last
                // stage (e.g. `enc` after `enc.down.1`): no time of its own.
                if !name.is_empty() {
                    out.push((key(), now - *last));
                }
                *last = now;
            }
        }
    }
}

pub(crate) fn join(prefix: &str, name: &str) -> String {
    if prefix.is_empty() {
        name.to_string()
    } else {
        format!("{prefix}.{name}")
    }
}

fn load_bn(w: &WeightsPrefix<'_>, c: usize, eps: f32) -> Result<BatchNorm> {
    let bn = BatchNorm {
        gamma: w.get("weight", &[c])?,
        beta: w.get("bias", &[c])?,
        mean: w.get("running_mean", &[c])?,
        var: w.get("running_var", &[c])?,
        eps,
    };
    if let Some(i) = bn.var.iter().position(|&v| v < 0.0) {
        return Err(Error::InvalidTensor {
            path: w.weights().path().to_path_buf(),
            key: w.key("running_var"),
            reason: format!(
                "variance {} at channel {i} is negative; a running variance must be ≥ 0",
                bn.var[i]
            ),
        });
    }
    Ok(bn)
}

/// Reads `conv.weight` (+ `conv.bias` when `opts.conv_bias`) and the BatchNorm `bn`
/// under `w`, and folds them into one convolution with activation `act`.
fn folded_conv(
    w: &WeightsPrefix<'_>,
    conv: &str,
    bn: &str,
    spec: ConvSpec,
    opts: LayerOptions,
    act: Activation,
) -> Result<Conv2d> {
    let cw = w.pp(conv);
    let weight = cw.get("weight", &[spec.c_out, spec.c_in, spec.kh, spec.kw])?;
    let bias = if opts.conv_bias {
        Some(cw.get("bias", &[spec.c_out])?)
    } else {
        None
    };
    let bn = load_bn(&w.pp(bn), spec.c_out, opts.bn_eps)?;
    let (fw, fb) = fold_batchnorm(&weight, bias.as_deref(), &bn, WeightLayout::Conv)?;
    let algorithm = if opts.lazy_winograd {
        ConvAlgorithm::AutoLowMemory
    } else {
        ConvAlgorithm::Auto
    };
    Ok(Conv2d::with_algorithm(
        Isa::best(),
        algorithm,
        spec,
        &fw,
        Some(&fb),
        act,
    )?)
}

fn conv_params(spec: ConvSpec) -> u64 {
    (spec.weight_len() + spec.c_out) as u64
}

/// `Conv2d` (zero padding) + BatchNorm + activation, folded into one convolution.
/// Keys: `P.conv.weight`, `P.conv.bias` (if `conv_bias`), `P.bn.{weight,bias,running_mean,running_var}`.
#[derive(Clone, Debug)]
pub struct ConvBn {
    conv: Conv2d,
}

impl ConvBn {
    /// Loads and folds the layer at prefix `w`.
    pub fn load(
        w: &WeightsPrefix<'_>,
        spec: ConvSpec,
        opts: LayerOptions,
        act: Activation,
    ) -> Result<Self> {
        Ok(Self {
            conv: folded_conv(w, "conv", "bn", spec, opts, act)?,
        })
    }
    /// `act(bn(conv(x)))`.
    pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
        Ok(self.conv.forward(x)?)
    }
    /// `act(bn(conv(reflect_pad(x, pad))))`, the padding fused where the kernel can.
    pub fn forward_reflect(&self, x: &Tensor, pad: usize) -> Result<Tensor> {
        Ok(self.conv.forward_reflect(x, pad, None)?)
    }
    /// Parameters after folding.
    pub fn param_count(&self) -> u64 {
        conv_params(self.conv.spec())
    }
    /// The folded convolution.
    pub fn conv(&self) -> &Conv2d {
        &self.conv
    }
}

/// `ConvTranspose2d(k3, stride 2, pad 1, output_padding 1)` + BatchNorm + ReLU, folded.
/// Keys as [`ConvBn`], with the weight `[c_in, c_out, 3, 3]`.
#[derive(Clone, Debug)]
pub struct ConvTBn {
    conv: ConvTranspose2d,
}

impl ConvTBn {
    /// Loads and folds the layer at prefix `w` (`c_in → c_out`).
    pub fn load(
        w: &WeightsPrefix<'_>,
        c_in: usize,
        c_out: usize,
        opts: LayerOptions,
    ) -> Result<Self> {
        let spec = ConvTransposeSpec::square(c_in, c_out, 3, 2, 1, 1);
        let cw = w.pp("conv");
        let weight = cw.get("weight", &[c_in, c_out, 3, 3])?;
        let bias = if opts.conv_bias {
            Some(cw.get("bias", &[c_out])?)
        } else {
            None
        };
        let bn = load_bn(&w.pp("bn"), c_out, opts.bn_eps)?;
        let (fw, fb) = fold_batchnorm(
            &weight,
            bias.as_deref(),
            &bn,
            WeightLayout::Transposed { kernel_area: 9 },
        )?;
        Ok(Self {
            conv: ConvTranspose2d::new(spec, &fw, Some(&fb), Activation::Relu)?,
        })
    }
    /// `relu(bn(conv_transpose(x)))`: doubles height and width.
    pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
        Ok(self.conv.forward(x)?)
    }
    /// `conv.forward_reflect(&self.forward(x)?, pad, None)` in bands of rows
    /// ([`ConvTranspose2d::then_reflect_conv`]).
    pub fn then_reflect_conv(&self, x: &Tensor, conv: &Conv2d, pad: usize) -> Result<Tensor> {
        Ok(self.conv.then_reflect_conv(x, conv, pad)?)
    }
    /// Parameters after folding.
    pub fn param_count(&self) -> u64 {
        let s = self.conv.spec();
        (s.weight_len() + s.c_out) as u64
    }
}

/// Residual block: ReflectionPad(1) → `conv1` → `bn1` → ReLU → ReflectionPad(1) →
/// `conv2` → `bn2`, plus the input (no activation after the sum).
#[derive(Clone, Debug)]
pub struct ResBlock {
    conv1: Conv2d,
    conv2: Conv2d,
}

impl ResBlock {
    /// Loads a `c`-channel block at prefix `w`.
    pub fn load(w: &WeightsPrefix<'_>, c: usize, opts: LayerOptions) -> Result<Self> {
        let spec = ConvSpec::square(c, c, 3, 1, 0);
        Ok(Self {
            conv1: folded_conv(w, "conv1", "bn1", spec, opts, Activation::Relu)?,
            conv2: folded_conv(w, "conv2", "bn2", spec, opts, Activation::None)?,
        })
    }
    /// `x + bn2(conv2(pad(relu(bn1(conv1(pad(x)))))))`; needs `h, w ≥ 2`.
    pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
        // The reflection padding is fused into the convolution's gather.
        let h = self.conv1.forward_reflect(x, 1, None)?;
        Ok(self.conv2.forward_reflect(&h, 1, Some(x))?)
    }
    /// Parameters after folding.
    pub fn param_count(&self) -> u64 {
        conv_params(self.conv1.spec()) + conv_params(self.conv2.spec())
    }
}

/// A stack of residual blocks (`P.<i>`).
#[derive(Clone, Debug, Default)]
pub struct ResBlocks {
    blocks: Vec<ResBlock>,
}

impl ResBlocks {
    /// Loads `n` blocks of `c` channels at `P.0 … P.{n-1}`.
    pub fn load(w: &WeightsPrefix<'_>, n: usize, c: usize, opts: LayerOptions) -> Result<Self> {
        let blocks = (0..n)
            .map(|i| ResBlock::load(&w.pp(i), c, opts))
            .collect::<Result<_>>()?;
        Ok(Self { blocks })
    }
    /// Runs every block in turn.
    pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
        self.forward_traced(x, &mut Tracer::new(None), "")
    }
    pub(crate) fn forward_traced(
        &self,
        x: &Tensor,
        tr: &mut Tracer<'_>,
        path: &str,
    ) -> Result<Tensor> {
        let Some((first, rest)) = self.blocks.split_first() else {
            return Ok(x.clone());
        };
        let mut y = first.forward(x)?;
        tr.record(path, "0", &y);
        for (i, b) in rest.iter().enumerate() {
            y = b.forward(&y)?;
            tr.record(path, &(i + 1).to_string(), &y);
        }
        Ok(y)
    }
    /// Number of blocks.
    pub fn len(&self) -> usize {
        self.blocks.len()
    }
    /// True with no blocks.
    pub fn is_empty(&self) -> bool {
        self.blocks.is_empty()
    }
    /// Parameters after folding.
    pub fn param_count(&self) -> u64 {
        self.blocks.iter().map(ResBlock::param_count).sum()
    }
}

/// Encoder: ReflectionPad(3) → `conv_in` ConvBn(c_in, w0, k7, stride0) + ReLU →
/// `down.0` ConvBn(w0, w1, k3, s2, pad 1) + ReLU → `down.1` ConvBn(w1, w2, k3, s2, pad 1) + ReLU.
#[derive(Clone, Debug)]
pub struct Encoder {
    conv_in: ConvBn,
    down: [ConvBn; 2],
}

impl Encoder {
    /// Loads the 3-input encoder at prefix `w` (`stride0` = 1 for IRN/MSN, 2 for EnvMap).
    pub fn load(
        w: &WeightsPrefix<'_>,
        widths: [usize; 3],
        stride0: usize,
        opts: LayerOptions,
    ) -> Result<Self> {
        Self::load_with_inputs(w, 3, widths, stride0, opts)
    }

    /// Loads an encoder whose first convolution reads `c_in` planes (the
    /// inpainter: texture channels + the known mask).
    pub fn load_with_inputs(
        w: &WeightsPrefix<'_>,
        c_in: usize,
        [w0, w1, w2]: [usize; 3],
        stride0: usize,
        opts: LayerOptions,
    ) -> Result<Self> {
        let relu = Activation::Relu;
        Ok(Self {
            conv_in: ConvBn::load(
                &w.pp("conv_in"),
                ConvSpec::square(c_in, w0, 7, stride0, 0),
                opts,
                relu,
            )?,
            down: [
                ConvBn::load(
                    &w.pp("down.0"),
                    ConvSpec::square(w0, w1, 3, 2, 1),
                    opts,
                    relu,
                )?,
                ConvBn::load(
                    &w.pp("down.1"),
                    ConvSpec::square(w1, w2, 3, 2, 1),
                    opts,
                    relu,
                )?,
            ],
        })
    }
    /// Runs the encoder (input at least 4×4).
    pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
        self.forward_traced(x, &mut Tracer::new(None), "")
    }
    pub(crate) fn forward_traced(
        &self,
        x: &Tensor,
        tr: &mut Tracer<'_>,
        path: &str,
    ) -> Result<Tensor> {
        let x1 = if tr.records_activations() {
            let x0 = self.conv_in.forward_reflect(x, 3)?;
            tr.record(path, "conv_in", &x0);
            self.down[0].forward(&x0)?
        } else {
            // `conv_in` and `down.0` a band of rows at a time: the full-size
            // `conv_in` output is never held whole (the same values). Timed
            // as one stage.
            let x1 = self
                .conv_in
                .conv()
                .reflect_then(x, 3, self.down[0].conv())?;
            tr.record(path, "conv_in+down.0", &x1);
            x1
        };
        if tr.records_activations() {
            tr.record(path, "down.0", &x1);
        }
        // The input of each stage is dropped once the next is made.
        let x2 = self.down[1].forward(&x1)?;
        drop(x1);
        tr.record(path, "down.1", &x2);
        tr.record(path, "", &x2);
        Ok(x2)
    }
    /// Parameters after folding.
    pub fn param_count(&self) -> u64 {
        self.conv_in.param_count() + self.down.iter().map(ConvBn::param_count).sum::<u64>()
    }
}

/// Decoder: `up.0` ConvTBn(w2, w1) → `up.1` ConvTBn(w1, w0) → ReflectionPad(3) →
/// `conv_out` Conv2d(w0, c, 7, bias) → Tanh.
#[derive(Clone, Debug)]
pub struct Decoder {
    up: [ConvTBn; 2],
    conv_out: Conv2d,
}

impl Decoder {
    /// Loads a decoder with `c` outputs at prefix `w`.
    pub fn load(
        w: &WeightsPrefix<'_>,
        [w0, w1, w2]: [usize; 3],
        c: usize,
        opts: LayerOptions,
    ) -> Result<Self> {
        let spec = ConvSpec::square(w0, c, 7, 1, 0);
        let out = w.pp("conv_out");
        let weight = out.get("weight", &[c, w0, 7, 7])?;
        let bias = out.get("bias", &[c])?;
        Ok(Self {
            up: [
                ConvTBn::load(&w.pp("up.0"), w2, w1, opts)?,
                ConvTBn::load(&w.pp("up.1"), w1, w0, opts)?,
            ],
            conv_out: Conv2d::new(spec, &weight, Some(&bias), Activation::Tanh)?,
        })
    }
    /// Runs the decoder: ×4 spatially, tanh outputs.
    pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
        self.forward_traced(x.clone(), &mut Tracer::new(None), "")
    }
    /// As `forward`, taking the input by value: it is dropped once `up.0`
    /// has read it. `up.1` and `conv_out` run fused in bands of rows
    /// ([`ConvTranspose2d::then_reflect_conv`]), except when a trace records
    /// `up.1`'s output: the full-size 64-channel activation would otherwise be
    /// the largest a network holds (the IRN runs two decoders side by side).
    pub(crate) fn forward_traced(
        &self,
        x: Tensor,
        tr: &mut Tracer<'_>,
        path: &str,
    ) -> Result<Tensor> {
        let u0 = self.up[0].forward(&x)?;
        drop(x);
        tr.record(path, "up.0", &u0);
        if tr.records_activations() {
            let u1 = self.up[1].forward(&u0)?;
            drop(u0);
            tr.record(path, "up.1", &u1);
            let y = self.conv_out.forward_reflect(&u1, 3, None)?;
            tr.record(path, "conv_out", &y);
            return Ok(y);
        }
        // `up.1` and `conv_out` a band of rows at a time: the full-size
        // `up.1` output is never held whole (the same values). Timed as one
        // stage.
        let y = self.up[1].then_reflect_conv(&u0, &self.conv_out, 3)?;
        tr.record(path, "up.1+conv_out", &y);
        Ok(y)
    }
    /// Output channels.
    pub fn out_channels(&self) -> usize {
        self.conv_out.spec().c_out
    }
    /// Parameters after folding.
    pub fn param_count(&self) -> u64 {
        self.up.iter().map(ConvTBn::param_count).sum::<u64>() + conv_params(self.conv_out.spec())
    }
}
