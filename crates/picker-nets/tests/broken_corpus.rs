//! The committed corpus of broken weights files, `fixtures/weights/broken/`
//! (written by `scripts/make-broken-weights.py` from the tiny weights; listed in
//! that folder's README.md): every file is refused, at the stage stated, with a
//! message that names the file and says what is wrong.
//!
//! Every file of the folder must have a row in [`CASES`]; a new file without one
//! fails `every_file_has_a_case`.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use picker_nets::{EnvMap, Inpaint, Irn, Msn, NetKind, Weights};

/// Where a file is refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Stage {
    /// By [`Weights::open`]: header, offsets or metadata.
    Open,
    /// By the network loader expecting [`Case::net`]: tensors, or the wrong network.
    Load,
}

struct Case {
    file: &'static str,
    /// The network the caller asks for (the loader that gets the file).
    net: NetKind,
    stage: Stage,
    /// Words the message must contain (besides the file name).
    words: &'static [&'static str],
}

const fn case(
    file: &'static str,
    net: NetKind,
    stage: Stage,
    words: &'static [&'static str],
) -> Case {
    Case {
        file,
        net,
        stage,
        words,
    }
}

use NetKind::{EnvMap as E, Irn as I};
use Stage::{Load, Open};

#[rustfmt::skip]
const CASES: &[Case] = &[
    case("missing_tensor.safetensors", E, Load,
         &["missing tensor \"tail.1.bn.running_var\"", "expected shape [12]"]),
    case("extra_tensor.safetensors", E, Load,
         &["1 unused tensor(s) not part of the network: optimizer.lr"]),
    case("wrong_shape.safetensors", E, Load,
         &["tensor \"blocks.0.conv2.weight\" has shape [16, 16, 9], expected [16, 16, 3, 3]"]),
    case("wrong_dtype.safetensors", E, Load,
         &["tensor \"tail.2.conv.bias\" has dtype I32", "accepted: F32, F16 or BF16"]),
    case("wrong_dtype_f64.safetensors", E, Load,
         &["tensor \"tail.2.conv.bias\" has dtype F64", "accepted: F32, F16 or BF16"]),
    case("nan_values.safetensors", E, Load,
         &["tensor \"blocks.0.conv1.weight\" holds a non-finite value (NaN) at flat index 5"]),
    case("negative_variance.safetensors", E, Load,
         &["tensor \"tail.1.bn.running_var\"", "variance -0.5 at channel 2 is negative"]),
    case("key_prefix.safetensors", E, Load,
         &["missing tensor \"enc.conv_in.conv.weight\"", "strip the key prefix \"module.\""]),
    case("truncated.safetensors", E, Open,
         &["file is truncated", "describes 49620 bytes but the file has 49520"]),
    case("trailing_bytes.safetensors", E, Open,
         &["16 trailing bytes after the last tensor"]),
    case("wrong_net.safetensors", I, Load,
         &["file holds msn weights, but irn weights were asked for"]),
    case("truncated_header.safetensors", E, Open,
         &["not a valid safetensors file", "header length field says 328 bytes",
           "file has 172 bytes"]),
    case("header_len_huge.safetensors", E, Open,
         &["not a valid safetensors file", "header length field says 9223372036854775808 bytes"]),
    case("header_len_1tb.safetensors", E, Open,
         &["not a valid safetensors file", "header length field says 1000000000000 bytes"]),
    case("tensor_shape_huge.safetensors", E, Open,
         &["not a valid safetensors file", "shape overflows the address space"]),
    case("tensor_shape_large.safetensors", E, Open,
         &["byte range of tensor \"tail.2.conv.bias\" does not match its dtype and shape"]),
    case("offsets_out_of_range.safetensors", E, Open,
         &["file is truncated", "describes 1000436 bytes but the file has 436"]),
    case("offsets_overflow.safetensors", E, Open,
         &["data_offsets of tensor \"tail.2.conv.bias\" end at byte 18446744073709551615",
           "beyond the end of any file"]),
    case("overlapping_offsets.safetensors", E, Open,
         &["data_offsets of tensor \"tail.1.conv.bias\" overlap another tensor"]),
    case("not_json_header.safetensors", E, Open,
         &["the header is not valid JSON", "key must be a string"]),
    case("malformed_entry.safetensors", E, Open,
         &["header entry for tensor \"tail.2.conv.bias\" is malformed", "data_offsets"]),
    case("missing_metadata.safetensors", E, Open,
         &["metadata key \"format\" is missing", "need format, format_version, net and config"]),
    case("bad_metadata_version.safetensors", E, Open,
         &["unsupported format_version \"2\"", "reads version \"1\""]),
    case("wrong_format.safetensors", E, Open,
         &["metadata \"format\": expected \"material-picker\", found \"pt\""]),
    case("config_unknown_key.safetensors", E, Open,
         &["metadata \"config\"", "unknown field `dropout`"]),
    case("preset_mismatch.safetensors", E, Open,
         &["metadata \"preset\": says \"tiny\", but the config differs from that preset",
           "\"blocks\":3"]),
    case("config_huge_widths.safetensors", E, Open,
         &["metadata \"config\"", "widths[0] is 4294967296; widths may be at most 16384"]),
    case("empty.safetensors", E, Open,
         &["not a valid safetensors file", "file is 0 bytes"]),
    case("text_file.txt", E, Open,
         &["not a valid safetensors file", "header length field says", "file has 76 bytes"]),
];

fn corpus_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/weights/broken")
}

/// Builds the network `net` from `w` (what a caller expecting that network does).
fn load_as(w: &Weights, net: NetKind) -> picker_nets::Result<()> {
    match net {
        NetKind::Irn => Irn::load(w).map(drop),
        NetKind::Msn => Msn::load(w).map(drop),
        NetKind::EnvMap => EnvMap::load(w).map(drop),
        NetKind::Inpaint => Inpaint::load(w).map(drop),
    }
}

/// The stage and message of the failure, or `None` if the file loads.
fn refusal(w: picker_nets::Result<Weights>, net: NetKind) -> Option<(Stage, String)> {
    match w {
        Err(e) => Some((Open, e.to_string())),
        Ok(w) => load_as(&w, net).err().map(|e| (Load, e.to_string())),
    }
}

#[test]
fn every_broken_file_is_refused_with_its_message() {
    let dir = corpus_dir();
    let mut failures = Vec::new();
    for c in CASES {
        let path = dir.join(c.file);
        let Some((stage, msg)) = refusal(Weights::open(&path), c.net) else {
            failures.push(format!("{}: loaded without error", c.file));
            continue;
        };
        println!("{}: {msg}", c.file);
        if stage != c.stage {
            failures.push(format!(
                "{}: refused at {stage:?}, expected at {:?}: {msg}",
                c.file, c.stage
            ));
        }
        if !msg.contains(&path.display().to_string()) {
            failures.push(format!("{}: message does not name the file: {msg}", c.file));
        }
        for w in c.words {
            if !msg.contains(w) {
                failures.push(format!("{}: message lacks {w:?}: {msg}", c.file));
            }
        }
        // The same bytes in memory are refused with the same message.
        let bytes = std::fs::read(&path).expect("reading a corpus file");
        let from_bytes = refusal(Weights::from_bytes(&path, bytes), c.net);
        if from_bytes.as_ref() != Some(&(stage, msg.clone())) {
            failures.push(format!(
                "{}: from_bytes gives {from_bytes:?}, open gives {msg:?}",
                c.file
            ));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn every_file_has_a_case() {
    let files: BTreeSet<String> = std::fs::read_dir(corpus_dir())
        .expect("fixtures/weights/broken exists (run scripts/make-broken-weights.py)")
        .map(|e| e.expect("listing the corpus").file_name())
        .map(|n| n.to_string_lossy().into_owned())
        .filter(|n| n != "README.md")
        .collect();
    let cases: BTreeSet<String> = CASES.iter().map(|c| c.file.to_string()).collect();
    assert_eq!(cases.len(), CASES.len(), "a file is listed twice in CASES");
    let untested: Vec<_> = files.difference(&cases).collect();
    let missing: Vec<_> = cases.difference(&files).collect();
    assert!(
        untested.is_empty(),
        "files in fixtures/weights/broken without a row in CASES: {untested:?}"
    );
    assert!(
        missing.is_empty(),
        "CASES rows whose file is missing (run scripts/make-broken-weights.py): {missing:?}"
    );
}

#[test]
fn every_file_is_listed_in_the_readme() {
    let readme = std::fs::read_to_string(corpus_dir().join("README.md")).expect("README.md");
    for c in CASES {
        assert!(
            readme.contains(&format!("`{}`", c.file)),
            "{} is not listed in fixtures/weights/broken/README.md",
            c.file
        );
    }
}

/// The sources of the corpus load, so each broken file differs by its one defect.
#[test]
fn the_tiny_sources_load() {
    let tiny = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/weights/tiny");
    for (file, net) in [("msn.safetensors", NetKind::Msn), ("envmap.safetensors", E)] {
        let w = Weights::open(tiny.join(file)).expect("tiny weights open");
        load_as(&w, net).expect("tiny weights load");
    }
}
