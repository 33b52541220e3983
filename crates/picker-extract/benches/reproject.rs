//! Reprojection benchmarks (`cargo bench -p picker-extract --bench reproject`):
//! the splat, robust pass and back-projection rounds of a receding plane
//! folded into one tile, the shape of the 12-megapixel extraction's largest
//! stage (a wall of running-bond bricks: millions of pixels folded into a
//! 512² tile, centred, so every pixel is splatted twice). Throughput in
//! picked pixels.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use picker_extract::reproject::{self, Coords};
use picker_render::io::Image;
use picker_tensor::Rng;

/// A `w × h` photo of a plane receding to the right (perspective: the
/// texture scale grows with `x`), its coordinates folded into a tile that
/// repeats `repeats` times across the photo, a brick-like colour with
/// noise, every pixel picked with confidence 1.
fn problem(w: usize, h: usize, repeats: f32) -> (Coords, Vec<bool>, Image, Vec<f32>) {
    let mut rng = Rng::new((w * h) as u64);
    let n = w * h;
    let (mut u, mut v) = (vec![0.0f32; n], vec![0.0f32; n]);
    let mut colour = vec![0.0f32; 3 * n];
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            // Projective: depth grows along x, so a texel covers fewer
            // pixels towards the right.
            let (fx, fy) = (x as f32 / w as f32, y as f32 / h as f32 - 0.5);
            let z = 1.0 + 1.5 * fx;
            let (su, sv) = (repeats * fx * 1.6 / z, repeats * (0.5 + fy / z));
            u[i] = su - su.floor();
            v[i] = sv - sv.floor();
            let brick = ((su * 3.0).fract() < 0.9 && (sv * 5.0).fract() < 0.85) as u8 as f32;
            for c in 0..3 {
                let base = [0.55, 0.25, 0.18][c] * brick + 0.6 * (1.0 - brick);
                colour[c * n + i] = base + rng.uniform(-0.03, 0.03);
            }
        }
    }
    (
        Coords {
            width: w,
            height: h,
            u,
            v,
            wrap: true,
        },
        vec![true; n],
        Image::new(3, h, w, colour).unwrap(),
        vec![1.0; n],
    )
}

fn bench(c: &mut Criterion) {
    let mut g = c.benchmark_group("reproject");
    g.sample_size(10);
    for (w, h, size) in [(1000, 750, 256), (2400, 1600, 512)] {
        let (coords, mask, colour, conf) = problem(w, h, 2.5);
        g.throughput(Throughput::Elements((w * h) as u64));
        g.bench_function(format!("reproject {w}x{h} into {size}"), |b| {
            b.iter(|| reproject::reproject(&coords, &mask, &colour, &conf, size))
        });
        g.bench_function(format!("reproject_centred {w}x{h} into {size}"), |b| {
            b.iter(|| {
                reproject::reproject_centred(&coords, &mask, &colour, &conf, size, [1.0 / 6.0, 0.1])
            })
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
