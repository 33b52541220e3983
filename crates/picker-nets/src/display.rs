//! Display encodings for 8-bit previews of decoded render elements (files
//! meant for exact values, such as EXR, hold the decoded values themselves).
//! Part of the conventions: re-exported from [`crate::conventions`].

/// The sRGB transfer function (IEC 61966-2-1): linear `[0, 1]` → encoded `[0, 1]`.
/// Values outside `[0, 1]` are clamped; NaN gives 0.
pub fn srgb_encode(linear: f32) -> f32 {
    if linear.is_nan() {
        return 0.0;
    }
    let l = linear.clamp(0.0, 1.0);
    if l <= 0.003_130_8 {
        12.92 * l
    } else {
        1.055 * l.powf(1.0 / 2.4) - 0.055
    }
}

/// Reinhard's key for the global operator: a middle-grey scene maps to this.
pub const TONE_MAP_KEY: f32 = 0.18;

/// Tone-maps planar linear HDR RGB (`3` planes of `n` pixels) for display:
/// Reinhard et al. 2002's global operator with automatic exposure — scale so
/// the log-average Rec. 709 luminance becomes [`TONE_MAP_KEY`], then
/// `c / (1 + c)` per channel — followed by [`srgb_encode`].
///
/// # Panics
/// When `planes` holds fewer than three planes of `n` values (further planes
/// are ignored).
pub fn tone_map_rgb(planes: &[f32], n: usize) -> Vec<f32> {
    assert!(
        n.checked_mul(3).is_some_and(|m| planes.len() >= m),
        "tone_map_rgb: expected 3 planes of {n} values, got {} values",
        planes.len()
    );
    let (r, rest) = planes.split_at(n);
    let (g, b) = rest.split_at(n);
    let mut log_sum = 0.0f64;
    for i in 0..n {
        let y = 0.2126 * r[i] + 0.7152 * g[i] + 0.0722 * b[i];
        let y = if y.is_finite() { y.max(0.0) } else { 0.0 };
        log_sum += (1e-4 + y as f64).ln();
    }
    let log_avg = if n > 0 {
        (log_sum / n as f64).exp() as f32
    } else {
        1.0
    };
    let scale = TONE_MAP_KEY / log_avg.max(1e-6);
    planes
        .iter()
        .map(|&v| {
            let c = if v.is_finite() {
                v.max(0.0) * scale
            } else {
                0.0
            };
            srgb_encode(c / (1.0 + c))
        })
        .collect()
}

/// Where [`soft_clip`] leaves the identity: linear values up to this are
/// shown as they are, brighter ones roll off towards 1.
pub const SOFT_CLIP_KNEE: f32 = 0.8;

/// A display curve for exposed linear values: the identity up to
/// [`SOFT_CLIP_KNEE`], then `k + (1 − k)(1 − e^{−(x − k)/(1 − k)})`, which
/// meets it with the same slope and approaches 1, so highlights keep
/// their gradation instead of clipping flat. Negative values give 0, NaN 0,
/// +∞ 1.
pub fn soft_clip(x: f32) -> f32 {
    if x.is_nan() || x <= 0.0 {
        return 0.0;
    }
    let k = SOFT_CLIP_KNEE;
    if x <= k {
        x
    } else {
        k + (1.0 - k) * -(-(x - k) / (1.0 - k)).exp_m1()
    }
}

/// Planar linear RGB multiplied by `exposure`, then [`soft_clip`] and
/// [`srgb_encode`] per value: the display of an image whose exposure is
/// known (e.g. a material preview exposed by its lighting), unlike
/// [`tone_map_rgb`], which measures it from the pixels themselves. A
/// non-finite or negative `exposure` is treated as 0 (black).
pub fn expose_rgb(planes: &[f32], exposure: f32) -> Vec<f32> {
    let e = if exposure.is_finite() {
        exposure.max(0.0)
    } else {
        0.0
    };
    planes
        .iter()
        .map(|&v| srgb_encode(soft_clip(v * e)))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn srgb_curve() {
        assert_eq!(srgb_encode(0.0), 0.0);
        assert!((srgb_encode(1.0) - 1.0).abs() < 1e-6);
        assert!((srgb_encode(0.214_041) - 0.5).abs() < 1e-4);
        assert_eq!(srgb_encode(f32::NAN), 0.0);
        assert_eq!(srgb_encode(7.0), srgb_encode(1.0));
    }

    #[test]
    fn tone_map_is_bounded_and_monotone() {
        let planes = [0.0, 1.0, 1000.0, 0.0, 1.0, 1000.0, 0.0, 1.0, 1000.0];
        let d = tone_map_rgb(&planes, 3);
        assert!(d.iter().all(|v| (0.0..=1.0).contains(v)));
        assert!(d[0] < d[1] && d[1] < d[2]);
    }

    #[test]
    fn soft_clip_is_the_identity_then_rolls_off() {
        for x in [0.0, 0.01, 0.3, SOFT_CLIP_KNEE] {
            assert_eq!(soft_clip(x), x);
        }
        assert_eq!(soft_clip(-2.0), 0.0);
        assert_eq!(soft_clip(f32::NAN), 0.0);
        assert_eq!(soft_clip(f32::INFINITY), 1.0);
        // Continuous with slope 1 at the knee, monotone, below 1.
        let e = 1e-3;
        let slope = (soft_clip(SOFT_CLIP_KNEE + e) - soft_clip(SOFT_CLIP_KNEE)) / e;
        assert!((slope - 1.0).abs() < 1e-2, "{slope}");
        let mut last = soft_clip(SOFT_CLIP_KNEE);
        for i in 1..200 {
            let x = SOFT_CLIP_KNEE + i as f32 * 0.05;
            let y = soft_clip(x);
            // Strictly rising while f32 can tell (past ~4 it rounds to 1).
            assert!(
                if x < 3.0 { y > last } else { y >= last } && y <= 1.0,
                "{i} {y}"
            );
            last = y;
        }
    }

    #[test]
    fn expose_scales_before_the_curve() {
        let planes = [0.0, 0.1, 0.2, 10.0];
        let d = expose_rgb(&planes, 2.0);
        assert_eq!(d[0], 0.0);
        assert!((d[1] - srgb_encode(0.2)).abs() < 1e-7);
        assert!((d[2] - srgb_encode(0.4)).abs() < 1e-7);
        assert!(d[3] < 1.0 && d[3] > srgb_encode(0.99));
        assert!(expose_rgb(&planes, f32::NAN).iter().all(|&v| v == 0.0));
        assert!(expose_rgb(&planes, -1.0).iter().all(|&v| v == 0.0));
    }
}
