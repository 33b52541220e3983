//! Largest output difference between the default algorithms (Winograd for the
//! residual blocks, the direct kernel for the ≤ 4-output convolutions, the
//! pixel tiles for the strided ones on AVX-512, the shifted GEMM for the
//! others), the
//! low-memory Winograd, and the plain packed GEMM for every layer, on random
//! thesis-size networks:
//! `cargo run --release -p picker-nets --example algo_diff -- [HxW]`.

use picker_nets::{
    metadata_for, random_weights, serialize_safetensors, Net, NetConfig, NetKind, StorageDtype,
    Weights,
};
use picker_tensor::Rng;
use std::path::Path;

fn load(bytes: &[u8]) -> Net {
    let weights = Weights::from_bytes("memory", bytes.to_vec()).expect("weights");
    Net::load(&weights).expect("load")
}

fn main() {
    let size = std::env::args().nth(1).unwrap_or_else(|| "240x320".into());
    let (h, w) = size
        .split_once('x')
        .and_then(|(a, b)| Some((a.parse().ok()?, b.parse().ok()?)))
        .expect("size as HxW");
    let x = Rng::new(5).tensor([1, 3, h, w]);
    for kind in [NetKind::Irn, NetKind::Msn, NetKind::EnvMap] {
        let cfg = NetConfig::preset(kind, "thesis").expect("preset");
        let meta = metadata_for(&cfg, "thesis").expect("metadata");
        let bytes = serialize_safetensors(
            Path::new("memory"),
            &random_weights(&cfg, 0),
            &meta,
            StorageDtype::F32,
        )
        .expect("serialise");
        // The algorithm is chosen when a layer is built.
        std::env::set_var("PICKER_CONV", "gemm");
        let gemm = load(&bytes).forward(&x).expect("forward");
        std::env::remove_var("PICKER_CONV");
        let auto = load(&bytes).forward(&x).expect("forward");
        std::env::set_var("PICKER_WINOGRAD_WEIGHTS", "lazy");
        let lazy = load(&bytes).forward(&x).expect("forward");
        std::env::remove_var("PICKER_WINOGRAD_WEIGHTS");
        // bf16 products, where the CPU has them.
        let bf16 = picker_tensor::Precision::Bf16.is_available().then(|| {
            std::env::set_var("PICKER_PRECISION", "bf16");
            let out = load(&bytes).forward(&x).expect("forward");
            std::env::remove_var("PICKER_PRECISION");
            out
        });
        for (i, (((name, a), (_, b)), (_, c))) in gemm
            .tensors
            .iter()
            .zip(&auto.tensors)
            .zip(&lazy.tensors)
            .enumerate()
        {
            let d = a.max_abs_diff(b).expect("same shapes");
            let dl = a.max_abs_diff(c).expect("same shapes");
            let bf = bf16
                .as_ref()
                .map_or("not run (no AVX512_BF16)".to_string(), |o| {
                    let t = &o.tensors[i].1;
                    let mean = a
                        .data()
                        .iter()
                        .zip(t.data())
                        .map(|(p, q)| f64::from((p - q).abs()))
                        .sum::<f64>()
                        / a.data().len() as f64;
                    format!(
                        "max {:.2e}, mean {mean:.2e}",
                        a.max_abs_diff(t).expect("same shapes")
                    )
                });
            println!(
                "{} {name}: max |default - gemm| = {d:.2e}, max |low-memory winograd - gemm| = {dl:.2e}, |bf16 - gemm|: {bf}",
                kind.as_str()
            );
        }
    }
}
