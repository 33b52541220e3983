//! How visible the wrap seams of a tileable texture are.

use picker_render::io::Image;

/// The seam score of a texture (see [`seam_score`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SeamScore {
    /// Mean absolute difference across the wrap edges (last column vs first,
    /// last row vs first), over all channels.
    pub wrap: f64,
    /// Mean absolute difference between horizontally and vertically
    /// neighbouring texels inside the image.
    pub interior: f64,
    /// `wrap / interior` (1 when both are 0): about 1 or less means the
    /// seam is no more visible than any pair of neighbouring texels.
    pub ratio: f64,
}

/// Measures how visible the wrap edges of `img` are when it is tiled.
pub fn seam_score(img: &Image) -> SeamScore {
    let (h, w) = (img.height, img.width);
    let (mut wrap, mut nw) = (0.0f64, 0usize);
    let (mut inside, mut ni) = (0.0f64, 0usize);
    for c in 0..img.channels {
        let p = img.plane(c);
        for r in 0..h {
            let row = &p[r * w..(r + 1) * w];
            for x in 0..w.saturating_sub(1) {
                inside += (row[x + 1] - row[x]).abs() as f64;
                ni += 1;
            }
            if w > 1 {
                wrap += (row[0] - row[w - 1]).abs() as f64;
                nw += 1;
            }
        }
        for r in 0..h.saturating_sub(1) {
            for x in 0..w {
                inside += (p[(r + 1) * w + x] - p[r * w + x]).abs() as f64;
                ni += 1;
            }
        }
        if h > 1 {
            for x in 0..w {
                wrap += (p[x] - p[(h - 1) * w + x]).abs() as f64;
                nw += 1;
            }
        }
    }
    let wrap = if nw > 0 { wrap / nw as f64 } else { 0.0 };
    let interior = if ni > 0 { inside / ni as f64 } else { 0.0 };
    let ratio = if interior > 0.0 {
        wrap / interior
    } else if wrap > 0.0 {
        f64::INFINITY
    } else {
        1.0
    };
    SeamScore {
        wrap,
        interior,
        ratio,
    }
}
