//! Inpainting quality and time on real textures under a real mask:
//!
//! ```text
//! cargo run --release -p picker-inpaint --example inpaint_quality -- \
//!     MASK.png TEXTURE... [--em N] [--em-finest N] [--finest-mean-tolerance X] [--no-adaptive] [--save DIR]
//! ```
//!
//! Each texture is tiled to the mask's size (periodic, like a reprojected
//! texture), the texels where the mask is black (≤ 0.5) are removed, and
//! toroidal PatchMatch fills them. Prints the hole PSNR against the texture
//! (capped at 60 dB in the mean, so exact copies do not dominate it) and the
//! time per texture. The mask of a real extraction is its `coverage.png`.
//! With `--save DIR`, each filled texture is written to `DIR/NAME.png`, to
//! look at.

use picker_inpaint::{InpaintOptions, Inpainter, PatchMatchInpainter};
use picker_render::io::{read_image, write_png, Image};
use std::path::PathBuf;
use std::process::ExitCode;

fn main() -> ExitCode {
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("inpaint_quality: {e}");
            ExitCode::FAILURE
        }
    }
}

fn run() -> Result<(), String> {
    let mut ip = PatchMatchInpainter::default();
    let mut files: Vec<PathBuf> = Vec::new();
    let mut save: Option<PathBuf> = None;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        let mut value = |name: &str| args.next().ok_or(format!("{name} needs a value"));
        match a.as_str() {
            "--em" => {
                ip.em_iterations = value("--em")?.parse().map_err(|e| format!("--em: {e}"))?
            }
            "--em-finest" => {
                ip.em_iterations_finest = value("--em-finest")?
                    .parse()
                    .map_err(|e| format!("--em-finest: {e}"))?
            }
            "--finest-mean-tolerance" => {
                ip.finest_mean_tolerance = value("--finest-mean-tolerance")?
                    .parse()
                    .map_err(|e| format!("--finest-mean-tolerance: {e}"))?
            }
            "--save" => save = Some(value("--save")?.into()),
            "--no-adaptive" => ip.adaptive_levels = false,
            _ => files.push(a.into()),
        }
    }
    if files.len() < 2 {
        return Err("usage: inpaint_quality MASK.png TEXTURE... [--em N] [--em-finest N] [--finest-mean-tolerance X] [--no-adaptive] [--save DIR]".into());
    }
    let mask_path = files.remove(0);
    let mask = read_image(&mask_path).map_err(|e| format!("{}: {e}", mask_path.display()))?;
    let (h, w) = (mask.height, mask.width);
    let known: Vec<bool> = mask.data[..h * w].iter().map(|&v| v > 0.5).collect();
    let opts = InpaintOptions {
        toroidal: true,
        ..InpaintOptions::default()
    };
    println!("{ip:?}");
    let (mut total_db, mut total_s) = (0.0, 0.0);
    for path in &files {
        let tex = read_image(path).map_err(|e| format!("{}: {e}", path.display()))?;
        if tex.channels < 3 {
            return Err(format!("{}: not an RGB texture", path.display()));
        }
        let (th, tw, tn) = (tex.height, tex.width, tex.plane_len());
        let mut data = vec![0.0f32; 3 * h * w];
        for c in 0..3 {
            for y in 0..h {
                for x in 0..w {
                    data[c * h * w + y * w + x] = tex.data[c * tn + (y % th) * tw + x % tw];
                }
            }
        }
        let img = Image::new(3, h, w, data).map_err(|e| e.to_string())?;
        let t = std::time::Instant::now();
        let out = ip.inpaint(&img, &known, &opts).map_err(|e| e.to_string())?;
        let s = t.elapsed().as_secs_f64();
        let (mut se, mut k) = (0.0f64, 0usize);
        for c in 0..3 {
            for i in (0..h * w).filter(|&i| !known[i]) {
                let d = f64::from(out.data[c * h * w + i] - img.data[c * h * w + i]);
                se += d * d;
                k += 1;
            }
        }
        let db = if se > 0.0 {
            10.0 * (k as f64 / se).log10()
        } else {
            f64::INFINITY
        };
        let name = path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        if let Some(dir) = &save {
            let p = dir.join(format!("{name}.png"));
            write_png(&p, &out).map_err(|e| format!("{}: {e}", p.display()))?;
        }
        println!("{name:<24} hole PSNR {db:7.2} dB  {s:.3} s");
        total_db += db.min(60.0);
        total_s += s;
    }
    println!(
        "mean {:.2} dB (each capped at 60), {:.2} s in all",
        total_db / files.len() as f64,
        total_s
    );
    Ok(())
}
