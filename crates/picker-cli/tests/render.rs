//! `picker render` end to end: a tiny elements folder and a uniform
//! environment map in a temporary directory.

use std::path::Path;
use std::process::{Command, Output};

use picker_render::io::{self, Image};

fn picker(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_picker"))
        .args(args)
        .output()
        .expect("running picker")
}

fn assert_ok(o: &Output) {
    assert!(
        o.status.success(),
        "picker failed: {}\n{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
}

const H: usize = 3;
const W: usize = 4;

fn rgb_image(f: impl Fn(usize) -> [f32; 3]) -> Image {
    let mut img = Image::zeros(3, H, W);
    for i in 0..H * W {
        img.set_rgb(i, f(i).into());
    }
    img
}

/// Diffuse 0.5 grey, no specular, normals facing the camera except the last
/// pixel (no surface); a uniform environment of radiance 1 (so the render is 0.5).
fn make_scene(dir: &Path) {
    let el = dir.join("elements");
    std::fs::create_dir_all(&el).unwrap();
    let files = [
        ("diffuse_albedo", rgb_image(|_| [0.5; 3])),
        ("specular_albedo", rgb_image(|_| [0.0; 3])),
        ("glossiness", Image::new(1, H, W, vec![0.5; H * W]).unwrap()),
        (
            "normals",
            rgb_image(|i| {
                if i + 1 == H * W {
                    [0.0; 3]
                } else {
                    [0.0, 0.0, 1.0]
                }
            }),
        ),
        ("view_vector", rgb_image(|_| [0.0, 0.0, 1.0])),
    ];
    for (name, img) in files {
        io::write_exr(&el.join(format!("{name}.exr")), &img).unwrap();
    }
    let env = Image::new(3, 8, 16, vec![1.0; 3 * 8 * 16]).unwrap();
    io::write_exr(&dir.join("env.exr"), &env).unwrap();
    let reference = rgb_image(|i| if i + 1 == H * W { [0.0; 3] } else { [0.5; 3] });
    io::write_exr(&dir.join("reference.exr"), &reference).unwrap();
}

#[test]
fn render_writes_image_error_map_and_score() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    make_scene(d);
    for fast in [false, true] {
        let out = d.join(if fast { "out_fast" } else { "out" });
        let mut args = vec![
            "render",
            d.join("elements").to_str().unwrap(),
            "--envmap",
            d.join("env.exr").to_str().unwrap(),
            "--reference",
            d.join("reference.exr").to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--threads",
            "1",
        ]
        .into_iter()
        .map(String::from)
        .collect::<Vec<_>>();
        if fast {
            args.push("--fast".into());
        }
        let o = picker(&args.iter().map(String::as_str).collect::<Vec<_>>());
        assert_ok(&o);
        assert!(String::from_utf8_lossy(&o.stdout).contains("RMSE"));
        let img = io::read_exr(&out.join("render.exr")).unwrap();
        assert_eq!((img.channels, img.height, img.width), (3, H, W));
        for i in 0..H * W - 1 {
            let v = img.rgb(i);
            assert!((0..3).all(|c| (v[c] - 0.5).abs() < 0.01), "{fast}: {v}");
        }
        assert_eq!(img.rgb(H * W - 1).max_element(), 0.0);
        let png = io::read_png(&out.join("render.png")).unwrap();
        assert_eq!((png.channels, png.height, png.width), (3, H, W));
        assert!(out.join("error.png").exists());
        let json: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("render.json")).unwrap())
                .unwrap();
        assert_eq!(json["score"]["pixels"], (H * W - 1) as u64);
        assert!(json["score"]["rmse_linear"].as_f64().unwrap() < 0.01);
        assert!(json["score"]["rmse_srgb"].as_f64().unwrap() < 0.02);
        assert_eq!(json["quality"], if fast { "fast" } else { "exact" });
    }
}

/// `picker render --preview` of one material under `d/env` into `d/out`, with `extra` flags.
fn preview(d: &Path, env: &str, out: &str, extra: &[&str]) -> Output {
    let (env, out) = (d.join(env), d.join(out));
    let mut args = vec![
        "render",
        "--preview",
        "--diffuse",
        "0.6,0.3,0.2",
        "--specular",
        "0.2,0.2,0.2",
        "--exponent",
        "64",
        "--envmap",
        env.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    picker(&args)
}

#[test]
fn preview_writes_sphere_and_tile() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    make_scene(d);
    assert_ok(&preview(d, "env.exr", "preview", &["--size", "24"]));
    for name in ["preview_sphere.png", "preview_tile.png"] {
        let img = io::read_png(&d.join("preview").join(name)).unwrap();
        assert_eq!((img.height, img.width), (24, 24), "{name}");
        assert!(img.data.iter().any(|&v| v > 0.1), "{name} is black");
    }
    // The automatic exposure follows the lighting: the same envmap 50 times
    // brighter gives the same pictures (to 8-bit rounding); a fixed exposure
    // does not.
    let env = io::read_exr(&d.join("env.exr")).unwrap();
    let bright = Image {
        data: env.data.iter().map(|v| v * 50.0).collect(),
        ..env
    };
    io::write_exr(&d.join("bright.exr"), &bright).unwrap();
    let run = |env: &str, out: &str, exposure: &str| {
        assert_ok(&preview(
            d,
            env,
            out,
            &["--size", "24", "--exposure", exposure],
        ));
        io::read_png(&d.join(out).join("preview_sphere.png"))
            .unwrap()
            .data
    };
    let close = |a: &[f32], b: &[f32]| a.iter().zip(b).all(|(x, y)| (x - y).abs() <= 2.5 / 255.0);
    let (a, b) = (
        run("env.exr", "pa", "auto"),
        run("bright.exr", "pb", "auto"),
    );
    assert!(
        close(&a, &b),
        "auto exposure changed with the lighting's scale"
    );
    let (f, g) = (run("env.exr", "pf", "1"), run("bright.exr", "pg", "1"));
    assert!(
        !close(&f, &g),
        "a fixed exposure ignored the lighting's scale"
    );
    let o = preview(d, "env.exr", "px", &["--exposure", "-2"]);
    assert!(!o.status.success(), "a negative exposure was accepted");
}

#[test]
fn non_finite_envmaps_and_textures_are_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    make_scene(d);
    let mut env = io::read_exr(&d.join("env.exr")).unwrap();
    env.data[5] = f32::NAN;
    env.data[6] = f32::INFINITY;
    io::write_exr(&d.join("nan-env.exr"), &env).unwrap();
    let o = preview(d, "nan-env.exr", "o1", &[]);
    assert_eq!(o.status.code(), Some(1));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("nan-env.exr") && err.contains("NaN or infinite"),
        "{err}"
    );
    assert!(!d.join("o1/preview_sphere.png").exists());
    let mut tex = rgb_image(|i| [0.2, 0.3, (i % 3) as f32 / 3.0]);
    tex.data[2] = f32::NAN;
    io::write_exr(&d.join("nan-tex.exr"), &tex).unwrap();
    let t = d.join("nan-tex.exr");
    let o = preview(d, "env.exr", "o2", &["--texture", t.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("nan-tex.exr") && err.contains("NaN or infinite"),
        "{err}"
    );
}

#[test]
fn errors_name_the_file() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    make_scene(d);
    let out = d.join("o");
    let missing = d.join("missing.hdr");
    let o = picker(&[
        "render",
        d.join("elements").to_str().unwrap(),
        "--envmap",
        missing.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(1));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("missing.hdr") && err.lines().count() == 1,
        "{err}"
    );

    // A reference of the wrong size.
    io::write_exr(&d.join("small.exr"), &Image::zeros(3, 2, 2)).unwrap();
    let o = picker(&[
        "render",
        d.join("elements").to_str().unwrap(),
        "--envmap",
        d.join("env.exr").to_str().unwrap(),
        "--reference",
        d.join("small.exr").to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(1));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("small.exr") && err.contains("3x4"), "{err}");

    // A missing element.
    std::fs::remove_file(d.join("elements/normals.exr")).unwrap();
    let o = picker(&[
        "render",
        d.join("elements").to_str().unwrap(),
        "--envmap",
        d.join("env.exr").to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("normals.exr"));

    // --preview without a material is a usage error.
    let o = picker(&["render", "--preview", "--envmap", "x.exr", "--out", "o"]);
    assert_eq!(o.status.code(), Some(2));
}
