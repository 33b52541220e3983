//! Paired A/B timing of one thesis network built twice, each build under its
//! own environment (the algorithm and its parameters are chosen when a layer
//! is built), the two forward passes alternating in one process so that the
//! host's slow drifts hit both alike:
//! `cargo run --release -p picker-nets --example pair_bench -- NET HxW PAIRS 'A=1 B=2' 'A=3'`
//! (either environment may be empty: `''`). Runs two halves of `PAIRS`
//! pairs, the networks built A first and then B first (the one built second
//! ran ~2 % faster in an A-against-A control), and prints each half's
//! medians and median per-pair ratio B/A, then their geometric mean.

use picker_nets::{
    metadata_for, random_weights, serialize_safetensors, Net, NetConfig, NetKind, StorageDtype,
    Weights,
};
use picker_tensor::Rng;
use std::path::Path;
use std::time::Instant;

/// Builds the network from `bytes` with the `KEY=VALUE` pairs of `env` set,
/// then removes them again.
fn build(bytes: &[u8], env: &str) -> Net {
    let kv: Vec<(&str, &str)> = env
        .split_whitespace()
        .filter_map(|p| p.split_once('='))
        .collect();
    for (k, v) in &kv {
        std::env::set_var(k, v);
    }
    let weights = Weights::from_bytes("memory", bytes.to_vec()).expect("weights");
    let net = Net::load(&weights).expect("load");
    for (k, _) in &kv {
        std::env::remove_var(k);
    }
    net
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [net, size, pairs, a, b] = &args[..] else {
        eprintln!("usage: pair_bench NET HxW PAIRS ENV_A ENV_B");
        std::process::exit(2);
    };
    let kind = match net.as_str() {
        "irn" => NetKind::Irn,
        "msn" => NetKind::Msn,
        "envmap" => NetKind::EnvMap,
        other => panic!("unknown net {other}"),
    };
    let (h, w) = size
        .split_once('x')
        .and_then(|(a, b)| Some((a.parse().ok()?, b.parse().ok()?)))
        .expect("size as HxW");
    let pairs: usize = pairs.parse().expect("PAIRS");
    let cfg = NetConfig::preset(kind, "thesis").expect("preset");
    let meta = metadata_for(&cfg, "thesis").expect("metadata");
    let bytes = serialize_safetensors(
        Path::new("memory"),
        &random_weights(&cfg, 0),
        &meta,
        StorageDtype::F32,
    )
    .expect("serialise");
    let x = Rng::new(5).tensor([1, cfg.in_channels(), h, w]);
    let time = |n: &Net| {
        let t = Instant::now();
        std::hint::black_box(n.forward(&x).expect("forward"));
        t.elapsed().as_secs_f64() * 1e3
    };
    // Two halves, the networks built in either order (in an A-against-A
    // control the one built second ran ~2 % faster), `pairs` each.
    let mut ratios = Vec::new();
    for (half, first_a) in [(1, true), (2, false)] {
        let (na, nb) = if first_a {
            let na = build(&bytes, a);
            (na, build(&bytes, b))
        } else {
            let nb = build(&bytes, b);
            (build(&bytes, a), nb)
        };
        time(&na);
        time(&nb);
        let (mut ta, mut tb, mut r) = (Vec::new(), Vec::new(), Vec::new());
        for i in 0..pairs {
            // Alternate which runs first.
            let (x, y) = if i % 2 == 0 {
                let x = time(&na);
                (x, time(&nb))
            } else {
                let y = time(&nb);
                (time(&na), y)
            };
            ta.push(x);
            tb.push(y);
            r.push(y / x);
        }
        let ratio = median(r);
        ratios.push(ratio);
        println!(
            "{net} {size}, half {half} ({} built first): A [{a}] median {:.2} ms, B [{b}] median {:.2} ms; median ratio B/A {ratio:.3} over {pairs} pairs",
            if first_a { "A" } else { "B" },
            median(ta),
            median(tb),
        );
    }
    println!(
        "{net} {size}: ratio B/A {:.3} (geometric mean of the two halves)",
        (ratios[0] * ratios[1]).sqrt()
    );
}
