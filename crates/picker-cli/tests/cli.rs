//! End-to-end tests of the `picker` binary: inference on real and generated
//! photos with the committed tiny random weights (`fixtures/weights/tiny`,
//! made by `picker weights random --preset tiny`, see its README), weights
//! generation and inspection, benchmarking, and the error messages users see.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use image::{ImageEncoder, Luma, Rgb, Rgba};

/// The repository root (two levels above this crate).
fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn example_photo() -> PathBuf {
    root().join("fixtures/examples/coffee.jpg")
}

/// A convex quadrilateral on `example_photo()`.
const QUAD: &str = "10,20,200,30,190,150,15,140";

fn tiny_weights() -> PathBuf {
    root().join("fixtures/weights/tiny")
}

fn picker<I, S>(args: I) -> Output
where
    I: IntoIterator<Item = S>,
    S: AsRef<std::ffi::OsStr>,
{
    Command::new(env!("CARGO_BIN_EXE_picker"))
        .args(args)
        .env("RAYON_NUM_THREADS", "2")
        .output()
        .expect("running picker")
}

fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn assert_ok(o: &Output) {
    assert!(
        o.status.success(),
        "picker failed ({:?})\nstdout: {}\nstderr: {}",
        o.status,
        stdout(o),
        stderr(o)
    );
}

/// Asserts a failure with exactly one `error: …` line on stderr that mentions `needle`.
fn assert_error_names(o: &Output, needle: &str) {
    let err = stderr(o);
    assert!(
        !o.status.success(),
        "expected failure, got success; stdout: {}",
        stdout(o)
    );
    assert_eq!(o.status.code(), Some(1), "exit status; stderr: {err}");
    assert!(err.starts_with("error: "), "stderr: {err}");
    assert_eq!(
        err.trim_end().lines().count(),
        1,
        "one line expected: {err}"
    );
    assert!(err.contains(needle), "stderr should name {needle:?}: {err}");
    assert!(!err.contains("panicked"), "{err}");
}

/// `(width, height)` of a PNG.
fn png_size(p: &Path) -> (u32, u32) {
    image::image_dimensions(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

/// An EXR file's first layer: `(width, height)` and `(channel name, samples)` in file order.
type Exr = ((usize, usize), Vec<(String, Vec<f32>)>);

/// Reads an EXR file's first layer.
fn read_exr(p: &Path) -> Exr {
    use exr::prelude::*;
    let img = read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .from_file(p)
        .unwrap_or_else(|e| panic!("{}: {e}", p.display()));
    let size = img.layer_data.size;
    let chans = img
        .layer_data
        .channel_data
        .list
        .iter()
        .map(|c| {
            (
                c.name.to_string(),
                c.sample_data.values_as_f32().collect::<Vec<_>>(),
            )
        })
        .collect();
    ((size.0, size.1), chans)
}

const IRN_HEADS: [(&str, usize); 6] = [
    ("diffuse_albedo", 3),
    ("specular_albedo", 3),
    ("normals", 3),
    ("glossiness", 1),
    ("view_vector", 3),
    ("uv", 3),
];

/// Checks every output of a full (IRN + MSN + EnvMap) run at working size `w × h`.
fn check_full_outputs(out: &Path, w: usize, h: usize) {
    assert_eq!(png_size(&out.join("input.png")), (w as u32, h as u32));
    let (ew, eh) = ((w / 8).max(1), (h / 8).max(1));
    let mut expected: Vec<(String, usize, usize, usize)> = IRN_HEADS
        .iter()
        .map(|&(n, c)| (n.to_string(), c, w, h))
        .collect();
    expected.push(("segmentation".into(), 3, w, h));
    expected.push(("envmap".into(), 3, ew, eh));
    // The mirror pass (the default): how far the IRN's two passes disagree.
    expected.push(("disagreement_albedo".into(), 1, w, h));
    expected.push(("disagreement_normals".into(), 1, w, h));
    for (name, c, ow, oh) in &expected {
        let exr = out.join(format!("{name}.exr"));
        let ((xw, xh), chans) = read_exr(&exr);
        assert_eq!((xw, xh), (*ow, *oh), "{name}.exr size");
        let names: Vec<&str> = chans.iter().map(|(n, _)| n.as_str()).collect();
        if *c == 1 {
            assert_eq!(names, ["Y"], "{name}.exr channels");
        } else {
            // exr sorts channel names alphabetically.
            assert_eq!(names, ["B", "G", "R"], "{name}.exr channels");
        }
        for (ch, values) in &chans {
            assert_eq!(values.len(), ow * oh);
            assert!(
                values.iter().all(|v| v.is_finite()),
                "{name}.{ch} not finite"
            );
            if name == "disagreement_normals" {
                assert!(
                    values.iter().all(|v| (0.0..=180.0).contains(v)),
                    "{name}.{ch} not an angle in degrees"
                );
            } else if name != "envmap" && name != "normals" && name != "view_vector" {
                assert!(
                    values.iter().all(|v| (0.0..=1.0).contains(v)),
                    "{name}.{ch} outside [0, 1]"
                );
            }
        }
        if name == "normals" || name == "view_vector" {
            let get = |n: &str| &chans.iter().find(|(c, _)| c == n).unwrap().1;
            let (x, y, z) = (get("R"), get("G"), get("B"));
            for i in 0..x.len() {
                let len = (x[i] * x[i] + y[i] * y[i] + z[i] * z[i]).sqrt();
                assert!((len - 1.0).abs() < 1e-4, "{name} not unit at {i}: {len}");
            }
        }
        let png = out.join(format!("{name}.png"));
        assert_eq!(png_size(&png), (*ow as u32, *oh as u32), "{name}.png size");
    }
    let manifest: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("manifest.json")).unwrap()).unwrap();
    let files = manifest["files"].as_array().unwrap();
    assert_eq!(files.len(), 1 + 2 * expected.len());
    for f in files {
        let name = f["file"].as_str().unwrap();
        assert!(out.join(name).is_file(), "manifest lists missing {name}");
    }
    let nets: Vec<&str> = manifest["nets"]
        .as_array()
        .unwrap()
        .iter()
        .map(|n| n["net"].as_str().unwrap())
        .collect();
    assert_eq!(nets, ["irn", "msn", "envmap"]);
    assert_eq!(manifest["working_size"]["width"], w);
    assert_eq!(manifest["working_size"]["height"], h);
    // No temporary files left behind by the atomic writes.
    for e in std::fs::read_dir(out).unwrap() {
        let n = e.unwrap().file_name().to_string_lossy().into_owned();
        assert!(!n.starts_with('.'), "leftover {n}");
    }
}

fn infer(photo: &Path, out: &Path, extra: &[&str]) -> Output {
    let mut args: Vec<std::ffi::OsString> = vec![
        "infer".into(),
        photo.into(),
        "--weights".into(),
        tiny_weights().into(),
        "--out".into(),
        out.into(),
    ];
    args.extend(extra.iter().map(Into::into));
    picker(args)
}

#[test]
fn infer_example_photo_writes_every_output() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("nested/out");
    let o = infer(&example_photo(), &out, &[]);
    assert_ok(&o);
    assert!(stdout(&o).contains("wrote 21 files"), "{}", stdout(&o));
    // coffee.jpg is 320×213; the default work size 320 keeps it.
    check_full_outputs(&out, 320, 213);
}

#[test]
fn low_memory_mode_gives_the_same_bytes() {
    // PICKER_MEMORY=low: lazy Winograd weights and the IRN's towers one
    // after another; every output file must be byte-identical.
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = (dir.path().join("default"), dir.path().join("low"));
    assert_ok(&infer(&example_photo(), &a, &[]));
    let mut args: Vec<std::ffi::OsString> = vec!["infer".into(), example_photo().into()];
    args.extend([
        "--weights".into(),
        tiny_weights().into(),
        "--out".into(),
        b.clone().into(),
    ]);
    let o = Command::new(env!("CARGO_BIN_EXE_picker"))
        .args(args)
        .env("RAYON_NUM_THREADS", "2")
        .env("PICKER_MEMORY", "low")
        .output()
        .expect("running picker");
    assert_ok(&o);
    let mut names: Vec<_> = std::fs::read_dir(&a)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    names.sort();
    assert!(names.len() > 10, "{names:?}");
    for n in names {
        if n.to_string_lossy().ends_with(".json") {
            continue; // timings differ
        }
        let (x, y) = (
            std::fs::read(a.join(&n)).unwrap(),
            std::fs::read(b.join(&n)).unwrap(),
        );
        assert!(x == y, "{n:?} differs in the low-memory mode");
    }
}

#[test]
fn bf16_precision_is_close_to_f32_or_refused() {
    let o = picker([
        "--precision",
        "f16",
        "bench",
        "--net",
        "envmap",
        "--preset",
        "tiny",
    ]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = (dir.path().join("f32"), dir.path().join("bf16"));
    let o = infer(&example_photo(), &b, &["--precision", "bf16"]);
    #[cfg(target_arch = "x86_64")]
    let has_bf16 = std::arch::is_x86_feature_detected!("avx512bf16")
        && std::arch::is_x86_feature_detected!("avx512bw");
    #[cfg(not(target_arch = "x86_64"))]
    let has_bf16 = false;
    if !has_bf16 {
        eprintln!("SKIPPED: this CPU lacks AVX512_BF16; only the refusal is tested");
        assert_eq!(o.status.code(), Some(1));
        assert!(stderr(&o).contains("AVX512_BF16"), "{}", stderr(&o));
        return;
    }
    assert_ok(&o);
    assert_ok(&infer(&example_photo(), &a, &[]));
    // The tiny nets' 16-channel residual blocks run in bf16: outputs move,
    // but the ones decoded linearly from tanh, (y + 1)/2, stay within the
    // bf16 error of f32 (normals, view vectors and the HDR envmap go through
    // a normalisation or an exponential that magnifies small random outputs).
    let mut moved = false;
    for name in IRN_HEADS
        .iter()
        .map(|h| h.0)
        .chain(["segmentation", "envmap"])
    {
        let (x, y) = (
            read_exr(&a.join(format!("{name}.exr"))),
            read_exr(&b.join(format!("{name}.exr"))),
        );
        assert_eq!(x.0, y.0, "{name}");
        let mut worst = 0.0f32;
        for ((_, p), (_, q)) in x.1.iter().zip(&y.1) {
            for (u, v) in p.iter().zip(q) {
                worst = worst.max((u - v).abs());
            }
        }
        moved |= worst > 0.0;
        let linear = matches!(
            name,
            "diffuse_albedo" | "specular_albedo" | "glossiness" | "segmentation"
        );
        assert!(!linear || worst < 0.05, "bf16 moved {name} by {worst}");
    }
    assert!(moved, "bf16 changed nothing: the flag was not applied");
}

#[test]
fn infer_odd_size_rgb_png_upscales_to_work_size() {
    let dir = tempfile::tempdir().unwrap();
    let photo = dir.path().join("odd.png");
    image::RgbImage::from_fn(37, 53, |x, y| Rgb([(x * 7) as u8, (y * 5) as u8, 128]))
        .save(&photo)
        .unwrap();
    let out = dir.path().join("out");
    assert_ok(&infer(&photo, &out, &["--work-size", "96"]));
    // Long side 53 → 96, short side round(37·96/53) = 67.
    check_full_outputs(&out, 67, 96);
}

#[test]
fn infer_grey_16bit_png() {
    let dir = tempfile::tempdir().unwrap();
    let photo = dir.path().join("grey16.png");
    image::ImageBuffer::<Luma<u16>, Vec<u16>>::from_fn(37, 53, |x, y| {
        Luma([((x * 1500 + y * 700) % 65536) as u16])
    })
    .save(&photo)
    .unwrap();
    let out = dir.path().join("out");
    assert_ok(&infer(&photo, &out, &["--work-size", "64"]));
    check_full_outputs(&out, 45, 64);
    // Greyscale in, grey working image out.
    let input = image::open(out.join("input.png")).unwrap().to_rgb8();
    assert!(input.pixels().all(|p| p[0] == p[1] && p[1] == p[2]));
}

#[test]
fn infer_rgba_png_and_tiny_work_size() {
    let dir = tempfile::tempdir().unwrap();
    let photo = dir.path().join("rgba.png");
    image::RgbaImage::from_fn(20, 9, |x, y| {
        Rgba([(x * 12) as u8, (y * 20) as u8, 90, (x * 10) as u8])
    })
    .save(&photo)
    .unwrap();
    let out = dir.path().join("out");
    // A 5×2 working image: smaller than any network's stride; padding handles it.
    assert_ok(&infer(&photo, &out, &["--work-size", "5"]));
    check_full_outputs(&out, 5, 2);
}

/// A minimal little-endian EXIF (TIFF) block holding only an Orientation tag.
fn exif_orientation(value: u16) -> Vec<u8> {
    let mut e = b"II*\0".to_vec();
    e.extend_from_slice(&8u32.to_le_bytes()); // offset of IFD0
    e.extend_from_slice(&1u16.to_le_bytes()); // one entry
    e.extend_from_slice(&0x0112u16.to_le_bytes()); // Orientation
    e.extend_from_slice(&3u16.to_le_bytes()); // SHORT
    e.extend_from_slice(&1u32.to_le_bytes()); // count
    e.extend_from_slice(&value.to_le_bytes());
    e.extend_from_slice(&[0, 0]);
    e.extend_from_slice(&0u32.to_le_bytes()); // no next IFD
    e
}

#[test]
fn infer_applies_exif_orientation() {
    let dir = tempfile::tempdir().unwrap();
    let photo = dir.path().join("rotated.png");
    // Stored 40 wide × 20 tall, left half black; orientation 6 = rotate 90° clockwise to view.
    let img = image::RgbImage::from_fn(40, 20, |x, _| {
        if x < 20 {
            Rgb([0, 0, 0])
        } else {
            Rgb([255, 255, 255])
        }
    });
    let mut bytes = Vec::new();
    let mut enc = image::codecs::png::PngEncoder::new(&mut bytes);
    enc.set_exif_metadata(exif_orientation(6)).unwrap();
    enc.write_image(img.as_raw(), 40, 20, image::ExtendedColorType::Rgb8)
        .unwrap();
    std::fs::write(&photo, bytes).unwrap();
    let out = dir.path().join("out");
    assert_ok(&infer(&photo, &out, &["--work-size", "40"]));
    // Viewed: 20 wide × 40 tall, the stored left (black) half now on top.
    let input = image::open(out.join("input.png")).unwrap().to_rgb8();
    assert_eq!(input.dimensions(), (20, 40));
    assert_eq!(input.get_pixel(10, 2).0, [0, 0, 0]);
    assert_eq!(input.get_pixel(10, 37).0, [255, 255, 255]);
    let manifest: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("manifest.json")).unwrap()).unwrap();
    assert_eq!(manifest["photo"]["width"], 20);
    assert_eq!(manifest["photo"]["exif_orientation"], "Rotate90");
}

#[test]
fn infer_single_weights_file_runs_that_net_only() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let o = picker([
        "infer".as_ref(),
        example_photo().as_os_str(),
        "--weights".as_ref(),
        tiny_weights().join("msn.safetensors").as_os_str(),
        "--out".as_ref(),
        out.as_os_str(),
        "--work-size".as_ref(),
        "64".as_ref(),
    ]);
    assert_ok(&o);
    let mut names: Vec<String> = std::fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    assert_eq!(
        names,
        [
            "input.png",
            "manifest.json",
            "segmentation.exr",
            "segmentation.png"
        ]
    );
    assert_eq!(png_size(&out.join("segmentation.png")), (64, 43));
}

/// An MSN with a material embedding: `picker infer` writes `embedding.exr`
/// (the raw values), and `extract --elements` of that folder reads it.
#[test]
fn infer_writes_the_material_embedding_and_extract_reads_it() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("elements");
    let embed = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/parity/msn_tiny_embed.safetensors");
    let o = picker([
        "infer".as_ref(),
        example_photo().as_os_str(),
        "--weights".as_ref(),
        tiny_weights().join("irn.safetensors").as_os_str(),
        "--weights".as_ref(),
        embed.as_os_str(),
        "--out".as_ref(),
        out.as_os_str(),
        "--work-size".as_ref(),
        "64".as_ref(),
    ]);
    assert_ok(&o);
    let emb = picker_render::io::read_exr(&out.join("embedding.exr")).unwrap();
    assert_eq!((emb.channels, emb.width, emb.height), (3, 64, 43));
    assert!(emb.data.iter().all(|v| (-1.0..=1.0).contains(v)));
    assert!(
        emb.data.iter().any(|&v| v < 0.0),
        "raw tanh values, not (e+1)/2"
    );
    assert_eq!(png_size(&out.join("embedding.png")), (64, 43));
    let manifest: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("manifest.json")).unwrap()).unwrap();
    assert!(manifest["files"]
        .as_array()
        .unwrap()
        .iter()
        .any(|f| f.to_string().contains("embedding.exr")));
    let extract = |name: &str| {
        picker([
            "extract".as_ref(),
            example_photo().as_os_str(),
            "--elements".as_ref(),
            out.as_os_str(),
            "--pick".as_ref(),
            "10,10".as_ref(),
            "--out".as_ref(),
            dir.path().join(name).as_os_str(),
        ])
    };
    assert_ok(&extract("m"));
    // A misshaped embedding names the problem.
    let small = picker_render::io::Image::new(3, 4, 4, vec![0.0; 48]).unwrap();
    picker_render::io::write_exr(&out.join("embedding.exr"), &small).unwrap();
    let o = extract("m2");
    assert!(!o.status.success());
    assert!(
        String::from_utf8_lossy(&o.stderr).contains("material embedding"),
        "{o:?}"
    );
}

#[test]
fn weights_random_and_inspect_tiny() {
    let dir = tempfile::tempdir().unwrap();
    let f = dir.path().join("envmap.safetensors");
    let o = picker([
        "weights".as_ref(),
        "random".as_ref(),
        "--net".as_ref(),
        "envmap".as_ref(),
        "--preset".as_ref(),
        "tiny".as_ref(),
        "--seed".as_ref(),
        "9".as_ref(),
        "--dtype".as_ref(),
        "f16".as_ref(),
        "--out".as_ref(),
        f.as_os_str(),
    ]);
    assert_ok(&o);
    let o = picker([
        "weights".as_ref(),
        "inspect".as_ref(),
        f.as_os_str(),
        "--json".as_ref(),
        "--check".as_ref(),
    ]);
    assert_ok(&o);
    let v: serde_json::Value = serde_json::from_str(stdout(&o).trim()).unwrap();
    assert_eq!(v["net"], "envmap");
    assert_eq!(v["preset"], "tiny");
    assert_eq!(v["parameters"], 10_783);
    assert_eq!(v["check"], "ok");
    assert_eq!(v["config"]["tail_widths"], serde_json::json!([16, 12]));
    assert!(v["dtypes"]
        .as_array()
        .unwrap()
        .iter()
        .any(|d| d["dtype"] == "F16"));
    assert_eq!(v["file_size"], std::fs::metadata(&f).unwrap().len());

    // Same seed, same tensors; the text form names the net and count.
    let g = dir.path().join("again.safetensors");
    assert_ok(&picker([
        "weights",
        "random",
        "--net",
        "envmap",
        "--preset",
        "tiny",
        "--seed",
        "9",
        "--dtype",
        "f16",
        "--out",
        g.to_str().unwrap(),
    ]));
    // (Compared tensor by tensor: the header's JSON key order may differ between runs.)
    let (a, b) = (std::fs::read(&f).unwrap(), std::fs::read(&g).unwrap());
    let (a, b) = (
        safetensors::SafeTensors::deserialize(&a).unwrap(),
        safetensors::SafeTensors::deserialize(&b).unwrap(),
    );
    assert_eq!(a.len(), b.len());
    for (name, t) in a.tensors() {
        let u = b.tensor(&name).unwrap();
        assert!(
            t.data() == u.data() && t.shape() == u.shape() && t.dtype() == u.dtype(),
            "{name} differs"
        );
    }
    let o = picker(["weights".as_ref(), "inspect".as_ref(), f.as_os_str()]);
    assert_ok(&o);
    let text = stdout(&o);
    assert!(text.contains("envmap"), "{text}");
    assert!(text.contains("10.78 K (10,783)"), "{text}");
}

#[test]
fn inspect_reports_thesis_msn_parameter_count() {
    let dir = tempfile::tempdir().unwrap();
    let f = dir.path().join("msn.safetensors");
    assert_ok(&picker([
        "weights",
        "random",
        "--net",
        "msn",
        "--preset",
        "thesis",
        "--dtype",
        "bf16",
        "--out",
        f.to_str().unwrap(),
    ]));
    let o = picker(["weights".as_ref(), "inspect".as_ref(), f.as_os_str()]);
    assert_ok(&o);
    let text = stdout(&o);
    assert!(text.contains("11.38 M (11,378,179)"), "{text}");
    assert!(text.contains("thesis"), "{text}");
    assert!(text.contains("BF16"), "{text}");
}

#[test]
fn bench_json_has_the_keys() {
    let irn = tiny_weights().join("irn.safetensors");
    let o = picker([
        "bench".as_ref(),
        "--weights".as_ref(),
        irn.as_os_str(),
        "--size".as_ref(),
        "24x40".as_ref(),
        "--runs".as_ref(),
        "3".as_ref(),
        "--warmup".as_ref(),
        "1".as_ref(),
        "--threads".as_ref(),
        "2".as_ref(),
        "--json".as_ref(),
    ]);
    assert_ok(&o);
    let text = stdout(&o);
    assert_eq!(text.trim().lines().count(), 1, "{text}");
    let v: serde_json::Value = serde_json::from_str(text.trim()).unwrap();
    for key in [
        "net",
        "size",
        "threads",
        "runs",
        "median_ms",
        "min_ms",
        "gflops",
        "peak_rss_mb",
        "isa",
    ] {
        assert!(v.get(key).is_some(), "missing {key}: {text}");
    }
    assert_eq!(v["net"], "irn");
    assert_eq!(v["size"], "24x40");
    assert_eq!(v["threads"], 2);
    assert_eq!(v["runs"], 3);
    let (median, min) = (
        v["median_ms"].as_f64().unwrap(),
        v["min_ms"].as_f64().unwrap(),
    );
    assert!(min > 0.0 && min <= median, "{text}");
    assert!(v["gflops"].as_f64().unwrap() > 0.0);

    // Without --weights: random weights of a preset, via a temporary file.
    let o = picker([
        "bench", "--net", "envmap", "--preset", "tiny", "--size", "17x23", "--runs", "1",
        "--warmup", "0", "--json",
    ]);
    assert_ok(&o);
    let v: serde_json::Value = serde_json::from_str(stdout(&o).trim()).unwrap();
    assert_eq!(v["net"], "envmap");
    assert_eq!(v["preset"], "tiny");
    assert_eq!(
        v["stages"].as_array().map(Vec::len),
        Some(0),
        "no --profile"
    );

    // --profile: one median per stage, in execution order.
    let o = picker([
        "bench",
        "--net",
        "envmap",
        "--preset",
        "tiny",
        "--size",
        "17x23",
        "--runs",
        "2",
        "--warmup",
        "0",
        "--profile",
        "--json",
    ]);
    assert_ok(&o);
    let v: serde_json::Value = serde_json::from_str(stdout(&o).trim()).unwrap();
    let stages: Vec<&str> = v["stages"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s["stage"].as_str().unwrap())
        .collect();
    // The encoder's first two layers run fused: one stage.
    assert_eq!(stages.first(), Some(&"enc.conv_in+down.0"), "{stages:?}");
    assert_eq!(stages.last(), Some(&"tail.2"), "{stages:?}");
    assert!(v["stages"][0]["median_ms"].as_f64().unwrap() >= 0.0);
}

// ---- errors: one line on stderr naming the file, exit status 1 ----

#[test]
fn error_missing_photo() {
    let dir = tempfile::tempdir().unwrap();
    let photo = dir.path().join("no-such-photo.jpg");
    let o = infer(&photo, &dir.path().join("out"), &[]);
    assert_error_names(&o, "no-such-photo.jpg");
}

#[test]
fn error_a_folder_given_as_a_weights_file_or_a_file_as_scenes() {
    let dir = tempfile::tempdir().unwrap();
    let folder = dir.path().join("not-weights");
    std::fs::create_dir(&folder).unwrap();
    let o = picker(["weights", "inspect", folder.to_str().unwrap()]);
    assert_error_names(&o, "not-weights");
    assert!(stderr(&o).contains("is a directory"), "{}", stderr(&o));
    let o = picker(["eval", example_photo().to_str().unwrap()]);
    assert_error_names(&o, "coffee.jpg");
    assert!(stderr(&o).contains("not a folder"), "{}", stderr(&o));
}

#[test]
fn error_corrupt_png() {
    let dir = tempfile::tempdir().unwrap();
    let photo = dir.path().join("noise.png");
    let noise: Vec<u8> = (0..600u32)
        .map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8)
        .collect();
    std::fs::write(&photo, noise).unwrap();
    let o = infer(&photo, &dir.path().join("out"), &[]);
    assert_error_names(&o, "noise.png");
}

#[test]
fn error_truncated_png() {
    let dir = tempfile::tempdir().unwrap();
    let full = dir.path().join("full.png");
    image::RgbImage::from_fn(64, 64, |x, y| {
        Rgb([(x * 3) as u8, (y * 3) as u8, ((x ^ y) * 4) as u8])
    })
    .save(&full)
    .unwrap();
    let bytes = std::fs::read(&full).unwrap();
    let photo = dir.path().join("truncated.png");
    std::fs::write(&photo, &bytes[..bytes.len() / 2]).unwrap();
    let o = infer(&photo, &dir.path().join("out"), &[]);
    assert_error_names(&o, "truncated.png");
}

#[test]
fn error_truncated_jpeg() {
    let dir = tempfile::tempdir().unwrap();
    let bytes = std::fs::read(example_photo()).unwrap();
    let photo = dir.path().join("truncated.jpg");
    std::fs::write(&photo, &bytes[..bytes.len() / 3]).unwrap();
    let o = infer(&photo, &dir.path().join("out"), &[]);
    assert_error_names(&o, "truncated.jpg");
    assert!(String::from_utf8_lossy(&o.stderr).contains("truncated"));
}

#[test]
fn error_unsupported_format() {
    let dir = tempfile::tempdir().unwrap();
    let photo = dir.path().join("anim.gif");
    std::fs::write(&photo, b"GIF89a\x01\x00\x01\x00\x00\x00\x00;").unwrap();
    let o = infer(&photo, &dir.path().join("out"), &[]);
    assert_error_names(&o, "anim.gif");
}

#[test]
fn error_missing_weights() {
    let dir = tempfile::tempdir().unwrap();
    let w = dir.path().join("no-such-weights.safetensors");
    let o = picker([
        "infer".as_ref(),
        example_photo().as_os_str(),
        "--weights".as_ref(),
        w.as_os_str(),
        "--out".as_ref(),
        dir.path().join("out").as_os_str(),
    ]);
    assert_error_names(&o, "no-such-weights.safetensors");
    // A directory without any weights file in it.
    let empty = dir.path().join("empty-weights-dir");
    std::fs::create_dir(&empty).unwrap();
    let o = picker([
        "infer".as_ref(),
        example_photo().as_os_str(),
        "--weights".as_ref(),
        empty.as_os_str(),
        "--out".as_ref(),
        dir.path().join("out").as_os_str(),
    ]);
    assert_error_names(&o, "empty-weights-dir");
}

#[test]
fn error_weights_with_a_tensor_removed() {
    use safetensors::SafeTensors;
    let dir = tempfile::tempdir().unwrap();
    let src = std::fs::read(tiny_weights().join("msn.safetensors")).unwrap();
    let st = SafeTensors::deserialize(&src).unwrap();
    let (_, meta) = SafeTensors::read_metadata(&src).unwrap();
    let removed = "dec.conv_out.bias";
    let kept: Vec<_> = st
        .tensors()
        .into_iter()
        .filter(|(k, _)| k != removed)
        .collect();
    assert_eq!(kept.len() + 1, st.len(), "fixture should hold {removed}");
    let bad = dir.path().join("broken-msn.safetensors");
    safetensors::serialize_to_file(kept, meta.metadata(), &bad).unwrap();

    let o = picker([
        "infer".as_ref(),
        example_photo().as_os_str(),
        "--weights".as_ref(),
        bad.as_os_str(),
        "--out".as_ref(),
        dir.path().join("out").as_os_str(),
        "--work-size".as_ref(),
        "32".as_ref(),
    ]);
    assert_error_names(&o, "broken-msn.safetensors");
    assert!(stderr(&o).contains(removed), "{}", stderr(&o));
    // inspect reads the header fine; --check builds the network and fails the same way.
    let o = picker([
        "weights".as_ref(),
        "inspect".as_ref(),
        bad.as_os_str(),
        "--check".as_ref(),
    ]);
    assert_error_names(&o, "broken-msn.safetensors");
}

#[test]
fn error_unwritable_out_dir() {
    let dir = tempfile::tempdir().unwrap();
    // A regular file where a directory is needed: fails for every user, root included.
    let blocker = dir.path().join("a-file");
    std::fs::write(&blocker, b"x").unwrap();
    let out = blocker.join("out");
    let o = infer(&example_photo(), &out, &["--work-size", "32"]);
    assert_error_names(&o, "a-file");
}

/// Bad values that once ran (or aborted) are refused up front with one
/// clear line, and nothing is written (issue 4's bad-input rules).
#[test]
fn out_of_range_values_are_refused_before_anything_is_written() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("o");
    let w = tiny_weights();
    let photo = example_photo();
    let extract = |extra: &[&str]| {
        let mut args = vec![
            "extract",
            photo.to_str().unwrap(),
            "--weights",
            w.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ];
        args.extend_from_slice(extra);
        picker(args)
    };
    // Masks: a 10×10 one, an empty one and one of the photo's size (320×213)
    // set only in its middle.
    let masks = tempfile::tempdir().unwrap();
    let mask_png = |name: &str, w: u32, h: u32, on: &dyn Fn(u32, u32) -> bool| {
        let p = masks.path().join(name);
        image::GrayImage::from_fn(w, h, |x, y| Luma([if on(x, y) { 255 } else { 0 }]))
            .save(&p)
            .unwrap();
        p.display().to_string()
    };
    let small = mask_png("small.png", 10, 10, &|_, _| true);
    let empty = mask_png("empty.png", 320, 213, &|_, _| false);
    let middle = mask_png("middle.png", 320, 213, &|x, y| {
        (100..200).contains(&x) && (50..150).contains(&y)
    });
    for (extra, needle) in [
        (&["--mask", "quad"][..], "--mask quad needs --quad"),
        (&["--mask", &small][..], "the mask is 10x10 but the photo"),
        (&["--mask", &empty][..], "no pixel is set"),
        (
            &["--mask", &middle, "--pick", "5,5"][..],
            "--pick 5,5 is outside the mask",
        ),
        (
            &["--mask", &middle, "--pick", "150,60", "--pick", "160,70"][..],
            "at most one --pick",
        ),
        (&["--mask", "/nonexistent/m.png"][..], "/nonexistent/m.png"),
        (
            &["--mask", &middle, "--quad", QUAD, "--pick", "12,22"][..],
            "--pick 12,22 is outside the mask",
        ),
    ] {
        let o = extract(extra);
        assert_error_names(&o, needle);
        assert!(!out.exists(), "{extra:?} wrote {}", out.display());
    }
    for (extra, needle) in [
        (
            &["--pick", "10,10", "--tolerance", "2"][..],
            "--tolerance 2",
        ),
        (&["--pick", "10,10", "--fov", "1e-30"][..], "--fov"),
        (&["--pick", "10,10", "--fov", "180"][..], "--fov 180"),
        (
            &["--pick", "10,10", "--max-megapixels", "inf"][..],
            "finite",
        ),
        // A plane given by a quad or a normal that cannot be used.
        (
            &["--quad", "10,20,330,30,190,150,15,140"][..],
            "--quad: corner 2 (330,30) is outside the 320x213 photo",
        ),
        (
            &["--quad", "10,20,190,150,200,30,15,140"][..],
            "convex quadrilateral",
        ),
        (
            &["--quad", QUAD, "--pick", "50,50", "--pick", "60,60"][..],
            "at most one --pick",
        ),
        (&["--quad", QUAD, "--uv", "net"][..], "--uv net"),
        (
            &["--pick", "50,50", "--normal", "front", "--uv", "net"][..],
            "--uv net",
        ),
        (
            &["--pick", "20,190", "--normal", "0,0,-1"][..],
            "seen edge-on or from behind",
        ),
    ] {
        let o = extract(extra);
        assert_error_names(&o, needle);
        assert!(!out.exists(), "{extra:?} wrote {}", out.display());
    }
    // Usage errors of the plane flags (exit status 2, clap's).
    for (extra, needle) in [
        (&["--quad", "10,20,200,30"][..], "X1,Y1,X2,Y2,X3,Y3,X4,Y4"),
        (&["--quad", QUAD, "--all"][..], "--all"),
        (&["--quad", QUAD, "--normal", "front"][..], "--normal"),
        (
            &["--pick", "50,50", "--normal", "0,0,0"][..],
            "no direction",
        ),
        (&["--pick", "50,50", "--normal", "up"][..], "front or X,Y,Z"),
        (&["--pick", "50,50", "--quad-size", "1x1"][..], "--quad"),
        (&["--quad", QUAD, "--quad-size", "30cm"][..], "expected WxH"),
        (
            &["--quad", QUAD, "--quad-size", "0x1m"][..],
            "not a positive size",
        ),
        (
            &["--quad", QUAD, "--quad-size", "1x-2"][..],
            "not a positive size",
        ),
        (
            &["--quad", QUAD, "--quad-size", "ax1"][..],
            "not a positive size",
        ),
        (
            &["--quad", QUAD, "--quad-size", "1x1ft"][..],
            "not a positive size",
        ),
        (
            &["--quad", QUAD, "--quad-size", "1e39x1"][..],
            "not a positive size",
        ),
        (&["--mask", "quad", "--all"][..], "--all"),
        (&["--mask", "quad", "--tolerance", "0.1"][..], "--tolerance"),
        (&["--mask", "quad", "--connected"][..], "--connected"),
        (
            &["--pick", "5,5", "--mask", ""][..],
            "a mask image or `quad`",
        ),
    ] {
        let o = extract(extra);
        assert_eq!(o.status.code(), Some(2), "{extra:?}: {}", stderr(&o));
        assert!(stderr(&o).contains(needle), "{extra:?}: {}", stderr(&o));
        assert!(!out.exists(), "{extra:?} wrote {}", out.display());
    }
    // A negative coordinate reaches the pick's own parser (clap would
    // otherwise take it for an unknown flag).
    let o = extract(&["--pick", "-1,5"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("\"-1\" in \"-1,5\""), "{}", stderr(&o));
    // Sizes whose buffers could not be allocated are refused, not aborted on.
    let o = picker([
        "synth",
        "--out",
        out.to_str().unwrap(),
        "--size",
        "100000x100000",
    ]);
    assert_eq!(o.status.code(), Some(2), "a usage error: {}", stderr(&o));
    assert!(stderr(&o).contains("megapixels"), "{}", stderr(&o));
    assert!(!out.exists());
    let o = picker([
        "bench", "--net", "irn", "--preset", "tiny", "--runs", "1", "--batch", "100000",
    ]);
    assert_eq!(o.status.code(), Some(2), "a usage error: {}", stderr(&o));
    assert!(stderr(&o).contains("--batch 100000"), "{}", stderr(&o));
    // Far more threads than cores: lowered, with a warning, and the run works.
    let o = extract(&["--pick", "10,10", "--threads", "100000", "--no-timings"]);
    assert_ok(&o);
    assert!(
        stderr(&o).contains("warning: --threads 100000"),
        "{}",
        stderr(&o)
    );
}

/// A copy of the committed synthetic scene `fixtures/synth/scene_000000`
/// (image and render elements) in `dir`, to alter.
fn copy_fixture_scene(dir: &Path) {
    let scene = root().join("fixtures/synth/scene_000000");
    std::fs::create_dir_all(dir).unwrap();
    for e in std::fs::read_dir(&scene).unwrap().flatten() {
        if e.path().is_file() {
            std::fs::copy(e.path(), dir.join(e.file_name())).unwrap();
        }
    }
}

fn write_rgb_exr(path: &Path, w: usize, h: usize, f: impl Fn(usize, usize) -> [f32; 3] + Sync) {
    use exr::prelude::*;
    write_rgb_file(path, w, h, |x, y| {
        let p = f(x, y);
        (p[0], p[1], p[2])
    })
    .unwrap();
}

/// A chessboard whose segmentation has two colours: a pick on a dark square
/// gives the whole board, says so (diagnostics, hint), and `--no-pattern`
/// gives the dark squares alone.
#[test]
fn a_pick_on_a_chessboard_square_gives_the_board() {
    use picker_render::io::{write_exr, Image};
    let tmp = tempfile::tempdir().unwrap();
    let scene = tmp.path().join("scene");
    std::fs::create_dir_all(&scene).unwrap();
    // Render elements and photo at 160x120: a 64x64 board of 8-pixel
    // squares on a brown floor, facing the camera.
    let (w, h) = (160usize, 120usize);
    let on_board = |x: usize, y: usize| (48..112).contains(&x) && (28..92).contains(&y);
    let dark =
        |x: usize, y: usize| on_board(x, y) && ((x - 48) / 8 + (y - 28) / 8).is_multiple_of(2);
    let colour = |x: usize, y: usize| -> [f32; 3] {
        if dark(x, y) {
            [0.02, 0.02, 0.02]
        } else if on_board(x, y) {
            [0.7, 0.7, 0.65]
        } else {
            [0.3, 0.15, 0.08]
        }
    };
    let write = |name: &str, c: usize, f: &dyn Fn(usize, usize) -> [f32; 3]| {
        let mut data = vec![0.0f32; c * w * h];
        for i in 0..w * h {
            let v = f(i % w, i / w);
            for k in 0..c {
                data[k * w * h + i] = v[k];
            }
        }
        write_exr(
            &scene.join(format!("{name}.exr")),
            &Image::new(c, h, w, data).unwrap(),
        )
        .unwrap();
    };
    write("diffuse_albedo", 3, &colour);
    write("specular_albedo", 3, &|_, _| [0.04; 3]);
    write("glossiness", 1, &|_, _| [0.3; 3]);
    write("normals", 3, &|_, _| [0.0, 0.0, 1.0]);
    write("view_vector", 3, &|_, _| [0.0, 0.0, 1.0]);
    write("segmentation", 3, &|x, y| {
        let c = colour(x, y);
        [c[0] + 0.1, c[1] + 0.1, c[2] + 0.1]
    });
    let photo = image::RgbImage::from_fn(w as u32, h as u32, |x, y| {
        let c = colour(x as usize, y as usize);
        image::Rgb(c.map(|v| (v.powf(1.0 / 2.2) * 255.0) as u8))
    });
    photo.save(scene.join("image.png")).unwrap();
    let board = 64 * 64;
    let mask_count = |dir: &Path| {
        image::open(dir.join("mask.png"))
            .unwrap()
            .to_luma8()
            .pixels()
            .filter(|p| p.0[0] > 127)
            .count()
    };
    let run = |name: &str, extra: &[&str]| {
        let out = tmp.path().join(name);
        let mut args = vec![
            "extract",
            "--elements",
            scene.to_str().unwrap(),
            "--pick",
            "51,31",
            "--uv",
            "plane",
            "--out",
            out.to_str().unwrap(),
        ];
        args.extend_from_slice(extra);
        let o = picker(args);
        assert_ok(&o);
        let m: serde_json::Value =
            serde_json::from_slice(&std::fs::read(out.join("material.json")).unwrap()).unwrap();
        (out, o, m)
    };
    let (out, o, m) = run("board", &[]);
    let n = mask_count(&out);
    assert!((n as f64 - board as f64).abs() < 0.02 * board as f64, "{n}");
    assert_eq!(
        m["diagnostics"]["pattern"]["merged"], true,
        "{}",
        m["diagnostics"]
    );
    assert!(stderr(&o).contains("two-colour pattern"), "{}", stderr(&o));
    // The texture is a checker: about half its texels light.
    let light_share = |dir: &Path| {
        let t = image::open(dir.join("texture.png")).unwrap().to_luma8();
        t.pixels().filter(|p| p.0[0] > 128).count() as f64 / t.pixels().len() as f64
    };
    let s = light_share(&out);
    assert!((0.35..0.65).contains(&s), "{s}");
    let (out, o, m) = run("dark", &["--no-pattern"]);
    let n = mask_count(&out);
    // The dark squares (the leak guard's relief leaves out some of their
    // corners, where four squares meet).
    assert!(
        n <= board / 2 && n as f64 > 0.85 * board as f64 / 2.0,
        "{n}"
    );
    assert!(
        m["diagnostics"]["pattern"].is_null(),
        "{}",
        m["diagnostics"]
    );
    assert!(!stderr(&o).contains("two-colour pattern"), "{}", stderr(&o));
    let s = light_share(&out);
    assert!(s < 0.1, "{s}");
}

/// A photo whose lines contradict the plane the elements give (vertical
/// stripes seen head-on, normals saying a floor): the refused turn is in
/// `material.json`, and `picker extract` suggests giving the plane, in
/// `summary.json` and on stderr, and says how little of the texture the
/// photo shows; the README's wall gets no hint.
#[test]
fn a_plane_the_lines_contradict_brings_a_hint() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = tmp.path().join("scene");
    copy_fixture_scene(&scene);
    let (w, h) = png_size(&scene.join("image.png"));
    let (w, h) = (w as usize, h as usize);
    write_rgb_exr(&scene.join("normals.exr"), w, h, |_, _| [0.0, 1.0, 0.05]);
    write_rgb_exr(&scene.join("segmentation.exr"), w, h, |_, _| [0.5; 3]);
    let stripes = image::RgbImage::from_fn(320, 240, |x, _| {
        image::Rgb([if (x / 16) % 2 == 0 { 200 } else { 50 }; 3])
    });
    stripes.save(scene.join("image.png")).unwrap();
    let out = tmp.path().join("o");
    let o = picker([
        "extract",
        "--elements",
        scene.to_str().unwrap(),
        "--pick",
        "160,120",
        "--uv",
        "plane",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_ok(&o);
    let m: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("material.json")).unwrap()).unwrap();
    let turn = m["diagnostics"]["uv"]["lines"]["refused_turn_deg"]
        .as_f64()
        .unwrap_or_else(|| panic!("{}", m["diagnostics"]["uv"]));
    assert!(turn > 80.0, "{turn}");
    let s: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("summary.json")).unwrap()).unwrap();
    let hint = s["materials"][0]["hints"][0].as_str().unwrap_or_default();
    assert!(
        hint.contains("--normal front") && hint.contains("--quad"),
        "{s}"
    );
    assert!(
        stderr(&o).contains("hint: material_0: the photo's lines"),
        "{}",
        stderr(&o)
    );
    assert!(!stderr(&o).contains("the photo shows"), "{}", stderr(&o));

    // A material that is a thin diagonal band (one or two pixels a row),
    // facing the camera: no square on it is mostly seen, not even the best
    // covered one framed, and that is said.
    write_rgb_exr(&scene.join("normals.exr"), w, h, |_, _| [0.0, 0.0, 1.0]);
    write_rgb_exr(&scene.join("segmentation.exr"), w, h, |x, y| {
        let on = (x as f64 - y as f64 * w as f64 / h as f64).abs() < 0.8;
        if on {
            [0.9, 0.1, 0.1]
        } else {
            [0.1, 0.1, 0.9]
        }
    });
    let band = tmp.path().join("band");
    let o = picker([
        "extract",
        "--elements",
        scene.to_str().unwrap(),
        "--pick",
        "160,120",
        "--uv",
        "plane",
        "--out",
        band.to_str().unwrap(),
    ]);
    assert_ok(&o);
    let m: serde_json::Value =
        serde_json::from_slice(&std::fs::read(band.join("material.json")).unwrap()).unwrap();
    let coverage = m["texture"]["coverage_fraction"].as_f64().unwrap();
    assert!(coverage < 0.25, "{coverage}");
    let said = format!(
        "hint: material_0: the photo shows {:.0} % of the texture",
        100.0 * coverage
    );
    assert!(stderr(&o).contains(&said), "{}", stderr(&o));

    let o = picker([
        "extract",
        root().join("fixtures/examples/room.png").to_str().unwrap(),
        "--pick",
        "200,150",
        "--out",
        tmp.path().join("room").to_str().unwrap(),
    ]);
    assert_ok(&o);
    assert!(!stderr(&o).contains("hint"), "{}", stderr(&o));
}

/// Float images with no finite value, segmentations with NaN and
/// environment maps without any light are refused, naming the file; nothing is written.
#[test]
fn non_finite_and_lightless_float_inputs_are_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("o");
    let nan = tmp.path().join("allnan.exr");
    write_rgb_exr(&nan, 16, 12, |_, _| [f32::NAN; 3]);
    let w = tiny_weights();
    let o = picker([
        "extract",
        nan.to_str().unwrap(),
        "--weights",
        w.to_str().unwrap(),
        "--pick",
        "1,1",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_error_names(&o, "allnan.exr");
    assert!(stderr(&o).contains("NaN or infinite"), "{}", stderr(&o));
    assert!(!out.exists());
    // A photo with a few NaN pixels still runs (they become 0, as documented).
    let some = tmp.path().join("some.exr");
    write_rgb_exr(&some, 16, 12, |x, y| {
        if x == y {
            [f32::NAN; 3]
        } else {
            [0.2 + 0.01 * x as f32, 0.3, 0.4]
        }
    });
    assert_ok(&picker([
        "extract",
        some.to_str().unwrap(),
        "--weights",
        w.to_str().unwrap(),
        "--pick",
        "3,1",
        "--out",
        out.to_str().unwrap(),
    ]));
    // Ground-truth elements whose segmentation is NaN.
    let el = tmp.path().join("el");
    copy_fixture_scene(&el);
    let (sw, sh) = png_size(&el.join("image.png"));
    write_rgb_exr(
        &el.join("segmentation.exr"),
        sw as usize,
        sh as usize,
        |_, _| [f32::NAN; 3],
    );
    let out2 = tmp.path().join("o2");
    let o = picker([
        "extract",
        "--elements",
        el.to_str().unwrap(),
        "--pick",
        "5,5",
        "--out",
        out2.to_str().unwrap(),
    ]);
    assert_error_names(&o, "segmentation.exr");
    assert!(!out2.exists());
    // A negative environment map for `render`: refused, no output folder.
    let env = tmp.path().join("neg.exr");
    write_rgb_exr(&env, 8, 4, |x, _| [-1.0 - x as f32, 0.0, -0.5]);
    let out3 = tmp.path().join("o3");
    let o = picker([
        "render",
        "--preview",
        "--envmap",
        env.to_str().unwrap(),
        "--diffuse",
        "0.5,0.5,0.5",
        "--specular",
        "0,0,0",
        "--exponent",
        "10",
        "--out",
        out3.to_str().unwrap(),
    ]);
    assert_error_names(&o, "neg.exr");
    assert!(stderr(&o).contains("holds no light"), "{}", stderr(&o));
    assert!(!out3.exists());
}

/// A run that fails after writing some files, or is interrupted, leaves
/// nothing new: the files are staged and moved into place together.
#[test]
fn failed_and_interrupted_extractions_leave_no_partial_result() {
    let tmp = tempfile::tempdir().unwrap();
    let w = tiny_weights();
    let photo = example_photo();
    let run_into = |out: &Path, extra: &[&str]| {
        let mut args = vec![
            "extract",
            photo.to_str().unwrap(),
            "--weights",
            w.to_str().unwrap(),
            "--pick",
            "10,10",
            "--no-timings",
            "--out",
            out.to_str().unwrap(),
        ];
        args.extend_from_slice(extra);
        picker(args)
    };
    let entries = |d: &Path| -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(d)
            .unwrap()
            .flatten()
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    };
    // A folder where a file goes: refused before anything moves; the
    // folder's other contents are untouched.
    let out = tmp.path().join("clash");
    std::fs::create_dir_all(out.join("material.json")).unwrap();
    std::fs::write(out.join("texture.png"), b"older").unwrap();
    let o = run_into(&out, &[]);
    assert_error_names(&o, "material.json");
    assert_eq!(entries(&out), ["material.json", "texture.png"]);
    assert_eq!(std::fs::read(out.join("texture.png")).unwrap(), b"older");
    // `picker infer` stages its set the same way.
    let inf = tmp.path().join("infer");
    std::fs::create_dir_all(inf.join("manifest.json")).unwrap();
    let o = picker([
        "infer",
        photo.to_str().unwrap(),
        "--weights",
        w.to_str().unwrap(),
        "--out",
        inf.to_str().unwrap(),
    ]);
    assert_error_names(&o, "manifest.json");
    assert_eq!(entries(&inf), ["manifest.json"]);
    // A good run replaces the older files and leaves no hidden entry.
    let good = tmp.path().join("good");
    std::fs::create_dir_all(&good).unwrap();
    std::fs::write(good.join("preview.png"), b"older").unwrap();
    assert_ok(&run_into(&good, &[]));
    assert!(
        entries(&good).iter().all(|n| !n.starts_with('.')),
        "{:?}",
        entries(&good)
    );
    assert!(entries(&good).contains(&"summary.json".to_string()));
    assert_ne!(std::fs::read(good.join("preview.png")).unwrap(), b"older");

    #[cfg(unix)]
    {
        use std::time::{Duration, Instant};
        // Interrupted once its staging folder exists: SIGTERM removes it
        // (and the output folder the run made); SIGKILL cannot, and the
        // next run into the folder removes what it left.
        for (signal, out) in [
            ("TERM", tmp.path().join("term")),
            ("KILL", tmp.path().join("kill")),
        ] {
            // A textured wall of a ground-truth scene at a 1024-texel size:
            // about 2 s of inpainting after the staging folder appears.
            let scene = root().join("fixtures/synth/scene_000000");
            let mut child = Command::new(env!("CARGO_BIN_EXE_picker"))
                .args([
                    "extract",
                    "--elements",
                    scene.to_str().unwrap(),
                    "--pick",
                    "16,20",
                    "--size",
                    "1024",
                    "--out",
                    out.to_str().unwrap(),
                ])
                .env("RAYON_NUM_THREADS", "2")
                .stdout(std::process::Stdio::null())
                .stderr(std::process::Stdio::null())
                .spawn()
                .unwrap();
            let staged = || {
                out.is_dir()
                    && std::fs::read_dir(&out).unwrap().flatten().any(|e| {
                        e.file_name()
                            .to_string_lossy()
                            .starts_with(".picker-partial-")
                    })
            };
            let t0 = Instant::now();
            while !staged() && t0.elapsed() < Duration::from_secs(60) {
                if child.try_wait().unwrap().is_some() {
                    break;
                }
                std::thread::sleep(Duration::from_millis(2));
            }
            let early = child.try_wait().unwrap().is_some();
            let killed = Command::new("kill")
                .args([format!("-{signal}"), child.id().to_string()])
                .status()
                .unwrap();
            let status = child.wait().unwrap();
            assert!(
                !early && killed.success(),
                "the run ended before the signal"
            );
            if signal == "TERM" {
                assert_eq!(status.code(), Some(130));
                assert!(!out.exists(), "{:?}", entries(&out));
            } else {
                assert!(staged(), "SIGKILL leaves the staging folder");
                assert_ok(&run_into(&out, &[]));
                assert!(
                    entries(&out).iter().all(|n| !n.starts_with('.')),
                    "{:?}",
                    entries(&out)
                );
            }
        }
    }
}

/// With the mirror pass (the default), each network also runs on the
/// mirrored photo and the outputs that mirror with it are averaged
/// (`picker_nets::mirror`): so the outputs for the mirrored photo are the
/// photo's outputs mirrored, bit for bit (the x component of the normals and
/// view vectors negated; the environment map mirrored in longitude), which
/// a network run once does not give. The texture coordinates and the material
/// embedding, which have no mirror relation, are the first pass's: the same
/// as with `--single-pass`. The manifest says which was run.
#[test]
fn the_mirror_pass_makes_the_outputs_mirror_with_the_photo() {
    let dir = tempfile::tempdir().unwrap();
    // 320×240, the working size: no resampling between the two photos.
    let photo = root().join("fixtures/examples/room.png");
    let mirrored = dir.path().join("mirrored.png");
    image::imageops::flip_horizontal(&image::open(&photo).unwrap().to_rgb8())
        .save(&mirrored)
        .unwrap();
    let run = |p: &Path, name: &str, extra: &[&str]| {
        let out = dir.path().join(name);
        let mut args: Vec<std::ffi::OsString> = vec![
            "infer".into(),
            p.into(),
            "--out".into(),
            out.as_os_str().into(),
        ];
        args.extend(extra.iter().map(Into::into));
        assert_ok(&picker(args));
        let m: serde_json::Value =
            serde_json::from_slice(&std::fs::read(out.join("manifest.json")).unwrap()).unwrap();
        (out, m["mirror_pass"].as_bool())
    };
    let (a, ma) = run(&photo, "a", &[]);
    let (b, mb) = run(&mirrored, "b", &[]);
    let (s, ms) = run(&photo, "s", &["--single-pass"]);
    let (t, _) = run(&mirrored, "t", &["--single-pass"]);
    assert_eq!((ma, mb, ms), (Some(true), Some(true), Some(false)));
    let exr = |dir: &Path, name: &str| {
        picker_render::io::read_exr(&dir.join(format!("{name}.exr"))).unwrap()
    };
    // Whether `q` is `p` mirrored (channel 0 negated when `negate_x`).
    let mirrors = |p: &picker_render::Image, q: &picker_render::Image, negate_x: bool| {
        let (w, h) = (p.width, p.height);
        (0..p.channels).all(|c| {
            (0..h * w).all(|i| {
                let (x, y) = (i % w, i / w);
                let v = p.data[c * h * w + y * w + (w - 1 - x)];
                let v = if negate_x && c == 0 { -v } else { v };
                q.data[c * h * w + i].to_bits() == v.to_bits()
            })
        })
    };
    for (name, negate_x) in [
        ("diffuse_albedo", false),
        ("specular_albedo", false),
        ("glossiness", false),
        ("normals", true),
        ("view_vector", true),
        ("segmentation", false),
        ("envmap", false),
    ] {
        assert!(mirrors(&exr(&a, name), &exr(&b, name), negate_x), "{name}");
    }
    assert!(
        !mirrors(
            &exr(&s, "diffuse_albedo"),
            &exr(&t, "diffuse_albedo"),
            false
        ),
        "one pass is not mirror-symmetric by itself"
    );
    for name in ["uv", "embedding"] {
        assert_eq!(exr(&a, name), exr(&s, name), "{name}: the first pass's");
    }
    // The passes' disagreement: written only with two passes, and the same
    // for the photo and its mirror image (mirrored).
    for name in ["disagreement_albedo", "disagreement_normals"] {
        assert!(!s.join(format!("{name}.exr")).exists(), "{name}");
        assert!(mirrors(&exr(&a, name), &exr(&b, name), false), "{name}");
    }
    assert_ne!(exr(&a, "diffuse_albedo"), exr(&s, "diffuse_albedo"));
}
