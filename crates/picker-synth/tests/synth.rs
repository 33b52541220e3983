//! Properties of generated scenes: determinism (also across thread counts), the
//! camera never inside or clipping geometry, element validity, and the re-render
//! check of `direct_env.exr` against `picker_render::rerender` (exact quadrature).

use std::collections::BTreeMap;
use std::path::Path;

use glam::Vec3;
use picker_render::{io, ElementImages, EnvMap, EnvQuadrature, Image};
use picker_synth::geometry::Shape;
use picker_synth::render::render;
use picker_synth::scene::{generate, SceneConfig, View, Views};

fn files(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    let mut out = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else {
                let rel = p.strip_prefix(dir).unwrap().to_string_lossy().into_owned();
                out.insert(rel, std::fs::read(&p).unwrap());
            }
        }
    }
    out
}

fn write_in_pool(threads: usize, dir: &Path, seed: u64, indices: &[u64], cfg: SceneConfig) {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    pool.install(|| {
        use rayon::prelude::*;
        indices.par_iter().for_each(|&i| {
            let d = dir.join(picker_synth::scene_dir_name(i));
            picker_synth::generate_scene_to(&d, seed, i, cfg, None, true).unwrap();
        })
    });
}

#[test]
fn same_seed_same_bytes_on_any_thread_count() {
    let cfg = SceneConfig::for_size(24, 32);
    let a = tempfile::tempdir().unwrap();
    let b = tempfile::tempdir().unwrap();
    write_in_pool(1, a.path(), 11, &[0, 1, 2], cfg);
    write_in_pool(2, b.path(), 11, &[2, 1, 0], cfg);
    let (fa, fb) = (files(a.path()), files(b.path()));
    assert!(fa.len() > 3 * 20, "{} files", fa.len());
    assert_eq!(fa.keys().collect::<Vec<_>>(), fb.keys().collect::<Vec<_>>());
    for (k, v) in &fa {
        assert!(v == &fb[k], "{k} differs between runs with 1 and 2 threads");
    }
    // A different seed gives a different scene.
    let c = tempfile::tempdir().unwrap();
    write_in_pool(1, c.path(), 12, &[0], cfg);
    let fc = files(c.path());
    assert_ne!(fc["scene_000000/image.exr"], fa["scene_000000/image.exr"]);
}

#[test]
fn camera_never_inside_or_clipping_geometry() {
    let near = 0.05;
    for views in [Views::Room, Views::Wide] {
        let cfg = SceneConfig {
            height: 24,
            width: 32,
            texture_size: 8,
            sky_height: 8,
            views,
        };
        let mut kinds = BTreeMap::new();
        for index in 0..150 {
            let s = generate(3, index, cfg, None).unwrap();
            *kinds.entry(s.view.name()).or_insert(0) += 1;
            let cam = &s.camera;
            let p = cam.position;
            assert!(
                p.cmpgt(Vec3::splat(0.0)).all() && p.cmplt(s.room).all(),
                "scene {index}: camera {p} outside the room {}",
                s.room
            );
            let (fov, pitch, roll) = (
                cam.fov_y.to_degrees(),
                cam.pitch.to_degrees(),
                cam.roll.to_degrees(),
            );
            let forward = cam.rotation * Vec3::NEG_Z;
            let ahead = picker_synth::geometry::nearest(&s.shapes, p, forward, 0.0, f32::INFINITY)
                .map_or(f32::INFINITY, |(_, h)| h.t);
            assert!(
                views == Views::Wide || s.view == View::Room,
                "{views:?} made {:?}",
                s.view
            );
            let b = s.view.bounds();
            let within = |v: f32, [lo, hi]: [f32; 2]| (lo - 1e-3..=hi + 1e-3).contains(&v);
            assert!(within(fov, b.fov), "scene {index}: fov {fov}");
            assert!(within(pitch, b.pitch), "scene {index}: pitch {pitch}");
            assert!(roll.abs() <= b.roll + 1e-3, "scene {index}: roll {roll}");
            assert!(ahead >= b.free, "scene {index}: {ahead} m ahead");
            assert!(
                b.reach.is_none_or(|r| ahead <= r),
                "scene {index}: {ahead} m ahead"
            );
            for prim in &s.primitives {
                let d = prim.shape.aabb().distance(p);
                assert!(
                    d >= 0.4 - 1e-4,
                    "scene {index}: camera {d} m from {:?}",
                    prim.shape
                );
                if let Shape::Sphere { center, radius } = prim.shape {
                    assert!((p - center).length() > radius + 0.4 - 1e-4);
                }
            }
            // The near plane's corners and centre see every surface beyond it.
            for (row, col) in [(0, 0), (0, 31), (23, 0), (23, 31), (12, 16)] {
                let d = cam.rotation * cam.pixel_direction(row, col, 24, 32);
                let hit = picker_synth::geometry::nearest(&s.shapes, p, d, 0.0, f32::INFINITY);
                if let Some((_, h)) = hit {
                    assert!(h.t > near, "scene {index}: surface at {} m", h.t);
                }
            }
        }
        // Room views only make room views; wide ones make every kind, about half room views.
        match views {
            Views::Room => assert_eq!(kinds.len(), 1, "{kinds:?}"),
            Views::Wide => {
                assert_eq!(kinds.len(), 3, "{kinds:?}");
                assert!((50..=100).contains(&kinds["room"]), "{kinds:?}");
                assert!(kinds["down"] >= 20 && kinds["close"] >= 15, "{kinds:?}");
            }
        }
    }
}

/// `Views::Room` is the default, and a wide scene differs from the room scene of the same seed only
/// in its camera (the room, materials and lights are drawn before it).
#[test]
fn wide_views_change_only_the_camera() {
    let room = SceneConfig::for_size(24, 32);
    assert_eq!(room.views, Views::Room);
    // The room views' bounds are those every dataset before `--views` was drawn with.
    let b = View::Room.bounds();
    assert_eq!(
        (b.pitch, b.roll, b.fov, b.free, b.reach, b.any_heading),
        ([-20.0, 20.0], 3.0, [40.0, 75.0], 1.2, None, false)
    );
    let wide = SceneConfig {
        views: Views::Wide,
        ..room
    };
    let mut moved = 0;
    for index in 0..20 {
        let (a, b) = (
            generate(5, index, room, None).unwrap(),
            generate(5, index, wide, None).unwrap(),
        );
        assert_eq!(a.room, b.room);
        assert_eq!(a.materials.len(), b.materials.len());
        assert_eq!(a.primitives.len(), b.primitives.len());
        moved += usize::from(a.camera.position != b.camera.position);
    }
    assert!(moved >= 10, "{moved}");
}

#[test]
fn elements_are_valid() {
    let cfg = SceneConfig::for_size(36, 48);
    for index in 0..6 {
        let s = generate(5, index, cfg, None).unwrap();
        let b = render(&s);
        let mut seg_of: BTreeMap<u16, Vec3> = BTreeMap::new();
        let mut surfaces = 0;
        for i in 0..b.height * b.width {
            let (n, v) = (b.normals[i], b.view[i]);
            assert!((n.length() - 1.0).abs() < 1e-4, "normal {n}");
            assert!((v.length() - 1.0).abs() < 1e-4, "view {v}");
            assert!(
                n.dot(v) >= -1e-5,
                "scene {index} pixel {i}: normal {n} faces away from {v}"
            );
            let uv = b.uv[i];
            assert!(
                (0.0..1.0).contains(&uv.x) && (0.0..1.0).contains(&uv.y),
                "uv {uv}"
            );
            assert!(uv.z == 0.0 || uv.z == 1.0);
            if uv.z == 0.0 {
                assert_eq!((uv.x, uv.y), (0.0, 0.0));
            }
            assert!((0.0..=1.0).contains(&b.glossiness[i]));
            assert!(b.image[i].is_finite() && b.image[i].min_element() >= 0.0);
            assert!(b.direct_env[i].is_finite() && b.direct_env[i].min_element() >= 0.0);
            let id = b.material_id[i];
            if id == 0 {
                assert_eq!(b.depth[i], 0.0);
                assert_eq!(b.diffuse[i], Vec3::ZERO);
                continue;
            }
            surfaces += 1;
            assert!(b.depth[i] > 0.0);
            let m = &s.materials[id as usize - 1];
            assert_eq!(m.id, id);
            assert_eq!(uv.z == 1.0, m.textured());
            let seg = *seg_of.entry(id).or_insert(b.segmentation[i]);
            assert_eq!(
                seg, b.segmentation[i],
                "segmentation not constant for material {id}"
            );
            assert_eq!(seg, (m.diffuse_mode + m.specular) * 0.5);
            assert_eq!(b.specular[i], m.specular);
            assert_eq!(b.glossiness[i], m.glossiness);
        }
        assert!(surfaces > 0);
        assert!(b.exposure.is_finite() && b.exposure > 0.0);
    }
}

/// Worst per-pixel error of the fast path allowed, relative to the image's
/// mean direct-env radiance, and the allowed mean absolute error (same units).
const RERENDER_MAX_REL: f32 = 0.1;
const RERENDER_MEAN_REL: f32 = 0.01;

/// The exact quadrature of eq. 3.7 per pixel over the map `PrefilteredEnv::
/// resolving` reads for its lobe: the map itself where it resolves the lobe
/// (rows at least `π·√n / (2/3)`), else its bilinear upsampling to the first
/// level of the chain `16·2^(j/2)` (up to 512 rows) above the map with at
/// least `π·√n` rows (one lobe width per pixel).
fn continuous_reference(el: &ElementImages, env: &EnvMap) -> Image {
    let (h, w) = (env.height(), env.width());
    let mut maps: BTreeMap<usize, EnvQuadrature> = BTreeMap::new();
    let mut out = Image::zeros(3, el.height(), el.width());
    for i in 0..el.height() * el.width() {
        if !el.is_valid(i) {
            continue;
        }
        let m = el.material(i);
        let need = std::f64::consts::PI * (m.exponent as f64).sqrt() * 1.5;
        let rows = if need <= h as f64 {
            h
        } else {
            (0..)
                .map(|j| (16.0 * (j as f64 / 2.0).exp2()).round() as usize)
                .map(|r| r.min(512))
                .find(|&r| (r > h && r as f64 >= need / 1.5) || r == 512)
                .unwrap()
        };
        let q = maps.entry(rows).or_insert_with(|| {
            if rows == h {
                EnvQuadrature::new(env)
            } else {
                EnvQuadrature::new(&env.resample((rows * w).div_ceil(h), rows).unwrap())
            }
        });
        out.set_rgb(i, q.shade(el.normals.rgb(i), el.view.rgb(i), &m));
    }
    out
}

/// `direct_env.exr` is eq. 3.7 over the written env map read as a continuous
/// function ([`continuous_reference`]), to the fast path's accuracy.
#[test]
fn rerender_matches_direct_env() {
    let cfg = SceneConfig::for_size(30, 40);
    for index in 0..3 {
        let dir = tempfile::tempdir().unwrap();
        picker_synth::generate_scene_to(dir.path(), 21, index, cfg, None, false).unwrap();
        let el = ElementImages::load(dir.path()).unwrap();
        let env = EnvMap::read(&dir.path().join("envmap.exr")).unwrap();
        assert_eq!((env.height(), env.width()), (30 / 8, 40 / 8));
        let exact = continuous_reference(&el, &env);
        let direct = io::read_exr(&dir.path().join("direct_env.exr")).unwrap();
        assert_eq!(exact.data.len(), direct.data.len());
        let n = direct.data.len();
        let mean = direct.data.iter().map(|v| v.abs()).sum::<f32>() / n as f32;
        let mut worst = 0.0f32;
        let mut sum = 0.0f32;
        for (a, b) in exact.data.iter().zip(&direct.data) {
            let e = (a - b).abs();
            worst = worst.max(e);
            sum += e;
        }
        let (worst_rel, mean_rel) = (worst / mean, sum / n as f32 / mean);
        eprintln!("scene {index}: rerender vs direct_env: worst {worst_rel:.4}, mean {mean_rel:.5} of mean radiance {mean}");
        assert!(
            worst_rel <= RERENDER_MAX_REL && mean_rel <= RERENDER_MEAN_REL,
            "scene {index}: worst {worst_rel}, mean {mean_rel} (relative to the mean radiance {mean})"
        );
    }
}

#[test]
fn envmap_is_the_sky_in_the_camera_frame() {
    let cfg = SceneConfig {
        sky_height: 64,
        ..SceneConfig::for_size(24, 32)
    };
    for index in 0..4 {
        let s = generate(8, index, cfg, None).unwrap();
        let r = s.camera.rotation;
        let cam_sky = s.sky.rotated(r.transpose());
        let (mut err, mut total, mut err_wrong) = (0.0f32, 0.0f32, 0.0f32);
        for k in 0..400 {
            let a = k as f32 * 0.731;
            let b = (k as f32 * 0.377).sin() * 1.4;
            let d_cam = Vec3::new(a.sin() * b.cos(), b.sin(), a.cos() * b.cos()).normalize();
            let want = s.sky.sample(r * d_cam);
            err += (cam_sky.sample(d_cam) - want).abs().element_sum();
            err_wrong += (cam_sky.sample(r * d_cam) - want).abs().element_sum();
            total += want.element_sum();
        }
        // Resampling the rotated map blurs it a little (a sun most); a wrong frame
        // (the rotation applied the other way) is far off unless the camera is level.
        eprintln!(
            "scene {index}: mean error {:.4}, wrong frame {:.4}",
            err / total,
            err_wrong / total
        );
        assert!(
            err <= 0.1 * total,
            "scene {index}: mean error {}",
            err / total
        );
        assert!(err <= err_wrong + 1e-3 * total);
    }
}
