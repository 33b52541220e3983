//! Reading weights: a memory-mapped safetensors file with Material Picker
//! metadata, read strictly through prefix-scoped accessors.
//!
//! [`Weights::open`] checks the header and the metadata (format, version, net,
//! config). Models then read tensors by their PyTorch `state_dict` key through
//! [`Weights::pp`] / [`WeightsPrefix::get`], which check shape and dtype and
//! record the key; after a model is built, [`Weights::check_all_used`] refuses
//! tensors no layer read (`*.num_batches_tracked` excepted).

use std::collections::{BTreeMap, BTreeSet};
use std::fmt;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use safetensors::{Dtype, SafeTensorError, SafeTensors};

use crate::config::{NetConfig, NetKind};
use crate::error::{Error, Result, ACCEPTED_DTYPES};

/// The `format` metadata value of Material Picker weights.
pub const FORMAT_NAME: &str = "material-picker";
/// The `format_version` this build reads and writes.
pub const FORMAT_VERSION: &str = "1";
/// Suffix of the BatchNorm batch counters PyTorch stores; accepted (I64, shape `[]`) and ignored.
pub const NUM_BATCHES_TRACKED: &str = "num_batches_tracked";
/// How many unused keys an [`Error::UnusedTensors`] lists.
const UNUSED_LISTED: usize = 12;

enum Storage {
    Mmap(memmap2::Mmap),
    Owned(Vec<u8>),
    Static(&'static [u8]),
}

impl Storage {
    fn bytes(&self) -> &[u8] {
        match self {
            Storage::Mmap(m) => m,
            Storage::Owned(v) => v,
            Storage::Static(s) => s,
        }
    }

    /// Tells the OS that bytes `[start, end)` of a memory-mapped file were
    /// consumed (copied out), so their pages leave the process's resident set
    /// while the network's own copy is built: loading then peaks at about
    /// one copy of the weights, not two. A later read simply faults the pages
    /// in again from the page cache; the contents never change.
    fn release(&self, start: usize, end: usize) {
        #[cfg(unix)]
        if let Storage::Mmap(m) = self {
            if end > start {
                // SAFETY: the mapping is read-only and private, so MADV_DONTNEED
                // only drops clean pages, which read back unchanged.
                let _ = unsafe {
                    m.unchecked_advise_range(memmap2::UncheckedAdvice::DontNeed, start, end - start)
                };
            }
        }
        #[cfg(not(unix))]
        let _ = (start, end);
    }
}

#[derive(Clone, Debug)]
struct Entry {
    dtype: Dtype,
    shape: Vec<usize>,
    /// Byte range in the whole file.
    start: usize,
    end: usize,
}

/// One tensor of a weights file, as listed by [`Weights::tensors`].
#[derive(Clone, Copy, Debug)]
pub struct TensorInfo<'a> {
    /// The state_dict key.
    pub name: &'a str,
    /// Storage dtype.
    pub dtype: Dtype,
    /// Shape.
    pub shape: &'a [usize],
    /// Bytes of data.
    pub bytes: usize,
}

/// Per-dtype totals of a weights file ([`Weights::dtypes`]).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct DtypeSummary {
    /// The dtype's safetensors name (`F32`, `F16`, `BF16`, `I64`, ...).
    pub dtype: String,
    /// Number of tensors.
    pub tensors: usize,
    /// Number of elements.
    pub elements: u64,
    /// Bytes of data.
    pub bytes: u64,
}

/// A Material Picker weights file: safetensors data (memory-mapped when
/// opened from a path) plus its parsed metadata and configuration.
///
/// Reading is strict; see the [module docs](self). `Weights` is `Send + Sync`.
pub struct Weights {
    path: PathBuf,
    storage: Storage,
    tensors: BTreeMap<String, Entry>,
    metadata: BTreeMap<String, String>,
    kind: NetKind,
    config: NetConfig,
    preset: String,
    used: Mutex<BTreeSet<String>>,
}

impl fmt::Debug for Weights {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Weights")
            .field("path", &self.path)
            .field("kind", &self.kind)
            .field("preset", &self.preset)
            .field("tensors", &self.tensors.len())
            .field("file_size", &self.file_size())
            .finish()
    }
}

fn header_err(path: &Path, reason: impl Into<String>) -> Error {
    Error::Header {
        path: path.to_path_buf(),
        reason: reason.into(),
    }
}

fn meta_err(path: &Path, key: &str, reason: impl Into<String>) -> Error {
    Error::InvalidMetadata {
        path: path.to_path_buf(),
        key: key.to_string(),
        reason: reason.into(),
    }
}

/// Explains a safetensors parse failure with a specific, readable reason.
fn diagnose(path: &Path, bytes: &[u8], err: SafeTensorError) -> Error {
    let len = bytes.len() as u64;
    let n = u64::from_le_bytes(bytes[..8].try_into().unwrap_or([0; 8]));
    let header = bytes
        .get(8..)
        .and_then(|b| b.get(..usize::try_from(n).ok()?));
    let raw: Option<BTreeMap<String, serde_json::Value>> = header
        .and_then(|h| std::str::from_utf8(h).ok())
        .and_then(|s| serde_json::from_str(s).ok());
    match err {
        SafeTensorError::HeaderTooLarge | SafeTensorError::InvalidHeaderLength => header_err(
            path,
            format!(
                "the header length field says {n} bytes, but the file has {len} bytes in all \
                 (not a safetensors file, or truncated)"
            ),
        ),
        SafeTensorError::HeaderTooSmall => header_err(
            path,
            format!("file is {len} bytes; a safetensors file starts with an 8-byte header length"),
        ),
        SafeTensorError::InvalidHeader | SafeTensorError::InvalidHeaderStart => {
            header_err(path, "the header is not UTF-8 JSON")
        }
        SafeTensorError::InvalidHeaderDeserialization => {
            let text = header.map(String::from_utf8_lossy).unwrap_or_default();
            match serde_json::from_str::<BTreeMap<String, serde_json::Value>>(&text) {
                Err(e) => header_err(path, format!("the header is not valid JSON: {e}")),
                Ok(map) => {
                    #[derive(serde::Deserialize)]
                    #[serde(deny_unknown_fields)]
                    #[allow(dead_code)]
                    struct Info {
                        dtype: Dtype,
                        shape: Vec<usize>,
                        data_offsets: (usize, usize),
                    }
                    for (k, v) in &map {
                        if k == "__metadata__" {
                            if let Err(e) =
                                serde_json::from_value::<BTreeMap<String, String>>(v.clone())
                            {
                                return header_err(
                                    path,
                                    format!("__metadata__ must map strings to strings: {e}"),
                                );
                            }
                        } else if let Err(e) = serde_json::from_value::<Info>(v.clone()) {
                            return header_err(
                                path,
                                format!("header entry for tensor {k:?} is malformed: {e}"),
                            );
                        }
                    }
                    header_err(
                        path,
                        "the header JSON does not describe safetensors tensors",
                    )
                }
            }
        }
        SafeTensorError::MetadataIncompleteBuffer => {
            let data_end = raw
                .as_ref()
                .map(|m| {
                    m.iter()
                        .filter(|(k, _)| k.as_str() != "__metadata__")
                        .filter_map(|(_, v)| v.get("data_offsets")?.get(1)?.as_u64())
                        .max()
                        .unwrap_or(0)
                })
                .unwrap_or(0);
            let expected = n.saturating_add(8).saturating_add(data_end);
            if expected > len {
                Error::Truncated {
                    path: path.to_path_buf(),
                    expected,
                    found: len,
                }
            } else {
                header_err(
                    path,
                    format!(
                        "{} trailing bytes after the last tensor (header describes {expected} bytes, \
                         file has {len})",
                        len - expected
                    ),
                )
            }
        }
        SafeTensorError::InvalidOffset(name) => header_err(
            path,
            format!("data_offsets of tensor {name:?} overlap another tensor or leave a gap"),
        ),
        SafeTensorError::TensorInvalidInfo => {
            let which = raw
                .as_ref()
                .and_then(|m| {
                    m.iter().find(|(k, v)| {
                        if k.as_str() == "__metadata__" {
                            return false;
                        }
                        let info = || -> Option<bool> {
                            let dt: Dtype = serde_json::from_value(v.get("dtype")?.clone()).ok()?;
                            let shape: Vec<usize> =
                                serde_json::from_value(v.get("shape")?.clone()).ok()?;
                            let o = v.get("data_offsets")?;
                            let (s, e) = (o.get(0)?.as_u64()?, o.get(1)?.as_u64()?);
                            // An overflowing size cannot match either.
                            let n = shape
                                .iter()
                                .try_fold(dt.size(), |a, &d| a.checked_mul(d))
                                .map_or(u64::MAX, |n| n as u64);
                            Some(e.checked_sub(s)? != n)
                        };
                        info().unwrap_or(true)
                    })
                })
                .map(|(k, _)| k.clone())
                .unwrap_or_else(|| "?".to_string());
            header_err(
                path,
                format!("the byte range of tensor {which:?} does not match its dtype and shape"),
            )
        }
        SafeTensorError::ValidationOverflow => {
            header_err(path, "a tensor's shape overflows the address space")
        }
        other => header_err(path, format!("{other:?}")),
    }
}

/// Refuses tensors whose data would end past `usize::MAX` once the header is
/// counted: `SafeTensors::read_metadata` (0.4) adds the header length to the
/// end of the data unchecked, which panics in debug builds
/// (`fixtures/weights/broken/offsets_overflow.safetensors`). Anything else is
/// left to it.
fn check_data_end(path: &Path, bytes: &[u8]) -> Result<()> {
    let n = u64::from_le_bytes(bytes[..8].try_into().unwrap_or([0; 8]));
    // Longer headers are refused by safetensors without being parsed.
    const MAX_HEADER_SIZE: u64 = 100_000_000;
    let Some(header) = usize::try_from(n)
        .ok()
        .filter(|_| n <= MAX_HEADER_SIZE)
        .and_then(|n| bytes.get(8..)?.get(..n))
    else {
        return Ok(());
    };
    let Ok(meta) = serde_json::from_slice::<safetensors::tensor::Metadata>(header) else {
        return Ok(());
    };
    let tensors = meta.tensors();
    let overflowing = tensors
        .iter()
        .filter(|(_, info)| info.data_offsets.1.checked_add(8 + header.len()).is_none())
        .min_by_key(|(name, _)| name.as_str());
    if let Some((name, info)) = overflowing {
        return Err(header_err(
            path,
            format!(
                "the data_offsets of tensor {name:?} end at byte {} of the data, beyond the \
                 end of any file (this one has {} bytes)",
                info.data_offsets.1,
                bytes.len()
            ),
        ));
    }
    Ok(())
}

impl Weights {
    /// Opens and memory-maps a weights file, checking its header and metadata.
    ///
    /// The file must not be modified while the returned value lives (it is
    /// memory-mapped).
    pub fn open(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let io = |op, source| Error::Io {
            path: path.to_path_buf(),
            op,
            source,
        };
        let file = std::fs::File::open(path).map_err(|e| io("open", e))?;
        let meta = file.metadata().map_err(|e| io("stat", e))?;
        if meta.is_dir() {
            return Err(io(
                "open",
                std::io::Error::other("it is a directory, not a weights (.safetensors) file"),
            ));
        }
        let size = meta.len();
        if size < 8 {
            // Mapping an empty file fails on some platforms; say what is wrong instead.
            return Self::parse(path.to_path_buf(), Storage::Owned(vec![0; size as usize]));
        }
        // SAFETY: the map is read-only; the documented contract is that the file is not
        // modified while mapped (as with every memory-mapped model loader).
        let mmap = unsafe { memmap2::Mmap::map(&file) }.map_err(|e| io("memory-map", e))?;
        Self::parse(path.to_path_buf(), Storage::Mmap(mmap))
    }

    /// Reads weights from bytes in memory; `label` stands for the path in messages.
    pub fn from_bytes(label: impl Into<PathBuf>, bytes: Vec<u8>) -> Result<Self> {
        Self::parse(label.into(), Storage::Owned(bytes))
    }

    /// Reads weights embedded in the binary (`include_bytes!`); `label` stands for the path.
    pub fn from_static(label: impl Into<PathBuf>, bytes: &'static [u8]) -> Result<Self> {
        Self::parse(label.into(), Storage::Static(bytes))
    }

    fn parse(path: PathBuf, storage: Storage) -> Result<Self> {
        let bytes = storage.bytes();
        if bytes.len() < 8 {
            return Err(header_err(
                &path,
                format!(
                    "file is {} bytes; a safetensors file starts with an 8-byte header length",
                    bytes.len()
                ),
            ));
        }
        check_data_end(&path, bytes)?;
        let (n, meta) = SafeTensors::read_metadata(bytes).map_err(|e| diagnose(&path, bytes, e))?;
        let base = 8 + n;
        let tensors: BTreeMap<String, Entry> = meta
            .tensors()
            .into_iter()
            .map(|(k, info)| {
                let e = Entry {
                    dtype: info.dtype,
                    shape: info.shape.clone(),
                    start: base + info.data_offsets.0,
                    end: base + info.data_offsets.1,
                };
                (k, e)
            })
            .collect();
        let metadata: BTreeMap<String, String> = meta
            .metadata()
            .as_ref()
            .map(|m| m.iter().map(|(k, v)| (k.clone(), v.clone())).collect())
            .unwrap_or_default();
        let (kind, config, preset) = parse_metadata(&path, &metadata)?;
        Ok(Self {
            path,
            storage,
            tensors,
            metadata,
            kind,
            config,
            preset,
            used: Mutex::new(BTreeSet::new()),
        })
    }

    /// The file's path (or the label given to [`Weights::from_bytes`]).
    pub fn path(&self) -> &Path {
        &self.path
    }
    /// Which network the file holds (metadata `net`).
    pub fn kind(&self) -> NetKind {
        self.kind
    }
    /// The network configuration (metadata `config`), validated.
    pub fn config(&self) -> &NetConfig {
        &self.config
    }
    /// The preset label (metadata `preset`; `custom` when absent).
    pub fn preset(&self) -> &str {
        &self.preset
    }
    /// Every `__metadata__` entry, including free-form ones.
    pub fn metadata(&self) -> &BTreeMap<String, String> {
        &self.metadata
    }
    /// Size of the file in bytes.
    pub fn file_size(&self) -> u64 {
        self.storage.bytes().len() as u64
    }
    /// Every tensor, sorted by key.
    pub fn tensors(&self) -> impl Iterator<Item = TensorInfo<'_>> {
        self.tensors.iter().map(|(k, e)| TensorInfo {
            name: k,
            dtype: e.dtype,
            shape: &e.shape,
            bytes: e.end - e.start,
        })
    }
    /// Number of tensors.
    pub fn len(&self) -> usize {
        self.tensors.len()
    }
    /// True when the file holds no tensors.
    pub fn is_empty(&self) -> bool {
        self.tensors.is_empty()
    }
    /// Totals per storage dtype, sorted by dtype name.
    pub fn dtypes(&self) -> Vec<DtypeSummary> {
        let mut m: BTreeMap<String, DtypeSummary> = BTreeMap::new();
        for e in self.tensors.values() {
            let name = format!("{:?}", e.dtype);
            let s = m.entry(name.clone()).or_insert(DtypeSummary {
                dtype: name,
                tensors: 0,
                elements: 0,
                bytes: 0,
            });
            s.tensors += 1;
            s.elements += e.shape.iter().product::<usize>() as u64;
            s.bytes += (e.end - e.start) as u64;
        }
        m.into_values().collect()
    }

    /// Refuses the file unless it holds a `kind` network.
    pub fn expect_kind(&self, kind: NetKind) -> Result<()> {
        if self.kind != kind {
            return Err(Error::NetMismatch {
                path: self.path.clone(),
                expected: kind,
                found: self.kind,
            });
        }
        Ok(())
    }

    /// Refuses the file unless its configuration equals `expected`.
    pub fn expect_config(&self, expected: &NetConfig) -> Result<()> {
        self.expect_kind(expected.kind())?;
        if &self.config != expected {
            return Err(Error::ConfigMismatch {
                path: self.path.clone(),
                expected: expected.to_json(),
                found: self.config.to_json(),
            });
        }
        Ok(())
    }

    /// Refuses the file unless its configuration is the preset `name` of its kind.
    pub fn expect_preset(&self, name: &str) -> Result<()> {
        let expected = NetConfig::preset(self.kind, name)?;
        self.expect_config(&expected).map_err(|e| match e {
            Error::ConfigMismatch {
                path,
                expected,
                found,
            } => Error::ConfigMismatch {
                path,
                expected: format!("preset {name:?} {expected}"),
                found,
            },
            e => e,
        })
    }

    /// The accessor for keys under `prefix` (`w.pp("heads").pp("normals")`).
    pub fn pp(&self, prefix: impl fmt::Display) -> WeightsPrefix<'_> {
        WeightsPrefix {
            w: self,
            prefix: prefix.to_string(),
        }
    }

    /// The accessor for top-level keys.
    pub fn root(&self) -> WeightsPrefix<'_> {
        WeightsPrefix {
            w: self,
            prefix: String::new(),
        }
    }

    /// Keys read so far.
    pub fn used_keys(&self) -> BTreeSet<String> {
        self.used.lock().map(|u| u.clone()).unwrap_or_default()
    }

    fn mark_used(&self, key: &str) {
        if let Ok(mut u) = self.used.lock() {
            u.insert(key.to_string());
        }
    }

    /// Reads tensor `key`, which must have `shape` and an accepted float dtype,
    /// as f32 values; records the key as used.
    pub fn get(&self, key: &str, shape: &[usize]) -> Result<Vec<f32>> {
        let Some(e) = self.tensors.get(key) else {
            return Err(Error::MissingTensor {
                path: self.path.clone(),
                key: key.to_string(),
                expected: shape.to_vec(),
                hint: self.missing_hint(key),
            });
        };
        if e.shape != shape {
            return Err(Error::ShapeMismatch {
                path: self.path.clone(),
                key: key.to_string(),
                expected: shape.to_vec(),
                found: e.shape.clone(),
            });
        }
        let raw = &self.storage.bytes()[e.start..e.end];
        let values: Vec<f32> = match e.dtype {
            Dtype::F32 => raw
                .chunks_exact(4)
                .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                .collect(),
            Dtype::F16 => raw
                .chunks_exact(2)
                .map(|b| half::f16::from_le_bytes([b[0], b[1]]).to_f32())
                .collect(),
            Dtype::BF16 => raw
                .chunks_exact(2)
                .map(|b| half::bf16::from_le_bytes([b[0], b[1]]).to_f32())
                .collect(),
            other => {
                return Err(Error::Dtype {
                    path: self.path.clone(),
                    key: key.to_string(),
                    found: format!("{other:?}"),
                    accepted: ACCEPTED_DTYPES,
                })
            }
        };
        self.storage.release(e.start, e.end);
        if let Some(index) = values.iter().position(|v| !v.is_finite()) {
            return Err(Error::NonFinite {
                path: self.path.clone(),
                key: key.to_string(),
                index,
                value: values[index],
            });
        }
        self.mark_used(key);
        Ok(values)
    }

    /// True when the file holds tensor `key`.
    pub fn contains(&self, key: &str) -> bool {
        self.tensors.contains_key(key)
    }

    fn missing_hint(&self, key: &str) -> String {
        if let Some(k) = self
            .tensors
            .keys()
            .find(|k| k.ends_with(&format!(".{key}")))
        {
            let prefix = &k[..k.len() - key.len()];
            return format!(
                "; the file has {k:?}: strip the key prefix {prefix:?} when exporting \
                 (e.g. save model.module.state_dict())"
            );
        }
        if let Some(k) = key.strip_suffix(".conv.bias") {
            if !self.config.conv_bias() {
                return String::new();
            }
            return format!(
                "; the config says conv_bias=true but {k:?} has no conv bias (set conv_bias=false?)"
            );
        }
        String::new()
    }

    /// Refuses tensors no layer has read. `P.num_batches_tracked` is accepted when
    /// it is an I64 scalar (shape `[]`) beside a `P.running_mean` that was read.
    pub fn check_all_used(&self) -> Result<()> {
        let used = self.used_keys();
        let mut unused = Vec::new();
        for (k, e) in &self.tensors {
            if used.contains(k) {
                continue;
            }
            if let Some(p) = k.strip_suffix(NUM_BATCHES_TRACKED) {
                if used.contains(&format!("{p}running_mean")) {
                    if e.dtype != Dtype::I64 {
                        return Err(Error::Dtype {
                            path: self.path.clone(),
                            key: k.clone(),
                            found: format!("{:?}", e.dtype),
                            accepted: "I64 (BatchNorm batch counter)",
                        });
                    }
                    if !e.shape.is_empty() {
                        return Err(Error::ShapeMismatch {
                            path: self.path.clone(),
                            key: k.clone(),
                            expected: vec![],
                            found: e.shape.clone(),
                        });
                    }
                    continue;
                }
            }
            unused.push(k.clone());
        }
        if unused.is_empty() {
            return Ok(());
        }
        let mut hint = String::new();
        if !self.config.conv_bias() && unused.iter().any(|k| k.ends_with(".conv.bias")) {
            hint = "; the file has conv biases but its config says conv_bias=false".to_string();
        }
        let count = unused.len();
        unused.truncate(UNUSED_LISTED);
        if count > UNUSED_LISTED {
            unused.push(format!("... ({} more)", count - UNUSED_LISTED));
        }
        Err(Error::UnusedTensors {
            path: self.path.clone(),
            count,
            keys: unused,
            hint,
        })
    }
}

fn parse_metadata(
    path: &Path,
    metadata: &BTreeMap<String, String>,
) -> Result<(NetKind, NetConfig, String)> {
    let get = |key: &'static str| {
        metadata.get(key).ok_or_else(|| Error::MissingMetadata {
            path: path.to_path_buf(),
            key,
        })
    };
    let format = get("format")?;
    if format != FORMAT_NAME {
        return Err(meta_err(
            path,
            "format",
            format!("expected {FORMAT_NAME:?}, found {format:?}"),
        ));
    }
    let version = get("format_version")?;
    if version != FORMAT_VERSION {
        return Err(Error::UnsupportedVersion {
            path: path.to_path_buf(),
            found: version.clone(),
            supported: FORMAT_VERSION,
        });
    }
    let net = get("net")?;
    let kind: NetKind = net.parse().map_err(|_| {
        meta_err(
            path,
            "net",
            format!("expected \"irn\", \"msn\", \"envmap\" or \"inpaint\", found {net:?}"),
        )
    })?;
    let json = get("config")?;
    let config = NetConfig::from_json(kind, json).map_err(|e| match e {
        Error::InvalidConfig { reason } => meta_err(path, "config", reason),
        e => e,
    })?;
    let preset = metadata
        .get("preset")
        .cloned()
        .unwrap_or_else(|| "custom".to_string());
    // A known preset of this net must match its configuration (`lite` has no
    // inpainter, so there it is a free-form label).
    if let Ok(p) = NetConfig::preset(kind, &preset) {
        if p != config {
            return Err(meta_err(
                path,
                "preset",
                format!(
                    "says {preset:?}, but the config differs from that preset \
                     (preset {}, file {}); label such files \"custom\"",
                    p.to_json(),
                    config.to_json()
                ),
            ));
        }
    }
    Ok((kind, config, preset))
}

/// A prefix-scoped view of [`Weights`]: `w.pp("enc").pp("conv_in").get("conv.weight", shape)`
/// reads `enc.conv_in.conv.weight`.
#[derive(Clone)]
pub struct WeightsPrefix<'a> {
    w: &'a Weights,
    prefix: String,
}

impl fmt::Debug for WeightsPrefix<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "WeightsPrefix({:?} in {})",
            self.prefix,
            self.w.path.display()
        )
    }
}

impl<'a> WeightsPrefix<'a> {
    /// The accessor one level down: `prefix.name`.
    pub fn pp(&self, name: impl fmt::Display) -> WeightsPrefix<'a> {
        WeightsPrefix {
            w: self.w,
            prefix: self.key(&name.to_string()),
        }
    }
    /// The full key of `name` under this prefix.
    pub fn key(&self, name: &str) -> String {
        if self.prefix.is_empty() {
            name.to_string()
        } else {
            format!("{}.{name}", self.prefix)
        }
    }
    /// The prefix (`""` at the root).
    pub fn prefix(&self) -> &str {
        &self.prefix
    }
    /// The weights file.
    pub fn weights(&self) -> &'a Weights {
        self.w
    }
    /// Reads `prefix.name` with `shape` ([`Weights::get`]).
    pub fn get(&self, name: &str, shape: &[usize]) -> Result<Vec<f32>> {
        self.w.get(&self.key(name), shape)
    }
    /// True when the file holds `prefix.name`.
    pub fn contains(&self, name: &str) -> bool {
        self.w.contains(&self.key(name))
    }
}
