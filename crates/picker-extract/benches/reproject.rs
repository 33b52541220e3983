//! Reprojection benchmarks (`cargo bench -p picker-extract --bench reproject`):
//! the splat, robust pass and back-projection rounds of a receding plane
//! folded into one tile, the shape of the 12-megapixel extraction's largest
//! stage (a wall of running-bond bricks: millions of pixels folded into a
//! 512² tile, centred, so every pixel is splatted twice), and the fold's
//! refinement (`period::refine_tile`) on the same plane unfolded, its tile
//! measured 1 % off. Throughput in picked pixels.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use picker_extract::period::{self, Fold};
use picker_extract::reproject::{self, Coords};
use picker_render::io::Image;
use picker_tensor::Rng;

/// A `w × h` photo of a plane receding to the right (perspective: the
/// texture scale grows with `x`), its coordinates folded into a tile that
/// repeats `repeats` times across the photo, a brick-like colour with
/// noise, every pixel picked with confidence 1.
fn problem(w: usize, h: usize, repeats: f32) -> (Coords, Vec<bool>, Image, Vec<f32>) {
    plane(w, h, repeats, true)
}

/// [`problem`]'s plane before the fold: the rectified square's coordinates
/// (`1.6 · repeats` tiles of bricks across, three bricks by five courses
/// each), not wrapping.
fn unfolded(w: usize, h: usize, repeats: f32) -> (Coords, Vec<bool>, Image, Vec<f32>) {
    plane(w, h, repeats, false)
}

/// The plane of [`problem`] (`folded`) or [`unfolded`].
fn plane(w: usize, h: usize, repeats: f32, folded: bool) -> (Coords, Vec<bool>, Image, Vec<f32>) {
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
            (u[i], v[i]) = if folded {
                (su - su.floor(), sv - sv.floor())
            } else {
                (su / (1.6 * repeats), sv / (1.6 * repeats))
            };
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
            wrap: folded,
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
    let mut g = c.benchmark_group("fold");
    g.sample_size(10);
    for (w, h) in [(1000, 750), (2400, 1600)] {
        let (coords, mask, colour, conf) = unfolded(w, h, 2.5);
        // A brick's period in the square is a third of a tile across and a
        // fifth up; the tile (one period each way) measured 1 % off.
        let p = [1.0 / (3.0 * 1.6 * 2.5), 1.0 / (5.0 * 1.6 * 2.5)];
        let fold = Fold {
            period: [p[0] * 1.01, p[1] * 0.99],
            periods_per_tile: [1, 1],
            tile: [p[0] * 1.01, p[1] * 0.99],
            aspect: p[0] / p[1] * 1.01 / 0.99,
            strength: [0.8, 0.8],
            centred: None,
            refined: None,
            shear: [0.0, 0.0],
        };
        g.throughput(Throughput::Elements((w * h) as u64));
        g.bench_function(format!("refine_tile {w}x{h}"), |b| {
            b.iter(|| period::refine_tile(&coords, &mask, &colour, &conf, fold))
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
