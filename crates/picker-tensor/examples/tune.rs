//! Times one layer shape: `cargo run --release -p picker-tensor --example tune -- res`.
use picker_tensor::{Activation, Conv2d, ConvSpec, ConvTranspose2d, ConvTransposeSpec, Rng};
use std::time::Instant;

fn main() {
    let which = std::env::args().nth(1).unwrap_or_else(|| "res".into());
    if which.starts_with("up") {
        let (h, w, s) = if which == "up0" {
            (60, 80, ConvTransposeSpec::square(256, 128, 3, 2, 1, 1))
        } else {
            (120, 160, ConvTransposeSpec::square(128, 64, 3, 2, 1, 1))
        };
        let mut rng = Rng::new(1);
        let wt = rng.normal_vec(s.weight_len(), 0.05);
        let conv = ConvTranspose2d::new(s, &wt, None, Activation::Relu).unwrap();
        let x = rng.tensor([1, s.c_in, h, w]);
        let mut t = vec![];
        for _ in 0..25 {
            let t0 = Instant::now();
            std::hint::black_box(conv.forward(&x).unwrap());
            t.push(t0.elapsed().as_secs_f64());
        }
        t.sort_by(|a, b| a.partial_cmp(b).unwrap());
        let f = s.flops(h, w) as f64;
        println!(
            "{which}: median {:.2} ms ({:.0} GFLOP/s), min {:.2} ms",
            t[12] * 1e3,
            f / t[12] / 1e9,
            t[0] * 1e3
        );
        return;
    }
    let (h, w, s) = match which.as_str() {
        "res" => (62, 82, ConvSpec::square(256, 256, 3, 1, 0)),
        "envres" => (32, 42, ConvSpec::square(256, 256, 3, 1, 0)),
        "decout" => (246, 326, ConvSpec::square(64, 3, 7, 1, 0)),
        "encin" => (246, 326, ConvSpec::square(3, 64, 7, 1, 0)),
        _ => panic!("unknown"),
    };
    let mut rng = Rng::new(1);
    let wt = rng.normal_vec(s.weight_len(), 0.05);
    let conv = Conv2d::new(s, &wt, None, Activation::Relu).unwrap();
    let x = rng.tensor([1, s.c_in, h, w]);
    let mut t = vec![];
    for _ in 0..25 {
        let t0 = Instant::now();
        std::hint::black_box(conv.forward(&x).unwrap());
        t.push(t0.elapsed().as_secs_f64());
    }
    t.sort_by(|a, b| a.partial_cmp(b).unwrap());
    let f = s.flops(h, w) as f64;
    println!(
        "{which}: median {:.2} ms ({:.0} GFLOP/s), min {:.2} ms ({:.0} GFLOP/s)",
        t[12] * 1e3,
        f / t[12] / 1e9,
        t[0] * 1e3,
        f / t[0] / 1e9
    );
}
