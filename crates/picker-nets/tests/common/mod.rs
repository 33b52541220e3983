//! Shared test helpers: temp files, an independent safetensors reader, and a
//! straightforward **unfused** reference forward of the networks built
//! from `picker_tensor::reference` ops (plain conv + plain BatchNorm + plain
//! pads), written from docs/contract.md. It is a second check of the fast,
//! BatchNorm-folded models, independent of their loading code.
#![allow(dead_code)]

use std::collections::HashMap;
use std::path::PathBuf;

use picker_nets::{NetConfig, NetKind};
use picker_tensor::{reference as r, Activation, BatchNorm, ConvSpec, ConvTransposeSpec, Tensor};
use safetensors::{Dtype, SafeTensors};

/// A unique path in the temp dir; the file is removed when the guard drops.
pub struct TempFile(pub PathBuf);

impl TempFile {
    pub fn new(tag: &str) -> Self {
        use std::sync::atomic::{AtomicUsize, Ordering};
        static N: AtomicUsize = AtomicUsize::new(0);
        let n = N.fetch_add(1, Ordering::Relaxed);
        let name = format!(
            "picker-nets-test-{}-{tag}-{n}.safetensors",
            std::process::id()
        );
        Self(std::env::temp_dir().join(name))
    }
    pub fn path(&self) -> &std::path::Path {
        &self.0
    }
}

impl Drop for TempFile {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}

/// A state dict read with the safetensors crate directly (not through `Weights`).
pub struct StateDict {
    pub tensors: HashMap<String, (Vec<usize>, Vec<f32>)>,
    pub metadata: HashMap<String, String>,
}

impl StateDict {
    pub fn read(path: &std::path::Path) -> Self {
        let bytes = std::fs::read(path).expect("read");
        let st = SafeTensors::deserialize(&bytes).expect("parse");
        let (_, meta) = SafeTensors::read_metadata(&bytes).expect("meta");
        let metadata = meta.metadata().clone().unwrap_or_default();
        let mut tensors = HashMap::new();
        for (name, view) in st.tensors() {
            let d = view.data();
            let v: Vec<f32> = match view.dtype() {
                Dtype::F32 => d
                    .chunks_exact(4)
                    .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
                    .collect(),
                Dtype::F16 => d
                    .chunks_exact(2)
                    .map(|b| half::f16::from_le_bytes([b[0], b[1]]).to_f32())
                    .collect(),
                Dtype::BF16 => d
                    .chunks_exact(2)
                    .map(|b| half::bf16::from_le_bytes([b[0], b[1]]).to_f32())
                    .collect(),
                Dtype::I64 => d
                    .chunks_exact(8)
                    .map(|b| i64::from_le_bytes(b.try_into().unwrap()) as f32)
                    .collect(),
                other => panic!("unexpected dtype {other:?} for {name}"),
            };
            tensors.insert(name, (view.shape().to_vec(), v));
        }
        Self { tensors, metadata }
    }

    pub fn get(&self, key: &str) -> &[f32] {
        &self
            .tensors
            .get(key)
            .unwrap_or_else(|| panic!("state dict lacks {key}"))
            .1
    }

    pub fn tensor(&self, key: &str) -> Tensor {
        let (shape, v) = self.tensors.get(key).unwrap_or_else(|| panic!("no {key}"));
        let mut s = [1usize; 4];
        let off = 4 - shape.len();
        for (i, d) in shape.iter().enumerate() {
            s[off + i] = *d;
        }
        Tensor::new(s, v.clone()).expect("shape")
    }

    pub fn config(&self) -> NetConfig {
        let kind: NetKind = self.metadata["net"].parse().unwrap();
        NetConfig::from_json(kind, &self.metadata["config"]).unwrap()
    }
}

struct Ref<'a> {
    sd: &'a StateDict,
    conv_bias: bool,
    eps: f32,
    trace: Vec<(String, Tensor)>,
}

impl Ref<'_> {
    fn bn(&self, p: &str, x: &Tensor) -> Tensor {
        let bn = BatchNorm {
            gamma: self.sd.get(&format!("{p}.weight")).to_vec(),
            beta: self.sd.get(&format!("{p}.bias")).to_vec(),
            mean: self.sd.get(&format!("{p}.running_mean")).to_vec(),
            var: self.sd.get(&format!("{p}.running_var")).to_vec(),
            eps: self.eps,
        };
        r::batch_norm(x, &bn).unwrap()
    }

    fn conv(&self, p: &str, x: &Tensor, k: usize, stride: usize, pad: usize, bias: bool) -> Tensor {
        let (shape, w) = &self.sd.tensors[&format!("{p}.weight")];
        let spec = ConvSpec::square(shape[1], shape[0], k, stride, pad);
        let b = bias.then(|| self.sd.get(&format!("{p}.bias")));
        r::conv2d(x, w, b, spec).unwrap()
    }

    fn conv_bn(
        &self,
        p: &str,
        x: &Tensor,
        k: usize,
        stride: usize,
        pad: usize,
        act: Activation,
    ) -> Tensor {
        let y = self.conv(&format!("{p}.conv"), x, k, stride, pad, self.conv_bias);
        r::activate(&self.bn(&format!("{p}.bn"), &y), act)
    }

    fn convt_bn(&self, p: &str, x: &Tensor) -> Tensor {
        let (shape, w) = &self.sd.tensors[&format!("{p}.conv.weight")];
        let spec = ConvTransposeSpec::square(shape[0], shape[1], 3, 2, 1, 1);
        let b = self
            .conv_bias
            .then(|| self.sd.get(&format!("{p}.conv.bias")));
        let y = r::conv_transpose2d(x, w, b, spec).unwrap();
        r::activate(&self.bn(&format!("{p}.bn"), &y), Activation::Relu)
    }

    fn res_block(&self, p: &str, x: &Tensor) -> Tensor {
        let h = r::reflect_pad(x, [1; 4]).unwrap();
        let h = self.conv(&format!("{p}.conv1"), &h, 3, 1, 0, self.conv_bias);
        let h = r::activate(&self.bn(&format!("{p}.bn1"), &h), Activation::Relu);
        let h = r::reflect_pad(&h, [1; 4]).unwrap();
        let h = self.conv(&format!("{p}.conv2"), &h, 3, 1, 0, self.conv_bias);
        let h = self.bn(&format!("{p}.bn2"), &h);
        r::add(x, &h).unwrap()
    }

    fn record(&mut self, name: String, t: &Tensor) {
        self.trace.push((name, t.clone()));
    }

    fn encoder(&mut self, x: &Tensor, stride0: usize) -> Tensor {
        let x = r::reflect_pad(x, [3; 4]).unwrap();
        let x = self.conv_bn("enc.conv_in", &x, 7, stride0, 0, Activation::Relu);
        self.record("enc.conv_in".into(), &x);
        let x = self.conv_bn("enc.down.0", &x, 3, 2, 1, Activation::Relu);
        self.record("enc.down.0".into(), &x);
        let x = self.conv_bn("enc.down.1", &x, 3, 2, 1, Activation::Relu);
        self.record("enc".into(), &x);
        x
    }

    fn blocks(&mut self, p: &str, n: usize, mut x: Tensor) -> Tensor {
        for i in 0..n {
            x = self.res_block(&format!("{p}.{i}"), &x);
            self.record(format!("{p}.{i}"), &x);
        }
        x
    }

    fn decoder(&mut self, p: &str, x: &Tensor) -> Tensor {
        let x = self.convt_bn(&format!("{p}.up.0"), x);
        self.record(format!("{p}.up.0"), &x);
        let x = self.convt_bn(&format!("{p}.up.1"), &x);
        self.record(format!("{p}.up.1"), &x);
        let x = r::reflect_pad(&x, [3; 4]).unwrap();
        let y = self.conv(&format!("{p}.conv_out"), &x, 7, 1, 0, true);
        r::activate(&y, Activation::Tanh)
    }
}

/// The contract's any-size padding, written out independently.
fn pads(kind: NetKind, h: usize, w: usize) -> [usize; 4] {
    let target = |n: usize| match kind {
        NetKind::EnvMap => n.max(16),
        _ => (n.div_ceil(4) * 4).max(8),
    };
    let (hp, wp) = (target(h), target(w));
    [
        (hp - h) / 2,
        hp - h - (hp - h) / 2,
        (wp - w) / 2,
        wp - w - (wp - w) / 2,
    ]
}

/// Named tensors.
pub type Named = Vec<(String, Tensor)>;

/// Unfused reference forward: `(named outputs, traced activations)`.
pub fn reference_forward(sd: &StateDict, x: &Tensor) -> (Named, Named) {
    let cfg = sd.config();
    let mut rf = Ref {
        sd,
        conv_bias: cfg.conv_bias(),
        eps: cfg.bn_eps() as f32,
        trace: Vec::new(),
    };
    let (h, w) = (x.h(), x.w());
    let p = pads(cfg.kind(), h, w);
    let xp = r::mirror_pad(x, p);
    let crop = |t: Tensor| t.crop(p[0], p[2], h, w).unwrap();
    let outputs = match &cfg {
        NetConfig::Irn(c) => {
            let e = rf.encoder(&xp, 1);
            let mut outs = Vec::new();
            for hd in &c.heads {
                let b = rf.blocks(&format!("heads.{}.blocks", hd.name), c.blocks, e.clone());
                let y = rf.decoder(&format!("heads.{}.dec", hd.name), &b);
                outs.push((hd.name.clone(), crop(y)));
            }
            outs
        }
        NetConfig::Msn(c) => {
            let e = rf.encoder(&xp, 1);
            let b = rf.blocks("blocks", c.blocks, e);
            let y = crop(rf.decoder("dec", &b));
            if y.c() == 3 {
                vec![("segmentation".to_string(), y)]
            } else {
                // Colours, then the material embedding.
                vec![
                    ("segmentation".to_string(), y.channels(0, 3).unwrap()),
                    ("embedding".to_string(), y.channels(3, y.c() - 3).unwrap()),
                ]
            }
        }
        NetConfig::Inpaint(c) => {
            let e = rf.encoder(&xp, 1);
            let b = rf.blocks("blocks", c.blocks, e);
            let y = rf.decoder("dec", &b);
            vec![("inpainted".to_string(), crop(y))]
        }
        NetConfig::EnvMap(c) => {
            let e = rf.encoder(&xp, 2);
            let b = rf.blocks("blocks", c.blocks, e);
            let t0 = rf.conv_bn("tail.0", &b, 1, 2, 0, Activation::Relu);
            rf.record("tail.0".into(), &t0);
            let t1 = rf.conv_bn("tail.1", &t0, 3, 2, 1, Activation::Relu);
            rf.record("tail.1".into(), &t1);
            let t2 = rf.conv_bn("tail.2", &t1, 3, 2, 1, Activation::Tanh);
            rf.record("tail.2".into(), &t2);
            let y = r::resize_bilinear(&t2, (h / 8).max(1), (w / 8).max(1)).unwrap();
            vec![("envmap".to_string(), y)]
        }
    };
    (outputs, rf.trace)
}

/// Compares `found` to `expected` within `tol`; returns the max abs error or panics with a readable message.
pub fn compare(
    what: &str,
    found: &Tensor,
    expected: &Tensor,
    tol: picker_tensor::Tolerance,
) -> f32 {
    assert_eq!(found.shape(), expected.shape(), "{what}: shape");
    if let Err(e) = tol.check(found.data(), expected.data()) {
        panic!("{what}: {e}");
    }
    found.max_abs_diff(expected).unwrap()
}
