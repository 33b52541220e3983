//! The direction a rectified texture's pattern runs along (wood grain,
//! stripes, brushed or woven material), so that the plane mode can turn the
//! texture's axes to it.
//!
//! A plane's rectified axes start from the camera's x axis projected on the
//! plane ([`crate::plane::plane_basis`]); where the photo has straight lines
//! on the plane ([`crate::lines`]) they are turned to follow them. A table's
//! grain has no straight lines, so a table seen at an angle gave a texture
//! whose grain runs diagonally, which no artist wants (the grain of a wood
//! texture runs along one of its axes, so that it can be laid along a board).
//!
//! **Measure.** The structure tensor of the picked pixels' luminance, taken
//! in texture-square coordinates: at every pixel whose 3×3 neighbourhood is
//! picked (every `k`-th along both axes when there are more than
//! [`MAX_SAMPLES`]), the gradient `g` of the luminance in the photo (Scharr's
//! 3×3 derivative, the most rotation-invariant of its size)
//! is carried into the square by the coordinates' Jacobian `M` (`(u, v)` per
//! pixel step): `g_uv = M⁻ᵀ g`, and `S = Σ |det M| · g_uv g_uvᵀ` (each pixel
//! weighted by the texture area it covers). The gradients are clipped at
//! their 90th percentile, so that a few strong edges (a leaked object
//! boundary) cannot decide alone. The pattern runs along `S`'s eigenvector
//! of the smaller eigenvalue; its *coherence* is `(λ₁ − λ₂)/(λ₁ + λ₂)`.
//!
//! **Sampling.** The rectification stretches the photo's pixels unevenly:
//! at a grazing angle one pixel step spans many texels along the depth
//! direction, so gradients that are isotropic in the photo (noise, detail
//! finer than a pixel) become anisotropic in the square. The tensor that
//! isotropic photo gradients of the same strength would give,
//! `N = Σ |det M| · |g|²/2 · M⁻ᵀM⁻¹`, measures that bias
//! ([`Grain::sampling_coherence`], [`Grain::sampling_angle_deg`]). The other
//! way round, a texture with features the photo resolves is made directional
//! in the photo by the perspective and isotropic again by the rectification.
//! A real grain is directional both in the photo and in the square, and,
//! where the sampling is directional, not along the sampling's direction
//! ([`Grain::decisive`]).

use serde::Serialize;

use crate::reproject::Coords;

/// Least coherence (`(λ₁ − λ₂)/(λ₁ + λ₂)`) for the grain to turn the axes.
pub const MIN_COHERENCE: f32 = 0.3;
/// Least angle (degrees) between the grain and the sampling's own
/// direction when the rectification is directional.
pub const MIN_FROM_SAMPLING_DEG: f32 = 15.0;
/// Least number of pixels the tensor is summed over.
pub const MIN_PIXELS: usize = 400;
/// At most about this many pixels are read (every `k`-th along both axes).
pub const MAX_SAMPLES: usize = 250_000;
/// Turns smaller than this (degrees) are not made.
pub const MIN_TURN_DEG: f32 = 3.0;

/// The measured grain of a rectified region (see the [module docs](self)).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Grain {
    /// Unit direction `(du, dv)` in the texture square the pattern runs
    /// along.
    pub along: [f32; 2],
    /// Angle of `along` from the `u` axis towards `+v`, in degrees, in
    /// `(−90, 90]`.
    pub angle_deg: f32,
    /// The smallest turn (degrees, in `[−45, 45]`) that puts `along` on an
    /// axis of the square: `angle_deg` less the nearest multiple of 90.
    pub turn_deg: f32,
    /// `(λ₁ − λ₂)/(λ₁ + λ₂)` of the texture-space structure tensor, in `[0, 1]`.
    pub coherence: f32,
    /// The same of the tensor that isotropic photo gradients would give
    /// through the same coordinates: the rectification's own anisotropy.
    pub sampling_coherence: f32,
    /// The direction (degrees, like `angle_deg`) along which that tensor
    /// has its smaller eigenvalue: where the sampling alone would put a grain.
    pub sampling_angle_deg: f32,
    /// The coherence of the same gradients' tensor in the photo (before the
    /// rectification): a pattern the rectification alone made directional
    /// (an isotropic texture seen at a grazing angle, sharp in one
    /// direction and blurred in the other) is not directional there.
    pub photo_coherence: f32,
    /// Pixels the tensor was summed over.
    pub pixels: usize,
}

impl Grain {
    /// Whether the grain is clear enough to turn the texture's axes to it:
    /// at least [`MIN_PIXELS`] pixels, a coherence of at least
    /// [`MIN_COHERENCE`] both in the texture square and in the photo, a
    /// direction at least [`MIN_FROM_SAMPLING_DEG`] from the sampling's when
    /// that is directional too (coherence at least [`MIN_COHERENCE`]: the
    /// two cannot be told apart), and a turn of at least [`MIN_TURN_DEG`].
    pub fn decisive(&self) -> bool {
        let mut off = (self.angle_deg - self.sampling_angle_deg).abs() % 180.0;
        off = off.min(180.0 - off);
        self.pixels >= MIN_PIXELS
            && self.coherence >= MIN_COHERENCE
            && self.photo_coherence >= MIN_COHERENCE
            && (self.sampling_coherence < MIN_COHERENCE || off >= MIN_FROM_SAMPLING_DEG)
            && self.turn_deg.abs() >= MIN_TURN_DEG
    }
}

/// Eigen-analysis of a symmetric 2×2 tensor `[a, b; b, c]`: the unit
/// eigenvector of the smaller eigenvalue and the coherence; `None` when the
/// tensor is zero or not finite.
fn minor_direction(a: f64, b: f64, c: f64) -> Option<([f64; 2], f64)> {
    let tr = a + c;
    if !(tr > 0.0 && tr.is_finite() && b.is_finite()) {
        return None;
    }
    let diff = ((a - c) * (a - c) + 4.0 * b * b).sqrt();
    let coherence = (diff / tr).clamp(0.0, 1.0);
    // Major axis at angle φ = ½·atan2(2b, a − c); the minor one is at φ + 90°.
    let phi = 0.5 * (2.0 * b).atan2(a - c);
    Some(([-phi.sin(), phi.cos()], coherence))
}

/// The angle of direction `d` from the `u` axis, in degrees in `(−90, 90]`
/// (a line, not an arrow).
fn line_angle(d: [f64; 2]) -> f64 {
    let a = d[1].atan2(d[0]).to_degrees();
    if a <= -90.0 {
        a + 180.0
    } else if a > 90.0 {
        a - 180.0
    } else {
        a
    }
}

/// Measures the grain of the `mask`ed pixels of a photo's `luma` (row-major,
/// `coords.width × coords.height`) through the texture coordinates
/// `coords`; `None` when no pixel has a picked 3×3 neighbourhood with finite
/// coordinates, or the luminance is flat there.
///
/// # Panics
/// If `mask` or `luma` do not hold one value per pixel of `coords`.
pub fn measure(coords: &Coords, mask: &[bool], luma: &[f32]) -> Option<Grain> {
    let (w, h) = (coords.width, coords.height);
    assert_eq!(mask.len(), w * h, "grain::measure: mask size");
    assert_eq!(luma.len(), w * h, "grain::measure: luma size");
    if w < 3 || h < 3 {
        return None;
    }
    // Every `stride`-th pixel along both axes, so that at most about
    // MAX_SAMPLES picked pixels are read (a 12-megapixel photo's mask).
    let picked = mask.iter().filter(|&&m| m).count();
    let stride = ((picked as f64 / MAX_SAMPLES as f64).sqrt().ceil() as usize).max(1);
    // (photo gradient, inverse-transposed Jacobian, |det|) per usable pixel.
    let samples: Vec<([f64; 2], [[f64; 2]; 2], f64)> = (1..h - 1)
        .step_by(stride)
        .flat_map(|y| (1..w - 1).step_by(stride).map(move |x| y * w + x))
        .filter_map(|i| {
            let inside = [
                i - w - 1,
                i - w,
                i - w + 1,
                i - 1,
                i,
                i + 1,
                i + w - 1,
                i + w,
                i + w + 1,
            ]
            .iter()
            .all(|&j| mask[j]);
            if !inside {
                return None;
            }
            let (jx, jy) = coords.jacobian(mask, i)?;
            // M = [[du/dx, du/dy], [dv/dx, dv/dy]].
            let (m00, m01, m10, m11) = (
                f64::from(jx[0]),
                f64::from(jy[0]),
                f64::from(jx[1]),
                f64::from(jy[1]),
            );
            let det = m00 * m11 - m01 * m10;
            if !(det.abs() > 0.0 && det.is_finite()) {
                return None;
            }
            // M⁻ᵀ = [[m11, −m10], [−m01, m00]] / det.
            let inv_t = [[m11 / det, -m10 / det], [-m01 / det, m00 / det]];
            let l = |j: usize| f64::from(luma[j]);
            // Scharr's 3×3 derivative (weights 3, 10, 3 across): its
            // direction error is a tenth of the central difference's, whose
            // damping of fine stripes differs between the axes (a floor's
            // stripes at 30° measured 33.8° with it, 30.0° with this).
            let g = [
                (3.0 * (l(i - w + 1) - l(i - w - 1))
                    + 10.0 * (l(i + 1) - l(i - 1))
                    + 3.0 * (l(i + w + 1) - l(i + w - 1)))
                    / 32.0,
                (3.0 * (l(i + w - 1) - l(i - w - 1))
                    + 10.0 * (l(i + w) - l(i - w))
                    + 3.0 * (l(i + w + 1) - l(i - w + 1)))
                    / 32.0,
            ];
            (g[0].is_finite() && g[1].is_finite()).then_some((g, inv_t, det.abs()))
        })
        .collect();
    if samples.is_empty() {
        return None;
    }
    // Gradients clipped at their 90th percentile.
    let mut mags: Vec<f64> = samples.iter().map(|(g, _, _)| g[0].hypot(g[1])).collect();
    let k = (mags.len() - 1) * 9 / 10;
    let clip = *mags.select_nth_unstable_by(k, |a, b| a.total_cmp(b)).1;
    if clip.is_nan() || clip <= 0.0 {
        return None;
    }
    let (mut s, mut n, mut q) = ([0.0f64; 3], [0.0f64; 3], [0.0f64; 3]);
    for (g, m, area) in &samples {
        let mag = g[0].hypot(g[1]);
        let scale = if mag > clip { clip / mag } else { 1.0 };
        let g = [g[0] * scale, g[1] * scale];
        let gu = [
            m[0][0] * g[0] + m[0][1] * g[1],
            m[1][0] * g[0] + m[1][1] * g[1],
        ];
        q[0] += area * g[0] * g[0];
        q[1] += area * g[0] * g[1];
        q[2] += area * g[1] * g[1];
        s[0] += area * gu[0] * gu[0];
        s[1] += area * gu[0] * gu[1];
        s[2] += area * gu[1] * gu[1];
        // Isotropic photo gradients of the same strength: E[g gᵀ] = |g|²/2 · I.
        let e = area * (g[0] * g[0] + g[1] * g[1]) / 2.0;
        n[0] += e * (m[0][0] * m[0][0] + m[0][1] * m[0][1]);
        n[1] += e * (m[0][0] * m[1][0] + m[0][1] * m[1][1]);
        n[2] += e * (m[1][0] * m[1][0] + m[1][1] * m[1][1]);
    }
    let (dir, coherence) = minor_direction(s[0], s[1], s[2])?;
    let photo_coherence = minor_direction(q[0], q[1], q[2]).map_or(0.0, |(_, c)| c);
    let sampling = minor_direction(n[0], n[1], n[2]);
    let sampling_coherence = sampling.map_or(0.0, |(_, c)| c);
    let sampling_angle = sampling.map_or(0.0, |(d, _)| line_angle(d));
    let angle = line_angle(dir);
    let turn = angle - 90.0 * (angle / 90.0).round();
    let rad = angle.to_radians();
    Some(Grain {
        along: [rad.cos() as f32, rad.sin() as f32],
        angle_deg: angle as f32,
        turn_deg: turn as f32,
        coherence: coherence as f32,
        sampling_coherence: sampling_coherence as f32,
        sampling_angle_deg: sampling_angle as f32,
        photo_coherence: photo_coherence as f32,
        pixels: samples.len(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plane::{plane_basis, plane_coords};
    use glam::Vec3;

    /// A photo of stripes whose luminance changes along `grad_deg` (photo
    /// axes, y down) with the given period, over a `w × h` frame.
    fn stripes(w: usize, h: usize, grad_deg: f32, period: f32) -> Vec<f32> {
        let (c, s) = (grad_deg.to_radians().cos(), grad_deg.to_radians().sin());
        (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f32, (i / w) as f32);
                0.5 + 0.4 * (std::f32::consts::TAU * (x * c + y * s) / period).sin()
            })
            .collect()
    }

    fn line_off(a: f32, b: f32) -> f32 {
        let d = (a - b).abs() % 180.0;
        d.min(180.0 - d)
    }

    /// Seen head-on, the square's axes are the photo's: the stripes' angle
    /// comes out as drawn, the turn puts them on the nearest axis, and a
    /// tilted view of the same stripes gives the same direction on the plane.
    #[test]
    fn frontal_stripes_give_their_direction() {
        let (w, h) = (96, 80);
        let mask = vec![true; w * h];
        let coords = plane_coords(w, h, &mask, Vec3::Z, 100.0, None);
        for grad in [0.0f32, 20.0, 35.0, 60.0, 100.0, 150.0] {
            let luma = stripes(w, h, grad, 12.0);
            let g = measure(&coords, &mask, &luma).unwrap();
            let along = grad + 90.0;
            assert!(line_off(g.angle_deg, along) < 0.2, "{grad}: {g:?}");
            assert!(
                g.coherence > 0.9 && g.photo_coherence > 0.9,
                "{grad}: {g:?}"
            );
            assert!(g.sampling_coherence < 0.05, "{grad}: {g:?}");
            let axis = g.angle_deg - g.turn_deg;
            assert!((axis / 90.0 - (axis / 90.0).round()).abs() < 1e-4, "{g:?}");
            assert!(g.turn_deg.abs() <= 45.0);
            assert_eq!(
                g.decisive(),
                line_off(along, 0.0).min(line_off(along, 90.0)) >= MIN_TURN_DEG
            );
        }
    }

    /// A floor seen obliquely with the camera rolled: the stripes drawn on
    /// the plane at 30° to its x axis; measured through the rectification,
    /// turned by the basis, they come out along an axis of the square.
    #[test]
    fn turned_axes_put_the_grain_on_an_axis() {
        let (w, h, f) = (160, 120, 140.0f32);
        let n = Vec3::new(0.25, 0.85, 0.45).normalize();
        let (e1, e2) = plane_basis(n, None);
        let dir = (e1 * 30f32.to_radians().cos() + e2 * 30f32.to_radians().sin()).normalize();
        let across = n.cross(dir);
        // The photo: each pixel's ray meets the plane N·P = −1 at P; its
        // luminance is the stripe at P (period 0.08 across `dir`).
        let (cx, cy) = (w as f32 / 2.0, h as f32 / 2.0);
        let luma: Vec<f32> = (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f32 + 0.5, (i / w) as f32 + 0.5);
                let d = Vec3::new((x - cx) / f, -(y - cy) / f, -1.0);
                let p = -d / n.dot(d);
                0.5 + 0.4 * (std::f32::consts::TAU * p.dot(across) / 0.08).sin()
            })
            .collect();
        let mask: Vec<bool> = (0..w * h).map(|i| i / w > h / 3).collect();
        let c = plane_coords(w, h, &mask, n, f, None);
        let g = measure(&c, &mask, &luma).unwrap();
        assert!(line_off(g.angle_deg, -30.0) < 0.5, "{g:?}");
        assert!(g.decisive(), "{g:?}");
        let turned = e1 * g.along[0] - e2 * g.along[1];
        let c2 = plane_coords(w, h, &mask, n, f, Some(turned));
        let g2 = measure(&c2, &mask, &luma).unwrap();
        assert!(g2.turn_deg.abs() < 2.0, "{g2:?}");
        assert!(!g2.decisive());
    }

    /// The closed form against a brute-force search: the direction that
    /// minimises `dᵀSd` over half a turn in 0.01° steps, on seeded random
    /// tensors (and the coherence from the two extreme values).
    #[test]
    fn minor_direction_matches_a_search() {
        let mut rng = picker_tensor::Rng::new(11);
        for _ in 0..200 {
            let (p, q, r) = (
                rng.f64() * 2.0 - 1.0,
                rng.f64() * 2.0 - 1.0,
                rng.f64() * 2.0 - 1.0,
            );
            // S = AᵀA is symmetric positive semi-definite.
            let (a, b, c) = (p * p + r * r, p * q, q * q + r * r * 0.3);
            let (d, coh) = minor_direction(a, b, c).unwrap();
            let quad = |t: f64| {
                let (x, y) = (t.cos(), t.sin());
                a * x * x + 2.0 * b * x * y + c * y * y
            };
            let ts: Vec<f64> = (0..18_000)
                .map(|k| (k as f64 * 0.01).to_radians())
                .collect();
            let lo = ts
                .iter()
                .cloned()
                .fold(f64::INFINITY, |m, t| m.min(quad(t)));
            let hi = ts.iter().cloned().fold(0.0f64, |m, t| m.max(quad(t)));
            assert!(
                (quad(d[1].atan2(d[0])) - lo).abs() <= 1e-6 * (a + c),
                "{a} {b} {c}"
            );
            assert!((coh - (hi - lo) / (hi + lo)).abs() < 1e-6, "{a} {b} {c}");
        }
        assert!(minor_direction(0.0, 0.0, 0.0).is_none());
        assert!(minor_direction(f64::NAN, 0.0, 1.0).is_none());
        // Isotropic: no preferred direction, coherence 0.
        assert_eq!(minor_direction(2.0, 0.0, 2.0).unwrap().1, 0.0);
    }

    /// Nothing to measure: no picked 3×3 neighbourhood, a flat photo, a
    /// frame too small, coordinates that are not finite.
    #[test]
    fn nothing_to_measure_gives_none() {
        let (w, h) = (20, 16);
        let all = vec![true; w * h];
        let coords = plane_coords(w, h, &all, Vec3::Z, 30.0, None);
        let luma = stripes(w, h, 30.0, 6.0);
        assert!(measure(&coords, &all, &vec![0.3; w * h]).is_none());
        let checker: Vec<bool> = (0..w * h).map(|i| (i % w + i / w) % 2 == 0).collect();
        assert!(measure(&coords, &checker, &luma).is_none());
        assert!(measure(&coords, &vec![false; w * h], &luma).is_none());
        let mut nan = coords.clone();
        nan.u.iter_mut().for_each(|u| *u = f32::NAN);
        assert!(measure(&nan, &all, &luma).is_none());
        let tiny = plane_coords(2, 2, &[true; 4], Vec3::Z, 30.0, None);
        assert!(measure(&tiny, &[true; 4], &[0.1, 0.5, 0.2, 0.9]).is_none());
        assert!(measure(&coords, &all, &luma).is_some());
    }
}
