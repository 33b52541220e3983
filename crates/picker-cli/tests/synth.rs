//! `picker synth` end to end, and the golden scenes of `fixtures/synth/`.
//!
//! The golden test regenerates the committed scenes (`--seed 2026 --size 24x32`,
//! scenes 0 and 1, two threads) and requires every committed file to come back
//! byte for byte. On a mismatch the whole output is copied to
//! `target/golden-failures/synth/` and the panic names the differing files.
//! Re-bless (after a deliberate change of the generator — bump
//! `picker_synth::GENERATOR_VERSION` too) with
//! `PICKER_BLESS=1 cargo test -p picker-cli --test synth`.

use std::path::{Path, PathBuf};
use std::process::Command;

const GOLDEN_SEED: &str = "2026";
const GOLDEN_SIZE: &str = "24x32";
const GOLDEN_COUNT: usize = 2;

fn picker() -> Command {
    Command::new(env!("CARGO_BIN_EXE_picker"))
}

/// Runs `cmd` and requires it to succeed (the panic shows its stderr).
fn succeed(cmd: &mut Command) -> std::process::Output {
    let out = cmd.output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// Runs `cmd` and requires it to be refused as a usage error (exit code 2); returns its stderr.
fn refused(cmd: &mut Command) -> String {
    let out = cmd.output().unwrap();
    assert_eq!(out.status.code(), Some(2));
    String::from_utf8_lossy(&out.stderr).into_owned()
}

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// Files of `dir` (relative paths, sorted), skipping the `materials/` folder.
fn listing(dir: &Path) -> Vec<String> {
    let mut out: Vec<String> = std::fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .filter(|p| p.is_file())
        .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
        .collect();
    out.sort();
    out
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for name in listing(from) {
        std::fs::copy(from.join(&name), to.join(&name)).unwrap();
    }
}

#[test]
fn golden_scenes_regenerate_bit_exactly() {
    let tmp = tempfile::tempdir().unwrap();
    succeed(
        picker()
            .args([
                "synth",
                "--count",
                &GOLDEN_COUNT.to_string(),
                "--size",
                GOLDEN_SIZE,
            ])
            .args(["--seed", GOLDEN_SEED, "--threads", "2", "--out"])
            .arg(tmp.path()),
    );
    let fixtures = repo().join("fixtures/synth");
    let bless = std::env::var_os("PICKER_BLESS").is_some_and(|v| v == "1");
    let mut failures = Vec::new();
    for i in 0..GOLDEN_COUNT {
        let name = format!("scene_{i:06}");
        let (got, want) = (tmp.path().join(&name), fixtures.join(&name));
        if bless {
            let _ = std::fs::remove_dir_all(&want);
            copy_dir(&got, &want);
            continue;
        }
        let want_files = listing(&want);
        assert!(!want_files.is_empty(), "no fixtures in {}", want.display());
        let got_files = listing(&got);
        if got_files != want_files {
            failures.push(format!(
                "{name}: files {got_files:?}, fixture has {want_files:?}"
            ));
        }
        for f in &want_files {
            let (a, b) = (
                std::fs::read(got.join(f)),
                std::fs::read(want.join(f)).unwrap(),
            );
            if a.ok().as_ref() != Some(&b) {
                failures.push(format!("{name}/{f}"));
            }
        }
    }
    if !failures.is_empty() {
        let out = repo().join("target/golden-failures/synth");
        let _ = std::fs::remove_dir_all(&out);
        for i in 0..GOLDEN_COUNT {
            let name = format!("scene_{i:06}");
            copy_dir(&tmp.path().join(&name), &out.join(&name));
        }
        panic!(
            "golden synth scenes differ: {}; the actual output is in {} (re-bless with PICKER_BLESS=1 if the change is intended)",
            failures.join(", "),
            out.display()
        );
    }
}

#[test]
fn synth_writes_scene_folders_and_a_contact_sheet() {
    let tmp = tempfile::tempdir().unwrap();
    let sheet = tmp.path().join("sheet.png");
    // What a killed run left (a hidden partial scene of a process that is
    // gone) is removed; a scene that was there is replaced whole.
    let stale = tmp.path().join("run/.scene_000005.partial-9999999");
    std::fs::create_dir_all(&stale).unwrap();
    std::fs::create_dir_all(tmp.path().join("run/scene_000006")).unwrap();
    std::fs::write(tmp.path().join("run/scene_000006/old.txt"), b"x").unwrap();
    let st = succeed(
        picker()
            .args([
                "synth", "--count", "2", "--size", "16x24", "--seed", "9", "--start", "5",
            ])
            .arg("--out")
            .arg(tmp.path().join("run"))
            .arg("--contact-sheet")
            .arg(&sheet),
    );
    let err = String::from_utf8_lossy(&st.stderr);
    assert!(err.contains("wrote 2 scenes"), "{err}");
    for i in [5, 6] {
        let d = tmp.path().join(format!("run/scene_{i:06}"));
        for f in [
            "image.png",
            "image.exr",
            "uv.exr",
            "material_id.png",
            "envmap.exr",
            "scene.json",
        ] {
            assert!(d.join(f).is_file(), "{} missing", d.join(f).display());
        }
        assert!(d.join("materials/1/material.json").is_file());
    }
    let entries: Vec<String> = std::fs::read_dir(tmp.path().join("run"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert!(
        entries.iter().all(|n| !n.starts_with('.')),
        "hidden entries left: {entries:?}"
    );
    assert!(!tmp.path().join("run/scene_000006/old.txt").exists());
    let img = image::open(&sheet).unwrap();
    assert_eq!((img.width(), img.height()), (2 * 12, 8));
    // Sizes whose scenes could not be held in memory are refused up front.
    refused(
        picker()
            .args(["synth", "--size", "100000x100000", "--out"])
            .arg(tmp.path().join("huge")),
    );
    assert!(!tmp.path().join("huge").exists());

    refused(
        picker()
            .args(["synth", "--size", "0x5", "--out"])
            .arg(tmp.path()),
    );

    // --views: recorded in scene.json; the default is room views; an unknown name is refused.
    let views_of = |dir: &Path| -> (String, String) {
        let j: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(dir.join("scene.json")).unwrap())
                .unwrap();
        let c = &j["camera"];
        (
            c["views"].as_str().unwrap().into(),
            c["view"].as_str().unwrap().into(),
        )
    };
    assert_eq!(
        views_of(&tmp.path().join("run/scene_000005")),
        ("room".into(), "room".into())
    );
    succeed(
        picker()
            .args([
                "synth", "--count", "12", "--size", "16x24", "--seed", "9", "--views", "wide",
            ])
            .arg("--out")
            .arg(tmp.path().join("wide")),
    );
    let kinds: std::collections::BTreeSet<String> = (0..12)
        .map(|i| {
            let (views, view) = views_of(&tmp.path().join(format!("wide/scene_{i:06}")));
            assert_eq!(views, "wide");
            view
        })
        .collect();
    assert!(
        kinds.len() >= 2
            && kinds
                .iter()
                .all(|k| ["room", "down", "close"].contains(&k.as_str())),
        "{kinds:?}"
    );
    let err = refused(
        picker()
            .args(["synth", "--views", "aerial", "--out"])
            .arg(tmp.path()),
    );
    assert!(err.contains("aerial"), "{err}");
}
