//! Contact sheets: a grid of scene images, box-filtered down, for a quick look at a run.

use std::path::Path;

use picker_render::io::{self, Image};

use crate::Result;

/// Reads the 8-bit RGB PNGs `paths` (all the same size as the first), shrinks each
/// by the integer factor `shrink` (box filter) and lays them out row by row,
/// `cols` per row, on a black background.
pub fn contact_sheet(paths: &[impl AsRef<Path>], cols: usize, shrink: usize) -> Result<Image> {
    let shrink = shrink.max(1);
    let cols = cols.max(1);
    let mut tiles = Vec::new();
    for p in paths {
        tiles.push(io::read_png(p.as_ref())?);
    }
    let Some(first) = tiles.first() else {
        return Ok(Image::zeros(3, 1, 1));
    };
    let (th, tw) = (first.height / shrink, first.width / shrink);
    let rows = tiles.len().div_ceil(cols);
    let (h, w) = (rows * th, cols.min(tiles.len()) * tw);
    let mut out = Image::zeros(3, h, w);
    for (k, t) in tiles.iter().enumerate() {
        let (oy, ox) = ((k / cols) * th, (k % cols) * tw);
        for c in 0..3 {
            let src = t.plane(c.min(t.channels - 1));
            for y in 0..th.min(t.height / shrink) {
                for x in 0..tw.min(t.width / shrink) {
                    let mut s = 0.0;
                    for dy in 0..shrink {
                        for dx in 0..shrink {
                            s += src[(y * shrink + dy) * t.width + x * shrink + dx];
                        }
                    }
                    out.data[c * h * w + (oy + y) * w + ox + x] = s / (shrink * shrink) as f32;
                }
            }
        }
    }
    Ok(out)
}
