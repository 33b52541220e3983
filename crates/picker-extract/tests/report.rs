//! Tests of `picker_extract::report`: sheet layout, labels, the pick marker.

use picker_extract::report::{
    compose_sheet, draw_marker, draw_text, text_width, Tile, MAX_TILE_ASPECT, SHEET_BACKGROUND,
    SHEET_MARGIN,
};
use picker_render::io::Image;

fn solid(c: usize, h: usize, w: usize, v: f32) -> Image {
    Image::new(c, h, w, vec![v; c * h * w]).unwrap()
}

fn tile(label: &str, img: Image) -> Tile {
    Tile {
        label: label.into(),
        image: img,
    }
}

/// Label band height of the sheet (7 font rows × 2 + 4).
const BAND: usize = 18;

#[test]
fn sheet_dimensions_follow_the_grid() {
    let tiles: Vec<Tile> = (0..5)
        .map(|k| tile("", solid(3, 32, 64, k as f32 / 5.0)))
        .collect();
    let sheet = compose_sheet(&tiles, 2, 50);
    // Cells: 100 wide (aspect 2:1 at height 50), 3 rows of 2.
    let cell_w = 100;
    assert_eq!(sheet.channels, 3);
    assert_eq!(sheet.width, SHEET_MARGIN + 2 * (cell_w + SHEET_MARGIN));
    assert_eq!(sheet.height, SHEET_MARGIN + 3 * (BAND + 50 + SHEET_MARGIN));
    // Tile 3 (row 1, column 1) is its solid value at the centre of its cell.
    let n = sheet.plane_len();
    let x = SHEET_MARGIN + (cell_w + SHEET_MARGIN) + cell_w / 2;
    let y = SHEET_MARGIN + (BAND + 50 + SHEET_MARGIN) + BAND + 25;
    for c in 0..3 {
        assert!((sheet.data[c * n + y * sheet.width + x] - 0.6).abs() < 1e-6);
    }
    // The empty sixth cell is background.
    let x = SHEET_MARGIN + (cell_w + SHEET_MARGIN) + cell_w / 2;
    let y = SHEET_MARGIN + 2 * (BAND + 50 + SHEET_MARGIN) + BAND + 25;
    assert_eq!(sheet.data[y * sheet.width + x], SHEET_BACKGROUND);
    // Columns larger than the number of tiles shrink to one row.
    let one_row = compose_sheet(&tiles[..2], 10, 50);
    assert_eq!(one_row.width, SHEET_MARGIN + 2 * (cell_w + SHEET_MARGIN));
    // Zero columns count as one.
    let one_col = compose_sheet(&tiles[..2], 0, 50);
    assert_eq!(one_col.width, SHEET_MARGIN + cell_w + SHEET_MARGIN);
}

#[test]
fn tiles_are_resized_keeping_aspect() {
    // A 4×8 image with a left half 0 and right half 1, drawn at height 16 → 32 wide.
    let mut img = solid(1, 4, 8, 0.0);
    for r in 0..4 {
        for c in 4..8 {
            img.data[r * 8 + c] = 1.0;
        }
    }
    let sheet = compose_sheet(&[tile("", img)], 1, 16);
    assert_eq!(sheet.width, SHEET_MARGIN * 2 + 32);
    let y = SHEET_MARGIN + BAND + 8;
    let at = |x: usize| sheet.data[y * sheet.width + SHEET_MARGIN + x];
    assert!(at(2) < 0.01 && at(29) > 0.99, "{} {}", at(2), at(29));
}

#[test]
fn labels_draw_pixels() {
    let img = solid(3, 20, 20, 0.5);
    let plain = compose_sheet(&[tile("", img.clone())], 1, 20);
    let labelled = compose_sheet(&[tile("Ab 9", img)], 1, 20);
    assert!(labelled.width >= text_width("Ab 9") + 2 * SHEET_MARGIN);
    // Only the label band changes, and it does change.
    let w = labelled.width;
    let mut changed = 0;
    for row in 0..labelled.height {
        for col in 0..w.min(plain.width) {
            let i = row * w + col;
            if labelled.data[i] != SHEET_BACKGROUND && labelled.data[i] != 0.5 {
                changed += 1;
                assert!((SHEET_MARGIN..SHEET_MARGIN + BAND).contains(&row));
            }
        }
    }
    assert!(changed > 20, "{changed} label pixels");
    // The font: a space draws nothing, every printable character draws something.
    let mut canvas = solid(1, 14, 12, 0.0);
    draw_text(&mut canvas, 0, 0, " ", 1.0, 100);
    assert!(canvas.data.iter().all(|&v| v == 0.0));
    for c in '!'..='~' {
        let mut canvas = solid(1, 14, 12, 0.0);
        draw_text(&mut canvas, 0, 0, &c.to_string(), 1.0, 100);
        assert!(canvas.data.contains(&1.0), "glyph {c:?} is blank");
    }
    // Non-ASCII is drawn as '?'.
    let mut q = solid(1, 14, 12, 0.0);
    let mut e = solid(1, 14, 12, 0.0);
    draw_text(&mut q, 0, 0, "?", 1.0, 100);
    draw_text(&mut e, 0, 0, "é", 1.0, 100);
    assert_eq!(q, e);
}

#[test]
fn grey_tiles_are_expanded() {
    let sheet = compose_sheet(&[tile("", solid(1, 10, 10, 0.7))], 1, 10);
    let n = sheet.plane_len();
    let i = (SHEET_MARGIN + BAND + 5) * sheet.width + SHEET_MARGIN + 5;
    for c in 0..3 {
        assert!((sheet.data[c * n + i] - 0.7).abs() < 1e-6);
    }
}

#[test]
fn very_wide_tiles_are_fitted_to_the_widest_cell() {
    // A 1×4000 picture at tile height 50 would be 200 000 pixels wide: it is
    // fitted to MAX_TILE_ASPECT·50 columns and 1 row, centred in the band.
    let th = 50;
    let wide = solid(3, 1, 4000, 0.7);
    let sheet = compose_sheet(&[tile("", wide), tile("", solid(3, 10, 10, 0.2))], 2, th);
    let cell_w = MAX_TILE_ASPECT * th;
    assert_eq!(sheet.width, SHEET_MARGIN + 2 * (cell_w + SHEET_MARGIN));
    assert_eq!(sheet.height, SHEET_MARGIN + BAND + th + SHEET_MARGIN);
    let n = sheet.plane_len();
    let at = |row: usize, col: usize| sheet.data[row * sheet.width + col];
    let mid = SHEET_MARGIN + BAND + (th - 1) / 2;
    for col in [
        SHEET_MARGIN,
        SHEET_MARGIN + cell_w / 2,
        SHEET_MARGIN + cell_w - 1,
    ] {
        for c in 0..3 {
            assert!((sheet.data[c * n + mid * sheet.width + col] - 0.7).abs() < 1e-6);
        }
        // Only that row: the rest of the band is background.
        assert_eq!(at(mid - 1, col), SHEET_BACKGROUND);
        assert_eq!(at(mid + 1, col), SHEET_BACKGROUND);
    }
    // A picture of exactly MAX_TILE_ASPECT keeps its full height.
    let edge = compose_sheet(&[tile("", solid(3, 10, 10 * MAX_TILE_ASPECT, 0.3))], 1, th);
    assert_eq!(edge.width, SHEET_MARGIN + cell_w + SHEET_MARGIN);
    for row in [SHEET_MARGIN + BAND, SHEET_MARGIN + BAND + th - 1] {
        assert!((edge.data[row * edge.width + SHEET_MARGIN] - 0.3).abs() < 1e-6);
    }
    // A very tall one stays at the tile height, one column wide.
    let tall = compose_sheet(&[tile("", solid(3, 4000, 1, 0.4))], 1, th);
    assert_eq!(tall.height, SHEET_MARGIN + BAND + th + SHEET_MARGIN);
}

#[test]
fn empty_input_gives_an_empty_sheet() {
    let sheet = compose_sheet(&[], 3, 64);
    assert_eq!((sheet.channels, sheet.height, sheet.width), (3, 0, 0));
    // An empty tile leaves its cell blank but keeps the label.
    let sheet = compose_sheet(&[tile("x", Image::zeros(3, 0, 0))], 1, 8);
    assert!(sheet.width > 0 && sheet.height > 0);
}

#[test]
fn marker_draws_at_the_given_place() {
    let (h, w) = (64, 80);
    let mut img = solid(3, h, w, 0.5);
    let (x, y, r) = (30.5f32, 20.5f32, 8.0f32);
    draw_marker(&mut img, x, y, r);
    let n = img.plane_len();
    let px = |row: usize, col: usize| img.data[row * w + col];
    // The ring at distance r on the four axes is drawn (white or black outline).
    let (cx, cy) = (30usize, 20usize);
    for (row, col) in [(cy, cx + 8), (cy, cx - 8), (cy + 8, cx), (cy - 8, cx)] {
        assert_ne!(px(row, col), 0.5, "ring at ({row}, {col})");
    }
    // White and black both present, in every channel alike.
    assert!(img.data[..n].contains(&1.0) && img.data[..n].contains(&0.0));
    assert_eq!(img.data[..n], img.data[n..2 * n]);
    // The picked pixel itself is untouched; far pixels too.
    assert_eq!(px(cy, cx), 0.5);
    assert_eq!(px(cy + 30, cx + 30), 0.5);
    assert_eq!(px(0, 0), 0.5);
    // Changed pixels stay within the marker's reach.
    for row in 0..h {
        for col in 0..w {
            if px(row, col) != 0.5 {
                let d = ((col as f32 + 0.5 - x).powi(2) + (row as f32 + 0.5 - y).powi(2)).sqrt();
                assert!(d <= 1.6 * r + 2.5, "pixel ({row}, {col}) at {d}");
            }
        }
    }
    // Near an edge it is clipped without panicking.
    let mut img = solid(1, 10, 10, 0.5);
    draw_marker(&mut img, 0.0, 9.9, 20.0);
    draw_marker(&mut img, -100.0, 1e9, 5.0);
    draw_marker(&mut img, f32::NAN, 1.0, 5.0);
}
