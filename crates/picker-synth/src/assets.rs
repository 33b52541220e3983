//! Real assets for the scene generator: photographs of surfaces and HDR environment
//! maps found under an `assets/` folder (made by `scripts/fetch-assets.sh`, gitignored).
//!
//! Layout (the script's `assets/README.md` says the same):
//! - `hdri/**/*.exr|*.hdr`: equirectangular HDR environment maps (linear radiance);
//! - `textures/**/*.jpg|*.jpeg|*.png|*.pat`: photographs of surfaces (sRGB; `.pat` is a GIMP
//!   pattern); the parent folder's name (`floor`, `wall`, `wood`, …) is kept as the photo's
//!   [`Asset::category`];
//! - a file named `copyright`, `LICENSE*`, `LICENCE*` or `COPYING*` in an asset's folder, or in
//!   the nearest folder above it inside the library, is that asset's [`Asset::licence`].
//!
//! A missing or empty folder is an empty library (procedural textures and skies only), not
//! an error. Files are listed in sorted path order, so a seed picks the same asset on every
//! machine that has the same files. Files are only opened when used (and then cached in the
//! library); a file that cannot be read then gives an [`AssetError`] naming it.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use picker_render::EnvMap;

use crate::textures::Texture;

/// Errors of the asset library and of loading assets.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum AssetError {
    /// A folder of the library exists but cannot be listed.
    #[error("cannot list asset folder {path}: {source}")]
    List {
        /// The folder.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// An asset file exists but cannot be read or decoded.
    #[error("cannot load asset {path}: {reason}")]
    Load {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        reason: String,
    },
}

/// `Result` with [`AssetError`].
pub type Result<T, E = AssetError> = std::result::Result<T, E>;

/// One asset file.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Asset {
    /// The file.
    pub path: PathBuf,
    /// The name of its folder (e.g. `floor`, `wall`, `blender-data`), lower-case.
    pub category: String,
    /// Its licence file, if the library has one for it.
    pub licence: Option<PathBuf>,
}

/// The photographs and HDR environment maps under one folder.
///
/// Decoded photos and resampled HDRIs are cached inside the library (shared by its clones
/// and across threads), so generating many scenes decodes each file once per size; a cached
/// value is a pure function of the file, so caching never changes any output.
#[derive(Clone, Debug, Default)]
pub struct AssetLibrary {
    /// The folder scanned.
    pub root: PathBuf,
    /// Surface photographs (`textures/`), sorted by path.
    pub photos: Vec<Asset>,
    /// HDR environment maps (`hdri/`), sorted by path.
    pub hdris: Vec<Asset>,
    cache: Arc<Cache>,
}

type HdriKey = (PathBuf, usize, usize);

#[derive(Debug, Default)]
struct Cache {
    photos: Mutex<HashMap<PathBuf, Arc<Texture>>>,
    hdris: Mutex<HashMap<HdriKey, Arc<EnvMap>>>,
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

const PHOTO_EXTENSIONS: &[&str] = &["jpg", "jpeg", "png", "pat"];
const HDRI_EXTENSIONS: &[&str] = &["exr", "hdr"];

impl AssetLibrary {
    /// An empty library: procedural textures and skies only.
    pub fn empty() -> Self {
        Self::default()
    }

    /// Scans `dir` (see the module docs for the layout). A missing `dir`, or one without
    /// `textures/` and `hdri/`, gives an empty library.
    pub fn scan(dir: impl AsRef<Path>) -> Result<Self> {
        let root = dir.as_ref().to_path_buf();
        let photos = scan_kind(&root, "textures", PHOTO_EXTENSIONS)?;
        let hdris = scan_kind(&root, "hdri", HDRI_EXTENSIONS)?;
        Ok(Self {
            root,
            photos,
            hdris,
            cache: Arc::default(),
        })
    }

    /// The photo `asset` as linear RGB (sRGB decoded), decoded once and cached.
    pub fn photo(&self, asset: &Asset) -> Result<Arc<Texture>> {
        if let Some(t) = lock(&self.cache.photos).get(&asset.path) {
            return Ok(Arc::clone(t));
        }
        let (width, height, data) = load_photo_linear(&asset.path)?;
        let t = Arc::new(Texture {
            width,
            height,
            data,
        });
        lock(&self.cache.photos).insert(asset.path.clone(), Arc::clone(&t));
        Ok(t)
    }

    /// The HDRI `asset` read with `picker_render::EnvMap::read` and resampled (area-correct)
    /// to `width × height`, cached per size.
    pub fn hdri(&self, asset: &Asset, width: usize, height: usize) -> Result<Arc<EnvMap>> {
        let key = (asset.path.clone(), width, height);
        if let Some(m) = lock(&self.cache.hdris).get(&key) {
            return Ok(Arc::clone(m));
        }
        let load_err = |e: picker_render::Error| AssetError::Load {
            path: asset.path.clone(),
            reason: e.to_string(),
        };
        let map = EnvMap::read(&asset.path)
            .and_then(|m| m.resample(width, height))
            .map_err(load_err)?;
        let map = Arc::new(map);
        lock(&self.cache.hdris).insert(key, Arc::clone(&map));
        Ok(map)
    }

    /// Whether the library has neither photos nor HDRIs.
    pub fn is_empty(&self) -> bool {
        self.photos.is_empty() && self.hdris.is_empty()
    }

    /// The photos of one category (`floor`, `wall`, …).
    pub fn photos_in(&self, category: &str) -> impl Iterator<Item = &Asset> + '_ {
        let category = category.to_lowercase();
        self.photos.iter().filter(move |a| a.category == category)
    }
}

fn has_extension(path: &Path, exts: &[&str]) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| exts.iter().any(|x| e.eq_ignore_ascii_case(x)))
}

fn is_licence_name(name: &str) -> bool {
    let n = name.to_ascii_lowercase();
    n == "copyright"
        || n.starts_with("license")
        || n.starts_with("licence")
        || n.starts_with("copying")
}

fn scan_kind(root: &Path, sub: &str, exts: &[&str]) -> Result<Vec<Asset>> {
    let top = root.join(sub);
    if !top.is_dir() {
        return Ok(Vec::new());
    }
    let mut out = Vec::new();
    walk(&top, exts, None, &mut out)?;
    out.sort_by(|a, b| a.path.cmp(&b.path));
    Ok(out)
}

fn walk(dir: &Path, exts: &[&str], inherited: Option<&Path>, out: &mut Vec<Asset>) -> Result<()> {
    let list_err = |source| AssetError::List {
        path: dir.to_path_buf(),
        source,
    };
    let mut entries: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(list_err)?
        .map(|e| e.map(|e| e.path()))
        .collect::<std::io::Result<_>>()
        .map_err(list_err)?;
    entries.sort();
    let licence = entries
        .iter()
        .find(|p| {
            p.is_file()
                && p.file_name()
                    .and_then(|n| n.to_str())
                    .is_some_and(is_licence_name)
        })
        .cloned()
        .or_else(|| inherited.map(Path::to_path_buf));
    let category = dir
        .file_name()
        .and_then(|n| n.to_str())
        .unwrap_or("")
        .to_lowercase();
    for p in &entries {
        if p.is_dir() {
            walk(p, exts, licence.as_deref(), out)?;
        } else if p.is_file() && has_extension(p, exts) {
            out.push(Asset {
                path: p.clone(),
                category: category.clone(),
                licence: licence.clone(),
            });
        }
    }
    Ok(())
}

/// Reads a photo as linear RGB (sRGB decoded), row-major, with its width and height:
/// JPEG or PNG (image crate), or a GIMP pattern (`.pat`, [`decode_gimp_pattern`]).
pub fn load_photo_linear(path: &Path) -> Result<(usize, usize, Vec<glam::Vec3>)> {
    let load_err = |reason: String| AssetError::Load {
        path: path.to_path_buf(),
        reason,
    };
    let (w, h, bytes) = if has_extension(path, &["pat"]) {
        let data = std::fs::read(path).map_err(|e| load_err(e.to_string()))?;
        decode_gimp_pattern(&data).map_err(load_err)?
    } else {
        let rgb = image::open(path)
            .map_err(|e| load_err(e.to_string()))?
            .to_rgb8();
        let (w, h) = (rgb.width() as usize, rgb.height() as usize);
        (w, h, rgb.into_raw())
    };
    if w == 0 || h == 0 {
        return Err(load_err("image is empty".into()));
    }
    let lut: Vec<f32> = (0..256)
        .map(|i| picker_render::io::srgb_decode(i as f32 / 255.0))
        .collect();
    let data = bytes
        .chunks_exact(3)
        .map(|p| glam::Vec3::new(lut[p[0] as usize], lut[p[1] as usize], lut[p[2] as usize]))
        .collect();
    Ok((w, h, data))
}

/// Decodes a GIMP pattern (`.pat`, version 1): a big-endian header `header_size, version,
/// width, height, bytes_per_pixel` (u32 each), the magic `GPAT`, a name, then
/// `width·height·bytes_per_pixel` bytes from `header_size` on (1 grey, 2 grey+alpha, 3 RGB,
/// 4 RGBA; alpha is dropped). Returns width, height and 8-bit sRGB RGB bytes.
pub fn decode_gimp_pattern(data: &[u8]) -> std::result::Result<(usize, usize, Vec<u8>), String> {
    let word = |i: usize| -> usize {
        u32::from_be_bytes([data[i], data[i + 1], data[i + 2], data[i + 3]]) as usize
    };
    if data.len() < 24 || &data[20..24] != b"GPAT" {
        return Err("not a GIMP pattern (no GPAT magic)".into());
    }
    let (header, version, w, h, bpp) = (word(0), word(4), word(8), word(12), word(16));
    if version != 1 || !(1..=4).contains(&bpp) || header < 24 {
        return Err(format!(
            "unsupported GIMP pattern (version {version}, {bpp} bytes per pixel, header {header})"
        ));
    }
    let n = w
        .checked_mul(h)
        .and_then(|n| n.checked_mul(bpp))
        .ok_or("GIMP pattern size overflows")?;
    let pixels = data
        .get(header..)
        .and_then(|d| d.get(..n))
        .ok_or_else(|| format!("GIMP pattern truncated: {w}x{h}x{bpp} needs {n} bytes"))?;
    let rgb = pixels
        .chunks_exact(bpp)
        .flat_map(|p| match bpp {
            1 | 2 => [p[0], p[0], p[0]],
            _ => [p[0], p[1], p[2]],
        })
        .collect();
    Ok((w, h, rgb))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tmp(name: &str) -> PathBuf {
        let d =
            std::env::temp_dir().join(format!("picker-synth-assets-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        d
    }

    #[test]
    fn gimp_patterns_decode() {
        let mut pat = Vec::new();
        for v in [28u32, 1, 2, 1, 1] {
            pat.extend_from_slice(&v.to_be_bytes());
        }
        pat.extend_from_slice(b"GPATabc\0");
        pat.extend_from_slice(&[10, 200]);
        assert_eq!(
            decode_gimp_pattern(&pat).unwrap(),
            (2, 1, vec![10, 10, 10, 200, 200, 200])
        );
        assert!(decode_gimp_pattern(&pat[..29])
            .unwrap_err()
            .contains("truncated"));
        assert!(decode_gimp_pattern(b"nope").is_err());
    }

    #[test]
    fn missing_and_empty_folders_are_empty_libraries() {
        let d = tmp("missing");
        let lib = AssetLibrary::scan(&d).unwrap();
        assert!(lib.is_empty());
        std::fs::create_dir_all(&d).unwrap();
        assert!(AssetLibrary::scan(&d).unwrap().is_empty());
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn scan_sorts_categorises_and_finds_licences() {
        let d = tmp("scan");
        let floor = d.join("textures/src/floor");
        let wall = d.join("textures/src/wall");
        let hdri = d.join("hdri/set");
        for f in [&floor, &wall, &hdri] {
            std::fs::create_dir_all(f).unwrap();
        }
        for p in [
            floor.join("b.JPG"),
            floor.join("a.png"),
            wall.join("c.jpeg"),
            wall.join("notes.txt"),
            d.join("textures/src/copyright"),
            hdri.join("sky.exr"),
            hdri.join("old.hdr"),
            hdri.join("LICENSE.txt"),
        ] {
            std::fs::write(p, b"x").unwrap();
        }
        let lib = AssetLibrary::scan(&d).unwrap();
        let names: Vec<_> = lib
            .photos
            .iter()
            .map(|a| a.path.file_name().unwrap().to_str().unwrap())
            .collect();
        assert_eq!(names, ["a.png", "b.JPG", "c.jpeg"]);
        assert_eq!(lib.photos_in("Floor").count(), 2);
        assert_eq!(
            lib.photos[2].licence.as_deref(),
            Some(d.join("textures/src/copyright").as_path())
        );
        assert_eq!(lib.hdris.len(), 2);
        assert_eq!(lib.hdris[0].licence, Some(hdri.join("LICENSE.txt")));
        // Unreadable files are an error naming the file when used.
        let err = load_photo_linear(&lib.photos[0].path).unwrap_err();
        assert!(err.to_string().contains("a.png"), "{err}");
        std::fs::remove_dir_all(&d).unwrap();
    }
}
