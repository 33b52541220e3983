//! Writing result files: re-exports of `picker_render::io` (the one place that
//! encodes EXR / PNG and writes atomically through `picker_nets::write_atomic`).
//! Its errors name the file and convert into `anyhow::Error` with `?`.

pub use picker_render::io::{encode_exr, encode_png, exr_channel_names, write_atomic};
