//! All of a `picker extract` run's files, or none of them.
//!
//! Every file is written atomically (temporary file + rename), but a run
//! writes a dozen of them: a run that fails half-way (a full disk, a
//! material that cannot be extracted after another one was) or is
//! interrupted would leave some of the new files beside older ones. So a run
//! writes into a hidden staging folder inside `--out` (the same file system,
//! so moving is a rename), and only when everything is written moves the
//! entries into place, `summary.json` last (an older `summary.json` is
//! removed first, so a set without one is never taken for a finished run).
//! On an error, or on Ctrl-C / SIGTERM, the staging folder is removed, and
//! so is `--out` itself when this run created it and it is empty. Staging
//! folders of killed runs (`SIGKILL`) are removed by the next run into the
//! same folder (Linux: when their process no longer exists).

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};

/// Prefix of a staging folder's name; the process id follows.
const PREFIX: &str = ".picker-partial-";

/// Held while [`Staging::begin`] makes the folders, and by the interrupt
/// handler before it removes them, so an interrupt never removes the staging
/// folder before it is made and lets it be made after.
static MAKING: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// Removes the folder `dir` that other threads may still be writing into
/// (an interrupt handler's cleanup): a file made while it is being removed
/// can make one removal fail, so it is retried for up to a second.
pub fn remove_while_written(dir: &Path) {
    for _ in 0..200 {
        let _ = std::fs::remove_dir_all(dir);
        if !dir.exists() {
            return;
        }
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
}

/// `picker extract`'s file moved into place last.
pub const SUMMARY: &str = "summary.json";

/// A staging folder inside the output folder (see the module docs).
#[derive(Debug)]
pub struct Staging {
    out: PathBuf,
    dir: PathBuf,
    last: &'static str,
    created_out: bool,
    done: bool,
}

impl Staging {
    /// Creates `out` if needed (refusing a path that exists and is not a
    /// folder), removes stale staging folders of dead processes, and makes
    /// this run's staging folder; `last` is the file that marks a finished
    /// set (moved last, an older one removed first). With `on_signal`, an
    /// interrupt removes the staging folder (and `out`, if it was made here
    /// and is empty) and exits with status 130.
    pub fn begin(out: &Path, last: &'static str, on_signal: bool) -> Result<Staging> {
        if out.exists() && !out.is_dir() {
            bail!("{}: --out exists and is not a folder", out.display());
        }
        let created_out = !out.exists();
        let dir = out.join(format!("{PREFIX}{}", std::process::id()));
        if on_signal {
            // Installed before the folders are made, so that no interrupt
            // can find the staging folder without the handler that removes
            // it (removing what does not exist yet is a no-op). Installing
            // fails only when a handler exists already (a second run in one
            // process, as in tests): then an interrupt just stops.
            let (d, o) = (dir.clone(), out.to_path_buf());
            let _ = ctrlc::set_handler(move || {
                // Not while `begin` makes the folders (it holds the lock).
                let _making = MAKING.lock();
                remove_while_written(&d);
                if created_out {
                    let _ = std::fs::remove_dir(&o);
                }
                eprintln!("\ninterrupted: no result written");
                std::process::exit(130);
            });
        }
        let _making = MAKING.lock();
        std::fs::create_dir_all(out)
            .with_context(|| format!("creating output folder {}", out.display()))?;
        remove_stale(out);
        if dir.exists() {
            std::fs::remove_dir_all(&dir)
                .with_context(|| format!("{}: removing an old staging folder", dir.display()))?;
        }
        if let Err(e) = std::fs::create_dir(&dir) {
            if created_out {
                let _ = std::fs::remove_dir(out);
            }
            return Err(e).with_context(|| format!("{}: creating a staging folder", dir.display()));
        }
        Ok(Staging {
            out: out.to_path_buf(),
            dir,
            last,
            created_out,
            done: false,
        })
    }

    /// Where the run writes its files.
    pub fn path(&self) -> &Path {
        &self.dir
    }

    /// `e` with the staging folder's path in its message replaced by the
    /// output folder's, so that a failure names the file the user asked for
    /// (`OUT/report.png: cannot write: No space left on device`).
    pub fn in_out(&self, e: anyhow::Error) -> anyhow::Error {
        let (from, to) = (
            self.dir.display().to_string(),
            self.out.display().to_string(),
        );
        let text = crate::one_line(&e);
        if text.contains(&from) {
            anyhow::Error::msg(text.replace(&from, &to))
        } else {
            e
        }
    }

    /// Moves every staged entry into the output folder, replacing entries of
    /// the same name and kind, `summary.json` last. Refuses, before moving
    /// anything, when an entry would replace one of the other kind (a file
    /// where a folder is, or the reverse).
    ///
    /// Runs into the same folder commit one at a time: the folder is locked
    /// (an advisory `flock` on the folder itself, where the platform allows
    /// one; released when the move is done or the process ends), so two
    /// runs that finish together leave one run's whole set, never a mix.
    pub fn commit(mut self) -> Result<()> {
        let lock = std::fs::File::open(&self.out).ok();
        if let Some(l) = &lock {
            // A platform or file system without folder locks moves unlocked.
            let _ = l.lock();
        }
        let mut names: Vec<std::ffi::OsString> = std::fs::read_dir(&self.dir)
            .with_context(|| format!("{}: reading the staging folder", self.dir.display()))?
            .map(|e| e.map(|e| e.file_name()))
            .collect::<std::io::Result<_>>()
            .with_context(|| format!("{}: reading the staging folder", self.dir.display()))?;
        // The `last` file last, the rest in a fixed order.
        names.sort_by_key(|n| (n == self.last, n.clone()));
        for n in &names {
            let (src, dst) = (self.dir.join(n), self.out.join(n));
            let Ok(meta) = std::fs::symlink_metadata(&dst) else {
                continue;
            };
            if meta.is_dir() != src.is_dir() {
                bail!(
                    "{}: is a {}, where this run writes a {}; nothing was written (move it away or choose another --out)",
                    dst.display(),
                    kind(meta.is_dir()),
                    kind(src.is_dir()),
                );
            }
        }
        let last = self.out.join(self.last);
        if last.is_file() {
            std::fs::remove_file(&last)
                .with_context(|| format!("{}: removing the older summary", last.display()))?;
        }
        for n in &names {
            let (src, dst) = (self.dir.join(n), self.out.join(n));
            if src.is_dir() && dst.is_dir() {
                std::fs::remove_dir_all(&dst)
                    .with_context(|| format!("{}: removing the older folder", dst.display()))?;
            }
            std::fs::rename(&src, &dst)
                .with_context(|| format!("{}: moving the result into place", dst.display()))?;
        }
        std::fs::remove_dir(&self.dir)
            .with_context(|| format!("{}: removing the staging folder", self.dir.display()))?;
        if let Some(d) = &lock {
            let _ = d.sync_all();
        }
        self.done = true;
        Ok(())
    }
}

impl Drop for Staging {
    /// A run that did not commit leaves nothing: the staging folder goes,
    /// and so does `--out` when this run made it and it is empty.
    fn drop(&mut self) {
        if !self.done {
            let _ = std::fs::remove_dir_all(&self.dir);
            if self.created_out {
                let _ = std::fs::remove_dir(&self.out);
            }
        }
    }
}

fn kind(dir: bool) -> &'static str {
    if dir {
        "folder"
    } else {
        "file"
    }
}

/// Removes the staging folders in `out` whose process is gone (Linux, where
/// `/proc/PID` tells; elsewhere none is removed).
fn remove_stale(out: &Path) {
    remove_dead_partials(out, |n| n.strip_prefix(PREFIX));
}

/// Removes the folders in `out` that a run left while writing and whose
/// process is gone (Linux, where `/proc/PID` tells; elsewhere none):
/// `pid_of` gives the process id's text from an entry's name, `None` for
/// entries that are not such folders.
pub fn remove_dead_partials(out: &Path, pid_of: impl Fn(&str) -> Option<&str>) {
    let Ok(entries) = std::fs::read_dir(out) else {
        return;
    };
    for e in entries.flatten() {
        let name = e.file_name();
        let Some(pid) = name
            .to_str()
            .and_then(&pid_of)
            .and_then(|p| p.parse::<u32>().ok())
        else {
            continue;
        };
        if pid != std::process::id() && process_gone(pid) {
            let _ = std::fs::remove_dir_all(e.path());
        }
    }
}

/// True when process `pid` surely no longer exists.
fn process_gone(pid: u32) -> bool {
    let proc = Path::new("/proc");
    proc.join("self").exists() && !proc.join(pid.to_string()).exists()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tmp(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("picker-staging-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        d
    }

    #[test]
    fn commit_moves_everything_summary_last_and_replaces_older_files() {
        let out = tmp("commit");
        std::fs::create_dir_all(out.join("material_0")).unwrap();
        std::fs::write(out.join("material_0/old.png"), b"old").unwrap();
        std::fs::write(out.join("texture.png"), b"old").unwrap();
        std::fs::write(out.join("keep.txt"), b"mine").unwrap();
        let s = Staging::begin(&out, SUMMARY, false).unwrap();
        std::fs::write(s.path().join("texture.png"), b"new").unwrap();
        std::fs::write(s.path().join(SUMMARY), b"{}").unwrap();
        std::fs::create_dir(s.path().join("material_0")).unwrap();
        std::fs::write(s.path().join("material_0/new.png"), b"new").unwrap();
        s.commit().unwrap();
        assert_eq!(std::fs::read(out.join("texture.png")).unwrap(), b"new");
        assert_eq!(std::fs::read(out.join(SUMMARY)).unwrap(), b"{}");
        assert!(out.join("material_0/new.png").is_file());
        assert!(!out.join("material_0/old.png").exists());
        assert_eq!(std::fs::read(out.join("keep.txt")).unwrap(), b"mine");
        let left: Vec<_> = std::fs::read_dir(&out)
            .unwrap()
            .flatten()
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .filter(|n| n.starts_with('.'))
            .collect();
        assert!(left.is_empty(), "hidden entries left: {left:?}");
        std::fs::remove_dir_all(&out).unwrap();
    }

    /// A commit waits while another run holds the output folder's lock
    /// (as a run that is moving its own set into place does), then moves.
    #[test]
    fn commit_waits_for_the_folders_lock() {
        let out = tmp("lock");
        let s = Staging::begin(&out, SUMMARY, false).unwrap();
        std::fs::write(s.path().join("texture.png"), b"new").unwrap();
        std::fs::write(s.path().join(SUMMARY), b"{}").unwrap();
        let other = std::fs::File::open(&out).unwrap();
        if other.try_lock().is_err() {
            // No folder locks on this platform or file system: nothing to test.
            eprintln!("skipped: {} cannot be locked here", out.display());
            std::fs::remove_dir_all(&out).unwrap();
            return;
        }
        let mover = std::thread::spawn(move || s.commit());
        std::thread::sleep(std::time::Duration::from_millis(300));
        assert!(!out.join("texture.png").exists(), "moved while locked");
        assert!(!mover.is_finished());
        other.unlock().unwrap();
        mover.join().unwrap().unwrap();
        assert_eq!(std::fs::read(out.join("texture.png")).unwrap(), b"new");
        assert!(out.join(SUMMARY).is_file());
        std::fs::remove_dir_all(&out).unwrap();
    }

    #[test]
    fn a_run_that_does_not_commit_leaves_nothing() {
        let out = tmp("drop");
        {
            let s = Staging::begin(&out, SUMMARY, false).unwrap();
            std::fs::write(s.path().join("texture.png"), b"new").unwrap();
        }
        assert!(!out.exists(), "the folder this run made is gone");
        {
            let s = Staging::begin(&out, SUMMARY, false).unwrap();
            let e = anyhow::anyhow!("{}: cannot write", s.path().join("report.png").display());
            let shown = s.in_out(e).to_string();
            assert_eq!(
                shown,
                format!("{}: cannot write", out.join("report.png").display())
            );
        }
        // A folder that was there stays, with what it held.
        std::fs::create_dir_all(&out).unwrap();
        std::fs::write(out.join("texture.png"), b"old").unwrap();
        {
            let s = Staging::begin(&out, SUMMARY, false).unwrap();
            std::fs::write(s.path().join("texture.png"), b"new").unwrap();
        }
        assert_eq!(std::fs::read(out.join("texture.png")).unwrap(), b"old");
        assert_eq!(std::fs::read_dir(&out).unwrap().count(), 1);
        std::fs::remove_dir_all(&out).unwrap();
    }

    #[test]
    fn a_kind_clash_is_refused_before_anything_moves() {
        let out = tmp("clash");
        std::fs::create_dir_all(out.join(SUMMARY)).unwrap();
        let s = Staging::begin(&out, SUMMARY, false).unwrap();
        std::fs::write(s.path().join("texture.png"), b"new").unwrap();
        std::fs::write(s.path().join(SUMMARY), b"{}").unwrap();
        let e = format!("{:#}", s.commit().unwrap_err());
        assert!(!e.contains(PREFIX), "{e}");
        assert!(
            e.contains("summary.json") && e.contains("is a folder"),
            "{e}"
        );
        assert!(!out.join("texture.png").exists(), "nothing moved");
        assert!(out.join(SUMMARY).is_dir());
        assert_eq!(
            std::fs::read_dir(&out).unwrap().count(),
            1,
            "staging removed"
        );
        std::fs::remove_dir_all(&out).unwrap();
    }

    #[test]
    fn stale_staging_of_a_dead_process_is_removed_and_a_file_out_refused() {
        let out = tmp("stale");
        // A pid far above any live one (Linux caps pids at 2^22).
        let stale = out.join(format!("{PREFIX}{}", 9_999_999));
        std::fs::create_dir_all(stale.join("x")).unwrap();
        let s = Staging::begin(&out, SUMMARY, false).unwrap();
        if Path::new("/proc/self").exists() {
            assert!(!stale.exists());
        }
        drop(s);
        let _ = std::fs::remove_dir_all(&out);
        let file = tmp("file");
        std::fs::write(&file, b"x").unwrap();
        let e = format!("{:#}", Staging::begin(&file, SUMMARY, false).unwrap_err());
        assert!(e.contains("not a folder"), "{e}");
        std::fs::remove_file(&file).unwrap();
    }
}
