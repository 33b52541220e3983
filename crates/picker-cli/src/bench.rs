//! `picker bench`: time forward passes of one network on a random input.
//!
//! Peak RSS is the `VmHWM` of the whole `picker` process (Linux
//! `/proc/self/status`); where the kernel allows it, the high-water mark is
//! reset (`/proc/self/clear_refs`) after random weights are generated and
//! before the weights file is opened, so the figure covers loading the
//! weights plus the timed runs, not weight generation.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use picker_nets::{Net, NetConfig, NetKind, StorageDtype, Weights};
use picker_tensor::{Isa, Rng, Tensor};

use crate::args::{self, NetArg};

/// Arguments of `picker bench`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Which network (with --weights: defaults to the file's, must match it).
    #[arg(long, value_enum)]
    pub net: Option<NetArg>,
    /// Input size HEIGHTxWIDTH.
    #[arg(long, default_value = "240x320", value_parser = args::parse_size)]
    pub size: (usize, usize),
    /// A weights file to benchmark; without it, random weights of --preset.
    #[arg(long, value_name = "FILE.safetensors")]
    pub weights: Option<PathBuf>,
    /// Preset of the random weights used without --weights.
    #[arg(long, default_value = "thesis", conflicts_with = "weights")]
    pub preset: String,
    /// Worker threads (default: one per logical core).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Timed forward passes.
    #[arg(long, default_value_t = 5, value_parser = clap::value_parser!(u32).range(1..))]
    pub runs: u32,
    /// Untimed forward passes before the timed ones.
    #[arg(long, default_value_t = 1)]
    pub warmup: u32,
    /// Batch size of the input.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..))]
    pub batch: u32,
    /// Print exactly one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
    /// After the timed runs, run --runs more passes stage by stage (towers one
    /// after another) and report each stage's median time.
    #[arg(long)]
    pub profile: bool,
}

/// Runs `picker bench`.
pub fn run(a: Args) -> Result<()> {
    let (h, w) = a.size;
    args::check_megapixels(
        &format!("--batch {} --size {h}x{w}", a.batch),
        a.batch as u64 * h as u64 * w as u64,
    )?;
    let threads = crate::threads::init(a.threads)?;

    // Weights: the given file, or random ones of the preset via a temporary file
    // (removed when `_tmp` drops) so loading goes the same mmap path as a real run.
    let mut _tmp = None;
    let (path, source) = match &a.weights {
        Some(p) => (p.clone(), p.display().to_string()),
        None => {
            let kind: NetKind = a.net.context("--net is required without --weights")?.into();
            let config = NetConfig::preset(kind, &a.preset)?;
            let dir = tempfile::Builder::new()
                .prefix("picker-bench-")
                .tempdir()
                .context("creating a temporary directory for random weights")?;
            let p = dir.path().join(format!("{kind}-{}.safetensors", a.preset));
            // Plain write, no fsync: the file is scratch and only read back by this process.
            let bytes = picker_nets::serialize_safetensors(
                &p,
                &picker_nets::random_weights(&config, 0),
                &picker_nets::metadata_for(&config, &a.preset)?,
                StorageDtype::F32,
            )?;
            std::fs::write(&p, bytes)
                .with_context(|| format!("writing random weights to {}", p.display()))?;
            _tmp = Some(dir);
            (p, format!("random {} (seed 0)", a.preset))
        }
    };
    let rss_reset = reset_peak_rss();

    let t0 = Instant::now();
    let weights = Weights::open(&path).context("reading weights")?;
    if let Some(n) = a.net {
        let kind: NetKind = n.into();
        if weights.kind() != kind {
            bail!(
                "{}: holds {} weights, but --net {kind} was given",
                path.display(),
                weights.kind()
            );
        }
    }
    let net = Net::load(&weights).context("loading network")?;
    let preset = weights.preset().to_string();
    // The network holds its own (folded, packed) copy: unmap the file.
    drop(weights);
    let load_ms = t0.elapsed().as_secs_f64() * 1e3;
    let load_rss_mb = peak_rss_mb();
    let kind = net.kind();
    let config = net.config();

    let mut rng = Rng::new(1);
    // 3 planes (normalised RGB); the learned inpainter reads channels + 1 (texture + mask).
    let shape = [a.batch as usize, config.in_channels(), h, w];
    let input = Tensor::new(shape, rng.uniform_vec(shape.iter().product(), -1.0, 1.0))
        .context("making the random input")?;

    for _ in 0..a.warmup {
        net.forward(&input).context("forward pass")?;
    }
    let mut times = Vec::with_capacity(a.runs as usize);
    for _ in 0..a.runs {
        let t = Instant::now();
        let out = net.forward(&input).context("forward pass")?;
        times.push(t.elapsed().as_secs_f64() * 1e3);
        drop(out);
    }
    times.sort_by(f64::total_cmp);
    let median_ms = median(&times);
    let min_ms = times[0];
    let flops = config.flops(h, w) as f64 * a.batch as f64;
    let gflops = flops / (median_ms * 1e-3) / 1e9;
    let peak_rss_mb = peak_rss_mb();
    let isa = Isa::best().name();
    let stages = if a.profile {
        profile(&net, &input, a.runs)?
    } else {
        Vec::new()
    };

    if a.json {
        let obj = serde_json::json!({
            "net": kind.as_str(),
            "preset": preset,
            "weights": source,
            "size": format!("{h}x{w}"),
            "height": h,
            "width": w,
            "batch": a.batch,
            "threads": threads,
            "runs": a.runs,
            "warmup": a.warmup,
            "median_ms": median_ms,
            "min_ms": min_ms,
            "times_ms": times,
            "load_ms": load_ms,
            "gflop": flops / 1e9,
            "gflops": gflops,
            "peak_rss_mb": peak_rss_mb,
            "peak_rss_after_load_mb": load_rss_mb,
            "peak_rss_scope": if rss_reset { "process, from weight loading on" } else { "process" },
            "isa": isa,
            "precision": picker_tensor::precision().name(),
            "params": config.param_count(),
            "stages": stages
                .iter()
                .map(|(name, ms)| serde_json::json!({"stage": name, "median_ms": ms}))
                .collect::<Vec<_>>(),
        });
        println!("{obj}");
    } else {
        println!(
            "{kind} ({preset}, {} parameters) at {h}x{w}, batch {}: median {median_ms:.1} ms, \
             min {min_ms:.1} ms over {} runs ({} warm-up); {:.1} GFLOP/run, {gflops:.1} GFLOP/s; \
             load {load_ms:.0} ms; peak RSS {}; {threads} threads; ISA {isa}, {}",
            args::thousands(config.param_count()),
            a.batch,
            a.runs,
            a.warmup,
            flops / 1e9,
            peak_rss_mb.map_or("n/a".to_string(), |m| format!("{m:.0} MB")),
            picker_tensor::precision(),
        );
        if !stages.is_empty() {
            let total: f64 = stages.iter().map(|(_, ms)| ms).sum();
            println!(
                "stages, one after another (median of {} passes; sum {total:.1} ms):",
                a.runs
            );
            let width = stages.iter().map(|(n, _)| n.len()).max().unwrap_or(0);
            for (name, ms) in &stages {
                println!("  {name:<width$} {ms:>9.2} ms {:>5.1}%", 100.0 * ms / total);
            }
        }
    }
    Ok(())
}

/// Runs `runs` stage-timed passes; returns each stage's median in ms, in
/// execution order.
fn profile(net: &Net, input: &Tensor, runs: u32) -> Result<Vec<(String, f64)>> {
    let mut per_stage: Vec<(String, Vec<f64>)> = Vec::new();
    for _ in 0..runs {
        let mut timings = picker_nets::Timings::new();
        net.forward_timed(input, &mut timings)
            .context("profiled forward pass")?;
        if per_stage.is_empty() {
            per_stage = timings
                .iter()
                .map(|(n, _)| (n.clone(), Vec::new()))
                .collect();
        }
        if timings.len() != per_stage.len() {
            bail!("the profiled passes recorded different stages");
        }
        for ((_, v), (_, d)) in per_stage.iter_mut().zip(&timings) {
            v.push(d.as_secs_f64() * 1e3);
        }
    }
    Ok(per_stage
        .into_iter()
        .map(|(n, mut v)| {
            v.sort_by(f64::total_cmp);
            (n, median(&v))
        })
        .collect())
}

/// Median of sorted values (mean of the middle two for an even count).
fn median(sorted: &[f64]) -> f64 {
    let n = sorted.len();
    if n % 2 == 1 {
        sorted[n / 2]
    } else {
        (sorted[n / 2 - 1] + sorted[n / 2]) / 2.0
    }
}

/// The process's peak resident set size in MB (10⁶ bytes), from `VmHWM` in
/// `/proc/self/status`; `None` where that is not available.
fn peak_rss_mb() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024.0 / 1e6)
}

/// Resets the peak-RSS high-water mark (Linux: write `5` to
/// `/proc/self/clear_refs`). Returns whether it worked.
fn reset_peak_rss() -> bool {
    std::fs::write("/proc/self/clear_refs", "5").is_ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn medians() {
        assert_eq!(median(&[1.0]), 1.0);
        assert_eq!(median(&[1.0, 2.0, 10.0]), 2.0);
        assert_eq!(median(&[1.0, 2.0, 4.0, 10.0]), 3.0);
    }
}
