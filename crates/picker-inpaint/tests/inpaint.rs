//! Inpainting tests: argument validation, the contract (known texels kept,
//! determinism, tiny images), toroidal seams, and quality of PatchMatch
//! against the diffusion baseline on synthetic periodic textures.
//! `cargo test --release -p picker-inpaint --test inpaint -- --nocapture`
//! prints the numbers.

use picker_inpaint::{
    colour_stats_distance, psnr, seam_score, DiffusionInpainter, Error, InpaintOptions, Inpainter,
    PatchMatchInpainter,
};
use picker_render::io::Image;
use picker_tensor::Rng;
use std::f32::consts::TAU;

// ---------------------------------------------------------------- helpers

/// A `c`-channel image from a per-texel function.
fn image_from(c: usize, h: usize, w: usize, f: impl Fn(usize, usize) -> [f32; 4]) -> Image {
    let mut data = vec![0.0; c * h * w];
    for y in 0..h {
        for x in 0..w {
            let v = f(y, x);
            for ch in 0..c {
                data[ch * h * w + y * w + x] = v[ch];
            }
        }
    }
    Image::new(c, h, w, data).expect("shape")
}

/// Random discs (wrapping around the edges) until `fraction` of the texels is unknown.
fn blob_mask(h: usize, w: usize, fraction: f64, seed: u64) -> Vec<bool> {
    let mut rng = Rng::new(seed);
    let mut known = vec![true; h * w];
    let mut unknown = 0usize;
    let max_r = (h.min(w) / 12).max(2);
    while (unknown as f64) < fraction * (h * w) as f64 {
        let (cy, cx) = (rng.range(0, h - 1) as isize, rng.range(0, w - 1) as isize);
        let r = rng.range(2, max_r) as isize;
        for dy in -r..=r {
            for dx in -r..=r {
                if dy * dy + dx * dx <= r * r {
                    let y = (cy + dy).rem_euclid(h as isize) as usize;
                    let x = (cx + dx).rem_euclid(w as isize) as usize;
                    if known[y * w + x] {
                        known[y * w + x] = false;
                        unknown += 1;
                    }
                }
            }
        }
    }
    known
}

/// Unknown texels of the input set to NaN: an inpainter must never read them.
fn poisoned(img: &Image, known: &[bool]) -> Image {
    let mut out = img.clone();
    let n = img.height * img.width;
    for plane in out.data.chunks_mut(n) {
        for (v, _) in plane.iter_mut().zip(known).filter(|(_, k)| !**k) {
            *v = f32::NAN;
        }
    }
    out
}

/// The texels where `mask` is false, as a one-row image (for colour statistics of the hole).
fn hole_texels(img: &Image, known: &[bool]) -> Image {
    let n = img.height * img.width;
    let idx: Vec<usize> = (0..n).filter(|&i| !known[i]).collect();
    let mut data = Vec::with_capacity(idx.len() * img.channels);
    for c in 0..img.channels {
        data.extend(idx.iter().map(|&i| img.data[c * n + i]));
    }
    Image::new(img.channels, 1, idx.len(), data).expect("shape")
}

fn assert_known_kept(out: &Image, input: &Image, known: &[bool]) {
    assert_eq!(
        (out.channels, out.height, out.width),
        (input.channels, input.height, input.width)
    );
    let n = input.height * input.width;
    for c in 0..input.channels {
        for (i, &k) in known.iter().enumerate() {
            let (a, b) = (out.data[c * n + i], input.data[c * n + i]);
            if k {
                assert_eq!(
                    a.to_bits(),
                    b.to_bits(),
                    "known texel {i} channel {c} changed"
                );
            } else {
                assert!(a.is_finite(), "unknown texel {i} channel {c} is {a}");
            }
        }
    }
}

fn inpainters() -> Vec<Box<dyn Inpainter>> {
    vec![
        Box::new(PatchMatchInpainter::default()),
        Box::new(DiffusionInpainter::default()),
    ]
}

/// Small hash → [0, 1) for per-cell colours of the generators.
fn cell_rand(a: usize, b: usize, k: usize, seed: u64) -> f32 {
    let mut r = Rng::new(seed ^ ((a as u64) << 40) ^ ((b as u64) << 20) ^ k as u64);
    r.f64() as f32
}

fn noise(y: usize, x: usize, k: usize, amp: f32) -> f32 {
    (cell_rand(y, x, k, 99) - 0.5) * 2.0 * amp
}

// ----------------------------------------------------- texture generators

/// Bricks 32×16 with 2-texel mortar lines, alternate courses offset by half a brick.
fn bricks(n: usize) -> Image {
    image_from(3, n, n, |y, x| {
        let course = y / 16;
        let xs = x + if course % 2 == 1 { 16 } else { 0 };
        let brick = (xs / 32) % (n / 32);
        let mortar = y % 16 < 2 || xs % 32 < 2;
        let mut v = [0.0; 4];
        for (c, v) in v.iter_mut().enumerate().take(3) {
            let base = if mortar {
                0.75
            } else {
                [0.55, 0.25, 0.18][c] + 0.15 * cell_rand(course, brick, 0, 1)
            };
            *v = base + noise(y, x, c, 0.02);
        }
        v
    })
}

/// Diagonal two-colour stripes of period 16 with a little noise.
fn stripes(n: usize) -> Image {
    image_from(3, n, n, |y, x| {
        let t = ((x + 2 * y) % 16) as f32 / 16.0;
        let s = 0.5 + 0.5 * (TAU * t).sin();
        let a = [0.1, 0.3, 0.6];
        let b = [0.9, 0.8, 0.3];
        let mut v = [0.0; 4];
        for c in 0..3 {
            v[c] = a[c] + (b[c] - a[c]) * s + noise(y, x, c, 0.03);
        }
        v
    })
}

/// A 16-texel checker with a per-cell colour jitter and a little noise.
fn checker(n: usize) -> Image {
    image_from(3, n, n, |y, x| {
        let (cy, cx) = (y / 16, x / 16);
        let dark = (cy + cx) % 2 == 0;
        let mut v = [0.0; 4];
        for (c, v) in v.iter_mut().enumerate().take(3) {
            let base = if dark { 0.15 } else { 0.8 };
            *v = base + 0.12 * (cell_rand(cy, cx, c, 2) - 0.5) + noise(y, x, c, 0.02);
        }
        v
    })
}

/// A smooth random pattern of period 32 in both directions, repeated, plus a little noise.
fn periodic_noise(n: usize) -> Image {
    let mut rng = Rng::new(7);
    let waves: Vec<(f32, f32, f32, f32, usize)> = (0..8)
        .map(|k| {
            let fy = rng.range(0, 3) as f32;
            let fx = rng.range(1, 3) as f32 * if rng.f64() < 0.5 { -1.0 } else { 1.0 };
            (
                fy,
                fx,
                rng.uniform(0.0, TAU),
                rng.uniform(0.05, 0.15),
                k % 3,
            )
        })
        .collect();
    image_from(3, n, n, |y, x| {
        let mut v = [0.45, 0.4, 0.35, 0.0];
        for (c, v) in v.iter_mut().enumerate().take(3) {
            *v += noise(y, x, c, 0.02);
        }
        for &(fy, fx, ph, amp, c) in &waves {
            let t = TAU * (fy * y as f32 + fx * x as f32) / 32.0 + ph;
            v[c] += amp * t.sin();
            v[(c + 1) % 3] += 0.5 * amp * t.sin();
        }
        v
    })
}

// -------------------------------------------------------------- validation

#[test]
fn invalid_arguments_are_refused() {
    let img = Image::zeros(3, 8, 8);
    let known = vec![true; 64];
    let mut some = known.clone();
    some[5] = false;
    let opts = InpaintOptions::default();
    for ip in inpainters() {
        let name = ip.name().to_string();
        let invalid = |r: picker_inpaint::Result<Image>, what: &str| match r {
            Err(Error::Invalid(msg)) => println!("{name}: {what}: {msg}"),
            other => panic!("{name}: {what}: expected Error::Invalid, got {other:?}"),
        };
        invalid(ip.inpaint(&img, &known[..63], &opts), "short mask");
        invalid(
            ip.inpaint(&Image::zeros(5, 8, 8), &some, &opts),
            "5 channels",
        );
        invalid(
            ip.inpaint(
                &Image {
                    channels: 0,
                    height: 8,
                    width: 8,
                    data: vec![],
                },
                &some,
                &opts,
            ),
            "0 channels",
        );
        invalid(
            ip.inpaint(
                &Image {
                    channels: 3,
                    height: 8,
                    width: 8,
                    data: vec![0.0; 10],
                },
                &some,
                &opts,
            ),
            "inconsistent data",
        );
        invalid(ip.inpaint(&Image::zeros(1, 0, 4), &[], &opts), "empty");
        for p in [0, 1, 2, 4, 8] {
            let o = InpaintOptions {
                patch_size: p,
                ..opts
            };
            invalid(ip.inpaint(&img, &some, &o), "bad patch size");
        }
        let mut nan = img.clone();
        nan.data[0] = f32::NAN;
        invalid(ip.inpaint(&nan, &some, &opts), "NaN known texel");
        match ip.inpaint(&img, &[false; 64], &opts) {
            Err(
                e @ Error::NothingKnown {
                    width: 8,
                    height: 8,
                },
            ) => println!("{name}: {e}"),
            other => panic!("{name}: expected NothingKnown, got {other:?}"),
        }
        assert!(matches!(
            ip.inpaint(&Image::zeros(1, 1, 1), &[false], &opts),
            Err(Error::NothingKnown { .. })
        ));
    }
}

// ----------------------------------------------------------------- contract

#[test]
fn all_known_is_identity() {
    let img = checker(32);
    let known = vec![true; 32 * 32];
    for ip in inpainters() {
        let out = ip
            .inpaint(&img, &known, &InpaintOptions::default())
            .unwrap();
        assert_eq!(out, img, "{}", ip.name());
    }
}

#[test]
fn known_texels_are_kept_and_unknown_never_read() {
    let img = bricks(64);
    let known = blob_mask(64, 64, 0.3, 3);
    let input = poisoned(&img, &known);
    for ip in inpainters() {
        for toroidal in [true, false] {
            let opts = InpaintOptions {
                toroidal,
                seed: 5,
                patch_size: 5,
            };
            let out = ip.inpaint(&input, &known, &opts).unwrap();
            assert_known_kept(&out, &input, &known);
        }
    }
}

#[test]
fn tiny_and_thin_images() {
    let shapes = [
        (1, 1),
        (1, 2),
        (2, 1),
        (1, 9),
        (9, 1),
        (1, 40),
        (2, 2),
        (3, 3),
        (5, 5),
        (6, 7),
        (7, 7),
        (9, 3),
        (8, 13),
        (16, 9),
        (37, 100),
        (61, 45),
    ];
    for (h, w) in shapes {
        for c in 1..=4 {
            let img = image_from(c, h, w, |y, x| {
                let v = ((x * 7 + y * 3) % 5) as f32 / 5.0;
                [v, 1.0 - v, 0.5 * v, 0.25]
            });
            let mut known: Vec<bool> = (0..h * w).map(|i| i % 3 != 1).collect();
            known[0] = true;
            let input = poisoned(&img, &known);
            for ip in inpainters() {
                for toroidal in [true, false] {
                    for patch_size in [3, 7] {
                        let opts = InpaintOptions {
                            toroidal,
                            seed: 1,
                            patch_size,
                        };
                        let out = ip
                            .inpaint(&input, &known, &opts)
                            .unwrap_or_else(|e| panic!("{} {h}x{w}x{c}: {e}", ip.name()));
                        assert_known_kept(&out, &input, &known);
                    }
                }
            }
        }
    }
    // A single unknown texel between two known ones is their mean.
    let img = Image::new(1, 1, 3, vec![0.2, f32::NAN, 0.6]).unwrap();
    let out = DiffusionInpainter::default()
        .inpaint(
            &img,
            &[true, false, true],
            &InpaintOptions {
                toroidal: false,
                ..Default::default()
            },
        )
        .unwrap();
    assert!((out.data[1] - 0.4).abs() < 1e-4, "{}", out.data[1]);
}

#[test]
fn deterministic_for_a_seed_whatever_the_thread_count() {
    let img = stripes(96);
    let known = blob_mask(96, 96, 0.3, 11);
    let opts = InpaintOptions {
        toroidal: true,
        seed: 42,
        patch_size: 7,
    };
    let pm = PatchMatchInpainter::default();
    let run = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| pm.inpaint(&img, &known, &opts).unwrap())
    };
    let a = run(1);
    let b = run(3);
    let c = pm.inpaint(&img, &known, &opts).unwrap();
    let bits = |i: &Image| i.data.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&a), bits(&b), "1 vs 3 threads");
    assert_eq!(bits(&a), bits(&c), "repeat");
    let d1 = DiffusionInpainter::default();
    let x = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap()
        .install(|| d1.inpaint(&img, &known, &opts).unwrap());
    let y = d1.inpaint(&img, &known, &opts).unwrap();
    assert_eq!(bits(&x), bits(&y), "diffusion");
}

// ----------------------------------------------------------------- toroidal

#[test]
fn toroidal_fill_across_the_wrap_edge_is_seamless() {
    let n = 96;
    let img = periodic_noise(n);
    // A square hole centred on the corner: it straddles both wrap edges.
    let known: Vec<bool> = (0..n * n)
        .map(|i| {
            let (y, x) = (i / n, i % n);
            let dy = y.min(n - y);
            let dx = x.min(n - x);
            !(dy < 12 && dx < 12)
        })
        .collect();
    let before = seam_score(&img);
    for ip in inpainters() {
        let out = ip
            .inpaint(&poisoned(&img, &known), &known, &InpaintOptions::default())
            .unwrap();
        let s = seam_score(&out);
        println!(
            "seam {:>10}: wrap {:.4} interior {:.4} ratio {:.3} (original ratio {:.3}), hole PSNR {:.2} dB",
            ip.name(),
            s.wrap,
            s.interior,
            s.ratio,
            before.ratio,
            psnr(&out, &img, Some(&known.iter().map(|k| !k).collect::<Vec<_>>()))
        );
        assert!(s.ratio <= 1.1, "{}: seam ratio {}", ip.name(), s.ratio);
    }
}

// ------------------------------------------------------------------ quality

#[test]
fn patchmatch_beats_diffusion_on_textures() {
    let n = 128;
    let cases: [(&str, Image, bool); 6] = [
        ("bricks", bricks(n), false),
        ("stripes", stripes(n), false),
        ("checker", checker(n), false),
        ("periodic-noise", periodic_noise(n), false),
        // 30% of single texels missing, as reprojection leaves them.
        ("bricks/scatter", bricks(n), true),
        ("checker/scatter", checker(n), true),
    ];
    let pm = PatchMatchInpainter::default();
    let diff = DiffusionInpainter::default();
    println!("texture          method      hole PSNR dB   colour-stats distance (hole)");
    for (k, (name, img, scatter)) in cases.iter().enumerate() {
        let known = if *scatter {
            let mut rng = Rng::new(100 + k as u64);
            (0..n * n).map(|_| rng.f64() >= 0.3).collect()
        } else {
            blob_mask(n, n, 0.3, 100 + k as u64)
        };
        let hole: Vec<bool> = known.iter().map(|k| !k).collect();
        let input = poisoned(img, &known);
        let opts = InpaintOptions {
            toroidal: true,
            seed: 1,
            patch_size: 7,
        };
        let truth = hole_texels(img, &known);
        let mut scores = vec![];
        for ip in [&pm as &dyn Inpainter, &diff] {
            let t = std::time::Instant::now();
            let out = ip.inpaint(&input, &known, &opts).unwrap();
            let el = t.elapsed();
            let p = psnr(&out, img, Some(&hole));
            let d = colour_stats_distance(&hole_texels(&out, &known), &truth);
            println!(
                "{name:<16} {:<11} {p:>9.2}      {d:.4}   ({:.0} ms)",
                ip.name(),
                el.as_secs_f64() * 1e3
            );
            scores.push((p, d));
        }
        let ((p_pm, d_pm), (p_df, d_df)) = (scores[0], scores[1]);
        assert!(
            p_pm > p_df,
            "{name}: PSNR PatchMatch {p_pm:.2} <= diffusion {p_df:.2}"
        );
        assert!(
            d_pm < d_df,
            "{name}: colour distance PatchMatch {d_pm:.4} >= diffusion {d_df:.4}"
        );
    }
}

/// An `n × n` RGB image of a random 16×16 tile repeated: every texel
/// exists elsewhere.
fn repeated_tile(n: usize) -> Image {
    let mut rng = Rng::new(3);
    let tile: Vec<[f32; 4]> = (0..256)
        .map(|_| {
            [
                rng.uniform(0.0, 1.0),
                rng.uniform(0.0, 1.0),
                rng.uniform(0.0, 1.0),
                0.0,
            ]
        })
        .collect();
    image_from(3, n, n, |y, x| tile[(y % 16) * 16 + x % 16])
}

#[test]
fn exact_copies_are_reconstructed() {
    // A random 16×16 tile repeated: every hole texel exists elsewhere.
    let n = 96;
    let img = repeated_tile(n);
    let known = blob_mask(n, n, 0.3, 21);
    let hole: Vec<bool> = known.iter().map(|k| !k).collect();
    for toroidal in [true, false] {
        let opts = InpaintOptions {
            toroidal,
            seed: 2,
            patch_size: 7,
        };
        let out = PatchMatchInpainter::default()
            .inpaint(&poisoned(&img, &known), &known, &opts)
            .unwrap();
        let p = psnr(&out, &img, Some(&hole));
        let pd = psnr(
            &DiffusionInpainter::default()
                .inpaint(&img, &known, &opts)
                .unwrap(),
            &img,
            Some(&hole),
        );
        println!(
            "exact-copy toroidal={toroidal}: PatchMatch hole PSNR {p:.2} dB (diffusion {pd:.2} dB)"
        );
        assert!(p > 40.0, "toroidal={toroidal}: PSNR {p:.2} dB");
    }
}

// ------------------------------------------------------------------ metrics

#[test]
fn psnr_values() {
    let a = Image::new(1, 2, 2, vec![0.0, 0.5, 1.0, 0.25]).unwrap();
    assert_eq!(psnr(&a, &a, None), f64::INFINITY);
    let b = a.map(|v| v + 0.1);
    assert!((psnr(&a, &b, None) - 20.0).abs() < 1e-4);
    let mut c = a.clone();
    c.data[3] = 0.0;
    assert_eq!(
        psnr(&a, &c, Some(&[true, true, true, false])),
        f64::INFINITY
    );
    assert!(
        (psnr(&a, &c, Some(&[false, false, false, true])) - -10.0 * (0.0625f64).log10()).abs()
            < 1e-4
    );
    assert!(psnr(&a, &c, Some(&[false; 4])).is_nan());
    assert!(psnr(&a, &Image::zeros(1, 2, 3), None).is_nan());
    assert!(psnr(&a, &c, Some(&[true; 3])).is_nan());
}

#[test]
fn colour_stats_distance_properties() {
    let mut rng = Rng::new(8);
    let imgs: Vec<Image> = (0..6)
        .map(|k| {
            let (h, w) = (8 + k, 12 - k);
            let lo = 0.1 * k as f32;
            Image::new(3, h, w, rng.uniform_vec(3 * h * w, lo, (lo + 0.5).min(1.0))).unwrap()
        })
        .collect();
    for a in &imgs {
        assert_eq!(colour_stats_distance(a, a), 0.0);
        for b in &imgs {
            let d = colour_stats_distance(a, b);
            assert!(d >= 0.0);
            assert_eq!(d, colour_stats_distance(b, a), "symmetric");
            for c in &imgs {
                assert!(d <= colour_stats_distance(a, c) + colour_stats_distance(c, b) + 1e-12);
            }
        }
    }
    // A permutation of the texels has the same statistics.
    let a = &imgs[0];
    let mut rev = a.clone();
    let n = a.height * a.width;
    for c in 0..3 {
        rev.data[c * n..(c + 1) * n].reverse();
    }
    assert!(colour_stats_distance(a, &rev) < 1e-12);
    // A flat image has no spread and another mean: clearly positive.
    let flat = a.map(|_| 0.3);
    assert!(colour_stats_distance(a, &flat) > 0.1);
    assert!(colour_stats_distance(a, &Image::zeros(1, 2, 2)).is_nan());
}

// ------------------------------------------------------------------ timings

/// `cargo test --release -p picker-inpaint --test inpaint timings -- --ignored --nocapture`
#[test]
#[ignore = "timings for the report; slow in debug builds"]
fn timings() {
    // Blob holes (30%), then the case `picker extract` meets with collapsed
    // predicted UVs: 1024² with only a few hundred scattered known texels.
    let cases = [(256, false), (512, false), (1024, false), (1024, true)];
    for (n, sparse) in cases {
        let img = bricks(n);
        let known = if sparse {
            let mut rng = Rng::new(5);
            (0..n * n).map(|_| rng.f64() < 3e-4).collect()
        } else {
            blob_mask(n, n, 0.3, 5)
        };
        let hole: Vec<bool> = known.iter().map(|k| !k).collect();
        let opts = InpaintOptions::default();
        for ip in inpainters() {
            let t = std::time::Instant::now();
            let out = ip.inpaint(&img, &known, &opts).unwrap();
            let el = t.elapsed().as_secs_f64();
            println!(
                "{n:>5}²{} {:<11} {el:>7.3} s  hole PSNR {:.2} dB, colour distance {:.4}",
                if sparse { " sparse" } else { "" },
                ip.name(),
                psnr(&out, &img, Some(&hole)),
                colour_stats_distance(&hole_texels(&out, &known), &hole_texels(&img, &known))
            );
        }
    }
}

/// Scattered observed texels at densities from 0.03% to 30% (256², toroidal):
/// PatchMatch against diffusion. Below about 0.1% (fewer than 5% of the 7×7
/// patches hold an observed texel) PatchMatch falls back to the harmonic fill
/// and must score the same as diffusion; above, the numbers are printed
/// (`-- --nocapture`).
#[test]
fn density_sweep() {
    let n = 128;
    let pm = PatchMatchInpainter::default();
    let diff = DiffusionInpainter::default();
    for dens in [0.0003, 0.001, 0.003, 0.01, 0.03, 0.1, 0.3] {
        for (name, img) in [
            ("bricks", bricks(n)),
            ("checker", checker(n)),
            ("noise", periodic_noise(n)),
        ] {
            let mut rng = Rng::new(5);
            let mut known: Vec<bool> = (0..n * n).map(|_| rng.f64() < dens).collect();
            known[0] = true;
            let hole: Vec<bool> = known.iter().map(|k| !k).collect();
            let opts = InpaintOptions::default();
            let input = poisoned(&img, &known);
            let a = pm.inpaint(&input, &known, &opts).unwrap();
            let b = diff.inpaint(&input, &known, &opts).unwrap();
            assert_known_kept(&a, &input, &known);
            let (pa, pb) = (psnr(&a, &img, Some(&hole)), psnr(&b, &img, Some(&hole)));
            let truth = hole_texels(&img, &known);
            let da = colour_stats_distance(&hole_texels(&a, &known), &truth);
            let db = colour_stats_distance(&hole_texels(&b, &known), &truth);
            println!(
                "density {dens:<6} {name:<8} patchmatch {pa:.2} dB {da:.4}   diffusion {pb:.2} dB {db:.4}"
            );
            if dens <= 0.001 {
                // The harmonic fallback: the baseline's scores.
                assert!((pa - pb).abs() < 0.05, "{name} {dens}: PSNR {pa} vs {pb}");
                assert!(
                    (da - db).abs() < 0.005,
                    "{name} {dens}: colour {da} vs {db}"
                );
            }
        }
    }
}

#[test]
fn finest_level_stops_once_settled() {
    // The finest level's EM loop stops after an iteration that moves the
    // unknown texels by at most `finest_mean_tolerance` on average: periodic
    // noise with blob holes settles after one (the result is that of a single
    // iteration); an exact copy without wrapping still moves a lot and gets
    // its second (the result is that of no early stop).
    let n = 128;
    let run = |img: &Image, known: &[bool], toroidal: bool, ip: PatchMatchInpainter| {
        let opts = InpaintOptions {
            toroidal,
            seed: 3,
            patch_size: 7,
        };
        ip.inpaint(&poisoned(img, known), known, &opts).unwrap()
    };
    let default = PatchMatchInpainter::default();
    assert_eq!(default.em_iterations_finest, 2);
    let one = PatchMatchInpainter {
        em_iterations_finest: 1,
        ..default
    };
    let never = PatchMatchInpainter {
        finest_mean_tolerance: -1.0,
        ..default
    };
    let img = periodic_noise(n);
    let known = blob_mask(n, n, 0.3, 31);
    let a = run(&img, &known, true, default);
    assert!(
        a == run(&img, &known, true, one),
        "periodic noise: settled after one"
    );
    assert_ne!(
        a,
        run(&img, &known, true, never),
        "periodic noise: a second iteration differs"
    );
    let copy = repeated_tile(96);
    let known = blob_mask(96, 96, 0.3, 21);
    let b = run(&copy, &known, false, default);
    assert_eq!(
        b,
        run(&copy, &known, false, never),
        "exact copy: both iterations"
    );
    assert_ne!(
        b,
        run(&copy, &known, false, one),
        "exact copy: one iteration differs"
    );
}
