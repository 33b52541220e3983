//! The error type of `picker-render`.

use std::path::PathBuf;

/// Everything that can go wrong in `picker-render`; every I/O error names its file.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// Reading, writing or creating a file or directory failed.
    #[error("{path}: cannot {op}: {source}")]
    Io {
        /// The file or directory.
        path: PathBuf,
        /// What was being done (`read`, `write`, ...).
        op: &'static str,
        /// The OS error.
        source: std::io::Error,
    },
    /// A file could not be decoded (bad EXR, PNG or HDR data, unsupported layout).
    #[error("{path}: cannot decode: {reason}")]
    Decode {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// Encoding an image in memory failed.
    #[error("encoding {format}: {reason}")]
    Encode {
        /// `EXR`, `PNG` or `HDR`.
        format: &'static str,
        /// What went wrong.
        reason: String,
    },
    /// Image or map dimensions do not fit together.
    #[error("{what}: expected {expected}, found {found}")]
    Shape {
        /// What was checked (names the file where there is one).
        what: String,
        /// The expected size or channel count.
        expected: String,
        /// What was found.
        found: String,
    },
    /// A parameter is out of range (a zero size, a negative exponent, ...).
    #[error("invalid {what}: {reason}")]
    Invalid {
        /// The parameter.
        what: &'static str,
        /// Why it is refused.
        reason: String,
    },
}

/// `Result` with [`Error`].
pub type Result<T> = std::result::Result<T, Error>;

impl Error {
    /// An [`Error::Io`] for `path`.
    pub(crate) fn io(path: impl Into<PathBuf>, op: &'static str, source: std::io::Error) -> Self {
        Error::Io {
            path: path.into(),
            op,
            source,
        }
    }

    /// An [`Error::Decode`] for `path`.
    pub(crate) fn decode(path: impl Into<PathBuf>, reason: impl ToString) -> Self {
        Error::Decode {
            path: path.into(),
            reason: reason.to_string(),
        }
    }

    /// An [`Error::Shape`].
    pub(crate) fn shape(
        what: impl Into<String>,
        expected: impl ToString,
        found: impl ToString,
    ) -> Self {
        Error::Shape {
            what: what.into(),
            expected: expected.to_string(),
            found: found.to_string(),
        }
    }
}

impl From<picker_nets::Error> for Error {
    fn from(e: picker_nets::Error) -> Self {
        match e {
            picker_nets::Error::Io { path, op, source } => Error::Io { path, op, source },
            other => Error::Io {
                path: PathBuf::new(),
                op: "write",
                source: std::io::Error::other(other.to_string()),
            },
        }
    }
}
