//! The error type of the kernels crate.

/// Everything a kernel can refuse.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// A tensor's data length does not match the product of its shape.
    #[error("tensor data has {found} elements but shape {shape:?} needs {expected}")]
    DataLength {
        /// The shape given.
        shape: [usize; 4],
        /// Elements the shape needs.
        expected: usize,
        /// Elements supplied.
        found: usize,
    },
    /// An operand has the wrong shape for an op.
    #[error("{op}: {what}: expected {expected}, found {found}")]
    Shape {
        /// The op that refused.
        op: &'static str,
        /// Which operand or dimension.
        what: String,
        /// What was expected.
        expected: String,
        /// What was found.
        found: String,
    },
    /// Parameters that describe no valid op (zero kernel, zero stride, pad too large...).
    #[error("{op}: invalid parameters: {why}")]
    InvalidParams {
        /// The op that refused.
        op: &'static str,
        /// Why.
        why: String,
    },
}

/// `Result` with this crate's [`Error`].
pub type Result<T> = std::result::Result<T, Error>;

pub(crate) fn shape_err(
    op: &'static str,
    what: impl Into<String>,
    expected: impl std::fmt::Display,
    found: impl std::fmt::Display,
) -> Error {
    Error::Shape {
        op,
        what: what.into(),
        expected: expected.to_string(),
        found: found.to_string(),
    }
}

pub(crate) fn invalid(op: &'static str, why: impl Into<String>) -> Error {
    Error::InvalidParams {
        op,
        why: why.into(),
    }
}
