//! Reading a photograph: the inputs people actually have (design §2).
//!
//! [`decode`] turns the bytes of a file into a [`Photo`]: RGB `f32` values,
//! sRGB-encoded in `[0, 1]`, with the EXIF orientation applied, so pixel
//! coordinates are those of the photo as a viewer shows it.
//!
//! - **Formats.** PNG, JPEG, TIFF, WebP and BMP at any bit depth the `image`
//!   crate reads (1–16 bit integer, and 32-bit float TIFF), float TIFFs of
//!   16, 32 or 64 bits it does not (read with the `tiff` crate), plus
//!   OpenEXR and Radiance HDR. The format is found from the *content*, never
//!   from the file name: a PNG named `.jpg` decodes fine and
//!   [`Photo::format`] says `"png"`
//!   (compare with [`format_for_extension`] to warn about it). A mislabelled
//!   file only fails when its content does not decode, and then the message
//!   says both what it is named and what it contains.
//! - **Channels.** Greyscale is replicated to RGB. 16-bit and float samples
//!   keep their precision.
//! - **Transparency.** Alpha is not composited over any background. A pixel
//!   whose alpha is below ½ shows nothing of the scene (a cut-out's
//!   background): it is listed in [`Photo::opaque`] as not opaque, and its
//!   colour becomes [`TRANSPARENT_FILL`] (neutral grey: what it stored is
//!   often black or left-over garbage, and the networks see it). Pixels at
//!   ½ or above keep their colour as stored (straight alpha), except in
//!   OpenEXR files, whose colours are premultiplied by alpha by the
//!   format's convention and are divided by it. A file whose every pixel is
//!   below ½ has its alpha ignored ([`Photo::alpha_ignored`]): a viewer
//!   shows nothing, so its colours are all there is.
//! - **Display-referred inputs** (everything but EXR/HDR) are taken as
//!   sRGB-encoded: integers are scaled to `[0, 1]`, float TIFF values are
//!   clamped to `[0, 1]` and NaN becomes 0; a colour profile (ICC) in the
//!   file is applied first, converting the values to sRGB ([`to_srgb`]).
//! - **JPEG data** is walked block by block ([`crate::jpeg`]) while it
//!   decodes: a file whose data stops early or is damaged is refused rather
//!   than decoded into grey or garbage.
//! - **Linear inputs** (EXR, HDR; [`Photo::linear_input`]) hold scene-linear
//!   radiance. They are brought to the sRGB-encoded range the networks were
//!   trained on by [`expose_linear`]: NaN, infinities and negative values
//!   become 0; when the 99th percentile of the luminance
//!   (`0.2126 R + 0.7152 G + 0.0722 B`) exceeds 1 the image is scaled so that
//!   it becomes exactly 1 (otherwise it is left as is, never brightened); then
//!   each channel is sRGB-encoded (IEC 61966-2-1) and clamped to `[0, 1]`.
//! - **Decompression bombs.** The dimensions are read from the header before
//!   any pixel is decoded, and the photo is refused when it has more than
//!   [`PhotoLimits::max_pixels`] pixels, or when decoding it would need more
//!   than [`PhotoLimits::max_alloc`] bytes at the budget of
//!   [`PEAK_BYTES_PER_PIXEL`]. The same limits are handed to the decoder
//!   (`image::Limits`), so a header that lies cannot make it allocate more.
//!
//! Every failure is a [`PhotoError`] whose message is one line naming the
//! file and saying what is wrong with it.
//!
//! ```
//! use picker_extract::photo::{self, PhotoLimits};
//! use std::path::Path;
//!
//! let err = photo::decode(b"", Path::new("photo.png"), &PhotoLimits::default()).unwrap_err();
//! assert_eq!(err.to_string(), "photo.png: the file is empty (0 bytes)");
//! ```

use std::io::{Cursor, Read};
use std::path::{Path, PathBuf};

use image::imageops::FilterType;
use image::metadata::Orientation;
use image::{DynamicImage, ImageDecoder, ImageError, ImageFormat, ImageReader, Rgb32FImage};

/// The file extensions [`is_supported_extension`] accepts (lower case,
/// without the dot).
pub const SUPPORTED_EXTENSIONS: &[&str] = &[
    "png", "jpg", "jpeg", "tif", "tiff", "webp", "bmp", "exr", "hdr",
];

/// The supported formats as named in messages.
const SUPPORTED_LIST: &str = "PNG, JPEG, TIFF, WebP, BMP, OpenEXR, Radiance HDR";

/// The decode memory budget, in bytes per photo pixel, that
/// [`PhotoLimits::max_alloc`] is checked against before decoding.
///
/// At its peak, decoding holds the decoder's native buffer (up to 16 B/px,
/// RGBA `f32`) and the `f32` RGB copy being made of it (12 B/px); the EXR
/// decoder also holds its own `f32` copy of the pixels (up to 16 B/px) while
/// it fills the native buffer, and a 90° orientation needs a second 12 B/px
/// image. The worst case, float RGBA EXR, is 32 B/px; an 8-bit JPEG or PNG
/// peaks at about 15–24 B/px. The returned [`Photo`] keeps 12 B/px. Not
/// counted: the file's bytes themselves (and a copy of them the JPEG decoder
/// makes), and the decoders' small per-row or per-strip buffers.
pub const PEAK_BYTES_PER_PIXEL: u64 = 32;

/// The default [`PhotoLimits::max_pixels`]: 100 megapixels.
pub const DEFAULT_MAX_PIXELS: u64 = 100_000_000;

/// The default [`PhotoLimits::max_alloc`]: 4 GiB.
pub const DEFAULT_MAX_ALLOC: u64 = 4 << 30;

/// How large a photo [`decode`] accepts.
///
/// With the defaults a 100 MP photo needs at most
/// 100 M × [`PEAK_BYTES_PER_PIXEL`] = 3.2 GB while decoding, under the 4 GiB
/// `max_alloc`; in general `max_alloc / 32` pixels always fit.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PhotoLimits {
    /// The most pixels (width × height) a photo may have.
    pub max_pixels: u64,
    /// The most bytes decoding may allocate: checked up front as
    /// pixels × [`PEAK_BYTES_PER_PIXEL`], and given to the decoder as its
    /// `image::Limits::max_alloc`.
    pub max_alloc: u64,
}

impl Default for PhotoLimits {
    fn default() -> Self {
        Self {
            max_pixels: DEFAULT_MAX_PIXELS,
            max_alloc: DEFAULT_MAX_ALLOC,
        }
    }
}

/// A decoded photo.
#[derive(Clone, Debug)]
pub struct Photo {
    /// The pixels: RGB `f32`, row-major, sRGB-encoded in `[0, 1]`, with the
    /// EXIF orientation applied (linear inputs already exposed and encoded,
    /// see the module docs).
    pub rgb: Rgb32FImage,
    /// The EXIF orientation that was applied (`NoTransforms` when none).
    pub orientation: Orientation,
    /// The format found from the content: `"png"`, `"jpeg"`, `"tiff"`,
    /// `"webp"`, `"bmp"`, `"exr"` or `"hdr"`, whatever the file is named.
    pub format: String,
    /// Bits per sample in the file (1, 2, 4, 8, 16 or 32).
    pub bit_depth: u8,
    /// Channels in the file, alpha included (1–4).
    pub channels_in_file: u8,
    /// True for scene-linear inputs (EXR, HDR) that went through
    /// [`expose_linear`].
    pub linear_input: bool,
    /// The camera's 35 mm-equivalent focal length in mm, when the file's
    /// EXIF states it ([`exif_focal_35mm`]): the plane mode's focal length
    /// then follows from the photo's diagonal
    /// ([`crate::Prepared::focal_35mm`]).
    pub focal_35mm: Option<f32>,
    /// The colour profile (ICC) the file holds and what was done with it
    /// ([`to_srgb`]); `None` when it holds none (its values are sRGB).
    pub colour_profile: Option<ColourProfile>,
    /// Which pixels are opaque (alpha at least ½), row-major as [`Photo::rgb`]
    /// (orientation applied), when the file has an alpha channel and some
    /// pixel below ½ but not all of them; `None` when every pixel counts.
    /// The others' colours are [`TRANSPARENT_FILL`]; nothing is extracted
    /// from them.
    pub opaque: Option<Vec<bool>>,
    /// The file has alpha but every pixel is below ½ (a viewer shows
    /// nothing): the alpha was ignored and every pixel kept its colour.
    pub alpha_ignored: bool,
}

/// The colour (sRGB-encoded, all three channels) that transparent pixels
/// ([`Photo::opaque`]) take: neutral mid-grey.
pub const TRANSPARENT_FILL: f32 = 0.5;

/// What [`to_srgb`] did with a photo's colour profile.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct ColourProfile {
    /// The profile's description (its `desc` tag), when it has one.
    pub description: Option<String>,
    /// Whether the pixels were converted from it to sRGB.
    pub converted: bool,
    /// Why they were not, when they were not.
    pub note: Option<String>,
}

/// Why a photo could not be read. Every message is one line that starts with
/// the file's name.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum PhotoError {
    /// An I/O operation on the file failed.
    #[error("{}: {op} failed: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// What was being done, e.g. `"opening the file"`.
        op: &'static str,
        /// The operating system's reason.
        #[source]
        source: std::io::Error,
    },
    /// The file has no bytes at all.
    #[error("{}: the file is empty (0 bytes)", path.display())]
    Empty {
        /// The file.
        path: PathBuf,
    },
    /// The content is not an image format this build reads.
    #[error("{}: not a supported image (the content is {content}); supported: {SUPPORTED_LIST}", path.display())]
    Unsupported {
        /// The file.
        path: PathBuf,
        /// What the content looks like, e.g. `"a PDF document"`.
        content: String,
    },
    /// The file ends before the image data does.
    #[error("{}: the {format} data is truncated ({detail})", path.display())]
    Truncated {
        /// The file.
        path: PathBuf,
        /// The format found from the content, e.g. `"JPEG"`.
        format: &'static str,
        /// What is missing.
        detail: String,
    },
    /// The image data holds what no encoder writes (a damaged file that
    /// decoders would silently decode into garbage).
    #[error("{}: the {format} data is damaged ({detail})", path.display())]
    Corrupt {
        /// The file.
        path: PathBuf,
        /// The format found from the content, e.g. `"JPEG"`.
        format: &'static str,
        /// What is wrong and where.
        detail: String,
    },
    /// The extension names one format, the content is another, and the
    /// content does not decode.
    #[error("{}: the file is named .{extension} but its content is {format}, which could not be decoded: {reason}", path.display())]
    Mislabelled {
        /// The file.
        path: PathBuf,
        /// The file's extension.
        extension: String,
        /// The format found from the content, e.g. `"PNG"`.
        format: &'static str,
        /// The decoder's reason.
        reason: String,
    },
    /// More pixels than [`PhotoLimits::max_pixels`].
    #[error("{}: {width} × {height} = {} megapixels exceeds the limit of {} megapixels (--max-megapixels)", path.display(), megapixels(*width as u64 * *height as u64), megapixels(*max_pixels))]
    TooManyPixels {
        /// The file.
        path: PathBuf,
        /// Width from the header.
        width: u32,
        /// Height from the header.
        height: u32,
        /// The limit.
        max_pixels: u64,
    },
    /// Decoding would need more memory than [`PhotoLimits::max_alloc`].
    #[error("{}: decoding {width} × {height} pixels needs about {} (at {PEAK_BYTES_PER_PIXEL} bytes per pixel), over the memory limit of {} (--max-megapixels)", path.display(), bytes_text(*needed), bytes_text(*max_alloc))]
    TooMuchMemory {
        /// The file.
        path: PathBuf,
        /// Width from the header.
        width: u32,
        /// Height from the header.
        height: u32,
        /// Bytes the decode is budgeted to need.
        needed: u64,
        /// The limit.
        max_alloc: u64,
    },
    /// The file itself is larger than [`PhotoLimits::max_alloc`].
    #[error("{}: the file is {}, more than the memory limit of {} (--max-megapixels)", path.display(), bytes_text(*bytes), bytes_text(*max_alloc))]
    FileTooLarge {
        /// The file.
        path: PathBuf,
        /// The file's size.
        bytes: u64,
        /// The limit.
        max_alloc: u64,
    },
    /// The header declares a width or height of zero.
    #[error("{}: the image has no pixels ({width} × {height})", path.display())]
    NoPixels {
        /// The file.
        path: PathBuf,
        /// Width from the header.
        width: u32,
        /// Height from the header.
        height: u32,
    },
    /// Every value of a floating-point image is NaN or infinite: there is
    /// no picture to read (a few such values become 0; see [`expose_linear`]).
    #[error("{}: every pixel is NaN or infinite; the file holds no picture", path.display())]
    NoFiniteValues {
        /// The file.
        path: PathBuf,
    },
    /// The decoder refused the content.
    #[error("{}: cannot decode the {format} data: {reason}", path.display())]
    Decode {
        /// The file.
        path: PathBuf,
        /// The format found from the content, e.g. `"TIFF"`.
        format: &'static str,
        /// The decoder's reason.
        reason: String,
    },
}

impl PhotoError {
    /// The file the error is about.
    pub fn path(&self) -> &Path {
        match self {
            Self::Io { path, .. }
            | Self::Empty { path }
            | Self::Unsupported { path, .. }
            | Self::Truncated { path, .. }
            | Self::Corrupt { path, .. }
            | Self::Mislabelled { path, .. }
            | Self::TooManyPixels { path, .. }
            | Self::TooMuchMemory { path, .. }
            | Self::FileTooLarge { path, .. }
            | Self::NoPixels { path, .. }
            | Self::NoFiniteValues { path }
            | Self::Decode { path, .. } => path,
        }
    }
}

/// A format this module reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Kind {
    image: ImageFormat,
    /// Lower-case short name, [`Photo::format`].
    name: &'static str,
    /// Name in messages.
    display: &'static str,
    linear: bool,
}

const KINDS: [Kind; 7] = [
    Kind::new(ImageFormat::Png, "png", "PNG", false),
    Kind::new(ImageFormat::Jpeg, "jpeg", "JPEG", false),
    Kind::new(ImageFormat::Tiff, "tiff", "TIFF", false),
    Kind::new(ImageFormat::WebP, "webp", "WebP", false),
    Kind::new(ImageFormat::Bmp, "bmp", "BMP", false),
    Kind::new(ImageFormat::OpenExr, "exr", "OpenEXR", true),
    Kind::new(ImageFormat::Hdr, "hdr", "Radiance HDR", true),
];

impl Kind {
    const fn new(
        image: ImageFormat,
        name: &'static str,
        display: &'static str,
        linear: bool,
    ) -> Self {
        Self {
            image,
            name,
            display,
            linear,
        }
    }

    fn from_image(f: ImageFormat) -> Option<Self> {
        KINDS.iter().copied().find(|k| k.image == f)
    }
}

/// True when `path` has one of the [`SUPPORTED_EXTENSIONS`] (any case): the
/// files batch discovery picks up. Says nothing about the content.
pub fn is_supported_extension(path: &Path) -> bool {
    format_for_extension(path).is_some()
}

/// The [`Photo::format`] name a file with this extension should have
/// (`"jpeg"` for `.JPG`), or `None` for an unsupported extension. Compare
/// with the decoded [`Photo::format`] to notice a mislabelled file.
pub fn format_for_extension(path: &Path) -> Option<&'static str> {
    let ext = path.extension()?.to_str()?.to_ascii_lowercase();
    Some(match ext.as_str() {
        "png" => "png",
        "jpg" | "jpeg" => "jpeg",
        "tif" | "tiff" => "tiff",
        "webp" => "webp",
        "bmp" => "bmp",
        "exr" => "exr",
        "hdr" => "hdr",
        _ => return None,
    })
}

/// Reads and decodes the file at `path`; see [`decode`]. A file larger than
/// [`PhotoLimits::max_alloc`] is refused before it is read.
pub fn load(path: &Path, limits: &PhotoLimits) -> Result<Photo, PhotoError> {
    decode(&read_limited(path, limits)?, path, limits)
}

/// The bytes of the file at `path`, refused when larger than
/// [`PhotoLimits::max_alloc`].
fn read_limited(path: &Path, limits: &PhotoLimits) -> Result<Vec<u8>, PhotoError> {
    let io = |op: &'static str| {
        move |source| PhotoError::Io {
            path: path.to_path_buf(),
            op,
            source,
        }
    };
    let mut file = std::fs::File::open(path).map_err(io("opening the file"))?;
    let len = file
        .metadata()
        .map_err(io("reading the file's metadata"))?
        .len();
    if len > limits.max_alloc {
        return Err(PhotoError::FileTooLarge {
            path: path.to_path_buf(),
            bytes: len,
            max_alloc: limits.max_alloc,
        });
    }
    let mut bytes = Vec::new();
    bytes
        .try_reserve_exact(len as usize)
        .map_err(|e| io("reading the file")(std::io::Error::other(e)))?;
    file.read_to_end(&mut bytes)
        .map_err(io("reading the file"))?;
    Ok(bytes)
}

/// Decodes a photo from the bytes of a file; `label` names the file in
/// messages (and its extension is compared with the content). See the module
/// docs for what is accepted and how values are encoded.
pub fn decode(bytes: &[u8], label: &Path, limits: &PhotoLimits) -> Result<Photo, PhotoError> {
    let path = || label.to_path_buf();
    let Decoded {
        img,
        kind,
        orientation,
        bit_depth,
        channels_in_file,
        focal_35mm,
        icc,
    } = decode_image(bytes, label, limits)?;
    let mut img = img;
    if kind.image == ImageFormat::OpenExr {
        unpremultiply(&mut img);
    }
    let alpha = opaque_plane(&img);
    let alpha_ignored = alpha
        .as_ref()
        .is_some_and(|a| !a.is_empty() && !a.iter().any(|&o| o));
    let opaque = alpha.filter(|a| a.iter().any(|&o| o) && !a.iter().all(|&o| o));
    // Native buffer + 12 B/px here; the native buffer is freed right after.
    let eight_bit_rgb = matches!(img, DynamicImage::ImageRgb8(_));
    let mut rgb = rgb32f(img);
    if !eight_bit_rgb && !rgb.is_empty() && rgb.iter().all(|v| !v.is_finite()) {
        return Err(PhotoError::NoFiniteValues { path: path() });
    }
    if kind.linear {
        expose_linear_where(&mut rgb, opaque.as_deref());
    } else if !eight_bit_rgb {
        // (8-bit values are k / 255, always in [0, 1].)
        // Float formats (e.g. 32-bit TIFF) may hold values outside [0, 1] or NaN.
        for v in rgb.iter_mut() {
            *v = if v.is_nan() { 0.0 } else { v.clamp(0.0, 1.0) };
        }
    }
    // Scene-linear formats carry no display profile worth applying.
    let colour_profile = icc
        .filter(|_| !kind.linear)
        .map(|icc| to_srgb(&mut rgb, &icc, channels_in_file < 3));
    if let Some(opaque) = &opaque {
        for (p, _) in rgb.pixels_mut().zip(opaque).filter(|(_, &o)| !o) {
            p.0 = [TRANSPARENT_FILL; 3];
        }
    }
    let opaque = opaque.map(|o| orient_flags(o, rgb.width(), rgb.height(), orientation));
    let rgb = orient(rgb, orientation);
    Ok(Photo {
        rgb,
        orientation,
        format: kind.name.to_owned(),
        bit_depth: u8::try_from(bit_depth).unwrap_or(u8::MAX),
        channels_in_file,
        linear_input: kind.linear,
        focal_35mm,
        colour_profile,
        opaque,
        alpha_ignored,
    })
}

/// Divides the colour of every opaque pixel (alpha from ½ to 1) of a float
/// RGBA image by its alpha: OpenEXR stores colours premultiplied by alpha
/// (associated alpha, the format's convention), so a render's anti-aliased
/// edge pixel holds its colour times its coverage. Other pixels and layouts
/// are left as they are.
fn unpremultiply(img: &mut DynamicImage) {
    if let DynamicImage::ImageRgba32F(buf) = img {
        for p in buf.pixels_mut() {
            let a = p.0[3];
            if (0.5..1.0).contains(&a) {
                for c in &mut p.0[..3] {
                    *c /= a;
                }
            }
        }
    }
}

/// Whether each pixel of `img` is opaque (alpha at least ½; NaN is not),
/// row-major as stored, when it has an alpha channel.
fn opaque_plane(img: &DynamicImage) -> Option<Vec<bool>> {
    fn plane<P: image::Pixel>(
        b: &image::ImageBuffer<P, Vec<P::Subpixel>>,
        on: impl Fn(P::Subpixel) -> bool,
    ) -> Vec<bool> {
        let a = usize::from(P::CHANNEL_COUNT) - 1;
        b.pixels().map(|p| on(p.channels()[a])).collect()
    }
    Some(match img {
        DynamicImage::ImageLumaA8(b) => plane(b, |a| a >= 128),
        DynamicImage::ImageRgba8(b) => plane(b, |a| a >= 128),
        DynamicImage::ImageLumaA16(b) => plane(b, |a| a >= 32768),
        DynamicImage::ImageRgba16(b) => plane(b, |a| a >= 32768),
        DynamicImage::ImageRgba32F(b) => plane(b, |a| a >= 0.5),
        other if other.color().has_alpha() => plane(&other.to_rgba32f(), |a| a >= 0.5),
        _ => return None,
    })
}

/// `flags` (row-major, `w × h` as stored) with `orientation` applied, as
/// [`orient`] applies it to the pixels.
fn orient_flags(flags: Vec<bool>, w: u32, h: u32, orientation: Orientation) -> Vec<bool> {
    if orientation == Orientation::NoTransforms {
        return flags;
    }
    let grey = image::GrayImage::from_raw(w, h, flags.iter().map(|&o| u8::from(o)).collect())
        .expect("one value per pixel");
    let mut img = DynamicImage::ImageLuma8(grey);
    img.apply_orientation(orientation);
    img.into_luma8()
        .into_raw()
        .into_iter()
        .map(|v| v != 0)
        .collect()
}

/// What [`decode_image`] found: the decoded image as stored (not yet
/// oriented), its format, orientation, bits per sample and channels.
struct Decoded {
    img: DynamicImage,
    kind: Kind,
    orientation: Orientation,
    bit_depth: u16,
    channels_in_file: u8,
    focal_35mm: Option<f32>,
    /// The file's colour profile (ICC), if it holds one.
    icc: Option<Vec<u8>>,
}

/// The checks and the decoding [`decode`] and [`decode_mask`] share: the
/// format from the content, cut-off files, the size limits, the pixels.
fn decode_image(bytes: &[u8], label: &Path, limits: &PhotoLimits) -> Result<Decoded, PhotoError> {
    let path = || label.to_path_buf();
    if bytes.is_empty() {
        return Err(PhotoError::Empty { path: path() });
    }
    let kind = match image::guess_format(bytes).ok().and_then(Kind::from_image) {
        Some(k) => k,
        None => {
            return Err(PhotoError::Unsupported {
                path: path(),
                content: describe_content(bytes),
            })
        }
    };
    let extension = label
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_owned);
    let mislabelled = match (&extension, format_for_extension(label)) {
        (Some(ext), Some(named)) if named != kind.name => Some(ext.clone()),
        _ => None,
    };
    let fail = |e: ImageError| classify(e, kind, label, mislabelled.as_deref());
    let truncated = |detail: String| PhotoError::Truncated {
        path: path(),
        format: kind.display,
        detail,
    };

    // Cut-off files some decoders would silently fill in.
    match kind.image {
        // The JPEG decoder fills a cut-off file with grey instead of failing.
        ImageFormat::Jpeg if !jpeg_is_complete(bytes) => {
            return Err(truncated(
                "no end-of-image marker after the image data".into(),
            ))
        }

        ImageFormat::WebP => {
            if let Some(declared) = bytes.get(4..8) {
                let declared = u32::from_le_bytes(declared.try_into().unwrap_or([0; 4])) as u64;
                if (bytes.len() as u64) < declared + 8 {
                    return Err(truncated(format!(
                        "the RIFF header declares {} bytes, the file has {}",
                        declared + 8,
                        bytes.len()
                    )));
                }
            }
        }
        _ => {}
    }

    // EXR: the `image` decoder reads the offset tables (sized by the header)
    // as it is made, so the header's size is checked on its own first.
    if kind.image == ImageFormat::OpenExr {
        if let Ok(meta) = exr::meta::MetaData::read_from_buffered(bytes, false) {
            for header in &meta.headers {
                for size in [
                    header.shared_attributes.display_window.size,
                    header.layer_size,
                ] {
                    let (w, h) = (size.width() as u64, size.height() as u64);
                    if w.saturating_mul(h) > limits.max_pixels {
                        return Err(PhotoError::TooManyPixels {
                            path: path(),
                            width: u32::try_from(w).unwrap_or(u32::MAX),
                            height: u32::try_from(h).unwrap_or(u32::MAX),
                            max_pixels: limits.max_pixels,
                        });
                    }
                }
            }
        }
    }

    // The header only: no pixel buffer is allocated yet.
    let mut reader = ImageReader::with_format(Cursor::new(bytes), kind.image);
    let mut header_limits = image::Limits::no_limits();
    header_limits.max_alloc = Some(limits.max_alloc);
    reader.limits(header_limits);
    let mut decoder = match reader.into_decoder() {
        Ok(d) => d,
        // Float samples the `image` crate does not read (16 and 64 bits, 32-bit grey).
        Err(e @ ImageError::Unsupported(_)) if kind.image == ImageFormat::Tiff => {
            return float_tiff(bytes, label, limits, kind).unwrap_or_else(|| Err(fail(e)));
        }
        Err(e) => return Err(fail(e)),
    };
    let (width, height) = decoder.dimensions();
    check_dimensions(width, height, label, limits)?;
    let mut decode_limits = image::Limits::no_limits();
    let side = u32::try_from(limits.max_pixels).unwrap_or(u32::MAX);
    decode_limits.max_image_width = Some(side);
    decode_limits.max_image_height = Some(side);
    decode_limits.max_alloc = Some(limits.max_alloc);
    decoder.set_limits(decode_limits).map_err(fail)?;

    let original = decoder.original_color_type();
    let (bit_depth, channels_in_file) = match original.channel_count() {
        0 => {
            let c = decoder.color_type();
            (
                c.bits_per_pixel() / c.channel_count() as u16,
                c.channel_count(),
            )
        }
        n => (original.bits_per_pixel() / n as u16, n),
    };
    // A broken EXIF block is not worth refusing the photo for.
    let orientation = decoder.orientation().unwrap_or(Orientation::NoTransforms);
    // A TIFF file is itself the TIFF structure EXIF blocks are made of: its
    // first IFD holds the Exif IFD pointer a camera writes (the `image`
    // crate's TIFF decoder gives no EXIF block).
    let focal_35mm = decoder
        .exif_metadata()
        .ok()
        .flatten()
        .and_then(|raw| exif_focal_35mm(&raw))
        .or_else(|| {
            (kind.image == ImageFormat::Tiff)
                .then(|| exif_focal_35mm(bytes))
                .flatten()
        });

    // The JPEG decoder also fills in what a damaged file's blocks lack and
    // decodes changed bytes as whatever they say: its coded blocks are
    // walked (crate::jpeg) on a second thread while it decodes.
    // A broken profile is not worth refusing the photo for ([`to_srgb`]).
    let icc = decoder.icc_profile().ok().flatten();
    let (img, walked) = std::thread::scope(|s| {
        let check =
            (kind.image == ImageFormat::Jpeg).then(|| s.spawn(|| crate::jpeg::check(bytes)));
        let img = DynamicImage::from_decoder(decoder);
        let walked = check.map(|h| h.join().unwrap_or_else(|p| std::panic::resume_unwind(p)));
        (img, walked)
    });
    match walked {
        Some(Err(crate::jpeg::Damage::EndsEarly(detail))) => return Err(truncated(detail)),
        Some(Err(crate::jpeg::Damage::Corrupt(detail))) => {
            return Err(PhotoError::Corrupt {
                path: path(),
                format: kind.display,
                detail,
            })
        }
        _ => {}
    }
    let img = img.map_err(fail)?;
    Ok(Decoded {
        img,
        kind,
        orientation,
        bit_depth,
        channels_in_file,
        focal_35mm,
        icc,
    })
}

/// Refuses a photo of `width × height` pixels that has none, more than
/// [`PhotoLimits::max_pixels`], or needs more than [`PhotoLimits::max_alloc`]
/// bytes to decode ([`PEAK_BYTES_PER_PIXEL`] a pixel).
fn check_dimensions(
    width: u32,
    height: u32,
    label: &Path,
    limits: &PhotoLimits,
) -> Result<(), PhotoError> {
    let path = || label.to_path_buf();
    if width == 0 || height == 0 {
        return Err(PhotoError::NoPixels {
            path: path(),
            width,
            height,
        });
    }
    let pixels = width as u64 * height as u64;
    if pixels > limits.max_pixels {
        return Err(PhotoError::TooManyPixels {
            path: path(),
            width,
            height,
            max_pixels: limits.max_pixels,
        });
    }
    let needed = pixels.saturating_mul(PEAK_BYTES_PER_PIXEL);
    if needed > limits.max_alloc {
        return Err(PhotoError::TooMuchMemory {
            path: path(),
            width,
            height,
            needed,
            max_alloc: limits.max_alloc,
        });
    }
    Ok(())
}

/// A TIFF of IEEE float samples that the `image` crate does not read (16 or
/// 64 bits, and 32-bit grey; grey, RGB or RGBA, as scientific
/// and HDR tools write them), decoded with the `tiff` crate into 32-bit float
/// pixels: from there it is a float TIFF like a 32-bit one (values clamped
/// to `[0, 1]`, NaN 0; its ICC profile, orientation and EXIF focal length
/// read as for other TIFFs). `None` when the file is not such a TIFF (the
/// caller then reports the `image` crate's error).
fn float_tiff(
    bytes: &[u8],
    label: &Path,
    limits: &PhotoLimits,
    kind: Kind,
) -> Option<Result<Decoded, PhotoError>> {
    use tiff::decoder::{Decoder, DecodingResult};
    use tiff::tags::Tag;
    use tiff::ColorType;
    let mut dec = Decoder::new(Cursor::new(bytes)).ok()?;
    let formats = dec
        .find_tag_unsigned_vec::<u16>(Tag::SampleFormat)
        .ok()
        .flatten()?;
    // Sample format 3: IEEE floating point.
    if formats.is_empty() || formats.iter().any(|&f| f != 3) {
        return None;
    }
    let (channels, bits) = match dec.colortype().ok()? {
        ColorType::Gray(b) => (1u8, b),
        ColorType::RGB(b) => (3, b),
        ColorType::RGBA(b) => (4, b),
        _ => return None,
    };
    if !matches!(bits, 16 | 32 | 64) {
        return None;
    }
    let (width, height) = dec.dimensions().ok()?;
    Some((|| {
        check_dimensions(width, height, label, limits)?;
        // The decoded samples and their f32 copy are held together (64-bit
        // RGBA: 48 B/px, above PEAK_BYTES_PER_PIXEL).
        let pixels = u64::from(width) * u64::from(height);
        let needed = pixels.saturating_mul(u64::from(channels) * (u64::from(bits) / 8 + 4));
        if needed > limits.max_alloc {
            return Err(PhotoError::TooMuchMemory {
                path: label.to_path_buf(),
                width,
                height,
                needed,
                max_alloc: limits.max_alloc,
            });
        }
        let mut tl = tiff::decoder::Limits::default();
        let max = usize::try_from(limits.max_alloc).unwrap_or(usize::MAX);
        tl.decoding_buffer_size = max;
        tl.intermediate_buffer_size = max;
        let mut dec = dec.with_limits(tl);
        let failed = |e: tiff::TiffError| PhotoError::Corrupt {
            path: label.to_path_buf(),
            format: kind.display,
            detail: one_line(&e.to_string()),
        };
        let mut values: Vec<f32> = match dec.read_image().map_err(failed)? {
            DecodingResult::F16(v) => v.iter().map(|x| x.to_f32()).collect(),
            DecodingResult::F32(v) => v,
            DecodingResult::F64(v) => v.iter().map(|&x| x as f32).collect(),
            _ => {
                return Err(PhotoError::Corrupt {
                    path: label.to_path_buf(),
                    format: kind.display,
                    detail: format!("{bits}-bit float samples decoded as another type"),
                })
            }
        };
        let n = width as usize * height as usize;
        if values.len() < n * channels as usize {
            return Err(PhotoError::Truncated {
                path: label.to_path_buf(),
                format: kind.display,
                detail: format!(
                    "{} samples for {width}x{height} pixels of {channels} channels",
                    values.len()
                ),
            });
        }
        values.truncate(n * channels as usize);
        // Grey is given as RGB (as `image` gives 32-bit grey), alpha kept. (Grey
        // with alpha is "multiband" to the `tiff` crate: not read here.) The
        // lengths were checked above.
        let sized = "sample count checked";
        let img = match channels {
            1 => DynamicImage::ImageRgb32F(
                image::ImageBuffer::from_raw(
                    width,
                    height,
                    values.iter().flat_map(|&g| [g; 3]).collect(),
                )
                .expect(sized),
            ),
            3 => DynamicImage::ImageRgb32F(
                image::ImageBuffer::from_raw(width, height, values).expect(sized),
            ),
            _ => DynamicImage::ImageRgba32F(
                image::ImageBuffer::from_raw(width, height, values).expect(sized),
            ),
        };
        let orientation = dec
            .find_tag_unsigned::<u8>(Tag::Orientation)
            .ok()
            .flatten()
            .and_then(Orientation::from_exif)
            .unwrap_or(Orientation::NoTransforms);
        let icc = dec.get_tag_u8_vec(Tag::IccProfile).ok();
        Ok(Decoded {
            img,
            kind,
            orientation,
            bit_depth: u16::from(bits),
            channels_in_file: channels,
            focal_35mm: exif_focal_35mm(bytes),
            icc,
        })
    })())
}

/// Converts `rgb` (interleaved RGB, sRGB-encoded-looking values in
/// `[0, 1]`) from the colour space of the ICC profile `icc` to sRGB, in
/// place (relative colorimetric; colours outside sRGB's gamut are clipped to
/// it). A phone's Display P3 photo read as sRGB would give every material a
/// duller colour than it has. Left as it is, with a note saying why: a
/// profile that does not parse, one that is not RGB (a CMYK file's, which
/// the decoder has already turned into RGB its own way), a grey picture
/// (`grey`: a grey profile's tone curve is not applied), and a profile that
/// is sRGB already (a probe of 27 colours moves by less than 1/500).
pub fn to_srgb(rgb: &mut [f32], icc: &[u8], grey: bool) -> ColourProfile {
    use moxcms::{ColorProfile, DataColorSpace, Layout, ProfileText, RenderingIntent};
    use rayon::prelude::*;
    let kept = |description: Option<String>, note: String| ColourProfile {
        description,
        converted: false,
        note: Some(note),
    };
    let profile = match ColorProfile::new_from_slice(icc) {
        Ok(p) => p,
        Err(e) => {
            let e = one_line(&e.to_string());
            return kept(None, format!("unreadable ({e}): colours taken as sRGB"));
        }
    };
    let description = profile.description.as_ref().and_then(|d| match d {
        ProfileText::PlainString(s) => Some(s.trim().to_owned()),
        ProfileText::Localizable(v) => v.first().map(|l| l.value.trim().to_owned()),
        ProfileText::Description(d) => {
            Some(d.ascii_string.trim_end_matches('\0').trim().to_owned())
        }
    });
    if profile.color_space != DataColorSpace::Rgb {
        return kept(
            description,
            format!("a {:?} profile, not RGB: not applied", profile.color_space),
        );
    }
    if grey {
        return kept(description, "a grey picture: not applied".into());
    }
    let options = moxcms::TransformOptions {
        rendering_intent: RenderingIntent::RelativeColorimetric,
        ..Default::default()
    };
    let srgb = ColorProfile::new_srgb();
    let transform = match profile.create_transform_f32(Layout::Rgb, &srgb, Layout::Rgb, options) {
        Ok(t) => t,
        Err(e) => {
            let e = one_line(&e.to_string());
            return kept(
                description,
                format!("cannot be applied ({e}): colours taken as sRGB"),
            );
        }
    };
    let probe: Vec<f32> = (0..27)
        .flat_map(|k| [k % 3, k / 3 % 3, k / 9].map(|v| v as f32 * 0.5))
        .collect();
    let mut probed = vec![0.0f32; probe.len()];
    if transform.transform(&probe, &mut probed).is_ok()
        && probe.iter().zip(&probed).all(|(a, b)| (a - b).abs() < 2e-3)
    {
        return kept(description, "sRGB already".into());
    }
    // Whole pixels per chunk; each chunk converted on its own.
    rgb.par_chunks_mut(3 * 4096).for_each(|chunk| {
        let src = chunk.to_vec();
        if transform.transform(&src, chunk).is_err() {
            chunk.copy_from_slice(&src);
        }
        for v in chunk.iter_mut() {
            *v = if v.is_nan() { 0.0 } else { v.clamp(0.0, 1.0) };
        }
    });
    ColourProfile {
        description,
        converted: true,
        note: None,
    }
}

/// `text` on one line: its runs of whitespace (newlines included) become
/// single spaces (decoders' and libraries' messages may span lines; every
/// message of this module is one line).
fn one_line(text: &str) -> String {
    text.split_whitespace().collect::<Vec<_>>().join(" ")
}

/// Largest 35 mm-equivalent focal length taken from EXIF, mm (a 2000 mm
/// lens is a telescope; beyond, the tag is garbage).
pub const MAX_FOCAL_35MM: u32 = 2000;

/// The 35 mm-equivalent focal length in mm stated by a raw EXIF block (a
/// TIFF header and its IFDs, with or without the `Exif\0\0` prefix JPEG's
/// APP1 segment has): the tag `FocalLengthIn35mmFilm` (0xA405, a SHORT or
/// LONG) of the Exif IFD that IFD0's `ExifIFDPointer` (0x8769) points to.
/// `None` when the block does not hold it, states 0 (unknown) or more than
/// [`MAX_FOCAL_35MM`], or is malformed anywhere on the way (every read is
/// bounds-checked: any bytes are safe).
pub fn exif_focal_35mm(raw: &[u8]) -> Option<f32> {
    let t = raw.strip_prefix(b"Exif\0\0").unwrap_or(raw);
    let le = match t.get(0..4)? {
        b"II*\0" => true,
        b"MM\0*" => false,
        _ => return None,
    };
    let u16_at = |o: usize| -> Option<u16> {
        let b: [u8; 2] = t.get(o..o.checked_add(2)?)?.try_into().ok()?;
        Some(if le {
            u16::from_le_bytes(b)
        } else {
            u16::from_be_bytes(b)
        })
    };
    let u32_at = |o: usize| -> Option<u32> {
        let b: [u8; 4] = t.get(o..o.checked_add(4)?)?.try_into().ok()?;
        Some(if le {
            u32::from_le_bytes(b)
        } else {
            u32::from_be_bytes(b)
        })
    };
    // The entry of `tag` in the IFD at `ifd`: its type, count and where its
    // value (or the offset to it) is.
    let find = |ifd: usize, tag: u16| -> Option<(u16, u32, usize)> {
        let n = usize::from(u16_at(ifd)?);
        (0..n).find_map(|k| {
            let e = ifd.checked_add(2 + 12 * k)?;
            (u16_at(e)? == tag).then(|| Some((u16_at(e + 2)?, u32_at(e + 4)?, e + 8)))?
        })
    };
    let ifd0 = usize::try_from(u32_at(4)?).ok()?;
    let (ty, count, at) = find(ifd0, 0x8769)?;
    if !matches!(ty, 4 | 13) || count != 1 {
        return None;
    }
    let exif = usize::try_from(u32_at(at)?).ok()?;
    let (ty, count, at) = find(exif, 0xA405)?;
    let v = match (ty, count) {
        (3, 1) => u32::from(u16_at(at)?),
        (4, 1) => u32_at(at)?,
        _ => return None,
    };
    (1..=MAX_FOCAL_35MM).contains(&v).then_some(v as f32)
}

/// A mask image read by [`load_mask`]: which pixels are in, as a viewer
/// shows the image (EXIF orientation applied).
#[derive(Clone, Debug, PartialEq)]
pub struct MaskImage {
    /// Columns.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// `true` inside, row-major.
    pub data: Vec<bool>,
    /// Whether the mask came from the alpha channel (else from the grey
    /// level).
    pub from_alpha: bool,
}

/// Reads a mask image (any format [`load`] reads, the same limits and
/// errors): a pixel is in when its alpha is at least ½ where the file has
/// an alpha channel that is not opaque everywhere (a selection exported
/// with transparency), else when its grey level (the mean of its channels,
/// as stored: sRGB-encoded, or linear for EXR and HDR) is at least ½
/// (white on black). NaN counts as 0.
pub fn load_mask(path: &Path, limits: &PhotoLimits) -> Result<MaskImage, PhotoError> {
    decode_mask(&read_limited(path, limits)?, path, limits)
}

/// [`load_mask`] of the bytes of a file (`label` names it in errors).
pub fn decode_mask(
    bytes: &[u8],
    label: &Path,
    limits: &PhotoLimits,
) -> Result<MaskImage, PhotoError> {
    let Decoded {
        img, orientation, ..
    } = decode_image(bytes, label, limits)?;
    let has_alpha = img.color().has_alpha();
    let rgba = img.into_rgba32f();
    let value = |a: &image::Rgba<f32>| if a.0[3].is_nan() { 0.0 } else { a.0[3] };
    let from_alpha = has_alpha && rgba.pixels().any(|p| value(p) < 0.5);
    let grey = |p: &image::Rgba<f32>| {
        let m = (p.0[0] + p.0[1] + p.0[2]) / 3.0;
        if m.is_nan() {
            0.0
        } else {
            m
        }
    };
    // One channel per pixel, replicated to RGB to reuse the orientation.
    let (w, h) = rgba.dimensions();
    let flags: Vec<f32> = rgba
        .pixels()
        .flat_map(|p| {
            let on = if from_alpha { value(p) } else { grey(p) } >= 0.5;
            [f32::from(u8::from(on)); 3]
        })
        .collect();
    drop(rgba);
    let rgb = Rgb32FImage::from_raw(w, h, flags).expect("3 values per pixel");
    let rgb = orient(rgb, orientation);
    Ok(MaskImage {
        width: rgb.width() as usize,
        height: rgb.height() as usize,
        data: rgb.pixels().map(|p| p.0[0] >= 0.5).collect(),
        from_alpha,
    })
}

/// `img.into_rgb32f()`, with 8-bit RGB (the usual photo) converted in
/// parallel through a table of the 256 values that `into_rgb32f` itself gives
/// (so the same bits; `tests::parallel_rgb8_conversion_matches_image`).
pub fn rgb32f(img: DynamicImage) -> Rgb32FImage {
    use rayon::prelude::*;
    let DynamicImage::ImageRgb8(src) = img else {
        return img.into_rgb32f();
    };
    let table: Vec<f32> = {
        let ramp = image::RgbImage::from_fn(256, 1, |x, _| image::Rgb([x as u8; 3]));
        DynamicImage::ImageRgb8(ramp)
            .into_rgb32f()
            .pixels()
            .map(|p| p.0[0])
            .collect()
    };
    let (w, h) = src.dimensions();
    let mut data = vec![0.0f32; src.as_raw().len()];
    let row = (3 * w as usize).max(1);
    data.par_chunks_mut(row)
        .zip(src.as_raw().par_chunks(row))
        .for_each(|(o, i)| {
            for (o, &v) in o.iter_mut().zip(i) {
                *o = table[v as usize];
            }
        });
    let mut out = Rgb32FImage::from_raw(w, h, data).expect("3 values per pixel");
    // The colour space travels with the pixels, as `into_rgb32f` keeps it.
    out.set_color_space(src.color_space()).ok();
    out
}

/// Applies an EXIF orientation (flips in place, rotations into a new image).
fn orient(rgb: Rgb32FImage, orientation: Orientation) -> Rgb32FImage {
    if orientation == Orientation::NoTransforms {
        return rgb;
    }
    let mut img = DynamicImage::ImageRgb32F(rgb);
    img.apply_orientation(orientation);
    img.into_rgb32f()
}

/// Brings scene-linear RGB to sRGB-encoded `[0, 1]` (the rule for EXR and
/// HDR inputs): non-finite and negative values become 0; when the 99th
/// percentile of the luminance `0.2126 R + 0.7152 G + 0.0722 B` is above 1,
/// everything is scaled by its inverse (so it maps to 1.0 and the brightest
/// 1 % clip); then each channel is sRGB-encoded and clamped to `[0, 1]`.
/// Inputs whose 99th percentile is at most 1 are not rescaled.
pub fn expose_linear(rgb: &mut Rgb32FImage) {
    expose_linear_where(rgb, None);
}

/// [`expose_linear`] with the percentile taken over the pixels `counted`
/// marks (row-major; all of them when `None` or when it marks none): a
/// cut-out's transparent background does not set the exposure.
fn expose_linear_where(rgb: &mut Rgb32FImage, counted: Option<&[bool]>) {
    for v in rgb.iter_mut() {
        if !v.is_finite() || *v < 0.0 {
            *v = 0.0;
        }
    }
    let counted = counted.filter(|c| c.iter().any(|&o| o));
    let mut lum: Vec<f32> = rgb
        .pixels()
        .enumerate()
        .filter(|(i, _)| counted.is_none_or(|c| c[*i]))
        .map(|(_, p)| 0.2126 * p.0[0] + 0.7152 * p.0[1] + 0.0722 * p.0[2])
        .collect();
    let p99 = if lum.is_empty() {
        0.0
    } else {
        let k = (lum.len() - 1) * 99 / 100;
        *lum.select_nth_unstable_by(k, f32::total_cmp).1
    };
    drop(lum);
    let scale = if p99 > 1.0 { 1.0 / p99 } else { 1.0 };
    for v in rgb.iter_mut() {
        *v = srgb_encode(*v * scale).clamp(0.0, 1.0);
    }
}

/// The sRGB transfer function (IEC 61966-2-1), linear → encoded.
pub(crate) fn srgb_encode(c: f32) -> f32 {
    if c <= 0.003_130_8 {
        12.92 * c
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    }
}

/// Turns a decoder error into a [`PhotoError`], telling truncation apart.
fn classify(e: ImageError, kind: Kind, path: &Path, mislabelled: Option<&str>) -> PhotoError {
    let reason = match &e {
        // "Format error decoding Png: <reason>" → "<reason>"
        ImageError::Decoding(d) => match std::error::Error::source(d) {
            Some(s) => s.to_string(),
            None => d.to_string(),
        },
        ImageError::Limits(l) => {
            format!("{l} (the decoder hit the memory limit set by --max-megapixels)")
        }
        other => other.to_string(),
    };
    // Decoders' texts may hold newlines (e.g. zune-jpeg's "Not enough bytes…\n");
    // every message is one line.
    let reason = one_line(&reason);
    if is_truncation(&e, &reason) {
        return PhotoError::Truncated {
            path: path.to_path_buf(),
            format: kind.display,
            detail: format!("the file ends early; the decoder says: {reason}"),
        };
    }
    match mislabelled {
        Some(ext) => PhotoError::Mislabelled {
            path: path.to_path_buf(),
            extension: ext.to_owned(),
            format: kind.display,
            reason,
        },
        None => PhotoError::Decode {
            path: path.to_path_buf(),
            format: kind.display,
            reason,
        },
    }
}

/// Whether a decoder error means the data stopped early.
fn is_truncation(e: &ImageError, reason: &str) -> bool {
    let mut source: Option<&(dyn std::error::Error + 'static)> = Some(e);
    while let Some(s) = source {
        if let Some(io) = s.downcast_ref::<std::io::Error>() {
            if io.kind() == std::io::ErrorKind::UnexpectedEof {
                return true;
            }
        }
        source = s.source();
    }
    if let ImageError::IoError(io) = e {
        if io.kind() == std::io::ErrorKind::UnexpectedEof {
            return true;
        }
    }
    let r = reason.to_ascii_lowercase();
    [
        "eof",
        "end of file",
        "unexpected end",
        "truncated",
        "not enough data",
        "no more data",
        "fill whole buffer",
        "missing bytes",
    ]
    .iter()
    .any(|m| r.contains(m))
}

/// A short description of content that is not a supported image.
fn describe_content(b: &[u8]) -> String {
    let starts = |m: &[u8]| b.starts_with(m);
    if starts(b"%PDF") {
        return "a PDF document".into();
    }
    if starts(b"PK\x03\x04") {
        return "a ZIP archive (or a DOCX/XLSX/… document)".into();
    }
    if starts(&[0x1F, 0x8B]) {
        return "gzip-compressed data".into();
    }
    if starts(b"8BPS") {
        return "a Photoshop PSD document".into();
    }
    if b.get(4..8) == Some(b"ftyp") {
        let brand = b.get(8..12).unwrap_or_default();
        return match brand {
            b"heic" | b"heix" | b"hevc" | b"heim" | b"heis" | b"mif1" | b"msf1" => {
                "a HEIF/HEIC photo, which is not supported: export it as JPEG or PNG".into()
            }
            b"avif" | b"avis" => "an AVIF image, which is not supported".into(),
            b"crx " => "a Canon CR3 raw file, which is not supported".into(),
            _ => "an MP4/QuickTime (ISO media) file".into(),
        };
    }
    if let Ok(f) = image::guess_format(b) {
        return format!("a {f:?} image, which is not supported");
    }
    let head = &b[..b.len().min(512)];
    let text = match std::str::from_utf8(head) {
        Ok(s) => Some(s),
        // A multi-byte character cut at the 512-byte boundary.
        Err(e) if e.error_len().is_none() => std::str::from_utf8(&head[..e.valid_up_to()]).ok(),
        Err(_) => None,
    };
    if let Some(t) = text {
        if t.chars()
            .all(|c| !c.is_control() || matches!(c, '\n' | '\r' | '\t'))
        {
            let lower = t.trim_start().to_ascii_lowercase();
            if lower.starts_with("<svg") || (lower.starts_with("<?xml") && lower.contains("<svg")) {
                return "an SVG drawing (vector graphics)".into();
            }
            if lower.starts_with("<!doctype html") || lower.starts_with("<html") {
                return "an HTML page".into();
            }
            return "text".into();
        }
    }
    "unrecognised bytes".into()
}

/// `n` pixels as megapixels: two decimals from 1 MP up, six below, with
/// trailing zeros dropped ("2500", "1.23", "0.000035").
fn megapixels(n: u64) -> String {
    let decimals = if n >= 1_000_000 { 2 } else { 6 };
    let s = format!("{:.*}", decimals, n as f64 / 1e6);
    s.trim_end_matches('0').trim_end_matches('.').to_owned()
}

/// A byte count for messages, in GiB or MiB.
fn bytes_text(n: u64) -> String {
    if n >= 1 << 30 {
        format!("{:.1} GiB", n as f64 / (1u64 << 30) as f64)
    } else {
        format!("{:.0} MiB", (n as f64 / (1u64 << 20) as f64).ceil())
    }
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
/// ratio (rounded, at least 1); `(0, 0)` for a photo with no pixels.
pub fn working_size(w: u32, h: u32, work_size: u32) -> (u32, u32) {
    let (long, short) = (w.max(h) as u64, w.min(h) as u64);
    if short == 0 {
        return (0, 0);
    }
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
    use rayon::prelude::*;
    let (w, h) = rgb.dimensions();
    let n = (w * h) as usize;
    let raw: &[f32] = rgb.as_raw();
    let mut planes = vec![0.0f32; 3 * n];
    // Rows in parallel, the three planes' rows written in one pass over the
    // pixels (pure copies).
    let row = (w as usize).max(1);
    let (r, rest) = planes.split_at_mut(n);
    let (g, b) = rest.split_at_mut(n);
    r.par_chunks_mut(row)
        .zip(g.par_chunks_mut(row))
        .zip(b.par_chunks_mut(row))
        .zip(raw.par_chunks(3 * row))
        .for_each(|(((r, g), b), px)| {
            for (x, p) in px.chunks_exact(3).enumerate() {
                (r[x], g[x], b[x]) = (p[0], p[1], p[2]);
            }
        });
    planes
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sixteen_bit_photos_decode_to_sixteen_bit_codes() {
        // Every value of a 16-bit PNG comes out as `k / 65535` computed in
        // f32, the codes `pipeline::SrgbDecodeTable` looks up (else each would
        // cost a `powf`).
        let img = image::ImageBuffer::<image::Rgb<u16>, Vec<u16>>::from_fn(256, 256, |x, y| {
            let k = (y * 256 + x) as u16;
            image::Rgb([k, k.wrapping_mul(7), u16::MAX - k])
        });
        let mut png = Vec::new();
        image::DynamicImage::ImageRgb16(img)
            .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
            .unwrap();
        let p = decode(&png, Path::new("t.png"), &PhotoLimits::default()).unwrap();
        assert_eq!(p.bit_depth, 16);
        let lut = crate::pipeline::SrgbDecodeTable::new();
        for (i, &v) in p.rgb.as_raw().iter().enumerate() {
            let k = (v * 65535.0 + 0.5) as u32;
            assert_eq!(
                (k as f32 / 65535.0).to_bits(),
                v.to_bits(),
                "value {i}: {v}"
            );
            assert_eq!(
                lut.decode(v).to_bits(),
                picker_render::io::srgb_decode(v).to_bits()
            );
        }
    }

    /// A TIFF-structured EXIF block: IFD0 with an orientation entry and the
    /// Exif IFD pointer, the Exif IFD with `FocalLengthIn35mmFilm` of type
    /// `ty` (3 SHORT, 4 LONG) and value `v`, in either byte order.
    fn exif_block(le: bool, ty: u16, v: u32) -> Vec<u8> {
        let w16 = |o: &mut Vec<u8>, x: u16| {
            o.extend_from_slice(&if le { x.to_le_bytes() } else { x.to_be_bytes() })
        };
        let w32 = |o: &mut Vec<u8>, x: u32| {
            o.extend_from_slice(&if le { x.to_le_bytes() } else { x.to_be_bytes() })
        };
        let mut o = if le {
            b"II*\0".to_vec()
        } else {
            b"MM\0*".to_vec()
        };
        w32(&mut o, 8); // IFD0 at 8
        w16(&mut o, 2);
        // Orientation = 1.
        w16(&mut o, 0x0112);
        w16(&mut o, 3);
        w32(&mut o, 1);
        w16(&mut o, 1);
        w16(&mut o, 0);
        // ExifIFDPointer -> 8 + 2 + 24 + 4 = 38.
        w16(&mut o, 0x8769);
        w16(&mut o, 4);
        w32(&mut o, 1);
        w32(&mut o, 38);
        w32(&mut o, 0); // no next IFD
        assert_eq!(o.len(), 38);
        w16(&mut o, 1);
        w16(&mut o, 0xA405);
        w16(&mut o, ty);
        w32(&mut o, 1);
        if ty == 3 {
            w16(&mut o, v as u16);
            w16(&mut o, 0);
        } else {
            w32(&mut o, v);
        }
        w32(&mut o, 0);
        o
    }

    /// Appends a little-endian IFD of `entries` (tag, type, count, value;
    /// `at(tag)` replaces the value of the entries that point elsewhere in the
    /// file) and the zero offset of the next one.
    fn push_ifd(
        o: &mut Vec<u8>,
        entries: &[(u16, u16, u32, u32)],
        at: impl Fn(u16) -> Option<u32>,
    ) {
        o.extend((entries.len() as u16).to_le_bytes());
        for &(tag, ty, count, v) in entries {
            let v = at(tag).unwrap_or(v);
            o.extend(tag.to_le_bytes());
            o.extend(ty.to_le_bytes());
            o.extend(count.to_le_bytes());
            if ty == 3 && count == 1 {
                o.extend((v as u16).to_le_bytes());
                o.extend([0, 0]);
            } else {
                o.extend(v.to_le_bytes());
            }
        }
        o.extend(0u32.to_le_bytes());
    }

    /// A 4×2 uncompressed 8-bit RGB TIFF file whose IFD0 points to an Exif
    /// IFD stating `FocalLengthIn35mmFilm` = `f35` (little-endian), as a
    /// camera writes it: the file is its own EXIF structure.
    fn tiff_with_focal(f35: u16) -> Vec<u8> {
        let (w, h) = (4u32, 2u32);
        let entries: [(u16, u16, u32, u32); 10] = [
            (256, 3, 1, w),         // ImageWidth
            (257, 3, 1, h),         // ImageLength
            (258, 3, 3, 0),         // BitsPerSample -> patched below
            (259, 3, 1, 1),         // no compression
            (262, 3, 1, 2),         // RGB
            (273, 4, 1, 0),         // StripOffsets -> patched
            (277, 3, 1, 3),         // SamplesPerPixel
            (278, 3, 1, h),         // RowsPerStrip
            (279, 4, 1, w * h * 3), // StripByteCounts
            (0x8769, 4, 1, 0),      // ExifIFDPointer -> patched
        ];
        let ifd0 = 8u32;
        let ifd0_len = 2 + 12 * entries.len() as u32 + 4;
        let bits_at = ifd0 + ifd0_len;
        let exif_at = bits_at + 6;
        let exif_len = 2 + 12 + 4;
        let pixels_at = exif_at + exif_len;
        let mut o = b"II*\0".to_vec();
        o.extend(ifd0.to_le_bytes());
        push_ifd(&mut o, &entries, |tag| match tag {
            258 => Some(bits_at),
            273 => Some(pixels_at),
            0x8769 => Some(exif_at),
            _ => None,
        });
        for _ in 0..3 {
            o.extend(8u16.to_le_bytes());
        }
        o.extend(1u16.to_le_bytes());
        o.extend(0xA405u16.to_le_bytes());
        o.extend(3u16.to_le_bytes());
        o.extend(1u32.to_le_bytes());
        o.extend(f35.to_le_bytes());
        o.extend([0, 0]);
        o.extend(0u32.to_le_bytes());
        assert_eq!(o.len() as u32, pixels_at);
        o.extend((0..w * h * 3).map(|i| (i * 10) as u8));
        o
    }

    /// A TIFF of `w × h` pixels of `C` samples written by the `tiff` crate.
    fn encoded<C: tiff::encoder::colortype::ColorType>(w: u32, h: u32, data: &[C::Inner]) -> Vec<u8>
    where
        [C::Inner]: tiff::encoder::TiffValue,
    {
        let mut buf = Cursor::new(Vec::new());
        let mut enc = tiff::encoder::TiffEncoder::new(&mut buf).unwrap();
        enc.write_image::<C>(w, h, data).unwrap();
        buf.into_inner()
    }

    /// An uncompressed little-endian RGB TIFF of 16-bit float samples (the
    /// `tiff` crate writes none).
    fn f16_tiff(w: u32, h: u32, values: &[half::f16]) -> Vec<u8> {
        let entries: [(u16, u16, u32, u32); 10] = [
            (256, 3, 1, w),         // ImageWidth
            (257, 3, 1, h),         // ImageLength
            (258, 3, 3, 0),         // BitsPerSample -> the three below
            (259, 3, 1, 1),         // no compression
            (262, 3, 1, 2),         // RGB
            (273, 4, 1, 0),         // StripOffsets -> the pixels
            (277, 3, 1, 3),         // SamplesPerPixel
            (278, 3, 1, h),         // RowsPerStrip
            (279, 4, 1, w * h * 6), // StripByteCounts
            (339, 3, 3, 0),         // SampleFormat -> the three below
        ];
        let ifd_len = 2 + 12 * entries.len() as u32 + 4;
        let (bits_at, formats_at) = (8 + ifd_len, 8 + ifd_len + 6);
        let pixels_at = formats_at + 6;
        let mut o = b"II*\0".to_vec();
        o.extend(8u32.to_le_bytes());
        push_ifd(&mut o, &entries, |tag| match tag {
            258 => Some(bits_at),
            273 => Some(pixels_at),
            339 => Some(formats_at),
            _ => None,
        });
        for v in [16u16, 16, 16, 3, 3, 3] {
            o.extend(v.to_le_bytes());
        }
        assert_eq!(o.len() as u32, pixels_at);
        for v in values {
            o.extend(v.to_bits().to_le_bytes());
        }
        o
    }

    #[test]
    fn float_tiffs_of_16_and_64_bits_read_as_32_bit_ones() {
        // Values beyond [0, 1] and a NaN (clamped, 0), alpha partly below ½.
        let (w, h) = (7u32, 5u32);
        let n = (w * h) as usize;
        let mut rng = picker_tensor::Rng::new(67);
        let mut v: Vec<f32> = (0..4 * n).map(|_| rng.uniform(-0.2, 1.2)).collect();
        v[5] = f32::NAN;
        let wide = |x: &[f32]| x.iter().map(|&t| f64::from(t)).collect::<Vec<f64>>();
        let limits = PhotoLimits::default();
        let read = |b: &[u8]| decode(b, Path::new("t.tif"), &limits).unwrap();
        let raw = |p: &Photo| {
            p.rgb
                .as_raw()
                .iter()
                .map(|x| x.to_bits())
                .collect::<Vec<_>>()
        };
        let same = |a: &Photo, b: &Photo, bits: u8| {
            assert_eq!(raw(a), raw(b));
            assert_eq!(a.opaque, b.opaque);
            assert_eq!(a.channels_in_file, b.channels_in_file);
            assert_eq!((a.bit_depth, b.bit_depth), (bits, 32));
        };
        use tiff::encoder::colortype as ct;
        let rgb = &v[..3 * n];
        same(
            &read(&encoded::<ct::RGB64Float>(w, h, &wide(rgb))),
            &read(&encoded::<ct::RGB32Float>(w, h, rgb)),
            64,
        );
        // Grey (32-bit grey too, which `image` does not read) as its RGB.
        let grey = &v[..n];
        let as_rgb: Vec<f32> = grey.iter().flat_map(|&g| [g; 3]).collect();
        let rgb_of_grey = read(&encoded::<ct::RGB32Float>(w, h, &as_rgb));
        for (bits, g) in [
            (64, read(&encoded::<ct::Gray64Float>(w, h, &wide(grey)))),
            (32, read(&encoded::<ct::Gray32Float>(w, h, grey))),
        ] {
            assert_eq!(g.channels_in_file, 1);
            assert_eq!(g.bit_depth, bits);
            assert_eq!(raw(&g), raw(&rgb_of_grey));
        }
        let a = read(&encoded::<ct::RGBA64Float>(w, h, &wide(&v)));
        same(&a, &read(&encoded::<ct::RGBA32Float>(w, h, &v)), 64);
        assert!(a
            .opaque
            .as_ref()
            .is_some_and(|o| o.contains(&false) && o.contains(&true)));
        // 16-bit floats: the same values rounded to half precision.
        let halves: Vec<half::f16> = rgb.iter().map(|&x| half::f16::from_f32(x)).collect();
        let back: Vec<f32> = halves.iter().map(|x| x.to_f32()).collect();
        same(
            &read(&f16_tiff(w, h, &halves)),
            &read(&encoded::<ct::RGB32Float>(w, h, &back)),
            16,
        );
        // The size limits hold for them too.
        let small = PhotoLimits {
            max_pixels: n as u64 - 1,
            ..PhotoLimits::default()
        };
        let e = decode(
            &encoded::<ct::RGB64Float>(w, h, &wide(rgb)),
            Path::new("t.tif"),
            &small,
        )
        .unwrap_err();
        assert!(matches!(e, PhotoError::TooManyPixels { .. }), "{e}");
        // 64-bit RGBA needs 48 bytes a pixel while it is converted.
        let tight = PhotoLimits {
            max_alloc: 40 * n as u64,
            ..PhotoLimits::default()
        };
        let e = decode(
            &encoded::<ct::RGBA64Float>(w, h, &wide(&v)),
            Path::new("t.tif"),
            &tight,
        )
        .unwrap_err();
        assert!(matches!(e, PhotoError::TooMuchMemory { .. }), "{e}");
    }

    #[test]
    fn a_tiff_photo_states_its_focal_length_itself() {
        let bytes = tiff_with_focal(35);
        let p = decode(&bytes, Path::new("cam.tif"), &PhotoLimits::default()).unwrap();
        assert_eq!(
            (p.rgb.width(), p.rgb.height(), p.format.as_str()),
            (4, 2, "tiff")
        );
        assert_eq!(p.focal_35mm, Some(35.0));
        // Without the tag, none.
        let mut plain = bytes.clone();
        let at = plain
            .windows(2)
            .position(|b| b == 0xA405u16.to_le_bytes())
            .unwrap();
        plain[at..at + 2].copy_from_slice(&0xA404u16.to_le_bytes());
        let p = decode(&plain, Path::new("cam.tif"), &PhotoLimits::default()).unwrap();
        assert_eq!(p.focal_35mm, None);
    }

    #[test]
    fn the_35mm_focal_length_is_read_from_exif_blocks() {
        for le in [true, false] {
            assert_eq!(exif_focal_35mm(&exif_block(le, 3, 26)), Some(26.0));
            assert_eq!(exif_focal_35mm(&exif_block(le, 4, 105)), Some(105.0));
            let mut app1 = b"Exif\0\0".to_vec();
            app1.extend(exif_block(le, 3, 28));
            assert_eq!(exif_focal_35mm(&app1), Some(28.0));
            // 0 is "unknown"; a telescope's worth is garbage; a RATIONAL is
            // not the tag's type.
            assert_eq!(exif_focal_35mm(&exif_block(le, 3, 0)), None);
            assert_eq!(exif_focal_35mm(&exif_block(le, 4, 5000)), None);
            assert_eq!(exif_focal_35mm(&exif_block(le, 5, 26)), None);
            // Every cut of the block, and seeded byte damage: no panic.
            let full = exif_block(le, 3, 26);
            for n in 0..full.len() {
                let got = exif_focal_35mm(&full[..n]);
                assert!(got.is_none() || got == Some(26.0), "cut at {n}: {got:?}");
            }
            let mut rng = picker_tensor::Rng::new(u64::from(le));
            for _ in 0..2000 {
                let mut b = full.clone();
                for _ in 0..3 {
                    let i = rng.range(0, b.len() - 1);
                    b[i] = (rng.f64() * 256.0) as u8;
                }
                if let Some(f) = exif_focal_35mm(&b) {
                    assert!((1.0..=MAX_FOCAL_35MM as f32).contains(&f));
                }
            }
        }
        // Not EXIF, or no Exif IFD.
        assert_eq!(exif_focal_35mm(b""), None);
        assert_eq!(exif_focal_35mm(b"JFIF\0\0\0\0\0\0"), None);
        let mut no_ptr = exif_block(true, 3, 26);
        no_ptr[22] = 0x00; // the pointer's tag 0x8769 -> 0x8700
        assert_eq!(exif_focal_35mm(&no_ptr), None);
    }

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
    fn opacity_turns_with_the_pixels() {
        // Every orientation moves the flags as it moves the pixels: a
        // 5×3 image whose pixels are opaque where their red is odd.
        let (w, h) = (5u32, 3u32);
        let rgb = Rgb32FImage::from_fn(w, h, |x, y| image::Rgb([(x + w * y) as f32, 0.0, 0.0]));
        let flags: Vec<bool> = rgb.pixels().map(|p| p.0[0] as u32 % 2 == 1).collect();
        for o in 1..=8 {
            let o = Orientation::from_exif(o).unwrap();
            let turned = orient(rgb.clone(), o);
            let want: Vec<bool> = turned.pixels().map(|p| p.0[0] as u32 % 2 == 1).collect();
            assert_eq!(orient_flags(flags.clone(), w, h, o), want, "{o:?}");
        }
    }

    #[test]
    fn planar_copy_matches_pixels() {
        for (w, h) in [(1u32, 1u32), (3, 1), (1, 4), (17, 9)] {
            let img = Rgb32FImage::from_fn(w, h, |x, y| {
                image::Rgb([x as f32, y as f32 * 10.0, (x * 100 + y) as f32 + 0.5])
            });
            let got = to_planar(&img);
            let n = (w * h) as usize;
            assert_eq!(got.len(), 3 * n);
            for (i, p) in img.pixels().enumerate() {
                for c in 0..3 {
                    assert_eq!(got[c * n + i], p.0[c]);
                }
            }
        }
    }

    #[test]
    fn parallel_rgb8_conversion_matches_image() {
        let mut rng = picker_tensor::Rng::new(9);
        for (w, h) in [(1u32, 1u32), (256, 1), (17, 9), (64, 48)] {
            let img = image::RgbImage::from_fn(w, h, |x, y| {
                if y == 0 && x < 256 {
                    image::Rgb([x as u8, 255 - x as u8, (x * 7) as u8])
                } else {
                    image::Rgb([rng.range(0, 255) as u8, rng.range(0, 255) as u8, 0])
                }
            });
            let a = rgb32f(DynamicImage::ImageRgb8(img.clone()));
            let b = DynamicImage::ImageRgb8(img).into_rgb32f();
            assert_eq!(a.dimensions(), b.dimensions());
            let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(a.as_raw()), bits(b.as_raw()), "{w}x{h}");
            assert_eq!(a.color_space(), b.color_space());
        }
        // Other layouts go through `into_rgb32f` itself.
        let grey = DynamicImage::ImageLuma16(image::ImageBuffer::from_fn(5, 3, |x, y| {
            image::Luma([(x * 9000 + y) as u16])
        }));
        assert_eq!(rgb32f(grey.clone()), grey.into_rgb32f());
    }

    #[test]
    fn megapixel_text() {
        assert_eq!(megapixels(100_000_000), "100");
        assert_eq!(megapixels(2_500_000_000), "2500");
        assert_eq!(megapixels(1_234_567), "1.23");
        assert_eq!(megapixels(35), "0.000035");
        assert_eq!(megapixels(1_500_000), "1.5");
    }

    #[test]
    fn srgb_curve_ends() {
        assert_eq!(srgb_encode(0.0), 0.0);
        assert!((srgb_encode(1.0) - 1.0).abs() < 1e-6);
        assert!((srgb_encode(0.18) - 0.4614).abs() < 1e-3);
    }
}
