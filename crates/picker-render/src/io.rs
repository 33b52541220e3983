//! Planar `f32` images and their files: EXR (exact `f32`, channels `R,G,B` or
//! `Y`), 8-bit PNG (display values) and 16-bit PNG (ids, precise previews).
//! Every write is atomic ([`picker_nets::write_atomic`]: temporary file in the
//! same directory, fsync, rename), so a crash never leaves a half-written file.
//! `picker infer`, `picker synth` and `picker render` all write through here.

use std::io::Cursor;
use std::path::Path;

use crate::error::{Error, Result};

/// A planar `f32` image: `channels` planes of `height × width` values, row-major,
/// row 0 at the top (`data[c·h·w + row·w + col]`).
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    /// Number of planes (1 grey, 3 RGB, ...).
    pub channels: usize,
    /// Rows.
    pub height: usize,
    /// Columns.
    pub width: usize,
    /// `channels · height · width` values, plane after plane.
    pub data: Vec<f32>,
}

impl Image {
    /// An image from planar data; refuses a length that is not `channels·height·width`.
    pub fn new(channels: usize, height: usize, width: usize, data: Vec<f32>) -> Result<Self> {
        let Some(n) = channels
            .checked_mul(height)
            .and_then(|v| v.checked_mul(width))
        else {
            return Err(Error::shape(
                format!("{channels}x{height}x{width} image"),
                "a size that fits in memory",
                "an overflowing size",
            ));
        };
        if data.len() != n {
            return Err(Error::shape(
                format!("{channels}x{height}x{width} image"),
                format!("{n} values"),
                data.len(),
            ));
        }
        Ok(Self {
            channels,
            height,
            width,
            data,
        })
    }

    /// An image of zeros.
    ///
    /// # Panics
    /// When `channels · height · width` overflows `usize`.
    pub fn zeros(channels: usize, height: usize, width: usize) -> Self {
        let n = channels
            .checked_mul(height)
            .and_then(|v| v.checked_mul(width))
            .unwrap_or_else(|| panic!("Image::zeros: {channels}x{height}x{width} overflows"));
        Self {
            channels,
            height,
            width,
            data: vec![0.0; n],
        }
    }

    /// Refuses an image whose fields disagree (they are public): a data
    /// length other than `channels · height · width`, or no channel at all
    /// where pixels are read; `what` names it in the error.
    pub fn check_readable(&self, what: &str) -> Result<()> {
        let n = self
            .channels
            .checked_mul(self.height)
            .and_then(|v| v.checked_mul(self.width));
        if n != Some(self.data.len()) {
            return Err(Error::shape(
                format!("{what} ({}x{}x{})", self.channels, self.height, self.width),
                "channels x height x width values",
                format!("{} values", self.data.len()),
            ));
        }
        if self.channels == 0 && self.height * self.width > 0 {
            return Err(Error::shape(format!("{what} channels"), "at least 1", 0));
        }
        Ok(())
    }

    /// Pixels per plane (`height · width`).
    pub fn plane_len(&self) -> usize {
        self.height * self.width
    }

    /// Plane `c`.
    pub fn plane(&self, c: usize) -> &[f32] {
        let n = self.plane_len();
        &self.data[c * n..(c + 1) * n]
    }

    /// Value of channel `c` at pixel index `i = row·width + col`.
    pub fn at(&self, c: usize, i: usize) -> f32 {
        self.data[c * self.plane_len() + i]
    }

    /// The first three channels at pixel index `i` (a one-channel image repeats its value).
    pub fn rgb(&self, i: usize) -> glam::Vec3 {
        if self.channels >= 3 {
            glam::Vec3::new(self.at(0, i), self.at(1, i), self.at(2, i))
        } else {
            glam::Vec3::splat(self.at(0, i))
        }
    }

    /// Sets the first three channels at pixel index `i` (needs ≥ 3 channels).
    pub fn set_rgb(&mut self, i: usize, v: glam::Vec3) {
        let n = self.plane_len();
        self.data[i] = v.x;
        self.data[n + i] = v.y;
        self.data[2 * n + i] = v.z;
    }

    /// Every value passed through `f`.
    pub fn map(&self, f: impl Fn(f32) -> f32) -> Image {
        Image {
            data: self.data.iter().map(|&v| f(v)).collect(),
            ..self.clone()
        }
    }
}

/// Writes `bytes` to `path` atomically (via [`picker_nets::write_atomic`]).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    picker_nets::write_atomic(path, bytes).map_err(|e| match Error::from(e) {
        Error::Io {
            path: p,
            op,
            source,
        } if p.as_os_str().is_empty() => Error::io(path, op, source),
        other => other,
    })
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

fn check_planes(format: &'static str, planes: &[f32], c: usize, w: usize, h: usize) -> Result<()> {
    if c == 0 || planes.len() != c * w * h {
        return Err(Error::Encode {
            format,
            reason: format!("given {} values for {c} channels of {w}x{h}", planes.len()),
        });
    }
    Ok(())
}

/// Encodes planar f32 data (`c` planes of `w × h`, row-major, row 0 at the
/// top) as a single-layer, losslessly compressed, 32-bit float OpenEXR file
/// with the channels of [`exr_channel_names`].
pub fn encode_exr(planes: &[f32], c: usize, w: usize, h: usize) -> Result<Vec<u8>> {
    use exr::prelude::*;
    check_planes("EXR", planes, c, w, h)?;
    let n = w * h;
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
        .map_err(|e| crate::error::Error::Encode {
            format: "EXR",
            reason: e.to_string(),
        })?;
    Ok(buf.into_inner())
}

/// Quantises a display value in `[0, 1]` to 8 bits (rounded, clamped; NaN → 0).
pub fn to_u8(v: f32) -> u8 {
    if v.is_nan() {
        0
    } else {
        (v.clamp(0.0, 1.0) * 255.0).round() as u8
    }
}

/// Quantises a display value in `[0, 1]` to 16 bits (rounded, clamped; NaN → 0).
pub fn to_u16(v: f32) -> u16 {
    if v.is_nan() {
        0
    } else {
        (v.clamp(0.0, 1.0) * 65535.0).round() as u16
    }
}

fn png_dims(w: usize, h: usize) -> Result<(u32, u32)> {
    let bad = |what| Error::Encode {
        format: "PNG",
        reason: format!("image too {what}"),
    };
    Ok((
        u32::try_from(w).map_err(|_| bad("wide"))?,
        u32::try_from(h).map_err(|_| bad("tall"))?,
    ))
}

fn png_bytes(img: image::DynamicImage) -> Result<Vec<u8>> {
    let mut buf = Cursor::new(Vec::new());
    img.write_to(&mut buf, image::ImageFormat::Png)
        .map_err(|e| Error::Encode {
            format: "PNG",
            reason: e.to_string(),
        })?;
    Ok(buf.into_inner())
}

/// Interleaves `c` planes of `n` values, quantised by `q`; pixels in
/// parallel chunks (each value on its own: the same bytes for any thread
/// count).
fn interleave<T: Copy + Default + Send>(
    planes: &[f32],
    c: usize,
    n: usize,
    q: impl Fn(f32) -> T + Sync,
) -> Vec<T> {
    use rayon::prelude::*;
    const CHUNK: usize = 1 << 14;
    let mut px = vec![T::default(); c * n];
    px.par_chunks_mut(CHUNK * c.max(1))
        .enumerate()
        .for_each(|(k, out)| {
            for (j, p) in out.chunks_mut(c.max(1)).enumerate() {
                let i = k * CHUNK + j;
                for (ch, o) in p.iter_mut().enumerate() {
                    *o = q(planes[ch * n + i]);
                }
            }
        });
    px
}

fn check_png(planes: &[f32], c: usize, w: usize, h: usize) -> Result<()> {
    check_planes("PNG", planes, c, w, h)?;
    if c != 1 && c != 3 && c != 4 {
        return Err(Error::Encode {
            format: "PNG",
            reason: format!("needs 1, 3 or 4 channels, given {c}"),
        });
    }
    Ok(())
}

/// Encodes planar display values in `[0, 1]` (`c` = 1 grey, 3 RGB or 4 RGBA
/// planes of `w × h`) as an 8-bit PNG ([`to_u8`]; no transfer function is applied).
pub fn encode_png(planes: &[f32], c: usize, w: usize, h: usize) -> Result<Vec<u8>> {
    encode_png_mapped(planes, c, w, h, |v| v)
}

/// [`encode_png`] of `map` applied to every value first (a transfer
/// function, e.g. sRGB encoding of linear values), without a mapped copy of
/// the planes.
pub fn encode_png_mapped(
    planes: &[f32],
    c: usize,
    w: usize,
    h: usize,
    map: impl Fn(f32) -> f32 + Sync,
) -> Result<Vec<u8>> {
    encode_png_as(planes, c, w, h, |v| to_u8(map(v)))
}

/// The PNG of planar values quantised by `q` to samples of type `T` (8 or
/// 16 bits), 1, 3 or 4 channels.
fn encode_png_as<T>(
    planes: &[f32],
    c: usize,
    w: usize,
    h: usize,
    q: impl Fn(f32) -> T + Sync,
) -> Result<Vec<u8>>
where
    T: image::Primitive + Default + Send,
    image::Luma<T>: image::Pixel<Subpixel = T>,
    image::Rgb<T>: image::Pixel<Subpixel = T>,
    image::Rgba<T>: image::Pixel<Subpixel = T>,
    image::ImageBuffer<image::Luma<T>, Vec<T>>: Into<image::DynamicImage>,
    image::ImageBuffer<image::Rgb<T>, Vec<T>>: Into<image::DynamicImage>,
    image::ImageBuffer<image::Rgba<T>, Vec<T>>: Into<image::DynamicImage>,
{
    check_png(planes, c, w, h)?;
    let (wu, hu) = png_dims(w, h)?;
    let px = interleave(planes, c, w * h, q);
    let mismatch = || Error::Encode {
        format: "PNG",
        reason: "buffer size mismatch".into(),
    };
    let img: image::DynamicImage = match c {
        1 => image::ImageBuffer::<image::Luma<T>, _>::from_raw(wu, hu, px)
            .ok_or_else(mismatch)?
            .into(),
        3 => image::ImageBuffer::<image::Rgb<T>, _>::from_raw(wu, hu, px)
            .ok_or_else(mismatch)?
            .into(),
        _ => image::ImageBuffer::<image::Rgba<T>, _>::from_raw(wu, hu, px)
            .ok_or_else(mismatch)?
            .into(),
    };
    png_bytes(img)
}

/// Like [`encode_png`] with 16 bits per sample ([`to_u16`]).
pub fn encode_png16(planes: &[f32], c: usize, w: usize, h: usize) -> Result<Vec<u8>> {
    encode_png16_mapped(planes, c, w, h, |v| v)
}

/// [`encode_png16`] of `map` applied to every value first (as
/// [`encode_png_mapped`]).
pub fn encode_png16_mapped(
    planes: &[f32],
    c: usize,
    w: usize,
    h: usize,
    map: impl Fn(f32) -> f32 + Sync,
) -> Result<Vec<u8>> {
    encode_png_as(planes, c, w, h, |v| to_u16(map(v)))
}

/// Writes `img` as a 32-bit float EXR ([`encode_exr`]), atomically.
pub fn write_exr(path: &Path, img: &Image) -> Result<()> {
    let bytes = encode_exr(&img.data, img.channels, img.width, img.height)?;
    write_atomic(path, &bytes)
}

/// Writes `img` (display values in `[0, 1]`) as an 8-bit PNG ([`encode_png`]), atomically.
pub fn write_png(path: &Path, img: &Image) -> Result<()> {
    let bytes = encode_png(&img.data, img.channels, img.width, img.height)?;
    write_atomic(path, &bytes)
}

/// Writes `img` with `map` applied to every value (a transfer function, e.g.
/// sRGB encoding of linear values) as an 8-bit PNG, or a 16-bit one with
/// `sixteen_bit` ([`encode_png_mapped`], [`encode_png16_mapped`]), atomically.
pub fn write_png_mapped(
    path: &Path,
    img: &Image,
    sixteen_bit: bool,
    map: impl Fn(f32) -> f32 + Sync,
) -> Result<()> {
    let (d, c, w, h) = (&img.data, img.channels, img.width, img.height);
    let bytes = if sixteen_bit {
        encode_png16_mapped(d, c, w, h, map)?
    } else {
        encode_png_mapped(d, c, w, h, map)?
    };
    write_atomic(path, &bytes)
}

/// Writes `img` (values in `[0, 1]`) as a 16-bit PNG ([`encode_png16`]), atomically.
pub fn write_png16(path: &Path, img: &Image) -> Result<()> {
    let bytes = encode_png16(&img.data, img.channels, img.width, img.height)?;
    write_atomic(path, &bytes)
}

/// Reads an EXR's first layer (any sample type: f32, f16, u32, as f32) into a
/// planar image: channels `R,G,B` (an `A` is dropped) → 3 planes, `Y` → 1 plane,
/// otherwise every channel in the file's (alphabetical) order.
pub fn read_exr(path: &Path) -> Result<Image> {
    let img = exr::prelude::read_all_flat_layers_from_file(path).map_err(|e| match e {
        exr::error::Error::Io(io) => Error::io(path, "read", io),
        other => Error::decode(path, other),
    })?;
    let layer = img
        .layer_data
        .first()
        .ok_or_else(|| Error::decode(path, "no layer"))?;
    let (w, h) = (layer.size.width(), layer.size.height());
    let list = &layer.channel_data.list;
    let find = |name: &str| list.iter().find(|c| c.name.to_string() == name);
    let chosen: Vec<_> = match (find("R"), find("G"), find("B"), find("Y")) {
        (Some(r), Some(g), Some(b), _) => vec![r, g, b],
        (_, _, _, Some(y)) => vec![y],
        _ => list.iter().collect(),
    };
    let mut data = Vec::with_capacity(chosen.len() * w * h);
    for ch in &chosen {
        data.extend(ch.sample_data.values_as_f32());
    }
    Image::new(chosen.len(), h, w, data).map_err(|e| Error::decode(path, e))
}

/// Reads a PNG (8- or 16-bit, grey, grey+alpha, RGB or RGBA) into values in
/// `[0, 1]` as stored (no transfer function): grey → 1 plane, colour → 3 planes
/// (alpha dropped).
pub fn read_png(path: &Path) -> Result<Image> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, "read", e))?;
    let dynimg = image::load_from_memory_with_format(&bytes, image::ImageFormat::Png)
        .map_err(|e| Error::decode(path, e))?;
    let (w, h) = (dynimg.width() as usize, dynimg.height() as usize);
    let grey = !dynimg.color().has_color();
    if grey {
        let g = dynimg.to_luma32f();
        Image::new(1, h, w, g.into_raw()).map_err(|e| Error::decode(path, e))
    } else {
        let rgb = dynimg.to_rgb32f().into_raw();
        let n = w * h;
        let mut data = vec![0.0; 3 * n];
        for i in 0..n {
            for c in 0..3 {
                data[c * n + i] = rgb[3 * i + c];
            }
        }
        Image::new(3, h, w, data).map_err(|e| Error::decode(path, e))
    }
}

/// Reads an EXR or PNG by its extension (`.exr` → [`read_exr`], `.png` → [`read_png`]).
pub fn read_image(path: &Path) -> Result<Image> {
    match extension(path).as_str() {
        "exr" => read_exr(path),
        "png" => read_png(path),
        other => Err(Error::decode(
            path,
            format!("unsupported image type {other:?} (expected .exr or .png)"),
        )),
    }
}

/// The lower-case extension of `path` (empty if none).
pub(crate) fn extension(path: &Path) -> String {
    path.extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default()
}

/// The inverse of [`picker_nets::conventions::srgb_encode`] (IEC 61966-2-1):
/// encoded `[0, 1]` → linear; values outside `[0, 1]` are clamped, NaN gives 0.
pub fn srgb_decode(v: f32) -> f32 {
    if v.is_nan() {
        return 0.0;
    }
    let v = v.clamp(0.0, 1.0);
    if v <= 0.040_45 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use picker_nets::conventions::srgb_encode;

    /// The mapped encoders equal the plain ones on mapped planes, byte for
    /// byte, on 1, 3 and 4 channels and sizes around the parallel chunk
    /// (16384 pixels), and the interleave equals a plain loop.
    #[test]
    fn mapped_png_equals_png_of_the_mapped_planes() {
        let map = |v: f32| (v * 1.7 - 0.2).sqrt();
        let mut seed = 12345u64;
        let mut next = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 40) as f32 / (1u64 << 24) as f32
        };
        for (c, w, h) in [
            (1, 1, 1),
            (3, 5, 3),
            (4, 7, 2),
            (3, 128, 128),
            (3, 16385, 1),
            (1, 3, 7000),
        ] {
            let planes: Vec<f32> = (0..c * w * h).map(|_| next() * 1.2 - 0.1).collect();
            let mapped: Vec<f32> = planes.iter().map(|&v| map(v)).collect();
            assert_eq!(
                encode_png_mapped(&planes, c, w, h, map).unwrap(),
                encode_png(&mapped, c, w, h).unwrap(),
                "{c}x{w}x{h}"
            );
            assert_eq!(
                encode_png16_mapped(&planes, c, w, h, map).unwrap(),
                encode_png16(&mapped, c, w, h).unwrap(),
                "16-bit {c}x{w}x{h}"
            );
            let n = w * h;
            let plain: Vec<u8> = (0..n)
                .flat_map(|i| (0..c).map(move |ch| (ch, i)))
                .map(|(ch, i)| to_u8(planes[ch * n + i]))
                .collect();
            assert_eq!(interleave(&planes, c, n, to_u8), plain, "{c}x{w}x{h}");
        }
    }

    #[test]
    fn quantisation() {
        assert_eq!(to_u8(-1.0), 0);
        assert_eq!(to_u8(0.5), 128);
        assert_eq!(to_u8(2.0), 255);
        assert_eq!(to_u8(f32::NAN), 0);
        assert_eq!(to_u16(1.0), 65535);
        for i in 0..=100 {
            let v = i as f32 / 100.0;
            assert!((srgb_decode(srgb_encode(v)) - v).abs() < 1e-5);
        }
    }

    #[test]
    fn atomic_write_replaces_and_leaves_no_temp() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.txt");
        write_atomic(&p, b"one").unwrap();
        write_atomic(&p, b"two").unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"two");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
        let e = write_atomic(&dir.path().join("no/such/dir/x"), b"x").unwrap_err();
        assert!(e.to_string().contains("no/such/dir"), "{e}");
    }

    #[test]
    fn exr_and_png_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let (h, w) = (3, 5);
        let data: Vec<f32> = (0..3 * h * w).map(|i| i as f32 * 0.37 - 2.0).collect();
        let img = Image::new(3, h, w, data).unwrap();
        let p = dir.path().join("x.exr");
        write_exr(&p, &img).unwrap();
        assert_eq!(read_image(&p).unwrap(), img);
        let grey = Image::new(1, h, w, (0..h * w).map(|i| i as f32).collect()).unwrap();
        write_exr(&p, &grey).unwrap();
        assert_eq!(read_exr(&p).unwrap(), grey);

        let disp = img.map(|v| (v + 2.0) / 6.0);
        let p8 = dir.path().join("x.png");
        write_png(&p8, &disp).unwrap();
        let back = read_image(&p8).unwrap();
        assert_eq!((back.channels, back.height, back.width), (3, h, w));
        for (a, b) in back.data.iter().zip(&disp.data) {
            assert!((a - b.clamp(0.0, 1.0)).abs() <= 0.5 / 255.0 + 1e-6);
        }
        write_png16(&p8, &disp).unwrap();
        let back = read_png(&p8).unwrap();
        for (a, b) in back.data.iter().zip(&disp.data) {
            assert!((a - b.clamp(0.0, 1.0)).abs() <= 0.5 / 65535.0 + 1e-6);
        }
        write_png16(&p8, &grey.map(|v| v / 20.0)).unwrap();
        assert_eq!(read_png(&p8).unwrap().channels, 1);
    }

    #[test]
    fn errors_name_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("missing.exr");
        assert!(read_exr(&p)
            .unwrap_err()
            .to_string()
            .contains("missing.exr"));
        let bad = dir.path().join("bad.png");
        std::fs::write(&bad, b"not a png").unwrap();
        assert!(read_png(&bad).unwrap_err().to_string().contains("bad.png"));
        assert!(read_image(&dir.path().join("a.jpg")).is_err());
        assert!(encode_png(&[0.0; 6], 2, 3, 1).is_err());
        assert!(Image::new(3, 2, 2, vec![0.0; 5]).is_err());
    }
}
