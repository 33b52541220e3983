//! Cross-crate checks: the same input and weights give the same output bytes,
//! run after run and whatever the thread count (each output element is summed
//! in the same order however the work is split).

use material_picker::nets::{
    metadata_for, random_weights, serialize_safetensors, Net, NetConfig, NetKind, StorageDtype,
    Weights,
};
use material_picker::tensor::Rng;
use std::collections::BTreeMap;
use std::path::Path;

fn load(kind: NetKind, preset: &str, seed: u64) -> Net {
    let cfg = NetConfig::preset(kind, preset).unwrap();
    let meta: BTreeMap<String, String> = metadata_for(&cfg, preset).unwrap();
    let bytes = serialize_safetensors(
        Path::new("memory"),
        &random_weights(&cfg, seed),
        &meta,
        StorageDtype::F32,
    )
    .unwrap();
    Net::load(&Weights::from_bytes("memory", bytes).unwrap()).unwrap()
}

fn bits(net: &Net, x: &material_picker::tensor::Tensor, threads: usize) -> Vec<Vec<u32>> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    let out = pool.install(|| net.forward(x).unwrap());
    out.tensors
        .iter()
        .map(|(_, t)| t.data().iter().map(|v| v.to_bits()).collect())
        .collect()
}

#[test]
fn outputs_are_bit_identical_across_runs_and_thread_counts() {
    for (kind, preset, h, w) in [
        (NetKind::Irn, "tiny", 37, 53),
        (NetKind::Msn, "thesis", 20, 28),
        (NetKind::EnvMap, "thesis", 45, 61),
    ] {
        let net = load(kind, preset, 9);
        let x = Rng::new(4).tensor([1, 3, h, w]);
        let one = bits(&net, &x, 1);
        assert_eq!(one, bits(&net, &x, 1), "{kind:?}: two runs differ");
        assert_eq!(one, bits(&net, &x, 2), "{kind:?}: 1 vs 2 threads differ");
        assert_eq!(one, bits(&net, &x, 3), "{kind:?}: 1 vs 3 threads differ");
    }
}
