//! Photo input (`picker_extract::photo`): every format × bit depth × channel
//! layout, EXIF orientation, linear EXR/HDR, and the files people actually
//! have by mistake (empty, cut off, mislabelled, not an image, a bomb).
//!
//! All inputs are made here at test time with the `image` crate (or by hand,
//! for the EXIF segment and the lying PNG header); no fixture files.

use std::io::Cursor;
use std::path::Path;
use std::time::{Duration, Instant};

use image::codecs::jpeg::JpegEncoder;
use image::metadata::Orientation;
use image::ImageEncoder;
use image::{
    DynamicImage, ImageBuffer, ImageFormat, Luma, LumaA, Rgb, Rgb32FImage, Rgba, Rgba32FImage,
};
use picker_extract::photo::{self, Photo, PhotoError, PhotoLimits};

const W: u32 = 7;
const H: u32 = 5;

fn dec(bytes: &[u8], name: &str) -> Result<Photo, PhotoError> {
    photo::decode(bytes, Path::new(name), &PhotoLimits::default())
}

/// The error message for `bytes` named `name`, asserting it is one line
/// that starts with the name.
fn err(bytes: &[u8], name: &str) -> String {
    let msg = match dec(bytes, name) {
        Ok(p) => panic!("{name}: decoded as {} instead of failing", p.format),
        Err(e) => e.to_string(),
    };
    assert!(msg.starts_with(&format!("{name}: ")), "{msg}");
    assert!(!msg.contains('\n'), "{msg}");
    msg
}

fn encode(img: &DynamicImage, fmt: ImageFormat) -> Vec<u8> {
    let mut out = Vec::new();
    img.write_to(&mut Cursor::new(&mut out), fmt)
        .unwrap_or_else(|e| panic!("encoding {:?} as {fmt:?}: {e}", img.color()));
    out
}

fn jpeg(img: &DynamicImage) -> Vec<u8> {
    let mut out = Vec::new();
    // `write_image` with the image's own colour type: `encode_image` on a
    // `DynamicImage` would always write three components.
    JpegEncoder::new_with_quality(&mut out, 100)
        .write_image(
            img.as_bytes(),
            img.width(),
            img.height(),
            img.color().into(),
        )
        .unwrap();
    out
}

/// Smooth test values in `[0, 1]` for channel `c` (0–2: colour, 3: alpha)
/// at `(x, y)`, exact in 8 bits.
fn v8(x: u32, y: u32, c: u32) -> u8 {
    if c == 3 {
        // Varying alpha, all of it at least ½: must not matter.
        return (255 - x * 15 - y * 3) as u8;
    }
    (x * 16 + y * 20 + c * 35) as u8
}

/// Values that use all 16 bits.
fn v16(x: u32, y: u32, c: u32) -> u16 {
    if c == 3 {
        return (65535 - x * 4000 - y * 1000) as u16;
    }
    (x * 4111 + y * 5003 + c * 9001 + 7) as u16
}

/// A test image with `channels` (1 grey, 2 grey+alpha, 3 RGB, 4 RGBA) at
/// `bits` (8, 16 or 32 float) and the expected decoded RGB.
fn sample(channels: u32, bits: u32) -> (DynamicImage, Rgb32FImage) {
    let val = |x, y, c| -> f32 {
        match bits {
            8 => v8(x, y, c) as f32 / 255.0,
            16 => v16(x, y, c) as f32 / 65535.0,
            _ => v16(x, y, c) as f32 / 65535.0,
        }
    };
    let expected = Rgb32FImage::from_fn(W, H, |x, y| {
        if channels <= 2 {
            Rgb([val(x, y, 0); 3])
        } else {
            Rgb([val(x, y, 0), val(x, y, 1), val(x, y, 2)])
        }
    });
    let img = match (channels, bits) {
        (1, 8) => ImageBuffer::from_fn(W, H, |x, y| Luma([v8(x, y, 0)])).into(),
        (2, 8) => ImageBuffer::from_fn(W, H, |x, y| LumaA([v8(x, y, 0), v8(x, y, 3)])).into(),
        (3, 8) => ImageBuffer::from_fn(W, H, |x, y| Rgb([0, 1, 2].map(|c| v8(x, y, c)))).into(),
        (4, 8) => ImageBuffer::from_fn(W, H, |x, y| Rgba([0, 1, 2, 3].map(|c| v8(x, y, c)))).into(),
        (1, 16) => ImageBuffer::from_fn(W, H, |x, y| Luma([v16(x, y, 0)])).into(),
        (2, 16) => ImageBuffer::from_fn(W, H, |x, y| LumaA([v16(x, y, 0), v16(x, y, 3)])).into(),
        (3, 16) => ImageBuffer::from_fn(W, H, |x, y| Rgb([0, 1, 2].map(|c| v16(x, y, c)))).into(),
        (4, 16) => {
            ImageBuffer::from_fn(W, H, |x, y| Rgba([0, 1, 2, 3].map(|c| v16(x, y, c)))).into()
        }
        (3, 32) => DynamicImage::ImageRgb32F(Rgb32FImage::from_fn(W, H, |x, y| {
            Rgb([0, 1, 2].map(|c| val(x, y, c)))
        })),
        (4, 32) => DynamicImage::ImageRgba32F(Rgba32FImage::from_fn(W, H, |x, y| {
            Rgba([0, 1, 2, 3].map(|c| val(x, y, c)))
        })),
        other => panic!("no sample for {other:?}"),
    };
    (img, expected)
}

/// Largest absolute difference, with the first place it occurs.
fn max_diff(a: &Rgb32FImage, b: &Rgb32FImage) -> (f32, (u32, u32)) {
    assert_eq!(a.dimensions(), b.dimensions());
    let mut worst = (0.0f32, (0, 0));
    for (x, y, p) in a.enumerate_pixels() {
        let q = b.get_pixel(x, y);
        for c in 0..3 {
            let d = (p.0[c] - q.0[c]).abs();
            if d > worst.0 || d.is_nan() {
                worst = (d, (x, y));
            }
        }
    }
    worst
}

#[test]
fn every_format_depth_and_layout() {
    // (format, extension, channels, bits, expected channels_in_file, tolerance)
    #[rustfmt::skip]
    let cases: &[(ImageFormat, &str, u32, u32, u8, f32)] = &[
        (ImageFormat::Png, "png", 1, 8, 1, 1e-6),
        (ImageFormat::Png, "png", 2, 8, 2, 1e-6),
        (ImageFormat::Png, "png", 3, 8, 3, 1e-6),
        (ImageFormat::Png, "png", 4, 8, 4, 1e-6),
        (ImageFormat::Png, "png", 1, 16, 1, 1e-6),
        (ImageFormat::Png, "png", 2, 16, 2, 1e-6),
        (ImageFormat::Png, "png", 3, 16, 3, 1e-6),
        (ImageFormat::Png, "png", 4, 16, 4, 1e-6),
        (ImageFormat::Jpeg, "jpg", 1, 8, 1, 0.03),
        (ImageFormat::Jpeg, "jpg", 3, 8, 3, 0.06),
        (ImageFormat::Tiff, "tif", 1, 8, 1, 1e-6),
        (ImageFormat::Tiff, "tif", 3, 8, 3, 1e-6),
        (ImageFormat::Tiff, "tif", 4, 8, 4, 1e-6),
        (ImageFormat::Tiff, "tif", 1, 16, 1, 1e-6),
        (ImageFormat::Tiff, "tif", 3, 16, 3, 1e-6),
        (ImageFormat::Tiff, "tif", 4, 16, 4, 1e-6),
        (ImageFormat::Tiff, "tif", 3, 32, 3, 1e-6),
        (ImageFormat::Tiff, "tif", 4, 32, 4, 1e-6),
        (ImageFormat::WebP, "webp", 1, 8, 3, 1e-6),
        (ImageFormat::WebP, "webp", 2, 8, 4, 1e-6),
        (ImageFormat::WebP, "webp", 3, 8, 3, 1e-6),
        (ImageFormat::WebP, "webp", 4, 8, 4, 1e-6),
        (ImageFormat::Bmp, "bmp", 1, 8, 3, 1e-6),
        (ImageFormat::Bmp, "bmp", 3, 8, 3, 1e-6),
        (ImageFormat::Bmp, "bmp", 4, 8, 4, 1e-6),
    ];
    for &(fmt, ext, channels, bits, in_file, tol) in cases {
        let (img, expected) = sample(channels, bits);
        let bytes = match fmt {
            ImageFormat::Jpeg => jpeg(&img),
            _ => encode(&img, fmt),
        };
        let name = format!("sample-{channels}ch-{bits}bit.{ext}");
        let p = dec(&bytes, &name).unwrap_or_else(|e| panic!("{e}"));
        let what = format!("{fmt:?} {channels} channels {bits} bit");
        assert_eq!(p.rgb.dimensions(), (W, H), "{what}");
        assert_eq!(
            p.format,
            photo::format_for_extension(Path::new(&name)).unwrap()
        );
        assert_eq!(p.bit_depth as u32, bits, "{what}: bit depth");
        assert_eq!(p.channels_in_file, in_file, "{what}: channels in file");
        assert!(!p.linear_input, "{what}");
        assert_eq!(p.orientation, Orientation::NoTransforms, "{what}");
        let (d, at) = max_diff(&p.rgb, &expected);
        assert!(
            d <= tol,
            "{what}: max difference {d} at {at:?} (found {:?}, expected {:?})",
            p.rgb.get_pixel(at.0, at.1),
            expected.get_pixel(at.0, at.1)
        );
    }
}

#[test]
fn float_tiff_is_clamped_and_nan_is_zero() {
    let img = Rgb32FImage::from_fn(3, 1, |x, _| match x {
        0 => Rgb([-0.5, 0.25, 2.0]),
        1 => Rgb([f32::NAN, 1.0, 0.0]),
        _ => Rgb([0.5, 0.5, 0.5]),
    });
    let p = dec(&encode(&img.into(), ImageFormat::Tiff), "f.tiff").unwrap();
    assert_eq!(p.rgb.get_pixel(0, 0).0, [0.0, 0.25, 1.0]);
    assert_eq!(p.rgb.get_pixel(1, 0).0, [0.0, 1.0, 0.0]);
    assert_eq!(p.rgb.get_pixel(2, 0).0, [0.5, 0.5, 0.5]);
}

/// A JPEG with an APP1 EXIF segment holding `orientation`, inserted right
/// after the start-of-image marker.
fn jpeg_with_orientation(img: &DynamicImage, orientation: u16) -> Vec<u8> {
    let plain = jpeg(img);
    let mut tiff = Vec::new();
    tiff.extend_from_slice(b"MM\0\x2a"); // big-endian TIFF header
    tiff.extend_from_slice(&8u32.to_be_bytes()); // IFD0 offset
    tiff.extend_from_slice(&1u16.to_be_bytes()); // one entry
    tiff.extend_from_slice(&0x0112u16.to_be_bytes()); // Orientation
    tiff.extend_from_slice(&3u16.to_be_bytes()); // SHORT
    tiff.extend_from_slice(&1u32.to_be_bytes()); // count
    tiff.extend_from_slice(&orientation.to_be_bytes());
    tiff.extend_from_slice(&[0, 0]); // value padding
    tiff.extend_from_slice(&0u32.to_be_bytes()); // no next IFD
    let mut payload = b"Exif\0\0".to_vec();
    payload.extend_from_slice(&tiff);
    let mut out = plain[..2].to_vec();
    out.extend_from_slice(&[0xFF, 0xE1]);
    out.extend_from_slice(&(payload.len() as u16 + 2).to_be_bytes());
    out.extend_from_slice(&payload);
    out.extend_from_slice(&plain[2..]);
    out
}

#[test]
fn all_eight_exif_orientations() {
    // 4 × 2 blocks of 8 × 8 pixels, each block its own colour, so JPEG keeps
    // block centres nearly exact and every orientation looks different.
    let colours: [[u8; 3]; 8] = [
        [250, 10, 10],
        [10, 250, 10],
        [10, 10, 250],
        [250, 250, 10],
        [10, 250, 250],
        [250, 10, 250],
        [128, 128, 128],
        [250, 250, 250],
    ];
    let (bw, bh) = (4u32, 2u32);
    let src = ImageBuffer::from_fn(bw * 8, bh * 8, |x, y| {
        Rgb(colours[(y / 8 * bw + x / 8) as usize])
    });
    let img = DynamicImage::ImageRgb8(src);
    // Which source block is shown at block (x, y) of the displayed photo,
    // per EXIF orientation (the TIFF/EXIF 2.3 definitions).
    let (w, h) = (bw, bh);
    let source_block = |o: u16, x: u32, y: u32| -> (u32, u32) {
        match o {
            1 => (x, y),
            2 => (w - 1 - x, y),
            3 => (w - 1 - x, h - 1 - y),
            4 => (x, h - 1 - y),
            5 => (y, x),
            6 => (y, h - 1 - x),
            7 => (w - 1 - y, h - 1 - x),
            8 => (w - 1 - y, x),
            _ => unreachable!(),
        }
    };
    for o in 1..=8u16 {
        let p = dec(&jpeg_with_orientation(&img, o), "oriented.jpg").unwrap();
        assert_eq!(p.orientation, Orientation::from_exif(o as u8).unwrap());
        let (dw, dh) = if o >= 5 { (bh, bw) } else { (bw, bh) };
        assert_eq!(p.rgb.dimensions(), (dw * 8, dh * 8), "orientation {o}");
        for by in 0..dh {
            for bx in 0..dw {
                let (sx, sy) = source_block(o, bx, by);
                let want = colours[(sy * bw + sx) as usize].map(|c| c as f32 / 255.0);
                let got = p.rgb.get_pixel(bx * 8 + 4, by * 8 + 4).0;
                for c in 0..3 {
                    assert!(
                        (got[c] - want[c]).abs() < 0.05,
                        "orientation {o}, displayed block ({bx}, {by}): found {got:?}, expected source block ({sx}, {sy}) {want:?}"
                    );
                }
            }
        }
    }
}

/// The sRGB encoding, written out independently of the library.
fn srgb(c: f32) -> f32 {
    if c <= 0.0031308 {
        12.92 * c
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    }
}

#[test]
fn exr_is_linear_exposed_at_the_99th_percentile() {
    // 100 grey pixels 0.0, 0.1, …, 9.9 (luminance = grey); the first three
    // are NaN, -inf, +inf and count as 0. The 99th percentile (index 98 of
    // 100) is 9.8, so everything is divided by 9.8.
    let img = Rgb32FImage::from_fn(10, 10, |x, y| {
        let i = y * 10 + x;
        Rgb([match i {
            0 => f32::NAN,
            1 => f32::NEG_INFINITY,
            2 => f32::INFINITY,
            _ => i as f32 * 0.1,
        }; 3])
    });
    let p = dec(&encode(&img.into(), ImageFormat::OpenExr), "scene.exr").unwrap();
    assert!(p.linear_input);
    assert_eq!(
        (p.format.as_str(), p.bit_depth, p.channels_in_file),
        ("exr", 32, 3)
    );
    for (x, y, px) in p.rgb.enumerate_pixels() {
        let i = y * 10 + x;
        let want = if i < 3 {
            0.0
        } else {
            srgb(i as f32 * 0.1 / 9.8).min(1.0)
        };
        for c in 0..3 {
            assert!(
                (px.0[c] - want).abs() < 1e-5,
                "pixel {i}: {:?} vs {want}",
                px.0
            );
        }
    }
    assert_eq!(
        p.rgb.get_pixel(9, 9).0,
        [1.0; 3],
        "above the 99th percentile clips"
    );
}

#[test]
fn dim_exr_is_not_brightened_and_alpha_is_not_composited() {
    let img = Rgba32FImage::from_fn(4, 3, |x, y| {
        Rgba([0.02 * x as f32, 0.5, 0.1 * y as f32, 0.25 * x as f32])
    });
    let p = dec(
        &encode(&img.clone().into(), ImageFormat::OpenExr),
        "dim.exr",
    )
    .unwrap();
    assert_eq!(p.channels_in_file, 4);
    // Alpha 0 and ¼ (x < 2) is transparent: grey; ½ and ¾ are opaque, their
    // colours premultiplied by alpha (OpenEXR's convention): divided by it.
    let opaque = p.opaque.as_ref().expect("some pixels are transparent");
    for (x, y, px) in p.rgb.enumerate_pixels() {
        let src = img.get_pixel(x, y).0;
        assert_eq!(opaque[(y * 4 + x) as usize], x >= 2, "({x}, {y})");
        if x < 2 {
            assert_eq!(px.0, [photo::TRANSPARENT_FILL; 3], "({x}, {y})");
            continue;
        }
        for (found, linear) in px.0.iter().zip(&src[..3]) {
            let want = srgb(linear / src[3]);
            assert!((found - want).abs() < 1e-5, "({x}, {y}): {found} vs {want}");
        }
    }
}

/// An image with alpha: pixels below ½ are transparent (listed, their
/// colour the grey fill), ½ and above keep their colour as stored; at 8
/// bits the line is between 127 and 128, at 16 between 32767 and 32768.
#[test]
fn transparent_pixels_are_listed_and_filled_grey() {
    let alpha8 = |x: u32| [0, 127, 128, 255, 60, 200, 255][x as usize];
    let rgba8 = DynamicImage::ImageRgba8(ImageBuffer::from_fn(W, H, |x, y| {
        Rgba([10 * x as u8, 20 + y as u8, 200, alpha8(x)])
    }));
    let alpha16 = |x: u32| [0, 32767, 32768, 65535, 1000, 50000, 65535][x as usize];
    let la16 = DynamicImage::ImageLumaA16(ImageBuffer::from_fn(W, H, |x, y| {
        LumaA([1000 * (x + y) as u16, alpha16(x)])
    }));
    for (img, fmt, name) in [
        (&rgba8, ImageFormat::Png, "cut.png"),
        (&rgba8, ImageFormat::WebP, "cut.webp"),
        (&rgba8, ImageFormat::Tiff, "cut.tif"),
        (&la16, ImageFormat::Png, "cut16.png"),
    ] {
        let p = dec(&encode(img, fmt), name).unwrap();
        let stored = img.to_rgb32f();
        let opaque = p.opaque.as_ref().unwrap_or_else(|| panic!("{name}"));
        assert!(!p.alpha_ignored, "{name}");
        for (x, y, px) in p.rgb.enumerate_pixels() {
            let on = [false, false, true, true, false, true, true][x as usize];
            assert_eq!(opaque[(y * W + x) as usize], on, "{name} ({x}, {y})");
            let want = if on {
                stored.get_pixel(x, y).0
            } else {
                [photo::TRANSPARENT_FILL; 3]
            };
            assert_eq!(px.0, want, "{name} ({x}, {y})");
        }
    }
    // Opaque everywhere: nothing listed. Transparent everywhere (a viewer
    // shows nothing): the alpha is ignored and the colours kept.
    for (a, ignored) in [(255u8, false), (0, true)] {
        let img = DynamicImage::ImageRgba8(ImageBuffer::from_fn(W, H, |x, y| {
            Rgba([x as u8 * 30, y as u8 * 40, 7, a])
        }));
        let p = dec(&encode(&img, ImageFormat::Png), "all.png").unwrap();
        assert!(p.opaque.is_none());
        assert_eq!(p.alpha_ignored, ignored);
        assert_eq!(p.rgb, img.to_rgb32f());
    }
    // No alpha channel: nothing listed.
    let (rgb, _) = sample(3, 8);
    let p = dec(&encode(&rgb, ImageFormat::Png), "rgb.png").unwrap();
    assert!(p.opaque.is_none() && !p.alpha_ignored);
}

/// A linear image's transparent background does not set its exposure: the
/// 99th percentile is over the opaque pixels.
#[test]
fn a_cut_outs_background_does_not_set_the_exposure() {
    let img = Rgba32FImage::from_fn(20, 10, |x, _| {
        if x < 15 {
            Rgba([50.0, 50.0, 50.0, 0.0])
        } else {
            Rgba([0.25, 0.25, 0.25, 1.0])
        }
    });
    let p = dec(&encode(&img.into(), ImageFormat::OpenExr), "cut.exr").unwrap();
    let px = p.rgb.get_pixel(17, 3).0;
    assert!((px[0] - srgb(0.25)).abs() < 1e-5, "{px:?}");
    assert_eq!(p.rgb.get_pixel(3, 3).0, [photo::TRANSPARENT_FILL; 3]);
}

#[test]
fn radiance_hdr_is_linear() {
    let pixels: Vec<Rgb<f32>> = (0..12)
        .map(|i| Rgb([0.5, 0.25 * (i % 4) as f32, 8.0]))
        .collect();
    let mut bytes = Vec::new();
    image::codecs::hdr::HdrEncoder::new(&mut bytes)
        .encode(&pixels, 4, 3)
        .unwrap();
    let p = dec(&bytes, "sky.hdr").unwrap();
    assert!(p.linear_input);
    assert_eq!((p.format.as_str(), p.rgb.dimensions()), ("hdr", (4, 3)));
    // Luminance 0.2126·0.5 + 0.7152·g + 0.0722·8 is 1.22 for g = 0.75: the
    // 99th percentile (index 10 of 12) is that, so it maps to 1.
    let p99 = 0.2126 * 0.5 + 0.7152 * 0.75 + 0.0722 * 8.0;
    for (i, px) in p.rgb.pixels().enumerate() {
        let want = [0.5, 0.25 * (i % 4) as f32, 8.0].map(|v| srgb(v / p99).min(1.0));
        for c in 0..3 {
            // RGBE keeps 8 bits of mantissa.
            assert!(
                (px.0[c] - want[c]).abs() < 0.01,
                "pixel {i}: {:?} vs {want:?}",
                px.0
            );
        }
    }
}

#[test]
fn empty_file() {
    assert_eq!(
        err(b"", "photo.png"),
        "photo.png: the file is empty (0 bytes)"
    );
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("empty.jpg");
    std::fs::write(&path, b"").unwrap();
    let msg = photo::load(&path, &PhotoLimits::default())
        .unwrap_err()
        .to_string();
    assert_eq!(
        msg,
        format!("{}: the file is empty (0 bytes)", path.display())
    );
}

#[test]
fn missing_file_names_the_operation() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("nope.png");
    let e = photo::load(&path, &PhotoLimits::default()).unwrap_err();
    assert!(matches!(e, PhotoError::Io { .. }));
    assert_eq!(e.path(), path);
    let msg = e.to_string();
    assert!(
        msg.starts_with(&format!("{}: opening the file failed: ", path.display())),
        "{msg}"
    );
}

#[test]
fn truncated_files() {
    let (img, _) = sample(3, 8);
    let big = DynamicImage::ImageRgb8(ImageBuffer::from_fn(64, 48, |x, y| {
        Rgb([(x * 4) as u8, (y * 5) as u8, ((x * y) % 256) as u8])
    }));
    let cases = [
        ("cut.png", "PNG", encode(&big, ImageFormat::Png)),
        ("cut.jpg", "JPEG", jpeg(&big)),
        ("cut.webp", "WebP", encode(&big, ImageFormat::WebP)),
        ("cut.tif", "TIFF", encode(&big, ImageFormat::Tiff)),
        ("cut.bmp", "BMP", encode(&big, ImageFormat::Bmp)),
        (
            "cut.exr",
            "OpenEXR",
            encode(&big.to_rgb32f().into(), ImageFormat::OpenExr),
        ),
        (
            "cut.hdr",
            "Radiance HDR",
            encode(&big.to_rgb32f().into(), ImageFormat::Hdr),
        ),
        ("small.png", "PNG", encode(&img, ImageFormat::Png)),
    ];
    for (name, format, full) in cases {
        dec(&full, name).unwrap_or_else(|e| panic!("the whole file must decode: {e}"));
        for cut in [full.len() / 2, full.len() * 9 / 10] {
            let msg = err(&full[..cut], name);
            let want = format!("{name}: the {format} data is truncated");
            assert!(
                msg.starts_with(&want),
                "cut at {cut} of {}: {msg}",
                full.len()
            );
        }
    }
}

#[test]
fn mislabelled_png_named_jpg_decodes_by_content() {
    let (img, expected) = sample(3, 8);
    let p = dec(&encode(&img, ImageFormat::Png), "holiday.jpg").unwrap();
    assert_eq!(p.format, "png");
    assert_ne!(
        photo::format_for_extension(Path::new("holiday.jpg")),
        Some("png")
    );
    assert_eq!(max_diff(&p.rgb, &expected).0, 0.0);
}

#[test]
fn mislabelled_and_broken_says_both() {
    let (img, _) = sample(3, 8);
    let mut bytes = encode(&img, ImageFormat::Png);
    // Corrupt the zlib stream inside IDAT (after its 8-byte chunk header).
    let idat = bytes.windows(4).position(|w| w == b"IDAT").unwrap();
    bytes[idat + 4] ^= 0xFF;
    bytes[idat + 5] ^= 0xFF;
    let msg = err(&bytes, "x.jpg");
    assert!(
        msg.starts_with(
            "x.jpg: the file is named .jpg but its content is PNG, which could not be decoded: "
        ),
        "{msg}"
    );
    // The same bytes correctly named: a plain decode error.
    let msg = err(&bytes, "x.png");
    assert!(
        msg.starts_with("x.png: cannot decode the PNG data: "),
        "{msg}"
    );
}

const SUPPORTED: &str = "supported: PNG, JPEG, TIFF, WebP, BMP, OpenEXR, Radiance HDR";

#[test]
fn not_images() {
    let mut state = 0x2545_F491_4F6C_DD1Du64;
    let random: Vec<u8> = (0..4096)
        .map(|_| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 24) as u8
        })
        .collect();
    let mut random = random;
    random[0] = 0xAB; // no format starts so
    let cases: [(&str, &[u8], &str); 7] = [
        ("noise.png", &random, "unrecognised bytes"),
        ("notes.png", b"shopping list:\n- milk\n- eggs\n", "text"),
        (
            "scan.png",
            b"%PDF-1.7\n%\xE2\xE3\xCF\xD3\n1 0 obj",
            "a PDF document",
        ),
        (
            "anim.png",
            b"GIF89a\x01\x00\x01\x00\x00\x00\x00;",
            "a Gif image, which is not supported",
        ),
        (
            "IMG_0001.jpg",
            b"\0\0\0\x18ftypheic\0\0\0\0mif1heic",
            "a HEIF/HEIC photo, which is not supported: export it as JPEG or PNG",
        ),
        (
            "logo.png",
            b"<?xml version=\"1.0\"?>\n<svg xmlns=\"http://www.w3.org/2000/svg\"/>",
            "an SVG drawing (vector graphics)",
        ),
        (
            "page.jpg",
            b"<!DOCTYPE html><html><body>404</body></html>",
            "an HTML page",
        ),
    ];
    for (name, bytes, content) in cases {
        assert_eq!(
            err(bytes, name),
            format!("{name}: not a supported image (the content is {content}); {SUPPORTED}")
        );
    }
}

/// CRC-32 (PNG's), bitwise.
fn crc32(data: &[u8]) -> u32 {
    let mut crc = !0u32;
    for &b in data {
        crc ^= b as u32;
        for _ in 0..8 {
            crc = if crc & 1 != 0 {
                (crc >> 1) ^ 0xEDB8_8320
            } else {
                crc >> 1
            };
        }
    }
    !crc
}

fn png_chunk(out: &mut Vec<u8>, kind: &[u8; 4], data: &[u8]) {
    out.extend_from_slice(&(data.len() as u32).to_be_bytes());
    let start = out.len();
    out.extend_from_slice(kind);
    out.extend_from_slice(data);
    let crc = crc32(&out[start..]);
    out.extend_from_slice(&crc.to_be_bytes());
}

/// A well-formed PNG whose IHDR claims `w × h` RGB8 but whose IDAT holds a
/// few bytes only.
fn lying_png(w: u32, h: u32) -> Vec<u8> {
    let mut out = b"\x89PNG\r\n\x1a\n".to_vec();
    let mut ihdr = Vec::new();
    ihdr.extend_from_slice(&w.to_be_bytes());
    ihdr.extend_from_slice(&h.to_be_bytes());
    ihdr.extend_from_slice(&[8, 2, 0, 0, 0]); // 8-bit RGB, deflate, no interlace
    png_chunk(&mut out, b"IHDR", &ihdr);
    // zlib: a stored empty block would do; any small stream will.
    png_chunk(
        &mut out,
        b"IDAT",
        &[0x78, 0x9C, 0x03, 0x00, 0x00, 0x00, 0x00, 0x01],
    );
    png_chunk(&mut out, b"IEND", &[]);
    out
}

#[test]
fn decompression_bomb_fails_fast_without_allocating() {
    let start = Instant::now();
    let msg = err(&lying_png(100_000, 100_000), "bomb.png");
    let took = start.elapsed();
    assert_eq!(
        msg,
        "bomb.png: 100000 × 100000 = 10000 megapixels exceeds the limit of 100 megapixels (--max-megapixels)"
    );
    assert!(took < Duration::from_millis(200), "took {took:?}");
    assert_eq!(
        err(&lying_png(50_000, 50_000), "x.png"),
        "x.png: 50000 × 50000 = 2500 megapixels exceeds the limit of 100 megapixels (--max-megapixels)"
    );
}

#[test]
fn exr_header_is_checked_before_decoding() {
    // A real EXR whose data and display windows are patched to claim
    // 100000 × 100000 pixels.
    let img = Rgb32FImage::from_pixel(4, 4, Rgb([0.5; 3]));
    let mut bytes = encode(&img.into(), ImageFormat::OpenExr);
    for attr in [&b"dataWindow\0box2i\0"[..], &b"displayWindow\0box2i\0"[..]] {
        let at = bytes.windows(attr.len()).position(|w| w == attr).unwrap() + attr.len() + 4;
        bytes[at + 8..at + 12].copy_from_slice(&99_999i32.to_le_bytes());
        bytes[at + 12..at + 16].copy_from_slice(&99_999i32.to_le_bytes());
    }
    let start = Instant::now();
    let msg = err(&bytes, "huge.exr");
    assert!(start.elapsed() < Duration::from_millis(500));
    assert_eq!(
        msg,
        "huge.exr: 100000 × 100000 = 10000 megapixels exceeds the limit of 100 megapixels (--max-megapixels)"
    );
}

#[test]
fn limits_are_configurable() {
    let (img, _) = sample(3, 8);
    let bytes = encode(&img, ImageFormat::Png);
    let tight = PhotoLimits {
        max_pixels: 34,
        ..PhotoLimits::default()
    };
    let msg = photo::decode(&bytes, Path::new("a.png"), &tight)
        .unwrap_err()
        .to_string();
    assert_eq!(msg, "a.png: 7 × 5 = 0.000035 megapixels exceeds the limit of 0.000034 megapixels (--max-megapixels)");
    let exact = PhotoLimits {
        max_pixels: 35,
        ..PhotoLimits::default()
    };
    photo::decode(&bytes, Path::new("a.png"), &exact).unwrap();
    let little = PhotoLimits {
        max_alloc: 1000,
        ..PhotoLimits::default()
    };
    let msg = photo::decode(&bytes, Path::new("a.png"), &little)
        .unwrap_err()
        .to_string();
    assert_eq!(
        msg,
        "a.png: decoding 7 × 5 pixels needs about 1 MiB (at 32 bytes per pixel), over the memory limit of 1 MiB (--max-megapixels)"
    );
    let defaults = PhotoLimits::default();
    assert_eq!(
        (defaults.max_pixels, defaults.max_alloc),
        (100_000_000, 4 << 30)
    );
    assert!(defaults.max_pixels * photo::PEAK_BYTES_PER_PIXEL <= defaults.max_alloc);
}

#[test]
fn zero_sized_image() {
    let msg = err(&lying_png(0, 10), "empty.png");
    assert!(msg.starts_with("empty.png: "), "{msg}");
}

#[test]
fn supported_extensions() {
    for name in [
        "a.png", "b.JPG", "c.jpeg", "d.Tif", "e.tiff", "f.webp", "g.BMP", "h.exr", "i.hdr",
    ] {
        assert!(photo::is_supported_extension(Path::new(name)), "{name}");
    }
    for name in ["a.gif", "b.heic", "c", "d.png.txt", ".png"] {
        assert!(!photo::is_supported_extension(Path::new(name)), "{name}");
    }
    assert_eq!(photo::SUPPORTED_EXTENSIONS.len(), 9);
}

#[test]
fn working_size_keeps_aspect() {
    assert_eq!(photo::working_size(600, 400, 320), (320, 213));
    assert_eq!(photo::working_size(400, 600, 320), (213, 320));
    assert_eq!(photo::working_size(37, 53, 320), (223, 320));
    assert_eq!(photo::working_size(1000, 1, 320), (320, 1));
    assert_eq!(photo::working_size(5, 5, 320), (320, 320));
}

#[test]
fn resize_is_the_triangle_filter() {
    let (img, _) = sample(3, 16);
    let rgb = img.to_rgb32f();
    let ours = photo::resize(&rgb, 4, 9);
    let theirs = image::imageops::resize(&rgb, 4, 9, image::imageops::FilterType::Triangle);
    assert_eq!(ours.as_raw(), theirs.as_raw());
    assert_eq!(photo::resize(&rgb, W, H).as_raw(), rgb.as_raw());
}

#[test]
fn planar_layout() {
    let mut img = Rgb32FImage::new(2, 1);
    img.put_pixel(0, 0, Rgb([0.1, 0.2, 0.3]));
    img.put_pixel(1, 0, Rgb([0.4, 0.5, 0.6]));
    assert_eq!(photo::to_planar(&img), vec![0.1, 0.4, 0.2, 0.5, 0.3, 0.6]);
}

/// Every file of the fuzzers' regression folder decodes or fails with one line
/// naming the file (a JPEG decoder message once ended in a newline).
#[test]
fn fuzz_regressions_give_one_line_errors() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fuzz/regressions/photo_decode");
    let mut n = 0;
    for e in std::fs::read_dir(&dir).unwrap() {
        let p = e.unwrap().path();
        let bytes = std::fs::read(&p).unwrap();
        let limits = PhotoLimits {
            max_pixels: 4_000_000,
            max_alloc: 256 << 20,
        };
        if let Err(e) = photo::decode(&bytes, Path::new("fuzz.img"), &limits) {
            let msg = e.to_string();
            assert!(msg.starts_with("fuzz.img: "), "{msg:?}");
            assert!(!msg.contains('\n') && !msg.ends_with(' '), "{msg:?}");
        }
        n += 1;
    }
    assert!(n >= 1);
}

fn mask_of(bytes: &[u8], name: &str) -> Result<photo::MaskImage, PhotoError> {
    photo::decode_mask(bytes, Path::new(name), &PhotoLimits::default())
}

/// Masks: white on black in grey, RGB or 16-bit; a selection exported with
/// transparency by its alpha (its colours ignored); an opaque alpha by the
/// grey level; a linear EXR at ½; EXIF orientation applied as for photos;
/// and the photo's errors for a file that is not a mask image.
#[test]
fn masks_from_grey_levels_or_alpha() {
    let inside = |x: u32, y: u32| (2..5).contains(&x) && (1..4).contains(&y);
    let want: Vec<bool> = (0..W * H).map(|i| inside(i % W, i / W)).collect();
    let grey = DynamicImage::ImageLuma8(ImageBuffer::from_fn(W, H, |x, y| {
        Luma([if inside(x, y) { 200 } else { 40 }])
    }));
    for (what, img) in [
        ("grey png", grey.clone()),
        ("rgb png", DynamicImage::ImageRgb8(grey.to_rgb8())),
        ("grey16 png", DynamicImage::ImageLuma16(grey.to_luma16())),
    ] {
        let m = mask_of(&encode(&img, ImageFormat::Png), "m.png").unwrap();
        assert_eq!((m.width, m.height), (W as usize, H as usize), "{what}");
        assert_eq!(m.data, want, "{what}");
        assert!(!m.from_alpha, "{what}");
    }
    // Transparent outside, whatever the colours say (here the reverse).
    let sel = DynamicImage::ImageRgba8(ImageBuffer::from_fn(W, H, |x, y| {
        if inside(x, y) {
            Rgba([0, 0, 0, 255])
        } else {
            Rgba([255, 255, 255, 0])
        }
    }));
    let m = mask_of(&encode(&sel, ImageFormat::Png), "sel.png").unwrap();
    assert!(m.from_alpha);
    assert_eq!(m.data, want);
    let la = DynamicImage::ImageLumaA8(ImageBuffer::from_fn(W, H, |x, y| {
        LumaA([0, if inside(x, y) { 255 } else { 10 }])
    }));
    assert_eq!(
        mask_of(&encode(&la, ImageFormat::Png), "la.png")
            .unwrap()
            .data,
        want
    );
    // Opaque everywhere: the grey level.
    let opaque = DynamicImage::ImageRgba8(ImageBuffer::from_fn(W, H, |x, y| {
        let v = if inside(x, y) { 255 } else { 0 };
        Rgba([v, v, v, 255])
    }));
    let m = mask_of(&encode(&opaque, ImageFormat::Png), "o.png").unwrap();
    assert!(!m.from_alpha);
    assert_eq!(m.data, want);
    // Linear EXR: ½ is the threshold, NaN is out.
    let exr = DynamicImage::ImageRgba32F(Rgba32FImage::from_fn(W, H, |x, y| {
        let v = if inside(x, y) {
            0.6
        } else if x == 0 {
            f32::NAN
        } else {
            0.4
        };
        Rgba([v, v, v, 1.0])
    }));
    let m = mask_of(&encode(&exr, ImageFormat::OpenExr), "m.exr").unwrap();
    assert_eq!(m.data, want);
    // EXIF orientation 6 (rotate 90° clockwise): displayed H × W.
    let rgb = DynamicImage::ImageRgb8(grey.to_rgb8());
    let m = mask_of(&jpeg_with_orientation(&rgb, 6), "m.jpg").unwrap();
    assert_eq!((m.width, m.height), (H as usize, W as usize));
    for y in 0..W as usize {
        for x in 0..H as usize {
            // Displayed (x, y) shows stored (y, H − 1 − x).
            let (sx, sy) = (y as u32, H - 1 - x as u32);
            assert_eq!(m.data[y * H as usize + x], inside(sx, sy), "({x}, {y})");
        }
    }
    // Not an image, and a missing file: the photo's messages.
    let e = mask_of(b"hello", "m.png").unwrap_err().to_string();
    assert!(e.starts_with("m.png: "), "{e}");
    let e = photo::load_mask(Path::new("/nonexistent/m.png"), &PhotoLimits::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("/nonexistent/m.png") && e.contains("opening"),
        "{e}"
    );
}

/// The sRGB transfer function and its inverse (IEC 61966-2-1).
fn srgb_to_linear(v: f64) -> f64 {
    if v <= 0.04045 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

fn linear_to_srgb(v: f64) -> f64 {
    if v <= 0.0031308 {
        v * 12.92
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}

/// The RGB → XYZ matrix of primaries `(x, y)` with white D65 (the standard
/// construction from chromaticities: columns scaled so that white maps to
/// the white point).
fn rgb_to_xyz(prim: [[f64; 2]; 3]) -> [[f64; 3]; 3] {
    let (wx, wy) = (0.3127, 0.3290);
    let white = [wx / wy, 1.0, (1.0 - wx - wy) / wy];
    let col = |[x, y]: [f64; 2]| [x / y, 1.0, (1.0 - x - y) / y];
    let m = [col(prim[0]), col(prim[1]), col(prim[2])]; // columns
    let p = [
        [m[0][0], m[1][0], m[2][0]],
        [m[0][1], m[1][1], m[2][1]],
        [m[0][2], m[1][2], m[2][2]],
    ];
    let s = solve3(p, white);
    [
        [p[0][0] * s[0], p[0][1] * s[1], p[0][2] * s[2]],
        [p[1][0] * s[0], p[1][1] * s[1], p[1][2] * s[2]],
        [p[2][0] * s[0], p[2][1] * s[1], p[2][2] * s[2]],
    ]
}

/// `x` with `a x = b` (Cramer's rule).
fn solve3(a: [[f64; 3]; 3], b: [f64; 3]) -> [f64; 3] {
    let det = |m: [[f64; 3]; 3]| {
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
            - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    };
    let d = det(a);
    std::array::from_fn(|k| {
        let mut m = a;
        for r in 0..3 {
            m[r][k] = b[r];
        }
        det(m) / d
    })
}

fn invert3(a: [[f64; 3]; 3]) -> [[f64; 3]; 3] {
    let cols: [[f64; 3]; 3] = std::array::from_fn(|k| {
        let mut e = [0.0; 3];
        e[k] = 1.0;
        solve3(a, e)
    });
    std::array::from_fn(|r| std::array::from_fn(|c| cols[c][r]))
}

fn mul3(a: [[f64; 3]; 3], b: [[f64; 3]; 3]) -> [[f64; 3]; 3] {
    std::array::from_fn(|r| std::array::from_fn(|c| (0..3).map(|k| a[r][k] * b[k][c]).sum()))
}

const SRGB_PRIMARIES: [[f64; 2]; 3] = [[0.64, 0.33], [0.30, 0.60], [0.15, 0.06]];

/// What a colour-managed viewer shows for `rgb` (encoded values in a space
/// of `primaries`, white D65, tone curve `decode`): the same light in sRGB,
/// clipped to its gamut.
fn reference_to_srgb(
    rgb: [f64; 3],
    primaries: [[f64; 2]; 3],
    decode: impl Fn(f64) -> f64,
) -> [f64; 3] {
    let m = mul3(invert3(rgb_to_xyz(SRGB_PRIMARIES)), rgb_to_xyz(primaries));
    let lin = rgb.map(&decode);
    std::array::from_fn(|r| {
        let v: f64 = (0..3).map(|k| m[r][k] * lin[k]).sum();
        linear_to_srgb(v.clamp(0.0, 1.0))
    })
}

/// A colour space for [`colour_profiles_are_converted_to_srgb`]: its name,
/// its ICC profile, its primaries and its tone curve (encoded → linear).
type ProfileCase = (
    &'static str,
    moxcms::ColorProfile,
    [[f64; 2]; 3],
    Box<dyn Fn(f64) -> f64>,
);

/// A PNG of `pixels` (8-bit RGB, one row) with the colour profile `icc`.
fn png_with_profile(pixels: &[[u8; 3]], icc: Option<Vec<u8>>) -> Vec<u8> {
    let mut out = Vec::new();
    let mut enc = image::codecs::png::PngEncoder::new(&mut out);
    if let Some(icc) = icc {
        enc.set_icc_profile(icc).unwrap();
    }
    let raw: Vec<u8> = pixels.iter().flatten().copied().collect();
    enc.write_image(&raw, pixels.len() as u32, 1, image::ExtendedColorType::Rgb8)
        .unwrap();
    out
}

/// Pixels of a Display P3 or Adobe RGB photo come out as the same colours
/// in sRGB (against the standard construction from the spaces' primaries),
/// an sRGB profile leaves them byte for byte, a grey picture and an
/// unreadable profile are left alone and say why.
#[test]
fn colour_profiles_are_converted_to_srgb() {
    let pixels: Vec<[u8; 3]> = vec![
        [200, 100, 50],
        [40, 160, 90],
        [128, 128, 128],
        [250, 240, 20],
        [10, 20, 200],
        [90, 60, 40],
        [255, 0, 0],
    ];
    let adobe_gamma = 563.0 / 256.0;
    let cases: [ProfileCase; 2] = [
        (
            "Display P3",
            moxcms::ColorProfile::new_display_p3(),
            [[0.680, 0.320], [0.265, 0.690], [0.150, 0.060]],
            Box::new(srgb_to_linear),
        ),
        (
            "Adobe RGB",
            moxcms::ColorProfile::new_adobe_rgb(),
            [[0.64, 0.33], [0.21, 0.71], [0.15, 0.06]],
            Box::new(move |v: f64| v.powf(adobe_gamma)),
        ),
    ];
    for (name, profile, primaries, decode) in cases {
        let file = png_with_profile(&pixels, Some(profile.encode().unwrap()));
        let p = dec(&file, "p3.png").unwrap();
        let cp = p.colour_profile.as_ref().expect("a profile");
        assert!(cp.converted, "{name}: {cp:?}");
        for (k, px) in pixels.iter().enumerate() {
            let want = reference_to_srgb(px.map(|v| f64::from(v) / 255.0), primaries, &decode);
            let got = p.rgb.get_pixel(k as u32, 0).0;
            for c in 0..3 {
                assert!(
                    (f64::from(got[c]) - want[c]).abs() < 3e-3,
                    "{name} {px:?}: {got:?} vs {want:?}"
                );
            }
        }
    }
    // A JPEG's profile (APP2 segments) is read too.
    let mut jpg = Vec::new();
    let mut enc = JpegEncoder::new_with_quality(&mut jpg, 95);
    enc.set_icc_profile(moxcms::ColorProfile::new_display_p3().encode().unwrap())
        .unwrap();
    enc.write_image(
        &[200, 100, 50].repeat(64),
        8,
        8,
        image::ExtendedColorType::Rgb8,
    )
    .unwrap();
    let p = dec(&jpg, "p3.jpg").unwrap();
    assert!(
        p.colour_profile.as_ref().is_some_and(|c| c.converted),
        "{:?}",
        p.colour_profile
    );
    // sRGB: untouched.
    let plain = dec(&png_with_profile(&pixels, None), "plain.png").unwrap();
    assert_eq!(plain.colour_profile, None);
    let srgb = png_with_profile(
        &pixels,
        Some(moxcms::ColorProfile::new_srgb().encode().unwrap()),
    );
    let p = dec(&srgb, "srgb.png").unwrap();
    assert_eq!(p.rgb, plain.rgb);
    let cp = p.colour_profile.unwrap();
    assert!(
        !cp.converted && cp.note.as_deref() == Some("sRGB already"),
        "{cp:?}"
    );
    // Unreadable: untouched, said so.
    let junk = png_with_profile(
        &pixels,
        Some(b"not a colour profile at all, just bytes".repeat(4)),
    );
    let p = dec(&junk, "junk.png").unwrap();
    assert_eq!(p.rgb, plain.rgb);
    let note = p.colour_profile.unwrap().note.unwrap();
    assert!(note.starts_with("unreadable ("), "{note}");
    // A grey picture with an RGB profile: its grey stays grey.
    let mut out = Vec::new();
    let mut enc = image::codecs::png::PngEncoder::new(&mut out);
    enc.set_icc_profile(moxcms::ColorProfile::new_display_p3().encode().unwrap())
        .unwrap();
    enc.write_image(&[10, 100, 200], 3, 1, image::ExtendedColorType::L8)
        .unwrap();
    let p = dec(&out, "grey.png").unwrap();
    let note = p.colour_profile.unwrap().note.unwrap();
    assert_eq!(note, "a grey picture: not applied");
}
