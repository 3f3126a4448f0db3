//! Checks the subcommands share, made before anything is created or
//! allocated: an output that is one of the inputs, and sizes that would
//! fill the memory or the disk.

use anyhow::{bail, Context};
use std::fmt::Display;
use std::path::Path;

/// Most Monte Carlo realizations `montecarlo` and `bench` take (the paper
/// used 2000): the engine keeps every realization's results in memory.
pub const MAX_RUNS: usize = 1_000_000;

/// Why [`MAX_RUNS`] is, for its error.
pub const RUNS_WHY: &str = "each realization's results are kept in memory";

/// Most realizations × frames a Monte Carlo keeps (55 bytes each: about
/// 2.8 GB), so a long trajectory cannot take a run count the memory cannot.
pub const MAX_RUN_FRAMES: u64 = 50_000_000;

/// `--{flag} n` must be at most `max` (`why` says what the bound keeps);
/// a count of 0 is the library's to refuse.
pub fn at_most(flag: &str, n: usize, max: usize, why: &str) -> anyhow::Result<()> {
    if n > max {
        bail!("--{flag} {n}: at most {max} ({why})");
    }
    Ok(())
}

/// `--{flag} n` must be at least 1, for a count the libraries would take
/// as 1 (`what` says what one is): 0 asked for nothing, and must not be
/// answered with something.
pub fn at_least_one(flag: &str, n: usize, what: &str) -> anyhow::Result<()> {
    if n == 0 {
        bail!("--{flag} 0: at least 1 ({what})");
    }
    Ok(())
}

/// `runs` realizations of `frames` frames each must fit [`MAX_RUN_FRAMES`].
pub fn run_frames(what: impl Display, runs: usize, frames: u64) -> anyhow::Result<()> {
    let total = (runs as u64).saturating_mul(frames);
    if total > MAX_RUN_FRAMES {
        bail!(
            "--runs {runs}: {what} has {frames} frames, {total} in all, more than the {MAX_RUN_FRAMES} a Monte Carlo keeps in memory (use fewer runs)"
        );
    }
    Ok(())
}

/// A log of `frames` frames must be within `--max-frames`: a typo must not
/// fill the disk. `what` says where the count comes from.
pub fn max_frames(what: impl Display, frames: u64, max: u64) -> anyhow::Result<()> {
    if frames > max {
        bail!("{what} is {frames} frames, more than --max-frames {max} (raise it to write them)");
    }
    Ok(())
}

/// `path` can be written as a file, checked without truncating one that
/// is there: a folder, a missing folder or no permission fails now, not
/// after the work whose results it was to hold.
pub fn writable_file(path: &Path) -> anyhow::Result<()> {
    let existed = path.exists();
    std::fs::OpenOptions::new()
        .append(true)
        .create(true)
        .open(path)
        .with_context(|| format!("--out {}: cannot be written", path.display()))?;
    if !existed {
        let _ = std::fs::remove_file(path);
    }
    Ok(())
}

/// `--out` must not be any of `inputs` (flag, path): creating it would
/// truncate the input before it is read.
pub fn not_an_input(out: &Path, inputs: &[(&str, &Path)]) -> anyhow::Result<()> {
    for (flag, input) in inputs {
        if lightpose_logs::same_file(input, out) {
            bail!(
                "{}: input and output are the same file (--{flag} and --out)",
                out.display()
            );
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_same_file_by_another_name_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let a = dir.path().join("a.jsonl");
        std::fs::write(&a, "x\n").unwrap();
        let other = dir.path().join("b.jsonl");
        let dotted = dir.path().join(".").join("a.jsonl");
        assert!(not_an_input(&other, &[("log", &a)]).is_ok());
        let e = not_an_input(&dotted, &[("log", &a)]).unwrap_err();
        assert!(e.to_string().contains("(--log and --out)"), "{e}");
        #[cfg(unix)]
        {
            let hard = dir.path().join("hard.jsonl");
            std::fs::hard_link(&a, &hard).unwrap();
            assert!(not_an_input(&hard, &[("log", &a)]).is_err());
        }
    }

    #[test]
    fn counts_are_bounded() {
        let why = "memory";
        assert!(at_most("runs", 1, MAX_RUNS, why).is_ok());
        assert!(at_most("runs", MAX_RUNS, MAX_RUNS, why).is_ok());
        let e = at_most("runs", usize::MAX, MAX_RUNS, why).unwrap_err();
        assert_eq!(
            e.to_string(),
            format!("--runs {}: at most 1000000 (memory)", usize::MAX)
        );
        assert!(run_frames("x", MAX_RUNS, u64::MAX).is_err());
        assert!(at_least_one("every", 1, "frames").is_ok());
        let e = at_least_one("every", 0, "print every n-th frame").unwrap_err();
        assert_eq!(
            e.to_string(),
            "--every 0: at least 1 (print every n-th frame)"
        );
        assert!(run_frames("x", 2000, 41).is_ok());
    }
}
