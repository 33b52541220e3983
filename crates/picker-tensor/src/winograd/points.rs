//! The transform matrices of the Winograd tile sizes, written once for
//! every kind of lane ([`Arith`]: one `f32`, or a vector of them), so the
//! generic transforms and the intrinsics ones do the same operations in the
//! same order.
//!
//! - [`F4`]: F(4×4, 3×3), 6×6 input tiles, the points 0, ±1, ±2, ∞.
//! - [`F5`]: F(5×5, 3×3), 7×7 input tiles, the points 0, ±1, ±2, ½, ∞: 49
//!   products per 25 outputs, for maps whose tiles fill whole panels in it
//!   (30×40: 48 tiles, one panel of 48, where F(4×4) takes 80 and F(6×6) 35
//!   of 48 lanes); its rounding error lies between F4's and F6's.
//! - [`F6`]: F(6×6, 3×3), 8×8 input tiles, the points 0, ±1, ±2, ±½, ∞
//!   (Lavin & Gray 2016; the points Barabasz et al. 2018 found the most
//!   accurate in f32). 64 products per 36 outputs instead of 36 per 16: 21%
//!   fewer multiplications, for about twice F4's rounding error (measured on a
//!   256-channel layer with outputs of standard deviation 1.4: max 5.6e-5 vs
//!   3.5e-5 against f64).
//! - [`S4`]: F(4×4, 3×3) with stride 2, 9×9 input tiles: per axis the
//!   kernel's even taps `(g₀, g₂)` correlate the even inputs by F(4, 2)
//!   (the points 0, ±1, 2, ∞) and its odd tap `g₁` the odd inputs one by
//!   one, so the two phases' sums meet in the output transform: 9 points per
//!   4 outputs, 81 products per 16 outputs instead of 144 (a direct stride-2
//!   layer): the polyphase split of a strided convolution with each phase
//!   by its own 1-D Winograd algorithm.
//! - [`S5`]: F(5×5, 3×3) with stride 2, 11×11 input tiles: per axis F(5, 2)
//!   on the even inputs (the points 0, ±1, ±2, ∞: F4's `Bᵀ` up to row
//!   signs) and the odd inputs times `g₁`: 11 points per 5 outputs, 121
//!   products per 25 outputs (4.84 per output against S4's 5.06), for maps
//!   whose tiles fill whole panels in it (a 30×40 output is 48 tiles, one
//!   panel of 48, where S4 takes 80 in two).

/// The arithmetic the transforms need, for one lane type.
pub(crate) trait Arith: Copy {
    /// `self + o`.
    fn add(self, o: Self) -> Self;
    /// `self − o`.
    fn sub(self, o: Self) -> Self;
    /// `self · k`.
    fn mul(self, k: f32) -> Self;
}

impl Arith for f32 {
    #[inline(always)]
    fn add(self, o: Self) -> Self {
        self + o
    }
    #[inline(always)]
    fn sub(self, o: Self) -> Self {
        self - o
    }
    #[inline(always)]
    fn mul(self, k: f32) -> Self {
        self * k
    }
}

/// One tile size: `T` points per axis of the transformed tile, `M` outputs
/// per tile side; an input tile is `T` pixels wide and its successor starts
/// `M · STRIDE` pixels on (`T = (M − 1) · STRIDE + 3` for a 3×3 kernel).
pub(crate) trait Points<const T: usize, const M: usize> {
    /// The convolution's stride.
    const STRIDE: usize = 1;
    /// `Bᵀ d`: one axis of the input transform.
    fn bt<A: Arith>(d: [A; T]) -> [A; T];
    /// `Aᵀ m`: one axis of the output transform.
    fn at<A: Arith>(m: [A; T]) -> [A; M];
    /// `G x` for one column `(x0, x1, x2)` of a 3×3 kernel.
    fn g<A: Arith>(x0: A, x1: A, x2: A) -> [A; T];
}

/// F(4×4, 3×3).
pub(crate) struct F4;

impl Points<6, 4> for F4 {
    #[inline(always)]
    fn bt<A: Arith>(d: [A; 6]) -> [A; 6] {
        [
            d[0].mul(4.0).sub(d[2].mul(5.0)).add(d[4]),
            d[1].mul(-4.0).sub(d[2].mul(4.0)).add(d[3]).add(d[4]),
            d[1].mul(4.0).sub(d[2].mul(4.0)).sub(d[3]).add(d[4]),
            d[1].mul(-2.0).sub(d[2]).add(d[3].mul(2.0)).add(d[4]),
            d[1].mul(2.0).sub(d[2]).sub(d[3].mul(2.0)).add(d[4]),
            d[1].mul(4.0).sub(d[3].mul(5.0)).add(d[5]),
        ]
    }

    #[inline(always)]
    fn at<A: Arith>(m: [A; 6]) -> [A; 4] {
        [
            m[0].add(m[1]).add(m[2]).add(m[3]).add(m[4]),
            m[1].sub(m[2]).add(m[3].sub(m[4]).mul(2.0)),
            m[1].add(m[2]).add(m[3].add(m[4]).mul(4.0)),
            m[1].sub(m[2]).add(m[3].sub(m[4]).mul(8.0)).add(m[5]),
        ]
    }

    /// `G` (6×3) has the rows `[¼ 0 0] [−⅙ −⅙ −⅙] [−⅙ ⅙ −⅙] [1/24 1/12 ⅙]
    /// [1/24 −1/12 ⅙] [0 0 1]`.
    #[inline(always)]
    fn g<A: Arith>(x0: A, x1: A, x2: A) -> [A; 6] {
        let (a, b) = (x0.add(x2), x1);
        let c = x0.mul(1.0 / 24.0).add(x2.mul(1.0 / 6.0));
        [
            x0.mul(0.25),
            a.add(b).mul(-(1.0 / 6.0)),
            a.sub(b).mul(-(1.0 / 6.0)),
            c.add(b.mul(1.0 / 12.0)),
            c.sub(b.mul(1.0 / 12.0)),
            x2,
        ]
    }
}

/// F(5×5, 3×3).
pub(crate) struct F5;

impl Points<7, 5> for F5 {
    /// `Bᵀ` (7×7), each row of `V⁻ᵀ` for the points 0, ±1, ±2, ½, ∞ scaled
    /// to integers (`G` scaled back): `[4 −8 −5 10 1 −2 0]`,
    /// `[0 −4 4 9 −1 −2 0]`, `[0 −4 12 −7 −3 2 0]`, `[0 2 −3 −4 3 2 0]`,
    /// `[0 2 −5 0 5 −2 0]`, `[0 4 0 −5 0 1 0]`, `[0 −4 8 5 −10 −1 2]`.
    #[inline(always)]
    fn bt<A: Arith>(d: [A; 7]) -> [A; 7] {
        [
            d[0].mul(4.0)
                .sub(d[1].mul(8.0))
                .sub(d[2].mul(5.0))
                .add(d[3].mul(10.0))
                .add(d[4])
                .sub(d[5].mul(2.0)),
            d[2].sub(d[1])
                .mul(4.0)
                .add(d[3].mul(9.0))
                .sub(d[4])
                .sub(d[5].mul(2.0)),
            d[2].mul(12.0)
                .sub(d[1].mul(4.0))
                .sub(d[3].mul(7.0))
                .sub(d[4].mul(3.0))
                .add(d[5].mul(2.0)),
            d[1].add(d[5])
                .mul(2.0)
                .sub(d[2].mul(3.0))
                .sub(d[3].mul(4.0))
                .add(d[4].mul(3.0)),
            d[1].sub(d[5]).mul(2.0).add(d[4].sub(d[2]).mul(5.0)),
            d[1].mul(4.0).sub(d[3].mul(5.0)).add(d[5]),
            d[2].mul(8.0)
                .sub(d[1].mul(4.0))
                .add(d[3].mul(5.0))
                .sub(d[4].mul(10.0))
                .sub(d[5])
                .add(d[6].mul(2.0)),
        ]
    }

    /// `Aᵀ` (5×7) has the rows `[1 1 1 1 1 1 0]` and
    /// `[0 1 (−1)ⁱ 2ⁱ (−2)ⁱ 2⁻ⁱ δᵢ₄]` for `i = 1..5`.
    #[inline(always)]
    fn at<A: Arith>(m: [A; 7]) -> [A; 5] {
        let (a, b) = (m[1].add(m[2]), m[1].sub(m[2]));
        let (c, d) = (m[3].add(m[4]), m[3].sub(m[4]));
        [
            m[0].add(a).add(c).add(m[5]),
            b.add(d.mul(2.0)).add(m[5].mul(0.5)),
            a.add(c.mul(4.0)).add(m[5].mul(0.25)),
            b.add(d.mul(8.0)).add(m[5].mul(0.125)),
            a.add(c.mul(16.0)).add(m[5].mul(0.0625)).add(m[6]),
        ]
    }

    /// `G` (7×3) has the rows `[¼ 0 0] [⅙ ⅙ ⅙] [1/18 −1/18 1/18]
    /// [1/72 1/36 1/18] [1/120 −1/60 1/30] [32/45 16/45 8/45] [0 0 ½]`.
    #[inline(always)]
    fn g<A: Arith>(x0: A, x1: A, x2: A) -> [A; 7] {
        let p = x0.add(x2);
        [
            x0.mul(0.25),
            p.add(x1).mul(1.0 / 6.0),
            p.sub(x1).mul(1.0 / 18.0),
            x0.mul(1.0 / 72.0)
                .add(x1.mul(1.0 / 36.0))
                .add(x2.mul(1.0 / 18.0)),
            x0.mul(1.0 / 120.0)
                .sub(x1.mul(1.0 / 60.0))
                .add(x2.mul(1.0 / 30.0)),
            x0.mul(32.0 / 45.0)
                .add(x1.mul(16.0 / 45.0))
                .add(x2.mul(8.0 / 45.0)),
            x2.mul(0.5),
        ]
    }
}

/// F(6×6, 3×3).
pub(crate) struct F6;

impl Points<8, 6> for F6 {
    /// `Bᵀ` (8×8) has the rows `[1 0 −21/4 0 21/4 0 −1 0]`,
    /// `[0 ±1 1 ∓17/4 −17/4 ±1 1 0]`, `[0 ±½ ¼ ∓5/2 −5/4 ±2 1 0]`,
    /// `[0 ±2 4 ∓5/2 −5 ±½ 1 0]` and `[0 −1 0 21/4 0 −21/4 0 1]`.
    #[inline(always)]
    fn bt<A: Arith>(d: [A; 8]) -> [A; 8] {
        let e1 = d[2].add(d[6]).sub(d[4].mul(4.25));
        let o1 = d[1].add(d[5]).sub(d[3].mul(4.25));
        let e2 = d[2].mul(0.25).sub(d[4].mul(1.25)).add(d[6]);
        let o2 = d[1].mul(0.5).sub(d[3].mul(2.5)).add(d[5].mul(2.0));
        let e3 = d[2].mul(4.0).sub(d[4].mul(5.0)).add(d[6]);
        let o3 = d[1].mul(2.0).sub(d[3].mul(2.5)).add(d[5].mul(0.5));
        [
            d[0].sub(d[6]).add(d[4].sub(d[2]).mul(5.25)),
            e1.add(o1),
            e1.sub(o1),
            e2.add(o2),
            e2.sub(o2),
            e3.add(o3),
            e3.sub(o3),
            d[7].sub(d[1]).add(d[3].sub(d[5]).mul(5.25)),
        ]
    }

    /// `Aᵀ` (6×8) has the rows `[1 1 1 1 1 1 1 0]` and
    /// `[0 1 (−1)ⁱ 2ⁱ (−2)ⁱ 2⁻ⁱ (−½)ⁱ δᵢ₅]` for `i = 1..6`.
    #[inline(always)]
    fn at<A: Arith>(m: [A; 8]) -> [A; 6] {
        let (a, b) = (m[1].add(m[2]), m[1].sub(m[2]));
        let (c, d) = (m[3].add(m[4]), m[3].sub(m[4]));
        let (e, f) = (m[5].add(m[6]), m[5].sub(m[6]));
        [
            m[0].add(a).add(c).add(e),
            b.add(d.mul(2.0)).add(f.mul(0.5)),
            a.add(c.mul(4.0)).add(e.mul(0.25)),
            b.add(d.mul(8.0)).add(f.mul(0.125)),
            a.add(c.mul(16.0)).add(e.mul(0.0625)),
            b.add(d.mul(32.0)).add(f.mul(0.03125)).add(m[7]),
        ]
    }

    /// `G` (8×3) has the rows `[1 0 0] [−2/9 ∓2/9 −2/9] [1/90 ±1/45 2/45]
    /// [32/45 ±16/45 8/45] [0 0 1]`.
    #[inline(always)]
    fn g<A: Arith>(x0: A, x1: A, x2: A) -> [A; 8] {
        let p = x0.add(x2);
        let c1 = x0.mul(1.0 / 90.0).add(x2.mul(2.0 / 45.0));
        let c2 = x0.mul(32.0 / 45.0).add(x2.mul(8.0 / 45.0));
        [
            x0,
            p.add(x1).mul(-(2.0 / 9.0)),
            p.sub(x1).mul(-(2.0 / 9.0)),
            c1.add(x1.mul(1.0 / 45.0)),
            c1.sub(x1.mul(1.0 / 45.0)),
            c2.add(x1.mul(16.0 / 45.0)),
            c2.sub(x1.mul(16.0 / 45.0)),
            x2,
        ]
    }
}

/// F(4×4, 3×3) with stride 2. One axis: the input `d₀ … d₈`, the output
/// `yᵢ = g₀ d₂ᵢ + g₁ d₂ᵢ₊₁ + g₂ d₂ᵢ₊₂`. Points 0–4 are F(4, 2) of the even
/// inputs `eⱼ = d₂ⱼ` with the taps `(g₀, g₂)` (its `Bᵀ` rows scaled to
/// integers, `G` scaled back), points 5–8 the odd inputs `d₁, d₃, d₅, d₇`
/// times `g₁`.
pub(crate) struct S4;

impl Points<9, 4> for S4 {
    const STRIDE: usize = 2;

    /// `Bᵀ` of the even phase (5×5): `[2 −1 −2 1 0] [0 2 1 −1 0]
    /// [0 −2 3 −1 0] [0 −1 0 1 0] [0 2 −1 −2 1]`; the odd phase passes.
    #[inline(always)]
    fn bt<A: Arith>(d: [A; 9]) -> [A; 9] {
        let (e0, e1, e2, e3, e4) = (d[0], d[2], d[4], d[6], d[8]);
        let t = e3.sub(e1);
        [
            e0.sub(e2).mul(2.0).add(t),
            e1.mul(2.0).add(e2).sub(e3),
            e2.mul(3.0).sub(e1.mul(2.0)).sub(e3),
            t,
            e1.sub(e3).mul(2.0).sub(e2).add(e4),
            d[1],
            d[3],
            d[5],
            d[7],
        ]
    }

    /// `Aᵀ` of the even phase (4×5): `[1 1 1 1 0] [0 1 −1 2 0] [0 1 1 4 0]
    /// [0 1 −1 8 1]`, plus the odd phase's point of each output.
    #[inline(always)]
    fn at<A: Arith>(m: [A; 9]) -> [A; 4] {
        let (a, b) = (m[1].add(m[2]), m[1].sub(m[2]));
        [
            m[0].add(a).add(m[3]).add(m[5]),
            b.add(m[3].mul(2.0)).add(m[6]),
            a.add(m[3].mul(4.0)).add(m[7]),
            b.add(m[3].mul(8.0)).add(m[4]).add(m[8]),
        ]
    }

    /// `G` of the even phase (5×2, on `(x₀, x₂)`): `[½ 0] [½ ½] [⅙ −⅙]
    /// [⅙ ⅓] [0 1]`; the odd phase's points are `x₁`.
    #[inline(always)]
    fn g<A: Arith>(x0: A, x1: A, x2: A) -> [A; 9] {
        [
            x0.mul(0.5),
            x0.add(x2).mul(0.5),
            x0.sub(x2).mul(1.0 / 6.0),
            x0.add(x2.mul(2.0)).mul(1.0 / 6.0),
            x2,
            x1,
            x1,
            x1,
            x1,
        ]
    }
}

/// F(5×5, 3×3) with stride 2. One axis: the input `d₀ … d₁₀`, the output
/// `yᵢ = g₀ d₂ᵢ + g₁ d₂ᵢ₊₁ + g₂ d₂ᵢ₊₂`. Points 0–5 are F(5, 2) of the even
/// inputs `eⱼ = d₂ⱼ` with the taps `(g₀, g₂)` (its `Bᵀ` rows scaled to
/// integers, `G` scaled back), points 6–10 the odd inputs `d₁, d₃, … d₉`
/// times `g₁`.
pub(crate) struct S5;

impl Points<11, 5> for S5 {
    const STRIDE: usize = 2;

    /// `Bᵀ` of the even phase (6×6): `[4 0 −5 0 1 0] [0 4 4 −1 −1 0]
    /// [0 −4 4 1 −1 0] [0 −2 −1 2 1 0] [0 2 −1 −2 1 0] [0 4 0 −5 0 1]`; the
    /// odd phase passes.
    #[inline(always)]
    fn bt<A: Arith>(d: [A; 11]) -> [A; 11] {
        let (e0, e1, e2, e3, e4, e5) = (d[0], d[2], d[4], d[6], d[8], d[10]);
        let (p, q) = (e2.mul(4.0).sub(e4), e1.mul(4.0).sub(e3));
        let (r, t) = (e4.sub(e2), e3.sub(e1).mul(2.0));
        [
            e0.mul(4.0).sub(e2.mul(5.0)).add(e4),
            p.add(q),
            p.sub(q),
            r.add(t),
            r.sub(t),
            e1.mul(4.0).sub(e3.mul(5.0)).add(e5),
            d[1],
            d[3],
            d[5],
            d[7],
            d[9],
        ]
    }

    /// `Aᵀ` of the even phase (5×6): `[1 1 1 1 1 0]` and
    /// `[0 1 (−1)ⁱ 2ⁱ (−2)ⁱ δᵢ₄]` for `i = 1..5`, plus the odd phase's point
    /// of each output.
    #[inline(always)]
    fn at<A: Arith>(m: [A; 11]) -> [A; 5] {
        let (a, b) = (m[1].add(m[2]), m[1].sub(m[2]));
        let (c, d) = (m[3].add(m[4]), m[3].sub(m[4]));
        [
            m[0].add(a).add(c).add(m[6]),
            b.add(d.mul(2.0)).add(m[7]),
            a.add(c.mul(4.0)).add(m[8]),
            b.add(d.mul(8.0)).add(m[9]),
            a.add(c.mul(16.0)).add(m[5]).add(m[10]),
        ]
    }

    /// `G` of the even phase (6×2, on `(x₀, x₂)`): `[¼ 0] [⅙ ⅙] [⅙ −⅙]
    /// [1/24 1/12] [1/24 −1/12] [0 1]`; the odd phase's points are `x₁`.
    #[inline(always)]
    fn g<A: Arith>(x0: A, x1: A, x2: A) -> [A; 11] {
        let (s, t) = (x0.add(x2), x0.sub(x2));
        let (c, e) = (x0.mul(1.0 / 24.0), x2.mul(1.0 / 12.0));
        [
            x0.mul(0.25),
            s.mul(1.0 / 6.0),
            t.mul(1.0 / 6.0),
            c.add(e),
            c.sub(e),
            x2,
            x1,
            x1,
            x1,
            x1,
            x1,
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `Aᵀ [(G g) ⊙ (Bᵀ d)]` is the 1-D correlation of `d` with `g`, in f64
    /// arithmetic to f32 rounding (the exact identity the 2-D transform is
    /// the square of).
    fn correlates<const T: usize, const M: usize, W: Points<T, M>>() {
        let mut rng = crate::Rng::new(5);
        for _ in 0..50 {
            let d: [f32; T] = std::array::from_fn(|_| rng.normal());
            let g: [f32; 3] = std::array::from_fn(|_| rng.normal());
            let (u, v) = (W::g(g[0], g[1], g[2]), W::bt(d));
            let y = W::at(std::array::from_fn(|k| u[k] * v[k]));
            assert_eq!(T, (M - 1) * W::STRIDE + 3, "tile width");
            for (i, &yi) in y.iter().enumerate() {
                let s = W::STRIDE * i;
                let exact: f64 = (0..3).map(|k| d[s + k] as f64 * g[k] as f64).sum();
                assert!(
                    (yi as f64 - exact).abs() < 1e-5 * (1.0 + exact.abs()),
                    "output {i}: {yi} vs {exact}"
                );
            }
        }
    }

    #[test]
    fn f4_points_correlate() {
        correlates::<6, 4, F4>();
    }

    #[test]
    fn f5_points_correlate() {
        correlates::<7, 5, F5>();
    }

    #[test]
    fn f6_points_correlate() {
        correlates::<8, 6, F6>();
    }

    #[test]
    fn s4_points_correlate_with_stride_two() {
        correlates::<9, 4, S4>();
    }

    #[test]
    fn s5_points_correlate_with_stride_two() {
        correlates::<11, 5, S5>();
    }
}
