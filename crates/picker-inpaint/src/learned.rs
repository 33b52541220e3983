//! [`LearnedInpainter`]: a learned texture inpainter (the thesis used a GAN
//! inpainter) loaded from a `picker-nets` weights file with `net` = `inpaint`.
//!
//! The network ([`picker_nets::Inpaint`], `weights-format.md`, "Inpaint") is a
//! pix2pix ResnetGenerator-style encoder → residual blocks → decoder, the MSN's
//! structure with one more input plane. This module only runs it; the default
//! inpainter of the extractor stays [`crate::PatchMatchInpainter`], since no
//! trained weights ship with Material Picker.
//!
//! **Convention** (the image is linear RGB, the network sees sRGB):
//! 1. each channel of a known texel is encoded with
//!    [`picker_nets::conventions::srgb_encode`] (clamped to `[0, 1]`) and mapped
//!    to `x = 2v − 1`; unknown texels are `0` in every texture plane;
//! 2. one more plane holds the mask: `+1` known, `−1` unknown
//!    ([`picker_nets::conventions::inpaint_input`]);
//! 3. the input is padded: with [`InpaintOptions::toroidal`] periodically (wrap)
//!    by [`LearnedInpainter::toroidal_margin`] texels on every side, then cropped
//!    back, so the network sees the texture's true neighbours across the wrap
//!    edges; otherwise the network's own mirror padding to a multiple of 4 is used;
//! 4. the tanh output `y` is decoded as sRGB `(y + 1)/2` and then to linear with
//!    [`picker_render::io::srgb_decode`]; known texels are copied from the input
//!    bit for bit, so only unknown texels take network values (in `[0, 1]`).
//!
//! A 1-channel (grey) image is run through a 3-channel network by replicating
//! the grey plane and averaging the outputs; other channel counts must equal
//! the network's `channels`.
//!
//! ```
//! use picker_inpaint::{Image, InpaintOptions, Inpainter, LearnedInpainter};
//! use picker_nets::{metadata_for, random_weights, save_safetensors, NetConfig, NetKind, StorageDtype};
//!
//! // Random (untrained) `tiny` weights stand in for a trained file.
//! let dir = tempfile::tempdir().unwrap();
//! let path = dir.path().join("inpaint.safetensors");
//! let config = NetConfig::preset(NetKind::Inpaint, "tiny").unwrap();
//! let meta = metadata_for(&config, "tiny").unwrap();
//! save_safetensors(&path, &random_weights(&config, 1), &meta, StorageDtype::F32).unwrap();
//!
//! let inpainter = LearnedInpainter::load(&path).unwrap();
//! let image = Image::new(3, 10, 12, vec![0.25; 3 * 10 * 12]).unwrap(); // linear RGB
//! let known: Vec<bool> = (0..10 * 12).map(|i| i % 12 < 8).collect(); // right third unknown
//! let filled = inpainter.inpaint(&image, &known, &InpaintOptions::default()).unwrap();
//! assert_eq!(filled.data[0], 0.25); // known texels kept exactly
//! assert!(filled.data.iter().all(|v| (0.0..=1.0).contains(v)));
//! ```

use std::path::{Path, PathBuf};

use picker_nets::conventions::{inpaint_input, srgb_encode, srgb_from_input};
use picker_nets::{Inpaint, InpaintConfig, NetKind, Weights};
use picker_render::io::{srgb_decode, Image};
use picker_tensor::Tensor;

use crate::{validate, Error, InpaintOptions, Inpainter, Plan, Result};

/// Default wrap margin (texels per side) of toroidal inpainting.
pub const DEFAULT_TOROIDAL_MARGIN: usize = 16;

/// A learned inpainting network ([`picker_nets::Inpaint`]) behind the
/// [`Inpainter`] interface. See the module documentation for the input and
/// output conventions.
#[derive(Clone, Debug)]
pub struct LearnedInpainter {
    net: Inpaint,
    path: PathBuf,
    margin: usize,
}

impl LearnedInpainter {
    /// Loads the network of an `inpaint` weights file, strictly: a file holding
    /// another network (IRN, MSN, EnvMap), a missing, extra or misshaped tensor
    /// or a broken file is refused with an error naming the file (and the key,
    /// expected and found shape where a tensor is at fault).
    pub fn load(path: &Path) -> Result<Self> {
        let weights = Weights::open(path)?;
        Self::from_weights(&weights)
    }

    /// As [`LearnedInpainter::load`], from already opened weights (e.g.
    /// [`Weights::from_bytes`] for embedded files).
    pub fn from_weights(weights: &Weights) -> Result<Self> {
        if weights.kind() != NetKind::Inpaint {
            return Err(Error::Weights {
                path: weights.path().to_path_buf(),
                reason: format!(
                    "file holds {} weights, but a learned inpainter needs inpaint weights \
                     (metadata net = \"inpaint\"; see weights-format.md)",
                    weights.kind()
                ),
            });
        }
        Ok(Self {
            net: Inpaint::load(weights)?,
            path: weights.path().to_path_buf(),
            margin: DEFAULT_TOROIDAL_MARGIN,
        })
    }

    /// Sets the wrap margin (texels per side) used when
    /// [`InpaintOptions::toroidal`] is set; default [`DEFAULT_TOROIDAL_MARGIN`].
    pub fn with_toroidal_margin(mut self, margin: usize) -> Self {
        self.margin = margin;
        self
    }

    /// The wrap margin (texels per side) of toroidal inpainting.
    pub fn toroidal_margin(&self) -> usize {
        self.margin
    }

    /// The file the network was loaded from.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The network's configuration.
    pub fn config(&self) -> &InpaintConfig {
        self.net.config()
    }

    /// The network.
    pub fn net(&self) -> &Inpaint {
        &self.net
    }

    /// Runs the network on the sRGB planes `srgb` (`nc` planes of `h × w`) and
    /// returns the decoded sRGB output planes (`nc × h × w`).
    fn run(
        &self,
        srgb: Vec<f32>,
        known: &[bool],
        (h, w): (usize, usize),
        toroidal: bool,
    ) -> Result<Vec<f32>> {
        let nc = self.net.config().channels;
        let m = if toroidal { self.margin } else { 0 };
        let (hp, wp) = (h + 2 * m, w + 2 * m);
        // Wrap-pad (periodic) by `m` on every side; m = 0 is the identity.
        let src = |r: usize, c: usize| ((r + h * m - m) % h) * w + (c + w * m - m) % w;
        let mut planes = vec![0.0f32; nc * hp * wp];
        let mut mask = vec![false; hp * wp];
        for r in 0..hp {
            for c in 0..wp {
                let s = src(r, c);
                mask[r * wp + c] = known[s];
                for ch in 0..nc {
                    planes[ch * hp * wp + r * wp + c] = srgb[ch * h * w + s];
                }
            }
        }
        let t = Tensor::new([1, nc, hp, wp], planes).map_err(picker_nets::Error::from)?;
        let x = inpaint_input(&t, &mask)?;
        let y = self.net.forward(&x)?.inpainted;
        let y = if m > 0 {
            y.crop(m, m, h, w).map_err(picker_nets::Error::from)?
        } else {
            y
        };
        Ok(y.data().iter().map(|&v| srgb_from_input(v)).collect())
    }
}

impl Inpainter for LearnedInpainter {
    fn name(&self) -> &str {
        "learned"
    }

    fn inpaint(&self, image: &Image, known: &[bool], opts: &InpaintOptions) -> Result<Image> {
        if let Plan::Done(img) = validate(image, known, opts)? {
            return Ok(img);
        }
        let (c, h, w) = (image.channels, image.height, image.width);
        let nc = self.net.config().channels;
        let n = h * w;
        let encoded: Vec<f32> = image.data.iter().map(|&v| srgb_encode(v)).collect();
        let (input, grey) = if c == nc {
            (encoded, false)
        } else if c == 1 {
            (encoded.repeat(nc), true)
        } else {
            return Err(Error::Invalid(format!(
                "{}: the learned inpainter fills {nc}-channel (or 1-channel) textures; the image has {c} channels",
                self.path.display()
            )));
        };
        let out = self.run(input, known, (h, w), opts.toroidal)?;
        let mut result = image.clone();
        for ch in 0..c {
            for (i, _) in known.iter().enumerate().filter(|(_, &k)| !k) {
                let v = if grey {
                    (0..nc).map(|k| out[k * n + i]).sum::<f32>() / nc as f32
                } else {
                    out[ch * n + i]
                };
                result.data[ch * n + i] = srgb_decode(v);
            }
        }
        Ok(result)
    }
}
