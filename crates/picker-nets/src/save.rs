//! Writing weights files: named tensors, metadata, atomic save.

use std::borrow::Cow;
use std::collections::{BTreeMap, HashMap};
use std::io::Write;
use std::path::{Path, PathBuf};

use safetensors::Dtype;

use crate::config::{NetConfig, KNOWN_PRESETS};
use crate::error::{Error, Result};
use crate::weights::{FORMAT_NAME, FORMAT_VERSION};

/// The values of a [`NamedTensor`].
#[derive(Clone, Debug, PartialEq)]
pub enum TensorData {
    /// Floating-point values, written in the [`StorageDtype`] chosen at save time.
    F32(Vec<f32>),
    /// 64-bit integers, always written as `I64` (BatchNorm `num_batches_tracked`).
    I64(Vec<i64>),
}

impl TensorData {
    /// Number of elements.
    pub fn len(&self) -> usize {
        match self {
            TensorData::F32(v) => v.len(),
            TensorData::I64(v) => v.len(),
        }
    }
    /// True when there are no elements.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// The float values, if this is float data.
    pub fn as_f32(&self) -> Option<&[f32]> {
        match self {
            TensorData::F32(v) => Some(v),
            TensorData::I64(_) => None,
        }
    }
}

/// One tensor of a state dict: key, shape (PyTorch order) and values.
#[derive(Clone, Debug, PartialEq)]
pub struct NamedTensor {
    /// The state_dict key, e.g. `enc.conv_in.conv.weight`.
    pub name: String,
    /// The shape; `[]` for a scalar.
    pub shape: Vec<usize>,
    /// The values, row-major.
    pub data: TensorData,
}

impl NamedTensor {
    /// A float tensor.
    pub fn f32(name: impl Into<String>, shape: Vec<usize>, values: Vec<f32>) -> Self {
        Self {
            name: name.into(),
            shape,
            data: TensorData::F32(values),
        }
    }
    /// An I64 tensor.
    pub fn i64(name: impl Into<String>, shape: Vec<usize>, values: Vec<i64>) -> Self {
        Self {
            name: name.into(),
            shape,
            data: TensorData::I64(values),
        }
    }
}

/// How float tensors are stored in a written file.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum StorageDtype {
    /// 32-bit IEEE float (exact).
    #[default]
    F32,
    /// 16-bit IEEE half (round to nearest even).
    F16,
    /// bfloat16 (round to nearest even).
    BF16,
}

impl StorageDtype {
    /// The safetensors dtype.
    pub fn dtype(self) -> Dtype {
        match self {
            StorageDtype::F32 => Dtype::F32,
            StorageDtype::F16 => Dtype::F16,
            StorageDtype::BF16 => Dtype::BF16,
        }
    }
    /// Parses `f32`, `f16` or `bf16` (any case).
    pub fn parse(s: &str) -> Option<Self> {
        match s.to_ascii_lowercase().as_str() {
            "f32" | "float32" => Some(StorageDtype::F32),
            "f16" | "float16" | "half" => Some(StorageDtype::F16),
            "bf16" | "bfloat16" => Some(StorageDtype::BF16),
            _ => None,
        }
    }
    /// `value` rounded to this storage type and back (what a reader will see).
    pub fn round(self, value: f32) -> f32 {
        match self {
            StorageDtype::F32 => value,
            StorageDtype::F16 => half::f16::from_f32(value).to_f32(),
            StorageDtype::BF16 => half::bf16::from_f32(value).to_f32(),
        }
    }
}

struct Encoded {
    dtype: Dtype,
    shape: Vec<usize>,
    bytes: Vec<u8>,
}

impl safetensors::View for &Encoded {
    fn dtype(&self) -> Dtype {
        self.dtype
    }
    fn shape(&self) -> &[usize] {
        &self.shape
    }
    fn data(&self) -> Cow<'_, [u8]> {
        Cow::Borrowed(&self.bytes)
    }
    fn data_len(&self) -> usize {
        self.bytes.len()
    }
}

fn encode(t: &NamedTensor, dtype: StorageDtype) -> Encoded {
    let (dt, bytes) = match (&t.data, dtype) {
        (TensorData::I64(v), _) => (Dtype::I64, v.iter().flat_map(|x| x.to_le_bytes()).collect()),
        (TensorData::F32(v), StorageDtype::F32) => {
            (Dtype::F32, v.iter().flat_map(|x| x.to_le_bytes()).collect())
        }
        (TensorData::F32(v), StorageDtype::F16) => (
            Dtype::F16,
            v.iter()
                .flat_map(|&x| half::f16::from_f32(x).to_le_bytes())
                .collect(),
        ),
        (TensorData::F32(v), StorageDtype::BF16) => (
            Dtype::BF16,
            v.iter()
                .flat_map(|&x| half::bf16::from_f32(x).to_le_bytes())
                .collect(),
        ),
    };
    Encoded {
        dtype: dt,
        shape: t.shape.clone(),
        bytes,
    }
}

/// The whole safetensors file for `tensors` and `metadata` as bytes (float tensors in `dtype`).
/// `path` only names the destination in errors.
pub fn serialize_safetensors(
    path: &Path,
    tensors: &[NamedTensor],
    metadata: &BTreeMap<String, String>,
    dtype: StorageDtype,
) -> Result<Vec<u8>> {
    let invalid = |reason: String| Error::Header {
        path: path.to_path_buf(),
        reason,
    };
    let mut seen = std::collections::BTreeSet::new();
    for t in tensors {
        let n: usize = t.shape.iter().product();
        if n != t.data.len() {
            return Err(invalid(format!(
                "cannot write tensor {:?}: shape {:?} needs {n} values, got {}",
                t.name,
                t.shape,
                t.data.len()
            )));
        }
        if !seen.insert(t.name.as_str()) {
            return Err(invalid(format!("cannot write tensor {:?} twice", t.name)));
        }
    }
    let encoded: Vec<(String, Encoded)> = tensors
        .iter()
        .map(|t| (t.name.clone(), encode(t, dtype)))
        .collect();
    let meta: HashMap<String, String> = metadata
        .iter()
        .map(|(k, v)| (k.clone(), v.clone()))
        .collect();
    let bytes = safetensors::serialize(encoded.iter().map(|(k, e)| (k.as_str(), e)), &Some(meta))
        .map_err(|e| invalid(format!("cannot serialise: {e:?}")))?;
    canonical_header(bytes).map_err(invalid)
}

/// Rewrites the JSON header of a serialised safetensors file with its keys
/// sorted (the `safetensors` crate takes metadata as a `HashMap`, whose order
/// changes from run to run), padded with spaces to the original length so the
/// data offsets stay valid: the same tensors and metadata give the same bytes.
fn canonical_header(mut bytes: Vec<u8>) -> std::result::Result<Vec<u8>, String> {
    let len_bytes: [u8; 8] = bytes
        .get(..8)
        .and_then(|b| b.try_into().ok())
        .ok_or("serialised file shorter than its length prefix")?;
    let n = u64::from_le_bytes(len_bytes) as usize;
    let header = bytes
        .get(8..8 + n)
        .ok_or("serialised header runs past the end")?;
    // serde_json's map is a BTreeMap (no `preserve_order`), so this sorts every object.
    let value: serde_json::Value = serde_json::from_slice(header)
        .map_err(|e| format!("serialised header is not JSON: {e}"))?;
    let mut sorted = serde_json::to_vec(&value).map_err(|e| e.to_string())?;
    if sorted.len() > n {
        return Err(format!(
            "sorted header grew from {n} to {} bytes",
            sorted.len()
        ));
    }
    sorted.resize(n, b' ');
    bytes[8..8 + n].copy_from_slice(&sorted);
    Ok(bytes)
}

/// Writes a safetensors file atomically: the bytes go to a temporary file in
/// the same directory, which is flushed to disk and renamed over `path`; on any
/// error the temporary file is removed and `path` is left as it was.
pub fn save_safetensors(
    path: impl AsRef<Path>,
    tensors: &[NamedTensor],
    metadata: &BTreeMap<String, String>,
    dtype: StorageDtype,
) -> Result<()> {
    let path = path.as_ref();
    let bytes = serialize_safetensors(path, tensors, metadata, dtype)?;
    write_atomic(path, &bytes)
}

/// Writes `bytes` to `path` atomically (temporary file in the same directory, fsync, rename).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let io = |op, source| Error::Io {
        path: path.to_path_buf(),
        op,
        source,
    };
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let file_name = path
        .file_name()
        .ok_or_else(|| {
            io(
                "write",
                std::io::Error::new(std::io::ErrorKind::InvalidInput, "path has no file name"),
            )
        })?
        .to_string_lossy()
        .into_owned();
    let tmp = dir.join(format!(".{file_name}.tmp-{}", std::process::id()));
    let result = (|| {
        let mut f =
            std::fs::File::create(&tmp).map_err(|e| io("create a temporary file beside", e))?;
        f.write_all(bytes).map_err(|e| io("write", e))?;
        f.sync_all().map_err(|e| io("flush to disk", e))?;
        drop(f);
        std::fs::rename(&tmp, path).map_err(|e| {
            io(
                "put the written file in place (renaming its temporary file)",
                e,
            )
        })?;
        // Make the rename durable where the platform allows syncing a directory.
        if let Ok(d) = std::fs::File::open(&dir) {
            let _ = d.sync_all();
        }
        Ok(())
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

/// The `__metadata__` of a weights file for `config`: `format`, `format_version`,
/// `net`, `preset`, `config` and `created_by`. `preset` is free-form (`lite`,
/// `custom`, ...), but naming a known preset of the net (`thesis`, `lite`, `tiny`) whose configuration
/// differs is refused, as the loader would refuse the file.
pub fn metadata_for(config: &NetConfig, preset: &str) -> Result<BTreeMap<String, String>> {
    config.validate()?;
    if KNOWN_PRESETS.contains(&preset)
        && NetConfig::preset(config.kind(), preset).is_ok_and(|p| p != *config)
    {
        return Err(Error::InvalidConfig {
            reason: format!(
                "preset label {preset:?} given for a config that differs from that preset; use \"custom\""
            ),
        });
    }
    let mut m = BTreeMap::new();
    m.insert("format".to_string(), FORMAT_NAME.to_string());
    m.insert("format_version".to_string(), FORMAT_VERSION.to_string());
    m.insert("net".to_string(), config.kind().as_str().to_string());
    m.insert("preset".to_string(), preset.to_string());
    m.insert("config".to_string(), config.to_json());
    m.insert(
        "created_by".to_string(),
        format!("picker-nets {}", env!("CARGO_PKG_VERSION")),
    );
    Ok(m)
}

#[cfg(test)]
mod canonical_tests {
    use super::*;
    use crate::{random_weights, NetConfig, NetKind, Weights};

    #[test]
    fn same_tensors_and_metadata_give_the_same_bytes() {
        let cfg = NetConfig::preset(NetKind::EnvMap, "tiny").unwrap();
        let tensors = random_weights(&cfg, 3);
        let mut meta = metadata_for(&cfg, "tiny").unwrap();
        for i in 0..12 {
            meta.insert(format!("extra.{i}"), format!("value {i}"));
        }
        let path = Path::new("memory");
        let first = serialize_safetensors(path, &tensors, &meta, StorageDtype::F16).unwrap();
        // Each call builds a fresh HashMap with its own random order.
        for _ in 0..8 {
            let again = serialize_safetensors(path, &tensors, &meta, StorageDtype::F16).unwrap();
            assert!(again == first, "serialisation is not byte-stable");
        }
        let w = Weights::from_bytes("memory", first).unwrap();
        assert_eq!(
            w.metadata().get("extra.7").map(String::as_str),
            Some("value 7")
        );
    }
}
