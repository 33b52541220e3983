//! `LearnedInpainter`: loading random `tiny` inpaint weights, running them
//! through the `Inpainter` interface, and refusing files that are not a valid
//! inpainting network with errors that name the file.

use std::path::{Path, PathBuf};

use picker_inpaint::{Error, Image, InpaintOptions, Inpainter, LearnedInpainter};
use picker_nets::{
    metadata_for, random_weights, save_safetensors, NamedTensor, NetConfig, NetKind, StorageDtype,
    TensorData,
};

/// Writes `tensors` of the tiny preset of `kind` (random, seed 5) to `dir/name`,
/// after `edit` changed them.
fn write_tiny(
    dir: &Path,
    name: &str,
    kind: NetKind,
    edit: impl FnOnce(&mut Vec<NamedTensor>),
) -> PathBuf {
    let cfg = NetConfig::preset(kind, "tiny").unwrap();
    let mut tensors = random_weights(&cfg, 5);
    edit(&mut tensors);
    let path = dir.join(name);
    save_safetensors(
        &path,
        &tensors,
        &metadata_for(&cfg, "tiny").unwrap(),
        StorageDtype::F32,
    )
    .unwrap();
    path
}

fn load_err(path: &Path) -> String {
    let e = LearnedInpainter::load(path).expect_err("loading should fail");
    let msg = e.to_string();
    println!("{msg}");
    assert!(
        msg.contains(&path.display().to_string()),
        "message does not name the file: {msg}"
    );
    msg
}

fn assert_has(msg: &str, parts: &[&str]) {
    for p in parts {
        assert!(msg.contains(p), "message lacks {p:?}: {msg}");
    }
}

/// A smooth linear-RGB test texture and a mask with a rectangular hole plus
/// scattered unknown texels.
fn texture(c: usize, h: usize, w: usize) -> (Image, Vec<bool>) {
    let data = (0..c * h * w)
        .map(|i| {
            let (ch, p) = (i / (h * w), i % (h * w));
            let (y, x) = ((p / w) as f32, (p % w) as f32);
            0.5 + 0.4 * (0.7 * x + 0.3 * y + ch as f32).sin()
        })
        .collect();
    let known = (0..h * w)
        .map(|p| {
            let (y, x) = (p / w, p % w);
            let hole = (h / 3..h / 3 + h / 3 + 1).contains(&y) && (w / 4..w / 2 + 1).contains(&x);
            !hole && p % 7 != 3
        })
        .collect();
    (Image::new(c, h, w, data).unwrap(), known)
}

#[test]
fn random_tiny_weights_fill_holes_and_keep_known_texels() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_tiny(dir.path(), "inpaint.safetensors", NetKind::Inpaint, |_| {});
    let inp = LearnedInpainter::load(&path).unwrap();
    assert_eq!(inp.name(), "learned");
    assert_eq!(inp.path(), path.as_path());
    assert_eq!(inp.config().channels, 3);

    for (c, h, w) in [(3, 19, 23), (3, 16, 16), (1, 9, 14), (3, 1, 1), (3, 2, 3)] {
        for toroidal in [false, true] {
            let (image, mut known) = texture(c, h, w);
            if h * w <= 6 {
                // Tiny images: one known texel, the rest unknown.
                known.iter_mut().enumerate().for_each(|(i, k)| *k = i == 0);
            }
            let opts = InpaintOptions {
                toroidal,
                ..InpaintOptions::default()
            };
            let out = inp.inpaint(&image, &known, &opts).unwrap();
            assert_eq!(
                (out.channels, out.height, out.width),
                (c, h, w),
                "shape at {c}x{h}x{w}"
            );
            let n = h * w;
            let mut filled = 0;
            for ch in 0..c {
                for (i, &k) in known.iter().enumerate() {
                    let (a, b) = (out.data[ch * n + i], image.data[ch * n + i]);
                    if k {
                        assert_eq!(a.to_bits(), b.to_bits(), "known texel {i} changed");
                    } else {
                        assert!(
                            a.is_finite() && (0.0..=1.0).contains(&a),
                            "unknown texel {i} filled with {a}"
                        );
                        filled += 1;
                    }
                }
            }
            if n > 1 {
                assert!(filled > 0);
            }
            // Deterministic.
            assert_eq!(inp.inpaint(&image, &known, &opts).unwrap().data, out.data);
        }
    }
}

#[test]
fn toroidal_and_plain_padding_differ_near_the_wrap_edges() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_tiny(dir.path(), "inpaint.safetensors", NetKind::Inpaint, |_| {});
    let inp = LearnedInpainter::load(&path).unwrap();
    let (image, _) = texture(3, 12, 12);
    // Unknown: the first column, next to the wrap edge.
    let known: Vec<bool> = (0..144).map(|p| p % 12 != 0).collect();
    let run = |toroidal| {
        let opts = InpaintOptions {
            toroidal,
            ..InpaintOptions::default()
        };
        inp.inpaint(&image, &known, &opts).unwrap()
    };
    assert_ne!(run(true).data, run(false).data);
    assert_eq!(inp.toroidal_margin(), 16);
    let narrow = inp.clone().with_toroidal_margin(4);
    assert_eq!(narrow.toroidal_margin(), 4);
    narrow
        .inpaint(&image, &known, &InpaintOptions::default())
        .unwrap();
}

#[test]
fn all_known_and_nothing_known() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_tiny(dir.path(), "inpaint.safetensors", NetKind::Inpaint, |_| {});
    let inp = LearnedInpainter::load(&path).unwrap();
    let (image, _) = texture(3, 8, 8);
    let opts = InpaintOptions::default();
    let out = inp.inpaint(&image, &[true; 64], &opts).unwrap();
    assert_eq!(out.data, image.data);
    let e = inp.inpaint(&image, &[false; 64], &opts).unwrap_err();
    assert!(matches!(e, Error::NothingKnown { .. }), "{e}");
    // A 2-channel image does not fit a 3-channel network.
    let (image2, known) = texture(2, 8, 8);
    let msg = inp.inpaint(&image2, &known, &opts).unwrap_err().to_string();
    assert_has(&msg, &["3-channel", "2 channels"]);
}

#[test]
fn other_networks_are_refused_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    for kind in [NetKind::Irn, NetKind::Msn, NetKind::EnvMap] {
        let path = write_tiny(dir.path(), &format!("{kind}.safetensors"), kind, |_| {});
        let msg = load_err(&path);
        assert_has(
            &msg,
            &[&format!("holds {kind} weights"), "needs inpaint weights"],
        );
    }
}

#[test]
fn missing_extra_and_misshaped_tensors_are_refused() {
    let dir = tempfile::tempdir().unwrap();

    let path = write_tiny(dir.path(), "missing.safetensors", NetKind::Inpaint, |t| {
        t.retain(|t| t.name != "blocks.1.bn2.running_var");
    });
    let msg = load_err(&path);
    assert_has(
        &msg,
        &["missing tensor", "\"blocks.1.bn2.running_var\"", "[16]"],
    );

    let path = write_tiny(dir.path(), "extra.safetensors", NetKind::Inpaint, |t| {
        t.push(NamedTensor::f32(
            "discriminator.conv.weight",
            vec![2],
            vec![0.0; 2],
        ));
    });
    let msg = load_err(&path);
    assert_has(&msg, &["1 unused tensor(s)", "discriminator.conv.weight"]);

    // An MSN-style 3-plane first convolution: the mask plane is missing.
    let path = write_tiny(dir.path(), "shape.safetensors", NetKind::Inpaint, |t| {
        let x = t
            .iter_mut()
            .find(|t| t.name == "enc.conv_in.conv.weight")
            .unwrap();
        x.shape = vec![8, 3, 7, 7];
        x.data = TensorData::F32(vec![0.1; 8 * 3 * 49]);
    });
    let msg = load_err(&path);
    assert_has(
        &msg,
        &[
            "\"enc.conv_in.conv.weight\"",
            "[8, 3, 7, 7]",
            "expected [8, 4, 7, 7]",
        ],
    );

    // Not a weights file at all.
    let path = dir.path().join("junk.safetensors");
    std::fs::write(&path, b"not safetensors").unwrap();
    load_err(&path);
}
