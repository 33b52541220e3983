//! Sizing rayon's global thread pool from `--threads`.

use anyhow::{Context, Result};

/// Builds rayon's global pool with `n` threads (`None` or 0: one per logical
/// core) and returns the number of threads it has. Must run before any other
/// rayon use in the process.
pub fn init(n: Option<usize>) -> Result<usize> {
    let mut b = rayon::ThreadPoolBuilder::new();
    if let Some(n) = n.filter(|&n| n > 0) {
        b = b.num_threads(n);
    }
    b.build_global()
        .context("setting up the thread pool (--threads)")?;
    Ok(rayon::current_num_threads())
}
