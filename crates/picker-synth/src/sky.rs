//! Environment maps for the synthetic scenes: procedural HDR skies and, when the
//! [`AssetLibrary`] has them, real HDRIs.
//!
//! Maps are in the conventions' equirectangular mapping
//! (`picker_nets::conventions::envmap_direction`: row 0 straight up, centre column straight
//! ahead = −z), linear radiance.
//!
//! **Procedural sky** ([`procedural_sky`]): a zenith-to-horizon gradient (clear: blue zenith,
//! paler horizon; 30 % overcast: grey, CIE-overcast-like `(1 + 2 sin el)/3` falloff, no sun),
//! fBm clouds on a plane above the camera (so they shrink towards the horizon, faded out near
//! it), a sun disc of radiance 50–1000 (log-uniform; warmer when low) with a soft glow, and a
//! ground hemisphere whose radiance is its albedo lit by the sky and the sun,
//! `L = ρ/π · (π·L_sky,mean + L_sun·Ω_sun·sin el)`, with fBm variation. The sun's angular
//! radius is 0.5°–4° but at least 0.75 pixel rows, so that it is resolved at the map's size;
//! pixels near the sun are supersampled 4×4 so the sun's power does not depend on where its
//! centre falls. Sky brightness (zenith) is 0.3–3 units (log-uniform).
//!
//! **HDRI** ([`hdri_sky`]): with probability [`HDRI_PROBABILITY`] when the library has HDRIs,
//! one is read (`picker_render::EnvMap::read`), resampled area-correctly to the size, turned
//! by a random yaw and scaled so that its level — the geometric mean of its median and mean
//! Rec. 709 luminance, so the background counts but a sun or lamp neither sets the exposure
//! alone nor is ignored (the mean alone where more than half the map is black) — is a random
//! 0.2–2 units (log-uniform), which keeps real and procedural skies comparable with the room
//! lamps. A sun in an HDRI may then exceed the range and be clamped (recorded). Decoded and
//! resampled HDRIs are cached in the [`AssetLibrary`].
//!
//! **Range.** Every map is clamped to `[0, ENVMAP_MAX_RADIANCE]` (1000, the largest radiance
//! the conventions' log encoding decodes); [`SkyInfo`] records the maximum and how many pixel
//! channels were clamped.

use std::f32::consts::{FRAC_PI_2, PI, TAU};

use glam::Vec3;
use picker_nets::conventions::{envmap_direction, ENVMAP_MAX_RADIANCE};
use picker_render::EnvMap;
use picker_tensor::Rng;
use serde::{Deserialize, Serialize};

use crate::assets::{Asset, AssetError, AssetLibrary};
use crate::textures::{hsv_to_linear, Fbm, Rgb};

/// Probability that [`random_sky`] uses a real HDRI when the library has some.
pub const HDRI_PROBABILITY: f64 = 0.5;

/// Probability of an overcast procedural sky (no sun).
pub const OVERCAST_PROBABILITY: f64 = 0.3;

/// The sun of a procedural sky.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Sun {
    /// Unit direction towards the sun (camera space of the map).
    pub direction: [f32; 3],
    /// Elevation above the horizon, radians.
    pub elevation: f32,
    /// Azimuth, radians: 0 straight ahead (−z), π/2 right (+x).
    pub azimuth: f32,
    /// Angular radius of the disc, radians.
    pub angular_radius: f32,
    /// Radiance of the disc (linear RGB).
    pub radiance: Rgb,
}

/// The parameters of a procedural sky.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ProceduralSky {
    /// Overcast (no sun, grey sky, full clouds).
    pub overcast: bool,
    /// Radiance straight up (without clouds).
    pub zenith: Rgb,
    /// Radiance at the horizon.
    pub horizon: Rgb,
    /// Cloud cover in `[0, 1]`.
    pub cloud_cover: f32,
    /// Ground albedo.
    pub ground_albedo: Rgb,
    /// Ground radiance (mean, before variation).
    pub ground: Rgb,
    /// The sun, if any.
    pub sun: Option<Sun>,
}

/// Where an environment map came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SkyKind {
    /// [`procedural_sky`].
    Procedural,
    /// A real HDRI ([`hdri_sky`]).
    Hdri,
}

/// What a sky is (recorded in `scene.json`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SkyInfo {
    /// Procedural or HDRI.
    pub kind: SkyKind,
    /// Width and height of the map.
    pub size: [usize; 2],
    /// Procedural parameters.
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub procedural: Option<ProceduralSky>,
    /// The HDRI file.
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub source: Option<String>,
    /// The HDRI's licence file, if the library has one.
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub licence: Option<String>,
    /// Yaw the HDRI was turned by (radians, `EnvMap::rotated_yaw`); 0 for procedural skies.
    pub yaw: f32,
    /// Factor the HDRI's radiance was multiplied by; 1 for procedural skies.
    pub scale: f32,
    /// Largest radiance in the map after clamping.
    pub max_radiance: f32,
    /// Pixel channels clamped to [`ENVMAP_MAX_RADIANCE`].
    pub clamped: usize,
}

/// A random `width × height` environment map: a real HDRI with probability
/// [`HDRI_PROBABILITY`] when `assets` has HDRIs, else a procedural sky. Errors only when an
/// HDRI cannot be read (the error names the file).
pub fn random_sky(
    rng: &mut Rng,
    width: usize,
    height: usize,
    assets: Option<&AssetLibrary>,
) -> Result<(EnvMap, SkyInfo), AssetError> {
    let (width, height) = (width.max(1), height.max(1));
    if let Some(lib) = assets.filter(|a| !a.hdris.is_empty()) {
        if rng.f64() < HDRI_PROBABILITY {
            let asset = &lib.hdris[rng.range(0, lib.hdris.len() - 1)];
            return hdri_sky(rng, width, height, lib, asset);
        }
    }
    Ok(procedural_sky(rng, width, height))
}

fn log_uniform(rng: &mut Rng, lo: f32, hi: f32) -> f32 {
    (rng.uniform(lo.ln(), hi.ln())).exp()
}

fn luminance(c: Vec3) -> f32 {
    c.dot(Vec3::new(0.2126, 0.7152, 0.0722))
}

/// Clamps to `[0, ENVMAP_MAX_RADIANCE]` (NaN → 0); returns the number of clamped channels
/// and the maximum.
fn clamp_radiance(data: &mut [Vec3]) -> (usize, f32) {
    let mut clamped = 0;
    let mut max = 0.0f32;
    for c in data.iter_mut() {
        for k in 0..3 {
            let v = c[k];
            let v = if v.is_nan() || v < 0.0 {
                0.0
            } else if v > ENVMAP_MAX_RADIANCE {
                clamped += 1;
                ENVMAP_MAX_RADIANCE
            } else {
                v
            };
            c[k] = v;
            max = max.max(v);
        }
    }
    (clamped, max)
}

/// A real HDRI from `asset`, resampled to `width × height`, turned by a random yaw and scaled
/// to a random background level (see the module docs).
pub fn hdri_sky(
    rng: &mut Rng,
    width: usize,
    height: usize,
    lib: &AssetLibrary,
    asset: &Asset,
) -> Result<(EnvMap, SkyInfo), AssetError> {
    let load_err = |e: picker_render::Error| AssetError::Load {
        path: asset.path.clone(),
        reason: e.to_string(),
    };
    let yaw = rng.uniform(0.0, TAU);
    let target_level = log_uniform(rng, 0.2, 2.0);
    let map = lib.hdri(asset, width, height)?.rotated_yaw(yaw);
    // The level is the geometric mean of the median and the mean luminance: the background
    // counts, but a sun or lamp in the map neither sets the exposure alone nor is ignored.
    let mut lum: Vec<f32> = map.data().iter().map(|&c| luminance(c)).collect();
    lum.sort_by(f32::total_cmp);
    let median = lum[lum.len() / 2];
    let mean = luminance(map.mean());
    let level = if median > 0.0 {
        (median * mean).sqrt()
    } else {
        mean
    };
    if !level.is_finite() || level <= 0.0 {
        return Err(AssetError::Load {
            path: asset.path.clone(),
            reason: format!("HDRI has no usable radiance (level {level})"),
        });
    }
    let scale = target_level / level;
    let mut data: Vec<Vec3> = map.data().iter().map(|&c| c * scale).collect();
    let (clamped, max_radiance) = clamp_radiance(&mut data);
    let env = EnvMap::new(width, height, data).map_err(load_err)?;
    let path_str = |p: &std::path::Path| p.to_string_lossy().into_owned();
    Ok((
        env,
        SkyInfo {
            kind: SkyKind::Hdri,
            size: [width, height],
            procedural: None,
            source: Some(path_str(&asset.path)),
            licence: asset.licence.as_deref().map(path_str),
            yaw,
            scale,
            max_radiance,
            clamped,
        },
    ))
}

/// Unit direction of elevation `el` and azimuth `az` (0 = −z, π/2 = +x).
fn direction(el: f32, az: f32) -> Vec3 {
    Vec3::new(el.cos() * az.sin(), el.sin(), -el.cos() * az.cos())
}

/// A procedural sky (see the module docs).
pub fn procedural_sky(rng: &mut Rng, width: usize, height: usize) -> (EnvMap, SkyInfo) {
    let (width, height) = (width.max(1), height.max(1));
    let overcast = rng.f64() < OVERCAST_PROBABILITY;
    let brightness = log_uniform(rng, 0.3, 3.0);
    let (zenith, horizon) = if overcast {
        let grey = hsv_to_linear(rng.uniform(0.0, 1.0), rng.uniform(0.0, 0.08), 1.0);
        (
            grey * brightness,
            grey * brightness * rng.uniform(0.35, 0.6),
        )
    } else {
        let z = hsv_to_linear(rng.uniform(0.55, 0.65), rng.uniform(0.35, 0.85), 1.0);
        let h = hsv_to_linear(rng.uniform(0.5, 0.65), rng.uniform(0.0, 0.3), 1.0);
        (z * brightness, h * brightness * rng.uniform(1.0, 2.0))
    };
    let cloud_cover = if overcast {
        rng.uniform(0.7, 1.0)
    } else {
        rng.uniform(0.0, 0.7)
    };
    let cloud_scale = rng.uniform(0.3, 1.5);
    let clouds = Fbm::new(rng, 4, 4, 5, 0.55);
    let cloud_color = Vec3::splat(rng.uniform(0.6, 1.2))
        * if overcast {
            brightness * rng.uniform(0.7, 1.1)
        } else {
            brightness * rng.uniform(0.8, 1.6)
        };
    let ground_albedo = hsv_to_linear(
        rng.uniform(0.05, 0.35),
        rng.uniform(0.0, 0.6),
        rng.uniform(0.2, 0.7),
    );
    let ground_noise = Fbm::new(rng, 8, 8, 3, 0.5);
    let sun = (!overcast).then(|| {
        let elevation = rng.uniform(2.0, 80.0).to_radians();
        let azimuth = rng.uniform(-PI, PI);
        let pixel = PI / height as f32;
        let angular_radius = rng.uniform(0.5, 4.0).to_radians().max(0.75 * pixel);
        let strength = log_uniform(rng, 50.0, 1000.0);
        // Warmer and dimmer towards the horizon.
        let warm = (1.0 - elevation / 0.35).clamp(0.0, 1.0);
        let tint = Vec3::ONE.lerp(Vec3::new(1.0, 0.55, 0.25), warm);
        let radiance = tint * strength;
        Sun {
            direction: direction(elevation, azimuth).to_array(),
            elevation,
            azimuth,
            angular_radius,
            radiance: radiance.to_array(),
        }
    });
    let glow = rng.uniform(0.5, 3.0);
    // Ground: albedo lit by the sky (≈ π × mean sky radiance) and the sun.
    let sky_mean = (zenith + horizon) * 0.5;
    let mut irradiance = PI * sky_mean;
    if let Some(s) = &sun {
        let omega = TAU * (1.0 - s.angular_radius.cos());
        irradiance += Vec3::from(s.radiance) * omega * s.elevation.sin();
    }
    let ground = ground_albedo * irradiance / PI;

    let sky_at = |d: Vec3| -> Vec3 {
        if d.y < 0.0 {
            // Ground, with a short haze band just below the horizon.
            let (u, v) = (0.5 + d.x.atan2(-d.z) / TAU, (-d.y).acos() / PI);
            let n = 1.0 + 0.25 * ground_noise.eval(u, v);
            let haze = (1.0 + d.y / 0.05).clamp(0.0, 1.0);
            return (ground * n).lerp(horizon, haze * 0.7);
        }
        let el = d.y.clamp(0.0, 1.0).asin();
        let mut c = if overcast {
            zenith * ((1.0 + 2.0 * d.y) / 3.0) + horizon * (1.0 - d.y) * 0.3
        } else {
            let t = (1.0 - el / FRAC_PI_2).powf(3.0);
            zenith.lerp(horizon, t)
        };
        if let Some(s) = &sun {
            let cosang = d.dot(Vec3::from(s.direction)).clamp(-1.0, 1.0);
            let ang = cosang.acos();
            c += Vec3::from(s.radiance) * 0.002 * glow * (-ang / 0.15).exp();
            c += horizon * glow * 0.3 * (-ang / 0.6).exp();
        }
        // Clouds on a plane above the camera.
        if cloud_cover > 0.0 && d.y > 0.01 {
            let p = Vec3::new(d.x, 0.0, d.z) / d.y * (0.1 * cloud_scale);
            let n = 0.5 + 0.5 * clouds.eval(p.x.rem_euclid(1.0), p.z.rem_euclid(1.0));
            let cover = cloud_cover;
            let a = ((n - (1.0 - cover)) / 0.25).clamp(0.0, 1.0);
            let fade = ((d.y - 0.01) / 0.15).clamp(0.0, 1.0);
            let shade = 0.75 + 0.5 * n;
            c = c.lerp(cloud_color * shade, a * fade);
        }
        c
    };

    let (h, w) = (height, width);
    let mut data = Vec::with_capacity(w * h);
    // A pixel's points are within its angular diagonal of its centre.
    let pixel_diag = ((PI / h as f32).powi(2) + (TAU / w as f32).powi(2)).sqrt();
    for row in 0..h {
        for col in 0..w {
            let d = envmap_direction(col as f64 + 0.5, row as f64 + 0.5, h, w);
            let d = Vec3::new(d[0] as f32, d[1] as f32, d[2] as f32);
            let mut c = sky_at(d);
            if let Some(s) = &sun {
                let sd = Vec3::from(s.direction);
                // Pixels near the sun: the covered fraction by 4×4 supersampling.
                if d.dot(sd).clamp(-1.0, 1.0).acos() < s.angular_radius + pixel_diag {
                    let mut hits = 0;
                    for b in 0..4 {
                        for a in 0..4 {
                            let e = envmap_direction(
                                col as f64 + (a as f64 + 0.5) / 4.0,
                                row as f64 + (b as f64 + 0.5) / 4.0,
                                h,
                                w,
                            );
                            let e = Vec3::new(e[0] as f32, e[1] as f32, e[2] as f32);
                            if e.dot(sd).clamp(-1.0, 1.0).acos() < s.angular_radius {
                                hits += 1;
                            }
                        }
                    }
                    c += Vec3::from(s.radiance) * (hits as f32 / 16.0);
                }
            }
            data.push(c);
        }
    }
    let (clamped, max_radiance) = clamp_radiance(&mut data);
    let env = EnvMap::new(w, h, data).expect("sizes are at least 1 and the length matches");
    let info = SkyInfo {
        kind: SkyKind::Procedural,
        size: [w, h],
        procedural: Some(ProceduralSky {
            overcast,
            zenith: zenith.to_array(),
            horizon: horizon.to_array(),
            cloud_cover,
            ground_albedo: ground_albedo.to_array(),
            ground: ground.to_array(),
            sun,
        }),
        source: None,
        licence: None,
        yaw: 0.0,
        scale: 1.0,
        max_radiance,
        clamped,
    };
    (env, info)
}

#[cfg(test)]
mod tests {
    use super::*;
    use picker_nets::conventions::pixel_solid_angle;

    fn sky(seed: u64, w: usize, h: usize) -> (EnvMap, SkyInfo) {
        random_sky(&mut Rng::new(seed), w, h, None).expect("procedural")
    }

    #[test]
    fn same_seed_same_sky() {
        let (a, ia) = sky(5, 64, 32);
        let (b, ib) = sky(5, 64, 32);
        assert_eq!(a, b);
        assert_eq!(ia, ib);
        assert_ne!(a, sky(6, 64, 32).0);
        serde_json::to_string(&ia).expect("info serialises");
    }

    #[test]
    fn radiance_is_finite_and_within_the_decodable_range() {
        for seed in 0..24 {
            let (env, info) = sky(seed, 64, 32);
            assert_eq!(info.kind, SkyKind::Procedural);
            assert_eq!((env.width(), env.height()), (64, 32));
            for c in env.data() {
                assert!(c.is_finite() && c.min_element() >= 0.0, "seed {seed}: {c}");
                assert!(c.max_element() <= ENVMAP_MAX_RADIANCE, "seed {seed}: {c}");
            }
            // Nothing is pitch black: the sky and the ground light the room.
            assert!(
                luminance(env.mean()) > 0.05,
                "seed {seed}: mean {}",
                env.mean()
            );
        }
    }

    #[test]
    fn the_sun_is_the_brightest_region_and_keeps_its_power() {
        let mut suns = 0;
        for seed in 0..24 {
            for (w, h) in [(64, 32), (256, 128)] {
                let (env, info) = sky(seed, w, h);
                let p = info.procedural.as_ref().unwrap();
                let Some(sun) = &p.sun else {
                    assert!(p.overcast);
                    assert!(
                        info.max_radiance < 50.0,
                        "overcast max {}",
                        info.max_radiance
                    );
                    continue;
                };
                suns += 1;
                let (mut best, mut best_l) = ((0, 0), -1.0);
                for row in 0..h {
                    for col in 0..w {
                        let l = luminance(env.get(row, col));
                        if l > best_l {
                            (best, best_l) = ((row, col), l);
                        }
                    }
                }
                let d = env.direction(best.0, best.1);
                let pixel = ((PI / h as f32).powi(2) + (TAU / w as f32).powi(2)).sqrt();
                let ang = d.dot(Vec3::from(sun.direction)).clamp(-1.0, 1.0).acos();
                assert!(
                    ang <= sun.angular_radius + pixel,
                    "seed {seed} {w}x{h}: brightest pixel {ang} rad from the sun"
                );
                // The sun's power Σ L·ΔΩ over the disc's pixels is about L_sun·Ω_sun.
                let sd = Vec3::from(sun.direction);
                let mut power = 0.0f64;
                for row in 0..h {
                    for col in 0..w {
                        let d = env.direction(row, col);
                        if d.dot(sd).clamp(-1.0, 1.0).acos() <= sun.angular_radius + pixel {
                            power +=
                                luminance(env.get(row, col)) as f64 * pixel_solid_angle(row, h, w);
                        }
                    }
                }
                let omega = TAU * (1.0 - sun.angular_radius.cos());
                let expected = luminance(Vec3::from(sun.radiance)).min(ENVMAP_MAX_RADIANCE) * omega;
                let ratio = power as f32 / expected;
                assert!(
                    (0.8..1.6).contains(&ratio),
                    "seed {seed} {w}x{h}: sun power ratio {ratio}"
                );
            }
        }
        assert!(suns > 10, "only {suns} sunny skies");
    }

    #[test]
    fn ground_is_below_the_horizon_and_darker_than_the_sun() {
        let (env, info) = sky(2, 64, 32);
        let p = info.procedural.unwrap();
        let g = Vec3::from(p.ground);
        let bottom = env.get(31, 10);
        assert!(
            (bottom - g).abs().max_element() <= 0.3 * g.max_element() + 1e-6,
            "{bottom} vs {g}"
        );
        assert!(info.max_radiance > bottom.max_element());
    }

    #[test]
    fn hdri_errors_name_the_file() {
        let dir = std::env::temp_dir().join(format!("picker-synth-hdri-{}", std::process::id()));
        std::fs::create_dir_all(dir.join("hdri/x")).unwrap();
        std::fs::write(dir.join("hdri/x/bad.exr"), b"not an exr").unwrap();
        let lib = AssetLibrary::scan(&dir).unwrap();
        let mut failed = false;
        for seed in 0..8 {
            if let Err(e) = random_sky(&mut Rng::new(seed), 16, 8, Some(&lib)) {
                assert!(e.to_string().contains("bad.exr"), "{e}");
                failed = true;
            }
        }
        assert!(failed, "an HDRI was never chosen in 8 tries");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn hdri_is_resampled_rotated_scaled_and_clamped() {
        let dir = std::env::temp_dir().join(format!("picker-synth-hdri2-{}", std::process::id()));
        std::fs::create_dir_all(dir.join("hdri/x")).unwrap();
        // A 64×32 map with a very bright spot straight ahead.
        let mut data = vec![Vec3::splat(0.5); 64 * 32];
        data[16 * 64 + 32] = Vec3::splat(1e6);
        let src = EnvMap::new(64, 32, data).unwrap();
        src.write_exr(&dir.join("hdri/x/spot.exr")).unwrap();
        std::fs::write(dir.join("hdri/x/LICENSE"), b"CC0").unwrap();
        let lib = AssetLibrary::scan(&dir).unwrap();
        let (env, info) = hdri_sky(&mut Rng::new(4), 32, 16, &lib, &lib.hdris[0]).unwrap();
        assert_eq!(info.kind, SkyKind::Hdri);
        assert_eq!((env.width(), env.height()), (32, 16));
        assert!(info.licence.unwrap().ends_with("LICENSE"));
        assert!(info.max_radiance <= ENVMAP_MAX_RADIANCE);
        assert!(env
            .data()
            .iter()
            .all(|c| c.is_finite() && c.min_element() >= 0.0));
        assert!(info.clamped > 0 && info.scale > 0.0);
        // The spot (straight ahead in the file) is where the yaw turned it.
        let (mut best, mut best_l) = (Vec3::ZERO, -1.0);
        for row in 0..16 {
            for col in 0..32 {
                if luminance(env.get(row, col)) > best_l {
                    (best, best_l) = (env.direction(row, col), luminance(env.get(row, col)));
                }
            }
        }
        let expected = glam::Mat3::from_rotation_y(info.yaw) * Vec3::NEG_Z;
        assert!(best.angle_between(expected) < 0.3, "{best} vs {expected}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// `cargo test --release -p picker-synth --lib -- --ignored --nocapture sky_timing`
    #[test]
    #[ignore = "timing; run in release"]
    fn sky_timing() {
        for (w, h) in [(128, 64), (256, 128)] {
            let n = 20;
            let start = std::time::Instant::now();
            for seed in 0..n {
                sky(seed, w, h);
            }
            let ms = start.elapsed().as_secs_f64() * 1e3 / n as f64;
            eprintln!("procedural sky {w}x{h}: {ms:.2} ms");
        }
    }
}
