//! Scores an extracted texture against a true one: `score EXTRACTED.exr TRUTH.exr`
//! prints the aligned PSNR (dB), the best scale and the colour distance.

use std::path::Path;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if args.len() != 3 {
        eprintln!("usage: score EXTRACTED TRUTH");
        std::process::exit(2);
    }
    let e = picker_render::io::read_image(Path::new(&args[1])).expect("extracted");
    let t = picker_render::io::read_image(Path::new(&args[2])).expect("truth");
    let s = picker_extract::eval::aligned_texture_score(&e, &t);
    println!(
        "{:.2} dB scale {} shift {:?} colour {:.4}",
        s.psnr_db, s.scale, s.shift, s.colour_distance
    );
}
