//! Criterion benchmarks of every layer shape of the three networks at 240×320
//! (thesis widths), with throughput in FLOPs (2 × multiply-adds) so rates compare.
//!
//! `cargo bench -p picker-tensor --bench kernels` (set `PICKER_ISA=avx2|portable` to
//! bench another micro-kernel family; `RAYON_NUM_THREADS` to set threads).

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use picker_tensor::{
    Activation, Conv2d, ConvAlgorithm, ConvSpec, ConvTranspose2d, ConvTransposeSpec, Isa, Rng,
};

/// (id, input h, input w, spec) of the convolutions at 240×320.
fn conv_layers() -> Vec<(&'static str, usize, usize, ConvSpec)> {
    vec![
        ("enc_in", 246, 326, ConvSpec::square(3, 64, 7, 1, 0)),
        ("enc_down0", 240, 320, ConvSpec::square(64, 128, 3, 2, 1)),
        ("enc_down1", 120, 160, ConvSpec::square(128, 256, 3, 2, 1)),
        ("res", 62, 82, ConvSpec::square(256, 256, 3, 1, 0)),
        ("dec_out", 246, 326, ConvSpec::square(64, 3, 7, 1, 0)),
        ("env_in", 246, 326, ConvSpec::square(3, 64, 7, 2, 0)),
        ("env_down0", 120, 160, ConvSpec::square(64, 128, 3, 2, 1)),
        ("env_down1", 60, 80, ConvSpec::square(128, 256, 3, 2, 1)),
        ("env_res", 32, 42, ConvSpec::square(256, 256, 3, 1, 0)),
        ("env_tail0", 30, 40, ConvSpec::square(256, 256, 1, 2, 0)),
        ("env_tail1", 15, 20, ConvSpec::square(256, 128, 3, 2, 1)),
        ("env_tail2", 8, 10, ConvSpec::square(128, 3, 3, 2, 1)),
    ]
}

fn conv_transpose_layers() -> Vec<(&'static str, usize, usize, ConvTransposeSpec)> {
    vec![
        (
            "dec_up0",
            60,
            80,
            ConvTransposeSpec::square(256, 128, 3, 2, 1, 1),
        ),
        (
            "dec_up1",
            120,
            160,
            ConvTransposeSpec::square(128, 64, 3, 2, 1, 1),
        ),
    ]
}

fn bench(c: &mut Criterion) {
    let mut rng = Rng::new(1);
    let mut g = c.benchmark_group("conv2d/f32");
    g.sample_size(10);
    for (name, h, w, s) in conv_layers() {
        let wt = rng.normal_vec(s.weight_len(), 0.05);
        let bias = vec![0.1; s.c_out];
        // The default algorithm, and for the residual-block shapes the
        // low-memory Winograd, the F(6×6) and F(5×5) ones, the per-image
        // tile (the networks' choice), the bf16 one (where the CPU
        // has it) and the plain packed GEMM beside it; for the 3×3 stride-2
        // shapes the stride-2 Winograd variants (both tiles) and the pixel tiles (the
        // ones Auto does not take run too).
        let mut algos = vec![ConvAlgorithm::Auto];
        if s.kh == 3 && s.stride == 2 {
            algos.extend([
                ConvAlgorithm::WinogradStride2,
                ConvAlgorithm::WinogradStride2LowMemory,
                ConvAlgorithm::Winograd5Stride2,
                ConvAlgorithm::Winograd5Stride2LowMemory,
                ConvAlgorithm::PixelTiles,
            ]);
        }
        if name.ends_with("res") {
            algos.extend([
                ConvAlgorithm::WinogradLowMemory,
                ConvAlgorithm::Winograd6,
                ConvAlgorithm::Winograd6LowMemory,
                ConvAlgorithm::Winograd5,
                ConvAlgorithm::Winograd5LowMemory,
                ConvAlgorithm::WinogradLowMemoryAutoTile,
                ConvAlgorithm::WinogradBf16,
                ConvAlgorithm::Gemm,
            ]);
        }
        algos.retain(|a| a.runs_on(Isa::best()));
        let auto = Conv2d::with_algorithm(
            Isa::best(),
            ConvAlgorithm::Auto,
            s,
            &wt,
            Some(&bias),
            Activation::Relu,
        )
        .unwrap()
        .algorithm();
        // Auto once, under the name of what it resolves to.
        algos.retain(|&a| a == ConvAlgorithm::Auto || a != auto);
        let x = rng.tensor([1, s.c_in, h, w]);
        for algo in algos {
            let conv =
                Conv2d::with_algorithm(Isa::best(), algo, s, &wt, Some(&bias), Activation::Relu)
                    .unwrap();
            g.throughput(Throughput::Elements(s.flops(h, w)));
            let id = format!(
                "{name}/{}x{}x{}_k{}s{}/{:?}",
                s.c_in,
                h,
                w,
                s.kh,
                s.stride,
                conv.algorithm()
            );
            g.bench_function(BenchmarkId::from_parameter(id), |b| {
                b.iter(|| conv.forward(&x).unwrap())
            });
        }
    }
    g.finish();
    let mut g = c.benchmark_group("conv_transpose2d/f32");
    g.sample_size(10);
    for (name, h, w, s) in conv_transpose_layers() {
        let wt = rng.normal_vec(s.weight_len(), 0.05);
        let conv = ConvTranspose2d::new(s, &wt, None, Activation::Relu).unwrap();
        let x = rng.tensor([1, s.c_in, h, w]);
        g.throughput(Throughput::Elements(s.flops(h, w)));
        let id = format!("{name}/{}x{}x{}_k{}s{}", s.c_in, h, w, s.kh, s.stride);
        g.bench_function(BenchmarkId::from_parameter(id), |b| {
            b.iter(|| conv.forward(&x).unwrap())
        });
    }
    g.finish();
    // A decoder's tail as the networks run it: `dec_up1` and the 7×7
    // `dec_out` with reflection padding 3, fused in bands of rows, and the
    // two layers one after the other beside it.
    let mut g = c.benchmark_group("decoder_tail/f32");
    g.sample_size(10);
    let (h, w) = (120, 160);
    let up = ConvTransposeSpec::square(128, 64, 3, 2, 1, 1);
    let out = ConvSpec::square(64, 3, 7, 1, 0);
    let upl = ConvTranspose2d::new(
        up,
        &rng.normal_vec(up.weight_len(), 0.05),
        None,
        Activation::Relu,
    )
    .unwrap();
    let outl = Conv2d::new(
        out,
        &rng.normal_vec(out.weight_len(), 0.05),
        None,
        Activation::Tanh,
    )
    .unwrap();
    let x = rng.tensor([1, up.c_in, h, w]);
    g.throughput(Throughput::Elements(
        up.flops(h, w) + out.flops(2 * h + 6, 2 * w + 6),
    ));
    g.bench_function(BenchmarkId::from_parameter("up1_out/fused_bands"), |b| {
        b.iter(|| upl.then_reflect_conv(&x, &outl, 3).unwrap())
    });
    g.bench_function(
        BenchmarkId::from_parameter("up1_out/one_after_the_other"),
        |b| {
            b.iter(|| {
                outl.forward_reflect(&upl.forward(&x).unwrap(), 3, None)
                    .unwrap()
            })
        },
    );
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
