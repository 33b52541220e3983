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

/// The periodic component of `img` (Moisan 2011, "Periodic plus smooth image
/// decomposition", J. Math. Imaging Vis. 39): the image `p` that tiles with
/// no jump across its wrap edges while keeping every interior difference of
/// `img`, i.e. `img = p + s` with `s` smooth and of mean 0.
///
/// `p` is the periodic image whose periodic discrete Laplacian equals the
/// Laplacian of `img` taken over its inside neighbours only; equivalently `s`
/// solves the periodic Poisson equation `Δs = v`, where `v` holds the jumps
/// across the edges (`v(0, x) = img(h−1, x) − img(0, x)`, `v(h−1, x)` the
/// opposite, and likewise for the columns) and is zero inside. It is solved
/// exactly with a 2-D DFT per channel, in `f64`; `p` keeps the mean of
/// `img`. The step across each wrap edge becomes about one of the image's
/// own neighbour steps. Only colour jumps are removed: a pattern cut off at
/// an edge stays cut. Even a texture that already tiles is changed (smoothly,
/// near the edges: its step across the edge is treated as a jump), so use
/// [`make_seamless`] to change only textures whose seams show.
pub fn periodic_component(img: &Image) -> Image {
    use rayon::prelude::*;
    use rustfft::num_complex::Complex;
    use rustfft::FftPlanner;

    let (h, w) = (img.height, img.width);
    let mut out = img.clone();
    if h == 0 || w == 0 {
        return out;
    }
    let mut planner = FftPlanner::<f64>::new();
    let (fwd_w, inv_w) = (planner.plan_fft_forward(w), planner.plan_fft_inverse(w));
    let (fwd_h, inv_h) = (planner.plan_fft_forward(h), planner.plan_fft_inverse(h));
    let cos2 = |n: usize| -> Vec<f64> {
        (0..n)
            .map(|k| 2.0 * (2.0 * std::f64::consts::PI * k as f64 / n as f64).cos())
            .collect()
    };
    let (cx, cy) = (cos2(w), cos2(h));
    let zero = Complex::new(0.0, 0.0);
    out.data.par_chunks_mut(h * w).for_each(|plane| {
        // The jumps across the wrap edges (rows, then columns).
        let mut v = vec![zero; h * w];
        for x in 0..w {
            let d = (plane[(h - 1) * w + x] - plane[x]) as f64;
            v[x].re += d;
            v[(h - 1) * w + x].re -= d;
        }
        for y in 0..h {
            let d = (plane[y * w + w - 1] - plane[y * w]) as f64;
            v[y * w].re += d;
            v[y * w + w - 1].re -= d;
        }
        // 2-D DFT: along the rows, then along the columns of the transpose.
        fwd_w.process(&mut v);
        let mut t = vec![zero; h * w];
        for y in 0..h {
            for x in 0..w {
                t[x * h + y] = v[y * w + x];
            }
        }
        fwd_h.process(&mut t);
        // Divide by the periodic Laplacian's eigenvalues (zero only at the
        // mean, which s does not have).
        for (x, (col, &lx)) in t.chunks_exact_mut(h).zip(&cx).enumerate() {
            for (y, (ti, &ly)) in col.iter_mut().zip(&cy).enumerate() {
                *ti = if x == 0 && y == 0 {
                    zero
                } else {
                    *ti / (lx + ly - 4.0)
                };
            }
        }
        inv_h.process(&mut t);
        for y in 0..h {
            for x in 0..w {
                v[y * w + x] = t[x * h + y];
            }
        }
        inv_w.process(&mut v);
        let scale = 1.0 / (h * w) as f64;
        for (p, s) in plane.iter_mut().zip(&v) {
            *p = (*p as f64 - s.re * scale) as f32;
        }
    });
    out
}

/// Seam ratio (see [`SeamScore::ratio`]) above which [`make_seamless`] replaces
/// a texture by its periodic component: below it the wrap edges are about as
/// visible as any pair of neighbouring texels.
pub const SEAMLESS_MIN_RATIO: f64 = 1.25;

/// `img` made to tile without visible seams: its [`periodic_component`] when
/// the seam ratio is above [`SEAMLESS_MIN_RATIO`] and the component's ratio
/// is lower, else `img` itself (not copied). Returns the texture and whether
/// it was replaced.
pub fn make_seamless(img: Image) -> (Image, bool) {
    let before = seam_score(&img);
    if before.ratio <= SEAMLESS_MIN_RATIO {
        return (img, false);
    }
    let p = periodic_component(&img);
    if seam_score(&p).ratio < before.ratio {
        (p, true)
    } else {
        (img, false)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn image(c: usize, h: usize, w: usize, f: impl Fn(usize, usize, usize) -> f32) -> Image {
        let data = (0..c * h * w)
            .map(|i| f(i / (h * w), (i / w) % h, i % w))
            .collect();
        Image::new(c, h, w, data).unwrap()
    }

    /// A seeded value in [0, 1) per index (splitmix-style).
    fn noise(i: usize) -> f32 {
        let mut z = (i as u64).wrapping_add(0x9E37_79B9_7F4A_7C15);
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 40) as f32 / (1u64 << 24) as f32
    }

    /// The defining property: p's periodic Laplacian is the image's
    /// Laplacian over inside neighbours, everywhere, and the mean is kept.
    #[test]
    fn periodic_laplacian_matches_the_inside_laplacian() {
        for &(h, w) in &[(13, 19), (64, 48), (2, 2), (1, 5), (7, 1), (1, 1)] {
            let u = image(3, h, w, |c, y, x| noise((c * 1000 + y) * 1000 + x));
            let p = periodic_component(&u);
            for c in 0..3 {
                let (up, pp) = (u.plane(c), p.plane(c));
                let at = |img: &[f32], y: usize, x: usize| img[y * w + x] as f64;
                let (mut mu, mut mp) = (0.0, 0.0);
                for y in 0..h {
                    for x in 0..w {
                        let mut inside = 0.0;
                        for (dy, dx) in [(-1i64, 0i64), (1, 0), (0, -1), (0, 1)] {
                            let (yy, xx) = (y as i64 + dy, x as i64 + dx);
                            if (0..h as i64).contains(&yy) && (0..w as i64).contains(&xx) {
                                inside += at(up, yy as usize, xx as usize) - at(up, y, x);
                            }
                        }
                        let wrapped: f64 = [(h - 1, 0), (1, 0), (0, w - 1), (0, 1)]
                            .iter()
                            .map(|&(dy, dx)| at(pp, (y + dy) % h, (x + dx) % w) - at(pp, y, x))
                            .sum();
                        assert!(
                            (inside - wrapped).abs() < 1e-4,
                            "{h}x{w} c{c} ({y},{x}): {inside} vs {wrapped}"
                        );
                        mu += at(up, y, x);
                        mp += at(pp, y, x);
                    }
                }
                let n = (h * w) as f64;
                assert!((mu / n - mp / n).abs() < 1e-5, "{h}x{w}: mean moved");
            }
        }
    }

    /// A texture that already tiles is left as it is by `make_seamless`; an
    /// empty one too.
    #[test]
    fn a_tiling_texture_is_left_alone() {
        use std::f32::consts::TAU;
        for &(h, w) in &[(17, 23), (32, 32), (40, 28)] {
            let u = image(2, h, w, |c, y, x| {
                // Texel noise (any pair of texels alike) on slow waves.
                0.5 + 0.1 * noise((c * 100 + y) * 100 + x)
                    + 0.05 * (TAU * x as f32 / w as f32 + 0.3).sin()
                    + 0.05 * (TAU * 2.0 * y as f32 / h as f32 + c as f32).cos()
            });
            let (p, replaced) = make_seamless(u.clone());
            assert!(!replaced, "{h}x{w}: {:?}", seam_score(&u));
            assert_eq!(p.data, u.data);
        }
        let empty = Image::new(3, 0, 4, Vec::new()).unwrap();
        assert_eq!(periodic_component(&empty).data.len(), 0);
        assert!(!make_seamless(empty).1);
    }

    /// A pattern on a colour ramp has a visible seam; in its periodic
    /// component the step across the wrap edges is like a step inside.
    #[test]
    fn the_seam_of_a_ramp_goes() {
        let (h, w) = (48, 64);
        let u = image(3, h, w, |c, y, x| {
            // Checks whose cell edges are not on the wrap edges.
            let checks = if ((x + 2) / 4 + (y + 2) / 4) % 2 == 0 {
                0.1
            } else {
                0.0
            };
            0.2 + 0.5 * x as f32 / w as f32 + 0.3 * y as f32 / h as f32 + checks + 0.05 * c as f32
        });
        let before = seam_score(&u);
        let (p, replaced) = make_seamless(u);
        let after = seam_score(&p);
        assert!(replaced);
        assert!(before.ratio > 3.0, "the ramp should show: {before:?}");
        assert!(
            after.wrap <= 1.25 * before.interior,
            "{before:?} -> {after:?}"
        );
        assert!(after.ratio < before.ratio / 2.0, "{before:?} -> {after:?}");
    }
}
