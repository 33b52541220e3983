//! Writing a rendered scene as a folder of files (names and encodings as
//! `picker infer` writes where they overlap; every write atomic).
//!
//! | file | contents |
//! |---|---|
//! | `image.exr` / `image.png` | linear RGB (exposure applied) / sRGB 8-bit, clipped |
//! | `diffuse_albedo`, `specular_albedo` `.exr/.png` | linear ρd, ρs / sRGB-encoded |
//! | `glossiness.exr/.png` | g ∈ \[0,1\] (channel Y) / g as grey |
//! | `normals`, `view_vector` `.exr/.png` | unit camera-space vectors / (n+1)/2 |
//! | `uv.exr/.png` | (u, v, t), u, v ∈ [0,1) wrapped texture coordinates as given to `Texture::sample`, t = 1 textured / 0 single colour (then u = v = 0) / as RGB |
//! | `depth.exr` | distance along −z in metres (channel Y), 0 where the sky is seen |
//! | `material_id.png` | 16-bit grey, the material id (0: sky) |
//! | `segmentation.exr/.png` | (ρd*+ρs)/2 of the pixel's material (0 for the sky) / as is |
//! | `envmap.exr/.png` | camera-frame environment map at 1/8 size, exposure applied / Reinhard tone map |
//! | `direct_env.exr` | the env-map Phong term alone, exposure applied |
//! | `materials/<id>/` | `material.json`; textured materials also `texture.exr` (linear) + `texture.png` (sRGB) |
//! | `scene.json` | everything needed to rebuild the scene |

use std::path::Path;

use glam::Vec3;
use picker_nets::conventions as conv;
use picker_render::io::{self, Image};
use serde_json::json;

use crate::render::Buffers;
use crate::scene::{Diffuse, Scene};
use crate::{Error, Result, GENERATOR_VERSION};

fn planes3(v: &[Vec3], f: impl Fn(f32) -> f32) -> Vec<f32> {
    let n = v.len();
    let mut out = vec![0.0; 3 * n];
    for (i, c) in v.iter().enumerate() {
        out[i] = f(c.x);
        out[n + i] = f(c.y);
        out[2 * n + i] = f(c.z);
    }
    out
}

fn img(c: usize, h: usize, w: usize, data: Vec<f32>) -> Result<Image> {
    Ok(Image::new(c, h, w, data)?)
}

fn write_pair(
    dir: &Path,
    name: &str,
    b: &Buffers,
    v: &[Vec3],
    png: impl Fn(f32) -> f32,
) -> Result<()> {
    let (h, w) = (b.height, b.width);
    io::write_exr(
        &dir.join(format!("{name}.exr")),
        &img(3, h, w, planes3(v, |x| x))?,
    )?;
    io::write_png(
        &dir.join(format!("{name}.png")),
        &img(3, h, w, planes3(v, png))?,
    )?;
    Ok(())
}

fn vec3(v: Vec3) -> [f32; 3] {
    v.to_array()
}

/// The `scene.json` of a rendered scene.
pub fn scene_json(scene: &Scene, b: &Buffers) -> serde_json::Value {
    let cam = &scene.camera;
    let materials: Vec<_> = scene.materials.iter().map(material_json).collect();
    let primitives: Vec<_> = scene
        .primitives
        .iter()
        .map(|p| {
            json!({"shape": p.shape, "material_id": scene.materials[p.material].id, "shell": p.shell})
        })
        .collect();
    let objects: Vec<_> = scene
        .objects
        .iter()
        .map(|(k, bb)| json!({"kind": k, "min": vec3(bb.min), "max": vec3(bb.max)}))
        .collect();
    json!({
        "generator": "picker-synth",
        "generator_version": GENERATOR_VERSION,
        "seed": scene.seed,
        "index": scene.index,
        "width": b.width,
        "height": b.height,
        "world": "metres, +y up; the room spans [0,W]x[0,H]x[0,D]",
        "room": {"width": scene.room.x, "height": scene.room.y, "depth": scene.room.z},
        "camera": {
            "position": vec3(cam.position),
            "yaw_deg": cam.yaw.to_degrees(),
            "pitch_deg": cam.pitch.to_degrees(),
            "roll_deg": cam.roll.to_degrees(),
            "fov_y_deg": cam.fov_y.to_degrees(),
            "camera_to_world": [vec3(cam.rotation.x_axis), vec3(cam.rotation.y_axis), vec3(cam.rotation.z_axis)],
            "camera_to_world_layout": "columns: the camera's x, y, z axes in world coordinates; the camera looks along -z",
            "views": scene.config.views.name(),
            "view": scene.view.name(),
        },
        "primitives": primitives,
        "objects": objects,
        "openings": scene.openings,
        "lamps": scene.lamps,
        "materials": materials,
        "sky": scene.sky_info,
        "sky_frame": "world frame; envmap.exr is this sky turned into the camera frame and resampled to 1/8 of the image size",
        "exposure": b.exposure,
        "exposure_note": "image, direct_env and envmap are the linear renders times this factor (log-average luminance of the image -> 0.18)",
        "image_model": "image = visibility * direct_env + lamps (Phong, soft shadows) + ambient (rho_d/pi * flux/room area); sky pixels show the sky",
    })
}

fn material_json(m: &crate::scene::Material) -> serde_json::Value {
    let (family, texture) = match &m.diffuse {
        Diffuse::Texture(_, info) => (json!(info.family), json!(info)),
        Diffuse::Colour(_) => (json!("single_colour"), serde_json::Value::Null),
    };
    let colour = match &m.diffuse {
        Diffuse::Colour(c) => json!(vec3(*c)),
        Diffuse::Texture(..) => serde_json::Value::Null,
    };
    json!({
        "id": m.id,
        "name": m.name,
        "textured": m.textured(),
        "family": family,
        "texture": texture,
        "diffuse_colour": colour,
        "diffuse_mode": vec3(m.diffuse_mode),
        "diffuse_mode_definition": "most frequent diffuse value: texels quantised to 16 levels per sRGB-encoded channel, the fullest bin (ties: lowest index), mean linear colour of its texels",
        "specular": vec3(m.specular),
        "glossiness": m.glossiness,
        "exponent": conv::phong_exponent(m.glossiness),
        "segmentation": vec3(m.segmentation()),
        "mapping": {
            "scale_m": m.scale,
            "rotation_rad": m.rotation,
            "offset": m.offset.to_array(),
            "kind": "planar (world metres) on rectangles, box faces and cylinder caps, rotated; cylindrical/spherical with a whole number of repeats around, unrotated",
        },
    })
}

fn write_json(path: &Path, v: &serde_json::Value) -> Result<()> {
    let mut s = serde_json::to_string_pretty(v).map_err(|e| Error::Json(e.to_string()))?;
    s.push('\n');
    picker_nets::write_atomic(path, s.as_bytes())?;
    Ok(())
}

/// Writes every output of a rendered scene into `dir` (created if needed).
/// `materials`: also write the `materials/` folder (textures and parameters).
pub fn write_scene(dir: &Path, scene: &Scene, b: &Buffers, materials: bool) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|source| Error::Io {
        path: dir.to_path_buf(),
        source,
    })?;
    let (h, w) = (b.height, b.width);
    write_pair(dir, "image", b, &b.image, conv::srgb_encode)?;
    write_pair(dir, conv::DIFFUSE_ALBEDO, b, &b.diffuse, conv::srgb_encode)?;
    write_pair(
        dir,
        conv::SPECULAR_ALBEDO,
        b,
        &b.specular,
        conv::srgb_encode,
    )?;
    io::write_exr(
        &dir.join("glossiness.exr"),
        &img(1, h, w, b.glossiness.clone())?,
    )?;
    io::write_png(
        &dir.join("glossiness.png"),
        &img(1, h, w, b.glossiness.clone())?,
    )?;
    write_pair(dir, conv::NORMALS, b, &b.normals, conv::unit_from_tanh)?;
    write_pair(dir, conv::VIEW_VECTOR, b, &b.view, conv::unit_from_tanh)?;
    write_pair(dir, conv::UV, b, &b.uv, |x| x)?;
    write_pair(dir, conv::SEGMENTATION, b, &b.segmentation, |x| x)?;
    io::write_exr(&dir.join("depth.exr"), &img(1, h, w, b.depth.clone())?)?;
    let ids: Vec<f32> = b.material_id.iter().map(|&i| i as f32 / 65535.0).collect();
    io::write_png16(&dir.join("material_id.png"), &img(1, h, w, ids)?)?;
    io::write_exr(
        &dir.join("direct_env.exr"),
        &img(3, h, w, planes3(&b.direct_env, |x| x))?,
    )?;
    let env = &b.envmap;
    let env_planes = planes3(env.data(), |x| x);
    let (eh, ew) = (env.height(), env.width());
    io::write_exr(
        &dir.join("envmap.exr"),
        &img(3, eh, ew, env_planes.clone())?,
    )?;
    io::write_png(
        &dir.join("envmap.png"),
        &img(3, eh, ew, conv::tone_map_rgb(&env_planes, eh * ew))?,
    )?;
    if materials {
        for m in &scene.materials {
            let md = dir.join("materials").join(m.id.to_string());
            std::fs::create_dir_all(&md).map_err(|source| Error::Io {
                path: md.clone(),
                source,
            })?;
            if let Diffuse::Texture(t, _) = &m.diffuse {
                let p = t.to_planes();
                io::write_exr(
                    &md.join("texture.exr"),
                    &img(3, t.height, t.width, p.clone())?,
                )?;
                let s = p.iter().map(|&x| conv::srgb_encode(x)).collect();
                io::write_png(&md.join("texture.png"), &img(3, t.height, t.width, s)?)?;
            }
            write_json(&md.join("material.json"), &material_json(m))?;
        }
    }
    write_json(&dir.join("scene.json"), &scene_json(scene, b))
}
