//! `picker batch IN_DIR --out OUT_DIR`: `picker extract` over a folder of
//! photos, never losing work and never stopping for one bad photo.
//!
//! - **Discovery**: every file under `IN_DIR` (recursively, hidden entries
//!   and `OUT_DIR` skipped, symlinked folders not followed) whose extension is
//!   a supported image format, in byte order of the relative path. Earlier
//!   results inside `IN_DIR` are skipped too (their images are not photos):
//!   a folder holding a batch report, and a `*.material` folder holding a
//!   `manifest.json` or `summary.json` (`picker batch` / `picker extract`
//!   output).
//! - **Work**: `--picks picks.csv` (`file,x,y[,name]`, file relative to
//!   `IN_DIR`) and/or `--all`; `--quads quads.csv`
//!   (`file,X1,Y1,X2,Y2,X3,Y3,X4,Y4[,WxH]`) gives a photo's plane by a
//!   rectangle's corners, as `picker extract --quad` (and `--quad-size`;
//!   with `--quad-masks` its interior is the material, as `--mask quad`);
//!   `--masks MASK_DIR` gives a photo `a/b.jpg` its material's pixels as the
//!   mask image `MASK_DIR/a/b.<ext>`, as `picker extract --mask`.
//!   The networks are loaded once.
//! - **Outputs**: `OUT_DIR/<relative path>.material/` per photo, one folder
//!   per material inside it, `summary.json`, `envmap.exr` and `manifest.json`.
//!   A photo's folder appears whole: it is written as a hidden `.partial`
//!   folder and renamed into place after its manifest.
//! - **Resume**: the manifest holds the input's SHA-256, the weights' SHA-256,
//!   every output-changing setting, the picks, the quad, the mask's SHA-256, the version, the
//!   SHA-256 of the `picker` binary itself ([`build_sha256`]: another build may write other
//!   results) and each file's size; a re-run skips photos whose manifest matches and redoes the rest.
//!   Batch outputs hold no timings, thread counts or absolute paths, so a
//!   resumed run ends with the same bytes as an uninterrupted one.
//! - **Sharding**: `--shard K/N` keeps the photos whose path hash is `K` mod `N`
//!   (stable under adding files, no coordination needed).
//! - **Parallelism**: `--jobs N` photos at once, each with `threads / N`
//!   kernel threads.
//! - **Ctrl-C / SIGTERM**: no new photo starts, the ones in flight finish;
//!   a second signal removes their partial folders and exits at once (130).
//!   A full output disk stops the batch the same way (every later photo
//!   would fail), with exit status 1.
//! - **Report**: a progress bar (plain lines when stderr is not a terminal),
//!   a summary and `OUT_DIR/batch-report.json`. Exit status 0 when every
//!   photo is ok or up to date, 1 when some failed, 2 for usage errors, 130
//!   when interrupted.

use std::collections::{BTreeMap, BTreeSet};
use std::io::{IsTerminal, Read};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Instant;

use anyhow::{anyhow, Context, Result};
use picker_extract::photo::is_supported_extension;
use picker_inpaint::Inpainter;
use serde_json::{json, Value};
use sha2::{Digest, Sha256};

use crate::extract::{self, Flags, Layout, Models, Request, Source};
use crate::UsageError;
use picker_extract::quad::Quad;
use picker_extract::UserPlane;

/// Arguments of `picker batch`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The folder of photos (searched recursively).
    #[arg(value_name = "IN_DIR")]
    pub in_dir: PathBuf,
    /// The output folder: `<relative path>.material/` per photo and `batch-report.json`.
    #[arg(long, value_name = "OUT_DIR")]
    pub out: PathBuf,
    /// Picks: a CSV file with rows `file,x,y[,name]` (file relative to IN_DIR; a
    /// header row is allowed). Photos without a row are skipped unless --all.
    #[arg(long, value_name = "CSV")]
    pub picks: Option<PathBuf>,
    /// Planes: a CSV file with rows `file,X1,Y1,X2,Y2,X3,Y3,X4,Y4[,WxH]`, the corners
    /// of a rectangle on the surface to extract (as `picker extract --quad`) and
    /// optionally its real size (as `--quad-size`: `210x297mm`). One row per photo;
    /// the photo's one pick in --picks, else the quad's centre, is the material.
    #[arg(long, value_name = "CSV", conflicts_with = "all")]
    pub quads: Option<PathBuf>,
    /// Surface orientations: a CSV file with rows `file,front` or `file,X,Y,Z`, the plane
    /// of that photo's materials instead of the predicted one (as `picker extract --normal`:
    /// `front` for a scan or a head-on photo, else the normal in camera space). One row per
    /// photo; a row overrides --normal for its photo; not for a photo with a quad in --quads.
    #[arg(long, value_name = "CSV")]
    pub normals: Option<PathBuf>,
    /// Masks: a folder where the photo IN_DIR/a/b.jpg finds its material's mask as
    /// MASK_DIR/a/b.png (or .tif, .tiff, .webp, .bmp, .exr, .jpg, .jpeg, .hdr: one of them), as
    /// `picker extract --mask` reads it; that photo gets that one material (its one pick in
    /// --picks, if any, must lie in it). Photos without a mask go as the other flags say.
    #[arg(long, value_name = "MASK_DIR", conflicts_with = "all")]
    pub masks: Option<PathBuf>,
    /// Each photo with a quad in --quads (and no mask in --masks) takes the quad's interior as its
    /// material's pixels, as `picker extract --mask quad`: a perspective crop of every photo.
    #[arg(long, requires = "quads")]
    pub quad_masks: bool,
    /// Extract every material covering at least --min-area of each photo.
    #[arg(long)]
    pub all: bool,
    /// The extraction settings.
    #[command(flatten)]
    pub flags: Flags,
    /// Photos processed at once (default: one per 4 threads, at least 1).
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=1024))]
    pub jobs: Option<u32>,
    /// Threads in all (default: one per logical core), split between the jobs.
    #[arg(long)]
    pub threads: Option<usize>,
    /// Process only shard K of N (0 ≤ K < N): photos whose path hash is K mod N.
    #[arg(long, value_name = "K/N", value_parser = parse_shard)]
    pub shard: Option<(u64, u64)>,
    /// Redo every photo, even those whose manifest says they are up to date.
    #[arg(long)]
    pub force: bool,
    /// Where to write the JSON report (default: OUT_DIR/batch-report.json, or
    /// batch-report.shard-K-of-N.json with --shard).
    #[arg(long, value_name = "FILE")]
    pub report: Option<PathBuf>,
    /// No progress bar or per-photo lines; only the summary.
    #[arg(long)]
    pub quiet: bool,
}

/// Parses `K/N` with `0 ≤ K < N`.
pub fn parse_shard(s: &str) -> std::result::Result<(u64, u64), String> {
    let (k, n) = s
        .split_once('/')
        .ok_or_else(|| format!("expected K/N (e.g. 0/4), got {s:?}"))?;
    let k: u64 = k
        .trim()
        .parse()
        .map_err(|_| format!("{k:?} in {s:?} is not a shard number"))?;
    let n: u64 = n
        .trim()
        .parse()
        .map_err(|_| format!("{n:?} in {s:?} is not a shard count"))?;
    if n == 0 || k >= n {
        return Err(format!(
            "shard {k}/{n}: need 0 ≤ K < N (shards are numbered from 0)"
        ));
    }
    Ok((k, n))
}

/// The shard a photo belongs to: FNV-1a of its relative path (with `/`
/// separators) mod `n`. Stable across machines and runs.
pub fn shard_of(rel: &str, n: u64) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in rel.bytes() {
        h ^= b as u64;
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h % n
}

/// A photo found under `IN_DIR`.
#[derive(Clone, Debug)]
struct Photo {
    /// Path relative to IN_DIR, `/`-separated.
    rel: String,
    /// Full path.
    path: PathBuf,
}

/// Every supported image under `root`, sorted by relative path; `skip` (the
/// output folder) and hidden entries are left out.
fn discover(root: &Path, skip: &[&Path]) -> Result<(Vec<Photo>, usize)> {
    let mut found = Vec::new();
    let mut ignored = 0usize;
    let mut stack = vec![(root.to_path_buf(), String::new())];
    while let Some((dir, prefix)) = stack.pop() {
        let entries =
            std::fs::read_dir(&dir).with_context(|| format!("listing {}", dir.display()))?;
        for e in entries {
            let e = e.with_context(|| format!("listing {}", dir.display()))?;
            let name = e.file_name().to_string_lossy().into_owned();
            if name.starts_with('.') {
                continue;
            }
            let path = e.path();
            let rel = if prefix.is_empty() {
                name.clone()
            } else {
                format!("{prefix}/{name}")
            };
            let ft = e
                .file_type()
                .with_context(|| format!("reading {}", path.display()))?;
            if ft.is_dir() {
                if skip.iter().any(|s| same_file(&path, s)) {
                    continue;
                }
                if is_result_folder(&path) {
                    continue;
                }
                stack.push((path, rel));
            } else if ft.is_file() || (ft.is_symlink() && path.is_file()) {
                if is_supported_extension(&path) {
                    found.push(Photo { rel, path });
                } else {
                    ignored += 1;
                }
            }
        }
    }
    found.sort_by(|a, b| a.rel.as_bytes().cmp(b.rel.as_bytes()));
    Ok((found, ignored))
}

/// An earlier `picker batch` or `picker extract` result (see the module
/// docs): an output root with a batch report, or a photo's `*.material`
/// folder with its manifest or summary.
fn is_result_folder(dir: &Path) -> bool {
    let report = std::fs::read_dir(dir).is_ok_and(|entries| {
        entries.flatten().any(|e| {
            let n = e.file_name();
            let n = n.to_string_lossy();
            n.starts_with("batch-report") && n.ends_with(".json")
        })
    });
    let material = dir
        .file_name()
        .is_some_and(|n| n.to_string_lossy().ends_with(".material"))
        && (dir.join(MANIFEST).is_file() || dir.join("summary.json").is_file());
    report || material
}

fn same_file(a: &Path, b: &Path) -> bool {
    match (a.canonicalize(), b.canonicalize()) {
        (Ok(x), Ok(y)) => x == y,
        _ => false,
    }
}

/// Named picks per photo (relative path → `(name, [x, y])` in file order).
type Picks = BTreeMap<String, Vec<(String, [u32; 2])>>;

/// A photo's plane per photo (relative path → the quad and its real size in
/// metres, if given).
type Quads = BTreeMap<String, (Quad, Option<[f32; 2]>)>;

/// A photo's given plane normal (relative path → the plane, `--normals`).
type Normals = BTreeMap<String, UserPlane>;

/// The CSV reader `--picks`, `--quads` and `--normals` use: no required header,
/// rows of varying length, fields trimmed, `#` comments.
fn csv_reader(path: &Path, flag: &str) -> Result<csv::Reader<std::fs::File>> {
    csv::ReaderBuilder::new()
        .has_headers(false)
        .flexible(true)
        .trim(csv::Trim::All)
        .comment(Some(b'#'))
        .from_path(path)
        .map_err(|e| UsageError(format!("reading {flag} {}: {e}", path.display())).into())
}

/// A CSV row's photo, `/`-separated and relative to `IN_DIR`, or why not.
fn photo_field(field: &str) -> std::result::Result<String, String> {
    let file = field.replace('\\', "/");
    let file = file.trim_start_matches("./").to_string();
    if file.is_empty()
        || file.starts_with('/')
        || Path::new(&file).is_absolute()
        || file.split('/').any(|c| c == "..")
    {
        return Err(format!(
            "{field:?} must be a path inside IN_DIR (relative, no `..`)"
        ));
    }
    Ok(file)
}

/// Reads a CSV file of one row per photo (`--quads`, `--normals`): `file`
/// then `fields` (one of `lengths` fields in all), an optional header row
/// (`is_header`, first row only), each row's value made by `parse`; `what`
/// names the value in the error for a second row of one photo.
fn read_per_photo<T>(
    path: &Path,
    flag: &str,
    (lengths, fields): (&[usize], &str),
    what: &str,
    is_header: impl Fn(&csv::StringRecord) -> bool,
    parse: impl Fn(&csv::StringRecord) -> std::result::Result<T, String>,
) -> Result<BTreeMap<String, T>> {
    let usage = |msg: String| anyhow::Error::new(UsageError(msg));
    let mut out = BTreeMap::new();
    for (i, rec) in csv_reader(path, flag)?.records().enumerate() {
        let rec = rec.map_err(|e| usage(format!("{}: {e}", path.display())))?;
        let line = rec.position().map(|p| p.line()).unwrap_or(i as u64 + 1);
        if rec.iter().all(|f| f.is_empty()) {
            continue;
        }
        let at = |msg: String| usage(format!("{} line {line}: {msg}", path.display()));
        if i == 0 && rec.len() > 1 && is_header(&rec) {
            continue;
        }
        if !lengths.contains(&rec.len()) {
            return Err(at(format!(
                "expected file,{fields}, got {} fields",
                rec.len()
            )));
        }
        let file = photo_field(&rec[0]).map_err(at)?;
        let value = parse(&rec).map_err(at)?;
        if out.insert(file, value).is_some() {
            return Err(at(format!(
                "{:?} has a {what} already (one plane per photo)",
                &rec[0]
            )));
        }
    }
    Ok(out)
}

/// Reads `quads.csv`: rows `file,X1,Y1,X2,Y2,X3,Y3,X4,Y4[,WxH]`, an
/// optional header row, one row per photo.
fn read_quads(path: &Path) -> Result<Quads> {
    read_per_photo(
        path,
        "--quads",
        (&[9, 10], "X1,Y1,X2,Y2,X3,Y3,X4,Y4[,WxH]"),
        "quad",
        |rec| rec[1].parse::<f64>().is_err(),
        |rec| {
            let corners: Vec<&str> = rec.iter().skip(1).take(8).collect();
            let quad = crate::extract::parse_quad(&corners.join(","))?;
            let size = match rec.get(9).filter(|f| !f.is_empty()) {
                Some(f) => Some(crate::extract::parse_size_m(f)?),
                None => None,
            };
            Ok((quad, size))
        },
    )
}

/// Reads `normals.csv`: rows `file,front` or `file,X,Y,Z`, an optional header
/// row, one row per photo.
fn read_normals(path: &Path) -> Result<Normals> {
    read_per_photo(
        path,
        "--normals",
        (&[2, 4], "front or file,X,Y,Z"),
        "normal",
        // A header row: a first row that names no image and gives no value.
        |rec| {
            let value_like = |f: &str| f.eq_ignore_ascii_case("front") || f.parse::<f64>().is_ok();
            !is_supported_extension(Path::new(&rec[0])) && !value_like(&rec[1])
        },
        |rec| {
            let value: Vec<&str> = rec.iter().skip(1).collect();
            crate::extract::parse_normal(&value.join(","))
        },
    )
}

/// Reads `picks.csv`: rows `file,x,y[,name]`, an optional header row.
fn read_picks(path: &Path) -> Result<Picks> {
    let usage = |msg: String| anyhow::Error::new(UsageError(msg));
    let mut out = Picks::new();
    for (i, rec) in csv_reader(path, "--picks")?.records().enumerate() {
        let rec = rec.map_err(|e| usage(format!("{}: {e}", path.display())))?;
        let line = rec.position().map(|p| p.line()).unwrap_or(i as u64 + 1);
        if rec.iter().all(|f| f.is_empty()) {
            continue;
        }
        let at = |msg: String| usage(format!("{} line {line}: {msg}", path.display()));
        if !(3..=4).contains(&rec.len()) {
            return Err(at(format!(
                "expected file,x,y[,name], got {} fields",
                rec.len()
            )));
        }
        let (x, y) = (rec[1].parse::<u32>(), rec[2].parse::<u32>());
        if i == 0 && (x.is_err() || y.is_err()) && rec[1].parse::<f64>().is_err() {
            continue; // a header row
        }
        let coord = |v: std::result::Result<u32, _>, s: &str| {
            v.map_err(|_| {
                at(format!(
                    "{s:?} is not a pixel coordinate (a whole number ≥ 0)"
                ))
            })
        };
        let (x, y) = (coord(x, &rec[1])?, coord(y, &rec[2])?);
        let file = photo_field(&rec[0]).map_err(at)?;
        let entry = out.entry(file).or_default();
        let name = match rec.get(3).filter(|n| !n.is_empty()) {
            Some(n) => {
                let ok = !n.starts_with('.')
                    && n.len() <= 100
                    && n.chars()
                        .all(|c| c.is_ascii_alphanumeric() || "._-".contains(c));
                if !ok {
                    return Err(at(format!(
                        "name {n:?}: use letters, digits, `.`, `_` and `-` (not first `.`), at most 100"
                    )));
                }
                n.to_string()
            }
            None => format!("material_{}", entry.len()),
        };
        if entry.iter().any(|(m, _)| *m == name) {
            return Err(at(format!("name {name:?} is used twice for {}", &rec[0])));
        }
        entry.push((name, [x, y]));
    }
    Ok(out)
}

/// The extensions a mask in `--masks` may have, in the order they are
/// looked for.
const MASK_EXTENSIONS: [&str; 9] = [
    "png", "tif", "tiff", "webp", "bmp", "exr", "jpg", "jpeg", "hdr",
];

/// The mask of the photo `rel` (relative to IN_DIR) in `dir`: `dir/<rel
/// without its extension>.<ext>` for one of [`MASK_EXTENSIONS`]; `None`
/// when there is none; an error naming both when there are several.
fn mask_for(dir: &Path, rel: &str) -> std::result::Result<Option<PathBuf>, String> {
    let base = dir.join(Path::new(rel).with_extension(""));
    let found: Vec<PathBuf> = MASK_EXTENSIONS
        .iter()
        .map(|e| {
            let mut p = base.clone().into_os_string();
            p.push(".");
            p.push(e);
            PathBuf::from(p)
        })
        .filter(|p| p.is_file())
        .collect();
    match found.as_slice() {
        [] => Ok(None),
        [one] => Ok(Some(one.clone())),
        [a, b, ..] => Err(format!(
            "{rel}: two masks in --masks, {} and {}: keep one",
            a.display(),
            b.display()
        )),
    }
}

/// Lower-case hex SHA-256 of a file.
fn sha256_file(path: &Path) -> Result<String> {
    let mut f = std::fs::File::open(path).with_context(|| format!("opening {}", path.display()))?;
    let mut h = Sha256::new();
    let mut buf = vec![0u8; 1 << 16];
    loop {
        let n = f
            .read(&mut buf)
            .with_context(|| format!("reading {}", path.display()))?;
        if n == 0 {
            break;
        }
        h.update(&buf[..n]);
    }
    Ok(hex(&h.finalize()))
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// Every file under `dir` (relative, `/`-separated, sorted) with its size.
fn list_files(dir: &Path) -> Result<Vec<(String, u64)>> {
    let mut out = Vec::new();
    let mut stack = vec![(dir.to_path_buf(), String::new())];
    while let Some((d, prefix)) = stack.pop() {
        for e in std::fs::read_dir(&d).with_context(|| format!("listing {}", d.display()))? {
            let e = e.with_context(|| format!("listing {}", d.display()))?;
            let name = e.file_name().to_string_lossy().into_owned();
            let rel = if prefix.is_empty() {
                name
            } else {
                format!("{prefix}/{name}")
            };
            let md = e
                .metadata()
                .with_context(|| format!("reading {}", e.path().display()))?;
            if md.is_dir() {
                stack.push((e.path(), rel));
            } else {
                out.push((rel, md.len()));
            }
        }
    }
    out.sort();
    Ok(out)
}

const MANIFEST: &str = "manifest.json";

/// What a photo's outputs depend on; equal keys mean an up-to-date result.
fn manifest_key(
    input_sha: &str,
    weights: &[(String, String)],
    flags: &Flags,
    req: &Request,
    mask_sha: Option<&str>,
) -> Value {
    json!({
        "picker_version": env!("CARGO_PKG_VERSION"),
        "picker_build_sha256": build_sha256(),
        "input_sha256": input_sha,
        "weights_sha256": weights.iter().map(|(_, h)| h.clone()).collect::<Vec<_>>(),
        "settings": flags.output_settings(),
        "picks": req.picks.iter().map(|(n, p)| json!([n, p[0], p[1]])).collect::<Vec<_>>(),
        "all": req.all,
        "quad": req.quad.map(|q| q.0),
        "quad_size_m": req.quad_size_m,
        "normal": req.normal.map(|p| match p {
            UserPlane::Normal(n) => json!(n.to_array()),
            UserPlane::Quad(q) => json!(q.0),
        }),
        "mask_sha256": mask_sha,
        "quad_mask": req.mask == Some(extract::MaskArg::Quad),
    })
}

/// The SHA-256 of the running `picker` binary (read once), so that a batch
/// resumed with another build redoes every photo: the crate's version is not
/// bumped with every change to what extraction writes. `None` when the
/// binary cannot be read (the key then holds the version alone).
pub fn build_sha256() -> Option<&'static str> {
    static HASH: std::sync::OnceLock<Option<String>> = std::sync::OnceLock::new();
    HASH.get_or_init(|| {
        let exe = std::env::current_exe().ok()?;
        sha256_file(&exe).ok()
    })
    .as_deref()
}

/// True when `dir` holds a manifest with `key` and every file it lists, at its size.
fn up_to_date(dir: &Path, key: &Value) -> bool {
    let Ok(bytes) = std::fs::read(dir.join(MANIFEST)) else {
        return false;
    };
    let Ok(m) = serde_json::from_slice::<Value>(&bytes) else {
        return false;
    };
    if m.get("key") != Some(key) {
        return false;
    }
    let Some(files) = m.get("files").and_then(Value::as_array) else {
        return false;
    };
    files.iter().all(|f| {
        let (Some(p), Some(n)) = (f[0].as_str(), f[1].as_u64()) else {
            return false;
        };
        std::fs::metadata(dir.join(p))
            .map(|md| md.len() == n)
            .unwrap_or(false)
    })
}

/// How one photo ended.
#[derive(Clone, Debug)]
enum Outcome {
    Ok {
        materials: usize,
        seconds: f64,
        /// Each material's hints (`summary.json`, `materials[].hints`),
        /// prefixed with its name.
        hints: Vec<String>,
    },
    UpToDate,
    Skipped(String),
    Failed(String),
}

/// Shared state of the workers.
struct Shared<'a> {
    photos: Vec<(Photo, Request)>,
    next: AtomicUsize,
    results: Mutex<Vec<Option<Outcome>>>,
    stop: Arc<AtomicBool>,
    disk_full: AtomicBool,
    in_flight: Arc<Mutex<BTreeSet<PathBuf>>>,
    out: &'a Path,
    flags: &'a Flags,
    models: &'a Models,
    weights: &'a [(String, String)],
    inpainter: &'a dyn Inpainter,
    force: bool,
    progress: Progress,
}

/// The output folder of a photo and its hidden partial twin.
fn out_dirs(out: &Path, rel: &str) -> (PathBuf, PathBuf) {
    let target = out.join(format!("{rel}.material"));
    let name = target
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let partial = target.with_file_name(format!(".{name}.partial"));
    (target, partial)
}

fn remove_dir_if_exists(d: &Path) -> Result<()> {
    match std::fs::remove_dir_all(d) {
        Ok(()) => Ok(()),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
        Err(e) => Err(e).with_context(|| format!("removing {}", d.display())),
    }
}

fn process(s: &Shared<'_>, photo: &Photo, req: &Request) -> Result<Outcome> {
    let t = Instant::now();
    let (target, partial) = out_dirs(s.out, &photo.rel);
    // Read the photo once: hashed here, decoded from the same bytes. A file too
    // big to hold is streamed through the hash and refused by the decoder.
    let limits = s.flags.photo_limits();
    let size = std::fs::metadata(&photo.path)
        .with_context(|| format!("{}: reading the file's metadata", photo.path.display()))?
        .len();
    let bytes = if size <= limits.max_alloc {
        Some(
            std::fs::read(&photo.path)
                .with_context(|| format!("{}: reading the file", photo.path.display()))?,
        )
    } else {
        None
    };
    let input_sha = match &bytes {
        Some(b) => hex(&Sha256::digest(b)),
        None => sha256_file(&photo.path)?,
    };
    let mask_sha = match &req.mask {
        Some(extract::MaskArg::File(f)) => Some(sha256_file(f)?),
        _ => None,
    };
    let key = manifest_key(&input_sha, s.weights, s.flags, req, mask_sha.as_deref());
    if !s.force && up_to_date(&target, &key) {
        return Ok(Outcome::UpToDate);
    }
    remove_dir_if_exists(&partial)?;
    s.in_flight.lock().unwrap().insert(partial.clone());
    let result = (|| -> Result<(usize, Vec<String>)> {
        let loaded = extract::load_inputs_from(
            &Source::Nets(s.models),
            &photo.path,
            bytes,
            &photo.rel,
            s.flags,
        )?;
        let layout = Layout {
            always_subdirs: true,
            timings: false,
            shown_root: None,
        };
        let summary =
            extract::write_materials(&loaded, req, s.flags, s.inpainter, &partial, layout)?;
        let materials = summary["materials"].as_array().map_or(0, Vec::len);
        let hints = summary_hints(&summary);
        let files = list_files(&partial)?;
        let manifest = json!({
            "format": "material-picker-batch-manifest",
            "format_version": 1,
            "key": key,
            "input": {"path": photo.rel, "sha256": input_sha},
            "weights": s.weights.iter().map(|(f, h)| json!({"file": f, "sha256": h})).collect::<Vec<_>>(),
            "files": files.iter().map(|(f, n)| json!([f, n])).collect::<Vec<_>>(),
        });
        let text = serde_json::to_string_pretty(&manifest).context("serialising the manifest")?;
        crate::output::write_atomic(&partial.join(MANIFEST), format!("{text}\n").as_bytes())?;
        remove_dir_if_exists(&target)?;
        std::fs::rename(&partial, &target)
            .with_context(|| format!("renaming {} to {}", partial.display(), target.display()))?;
        if let Some(parent) = target.parent() {
            if let Ok(d) = std::fs::File::open(parent) {
                let _ = d.sync_all();
            }
        }
        Ok((materials, hints))
    })();
    s.in_flight.lock().unwrap().remove(&partial);
    match result {
        Ok((materials, hints)) => Ok(Outcome::Ok {
            materials,
            seconds: t.elapsed().as_secs_f64(),
            hints,
        }),
        Err(e) => {
            let _ = remove_dir_if_exists(&partial);
            Err(e)
        }
    }
}

/// Every material's hints in a photo's `summary.json`
/// (`materials[].hints`), each prefixed with the material's name.
fn summary_hints(summary: &Value) -> Vec<String> {
    summary["materials"]
        .as_array()
        .into_iter()
        .flatten()
        .flat_map(|m| {
            let name = m["name"].as_str().unwrap_or("?").to_string();
            m["hints"]
                .as_array()
                .into_iter()
                .flatten()
                .map(move |h| format!("{name}: {}", h.as_str().unwrap_or("?")))
        })
        .collect()
}

/// True when an error comes from a full disk (or quota), where every later
/// photo would fail the same way.
fn is_disk_full(e: &anyhow::Error) -> bool {
    e.chain().any(|c| {
        c.downcast_ref::<std::io::Error>().is_some_and(|io| {
            matches!(
                io.kind(),
                std::io::ErrorKind::StorageFull | std::io::ErrorKind::QuotaExceeded
            )
        })
    })
}

fn worker(s: &Shared<'_>) {
    loop {
        if s.stop.load(Ordering::SeqCst) {
            return;
        }
        let i = s.next.fetch_add(1, Ordering::SeqCst);
        let Some((photo, req)) = s.photos.get(i) else {
            return;
        };
        let outcome = if req.picks.is_empty() && !req.all && req.mask.is_none() {
            Outcome::Skipped("no picks for this photo in --picks, --quads or --masks".into())
        } else {
            match std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| process(s, photo, req)))
            {
                Ok(Ok(o)) => o,
                Ok(Err(e)) => {
                    if is_disk_full(&e) && !s.stop.swap(true, Ordering::SeqCst) {
                        s.disk_full.store(true, Ordering::SeqCst);
                        s.progress.note(
                            "the output disk is full: stopping (photos in progress finish or fail); free some space and run the same command again to resume",
                        );
                    }
                    Outcome::Failed(crate::one_line(&e))
                }
                Err(p) => {
                    let msg = p
                        .downcast_ref::<&str>()
                        .map(|s| s.to_string())
                        .or_else(|| p.downcast_ref::<String>().cloned())
                        .unwrap_or_else(|| "unknown panic".into());
                    Outcome::Failed(format!(
                        "{}: internal error (a bug, please report it): {msg}",
                        photo.path.display()
                    ))
                }
            }
        };
        s.progress.done(&photo.rel, &outcome);
        s.results.lock().unwrap()[i] = Some(outcome);
    }
}

/// A progress bar on a terminal, plain lines otherwise, nothing with --quiet.
struct Progress {
    bar: Option<indicatif::ProgressBar>,
    lines: bool,
    total: usize,
    count: AtomicUsize,
}

impl Progress {
    fn new(total: usize, quiet: bool) -> Self {
        let tty = std::io::stderr().is_terminal();
        let bar = (!quiet && tty).then(|| {
            let b = indicatif::ProgressBar::new(total as u64);
            b.set_style(
                indicatif::ProgressStyle::with_template(
                    "{elapsed_precise} [{bar:30}] {pos}/{len} photos, ETA {eta} {msg}",
                )
                .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar())
                .progress_chars("=> "),
            );
            b
        });
        Self {
            bar,
            lines: !quiet && !tty,
            total,
            count: AtomicUsize::new(0),
        }
    }

    fn done(&self, rel: &str, o: &Outcome) {
        let k = self.count.fetch_add(1, Ordering::SeqCst) + 1;
        let what = match o {
            Outcome::Ok {
                materials,
                seconds,
                hints,
            } => {
                let mut line = format!("ok      {rel} (materials: {materials}, {seconds:.1} s)");
                for h in hints {
                    line.push_str(&format!("\n        hint: {rel}: {h}"));
                }
                line
            }
            Outcome::UpToDate => format!("done    {rel} (up to date)"),
            Outcome::Skipped(r) => format!("skipped {rel}: {r}"),
            Outcome::Failed(r) => format!("FAILED  {rel}: {r}"),
        };
        if let Some(b) = &self.bar {
            let hinted = matches!(o, Outcome::Ok { hints, .. } if !hints.is_empty());
            if matches!(o, Outcome::Failed(_)) || hinted {
                b.println(what);
            }
            b.set_message(rel.to_string());
            b.inc(1);
        } else if self.lines {
            eprintln!("[{k}/{}] {what}", self.total);
        }
    }

    fn note(&self, msg: &str) {
        match &self.bar {
            Some(b) => b.println(msg),
            None => eprintln!("{msg}"),
        }
    }

    fn finish(&self) {
        if let Some(b) = &self.bar {
            b.finish_and_clear();
        }
    }
}

/// How the threads are split: `(jobs, kernel threads per job)`.
pub fn split_threads(total: usize, jobs: Option<u32>) -> (usize, usize) {
    let total = total.max(1);
    let jobs = jobs.map(|j| j as usize).unwrap_or((total / 4).max(1));
    (jobs, (total / jobs).max(1))
}

/// Runs `picker batch`.
pub fn run(a: Args) -> Result<ExitCode> {
    let t0 = Instant::now();
    let usage = |msg: String| anyhow::Error::new(UsageError(msg));
    a.flags.validate().map_err(|e| usage(e.to_string()))?;
    if a.picks.is_none() && !a.all && a.quads.is_none() && a.masks.is_none() {
        return Err(usage(
            "nothing to extract: give --picks picks.csv, --quads quads.csv, --masks MASK_DIR and/or --all"
                .into(),
        ));
    }
    if a.quads.is_some() && a.flags.uv == crate::extract::UvArg::Net {
        return Err(usage(
            "--quads gives the planes to rectify: it cannot be used with --uv net".into(),
        ));
    }
    if a.normals.is_some() && a.flags.uv == crate::extract::UvArg::Net {
        return Err(usage(
            "--normals gives the planes to rectify: it cannot be used with --uv net".into(),
        ));
    }
    if !a.in_dir.is_dir() {
        return Err(usage(format!("{}: not a folder", a.in_dir.display())));
    }
    let mut picks = match &a.picks {
        Some(p) => read_picks(p)?,
        None => BTreeMap::new(),
    };
    let quads = match &a.quads {
        Some(p) => read_quads(p)?,
        None => BTreeMap::new(),
    };
    let normals = match &a.normals {
        Some(p) => read_normals(p)?,
        None => BTreeMap::new(),
    };
    if let Some(file) = normals.keys().find(|f| quads.contains_key(*f)) {
        return Err(usage(format!(
            "{file}: has both a quad in --quads and a normal in --normals (one plane per photo)"
        )));
    }
    let in_picks_csv: BTreeSet<String> = picks.keys().cloned().collect();
    if let Some(m) = &a.masks {
        if !m.is_dir() {
            return Err(usage(format!("--masks {}: not a folder", m.display())));
        }
    }
    let mask_of = |rel: &str| match &a.masks {
        Some(dir) => mask_for(dir, rel).map_err(usage),
        None => Ok(None),
    };
    // A quad gives one material's plane: its photo's one pick, or its
    // centre (unless a mask gives the material).
    for (file, (q, _)) in &quads {
        let masked = a.quad_masks || mask_of(file)?.is_some();
        let entry = picks.entry(file.clone()).or_default();
        match entry.len() {
            0 if masked => {}
            0 => entry.push(("material_0".into(), q.centre_pixel())),
            1 => {}
            n => {
                return Err(usage(format!(
                    "{file}: a quad in --quads gives the plane of one material, but --picks has {n} picks for it"
                )))
            }
        }
    }
    // The report is written last: refuse a path it cannot go to now, not
    // after every photo.
    if let Some(r) = &a.report {
        if r.is_dir() {
            return Err(usage(format!(
                "--report {}: is a folder; give the report's file name",
                r.display()
            )));
        }
    }
    std::fs::create_dir_all(&a.out)
        .with_context(|| format!("creating output folder {}", a.out.display()))?;
    let mut skip: Vec<&Path> = vec![&a.out];
    skip.extend(a.masks.as_deref());
    let (all_photos, ignored) = discover(&a.in_dir, &skip)?;
    let total_found = all_photos.len();
    let known: BTreeSet<&str> = all_photos.iter().map(|p| p.rel.as_str()).collect();
    // Picks for files that are not there fail loudly instead of vanishing.
    let mut missing: Vec<(String, String)> = picks
        .keys()
        .filter(|f| !known.contains(f.as_str()))
        .filter(|f| a.shard.is_none_or(|(k, n)| shard_of(f, n) == k))
        .map(|f| {
            let p = a.in_dir.join(f);
            let list = if in_picks_csv.contains(f) {
                "--picks"
            } else {
                "--quads"
            };
            let why = if p.exists() {
                format!("listed in {list} but not a supported image (by extension) under IN_DIR")
            } else {
                format!("listed in {list} but not found under IN_DIR")
            };
            (f.clone(), format!("{}: {why}", p.display()))
        })
        .collect();
    // Normals for files that are not there, likewise.
    missing.extend(
        normals
            .keys()
            .filter(|f| !known.contains(f.as_str()) && !picks.contains_key(*f))
            .filter(|f| a.shard.is_none_or(|(k, n)| shard_of(f, n) == k))
            .map(|f| {
                let p = a.in_dir.join(f);
                let why = if p.exists() {
                    "listed in --normals but not a supported image (by extension) under IN_DIR"
                } else {
                    "listed in --normals but not found under IN_DIR"
                };
                (f.clone(), format!("{}: {why}", p.display()))
            }),
    );
    missing.sort();
    let photos: Vec<(Photo, Request)> = all_photos
        .into_iter()
        .filter(|p| a.shard.is_none_or(|(k, n)| shard_of(&p.rel, n) == k))
        .map(|p| -> Result<(Photo, Request)> {
            let mask = mask_of(&p.rel)?;
            let quad_mask = a.quad_masks && mask.is_none() && quads.contains_key(&p.rel);
            let n = picks.get(&p.rel).map_or(0, Vec::len);
            if mask.is_some() && n > 1 {
                return Err(usage(format!(
                    "{}: a mask in --masks gives the pixels of one material, but --picks has {n} picks for it",
                    p.rel
                )));
            }
            let req = Request {
                picks: picks.get(&p.rel).cloned().unwrap_or_default(),
                all: a.all,
                quad: quads.get(&p.rel).map(|q| q.0),
                quad_size_m: quads.get(&p.rel).and_then(|q| q.1),
                normal: normals.get(&p.rel).copied(),
                mask_label: mask.as_ref().and_then(|m| {
                    let dir = a.masks.as_deref()?;
                    let rel = m.strip_prefix(dir).ok()?;
                    Some(format!("MASK_DIR/{}", rel.display()).replace('\\', "/"))
                }),
                mask: match (mask, quad_mask) {
                    (Some(m), _) => Some(extract::MaskArg::File(m)),
                    (None, true) => Some(extract::MaskArg::Quad),
                    (None, false) => None,
                },
            };
            Ok((p, req))
        })
        .collect::<Result<_>>()?;

    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    // At most MAX_PER_CORE threads (and jobs) per logical core, as elsewhere.
    let (threads, warning) = crate::threads::capped(a.threads, cores);
    if let Some(w) = warning {
        eprintln!("{w}");
    }
    let total_threads = threads.unwrap_or(cores);
    let max_jobs = crate::threads::MAX_PER_CORE * cores;
    if a.jobs.is_some_and(|j| j as usize > max_jobs) {
        eprintln!(
            "warning: --jobs {} is more than {} per logical core ({cores} here); using {max_jobs}",
            a.jobs.unwrap_or_default(),
            crate::threads::MAX_PER_CORE
        );
    }
    let (jobs, per_job) = split_threads(total_threads, a.jobs.map(|j| j.min(max_jobs as u32)));
    let jobs = jobs.min(photos.len().max(1));

    let models = Models::load(&a.flags.weights)?.with_mirror_pass(!a.flags.single_pass);
    let weights: Vec<(String, String)> = models
        .paths()
        .into_iter()
        .zip(models.embedded_bytes())
        .map(|(p, embedded)| {
            let digest = match embedded {
                Some(bytes) => hex(&Sha256::digest(bytes)),
                None => sha256_file(p)?,
            };
            Ok((p.display().to_string(), digest))
        })
        .collect::<Result<_>>()?;
    let inpainter = extract::inpainter(&a.flags.inpainter)?;

    let stop = Arc::new(AtomicBool::new(false));
    let in_flight: Arc<Mutex<BTreeSet<PathBuf>>> = Arc::default();
    {
        let (stop, in_flight) = (stop.clone(), in_flight.clone());
        let signals = AtomicUsize::new(0);
        // Installing fails only when a handler exists already (tests calling run twice).
        let _ = ctrlc::set_handler(move || {
            if signals.fetch_add(1, Ordering::SeqCst) == 0 {
                stop.store(true, Ordering::SeqCst);
                eprintln!(
                    "\ninterrupted: finishing the photos in progress (interrupt again to stop now)"
                );
            } else {
                for d in in_flight.lock().map(|s| s.clone()).unwrap_or_default() {
                    crate::staging::remove_while_written(&d);
                }
                eprintln!("\nstopped; run the same command again to resume");
                std::process::exit(130);
            }
        });
    }

    let n = photos.len();
    if !a.quiet {
        eprintln!(
            "picker batch: {n} photos{} ({} found, {ignored} other files ignored), {jobs} jobs × {per_job} threads",
            a.shard.map(|(k, s)| format!(" in shard {k}/{s}")).unwrap_or_default(),
            total_found,
        );
    }
    let shared = Shared {
        photos,
        next: AtomicUsize::new(0),
        results: Mutex::new(vec![None; n]),
        stop: stop.clone(),
        disk_full: AtomicBool::new(false),
        in_flight,
        out: &a.out,
        flags: &a.flags,
        models: &models,
        weights: &weights,
        inpainter: inpainter.as_ref(),
        force: a.force,
        progress: Progress::new(n, a.quiet),
    };
    std::thread::scope(|scope| -> Result<()> {
        let mut handles = Vec::new();
        for j in 0..jobs {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(per_job)
                .thread_name(move |i| format!("picker-job{j}-{i}"))
                .build()
                .context("setting up the thread pools")?;
            let shared = &shared;
            handles.push(scope.spawn(move || pool.install(|| worker(shared))));
        }
        for h in handles {
            h.join()
                .map_err(|_| anyhow!("a batch worker thread panicked"))?;
        }
        Ok(())
    })?;
    shared.progress.finish();

    let results = shared.results.into_inner().unwrap_or_default();
    let disk_full = shared.disk_full.load(Ordering::SeqCst);
    let interrupted = stop.load(Ordering::SeqCst) && !disk_full;
    let mut rows = Vec::new();
    let (mut ok, mut fresh, mut failed, mut skipped, mut not_started) = (0, 0, 0, 0, 0);
    for ((photo, _), r) in shared.photos.iter().zip(&results) {
        let (status, extra) = match r {
            Some(Outcome::Ok {
                materials,
                seconds,
                hints,
            }) => {
                ok += 1;
                let mut extra = json!({"materials": materials, "seconds": seconds});
                if !hints.is_empty() {
                    extra["hints"] = json!(hints);
                }
                ("ok", extra)
            }
            Some(Outcome::UpToDate) => {
                fresh += 1;
                ("up_to_date", json!({}))
            }
            Some(Outcome::Skipped(why)) => {
                skipped += 1;
                ("skipped", json!({"reason": why}))
            }
            Some(Outcome::Failed(why)) => {
                failed += 1;
                ("failed", json!({"reason": why}))
            }
            None => {
                not_started += 1;
                (
                    "not_started",
                    json!({"reason": "interrupted before it started"}),
                )
            }
        };
        let mut row = json!({"photo": photo.rel, "status": status});
        if matches!(status, "ok" | "up_to_date") {
            row["out"] = json!(format!("{}.material", photo.rel));
        }
        if let (Some(o), Some(e)) = (row.as_object_mut(), extra.as_object()) {
            o.extend(e.clone());
        }
        rows.push(row);
    }
    for (f, why) in &missing {
        failed += 1;
        rows.push(json!({"photo": f, "status": "failed", "reason": why}));
    }
    let elapsed = t0.elapsed().as_secs_f64();
    let report = json!({
        "format": "material-picker-batch-report",
        "format_version": 1,
        "picker_version": env!("CARGO_PKG_VERSION"),
        "in_dir": a.in_dir.display().to_string(),
        "out_dir": a.out.display().to_string(),
        "shard": a.shard.map(|(k, n)| format!("{k}/{n}")),
        "jobs": jobs,
        "threads_per_job": per_job,
        "interrupted": interrupted,
        "disk_full": disk_full,
        "counts": {"photos": rows.len(), "ok": ok, "up_to_date": fresh, "failed": failed, "skipped": skipped, "not_started": not_started},
        "seconds": elapsed,
        "photos": rows,
    });
    let report_path = a.report.clone().unwrap_or_else(|| {
        a.out.join(match a.shard {
            Some((k, n)) => format!("batch-report.shard-{k}-of-{n}.json"),
            None => "batch-report.json".into(),
        })
    });
    eprintln!(
        "{} photos: {ok} ok, {fresh} up to date, {failed} failed, {skipped} skipped{} in {elapsed:.1} s; report: {}",
        rows.len(),
        if not_started > 0 {
            format!(", {not_started} not started")
        } else {
            String::new()
        },
        report_path.display()
    );
    for r in &rows {
        if r["status"] == "failed" {
            eprintln!(
                "  failed: {}",
                r["reason"].as_str().unwrap_or("unknown reason")
            );
        }
    }
    // After the summary, so a full disk still shows what happened.
    let text = serde_json::to_string_pretty(&report).context("serialising the batch report")?;
    crate::output::write_atomic(&report_path, format!("{text}\n").as_bytes())?;
    Ok(if interrupted {
        ExitCode::from(130)
    } else if failed > 0 || disk_full {
        ExitCode::from(1)
    } else {
        ExitCode::SUCCESS
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hints_are_gathered_from_the_summary_with_their_material() {
        let summary = json!({"materials": [
            {"name": "material_0"},
            {"name": "material_1", "hints": ["a", "b"]},
            {"name": "material_2", "hints": []},
            {"name": "material_3", "hints": ["c"]},
        ]});
        assert_eq!(
            summary_hints(&summary),
            ["material_1: a", "material_1: b", "material_3: c"]
        );
        assert!(summary_hints(&json!({})).is_empty());
    }

    #[test]
    fn earlier_results_inside_the_input_are_not_photos() {
        let tmp = tempfile::tempdir().unwrap();
        let root = tmp.path();
        let touch = |p: &str| {
            let p = root.join(p);
            std::fs::create_dir_all(p.parent().unwrap()).unwrap();
            std::fs::write(p, b"x").unwrap();
        };
        touch("a.png");
        touch("sub/b.jpg");
        // An earlier batch's output root, and photos' result folders.
        touch("old/batch-report.json");
        touch("old/a.png.material/material_0/texture.png");
        touch("c.material/summary.json");
        touch("c.material/texture.png");
        touch("d.material/manifest.json");
        touch("d.material/preview.png");
        // A folder merely named like one, without a result in it.
        touch("e.material/photo.png");
        let (found, _) = discover(root, &[]).unwrap();
        let rel: Vec<&str> = found.iter().map(|p| p.rel.as_str()).collect();
        assert_eq!(rel, ["a.png", "e.material/photo.png", "sub/b.jpg"]);
    }

    #[test]
    fn shard_parsing() {
        assert_eq!(parse_shard("0/4"), Ok((0, 4)));
        assert_eq!(parse_shard(" 3 / 4 "), Ok((3, 4)));
        assert!(parse_shard("4/4").unwrap_err().contains("0 ≤ K < N"));
        assert!(parse_shard("1/0").is_err());
        assert!(parse_shard("1").is_err());
        assert!(parse_shard("a/2").is_err());
    }

    #[test]
    fn shards_partition_and_are_stable() {
        let names: Vec<String> = (0..1000)
            .map(|i| format!("dir{}/photo_{i}.jpg", i % 7))
            .collect();
        for n in [1u64, 2, 3, 8] {
            let mut counts = vec![0usize; n as usize];
            for s in &names {
                counts[shard_of(s, n) as usize] += 1;
            }
            assert_eq!(counts.iter().sum::<usize>(), names.len());
            // Roughly even: no shard gets under half its share.
            for c in counts {
                assert!(c * 2 * n as usize >= names.len(), "{n}: {c}");
            }
        }
        // Fixed values: the partition must not change between versions.
        assert_eq!(shard_of("a.jpg", 1000), shard_of("a.jpg", 1000));
        assert_eq!(shard_of("", 7), 0xcbf2_9ce4_8422_2325u64 % 7);
    }

    #[test]
    fn thread_split() {
        assert_eq!(split_threads(2, None), (1, 2));
        assert_eq!(split_threads(16, None), (4, 4));
        assert_eq!(split_threads(16, Some(16)), (16, 1));
        assert_eq!(split_threads(4, Some(8)), (8, 1));
        assert_eq!(split_threads(0, None), (1, 1));
    }

    #[test]
    fn quads_csv() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("quads.csv");
        std::fs::write(
            &p,
            "file,x1,y1,x2,y2,x3,y3,x4,y4,size\n# a comment\na.jpg,10,20,200,30,190,150,15,140\n\
             sub/b.png, 1.5,2,50,2,50,40,1.5,40 ,210x297mm\n\"c,d.jpg\",0,0,9,0,9,9,0,9,\n",
        )
        .unwrap();
        let m = read_quads(&p).unwrap();
        assert_eq!(m.len(), 3);
        assert_eq!(m["a.jpg"].0 .0[1], [200.0, 30.0]);
        assert_eq!(m["a.jpg"].1, None);
        assert_eq!(m["sub/b.png"].0 .0[0], [1.5, 2.0]);
        assert_eq!(m["sub/b.png"].1, Some([0.21, 0.297]));
        assert_eq!(m["c,d.jpg"].1, None);
        for (bad, want) in [
            ("a.jpg,1,2,3,4,5,6,7\n", "got 8 fields"),
            ("a.jpg,1,2,3,4,5,6,7,8,1x1,extra\n", "11 fields"),
            ("a.jpg,0,0,9,0,9,9,0,9\nb.jpg,0,0,9,0,9,x,0,9\n", "line 2"),
            ("a.jpg,0,0,9,0,9,nan,0,9\n", "line 1"),
            ("a.jpg,0,0,9,0,9,9,0,9,30cm\n", "expected WxH"),
            ("a.jpg,0,0,9,0,9,9,0,9,0x1\n", "not a positive size"),
            ("../a.jpg,0,0,9,0,9,9,0,9\n", "inside IN_DIR"),
            (
                "a.jpg,0,0,9,0,9,9,0,9\n./a.jpg,0,0,8,0,8,8,0,8\n",
                "one plane per photo",
            ),
        ] {
            std::fs::write(&p, bad).unwrap();
            let e = read_quads(&p).unwrap_err();
            assert!(e.downcast_ref::<UsageError>().is_some());
            let msg = format!("{e:#}");
            assert!(
                msg.contains(want) && msg.contains("quads.csv"),
                "{bad:?}: {msg}"
            );
        }
    }

    #[test]
    fn normals_csv() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("normals.csv");
        std::fs::write(
            &p,
            "file,normal\n# a comment\na.jpg,front\nsub/b.png, 0,1, 0.2\n\"c,d.jpg\",FRONT\n",
        )
        .unwrap();
        let m = read_normals(&p).unwrap();
        assert_eq!(m.len(), 3);
        let n = |f: &str| match m[f] {
            UserPlane::Normal(n) => n,
            UserPlane::Quad(_) => panic!("{f}: a quad"),
        };
        assert_eq!(n("a.jpg"), glam::Vec3::Z);
        assert!((n("sub/b.png") - glam::Vec3::new(0.0, 1.0, 0.2).normalize()).length() < 1e-6);
        assert_eq!(n("c,d.jpg"), glam::Vec3::Z);
        for (bad, want) in [
            ("a.jpg\n", "got 1 fields"),
            ("a.jpg,1,2\n", "got 3 fields"),
            ("a.jpg,front\nb.jpg,0,0,0\n", "line 2"),
            ("a.jpg,sideways\n", "line 1"),
            ("../a.jpg,front\n", "inside IN_DIR"),
            ("a.jpg,front\n./a.jpg,0,0,1\n", "one plane per photo"),
        ] {
            std::fs::write(&p, bad).unwrap();
            let e = read_normals(&p).unwrap_err();
            assert!(e.downcast_ref::<UsageError>().is_some());
            let msg = format!("{e:#}");
            assert!(
                msg.contains(want) && msg.contains("normals.csv"),
                "{bad:?}: {msg}"
            );
        }
    }

    #[test]
    fn picks_csv() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("picks.csv");
        std::fs::write(
            &p,
            "file,x,y,name\n# a comment\na.jpg,1,2\nsub/b.png, 3 , 4 ,floor\n\"c,d.jpg\",5,6\na.jpg,7,8,wall\n",
        )
        .unwrap();
        let m = read_picks(&p).unwrap();
        assert_eq!(
            m["a.jpg"],
            vec![("material_0".into(), [1, 2]), ("wall".into(), [7, 8])]
        );
        assert_eq!(m["sub/b.png"], vec![("floor".into(), [3, 4])]);
        assert_eq!(m["c,d.jpg"], vec![("material_0".into(), [5, 6])]);
        for (bad, want) in [
            ("a.jpg,1\n", "fields"),
            ("a.jpg,1,2\na.jpg,x,2\n", "line 2"),
            ("../a.jpg,1,2\n", "inside IN_DIR"),
            ("a.jpg,1,2,../x\n", "name"),
            ("a.jpg,1,2,n\na.jpg,3,4,n\n", "twice"),
        ] {
            std::fs::write(&p, bad).unwrap();
            let e = read_picks(&p).unwrap_err();
            assert!(e.downcast_ref::<UsageError>().is_some());
            let msg = format!("{e:#}");
            assert!(
                msg.contains(want) && msg.contains("picks.csv"),
                "{bad:?}: {msg}"
            );
        }
    }
}
