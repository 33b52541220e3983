//! Network configurations: the JSON stored in a weights file's
//! `__metadata__["config"]`, the presets, validation, parameter and FLOP counts.
//!
//! The key names and presets are those of `docs/contract.md` (shared with the
//! PyTorch reference in `training/`). Parsing refuses unknown keys, and every
//! key is required.

use std::fmt;
use std::str::FromStr;

use picker_tensor::{ConvSpec, ConvTransposeSpec};
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};

/// The preset names this crate knows the configuration of.
pub const KNOWN_PRESETS: [&str; 3] = ["thesis", "lite", "tiny"];

/// Which network: the three of the thesis, plus the learned texture inpainter.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum NetKind {
    /// Intrinsic Render-element Network: shared encoder, one residual tower and decoder per head.
    Irn,
    /// Material Segmentation Network.
    Msn,
    /// Environment-map (lighting) network.
    EnvMap,
    /// Learned texture inpainter (pix2pix ResnetGenerator-style, like the MSN, with the
    /// known-texel mask as an extra input channel).
    Inpaint,
}

impl NetKind {
    /// Every kind, in a fixed order.
    pub const ALL: [NetKind; 4] = [
        NetKind::Irn,
        NetKind::Msn,
        NetKind::EnvMap,
        NetKind::Inpaint,
    ];

    /// The name used in metadata (`net` key) and on the command line: `irn`, `msn`, `envmap`,
    /// `inpaint`.
    pub fn as_str(self) -> &'static str {
        match self {
            NetKind::Irn => "irn",
            NetKind::Msn => "msn",
            NetKind::EnvMap => "envmap",
            NetKind::Inpaint => "inpaint",
        }
    }

    /// The size `(hp, wp)` an `h × w` input is mirror-padded to before the
    /// network runs (contract, "Inputs of any size"): IRN, MSN and the inpainter need
    /// `max(8, ceil4(·))` on each axis, EnvMap `max(16, ·)`.
    pub fn padded_size(self, h: usize, w: usize) -> (usize, usize) {
        match self {
            NetKind::Irn | NetKind::Msn | NetKind::Inpaint => {
                let f = |n: usize| n.div_ceil(4).saturating_mul(4).max(8);
                (f(h), f(w))
            }
            NetKind::EnvMap => (h.max(16), w.max(16)),
        }
    }

    /// Pad widths `[top, bottom, left, right]` taking `h × w` to
    /// [`NetKind::padded_size`]: half (rounded down) before, the rest after.
    pub fn input_pads(self, h: usize, w: usize) -> [usize; 4] {
        let (hp, wp) = self.padded_size(h, w);
        let (t, l) = ((hp - h) / 2, (wp - w) / 2);
        [t, hp - h - t, l, wp - w - l]
    }
}

impl fmt::Display for NetKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl FromStr for NetKind {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        match s {
            "irn" => Ok(NetKind::Irn),
            "msn" => Ok(NetKind::Msn),
            "envmap" => Ok(NetKind::EnvMap),
            "inpaint" => Ok(NetKind::Inpaint),
            _ => Err(Error::UnknownNet {
                found: s.to_string(),
            }),
        }
    }
}

/// One output head of the IRN: its name (a state_dict path component) and channel count.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HeadConfig {
    /// Head name, e.g. `normals`; letters, digits and `_` only.
    pub name: String,
    /// Output channels of the head's decoder.
    pub channels: usize,
}

impl HeadConfig {
    /// A head named `name` with `channels` outputs.
    pub fn new(name: &str, channels: usize) -> Self {
        Self {
            name: name.to_string(),
            channels,
        }
    }
}

/// IRN configuration (contract: `{"widths","blocks","heads","conv_bias","bn_eps"}`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct IrnConfig {
    /// Encoder widths `[w0, w1, w2]`; the residual towers run at `w2`.
    pub widths: [usize; 3],
    /// Residual blocks per head.
    pub blocks: usize,
    /// The heads, in state_dict and output order.
    pub heads: Vec<HeadConfig>,
    /// Whether the convolutions before a BatchNorm have a bias.
    pub conv_bias: bool,
    /// BatchNorm ε.
    pub bn_eps: f64,
}

/// MSN configuration (contract: `{"widths","blocks","out_channels","conv_bias","bn_eps"}`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MsnConfig {
    /// Encoder widths `[w0, w1, w2]`.
    pub widths: [usize; 3],
    /// Residual blocks.
    pub blocks: usize,
    /// Output channels (3: an RGB segmentation colour).
    pub out_channels: usize,
    /// Whether the convolutions before a BatchNorm have a bias.
    pub conv_bias: bool,
    /// BatchNorm ε.
    pub bn_eps: f64,
}

/// EnvMap configuration (contract:
/// `{"widths","blocks","tail_widths","out_channels","conv_bias","bn_eps"}`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EnvMapConfig {
    /// Encoder widths `[w0, w1, w2]` (first conv has stride 2).
    pub widths: [usize; 3],
    /// Residual blocks.
    pub blocks: usize,
    /// Widths `[t0, t1]` of the first two tail convolutions.
    pub tail_widths: [usize; 2],
    /// Output channels (3: RGB radiance).
    pub out_channels: usize,
    /// Whether the convolutions before a BatchNorm have a bias.
    pub conv_bias: bool,
    /// BatchNorm ε.
    pub bn_eps: f64,
}

/// Learned-inpainter configuration (contract:
/// `{"widths","blocks","channels","conv_bias","bn_eps"}`).
///
/// The network is the MSN's Encoder → ResBlocks → Decoder with `channels + 1`
/// inputs (the texture with unknown texels zeroed, then the known mask) and
/// `channels` tanh outputs (the filled texture).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct InpaintConfig {
    /// Encoder widths `[w0, w1, w2]`.
    pub widths: [usize; 3],
    /// Residual blocks.
    pub blocks: usize,
    /// Texture channels (3: RGB); the network reads `channels + 1` planes and writes `channels`.
    pub channels: usize,
    /// Whether the convolutions before a BatchNorm have a bias.
    pub conv_bias: bool,
    /// BatchNorm ε.
    pub bn_eps: f64,
}

/// The six standard IRN heads `(name, channels)`, in the thesis order.
pub const STANDARD_HEADS: [(&str, usize); 6] = [
    ("diffuse_albedo", 3),
    ("specular_albedo", 3),
    ("normals", 3),
    ("glossiness", 1),
    ("view_vector", 3),
    ("uv", 3),
];

fn standard_heads() -> Vec<HeadConfig> {
    STANDARD_HEADS
        .iter()
        .map(|&(n, c)| HeadConfig::new(n, c))
        .collect()
}

impl IrnConfig {
    /// The thesis network (108,856,080 parameters).
    pub fn thesis() -> Self {
        Self {
            widths: [64, 128, 256],
            blocks: 15,
            heads: standard_heads(),
            conv_bias: false,
            bn_eps: 1e-5,
        }
    }
    /// The embedded default (issue 5): 1,506,000 parameters, sized so the three
    /// `lite` nets run in well under 0.5 s at 240×320 on 2 cores and train on a CPU.
    pub fn lite() -> Self {
        Self {
            widths: [16, 32, 64],
            blocks: 3,
            heads: standard_heads(),
            conv_bias: false,
            bn_eps: 1e-5,
        }
    }
    /// The test-sized network of the contract.
    pub fn tiny() -> Self {
        Self {
            widths: [8, 12, 16],
            blocks: 2,
            heads: standard_heads(),
            conv_bias: true,
            bn_eps: 1e-5,
        }
    }
}

impl MsnConfig {
    /// The thesis network (11,378,179 parameters).
    pub fn thesis() -> Self {
        Self {
            widths: [64, 128, 256],
            blocks: 9,
            out_channels: 3,
            conv_bias: false,
            bn_eps: 1e-5,
        }
    }
    /// The embedded default (issue 5); see [`IrnConfig::lite`]. Its 6 output
    /// channels are the segmentation colours and a material embedding
    /// ([`crate::MsnOutput::embedding`]).
    pub fn lite() -> Self {
        Self {
            widths: [24, 48, 96],
            blocks: 4,
            out_channels: 6,
            conv_bias: false,
            bn_eps: 1e-5,
        }
    }
    /// The test-sized network of the contract.
    pub fn tiny() -> Self {
        Self {
            widths: [8, 12, 16],
            blocks: 2,
            out_channels: 3,
            conv_bias: false,
            bn_eps: 1e-5,
        }
    }
}

impl EnvMapConfig {
    /// The thesis network (5,463,427 parameters).
    pub fn thesis() -> Self {
        Self {
            widths: [64, 128, 256],
            blocks: 4,
            tail_widths: [256, 128],
            out_channels: 3,
            conv_bias: false,
            bn_eps: 1e-5,
        }
    }
    /// The embedded default (issue 5); see [`IrnConfig::lite`].
    pub fn lite() -> Self {
        Self {
            widths: [16, 32, 64],
            blocks: 2,
            tail_widths: [64, 32],
            out_channels: 3,
            conv_bias: false,
            bn_eps: 1e-5,
        }
    }
    /// The test-sized network of the contract.
    pub fn tiny() -> Self {
        Self {
            widths: [8, 12, 16],
            blocks: 1,
            tail_widths: [16, 12],
            out_channels: 3,
            conv_bias: true,
            bn_eps: 1e-5,
        }
    }
}

impl InpaintConfig {
    /// The thesis-sized inpainter: pix2pix's `resnet_9blocks` generator at the MSN's widths
    /// (11,381,315 parameters).
    pub fn thesis() -> Self {
        Self {
            widths: [64, 128, 256],
            blocks: 9,
            channels: 3,
            conv_bias: false,
            bn_eps: 1e-5,
        }
    }
    /// The test-sized network of the contract.
    pub fn tiny() -> Self {
        Self {
            widths: [8, 12, 16],
            blocks: 2,
            channels: 3,
            conv_bias: true,
            bn_eps: 1e-5,
        }
    }
}

impl Default for InpaintConfig {
    fn default() -> Self {
        Self::thesis()
    }
}

impl Default for IrnConfig {
    fn default() -> Self {
        Self::thesis()
    }
}
impl Default for MsnConfig {
    fn default() -> Self {
        Self::thesis()
    }
}
impl Default for EnvMapConfig {
    fn default() -> Self {
        Self::thesis()
    }
}

/// The configuration of any of the networks.
#[derive(Clone, Debug, PartialEq)]
pub enum NetConfig {
    /// An IRN.
    Irn(IrnConfig),
    /// An MSN.
    Msn(MsnConfig),
    /// An EnvMap network.
    EnvMap(EnvMapConfig),
    /// A learned inpainter.
    Inpaint(InpaintConfig),
}

impl From<IrnConfig> for NetConfig {
    fn from(c: IrnConfig) -> Self {
        NetConfig::Irn(c)
    }
}
impl From<MsnConfig> for NetConfig {
    fn from(c: MsnConfig) -> Self {
        NetConfig::Msn(c)
    }
}
impl From<EnvMapConfig> for NetConfig {
    fn from(c: EnvMapConfig) -> Self {
        NetConfig::EnvMap(c)
    }
}
impl From<InpaintConfig> for NetConfig {
    fn from(c: InpaintConfig) -> Self {
        NetConfig::Inpaint(c)
    }
}

fn invalid(reason: impl Into<String>) -> Error {
    Error::InvalidConfig {
        reason: reason.into(),
    }
}

/// Largest width or channel count a configuration may have (the thesis nets
/// use 256). The bound keeps parameter and FLOP counts far from overflow and
/// refuses absurd configurations before any allocation.
pub const MAX_WIDTH: usize = 16384;
/// Largest number of residual blocks (per IRN head) a configuration may have.
pub const MAX_BLOCKS: usize = 1024;
/// Largest number of IRN heads.
pub const MAX_HEADS: usize = 64;

fn check_widths(what: &str, widths: &[usize]) -> Result<()> {
    if let Some(i) = widths.iter().position(|&w| w == 0) {
        return Err(invalid(format!(
            "{what}[{i}] is 0; every width must be positive (found {widths:?})"
        )));
    }
    if let Some(i) = widths.iter().position(|&w| w > MAX_WIDTH) {
        return Err(invalid(format!(
            "{what}[{i}] is {}; widths may be at most {MAX_WIDTH} (found {widths:?})",
            widths[i]
        )));
    }
    Ok(())
}

fn check_blocks(blocks: usize) -> Result<()> {
    if blocks > MAX_BLOCKS {
        return Err(invalid(format!(
            "blocks is {blocks}; at most {MAX_BLOCKS} residual blocks are allowed"
        )));
    }
    Ok(())
}

fn check_eps(eps: f64) -> Result<()> {
    if !(eps.is_finite() && eps > 0.0) {
        return Err(invalid(format!(
            "bn_eps must be a positive finite number (found {eps})"
        )));
    }
    Ok(())
}

fn check_channels(what: &str, c: usize) -> Result<()> {
    if c == 0 {
        return Err(invalid(format!("{what} is 0; it must be at least 1")));
    }
    if c > MAX_WIDTH {
        return Err(invalid(format!(
            "{what} is {c}; it may be at most {MAX_WIDTH}"
        )));
    }
    Ok(())
}

impl NetConfig {
    /// The preset `name` (`thesis`, `lite` — not for the inpainter — or `tiny`) of network `kind`.
    pub fn preset(kind: NetKind, name: &str) -> Result<Self> {
        Ok(match (kind, name) {
            (NetKind::Irn, "thesis") => IrnConfig::thesis().into(),
            (NetKind::Irn, "tiny") => IrnConfig::tiny().into(),
            (NetKind::Irn, "lite") => IrnConfig::lite().into(),
            (NetKind::Msn, "lite") => MsnConfig::lite().into(),
            (NetKind::EnvMap, "lite") => EnvMapConfig::lite().into(),
            (NetKind::Msn, "thesis") => MsnConfig::thesis().into(),
            (NetKind::Msn, "tiny") => MsnConfig::tiny().into(),
            (NetKind::EnvMap, "thesis") => EnvMapConfig::thesis().into(),
            (NetKind::EnvMap, "tiny") => EnvMapConfig::tiny().into(),
            (NetKind::Inpaint, "thesis") => InpaintConfig::thesis().into(),
            (NetKind::Inpaint, "tiny") => InpaintConfig::tiny().into(),
            _ => {
                return Err(Error::UnknownPreset {
                    kind,
                    name: name.to_string(),
                })
            }
        })
    }

    /// Which network this configures.
    pub fn kind(&self) -> NetKind {
        match self {
            NetConfig::Irn(_) => NetKind::Irn,
            NetConfig::Msn(_) => NetKind::Msn,
            NetConfig::EnvMap(_) => NetKind::EnvMap,
            NetConfig::Inpaint(_) => NetKind::Inpaint,
        }
    }

    /// Channels of the network input: 3 (normalised RGB) for IRN, MSN and EnvMap,
    /// `channels + 1` for the inpainter (texture planes, then the known mask).
    pub fn in_channels(&self) -> usize {
        match self {
            NetConfig::Inpaint(c) => c.channels + 1,
            NetConfig::Irn(_) | NetConfig::Msn(_) | NetConfig::EnvMap(_) => 3,
        }
    }

    /// Encoder widths `[w0, w1, w2]`.
    pub fn widths(&self) -> [usize; 3] {
        match self {
            NetConfig::Irn(c) => c.widths,
            NetConfig::Msn(c) => c.widths,
            NetConfig::EnvMap(c) => c.widths,
            NetConfig::Inpaint(c) => c.widths,
        }
    }

    /// Residual blocks (IRN: per head).
    pub fn blocks(&self) -> usize {
        match self {
            NetConfig::Irn(c) => c.blocks,
            NetConfig::Msn(c) => c.blocks,
            NetConfig::EnvMap(c) => c.blocks,
            NetConfig::Inpaint(c) => c.blocks,
        }
    }

    /// Whether convolutions before a BatchNorm carry a bias.
    pub fn conv_bias(&self) -> bool {
        match self {
            NetConfig::Irn(c) => c.conv_bias,
            NetConfig::Msn(c) => c.conv_bias,
            NetConfig::EnvMap(c) => c.conv_bias,
            NetConfig::Inpaint(c) => c.conv_bias,
        }
    }

    /// BatchNorm ε.
    pub fn bn_eps(&self) -> f64 {
        match self {
            NetConfig::Irn(c) => c.bn_eps,
            NetConfig::Msn(c) => c.bn_eps,
            NetConfig::EnvMap(c) => c.bn_eps,
            NetConfig::Inpaint(c) => c.bn_eps,
        }
    }

    /// Checks the configuration describes a buildable network: positive
    /// widths and channel counts (at most [`MAX_WIDTH`], at most [`MAX_BLOCKS`]
    /// blocks and [`MAX_HEADS`] heads), a positive finite ε, at least one IRN head,
    /// head names unique and made of letters, digits and `_`.
    pub fn validate(&self) -> Result<()> {
        check_widths("widths", &self.widths())?;
        check_blocks(self.blocks())?;
        check_eps(self.bn_eps())?;
        match self {
            NetConfig::Irn(c) => {
                if c.heads.is_empty() {
                    return Err(invalid("heads is empty; an IRN needs at least one head"));
                }
                if c.heads.len() > MAX_HEADS {
                    return Err(invalid(format!(
                        "{} heads; an IRN may have at most {MAX_HEADS}",
                        c.heads.len()
                    )));
                }
                for (i, h) in c.heads.iter().enumerate() {
                    let ok = !h.name.is_empty()
                        && h.name
                            .chars()
                            .all(|ch| ch.is_ascii_alphanumeric() || ch == '_');
                    if !ok {
                        return Err(invalid(format!(
                            "heads[{i}].name {:?} must be non-empty and use only letters, digits and '_' \
                             (it becomes a state_dict key component)",
                            h.name
                        )));
                    }
                    check_channels(&format!("heads[{i}].channels ({})", h.name), h.channels)?;
                    if c.heads[..i].iter().any(|o| o.name == h.name) {
                        return Err(invalid(format!(
                            "head name {:?} appears more than once; head names must be unique",
                            h.name
                        )));
                    }
                }
            }
            NetConfig::Msn(c) => {
                let with_embedding = 3 + crate::nets::MSN_EMBEDDING_CHANNELS;
                if c.out_channels != 3 && c.out_channels != with_embedding {
                    return Err(invalid(format!(
                        "out_channels is {}; an MSN has 3 (segmentation colours) or {with_embedding} \
                         (colours, then a {}-channel material embedding)",
                        c.out_channels,
                        crate::nets::MSN_EMBEDDING_CHANNELS
                    )));
                }
            }
            NetConfig::EnvMap(c) => {
                check_widths("tail_widths", &c.tail_widths)?;
                check_channels("out_channels", c.out_channels)?;
            }
            NetConfig::Inpaint(c) => check_channels("channels", c.channels)?,
        }
        Ok(())
    }

    /// The configuration as the contract's JSON (the `config` metadata value).
    pub fn to_json(&self) -> String {
        let r = match self {
            NetConfig::Irn(c) => serde_json::to_string(c),
            NetConfig::Msn(c) => serde_json::to_string(c),
            NetConfig::EnvMap(c) => serde_json::to_string(c),
            NetConfig::Inpaint(c) => serde_json::to_string(c),
        };
        // Serialising plain structs of numbers, bools and strings cannot fail.
        r.unwrap_or_default()
    }

    /// Parses and validates the JSON of a `kind` configuration; unknown or missing keys are
    /// refused. The error is [`Error::InvalidConfig`] (callers reading a file wrap it with the path).
    pub fn from_json(kind: NetKind, json: &str) -> Result<Self> {
        let parsed: std::result::Result<NetConfig, serde_json::Error> = match kind {
            NetKind::Irn => serde_json::from_str::<IrnConfig>(json).map(Into::into),
            NetKind::Msn => serde_json::from_str::<MsnConfig>(json).map(Into::into),
            NetKind::EnvMap => serde_json::from_str::<EnvMapConfig>(json).map(Into::into),
            NetKind::Inpaint => serde_json::from_str::<InpaintConfig>(json).map(Into::into),
        };
        let cfg = parsed.map_err(|e| invalid(format!("{kind} config JSON: {e}")))?;
        cfg.validate()?;
        Ok(cfg)
    }

    /// The name of the known preset equal to this configuration, if any.
    pub fn preset_name(&self) -> Option<&'static str> {
        KNOWN_PRESETS
            .into_iter()
            .find(|p| NetConfig::preset(self.kind(), p).is_ok_and(|c| &c == self))
    }

    /// Parameters of the inference network after BatchNorm folding: Σ over all
    /// convolutions of (weights + output channels). Independent of `conv_bias`.
    pub fn param_count(&self) -> u64 {
        let [w0, w1, w2] = self.widths().map(|v| v as u64);
        let conv = |cin: u64, cout: u64, k: u64| cin * cout * k * k + cout;
        let cin = self.in_channels() as u64;
        let encoder = conv(cin, w0, 7) + conv(w0, w1, 3) + conv(w1, w2, 3);
        let block = 2 * conv(w2, w2, 3);
        let decoder = |c: u64| conv(w2, w1, 3) + conv(w1, w0, 3) + conv(w0, c, 7);
        match self {
            NetConfig::Irn(c) => {
                encoder
                    + c.heads
                        .iter()
                        .map(|h| c.blocks as u64 * block + decoder(h.channels as u64))
                        .sum::<u64>()
            }
            NetConfig::Msn(c) => encoder + c.blocks as u64 * block + decoder(c.out_channels as u64),
            NetConfig::Inpaint(c) => encoder + c.blocks as u64 * block + decoder(c.channels as u64),
            NetConfig::EnvMap(c) => {
                let [t0, t1] = c.tail_widths.map(|v| v as u64);
                encoder
                    + c.blocks as u64 * block
                    + conv(w2, t0, 1)
                    + conv(t0, t1, 3)
                    + conv(t1, c.out_channels as u64, 3)
            }
        }
    }

    /// Floating-point operations (2 × multiply-adds of every convolution and
    /// transposed convolution) of one `h × w` image, counted at the size the
    /// image is padded to ([`NetKind::padded_size`]). Padding, activations,
    /// residual sums and the EnvMap resize are not counted. 0 for an empty image.
    pub fn flops(&self, h: usize, w: usize) -> u64 {
        if h == 0 || w == 0 {
            return 0;
        }
        // Past any size a pass could run at, the count saturates.
        if h.max(w) > 1 << 24 {
            return u64::MAX;
        }
        let (hp, wp) = self.kind().padded_size(h, w);
        let [w0, w1, w2] = self.widths();
        let mut total = 0u64;
        let mut conv = |spec: ConvSpec, (h, w): (usize, usize)| -> (usize, usize) {
            total = total.saturating_add(spec.flops(h, w));
            spec.out_hw(h, w).unwrap_or((0, 0))
        };
        let stride0 = if self.kind() == NetKind::EnvMap { 2 } else { 1 };
        let s = conv(
            ConvSpec::square(self.in_channels(), w0, 7, stride0, 0),
            (hp + 6, wp + 6),
        );
        let s = conv(ConvSpec::square(w0, w1, 3, 2, 1), s);
        let enc = conv(ConvSpec::square(w1, w2, 3, 2, 1), s);
        let block = |n: usize, (h, w): (usize, usize)| -> u64 {
            let f = ConvSpec::square(w2, w2, 3, 1, 0).flops(h + 2, w + 2);
            f.saturating_mul(2).saturating_mul(n as u64)
        };
        let decoder = |c: usize, (h, w): (usize, usize)| -> u64 {
            let up0 = ConvTransposeSpec::square(w2, w1, 3, 2, 1, 1);
            let up1 = ConvTransposeSpec::square(w1, w0, 3, 2, 1, 1);
            let (h1, w1_) = up0.out_hw(h, w).unwrap_or((0, 0));
            let (h2, w2_) = up1.out_hw(h1, w1_).unwrap_or((0, 0));
            up0.flops(h, w)
                .saturating_add(up1.flops(h1, w1_))
                .saturating_add(ConvSpec::square(w0, c, 7, 1, 0).flops(h2 + 6, w2_ + 6))
        };
        let rest = match self {
            NetConfig::Irn(c) => c
                .heads
                .iter()
                .map(|hd| block(c.blocks, enc).saturating_add(decoder(hd.channels, enc)))
                .fold(0u64, u64::saturating_add),
            NetConfig::Msn(c) => block(c.blocks, enc).saturating_add(decoder(c.out_channels, enc)),
            NetConfig::Inpaint(c) => block(c.blocks, enc).saturating_add(decoder(c.channels, enc)),
            NetConfig::EnvMap(c) => {
                let [t0, t1] = c.tail_widths;
                let t0s = ConvSpec::square(w2, t0, 1, 2, 0);
                let t1s = ConvSpec::square(t0, t1, 3, 2, 1);
                let t2s = ConvSpec::square(t1, c.out_channels, 3, 2, 1);
                let a = t0s.out_hw(enc.0, enc.1).unwrap_or((0, 0));
                let b = t1s.out_hw(a.0, a.1).unwrap_or((0, 0));
                block(c.blocks, enc)
                    .saturating_add(t0s.flops(enc.0, enc.1))
                    .saturating_add(t1s.flops(a.0, a.1))
                    .saturating_add(t2s.flops(b.0, b.1))
            }
        };
        total.saturating_add(rest)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_at_the_configuration_bounds_do_not_overflow() {
        let heads = (0..MAX_HEADS)
            .map(|i| HeadConfig {
                name: format!("h{i}"),
                channels: MAX_WIDTH,
            })
            .collect();
        let c: NetConfig = IrnConfig {
            widths: [MAX_WIDTH; 3],
            blocks: MAX_BLOCKS,
            heads,
            ..IrnConfig::thesis()
        }
        .into();
        c.validate().unwrap();
        // Exact in u128: encoder + heads × (blocks × 2 convs + decoder).
        let w = MAX_WIDTH as u128;
        let conv = |ci: u128, co: u128, k: u128| ci * co * k * k + co;
        let dec = conv(w, w, 3) + conv(w, w, 3) + conv(w, w, 7);
        let want = conv(3, w, 7)
            + conv(w, w, 3) * 2
            + MAX_HEADS as u128 * (MAX_BLOCKS as u128 * 2 * conv(w, w, 3) + dec);
        assert!(want < u64::MAX as u128);
        assert_eq!(c.param_count() as u128, want);
        // FLOPs saturate instead of wrapping.
        assert_eq!(c.flops(1 << 20, 1 << 20), u64::MAX);
        let mut too_wide = c.clone();
        if let NetConfig::Irn(i) = &mut too_wide {
            i.widths[2] = MAX_WIDTH + 1;
        }
        assert!(too_wide
            .validate()
            .unwrap_err()
            .to_string()
            .contains("at most 16384"));
    }

    #[test]
    fn thesis_parameter_counts() {
        let count = |k| NetConfig::preset(k, "thesis").unwrap().param_count();
        assert_eq!(count(NetKind::Irn), 108_856_080);
        assert_eq!(count(NetKind::Msn), 11_378_179);
        assert_eq!(count(NetKind::EnvMap), 5_463_427);
        // The MSN plus one input plane of the first 7×7 conv (64·49).
        assert_eq!(count(NetKind::Inpaint), 11_378_179 + 64 * 49);
    }

    #[test]
    fn thesis_flops_at_240x320() {
        let flops = |k| NetConfig::preset(k, "thesis").unwrap().flops(240, 320);
        // Exact values; design.md rounds them to 1068 G, 116 G, 13.2 G.
        assert_eq!(flops(NetKind::Irn), 1_068_004_147_200);
        assert_eq!(flops(NetKind::Msn), 116_136_345_600);
        assert_eq!(flops(NetKind::EnvMap), 13_188_111_360);
        // The MSN plus the mask plane of the first conv: 2·64·49·240·320.
        assert_eq!(flops(NetKind::Inpaint), 116_618_035_200);
        // ×4 at 480×640 for IRN and MSN; the EnvMap tail rounds odd sizes up (52.7 G).
        let at = |k| NetConfig::preset(k, "thesis").unwrap().flops(480, 640);
        assert_eq!(at(NetKind::Irn), 4_272_016_588_800);
        assert_eq!(at(NetKind::Msn), 464_545_382_400);
        assert_eq!(at(NetKind::EnvMap), 52_740_648_960);
        assert_eq!(at(NetKind::Inpaint), 466_472_140_800);
    }

    #[test]
    fn flops_count_the_padded_size() {
        let c = NetConfig::preset(NetKind::Msn, "tiny").unwrap();
        assert_eq!(c.flops(1, 1), c.flops(8, 8));
        assert_eq!(c.flops(13, 17), c.flops(16, 20));
        assert_eq!(c.flops(0, 5), 0);
        assert_eq!(c.flops(usize::MAX, usize::MAX), u64::MAX);
        let e = NetConfig::preset(NetKind::EnvMap, "tiny").unwrap();
        assert_eq!(e.flops(3, 3), e.flops(16, 16));
    }

    #[test]
    fn json_round_trip_and_contract_spelling() {
        for kind in NetKind::ALL {
            for p in KNOWN_PRESETS {
                if (kind, p) == (NetKind::Inpaint, "lite") {
                    assert!(NetConfig::preset(kind, p).is_err(), "no lite inpainter");
                    continue;
                }
                let c = NetConfig::preset(kind, p).unwrap();
                let j = c.to_json();
                assert_eq!(NetConfig::from_json(kind, &j).unwrap(), c);
                assert_eq!(c.preset_name(), Some(p));
            }
        }
        // The contract's JSON, verbatim, parses to the presets.
        let contract = [
            (
                NetKind::Irn,
                "thesis",
                r#"{"widths":[64,128,256],"blocks":15,"heads":[{"name":"diffuse_albedo","channels":3},
                {"name":"specular_albedo","channels":3},{"name":"normals","channels":3},
                {"name":"glossiness","channels":1},{"name":"view_vector","channels":3},{"name":"uv","channels":3}],
                "conv_bias":false,"bn_eps":1e-5}"#,
            ),
            (
                NetKind::Msn,
                "thesis",
                r#"{"widths":[64,128,256],"blocks":9,"out_channels":3,"conv_bias":false,"bn_eps":1e-5}"#,
            ),
            (
                NetKind::EnvMap,
                "thesis",
                r#"{"widths":[64,128,256],"blocks":4,"tail_widths":[256,128],"out_channels":3,"conv_bias":false,"bn_eps":1e-5}"#,
            ),
            (
                NetKind::EnvMap,
                "tiny",
                r#"{"widths":[8,12,16],"blocks":1,"tail_widths":[16,12],"out_channels":3,"conv_bias":true,"bn_eps":1e-05}"#,
            ),
            (
                NetKind::Inpaint,
                "thesis",
                r#"{"widths":[64,128,256],"blocks":9,"channels":3,"conv_bias":false,"bn_eps":1e-5}"#,
            ),
            (
                NetKind::Inpaint,
                "tiny",
                r#"{"widths":[8,12,16],"blocks":2,"channels":3,"conv_bias":true,"bn_eps":1e-5}"#,
            ),
        ];
        for (kind, preset, json) in contract {
            assert_eq!(
                NetConfig::from_json(kind, json).unwrap(),
                NetConfig::preset(kind, preset).unwrap()
            );
        }
        assert_eq!(
            NetConfig::preset(NetKind::Msn, "thesis").unwrap().to_json(),
            r#"{"widths":[64,128,256],"blocks":9,"out_channels":3,"conv_bias":false,"bn_eps":0.00001}"#
        );
    }

    #[test]
    fn unknown_and_missing_keys_are_refused() {
        let j = r#"{"widths":[8,12,16],"blocks":2,"out_channels":3,"conv_bias":false,"bn_eps":1e-5,"dropout":0.1}"#;
        let e = NetConfig::from_json(NetKind::Msn, j)
            .unwrap_err()
            .to_string();
        assert!(e.contains("dropout"), "{e}");
        let j = r#"{"widths":[8,12,16],"blocks":2,"conv_bias":false,"bn_eps":1e-5}"#;
        let e = NetConfig::from_json(NetKind::Msn, j)
            .unwrap_err()
            .to_string();
        assert!(e.contains("out_channels"), "{e}");
    }

    #[test]
    fn validation() {
        let mut c = IrnConfig::tiny();
        c.heads.push(HeadConfig::new("normals", 3));
        let e = NetConfig::Irn(c).validate().unwrap_err().to_string();
        assert!(e.contains("more than once"), "{e}");
        let mut c = IrnConfig::tiny();
        c.heads.clear();
        assert!(NetConfig::Irn(c).validate().is_err());
        let mut c = IrnConfig::tiny();
        c.heads[0].name = "a.b".into();
        assert!(NetConfig::Irn(c).validate().is_err());
        let mut c = MsnConfig::tiny();
        c.widths[1] = 0;
        let e = NetConfig::Msn(c).validate().unwrap_err().to_string();
        assert!(e.contains("widths[1]"), "{e}");
        // An MSN outputs 3 colours, or 3 colours and a 3-channel embedding.
        for (out, ok) in [
            (1, false),
            (3, true),
            (4, false),
            (5, false),
            (6, true),
            (7, false),
        ] {
            let mut c = MsnConfig::tiny();
            c.out_channels = out;
            let r = NetConfig::Msn(c).validate();
            assert_eq!(r.is_ok(), ok, "out_channels {out}: {r:?}");
            if let Err(e) = r {
                assert!(e.to_string().contains("out_channels is"), "{e}");
            }
        }
        assert_eq!(MsnConfig::lite().out_channels, 6);
        let mut c = EnvMapConfig::tiny();
        c.bn_eps = 0.0;
        assert!(NetConfig::EnvMap(c).validate().is_err());
        let mut c = EnvMapConfig::tiny();
        c.out_channels = 0;
        assert!(NetConfig::EnvMap(c).validate().is_err());
        let mut c = InpaintConfig::tiny();
        c.channels = 0;
        let e = NetConfig::Inpaint(c).validate().unwrap_err().to_string();
        assert!(e.contains("channels is 0"), "{e}");
        assert!(NetConfig::preset(NetKind::Irn, "huge").is_err());
    }

    #[test]
    fn padding_policy() {
        assert_eq!(NetKind::Irn.padded_size(1, 1), (8, 8));
        assert_eq!(NetKind::Msn.padded_size(13, 240), (16, 240));
        assert_eq!(NetKind::EnvMap.padded_size(13, 240), (16, 240));
        assert_eq!(NetKind::Irn.input_pads(13, 7), [1, 2, 0, 1]);
        assert_eq!(NetKind::EnvMap.input_pads(5, 20), [5, 6, 0, 0]);
        assert_eq!(NetKind::Inpaint.padded_size(13, 240), (16, 240));
        assert_eq!("inpaint".parse::<NetKind>().unwrap(), NetKind::Inpaint);
    }
}
