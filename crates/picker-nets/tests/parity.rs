//! Parity with the PyTorch reference (docs/contract.md).
//!
//! The fixtures in `fixtures/parity/` were made by `training/make_fixtures.py`
//! (PyTorch reference nets of `training/picker_nets.py`, eval mode, float64 on
//! the exact stored weights, rounded to float32); see `fixtures/parity/README.md`
//! for how to regenerate them. Each `<net>_tiny[_dtype].safetensors` is an
//! ordinary weights file; its `_io` companion holds `input` → `out.<name>` with
//! activations `act.<module path>`, and `input_<case>` → `out_<case>.<name>` for
//! inputs that go through the any-size padding.
//!
//! Outputs are compared with `Tolerance::NET_E2E`, activations with
//! `Tolerance::NET_ACTIVATION`; the max abs error of every output is printed
//! (`cargo test -p picker-nets --release --test parity -- --nocapture`).
//! The unfused reference forward of `common` is checked against the same data.
//!
//! `inpaint_tiny` is the learned inpainter (input `[N, 4, H, W]`: texture planes
//! with unknown texels 0, then the known mask ±1; see `training/conventions.py`).

mod common;

use std::path::PathBuf;

use common::{reference_forward, StateDict};
use picker_nets::{Net, NetKind, Weights};
use picker_tensor::{Tensor, Tolerance};

fn fixture(name: &str) -> PathBuf {
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/parity")
        .join(name);
    assert!(
        p.exists(),
        "fixture {} is missing; regenerate with `python -m training.make_fixtures` (see fixtures/parity/README.md)",
        p.display()
    );
    p
}

fn check(what: &str, found: &Tensor, expected: &Tensor, tol: Tolerance) -> f32 {
    assert_eq!(found.shape(), expected.shape(), "{what}: shape");
    if let Err(e) = tol.check(found.data(), expected.data()) {
        panic!("{what}: {e}");
    }
    found.max_abs_diff(expected).unwrap_or(f32::INFINITY)
}

fn parity(weights: &str, io: &str, kind: NetKind, dtype: &str) {
    let w = Weights::open(fixture(weights)).unwrap();
    assert_eq!(w.kind(), kind);
    // The tiny preset, or (the embedding fixture) the tiny MSN with 6 output channels.
    if weights.starts_with("msn_tiny_embed") {
        let picker_nets::NetConfig::Msn(c) = *w.config() else {
            panic!("{weights}: not an MSN")
        };
        assert_eq!(c.out_channels, 6, "{weights}: out_channels");
    } else {
        w.expect_preset("tiny").unwrap();
    }
    assert!(
        w.dtypes().iter().any(|d| d.dtype == dtype),
        "{weights}: expected {dtype} storage, found {:?}",
        w.dtypes()
    );
    let net = Net::load(&w).unwrap();
    let io = StateDict::read(&fixture(io));
    let sd = StateDict::read(&fixture(weights));

    let mut cases: Vec<&String> = io
        .tensors
        .keys()
        .filter(|k| k.starts_with("input"))
        .collect();
    cases.sort();
    assert!(
        cases.iter().any(|c| c.as_str() == "input"),
        "{io:?} lacks `input`",
        io = weights
    );
    let mut outputs_checked = 0;
    let mut acts_checked = 0;
    for case in cases {
        let out_prefix = match case.strip_prefix("input") {
            Some("") => "out.".to_string(),
            Some(rest) => format!("out{rest}."),
            None => unreachable!(),
        };
        let x = io.tensor(case);
        let mut trace = Vec::new();
        let out = net.forward_traced(&x, &mut trace).unwrap();
        let (ref_out, _) = reference_forward(&sd, &x);
        let expected: Vec<&String> = io
            .tensors
            .keys()
            .filter(|k| k.starts_with(&out_prefix))
            .collect();
        assert_eq!(
            expected.len(),
            out.tensors.len(),
            "{weights} {case}: number of outputs"
        );
        for (name, t) in &out.tensors {
            let key = format!("{out_prefix}{name}");
            let exp = io.tensor(&key);
            let err = check(&format!("{weights} {key}"), t, &exp, Tolerance::NET_E2E);
            let rt = &ref_out.iter().find(|(n, _)| n == name).unwrap().1;
            let rerr = check(
                &format!("{weights} {key} (unfused reference)"),
                rt,
                &exp,
                Tolerance::NET_E2E,
            );
            println!(
                "parity {weights:<28} {key:<26} {:?}: max |rust - torch| = {err:.2e}  (unfused reference {rerr:.2e})",
                t.shape()
            );
            outputs_checked += 1;
        }
        if case == "input" {
            for (key, _) in io.tensors.iter().filter(|(k, _)| k.starts_with("act.")) {
                let path = &key["act.".len()..];
                let (_, t) = trace
                    .iter()
                    .find(|(n, _)| n == path)
                    .unwrap_or_else(|| panic!("{weights}: no traced activation {path}"));
                let err = check(
                    &format!("{weights} {key}"),
                    t,
                    &io.tensor(key),
                    Tolerance::NET_ACTIVATION,
                );
                println!(
                    "parity {weights:<28} {key:<26} {:?}: max |rust - torch| = {err:.2e}",
                    t.shape()
                );
                acts_checked += 1;
            }
        }
    }
    assert!(
        outputs_checked >= 2 && acts_checked >= 2,
        "{weights}: too little checked"
    );
}

#[test]
fn irn_tiny_f32() {
    parity(
        "irn_tiny.safetensors",
        "irn_tiny_io.safetensors",
        NetKind::Irn,
        "F32",
    );
}

#[test]
fn msn_tiny_f32() {
    parity(
        "msn_tiny.safetensors",
        "msn_tiny_io.safetensors",
        NetKind::Msn,
        "F32",
    );
}

/// An MSN with a material embedding (6 output channels): `segmentation` and
/// `embedding` against PyTorch's split of the output.
#[test]
fn msn_tiny_embedding_f32() {
    parity(
        "msn_tiny_embed.safetensors",
        "msn_tiny_embed_io.safetensors",
        NetKind::Msn,
        "F32",
    );
}

#[test]
fn envmap_tiny_f32() {
    parity(
        "envmap_tiny.safetensors",
        "envmap_tiny_io.safetensors",
        NetKind::EnvMap,
        "F32",
    );
}

#[test]
fn msn_tiny_f16() {
    parity(
        "msn_tiny_f16.safetensors",
        "msn_tiny_f16_io.safetensors",
        NetKind::Msn,
        "F16",
    );
}

#[test]
fn envmap_tiny_bf16() {
    parity(
        "envmap_tiny_bf16.safetensors",
        "envmap_tiny_bf16_io.safetensors",
        NetKind::EnvMap,
        "BF16",
    );
}

#[test]
fn inpaint_tiny_f32() {
    parity(
        "inpaint_tiny.safetensors",
        "inpaint_tiny_io.safetensors",
        NetKind::Inpaint,
        "F32",
    );
}
