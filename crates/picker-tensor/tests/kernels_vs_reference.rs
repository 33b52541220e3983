//! Every fast kernel against its plain reference on seeded random problems,
//! for every micro-kernel family this CPU has (the others are reported as skipped).

use picker_tensor::{
    activate, add_assign, fold_batchnorm, mirror_pad, reference, reflect_pad, resize_bilinear,
    Activation, BatchNorm, Conv2d, ConvAlgorithm, ConvSpec, ConvTranspose2d, ConvTransposeSpec,
    Isa, Rng, Tensor, Tolerance, WeightLayout,
};

/// The families to test: available ones, with a line for each skipped one.
fn isas() -> Vec<Isa> {
    Isa::ALL
        .into_iter()
        .filter(|isa| {
            let ok = isa.is_available();
            if !ok {
                eprintln!("SKIPPED: micro-kernel family {isa} is not supported by this CPU");
            }
            ok
        })
        .collect()
}

/// The explicit algorithms that can run `spec` with `isa` on this CPU; a
/// bf16 algorithm the CPU cannot run is reported as skipped.
fn algorithms(isa: Isa, spec: &ConvSpec) -> Vec<ConvAlgorithm> {
    ConvAlgorithm::EXPLICIT
        .into_iter()
        .filter(|a| a.applies(spec))
        .filter(|a| {
            let ok = a.runs_on(isa);
            if !ok && isa == Isa::Avx512 {
                eprintln!("SKIPPED: {a:?} needs AVX512_BF16, which this CPU lacks");
            }
            ok
        })
        .collect()
}

/// The tolerance of an algorithm against the f64 reference.
fn tolerance(algo: ConvAlgorithm) -> Tolerance {
    match algo {
        a if a.is_bf16() => Tolerance::WINOGRAD_BF16,
        a if a.is_winograd() => Tolerance::WINOGRAD_F32,
        _ => Tolerance::KERNEL_F32,
    }
}

fn check(what: &str, found: &Tensor, expected: &Tensor, tol: Tolerance) {
    assert_eq!(found.shape(), expected.shape(), "{what}: shape");
    if let Err(e) = tol.check(found.data(), expected.data()) {
        panic!("{what}: {e}");
    }
}

/// One convolution problem.
#[derive(Clone, Copy, Debug)]
struct ConvProblem {
    n: usize,
    h: usize,
    w: usize,
    spec: ConvSpec,
    bias: bool,
    act: Activation,
    residual: bool,
}

impl ConvProblem {
    fn run(&self, isa: Isa, seed: u64) {
        let mut rng = Rng::new(seed);
        let s = self.spec;
        let x = rng.tensor([self.n, s.c_in, self.h, self.w]);
        let k = s.c_in * s.kh * s.kw;
        let wt = rng.normal_vec(s.weight_len(), (1.0 / k as f32).sqrt());
        let b = self.bias.then(|| rng.normal_vec(s.c_out, 0.5));
        let mut expected = reference::conv2d(&x, &wt, b.as_deref(), s).unwrap();
        expected = reference::activate(&expected, self.act);
        let r = rng.tensor(expected.shape());
        if self.residual {
            expected = reference::add(&expected, &r).unwrap();
        }
        for algo in algorithms(isa, &s) {
            let conv = Conv2d::with_algorithm(isa, algo, s, &wt, b.as_deref(), self.act).unwrap();
            assert_eq!(conv.algorithm(), algo);
            let found = if self.residual {
                conv.forward_add(&x, &r).unwrap()
            } else {
                conv.forward(&x).unwrap()
            };
            let tol = tolerance(algo);
            check(&format!("{isa} {algo:?} {self:?}"), &found, &expected, tol);
        }
    }
}

// One argument per dimension of the problem, in the order they are read in the table below.
#[allow(clippy::too_many_arguments)]
fn conv(
    n: usize,
    h: usize,
    w: usize,
    ci: usize,
    co: usize,
    k: usize,
    s: usize,
    p: usize,
) -> ConvProblem {
    ConvProblem {
        n,
        h,
        w,
        spec: ConvSpec::square(ci, co, k, s, p),
        bias: true,
        act: Activation::None,
        residual: false,
    }
}

/// Named shapes: the awkward ones and scaled-down versions of the real layers.
fn named_conv_problems() -> Vec<ConvProblem> {
    let relu = |p: ConvProblem| ConvProblem {
        act: Activation::Relu,
        ..p
    };
    let tanh = |p: ConvProblem| ConvProblem {
        act: Activation::Tanh,
        ..p
    };
    let res = |p: ConvProblem| ConvProblem {
        residual: true,
        bias: false,
        ..p
    };
    vec![
        conv(1, 1, 1, 1, 1, 1, 1, 0),          // 1x1 image, 1x1 kernel
        conv(1, 1, 1, 3, 5, 3, 1, 1),          // 1x1 image, 3x3 kernel, padding only
        conv(1, 7, 9, 3, 8, 7, 1, 3),          // 7x7 with 3 input channels
        relu(conv(1, 13, 11, 5, 17, 3, 2, 1)), // stride 2 on odd sizes, channels off the SIMD width
        relu(conv(2, 9, 14, 16, 12, 3, 2, 1)), // batch 2
        conv(1, 6, 7, 33, 9, 1, 2, 0),         // 1x1 stride 2
        // Pixel tiles: two output-channel panels (one partial), several
        // depth blocks, border tiles on every side and a partial last tile.
        res(relu(conv(1, 17, 29, 40, 80, 3, 2, 1))),
        relu(conv(1, 9, 40, 3, 64, 7, 2, 3)), // EnvMap input conv, stride 2
        conv(1, 10, 12, 20, 24, 1, 1, 0),     // 1x1 as plain GEMM
        res(conv(1, 12, 10, 24, 24, 3, 1, 0)), // ResBlock conv after reflect pad
        res(conv(2, 7, 5, 9, 9, 3, 1, 1)),
        tanh(conv(1, 14, 18, 8, 3, 7, 1, 0)), // decoder output conv
        conv(1, 5, 5, 2, 7, 5, 3, 2),         // stride 3, kernel 5
        conv(1, 4, 6, 3, 4, 3, 1, 4),         // padding larger than the kernel
        relu(conv(1, 20, 20, 70, 50, 3, 1, 1)), // K = 630: several K blocks
        conv(1, 3, 97, 2, 2, 1, 1, 0),        // N not a multiple of any NR, tiny M
        relu(conv(1, 30, 40, 64, 64, 3, 1, 1)), // many tasks, real-ish sizes
        res(conv(1, 17, 23, 40, 36, 3, 1, 0)), // Winograd: partial tiles on both axes
        relu(conv(1, 2, 3, 16, 16, 3, 1, 1)), // Winograd: one partial tile
        res(conv(1, 34, 44, 256, 256, 3, 1, 0)), // the ResBlock convs at full width
        res(conv(1, 50, 70, 40, 136, 3, 1, 0)), // Winograd: 5 panels (3 blocks, a narrow one), uneven chunks
        res(conv(1, 20, 26, 300, 40, 3, 1, 0)), // Winograd: two depth blocks (256 + 44 channels)
        tanh(conv(1, 11, 150, 6, 3, 7, 1, 0)),  // direct path: full and partial row blocks
        res(conv(2, 5, 70, 4, 4, 3, 1, 0)),     // direct path, 4 outputs, residual
        conv(1, 4, 66, 3, 2, 1, 1, 0),          // direct path, 1x1
        relu(conv(1, 9, 13, 6, 3, 7, 1, 2)),    // folded shifted GEMM with zero padding
        conv(1, 8, 70, 5, 2, 5, 1, 0),          // folded, two outputs, rows across panels
        tanh(conv(1, 7, 130, 9, 1, 7, 1, 3)),   // direct: one output, zero pad, 3 column blocks
        relu(conv(1, 1, 3, 2, 4, 3, 1, 1)),     // direct: one output row (half a row pair)
        tanh(conv(1, 25, 40, 6, 3, 7, 1, 3)),   // direct: three whole strips and one row
        relu(conv(1, 19, 21, 3, 10, 7, 2, 3)),  // shifted via phase planes, 7x7 stride 2
        conv(1, 23, 17, 9, 11, 3, 3, 1),        // phase planes, stride 3
        res(conv(1, 14, 28, 16, 16, 3, 1, 0)),  // Winograd: 28 tiles, one narrow panel (2 zmm)
        res(conv(1, 54, 34, 16, 24, 3, 1, 0)),  // Winograd: 104 tiles, several blocks, narrow tail
        // Winograd: tile rows of 33 tiles (three groups of 16 in the phase split,
        // runs across panel ends), tanh with bias and residual, zero padding.
        ConvProblem {
            act: Activation::Tanh,
            residual: true,
            ..conv(1, 9, 131, 5, 7, 3, 1, 1)
        },
        relu(conv(1, 5, 66, 3, 4, 3, 1, 2)), // Winograd: zero pad 2, 16 tiles + 1
        // Stride-2 Winograd: rows of 18 tiles (two groups of 16 in the
        // eight-phase split, runs across panel ends), a partial last tile
        // on both axes; even sizes with zero pad 0 and 2; one tile.
        res(relu(conv(1, 9, 141, 6, 8, 3, 2, 1))),
        relu(conv(1, 34, 50, 24, 40, 3, 2, 0)),
        tanh(conv(1, 16, 20, 17, 9, 3, 2, 2)),
        relu(conv(2, 3, 3, 16, 16, 3, 2, 1)),
        res(conv(1, 60, 80, 64, 128, 3, 2, 1)), // the EnvMap's first down conv at 1/2 scale
        // Stride-2 Winograd with 5×5 tiles (ten-phase split): rows of 18
        // tiles (two groups of 16, runs across panel ends); the EnvMap's
        // `down.1` at 32→48 channels (a 30×40 output: rows of 8 tiles, two
        // runs to a vector, 48 tiles in one panel); rows of 8 with a partial
        // last tile on both axes.
        relu(conv(1, 9, 171, 6, 8, 3, 2, 1)),
        res(conv(1, 60, 80, 32, 48, 3, 2, 1)),
        relu(conv(1, 27, 73, 5, 9, 3, 2, 1)),
        // F(5×5): the EnvMap's 30×40 blocks at 48 channels (48 tiles, one
        // panel); rows of 17 tiles (the five-phase split past one group of
        // 16, runs across panel ends) with a partial last tile.
        res(conv(1, 32, 42, 48, 40, 3, 1, 0)),
        relu(conv(1, 11, 86, 9, 7, 3, 1, 1)),
        // Rows of 7 F(4×4) tiles (40×28 output, 70 tiles): the AVX-512 input
        // transform packs two short runs into one vector, here also a
        // run of 6 and one of 1 around a panel's end.
        res(conv(1, 42, 30, 16, 24, 3, 1, 0)),
    ]
}

#[test]
fn conv2d_named_shapes() {
    for isa in isas() {
        for (i, p) in named_conv_problems().into_iter().enumerate() {
            p.run(isa, 1000 + i as u64);
        }
    }
}

#[test]
fn conv2d_random_shapes() {
    let mut rng = Rng::new(42);
    let isas = isas();
    for case in 0..60 {
        let k = [1, 2, 3, 5, 7][rng.range(0, 4)];
        let stride = rng.range(1, 3);
        let pad = rng.range(0, k);
        let h = rng.range(1, 19);
        let w = rng.range(1, 23);
        if h + 2 * pad < k || w + 2 * pad < k {
            continue;
        }
        let p = ConvProblem {
            n: rng.range(1, 2),
            h,
            w,
            spec: ConvSpec {
                c_in: rng.range(1, 40),
                c_out: rng.range(1, 40),
                kh: k,
                kw: k,
                stride,
                pad,
            },
            bias: rng.range(0, 1) == 1,
            act: [Activation::None, Activation::Relu, Activation::Tanh][rng.range(0, 2)],
            residual: rng.range(0, 3) == 0,
        };
        for &isa in &isas {
            p.run(isa, 5000 + case);
        }
    }
}

#[test]
fn auto_algorithm_choice() {
    let w = vec![0.01; 256 * 256 * 9];
    let pick_with = |algo: ConvAlgorithm, s: ConvSpec| {
        Conv2d::with_algorithm(
            Isa::best(),
            algo,
            s,
            &w[..s.weight_len()],
            None,
            Activation::None,
        )
        .unwrap()
        .algorithm()
    };
    // AutoLowMemory: the same choices, with the Winograd weights made per pass.
    for (auto, winograd) in [
        (ConvAlgorithm::Auto, ConvAlgorithm::Winograd),
        (
            ConvAlgorithm::AutoLowMemory,
            ConvAlgorithm::WinogradLowMemoryAutoTile,
        ),
    ] {
        let pick = |s: ConvSpec| pick_with(auto, s);
        if std::env::var_os("PICKER_WINOGRAD_WEIGHTS").is_none()
            && std::env::var_os("PICKER_MEMORY").is_none()
            && std::env::var_os("PICKER_PRECISION").is_none()
            && std::env::var_os("PICKER_WINOGRAD_TILE").is_none()
        {
            assert_eq!(pick(ConvSpec::square(256, 256, 3, 1, 0)), winograd);
        }
        assert_eq!(
            pick(ConvSpec::square(64, 3, 7, 1, 0)),
            ConvAlgorithm::Direct
        );
        // Strided layers: 3×3 stride 2 by Winograd on AVX-512, other
        // strided ones with output channels in the lanes there; else the
        // shifted GEMM over phase planes (also for few outputs).
        let (s2, strided) = if Isa::best() == Isa::Avx512 {
            let weights = std::env::var("PICKER_WINOGRAD_WEIGHTS");
            let lazy = weights.as_deref() == Ok("lazy")
                || std::env::var("PICKER_MEMORY").as_deref() == Ok("low")
                || (auto == ConvAlgorithm::AutoLowMemory && weights.as_deref() != Ok("packed"));
            // 5×5 output tiles, unless PICKER_WINOGRAD_S2_TILE=4 asks
            // for 4×4 ones.
            let forced = std::env::var("PICKER_WINOGRAD_S2_TILE");
            let tile = |lazy: bool| {
                let five = forced.as_deref() != Ok("4");
                match (five, lazy) {
                    (true, true) => ConvAlgorithm::Winograd5Stride2LowMemory,
                    (true, false) => ConvAlgorithm::Winograd5Stride2,
                    (false, true) => ConvAlgorithm::WinogradStride2LowMemory,
                    (false, false) => ConvAlgorithm::WinogradStride2,
                }
            };
            // Small transformed weights (at most 3 MB: 16 → 16, or 64 → 128
            // with 4×4 tiles, 2.7 MB; not with 5×5 ones, 4.0 MB) stay packed
            // unless asked.
            let unasked = std::env::var_os("PICKER_WINOGRAD_WEIGHTS").is_none()
                && std::env::var_os("PICKER_MEMORY").is_none();
            let small_lazy = lazy && !(unasked && auto == ConvAlgorithm::AutoLowMemory);
            let four = forced.as_deref() == Ok("4");
            (
                (
                    tile(lazy),
                    tile(if four { small_lazy } else { lazy }),
                    tile(small_lazy),
                ),
                ConvAlgorithm::PixelTiles,
            )
        } else {
            let s = ConvAlgorithm::Shifted;
            ((s, s, s), s)
        };
        let (s2, small_s2, tiny_s2) = s2;
        assert_eq!(pick(ConvSpec::square(128, 256, 3, 2, 1)), s2);
        assert_eq!(pick(ConvSpec::square(64, 128, 3, 2, 1)), small_s2);
        assert_eq!(pick(ConvSpec::square(16, 16, 3, 2, 1)), tiny_s2);
        assert_eq!(pick(ConvSpec::square(8, 128, 3, 2, 1)), strided);
        assert_eq!(pick(ConvSpec::square(256, 128, 3, 2, 1)), strided);
        assert_eq!(pick(ConvSpec::square(64, 128, 5, 2, 1)), strided);
        assert_eq!(
            pick(ConvSpec::square(128, 3, 3, 2, 1)),
            ConvAlgorithm::Shifted
        );
        assert_eq!(
            pick(ConvSpec::square(3, 64, 7, 1, 0)),
            ConvAlgorithm::Shifted
        );
        assert_eq!(pick(ConvSpec::square(64, 64, 1, 1, 0)), ConvAlgorithm::Gemm);
    }
    let s = ConvSpec::square(8, 8, 5, 1, 2);
    let w5 = &w[..s.weight_len()];
    let r = Conv2d::with_algorithm(
        Isa::Portable,
        ConvAlgorithm::Winograd,
        s,
        w5,
        None,
        Activation::None,
    );
    assert!(r.is_err(), "Winograd refuses 5x5 kernels");
}

#[test]
fn conv2d_rectangular_kernel() {
    for isa in isas() {
        let spec = ConvSpec {
            c_in: 4,
            c_out: 10,
            kh: 1,
            kw: 3,
            stride: 1,
            pad: 1,
        };
        ConvProblem {
            n: 1,
            h: 5,
            w: 6,
            spec,
            bias: true,
            act: Activation::None,
            residual: false,
        }
        .run(isa, 9);
    }
}

/// One transposed-convolution problem.
#[derive(Clone, Copy, Debug)]
struct ConvTProblem {
    n: usize,
    h: usize,
    w: usize,
    spec: ConvTransposeSpec,
    bias: bool,
    act: Activation,
}

impl ConvTProblem {
    fn run(&self, isa: Isa, seed: u64) {
        let mut rng = Rng::new(seed);
        let s = self.spec;
        let x = rng.tensor([self.n, s.c_in, self.h, self.w]);
        let wt = rng.normal_vec(s.weight_len(), (1.0 / (s.c_in * s.kh * s.kw) as f32).sqrt());
        let b = self.bias.then(|| rng.normal_vec(s.c_out, 0.5));
        let conv = ConvTranspose2d::with_isa(isa, s, &wt, b.as_deref(), self.act).unwrap();
        let expected = reference::activate(
            &reference::conv_transpose2d(&x, &wt, b.as_deref(), s).unwrap(),
            self.act,
        );
        let full = conv.forward(&x).unwrap();
        check(
            &format!("{isa} {self:?}"),
            &full,
            &expected,
            Tolerance::KERNEL_F32,
        );
        // Any window of output rows: the full output's rows, bit for bit.
        let (oh, ow) = (full.h(), full.w());
        let windows: Vec<(usize, usize)> = if oh <= 10 {
            (0..=oh)
                .flat_map(|a| (a..=oh).map(move |b| (a, b)))
                .collect()
        } else {
            (0..12)
                .map(|_| {
                    let a = rng.range(0, oh);
                    (a, rng.range(a, oh))
                })
                .chain([(0, oh), (0, 1), (oh - 1, oh)])
                .collect()
        };
        for (a, b) in windows {
            let part = conv.forward_rows(&x, a..b).unwrap();
            assert_eq!(
                part.shape(),
                [self.n, s.c_out, b - a, ow],
                "{isa} {self:?} rows {a}..{b}"
            );
            if b > a {
                let want = full.crop(a, 0, b - a, ow).unwrap();
                assert!(
                    part.data() == want.data(),
                    "{isa} {self:?}: rows {a}..{b} differ from the full output's"
                );
            }
        }
        assert!(
            conv.forward_rows(&x, 0..oh + 1).is_err(),
            "rows past the output"
        );
    }
}

/// `got(band)` equals `want` bit for bit at band sizes 1, 2, 3, a random
/// one, the whole output and past it, in rayon pools of 1, 2 and 3 threads
/// (the bands run in one contiguous run per thread).
fn same_in_bands(
    what: &str,
    want: &Tensor,
    rng: &mut Rng,
    got: impl Fn(usize) -> picker_tensor::Result<Tensor> + Sync,
) {
    near_in_bands(what, want, rng, None, got)
}

/// As [`same_in_bands`], or with `tol` within it (a Winograd `next`, whose
/// tiles a band cuts differently).
fn near_in_bands(
    what: &str,
    want: &Tensor,
    rng: &mut Rng,
    tol: Option<Tolerance>,
    got: impl Fn(usize) -> picker_tensor::Result<Tensor> + Sync,
) {
    let oh = want.h();
    let mut bands = vec![1, 2, 3, oh, oh + 5, rng.range(1, oh)];
    bands.dedup();
    for threads in [1, 2, 3] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        for &band in &bands {
            let got = pool.install(|| got(band)).unwrap();
            assert_eq!(got.shape(), want.shape(), "{what} band {band}");
            match tol {
                None => assert!(
                    got.data() == want.data(),
                    "{what} band {band}, {threads} threads: differs"
                ),
                Some(tol) => check(
                    &format!("{what} band {band}, {threads} threads"),
                    &got,
                    want,
                    tol,
                ),
            }
        }
    }
}

/// A transposed convolution followed by a reflection-padded convolution,
/// fused in bands ([`ConvTranspose2d::then_reflect_conv_bands`]), against the
/// two layers run one after the other: the same values bit for bit, at any
/// band size.
#[test]
fn conv_transpose_then_reflect_conv_in_bands() {
    let mut rng = Rng::new(91);
    let mut cases = vec![
        // The decoder's tail, scaled down: 3x3 stride-2 upsampling, 7x7 output conv.
        (
            1,
            6,
            8,
            ConvTransposeSpec::square(12, 16, 3, 2, 1, 1),
            ConvSpec::square(16, 3, 7, 1, 0),
            3,
        ),
        (
            2,
            5,
            7,
            ConvTransposeSpec::square(5, 9, 3, 2, 1, 1),
            ConvSpec::square(9, 4, 7, 1, 0),
            3,
        ),
        // Smallest output that a pad of 3 can reflect: 4 rows.
        (
            1,
            2,
            2,
            ConvTransposeSpec::square(3, 8, 3, 2, 1, 1),
            ConvSpec::square(8, 2, 7, 1, 0),
            3,
        ),
        // A pad wider than the kernel's reach (rows far from the band), stride 2.
        (
            1,
            5,
            4,
            ConvTransposeSpec::square(4, 6, 3, 2, 1, 1),
            ConvSpec::square(6, 5, 1, 2, 0),
            3,
        ),
        // Stride 1 upsampling, 3x3 output conv.
        (
            1,
            9,
            5,
            ConvTransposeSpec::square(7, 5, 3, 1, 1, 0),
            ConvSpec::square(5, 3, 3, 1, 0),
            1,
        ),
    ];
    for _ in 0..30 {
        let k = rng.range(1, 4);
        let s = rng.range(1, 3);
        let up = ConvTransposeSpec::square(
            rng.range(1, 12),
            rng.range(1, 20),
            k,
            s,
            rng.range(0, k - 1),
            rng.range(0, s - 1),
        );
        let (h, w) = (rng.range(1, 9), rng.range(1, 9));
        let Ok((oh, ow)) = up.out_hw(h, w) else {
            continue;
        };
        let pad = rng.range(0, oh.min(ow) - 1);
        let kk = rng.range(1, 7);
        let conv = ConvSpec {
            c_in: up.c_out,
            c_out: rng.range(1, 6),
            kh: kk,
            kw: rng.range(1, 7),
            stride: rng.range(1, 2),
            pad: 0,
        };
        if conv.out_hw(oh + 2 * pad, ow + 2 * pad).is_err() {
            continue;
        }
        cases.push((rng.range(1, 2), h, w, up, conv, pad));
    }
    assert!(cases.len() >= 25, "only {} cases", cases.len());
    for isa in isas() {
        for (i, &(n, h, w, up, cs, pad)) in cases.iter().enumerate() {
            let x = rng.tensor([n, up.c_in, h, w]);
            let uw = rng.normal_vec(up.weight_len(), 0.4);
            let ub = rng.normal_vec(up.c_out, 0.3);
            let cw = rng.normal_vec(cs.weight_len(), 0.2);
            let cb = rng.normal_vec(cs.c_out, 0.3);
            let upl = ConvTranspose2d::with_isa(isa, up, &uw, Some(&ub), Activation::Relu).unwrap();
            let conv = Conv2d::with_isa(isa, cs, &cw, Some(&cb), Activation::Tanh).unwrap();
            let want = conv
                .forward_reflect(&upl.forward(&x).unwrap(), pad, None)
                .unwrap();
            let what = format!("case {i} {isa}: {up:?} then {cs:?} pad {pad}");
            same_in_bands(&what, &want, &mut rng, |band| {
                upl.then_reflect_conv_bands(&x, &conv, pad, band)
            });
            let got = upl.then_reflect_conv(&x, &conv, pad).unwrap();
            assert!(
                got.data() == want.data(),
                "case {i} {isa}: default bands differ"
            );
        }
    }
}

/// A reflection-padded convolution followed by a zero-padded one, fused in
/// bands ([`Conv2d::reflect_then_bands`]), against the two layers run one
/// after the other: the same values bit for bit (a Winograd second layer:
/// within its rounding), at any band size and in pools of 1, 2 and 3 threads.
#[test]
fn reflect_conv_then_conv_in_bands() {
    let mut rng = Rng::new(93);
    let sq = ConvSpec::square;
    let mut cases = vec![
        // The IRN/MSN encoder's first two layers, scaled down.
        (1, 9, 12, sq(3, 16, 7, 1, 0), sq(16, 12, 3, 2, 1), 3),
        (2, 8, 7, sq(3, 8, 7, 1, 0), sq(8, 5, 3, 2, 1), 3),
        // The EnvMap's: a stride-2 first layer.
        (1, 11, 10, sq(3, 8, 7, 2, 0), sq(8, 6, 3, 2, 1), 3),
        // A second layer whose padding exceeds its kernel (rows of padding only).
        (1, 6, 5, sq(2, 4, 3, 1, 0), sq(4, 3, 1, 1, 2), 1),
        // Stride-2 Winograd second layers (AVX-512): the IRN/MSN's and the
        // EnvMap's heads at 16 and 24 channels, several default bands (the
        // last one short), and a head whose output rows are a whole number
        // of default bands (60).
        (1, 70, 38, sq(3, 16, 7, 1, 0), sq(16, 24, 3, 2, 1), 3),
        (1, 75, 41, sq(3, 16, 7, 2, 0), sq(16, 16, 3, 2, 1), 3),
        (1, 240, 20, sq(3, 16, 7, 2, 0), sq(16, 16, 3, 2, 1), 3),
        // A stride-1 Winograd second layer (AVX-512 or AVX2).
        (1, 37, 23, sq(3, 16, 7, 1, 0), sq(16, 16, 3, 1, 1), 3),
        // Stride 3 with a wide kernel.
        (1, 12, 9, sq(4, 5, 3, 1, 0), sq(5, 4, 5, 3, 2), 2),
    ];
    for _ in 0..30 {
        let (h, w) = (rng.range(2, 12), rng.range(2, 12));
        let pad = rng.range(0, h.min(w) - 1);
        let first = ConvSpec {
            c_in: rng.range(1, 5),
            c_out: rng.range(1, 12),
            kh: rng.range(1, 7),
            kw: rng.range(1, 7),
            stride: rng.range(1, 2),
            pad: 0,
        };
        let Ok((h1, w1)) = first.out_hw(h + 2 * pad, w + 2 * pad) else {
            continue;
        };
        let second = ConvSpec {
            c_in: first.c_out,
            c_out: rng.range(1, 8),
            kh: rng.range(1, 5),
            kw: rng.range(1, 5),
            stride: rng.range(1, 3),
            pad: rng.range(0, 3),
        };
        if second.out_hw(h1, w1).is_err() {
            continue;
        }
        cases.push((rng.range(1, 2), h, w, first, second, pad));
    }
    assert!(cases.len() >= 20, "only {} cases", cases.len());
    for isa in isas() {
        let mut winograd_cases = 0;
        for (i, &(n, h, w, fs, ss, pad)) in cases.iter().enumerate() {
            let x = rng.tensor([n, fs.c_in, h, w]);
            let fw = rng.normal_vec(fs.weight_len(), 0.3);
            let fb = rng.normal_vec(fs.c_out, 0.2);
            let sw = rng.normal_vec(ss.weight_len(), 0.3);
            let first = Conv2d::with_isa(isa, fs, &fw, Some(&fb), Activation::Relu).unwrap();
            let second = Conv2d::with_isa(isa, ss, &sw, None, Activation::Relu).unwrap();
            let want = second
                .forward(&first.forward_reflect(&x, pad, None).unwrap())
                .unwrap();
            let what = format!("case {i} {isa}: {fs:?} then {ss:?} pad {pad}");
            // A Winograd second layer gives the same values within its
            // rounding (its tiles fall differently in a band); a stride-2
            // one the same bits with the default bands whatever the threads
            // (its bands are a fixed number of rows).
            let stride2 = matches!(
                second.algorithm(),
                ConvAlgorithm::WinogradStride2
                    | ConvAlgorithm::WinogradStride2LowMemory
                    | ConvAlgorithm::Winograd5Stride2
                    | ConvAlgorithm::Winograd5Stride2LowMemory
            );
            let winograd = format!("{:?}", second.algorithm()).starts_with("Winograd");
            winograd_cases += usize::from(stride2);
            let tol = winograd.then(|| tolerance(second.algorithm()));
            near_in_bands(&what, &want, &mut rng, tol, |band| {
                first.reflect_then_bands(&x, pad, &second, band)
            });
            let got = first.reflect_then(&x, pad, &second).unwrap();
            if winograd {
                check(&what, &got, &want, tolerance(second.algorithm()));
            }
            if stride2 {
                for threads in [1, 3] {
                    let pool = rayon::ThreadPoolBuilder::new()
                        .num_threads(threads)
                        .build()
                        .unwrap();
                    let again = pool
                        .install(|| first.reflect_then(&x, pad, &second))
                        .unwrap();
                    assert!(
                        again.data() == got.data(),
                        "case {i} {isa}: default bands differ with {threads} threads"
                    );
                }
            } else if !winograd {
                assert!(
                    got.data() == want.data(),
                    "case {i} {isa}: default bands differ"
                );
            }
        }
        if isa == Isa::Avx512 {
            assert_eq!(winograd_cases, 3, "the stride-2 Winograd cases");
        }
    }
    // Refused: a first layer with zero padding, a reflection as large as
    // the input, mismatched channels, a band of 0 rows.
    let mk = |rng: &mut Rng, s: ConvSpec| {
        Conv2d::new(
            s,
            &rng.normal_vec(s.weight_len(), 0.3),
            None,
            Activation::None,
        )
        .unwrap()
    };
    let x = rng.tensor([1, 3, 4, 5]);
    let first = mk(&mut rng, sq(3, 4, 3, 1, 0));
    let second = mk(&mut rng, sq(4, 2, 3, 2, 1));
    assert!(first.reflect_then_bands(&x, 1, &second, 2).is_ok());
    let e = first
        .reflect_then_bands(&x, 1, &second, 0)
        .unwrap_err()
        .to_string();
    assert!(e.contains("band"), "{e}");
    let e = first.reflect_then(&x, 4, &second).unwrap_err().to_string();
    assert!(e.contains("reflection pad"), "{e}");
    let e = first
        .reflect_then(&x, 1, &mk(&mut rng, sq(5, 2, 3, 2, 1)))
        .unwrap_err()
        .to_string();
    assert!(e.contains("input channels"), "{e}");
    let e = mk(&mut rng, sq(3, 4, 3, 1, 1))
        .reflect_then(&x, 1, &second)
        .unwrap_err()
        .to_string();
    assert!(e.contains("zero padding"), "{e}");
}

#[test]
fn conv_transpose_then_reflect_conv_refuses_bad_shapes() {
    let mut rng = Rng::new(5);
    let up = ConvTransposeSpec::square(3, 4, 3, 2, 1, 1);
    let upl = ConvTranspose2d::new(
        up,
        &rng.normal_vec(up.weight_len(), 0.3),
        None,
        Activation::Relu,
    )
    .unwrap();
    let x = rng.tensor([1, 3, 2, 3]); // output 4x6
    let mut conv = |c_in, pad| {
        let s = ConvSpec::square(c_in, 2, 3, 1, pad);
        Conv2d::new(
            s,
            &rng.normal_vec(s.weight_len(), 0.3),
            None,
            Activation::None,
        )
        .unwrap()
    };
    let ok = conv(4, 0);
    assert!(upl.then_reflect_conv_bands(&x, &ok, 1, 2).is_ok());
    let e = upl
        .then_reflect_conv_bands(&x, &ok, 1, 0)
        .unwrap_err()
        .to_string();
    assert!(e.contains("band"), "{e}");
    let e = upl.then_reflect_conv(&x, &ok, 4).unwrap_err().to_string();
    assert!(e.contains("reflection pad"), "{e}");
    let e = upl
        .then_reflect_conv(&x, &conv(5, 0), 1)
        .unwrap_err()
        .to_string();
    assert!(e.contains("input channels"), "{e}");
    let e = upl
        .then_reflect_conv(&x, &conv(4, 1), 1)
        .unwrap_err()
        .to_string();
    assert!(e.contains("zero padding"), "{e}");
    let e = upl
        .then_reflect_conv(&rng.tensor([1, 2, 2, 3]), &ok, 1)
        .unwrap_err()
        .to_string();
    assert!(!e.is_empty());
}

#[test]
fn conv_transpose2d_shapes() {
    let t = |n, h, w, ci, co, k, s, p, op| ConvTProblem {
        n,
        h,
        w,
        spec: ConvTransposeSpec::square(ci, co, k, s, p, op),
        bias: true,
        act: Activation::Relu,
    };
    let mut problems = vec![
        t(1, 1, 1, 1, 1, 3, 2, 1, 1),    // 1x1 input
        t(1, 5, 7, 16, 12, 3, 2, 1, 1),  // the decoder's layer, scaled down
        t(2, 6, 3, 9, 5, 3, 2, 1, 1),    // batch 2, odd channels
        t(1, 4, 4, 3, 4, 3, 2, 1, 0),    // no output padding
        t(1, 3, 5, 4, 6, 4, 2, 1, 0),    // even kernel
        t(1, 4, 3, 5, 3, 3, 1, 1, 0),    // stride 1
        t(1, 3, 4, 2, 3, 5, 3, 2, 2),    // stride 3, output padding 2
        t(1, 2, 3, 70, 8, 3, 2, 0, 1),   // no padding
        t(1, 9, 61, 12, 10, 3, 2, 1, 1), // rows wider than a panel, runs across rows
        t(1, 5, 30, 20, 9, 3, 2, 1, 0),  // odd output width: the last pair is half full
        t(1, 3, 4, 3, 2, 1, 2, 0, 1),    // 1x1 kernel, stride 2: phases without taps
        t(1, 4, 5, 6, 4, 2, 3, 0, 2),    // stride 3, a row phase without taps
    ];
    let mut rng = Rng::new(77);
    for _ in 0..25 {
        let k = rng.range(1, 5);
        let s = rng.range(1, 3);
        let p = rng.range(0, k - 1);
        let op = rng.range(0, s - 1);
        let mut pr = t(
            rng.range(1, 2),
            rng.range(1, 9),
            rng.range(1, 9),
            rng.range(1, 30),
            rng.range(1, 30),
            k,
            s,
            p,
            op,
        );
        pr.bias = rng.range(0, 1) == 1;
        pr.act = [Activation::None, Activation::Relu, Activation::Tanh][rng.range(0, 2)];
        if pr.spec.out_hw(pr.h, pr.w).is_ok() {
            problems.push(pr);
        }
    }
    for isa in isas() {
        for (i, p) in problems.iter().enumerate() {
            p.run(isa, 300 + i as u64);
        }
    }
}

#[test]
fn batchnorm_folding_matches_conv_then_bn() {
    let mut rng = Rng::new(3);
    let bn = |rng: &mut Rng, c| BatchNorm {
        gamma: rng.uniform_vec(c, 0.5, 1.5),
        beta: rng.normal_vec(c, 0.2),
        mean: rng.normal_vec(c, 0.3),
        var: rng.uniform_vec(c, 0.5, 2.0),
        eps: 1e-5,
    };
    for with_bias in [false, true] {
        let s = ConvSpec::square(6, 11, 3, 2, 1);
        let x = rng.tensor([1, 6, 9, 8]);
        let wt = rng.normal_vec(s.weight_len(), 0.3);
        let b = with_bias.then(|| rng.normal_vec(11, 0.3));
        let norm = bn(&mut rng, 11);
        let expected =
            reference::batch_norm(&reference::conv2d(&x, &wt, b.as_deref(), s).unwrap(), &norm)
                .unwrap();
        let (fw, fb) = fold_batchnorm(&wt, b.as_deref(), &norm, WeightLayout::Conv).unwrap();
        let found = Conv2d::new(s, &fw, Some(&fb), Activation::None)
            .unwrap()
            .forward(&x)
            .unwrap();
        check("folded conv", &found, &expected, Tolerance::KERNEL_F32);

        let st = ConvTransposeSpec::square(5, 7, 3, 2, 1, 1);
        let x = rng.tensor([1, 5, 4, 6]);
        let wt = rng.normal_vec(st.weight_len(), 0.3);
        let b = with_bias.then(|| rng.normal_vec(7, 0.3));
        let norm = bn(&mut rng, 7);
        let expected = reference::batch_norm(
            &reference::conv_transpose2d(&x, &wt, b.as_deref(), st).unwrap(),
            &norm,
        )
        .unwrap();
        let (fw, fb) = fold_batchnorm(
            &wt,
            b.as_deref(),
            &norm,
            WeightLayout::Transposed { kernel_area: 9 },
        )
        .unwrap();
        let found = ConvTranspose2d::new(st, &fw, Some(&fb), Activation::None)
            .unwrap()
            .forward(&x)
            .unwrap();
        check(
            "folded conv-transpose",
            &found,
            &expected,
            Tolerance::KERNEL_F32,
        );
    }
}

#[test]
fn padding_matches_reference() {
    let mut rng = Rng::new(11);
    for (h, w, pads) in [
        (1, 1, [0, 0, 0, 0]),
        (4, 5, [1, 1, 1, 1]),
        (7, 4, [3, 3, 3, 3]),
        (9, 6, [2, 0, 1, 4]),
    ] {
        let x = rng.tensor([2, 3, h, w]);
        if pads.iter().all(|&p| p < h.min(w)) || pads == [0, 0, 0, 0] {
            check(
                "reflect_pad",
                &reflect_pad(&x, pads).unwrap(),
                &reference::reflect_pad(&x, pads).unwrap(),
                Tolerance::EXACT,
            );
        }
        check(
            "mirror_pad",
            &mirror_pad(&x, pads),
            &reference::mirror_pad(&x, pads),
            Tolerance::EXACT,
        );
    }
    // mirror extension far beyond the size, and of a single pixel
    for (h, w, pads) in [
        (1, 1, [3, 4, 5, 6]),
        (2, 3, [7, 1, 9, 2]),
        (3, 1, [0, 5, 2, 2]),
    ] {
        let x = rng.tensor([1, 2, h, w]);
        check(
            "mirror_pad large",
            &mirror_pad(&x, pads),
            &reference::mirror_pad(&x, pads),
            Tolerance::EXACT,
        );
    }
    // PyTorch refuses reflection pads not smaller than the axis; so do we
    assert!(reflect_pad(&rng.tensor([1, 1, 3, 3]), [3, 0, 0, 0]).is_err());
    assert!(reference::reflect_pad(&rng.tensor([1, 1, 3, 3]), [0, 0, 0, 3]).is_err());
}

#[test]
fn mirror_pad_known_values() {
    let x = Tensor::new([1, 1, 1, 3], vec![0.0, 1.0, 2.0]).unwrap();
    let y = mirror_pad(&x, [0, 0, 4, 4]);
    assert_eq!(
        y.data(),
        &[0.0, 1.0, 2.0, 1.0, 0.0, 1.0, 2.0, 1.0, 0.0, 1.0, 2.0]
    );
}

#[test]
fn resize_matches_reference() {
    let mut rng = Rng::new(5);
    for (h, w, oh, ow) in [
        (1, 1, 3, 2),
        (4, 6, 8, 12),
        (30, 40, 3, 5),
        (7, 9, 7, 9),
        (5, 3, 2, 11),
        (2, 2, 1, 1),
    ] {
        let x = rng.tensor([2, 3, h, w]);
        check(
            &format!("resize {h}x{w}->{oh}x{ow}"),
            &resize_bilinear(&x, oh, ow).unwrap(),
            &reference::resize_bilinear(&x, oh, ow).unwrap(),
            Tolerance {
                abs: 1e-6,
                rel: 1e-6,
            },
        );
    }
    assert!(resize_bilinear(&rng.tensor([1, 1, 2, 2]), 0, 3).is_err());
}

#[test]
fn resize_known_values() {
    // PyTorch: F.interpolate(tensor([[[[0., 1.]]]]), size=(1, 4), mode="bilinear", align_corners=False)
    // gives [0, 0.25, 0.75, 1].
    let x = Tensor::new([1, 1, 1, 2], vec![0.0, 1.0]).unwrap();
    assert_eq!(
        resize_bilinear(&x, 1, 4).unwrap().data(),
        &[0.0, 0.25, 0.75, 1.0]
    );
}

#[test]
fn elementwise_matches_reference() {
    let mut rng = Rng::new(8);
    let x = rng.tensor([2, 3, 33, 17]);
    let y = rng.tensor([2, 3, 33, 17]);
    for act in [Activation::None, Activation::Relu, Activation::Tanh] {
        let mut f = x.clone();
        activate(&mut f, act);
        check(
            "activate",
            &f,
            &reference::activate(&x, act),
            Tolerance {
                abs: 1e-6,
                rel: 0.0,
            },
        );
    }
    let mut s = x.clone();
    add_assign(&mut s, &y).unwrap();
    check(
        "add",
        &s,
        &reference::add(&x, &y).unwrap(),
        Tolerance::EXACT,
    );
    assert!(add_assign(&mut s, &rng.tensor([1, 3, 33, 17])).is_err());
}

#[test]
fn bad_parameters_are_refused() {
    let w = vec![0.0; 27];
    assert!(
        Conv2d::new(ConvSpec::square(3, 1, 3, 0, 1), &w, None, Activation::None).is_err(),
        "stride 0"
    );
    assert!(
        Conv2d::new(
            ConvSpec::square(3, 1, 3, 1, 1),
            &w[..26],
            None,
            Activation::None
        )
        .is_err(),
        "weight length"
    );
    assert!(
        Conv2d::new(
            ConvSpec::square(3, 1, 3, 1, 1),
            &w,
            Some(&[0.0, 1.0]),
            Activation::None
        )
        .is_err(),
        "bias length"
    );
    let c = Conv2d::new(ConvSpec::square(3, 1, 3, 1, 0), &w, None, Activation::None).unwrap();
    assert!(c.forward(&Tensor::zeros([1, 4, 5, 5])).is_err(), "channels");
    assert!(
        c.forward(&Tensor::zeros([1, 3, 2, 5])).is_err(),
        "smaller than kernel"
    );
    assert!(
        c.forward_add(&Tensor::zeros([1, 3, 5, 5]), &Tensor::zeros([1, 1, 5, 5]))
            .is_err(),
        "residual shape"
    );
    let t = ConvTransposeSpec::square(1, 1, 3, 2, 1, 2);
    assert!(
        ConvTranspose2d::new(t, &[0.0; 9], None, Activation::None).is_err(),
        "output_padding >= stride"
    );
    assert!(Tensor::new([1, 2, 3, 4], vec![0.0; 23]).is_err());
}

#[test]
fn reused_buffers_never_leak_stale_values() {
    // Large tensors go back to a pool when dropped; new ones must still be exact.
    let shape = [1, 8, 256, 256];
    for round in 0..3 {
        let mut big = Tensor::zeros(shape);
        big.data_mut().fill(7.0 + round as f32);
        drop(big);
        assert!(
            Tensor::zeros(shape).data().iter().all(|&v| v == 0.0),
            "zeros after reuse"
        );
        let mut rng = Rng::new(round);
        let x = rng.tensor([1, 8, 254, 254]);
        let spec = ConvSpec::square(8, 8, 3, 1, 1);
        let wt = rng.normal_vec(spec.weight_len(), 0.2);
        let conv = Conv2d::new(spec, &wt, None, Activation::None).unwrap();
        let fast = conv.forward(&mirror_pad(&x, [1, 1, 1, 1])).unwrap();
        let slow =
            reference::conv2d(&reference::mirror_pad(&x, [1, 1, 1, 1]), &wt, None, spec).unwrap();
        check(
            "conv after buffer reuse",
            &fast,
            &slow,
            Tolerance::KERNEL_F32,
        );
    }
}

/// `forward_reflect` (reflection padding fused into the gather or the padded
/// copy) against `reference::reflect_pad` then the reference convolution.
#[test]
fn conv2d_reflect_forward() {
    // (n, h, w, c_in, c_out, k, stride, reflect pad, residual)
    let cases = [
        (1, 5, 7, 17, 19, 3, 1, 1, true),   // Winograd
        (1, 2, 2, 16, 16, 3, 1, 1, true),   // Winograd, 2x2 image (smallest reflect 1)
        (2, 9, 12, 24, 16, 3, 1, 1, false), // Winograd, batch 2
        (1, 30, 41, 32, 32, 3, 1, 1, true), // Winograd, several tile rows, odd width
        (1, 4, 9, 3, 9, 7, 1, 3, false),    // encoder input conv (shifted)
        (1, 9, 11, 6, 3, 7, 1, 3, false),   // decoder output conv (folded)
        (1, 21, 30, 6, 3, 7, 1, 3, true),   // decoder output conv, strips of rows
        (1, 11, 13, 3, 8, 7, 2, 3, false),  // EnvMap input conv (phase planes)
        (1, 6, 5, 5, 7, 3, 1, 2, true),     // pad 2 with a 3x3 kernel
        (1, 6, 133, 8, 5, 3, 1, 1, true),   // Winograd, tile rows of 34 tiles
        (1, 9, 70, 4, 6, 3, 1, 2, false),   // Winograd, reflect 2 on a wide row
        (1, 11, 13, 8, 12, 3, 2, 1, true),  // stride-2 Winograd, odd sizes
        (1, 8, 150, 5, 7, 3, 2, 2, false),  // stride-2 Winograd, reflect 2, rows of 19 tiles
    ];
    for isa in isas() {
        for (i, &(n, h, w, ci, co, k, st, rp, with_res)) in cases.iter().enumerate() {
            let mut rng = Rng::new(7000 + i as u64);
            let spec = ConvSpec::square(ci, co, k, st, 0);
            let x = rng.tensor([n, ci, h, w]);
            let wt = rng.normal_vec(spec.weight_len(), (1.0 / (ci * k * k) as f32).sqrt());
            let b = rng.normal_vec(co, 0.5);
            let padded = reference::reflect_pad(&x, [rp; 4]).unwrap();
            let mut expected = reference::conv2d(&padded, &wt, Some(&b), spec).unwrap();
            expected = reference::activate(&expected, Activation::Relu);
            let r = rng.tensor(expected.shape());
            if with_res {
                expected = reference::add(&expected, &r).unwrap();
            }
            for algo in algorithms(isa, &spec) {
                let conv = Conv2d::with_algorithm(isa, algo, spec, &wt, Some(&b), Activation::Relu)
                    .unwrap();
                let found = conv
                    .forward_reflect(&x, rp, with_res.then_some(&r))
                    .unwrap();
                check(
                    &format!("{isa} {algo:?} reflect case {i}"),
                    &found,
                    &expected,
                    tolerance(algo),
                );
            }
        }
    }
    // Refused: a layer with its own zero padding, and a pad as large as the image.
    let mut rng = Rng::new(1);
    let spec = ConvSpec::square(4, 4, 3, 1, 1);
    let conv = Conv2d::new(
        spec,
        &rng.normal_vec(spec.weight_len(), 0.1),
        None,
        Activation::None,
    )
    .unwrap();
    assert!(conv
        .forward_reflect(&rng.tensor([1, 4, 5, 5]), 1, None)
        .is_err());
    let spec = ConvSpec::square(16, 16, 3, 1, 0);
    let conv = Conv2d::new(
        spec,
        &rng.normal_vec(spec.weight_len(), 0.1),
        None,
        Activation::None,
    )
    .unwrap();
    assert!(conv
        .forward_reflect(&rng.tensor([1, 16, 2, 5]), 2, None)
        .is_err());
}

/// Winograd weights made per pass (`WinogradLowMemory`: one transform row at
/// a time, for blocks of at most four tile panels) give the same bits as the
/// weights packed once, and both match the reference, with either tile size.
#[test]
fn winograd_lazy_weights_match_packed_bit_for_bit() {
    // (h, w, c_in, c_out): one panel; three panels and two depth blocks (256
    // + 44 channels); five panels (two blocks, 3 + 2, on AVX-512) with a
    // partial depth block and a partial row panel; more panels (blocks of 4,
    // 4, 4, 3 for 100×110 in F(4×4)); a single channel; 1100 input channels,
    // whose `V` allows only two F(4×4) panels (one F(6×6) panel) per block,
    // in five depth blocks.
    // In F(6×6) tiles: one, two, three, four and seven panels (4 + 3).
    let cases = [
        (14, 18, 20, 13),
        (34, 49, 300, 24),
        (60, 58, 160, 19),
        (90, 70, 24, 72),
        (9, 9, 1, 1),
        (100, 110, 24, 40),
        (40, 44, 1100, 12),
    ];
    // (packed, lazy, stride)
    let pairs = [
        (ConvAlgorithm::Winograd, ConvAlgorithm::WinogradLowMemory, 1),
        (
            ConvAlgorithm::Winograd6,
            ConvAlgorithm::Winograd6LowMemory,
            1,
        ),
        (
            ConvAlgorithm::WinogradStride2,
            ConvAlgorithm::WinogradStride2LowMemory,
            2,
        ),
        (
            ConvAlgorithm::Winograd5Stride2,
            ConvAlgorithm::Winograd5Stride2LowMemory,
            2,
        ),
        (
            ConvAlgorithm::Winograd5,
            ConvAlgorithm::Winograd5LowMemory,
            1,
        ),
    ];
    for isa in isas() {
        for (packed_algo, lazy_algo, stride) in pairs {
            for (i, &(h, w, ci, co)) in cases.iter().enumerate() {
                let mut rng = Rng::new(9100 + i as u64);
                let spec = ConvSpec::square(ci, co, 3, stride, 1);
                let x = rng.tensor([1, ci, h, w]);
                let wt = rng.normal_vec(spec.weight_len(), (1.0 / (ci * 9) as f32).sqrt());
                let b = rng.normal_vec(co, 0.5);
                let (oh, ow) = spec.out_hw(h, w).unwrap();
                let r = rng.tensor([1, co, oh, ow]);
                let run = |algo| {
                    Conv2d::with_algorithm(isa, algo, spec, &wt, Some(&b), Activation::Relu)
                        .unwrap()
                        .forward_add(&x, &r)
                        .unwrap()
                };
                let packed = run(packed_algo);
                let lazy = run(lazy_algo);
                let what = format!("{isa} {lazy_algo:?} case {i} {h}x{w} {ci}->{co}");
                let differ = packed
                    .data()
                    .iter()
                    .zip(lazy.data())
                    .filter(|(a, b)| a.to_bits() != b.to_bits())
                    .count();
                assert_eq!(
                    differ, 0,
                    "{what}: lazy differs from packed in {differ} values"
                );
                let mut expected = reference::conv2d(&x, &wt, Some(&b), spec).unwrap();
                expected = reference::activate(&expected, Activation::Relu);
                expected = reference::add(&expected, &r).unwrap();
                check(&what, &lazy, &expected, Tolerance::WINOGRAD_F32);
            }
        }
    }
}

/// bf16 rounding as the bf16 path does it: to nearest, ties to even, on the
/// f32 value (no NaN or denormal in these tests).
fn bf16_round(x: f32) -> f32 {
    let b = x.to_bits();
    f32::from_bits(b.wrapping_add(0x7fff + ((b >> 16) & 1)) & 0xffff_0000)
}

/// Winograd F(4×4, 3×3) in f64 with the bf16 path's two roundings: the
/// transformed weights `U = G g Gᵀ` and inputs `V = Bᵀ d B` rounded (via
/// f32) to bf16. One image, zero padding `spec.pad`.
#[allow(clippy::needless_range_loop)] // index loops, to read like the formulas
fn winograd_bf16_reference(
    x: &Tensor,
    wt: &[f32],
    bias: &[f32],
    spec: ConvSpec,
    act: Activation,
    residual: &Tensor,
) -> Tensor {
    const BT: [[f64; 6]; 6] = [
        [4.0, 0.0, -5.0, 0.0, 1.0, 0.0],
        [0.0, -4.0, -4.0, 1.0, 1.0, 0.0],
        [0.0, 4.0, -4.0, -1.0, 1.0, 0.0],
        [0.0, -2.0, -1.0, 2.0, 1.0, 0.0],
        [0.0, 2.0, -1.0, -2.0, 1.0, 0.0],
        [0.0, 4.0, 0.0, -5.0, 0.0, 1.0],
    ];
    const G: [[f64; 3]; 6] = [
        [0.25, 0.0, 0.0],
        [-1.0 / 6.0, -1.0 / 6.0, -1.0 / 6.0],
        [-1.0 / 6.0, 1.0 / 6.0, -1.0 / 6.0],
        [1.0 / 24.0, 1.0 / 12.0, 1.0 / 6.0],
        [1.0 / 24.0, -1.0 / 12.0, 1.0 / 6.0],
        [0.0, 0.0, 1.0],
    ];
    const AT: [[f64; 6]; 4] = [
        [1.0, 1.0, 1.0, 1.0, 1.0, 0.0],
        [0.0, 1.0, -1.0, 2.0, -2.0, 0.0],
        [0.0, 1.0, 1.0, 4.0, 4.0, 0.0],
        [0.0, 1.0, -1.0, 8.0, -8.0, 1.0],
    ];
    let round = |v: f64| f64::from(bf16_round(v as f32));
    let (ci_n, co_n, h, w, p) = (spec.c_in, spec.c_out, x.h(), x.w(), spec.pad);
    let (oh, ow) = spec.out_hw(h, w).unwrap();
    let (th, tw) = (oh.div_ceil(4), ow.div_ceil(4));
    let px = |c: usize, y: isize, xx: isize| -> f64 {
        let (y, xx) = (y - p as isize, xx - p as isize);
        if y < 0 || xx < 0 || y >= h as isize || xx >= w as isize {
            0.0
        } else {
            f64::from(x.data()[(c * h + y as usize) * w + xx as usize])
        }
    };
    // u[(co·c_in + ci)·36 + ξ]
    let mut u = vec![0.0f64; co_n * ci_n * 36];
    for co in 0..co_n {
        for ci in 0..ci_n {
            let g = |r: usize, c: usize| f64::from(wt[((co * ci_n + ci) * 3 + r) * 3 + c]);
            for i in 0..6 {
                for j in 0..6 {
                    let mut acc = 0.0;
                    for r in 0..3 {
                        for c in 0..3 {
                            acc += G[i][r] * g(r, c) * G[j][c];
                        }
                    }
                    u[(co * ci_n + ci) * 36 + i * 6 + j] = round(acc);
                }
            }
        }
    }
    let mut out = Tensor::zeros([1, co_n, oh, ow]);
    let mut v = vec![0.0f64; ci_n * 36];
    for ty in 0..th {
        for tx in 0..tw {
            for ci in 0..ci_n {
                let d = |r: usize, c: usize| px(ci, (4 * ty + r) as isize, (4 * tx + c) as isize);
                for i in 0..6 {
                    for j in 0..6 {
                        let mut acc = 0.0;
                        for r in 0..6 {
                            for c in 0..6 {
                                acc += BT[i][r] * d(r, c) * BT[j][c];
                            }
                        }
                        v[ci * 36 + i * 6 + j] = round(acc);
                    }
                }
            }
            for co in 0..co_n {
                let mut m = [0.0f64; 36];
                for ci in 0..ci_n {
                    for (xi, mv) in m.iter_mut().enumerate() {
                        *mv += u[(co * ci_n + ci) * 36 + xi] * v[ci * 36 + xi];
                    }
                }
                for a in 0..4 {
                    for b in 0..4 {
                        let (oy, ox) = (4 * ty + a, 4 * tx + b);
                        if oy >= oh || ox >= ow {
                            continue;
                        }
                        let mut y = f64::from(bias[co]);
                        for r in 0..6 {
                            for c in 0..6 {
                                y += AT[a][r] * m[r * 6 + c] * AT[b][c];
                            }
                        }
                        let at = (co * oh + oy) * ow + ox;
                        let y = act.apply_one(y as f32) + residual.data()[at];
                        out.data_mut()[at] = y;
                    }
                }
            }
        }
    }
    out
}

/// The bf16 Winograd against a reference that rounds at the same two points
/// (so this bound is 50× tighter than the one against the exact convolution):
/// odd channel counts (a zero half pair), two depth blocks, output channels
/// off the tile, several tile blocks, padding, ReLU and the residual add.
#[test]
fn winograd_bf16_matches_rounding_reference() {
    if !ConvAlgorithm::WinogradBf16.runs_on(Isa::Avx512) {
        eprintln!("SKIPPED: WinogradBf16 needs AVX512_BF16, which this CPU lacks");
        return;
    }
    // (h, w, c_in, c_out, pad)
    let cases = [
        (6, 6, 16, 16, 0),
        (9, 13, 17, 19, 1),
        (30, 41, 33, 8, 1),
        (14, 10, 301, 12, 0),
        (7, 131, 20, 24, 1),
        // Whole AMX tiles (depth pairs and outputs in 16s): on a CPU with
        // AMX-BF16 these run on the tiles, the ones above on AVX512_BF16.
        (12, 20, 64, 48, 1),
        (50, 70, 320, 32, 1), // two depth blocks, 5 tile panels
    ];
    for (i, &(h, w, ci, co, pad)) in cases.iter().enumerate() {
        let mut rng = Rng::new(9100 + i as u64);
        let spec = ConvSpec::square(ci, co, 3, 1, pad);
        let x = rng.tensor([1, ci, h, w]);
        let wt = rng.normal_vec(spec.weight_len(), (1.0 / (ci * 9) as f32).sqrt());
        let b = rng.normal_vec(co, 0.5);
        let (oh, ow) = spec.out_hw(h, w).unwrap();
        let r = rng.tensor([1, co, oh, ow]);
        let expected = winograd_bf16_reference(&x, &wt, &b, spec, Activation::Relu, &r);
        for algo in [
            ConvAlgorithm::WinogradBf16,
            ConvAlgorithm::WinogradBf16LowMemory,
        ] {
            let conv =
                Conv2d::with_algorithm(Isa::Avx512, algo, spec, &wt, Some(&b), Activation::Relu)
                    .unwrap();
            let found = conv.forward_add(&x, &r).unwrap();
            check(
                &format!("{algo:?} case {i}"),
                &found,
                &expected,
                // Far below the bf16 error itself (~0.2 here): what is left
                // is the rare V whose f32 and f64 values round to different
                // bf16 neighbours (up to ~7e-3 with 64 input channels; the
                // AMX and AVX512_BF16 kernels agree with each other to ~1e-6).
                Tolerance {
                    abs: 1e-2,
                    rel: 0.0,
                },
            );
        }
    }
}
