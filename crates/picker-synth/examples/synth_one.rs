//! Generates one scene and prints timings: `cargo run --release -p picker-synth --example synth_one -- OUT SEED INDEX HxW`.
use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let a: Vec<String> = std::env::args().collect();
    let out = std::path::PathBuf::from(a.get(1).map(String::as_str).unwrap_or("/tmp/synth_one"));
    let seed: u64 = a.get(2).and_then(|s| s.parse().ok()).unwrap_or(1);
    let index: u64 = a.get(3).and_then(|s| s.parse().ok()).unwrap_or(0);
    let (h, w) = a
        .get(4)
        .and_then(|s| s.split_once('x'))
        .and_then(|(h, w)| Some((h.parse().ok()?, w.parse().ok()?)))
        .unwrap_or((240, 320));
    let cfg = picker_synth::scene::SceneConfig::for_size(h, w);
    let t = Instant::now();
    let s = picker_synth::scene::generate(seed, index, cfg, None)?;
    let t_gen = t.elapsed();
    let t = Instant::now();
    let b = picker_synth::render::render(&s);
    let t_render = t.elapsed();
    let t = Instant::now();
    picker_synth::output::write_scene(&out, &s, &b, true)?;
    let t_write = t.elapsed();
    println!(
        "generate {:?} render {:?} write {:?}; {} primitives, {} materials, exposure {}",
        t_gen,
        t_render,
        t_write,
        s.primitives.len(),
        s.materials.len(),
        b.exposure
    );
    Ok(())
}
