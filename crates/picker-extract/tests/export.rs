//! Tests of `picker_extract::export`: the files exist, parse and agree with the material.

use std::path::Path;

use picker_extract::export::{write_material_files, ExportOptions, GltfConversion};
use picker_extract::{Material, MaterialParams, TextureResult, UvMode};
use picker_render::io::{read_exr, read_png, Image};
use serde_json::{json, Value};

fn params() -> MaterialParams {
    let g = 0.5f32;
    MaterialParams {
        diffuse: [0.4, 0.2, 0.1],
        specular: [0.05, 0.04, 0.03],
        glossiness: g,
        exponent: picker_nets::conventions::phong_exponent(g),
    }
}

fn mask() -> Image {
    let (h, w) = (6, 8);
    let data = (0..h * w)
        .map(|i| if i % w >= 3 { 1.0 } else { 0.0 })
        .collect();
    Image::new(1, h, w, data).unwrap()
}

fn textured() -> Material {
    let s = 16;
    let n = s * s;
    let mut tex = Image::zeros(3, s, s);
    for i in 0..n {
        let (r, c) = (i / s, i % s);
        tex.data[i] = r as f32 / s as f32;
        tex.data[n + i] = c as f32 / s as f32;
        tex.data[2 * n + i] = 0.25;
    }
    let coverage = Image::new(1, s, s, (0..n).map(|i| (i % 3) as f32 / 2.0).collect()).unwrap();
    Material {
        name: "material_0".into(),
        pick: Some([3, 2]),
        params: params(),
        textured: true,
        texture: Some(TextureResult {
            raw: tex.clone(),
            texture: tex,
            coverage,
            coverage_fraction: 0.66,
            observed_size: s,
            size_m: None,
            uv_mode: UvMode::Plane,
            seam: picker_inpaint::SeamScore {
                wrap: 0.1,
                interior: 0.2,
                ratio: 0.5,
            },
            seam_corrected: false,
            inpainter: "patchmatch".into(),
        }),
        mask: mask(),
        area_fraction: 0.625,
        rerender_psnr: Some(31.5),
    }
}

fn untextured() -> Material {
    Material {
        name: "plain paint".into(),
        pick: None,
        params: params(),
        textured: false,
        texture: None,
        mask: mask(),
        area_fraction: 0.625,
        rerender_psnr: None,
    }
}

fn read_json(path: &Path) -> Value {
    serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap()
}

fn names(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

/// The `Kd`/`Ks`/... lines of an MTL file as (keyword, numbers or text).
fn mtl_lines(text: &str) -> Vec<(String, Vec<String>)> {
    text.lines()
        .map(str::trim)
        .filter(|l| !l.is_empty() && !l.starts_with('#'))
        .map(|l| {
            let mut it = l.split_whitespace();
            let k = it.next().unwrap().to_string();
            (k, it.map(String::from).collect())
        })
        .collect()
}

fn floats(v: &[String]) -> Vec<f32> {
    v.iter().map(|s| s.parse::<f32>().unwrap()).collect()
}

#[test]
fn textured_material_writes_every_file() {
    let dir = tempfile::tempdir().unwrap();
    let m = textured();
    let extra = json!({"timings": {"total_s": 1.5}, "version": "0.1.0"});
    let files = write_material_files(dir.path(), &m, &extra, &ExportOptions::default()).unwrap();
    let expected = [
        "coverage.png",
        "mask.png",
        "material.gltf",
        "material.json",
        "material.mtl",
        "material.usda",
        "texture.exr",
        "texture.png",
    ];
    assert_eq!(names(dir.path()), expected, "no temporary files left");
    assert_eq!(files.len(), expected.len());
    assert!(files.iter().all(|p| p.exists()));

    // Texture: sRGB in the PNG, linear in the EXR.
    let tex = &m.texture.as_ref().unwrap().texture;
    let png = read_png(&dir.path().join("texture.png")).unwrap();
    assert_eq!((png.channels, png.height, png.width), (3, 16, 16));
    let exr = read_exr(&dir.path().join("texture.exr")).unwrap();
    assert_eq!(exr.data, tex.data);
    for i in [0usize, 37, 255] {
        let lin = tex.data[i];
        let enc = picker_nets::conventions::srgb_encode(lin);
        assert!((png.data[i] - enc).abs() <= 0.5 / 255.0 + 1e-6, "texel {i}");
    }
    let cov = read_png(&dir.path().join("coverage.png")).unwrap();
    assert_eq!((cov.channels, cov.height, cov.width), (1, 16, 16));
    let mk = read_png(&dir.path().join("mask.png")).unwrap();
    assert_eq!(mk.data, m.mask.data);

    // material.json
    let j = read_json(&dir.path().join("material.json"));
    assert_eq!(j["name"], "material_0");
    assert_eq!(j["pick"], json!([3, 2]));
    assert_eq!(j["textured"], true);
    assert_eq!(j["texture"]["uv_mode"], "plane");
    assert_eq!(j["texture"]["inpainter"], "patchmatch");
    assert_eq!(j["texture"]["seam"]["ratio"], 0.5);
    assert_eq!(j["texture"]["coverage_fraction"], 0.66);
    assert_eq!(j["area_fraction"], 0.625);
    assert_eq!(j["rerender_psnr_db"], 31.5);
    assert_eq!(j["timings"]["total_s"], 1.5);
    assert_eq!(j["version"], "0.1.0");
    assert_eq!(j["files"]["texture_png"], "texture.png");
    let n = j["phong"]["exponent"].as_f64().unwrap();
    assert!((n - 2f64.powf(6.5)).abs() < 1e-3);
    assert!(j["conventions"]["phong.exponent"]
        .as_str()
        .unwrap()
        .contains("2^(13 g)"));
    assert!(j["conventions"]["gltf.alpha"]
        .as_str()
        .unwrap()
        .contains("sqrt"));

    // Stable key order: sorted, and the same bytes when written again.
    let text = std::fs::read_to_string(dir.path().join("material.json")).unwrap();
    let keys: Vec<&String> = j.as_object().unwrap().keys().collect();
    let pos: Vec<usize> = keys
        .iter()
        .map(|k| text.find(&format!("\n  \"{k}\"")).unwrap())
        .collect();
    assert!(
        pos.windows(2).all(|w| w[0] < w[1]),
        "keys sorted in the file"
    );
    let mut sorted_keys = keys.clone();
    sorted_keys.sort();
    assert_eq!(keys, sorted_keys);
    write_material_files(dir.path(), &m, &extra, &ExportOptions::default()).unwrap();
    assert_eq!(
        text,
        std::fs::read_to_string(dir.path().join("material.json")).unwrap()
    );

    // material.mtl
    let mtl = std::fs::read_to_string(dir.path().join("material.mtl")).unwrap();
    let lines = mtl_lines(&mtl);
    let get = |k: &str| {
        lines
            .iter()
            .find(|(kk, _)| kk == k)
            .unwrap_or_else(|| panic!("{k} missing in\n{mtl}"))
            .1
            .clone()
    };
    assert_eq!(get("newmtl"), ["material_0"]);
    // Textured: MTL multiplies map_Kd by Kd, so Kd is white.
    assert_eq!(floats(&get("Kd")), [1.0, 1.0, 1.0]);
    assert_eq!(floats(&get("Ks")), m.params.specular);
    assert!((floats(&get("Ns"))[0] - m.params.exponent).abs() < 1e-3);
    assert_eq!(get("d"), ["1"]);
    assert_eq!(get("illum"), ["2"]);
    assert_eq!(get("map_Kd"), ["texture.png"]);

    // material.gltf
    let g = read_json(&dir.path().join("material.gltf"));
    assert_eq!(g["asset"]["version"], "2.0");
    assert_eq!(g["extensionsUsed"], json!(["KHR_materials_specular"]));
    let mat = &g["materials"][0];
    let pbr = &mat["pbrMetallicRoughness"];
    assert_eq!(pbr["metallicFactor"], 0.0);
    assert_eq!(pbr["baseColorTexture"]["index"], 0);
    assert_eq!(pbr["baseColorFactor"], json!([1.0, 1.0, 1.0, 1.0]));
    let rough = pbr["roughnessFactor"].as_f64().unwrap();
    assert!(rough > 0.0 && rough < 1.0);
    let conv = GltfConversion::new(m.params.exponent, m.params.specular);
    assert!((rough - conv.perceptual_roughness).abs() < 1e-12);
    let spec = &mat["extensions"]["KHR_materials_specular"];
    assert_eq!(spec["specularFactor"], 1.0);
    let sc: Vec<f64> = spec["specularColorFactor"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    assert_eq!(sc.len(), 3);
    // The ratified extension's F0 = min(0.04 · specularColorFactor, 1) · specularFactor
    // is ρs, channel by channel.
    for (c, &v) in sc.iter().enumerate() {
        let f0 = (0.04 * v).min(1.0);
        assert!((f0 - m.params.specular[c] as f64).abs() < 1e-6, "{sc:?}");
    }
    assert_eq!(g["textures"][0]["source"], 0);
    assert_eq!(g["textures"][0]["sampler"], 0);
    assert_eq!(g["images"][0]["uri"], "texture.png");
    assert_eq!(g["samplers"][0]["wrapS"], 10497);
    assert_eq!(g["samplers"][0]["wrapT"], 10497);
    assert!(g.get("meshes").is_none());

    // material.usda
    let usda = std::fs::read_to_string(dir.path().join("material.usda")).unwrap();
    let u = usda_attributes(&usda);
    assert!(usda.starts_with("#usda 1.0\n"));
    assert!(usda.contains("defaultPrim = \"material_0\""));
    assert!(usda.contains("def Material \"material_0\""));
    assert_eq!(
        u["token outputs:surface.connect"],
        "</material_0/PreviewSurface.outputs:surface>"
    );
    assert_eq!(u["uniform token info:id"], "\"UsdPreviewSurface\"");
    assert_eq!(u["int inputs:useSpecularWorkflow"], "1");
    assert_eq!(
        usd_triple(&u["color3f inputs:specularColor"]),
        m.params.specular
    );
    let r: f64 = u["float inputs:roughness"].parse().unwrap();
    assert!((r - conv.perceptual_roughness).abs() < 1e-6);
    assert_eq!(
        u["color3f inputs:diffuseColor.connect"],
        "</material_0/DiffuseTexture.outputs:rgb>"
    );
    assert_eq!(u["asset inputs:file"], "@texture.png@");
    assert_eq!(
        u["float2 inputs:st.connect"],
        "</material_0/TexCoordReader.outputs:result>"
    );
    assert_eq!(u["string inputs:varname"], "\"st\"");
    assert_eq!(u["token inputs:sourceColorSpace"], "\"sRGB\"");
    assert_eq!(u["token inputs:wrapS"], "\"repeat\"");
    assert_eq!(u["token inputs:wrapT"], "\"repeat\"");
    for shader in ["PreviewSurface", "TexCoordReader", "DiffuseTexture"] {
        assert!(
            usda.contains(&format!("def Shader \"{shader}\"")),
            "{shader}"
        );
    }
    assert_eq!(usda.matches('{').count(), usda.matches('}').count());
}

/// The `type name = value` lines of a `.usda` text (the last of each kind:
/// shader ids repeat, the first is the surface's).
fn usda_attributes(usda: &str) -> std::collections::HashMap<String, String> {
    let mut m = std::collections::HashMap::new();
    for line in usda.lines().map(str::trim) {
        if let Some((k, v)) = line.split_once(" = ") {
            if !k.contains('"') {
                m.entry(k.to_string()).or_insert_with(|| v.to_string());
            }
        }
    }
    m
}

/// `(a, b, c)` as three floats.
fn usd_triple(v: &str) -> [f32; 3] {
    let f: Vec<f32> = v
        .trim_matches(|c| c == '(' || c == ')')
        .split(", ")
        .map(|x| x.parse().unwrap())
        .collect();
    [f[0], f[1], f[2]]
}

#[test]
fn untextured_material_has_constant_colours_and_no_texture_files() {
    let dir = tempfile::tempdir().unwrap();
    let m = untextured();
    write_material_files(dir.path(), &m, &Value::Null, &ExportOptions::default()).unwrap();
    assert_eq!(
        names(dir.path()),
        [
            "mask.png",
            "material.gltf",
            "material.json",
            "material.mtl",
            "material.usda"
        ]
    );
    let j = read_json(&dir.path().join("material.json"));
    assert_eq!(j["textured"], false);
    assert_eq!(j["texture"], Value::Null);
    assert_eq!(j["pick"], Value::Null);
    assert_eq!(j["rerender_psnr_db"], Value::Null);
    assert_eq!(j["files"]["texture_png"], Value::Null);

    let mtl = std::fs::read_to_string(dir.path().join("material.mtl")).unwrap();
    assert!(!mtl.contains("map_Kd"));
    let lines = mtl_lines(&mtl);
    assert!(lines
        .iter()
        .any(|(k, v)| k == "newmtl" && v == &["plain_paint"]));

    let g = read_json(&dir.path().join("material.gltf"));
    let pbr = &g["materials"][0]["pbrMetallicRoughness"];
    assert!(pbr.get("baseColorTexture").is_none());
    let bc: Vec<f64> = pbr["baseColorFactor"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    assert!((bc[0] - 0.4).abs() < 1e-6 && (bc[1] - 0.2).abs() < 1e-6 && bc[3] == 1.0);
    assert!(g.get("images").is_none() && g.get("textures").is_none());
    assert_eq!(g["asset"]["version"], "2.0");

    // USD: a constant diffuse colour, no texture shaders, the name made an identifier.
    let usda = std::fs::read_to_string(dir.path().join("material.usda")).unwrap();
    let u = usda_attributes(&usda);
    assert!(usda.contains("def Material \"plain_paint\""));
    assert_eq!(
        usd_triple(&u["color3f inputs:diffuseColor"]),
        m.params.diffuse
    );
    assert!(!usda.contains("UsdUVTexture") && !usda.contains("texture.png"));
    assert!(!u.contains_key("color3f inputs:diffuseColor.connect"));
}

#[test]
fn sixteen_bit_texture_decodes() {
    let dir = tempfile::tempdir().unwrap();
    let m = textured();
    let opts = ExportOptions { sixteen_bit: true };
    write_material_files(dir.path(), &m, &Value::Null, &opts).unwrap();
    let bytes = std::fs::read(dir.path().join("texture.png")).unwrap();
    // IHDR: 8-byte signature, length, "IHDR", width, height, then the bit depth.
    assert_eq!(&bytes[12..16], b"IHDR");
    assert_eq!(bytes[24], 16, "16 bits per sample");
    let png = read_png(&dir.path().join("texture.png")).unwrap();
    let tex = &m.texture.as_ref().unwrap().texture;
    for (i, &lin) in tex.data.iter().enumerate() {
        let enc = picker_nets::conventions::srgb_encode(lin);
        assert!(
            (png.data[i] - enc).abs() <= 0.6 / 65535.0 + 1e-6,
            "sample {i}"
        );
    }
    let j = read_json(&dir.path().join("material.json"));
    assert_eq!(j["files"]["texture_png_bits"], 16);
}

#[test]
fn missing_directory_is_an_error_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("no").join("such");
    let err = write_material_files(
        &missing,
        &textured(),
        &Value::Null,
        &ExportOptions::default(),
    )
    .unwrap_err();
    assert!(
        err.to_string().contains(&missing.display().to_string()),
        "{err}"
    );
    // A file in place of the directory.
    let file = dir.path().join("file");
    std::fs::write(&file, b"x").unwrap();
    let err = write_material_files(&file, &textured(), &Value::Null, &ExportOptions::default())
        .unwrap_err();
    assert!(
        err.to_string().contains(&file.display().to_string()),
        "{err}"
    );
}

#[cfg(unix)]
#[test]
fn unwritable_directory_is_an_error_naming_the_file() {
    use std::os::unix::fs::PermissionsExt;
    let dir = tempfile::tempdir().unwrap();
    let ro = dir.path().join("ro");
    std::fs::create_dir(&ro).unwrap();
    std::fs::set_permissions(&ro, std::fs::Permissions::from_mode(0o555)).unwrap();
    if std::fs::write(ro.join("probe"), b"x").is_ok() {
        // Running as root: permissions are not enforced.
        eprintln!("skipped: directory permissions are not enforced for this user");
        std::fs::set_permissions(&ro, std::fs::Permissions::from_mode(0o755)).unwrap();
        return;
    }
    let err = write_material_files(&ro, &textured(), &Value::Null, &ExportOptions::default())
        .unwrap_err();
    let msg = err.to_string();
    std::fs::set_permissions(&ro, std::fs::Permissions::from_mode(0o755)).unwrap();
    assert!(msg.contains(&ro.display().to_string()), "{msg}");
    assert!(
        names(&ro).is_empty(),
        "nothing left behind: {:?}",
        names(&ro)
    );
}

#[test]
fn extra_must_be_an_object_without_clashes() {
    let dir = tempfile::tempdir().unwrap();
    let m = untextured();
    let opts = ExportOptions::default();
    assert!(write_material_files(dir.path(), &m, &json!([1, 2]), &opts).is_err());
    let err = write_material_files(dir.path(), &m, &json!({"name": "x"}), &opts).unwrap_err();
    assert!(err.to_string().contains("name"), "{err}");
    assert!(
        names(dir.path()).is_empty(),
        "nothing written on a refused extra"
    );
}

#[test]
fn exponent_conversions_are_sane() {
    // Ns clamped to MTL's range; roughness decreasing with the exponent.
    let dir = tempfile::tempdir().unwrap();
    let mut m = untextured();
    m.params.glossiness = 1.0;
    m.params.exponent = 8192.0;
    write_material_files(dir.path(), &m, &Value::Null, &ExportOptions::default()).unwrap();
    let mtl = std::fs::read_to_string(dir.path().join("material.mtl")).unwrap();
    let ns = mtl_lines(&mtl)
        .into_iter()
        .find(|(k, _)| k == "Ns")
        .unwrap()
        .1;
    assert_eq!(floats(&ns), [1000.0]);

    let mut last = f64::INFINITY;
    for n in [1.0f32, 2.0, 10.0, 100.0, 1000.0, 8192.0] {
        let c = GltfConversion::new(n, [0.0; 3]);
        assert!((c.alpha - (2.0 / (4.0 * n as f64 + 2.0)).sqrt()).abs() < 1e-12);
        assert!((c.perceptual_roughness - c.alpha.sqrt()).abs() < 1e-12);
        assert!(c.perceptual_roughness < last && c.perceptual_roughness > 0.0);
        last = c.perceptual_roughness;
        assert_eq!(c.specular_factor, 0.0);
        assert_eq!(c.specular_color, [1.0; 3]);
    }
    // glTF's dielectric F0 (KHR_materials_specular, ratified:
    // min(0.04 · specularColorFactor, 1) · specularFactor) is ρs, clamped to
    // [0, 1]; a non-finite ρs reads as 0.
    for rho in [
        [0.04f32, 0.04, 0.04],
        [0.5, 0.25, 0.0],
        [1.0, 1.0, 1.0],
        [2.0, -1.0, f32::NAN],
        [1e-6, 0.0, 0.0],
    ] {
        let c = GltfConversion::new(16.0, rho);
        assert_eq!(c.specular_factor, 1.0, "{rho:?}");
        for ch in 0..3 {
            let f0 = (0.04 * c.specular_color[ch]).min(1.0) * c.specular_factor;
            let want = if rho[ch].is_finite() {
                rho[ch].clamp(0.0, 1.0) as f64
            } else {
                0.0
            };
            assert!(
                (f0 - want).abs() < 1e-7,
                "{rho:?} channel {ch}: {f0} vs {want}"
            );
        }
    }
    assert_eq!(
        GltfConversion::new(16.0, [0.04; 3]).specular_color,
        [1.0; 3]
    );
}

#[test]
fn failed_write_names_the_file_and_leaves_no_temporary() {
    // A directory in the way of material.json makes its rename fail (even as root).
    let dir = tempfile::tempdir().unwrap();
    let blocker = dir.path().join("material.json");
    std::fs::create_dir(&blocker).unwrap();
    std::fs::write(blocker.join("keep"), b"x").unwrap();
    let err = write_material_files(
        dir.path(),
        &textured(),
        &Value::Null,
        &ExportOptions::default(),
    )
    .unwrap_err();
    assert!(
        err.to_string().contains(&blocker.display().to_string()),
        "{err}"
    );
    assert!(
        names(dir.path()).iter().all(|n| !n.starts_with('.')),
        "temporary files left: {:?}",
        names(dir.path())
    );
}
