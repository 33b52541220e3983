//! The three networks (thesis ch. 5.2) and the learned inpainter as typed
//! models, and [`Net`] over them.
//!
//! Every `forward` takes a normalised input `[N, 3, H, W]`
//! ([`crate::conventions::normalize_input`]; the inpainter:
//! `[N, channels + 1, H, W]` from [`crate::conventions::inpaint_input`]) of any
//! size ≥ 1×1, mirror-pads it to what the network needs
//! ([`NetKind::padded_size`]), runs, and crops back (IRN, MSN, inpainter) or
//! resizes to `(max(1, H/8), max(1, W/8))` (EnvMap).

use std::borrow::Cow;

use picker_tensor::{mirror_pad, resize_bilinear, Activation, ConvSpec, Tensor};

use crate::config::{EnvMapConfig, InpaintConfig, IrnConfig, MsnConfig, NetConfig, NetKind};
use crate::error::{Error, Result};
use crate::layers::{
    join, ConvBn, Decoder, Encoder, LayerOptions, ResBlocks, Timings, Trace, Tracer,
};
use crate::weights::Weights;

fn options(cfg: &NetConfig) -> LayerOptions {
    LayerOptions {
        conv_bias: cfg.conv_bias(),
        bn_eps: cfg.bn_eps() as f32,
        // Every net makes each chunk's Winograd weights from the 3×3 ones at
        // every pass rather than keeping them packed (4× the 3×3 weights:
        // 1.7 GB for the thesis IRN). Measured at 240×320 on a 2-core
        // AVX-512 Xeon, interleaved: IRN and MSN as fast as packed (IRN
        // ~1650-1700 ms either way; RSS 1864 -> ~600 MB), EnvMap faster.
        // On a Zen 4 host the packed weights were 6-13% faster for the IRN;
        // `PICKER_WINOGRAD_WEIGHTS=packed` restores them.
        lazy_winograd: true,
    }
}

/// Checks `x` is `[N ≥ 1, c_in, H ≥ 1, W ≥ 1]` and mirror-pads it for `kind`.
fn pad_input(kind: NetKind, x: &Tensor, c_in: usize) -> Result<(Cow<'_, Tensor>, [usize; 4])> {
    let [n, c, h, w] = x.shape();
    if n == 0 || c != c_in || h == 0 || w == 0 {
        let what = if kind == NetKind::Inpaint {
            "inpainting input (texture planes with unknown texels 0, then the known mask ±1)"
        } else {
            "normalised RGB"
        };
        return Err(Error::Input {
            reason: format!(
                "{kind} needs a {what} tensor [N >= 1, {c_in}, H >= 1, W >= 1]; got {:?}",
                x.shape()
            ),
        });
    }
    if let Some(i) = x.data().iter().position(|v| !v.is_finite()) {
        return Err(Error::Input {
            reason: format!("input value at flat index {i} is {}", x.data()[i]),
        });
    }
    let pads = kind.input_pads(h, w);
    if pads == [0; 4] {
        Ok((Cow::Borrowed(x), pads))
    } else {
        Ok((Cow::Owned(mirror_pad(x, pads)), pads))
    }
}

/// Crops a padded output back to the input's `h × w`.
fn crop_back(y: Tensor, pads: [usize; 4], h: usize, w: usize) -> Result<Tensor> {
    if pads == [0; 4] {
        return Ok(y);
    }
    Ok(y.crop(pads[0], pads[2], h, w)?)
}

fn load_start(w: &Weights, kind: NetKind) -> Result<()> {
    w.expect_kind(kind)
}

/// One IRN head: `blocks` residual blocks and a decoder.
#[derive(Clone, Debug)]
pub struct Tower {
    blocks: ResBlocks,
    dec: Decoder,
}

impl Tower {
    /// Parameters after folding.
    pub fn param_count(&self) -> u64 {
        self.blocks.param_count() + self.dec.param_count()
    }
    /// Output channels.
    pub fn out_channels(&self) -> usize {
        self.dec.out_channels()
    }
    fn forward_traced(&self, x: &Tensor, tr: &mut Tracer<'_>, path: &str) -> Result<Tensor> {
        let y = self.blocks.forward_traced(x, tr, &join(path, "blocks"))?;
        self.dec.forward_traced(y, tr, &join(path, "dec"))
    }
}

/// The IRN's outputs: each head's raw tanh values `[N, c, H, W]`, in config order.
#[derive(Clone, Debug)]
pub struct IrnOutput {
    /// `(head name, tensor)` in the configuration's head order.
    pub heads: Vec<(String, Tensor)>,
}

impl IrnOutput {
    /// The output of head `name`.
    pub fn get(&self, name: &str) -> Option<&Tensor> {
        self.heads.iter().find(|(n, _)| n == name).map(|(_, t)| t)
    }
}

/// Intrinsic Render-element Network: a shared encoder, then per head a tower of
/// residual blocks and a decoder.
#[derive(Clone, Debug)]
pub struct Irn {
    config: IrnConfig,
    enc: Encoder,
    heads: Vec<(String, Tower)>,
}

impl Irn {
    /// Builds the IRN of an `irn` weights file (strict: every tensor must be used).
    pub fn load(w: &Weights) -> Result<Self> {
        load_start(w, NetKind::Irn)?;
        let NetConfig::Irn(config) = w.config().clone() else {
            return Err(Error::NetMismatch {
                path: w.path().to_path_buf(),
                expected: NetKind::Irn,
                found: w.config().kind(),
            });
        };
        let opts = options(w.config());
        let enc = Encoder::load(&w.pp("enc"), config.widths, 1, opts)?;
        let mut heads = Vec::with_capacity(config.heads.len());
        for h in &config.heads {
            let p = w.pp("heads").pp(&h.name);
            let tower = Tower {
                blocks: ResBlocks::load(&p.pp("blocks"), config.blocks, config.widths[2], opts)?,
                dec: Decoder::load(&p.pp("dec"), config.widths, h.channels, opts)?,
            };
            heads.push((h.name.clone(), tower));
        }
        w.check_all_used()?;
        Ok(Self { config, enc, heads })
    }

    /// The configuration.
    pub fn config(&self) -> &IrnConfig {
        &self.config
    }
    /// The heads `(name, tower)` in order.
    pub fn heads(&self) -> &[(String, Tower)] {
        &self.heads
    }
    /// Parameters after BatchNorm folding.
    pub fn param_count(&self) -> u64 {
        self.enc.param_count() + self.heads.iter().map(|(_, t)| t.param_count()).sum::<u64>()
    }

    /// Runs the network on a normalised `[N, 3, H, W]` input of any size.
    pub fn forward(&self, x: &Tensor) -> Result<IrnOutput> {
        self.run(x, &mut Tracer::new(None))
    }

    /// As [`Irn::forward`], also pushing intermediate activations (at the padded
    /// size) onto `trace`: `enc.conv_in`, `enc.down.0`, `enc`,
    /// `heads.<name>.blocks.<i>`, `heads.<name>.dec.up.0`, `….up.1`, `….conv_out`.
    pub fn forward_traced(&self, x: &Tensor, trace: &mut Trace) -> Result<IrnOutput> {
        self.run(x, &mut Tracer::new(Some(trace)))
    }
    /// As `forward`, also timing each stage into `timings` (the stages a
    /// trace records; they run one after another, see [`Timings`]).
    pub fn forward_timed(&self, x: &Tensor, timings: &mut Timings) -> Result<IrnOutput> {
        self.run(x, &mut Tracer::timing(timings))
    }

    /// As [`Irn::forward`], running only the heads whose name `keep` accepts
    /// (the encoder always; the outputs in configuration order).
    pub fn forward_heads(&self, x: &Tensor, keep: impl Fn(&str) -> bool) -> Result<IrnOutput> {
        self.run_heads(x, &mut Tracer::new(None), &keep)
    }

    fn run(&self, x: &Tensor, tr: &mut Tracer<'_>) -> Result<IrnOutput> {
        self.run_heads(x, tr, &|_| true)
    }

    fn run_heads(
        &self,
        x: &Tensor,
        tr: &mut Tracer<'_>,
        keep: &dyn Fn(&str) -> bool,
    ) -> Result<IrnOutput> {
        let (xp, pads) = pad_input(NetKind::Irn, x, 3)?;
        let e = self.enc.forward_traced(&xp, tr, "enc")?;
        let towers: Vec<&(String, Tower)> = self.heads.iter().filter(|(n, _)| keep(n)).collect();
        let mut heads = Vec::with_capacity(towers.len());
        if tr.is_recording() || picker_tensor::low_memory() {
            for (name, tower) in towers.iter().map(|h| (&h.0, &h.1)) {
                let y = tower.forward_traced(&e, tr, &format!("heads.{name}"))?;
                heads.push((name.clone(), crop_back(y, pads, x.h(), x.w())?));
            }
        } else {
            // The towers are independent: run them side by side (each layer's
            // kernels still split over the pool), so no thread waits at the
            // end of one small layer for the other. One group of towers per
            // thread, each group's towers one after another: a thread that
            // waits inside a layer can then only pick up kernel tasks or a
            // group not yet started, never a further tower, so at most one
            // tower per thread holds its activations at a time. Results do
            // not depend on the schedule: every kernel's arithmetic is fixed
            // per element.
            use rayon::prelude::*;
            let groups = rayon::current_num_threads().clamp(1, towers.len().max(1));
            let ys: Vec<Vec<Result<Tensor>>> = (0..groups)
                .into_par_iter()
                .map(|g| {
                    towers
                        .iter()
                        .skip(g)
                        .step_by(groups)
                        .map(|(_, tower)| tower.forward_traced(&e, &mut Tracer::new(None), ""))
                        .collect()
                })
                .collect();
            let mut ys: Vec<_> = ys.into_iter().map(Vec::into_iter).collect();
            for (i, (name, _)) in towers.iter().map(|h| (&h.0, &h.1)).enumerate() {
                let y = ys[i % groups].next().expect("one output per head");
                heads.push((name.clone(), crop_back(y?, pads, x.h(), x.w())?));
            }
        }
        Ok(IrnOutput { heads })
    }
}

/// The MSN's output as raw tanh values: the segmentation colours `[N, 3, H, W]`
/// and, from an MSN with 6 output channels, the material embedding
/// `[N, 3, H, W]` (the last three channels; [`MSN_EMBEDDING_CHANNELS`]).
#[derive(Clone, Debug)]
pub struct MsnOutput {
    /// Raw tanh values of the segmentation colours.
    pub segmentation: Tensor,
    /// Raw tanh values of the material embedding: points that the training
    /// put close for pixels of one material and far apart for different
    /// materials; only distances between them mean anything.
    pub embedding: Option<Tensor>,
}

/// Channels of the MSN's material embedding (after its 3 colour channels),
/// when it has one.
pub const MSN_EMBEDDING_CHANNELS: usize = 3;

/// Material Segmentation Network: encoder, residual blocks, decoder.
#[derive(Clone, Debug)]
pub struct Msn {
    config: MsnConfig,
    enc: Encoder,
    blocks: ResBlocks,
    dec: Decoder,
}

impl Msn {
    /// Builds the MSN of an `msn` weights file (strict).
    pub fn load(w: &Weights) -> Result<Self> {
        load_start(w, NetKind::Msn)?;
        let NetConfig::Msn(config) = *w.config() else {
            return Err(Error::NetMismatch {
                path: w.path().to_path_buf(),
                expected: NetKind::Msn,
                found: w.config().kind(),
            });
        };
        let opts = options(w.config());
        let net = Self {
            config,
            enc: Encoder::load(&w.pp("enc"), config.widths, 1, opts)?,
            blocks: ResBlocks::load(&w.pp("blocks"), config.blocks, config.widths[2], opts)?,
            dec: Decoder::load(&w.pp("dec"), config.widths, config.out_channels, opts)?,
        };
        w.check_all_used()?;
        Ok(net)
    }
    /// The configuration.
    pub fn config(&self) -> &MsnConfig {
        &self.config
    }
    /// Parameters after BatchNorm folding.
    pub fn param_count(&self) -> u64 {
        self.enc.param_count() + self.blocks.param_count() + self.dec.param_count()
    }
    /// Runs the network on a normalised `[N, 3, H, W]` input of any size.
    pub fn forward(&self, x: &Tensor) -> Result<MsnOutput> {
        self.run(x, &mut Tracer::new(None))
    }
    /// As [`Msn::forward`], also recording `enc.conv_in`, `enc.down.0`, `enc`,
    /// `blocks.<i>`, `dec.up.0`, `dec.up.1`, `dec.conv_out` (padded size).
    pub fn forward_traced(&self, x: &Tensor, trace: &mut Trace) -> Result<MsnOutput> {
        self.run(x, &mut Tracer::new(Some(trace)))
    }
    /// As `forward`, also timing each stage into `timings` (the stages a
    /// trace records; they run one after another, see [`Timings`]).
    pub fn forward_timed(&self, x: &Tensor, timings: &mut Timings) -> Result<MsnOutput> {
        self.run(x, &mut Tracer::timing(timings))
    }
    fn run(&self, x: &Tensor, tr: &mut Tracer<'_>) -> Result<MsnOutput> {
        let (xp, pads) = pad_input(NetKind::Msn, x, 3)?;
        let e = self.enc.forward_traced(&xp, tr, "enc")?;
        let b = self.blocks.forward_traced(&e, tr, "blocks")?;
        drop(e);
        let y = crop_back(self.dec.forward_traced(b, tr, "dec")?, pads, x.h(), x.w())?;
        if y.c() == 3 {
            return Ok(MsnOutput {
                segmentation: y,
                embedding: None,
            });
        }
        Ok(MsnOutput {
            segmentation: y.channels(0, 3)?,
            embedding: Some(y.channels(3, MSN_EMBEDDING_CHANNELS)?),
        })
    }
}

/// The EnvMap network's output: an equirectangular map `[N, out_channels,
/// max(1, H/8), max(1, W/8)]` of raw tanh values (decode with
/// [`crate::conventions::decode_radiance`]).
#[derive(Clone, Debug)]
pub struct EnvMapOutput {
    /// Raw tanh values.
    pub envmap: Tensor,
}

/// Environment-map network: encoder (first conv stride 2), residual blocks, a
/// tail of three strided convolutions (the last with tanh), bilinear resize.
#[derive(Clone, Debug)]
pub struct EnvMap {
    config: EnvMapConfig,
    enc: Encoder,
    blocks: ResBlocks,
    tail: [ConvBn; 3],
}

impl EnvMap {
    /// Builds the EnvMap network of an `envmap` weights file (strict).
    pub fn load(w: &Weights) -> Result<Self> {
        load_start(w, NetKind::EnvMap)?;
        let NetConfig::EnvMap(config) = *w.config() else {
            return Err(Error::NetMismatch {
                path: w.path().to_path_buf(),
                expected: NetKind::EnvMap,
                found: w.config().kind(),
            });
        };
        let opts = options(w.config());
        let [_, _, w2] = config.widths;
        let [t0, t1] = config.tail_widths;
        let relu = Activation::Relu;
        let tail = w.pp("tail");
        let net = Self {
            config,
            enc: Encoder::load(&w.pp("enc"), config.widths, 2, opts)?,
            blocks: ResBlocks::load(&w.pp("blocks"), config.blocks, w2, opts)?,
            tail: [
                ConvBn::load(&tail.pp(0), ConvSpec::square(w2, t0, 1, 2, 0), opts, relu)?,
                ConvBn::load(&tail.pp(1), ConvSpec::square(t0, t1, 3, 2, 1), opts, relu)?,
                ConvBn::load(
                    &tail.pp(2),
                    ConvSpec::square(t1, config.out_channels, 3, 2, 1),
                    opts,
                    Activation::Tanh,
                )?,
            ],
        };
        w.check_all_used()?;
        Ok(net)
    }
    /// The configuration.
    pub fn config(&self) -> &EnvMapConfig {
        &self.config
    }
    /// Parameters after BatchNorm folding.
    pub fn param_count(&self) -> u64 {
        self.enc.param_count()
            + self.blocks.param_count()
            + self.tail.iter().map(ConvBn::param_count).sum::<u64>()
    }
    /// The output size `(max(1, h/8), max(1, w/8))` for an `h × w` input.
    pub fn output_size(h: usize, w: usize) -> (usize, usize) {
        ((h / 8).max(1), (w / 8).max(1))
    }
    /// Runs the network on a normalised `[N, 3, H, W]` input of any size.
    pub fn forward(&self, x: &Tensor) -> Result<EnvMapOutput> {
        self.run(x, &mut Tracer::new(None))
    }
    /// As [`EnvMap::forward`], also recording `enc.conv_in`, `enc.down.0`, `enc`,
    /// `blocks.<i>`, `tail.0`, `tail.1`, `tail.2` (before the resize).
    pub fn forward_traced(&self, x: &Tensor, trace: &mut Trace) -> Result<EnvMapOutput> {
        self.run(x, &mut Tracer::new(Some(trace)))
    }
    /// As `forward`, also timing each stage into `timings` (the stages a
    /// trace records; they run one after another, see [`Timings`]).
    pub fn forward_timed(&self, x: &Tensor, timings: &mut Timings) -> Result<EnvMapOutput> {
        self.run(x, &mut Tracer::timing(timings))
    }
    fn run(&self, x: &Tensor, tr: &mut Tracer<'_>) -> Result<EnvMapOutput> {
        let (xp, _) = pad_input(NetKind::EnvMap, x, 3)?;
        let e = self.enc.forward_traced(&xp, tr, "enc")?;
        let mut y = self.blocks.forward_traced(&e, tr, "blocks")?;
        for (i, t) in self.tail.iter().enumerate() {
            y = t.forward(&y)?;
            tr.record("tail", &i.to_string(), &y);
        }
        let (oh, ow) = Self::output_size(x.h(), x.w());
        let envmap = if (y.h(), y.w()) == (oh, ow) {
            y
        } else {
            resize_bilinear(&y, oh, ow)?
        };
        Ok(EnvMapOutput { envmap })
    }
}

/// The learned inpainter's output: the filled texture as raw tanh values
/// `[N, channels, H, W]` for every texel (known ones included; callers keep the
/// known texels from their input). Decode with [`crate::conventions::srgb_from_input`].
#[derive(Clone, Debug)]
pub struct InpaintOutput {
    /// Raw tanh values: the texture in `[-1, 1]` (sRGB `v = (y + 1)/2`).
    pub inpainted: Tensor,
}

/// Learned texture inpainter (pix2pix ResnetGenerator-style, as the MSN):
/// encoder with `channels + 1` inputs, residual blocks, decoder with `channels`
/// tanh outputs. The input layout is [`crate::conventions::inpaint_input`]'s.
#[derive(Clone, Debug)]
pub struct Inpaint {
    config: InpaintConfig,
    enc: Encoder,
    blocks: ResBlocks,
    dec: Decoder,
}

impl Inpaint {
    /// Builds the inpainter of an `inpaint` weights file (strict).
    pub fn load(w: &Weights) -> Result<Self> {
        load_start(w, NetKind::Inpaint)?;
        let NetConfig::Inpaint(config) = *w.config() else {
            return Err(Error::NetMismatch {
                path: w.path().to_path_buf(),
                expected: NetKind::Inpaint,
                found: w.config().kind(),
            });
        };
        let opts = options(w.config());
        let net = Self {
            config,
            enc: Encoder::load_with_inputs(
                &w.pp("enc"),
                config.channels + 1,
                config.widths,
                1,
                opts,
            )?,
            blocks: ResBlocks::load(&w.pp("blocks"), config.blocks, config.widths[2], opts)?,
            dec: Decoder::load(&w.pp("dec"), config.widths, config.channels, opts)?,
        };
        w.check_all_used()?;
        Ok(net)
    }
    /// The configuration.
    pub fn config(&self) -> &InpaintConfig {
        &self.config
    }
    /// Parameters after BatchNorm folding.
    pub fn param_count(&self) -> u64 {
        self.enc.param_count() + self.blocks.param_count() + self.dec.param_count()
    }
    /// Runs the network on an `[N, channels + 1, H, W]` input of any size
    /// ([`crate::conventions::inpaint_input`]); mirror-pads like the MSN and crops back.
    pub fn forward(&self, x: &Tensor) -> Result<InpaintOutput> {
        self.run(x, &mut Tracer::new(None))
    }
    /// As [`Inpaint::forward`], also recording `enc.conv_in`, `enc.down.0`, `enc`,
    /// `blocks.<i>`, `dec.up.0`, `dec.up.1`, `dec.conv_out` (padded size).
    pub fn forward_traced(&self, x: &Tensor, trace: &mut Trace) -> Result<InpaintOutput> {
        self.run(x, &mut Tracer::new(Some(trace)))
    }
    /// As `forward`, also timing each stage into `timings` (the stages a
    /// trace records; they run one after another, see [`Timings`]).
    pub fn forward_timed(&self, x: &Tensor, timings: &mut Timings) -> Result<InpaintOutput> {
        self.run(x, &mut Tracer::timing(timings))
    }
    fn run(&self, x: &Tensor, tr: &mut Tracer<'_>) -> Result<InpaintOutput> {
        let (xp, pads) = pad_input(NetKind::Inpaint, x, self.config.channels + 1)?;
        let e = self.enc.forward_traced(&xp, tr, "enc")?;
        let b = self.blocks.forward_traced(&e, tr, "blocks")?;
        drop(e);
        let y = self.dec.forward_traced(b, tr, "dec")?;
        Ok(InpaintOutput {
            inpainted: crop_back(y, pads, x.h(), x.w())?,
        })
    }
}

/// Named outputs of any network: IRN heads by name, MSN `segmentation` (and
/// `embedding` when it has one), EnvMap `envmap`,
/// inpainter `inpainted`.
#[derive(Clone, Debug)]
pub struct NetOutput {
    /// Which network produced them.
    pub kind: NetKind,
    /// `(name, raw tanh values)` in a fixed order.
    pub tensors: Vec<(String, Tensor)>,
}

impl NetOutput {
    /// The output called `name`.
    pub fn get(&self, name: &str) -> Option<&Tensor> {
        self.tensors.iter().find(|(n, _)| n == name).map(|(_, t)| t)
    }
    /// The output names in order.
    pub fn names(&self) -> impl Iterator<Item = &str> {
        self.tensors.iter().map(|(n, _)| n.as_str())
    }
}

impl From<IrnOutput> for NetOutput {
    fn from(o: IrnOutput) -> Self {
        Self {
            kind: NetKind::Irn,
            tensors: o.heads,
        }
    }
}
impl From<MsnOutput> for NetOutput {
    fn from(o: MsnOutput) -> Self {
        Self {
            kind: NetKind::Msn,
            tensors: std::iter::once(("segmentation".to_string(), o.segmentation))
                .chain(o.embedding.map(|e| ("embedding".to_string(), e)))
                .collect(),
        }
    }
}
impl From<EnvMapOutput> for NetOutput {
    fn from(o: EnvMapOutput) -> Self {
        Self {
            kind: NetKind::EnvMap,
            tensors: vec![("envmap".to_string(), o.envmap)],
        }
    }
}
impl From<InpaintOutput> for NetOutput {
    fn from(o: InpaintOutput) -> Self {
        Self {
            kind: NetKind::Inpaint,
            tensors: vec![("inpainted".to_string(), o.inpainted)],
        }
    }
}

/// Any of the networks.
// One `Net` exists per loaded file and the variants hold only layer handles (the
// weights live on the heap), so boxing them would buy nothing.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Debug)]
pub enum Net {
    /// An IRN.
    Irn(Irn),
    /// An MSN.
    Msn(Msn),
    /// An EnvMap network.
    EnvMap(EnvMap),
    /// A learned inpainter.
    Inpaint(Inpaint),
}

impl Net {
    /// Builds the network the file holds (metadata `net`), strictly.
    pub fn load(w: &Weights) -> Result<Self> {
        Ok(match w.kind() {
            NetKind::Irn => Net::Irn(Irn::load(w)?),
            NetKind::Msn => Net::Msn(Msn::load(w)?),
            NetKind::EnvMap => Net::EnvMap(EnvMap::load(w)?),
            NetKind::Inpaint => Net::Inpaint(Inpaint::load(w)?),
        })
    }
    /// Which network.
    pub fn kind(&self) -> NetKind {
        match self {
            Net::Irn(_) => NetKind::Irn,
            Net::Msn(_) => NetKind::Msn,
            Net::EnvMap(_) => NetKind::EnvMap,
            Net::Inpaint(_) => NetKind::Inpaint,
        }
    }
    /// The configuration.
    pub fn config(&self) -> NetConfig {
        match self {
            Net::Irn(n) => n.config().clone().into(),
            Net::Msn(n) => (*n.config()).into(),
            Net::EnvMap(n) => (*n.config()).into(),
            Net::Inpaint(n) => (*n.config()).into(),
        }
    }
    /// Parameters after BatchNorm folding.
    pub fn param_count(&self) -> u64 {
        match self {
            Net::Irn(n) => n.param_count(),
            Net::Msn(n) => n.param_count(),
            Net::EnvMap(n) => n.param_count(),
            Net::Inpaint(n) => n.param_count(),
        }
    }
    /// Runs the network on a normalised `[N, 3, H, W]` input of any size
    /// (the inpainter: `[N, channels + 1, H, W]`, see [`NetConfig::in_channels`]).
    pub fn forward(&self, x: &Tensor) -> Result<NetOutput> {
        Ok(match self {
            Net::Irn(n) => n.forward(x)?.into(),
            Net::Msn(n) => n.forward(x)?.into(),
            Net::EnvMap(n) => n.forward(x)?.into(),
            Net::Inpaint(n) => n.forward(x)?.into(),
        })
    }
    /// As [`Net::forward`], also recording intermediate activations by module path.
    pub fn forward_traced(&self, x: &Tensor, trace: &mut Trace) -> Result<NetOutput> {
        Ok(match self {
            Net::Irn(n) => n.forward_traced(x, trace)?.into(),
            Net::Msn(n) => n.forward_traced(x, trace)?.into(),
            Net::EnvMap(n) => n.forward_traced(x, trace)?.into(),
            Net::Inpaint(n) => n.forward_traced(x, trace)?.into(),
        })
    }
    /// As [`Net::forward`], also timing each stage (see [`Timings`]).
    pub fn forward_timed(&self, x: &Tensor, timings: &mut Timings) -> Result<NetOutput> {
        Ok(match self {
            Net::Irn(n) => n.forward_timed(x, timings)?.into(),
            Net::Msn(n) => n.forward_timed(x, timings)?.into(),
            Net::EnvMap(n) => n.forward_timed(x, timings)?.into(),
            Net::Inpaint(n) => n.forward_timed(x, timings)?.into(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every net makes its Winograd weights per pass by default.
    #[test]
    fn lazy_winograd_weights_by_default() {
        for kind in [
            NetKind::Irn,
            NetKind::Msn,
            NetKind::EnvMap,
            NetKind::Inpaint,
        ] {
            for preset in ["thesis", "lite", "tiny"] {
                let Ok(cfg) = NetConfig::preset(kind, preset) else {
                    continue;
                };
                assert!(options(&cfg).lazy_winograd, "{kind} {preset}");
            }
        }
    }
}
