//! Prints the lens distortion [`picker_extract::lens::estimate`] finds in
//! each photo given: `lens_probe PHOTO…` (add `-v` first for every region).

use std::path::Path;

use picker_extract::lens;
use picker_extract::lines::SmallLuma;
use picker_extract::photo::{load, PhotoLimits};

fn main() {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    let verbose = args.first().is_some_and(|a| a == "-v");
    if verbose {
        args.remove(0);
    }
    for a in &args {
        let p = load(Path::new(a), &PhotoLimits::default()).expect("photo");
        let (w, h) = (p.rgb.width() as usize, p.rgb.height() as usize);
        let luma: Vec<f32> = p
            .rgb
            .pixels()
            .map(|px| 0.2126 * px[0] + 0.7152 * px[1] + 0.0722 * px[2])
            .collect();
        let small = SmallLuma::new(&luma, w, h);
        let t = std::time::Instant::now();
        let (_, est) = lens::estimate(&small);
        let ms = t.elapsed().as_secs_f64() * 1e3;
        println!(
            "{a}: λ {:.3} ({}) median {:?} regions {} agreeing {} ({:.2}) corner shift {:.1} px, {ms:.1} ms",
            est.lambda, est.source, est.median, est.regions, est.agreeing, est.agreement, est.corner_shift_px
        );
        if verbose {
            let mut fits = lens::arc_fits(&small);
            fits.sort_by(|a, b| b.weight.total_cmp(&a.weight));
            for f in fits.iter().take(40) {
                println!(
                    "   λ {:+.3} weight {:9.1} points {:5} width {:.2} at ({:.0}, {:.0}) length {:.0}",
                    f.lambda, f.weight, f.points, f.width_px, f.centroid[0], f.centroid[1], f.length_px
                );
            }
        }
    }
}
