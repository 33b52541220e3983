//! The physically based Phong model of the thesis (eq. 3.7, design.md §3) and
//! its exact quadrature over an environment map — the reference every faster
//! path is tested against:
//!
//! `L(x) = Σ_i (ρd/π + ρs(n+2)·max(0, V·R_i)ⁿ/2π) · L_i · max(0, ω_i·N) · ΔΩ_i`,
//! `R_i = 2(ω_i·N)N − ω_i`,
//!
//! summed over every pixel `i` of the map (direction `ω_i` of its centre,
//! radiance `L_i`). `ΔΩ_i` is [`conv::pixel_solid_angle`], the exact area of
//! the pixel's latitude band, which sums to exactly 4π; the thesis writes
//! `(2π/W)(π/H)·cos(latitude)` ([`conv::pixel_solid_angle_thesis`]), which
//! differs by a factor `sinc(π/2H)` (1.6·10⁻³ at H = 16).
//!
//! The quadrature samples the lobe only at pixel centres, so it resolves a
//! lobe of exponent `n` (angular width ≈ `1/√n`) only while the map is fine
//! enough: about `n ≤ (H/5)²` ([`resolved_exponent`]); beyond, it aliases
//! (a narrow lobe falls between pixel centres).

use glam::{DVec3, Vec3};
use picker_nets::conventions as conv;

use crate::envmap::EnvMap;

/// A Phong material: linear-RGB albedos and the exponent `n` (glossiness g maps
/// to `n = 2^(13g)`, [`conv::phong_exponent`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PhongMaterial {
    /// Diffuse albedo ρd, linear RGB in `[0, 1]`.
    pub diffuse: Vec3,
    /// Specular albedo ρs, linear RGB in `[0, 1]`.
    pub specular: Vec3,
    /// Phong exponent `n ≥ 0` (1 … 8192 in the conventions).
    pub exponent: f32,
}

impl PhongMaterial {
    /// A material from albedos and a glossiness `g ∈ [0, 1]` ([`conv::phong_exponent`]).
    pub fn from_glossiness(diffuse: Vec3, specular: Vec3, glossiness: f32) -> Self {
        Self {
            diffuse,
            specular,
            exponent: conv::phong_exponent(glossiness),
        }
    }
}

/// The largest exponent whose lobe a map of `height` rows resolves: lobe
/// width `1/√n` at least 1.6 pixel spacings (`π/H`), i.e. `n ≤ (H/(1.6π))² ≈ (H/5)²`.
pub fn resolved_exponent(height: usize) -> f64 {
    let h = height as f64 / (1.6 * std::f64::consts::PI);
    (h * h).max(1.0)
}

/// Mirror reflection of `w` about the unit normal `n`: `2(w·n)n − w`.
pub fn reflect(w: DVec3, n: DVec3) -> DVec3 {
    2.0 * w.dot(n) * n - w
}

/// The normalised Phong lobe `(n+2)/2π · max(0, V·R)ⁿ` with `R = reflect(ωi, N)`
/// (unit vectors).
pub fn specular_lobe(wi: DVec3, wo: DVec3, normal: DVec3, exponent: f64) -> f64 {
    let c = wo.dot(reflect(wi, normal));
    if c <= 0.0 {
        0.0
    } else {
        (exponent + 2.0) / (2.0 * std::f64::consts::PI) * c.powf(exponent)
    }
}

/// The BRDF `f(ωi, ωo) = ρd/π + ρs·(n+2)/2π·max(0, ωo·R(ωi))ⁿ` (unit vectors).
/// It is symmetric in `ωi`, `ωo` (Helmholtz reciprocity): `ωo·R(ωi) =
/// 2(ωi·N)(ωo·N) − ωi·ωo`.
pub fn brdf(material: &PhongMaterial, wi: DVec3, wo: DVec3, normal: DVec3) -> DVec3 {
    material.diffuse.as_dvec3() / std::f64::consts::PI
        + material.specular.as_dvec3() * specular_lobe(wi, wo, normal, material.exponent as f64)
}

/// An environment map prepared for [`shade_exact`]-style quadrature: each
/// pixel's unit direction and `L_i·ΔΩ_i` in f64.
#[derive(Clone, Debug)]
pub struct EnvQuadrature {
    dirs: Vec<DVec3>,
    weighted: Vec<DVec3>,
}

impl EnvQuadrature {
    /// Precomputes directions and radiance × solid angle of every pixel
    /// (pixels with zero radiance are skipped).
    pub fn new(env: &EnvMap) -> Self {
        let (h, w) = (env.height(), env.width());
        let mut dirs = Vec::with_capacity(h * w);
        let mut weighted = Vec::with_capacity(h * w);
        for row in 0..h {
            let sa = conv::pixel_solid_angle(row, h, w);
            for col in 0..w {
                let l = env.get(row, col).as_dvec3();
                if l == DVec3::ZERO {
                    continue;
                }
                dirs.push(DVec3::from(conv::envmap_pixel_direction(row, col, h, w)));
                weighted.push(l * sa);
            }
        }
        Self { dirs, weighted }
    }

    /// Eq. 3.7 at a surface point with unit `normal` and unit `view` (towards
    /// the camera); see [`shade_exact`]. Accumulates in f64. A zero or
    /// non-finite normal gives black.
    pub fn shade(&self, normal: Vec3, view: Vec3, material: &PhongMaterial) -> Vec3 {
        let Some(n) = unit(normal) else {
            return Vec3::ZERO;
        };
        let v = unit(view).unwrap_or(DVec3::Z);
        let e = material.exponent.max(0.0) as f64;
        let spec_norm = (e + 2.0) / (2.0 * std::f64::consts::PI);
        let mut diffuse = DVec3::ZERO;
        let mut specular = DVec3::ZERO;
        let spec_on = material.specular != Vec3::ZERO;
        for (d, lw) in self.dirs.iter().zip(&self.weighted) {
            let cos_i = d.dot(n);
            if cos_i <= 0.0 {
                continue;
            }
            let c = *lw * cos_i;
            diffuse += c;
            if spec_on {
                let vr = 2.0 * cos_i * v.dot(n) - v.dot(*d);
                if vr > 0.0 {
                    specular += c * vr.powf(e);
                }
            }
        }
        (material.diffuse.as_dvec3() * diffuse / std::f64::consts::PI
            + material.specular.as_dvec3() * specular * spec_norm)
            .as_vec3()
    }
}

/// A unit f64 vector, or `None` for a zero / non-finite one.
pub(crate) fn unit(v: Vec3) -> Option<DVec3> {
    let d = v.as_dvec3();
    let len = d.length();
    if !len.is_finite() || len < 1e-6 {
        None
    } else {
        Some(d / len)
    }
}

/// Thesis eq. 3.7 by exact quadrature over every pixel of `env` (design.md §3):
/// radiance leaving a point with unit `normal` towards unit `view` (both camera
/// space; `view` points from the surface to the camera). The reference
/// renderer. Builds an [`EnvQuadrature`] per call: to shade many points, build
/// it once.
pub fn shade_exact(env: &EnvMap, normal: Vec3, view: Vec3, material: &PhongMaterial) -> Vec3 {
    EnvQuadrature::new(env).shade(normal, view, material)
}

/// Directional albedo of the specular lobe under uniform unit light:
/// `A(n, μ) = ∫ (n+2)/2π · max(0, ω·R)ⁿ · max(0, ω·N) dω` for a view at
/// `μ = N·V` (R the reflected view), by a quadrature in lobe coordinates: with
/// `t = (ω·R)^(n+1)` the lobe weight becomes uniform in `t`, so a midpoint rule
/// with `nt × nb` points (in `t` and azimuth around R) is accurate for every
/// exponent. `A(n, 1) = 1` exactly (the lobe is normalised); `A ≤ 1`.
pub fn specular_albedo(exponent: f64, mu: f64, nt: usize, nb: usize) -> f64 {
    use std::f64::consts::PI;
    let mu = mu.clamp(0.0, 1.0);
    let n = DVec3::Z;
    let v = DVec3::new((1.0 - mu * mu).sqrt(), 0.0, mu);
    let r = reflect(v, n);
    // Orthonormal frame around R.
    let t1 = if r.x.abs() < 0.9 { DVec3::X } else { DVec3::Y };
    let b1 = r.cross(t1).normalize();
    let b2 = r.cross(b1);
    let mut acc = 0.0;
    for i in 0..nt {
        let t = (i as f64 + 0.5) / nt as f64;
        let cos_a = t.powf(1.0 / (exponent + 1.0));
        let sin_a = (1.0 - cos_a * cos_a).max(0.0).sqrt();
        let mut ring = 0.0;
        for j in 0..nb {
            let b = 2.0 * PI * (j as f64 + 0.5) / nb as f64;
            let w = r * cos_a + (b1 * b.cos() + b2 * b.sin()) * sin_a;
            ring += w.dot(n).max(0.0);
        }
        acc += ring / nb as f64;
    }
    // ∫ (n+2)/2π cosⁿα · g dω = (n+2)/(n+1) · mean over (t, β) of g.
    (exponent + 2.0) / (exponent + 1.0) * acc / nt as f64
}

#[cfg(test)]
mod tests {
    use super::*;
    use picker_tensor::Rng;

    fn random_unit(rng: &mut Rng) -> DVec3 {
        loop {
            let v = DVec3::new(
                rng.f64() * 2.0 - 1.0,
                rng.f64() * 2.0 - 1.0,
                rng.f64() * 2.0 - 1.0,
            );
            let l = v.length();
            if l > 0.1 && l <= 1.0 {
                return v / l;
            }
        }
    }

    #[test]
    fn brdf_is_reciprocal() {
        let mut rng = Rng::new(11);
        for _ in 0..2000 {
            let m = PhongMaterial {
                diffuse: Vec3::new(rng.uniform(0.0, 1.0), 0.3, 0.7),
                specular: Vec3::splat(rng.uniform(0.0, 1.0)),
                exponent: rng.uniform(0.0, 13.0).exp2(),
            };
            let (n, a, b) = (
                random_unit(&mut rng),
                random_unit(&mut rng),
                random_unit(&mut rng),
            );
            let (f, g) = (brdf(&m, a, b, n), brdf(&m, b, a, n));
            assert!(
                (f - g).abs().max_element() <= 1e-9 * (1.0 + f.abs().max_element()),
                "{f} {g}"
            );
        }
    }

    #[test]
    fn lobe_conserves_energy_for_every_exponent() {
        // A(n, 1) is exactly 1 (analytically), A(n, μ) ≤ 1 and decreasing towards grazing.
        let mut n = 1.0;
        while n <= 8192.0 {
            let normal = specular_albedo(n, 1.0, 400, 64);
            assert!((normal - 1.0).abs() < 1e-4, "n={n}: {normal}");
            let mut last = normal;
            for mu in [0.9, 0.7, 0.5, 0.3, 0.1, 0.01] {
                let a = specular_albedo(n, mu, 400, 256);
                assert!(a <= 1.0 + 1e-3 && a > 0.0, "n={n} mu={mu}: {a}");
                assert!(a <= last + 1e-3, "n={n} mu={mu}: {a} > {last}");
                last = a;
            }
            n *= 2.0;
        }
        // Independent check: plain midpoint quadrature over the hemisphere in
        // (θ, φ) for moderate exponents.
        for (n, mu) in [(1.0, 0.8), (10.0, 0.5), (50.0, 0.95), (3.0, 0.2)] {
            let (nth, nph) = (800, 1600);
            let normal = DVec3::Z;
            let v = DVec3::new((1.0f64 - mu * mu).sqrt(), 0.0, mu);
            let mut acc = 0.0;
            for i in 0..nth {
                let th = (i as f64 + 0.5) / nth as f64 * std::f64::consts::FRAC_PI_2;
                for j in 0..nph {
                    let ph = (j as f64 + 0.5) / nph as f64 * 2.0 * std::f64::consts::PI;
                    let w = DVec3::new(th.sin() * ph.cos(), th.sin() * ph.sin(), th.cos());
                    acc += specular_lobe(w, v, normal, n) * th.cos() * th.sin();
                }
            }
            acc *=
                std::f64::consts::FRAC_PI_2 / nth as f64 * 2.0 * std::f64::consts::PI / nph as f64;
            let a = specular_albedo(n, mu, 400, 256);
            assert!((acc - a).abs() < 2e-3, "n={n} mu={mu}: {acc} vs {a}");
        }
    }

    #[test]
    fn zero_normal_is_black() {
        let env = EnvMap::uniform(8, 4, Vec3::ONE);
        let m = PhongMaterial {
            diffuse: Vec3::ONE,
            specular: Vec3::ONE,
            exponent: 10.0,
        };
        assert_eq!(shade_exact(&env, Vec3::ZERO, Vec3::Z, &m), Vec3::ZERO);
        assert_eq!(
            shade_exact(&env, Vec3::splat(f32::NAN), Vec3::Z, &m),
            Vec3::ZERO
        );
    }
}
