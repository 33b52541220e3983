//! Material Picker facade crate.
//!
//! Re-exports the workspace crates so the cross-crate tests in `tests/` and the
//! benchmarks in `benches/` have one dependency. See `README.md` for the tour.

pub use picker_nets as nets;
pub use picker_tensor as tensor;
