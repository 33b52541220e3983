//! Fuzzes the weights loader: arbitrary bytes as a safetensors file.
//!
//! Parsing, metadata checks, every network loader and every tensor read must
//! return `Ok` or an `Err` whose message names the file, and never panic,
//! abort or allocate more than the input justifies.
#![no_main]

use libfuzzer_sys::fuzz_target;
use picker_nets::{EnvMap, Inpaint, Irn, Msn, Net, NetKind, Weights};

const LABEL: &str = "fuzz.safetensors";

fn check_message(e: &picker_nets::Error) {
    let msg = e.to_string();
    assert!(!msg.is_empty());
    let _ = format!("{e:?}");
}

fuzz_target!(|data: &[u8]| {
    let w = match Weights::from_bytes(LABEL, data.to_vec()) {
        Ok(w) => w,
        Err(e) => {
            check_message(&e);
            assert!(
                e.to_string().contains(LABEL),
                "message does not name the file: {e}"
            );
            return;
        }
    };
    let _ = format!("{w:?}");
    let _ = w.dtypes();
    let _ = w.metadata().len();
    let _ = w.config().to_json();
    for preset in ["tiny", "thesis", "lite", "no-such-preset"] {
        if let Err(e) = w.expect_preset(preset) {
            check_message(&e);
        }
    }
    // Every kind's loader: only the file's own kind gets past `expect_kind`.
    for kind in [
        NetKind::Irn,
        NetKind::Msn,
        NetKind::EnvMap,
        NetKind::Inpaint,
    ] {
        let r = match kind {
            NetKind::Irn => Irn::load(&w).map(|n| n.param_count()),
            NetKind::Msn => Msn::load(&w).map(|n| n.param_count()),
            NetKind::EnvMap => EnvMap::load(&w).map(|n| n.param_count()),
            NetKind::Inpaint => Inpaint::load(&w).map(|n| n.param_count()),
        };
        if let Err(e) = r {
            check_message(&e);
        }
    }
    if let Err(e) = Net::load(&w) {
        check_message(&e);
    }
    if let Err(e) = w.check_all_used() {
        check_message(&e);
    }
    // Every tensor with its declared shape, and once with a wrong one.
    let infos: Vec<(String, Vec<usize>)> = w
        .tensors()
        .map(|t| (t.name.to_string(), t.shape.to_vec()))
        .collect();
    for (name, shape) in &infos {
        match w.get(name, shape) {
            Ok(v) => assert_eq!(v.len(), shape.iter().product::<usize>()),
            Err(e) => check_message(&e),
        }
        let mut wrong = shape.clone();
        wrong.push(1);
        assert!(w.get(name, &wrong).is_err());
    }
    if let Err(e) = w.get("no.such.tensor", &[3]) {
        check_message(&e);
    }
});
