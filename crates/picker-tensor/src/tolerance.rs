//! Named numeric tolerances and a readable comparison, shared by every test.

/// `|found − expected| ≤ abs + rel·|expected|` element-wise.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Tolerance {
    /// Absolute part.
    pub abs: f32,
    /// Relative part.
    pub rel: f32,
}

impl Tolerance {
    /// A fast f32 kernel against its f64-accumulating reference.
    pub const KERNEL_F32: Tolerance = Tolerance {
        abs: 1e-4,
        rel: 1e-4,
    };
    /// Winograd F(4×4, 3×3) against the direct reference. Its transforms scale
    /// values by up to ~10², so it loses a few bits against a GEMM (measured:
    /// ~1.2e-5 max on O(1) outputs); it still meets the kernel tier.
    pub const WINOGRAD_F32: Tolerance = Tolerance {
        abs: 1e-4,
        rel: 1e-4,
    };
    /// The bf16 Winograd ([`crate::ConvAlgorithm::WinogradBf16`]) against the
    /// exact convolution, on outputs of standard deviation ~1 made from O(1)
    /// inputs: the transformed weights and inputs keep 8 significant bits
    /// (relative error ≤ 2⁻⁸ each), after the input transform has grown
    /// values up to ~30×. Measured: ≤ 0.2 over the kernel suite's shapes.
    pub const WINOGRAD_BF16: Tolerance = Tolerance { abs: 0.3, rel: 0.0 };
    /// Pure data movement (padding, cropping): exact.
    pub const EXACT: Tolerance = Tolerance { abs: 0.0, rel: 0.0 };
    /// Whole networks against the PyTorch reference, on tanh outputs in [-1, 1].
    pub const NET_E2E: Tolerance = Tolerance {
        abs: 1e-4,
        rel: 0.0,
    };
    /// Intermediate activations of whole networks against the PyTorch reference.
    pub const NET_ACTIVATION: Tolerance = Tolerance {
        abs: 1e-4,
        rel: 1e-4,
    };

    /// `Ok` when every pair is within tolerance, else a message naming the
    /// first mismatching index, the values and the largest error.
    pub fn check(&self, found: &[f32], expected: &[f32]) -> Result<(), String> {
        if found.len() != expected.len() {
            return Err(format!(
                "length mismatch: found {} expected {}",
                found.len(),
                expected.len()
            ));
        }
        let mut first = None;
        let mut worst = 0.0f32;
        for (i, (&f, &e)) in found.iter().zip(expected).enumerate() {
            let err = (f - e).abs();
            let ok = err <= self.abs + self.rel * e.abs() && f.is_finite() == e.is_finite();
            worst = if err.is_nan() {
                f32::INFINITY
            } else {
                worst.max(err)
            };
            if !ok && first.is_none() {
                first = Some((i, f, e));
            }
        }
        match first {
            None => Ok(()),
            Some((i, f, e)) => Err(format!(
                "first mismatch at index {i}: found {f}, expected {e} (|diff| {}); max |diff| {worst}; tolerance {self:?}",
                (f - e).abs()
            )),
        }
    }
}
