//! Inpainting benchmarks (`cargo bench -p picker-inpaint --bench inpaint`):
//! PatchMatch at 256² and 512², diffusion at 512², RGB, 30% of the texels
//! missing in random discs, toroidal. Throughput is in filled texels.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use picker_inpaint::{DiffusionInpainter, InpaintOptions, Inpainter, PatchMatchInpainter};
use picker_render::io::Image;
use picker_tensor::Rng;

/// A tileable brick-like RGB texture with noise and a 30% blob mask.
fn problem(n: usize) -> (Image, Vec<bool>) {
    let mut rng = Rng::new(n as u64);
    let mut data = vec![0.0f32; 3 * n * n];
    for y in 0..n {
        for x in 0..n {
            let xs = x + if (y / 16) % 2 == 1 { 16 } else { 0 };
            let mortar = y % 16 < 2 || xs % 32 < 2;
            for c in 0..3 {
                let base = if mortar { 0.75 } else { [0.55, 0.25, 0.18][c] };
                data[c * n * n + y * n + x] = base + rng.uniform(-0.03, 0.03);
            }
        }
    }
    let mut known = vec![true; n * n];
    let mut unknown = 0;
    while unknown * 10 < n * n * 3 {
        let (cy, cx) = (rng.range(0, n - 1) as isize, rng.range(0, n - 1) as isize);
        let r = rng.range(2, n / 12) as isize;
        for dy in -r..=r {
            for dx in -r..=r {
                if dy * dy + dx * dx <= r * r {
                    let i = (cy + dy).rem_euclid(n as isize) as usize * n
                        + (cx + dx).rem_euclid(n as isize) as usize;
                    if known[i] {
                        known[i] = false;
                        unknown += 1;
                    }
                }
            }
        }
    }
    (Image::new(3, n, n, data).expect("shape"), known)
}

fn bench(c: &mut Criterion) {
    let opts = InpaintOptions::default();
    let mut g = c.benchmark_group("inpaint/rgb_30pct");
    g.sample_size(10);
    let cases: [(&str, usize, Box<dyn Inpainter>); 3] = [
        ("patchmatch", 256, Box::new(PatchMatchInpainter::default())),
        ("patchmatch", 512, Box::new(PatchMatchInpainter::default())),
        ("diffusion", 512, Box::new(DiffusionInpainter::default())),
    ];
    for (name, n, ip) in cases {
        let (img, known) = problem(n);
        let holes = known.iter().filter(|k| !**k).count();
        g.throughput(Throughput::Elements(holes as u64));
        g.bench_function(format!("{name}/{n}x{n}"), |b| {
            b.iter(|| ip.inpaint(&img, &known, &opts).expect("inpaint"))
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
