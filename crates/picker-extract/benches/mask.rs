//! Mask-step benchmarks (`cargo bench -p picker-extract --bench mask`): the
//! segmentation's smoothing along the photo, the leak guard's relief and the
//! photo's split of a mask (the whole image, picked at its centre) at the
//! default working size (240×320) and at 480×640, throughput in pixels.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use picker_extract::{mask, smooth, split};
use picker_render::io::Image;
use picker_tensor::Rng;

/// A random photo of flat rectangles with noise and a noisy segmentation.
fn problem(w: usize, h: usize) -> (Image, Image, Vec<bool>) {
    let mut rng = Rng::new((w * h) as u64);
    let n = w * h;
    let mut photo = vec![0.0f32; 3 * n];
    let mut seg = vec![0.0f32; 3 * n];
    for y in 0..h {
        for x in 0..w {
            let cell = (x * 5 / w + 5 * (y * 4 / h)) as f32;
            for c in 0..3 {
                let base = ((cell * (c as f32 + 1.3)).sin() * 0.5 + 0.5) * 0.8;
                photo[c * n + y * w + x] = base + rng.uniform(-0.02, 0.02);
                seg[c * n + y * w + x] = base * 0.7 + rng.uniform(-0.05, 0.05);
            }
        }
    }
    (
        Image::new(3, h, w, seg).unwrap(),
        Image::new(3, h, w, photo).unwrap(),
        vec![true; n],
    )
}

fn bench(c: &mut Criterion) {
    let mut g = c.benchmark_group("mask");
    g.sample_size(20);
    for (w, h) in [(320, 240), (640, 480)] {
        let (seg, photo, valid) = problem(w, h);
        g.throughput(Throughput::Elements((w * h) as u64));
        g.bench_function(format!("smooth_segmentation {w}x{h}"), |b| {
            b.iter(|| smooth::smooth_segmentation(&seg, &photo, &valid).unwrap())
        });
        g.bench_function(format!("leak_guard_relief {w}x{h}"), |b| {
            b.iter(|| mask::leak_guard_relief(&seg))
        });
        let whole = mask::Mask {
            width: w,
            height: h,
            data: valid.clone(),
        };
        g.bench_function(format!("split_mask {w}x{h}"), |b| {
            b.iter(|| split::split_mask(&photo, &seg, &whole, w / 2, h / 2, false))
        });
    }
    let (seg, photo, valid) = problem(320, 240);
    g.sample_size(10);
    g.bench_function("smooth_segmentation_reference 320x240", |b| {
        b.iter(|| smooth::smooth_segmentation_reference(&seg, &photo, &valid).unwrap())
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
