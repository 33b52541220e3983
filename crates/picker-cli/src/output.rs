//! Writing result files: an atomic-write helper, EXR (exact f32) and 8-bit PNG encoders.

use std::io::{Cursor, Write};
use std::path::{Path, PathBuf};

use anyhow::{anyhow, Context, Result};

/// Writes `bytes` to `path` atomically: into a temporary file in the same
/// directory, flushed, then renamed over `path`. On failure the temporary file
/// is removed and `path` is left as it was. Errors name `path`.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let name = path
        .file_name()
        .ok_or_else(|| anyhow!("{}: not a file path", path.display()))?
        .to_string_lossy();
    let tmp = dir.join(format!(".{name}.{}.tmp", std::process::id()));
    let result = (|| -> std::io::Result<()> {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        drop(f);
        std::fs::rename(&tmp, path)
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result.with_context(|| format!("writing {}", path.display()))
}

/// EXR channel names for `c` channels: `Y` for one, `R G B` for three,
/// `R G B A` for four, `C0 C1 …` otherwise.
pub fn exr_channel_names(c: usize) -> Vec<String> {
    match c {
        1 => vec!["Y".into()],
        3 => ["R", "G", "B"].map(String::from).to_vec(),
        4 => ["R", "G", "B", "A"].map(String::from).to_vec(),
        _ => (0..c).map(|i| format!("C{i}")).collect(),
    }
}

/// Encodes planar f32 data (`c` planes of `w × h`, row-major, row 0 at the
/// top) as a single-layer, losslessly compressed, 32-bit float OpenEXR file.
pub fn encode_exr(planes: &[f32], c: usize, w: usize, h: usize) -> Result<Vec<u8>> {
    use exr::prelude::*;
    let n = w * h;
    anyhow::ensure!(
        c > 0 && planes.len() == c * n,
        "EXR encoder given {} values for {c} channels of {w}x{h}",
        planes.len()
    );
    let channels: Vec<AnyChannel<FlatSamples>> = exr_channel_names(c)
        .into_iter()
        .enumerate()
        .map(|(i, name)| {
            AnyChannel::new(
                name.as_str(),
                FlatSamples::F32(planes[i * n..(i + 1) * n].to_vec()),
            )
        })
        .collect();
    let layer = Layer::new(
        (w, h),
        LayerAttributes::default(),
        Encoding::FAST_LOSSLESS,
        AnyChannels::sort(SmallVec::from_vec(channels)),
    );
    let mut buf = Cursor::new(Vec::new());
    Image::from_layer(layer)
        .write()
        .non_parallel()
        .to_buffered(&mut buf)
        .map_err(|e| anyhow!("encoding EXR: {e}"))?;
    Ok(buf.into_inner())
}

/// Quantises a display value in `[0, 1]` to 8 bits (rounded, clamped; NaN → 0).
fn to_u8(v: f32) -> u8 {
    if v.is_nan() {
        0
    } else {
        (v.clamp(0.0, 1.0) * 255.0).round() as u8
    }
}

/// Encodes planar display values in `[0, 1]` (`c` = 1 grey or 3 RGB planes of
/// `w × h`) as an 8-bit PNG.
pub fn encode_png(planes: &[f32], c: usize, w: usize, h: usize) -> Result<Vec<u8>> {
    let n = w * h;
    anyhow::ensure!(
        (c == 1 || c == 3) && planes.len() == c * n,
        "PNG encoder given {} values for {c} channels of {w}x{h}",
        planes.len()
    );
    let (wu, hu) = (
        u32::try_from(w).context("image too wide")?,
        u32::try_from(h).context("image too tall")?,
    );
    let img: image::DynamicImage = if c == 1 {
        let px: Vec<u8> = planes.iter().copied().map(to_u8).collect();
        image::GrayImage::from_raw(wu, hu, px)
            .ok_or_else(|| anyhow!("PNG buffer size mismatch"))?
            .into()
    } else {
        let mut px = Vec::with_capacity(3 * n);
        for i in 0..n {
            for ch in 0..3 {
                px.push(to_u8(planes[ch * n + i]));
            }
        }
        image::RgbImage::from_raw(wu, hu, px)
            .ok_or_else(|| anyhow!("PNG buffer size mismatch"))?
            .into()
    };
    let mut buf = Cursor::new(Vec::new());
    img.write_to(&mut buf, image::ImageFormat::Png)
        .context("encoding PNG")?;
    Ok(buf.into_inner())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn atomic_write_replaces_and_leaves_no_temp() {
        let dir = std::env::temp_dir().join(format!("picker-cli-aw-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("a.txt");
        write_atomic(&p, b"one").unwrap();
        write_atomic(&p, b"two").unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"two");
        let names: Vec<_> = std::fs::read_dir(&dir).unwrap().collect();
        assert_eq!(names.len(), 1);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn quantisation() {
        assert_eq!(to_u8(-1.0), 0);
        assert_eq!(to_u8(0.5), 128);
        assert_eq!(to_u8(2.0), 255);
        assert_eq!(to_u8(f32::NAN), 0);
    }

    #[test]
    fn encoders_produce_files() {
        let planes = vec![0.25f32; 3 * 6];
        assert!(encode_exr(&planes, 3, 3, 2)
            .unwrap()
            .starts_with(&[0x76, 0x2f, 0x31, 0x01]));
        assert!(encode_png(&planes, 3, 3, 2)
            .unwrap()
            .starts_with(b"\x89PNG"));
        assert!(encode_exr(&planes[..6], 1, 3, 2).is_ok());
        assert!(encode_png(&planes, 2, 3, 3).is_err());
    }
}
