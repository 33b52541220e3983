//! `picker`: the Material Picker command-line tool.
//!
//! Subcommands (one module each, no numerics here — decoding and conventions
//! live in `picker_nets::conventions`, kernels in `picker_tensor`):
//!
//! - `picker extract PHOTO --weights DIR --pick X,Y`: the material under a
//!   point as a tileable texture + Phong parameters + exports ([`extract`]).
//! - `picker batch IN_DIR --out OUT_DIR --picks picks.csv | --all`: extract over
//!   a folder, resumable and shardable ([`batch`]).
//! - `picker completions SHELL`: a shell completion script.
//! - `picker infer PHOTO --weights DIR_OR_FILE --out DIR`: run IRN, MSN and/or
//!   EnvMap on a photo and write every decoded output as EXR + PNG
//!   ([`infer`]).
//! - `picker weights random|inspect`: make random weights files, describe one
//!   ([`weights_cmd`]).
//! - `picker bench --net irn --size 240x320`: time forward passes ([`mod@bench`]).
//! - `picker synth --count N --size HxW --seed S --out DIR`: synthetic scenes
//!   with ground-truth render elements ([`synth`]).
//! - `picker render ELEMENTS_DIR --envmap F --out DIR`: re-render from render
//!   elements and score against a reference; `--preview` renders a material ([`render`]).
//!
//! Errors are printed as one line, `error: <what>: <cause>`, and the exit
//! status is 1 (2 for command-line usage errors; `picker batch` also exits 1
//! when some photos failed and 130 when interrupted).

use std::process::ExitCode;

use clap::{Parser, Subcommand};

mod args;
mod batch;
mod bench;
mod eval;
mod extract;
mod infer;
mod output;
mod photo;
mod render;
mod staging;
mod synth;
mod threads;
mod weights_cmd;

/// Material Picker: material recognition in photographs (IRN, MSN and EnvMap
/// networks, pure-Rust CPU inference).
#[derive(Debug, Parser)]
#[command(name = "picker", version)]
struct Cli {
    /// Arithmetic of the networks' 3×3 stride-1 layers (the residual blocks): `f32`
    /// (default) or `bf16` (AVX512_BF16 dot products, or AMX tiles where the CPU has
    /// them: measured 1.3–1.6× faster networks on AMD Zen 4/5 and ~1.7× on an Intel
    /// Xeon with AMX against the f32 of before its F(5×5) tile, 1.1–1.25× for the MSN and
    /// no faster for the EnvMap since, on Zen 4; slower than f32 on Intel CPUs with
    /// AVX512_BF16 and no AMX;
    /// outputs within ~6e-2 of f32 on the tanh scale; needs a CPU with AVX512_BF16).
    /// Default: `PICKER_PRECISION`, else f32.
    #[arg(long, global = true, value_name = "f32|bf16", value_parser = parse_precision)]
    precision: Option<picker_tensor::Precision>,
    #[command(subcommand)]
    command: Command,
}

/// Parses `--precision`.
fn parse_precision(s: &str) -> Result<picker_tensor::Precision, String> {
    picker_tensor::Precision::parse(s).ok_or_else(|| format!("{s:?} is not f32 or bf16"))
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Extract the material under a picked point: tileable texture, Phong parameters, exports.
    Extract(extract::Args),
    /// Extract materials from a folder of photos: resumable, shardable, one report.
    Batch(batch::Args),
    /// Score extraction on synthetic scenes with ground truth (mask IoU, texture PSNR, ...).
    Eval(eval::Args),
    /// Run the networks on a photo and write their decoded outputs (EXR + PNG).
    Infer(infer::Args),
    /// Create or describe weights files.
    #[command(subcommand)]
    Weights(weights_cmd::Command),
    /// Time forward passes of one network.
    Bench(bench::Args),
    /// Re-render an image from render elements and an environment map, or preview a material.
    Render(render::Args),
    /// Generate synthetic indoor scenes with ground-truth render elements.
    Synth(synth::Args),
    /// Print a shell completion script (bash, zsh, fish, elvish, powershell).
    Completions {
        /// The shell.
        #[arg(value_enum)]
        shell: clap_complete::Shell,
    },
}

/// A command-line usage error found after parsing (exit status 2, as clap's own).
#[derive(Debug)]
pub struct UsageError(pub String);

impl std::fmt::Display for UsageError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for UsageError {}

fn run(cli: Cli) -> anyhow::Result<ExitCode> {
    use anyhow::Context;
    let done = |r: anyhow::Result<()>| r.map(|()| ExitCode::SUCCESS);
    if let Some(p) = cli.precision {
        picker_tensor::set_precision(p).context("--precision")?;
    } else if let Some(v) = std::env::var_os("PICKER_PRECISION") {
        // The environment's precision, refused as clearly as the flag's.
        let p = v
            .to_str()
            .and_then(picker_tensor::Precision::parse)
            .ok_or_else(|| UsageError(format!("PICKER_PRECISION={v:?} is not f32 or bf16")))?;
        picker_tensor::set_precision(p).context("PICKER_PRECISION")?;
    }
    match cli.command {
        Command::Batch(a) => batch::run(a),
        Command::Completions { shell } => {
            use clap::CommandFactory;
            clap_complete::generate(shell, &mut Cli::command(), "picker", &mut std::io::stdout());
            Ok(ExitCode::SUCCESS)
        }
        Command::Extract(a) => done(extract::run(a)),
        Command::Eval(a) => done(eval::run(a)),
        Command::Infer(a) => done(infer::run(a)),
        Command::Weights(c) => done(weights_cmd::run(c)),
        Command::Bench(a) => done(bench::run(a)),
        Command::Render(a) => done(render::run(a)),
        Command::Synth(a) => done(synth::run(a)),
    }
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match run(cli) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {}", one_line(&e));
            if e.downcast_ref::<UsageError>().is_some() {
                ExitCode::from(2)
            } else {
                ExitCode::FAILURE
            }
        }
    }
}

/// The error and its causes joined by `": "` on one line, skipping a cause
/// whose text the message already contains (some library errors print their
/// source themselves).
pub(crate) fn one_line(e: &anyhow::Error) -> String {
    let mut msg = String::new();
    for cause in e.chain() {
        let text = cause.to_string();
        let text = text.trim().trim_end_matches('.');
        if text.is_empty() || msg.contains(text) {
            continue;
        }
        if !msg.is_empty() {
            msg.push_str(": ");
        }
        msg.push_str(text);
    }
    msg.replace(['\n', '\r'], " ")
}
