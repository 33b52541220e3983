//! Whole-network criterion benchmarks at 240×320 with random weights
//! (`cargo bench --bench nets`; `NETS_BENCH_PRESET=thesis|tiny`, default thesis;
//! IRN thesis takes seconds per pass, so it runs only with `NETS_BENCH_IRN=1`).
//! For same-run comparisons with onnxruntime use `picker bench` and
//! `scripts/ort-anchor/bench_vs_ort.py`.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use material_picker::nets::{
    metadata_for, random_weights, serialize_safetensors, Net, NetConfig, NetKind, StorageDtype,
    Weights,
};
use material_picker::tensor::Rng;
use std::path::Path;

fn bench(c: &mut Criterion) {
    let preset = std::env::var("NETS_BENCH_PRESET").unwrap_or_else(|_| "thesis".into());
    let mut kinds = vec![NetKind::Msn, NetKind::EnvMap];
    if std::env::var_os("NETS_BENCH_IRN").is_some() {
        kinds.insert(0, NetKind::Irn);
    }
    let (h, w) = (240, 320);
    let mut g = c.benchmark_group("net/f32");
    g.sample_size(10);
    for kind in kinds {
        let cfg = NetConfig::preset(kind, &preset).expect("preset");
        let bytes = serialize_safetensors(
            Path::new("memory"),
            &random_weights(&cfg, 0),
            &metadata_for(&cfg, &preset).expect("metadata"),
            StorageDtype::F32,
        )
        .expect("serialise");
        let net = Net::load(&Weights::from_bytes("memory", bytes).expect("weights")).expect("load");
        let x = Rng::new(1).tensor([1, 3, h, w]);
        g.throughput(Throughput::Elements(cfg.flops(h, w)));
        g.bench_function(format!("{}_{preset}/{h}x{w}", kind.as_str()), |b| {
            b.iter(|| net.forward(&x).expect("forward"))
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
