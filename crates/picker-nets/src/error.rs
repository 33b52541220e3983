//! The error type of this crate. Every variant about a weights file names the file.

use std::path::PathBuf;

use crate::config::NetKind;

/// The dtypes accepted for weights (converted to f32 at load).
pub const ACCEPTED_DTYPES: &str = "F32, F16 or BF16";

/// Everything loading, saving or running a network can refuse.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// The file could not be opened, read, mapped, written or renamed.
    #[error("{}: cannot {op}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// What was being done (`open`, `memory-map`, `write`, ...).
        op: &'static str,
        /// The OS error.
        source: std::io::Error,
    },
    /// The safetensors header is unreadable or inconsistent.
    #[error("{}: not a valid safetensors file: {reason}", path.display())]
    Header {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// The header describes more data than the file holds.
    #[error(
        "{}: file is truncated: its header describes {expected} bytes but the file has {found} \
         (incomplete download or copy?)",
        path.display()
    )]
    Truncated {
        /// The file.
        path: PathBuf,
        /// Bytes the header describes.
        expected: u64,
        /// Bytes in the file.
        found: u64,
    },
    /// A required `__metadata__` key is absent.
    #[error(
        "{}: metadata key {key:?} is missing; Material Picker weights need \
         format, format_version, net and config (see weights-format.md)",
        path.display()
    )]
    MissingMetadata {
        /// The file.
        path: PathBuf,
        /// The key.
        key: &'static str,
    },
    /// A `__metadata__` value is invalid.
    #[error("{}: metadata {key:?}: {reason}", path.display())]
    InvalidMetadata {
        /// The file.
        path: PathBuf,
        /// The key.
        key: String,
        /// What is wrong.
        reason: String,
    },
    /// The file's `format_version` is not one this build reads.
    #[error(
        "{}: unsupported format_version {found:?}; this build of picker-nets reads version {supported:?}",
        path.display()
    )]
    UnsupportedVersion {
        /// The file.
        path: PathBuf,
        /// The version in the file.
        found: String,
        /// The version this build reads.
        supported: &'static str,
    },
    /// The file holds a different network than the one asked for.
    #[error("{}: file holds {found} weights, but {expected} weights were asked for", path.display())]
    NetMismatch {
        /// The file.
        path: PathBuf,
        /// The network asked for.
        expected: NetKind,
        /// The network in the file.
        found: NetKind,
    },
    /// The file's configuration differs from the one asked for.
    #[error("{}: config mismatch: expected {expected}, file has {found}", path.display())]
    ConfigMismatch {
        /// The file.
        path: PathBuf,
        /// The configuration (or preset) asked for, as JSON.
        expected: String,
        /// The file's configuration, as JSON.
        found: String,
    },
    /// A tensor the network needs is absent.
    #[error("{}: missing tensor {key:?} (expected shape {expected:?}){hint}", path.display())]
    MissingTensor {
        /// The file.
        path: PathBuf,
        /// The full state_dict key.
        key: String,
        /// The shape the network needs.
        expected: Vec<usize>,
        /// Extra advice (may be empty; starts with `; ` otherwise).
        hint: String,
    },
    /// Tensors in the file that the network does not use.
    #[error(
        "{}: {count} unused tensor(s) not part of the network: {}{hint}",
        path.display(),
        keys.join(", ")
    )]
    UnusedTensors {
        /// The file.
        path: PathBuf,
        /// Number of unused tensors.
        count: usize,
        /// The first few unused keys.
        keys: Vec<String>,
        /// Extra advice (may be empty; starts with `; ` otherwise).
        hint: String,
    },
    /// A tensor has the wrong shape.
    #[error("{}: tensor {key:?} has shape {found:?}, expected {expected:?}", path.display())]
    ShapeMismatch {
        /// The file.
        path: PathBuf,
        /// The full key.
        key: String,
        /// The shape the network needs.
        expected: Vec<usize>,
        /// The shape in the file.
        found: Vec<usize>,
    },
    /// A tensor is stored in a dtype that is not accepted.
    #[error("{}: tensor {key:?} has dtype {found}; accepted: {accepted}", path.display())]
    Dtype {
        /// The file.
        path: PathBuf,
        /// The full key.
        key: String,
        /// The dtype in the file.
        found: String,
        /// The accepted dtypes.
        accepted: &'static str,
    },
    /// A weight is NaN or infinite.
    #[error("{}: tensor {key:?} holds a non-finite value ({value}) at flat index {index}", path.display())]
    NonFinite {
        /// The file.
        path: PathBuf,
        /// The full key.
        key: String,
        /// Flat index of the first bad value.
        index: usize,
        /// The value.
        value: f32,
    },
    /// A tensor's values cannot be used (e.g. a negative BatchNorm running variance).
    #[error("{}: tensor {key:?}: {reason}", path.display())]
    InvalidTensor {
        /// The file.
        path: PathBuf,
        /// The full key.
        key: String,
        /// What is wrong.
        reason: String,
    },
    /// A configuration built in code (or parsed from JSON) is invalid.
    #[error("invalid network config: {reason}")]
    InvalidConfig {
        /// What is wrong.
        reason: String,
    },
    /// A preset name this crate does not know.
    #[error("unknown {kind} preset {name:?}; known presets: thesis, tiny")]
    UnknownPreset {
        /// The network.
        kind: NetKind,
        /// The name asked for.
        name: String,
    },
    /// A network name other than `irn`, `msn`, `envmap`, `inpaint`.
    #[error("unknown network {found:?}; expected irn, msn, envmap or inpaint")]
    UnknownNet {
        /// The name given.
        found: String,
    },
    /// An input tensor the network cannot run on.
    #[error("invalid network input: {reason}")]
    Input {
        /// What is wrong.
        reason: String,
    },
    /// A tensor handed to a decoder lacks a head or has the wrong channel count.
    #[error("missing or malformed output {name:?}: {reason}")]
    Output {
        /// The output (head) name.
        name: String,
        /// What is wrong.
        reason: String,
    },
    /// A kernel refused its operands (a bug if reached through a loaded network).
    #[error("kernel error: {0}")]
    Kernel(#[from] picker_tensor::Error),
}

/// `Result` with this crate's [`Error`].
pub type Result<T> = std::result::Result<T, Error>;
