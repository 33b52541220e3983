//! The full PyTorch `state_dict` of a configuration (every key, shape and
//! role), and random weights generated from it.

use picker_tensor::Rng;

use crate::config::NetConfig;
use crate::save::NamedTensor;

/// What a state_dict tensor is, for documentation and for [`random_weights`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ParamRole {
    /// A convolution weight `[c_out, c_in, k, k]` (or `[c_in, c_out, k, k]` transposed).
    ConvWeight {
        /// Inputs each output sums over (`c_in·k·k`; `c_in·k·k/4` for the stride-2 transposed convs).
        fan_in: usize,
        /// Extra scale applied to the He-normal draw (0.2 for the second conv of a residual block,
        /// smaller for the output convs so tanh does not saturate).
        gain_scale: Scale,
    },
    /// A convolution bias `[c_out]`.
    ConvBias,
    /// BatchNorm γ (`bn.weight`).
    BnWeight,
    /// BatchNorm β (`bn.bias`).
    BnBias,
    /// BatchNorm running mean.
    BnMean,
    /// BatchNorm running variance.
    BnVar,
    /// BatchNorm batch counter (I64, shape `[]`), ignored by the loader.
    BnCount,
}

/// Extra scale of a random convolution weight.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Scale {
    /// He-normal as is.
    One,
    /// ×0.2: second conv of a residual block.
    Residual,
    /// Output conv followed by tanh, after `blocks` residual blocks: ×0.5/√(1 + blocks),
    /// since the residual stream's spread grows with the number of blocks.
    Output {
        /// Residual blocks before the output.
        blocks: usize,
    },
}

impl Scale {
    fn factor(self) -> f32 {
        match self {
            Scale::One => 1.0,
            Scale::Residual => 0.2,
            Scale::Output { blocks } => 0.5 / (1.0 + blocks as f32).sqrt(),
        }
    }
}

/// One tensor of a state dict: key, shape and role.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ParamSpec {
    /// The full key.
    pub name: String,
    /// The shape (`[]` for the batch counters).
    pub shape: Vec<usize>,
    /// What it is.
    pub role: ParamRole,
}

struct Builder {
    out: Vec<ParamSpec>,
    conv_bias: bool,
}

impl Builder {
    fn push(&mut self, name: String, shape: Vec<usize>, role: ParamRole) {
        self.out.push(ParamSpec { name, shape, role });
    }

    fn bn(&mut self, p: &str, c: usize) {
        self.push(format!("{p}.weight"), vec![c], ParamRole::BnWeight);
        self.push(format!("{p}.bias"), vec![c], ParamRole::BnBias);
        self.push(format!("{p}.running_mean"), vec![c], ParamRole::BnMean);
        self.push(format!("{p}.running_var"), vec![c], ParamRole::BnVar);
        self.push(
            format!("{p}.num_batches_tracked"),
            vec![],
            ParamRole::BnCount,
        );
    }

    fn conv(&mut self, p: &str, cin: usize, cout: usize, k: usize, bias: bool, scale: Scale) {
        let role = ParamRole::ConvWeight {
            fan_in: cin * k * k,
            gain_scale: scale,
        };
        self.push(format!("{p}.weight"), vec![cout, cin, k, k], role);
        if bias {
            self.push(format!("{p}.bias"), vec![cout], ParamRole::ConvBias);
        }
    }

    fn conv_bn(&mut self, p: &str, cin: usize, cout: usize, k: usize, scale: Scale) {
        let b = self.conv_bias;
        self.conv(&format!("{p}.conv"), cin, cout, k, b, scale);
        self.bn(&format!("{p}.bn"), cout);
    }

    fn convt_bn(&mut self, p: &str, cin: usize, cout: usize) {
        let role = ParamRole::ConvWeight {
            fan_in: (cin * 9).div_ceil(4),
            gain_scale: Scale::One,
        };
        self.push(format!("{p}.conv.weight"), vec![cin, cout, 3, 3], role);
        if self.conv_bias {
            self.push(format!("{p}.conv.bias"), vec![cout], ParamRole::ConvBias);
        }
        self.bn(&format!("{p}.bn"), cout);
    }

    fn res_block(&mut self, p: &str, c: usize) {
        let b = self.conv_bias;
        self.conv(&format!("{p}.conv1"), c, c, 3, b, Scale::One);
        self.bn(&format!("{p}.bn1"), c);
        self.conv(&format!("{p}.conv2"), c, c, 3, b, Scale::Residual);
        self.bn(&format!("{p}.bn2"), c);
    }

    fn encoder(&mut self, p: &str, c_in: usize, [w0, w1, w2]: [usize; 3]) {
        self.conv_bn(&format!("{p}.conv_in"), c_in, w0, 7, Scale::One);
        self.conv_bn(&format!("{p}.down.0"), w0, w1, 3, Scale::One);
        self.conv_bn(&format!("{p}.down.1"), w1, w2, 3, Scale::One);
    }

    fn blocks(&mut self, p: &str, n: usize, c: usize) {
        for i in 0..n {
            self.res_block(&format!("{p}.{i}"), c);
        }
    }

    fn decoder(&mut self, p: &str, [w0, w1, w2]: [usize; 3], c: usize, blocks: usize) {
        self.convt_bn(&format!("{p}.up.0"), w2, w1);
        self.convt_bn(&format!("{p}.up.1"), w1, w0);
        self.conv(
            &format!("{p}.conv_out"),
            w0,
            c,
            7,
            true,
            Scale::Output { blocks },
        );
    }
}

/// Every tensor of the PyTorch reference's `state_dict()` for `config`, in
/// `state_dict` order, including the `num_batches_tracked` counters.
pub fn state_dict_spec(config: &NetConfig) -> Vec<ParamSpec> {
    let mut b = Builder {
        out: Vec::new(),
        conv_bias: config.conv_bias(),
    };
    let widths = config.widths();
    b.encoder("enc", config.in_channels(), widths);
    match config {
        NetConfig::Irn(c) => {
            for h in &c.heads {
                b.blocks(&format!("heads.{}.blocks", h.name), c.blocks, widths[2]);
                b.decoder(
                    &format!("heads.{}.dec", h.name),
                    widths,
                    h.channels,
                    c.blocks,
                );
            }
        }
        NetConfig::Msn(c) => {
            b.blocks("blocks", c.blocks, widths[2]);
            b.decoder("dec", widths, c.out_channels, c.blocks);
        }
        NetConfig::Inpaint(c) => {
            b.blocks("blocks", c.blocks, widths[2]);
            b.decoder("dec", widths, c.channels, c.blocks);
        }
        NetConfig::EnvMap(c) => {
            let [t0, t1] = c.tail_widths;
            b.blocks("blocks", c.blocks, widths[2]);
            b.conv_bn("tail.0", widths[2], t0, 1, Scale::One);
            b.conv_bn("tail.1", t0, t1, 3, Scale::One);
            b.conv_bn(
                "tail.2",
                t1,
                c.out_channels,
                3,
                Scale::Output { blocks: c.blocks },
            );
        }
    }
    b.out
}

/// A complete, unfolded random state dict for `config`, deterministic in `seed`
/// (picker_tensor's [`Rng`]): He-normal convolution weights (std √(2/fan_in)),
/// the second conv of each residual block ×0.2, output convs ×0.5/√(1 + blocks)
/// (tanh outputs stay mostly inside (−0.99, 0.99)), conv biases N(0, 0.1²), BatchNorm γ ~ U(0.5, 1.5),
/// β ~ N(0, 0.1²), running mean ~ N(0, 0.1²), running var ~ U(0.5, 1.5), batch
/// counters 0 (I64 scalars). Save it with [`crate::save_safetensors`].
pub fn random_weights(config: &NetConfig, seed: u64) -> Vec<NamedTensor> {
    let mut rng = Rng::new(seed);
    state_dict_spec(config)
        .into_iter()
        .map(|p| {
            let n: usize = p.shape.iter().product();
            let values = match p.role {
                ParamRole::ConvWeight { fan_in, gain_scale } => {
                    let std = (2.0 / fan_in.max(1) as f32).sqrt() * gain_scale.factor();
                    rng.normal_vec(n, std)
                }
                ParamRole::ConvBias | ParamRole::BnBias | ParamRole::BnMean => {
                    rng.normal_vec(n, 0.1)
                }
                ParamRole::BnWeight | ParamRole::BnVar => rng.uniform_vec(n, 0.5, 1.5),
                ParamRole::BnCount => return NamedTensor::i64(p.name, p.shape, vec![0]),
            };
            NamedTensor::f32(p.name, p.shape, values)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::NetKind;

    #[test]
    fn spec_counts_match_param_count() {
        for kind in NetKind::ALL {
            for p in ["thesis", "tiny"] {
                let c = NetConfig::preset(kind, p).unwrap();
                let spec = state_dict_spec(&c);
                // Folded: every conv contributes weights + c_out.
                let folded: u64 = spec
                    .iter()
                    .filter(|s| matches!(s.role, ParamRole::ConvWeight { .. }))
                    .map(|s| {
                        let n: usize = s.shape.iter().product();
                        let cout = if s.name.contains(".up.") {
                            s.shape[1]
                        } else {
                            s.shape[0]
                        };
                        (n + cout) as u64
                    })
                    .sum();
                assert_eq!(folded, c.param_count(), "{kind} {p}");
                let mut names: Vec<_> = spec.iter().map(|s| &s.name).collect();
                names.sort();
                names.dedup();
                assert_eq!(names.len(), spec.len());
            }
        }
    }

    #[test]
    fn random_weights_are_deterministic() {
        let c = NetConfig::preset(NetKind::EnvMap, "tiny").unwrap();
        assert_eq!(random_weights(&c, 3), random_weights(&c, 3));
        assert_ne!(random_weights(&c, 3), random_weights(&c, 4));
    }
}
