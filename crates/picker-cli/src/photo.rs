//! Reading a photograph and making the working-resolution copy the networks see.
//!
//! Any format the `image` crate is built with here (PNG, JPEG, TIFF, WebP, BMP)
//! at any bit depth is read; greyscale is replicated to RGB, alpha is dropped
//! (not composited), 16-bit and float samples keep their precision. The EXIF
//! orientation is applied, so pixel coordinates are those of the photo as a
//! viewer shows it (design §2). Values are sRGB-encoded in `[0, 1]`.

use std::path::Path;

use anyhow::{Context, Result};
use image::imageops::FilterType;
use image::{DynamicImage, ImageDecoder, ImageReader, Rgb32FImage};

/// A decoded photo: sRGB values in `[0, 1]` (float inputs clamped, NaN → 0),
/// EXIF orientation applied.
pub struct Photo {
    /// The pixels, RGB f32, row-major.
    pub rgb: Rgb32FImage,
    /// The EXIF orientation that was applied (`NoTransforms` when none).
    pub orientation: image::metadata::Orientation,
    /// The format the file was decoded as (e.g. `Png`).
    pub format: Option<image::ImageFormat>,
}

/// Reads `path`, applying its EXIF orientation. Errors name the file.
pub fn load(path: &Path) -> Result<Photo> {
    let ctx = || format!("reading photo {}", path.display());
    let bytes = std::fs::read(path).with_context(ctx)?;
    let reader = ImageReader::new(std::io::Cursor::new(&bytes))
        .with_guessed_format()
        .with_context(ctx)?;
    let format = reader.format();
    // The JPEG decoder fills a cut-off file with grey instead of failing.
    if format == Some(image::ImageFormat::Jpeg) && !jpeg_is_complete(&bytes) {
        anyhow::bail!(
            "reading photo {}: the JPEG data is truncated (no end-of-image marker after the image data)",
            path.display()
        );
    }
    let mut decoder = reader.into_decoder().with_context(ctx)?;
    // A broken EXIF block is not worth refusing the photo for.
    let orientation = decoder
        .orientation()
        .unwrap_or(image::metadata::Orientation::NoTransforms);
    let mut img = DynamicImage::from_decoder(decoder).with_context(ctx)?;
    img.apply_orientation(orientation);
    if img.width() == 0 || img.height() == 0 {
        anyhow::bail!("{}: the image is empty (0 pixels)", path.display());
    }
    let mut rgb = img.to_rgb32f();
    // Float formats (e.g. 32-bit TIFF) may hold values outside [0, 1] or NaN.
    for v in rgb.iter_mut() {
        *v = if v.is_nan() { 0.0 } else { v.clamp(0.0, 1.0) };
    }
    Ok(Photo {
        rgb,
        orientation,
        format,
    })
}

/// True when a JPEG stream has an end-of-image marker (`FF D9`) after its
/// first scan. The marker segments before the scan are walked by their
/// lengths, so an EXIF thumbnail's own end marker does not count; inside the
/// entropy-coded data `FF` is always followed by `00` or a restart marker.
fn jpeg_is_complete(b: &[u8]) -> bool {
    if !b.starts_with(&[0xFF, 0xD8]) {
        return false;
    }
    let mut i = 2;
    loop {
        while b.get(i) == Some(&0xFF) && b.get(i + 1) == Some(&0xFF) {
            i += 1; // fill bytes
        }
        match (b.get(i), b.get(i + 1)) {
            (Some(0xFF), Some(0xDA)) => break, // start of scan
            (Some(0xFF), Some(0xD9)) | (None, _) | (_, None) => return false,
            (Some(0xFF), Some(m)) if (0xD0..=0xD7).contains(m) || *m == 0x01 => i += 2,
            (Some(0xFF), Some(_)) => match (b.get(i + 2), b.get(i + 3)) {
                (Some(&hi), Some(&lo)) => i += 2 + u16::from_be_bytes([hi, lo]) as usize,
                _ => return false,
            },
            _ => return false,
        }
    }
    b[i..].windows(2).any(|w| w == [0xFF, 0xD9])
}

/// The working size `(width, height)` for a `w × h` photo: the long side
/// becomes exactly `work_size` (up or down), the short side keeps the aspect
/// ratio (rounded, at least 1).
pub fn working_size(w: u32, h: u32, work_size: u32) -> (u32, u32) {
    let (long, short) = (w.max(h) as u64, w.min(h) as u64);
    let s = work_size as u64;
    let short_new = ((short * s + long / 2) / long).max(1) as u32;
    if w >= h {
        (work_size, short_new)
    } else {
        (short_new, work_size)
    }
}

/// Resizes to `(w, h)` with the `image` crate's triangle (bilinear) filter,
/// which widens its support when shrinking, so downscaling is antialiased.
/// Resampling happens on the sRGB-encoded values, as the training pipeline's
/// image loaders do. Returns the image unchanged when the size already matches.
pub fn resize(rgb: &Rgb32FImage, w: u32, h: u32) -> Rgb32FImage {
    if rgb.dimensions() == (w, h) {
        return rgb.clone();
    }
    image::imageops::resize(rgb, w, h, FilterType::Triangle)
}

/// The image as planar `[3, h, w]` values (R plane, G plane, B plane), ready
/// to wrap as an NCHW tensor with batch 1.
pub fn to_planar(rgb: &Rgb32FImage) -> Vec<f32> {
    let (w, h) = rgb.dimensions();
    let n = (w * h) as usize;
    let mut planes = vec![0.0f32; 3 * n];
    for (i, p) in rgb.pixels().enumerate() {
        for c in 0..3 {
            planes[c * n + i] = p.0[c];
        }
    }
    planes
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn jpeg_completeness() {
        let full = std::fs::read(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../fixtures/examples/coffee.jpg"
        ))
        .unwrap();
        assert!(jpeg_is_complete(&full));
        for cut in [2, 100, 700, full.len() / 2, full.len() - 2] {
            assert!(!jpeg_is_complete(&full[..cut]), "cut at {cut}");
        }
        assert!(!jpeg_is_complete(b"not a jpeg"));
    }

    #[test]
    fn working_size_keeps_aspect() {
        assert_eq!(working_size(600, 400, 320), (320, 213));
        assert_eq!(working_size(400, 600, 320), (213, 320));
        assert_eq!(working_size(37, 53, 320), (223, 320));
        assert_eq!(working_size(1000, 1, 320), (320, 1));
        assert_eq!(working_size(5, 5, 320), (320, 320));
    }

    #[test]
    fn planar_layout() {
        let mut img = Rgb32FImage::new(2, 1);
        img.put_pixel(0, 0, image::Rgb([0.1, 0.2, 0.3]));
        img.put_pixel(1, 0, image::Rgb([0.4, 0.5, 0.6]));
        assert_eq!(to_planar(&img), vec![0.1, 0.4, 0.2, 0.5, 0.3, 0.6]);
    }
}
