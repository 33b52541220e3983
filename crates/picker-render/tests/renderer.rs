//! Renderer tests (issue 3, item 1): white furnace, Monte Carlo agreement,
//! solid angles, fast path vs exact quadrature, re-rendering from element files.

use glam::{DVec3, Vec3};
use picker_nets::conventions as conv;
use picker_render::phong::{reflect, resolved_exponent};
use picker_render::{
    io, rerender, shade_exact, ElementImages, EnvMap, EnvQuadrature, Image, PhongMaterial,
    PrefilteredEnv, Quality,
};
use picker_tensor::Rng;

/// Relative error allowed between the fast path and the exact quadrature, per
/// channel, of the total radiance (measured worst case over the cases below: see
/// `fast_path_matches_exact`).
const FAST_REL: f32 = 0.03;

fn random_unit(rng: &mut Rng) -> Vec3 {
    loop {
        let v = Vec3::new(
            rng.uniform(-1.0, 1.0),
            rng.uniform(-1.0, 1.0),
            rng.uniform(-1.0, 1.0),
        );
        let l = v.length();
        if l > 0.1 && l <= 1.0 {
            return v / l;
        }
    }
}

/// A random view in the hemisphere of `n` with `N·V ≥ min_mu`.
fn random_view(rng: &mut Rng, n: Vec3, min_mu: f32) -> Vec3 {
    loop {
        let v = random_unit(rng);
        if v.dot(n) >= min_mu {
            return v;
        }
    }
}

fn random_material(rng: &mut Rng, max_exponent: f32) -> PhongMaterial {
    PhongMaterial {
        diffuse: Vec3::new(
            rng.uniform(0.0, 1.0),
            rng.uniform(0.0, 1.0),
            rng.uniform(0.0, 1.0),
        ),
        specular: Vec3::splat(rng.uniform(0.0, 1.0)),
        exponent: rng.uniform(0.0, max_exponent.log2()).exp2(),
    }
}

/// A random smooth environment: a sky gradient plus a few soft "suns" of random
/// direction, width and colour.
fn random_env(rng: &mut Rng, w: usize, h: usize) -> EnvMap {
    let probe = EnvMap::uniform(w, h, Vec3::ZERO);
    let suns: Vec<(Vec3, f32, Vec3)> = (0..3)
        .map(|_| {
            (
                random_unit(rng),
                rng.uniform(2.0, 12.0),
                Vec3::new(
                    rng.uniform(0.5, 5.0),
                    rng.uniform(0.5, 5.0),
                    rng.uniform(0.5, 5.0),
                ),
            )
        })
        .collect();
    let base = Vec3::new(
        rng.uniform(0.1, 1.0),
        rng.uniform(0.1, 1.0),
        rng.uniform(0.1, 1.0),
    );
    let data = (0..h * w)
        .map(|i| {
            let d = probe.direction(i / w, i % w);
            let mut l = base * (1.0 + 0.5 * d.y);
            for (s, k, c) in &suns {
                l += *c * (k * (d.dot(*s) - 1.0)).exp();
            }
            l
        })
        .collect();
    EnvMap::new(w, h, data).unwrap()
}

/// Pixel noise: every pixel independent in [0, 2).
fn noise_env(rng: &mut Rng, w: usize, h: usize) -> EnvMap {
    let data = (0..h * w)
        .map(|_| {
            Vec3::new(
                rng.uniform(0.0, 2.0),
                rng.uniform(0.0, 2.0),
                rng.uniform(0.0, 2.0),
            )
        })
        .collect();
    EnvMap::new(w, h, data).unwrap()
}

#[test]
fn solid_angles_sum_to_4pi() {
    for (h, w) in [(16, 32), (30, 40), (1, 1), (7, 3), (64, 128)] {
        let s: f64 = (0..h)
            .map(|r| conv::pixel_solid_angle(r, h, w) * w as f64)
            .sum();
        assert!(
            (s / (4.0 * std::f64::consts::PI) - 1.0).abs() < 1e-12,
            "{h}x{w}: {s}"
        );
        // Irradiance of a uniform unit map on any normal is π.
        let env = EnvMap::uniform(w, h, Vec3::ONE);
        let mean = env.mean();
        assert!((mean - Vec3::ONE).abs().max_element() < 1e-6);
    }
}

#[test]
fn white_furnace_exact_and_fast() {
    let white = PhongMaterial {
        diffuse: Vec3::ONE,
        specular: Vec3::ZERO,
        exponent: 1.0,
    };
    let mut rng = Rng::new(7);
    for (w, h) in [(32, 16), (40, 30), (128, 64)] {
        let env = EnvMap::uniform(w, h, Vec3::ONE);
        let q = EnvQuadrature::new(&env);
        let fast = PrefilteredEnv::new(&env);
        // The exact quadrature's error is the discretisation of max(0, ω·N) over
        // the map's pixels: ≤ 0.5% at 16 rows.
        let tol = if h < 32 { 5e-3 } else { 1e-3 };
        for _ in 0..200 {
            let n = random_unit(&mut rng);
            let v = random_view(&mut rng, n, 0.0);
            let e = q.shade(n, v, &white);
            assert!(
                (e - Vec3::ONE).abs().max_element() < tol,
                "{w}x{h} exact {n}: {e}"
            );
            let f = fast.shade(n, v, &white);
            assert!(
                (f - Vec3::ONE).abs().max_element() < tol,
                "{w}x{h} fast {n}: {f}"
            );
        }
        // Specular furnace: ρs = 1, view along the normal → the lobe's albedo,
        // exactly 1, for every exponent the map resolves (beyond, both paths alias).
        let n_max = resolved_exponent(h) as f32;
        for e in [1.0f32, 2.0, 5.0, 20.0, 100.0, 1000.0, 8192.0] {
            if e > n_max {
                continue;
            }
            let m = PhongMaterial {
                diffuse: Vec3::ZERO,
                specular: Vec3::ONE,
                exponent: e,
            };
            let n = random_unit(&mut rng);
            let f = fast.shade(n, n, &m);
            assert!(
                (f - Vec3::ONE).abs().max_element() < 0.02,
                "{w}x{h} fast n={e}: {f}"
            );
            let x = q.shade(n, n, &m);
            assert!(
                (x - Vec3::ONE).abs().max_element() < 0.02,
                "{w}x{h} exact n={e}: {x}"
            );
        }
    }
}

/// `shade_exact` against a seeded Monte Carlo estimate of the same integral
/// over the continuous (bilinearly interpolated) map, uniform sphere sampling.
#[test]
fn exact_agrees_with_monte_carlo() {
    let mut rng = Rng::new(21);
    let (w, h) = (64, 32);
    let env = random_env(&mut rng, w, h);
    let samples = 200_000;
    for case in 0..4 {
        let n = random_unit(&mut rng);
        let v = random_view(&mut rng, n, 0.2);
        let m = random_material(&mut rng, resolved_exponent(h) as f32);
        let exact = shade_exact(&env, n, v, &m).as_dvec3();
        // Uniform sphere sampling: E[f·L·cos / (1/4π)], seeded.
        let (nd, vd) = (n.as_dvec3(), v.as_dvec3());
        let mut sum = DVec3::ZERO;
        let mut sum2 = DVec3::ZERO;
        for _ in 0..samples {
            let z = rng.f64() * 2.0 - 1.0;
            let phi = rng.f64() * 2.0 * std::f64::consts::PI;
            let r = (1.0 - z * z).sqrt();
            let wi = DVec3::new(r * phi.cos(), r * phi.sin(), z);
            let cos = wi.dot(nd);
            let x = if cos > 0.0 {
                picker_render::brdf(&m, wi, vd, nd)
                    * env.sample(wi.as_vec3()).as_dvec3()
                    * cos
                    * (4.0 * std::f64::consts::PI)
            } else {
                DVec3::ZERO
            };
            sum += x;
            sum2 += x * x;
        }
        let mean = sum / samples as f64;
        let var = sum2 / samples as f64 - mean * mean;
        let stderr = (var / samples as f64).max(DVec3::ZERO);
        for c in 0..3 {
            let se = stderr[c].sqrt();
            // 5 standard errors of the estimate, plus 1.5% for the difference
            // between a pixel-centre sum and the bilinear continuous integral.
            let tol = 5.0 * se + 0.015 * exact[c];
            assert!(
                (mean[c] - exact[c]).abs() <= tol,
                "case {case} channel {c}: MC {} ± {se}, exact {} (n = {}, ρs = {})",
                mean[c],
                exact[c],
                m.exponent,
                m.specular
            );
        }
    }
    // Check that the reflection used by the BRDF is the one of eq. 3.7.
    let r = reflect(DVec3::new(0.6, 0.0, 0.8), DVec3::Z);
    assert!((r - DVec3::new(-0.6, 0.0, 0.8)).length() < 1e-12);
}

/// Fast path vs exact quadrature on random smooth and noisy maps, random
/// normals, views (N·V ≥ 0.05) and materials, with exponents up to what each
/// map resolves (`resolved_exponent`): per-channel relative error of the total
/// radiance ≤ [`FAST_REL`].
#[test]
fn fast_path_matches_exact() {
    let mut rng = Rng::new(99);
    let mut worst = 0.0f32;
    let mut sum = 0.0f64;
    let mut count = 0usize;
    for (map, (w, h)) in [(16usize, 32usize), (32, 64), (30, 40), (64, 128)]
        .into_iter()
        .map(|(h, w)| (w, h))
        .enumerate()
    {
        for kind in 0..2 {
            let env = if kind == 0 {
                random_env(&mut rng, w, h)
            } else {
                noise_env(&mut rng, w, h)
            };
            let q = EnvQuadrature::new(&env);
            let fast = PrefilteredEnv::new(&env);
            let n_max = resolved_exponent(h) as f32;
            for _ in 0..150 {
                let n = random_unit(&mut rng);
                let v = random_view(&mut rng, n, 0.05);
                let m = random_material(&mut rng, n_max);
                let (e, f) = (q.shade(n, v, &m), fast.shade(n, v, &m));
                for c in 0..3 {
                    let rel = (f[c] - e[c]).abs() / e[c].max(1e-3);
                    sum += rel as f64;
                    count += 1;
                    if rel > worst {
                        worst = rel;
                    }
                    assert!(
                        rel <= FAST_REL,
                        "map {map} ({h}x{w}, kind {kind}): n={n} v={v} {m:?}: fast {f} exact {e}"
                    );
                }
            }
        }
    }
    println!(
        "fast vs exact: worst relative error {worst:.4}, mean {:.5}",
        sum / count as f64
    );
}

fn write_elements(dir: &std::path::Path, h: usize, w: usize, material: &PhongMaterial) {
    let mut d = Image::zeros(3, h, w);
    let mut s = Image::zeros(3, h, w);
    let mut n = Image::zeros(3, h, w);
    let mut v = Image::zeros(3, h, w);
    for i in 0..h * w {
        d.set_rgb(i, material.diffuse);
        s.set_rgb(i, material.specular);
        // Last pixel: no surface.
        n.set_rgb(
            i,
            if i + 1 == h * w {
                Vec3::ZERO
            } else {
                Vec3::new(0.0, 0.6, 0.8)
            },
        );
        v.set_rgb(i, Vec3::Z);
    }
    let g = Image::new(
        1,
        h,
        w,
        vec![conv::glossiness_from_exponent(material.exponent); h * w],
    )
    .unwrap();
    for (name, img) in [
        (conv::DIFFUSE_ALBEDO, &d),
        (conv::SPECULAR_ALBEDO, &s),
        (conv::GLOSSINESS, &g),
        (conv::NORMALS, &n),
        (conv::VIEW_VECTOR, &v),
    ] {
        io::write_exr(&dir.join(format!("{name}.exr")), img).unwrap();
    }
}

#[test]
fn rerender_from_element_files() {
    let dir = tempfile::tempdir().unwrap();
    let (h, w) = (4, 5);
    let m = PhongMaterial {
        diffuse: Vec3::new(0.5, 0.25, 1.0),
        specular: Vec3::ZERO,
        exponent: 1.0,
    };
    write_elements(dir.path(), h, w, &m);
    let el = ElementImages::load(dir.path()).unwrap();
    let env = EnvMap::uniform(40, 20, Vec3::splat(2.0));
    for q in [Quality::Exact, Quality::Fast] {
        let img = rerender(&el, &env, q);
        assert_eq!((img.channels, img.height, img.width), (3, h, w));
        for i in 0..h * w - 1 {
            assert!(
                (img.rgb(i) - 2.0 * m.diffuse).abs().max_element() < 5e-3,
                "{q:?} {}",
                img.rgb(i)
            );
        }
        assert_eq!(img.rgb(h * w - 1), Vec3::ZERO);
    }
    // A size mismatch names the file; a missing element names the file.
    let g = dir.path().join("glossiness.exr");
    let good = io::read_exr(&g).unwrap();
    io::write_exr(&g, &Image::zeros(1, 3, 5)).unwrap();
    let e = ElementImages::load(dir.path()).unwrap_err().to_string();
    assert!(e.contains("glossiness.exr") && e.contains("4x5"), "{e}");
    io::write_exr(&g, &good).unwrap();
    std::fs::remove_file(dir.path().join("normals.exr")).unwrap();
    let e = ElementImages::load(dir.path()).unwrap_err().to_string();
    assert!(e.contains("normals.exr"), "{e}");
}

#[test]
fn previews() {
    let env = EnvMap::uniform(32, 16, Vec3::ONE);
    let m = PhongMaterial {
        diffuse: Vec3::splat(0.5),
        specular: Vec3::splat(0.3),
        exponent: 50.0,
    };
    let s = picker_render::preview_sphere(&m, &env, 32);
    assert_eq!((s.channels, s.height, s.width), (3, 32, 32));
    assert_eq!(s.rgb(0), Vec3::ZERO); // corner: outside the sphere
    let centre = s.rgb(16 * 32 + 16);
    assert!(
        (centre - Vec3::splat(0.8)).abs().max_element() < 0.02,
        "{centre}"
    );
    let tex = Image::new(3, 1, 2, vec![1.0, 0.0, 1.0, 0.0, 1.0, 0.0]).unwrap();
    let t = picker_render::preview_tile(&m, &env, 32, Some(&tex));
    assert_eq!(t.rgb(0), Vec3::ZERO);
    let mid = t.rgb(16 * 32 + 16);
    assert!(mid.max_element() > 0.3, "{mid}");
    let plain = picker_render::preview_tile(&m, &env, 32, None);
    assert!(
        (plain.rgb(16 * 32 + 16) - Vec3::splat(0.8))
            .abs()
            .max_element()
            < 0.05
    );
}

#[test]
fn preview_exposure_is_set_by_the_lighting() {
    use picker_render::{preview_exposure, Quality, Shader, PREVIEW_WHITE};
    // Uniform radiance L: a white Lambertian sphere shows L, so the exposure
    // is WHITE / L, for any L.
    for l in [0.02f32, 1.0, 250.0] {
        let e = preview_exposure(&Shader::new(
            &EnvMap::uniform(32, 16, Vec3::splat(l)),
            Quality::Fast,
        ));
        assert!((e * l / PREVIEW_WHITE - 1.0).abs() < 2e-2, "L {l}: {e}");
    }
    // Light from one side only: half the disc is dark, the exposure rises
    // above that of uniform light of the same radiance.
    let mut img = Image::zeros(3, 16, 32);
    for y in 0..16 {
        for x in 16..32 {
            img.set_rgb(y * 32 + x, Vec3::ONE);
        }
    }
    let half = EnvMap::from_image(&img).unwrap();
    let e = preview_exposure(&Shader::new(&half, Quality::Fast));
    assert!(e > PREVIEW_WHITE * 1.2, "{e}");
    // No light: 1 (no division by zero).
    let dark = Shader::new(&EnvMap::uniform(8, 4, Vec3::ZERO), Quality::Fast);
    assert_eq!(preview_exposure(&dark), 1.0);
}

/// `PrefilteredEnv::resolving`: exponents the map resolves give the same
/// specular bits as the plain fast path, and the diffuse term of the map
/// upsampled to 64 rows; narrower lobes, which alias on the map itself
/// (a uniform sky's specular furnace falls to nothing between pixel
/// centres), give the exact quadrature over the map's bilinear upsampling
/// fine enough to resolve them, and the furnace's 1 everywhere.
#[test]
fn the_resolving_fast_path_does_not_alias_narrow_lobes() {
    let mut rng = Rng::new(48);
    let (w, h) = (40, 30);
    let env = random_env(&mut rng, w, h);
    let plain = PrefilteredEnv::new(&env);
    let smooth = PrefilteredEnv::resolving(&env);
    let n_max = resolved_exponent(h) as f32;
    // The diffuse term is the irradiance of the map upsampled to 64 rows.
    let q64 = EnvQuadrature::new(&env.resample((64 * w).div_ceil(h), 64).unwrap());
    for _ in 0..50 {
        let n = random_unit(&mut rng);
        let v = random_view(&mut rng, n, 0.2);
        let m = random_material(&mut rng, n_max);
        let glossy = PhongMaterial {
            diffuse: Vec3::ZERO,
            ..m
        };
        assert_eq!(
            plain.shade(n, v, &glossy),
            smooth.shade(n, v, &glossy),
            "n = {}",
            m.exponent
        );
        let matte = PhongMaterial {
            specular: Vec3::ZERO,
            ..m
        };
        let (f, x) = (smooth.shade(n, v, &matte), q64.shade(n, v, &matte));
        assert!(
            ((f - x).abs() / x.max(Vec3::splat(1e-3))).max_element() < FAST_REL,
            "diffuse {f} vs exact {x}"
        );
    }
    // A uniform sky, ρs = 1, view along the normal: exactly 1 for any lobe.
    let sky = EnvMap::uniform(w, h, Vec3::ONE);
    let (plain_sky, smooth_sky) = (PrefilteredEnv::new(&sky), PrefilteredEnv::resolving(&sky));
    for e in [200.0f32, 1000.0, 3000.0, 8192.0] {
        let m = PhongMaterial {
            diffuse: Vec3::ZERO,
            specular: Vec3::ONE,
            exponent: e,
        };
        let (mut lo, mut hi) = (f32::MAX, 0.0f32);
        let mut plain_lo = f32::MAX;
        for _ in 0..200 {
            let n = random_unit(&mut rng);
            let s = smooth_sky.shade(n, n, &m).x;
            (lo, hi) = (lo.min(s), hi.max(s));
            plain_lo = plain_lo.min(plain_sky.shade(n, n, &m).x);
        }
        assert!(lo > 0.97 && hi < 1.03, "n = {e}: {lo} … {hi}");
        if e >= 1000.0 {
            assert!(
                plain_lo < 0.5,
                "n = {e}: the map itself aliases ({plain_lo})"
            );
        }
    }
    // Against the exact quadrature over the upsampled map.
    for e in [300.0f32, 2000.0] {
        // One lobe width per pixel in the levels finer than the map.
        let rows = (std::f64::consts::PI * (e as f64).sqrt()).ceil() as usize;
        let rows = [16usize, 23, 32, 45, 64, 91, 128, 181, 256, 362, 512]
            .into_iter()
            .find(|&r| r > h && r >= rows)
            .unwrap();
        let fine = env.resample((rows * w).div_ceil(h), rows).unwrap();
        let q = EnvQuadrature::new(&fine);
        for _ in 0..10 {
            let n = random_unit(&mut rng);
            let v = random_view(&mut rng, n, 0.3);
            let m = PhongMaterial {
                diffuse: Vec3::ZERO,
                specular: Vec3::ONE,
                exponent: e,
            };
            let (f, x) = (smooth.shade(n, v, &m), q.shade(n, v, &m));
            assert!(
                ((f - x).abs() / x.max(Vec3::splat(1e-3))).max_element() < FAST_REL,
                "n = {e}: {f} vs exact {x}"
            );
        }
    }
}
