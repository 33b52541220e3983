//! Sizing rayon's global thread pool from `--threads`.

use anyhow::{Context, Result};

/// Most threads per logical core `--threads` may ask for: more only slows a
/// run down (the kernels split their work per thread: 1 000 threads on 2
/// cores took 26 s for a 0.3 s extraction), and results do not depend on
/// the thread count, so a larger request is lowered, with a warning.
pub const MAX_PER_CORE: usize = 4;

/// The thread count for a `--threads` request of `n` on a machine with
/// `cores` logical cores: `None` or 0 give `None` (one per core); more than
/// [`MAX_PER_CORE`] per core gives that many, and the warning to print.
pub fn capped(n: Option<usize>, cores: usize) -> (Option<usize>, Option<String>) {
    let max = MAX_PER_CORE * cores.max(1);
    match n.filter(|&n| n > 0) {
        Some(n) if n > max => (
            Some(max),
            Some(format!(
                "warning: --threads {n} is more than {MAX_PER_CORE} per logical core ({cores} here); using {max}"
            )),
        ),
        other => (other, None),
    }
}

/// Builds rayon's global pool with `n` threads (`None` or 0: one per logical
/// core; at most [`MAX_PER_CORE`] per core) and returns the number of
/// threads it has. Must run before any other rayon use in the process.
pub fn init(n: Option<usize>) -> Result<usize> {
    let mut b = rayon::ThreadPoolBuilder::new();
    let cores = std::thread::available_parallelism().map_or(1, |c| c.get());
    let (n, warning) = capped(n, cores);
    if let Some(w) = warning {
        eprintln!("{w}");
    }
    if let Some(n) = n {
        b = b.num_threads(n);
    }
    b.build_global()
        .context("setting up the thread pool (--threads)")?;
    Ok(rayon::current_num_threads())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn thread_requests_are_capped_per_core() {
        assert_eq!(capped(None, 2), (None, None));
        assert_eq!(capped(Some(0), 2), (None, None));
        assert_eq!(capped(Some(1), 2), (Some(1), None));
        assert_eq!(capped(Some(8), 2), (Some(8), None));
        let (n, w) = capped(Some(1000), 2);
        assert_eq!(n, Some(8));
        assert!(w.unwrap().contains("--threads 1000"));
        assert_eq!(capped(Some(5), 0).0, Some(4), "no core count: one core");
    }
}
