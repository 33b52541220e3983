//! The three networks of Material Picker — IRN (render elements), MSN
//! (material segmentation) and EnvMap (lighting) — and a learned texture
//! inpainter (`inpaint`), loaded from safetensors files and run on the CPU
//! with the kernels of [`picker_tensor`].
//!
//! The networks are those of the thesis "Material picker: Material recognition
//! in images using machine learning" (Charles University, 2023, ch. 5.2),
//! after Sengupta et al. 2019. The file format (keys, shapes, metadata) is
//! specified for users in `weights-format.md` at the repository root, and is
//! shared byte for byte with the PyTorch reference in `training/`.
//!
//! # Tour
//! - [`config`]: [`NetConfig`] (JSON in the file's metadata), presets
//!   (`thesis`, `tiny`), [`NetConfig::param_count`] and [`NetConfig::flops`].
//! - [`weights`]: [`Weights::open`] memory-maps a file and checks its header and
//!   metadata; models read tensors through prefix-scoped accessors
//!   ([`Weights::pp`]) that check shape and dtype, and loading fails on missing
//!   **and unused** tensors.
//! - [`layers`]: `ConvBn`, `ResBlock`, `Encoder`, `Decoder`, with BatchNorm folded
//!   into the convolutions at load and activations fused.
//! - [`nets`]: [`Irn`], [`Msn`], [`EnvMap`], [`Inpaint`] and [`Net`]; `forward`
//!   takes a normalised input of any size ≥ 1×1 and returns raw tanh outputs.
//! - [`conventions`]: input normalisation, output decoding (albedo, Phong
//!   exponent, normals, uv, segmentation, HDR radiance), environment-map
//!   directions and solid angles, [`conventions::RenderElements`].
//! - Writing: [`random_weights`], [`metadata_for`], [`save_safetensors`].
//!
//! # Example
//! Random `tiny` MSN weights, saved, loaded and run on a 13×21 image:
//! ```
//! use picker_nets::{
//!     conventions, metadata_for, random_weights, save_safetensors, Net, NetConfig, NetKind,
//!     StorageDtype, Weights,
//! };
//! use picker_tensor::Tensor;
//!
//! # fn main() -> picker_nets::Result<()> {
//! let config = NetConfig::preset(NetKind::Msn, "tiny")?;
//! let path = std::env::temp_dir().join(format!("picker-nets-doc-{}.safetensors", std::process::id()));
//! let tensors = random_weights(&config, 42);
//! save_safetensors(&path, &tensors, &metadata_for(&config, "tiny")?, StorageDtype::F16)?;
//!
//! let weights = Weights::open(&path)?;
//! assert_eq!(weights.kind(), NetKind::Msn);
//! let net = Net::load(&weights)?;
//! assert_eq!(net.param_count(), config.param_count());
//!
//! // sRGB in [0, 1] -> [-1, 1]; any size works.
//! let mut image = Tensor::from_fn([1, 3, 13, 21], |_, c, y, x| ((c + y + x) % 7) as f32 / 6.0);
//! conventions::normalize_input(&mut image);
//! let out = net.forward(&image)?;
//! let seg = out.get("segmentation").expect("MSN output");
//! assert_eq!(seg.shape(), [1, 3, 13, 21]);
//! let colours = conventions::decode_segmentation_tensor(seg);
//! assert!(colours.data().iter().all(|v| (0.0..=1.0).contains(v)));
//! # drop(weights);
//! # std::fs::remove_file(&path).ok();
//! # Ok(())
//! # }
//! ```

#![warn(missing_docs)]

pub mod config;
pub mod conventions;
mod display;
mod error;
pub mod keys;
pub mod layers;
pub mod mirror;
pub mod nets;
mod save;
pub mod weights;

pub use config::{
    EnvMapConfig, HeadConfig, InpaintConfig, IrnConfig, MsnConfig, NetConfig, NetKind,
    KNOWN_PRESETS, STANDARD_HEADS,
};
pub use conventions::RenderElements;
pub use error::{Error, Result, ACCEPTED_DTYPES};
pub use keys::{random_weights, state_dict_spec, ParamRole, ParamSpec};
pub use layers::{LayerOptions, Timings, Trace};
pub use nets::{
    EnvMap, EnvMapOutput, Inpaint, InpaintOutput, Irn, IrnOutput, Msn, MsnOutput, Net, NetOutput,
    Tower, MSN_EMBEDDING_CHANNELS,
};
pub use safetensors::Dtype;
pub use save::{
    metadata_for, save_safetensors, serialize_safetensors, write_atomic, NamedTensor, StorageDtype,
    TensorData,
};
pub use weights::{DtypeSummary, TensorInfo, Weights, WeightsPrefix, FORMAT_NAME, FORMAT_VERSION};

#[cfg(test)]
mod tests {
    fn assert_send_sync<T: Send + Sync>() {}

    #[test]
    fn models_are_send_and_sync() {
        assert_send_sync::<crate::Net>();
        assert_send_sync::<crate::Irn>();
        assert_send_sync::<crate::Msn>();
        assert_send_sync::<crate::EnvMap>();
        assert_send_sync::<crate::Inpaint>();
        assert_send_sync::<crate::Weights>();
    }
}
