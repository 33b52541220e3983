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
pub fn tone_map_rgb(planes: &[f32], n: usize) -> Vec<f32> {
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
}
