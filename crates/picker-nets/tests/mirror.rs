//! The IRN's head selection and its mirror pass on a real (random, `tiny`)
//! network: `forward_heads` gives the chosen heads bit for bit as `forward`
//! does, and `Irn::forward_mirrored`, which skips the texture coordinates'
//! tower in the mirrored pass, gives what merging two full passes gives.

mod common;

use common::TempFile;
use picker_nets::mirror::MergeMirrored;
use picker_nets::{
    metadata_for, random_weights, save_safetensors, Irn, NetConfig, NetKind, StorageDtype, Weights,
};
use picker_tensor::Rng;

fn tiny_irn(seed: u64) -> (TempFile, Irn) {
    let cfg = NetConfig::preset(NetKind::Irn, "tiny").unwrap();
    let f = TempFile::new("irn-mirror");
    save_safetensors(
        f.path(),
        &random_weights(&cfg, seed),
        &metadata_for(&cfg, "tiny").unwrap(),
        StorageDtype::F32,
    )
    .unwrap();
    let irn = Irn::load(&Weights::open(f.path()).unwrap()).unwrap();
    (f, irn)
}

#[test]
fn forward_heads_and_the_mirror_pass_match_full_passes() {
    let (_f, irn) = tiny_irn(3);
    let mut rng = Rng::new(17);
    for shape in [[1, 3, 16, 20], [1, 3, 13, 21], [1, 3, 1, 1]] {
        let x = rng.tensor(shape);
        let full = irn.forward(&x).unwrap();
        let some = irn.forward_heads(&x, |n| n != "uv").unwrap();
        assert_eq!(some.heads.len(), full.heads.len() - 1, "{shape:?}");
        assert!(some.get("uv").is_none());
        for (name, t) in &some.heads {
            assert!(full.get(name).unwrap() == t, "{shape:?} {name}");
        }
        assert_eq!(irn.forward_heads(&x, |_| false).unwrap().heads.len(), 0);

        let xm = x.mirror_w();
        let merged = full
            .clone()
            .merge_mirrored(&irn.forward(&xm).unwrap())
            .unwrap();
        let pass = irn.forward_mirrored(&x, Some(&xm)).unwrap();
        assert_eq!(pass.heads.len(), merged.heads.len());
        for ((a, s), (b, t)) in pass.heads.iter().zip(&merged.heads) {
            assert_eq!(a, b);
            assert!(s == t, "{shape:?} {a}");
        }
        let once = irn.forward_mirrored(&x, None).unwrap();
        for ((_, s), (_, t)) in once.heads.iter().zip(&full.heads) {
            assert!(s == t);
        }
    }
}
