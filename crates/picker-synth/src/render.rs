//! Rendering a [`Scene`] into its image and ground-truth render elements.
//!
//! One ray per pixel through the pixel centre: every element is the value of the
//! surface point seen at the centre, except that a textured ρd is the texture
//! averaged over 4 rotated-grid sub-pixel positions on that same surface (a box
//! filter against moiré; `uv` stays the centre's). Geometry edges are not
//! anti-aliased. The image is
//!
//! `L = V·E + Σ_lamps S + A`, all in linear RGB, then multiplied by the exposure:
//!
//! - `E`, the **env-map Phong term** (thesis eq. 3.7): the camera-frame environment
//!   map at 1/8 of the image size (the one written as `envmap.exr`) shading the
//!   pixel's camera-space normal, view vector and material with picker-render's
//!   [`PrefilteredEnv::resolving`] fast path, which reads the map as the
//!   continuous function its bilinear sampling makes of it: summed over the
//!   map's own pixel centres, a glossy lobe narrower than them (exponents
//!   above about (rows/5)², 36 for the 30-row map of a 240×320 image; half of
//!   the materials are glossier) showed the map's pixels on every glossy wall
//!   as a grid of bright dots, which no camera sees. Written alone as
//!   `direct_env.exr`, so `picker_render::rerender` of the written elements
//!   and env map with `Quality::Continuous` reproduces it.
//! - `V ∈ [0, 1]`, **sky visibility**: the env map lights the room only through its
//!   openings, so `E` is scaled by the cosine-weighted fraction of the hemisphere
//!   above the point that the openings cover (their point-to-polygon form factors,
//!   each clipped to the hemisphere, Lambert's formula) times the fraction of 2
//!   stratified shadow rays to each opening that no furniture blocks.
//! - `S`, **ceiling lamps**: small spherical lights, Phong BRDF, `I·cos θ/d²`, soft
//!   shadows from 4 shadow rays to points on the lamp's disc.
//! - `A`, **ambient / indirect**: `ρd/π · Φ/A_room`, the average irradiance of an
//!   integrating-sphere room with mean reflectance ½ (Φ: flux of the lamps plus the
//!   daylight through the openings, `A_room`: the shell's area), so nothing is black.
//!
//! Pixels that see the sky through an opening show the world-frame sky itself;
//! their elements are "no surface": albedos, glossiness, uv, depth and segmentation
//! 0, material id 0, normal = view vector = the direction towards the camera.
//!
//! **Exposure**: a factor `k` makes the log-average luminance of the image 0.18;
//! `image`, `direct_env` and `envmap` are all multiplied by it (recorded in
//! `scene.json`), so the written env map and elements still re-render `direct_env`.
//! Jitter of the shadow rays comes from a hash of the pixel, not from an RNG
//! stream, so the result does not depend on evaluation order.

use glam::Vec3;
use picker_render::{EnvMap, PhongMaterial, PrefilteredEnv};

use crate::geometry::nearest;
use crate::scene::{Diffuse, Scene};

/// Target log-average luminance of the exposed image.
pub const EXPOSURE_KEY: f32 = 0.18;
/// Shadow rays per lamp.
pub const SHADOW_RAYS: u32 = 4;
/// Shadow rays per opening.
pub const OPENING_RAYS: u32 = 2;
/// Sub-pixel offsets (rotated grid) at which textures are averaged into ρd.
const SUBPIXELS: [(f32, f32); 4] = [
    (0.125, -0.375),
    (0.375, 0.125),
    (-0.125, 0.375),
    (-0.375, -0.125),
];
/// Offset of shadow-ray origins along the normal (metres).
const EPS: f32 = 1e-3;

/// Everything rendered for one scene, `h × w` pixels, row-major, exposure applied
/// where radiance is concerned.
pub struct Buffers {
    /// Height.
    pub height: usize,
    /// Width.
    pub width: usize,
    /// The image, linear RGB.
    pub image: Vec<Vec3>,
    /// The env-map Phong term alone ([`picker_render::rerender`] of the elements).
    pub direct_env: Vec<Vec3>,
    /// ρd, linear.
    pub diffuse: Vec<Vec3>,
    /// ρs, linear.
    pub specular: Vec<Vec3>,
    /// g ∈ [0, 1].
    pub glossiness: Vec<f32>,
    /// Unit camera-space normals, facing the camera.
    pub normals: Vec<Vec3>,
    /// Unit camera-space vectors towards the camera.
    pub view: Vec<Vec3>,
    /// (u, v, t).
    pub uv: Vec<Vec3>,
    /// Distance along −z (metres), 0 for the sky.
    pub depth: Vec<f32>,
    /// Material ids (0: the sky).
    pub material_id: Vec<u16>,
    /// (ρd* + ρs)/2 of the pixel's material.
    pub segmentation: Vec<Vec3>,
    /// Sky visibility `V` (before exposure; diagnostics).
    pub visibility: Vec<f32>,
    /// The camera-frame environment map at 1/8 size, exposure applied.
    pub envmap: EnvMap,
    /// The exposure factor applied.
    pub exposure: f32,
}

/// Whether furniture blocks the segment from `o` along unit `d` up to `dist`.
#[inline]
fn blocked(scene: &Scene, o: Vec3, d: Vec3, dist: f32) -> bool {
    let inv = d.recip();
    scene.occluder_groups.iter().any(|(bb, r)| {
        bb.hit_by(o, inv, 0.0, dist)
            && scene.occluders[r.clone()]
                .iter()
                .any(|s| s.blocks(o, d, inv, 0.0, dist))
    })
}

/// A hash of three integers to `[0, 1)`.
#[inline]
fn hash01(a: u32, b: u32, c: u32) -> f32 {
    let mut x = (a as u64) << 40 ^ (b as u64) << 20 ^ c as u64;
    x = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
    x = (x ^ (x >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    x ^= x >> 31;
    (x >> 40) as f32 / (1u64 << 24) as f32
}

/// Cosine-weighted form factor from a point `p` with unit normal `n` to the polygon
/// `poly` (world), clipped to the hemisphere above `p` (Lambert's formula).
pub fn form_factor(p: Vec3, n: Vec3, poly: &[Vec3; 4]) -> f32 {
    // Clip against the plane n·(q − p) ≥ 0 (Sutherland–Hodgman).
    let mut pts = [Vec3::ZERO; 8];
    let mut m = 0;
    for i in 0..4 {
        let a = poly[i] - p;
        let b = poly[(i + 1) % 4] - p;
        let (da, db) = (n.dot(a), n.dot(b));
        if da >= 0.0 {
            pts[m] = a;
            m += 1;
        }
        if (da >= 0.0) != (db >= 0.0) {
            pts[m] = a + (b - a) * (da / (da - db));
            m += 1;
        }
    }
    if m < 3 {
        return 0.0;
    }
    let mut sum = 0.0f32;
    for i in 0..m {
        let a = pts[i].normalize_or_zero();
        let b = pts[(i + 1) % m].normalize_or_zero();
        let c = a.cross(b);
        let len = c.length();
        if len > 1e-9 {
            sum += a.dot(b).clamp(-1.0, 1.0).acos() * n.dot(c / len);
        }
    }
    (sum.abs() / std::f32::consts::TAU).min(1.0)
}

/// The Phong BRDF times π-free lobe: `ρd/π + ρs(n+2)/2π · max(0, V·R)^n` with `R = 2(ω·N)N − ω`.
#[inline]
fn phong(m: &PhongMaterial, wi: Vec3, view: Vec3, normal: Vec3) -> Vec3 {
    let r = 2.0 * wi.dot(normal) * normal - wi;
    let c = view.dot(r).max(0.0);
    let spec = if c > 0.0 {
        (m.exponent + 2.0) / std::f32::consts::TAU * c.powf(m.exponent)
    } else {
        0.0
    };
    m.diffuse * std::f32::consts::FRAC_1_PI + m.specular * spec
}

/// Renders `scene` at its configured size.
pub fn render(scene: &Scene) -> Buffers {
    let (h, w) = (scene.config.height, scene.config.width);
    let cam = &scene.camera;
    let rot = cam.rotation;
    let rot_t = rot.transpose();

    // The camera-frame env map at 1/8 size: out.sample(Rᵀ·d_world) = sky.sample(d_world).
    let env_cam = scene
        .sky
        .rotated(rot_t)
        .resample((w / 8).max(1), (h / 8).max(1))
        .expect("non-zero sizes");
    let pre = PrefilteredEnv::resolving(&env_cam);

    // Ambient: integrating-sphere average irradiance Φ/A (mean reflectance ½).
    let r = scene.room;
    let area = 2.0 * (r.x * r.z + r.x * r.y + r.z * r.y);
    let sky_up = crate::scene::upper_mean_radiance(&scene.sky);
    let mut flux = Vec3::ZERO;
    for o in &scene.openings {
        flux += o.area() * std::f32::consts::PI * sky_up;
    }
    for l in &scene.lamps {
        flux += 4.0 * std::f32::consts::PI * l.intensity;
    }
    let ambient = flux / area * std::f32::consts::FRAC_1_PI;

    let n = h * w;
    let mut b = Buffers {
        height: h,
        width: w,
        image: vec![Vec3::ZERO; n],
        direct_env: vec![Vec3::ZERO; n],
        diffuse: vec![Vec3::ZERO; n],
        specular: vec![Vec3::ZERO; n],
        glossiness: vec![0.0; n],
        normals: vec![Vec3::Z; n],
        view: vec![Vec3::Z; n],
        uv: vec![Vec3::ZERO; n],
        depth: vec![0.0; n],
        material_id: vec![0; n],
        segmentation: vec![Vec3::ZERO; n],
        visibility: vec![0.0; n],
        envmap: env_cam,
        exposure: 1.0,
    };
    let seg: Vec<Vec3> = scene.materials.iter().map(|m| m.segmentation()).collect();

    for row in 0..h {
        for col in 0..w {
            let i = row * w + col;
            let d_cam = cam.pixel_direction(row, col, h, w);
            let d = rot * d_cam;
            let view_cam = -d_cam;
            b.normals[i] = view_cam;
            b.view[i] = view_cam;
            let Some((k, hit)) = nearest(&scene.shapes, cam.position, d, 0.0, f32::INFINITY) else {
                b.image[i] = scene.sky.sample(d);
                continue;
            };
            let prim = &scene.primitives[k];
            let mat = &scene.materials[prim.material];
            let p = cam.position + hit.t * d;
            let nw = if hit.normal.dot(d) > 0.0 {
                -hit.normal
            } else {
                hit.normal
            };
            let n_cam = (rot_t * nw).normalize();
            let (rho_d, uvt) = match &mat.diffuse {
                Diffuse::Texture(t, _) => {
                    let uv = mat.uv(hit.coords, hit.period);
                    let (u, v) = (
                        picker_nets::conventions::wrap_unit(uv.x),
                        picker_nets::conventions::wrap_unit(uv.y),
                    );
                    // ρd: the texture averaged over 4 rotated-grid sub-pixel positions
                    // on the same surface (a box filter against moiré).
                    let centre = t.sample(u, v);
                    let mut sum = Vec3::ZERO;
                    for (dx, dy) in SUBPIXELS {
                        let ds = rot
                            * cam.image_direction(
                                col as f32 + 0.5 + dx,
                                row as f32 + 0.5 + dy,
                                h,
                                w,
                            );
                        sum += match prim.shape.intersect(cam.position, ds, 0.0, f32::INFINITY) {
                            Some(hs) => {
                                let uvs = mat.uv(hs.coords, hs.period);
                                t.sample(uvs.x, uvs.y)
                            }
                            None => centre,
                        };
                    }
                    (sum / SUBPIXELS.len() as f32, Vec3::new(u, v, 1.0))
                }
                Diffuse::Colour(c) => (*c, Vec3::ZERO),
            };
            let pm = PhongMaterial::from_glossiness(rho_d, mat.specular, mat.glossiness);
            let env = pre.shade(n_cam, view_cam, &pm);

            // Sky visibility through the openings.
            let origin = p + nw * EPS;
            let mut vis = 0.0;
            for (oi, o) in scene.openings.iter().enumerate() {
                let ff = form_factor(p, nw, &o.corners);
                if ff <= 0.0 {
                    continue;
                }
                let mut free = 0;
                for s in 0..OPENING_RAYS {
                    let su = (s as f32 + hash01(i as u32, oi as u32, 2 * s)) / OPENING_RAYS as f32;
                    let sv = hash01(i as u32, oi as u32, 2 * s + 1);
                    let q = o.point(su, sv);
                    let to = q - origin;
                    let dist = to.length();
                    if !blocked(scene, origin, to / dist, dist) {
                        free += 1;
                    }
                }
                vis += ff * free as f32 / OPENING_RAYS as f32;
            }
            let vis = vis.min(1.0);

            // Lamps.
            let mut lamps = Vec3::ZERO;
            for (li, l) in scene.lamps.iter().enumerate() {
                let to = l.position - p;
                let dist2 = to.length_squared();
                let wi = to / dist2.sqrt();
                let cos = wi.dot(nw);
                if cos <= 0.0 {
                    continue;
                }
                let e1 = wi.any_orthonormal_vector();
                let e2 = wi.cross(e1);
                let mut free = 0;
                for s in 0..SHADOW_RAYS {
                    let a = (s as f32 + hash01(i as u32, 100 + li as u32, s)) / SHADOW_RAYS as f32
                        * std::f32::consts::TAU;
                    let rr = l.radius * hash01(i as u32, 200 + li as u32, s).sqrt();
                    let q = l.position + rr * (a.cos() * e1 + a.sin() * e2);
                    let tq = q - origin;
                    let dq = tq.length();
                    if !blocked(scene, origin, tq / dq, dq) {
                        free += 1;
                    }
                }
                if free > 0 {
                    let f = phong(&pm, wi, -d, nw);
                    lamps += f * l.intensity * (cos / dist2 * free as f32 / SHADOW_RAYS as f32);
                }
            }

            b.image[i] = env * vis + lamps + rho_d * ambient;
            b.direct_env[i] = env;
            b.visibility[i] = vis;
            b.diffuse[i] = rho_d;
            b.specular[i] = mat.specular;
            b.glossiness[i] = mat.glossiness;
            b.normals[i] = n_cam;
            b.uv[i] = uvt;
            b.depth[i] = hit.t * d_cam.z.abs();
            b.material_id[i] = mat.id;
            b.segmentation[i] = seg[prim.material];
        }
    }

    // Exposure: log-average luminance → EXPOSURE_KEY.
    let mut log_sum = 0.0f64;
    for c in &b.image {
        let y = c.dot(Vec3::new(0.2126, 0.7152, 0.0722)).max(0.0);
        log_sum += (1e-4 + y as f64).ln();
    }
    let log_avg = (log_sum / n.max(1) as f64).exp() as f32;
    let k = EXPOSURE_KEY / log_avg.max(1e-6);
    b.exposure = k;
    b.image.iter_mut().for_each(|c| *c *= k);
    b.direct_env.iter_mut().for_each(|c| *c *= k);
    b.envmap.data_mut().iter_mut().for_each(|c| *c *= k);
    b
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square(y: f32, half: f32) -> [Vec3; 4] {
        [
            Vec3::new(-half, y, -half),
            Vec3::new(half, y, -half),
            Vec3::new(half, y, half),
            Vec3::new(-half, y, half),
        ]
    }

    #[test]
    fn form_factors() {
        let (p, n) = (Vec3::ZERO, Vec3::Y);
        // An infinite plane above covers the whole hemisphere.
        assert!((form_factor(p, n, &square(1.0, 1e4)) - 1.0).abs() < 1e-3);
        // A small square straight above: A/(π d²).
        let f = form_factor(p, n, &square(10.0, 0.05));
        let want = 0.01 / (std::f32::consts::PI * 100.0);
        assert!((f / want - 1.0).abs() < 1e-2, "{f} vs {want}");
        // Below the horizon: nothing; half below: clipped to the upper half.
        assert_eq!(form_factor(p, n, &square(-1.0, 1.0)), 0.0);
        let wall = [
            Vec3::new(-1e4, -1e4, -1.0),
            Vec3::new(1e4, -1e4, -1.0),
            Vec3::new(1e4, 1e4, -1.0),
            Vec3::new(-1e4, 1e4, -1.0),
        ];
        assert!((form_factor(p, n, &wall) - 0.5).abs() < 1e-3);
        // A polygon in the point's own plane subtends nothing.
        let side = [
            Vec3::new(2.0, 0.0, -1.0),
            Vec3::new(3.0, 0.0, -1.0),
            Vec3::new(3.0, 0.0, 1.0),
            Vec3::new(2.0, 0.0, 1.0),
        ];
        assert!(form_factor(p, n, &side) < 1e-6);
    }

    #[test]
    fn hash_is_uniform_and_stable() {
        let mean: f32 = (0..10_000).map(|i| hash01(i, 3, 7)).sum::<f32>() / 10_000.0;
        assert!((mean - 0.5).abs() < 0.02);
        assert_eq!(hash01(1, 2, 3), hash01(1, 2, 3));
        assert!((0..1000).all(|i| (0.0..1.0).contains(&hash01(i, i, i))));
    }
}
