//! `picker batch` end to end: a folder of good photos in every supported
//! format with broken files of every kind mixed in, a killed-then-resumed run
//! against an uninterrupted one (byte-identical outputs), Ctrl-C, shards,
//! `--jobs`, staleness and usage errors.
//!
//! The CI test uses 40 photos; `batch_300_photos_kill_and_resume` (ignored,
//! run with `cargo test --release -p picker-cli --test batch -- --ignored`)
//! does the 300 photos with 5% broken files.

use sha2::{Digest, Sha256};
use std::collections::BTreeMap;
use std::io::Cursor;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use image::{DynamicImage, ImageFormat, Rgb, RgbImage};
use serde_json::Value;

fn picker() -> Command {
    Command::new(env!("CARGO_BIN_EXE_picker"))
}

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn weights() -> String {
    repo().join("fixtures/weights/tiny").display().to_string()
}

/// A small deterministic "photo": a floor, a wall and a box with noise.
fn photo(seed: u64, w: u32, h: u32) -> RgbImage {
    let mut s = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    let mut rnd = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 40) as f32 / (1u64 << 24) as f32
    };
    let wall = [rnd(), rnd(), rnd()];
    let floor = [rnd(), rnd(), rnd()];
    let boxc = [rnd(), rnd(), rnd()];
    let horizon = 0.4 + 0.3 * rnd();
    let (bx, by) = (rnd() * 0.5, 0.3 + rnd() * 0.4);
    RgbImage::from_fn(w, h, |x, y| {
        let (u, v) = (x as f32 / w as f32, y as f32 / h as f32);
        let base = if u > bx && u < bx + 0.3 && v > by && v < by + 0.25 {
            boxc
        } else if v > horizon {
            let check = ((x / 6 + y / 6) % 2) as f32 * 0.15;
            [floor[0] + check, floor[1] + check, floor[2] + check]
        } else {
            wall
        };
        let n = (rnd() - 0.5) * 0.06;
        Rgb(base.map(|c| ((c + n).clamp(0.0, 1.0) * 255.0) as u8))
    })
}

fn encode(img: DynamicImage, f: ImageFormat) -> Vec<u8> {
    let mut b = Cursor::new(Vec::new());
    img.write_to(&mut b, f).unwrap();
    b.into_inner()
}

fn crc32(bytes: &[u8]) -> u32 {
    let mut c = !0u32;
    for &b in bytes {
        c ^= b as u32;
        for _ in 0..8 {
            c = if c & 1 != 0 {
                0xEDB8_8320 ^ (c >> 1)
            } else {
                c >> 1
            };
        }
    }
    !c
}

/// A PNG whose header claims `w × h` (a decompression bomb's calling card).
fn bomb_png(w: u32, h: u32) -> Vec<u8> {
    let mut png = encode(DynamicImage::ImageRgb8(photo(1, 8, 8)), ImageFormat::Png);
    png[16..20].copy_from_slice(&w.to_be_bytes());
    png[20..24].copy_from_slice(&h.to_be_bytes());
    let crc = crc32(&png[12..29]);
    png[29..33].copy_from_slice(&crc.to_be_bytes());
    png
}

/// Writes `n` photos under `dir` (about 5% of them broken, every kind), and
/// `picks.csv`. Returns the relative paths of the broken files.
fn make_folder(dir: &Path, n: usize) -> Vec<String> {
    let good = [
        ("png", ImageFormat::Png),
        ("jpg", ImageFormat::Jpeg),
        ("tif", ImageFormat::Tiff),
        ("webp", ImageFormat::WebP),
        ("bmp", ImageFormat::Bmp),
    ];
    let good_png = encode(DynamicImage::ImageRgb8(photo(7, 48, 36)), ImageFormat::Png);
    let good_jpg = encode(DynamicImage::ImageRgb8(photo(8, 48, 36)), ImageFormat::Jpeg);
    let good_tif = encode(DynamicImage::ImageRgb8(photo(9, 48, 36)), ImageFormat::Tiff);
    let mut corrupt = good_png.clone();
    let mid = corrupt.len() / 2;
    for b in &mut corrupt[mid..mid + 16] {
        *b ^= 0x5A;
    }
    let broken: Vec<(&str, Vec<u8>)> = vec![
        ("empty.png", Vec::new()),
        ("truncated.png", good_png[..good_png.len() / 2].to_vec()),
        ("truncated.jpg", good_jpg[..good_jpg.len() / 2].to_vec()),
        ("truncated.tif", good_tif[..good_tif.len() / 3].to_vec()),
        ("text.jpg", b"this is not a photo\n".to_vec()),
        (
            "pdf.png",
            b"%PDF-1.7\n%\xe2\xe3\xcf\xd3\n1 0 obj\n".to_vec(),
        ),
        (
            "random.webp",
            (0..4000u32)
                .map(|i| (i.wrapping_mul(2654435761) >> 13) as u8)
                .collect(),
        ),
        ("bomb.png", bomb_png(100_000, 100_000)),
        ("corrupt.png", corrupt),
    ];
    let n_broken = (n / 20).max(broken.len().min(n / 4)).min(broken.len() * 4);
    let mut csv = String::from("file,x,y,name\n");
    let mut broken_names = Vec::new();
    for k in 0..n_broken {
        let (name, bytes) = &broken[k % broken.len()];
        let rel = format!("broken/{k:02}_{name}");
        std::fs::create_dir_all(dir.join("broken")).unwrap();
        std::fs::write(dir.join(&rel), bytes).unwrap();
        csv.push_str(&format!("{rel},4,4\n"));
        broken_names.push(rel);
    }
    for k in 0..n - n_broken {
        let (ext, fmt) = good[k % good.len()];
        let (w, h) = (40 + (k as u32 * 7) % 40, 30 + (k as u32 * 5) % 30);
        let img = photo(k as u64 + 100, w, h);
        let img = match k % 7 {
            3 if fmt == ImageFormat::Png => {
                DynamicImage::ImageLuma16(DynamicImage::ImageRgb8(img).to_luma16())
            }
            5 if fmt == ImageFormat::Png => {
                DynamicImage::ImageRgba8(DynamicImage::ImageRgb8(img).to_rgba8())
            }
            _ => DynamicImage::ImageRgb8(img),
        };
        let rel = format!("set{}/photo_{k:03}.{ext}", k % 3);
        std::fs::create_dir_all(dir.join(format!("set{}", k % 3))).unwrap();
        std::fs::write(dir.join(&rel), encode(img, fmt)).unwrap();
        csv.push_str(&format!("{rel},{},{},centre\n", w / 2, h / 2));
        if k % 4 == 0 {
            csv.push_str(&format!("{rel},{},{},floor\n", w / 3, h - 2));
        }
    }
    std::fs::write(dir.join("README.txt"), "not an image; ignored\n").unwrap();
    std::fs::write(dir.parent().unwrap().join("picks.csv"), csv).unwrap();
    broken_names
}

fn batch_cmd(input: &Path, out: &Path, extra: &[&str]) -> Command {
    let mut c = picker();
    c.arg("batch")
        .arg(input)
        .arg("--out")
        .arg(out)
        .arg("--picks")
        .arg(input.parent().unwrap().join("picks.csv"))
        .args([
            "--weights",
            &weights(),
            "--work-size",
            "48",
            "--max-size",
            "32",
        ])
        .args(extra);
    c
}

fn run(mut c: Command) -> Output {
    c.output().expect("runs picker")
}

/// Every file under `dir` but the batch reports, with its bytes.
fn tree(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    let mut out = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else {
                let rel = p.strip_prefix(dir).unwrap().display().to_string();
                if !rel.starts_with("batch-report") {
                    out.insert(rel, std::fs::read(&p).unwrap());
                }
            }
        }
    }
    out
}

fn assert_same_tree(a: &Path, b: &Path) {
    let (ta, tb) = (tree(a), tree(b));
    let ka: Vec<_> = ta.keys().collect();
    let kb: Vec<_> = tb.keys().collect();
    assert_eq!(ka, kb, "the two runs wrote different files");
    for (k, v) in &ta {
        assert!(tb[k] == *v, "{k} differs between the runs");
    }
}

fn report(out: &Path) -> Value {
    serde_json::from_slice(&std::fs::read(out.join("batch-report.json")).unwrap()).unwrap()
}

/// Finished photos (visible folders with a manifest), tolerant of a batch
/// renaming folders while it is counted.
fn manifests(out: &Path) -> usize {
    let mut n = 0;
    let mut stack = vec![out.to_path_buf()];
    while let Some(d) = stack.pop() {
        let Ok(rd) = std::fs::read_dir(&d) else {
            continue;
        };
        for e in rd.flatten() {
            let name = e.file_name().to_string_lossy().into_owned();
            if name.starts_with('.') {
                continue;
            }
            if name.ends_with(".material") {
                n += e.path().join("manifest.json").exists() as usize;
            } else if e.path().is_dir() {
                stack.push(e.path());
            }
        }
    }
    n
}

/// Checks the invariant of an interrupted run: every visible photo folder is
/// complete (has its manifest); partial work is only in hidden folders.
fn assert_only_whole_results(out: &Path) {
    for k in tree(out).keys() {
        if k.split('/').any(|c| c.starts_with('.')) {
            continue;
        }
        let photo_dir = k.split(".material/").next().unwrap();
        if k.contains(".material/") {
            assert!(
                out.join(format!("{photo_dir}.material/manifest.json"))
                    .exists(),
                "{k} is visible but its photo folder has no manifest"
            );
        }
    }
}

fn check_batch(n: usize, kill_at: usize) {
    let tmp = tempfile::tempdir().unwrap();
    let input = tmp.path().join("photos");
    std::fs::create_dir_all(&input).unwrap();
    let broken = make_folder(&input, n);

    // 1. Uninterrupted.
    let out_a = tmp.path().join("a");
    let o = run(batch_cmd(&input, &out_a, &[]));
    assert_eq!(
        o.status.code(),
        Some(1),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let r = report(&out_a);
    assert_eq!(r["counts"]["photos"], n as u64);
    assert_eq!(r["counts"]["failed"], broken.len() as u64, "{r:#}");
    assert_eq!(r["counts"]["ok"], (n - broken.len()) as u64, "{r:#}");
    let stderr = String::from_utf8_lossy(&o.stderr);
    for row in r["photos"].as_array().unwrap() {
        if row["status"] == "failed" {
            let why = row["reason"].as_str().unwrap();
            let name = row["photo"].as_str().unwrap();
            assert!(why.contains(name), "the reason names the file: {why}");
            assert!(!why.contains('\n'), "one line: {why}");
            assert!(stderr.contains(why), "the summary lists {why}");
        }
    }
    let why = |needle: &str| {
        r["photos"]
            .as_array()
            .unwrap()
            .iter()
            .find(|p| p["photo"].as_str().unwrap().contains(needle))
            .map(|p| p["reason"].as_str().unwrap().to_lowercase())
            .unwrap()
    };
    assert!(why("empty.png").contains("empty"));
    assert!(why("bomb.png").contains("megapixel"), "{}", why("bomb.png"));
    assert!(
        why("truncated.jpg").contains("truncated"),
        "{}",
        why("truncated.jpg")
    );

    // 2. Killed (SIGKILL, the worst case) then resumed.
    let out_b = tmp.path().join("b");
    let mut child = batch_cmd(&input, &out_b, &["--quiet"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let t = Instant::now();
    while manifests(&out_b) < kill_at && t.elapsed() < Duration::from_secs(120) {
        if child.try_wait().unwrap().is_some() {
            break;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let _ = child.kill();
    let _ = child.wait();
    let done_before = manifests(&out_b);
    assert!(
        done_before < n - broken.len(),
        "killed too late to test resume ({done_before})"
    );
    assert_only_whole_results(&out_b);
    let o = run(batch_cmd(&input, &out_b, &[]));
    assert_eq!(o.status.code(), Some(1));
    let r = report(&out_b);
    assert_eq!(r["counts"]["up_to_date"], done_before as u64, "{r:#}");
    assert_eq!(
        r["counts"]["ok"],
        (n - broken.len() - done_before) as u64,
        "{r:#}"
    );
    assert_same_tree(&out_a, &out_b);

    // 3. A re-run does nothing and changes nothing.
    let o = run(batch_cmd(&input, &out_b, &[]));
    assert_eq!(o.status.code(), Some(1));
    assert_eq!(report(&out_b)["counts"]["ok"], 0);
    assert_same_tree(&out_a, &out_b);
}

#[test]
fn batch_with_broken_files_kill_and_resume() {
    check_batch(40, 8);
}

#[test]
#[ignore = "the issue's full 300-photo run (about a minute in release)"]
fn batch_300_photos_kill_and_resume() {
    check_batch(300, 100);
}

#[test]
fn interrupt_stops_cleanly_and_resumes() {
    let tmp = tempfile::tempdir().unwrap();
    let input = tmp.path().join("photos");
    std::fs::create_dir_all(&input).unwrap();
    make_folder(&input, 30);
    let out = tmp.path().join("out");
    let child = batch_cmd(&input, &out, &["--quiet", "--jobs", "1"])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let t = Instant::now();
    while manifests(&out) < 3 && t.elapsed() < Duration::from_secs(60) {
        std::thread::sleep(Duration::from_millis(10));
    }
    let st = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(st.success());
    let o = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(130), "{stderr}");
    assert!(stderr.contains("interrupted"), "{stderr}");
    let r = report(&out);
    assert_eq!(r["interrupted"], true);
    assert!(r["counts"]["not_started"].as_u64().unwrap() > 0, "{r:#}");
    // No partial folder is left behind by a clean stop.
    for k in tree(&out).keys() {
        assert!(!k.contains(".partial"), "{k}");
    }
    assert_only_whole_results(&out);
    let o = run(batch_cmd(&input, &out, &[]));
    assert_eq!(o.status.code(), Some(1));
    let r = report(&out);
    assert_eq!(r["counts"]["not_started"], 0);
    assert!(r["counts"]["up_to_date"].as_u64().unwrap() >= 3);
}

#[test]
fn shards_jobs_and_staleness() {
    let tmp = tempfile::tempdir().unwrap();
    let input = tmp.path().join("photos");
    std::fs::create_dir_all(&input).unwrap();
    make_folder(&input, 16);
    let full = tmp.path().join("full");
    assert_eq!(
        run(batch_cmd(&input, &full, &["--jobs", "2", "--threads", "2"]))
            .status
            .code(),
        Some(1)
    );
    // Three shards into one folder (as three machines would) make the same tree.
    let sharded = tmp.path().join("sharded");
    let mut seen = 0;
    for k in 0..3 {
        let shard = format!("{k}/3");
        let o = run(batch_cmd(
            &input,
            &sharded,
            &["--shard", &shard, "--jobs", "1"],
        ));
        assert!(matches!(o.status.code(), Some(0 | 1)));
        let r: Value = serde_json::from_slice(
            &std::fs::read(sharded.join(format!("batch-report.shard-{k}-of-3.json"))).unwrap(),
        )
        .unwrap();
        seen += r["counts"]["photos"].as_u64().unwrap();
    }
    assert_eq!(seen, 16, "every photo in exactly one shard");
    assert_same_tree(&full, &sharded);

    // Changing a photo or a setting redoes exactly what is stale.
    let victim = input.join("set0/photo_000.png");
    let img = image::open(&victim).unwrap().to_rgb8();
    let mut img2 = img.clone();
    img2.put_pixel(0, 0, Rgb([255, 0, 255]));
    img2.save(&victim).unwrap();
    let o = run(batch_cmd(&input, &full, &[]));
    assert_eq!(o.status.code(), Some(1));
    let r = report(&full);
    assert_eq!(r["counts"]["ok"], 1, "{r:#}");
    let o = run(batch_cmd(&input, &full, &["--seed", "5"]));
    assert_eq!(o.status.code(), Some(1));
    let r = report(&full);
    assert_eq!(r["counts"]["up_to_date"], 0, "{r:#}");
    // A half-deleted result is redone.
    let o = run(batch_cmd(&input, &full, &["--seed", "5"]));
    assert_eq!(
        report(&full)["counts"]["ok"],
        0,
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    std::fs::remove_file(full.join("set0/photo_000.png.material/centre/material.json")).unwrap();
    run(batch_cmd(&input, &full, &["--seed", "5"]));
    assert_eq!(report(&full)["counts"]["ok"], 1);
    // The extraction's switches are settings too: each redoes every photo.
    for flag in [
        "--no-lines",
        "--no-grain",
        "--no-fold",
        "--no-centring",
        "--no-pattern",
        "--no-split",
        "--no-mask-fill",
        "--keep-seams",
    ] {
        run(batch_cmd(&input, &full, &["--seed", "5", flag]));
        let r = report(&full);
        assert_eq!(r["counts"]["up_to_date"], 0, "{flag}: {r:#}");
    }
    // The key holds the running binary's digest: another build (here a
    // manifest tampered to say so) redoes the photo, the rest stay.
    let manifest_path = full.join("set0/photo_000.png.material/manifest.json");
    let mut m: Value = serde_json::from_slice(&std::fs::read(&manifest_path).unwrap()).unwrap();
    let exe = std::fs::read(env!("CARGO_BIN_EXE_picker")).unwrap();
    let want: String = Sha256::digest(&exe)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect();
    assert_eq!(
        m["key"]["picker_build_sha256"].as_str(),
        Some(want.as_str())
    );
    m["key"]["picker_build_sha256"] = Value::from("0".repeat(64));
    std::fs::write(&manifest_path, serde_json::to_vec_pretty(&m).unwrap()).unwrap();
    run(batch_cmd(&input, &full, &["--seed", "5", "--keep-seams"]));
    let r = report(&full);
    assert_eq!(r["counts"]["ok"], 1, "{r:#}");
    assert_eq!(
        r["counts"]["up_to_date"],
        r["counts"]["photos"].as_u64().unwrap() - 1 - r["counts"]["failed"].as_u64().unwrap(),
        "{r:#}"
    );
}

#[test]
fn usage_errors_exit_2() {
    let tmp = tempfile::tempdir().unwrap();
    let input = tmp.path().join("photos");
    std::fs::create_dir_all(&input).unwrap();
    let out = tmp.path().join("out");
    let w = weights();
    let o = out.to_str().unwrap();
    let i = input.to_str().unwrap();
    // Picks files: a short row, and an absolute path (refused as one, not
    // as an unknown image).
    let bad = tmp.path().join("bad.csv");
    std::fs::write(&bad, "a.png,1\n").unwrap();
    let abs = tmp.path().join("abs.csv");
    std::fs::write(&abs, "/tmp/a.png,1,2\n").unwrap();
    let (bad, abs) = (bad.to_str().unwrap(), abs.to_str().unwrap());
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (vec!["batch", i, "--out", o, "--weights", &w], "--picks"),
        (
            vec![
                "batch",
                i,
                "--out",
                o,
                "--all",
                "--weights",
                &w,
                "--shard",
                "3/3",
            ],
            "K < N",
        ),
        (
            vec![
                "batch",
                "/nonexistent/dir",
                "--out",
                o,
                "--all",
                "--weights",
                &w,
            ],
            "not a folder",
        ),
        (
            vec!["batch", i, "--out", o, "--weights", &w, "--picks", bad],
            "bad.csv line 1",
        ),
        (
            vec!["batch", i, "--out", o, "--weights", &w, "--picks", abs],
            "must be a path inside IN_DIR",
        ),
        // A report path that is a folder, refused before any photo is made.
        (
            vec![
                "batch",
                i,
                "--out",
                o,
                "--weights",
                &w,
                "--all",
                "--report",
                i,
            ],
            "is a folder",
        ),
    ];
    for (args, want) in cases {
        let r = picker().args(&args).output().unwrap();
        let err = String::from_utf8_lossy(&r.stderr);
        assert_eq!(r.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains(want), "{args:?}: {err}");
    }
}

#[test]
fn embedded_default_weights_without_a_weights_flag() {
    let tmp = tempfile::tempdir().unwrap();
    let input = tmp.path().join("photos");
    std::fs::create_dir_all(&input).unwrap();
    photo(7, 64, 48).save(input.join("a.png")).unwrap();
    let picks = tmp.path().join("picks.csv");
    std::fs::write(&picks, "a.png,10,40\n").unwrap();
    let out = tmp.path().join("out");
    let r = picker()
        .args([
            "batch",
            input.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ])
        .args(["--picks", picks.to_str().unwrap()])
        .args(["--work-size", "48", "--max-size", "32", "--quiet"])
        .output()
        .unwrap();
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let m: Value =
        serde_json::from_slice(&std::fs::read(out.join("a.png.material/manifest.json")).unwrap())
            .unwrap();
    let files: Vec<&str> = m["weights"]
        .as_array()
        .unwrap()
        .iter()
        .map(|w| w["file"].as_str().unwrap())
        .collect();
    assert_eq!(
        files,
        [
            "<embedded lite>/irn.safetensors",
            "<embedded lite>/msn.safetensors",
            "<embedded lite>/envmap.safetensors"
        ]
    );
    // The manifest's digest is that of the committed file the binary embeds.
    for w in m["weights"].as_array().unwrap() {
        let name = w["file"].as_str().unwrap().rsplit('/').next().unwrap();
        let bytes = std::fs::read(repo().join("crates/picker-weights/weights").join(name)).unwrap();
        let want: String = Sha256::digest(&bytes)
            .iter()
            .map(|b| format!("{b:02x}"))
            .collect();
        assert_eq!(w["sha256"].as_str().unwrap(), want, "{name}");
    }
}

#[test]
fn completions_for_every_shell() {
    for shell in ["bash", "zsh", "fish", "elvish", "powershell"] {
        let o = picker().args(["completions", shell]).output().unwrap();
        assert!(o.status.success(), "{shell}");
        let text = String::from_utf8_lossy(&o.stdout);
        assert!(
            text.contains("batch") && text.contains("extract"),
            "{shell}"
        );
    }
}

/// Writes the test folder for a look by hand:
/// `PICKER_BATCH_FOLDER=/tmp/b PICKER_BATCH_PHOTOS=300 cargo test --release -p picker-cli --test batch -- --ignored write_folder`
/// makes `/tmp/b/photos/` and `/tmp/b/picks.csv`.
#[test]
#[ignore = "writes a folder for inspection when PICKER_BATCH_FOLDER is set"]
fn write_folder() {
    let Some(dir) = std::env::var_os("PICKER_BATCH_FOLDER") else {
        return;
    };
    let n = std::env::var("PICKER_BATCH_PHOTOS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(300);
    let input = Path::new(&dir).join("photos");
    std::fs::create_dir_all(&input).unwrap();
    make_folder(&input, n);
}

#[test]
fn output_inside_the_input_folder_is_not_read_back() {
    let tmp = tempfile::tempdir().unwrap();
    let input = tmp.path().join("photos");
    std::fs::create_dir_all(&input).unwrap();
    make_folder(&input, 6);
    let out = input.join("results");
    for _ in 0..2 {
        let o = run(batch_cmd(&input, &out, &["--all"]));
        assert!(
            matches!(o.status.code(), Some(0 | 1)),
            "{}",
            String::from_utf8_lossy(&o.stderr)
        );
        let r = report(&out);
        assert_eq!(r["counts"]["photos"], 6, "{r:#}");
        for p in r["photos"].as_array().unwrap() {
            assert!(!p["photo"].as_str().unwrap().starts_with("results/"), "{p}");
        }
    }
}

/// A full output disk stops the batch (every later photo would fail) and
/// loses nothing: visible results are whole, and a re-run with space resumes.
/// Needs a small tmpfs (root in a container); skipped, saying so, elsewhere.
#[test]
fn full_disk_stops_and_resumes() {
    let tmp = tempfile::tempdir().unwrap();
    let mnt = tmp.path().join("small");
    std::fs::create_dir_all(&mnt).unwrap();
    let mounted = Command::new("mount")
        .args(["-t", "tmpfs", "-o", "size=400k", "tmpfs"])
        .arg(&mnt)
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    if !mounted {
        eprintln!("SKIPPED full_disk_stops_and_resumes: cannot mount a small tmpfs here");
        return;
    }
    struct Unmount<'a>(&'a Path);
    impl Drop for Unmount<'_> {
        fn drop(&mut self) {
            let _ = Command::new("umount").arg(self.0).status();
        }
    }
    let _guard = Unmount(&mnt);
    let input = tmp.path().join("photos");
    std::fs::create_dir_all(&input).unwrap();
    make_folder(&input, 40);
    let out = mnt.join("out");
    let o = run(batch_cmd(&input, &out, &["--jobs", "1"]));
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("disk is full"), "{stderr}");
    assert!(stderr.contains("No space left"), "{stderr}");
    assert_only_whole_results(&out);
    let done = manifests(&out);
    assert!(done < 35, "the disk was meant to fill up ({done} done)");
    // Move the partial results to a roomy disk and resume there.
    let roomy = tmp.path().join("roomy");
    let cp = Command::new("cp")
        .arg("-a")
        .arg(&out)
        .arg(&roomy)
        .status()
        .unwrap();
    assert!(cp.success());
    let o = run(batch_cmd(&input, &roomy, &[]));
    assert_eq!(o.status.code(), Some(1));
    let r = report(&roomy);
    assert_eq!(r["counts"]["up_to_date"], done as u64, "{r:#}");
    assert_eq!(r["counts"]["not_started"], 0);
    let full = tmp.path().join("full");
    run(batch_cmd(&input, &full, &[]));
    assert_same_tree(&full, &roomy);
}

/// `--quads`: each listed photo's material is rectified on the plane of its
/// quad (the README example's wall: its true plane, the quad's centre as the
/// pick, its size in metres), a photo the quad does not fit fails alone, the
/// manifest holds the quad so changing its size redoes the photo, and a quad
/// with several picks for its photo, with `--all` or `--uv net` is refused.
#[test]
fn quads_give_each_photo_its_plane() {
    const WALL: &str = "150.060,180.020,287.172,202.513,275.140,104.832,152.810,121.572";
    let tmp = tempfile::tempdir().unwrap();
    let input = tmp.path().join("photos");
    std::fs::create_dir_all(input.join("sub")).unwrap();
    std::fs::copy(
        repo().join("fixtures/examples/room.png"),
        input.join("room.png"),
    )
    .unwrap();
    photo(3, 64, 48).save(input.join("sub/small.png")).unwrap();
    photo(4, 64, 48).save(input.join("other.png")).unwrap();
    let quads = tmp.path().join("quads.csv");
    let write_quads = |size: &str| {
        std::fs::write(
            &quads,
            format!(
                "file,x1,y1,x2,y2,x3,y3,x4,y4,size\nroom.png,{WALL},{size}\nsub/small.png,{WALL}\n"
            ),
        )
        .unwrap();
    };
    write_quads("800x440mm");
    let out = tmp.path().join("out");
    let batch = |extra: &[&str]| {
        picker()
            .args(["batch", input.to_str().unwrap(), "--out"])
            .arg(&out)
            .args(["--quads", quads.to_str().unwrap()])
            .args(["--weights", &weights(), "--max-size", "32", "--quiet"])
            .args(extra)
            .output()
            .unwrap()
    };
    let o = batch(&[]);
    assert_eq!(
        o.status.code(),
        Some(1),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let r = report(&out);
    assert_eq!(r["counts"]["ok"], 1, "{r:#}");
    assert_eq!(r["counts"]["failed"], 1, "{r:#}");
    assert_eq!(r["counts"]["skipped"], 1, "{r:#}");
    let text = r.to_string();
    assert!(text.contains("outside the 64x48 photo"), "{r:#}");
    let m: Value = serde_json::from_slice(
        &std::fs::read(out.join("room.png.material/material_0/material.json")).unwrap(),
    )
    .unwrap();
    let used = &m["diagnostics"]["uv"]["user_plane"];
    assert_eq!(used["source"], "quad", "{used}");
    let n: Vec<f64> = used["normal"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    let truth = [-0.632f64, 0.192, 0.750];
    let len = truth.iter().map(|v| v * v).sum::<f64>().sqrt();
    let cos: f64 = n.iter().zip(truth).map(|(a, b)| a * b / len).sum();
    assert!(cos.clamp(-1.0, 1.0).acos().to_degrees() < 0.5, "{used}");
    assert!(
        (used["size_ratio"].as_f64().unwrap() - 1.0).abs() < 0.01,
        "{used}"
    );
    assert!(m["texture"]["size_m"].is_array(), "{}", m["texture"]);
    // The pick is the quad's centre.
    let c: Vec<f64> = WALL.split(',').map(|v| v.parse().unwrap()).collect();
    let mean = |k: usize| ((c[k] + c[k + 2] + c[k + 4] + c[k + 6]) / 4.0).round();
    assert_eq!(
        m["pick"],
        serde_json::json!([mean(0) as u64, mean(1) as u64])
    );

    // Up to date; a new size redoes it.
    batch(&[]);
    assert_eq!(report(&out)["counts"]["up_to_date"], 1);
    write_quads("0.8x0.5");
    batch(&[]);
    let r = report(&out);
    assert_eq!(r["counts"]["ok"], 1, "{r:#}");
    let m: Value = serde_json::from_slice(
        &std::fs::read(out.join("room.png.material/material_0/material.json")).unwrap(),
    )
    .unwrap();
    let ratio = m["diagnostics"]["uv"]["user_plane"]["size_ratio"]
        .as_f64()
        .unwrap();
    assert!((ratio / (0.44 / 0.5) - 1.0).abs() < 0.02, "{ratio}");

    // --quad-masks: the quad's interior is the material (a perspective
    // crop); a changed setting, so the photo is redone.
    let o = batch(&["--quad-masks"]);
    assert_eq!(
        o.status.code(),
        Some(1),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let r = report(&out);
    assert_eq!(r["counts"]["ok"], 1, "{r:#}");
    let dir = out.join("room.png.material/material_0");
    let m: Value =
        serde_json::from_slice(&std::fs::read(dir.join("material.json")).unwrap()).unwrap();
    assert_eq!(m["diagnostics"]["mask_given"], true);
    assert_eq!(m["given_mask"], "the --quad's interior");
    let mask = image::open(dir.join("mask.png")).unwrap().to_luma8();
    let set = mask.pixels().filter(|p| p.0[0] > 127).count() as f64;
    // The quad's area (shoelace, on the corners' continuous points) within
    // its perimeter.
    let p: Vec<(f64, f64)> = c.chunks(2).map(|v| (v[0] + 0.5, v[1] + 0.5)).collect();
    let area = (0..4)
        .map(|k| p[k].0 * p[(k + 1) % 4].1 - p[(k + 1) % 4].0 * p[k].1)
        .sum::<f64>()
        .abs()
        / 2.0;
    let perimeter: f64 = (0..4)
        .map(|k| ((p[(k + 1) % 4].0 - p[k].0).powi(2) + (p[(k + 1) % 4].1 - p[k].1).powi(2)).sqrt())
        .sum();
    assert!((set - area).abs() < perimeter, "{set} vs {area}");

    // Refused before any photo is made.
    let picks = tmp.path().join("picks.csv");
    std::fs::write(&picks, "room.png,200,150\nroom.png,100,200\n").unwrap();
    let fresh = tmp.path().join("fresh");
    for (extra, want) in [
        (
            vec!["--picks", picks.to_str().unwrap()],
            "--picks has 2 picks",
        ),
        (vec!["--all"], "--all"),
        (vec!["--uv", "net"], "--uv net"),
    ] {
        let o = picker()
            .args(["batch", input.to_str().unwrap(), "--out"])
            .arg(&fresh)
            .args(["--quads", quads.to_str().unwrap(), "--weights", &weights()])
            .args(&extra)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{extra:?}: {err}");
        assert!(err.contains(want), "{extra:?}: {err}");
        assert!(!fresh.join("room.png.material").exists(), "{extra:?}");
    }
}

/// `--normals`: a listed photo's material is rectified on its given plane
/// (`front`, or a normal) and the others on the predicted one; a row
/// overrides `--normal`; the normal is in the manifest (a changed one redoes
/// the photo, the others stay up to date); a photo with both a quad and a
/// normal, a listed photo that is not there, and `--uv net` are refused.
#[test]
fn normals_give_each_photo_its_plane() {
    let tmp = tempfile::tempdir().unwrap();
    let input = tmp.path().join("photos");
    std::fs::create_dir_all(input.join("sub")).unwrap();
    photo(6, 64, 48).save(input.join("sub/scan.png")).unwrap();
    photo(7, 64, 48).save(input.join("floor.png")).unwrap();
    photo(8, 64, 48).save(input.join("other.png")).unwrap();
    let picks = tmp.path().join("picks.csv");
    std::fs::write(
        &picks,
        "sub/scan.png,30,20\nfloor.png,30,30\nother.png,20,20\n",
    )
    .unwrap();
    let normals = tmp.path().join("normals.csv");
    let write_normals = |floor: &str| {
        std::fs::write(
            &normals,
            format!("file,normal\nsub/scan.png,front\nfloor.png,{floor}\n"),
        )
        .unwrap();
    };
    write_normals("0,1,0.3");
    let out = tmp.path().join("out");
    let batch = |extra: &[&str]| {
        picker()
            .args(["batch", input.to_str().unwrap(), "--out"])
            .arg(&out)
            .args(["--picks", picks.to_str().unwrap()])
            .args(["--normals", normals.to_str().unwrap()])
            .args(["--weights", &weights(), "--max-size", "32", "--quiet"])
            .args(extra)
            .output()
            .unwrap()
    };
    let used = |rel: &str| -> Value {
        let m: Value = serde_json::from_slice(
            &std::fs::read(out.join(format!("{rel}.material/material_0/material.json"))).unwrap(),
        )
        .unwrap();
        m["diagnostics"]["uv"]["user_plane"].clone()
    };
    let o = batch(&[]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(report(&out)["counts"]["ok"], 3);
    let scan = used("sub/scan.png");
    assert_eq!(scan["source"], "normal", "{scan}");
    assert_eq!(scan["normal"], serde_json::json!([0.0, 0.0, 1.0]));
    let floor = used("floor.png");
    let n: Vec<f64> = floor["normal"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    let len = (1.0f64 + 0.09).sqrt();
    assert!(
        (n[1] - 1.0 / len).abs() < 1e-5 && (n[2] - 0.3 / len).abs() < 1e-5,
        "{floor}"
    );
    assert!(used("other.png").is_null());

    // A changed normal redoes that photo only; --normal sets the others'
    // (a changed setting: all are redone), the rows still win.
    write_normals("0,1,0.5");
    batch(&[]);
    let r = report(&out);
    assert_eq!(
        (
            r["counts"]["ok"].as_u64(),
            r["counts"]["up_to_date"].as_u64()
        ),
        (Some(1), Some(2)),
        "{r:#}"
    );
    batch(&["--normal", "1,0,0.2"]);
    assert_eq!(report(&out)["counts"]["ok"], 3);
    assert_eq!(
        used("sub/scan.png")["normal"],
        serde_json::json!([0.0, 0.0, 1.0])
    );
    let other: Vec<f64> = used("other.png")["normal"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    assert!(other[0] > 0.9, "{other:?}");

    // Refused before any photo is made.
    let quads = tmp.path().join("quads.csv");
    std::fs::write(&quads, "floor.png,5,5,40,5,40,40,5,40\n").unwrap();
    let missing = tmp.path().join("missing.csv");
    std::fs::write(&missing, "gone.png,front\n").unwrap();
    let fresh = tmp.path().join("fresh");
    for (extra, want, code) in [
        (
            vec!["--quads", quads.to_str().unwrap()],
            "one plane per photo",
            2,
        ),
        (vec!["--uv", "net"], "--uv net", 2),
    ] {
        let o = picker()
            .args(["batch", input.to_str().unwrap(), "--out"])
            .arg(&fresh)
            .args([
                "--normals",
                normals.to_str().unwrap(),
                "--picks",
                picks.to_str().unwrap(),
                "--weights",
                &weights(),
            ])
            .args(&extra)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(code), "{extra:?}: {err}");
        assert!(err.contains(want), "{extra:?}: {err}");
        assert!(!fresh.join("floor.png.material").exists(), "{extra:?}");
    }
    let o = picker()
        .args(["batch", input.to_str().unwrap(), "--out"])
        .arg(&fresh)
        .args([
            "--picks",
            picks.to_str().unwrap(),
            "--normals",
            missing.to_str().unwrap(),
            "--weights",
            &weights(),
        ])
        .args(["--max-size", "32", "--quiet"])
        .output()
        .unwrap();
    assert_eq!(
        o.status.code(),
        Some(1),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(
        report(&fresh)
            .to_string()
            .contains("listed in --normals but not found"),
        "{}",
        report(&fresh)
    );
}

/// `--masks`: a photo with a mask in MASK_DIR (same relative path, its own
/// extension) gets that material exactly, pick or none; a photo without one
/// follows --picks; the mask is in the manifest (a new mask redoes the
/// photo); a mask folder inside IN_DIR is not read as photos; two masks for
/// one photo, or a mask with two picks, are usage errors.
#[test]
fn masks_give_each_photo_its_material() {
    let tmp = tempfile::tempdir().unwrap();
    let input = tmp.path().join("photos");
    std::fs::create_dir_all(input.join("sub")).unwrap();
    photo(5, 64, 48).save(input.join("sub/a.jpg")).unwrap();
    photo(6, 64, 48).save(input.join("b.png")).unwrap();
    let masks = input.join("masks");
    std::fs::create_dir_all(masks.join("sub")).unwrap();
    let rect = |x0: u32, x1: u32| {
        image::GrayImage::from_fn(64, 48, move |x, y| {
            image::Luma([if (x0..x1).contains(&x) && (10..30).contains(&y) {
                255
            } else {
                0
            }])
        })
    };
    rect(20, 40).save(masks.join("sub/a.png")).unwrap();
    let picks = tmp.path().join("picks.csv");
    std::fs::write(&picks, "b.png,5,40\n").unwrap();
    let out = tmp.path().join("out");
    let batch = |extra: &[&str]| {
        picker()
            .args(["batch", input.to_str().unwrap(), "--out"])
            .arg(&out)
            .args(["--masks", masks.to_str().unwrap()])
            .args(["--picks", picks.to_str().unwrap()])
            .args([
                "--weights",
                &weights(),
                "--work-size",
                "48",
                "--max-size",
                "32",
                "--quiet",
            ])
            .args(extra)
            .output()
            .unwrap()
    };
    let o = batch(&[]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let r = report(&out);
    // The masks are not photos.
    assert_eq!(r["counts"]["photos"], 2, "{r:#}");
    assert_eq!(r["counts"]["ok"], 2, "{r:#}");
    let dir = out.join("sub/a.jpg.material/material_0");
    let m: Value =
        serde_json::from_slice(&std::fs::read(dir.join("material.json")).unwrap()).unwrap();
    assert_eq!(m["diagnostics"]["mask_given"], true);
    // Named relative to its folder: no absolute path in the outputs.
    assert_eq!(m["given_mask"], "MASK_DIR/sub/a.png");
    assert_eq!(m["pick"], serde_json::json!([29, 19]));
    let mask = image::open(dir.join("mask.png")).unwrap().to_luma8();
    for (x, y, v) in mask.enumerate_pixels() {
        let want = (20..40).contains(&x) && (10..30).contains(&y);
        assert_eq!(v.0[0] > 127, want, "({x}, {y})");
    }
    let m: Value = serde_json::from_slice(
        &std::fs::read(out.join("b.png.material/material_0/material.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(m["diagnostics"]["mask_given"], false);

    batch(&[]);
    assert_eq!(report(&out)["counts"]["up_to_date"], 2);
    rect(10, 30).save(masks.join("sub/a.png")).unwrap();
    batch(&[]);
    let r = report(&out);
    assert_eq!(
        (
            r["counts"]["ok"].as_u64(),
            r["counts"]["up_to_date"].as_u64()
        ),
        (Some(1), Some(1)),
        "{r:#}"
    );

    // Two masks for one photo; a mask and two picks.
    rect(10, 30).save(masks.join("sub/a.tif")).unwrap();
    let o = batch(&[]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("two masks"), "{err}");
    std::fs::remove_file(masks.join("sub/a.tif")).unwrap();
    std::fs::write(&picks, "sub/a.jpg,25,15\nsub/a.jpg,26,16\n").unwrap();
    let o = batch(&[]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("--picks has 2 picks"), "{err}");
}

/// `--analysis-megapixels` in a batch: the CSV's picks are the photos' own
/// pixels, and so are the outputs (the pick and mask.png), whatever size
/// the extraction worked at.
#[test]
fn picks_stay_in_the_photos_pixels_when_analysed_smaller() {
    let tmp = tempfile::tempdir().unwrap();
    let input = tmp.path().join("photos");
    std::fs::create_dir_all(&input).unwrap();
    std::fs::copy(
        repo().join("fixtures/examples/coffee.jpg"),
        input.join("coffee.jpg"),
    )
    .unwrap();
    let picks = tmp.path().join("picks.csv");
    std::fs::write(&picks, "file,x,y\ncoffee.jpg,319,212\n").unwrap();
    let out = tmp.path().join("out");
    let o = picker()
        .args(["batch", input.to_str().unwrap(), "--out"])
        .arg(&out)
        .args(["--picks", picks.to_str().unwrap()])
        .args(["--weights", &weights(), "--max-size", "32", "--quiet"])
        .args(["--analysis-megapixels", "0.02"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let dir = out.join("coffee.jpg.material/material_0");
    let m: Value =
        serde_json::from_slice(&std::fs::read(dir.join("material.json")).unwrap()).unwrap();
    assert_eq!(m["pick"], serde_json::json!([319, 212]), "{}", m["pick"]);
    assert_eq!(m["photo"]["analysis"]["width"], 173, "{}", m["photo"]);
    let mask = image::open(dir.join("mask.png")).unwrap();
    assert_eq!((mask.width(), mask.height()), (320, 213));
}
