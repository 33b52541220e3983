//! `picker infer`: run the networks on a photo and write every decoded output.
//!
//! The photo is read ([`crate::photo`]), resized so its long side is
//! `--work-size`, normalised (`conventions::normalize_input`) and given to each
//! network found through `--weights`. Each output is decoded per
//! `picker_nets::conventions` and written twice: an EXR with the exact f32
//! decoded values and an 8-bit PNG for viewing (encodings in [`ENCODINGS`] and
//! the README). A `manifest.json` lists the files, networks, weights, sizes and
//! timings. Every file is written atomically.

use std::collections::BTreeSet;
use std::path::PathBuf;
use std::time::Instant;

use anyhow::{anyhow, bail, Context, Result};
use picker_nets::conventions as conv;
use picker_nets::mirror;
use picker_nets::{IrnOutput, Net, NetKind, Weights};
use picker_tensor::{Isa, Tensor};
use serde_json::json;

use crate::{output, photo};

/// Arguments of `picker infer`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The photograph (PNG, JPEG, TIFF, WebP or BMP; any bit depth; EXIF orientation applied).
    #[arg(value_name = "PHOTO")]
    pub photo: PathBuf,
    /// A directory holding irn.safetensors, msn.safetensors and/or envmap.safetensors
    /// (those present run), or one weights file (its metadata says which network).
    /// May be repeated. Default: the embedded `lite` weights.
    #[arg(long, value_name = "DIR_OR_FILE")]
    pub weights: Vec<PathBuf>,
    /// Output directory (created if needed; existing files of the same names are replaced).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Long side of the working resolution in pixels; the photo is resized (up or down)
    /// so its long side is exactly this, keeping the aspect ratio.
    #[arg(long, default_value_t = 320, value_parser = clap::value_parser!(u32).range(1..=8192))]
    pub work_size: u32,
    /// Worker threads (default: one per logical core).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Run each network once. By default it also runs on the mirrored photo and the outputs that
    /// mirror with it are averaged, as `picker extract` does (texture coordinates, the material
    /// embedding and outputs of unknown meaning are the first pass's).
    #[arg(long)]
    pub single_pass: bool,
}

/// The file names looked for in a `--weights` directory.
pub const WEIGHTS_FILES: [(NetKind, &str); 3] = [
    (NetKind::Irn, "irn.safetensors"),
    (NetKind::Msn, "msn.safetensors"),
    (NetKind::EnvMap, "envmap.safetensors"),
];

/// How each output is stored: `(output name, EXR contents, PNG contents)`.
pub const ENCODINGS: [(&str, &str, &str); 12] = [
    (
        conv::DIFFUSE_ALBEDO,
        "diffuse albedo, linear RGB in [0,1]: (y+1)/2",
        "sRGB-encoded diffuse albedo",
    ),
    (
        conv::SPECULAR_ALBEDO,
        "specular albedo, linear RGB in [0,1]: (y+1)/2",
        "sRGB-encoded specular albedo",
    ),
    (
        conv::NORMALS,
        "unit normals (x,y,z) in camera space (+x right, +y up, +z to the camera), renormalised",
        "(n+1)/2",
    ),
    (
        conv::GLOSSINESS,
        "glossiness g in [0,1] (channel Y): (y+1)/2; Phong exponent n = 2^(13 g)",
        "g as grey",
    ),
    (
        conv::VIEW_VECTOR,
        "unit vectors (x,y,z) from the surface to the camera, camera space, renormalised",
        "(v+1)/2",
    ),
    (
        conv::UV,
        "texture coordinates (u,v,t): (y+1)/2, u and v wrapped to [0,1); t=1 textured, 0 single-colour",
        "(u,v,t) as RGB",
    ),
    (
        conv::SEGMENTATION,
        "segmentation colour RGB in [0,1]: (y+1)/2",
        "segmentation colour as is",
    ),
    (
        conv::EMBEDDING,
        "material embedding, the network's raw tanh values in [-1,1] (3 channels): pixels of one material \
         near each other, different materials far apart; only distances mean anything",
        "(e+1)/2",
    ),
    (
        conv::ENVMAP,
        "equirectangular environment map, linear HDR radiance L = expm1(ln(1001)(y+1)/2) in [0,1000]; \
         row 0 up, centre column straight ahead (-z)",
        "Reinhard global tone map (auto exposure, key 0.18), sRGB-encoded",
    ),
    (
        DISAGREEMENT_ALBEDO,
        "how far the IRN's two passes (the photo and its mirror image) disagree: the mean over R, G, B \
         of |albedo1 - albedo2| (linear, channel Y); only with the mirror pass",
        "4 x the value, clamped to [0,1], grey",
    ),
    (
        DISAGREEMENT_NORMALS,
        "the angle in degrees between the IRN's two passes' normals (channel Y); only with the mirror \
         pass",
        "degrees / 90, clamped to [0,1], grey",
    ),
    (
        "*",
        "unknown output, (y+1)/2",
        "(y+1)/2 clamped to [0,1]",
    ),
];

/// The output name of the IRN passes' albedo disagreement
/// ([`picker_nets::mirror::IrnDisagreement::albedo`]).
pub const DISAGREEMENT_ALBEDO: &str = "disagreement_albedo";
/// The output name of the IRN passes' normals disagreement, degrees.
pub const DISAGREEMENT_NORMALS: &str = "disagreement_normals";

fn encoding(name: &str) -> (&'static str, &'static str) {
    let e = ENCODINGS
        .iter()
        .find(|(n, _, _)| *n == name)
        .unwrap_or(&ENCODINGS[ENCODINGS.len() - 1]);
    (e.1, e.2)
}

/// A weights file chosen to run.
pub(crate) struct Chosen {
    /// The file, or `<embedded lite>/FILE` for the default weights.
    pub(crate) path: PathBuf,
    pub(crate) weights: Weights,
    /// The file's bytes when it is one of the embedded defaults.
    pub(crate) embedded: Option<&'static [u8]>,
}

/// The default weights compiled into the binary (`picker_weights`), parsed.
pub(crate) fn embedded_weights() -> Result<Vec<Chosen>> {
    picker_weights::FILES
        .iter()
        .map(|f| {
            let path = PathBuf::from(picker_weights::label(f));
            let weights = Weights::from_static(&path, f.bytes)
                .context("reading the embedded default weights (a broken build)")?;
            Ok(Chosen {
                path,
                weights,
                embedded: Some(f.bytes),
            })
        })
        .collect()
}

/// Resolves every `--weights` argument to opened weights files, one per
/// network; no argument at all means the embedded default weights.
pub(crate) fn resolve_weights(args: &[PathBuf]) -> Result<Vec<Chosen>> {
    if args.is_empty() {
        return embedded_weights();
    }
    let mut chosen: Vec<Chosen> = Vec::new();
    for arg in args {
        let meta =
            std::fs::metadata(arg).with_context(|| format!("reading weights {}", arg.display()))?;
        let mut found = Vec::new();
        if meta.is_dir() {
            for (kind, file) in WEIGHTS_FILES {
                let p = arg.join(file);
                if p.exists() {
                    found.push((Some(kind), p));
                }
            }
            if found.is_empty() {
                bail!(
                    "{}: directory holds no weights (looked for {})",
                    arg.display(),
                    WEIGHTS_FILES.map(|(_, f)| f).join(", ")
                );
            }
        } else {
            found.push((None, arg.clone()));
        }
        for (expected, path) in found {
            let weights = Weights::open(&path).context("reading weights")?;
            if weights.kind() == NetKind::Inpaint {
                bail!(
                    "{}: file holds inpaint weights (the learned texture inpainter), which \
                     `picker infer` does not run; give irn, msn or envmap weights",
                    path.display()
                );
            }
            if let Some(kind) = expected {
                if weights.kind() != kind {
                    bail!(
                        "{}: file holds {} weights, but its name says {kind}",
                        path.display(),
                        weights.kind()
                    );
                }
            }
            if let Some(other) = chosen.iter().find(|c| c.weights.kind() == weights.kind()) {
                bail!(
                    "{} and {} both hold {} weights; give one per network",
                    other.path.display(),
                    path.display(),
                    weights.kind()
                );
            }
            chosen.push(Chosen {
                path,
                weights,
                embedded: None,
            });
        }
    }
    chosen.sort_by_key(|c| c.weights.kind());
    Ok(chosen)
}

/// One decoded output, planar `[c, h, w]`, ready to write.
struct Decoded {
    name: String,
    net: NetKind,
    exr: Vec<f32>,
    png: Option<Vec<f32>>,
    c: usize,
    h: usize,
    w: usize,
}

impl Decoded {
    fn new(name: &str, net: NetKind, t: &Tensor) -> Self {
        Self {
            name: name.to_string(),
            net,
            exr: t.image(0).to_vec(),
            png: None,
            c: t.c(),
            h: t.h(),
            w: t.w(),
        }
    }
    fn plane_len(&self) -> usize {
        self.h * self.w
    }
    /// PNG values: the EXR values passed through `f` element-wise (1 or 3 channels only).
    fn png_map(mut self, f: impl Fn(f32) -> f32) -> Self {
        if self.c == 1 || self.c == 3 {
            self.png = Some(self.exr.iter().map(|&v| f(v)).collect());
        }
        self
    }
}

/// `(y + 1)/2` of every value: the decoding of an output the conventions do not name.
fn generic(t: &Tensor) -> Tensor {
    let mut out = t.clone();
    out.data_mut()
        .iter_mut()
        .for_each(|v| *v = conv::unit_from_tanh(*v));
    out
}

/// Decodes the IRN heads: the six standard ones through
/// `RenderElements::from_irn`, any others with `(y+1)/2`.
fn decode_irn(out: IrnOutput) -> Result<Vec<Decoded>> {
    let k = NetKind::Irn;
    let standard: BTreeSet<&str> = [
        conv::DIFFUSE_ALBEDO,
        conv::SPECULAR_ALBEDO,
        conv::NORMALS,
        conv::GLOSSINESS,
        conv::VIEW_VECTOR,
        conv::UV,
    ]
    .into();
    let has_all = standard.iter().all(|n| out.get(n).is_some());
    let re = if has_all {
        Some(conv::RenderElements::from_irn(&out).context("decoding IRN outputs")?)
    } else {
        None
    };
    let mut decoded = Vec::new();
    for (name, raw) in &out.heads {
        let d = match (&re, name.as_str()) {
            (Some(re), conv::DIFFUSE_ALBEDO) => {
                Decoded::new(name, k, &re.diffuse_albedo).png_map(conv::srgb_encode)
            }
            (Some(re), conv::SPECULAR_ALBEDO) => {
                Decoded::new(name, k, &re.specular_albedo).png_map(conv::srgb_encode)
            }
            (Some(re), conv::GLOSSINESS) => Decoded::new(name, k, &re.glossiness).png_map(|v| v),
            (Some(re), conv::UV) => Decoded::new(name, k, &re.uv).png_map(|v| v),
            (Some(re), n @ (conv::NORMALS | conv::VIEW_VECTOR)) => {
                let t = if n == conv::NORMALS {
                    &re.normals
                } else {
                    &re.view_vector
                };
                let mut d = Decoded::new(name, k, t);
                let hw = d.plane_len();
                let mut png = vec![0.0; 3 * hw];
                for i in 0..hw {
                    let c =
                        conv::encode_direction_color([d.exr[i], d.exr[hw + i], d.exr[2 * hw + i]]);
                    png[i] = c[0];
                    png[hw + i] = c[1];
                    png[2 * hw + i] = c[2];
                }
                d.png = Some(png);
                d
            }
            _ => Decoded::new(name, k, &generic(raw)).png_map(|v| v),
        };
        decoded.push(d);
    }
    Ok(decoded)
}

/// Runs one network (and on `mirrored`, the input mirrored, when given:
/// [`picker_nets::mirror`]) and decodes its outputs.
fn run_net(net: &Net, x: &Tensor, mirrored: Option<&Tensor>) -> Result<Vec<Decoded>> {
    let what = || format!("running the {} network", net.kind());
    match net {
        Net::Irn(irn) => {
            let (out, dis) = irn
                .forward_mirrored_measured(x, mirrored)
                .with_context(what)?;
            let mut decoded = decode_irn(out)?;
            if let Some(d) = dis {
                let k = NetKind::Irn;
                decoded.push(
                    Decoded::new(DISAGREEMENT_ALBEDO, k, &d.albedo)
                        .png_map(|v| (4.0 * v).clamp(0.0, 1.0)),
                );
                decoded.push(
                    Decoded::new(DISAGREEMENT_NORMALS, k, &d.normals_deg)
                        .png_map(|v| (v / 90.0).clamp(0.0, 1.0)),
                );
            }
            Ok(decoded)
        }
        _ => {
            let out =
                mirror::forward_mirrored(x, mirrored, |t| net.forward(t)).with_context(what)?;
            let mut decoded = Vec::new();
            for (name, raw) in &out.tensors {
                let d = match name.as_str() {
                    conv::SEGMENTATION => {
                        Decoded::new(name, out.kind, &conv::decode_segmentation_tensor(raw))
                            .png_map(|v| v)
                    }
                    conv::EMBEDDING => Decoded::new(name, out.kind, raw)
                        .png_map(|v| conv::unit_from_tanh(v).clamp(0.0, 1.0)),
                    conv::ENVMAP => {
                        let mut d = Decoded::new(name, out.kind, &conv::decode_envmap(raw));
                        if d.c == 3 {
                            d.png = Some(conv::tone_map_rgb(&d.exr, d.plane_len()));
                        }
                        d
                    }
                    _ => Decoded::new(name, out.kind, &generic(raw)).png_map(|v| v),
                };
                decoded.push(d);
            }
            Ok(decoded)
        }
    }
}

/// Writes `bytes` as `out/name` and records it in the manifest list.
fn write_file(
    out: &crate::staging::Staging,
    name: &str,
    bytes: &[u8],
    entry: serde_json::Value,
    files: &mut Vec<serde_json::Value>,
    names: &mut BTreeSet<String>,
) -> Result<()> {
    if !names.insert(name.to_string()) {
        bail!("two outputs would both be written as {name}; rename a network head");
    }
    output::write_atomic(&out.path().join(name), bytes).map_err(|e| out.in_out(e.into()))?;
    files.push(entry);
    Ok(())
}

fn ms(t: Instant) -> f64 {
    (t.elapsed().as_secs_f64() * 1e3 * 1000.0).round() / 1000.0
}

/// Runs `picker infer`.
pub fn run(a: Args) -> Result<()> {
    let t_total = Instant::now();
    let threads = crate::threads::init(a.threads)?;

    // Check everything cheap before the expensive work: photo, weights headers, out dir.
    let t = Instant::now();
    let photo = photo::load(&a.photo)?;
    let read_ms = ms(t);
    let chosen = resolve_weights(&a.weights)?;
    // Every file of the run, or none (see `staging`).
    let staging = crate::staging::Staging::begin(&a.out, "manifest.json", true)?;

    let t = Instant::now();
    let (pw, ph) = photo.rgb.dimensions();
    let (ww, wh) = photo::working_size(pw, ph, a.work_size);
    let work = photo::resize(&photo.rgb, ww, wh);
    let (w, h) = (ww as usize, wh as usize);
    let mut x = Tensor::new([1, 3, h, w], photo::to_planar(&work))
        .map_err(|e| anyhow!("making the input tensor: {e}"))?;
    conv::normalize_input(&mut x);
    let xm = (!a.single_pass).then(|| x.mirror_w());
    let resize_ms = ms(t);

    let mut files = Vec::new();
    let mut names = BTreeSet::new();
    let input_png = output::encode_png(&photo::to_planar(&work), 3, w, h)?;
    write_file(
        &staging,
        "input.png",
        &input_png,
        json!({"file": "input.png", "output": "input", "net": null, "format": "png",
               "width": w, "height": h, "channels": ["R", "G", "B"],
               "encoding": "the photo at the working resolution, sRGB, 8-bit"}),
        &mut files,
        &mut names,
    )?;

    let kinds: Vec<&str> = chosen.iter().map(|c| c.weights.kind().as_str()).collect();
    let mut nets = Vec::new();
    for c in chosen {
        let t = Instant::now();
        let net = Net::load(&c.weights).context("loading network")?;
        let load_ms = ms(t);
        // The network holds its own (folded) copy; unmap the file now.
        let (kind, preset, config, file_size) = (
            c.weights.kind(),
            c.weights.preset().to_string(),
            c.weights.config().clone(),
            c.weights.file_size(),
        );
        drop(c.weights);
        let t = Instant::now();
        let decoded = run_net(&net, &x, xm.as_ref())?;
        let forward_ms = ms(t);
        let t = Instant::now();
        let mut outputs = Vec::new();
        for d in decoded {
            let (exr_enc, png_enc) = encoding(&d.name);
            let exr_name = format!("{}.exr", d.name);
            let bytes = output::encode_exr(&d.exr, d.c, d.w, d.h)
                .with_context(|| format!("encoding {exr_name}"))?;
            write_file(
                &staging,
                &exr_name,
                &bytes,
                json!({"file": exr_name, "output": d.name, "net": d.net.as_str(), "format": "exr",
                       "width": d.w, "height": d.h, "channels": output::exr_channel_names(d.c),
                       "sample": "f32", "encoding": exr_enc}),
                &mut files,
                &mut names,
            )?;
            if let Some(png) = &d.png {
                let png_name = format!("{}.png", d.name);
                let bytes = output::encode_png(png, d.c, d.w, d.h)
                    .with_context(|| format!("encoding {png_name}"))?;
                let ch = if d.c == 1 {
                    vec!["Y"]
                } else {
                    vec!["R", "G", "B"]
                };
                write_file(
                    &staging,
                    &png_name,
                    &bytes,
                    json!({"file": png_name, "output": d.name, "net": d.net.as_str(),
                           "format": "png", "width": d.w, "height": d.h, "channels": ch,
                           "sample": "u8", "encoding": png_enc}),
                    &mut files,
                    &mut names,
                )?;
            }
            outputs.push(d.name);
        }
        let write_ms = ms(t);
        nets.push(json!({
            "net": kind.as_str(),
            "weights": c.path.display().to_string(),
            "preset": preset,
            "config": serde_json::from_str::<serde_json::Value>(&config.to_json())
                .unwrap_or(serde_json::Value::Null),
            "parameters": config.param_count(),
            "file_size": file_size,
            "gflop": config.flops(h, w) as f64 / 1e9,
            "outputs": outputs,
            "timings_ms": {"load": load_ms, "forward_and_decode": forward_ms, "write": write_ms},
        }));
    }

    let manifest = json!({
        "format": "material-picker-infer",
        "format_version": 1,
        "picker_version": env!("CARGO_PKG_VERSION"),
        "photo": {
            "path": a.photo.display().to_string(),
            "format": photo.format.map(|f| format!("{f:?}")),
            "width": pw,
            "height": ph,
            "exif_orientation": format!("{:?}", photo.orientation),
        },
        "working_size": {"width": w, "height": h, "work_size": a.work_size,
                         "resize": "triangle (bilinear, antialiased) on sRGB values"},
        "nets": nets,
        "mirror_pass": xm.is_some(),
        "files": files,
        "threads": threads,
        "isa": Isa::best().name(),
        "timings_ms": {"read_photo": read_ms, "resize": resize_ms, "total": ms(t_total)},
    });
    let text = serde_json::to_string_pretty(&manifest).context("serialising manifest.json")?;
    output::write_atomic(
        &staging.path().join("manifest.json"),
        format!("{text}\n").as_bytes(),
    )
    .map_err(|e| staging.in_out(e.into()))?;
    staging.commit()?;

    println!(
        "wrote {} files and manifest.json to {} ({} at {w}x{h}) in {:.2} s",
        files.len(),
        a.out.display(),
        kinds.join(", "),
        t_total.elapsed().as_secs_f64()
    );
    Ok(())
}
