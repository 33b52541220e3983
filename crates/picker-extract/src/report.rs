//! Contact sheets for reports: labelled tiles on a grid ([`compose_sheet`]), a
//! pick marker ([`draw_marker`]) and a given quadrilateral's outline
//! ([`draw_polygon`], [`outlined`]).
//!
//! Every image here holds **display values** (sRGB-encoded, `[0, 1]`), with 1
//! (grey) or 3 (RGB) channels; sheets are always RGB. Labels are drawn by a
//! built-in 5×7 bitmap font (printable ASCII `' '..='~'`; any other character
//! is drawn as `?`) scaled ×2, so no font file or dependency is needed.

use picker_render::io::Image;
use rayon::prelude::*;
use std::borrow::Cow;

/// Background of a sheet (display value, neutral dark grey).
pub const SHEET_BACKGROUND: f32 = 0.2;
/// Colour of the labels (display value, white).
pub const LABEL_COLOUR: f32 = 1.0;
/// Margin around and between cells, in pixels.
pub const SHEET_MARGIN: usize = 8;
/// Scale of the 5×7 font (each font pixel is a `FONT_SCALE × FONT_SCALE` block).
pub const FONT_SCALE: usize = 2;
/// Longest label drawn; longer ones are cut.
pub const MAX_LABEL_CHARS: usize = 48;

const GLYPH_W: usize = 5;
const GLYPH_H: usize = 7;
/// Horizontal advance of one character in font pixels (glyph + 1 blank column).
const ADVANCE: usize = GLYPH_W + 1;
/// Height of the label band above each tile: the scaled glyph plus 2 px above and below.
const LABEL_BAND: usize = GLYPH_H * FONT_SCALE + 4;

/// One tile of a sheet.
#[derive(Clone, Debug)]
pub struct Tile {
    /// Text drawn above the tile (printable ASCII; other characters show as `?`).
    pub label: String,
    /// The picture: display-ready sRGB values in `[0, 1]`, 1 or 3 channels
    /// (a 1-channel tile is shown as grey; channels beyond 3 are ignored).
    pub image: Image,
}

/// The classic 5×7 LCD glyphs for ASCII 32..=126: five columns per glyph,
/// left to right, bit 0 of each column byte is the top row.
const FONT_5X7: [[u8; 5]; 95] = [
    [0x00, 0x00, 0x00, 0x00, 0x00], // ' '
    [0x00, 0x00, 0x5f, 0x00, 0x00], // !
    [0x00, 0x07, 0x00, 0x07, 0x00], // "
    [0x14, 0x7f, 0x14, 0x7f, 0x14], // #
    [0x24, 0x2a, 0x7f, 0x2a, 0x12], // $
    [0x23, 0x13, 0x08, 0x64, 0x62], // %
    [0x36, 0x49, 0x55, 0x22, 0x50], // &
    [0x00, 0x05, 0x03, 0x00, 0x00], // '
    [0x00, 0x1c, 0x22, 0x41, 0x00], // (
    [0x00, 0x41, 0x22, 0x1c, 0x00], // )
    [0x14, 0x08, 0x3e, 0x08, 0x14], // *
    [0x08, 0x08, 0x3e, 0x08, 0x08], // +
    [0x00, 0x50, 0x30, 0x00, 0x00], // ,
    [0x08, 0x08, 0x08, 0x08, 0x08], // -
    [0x00, 0x60, 0x60, 0x00, 0x00], // .
    [0x20, 0x10, 0x08, 0x04, 0x02], // /
    [0x3e, 0x51, 0x49, 0x45, 0x3e], // 0
    [0x00, 0x42, 0x7f, 0x40, 0x00], // 1
    [0x42, 0x61, 0x51, 0x49, 0x46], // 2
    [0x21, 0x41, 0x45, 0x4b, 0x31], // 3
    [0x18, 0x14, 0x12, 0x7f, 0x10], // 4
    [0x27, 0x45, 0x45, 0x45, 0x39], // 5
    [0x3c, 0x4a, 0x49, 0x49, 0x30], // 6
    [0x01, 0x71, 0x09, 0x05, 0x03], // 7
    [0x36, 0x49, 0x49, 0x49, 0x36], // 8
    [0x06, 0x49, 0x49, 0x29, 0x1e], // 9
    [0x00, 0x36, 0x36, 0x00, 0x00], // :
    [0x00, 0x56, 0x36, 0x00, 0x00], // ;
    [0x08, 0x14, 0x22, 0x41, 0x00], // <
    [0x14, 0x14, 0x14, 0x14, 0x14], // =
    [0x00, 0x41, 0x22, 0x14, 0x08], // >
    [0x02, 0x01, 0x51, 0x09, 0x06], // ?
    [0x32, 0x49, 0x79, 0x41, 0x3e], // @
    [0x7e, 0x11, 0x11, 0x11, 0x7e], // A
    [0x7f, 0x49, 0x49, 0x49, 0x36], // B
    [0x3e, 0x41, 0x41, 0x41, 0x22], // C
    [0x7f, 0x41, 0x41, 0x22, 0x1c], // D
    [0x7f, 0x49, 0x49, 0x49, 0x41], // E
    [0x7f, 0x09, 0x09, 0x09, 0x01], // F
    [0x3e, 0x41, 0x49, 0x49, 0x7a], // G
    [0x7f, 0x08, 0x08, 0x08, 0x7f], // H
    [0x00, 0x41, 0x7f, 0x41, 0x00], // I
    [0x20, 0x40, 0x41, 0x3f, 0x01], // J
    [0x7f, 0x08, 0x14, 0x22, 0x41], // K
    [0x7f, 0x40, 0x40, 0x40, 0x40], // L
    [0x7f, 0x02, 0x0c, 0x02, 0x7f], // M
    [0x7f, 0x04, 0x08, 0x10, 0x7f], // N
    [0x3e, 0x41, 0x41, 0x41, 0x3e], // O
    [0x7f, 0x09, 0x09, 0x09, 0x06], // P
    [0x3e, 0x41, 0x51, 0x21, 0x5e], // Q
    [0x7f, 0x09, 0x19, 0x29, 0x46], // R
    [0x46, 0x49, 0x49, 0x49, 0x31], // S
    [0x01, 0x01, 0x7f, 0x01, 0x01], // T
    [0x3f, 0x40, 0x40, 0x40, 0x3f], // U
    [0x1f, 0x20, 0x40, 0x20, 0x1f], // V
    [0x3f, 0x40, 0x38, 0x40, 0x3f], // W
    [0x63, 0x14, 0x08, 0x14, 0x63], // X
    [0x07, 0x08, 0x70, 0x08, 0x07], // Y
    [0x61, 0x51, 0x49, 0x45, 0x43], // Z
    [0x00, 0x7f, 0x41, 0x41, 0x00], // [
    [0x02, 0x04, 0x08, 0x10, 0x20], // backslash
    [0x00, 0x41, 0x41, 0x7f, 0x00], // ]
    [0x04, 0x02, 0x01, 0x02, 0x04], // ^
    [0x40, 0x40, 0x40, 0x40, 0x40], // _
    [0x00, 0x01, 0x02, 0x04, 0x00], // `
    [0x20, 0x54, 0x54, 0x54, 0x78], // a
    [0x7f, 0x48, 0x44, 0x44, 0x38], // b
    [0x38, 0x44, 0x44, 0x44, 0x20], // c
    [0x38, 0x44, 0x44, 0x48, 0x7f], // d
    [0x38, 0x54, 0x54, 0x54, 0x18], // e
    [0x08, 0x7e, 0x09, 0x01, 0x02], // f
    [0x0c, 0x52, 0x52, 0x52, 0x3e], // g
    [0x7f, 0x08, 0x04, 0x04, 0x78], // h
    [0x00, 0x44, 0x7d, 0x40, 0x00], // i
    [0x20, 0x40, 0x44, 0x3d, 0x00], // j
    [0x7f, 0x10, 0x28, 0x44, 0x00], // k
    [0x00, 0x41, 0x7f, 0x40, 0x00], // l
    [0x7c, 0x04, 0x18, 0x04, 0x78], // m
    [0x7c, 0x08, 0x04, 0x04, 0x78], // n
    [0x38, 0x44, 0x44, 0x44, 0x38], // o
    [0x7c, 0x14, 0x14, 0x14, 0x08], // p
    [0x08, 0x14, 0x14, 0x18, 0x7c], // q
    [0x7c, 0x08, 0x04, 0x04, 0x08], // r
    [0x48, 0x54, 0x54, 0x54, 0x20], // s
    [0x04, 0x3f, 0x44, 0x40, 0x20], // t
    [0x3c, 0x40, 0x40, 0x20, 0x7c], // u
    [0x1c, 0x20, 0x40, 0x20, 0x1c], // v
    [0x3c, 0x40, 0x30, 0x40, 0x3c], // w
    [0x44, 0x28, 0x10, 0x28, 0x44], // x
    [0x0c, 0x50, 0x50, 0x50, 0x3c], // y
    [0x44, 0x64, 0x54, 0x4c, 0x44], // z
    [0x00, 0x08, 0x36, 0x41, 0x00], // {
    [0x00, 0x00, 0x7f, 0x00, 0x00], // |
    [0x00, 0x41, 0x36, 0x08, 0x00], // }
    [0x10, 0x08, 0x08, 0x10, 0x08], // ~
];

/// The 5×7 glyph of `c` (`?` for anything outside printable ASCII).
fn glyph(c: char) -> &'static [u8; 5] {
    let code = c as u32;
    let index = if (32..=126).contains(&code) {
        (code - 32) as usize
    } else {
        ('?' as u32 - 32) as usize
    };
    &FONT_5X7[index]
}

/// Width in pixels of `text` drawn by [`draw_text`] (at most [`MAX_LABEL_CHARS`] characters).
pub fn text_width(text: &str) -> usize {
    let n = text.chars().take(MAX_LABEL_CHARS).count();
    if n == 0 {
        0
    } else {
        (n * ADVANCE - 1) * FONT_SCALE
    }
}

/// Draws `text` (at most [`MAX_LABEL_CHARS`] characters) into `img` with its
/// top-left corner at pixel `(x, y)` in colour `value` (every channel), in the
/// 5×7 font scaled ×[`FONT_SCALE`]; clipped to the image and to `max_width` pixels.
pub fn draw_text(img: &mut Image, x: usize, y: usize, text: &str, value: f32, max_width: usize) {
    let (w, h, n) = (img.width, img.height, img.plane_len());
    let right = x.saturating_add(max_width).min(w);
    for (k, c) in text.chars().take(MAX_LABEL_CHARS).enumerate() {
        let g = glyph(c);
        let x0 = x + k * ADVANCE * FONT_SCALE;
        if x0 >= right {
            break;
        }
        for (gc, column) in g.iter().enumerate() {
            for gr in 0..GLYPH_H {
                if column >> gr & 1 == 0 {
                    continue;
                }
                for dy in 0..FONT_SCALE {
                    let row = y + gr * FONT_SCALE + dy;
                    if row >= h {
                        continue;
                    }
                    for dx in 0..FONT_SCALE {
                        let col = x0 + gc * FONT_SCALE + dx;
                        if col >= right {
                            continue;
                        }
                        for ch in 0..img.channels {
                            img.data[ch * n + row * w + col] = value;
                        }
                    }
                }
            }
        }
    }
}

/// Widest tile of a sheet, in multiples of its tile height ([`compose_sheet`]).
pub const MAX_TILE_ASPECT: usize = 4;

/// A grid sheet of `tiles`, `columns` per row (clamped to `1..=tiles.len()`),
/// on a neutral background ([`SHEET_BACKGROUND`]), always 3 channels.
///
/// Every tile is resized to `tile_height` rows (at least 1), keeping its
/// aspect ratio (area-average filter when shrinking, bilinear when
/// enlarging), or, if that would make it wider than [`MAX_TILE_ASPECT`]
/// times `tile_height`, to that width (and fewer rows, centred vertically:
/// a 1×4000 photo must not make a sheet millions of pixels wide), and
/// centred in a cell as wide as the widest resized tile or label; its label is drawn above it. A 1-channel tile is expanded to grey.
/// Cells are separated by [`SHEET_MARGIN`] pixels.
///
/// **Empty input** gives an empty `3 × 0 × 0` image (nothing to show; the
/// caller decides whether that is an error). A tile with no pixels leaves
/// its cell blank.
pub fn compose_sheet(tiles: &[Tile], columns: usize, tile_height: usize) -> Image {
    let lazy: Vec<LazyTile<'_>> = tiles
        .iter()
        .map(|t| borrowed_tile(t.label.clone(), &t.image))
        .collect();
    compose_lazy_sheet(&lazy, columns, tile_height)
}

/// A tile whose picture is made only at the size it is shown at: for large
/// pictures (a photo-resolution tile) that need not exist at full size.
pub struct LazyTile<'a> {
    /// Text drawn above the tile (as [`Tile::label`]).
    pub label: String,
    /// Width of the full-size picture (with `height`, sets the aspect ratio).
    pub width: usize,
    /// Height of the full-size picture.
    pub height: usize,
    /// Channels of the picture (1 or 3, as [`Tile::image`]).
    pub channels: usize,
    /// The picture resized to `(rows, columns)`, as [`resize_rows`] (or the
    /// crate's resize of the full-size picture) would make it.
    #[allow(clippy::type_complexity)]
    pub render: Box<dyn Fn(usize, usize) -> Image + Sync + 'a>,
}

impl From<Tile> for LazyTile<'static> {
    /// The tile's picture, resized when shown.
    fn from(t: Tile) -> Self {
        LazyTile {
            label: t.label,
            width: t.image.width,
            height: t.image.height,
            channels: t.image.channels,
            render: Box::new(move |h, w| resize(&t.image, h, w, false)),
        }
    }
}

/// A [`LazyTile`] of a picture that is only borrowed (resized when shown).
pub fn borrowed_tile(label: String, img: &Image) -> LazyTile<'_> {
    LazyTile {
        label,
        width: img.width,
        height: img.height,
        channels: img.channels,
        render: Box::new(move |h, w| resize(img, h, w, false)),
    }
}

/// [`compose_sheet`] of tiles given as [`LazyTile`]s (the same sheet for the
/// same pictures); the tiles are rendered in parallel.
pub fn compose_lazy_sheet(tiles: &[LazyTile<'_>], columns: usize, tile_height: usize) -> Image {
    if tiles.is_empty() {
        return Image::zeros(3, 0, 0);
    }
    let tile_height = tile_height.max(1);
    let columns = columns.clamp(1, tiles.len());
    let rows = tiles.len().div_ceil(columns);
    let max_width = tile_height.saturating_mul(MAX_TILE_ASPECT);
    // (rows, columns) a tile is shown at: `tile_height` rows, or fewer for a
    // picture wider than MAX_TILE_ASPECT, which is fitted to `max_width`.
    let fitted = |t: &LazyTile<'_>| -> (usize, usize) {
        if t.width == 0 || t.height == 0 {
            return (0, 0);
        }
        let w = (t.width as f64 * tile_height as f64 / t.height as f64).round();
        if w <= max_width as f64 {
            (tile_height, (w as usize).max(1))
        } else {
            let h = (t.height as f64 * max_width as f64 / t.width as f64).round() as usize;
            (h.clamp(1, tile_height), max_width)
        }
    };
    let resized_width = |t: &LazyTile<'_>| fitted(t).1;
    let cell_w = tiles
        .iter()
        .map(|t| resized_width(t).max(text_width(&t.label)))
        .max()
        .unwrap_or(0)
        .max(1);
    let cell_h = LABEL_BAND + tile_height;
    let width = SHEET_MARGIN + columns * (cell_w + SHEET_MARGIN);
    let height = SHEET_MARGIN + rows * (cell_h + SHEET_MARGIN);
    let mut sheet = Image {
        channels: 3,
        height,
        width,
        data: vec![SHEET_BACKGROUND; 3 * width * height],
    };
    let n = width * height;
    let smalls: Vec<Option<Image>> = tiles
        .par_iter()
        .map(|t| {
            let (th, tw) = fitted(t);
            (tw != 0 && t.channels != 0).then(|| (t.render)(th, tw))
        })
        .collect();
    for (k, (tile, small)) in tiles.iter().zip(&smalls).enumerate() {
        let x0 = SHEET_MARGIN + (k % columns) * (cell_w + SHEET_MARGIN);
        let y0 = SHEET_MARGIN + (k / columns) * (cell_h + SHEET_MARGIN);
        draw_text(&mut sheet, x0, y0 + 2, &tile.label, LABEL_COLOUR, cell_w);
        let Some(small) = small else {
            continue;
        };
        let (th, tw) = fitted(tile);
        let xoff = x0 + (cell_w - tw) / 2;
        let yoff = y0 + LABEL_BAND + (tile_height - th) / 2;
        for ch in 0..3 {
            let src = small.plane(ch.min(small.channels - 1));
            for r in 0..th {
                let dst = ch * n + (yoff + r) * width + xoff;
                sheet.data[dst..dst + tw].copy_from_slice(&src[r * tw..(r + 1) * tw]);
            }
        }
    }
    sheet
}

/// The rows `r0..r1` of an image `h` rows tall that [`draw_marker`] may
/// change (`None`: none), and the marker's outer radius `r`.
fn marker_rows(h: usize, x: f32, y: f32, radius: f32) -> Option<(usize, usize, f32)> {
    if !(x.is_finite() && y.is_finite()) {
        return None;
    }
    let r = if radius.is_finite() {
        radius.max(3.0)
    } else {
        3.0
    };
    let reach = 1.6 * r + 1.75 + 1.0;
    let r0 = ((y - reach).floor().max(0.0)) as usize;
    let r1 = ((y + reach).ceil().max(0.0) as usize).min(h);
    Some((r0, r1, r))
}

/// Draws a pick marker centred on `(x, y)` (pixels, x right, y down, pixel
/// `(row, col)` centred at `(col + 0.5, row + 0.5)`): a ring of radius
/// `radius` (at least 3) and four crosshair arms from `0.4·radius` to
/// `1.6·radius`, white with a black outline, so it is visible on any
/// background. The centre itself is left untouched so the picked pixel stays
/// visible. Works on any channel count; clipped to the image.
pub fn draw_marker(img: &mut Image, x: f32, y: f32, radius: f32) {
    let Some((r0, r1, r)) = marker_rows(img.height, x, y, radius) else {
        return;
    };
    let (w, n) = (img.width, img.plane_len());
    let (gap, arm) = (0.4 * r, 1.6 * r);
    let (inner, outer) = (0.75f32, 1.75f32);
    let reach = arm + outer + 1.0;
    let c0 = ((x - reach).floor().max(0.0)) as usize;
    let c1 = ((x + reach).ceil().max(0.0) as usize).min(w);
    // Distance of a pixel centre to the marker's strokes.
    let stroke_distance = |dx: f32, dy: f32| -> f32 {
        let ring = ((dx * dx + dy * dy).sqrt() - r).abs();
        let along = |a: f32, b: f32| {
            let t = a.abs();
            if t < gap {
                f32::INFINITY
            } else if t <= arm {
                b.abs()
            } else {
                ((t - arm).powi(2) + b * b).sqrt()
            }
        };
        ring.min(along(dx, dy)).min(along(dy, dx))
    };
    for row in r0..r1 {
        for col in c0..c1 {
            let d = stroke_distance(col as f32 + 0.5 - x, row as f32 + 0.5 - y);
            let value = if d <= inner {
                1.0
            } else if d <= outer {
                0.0
            } else {
                continue;
            };
            for ch in 0..img.channels {
                img.data[ch * n + row * w + col] = value;
            }
        }
    }
}

/// A [`LazyTile`] of `img` with a pick marker on it: the image resized to
/// the tile, then [`draw_marker`] at `(x, y)` and `radius` (image pixels)
/// mapped into the tile's pixels, so the marker's strokes are as wide on
/// the sheet whatever the image's size (drawn on a 12-megapixel photo
/// before resizing, they were thinner than a tile pixel and vanished).
/// A tile stretched unevenly takes the radius along its width.
pub fn marked_tile(label: String, img: &Image, x: f32, y: f32, radius: f32) -> LazyTile<'_> {
    let (c, h, w) = (img.channels, img.height, img.width);
    LazyTile {
        label,
        width: w,
        height: h,
        channels: c,
        render: Box::new(move |th, tw| {
            let mut tile = resize(img, th, tw, false);
            let (sx, sy) = (tw as f32 / w.max(1) as f32, th as f32 / h.max(1) as f32);
            draw_marker(&mut tile, x * sx, y * sy, radius * sx);
            tile
        }),
    }
}

/// Draws the closed polygon through `points` (pixels, as [`draw_marker`])
/// on `img`: every pixel whose centre is within 0.75 px of a side white
/// (1.0 in each channel), those within 1.75 px and not white black, so the
/// outline shows on any background. Sides with a point that is not finite
/// are left out; clipped to the image. Works on any channel count.
pub fn draw_polygon(img: &mut Image, points: &[[f32; 2]]) {
    let (h, w, n) = (img.height, img.width, img.plane_len());
    if points.len() < 2 || w == 0 || h == 0 {
        return;
    }
    let (inner, outer) = (0.75f32, 1.75f32);
    // 0: untouched, 1: outline, 2: line.
    let mut ink = vec![0u8; w * h];
    for k in 0..points.len() {
        let (a, b) = (points[k], points[(k + 1) % points.len()]);
        if !a.iter().chain(&b).all(|v| v.is_finite()) {
            continue;
        }
        let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
        let len2 = dx * dx + dy * dy;
        let lo = |u: f32, v: f32| (u.min(v) - outer - 1.0).floor().max(0.0) as usize;
        let hi =
            |u: f32, v: f32, n: usize| ((u.max(v) + outer + 1.0).ceil().max(0.0) as usize).min(n);
        for y in lo(a[1], b[1]).min(h)..hi(a[1], b[1], h) {
            for x in lo(a[0], b[0]).min(w)..hi(a[0], b[0], w) {
                let (px, py) = (x as f32 + 0.5 - a[0], y as f32 + 0.5 - a[1]);
                let t = if len2 > 0.0 {
                    ((px * dx + py * dy) / len2).clamp(0.0, 1.0)
                } else {
                    0.0
                };
                let d = (px - t * dx).hypot(py - t * dy);
                let i = y * w + x;
                if d <= inner {
                    ink[i] = 2;
                } else if d <= outer {
                    ink[i] = ink[i].max(1);
                }
            }
        }
    }
    for (i, &k) in ink.iter().enumerate() {
        if k > 0 {
            let v = if k == 2 { 1.0 } else { 0.0 };
            for c in 0..img.channels {
                img.data[c * n + i] = v;
            }
        }
    }
}

/// `tile` with the closed polygon `points` (pixels of the full-size
/// picture, as [`draw_marker`]) drawn over each rendering at its size
/// ([`draw_polygon`] with the points scaled to it), so the outline is as
/// thin on a 12-megapixel photo's tile as on a small one's.
pub fn outlined(tile: LazyTile<'_>, points: Vec<[f32; 2]>) -> LazyTile<'_> {
    let (w, h) = (tile.width.max(1) as f32, tile.height.max(1) as f32);
    let inner = tile.render;
    LazyTile {
        render: Box::new(move |th, tw| {
            let mut img = inner(th, tw);
            let (sx, sy) = (tw as f32 / w, th as f32 / h);
            let scaled: Vec<[f32; 2]> = points.iter().map(|p| [p[0] * sx, p[1] * sy]).collect();
            draw_polygon(&mut img, &scaled);
            img
        }),
        ..tile
    }
}

/// Share of a pixel's own colour kept outside the mask by [`dimmed_tile`]
/// (the rest is its grey), so the masked part stands out by colour as well
/// as by brightness, also in dark photos.
pub const DIM_SATURATION: f32 = 0.3;

/// Blue added outside the mask by [`dimmed_tile`] (display value), so that
/// dimmed black and masked black differ.
pub const DIM_TINT: f32 = 0.06;

/// The colour [`dimmed_tile`] shows for channel `ch` of a pixel outside the
/// mask: the pixel desaturated to [`DIM_SATURATION`] (grey = Rec. 709 weights
/// of the displayed RGB), times `factor`, plus [`DIM_TINT`] in blue. One- or
/// two-channel images are only multiplied by `factor`.
fn dimmed_value(img: &Image, ch: usize, i: usize, factor: f32) -> f32 {
    let v = img.plane(ch)[i];
    if img.channels < 3 {
        return v * factor;
    }
    let grey = 0.2126 * img.plane(0)[i] + 0.7152 * img.plane(1)[i] + 0.0722 * img.plane(2)[i];
    let tint = if ch == 2 { DIM_TINT } else { 0.0 };
    factor * (DIM_SATURATION * v + (1.0 - DIM_SATURATION) * grey) + tint
}

/// A [`LazyTile`] of `img` (display values) with every pixel outside `mask` (a
/// plane of the image's size; outside: `≤ 0.5`) dimmed by `factor`,
/// desaturated and tinted blue ([`DIM_SATURATION`], [`DIM_TINT`]), computed
/// row by row instead of as a copy of the image.
pub fn dimmed_tile<'a>(
    label: String,
    img: &'a Image,
    mask: &'a [f32],
    factor: f32,
) -> LazyTile<'a> {
    let (c, h, w) = (img.channels, img.height, img.width);
    assert_eq!(mask.len(), h * w, "mask size");
    LazyTile {
        label,
        width: w,
        height: h,
        channels: c,
        render: Box::new(move |th, tw| {
            resize_rows((c, h, w), th, tw, false, |ch, r, out| {
                let src = &img.plane(ch)[r * w..(r + 1) * w];
                let row = &mask[r * w..(r + 1) * w];
                for (x, ((o, &v), &m)) in out.iter_mut().zip(src).zip(row).enumerate() {
                    *o = if m <= 0.5 {
                        dimmed_value(img, ch, r * w + x, factor)
                    } else {
                        v
                    };
                }
            })
        }),
    }
}

/// A [`LazyTile`] of `img` repeated `k × k` times, made row by row.
///
/// # Panics
/// When `k` times the image's size overflows `usize`.
pub fn tiled_tile(label: String, img: Image, k: usize) -> LazyTile<'static> {
    tiling(label, Cow::Owned(img), k, None)
}

/// A [`LazyTile`] of `img` with `map` applied to every value, repeated
/// `k × k` times (1: once), made row by row: the same tile as the mapped,
/// tiled picture resized ([`LazyTile::from`] of it), without that picture
/// ever existing (a 8192² texture shown on a report sheet).
///
/// # Panics
/// When `k` times the image's size overflows `usize`.
pub fn mapped_tile<'a>(
    label: String,
    img: &'a Image,
    k: usize,
    map: fn(f32) -> f32,
) -> LazyTile<'a> {
    tiling(label, Cow::Borrowed(img), k, Some(map))
}

/// [`tiled_tile`] and [`mapped_tile`].
fn tiling<'a>(
    label: String,
    img: Cow<'a, Image>,
    k: usize,
    map: Option<fn(f32) -> f32>,
) -> LazyTile<'a> {
    let (c, h, w) = (img.channels, img.height, img.width);
    assert!(
        h.checked_mul(k).is_some() && w.checked_mul(k).is_some(),
        "tiled_tile: {k} x {k} copies of a {w}x{h} image overflow"
    );
    LazyTile {
        label,
        width: w * k,
        height: h * k,
        channels: c,
        render: Box::new(move |th, tw| {
            resize_rows((c, h * k, w * k), th, tw, false, |ch, r, out| {
                let src = &img.plane(ch)[(r % h) * w..(r % h + 1) * w];
                for copy in out.chunks_mut(w.max(1)) {
                    match map {
                        Some(f) => copy.iter_mut().zip(src).for_each(|(o, &v)| *o = f(v)),
                        None => copy.copy_from_slice(src),
                    }
                }
            })
        }),
    }
}

/// Resamples every plane of `img` to `height × width`: area average (box
/// filter) along an axis that shrinks, bilinear interpolation (texel centres)
/// along one that grows. `wrap` treats the image as periodic (bilinear
/// neighbours wrap around); otherwise edge texels are repeated. An empty
/// source gives zeros.
pub(crate) fn resize(img: &Image, height: usize, width: usize, wrap: bool) -> Image {
    let sw = img.width;
    resize_rows(
        (img.channels, img.height, img.width),
        height,
        width,
        wrap,
        |ch, r, row| row.copy_from_slice(&img.plane(ch)[r * sw..(r + 1) * sw]),
    )
}

/// The resize of the sheets (area average along a shrinking axis, bilinear
/// along a growing one; `wrap` as for tiles) of a `(channels, rows,
/// columns)` picture that is given row by row: `row(ch, r, out)` writes row
/// `r` of channel `ch` into `out`. The same values as resizing the whole
/// picture (the same sums in the same order), without it ever existing.
pub fn resize_rows(
    (c, sh, sw): (usize, usize, usize),
    height: usize,
    width: usize,
    wrap: bool,
    row: impl Fn(usize, usize, &mut [f32]) + Sync,
) -> Image {
    resize_rows_at((c, sh, sw), height, width, (wrap, (0.0, 0.0)), row)
}

/// [`resize`] of a periodic image with its output grid moved by `offset =
/// (rows, columns)` output texels: output texel `(r, c)` covers (or, along a
/// growing axis, samples the centre of) the source footprint of texel
/// `(r + offset.0, c + offset.1)` of the unmoved resize, wrapping around.
/// Offset `(0, 0)` gives exactly `resize(img, height, width, true)`.
pub(crate) fn resize_periodic_at(
    img: &Image,
    height: usize,
    width: usize,
    offset: (f64, f64),
) -> Image {
    let sw = img.width;
    resize_rows_at(
        (img.channels, img.height, img.width),
        height,
        width,
        (true, offset),
        |ch, r, row| row.copy_from_slice(&img.plane(ch)[r * sw..(r + 1) * sw]),
    )
}

/// [`resize_rows`] with the output grid moved by `offset` output texels
/// (`(wrap, offset)`; see [`resize_periodic_at`]).
fn resize_rows_at(
    (c, sh, sw): (usize, usize, usize),
    height: usize,
    width: usize,
    (wrap, offset): (bool, (f64, f64)),
    row: impl Fn(usize, usize, &mut [f32]) + Sync,
) -> Image {
    if sw == 0 || sh == 0 || width == 0 || height == 0 {
        return Image::zeros(c, height, width);
    }
    let wx = axis_weights_at(sw, width, wrap, offset.1);
    let wy = axis_weights_at(sh, height, wrap, offset.0);
    let mut out = vec![0.0f32; c * width * height];
    let mut tmp = vec![0.0f32; sh * width];
    // Rows in parallel in both passes; every value is one fixed-order sum, so
    // the bytes do not depend on the thread count.
    for (ch, plane) in out.chunks_mut(width * height).enumerate() {
        tmp.par_chunks_mut(width).enumerate().for_each_init(
            || vec![0.0f32; sw],
            |src, (r, out)| {
                row(ch, r, src);
                for (o, taps) in out.iter_mut().zip(&wx) {
                    *o = taps.iter().map(|&(i, wt)| src[i] * wt).sum();
                }
            },
        );
        plane
            .par_chunks_mut(width)
            .zip(wy.par_iter())
            .for_each(|(row, taps)| {
                for (col, o) in row.iter_mut().enumerate() {
                    *o = taps.iter().map(|&(i, wt)| tmp[i * width + col] * wt).sum();
                }
            });
    }
    Image {
        channels: c,
        height,
        width,
        data: out,
    }
}

/// Per output index, the source taps `(index, weight)` (weights sum to 1).
#[cfg(test)]
fn axis_weights(src: usize, dst: usize, wrap: bool) -> Vec<Vec<(usize, f32)>> {
    axis_weights_at(src, dst, wrap, 0.0)
}

/// Per output index, the source taps `(index, weight)` (weights sum to 1),
/// for the output grid moved by `offset` output texels
/// (source indices wrap with `wrap`, else clamp to the edge). Offset 0 gives
/// the same taps in the same order as no offset.
fn axis_weights_at(src: usize, dst: usize, wrap: bool, offset: f64) -> Vec<Vec<(usize, f32)>> {
    let scale = src as f64 / dst as f64;
    let idx = |i: i64| -> usize {
        if wrap {
            i.rem_euclid(src as i64) as usize
        } else {
            i.clamp(0, src as i64 - 1) as usize
        }
    };
    (0..dst)
        .map(|o| {
            let at = o as f64 + offset;
            if scale > 1.0 {
                // Area average over [at·scale, (at+1)·scale); unmoved, the
                // footprint ends inside the source (`i < src` drops a last
                // index that rounding alone reaches).
                let (a, b) = (at * scale, (at + 1.0) * scale);
                let mut taps = Vec::new();
                let mut i = a.floor() as i64;
                while (i as f64) < b && (offset != 0.0 || i < src as i64) {
                    let lo = a.max(i as f64);
                    let hi = b.min(i as f64 + 1.0);
                    if hi > lo {
                        taps.push((idx(i), ((hi - lo) / scale) as f32));
                    }
                    i += 1;
                }
                taps
            } else {
                // Bilinear at the output texel centre.
                let s = (at + 0.5) * scale - 0.5;
                let f = s.floor();
                let t = (s - f) as f32;
                let i0 = f as i64;
                vec![(idx(i0), 1.0 - t), (idx(i0 + 1), t)]
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The sequential two-pass resize the parallel one must equal bit for bit.
    fn resize_reference(img: &Image, height: usize, width: usize, wrap: bool) -> Image {
        let c = img.channels;
        if img.width == 0 || img.height == 0 || width == 0 || height == 0 {
            return Image::zeros(c, height, width);
        }
        let wx = axis_weights(img.width, width, wrap);
        let wy = axis_weights(img.height, height, wrap);
        let (sw, sh) = (img.width, img.height);
        let mut out = Vec::with_capacity(c * width * height);
        let mut tmp = vec![0.0f32; sh * width];
        for ch in 0..c {
            let p = img.plane(ch);
            for r in 0..sh {
                let src = &p[r * sw..(r + 1) * sw];
                for (o, taps) in wx.iter().enumerate() {
                    tmp[r * width + o] = taps.iter().map(|&(i, wt)| src[i] * wt).sum();
                }
            }
            for taps in &wy {
                for col in 0..width {
                    out.push(taps.iter().map(|&(i, wt)| tmp[i * width + col] * wt).sum());
                }
            }
        }
        Image {
            channels: c,
            height,
            width,
            data: out,
        }
    }

    /// A moved periodic resize against its definition: the integral of the
    /// source (a step function, periodic) over each output texel's footprint,
    /// taken by brute force on a 1/64-texel grid along the shrinking axis;
    /// bilinear samples of the periodic source along the growing one.
    #[test]
    fn moved_periodic_resize_matches_its_definition() {
        let mut rng = picker_tensor::Rng::new(17);
        for (sh, sw, h, w) in [(24, 40, 6, 5), (7, 9, 3, 4), (5, 6, 10, 15), (32, 3, 8, 7)] {
            let data: Vec<f32> = (0..sh * sw).map(|_| rng.uniform(0.0, 1.0)).collect();
            let img = Image::new(1, sh, sw, data.clone()).unwrap();
            for off in [(0.0, 0.0), (0.375, -0.5), (-0.875, 0.25), (2.0, -1.0)] {
                let out = resize_periodic_at(&img, h, w, off);
                // Along one axis: the weights the definition gives output `o`.
                let weights = |src: usize, dst: usize, o: usize, off: f64| -> Vec<f64> {
                    let scale = src as f64 / dst as f64;
                    let mut wts = vec![0.0f64; src];
                    if scale > 1.0 {
                        let steps = 64 * src;
                        for k in 0..steps {
                            let x =
                                (o as f64 + off) * scale + (k as f64 + 0.5) * scale / steps as f64;
                            wts[(x.floor() as i64).rem_euclid(src as i64) as usize] +=
                                1.0 / steps as f64;
                        }
                    } else {
                        let x = (o as f64 + 0.5 + off) * scale - 0.5;
                        let t = x - x.floor();
                        wts[(x.floor() as i64).rem_euclid(src as i64) as usize] += 1.0 - t;
                        wts[(x.floor() as i64 + 1).rem_euclid(src as i64) as usize] += t;
                    }
                    wts
                };
                for r in 0..h {
                    let wy = weights(sh, h, r, off.0);
                    for c in 0..w {
                        let wx = weights(sw, w, c, off.1);
                        let mut want = 0.0f64;
                        for (y, a) in wy.iter().enumerate() {
                            for (x, b) in wx.iter().enumerate() {
                                want += a * b * f64::from(data[y * sw + x]);
                            }
                        }
                        let got = f64::from(out.data[r * w + c]);
                        assert!(
                            (got - want).abs() < 2e-3,
                            "{sh}x{sw} -> {h}x{w} at {off:?}: ({r}, {c}) {got} vs {want}"
                        );
                    }
                }
                if off == (0.0, 0.0) {
                    assert_eq!(
                        out.data,
                        resize(&img, h, w, true).data,
                        "unmoved: resize's bytes"
                    );
                }
                if off == (2.0, -1.0) {
                    // Whole texels: the unmoved resize rolled.
                    let plain = resize(&img, h, w, true);
                    for r in 0..h {
                        for c in 0..w {
                            let (pr, pc) = ((r + 2) % h, (c + w - 1) % w);
                            let d = out.data[r * w + c] - plain.data[pr * w + pc];
                            assert!(d.abs() < 1e-5, "{sh}x{sw} roll ({r}, {c}): {d}");
                        }
                    }
                }
            }
        }
    }

    /// The outline: pixels on a side white, their neighbours black, the
    /// inside untouched; sides with a non-finite point left out; points far
    /// outside clipped; on a lazy tile, drawn at the rendering's size.
    #[test]
    fn polygons_are_outlined_and_clipped() {
        let (h, w) = (30, 40);
        let grey = Image::new(1, h, w, vec![0.5; h * w]).unwrap();
        let at = |img: &Image, x: usize, y: usize| img.data[y * w + x];
        let square = [[10.5, 10.5], [30.5, 10.5], [30.5, 20.5], [10.5, 20.5]];
        let mut img = grey.clone();
        draw_polygon(&mut img, &square);
        for x in 10..=30 {
            assert_eq!((at(&img, x, 10), at(&img, x, 20)), (1.0, 1.0), "x {x}");
        }
        for y in 10..=20 {
            assert_eq!((at(&img, 10, y), at(&img, 30, y)), (1.0, 1.0), "y {y}");
        }
        assert_eq!(at(&img, 20, 9), 0.0, "outline above the top side");
        assert_eq!(at(&img, 20, 11), 0.0, "outline below it");
        assert_eq!(at(&img, 20, 8), 0.5, "two pixels off: untouched");
        assert_eq!(at(&img, 20, 15), 0.5, "inside: untouched");
        // A NaN corner drops its two sides, the others stay.
        let mut img = grey.clone();
        draw_polygon(
            &mut img,
            &[[10.5, 10.5], [30.5, 10.5], [f32::NAN, 0.0], [10.5, 20.5]],
        );
        assert_eq!(at(&img, 20, 10), 1.0);
        assert_eq!(at(&img, 10, 15), 1.0);
        assert_eq!(at(&img, 30, 15), 0.5);
        // Far outside: clipped, no panic; a side crossing the picture shows.
        let mut img = grey.clone();
        draw_polygon(&mut img, &[[-1e6, 15.5], [1e6, 15.5], [1e6, 1e6]]);
        assert_eq!(at(&img, 0, 15), 1.0);
        let mut rgb = Image::new(3, h, w, vec![0.25; 3 * h * w]).unwrap();
        draw_polygon(&mut rgb, &square);
        assert_eq!(
            [0, 1, 2].map(|c| rgb.data[c * h * w + 10 * w + 20]),
            [1.0; 3]
        );
        // Lazily: at the full size as drawn on the picture, at half size
        // with the points halved.
        let tile = outlined(
            LazyTile::from(Tile {
                label: "q".into(),
                image: grey.clone(),
            }),
            square.to_vec(),
        );
        let mut want = grey.clone();
        draw_polygon(&mut want, &square);
        assert_eq!((tile.render)(h, w).data, want.data);
        let mut half = resize(&grey, h / 2, w / 2, false);
        draw_polygon(&mut half, &square.map(|p| [p[0] / 2.0, p[1] / 2.0]));
        assert_eq!((tile.render)(h / 2, w / 2).data, half.data);
    }

    #[test]
    fn row_resize_matches_resizing_the_whole_picture() {
        let mut rng = picker_tensor::Rng::new(4);
        for &(c, h, w, dh, dw) in &[(1, 1, 1, 1, 1), (3, 40, 30, 7, 5), (3, 300, 401, 192, 256)] {
            let img = Image::new(c, h, w, rng.uniform_vec(c * h * w, 0.0, 1.0)).unwrap();
            // A picture that differs from `img`: every other row darkened.
            let mut changed = img.clone();
            for ch in 0..c {
                for r in (0..h).step_by(2) {
                    for v in &mut changed.data[ch * h * w + r * w..ch * h * w + (r + 1) * w] {
                        *v *= 0.25;
                    }
                }
            }
            for wrap in [false, true] {
                let a = resize_rows((c, h, w), dh, dw, wrap, |ch, r, out| {
                    out.copy_from_slice(&img.plane(ch)[r * w..(r + 1) * w]);
                    if r % 2 == 0 {
                        for v in out.iter_mut() {
                            *v *= 0.25;
                        }
                    }
                });
                let b = resize_reference(&changed, dh, dw, wrap);
                let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&a.data), bits(&b.data), "{c}x{h}x{w} -> {dh}x{dw}");
            }
        }
    }

    #[test]
    fn lazy_tiles_match_the_pictures_they_stand_for() {
        let mut rng = picker_tensor::Rng::new(5);
        let (h, w) = (120, 160);
        let img = Image::new(3, h, w, rng.uniform_vec(3 * h * w, 0.0, 1.0)).unwrap();
        let mask: Vec<f32> = (0..h * w).map(|_| rng.range(0, 1) as f32).collect();
        let bits = |v: &Image| v.data.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        // Markers inside, on every edge, outside and not finite.
        for (x, y, r) in [
            (80.5, 60.5, 4.0),
            (0.5, 0.5, 9.0),
            (159.5, 119.5, 3.0),
            (80.5, 2.5, 30.0),
            (-40.0, 500.0, 4.0),
            (80.5, f32::NAN, 4.0),
            (33.25, 71.7, 6.3),
        ] {
            let lazy = marked_tile("m".into(), &img, x, y, r);
            // The image resized, then the marker drawn in the tile's pixels.
            for (th, tw) in [(48, 64), (200, 260), (120, 160)] {
                let mut want = resize(&img, th, tw, false);
                let (sx, sy) = (tw as f32 / w as f32, th as f32 / h as f32);
                draw_marker(&mut want, x * sx, y * sy, r * sx);
                assert_eq!(
                    bits(&(lazy.render)(th, tw)),
                    bits(&want),
                    "marker at {x},{y} r {r}"
                );
            }
        }
        // On a picture far larger than its tile (a 12-megapixel photo) the
        // marker stays as visible as on a small one: white strokes in the
        // tile, none of them lost to the resize.
        let big = Image::new(3, 1200, 1600, vec![0.5; 3 * 1200 * 1600]).unwrap();
        let small = Image::new(3, 120, 160, vec![0.5; 3 * 120 * 160]).unwrap();
        let white = |t: &Image| t.data.iter().filter(|&&v| v == 1.0).count();
        let on_big = white(&(marked_tile("b".into(), &big, 800.0, 600.0, 40.0).render)(
            96, 128,
        ));
        let on_small = white(&(marked_tile("s".into(), &small, 80.0, 60.0, 4.0).render)(
            96, 128,
        ));
        assert!(on_big > 30, "{on_big} white values");
        assert_eq!(on_big, on_small);
        // Dimmed: outside the mask the pixel's grey (Rec. 709) mixed with 30 %
        // of its colour, a quarter as bright, plus a blue tint; inside as is.
        let mut dimmed = img.clone();
        for (i, _) in mask.iter().enumerate().filter(|(_, &m)| m <= 0.5) {
            let rgb = [0, 1, 2].map(|c| img.data[c * h * w + i]);
            let grey = 0.2126 * rgb[0] + 0.7152 * rgb[1] + 0.0722 * rgb[2];
            for (c, v) in rgb.into_iter().enumerate() {
                let tint = if c == 2 { DIM_TINT } else { 0.0 };
                dimmed.data[c * h * w + i] =
                    0.25 * (DIM_SATURATION * v + (1.0 - DIM_SATURATION) * grey) + tint;
            }
        }
        let lazy = dimmed_tile("d".into(), &img, &mask, 0.25);
        assert_eq!(
            bits(&(lazy.render)(48, 64)),
            bits(&resize(&dimmed, 48, 64, false))
        );
        // A one-channel image is only multiplied.
        let grey_img = Image::new(1, h, w, img.data[..h * w].to_vec()).unwrap();
        let mut grey_dim = grey_img.clone();
        for (v, &m) in grey_dim.data.iter_mut().zip(&mask) {
            if m <= 0.5 {
                *v *= 0.25;
            }
        }
        let lazy = dimmed_tile("g".into(), &grey_img, &mask, 0.25);
        assert_eq!(
            bits(&(lazy.render)(48, 64)),
            bits(&resize(&grey_dim, 48, 64, false))
        );
        let mut tiled = Image::zeros(3, 2 * h, 2 * w);
        for c in 0..3 {
            for y in 0..2 * h {
                for x in 0..2 * w {
                    tiled.data[c * 4 * h * w + y * 2 * w + x] =
                        img.data[c * h * w + (y % h) * w + x % w];
                }
            }
        }
        let lazy = tiled_tile("t".into(), img.clone(), 2);
        assert_eq!((lazy.width, lazy.height), (2 * w, 2 * h));
        assert_eq!(
            bits(&(lazy.render)(192, 256)),
            bits(&resize(&tiled, 192, 256, false))
        );
        // Mapped per value: the mapped picture (tiled or not), resized.
        let half = |v: f32| (v * 0.5).sqrt();
        for (k, whole) in [(1, &img), (2, &tiled)] {
            let mut mapped = whole.clone();
            mapped.data.iter_mut().for_each(|v| *v = half(*v));
            let lazy = mapped_tile("m".into(), &img, k, half);
            assert_eq!((lazy.width, lazy.height), (k * w, k * h));
            for (th, tw) in [(48, 64), (192, 256), (7, 3)] {
                assert_eq!(
                    bits(&(lazy.render)(th, tw)),
                    bits(&resize(&mapped, th, tw, false)),
                    "k {k}, {th}x{tw}"
                );
            }
        }
    }

    #[test]
    fn parallel_resize_matches_reference() {
        let mut rng = picker_tensor::Rng::new(3);
        for &(c, h, w, dh, dw) in &[
            (1, 1, 1, 1, 1),
            (3, 1, 9, 4, 2),
            (3, 40, 30, 7, 5),
            (1, 5, 7, 33, 21),
            (4, 300, 401, 192, 256),
            (3, 2, 2, 0, 3),
        ] {
            let img = Image::new(c, h, w, rng.uniform_vec(c * h * w, 0.0, 1.0)).unwrap();
            for wrap in [false, true] {
                let a = resize(&img, dh, dw, wrap);
                let b = resize_reference(&img, dh, dw, wrap);
                assert_eq!(
                    (a.channels, a.height, a.width),
                    (b.channels, b.height, b.width)
                );
                let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&a.data), bits(&b.data), "{c}x{h}x{w} -> {dh}x{dw}");
            }
        }
    }
}
