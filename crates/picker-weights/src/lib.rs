//! The default weights of Material Picker, compiled into the binary.
//!
//! These are the `lite` IRN, MSN and EnvMap of issue 5, trained by `training/`
//! on `picker synth` scenes (the recipe and the metrics are in
//! `docs/model-card.md`; the training metadata is in each file's
//! `__metadata__`, shown by `picker weights inspect --default`). The files are
//! F16 safetensors in the format of `weights-format.md`; they live in
//! `crates/picker-weights/weights/` and are embedded with `include_bytes!`, so
//! a fresh binary needs no download.
//!
//! This crate only holds bytes: parsing and validation are `picker-nets`'
//! (`Weights::from_static`), exactly as for a file given with `--weights`.

#![warn(missing_docs)]

/// One embedded weights file.
#[derive(Clone, Copy, Debug)]
pub struct EmbeddedFile {
    /// The file name (`irn.safetensors`, `msn.safetensors`, `envmap.safetensors`).
    pub file: &'static str,
    /// The whole safetensors file.
    pub bytes: &'static [u8],
}

/// What stands for the folder of the embedded files in messages and manifests:
/// `<embedded lite>/irn.safetensors`, and so on.
pub const LABEL: &str = "<embedded lite>";

/// The embedded files, in network order (IRN, MSN, EnvMap).
pub const FILES: [EmbeddedFile; 3] = [
    EmbeddedFile {
        file: "irn.safetensors",
        bytes: include_bytes!("../weights/irn.safetensors"),
    },
    EmbeddedFile {
        file: "msn.safetensors",
        bytes: include_bytes!("../weights/msn.safetensors"),
    },
    EmbeddedFile {
        file: "envmap.safetensors",
        bytes: include_bytes!("../weights/envmap.safetensors"),
    },
];

/// The label of one embedded file, as shown in messages: `<embedded lite>/FILE`.
pub fn label(file: &EmbeddedFile) -> String {
    format!("{LABEL}/{}", file.file)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_file_is_a_safetensors_file_with_metadata() {
        for f in FILES {
            // An 8-byte little-endian header length, then a JSON header that fits.
            assert!(f.bytes.len() > 8, "{} is too short", f.file);
            let n = u64::from_le_bytes(f.bytes[..8].try_into().unwrap()) as usize;
            assert!(
                8 + n <= f.bytes.len(),
                "{}: header overruns the file",
                f.file
            );
            let header = std::str::from_utf8(&f.bytes[8..8 + n]).unwrap();
            assert!(header.contains("__metadata__"), "{}: no metadata", f.file);
            assert!(
                header.contains("\"lite\""),
                "{}: not the lite preset",
                f.file
            );
        }
    }

    #[test]
    fn labels_name_the_file() {
        assert_eq!(label(&FILES[0]), "<embedded lite>/irn.safetensors");
    }
}
