//! Broken weights files are refused with messages that name the file and say
//! what is wrong (key, expected, found).

mod common;

use std::borrow::Cow;
use std::collections::{BTreeMap, HashMap};

use common::TempFile;
use picker_nets::{
    metadata_for, random_weights, save_safetensors, EnvMap, Error, Irn, Msn, NamedTensor, Net,
    NetConfig, NetKind, StorageDtype, TensorData, Weights,
};
use safetensors::Dtype;

fn tiny(kind: NetKind) -> (NetConfig, Vec<NamedTensor>, BTreeMap<String, String>) {
    let cfg = NetConfig::preset(kind, "tiny").unwrap();
    let t = random_weights(&cfg, 99);
    let m = metadata_for(&cfg, "tiny").unwrap();
    (cfg, t, m)
}

fn save(tag: &str, t: &[NamedTensor], m: &BTreeMap<String, String>) -> TempFile {
    let f = TempFile::new(tag);
    save_safetensors(f.path(), t, m, StorageDtype::F32).unwrap();
    f
}

/// Opens and builds the net; returns the error message (which must name the file).
fn load_err(f: &TempFile) -> (Error, String) {
    let e = match Weights::open(f.path()) {
        Err(e) => e,
        Ok(w) => Net::load(&w).expect_err("loading should fail"),
    };
    let msg = e.to_string();
    println!("{msg}");
    assert!(
        msg.contains(&f.path().display().to_string()),
        "message does not name the file: {msg}"
    );
    (e, msg)
}

fn assert_has(msg: &str, parts: &[&str]) {
    for p in parts {
        assert!(msg.contains(p), "message lacks {p:?}: {msg}");
    }
}

struct Raw {
    dtype: Dtype,
    shape: Vec<usize>,
    bytes: Vec<u8>,
}

impl safetensors::View for &Raw {
    fn dtype(&self) -> Dtype {
        self.dtype
    }
    fn shape(&self) -> &[usize] {
        &self.shape
    }
    fn data(&self) -> Cow<'_, [u8]> {
        Cow::Borrowed(&self.bytes)
    }
    fn data_len(&self) -> usize {
        self.bytes.len()
    }
}

/// Writes tensors as F32/I64, except `key` which is written as `dtype` with raw `bytes`.
fn save_with_dtype(
    tag: &str,
    t: &[NamedTensor],
    m: &BTreeMap<String, String>,
    key: &str,
    dtype: Dtype,
) -> TempFile {
    let raws: Vec<(String, Raw)> = t
        .iter()
        .map(|t| {
            let n = t.shape.iter().product::<usize>();
            let raw = match (&t.data, t.name == key) {
                (_, true) => Raw {
                    dtype,
                    shape: t.shape.clone(),
                    bytes: vec![0u8; n * dtype.size()],
                },
                (TensorData::F32(v), _) => Raw {
                    dtype: Dtype::F32,
                    shape: t.shape.clone(),
                    bytes: v.iter().flat_map(|x| x.to_le_bytes()).collect(),
                },
                (TensorData::I64(v), _) => Raw {
                    dtype: Dtype::I64,
                    shape: t.shape.clone(),
                    bytes: v.iter().flat_map(|x| x.to_le_bytes()).collect(),
                },
            };
            (t.name.clone(), raw)
        })
        .collect();
    let meta: HashMap<String, String> = m.clone().into_iter().collect();
    let bytes =
        safetensors::serialize(raws.iter().map(|(k, r)| (k.as_str(), r)), &Some(meta)).unwrap();
    let f = TempFile::new(tag);
    std::fs::write(f.path(), bytes).unwrap();
    f
}

#[test]
fn missing_tensor() {
    let (_, mut t, m) = tiny(NetKind::Msn);
    t.retain(|t| t.name != "blocks.1.bn2.running_var");
    let f = save("missing", &t, &m);
    let (e, msg) = load_err(&f);
    assert!(matches!(e, Error::MissingTensor { .. }));
    assert_has(
        &msg,
        &["missing tensor", "\"blocks.1.bn2.running_var\"", "[16]"],
    );
}

#[test]
fn missing_conv_bias_when_config_says_conv_bias() {
    let (_, mut t, m) = tiny(NetKind::EnvMap);
    t.retain(|t| t.name != "tail.1.conv.bias");
    let (_, msg) = load_err(&save("nobias", &t, &m));
    assert_has(&msg, &["\"tail.1.conv.bias\"", "conv_bias=true"]);
}

#[test]
fn extra_tensor() {
    let (_, mut t, m) = tiny(NetKind::EnvMap);
    t.push(NamedTensor::f32(
        "tail.3.conv.weight",
        vec![2, 2],
        vec![0.0; 4],
    ));
    t.push(NamedTensor::f32("optimizer.lr", vec![1], vec![0.1]));
    let (e, msg) = load_err(&save("extra", &t, &m));
    assert!(matches!(e, Error::UnusedTensors { count: 2, .. }));
    assert_has(
        &msg,
        &["2 unused tensor(s)", "optimizer.lr", "tail.3.conv.weight"],
    );
}

#[test]
fn conv_bias_present_but_config_says_none() {
    // MSN tiny has conv_bias=false: IRN-style conv biases are unused, with a hint.
    let (cfg, mut t, m) = tiny(NetKind::Msn);
    assert!(!cfg.conv_bias());
    t.push(NamedTensor::f32(
        "enc.conv_in.conv.bias",
        vec![8],
        vec![0.0; 8],
    ));
    let (_, msg) = load_err(&save("bias", &t, &m));
    assert_has(&msg, &["enc.conv_in.conv.bias", "conv_bias=false"]);
}

#[test]
fn wrong_shape() {
    let (_, mut t, m) = tiny(NetKind::Irn);
    let x = t
        .iter_mut()
        .find(|t| t.name == "heads.normals.blocks.1.conv2.weight")
        .unwrap();
    x.shape = vec![16, 16, 9];
    let (e, msg) = load_err(&save("shape", &t, &m));
    assert!(matches!(e, Error::ShapeMismatch { .. }));
    assert_has(
        &msg,
        &[
            "\"heads.normals.blocks.1.conv2.weight\"",
            "[16, 16, 9]",
            "expected [16, 16, 3, 3]",
        ],
    );
}

#[test]
fn wrong_dtype() {
    for dtype in [Dtype::I32, Dtype::F64, Dtype::U8] {
        let (_, t, m) = tiny(NetKind::Msn);
        let f = save_with_dtype("dtype", &t, &m, "dec.conv_out.weight", dtype);
        let (e, msg) = load_err(&f);
        assert!(matches!(e, Error::Dtype { .. }));
        assert_has(
            &msg,
            &[
                "\"dec.conv_out.weight\"",
                &format!("{dtype:?}"),
                "accepted: F32, F16 or BF16",
            ],
        );
    }
    // A batch counter must be an I64 scalar.
    let (_, t, m) = tiny(NetKind::Msn);
    let f = save_with_dtype(
        "counter",
        &t,
        &m,
        "enc.down.0.bn.num_batches_tracked",
        Dtype::F32,
    );
    let (_, msg) = load_err(&f);
    assert_has(&msg, &["enc.down.0.bn.num_batches_tracked", "F32", "I64"]);
}

#[test]
fn truncated_file() {
    let (_, t, m) = tiny(NetKind::Msn);
    let f = save("trunc", &t, &m);
    let len = std::fs::metadata(f.path()).unwrap().len();
    let file = std::fs::OpenOptions::new()
        .write(true)
        .open(f.path())
        .unwrap();
    file.set_len(len - 100).unwrap();
    drop(file);
    let (e, msg) = load_err(&f);
    assert!(matches!(e, Error::Truncated { .. }), "{e:?}");
    assert_has(
        &msg,
        &[
            "truncated",
            &format!("{len} bytes"),
            &format!("{}", len - 100),
        ],
    );
    // Cut inside the header.
    let file = std::fs::OpenOptions::new()
        .write(true)
        .open(f.path())
        .unwrap();
    file.set_len(50).unwrap();
    drop(file);
    let (_, msg) = load_err(&f);
    assert_has(&msg, &["not a valid safetensors file", "header length"]);
}

#[test]
fn garbage_headers() {
    let cases: Vec<(&str, Vec<u8>, &str)> = vec![
        ("empty", vec![], "0 bytes"),
        ("tiny", b"abc".to_vec(), "3 bytes"),
        (
            "png",
            b"\x89PNG\r\n\x1a\n\0\0\0\rIHDR garbage garbage".to_vec(),
            "header length",
        ),
        (
            "notjson",
            {
                let mut v = 12u64.to_le_bytes().to_vec();
                v.extend_from_slice(b"{not json!!}");
                v
            },
            "not valid JSON",
        ),
        (
            "badentry",
            {
                let h = br#"{"a":{"dtype":"F32","shape":[2],"offsets":[0,8]}}"#;
                let mut v = (h.len() as u64).to_le_bytes().to_vec();
                v.extend_from_slice(h);
                v.extend_from_slice(&[0; 8]);
                v
            },
            "\"a\"",
        ),
        (
            "badsize",
            {
                let h = br#"{"a":{"dtype":"F32","shape":[3],"data_offsets":[0,8]}}"#;
                let mut v = (h.len() as u64).to_le_bytes().to_vec();
                v.extend_from_slice(h);
                v.extend_from_slice(&[0; 8]);
                v
            },
            "does not match its dtype and shape",
        ),
    ];
    for (tag, bytes, part) in cases {
        let f = TempFile::new(tag);
        std::fs::write(f.path(), &bytes).unwrap();
        let (e, msg) = load_err(&f);
        assert!(matches!(e, Error::Header { .. }), "{tag}: {e:?}");
        assert_has(&msg, &[part]);
    }
}

#[test]
fn wrong_net() {
    let (_, t, m) = tiny(NetKind::Msn);
    let f = save("wrongnet", &t, &m);
    let w = Weights::open(f.path()).unwrap();
    let msg = Irn::load(&w).unwrap_err().to_string();
    assert_has(
        &msg,
        &[
            &f.path().display().to_string(),
            "holds msn weights",
            "irn weights were asked for",
        ],
    );
    assert!(EnvMap::load(&w).is_err());
    assert!(Msn::load(&w).is_ok());
    // metadata `net` says irn but the tensors are an MSN's.
    let mut m2 = m.clone();
    m2.insert("net".into(), "irn".into());
    m2.insert(
        "config".into(),
        NetConfig::preset(NetKind::Irn, "tiny").unwrap().to_json(),
    );
    let (_, msg) = load_err(&save("mislabelled", &t, &m2));
    assert_has(&msg, &["missing tensor \"enc.conv_in.conv.bias\""]);
}

#[test]
fn metadata_errors() {
    let (_, t, m) = tiny(NetKind::Msn);
    type Edit = Box<dyn Fn(&mut BTreeMap<String, String>)>;
    let cases: Vec<(&str, Edit, Vec<&str>)> = vec![
        (
            "version",
            Box::new(|m| {
                m.insert("format_version".into(), "2".into());
            }),
            vec!["unsupported format_version \"2\"", "version \"1\""],
        ),
        (
            "format",
            Box::new(|m| {
                m.insert("format".into(), "pt".into());
            }),
            vec!["\"format\"", "\"material-picker\"", "\"pt\""],
        ),
        (
            "nonet",
            Box::new(|m| {
                m.remove("net");
            }),
            vec!["\"net\" is missing"],
        ),
        (
            "noconfig",
            Box::new(|m| {
                m.remove("config");
            }),
            vec!["\"config\" is missing"],
        ),
        (
            "nometa",
            Box::new(|m| m.clear()),
            vec!["\"format\" is missing"],
        ),
        (
            "badnet",
            Box::new(|m| {
                m.insert("net".into(), "unet".into());
            }),
            vec!["\"unet\"", "\"envmap\""],
        ),
        (
            "badjson",
            Box::new(|m| {
                m.insert("config".into(), "{widths:".into());
            }),
            vec!["\"config\"", "JSON"],
        ),
        (
            "unknownkey",
            Box::new(|m| {
                m.insert("config".into(),
                r#"{"widths":[8,12,16],"blocks":2,"out_channels":3,"conv_bias":false,"bn_eps":1e-5,"dropout":0.5}"#.into());
            }),
            vec!["\"config\"", "unknown field `dropout`"],
        ),
        (
            "zerowidth",
            Box::new(|m| {
                m.insert("config".into(),
                r#"{"widths":[8,0,16],"blocks":2,"out_channels":3,"conv_bias":false,"bn_eps":1e-5}"#.into());
            }),
            vec!["\"config\"", "widths[1] is 0"],
        ),
        (
            "presetlabel",
            Box::new(|m| {
                m.insert("preset".into(), "thesis".into());
            }),
            vec!["\"preset\"", "says \"thesis\"", "custom"],
        ),
    ];
    for (tag, edit, parts) in cases {
        let mut m2 = m.clone();
        edit(&mut m2);
        let (e, msg) = load_err(&save(tag, &t, &m2));
        assert!(
            matches!(
                e,
                Error::InvalidMetadata { .. }
                    | Error::MissingMetadata { .. }
                    | Error::UnsupportedVersion { .. }
            ),
            "{tag}: {e:?}"
        );
        assert_has(&msg, &parts);
    }
    // Free-form keys and labels that name no preset are fine.
    let mut m2 = m.clone();
    m2.insert("training.epochs".into(), "40".into());
    m2.insert("preset".into(), "my-experiment".into());
    let w = Weights::open(save("freeform", &t, &m2).path()).unwrap();
    assert_eq!(w.preset(), "my-experiment");
    // `lite` is a preset now: a file labelled so must have its configuration.
    m2.insert("preset".into(), "lite".into());
    let e = Weights::open(save("not_lite", &t, &m2).path()).unwrap_err();
    assert_has(
        &e.to_string(),
        &["says \"lite\"", "differs from that preset"],
    );
}

#[test]
fn config_mismatch() {
    let (_, t, m) = tiny(NetKind::EnvMap);
    let f = save("cfg", &t, &m);
    let w = Weights::open(f.path()).unwrap();
    w.expect_preset("tiny").unwrap();
    let msg = w.expect_preset("thesis").unwrap_err().to_string();
    assert_has(
        &msg,
        &[
            &f.path().display().to_string(),
            "config mismatch",
            "preset \"thesis\"",
            "[8,12,16]",
        ],
    );
    let msg = w
        .expect_config(&NetConfig::preset(NetKind::Irn, "tiny").unwrap())
        .unwrap_err()
        .to_string();
    assert_has(&msg, &["holds envmap weights"]);
}

#[test]
fn bad_values() {
    let (_, mut t, m) = tiny(NetKind::Msn);
    if let TensorData::F32(v) = &mut t
        .iter_mut()
        .find(|t| t.name == "blocks.0.conv1.weight")
        .unwrap()
        .data
    {
        v[5] = f32::NAN;
    }
    let (e, msg) = load_err(&save("nan", &t, &m));
    assert!(matches!(e, Error::NonFinite { index: 5, .. }));
    assert_has(&msg, &["\"blocks.0.conv1.weight\"", "NaN"]);
    let (_, mut t, m) = tiny(NetKind::Msn);
    if let TensorData::F32(v) = &mut t
        .iter_mut()
        .find(|t| t.name == "dec.up.1.bn.running_var")
        .unwrap()
        .data
    {
        v[2] = -0.5;
    }
    let (_, msg) = load_err(&save("negvar", &t, &m));
    assert_has(&msg, &["\"dec.up.1.bn.running_var\"", "negative"]);
}

#[test]
fn prefixed_keys_get_a_hint() {
    let (_, mut t, m) = tiny(NetKind::EnvMap);
    for x in &mut t {
        x.name = format!("module.{}", x.name);
    }
    let (_, msg) = load_err(&save("prefixed", &t, &m));
    assert_has(
        &msg,
        &[
            "missing tensor \"enc.conv_in.conv.weight\"",
            "strip the key prefix \"module.\"",
        ],
    );
}

#[test]
fn save_errors_name_the_path_and_leave_nothing_behind() {
    let (cfg, t, m) = tiny(NetKind::Msn);
    let dir = std::env::temp_dir().join(format!("picker-nets-no-such-dir-{}", std::process::id()));
    let path = dir.join("x.safetensors");
    let msg = save_safetensors(&path, &t, &m, StorageDtype::F32)
        .unwrap_err()
        .to_string();
    assert_has(&msg, &[&path.display().to_string(), "cannot"]);
    assert!(!dir.exists());
    // Overwrite is atomic: the old file stays readable until the rename, no temp file remains.
    let f = save("atomic", &t, &m);
    save_safetensors(f.path(), &random_weights(&cfg, 5), &m, StorageDtype::BF16).unwrap();
    let w = Weights::open(f.path()).unwrap();
    assert_eq!(w.dtypes()[0].dtype, "BF16");
    let parent = f.path().parent().unwrap();
    let name = f.path().file_name().unwrap().to_string_lossy().into_owned();
    let leftovers: Vec<_> = std::fs::read_dir(parent)
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| {
            e.file_name()
                .to_string_lossy()
                .starts_with(&format!(".{name}.tmp-"))
        })
        .collect();
    assert!(leftovers.is_empty());
    // Inconsistent tensors are refused before anything is written.
    let bad = vec![NamedTensor::f32("a", vec![2, 2], vec![0.0; 3])];
    let p = TempFile::new("bad");
    let msg = save_safetensors(p.path(), &bad, &m, StorageDtype::F32)
        .unwrap_err()
        .to_string();
    assert_has(&msg, &["\"a\"", "needs 4 values, got 3"]);
    assert!(!p.path().exists());
    // metadata_for refuses a known preset label on a different config.
    let mut c = picker_nets::MsnConfig::tiny();
    c.blocks = 3;
    assert!(metadata_for(&c.into(), "tiny").is_err());
}

#[test]
fn missing_file() {
    let p = std::env::temp_dir().join("picker-nets-definitely-missing.safetensors");
    let msg = Weights::open(&p).unwrap_err().to_string();
    assert_has(&msg, &[&p.display().to_string(), "cannot open"]);
}

#[test]
fn inpaint_tensor_errors_name_key_expected_and_found() {
    // A 3-input (MSN-style) first conv in an inpaint file: the mask plane is missing.
    let (_, mut t, m) = tiny(NetKind::Inpaint);
    let x = t
        .iter_mut()
        .find(|t| t.name == "enc.conv_in.conv.weight")
        .unwrap();
    x.shape = vec![8, 3, 7, 7];
    x.data = TensorData::F32(vec![0.0; 8 * 3 * 49]);
    let (e, msg) = load_err(&save("inpaint-shape", &t, &m));
    assert!(matches!(e, Error::ShapeMismatch { .. }));
    assert_has(
        &msg,
        &[
            "\"enc.conv_in.conv.weight\"",
            "[8, 3, 7, 7]",
            "expected [8, 4, 7, 7]",
        ],
    );

    let (_, mut t, m) = tiny(NetKind::Inpaint);
    t.retain(|t| t.name != "dec.conv_out.bias");
    let (e, msg) = load_err(&save("inpaint-missing", &t, &m));
    assert!(matches!(e, Error::MissingTensor { .. }));
    assert_has(&msg, &["missing tensor", "\"dec.conv_out.bias\"", "[3]"]);

    let (_, mut t, m) = tiny(NetKind::Inpaint);
    t.push(NamedTensor::f32("disc.conv.weight", vec![1], vec![0.0]));
    let (e, msg) = load_err(&save("inpaint-extra", &t, &m));
    assert!(matches!(e, Error::UnusedTensors { count: 1, .. }));
    assert_has(&msg, &["1 unused tensor(s)", "disc.conv.weight"]);
}

#[test]
fn inpaint_loader_refuses_other_nets() {
    let (_, t, m) = tiny(NetKind::Msn);
    let f = save("msn-as-inpaint", &t, &m);
    let w = Weights::open(f.path()).unwrap();
    let msg = picker_nets::Inpaint::load(&w).unwrap_err().to_string();
    assert_has(
        &msg,
        &[
            &f.path().display().to_string(),
            "msn weights",
            "inpaint weights were asked for",
        ],
    );
}
