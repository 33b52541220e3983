//! Reading a photograph and making the working-resolution copy the networks
//! see: a thin layer over [`picker_extract::photo`], which holds the decoding
//! rules (formats, EXIF orientation, linear EXR/HDR exposure, size limits).
//!
//! Values are sRGB-encoded in `[0, 1]`, with the EXIF orientation applied, so
//! pixel coordinates are those of the photo as a viewer shows it (design §2).

use std::path::Path;

use anyhow::Result;
use image::Rgb32FImage;
use picker_extract::photo as lib;

pub use picker_extract::photo::PhotoLimits;

/// A decoded photo: sRGB values in `[0, 1]`, EXIF orientation applied
/// ([`picker_extract::photo::Photo`] with the format as an `ImageFormat`).
pub struct Photo {
    /// The pixels, RGB f32, row-major.
    pub rgb: Rgb32FImage,
    /// The EXIF orientation that was applied (`NoTransforms` when none).
    pub orientation: image::metadata::Orientation,
    /// The format the content was decoded as (e.g. `Png`), whatever the
    /// file's extension says.
    pub format: Option<image::ImageFormat>,
    /// Bits per sample in the file.
    pub bit_depth: u8,
    /// Channels in the file, alpha included.
    pub channels_in_file: u8,
    /// True for scene-linear inputs (EXR, HDR), exposed and sRGB-encoded.
    pub linear_input: bool,
    /// The 35 mm-equivalent focal length the EXIF states, mm.
    pub focal_35mm: Option<f32>,
    /// The file's colour profile and whether the pixels were converted from it to sRGB.
    pub colour_profile: Option<lib::ColourProfile>,
    /// Which pixels are opaque, when some are transparent; see
    /// [`picker_extract::photo::Photo::opaque`].
    pub opaque: Option<Vec<bool>>,
    /// The file's alpha was ignored (every pixel below ½).
    pub alpha_ignored: bool,
}

impl From<lib::Photo> for Photo {
    fn from(p: lib::Photo) -> Self {
        Self {
            format: image::ImageFormat::from_extension(&p.format),
            rgb: p.rgb,
            orientation: p.orientation,
            bit_depth: p.bit_depth,
            channels_in_file: p.channels_in_file,
            linear_input: p.linear_input,
            focal_35mm: p.focal_35mm,
            colour_profile: p.colour_profile,
            opaque: p.opaque,
            alpha_ignored: p.alpha_ignored,
        }
    }
}

/// Reads `path` with the default [`PhotoLimits`]. Errors name the file.
pub fn load(path: &Path) -> Result<Photo> {
    load_with(path, &PhotoLimits::default())
}

/// Reads `path` within `limits`. Errors name the file.
pub fn load_with(path: &Path, limits: &PhotoLimits) -> Result<Photo> {
    Ok(lib::load(path, limits)?.into())
}

/// Decodes the bytes of the file at `path` (already read) within `limits`.
pub fn decode_with(bytes: &[u8], path: &Path, limits: &PhotoLimits) -> Result<Photo> {
    Ok(lib::decode(bytes, path, limits)?.into())
}

/// The working size `(width, height)` for a `w × h` photo; see
/// [`picker_extract::photo::working_size`].
pub fn working_size(w: u32, h: u32, work_size: u32) -> (u32, u32) {
    lib::working_size(w, h, work_size)
}

/// Resizes to `(w, h)` (triangle filter on sRGB values); see
/// [`picker_extract::photo::resize`].
pub fn resize(rgb: &Rgb32FImage, w: u32, h: u32) -> Rgb32FImage {
    lib::resize(rgb, w, h)
}

/// The image as planar `[3, h, w]` values; see
/// [`picker_extract::photo::to_planar`].
pub fn to_planar(rgb: &Rgb32FImage) -> Vec<f32> {
    lib::to_planar(rgb)
}
