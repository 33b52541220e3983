//! `picker synth`: generate synthetic indoor scenes with ground-truth render
//! elements (`picker_synth`), one folder per scene (`scene_000123/`), in
//! parallel over scenes. Each scene depends only on `(--seed, index)`, so the
//! same seed gives identical files whatever `--threads` is.

use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use anyhow::{Context, Result};
use picker_synth::assets::AssetLibrary;
use picker_synth::scene::{SceneConfig, Views};
use rayon::prelude::*;

/// Arguments of `picker synth`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Number of scenes.
    #[arg(long, default_value_t = 1)]
    pub count: u64,
    /// Image size HEIGHTxWIDTH.
    #[arg(long, default_value = "240x320", value_parser = crate::args::parse_size)]
    pub size: (usize, usize),
    /// Seed of the run; scene i is a function of (seed, i) alone.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Index of the first scene (to extend a run or regenerate one scene).
    #[arg(long, default_value_t = 0)]
    pub start: u64,
    /// Output directory (created if needed).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Asset folder (photo textures, HDR skies) as made by scripts/fetch-assets.sh;
    /// procedural textures and skies only without it.
    #[arg(long, value_name = "DIR")]
    pub assets: Option<PathBuf>,
    /// Camera views: `room` (eye level across the room: pitch ±20°, nothing within 1.2 m ahead; what
    /// every dataset before this option used, and the same scenes) or `wide` (half room views, a
    /// quarter looking down at a floor or table top at pitch −80…−30°, a quarter close-ups of a
    /// surface 0.3–1.5 m ahead; roll ±12°, field of view 30–75°).
    #[arg(long, value_enum, default_value_t = ViewsArg::Room)]
    pub views: ViewsArg,
    /// Also write a contact sheet of the first (up to) 16 images, 4 per row, at half size.
    #[arg(long, value_name = "PNG")]
    pub contact_sheet: Option<PathBuf>,
    /// Worker threads (default: one per logical core).
    #[arg(long)]
    pub threads: Option<usize>,
}

/// `--views` ([`Views`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum ViewsArg {
    /// Eye-level views across the room.
    Room,
    /// Room views, views down at a floor or table and close-ups.
    Wide,
}

/// Infix of a scene folder being written: `.scene_000007.partial-<pid>`.
const PARTIAL: &str = ".partial-";

/// Removes the hidden partial scene folders of runs that were killed
/// (their process no longer exists; Linux only, by `/proc`).
fn remove_stale_partials(out: &Path) {
    crate::staging::remove_dead_partials(out, |n| {
        n.strip_prefix('.')
            .and_then(|n| n.rsplit_once(PARTIAL))
            .map(|(_, pid)| pid)
    });
}

/// Runs `picker synth`.
pub fn run(a: Args) -> Result<()> {
    let t0 = Instant::now();
    let (h, w) = a.size;
    crate::args::check_megapixels(&format!("--size {h}x{w}"), h as u64 * w as u64)?;
    let threads = crate::threads::init(a.threads)?;
    let assets = match &a.assets {
        Some(dir) => Some(
            AssetLibrary::scan(dir)
                .with_context(|| format!("scanning assets in {}", dir.display()))?,
        ),
        None => None,
    };
    std::fs::create_dir_all(&a.out)
        .with_context(|| format!("creating output directory {}", a.out.display()))?;
    remove_stale_partials(&a.out);
    let config = SceneConfig {
        views: match a.views {
            ViewsArg::Room => Views::Room,
            ViewsArg::Wide => Views::Wide,
        },
        ..SceneConfig::for_size(h, w)
    };
    let n = a.count;

    let tty = std::io::stderr().is_terminal();
    let bar = if tty {
        let b = indicatif::ProgressBar::new(n);
        b.set_style(
            indicatif::ProgressStyle::with_template(
                "synth {bar:40} {pos}/{len} scenes  {elapsed_precise} (eta {eta})",
            )
            .expect("valid template"),
        );
        Some(b)
    } else {
        None
    };
    let done = AtomicUsize::new(0);
    let step = (n / 20).max(1) as usize;
    (a.start..a.start + n)
        .into_par_iter()
        .try_for_each(|i| -> Result<()> {
            // Each scene folder appears whole: written as a hidden folder,
            // then renamed into place (an older one of the name replaced).
            let name = picker_synth::scene_dir_name(i);
            let dir = a.out.join(&name);
            let partial = a
                .out
                .join(format!(".{name}{PARTIAL}{}", std::process::id()));
            let made = (|| -> Result<()> {
                if partial.exists() {
                    std::fs::remove_dir_all(&partial)
                        .with_context(|| format!("removing {}", partial.display()))?;
                }
                picker_synth::generate_scene_to(
                    &partial,
                    a.seed,
                    i,
                    config,
                    assets.as_ref(),
                    true,
                )?;
                if dir.exists() {
                    std::fs::remove_dir_all(&dir)
                        .with_context(|| format!("removing the older {}", dir.display()))?;
                }
                std::fs::rename(&partial, &dir)
                    .with_context(|| format!("moving {} into place", dir.display()))
            })();
            if made.is_err() {
                let _ = std::fs::remove_dir_all(&partial);
            }
            made.with_context(|| format!("scene {i} ({})", dir.display()))?;
            let k = done.fetch_add(1, Ordering::Relaxed) + 1;
            match &bar {
                Some(b) => b.inc(1),
                None if k.is_multiple_of(step) || k as u64 == n => {
                    eprintln!("synth: {k}/{n} scenes")
                }
                None => {}
            }
            Ok(())
        })?;
    if let Some(b) = bar {
        b.finish_and_clear();
    }
    let secs = t0.elapsed().as_secs_f64();
    if let Some(sheet) = &a.contact_sheet {
        let paths: Vec<PathBuf> = (a.start..a.start + n.min(16))
            .map(|i| {
                a.out
                    .join(picker_synth::scene_dir_name(i))
                    .join("image.png")
            })
            .collect();
        let img = picker_synth::contact::contact_sheet(&paths, 4, 2)
            .context("making the contact sheet")?;
        picker_render::io::write_png(sheet, &img)
            .with_context(|| format!("writing contact sheet {}", sheet.display()))?;
    }
    eprintln!(
        "wrote {n} scenes ({h}x{w}) to {} in {secs:.2} s: {:.1} ms per scene on {threads} thread{}",
        a.out.display(),
        secs * 1e3 / n.max(1) as f64,
        if threads == 1 { "" } else { "s" }
    );
    Ok(())
}
