//! Tests of `picker_extract::eval`: mask IoU, aligned texture score, albedo and normal errors.

use std::time::Instant;

use picker_extract::eval::{
    albedo_error, aligned_texture_score, colour_distance, mask_iou, normal_error_deg, quarter_turn,
    turned_texture_score,
};
use picker_render::io::Image;
use picker_tensor::Rng;

/// A tileable linear-RGB texture: a few random integer-frequency waves per
/// channel plus a little white noise (so no shift but 0 matches it).
fn texture(h: usize, w: usize, seed: u64) -> Image {
    let mut rng = Rng::new(seed);
    let n = h * w;
    let mut data = vec![0.0f32; 3 * n];
    for c in 0..3 {
        let waves: Vec<(f32, f32, f32, f32)> = (0..4)
            .map(|_| {
                (
                    rng.range(1, 6) as f32,
                    rng.range(0, 5) as f32,
                    rng.uniform(0.0, std::f32::consts::TAU),
                    rng.uniform(0.05, 0.15),
                )
            })
            .collect();
        for r in 0..h {
            for col in 0..w {
                let (u, v) = (col as f32 / w as f32, r as f32 / h as f32);
                let mut x = 0.45;
                for &(fu, fv, ph, a) in &waves {
                    x += a * (std::f32::consts::TAU * (fu * u + fv * v) + ph).sin();
                }
                x += rng.uniform(-0.04, 0.04);
                data[c * n + r * w + col] = x.clamp(0.02, 0.98);
            }
        }
    }
    Image::new(3, h, w, data).unwrap()
}

/// `out(r, c) = img((r + dy) mod h, (c + dx) mod w)`.
fn shifted(img: &Image, dy: usize, dx: usize) -> Image {
    let (h, w, n) = (img.height, img.width, img.plane_len());
    let mut out = img.clone();
    for c in 0..img.channels {
        for r in 0..h {
            for x in 0..w {
                out.data[c * n + r * w + x] = img.data[c * n + ((r + dy) % h) * w + (x + dx) % w];
            }
        }
    }
    out
}

#[test]
fn identical_textures_score_perfectly() {
    let t = texture(48, 64, 1);
    let s = aligned_texture_score(&t, &t);
    assert_eq!(s.psnr_db, f64::INFINITY);
    assert_eq!(s.shift, (0, 0));
    assert_eq!(s.offset, (0.0, 0.0));
    assert_eq!(s.scale, 1.0);
    assert_eq!(s.colour_distance, 0.0);
    assert_eq!(colour_distance(&t, &t), 0.0);
}

#[test]
fn cyclic_shift_is_found_exactly() {
    for (h, w, dy, dx) in [(64, 96, 5, 17), (40, 40, 39, 1), (33, 50, 16, 25)] {
        let t = texture(h, w, 2 + dy as u64);
        let e = shifted(&t, dy, dx);
        let s = aligned_texture_score(&e, &t);
        assert_eq!(s.shift, (dy, dx), "{h}x{w}");
        assert_eq!(s.scale, 1.0);
        assert!(s.psnr_db > 100.0, "{}", s.psnr_db);
        assert!(s.colour_distance < 1e-9, "{}", s.colour_distance);
    }
}

#[test]
fn cyclic_shift_256_is_found() {
    let t = texture(256, 256, 7);
    let e = shifted(&t, 100, 37);
    let start = Instant::now();
    let s = aligned_texture_score(&e, &t);
    let took = start.elapsed();
    eprintln!("aligned_texture_score 256x256: {took:?}");
    assert_eq!(s.shift, (100, 37));
    assert!(s.psnr_db > 100.0);
}

#[test]
fn half_scale_tiled_copy_is_found_at_half_scale() {
    let (h, w) = (64, 64);
    let t = texture(h, w, 11);
    // Box-downsample by 2 (in linear light) and tile 2×2, then shift.
    let (hh, hw) = (h / 2, w / 2);
    let n = h * w;
    let mut small = vec![0.0f32; 3 * hh * hw];
    for c in 0..3 {
        for r in 0..hh {
            for x in 0..hw {
                let at = |rr: usize, xx: usize| t.data[c * n + rr * w + xx];
                small[c * hh * hw + r * hw + x] = 0.25
                    * (at(2 * r, 2 * x)
                        + at(2 * r + 1, 2 * x)
                        + at(2 * r, 2 * x + 1)
                        + at(2 * r + 1, 2 * x + 1));
            }
        }
    }
    let mut tiled = Image::zeros(3, h, w);
    for c in 0..3 {
        for r in 0..h {
            for x in 0..w {
                tiled.data[c * n + r * w + x] = small[c * hh * hw + (r % hh) * hw + x % hw];
            }
        }
    }
    let e = shifted(&tiled, 3, 9);
    let s = aligned_texture_score(&e, &t);
    assert_eq!(s.scale, 0.5, "{s:?}");
    assert_eq!(s.shift, (3, 9));
    assert!(s.psnr_db > 60.0, "{s:?}");
}

/// The `h × w` area average of `img` (each side a whole multiple), in linear light.
fn box_down(img: &Image, h: usize, w: usize) -> Image {
    let (ry, rx) = (img.height / h, img.width / w);
    let mut out = Image::zeros(img.channels, h, w);
    for c in 0..img.channels {
        for r in 0..h {
            for x in 0..w {
                let mut sum = 0.0f32;
                for yy in 0..ry {
                    for xx in 0..rx {
                        sum +=
                            img.data[c * img.plane_len() + (r * ry + yy) * img.width + x * rx + xx];
                    }
                }
                out.data[c * h * w + r * w + x] = sum / (ry * rx) as f32;
            }
        }
    }
    out
}

/// A texture seen at an eighth of the truth's resolution with its texel grid
/// a fraction of a texel off the truth's (3 and 5 truth pixels = 3/8 and 5/8
/// of a texel): the whole-texel search alone cannot line it up; the sub-texel
/// search finds the offset and a near-exact match.
#[test]
fn subtexel_offset_is_found_when_the_truth_is_finer() {
    let t = texture(128, 128, 21);
    for (dy, dx, sy, sx) in [(3, 5, 0, 0), (5, 13, 7, 2)] {
        // Extracted texel (r, c) averages truth rows 8r + dy .. 8r + dy + 8.
        let e = shifted(&box_down(&shifted(&t, dy, dx), 16, 16), sy, sx);
        let s = aligned_texture_score(&e, &t);
        assert_eq!(s.scale, 1.0, "{s:?}");
        assert!(s.psnr_db > 60.0, "({dy}, {dx}): {s:?}");
        // Offset and whole shift together: (dy, dx)/8 + (sy, sx) texels.
        let at = |shift: usize, off: f64, want: f64| {
            let got = shift as f64 + off;
            ((got - want).rem_euclid(16.0)).min((want - got).rem_euclid(16.0)) < 1e-9
        };
        assert!(
            at(s.shift.0, s.offset.0, dy as f64 / 8.0 + sy as f64),
            "{s:?}"
        );
        assert!(
            at(s.shift.1, s.offset.1, dx as f64 / 8.0 + sx as f64),
            "{s:?}"
        );
    }
}

/// Where the truth is no finer than the extracted grid, the grid is never
/// moved (it would blur the truth): a half-texel shift of a same-size
/// texture is scored at whole texels only.
#[test]
fn no_subtexel_offset_at_the_truths_own_resolution() {
    let t = texture(48, 48, 23);
    // Halfway between each texel and its right neighbour.
    let mut e = t.clone();
    let n = t.plane_len();
    for c in 0..3 {
        for r in 0..48 {
            for x in 0..48 {
                let at = |xx: usize| t.data[c * n + r * 48 + xx % 48];
                e.data[c * n + r * 48 + x] = 0.5 * (at(x) + at(x + 1));
            }
        }
    }
    let s = aligned_texture_score(&e, &t);
    assert_eq!(s.offset, (0.0, 0.0), "{s:?}");
    assert!(s.psnr_db < 40.0, "{s:?}");
}

#[test]
fn noise_lowers_psnr_monotonically() {
    let t = texture(64, 64, 5);
    let mut rng = Rng::new(99);
    let noise = rng.normal_vec(t.data.len(), 1.0);
    let mut last = f64::INFINITY;
    for sigma in [0.005f32, 0.01, 0.02, 0.05, 0.1] {
        let mut e = t.clone();
        for (v, z) in e.data.iter_mut().zip(&noise) {
            *v = (*v + sigma * z).clamp(0.0, 1.0);
        }
        let s = aligned_texture_score(&e, &t);
        assert!(s.psnr_db < last, "sigma {sigma}: {} !< {last}", s.psnr_db);
        assert!(s.psnr_db.is_finite() && s.psnr_db > 5.0);
        last = s.psnr_db;
    }
}

#[test]
fn colour_distance_sees_colour_changes() {
    let t = texture(32, 32, 3);
    let darker = t.map(|v| v * 0.5);
    let d = colour_distance(&darker, &t);
    assert!(d > 0.05, "{d}");
    let slightly = t.map(|v| v * 0.95);
    assert!(colour_distance(&slightly, &t) < d);
    // Grey against its own RGB expansion is 0.
    let grey = Image::new(1, 4, 4, (0..16).map(|i| i as f32 / 16.0).collect()).unwrap();
    let mut rgb = Vec::new();
    for _ in 0..3 {
        rgb.extend_from_slice(&grey.data);
    }
    let rgb = Image::new(3, 4, 4, rgb).unwrap();
    assert_eq!(colour_distance(&grey, &rgb), 0.0);
}

#[test]
fn empty_images_give_nan() {
    let t = texture(8, 8, 1);
    let s = aligned_texture_score(&Image::zeros(3, 0, 0), &t);
    assert!(s.psnr_db.is_nan() && s.colour_distance.is_nan());
}

#[test]
fn mask_iou_cases() {
    let a = [true, true, false, false];
    let b = [false, true, true, false];
    assert_eq!(mask_iou(&a, &a), 1.0);
    assert!((mask_iou(&a, &b) - 1.0 / 3.0).abs() < 1e-12);
    assert_eq!(mask_iou(&a, &[false, false, true, true]), 0.0);
    assert_eq!(mask_iou(&[false; 4], &[false; 4]), 1.0);
    assert_eq!(mask_iou(&[], &[]), 1.0);
    assert_eq!(mask_iou(&a, &[false; 4]), 0.0);
}

fn constant(c: usize, h: usize, w: usize, v: [f32; 3]) -> Image {
    let n = h * w;
    let mut data = vec![0.0; c * n];
    for ch in 0..c {
        data[ch * n..(ch + 1) * n].fill(v[ch.min(2)]);
    }
    Image::new(c, h, w, data).unwrap()
}

#[test]
fn normal_error_analytic_cases() {
    let z = constant(3, 4, 4, [0.0, 0.0, 1.0]);
    let x = constant(3, 4, 4, [2.0, 0.0, 0.0]); // not unit: renormalised
    let minus_z = constant(3, 4, 4, [0.0, 0.0, -1.0]);
    let all = vec![true; 16];
    assert!((normal_error_deg(&z, &x, &all) - 90.0).abs() < 1e-9);
    assert_eq!(normal_error_deg(&z, &z, &all), 0.0);
    assert!((normal_error_deg(&z, &minus_z, &all) - 180.0).abs() < 1e-9);
    // 45° between +z and (1, 0, 1).
    let diag = constant(3, 4, 4, [1.0, 0.0, 1.0]);
    assert!((normal_error_deg(&z, &diag, &all) - 45.0).abs() < 1e-6);
    // Only masked texels count: half at 90°, half at 0° → 45° mean.
    let mut mixed = z.clone();
    for i in 0..8 {
        mixed.data[i] = 1.0;
        mixed.data[32 + i] = 0.0;
    }
    assert!((normal_error_deg(&mixed, &z, &all) - 45.0).abs() < 1e-9);
    let first_half: Vec<bool> = (0..16).map(|i| i < 8).collect();
    assert!((normal_error_deg(&mixed, &z, &first_half) - 90.0).abs() < 1e-9);
    assert!(normal_error_deg(&z, &x, &[false; 16]).is_nan());
}

#[test]
fn albedo_error_is_rmse_inside_the_mask() {
    let a = constant(3, 2, 2, [0.5, 0.5, 0.5]);
    let b = constant(3, 2, 2, [0.6, 0.4, 0.5]);
    let all = [true; 4];
    let expected = ((0.01 + 0.01 + 0.0) / 3.0f64).sqrt();
    assert!((albedo_error(&a, &b, &all) - expected).abs() < 1e-6);
    let mut c = a.clone();
    c.data[0] = 1.0; // outside the mask below
    let mask = [false, true, true, true];
    assert_eq!(albedo_error(&c, &a, &mask), 0.0);
    assert!(albedo_error(&a, &b, &[false; 4]).is_nan());
}

/// Quarter turns against the plain definition (a texel at row r, column c
/// of an h × w image lands at row c, column h−1−r after one clockwise turn),
/// on odd and even shapes; four turns give the image back.
#[test]
fn quarter_turns_match_their_definition() {
    for (h, w) in [(1, 1), (1, 5), (4, 1), (3, 7), (6, 6)] {
        let t = texture(h, w, 40 + h as u64);
        let mut cur = t.clone();
        for k in 1..=4 {
            let next = quarter_turn(&t, k);
            let once = quarter_turn(&cur, 1);
            assert_eq!((once.height, once.width), (cur.width, cur.height));
            for c in 0..3 {
                for r in 0..cur.height {
                    for x in 0..cur.width {
                        let want = cur.plane(c)[r * cur.width + x];
                        let got = once.plane(c)[x * once.width + (cur.height - 1 - r)];
                        assert_eq!(got, want, "{h}x{w} turn {k}");
                    }
                }
            }
            assert_eq!(
                next.data, once.data,
                "{h}x{w}: turn {k} at once vs one by one"
            );
            cur = once;
        }
        assert_eq!(cur.data, t.data);
        assert_eq!(quarter_turn(&t, 5).data, quarter_turn(&t, 1).data);
    }
}

/// A texture turned by a quarter turn (and shifted) is found at the turn
/// that undoes it, exactly; unturned, the plain score's alignment is kept.
#[test]
fn turned_textures_are_scored_at_the_turn_that_undoes_them() {
    let t = texture(40, 40, 9);
    for k in 0..4 {
        let e = quarter_turn(&shifted(&t, 7, 3), k);
        let (plain, s, turns) = turned_texture_score(&e, &t);
        assert_eq!(plain, aligned_texture_score(&e, &t), "turned {k}");
        assert_eq!(turns, (4 - k) % 4, "turned {k}");
        assert!(s.psnr_db > 100.0, "turned {k}: {}", s.psnr_db);
        if k != 0 {
            assert!(aligned_texture_score(&e, &t).psnr_db < 40.0, "turned {k}");
        }
    }
}

/// At scales over 1 the truth's whole period is compared with the texture
/// tiled: a texture holding half the period scores the same at every cyclic
/// roll, and one that is exactly the period's repeating half matches.
#[test]
fn textures_smaller_than_the_period_are_compared_tiled() {
    // The truth: a 32 × 32 tile repeated 2 × 2 with a faint difference
    // between the copies, so its period is 64.
    let tile = texture(32, 32, 31);
    let mut t = Image::zeros(3, 64, 64);
    for c in 0..3 {
        for r in 0..64 {
            for x in 0..64 {
                let faint = if (r / 32 + x / 32) % 2 == 1 {
                    0.02
                } else {
                    0.0
                };
                t.data[c * 4096 + r * 64 + x] =
                    tile.data[c * 1024 + (r % 32) * 32 + x % 32] + faint;
            }
        }
    }
    let e = shifted(&tile, 5, 9);
    let s0 = aligned_texture_score(&e, &t);
    assert_eq!(s0.scale, 2.0, "{s0:?}");
    assert!(s0.psnr_db > 35.0 && s0.psnr_db < 60.0, "{s0:?}");
    for (dy, dx) in [(1, 0), (0, 13), (17, 30), (31, 31)] {
        let s = aligned_texture_score(&shifted(&e, dy, dx), &t);
        assert_eq!(s.scale, 2.0, "roll ({dy}, {dx}): {s:?}");
        assert!(
            (s.psnr_db - s0.psnr_db).abs() < 1e-6,
            "roll ({dy}, {dx}): {s:?} vs {s0:?}"
        );
    }
    // Without the difference between copies, the tiled texture is the truth.
    let mut exact = t.clone();
    for c in 0..3 {
        for r in 0..64 {
            for x in 0..64 {
                exact.data[c * 4096 + r * 64 + x] = tile.data[c * 1024 + (r % 32) * 32 + x % 32];
            }
        }
    }
    let s = aligned_texture_score(&shifted(&tile, 3, 4), &exact);
    assert!(s.psnr_db > 100.0, "{s:?}");
}

/// At the scales `1/k` the texture is compared with exactly `k × k` periods
/// of the truth resampled to its size: a 40-texel texture holding three
/// periods of a 30-texel truth (13⅓ texels each, bilinear) is found at scale
/// ⅓ above 32 dB, the same at every cyclic roll. Compared with a window of
/// the truth resampled to 13 texels a period, as before, it scored 24.2–24.8
/// dB; with the coarse levels searched at one phase, the rolls scored 33.0 or
/// 33.5 dB (a shift by one period of the truth outranked the true one).
#[test]
fn whole_numbers_of_periods_are_compared_whole() {
    let t = texture(30, 30, 41);
    let (n, k) = (40usize, 3usize);
    // Bilinear periodic sampling of `t` at k periods across n texels.
    let at = |c: usize, y: f64, x: f64| -> f32 {
        let (y0, x0) = (y.floor(), x.floor());
        let (fy, fx) = ((y - y0) as f32, (x - x0) as f32);
        let px = |yy: f64, xx: f64| {
            let (r, q) = (
                (yy as i64).rem_euclid(30) as usize,
                (xx as i64).rem_euclid(30) as usize,
            );
            t.data[c * 900 + r * 30 + q]
        };
        let top = px(y0, x0) * (1.0 - fx) + px(y0, x0 + 1.0) * fx;
        let bottom = px(y0 + 1.0, x0) * (1.0 - fx) + px(y0 + 1.0, x0 + 1.0) * fx;
        top * (1.0 - fy) + bottom * fy
    };
    let step = (30 * k) as f64 / n as f64;
    let mut e = Image::zeros(3, n, n);
    for c in 0..3 {
        for y in 0..n {
            for x in 0..n {
                e.data[c * n * n + y * n + x] = at(
                    c,
                    (y as f64 + 0.5) * step - 0.5,
                    (x as f64 + 0.5) * step - 0.5,
                );
            }
        }
    }
    let mut seen = Vec::new();
    for d in 0..n {
        let s = aligned_texture_score(&shifted(&e, d, (d * 7) % n), &t);
        seen.push(s.psnr_db);
        assert!((s.scale - 1.0 / 3.0).abs() < 1e-12, "roll {d}: {s:?}");
        assert!(s.psnr_db > 32.0, "roll {d}: {s:?}");
    }
    let (lo, hi) = seen
        .iter()
        .fold((f64::MAX, f64::MIN), |(l, h), &v| (l.min(v), h.max(v)));
    assert!(hi - lo < 1e-6, "rolls scored {lo} to {hi}");
}
