//! The JPEG entropy-data check (`picker_extract::jpeg`): every coding it
//! walks passes whole, and cut, damaged and lying files are refused, by the
//! check and by `photo::decode`.
//!
//! Sequential files are made here with the `image` crate's encoder; the
//! codings it does not write (progressive with successive approximation,
//! restart markers, 4:2:2, optimised tables) are the small committed files in
//! `fixtures/jpeg/`, made by `scripts/make-jpeg-fixtures.py` (Pillow/libjpeg).

use std::path::{Path, PathBuf};

use image::codecs::jpeg::JpegEncoder;
use image::{DynamicImage, ExtendedColorType, ImageBuffer, ImageEncoder, Luma, Rgb};
use picker_extract::jpeg::{check, Checked, Damage};
use picker_extract::photo::{self, PhotoLimits};
use picker_tensor::Rng;

fn fixture_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/jpeg")
}

/// Every committed fixture, `(name, bytes)`, in name order.
fn fixtures() -> Vec<(String, Vec<u8>)> {
    let mut out: Vec<_> = std::fs::read_dir(fixture_dir())
        .expect("fixtures/jpeg")
        .map(|e| {
            let p = e.unwrap().path();
            let name = p.file_name().unwrap().to_string_lossy().into_owned();
            (name, std::fs::read(&p).unwrap())
        })
        .filter(|(n, _)| n.ends_with(".jpg"))
        .collect();
    out.sort();
    assert!(out.len() >= 6, "fixtures/jpeg holds {} files", out.len());
    out
}

/// A noisy picture (every block has AC coefficients), grey or RGB.
fn picture(w: u32, h: u32, grey: bool, seed: u64) -> DynamicImage {
    let mut rng = Rng::new(seed);
    let mut v = |x: u32, y: u32, c: u32| {
        let base = 128.0 + 90.0 * ((x as f32 / (4.0 + c as f32)) + y as f32 / 6.0).sin();
        (base + rng.uniform(-20.0, 20.0)).clamp(0.0, 255.0) as u8
    };
    if grey {
        DynamicImage::ImageLuma8(ImageBuffer::from_fn(w, h, |x, y| Luma([v(x, y, 0)])))
    } else {
        DynamicImage::ImageRgb8(ImageBuffer::from_fn(w, h, |x, y| {
            Rgb([v(x, y, 0), v(x, y, 1), v(x, y, 2)])
        }))
    }
}

fn jpeg(img: &DynamicImage, quality: u8) -> Vec<u8> {
    let mut out = Vec::new();
    let colour = if img.color().channel_count() == 1 {
        ExtendedColorType::L8
    } else {
        ExtendedColorType::Rgb8
    };
    JpegEncoder::new_with_quality(&mut out, quality)
        .write_image(img.as_bytes(), img.width(), img.height(), colour)
        .unwrap();
    out
}

/// Sequential files of the `image` crate's encoder and the committed ones.
fn whole_files() -> Vec<(String, Vec<u8>)> {
    let mut out = fixtures();
    for (k, (w, h)) in [(1, 1), (7, 5), (17, 33), (64, 48), (130, 9)]
        .into_iter()
        .enumerate()
    {
        for grey in [false, true] {
            for quality in [50, 100] {
                let name = format!(
                    "enc-{w}x{h}-{}-q{quality}.jpg",
                    if grey { "grey" } else { "rgb" }
                );
                out.push((name, jpeg(&picture(w, h, grey, k as u64), quality)));
            }
        }
    }
    out
}

/// Where the first scan's coded data starts (after its SOS segment).
fn first_scan_data(b: &[u8]) -> usize {
    let sos = b
        .windows(2)
        .position(|w| w == [0xFF, 0xDA])
        .expect("a scan");
    sos + 2 + u16::from_be_bytes([b[sos + 2], b[sos + 3]]) as usize
}

#[test]
fn whole_files_walk_clean_and_decode() {
    for (name, bytes) in whole_files() {
        assert_eq!(check(&bytes), Ok(Checked::Walked), "{name}");
        photo::decode(&bytes, Path::new(&name), &PhotoLimits::default())
            .unwrap_or_else(|e| panic!("{name}: {e}"));
    }
}

/// The "lying header" file: an end-of-image marker put after half of the
/// coded data (a file with its middle lost). Decoders fill the rest; the
/// check says where the data stops.
#[test]
fn middle_cut_out_ends_early() {
    for (name, bytes) in whole_files() {
        let start = first_scan_data(&bytes);
        let end = bytes.len() - 2;
        if end - start < 8 {
            continue; // A 1 × 1 picture's data is a byte or two.
        }
        for cut in [start + (end - start) / 2, start + (end - start) * 9 / 10] {
            let mut cut_out = bytes[..cut].to_vec();
            cut_out.extend_from_slice(&[0xFF, 0xD9]);
            match check(&cut_out) {
                Err(Damage::EndsEarly(d)) => {
                    assert!(
                        d.contains("stops in MCU row") || d.contains("the file ends inside"),
                        "{name}: {d}"
                    );
                }
                other => panic!("{name} cut at {cut} of {}: {other:?}", bytes.len()),
            }
            let msg = photo::decode(&cut_out, Path::new(&name), &PhotoLimits::default())
                .err()
                .unwrap_or_else(|| panic!("{name} cut at {cut}: decoded"))
                .to_string();
            assert!(
                msg.starts_with(&format!("{name}: the JPEG data is truncated (")),
                "{msg}"
            );
        }
    }
}

/// A header that states a taller picture than the data holds.
#[test]
fn taller_header_than_data_ends_early() {
    for (name, bytes) in whole_files() {
        let sof = bytes
            .windows(2)
            .position(|w| w[0] == 0xFF && (0xC0..=0xC2).contains(&w[1]))
            .expect("a frame header");
        let h = u16::from_be_bytes([bytes[sof + 5], bytes[sof + 6]]);
        let mut lying = bytes.clone();
        lying[sof + 5..sof + 7].copy_from_slice(&(h * 2 + 16).to_be_bytes());
        assert!(
            matches!(check(&lying), Err(Damage::EndsEarly(_))),
            "{name}: {:?}",
            check(&lying)
        );
    }
}

/// 24 random bytes written over the coded data (seeded, 4 places per
/// file): the codes almost always go out of step and the check finds it.
/// Not always: Huffman codes fall back into step, and damage whose bits
/// happen to end where the block's did, with DC values in range, is
/// invisible to any check that does not look at the picture (1 of 64 here).
#[test]
fn damaged_data_is_refused() {
    let mut rng = Rng::new(2026);
    let (mut tried, mut seen) = (0, 0);
    for (name, bytes) in whole_files() {
        let start = first_scan_data(&bytes);
        let end = bytes.len() - 2;
        if end - start < 200 {
            continue;
        }
        for _ in 0..4 {
            let at = start + rng.range(0, end - start - 24);
            let mut bad = bytes.clone();
            for b in &mut bad[at..at + 24] {
                *b = rng.range(0, 255) as u8;
            }
            tried += 1;
            if check(&bad).is_err() {
                seen += 1;
                let msg = photo::decode(&bad, Path::new(&name), &PhotoLimits::default())
                    .err()
                    .unwrap_or_else(|| panic!("{name}: damaged at {at}, decoded"))
                    .to_string();
                assert!(
                    msg.starts_with(&format!("{name}: the JPEG data is damaged ("))
                        || msg.starts_with(&format!("{name}: the JPEG data is truncated (")),
                    "{msg}"
                );
            }
        }
    }
    eprintln!("damaged files refused: {seen} of {tried}");
    assert!(
        seen * 100 >= tried * 95,
        "only {seen} of {tried} damaged files refused"
    );
}

/// Restart markers: one removed, one renumbered, bytes slipped in before one.
#[test]
fn restart_markers_are_checked() {
    for (name, bytes) in fixtures()
        .into_iter()
        .filter(|(n, _)| n.starts_with("restart"))
    {
        let start = first_scan_data(&bytes);
        let rst: Vec<usize> = (start..bytes.len() - 1)
            .filter(|&i| bytes[i] == 0xFF && (0xD0..=0xD7).contains(&bytes[i + 1]))
            .collect();
        assert!(rst.len() >= 2, "{name}: {} restart markers", rst.len());
        let second = rst[1];
        assert_eq!(bytes[second + 1], 0xD1, "{name}");

        let mut removed = bytes.clone();
        removed.drain(second..second + 2);
        let mut renumbered = bytes.clone();
        renumbered[second + 1] = 0xD3;
        let mut slipped = bytes.clone();
        slipped.splice(second..second, [0x12, 0x34]);
        for (what, file, want) in [
            (
                "removed",
                removed,
                "restart marker 1 is missing or out of order",
            ),
            (
                "renumbered",
                renumbered,
                "restart marker 1 is missing or out of order",
            ),
            (
                "slipped",
                slipped,
                "2 bytes of image data left over before restart marker 1",
            ),
        ] {
            match check(&file) {
                Err(Damage::Corrupt(d)) => assert!(d.starts_with(want), "{name} {what}: {d}"),
                other => panic!("{name} {what}: {other:?}"),
            }
        }
    }
}

/// Whole bytes after a scan's last block: the data went out of step.
#[test]
fn bytes_after_the_last_block_are_refused() {
    let bytes = jpeg(&picture(40, 24, false, 5), 90);
    let mut extra = bytes[..bytes.len() - 2].to_vec();
    extra.extend_from_slice(&[0x55, 0xAA, 0x55, 0xFF, 0xD9]);
    match check(&extra) {
        Err(Damage::Corrupt(d)) => assert!(d.starts_with("3 bytes of image data left over"), "{d}"),
        other => panic!("{other:?}"),
    }
}

/// Files the check does not walk pass untouched: arithmetic coding, a DNL
/// height, no JPEG at all.
#[test]
fn other_codings_are_not_walked() {
    let bytes = jpeg(&picture(16, 16, true, 1), 90);
    let sof = bytes.windows(2).position(|w| w == [0xFF, 0xC0]).unwrap();
    let mut arithmetic = bytes.clone();
    arithmetic[sof + 1] = 0xC9;
    assert_eq!(check(&arithmetic), Ok(Checked::NotWalked));
    let mut dnl = bytes.clone();
    dnl[sof + 5..sof + 7].copy_from_slice(&[0, 0]);
    assert_eq!(check(&dnl), Ok(Checked::NotWalked));
    assert_eq!(check(b"not a jpeg"), Ok(Checked::NotWalked));
    assert_eq!(check(&[]), Ok(Checked::NotWalked));
}

/// A DC refinement scan decodes raw bits: its table selectors are not used
/// and may hold anything (a fuzzed file once made the walk index past the
/// four tables).
#[test]
fn unused_table_selectors_are_ignored() {
    let (_, bytes) = fixtures()
        .into_iter()
        .find(|(n, _)| n == "progressive-420.jpg")
        .unwrap();
    let mut changed = 0;
    let mut file = bytes.clone();
    for sos in (0..bytes.len() - 1).filter(|&i| bytes[i] == 0xFF && bytes[i + 1] == 0xDA) {
        let n = bytes[sos + 4] as usize;
        let tail = sos + 5 + 2 * n;
        // Ss = Se = 0, Ah ≠ 0: a DC refinement.
        if bytes[tail] == 0 && bytes[tail + 1] == 0 && bytes[tail + 2] >> 4 != 0 {
            for k in 0..n {
                file[sos + 5 + 2 * k + 1] = 0xFF;
                changed += 1;
            }
        }
    }
    assert!(changed > 0, "no DC refinement scan in the fixture");
    assert_eq!(check(&file), Ok(Checked::Walked));
}
