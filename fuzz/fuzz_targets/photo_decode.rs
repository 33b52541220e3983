//! Fuzzes photo decoding: arbitrary bytes as an image file.
//!
//! `picker_extract::photo::decode` must return a photo within the limits, with
//! values in `[0, 1]`, or an error whose message is one line naming the file;
//! never panic, abort or allocate past the limits.
#![no_main]

use std::path::Path;

use libfuzzer_sys::fuzz_target;
use picker_extract::photo::{decode, PhotoLimits};

const LABEL: &str = "fuzz.img";
const LIMITS: PhotoLimits = PhotoLimits {
    max_pixels: 4_000_000,
    max_alloc: 256 << 20,
};

fuzz_target!(|data: &[u8]| {
    match decode(data, Path::new(LABEL), &LIMITS) {
        Ok(photo) => {
            let (w, h) = photo.rgb.dimensions();
            assert!(w >= 1 && h >= 1, "empty photo {w}x{h}");
            assert!(u64::from(w) * u64::from(h) <= LIMITS.max_pixels);
            if let Some(v) = photo.rgb.iter().find(|v| !(0.0..=1.0).contains(*v)) {
                panic!("value {v} outside [0, 1] in a {} photo", photo.format);
            }
        }
        Err(e) => {
            let msg = e.to_string();
            assert!(msg.contains(LABEL), "message does not name the file: {msg}");
            // regressions/photo_decode/jpeg_error_message_newline.jpg once ended in a newline.
            assert!(!msg.contains('\n'), "message is not one line: {msg:?}");
        }
    }
});
