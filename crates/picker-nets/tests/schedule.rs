//! The IRN runs its towers side by side when no activations are recorded:
//! the outputs must be bit-identical to the sequential (traced) run, on any
//! number of threads.

use picker_nets::{
    metadata_for, random_weights, serialize_safetensors, Irn, NetConfig, NetKind, StorageDtype,
    Timings, Trace, Weights,
};
use picker_tensor::Rng;
use std::path::Path;

fn tiny_irn() -> Irn {
    let cfg = NetConfig::preset(NetKind::Irn, "tiny").expect("preset");
    let meta = metadata_for(&cfg, "tiny").expect("metadata");
    let bytes = serialize_safetensors(
        Path::new("memory"),
        &random_weights(&cfg, 3),
        &meta,
        StorageDtype::F32,
    )
    .expect("serialise");
    let w = Weights::from_bytes("memory", bytes).expect("weights");
    Irn::load(&w).expect("load")
}

#[test]
fn parallel_towers_match_the_sequential_run_bit_for_bit() {
    let irn = tiny_irn();
    let x = Rng::new(11).tensor([1, 3, 37, 52]);
    let mut trace = Trace::default();
    let sequential = irn.forward_traced(&x, &mut trace).expect("traced");
    for threads in [1, 2, 3] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("pool");
        let parallel = pool.install(|| irn.forward(&x)).expect("forward");
        assert_eq!(parallel.heads.len(), sequential.heads.len());
        for ((na, a), (nb, b)) in parallel.heads.iter().zip(&sequential.heads) {
            assert_eq!(na, nb, "head order");
            assert_eq!(a.shape(), b.shape(), "{na}");
            assert!(
                a.data()
                    .iter()
                    .zip(b.data())
                    .all(|(p, q)| p.to_bits() == q.to_bits()),
                "{na}: parallel towers differ from the sequential run on {threads} threads"
            );
        }
    }
}

#[test]
fn timed_run_gives_the_same_outputs_and_one_time_per_traced_stage() {
    let irn = tiny_irn();
    let x = Rng::new(12).tensor([1, 3, 29, 40]);
    let mut trace = Trace::default();
    let traced = irn.forward_traced(&x, &mut trace).expect("traced");
    let mut timings = Timings::default();
    let timed = irn.forward_timed(&x, &mut timings).expect("timed");
    for ((na, a), (_, b)) in timed.heads.iter().zip(&traced.heads) {
        assert_eq!(a.data(), b.data(), "{na}");
    }
    // Every traced activation has a stage time, except `enc` (the encoder's
    // output repeats its last stage, `enc.down.1`), and the encoder's
    // `conv_in` and `down.0` and a decoder's `up.1` and `conv_out`, which run
    // fused, each pair timed as one stage.
    let traced_names: Vec<String> = trace
        .iter()
        .map(|(n, _)| n.as_str())
        .filter(|n| *n != "enc" && *n != "enc.conv_in" && !n.ends_with(".dec.up.1"))
        .map(|n| {
            n.replace(".dec.conv_out", ".dec.up.1+conv_out")
                .replace("enc.down.0", "enc.conv_in+down.0")
        })
        .collect();
    let timed_names: Vec<String> = timings.iter().map(|(n, _)| n.clone()).collect();
    assert_eq!(timed_names, traced_names);
    assert!(
        timed_names.contains(&"heads.normals.dec.up.1+conv_out".to_string()),
        "{timed_names:?}"
    );
}
