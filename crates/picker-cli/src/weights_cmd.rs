//! `picker weights random|inspect`: make random weights files and describe weights files.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use clap::Subcommand;
use picker_nets::{NetConfig, NetKind, StorageDtype, Weights};

use crate::args::{self, DtypeArg, NetArg};

/// `picker weights …`
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Write a weights file with random (untrained) values for a preset.
    ///
    /// Deterministic in --seed. Useful for tests, benchmarks and the quick start;
    /// the outputs of random networks are not meaningful.
    Random(RandomArgs),
    /// Describe a weights file: network, preset, configuration, parameter count,
    /// dtypes, size and metadata.
    Inspect(InspectArgs),
}

/// Arguments of `picker weights random`.
#[derive(Debug, clap::Args)]
pub struct RandomArgs {
    /// Which network.
    #[arg(long, value_enum)]
    pub net: NetArg,
    /// Size preset: `thesis` (the thesis networks), `lite` (the embedded default's size) or `tiny` (test-sized).
    #[arg(long, default_value = "thesis")]
    pub preset: String,
    /// Seed of the random values.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Storage type of the float tensors.
    #[arg(long, value_enum, default_value_t = DtypeArg::F32)]
    pub dtype: DtypeArg,
    /// The file to write (written atomically).
    #[arg(long, value_name = "FILE.safetensors")]
    pub out: PathBuf,
}

/// Arguments of `picker weights inspect`.
#[derive(Debug, clap::Args)]
pub struct InspectArgs {
    /// The weights file.
    #[arg(value_name = "FILE.safetensors", required_unless_present = "default")]
    pub file: Option<PathBuf>,
    /// Describe the default weights embedded in this binary (all three nets)
    /// instead of a file: preset, parameters and how they were trained.
    #[arg(long = "default", conflicts_with = "file")]
    pub default: bool,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
    /// Also build the network from the file (checks every tensor's presence,
    /// shape, dtype and finiteness, and that none is unused).
    #[arg(long)]
    pub check: bool,
}

/// Runs `picker weights …`.
pub fn run(cmd: Command) -> Result<()> {
    match cmd {
        Command::Random(a) => random(a),
        Command::Inspect(a) => inspect(a),
    }
}

/// Generates, saves and returns nothing; prints a one-line summary.
fn random(a: RandomArgs) -> Result<()> {
    let kind: NetKind = a.net.into();
    let config = NetConfig::preset(kind, &a.preset)?;
    let dtype: StorageDtype = a.dtype.into();
    write_random(&config, &a.preset, a.seed, dtype, &a.out)?;
    let size = std::fs::metadata(&a.out)
        .with_context(|| format!("reading the size of {}", a.out.display()))?
        .len();
    println!(
        "wrote {}: {kind} preset {} seed {}, {} parameters, {:?}, {}",
        a.out.display(),
        a.preset,
        a.seed,
        args::param_count(config.param_count()),
        dtype,
        args::bytes(size)
    );
    Ok(())
}

/// Writes random weights of `config` (labelled `preset`) to `path` atomically.
pub fn write_random(
    config: &NetConfig,
    preset: &str,
    seed: u64,
    dtype: StorageDtype,
    path: &Path,
) -> Result<()> {
    let tensors = picker_nets::random_weights(config, seed);
    let metadata = picker_nets::metadata_for(config, preset)?;
    picker_nets::save_safetensors(path, &tensors, &metadata, dtype).context("writing weights")
}

fn inspect(a: InspectArgs) -> Result<()> {
    let Some(file) = &a.file else {
        let mut all = Vec::new();
        for (i, c) in crate::infer::embedded_weights()?.into_iter().enumerate() {
            if i > 0 && !a.json {
                println!();
            }
            all.push(describe(&c.path, &c.weights, a.check, a.json)?);
        }
        if a.json {
            println!("{}", serde_json::Value::Array(all));
        }
        return Ok(());
    };
    let w = Weights::open(file).context("reading weights")?;
    let obj = describe(file, &w, a.check, a.json)?;
    if a.json {
        println!("{obj}");
    }
    Ok(())
}

/// Prints `w` as text, or returns it as a JSON object when `json`.
fn describe(file: &Path, w: &Weights, do_check: bool, json: bool) -> Result<serde_json::Value> {
    let check = if do_check {
        picker_nets::Net::load(w).context("checking weights")?;
        Some("ok")
    } else {
        None
    };
    let config = w.config();
    let params = config.param_count();
    let dtypes = w.dtypes();
    if json {
        let obj = serde_json::json!({
            "file": file.display().to_string(),
            "net": w.kind().as_str(),
            "preset": w.preset(),
            "config": serde_json::from_str::<serde_json::Value>(&config.to_json())
                .unwrap_or(serde_json::Value::Null),
            "parameters": params,
            "tensors": w.len(),
            "dtypes": dtypes.iter().map(|d| serde_json::json!({
                "dtype": d.dtype, "tensors": d.tensors, "elements": d.elements, "bytes": d.bytes,
            })).collect::<Vec<_>>(),
            "file_size": w.file_size(),
            "metadata": w.metadata(),
            "check": check,
        });
        return Ok(obj);
    }
    println!("file:        {}", file.display());
    println!("net:         {}", w.kind());
    println!("preset:      {}", w.preset());
    println!("parameters:  {}", args::param_count(params));
    println!("tensors:     {}", w.len());
    let dt: Vec<String> = dtypes
        .iter()
        .map(|d| {
            format!(
                "{} ({} tensors, {} values, {})",
                d.dtype,
                d.tensors,
                args::thousands(d.elements),
                args::bytes(d.bytes)
            )
        })
        .collect();
    println!("dtypes:      {}", dt.join(", "));
    println!(
        "file size:   {} ({} bytes)",
        args::bytes(w.file_size()),
        args::thousands(w.file_size())
    );
    println!("config:      {}", config.to_json());
    if let Some(c) = check {
        println!("check:       {c} (the network builds from this file)");
    }
    println!("metadata:");
    for (k, v) in w.metadata() {
        if k != "config" {
            println!("  {k}: {v}");
        }
    }
    Ok(serde_json::Value::Null)
}
